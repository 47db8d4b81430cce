"""A study with a closed-form answer: no train is left out of P(contact).

``configs/known_answer.toml``: [Lin2018] Sec. 3.2's two balls (rho = -0.6 trailing, +0.6
leading, N_y = 200 N, paired forces, gap 0.5 mm, v = 10 mm/s, 10 s) with a normal rail
rotation theta ~ N(0, sigma). dbeta = (-theta, +theta, 0, 0) ([Lin2018] Sec. 3.1, Fig. 6), and
eps_1 - eps_2 grows with theta, so the pair touches within the horizon iff theta >= theta*,
where (eps_1 - eps_2)(theta*) v / 2 * T = gap. Hence P(contact) = 1 - Phi(theta* / sigma)
(the issue's case: 0.2535 at sigma = 2 deg). theta* is found here by root-finding on the public
physics functions, with the model that evaluates a ball at the threshold: the fast model where
its validity flag holds there, the full model otherwise. Every sampled train must count: the
balls with large theta (outside the fast models' validity) go to the full model.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.optimize import brentq
from scipy.stats import norm

from tolsim.io.config import load_config
from tolsim.physics.geometry import paired_forces
from tolsim.physics.velocity import analytic as A
from tolsim.physics.velocity.full import full
from tolsim.study.execution.runner import run_study
from tolsim.study.statistics.intervals import clopper_pearson_interval

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "known_answer.toml"
GAP, SPEED, HORIZON = 0.5e-3, 0.01, 10.0  # configs/known_answer.toml
RHO, NY = (-0.6, 0.6), 200.0
FAST = {"eq24": A.eq24, "analytic": A.analytic}


def ball_velocity_deviation(model, theta, rho):
    """epsilon of one ball: the fast model where it is valid, else the full model."""
    dbeta = np.array([-theta, theta, 0.0, 0.0])
    force = paired_forces(rho * NY, NY)
    if model in FAST:
        res = FAST[model](dbeta, force)
        if bool(res.valid):
            return float(res.velocity_deviation)
    res = full(dbeta, force)
    assert bool(res.valid)
    return float(res.velocity_deviation)


def threshold(model):
    """theta* [rad]: the rotation at which the pair closes the gap exactly at the horizon."""

    def closing(theta):
        e1, e2 = (ball_velocity_deviation(model, theta, r) for r in RHO)
        return (e1 - e2) * SPEED / 2 * HORIZON - GAP

    return brentq(closing, np.radians(0.5), np.radians(3.0), xtol=1e-12)


def test_threshold_of_the_issue():
    # The issue's figure, theta* = 1.327 deg, is Eq. (26) with ERRATA 2 (eps = (theta/2)
    # (1 - r^(2/3))/(1 + r^(2/3)), r = (1 + rho)/(1 - rho)): eps_1 - eps_2 = 2 eps_1 closes
    # 0.5 mm at 5 mm/s in 10 s when 2 eps_1 = 0.01. Closed form to 1e-3 deg.
    r = (1 - 0.6) / (1 + 0.6)
    slope = (1 - r ** (2 / 3)) / (1 + r ** (2 / 3))  # d eps_1 / d theta
    theta_formula = GAP / (SPEED / 2 * HORIZON) / slope
    assert_allclose(np.degrees(theta_formula), 1.327, atol=1e-3)
    # At that rotation the fast models are outside their error budget (|eps| ~ 0.5 %,
    # tolsim.physics.velocity.analytic), so the ball is evaluated by the full model, whose
    # threshold is
    # lower (full's eps is ~4.7 % larger, Table 2 case (a): 0.789 % against 0.754 %): measured
    # 1.2908 deg, and 1 - Phi(1.2908 / 2) = 0.2593 at sigma = 2 deg instead of 0.2535.
    for model in ("eq24", "analytic", "full"):
        assert_allclose(np.degrees(threshold(model)), 1.2908, atol=1e-3)


@pytest.mark.parametrize("model", ["eq24", "analytic", "full"])
@pytest.mark.parametrize("sigma_deg", [0.8, 2.0, 4.0])
def test_known_answer(model, sigma_deg):
    config = load_config(CONFIG).with_overrides(samples=4000 if model == "full" else 20000)
    tol = replace(config.tolerances[0],
                  distribution=replace(config.tolerances[0].distribution,
                                       std=np.radians(sigma_deg)))
    config = replace(config, tolerances=(tol,),
                     study=replace(config.study, velocity_model=model, spot_checks=0))
    acc = run_study(config).statistics
    truth = norm.sf(threshold(model) / np.radians(sigma_deg))
    n, k, u = int(acc.n_assemblies), int(acc.n_contact), int(acc.n_unresolved)
    assert n == config.study.samples  # every train counted
    # the truth lies in the 99.9 % interval that covers the partial-identification bounds
    # (Clopper-Pearson of k of N and of k + u of N; with u = 0 the plain interval)
    lo, _ = clopper_pearson_interval(k, n, 0.999)
    _, hi = clopper_pearson_interval(k + u, n, 0.999)
    assert lo <= truth <= hi, (model, sigma_deg, k, u, n, truth)
    # Unresolved trains are few: the full model does not converge beyond |theta| ~ 9-10 deg
    # (checked by hand: 8 deg converges, 10 deg does not), which at sigma = 4 deg is ~2 % of
    # the balls' rotations but only trains whose outcome is not already certain; measured
    # u / N = 0.46 % at sigma = 4 deg, 0 at 0.8 and 2 deg. Bound: 1 %.
    assert u <= 0.01 * n
    if sigma_deg < 4.0:
        assert u == 0
    if sigma_deg >= 2.0 and model != "full":  # big rotations leave the fast model's validity
        assert acc.n_resolved_full > 0
