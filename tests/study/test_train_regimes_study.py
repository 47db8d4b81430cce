"""Trains with anchors and balls pushed along, through a study's friction (issue 25, item 3).

Three balls of the paper's bearing (Table 1) under paired forces (side force ratios -0.3, 0,
+0.3, bottom groove turned 0.5 deg): ball 0 is faster than ball 2. The middle ball is made
an exactly two-point ball (an anchor) or unloaded (pushed along) in the evaluated state, and
the friction figures are checked against closed forms: the cluster rule with anchors (eqs. 6a,
6b of tolsim.physics.trains), the two-point ball's F_c = (mu_bb S - P) / 2 (issue 25), the
pair braking from the actual rotations (tolsim.physics.trains.regimes.pair_braking), and the
single-ball coefficients of tolsim.physics.velocity.analytic.analytic. Tolerance 1e-12
relative (the study runs the same arithmetic in another order).
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.io.config import parse_config
from tolsim.physics.geometry import TABLE1, paired_forces
from tolsim.physics.trains.ball_minimum import stick_line_release, three_point_coefficients
from tolsim.physics.trains.regimes import rigid_rolling_rate, two_point_rolling_rate
from tolsim.physics.velocity.analytic import analytic
from tolsim.physics.velocity.models import (
    BALL_REGIME_B,
    BALL_THREE_POINT,
    BALL_TWO_POINT,
    BALL_UNLOADED,
)
from tolsim.study.pipeline import track_friction as fr
from tolsim.study.pipeline.block import evaluate_block
from tolsim.study.pipeline.propagation import FirstContact, FreeBalls, TrainMotion, integrate
from tolsim.study.sampling import sample_block
from tolsim.study.statistics.friction import FrictionStatistics

THREE_BALLS = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
friction_coefficient = 0.1
[motion]
groove_velocity_mm_per_s = 10.0
duration_s = 10.0
[train]
balls = 3
initial_gap = { distribution = "fixed", value_um = 5.0 }
[loads]
normal_load_N = 200.0
side_force_ratio = [-0.3, 0.0, 0.3]
[tolerances.bottom_rotation]
distribution = "fixed"
value_deg = 0.5
[study]
samples = 4
seed = 5
block_size = 4
velocity_model = "analytic"
static_model = "paired"
[contact]
ball_friction_coefficient = 0.1
"""
MU_BB = 0.1


def _setup():
    config = parse_config(THREE_BALLS, "three_balls.toml")
    block = sample_block(config, 0)
    state = evaluate_block(config, block, propagate=False).state
    theta = np.radians(0.5)
    dbeta = np.array([[-theta, theta, 0.0, 0.0]] * 2)  # balls 0 and 2, [Lin2018] Sec. 3.1
    force = np.array([paired_forces(rho * 200.0, 200.0) for rho in (-0.3, 0.3)])
    ref = analytic(dbeta, force, TABLE1, push=0.0, ball_friction=MU_BB)
    assert ref.velocity_deviation[0] > 0 > ref.velocity_deviation[1]
    return config, block, state, dbeta, force, ref


def test_unloaded_middle_ball_is_pushed_along_and_resolves():
    # The unloaded ball has no epsilon of its own: before issue 25's item 3 its train was
    # unresolved. Pushed along (K = 0) it closes both gaps at once and transmits the force:
    # the two soft balls act as a pair, Q = (eps_0 - eps_2) / (1/K_0 + 1/K_2 - c_0 + c_2); it
    # has no raceway friction and its pairs no ball-ball braking (Notes of pair_braking), so
    # the increase is (a_2 - a_0) Q (0 before contact: the maximum is max(0, that)).
    config, block, state, _, _, ref = _setup()
    state.velocity_deviation[:, 1] = np.nan
    state.valid[:, 1] = False
    state.regime[:, 1] = BALL_UNLOADED
    state.normal_force[:, 1, :] = 0.0
    out = fr.evaluate_friction(config, block.initial_gap, state)
    assert out.resolved.all()
    eps, k, c = ref.velocity_deviation, ref.creep_stiffness, ref.braking_sensitivity
    a = ref.carriage_force_per_push
    q = (eps[0] - eps[1]) / (1 / k[0] + 1 / k[1] - c[0] + c[1])
    assert_allclose(out.contact_force_max, q, rtol=1e-12)
    assert_allclose(out.increase_max, max((a[1] - a[0]) * q, 0.0), rtol=1e-12)
    assert_allclose(out.baseline, ref.free_rolling_carriage_force.sum(), rtol=1e-12)


def test_two_point_middle_ball_is_an_anchor():
    # The middle ball exactly two-point (BL and TR at 45 deg, eps = 0): ball 0 pushes it with
    # Q_01 = eps_0 / (1/K_0 - c_0), it pushes ball 2 with Q_12 = -eps_2 / (1/K_2 + c_2), and
    # the friction rises by k_01 Q_01 + k_12 Q_12 with k_01 = (-1/2 - a_0) + B_01,
    # k_12 = (a_2 + 1/2) + B_12, B = mu_bb |Omega + Omega'| R / v from the rotations.
    config, block, state, dbeta, force, ref = _setup()
    two = np.array([141.4, 0.0, 141.4, 0.0])
    state.velocity_deviation[:, 1] = 0.0
    state.valid[:, 1] = True
    state.regime[:, 1] = BALL_TWO_POINT
    state.normal_force[:, 1, :] = two
    state.contact_angle_deviation[:, 1, :] = 0.0
    out = fr.evaluate_friction(config, block.initial_gap, state)
    assert out.resolved.all() and not out.sliding.any()
    eps, k, c = ref.velocity_deviation, ref.creep_stiffness, ref.braking_sensitivity
    a = ref.carriage_force_per_push
    q01 = eps[0] / (1 / k[0] - c[0])
    q12 = -eps[1] / (1 / k[1] + c[1])
    spin = rigid_rolling_rate(dbeta, force, TABLE1)
    middle = two_point_rolling_rate(np.zeros((1, 4)), two[None, :], TABLE1)[0]
    b01 = MU_BB * np.hypot(*(spin[0] + middle))
    b12 = MU_BB * np.hypot(*(spin[1] + middle))
    first = ((-0.5 - a[0]) + b01) * q01
    second = ((a[1] + 0.5) + b12) * q12
    single = first if eps[0] > -eps[1] else second  # the pair that closes first
    assert_allclose(out.contact_force_max, max(q01, q12), rtol=1e-12)
    assert_allclose(out.increase_max, max(0.0, single, first + second), rtol=1e-12)
    assert_allclose(out.baseline, ref.free_rolling_carriage_force.sum(), rtol=1e-12)


class _FixedBalls(FreeBalls):
    """Free balls whose every evaluation is ``state`` (epsilon constant along the track)."""

    def __init__(self, config, block, state):
        super().__init__(config, block, state)
        self.fixed = state

    def evaluate(self, position, t):
        return self.fixed


def test_unloaded_middle_ball_along_the_track_gives_the_constant_trains():
    # The same train along the track (propagation = "along_track", the step rule of the
    # trains after contact, TrainMotion) with epsilon constant along it: the unloaded ball is
    # pushed along before and after contact, the train resolves, and its contact force and
    # friction increase are those of the constant propagation (evaluate_friction, the test
    # above). Tolerance 1e-9 relative (the step rule reaches the cluster's force exactly once
    # the gaps have closed; measured agreement to the printed 8 digits). Before, the friction
    # figures of such a train were unresolved (NaN).
    config, block, state, _, _, _ = _setup()
    state.velocity_deviation[:, 1] = np.nan
    state.valid[:, 1] = False
    state.regime[:, 1] = BALL_UNLOADED
    state.normal_force[:, 1, :] = 0.0
    constant = fr.evaluate_friction(config, block.initial_gap, state)
    along = parse_config(THREE_BALLS.replace(
        "[study]", '[study]\npropagation = "along_track"\ntime_steps = 100'), "along.toml")
    friction, first = fr.TrackFriction(along), FirstContact()
    frame = _FixedBalls(along, block, state)
    integrate(along, frame, [first, TrainMotion(friction, along.motion.groove_velocity)])
    out = friction.figures()
    assert np.isfinite(first.time).all() and frame.ball_ok.all()
    assert out.resolved.all()
    assert_allclose(out.contact_force_max, constant.contact_force_max, rtol=1e-9)
    assert_allclose(out.increase_max, constant.increase_max, rtol=1e-9)


def test_three_point_ball_behind_an_anchor_resolves():
    # Ball 0 made a three-point ball (case (a): bottom groove turned 2 deg, rho = -0.8 at
    # N_y = 200 N, BR open; eps 2.03 %), ball 1 the two-point anchor of the test above. Before
    # issue 25's three-point coefficients the train was unresolved (the creep model has none
    # with an open contact). Now ball 0 pushes the anchor with Q_01 = eps_0 / (1/K_0 -
    # c_front), c_front = gamma_0 . W_hat_01 its response to a moment along the pair's actual
    # rotation (T4 of tolsim.physics.trains.regimes.directional_braking), K_0 and gamma_0 from
    # three_point_coefficients; ball 2 (regime A) is pushed with Q_12 = -eps_2 / (1/K_2 +
    # c_2 Omega_hat_2 . W_hat_12); the friction rises by k_01 Q_01 + k_12 Q_12 with
    # k_01 = (-1/2 - a_0) + mu_bb |Omega_0 + Omega_1| R / v, a_0 = -(1 + eps_0) / 2 (T3).
    # Tolerance 1e-12 relative, as above.
    config, block, state, dbeta, force, ref = _setup()
    theta = np.radians(2.0)
    d0 = np.array([-theta, theta, 0.0, 0.0])
    f0 = np.array(paired_forces(-0.8 * 200.0, 200.0))
    f0[1] = 0.0
    cols, rate0 = three_point_coefficients(d0[None], f0[None], TABLE1, ball_friction=MU_BB)
    two = np.array([141.4, 0.0, 141.4, 0.0])
    for ball, (eps, regime, f, d) in enumerate(
            [(cols["free_rolling_velocity_deviation"][0], BALL_THREE_POINT, f0, d0),
             (0.0, BALL_TWO_POINT, two, np.zeros(4))]):
        state.velocity_deviation[:, ball] = eps
        state.valid[:, ball] = True
        state.regime[:, ball] = regime
        state.normal_force[:, ball, :] = f
        state.contact_angle_deviation[:, ball, :] = d
    out = fr.evaluate_friction(config, block.initial_gap, state)
    assert out.resolved.all() and not out.sliding.any()
    middle = two_point_rolling_rate(np.zeros((1, 4)), two[None, :], TABLE1)[0]
    spin2 = rigid_rolling_rate(dbeta[1:], force[1:], TABLE1)[0]
    w01, w12 = rate0[0] + middle, spin2 + middle
    u01, u12 = w01 / np.hypot(*w01), w12 / np.hypot(*w12)
    gamma0 = np.array([cols["braking_vector_x"][0], cols["braking_vector_y"][0]])
    eps0, k0 = cols["free_rolling_velocity_deviation"][0], cols["creep_stiffness"][0]
    c2 = ref.braking_sensitivity[1] * (spin2 / np.hypot(*spin2)) @ u12
    q01 = eps0 / (1 / k0 - gamma0 @ u01)
    q12 = -ref.velocity_deviation[1] / (1 / ref.creep_stiffness[1] + c2)
    first = ((-0.5 + 0.5 * (1 + eps0)) + MU_BB * np.hypot(*w01)) * q01
    second = ((ref.carriage_force_per_push[1] + 0.5) + MU_BB * np.hypot(*w12)) * q12
    assert_allclose(out.contact_force_max, max(q01, q12), rtol=1e-12)
    assert_allclose(out.increase_max, max(0.0, first, first + second), rtol=1e-12)
    assert_allclose(out.baseline, cols["free_rolling_carriage_force"][0]
                    + ref.free_rolling_carriage_force[1], rtol=1e-12)


def test_regime_b_ball_pushed_past_its_release_is_unresolved():
    # The middle ball in regime B (case (a), theta = 2 deg, N_y = 200 N), ball 0 made faster
    # (epsilon 1 %): the pair 0-1 closes and pushes the middle ball forward with Q = 6.66 N
    # (the cluster rule, K_B = 3.3e4 N). At rho = -0.9 its stuck contact lets go at +2.95 N
    # (stick_line_release; stick_release +2.94 N, issue 25), so its K no longer holds and the
    # train is unresolved from that step on (counted as released, apart from the sliding
    # ones, bounded, never dropped); at rho = -0.95 the release is +33.5 N and the train
    # stays resolved.
    theta = np.radians(2.0)
    dbeta = np.array([-theta, theta, 0.0, 0.0])
    for rho, released in ((-0.9, True), (-0.95, False)):
        config, block, state, _, _, _ = _setup()
        force = np.array(paired_forces(rho * 200.0, 200.0))
        _, release, res = stick_line_release(dbeta[None], force[None], TABLE1)
        state.velocity_deviation[:, 0] = 0.01
        state.velocity_deviation[:, 1] = res.velocity_deviation[0]
        state.valid[:, 1] = True
        state.regime[:, 1] = BALL_REGIME_B
        state.normal_force[:, 1, :] = force
        state.contact_angle_deviation[:, 1, :] = dbeta
        out = fr.evaluate_friction(config, block.initial_gap, state)
        assert out.released.all() == released and out.resolved.all() != released
        assert not out.sliding.any()  # no ball beyond a capacity
        if not released:
            assert 3.0 < out.contact_force_max[0] < release[0, 0]
        else:
            assert release[0, 0] < 3.0


def _stuck_middle_ball(rho, open_contact, eps0, regime):
    """The three balls with the middle one on a stick line (case (a): theta = 2 deg on the
    bottom groove, paired forces at ``rho``, N_y = 200 N, contact ``open_contact`` open or
    None) in ``regime``, ball 0 at epsilon ``eps0``: (config, block, state, release)."""
    theta = np.radians(2.0)
    dbeta = np.array([-theta, theta, 0.0, 0.0])
    force = np.array(paired_forces(rho * 200.0, 200.0))
    if open_contact is not None:
        force[open_contact] = 0.0
    _, release, res = stick_line_release(dbeta[None], force[None], TABLE1)
    assert res.regime[0] == 2  # one contact stuck (FullResult.regime)
    config, block, state, _, _, _ = _setup()
    state.velocity_deviation[:, 0] = eps0
    state.velocity_deviation[:, 1] = res.velocity_deviation[0]
    state.valid[:, 1] = True
    state.regime[:, 1] = regime
    state.normal_force[:, 1, :] = force
    state.contact_angle_deviation[:, 1, :] = dbeta
    return config, block, state, release[0]


def test_three_point_ball_pushed_past_its_release_is_unresolved():
    # The middle ball three-point (case (a) at rho = -0.85 with BR open): its BL contact
    # sticks (full, regime 2) and lets go at +17.08 N / -39.82 N (stick_line_release; the
    # reference scan stick_release gives +17.04 / -39.77 N, and the independent minimiser
    # of D - P v_B agrees, tests/physics/test_train_regimes.py). Ball 0 at epsilon 2 % pushes
    # it with about 13 N (the cluster rule: 2 x 6.61 N at 1 %), below the release: resolved;
    # at 3 % with about 20 N, past it: the train is unresolved from then on, counted as
    # released (not as sliding: no ball reaches a capacity, P_cap ~ 50 N). Before, a
    # three-point ball had no release pushes (+-inf) and the train stayed resolved.
    for eps0, released in ((0.02, False), (0.03, True)):
        config, block, state, release = _stuck_middle_ball(-0.85, 1, eps0, BALL_THREE_POINT)
        assert 17.0 < release[0] < 17.2
        out = fr.evaluate_friction(config, block.initial_gap, state)
        assert out.released.all() == released and out.resolved.all() != released
        assert not out.sliding.any()
        if not released:
            assert 12.0 < out.contact_force_max[0] < release[0]
        stats = FrictionStatistics()
        stats.add(out)
        assert stats.n_released == (4 if released else 0) and stats.n_sliding == 0
        assert stats.n_resolved + stats.n_released == 4


@pytest.mark.parametrize(("rho", "open_contact", "regime", "eps0"),
                         [(-0.9, None, BALL_REGIME_B, 0.01), (-0.95, None, BALL_REGIME_B, 0.01),
                          (-0.85, 1, BALL_THREE_POINT, 0.03)])
def test_lazy_release_pushes_match_the_eager_ones(monkeypatch, rho, open_contact, regime,
                                                  eps0):
    # The trains compute the release pushes only for the balls a push reaches (lazy,
    # settle_release_pushes); forcing regime_creep_coefficients to compute them for every
    # ball (eager, as before) must give the same figures to the bit, on trains that are
    # released (rho = -0.9, +2.95 N; the three-point ball at 3 %) and one that is not
    # (rho = -0.95, +33.5 N). The lazy run computes the pushes of the middle ball only (the
    # outer balls are in regime A: nothing to compute).
    config, block, state, _ = _stuck_middle_ball(rho, open_contact, eps0, regime)
    settled = []
    settle = fr.settle_release_pushes

    def counted(coefficients, need, bearing):
        settled.append(settle(coefficients, need, bearing))
        return settled[-1]

    monkeypatch.setattr(fr, "settle_release_pushes", counted)
    lazy = fr.evaluate_friction(config, block.initial_gap, state)
    assert settled == [4]  # the middle ball of each of the 4 trains, once
    original = fr.regime_creep_coefficients
    monkeypatch.setattr(fr, "regime_creep_coefficients",
                        lambda *a, **k: original(*a, **{**k, "lazy_release": False}))
    eager = fr.evaluate_friction(config, block.initial_gap, state)
    assert settled == [4, 0]  # nothing left pending
    for name, value in lazy.__dict__.items():
        assert_array_equal(value, getattr(eager, name), err_msg=name)
