"""One ball under external loads: pushes of its neighbours and ball-to-ball friction.

[Lin2018] stops where ball-to-ball contact begins (Sec. 4: "the effect of velocity difference
on the level of ball-to-ball contact force and sliding friction loss still remains a
question"). This module derives what a touching neighbour does to one ball; the velocity
models take the loads as keyword arguments (:func:`tolsim.physics.velocity.analytic.analytic`,
:func:`tolsim.physics.velocity.full.full`).

The kinematics and the friction of a ball-ball contact are in the Notes of
:func:`ball_contact_slip` and :func:`ball_contact_friction`; the equilibrium with the loads,
the creep stiffness and the traction capacity in those of :class:`BallLoadFields`.

Nomenclature (code name <- symbol)
----------------------------------
``push`` <- P = Q_back - Q_front [N], net force of the neighbours along +z through the centre;
``neighbour_force`` <- (Q_back, Q_front) >= 0 [N]; ``neighbour_force_sum`` <- Q_back + Q_front;
``ball_friction`` <- mu_bb [-], Coulomb coefficient of the ball-ball contact;
``carriage_force`` <- F_c [N]; ``creep_stiffness`` <- K = dP/d(epsilon) [N];
``traction_capacity`` <- P_cap [N]; epsilon, beta_i, F_i, Omega as in
:mod:`tolsim.physics.geometry` (x right, y up, z along the rail, top groove moving at +v).
"""

from dataclasses import dataclass

import numpy as np

from tolsim._jit import jit
from tolsim.physics.geometry import SIDE_SIGN_X, SIDE_SIGN_Y

#: Default Coulomb coefficient mu_bb of the ball-ball contact (steel on steel, boundary
#: lubrication; the same value as the raceways' mu of [Lin2018] Table 1).
DEFAULT_BALL_FRICTION = 0.1

#: Sides of a ball-ball contact: the arm from the ball centre to the contact, along z.
CONTACT_SIDES = {"back": -1.0, "front": 1.0}


@dataclass(frozen=True, kw_only=True)
class BallLoadFields:
    """Fields shared by the velocity models' results under external loads.

    Attributes
    ----------
    push : ndarray, shape (n,)
        P = Q_back - Q_front [N], the net push through the centre along +z (as applied).
    neighbour_force_sum : ndarray, shape (n,)
        Q_back + Q_front [N], the normal force that sets the ball-ball friction.
    free_rolling_velocity_deviation : ndarray, shape (n,)
        epsilon with P = 0 and no neighbours [-] (the unloaded model's value).
    carriage_force : ndarray, shape (n,)
        F_c = f_TR + f_TL [N], the friction force between the ball and the moving (top)
        groove along the rail: positive opposes the carriage motion.
    free_rolling_carriage_force : ndarray, shape (n,)
        F_c with P = 0 and no neighbours [N]: the baseline (spin and differential slip).
    creep_stiffness : ndarray, shape (n,)
        K = dP/d(epsilon) [N per unit epsilon] at the loaded state (> 0; 0 when sliding).
    braking_sensitivity : ndarray, shape (n,)
        d(epsilon)/d(Q_back + Q_front) at fixed P [1/N] at the loaded state.
    traction_capacity : ndarray, shape (n,)
        P_cap [N]: |P| >= P_cap means gross sliding (the same in both directions).
    braking_capacity : ndarray, shape (n,)
        Q_back + Q_front [N] beyond which the braking stalls the rotation (inf for
        mu_bb = 0; Notes).
    sliding : ndarray of bool, shape (n,)
        |P| >= P_cap or Q_back + Q_front >= braking capacity: no rolling quasi-static state,
        the ball slides.

    Notes
    -----
    **Equilibrium (Eq. 18 with the loads)**

    Force along z (the first row of Eq. 18): sum_i f_i + P = 0. Moments: sum_i (-R f_i x_i - M_i
    y_i) + M_bb = 0, i.e. in the rows of :mod:`tolsim.physics.velocity.analytic` (friction over mu,
    u_i = f_i / mu, m_i = M_i / (mu R)):

        sum u_i = -P / mu,   sum u_i x_i + sum m_i y_i = -(mu_bb / mu) (Q_back + Q_front) e,

    e the unit rolling axis (Omega_perp / |Omega_perp|; the analytic model takes the axis of rigid
    rolling at the four contact centres, :func:`rolling_axis`, x for a symmetric ball: the braking
    enters the rolling-axis (x) row of Eq. 18, and a y component for a tilted axis).

    The full model adds the same loads to its exact equilibrium. Its equations are the gradient of

        Phi(v_B, Omega) = D(v_B, Omega) + mu_bb (Q_back + Q_front) R_B |Omega_perp| - P v_B,

    D the friction power in the four raceway contacts (convex); the braking term is convex and
    the push term linear, so Phi is convex and the equilibrium is its minimum.

    Power balance. In steady rolling the ball's kinetic energy is constant, so the power of all
    loads on it vanishes. With t the raceway traction, slip_i = (ball velocity) - V_i z and
    t . slip_i = -mu sigma |slip_i| pointwise:

        v F_c + P v_B = sum_i D_i + D_bb,   D_bb = mu_bb (Q_back + Q_front) R_B |Omega_perp|,

    where F_c = f_TR + f_TL is the carriage friction force (below), D_i the dissipation in raceway
    contact i and D_bb the ball's share of the ball-contact dissipation (its braking moment times
    Omega). A contact between two balls dissipates mu_bb Q |s|, the sum of the two balls' shares
    (parallel axes). The neighbours' normal pushes put in P v_B; their friction takes out D_bb.

    Carriage friction force. F_c = f_TR + f_TL, the z friction of the top groove on the ball:
    by Newton's third law the ball pulls the carriage along -F_c, so **F_c > 0 opposes the
    carriage motion** (it is the force the drive spends on this ball; the existing ``drag_force``
    of the full model). Free rolling (P = 0, no neighbours) it is the drag from spin and
    differential slip: for the nominal ball, 4 M_spin tan(beta_0) / (2 R_B) with M_spin from Eq.
    (14) (ERRATA notes). A push P > 0 is carried by both grooves, about half each: F_c falls by
    ~P/2 (the ball helps the carriage along) and the rail takes the rest. Braking needs a couple
    of the grooves: F_c rises by mu_bb (Q_back + Q_front) / (2 cos beta_0) for the nominal ball
    (top and bottom friction opposite, moment arm R_B cos beta_0 each).

    **Creep stiffness and its sign**

    K = dP/d(epsilon) [N per unit epsilon]. A push from behind (P > 0) must be balanced by raceway
    friction along -z; friction opposes the slip of the ball over the grooves, so on balance the
    ball slips forward over them: it runs faster, epsilon grows, K > 0. In the full model this is
    convexity: the equilibrium moves by dx/dP = H^-1 e_vB (H the Hessian of Phi, positive
    definite), so dv_B/dP = (H^-1)_00 > 0. In the linear (analytic) model K is exact for the
    model and constant: for the nominal ball each contact carries -P/4, dgamma_i = -P a /
    (4 mu k_f R F g_i), and epsilon = tan(beta_0)/2 (-dgamma_BR + dgamma_TL) gives

        K = -4 mu k_f R_B F / (a tan(beta_0))   (k_f < 0),

    704.6 N for Table 1 at N_y = 200 N (F = 141.4 N, a = 0.554 mm): 7.05 N per percent of
    epsilon. The full model's slope at c/a = 0 is steeper than k_f (ERRATA 7), so its K is a few
    percent larger (746.4 N for this ball; 2.6-5.7 % over |rho| <= 0.6, |theta| <= 2 deg,
    tests/physics/test_ball_push.py).

    **Gross sliding and the traction capacity**

    Coulomb friction is rate independent: the loads depend only on the direction of
    (v_B, Omega, v). Far from rolling (v_B -> infinity at fixed v) the ball slides between two
    grooves that are, relatively, at rest, and Phi grows like |v_B| (Phi_0 - |P|) with

        P_cap = min over Omega of Phi_0(Omega),
        Phi_0 = D(v_B = 1, Omega; V_i = 0) + mu_bb (Q_back + Q_front) R_B |Omega_perp|,

    the least force that keeps the ball sliding at unit speed between fixed grooves (D is even
    and homogeneous of degree one there, so the same P_cap holds backward). For |P| < P_cap an
    equilibrium exists; as |P| -> P_cap, epsilon -> +-infinity and the friction saturates at the
    sliding state of the minimiser; for |P| >= P_cap there is no quasi-static state: the ball
    slides (gross sliding) and is carried along by its neighbours. Bounds: Omega = 0 (pure
    sliding, all four contacts at mu F_i) gives P_cap <= mu sum F_i; Jensen's inequality on each
    planar contact (the pressure-weighted mean slip is the slip at the centre) gives
    P_cap >= the same minimum for point contacts, :func:`point_traction_capacity`, which is what
    the analytic model uses (with the braking about the rolling axis only, |e . Omega| <=
    |Omega_perp|, still a lower bound). Table 1 at N_y = 200 N: mu sum F_i = 56.6 N, the push
    that would take an epsilon of about 8 % at the linear K: far beyond the ~1 % of Table 2.

    The braking has a limit of its own: the grooves can turn the ball against the neighbours'
    braking only up to the moment they exert on a ball that does not rotate and slides on both
    (Omega = 0, 0 < v_B < v: the bottom contacts' friction -mu F_i z, the top ones' +mu F_i z),

        M_stall = mu R_B |sum_bottom F_i x_i - sum_top F_i x_i|  (~ mu R_B cos(beta_0) sum F_i),

    :func:`stall_moment`. For mu_bb (Q_back + Q_front) R_B >= M_stall the rotation stalls
    (Omega_perp = 0 is the minimiser of Phi, on the kink of |Omega_perp|): the ball skids on both
    grooves, its speed is no longer set by rolling. ``braking_capacity`` = M_stall / (mu_bb R_B) is
    that neighbour force sum (about 400 N for Table 1 at N_y = 200 N, mu_bb = 0.1). Both models flag
    ``sliding`` for |P| >= P_cap or Q_back + Q_front >= ``braking_capacity``.
    """

    push: np.ndarray
    neighbour_force_sum: np.ndarray
    free_rolling_velocity_deviation: np.ndarray
    carriage_force: np.ndarray
    free_rolling_carriage_force: np.ndarray
    creep_stiffness: np.ndarray
    braking_sensitivity: np.ndarray
    traction_capacity: np.ndarray
    braking_capacity: np.ndarray
    sliding: np.ndarray


def as_ball_loads(push, neighbour_force, ball_friction, shape):
    """Validate the external loads and broadcast them to flat arrays for ``shape`` balls.

    Parameters
    ----------
    push : None or array_like, broadcastable to ``shape``
        P [N] (finite, either sign).
    neighbour_force : None or array_like, shape broadcastable to ``shape + (2,)``
        (Q_back, Q_front) [N] (finite, >= 0). At most one of ``push`` and ``neighbour_force``.
    ball_friction : float
        mu_bb [-] (finite, >= 0).
    shape : tuple
        Batch shape of the balls.

    Returns
    -------
    push, neighbour_force_sum : ndarray, shape (prod(shape),)
        C-contiguous float64 P [N] and Q_back + Q_front [N].

    Raises
    ------
    ValueError
        Naming the bad value.
    """
    if push is not None and neighbour_force is not None:
        raise ValueError("give push or neighbour_force, not both (push = Q_back - Q_front)")
    mu_bb = _finite_float(ball_friction, "ball_friction")
    if mu_bb < 0:
        raise ValueError(f"ball_friction = {mu_bb!r} must be >= 0")
    n = int(np.prod(shape, dtype=np.int64))
    if neighbour_force is not None:
        q = _finite_array(neighbour_force, "neighbour_force")
        if q.ndim == 0 or q.shape[-1] != 2:
            raise ValueError("neighbour_force must have a last axis of length 2 (Q_back, "
                             f"Q_front), got shape {q.shape}")
        if np.any(q < 0):
            raise ValueError("neighbour_force must be >= 0 (a contact force pushes; "
                             f"got {q[q < 0].ravel()[:3].tolist()})")
        q = _broadcast(q, shape + (2,), "neighbour_force").reshape(n, 2)
        return (np.ascontiguousarray(q[:, 0] - q[:, 1]),
                np.ascontiguousarray(q[:, 0] + q[:, 1]))
    p = np.zeros(()) if push is None else _finite_array(push, "push")
    p = _broadcast(p, shape, "push").reshape(n)
    return np.ascontiguousarray(p, dtype=np.float64), np.zeros(n)


def _finite_float(value, name):
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(out):
        raise ValueError(f"{name} = {out!r} must be finite")
    return out


def _finite_array(value, name):
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {value!r}") from None
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite")
    return arr


def _broadcast(arr, shape, name):
    try:
        return np.broadcast_to(arr, shape)
    except ValueError:
        raise ValueError(f"{name} of shape {arr.shape} does not broadcast to the balls' "
                         f"shape {shape}") from None


# --------------------------------------------------------------------------------------------
# Ball-ball contact (NumPy, vectorised): the kinematics of ball_contact_slip's Notes
# --------------------------------------------------------------------------------------------
def ball_contact_slip(angular_velocity, neighbour_angular_velocity, ball_radius, side="front"):
    """Slip velocity of a ball over its neighbour at their contact point.

    s = (Omega + Omega') x (sign R_B z), sign = +1 for the front neighbour, -1 for the back
    one (Notes). The translations are along the line of centres and do not slip.

    Parameters
    ----------
    angular_velocity, neighbour_angular_velocity : array_like, shape (..., 3)
        Omega of the ball and of its neighbour [rad/s].
    ball_radius : float
        R_B [m].
    side : {"front", "back"}
        Where the neighbour is.

    Returns
    -------
    ndarray, shape (..., 3)
        s [m/s], perpendicular to z.

    Notes
    -----
    **Kinematics of a ball-ball contact (from Eqs. 1-9)**

    The balls of a track lie on one line of centres parallel to z (the pitch line of Fig. 1). A
    ball touches its front neighbour at C = +R_B z from its own centre and its back neighbour at
    -R_B z. Each ball moves rigidly, v_B z + Omega x r (Eq. 4), so at C

    * the ball's material point moves at v_B z + Omega x (R_B z) = v_B z + R_B (w_y, -w_x, 0);
    * the front neighbour's moves at v_B' z + Omega' x (-R_B z) = v_B' z + R_B (-w_y', w_x', 0).

    The z components are the normal approach v_B - v_B', zero while the balls stay in contact.
    The tangential slip of the ball over its neighbour is

        s = (Omega + Omega') x (R_B z) = R_B (w_y + w_y', -(w_x + w_x'), 0),

    perpendicular to z and to the sum of the rolling axes. Both balls roll the same way (w_x > 0
    for the top groove moving at +v: Omega_0 = (v / (2 R_B cos beta_0), 0, 0)), so the front
    face of the ball goes down (-y) while the back face of its neighbour goes up (+y): the
    surfaces slide past each other at the *sum* of their surface speeds,
    |s| = R_B |Omega_perp + Omega'_perp| = R_B (|Omega_perp| + |Omega'_perp|) for parallel axes
    (Omega_perp = (w_x, w_y), the part that moves C; w_z does not). Nominal rolling:
    |s| = 2 R_B w_x = v / cos(beta_0) = 1.414 v at 45 deg. At the back contact the same holds with
    C = -R_B z, and the slip of the ball over the back neighbour is (Omega + Omega'') x (-R_B z).
    """
    sign = CONTACT_SIDES[side]
    w = np.asarray(angular_velocity, dtype=float) + np.asarray(neighbour_angular_velocity,
                                                                dtype=float)
    return np.cross(w, np.array([0.0, 0.0, sign * ball_radius]))


def ball_contact_friction(angular_velocity, neighbour_angular_velocity, contact_force,
                          ball_radius, ball_friction=DEFAULT_BALL_FRICTION, side="front"):
    """Coulomb friction of a ball-ball contact on the ball: force, moment and contact power.

    Parameters
    ----------
    angular_velocity, neighbour_angular_velocity : array_like, shape (..., 3)
        Omega of the ball and of its neighbour [rad/s].
    contact_force : array_like, shape (...)
        Q >= 0, the normal force of the contact [N].
    ball_radius : float
        R_B [m].
    ball_friction : float
        mu_bb [-].
    side : {"front", "back"}
        Where the neighbour is.

    Returns
    -------
    force : ndarray, shape (..., 3)
        Friction force on the ball [N], -mu_bb Q s / |s| (zero where s = 0).
    moment : ndarray, shape (..., 3)
        Its moment about the ball centre [N m]; the neighbour gets the same moment.
    power : ndarray, shape (...)
        Power dissipated in the contact, mu_bb Q |s| [W].

    Notes
    -----
    **Coulomb friction, direction and moment**

    The friction on the ball at C opposes its slip: f_C = -mu_bb Q s / |s|. For rolling about +x
    it points along +y (up) at the front contact and along -y (down) at the back contact: the
    pair of tangential forces lies along the module's y axis, which is the axis perpendicular to
    both z and the rolling axis (for a rolling axis tilted in the x-y plane, the axis
    perpendicular to both). Its moment about the ball centre is

        (R_B z) x f_C = -mu_bb Q R_B z x (W x z) / |W_perp| = -mu_bb Q R_B W_perp / |W_perp|,

    with W = Omega + Omega' (z x (W x z) = W_perp). It points against the rolling axis: it
    *brakes* the ball's rotation, and (at the back contact, arm -R_B z and slip of opposite
    sign) it has the same sign there. The neighbour receives -f_C at arm -R_B z, the same moment:
    ball-ball friction brakes both balls. It has no z component (the force is perpendicular to z)
    and no moment about z (the arm is along z), so the z force row and the omega_z row of the
    equilibrium are unchanged.

    One ball (this module's model): the neighbours roll about parallel axes (their Omega differ
    by O(epsilon, dbeta), a relative 1e-2), so W_perp / |W_perp| = Omega_perp / |Omega_perp| and
    the neighbours' total braking moment is

        M_bb = -mu_bb (Q_back + Q_front) R_B Omega_perp / |Omega_perp|.

    The resultant of the two tangential forces, mu_bb (Q_front - Q_back) along +y for rolling
    about +x, lies in the cross-section; like every load of the cross-section it is carried by the
    normal forces F_i, which are inputs of the velocity models (from the static contact). It
    changes them by O(mu_bb |P|) and epsilon by second order; it is neglected. The normal forces
    Q pass through the centre (z, no moment): the push P = Q_back - Q_front along +z.
    """
    slip = ball_contact_slip(angular_velocity, neighbour_angular_velocity, ball_radius, side)
    q = np.asarray(contact_force, dtype=float)
    speed = np.linalg.norm(slip, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = np.where(speed[..., None] > 0, slip / speed[..., None], 0.0)
    force = -(ball_friction * q)[..., None] * unit
    arm = np.array([0.0, 0.0, CONTACT_SIDES[side] * ball_radius])
    return force, np.cross(arm, force), ball_friction * q * speed


# --------------------------------------------------------------------------------------------
# Kernels shared by the velocity models (R_B = 1 units, no checks)
# --------------------------------------------------------------------------------------------
#: The side signs as tuples (Numba reads module-level tuples as compile-time constants).
SIDE_SIGN_X_T = tuple(float(s) for s in SIDE_SIGN_X)
SIDE_SIGN_Y_T = tuple(float(s) for s in SIDE_SIGN_Y)


@jit
def rolling_axis(beta, force):
    """Unit rolling axis (e_x, e_y) of rigid rolling at the loaded contact centres.

    Least squares over the contacts with F_i > 0 of v_B + w_x p_y - w_y p_x = V_i (R = 1,
    v = 1; V = 0 bottom, 1 top), p_i the unit vector to contact i. (1, 0) for a symmetric
    ball; tilted by O(dbeta) otherwise. Returns (1, 0) if the system is singular.
    """
    ata = np.zeros((3, 3))
    atb = np.zeros(3)
    for i in range(4):
        if force[i] > 0.0:
            px = SIDE_SIGN_X_T[i] * np.sin(beta[i])
            py = SIDE_SIGN_Y_T[i] * np.cos(beta[i])
            row = (1.0, py, -px)
            target = 1.0 if i >= 2 else 0.0
            for r in range(3):
                atb[r] += row[r] * target
                for c in range(3):
                    ata[r, c] += row[r] * row[c]
    det = (ata[0, 0] * (ata[1, 1] * ata[2, 2] - ata[1, 2] * ata[2, 1])
           - ata[0, 1] * (ata[1, 0] * ata[2, 2] - ata[1, 2] * ata[2, 0])
           + ata[0, 2] * (ata[1, 0] * ata[2, 1] - ata[1, 1] * ata[2, 0]))
    if not (abs(det) > 1e-300):
        return 1.0, 0.0
    # Cramer for w_x (column 1) and w_y (column 2)
    wx = (ata[0, 0] * (atb[1] * ata[2, 2] - ata[1, 2] * atb[2])
          - atb[0] * (ata[1, 0] * ata[2, 2] - ata[1, 2] * ata[2, 0])
          + ata[0, 2] * (ata[1, 0] * atb[2] - atb[1] * ata[2, 0])) / det
    wy = (ata[0, 0] * (ata[1, 1] * atb[2] - atb[1] * ata[2, 1])
          - ata[0, 1] * (ata[1, 0] * atb[2] - atb[1] * ata[2, 0])
          + atb[0] * (ata[1, 0] * ata[2, 1] - ata[1, 1] * ata[2, 0])) / det
    norm = np.hypot(wx, wy)
    if not norm > 0.0:
        return 1.0, 0.0
    return wx / norm, wy / norm


@jit
def point_traction_capacity(beta, force, braking, axis_x, axis_y):
    """Traction capacity of a rigid ball with point contacts, over mu [N].

    Minimises Phi_0(w) = sum_i F_i |1 + w_x p_y,i - w_y p_x,i| + B |e . w| over w = Omega R / v_B
    (the ball sliding at unit speed between fixed grooves; Notes of :class:`BallLoadFields`), with
    the braking B = (mu_bb / mu)(Q_back + Q_front) about the axis e = (axis_x, axis_y). Phi_0 is
    convex, piecewise linear and coercive, so its minimum lies on a vertex of the lines 1 + a_i . w
    = 0 (a_i = (p_y, -p_x)) and e . w = 0: all pairs are tried, with w = 0.

    Returns
    -------
    capacity : float
        min Phi_0 (multiply by mu for N).
    w_x, w_y : float
        The minimiser.
    """
    ax = np.empty(5)
    ay = np.empty(5)
    rhs = np.empty(5)
    for i in range(4):
        px = SIDE_SIGN_X_T[i] * np.sin(beta[i])
        py = SIDE_SIGN_Y_T[i] * np.cos(beta[i])
        ax[i] = py
        ay[i] = -px
        rhs[i] = -1.0
    ax[4] = axis_x
    ay[4] = axis_y
    rhs[4] = 0.0
    best = 0.0
    for i in range(4):
        best += force[i]
    best_x = 0.0
    best_y = 0.0
    for i in range(5):
        for j in range(i + 1, 5):
            det = ax[i] * ay[j] - ay[i] * ax[j]
            if abs(det) < 1e-12:
                continue
            wx = (rhs[i] * ay[j] - ay[i] * rhs[j]) / det
            wy = (ax[i] * rhs[j] - rhs[i] * ax[j]) / det
            val = braking * abs(axis_x * wx + axis_y * wy)
            for k in range(4):
                val += force[k] * abs(1.0 + ax[k] * wx + ay[k] * wy)
            if val < best:
                best = val
                best_x = wx
                best_y = wy
    return best, best_x, best_y


@jit
def stall_moment(beta, force):
    """|sum_bottom F_i x_i - sum_top F_i x_i| [N R_B]: M_stall / (mu R_B), BallLoadFields Notes.

    The moment of the friction of both grooves on a ball that does not rotate and slides on
    both (x_i = (-p_y, p_x) the local x axis of contact i).
    """
    mx = 0.0
    my = 0.0
    for i in range(4):
        sign = 1.0 if i < 2 else -1.0
        mx -= sign * force[i] * SIDE_SIGN_Y_T[i] * np.cos(beta[i])
        my += sign * force[i] * SIDE_SIGN_X_T[i] * np.sin(beta[i])
    return np.hypot(mx, my)
