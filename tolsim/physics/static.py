r"""Static contact model: from groove errors and loads to loaded contact angles and forces.

[Lin2018] takes the contact angles beta_i and the normal forces F_i as given "a priori from
static load distribution models" (its ref. [12]). This module computes them, per ball, in the
cross-section of the bearing (global x lateral, y up, ball centre nominally at the origin).

Gothic-arch geometry
--------------------
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

      u_i = (P - C_i) / |P - C_i|         contact direction (ball centre -> contact)
      beta_i from u_i = (sx_i sin beta_i, sy_i cos beta_i), sx = (-,+,+,-), sy = (-,-,+,+)
      delta_i = |P - C_i| - d + dD/2      approach (negative: a gap)
      F_i = K max(delta_i, 0)^1.5         Hertz, K from :func:`tolsim.physics.hertz.hertz_constants`

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

Static solutions
----------------
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
per instruction (the vectorised path: comment block above ``_LANE_STEPS``), each result
verified and, if the check fails, solved again by the scalar Newton.

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

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033 (Sec. 2.1, Fig. 2,
   Fig. 6, Table 2).
.. [Johnson1985] K. L. Johnson, Contact Mechanics, Cambridge University Press, 1985 (Hertz).
"""

from dataclasses import dataclass, fields

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics._fastmath import SMALL_ANGLE, SMALL_TAN, atan_small, sin_cosm1_small
from tolsim.physics.geometry import CONTACTS, TABLE1, Bearing
from tolsim.physics.hertz import hertz_constants

#: Default relative tolerance on the force imbalance (relative to the largest of |N|, F_i);
#: Newton converges quadratically, so this costs at most one step over 1e-10 and leaves the
#: imbalance at round-off level.
DEFAULT_TOLERANCE = 1e-12
#: Default cap on Newton steps per groove.
DEFAULT_MAX_ITER = 50
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


@jit
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


@jit
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


@jit
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


@jit
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


@jit
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
    """n_i and the signs (sx, sy) of flank i (module docstring)."""
    sx = -1.0 if (i == 0 or i == 3) else 1.0
    sy = -1.0 if i < 2 else 1.0
    return sx * s0, sy * c0, sx, sy


@jit
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


@jit
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


@jit
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


@jit
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
    """Load-controlled static solution of every ball (see the module docstring).

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


@jit
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


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class GrooveErrors:
    """Manufacturing and assembly errors of the grooves and the ball (SI units, default 0).

    Every field broadcasts against the ball shape: per-flank fields to (..., 4) in the order
    BL, BR, TR, TL, per-groove vectors to (..., 2) as (x, y), the rest to (...). The
    geometric meaning and sign of each is drawn in the module docstring.

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


def _as_float(name, value):
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

    ``items`` is a list of (name, value, trailing) with trailing 0 (per ball), 2 or 4.
    Returns (arrays, ball_shape).
    """
    arrays = []
    shapes = []
    for name, value, trailing in items:
        arr = _as_float(name, value)[0]
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
    for (_name, _value, trailing), arr, shape in zip(items, arrays, shapes, strict=True):
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
    """``prepare_inputs`` items of a GrooveErrors, each field checked finite and in range.

    Rotations must stay within +/-pi/8 rad and lengths within +/-(R_G - R_B)/4.
    """
    errors = GrooveErrors() if errors is None else errors
    if not isinstance(errors, GrooveErrors):
        raise ValueError(f"errors must be a GrooveErrors, got {type(errors).__name__}")
    dist = bearing.groove_radius - bearing.ball_radius
    items = []
    for f in fields(GrooveErrors):
        name = f"errors.{f.name}"
        arr, largest = _as_float(name, getattr(errors, f.name))
        if f.name.endswith("rotation"):
            limit, unit = np.pi / 8, "rad"
        else:
            limit, unit = 0.25 * dist, "m"
        if largest > limit:
            raise ValueError(f"{name} must stay within +/-{limit:.3g} {unit} "
                             f"(|value| up to {largest:.3g} {unit})")
        items.append((name, arr, GrooveErrors.TRAILING[f.name]))
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
    that the ball and the top groove are in equilibrium (module docstring), with exact Hertz
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
        the forces from statics (see the module docstring).
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
    """
    check_solver_options(tol, max_iter)
    items = [("side_load", side_load, 0), ("normal_load", normal_load, 0)]
    items += error_items(errors, bearing)
    arrays, shape = prepare_inputs(items, bearing)
    nx, ny, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize = arrays
    nx, ny, rot_b, rot_t, oversize = (a[:, 0] for a in (nx, ny, rot_b, rot_t, oversize))
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
    rot_b, rot_t, oversize = (a[:, 0] for a in (rot_b, rot_t, oversize))
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


# --------------------------------------------------------------------------------------------
# Linear sensitivities and the linearised model
# --------------------------------------------------------------------------------------------
#: Output rows of the sensitivity matrix and their units.
SENSITIVITY_ROWS = tuple(f"contact_angle_deviation_{c}" for c in CONTACTS) + tuple(
    f"normal_force_{c}" for c in CONTACTS)
SENSITIVITY_ROW_UNITS = ("rad",) * 4 + ("N",) * 4
#: Input columns: (label, GrooveErrors field or load name, component index or None, unit).
_COLUMNS = (
    [(f"arc_centre_offset_normal_{c}", "arc_centre_offset_normal", i, "m")
     for i, c in enumerate(CONTACTS)]
    + [(f"arc_centre_offset_tangential_{c}", "arc_centre_offset_tangential", i, "m")
       for i, c in enumerate(CONTACTS)]
    + [("bottom_rotation", "bottom_rotation", None, "rad"),
       ("top_rotation", "top_rotation", None, "rad"),
       ("bottom_offset_x", "bottom_offset", 0, "m"), ("bottom_offset_y", "bottom_offset", 1, "m"),
       ("top_offset_x", "top_offset", 0, "m"), ("top_offset_y", "top_offset", 1, "m"),
       ("ball_oversize", "ball_oversize", None, "m"),
       ("side_load", "side_load", None, "N"), ("normal_load", "normal_load", None, "N")]
)
SENSITIVITY_COLUMNS = tuple(c[0] for c in _COLUMNS)
SENSITIVITY_COLUMN_UNITS = tuple(c[3] for c in _COLUMNS)


@dataclass(frozen=True)
class StaticSensitivity:
    """Linear sensitivities d(dbeta_i, F_i) / d(errors, loads) of one ball at a nominal state.

    Attributes
    ----------
    matrix : ndarray, (8, 17)
        ``matrix[r, c]`` = d row_r / d column_c, in row unit per column unit (e.g. rad/m).
    rows, row_units : tuple of str
        ``SENSITIVITY_ROWS`` (dbeta_BL..TL [rad], F_BL..TL [N]) and their units.
    columns, column_units : tuple of str
        ``SENSITIVITY_COLUMNS``: the 8 arc-centre offsets, the two rotations, the four groove
        offset components, the ball oversize, then N_x and N_y; and their units.
    nominal : StaticSolution
        The solution at the nominal state (ball shape ()).
    side_load, normal_load : float
        Nominal loads [N].
    errors : GrooveErrors
        Nominal errors.
    rigid : bool
        Whether the rigid (geometric) solution was differentiated.
    """

    matrix: np.ndarray
    rows: tuple
    row_units: tuple
    columns: tuple
    column_units: tuple
    nominal: StaticSolution
    side_load: float
    normal_load: float
    errors: GrooveErrors
    rigid: bool

    def entry(self, row: str, column: str) -> float:
        """One derivative by labels, e.g. ``entry("contact_angle_deviation_BL",
        "bottom_rotation")``."""
        return float(self.matrix[self.rows.index(row), self.columns.index(column)])

    def table(self) -> str:
        """Plain-text table in practical units (deg and N per um, per deg and per N)."""
        conv_row = [np.rad2deg(1.0)] * 4 + [1.0] * 4
        unit_row = ["deg"] * 4 + ["N"] * 4
        col_scale = {"m": (1e-6, "um"), "rad": (np.deg2rad(1.0), "deg"), "N": (1.0, "N")}
        head = f"{'d(row)/d(column)':<40}" + "".join(f"{'db_' + r[-2:]:>11}" for r in self.rows[:4])
        head += "".join(f"{'F_' + r[-2:]:>11}" for r in self.rows[4:])
        lines = [head, " " * 40 + "".join(f"{'[' + u + '/.]':>11}" for u in unit_row)]
        for j, (col, unit) in enumerate(zip(self.columns, self.column_units, strict=True)):
            scale, label = col_scale[unit]
            vals = self.matrix[:, j] * scale * np.array(conv_row)
            lines.append(f"{col + ' [./' + label + ']':<40}"
                         + "".join(f" {v:10.4g}" for v in vals))
        return "\n".join(lines)


def _single(errors, name):
    """Each field of ``errors`` reduced to one ball (raise if it holds several)."""
    errors = GrooveErrors() if errors is None else errors
    if not isinstance(errors, GrooveErrors):
        raise ValueError(f"{name} must be a GrooveErrors, got {type(errors).__name__}")
    out = {}
    for f in fields(GrooveErrors):
        trailing = GrooveErrors.TRAILING[f.name]
        arr = _as_float(f"{name}.{f.name}", getattr(errors, f.name))[0]
        target = (trailing,) if trailing else ()
        try:
            out[f.name] = np.broadcast_to(arr, target).copy()
        except ValueError:
            raise ValueError(f"{name}.{f.name} must describe a single ball (shape {target} "
                             f"or broadcastable), got {arr.shape}") from None
    return out


def static_sensitivity(side_load: float, normal_load: float, errors: GrooveErrors | None = None,
                       bearing: Bearing = TABLE1, *, rigid: bool = False,
                       length_step: float = 1e-9, angle_step: float = 1e-7,
                       load_step: float | None = None) -> StaticSensitivity:
    """Matrix of d(dbeta_i, F_i)/d(errors, loads) at one nominal state, by central differences.

    All 2 x 17 perturbed states and the nominal one are solved in one vectorised call of
    :func:`solve_static`. For a rigid ball at the nominal centre the tangential arc-centre
    offset gives d beta_i / d e_t = 1 / ((f - 1/2) 2 R_B) (0.1432 deg/um for Table 1) and a
    groove rotation d beta = -/+ 1 ([Lin2018] Fig. 6); the elastic solution shows how the load
    changes those.

    Parameters
    ----------
    side_load, normal_load : float
        Nominal N_x, N_y [N].
    errors : GrooveErrors, optional
        Nominal errors of one ball (default: none).
    bearing : Bearing
        Geometry and material.
    rigid : bool
        Differentiate the rigid (geometric) solution instead of the elastic one.
    length_step, angle_step : float
        Central-difference steps for lengths [m] and rotations [rad].
    load_step : float, optional
        Step for the loads [N]; default 1e-6 max(|N_x|, N_y, 1 N).

    Returns
    -------
    StaticSensitivity
    """
    base = _single(errors, "errors")
    nx0 = float(_as_float("side_load", side_load)[0])
    ny0 = float(_as_float("normal_load", normal_load)[0])
    for name, step in (("length_step", length_step), ("angle_step", angle_step)):
        if not (np.isfinite(step) and step > 0):
            raise ValueError(f"{name} = {step!r} must be positive")
    if load_step is None:
        load_step = 1e-6 * max(abs(nx0), abs(ny0), 1.0)
    if not (np.isfinite(load_step) and load_step > 0):
        raise ValueError(f"load_step = {load_step!r} must be positive")
    ncol = len(_COLUMNS)
    nball = 2 * ncol + 1
    batch = {k: np.repeat(v[None, ...], nball, axis=0) for k, v in base.items()}
    loads = {"side_load": np.full(nball, nx0), "normal_load": np.full(nball, ny0)}
    steps = np.empty(ncol)
    for j, (_label, field, comp, unit) in enumerate(_COLUMNS):
        h = {"m": length_step, "rad": angle_step, "N": load_step}[unit]
        steps[j] = h
        arr = loads[field] if field in loads else batch[field]
        for sign, row in ((1.0, 1 + 2 * j), (-1.0, 2 + 2 * j)):
            if comp is None:
                arr[row] += sign * h
            else:
                arr[row, comp] += sign * h
    sol = solve_static(loads["side_load"], loads["normal_load"], GrooveErrors(**batch), bearing,
                       rigid=rigid)
    out = np.concatenate([sol.contact_angle_deviation, sol.normal_force], axis=1)  # (nball, 8)
    matrix = (out[1::2] - out[2::2]).T / (2.0 * steps)
    nominal = StaticSolution(*(getattr(sol, f.name)[0] for f in fields(StaticSolution)))
    return StaticSensitivity(matrix, SENSITIVITY_ROWS, SENSITIVITY_ROW_UNITS,
                             SENSITIVITY_COLUMNS, SENSITIVITY_COLUMN_UNITS, nominal, nx0, ny0,
                             GrooveErrors(**base), bool(rigid))


def linearised_static(sensitivity: StaticSensitivity, side_load=None, normal_load=None,
                      errors: GrooveErrors | None = None):
    """Cheap first-order prediction of dbeta_i and F_i from a :class:`StaticSensitivity`.

    dbeta = dbeta_nom + S_beta (x - x_nom), F = F_nom + S_F (x - x_nom), with x the 17
    inputs of the sensitivity columns. No flank unloading and no convergence check: use only
    where the full solution stays in four-point contact (its error against
    :func:`solve_static` is measured in ``tests/test_static.py`` and
    ``benchmarks/bench_static.py``).

    Parameters
    ----------
    sensitivity : StaticSensitivity
        Linearisation point and matrix.
    side_load, normal_load : array_like, optional
        Loads [N] (default: the nominal ones).
    errors : GrooveErrors, optional
        Errors of the balls (default: the nominal ones).

    Returns
    -------
    contact_angle_deviation, normal_force : ndarray, s + (4,)
        dbeta_i [rad] and F_i [N] (F_i clipped at 0).
    """
    nominal = sensitivity.errors
    errors = nominal if errors is None else errors
    nx = sensitivity.side_load if side_load is None else side_load
    ny = sensitivity.normal_load if normal_load is None else normal_load
    items = [("side_load", nx, 0), ("normal_load", ny, 0)]
    items += [(f"errors.{f.name}", getattr(errors, f.name), GrooveErrors.TRAILING[f.name])
              for f in fields(GrooveErrors)]
    arrays, shape = prepare_inputs(items, TABLE1)
    values = dict(zip(["side_load", "normal_load"] + [f.name for f in fields(GrooveErrors)],
                      arrays, strict=True))
    base = _single(nominal, "sensitivity.errors")
    base["side_load"] = np.array(sensitivity.side_load)
    base["normal_load"] = np.array(sensitivity.normal_load)
    size = int(np.prod(shape))
    delta = np.zeros((size, len(_COLUMNS)))
    for j, (_label, field, comp, _unit) in enumerate(_COLUMNS):
        col = values[field][:, 0 if comp is None else comp]
        ref = base[field] if comp is None else base[field][comp]
        delta[:, j] = col - ref
    nom = np.concatenate([sensitivity.nominal.contact_angle_deviation,
                          sensitivity.nominal.normal_force])
    pred = nom + delta @ sensitivity.matrix.T
    return (pred[:, :4].reshape(shape + (4,)),
            np.maximum(pred[:, 4:], 0.0).reshape(shape + (4,)))


__all__ = [
    "CONTACTS",
    "DEFAULT_MAX_ITER",
    "DEFAULT_TOLERANCE",
    "GrooveErrors",
    "SENSITIVITY_COLUMNS",
    "SENSITIVITY_ROWS",
    "StaticSensitivity",
    "StaticSolution",
    "linearised_static",
    "solve_static",
    "solve_static_displacement",
    "static_sensitivity",
]
