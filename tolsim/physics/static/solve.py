"""Static solutions of one ball: groove errors, validated inputs, load and displacement control."""

from dataclasses import dataclass, fields

import numpy as np

from tolsim._jit import kernel_array
from tolsim.physics.geometry import TABLE1, Bearing
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static._kernels import static_displacement_kernel, static_load_kernel

#: Default relative tolerance on the force imbalance (relative to the largest of |N|, F_i);
#: Newton converges quadratically, so this costs at most one step over 1e-10 and leaves the
#: imbalance at round-off level.
DEFAULT_TOLERANCE = 1e-12
#: Default cap on Newton steps per groove.
DEFAULT_MAX_ITER = 50


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GrooveErrors:
    r"""Manufacturing and assembly errors of the grooves and the ball (SI units, default 0).

    Every field broadcasts against the ball shape: per-flank fields to (..., 4) in the order
    BL, BR, TR, TL, per-groove vectors to (..., 2) as (x, y), the rest to (...). The
    geometric meaning and sign of each is drawn in the Notes.

    Attributes
    ----------
    arc_centre_offset_normal : array_like, (..., 4)
        e_n [m], arc-centre offset along the nominal contact line, positive moving the flank
        away from the ball (opens clearance: the approach falls by e_n).
    arc_centre_offset_tangential : array_like, (..., 4)
        e_t [m], arc-centre offset across the contact line, positive towards increasing
        beta_i (a rigid ball at the nominal centre sees dbeta_i = e_t / ((f - 1/2) 2 R_B)).
    bottom_rotation : array_like, (...)
        theta_b [rad], counter-clockwise rotation of the rail profile about the nominal ball
        centre (dbeta_BL = -theta_b, dbeta_BR = +theta_b when rigid; [Lin2018] Fig. 6).
    top_rotation : array_like, (...)
        theta_t [rad], the same for the carriage profile (dbeta_TR = -theta_t,
        dbeta_TL = +theta_t when rigid).
    bottom_offset : array_like, (..., 2)
        Lateral x and vertical y offset of the rail groove [m].
    top_offset : array_like, (..., 2)
        Lateral x and vertical y offset of the carriage groove [m].
    ball_oversize : array_like, (...)
        dD [m], ball *diameter* deviation (+ = oversize: preload when the top groove is held,
        - = undersize: clearance).

    Notes
    -----
    **Gothic-arch geometry**

    Each of the four flanks (BL, BR on the fixed bottom groove = rail; TR, TL on the top groove =
    carriage) is a circular arc of radius R_G = 2 f R_B. Its centre C_i sits at the distance
    d = R_G - R_B = (f - 1/2) 2 R_B from the ball centre O, on the far side of the contact::

                       top groove (carriage, translated by g)
              TL  \                         /  TR      n_i : unit vector, ball centre -> contact
                    \      C_BR   C_BL     /                BL (-sin b0, -cos b0)
                     |          O          |                BR (+sin b0, -cos b0)
                    /      C_TR   C_TL     \                TR (+sin b0, +cos b0)
              BL  /                         \  BR           TL (-sin b0, +cos b0)
                       bottom groove (rail, fixed)      t_i = dn_i/dbeta_i; C_i = -d n_i

    So C_BL lies up and to the right of O, C_TR down and to the left, and so on. The contact of
    flank i lies on the line from C_i through the ball centre P, beyond P::

          u_i = (P - C_i) / |P - C_i|     contact direction (ball centre -> contact)
          beta_i from u_i = (sx_i sin beta_i, sy_i cos beta_i), sx = (-,+,+,-), sy = (-,-,+,+)
          delta_i = |P - C_i| - d + dD/2  approach (negative: a gap)
          F_i = K max(delta_i, 0)^1.5     Hertz, K from :func:`tolsim.physics.hertz.hertz_constants`

    The flank pushes the ball with -F_i u_i; the ball pushes the flank with +F_i u_i. All forces
    pass through the ball centre, so the ball's moment balance in the cross-section holds
    identically; its force balance and that of the top groove are solved.

    Errors (:class:`GrooveErrors`), applied in this order to each flank's arc centre:

    1. *Arc-centre offset along the contact line*, e_n [m], positive moving the flank *surface*
       away from the ball (opens clearance, lowers the approach by e_n). The whole arc moves by
       e_n along n_i, so its centre, on the far side, moves towards O::

              C_i -> C_i + e_n n_i = -(d - e_n) n_i

              C_i o-->o . . . . . . O . . . . . . )-->)    flank at the contact
                    e_n                             e_n    (n_i points to the right here)

    2. *Arc-centre offset across the contact line*, e_t [m], positive in the sense that increases
       beta_i: the arc centre moves along -t_i, as it would if the flank were turned about the
       ball centre towards larger beta_i, so a rigid ball at O sees dbeta_i = atan(e_t/(d - e_n))
       ~ e_t / ((f - 1/2) 2 R_B) (0.143 deg per um for Table 1)::

              C_i -> C_i - e_t t_i

              C_i  o                              contact line through C'_i and O turns by
                   | e_t (along -t_i)             atan(e_t / d) towards larger beta_i
              C'_i o . . . . . . . . O . . . . ) n_i

    3. *Rotation of a whole groove profile* (both flanks) by theta about the nominal ball centre O,
       counter-clockwise positive (right-handed about +z, with x to the right and y up, z towards
       the viewer). With beta_BL measured from -y towards -x and beta_BR from -y towards +x, a
       counter-clockwise turn of the bottom profile moves the BL contact towards -y and the BR
       contact away from it: dbeta_BL = -theta, dbeta_BR = +theta, the paper's Fig. 6 and
       Table 2 convention. On the top groove the same counter-clockwise turn moves TR towards +y
       and TL away from it: dbeta_TR = -theta, dbeta_TL = +theta. Equal top and bottom rotations
       are therefore the paper's case (b) (parallel grooves turned together)::

                     top profile turned +theta (ccw)
                 TL  \           /  TR        TL: beta grows, TR: beta shrinks
                      .    O    .
                 BL  /           \  BR        BL: beta shrinks, BR: beta grows
                     bottom profile turned +theta (ccw)

    4. *Groove offsets* (lateral x, vertical y) [m]: translate all arc centres of the bottom or
       the top groove. In the load-controlled solution they only shift the ball and the top
       groove, without changing the angles or forces; they matter in the displacement-controlled
       solution.

    5. *Ball diameter deviation* dD [m], positive = oversize: the ball radius is R_B + dD/2, which
       adds dD/2 to every approach. With the top groove held in place this is preload; with the
       top groove free (load control) it raises the ball and the top groove and increases all
       geometric contact angles (0.072 deg per um for Table 1), but adds no preload force: the
       forces change only through those angles.
    """

    arc_centre_offset_normal: np.ndarray | float = 0.0
    arc_centre_offset_tangential: np.ndarray | float = 0.0
    bottom_rotation: np.ndarray | float = 0.0
    top_rotation: np.ndarray | float = 0.0
    bottom_offset: np.ndarray | float = 0.0
    top_offset: np.ndarray | float = 0.0
    ball_oversize: np.ndarray | float = 0.0

    #: trailing axis length of each field (0 = per ball scalar)
    TRAILING = {
        "arc_centre_offset_normal": 4,
        "arc_centre_offset_tangential": 4,
        "bottom_rotation": 0,
        "top_rotation": 0,
        "bottom_offset": 2,
        "top_offset": 2,
        "ball_oversize": 0,
    }


def turned_flank_offsets(contact_angle_deviation, bearing: Bearing = TABLE1):
    """Arc-centre offsets that turn each flank about the nominal ball centre by dbeta_i.

    Realises given contact-angle deviations as groove errors: a rigid ball at the nominal
    centre O then touches flank i at beta_0 + dbeta_i.

    Parameters
    ----------
    contact_angle_deviation : array_like
        dbeta_i [rad], per flank in the order BL, BR, TR, TL (trailing axis 4).
    bearing : Bearing
        Ball and groove (default [Lin2018] Table 1); d = R_G - R_B.

    Returns
    -------
    normal : ndarray
        ``arc_centre_offset_normal`` e_n = d (1 - cos dbeta_i) [m] of :class:`GrooveErrors`.
    tangential : ndarray
        ``arc_centre_offset_tangential`` e_t = d sin dbeta_i [m] of :class:`GrooveErrors`.

    Notes
    -----
    Turning the flank's arc centre C_i = -d n_i about O by dbeta_i keeps it at the distance d
    from O; in the flank's own frame the centre moves by e_n = d (1 - cos dbeta_i) along n_i
    and by e_t = d sin dbeta_i along -t_i, so the rigid ball sees atan(e_t / (d - e_n)) =
    dbeta_i exactly (errors 1 and 2 in the Notes of :class:`GrooveErrors`).
    """
    dbeta = np.asarray(contact_angle_deviation, dtype=float)
    dist = bearing.groove_radius - bearing.ball_radius
    return dist * (1.0 - np.cos(dbeta)), dist * np.sin(dbeta)


@dataclass(frozen=True)
class StaticSolution:
    """Static solution for an array of balls (ball shape ``s``; contacts BL, BR, TR, TL).

    Attributes
    ----------
    contact_angle : ndarray, s + (4,)
        Loaded contact angles beta_i [rad] (at a flank without force: the direction of its
        nearest point).
    contact_angle_deviation : ndarray, s + (4,)
        dbeta_i = beta_i - beta_0 [rad] ([Lin2018] Eq. 20).
    normal_force : ndarray, s + (4,)
        F_i [N].
    approach : ndarray, s + (4,)
        delta_i [m]; negative values are gaps (F_i = 0). Zero at loaded flanks when rigid.
    ball_displacement : ndarray, s + (2,)
        Ball-centre position (x, y) from the nominal centre [m].
    groove_displacement : ndarray, s + (2,)
        Top-groove translation (x, y) [m] on top of its ``top_offset`` error.
    converged : ndarray of bool, s
        Newton converged and a compressive equilibrium exists.
    iterations : ndarray of int, s
        Newton steps (max over the two grooves in load control; 0 when rigid).
    four_point : ndarray of bool, s
        All four flanks carry force.
    residual : ndarray, s
        Max force imbalance of the ball and the top groove, recomputed from the outputs [N].
    contact_count : ndarray of int, s
        Number of flanks that carry force (4, 3, 2, ...).
    groove_load : ndarray, s + (2,)
        (N_x, N_y) on the top groove [N]: the input in load control, the reaction holding the
        groove in displacement control.
    """

    contact_angle: np.ndarray
    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    approach: np.ndarray
    ball_displacement: np.ndarray
    groove_displacement: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    four_point: np.ndarray
    residual: np.ndarray
    contact_count: np.ndarray
    groove_load: np.ndarray


def as_float(name, value):
    """``value`` as a float64 array, checked finite; returns (array, max |value|)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {value!r}") from None
    if arr.size == 0:
        return arr, 0.0
    lo, hi = arr.min(), arr.max()  # two reductions, no temporaries; NaN propagates
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError(f"{name} must be finite")
    return arr, float(max(-lo, hi))


def prepare_inputs(items, bearing):
    """Validate inputs and bring each to a 2-D C array with first axis 1 or n.

    ``items`` is a list of (name, value, trailing) with trailing 0 (per ball), 2 or 4, or of
    (name, value, trailing, True) for a value already checked by :func:`as_float` (the items
    of :func:`error_items`: not read again). Returns (arrays, ball_shape).
    """
    arrays = []
    shapes = []
    for name, value, trailing, *checked in items:
        arr = value if checked and checked[0] else as_float(name, value)[0]
        if trailing:
            if arr.ndim == 0:
                arr = np.broadcast_to(arr, (trailing,))
            if arr.shape[-1] != trailing:
                raise ValueError(f"{name} must have a last axis of length {trailing}, got "
                                 f"shape {arr.shape}")
            shapes.append(arr.shape[:-1])
        else:
            shapes.append(arr.shape)
        arrays.append(arr)
    try:
        ball_shape = np.broadcast_shapes(*shapes)
    except ValueError:
        desc = ", ".join(f"{it[0]} {s}" for it, s in zip(items, shapes, strict=True))
        raise ValueError(f"ball shapes do not broadcast: {desc}") from None
    size = int(np.prod(ball_shape))
    out = []
    for (_name, _value, trailing, *_), arr, shape in zip(items, arrays, shapes, strict=True):
        width = max(trailing, 1)
        if int(np.prod(shape)) == 1:
            flat = arr.reshape(1, width)
        elif shape == ball_shape:
            flat = arr.reshape(size, width)
        else:
            target = ball_shape + ((trailing,) if trailing else ())
            flat = np.broadcast_to(arr, target).reshape(size, width)
        out.append(np.ascontiguousarray(flat, dtype=np.float64))
    return out, ball_shape


def error_items(errors, bearing):
    """``prepare_inputs`` items of a GrooveErrors, each field checked finite and in range
    (float64 arrays, marked checked).

    Rotations must stay within +/-pi/8 rad and lengths within +/-(R_G - R_B)/4.
    """
    errors = GrooveErrors() if errors is None else errors
    if not isinstance(errors, GrooveErrors):
        raise ValueError(f"errors must be a GrooveErrors, got {type(errors).__name__}")
    dist = bearing.groove_radius - bearing.ball_radius
    items = []
    for f in fields(GrooveErrors):
        name = f"errors.{f.name}"
        arr, largest = as_float(name, getattr(errors, f.name))
        if f.name.endswith("rotation"):
            limit, unit = np.pi / 8, "rad"
        else:
            limit, unit = 0.25 * dist, "m"
        if largest > limit:
            raise ValueError(f"{name} must stay within +/-{limit:.3g} {unit} "
                             f"(|value| up to {largest:.3g} {unit})")
        items.append((name, arr, GrooveErrors.TRAILING[f.name], True))
    return items


def _kernel_outputs(n):
    """Output arrays of the static kernels for n balls: dbeta, F, delta (n, 4); ball and
    groove displacement or load (n, 2); converged, iterations, contact count, residual."""
    return (np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 2)),
            np.empty((n, 2)), np.empty(n, dtype=np.bool_), np.empty(n, dtype=np.int64),
            np.empty(n, dtype=np.int64), np.empty(n))


def check_solver_options(tol, max_iter):
    """Raise ValueError unless 0 < tol < 1 and max_iter is a positive integer."""
    if not (np.isfinite(tol) and 0 < tol < 1):
        raise ValueError(f"tol = {tol!r} must be in (0, 1)")
    if int(max_iter) != max_iter or max_iter < 1:
        raise ValueError(f"max_iter = {max_iter!r} must be a positive integer")


def hertz_k(bearing):
    """Hertz load-deflection constant K [N/m^1.5] of the ball in a flank (F = K delta^1.5)."""
    return hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                           bearing.poisson_ratio).load_deflection_constant


def solve_static(side_load, normal_load, errors: GrooveErrors | None = None,
                 bearing: Bearing = TABLE1, *, rigid: bool = False,
                 tol: float = DEFAULT_TOLERANCE, max_iter: int = DEFAULT_MAX_ITER,
                 vectorised: bool = True) -> StaticSolution:
    """Loaded contact angles and forces of balls under a given top-groove load.

    Solves the ball-centre position and the top-groove translation in the cross-section so
    that the ball and the top groove are in equilibrium (Notes), with exact Hertz
    contact F = K delta^1.5 at each flank.

    Parameters
    ----------
    side_load : array_like, (...)
        N_x, lateral load on the top groove per ball [N], positive towards +x (BR/TR side).
    normal_load : array_like, (...)
        N_y, load pressing the top groove down per ball [N] ([Lin2018] Fig. 6).
    errors : GrooveErrors, optional
        Groove and ball errors (None: a perfect bearing).
    bearing : Bearing
        Geometry and material (Table 1 by default).
    rigid : bool
        True: the K -> infinity limit, i.e. the geometric contact angles at zero approach and
        the forces from statics (see the Notes).
    tol : float
        Relative tolerance on the force imbalance [-] (relative to max(|N|, F_i)).
    max_iter : int
        Newton steps allowed per groove.
    vectorised : bool
        Solve balls in four-point contact with the branch-free Newton iteration that runs
        several balls per instruction (``_lane_*`` kernels), verified ball by ball, and only
        the rest with the scalar solver (default). False solves every ball with the scalar
        solver; the results agree to round-off (about 1e-15), 5-10x slower.

    Returns
    -------
    StaticSolution
        Arrays over the broadcast ball shape of the loads and the errors.

    Notes
    -----
    **Static solutions**

    *Load controlled* (:func:`solve_static`): the external load (N_x, -N_y) acts on the top groove
    (N_x towards +x, N_y pressing down, [Lin2018] Fig. 6). Unknowns: the ball centre P and the top
    groove translation g. Equilibrium of the ball, -sum_i F_i u_i = 0, and of the top groove,
    F_TR u_TR + F_TL u_TL + (N_x, -N_y) = 0, are equivalent to two independent 2x2 problems::

          bottom:  F_BL u_BL + F_BR u_BR = (N_x, -N_y)      u_BL, u_BR depend on P only
          top:     F_TR u_TR + F_TL u_TL = -(N_x, -N_y)     u_TR, u_TL depend on q = P - g only

    Each is the gradient of the convex potential sum_i (2/5) K max(delta_i, 0)^2.5 - T . P
    (delta_i is convex in P, s^2.5 is convex and increasing), so it is solved by Newton's method
    with the analytic Hessian as Jacobian and a backtracking line search. The start is the
    rigid-groove solution (below) moved by the Hertz approaches of its forces; Newton then needs
    3 steps to reach a round-off force imbalance (measured over 1e6 tolerance-sized cases).
    Balls in four-point contact take those 3 steps without line search or branches, several balls
    per instruction (the vectorised path: comment block above ``_LANE_STEPS`` in ``_kernels``),
    each result verified and, if the check fails, solved again by the scalar Newton.

    *Rigid* (``rigid=True``): the limit K -> infinity at the given load, i.e. the geometric
    (infinitesimal-approach) contact angles. In each groove the ball sits where both flanks touch
    (delta = 0: the intersection of the two circles of radius d - dD/2 about the arc centres) and
    the two forces follow from statics. If statics gives one flank a negative force, the ball
    rolls onto the other flank alone, to where that flank's contact direction is parallel to the
    load (two- or three-point contact). At zero load the geometric two-flank position is used.
    This is the sense of the paper's "dbeta_BL = -theta, dbeta_BR = theta" for a rotated groove.

    *Displacement controlled* (:func:`solve_static_displacement`): the top groove is held at a
    given translation g (for instance g = 0 with an oversize ball: preload) and only the ball
    centre is solved, from the same potential with all four flanks; the load the top groove must
    carry is an output.

    *Sensitivities* (:func:`static_sensitivity`): the matrix d(dbeta_i, F_i)/d(errors, loads) at
    one nominal state by central differences (all perturbed states in one vectorised call), with
    labelled rows and columns; :func:`linearised_static` is the first-order model built on it.

    Loss of contact is never an error: a flank whose approach is not positive carries no force,
    ``four_point`` is False and ``contact_count`` says how many flanks carry force.
    ``converged`` is False only if Newton fails or no compressive equilibrium exists (a load
    pulling the grooves apart).
    """
    check_solver_options(tol, max_iter)
    items = [("side_load", side_load, 0), ("normal_load", normal_load, 0)]
    items += error_items(errors, bearing)
    arrays, shape = prepare_inputs(items, bearing)
    nx, ny, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize = arrays
    nx, ny, rot_b, rot_t, oversize = (kernel_array(a[:, 0])
                                      for a in (nx, ny, rot_b, rot_t, oversize))
    n = int(np.prod(shape))
    dbeta, force, approach, ball, groove, conv, iters, count, resid = _kernel_outputs(n)
    dist = bearing.groove_radius - bearing.ball_radius
    static_load_kernel(nx, ny, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize,
                       bearing.nominal_contact_angle, dist, hertz_k(bearing), bool(rigid),
                       float(tol), int(max_iter), bool(vectorised), dbeta, force, approach,
                       ball, groove, conv, iters, count, resid)
    load = np.empty((n, 2))
    load[:, 0] = np.broadcast_to(nx, (n,))
    load[:, 1] = np.broadcast_to(ny, (n,))
    return _solution(shape, bearing, dbeta, force, approach, ball, groove, conv, iters, count,
                     resid, load)


def solve_static_displacement(groove_displacement, errors: GrooveErrors | None = None,
                              bearing: Bearing = TABLE1, *, tol: float = DEFAULT_TOLERANCE,
                              max_iter: int = DEFAULT_MAX_ITER) -> StaticSolution:
    """Static solution with the top groove held at a given translation (preload).

    Only the ball centre is solved (force balance of the ball against all four flanks); the
    load that holds the top groove is returned as ``groove_load``. With
    ``groove_displacement = 0`` and an oversize ball dD > 0 on a perfect bearing every flank
    carries F = K (dD/2)^1.5 at beta_0.

    Parameters
    ----------
    groove_displacement : array_like, (..., 2)
        Top-groove translation (x, y) [m] on top of its ``top_offset`` error.
    errors : GrooveErrors, optional
        As in :func:`solve_static`.
    bearing : Bearing
        Geometry and material.
    tol, max_iter
        As in :func:`solve_static` (the tolerance is relative to max(|N|, F_i)).

    Returns
    -------
    StaticSolution
        ``groove_displacement`` echoes the input; ``groove_load`` holds (N_x, N_y).
    """
    check_solver_options(tol, max_iter)
    items = [("groove_displacement", groove_displacement, 2)] + error_items(errors, bearing)
    arrays, shape = prepare_inputs(items, bearing)
    disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize = arrays
    dist = bearing.groove_radius - bearing.ball_radius
    if np.any(np.abs(disp) > 0.25 * dist):
        raise ValueError(f"groove_displacement must stay within +/-{0.25 * dist:.3g} m")
    rot_b, rot_t, oversize = (kernel_array(a[:, 0]) for a in (rot_b, rot_t, oversize))
    n = int(np.prod(shape))
    dbeta, force, approach, ball, load, conv, iters, count, resid = _kernel_outputs(n)
    static_displacement_kernel(disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize,
                               bearing.nominal_contact_angle, dist, hertz_k(bearing),
                               float(tol), int(max_iter), dbeta, force, approach, ball, load,
                               conv, iters, count, resid)
    groove = np.ascontiguousarray(np.broadcast_to(disp, (n, 2)))
    return _solution(shape, bearing, dbeta, force, approach, ball, groove, conv, iters, count,
                     resid, load)


def _solution(shape, bearing, dbeta, force, approach, ball, groove, conv, iters, count,
              resid, load):
    s4, s2 = shape + (4,), shape + (2,)
    return StaticSolution(
        contact_angle=(bearing.nominal_contact_angle + dbeta).reshape(s4),
        contact_angle_deviation=dbeta.reshape(s4),
        normal_force=force.reshape(s4),
        approach=approach.reshape(s4),
        ball_displacement=ball.reshape(s2),
        groove_displacement=groove.reshape(s2),
        converged=conv.reshape(shape),
        iterations=iters.reshape(shape),
        four_point=(count == 4).reshape(shape),
        residual=resid.reshape(shape),
        contact_count=count.reshape(shape),
        groove_load=load.reshape(s2),
    )
