"""Numba kernels of the batched carriage solve: the joint Newton on balls and carriage."""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics._fastmath import SMALL_ANGLE, SMALL_TAN, atan_small, sin_cosm1_small
from tolsim.physics.carriage._kernels import (
    LIFT_OFF,
    STATUS_CONVERGED,
    STATUS_FAILED,
    STATUS_LIFT_OFF,
    STEP_CAP,
    cholesky,
    cholesky_solve,
    nested_newton,
    scaled_error,
    schur_complement,
)
from tolsim.physics.carriage._map_kernels import (
    assembly_groove_rows,
    formed_pivot,
    gram_diagonal,
    gram_of_rows,
    trace_bounds,
)
from tolsim.physics.static import (
    FLOOR_LENGTH,
    arc_centres,
    ball_outputs,
    flank,
    flank_newton,
    move_top_groove,
)

#: Assemblies per parallel work item of :func:`carriage_batch_kernel` (scratch arrays are
#: allocated once per item, 21 of them: fewer, larger items allocate less; an assembly's
#: result does not depend on its item).
_ASSEMBLY_TILE = 32
#: Steps of the joint Newton (:func:`_joint_newton`) before the nested fallback.
_JOINT_MAX_ITER = 12
#: Relative ball imbalance above which the joint Newton first solves the ball alone: after a
#: joint step, and (_START_RESOLVE) at the start. The start of every ball is the least-squares
#: balance of its four flanks at equal stiffness (:func:`_ball_start`), which leaves 1e-2 to
#: 1e-1 of imbalance from the unequal flank stiffnesses: the joint step corrects that at
#: quadratic rate as well as a ball-only step does, so at the start only a ball farther off
#: takes ball-only steps. On ``configs/carriage_preload.toml`` (along the track, 40
#: assemblies, 379 solves) the lane passes per solve fell from 5.38 (mean start, 1e-3: 2.28
#: ball-only steps at the start) to 3.10 with the same joint steps (2.10), and on its
#: constant study (200 solves) from 6.12 to 4.0 (3.0 joint steps instead of 2.8).
_RESOLVE = 1e-3
_START_RESOLVE = 1e-1
#: Ball-only Newton steps from the start before the first joint step (while a ball's relative
#: imbalance is above _START_RESOLVE), and after a joint step that left one above _RESOLVE.
_START_STEPS = 3
_LOCAL_STEPS = 2


# Rows of the per-assembly lane array ``w`` of the joint Newton, ball b in column b. The loops
# over balls read and write whole rows and have no branches, so LLVM vectorises them (as the
# ``_lane_*`` kernels of tolsim.physics.static); each loop writes at most seven rows, since
# with more LLVM gives up on the run-time checks that the rows do not overlap.
_L_DC = 0  # C_i + d n_i (x, y) of flanks BL, BR, TR, TL, carriage groove at g = 0: 8 rows
_L_H = 8  # half the ball oversize
_L_P = 9  # ball centre (x, y)
_L_G = 11  # carriage-groove translation g = A q (x, y)
_L_DG = 13  # groove translation of the step, A dq (x, y)
_L_KB = 15  # K_b (11, 12, 22)
_L_RB = 18  # F_BL u_BL + F_BR u_BR (x, y)
_L_F01 = 20  # F_BL, F_BR
_L_KT = 22  # K_t (11, 12, 22)
_L_F = 25  # f = F_TR u_TR + F_TL u_TL, the force of the ball on its carriage groove (x, y)
_L_F23 = 27  # F_TR, F_TL
_L_S = 29  # S (11, 12, 22)
_L_W = 32  # M^-1 K_t (11, 12, 21, 22)
_L_D = 36  # ball correction gamma M^-1 r (x, y)
_L_RES = 38  # relative imbalance |r|_inf / max(F_max, floor)
_L_FM = 39  # largest flank force
_L_DB = 40  # dbeta_i of the four flanks (outputs)
_L_ROWS = 44
# The errors of the balls, gathered before the first pass into rows that the passes
# overwrite: e_n (4), e_t (4), rotations (rail, carriage), offsets (rail x, y, carriage x, y).
_L_EN, _L_ET, _L_ROT, _L_OFF = 15, 19, 23, 25
# And the sine and cosine - 1 of the rail and carriage rotations (sin_cosm1_small).
_L_SC = 29


@jit(inline="always")
def _soft_flank(px, py, dcx, dcy, nx, ny, d, h, k):
    """:func:`tolsim.physics.static.flank` without its branch (no force where delta <= 0).

    Returns F u (x, y), the flank stiffness k_i (11, 12, 22) and F, with the operations of
    ``flank`` and :func:`condensed_ball` (the same values where delta > 0).
    """
    vx = px - dcx
    vy = py - dcy
    wx = vx + d * nx
    wy = vy + d * ny
    dist = np.sqrt(wx * wx + wy * wy)
    inv = 1.0 / dist
    ux = wx * inv
    uy = wy * inv
    delta = (vx * vx + vy * vy + 2.0 * d * (nx * vx + ny * vy) + h * (2.0 * d - h)) / (
        dist + d - h)
    dp = max(delta, 0.0)
    sd = np.sqrt(dp)
    f = k * dp * sd
    df = 1.5 * k * sd
    g = f * inv
    a11 = df * ux * ux + g * (1.0 - ux * ux)
    a12 = (df - g) * ux * uy
    a22 = df * uy * uy + g * (1.0 - uy * uy)
    return f * ux, f * uy, a11, a12, a22, f


@jit(leaf=True)
def _lane_groove(w, groove, s0, c0, dist, k):
    """Flanks of one groove (0 rail: BL, BR; 1 carriage: TR, TL) of every ball at (P, g).

    Rows _L_KB, _L_RB, _L_F01 (rail) or _L_KT, _L_F, _L_F23 (carriage): the stiffness sum, the
    force sum sum F_i u_i and the two forces.
    """
    i0 = 2 * groove
    sgn = 1.0 if groove == 0 else -1.0
    ax, ay = -sgn * s0, -sgn * c0  # n_i of the first flank (BL or TR, GrooveErrors Notes)
    bx, by = sgn * s0, -sgn * c0  # and of the second (BR or TL)
    rk = _L_KB if groove == 0 else _L_KT
    rf = _L_RB if groove == 0 else _L_F
    rn = _L_F01 if groove == 0 else _L_F23
    shift = 0.0 if groove == 0 else 1.0  # the carriage groove is translated by g
    for b in range(w.shape[1]):
        px, py, h = w[_L_P, b], w[_L_P + 1, b], w[_L_H, b]
        gx, gy = shift * w[_L_G, b], shift * w[_L_G + 1, b]
        f0x, f0y, p11, p12, p22, f0 = _soft_flank(
            px, py, w[_L_DC + 2 * i0, b] + gx, w[_L_DC + 2 * i0 + 1, b] + gy, ax, ay, dist, h, k)
        f1x, f1y, q11, q12, q22, f1 = _soft_flank(
            px, py, w[_L_DC + 2 * i0 + 2, b] + gx, w[_L_DC + 2 * i0 + 3, b] + gy, bx, by, dist,
            h, k)
        w[rk, b] = p11 + q11
        w[rk + 1, b] = p12 + q12
        w[rk + 2, b] = p22 + q22
        w[rf, b] = f0x + f1x
        w[rf + 1, b] = f0y + f1y
        w[rn, b] = f0
        w[rn + 1, b] = f1


@jit(leaf=True)
def _lane_condense(w):
    """S and M^-1 K_t of every ball (rows _L_S, _L_W) by :func:`schur_complement`."""
    for b in range(w.shape[1]):
        s11, s12, s22, r11, r12, r21, r22 = schur_complement(
            w[_L_KB, b], w[_L_KB + 1, b], w[_L_KB + 2, b], w[_L_KT, b], w[_L_KT + 1, b],
            w[_L_KT + 2, b])
        w[_L_S, b] = s11
        w[_L_S + 1, b] = s12
        w[_L_S + 2, b] = s22
        w[_L_W, b] = r11
        w[_L_W + 1, b] = r12
        w[_L_W + 2, b] = r21
        w[_L_W + 3, b] = r22


@jit(leaf=True)
def _lane_correct(w, k, ball_floor):
    """The ball's own Newton correction gamma M^-1 r, its relative imbalance and F_max.

    M is regularised as ``flank_newton`` does. gamma = 1.5 for a loose ball (no diagonal pair
    BL-TR or BR-TL carries force: its only equilibrium has no force, so each loaded flank goes
    to delta = 0, where F = K delta^1.5 has a root of order 1.5 and a Newton step only divides
    delta by 3; the 1.5 step lands on delta = 0 to first order), else 1.
    """
    reg = 1.5 * k * 1e-3  # as displacement_one
    for b in range(w.shape[1]):
        m11 = w[_L_KB, b] + w[_L_KT, b]
        m12 = w[_L_KB + 1, b] + w[_L_KT + 1, b]
        m22 = w[_L_KB + 2, b] + w[_L_KT + 2, b]
        rx = w[_L_RB, b] + w[_L_F, b]
        ry = w[_L_RB + 1, b] + w[_L_F + 1, b]
        f0, f1, f2, f3 = w[_L_F01, b], w[_L_F01 + 1, b], w[_L_F23, b], w[_L_F23 + 1, b]
        det = m11 * m22 - m12 * m12
        trace = m11 + m22
        add = reg if (not det > 1e-12 * trace * trace) | (trace == 0.0) else 0.0
        e11, e22 = m11 + add, m22 + add
        loose = not ((min(f0, f2) > 0.0) | (min(f1, f3) > 0.0))
        gamma = (1.5 if loose else 1.0) / (e11 * e22 - m12 * m12)
        fm = max(max(f0, f1), max(f2, f3))
        w[_L_D, b] = gamma * (e22 * rx - m12 * ry)
        w[_L_D + 1, b] = gamma * (e11 * ry - m12 * rx)
        w[_L_RES, b] = max(abs(rx), abs(ry)) / max(fm, ball_floor)
        w[_L_FM, b] = fm


@jit(leaf=True)
def _lane_balls(w, s0, c0, dist, k, ball_floor):
    """Every ball (column of w) at its (P, g): the rows _L_KB to _L_FM (:func:`condensed_ball`
    in vectorised passes). The loops run from 0 (with a variable start Numba's negative-index
    wrap-around keeps LLVM from vectorising): pass a column slice for one ball."""
    _lane_groove(w, 0, s0, c0, dist, k)
    _lane_groove(w, 1, s0, c0, dist, k)
    _lane_condense(w)
    _lane_correct(w, k, ball_floor)


@jit(leaf=True)
def _lane_angles(w, s0, c0, dist):
    """dbeta_i of every flank of every ball at (P, g) into rows _L_DB, as ``ball_outputs``.

    dbeta_i = atan(t_i . u_i / n_i . u_i) by the series of ``atan_small`` (round-off
    accurate for |tan| <= SMALL_TAN, about 5.7 deg); NaN beyond, for the caller to redo with
    arctan2 (the loop stays branch-free and vectorises).
    """
    for i in range(4):
        sx = -1.0 if (i == 0 or i == 3) else 1.0
        sy = -1.0 if i < 2 else 1.0
        nx, ny = sx * s0, sy * c0
        sxy = sx * sy
        shift = 0.0 if i < 2 else 1.0
        for b in range(w.shape[1]):
            wx = w[_L_P, b] - (w[_L_DC + 2 * i, b] + shift * w[_L_G, b]) + dist * nx
            wy = w[_L_P + 1, b] - (w[_L_DC + 2 * i + 1, b] + shift * w[_L_G + 1, b]) + dist * ny
            tan = sxy * (ny * wx - nx * wy) / (nx * wx + ny * wy)
            w[_L_DB + i, b] = atan_small(tan) if abs(tan) <= SMALL_TAN else np.nan


@jit(leaf=True)
def _lane_arc_centres(a, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist, w, work):
    """Rows _L_DC (C_i + d n_i, carriage groove at g = 0) of every ball of assembly a.

    The operations of ``tolsim.physics.static.arc_centres``, vectorised over the balls with
    the sine and cosine of the groove rotations from ``sin_cosm1_small`` (round-off accurate
    up to SMALL_ANGLE = 0.2 rad); a ball with a larger rotation gets ``arc_centres`` itself.
    """
    nball = w.shape[1]
    # gather (inputs have a first axis of m n_balls or 1: row n times 1 or 0)
    se, st_, sb, sq = (int(e_n.shape[0] > 1), int(e_t.shape[0] > 1), int(rot_b.shape[0] > 1),
                       int(rot_t.shape[0] > 1))
    so, sp = int(off_b.shape[0] > 1), int(off_t.shape[0] > 1)
    for b in range(nball):
        n = a * nball + b
        ie, it = n * se, n * st_
        for i in range(4):
            w[_L_EN + i, b] = e_n[ie, i]
            w[_L_ET + i, b] = e_t[it, i]
        w[_L_ROT, b] = rot_b[n * sb]
        w[_L_ROT + 1, b] = rot_t[n * sq]
        ib, iq = n * so, n * sp
        w[_L_OFF, b] = off_b[ib, 0]
        w[_L_OFF + 1, b] = off_b[ib, 1]
        w[_L_OFF + 2, b] = off_t[iq, 0]
        w[_L_OFF + 3, b] = off_t[iq, 1]
    for b in range(nball):  # sine and cosine - 1 of each groove's rotation, once per ball
        s_b, c_b = sin_cosm1_small(w[_L_ROT, b])
        s_t, c_t = sin_cosm1_small(w[_L_ROT + 1, b])
        w[_L_SC, b] = s_b
        w[_L_SC + 1, b] = c_b
        w[_L_SC + 2, b] = s_t
        w[_L_SC + 3, b] = c_t
    for i in range(4):
        groove = i // 2
        sx = -1.0 if (i == 0 or i == 3) else 1.0
        sy = -1.0 if i < 2 else 1.0
        nx, ny = sx * s0, sy * c0  # n_i
        tx, ty = sx * c0, -sy * s0  # t_i = dn_i/dbeta
        for b in range(nball):
            st, cm1 = w[_L_SC + 2 * groove, b], w[_L_SC + 2 * groove + 1, b]
            ct = 1.0 + cm1
            en, et = w[_L_EN + i, b], w[_L_ET + i, b]
            x = en * nx - et * tx
            y = en * ny - et * ty
            w[_L_DC + 2 * i, b] = (-dist * (cm1 * nx - st * ny) + ct * x - st * y
                                   + w[_L_OFF + 2 * groove, b])
            w[_L_DC + 2 * i + 1, b] = (-dist * (st * nx + cm1 * ny) + st * x + ct * y
                                       + w[_L_OFF + 2 * groove + 1, b])
    for b in range(nball):
        if not (abs(w[_L_ROT, b]) <= SMALL_ANGLE and abs(w[_L_ROT + 1, b]) <= SMALL_ANGLE):
            arc_centres(a * nball + b, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist,
                        work)
            for i in range(4):
                w[_L_DC + 2 * i, b] = work[i, 2]
                w[_L_DC + 2 * i + 1, b] = work[i, 3]


@jit(inline="always")
def _lane_work(w, b, s0, c0, dist, work):
    """The arc centres of ball b (as ``arc_centres``, carriage groove moved by g) into work."""
    for i in range(4):
        sx = -1.0 if (i == 0 or i == 3) else 1.0
        sy = -1.0 if i < 2 else 1.0
        nx, ny = sx * s0, sy * c0
        work[i, 2] = w[_L_DC + 2 * i, b]
        work[i, 3] = w[_L_DC + 2 * i + 1, b]
        work[i, 0] = work[i, 2] - dist * nx
        work[i, 1] = work[i, 3] - dist * ny
        work[i, 4] = nx
        work[i, 5] = ny
    move_top_groove(work, w[_L_G, b], w[_L_G + 1, b])


@jit(leaf=True)
def _lane_local_step(nball, w, dist):
    """Ball-only Newton step P -= gamma M^-1 r (groove held), capped at 0.1 d."""
    cap2 = (0.1 * dist) ** 2
    for b in range(nball):
        dx, dy = w[_L_D, b], w[_L_D + 1, b]
        s2 = dx * dx + dy * dy
        c = np.sqrt(cap2 / s2) if s2 > cap2 else 1.0
        w[_L_P, b] -= c * dx
        w[_L_P + 1, b] -= c * dy


@jit(leaf=True)
def _track_assembly(w, frame, zeta, q_ext, residual, reduced, tangent, ball_tol):
    """Carriage residual R, reduced residual and tangent of the joint Newton, track by track.

    With A_b = E_t^T B_b (solve_carriage Notes; scaled: B_b = [[1, 0, 0, zeta, -eta], [0, 1,
    -zeta, 0, xi]], zeta = z_j / L, xi = x_t / L, eta = y_t / L) and, in the carriage frame,
    T_b = E_t S_b E_t^T and f_c = E_t f: sum_b A_b^T S_b A_b = sum_b B_b^T T_b B_b and
    sum_b A_b^T f_b = sum_b B_b^T f_c,b, so each track needs only the sums of T, zeta T and
    zeta^2 T and of f_c and zeta f_c over its balls (ball b = t n + j). The same K and R as
    ``sum A^T S A`` over ``groove_map`` (to round-off), in a third of the operations.
    ``zeta`` holds z_b / L of every ball (n_tracks n,), so that the balls of each assembly
    may sit at their own z (:func:`solve_carriage_batch` with ``ball_z``).

    Returns the largest flank force [N], sum_b |f_b|^2 [N^2] and whether every ball's relative
    imbalance is within ball_tol.
    """
    n = zeta.shape[0] // frame.shape[0]
    for i in range(5):
        residual[i] = q_ext[i]
        reduced[i] = q_ext[i]
        for j in range(5):
            tangent[i, j] = 0.0
    fmax = force2 = 0.0
    balls_ok = True
    for t in range(frame.shape[0]):
        c, s, xi, eta = frame[t, 0], frame[t, 1], frame[t, 2], frame[t, 3]
        cc, ss, cs = c * c, s * s, c * s
        a11 = a12 = a22 = z11 = z12 = z22 = y11 = y12 = y22 = 0.0  # sums of T, zeta T, zeta^2 T
        fx0 = fy0 = fx1 = fy1 = gx0 = gy0 = gx1 = gy1 = 0.0  # of f_c, zeta f_c (f, reduced)
        for j in range(n):
            b = t * n + j
            z = zeta[b]
            fx, fy = w[_L_F, b], w[_L_F + 1, b]
            rx, ry = w[_L_RB, b] + fx, w[_L_RB + 1, b] + fy
            fmax = max(fmax, w[_L_FM, b])
            force2 += fx * fx + fy * fy
            balls_ok = balls_ok and w[_L_RES, b] <= ball_tol
            # f - K_t M^-1 r, with K_t M^-1 r = (M^-1 K_t)^T r
            gx = fx - (w[_L_W, b] * rx + w[_L_W + 2, b] * ry)
            gy = fy - (w[_L_W + 1, b] * rx + w[_L_W + 3, b] * ry)
            sa, sb, sd = w[_L_S, b], w[_L_S + 1, b], w[_L_S + 2, b]
            t11 = cc * sa - 2.0 * cs * sb + ss * sd
            t12 = cs * (sa - sd) + (cc - ss) * sb
            t22 = ss * sa + 2.0 * cs * sb + cc * sd
            a11 += t11
            a12 += t12
            a22 += t22
            z11 += z * t11
            z12 += z * t12
            z22 += z * t22
            y11 += z * z * t11
            y12 += z * z * t12
            y22 += z * z * t22
            fcx, fcy = c * fx - s * fy, s * fx + c * fy
            gcx, gcy = c * gx - s * gy, s * gx + c * gy
            fx0 += fcx
            fy0 += fcy
            fx1 += z * fcx
            fy1 += z * fcy
            gx0 += gcx
            gy0 += gcy
            gx1 += z * gcx
            gy1 += z * gcy
        residual[0] += fx0
        residual[1] += fy0
        residual[2] -= fy1
        residual[3] += fx1
        residual[4] += xi * fy0 - eta * fx0
        reduced[0] += gx0
        reduced[1] += gy0
        reduced[2] -= gy1
        reduced[3] += gx1
        reduced[4] += xi * gy0 - eta * gx0
        tangent[0, 0] += a11
        tangent[0, 1] += a12
        tangent[1, 1] += a22
        tangent[0, 2] -= z12
        tangent[1, 2] -= z22
        tangent[2, 2] += y22
        tangent[0, 3] += z11
        tangent[1, 3] += z12
        tangent[2, 3] -= y12
        tangent[3, 3] += y11
        tangent[0, 4] += xi * a12 - eta * a11
        tangent[1, 4] += xi * a22 - eta * a12
        tangent[2, 4] += eta * z12 - xi * z22
        tangent[3, 4] += xi * z12 - eta * z11
        tangent[4, 4] += eta * eta * a11 - 2.0 * eta * xi * a12 + xi * xi * a22
    for j in range(5):
        for i in range(j):
            tangent[j, i] = tangent[i, j]
    return fmax, force2, balls_ok


@jit(leaf=True)
def _joint_newton(q, free, amap, frame, zeta, w, s0, c0, dist, k, tol, ball_tol, ball_max_iter,
                  ball_floor, force_floor, load_norm, singular, geometric, k_ref, eig_work, cap,
                  limit, q_ext, residual, tangent, state, work, low, step, reduced):
    """Newton on the balls and the carriage together (the fast path): its steps, or -1.

    Unknowns: every ball centre P_b and q. Linearising the ball balance r_b = sum_i F_i u_i
    = 0 and the carriage balance R = Q + sum_b A_b^T f_b = 0 (:func:`condensed_ball`):
    r_b + M_b dP_b - K_t,b A_b dq = 0 gives dP_b = M_b^-1 K_t,b A_b dq - M_b^-1 r_b and
    df_b = -S_b A_b dq - K_t,b M_b^-1 r_b, so the carriage step solves

        (sum_b A_b^T S_b A_b) dq = R - sum_b A_b^T K_t,b M_b^-1 r_b

    (the tangent of the nested Newton, which has r_b = 0). A step costs one flank pass over
    the balls (:func:`_lane_balls`, vectorised) instead of a Newton solve of every ball.
    While some ball's relative imbalance exceeds _START_RESOLVE at the start
    (_START_STEPS times) or _RESOLVE after a step (_LOCAL_STEPS times) all balls take a
    ball-only Newton step (:func:`_lane_local_step`); a ball still above it is solved alone
    by ``flank_newton``.
    Loose balls take the 1.5 correction of :func:`_lane_correct`. Steps are capped as the
    nested Newton's (groove travel STEP_CAP d, ball travel 0.1 d); no line search. Converged
    when every ball's imbalance is <= ball_tol max(F_max,b, ball_floor) and the carriage's
    <= tol, as the nested Newton. Returns -1 (the caller falls back to the nested Newton) on
    a singular tangent, a ball step beyond 0.1 d, a motion beyond ``limit``, a failed ball
    solve, no carriage force under a load, or _JOINT_MAX_ITER steps.

    On entry w holds the arc centres (rows _L_DC), the oversizes and the start of P; q the
    start of the carriage. On success q, residual[0], tangent[0], state[0] (NaN energy: no
    line search needs it) and w hold the solution.
    """
    nball = w.shape[1]
    reg = 1.5 * k * 1e-3
    it = 0
    while True:
        gmax = 0.0
        for b in range(nball):
            gx = gy = 0.0
            for j in range(5):
                gx += amap[j, b] * q[j]
                gy += amap[5 + j, b] * q[j]
            w[_L_G, b] = gx
            w[_L_G + 1, b] = gy
            gmax = max(gmax, max(abs(gx), abs(gy)))
        if not gmax <= limit:
            return -1
        _lane_balls(w, s0, c0, dist, k, ball_floor)
        # ball-only steps, all balls at once: from the start, and after a step that left some
        # ball far from its balance
        for _ in range(_START_STEPS if it == 0 else _LOCAL_STEPS):
            worst = 0.0
            for b in range(nball):
                worst = max(worst, w[_L_RES, b])
            if worst <= (_START_RESOLVE if it == 0 else _RESOLVE):
                break
            _lane_local_step(nball, w, dist)
            _lane_balls(w, s0, c0, dist, k, ball_floor)
        for b in range(nball):
            if not w[_L_RES, b] <= (_START_RESOLVE if it == 0 else _RESOLVE):  # alone (or NaN)
                _lane_work(w, b, s0, c0, dist, work)
                px, py, _, ok, _ = flank_newton(work, 0, 4, dist, w[_L_H, b], k, 0.0, 0.0,
                                                w[_L_P, b], w[_L_P + 1, b], ball_tol,
                                                ball_max_iter, ball_floor, reg, False)
                if not ok:
                    return -1
                w[_L_P, b] = px
                w[_L_P + 1, b] = py
                _lane_balls(w[:, b:b + 1], s0, c0, dist, k, ball_floor)
        fmax, force2, balls_ok = _track_assembly(w, frame, zeta, q_ext, residual[0], reduced,
                                                 tangent[0], ball_tol)
        state[0, 0] = np.nan  # (no energy: no line search)
        state[0, 1] = fmax
        state[0, 2] = force2
        err = scaled_error(residual[0], free, max(max(load_norm, fmax), force_floor))
        if balls_ok and err <= tol:
            if not force2 > 0.0 and load_norm > 0.0:
                return -1
            return it
        if it >= _JOINT_MAX_ITER:
            return -1
        it += 1
        if formed_pivot(cholesky(tangent[0], free, low), singular, geometric, amap, free, k_ref,
                        eig_work):
            return -1
        cholesky_solve(low, free, reduced, step)
        move = 0.0
        for b in range(nball):
            gx = gy = 0.0
            for j in range(5):
                gx += amap[j, b] * step[j]
                gy += amap[5 + j, b] * step[j]
            w[_L_DG, b] = gx
            w[_L_DG + 1, b] = gy
            move = max(move, max(abs(gx), abs(gy)))
        damp = cap / move if move > cap else 1.0
        for j in range(5):
            q[j] += damp * step[j]
        big = 0.0
        for b in range(nball):
            dgx, dgy = w[_L_DG, b], w[_L_DG + 1, b]
            dpx = damp * (w[_L_W, b] * dgx + w[_L_W + 1, b] * dgy - w[_L_D, b])
            dpy = damp * (w[_L_W + 2, b] * dgx + w[_L_W + 3, b] * dgy - w[_L_D + 1, b])
            w[_L_P, b] += dpx
            w[_L_P + 1, b] += dpy
            big = max(big, dpx * dpx + dpy * dpy)
        if not big <= (0.1 * dist) ** 2:
            return -1
    return -1


@jit(inline="always")
def _ball_start(w, b, s0, c0):
    """Start of ball b's centre with the carriage groove at g = 0 (the caller adds g / 2):
    the balance of its four flanks at equal stiffness, to first order.

    Flank i pushes with k delta_i, delta_i = n_i . (P - T_i) to first order about the
    touching position T_i = C_i + (d - h) n_i (rows _L_DC: C_i + d n_i). The balance
    sum_i delta_i n_i = 0 is the least-squares P of sum_i (n_i . (P - T_i))^2; with
    n_i = (s_x s0, s_y c0), sum_i n_i n_i^T = diag(4 s0^2, 4 c0^2) and the h terms cancel:

        P_x = 1/4 sum_i (D_x,i + s_x s_y (c0 / s0) D_y,i),
        P_y = 1/4 sum_i (D_y,i + s_x s_y (s0 / c0) D_x,i),   D_i = C_i + d n_i.

    Unlike the mean of the T_i (the start of ``displacement_one``) it leaves out the
    tangential arc-centre offsets, which move no flank's approach to first order; a carriage
    groove moved by g moves it by g / 2, as the mean.
    """
    px = py = 0.0
    ty, tx = c0 / s0, s0 / c0
    for i in range(4):
        sxy = 1.0 if (i == 0 or i == 2) else -1.0  # s_x s_y of flank i
        dx, dy = w[_L_DC + 2 * i, b], w[_L_DC + 2 * i + 1, b]
        px += 0.25 * (dx + sxy * ty * dy)
        py += 0.25 * (dy + sxy * tx * dx)
    return px, py


@jit(inline="always")
def _settle_loose(a, limit, s0, c0, out_force, out_dbeta, out_side, out_normal, out_count):
    """No force on a loose ball of assembly a whose imbalance is within the solve's tolerance
    ``limit`` (ball_tol times the reference ball force) [N].

    A loose ball (no diagonal pair BL-TR or BR-TL carries force) has one balance, with no
    force (:func:`_lane_correct`). The Newton's ball test is relative to the reference ball
    force: a converged ball's imbalance r = sum_i F_i u_i has max(|r_x|, |r_y|) <= ``limit``,
    so a converged loose ball may keep forces of that order. At the default 1e-12 that is an
    approach of about 1e-14 m, far below the 1 pm that counts as round-off downstream
    (:data:`tolsim.study.pipeline.evaluate.ROUND_OFF_APPROACH`); at the 1e-8 of the solves
    along the track then (``TRACK_TOLERANCE``, now 1e-4: some 1.4 nm) it was about 3 pm, and
    such a ball was taken for a one-point contact, unresolved, instead of an unloaded ball
    (measured: 7 balls of 4 of the 24 assemblies of the circuit with an 8 um end relief of
    ``tests/study/test_carriage_circuit.py``, from the joint Newton and from its fallback).
    Its forces are the solve's error, so they are reported as none (its carriage flank
    forces, N_x and N_y too); the carriage's balance changes by at most ``limit`` per such
    ball, within the carriage tolerance.

    The test is the Newton's own, on r rebuilt from the outputs: u_i = cos(dbeta_i) n_i +
    s_i sin(dbeta_i) (n_i,y, -n_i,x), with n_i = (s_x s0, s_y c0) and s_i = s_x s_y, the
    convention of :func:`_lane_angles`. A bound on the forces alone would not do: a single
    flank at 45 deg has max(|r_x|, |r_y|) = F / sqrt(2), so forces up to sqrt(2) ``limit``
    pass the Newton's test (measured at 1e-4: a ball with 3.5e-3 N on its TL flank alone,
    converged, beyond the bound ``limit`` on its forces that this test had before).
    """
    for b in range(out_force.shape[1]):
        f0, f1, f2, f3 = (out_force[a, b, 0], out_force[a, b, 1], out_force[a, b, 2],
                          out_force[a, b, 3])
        fm = max(max(f0, f1), max(f2, f3))
        if not (fm > 0.0) or (min(f0, f2) > 0.0) or (min(f1, f3) > 0.0):
            continue  # no force, or a diagonal pair carries force (or NaN)
        rx = ry = 0.0
        for i in range(4):
            f = out_force[a, b, i]
            if not f > 0.0:
                continue
            sx = -1.0 if (i == 0 or i == 3) else 1.0
            sy = -1.0 if i < 2 else 1.0
            nx, ny = sx * s0, sy * c0
            db = out_dbeta[a, b, i]
            cb, sb = np.cos(db), sx * sy * np.sin(db)
            rx += f * (cb * nx + sb * ny)
            ry += f * (cb * ny - sb * nx)
        if max(abs(rx), abs(ry)) <= limit:
            for i in range(4):
                out_force[a, b, i] = 0.0
            out_count[a, b] = 0
            out_side[a, b] = 0.0
            out_normal[a, b] = 0.0


@jit(inline="always")
def _unloaded_outputs(loaded, a, out_dbeta, out_force, out_side, out_normal, out_count,
                      out_ball_converged):
    """The outputs of the balls of assembly a outside the loaded zone (``loaded`` False):
    no force, no contact, NaN contact angles and loads, converged (nothing to solve)."""
    for b in range(loaded.shape[0]):
        if not loaded[b]:
            out_count[a, b] = 0
            out_side[a, b] = np.nan
            out_normal[a, b] = np.nan
            out_ball_converged[a, b] = True
            for i in range(4):
                out_dbeta[a, b, i] = np.nan
                out_force[a, b, i] = 0.0


@pjit
def carriage_batch_kernel(groove_maps, frame, zetas, free, geometrics, geometric_maxs,
                          ball_z, tracks, length, loaded, load, start, e_n, e_t, rot_b,
                          rot_t, off_b, off_t, oversize_error,
                          oversize, scale, beta0, dist, k, tol, max_iter, ball_tol,
                          ball_max_iter, out_dbeta, out_force, out_side, out_normal, out_count,
                          out_ball_converged, out_displacement, out_stiffness, out_residual,
                          out_iterations, out_status, out_fallback, joint):
    """Equilibrium of many carriage assemblies (see :func:`solve_carriage_batch`).

    Scaled coordinates as in :func:`solve_carriage` (q_s = q / scale, rotations times L).
    Ball inputs have a first axis of m n_balls (assembly a, ball b at row a n_balls + b) or
    1 (the ball's oversize is ``oversize_error`` + ``oversize``, the two of
    :func:`solve_carriage`); ``load`` (m or 1, 5) holds Q [N, N m] and ``start`` (m or 1, 5)
    the scaled start of q.
    ``groove_maps`` (m or 1, n_balls, 2, 5) is the scaled A of each assembly (copied by rows
    into the tile's scratch for the joint Newton: row 5 c + j: A[:, c, j]); ``frame`` (n_tracks, 4)
    holds cos phi, sin phi, x / L and y / L of each track and ``zetas`` (m or 1, n_balls)
    z_b / L (:func:`_track_assembly`); ``free`` the indices of the free DOFs, ``geometrics``
    (m or 1, 5, 5) sum_b A_b^T A_b and ``geometric_maxs`` (m or 1,) the largest eigenvalue of
    its free block, or NaN: then computed only if a pivot needs it (:func:`singular_pivot`).
    Balls at their own z instead: ``ball_z`` (m, n_balls) [m] (else (0, n_balls)), whose
    maps (by rows, into the scratch ``amap``) and z / L the kernel forms per assembly
    (:func:`assembly_groove_rows` with ``tracks`` (n_tracks, 6) and ``length`` L), and of
    sum_b A_b^T A_b the diagonal (:func:`gram_diagonal`, for the trace bounds), the whole of it
    only if a pivot needs its largest eigenvalue (:func:`formed_pivot`) or the nested Newton
    takes over; ``groove_maps``, ``zetas``, ``geometrics`` and ``geometric_maxs`` are then not
    read;
    ``loaded`` (m or 1, n_balls) marks the balls in the loaded zone. A ball
    that is not loaded has zero rows in A and a radius of R_B - d/2 in the kernel (no flank
    touches it, so it carries and transmits nothing); its outputs are overwritten: no force,
    NaN angles and loads, count 0, converged. Assembly a is solved by the same sequence of
    operations whatever the batch and the thread count (scratch per tile of _ASSEMBLY_TILE
    assemblies, overwritten before use).

    Per assembly: the arc centres of every ball once (only the carriage groove moves with q;
    :func:`_lane_arc_centres`); the reference ball force f_ref and stiffness k_ref of
    :func:`solve_carriage`; the balls start from the mean of their four touching positions
    (as ``displacement_one``) with the carriage groove at A q_start; then, if ``joint``,
    :func:`_joint_newton`, and where it fails (or without ``joint``) :func:`nested_newton`
    from the start again (``out_fallback``). A tangent whose smallest Cholesky pivot is below
    1e-10 k_ref ``geometric_max`` counts as singular (:func:`solve_carriage` compares its
    smallest eigenvalue with the largest of k_ref sum_b A_b^T A_b: the same zero tangents).
    Outputs as :class:`CarriageBatch` (scaled back: q = q_s scale, K = K_s / scale scale^T).
    """
    nasm = out_status.shape[0]
    for tile in prange((nasm + _ASSEMBLY_TILE - 1) // _ASSEMBLY_TILE):
        _solve_tile(tile, groove_maps, frame, zetas, free, geometrics, geometric_maxs,
                    ball_z, tracks, length, loaded, load, start, e_n, e_t, rot_b, rot_t,
                    off_b, off_t, oversize_error, oversize, scale, beta0, dist, k, tol,
                    max_iter, ball_tol, ball_max_iter, out_dbeta, out_force, out_side,
                    out_normal, out_count, out_ball_converged, out_displacement,
                    out_stiffness, out_residual, out_iterations, out_status, out_fallback,
                    joint)


@jit
def _solve_tile(tile, groove_maps, frame, zetas, free, geometrics, geometric_maxs,
                ball_z, tracks, length, loaded, load, start, e_n, e_t, rot_b, rot_t, off_b,
                off_t, oversize_error, oversize, scale, beta0, dist, k, tol, max_iter,
                ball_tol, ball_max_iter, out_dbeta, out_force, out_side, out_normal,
                out_count, out_ball_converged, out_displacement, out_stiffness,
                out_residual, out_iterations, out_status, out_fallback, joint):
    """The assemblies of tile ``tile`` of :func:`carriage_batch_kernel` (its arguments),
    with the tile's scratch: a function of its own, so that the parallel loop hands its
    arrays over once per tile, not once per assembly. The joint Newton and the balls'
    passes it calls per assembly and per step are leaf kernels (:func:`tolsim._jit.jit`):
    their two dozen arrays cost no reference counts (about 13 % of a solve, session 26)."""
    nasm = out_status.shape[0]
    nball = groove_maps.shape[1]
    moving = ball_z.shape[0] > 0
    s0, c0 = np.sin(beta0), np.cos(beta0)
    floor = k * FLOOR_LENGTH**1.5
    limit = LIFT_OFF * dist
    cap = STEP_CAP * dist
    base = np.empty((nball, 4, 6))
    half = np.empty(nball)
    w = np.empty((_L_ROWS, nball))
    pos = np.empty((2, nball, 2))
    grv = np.empty((2, nball, 2))
    resp = np.empty((2, nball, 4))
    ball_ok = np.empty((2, nball), dtype=np.bool_)
    residual = np.empty((2, 5))
    tangent = np.empty((2, 5, 5))
    state = np.empty((2, 3))
    q = np.empty(5)
    q_ext = np.empty(5)
    step = np.empty(5)
    trial = np.empty(5)
    reduced = np.empty(5)
    kreg = np.empty((5, 5))
    singular = np.empty(3)
    low = np.empty((5, 5))
    work = np.empty((4, 6))
    unit = np.empty((4, 2))
    approach = np.empty((nball, 4))
    amap = np.empty((10, nball))
    own_map = np.empty((nball, 2, 5))
    own_zeta = np.empty(nball)
    own_geometric = np.empty((5, 5))
    for a in range(tile * _ASSEMBLY_TILE, min(nasm, (tile + 1) * _ASSEMBLY_TILE)):
        il = a if load.shape[0] > 1 else 0
        i_s = a if start.shape[0] > 1 else 0
        iz = a if loaded.shape[0] > 1 else 0
        if moving:  # the balls' own maps (by rows), at their own z; of sum_b A_b^T A_b
            # its diagonal, the rest when needed (formed_pivot, the nested fallback)
            assembly_groove_rows(ball_z[a], loaded[iz], tracks, scale, length, amap,
                                 own_zeta)
            gram_diagonal(amap, own_geometric)
            groove_map, zeta, geometric, geometric_max = (own_map, own_zeta,
                                                          own_geometric, np.nan)
        else:
            ig = a if groove_maps.shape[0] > 1 else 0
            groove_map, zeta = groove_maps[ig], zetas[ig]
            geometric, geometric_max = geometrics[ig], geometric_maxs[ig]
        if not moving and (groove_maps.shape[0] > 1 or a == tile * _ASSEMBLY_TILE):
            for b in range(nball):  # A by rows
                for c in range(2):
                    for j in range(5):
                        amap[5 * c + j, b] = groove_map[b, c, j]
        load_norm = 0.0
        for j in range(5):
            q_ext[j] = load[il, j] * scale[j]
            load_norm = max(load_norm, abs(q_ext[j]))
            q[j] = start[i_s, j]
        omax = -np.inf
        nloaded = 0
        for b in range(nball):
            n = a * nball + b
            o = (oversize_error[n if oversize_error.shape[0] > 1 else 0]
                 + oversize[n if oversize.shape[0] > 1 else 0])
            if loaded[iz, b]:
                half[b] = 0.5 * o
                omax = max(omax, o)
                nloaded += 1
            else:  # free: no flank reaches it
                half[b] = -0.5 * dist
            w[_L_H, b] = half[b]
        _lane_arc_centres(a, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist, w, work)
        for b in range(nball):
            gx = gy = 0.0
            for j in range(5):
                gx += amap[j, b] * q[j]
                gy += amap[5 + j, b] * q[j]
            px, py = _ball_start(w, b, s0, c0)
            w[_L_P, b] = px + 0.5 * gx
            w[_L_P + 1, b] = py + 0.5 * gy
        # reference ball force and stiffness, as solve_carriage
        f_ref = max(load_norm / max(nloaded, 1), k * max(0.5 * omax, 0.0) ** 1.5)
        delta_ref = max((f_ref / k) ** (2.0 / 3.0), FLOOR_LENGTH)
        k_ref = 1.5 * k * np.sqrt(delta_ref) * 0.5
        ball_floor = max(f_ref, floor)
        if np.isnan(geometric_max):  # not given: bounds, the value when needed
            trace_bounds(geometric, free, k_ref, singular)
        else:
            for i in range(3):
                singular[i] = 1e-10 * k_ref * geometric_max
        it = -1
        if joint:
            it = _joint_newton(q, free, amap, frame, zeta, w, s0, c0, dist, k, tol, ball_tol,
                               ball_max_iter, ball_floor, floor, load_norm, singular, geometric,
                               k_ref, kreg, cap, limit, q_ext, residual, tangent, state, work,
                               low, step, reduced)
        out_fallback[a] = joint and it < 0
        if it >= 0:
            status, cur, last = STATUS_CONVERGED, 0, 0
            for b in range(nball):
                pos[0, b, 0] = w[_L_P, b]
                pos[0, b, 1] = w[_L_P + 1, b]
                grv[0, b, 0] = w[_L_G, b]
                grv[0, b, 1] = w[_L_G + 1, b]
                ball_ok[0, b] = True
        else:
            for j in range(5):
                q[j] = start[i_s, j]
            if moving:  # the maps by balls and the whole sum_b A_b^T A_b
                for b in range(nball):
                    for c in range(2):
                        for j in range(5):
                            own_map[b, c, j] = amap[5 * c + j, b]
                if np.isnan(own_geometric[0, 1]):
                    gram_of_rows(amap, own_geometric)
            for b in range(nball):
                arc_centres(a * nball + b, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0,
                            dist, base[b])
            status, it, cur, last = nested_newton(
                q, free, groove_map, geometric, base, half, s0, c0, dist, k, tol, max_iter,
                ball_tol, ball_max_iter, ball_floor, floor, load_norm, k_ref, singular, cap,
                limit, q_ext, pos, grv, resp, ball_ok, work, residual, tangent, state, kreg,
                low, step, trial)
        out_status[a] = status
        out_iterations[a] = it
        if status == STATUS_LIFT_OFF or status == STATUS_FAILED:
            for b in range(nball):
                out_ball_converged[a, b] = ball_ok[last, b]
                out_count[a, b] = 0
                out_side[a, b] = np.nan
                out_normal[a, b] = np.nan
                for i in range(4):
                    out_dbeta[a, b, i] = np.nan
                    out_force[a, b, i] = np.nan
            for i in range(5):
                out_displacement[a, i] = np.nan
                out_residual[a, i] = np.nan
                for j in range(5):
                    out_stiffness[a, i, j] = np.nan
            continue
        if not out_fallback[a] and joint:  # from the lanes of the joint Newton
            _lane_angles(w, s0, c0, dist)
            for b in range(nball):
                count = 0
                for i in range(4):
                    f = w[_L_F01 + i, b] if i < 2 else w[_L_F23 + i - 2, b]
                    out_force[a, b, i] = f
                    count += f > 0.0
                    dbeta = w[_L_DB + i, b]
                    if np.isnan(dbeta):  # beyond the series: as ball_outputs
                        _lane_work(w, b, s0, c0, dist, work)
                        ux, uy, _, _, _, _ = flank(w[_L_P, b], w[_L_P + 1, b], work, i,
                                                   dist, half[b], k)
                        nx, ny = work[i, 4], work[i, 5]
                        sxy = 1.0 if (i == 0 or i == 2) else -1.0
                        dbeta = np.arctan2(sxy * (ny * ux - nx * uy), nx * ux + ny * uy)
                    out_dbeta[a, b, i] = dbeta
                out_count[a, b] = count
                # (N_x, -N_y) = -(F_TR u_TR + F_TL u_TL), as displacement_one
                out_side[a, b] = -w[_L_F, b]
                out_normal[a, b] = w[_L_F + 1, b]
                out_ball_converged[a, b] = True
            for i in range(5):
                out_displacement[a, i] = q[i] * scale[i]
                out_residual[a, i] = residual[0, i] / scale[i]
                for j in range(5):
                    out_stiffness[a, i, j] = tangent[0, i, j] / (scale[i] * scale[j])
            _settle_loose(a, ball_tol * ball_floor, s0, c0, out_force, out_dbeta,
                          out_side, out_normal, out_count)
            if nloaded < nball:
                _unloaded_outputs(loaded[iz], a, out_dbeta, out_force, out_side,
                                  out_normal, out_count, out_ball_converged)
            continue
        dbeta_a = out_dbeta[a]
        force_a = out_force[a]
        for b in range(nball):
            for i in range(4):
                for c in range(6):
                    work[i, c] = base[b, i, c]
            move_top_groove(work, grv[cur, b, 0], grv[cur, b, 1])
            out_count[a, b] = ball_outputs(b, work, pos[cur, b, 0], pos[cur, b, 1], dist,
                                           half[b], k, dbeta_a, force_a, approach, unit)
            # (N_x, -N_y) = -(F_TR u_TR + F_TL u_TL), as displacement_one
            out_side[a, b] = -(force_a[b, 2] * unit[2, 0] + force_a[b, 3] * unit[3, 0])
            out_normal[a, b] = force_a[b, 2] * unit[2, 1] + force_a[b, 3] * unit[3, 1]
            out_ball_converged[a, b] = ball_ok[cur, b]
        for i in range(5):
            out_displacement[a, i] = q[i] * scale[i]
            out_residual[a, i] = residual[cur, i] / scale[i]
            for j in range(5):
                out_stiffness[a, i, j] = tangent[cur, i, j] / (scale[i] * scale[j])
        _settle_loose(a, ball_tol * ball_floor, s0, c0, out_force, out_dbeta, out_side,
                      out_normal, out_count)
        if nloaded < nball:
            _unloaded_outputs(loaded[iz], a, out_dbeta, out_force, out_side, out_normal,
                              out_count, out_ball_converged)
