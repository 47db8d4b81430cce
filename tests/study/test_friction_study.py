"""What a study reports after contact (issue 13, part 3): tolsim.study.pipeline.track_friction.

Each reference value names its source and tolerance. Closed forms: the nominal ball's creep
coefficients (tolsim.physics.velocity.ball_loads docstring), two balls with constant epsilon (the
K-weighted cluster, tolsim.physics.trains docstring) and the friction increase of a track
(eq. 1 of tolsim.study.pipeline.track_friction), a binomial exceedance (Clopper-Pearson, scipy).
Invariants:
bit-identical across chunking and resuming, no [contact] changes nothing, matched deviations
(paper case b) give nothing, the x-mirrored assembly gives the same figures.
"""

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import xarray as xr
from numpy.testing import assert_allclose, assert_array_equal
from scipy.stats import binomtest

from tolsim.cli import main
from tolsim.io.config import load_config, parse_config, with_study_settings
from tolsim.io.netcdf import read_result, result_to_dataset, write_result
from tolsim.io.schema.friction import FRICTION_COORDINATES, FRICTION_VARIABLES
from tolsim.physics.geometry import K_F_PAPER, TABLE1, paired_forces
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.trains import train_contact_constant
from tolsim.physics.trains.regimes import TRAIN_COLUMNS
from tolsim.physics.velocity.analytic import LOAD_COLUMNS, analytic
from tolsim.study.analyses import friction_examples as fx
from tolsim.study.execution.runner import StudyInterrupted, run_study
from tolsim.study.pipeline import track_friction as fr
from tolsim.study.pipeline.evaluate import BallState
from tolsim.study.sampling import sample_block
from tolsim.study.statistics import friction as fs
from tolsim.study.statistics.accumulator import Accumulator

CONFIGS = Path(__file__).resolve().parents[2] / "configs"

#: Two balls of the paper's bearing (Table 1) under paired forces, side force ratio -/+0.3,
#: the bottom groove turned by 0.5 deg, inside the analytic model's validity: ball 0
#: (trailing) is faster and catches ball 1 within the stroke.
TWO_BALLS = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
friction_coefficient = 0.1
[motion]
groove_velocity_mm_per_s = 10.0
duration_s = 10.0
[train]
balls = 2
initial_gap = {gap}
[loads]
normal_load_N = 200.0
side_force_ratio = [-0.3, 0.3]
[tolerances.bottom_rotation]
distribution = "fixed"
value_deg = 0.5
[study]
samples = {samples}
seed = 5
block_size = {block}
velocity_model = "analytic"
static_model = "paired"
[contact]
ball_friction_coefficient = {mu_bb}
creep_model = "{creep}"
{limit}
"""
FIXED_GAP = '{ distribution = "fixed", value_um = 50.0 }'


def two_balls(gap=FIXED_GAP, samples=8, block=8, mu_bb=0.1, creep="analytic", limit=""):
    return parse_config(TWO_BALLS.format(gap=gap, samples=samples, block=block, mu_bb=mu_bb,
                                         creep=creep, limit=limit), "two_balls.toml")


def two_ball_reference(mu_bb, creep="analytic"):
    """(eps, K, c, F_0, a, b) of the two balls from the public single-ball models."""
    theta = np.radians(0.5)
    dbeta = np.array([[-theta, theta, 0.0, 0.0]] * 2)  # rigid mapping, [Lin2018] Sec. 3.1
    force = np.array([paired_forces(rho * 200.0, 200.0) for rho in (-0.3, 0.3)])
    eps = analytic(dbeta, force, TABLE1).velocity_deviation
    r = analytic(dbeta, force, TABLE1, push=0.0, ball_friction=mu_bb)
    k, c, f0 = r.creep_stiffness, r.braking_sensitivity, r.free_rolling_carriage_force
    if creep == "full":
        from tolsim.physics.velocity.full import full

        rf = full(dbeta, force, TABLE1, push=0.0, ball_friction=mu_bb)
        k, c, f0 = rf.creep_stiffness, rf.braking_sensitivity, rf.free_rolling_carriage_force
    return (eps, k, c, f0, r.carriage_force_per_push, r.carriage_force_per_neighbour_force)


# --------------------------------------------------------------------------------------------
# Kernel against its NumPy twin
# --------------------------------------------------------------------------------------------
def stroke_friction_numpy(segment_start, segment_force, valid, load, horizon):
    """NumPy twin of :func:`tolsim.study.pipeline.track_friction.stroke_friction_kernel` (eq. 1)."""
    m, s = segment_start.shape
    a, b = load[:, :, fr._A], load[:, :, fr._B]
    k = (a[:, 1:] - a[:, :-1]) + (b[:, :-1] + b[:, 1:])
    q = np.nan_to_num(segment_force)
    increase = np.einsum("msj,mj->ms", q, k)
    used = segment_start <= horizon
    following = np.concatenate([segment_start[:, 1:], np.full((m, 1), np.inf)], axis=1)
    end = np.minimum(following, horizon)
    duration = np.where(used, end - segment_start, 0.0)
    zero = np.zeros((m, s, 1))
    back, front = np.concatenate([zero, q], axis=2), np.concatenate([q, zero], axis=2)
    slides = used & np.any((np.abs(back - front) >= load[:, None, :, fr._PCAP])
                           | (back + front >= load[:, None, :, fr._BCAP]), axis=2)
    rolling = used & (np.cumsum(slides, axis=1) == 0)
    out = {
        "baseline": load[:, :, fr._F0].sum(axis=1),
        "mean": (increase * duration).sum(axis=1) / horizon,
        "max": np.where(used, increase, -np.inf).max(axis=1),
        "min": np.where(used, increase, np.inf).min(axis=1),
        "sliding": slides.any(axis=1),
        "rolling": np.where(rolling, increase, -np.inf).max(axis=1),
    }
    for key in ("mean", "max", "min", "rolling"):
        out[key] = np.where(valid, out[key], np.nan)
    out["sliding"] &= valid
    return out


def test_stroke_kernel_matches_numpy_twin(rng):
    # Random trains (tolsim.physics.trains, exact segments) and random creep coefficients,
    # some capacities small enough to slide. Tolerance 1e-12 relative (summation order).
    m, n, horizon = 400, 7, 0.5
    eps = rng.normal(0.0, 3e-3, (m, n))
    gap = rng.uniform(0.0, 60e-6, (m, n - 1))
    gap[:20] = 0.0  # touching at the start
    stiffness = rng.uniform(600.0, 800.0, (m, n))
    stiffness[-3:, 2] = np.nan  # unresolved trains
    res = train_contact_constant(gap, eps, stiffness, 0.2, horizon, segments=True)
    load = np.full((m, n, len(TRAIN_COLUMNS)), np.nan)
    load[:, :, TRAIN_COLUMNS.index("release_push_forward")] = np.inf
    load[:, :, TRAIN_COLUMNS.index("release_push_backward")] = -np.inf
    load[:, :, fr._F0] = rng.uniform(1.1, 1.3, (m, n))
    load[:, :, fr._A] = rng.normal(-0.5, 0.01, (m, n))
    load[:, :, fr._B] = rng.normal(0.07, 0.005, (m, n))
    load[:, :, fr._PCAP] = rng.choice([1.0, 56.0], (m, n), p=[0.05, 0.95])
    load[:, :, fr._BCAP] = rng.choice([2.0, 400.0, np.inf], (m, n), p=[0.05, 0.5, 0.45])
    out = {k: np.empty(m) for k in ("baseline", "mean", "max", "min", "rolling")}
    onset = np.empty(m, dtype=np.int8)
    pairs = load[:, :-1, fr._B] + load[:, 1:, fr._B]
    fr.stroke_friction_kernel(res.segment_start, res.segment_contact_force, res.valid, load,
                              pairs, horizon, out["baseline"], out["mean"], out["max"], out["min"],
                              onset, out["rolling"])
    sliding = onset != 0  # SLIDING: no release pushes here
    twin = stroke_friction_numpy(res.segment_start, res.segment_contact_force, res.valid,
                                 load, horizon)
    assert_array_equal(sliding, twin["sliding"])
    assert 20 < sliding.sum() < m - 20 and not res.valid[-3:].any()  # both branches seen
    for key in out:
        assert_allclose(out[key], twin[key], rtol=1e-12, atol=1e-15, err_msg=key)


def test_creep_kernel_matches_the_loaded_analytic_kernel(rng):
    # tolsim.study.pipeline.track_friction.creep_coefficients_kernel is the study's fast path of
    # tolsim.physics.velocity.analytic.analytic_loaded_kernel at zero load (its twin here): epsilon,
    # K, F_0 and dF_c/dP bit for bit (same arithmetic), the braking columns to round-off
    # (c K to 1e-12 absolute, b and the stall capacity to 1e-12 relative: the rolling axis
    # from sin_cos_near instead of np.sin). Its traction column is a lower bound of the
    # point-contact capacity: never above it (1e-12), equal for balls in equilibrium, and
    # (measured) equal on these random balls too (1e-9).
    from tolsim.physics.velocity.analytic import (
        MAX_ANGLE_SUM,
        MAX_VELOCITY_DEVIATION,
        MAX_ZERO_VELOCITY_RATIO,
        analytic_loaded_kernel,
    )

    n = 20000
    dbeta = rng.normal(0.0, np.radians(0.6), (n, 4))
    force = 141.4 * rng.uniform(0.3, 1.7, (n, 4))
    force[:50] = paired_forces(rng.uniform(-0.8, 0.8, 50) * 200.0, 200.0)  # equilibrium
    dbeta[:50] = 0.0
    ref = np.empty((n, len(LOAD_COLUMNS)))
    hc = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                         TABLE1.poisson_ratio)
    zero = np.zeros(n)
    analytic_loaded_kernel(dbeta, force, zero, zero, TABLE1.nominal_contact_angle,
                           TABLE1.ball_radius, hc.semi_major_coefficient, hc.elliptic_e,
                           K_F_PAPER, TABLE1.friction_coefficient, 0.1,
                           MAX_ZERO_VELOCITY_RATIO, MAX_ANGLE_SUM, MAX_VELOCITY_DEVIATION,
                           np.empty(n), np.empty(n), np.empty((n, 4)), np.empty(n, bool), ref,
                           np.empty(n, bool))
    load = fr.CREEP_MODELS["analytic"](dbeta, force, TABLE1, 0.1)
    for name in ("free_rolling_velocity_deviation", "creep_stiffness",
                 "free_rolling_carriage_force", "carriage_force", "carriage_force_per_push"):
        j = LOAD_COLUMNS.index(name)
        assert_array_equal(load[:, j], ref[:, j], err_msg=name)
    assert_allclose(load[:, fr._C] * ref[:, fr._K], ref[:, fr._C] * ref[:, fr._K], rtol=0,
                    atol=1e-12)
    assert_allclose(load[:, [fr._B, fr._BCAP]], ref[:, [fr._B, fr._BCAP]], rtol=1e-12)
    bound, exact = load[:, fr._PCAP], ref[:, fr._PCAP]
    assert np.all(bound <= exact * (1 + 1e-12))
    assert_allclose(bound[:50], exact[:50], rtol=1e-12)
    assert_allclose(bound[:50], 0.1 * force[:50].sum(axis=1), rtol=1e-12)
    assert np.min(bound / exact) > 1 - 1e-9


# --------------------------------------------------------------------------------------------
# Closed forms
# --------------------------------------------------------------------------------------------
def test_nominal_ball_creep_coefficients_closed_form():
    # tolsim.physics.velocity.ball_loads docstring, the nominal ball of Table 1 at N_y = 200 N
    # (F = 141.4 N per contact): K = -4 mu k_f R_B F / (a tan beta_0) = 704.6 N,
    # F_0 = 4 M_spin tan(beta_0) / (2 R_B) with M_spin = 3/8 mu F a E(e) (Eq. 14) = 1.227 N,
    # a = dF_c/dP = -1/2, b = mu_bb / (2 cos beta_0), P_cap = mu sum F_i. Tolerance 1e-12.
    force = np.array(paired_forces(0.0, 200.0))
    state = BallState(np.zeros((1, 1)), np.ones((1, 1), bool), np.ones((1, 1), bool),
                      np.zeros((1, 1), bool), np.zeros((1, 1, 4)), force.reshape(1, 1, 4),
                      np.zeros((1, 1), np.int8))
    config = replace(two_balls(), bearing=TABLE1)
    load = fr.ball_creep_coefficients(config, state)[0]
    hc = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                         TABLE1.poisson_ratio)
    f, mu, r, beta = force[0], TABLE1.friction_coefficient, TABLE1.ball_radius, np.pi / 4
    a = hc.semi_major_coefficient * np.cbrt(f)
    assert_allclose(load[fr._K], -4 * mu * K_F_PAPER * r * f / (a * np.tan(beta)), rtol=1e-12)
    assert_allclose(load[fr._K], 704.6, atol=0.05)
    assert_allclose(load[fr._F0], 4 * 0.375 * mu * f * a * hc.elliptic_e * np.tan(beta) / (2 * r),
                    rtol=1e-12)
    assert_allclose(load[fr._F0], 1.227, atol=5e-4)
    assert_allclose(load[fr._A], -0.5, rtol=1e-12)
    assert_allclose(load[fr._B], 0.1 / (2 * np.cos(beta)), rtol=1e-12)
    assert_allclose(load[fr._PCAP], mu * 4 * f, rtol=1e-12)


@pytest.mark.parametrize("mu_bb", [0.0, 0.1])
def test_two_balls_closed_form_through_the_study(mu_bb):
    # tolsim.physics.trains docstring: two balls with constant epsilon touch at
    # t_c = g / ((eps_0 - eps_1) v / 2) and then move as one cluster with
    # Q = (eps_0 - eps_1) / (1/K_0 + 1/K_1 - c_0 + c_1) (for mu_bb = 0, c = 0:
    # Q = K_0 K_1 (eps_0 - eps_1) / (K_0 + K_1), the closed form). The friction
    # increase is k Q with k = (a_1 - a_0) + (b_0 + b_1) (eq. 1 of
    # tolsim.study.pipeline.track_friction),
    # 0 before contact. K, c, a, b, F_0 from tolsim.physics.velocity.analytic.analytic on the same
    # contact state. Tolerance 1e-12 relative (the study runs the same kernels).
    eps, k, c, f0, a, b = two_ball_reference(mu_bb)
    assert eps[0] > eps[1] > -0.0052  # inside the analytic model's validity, ball 0 faster
    q = (eps[0] - eps[1]) / (1 / k[0] + 1 / k[1] - c[0] + c[1])
    if mu_bb == 0:
        assert_allclose(q, k[0] * k[1] * (eps[0] - eps[1]) / (k[0] + k[1]), rtol=1e-12)
        assert c[0] == c[1] == b[0] == b[1] == 0
    coefficient = (a[1] - a[0]) + (b[0] + b[1])
    v, horizon = 0.01, 10.0
    t_contact = 50e-6 / ((eps[0] - eps[1]) * v / 2)
    assert 1.0 < t_contact < 9.0
    increase = coefficient * q
    expected = {"baseline": f0.sum(), "increase_max": max(increase, 0.0),
                "increase_mean": increase * (horizon - t_contact) / horizon,
                "ripple": abs(increase), "contact_force_max": q,
                "contact_fraction": (horizon - t_contact) / horizon, "clusters_formed": 1.0}
    result = run_study(two_balls(mu_bb=mu_bb))
    stats = result.friction
    assert stats.n_assemblies == stats.n_resolved == stats.count == 8
    for name, value in expected.items():
        j = fs.COLUMNS.index(name)
        assert_allclose([stats.minimum[j], stats.maximum[j]], value, rtol=1e-12,
                        atol=1e-15 if value == 0 else 0, err_msg=name)
    assert_allclose(stats.quantiles("contact_force_max", (0.01, 0.5, 0.99)), q, rtol=1e-12)
    # the example trajectory: the friction force steps from F_0 to F_0 + k Q at contact
    ex = result.friction_examples
    assert len(ex.assembly) == 4 and np.all(ex.track == 0)
    before, after = ex.travel < v * t_contact, ex.travel > v * t_contact
    assert_allclose(ex.friction_force[:, before], f0.sum(), rtol=1e-12)
    assert_allclose(ex.friction_force[:, after], f0.sum() + increase, rtol=1e-12)
    assert_allclose(ex.contact_force[:, after, 0], q, rtol=1e-12)
    gap = ex.ball_position[:, :, 1] - ex.ball_position[:, :, 0] - 2 * TABLE1.ball_radius
    assert_allclose(gap[:, after], 0.0, atol=1e-15)
    assert_allclose(gap[:, 0], 50e-6, rtol=1e-12)


def test_paper_case_a_after_contact():
    # [Lin2018] Sec. 3.2 case (a) (configs/paper_case_study.toml): epsilon = +-0.7889 % from
    # the full model (tests/integration/test_configs.py), contact at 6.34 s. After it, Q =
    # K_0 K_1 (eps_0 - eps_1) / (K_0 + K_1) (c = 0 for these balls) with K from the analytic
    # model at their contact states (673.2 N), and the friction increase k Q (eq. 1). The
    # figures quoted in tolsim.study.pipeline.track_friction: Q = 5.31 N, increase 0.79 N on 2.82 N.
    # Tolerance 1e-9 relative (epsilon from the full model's Newton solve, the same in both).
    from tolsim.physics.velocity.full import full

    theta = np.radians(2.0)
    dbeta = np.array([[-theta, theta, 0.0, 0.0]] * 2)
    force = np.array([paired_forces(rho * 200.0, 200.0) for rho in (-0.6, 0.6)])
    eps = full(dbeta, force, TABLE1).velocity_deviation
    r = analytic(dbeta, force, TABLE1, push=0.0)
    k, a, b = r.creep_stiffness, r.carriage_force_per_push, r.carriage_force_per_neighbour_force
    q = k[0] * k[1] * (eps[0] - eps[1]) / (k[0] + k[1])
    increase = ((a[1] - a[0]) + (b[0] + b[1])) * q
    assert_allclose([q, increase, r.free_rolling_carriage_force.sum()], [5.31, 0.79, 2.82],
                    atol=0.005)
    c = load_config(CONFIGS / "paper_case_study.toml")
    result = run_study(parse_config(c.text + "\n[contact]\n", "paper_case_contact.toml"))
    stats, j = result.friction, fs.COLUMNS.index
    assert_allclose(stats.maximum[j("contact_force_max")], q, rtol=1e-9)
    assert_allclose(stats.maximum[j("increase_max")], increase, rtol=1e-9)
    t_contact = 0.5e-3 / ((eps[0] - eps[1]) * 0.01 / 2)
    assert_allclose(stats.maximum[j("contact_fraction")], (10.0 - t_contact) / 10.0, rtol=1e-9)
    assert_allclose(t_contact, 6.34, atol=0.005)


def test_two_balls_full_creep_model():
    # creep_model = "full": K, c and F_0 from tolsim.physics.velocity.full.full at zero load
    # (746.4 N for the nominal ball, ball_loads docstring: a few % above the analytic K),
    # the slopes a, b analytic. Same closed form as above; tolerance 1e-9 relative (full is
    # solved to its Newton tolerance, the same solve in both).
    pytest.importorskip("tolsim.physics.velocity.full")
    eps, k, c, f0, a, b = two_ball_reference(0.1, creep="full")
    k_analytic = two_ball_reference(0.1)[1]
    assert np.all((k > 1.01 * k_analytic) & (k < 1.1 * k_analytic))
    q = (eps[0] - eps[1]) / (1 / k[0] + 1 / k[1] - c[0] + c[1])
    stats = run_study(two_balls(samples=2, block=2, creep="full")).friction
    j = fs.COLUMNS.index
    assert_allclose(stats.maximum[j("contact_force_max")], q, rtol=1e-9)
    assert_allclose(stats.maximum[j("baseline")], f0.sum(), rtol=1e-9)
    assert_allclose(stats.maximum[j("increase_max")], ((a[1] - a[0]) + (b[0] + b[1])) * q,
                    rtol=1e-9)


def test_exceedance_is_a_binomial_proportion_closed_form():
    # Two balls with a uniform gap on [0, 200 um]: a pair touches within the stroke exactly
    # when g < g* = (eps_0 - eps_1) v T / 2, and then its increase k Q exceeds a limit of
    # k Q / 2 for the rest of the stroke. So the exceedances are Bernoulli(g* / 200 um): the
    # count equals the contacts exactly, the estimate is k / N with the Clopper-Pearson
    # interval of scipy.stats.binomtest (to 1e-9), and it covers g* / 200 um (seeded).
    eps, k, c, f0, a, b = two_ball_reference(0.1)
    q = (eps[0] - eps[1]) / (1 / k[0] + 1 / k[1] - c[0] + c[1])
    limit = 0.5 * ((a[1] - a[0]) + (b[0] + b[1])) * q
    gap = '{ distribution = "uniform", low_um = 0.0, high_um = 200.0 }'
    n = 3000
    result = run_study(two_balls(gap=gap, samples=n, block=512,
                                 limit=f"friction_increase_limit_N = {float(limit)!r}"))
    stats, acc = result.friction, result.statistics
    assert stats.n_exceed == acc.n_contact and stats.n_unresolved == 0
    p_true = (eps[0] - eps[1]) * 0.01 * 10.0 / 2 / 200e-6
    assert 0.2 < p_true < 0.8
    p, lo, hi = stats.exceedance_probability()
    ci = binomtest(int(stats.n_exceed), n).proportion_ci(0.95, method="exact")
    assert p == stats.n_exceed / n
    assert_allclose([lo, hi], [ci.low, ci.high], rtol=1e-9)
    assert lo < p_true < hi
    assert_allclose(stats.exceedance_bounds(), [p, p, lo, hi], rtol=1e-12)


def figures(resolved, exceeds, sliding=None, increase=None):
    m = len(resolved)
    x = np.where(resolved, 0.1 if increase is None else increase, np.nan)
    return fr.FrictionState(
        baseline=np.where(resolved, 12.0, np.nan), increase_max=x, increase_mean=x / 2,
        ripple=x, contact_force_max=x * 7, contact_fraction=np.where(resolved, 0.5, np.nan),
        clusters_formed=np.where(resolved, 1.0, np.nan),
        worst_track=np.where(resolved, 0, -1), resolved=np.asarray(resolved),
        exceeds=np.asarray(exceeds),
        sliding=np.zeros(m, bool) if sliding is None else np.asarray(sliding),
        released=np.zeros(m, bool))


def test_exceedance_with_unresolved_assemblies_is_bounded():
    # Like P(contact) (tolsim.study.statistics.accumulator): k certain exceedances (two of them in
    # unresolved assemblies, e.g. sliding after an exceedance), u unresolved without one, N
    # in all: estimate k / (N - u) with the exact interval, bounds [k/N, (k + u)/N] with the
    # CP lower end of k of N and upper end of k + u of N (scipy.stats.binomtest, 1e-9).
    n, k_resolved, k_unresolved, u = 400, 30, 2, 25
    resolved = np.arange(n) >= u + k_unresolved
    exceeds = np.zeros(n, bool)
    exceeds[u:u + k_unresolved] = True
    exceeds[u + k_unresolved:u + k_unresolved + k_resolved] = True
    stats = fs.FrictionStatistics(friction_increase_limit=0.05)
    stats.add(figures(resolved, exceeds))
    k = k_resolved + k_unresolved
    assert (stats.n_exceed, stats.n_unresolved, stats.n_resolved) == (k, u, n - u - 2)
    p, lo, hi = stats.exceedance_probability()
    ci = binomtest(k, n - u).proportion_ci(0.95, method="exact")
    assert p == k / (n - u)
    assert_allclose([lo, hi], [ci.low, ci.high], rtol=1e-9)
    low, high, ci_low, ci_high = stats.exceedance_bounds()
    assert (low, high) == (k / n, (k + u) / n)
    assert_allclose(ci_low, binomtest(k, n).proportion_ci(method="exact").low, rtol=1e-9)
    assert_allclose(ci_high, binomtest(k + u, n).proportion_ci(method="exact").high, rtol=1e-9)
    # no limit: no probability
    assert np.isnan(fs.FrictionStatistics().exceedance_probability()[0])


def test_statistics_merge_and_state_round_trip(rng):
    # Merging block by block gives the same counts and histograms as one add, the moments to
    # 1e-12 (Chan et al.); state() -> from_state() restores every array exactly.
    m = 1000
    resolved = rng.random(m) > 0.1
    inc = rng.lognormal(-3.0, 1.0, m)
    one = fs.FrictionStatistics(0.1)
    one.add(figures(resolved, resolved & (inc > 0.1), increase=inc))
    blocks = fs.FrictionStatistics(0.1)
    for sl in (slice(0, 300), slice(300, 301), slice(301, m)):
        blocks.add(figures(resolved, resolved & (inc > 0.1), increase=inc).rows(sl))
    for name in ("n_assemblies", "n_resolved", "n_exceed", "count", "histogram", "minimum",
                 "maximum"):
        assert_array_equal(getattr(one, name), getattr(blocks, name))
    assert_allclose(blocks.mean, one.mean, rtol=1e-12)
    assert_allclose(blocks.m2, one.m2, rtol=1e-12)
    # quantiles within one bin (4.7 %) of the empirical ones, exact at the ends
    x = np.sort(inc[resolved])
    assert_allclose(blocks.quantiles("increase_max", (0.5, 0.9)), np.quantile(x, [0.5, 0.9]),
                    rtol=0.05)
    assert_allclose(blocks.quantiles("increase_max", (0.0, 1.0)), [x[0], x[-1]], rtol=1e-15)
    # a majority without contact: the median is "no force", exactly 0 (first bin)
    zeros = fs.FrictionStatistics(0.1)
    zeros.add(figures(resolved, resolved & (inc > 0.1), increase=np.where(inc < 0.1, 0.0, inc)))
    assert np.mean(inc[resolved] < 0.1) > 0.6
    assert zeros.quantiles("increase_max", (0.5,))[0] == 0.0
    assert zeros.quantiles("increase_max", (0.9,))[0] > 0.1
    back = fs.FrictionStatistics.from_state(blocks.state())
    for name in fs.FrictionStatistics.FIELDS:
        assert_array_equal(getattr(back, name), getattr(blocks, name))


# --------------------------------------------------------------------------------------------
# The study: reproducibility, invariance, invariants
# --------------------------------------------------------------------------------------------
def friction_yaw(samples=600, block=64, sensitivity=0):
    c = load_config(CONFIGS / "friction_yaw.toml")
    c = with_study_settings(c, block_size=block, spot_checks=0,
                            sensitivity_samples=sensitivity)
    return c.with_overrides(samples=samples)


def assert_same_statistics(a, b):
    sa, sb = a.statistics.state(), b.statistics.state()
    assert sorted(sa) == sorted(sb)
    for key in sa:
        assert_array_equal(sa[key], sb[key], err_msg=key)


def test_bit_identical_across_chunking_and_resume(tmp_path):
    c = friction_yaw()
    a = run_study(c, chunk_blocks=1)
    b = run_study(c, chunk_blocks=4)
    assert isinstance(a.statistics, fs.FrictionAccumulator)
    assert any(k.startswith("friction_") for k in a.statistics.state())
    assert_same_statistics(a, b)
    ckpt = tmp_path / "run.partial"
    with pytest.raises(StudyInterrupted):
        run_study(c, chunk_blocks=2, checkpoint_path=str(ckpt), max_blocks=2)
    resumed = run_study(c, chunk_blocks=3, checkpoint_path=str(ckpt))
    assert resumed.resumed_blocks == 2
    assert_same_statistics(a, resumed)
    for name in ("assembly", "friction_force", "ball_position", "contact_force"):
        assert_array_equal(getattr(a.friction_examples, name),
                           getattr(resumed.friction_examples, name))
    da, dr = result_to_dataset(a), result_to_dataset(resumed)
    xr.testing.assert_identical(da.drop_attrs(), dr.drop_attrs())


@pytest.mark.parametrize("window", [1, 3, 1000])
def test_examples_do_not_depend_on_the_window(monkeypatch, window):
    # The examples are the first assemblies of block 0 whose worst track touches (then the
    # first without contact); looking at the first EXAMPLE_WINDOW assemblies first, and at
    # the whole block only if too few of them touch, changes nothing (the reference: the
    # default window of 128, enough of them touch; 1 and 3: too few, then the whole block;
    # 1000: the whole block at once).
    c = friction_yaw(samples=256, block=128)
    reference = fx.friction_examples(c)
    monkeypatch.setattr(fx, "EXAMPLE_WINDOW", window)
    again = fx.friction_examples(c)
    for name in ("assembly", "track", "travel", "baseline", "friction_force", "contact_force",
                 "ball_position"):
        assert_array_equal(getattr(again, name), getattr(reference, name), err_msg=name)
    assert len(reference.assembly) == 4 and np.all(np.diff(reference.assembly) > 0)
    assert np.all(np.ptp(reference.friction_force, axis=1) > 0)  # they touch


EXAMPLE_FIELDS = ("assembly", "track", "travel", "baseline", "friction_force", "contact_force",
                  "ball_position")


@pytest.mark.parametrize("propagation", ["constant", "along_track"])
def test_examples_follow_only_the_assemblies_the_study_chose(monkeypatch, tmp_path,
                                                            propagation):
    # The study keeps the examples it chose from its own evaluation of block 0 (run_chunk);
    # friction_examples then follows again only the assemblies up to the last chosen one,
    # not a window of EXAMPLE_WINDOW (or the whole block): the same examples, bit for bit,
    # as friction_examples choosing them itself, also when resumed from a checkpoint written
    # after block 0. A wrong choice passed in is not taken: its
    # prefix chooses other examples, and the window's are returned.
    c = friction_yaw(samples=256, block=128)
    if propagation == "along_track":
        c = replace(c, study=replace(c.study, propagation="along_track", time_steps=40))
    reference = fx.friction_examples(c)
    sizes = []
    first = fx._first_assemblies

    def spy(block, count):
        sizes.append(count)
        return first(block, count)

    monkeypatch.setattr(fx, "_first_assemblies", spy)
    result = run_study(c)
    last = int(result.friction_examples.assembly.max())
    assert sizes == [last + 1] and last + 1 < fx.EXAMPLE_WINDOW
    for name in EXAMPLE_FIELDS:
        assert_array_equal(getattr(result.friction_examples, name),
                           getattr(reference, name), err_msg=name)
    sizes.clear()  # a run resumed from a checkpoint: the choice is in it
    with pytest.raises(StudyInterrupted):
        run_study(c, chunk_blocks=1, checkpoint_path=str(tmp_path / "run.partial"),
                  max_blocks=1)
    assert sizes == []
    resumed = run_study(c, chunk_blocks=1, checkpoint_path=str(tmp_path / "run.partial"))
    assert resumed.resumed_blocks == 1 and sizes == [last + 1]
    for name in EXAMPLE_FIELDS:
        assert_array_equal(getattr(resumed.friction_examples, name),
                           getattr(reference, name), err_msg=name)
    sizes.clear()
    wrong = fx.friction_examples(c, order=reference.assembly[::-1])
    assert sizes == [last + 1, fx.EXAMPLE_WINDOW]
    for name in EXAMPLE_FIELDS:
        assert_array_equal(getattr(wrong, name), getattr(reference, name), err_msg=name)


def test_no_contact_section_changes_nothing(tmp_path):
    # Without [contact] the accumulator, the checkpoint and the file are today's: no friction
    # state or variable. With it, every other variable is bit-identical (the friction adds
    # variables and changes nothing else, Sobol' indices of epsilon and contact included).
    with_contact = friction_yaw(samples=300, sensitivity=8)
    text = with_contact.text.split("\n[contact]")[0]
    text = text[:text.rindex("# After contact")]
    without = replace(with_contact, text=text, contact=None)
    assert parse_config(text).contact is None
    a, b = run_study(without), run_study(with_contact)
    assert type(a.statistics) is Accumulator and a.friction is None
    assert a.friction_examples is None
    assert not any(k.startswith("friction_") for k in a.statistics.state())
    da, db = result_to_dataset(a), result_to_dataset(b)
    extra = set(db.variables) - set(da.variables)
    assert not set(da.variables) - set(db.variables)
    assert extra == {*FRICTION_VARIABLES, *FRICTION_COORDINATES}
    assert "sensitivity_friction_total" in extra
    for name in da.data_vars:
        xr.testing.assert_identical(da[name].drop_attrs(), db[name].drop_attrs())
    assert "friction_assumptions" not in da.attrs and "friction_assumptions" in db.attrs


def test_paper_mitigated_matched_deviations_no_contact_zero_increase():
    # [Lin2018] Sec. 3.2 case (b): dbeta_TR = dbeta_BL, dbeta_TL = dbeta_BR gives epsilon = 0
    # for both balls (Eq. 24), so they never touch: no contact force, zero increase, zero
    # ripple, no exceedance of any limit (exact zeros), baseline = 2 F_0 of the loaded balls.
    c = load_config(CONFIGS / "paper_mitigated.toml")
    text = c.text + "\n[contact]\nfriction_increase_limit_N = 1e-9\n"
    result = run_study(parse_config(text, "paper_mitigated_contact.toml"))
    stats = result.friction
    assert result.statistics.n_contact == 0
    assert stats.n_resolved == stats.n_assemblies == 16 and stats.n_exceed == 0
    for name in ("increase_max", "increase_mean", "ripple", "contact_force_max",
                 "contact_fraction", "clusters_formed"):
        j = fs.COLUMNS.index(name)
        assert stats.minimum[j] == stats.maximum[j] == 0.0, name
    assert stats.exceedance_probability()[0] == 0.0
    assert_array_equal(stats.quantiles("increase_max"), 0.0)
    assert 2.0 < stats.maximum[0] < 3.0  # two balls of about 1.2 N each


SWAP = {"BL": "BR", "BR": "BL", "TR": "TL", "TL": "TR"}


def mirrored(config):
    """The x-mirror of a study (x -> -x: BL <-> BR, TR <-> TL): side loads and the (fixed)
    groove rotations change sign, an arc-centre offset moves to the mirrored contact with its
    sign (toward increasing beta). The tolerances keep their order, so a ball source draws
    the same numbers (tolsim.study.sampling draws the ball sources in config order)."""
    def mirror(t):
        if t.source[-2:] in SWAP:
            return replace(t, source=t.source[:-2] + SWAP[t.source[-2:]])
        return replace(t, distribution=replace(t.distribution, value=-t.distribution.value))

    tolerances = tuple(mirror(t) for t in config.tolerances)
    loads = replace(config.loads, side_load=tuple(-x for x in config.loads.side_load),
                    yaw_moment=-config.loads.yaw_moment)
    return replace(config, tolerances=tolerances, loads=loads)


def test_mirrored_assembly_gives_the_same_friction():
    # Mirroring the cross-section (x -> -x) leaves every quantity along z unchanged
    # (tests/physics/test_ball_push.py::test_mirror_analytic: epsilon to 1e-12, K, F_c and the
    # slopes to 1e-9 relative), so the mirrored trains have the same contact forces and
    # friction figures: per assembly to 1e-9 relative, and the same counts. Gaps and a
    # per-ball arc-centre offset are random (the same draws in both), rotations and loads
    # fixed.
    text = (open(CONFIGS / "yaw_moment_tolerances.toml").read().split("# Rail (bottom")[0]
            + """
[tolerances.bottom_rotation]
distribution = "fixed"
value_deg = 0.3
[tolerances.top_rotation]
distribution = "fixed"
value_deg = -0.1
[tolerances.arc_centre_offset_tangential_BL]
distribution = "normal"
std_um = 1.0
scope = "ball"
[study]
samples = 256
seed = 3
block_size = 256
static_model = "paired"
[contact]
friction_increase_limit_N = 0.1
""")
    c = parse_config(text)
    block = sample_block(c, 0)
    state = fx._evaluate_assemblies(c, block)
    a = fr.evaluate_friction(c, block.initial_gap, state)
    m = mirrored(c)
    mstate = fx._evaluate_assemblies(m, sample_block(m, 0))
    assert_array_equal(mstate.contact_angle_deviation,
                       state.contact_angle_deviation[..., [1, 0, 3, 2]])
    b = fr.evaluate_friction(m, block.initial_gap, mstate)
    assert a.resolved.all() and 0 < np.mean(a.contact_fraction > 0) < 1
    assert 0 < a.exceeds.sum() < len(a.exceeds)
    assert_array_equal(a.resolved, b.resolved)
    assert_array_equal(a.clusters_formed, b.clusters_formed)
    assert_array_equal(a.exceeds, b.exceeds)
    assert_allclose(b.columns(), a.columns(), rtol=1e-9, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Unresolved, sliding, several tracks
# --------------------------------------------------------------------------------------------
def test_train_inputs_kernel_matches_numpy_twin(rng):
    # NaN K (and c = 0) for a ball that leaves its train unresolved: epsilon, c, F_0, a or
    # b not finite, K NaN or < 0, or a finite K with |c K| >= 1 (tolsim.physics.trains refuses
    # |c K| >= 1); an anchor (K = inf) and a pushed ball (K = 0, issue 25) keep K with c = 0;
    # exact.
    m, n = 300, 6
    eps = rng.normal(0.0, 1e-3, (m, n))
    load = rng.normal(0.0, 1.0, (m, n, len(LOAD_COLUMNS)))
    load[:, :, fr._K] = rng.choice([700.0, -5.0, 0.0, np.nan, np.inf], (m, n),
                                   p=[0.8, 0.05, 0.05, 0.05, 0.05])
    load[:, :, fr._C] = rng.choice([1e-5, 2e-3, np.nan], (m, n), p=[0.9, 0.05, 0.05])
    load[rng.random((m, n)) < 0.05, fr._A] = np.nan
    eps[rng.random((m, n)) < 0.05] = np.nan
    k, c = np.empty((m, n)), np.empty((m, n))
    fr.train_inputs_kernel(eps, load, k, c)
    with np.errstate(invalid="ignore"):
        kk, cc = load[:, :, fr._K], load[:, :, fr._C]
        fixed = (kk == np.inf) | (kk == 0.0)
        ok = (np.isfinite(eps) & (fixed | (np.isfinite(kk) & (kk > 0) & (np.abs(cc * kk) < 1)))
              & np.isfinite(cc)
              & np.all(np.isfinite(load[:, :, [fr._F0, fr._A, fr._B]]), axis=2))
    assert 0.3 < ok.mean() < 0.9 and (ok & fixed).any()
    assert_array_equal(k, np.where(ok, kk, np.nan))
    assert_array_equal(c, np.where(ok, np.where(fixed, 0.0, cc), 0.0))


def test_unresolved_ball_makes_the_assembly_unresolved():
    # A ball without epsilon (unresolved in tolsim.study.pipeline.evaluate) leaves its train, and so
    # its assembly, unresolved: NaN figures, counted, never dropped.
    c = two_balls(limit="friction_increase_limit_N = 0.01")
    block = sample_block(c, 0)
    state = fx._evaluate_assemblies(c, block)
    state.velocity_deviation[3, 1] = np.nan
    state.valid[3, 1] = False
    out = fr.evaluate_friction(c, block.initial_gap, state)
    assert_array_equal(out.resolved, np.arange(8) != 3)
    assert np.isnan(out.increase_max[3]) and out.worst_track[3] == -1
    stats = fs.FrictionStatistics.for_config(c)
    stats.add(out)
    assert (stats.n_assemblies, stats.n_resolved, stats.n_unresolved) == (8, 7, 1)
    low, high, _, _ = stats.exceedance_bounds()
    assert (low, high) == (7 / 8, 1.0)  # the resolved ones exceed 0.01 N (k Q = 0.12 N)


def test_sliding_train_is_unresolved_and_bounded(monkeypatch):
    # A ball whose push reaches its traction capacity slides: the train is unresolved from
    # the onset; its increase before the onset is a lower bound of its maximum, so an
    # exceedance before it is certain. With the traction capacity lowered to 0.1 N (the
    # contact force of these balls is ~0.9 N) every train that touches slides at contact,
    # before any increase: no certain exceedance, the touching trains are unresolved.
    original = fr.CREEP_MODELS["analytic"]

    def weak(*args):
        load = original(*args)
        load[:, fr._PCAP] = 0.1
        return load

    monkeypatch.setitem(fr.CREEP_MODELS, "analytic", weak)
    gap = '{ distribution = "uniform", low_um = 0.0, high_um = 100.0 }'
    result = run_study(two_balls(gap=gap, samples=500, block=100,
                                 limit="friction_increase_limit_N = 0.01"))
    stats, contacts = result.friction, int(result.statistics.n_contact)
    assert 0 < contacts < 500
    assert stats.n_sliding == contacts == stats.n_unresolved
    assert stats.n_exceed == 0 and stats.n_resolved == 500 - contacts
    low, high, _, _ = stats.exceedance_bounds()
    assert (low, high) == (0.0, contacts / 500)
    assert stats.maximum[fs.COLUMNS.index("contact_force_max")] == 0.0


def test_carriage_reports_the_worst_track():
    # A study with a [carriage] (issue 12): the row of an assembly is its track with the
    # largest increase (ties: the larger baseline). Checked against each track followed
    # alone (a one-track study of the same balls), to the last bit.
    c = load_config(CONFIGS / "carriage_preload.toml")
    text = c.text + "\n[contact]\n"
    c = parse_config(text, "carriage_contact.toml").with_overrides(samples=24)
    c = with_study_settings(c, block_size=24, propagation="constant")
    block = sample_block(c, 0)
    state = fx._evaluate_assemblies(c, block)
    out = fr.evaluate_friction(c, block.initial_gap, state)
    tracks, n = c.n_tracks, c.train.balls
    assert tracks > 1 and out.resolved.all()
    single = replace(c, carriage=None)
    per_track = []
    for k in range(tracks):
        balls = slice(k * n, (k + 1) * n)
        sub = BallState(state.velocity_deviation[:, balls], state.valid[:, balls],
                        state.converged[:, balls], state.loss_of_contact[:, balls],
                        state.contact_angle_deviation[:, balls], state.normal_force[:, balls],
                        state.model[:, balls])
        gaps = block.initial_gap[:, k * (n - 1):(k + 1) * (n - 1)]
        per_track.append(fr.evaluate_friction(single, gaps, sub))
    inc = np.stack([t.increase_max for t in per_track], axis=1)
    base = np.stack([t.baseline for t in per_track], axis=1)
    key = np.where(inc == inc.max(axis=1, keepdims=True), base, -np.inf)
    assert_array_equal(out.worst_track, np.argmax(key, axis=1))
    rows = np.arange(len(inc))
    assert_array_equal(out.increase_max, inc[rows, out.worst_track])
    assert_array_equal(out.baseline, base[rows, out.worst_track])


# --------------------------------------------------------------------------------------------
# Config, file, CLI
# --------------------------------------------------------------------------------------------
def test_friction_yaw_config_and_file(tmp_path):
    # configs/friction_yaw.toml (seeded): every assembly resolved, no sliding (the contact
    # forces, a few N, are far below the ~56 N traction capacity), an uncertain exceedance of
    # the 0.2 N limit, the baseline of 10 balls of about 1.2 N (the nominal 1.227 N, to 3 %),
    # and the file round trip (schema-validated netCDF).
    result = run_study(friction_yaw(samples=512, block=128, sensitivity=8))
    stats = result.friction
    assert stats.n_resolved == 512 and stats.n_sliding == 0
    assert 0.0 < stats.exceedance_probability()[0] < 0.5
    assert_allclose(stats.column_mean("baseline"), 12.27, rtol=0.03)
    assert 0.5 < stats.maximum[fs.COLUMNS.index("contact_force_max")] < 10.0
    assert "friction_increase" in result.sensitivity.outputs
    path = tmp_path / "friction.nc"
    ds = write_result(result, path)
    back = read_result(path)
    xr.testing.assert_allclose(ds.drop_attrs(), back.drop_attrs())
    assert back.example_ball_position.dims == ("example", "travel", "ball")
    assert back.example_friction_force.shape == (4, 201)
    assert back.friction_increase_histogram.sum() == 512
    assert back.attrs["contact_creep_model"] == "analytic"


def test_run_summary_reports_friction(tmp_path, capsys):
    cfg = tmp_path / "friction.toml"
    cfg.write_text((CONFIGS / "friction_yaw.toml").read_text()
                   .replace("sensitivity_samples = 1024", "sensitivity_samples = 0")
                   .replace("spot_checks = 50", "spot_checks = 0"))
    assert main(["run", str(cfg), "-o", str(tmp_path / "f.nc"), "--samples", "256"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.startswith("friction"))
    assert "increase median" in line and "99 %" in line
    assert any(x.startswith("P(friction increase > 0.2 N) = ") and "95 % CI" in x
               for x in out.splitlines())


BAD_CONTACT = [
    ("ball_friction_coefficient = -0.1", "contact.ball_friction_coefficient"),
    ("friction_increase_limit_N = 0", "contact.friction_increase_limit_N"),
    ("friction_increase_limit_N = -1", "contact.friction_increase_limit_N"),
    ("friction_increase_limit = 1", "contact.friction_increase_limit"),
    ("creep_model = \"exact\"", "contact.creep_model"),
    ("examples = -1", "contact.examples"),
    ("travel_points = 1", "contact.travel_points"),
    ("friction = 0.1", "contact.friction"),
]


@pytest.mark.parametrize(("line", "key"), BAD_CONTACT)
def test_bad_contact_keys_exit_2_one_line(tmp_path, capsys, line, key):
    cfg = tmp_path / "bad.toml"
    base = (CONFIGS / "friction_yaw.toml").read_text().split("\n[contact]")[0]
    cfg.write_text(f"{base}\n[contact]\n{line}\n")
    out = tmp_path / "bad.nc"
    assert main(["run", str(cfg), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and key in err and "bad.toml:" in err
    assert not out.exists()


def test_contact_settings_validate():
    # The Python API refuses what the config reader refuses (one line naming the field).
    # Both propagations are accepted (along_track: tests/study/test_friction_along_track.py).
    from tolsim.study.spec import ContactSettings

    for field, value in (("ball_friction_coefficient", -0.1), ("creep_model", "exact"),
                         ("travel_points", 1), ("friction_increase_limit", np.nan)):
        with pytest.raises(ValueError, match=field):
            ContactSettings(**{field: value})
    c = two_balls()
    c = with_study_settings(c, propagation="along_track")
    assert isinstance(fs.study_accumulator(c), fs.FrictionAccumulator)


@pytest.mark.parametrize(("old", "new", "key"), [
    ("friction_coefficient = 0.1", "friction_coefficient = 0.0",
     "bearing.friction_coefficient"),
])
def test_contact_needs_raceway_friction(old, new, key):
    text = (CONFIGS / "friction_yaw.toml").read_text().replace(old, new, 1)
    assert text != (CONFIGS / "friction_yaw.toml").read_text()
    with pytest.raises(ValueError, match=key) as info:
        parse_config(text, "f.toml")
    assert "\n" not in str(info.value)


def test_released_trains_are_counted_apart_from_sliding_ones():
    # Why a train stops (friction_kernels.slides): a ball beyond a capacity (SLIDING) or,
    # none such, a ball pushed past a release push (RELEASED). Per assembly (three tracks):
    # sliding when some track slid, released when none slid but some was released; so the
    # two counts add up to the assemblies that were counted as sliding before they were told
    # apart (exact counts; merged block by block, kept in a checkpoint, and written to the
    # result file as n_assemblies_sliding and n_assemblies_released).
    rolling, sliding, released = fr.ROLLING, fr.SLIDING, fr.RELEASED
    onset = np.array([[rolling, rolling, rolling], [sliding, rolling, rolling],
                      [released, rolling, rolling], [released, sliding, rolling],
                      [released, released, rolling], [rolling, rolling, rolling]])
    m = len(onset)
    ok = (onset == rolling).reshape(-1)
    config = SimpleNamespace(n_tracks=3, contact=SimpleNamespace(friction_increase_limit=0.0))
    ones = np.ones(3 * m)
    rows = fr._worst_tracks(config, m, track_ok=ok, baseline=ones, increase_max=ones,
                            increase_mean=ones, ripple=ones, contact_force_max=ones,
                            contact_fraction=ones, clusters_formed=ones, bounded=~ok,
                            rolling=ones, onset=onset.reshape(-1))
    assert_array_equal(rows.sliding, [False, True, False, True, False, False])
    assert_array_equal(rows.released, [False, False, True, False, True, False])
    assert_array_equal(rows.sliding | rows.released, (onset != rolling).any(axis=1))
    stats = fs.FrictionStatistics()
    stats.add(rows.rows(slice(0, 3)))
    stats.add(rows.rows(slice(3, None)))
    again = fs.FrictionStatistics.from_state(stats.state())
    for s in (stats, again):
        assert (s.n_sliding, s.n_released, s.n_resolved, s.n_unresolved) == (2, 2, 2, 4)
    old = {k: v for k, v in stats.state().items() if k != "n_released"}
    assert fs.FrictionStatistics.from_state(old).n_released == 0  # a checkpoint from before
    assert FRICTION_VARIABLES["n_assemblies_released"][:2] == ((), "1")
