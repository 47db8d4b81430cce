"""Numba kernels of the full model's fast path: tables of the planar contact integrals, the
ball's loads with their exact Jacobian from them, and the Newton solve of regime A on them.

The tables (built by :func:`tolsim.physics.velocity.full.contact_table`) and why they give the
quadrature's answer to round-off are in the Notes of that function.
"""

import math

import numpy as np

from tolsim._jit import jit
from tolsim.physics.velocity._full_kernels import (
    SLIDING_POLE,
    planar_contact_integrals,
    rolling_start,
    solve_small,
)

#: Chebyshev degree of each piece of the tables.
TABLE_DEGREE = 11
#: Dyadic ranges per table: y = 1 - |x| in [2^-(k+1), 2^-k], k < TABLE_PIECES ...
TABLE_PIECES = 44
#: ... each cut into TABLE_SUBPIECES equal pieces.
TABLE_SUBPIECES = 8
#: Closer to |p| = 1 (y < 2^-TABLE_PIECES, where the integrals are singular) the table holds the
#: quadrature's values at each of the NEAR_FLOATS floats next to 1 (|p| = 1 - m 2^-53 inside,
#: 1 + m 2^-52 outside, m < NEAR_FLOATS), stored in the extra pieces after the fits.
NEAR_FLOATS = 2 ** (53 - TABLE_PIECES)
#: :func:`table_newton_solve` iterates until the residual is below POLISH ``tol``; above
#: ROUND_OFF ``tol`` it then takes one more Newton step if that lowers the residual (the
#: root to round-off).
POLISH = 1e-2
ROUND_OFF = 1e-4
_SX = (-1.0, 1.0, 1.0, -1.0)
_SY = (-1.0, -1.0, 1.0, 1.0)


@jit
def direct_integrals(p, a, b, cin, sin_, win, xo, wo, out):
    """(S_z, S_n, S_d) of :func:`planar_contact_integrals` at the pole (p a, 0) and their
    central differences in p (step 1e-7 max(1, |p|)) into ``out`` (6,): the tables' fallback."""
    s3 = np.empty(4)
    planar_contact_integrals(p, 0.0, a, b, cin, sin_, win, xo, wo, s3)
    out[0] = s3[1]
    out[1] = s3[2]
    out[2] = s3[3]
    h = 1e-7 * max(1.0, abs(p))
    planar_contact_integrals(p + h, 0.0, a, b, cin, sin_, win, xo, wo, s3)
    out[3] = s3[1]
    out[4] = s3[2]
    out[5] = s3[3]
    planar_contact_integrals(p - h, 0.0, a, b, cin, sin_, win, xo, wo, s3)
    out[3] = (out[3] - s3[1]) / (2.0 * h)
    out[4] = (out[4] - s3[2]) / (2.0 * h)
    out[5] = (out[5] - s3[3]) / (2.0 * h)


@jit
def sample_kernel(table, sign, y, q, cin, sin_, win, xo, wo, out):
    """Samples of table 0 (inside, x = p) or 1 (outside, x = 1/p) on side ``sign`` of x, at
    about y = 1 - |x| (a = 1, b = q).

    ``out[k]`` = (y, S_z, S_n, S_d), y being the value :func:`table_integrals` computes from
    the p that is evaluated (x = sign (1 - y) rounds); outside, S_n and S_d times |x|.
    """
    s3 = np.empty(4)
    for k in range(y.shape[0]):
        x = sign * (1.0 - y[k])
        p = x if table == 0 else 1.0 / x
        xe = p if table == 0 else 1.0 / p
        planar_contact_integrals(p, 0.0, 1.0, q, cin, sin_, win, xo, wo, s3)
        scale = 1.0 if table == 0 else abs(xe)
        out[k, 0] = 1.0 - abs(xe)
        out[k, 1] = s3[1]
        out[k, 2] = scale * s3[2]
        out[k, 3] = scale * s3[3]


@jit
def near_kernel(q, cin, sin_, win, xo, wo, out):
    """:func:`direct_integrals` (a = 1, b = q) at the floats next to |p| = 1: ``out`` (4, m, 6)
    for p = 1 - m 2^-53, -(1 - m 2^-53), 1 + m 2^-52, -(1 + m 2^-52)."""
    o = np.empty(6)
    for t in range(4):
        sign = 1.0 if t % 2 == 0 else -1.0
        for m in range(out.shape[1]):
            p = sign * (1.0 - m * 2.0**-53 if t < 2 else 1.0 + m * 2.0**-52)
            direct_integrals(p, 1.0, q, cin, sin_, win, xo, wo, o)
            for j in range(6):
                out[t, m, j] = o[j]


@jit
def table_integrals(p, a, b, table, cin, sin_, win, xo, wo, out):
    """S = (S_z, S_n, S_d) of :func:`planar_contact_integrals` at the pole (p a, 0) and dS/dp.

    Writes (S_z, S_n, S_d, dS_z/dp, dS_n/dp, dS_d/dp) into ``out`` (only the first three when
    ``out`` has three entries): from ``table``
    (:func:`tolsim.physics.velocity.full.contact_table`); within 2^-TABLE_PIECES of |p| = 1
    the stored :func:`direct_integrals` of that float.
    """
    ap = abs(p)
    inside = ap <= 1.0
    x = p if inside else 1.0 / p
    y = 1.0 - abs(x)
    t = (0 if x >= 0.0 else 1) + (0 if inside else 2)
    k = 0
    if y < 1.0:
        k = -math.frexp(y)[1]
    ndeg = table.shape[3]
    with_derivative = out.shape[0] > 3
    if y <= 0.0 or k >= TABLE_PIECES:
        m = int((1.0 - ap) * 2.0**53) if inside else int((ap - 1.0) * 2.0**52)
        if m >= NEAR_FLOATS:
            full6 = np.empty(6)
            direct_integrals(p, a, b, cin, sin_, win, xo, wo, full6)
            for c in range(out.shape[0]):
                out[c] = full6[c]
            return
        near = table[t, TABLE_PIECES * TABLE_SUBPIECES + m // ndeg]
        col = m % ndeg
        out[0] = near[0, col]
        out[1] = a * near[1, col]
        out[2] = a * near[2, col]
        if with_derivative:
            out[3] = near[3, col]
            out[4] = a * near[4, col]
            out[5] = a * near[5, col]
        return
    u = (y * math.ldexp(1.0, k + 1) - 1.0) * TABLE_SUBPIECES
    j = min(int(u), TABLE_SUBPIECES - 1)
    s = 2.0 * (u - j) - 1.0
    coef = table[t, k * TABLE_SUBPIECES + j]
    # T_j(s) by the recurrence, summed against the six coefficient rows
    f0 = coef[0, 0]
    f1 = coef[1, 0]
    f2 = coef[2, 0]
    g0 = 0.0
    g1 = 0.0
    g2 = 0.0
    tm = 1.0
    tj = s
    if with_derivative:
        g0 = coef[3, 0]
        g1 = coef[4, 0]
        g2 = coef[5, 0]
        for c in range(1, ndeg):
            f0 += coef[0, c] * tj
            f1 += coef[1, c] * tj
            f2 += coef[2, c] * tj
            g0 += coef[3, c] * tj
            g1 += coef[4, c] * tj
            g2 += coef[5, c] * tj
            tn = 2.0 * s * tj - tm
            tm = tj
            tj = tn
    else:
        for c in range(1, ndeg):
            f0 += coef[0, c] * tj
            f1 += coef[1, c] * tj
            f2 += coef[2, c] * tj
            tn = 2.0 * s * tj - tm
            tm = tj
            tj = tn
    sgn = 1.0 if x >= 0.0 else -1.0
    if inside:
        # y = 1 - sgn p
        out[0] = f0
        out[1] = a * f1
        out[2] = a * f2
        if not with_derivative:
            return
        out[3] = -sgn * g0
        out[4] = -sgn * a * g1
        out[5] = -sgn * a * g2
    else:
        # y = 1 - sgn / p, dy/dp = sgn x^2; the last two tabulated times |x| = sgn x
        out[0] = f0
        out[1] = a * f1 * sgn * p
        out[2] = a * f2 * sgn * p
        if not with_derivative:
            return
        out[3] = sgn * x * x * g0
        # d(f / |x|)/dp = d(f sgn p)/dp = sgn (p df/dp + f), df/dp = sgn x^2 g
        out[4] = a * (x * g1 + sgn * f1)
        out[5] = a * (x * g2 + sgn * f2)


@jit
def table_ball_loads(state, px, py, vgroove, force, semi_major, semi_minor, sigma_scale, table,
                     cin, sin_, win, xo, wo, loads, contact, jac, o):
    """:func:`~tolsim.physics.velocity._full_kernels.ball_loads_kernel` of a planar ball with
    omega_z = 0 from the tables, and the Jacobian of (F_z, M_x, M_y).

    The same outputs (``loads[3]``, M_z, is 0: it vanishes with omega_z = 0 by the symmetry of
    the grid), plus ``jac`` (3, 3) = d(F_z, M_x, M_y)/d(v_B, omega_x, omega_y), exact for the
    tabulated integrals: contact i adds the rank-one term sgn(omega_i) sigma F_i
    (dS_z, dS_n)/dp (dp_i/dx) with p_i = u_i / (omega_i a_i), u_i = v_B - V_i - Omega . x_i,
    omega_i = Omega . y_i (R = v = mu = 1 units). ``o`` (6,) is scratch.
    """
    with_power = contact.shape[1] > 5
    vb = state[0]
    wx = state[1]
    wy = state[2]
    fz_tot = 0.0
    mx = 0.0
    my = 0.0
    power = 0.0
    for r in range(3):
        for c in range(3):
            jac[r, c] = 0.0
    for i in range(4):
        f = force[i]
        a = semi_major[i]
        yx = -px[i]
        yy = -py[i]
        xx = yy
        xy = -yx
        om = wx * yx + wy * yy
        wr_ = wx * xx + wy * xy
        u0 = vb - vgroove[i] - wr_
        contact[i, 3] = om
        contact[i, 4] = wr_
        power_before = power
        if f <= 0.0:
            contact[i, 0] = np.nan
            contact[i, 1] = np.nan
            contact[i, 2] = 0.0
            if with_power:
                contact[i, 5] = 0.0
            continue
        if abs(om) * SLIDING_POLE * a > abs(u0):
            pt = u0 / om / a
            ps = -0.0 / om
            table_integrals(pt, a, semi_minor[i], table, cin, sin_, win, xo, wo, o)
            scale = sigma_scale * f * (1.0 if om > 0.0 else -1.0)
            fz = scale * o[0]
            mn = scale * o[1]
            power += sigma_scale * f * abs(om) * o[2]
            inv = 1.0 / (om * a)
            g0 = inv
            g1 = (-xx - pt * a * yx) * inv
            g2 = (-xy - pt * a * yy) * inv
            dfz = scale * o[3]
            dmn = scale * o[4]
            dmx = -xx * dfz + yx * dmn
            dmy = -xy * dfz + yy * dmn
            jac[0, 0] += dfz * g0
            jac[0, 1] += dfz * g1
            jac[0, 2] += dfz * g2
            jac[1, 0] += dmx * g0
            jac[1, 1] += dmx * g1
            jac[1, 2] += dmx * g2
            jac[2, 0] += dmy * g0
            jac[2, 1] += dmy * g1
            jac[2, 2] += dmy * g2
        else:
            pt = np.inf
            ps = 0.0
            slip = abs(u0)
            fz = -f * u0 / slip if slip > 0.0 else 0.0
            mn = 0.0
            power += f * slip
        fz_tot += fz
        mx += -fz * xx + mn * yx
        my += -fz * xy + mn * yy
        contact[i, 0] = pt
        contact[i, 1] = ps
        contact[i, 2] = fz
        if with_power:
            contact[i, 5] = power - power_before
    loads[0] = fz_tot
    loads[1] = mx
    loads[2] = my
    loads[3] = 0.0
    loads[4] = power


@jit
def _table_equilibrium(state, px, py, vgroove, force, a, b, sigma_scale, table, cin, sin_, win,
                       xo, wo, total, loads, contact, jac, res, o):
    """(F_z, M_x, M_y) / sum F into ``res`` and its Jacobian into ``jac``; max |res| (inf if
    NaN)."""
    table_ball_loads(state, px, py, vgroove, force, a, b, sigma_scale, table, cin, sin_, win, xo,
                     wo, loads, contact, jac, o)
    worst = 0.0
    for k in range(3):
        res[k] = loads[k] / total
        worst = max(worst, abs(res[k]))
        for c in range(3):
            jac[k, c] /= total
    if not np.isfinite(worst):
        worst = np.inf
    return worst


@jit
def table_newton_solve(beta, force, a, b, sigma_scale, tol, max_iter, table, cin, sin_, win, xo,
                       wo, state, contact, info):
    """Regime A on the planar surface with omega_z = 0: Newton's method on the tables.

    The equations, start (pure rolling) and step acceptance of
    :func:`~tolsim.physics.velocity._full_kernels.solve_one` (a step is taken when it lowers
    the sum of squares of the residual or D, Armijo; backtracking by halves), with the exact
    Jacobian of :func:`table_ball_loads`: one evaluation per step, quadratic convergence. It
    iterates to ``POLISH * tol`` and then, unless the residual is below ``ROUND_OFF * tol``,
    takes one more step if that lowers the residual, so that the answer is the root to
    round-off. Writes ``state``, ``contact``, ``info`` =
    (residual, iterations, converged) as ``solve_one``; returns False (the caller falls back)
    unless residual <= tol.
    """
    px = np.empty(4)
    py = np.empty(4)
    vgroove = np.array([0.0, 0.0, 1.0, 1.0])
    for i in range(4):
        px[i] = _SX[i] * np.sin(beta[i])
        py[i] = _SY[i] * np.cos(beta[i])
    total = force[0] + force[1] + force[2] + force[3]
    rolling_start(beta, force, px, py, vgroove, state)
    loads = np.empty(5)
    res = np.empty(3)
    res_new = np.empty(3)
    neg = np.empty(3)
    step = np.zeros(3)
    trial = np.zeros(4)
    jac = np.empty((3, 3))
    jac_new = np.empty((3, 3))
    work = np.empty((4, contact.shape[1]))
    o = np.empty(6)
    worst = _table_equilibrium(state, px, py, vgroove, force, a, b, sigma_scale, table, cin,
                               sin_, win, xo, wo, total, loads, contact, jac, res, o)
    dis = loads[4]
    target = POLISH * tol
    it = 0
    polish = False
    while it < max_iter and (worst > target or not polish) and worst > ROUND_OFF * tol:
        if worst <= target:
            polish = True
        it += 1
        merit = 0.0
        for r in range(3):
            neg[r] = -res[r]
            merit += res[r] * res[r]
        if not solve_small(jac, neg, 3, step):
            break
        accepted = False
        t = 1.0
        new = worst
        for _ls in range(30 if not polish else 1):
            for c in range(3):
                trial[c] = state[c] + t * step[c]
            trial[3] = 0.0
            new = _table_equilibrium(trial, px, py, vgroove, force, a, b, sigma_scale, table,
                                     cin, sin_, win, xo, wo, total, loads, work, jac_new,
                                     res_new, o)
            if polish:
                accepted = new < worst
                break
            msum = 0.0
            slope = 0.0  # directional derivative of D: gradient = -loads
            for r in range(3):
                msum += res_new[r] * res_new[r]
                slope -= res[r] * step[r] * total
            if (msum < (1.0 - 1e-4 * t) * merit or new <= target
                    or loads[4] <= dis + 1e-4 * t * slope):
                accepted = True
                break
            t *= 0.5
        if not accepted:
            break
        for c in range(3):
            state[c] = trial[c]
            res[c] = res_new[c]
            for r in range(3):
                jac[r, c] = jac_new[r, c]
        state[3] = 0.0
        contact[:, :] = work
        worst = new
        dis = loads[4]
    info[0] = worst
    info[1] = it
    info[2] = 1.0 if worst <= tol else 0.0
    return worst <= tol
