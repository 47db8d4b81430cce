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

from tolsim._jit import kernel_array
from tolsim.physics.geometry import K_F_PAPER, TABLE1, Bearing, check_bearing
from tolsim.physics.hertz import bearing_constants
from tolsim.physics.velocity._analytic_kernels import (
    ANALYTIC_TILE,
    LOAD_COLUMNS,
    analytic_kernel,
    analytic_loaded_kernel,
    analytic_tile,
    count_bad_inputs,
    creep_coefficients_kernel,
    det3,
    eq22_velocity_deviation,
    eq24_kernel,
    point_kernel,
)
from tolsim.physics.velocity.ball_loads import DEFAULT_BALL_FRICTION, BallLoadFields, as_ball_loads

# --------------------------------------------------------------------------------------------
# Validity: thresholds derived from an error budget against the full model (flags, never
# errors)
# --------------------------------------------------------------------------------------------
# A ball is *valid* for a fast model when its epsilon is within VALIDITY_ERROR_BUDGET of the
# comprehensive model (tolsim.physics.velocity.full.full) fed the same dbeta_i and F_i. In a study
# an invalid ball is re-solved with ``full`` (tolsim.study.pipeline.evaluate), so the thresholds
# trade speed (the share of balls the fast model keeps; ``full`` is about a hundred times slower
# per ball than ``analytic``, the README's timing table) against accuracy (the error on the
# balls it keeps), not truth against bias.
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
# tests/physics/test_validity_budget.py checks the budget on fresh random balls of another seed.
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
# Public, validated API
# --------------------------------------------------------------------------------------------
def as_ball_arrays(contact_angle_deviation, normal_force):
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
    check_bearing(bearing)
    dbeta, force, shape = as_ball_arrays(contact_angle_deviation, normal_force)
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
    dbeta, force, shape = as_ball_arrays(contact_angle_deviation, normal_force)
    hc = bearing_constants(bearing)
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
    load_p, load_q = (kernel_array(a)
                      for a in as_ball_loads(push, neighbour_force, ball_friction, shape))
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
    check_bearing(bearing)
    dbeta, force, shape = as_ball_arrays(contact_angle_deviation, normal_force)
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


__all__ = [
    "ANALYTIC_TILE",
    "LOAD_COLUMNS",
    "MAX_ANGLE_DEVIATION",
    "MAX_ANGLE_SUM",
    "MAX_EQ24_VELOCITY_DEVIATION",
    "MAX_PAIRING_ASYMMETRY",
    "MAX_VELOCITY_DEVIATION",
    "MAX_ZERO_VELOCITY_RATIO",
    "MIN_DIAGONAL_FORCE_RATIO",
    "VALIDITY_ERROR_BUDGET",
    "LoadedVelocityResult",
    "VelocityResult",
    "analytic",
    "analytic_kernel",
    "analytic_loaded_kernel",
    "analytic_tile",
    "as_ball_arrays",
    "count_bad_inputs",
    "creep_coefficients_kernel",
    "det3",
    "eq22_velocity_deviation",
    "eq24",
    "eq24_kernel",
    "point",
    "point_kernel",
]
