"""Numba kernels of the static contact model: flank geometry, Newton solves, vectorised lanes."""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics._fastmath import SMALL_ANGLE, SMALL_TAN, atan_small, sin_cosm1_small

#: Newton ends with an unverified full step once the relative residual is below
#: _PREDICT sqrt(tol) (see ``flank_newton``).
_PREDICT = 0.1
#: Length scale [m] that sets the absolute force floor K * (1 nm)^1.5 of the tolerance (so a
#: ball that loses all contact still converges).
FLOOR_LENGTH = 1e-9


# --------------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------------
@jit(inline="always")
def _idx(arr, n):
    """Row n of an input whose first axis is n_balls or 1 (broadcast without copying)."""
    # (the prange index may be unsigned: keep both branches int64 so they unify)
    return np.int64(n) if arr.shape[0] > 1 else np.int64(0)


@jit(leaf=True)
def arc_centres(n, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist, cen):
    """Arc centres of the four flanks of ball n (top groove at g = 0) into cen (4, 6).

    Row i holds the arc centre C_i (x, y), its offset from the nominal centre C_i + d n_i
    (x, y), and n_i (x, y). The offsets are computed directly (small numbers, full relative
    precision) so that the approach keeps its precision even when it is 1e-10 of d.
    """
    i_n = _idx(e_n, n)
    i_t = _idx(e_t, n)
    for groove in range(2):
        if groove == 0:
            th = rot_b[_idx(rot_b, n)]
            ox = off_b[_idx(off_b, n), 0]
            oy = off_b[_idx(off_b, n), 1]
        else:
            th = rot_t[_idx(rot_t, n)]
            ox = off_t[_idx(off_t, n), 0]
            oy = off_t[_idx(off_t, n), 1]
        ct, st = np.cos(th), np.sin(th)
        sh = np.sin(0.5 * th)
        cm1 = -2.0 * sh * sh  # cos(th) - 1 without cancellation
        for i in range(2 * groove, 2 * groove + 2):
            sx = -1.0 if (i == 0 or i == 3) else 1.0
            sy = -1.0 if i < 2 else 1.0
            nx, ny = sx * s0, sy * c0  # n_i
            tx, ty = sx * c0, -sy * s0  # t_i = dn_i/dbeta
            en = e_n[i_n, i]
            et = e_t[i_t, i]
            x = en * nx - et * tx  # offset before the rotation
            y = en * ny - et * ty
            # C_i + d n_i = -d (Rot n_i - n_i) + Rot (e_n n_i - e_t t_i) + offset
            dcx = -dist * (cm1 * nx - st * ny) + ct * x - st * y + ox
            dcy = -dist * (st * nx + cm1 * ny) + st * x + ct * y + oy
            cen[i, 0] = dcx - dist * nx
            cen[i, 1] = dcy - dist * ny
            cen[i, 2] = dcx
            cen[i, 3] = dcy
            cen[i, 4] = nx
            cen[i, 5] = ny


@jit(inline="always")
def flank(px, py, cen, i, d, h, k):
    """Contact direction, 1/distance, approach, force and force slope of flank i.

    delta = |P - C_i| - (d - h) is evaluated as (|v|^2 + 2 d n.v + h (2 d - h)) / (|P - C_i|
    + d - h) with v = P - (C_i + d n_i), free of the cancellation of two ~d numbers.
    """
    vx = px - cen[i, 2]
    vy = py - cen[i, 3]
    nx = cen[i, 4]
    ny = cen[i, 5]
    wx = vx + d * nx
    wy = vy + d * ny
    dist = np.sqrt(wx * wx + wy * wy)
    inv = 1.0 / dist
    ux = wx * inv
    uy = wy * inv
    delta = (vx * vx + vy * vy + 2.0 * d * (nx * vx + ny * vy) + h * (2.0 * d - h)) / (
        dist + d - h)
    if delta > 0.0:
        sd = np.sqrt(delta)
        return ux, uy, inv, delta, k * delta * sd, 1.5 * k * sd
    return ux, uy, inv, delta, 0.0, 0.0


@jit(leaf=True)
def _residual(cen, i0, i1, d, h, k, tx, ty, px, py):
    """r = sum_i F_i u_i - T over flanks i0..i1-1, its Jacobian (symmetric) and max F_i."""
    rx = -tx
    ry = -ty
    j11 = 0.0
    j12 = 0.0
    j22 = 0.0
    fmax = 0.0
    for i in range(i0, i1):
        ux, uy, inv, delta, f, df = flank(px, py, cen, i, d, h, k)
        if f > 0.0:
            rx += f * ux
            ry += f * uy
            g = f * inv  # transverse stiffness: d u / dP = (I - u u^T) / |P - C|
            j11 += df * ux * ux + g * (1.0 - ux * ux)
            j12 += df * ux * uy - g * ux * uy
            j22 += df * uy * uy + g * (1.0 - uy * uy)
            if f > fmax:
                fmax = f
    return rx, ry, j11, j12, j22, fmax


@jit(leaf=True)
def flank_newton(cen, i0, i1, d, h, k, tx, ty, px, py, tol, max_iter, floor, reg, predict):
    """Newton with backtracking on |r| for sum_i F_i u_i = T; returns px, py, iters, ok, |r|.

    With ``predict``, a full step taken from a residual below ``_PREDICT sqrt(tol)`` of the
    force scale ends the iteration without re-evaluating: Newton converges quadratically
    (relative residual e -> about 0.2 e^2 here), so that step lands within tol. The caller
    must verify the result (``_load_one`` does, from the final outputs).
    """
    tnorm = max(abs(tx), abs(ty))
    it = 0
    ok = False
    rx, ry, j11, j12, j22, fmax = _residual(cen, i0, i1, d, h, k, tx, ty, px, py)
    rinf = max(abs(rx), abs(ry))
    while True:
        scale = max(tnorm, fmax, floor)
        if rinf <= tol * scale:
            ok = True
            break
        if it >= max_iter:
            break
        it += 1
        det = j11 * j22 - j12 * j12
        trace = j11 + j22
        if not (det > 1e-12 * trace * trace) or trace == 0.0:
            j11 += reg
            j22 += reg
            det = j11 * j22 - j12 * j12
        dx = -(j22 * rx - j12 * ry) / det
        dy = -(-j12 * rx + j11 * ry) / det
        if predict and rinf <= _PREDICT * np.sqrt(tol) * scale:
            px += dx
            py += dy
            ok = True
            break
        # keep a step well inside the arch (far larger than any elastic approach)
        step = np.sqrt(dx * dx + dy * dy)
        if step > 0.1 * d:
            dx *= 0.1 * d / step
            dy *= 0.1 * d / step
        r2 = rx * rx + ry * ry
        alpha = 1.0
        nx_, ny_ = px + dx, py + dy
        sx_, sy_, a11, a12, a22, fm = rx, ry, j11, j12, j22, fmax
        for _ in range(40):
            nx_, ny_ = px + alpha * dx, py + alpha * dy
            sx_, sy_, a11, a12, a22, fm = _residual(cen, i0, i1, d, h, k, tx, ty, nx_, ny_)
            s2 = sx_ * sx_ + sy_ * sy_
            if s2 <= (1.0 - 1e-4 * alpha) * r2:
                break
            alpha *= 0.5
        px, py = nx_, ny_
        rx, ry, j11, j12, j22, fmax = sx_, sy_, a11, a12, a22, fm
        rinf = max(abs(rx), abs(ry))
    return px, py, it, ok, rinf


@jit(leaf=True)
def _groove(cen, i0, d, h, refx, refy, tx, ty, k, rigid, tol, max_iter, floor, predict):
    """Solve one groove (flanks i0, i0+1) for the ball position relative to it.

    Returns px, py, iterations, status (0 converged, 1 Newton failed, 2 no compressive
    equilibrium or no geometric position).
    """
    length = d - h
    ax, ay = cen[i0, 0], cen[i0, 1]
    bx, by = cen[i0 + 1, 0], cen[i0 + 1, 1]
    # Geometric two-flank position: intersection of circles of radius `length` about A and B.
    mx, my = 0.5 * (ax + bx), 0.5 * (ay + by)
    dx, dy = bx - ax, by - ay
    half2 = 0.25 * (dx * dx + dy * dy)
    h2 = length * length - half2
    if not (h2 > 0.0):
        return refx, refy, 0, 2
    s = np.sqrt(h2 / (4.0 * half2))
    c1x, c1y = mx - dy * s, my + dx * s
    c2x, c2y = mx + dy * s, my - dx * s
    if (c1x - refx) ** 2 + (c1y - refy) ** 2 <= (c2x - refx) ** 2 + (c2y - refy) ** 2:
        px, py = c1x, c1y
    else:
        px, py = c2x, c2y
    # Statics with both flanks touching: F_a u_a + F_b u_b = T.
    uax, uay = (px - ax) / length, (py - ay) / length
    ubx, uby = (px - bx) / length, (py - by) / length
    det = uax * uby - uay * ubx
    fa = (tx * uby - ty * ubx) / det
    fb = (uax * ty - uay * tx) / det
    tnorm = np.sqrt(tx * tx + ty * ty)
    single = -1
    if fa >= 0.0 and fb >= 0.0:
        pass
    elif fa >= 0.0 or fb >= 0.0:
        # one flank alone: its contact direction is parallel to the load
        single = i0 if fa >= 0.0 else i0 + 1
        ex, ey = tx / tnorm, ty / tnorm
        px = cen[single, 0] + length * ex
        py = cen[single, 1] + length * ey
    else:
        return px, py, 0, 2
    if rigid:
        return px, py, 0, 0
    # Elastic start: move by the Hertz approaches of the rigid forces.
    if single < 0:
        da = np.cbrt(fa / k) ** 2
        db = np.cbrt(fb / k) ** 2
        px += (da * uby - db * uay) / det
        py += (uax * db - ubx * da) / det
    else:
        d0 = np.cbrt(tnorm / k) ** 2
        px += d0 * tx / tnorm
        py += d0 * ty / tnorm
    # contact stiffness dF/ddelta = 1.5 K^(2/3) F^(1/3) at F = |T|: the fallback regularisation
    reg = 1.5 * k * np.cbrt(max(tnorm, floor) / k)
    px, py, it, ok, _ = flank_newton(cen, i0, i0 + 2, d, h, k, tx, ty, px, py, tol,
                                     max_iter, floor, reg, predict)
    return px, py, it, 0 if ok else 1


@jit(leaf=True)
def ball_outputs(n, cen, px, py, d, h, k, out_dbeta, out_force, out_approach, unit):
    """Contact-angle deviations, forces, approaches (and u_i into unit) of ball n at P.

    dbeta_i = atan2(t_i . u_i, n_i . u_i), since u_i = cos(dbeta_i) n_i + sin(dbeta_i) t_i;
    t_i = sx sy (n_iy, -n_ix).
    """
    count = 0
    for i in range(4):
        ux, uy, _, delta, f, _ = flank(px, py, cen, i, d, h, k)
        unit[i, 0] = ux
        unit[i, 1] = uy
        nx, ny = cen[i, 4], cen[i, 5]
        sxy = 1.0 if (i == 0 or i == 2) else -1.0
        out_dbeta[n, i] = np.arctan2(sxy * (ny * ux - nx * uy), nx * ux + ny * uy)
        out_approach[n, i] = delta
        out_force[n, i] = f
        if f > 0.0:
            count += 1
    return count


@jit(inline="always")
def _imbalance(n, unit, out_force, lx, ly):
    """Max |force imbalance| [N] of the ball and of the top groove from the final u_i, F_i."""
    bx = 0.0
    by = 0.0
    tx = lx
    ty = ly
    for i in range(4):
        fx = out_force[n, i] * unit[i, 0]
        fy = out_force[n, i] * unit[i, 1]
        bx -= fx
        by -= fy
        if i >= 2:
            tx += fx
            ty += fy
    return max(max(abs(bx), abs(by)), max(abs(tx), abs(ty)))


@jit(inline="always")
def move_top_groove(cen, gx, gy):
    """Translate the top groove's arc centres (rows 2, 3) by g."""
    for i in range(2, 4):
        cen[i, 0] += gx
        cen[i, 1] += gy
        cen[i, 2] += gx
        cen[i, 3] += gy


@jit(inline="always")  # inlined into the parallel loop: 15-25 % faster than a call
def _load_one(n, side_load, normal_load, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, s0,
              c0, dist, k, rigid, tol, max_iter, floor, cen, unit,
              out_dbeta, out_force, out_approach, out_ball, out_groove, out_converged,
              out_iter, out_count, out_residual):
    """Load-controlled solution of ball n (cen, unit: work arrays)."""
    arc_centres(n, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist, cen)
    h = 0.5 * oversize[_idx(oversize, n)]
    lx = side_load[_idx(side_load, n)]
    ly = -normal_load[_idx(normal_load, n)]
    ib, it_ = _idx(off_b, n), _idx(off_t, n)
    px, py, nb, sb = _groove(cen, 0, dist, h, off_b[ib, 0], off_b[ib, 1], lx, ly, k,
                             rigid, tol, max_iter, floor, True)
    qx, qy, nt, st = _groove(cen, 2, dist, h, off_t[it_, 0], off_t[it_, 1], -lx, -ly, k,
                             rigid, tol, max_iter, floor, True)
    gx, gy = px - qx, py - qy
    move_top_groove(cen, gx, gy)
    count = ball_outputs(n, cen, px, py, dist, h, k, out_dbeta, out_force, out_approach, unit)
    if not rigid and sb == 0 and st == 0:
        # verify the predicted last Newton steps on the final state; polish if needed
        fmax = max(max(out_force[n, 0], out_force[n, 1]), max(out_force[n, 2], out_force[n, 3]))
        scale = max(max(abs(lx), abs(ly)), max(fmax, floor))
        if _imbalance(n, unit, out_force, lx, ly) > 2.0 * tol * scale:
            move_top_groove(cen, -gx, -gy)
            reg = 1.5 * k * np.cbrt(max(np.sqrt(lx * lx + ly * ly), floor) / k)
            px, py, mb, okb, _ = flank_newton(cen, 0, 2, dist, h, k, lx, ly, px, py, tol,
                                              max_iter, floor, reg, False)
            qx, qy, mt, okt, _ = flank_newton(cen, 2, 4, dist, h, k, -lx, -ly, qx, qy, tol,
                                              max_iter, floor, reg, False)
            nb += mb
            nt += mt
            sb = 0 if okb else 1
            st = 0 if okt else 1
            gx, gy = px - qx, py - qy
            move_top_groove(cen, gx, gy)
            count = ball_outputs(n, cen, px, py, dist, h, k, out_dbeta, out_force,
                                 out_approach, unit)
    if rigid:  # forces from statics at zero approach
        count = 0
        for i0 in (0, 2):
            sgn = 1.0 if i0 == 0 else -1.0
            uax, uay = unit[i0, 0], unit[i0, 1]
            ubx, uby = unit[i0 + 1, 0], unit[i0 + 1, 1]
            tx, ty = sgn * lx, sgn * ly
            det = uax * uby - uay * ubx
            fa = (tx * uby - ty * ubx) / det
            fb = (uax * ty - uay * tx) / det
            if fa < 0.0 or fb < 0.0:  # one flank alone carries the load
                tn = np.sqrt(tx * tx + ty * ty)
                fa, fb = (tn, 0.0) if fa >= 0.0 else (0.0, tn)
            out_force[n, i0] = fa
            out_force[n, i0 + 1] = fb
            out_approach[n, i0] = min(out_approach[n, i0], 0.0) if fa == 0.0 else 0.0
            out_approach[n, i0 + 1] = (min(out_approach[n, i0 + 1], 0.0) if fb == 0.0
                                       else 0.0)
            count += (fa > 0.0) + (fb > 0.0)
    out_count[n] = count
    out_ball[n, 0] = px
    out_ball[n, 1] = py
    out_groove[n, 0] = gx
    out_groove[n, 1] = gy
    out_converged[n] = sb == 0 and st == 0
    out_iter[n] = max(nb, nt)
    out_residual[n] = _imbalance(n, unit, out_force, lx, ly)


# --------------------------------------------------------------------------------------------
# Vectorised fast path of the load-controlled solution
# --------------------------------------------------------------------------------------------
# The scalar solver above branches (line search, loss of contact, convergence tests) and so
# runs one ball at a time. Almost every ball of a tolerance study is in four-point contact a
# few micrometres from the nominal state, where the same Newton iteration needs no branch:
# start from the elastic start of ``_groove``, take _LANE_STEPS full steps, evaluate. The
# kernels below do exactly that for a tile of balls held as structure-of-arrays rows of a work
# array ``w`` (row r, lane j), with loop bodies free of calls and branches so that LLVM
# vectorises them across balls (4 balls per AVX2 instruction). Sines of the groove rotations
# and the final arctangents are short Taylor series, exact to round-off in their stated
# ranges. Each ball's result is then verified exactly as the scalar path verifies its own
# (force imbalance of the ball and the top groove <= 2 tol, from the final outputs, and four
# positive approaches); a ball that fails, or is outside a series range, is solved again by
# ``_load_one``. A ball's result depends only on its own inputs, never on its tile.
#
# _LANE_STEPS: the elastic start leaves a relative force imbalance of about 1e-2 (the elastic
# change of the contact angles, ~0.5 deg at these loads, which the start ignores). Measured on
# 1280 tolerance-sized balls (median / worst): 1.3e-2 / 2.6e-2 at the start, then
# 6e-5 / 2e-4, 1.5e-9 / 4.5e-8 and 4e-16 / 5e-15 after one, two and three Newton steps.
_LANE_STEPS = 3
#: Balls per tile (work array: _ROWS x _TILE doubles, 25 kB: stays in L1).
_TILE = 64
# Rows of the work array: inputs, then per-flank state (flanks BL, BR, TR, TL).
_W_EN, _W_ET = 0, 4  # e_n, e_t (4 rows each)
_W_ROT = 8  # theta_b, theta_t
_W_OFF = 10  # offsets: bottom x, y, top x, y
_W_H, _W_LX, _W_LY, _W_Q = 14, 15, 16, 17  # dD/2, N_x, -N_y, cbrt(|N| / K)
_W_DC = 18  # C_i + d n_i (x, y per flank: 8 rows)
_W_P = 26  # ball centre relative to the bottom groove (x, y), to the top groove (x, y)
_W_F, _W_UX, _W_UY, _W_DL, _W_DB = 30, 34, 38, 42, 46  # F_i, u_i, delta_i, dbeta_i
_ROWS = 50


@jit(inline="always")
def _nominal(i, s0, c0):
    """n_i and the signs (sx, sy) of flank i (:class:`GrooveErrors` Notes)."""
    sx = -1.0 if (i == 0 or i == 3) else 1.0
    sy = -1.0 if i < 2 else 1.0
    return sx * s0, sy * c0, sx, sy


@jit(leaf=True)
def _lane_gather(lo, m, side_load, normal_load, e_n, e_t, rot_b, rot_t, off_b, off_t,
                 oversize, k, w):
    """Inputs of balls lo..lo+m-1 into the rows of w (resolving the broadcast)."""
    for j in range(m):
        n = lo + j
        ie, it_ = _idx(e_n, n), _idx(e_t, n)
        for i in range(4):
            w[_W_EN + i, j] = e_n[ie, i]
            w[_W_ET + i, j] = e_t[it_, i]
        w[_W_ROT, j] = rot_b[_idx(rot_b, n)]
        w[_W_ROT + 1, j] = rot_t[_idx(rot_t, n)]
        ib, iq = _idx(off_b, n), _idx(off_t, n)
        w[_W_OFF, j] = off_b[ib, 0]
        w[_W_OFF + 1, j] = off_b[ib, 1]
        w[_W_OFF + 2, j] = off_t[iq, 0]
        w[_W_OFF + 3, j] = off_t[iq, 1]
        w[_W_H, j] = 0.5 * oversize[_idx(oversize, n)]
        lx = side_load[_idx(side_load, n)]
        ly = -normal_load[_idx(normal_load, n)]
        w[_W_LX, j] = lx
        w[_W_LY, j] = ly
        w[_W_Q, j] = np.cbrt(np.sqrt(lx * lx + ly * ly) / k)


@jit(leaf=True)
def _lane_start(m, groove, s0, c0, d, k, w):
    """Arc centres and elastic start of one groove (0 bottom, 1 top) for lanes 0..m-1.

    As ``arc_centres`` and ``_groove`` (two-flank branch) without the branches; a lane with
    a one-flank rigid solution or a rotation beyond the series range gets P = NaN.
    """
    ia = 2 * groove
    ib = ia + 1
    sgn = 1.0 if groove == 0 else -1.0  # load on this groove: +-(N_x, -N_y)
    nax, nay, sxa, sya = _nominal(ia, s0, c0)
    nbx, nby, sxb, syb = _nominal(ib, s0, c0)
    tax, tay = sxa * c0, -sya * s0
    tbx, tby = sxb * c0, -syb * s0
    for j in range(m):
        th = w[_W_ROT + groove, j]
        ox = w[_W_OFF + 2 * groove, j]
        oy = w[_W_OFF + 2 * groove + 1, j]
        st, cm1 = sin_cosm1_small(th)
        ct = 1.0 + cm1
        x = w[_W_EN + ia, j] * nax - w[_W_ET + ia, j] * tax
        y = w[_W_EN + ia, j] * nay - w[_W_ET + ia, j] * tay
        dax = -d * (cm1 * nax - st * nay) + ct * x - st * y + ox
        day = -d * (st * nax + cm1 * nay) + st * x + ct * y + oy
        x = w[_W_EN + ib, j] * nbx - w[_W_ET + ib, j] * tbx
        y = w[_W_EN + ib, j] * nby - w[_W_ET + ib, j] * tby
        dbx = -d * (cm1 * nbx - st * nby) + ct * x - st * y + ox
        dby = -d * (st * nbx + cm1 * nby) + st * x + ct * y + oy
        w[_W_DC + 2 * ia, j] = dax
        w[_W_DC + 2 * ia + 1, j] = day
        w[_W_DC + 2 * ib, j] = dbx
        w[_W_DC + 2 * ib + 1, j] = dby
        # rigid position: the intersection of the circles of radius L = d - dD/2 about A, B
        # on the ball's side (the first root of ``_groove`` for the flank order BL, BR and
        # TR, TL)
        length = d - w[_W_H, j]
        ax, ay = dax - d * nax, day - d * nay
        bx, by = dbx - d * nbx, dby - d * nby
        ddx, ddy = bx - ax, by - ay
        half2 = 0.25 * (ddx * ddx + ddy * ddy)
        s = np.sqrt((length * length - half2) / (4.0 * half2))
        px = 0.5 * (ax + bx) - ddy * s
        py = 0.5 * (ay + by) + ddx * s
        # rigid forces, as fractions xa, xb of |T| = K q^3
        tx, ty = sgn * w[_W_LX, j], sgn * w[_W_LY, j]
        inv = 1.0 / length
        uax, uay = (px - ax) * inv, (py - ay) * inv
        ubx, uby = (px - bx) * inv, (py - by) * inv
        det = uax * uby - uay * ubx
        q = w[_W_Q, j]
        tdet = det * (k * q * q * q)
        xa = (tx * uby - ty * ubx) / tdet
        xb = (uax * ty - uay * tx) / tdet
        # Hertz approaches delta = q^2 x^(2/3): Halley's iteration for y^3 = x^2 from the
        # tangent of x^(2/3) at 1 (rigid forces are within a few |T| of each other)
        ya = (1.0 + 2.0 * xa) / 3.0
        yb = (1.0 + 2.0 * xb) / 3.0
        xa2, xb2 = xa * xa, xb * xb
        for _ in range(3):
            y3 = ya * ya * ya
            ya = ya * (y3 + 2.0 * xa2) / (2.0 * y3 + xa2)
            y3 = yb * yb * yb
            yb = yb * (y3 + 2.0 * xb2) / (2.0 * y3 + xb2)
        da = q * q * ya
        db = q * q * yb
        px += (da * uby - db * uay) / det
        py += (uax * db - ubx * da) / det
        ok = xa > 0.0 and xb > 0.0 and abs(th) <= SMALL_ANGLE
        w[_W_P + 2 * groove, j] = px if ok else np.nan
        w[_W_P + 2 * groove + 1, j] = py


@jit(inline="always")
def _lane_flank(px, py, dcx, dcy, nx, ny, d, h, k):
    """``flank`` without the branch (delta <= 0 gives NaN): u, 1/|P - C|, delta, F, dF."""
    vx = px - dcx
    vy = py - dcy
    wx = vx + d * nx
    wy = vy + d * ny
    r = np.sqrt(wx * wx + wy * wy)
    inv = 1.0 / r
    delta = (vx * vx + vy * vy + 2.0 * d * (nx * vx + ny * vy) + h * (2.0 * d - h)) / (
        r + d - h)
    sd = np.sqrt(delta)
    return wx * inv, wy * inv, inv, delta, k * delta * sd, 1.5 * k * sd


@jit(leaf=True)
def _lane_newton(m, groove, s0, c0, d, k, w):
    """_LANE_STEPS full Newton steps (as ``flank_newton``) on one groove for lanes 0..m-1."""
    ia = 2 * groove
    sgn = 1.0 if groove == 0 else -1.0
    nax, nay, _, _ = _nominal(ia, s0, c0)
    nbx, nby, _, _ = _nominal(ia + 1, s0, c0)
    rp = _W_P + 2 * groove
    for _ in range(_LANE_STEPS):
        for j in range(m):
            px, py, h = w[rp, j], w[rp + 1, j], w[_W_H, j]
            ux, uy, inv, _, f, df = _lane_flank(px, py, w[_W_DC + 2 * ia, j],
                                                w[_W_DC + 2 * ia + 1, j], nax, nay, d, h, k)
            g = f * inv
            rx = f * ux - sgn * w[_W_LX, j]
            ry = f * uy - sgn * w[_W_LY, j]
            j11 = df * ux * ux + g * (1.0 - ux * ux)
            j12 = (df - g) * ux * uy
            j22 = df * uy * uy + g * (1.0 - uy * uy)
            ux, uy, inv, _, f, df = _lane_flank(px, py, w[_W_DC + 2 * ia + 2, j],
                                                w[_W_DC + 2 * ia + 3, j], nbx, nby, d, h, k)
            g = f * inv
            rx += f * ux
            ry += f * uy
            j11 += df * ux * ux + g * (1.0 - ux * ux)
            j12 += (df - g) * ux * uy
            j22 += df * uy * uy + g * (1.0 - uy * uy)
            det = j11 * j22 - j12 * j12
            w[rp, j] = px - (j22 * rx - j12 * ry) / det
            w[rp + 1, j] = py - (j11 * ry - j12 * rx) / det


@jit(leaf=True)
def _lane_outputs(m, s0, c0, d, k, w):
    """u_i, delta_i, F_i and dbeta_i of the four flanks for lanes 0..m-1 (as ``ball_outputs``)."""
    for i in range(4):
        nx, ny, sx, sy = _nominal(i, s0, c0)
        sxy = sx * sy
        rp = _W_P + 2 * (i // 2)
        for j in range(m):
            ux, uy, _, delta, f, _ = _lane_flank(w[rp, j], w[rp + 1, j], w[_W_DC + 2 * i, j],
                                                 w[_W_DC + 2 * i + 1, j], nx, ny, d,
                                                 w[_W_H, j], k)
            w[_W_F + i, j] = f
            w[_W_UX + i, j] = ux
            w[_W_UY + i, j] = uy
            w[_W_DL + i, j] = delta
            tan = sxy * (ny * ux - nx * uy) / (nx * ux + ny * uy)
            w[_W_DB + i, j] = atan_small(tan) if abs(tan) <= SMALL_TAN else np.nan


@jit(inline="always")
def _lane_store(lo, j, tol, floor, w, out_dbeta, out_force, out_approach, out_ball,
                out_groove, out_converged, out_iter, out_count, out_residual):
    """Verify lane j and write ball lo + j; False if it needs the scalar solver."""
    lx, ly = w[_W_LX, j], w[_W_LY, j]
    bx = 0.0
    by = 0.0
    tx, ty = lx, ly
    fmax = 0.0
    ok = True
    for i in range(4):
        f = w[_W_F + i, j]
        fx = f * w[_W_UX + i, j]
        fy = f * w[_W_UY + i, j]
        bx -= fx
        by -= fy
        if i >= 2:
            tx += fx
            ty += fy
        fmax = max(fmax, f)
        ok = ok and w[_W_DL + i, j] > 0.0 and not np.isnan(w[_W_DB + i, j])
    imbalance = max(max(abs(bx), abs(by)), max(abs(tx), abs(ty)))
    scale = max(max(abs(lx), abs(ly)), max(fmax, floor))
    if not (ok and imbalance <= 2.0 * tol * scale):
        return False
    n = lo + j
    for i in range(4):
        out_dbeta[n, i] = w[_W_DB + i, j]
        out_force[n, i] = w[_W_F + i, j]
        out_approach[n, i] = w[_W_DL + i, j]
    out_ball[n, 0] = w[_W_P, j]
    out_ball[n, 1] = w[_W_P + 1, j]
    out_groove[n, 0] = w[_W_P, j] - w[_W_P + 2, j]
    out_groove[n, 1] = w[_W_P + 1, j] - w[_W_P + 3, j]
    out_converged[n] = True
    out_iter[n] = _LANE_STEPS
    out_count[n] = 4
    out_residual[n] = imbalance
    return True


@pjit
def static_load_kernel(side_load, normal_load, e_n, e_t, rot_b, rot_t, off_b, off_t,
                       oversize, beta0, dist, k, rigid, tol, max_iter, vectorised,
                       out_dbeta, out_force, out_approach, out_ball, out_groove,
                       out_converged, out_iter, out_count, out_residual):
    """Load-controlled static solution of every ball (see the Notes of :func:`solve_static`).

    Inputs have a first axis of n or 1 (broadcast); outputs have n rows. With
    ``vectorised``, elastic solutions take the vectorised fast path where it verifies, the
    scalar solver elsewhere.
    """
    floor = k * FLOOR_LENGTH**1.5
    s0, c0 = np.sin(beta0), np.cos(beta0)
    nball = out_dbeta.shape[0]
    lanes = vectorised and not rigid and max_iter >= _LANE_STEPS
    for tile in prange((nball + _TILE - 1) // _TILE):
        cen = np.empty((4, 6))  # work arrays once per tile, not per ball
        unit = np.empty((4, 2))
        w = np.empty((_ROWS, _TILE))
        lo = tile * _TILE
        m = min(nball, lo + _TILE) - lo
        if lanes:
            _lane_gather(lo, m, side_load, normal_load, e_n, e_t, rot_b, rot_t, off_b, off_t,
                         oversize, k, w)
            for groove in range(2):
                _lane_start(m, groove, s0, c0, dist, k, w)
                _lane_newton(m, groove, s0, c0, dist, k, w)
            _lane_outputs(m, s0, c0, dist, k, w)
        for j in range(m):
            if lanes and _lane_store(lo, j, tol, floor, w, out_dbeta, out_force,
                                     out_approach, out_ball, out_groove, out_converged,
                                     out_iter, out_count, out_residual):
                continue
            _load_one(lo + j, side_load, normal_load, e_n, e_t, rot_b, rot_t, off_b, off_t,
                      oversize, s0, c0, dist, k, rigid, tol, max_iter, floor, cen, unit,
                      out_dbeta, out_force, out_approach, out_ball, out_groove,
                      out_converged, out_iter, out_count, out_residual)


@jit(leaf=True)
def displacement_one(n, groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, s0, c0,
                     dist, k, tol, max_iter, floor, cen, unit, out_dbeta, out_force,
                     out_approach, out_ball, out_load, out_converged, out_iter, out_count,
                     out_residual):
    """Displacement-controlled solution of ball n (cen, unit: work arrays)."""
    arc_centres(n, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist, cen)
    ig = _idx(groove_disp, n)
    move_top_groove(cen, groove_disp[ig, 0], groove_disp[ig, 1])
    h = 0.5 * oversize[_idx(oversize, n)]
    # start: mean of the four "touching along the nominal direction" positions,
    # C_i + (d - h) n_i = (C_i + d n_i) - h n_i
    px = 0.0
    py = 0.0
    for i in range(4):
        px += 0.25 * (cen[i, 2] - h * cen[i, 4])
        py += 0.25 * (cen[i, 3] - h * cen[i, 5])
    # contact stiffness dF/ddelta at a 1 um approach as the fallback regularisation
    reg = 1.5 * k * 1e-3
    px, py, it, ok, _ = flank_newton(cen, 0, 4, dist, h, k, 0.0, 0.0, px, py, tol, max_iter,
                                     floor, reg, False)
    out_count[n] = ball_outputs(n, cen, px, py, dist, h, k, out_dbeta, out_force,
                                out_approach, unit)
    # load on the top groove that holds it: (N_x, -N_y) = -sum_top F_i u_i
    lx = -(out_force[n, 2] * unit[2, 0] + out_force[n, 3] * unit[3, 0])
    ly = -(out_force[n, 2] * unit[2, 1] + out_force[n, 3] * unit[3, 1])
    out_load[n, 0] = lx
    out_load[n, 1] = -ly
    out_ball[n, 0] = px
    out_ball[n, 1] = py
    out_converged[n] = ok
    out_iter[n] = it
    out_residual[n] = _imbalance(n, unit, out_force, lx, ly)


@pjit
def static_displacement_kernel(groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize,
                               beta0, dist, k, tol, max_iter,
                               out_dbeta, out_force, out_approach, out_ball, out_load,
                               out_converged, out_iter, out_count, out_residual):
    """Displacement-controlled solution: top groove held at its offset + groove_disp."""
    floor = k * FLOOR_LENGTH**1.5
    s0, c0 = np.sin(beta0), np.cos(beta0)
    nball = out_dbeta.shape[0]
    for tile in prange((nball + _TILE - 1) // _TILE):
        cen = np.empty((4, 6))
        unit = np.empty((4, 2))
        for n in range(tile * _TILE, min(nball, (tile + 1) * _TILE)):
            displacement_one(n, groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize,
                             s0, c0, dist, k, tol, max_iter, floor, cen, unit, out_dbeta,
                             out_force, out_approach, out_ball, out_load, out_converged,
                             out_iter, out_count, out_residual)
