"""A ball's creep coefficients from its own minimum of D where the creep model has none.

The stick line of a ball in regime B (:func:`stick_line_stiffness`) and the push at which its
stuck contact lets go (:func:`stick_release`); a three-point ball's coefficients at its own
minimum, smooth or on a stick line (:func:`three_point_coefficients`). Used by
:mod:`tolsim.physics.trains.regimes`; the derivations are in the Notes of each function.
"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics.geometry import SIDE_SIGN_X, SIDE_SIGN_Y, TABLE1, Bearing
from tolsim.physics.hertz import bearing_constants
from tolsim.physics.velocity._contact_tables import table_ball_loads
from tolsim.physics.velocity._full_kernels import ball_loads_kernel
from tolsim.physics.velocity.ball_loads import point_traction_capacity, stall_moment
from tolsim.physics.velocity.full import (
    DEFAULT_ANGULAR_NODES,
    DEFAULT_RADIAL_NODES,
    contact_table,
    full,
    quadrature_grid,
)

#: Step along the stick line for its curvature, a fraction of v.
STICK_STEP = 1e-5


def contact_directions(contact_angle_deviation, bearing):
    """p_i = (sx sin beta_i, sy cos beta_i), shape (n, 4, 2)."""
    beta = bearing.nominal_contact_angle + np.asarray(contact_angle_deviation, dtype=float)
    return np.stack([SIDE_SIGN_X * np.sin(beta), SIDE_SIGN_Y * np.cos(beta)], axis=-1)


@pjit
def stick_line_stiffness_kernel(beta, force, stuck, rate, a, b, table, cin, sin_, win, xo, wo,
                                step, out):
    """K = (v / 2) d^2 D_others / dw^2 [N / mu] on the stick line of each ball; unchecked.

    ``beta``, ``force`` (n, 4), ``stuck`` (n,) the stuck contact k (else inf: both contacts of
    a pair stick, rigid), ``rate`` (n,) w [v] at the minimum, ``a``, ``b`` (n, 4) the
    semi-axes [R]. Central difference of the line slope dD/dw = -(F_z + M . x_k) (the loads
    of the other contacts, R = v = mu = 1) over w +- ``step``, from the contact tables
    (:func:`~tolsim.physics.velocity._contact_tables.table_ball_loads`, as the line solve
    takes them: on a stick line every pole lies on its contact's semi-major axis). The
    quadrature (``ball_loads_kernel``) gave the same K to 2.4e-14 relative on 20 356 balls in
    regime B and three-point balls on a stick line, at 3.3-3.7x the cost.
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
        jac = np.empty((3, 3))
        scratch = np.empty(6)
        slope = np.empty(2)
        for side in range(2):
            w = rate[n] + (step if side else -step)
            state[0] = vgroove[k] + w
            state[1] = w * xx
            state[2] = w * xy
            state[3] = 0.0
            table_ball_loads(state, px, py, vgroove, others, a[n], b[n], 1.5 / np.pi, table,
                             cin, sin_, win, xo, wo, loads, contact, jac, scratch)
            slope[side] = -(loads[0] + loads[1] * xx + loads[2] * xy)
        out[n] = 0.25 * (slope[1] - slope[0]) / step


def _semi_axes(force, bearing):
    """(Hertz constants, a, b [R_B]) of contacts under the forces ``force`` [N]."""
    hc = bearing_constants(bearing)
    radius = bearing.ball_radius
    return (hc, hc.semi_major_coefficient * np.cbrt(force) / radius,
            hc.semi_minor_coefficient * np.cbrt(force) / radius)


#: The groove velocity [m/s] of the free solves here (``full``'s default); epsilon and every
#: coefficient are independent of it.
FREE_SOLVE_VELOCITY = 0.01


def _stick_line(contact_angle_deviation, normal_force, bearing, result=None):
    """The free solve of balls and their stick lines' inputs for the kernels: (result,
    beta, F, stuck contact, w at the minimum [v], a, b [R_B], quadrature grid). ``result``:
    the free solve when the caller has it (``full`` of these balls with its defaults)."""
    dbeta = np.ascontiguousarray(contact_angle_deviation, dtype=np.float64).reshape(-1, 4)
    force = np.ascontiguousarray(normal_force, dtype=np.float64).reshape(-1, 4)
    v = FREE_SOLVE_VELOCITY
    res = (full(dbeta, force, bearing, groove_velocity=v) if result is None else result)
    hc, a, b = _semi_axes(force, bearing)
    radius = bearing.ball_radius
    beta = bearing.nominal_contact_angle + dbeta
    stuck = np.asarray(res.stuck_contact, dtype=np.int64)
    p = contact_directions(dbeta, bearing)
    k = np.clip(stuck, 0, 3)
    xk = np.stack([-p[np.arange(len(p)), k, 1], p[np.arange(len(p)), k, 0]], axis=-1)
    rate = np.ascontiguousarray(np.sum(res.angular_velocity[:, :2] * radius / v * xk, axis=1))
    grid = quadrature_grid(DEFAULT_ANGULAR_NODES, DEFAULT_RADIAL_NODES, hc.ellipticity)
    return res, beta, force, stuck, rate, a, b, grid


def _line_stiffness(beta, force, stuck, rate, a, b, grid, bearing):
    """:func:`stick_line_stiffness_kernel` on the outputs of :func:`_stick_line` [N / mu]."""
    out = np.empty(len(beta))
    table = contact_table(DEFAULT_ANGULAR_NODES, bearing_constants(bearing).ellipticity)
    stick_line_stiffness_kernel(beta, force, stuck, rate, a, b, table, *grid[:5], STICK_STEP,
                                out)
    return out


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
    res, beta, force, stuck, rate, a, b, grid = _stick_line(contact_angle_deviation,
                                                            normal_force, bearing)
    out = _line_stiffness(beta, force, stuck, rate, a, b, grid, bearing)
    out = bearing.friction_coefficient * out
    return np.where(np.asarray(res.regime) == 2, out, np.nan), res


#: Directions of the off-line scan (over the circle, and again over +-RELEASE_WINDOW [rad]
#: about each pivot direction) and bisection steps of :func:`stick_release_kernel`.
RELEASE_ANGLES, RELEASE_STEPS, RELEASE_WINDOW = 256, 40, 0.2


@jit
def _stick_margin(push, w, t, px, py, vgroove, others, a, b, cin, sin_, win, xo, wo, tr, wr,
                  step, dirs, sigma, out_w):
    """Least directional slope of D - P v_B off the stick line at its minimum under ``push``
    (R = v = mu = 1), from ``w``; the line minimum's w into ``out_w[0]``."""
    x = np.zeros(4)
    loads = np.empty(5)
    contact = np.empty((4, 5))
    zero = np.zeros(4)
    slope = np.empty(3)
    for _ in range(6):  # Newton on dD_others/dw = push (D_others smooth on the line)
        for side in range(3):
            ws = w + (side - 1) * step
            x[0] = t[3] + ws
            x[1] = ws * t[1]
            x[2] = ws * t[2]
            ball_loads_kernel(x, px, py, vgroove, others, a, b, 1.5 / np.pi, False, 1.0, zero,
                              cin, sin_, win, xo, wo, tr, wr, loads, contact)
            slope[side] = -(loads[0] + loads[1] * t[1] + loads[2] * t[2])
        curvature = (slope[2] - slope[0]) / (2.0 * step)
        if not curvature > 0.0:
            break
        dw = (slope[1] - push) / curvature
        w -= dw
        if abs(dw) < 1e-14:
            break
    x[0] = t[3] + w
    x[1] = w * t[1]
    x[2] = w * t[2]
    ball_loads_kernel(x, px, py, vgroove, others, a, b, 1.5 / np.pi, False, 1.0, zero, cin,
                      sin_, win, xo, wo, tr, wr, loads, contact)
    least = np.inf
    for j in range(dirs.shape[0]):
        m = sigma[j] - (loads[0] + push) * dirs[j, 0] - loads[1] * dirs[j, 1] \
            - loads[2] * dirs[j, 2]
        least = min(least, m)
    out_w[0] = w
    return least


@jit
def _stick_frame(beta, force, k, px, py, others, alone):
    """Contact directions of one ball into ``px``, ``py``; the forces of the other contacts
    and of the stuck contact ``k`` alone into ``others``, ``alone``. Returns (sum F, t, e1,
    e2, pivot): the stick line (t[:3] its direction, t[3] its offset V_k: v_B = V_k + w,
    Omega R = w x_k), the unit vectors e1, e2 normal to it, and the phase of the pivot."""
    total = 0.0
    for i in range(4):
        px[i] = (-1.0 if i == 0 or i == 3 else 1.0) * np.sin(beta[i])
        py[i] = (-1.0 if i < 2 else 1.0) * np.cos(beta[i])
        others[i] = force[i] if i != k else 0.0
        alone[i] = force[i] if i == k else 0.0
        total += force[i]
    t = np.array([1.0, -py[k], px[k], 1.0 if k >= 2 else 0.0])
    norm = np.sqrt(1.0 + t[1] * t[1] + t[2] * t[2])
    e1 = np.array([-t[1], 1.0, 0.0]) / np.hypot(1.0, t[1])
    e2 = np.array([t[1] * e1[2] - t[2] * e1[1], t[2] * e1[0] - e1[2],
                   e1[1] - t[1] * e1[0]]) / norm
    # the pure spin about the stuck contact's normal, (0, y_k), at the phase pivot: there
    # sigma_k is smallest (only the spin moment resists), a dip of width ~ a / R_B
    pivot = np.arctan2(-px[k] * e2[1] - py[k] * e2[2], -px[k] * e1[1] - py[k] * e1[2])
    return total, t, e1, e2, pivot


@jit
def _support_scan(phases, e1, e2, px, py, alone, a, b, cin, sin_, win, xo, wo, tr, wr):
    """(dirs, sigma): the unit directions cos e1 + sin e2 at ``phases`` and the stuck
    contact's support function sigma_k there (its dissipation, grooves at rest)."""
    dirs = np.empty((len(phases), 3))
    sigma = np.empty(len(phases))
    loads = np.empty(5)
    contact = np.empty((4, 5))
    zero = np.zeros(4)
    d = np.zeros(4)
    for j in range(len(phases)):
        for i in range(3):
            dirs[j, i] = np.cos(phases[j]) * e1[i] + np.sin(phases[j]) * e2[i]
            d[i] = dirs[j, i]
        ball_loads_kernel(d, px, py, zero, alone, a, b, 1.5 / np.pi, False, 1.0, zero, cin,
                          sin_, win, xo, wo, tr, wr, loads, contact)
        sigma[j] = loads[4]
    return dirs, sigma


@jit
def _scan_phases(angles, nodes, pivot, half):
    """The directions of a release scan: ``angles`` over the circle, then ``nodes`` within
    +- ``half`` of the pivot's phase and as many within +- ``half`` of the opposite one."""
    phases = np.empty(angles + 2 * nodes)
    for j in range(len(phases)):
        if j < angles:
            phases[j] = 2.0 * np.pi * j / angles
        else:
            fine = j - angles
            phases[j] = (pivot + np.pi * (fine // nodes)
                         + half * (2.0 * (fine % nodes) / (nodes - 1) - 1.0))
    return phases


@jit
def _release_frame(beta, force, k, a, b, cin, sin_, win, xo, wo, tr, wr, angles, nodes, half):
    """What both release kernels set up per ball stuck at contact k: its stick frame
    (:func:`_stick_frame`), the grooves' speeds and the support scan of the directions
    around the pivot (:func:`_scan_phases`, ``nodes`` within +- ``half`` of it;
    :func:`_support_scan`). Returns (px, py, vgroove, others, total, t, dirs, sigma)."""
    px = np.empty(4)
    py = np.empty(4)
    others = np.empty(4)
    alone = np.empty(4)
    total, t, e1, e2, pivot = _stick_frame(beta, force, k, px, py, others, alone)
    vgroove = np.array([0.0, 0.0, 1.0, 1.0])
    phases = _scan_phases(angles, nodes, pivot, half)
    dirs, sigma = _support_scan(phases, e1, e2, px, py, alone, a, b, cin, sin_, win, xo, wo,
                                tr, wr)
    return px, py, vgroove, others, total, t, dirs, sigma


@pjit
def stick_release_kernel(beta, force, stuck, rate, a, b, cin, sin_, win, xo, wo, tr, wr, step,
                         angles, steps, out):
    """The pushes [N / mu] at which the stuck contact of each ball lets go; unchecked.

    ``out`` (n, 2): the forward (> 0) and backward (< 0) push at which the least slope of
    :func:`_stick_margin` reaches 0 (bisection, ``steps`` halvings of [0, +-sum F]; +-inf
    when it holds up to +-sum F, the gross-sliding bound); (inf, -inf) where no single
    contact sticks. Inputs as :func:`stick_line_stiffness_kernel`.
    """
    for n in prange(beta.shape[0]):
        out[n, 0] = np.inf
        out[n, 1] = -np.inf
        k = stuck[n]
        if k < 0 or k > 3:
            continue
        px, py, vgroove, others, total, t, dirs, sigma = _release_frame(
            beta[n], force[n], k, a[n], b[n], cin, sin_, win, xo, wo, tr, wr, angles,
            angles + 1, RELEASE_WINDOW)
        w = np.empty(1)
        for side in range(2):
            sign = 1.0 if side == 0 else -1.0
            if _stick_margin(sign * total, rate[n], t, px, py, vgroove, others, a[n], b[n],
                             cin, sin_, win, xo, wo, tr, wr, step, dirs, sigma, w) >= 0.0:
                continue
            low, high = 0.0, total
            start = rate[n]
            for _ in range(steps):
                mid = 0.5 * (low + high)
                if _stick_margin(sign * mid, start, t, px, py, vgroove, others, a[n], b[n],
                                 cin, sin_, win, xo, wo, tr, wr, step, dirs, sigma, w) >= 0.0:
                    low = mid
                else:
                    high = mid
            out[n, side] = sign * 0.5 * (low + high)


def stick_release(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """The pushes [N] at which a stuck contact lets go (regime B, three-point on a stick line).

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)

    Returns
    -------
    release : ndarray, shape (n, 2)
        The forward (> 0) and backward (< 0) push at which the stick line stops being the
        minimum of D - P v_B (+-inf: not below mu sum F, where the ball slides anyway);
        (inf, -inf) where ``full`` finds no single stuck contact.
    result : tolsim.physics.velocity.full.FullResult
        The free solve.

    Notes
    -----
    Under a push P the stick line's minimum moves to dD_others/dw = P (Notes of
    :func:`stick_line_stiffness`; Newton on the line). It stays the minimum of the convex
    Phi = D - P v_B while no direction d off the line descends. D is differentiable along
    the line (the stuck contact's slip stays zero on it), so the directional slope is
    linear in the line's component and only the plane normal to the line matters; there
    the stuck contact's slip is linear in d and its dissipation is its support function
    sigma_k(d) = D_k(d) with the grooves at rest:

        min over unit d normal to the line of  sigma_k(d) + (grad D_others - P e_v) . d >= 0

    (``RELEASE_ANGLES`` directions over the circle, and as many again within
    ``RELEASE_WINDOW`` of each *pivot* direction +-(0, y_k), the ball spinning about the
    stuck contact's normal: there the stuck contact resists only with its spin moment, ~a/R_B
    of its sliding friction, and the least slope lies in a dip of that width which a uniform
    scan misses). The release push is where that minimum reaches zero (bisection). Beyond it
    the ball leaves the stick line for its other branch (regime A's larger epsilon), which
    the linear K of the trains does not follow.
    """
    res, beta, force, stuck, rate, a, b, grid = _stick_line(contact_angle_deviation,
                                                            normal_force, bearing)
    out = np.empty((len(beta), 2))
    stick_release_kernel(beta, force, stuck, rate, a, b, *grid, STICK_STEP, RELEASE_ANGLES,
                         RELEASE_STEPS, out)
    return bearing.friction_coefficient * out, res


#: The fast release threshold (:func:`release_threshold_kernel`): directions over the circle,
#: nodes and half-width (in units of the stuck contact's a / R_B) of the scan about each pivot,
#: and the tolerance of the bracket on the push, a fraction of sum F.
FAST_ANGLES, FAST_WINDOW_NODES, FAST_WINDOW_WIDTH, FAST_TOLERANCE = 16, 48, 1.5, 1e-4


@jit
def _line_slope(w, t, px, py, vgroove, others, a, b, cin, sin_, win, xo, wo, tr, wr, loads,
                contact):
    """dD_others/dw on the stick line at ``w`` (R = v = mu = 1); loads into ``loads``."""
    x = np.zeros(4)
    x[0] = t[3] + w
    x[1] = w * t[1]
    x[2] = w * t[2]
    ball_loads_kernel(x, px, py, vgroove, others, a, b, 1.5 / np.pi, False, 1.0, np.zeros(4),
                      cin, sin_, win, xo, wo, tr, wr, loads, contact)
    return -(loads[0] + loads[1] * t[1] + loads[2] * t[2])


@jit
def _fast_margin(push, w, curvature, t, px, py, vgroove, others, a, b, cin, sin_, win, xo, wo,
                 tr, wr, dirs, sigma, out_w):
    """:func:`_stick_margin` by secant steps on the line slope from ``w`` (first step with
    ``curvature``), the line minimum's w into ``out_w[0]``; -inf where the steps find no
    minimum on the line (the stick line does not hold the push)."""
    loads = np.empty(5)
    contact = np.empty((4, 5))
    w0 = w
    r0 = _line_slope(w0, t, px, py, vgroove, others, a, b, cin, sin_, win, xo, wo, tr, wr,
                     loads, contact) - push
    w1 = w0 - r0 / curvature
    for _ in range(30):
        r1 = _line_slope(w1, t, px, py, vgroove, others, a, b, cin, sin_, win, xo, wo, tr, wr,
                         loads, contact) - push
        if r1 == r0 or abs(w1 - w0) < 1e-13:
            break
        w2 = w1 - r1 * (w1 - w0) / (r1 - r0)
        w0, r0, w1 = w1, r1, w2
    else:  # no minimum on the line (the push exceeds what the other contacts hold there)
        out_w[0] = np.nan
        return -np.inf
    least = np.inf
    for j in range(dirs.shape[0]):
        m = sigma[j] - (loads[0] + push) * dirs[j, 0] - loads[1] * dirs[j, 1] \
            - loads[2] * dirs[j, 2]
        least = min(least, m)
    out_w[0] = w1
    return least


@pjit
def release_threshold_kernel(beta, force, stuck, rate, a, b, cin, sin_, win, xo, wo, tr, wr,
                             step, angles, nodes, width, tolerance, out):
    """The pushes [N / mu] at which the stuck contact of each ball lets go, fast; unchecked.

    As :func:`stick_release_kernel` (same inputs and ``out``) with ``angles`` directions over
    the circle and ``nodes`` within +- ``width`` a_k / R_B of each pivot, the line minimum by
    secant steps from the last push found stuck, and the push bracketed to ``tolerance`` sum F
    by regula falsi (Illinois) with a bisection whenever a step does not halve the bracket;
    the midpoint of the last bracket. NaN where a line minimum is not found.
    """
    for n in prange(beta.shape[0]):
        out[n, 0] = np.inf
        out[n, 1] = -np.inf
        k = stuck[n]
        if k < 0 or k > 3:
            continue
        px, py, vgroove, others, total, t, dirs, sigma = _release_frame(
            beta[n], force[n], k, a[n], b[n], cin, sin_, win, xo, wo, tr, wr, angles, nodes,
            width * a[n, k])
        loads = np.empty(5)
        contact = np.empty((4, 5))
        low_slope = _line_slope(rate[n] - step, t, px, py, vgroove, others, a[n], b[n], cin,
                                sin_, win, xo, wo, tr, wr, loads, contact)
        high_slope = _line_slope(rate[n] + step, t, px, py, vgroove, others, a[n], b[n], cin,
                                 sin_, win, xo, wo, tr, wr, loads, contact)
        curvature = (high_slope - low_slope) / (2.0 * step)
        if not curvature > 0.0:
            out[n, 0] = np.nan
            out[n, 1] = np.nan
            continue
        w = np.empty(1)
        for side in range(2):
            sign = 1.0 if side == 0 else -1.0
            m_low = _fast_margin(0.0, rate[n], curvature, t, px, py, vgroove, others, a[n],
                                 b[n], cin, sin_, win, xo, wo, tr, wr, dirs, sigma, w)
            w_low = w[0]
            m_high = _fast_margin(sign * total, w_low + sign * total / curvature, curvature, t,
                                  px, py, vgroove, others, a[n], b[n], cin, sin_, win, xo, wo,
                                  tr, wr, dirs, sigma, w)
            if not m_low >= 0.0 or np.isnan(m_high):
                out[n, side] = np.nan
                continue
            if m_high >= 0.0:
                continue
            low, high = 0.0, total
            last = 0  # the end kept by the last step: 1 low, -1 high (Illinois)
            for _ in range(200):
                width_ = high - low
                if width_ <= tolerance * total:
                    break
                mid = low - m_low * width_ / (m_high - m_low)
                if not (low < mid < high):
                    mid = 0.5 * (low + high)
                m = _fast_margin(sign * mid, w_low + sign * (mid - low) / curvature, curvature,
                                 t, px, py, vgroove, others, a[n], b[n], cin, sin_, win, xo,
                                 wo, tr, wr, dirs, sigma, w)
                if np.isnan(m):
                    low = np.nan
                    break
                if m >= 0.0:
                    low, m_low, w_low = mid, m, w[0]
                    if last == 1:
                        m_high *= 0.5
                    last = 1
                else:
                    high, m_high = mid, m
                    if last == -1:
                        m_low *= 0.5
                    last = -1
                if high - low > 0.5 * width_:  # no halving: bisect next
                    mid = 0.5 * (low + high)
                    m = _fast_margin(sign * mid, w_low + sign * (mid - low) / curvature,
                                     curvature, t, px, py, vgroove, others, a[n], b[n], cin,
                                     sin_, win, xo, wo, tr, wr, dirs, sigma, w)
                    if np.isnan(m):
                        low = np.nan
                        break
                    if m >= 0.0:
                        low, m_low, w_low = mid, m, w[0]
                    else:
                        high, m_high = mid, m
                    last = 0
            out[n, side] = sign * 0.5 * (low + high)


#: The inputs of a ball's release pushes kept with its coefficients, so that they can be
#: computed later (:func:`release_pushes`): the stuck contact k, w [v] at the minimum on its
#: stick line, dbeta_i [rad] and F_i [N]; NaN where nothing sticks or ``full`` does not certify
#: the ball on a stick line.
RELEASE_INPUTS = ("release_stuck_contact", "release_line_rate",
                  *(f"release_contact_angle_deviation_{i}" for i in range(4)),
                  *(f"release_normal_force_{i}" for i in range(4)))


def stick_line_inputs(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1, *,
                      result=None):
    """K [N] of balls on a stick line and the inputs of their release pushes, one free solve.

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)
    result : FullResult, optional
        The free solve of these balls, when the caller has it: :func:`full` with its defaults
        (``groove_velocity`` :data:`FREE_SOLVE_VELOCITY`); not solved again.

    Returns
    -------
    k : ndarray (n,)
        :func:`stick_line_stiffness` (bit for bit).
    inputs : ndarray, shape (n, len(RELEASE_INPUTS))
        For :func:`release_pushes`; NaN rows where ``full`` does not certify the ball in
        regime B (one contact, or both of a pair, stuck).
    result : tolsim.physics.velocity.full.FullResult
    """
    res, beta, force, stuck, rate, a, b, grid = _stick_line(contact_angle_deviation,
                                                            normal_force, bearing, result)
    k = _line_stiffness(beta, force, stuck, rate, a, b, grid, bearing)
    certified = np.asarray(res.regime) == 2
    dbeta = np.asarray(contact_angle_deviation, dtype=np.float64).reshape(-1, 4)
    inputs = np.column_stack([stuck.astype(np.float64), rate, dbeta, force])
    inputs[~certified] = np.nan
    return np.where(certified, bearing.friction_coefficient * k, np.nan), inputs, res


def release_pushes(inputs, bearing: Bearing = TABLE1):
    """The forward and backward release pushes [N] from :func:`stick_line_inputs`' inputs.

    Parameters
    ----------
    inputs : array_like, shape (n, len(RELEASE_INPUTS))

    Returns
    -------
    ndarray, shape (n, 2)
        As :func:`stick_line_release` (:func:`release_threshold_kernel` on the same inputs,
        bit for bit); NaN for a NaN row.
    """
    inputs = np.asarray(inputs, dtype=np.float64).reshape(-1, len(RELEASE_INPUTS))
    out = np.full((len(inputs), 2), np.nan)
    rows = np.flatnonzero(np.isfinite(inputs[:, 0]))
    if not len(rows):
        return out
    dbeta = np.ascontiguousarray(inputs[rows, 2:6])
    force = np.ascontiguousarray(inputs[rows, 6:10])
    hc, a, b = _semi_axes(force, bearing)
    beta = bearing.nominal_contact_angle + dbeta
    stuck = np.ascontiguousarray(inputs[rows, 0].astype(np.int64))
    rate = np.ascontiguousarray(inputs[rows, 1])
    grid = quadrature_grid(DEFAULT_ANGULAR_NODES, DEFAULT_RADIAL_NODES, hc.ellipticity)
    release = np.empty((len(rows), 2))
    release_threshold_kernel(beta, force, stuck, rate, a, b, *grid, STICK_STEP, FAST_ANGLES,
                             FAST_WINDOW_NODES, FAST_WINDOW_WIDTH, FAST_TOLERANCE, release)
    out[rows] = bearing.friction_coefficient * release
    return out


def stick_line_release(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """K [N] and the release pushes [N] of balls in regime B from one free solve (fast).

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)

    Returns
    -------
    k : ndarray (n,)
        :func:`stick_line_stiffness`.
    release : ndarray, shape (n, 2)
        The forward (> 0) and backward (< 0) push at which the stuck contact lets go, as
        :func:`stick_release` (+-inf: not below mu sum F) by
        :func:`release_threshold_kernel`; NaN where ``full`` does not certify the ball in
        regime B or a line minimum is not found.
    result : tolsim.physics.velocity.full.FullResult

    Notes
    -----
    The stick condition of :func:`stick_release` with the least slope scanned over
    ``FAST_ANGLES`` directions and ``FAST_WINDOW_NODES`` within +- ``FAST_WINDOW_WIDTH`` a_k /
    R_B of each pivot (the dip has the width of the stuck contact, a_k / R_B, Notes of
    :func:`stick_release`), and the push found by regula falsi to ``FAST_TOLERANCE`` sum F
    (0.057 N / mu ... about 0.006 N on case (a)). A scan over fewer directions can only miss
    the least slope, so it errs towards larger |release|: on case (a) +0.2 % at rho = -0.9
    (+2.947 / -22.63 N against +2.940 / -22.60 N of the reference scan with 1024 window
    directions) and < 0.15 % at rho = -0.95; about 0.5-1.5 ms per ball against 4-6 ms. It is
    :func:`stick_line_inputs` then :func:`release_pushes`, which the trains call apart (only
    for the balls a push reaches, :func:`tolsim.physics.trains.regimes.settle_release_pushes`).
    """
    k, inputs, res = stick_line_inputs(contact_angle_deviation, normal_force, bearing)
    return k, release_pushes(inputs, bearing), res


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


def _three_point_solve(dbeta, force, bearing, result=None):
    """The free solve of three-point balls and what their coefficients need.

    Returns (K on the stick line, FullResult, the v_B row of H^-1 at a smooth minimum [1/N,
    over mu] (NaN at other balls), the state (v_B, Omega_x R, Omega_y R) / v, the inputs of
    the release pushes on the stick line); see :func:`three_point_stiffness`,
    :func:`stick_line_inputs` (``result``: its free solve, when given).
    """
    stick, inputs, res = stick_line_inputs(dbeta, force, bearing, result=result)
    v = FREE_SOLVE_VELOCITY
    hc, a, b = _semi_axes(force, bearing)
    beta = bearing.nominal_contact_angle + dbeta
    state = np.empty((len(dbeta), 3))
    state[:, 0] = 0.5 * (1.0 + np.asarray(res.velocity_deviation))
    state[:, 1:] = np.asarray(res.angular_velocity)[:, :2] * bearing.ball_radius / v
    grid = quadrature_grid(DEFAULT_ANGULAR_NODES, DEFAULT_RADIAL_NODES, hc.ellipticity)
    # the Hessian at smooth minima only (NaN elsewhere): a ball on a stick line takes its
    # coefficients from the line, and an uncertified one has none; without preload 99 % of
    # the three-point balls stick, and their Hessians took 30 % of such a circuit study
    row = np.full((len(dbeta), 3), np.nan)
    smooth = np.flatnonzero(np.asarray(res.regime) == 1)
    if len(smooth):
        out = np.empty((len(smooth), 3))
        minimum_compliance_kernel(beta[smooth], force[smooth], state[smooth], a[smooth],
                                  b[smooth], *grid, STICK_STEP, out)
        row[smooth] = out
    return stick, res, row, state, inputs


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
    stick, res, row, _, _ = _three_point_solve(dbeta, force, bearing)
    smooth = bearing.friction_coefficient * 0.5 / row[:, 0]
    code = np.asarray(res.regime)
    return np.where(code == 2, stick, np.where(code == 1, smooth, np.nan)), res


def three_point_coefficients(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1,
                             *, ball_friction=0.1, release_inputs=False, result=None):
    """The creep coefficients of three-point balls from their own minimum of D (issue 25).

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)
        dbeta_i [rad], F_i [N]; one force 0 (the open contact).
    bearing : Bearing
    ball_friction : float
        mu_bb [-].
    release_inputs : bool
        Add the inputs of the release pushes of a ball with a stuck contact
        (:data:`RELEASE_INPUTS`, for :func:`release_pushes`; NaN where no contact sticks).
    result : FullResult, optional
        The free solve of these balls, as :func:`stick_line_inputs` takes it.

    Returns
    -------
    columns : dict of str to ndarray (n,)
        The :data:`tolsim.physics.velocity.analytic.LOAD_COLUMNS` at zero load (K [N], c
        [1/N], F_0 [N], a, b [-], P_cap, S_cap [N]) and the braking vector gamma
        (``braking_vector_x``, ``_y`` [1/N], c = gamma . Omega_perp / |Omega_perp|) (and the
        release inputs); NaN where ``full`` does not certify the ball.
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
      ((H^-1)_vx, (H^-1)_vy), c = gamma . g
      (:func:`~tolsim.physics.trains.regimes.directional_braking`). On a stick line (one
      contact stuck) K is the line's and c = -mu_bb / K, as regime B's (R1 in
      :func:`~tolsim.physics.trains.regimes.regime_creep_coefficients`), and gamma = c g
      (only the moment's component along the line does work on it).
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

    A stuck contact lets go under a push before P_cap, at the release pushes of its stick
    line (:func:`stick_line_release`, the derivation of :func:`stick_release` with the open
    contact's F = 0; ``release_inputs`` for the trains, which count a train in which it is
    pushed past one as unresolved). Not modelled: the released state's own coefficients
    (the smooth minimum's K under that push), as in regime B.
    """
    dbeta = np.ascontiguousarray(contact_angle_deviation, dtype=np.float64).reshape(-1, 4)
    force = np.ascontiguousarray(normal_force, dtype=np.float64).reshape(-1, 4)
    stick, res, row, state, inputs = _three_point_solve(dbeta, force, bearing, result)
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
    if release_inputs:
        columns.update(zip(RELEASE_INPUTS, inputs.T, strict=True))
    solved = smooth | stuck
    columns = {name: np.where(solved, value, np.nan) for name, value in columns.items()}
    rate = np.where(solved[:, None], state[:, 1:], np.nan)
    return columns, rate


__all__ = ["FAST_ANGLES", "FAST_TOLERANCE", "FAST_WINDOW_NODES", "FAST_WINDOW_WIDTH",
           "FREE_SOLVE_VELOCITY", "RELEASE_ANGLES", "RELEASE_STEPS", "RELEASE_WINDOW", "STICK_STEP",
           "contact_directions",
           "minimum_compliance_kernel", "point_capacity_kernel", "release_threshold_kernel",
           "stick_line_release", "stick_line_stiffness",
           "stick_line_stiffness_kernel", "stick_release", "stick_release_kernel",
           "three_point_coefficients", "three_point_stiffness"]
