"""Regimes of one ball in the planar Coulomb model: the dissipated power and its minimum.

The quasi-static state of a ball is the minimum of its dissipated power D (Notes of
:func:`dissipated_power`). Where every loaded contact spins and slips the minimum is smooth
(regime A, Newton in :mod:`tolsim.physics.velocity.full`); where one contact of the heavier
diagonal sticks it sits on a kink of D (regime B); an exactly two-point ball rolls at v/2
with D = 0. The criterion between A and B and the stick solve are in the Notes of
:func:`stick_criterion`; :func:`minimise_dissipation` is an independent NumPy/SciPy
minimiser of D, the reference of the tests and the baseline of ``benchmarks/bench_full.py``.
The Numba kernels are in :mod:`tolsim.physics.velocity._regime_kernels`.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import minimize

from tolsim.physics.geometry import SIDE_SIGN_X, SIDE_SIGN_Y, TABLE1, Bearing
from tolsim.physics.hertz import bearing_constants
from tolsim.physics.velocity._regime_kernels import (
    REGIME_SMOOTH,
    REGIME_STICK,
    REGIME_TWO_POINT,
    REGIME_UNSOLVED,
)

#: Names of the regime codes of :attr:`tolsim.physics.velocity.full.FullResult.regime`.
REGIME_NAMES = {REGIME_UNSOLVED: "unsolved", REGIME_SMOOTH: "A (all slip)",
                REGIME_STICK: "B (one contact sticks)", REGIME_TWO_POINT: "two-point"}
#: Default quadrature of :func:`dissipated_power`: Gauss-Legendre nodes in the radius
#: r = sin t, trapezoidal nodes in the polar angle about each contact centre.
DEFAULT_REFERENCE_NODES = (48, 192)


def stick_criterion(normal_force, bearing: Bearing = TABLE1):
    """chi: the light pair's sliding-friction moment over the heavy pair's spin capacity.

    chi = R_B sum F_light / [(3/8) E(e) sum (F_heavy a_heavy)] (issue 25), the diagonals
    being (BL, TR) and (BR, TL) and the heavy one the one with the larger force sum.

    Parameters
    ----------
    normal_force : array_like, shape (..., 4)
        F_i [N] (>= 0), BL, BR, TR, TL.
    bearing : Bearing
        Geometry and material (sets a_i and the eccentricity e).

    Returns
    -------
    ndarray, shape (...)
        chi [-]; inf when the heavy diagonal carries no force.

    Notes
    -----
    **Regime B.** A contact k sticks when its slip field vanishes: no slip at its centre,
    u_k = v_B - V_k - R Omega . x_k = 0, and no spin, omega_k = Omega . y_k = 0 (with
    omega_z = 0). These two linear conditions leave a line of states,

        v_B = V_k + w,   Omega = (w / R) x_k,                                    (B1)

    the ball pivoting about the axis x_k through the centre of contact k. On it D_k = 0 and
    D = sum_{i != k} D_i is convex and smooth in w (the other contacts slip), so its
    minimum is the root of the non-decreasing slope dD/dw, found by Newton's method with the
    exact curvature from the tables of the contact integrals, safeguarded by the bracket the
    slope's signs give (``stick_line_solve``). The kernel solves the line of every loaded
    contact, heaviest first, and stops at the first certified one (the minimum of D lies on
    the line of the contact that sticks, and no line goes below it).

    **Certificate.** At a point of (B1) the directional derivative of D along any d is

        D'(x; d) = grad D_others . d + D_k(A_k d),                               (B2)

    A_k d = (du_k, d omega_k), D_k(u, w) = mu int sigma sqrt((u - w x)^2 + (w z)^2) dA its
    dissipation, positively homogeneous of degree one. With grad D_others = A_k^T q + r
    (r along the line, |r| the line slope), every slope is >= 0 iff r = 0 and

        q . s + D_k(s) >= 0 for every s = (u, w),                                (B3)

    i.e. -q, the friction force and spin moment contact k has to carry, lies in the set
    of those it can carry (the subdifferential of D_k at zero, whose support function is
    D_k). (B3) is checked on a scan of s = (cos phi, sin phi / a_k) of its value and slope in
    phi (the gradient of D_k is the contact's friction force and spin moment, from the same
    integral), every local minimum located by regula falsi on the slope
    (``stick_certificate``), and ``converged`` means max(|r|, -min (B3)) <= tol (both over
    sum F).

    Where the two contacts of one diagonal are exactly opposite (equal angles: a perfect
    bearing, or [Lin2018] case (b)), the lines of both meet at v_B = v/2 and both contacts
    stick; the certificate is then that the two can share the moment the other pair
    needs (``double_stick_solve``), and epsilon = 0.

    **Criterion.** The stuck contact of the heavy diagonal carries the moment that keeps the
    light pair sliding, about R sum F_light mu; it can carry at most its pure-spin friction
    moment (3/8) mu F a E(e) ([Lin2018] Eq. 14) per heavy contact. chi compares the two:
    chi < 1 means a heavy contact sticks (regime B), chi > 1 all contacts slip (regime A).
    The kernel tries the stick solve first where chi < ``CHI_STICK_FIRST`` (it is cheaper
    than Newton, and a certified answer is the minimum), and after a failed Newton otherwise.
    """
    force = np.asarray(normal_force, dtype=np.float64)
    if force.shape[-1:] != (4,):
        raise ValueError(f"normal_force must have shape (..., 4), got {force.shape}")
    if np.any(force < 0) or not np.all(np.isfinite(force)):
        raise ValueError("normal_force must be finite and >= 0")
    hc = bearing_constants(bearing)
    fa = force * hc.semi_major_coefficient * np.cbrt(force)
    d1 = force[..., 0] + force[..., 2]
    d2 = force[..., 1] + force[..., 3]
    first_heavy = d1 >= d2
    light = np.where(first_heavy, d2, d1)
    heavy = 0.375 * hc.elliptic_e * np.where(first_heavy, fa[..., 0] + fa[..., 2],
                                             fa[..., 1] + fa[..., 3])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(heavy > 0, bearing.ball_radius * light / heavy, np.inf)


@dataclass(frozen=True)
class TwoPointLoaded:
    """Result of :func:`two_point_loaded` (arrays broadcast over the balls).

    Attributes
    ----------
    velocity_deviation : ndarray
        epsilon [-]: 0 while rolling, +-inf (the sign of P) when the push makes it slide,
        NaN when the braking alone does (its speed is then not set by rolling).
    carriage_force : ndarray
        F_c = (mu_bb S - P) / 2 [N] while rolling (positive opposes the carriage motion).
    sliding : ndarray of bool
        |P| + mu_bb S > 2 mu F: gross sliding.
    """

    velocity_deviation: np.ndarray
    carriage_force: np.ndarray
    sliding: np.ndarray


def two_point_loaded(normal_force, push=0.0, neighbour_force_sum=0.0, bearing: Bearing = TABLE1,
                     *, ball_friction=0.1):
    """An exactly two-point ball under a push P and ball-ball braking S (closed form).

    Not yet wired into :func:`tolsim.physics.velocity.full.full` (whose loaded path still
    needs three loaded contacts).

    Parameters
    ----------
    normal_force : array_like
        F [N], the force of each of the two opposite contacts (equal by statics).
    push : array_like
        P [N] along +z.
    neighbour_force_sum : array_like
        S = Q_back + Q_front [N] (>= 0).
    bearing : Bearing
        Sets mu of the raceways.
    ball_friction : float
        mu_bb [-].

    Returns
    -------
    TwoPointLoaded

    Notes
    -----
    Both contacts stick (the rolling state at v/2 with D = 0 of :func:`stick_criterion`'s
    Notes), so the loads only change the reactions. With f_b, f_t the friction forces on
    the ball along z at the bottom and top contact and x_b = -x_t the rolling axis, the force
    row is f_b + f_t + P = 0 and the moment about the rolling axis -R (f_b - f_t) -
    mu_bb S R = 0 (the braking opposes the rotation). So

        f_b = -(P + mu_bb S) / 2,   f_t = (mu_bb S - P) / 2 = F_c,

    with no spin moment. A stuck contact carries (f, 0) iff |f| <= mu F (D_k(u, w) >=
    mu F |u| by Jensen, since the pressure has its centroid at the centre), so the ball keeps
    epsilon = 0 while |P| + mu_bb S <= 2 mu F (issue 25) and slides beyond.
    """
    force = np.asarray(normal_force, dtype=float)
    p = np.asarray(push, dtype=float)
    s = np.asarray(neighbour_force_sum, dtype=float)
    if np.any(s < 0) or np.any(force < 0):
        raise ValueError("normal_force and neighbour_force_sum must be >= 0")
    mu = bearing.friction_coefficient
    braking = ball_friction * s
    sliding = np.abs(p) + braking > 2.0 * mu * force
    pushed = sliding & (np.abs(p) > 0)
    eps = np.where(sliding, np.where(pushed, np.copysign(np.inf, p), np.nan), 0.0)
    carriage = np.where(sliding, np.nan, 0.5 * (braking - p))
    return TwoPointLoaded(velocity_deviation=eps, carriage_force=carriage, sliding=sliding)


def _contact_points(contact_angle_deviation, normal_force, bearing, nodes):
    """Quadrature points r [R_B], weights [N] and normals p of the four planar ellipses
    (read-only arrays, kept for the latest balls: a minimisation asks for the same ball
    thousands of times, and forming them was a third of its time)."""
    dbeta = tuple(float(x) for x in np.asarray(contact_angle_deviation, dtype=float).ravel())
    force = tuple(float(x) for x in np.asarray(normal_force, dtype=float).ravel())
    return _contact_points_of(dbeta, force, bearing, tuple(int(n) for n in nodes))


@lru_cache(maxsize=4)
def _contact_points_of(dbeta, force, bearing, nodes):
    """:func:`_contact_points` of hashable inputs."""
    beta = bearing.nominal_contact_angle + np.asarray(dbeta, dtype=float)
    force = np.asarray(force, dtype=float)
    hc = bearing_constants(bearing)
    n_rad, n_ang = nodes
    tg, wg = np.polynomial.legendre.leggauss(n_rad)
    t = 0.25 * np.pi * (tg + 1.0)
    wt = 0.25 * np.pi * wg * np.sin(t) * np.cos(t) ** 2  # sqrt(1 - r^2) r dr, r = sin t
    theta = 2.0 * np.pi * np.arange(n_ang) / n_ang
    r = np.sin(t)[:, None]
    zhat = np.array([0.0, 0.0, 1.0])
    points, weights, normals, groove = [], [], [], []
    for i in range(4):
        if force[i] <= 0:
            continue
        p = np.array([SIDE_SIGN_X[i] * np.sin(beta[i]), SIDE_SIGN_Y[i] * np.cos(beta[i]), 0.0])
        x_axis = np.cross(-p, zhat)
        a = hc.semi_major_coefficient * np.cbrt(force[i]) / bearing.ball_radius
        b = hc.semi_minor_coefficient * np.cbrt(force[i]) / bearing.ball_radius
        xl = (a * r * np.cos(theta)).ravel()
        zl = (b * r * np.sin(theta)).ravel()
        points.append(p + xl[:, None] * x_axis + zl[:, None] * zhat)
        w = 1.5 * force[i] / np.pi * (wt[:, None] * (2.0 * np.pi / n_ang)) * np.ones(n_ang)
        weights.append(w.ravel())
        normals.append(np.broadcast_to(p, (xl.size, 3)))
        groove.append(np.full(xl.size, 0.0 if i < 2 else 1.0))
    out = (np.concatenate(points), np.concatenate(weights), np.concatenate(normals),
           np.concatenate(groove))
    for a in out:
        a.flags.writeable = False
    return out


def dissipated_power(ball_velocity, angular_velocity, contact_angle_deviation, normal_force,
                     bearing: Bearing = TABLE1, *, groove_velocity=0.01,
                     nodes=DEFAULT_REFERENCE_NODES, smoothing=0.0, gradient=False):
    """Dissipated power D of one ball in the planar Coulomb model, by direct quadrature (NumPy).

    Independent of the Numba kernels (3-D vectors, no pole-centred rule): the reference of
    the tests. Contacts with a zero force are open and dropped.

    Parameters
    ----------
    ball_velocity : float
        v_B [m/s].
    angular_velocity : array_like, shape (3,)
        Omega [rad/s].
    contact_angle_deviation, normal_force : array_like, shape (4,)
        dbeta_i [rad], F_i [N] (BL, BR, TR, TL).
    bearing : Bearing
        Geometry, material, mu.
    groove_velocity : float
        v [m/s].
    nodes : (int, int)
        Radial (Gauss-Legendre in r = sin t) and angular (trapezoidal) nodes per contact.
    smoothing : float
        delta [m/s]: |slip| is replaced by sqrt(|slip|^2 + delta^2) (0: the exact D).
    gradient : bool
        Also return dD/d(v_B, Omega) [N, N m].

    Returns
    -------
    float or (float, ndarray)
        D [W] (and its gradient).

    Notes
    -----
    Kinematics ([Lin2018] Eqs. 1-9, planar contact). Contact i has its centre at
    R p_i, p_i = (sx_i sin beta_i, sy_i cos beta_i, 0), inward normal y_i = -p_i, z_i = e_z
    and x_i = y_i x z_i. A point of its ellipse is r = R p_i + x x_i + z z_i. The slip of the
    ball over groove i (velocity V_i e_z, 0 bottom, v top) projected on the contact plane is

        s_i(r) = P_i [(v_B - V_i) e_z + Omega x r],   P_i = 1 - p_i p_i^T,      (D1)

    linear in the unknowns X = (v_B, Omega). With omega_z = 0 it is the rotation field of Eq. 8,
    s_i = (omega_i z, u_i - omega_i x) with u_i = v_B - V_i - R Omega . x_i and
    omega_i = Omega . y_i. Coulomb friction with the Hertz pressure sigma_i (Eq. 11) puts the
    traction t = -mu sigma_i s_i / |s_i| on the ball and dissipates

        D(X) = sum_i int_{E_i} mu sigma_i |s_i(r; X)| dA                          (D2)

    over the Hertz ellipses E_i (a_i across the groove, b_i along the rail, ERRATA 4).

    *D is convex.* Each integrand is a norm of a linear function of X; norms are convex and
    the weights mu sigma_i are >= 0, so D is a non-negative combination of convex functions.
    It is positively homogeneous of degree one in (X - X_rigid) only per contact, and it is not
    smooth where some s_i vanishes on a set of positive measure: where a contact's slip field
    is zero everywhere (u_i = omega_i = 0, a *stuck* contact).

    *Its stationary points are the equilibria.* Where D is differentiable,

        dD/dv_B = int mu sigma s/|s| . e_z = -F_z,
        dD/dOmega = int mu sigma r x s/|s| = -M,                                  (D3)

    since d s_i / dv_B = P_i e_z, d s_i / dOmega . u = (r x u) . dOmega and s_i is in the
    contact plane; F_z and M are the friction force along z and the friction moment about the
    centre (the rows of Eq. 18 in full: [Lin2018] Eqs. 12-13 and the spin moment, with the sign
    of ERRATA 8). So the quasi-static equilibrium F_z = 0, M_x = M_y = 0 is grad D = 0: the
    minimum of the convex D, unique where D is strictly convex. Under a push P along +z
    the force row reads F_z + P = 0, the gradient of

        Phi(X) = D(X) - P v_B,                                                    (D4)

    D less the work rate of the push, still convex, whose minimum is the loaded equilibrium.
    Where the minimum sits on a kink (a stuck contact), grad D does not exist and the
    equilibrium is 0 in the subdifferential of D (:func:`stick_criterion`, Notes); a smooth
    Newton on (D3) cannot converge there.
    """
    v = float(groove_velocity)
    radius = bearing.ball_radius
    r, w, p, groove = _contact_points(contact_angle_deviation, normal_force, bearing, nodes)
    omega = np.asarray(angular_velocity, dtype=float) * radius / v
    vel = np.cross(omega, r)
    vel[:, 2] += ball_velocity / v - groove
    slip = vel - np.sum(vel * p, axis=1)[:, None] * p
    norm = np.sqrt(np.sum(slip * slip, axis=1) + (smoothing / v) ** 2)
    mu = bearing.friction_coefficient
    power = mu * v * np.sum(w * norm)
    if not gradient:
        return power
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = np.where(norm[:, None] > 0, slip / norm[:, None], 0.0)
    grad = np.empty(4)
    grad[0] = mu * np.sum(w * unit[:, 2])
    grad[1:] = mu * radius * np.sum(w[:, None] * np.cross(r, unit), axis=0)
    return power, grad


@dataclass(frozen=True)
class DissipationMinimum:
    """Result of :func:`minimise_dissipation` for one ball.

    Attributes
    ----------
    ball_velocity : float
        v_B [m/s].
    angular_velocity : ndarray, shape (3,)
        Omega [rad/s] (omega_z = 0).
    velocity_deviation : float
        epsilon = 2 v_B / v - 1 [-].
    dissipated_power : float
        Phi = D - P v_B at the minimum [W].
    """

    ball_velocity: float
    angular_velocity: np.ndarray
    velocity_deviation: float
    dissipated_power: float


def minimise_dissipation(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1, *,
                         groove_velocity=0.01, push=0.0, nodes=DEFAULT_REFERENCE_NODES,
                         starts=3):
    """Minimise D - P v_B of one ball with SciPy: the independent twin of ``full``.

    A smoothing continuation (|s| -> sqrt(|s|^2 + delta^2), delta from 1e-2 v down to
    1e-10 v, BFGS with the exact gradient of :func:`dissipated_power`) from ``starts``
    starting points, then Nelder-Mead on the exact, non-smooth D from the best one. No
    Newton, no regime logic, no pole-centred quadrature: slow (seconds per ball), for tests
    and as the benchmark's baseline.

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (4,)
        dbeta_i [rad], F_i [N].
    bearing : Bearing
        Geometry, material, mu.
    groove_velocity : float
        v [m/s].
    push : float
        P [N] along +z (Notes of :func:`dissipated_power`, Eq. D4).
    nodes : (int, int)
        Quadrature of :func:`dissipated_power`.
    starts : int
        Starting points (pure rolling about x, and tilted axes).

    Returns
    -------
    DissipationMinimum
    """
    v = float(groove_velocity)
    radius = bearing.ball_radius
    mu = bearing.friction_coefficient
    scale = mu * v * float(np.sum(normal_force))
    beta0 = bearing.nominal_contact_angle

    def phi(x, delta):
        d, g = dissipated_power(x[0] * v, np.array([x[1], x[2], 0.0]) * v / radius,
                                contact_angle_deviation, normal_force, bearing,
                                groove_velocity=v, nodes=nodes, smoothing=delta * v,
                                gradient=True)
        val = (d - push * x[0] * v) / scale
        grad = np.array([(g[0] - push) * v, g[1] * v / radius, g[2] * v / radius]) / scale
        return val, grad

    candidates = [np.array([0.5, 0.5 / np.cos(beta0), 0.0]),
                  np.array([0.5, 0.5, 0.5]), np.array([0.5, 0.5, -0.5])][:max(1, starts)]
    best = None
    for x in candidates:
        for delta in 10.0 ** -np.arange(2, 11):
            x = minimize(phi, x, args=(delta,), jac=True, method="BFGS",
                         options={"gtol": 1e-13, "maxiter": 400}).x
        val = phi(x, 0.0)[0]
        if best is None or val < best[1]:
            best = (x, val)
    x0 = best[0]
    simplex = x0 + np.vstack([np.zeros(3), 1e-6 * np.eye(3)])
    res = minimize(lambda x: phi(x, 0.0)[0], x0, method="Nelder-Mead",
                   options={"initial_simplex": simplex, "xatol": 1e-13, "fatol": 1e-17,
                            "maxiter": 1500, "maxfev": 1500})
    x = res.x if res.fun <= best[1] else x0
    return DissipationMinimum(
        ball_velocity=float(x[0] * v),
        angular_velocity=np.array([x[1], x[2], 0.0]) * v / radius,
        velocity_deviation=float(2.0 * x[0] - 1.0),
        dissipated_power=float(min(res.fun, best[1]) * scale),
    )
