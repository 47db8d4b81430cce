"""Evaluation of balls: error sources and loads -> static contact -> velocity deviation.

Two registries, picked by name from the config (no if/elif chains):

``STATIC_MODELS``
    name -> ``f(errors, side_load, normal_load, bearing) -> StaticResult`` with the loaded
    contact angle deviations dbeta_i and forces F_i per ball. ``paired`` runs in one compiled
    pass from the source values, with its loads along the carriage and the contact counts
    (``ONE_PASS_STATIC_MODELS``, :func:`paired_balls`: the same numbers, without the
    GrooveErrors fields).

    * ``paired``: the paper's paired forces (Sec. 3.1, :func:`paired_forces`) and the rigid
      mapping of the angular error sources (rotations, Sec. 3.1; tangential arc-centre
      offsets, dbeta_i = t_i / (R_G - R_B)). Normal arc offsets, groove offsets and ball
      oversize do not change the angles to first order in this model and are ignored.
    * ``rigid``, ``solved``: :func:`tolsim.physics.static.solve_static` (``rigid=True``: the
      geometric contact angles; else the elastic load-controlled solution).
    * ``linearised``: :func:`tolsim.physics.static.linearised_static` about the error-free
      state at each distinct ball load (:func:`linearised_static`).

``VELOCITY_KERNELS``
    name -> ``f(dbeta, force, bearing, out_eps, out_valid)`` calling the Numba kernels of
    :mod:`tolsim.physics.velocity.analytic` directly on preallocated arrays.

Every ball counts (issue 25). A ball whose static solution converged with all four forces > 0
but which lies outside the fast model's validity (the error-budget thresholds of
:mod:`tolsim.physics.velocity.analytic`), and every ball with two or three loaded contacts,
is solved with the full friction model (:func:`tolsim.physics.velocity.full.full`, batched
over the balls that need it; it handles regime B and three- and two-point balls), and its
epsilon enters the train like any other. Each ball's regime is recorded
(:data:`tolsim.physics.velocity.models.BALL_REGIMES`). A ball with no loaded contact is
*unloaded*: it has no epsilon of its own, is pushed along by its neighbours, and is counted as
such (:func:`tolsim.study.pipeline.propagation.pushed_velocity_deviation`). Only a ball that no
model can solve stays *unresolved* (epsilon NaN): its static solve did not converge, its static
model put a contact in tension or left it one loaded contact (loss of contact; a static model
other than ``solved`` hands such a ball to ``solved`` first, :data:`STATIC_FALLBACK`), or ``full``
could not certify it (or a contact angle or ellipse outside the model's range). The statistics
count unresolved balls by cause and bound the probabilities over their trains
(:mod:`tolsim.study.statistics.accumulator`); none is silently dropped. Since invalid balls are
re-solved, the fast model's thresholds trade speed against accuracy, not truth against bias.

``velocity_model = "full"`` evaluates every ball with the full model (slow; for checks).
"""

import importlib
import time
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache

import numba
import numpy as np

from tolsim._jit import compile_seconds, kernel_array
from tolsim.physics.geometry import K_F_PAPER, paired_forces, rigid_angle_deviations_kernel
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity.analytic import (
    MAX_ANGLE_DEVIATION,
    MAX_ANGLE_SUM,
    MAX_EQ24_VELOCITY_DEVIATION,
    MAX_PAIRING_ASYMMETRY,
    MAX_VELOCITY_DEVIATION,
    MAX_ZERO_VELOCITY_RATIO,
    MIN_DIAGONAL_FORCE_RATIO,
    analytic_kernel,
    eq24_kernel,
)
from tolsim.physics.velocity.models import (
    BALL_REGIME_A,
    BALL_TWO_POINT,
    BALL_UNLOADED,
    BALL_UNRESOLVED,
    MODEL_FAST,
    MODEL_FULL,
    MODEL_UNRESOLVED,
    ball_regime,
)
from tolsim.study.pipeline.ball_kernels import (
    ball_outcomes_kernel,
    contact_counts_kernel,
    gather_analytic_kernel,
    gather_loaded_kernel,
    loads_at_kernel,
    paired_analytic_kernel,
    paired_balls_kernel,
    unresolved_loads_kernel,
)

CONTACTS = ("BL", "BR", "TR", "TL")


def static_module():
    """:mod:`tolsim.physics.static` if it is installed, else None."""
    try:
        return importlib.import_module("tolsim.physics.static")
    except ImportError:
        return None


def friction_module():
    """:mod:`tolsim.physics.velocity.full` if it is installed, else None."""
    try:
        return importlib.import_module("tolsim.physics.velocity.full")
    except ImportError:
        return None


# --------------------------------------------------------------------------------------------
# Error sources -> GrooveErrors fields
# --------------------------------------------------------------------------------------------
#: The sources of each :class:`tolsim.physics.static.GrooveErrors` field, in its trailing
#: order (one source: a field of one value per ball, no trailing axis).
GROOVE_ERROR_SOURCES = {
    "arc_centre_offset_normal": tuple(f"arc_centre_offset_normal_{c}" for c in CONTACTS),
    "arc_centre_offset_tangential": tuple(f"arc_centre_offset_tangential_{c}"
                                          for c in CONTACTS),
    "bottom_rotation": ("bottom_rotation",),
    "top_rotation": ("top_rotation",),
    "bottom_offset": ("bottom_offset_x", "bottom_offset_y"),
    "top_offset": ("top_offset_x", "top_offset_y"),
    "ball_oversize": ("ball_oversize",),
}


def groove_error_fields(values: dict, shape, compact: bool = False) -> dict:
    """Assemble the :class:`tolsim.physics.static.GrooveErrors` fields from source values.

    Parameters
    ----------
    values : dict
        source name (:data:`tolsim.study.spec.SOURCES`) -> ndarray of ``shape`` [m or rad].
    shape : tuple
        Shape of one per-ball array, e.g. (assemblies, balls).
    compact : bool
        Leave out the fields none of whose sources is in ``values`` (zero everywhere: the
        default of :class:`tolsim.physics.static.GrooveErrors`) instead of filling them with
        zeros.

    Returns
    -------
    dict
        Flattened over balls (n = prod(shape)): ``arc_centre_offset_normal`` and
        ``arc_centre_offset_tangential`` (n, 4) [m], ``bottom_rotation``, ``top_rotation``
        (n,) [rad], ``bottom_offset``, ``top_offset`` (n, 2) [m], ``ball_oversize`` (n,) [m].
    """
    sources = [name for names in GROOVE_ERROR_SOURCES.values() for name in names
               if not compact or any(other in values for other in names)]
    fields, columns = groove_error_buffers(sources, shape)
    for name, column in columns.items():  # filled with broadcasting: no per-source copies
        column[...] = values.get(name, 0.0)
    return fields


def groove_error_buffers(sources, shape):
    """Empty :class:`tolsim.physics.static.GrooveErrors` fields of ``shape`` balls, to be
    filled source by source (:func:`groove_error_fields` with ``compact``; a caller that
    writes the values in place, :func:`tolsim.study.sampling.moving_ball_values`).

    Parameters
    ----------
    sources : collection of str
        The sources that have values (:data:`GROOVE_ERROR_SOURCES`).
    shape : tuple
        Shape of one per-ball array.

    Returns
    -------
    fields : dict
        The fields with one of the ``sources``, flattened over balls as those of
        :func:`groove_error_fields`; the columns of sources not in ``sources`` are 0.
    columns : dict
        source -> its column of its field, a view of ``shape``, not filled.
    """
    n = int(np.prod(shape))
    fields, columns = {}, {}
    for field, names in GROOVE_ERROR_SOURCES.items():
        if not any(name in sources for name in names):
            continue
        out = np.empty(tuple(shape) + (len(names),))
        for i, name in enumerate(names):
            if name in sources:
                columns[name] = out[..., i]
            else:
                out[..., i] = 0.0
        flat = out.reshape(n, len(names))
        fields[field] = flat if len(names) > 1 else flat[:, 0]  # (n,): per ball
    return fields, columns


# --------------------------------------------------------------------------------------------
# Static models
# --------------------------------------------------------------------------------------------
@dataclass
class StaticResult:
    """Loaded contact state of n balls: dbeta (n, 4) [rad], force (n, 4) [N], converged (n,),
    and four_point (n,): all four forces > 0 (computed from the forces if not given)."""

    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    converged: np.ndarray
    four_point: np.ndarray | None = None

    def __post_init__(self):
        if self.four_point is None:
            f = self.normal_force  # column by column: a reduction over axis 1 is slow
            self.four_point = (f[:, 0] > 0.0) & (f[:, 1] > 0.0) & (f[:, 2] > 0.0) & (
                f[:, 3] > 0.0)


def rigid_angle_deviation(errors: dict, bearing) -> np.ndarray:
    """Contact angle deviations of rigid grooves from rotations and tangential arc offsets
    (:func:`tolsim.physics.geometry.rigid_angle_deviations` per ball).

    Returns
    -------
    ndarray, shape (n, 4)
        dbeta_i [rad].
    """
    tangential = kernel_array(errors["arc_centre_offset_tangential"])
    dbeta = np.empty(tangential.shape)
    rigid_angle_deviations_kernel(tangential, kernel_array(errors["bottom_rotation"]),
                                  kernel_array(errors["top_rotation"]),
                                  bearing.groove_radius - bearing.ball_radius, dbeta)
    return dbeta


def paired_static(errors, side_load, normal_load, bearing) -> StaticResult:
    """``paired``: paired forces ([Lin2018] Sec. 3.1) and rigid angle deviations.

    :func:`evaluate_balls` takes the one-pass route of :func:`paired_balls` instead (the same
    numbers, without the GrooveErrors fields).
    """
    dbeta = rigid_angle_deviation(errors, bearing)
    force = np.ascontiguousarray(
        paired_forces(side_load, normal_load, bearing.nominal_contact_angle))
    return StaticResult(dbeta, force, np.ones(len(dbeta), dtype=bool))


#: The sources the ``paired`` model reads: tangential arc-centre offsets, groove rotations.
PAIRED_SOURCES = tuple(f"arc_centre_offset_tangential_{c}" for c in CONTACTS) + (
    "bottom_rotation", "top_rotation")


def paired_balls(config, values: dict, shape, side_load=None, normal_load=None,
                 carriage_position=None):
    """The ``paired`` model of balls and their contact counts in one compiled pass.

    The numbers of :func:`paired_static` on :func:`groove_error_fields` and of the contact
    counts of :func:`ball_velocities` (``paired_balls_kernel`` of
    :mod:`tolsim.study.pipeline.ball_kernels`), without the GrooveErrors fields. With
    ``velocity_model = "analytic"`` the same pass gives the balls' epsilon too
    (``paired_analytic_kernel``: the numbers of :func:`_analytic` on the clipped forces).

    Parameters
    ----------
    config : StudyConfig
    values : dict
        source -> ndarray broadcastable to ``shape`` [m or rad].
    shape : tuple
        The per-ball shape, n = prod(shape) balls.
    side_load, normal_load : ndarray, optional
        N_x, N_y per ball [N], broadcastable to ``shape``; or
    carriage_position : ndarray, optional
        Positions along the carriage [m] (``shape``): the loads there, as :func:`loads_at`.

    Returns
    -------
    static : StaticResult
        n balls, flattened.
    counts : tuple
        (count (n,) int8, clipped forces (n, 4), number of settled balls, fast), as
        ``ball_velocities`` takes them: ``fast`` is (epsilon, valid) (n,) of the analytic
        model (then the clipped forces are None), or None.
    """
    n = int(np.prod(shape))

    def per_ball(v):  # (n,), or (1,) for one value for all balls
        if v is None:
            return _ZERO
        if np.shape(v) != tuple(shape):
            v = np.array(np.broadcast_to(v, shape), dtype=np.float64, order="C")
        return kernel_array(v).reshape(n)

    bearing = config.bearing
    dbeta, force = np.empty((n, 4)), np.empty((n, 4))
    four_point = np.empty(n, dtype=np.bool_)
    count = np.empty(n, dtype=np.int8)
    if carriage_position is None:
        nx, ny, position = per_ball(side_load), per_ball(normal_load), _NONE
        slots = side_slots = normal_slots = _NONE
    else:
        nx = ny = _NONE
        position = per_ball(carriage_position)
        slots, side_slots, normal_slots = _slot_loads(config)
    angle = bearing.nominal_contact_angle
    paired = (*(per_ball(values.get(name)) for name in PAIRED_SOURCES),
              bearing.groove_radius - bearing.ball_radius, nx, ny, position, slots, side_slots,
              normal_slots, np.sin(angle), np.cos(angle), round_off_force(bearing))
    clipped, fast = None, None
    with serial_if_small(n):
        if config.study.velocity_model == "analytic":
            eps, valid = np.empty(n), np.empty(n, dtype=np.bool_)
            with np.errstate(divide="ignore", invalid="ignore"):
                settled = paired_analytic_kernel(*paired, *analytic_arguments(bearing), dbeta,
                                                 force, four_point, count, eps, valid)
            fast = (eps, valid)
        else:
            clipped = np.empty((n, 4))
            settled = paired_balls_kernel(*paired, dbeta, force, four_point, count, clipped)
    static = StaticResult(dbeta, force, np.ones(n, dtype=bool), four_point)
    return static, (count, clipped, settled, fast)


_ZERO = np.zeros(1)
_NONE = np.empty(0)


def _static_solver(function="solve_static", **options):
    def solve(errors, side_load, normal_load, bearing):
        module = static_module()
        if module is None or not hasattr(module, function):
            raise ValueError(f"this static model needs tolsim.physics.static.{function}, "
                             "which is not available; use static_model = 'paired' or 'solved'")
        sol = getattr(module, function)(side_load, normal_load,
                                        module.GrooveErrors(**errors), bearing, **options)
        return StaticResult(
            np.ascontiguousarray(sol.contact_angle_deviation, dtype=np.float64),
            np.ascontiguousarray(sol.normal_force, dtype=np.float64),
            np.asarray(sol.converged, dtype=bool),
            np.asarray(sol.four_point, dtype=bool),
        )

    return solve


#: Most distinct (N_x, N_y) pairs linearised separately; beyond it, one point at the mean load.
MAX_LINEARISATION_POINTS = 32


@lru_cache(maxsize=256)
def _static_sensitivity(side_load, normal_load, bearing):
    return static_module().static_sensitivity(side_load, normal_load, None, bearing)


def linearised_static(errors, side_load, normal_load, bearing) -> StaticResult:
    """``linearised``: first-order static solution about the error-free state.

    One sensitivity matrix (:func:`tolsim.physics.static.static_sensitivity`) per distinct
    per-ball load (N_x, N_y), computed once and cached; more than
    :data:`MAX_LINEARISATION_POINTS` distinct loads (along-track propagation) share one
    linearisation at the mean load, with the load deviations through its load columns. No
    convergence check: ``converged`` is True; a force <= 0 counts as loss of contact.
    """
    module = static_module()
    if module is None or not hasattr(module, "linearised_static"):
        raise ValueError("static_model = 'linearised' needs tolsim.physics.static."
                         "linearised_static, which is not available")
    loads = np.stack([side_load, normal_load], axis=1)
    points, inverse = np.unique(loads, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    if len(points) > MAX_LINEARISATION_POINTS:
        points, inverse = loads.mean(axis=0, keepdims=True), np.zeros(len(loads), np.int64)
    n = len(loads)
    dbeta, force = np.empty((n, 4)), np.empty((n, 4))
    for k, (nx, ny) in enumerate(points):
        sel = inverse == k
        sub = module.GrooveErrors(**{name: v[sel] for name, v in errors.items()})
        sens = _static_sensitivity(float(nx), float(ny), bearing)
        dbeta[sel], force[sel] = module.linearised_static(sens, side_load[sel],
                                                          normal_load[sel], sub)
    return StaticResult(dbeta, force, np.ones(n, dtype=bool))


STATIC_MODELS = {
    "paired": paired_static,
    "rigid": _static_solver(rigid=True),
    "solved": _static_solver(),
    "linearised": linearised_static,
}

#: The static model that answers a ball the study's static model leaves without balance: a
#: contact in tension or one loaded contact (``loss_of_contact``), or not converged. The
#: ``paired`` forces put a contact in tension where |N_x| >= N_y (|rho| >= 1): the ball then
#: runs on two or three contacts at shifted angles, which the elastic load-controlled solve
#: finds (:func:`with_static_fallback`). ``solved`` has no better model: its failures stay
#: unresolved and are counted.
STATIC_FALLBACK = {"paired": "solved", "rigid": "solved", "linearised": "solved"}

#: Static models that :func:`evaluate_balls` runs from the source values in one compiled pass
#: with the contact counts, name -> ``f(config, values, shape, side_load, normal_load,
#: carriage_position) -> (StaticResult, counts)`` (the same numbers as ``STATIC_MODELS``).
ONE_PASS_STATIC_MODELS = {"paired": paired_balls}


# --------------------------------------------------------------------------------------------
# Velocity kernels
# --------------------------------------------------------------------------------------------
def _eq24(dbeta, force, bearing, out_eps, out_valid):
    eq24_kernel(dbeta, force, bearing.nominal_contact_angle, MIN_DIAGONAL_FORCE_RATIO,
                MAX_ANGLE_DEVIATION, MAX_PAIRING_ASYMMETRY, MAX_EQ24_VELOCITY_DEVIATION,
                out_eps, out_valid)


def analytic_arguments(bearing):
    """The arguments of ``analytic_kernel`` from ``nominal_angle`` to ``max_eps``."""
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    return (bearing.nominal_contact_angle, bearing.ball_radius, hc.semi_major_coefficient,
            hc.elliptic_e, K_F_PAPER, MAX_ZERO_VELOCITY_RATIO, MAX_ANGLE_SUM,
            MAX_VELOCITY_DEVIATION)


def _analytic(dbeta, force, bearing, out_eps, out_valid):
    eps22, gamma = np.empty(0), np.empty((0, 4))  # not needed: skipped
    analytic_kernel(dbeta, force, *analytic_arguments(bearing), out_eps, eps22, gamma,
                    out_valid)


def _full(dbeta, force, bearing, out_eps, out_valid):
    """The full friction model on every ball it can take (see :func:`full_velocity`)."""
    out_eps[:], out_valid[:], _ = full_velocity(dbeta, force, bearing)


VELOCITY_KERNELS = {"eq24": _eq24, "analytic": _analytic, "full": _full}


#: Loaded contacts of a ball whose approaches are all below this [m] carry round-off, not
#: load: 1 pm, a millionth of the smallest tolerance of the packaged configs (0.1 um) and far
#: above the round-off of the carriage's positions (about 1e-18 m).
ROUND_OFF_APPROACH = 1e-12


def round_off_force(bearing):
    """K ROUND_OFF_APPROACH^1.5 [N]: a loaded ball whose contact forces are all at or below it
    carries round-off only (:func:`settle_round_off_contacts`)."""
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    return hc.load_deflection_constant * ROUND_OFF_APPROACH**1.5


def settle_round_off_contacts(force, count, bearing):
    """Forces and loaded-contact counts with the contacts of balls that carry only round-off
    opened.

    Parameters
    ----------
    force : ndarray (n, 4)
        Contact forces [N].
    count : ndarray of int8 (n,)
        :func:`loaded_contacts` of ``force``.
    bearing : Bearing

    Returns
    -------
    force, count
        The inputs themselves when no loaded ball has all its contact forces at or below
        K ROUND_OFF_APPROACH^1.5 (K the Hertz constant, 2.35e10 N/m^1.5 for the paper's balls:
        2.4e-8 N); else copies in which those balls are unloaded (F = 0, count 0).

    Notes
    -----
    A loose ball (clearance, or an end relief deeper than its approach) has its balance at
    delta = 0 of the flanks it touches, a root of order 1.5 of F = K delta^1.5, and the
    carriage solver leaves round-off there: one flank (measured 3e-21 to 6e-21 N) or the two
    carriage flanks (2e-14 N), forces no other contact balances, below the solver's ball
    tolerance of 1e-12 of the reference ball force (Notes of
    :func:`tolsim.physics.carriage.solve_carriage`, "Ball tolerance"). Such a ball is
    unloaded (issue 25), not a ball that lost contact or a two-point ball the full model
    cannot solve.
    """
    if not np.any(count > 0):
        return force, count
    limit = round_off_force(bearing)
    small = (count > 0) & (force[:, 0] <= limit) & (force[:, 1] <= limit) & (
        force[:, 2] <= limit) & (force[:, 3] <= limit)
    if not small.any():
        return force, count
    force = np.where(small[:, None], 0.0, force)
    return force, np.where(small, np.int8(0), count)


def settle_unresolved_loads(force, loaded, tolerance):
    """Carriage contact forces with the balls that carry less than the solve resolves unloaded.

    Parameters
    ----------
    force : ndarray (m, ..., 4)
        Contact forces of the balls of m carriage assemblies from one solve [N] (non-finite
        where the assembly was not solved).
    loaded : ndarray of bool (m, ...)
        The balls in the loaded zone.
    tolerance : float
        Relative tolerance of the solve's carriage and ball balances [-] (``tol`` and
        ``ball_tol`` of :func:`tolsim.physics.carriage.solve_carriage_batch`).

    Returns
    -------
    ndarray
        ``force`` itself when no loaded ball has all its forces at or below ``tolerance``
        times the largest contact force of its assembly; else a copy in which those balls'
        forces are 0 (unloaded, issue 25).

    Notes
    -----
    The carriage Newton stops when the carriage's scaled imbalance is within ``tolerance``
    of its force scale max(|Q|, F_max, floor), F_max the largest contact force of the
    assembly, and each ball's within ``tolerance`` of its reference ball force (Notes of
    :func:`tolsim.physics.carriage.solve_carriage`). A ball whose every contact force is at
    or below ``tolerance`` F_max changes no balance by more than the solve accepts: the solve
    cannot tell it from a ball without load, so its forces are the solve's error, not load.
    Left as they are they were read as a loaded ball with one to four contacts of 1e-19 to
    1e-4 N, and the full model gave it an epsilon of the solve's noise: -100.4 % (a ball
    rolling backwards) for the forces [3e-14, 1e-19, 0, 6.3e-5] N beside a largest force of
    0.73 N at the 1e-4 of :data:`tolsim.study.pipeline.carriage_track.TRACK_TOLERANCE`
    (``carriage_preload`` without preload or load, sample 41). The measured effect of the
    tolerance on the forces agrees: from 1e-8 to 1e-4 they moved by at most 1.5e-4 F_max
    (Notes of ``TRACK_TOLERANCE``). ``tolerance`` F_max is at most the solve's force scale, so
    the floor never opens a force the solve resolves. The fixed floor of
    :func:`settle_round_off_contacts` (2.4e-8 N) is the one that matters at the default
    tolerance of 1e-11 (a floor of 1e-11 F_max is below it up to F_max = 2 400 N).
    """
    return settle_and_find_light(force, loaded, tolerance)[0]


def settle_and_find_light(force, loaded, tolerance, light=0.0):
    """:func:`settle_unresolved_loads` (the forces, the same array when nothing settles), and
    (m,) the assemblies with a contact of a loaded ball that stays loaded and carries less
    than ``light`` x the assembly's largest contact force (0: none), in the same pass."""
    m = force.shape[0]
    small = np.empty(loaded.shape, dtype=bool)
    rows = np.empty(m, dtype=bool)
    if not unresolved_loads_kernel(kernel_array(force).reshape(m, -1, 4),
                                   kernel_array(loaded, bool).reshape(m, -1), float(tolerance),
                                   float(light), small.reshape(m, -1), rows):
        return force, rows
    return np.where(small[..., None], 0.0, force), rows


def loaded_contacts(force):
    """Loaded contacts (F > 0) per ball, (n,) int8, from (n, 4) forces [N]; a negative force
    (a contact in tension: the static model out of its range) counts as -1 for the ball."""
    f = force  # column by column: a reduction over axis 1 is slow
    count = ((f[:, 0] > 0.0).astype(np.int8) + (f[:, 1] > 0.0) + (f[:, 2] > 0.0)
             + (f[:, 3] > 0.0))
    tension = (f[:, 0] < 0.0) | (f[:, 1] < 0.0) | (f[:, 2] < 0.0) | (f[:, 3] < 0.0)
    return np.where(tension, np.int8(-1), count.astype(np.int8))


def full_velocity(dbeta, force, bearing, groove_velocity=0.01, ball_tolerance=None,
                  solutions=False):
    """epsilon and regime of balls from :func:`tolsim.physics.velocity.full.full`, never raising.

    ``full`` takes four-, three- and two-point balls (issue 25); the exactly two-point ones
    (:func:`tolsim.physics.velocity.full.exactly_two_point`, to the static solve's
    ``ball_tolerance`` when given) are answered here in its closed form (epsilon = 0,
    two-point), without the kernel. Balls that it cannot take
    (fewer than two loaded contacts, a contact in tension, a loaded contact angle outside
    (0, 90) deg, a contact ellipse wider than R_B / 2) and balls it does not certify come back
    with ``ok`` False and epsilon NaN. epsilon does not depend on ``groove_velocity``.

    Parameters
    ----------
    dbeta, force : ndarray, shape (n, 4)
        [rad], [N].
    bearing : Bearing

    Returns
    -------
    eps : ndarray (n,)
    ok : ndarray of bool (n,)
    regime : ndarray of int8 (n,)
        :data:`tolsim.physics.velocity.models.BALL_REGIMES` code (``BALL_UNRESOLVED`` where not
        ok; ``BALL_UNLOADED`` for a ball without a loaded contact).
    solved : (ndarray of int, FullResult) or None
        With ``solutions``: the balls that ``full`` solved (their indices) and its result,
        for the trains' coefficients of balls with an open or a stuck contact
        (``solved`` of :func:`tolsim.physics.trains.regimes.regime_creep_coefficients`,
        which takes them at ``groove_velocity`` 0.01 m/s); None where it solved none.
    """
    module = friction_module()
    n = len(dbeta)
    eps = np.full(n, np.nan)
    ok = np.zeros(n, dtype=bool)
    regime = np.full(n, BALL_UNRESOLVED, dtype=np.int8)

    def answer(solved=None):
        return (eps, ok, regime, solved) if solutions else (eps, ok, regime)

    if n == 0:
        return answer()
    with np.errstate(invalid="ignore"):
        count = loaded_contacts(np.where(np.isfinite(force), force, -1.0))
    regime[count == 0] = BALL_UNLOADED
    if module is None or not hasattr(module, "full"):
        return answer()
    angles, ellipses = module.within_model(dbeta, force, bearing)
    takes = (count >= 2) & np.all(np.isfinite(dbeta), axis=1) & angles & ellipses
    idx = np.flatnonzero(takes)
    if len(idx):  # exactly two-point balls in closed form (epsilon = 0), the rest by ``full``
        two = module.exactly_two_point(dbeta[idx], force[idx], bearing, ball_tolerance)
        eps[idx[two]] = 0.0
        ok[idx[two]] = True
        regime[idx[two]] = BALL_TWO_POINT
        idx = idx[~two]
    if not len(idx):
        return answer()
    res = module.full(dbeta[idx], force[idx], bearing, groove_velocity=groove_velocity)
    good = np.asarray(res.valid, dtype=bool) & np.isfinite(res.velocity_deviation)
    eps[idx[good]] = res.velocity_deviation[good]
    ok[idx[good]] = True
    regime[idx[good]] = ball_regime(force[idx[good]], res.regime[good])
    return answer((idx, res))


# --------------------------------------------------------------------------------------------
# Balls
# --------------------------------------------------------------------------------------------
#: Below this many balls the parallel kernels run on one thread: launching the thread pool
#: costs more than it saves (along-track steps evaluate a block of balls at a time).
SERIAL_BELOW = 4096


@contextmanager
def serial_if_small(n):
    """Run the parallel kernels inside on one thread when ``n`` balls are fewer than
    :data:`SERIAL_BELOW` (no effect on the results: every kernel is thread-count invariant)."""
    if n >= SERIAL_BELOW:
        yield
        return
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(threads)


@dataclass
class BallState:
    """Evaluated balls, each array of shape ``shape`` (+ (4,) for per-contact arrays).

    ``velocity_deviation`` is NaN where the ball is unresolved or unloaded (``valid`` False);
    ``model`` says which model gave it (:data:`MODEL_FAST`, :data:`MODEL_FULL` for a ball
    solved with the full model, :data:`MODEL_UNRESOLVED`); ``regime`` is its
    :data:`tolsim.physics.velocity.models.BALL_REGIMES` code (None: ``BALL_REGIME_A`` where
    valid, else ``BALL_UNRESOLVED``). ``loss_of_contact``: balls the static model left
    without balance (a contact in tension, or one loaded contact). ``resolve_seconds`` is the
    time spent in the full-model solves [s], compilation of the
    kernels (a cold cache) excluded. ``static_fallback``: balls answered by the static model of
    :data:`STATIC_FALLBACK` instead of the study's (:func:`with_static_fallback`; None: none).
    ``solved``: (rows, FullResult), the full model's solves of these balls, rows of shape
    ``shape`` (-1: not solved by it; :func:`full_velocity`), which the trains' coefficients
    take instead of solving the balls again (:meth:`solved_rows`); None where the state was
    assembled from others (the coefficients then solve their balls) and in a study without
    trains that take them (neither ``[contact]`` nor ``[carriage.circuit]``).
    """

    velocity_deviation: np.ndarray
    valid: np.ndarray
    converged: np.ndarray
    loss_of_contact: np.ndarray
    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    model: np.ndarray
    resolve_seconds: float = 0.0
    regime: np.ndarray | None = None
    static_fallback: np.ndarray | None = None
    solved: tuple | None = None

    def __post_init__(self):
        if self.regime is None:
            self.regime = np.where(self.valid, np.int8(BALL_REGIME_A),
                                   np.int8(BALL_UNRESOLVED))
        if self.static_fallback is None:
            self.static_fallback = np.zeros(np.shape(self.valid), dtype=np.bool_)

    @property
    def unloaded(self) -> np.ndarray:
        """Balls without a loaded contact: no epsilon of their own, pushed along."""
        return self.regime == BALL_UNLOADED

    @property
    def accounted(self) -> np.ndarray:
        """Balls with an answer: an epsilon (``valid``) or unloaded (pushed along)."""
        return self.valid | (self.regime == BALL_UNLOADED)

    def rows(self, sl):
        """The balls of the assemblies ``sl`` (a slice or an index array of the first axis)."""
        solved = None if self.solved is None else (self.solved[0][sl], self.solved[1])
        return BallState(self.velocity_deviation[sl], self.valid[sl], self.converged[sl],
                         self.loss_of_contact[sl], self.contact_angle_deviation[sl],
                         self.normal_force[sl], self.model[sl], 0.0, self.regime[sl],
                         self.static_fallback[sl], solved)

    def solved_rows(self, index=slice(None)):
        """``solved`` of :func:`tolsim.physics.trains.regimes.regime_creep_coefficients` for
        the balls ``index`` of the flattened balls (None without solves)."""
        if self.solved is None:
            return None
        return self.solved[1], np.asarray(self.solved[0]).reshape(-1)[index]


def concatenated_balls(first: BallState, second: BallState) -> BallState:
    """The balls of two BallStates one after the other along the first axis (its
    ``resolve_seconds``: 0)."""
    def both(name):
        return np.concatenate([getattr(first, name), getattr(second, name)])

    return BallState(both("velocity_deviation"), both("valid"), both("converged"),
                     both("loss_of_contact"), both("contact_angle_deviation"),
                     both("normal_force"), both("model"), 0.0, both("regime"),
                     both("static_fallback"))


def evaluate_balls(config, values: dict, side_load, normal_load) -> BallState:
    """Velocity deviation of balls from their error-source values and loads.

    The static model gives each ball's loaded contact state, the study's velocity model its
    epsilon; balls outside that model's validity are re-solved with the full model (see the
    module docstring). The ``paired`` model runs in one pass (:func:`paired_balls`).

    Parameters
    ----------
    config : StudyConfig
    values : dict
        source -> ndarray of the common per-ball shape [m or rad].
    side_load, normal_load : ndarray
        N_x and N_y per ball [N], same shape (or broadcastable).

    Returns
    -------
    BallState
    """
    shape = np.broadcast_shapes(np.shape(side_load), np.shape(normal_load),
                                *(np.shape(v) for v in values.values()))
    n = int(np.prod(shape))

    def loads(index=slice(None)):  # flattened (copies): only where a model needs them
        return tuple(np.broadcast_to(x, shape).reshape(n)[index]
                     for x in (side_load, normal_load))

    one_pass = ONE_PASS_STATIC_MODELS.get(config.study.static_model)
    if one_pass is not None:
        static, counts = one_pass(config, values, shape, side_load, normal_load)
        state = ball_velocities(config, static, shape, counts)
    else:
        errors = groove_error_fields(
            {k: np.broadcast_to(v, shape) for k, v in values.items()}, shape)
        with serial_if_small(n):
            static = STATIC_MODELS[config.study.static_model](errors, *loads(),
                                                              config.bearing)
        state = ball_velocities(config, static, shape)
    return with_static_fallback(config, state, values, loads)


def evaluate_balls_at(config, values: dict, carriage_position) -> BallState:
    """:func:`evaluate_balls` with the loads at positions along the carriage [m]
    (:func:`loads_at`; read in the same pass by the ``paired`` model, :func:`paired_balls`).

    ``values``: source -> ndarray broadcastable to the shape of ``carriage_position``.
    """
    one_pass = ONE_PASS_STATIC_MODELS.get(config.study.static_model)
    if one_pass is None:
        return evaluate_balls(config, values, *loads_at(config, carriage_position))
    shape = np.broadcast_shapes(np.shape(carriage_position),
                                *(np.shape(v) for v in values.values()))
    static, counts = one_pass(config, values, shape, carriage_position=carriage_position)
    state = ball_velocities(config, static, shape, counts)

    def loads(index):
        return loads_at(config, np.broadcast_to(carriage_position, shape).reshape(-1)[index])

    return with_static_fallback(config, state, values, loads)


def with_static_fallback(config, state: BallState, values: dict, loads) -> BallState:
    """``state`` with the balls its static model left without balance answered by the model of
    :data:`STATIC_FALLBACK` (the same ``state`` if there is none, or no such ball).

    A ball goes to the fallback when its static model left it with a contact in tension or one
    loaded contact (``loss_of_contact``) or did not converge; the ``solved`` model then finds
    its contact state from all its error sources and loads, and the study's velocity model (and
    the full model where that one does not hold) its epsilon, as for any other ball. Such balls
    are marked (``static_fallback``) and counted by the statistics. A ball the fallback cannot
    balance either stays unresolved, with its cause.

    Parameters
    ----------
    config : StudyConfig
    state : BallState
        The balls of the study's static model, of shape ``shape``.
    values : dict
        source -> ndarray broadcastable to ``shape`` [m or rad].
    loads : callable
        index (k,) into the flattened balls -> (N_x, N_y) (k,) [N] of those balls.
    """
    fallback = STATIC_FALLBACK.get(config.study.static_model)
    if fallback is None or (state.converged.all() and not state.loss_of_contact.any()):
        return state  # (two reductions of booleans: no cost along the track)
    shape = state.valid.shape
    redo = np.flatnonzero((state.loss_of_contact | ~state.converged).reshape(-1))
    n = int(np.prod(shape))
    errors = groove_error_fields(
        {k: np.broadcast_to(v, shape).reshape(n)[redo] for k, v in values.items()},
        (len(redo),))
    nx, ny = loads(redo)
    with serial_if_small(len(redo)):
        static = STATIC_MODELS[fallback](errors, np.ascontiguousarray(nx, dtype=np.float64),
                                         np.ascontiguousarray(ny, dtype=np.float64),
                                         config.bearing)
    again = ball_velocities(config, static, (len(redo),))

    def merged(name, tail=()):
        x = np.array(getattr(state, name)).reshape((n,) + tail)
        x[redo] = getattr(again, name)
        return x.reshape(shape + tail)

    marked = state.static_fallback.copy().reshape(n)
    marked[redo] = True
    return BallState(merged("velocity_deviation"), merged("valid"), merged("converged"),
                     merged("loss_of_contact"), merged("contact_angle_deviation", (4,)),
                     merged("normal_force", (4,)), merged("model"),
                     state.resolve_seconds + again.resolve_seconds, merged("regime"),
                     marked.reshape(shape))


def ball_velocities(config, static: StaticResult, shape, counts=None,
                    ball_tolerance=None) -> BallState:
    """The study's velocity model on balls in a known contact state, with the re-solves.

    Parameters
    ----------
    config : StudyConfig
    static : StaticResult
        n = prod(shape) balls, flattened.
    shape : tuple
        Shape of the returned per-ball arrays.
    counts : tuple, optional
        (count, clipped, settled, fast): ``contact_counts_kernel`` of
        :mod:`tolsim.study.pipeline.ball_kernels` on ``static.normal_force``, if the caller
        has them (:func:`paired_balls`), and the fast model's (epsilon, valid) if it has
        them too (else None); computed here if not.
    ball_tolerance : float, optional
        The relative ball balance of the static solve, when looser than round-off (for
        :func:`full_velocity`).

    Returns
    -------
    BallState
    """
    n = int(np.prod(shape))
    resolve_seconds = 0.0
    solved = None
    fast = config.study.velocity_model != "full"
    with serial_if_small(n):
        force = static.normal_force
        dbeta = static.contact_angle_deviation
        if counts is None:
            count = np.empty(n, dtype=np.int8)
            clipped = np.empty((n, 4))  # max(F, 0) of the settled forces, for the fast model
            settled = contact_counts_kernel(force, round_off_force(config.bearing), count,
                                            clipped)
            computed = None
        else:
            count, clipped, settled, computed = counts
        if settled:
            force = settle_round_off_contacts(force, loaded_contacts(force),
                                              config.bearing)[0]
        eps = np.empty(n)
        valid = np.zeros(n, dtype=np.bool_)
        if fast and computed is not None:
            eps, valid = computed
        elif fast:
            with np.errstate(divide="ignore", invalid="ignore"):
                VELOCITY_KERNELS[config.study.velocity_model](dbeta, clipped, config.bearing,
                                                              eps, valid)
        model = np.empty(n, dtype=np.int8)
        regime = np.empty(n, dtype=np.int8)
        lost = np.empty(n, dtype=np.bool_)
        redo = np.empty(n, dtype=np.int64)
        # valid: the fast model's, solvable and finite; the full model: four-point balls
        # outside the fast model's validity, and every ball with two or three loaded contacts
        redo = redo[:ball_outcomes_kernel(
            eps, valid, static.converged, static.four_point, count, fast, MODEL_FAST,
            MODEL_UNRESOLVED, BALL_REGIME_A, BALL_UNRESOLVED, BALL_UNLOADED, model, regime,
            lost, redo)]
        if len(redo):
            c0, t0 = compile_seconds(), time.perf_counter()
            with serial_if_small(len(redo)):  # (a few balls: no thread pool)
                # at full_velocity's v (epsilon does not depend on it), the trains' own, so
                # that their coefficients take its solves as they are; kept only for a study
                # with trains that take them (the memory of a result per re-solved ball)
                eps_full, ok, regime_full, solved = full_velocity(
                    dbeta[redo], force[redo], config.bearing, ball_tolerance=ball_tolerance,
                    solutions=True)
            if not (config.has_contact or config.circuit is not None):
                solved = None
            # model time only: a cold kernel cache compiles the full model here, once
            resolve_seconds = (time.perf_counter() - t0) - (compile_seconds() - c0)
            eps[redo] = eps_full  # NaN where not ok
            valid[redo] = ok
            model[redo[ok]] = MODEL_FULL
            regime[redo] = regime_full
            if solved is not None:
                rows = np.full(n, -1, dtype=np.int64)
                rows[redo[solved[0]]] = np.arange(len(solved[0]))
                solved = (rows.reshape(shape), solved[1])
    if not fast:
        resolve_seconds = 0.0  # the study's own model, not a re-solve
    return BallState(
        eps.reshape(shape), valid.reshape(shape), static.converged.reshape(shape),
        lost.reshape(shape), dbeta.reshape(shape + (4,)), force.reshape(shape + (4,)),
        model.reshape(shape), resolve_seconds, regime.reshape(shape), solved=solved,
    )


def loaded_ball_velocities(config, loaded, dbeta, force, ball_converged, solved,
                           ball_tolerance=None) -> BallState:
    """:func:`ball_velocities` of the loaded balls of slot arrays (a carriage solve to the
    relative ball balance ``ball_tolerance``; None: a tight one).

    Parameters
    ----------
    config : StudyConfig
    loaded : ndarray of bool (m, T, S)
    dbeta, force : ndarray (m, T, S, 4)
        The solve's contact angle deviations [rad] and forces [N] (a non-finite force: 0).
    ball_converged : ndarray of bool (m, T, S)
    solved : ndarray of bool (m,)
        The assembly's solve converged.

    Returns
    -------
    BallState
        The loaded balls, in C order (as ``x[loaded]``), flattened: their static state from
        :func:`tolsim.study.pipeline.ball_kernels.gather_loaded_kernel`, then
        :func:`ball_velocities`; with ``velocity_model = "analytic"`` the gather, the contact
        counts and the fast model in one pass
        (:func:`tolsim.study.pipeline.ball_kernels.gather_analytic_kernel`: the same numbers).
    """
    n = int(np.count_nonzero(loaded))
    static = StaticResult(np.empty((n, 4)), np.empty((n, 4)), np.empty(n, dtype=bool),
                          np.empty(n, dtype=bool))
    outputs = (static.contact_angle_deviation, static.normal_force, static.converged,
               static.four_point)
    if config.study.velocity_model != "analytic":
        gather_loaded_kernel(loaded, dbeta, force, ball_converged, solved, *outputs)
        return ball_velocities(config, static, (n,), ball_tolerance=ball_tolerance)
    count, eps, valid = np.empty(n, dtype=np.int8), np.empty(n), np.empty(n, dtype=np.bool_)
    with serial_if_small(n), np.errstate(divide="ignore", invalid="ignore"):
        settled = gather_analytic_kernel(loaded, dbeta, force, ball_converged, solved,
                                         round_off_force(config.bearing),
                                         *analytic_arguments(config.bearing), *outputs,
                                         count, eps, valid)
    return ball_velocities(config, static, (n,), (count, None, settled, (eps, valid)),
                           ball_tolerance)


def loads_per_ball(config, shape):
    """Per-ball (N_x, N_y) [N] of the config's train, broadcast to (assemblies, balls)."""
    return (np.broadcast_to(np.asarray(config.loads.side_load), shape),
            np.broadcast_to(np.asarray(config.loads.normal_load), shape))


def _slot_loads(config):
    """The nominal slot positions [m] and the per-ball (N_x, N_y) [N] there, as kernel
    arrays."""
    slots = config.train.slot_positions(2.0 * config.bearing.ball_radius)
    return (kernel_array(slots), kernel_array(np.asarray(config.loads.side_load)),
            kernel_array(np.asarray(config.loads.normal_load)))


def loads_at(config, carriage_position):
    """(N_x, N_y) [N] at positions along the carriage [m] (along-track propagation).

    The per-ball loads of the config are taken at the nominal slot positions and
    interpolated linearly between them (constant beyond the end slots; ``np.interp``, bit for
    bit, in ``loads_at_kernel`` of :mod:`tolsim.study.pipeline.ball_kernels`); with a single
    slot its loads everywhere.
    """
    position = np.asarray(carriage_position, dtype=np.float64)
    side, normal = np.empty(position.shape), np.empty(position.shape)
    loads_at_kernel(kernel_array(position).reshape(-1), *_slot_loads(config),
                    side.reshape(-1), normal.reshape(-1))
    return side, normal
