"""Carriage equilibrium: the validated solves of one assembly and of many at once."""

import numpy as np

from tolsim._jit import kernel_array
from tolsim.physics.carriage._batch_kernels import carriage_batch_kernel
from tolsim.physics.carriage._kernels import (
    LIFT_OFF,
    STATUS_CONVERGED,
    STEP_CAP,
    carriage_balls_kernel,
    receding,
)
from tolsim.physics.carriage.layout import (
    DOFS,
    CarriageBatch,
    CarriageError,
    CarriageLayout,
    CarriageLoad,
    CarriageSolution,
    CarriageStatus,
    locked_dofs,
)
from tolsim.physics.geometry import TABLE1, Bearing
from tolsim.physics.static import (
    DEFAULT_MAX_ITER,
    DEFAULT_TOLERANCE,
    FLOOR_LENGTH,
    GrooveErrors,
    check_solver_options,
    error_items,
    hertz_k,
    prepare_inputs,
)

#: Default relative tolerance of the carriage force and moment balance.
CARRIAGE_TOLERANCE = 1e-11
#: Default cap on carriage Newton steps.
CARRIAGE_MAX_ITER = 60


def uncarried_motions(layout, load) -> tuple:
    """The DOFs the layout cannot resist (:func:`locked_dofs`) when ``load`` has a component
    along them (beyond 1e-9 of its largest, in scaled coordinates: moments / L); () when the
    layout carries the load."""
    locked, null = locked_dofs(layout)
    length = layout.length_scale()
    q_s_ext = load.generalised() * np.array([1.0, 1.0, 1.0 / length, 1.0 / length,
                                              1.0 / length])
    load_norm = np.abs(q_s_ext).max()
    if null.shape[1] and load_norm > 0:
        if np.abs(null.T @ q_s_ext).max() > 1e-9 * load_norm:
            return locked
    return ()


def _carried(layout, load):
    """Locked DOFs and the free mask; ValueError for a load along a locked mechanism."""
    locked, _ = locked_dofs(layout)
    free = np.array([name not in locked for name in DOFS])
    if uncarried_motions(layout, load):
        raise ValueError(f"the track layout cannot carry the load ({load.describe()}): "
                         f"it has no stiffness against a motion of {', '.join(locked)}")
    return locked, free


def _ball_positions(layout, ball_z, loaded):
    """``ball_z`` [m] and ``loaded`` of :func:`solve_carriage_batch`, validated and
    broadcast to a common (m, n_tracks, n)."""
    t, n = layout.n_tracks, layout.balls_per_track
    z = layout.ball_z if ball_z is None else np.asarray(ball_z, dtype=float)
    mask = True if loaded is None else np.asarray(loaded)
    if mask is not True and mask.dtype != np.bool_:
        raise ValueError(f"loaded must be an array of bool, got dtype {mask.dtype}")
    if not np.all(np.isfinite(z)):
        raise ValueError("ball_z must be finite")
    try:
        shape = np.broadcast_shapes(np.shape(z), np.shape(mask), (t, n))
    except ValueError:
        shape = ()
    if not 2 <= len(shape) <= 3 or shape[-2:] != (t, n):
        raise ValueError(f"ball_z {np.shape(z)} and loaded {np.shape(mask)} must broadcast to "
                         f"(assemblies, n_tracks, balls_per_track) = (m, {t}, {n})")
    shape = (1,) * (3 - len(shape)) + shape
    return (np.ascontiguousarray(np.broadcast_to(z, shape)),
            np.ascontiguousarray(np.broadcast_to(mask, shape)))


def _ball_inputs(layout, oversize, groove_errors, bearing):
    t, n = layout.n_tracks, layout.balls_per_track
    errors = GrooveErrors() if groove_errors is None else groove_errors
    items = [("groove_displacement", np.zeros((t, n, 2)), 2)]
    items += error_items(errors, bearing)
    items.append(("oversize", 0.0 if oversize is None else oversize, 0))
    arrays, shape = prepare_inputs(items, bearing)
    if shape != (t, n):
        raise ValueError(f"oversize and groove errors must broadcast to the balls (n_tracks, "
                         f"balls_per_track) = {(t, n)}, got {shape}")
    _, e_n, e_t, rot_b, rot_t, off_b, off_t, dd, extra = arrays
    total = np.ascontiguousarray(np.broadcast_to(dd[:, 0] + extra[:, 0], (t * n,)))
    return e_n, e_t, rot_b[:, 0].copy(), rot_t[:, 0].copy(), off_b, off_t, total


def _batch_inputs(layout, oversize, groove_errors, bearing):
    """Ball inputs of m assemblies for :func:`carriage_batch_kernel`, and m.

    Each input's first axis is m n_balls (assembly a, ball b = t n + j at row a n_balls + b)
    or 1 (the same for every ball of every assembly).
    """
    t, n = layout.n_tracks, layout.balls_per_track
    errors = GrooveErrors() if groove_errors is None else groove_errors
    items = error_items(errors, bearing)
    items.append(("oversize", 0.0 if oversize is None else oversize, 0))
    arrays, shape = prepare_inputs(items, bearing)
    try:
        full = np.broadcast_shapes(shape, (t, n))
    except ValueError:
        full = ()
    if not 2 <= len(full) <= 3:
        raise ValueError(f"oversize and groove errors must broadcast to (assemblies, n_tracks, "
                         f"balls_per_track) = (m, {t}, {n}), got ball shape {shape}")
    full = (1,) * (3 - len(full)) + full
    rows = int(np.prod(full))
    flat = []
    for arr in arrays:
        if arr.shape[0] not in (1, rows):  # broadcast over the missing axes of ``shape``
            width = arr.shape[1]
            arr = np.ascontiguousarray(np.broadcast_to(
                arr.reshape(shape + (width,)), full + (width,)).reshape(rows, width))
        flat.append(arr)
    e_n, e_t, rot_b, rot_t, off_b, off_t, dd, extra = flat
    # (columns of (rows, 1) arrays are contiguous views; the kernel adds the two oversizes)
    return (e_n, e_t, rot_b[:, 0], rot_t[:, 0], off_b, off_t, dd[:, 0], extra[:, 0]), full[0]


def _track_rows(layout):
    """(n_tracks, 6) c, s, -s, -c, s x - c y, c x + s y of each track (c, s: cos and sin of
    its orientation) for ``assembly_groove_rows``, as :meth:`CarriageLayout.groove_map_at`
    forms them."""
    c, s = np.cos(layout.track_orientation), np.sin(layout.track_orientation)
    x, y = layout.track_x, layout.track_y
    return np.ascontiguousarray(np.stack([c, s, -s, -c, s * x - c * y, c * x + s * y],
                                         axis=1))


class _Balls:
    """Evaluates all balls of one assembly at a carriage displacement."""

    def __init__(self, inputs, bearing, nball, tol, max_iter, floor):
        self.inputs = tuple(kernel_array(a, a.dtype) for a in inputs)
        self.beta0 = bearing.nominal_contact_angle
        self.dist = bearing.groove_radius - bearing.ball_radius
        self.k = hertz_k(bearing)
        self.tol, self.max_iter, self.nball, self.floor = tol, max_iter, nball, floor

    def __call__(self, groove):
        n = self.nball
        out = dict(dbeta=np.empty((n, 4)), force=np.empty((n, 4)), approach=np.empty((n, 4)),
                   ball=np.empty((n, 2)), load=np.empty((n, 2)),
                   converged=np.empty(n, dtype=np.bool_), iterations=np.empty(n, np.int64),
                   count=np.empty(n, np.int64), residual=np.empty(n),
                   stiffness=np.empty((n, 2, 2)), energy=np.empty(n))
        carriage_balls_kernel(np.ascontiguousarray(groove), *self.inputs, self.beta0, self.dist,
                              self.k, self.tol, self.max_iter, self.floor, *out.values())
        # force of the ball on its carriage groove, module frame: (-N_x, N_y)
        out["groove_force"] = np.stack([-out["load"][:, 0], out["load"][:, 1]], axis=-1)
        return out


def _settle(evaluate, a_s, q_s, step, out, limit, beta0):
    """Carry a carriage that touches nothing along ``step`` until its contacts close.

    ``out`` is the evaluation at ``q_s`` (no carriage flank loaded), ``step`` a descent
    direction of the potential Pi (scaled q). Pi(q_s + s step) is convex in s, with the
    constant slope -R . step < 0 while nothing touches: the distance s is doubled until the
    slope turns >= 0 (a contact closed and carries the load along ``step``), then the root of
    the slope is found by regula falsi (Illinois) to 1 % of the initial slope (Notes of
    :func:`solve_carriage`, "Settling"). Lift-off: the grooves reach ``limit`` with nothing
    loaded and every carriage flank receding (``_kernels.receding``); failure: with contacts
    loaded or approaching. Returns (status, q_s, out); compiled twin: ``_kernels.settle``.
    """
    move = float(np.abs(np.einsum("bik,k->bi", a_s, step)).max())
    room = limit - float(np.abs(np.einsum("bik,k->bi", a_s, q_s)).max())
    s_max = (1.0 - 1e-9) * room / move  # |A (q_s + s step)| <= limit for s <= s_max
    slope0 = -float(out["residual_q"] @ step)
    s_lo, d_lo = 0.0, slope0
    s = 1.0
    while True:  # bracket the minimum along the ray
        s = min(s, s_max)
        cand = evaluate(q_s + s * step)
        if cand is None or not cand["converged"].all():
            return CarriageStatus.FAILED, q_s, out
        slope = -float(cand["residual_q"] @ step)
        if slope >= 0.0:
            s_hi, d_hi = s, slope
            break
        s_lo, d_lo = s, slope
        if s >= s_max:
            off = (not (cand["groove_force"] ** 2).sum() > 0
                   and receding(np.ascontiguousarray(a_s), step, np.sin(beta0), np.cos(beta0)))
            return (CarriageStatus.LIFT_OFF if off else CarriageStatus.FAILED), q_s, out
        s *= 2.0
    side = 0
    for _ in range(60):  # regula falsi (Illinois) on the slope
        if abs(slope) <= 1e-2 * abs(slope0) or s_hi - s_lo <= 1e-12 * s_hi:
            break
        s = s_hi - d_hi * (s_hi - s_lo) / (d_hi - d_lo)
        cand = evaluate(q_s + s * step)
        if cand is None or not cand["converged"].all():
            return CarriageStatus.FAILED, q_s, out
        slope = -float(cand["residual_q"] @ step)
        if slope < 0.0:
            s_lo, d_lo = s, slope
            d_hi = 0.5 * d_hi if side == -1 else d_hi
            side = -1
        else:
            s_hi, d_hi = s, slope
            d_lo = 0.5 * d_lo if side == 1 else d_lo
            side = 1
    if not (cand["groove_force"] ** 2).sum() > 0:
        s = s_hi
        cand = evaluate(q_s + s * step)
        if cand is None or not cand["converged"].all():
            return CarriageStatus.FAILED, q_s, out
    return CarriageStatus.CONVERGED, q_s + s * step, cand


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------
def solve_carriage(layout: CarriageLayout, load: CarriageLoad, bearing: Bearing = TABLE1, *,
                   oversize=None, groove_errors: GrooveErrors | None = None,
                   tol: float = CARRIAGE_TOLERANCE, max_iter: int = CARRIAGE_MAX_ITER,
                   ball_tol: float = DEFAULT_TOLERANCE,
                   ball_max_iter: int = DEFAULT_MAX_ITER) -> CarriageSolution:
    """Equilibrium of a rigid carriage on its preloaded ball tracks under a carriage load.

    Parameters
    ----------
    layout : CarriageLayout
        Tracks and balls.
    load : CarriageLoad
        External load at the reference point [N, N m].
    bearing : Bearing
        Ball, groove and material of every module (default [Lin2018] Table 1).
    oversize : array_like, optional
        Ball diametral oversize o [m] (nominal preload plus deviation), broadcast to
        (n_tracks, n); added to ``groove_errors.ball_oversize``. Default 0.
    groove_errors : GrooveErrors, optional
        Errors of each ball's module (fields broadcast to (n_tracks, n) + trailing axis), in
        the module frame as in :mod:`tolsim.physics.static`.
    tol : float
        Relative tolerance of the carriage balance: |force rows| <= tol F and |moment rows|
        <= tol F L, F the largest of the load and the contact forces, L
        ``layout.length_scale()``.
    max_iter : int
        Carriage Newton steps.
    ball_tol, ball_max_iter
        Tolerance and step cap of each ball's solve (the imbalance relative to the larger
        of the ball's largest flank force and the reference ball force f_ref; Notes).

    Returns
    -------
    CarriageSolution

    Raises
    ------
    ValueError
        Bad input; a load the layout cannot carry (a component along a locked mechanism).
    CarriageError
        (a ValueError) A carriage that lifts off (``status`` ``CarriageStatus.LIFT_OFF``) or
        has no equilibrium within the gothic arch (``CarriageStatus.FAILED``; Notes,
        "Settling").

    Notes
    -----
    **Conventions (issue 12; kept exactly)**

    *Carriage frame*: z along the rail, x lateral, y up (rail to carriage). The reference point
    is midway between the tracks, at ball-centre height, in the middle of the rows.

    *Track* t at (x_t, y_t) with orientation phi_t: the module's up (its +y, rail groove to
    carriage groove) is e_2 = (-sin phi, cos phi) and its +x is e_1 = (cos phi, sin phi). E_t =
    [e_1 e_2] maps module to carriage components. phi = 0 is the paper's module; the wrapped
    two-row guide has the left track at x = -s/2 with phi = +90 deg, the right one at +s/2 with
    phi = -90 deg. Ball j sits at z_j = (j - (n - 1)/2) pitch, ball 0 trailing.

    *Carriage motion* q = (u_x, u_y, theta_x pitch, theta_y yaw, theta_z roll) (axial motion
    free). A carriage point p = (x, y, z) moves by

        d(p) = B(p) q,   B(p) = [[1, 0, 0, z, -y], [0, 1, -z, 0, x]]

    and the carriage groove of a ball translates by g = E_t^T d(p) in its module frame (the
    groove's own small rotation is neglected, as the issue states).

    *Ball forces*: the ball pushes its carriage groove with f = F_TR u_TR + F_TL u_TL (module
    frame, u_i the unit vector from the ball centre to contact i). As in [Lin2018] Fig. 6 and
    :func:`tolsim.physics.static.solve_static`, the load the top groove transmits to the ball is
    (N_x, -N_y) = -f, i.e. N_x = -f_x (lateral, module +x) and N_y = f_y (normal, pressing the
    groove onto the ball); the side-force ratio is rho = N_x / N_y. f acts on the carriage at the
    ball's nominal centre p, as E_t f in the carriage frame; its generalised force is
    B(p)^T E_t f = (f_x, f_y, -z f_y, z f_x, x f_y - y f_x) (carriage components), i.e. the
    force and its moment about the reference point.

    *External load* at the reference point: lateral force (+x), vertical force V (positive
    downward, pressing the carriage onto the rail), pitch, yaw and roll moments about +x, +y, +z
    (right-handed): Q = (lateral, -V, pitch, yaw, roll).

    *Contact*: a ball of radius R_B + o/2 touches a flank arc of radius R_G centred at C with the
    approach delta = |b - C| + R_B + o/2 - R_G and force F = K delta^1.5 while delta > 0, with K
    the exact Hertz load-deflection constant of the ball in its gothic-arch flank
    (:func:`tolsim.physics.hertz.hertz_constants`, ``load_deflection_constant``; [Johnson1985]
    Sec. 4.2), the same K as :mod:`tolsim.physics.static`.

    **Equilibrium**

    Each ball: its centre P is in equilibrium against its four flanks for the groove translation
    g (displacement control, :func:`tolsim.physics.static.solve_static_displacement`'s kernel,
    reused here ball by ball). Its condensed tangent stiffness follows from the flank stiffnesses
    k_i = F_i' u_i u_i^T + (F_i / |P - C_i|)(I - u_i u_i^T) (symmetric 2 x 2): with K_b, K_t the
    sums over the rail and carriage flanks, the Schur complement of the ball's block

        S = K_t - K_t (K_b + K_t)^-1 K_t = -df/dg        (symmetric, positive semidefinite)

    The carriage: R(q) = Q + sum_balls A^T f(A q) = 0 with A = E_t^T B(p), solved by Newton with
    the analytic tangent K_c = sum_balls A^T S A (the carriage stiffness matrix, [N/m], [N m/rad]
    and mixed [N/rad] = [N m/m] entries). R is minus the gradient of the convex potential
    sum_i (2/5) K max(delta_i, 0)^2.5 - Q . q (the ball positions minimised out), which the line
    search uses; a zero tangent (no preload, unloaded start) is regularised by the stiffness of
    balls at a reference approach, and a carriage with clearance settles (below).

    *Locked DOFs*: a ball in its gothic arch resists both translations of its groove in the module
    plane, so the carriage can move without loading any ball exactly along the null space of the
    stacked A (scaled so rotations are lengths). The DOFs are kept greedily in the order u_x, u_y,
    pitch, yaw, roll while they raise the rank; the others are locked (held at zero). A load with
    a component along that null space cannot be carried: ValueError. One straight track, for
    example, locks roll, and carries a vertical load only if it passes through the track line.

    *Ball tolerance*: a ball is in balance when its force imbalance is <= ball_tol times the
    larger of its largest flank force and the assembly's reference ball force f_ref = max(Q_max /
    n_balls, K (o_max/2)^1.5) (Q_max the largest load component, moments divided by L; the force
    of the regularisation). A loose ball (errors larger than the preload) touching one flank has
    its balance at that flank's delta = 0, a root of order 1.5 of F = K delta^1.5: judged against
    its own vanishing force, Newton stalled near 1e-13 N and the assembly was reported as lifted
    off.

    A contact that opens is reported (``contact_count``), not an error.

    **Settling (a carriage with clearance; issue 25)**

    With a negative oversize o (clearance, catalogue classes such as THK HSR "normal", -5 to +2
    um) nothing touches at q = 0: every force, the tangent K_c and the Hertz energy vanish, and
    the potential Pi(q) = sum_i (2/5) K max(delta_i, 0)^2.5 - Q . q is linear, -Q . q, on the
    whole set of motions that close no contact. Pi is convex in q (delta_i = |P - C_i(g)| + const
    is convex in (P, g) jointly, as the norm of an affine map; t -> max(t, 0)^2.5 is convex and
    increasing; minimising over the ball centres P keeps convexity) and C^1, with -grad Pi = R.
    Newton needs a nonzero tangent, so where it finds none it takes the regularised step dq =
    (k_ref sum A^T A)^-1 R, a descent direction (slope -R . dq < 0), with its line search; if
    that step, from a state with no carriage flank loaded, still closes no contact, the carriage
    *settles* along it: phi(s) = Pi(q + s dq) is convex with the constant slope -R . dq < 0 until
    a contact closes, and then increasing slope. s is doubled until the slope turns >= 0 (the
    contacts closed and carry the load along dq), and the root of the slope is found by regula
    falsi (Illinois) to 1 % of the initial slope; Newton goes on from there (a few steps: 6 for
    ``configs/carriage_preload.toml`` at o = -5 um). Pi falls at every step, so settling and
    Newton cannot cycle; a Newton step that opens every contact again settles again.

    *Lift-off* is the case where no equilibrium exists: along the descent ray nothing closes
    before the grooves leave the gothic arch (their travel reaches a quarter of d), so Pi falls
    without bound within the model. It is reported only where, besides, every carriage flank
    moves away from its ball along the ray: the approach of flank i changes by -u_i . dg, u_i =
    (+/-sin beta_0, cos beta_0) for TR and TL (module frame), so both recede where cos(beta_0)
    dg_2 >= sin(beta_0) |dg_1| for every ball. A phi = 0 track pulled upwards lifts off with or
    without preload. A four-point gothic arch carries a side load either way, so the wrapped
    two-row guide pulled upwards settles on its other diagonals (by the module's mirror symmetry
    exactly as far as pressed down): it does not lift off. A ray that reaches the end of the
    arch with contacts loaded or approaching (a load beyond the arch, or a clearance larger
    than it) has no answer within the model: ``CarriageStatus.FAILED``. :func:`solve_carriage`
    raises :class:`CarriageError` (a ValueError naming the load) with ``status`` LIFT_OFF or
    FAILED; :func:`solve_carriage_batch` reports the same codes per assembly.

    Settling happens only where the Newton before it gave up (a zero tangent after its first
    step), so every carriage that converged before converges by the same operations to the
    same bits. *Check*, pure vertical load V on the wrapped guide with clearance (h = o/2 < 0):
    by symmetry every ball carries the side load V/n on one diagonal pair, two-point, its centre
    midway between the two arc centres, rho(s) = |2 d e + s x| apart after a side travel s of
    the carriage groove, so delta = rho/2 - d + h and V/n = K delta^1.5 (2 d sin(beta_0) + s) /
    rho. To first order s = (-2 h + 2 (F/K)^(2/3)) / sin(beta_0), F = V / (n sin(beta_0)): the
    clearance closing along the diagonal plus the Hertz approach of the loaded pair, 7.071 +
    2.343 = 9.414 um for 300 N on 24 balls at o = -5 um; exactly 9.3626 um (the pair's line
    turns by s cos(beta_0) / (2 d)), as the solver gives
    (``tests/physics/test_carriage_clearance.py``).

    **How carriage loads map to the balls' side-force ratio**

    Small-displacement rigid-body kinematics, linearised at the ball; each step is tested in
    ``tests/physics/test_carriage.py`` (numbers for the [Lin2018] Table 1 ball, K = 2.345e10
    N/m^1.5,
    d = R_G - R_B = 0.4 mm).

    1. *Which DOF a load excites.* By d(p) = B(p) q a yaw theta_y moves the grooves sideways by
       d_x = theta_y z, a pitch theta_x moves them vertically by d_y = -theta_x z (both odd in z,
       zero at the reference point), a vertical load moves them all by u_y, a lateral one by u_x.
       The external moment is balanced by the ball forces' moments: yaw by sum z f_x, pitch by
       -sum z f_y (f the ball's force on the carriage, carriage frame).
    2. *Into the module frame.* g = E_t^T d: g_1 = cos(phi) d_x + sin(phi) d_y (side), g_2 =
       -sin(phi) d_x + cos(phi) d_y (normal). phi = 0: yaw -> g_1 = theta_y z, pitch and vertical
       -> g_2. Wrapped guide (phi = +/-90 deg): g_1 = +/-d_y (vertical and pitch become side
       displacements), g_2 = -/+d_x (lateral and yaw become normal displacements).
    3. *Linearised ball.* With f = (-N_x, N_y) and S = -df/dg: dN_x = S_11 g_1 + S_12 g_2, dN_y =
       -S_12 g_1 - S_22 g_2. In the (BL, TR) and (BR, TL) diagonal directions a, b (at 45 deg) the
       flank stiffnesses are diagonal and the rail and carriage flanks of a pair act in series:
       S ~ (k_1 a a^T + k_2 b b^T) / 2 with k ~ F^(1/3), F_1 ~ 1 - rho, F_2 ~ 1 + rho ([Lin2018]
       Sec. 3.1), so S_12 / S_22 = +/-(k_1 - k_2)/(k_1 + k_2): zero without a side load (mirror
       symmetry). Preloaded, unloaded and at beta_0 = 45 deg, exactly K_t = K_b = (k_n + F0/d) I,
       S = (k_n + F0/d)/2 I with F0 = K (o/2)^1.5, k_n = 1.5 K (o/2)^0.5 (F0/d is 0.25 % of k_n
       at o = 3 um, where F0 = 43.1 N, N0 = 2 F0 cos(beta_0) = 60.9 N, k_n = 43.1 N/um, S =
       21.6 N/um).
    4. *Wrapped guide, yaw moment M.* g_2 = -/+theta_y z, g_1 = 0, so it changes N_y along z and
       leaves N_x alone: N_y,j = N0 +/- M z_j / (2 sum z^2) (left/right track), theta_y = M / (2 S
       sum z^2) (K_yaw = 2 S sum z^2 = 0.118 N m/urad for six balls at 12.5 mm, o = 3 um), and
       N_x = 0 exactly for any M (module mirror symmetry). The Hertz correction to N_y is second
       order in M (1.6 % of the linear change at 1 N m). Once the balls already carry side load
       (a vertical load), S_12 != 0 drags N_x along: dN_x/dN_y = -(k_1 - k_2)/(k_1 + k_2) =
       -0.140 at rho0 = -0.40 (measured -0.138); each track still carries V/2.
    5. *Wrapped guide, pitch moment P.* g_1 = -/+theta_x z: N_x,j = -/+P z_j / (2 sum z^2), N_y =
       N0 + O(P^2), so rho_j = N_x,j / N_y,j is nearly linear in z. Measured (o = 3 um, six balls
       at 12.5 mm): P = 5 N m, |rho| <= 0.45: R^2 = 0.99985 and the largest deviation from the
       least-squares line 0.54 % of the rho range (the end balls' N_y rises 3.5 %); P = 10 N m:
       R^2 = 0.9975, 2.2 %; P = 20 N m: the end balls go to two-point contact, R^2 = 0.947, 11.6 %.
    6. *phi = 0 track, vertical load V and yaw M ([Lin2018] Fig. 8; the old per-ball rule).* g_1 =
       theta_y z, g_2 = u_y for every ball and S_12 = 0 at rho = 0, so to first order N_x,j = S_11
       theta_y z_j and, from sum z N_x = M, N_x,j = M z_j / sum z^2 at N_y = V/n: the old rule
       (``tolsim/io/config/sections.py`` ``read_loads``) is exactly the linearised carriage. Beyond
       it: N_y of a ball is even and convex in g_1 (the pair approaches are delta_v +/- c g_1 and F
       ~ delta^1.5), so at the common u_y the end balls take more N_y and the middle ones less (sum
       N_y = V); rho is odd in M, so rho - rho_old = O(M^3). Default study (10 balls at 10.05 mm, V
       = 10 x 200 N, M = 15 N m, no preload): theta_y = 57.3 urad, u_y = -9.21 um, max |rho -
       rho_old| = 0.0071 at the end balls (z = -/+45.2 mm: -/+0.4000 against -/+0.4071; 0.87 % of
       the rho range), 95 % of it from N_y = 203.4 N there (197.8 N in the middle); N_x is within
       0.067 N of the old rule. With two balls (Fig. 8) the track is statically determinate: V = 400
       N and M = 0.6 x 200 N x 10.5 mm = 1.26 N m give rho = (-0.6, +0.6) exactly, reading ball 0
       (trailing) as the paper's Ball 1 (the faster ball behind, which runs into Ball 2).
    """
    check_solver_options(tol, max_iter)
    check_solver_options(ball_tol, ball_max_iter)
    q_ext = load.generalised()
    t, n = layout.n_tracks, layout.balls_per_track
    nball = t * n
    inputs = _ball_inputs(layout, oversize, groove_errors, bearing)
    length = layout.length_scale()
    scale = np.array([1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
    a = layout.groove_map().reshape(nball, 2, 5)
    a_s = a * scale  # groove map in scaled coordinates (rotations times L)
    q_s_ext = q_ext * scale  # moments / L
    locked, free = _carried(layout, load)
    load_norm = np.abs(q_s_ext).max()
    dist = bearing.groove_radius - bearing.ball_radius
    k = hertz_k(bearing)
    # reference ball force (load share or flank preload): the force floor of the ball
    # tolerance, and with its approach the ball stiffness for the regularised start
    total_o = inputs[-1]
    f_ref = max(load_norm / nball, k * max(0.5 * float(total_o.max()), 0.0) ** 1.5)
    balls = _Balls(inputs, bearing, nball, ball_tol, ball_max_iter,
                   max(f_ref, k * FLOOR_LENGTH**1.5))

    def evaluate(q_s):
        groove = np.einsum("bik,k->bi", a_s, q_s)
        if np.abs(groove).max() > LIFT_OFF * dist:
            return None
        out = balls(groove)
        out["groove"] = groove
        out["residual_q"] = q_s_ext + np.einsum("bik,bi->k", a_s, out["groove_force"])
        out["tangent"] = np.einsum("bik,bij,bjl->kl", a_s, out["stiffness"], a_s)
        out["potential"] = out["energy"].sum() - q_s_ext @ q_s
        return out

    def failed():
        return CarriageError(f"the carriage solve failed under the load ({load.describe()}): "
                             f"the motion leaves the gothic arch before an equilibrium "
                             f"(contacts out of its reach, or a load beyond it), or a ball "
                             f"solve failed", CarriageStatus.FAILED)

    delta_ref = max((f_ref / k) ** (2.0 / 3.0), FLOOR_LENGTH)
    k_ref = 1.5 * k * np.sqrt(delta_ref) * 0.5
    geometric = k_ref * np.einsum("bik,bil->kl", a_s, a_s)

    def scaled_norm(out):
        fmax = max(load_norm, float(out["force"].max()), k * FLOOR_LENGTH**1.5)
        return np.abs(out["residual_q"][free]).max() / fmax

    q_s = np.zeros(5)
    out = evaluate(q_s)
    if out is None or not out["converged"].all():
        raise failed()
    converged = False
    it = 0
    while True:
        err = scaled_norm(out)
        if err <= tol:
            converged = True
            break
        if it >= max_iter:
            break
        it += 1
        loose = not (out["groove_force"] ** 2).sum() > 0  # no carriage flank loaded
        kff = out["tangent"][np.ix_(free, free)]
        rf = out["residual_q"][free]
        w = np.linalg.eigvalsh(kff)
        wg = np.linalg.eigvalsh(geometric[np.ix_(free, free)])
        if w[0] <= 1e-10 * wg[-1]:  # zero (unloaded) or singular tangent: regularise
            kff = kff + geometric[np.ix_(free, free)]
        step = np.zeros(5)
        step[free] = np.linalg.solve(kff, rf)
        move = np.abs(np.einsum("bik,k->bi", a_s, step)).max()
        if move > STEP_CAP * dist:
            step *= STEP_CAP * dist / move
        slope = -rf @ step[free]  # d potential / d alpha at 0
        r2 = err
        alpha = 1.0
        trial = None
        for _ in range(40):
            cand = evaluate(q_s + alpha * step)
            if cand is not None and cand["converged"].all():
                trial, alpha_trial = cand, alpha
                if (cand["potential"] <= out["potential"] + 1e-4 * alpha * slope
                        or scaled_norm(cand) < (1.0 - 1e-4 * alpha) * r2):
                    break
            alpha *= 0.5
        if trial is None:
            raise failed()
        q_s = q_s + alpha_trial * step
        out = trial
        if loose and not (out["groove_force"] ** 2).sum() > 0:  # closed no contact: settle
            status, q_s, out = _settle(evaluate, a_s, q_s, step, out, LIFT_OFF * dist,
                                       bearing.nominal_contact_angle)
            if status == CarriageStatus.LIFT_OFF:
                raise CarriageError(f"the carriage lifts off the rail under the load "
                                    f"({load.describe()}): it pulls the carriage away from "
                                    f"every contact", CarriageStatus.LIFT_OFF)
            if status != CarriageStatus.CONVERGED:
                raise failed()

    shape4, shape2 = (t, n, 4), (t, n, 2)
    nx, ny = out["load"][:, 0], out["load"][:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(ny > 0, nx / np.where(ny > 0, ny, 1.0), np.nan)
    stiffness = out["tangent"] / np.outer(scale, scale)
    return CarriageSolution(
        contact_angle_deviation=out["dbeta"].reshape(shape4),
        normal_force=out["force"].reshape(shape4),
        approach=out["approach"].reshape(shape4),
        contact_count=out["count"].reshape(t, n),
        side_load=nx.reshape(t, n).copy(),
        normal_load=ny.reshape(t, n).copy(),
        side_force_ratio=rho.reshape(t, n),
        ball_displacement=out["ball"].reshape(shape2),
        groove_displacement=out["groove"].reshape(shape2),
        ball_z=layout.ball_z,
        displacement=q_s * scale,
        stiffness=stiffness,
        locked=locked,
        converged=bool(converged),
        iterations=it,
        residual=out["residual_q"] / scale,
        status=CarriageStatus.CONVERGED if converged else CarriageStatus.NOT_CONVERGED,
    )


def solve_carriage_batch(layout: CarriageLayout, load: CarriageLoad, bearing: Bearing = TABLE1,
                         *, oversize=None, groove_errors: GrooveErrors | None = None,
                         nominal_oversize=None, ball_z=None, loaded=None, start=None,
                         tol: float = CARRIAGE_TOLERANCE, max_iter: int = CARRIAGE_MAX_ITER,
                         ball_tol: float = DEFAULT_TOLERANCE,
                         ball_max_iter: int = DEFAULT_MAX_ITER,
                         joint: bool = True) -> CarriageBatch:
    """Equilibria of many sampled carriage assemblies under one load, in parallel.

    Each assembly is solved to the certificate of :func:`solve_carriage` (every ball's and
    the carriage's balance within ``ball_tol`` and ``tol``), by the joint Newton on balls and
    carriage together or, where that does not converge, by the nested Newton of
    :func:`solve_carriage` (Notes, "Many assemblies at once"), compiled, with the
    assemblies in parallel (:func:`carriage_batch_kernel`). The results agree with
    :func:`solve_carriage` to about 1e-11 of their scale (forces, stiffness, angles) and
    1e-10 in displacement (up to 1e-9 on a badly conditioned carriage; tested to 1e-9 in
    ``tests/physics/test_carriage_batch.py``), except the contact angles of loose balls, whose
    position is not unique. Every
    assembly starts from the solution q0 of the nominal assembly (no groove errors,
    ``nominal_oversize``) by :func:`solve_carriage`, or from q = 0 if that one lifts off.

    An assembly is solved by the same operations whatever batch it is in and whatever the
    number of Numba threads: its result is bit-identical alone or in any batch. An assembly
    that lifts off or fails is reported by ``status``, never raised.

    Parameters
    ----------
    layout : CarriageLayout
        Tracks and balls (the same for all assemblies).
    load : CarriageLoad
        External load at the reference point [N, N m] (the same for all assemblies).
    bearing : Bearing
        Ball, groove and material of every module (default [Lin2018] Table 1).
    oversize : array_like, optional
        Ball diametral oversize o [m] (nominal preload plus deviation), broadcast to (m,
        n_tracks, n) by NumPy's rules; added to ``groove_errors.ball_oversize``. Default 0.
    groove_errors : GrooveErrors, optional
        Errors of each ball's module in its module frame (:mod:`tolsim.physics.static`),
        fields broadcast to (m, n_tracks, n) + their trailing axis. The number of assemblies
        m is the leading axis of the common broadcast shape of ``oversize`` and the error
        fields (1 if they have at most two axes).
    nominal_oversize : array_like, optional
        Oversize [m] of the nominal assembly whose solution starts every Newton, broadcast to
        (n_tracks, n). Default: ``oversize`` if it has at most two axes (the same for all
        assemblies, e.g. the preload class, with the sampled scatter in ``groove_errors``),
        else 0. Not used with ``start``.
    ball_z : array_like, optional
        Axial position z of every ball of every assembly [m], broadcast to (m, n_tracks, n)
        (balls moving through the carriage, :mod:`tolsim.study.pipeline.carriage_track`). Default:
        the layout's nominal z_j (``layout.ball_z``). The layout's ``balls_per_track`` is
        then the number of ball slots per track, not all of them loaded.
    loaded : array_like of bool, optional
        Whether each ball is in the loaded zone, broadcast to (m, n_tracks, n); default all.
        A ball outside carries nothing: its rows of the groove map are zero and no flank
        touches it (in the kernel its radius is R_B - d/2). Its outputs: ``normal_force``
        0, ``contact_count`` 0, ``contact_angle_deviation``, ``side_load`` and
        ``normal_load`` NaN, ``ball_converged`` True. Its errors and oversize are ignored
        but must be finite.
    start : array_like, optional
        Carriage displacement q [m, rad] (``DOFS`` order) that every Newton starts from,
        (5,) or (m, 5), e.g. each assembly's solution of the previous time step. Default:
        the solution of the nominal assembly (:func:`solve_carriage`, layout's nominal z,
        every ball loaded), or q = 0 if it lifts off.
    tol, max_iter, ball_tol, ball_max_iter
        As in :func:`solve_carriage`, for every assembly (``max_iter`` caps the nested
        Newton; the joint one gives up after 12 steps).
    joint : bool
        Try the joint Newton first (default). False solves every assembly by the nested
        Newton alone: the same results to about 1e-11, 3.5 times slower.

    Returns
    -------
    CarriageBatch

    Raises
    ------
    ValueError
        Bad input (shapes, non-finite values, errors out of range, solver options); a load
        the layout cannot carry (a component along a locked mechanism), as
        :func:`solve_carriage`.

    Notes
    -----
    **Many assemblies at once**

    :func:`solve_carriage_batch` solves m sampled assemblies (one layout and load, each its own
    errors and oversizes) in one compiled kernel, assemblies in parallel; an assembly's result is
    bit-identical whatever batch it is in and however many threads run. Each assembly first
    tries the *joint* Newton, ball centres P_b and q unknown together. Linearised, the ball
    balance gives r_b + M_b dP_b - K_t,b A_b dq = 0 (M = K_b + K_t), so

        dP_b = M_b^-1 K_t,b A_b dq - M_b^-1 r_b,    K_c dq = R - sum_b A_b^T K_t,b M_b^-1 r_b

    with the tangent K_c = sum A^T S A of the nested Newton (which has r_b = 0). A step costs one
    evaluation of every ball's flanks, vectorised across the balls, instead of a Newton solve of
    every ball. A ball whose loaded flanks hold no diagonal pair (BL-TR or BR-TL) is loose: its
    only balance has no force, each loaded flank going to delta = 0, where a Newton step only
    divides delta by 3; it takes 1.5 times its own correction, which lands on delta = 0 to first
    order. A ball far from its balance (at the start, after a large step) is first moved by
    ball-only Newton steps. The joint Newton ends on the certificate of the nested one (every
    ball's imbalance and the carriage's within tolerance); an assembly where it does not within
    12 steps (about 0.5 % of ``benchmarks/bench_carriage.py``'s, mostly balls changing contacts)
    is solved again by the nested Newton of :func:`solve_carriage`, compiled. Both start from the
    solution q0 of the error-free nominal assembly, which :func:`solve_carriage` finds once.
    Measured there (``configs/carriage_preload.toml``, 24 balls, 1 um errors, 2 um preload; a
    2-core VM): 4.9 joint steps on average, 9-10 us of CPU per assembly (about 190 k assemblies
    or 4.5 M balls per second on 2 threads), 3.5 times less than the nested Newton alone and
    about 90 times less than :func:`solve_carriage` one assembly at a time.

    **Balls moving through the carriage**

    With ``along_track`` propagation the balls roll through the carriage (:mod:`tolsim.study.
    pipeline.carriage_track` derives their motion and how balls enter and leave the loaded zone).
    :func:`solve_carriage_batch` then takes each assembly's balls at their own axial positions
    (``ball_z``, replacing z_j in B(p) and in the moments) and a ``loaded`` mask: the layout's
    ``balls_per_track`` is the number of ball slots of a track, and a slot whose ball is outside
    the loaded zone (or empty) carries nothing. Such a ball has zero rows in the groove map A (its
    groove does not follow the carriage) and no flank touches it (the kernel gives it a radius of
    R_B - d/2, so every approach is about -d/2 and F = K max(delta, 0)^1.5 = 0): it adds nothing
    to the residual, the tangent or the reference force f_ref (formed over the loaded balls).

    The locked DOFs are those of the layout's nominal balls, whatever ``ball_z`` and
    ``loaded``. Without ``ball_z`` and ``loaded`` the solve is exactly the one of the fixed
    nominal balls (bit-identical); with them, the kernel forms the groove map A of each
    assembly as it solves it (:func:`tolsim.physics.carriage._map_kernels.
    assembly_groove_rows`: no array of every assembly's maps is written) and of
    sum_b A_b^T A_b only the diagonal, which the trace bounds read
    (:func:`tolsim.physics.carriage._map_kernels.gram_diagonal`); the whole of it, and its
    largest eigenvalue, only where a tangent's pivot lies between those bounds
    (:func:`tolsim.physics.carriage._map_kernels.formed_pivot`) or the nested Newton takes
    over (it regularises with it).
    """
    check_solver_options(tol, max_iter)
    check_solver_options(ball_tol, ball_max_iter)
    q_ext = load.generalised()
    t, n = layout.n_tracks, layout.balls_per_track
    nball = t * n
    inputs, m = _batch_inputs(layout, oversize, groove_errors, bearing)
    length = layout.length_scale()
    scale = np.array([1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
    locked, free = _carried(layout, load)
    free_index = np.flatnonzero(free).astype(np.int64)
    own_z = np.empty((0, nball))  # (the balls' own z: the kernel forms their maps)
    if ball_z is None and loaded is None:  # the fixed nominal balls
        a_s = np.ascontiguousarray(layout.groove_map().reshape(nball, 2, 5) * scale)
        geometric = np.einsum("bik,bil->kl", a_s, a_s)
        geometric_max = float(np.linalg.eigvalsh(geometric[np.ix_(free, free)])[-1])
        maps = (a_s[None], np.tile(layout.ball_z / length, t)[None],
                geometric[None], np.array([geometric_max]), np.ones((1, nball), np.bool_))
    else:  # balls at their own z, in or out of the loaded zone (per assembly)
        z, mask = _ball_positions(layout, ball_z, loaded)
        if z.shape[0] != m and m != 1 and z.shape[0] != 1:
            raise ValueError(f"ball_z and loaded have {z.shape[0]} assemblies, oversize and "
                             f"groove errors {m}")
        if z.shape[0] > m:  # errors shared by the assemblies: one row of inputs each
            base = 0.0 if oversize is None else np.asarray(oversize, dtype=float)
            inputs, m = _batch_inputs(layout, np.broadcast_to(base, z.shape), groove_errors,
                                      bearing)
        own_z = np.ascontiguousarray(np.broadcast_to(z, (m, t, n))).reshape(m, nball)
        mask = np.ascontiguousarray(np.broadcast_to(mask, (m, t, n)))
        maps = (np.empty((0, nball, 2, 5)), np.empty((0, nball)), np.empty((0, 5, 5)),
                np.empty(0), mask.reshape(-1, nball))

    if start is not None:
        start = np.asarray(start, dtype=float)
        if start.shape not in ((5,), (m, 5)) or not np.all(np.isfinite(start)):
            raise ValueError(f"start must hold finite q of shape (5,) or ({m}, 5), got shape "
                             f"{start.shape}")
        start = np.ascontiguousarray(np.atleast_2d(start / scale))
    else:
        if nominal_oversize is None:
            nominal_oversize = oversize if oversize is None or np.ndim(oversize) <= 2 else 0.0
        _ball_inputs(layout, nominal_oversize, None, bearing)  # validate before solving
        try:
            nominal = solve_carriage(layout, load, bearing, oversize=nominal_oversize, tol=tol,
                                     max_iter=max_iter, ball_tol=ball_tol,
                                     ball_max_iter=ball_max_iter)
            start = nominal.displacement / scale if nominal.converged else np.zeros(5)
        except ValueError:  # the nominal assembly lifts off (the input was checked above)
            start = np.zeros(5)
        start = start[None, :]

    shape = (m, t, n)
    dbeta = np.empty((m, nball, 4))
    force = np.empty((m, nball, 4))
    side = np.empty((m, nball))
    normal = np.empty((m, nball))
    count = np.empty((m, nball), dtype=np.int8)
    ball_ok = np.empty((m, nball), dtype=np.bool_)
    displacement = np.empty((m, 5))
    stiffness = np.empty((m, 5, 5))
    residual = np.empty((m, 5))
    iterations = np.empty(m, dtype=np.int32)
    status = np.empty(m, dtype=np.int8)
    fallback = np.empty(m, dtype=np.bool_)
    frame = np.stack([np.cos(layout.track_orientation), np.sin(layout.track_orientation),
                      layout.track_x / length, layout.track_y / length], axis=1)
    groove_maps, zetas, geometrics, geometric_maxs, loaded_rows = maps
    loaded_rows = kernel_array(loaded_rows, np.bool_)
    carriage_batch_kernel(groove_maps, frame, zetas, free_index, geometrics,
                          geometric_maxs, own_z, _track_rows(layout), length, loaded_rows,
                          q_ext[None, :], start, *inputs, scale,
                          bearing.nominal_contact_angle,
                          bearing.groove_radius - bearing.ball_radius, hertz_k(bearing),
                          float(tol), int(max_iter), float(ball_tol), int(ball_max_iter),
                          dbeta, force, side, normal, count, ball_ok, displacement, stiffness,
                          residual, iterations, status, fallback, bool(joint))
    return CarriageBatch(
        contact_angle_deviation=dbeta.reshape(shape + (4,)),
        normal_force=force.reshape(shape + (4,)),
        side_load=side.reshape(shape),
        normal_load=normal.reshape(shape),
        contact_count=count.reshape(shape),
        ball_converged=ball_ok.reshape(shape),
        displacement=displacement,
        stiffness=stiffness,
        residual=residual,
        converged=status == STATUS_CONVERGED,
        iterations=iterations,
        status=status,
        fallback=fallback,
        locked=locked,
    )
