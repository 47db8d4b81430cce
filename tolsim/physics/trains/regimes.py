"""The creep coefficients of a ball in a train from its own regime (issue 25, item 3).

A ball in regime A creeps (finite K); a ball in regime B is stiff (K from its stick line,
3e4 N and more); an exactly two-point ball is an *anchor* (K = inf: it keeps its speed under
a push until its capacity); an unloaded ball is *pushed along* (K = 0: no epsilon of its
own). :func:`regime_creep_coefficients` overrides the creep model's columns for those and
adds each ball's rolling angular velocity; a three-point ball creeps with the coefficients of
its own minimum of D (:func:`three_point_coefficients`); :func:`pair_braking` gives the
ball-ball friction of a pair from the two balls' actual rotations. The cluster rule with
anchors is in the Notes of :func:`tolsim.physics.trains.cluster_velocities`.
"""

import numpy as np
from numba import prange

from tolsim._jit import pjit
from tolsim.physics.geometry import SIDE_SIGN_X, SIDE_SIGN_Y, TABLE1, Bearing
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity._full_kernels import ball_loads_kernel
from tolsim.physics.velocity.analytic import LOAD_COLUMNS
from tolsim.physics.velocity.ball_loads import (
    ball_contact_slip,
    point_traction_capacity,
    stall_moment,
)
from tolsim.physics.velocity.full import (
    DEFAULT_ANGULAR_NODES,
    DEFAULT_RADIAL_NODES,
    full,
    quadrature_grid,
)
from tolsim.physics.velocity.models import (
    BALL_REGIME_B,
    BALL_THREE_POINT,
    BALL_TWO_POINT,
    BALL_UNLOADED,
)

#: Columns of a train's per-ball coefficients: those of the creep model
#: (:data:`tolsim.physics.velocity.analytic.LOAD_COLUMNS`), then the ball's rolling angular
#: velocity Omega_perp R_B / v (x and y; NaN where no ball of the batch needs it), its
#: regime (:data:`tolsim.physics.velocity.models.BALL_REGIMES`; NaN: regime A only) and its
#: braking vector gamma [1/N] (x and y, NaN as the rates): d(epsilon)/dQ of a neighbour force Q
#: whose friction moment lies along the unit vector u is gamma . u (Notes of
#: :func:`directional_braking`).
TRAIN_COLUMNS = (*LOAD_COLUMNS, "rolling_rate_x", "rolling_rate_y", "regime",
                 "braking_vector_x", "braking_vector_y")
#: Creep stiffness of an anchor and of a ball pushed along [N].
ANCHOR_STIFFNESS, PUSHED_STIFFNESS = np.inf, 0.0
#: Step along the stick line for its curvature, a fraction of v.
STICK_STEP = 1e-5

_COL = {name: k for k, name in enumerate(TRAIN_COLUMNS)}


def _contact_directions(contact_angle_deviation, bearing):
    """p_i = (sx sin beta_i, sy cos beta_i), shape (n, 4, 2)."""
    beta = bearing.nominal_contact_angle + np.asarray(contact_angle_deviation, dtype=float)
    return np.stack([SIDE_SIGN_X * np.sin(beta), SIDE_SIGN_Y * np.cos(beta)], axis=-1)


def rigid_rolling_rate(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """Omega_perp R_B / v of rigid rolling at the loaded contact centres (least squares).

    The rows v_B + w_x p_y - w_y p_x = V_i (V = 0 bottom, 1 top; R_B = v = 1) over the
    contacts with F_i > 0, as :func:`tolsim.physics.velocity.ball_loads.rolling_axis` but
    keeping the rate: (1 / (2 cos beta_0), 0) for the nominal ball. NaN where the rows do not
    fix (w_x, w_y) (fewer than three loaded contacts).

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)

    Returns
    -------
    ndarray, shape (n, 2)
    """
    p = _contact_directions(contact_angle_deviation, bearing)
    on = (np.asarray(normal_force, dtype=float) > 0.0)[..., None]
    rows = np.concatenate([np.ones(p.shape[:-1] + (1,)), p[..., 1:2], -p[..., 0:1]], axis=-1)
    rows = rows * on
    target = np.array([0.0, 0.0, 1.0, 1.0])[None, :, None] * on
    ata = np.einsum("nki,nkj->nij", rows, rows)
    atb = np.einsum("nki,nk->ni", rows, target[..., 0])
    out = np.full((len(p), 2), np.nan)
    good = np.abs(np.linalg.det(ata)) > 1e-12
    if good.any():
        out[good] = np.linalg.solve(ata[good], atb[good][..., None])[:, 1:, 0]
    return out


def two_point_rolling_rate(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """Omega R_B / v = (p_t,y, -p_t,x) / 2 of an exactly two-point ball (issue 25).

    p_t the direction to its loaded top contact: (cos beta, -sin beta) / 2 on the diagonal
    BL-TR, (cos beta, sin beta) / 2 on BR-TL. Both contacts stick, Omega . p = 0 (no spin),
    and the top contact moves at v: v_B + R (Omega x p_t)_z = v with v_B = v / 2.

    Returns
    -------
    ndarray, shape (n, 2)
    """
    p = _contact_directions(contact_angle_deviation, bearing)
    force = np.asarray(normal_force, dtype=float)
    top = np.where(force[:, 2] > 0.0, 2, 3)
    pt = p[np.arange(len(p)), top]
    return 0.5 * np.stack([pt[:, 1], -pt[:, 0]], axis=-1)


@pjit
def stick_line_stiffness_kernel(beta, force, stuck, rate, a, b, cin, sin_, win, xo, wo, tr, wr,
                                step, out):
    """K = (v / 2) d^2 D_others / dw^2 [N / mu] on the stick line of each ball; unchecked.

    ``beta``, ``force`` (n, 4), ``stuck`` (n,) the stuck contact k (else inf: both contacts of
    a pair stick, rigid), ``rate`` (n,) w [v] at the minimum, ``a``, ``b`` (n, 4) the
    semi-axes [R]. Central difference of the line slope dD/dw = -(F_z + M . x_k) (the loads
    of the other contacts, R = v = mu = 1) over w +- ``step``.
    """
    for n in prange(beta.shape[0]):
        k = stuck[n]
        if k < 0 or k > 3:
            out[n] = np.inf
            continue
        px = np.empty(4)
        py = np.empty(4)
        others = np.empty(4)
        for i in range(4):
            px[i] = (-1.0 if i == 0 or i == 3 else 1.0) * np.sin(beta[n, i])
            py[i] = (-1.0 if i < 2 else 1.0) * np.cos(beta[n, i])
            others[i] = force[n, i] if i != k else 0.0
        vgroove = np.array([0.0, 0.0, 1.0, 1.0])
        xx, xy = -py[k], px[k]
        state = np.empty(4)
        loads = np.empty(5)
        contact = np.empty((4, 5))
        zero = np.zeros(4)
        slope = np.empty(2)
        for side in range(2):
            w = rate[n] + (step if side else -step)
            state[0] = vgroove[k] + w
            state[1] = w * xx
            state[2] = w * xy
            state[3] = 0.0
            ball_loads_kernel(state, px, py, vgroove, others, a[n], b[n], 1.5 / np.pi, False,
                              1.0, zero, cin, sin_, win, xo, wo, tr, wr, loads, contact)
            slope[side] = -(loads[0] + loads[1] * xx + loads[2] * xy)
        out[n] = 0.25 * (slope[1] - slope[0]) / step


def stick_line_stiffness(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """Creep stiffness K [N] of balls in regime B: the curvature of D on their stick line.

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)

    Returns
    -------
    k : ndarray (n,)
        K [N]; inf where both contacts of a pair stick (rigid), NaN where ``full`` does not
        certify the ball in regime B.
    result : tolsim.physics.velocity.full.FullResult
        The free solve (epsilon, F_0, Omega).

    Notes
    -----
    On the stick line of contact k the states are v_B = V_k + w, Omega = (w / R) x_k, and a
    push P moves the minimum of D_others(w) - P v_B to dD_others/dw = P; with
    epsilon = 2 v_B / v - 1, K = dP/d(epsilon) = (v / 2) d^2 D_others / dw^2, by central
    differences of the line slope (``STICK_STEP`` v; D_others is smooth there: the other
    contacts slip). 3-5e4 N against 110-750 N in regime A (issue 25).
    """
    dbeta = np.ascontiguousarray(contact_angle_deviation, dtype=np.float64).reshape(-1, 4)
    force = np.ascontiguousarray(normal_force, dtype=np.float64).reshape(-1, 4)
    v = 0.01
    res = full(dbeta, force, bearing, groove_velocity=v)
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    radius = bearing.ball_radius
    beta = bearing.nominal_contact_angle + dbeta
    a = hc.semi_major_coefficient * np.cbrt(force) / radius
    b = hc.semi_minor_coefficient * np.cbrt(force) / radius
    stuck = np.asarray(res.stuck_contact, dtype=np.int64)
    p = _contact_directions(dbeta, bearing)
    k = np.clip(stuck, 0, 3)
    xk = np.stack([-p[np.arange(len(p)), k, 1], p[np.arange(len(p)), k, 0]], axis=-1)
    rate = np.sum(res.angular_velocity[:, :2] * radius / v * xk, axis=1)
    out = np.empty(len(dbeta))
    grid = quadrature_grid(DEFAULT_ANGULAR_NODES, DEFAULT_RADIAL_NODES, hc.ellipticity)
    stick_line_stiffness_kernel(beta, force, stuck, np.ascontiguousarray(rate), a, b, *grid,
                                STICK_STEP, out)
    out = bearing.friction_coefficient * out
    return np.where(np.asarray(res.regime) == 2, out, np.nan), res


@pjit
def minimum_compliance_kernel(beta, force, state, a, b, cin, sin_, win, xo, wo, tr, wr, step,
                              out):
    """The v_B row of H^-1 [1 / N] at a smooth minimum of D; unchecked.

    ``state`` (n, 3): (v_B, Omega_x R, Omega_y R) / v at the minimum; H the Hessian of D over
    them by central differences of its gradient -(F_z, M_x, M_y) (R = v = mu = 1) over
    +- ``step``, symmetrised; ``out`` (n, 3) its inverse's first row ((H^-1)_vv, (H^-1)_vx,
    (H^-1)_vy), NaN where H is singular.
    """
    for n in prange(beta.shape[0]):
        px = np.empty(4)
        py = np.empty(4)
        for i in range(4):
            px[i] = (-1.0 if i == 0 or i == 3 else 1.0) * np.sin(beta[n, i])
            py[i] = (-1.0 if i < 2 else 1.0) * np.cos(beta[n, i])
        vgroove = np.array([0.0, 0.0, 1.0, 1.0])
        x = np.empty(4)
        loads = np.empty(5)
        contact = np.empty((4, 5))
        zero = np.zeros(4)
        h = np.empty((3, 3))
        for j in range(3):
            for side in range(2):
                for i in range(3):
                    x[i] = state[n, i]
                x[3] = 0.0
                x[j] += step if side else -step
                ball_loads_kernel(x, px, py, vgroove, force[n], a[n], b[n], 1.5 / np.pi, False,
                                  1.0, zero, cin, sin_, win, xo, wo, tr, wr, loads, contact)
                sign = 1.0 if side else -1.0
                for i in range(3):
                    if side == 0:
                        h[i, j] = 0.0
                    h[i, j] -= sign * loads[i] / (2.0 * step)
        for i in range(3):
            for j in range(i + 1, 3):
                m = 0.5 * (h[i, j] + h[j, i])
                h[i, j] = m
                h[j, i] = m
        # the first row of the adjugate over det(H)
        c0 = h[1, 1] * h[2, 2] - h[1, 2] * h[2, 1]
        c1 = h[0, 2] * h[2, 1] - h[0, 1] * h[2, 2]
        c2 = h[0, 1] * h[1, 2] - h[0, 2] * h[1, 1]
        det = h[0, 0] * c0 + h[1, 0] * c1 + h[2, 0] * c2
        for i in range(3):
            out[n, i] = np.nan
        if det != 0.0 and np.isfinite(det):
            out[n, 0] = c0 / det
            out[n, 1] = c1 / det
            out[n, 2] = c2 / det


@pjit
def point_capacity_kernel(beta, force, out):
    """(min Phi_0, M_stall / (mu R_B)) of point contacts per ball [N / mu]; unchecked.

    :func:`tolsim.physics.velocity.ball_loads.point_traction_capacity` without braking and
    :func:`tolsim.physics.velocity.ball_loads.stall_moment`, the creep model's capacities
    (:func:`tolsim.physics.velocity.analytic.creep_coefficients_kernel`), for any number of
    loaded contacts (an open contact has F = 0 and drops out of both).
    """
    for n in prange(beta.shape[0]):
        out[n, 0] = point_traction_capacity(beta[n], force[n], 0.0, 1.0, 0.0)[0]
        out[n, 1] = stall_moment(beta[n], force[n])


def _three_point_solve(dbeta, force, bearing):
    """The free solve of three-point balls and what their coefficients need.

    Returns (K on the stick line, FullResult, the v_B row of H^-1 at a smooth minimum [1/N,
    over mu], the state (v_B, Omega_x R, Omega_y R) / v); see :func:`three_point_stiffness`.
    """
    stick, res = stick_line_stiffness(dbeta, force, bearing)
    v = 0.01
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    beta = bearing.nominal_contact_angle + dbeta
    a = hc.semi_major_coefficient * np.cbrt(force) / bearing.ball_radius
    b = hc.semi_minor_coefficient * np.cbrt(force) / bearing.ball_radius
    state = np.empty((len(dbeta), 3))
    state[:, 0] = 0.5 * (1.0 + np.asarray(res.velocity_deviation))
    state[:, 1:] = np.asarray(res.angular_velocity)[:, :2] * bearing.ball_radius / v
    grid = quadrature_grid(DEFAULT_ANGULAR_NODES, DEFAULT_RADIAL_NODES, hc.ellipticity)
    row = np.empty((len(dbeta), 3))
    minimum_compliance_kernel(beta, force, np.ascontiguousarray(state), a, b, *grid,
                              STICK_STEP, row)
    return stick, res, row, state


def three_point_stiffness(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """Creep stiffness K [N] of three-point balls from their own minimum of D (issue 25).

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)
        One force 0 (the open contact).

    Returns
    -------
    k : ndarray (n,)
        K [N]; NaN where ``full`` does not certify the ball.
    result : tolsim.physics.velocity.full.FullResult
        The free solve (epsilon, F_0, Omega).

    Notes
    -----
    A push P moves the minimum of D(x) - P v_B, x = (v_B, Omega_x, Omega_y), to
    grad D = P e_v. Where the three contacts slip the minimum is smooth, dx/dP = H^-1 e_v with
    H the Hessian of D there, so dv_B / dP = (H^-1)_vv and, with epsilon = 2 v_B / v - 1,

        K = dP/d(epsilon) = (v / 2) / (H^-1)_vv = (v / 2) (H_vv - H_vw H_ww^-1 H_wv)   (R2)

    the curvature of D along v_B with the rotation at its best (the Schur complement); H by
    central differences of the loads of :func:`tolsim.physics.velocity._full_kernels.
    ball_loads_kernel` (``STICK_STEP`` v). Where a heavy contact sticks (``full``'s stick
    regime) the minimum sits on the stick line and K is regime B's, (v / 2) D''_others on
    it (:func:`stick_line_stiffness`). (R2) is regime B's (R1) with the rotation free instead
    of held on the stick line; for a four-point ball in regime A it is the creep stiffness of
    the exact model. The other coefficients of such a ball are those of
    :func:`three_point_coefficients`.
    """
    dbeta = np.ascontiguousarray(contact_angle_deviation, dtype=np.float64).reshape(-1, 4)
    force = np.ascontiguousarray(normal_force, dtype=np.float64).reshape(-1, 4)
    stick, res, row, _ = _three_point_solve(dbeta, force, bearing)
    smooth = bearing.friction_coefficient * 0.5 / row[:, 0]
    code = np.asarray(res.regime)
    return np.where(code == 2, stick, np.where(code == 1, smooth, np.nan)), res


def three_point_coefficients(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1,
                             *, ball_friction=0.1):
    """The creep coefficients of three-point balls from their own minimum of D (issue 25).

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)
        dbeta_i [rad], F_i [N]; one force 0 (the open contact).
    bearing : Bearing
    ball_friction : float
        mu_bb [-].

    Returns
    -------
    columns : dict of str to ndarray (n,)
        The :data:`tolsim.physics.velocity.analytic.LOAD_COLUMNS` at zero load (K [N], c
        [1/N], F_0 [N], a, b [-], P_cap, S_cap [N]) and the braking vector gamma
        (``braking_vector_x``, ``_y`` [1/N], c = gamma . Omega_perp / |Omega_perp|); NaN
        where ``full`` does not certify the ball.
    rate : ndarray, shape (n, 2)
        Omega_perp R_B / v of its minimum (its actual rotation).

    Notes
    -----
    **The ball under loads.** With neighbour forces Q_back, Q_front (push P = Q_back - Q_front,
    braking sum S = Q_back + Q_front) the state x = (v_B, Omega_x, Omega_y) minimises

        Phi(x; P, S) = D(x) + mu_bb S R_B |Omega_perp| - P v_B,                       (T1)

    D less the work of the push plus the ball-ball friction's dissipation, whose moment
    -mu_bb S R_B Omega_perp / |Omega_perp| lies along the ball's own axis (Notes of
    :class:`tolsim.physics.velocity.ball_loads.BallLoadFields`); D is that of the three loaded
    contacts (the open one carries nothing). Every coefficient is a derivative of the minimiser
    x*(P, S) or of the minimum Phi*(P, S) at P = S = 0:

    * **epsilon, F_0**: those of the free minimum (:func:`tolsim.physics.velocity.full.full`,
      certified: smooth, or on a stick line).
    * **K and c.** At a smooth minimum (all three contacts slip) grad Phi = 0 gives
      H dx = e_v dP - mu_bb R_B g dS with g = (0, Omega_perp / |Omega_perp|), so

          K = (v / 2) / (H^-1)_vv,   c = d(epsilon)/dS = -(2 / v) mu_bb R_B (H^-1 g)_v   (T2)

      (R2 of :func:`three_point_stiffness`; H by central differences, ``STICK_STEP``), and
      for a moment along any unit u the braking vector gamma = -(2 / v) mu_bb R_B
      ((H^-1)_vx, (H^-1)_vy), c = gamma . g (:func:`directional_braking`). On a stick line
      (one contact stuck) K is the line's and c = -mu_bb / K, as regime B's (R1 in
      :func:`regime_creep_coefficients`), and gamma = c g (only the moment's component
      along the line does work on it).
    * **a and b, exactly.** The power balance v F_c + P v_B = D + mu_bb S R_B |Omega_perp|
      (F_c the carriage force) says v F_c = Phi*(P, S). Phi* is a minimum over x of functions
      affine in (P, S), so (envelope theorem, at a kink too) dPhi*/dP = -v_B and
      dPhi*/dS = mu_bb R_B |Omega_perp| at the minimiser:

          a = dF_c/dP = -v_B / v = -(1 + epsilon) / 2,   b = dF_c/dS = mu_bb R_B |Omega_perp| / v
                                                                                        (T3)

      (-1/2 and mu_bb / 2 for the two-point ball; the creep model of regime A gives (T3) for its
      own state: a = -(1 + epsilon) / 2 to round-off).
    * **The capacities.** Phi is bounded below only while P < lim D / v_B for v_B -> inf, the
      ball sliding between grooves at rest: P_cap = min over Omega of D(v_B = 1, Omega; V = 0)
      (BallLoadFields, "Gross sliding"); the rotation stalls once mu_bb S R_B exceeds the
      moment M_stall of the grooves on a ball that does not rotate, S_cap = M_stall /
      (mu_bb R_B). Both as the creep model takes them for regime A: P_cap from point contacts
      (:func:`tolsim.physics.velocity.ball_loads.point_traction_capacity`, a lower bound by
      Jensen's inequality), M_stall from :func:`tolsim.physics.velocity.ball_loads.stall_moment`,
      over the three loaded contacts (:func:`point_capacity_kernel`).

    Not modelled: a stuck contact letting go under a push before P_cap (the stick line's K
    then gives way to the smooth one), as in regime B.
    """
    dbeta = np.ascontiguousarray(contact_angle_deviation, dtype=np.float64).reshape(-1, 4)
    force = np.ascontiguousarray(normal_force, dtype=np.float64).reshape(-1, 4)
    stick, res, row, state = _three_point_solve(dbeta, force, bearing)
    mu = bearing.friction_coefficient
    code = np.asarray(res.regime)
    smooth, stuck = code == 1, code == 2
    spin = np.hypot(state[:, 1], state[:, 2])
    with np.errstate(divide="ignore", invalid="ignore"):
        g = state[:, 1:] / spin[:, None]
        k = np.where(stuck, stick, np.where(smooth, 0.5 * mu / row[:, 0], np.nan))
        gamma = np.where(stuck[:, None], (-ball_friction / k)[:, None] * g,
                         -2.0 * ball_friction / mu * row[:, 1:])
        c = np.where(stuck, -ball_friction / k, np.sum(gamma * g, axis=1))
    capacity = np.empty((len(dbeta), 2))
    point_capacity_kernel(bearing.nominal_contact_angle + dbeta, force, capacity)
    with np.errstate(divide="ignore"):
        braking_capacity = (mu * capacity[:, 1] / ball_friction if ball_friction > 0
                            else np.full(len(dbeta), np.inf))
    eps = np.asarray(res.velocity_deviation, dtype=np.float64)
    drag = np.asarray(res.drag_force, dtype=np.float64)
    columns = {"free_rolling_velocity_deviation": eps, "creep_stiffness": k,
               "braking_sensitivity": c, "carriage_force": drag,
               "free_rolling_carriage_force": drag,
               "carriage_force_per_push": -0.5 * (1.0 + eps),
               "carriage_force_per_neighbour_force": ball_friction * spin,
               "traction_capacity": mu * capacity[:, 0],
               "braking_capacity": braking_capacity,
               "braking_vector_x": gamma[:, 0], "braking_vector_y": gamma[:, 1]}
    solved = smooth | stuck
    columns = {name: np.where(solved, value, np.nan) for name, value in columns.items()}
    rate = np.where(solved[:, None], state[:, 1:], np.nan)
    return columns, rate


def regime_creep_coefficients(load, regime, contact_angle_deviation, normal_force,
                              bearing: Bearing = TABLE1, *, ball_friction=0.1):
    """The train columns of balls from their regimes: anchors, soft balls, pushed balls.

    Parameters
    ----------
    load : ndarray, shape (n, len(LOAD_COLUMNS))
        The creep model's columns (regime A), NaN where it has none.
    regime : array_like of int, shape (n,)
        :data:`tolsim.physics.velocity.models.BALL_REGIMES` codes.
    contact_angle_deviation, normal_force : array_like, shape (n, 4)
        dbeta_i [rad], F_i [N].
    bearing : Bearing
    ball_friction : float
        mu_bb [-].

    Returns
    -------
    ndarray, shape (n, len(TRAIN_COLUMNS))
        ``load`` unchanged for every ball in regime A (bit for bit), the columns of the Notes
        for the others, and the rolling rates and regimes when the batch holds any.

    Notes
    -----
    **An exactly two-point ball** (both contacts stick, rolling at v / 2 with D = 0;
    :func:`tolsim.physics.velocity.regimes.two_point_loaded`). Under a push P and a
    neighbour-force sum S its force row f_b + f_t + P = 0 and its moment about the rolling
    axis -R (f_b - f_t) - mu_bb S R = 0 give F_c = f_t = (mu_bb S - P) / 2, and epsilon stays
    0 while |P| + mu_bb S <= 2 mu F. So its columns are exact: epsilon_free = 0, K = inf,
    c = 0, F_0 = 0, a = dF_c/dP = -1/2, b = dF_c/dS = mu_bb / 2, and the capacities
    P_cap = 2 mu F, S_cap = 2 mu F / mu_bb, between which the rolling range is the *line*
    |P| / P_cap + S / S_cap < 1 (the sliding check of an anchor in
    :mod:`tolsim.study.pipeline.track_friction`). F = the smaller of its two forces (they are
    equal in static equilibrium).

    **A ball in regime B** (one contact k stuck). Its states lie on the stick line
    v_B = V_k + w, Omega = (w / R) x_k; a push moves it along the line to the minimum of
    D_others(w) + mu_bb S |w| - P v_B, so dP - mu_bb dS = D''_others dw, and

        K = (v / 2) D''_others,   c = d(epsilon)/dS = -mu_bb / K                     (R1)

    (:func:`stick_line_stiffness`): 3.3e4 N on case (a) at rho = -0.9 .. -0.98, against
    110-750 N in regime A (issue 25), so it is a stiff ball rather than a rigid anchor: two
    balls in regime B of different epsilon pushed together share a finite force (as rigid
    anchors they could not roll together), and a soft neighbour's force is
    K_s K_B / (K_s + K_B) d(epsilon), 1-2 % below K_s d(epsilon). (Both contacts of a pair
    stuck, equal angles: rigid, K = inf, an anchor.) F_0 and Omega are those of its certified
    minimum of D (:func:`tolsim.physics.velocity.full.full`); a, b and the capacities are
    the creep model's (the loads split between the grooves about as in regime A). Not
    modelled: the push at which the stuck contact lets go before P_cap. It is not
    symmetric and can be small: in case (a) at rho = -0.9 (K = 32 698 N, eps 0.030 %) the
    independent minimiser of D - P v_B (:func:`tolsim.physics.velocity.regimes.
    minimise_dissipation`) keeps the stick for P from -20 N (secant K 32 057 N) to +2 N
    (eps 0.0366 %), and lets it go by +3 N (eps 1.92 %; the least directional slope of
    Phi off the stick line, from its exact line minimum, falls from 0.070 N at P = 0 to
    0.0004 N at 3 N); at rho = -0.95 it holds from -43 N to +30 N and has let go by +38 N
    (eps 7.8 %). Beyond it the ball leaves the stick line for the other branch (regime A's
    larger epsilon), which a linear K cannot follow; the trains keep K_B up to P_cap.

    **A three-point ball** (one contact open) creeps with the coefficients of its own minimum
    of D (:func:`three_point_coefficients`): K and c from the Hessian there (smooth) or from
    its stick line (one contact stuck), a = -(1 + epsilon) / 2 and b = mu_bb R_B
    |Omega_perp| / v exactly (envelope theorem), the capacities of its three loaded contacts,
    and its actual rotation.

    **The braking vector** gamma (:func:`directional_braking`): c Omega_perp / |Omega_perp|
    in regime A (the creep model gives the response to a moment along the ball's own axis
    only; the rest, the response to a tilt of the moment, is O(dbeta) and vanishes for a
    mirror-symmetric ball, whose v_B is even in the tilt) and in regime B (exact on the stick
    line), the full vector of (T2) for a three-point ball, 0 for an anchor or a pushed ball.

    **An unloaded ball** has no raceway contact, so no raceway friction: F_c = 0 whatever the
    loads (F_0 = a = b = 0), no creep resistance (K = 0: it moves with whatever it touches,
    a null weight in the cluster rule) and nothing to slide on (capacities inf).
    """
    load = np.asarray(load, dtype=np.float64)
    n = len(load)
    regime = np.asarray(regime).reshape(n)
    out = np.full((n, len(TRAIN_COLUMNS)), np.nan)
    out[:, :len(LOAD_COLUMNS)] = load
    two = regime == BALL_TWO_POINT
    stick = regime == BALL_REGIME_B
    three = regime == BALL_THREE_POINT
    pushed = regime == BALL_UNLOADED
    if not (two.any() or stick.any() or three.any() or pushed.any()):
        return out
    dbeta = np.asarray(contact_angle_deviation, dtype=np.float64).reshape(n, 4)
    force = np.asarray(normal_force, dtype=np.float64).reshape(n, 4)
    mu = bearing.friction_coefficient
    rate = np.full((n, 2), np.nan)
    gamma = np.zeros((n, 2))
    soft = ~(two | stick | three | pushed)
    if soft.any():
        rate[soft] = rigid_rolling_rate(dbeta[soft], force[soft], bearing)
    if two.any():
        loaded = np.where(force[two] > 0.0, force[two], np.inf).min(axis=1)
        capacity = 2.0 * mu * loaded
        with np.errstate(divide="ignore"):
            braking_capacity = (capacity / ball_friction if ball_friction > 0
                                else np.full(len(capacity), np.inf))
        values = {"free_rolling_velocity_deviation": 0.0, "creep_stiffness": ANCHOR_STIFFNESS,
                  "braking_sensitivity": 0.0, "carriage_force": 0.0,
                  "free_rolling_carriage_force": 0.0, "carriage_force_per_push": -0.5,
                  "carriage_force_per_neighbour_force": 0.5 * ball_friction,
                  "traction_capacity": capacity, "braking_capacity": braking_capacity}
        for name, value in values.items():
            out[two, _COL[name]] = value
        rate[two] = two_point_rolling_rate(dbeta[two], force[two], bearing)
    if stick.any():
        stiffness, res = stick_line_stiffness(dbeta[stick], force[stick], bearing)
        rows = np.flatnonzero(stick)
        out[rows, _COL["creep_stiffness"]] = stiffness
        with np.errstate(divide="ignore", invalid="ignore"):
            out[rows, _COL["braking_sensitivity"]] = np.where(np.isfinite(stiffness),
                                                              -ball_friction / stiffness, 0.0)
        out[rows, _COL["free_rolling_velocity_deviation"]] = res.velocity_deviation
        out[rows, _COL["free_rolling_carriage_force"]] = res.drag_force
        out[rows, _COL["carriage_force"]] = res.drag_force
        rate[stick] = res.angular_velocity[:, :2] * bearing.ball_radius / 0.01
    if three.any():
        columns, rate[three] = three_point_coefficients(dbeta[three], force[three], bearing,
                                                        ball_friction=ball_friction)
        for name, value in columns.items():
            out[three, _COL[name]] = value
        gamma[three] = out[three, _COL["braking_vector_x"]:]
    if pushed.any():
        values = {"free_rolling_velocity_deviation": np.nan, "creep_stiffness": PUSHED_STIFFNESS,
                  "braking_sensitivity": 0.0, "carriage_force": 0.0,
                  "free_rolling_carriage_force": 0.0, "carriage_force_per_push": 0.0,
                  "carriage_force_per_neighbour_force": 0.0, "traction_capacity": np.inf,
                  "braking_capacity": np.inf}
        for name, value in values.items():
            out[pushed, _COL[name]] = value
    out[:, _COL["rolling_rate_x"]:_COL["regime"]] = rate
    out[:, _COL["regime"]] = regime
    # the own-axis response of the creep model (regime A) and of a stick line (regime B)
    axial = soft | stick
    with np.errstate(divide="ignore", invalid="ignore"):
        gamma[axial] = (out[axial, _COL["braking_sensitivity"], None] * rate[axial]
                        / np.hypot(rate[axial, 0], rate[axial, 1])[:, None])
    out[:, _COL["braking_vector_x"]:] = gamma
    return out


def directional_braking(coefficients, stiffness, braking):
    """The train rule's K and c of balls braked along their pairs' actual rotations.

    Parameters
    ----------
    coefficients : ndarray, shape (..., n, len(TRAIN_COLUMNS))
        The train columns of the balls of trains (or of a carriage track's slots).
    stiffness, braking : ndarray, shape (..., n)
        K [N] and c [1/N] of the train rule (NaN K: unusable).

    Returns
    -------
    stiffness, braking : ndarray, shape (..., n)
        The inputs themselves where no pair holds a ball in regime B, three- or two-point
        (regime A unchanged, bit for bit); else K', c' of the Notes for the soft balls of
        such pairs (NaN K', c' = 0 where a compliance is not positive: unusable).

    Notes
    -----
    The friction moment of pair j on each of its balls is -mu_bb Q_j R_B W_hat_j, W_hat_j
    the direction of W_j = Omega_j + Omega_{j+1} (Notes of :func:`pair_braking`), not of the
    ball's own axis. A ball's epsilon responds to a moment along the unit u with gamma . u
    per newton of Q (``braking_vector``; gamma . Omega_hat = c), so ball i rolls at

        w_i = epsilon_i + Q_{i-1} (1 / K_i + c_back) - Q_i (1 / K_i - c_front),
        c_back = gamma_i . W_hat_{i-1},   c_front = gamma_i . W_hat_i,                   (T4)

    instead of eq. (1) of :func:`tolsim.physics.trains.cluster_velocities` with one c. (T4)
    is eq. (1) with

        1 / K' = 1 / K + (c_back - c_front) / 2,   c' = (c_back + c_front) / 2,

    (the same compliances 1/K' + c' = 1/K + c_back to a push from behind and 1/K' - c' =
    1/K - c_front from in front), so the cluster rule and the step projection take (K', c')
    unchanged; they need both compliances positive, |c'| K' < 1. Between two balls in regime
    A, or next to a ball pushed along (whose slip direction the model does not resolve,
    Notes of :func:`pair_braking`), the own-axis c is kept. The issue's example: a
    regime-A ball (0.707 v / R_B about x) in front of a two-point ball (0.5 v / R_B tilted
    by 45 deg) is braked along W_hat = (0.949, -0.316), so c_back = 0.949 c for a
    mirror-symmetric ball, not c.
    """
    stiffness = np.asarray(stiffness, dtype=np.float64)
    braking = np.asarray(braking, dtype=np.float64)
    coefficients = np.asarray(coefficients, dtype=np.float64)
    code = coefficients[..., _COL["regime"]]
    other = (code == BALL_REGIME_B) | (code == BALL_TWO_POINT) | (code == BALL_THREE_POINT)
    pushed = coefficients[..., _COL["creep_stiffness"]] == PUSHED_STIFFNESS
    mixed = (other[..., :-1] | other[..., 1:]) & ~(pushed[..., :-1] | pushed[..., 1:])
    if not mixed.any():
        return stiffness, braking
    rate = coefficients[..., _COL["rolling_rate_x"]:_COL["regime"]]
    w = rate[..., :-1, :] + rate[..., 1:, :]
    norm = np.hypot(w[..., 0], w[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = w / norm[..., None]
    gamma = coefficients[..., _COL["braking_vector_x"]:]
    use = mixed & np.isfinite(norm) & (norm > 0.0)
    c_front = braking.copy()
    c_back = braking.copy()
    with np.errstate(invalid="ignore"):
        front = np.sum(gamma[..., :-1, :] * unit, axis=-1)
        back = np.sum(gamma[..., 1:, :] * unit, axis=-1)
    c_front[..., :-1] = np.where(use, front, braking[..., :-1])
    c_back[..., 1:] = np.where(use, back, braking[..., 1:])
    soft = np.isfinite(stiffness) & (stiffness > 0.0)
    changed = soft & ((c_front != braking) | (c_back != braking))
    if not changed.any():
        return stiffness, braking
    with np.errstate(divide="ignore", invalid="ignore"):
        push_back = 1.0 / stiffness + c_back
        push_front = 1.0 / stiffness - c_front
        k_new = 1.0 / (0.5 * (push_back + push_front))
        c_new = 0.5 * (c_back + c_front)
    usable = (push_back > 0.0) & (push_front > 0.0)
    stiffness = np.where(changed, np.where(usable, k_new, np.nan), stiffness)
    braking = np.where(changed, np.where(usable, c_new, 0.0), braking)
    return stiffness, braking


def pair_braking(coefficients, ball_friction=0.1):
    """The ball-ball friction term of each pair's carriage-friction slope [-].

    Parameters
    ----------
    coefficients : ndarray, shape (..., n, len(TRAIN_COLUMNS))
        The train columns of the balls of trains (or of a carriage track's slots).
    ball_friction : float
        mu_bb [-].

    Returns
    -------
    ndarray, shape (..., n - 1)
        B_j, so that pair j adds k_j Q_j = ((a_{j+1} - a_j) + B_j) Q_j to the carriage
        friction: b_j + b_{j+1} (bit for bit) where both balls are in regime A (four-point,
        every contact slipping),
        mu_bb |Omega_j + Omega_{j+1}|_perp R_B / v where one is not (regime B, three- or
        two-point),
        0 where one is pushed along.

    Notes
    -----
    **Braking from the actual rotations.** The surfaces of a pair slide at the contact with
    s = (Omega_j + Omega_{j+1}) x (R_B z) (:func:`tolsim.physics.velocity.ball_loads.
    ball_contact_slip`), |s| = R_B |W_perp|, W = Omega_j + Omega_{j+1}. The Coulomb force
    mu_bb Q opposes s, so its moment on *each* ball is -mu_bb Q R_B W_perp / |W_perp|: the
    direction of the sum of the rotations, not of the ball's own axis. For the power balance
    of ball i (Notes of :class:`tolsim.physics.velocity.ball_loads.BallLoadFields`,
    v F_c + P v_B = sum D + D_bb, where D at the minimum is stationary in the state) the
    first-order change of v F_c from that moment is its power, mu_bb Q R_B W_hat . Omega_i;
    summed over the two balls, mu_bb Q R_B |W_perp|. So the pair costs the carriage

        B_j = mu_bb R_B |Omega_j + Omega_{j+1}|_perp / v  per newton of Q_j.

    Two nominal balls (parallel axes, 0.707 v / R_B each): 1.414 mu_bb = mu_bb / cos(beta_0),
    the soft balls' b_j + b_{j+1}. A four-point ball (0.707 v / R_B about x) and a two-point
    one (0.5 v / R_B, tilted by 45 deg): |W| R_B = |(1.0607, -0.3536)| v = 1.118 v, not the
    1.207 v of parallel axes (issue 25). Between two soft balls the creep model's b's are kept
    (their axes differ by O(dbeta), and the hard requirement is regime A unchanged to the
    bit).

    **A ball pushed along** turns freely: its moment balance with Q_back = Q_front = Q asks
    W_back_hat = -W_front_hat, met by Omega_u = -(Omega_back + Omega_front) / 2, which leaves
    the run slipping at |Omega_front - Omega_back| R_B / 2 on each side: O(dbeta) between two
    balls of one regime. B = 0 is taken for its pairs (not modelled: a run of two or more
    pushed balls, whose alternating rotations slip at |Omega_a + Omega_b| R_B at one contact).
    """
    coefficients = np.asarray(coefficients, dtype=np.float64)
    b = coefficients[..., _COL["carriage_force_per_neighbour_force"]]
    base = b[..., :-1] + b[..., 1:]
    code = coefficients[..., _COL["regime"]]
    other = (code == BALL_REGIME_B) | (code == BALL_TWO_POINT) | (code == BALL_THREE_POINT)
    pushed = coefficients[..., _COL["creep_stiffness"]] == PUSHED_STIFFNESS
    mixed = other[..., :-1] | other[..., 1:]
    null = pushed[..., :-1] | pushed[..., 1:]
    if not (mixed.any() or null.any()):
        return base
    rate = np.zeros(coefficients.shape[:-1] + (3,))
    rate[..., :2] = coefficients[..., _COL["rolling_rate_x"]:_COL["regime"]]
    slip = np.linalg.norm(ball_contact_slip(rate[..., :-1, :], rate[..., 1:, :], 1.0), axis=-1)
    out = np.where(mixed, ball_friction * slip, base)
    return np.ascontiguousarray(np.where(null, 0.0, out))


__all__ = ["ANCHOR_STIFFNESS", "PUSHED_STIFFNESS", "STICK_STEP", "TRAIN_COLUMNS",
           "directional_braking", "pair_braking", "regime_creep_coefficients", "rigid_rolling_rate",
           "minimum_compliance_kernel", "point_capacity_kernel", "stick_line_stiffness",
           "stick_line_stiffness_kernel", "three_point_coefficients", "three_point_stiffness",
           "two_point_rolling_rate"]
