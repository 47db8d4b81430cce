"""Worst case and RSS beside the Monte Carlo (issue 17): tolsim.study.analyses.worst_case."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats

from tolsim.io.config import load_config, parse_config, with_study_settings
from tolsim.study.analyses.worst_case import (
    NORMAL_BAND_STDS,
    linear_stackup,
    standard_deviation,
    tolerance_band,
)
from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.evaluate import evaluate_balls, loads_per_ball
from tolsim.study.sampling import error_values, sample_block
from tolsim.study.spec import Distribution

ROOT = Path(__file__).resolve().parents[2]
#: Assemblies of the Monte Carlo comparisons: the standard deviation of epsilon at one
#: position is then known to about 1 / sqrt(2 n) = 0.6 %, far inside the 10 % asked for.
MC_SAMPLES = 16_384


@pytest.fixture(scope="module")
def default_study():
    config = load_config()
    return run_study(with_study_settings(config, samples=MC_SAMPLES, sensitivity_samples=0,
                                         spot_checks=0))


def test_default_study_worst_case_and_rss_against_monte_carlo(default_study):
    # Issue 17: on the default study the worst case is at least the RSS figure, and the RSS
    # agrees with the Monte Carlo standard deviation within 10 % where the model is
    # near-linear. The default study is (epsilon is linear in the small dbeta of 0.1 deg
    # tolerances): measured when written, RSS / MC std = 1.000 at the critical ball (0) and
    # within 0.8 % at every position.
    stack = default_study.stackup
    acc = default_study.statistics
    mc_std = np.sqrt(acc.ball_m2 / (acc.ball_count - 1))
    j = stack.critical_ball
    assert 0 <= j < default_study.config.train.balls
    assert stack.velocity_deviation_worst_case[j] >= stack.velocity_deviation_rss[j] > 0
    assert abs(stack.velocity_deviation_rss[j] / mc_std[j] - 1.0) <= 0.10
    # every position and every pair, not only the critical one
    assert np.all(stack.velocity_deviation_worst_case >= stack.velocity_deviation_rss)
    assert np.all(stack.gap_closure_worst_case >= stack.gap_closure_rss)
    assert_allclose(stack.velocity_deviation_rss, mc_std, rtol=0.03)
    # the critical ball has the largest RSS (the train under the yaw moment is mirror-
    # symmetric: the tie of positions 0 and 9 goes to the lower one)
    assert stack.velocity_deviation_rss[j] >= stack.velocity_deviation_rss.max() * (1 - 1e-9)
    assert j == 0


def test_default_study_gap_closure_rss_against_monte_carlo():
    # The gap closure (eps_j - eps_j+1) v/2 T of each pair combines shared sources (the
    # carriage's, which nearly cancel), rail random fields (correlated ~0.8-0.9 between
    # neighbours) and per-ball sources: its RSS must match the Monte Carlo spread of the
    # same study's assemblies (measured when written: within 0.8 %).
    config = load_config()
    config = with_study_settings(config, samples=MC_SAMPLES,
                                 block_size=MC_SAMPLES)
    stack = linear_stackup(config)
    block = sample_block(config, 0)
    nx, ny = loads_per_ball(config, (block.size, config.train.balls))
    eps = evaluate_balls(config, error_values(config, block), nx, ny).velocity_deviation
    scale = 0.5 * config.motion.groove_velocity * config.motion.duration
    closure = (eps[:, :-1] - eps[:, 1:]) * scale
    assert_allclose(stack.gap_closure_rss, np.nanstd(closure, axis=0, ddof=1), rtol=0.05)
    assert_allclose(stack.velocity_deviation_rss, np.nanstd(eps, axis=0, ddof=1), rtol=0.05)
    # the shared sources cancel in the difference: the closure spreads far less than the
    # two balls' epsilon would if they were independent
    independent = scale * np.hypot(stack.velocity_deviation_rss[:-1],
                                   stack.velocity_deviation_rss[1:])
    assert np.all(stack.gap_closure_rss < 0.5 * independent)


SCOPES_TOML = """
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
nominal_contact_angle_deg = 45.0
youngs_modulus_GPa = 210.0
poisson_ratio = 0.28
friction_coefficient = 0.1

[motion]
groove_velocity_mm_per_s = 200.0
stroke_mm = 100.0

[train]
balls = 3
initial_gap = { distribution = "fixed", value_um = 50.0 }

[loads]                   # the same load on every ball: the same sensitivities
normal_load_N = 200.0
side_load_N = -120.0

[tolerances.top_rotation]
distribution = "normal"
std_deg = 0.1
scope = "carriage"

[tolerances.arc_centre_offset_tangential_BL]
distribution = "uniform"
low_um = -2.0
high_um = 2.0
scope = "ball"

[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.05
scope = "rail"
correlation_length_mm = 50.0

[study]
samples = 16
seed = 1
static_model = "paired"
velocity_model = "eq24"
"""


def test_shared_ball_and_field_sources_combine_by_scope():
    # Three balls with identical loads, so each source has the same sensitivity g_i at every
    # position. For one ball, RSS = sqrt(sum (g_i sigma_i)^2) and worst case =
    # sum |g_i| w_i whatever the scope. For the pair difference the carriage source (one
    # value shared by both balls) cancels exactly; the ball source adds twice, independently;
    # the rail field adds with its correlation r = exp(-pitch / l) between the two balls.
    config = parse_config(SCOPES_TOML, "scopes.toml")
    stack = linear_stackup(config)
    assert stack.sources == ("top_rotation", "arc_centre_offset_tangential_BL",
                             "bottom_rotation")
    g = stack.sensitivity
    assert np.all(g == g[:, :1]) and np.all(g != 0)  # same inputs, same numbers
    g = g[:, 0]
    sigma = np.array([np.deg2rad(0.1), 4e-6 / np.sqrt(12.0), np.deg2rad(0.05)])
    half = np.array([3 * np.deg2rad(0.1), 2e-6, 3 * np.deg2rad(0.05)])
    assert_allclose(stack.standard_deviation, sigma, rtol=1e-12)
    assert_allclose(stack.velocity_deviation_rss, np.sqrt(np.sum((g * sigma) ** 2)),
                    rtol=1e-12)
    assert_allclose(stack.velocity_deviation_worst_case, np.sum(np.abs(g) * half),
                    rtol=1e-12)
    scale = 0.5 * 0.2 * 0.5  # v/2 T: 200 mm/s over a 100 mm stroke
    r = np.exp(-(10.0 + 0.05) / 50.0)  # nominal pitch: diameter + gap [mm]
    rss = scale * np.sqrt(2 * (g[1] * sigma[1]) ** 2 + 2 * (1 - r) * (g[2] * sigma[2]) ** 2)
    worst = scale * 2 * (abs(g[1]) * half[1] + abs(g[2]) * half[2])
    assert_allclose(stack.gap_closure_rss, rss, rtol=1e-12)
    assert_allclose(stack.gap_closure_worst_case, worst, rtol=1e-12)
    assert_allclose(stack.gap_closure_nominal, 0.0, atol=1e-18)
    assert stack.critical_ball == 0 and stack.critical_pair == 0  # ties: the first


def test_no_random_source_gives_zero_spread_and_the_nominal_closure():
    # Lin2018 Sec. 3.2 (configs/paper_case_study.toml): theta = 2 deg fixed, rho = -/+0.6,
    # paired forces, no tolerance. The study's path re-solves these balls with the full model
    # (|dbeta| = 2 deg is outside eq24's error budget), as the study itself does: +/-0.789 %,
    # our full model's Table 2 value with paired forces (reports/paper/README.md).
    config = load_config(ROOT / "configs" / "paper_case_study.toml")
    stack = linear_stackup(config)
    assert stack.sources == ()
    assert_allclose(100 * stack.velocity_deviation_nominal, [0.789, -0.789], atol=0.001)
    assert np.all(stack.velocity_deviation_rss == 0)
    assert np.all(stack.velocity_deviation_worst_case == 0)
    closure = np.diff(stack.velocity_deviation_nominal[::-1]) * 0.5 * 0.01 * 10.0
    assert_allclose(stack.gap_closure_nominal, closure, rtol=1e-12)
    assert stack.critical_pair == 0


@pytest.mark.parametrize("dist, frozen, band", [
    (Distribution("normal", mean=1.0, std=2.0), stats.norm(1.0, 2.0),
     (1.0 - 3 * 2.0, 1.0 + 3 * 2.0)),
    (Distribution("uniform", low=-1.0, high=3.0), stats.uniform(-1.0, 4.0), (-1.0, 3.0)),
    (Distribution("truncated_normal", mean=0.5, std=1.0, low=-1.0, high=1.5),
     stats.truncnorm(-1.5, 1.0, loc=0.5, scale=1.0), (-1.0, 1.5)),
    (Distribution("cpk", mean=0.0, std=1.0 / 1.33, low=-3.0, high=3.0, cpk=1.33),
     stats.norm(0.0, 1.0 / 1.33), (-3.0, 3.0)),
    (Distribution("cpk", mean=0.5, std=1.0, low=-1.0, high=2.0, cpk=0.5, truncate=True),
     stats.truncnorm(-1.5, 1.5, loc=0.5, scale=1.0), (-1.0, 2.0)),
])
def test_standard_deviation_and_band_against_scipy(dist, frozen, band):
    # scipy.stats' standard deviations; bands as documented (normal: mean +/- 3 std)
    assert_allclose(standard_deviation(dist), frozen.std(), rtol=1e-12)
    assert_allclose(tolerance_band(dist), band, rtol=1e-12)
    assert NORMAL_BAND_STDS == 3.0


def test_empirical_standard_deviation_is_that_of_its_sampled_quantile_function():
    # from_normal samples the interpolated empirical quantile function; its exact standard
    # deviation against a dense midpoint rule over u (error ~1e-7 relative)
    data = (-2.0, -0.5, 0.0, 0.1, 0.7, 3.0)
    dist = Distribution("empirical", data=data)
    u = (np.arange(2_000_000) + 0.5) / 2_000_000
    values = dist.from_normal(stats.norm.ppf(u))
    assert_allclose(standard_deviation(dist), values.std(), rtol=1e-6)
    assert tolerance_band(dist) == (-2.0, 3.0)
    assert standard_deviation(Distribution("fixed", value=2.0)) == 0.0
    assert tolerance_band(Distribution("fixed", value=2.0)) == (2.0, 2.0)


def test_result_file_holds_the_stackup(default_study, tmp_path):
    from tolsim.io.netcdf import read_result, write_result

    write_result(default_study, tmp_path / "r.nc", history="test")
    ds = read_result(tmp_path / "r.nc")
    stack = default_study.stackup
    assert int(ds["critical_ball"]) == stack.critical_ball
    assert int(ds["critical_pair"]) == stack.critical_pair
    for name in ("velocity_deviation_worst_case", "velocity_deviation_rss",
                 "velocity_deviation_nominal"):
        assert ds[name].dims == ("ball",) and ds[name].attrs["units"] == "1"
        assert_allclose(ds[name].values, getattr(stack, name), rtol=0, atol=0)
    for name in ("gap_closure_worst_case", "gap_closure_rss", "gap_closure_nominal"):
        assert ds[name].dims == ("pair",) and ds[name].attrs["units"] == "m"
        assert_allclose(ds[name].values, getattr(stack, name), rtol=0, atol=0)


def test_correlated_sources_add_their_covariance():
    # A correlated group (Gaussian copula of normal marginals: Pearson rho = 0.8) of the two
    # carriage flanks: RSS^2 = (g1 s1)^2 + (g2 s2)^2 + 2 rho g1 s1 g2 s2, and it matches the
    # Monte Carlo spread of the study's own draws.
    text = SCOPES_TOML.replace(
        '[tolerances.arc_centre_offset_tangential_BL]\ndistribution = "uniform"\n'
        'low_um = -2.0\nhigh_um = 2.0\nscope = "ball"\n',
        '[tolerances.arc_centre_offset_tangential_TR]\ndistribution = "normal"\n'
        'std_um = 1.0\n\n[tolerances.arc_centre_offset_tangential_TL]\n'
        'distribution = "normal"\nstd_um = 2.0\n\n[[correlation]]\n'
        'sources = ["arc_centre_offset_tangential_TR", "arc_centre_offset_tangential_TL"]\n'
        'coefficient = 0.8\n')
    config = parse_config(text, "correlated.toml")
    stack = linear_stackup(config)
    k = [stack.sources.index(f"arc_centre_offset_tangential_{c}") for c in ("TR", "TL")]
    t = stack.sources.index("top_rotation")
    b = stack.sources.index("bottom_rotation")
    g, s = stack.sensitivity[:, 0], stack.standard_deviation
    var = ((g[t] * s[t]) ** 2 + (g[b] * s[b]) ** 2 + (g[k[0]] * s[k[0]]) ** 2
           + (g[k[1]] * s[k[1]]) ** 2 + 2 * 0.8 * g[k[0]] * s[k[0]] * g[k[1]] * s[k[1]])
    assert_allclose(stack.velocity_deviation_rss, np.sqrt(var), rtol=1e-12)
    big = with_study_settings(config, samples=MC_SAMPLES,
                              block_size=MC_SAMPLES)
    block = sample_block(big, 0)
    nx, ny = loads_per_ball(big, (block.size, big.train.balls))
    eps = evaluate_balls(big, error_values(big, block), nx, ny).velocity_deviation
    assert_allclose(stack.velocity_deviation_rss, np.std(eps, axis=0, ddof=1), rtol=0.05)
