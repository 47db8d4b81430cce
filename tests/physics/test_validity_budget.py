"""The validity thresholds of ``eq24`` and ``analytic`` hold their error budget against ``full``.

The thresholds in :mod:`tolsim.physics.velocity.analytic` were derived on a grid by
``benchmarks/validity_budget.py``. Here they are checked on balls the derivation never saw
(seeded random values between its grid points), and on a realistic population for speed:
a ball flagged invalid is re-solved with the full model in a study, so needlessly tight
thresholds cost time.
"""

import numpy as np
import pytest

from tolsim.physics.geometry import TABLE1
from tolsim.physics.static import GrooveErrors, solve_static
from tolsim.physics.velocity import analytic as A
from tolsim.physics.velocity.full import full

MODELS = {"analytic": A.analytic, "eq24": A.eq24}


def loaded_state(side_load, normal_load, errors):
    """dbeta, F of the balls whose static solve converged in four-point contact."""
    sol = solve_static(side_load, normal_load, errors, TABLE1)
    keep = sol.converged & sol.four_point
    return sol.contact_angle_deviation[keep], sol.normal_force[keep]


def fresh_balls(n, seed):
    """Random rho, loads, groove rotations and arc-centre / ball errors (not on the grid of
    benchmarks/validity_budget.py: continuous values, another seed), statically solved."""
    rng = np.random.default_rng(seed)
    rho = rng.uniform(-0.9, 0.9, n)
    ny = np.exp(rng.uniform(np.log(50.0), np.log(1000.0), n))
    # rotations up to 1 deg so that a good share of the balls is valid for both models
    tb, tt = rng.uniform(-np.deg2rad(1.0), np.deg2rad(1.0), (2, n))
    errors = GrooveErrors(
        bottom_rotation=tb, top_rotation=tt,
        arc_centre_offset_tangential=rng.uniform(-3e-6, 3e-6, (n, 4)),
        arc_centre_offset_normal=rng.uniform(-2e-6, 2e-6, (n, 4)),
        ball_oversize=rng.uniform(-0.5e-6, 0.5e-6, n))
    return loaded_state(rho * ny, ny, errors)


def realistic_balls(n, seed):
    """The tolerances of tolsim/data/default.toml (as benchmarks/validity_budget.py):
    theta_b ~ N(0, 0.1 deg), theta_t ~ N(0, 0.075 deg), tangential arc-centre offsets
    ~ N(0, 1 um), ball oversize ~ N(0, 0.1 um) clipped to +-0.25 um; N_y = 200 N, rho
    U(-0.4, 0.4) (the default yaw moment)."""
    rng = np.random.default_rng(seed)
    rho = rng.uniform(-0.4, 0.4, n)
    errors = GrooveErrors(
        bottom_rotation=rng.normal(0.0, np.deg2rad(0.1), n),
        top_rotation=rng.normal(0.0, np.deg2rad(0.075), n),
        arc_centre_offset_tangential=rng.normal(0.0, 1e-6, (n, 4)),
        ball_oversize=np.clip(rng.normal(0.0, 0.1e-6, n), -0.25e-6, 0.25e-6))
    return loaded_state(rho * 200.0, 200.0, errors)


@pytest.fixture(scope="module")
def fresh():
    dbeta, force = fresh_balls(1500, seed=20250101)
    ref = full(dbeta, force, TABLE1)
    return dbeta, force, ref


@pytest.mark.parametrize("name", sorted(MODELS))
def test_valid_balls_are_within_the_budget(fresh, name):
    # The budget VALIDITY_ERROR_BUDGET = 2e-4 (0.02 pp) is the statement, not a fit:
    # every valid ball with a converged full solution must be within it, no tolerance. The
    # grid maximum inside the thresholds was 1.99e-4 (analytic) and 1.96e-4 (eq24); on the
    # benchmark's 20 000 fresh balls (another seed) 1.48e-4 and 1.93e-4.
    dbeta, force, ref = fresh
    res = MODELS[name](dbeta, force)
    checked = res.valid & ref.converged
    err = np.abs(res.velocity_deviation - ref.velocity_deviation)[checked]
    # the check must bite: at least 100 of the ~1460 balls are valid (measured with this
    # seed: 363 for eq24, 454 for analytic; worst errors 1.81e-4 and 1.83e-4) and full
    # converged on them
    assert checked.sum() >= 100
    assert checked.sum() >= 0.95 * res.valid.sum()
    assert err.max() <= A.VALIDITY_ERROR_BUDGET, (
        f"{name}: {np.sum(err > A.VALIDITY_ERROR_BUDGET)} valid balls over the budget, "
        f"worst {err.max():.3g}")


def test_the_sample_exceeds_the_budget_outside_the_thresholds(fresh):
    # The sample probes the thresholds: many of its invalid balls are over the budget
    # (measured with this seed: 22 % for analytic, 27 % for eq24; limit 10 %).
    dbeta, force, ref = fresh
    for model in MODELS.values():
        res = model(dbeta, force)
        outside = ~res.valid & ref.converged
        err = np.abs(res.velocity_deviation - ref.velocity_deviation)[outside]
        assert np.mean(err > A.VALIDITY_ERROR_BUDGET) > 0.10


def test_thresholds_not_needlessly_tight_on_a_realistic_population():
    # Speed side of the trade: in a population with the default study's tolerances most balls
    # stay with the fast model (the thresholds were chosen, among those that hold the budget,
    # to keep the most of such a population: benchmarks/validity_budget.py, 20 000 balls,
    # seed 7: 100 % valid for analytic, 97.9 % for eq24). Here 2000 balls with another seed:
    # 100 % and 97.95 % (binomial standard error of the eq24 share 0.3 pp); the limits 0.99
    # and 0.95 sit 3 and 9 standard errors below. Balls flagged valid meet the budget here too
    # (worst 1.09e-4 and 7.9e-5).
    dbeta, force = realistic_balls(2000, seed=11)
    shares = {}
    ref = full(dbeta, force, TABLE1)
    for name, model in MODELS.items():
        res = model(dbeta, force)
        shares[name] = res.valid.mean()
        checked = res.valid & ref.converged
        err = np.abs(res.velocity_deviation - ref.velocity_deviation)[checked]
        assert err.max() <= A.VALIDITY_ERROR_BUDGET
    assert shares["analytic"] >= 0.99, shares
    assert shares["eq24"] >= 0.95, shares
