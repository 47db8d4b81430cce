"""Every file in configs/ (and the packaged default) runs, seeded, with its expected outcome."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tolsim.io.config import load_config
from tolsim.study.execution.runner import run_study

CONFIGS = Path(__file__).resolve().parents[2] / "configs"

# Small sample counts keep this file fast; the full counts are in the files.
SAMPLES = {
    "paper_case_study.toml": None,
    "paper_mitigated.toml": None,
    "yaw_moment_tolerances.toml": 2000,
    "whatif_no_yaw_moment.toml": 1024,
    "whatif_along_track.toml": 200,
    "known_answer.toml": 4096,  # the closed-form checks are in tests/study/test_known_answer.py
    "friction_yaw.toml": 1024,  # its checks are in tests/study/test_friction_study.py
    "rare_contact.toml": 1024,  # subset simulation after; checks: tests/study/test_rare_study.py
    "allocate_example.toml": 1024,  # its allocation (tolsim allocate): tests/study/test_allocate.py
}
#: Configs with a [carriage] (issue 12): their studies are checked in
#: tests/study/test_carriage_study.py (and tests/io/test_cf_compliance.py runs them); here their
#: `tolsim carriage` load distribution.
CARRIAGE_CONFIGS = ("carriage_preload.toml", "carriage_circuit.toml")
#: What-if sweeps (issue 14): run, seeded, in tests/io/test_sweep.py.
SWEEP_CONFIGS = ("sweep_circuit.toml", "sweep_preload.toml", "sweep_rail_roll.toml",
                 "sweep_yaw_moment.toml")


def run(name, samples="default"):
    c = load_config(CONFIGS / name)
    n = SAMPLES[name] if samples == "default" else samples
    return run_study(c.with_overrides(samples=n) if n else c)


def test_every_config_is_covered():
    assert sorted(p.name for p in CONFIGS.glob("*.toml")) == sorted(
        [*SAMPLES, *CARRIAGE_CONFIGS, *SWEEP_CONFIGS])
    for name in CARRIAGE_CONFIGS:
        assert load_config(CONFIGS / name).carriage is not None
    for name in SWEEP_CONFIGS:
        assert load_config(CONFIGS / name).sweep is not None


def test_paper_case_study_contact_time():
    # [Lin2018] Sec. 3.2 case (a): epsilon from the formula, Eq. (26) with ERRATA 2,
    # eps_1 = (theta/2)(1 - r^(2/3))/(1 + r^(2/3)), r = (1 + rho)/(1 - rho), theta = 2 deg,
    # rho_1 = -0.6: +0.754 % (Table 2), eps_2 = -eps_1, and contact at
    # t = gap / ((eps_1 - eps_2) v / 2) with gap 0.1 R_B = 0.5 mm, v = 10 mm/s: 6.63 s.
    theta = np.radians(2.0)
    r = (1 - 0.6) / (1 + 0.6)
    eps1 = theta / 2 * (1 - r ** (2 / 3)) / (1 + r ** (2 / 3))
    assert_allclose(eps1, 0.00754, atol=5e-6)  # Table 2, "derived formula" 0.75 %
    assert_allclose(0.5e-3 / (2 * eps1 * 0.01 / 2), 6.63, atol=0.01)
    # Those balls lie outside Eq. (24)'s error budget (0.02 pp against the full model,
    # tolsim.physics.velocity.analytic): the study re-solves them with the full model, whose epsilon
    # for the same paired forces and angles is +-0.7889 % (tests/study/test_paper_data.py,
    # Table 2 case (a), paired forces), so contact comes earlier, at 6.34 s.
    from tolsim.physics.geometry import paired_forces
    from tolsim.physics.velocity.full import full

    eps_full = float(full([-theta, theta, 0, 0], paired_forces(-0.6 * 200, 200))
                     .velocity_deviation)
    assert_allclose(eps_full, 0.007889, atol=1e-6)
    t_expected = 0.5e-3 / (2 * eps_full * 0.01 / 2)
    res = run("paper_case_study.toml").statistics
    assert res.n_assemblies_valid == res.n_assemblies == 16  # deterministic: all identical
    assert res.n_resolved_full == res.n_balls == 32
    assert res.n_contact == 16
    assert_allclose(res.ball_mean, [eps_full, -eps_full], rtol=1e-12)
    assert_allclose([res.time_min, res.time_max], t_expected, rtol=1e-12)
    assert_allclose(t_expected, 6.34, atol=0.01)
    assert_allclose(res.time_to_contact_quantiles((0.5,)), t_expected, rtol=1e-12)


def test_paper_mitigated_no_contact():
    # [Lin2018] Sec. 3.2 case (b), Table 2: dbeta_TR = dbeta_BL, dbeta_TL = dbeta_BR gives
    # epsilon = 0 for both balls (exactly, by Eq. 24) and no contact.
    res = run("paper_mitigated.toml").statistics
    assert res.n_assemblies_valid == 16
    assert res.n_contact == 0
    assert_allclose(res.ball_mean, 0.0, atol=1e-18)
    p, lo, hi = res.contact_probability()
    assert p == 0 and lo == 0
    assert_allclose(hi, 1 - 0.025 ** (1 / 16), rtol=1e-9)  # Clopper-Pearson, k = 0


def test_yaw_moment_tolerances():
    c = load_config(CONFIGS / "yaw_moment_tolerances.toml")
    rho = c.loads.side_force_ratio
    # the yaw moment makes rho vary linearly along the train, antisymmetric about its centre
    assert_allclose(rho, -rho[::-1], atol=1e-12)
    assert np.all(np.diff(rho) > 0) and 0.3 < rho[-1] < 0.5
    res = run("yaw_moment_tolerances.toml")
    s = res.statistics
    assert s.n_balls_valid == s.n_balls == 20000
    p, lo, hi = s.contact_probability()
    assert 0.05 < lo <= p <= hi < 0.95  # a genuinely uncertain outcome
    assert 5e-4 < s.velocity_deviation_std < 5e-3
    # Spot checks: the analytic model against the full friction model on 50 seeded balls.
    # Measured RMS 2.9e-5 and max 7.7e-5 (of epsilon, i.e. < 0.01 percentage points);
    # tolerance 2e-4 max, a tenth of the paper's Table 2 gap (0.85 % vs 0.75 %, Leblanc vs
    # formula) at much larger angles and side forces.
    pytest.importorskip("tolsim.physics.velocity.full")
    sc = res.spot_checks
    both = sc.valid_analytic & sc.valid_full
    assert len(sc.ball_index) == 50 and both.sum() >= 45
    diff = sc.velocity_deviation_analytic[both] - sc.velocity_deviation_full[both]
    assert np.max(np.abs(diff)) < 2e-4


def test_whatif_no_yaw_moment():
    s = run("whatif_no_yaw_moment.toml").statistics
    assert s.n_assemblies == 1024 and s.n_balls_valid == s.n_balls
    assert 0 < s.n_contact < 1024


def test_whatif_along_track():
    res = run("whatif_along_track.toml")
    s = res.statistics
    assert res.config.study.propagation == "along_track"
    assert s.n_assemblies == 200 and s.n_assemblies_valid == 200
    assert 0 < s.n_contact < 200


def test_packaged_default_runs():
    c = load_config()
    s = run_study(c.with_overrides(samples=1000)).statistics
    assert s.n_assemblies == 1000 and s.n_balls_valid == s.n_balls
    assert 0 < s.n_contact < 1000


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_configs_are_reproducible(name):
    n = 64 if SAMPLES[name] else None
    a, b = run(name, n), run(name, n)
    for k, v in a.statistics.state().items():
        np.testing.assert_array_equal(v, b.statistics.state()[k])


@pytest.mark.parametrize("name", CARRIAGE_CONFIGS)
def test_carriage_configs_run_through_tolsim_carriage(name, capsys):
    # `tolsim carriage` solves the nominal assembly: converged, nothing locked, every ball
    # loaded; the vertical load moves the carriage down. (Balance and the JSON interface:
    # tests/cli/test_cli_carriage.py.)
    import json

    from tolsim.cli import main

    assert main(["carriage", str(CONFIGS / name), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["converged"] is True and out["locked"] == []
    assert all(max(b["normal_force_n"]) > 0 for b in out["balls"])
    assert out["displacement"]["u_y_um"] < 0


def test_carriage_preload_classes():
    # The comment table of configs/carriage_preload.toml: preload per contact K (o/2)^1.5
    # for o = 0, 2, 4 um (0, 23, 66 N) and the vertical stiffness under the file's load
    # (192, 419, 598 N/um, to the table's 3 digits) and the largest |rho| (1.00, 0.47, 0.17);
    # light and medium keep four-point contact, none closes one diagonal of each ball. The
    # P(contact) column is the study's (tests/study/test_carriage_study.py checks its direction).
    from dataclasses import replace

    from tolsim.physics.carriage import solve_carriage
    from tolsim.physics.hertz import hertz_constants

    c = load_config(CONFIGS / "carriage_preload.toml")
    assert c.carriage.preload_oversize == pytest.approx(2e-6, rel=1e-12)  # "light"
    b = c.bearing
    k = hertz_constants(b.ball_radius, b.conformity, b.youngs_modulus,
                        b.poisson_ratio).load_deflection_constant
    for o, preload, stiffness, contacts, rho in ((0.0, 0.0, 192, 2, 1.00),
                                                 (2e-6, 23, 419, 4, 0.47),
                                                 (4e-6, 66, 598, 4, 0.17)):
        assert round(k * (o / 2) ** 1.5) == preload
        carriage = replace(c.carriage, preload_oversize=o)
        sol = solve_carriage(carriage.layout, carriage.load, b, oversize=carriage.oversize)
        assert sol.converged
        assert round(sol.stiffness[1, 1] * 1e-6) == stiffness
        assert sol.contact_count.min() == contacts
        assert round(float(np.nanmax(np.abs(sol.side_force_ratio))), 2) == rho


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_the_histogram_of_epsilon_holds_its_1_and_99_percent_quantiles(name):
    # A quantile beyond the histogram's range is unknown (NaN in the file, "< -2.000 %" in the
    # summary): each packaged study sets a range that holds its 1 % and 99 % quantiles.
    # known_answer.toml needs +-6 %: its 1 % and 99 % quantiles are +-2.28 % (20 000 assemblies).
    acc = run(name).statistics
    q = acc.velocity_deviation_quantiles((0.01, 0.99))
    assert np.all(np.isfinite(q)), (name, q, acc.eps_underflow, acc.eps_overflow)
