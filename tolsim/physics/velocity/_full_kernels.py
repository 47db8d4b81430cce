"""Numba kernels of the full friction model: contact integrals, ball loads, the Newton solve."""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics.velocity._curved_kernels import (
    STUCK_CUT,
    ZERO_SPIN,
    curved_point,
    curved_pole,
    curved_zero_spin,
    zero_spin_cut,
)

#: |pole|/a beyond which a contact is treated as pure sliding (uniform slip direction).
SLIDING_POLE = 1e7
#: Relative step of the central-difference Jacobian (unknowns scaled by v and v/R).
FD_STEP = 1e-6
#: A Newton state (v_B / v and Omega R / v, of order 1 for a rolling ball: 1/2 and sqrt(2)) at
#: or beyond this magnitude, or not finite, has diverged: not converged, whatever the residual
#: there (:func:`solve_one`).
DIVERGED_STATE = 1e6


# --------------------------------------------------------------------------------------------
# Kernels: typed loops, no checks.
# --------------------------------------------------------------------------------------------
@jit(inline="always")
def _ray_moments(beta, disc, inside):
    """Closed-form radial integrals along one ray in the unit disc.

    For a ray u = P + r e from the pole P, with beta = P . e and disc = beta^2 + 1 - |P|^2
    (> 0), 1 - |u|^2 = (r_2 - r)(r - r_1). Returns I_k = int sqrt(1 - |u|^2) r^k dr over the
    part of the ray inside the disc with r >= 0, for k = 1, 2 (r = m + h s,
    int sqrt(1 - s^2) s^j ds from s0 to 1 in closed form).
    """
    h = np.sqrt(disc)
    m = -beta
    if inside:
        s0 = beta / h if h > 0.0 else 1.0
        s0 = min(1.0, max(-1.0, s0))
        rt = np.sqrt(max(0.0, 1.0 - s0 * s0))
        asn = np.arcsin(s0)
        j0 = 0.5 * (0.5 * np.pi - s0 * rt - asn)
        j1 = rt * rt * rt / 3.0
        j2 = 0.125 * (0.5 * np.pi - s0 * (2.0 * s0 * s0 - 1.0) * rt - asn)
    else:
        j0 = 0.5 * np.pi
        j1 = 0.0
        j2 = 0.125 * np.pi
    h2 = h * h
    i1 = h2 * (m * j0 + h * j1)
    i2 = h2 * (m * m * j0 + 2.0 * m * h * j1 + h2 * j2)
    return i1, i2


@jit(leaf=True)
def planar_contact_integrals(pt, ps, a, b, cin, sin_, win, xo, wo, out):
    """Friction integrals of one planar contact for a pole at (x, z) = (pt a, ps b).

    Writes S = (S_x, S_z, S_n, S_d) into ``out`` such that, with omega_i the spin and
    sigma_0 = 3F/(2 pi a b), the friction force on the ball along x_i and z_i and its moment
    about the contact normal y_i are mu sigma_0 a b sgn(omega_i) (S_x, S_z, S_n) (Eqs. 12-13
    without the small-offset assumption; S_n [m], S_x and S_z [-]), and the dissipated power
    int mu sigma |slip| dA is mu sigma_0 a b |omega_i| S_d (S_d [m]).
    """
    pp = pt * pt + ps * ps
    sx = 0.0
    sz = 0.0
    sn = 0.0
    sd = 0.0
    c = pt * a
    d = ps * b
    if pp <= 1.0:
        for j in range(cin.shape[0]):
            e1 = cin[j]
            e2 = sin_[j]
            beta = pt * e1 + ps * e2
            disc = beta * beta + 1.0 - pp
            i1, i2 = _ray_moments(beta, disc, True)
            ll = np.sqrt(b * b * e2 * e2 + a * a * e1 * e1)
            w = win[j]
            sx -= w * b * e2 / ll * i1
            sz += w * a * e1 / ll * i1
            sn -= w * ((d * b * e2 + c * a * e1) * i1 / ll + ll * i2)
            sd += w * ll * i2
    else:
        rp = np.sqrt(pp)
        half = np.arcsin(1.0 / rp)
        base = np.arctan2(ps, pt) + np.pi
        for j in range(xo.shape[0]):
            ang = half * xo[j]
            phi = base + ang
            e1 = np.cos(phi)
            e2 = np.sin(phi)
            sa = rp * np.sin(ang)
            disc = 1.0 - sa * sa
            if disc <= 0.0:
                continue
            beta = -rp * np.cos(ang)
            i1, i2 = _ray_moments(beta, disc, False)
            ll = np.sqrt(b * b * e2 * e2 + a * a * e1 * e1)
            w = half * wo[j]
            sx -= w * b * e2 / ll * i1
            sz += w * a * e1 / ll * i1
            sn -= w * ((d * b * e2 + c * a * e1) * i1 / ll + ll * i2)
            sd += w * ll * i2
    out[0] = sx
    out[1] = sz
    out[2] = sn
    out[3] = sd


@pjit
def contact_friction_kernel(offset_ratio, lateral_ratio, semi_major, semi_minor, cin, sin_, win,
                            xo, wo, out):
    """Normalised friction of planar contacts: out[k] = (f_x, f_z, M_O) / (sgn(omega) mu F).

    M_O is the resisting spin moment of Eq. (13) [m] (positive at c/a = 0, Eq. 14).
    """
    scale = 1.5 / np.pi  # sigma_0 a b / F
    for k in prange(offset_ratio.shape[0]):
        s3 = np.empty(4)
        pt = offset_ratio[k]
        ps = lateral_ratio[k]
        if np.hypot(pt, ps) > SLIDING_POLE:
            # pure sliding: slip along (-d, c) direction of the centre, friction opposes it
            # (Eq. 15)
            a = semi_major[k]
            b = semi_minor[k]
            ux = -ps * b
            uz = pt * a
            un = np.hypot(ux, uz)
            out[k, 0] = -ux / un
            out[k, 1] = -uz / un
            out[k, 2] = 0.0
            continue
        planar_contact_integrals(pt, ps, semi_major[k], semi_minor[k], cin, sin_, win, xo, wo,
                                 s3)
        out[k, 0] = scale * s3[0]
        out[k, 1] = scale * s3[1]
        out[k, 2] = -scale * s3[2]


@jit
def ball_loads_kernel(state, px, py, vgroove, force, semi_major, semi_minor, sigma_scale,
                      curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr, loads, contact):
    """Friction loads on one ball (R = 1, v = 1 units; mu = 1).

    state = (v_B, omega_x, omega_y, omega_z). Writes loads = (F_z, M_x, M_y, M_z, D), D the
    dissipated power (the equilibrium is the minimum of D, a convex function), and per
    contact ``contact[i] = (c_i/a_i, d_i/b_i, F_z,i, omega_i, roll_i)``; when ``contact`` has
    a sixth column, ``contact[i, 5]`` = D_i, the power dissipated in contact i.
    """
    with_power = contact.shape[1] > 5
    vb = state[0]
    wx = state[1]
    wy = state[2]
    wz = state[3]
    fz_tot = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    power = 0.0
    s3 = np.empty(4)
    acc = np.empty(7)
    for i in range(4):
        f = force[i]
        a = semi_major[i]
        b = semi_minor[i]
        yx = -px[i]
        yy = -py[i]
        xx = yy  # x_i = y_i x z = (y_y, -y_x)
        xy = -yx
        om = wx * yx + wy * yy  # spin about the inward normal
        wr_ = wx * xx + wy * xy  # rolling component about x_i
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
        if not curved:
            # pole (c, d) of the rotation field; pure sliding if it is (nearly) at infinity
            if abs(om) * SLIDING_POLE * a > np.hypot(u0, wz):
                pt = u0 / om / a
                ps = -wz / om / b
                planar_contact_integrals(pt, ps, a, b, cin, sin_, win, xo, wo, s3)
                scale = sigma_scale * f * (1.0 if om > 0.0 else -1.0)
                fx = scale * s3[0]
                fz = scale * s3[1]
                mn = scale * s3[2]
                power += sigma_scale * f * abs(om) * s3[3]
            else:
                pt = np.inf
                ps = 0.0
                slip = np.hypot(u0, wz)
                if slip > 0.0:
                    fx = -f * wz / slip
                    fz = -f * u0 / slip
                else:
                    fx = 0.0
                    fz = 0.0
                mn = 0.0
                power += f * slip
            fz_tot += fz
            mx += -fz * xx + mn * yx
            my += -fz * xy + mn * yy
            mz += fx
            contact[i, 0] = pt
            contact[i, 1] = ps
            contact[i, 2] = fz
            if with_power:
                contact[i, 5] = power - power_before
        else:
            pt, ps, ok = curved_pole(vb - vgroove[i], wr_, om, wz, a, b, rd, hoff[i])
            pp = pt * pt + ps * ps
            sig0 = sigma_scale * f  # mu sigma_0 a b, with mu = 1
            for k in range(6):
                acc[k] = 0.0
            acc[6] = power  # the running total, in the same order as a scalar
            # zero spin (to round-off): the slip's zeros are lines, not a pole
            zero_spin = max(abs(om), abs(wz)) <= ZERO_SPIN * abs(wr_)
            cut = zero_spin_cut(vb - vgroove[i], wr_, a, rd, hoff[i]) if zero_spin else 2.0
            stuck = zero_spin and cut <= STUCK_CUT and pp <= 1.0
            if stuck:
                nang = 2 * xo.shape[0]
            elif zero_spin:
                nang = 0
            elif pp <= 1.0:
                nang = cin.shape[0]
            else:
                nang = xo.shape[0]
                rp = np.sqrt(pp)
                half = np.arcsin(1.0 / rp)
                base = np.arctan2(ps, pt) + np.pi
            for j in range(nang):
                if stuck:  # Gauss-Legendre on each side of the zero line through the pole
                    n_half = xo.shape[0]
                    ang = 0.5 * np.pi * xo[j % n_half] + (0.0 if j < n_half else np.pi)
                    e1 = np.cos(ang)
                    e2 = np.sin(ang)
                    beta = pt * e1 + ps * e2
                    disc = beta * beta + 1.0 - pp
                    wang = 0.5 * np.pi * wo[j % n_half]
                    s0 = beta / np.sqrt(disc) if disc > 0.0 else 1.0
                    s0 = min(1.0, max(-1.0, s0))
                elif pp <= 1.0:
                    e1 = cin[j]
                    e2 = sin_[j]
                    beta = pt * e1 + ps * e2
                    disc = beta * beta + 1.0 - pp
                    wang = win[j]
                    s0 = beta / np.sqrt(disc) if disc > 0.0 else 1.0
                    s0 = min(1.0, max(-1.0, s0))
                else:
                    ang = half * xo[j]
                    e1 = np.cos(base + ang)
                    e2 = np.sin(base + ang)
                    sa = rp * np.sin(ang)
                    disc = 1.0 - sa * sa
                    beta = -rp * np.cos(ang)
                    wang = half * wo[j]
                    s0 = -1.0
                if disc <= 0.0:
                    continue
                hh = np.sqrt(disc)
                m = -beta
                th0 = np.arccos(s0)
                for k in range(tr.shape[0]):
                    th = th0 * tr[k]
                    st = np.sin(th)
                    r = m + hh * np.cos(th)
                    wgt = wang * th0 * wr[k] * disc * st * st * r  # sqrt(1-|u|^2) r dr dphi
                    curved_point(a * (pt + r * e1), b * (ps + r * e2), wgt, vb - vgroove[i],
                                  wr_, om, wz, rd, hoff[i], xx, xy, px[i], py[i], sig0, acc)
            if zero_spin and not stuck:
                curved_zero_spin(vb - vgroove[i], wr_, om, wz, cut, a, b, rd, hoff[i], xx, xy,
                                  px[i], py[i], sig0, xo, wo, acc)
            ffz = acc[2]
            power = acc[6]
            fz_tot += ffz
            mx += acc[3]
            my += acc[4]
            mz += acc[5]
            contact[i, 0] = pt if ok else np.nan
            contact[i, 1] = ps if ok else np.nan
            contact[i, 2] = ffz
            if with_power:
                contact[i, 5] = power - power_before
    loads[0] = fz_tot
    loads[1] = mx
    loads[2] = my
    loads[3] = mz
    loads[4] = power


@jit(inline="always")
def solve_small(jac, rhs, n, out):
    """Gaussian elimination with partial pivoting of an n x n system (n <= 4); False if
    singular."""
    a = jac.copy()
    b = rhs.copy()
    for k in range(n):
        piv = k
        for r in range(k + 1, n):
            if abs(a[r, k]) > abs(a[piv, k]):
                piv = r
        if a[piv, k] == 0.0 or not np.isfinite(a[piv, k]):
            return False
        if piv != k:
            for c in range(n):
                tmp = a[k, c]
                a[k, c] = a[piv, c]
                a[piv, c] = tmp
            tmp = b[k]
            b[k] = b[piv]
            b[piv] = tmp
        for r in range(k + 1, n):
            fac = a[r, k] / a[k, k]
            for c in range(k, n):
                a[r, c] -= fac * a[k, c]
            b[r] -= fac * b[k]
    for k in range(n - 1, -1, -1):
        acc = b[k]
        for c in range(k + 1, n):
            acc -= a[k, c] * out[c]
        out[k] = acc / a[k, k]
    return True


@jit
def residual(state, nunk, first, push, braking, px, py, vgroove, force, semi_major, semi_minor,
              sigma_scale, curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr, loads, contact, res):
    """Normalised equilibrium residual (F_z, M_x, M_y[, M_z]) / sum F; returns max |res|.

    Rows ``first`` .. ``first + nunk - 1`` of the loads (``first`` = 1 when v_B is fixed).
    External loads (tolsim.physics.velocity.ball_loads, R = 1, v = 1, mu = 1 units): the push
    ``push`` = P / mu adds to F_z, the braking ``braking`` = (mu_bb / mu)(Q_back + Q_front)
    adds -braking Omega_perp / |Omega_perp| to (M_x, M_y). loads[4] becomes the potential
    Phi = D + braking |Omega_perp| - push v_B, whose gradient is -loads[:4] (the solver's
    merit); both are skipped when zero, so the unloaded residual is unchanged bit for bit.
    """
    ball_loads_kernel(state, px, py, vgroove, force, semi_major, semi_minor, sigma_scale, curved,
                      rd, hoff, cin, sin_, win, xo, wo, tr, wr, loads, contact)
    if push != 0.0:
        loads[0] += push
        loads[4] -= push * state[0]
    if braking > 0.0:
        spin_perp = np.hypot(state[1], state[2])
        if spin_perp > 0.0:
            loads[1] -= braking * state[1] / spin_perp
            loads[2] -= braking * state[2] / spin_perp
        loads[4] += braking * spin_perp
    total = force[0] + force[1] + force[2] + force[3]
    worst = 0.0
    for k in range(nunk):
        res[k] = loads[first + k] / total
        worst = max(worst, abs(res[k]))
    if not np.isfinite(worst):
        worst = np.inf
    return worst


@jit
def rolling_start(beta, force, px, py, vgroove, state):
    """Pure rolling at the contact centres, v_B + w_x p_y - w_y p_x = V_i (least squares over
    the contacts that carry load), written into ``state``: the Newton solvers' start."""
    ata = np.zeros((3, 3))
    atb = np.zeros(3)
    for i in range(4):
        if force[i] > 0.0:
            row = (1.0, py[i], -px[i])
            for r in range(3):
                atb[r] += row[r] * vgroove[i]
                for c in range(3):
                    ata[r, c] += row[r] * row[c]
    x0 = np.zeros(3)
    state[:] = 0.0
    if solve_small(ata, atb, 3, x0):
        state[0] = x0[0]
        state[1] = x0[1]
        state[2] = x0[2]
    else:
        state[0] = 0.5
        state[1] = 0.5 / np.cos(beta[0])


@jit
def solve_one(beta, force, semi_major, semi_minor, sigma_scale, curved, rd, hoff, free_spin,
               tol, max_iter, cin, sin_, win, xo, wo, tr, wr, state, contact, info,
               first=0, push=0.0, braking=0.0, groove_speed=1.0, given_start=False):
    """Damped Newton solve of the equilibrium of one ball (R = 1, v = 1, mu = 1).

    Writes the solution into ``state`` (v_B, omega_x, omega_y, omega_z), the per-contact
    quantities into ``contact`` and (residual, iterations, converged) into ``info``.

    Options for external loads (:func:`residual`): ``push`` = P / mu and ``braking`` =
    (mu_bb / mu)(Q_back + Q_front). ``first`` = 1 fixes v_B = state[0] and solves the moment
    rows for Omega only; ``groove_speed`` is the top groove's velocity (0: both grooves at
    rest, the sliding state of the traction capacity); ``given_start`` starts from ``state``
    instead of pure rolling. The defaults are the unloaded problem.
    """
    px = np.empty(4)
    py = np.empty(4)
    vgroove = np.array([0.0, 0.0, groove_speed, groove_speed])
    sxs = (-1.0, 1.0, 1.0, -1.0)
    sys_ = (-1.0, -1.0, 1.0, 1.0)
    for i in range(4):
        px[i] = sxs[i] * np.sin(beta[i])
        py[i] = sys_[i] * np.cos(beta[i])
    nunk = (4 if free_spin else 3) - first
    total = force[0] + force[1] + force[2] + force[3]
    if not given_start:
        rolling_start(beta, force, px, py, vgroove, state)
    loads = np.empty(5)
    res = np.empty(4)
    res_new = np.empty(4)
    trial = np.empty(4)
    jac = np.empty((nunk, nunk))
    step = np.zeros(4)
    rp = np.empty(4)
    rm = np.empty(4)
    work = np.empty((4, 5))
    worst = residual(state, nunk, first, push, braking, px, py, vgroove, force, semi_major,
                      semi_minor, sigma_scale, curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr,
                      loads, contact, res)
    dis = loads[4]
    it = 0
    converged = worst <= tol
    while not converged and it < max_iter:
        it += 1
        # central-difference Jacobian
        for c in range(nunk):
            k = first + c
            hstep = FD_STEP * max(1.0, abs(state[k]))
            trial[:] = state
            trial[k] = state[k] + hstep
            residual(trial, nunk, first, push, braking, px, py, vgroove, force, semi_major,
                      semi_minor, sigma_scale, curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr,
                      loads, work, rp)
            trial[k] = state[k] - hstep
            residual(trial, nunk, first, push, braking, px, py, vgroove, force, semi_major,
                      semi_minor, sigma_scale, curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr,
                      loads, work, rm)
            for r in range(nunk):
                jac[r, c] = (rp[r] - rm[r]) / (2.0 * hstep)
        neg = np.empty(nunk)
        for r in range(nunk):
            neg[r] = -res[r]
        merit = 0.0
        for r in range(nunk):
            merit += res[r] * res[r]
        accepted = False
        new = worst
        if first > 0:
            trial[0] = state[0]
        # 1) Newton step with backtracking on the sum of squares
        if solve_small(jac, neg, nunk, step):
            t = 1.0
            for _ls in range(8):
                for c in range(nunk):
                    trial[first + c] = state[first + c] + t * step[c]
                if first + nunk < 4:
                    trial[3] = 0.0
                new = residual(trial, nunk, first, push, braking, px, py, vgroove, force,
                                semi_major, semi_minor, sigma_scale, curved, rd, hoff, cin,
                                sin_, win, xo, wo, tr, wr, loads, work, res_new)
                msum = 0.0
                slope = 0.0  # directional derivative of D: gradient = -loads
                for r in range(nunk):
                    msum += res_new[r] * res_new[r]
                    slope -= res[r] * step[r] * total
                if (msum < (1.0 - 1e-4 * t) * merit or new <= tol
                        or loads[4] <= dis + 1e-4 * t * slope):
                    accepted = True
                    break
                t *= 0.5
        # 2) Levenberg-Marquardt steps (near two-point contact the Jacobian is nearly singular:
        #    the sliding contacts' forces saturate at mu F)
        if not accepted:
            jtj = np.empty((nunk, nunk))
            jtr = np.empty(nunk)
            big = 0.0
            for c in range(nunk):
                jtr[c] = 0.0
                for r in range(nunk):
                    jtr[c] -= jac[r, c] * res[r]
                for d in range(nunk):
                    acc = 0.0
                    for r in range(nunk):
                        acc += jac[r, c] * jac[r, d]
                    jtj[c, d] = acc
                big = max(big, jtj[c, c])
            lam = 1e-6
            damped = np.empty((nunk, nunk))
            for _lm in range(30):
                for c in range(nunk):
                    for d in range(nunk):
                        damped[c, d] = jtj[c, d]
                    damped[c, c] += lam * (jtj[c, c] + 1e-12 * big)
                if solve_small(damped, jtr, nunk, step):
                    for c in range(nunk):
                        trial[first + c] = state[first + c] + step[c]
                    if first + nunk < 4:
                        trial[3] = 0.0
                    new = residual(trial, nunk, first, push, braking, px, py, vgroove, force,
                                    semi_major, semi_minor, sigma_scale, curved, rd, hoff, cin,
                                    sin_, win, xo, wo, tr, wr, loads, work, res_new)
                    msum = 0.0
                    slope = 0.0
                    for r in range(nunk):
                        msum += res_new[r] * res_new[r]
                        slope -= res[r] * step[r] * total
                    if msum < merit or new <= tol or loads[4] <= dis + 1e-4 * slope:
                        accepted = True
                        break
                lam *= 10.0
        if not accepted:
            break
        state[:] = trial
        for r in range(nunk):
            res[r] = res_new[r]
        worst = new
        dis = loads[4]
        converged = worst <= tol
    # final per-contact quantities at the accepted state
    worst = residual(state, nunk, first, push, braking, px, py, vgroove, force, semi_major,
                      semi_minor, sigma_scale, curved, rd, hoff, cin, sin_, win, xo, wo, tr, wr,
                      loads, contact, res)
    info[0] = worst
    info[1] = it
    # a state that ran off to inf (or 1e300) is no solution, whatever its residual says: with
    # micronewton forces (a carriage without preload or load) the Newton diverged in 50
    # iterations and its residual at the infinite state read 0 (session 30)
    finite = True
    for k in range(4):
        if not abs(state[k]) < DIVERGED_STATE:
            finite = False
    info[2] = 1.0 if worst <= tol and finite else 0.0


@jit(inline="always")
def contact_ellipses(dbeta, force, nominal_angle, semi_major_coefficient,
                     semi_minor_coefficient, rd, beta, a, b, hoff):
    """A ball's four loaded contact angles [rad], Hertz semi-axes a, b and the curved surface's
    arc-centre offset h (lengths in units of R_B), written into ``beta``, ``a``, ``b``,
    ``hoff`` (4,): the setup shared by :func:`full_kernel`, :func:`full_loaded_kernel` and the
    regime kernel."""
    for i in range(4):
        beta[i] = nominal_angle + dbeta[i]
        f13 = np.cbrt(force[i])
        a[i] = semi_major_coefficient * f13
        b[i] = semi_minor_coefficient * f13
        # curved surface: centre of the deformed arc at h p_i (edges on the ball)
        hoff[i] = np.sqrt(max(0.0, 1.0 - a[i] * a[i])) - np.sqrt(max(0.0, rd * rd
                                                                      - a[i] * a[i]))
