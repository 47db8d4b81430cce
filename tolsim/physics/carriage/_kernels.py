"""Numba kernels of the carriage: ball-by-ball balance, condensed stiffness, nested Newton."""

import numpy as np

from tolsim._jit import jit
from tolsim.physics.carriage._map_kernels import singular_pivot
from tolsim.physics.carriage.layout import CarriageStatus
from tolsim.physics.static import displacement_one, flank, flank_newton, move_top_groove

#: Largest groove displacement [fraction of d = R_G - R_B] a Newton step may take, and the
#: largest total groove displacement before the carriage counts as lifted off.
STEP_CAP = 0.05
LIFT_OFF = 0.25


# --------------------------------------------------------------------------------------------
# Kernel
# --------------------------------------------------------------------------------------------
@jit(inline="always")
def schur_complement(kb11, kb12, kb22, kt11, kt12, kt22):
    """S = K_t - K_t M^-1 K_t [N/m] and M^-1 K_t [-] of a ball, M = K_b + K_t.

    K_b, K_t: the (symmetric) stiffness sums of its rail and carriage flanks [N/m]. Both are
    0 where the carriage flanks carry nothing or M is singular (det M <= 1e-14 tr(M)^2).
    Branch-free (selects), so that it vectorises inside a loop over balls.

    Returns
    -------
    s11, s12, s22, r11, r12, r21, r22 : float
    """
    m11, m12, m22 = kb11 + kt11, kb12 + kt12, kb22 + kt22
    det = m11 * m22 - m12 * m12
    trace = m11 + m22
    ok = (kt11 + kt22 > 0.0) & (det > 1e-14 * (trace * trace))
    safe = det if ok else 1.0
    keep = 1.0 if ok else 0.0
    # K_t M^-1 K_t with M^-1 = [[m22, -m12], [-m12, m11]] / det
    i11, i12, i22 = m22 / safe, -m12 / safe, m11 / safe
    w11 = kt11 * i11 + kt12 * i12  # W = K_t M^-1 = (M^-1 K_t)^T
    w12 = kt11 * i12 + kt12 * i22
    w21 = kt12 * i11 + kt22 * i12
    w22 = kt12 * i12 + kt22 * i22
    s11 = keep * (kt11 - (w11 * kt11 + w12 * kt12))
    s12 = keep * (kt12 - 0.5 * ((w11 * kt12 + w12 * kt22) + (w21 * kt11 + w22 * kt12)))
    s22 = keep * (kt22 - (w21 * kt12 + w22 * kt22))
    return s11, s12, s22, keep * w11, keep * w21, keep * w12, keep * w22


@jit(inline="always")
def condensed_ball(px, py, cen, dist, h, k):
    """Condensed stiffness, response, groove force and Hertz energy of a ball at P.

    From the flank stiffnesses k_i = F_i' u_i u_i^T + (F_i / |P - C_i|)(I - u_i u_i^T) (Notes of
    :func:`solve_carriage`), summed over the rail flanks (K_b) and the carriage flanks (K_t),
    M = K_b + K_t:
    the ball's balance sum_i F_i u_i = 0 moves by dP = M^-1 K_t dg under a groove translation
    dg (d(sum F_i u_i) = M dP - K_t dg), and the force of the ball on its groove, f = F_TR u_TR
    + F_TL u_TL, by df = -K_t dg + K_t dP = -S dg with the Schur complement S = K_t - K_t M^-1
    K_t (symmetric).

    Parameters
    ----------
    px, py : float
        Ball centre P (module frame) [m].
    cen : ndarray, (4, 6)
        Arc centres (``tolsim.physics.static.arc_centres``), carriage groove already moved.
    dist, h, k : float
        d = R_G - R_B [m], half the oversize [m], Hertz constant [N/m^1.5].

    Returns
    -------
    s11, s12, s22 : float
        S [N/m] (0 when the carriage flanks carry nothing or M is singular).
    r11, r12, r21, r22 : float
        M^-1 K_t [-] (0 likewise): the linear predictor of the ball position.
    fx, fy : float
        f [N].
    energy : float
        sum_i (2/5) K delta_i^2.5 = sum_i (2/5) F_i delta_i [J].
    fmax : float
        Largest flank force [N].
    bx, by : float
        Force imbalance of the ball, sum_i F_i u_i [N].
    m11, m12, m22 : float
        M [N/m].
    loaded : int
        Bit i set where flank i (BL, BR, TR, TL) carries force.
    """
    kb11 = kb12 = kb22 = kt11 = kt12 = kt22 = 0.0
    energy = fx = fy = bx = by = fmax = 0.0
    loaded = 0
    for i in range(4):
        ux, uy, inv, delta, f, df = flank(px, py, cen, i, dist, h, k)
        if f > 0.0:
            g = f * inv
            a11 = df * ux * ux + g * (1.0 - ux * ux)
            a12 = (df - g) * ux * uy
            a22 = df * uy * uy + g * (1.0 - uy * uy)
            energy += 0.4 * f * delta
            bx += f * ux
            by += f * uy
            fmax = max(fmax, f)
            loaded |= 1 << i
            if i < 2:
                kb11 += a11
                kb12 += a12
                kb22 += a22
            else:
                kt11 += a11
                kt12 += a12
                kt22 += a22
                fx += f * ux
                fy += f * uy
    s11, s12, s22, r11, r12, r21, r22 = schur_complement(kb11, kb12, kb22, kt11, kt12, kt22)
    return (s11, s12, s22, r11, r12, r21, r22, fx, fy, energy, fmax, bx, by, kb11 + kt11,
            kb12 + kt12, kb22 + kt22, loaded)


@jit
def carriage_balls_kernel(groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, beta0,
                          dist, k, tol, max_iter, floor, out_dbeta, out_force, out_approach,
                          out_ball, out_load, out_converged, out_iter, out_count, out_residual,
                          out_stiffness, out_energy):
    """Displacement-controlled balls with their condensed stiffness and Hertz energy.

    Each ball is solved by :func:`tolsim.physics.static.displacement_one` to a force
    imbalance <= tol max(F_max, floor) [N] (F_max its largest flank force); then
    out_stiffness[n] = K_t - K_t (K_b + K_t)^-1 K_t [N/m] (= -d f / d g, f the force of the
    ball on its carriage groove) and out_energy[n] = sum_i (2/5) K delta_i^2.5 [J]
    (:func:`condensed_ball`).
    """
    s0, c0 = np.sin(beta0), np.cos(beta0)
    cen = np.empty((4, 6))
    unit = np.empty((4, 2))
    for n in range(out_dbeta.shape[0]):
        displacement_one(n, groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, s0,
                         c0, dist, k, tol, max_iter, floor, cen, unit, out_dbeta, out_force,
                         out_approach, out_ball, out_load, out_converged, out_iter, out_count,
                         out_residual)
        h = 0.5 * oversize[n if oversize.shape[0] > 1 else 0]
        # cen holds the arc centres moved with the groove
        s11, s12, s22, _, _, _, _, _, _, energy, _, _, _, _, _, _, _ = condensed_ball(
            out_ball[n, 0], out_ball[n, 1], cen, dist, h, k)
        out_stiffness[n, 0, 0] = s11
        out_stiffness[n, 0, 1] = s12
        out_stiffness[n, 1, 0] = s12
        out_stiffness[n, 1, 1] = s22
        out_energy[n] = energy
#: Status codes of a batched assembly (:class:`CarriageBatch`), as plain ints for the kernels:
#: the values of :class:`CarriageStatus`.
STATUS_CONVERGED = int(CarriageStatus.CONVERGED)
STATUS_NOT_CONVERGED = int(CarriageStatus.NOT_CONVERGED)
STATUS_LIFT_OFF = int(CarriageStatus.LIFT_OFF)
STATUS_FAILED = int(CarriageStatus.FAILED)
BATCH_STATUS = {int(s): s.describe() for s in CarriageStatus}


@jit(leaf=True)
def _evaluate_balls(q, warm, src, dst, groove_map, base, half, dist, k, ball_tol,
                    ball_max_iter, floor, limit, q_ext, pos, grv, resp, ball_ok, work,
                    residual, tangent, state):
    """All balls of one assembly at the scaled carriage displacement q, into buffer ``dst``.

    Ball b's carriage groove moves by g_b = A_b q; its centre is solved by
    :func:`tolsim.physics.static.flank_newton` (all four flanks, displacement control),
    started, if ``warm``, from the solution in buffer ``src`` plus the linear predictor
    M^-1 K_t (g_b - g_b,src) (:func:`condensed_ball`), else from the mean of the four
    touching positions as :func:`tolsim.physics.static.displacement_one`, to an imbalance
    <= ball_tol max(F_max, floor) [N] (the last Newton step predicted, then verified here).
    Then residual[dst] = Q + sum_b A_b^T f_b, tangent[dst] = sum_b A_b^T S_b A_b and
    state[dst] = (Hertz energy [J], largest flank force [N], sum_b |f_b|^2 [N^2]).

    Returns 0 (every ball solved), 1 (a groove moved beyond ``limit``: no ball solved) or 2
    (a ball solve failed; ball_ok[dst] says which).
    """
    nball = groove_map.shape[0]
    gmax = 0.0
    for b in range(nball):
        ball_ok[dst, b] = False
        for c in range(2):
            g = 0.0
            for j in range(5):
                g += groove_map[b, c, j] * q[j]
            grv[dst, b, c] = g
            gmax = max(gmax, abs(g))
    if not gmax <= limit:
        return 1
    for i in range(5):
        residual[dst, i] = q_ext[i]
        for j in range(5):
            tangent[dst, i, j] = 0.0
    energy = fmax = force2 = 0.0
    status = 0
    reg = 1.5 * k * 1e-3  # as displacement_one: dF/ddelta at a 1 um approach
    for b in range(nball):
        gx, gy = grv[dst, b, 0], grv[dst, b, 1]
        for i in range(4):
            for c in range(6):
                work[i, c] = base[b, i, c]
        move_top_groove(work, gx, gy)
        h = half[b]
        if warm:
            dgx, dgy = gx - grv[src, b, 0], gy - grv[src, b, 1]
            px = pos[src, b, 0] + resp[src, b, 0] * dgx + resp[src, b, 1] * dgy
            py = pos[src, b, 1] + resp[src, b, 2] * dgx + resp[src, b, 3] * dgy
        else:
            px = py = 0.0
            for i in range(4):
                px += 0.25 * (work[i, 2] - h * work[i, 4])
                py += 0.25 * (work[i, 3] - h * work[i, 5])
        px, py, _, ok, _ = flank_newton(work, 0, 4, dist, h, k, 0.0, 0.0, px, py, ball_tol,
                                        ball_max_iter, floor, reg, True)
        s11, s12, s22, r11, r12, r21, r22, fx, fy, en, fm, bx, by, _, _, _, _ = condensed_ball(
            px, py, work, dist, h, k)
        if ok and max(abs(bx), abs(by)) > 2.0 * ball_tol * max(fm, floor):
            # the predicted last step of flank_newton missed: polish (as _load_one does)
            px, py, _, ok, _ = flank_newton(work, 0, 4, dist, h, k, 0.0, 0.0, px, py,
                                            ball_tol, ball_max_iter, floor, reg, False)
            s11, s12, s22, r11, r12, r21, r22, fx, fy, en, fm, bx, by, _, _, _, _ = condensed_ball(
                px, py, work, dist, h, k)
        ball_ok[dst, b] = ok
        if not ok:
            status = 2
            continue
        pos[dst, b, 0] = px
        pos[dst, b, 1] = py
        resp[dst, b, 0] = r11
        resp[dst, b, 1] = r12
        resp[dst, b, 2] = r21
        resp[dst, b, 3] = r22
        energy += en
        fmax = max(fmax, fm)
        force2 += fx * fx + fy * fy
        for j in range(5):
            a0, a1 = groove_map[b, 0, j], groove_map[b, 1, j]
            residual[dst, j] += a0 * fx + a1 * fy
            sa0 = s11 * a0 + s12 * a1  # (S A)_j
            sa1 = s12 * a0 + s22 * a1
            for i in range(j + 1):
                tangent[dst, i, j] += groove_map[b, 0, i] * sa0 + groove_map[b, 1, i] * sa1
    for j in range(5):
        for i in range(j):
            tangent[dst, j, i] = tangent[dst, i, j]
    state[dst, 0] = energy
    state[dst, 1] = fmax
    state[dst, 2] = force2
    return status


@jit(inline="always")
def cholesky(mat, free, low):
    """L L^T = mat[free][:, free] into low; returns the smallest pivot (before its square
    root; <= 0 or NaN: not positive definite, low incomplete)."""
    nf = free.shape[0]
    pmin = np.inf
    for i in range(nf):
        for j in range(i + 1):
            s = mat[free[i], free[j]]
            for m in range(j):
                s -= low[i, m] * low[j, m]
            if i == j:
                pmin = min(pmin, s)
                if not s > 0.0:
                    return s
                low[i, i] = np.sqrt(s)
            else:
                low[i, j] = s / low[j, j]
    return pmin


@jit(inline="always")
def cholesky_solve(low, free, rhs, x):
    """x[free] = (L L^T)^-1 rhs[free], x = 0 elsewhere (x has 5 entries)."""
    nf = free.shape[0]
    for j in range(5):
        x[j] = 0.0
    for i in range(nf):  # forward: L y = rhs, y stored in x[free]
        s = rhs[free[i]]
        for m in range(i):
            s -= low[i, m] * x[free[m]]
        x[free[i]] = s / low[i, i]
    for i in range(nf - 1, -1, -1):  # back: L^T x = y
        s = x[free[i]]
        for m in range(i + 1, nf):
            s -= low[m, i] * x[free[m]]
        x[free[i]] = s / low[i, i]


@jit(inline="always")
def scaled_error(residual, free, scale):
    """max |residual[free]| / scale."""
    err = 0.0
    for i in range(free.shape[0]):
        err = max(err, abs(residual[free[i]]))
    return err / scale


@jit(leaf=True)
def nested_newton(q, free, groove_map, geometric, base, half, s0, c0, dist, k, tol, max_iter,
                   ball_tol, ball_max_iter, ball_floor, force_floor, load_norm, k_ref, singular,
                   cap, limit, q_ext, pos, grv, resp, ball_ok, work, residual, tangent, state,
                   kreg, low, step, trial):
    """The Newton of :func:`solve_carriage` on q, every ball solved at each evaluation.

    A regularised step from a state with no carriage flank loaded that closes no contact
    settles the carriage along it (:func:`settle`; Notes of :func:`solve_carriage`,
    "Settling"). ``singular``: the threshold of :func:`singular_pivot` (3,).
    Returns (status, iterations, buffer of the solution, buffer of the last
    evaluation); the status is STATUS_LIFT_OFF only from :func:`settle`, STATUS_FAILED where
    no step stays in the gothic arch or a ball solve fails.
    """
    nball = groove_map.shape[0]
    cur = 0
    last = 0
    it = 0
    if _evaluate_balls(q, False, 0, cur, groove_map, base, half, dist, k, ball_tol,
                       ball_max_iter, ball_floor, limit, q_ext, pos, grv, resp, ball_ok, work,
                       residual, tangent, state) != 0:
        return STATUS_LIFT_OFF, it, cur, last
    status = STATUS_NOT_CONVERGED
    potential = state[cur, 0]
    for j in range(5):
        potential -= q_ext[j] * q[j]
    while True:
        err = scaled_error(residual[cur], free, max(max(load_norm, state[cur, 1]), force_floor))
        if err <= tol:
            status = STATUS_CONVERGED
            break
        if it >= max_iter:
            break
        it += 1
        loose = not state[cur, 2] > 0.0  # no carriage flank loaded
        if singular_pivot(cholesky(tangent[cur], free, low), singular, geometric, free,
                          k_ref, kreg):  # singular: regularise (kreg: scratch until here)
            for i in range(5):
                for j in range(5):
                    kreg[i, j] = tangent[cur, i, j] + k_ref * geometric[i, j]
            if not cholesky(kreg, free, low) > 0.0:
                return STATUS_FAILED, it, cur, last
        cholesky_solve(low, free, residual[cur], step)
        move = 0.0
        for b in range(nball):
            for c in range(2):
                g = 0.0
                for j in range(5):
                    g += groove_map[b, c, j] * step[j]
                move = max(move, abs(g))
        if move > cap:
            for j in range(5):
                step[j] *= cap / move
        slope = 0.0  # d potential / d alpha at 0
        for j in range(5):
            slope -= residual[cur, j] * step[j]
        nxt = 1 - cur
        alpha = 1.0
        found = -1.0  # alpha of the last valid candidate
        last_ok = False
        accepted = False
        pot = potential
        for _ in range(40):
            for j in range(5):
                trial[j] = q[j] + alpha * step[j]
            last = nxt
            last_ok = _evaluate_balls(trial, True, cur, nxt, groove_map, base, half, dist, k,
                                      ball_tol, ball_max_iter, ball_floor, limit, q_ext, pos,
                                      grv, resp, ball_ok, work, residual, tangent, state) == 0
            if last_ok:
                found = alpha
                pot = state[nxt, 0]
                for j in range(5):
                    pot -= q_ext[j] * trial[j]
                scale = max(max(load_norm, state[nxt, 1]), force_floor)
                if (pot <= potential + 1e-4 * alpha * slope
                        or scaled_error(residual[nxt], free, scale) < (1.0 - 1e-4 * alpha) * err):
                    accepted = True
                    break
            alpha *= 0.5
        if found < 0.0:
            return STATUS_FAILED, it, cur, last
        if not accepted:  # the last valid candidate (re-evaluated if overwritten since)
            alpha = found
            for j in range(5):
                trial[j] = q[j] + alpha * step[j]
            if not last_ok:
                last = nxt
                _evaluate_balls(trial, True, cur, nxt, groove_map, base, half, dist, k,
                                ball_tol, ball_max_iter, ball_floor, limit, q_ext, pos, grv,
                                resp, ball_ok, work, residual, tangent, state)
            pot = state[nxt, 0]
            for j in range(5):
                pot -= q_ext[j] * trial[j]
        for j in range(5):
            q[j] = trial[j]
        potential = pot
        cur = nxt
        last = cur
        if loose and not state[cur, 2] > 0.0:  # the step closed no contact: settle
            code, cur = settle(q, step, cur, groove_map, base, half, s0, c0, dist, k, ball_tol,
                               ball_max_iter, ball_floor, limit, q_ext, pos, grv, resp, ball_ok,
                               work, residual, tangent, state, trial)
            last = cur
            if code != STATUS_CONVERGED:
                return code, it, cur, last
            potential = state[cur, 0]
            for j in range(5):
                potential -= q_ext[j] * q[j]
    return status, it, cur, last


@jit(leaf=True)
def receding(groove_map, step, s0, c0):
    """Whether the carriage motion ``step`` moves every carriage flank away from its ball.

    The approach of carriage flank i changes by -u_i . dg under a groove translation dg, u_i
    the direction from the ball centre to the contact, nominally (s0, c0) for TR and (-s0,
    c0) for TL (module frame): both recede where c0 dg_2 >= s0 |dg_1| (to round-off, 1e-12
    of the largest groove travel). A ball held by its two flanks in a gothic arch then has
    no contact left to close, whatever its clearance.
    """
    big = 0.0
    for b in range(groove_map.shape[0]):
        for c in range(2):
            g = 0.0
            for j in range(5):
                g += groove_map[b, c, j] * step[j]
            big = max(big, abs(g))
    for b in range(groove_map.shape[0]):
        g1 = g2 = 0.0
        for j in range(5):
            g1 += groove_map[b, 0, j] * step[j]
            g2 += groove_map[b, 1, j] * step[j]
        if c0 * g2 - s0 * abs(g1) < -1e-12 * big:
            return False
    return True


@jit(leaf=True)
def _ray_slope(residual, src, step):
    """Slope -R . step of the carriage's potential along ``step`` (evaluation ``src``)."""
    slope = 0.0
    for j in range(5):
        slope -= residual[src, j] * step[j]
    return slope


@jit(leaf=True)
def _at_distance(s, q, step, trial, src, groove_map, base, half, dist, k, ball_tol,
                 ball_max_iter, ball_floor, limit, q_ext, pos, grv, resp, ball_ok, work,
                 residual, tangent, state):
    """Evaluate the balls at q + s step (:func:`settle`) into the buffer other than ``src``:
    (a ball solve failed, that buffer)."""
    for j in range(5):
        trial[j] = q[j] + s * step[j]
    dst = 1 - src
    failed = _evaluate_balls(trial, True, src, dst, groove_map, base, half, dist, k, ball_tol,
                             ball_max_iter, ball_floor, limit, q_ext, pos, grv, resp, ball_ok,
                             work, residual, tangent, state) != 0
    return failed, dst


@jit(leaf=True)
def settle(q, step, cur, groove_map, base, half, s0, c0, dist, k, ball_tol, ball_max_iter,
           ball_floor, limit, q_ext, pos, grv, resp, ball_ok, work, residual, tangent, state,
           trial):
    """Carry a carriage that touches nothing along ``step`` until its contacts close.

    The compiled twin of ``solve._settle`` (Notes of :func:`solve_carriage`, "Settling"):
    buffer ``cur`` holds the evaluation at q (no carriage flank loaded); the distance s along
    ``step`` is doubled until the slope -R . step of the potential turns >= 0, then its root
    is found by regula falsi (Illinois) to 1 % of the initial slope. On success q moves to
    q + s step, evaluated in the returned buffer. Returns (status, buffer): STATUS_CONVERGED
    (settled), STATUS_LIFT_OFF (the grooves reach ``limit`` with nothing loaded, every
    carriage flank moving away from its ball: :func:`receding`) or STATUS_FAILED (a ball
    solve failed, or the grooves reach ``limit`` with contacts loaded or approaching).
    """
    nball = groove_map.shape[0]
    move = gmax = 0.0
    for b in range(nball):
        for c in range(2):
            g = gs = 0.0
            for j in range(5):
                g += groove_map[b, c, j] * q[j]
                gs += groove_map[b, c, j] * step[j]
            gmax = max(gmax, abs(g))
            move = max(move, abs(gs))
    s_max = (1.0 - 1e-9) * (limit - gmax) / move  # |A (q + s step)| <= limit for s <= s_max
    slope0 = _ray_slope(residual, cur, step)
    s_lo, d_lo = 0.0, slope0
    s_hi, d_hi = 0.0, 0.0
    s = 1.0
    src = cur
    slope = slope0
    while True:  # bracket the minimum along the ray
        s = min(s, s_max)
        failed, src = _at_distance(s, q, step, trial, src, groove_map, base, half, dist, k,
                                   ball_tol, ball_max_iter, ball_floor, limit, q_ext, pos, grv,
                                   resp, ball_ok, work, residual, tangent, state)
        if failed:
            return STATUS_FAILED, src
        slope = _ray_slope(residual, src, step)
        if slope >= 0.0:
            s_hi, d_hi = s, slope
            break
        s_lo, d_lo = s, slope
        if s >= s_max:
            off = not state[src, 2] > 0.0 and receding(groove_map, step, s0, c0)
            return (STATUS_LIFT_OFF if off else STATUS_FAILED), src
        s *= 2.0
    side = 0
    for _ in range(60):  # regula falsi (Illinois) on the slope
        if abs(slope) <= 1e-2 * abs(slope0) or s_hi - s_lo <= 1e-12 * s_hi:
            break
        s = s_hi - d_hi * (s_hi - s_lo) / (d_hi - d_lo)
        failed, src = _at_distance(s, q, step, trial, src, groove_map, base, half, dist, k,
                                   ball_tol, ball_max_iter, ball_floor, limit, q_ext, pos, grv,
                                   resp, ball_ok, work, residual, tangent, state)
        if failed:
            return STATUS_FAILED, src
        slope = _ray_slope(residual, src, step)
        if slope < 0.0:
            s_lo, d_lo = s, slope
            d_hi = 0.5 * d_hi if side == -1 else d_hi
            side = -1
        else:
            s_hi, d_hi = s, slope
            d_lo = 0.5 * d_lo if side == 1 else d_lo
            side = 1
    if not state[src, 2] > 0.0:
        s = s_hi
        failed, src = _at_distance(s, q, step, trial, src, groove_map, base, half, dist, k,
                                   ball_tol, ball_max_iter, ball_floor, limit, q_ext, pos, grv,
                                   resp, ball_ok, work, residual, tangent, state)
        if failed:
            return STATUS_FAILED, src
    for j in range(5):
        q[j] += s * step[j]
    return STATUS_CONVERGED, src
