"""Trains across regimes (issue 25, item 3): anchors, balls pushed along, braking from rotations.

Sources of the reference values: the closed forms of the cluster rule with anchors (eqs. 6a, 6b
in the Notes of tolsim.physics.trains.cluster_velocities), the exactly two-point ball of issue
25 (tolsim.physics.velocity.regimes.two_point_loaded, an independent closed form), the
kinematics of a ball-ball contact (tolsim.physics.velocity.ball_loads.ball_contact_slip) and
the limit K_anchor -> inf, K_pushed -> 0 of the finite-stiffness rule (the same kernels with
large and small finite K). Tolerances are stated at each assertion.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.optimize import minimize

from tolsim.physics.geometry import TABLE1, paired_forces
from tolsim.physics.trains import (
    cluster_velocities,
    net_push,
    step_clusters_kernel,
    step_project_kernel,
    train_contact_constant,
)
from tolsim.physics.trains.ball_minimum import (
    stick_line_release,
    stick_line_stiffness,
    stick_release,
    three_point_coefficients,
    three_point_stiffness,
)
from tolsim.physics.trains.regimes import (
    TRAIN_COLUMNS,
    directional_braking,
    pair_braking,
    regime_creep_coefficients,
    rigid_rolling_rate,
    settle_release_pushes,
    two_point_rolling_rate,
)
from tolsim.physics.velocity.analytic import LOAD_COLUMNS
from tolsim.physics.velocity.full import full
from tolsim.physics.velocity.models import (
    BALL_REGIME_A,
    BALL_REGIME_B,
    BALL_THREE_POINT,
    BALL_TWO_POINT,
    BALL_UNLOADED,
)
from tolsim.physics.velocity.regimes import (
    dissipated_power,
    minimise_dissipation,
    two_point_loaded,
)

INF = np.inf
COL = {name: k for k, name in enumerate(TRAIN_COLUMNS)}
RELEASE = slice(COL["release_push_forward"], COL["release_push_backward"] + 1)


@pytest.fixture
def rng():
    return np.random.default_rng(2025)


# --------------------------------------------------------------------------------------------
# The cluster rule with anchors and pushed balls
# --------------------------------------------------------------------------------------------
def test_soft_ball_pushing_an_anchor_closed_form():
    # Eq. (1) with w_1 = w_2 = epsilon_anchor = 0: epsilon_1 - Q / K + c Q = 0, so
    # Q = epsilon_1 / (1 / K - c) (exact up to rounding, 1e-13 relative).
    k, c, e1 = 700.0, 2e-5, 2.3e-3
    w, q = cluster_velocities([[e1, 0.0]], [[k, INF]], [[True]], [[c, 0.0]])
    assert_array_equal(w, [[0.0, 0.0]])
    assert_allclose(q, [[e1 / (1.0 / k - c)]], rtol=1e-13)


def test_anchor_between_a_fast_and_a_slow_ball():
    # A fast ball behind the anchor and a slow one in front, all touching: everything rolls at
    # the anchor's epsilon; the fast ball pushes with K_1 eps_1, the slow one is pushed with
    # -K_3 eps_3, the anchor carries the difference (closed form, 1e-13 relative).
    k1, k3, e1, e3, ea = 650.0, 720.0, 1.9e-3, -1.1e-3, 3e-5
    w, q = cluster_velocities([[e1, ea, e3]], [[k1, INF, k3]], [[True, True]])
    assert_array_equal(w, [[ea, ea, ea]])
    assert_allclose(q, [[k1 * (e1 - ea), k3 * (ea - e3)]], rtol=1e-13)
    assert_allclose(net_push(q)[0, 1], k1 * (e1 - ea) - k3 * (ea - e3), rtol=1e-12)


def test_slower_ball_behind_an_anchor_falls_back():
    # A ball slower than the anchor in front of it separates at once: no force (exact).
    w, q = cluster_velocities([[-1e-3, 0.0]], [[700.0, INF]], [[True]])
    assert_array_equal(w, [[-1e-3, 0.0]]) and assert_array_equal(q, [[0.0]])


def test_pushed_ball_transmits_the_force():
    # An unloaded ball between two soft balls: no resistance of its own, so the two soft
    # balls act as a pair: w = K-weighted mean, Q = K1 K3 (e1 - e3) / (K1 + K3) on both
    # contacts (Notes of cluster_velocities; 1e-13 relative).
    k1, k3, e1, e3 = 650.0, 720.0, 1.9e-3, -1.1e-3
    w, q = cluster_velocities([[e1, 0.7, e3]], [[k1, 0.0, k3]], [[True, True]])
    mean = (k1 * e1 + k3 * e3) / (k1 + k3)
    assert_allclose(w, [[mean] * 3], rtol=1e-13)
    force = k1 * k3 * (e1 - e3) / (k1 + k3)
    assert_allclose(q, [[force, force]], rtol=1e-12)


def test_anchors_that_disagree_cannot_roll_together():
    # Two anchors with different epsilon pushed together: rigid against rigid, the force is
    # unbounded (+inf), which the friction check reads as sliding (exact).
    w, q = cluster_velocities([[2e-4, -1e-4]], [[INF, INF]], [[True]])
    assert q[0, 0] == np.inf and np.all(np.isfinite(w))


def _random_trains(rng, m, n, anchors=0.3, pushed=0.1):
    eps = rng.normal(0.0, 2e-3, (m, n))
    k = rng.uniform(150.0, 800.0, (m, n))
    c = rng.uniform(-2e-4, 2e-4, (m, n))
    kind = rng.choice(3, (m, n), p=[1.0 - anchors - pushed, anchors, pushed])
    eps[kind == 1] = 0.0  # two-point balls: epsilon = 0 exactly
    return eps, k, c, kind


@pytest.mark.parametrize("touch", [0.6, 1.0])
def test_anchor_and_pushed_limits_of_the_finite_rule(rng, touch):
    # The rule with K = inf (anchor) and K = 0 (pushed) is the limit of the finite rule with
    # K_anchor -> inf and K_pushed -> 0 (Notes, eqs. 6a, 6b: the next-order tie-break makes
    # chains of equal anchors share their load). Finite stand-ins 1e11 N and 1e-7 N: the
    # velocities agree to 1e-9 (K_soft / K_anchor ~ 1e-8 of epsilon) and the forces to
    # 1e-5 relative + 1e-6 N.
    m, n = 3000, 8
    eps, k, c, kind = _random_trains(rng, m, n)
    touching = rng.random((m, n - 1)) < touch
    k_exact = np.where(kind == 1, INF, np.where(kind == 2, 0.0, k))
    c_exact = np.where(kind == 0, c, 0.0)
    k_limit = np.where(kind == 1, 1e11, np.where(kind == 2, 1e-7, k))
    w, q = cluster_velocities(eps, k_exact, touching, c_exact)
    wl, ql = cluster_velocities(eps, k_limit, touching, c_exact)
    loaded = kind != 2  # a pushed ball alone keeps its own (given) epsilon in both
    assert_allclose(w[loaded], wl[loaded], atol=1e-9)
    assert_allclose(q, ql, rtol=1e-5, atol=1e-6)
    assert np.all(q >= 0) and (q > 0).mean() > 0.2


def test_mirrored_train_with_anchors_gives_the_mirrored_result(rng):
    # Mirror invariance (x -> -x turns the train around and flips epsilon): reversing the
    # balls and negating epsilon gives the reversed forces and negated velocities (c = 0;
    # 1e-12 relative + 1e-15 N, the summation runs from the other end).
    m, n = 2000, 7
    eps, k, _, kind = _random_trains(rng, m, n)
    k = np.where(kind == 1, INF, np.where(kind == 2, 0.0, k))
    gap = np.where(rng.random((m, n - 1)) < 0.5, 0.0, rng.uniform(0.0, 40e-6, (m, n - 1)))
    a = train_contact_constant(gap, eps, k, 0.2, 0.5)
    b = train_contact_constant(gap[:, ::-1], -eps[:, ::-1], k[:, ::-1], 0.2, 0.5)
    assert a.valid.all() and b.valid.all()
    assert_allclose(b.contact_force[:, ::-1], a.contact_force, rtol=1e-12, atol=1e-15)
    assert_allclose(-b.velocity[:, ::-1], a.velocity, rtol=1e-12, atol=1e-15)


def test_event_driven_soft_ball_catches_an_anchor():
    # A soft ball 20 um behind an anchor (epsilon 0) closes the gap at eps_1 v / 2 and then
    # pushes with K eps_1 for the rest of the stroke (closed form; 1e-12 relative).
    k, e1, v, gap = 700.0, 2e-3, 0.2, 20e-6
    r = train_contact_constant([[gap]], [[e1, 0.0]], [[k, INF]], v, 1.0)
    assert r.valid[0]
    assert_allclose(r.first_contact_time, [gap / (e1 * v / 2)], rtol=1e-12)
    assert_allclose(r.contact_force, [[k * e1]], rtol=1e-12)
    assert_allclose(r.velocity, [[0.0, 0.0]], atol=1e-18)


def test_all_soft_trains_never_see_the_new_tiers(rng):
    # Regime A only: the tiered rule is the old rule. K = inf or 0 placed anywhere changes
    # the rows that hold them only (bit for bit elsewhere).
    m, n = 500, 6
    eps, k, c, _ = _random_trains(rng, m, n, anchors=0.0, pushed=0.0)
    touching = rng.random((m, n - 1)) < 0.7
    w, q = cluster_velocities(eps, k, touching, c)
    k2 = k.copy()
    k2[::2, 3] = INF
    c2 = c.copy()
    c2[::2, 3] = 0.0
    w2, q2 = cluster_velocities(eps, k2, touching, c2)
    assert_array_equal(w2[1::2], w[1::2]) and assert_array_equal(q2[1::2], q[1::2])


# --------------------------------------------------------------------------------------------
# The columns of a ball by regime
# --------------------------------------------------------------------------------------------
def _two_point_ball(force=141.4):
    dbeta = np.zeros((1, 4))
    normal = np.array([[force, 0.0, force, 0.0]])  # BL and TR: exactly two-point
    return dbeta, normal


@pytest.mark.parametrize("push, braking_sum", [(5.0, 0.0), (-3.0, 12.0), (20.0, 40.0)])
def test_two_point_columns_reproduce_the_closed_form(push, braking_sum):
    # F_c = F_0 + a P + b S and the rolling range |P| / P_cap + S / S_cap < 1 against
    # tolsim.physics.velocity.regimes.two_point_loaded (issue 25: pushed by 5 N, eps = 0 and
    # F_c = -2.5 N); 1e-14 absolute.
    mu_bb = 0.1
    dbeta, normal = _two_point_ball()
    load = np.full((1, len(LOAD_COLUMNS)), np.nan)
    out = regime_creep_coefficients(load, [BALL_TWO_POINT], dbeta, normal, TABLE1,
                                    ball_friction=mu_bb)[0]
    ref = two_point_loaded(normal[0, 0], push, braking_sum, TABLE1, ball_friction=mu_bb)
    fc = (out[COL["free_rolling_carriage_force"]] + out[COL["carriage_force_per_push"]] * push
          + out[COL["carriage_force_per_neighbour_force"]] * braking_sum)
    assert_allclose(fc, ref.carriage_force, atol=1e-14)
    assert out[COL["creep_stiffness"]] == INF and out[COL["braking_sensitivity"]] == 0.0
    use = (abs(push) / out[COL["traction_capacity"]]
           + braking_sum / out[COL["braking_capacity"]])
    assert (use >= 1.0) == bool(ref.sliding)
    if push == 5.0 and braking_sum == 0.0:
        assert_allclose(fc, -2.5, atol=1e-14)


def test_two_point_sliding_onset_on_the_line():
    # Gross sliding sets in at |P| + mu_bb S = 2 mu F (issue 25): just inside, the capacity
    # line is not reached; on it, it is (relative 1e-12 on either side).
    mu_bb, force = 0.1, 141.4
    dbeta, normal = _two_point_ball(force)
    out = regime_creep_coefficients(np.full((1, 9), np.nan), [BALL_TWO_POINT], dbeta, normal,
                                    TABLE1, ball_friction=mu_bb)[0]
    cap = 2.0 * TABLE1.friction_coefficient * force
    s = 30.0
    for p, slides in ((cap - mu_bb * s) * (1 - 1e-12), False), ((cap - mu_bb * s), True):
        use = p / out[COL["traction_capacity"]] + s / out[COL["braking_capacity"]]
        assert (use >= 1.0) == slides


def test_regime_a_columns_are_untouched_and_unloaded_is_pushed(rng):
    # Balls in regime A keep the creep model's columns bit for bit; an unloaded ball gets
    # K = 0 (pushed along), no friction (F_0 = a = b = 0), infinite capacities (exact).
    load = rng.normal(size=(3, len(LOAD_COLUMNS)))
    dbeta = np.zeros((3, 4))
    normal = np.array([[141.0] * 4, [0.0] * 4, [141.0] * 4])
    out = regime_creep_coefficients(load, [BALL_REGIME_A, BALL_UNLOADED, BALL_REGIME_A],
                                    dbeta, normal, TABLE1)
    assert_array_equal(out[[0, 2], :len(LOAD_COLUMNS)], load[[0, 2]])
    assert out[1, COL["creep_stiffness"]] == 0.0
    assert np.all(out[1, [COL["free_rolling_carriage_force"], COL["carriage_force_per_push"],
                          COL["carriage_force_per_neighbour_force"]]] == 0.0)
    assert np.all(np.isinf(out[1, [COL["traction_capacity"], COL["braking_capacity"]]]))
    only_a = regime_creep_coefficients(load, [BALL_REGIME_A] * 3, dbeta, normal, TABLE1)
    assert_array_equal(only_a[:, :len(LOAD_COLUMNS)], load)


# --------------------------------------------------------------------------------------------
# Braking from the actual rotations
# --------------------------------------------------------------------------------------------
def test_rolling_rates_of_the_nominal_and_the_two_point_ball():
    # Nominal four-point ball: Omega = v / (2 R cos 45 deg) = 0.7071 v / R about x; two-point
    # (BL-TR) ball: (v / 2R)(cos 45, -sin 45) (issue 25); 1e-12.
    beta0 = TABLE1.nominal_contact_angle
    four = rigid_rolling_rate(np.zeros((1, 4)), np.full((1, 4), 141.4), TABLE1)
    assert_allclose(four, [[0.5 / np.cos(beta0), 0.0]], atol=1e-12)
    dbeta, normal = _two_point_ball()
    two = two_point_rolling_rate(dbeta, normal, TABLE1)
    assert_allclose(two, [[0.5 * np.cos(beta0), -0.5 * np.sin(beta0)]], atol=1e-12)
    other = two_point_rolling_rate(dbeta, np.array([[0.0, 141.4, 0.0, 141.4]]), TABLE1)
    assert_allclose(other, [[0.5 * np.cos(beta0), 0.5 * np.sin(beta0)]], atol=1e-12)


def _four_and_two_point(mu_bb):
    """A nominal four-point ball in regime A (K = 700 N, b = mu_bb / (2 cos beta_0)) and an
    exactly two-point ball: (load, regimes, dbeta, normal)."""
    load = np.full((2, len(LOAD_COLUMNS)), np.nan)
    load[0, LOAD_COLUMNS.index("creep_stiffness")] = 700.0
    load[0, LOAD_COLUMNS.index("carriage_force_per_neighbour_force")] = \
        mu_bb / (2 * np.cos(TABLE1.nominal_contact_angle))
    normal = np.array([[141.4] * 4, [141.4, 0.0, 141.4, 0.0]])
    return load, [BALL_REGIME_A, BALL_TWO_POINT], np.zeros((2, 4)), normal


def test_braking_between_a_four_point_and_a_two_point_ball():
    # Issue 25: |Omega + Omega'| R = 1.118 v, not the 1.207 v of parallel axes. Derivation:
    # (0.7071 + 0.3536, -0.3536) has norm sqrt(1.125 + 0.125) = sqrt(1.25) = 1.1180. The
    # pair's B is mu_bb times that (Notes of pair_braking), and it equals the sum of the two
    # balls' braking slopes along W_hat by the power balance, b_4 W_x + (mu_bb / 2)(e . W_hat)
    # with b_4 = mu_bb / (2 cos beta_0) (tolsim.physics.velocity.ball_loads Notes); 1e-12.
    mu_bb = 0.1
    beta0 = TABLE1.nominal_contact_angle
    load, kinds, dbeta, normal = _four_and_two_point(mu_bb)
    coefficients = regime_creep_coefficients(load, kinds, dbeta, normal, TABLE1,
                                             ball_friction=mu_bb)
    b = pair_braking(coefficients, mu_bb)
    assert_allclose(b, [mu_bb * np.sqrt(1.25)], rtol=1e-12)
    assert_allclose(np.sqrt(1.25), 1.118, atol=5e-4)
    w = np.array([0.5 / np.cos(beta0) + 0.5 * np.cos(beta0), -0.5 * np.sin(beta0)])
    w_hat = w / np.linalg.norm(w)
    e_two = np.array([np.cos(beta0), -np.sin(beta0)])
    power = mu_bb / (2 * np.cos(beta0)) * w_hat[0] + mu_bb / 2 * (e_two @ w_hat)
    assert_allclose(b, [power], rtol=1e-12)
    parallel = (coefficients[0, COL["carriage_force_per_neighbour_force"]]
                + coefficients[1, COL["carriage_force_per_neighbour_force"]])
    assert_allclose(parallel / mu_bb, 0.5 / np.cos(beta0) + 0.5, rtol=1e-12)  # 1.207


def test_a_pair_across_two_batches_brakes_as_within_one():
    # The pair of test_braking_between_a_four_point_and_a_two_point_ball, its balls' columns
    # from two calls (a circuit's midpoint balls and its entering ones): with ``rates`` the
    # all-A call gives its balls' rolling rates, regimes and braking vectors, so the pair's
    # B is the one-call value to the bit; without, they are NaN and so is B (the train was
    # lost; tests/study/test_circuit_friction.py shows it in a study).
    mu_bb = 0.1
    load, kinds, dbeta, normal = _four_and_two_point(mu_bb)
    one = regime_creep_coefficients(load, kinds, dbeta, normal, TABLE1, ball_friction=mu_bb)
    two = regime_creep_coefficients(load[1:], kinds[1:], dbeta[1:], normal[1:], TABLE1,
                                    ball_friction=mu_bb)

    def first(rates):
        return regime_creep_coefficients(load[:1], kinds[:1], dbeta[:1], normal[:1], TABLE1,
                                         ball_friction=mu_bb, rates=rates)

    joined = np.concatenate([first(True), two])
    assert_array_equal(joined, one)
    assert_array_equal(pair_braking(joined, mu_bb), pair_braking(one, mu_bb))
    assert_array_equal(first(False)[:, :len(LOAD_COLUMNS)], load[:1])
    assert np.isnan(pair_braking(np.concatenate([first(False), two]), mu_bb)).all()


def test_pair_braking_of_soft_pairs_is_bit_for_bit(rng):
    # Soft pairs keep b_j + b_{j+1} exactly; a pushed ball's pairs have no braking (Notes).
    coefficients = rng.normal(size=(4, 5, len(TRAIN_COLUMNS)))
    coefficients[..., COL["creep_stiffness"]] = rng.uniform(100, 800, (4, 5))
    b = coefficients[..., COL["carriage_force_per_neighbour_force"]]
    assert_array_equal(pair_braking(coefficients), b[:, :-1] + b[:, 1:])
    coefficients[1, 2, COL["creep_stiffness"]] = 0.0
    out = pair_braking(coefficients)
    assert_array_equal(out[1, [1, 2]], [0.0, 0.0])
    assert_array_equal(out[[0, 2, 3]], (b[:, :-1] + b[:, 1:])[[0, 2, 3]])


def test_step_rule_with_anchors_is_the_event_driven_solution(rng):
    # The along_track step rule (stage 1 + the projection (7), tolsim.physics.trains) is
    # exact for constant epsilon whatever dt (Notes of step_clusters_kernel): with anchors
    # and pushed balls too, since both stages run the same tiered rule. 40 steps against
    # train_contact_constant: end displacements to 1e-15 m (positions of ~0.1 m, rounding),
    # the last step's mean forces to 1e-9 N where no contact forms in it.
    m, n, v, horizon, steps, diameter = 400, 6, 0.2, 0.5, 40, 0.01
    eps, k, _, kind = _random_trains(rng, m, n)
    k = np.where(kind == 1, INF, np.where(kind == 2, 0.0, k))
    c = np.zeros((m, n))
    gap = np.where(rng.random((m, n - 1)) < 0.3, 0.0, rng.uniform(0.0, 40e-6, (m, n - 1)))
    ref = train_contact_constant(gap, eps, k, v, horizon)
    h = 0.5 * v * horizon / steps
    z0 = np.concatenate([np.zeros((m, 1)), np.cumsum(diameter + gap, axis=1)], axis=1)
    z = z0.copy()
    closed = gap == 0.0
    before = np.zeros_like(closed)
    member = np.ones((m, n), dtype=bool)
    active = np.ones(m, dtype=bool)
    for _ in range(steps):
        w, q = np.empty((m, n)), np.empty((m, n - 1))
        label, ok = np.empty((m, n), dtype=np.int64), np.empty(m, dtype=bool)
        step_clusters_kernel(eps, k, c, member, member, closed, active, w, q, label, ok)
        end = z + h * (1.0 + w)
        position, new_closed = np.empty_like(end), np.empty_like(closed)
        formed, contact = np.empty(m, dtype=np.int64), np.empty(m)
        step_project_kernel(z, end, k, c, member, member, ok, label, before, diameter,
                            1e-12 * diameter, h, position, q, new_closed, formed, contact)
        z, closed, before = position, new_closed, new_closed.copy()
    assert ok.all() and ref.valid.all()
    assert_allclose(z - z0 - steps * h, ref.displacement, rtol=0, atol=1e-15)
    late = np.isfinite(ref.contact_time) & (ref.contact_time > horizon * (1 - 1.0 / steps))
    quiet = ~late.any(axis=1)
    assert quiet.mean() > 0.8 and (ref.contact_force[quiet] > 0).mean() > 0.2
    assert_allclose(q[quiet], ref.contact_force[quiet], rtol=0, atol=1e-9)


@pytest.mark.parametrize("rho", [-0.9, -0.95, -0.98])
def test_regime_b_ball_is_stiff_with_its_own_friction(rho):
    # [Lin2018] case (a): theta = 2 deg on the bottom groove, paired forces at N_y = 200 N;
    # |rho| >= 0.9 is regime B (issue 25). Its columns: K from the stick line in the issue's
    # 3-5e4 N, c = -mu_bb / K (R1 in the Notes of regime_creep_coefficients), F_0 and Omega
    # those of full's certified minimum (bit for bit); and F_0 is about mu sum F_light / 2
    # (issue 25's estimate; 10 % here: measured 1.0 % to 7.7 %).
    theta = np.radians(2.0)
    dbeta = np.array([[-theta, theta, 0.0, 0.0]])
    force = np.array([paired_forces(rho * 200.0, 200.0)])
    ref = full(dbeta, force, TABLE1)
    assert ref.regime[0] == 2  # one contact stuck (FullResult.regime)
    load = np.full((1, len(LOAD_COLUMNS)), np.nan)
    out = regime_creep_coefficients(load, [BALL_REGIME_B], dbeta, force, TABLE1,
                                    ball_friction=0.1)[0]
    k = out[COL["creep_stiffness"]]
    assert 3e4 < k < 5e4
    assert_allclose(out[COL["braking_sensitivity"]], -0.1 / k, rtol=1e-15)
    assert out[COL["free_rolling_carriage_force"]] == ref.drag_force[0]
    assert_allclose(out[COL["rolling_rate_x"]:COL["regime"]], ref.angular_velocity[0, :2]
                    * TABLE1.ball_radius / 0.01, rtol=1e-15)
    light = min(force[0, 0] + force[0, 2], force[0, 1] + force[0, 3])
    assert_allclose(out[COL["free_rolling_carriage_force"]],
                    0.5 * TABLE1.friction_coefficient * light, rtol=0.1)


def test_regime_b_stiffness_against_the_numpy_minimiser():
    # The stick line's K (case (a), rho = -0.95) against the secant of the independent
    # minimiser of D - P v_B (tolsim.physics.velocity.regimes.minimise_dissipation) over
    # P = -2 .. +2 N: 4 N / (eps(+2) - eps(-2)). Measured 33 269 N against 33 322 N; 1 %
    # (the minimiser's epsilon to ~1e-7 over a difference of 1.2e-4, and the secant).
    theta = np.radians(2.0)
    dbeta = np.array([-theta, theta, 0.0, 0.0])
    force = np.array(paired_forces(-0.95 * 200.0, 200.0))
    k, _ = stick_line_stiffness(dbeta[None], force[None], TABLE1)
    eps = [minimise_dissipation(dbeta, force, TABLE1, push=p).velocity_deviation
           for p in (-2.0, 2.0)]
    assert_allclose(k[0], 4.0 / (eps[1] - eps[0]), rtol=0.01)


def _case_a_three_point(open_contact, rho=-0.8):
    """Case (a) (bottom groove turned 2 deg, paired forces at ``rho``, N_y = 200 N) with
    the contact ``open_contact`` open: (dbeta, F), shape (4,) each."""
    theta = np.radians(2.0)
    force = np.array(paired_forces(rho * 200.0, 200.0))
    force[open_contact] = 0.0
    return np.array([-theta, theta, 0.0, 0.0]), force


@pytest.mark.parametrize("open_contact", [1, 3])
def test_three_point_stiffness_against_the_numpy_minimiser(open_contact):
    # A three-point ball: case (a) (theta = 2 deg on the bottom groove, paired forces at
    # rho = -0.8, N_y = 200 N) with one contact of the light diagonal open; full finds all
    # three contacts slipping (a smooth minimum), and K = (v / 2) / (H^-1)_vv (R2 in the Notes
    # of three_point_stiffness) against the secant of the independent minimiser of D - P v_B
    # (minimise_dissipation) over P = -2 .. +2 N. Measured 623.6 N against 623.3 N (BR open)
    # and 549.1 N against 548.3 N (TL open); tolerance 1 %, as regime B's test above.
    dbeta, force = _case_a_three_point(open_contact)
    k, res = three_point_stiffness(dbeta[None], force[None], TABLE1)
    assert res.regime[0] == 1  # all three contacts slip (FullResult.regime)
    eps = [minimise_dissipation(dbeta, force, TABLE1, push=p).velocity_deviation
           for p in (-2.0, 2.0)]
    assert_allclose(k[0], 4.0 / (eps[1] - eps[0]), rtol=0.01)


def _loaded_minimum(dbeta, force, push, braking_sum, start, nodes=(48, 192)):
    """min over x = (v_B, Omega_x R, Omega_y R) / v of D + mu_bb S R |Omega_perp| - P v_B
    (T1 of three_point_coefficients) by SciPy's BFGS on the independent NumPy quadrature of
    D (dissipated_power with ``nodes``, exact gradient; D is smooth where all three contacts
    slip), from ``start``; returns (epsilon, the minimum [W])."""
    v, radius = 0.01, TABLE1.ball_radius

    def phi(x):
        d, g = dissipated_power(x[0] * v, np.array([x[1], x[2], 0.0]) * v / radius, dbeta,
                                force, TABLE1, groove_velocity=v, gradient=True, nodes=nodes)
        spin = np.hypot(x[1], x[2])
        val = d + 0.1 * braking_sum * v * spin - push * x[0] * v
        grad = np.array([(g[0] - push) * v, g[1] * v / radius + 0.1 * braking_sum * v
                         * x[1] / spin, g[2] * v / radius + 0.1 * braking_sum * v * x[2] / spin])
        return val, grad

    res = minimize(phi, start, jac=True, method="BFGS", options={"gtol": 1e-12, "maxiter": 500})
    return 2.0 * res.x[0] - 1.0, res.fun


@pytest.mark.parametrize("open_contact", [1, 3])
def test_three_point_coefficients_against_the_numpy_minimiser(open_contact):
    # The three-point ball of the test above (case (a), rho = -0.8, BR or TL open; all three
    # contacts slip). Its coefficients (T2, T3 in the Notes of three_point_coefficients)
    # against the independent minimiser of D + mu_bb S R |Omega| - P v_B (_loaded_minimum,
    # NumPy quadrature, SciPy BFGS):
    # * c = d(eps)/dS: secant over S = -0.5 .. +0.5 N (S < 0 is the same smooth minimum with
    #   the braking reversed) on a fine quadrature (192 x 768 nodes: the S-response is small,
    #   5e-5 per N, and curves beyond ~1 N, where a contact starts to stick: eps 2.03 % at
    #   S = 0, 0.22 % at S = 20 N); measured 4.604e-5 against 4.622e-5 /N (BR open),
    #   -1.822e-4 against -1.840e-4 (TL open); 2 %;
    # * b = dF_c/dS with v F_c = min (power balance): the same secant of the minimum
    #   (0.067650 against 0.067649); 1e-3;
    # * a = dF_c/dP: secant of the minimum over P = -2 .. +2 N (-0.510129 against -0.510128);
    #   1e-3;
    # * P_cap: min over Omega of D sliding at 1 m/s between grooves at rest (v_B / v = 1e8,
    #   Nelder-Mead): the point-contact value is a lower bound (Jensen) within 1 % of it
    #   (51.785 against 51.803 N, 50.008 against 50.027 N);
    # * S_cap: |dD/dOmega| of a non-rotating ball sliding at v / 2 (the grooves' moment; the
    #   planar uniform slip makes it exact) over mu_bb R; 1e-6.
    dbeta, force = _case_a_three_point(open_contact)
    cols, rate = three_point_coefficients(dbeta[None], force[None], TABLE1, ball_friction=0.1)
    cols = {name: value[0] for name, value in cols.items()}
    v, radius = 0.01, TABLE1.ball_radius
    start = np.array([0.5 * (1.0 + cols["free_rolling_velocity_deviation"]), *rate[0]])
    eps_s = [_loaded_minimum(dbeta, force, 0.0, s, start, (192, 768)) for s in (-0.5, 0.5)]
    assert_allclose(cols["braking_sensitivity"], eps_s[1][0] - eps_s[0][0], rtol=0.02)
    assert_allclose(cols["carriage_force_per_neighbour_force"],
                    (eps_s[1][1] - eps_s[0][1]) / v, rtol=1e-3)
    phi_p = [_loaded_minimum(dbeta, force, p, 0.0, start)[1] for p in (-2.0, 2.0)]
    assert_allclose(cols["carriage_force_per_push"], (phi_p[1] - phi_p[0]) / (4.0 * v),
                    rtol=1e-3)
    free = _loaded_minimum(dbeta, force, 0.0, 0.0, start)
    assert_allclose(cols["free_rolling_velocity_deviation"], free[0], atol=2e-5)
    assert_allclose(cols["free_rolling_carriage_force"], free[1] / v, rtol=1e-3)

    def sliding(w):
        return dissipated_power(1.0, np.array([w[0], w[1], 0.0]) / radius, dbeta, force,
                                TABLE1, groove_velocity=1e-8)

    best = min((minimize(sliding, w0, method="Nelder-Mead",
                         options={"xatol": 1e-10, "fatol": 1e-12, "maxiter": 4000})
                for w0 in ([0.0, 0.0], [1.0, 0.0], [0.5, 0.5], [0.5, -0.5])),
               key=lambda r: r.fun)
    assert cols["traction_capacity"] <= best.fun * (1.0 + 1e-9)
    assert_allclose(cols["traction_capacity"], best.fun, rtol=0.01)
    _, grad = dissipated_power(0.5 * v, np.zeros(3), dbeta, force, TABLE1, groove_velocity=v,
                               gradient=True)
    assert_allclose(cols["braking_capacity"], np.hypot(grad[1], grad[2]) / (0.1 * radius),
                    rtol=1e-6)


def test_three_point_ball_in_the_train_columns():
    # regime_creep_coefficients gives a three-point ball the columns of
    # three_point_coefficients (bit for bit) and its actual rotation, where before it left them
    # NaN (the creep model has none with an open contact), and pair_braking takes its pairs'
    # braking from the rotations, mu_bb |Omega + Omega'| R / v (exact formula, 1e-15).
    theta = np.radians(2.0)
    dbeta = np.array([[-theta, theta, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
    force = np.array([paired_forces(-0.8 * 200.0, 200.0), [141.4] * 4])
    force[0, 1] = 0.0
    load = np.full((2, len(LOAD_COLUMNS)), np.nan)
    load[1] = np.arange(len(LOAD_COLUMNS))
    out = regime_creep_coefficients(load, [BALL_THREE_POINT, BALL_REGIME_A], dbeta, force,
                                    TABLE1, ball_friction=0.1)
    cols, rate = three_point_coefficients(dbeta[:1], force[:1], TABLE1, ball_friction=0.1)
    for name, value in cols.items():
        assert out[0, COL[name]] == value[0]
    assert np.isfinite(out[0, :COL["release_push_forward"]]).all()
    assert_array_equal(out[0, COL["rolling_rate_x"]:COL["regime"]], rate[0])
    assert_array_equal(out[1, :len(LOAD_COLUMNS)], load[1])
    spin = out[:, COL["rolling_rate_x"]:COL["regime"]]
    assert_allclose(pair_braking(out, 0.1), [0.1 * np.hypot(*spin.sum(axis=0))], rtol=1e-15)


def test_braking_along_the_actual_rotations_in_the_train_rule():
    # Issue 25's example: a regime-A ball (nominal, 0.707 v / R_B about x) behind a two-point
    # ball (0.5 v / R_B tilted by 45 deg). Their contact brakes both along W_hat = (1.0607,
    # -0.3536) / 1.118, so the A ball's epsilon responds with c_front = c (Omega_hat .
    # W_hat) = 0.9487 c (T4 in the Notes of directional_braking), not c: it pushes the anchor
    # with Q = eps / (1 / K - 0.9487 c) (eq. 1 of cluster_velocities with the anchor at 0;
    # exact up to rounding, 1e-12). A large c (2e-4 / N) makes the difference 9 %.
    k, c, eps = 700.0, 2e-4, 2e-3
    load = np.full((2, len(LOAD_COLUMNS)), np.nan)
    load[0] = 0.0
    load[0, COL["creep_stiffness"]], load[0, COL["braking_sensitivity"]] = k, c
    dbeta = np.zeros((2, 4))
    force = np.array([[141.4] * 4, [141.4, 0.0, 141.4, 0.0]])
    out = regime_creep_coefficients(load, [BALL_REGIME_A, BALL_TWO_POINT], dbeta, force,
                                    TABLE1, ball_friction=0.1)
    assert_allclose(out[:, COL["rolling_rate_x"]:COL["regime"]],
                    [[0.5 / np.cos(np.pi / 4), 0.0], [0.5 * np.sin(np.pi / 4), -0.5 * np.sin(
                        np.pi / 4)]], rtol=1e-12)
    stiffness, braking = directional_braking(out[None], [[k, INF]], [[c, 0.0]])
    along = np.array([1.0607, -0.3536]) / 1.118  # W_hat, rounded as in the issue
    w, q = cluster_velocities([[eps, 0.0]], stiffness, [[True]], braking)
    assert_allclose(q, [[eps / (1.0 / k - c * along[0])]], rtol=1e-4)  # W_hat's rounding
    cos = (0.5 / np.cos(np.pi / 4) + 0.5 * np.sin(np.pi / 4)) / np.hypot(
        0.5 / np.cos(np.pi / 4) + 0.5 * np.sin(np.pi / 4), 0.5 * np.sin(np.pi / 4))
    assert_allclose(q, [[eps / (1.0 / k - c * cos)]], rtol=1e-12)
    assert_array_equal(w, [[0.0, 0.0]])
    # the same ball between two regime-A balls keeps its own-axis c, bit for bit
    same = regime_creep_coefficients(np.stack([load[0], load[0]]), [BALL_REGIME_A] * 2,
                                     np.zeros((2, 4)), np.full((2, 4), 141.4), TABLE1)
    kk, cc = np.array([[k, k]]), np.array([[c, c]])
    got = directional_braking(same[None], kk, cc)
    assert got[0] is kk and got[1] is cc


def test_stick_release_against_the_numpy_minimiser():
    # Case (a) at rho = -0.9 (regime B, BL stuck, K = 32 698 N, eps 0.030 %): the stuck
    # contact lets go at P = +2.94 N and -22.60 N (stick_release, Notes). The independent
    # minimiser of D - P v_B (minimise_dissipation) at 0.9 of those pushes stays on the stick
    # line (eps = eps_0 + P / K to 10 % of P / K; measured 0.03858 % against 0.03857 % at
    # +2.65 N, -0.0331 % against -0.0317 % at -20.3 N) and at 1.1 of them has left it for the
    # other branch (|eps - eps_0| > 10 |P / K|; measured 2.09 % at +3.24 N, -2.60 % at
    # -24.9 N). The creep model's capacity, about mu sum F = 56.6 N, is far above both.
    theta = np.radians(2.0)
    dbeta = np.array([-theta, theta, 0.0, 0.0])
    force = np.array(paired_forces(-0.9 * 200.0, 200.0))
    release, res = stick_release(dbeta[None], force[None], TABLE1)
    k, _ = stick_line_stiffness(dbeta[None], force[None], TABLE1)
    assert 2.0 < release[0, 0] < 3.0 and -25.0 < release[0, 1] < -20.0
    eps0 = res.velocity_deviation[0]
    for p in release[0]:
        stuck = minimise_dissipation(dbeta, force, TABLE1, push=0.9 * p).velocity_deviation
        assert abs(stuck - (eps0 + 0.9 * p / k[0])) < 0.1 * abs(0.9 * p / k[0])
        free = minimise_dissipation(dbeta, force, TABLE1, push=1.1 * p).velocity_deviation
        assert abs(free - eps0) > 10.0 * abs(1.1 * p / k[0])
    single = stick_release(np.zeros((1, 4)), np.full((1, 4), 141.4), TABLE1)[0]
    assert_array_equal(single, [[np.inf, -np.inf]])  # regime A: nothing sticks


@pytest.mark.parametrize("rho", [-0.9, -0.95])
def test_fast_release_threshold_against_stick_release_and_the_numpy_minimiser(rho):
    # Case (a) (theta = 2 deg on the bottom groove, paired forces, N_y = 200 N), regime B.
    # stick_line_release (the fast kernel) against stick_release (the reference scan: 256 +
    # 2 x 257 directions, 40 bisections): +2.94 / -22.60 N at rho = -0.9, +33.4 / -51.2 N at
    # -0.95 (issue 25, Notes of regime_creep_coefficients). A coarser scan can only miss the
    # least slope, so the fast pushes are not smaller in size, and within 0.5 % (measured
    # +0.11 % to +0.15 %; tolerance of the fast bracket 1e-4 mu sum F = 0.006 N). K is
    # stick_line_stiffness's to the bit (the same kernel). The independent minimiser of
    # D - P v_B (minimise_dissipation) stays on the stick branch at 0.97 of each fast push
    # (|eps - eps_0| < 2 |P / K|: the line softens under large pushes, measured -0.151 %
    # against the linear -0.119 % at -49.6 N, rho = -0.95) and has left it for the other
    # branch at 1.03 (|eps - eps_0| > 10 |P / K|; measured -9.0 % at -52.7 N).
    theta = np.radians(2.0)
    dbeta = np.array([-theta, theta, 0.0, 0.0])
    force = np.array(paired_forces(rho * 200.0, 200.0))
    k, fast, res = _fast_release_checked(dbeta, force)
    assert_array_equal(k, stick_line_stiffness(dbeta[None], force[None], TABLE1)[0])


def _fast_release_checked(dbeta, force):
    """stick_line_release of one ball, checked against stick_release's reference scan (not
    smaller in size, within 0.5 %) and the independent minimiser of D - P v_B (on the stick
    line at 0.97 of each push, off it at 1.03; the bounds of the test above)."""
    k, fast, res = stick_line_release(dbeta[None], force[None], TABLE1)
    ref, _ = stick_release(dbeta[None], force[None], TABLE1)
    assert np.all(np.abs(fast) >= np.abs(ref) - 0.01)
    assert_allclose(fast, ref, rtol=0.005)
    eps0 = res.velocity_deviation[0]
    for p in fast[0]:
        stuck = minimise_dissipation(dbeta, force, TABLE1, push=0.97 * p).velocity_deviation
        assert abs(stuck - eps0) < 2.0 * abs(0.97 * p / k[0])
        free = minimise_dissipation(dbeta, force, TABLE1, push=1.03 * p).velocity_deviation
        assert abs(free - eps0) > 10.0 * abs(1.03 * p / k[0])
    return k, fast, res


def test_release_pushes_in_the_train_columns():
    # The release pushes are train columns of a regime-B ball (stick_line_release's, bit for
    # bit) and +-inf for every other ball (so the trains' sliding check is unchanged there).
    theta = np.radians(2.0)
    dbeta = np.array([[-theta, theta, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
    force = np.array([paired_forces(-0.9 * 200.0, 200.0), [141.4, 0.0, 141.4, 0.0]])
    load = np.full((2, len(LOAD_COLUMNS)), np.nan)
    out = regime_creep_coefficients(load, [BALL_REGIME_B, BALL_TWO_POINT], dbeta, force,
                                    TABLE1, ball_friction=0.1)
    _, release, _ = stick_line_release(dbeta[:1], force[:1], TABLE1)
    assert_array_equal(out[0, RELEASE], release[0])
    assert_array_equal(out[1, RELEASE], [INF, -INF])
    soft = regime_creep_coefficients(np.zeros((1, len(LOAD_COLUMNS))), [BALL_REGIME_A],
                                     dbeta[1:], force[1:], TABLE1)
    assert_array_equal(soft[0, RELEASE], [INF, -INF])


def test_fast_release_threshold_over_regime_b():
    # Case (a) over regime B, rho = -0.90 .. -0.99 (24 balls): the fast pushes against
    # stick_release's reference scan. Always found (finite: beyond some pushes the stick line
    # has no minimum at all, which counts as released), not smaller in size than the
    # reference's (a coarser scan only misses the least slope; 0.01 N for the bisection's
    # tolerances), and within 2 % (measured at most +1.8 %, +7.545 N against +7.413 N at
    # rho = -0.904).
    theta = np.radians(2.0)
    rho = np.linspace(-0.9, -0.99, 24)
    dbeta = np.tile([-theta, theta, 0.0, 0.0], (len(rho), 1))
    force = np.array([paired_forces(r * 200.0, 200.0) for r in rho])
    _, fast, _ = stick_line_release(dbeta, force, TABLE1)
    ref, _ = stick_release(dbeta, force, TABLE1)
    assert np.isfinite(fast).all() and np.isfinite(ref).all()
    assert np.all(np.abs(fast) >= np.abs(ref) - 0.01)
    assert_allclose(fast, ref, rtol=0.02)


def test_three_point_release_pushes_against_the_numpy_minimiser():
    # A three-point ball with a stuck contact: case (a) (theta = 2 deg on the bottom groove,
    # paired forces at rho = -0.85, N_y = 200 N) with BR open; full puts it on BL's stick
    # line (regime 2, K = 32 091 N, eps 0.037 %). It leaves the line when the line's minimum
    # of D - P v_B is no longer the minimum overall: the stick condition of stick_release
    # (Notes), whose derivation holds for any loaded contacts (the open one has F = 0 and
    # drops out of D and of sum F). The fast pushes (stick_line_release): +17.08 N and
    # -39.82 N, against the reference scan's +17.04 / -39.77 N (stick_release; within 0.5 %
    # and not smaller in size, as for regime B). The independent minimiser of D - P v_B
    # (minimise_dissipation, SciPy on the NumPy quadrature) stays on the line at 0.97 of each
    # push (|eps - eps_0| < 2 |P / K|; measured 1.02 and 1.09 |P / K|) and has left it at 1.03
    # (> 10 |P / K|; measured 85 and 47 |P / K|: eps 4.69 % and -5.96 %). The train columns of
    # such a ball carry these pushes (before: +-inf, so a train never noticed the release).
    dbeta, force = _case_a_three_point(1, rho=-0.85)
    _, fast, res = _fast_release_checked(dbeta, force)
    assert res.regime[0] == 2 and res.stuck_contact[0] == 0
    assert 17.0 < fast[0, 0] < 17.2 and -40.0 < fast[0, 1] < -39.6
    load = np.full((1, len(LOAD_COLUMNS)), np.nan)
    out = regime_creep_coefficients(load, [BALL_THREE_POINT], dbeta[None], force[None],
                                    TABLE1, ball_friction=0.1)
    assert_array_equal(out[0, RELEASE], fast[0])


def test_lazy_release_pushes_are_the_eager_ones_computed_once():
    # regime_creep_coefficients with lazy_release leaves the pushes of the balls on a stick
    # line pending (NaN, with their inputs); settle_release_pushes computes them for the
    # balls asked for, once, to the bit of the eager columns (the same kernel on the same
    # inputs). Balls: regime B (case (a), rho = -0.9, +2.95 N), three-point stuck (rho =
    # -0.85, BR open), three-point smooth (rho = -0.8, BR open: +-inf), two-point, regime A.
    theta = np.radians(2.0)
    d_b = np.array([-theta, theta, 0.0, 0.0])
    f_b = np.array(paired_forces(-0.9 * 200.0, 200.0))
    d_3s, f_3s = _case_a_three_point(1, rho=-0.85)
    d_3, f_3 = _case_a_three_point(1)
    dbeta = np.array([d_b, d_3s, d_3, np.zeros(4), np.zeros(4)])
    force = np.array([f_b, f_3s, f_3, [141.4, 0.0, 141.4, 0.0], [141.4] * 4])
    regime = [BALL_REGIME_B, BALL_THREE_POINT, BALL_THREE_POINT, BALL_TWO_POINT, BALL_REGIME_A]
    load = np.zeros((5, len(LOAD_COLUMNS)))
    eager = regime_creep_coefficients(load, regime, dbeta, force, TABLE1)
    lazy = regime_creep_coefficients(load, regime, dbeta, force, TABLE1, lazy_release=True)
    assert np.isnan(lazy[:2, RELEASE]).all()
    assert_array_equal(lazy[2:, RELEASE], [[INF, -INF]] * 3)
    assert np.isfinite(eager[:2, RELEASE]).all() and eager[0, RELEASE][0] < 3.0
    assert settle_release_pushes(lazy, [False, True, True, True, True], TABLE1) == 1
    assert np.isnan(lazy[0, RELEASE]).all()
    assert_array_equal(lazy[1], eager[1])
    assert settle_release_pushes(lazy, np.ones(5, bool), TABLE1) == 1
    assert settle_release_pushes(lazy, np.ones(5, bool), TABLE1) == 0
    assert_array_equal(lazy, eager)


def test_three_point_hessian_only_at_smooth_minima(monkeypatch):
    # The Hessian of D (minimum_compliance_kernel, six quadrature solves of the ball) gives the
    # coefficients of a smooth minimum only; a ball on a stick line takes them from its line.
    # It is computed for the smooth balls alone (before: for every ball, 30 % of a circuit
    # study without preload), and a mixed batch gives each ball's coefficients bit for bit as
    # alone. Balls: case (a) at rho = -0.8 with BR open (smooth, the test above) and a nearly
    # two-point ball of carriage_preload.toml at 0 um oversize (stuck; tests/physics/
    # test_regimes.py).
    import tolsim.physics.trains.ball_minimum as bm

    smooth_dbeta, smooth_force = _case_a_three_point(1)
    dbeta = np.array([smooth_dbeta, [0.005060088740111875, -0.002113268661801396,
                                     0.005197254707667683, -0.00191100420590903]])
    force = np.array([smooth_force, [14.003677780805587, 0.0, 14.003683961083574,
                                     0.00192083988315822]])
    alone = [three_point_coefficients(dbeta[i:i + 1], force[i:i + 1], TABLE1) for i in (0, 1)]
    seen = []
    kernel = bm.minimum_compliance_kernel

    def spy(beta, *args):
        seen.append(len(beta))
        return kernel(beta, *args)

    monkeypatch.setattr(bm, "minimum_compliance_kernel", spy)
    cols, rate = three_point_coefficients(dbeta, force, TABLE1)
    assert seen == [1]
    assert_array_equal(full(dbeta, force).regime, [1, 2])
    for i in (0, 1):
        for name, value in cols.items():
            assert_array_equal(value[i], alone[i][0][name][0], err_msg=name)
        assert_array_equal(rate[i], alone[i][1][0])
    assert np.isfinite(cols["creep_stiffness"]).all()


def test_stick_line_stiffness_from_the_tables_is_the_quadrature_s():
    # K on the stick line takes the line slope from the contact tables (as the line solve
    # does), no longer from the quadrature (``ball_loads_kernel``): 3.3-3.7x cheaper. Both
    # are the planar Coulomb integrals; the tables fit the quadrature to round-off, so K
    # agrees to 1e-12 relative (measured 2.4e-14 at most on 20 356 balls). Balls: case (a)
    # in regime B at rho = -0.9 and -0.98, and a nearly two-point three-point ball of
    # carriage_preload.toml at 0 um oversize (tests/physics/test_regimes.py).
    import tolsim.physics.trains.ball_minimum as bm
    from tolsim.physics.velocity._full_kernels import ball_loads_kernel

    theta = np.radians(2.0)
    dbeta = np.array([[-theta, theta, 0.0, 0.0], [-theta, theta, 0.0, 0.0],
                      [0.005060088740111875, -0.002113268661801396, 0.005197254707667683,
                       -0.00191100420590903]])
    force = np.array([paired_forces(-0.9 * 200.0, 200.0), paired_forces(-0.98 * 200.0, 200.0),
                      [14.003677780805587, 0.0, 14.003683961083574, 0.00192083988315822]])
    k, res = stick_line_stiffness(dbeta, force, TABLE1)
    assert_array_equal(res.regime, 2)
    _, beta, f, stuck, rate, a, b, grid = bm._stick_line(dbeta, force, TABLE1)
    for n in range(len(dbeta)):  # the quadrature's central difference, ball by ball
        j = stuck[n]
        px = bm.SIDE_SIGN_X * np.sin(beta[n])
        py = bm.SIDE_SIGN_Y * np.cos(beta[n])
        others = np.where(np.arange(4) == j, 0.0, f[n])
        vgroove = np.array([0.0, 0.0, 1.0, 1.0])
        xx, xy = -py[j], px[j]
        slope = []
        for w in (rate[n] - bm.STICK_STEP, rate[n] + bm.STICK_STEP):
            loads, contact = np.empty(5), np.empty((4, 5))
            ball_loads_kernel(np.array([vgroove[j] + w, w * xx, w * xy, 0.0]), px, py, vgroove,
                              others, a[n], b[n], 1.5 / np.pi, False, 1.0, np.zeros(4), *grid,
                              loads, contact)
            slope.append(-(loads[0] + loads[1] * xx + loads[2] * xy))
        quadrature = TABLE1.friction_coefficient * 0.25 * (slope[1] - slope[0]) / bm.STICK_STEP
        assert_allclose(k[n], quadrature, rtol=1e-12)
