"""Numba kernels of the regimes of one ball: stick (regime B), two-point rolling, certificate.

The theory (dissipated power D, its kinks, the stick line and the certificate) is in the Notes
of :func:`tolsim.physics.velocity.regimes.dissipated_power` and
:func:`tolsim.physics.velocity.regimes.stick_criterion`.
"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics.velocity._contact_tables import table_ball_loads, table_integrals
from tolsim.physics.velocity._full_kernels import (
    SLIDING_POLE,
    ball_loads_kernel,
    contact_ellipses,
    planar_contact_integrals,
    solve_one,
)
from tolsim.physics.velocity._smooth_kernels import smooth_solve

#: Regime codes of :func:`regime_kernel` (``out_regime[:, 0]``).
REGIME_UNSOLVED = 0
REGIME_SMOOTH = 1
REGIME_STICK = 2
REGIME_TWO_POINT = 3
#: Directions of the certificate's first scan over the stuck contact's (slip, spin) plane.
CERTIFICATE_DIRECTIONS = 32
#: Iteration cap of the certificate's refinement of each local minimum.
_CERTIFICATE_MAX_ITER = 30
#: Directions of the first scan of :func:`spin_capacity` (a half circle).
CAPACITY_DIRECTIONS = 96
#: Two loaded contacts of one diagonal whose angles differ by at most this [rad] are exactly
#: opposite: the ball rolls at v/2 with both contacts stuck (D = 0).
TWO_POINT_ANGLE_TOLERANCE = 1e-9
#: Below this chi (:func:`tolsim.physics.velocity.regimes.stick_criterion`) the stick solve is
#: tried before the smooth Newton (it is cheaper, and a certified answer is the minimum).
CHI_STICK_FIRST = 1.0
#: Iteration cap of the line search along the stick line.
_LINE_MAX_ITER = 200
#: First half-width of the stick line's bracket about pure rolling at v/2 (units of v).
_LINE_BRACKET = 2e-3
#: Contact layout (BL, BR, TR, TL): side signs and the groove each contact belongs to.
_SX = (-1.0, 1.0, 1.0, -1.0)
_SY = (-1.0, -1.0, 1.0, 1.0)


@jit
def stuck_contact_power(u, w, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3):
    """D_k(u, w) of one planar contact with slip u at its centre and spin w (R = v = mu = 1).

    Positively homogeneous of degree one in (u, w): the support function of the set of
    friction (force, spin moment) pairs the stuck contact can carry.
    """
    if abs(w) * SLIDING_POLE * a > abs(u):
        planar_contact_integrals(u / w / a, 0.0, a, b, cin, sin_, win, xo, wo, s3)
        return sigma_scale * force * abs(w) * s3[3]
    return force * abs(u)


@jit
def _slope(phi, qu, qw, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3):
    u = np.cos(phi)
    w = np.sin(phi) / a
    return qu * u + qw * w + stuck_contact_power(u, w, force, a, b, sigma_scale, cin, sin_,
                                                 win, xo, wo, s3)


@jit
def _slope_and_derivative(phi, qu, qw, force, a, b, sigma_scale, table, cin, sin_, win, xo, wo,
                          s3):
    """f(phi) = q . s + D_k(s) at s = (cos phi, sin phi / a), and df/dphi.

    The gradient of D_k comes from the same contact integral: dD_k/du = -f_z and dD_k/dw =
    -M_n, the contact's friction force along z and its spin moment (Eqs. 12-13), i.e.
    -sigma F sgn(w) (S_z, S_n) of ``planar_contact_integrals`` (from the tables,
    :func:`~tolsim.physics.velocity._contact_tables.table_integrals`, into ``s3`` (3,));
    (F sgn(u), 0) when w = 0.
    """
    u = np.cos(phi)
    w = np.sin(phi) / a
    if abs(w) * SLIDING_POLE * a > abs(u):
        table_integrals(u / w / a, a, b, table, cin, sin_, win, xo, wo, s3)
        scale = sigma_scale * force
        power = scale * abs(w) * s3[2]
        sign = 1.0 if w > 0.0 else -1.0
        du = -scale * sign * s3[0]
        dw = -scale * sign * s3[1]
    else:
        power = force * abs(u)
        du = force if u > 0.0 else -force
        dw = 0.0
    value = qu * u + qw * w + power
    deriv = -(qu + du) * np.sin(phi) + (qw + dw) * np.cos(phi) / a
    return value, deriv


@jit
def scan_constants(ellipticity, table, cin, sin_, win, xo, wo):
    """The contact integrals of the certificate's scan directions, for every ball at once.

    In direction j, s = (cos phi_j, sin phi_j / a), the pole is at p = cot phi_j whatever a,
    and the integrals are (S_z, a S_n', a S_d') with S_n', S_d' those of a = 1. Returns
    (CERTIFICATE_DIRECTIONS, 6) = (cos phi_j, sin phi_j, S_z, S_n', S_d', usable): not usable
    where the contact slides (sin phi_j = 0 to round-off) or |p| is within 1e-9 of 1, where
    the quadrature changes rule and the few floats p rounds to from a ball's a matter.
    """
    n = CERTIFICATE_DIRECTIONS
    out = np.zeros((n, 6))
    o = np.empty(3)
    step = 2.0 * np.pi / n
    for j in range(n):
        u = np.cos(step * j)
        w = np.sin(step * j)
        out[j, 0] = u
        out[j, 1] = w
        if abs(w) * SLIDING_POLE > abs(u) and abs(abs(u / w) - 1.0) > 1e-9:
            table_integrals(u / w, 1.0, ellipticity, table, cin, sin_, win, xo, wo, o)
            out[j, 2] = o[0]
            out[j, 3] = o[1]
            out[j, 4] = o[2]
            out[j, 5] = 1.0
    return out


@jit
def stick_certificate(qu, qw, force, a, b, sigma_scale, table, cin, sin_, win, xo, wo, scan):
    """min over directions s = (cos phi, sin phi / a) of q . s + D_k(s) [N].

    >= 0 iff -q lies in the subdifferential of D_k at zero slip and spin, i.e. the stuck
    contact can carry the friction force q_u and spin moment q_w it has to (every directional
    slope of D at the stick point is >= 0). A scan over ``CERTIFICATE_DIRECTIONS`` angles of
    the value f and its derivative f' (one contact integral gives both,
    :func:`_slope_and_derivative`); every interval where f' turns from negative to positive
    holds a local minimum, which regula falsi on f' locates (``_CERTIFICATE_MAX_ITER`` steps
    at most, to a relative change of f below 1e-15). The scan takes the integrals of
    :func:`scan_constants` where usable (they do not depend on the ball).
    """
    s3 = np.empty(3)
    n = CERTIFICATE_DIRECTIONS
    vals = np.empty(n)
    ders = np.empty(n)
    step = 2.0 * np.pi / n
    best = np.inf
    scale = abs(qu) + abs(qw) / a + force
    for j in range(n):
        if scan[j, 5] > 0.5:
            cs = scan[j, 0]
            sn = scan[j, 1]
            w = sn / a
            sig = sigma_scale * force
            sign = 1.0 if w > 0.0 else -1.0
            du = -sig * sign * scan[j, 2]
            dw = -sig * sign * a * scan[j, 3]
            vals[j] = qu * cs + qw * w + sig * abs(w) * (a * scan[j, 4])
            ders[j] = -(qu + du) * sn + (qw + dw) * cs / a
        else:
            vals[j], ders[j] = _slope_and_derivative(step * j, qu, qw, force, a, b,
                                                     sigma_scale, table, cin, sin_, win, xo, wo,
                                                     s3)
        best = min(best, vals[j])
    for j in range(n):
        k = (j + 1) % n
        if not (ders[j] < 0.0 <= ders[k]):
            continue
        lo = step * j
        hi = lo + step
        dlo = ders[j]
        dhi = ders[k]
        side = 0
        prev = min(vals[j], vals[k])
        for _ in range(_CERTIFICATE_MAX_ITER):
            x = hi - dhi * (hi - lo) / (dhi - dlo)
            if not (lo < x < hi):
                x = 0.5 * (lo + hi)
            val, der = _slope_and_derivative(x, qu, qw, force, a, b, sigma_scale, table, cin,
                                             sin_, win, xo, wo, s3)
            best = min(best, val)
            if der == 0.0 or abs(val - prev) <= 1e-15 * scale:
                break
            prev = val
            if der > 0.0:
                hi = x
                dhi = der
                if side == 1:
                    dlo *= 0.5
                side = 1
            else:
                lo = x
                dlo = der
                if side == -1:
                    dhi *= 0.5
                side = -1
    return best


@jit
def _capacity_ratio(phi, pu, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3):
    u = np.cos(phi)
    w = np.sin(phi) / a
    return (stuck_contact_power(u, w, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3)
            - pu * u) / w


@jit
def spin_capacity(pu, force, a, b, sigma_scale, cin, sin_, win, xo, wo):
    """Largest spin moment W a stuck contact carries with the z force component p_u [N m / R].

    W = min over s_w > 0 of (D_k(s) - p_u s_u) / s_w: the subdifferential of D_k at zero is
    symmetric in each component (D_k(u, w) is even in u and in w), so (p_u, p_w) is in it
    iff |p_w| <= W(p_u). Negative when |p_u| > F_k (no moment can help).
    """
    s3 = np.empty(4)
    n = CAPACITY_DIRECTIONS
    best = np.inf
    jbest = 1
    for j in range(1, n):
        val = _capacity_ratio(np.pi * j / n, pu, force, a, b, sigma_scale, cin, sin_, win, xo,
                              wo, s3)
        if val < best:
            best = val
            jbest = j
    lo = np.pi * (jbest - 1) / n
    hi = np.pi * (jbest + 1) / n
    lo = max(lo, 1e-9)
    hi = min(hi, np.pi - 1e-9)
    g = 0.5 * (np.sqrt(5.0) - 1.0)
    x1 = hi - g * (hi - lo)
    x2 = lo + g * (hi - lo)
    f1 = _capacity_ratio(x1, pu, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3)
    f2 = _capacity_ratio(x2, pu, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3)
    for _ in range(40):
        if f1 < f2:
            hi = x2
            x2 = x1
            f2 = f1
            x1 = hi - g * (hi - lo)
            f1 = _capacity_ratio(x1, pu, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3)
        else:
            lo = x1
            x1 = x2
            f1 = f2
            x2 = lo + g * (hi - lo)
            f2 = _capacity_ratio(x2, pu, force, a, b, sigma_scale, cin, sin_, win, xo, wo, s3)
    return min(best, f1, f2)


@jit
def double_stick_solve(i, px, py, vgroove, force, a, b, sigma_scale, rd, hoff, cin, sin_, win,
                       xo, wo, tr, wr, state, contact):
    """Both contacts of an opposite pair (i, i + 2) with equal angles stick; the margin.

    The state is fixed, v_B = v/2, Omega = (v / 2R) x_i (:func:`two_point_state`), and D is the
    other pair's. With g = grad D_others, 0 is in the subdifferential of D iff g + A_i^T p_i +
    A_j^T p_j = 0 with p_i, p_j in the stuck contacts' sets: with x_j = -x_i, y_j = -y_i this
    fixes p_iu = (-g_v + g . x_i) / 2, p_ju = (-g_v - g . x_i) / 2 and p_iw - p_jw = -g . y_i,
    which two contacts can carry iff |g . y_i| <= W_i(p_iu) + W_j(p_ju)
    (:func:`spin_capacity`). Returns (W_i + W_j - |g . y_i|) [N m / R], >= 0 when certified.
    """
    j = i + 2
    fk0 = force.copy()
    fk0[i] = 0.0
    fk0[j] = 0.0
    loads = np.empty(5)
    xx = -py[i]
    xy = px[i]
    yx = -px[i]
    yy = -py[i]
    state[0] = 0.5
    state[1] = 0.5 * xx
    state[2] = 0.5 * xy
    state[3] = 0.0
    ball_loads_kernel(state, px, py, vgroove, fk0, a, b, sigma_scale, False, rd, hoff, cin,
                      sin_, win, xo, wo, tr, wr, loads, contact)
    gv = -loads[0]
    gx = -(loads[1] * xx + loads[2] * xy)
    gy = -(loads[1] * yx + loads[2] * yy)
    piu = 0.5 * (-gv + gx)
    pju = 0.5 * (-gv - gx)
    for k in (i, j):
        contact[k, 0] = 0.0
        contact[k, 1] = 0.0
        contact[k, 3] = 0.0
    contact[i, 2] = -piu
    contact[j, 2] = -pju
    contact[i, 4] = 0.5
    contact[j, 4] = -0.5
    wi = spin_capacity(piu, force[i], a[i], b[i], sigma_scale, cin, sin_, win, xo, wo)
    wj = spin_capacity(pju, force[j], a[j], b[j], sigma_scale, cin, sin_, win, xo, wo)
    return wi + wj - abs(gy)


@jit
def _line_slope(w, vk, xx, xy, px, py, vgroove, fk0, a, b, sigma_scale, table, cin, sin_,
                win, xo, wo, state, loads, contact, jac, o):
    """dD/dw and d2D/dw2 along the stick line of contact k: v_B = V_k + w, Omega = w x_k (D
    without k), from the tables (:func:`~tolsim.physics.velocity._contact_tables.table_ball_loads`,
    whose Jacobian is -Hess D)."""
    state[0] = vk + w
    state[1] = w * xx
    state[2] = w * xy
    state[3] = 0.0
    table_ball_loads(state, px, py, vgroove, fk0, a, b, sigma_scale, table, cin, sin_, win, xo,
                     wo, loads, contact, jac, o)
    curvature = 0.0
    for r in range(3):
        dr = 1.0 if r == 0 else (xx if r == 1 else xy)
        curvature -= dr * (jac[r, 0] + jac[r, 1] * xx + jac[r, 2] * xy)
    return -(loads[0] + loads[1] * xx + loads[2] * xy), curvature


@jit
def stick_line_solve(k, px, py, vgroove, force, a, b, sigma_scale, table, cin, sin_, win, xo,
                     wo, tol, state, contact, out):
    """Minimise D on the stick line of contact k (no slip and no spin at its centre).

    The line is v_B = V_k + w, Omega = w x_k: the ball pivots about the axis x_k through the
    centre of contact k. D restricted to it is convex in w, so its slope g is non-decreasing:
    Newton's method on g from pure rolling at v/2, with its exact curvature from the tables,
    kept inside the bracket that the signs of g give (bisection when a step leaves it; until
    both ends are known, steps of ``_LINE_BRACKET`` widened by 4x). It stops at |g| <= 1e-2
    ``tol`` sum F, after one more step if that lowers |g| (the minimum to round-off), or
    when the bracket collapses to round-off. A Newton step below the resolution of w (w + step
    == w: nearly two-point balls, whose slope rises by 3e5 to 1e7 sum F per unit w) tries the
    neighbouring float towards the minimum first: where the slope changes sign there, the
    bracket has collapsed, and the float of the smaller |g| is kept (tests/physics/
    test_regimes.py). Writes the state, the contact rows (the stuck
    contact's z force is the reaction that balances the others) and
    ``out`` = (D, |slope| / sum F, evaluations, q_u, q_w).
    """
    fk0 = force.copy()
    fk0[k] = 0.0
    total = force[0] + force[1] + force[2] + force[3]
    xx = -py[k]
    xy = px[k]
    vk = vgroove[k]
    loads = np.empty(5)
    jac = np.empty((3, 3))
    o = np.empty(6)
    # the minimum is near pure rolling at v/2 (|epsilon| ~ tan^2(Delta/2) is small)
    w = 0.5 - vk
    g, curv = _line_slope(w, vk, xx, xy, px, py, vgroove, fk0, a, b, sigma_scale, table, cin,
                          sin_, win, xo, wo, state, loads, contact, jac, o)
    evals = 1
    lo = -np.inf
    hi = np.inf
    h = _LINE_BRACKET
    collapsed = False
    target = 0.01 * tol * total
    polished = False
    nudged = False
    w_near = w
    g_old = g
    while evals < _LINE_MAX_ITER and np.isfinite(g):
        if abs(g) <= target:
            if polished or abs(g) <= 1e-2 * target or not curv > 0.0:
                break
            polished = True
        if g > 0.0:
            hi = w
        elif g < 0.0:
            lo = w
        else:
            break
        if hi - lo <= 4e-16 * max(1.0, abs(w)):
            # the slope changes sign between neighbouring floats: the minimum on the line is
            # located to round-off (a nearly stuck second contact makes the slope jump by
            # ~2 mu F over ~|dbeta| a, too steep to resolve |slope| below tol)
            collapsed = True
            if nudged and abs(g_old) < abs(g):  # back to the float of the smaller slope
                w = w_near
                g, curv = _line_slope(w, vk, xx, xy, px, py, vgroove, fk0, a, b, sigma_scale,
                                      table, cin, sin_, win, xo, wo, state, loads, contact, jac,
                                      o)
                evals += 1
            break
        step = -g / curv if curv > 0.0 else np.nan
        wn = w + step
        if wn == w and not nudged:
            # the Newton step is below w's resolution: the neighbouring float towards the
            # minimum brackets it to round-off when the slope changes sign there (else the
            # bracket's middle, as before); the bisection back from the bracket's far end took
            # ~20 evaluations to find that out
            wn = np.nextafter(w, np.inf if g < 0.0 else -np.inf)
            nudged = True
            w_near = w
        else:
            nudged = False
        if not (lo < wn < hi):
            if np.isfinite(lo) and np.isfinite(hi):
                wn = 0.5 * (lo + hi)
            else:
                wn = w - h if g > 0.0 else w + h
                h *= 4.0
        g_old = g
        w_old = w
        w = wn
        g, curv = _line_slope(w, vk, xx, xy, px, py, vgroove, fk0, a, b, sigma_scale, table,
                              cin, sin_, win, xo, wo, state, loads, contact, jac, o)
        evals += 1
        if polished:
            if not abs(g) <= abs(g_old):
                w = w_old
                g, curv = _line_slope(w, vk, xx, xy, px, py, vgroove, fk0, a, b, sigma_scale,
                                      table, cin, sin_, win, xo, wo, state, loads, contact, jac,
                                      o)
                evals += 1
            break
    # the stuck contact: pole at its centre, no spin, the reaction that balances the others
    qu = -loads[0]
    yx = -px[k]
    yy = -py[k]
    qw = ((-loads[1] + qu * xx) * yx + (-loads[2] + qu * xy) * yy) / (yx * yx + yy * yy)
    contact[k, 0] = 0.0
    contact[k, 1] = 0.0
    contact[k, 2] = qu
    contact[k, 3] = 0.0
    contact[k, 4] = w
    out[0] = loads[4]
    out[1] = 0.0 if collapsed else abs(g) / total
    out[2] = evals
    out[3] = qu
    out[4] = qw


@jit
def candidate_order(force):
    """The order in which :func:`stick_solve` tries the stick lines of a ball's contacts.

    By decreasing force; but a three-point ball (one diagonal loaded at both contacts, the
    other at one, the "single" contact) first tries the contact of the loaded pair on the
    other groove than the single one: that is the one that sticks, in every one of 73 905
    three-point regime-B balls of ``configs/carriage_preload.toml`` at 0 um oversize along
    the track (200 assemblies, seed 12, 20 steps), against 43 % for the heavier contact. Only the
    order changes, so the same certified line is found with one line solve instead of two
    where the heavier contact does not stick.
    """
    order = np.argsort(-force)
    single = -1
    loaded = 0
    for i in range(4):
        if force[i] > 0.0:
            loaded += 1
            if not force[(i + 2) % 4] > 0.0:
                single = i
    if loaded != 3 or single < 0:
        return order
    # the pair is (single + 1, single + 3) mod 4: one bottom (0, 1) and one top (2, 3) contact
    first = (single + 1) % 4
    if (first >= 2) == (single >= 2):
        first = (single + 3) % 4
    out = np.empty(4, dtype=order.dtype)
    out[0] = first
    m = 1
    for j in range(4):
        if order[j] != first:
            out[m] = order[j]
            m += 1
    return out


@jit
def stick_solve(beta, force, a, b, sigma_scale, rd, hoff, tol, table, cin, sin_, win, xo, wo,
                tr, wr, scan, state, contact, info, regime):
    """Regime B: the first certified stick line of a loaded contact (else the one of least D).

    An opposite pair with equal angles (a perfect or case (b) bearing) is tried first with
    both its contacts stuck (:func:`double_stick_solve`, stuck contact 4 + i).

    Writes ``state``, ``contact``, ``info`` = (residual, evaluations, converged) and
    ``regime`` = (code, stuck contact, certificate / sum F); residual is the larger of the
    line slope and the certificate's deficit, both over sum F.
    """
    px = np.empty(4)
    py = np.empty(4)
    vgroove = np.array([0.0, 0.0, 1.0, 1.0])
    for i in range(4):
        px[i] = _SX[i] * np.sin(beta[i])
        py[i] = _SY[i] * np.cos(beta[i])
    total = force[0] + force[1] + force[2] + force[3]
    trial = np.empty(4)
    tcontact = np.empty((4, 5))
    out = np.empty(5)
    for i in range(2):
        if (force[i] > 0.0 and force[i + 2] > 0.0
                and abs(beta[i] - beta[i + 2]) <= TWO_POINT_ANGLE_TOLERANCE):
            cert = double_stick_solve(i, px, py, vgroove, force, a, b, sigma_scale, rd, hoff,
                                      cin, sin_, win, xo, wo, tr, wr, trial, tcontact) / total
            if cert >= -tol:
                state[:] = trial
                contact[:, :] = tcontact
                regime[0] = REGIME_STICK
                regime[1] = 4 + i
                regime[2] = cert
                info[0] = max(0.0, -cert)
                info[1] = 1.0
                info[2] = 1.0
                return True
    # candidates by decreasing force (the heavy diagonal first), a three-point ball's likely
    # stuck contact before them; a certified line minimum is the minimum of D, so the search
    # stops there
    order = candidate_order(force)
    best_d = np.inf
    best_k = -1
    best_cert = np.nan
    best_res = np.inf
    evals = 0.0
    for m in range(4):
        k = order[m]
        if force[k] <= 0.0:
            continue
        stick_line_solve(k, px, py, vgroove, force, a, b, sigma_scale, table, cin, sin_, win,
                         xo, wo, tol, trial, tcontact, out)
        evals += out[2]
        cert = stick_certificate(out[3], out[4], force[k], a[k], b[k], sigma_scale, table, cin,
                                 sin_, win, xo, wo, scan) / total
        residual = max(out[1], -cert)
        if residual <= tol or (best_res > tol and out[0] < best_d):
            best_d = out[0]
            best_k = k
            best_cert = cert
            best_res = residual
            state[:] = trial
            contact[:, :] = tcontact
        if residual <= tol:
            break
    ok = best_res <= tol
    regime[0] = REGIME_STICK if ok else REGIME_UNSOLVED
    regime[1] = best_k
    regime[2] = best_cert
    info[0] = best_res
    info[1] = evals
    info[2] = 1.0 if ok else 0.0
    return ok


@jit
def two_point_state(i, beta_star, force, px, py, state, contact):
    """Exactly two-point ball (contacts i and i + 2 opposite): rolling at v/2, both stuck.

    v_B = v/2 and Omega = (v / 2R) x_i, x_i = (cos b*, -+ sin b*) (- for BL-TR, + for BR-TL):
    no slip anywhere in either contact, so D = 0, the least value D can take.
    """
    xx = np.cos(beta_star)
    xy = -_SX[i] * _SY[i] * np.sin(beta_star)
    state[0] = 0.5
    state[1] = 0.5 * xx
    state[2] = 0.5 * xy
    state[3] = 0.0
    for m in range(4):
        yx = -px[m]
        yy = -py[m]
        contact[m, 3] = 0.0 if force[m] > 0.0 else state[1] * yx + state[2] * yy
        contact[m, 4] = state[1] * yy - state[2] * yx
        contact[m, 0] = 0.0 if force[m] > 0.0 else np.nan
        contact[m, 1] = 0.0 if force[m] > 0.0 else np.nan
        contact[m, 2] = 0.0


@jit
def stick_criterion_one(force, a, ellip):
    """chi = R sum F_light / ((3/8) E(e) sum F_heavy a_heavy) (R = 1; a in units of R)."""
    d1 = force[0] + force[2]
    d2 = force[1] + force[3]
    if d1 >= d2:
        light = d2
        heavy = 0.375 * ellip * (force[0] * a[0] + force[2] * a[2])
    else:
        light = d1
        heavy = 0.375 * ellip * (force[1] * a[1] + force[3] * a[3])
    if heavy <= 0.0:
        return np.inf
    return light / heavy


@pjit
def regime_kernel(dbeta, force, nominal_angle, semi_major_coefficient, semi_minor_coefficient,
                  ellip, curved, rd, free_spin, tol, max_iter, cin, sin_, win, xo, wo, tr, wr,
                  table, out_state, out_contact, out_info, out_regime):
    """The full model of n balls in every regime (R = 1, v = 1, mu = 1 units).

    Per ball: fewer than two loaded contacts: unsolved (NaN). Two opposite contacts with
    equal angles: rolling at v/2 (:func:`two_point_state`). Otherwise the smooth Newton
    (:func:`~tolsim.physics.velocity._full_kernels.solve_one`, regime A) and, where it does
    not converge (or first, when chi < ``CHI_STICK_FIRST``), the stick solve
    (:func:`stick_solve`, regime B; planar surface with omega_z = 0 only); where neither is
    certified, Newton once more from the stick line's minimum. ``out_regime``
    (n, 3) = (regime code, stuck contact or -1, certificate / sum F or NaN).
    """
    sigma_scale = 1.5 / np.pi
    nonsmooth = not curved and not free_spin
    scan = scan_constants(semi_minor_coefficient / semi_major_coefficient, table, cin, sin_, win,
                          xo, wo)
    for n in prange(dbeta.shape[0]):
        beta = np.empty(4)
        a = np.empty(4)
        b = np.empty(4)
        hoff = np.empty(4)
        px = np.empty(4)
        py = np.empty(4)
        contact_ellipses(dbeta[n], force[n], nominal_angle, semi_major_coefficient,
                         semi_minor_coefficient, rd, beta, a, b, hoff)
        for i in range(4):
            px[i] = _SX[i] * np.sin(beta[i])
            py[i] = _SY[i] * np.cos(beta[i])
        fb = force[n]
        state = np.zeros(4)
        contact = np.full((4, 5), np.nan)
        info = np.zeros(3)
        regime = np.empty(3)
        regime[0] = REGIME_UNSOLVED
        regime[1] = -1.0
        regime[2] = np.nan
        npos = 0
        for i in range(4):
            if fb[i] > 0.0:
                npos += 1
        opposite = -1
        if npos == 2:
            for i in range(2):
                if fb[i] > 0.0 and fb[i + 2] > 0.0:
                    opposite = i
        if (opposite >= 0 and not curved
                and abs(beta[opposite] - beta[opposite + 2]) <= TWO_POINT_ANGLE_TOLERANCE):
            two_point_state(opposite, 0.5 * (beta[opposite] + beta[opposite + 2]), fb, px, py,
                            state, contact)
            info[2] = 1.0
            regime[0] = REGIME_TWO_POINT
            regime[2] = 0.0
        elif npos < 2 or (npos == 2 and (opposite < 0 or not nonsmooth)):
            state[:] = np.nan
            info[0] = np.inf
        elif npos == 2:
            stick_solve(beta, fb, a, b, sigma_scale, rd, hoff, tol, table, cin, sin_, win, xo,
                        wo, tr, wr, scan, state, contact, info, regime)
        else:
            done = False
            tried = False
            s_state = np.full(4, np.nan)
            s_contact = np.empty((4, 5))
            s_info = np.empty(3)
            if nonsmooth and stick_criterion_one(fb, a, ellip) < CHI_STICK_FIRST:
                tried = True
                done = stick_solve(beta, fb, a, b, sigma_scale, rd, hoff, tol, table, cin, sin_,
                                   win, xo, wo, tr, wr, scan, s_state, s_contact, s_info,
                                   regime)
            if not done:
                smooth_solve(beta, fb, a, b, sigma_scale, curved, rd, hoff, free_spin, tol,
                             max_iter, cin, sin_, win, xo, wo, tr, wr, table, state, contact,
                             info)
                if info[2] > 0.5:
                    regime[0] = REGIME_SMOOTH
                    regime[1] = -1.0
                    regime[2] = -info[0]
                    done = True
            if not done and nonsmooth and not tried:
                tried = True
                done = stick_solve(beta, fb, a, b, sigma_scale, rd, hoff, tol, table, cin, sin_,
                                   win, xo, wo, tr, wr, scan, s_state, s_contact, s_info,
                                   regime)
            if done and regime[0] == REGIME_STICK:
                state[:] = s_state
                contact[:, :] = s_contact
                info[:] = s_info
            elif not done and tried and np.isfinite(s_state[0]):
                # Newton again from the best stick line's minimum, which is near the minimum
                # when the smooth start is too far from it
                solve_one(beta, fb, a, b, sigma_scale, curved, rd, hoff, free_spin, tol,
                          max_iter, cin, sin_, win, xo, wo, tr, wr, s_state, s_contact,
                          s_info, 0, 0.0, 0.0, 1.0, True)
                if s_info[2] > 0.5:
                    state[:] = s_state
                    contact[:, :] = s_contact
                    info[:] = s_info
                    regime[0] = REGIME_SMOOTH
                    regime[1] = -1.0
                    regime[2] = -info[0]
                    done = True
            if not done:
                regime[0] = REGIME_UNSOLVED
                regime[1] = -1.0
        for k in range(4):
            out_state[n, k] = state[k]
            for m in range(5):
                out_contact[n, k, m] = contact[k, m]
        for m in range(3):
            out_info[n, m] = info[m]
            out_regime[n, m] = regime[m]
