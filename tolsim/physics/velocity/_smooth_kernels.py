"""Numba kernels of the smooth solve (regime A): a quasi-Newton solve and the batch drivers of
the smooth model, free (:func:`full_kernel`) and under loads (:func:`full_loaded_kernel`).

The model and the damped Newton it replaces on the planar surface are in the Notes of
:func:`tolsim.physics.velocity.full.full`; the Newton itself is
:func:`tolsim.physics.velocity._full_kernels.solve_one`, the fallback.
"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics.velocity._contact_tables import table_newton_solve
from tolsim.physics.velocity._full_kernels import (
    FD_STEP,
    ball_loads_kernel,
    contact_ellipses,
    residual,
    rolling_start,
    solve_one,
    solve_small,
)
from tolsim.physics.velocity.ball_loads import (
    SIDE_SIGN_X_T,
    SIDE_SIGN_Y_T,
    point_traction_capacity,
    rolling_axis,
    stall_moment,
)

#: Relative step of the forward-difference Jacobian of :func:`quasi_newton_solve`.
QUASI_NEWTON_STEP = 1e-7
#: :func:`quasi_newton_solve` iterates until the residual is below this fraction of ``tol``,
#: so that its answer agrees with the Newton of ``solve_one`` to about the latter's own error.
POLISH = 1e-2
#: The coarse grid of :func:`quasi_newton_solve` takes every COARSE_STRIDE-th angular node.
COARSE_STRIDE = 4
#: Residual to which :func:`quasi_newton_solve` iterates on the coarse grid.
COARSE_TARGET = 1e-6
_SX = (-1.0, 1.0, 1.0, -1.0)
_SY = (-1.0, -1.0, 1.0, 1.0)


@jit
def _equilibrium(state, px, py, vgroove, force, a, b, sigma_scale, rd, hoff, cin, sin_, win, xo,
                 wo, tr, wr, total, loads, contact, res):
    """(F_z, M_x, M_y) / sum F of a planar ball into ``res``; returns max |res| (inf if NaN)."""
    ball_loads_kernel(state, px, py, vgroove, force, a, b, sigma_scale, False, rd, hoff, cin,
                      sin_, win, xo, wo, tr, wr, loads, contact)
    worst = 0.0
    for k in range(3):
        res[k] = loads[k] / total
        worst = max(worst, abs(res[k]))
    if not np.isfinite(worst):
        worst = np.inf
    return worst


@jit
def _broyden(state, px, py, vgroove, force, a, b, sigma_scale, rd, hoff, cin, sin_, win, xo, wo,
             tr, wr, target, max_iter, jac, have, contact):
    """Broyden iterations on one quadrature grid from ``state`` to max |res| <= ``target``.

    ``jac`` is used as the start Jacobian when ``have`` (it is rebuilt by forward differences
    otherwise, and after a step that needed backtracking or failed). Returns (max |res|,
    iterations, whether ``jac`` is current); ``contact`` holds the rows at ``state``.
    """
    total = force[0] + force[1] + force[2] + force[3]
    loads = np.empty(5)
    res = np.empty(3)
    res_new = np.empty(3)
    rp = np.empty(3)
    neg = np.empty(3)
    step = np.zeros(3)
    trial = np.zeros(4)
    work = np.empty((4, contact.shape[1]))
    worst = _equilibrium(state, px, py, vgroove, force, a, b, sigma_scale, rd, hoff, cin, sin_,
                         win, xo, wo, tr, wr, total, loads, contact, res)
    dis = loads[4]
    it = 0
    fresh = False
    while worst > target and it < max_iter:
        it += 1
        if not have:
            for c in range(3):
                h = QUASI_NEWTON_STEP * max(1.0, abs(state[c]))
                trial[:] = state
                trial[c] = state[c] + h
                _equilibrium(trial, px, py, vgroove, force, a, b, sigma_scale, rd, hoff, cin,
                             sin_, win, xo, wo, tr, wr, total, loads, work, rp)
                for r in range(3):
                    jac[r, c] = (rp[r] - res[r]) / h
            have = True
            fresh = True
        merit = 0.0
        for r in range(3):
            neg[r] = -res[r]
            merit += res[r] * res[r]
        accepted = False
        t = 1.0
        new = worst
        if solve_small(jac, neg, 3, step):
            for _ls in range(8):
                for c in range(3):
                    trial[c] = state[c] + t * step[c]
                trial[3] = 0.0
                new = _equilibrium(trial, px, py, vgroove, force, a, b, sigma_scale, rd, hoff,
                                   cin, sin_, win, xo, wo, tr, wr, total, loads, work, res_new)
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
            if fresh:
                break
            have = False  # a stale Jacobian: rebuild it and try again
            continue
        # Broyden's update J += (dr - J dx) dx^T / |dx|^2 with dx = t step
        dx2 = 0.0
        for c in range(3):
            dx2 += (t * step[c]) ** 2
        if dx2 > 0.0:
            for r in range(3):
                u = res_new[r] - res[r]
                for c in range(3):
                    u -= jac[r, c] * t * step[c]
                for c in range(3):
                    jac[r, c] += u * t * step[c] / dx2
        for c in range(3):
            state[c] = trial[c]
            res[c] = res_new[c]
        state[3] = 0.0
        contact[:, :] = work
        worst = new
        dis = loads[4]
        fresh = False
        if t < 1.0:
            have = False
    return worst, it, have


@jit
def quasi_newton_solve(beta, force, a, b, sigma_scale, rd, hoff, tol, max_iter, cin, sin_, win,
                       xo, wo, tr, wr, state, contact, info):
    """Regime A on the planar surface with omega_z = 0: Broyden's method, coarse then fine.

    The same equations, start (pure rolling) and step acceptance as
    :func:`~tolsim.physics.velocity._full_kernels.solve_one` (a step is taken when it lowers
    the sum of squares of the residual or D, Armijo), with two savings:

    * the iteration first runs on a coarse angular grid (every ``COARSE_STRIDE``-th node of
      the trapezoidal rule, the same mapped rule with fewer nodes; the cone rule unchanged) to
      ``COARSE_TARGET``, and then on the given grid from that state and Jacobian;
    * the Jacobian is a forward-difference one (3 evaluations instead of 6), kept from step
      to step with Broyden's rank-one update and rebuilt only after a step that needed
      backtracking or failed; each further step costs one evaluation of the loads.

    On the given grid it runs to ``POLISH * tol``, so that its answer is the root to about the
    accuracy of the Newton's (whose last steps converge quadratically). Writes ``state``,
    ``contact``, ``info`` = (residual, iterations, converged) as ``solve_one``; returns False
    (the caller falls back to ``solve_one``) unless residual <= tol.
    """
    px = np.empty(4)
    py = np.empty(4)
    vgroove = np.array([0.0, 0.0, 1.0, 1.0])
    for i in range(4):
        px[i] = _SX[i] * np.sin(beta[i])
        py[i] = _SY[i] * np.cos(beta[i])
    rolling_start(beta, force, px, py, vgroove, state)
    jac = np.empty((3, 3))
    have = False
    it0 = 0
    nc = cin.shape[0] // COARSE_STRIDE
    if nc >= 8 and nc * COARSE_STRIDE == cin.shape[0]:
        ccin = np.empty(nc)
        csin = np.empty(nc)
        cwin = np.empty(nc)
        for j in range(nc):
            ccin[j] = cin[COARSE_STRIDE * j]
            csin[j] = sin_[COARSE_STRIDE * j]
            cwin[j] = COARSE_STRIDE * win[COARSE_STRIDE * j]
        _, it0, have = _broyden(state, px, py, vgroove, force, a, b, sigma_scale, rd, hoff,
                                ccin, csin, cwin, xo, wo, tr, wr, COARSE_TARGET, max_iter, jac,
                                have, contact)
        if not np.all(np.isfinite(state)):
            rolling_start(beta, force, px, py, vgroove, state)
            have = False
    worst, it, _ = _broyden(state, px, py, vgroove, force, a, b, sigma_scale, rd, hoff, cin,
                            sin_, win, xo, wo, tr, wr, POLISH * tol, max_iter, jac, have,
                            contact)
    info[0] = worst
    info[1] = it0 + it
    info[2] = 1.0 if worst <= tol else 0.0
    return worst <= tol


@jit
def smooth_solve(beta, force, a, b, sigma_scale, curved, rd, hoff, free_spin, tol, max_iter,
                 cin, sin_, win, xo, wo, tr, wr, table, state, contact, info):
    """Regime A of one unloaded ball: on the planar surface with omega_z = 0 the Newton on the
    tables (:func:`~tolsim.physics.velocity._contact_tables.table_newton_solve`), then
    :func:`quasi_newton_solve`; else (or where they fail) the damped Newton
    :func:`~tolsim.physics.velocity._full_kernels.solve_one` from pure rolling."""
    if not curved and not free_spin:
        if table_newton_solve(beta, force, a, b, sigma_scale, tol, max_iter, table, cin, sin_,
                              win, xo, wo, state, contact, info):
            return
        if quasi_newton_solve(beta, force, a, b, sigma_scale, rd, hoff, tol, max_iter, cin, sin_,
                              win, xo, wo, tr, wr, state, contact, info):
            return
    solve_one(beta, force, a, b, sigma_scale, curved, rd, hoff, free_spin, tol, max_iter, cin,
              sin_, win, xo, wo, tr, wr, state, contact, info)


@pjit
def full_kernel(dbeta, force, nominal_angle, semi_major_coefficient, semi_minor_coefficient,
                curved, rd, free_spin, tol, max_iter, cin, sin_, win, xo, wo, tr, wr, table,
                out_state, out_contact, out_info):
    """Solve the full model for n balls in parallel (R = 1, v = 1, mu = 1 units).

    Lengths are in units of R_B (``semi_*_coefficient`` and ``rd`` already divided by R_B).
    """
    sigma_scale = 1.5 / np.pi  # mu sigma_0 a b / F with mu = 1
    for n in prange(dbeta.shape[0]):
        beta = np.empty(4)
        a = np.empty(4)
        b = np.empty(4)
        hoff = np.empty(4)
        contact_ellipses(dbeta[n], force[n], nominal_angle, semi_major_coefficient,
                         semi_minor_coefficient, rd, beta, a, b, hoff)
        state = np.zeros(4)
        contact = np.empty((4, 5))
        info = np.zeros(3)
        npos = 0
        for i in range(4):
            if force[n, i] > 0.0:
                npos += 1
        if npos < 3:
            for k in range(4):
                out_state[n, k] = np.nan
                for m in range(5):
                    out_contact[n, k, m] = np.nan
            out_info[n, 0] = np.inf
            out_info[n, 1] = 0.0
            out_info[n, 2] = 0.0
            continue
        smooth_solve(beta, force[n], a, b, sigma_scale, curved, rd, hoff, free_spin, tol,
                     max_iter, cin, sin_, win, xo, wo, tr, wr, table, state, contact, info)
        for k in range(4):
            out_state[n, k] = state[k]
            for m in range(5):
                out_contact[n, k, m] = contact[k, m]
        out_info[n, 0] = info[0]
        out_info[n, 1] = info[1]
        out_info[n, 2] = info[2]


@jit
def _load_sensitivities(beta, force, semi_major, semi_minor, sigma_scale, curved, rd, hoff,
                        free_spin, push, braking, cin, sin_, win, xo, wo, tr, wr, state):
    """d(epsilon)/d(push) and d(epsilon)/d(braking) at an equilibrium ``state`` (internal units).

    The equilibrium res(x; push, braking) = 0 (res = loads / sum F, x = (v_B, Omega)) moves
    by dx = -J^-1 (d res / d load) d load, J the central-difference Jacobian of the solver;
    d res / d push = e_z / sum F and d res / d braking = -(0, e_x, e_y[, 0]) / sum F with e =
    Omega_perp / |Omega_perp|. epsilon = 2 v_B - 1 (v = 1). NaN if J is singular.
    """
    px = np.empty(4)
    py = np.empty(4)
    vgroove = np.array([0.0, 0.0, 1.0, 1.0])
    sxs = (-1.0, 1.0, 1.0, -1.0)
    sys_ = (-1.0, -1.0, 1.0, 1.0)
    for i in range(4):
        px[i] = sxs[i] * np.sin(beta[i])
        py[i] = sys_[i] * np.cos(beta[i])
    nunk = 4 if free_spin else 3
    total = force[0] + force[1] + force[2] + force[3]
    loads = np.empty(5)
    work = np.empty((4, 5))
    rp = np.empty(4)
    rm = np.empty(4)
    trial = np.empty(4)
    jac = np.empty((nunk, nunk))
    for c in range(nunk):
        hstep = FD_STEP * max(1.0, abs(state[c]))
        trial[:] = state
        trial[c] = state[c] + hstep
        residual(trial, nunk, 0, push, braking, px, py, vgroove, force, semi_major, semi_minor,
                  sigma_scale, curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr, loads, work, rp)
        trial[c] = state[c] - hstep
        residual(trial, nunk, 0, push, braking, px, py, vgroove, force, semi_major, semi_minor,
                  sigma_scale, curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr, loads, work, rm)
        for r in range(nunk):
            jac[r, c] = (rp[r] - rm[r]) / (2.0 * hstep)
    unit = np.zeros(nunk)
    sol = np.zeros(4)
    unit[0] = 1.0 / total
    deps_dpush = np.nan
    if solve_small(jac, unit, nunk, sol):
        deps_dpush = -2.0 * sol[0]
    deps_dbraking = np.nan
    spin_perp = np.hypot(state[1], state[2])
    if spin_perp > 0.0:
        unit[0] = 0.0
        unit[1] = -state[1] / spin_perp / total
        unit[2] = -state[2] / spin_perp / total
        if solve_small(jac, unit, nunk, sol):
            deps_dbraking = -2.0 * sol[0]
    return deps_dpush, deps_dbraking


#: Columns of ``out_load`` of :func:`full_loaded_kernel` (internal units, over mu).
FULL_LOAD_COLUMNS = ("traction_capacity", "saturated_carriage_force", "capacity_residual",
                     "velocity_deviation_per_push", "velocity_deviation_per_braking",
                     "sliding", "stall_moment")


@pjit
def full_loaded_kernel(dbeta, force, push, braking, nominal_angle, semi_major_coefficient,
                       semi_minor_coefficient, curved, rd, free_spin, tol, max_iter, cin, sin_,
                       win, xo, wo, tr, wr, table, out_state, out_contact, out_info, out_load):
    """The full model under external loads, n balls in parallel (R = 1, v = 1, mu = 1 units).

    ``push`` (n,) = P / mu [N] and ``braking`` (n,) = (mu_bb / mu)(Q_back + Q_front) [N]
    (:mod:`tolsim.physics.velocity.ball_loads`). Per ball:

    1. the traction capacity P_cap / mu = min over Omega of Phi_0, the ball sliding at
       v_B = 1 between grooves at rest (Newton on the moment rows from the point-contact
       minimiser, :func:`~tolsim.physics.velocity.ball_loads.point_traction_capacity`; exactly
       sum F_i with Omega = 0 when the pure-sliding moment sum F_i x_i is within the braking,
       the kink of |Omega_perp|); P_cap is D + braking |Omega_perp| there, the saturated
       carriage force F_c / mu = f_TR + f_TL of that state;
    2. if |push| < P_cap, the loaded equilibrium (F_z + push = 0, moments with the braking)
       from pure rolling, and d(epsilon)/d(push), d(epsilon)/d(braking) from its Jacobian
       (:func:`_load_sensitivities`); otherwise the ball slides (no state: NaN). Likewise
       when ``braking`` >= :func:`~tolsim.physics.velocity.ball_loads.stall_moment` (the braking
       stalls
       the rotation; sliding = 2.0).

    ``out_contact`` (n, 4, 6): as :func:`full_kernel` plus the contact power D_i. ``out_load``
    (n, 7): the columns ``FULL_LOAD_COLUMNS`` (capacity residual 0 when exact; sliding 0.0,
    1.0 for |push| >= capacity, 2.0 for a stall; stall moment over mu). ``out_info`` of a
    sliding ball is that of the capacity solve.
    """
    sigma_scale = 1.5 / np.pi
    for n in prange(dbeta.shape[0]):
        beta = np.empty(4)
        a = np.empty(4)
        b = np.empty(4)
        hoff = np.empty(4)
        contact_ellipses(dbeta[n], force[n], nominal_angle, semi_major_coefficient,
                         semi_minor_coefficient, rd, beta, a, b, hoff)
        for k in range(4):
            out_state[n, k] = np.nan
            for m in range(6):
                out_contact[n, k, m] = np.nan
        for m in range(7):
            out_load[n, m] = np.nan
        out_info[n, 0] = np.inf
        out_info[n, 1] = 0.0
        out_info[n, 2] = 0.0
        npos = 0
        for i in range(4):
            if force[n, i] > 0.0:
                npos += 1
        if npos < 3:
            continue
        # 1) traction capacity
        state = np.zeros(4)
        contact = np.empty((4, 6))
        info = np.zeros(3)
        total = force[n, 0] + force[n, 1] + force[n, 2] + force[n, 3]
        mx0 = 0.0
        my0 = 0.0
        for i in range(4):
            # moment of pure forward sliding, F_i x_i, x_i = (-p_y, p_x)
            mx0 -= force[n, i] * SIDE_SIGN_Y_T[i] * np.cos(beta[i])
            my0 += force[n, i] * SIDE_SIGN_X_T[i] * np.sin(beta[i])
        brake = braking[n]
        if np.hypot(mx0, my0) <= brake:
            capacity = total
            saturated = -(force[n, 2] + force[n, 3])
            cap_residual = 0.0
            cap_ok = True
        else:
            ex, ey = rolling_axis(beta, force[n])
            _, wx0, wy0 = point_traction_capacity(beta, force[n], brake, ex, ey)
            state[0] = 1.0
            state[1] = wx0
            state[2] = wy0
            state[3] = 0.0
            solve_one(beta, force[n], a, b, sigma_scale, curved, rd, hoff, free_spin, tol,
                       max_iter, cin, sin_, win, xo, wo, tr, wr, state, contact, info,
                       1, 0.0, brake, 0.0, True)
            capacity = brake * np.hypot(state[1], state[2])
            for i in range(4):
                capacity += contact[i, 5]
            saturated = contact[2, 2] + contact[3, 2]
            cap_residual = info[0]
            cap_ok = info[2] > 0.5
        out_load[n, 0] = capacity
        out_load[n, 1] = saturated
        out_load[n, 2] = cap_residual
        load_p = push[n]
        stall = stall_moment(beta, force[n])
        out_load[n, 6] = stall
        if (cap_ok and abs(load_p) >= capacity) or brake >= stall:
            out_load[n, 5] = 1.0 if cap_ok and abs(load_p) >= capacity else 2.0
            out_info[n, 0] = cap_residual
            out_info[n, 2] = 1.0 if cap_ok else 0.0
            continue
        out_load[n, 5] = 0.0
        # 2) the loaded equilibrium
        state[:] = 0.0
        if load_p == 0.0 and brake == 0.0:
            # the unloaded problem: solved as in full_kernel, so the fields are its bit for bit
            smooth_solve(beta, force[n], a, b, sigma_scale, curved, rd, hoff, free_spin, tol,
                         max_iter, cin, sin_, win, xo, wo, tr, wr, table, state, contact, info)
        else:
            solve_one(beta, force[n], a, b, sigma_scale, curved, rd, hoff, free_spin, tol,
                      max_iter, cin, sin_, win, xo, wo, tr, wr, state, contact, info,
                      0, load_p, brake, 1.0, False)
        for k in range(4):
            out_state[n, k] = state[k]
            for m in range(6):
                out_contact[n, k, m] = contact[k, m]
        out_info[n, 0] = info[0]
        out_info[n, 1] = info[1]
        out_info[n, 2] = info[2]
        dp, db = _load_sensitivities(beta, force[n], a, b, sigma_scale, curved, rd, hoff,
                                     free_spin, load_p, brake, cin, sin_, win, xo, wo, tr, wr,
                                     state)
        out_load[n, 3] = dp
        out_load[n, 4] = db
