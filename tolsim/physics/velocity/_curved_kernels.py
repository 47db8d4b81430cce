"""Numba kernels of the curved contact surface: the slip's zero, the zero-spin rules."""

import numpy as np

from tolsim._jit import jit


@jit
def curved_pole(vrel, w, om, omz, a, b, rd, h):
    """Zero of the slip on the curved surface, normalised (x0/a, z0/b); (0, 0) if none."""
    # u_z(x) = vrel - (h + S) w - x om = 0, S = sqrt(rd^2 - x^2); squared: quadratic in x.
    k = vrel - h * w
    aa = om * om + w * w
    best = 0.0
    found = False
    if aa > 0.0:
        disc = w * w * (aa * rd * rd - k * k)
        if disc >= 0.0:
            sq = np.sqrt(disc)
            for sgn in (-1.0, 1.0):
                x = (k * om + sgn * sq) / aa
                if abs(x) < rd and (k - x * om) * w >= 0.0:
                    if (not found) or abs(x) < abs(best):
                        best = x
                        found = True
    if not found:
        return 0.0, 0.0, False
    s = np.sqrt(rd * rd - best * best)
    den = s * om - best * w
    z = 0.0
    if den != 0.0:
        z = -omz * ((h + s) * s + best * best) / den
    return best / a, z / b, True


#: Half-distance x_0 / a of the two zero lines below which they are taken as one (the stuck
#: contact): the polar rule about the pole, split at the line (``ball_loads_kernel``).
STUCK_CUT = 0.0
#: Spin over rolling below which the curved contact is integrated by the zero-spin product
#: rule (:func:`curved_zero_spin`): round-off of a stuck contact's omega_i = Omega . y_i = 0.
ZERO_SPIN = 1e-12


@jit(inline="always")
def curved_point(x, z, wgt, vrel, wr_, om, wz, rd, h, xx, xy, pxi, pyi, sig0, acc):
    """Add one node of the curved contact at (x, z) [R_B] with weight ``wgt`` to ``acc`` =
    (f_x, f_y, f_z, M_x, M_y, M_z, D) (R = v = mu = 1)."""
    s = np.sqrt(rd * rd - x * x)
    rad = h + s
    uz = vrel - rad * wr_ - x * om
    ut = (wz * (rad * s + x * x) + z * (s * om - x * wr_)) / rd
    un = np.hypot(ut, uz)
    if un == 0.0:
        return
    # tangent t = (s x_i - x p_i)/rd; traction -sig0 (ut t + uz z)/|u|
    tx = (s * xx - x * pxi) / rd
    ty = (s * xy - x * pyi) / rd
    q = -sig0 * wgt / un
    dfx = q * ut * tx
    dfy = q * ut * ty
    dfz = q * uz
    rx = rad * pxi + x * xx
    ry = rad * pyi + x * xy
    acc[0] += dfx
    acc[1] += dfy
    acc[2] += dfz
    acc[6] += sig0 * wgt * un
    acc[3] += ry * dfz - z * dfy
    acc[4] += z * dfx - rx * dfz
    acc[5] += rx * dfy - ry * dfx


@jit(inline="always")
def zero_spin_cut(vrel, wr_, a, rd, h):
    """x_0 / a of the zero lines u_z(+-x_0) = 0 of a contact without spin; 2 (outside) if none."""
    if wr_ != 0.0:
        big = (vrel - h * wr_) / wr_
        if 0.0 <= big <= rd * (1.0 + 1e-12):  # round-off of a stuck contact's double root
            return np.sqrt(max(rd * rd - big * big, 0.0)) / a
    return 2.0


@jit
def curved_zero_spin(vrel, wr_, om, wz, cut, a, b, rd, h, xx, xy, pxi, pyi, sig0, xo, wo,
                      acc):
    """The curved contact without spin (|omega_i|, |omega_z| <= ``ZERO_SPIN`` |roll|), by a
    product rule (the slip itself is evaluated with the given om, wz).

    The slip u_z(x) = vrel - (h + sqrt(rd^2 - x^2)) wr_ depends on x alone, and
    u_t = -z x wr_ / rd, so the slip vanishes on the lines u_z(x) = 0, x = +-x_0,
    x_0 = sqrt(rd^2 - S^2), S = (vrel - h wr_) / wr_ (``cut`` = x_0 / a), and the direction
    of u_z jumps across them. A polar rule about one point of them converges at first
    order in the angular nodes. Here x / a is split at
    -x_0 / a, 0 and x_0 / a and integrated by Gauss-Legendre on each piece (``xo``, ``wo``);
    across the ellipse, z / b = c sin(theta), c = sqrt(1 - (x/a)^2), which turns the Hertz
    weight sqrt(c^2 - (z/b)^2) d(z/b) into c^2 cos^2(theta) d(theta), Gauss-Legendre in theta
    on (-pi/2, pi/2). Each piece is smooth, so the rule converges exponentially.
    """
    edges = np.empty(5)
    edges[0] = -1.0
    count = 1
    for e in (-cut, 0.0, cut):
        if -1.0 < e < 1.0 and e > edges[count - 1]:
            edges[count] = e
            count += 1
    edges[count] = 1.0
    count += 1
    for p in range(count - 1):
        lo, hi = edges[p], edges[p + 1]
        half = 0.5 * (hi - lo)
        mid = 0.5 * (hi + lo)
        for j in range(xo.shape[0]):
            xn = mid + half * xo[j]
            c2 = 1.0 - xn * xn
            if c2 <= 0.0:
                continue
            c = np.sqrt(c2)
            for k in range(xo.shape[0]):
                th = 0.5 * np.pi * xo[k]
                ct = np.cos(th)
                wgt = half * wo[j] * 0.5 * np.pi * wo[k] * c2 * ct * ct
                curved_point(a * xn, b * c * np.sin(th), wgt, vrel, wr_, om, wz, rd, h, xx,
                              xy, pxi, pyi, sig0, acc)
