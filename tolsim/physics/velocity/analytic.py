"""Analytical models of the ball velocity deviation epsilon ([Lin2018] Sec. 2.3-2.4).

Three models, each a Numba kernel over many balls behind a validated public function:

``eq24``
    Eq. (24): epsilon for pairwise-equal diagonal forces (F_1 on BL/TR, F_2 on BR/TL).
``analytic``
    The improved model proper: the linear friction law (17), the equilibrium (18) with the
    physical sign of the spin-moment block (ERRATA 8) and the linearised kinematic constraint
    (21) solved for the four zero-velocity offsets dgamma_i with four distinct forces;
    epsilon from the linearised Eq. (23), and the exact Eq. (22) reported beside it.
``point``
    The authors' prior point-contact model (ref. [11] of [Lin2018]): three contacts roll at
    their centres, the fourth slides; Fig. 7(b) baseline.

External loads (issue 13; derived in :mod:`tolsim.physics.velocity.ball_loads`): ``analytic`` takes
a push P of the neighbours (z-force row of Eq. 18) and their ball-to-ball braking moment
(moment rows, about the rolling axis) as keyword arguments, and returns the carriage friction
force, the creep stiffness K = dP/d(epsilon), the traction capacity and a sliding flag
(:func:`analytic_loaded_kernel`, kept apart from the study's :func:`analytic_kernel`, whose
speed and bits are unchanged). :func:`creep_coefficients_kernel` is its lean twin at zero load,
the creep coefficients a study's trains need (:mod:`tolsim.study.pipeline.track_friction`).

Signs (derived in :mod:`tolsim.physics.geometry`): c_i = s_i R dgamma_i with
s = (-1, +1, -1, +1), sgn(omega_i) = (+1, -1, -1, +1), so the friction force on the ball is
f_i = mu k_f (R / a_i) F_i g_i dgamma_i with g = (-1, -1, +1, +1).

ERRATA 9: linearising Eq. (22) gives the factor tan(beta_0)/2, not (1 - cos 2 beta_0)/2 (equal
only at 45 deg). Both Eq. (23) and Eq. (24) use tan(beta_0)/2 here.

Why ``analytic`` reduces exactly to Eq. (24) with paired forces: Eq. (18) row 1 reads
sum_i k_i g_i dgamma_i = 0, which with k_BL = k_TR = k_1, k_BR = k_TL = k_2 involves only
P = dgamma_TR - dgamma_BL and Q = dgamma_TL - dgamma_BR; Eq. (21) reads Q - P = D.  Those two
fix Q = k_1 D / (k_1 + k_2) whatever the moment rows say, and Eq. (23) needs only Q.
k_i ~ F_i / a_i ~ F_i^(2/3) then gives Eq. (24).
"""

from dataclasses import dataclass, field

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics._fastmath import cbrt_nonnegative, sin_cos_near
from tolsim.physics.geometry import K_F_PAPER, TABLE1, Bearing
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity.ball_loads import (
    DEFAULT_BALL_FRICTION,
    BallLoadFields,
    as_ball_loads,
    point_traction_capacity,
    rolling_axis,
    stall_moment,
)

# --------------------------------------------------------------------------------------------
# Validity: thresholds derived from an error budget against the full model (flags, never
# errors)
# --------------------------------------------------------------------------------------------
# A ball is *valid* for a fast model when its epsilon is within VALIDITY_ERROR_BUDGET of the
# comprehensive model (tolsim.physics.velocity.full.full) fed the same dbeta_i and F_i. In a study
# an invalid ball is re-solved with ``full`` (tolsim.study.pipeline.evaluate), so the thresholds
# trade
# speed (the share of balls the fast model keeps; full solves ~24 000 balls/s against ~15 M/s
# for analytic and ~90 M/s for eq24) against accuracy (the error on the balls it keeps), not
# truth against bias.
#
# Measured by ``python benchmarks/validity_budget.py`` (under a minute), on a grid of the
# Table 1 bearing: rho = N_x/N_y -0.95..0.95 step 0.05; rail and carriage groove rotations
# theta_b, theta_t -4..4 deg step 0.5; N_y = 50, 100, 200, 500, 1000 N; four contact states
# per point: the paper's paired forces with rigid angles, the solved static contact
# (tolsim.physics.static.solve_static) with the two rotations, and twice the same with
# random arc-centre offsets (tangential +-3 um, normal +-2 um) and ball oversize (+-0.5 um),
# which unpair the diagonal forces. 218 478 points, ``full`` converged on 200 479 (91.8 %);
# plus 20 000 fresh random balls between the grid points (seed 20240611). The errors are
# large on much of this grid (56 % of the points exceed the budget for analytic, 61 % for
# eq24): both models miss a relative 5-7 % of epsilon even at small |c/a| (for paired forces
# Eq. 24 does not depend on N_y, full does), more at large |c/a| and |rho|, and eq24 ignores
# unpaired forces; so |eps| itself is a criterion, besides the issue's |c/a| and
# |dbeta + dgamma|.
#
# Derivation: each criterion is put on a lattice of round values. A set of thresholds is
# admissible when no grid point and no fresh ball inside all of them has an error above the
# budget (the hard constraint, measured). Among the admissible sets the one that keeps the
# most balls of a realistic population (the tolerances of tolsim/data/default.toml, 20 000
# balls; ties broken by the share of the grid) is taken: that choice is speed only. Each
# threshold is then lowered to the extent of the grid and fresh points inside it, never to
# the realistic population's, beyond which nothing was measured.
#
# Result (budget 2e-4 = 0.02 pp):
#   analytic: |c/a| <= 0.18, |dbeta + dgamma| <= 1.6 deg, |eps| <= 0.52 %; max error inside
#             1.99e-4 on the grid (3.1 % of it inside), 1.48e-4 on the fresh balls; keeps
#             100 % of the realistic population (max error there 1.22e-4).
#   eq24:     q >= 0.24, |dbeta| <= 1.5 deg, pairing asymmetry P <= 0.015, |eps| <= 0.29 %;
#             max error inside 1.96e-4 on the grid (2.8 %), 1.93e-4 on the fresh balls;
#             keeps 97.9 % of the realistic population (max error there 8.1e-5).
# tests/test_validity_budget.py checks the budget on fresh random balls of another seed.
# Table 2 case (a) (theta = 2 deg, rho = +-0.6) is outside for both (|dbeta| = 2 deg, and its
# error is 3.5e-4: eps 0.754 % against 0.789 % from full), so a study re-solves those balls
# with full.

#: Budget on |eps_model - eps_full| [-] (0.02 percentage points) that the thresholds below
#: are derived from (benchmarks/validity_budget.py).
VALIDITY_ERROR_BUDGET = 2e-4
#: ``analytic``: largest |c_i/a_i| (c_i = R_B dgamma_i) at any contact.
MAX_ZERO_VELOCITY_RATIO = 0.18
#: ``analytic``: largest |dbeta_i + dgamma_i| [rad] at any contact.
MAX_ANGLE_SUM = np.deg2rad(1.6)
#: ``analytic``: largest |eps| [-] (Eq. 23).
MAX_VELOCITY_DEVIATION = 0.52e-2
#: ``eq24``: smallest ratio of the diagonal pair forces min(F_1, F_2)/max(F_1, F_2).
MIN_DIAGONAL_FORCE_RATIO = 0.24
#: ``eq24``: largest |dbeta_i| [rad] at any contact.
MAX_ANGLE_DEVIATION = np.deg2rad(1.5)
#: ``eq24``: largest pairing asymmetry
#: max(|F_BL - F_TR| / (F_BL + F_TR), |F_BR - F_TL| / (F_BR + F_TL)) (Eq. 24 assumes 0).
MAX_PAIRING_ASYMMETRY = 0.015
#: ``eq24``: largest |eps| [-].
MAX_EQ24_VELOCITY_DEVIATION = 0.29e-2


@dataclass(frozen=True)
class VelocityResult:
    """Result of a velocity model for n balls.

    Attributes
    ----------
    velocity_deviation : ndarray, shape (n,)
        epsilon [-], with v_B = (1 + epsilon) v / 2.
    valid : ndarray of bool, shape (n,)
        True where the model is trusted: for ``eq24`` and ``analytic``, inside the
        error-budget thresholds (module constants, "Validity").
    zero_velocity_offset : ndarray, shape (n, 4) or None
        dgamma_i [rad] (None for ``eq24``).
    velocity_deviation_eq22 : ndarray, shape (n,) or None
        epsilon from the exact Eq. (22) with the same dgamma (``analytic`` and ``point``).
    extra : dict
        Model-specific arrays (e.g. the sliding contact of ``point``).
    """

    velocity_deviation: np.ndarray
    valid: np.ndarray
    zero_velocity_offset: np.ndarray | None = None
    velocity_deviation_eq22: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class LoadedVelocityResult(VelocityResult, BallLoadFields):
    """Result of ``analytic`` for n balls under external loads (push, neighbours).

    The fields of :class:`VelocityResult` at the loaded state (``velocity_deviation``,
    ``zero_velocity_offset``, ``velocity_deviation_eq22``), those of
    :class:`tolsim.physics.velocity.ball_loads.BallLoadFields`, and the two coefficients that make
    the
    carriage force linear in the loads (the model is linear):
    F_c = free_rolling_carriage_force + carriage_force_per_push P
    + carriage_force_per_neighbour_force (Q_back + Q_front); likewise
    epsilon = free_rolling_velocity_deviation + P / creep_stiffness
    + braking_sensitivity (Q_back + Q_front).

    Attributes
    ----------
    carriage_force_per_push : ndarray, shape (n,)
        dF_c/dP [-] (about -1/2: the grooves share a push).
    carriage_force_per_neighbour_force : ndarray, shape (n,)
        dF_c/d(Q_back + Q_front) [-] (mu_bb / (2 cos beta_0) for the nominal ball).
    """

    carriage_force_per_push: np.ndarray
    carriage_force_per_neighbour_force: np.ndarray


# --------------------------------------------------------------------------------------------
# Kernels: typed loops, no checks, outputs written into preallocated arrays.
# --------------------------------------------------------------------------------------------
@pjit
def _diagonal_force_ratio_squared(force, out):
    """(min(F_1, F_2) / max(F_1, F_2))^2 per ball (pass 1 of Eq. 24)."""
    for n in prange(force.shape[0]):
        f1 = force[n, 0] + force[n, 2]
        f2 = force[n, 1] + force[n, 3]
        q = min(f1, f2) / max(f1, f2)
        out[n] = q * q


@pjit
def _eq24_finish(dbeta, force, ratio, nominal_angle, min_ratio, max_angle, max_asymmetry,
                 max_eps, out_eps, out_valid):
    """Eq. (24) given r = (F_small/F_large)^(2/3) per ball (pass 3), and its validity."""
    half_tan = 0.5 * np.tan(nominal_angle)
    for n in prange(dbeta.shape[0]):
        f1 = force[n, 0] + force[n, 2]
        f2 = force[n, 1] + force[n, 3]
        d1 = dbeta[n, 2] - dbeta[n, 0]  # -dbeta_BL + dbeta_TR, weighted by F_1^(2/3)
        d2 = dbeta[n, 3] - dbeta[n, 1]  # -dbeta_BR + dbeta_TL, weighted by F_2^(2/3)
        r = ratio[n]
        w1 = 1.0 if f1 >= f2 else r
        w2 = r if f1 >= f2 else 1.0
        num = half_tan * (w1 * d1 + w2 * d2)
        out_eps[n] = num / (1.0 + r)
        smallest = min(min(force[n, 0], force[n, 1]), min(force[n, 2], force[n, 3]))
        largest_angle = max(max(abs(dbeta[n, 0]), abs(dbeta[n, 1])),
                            max(abs(dbeta[n, 2]), abs(dbeta[n, 3])))
        q = min(f1, f2) / max(f1, f2)
        # Written so that the loop stays vectorised (this pass measured 2.3x faster than
        # testing |eps| on the quotient or folding the tests into one max): |eps| <= max_eps
        # as |num| <= max_eps (1 + r), and the pairing asymmetry |F_BL - F_TR| / F_1 <=
        # max_asymmetry (likewise BR, TL) without a division.
        u1 = force[n, 0] - force[n, 2]
        u2 = force[n, 1] - force[n, 3]
        t1 = max_asymmetry * f1
        t2 = max_asymmetry * f2
        out_valid[n] = ((smallest > 0.0) & (q >= min_ratio) & (largest_angle <= max_angle)
                        & (abs(u1) <= t1) & (abs(u2) <= t2) & (abs(num) <= max_eps * (1.0 + r)))


def eq24_kernel(dbeta, force, nominal_angle, min_ratio, max_angle, max_asymmetry, max_eps,
                out_eps, out_valid):
    """Eq. (24) with F_1 = (F_BL + F_TR)/2 and F_2 = (F_BR + F_TL)/2; unchecked fast path.

    Written with the ratio r = (F_small/F_large)^(2/3): one cube root per ball, no overflow,
    evaluated for all balls at once with the vectorised cube root (three passes).
    ``dbeta`` and ``force`` are C-contiguous (n, 4) float64; ``out_eps`` (n,) float64 doubles
    as scratch. ``out_valid``: all forces > 0, diagonal force ratio >= ``min_ratio``,
    |dbeta_i| <= ``max_angle``, pairing asymmetry <= ``max_asymmetry``, |eps| <= ``max_eps``
    (the module constants: ``MIN_DIAGONAL_FORCE_RATIO``, ``MAX_ANGLE_DEVIATION``,
    ``MAX_PAIRING_ASYMMETRY``, ``MAX_EQ24_VELOCITY_DEVIATION``).
    """
    _diagonal_force_ratio_squared(force, out_eps)
    ratio = cbrt_nonnegative(out_eps)
    _eq24_finish(dbeta, force, ratio, nominal_angle, min_ratio, max_angle, max_asymmetry,
                 max_eps, out_eps, out_valid)


@pjit
def count_bad_inputs(dbeta, force):
    """One parallel pass: counts of non-finite dbeta, non-finite force and negative force."""
    bad_angle = 0
    bad_force = 0
    negative = 0
    for n in prange(dbeta.shape[0]):
        for i in range(4):
            if not np.isfinite(dbeta[n, i]):
                bad_angle += 1
            if not np.isfinite(force[n, i]):
                bad_force += 1
            elif force[n, i] < 0.0:
                negative += 1
    return bad_angle, bad_force, negative


@jit(inline="always")
def det3(a11, a12, a13, a21, a22, a23, a31, a32, a33):
    return (
        a11 * (a22 * a33 - a23 * a32)
        - a12 * (a21 * a33 - a23 * a31)
        + a13 * (a21 * a32 - a22 * a31)
    )


@jit(inline="always")
def eq22_velocity_deviation(b_bl, b_br, b_tl):
    """Eq. (22): epsilon from the angles of the zero-velocity points (TR follows from (19))."""
    num = np.sin(b_bl + b_br)
    return 2.0 * num / (num + np.sin(b_bl + b_tl) + np.sin(b_br - b_tl)) - 1.0


def analytic_kernel(
    dbeta, force, nominal_angle, ball_radius, semi_major_coefficient, elliptic_e, k_f,
    max_ratio, max_angle, max_eps, out_eps, out_eps22, out_gamma, out_valid,
):
    """Solve Eqs. (17), (18) [ERRATA 8 sign], (21) for dgamma_i; unchecked fast path.

    ``dbeta``, ``force``: C-contiguous (n, 4) float64. The cube roots F_i^(1/3) (for a_i) are
    taken for all balls at once with the vectorised cube root, then the per-ball solve runs.
    ``out_eps22`` of length 0 skips Eq. (22), ``out_gamma`` with 0 rows skips storing dgamma
    (a study needs neither). ``out_valid``: all forces > 0, |c_i/a_i| <= ``max_ratio`` and
    |dbeta_i + dgamma_i| <= ``max_angle`` at every contact, and |eps| <= ``max_eps`` (the
    module constants ``MAX_ZERO_VELOCITY_RATIO``, ``MAX_ANGLE_SUM``,
    ``MAX_VELOCITY_DEVIATION``).
    """
    force_cbrt = cbrt_nonnegative(force)
    _analytic_solve(dbeta, force, force_cbrt, nominal_angle, ball_radius,
                    semi_major_coefficient, elliptic_e, k_f, max_ratio, max_angle, max_eps,
                    out_eps, out_eps22, out_gamma, out_valid)


@pjit
def _analytic_solve(
    dbeta, force, force_cbrt, nominal_angle, ball_radius, semi_major_coefficient, elliptic_e,
    k_f, max_ratio, max_angle, max_eps, out_eps, out_eps22, out_gamma, out_valid,
):
    """Per-ball closed-form solve of Eqs. (17), (18), (21); epsilon from (23) and (22)."""
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    with_eq22 = out_eps22.shape[0] > 0
    with_gamma = out_gamma.shape[0] > 0
    for n in prange(dbeta.shape[0]):
        # Contact angles and axes. x_i, y_i components (global x, y), order BL, BR, TR, TL.
        s0, c0 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 0])
        s1, c1 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 1])
        s2, c2 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 2])
        s3, c3 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 3])
        # local x axes: BL (c,-s) BR (c,s) TR (-c,s) TL (-c,-s)
        x0, y0 = c0, -s0
        x1, y1 = c1, s1
        x2, y2 = -c2, s2
        x3, y3 = -c3, -s3
        # inward normals y_i: BL (s,c) BR (-s,c) TR (-s,-c) TL (s,-c)
        f0, f1, f2, f3 = force[n, 0], force[n, 1], force[n, 2], force[n, 3]
        ok = min(min(f0, f1), min(f2, f3)) > 0.0
        a0 = semi_major_coefficient * force_cbrt[n, 0]
        a1 = semi_major_coefficient * force_cbrt[n, 1]
        a2 = semi_major_coefficient * force_cbrt[n, 2]
        a3 = semi_major_coefficient * force_cbrt[n, 3]
        # u_i = q_i dgamma_i = friction force / mu; q_i = k_f R F_i / a_i * g_i, g = (-,-,+,+)
        q0 = -k_f * ball_radius * f0 / a0
        q1 = -k_f * ball_radius * f1 / a1
        q2 = k_f * ball_radius * f2 / a2
        q3 = k_f * ball_radius * f3 / a3
        # spin moments / (mu R): m_i = 3/8 F_i a_i E(e) / R, signed with sgn(omega) = (+,-,-,+)
        sc = 0.375 * elliptic_e / ball_radius
        m0 = sc * f0 * a0
        m1 = -sc * f1 * a1
        m2 = -sc * f2 * a2
        m3 = sc * f3 * a3
        # Moment rows (ERRATA 8): sum u_i x_i + sum m_i y_i = 0
        r2 = -(m0 * s0 - m1 * s1 - m2 * s2 + m3 * s3)
        r3 = -(m0 * c0 + m1 * c1 - m2 * c2 - m3 * c3)
        # Null vector of rows (1,1,1,1), (x_i), (y_i): n_j = (-1)^j det(without column j)
        d012 = det3(1.0, 1.0, 1.0, x0, x1, x2, y0, y1, y2)
        n0 = det3(1.0, 1.0, 1.0, x1, x2, x3, y1, y2, y3)
        n1 = -det3(1.0, 1.0, 1.0, x0, x2, x3, y0, y2, y3)
        n2 = det3(1.0, 1.0, 1.0, x0, x1, x3, y0, y1, y3)
        n3 = -d012
        # Particular solution with u_3 = 0 (Cramer); rhs (0, r2, r3)
        p0 = det3(0.0, 1.0, 1.0, r2, x1, x2, r3, y1, y2) / d012
        p1 = det3(1.0, 0.0, 1.0, x0, r2, x2, y0, r3, y2) / d012
        p2 = det3(1.0, 1.0, 0.0, x0, x1, r2, y0, y1, r3) / d012
        # Eq. (21): g_BL - g_BR - g_TR + g_TL = -(db_BL + db_TL - db_BR - db_TR)
        rhs = -(dbeta[n, 0] + dbeta[n, 3] - dbeta[n, 1] - dbeta[n, 2])
        w0, w1, w2, w3 = 1.0 / q0, -1.0 / q1, -1.0 / q2, 1.0 / q3
        t = (rhs - (w0 * p0 + w1 * p1 + w2 * p2)) / (w0 * n0 + w1 * n1 + w2 * n2 + w3 * n3)
        g0 = (p0 + t * n0) / q0
        g1 = (p1 + t * n1) / q1
        g2 = (p2 + t * n2) / q2
        g3 = (t * n3) / q3
        if with_gamma:
            out_gamma[n, 0] = g0
            out_gamma[n, 1] = g1
            out_gamma[n, 2] = g2
            out_gamma[n, 3] = g3
        eps = half_tan * (-dbeta[n, 1] - g1 + dbeta[n, 3] + g3)
        out_eps[n] = eps
        if with_eq22:
            out_eps22[n] = eq22_velocity_deviation(nominal_angle + dbeta[n, 0] + g0,
                                                   nominal_angle + dbeta[n, 1] + g1,
                                                   nominal_angle + dbeta[n, 3] + g3)
        ok = ok and ball_radius * abs(g0) <= max_ratio * a0
        ok = ok and ball_radius * abs(g1) <= max_ratio * a1
        ok = ok and ball_radius * abs(g2) <= max_ratio * a2
        ok = ok and ball_radius * abs(g3) <= max_ratio * a3
        ok = ok and abs(dbeta[n, 0] + g0) <= max_angle and abs(dbeta[n, 1] + g1) <= max_angle
        ok = ok and abs(dbeta[n, 2] + g2) <= max_angle and abs(dbeta[n, 3] + g3) <= max_angle
        out_valid[n] = ok and abs(eps) <= max_eps


#: Columns of ``out_load`` of :func:`analytic_loaded_kernel`.
LOAD_COLUMNS = ("free_rolling_velocity_deviation", "creep_stiffness", "braking_sensitivity",
                "carriage_force", "free_rolling_carriage_force", "carriage_force_per_push",
                "carriage_force_per_neighbour_force", "traction_capacity", "braking_capacity")


def analytic_loaded_kernel(
    dbeta, force, push, neighbour_force_sum, nominal_angle, ball_radius, semi_major_coefficient,
    elliptic_e, k_f, friction_coefficient, ball_friction, max_ratio, max_angle, max_eps,
    out_eps, out_eps22, out_gamma, out_valid, out_load, out_sliding,
):
    """The analytic model under external loads; unchecked fast path (trains call it).

    Eqs. (17), (18) [ERRATA 8], (21) with the push P in the z-force row and the ball-ball
    braking moment in the moment rows (:mod:`tolsim.physics.velocity.ball_loads`):

        sum u_i = -P / mu,  sum u_i x_i + sum m_i y_i = -(mu_bb / mu)(Q_back + Q_front) e,

    e the rolling axis (:func:`~tolsim.physics.velocity.ball_loads.rolling_axis`). The system is
    linear in the loads, so each ball is solved three times on the same matrix: free (the
    arithmetic of :func:`analytic_kernel`, so P = Q = 0 reproduces its epsilon bit for bit),
    per unit P and per unit Q_back + Q_front; the loaded state is their superposition, and
    the creep stiffness K = 1 / (d epsilon / dP) follows exactly from the unit-push solve.

    ``dbeta``, ``force``: C-contiguous (n, 4) float64; ``push``, ``neighbour_force_sum``: (n,)
    [N]; ``friction_coefficient`` mu > 0 (raceways) and ``ball_friction`` mu_bb >= 0.
    Outputs as :func:`analytic_kernel` (``out_eps22`` and ``out_gamma`` always written), and
    ``out_load`` (n, 9) with the columns ``LOAD_COLUMNS`` (epsilon free [-], K [N], d epsilon
    / d(Q_back + Q_front) [1/N], F_c and F_c free [N], dF_c/dP and dF_c/d(Q_back + Q_front)
    [-], traction capacity and braking capacity [N]), ``out_sliding`` (n,) bool: |P| >=
    traction capacity or Q_back + Q_front >= braking capacity.
    ``out_valid``: the criteria of :func:`analytic_kernel` on the loaded dgamma_i (|c_i/a_i|,
    |dbeta_i + dgamma_i|) and on the free epsilon (|eps| <= ``max_eps``, the deviation-driven
    part the budget was measured for), and not sliding.
    """
    force_cbrt = cbrt_nonnegative(force)
    _analytic_loaded_solve(dbeta, force, force_cbrt, push, neighbour_force_sum, nominal_angle,
                           ball_radius, semi_major_coefficient, elliptic_e, k_f,
                           friction_coefficient, ball_friction, max_ratio, max_angle, max_eps,
                           out_eps, out_eps22, out_gamma, out_valid, out_load, out_sliding)


@pjit
def _analytic_loaded_solve(
    dbeta, force, force_cbrt, push, neighbour_force_sum, nominal_angle, ball_radius,
    semi_major_coefficient, elliptic_e, k_f, friction_coefficient, ball_friction, max_ratio,
    max_angle, max_eps, out_eps, out_eps22, out_gamma, out_valid, out_load, out_sliding,
):
    """Per-ball solve of :func:`analytic_loaded_kernel` (free, unit push, unit braking)."""
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    inv_mu = 1.0 / friction_coefficient
    braking_ratio = ball_friction * inv_mu  # (mu_bb / mu) per newton of Q_back + Q_front
    for n in prange(dbeta.shape[0]):
        # --- the system of analytic_kernel, same arithmetic ---
        s0, c0 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 0])
        s1, c1 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 1])
        s2, c2 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 2])
        s3, c3 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 3])
        x0, y0 = c0, -s0
        x1, y1 = c1, s1
        x2, y2 = -c2, s2
        x3, y3 = -c3, -s3
        f0, f1, f2, f3 = force[n, 0], force[n, 1], force[n, 2], force[n, 3]
        ok = min(min(f0, f1), min(f2, f3)) > 0.0
        a0 = semi_major_coefficient * force_cbrt[n, 0]
        a1 = semi_major_coefficient * force_cbrt[n, 1]
        a2 = semi_major_coefficient * force_cbrt[n, 2]
        a3 = semi_major_coefficient * force_cbrt[n, 3]
        q0 = -k_f * ball_radius * f0 / a0
        q1 = -k_f * ball_radius * f1 / a1
        q2 = k_f * ball_radius * f2 / a2
        q3 = k_f * ball_radius * f3 / a3
        sc = 0.375 * elliptic_e / ball_radius
        m0 = sc * f0 * a0
        m1 = -sc * f1 * a1
        m2 = -sc * f2 * a2
        m3 = sc * f3 * a3
        r2 = -(m0 * s0 - m1 * s1 - m2 * s2 + m3 * s3)
        r3 = -(m0 * c0 + m1 * c1 - m2 * c2 - m3 * c3)
        d012 = det3(1.0, 1.0, 1.0, x0, x1, x2, y0, y1, y2)
        n0 = det3(1.0, 1.0, 1.0, x1, x2, x3, y1, y2, y3)
        n1 = -det3(1.0, 1.0, 1.0, x0, x2, x3, y0, y2, y3)
        n2 = det3(1.0, 1.0, 1.0, x0, x1, x3, y0, y1, y3)
        n3 = -d012
        p0 = det3(0.0, 1.0, 1.0, r2, x1, x2, r3, y1, y2) / d012
        p1 = det3(1.0, 0.0, 1.0, x0, r2, x2, y0, r3, y2) / d012
        p2 = det3(1.0, 1.0, 0.0, x0, x1, r2, y0, y1, r3) / d012
        rhs = -(dbeta[n, 0] + dbeta[n, 3] - dbeta[n, 1] - dbeta[n, 2])
        w0, w1, w2, w3 = 1.0 / q0, -1.0 / q1, -1.0 / q2, 1.0 / q3
        wn = w0 * n0 + w1 * n1 + w2 * n2 + w3 * n3
        t = (rhs - (w0 * p0 + w1 * p1 + w2 * p2)) / wn
        g0 = (p0 + t * n0) / q0
        g1 = (p1 + t * n1) / q1
        g2 = (p2 + t * n2) / q2
        g3 = (t * n3) / q3
        eps = half_tan * (-dbeta[n, 1] - g1 + dbeta[n, 3] + g3)
        # --- unit push: rhs (-1/mu, 0, 0), Eq. (21) homogeneous ---
        pp0 = det3(-inv_mu, 1.0, 1.0, 0.0, x1, x2, 0.0, y1, y2) / d012
        pp1 = det3(1.0, -inv_mu, 1.0, x0, 0.0, x2, y0, 0.0, y2) / d012
        pp2 = det3(1.0, 1.0, -inv_mu, x0, x1, 0.0, y0, y1, 0.0) / d012
        tp = -(w0 * pp0 + w1 * pp1 + w2 * pp2) / wn
        # --- unit Q_back + Q_front: braking -(mu_bb/mu) e in the moment rows ---
        beta = np.empty(4)
        for i in range(4):
            beta[i] = nominal_angle + dbeta[n, i]
        ex, ey = rolling_axis(beta, force[n])
        bx = -braking_ratio * ex
        by = -braking_ratio * ey
        pb0 = det3(0.0, 1.0, 1.0, bx, x1, x2, by, y1, y2) / d012
        pb1 = det3(1.0, 0.0, 1.0, x0, bx, x2, y0, by, y2) / d012
        pb2 = det3(1.0, 1.0, 0.0, x0, x1, bx, y0, y1, by) / d012
        tb = -(w0 * pb0 + w1 * pb1 + w2 * pb2) / wn
        # --- superposition ---
        load_p = push[n]
        load_q = neighbour_force_sum[n]
        g0 = g0 + (load_p * (pp0 + tp * n0) / q0 + load_q * (pb0 + tb * n0) / q0)
        g1 = g1 + (load_p * (pp1 + tp * n1) / q1 + load_q * (pb1 + tb * n1) / q1)
        g2 = g2 + (load_p * (pp2 + tp * n2) / q2 + load_q * (pb2 + tb * n2) / q2)
        g3 = g3 + (load_p * (tp * n3) / q3 + load_q * (tb * n3) / q3)
        deps_dp = half_tan * (-(pp1 + tp * n1) / q1 + (tp * n3) / q3)
        deps_dq = half_tan * (-(pb1 + tb * n1) / q1 + (tb * n3) / q3)
        out_eps[n] = eps + (load_p * deps_dp + load_q * deps_dq)
        out_gamma[n, 0] = g0
        out_gamma[n, 1] = g1
        out_gamma[n, 2] = g2
        out_gamma[n, 3] = g3
        out_eps22[n] = eq22_velocity_deviation(nominal_angle + dbeta[n, 0] + g0,
                                               nominal_angle + dbeta[n, 1] + g1,
                                               nominal_angle + dbeta[n, 3] + g3)
        # carriage force: the top contacts' friction along z, mu (u_TR + u_TL), u = p + t n
        fc_free = friction_coefficient * ((p2 + t * n2) + t * n3)
        fc_p = friction_coefficient * ((pp2 + tp * n2) + tp * n3)
        fc_q = friction_coefficient * ((pb2 + tb * n2) + tb * n3)
        capacity, _, _ = point_traction_capacity(beta, force[n], braking_ratio * load_q, ex, ey)
        capacity *= friction_coefficient
        stall = stall_moment(beta, force[n]) * friction_coefficient
        braking_capacity = stall / ball_friction if ball_friction > 0.0 else np.inf
        sliding = abs(load_p) >= capacity or load_q >= braking_capacity
        out_load[n, 0] = eps
        out_load[n, 1] = 1.0 / deps_dp
        out_load[n, 2] = deps_dq
        out_load[n, 3] = fc_free + (load_p * fc_p + load_q * fc_q)
        out_load[n, 4] = fc_free
        out_load[n, 5] = fc_p
        out_load[n, 6] = fc_q
        out_load[n, 7] = capacity
        out_load[n, 8] = braking_capacity
        out_sliding[n] = sliding
        ok = ok and ball_radius * abs(g0) <= max_ratio * a0
        ok = ok and ball_radius * abs(g1) <= max_ratio * a1
        ok = ok and ball_radius * abs(g2) <= max_ratio * a2
        ok = ok and ball_radius * abs(g3) <= max_ratio * a3
        ok = ok and abs(dbeta[n, 0] + g0) <= max_angle and abs(dbeta[n, 1] + g1) <= max_angle
        ok = ok and abs(dbeta[n, 2] + g2) <= max_angle and abs(dbeta[n, 3] + g3) <= max_angle
        out_valid[n] = ok and abs(eps) <= max_eps and not sliding


# --------------------------------------------------------------------------------------------
# Creep coefficients at zero load: the loaded model's fast path for a study's trains
# --------------------------------------------------------------------------------------------
@pjit
def creep_coefficients_kernel(dbeta, force, force_cbrt, nominal_angle, ball_radius,
                              semi_major_coefficient, elliptic_e, k_f, friction_coefficient,
                              ball_friction, out_load):
    """The loaded analytic model's coefficients at zero load, a study's fast path; unchecked.

    The columns of :func:`analytic_loaded_kernel` (``LOAD_COLUMNS``)
    with push and neighbour forces zero, written into ``out_load`` (n, 9): the free, unit-push
    and unit-braking solves with the same arithmetic (so epsilon, K, c, F_0, a, b agree with
    it to round-off, tests/test_friction_study.py), the rolling axis and the stall moment of
    :mod:`tolsim.physics.velocity.ball_loads` from the same sines and cosines. What it leaves out is
    what a study does not need and what costs most there (the vertex search of
    :func:`tolsim.physics.velocity.ball_loads.point_traction_capacity`, Eq. 22, dgamma, validity):
    column ``traction_capacity`` holds a **lower bound** of the point-contact traction
    capacity instead, from a dual-feasible point of its linear programme. With
    u_i = 1 + a_i . w (a_i = (p_y, -p_x)) and any lambda_i in [-1, 1],

        Phi_0(w) = sum_i F_i |u_i| (+ braking >= 0) >= sum_i lambda_i F_i
                   + w . sum_i lambda_i F_i a_i,

    so every lambda with sum_i lambda_i F_i a_i = 0 gives P_cap >= mu sum_i lambda_i F_i.
    lambda = 1 - delta with delta on two contacts j, k solving sum F_i a_i = g_j a_j + g_k a_k
    (g = delta F >= 0, delta <= 2) gives mu (sum F_i - g_j - g_k); the best pair is taken (0 if
    none is feasible). For a ball in static equilibrium sum F_i a_i = 0 and the bound is the
    capacity, mu sum F_i. Otherwise it is the optimum of the dual whenever an optimal lambda
    has its two free entries on one pair and +1 elsewhere; on 20 000 random balls (dbeta ~
    0.6 deg, forces 0.3-1.7 x 141 N, far from equilibrium) it equalled the vertex search to
    1e-15 (tests/test_friction_study.py), 1/3 of its cost.

    ``dbeta``, ``force``, ``force_cbrt`` (:func:`tolsim.physics._fastmath.cbrt_nonnegative` of
    ``force``): C-contiguous (n, 4) float64; ``out_load`` (n, 9). Called by
    :mod:`tolsim.study.pipeline.track_friction` (``creep_model = "analytic"``), one call per chunk.
    """
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    inv_mu = 1.0 / friction_coefficient
    braking_ratio = ball_friction * inv_mu
    for n in prange(dbeta.shape[0]):
        # --- the free solve of analytic_kernel, same arithmetic ---
        s0, c0 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 0])
        s1, c1 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 1])
        s2, c2 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 2])
        s3, c3 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 3])
        x0, y0 = c0, -s0
        x1, y1 = c1, s1
        x2, y2 = -c2, s2
        x3, y3 = -c3, -s3
        f0, f1, f2, f3 = force[n, 0], force[n, 1], force[n, 2], force[n, 3]
        a0 = semi_major_coefficient * force_cbrt[n, 0]
        a1 = semi_major_coefficient * force_cbrt[n, 1]
        a2 = semi_major_coefficient * force_cbrt[n, 2]
        a3 = semi_major_coefficient * force_cbrt[n, 3]
        q0 = -k_f * ball_radius * f0 / a0
        q1 = -k_f * ball_radius * f1 / a1
        q2 = k_f * ball_radius * f2 / a2
        q3 = k_f * ball_radius * f3 / a3
        sc = 0.375 * elliptic_e / ball_radius
        m0 = sc * f0 * a0
        m1 = -sc * f1 * a1
        m2 = -sc * f2 * a2
        m3 = sc * f3 * a3
        r2 = -(m0 * s0 - m1 * s1 - m2 * s2 + m3 * s3)
        r3 = -(m0 * c0 + m1 * c1 - m2 * c2 - m3 * c3)
        d012 = det3(1.0, 1.0, 1.0, x0, x1, x2, y0, y1, y2)
        n0 = det3(1.0, 1.0, 1.0, x1, x2, x3, y1, y2, y3)
        n1 = -det3(1.0, 1.0, 1.0, x0, x2, x3, y0, y2, y3)
        n2 = det3(1.0, 1.0, 1.0, x0, x1, x3, y0, y1, y3)
        n3 = -d012
        p0 = det3(0.0, 1.0, 1.0, r2, x1, x2, r3, y1, y2) / d012
        p1 = det3(1.0, 0.0, 1.0, x0, r2, x2, y0, r3, y2) / d012
        p2 = det3(1.0, 1.0, 0.0, x0, x1, r2, y0, y1, r3) / d012
        rhs = -(dbeta[n, 0] + dbeta[n, 3] - dbeta[n, 1] - dbeta[n, 2])
        w0, w1, w2, w3 = 1.0 / q0, -1.0 / q1, -1.0 / q2, 1.0 / q3
        wn = w0 * n0 + w1 * n1 + w2 * n2 + w3 * n3
        t = (rhs - (w0 * p0 + w1 * p1 + w2 * p2)) / wn
        g1 = (p1 + t * n1) / q1
        g3 = (t * n3) / q3
        eps = half_tan * (-dbeta[n, 1] - g1 + dbeta[n, 3] + g3)
        # --- unit push ---
        pp0 = det3(-inv_mu, 1.0, 1.0, 0.0, x1, x2, 0.0, y1, y2) / d012
        pp1 = det3(1.0, -inv_mu, 1.0, x0, 0.0, x2, y0, 0.0, y2) / d012
        pp2 = det3(1.0, 1.0, -inv_mu, x0, x1, 0.0, y0, y1, 0.0) / d012
        tp = -(w0 * pp0 + w1 * pp1 + w2 * pp2) / wn
        # --- rolling axis (ball_loads.rolling_axis): rows (1, p_y, -p_x), p_y = -x, p_x = y ---
        ex, ey = _creep_rolling_axis(x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3)
        # --- unit Q_back + Q_front ---
        bx = -braking_ratio * ex
        by = -braking_ratio * ey
        pb0 = det3(0.0, 1.0, 1.0, bx, x1, x2, by, y1, y2) / d012
        pb1 = det3(1.0, 0.0, 1.0, x0, bx, x2, y0, by, y2) / d012
        pb2 = det3(1.0, 1.0, 0.0, x0, x1, bx, y0, y1, by) / d012
        tb = -(w0 * pb0 + w1 * pb1 + w2 * pb2) / wn
        deps_dp = half_tan * (-(pp1 + tp * n1) / q1 + (tp * n3) / q3)
        deps_dq = half_tan * (-(pb1 + tb * n1) / q1 + (tb * n3) / q3)
        fc_free = friction_coefficient * ((p2 + t * n2) + t * n3)
        fc_p = friction_coefficient * ((pp2 + tp * n2) + tp * n3)
        fc_q = friction_coefficient * ((pb2 + tb * n2) + tb * n3)
        # --- stall moment (ball_loads.stall_moment): |sum_bottom F x - sum_top F x| ---
        stall = np.hypot(f0 * x0 + f1 * x1 - f2 * x2 - f3 * x3,
                         f0 * y0 + f1 * y1 - f2 * y2 - f3 * y3) * friction_coefficient
        out_load[n, 0] = eps
        out_load[n, 1] = 1.0 / deps_dp
        out_load[n, 2] = deps_dq
        out_load[n, 3] = fc_free
        out_load[n, 4] = fc_free
        out_load[n, 5] = fc_p
        out_load[n, 6] = fc_q
        out_load[n, 7] = friction_coefficient * _creep_traction_bound(
            x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3)
        out_load[n, 8] = stall / ball_friction if ball_friction > 0.0 else np.inf


@jit(inline="always")
def _creep_rolling_axis(x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3):
    """:func:`tolsim.physics.velocity.ball_loads.rolling_axis` from the local x axes
    x_i = (-p_y, p_x)
    (same least squares, same Cramer's rule); (1, 0) if singular."""
    a00 = a01 = a02 = a11 = a12 = a22 = 0.0
    b0 = b1 = b2 = 0.0
    for i in range(4):
        if i == 0:
            xx, xy, f, target = x0, y0, f0, 0.0
        elif i == 1:
            xx, xy, f, target = x1, y1, f1, 0.0
        elif i == 2:
            xx, xy, f, target = x2, y2, f2, 1.0
        else:
            xx, xy, f, target = x3, y3, f3, 1.0
        if f > 0.0:
            r1, r2 = -xx, -xy  # (1, p_y, -p_x)
            b0 += target
            b1 += r1 * target
            b2 += r2 * target
            a00 += 1.0
            a01 += r1
            a02 += r2
            a11 += r1 * r1
            a12 += r1 * r2
            a22 += r2 * r2
    det = (a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02)
           + a02 * (a01 * a12 - a11 * a02))
    if not (abs(det) > 1e-300):
        return 1.0, 0.0
    wx = (a00 * (b1 * a22 - a12 * b2) - b0 * (a01 * a22 - a12 * a02)
          + a02 * (a01 * b2 - b1 * a02)) / det
    wy = (a00 * (a11 * b2 - b1 * a12) - a01 * (a01 * b2 - b1 * a02)
          + b0 * (a01 * a12 - a11 * a02)) / det
    norm = np.hypot(wx, wy)
    if not norm > 0.0:
        return 1.0, 0.0
    return wx / norm, wy / norm


@jit(inline="always")
def _creep_traction_bound(x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3):
    """Lower bound of min_w sum_i F_i |1 + a_i . w| with a_i = -x_i (kernel docstring)."""
    rx = -(f0 * x0 + f1 * x1 + f2 * x2 + f3 * x3)
    ry = -(f0 * y0 + f1 * y1 + f2 * y2 + f3 * y3)
    total = f0 + f1 + f2 + f3
    if rx == 0.0 and ry == 0.0:
        return total
    best = 0.0
    for j in range(4):
        for k in range(j + 1, 4):
            ajx, ajy, fj = ((-x0, -y0, f0) if j == 0 else (-x1, -y1, f1) if j == 1
                            else (-x2, -y2, f2))
            akx, aky, fk = ((-x1, -y1, f1) if k == 1 else (-x2, -y2, f2) if k == 2
                            else (-x3, -y3, f3))
            det = ajx * aky - ajy * akx
            if abs(det) < 1e-12:
                continue
            gj = (rx * aky - ry * akx) / det
            gk = (ajx * ry - ajy * rx) / det
            if 0.0 <= gj <= 2.0 * fj and 0.0 <= gk <= 2.0 * fk:
                bound = total - gj - gk
                if bound > best:
                    best = bound
    return best


@jit
def _point_one(beta, force):
    """Point-contact model for one ball (v = 1). Returns eps, eps22, gamma[4], slider, margin."""
    sx = (-1.0, 1.0, 1.0, -1.0)
    sy = (-1.0, -1.0, 1.0, 1.0)
    target = (0.0, 0.0, 1.0, 1.0)  # groove velocity along z at each contact
    px = np.empty(4)
    py = np.empty(4)
    xx = np.empty(4)
    xy = np.empty(4)
    for i in range(4):
        px[i] = sx[i] * np.sin(beta[i])
        py[i] = sy[i] * np.cos(beta[i])
        # local x = y_i x z with y_i = -p_i: x = (y_y, -y_x) = (-p_y, p_x)
        xx[i] = -py[i]
        xy[i] = px[i]
    best = -1
    best_margin = -np.inf
    second_margin = -np.inf
    best_state = np.zeros(3)
    for j in range(4):
        # rolling at the three contacts k != j: v_B + w_x p_y - w_y p_x = target_k (R = 1)
        ks = [k for k in range(4) if k != j]
        k0, k1, k2 = ks[0], ks[1], ks[2]
        det = det3(1.0, py[k0], -px[k0], 1.0, py[k1], -px[k1], 1.0, py[k2], -px[k2])
        vb = det3(target[k0], py[k0], -px[k0], target[k1], py[k1], -px[k1],
                  target[k2], py[k2], -px[k2]) / det
        wx = det3(1.0, target[k0], -px[k0], 1.0, target[k1], -px[k1],
                  1.0, target[k2], -px[k2]) / det
        wy = det3(1.0, py[k0], target[k0], 1.0, py[k1], target[k1],
                  1.0, py[k2], target[k2]) / det
        slip = vb + wx * py[j] - wy * px[j] - target[j]
        fj = -force[j] * np.sign(slip)  # friction / mu on the ball, along z
        # equilibrium of the other three: sum f = 0, sum f x_i = 0 (x and y components)
        det_e = det3(1.0, 1.0, 1.0, xx[k0], xx[k1], xx[k2], xy[k0], xy[k1], xy[k2])
        r1, r2, r3 = -fj, -fj * xx[j], -fj * xy[j]
        fk0 = det3(r1, 1.0, 1.0, r2, xx[k1], xx[k2], r3, xy[k1], xy[k2]) / det_e
        fk1 = det3(1.0, r1, 1.0, xx[k0], r2, xx[k2], xy[k0], r3, xy[k2]) / det_e
        fk2 = det3(1.0, 1.0, r1, xx[k0], xx[k1], r2, xy[k0], xy[k1], r3) / det_e
        margin = min(
            (force[k0] - abs(fk0)) / force[k0],
            (force[k1] - abs(fk1)) / force[k1],
            (force[k2] - abs(fk2)) / force[k2],
        )
        if margin > best_margin + 1e-12:
            second_margin = best_margin
            best_margin = margin
            best = j
            best_state[0] = vb
            best_state[1] = wx
            best_state[2] = wy
        elif margin > second_margin:
            second_margin = margin
    vb, wx, wy = best_state[0], best_state[1], best_state[2]
    gamma = np.zeros(4)
    # zero-velocity point of the sliding contact: on the circle, where v_z = target
    j = best
    amp_c = wx * sy[j]  # coefficient of cos(b)
    amp_s = -wy * sx[j]  # coefficient of sin(b)
    rhs = target[j] - vb
    amp = np.hypot(amp_c, amp_s)
    phase = np.arctan2(amp_s, amp_c)
    ratio = min(1.0, max(-1.0, rhs / amp))
    cand1 = phase + np.arccos(ratio)
    cand2 = phase - np.arccos(ratio)
    d1 = (cand1 - beta[j] + np.pi) % (2 * np.pi) - np.pi
    d2 = (cand2 - beta[j] + np.pi) % (2 * np.pi) - np.pi
    gamma[j] = d1 if abs(d1) < abs(d2) else d2
    eps = 2.0 * vb - 1.0
    return eps, gamma, best, best_margin, second_margin


@pjit
def point_kernel(dbeta, force, nominal_angle, out_eps, out_eps22, out_gamma, out_slider,
                 out_valid):
    """Prior point-contact model: three contacts roll at their centres, one slides."""
    for n in prange(dbeta.shape[0]):
        beta = np.empty(4)
        for i in range(4):
            beta[i] = nominal_angle + dbeta[n, i]
        eps, gamma, slider, margin, runner_up = _point_one(beta, force[n])
        out_eps[n] = eps
        for i in range(4):
            out_gamma[n, i] = gamma[i]
        out_eps22[n] = eq22_velocity_deviation(beta[0] + gamma[0], beta[1] + gamma[1],
                                               beta[3] + gamma[3])
        out_slider[n] = slider
        # invalid when no candidate is admissible, a force is zero, or two candidates tie
        # (equal diagonal forces: which contact slides is undetermined, eps jumps there)
        tie = runner_up >= margin - 1e-9 and abs(eps) > 1e-12
        out_valid[n] = (margin >= -1e-9 and not tie
                        and min(min(force[n, 0], force[n, 1]), min(force[n, 2], force[n, 3])) > 0)


# --------------------------------------------------------------------------------------------
# Public, validated API
# --------------------------------------------------------------------------------------------
def _as_ball_arrays(contact_angle_deviation, normal_force):
    """Validate and broadcast inputs to C-contiguous float64 arrays of shape (n, 4)."""
    try:
        dbeta = np.asarray(contact_angle_deviation, dtype=np.float64)
        force = np.asarray(normal_force, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"inputs must be numeric arrays: {exc}") from None
    for name, arr in (("contact_angle_deviation", dbeta), ("normal_force", force)):
        if arr.ndim == 0 or arr.shape[-1] != 4:
            raise ValueError(f"{name} must have a last axis of length 4 (BL, BR, TR, TL), "
                             f"got shape {arr.shape}")
    if dbeta.shape != force.shape:
        try:
            dbeta, force = np.broadcast_arrays(dbeta, force)
        except ValueError:
            raise ValueError(f"contact_angle_deviation {dbeta.shape} and normal_force "
                             f"{force.shape} do not broadcast") from None
    shape = dbeta.shape[:-1]
    dbeta = np.ascontiguousarray(dbeta.reshape(-1, 4))
    force = np.ascontiguousarray(force.reshape(-1, 4))
    bad_angle, bad_force, negative = count_bad_inputs(dbeta, force)
    if bad_angle:
        raise ValueError(f"contact_angle_deviation must be finite ({bad_angle} values are not)")
    if bad_force:
        raise ValueError(f"normal_force must be finite ({bad_force} values are not)")
    if negative:
        raise ValueError(f"normal_force must be >= 0 ({negative} values are negative; a zero "
                         "force means loss of contact)")
    return dbeta, force, shape


def eq24(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1) -> VelocityResult:
    """Velocity deviation from Eq. (24) of [Lin2018] (paired diagonal forces).

    epsilon = tan(b0)/2 [(-db_BL + db_TR) F_1^(2/3) + (-db_BR + db_TL) F_2^(2/3)]
              / (F_1^(2/3) + F_2^(2/3)),
    with F_1 = (F_BL + F_TR)/2 and F_2 = (F_BR + F_TL)/2 (ERRATA 9 for the factor). With
    Table 2's loading this is Eq. (26) (ERRATA 2 for its exponent).

    Parameters
    ----------
    contact_angle_deviation : array_like, shape (..., 4)
        dbeta_i [rad], BL, BR, TR, TL.
    normal_force : array_like, shape (..., 4)
        F_i [N].
    bearing : Bearing
        Only ``nominal_contact_angle`` is used.

    Returns
    -------
    VelocityResult
        ``valid`` is False where a force is zero or the ball is outside the error-budget
        thresholds (module constants, "Validity"): the diagonal force ratio below
        ``MIN_DIAGONAL_FORCE_RATIO``, some |dbeta_i| above ``MAX_ANGLE_DEVIATION``, the pairing
        asymmetry above ``MAX_PAIRING_ASYMMETRY`` or |epsilon| above
        ``MAX_EQ24_VELOCITY_DEVIATION``. Inside them epsilon was measured within
        ``VALIDITY_ERROR_BUDGET`` of :func:`tolsim.physics.velocity.full.full`.
    """
    dbeta, force, shape = _as_ball_arrays(contact_angle_deviation, normal_force)
    eps = np.empty(len(dbeta))
    valid = np.empty(len(dbeta), dtype=np.bool_)
    eq24_kernel(dbeta, force, bearing.nominal_contact_angle, MIN_DIAGONAL_FORCE_RATIO,
                MAX_ANGLE_DEVIATION, MAX_PAIRING_ASYMMETRY, MAX_EQ24_VELOCITY_DEVIATION, eps,
                valid)
    return VelocityResult(eps.reshape(shape), valid.reshape(shape))


def analytic(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1,
             k_f: float = K_F_PAPER, *, push=None, neighbour_force=None,
             ball_friction=DEFAULT_BALL_FRICTION) -> VelocityResult:
    """The improved analytical model with four distinct forces ([Lin2018] Eqs. 17-23).

    Solves, per ball, the linear friction law (17), the three equilibrium rows of (18) with
    the spin moments at their pure-spin value (14) and the physical sign (ERRATA 8), and the
    linearised constraint (21) for dgamma_i. epsilon is Eq. (23) with tan(b0)/2 (ERRATA 9);
    the exact Eq. (22) with the same dgamma is returned as ``velocity_deviation_eq22``.
    a_i = a(F_i) from :mod:`tolsim.physics.hertz`. mu cancels (without external loads).

    External loads (:mod:`tolsim.physics.velocity.ball_loads`): a push P enters the z-force row of
    Eq.
    (18), the ball-ball braking moment -mu_bb (Q_back + Q_front) R_B e its moment rows (about
    the rolling axis e); see :func:`analytic_loaded_kernel`. Then mu matters
    (``bearing.friction_coefficient`` > 0), and the result also carries the carriage friction
    force, its free-rolling baseline, the creep stiffness K = dP/d(epsilon) (exact for the
    linear model), the traction capacity of the rigid ball with point contacts
    (:func:`~tolsim.physics.velocity.ball_loads.point_traction_capacity`, a lower bound of the full
    model's) and the ``sliding`` flag |P| >= capacity. With ``push=0`` (or zero neighbour
    forces) epsilon is bit for bit the unloaded one.

    Parameters
    ----------
    contact_angle_deviation : array_like, shape (..., 4)
        dbeta_i [rad].
    normal_force : array_like, shape (..., 4)
        F_i [N].
    bearing : Bearing
        Geometry and material (for a_i).
    k_f : float
        Linear friction slope [-]; the paper's -1.38 by default.
    push : None or array_like, broadcast to the balls
        P = Q_back - Q_front [N], the neighbours' net push along +z (the direction the top
        groove moves). None: no push.
    neighbour_force : None or array_like, shape (..., 2)
        (Q_back, Q_front) >= 0 [N], the normal forces of the neighbours behind and in front;
        sets P and the ball-ball braking. Not together with ``push``.
    ball_friction : float
        mu_bb [-], Coulomb coefficient of the ball-ball contacts (used with
        ``neighbour_force``).

    Returns
    -------
    VelocityResult or LoadedVelocityResult
        Without ``push`` and ``neighbour_force``: :class:`VelocityResult`, ``valid`` False
        where a force is zero or the ball is outside the error-budget thresholds (module
        constants, "Validity"): |c_i/a_i| > ``MAX_ZERO_VELOCITY_RATIO`` or |dbeta_i +
        dgamma_i| > ``MAX_ANGLE_SUM`` at any contact, or |epsilon| >
        ``MAX_VELOCITY_DEVIATION``. Inside them epsilon was measured within
        ``VALIDITY_ERROR_BUDGET`` of :func:`tolsim.physics.velocity.full.full` (derived for the
        default ``k_f``). With either: :class:`LoadedVelocityResult`, whose ``valid`` applies
        the same criteria to the loaded dgamma_i and the free epsilon, and is False when
        sliding.
    """
    if not (np.isfinite(k_f) and k_f < 0):
        raise ValueError(f"k_f = {k_f!r} must be negative")
    dbeta, force, shape = _as_ball_arrays(contact_angle_deviation, normal_force)
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    if push is not None or neighbour_force is not None:
        return _analytic_loaded(dbeta, force, shape, bearing, k_f, hc, push, neighbour_force,
                                ball_friction)
    n = len(dbeta)
    eps, eps22 = np.empty(n), np.empty(n)
    gamma = np.empty((n, 4))
    valid = np.empty(n, dtype=np.bool_)
    with np.errstate(divide="ignore", invalid="ignore"):
        analytic_kernel(dbeta, force, bearing.nominal_contact_angle, bearing.ball_radius,
                        hc.semi_major_coefficient, hc.elliptic_e, k_f,
                        MAX_ZERO_VELOCITY_RATIO, MAX_ANGLE_SUM, MAX_VELOCITY_DEVIATION, eps,
                        eps22, gamma, valid)
    return VelocityResult(eps.reshape(shape), valid.reshape(shape),
                          gamma.reshape(shape + (4,)), eps22.reshape(shape))


def _analytic_loaded(dbeta, force, shape, bearing, k_f, hc, push, neighbour_force,
                     ball_friction):
    """:func:`analytic` under external loads (validated inputs)."""
    load_p, load_q = as_ball_loads(push, neighbour_force, ball_friction, shape)
    mu = bearing.friction_coefficient
    if not mu > 0:
        raise ValueError(f"friction_coefficient = {mu!r}: a push needs raceway friction "
                         "(mu > 0) to be carried")
    n = len(dbeta)
    eps, eps22 = np.empty(n), np.empty(n)
    gamma = np.empty((n, 4))
    valid = np.empty(n, dtype=np.bool_)
    load = np.empty((n, len(LOAD_COLUMNS)))
    sliding = np.empty(n, dtype=np.bool_)
    with np.errstate(divide="ignore", invalid="ignore"):
        analytic_loaded_kernel(dbeta, force, load_p, load_q, bearing.nominal_contact_angle,
                               bearing.ball_radius, hc.semi_major_coefficient, hc.elliptic_e,
                               k_f, mu, float(ball_friction), MAX_ZERO_VELOCITY_RATIO,
                               MAX_ANGLE_SUM, MAX_VELOCITY_DEVIATION, eps, eps22, gamma, valid,
                               load, sliding)
    col = {name: load[:, k].reshape(shape) for k, name in enumerate(LOAD_COLUMNS)}
    return LoadedVelocityResult(
        velocity_deviation=eps.reshape(shape),
        valid=valid.reshape(shape),
        zero_velocity_offset=gamma.reshape(shape + (4,)),
        velocity_deviation_eq22=eps22.reshape(shape),
        push=load_p.reshape(shape),
        neighbour_force_sum=load_q.reshape(shape),
        sliding=sliding.reshape(shape),
        **col,
    )


def point(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1) -> VelocityResult:
    """The authors' prior point-contact model (ref. [11] of [Lin2018]; Fig. 7(b)).

    Three contacts roll at their centres (dgamma = 0); the fourth slides, with Coulomb
    friction mu F opposing its slip. The sliding contact is the one for which the three
    sticking friction forces that balance it (z force and the two moments, point contacts,
    no spin moment) stay inside their friction cones, |f_k| <= mu F_k; among several, the
    one with the largest margin; if none, the least violating, flagged invalid. epsilon
    follows from the rolling constraints (equivalent to Eq. (22) with three dgamma = 0).

    Returns
    -------
    VelocityResult
        ``extra["sliding_contact"]`` holds the index (0..3, BL, BR, TR, TL) of the sliding
        contact.
    """
    dbeta, force, shape = _as_ball_arrays(contact_angle_deviation, normal_force)
    n = len(dbeta)
    eps, eps22 = np.empty(n), np.empty(n)
    gamma = np.empty((n, 4))
    slider = np.empty(n, dtype=np.int64)
    valid = np.empty(n, dtype=np.bool_)
    with np.errstate(divide="ignore", invalid="ignore"):
        point_kernel(dbeta, force, bearing.nominal_contact_angle, eps, eps22, gamma, slider,
                     valid)
    return VelocityResult(eps.reshape(shape), valid.reshape(shape), gamma.reshape(shape + (4,)),
                          eps22.reshape(shape), {"sliding_contact": slider.reshape(shape)})
