"""Numba kernels of the analytical models: Eq. (24), the creep model, the point-contact model."""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics._fastmath import (
    SMALL_ANGLE,
    cbrt_halley,
    cbrt_in_range,
    cbrt_nonnegative,
    cbrt_one,
    sin_cos_near,
    sin_cos_series,
)
from tolsim.physics.velocity.ball_loads import point_traction_capacity, rolling_axis, stall_moment


# --------------------------------------------------------------------------------------------
# Kernels: typed loops, no checks, outputs written into preallocated arrays.
# --------------------------------------------------------------------------------------------
@pjit
def _diagonal_force_ratio_squared(force, out):
    """(min(F_1, F_2) / max(F_1, F_2))^2 per ball (pass 1 of Eq. 24)."""
    for n in prange(force.shape[0]):
        f1 = force[n, 0] + force[n, 2]
        f2 = force[n, 1] + force[n, 3]
        q = min(f1, f2) / max(f1, f2)
        out[n] = q * q


@pjit
def _eq24_finish(dbeta, force, ratio, nominal_angle, min_ratio, max_angle, max_asymmetry,
                 max_eps, out_eps, out_valid):
    """Eq. (24) given r = (F_small/F_large)^(2/3) per ball (pass 3), and its validity."""
    half_tan = 0.5 * np.tan(nominal_angle)
    for n in prange(dbeta.shape[0]):
        f1 = force[n, 0] + force[n, 2]
        f2 = force[n, 1] + force[n, 3]
        d1 = dbeta[n, 2] - dbeta[n, 0]  # -dbeta_BL + dbeta_TR, weighted by F_1^(2/3)
        d2 = dbeta[n, 3] - dbeta[n, 1]  # -dbeta_BR + dbeta_TL, weighted by F_2^(2/3)
        r = ratio[n]
        w1 = 1.0 if f1 >= f2 else r
        w2 = r if f1 >= f2 else 1.0
        num = half_tan * (w1 * d1 + w2 * d2)
        out_eps[n] = num / (1.0 + r)
        smallest = min(min(force[n, 0], force[n, 1]), min(force[n, 2], force[n, 3]))
        largest_angle = max(max(abs(dbeta[n, 0]), abs(dbeta[n, 1])),
                            max(abs(dbeta[n, 2]), abs(dbeta[n, 3])))
        q = min(f1, f2) / max(f1, f2)
        # Written so that the loop stays vectorised (this pass measured 2.3x faster than
        # testing |eps| on the quotient or folding the tests into one max): |eps| <= max_eps
        # as |num| <= max_eps (1 + r), and the pairing asymmetry |F_BL - F_TR| / F_1 <=
        # max_asymmetry (likewise BR, TL) without a division.
        u1 = force[n, 0] - force[n, 2]
        u2 = force[n, 1] - force[n, 3]
        t1 = max_asymmetry * f1
        t2 = max_asymmetry * f2
        out_valid[n] = ((smallest > 0.0) & (q >= min_ratio) & (largest_angle <= max_angle)
                        & (abs(u1) <= t1) & (abs(u2) <= t2) & (abs(num) <= max_eps * (1.0 + r)))


def eq24_kernel(dbeta, force, nominal_angle, min_ratio, max_angle, max_asymmetry, max_eps,
                out_eps, out_valid):
    """Eq. (24) with F_1 = (F_BL + F_TR)/2 and F_2 = (F_BR + F_TL)/2; unchecked fast path.

    Written with the ratio r = (F_small/F_large)^(2/3): one cube root per ball, no overflow,
    evaluated for all balls at once with the vectorised cube root (three passes).
    ``dbeta`` and ``force`` are C-contiguous (n, 4) float64; ``out_eps`` (n,) float64 doubles
    as scratch. ``out_valid``: all forces > 0, diagonal force ratio >= ``min_ratio``,
    |dbeta_i| <= ``max_angle``, pairing asymmetry <= ``max_asymmetry``, |eps| <= ``max_eps``
    (the module constants: ``MIN_DIAGONAL_FORCE_RATIO``, ``MAX_ANGLE_DEVIATION``,
    ``MAX_PAIRING_ASYMMETRY``, ``MAX_EQ24_VELOCITY_DEVIATION``).
    """
    _diagonal_force_ratio_squared(force, out_eps)
    ratio = cbrt_nonnegative(out_eps)
    _eq24_finish(dbeta, force, ratio, nominal_angle, min_ratio, max_angle, max_asymmetry,
                 max_eps, out_eps, out_valid)


@pjit
def count_bad_inputs(dbeta, force):
    """One parallel pass: counts of non-finite dbeta, non-finite force and negative force."""
    bad_angle = 0
    bad_force = 0
    negative = 0
    for n in prange(dbeta.shape[0]):
        for i in range(4):
            if not np.isfinite(dbeta[n, i]):
                bad_angle += 1
            if not np.isfinite(force[n, i]):
                bad_force += 1
            elif force[n, i] < 0.0:
                negative += 1
    return bad_angle, bad_force, negative


@jit(inline="always")
def det3(a11, a12, a13, a21, a22, a23, a31, a32, a33):
    return (
        a11 * (a22 * a33 - a23 * a32)
        - a12 * (a21 * a33 - a23 * a31)
        + a13 * (a21 * a32 - a22 * a31)
    )


@jit(inline="always")
def eq22_velocity_deviation(b_bl, b_br, b_tl):
    """Eq. (22): epsilon from the angles of the zero-velocity points (TR follows from (19))."""
    num = np.sin(b_bl + b_br)
    return 2.0 * num / (num + np.sin(b_bl + b_tl) + np.sin(b_br - b_tl)) - 1.0


def analytic_kernel(
    dbeta, force, nominal_angle, ball_radius, semi_major_coefficient, elliptic_e, k_f,
    max_ratio, max_angle, max_eps, out_eps, out_eps22, out_gamma, out_valid,
):
    """Solve Eqs. (17), (18) [ERRATA 8 sign], (21) for dgamma_i; unchecked fast path.

    ``dbeta``, ``force``: C-contiguous (n, 4) float64. ``out_eps22`` of length 0 skips
    Eq. (22), ``out_gamma`` with 0 rows skips storing dgamma (a study needs neither: then the
    balls are solved in tiles, :func:`analytic_tile`; else the cube roots F_i^(1/3) (for a_i)
    are taken for all balls at once with the vectorised cube root, then the per-ball solve
    runs: the same numbers). ``out_valid``: all forces > 0, |c_i/a_i| <= ``max_ratio`` and
    |dbeta_i + dgamma_i| <= ``max_angle`` at every contact, and |eps| <= ``max_eps`` (the
    module constants ``MAX_ZERO_VELOCITY_RATIO``, ``MAX_ANGLE_SUM``,
    ``MAX_VELOCITY_DEVIATION``).
    """
    if out_eps22.shape[0] == 0 and out_gamma.shape[0] == 0:
        _analytic_tiles(dbeta, force, nominal_angle, ball_radius, semi_major_coefficient,
                        elliptic_e, k_f, max_ratio, max_angle, max_eps, out_eps, out_valid)
        return
    force_cbrt = cbrt_nonnegative(force)
    _analytic_solve(dbeta, force, force_cbrt, nominal_angle, ball_radius,
                    semi_major_coefficient, elliptic_e, k_f, max_ratio, max_angle, max_eps,
                    out_eps, out_eps22, out_gamma, out_valid)


@jit(inline="always")
def spin_particular(s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1, a2, a3, d012,
                    elliptic_e, ball_radius):
    """The particular solution (u_0, u_1, u_2), u_3 = 0, of the force and moment rows of
    Eqs. (17), (18) (ERRATA 8: sum u_i x_i + sum m_i y_i = 0) by Cramer's rule, ``d012`` the
    determinant of their first three columns; the spin moments / (mu R) m_i = 3/8 F_i a_i
    E(e) / R, signed with sgn(omega) = (+,-,-,+); local x axes BL (c,-s), BR (c,s), TR (-c,s).
    """
    x0, y0 = c0, -s0
    x1, y1 = c1, s1
    x2, y2 = -c2, s2
    sc = 0.375 * elliptic_e / ball_radius
    m0 = sc * f0 * a0
    m1 = -sc * f1 * a1
    m2 = -sc * f2 * a2
    m3 = sc * f3 * a3
    r2 = -(m0 * s0 - m1 * s1 - m2 * s2 + m3 * s3)
    r3 = -(m0 * c0 + m1 * c1 - m2 * c2 - m3 * c3)
    p0 = det3(0.0, 1.0, 1.0, r2, x1, x2, r3, y1, y2) / d012
    p1 = det3(1.0, 0.0, 1.0, x0, r2, x2, y0, r3, y2) / d012
    p2 = det3(1.0, 1.0, 0.0, x0, x1, r2, y0, y1, r3) / d012
    return p0, p1, p2


@jit(inline="always")
def analytic_ball(d0, d1, d2, d3, s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, r0, r1, r2,
                  r3, half_tan, ball_radius, semi_major_coefficient, elliptic_e, k_f, max_ratio,
                  max_angle, max_eps):
    """The closed-form solve of Eqs. (17), (18), (21) and epsilon (23) of one ball.

    dbeta_i ``d0..d3`` [rad], sin and cos of beta_0 + dbeta_i ``s0, c0 .. s3, c3``, forces
    ``f0..f3`` [N] and their cube roots ``r0..r3``, in the order BL, BR, TR, TL. Returns
    (epsilon, dgamma_0..3, valid) (the criteria of :func:`analytic_kernel`). No branch: the
    loops over it vectorise.
    """
    # local x axes: BL (c,-s) BR (c,s) TR (-c,s) TL (-c,-s)
    x0, y0 = c0, -s0
    x1, y1 = c1, s1
    x2, y2 = -c2, s2
    x3, y3 = -c3, -s3
    # inward normals y_i: BL (s,c) BR (-s,c) TR (-s,-c) TL (s,-c)
    ok = min(min(f0, f1), min(f2, f3)) > 0.0
    a0 = semi_major_coefficient * r0
    a1 = semi_major_coefficient * r1
    a2 = semi_major_coefficient * r2
    a3 = semi_major_coefficient * r3
    # u_i = q_i dgamma_i = friction force / mu; q_i = k_f R F_i / a_i * g_i, g = (-,-,+,+)
    q0 = -k_f * ball_radius * f0 / a0
    q1 = -k_f * ball_radius * f1 / a1
    q2 = k_f * ball_radius * f2 / a2
    q3 = k_f * ball_radius * f3 / a3
    # Null vector of rows (1,1,1,1), (x_i), (y_i): n_j = (-1)^j det(without column j)
    d012 = det3(1.0, 1.0, 1.0, x0, x1, x2, y0, y1, y2)
    n0 = det3(1.0, 1.0, 1.0, x1, x2, x3, y1, y2, y3)
    n1 = -det3(1.0, 1.0, 1.0, x0, x2, x3, y0, y2, y3)
    n2 = det3(1.0, 1.0, 1.0, x0, x1, x3, y0, y1, y3)
    n3 = -d012
    p0, p1, p2 = spin_particular(s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1, a2,
                                 a3, d012, elliptic_e, ball_radius)
    # Eq. (21): g_BL - g_BR - g_TR + g_TL = -(db_BL + db_TL - db_BR - db_TR)
    rhs = -(d0 + d3 - d1 - d2)
    w0, w1, w2, w3 = 1.0 / q0, -1.0 / q1, -1.0 / q2, 1.0 / q3
    t = (rhs - (w0 * p0 + w1 * p1 + w2 * p2)) / (w0 * n0 + w1 * n1 + w2 * n2 + w3 * n3)
    g0 = (p0 + t * n0) / q0
    g1 = (p1 + t * n1) / q1
    g2 = (p2 + t * n2) / q2
    g3 = (t * n3) / q3
    eps = half_tan * (-d1 - g1 + d3 + g3)
    ok &= ball_radius * abs(g0) <= max_ratio * a0
    ok &= ball_radius * abs(g1) <= max_ratio * a1
    ok &= ball_radius * abs(g2) <= max_ratio * a2
    ok &= ball_radius * abs(g3) <= max_ratio * a3
    ok &= (abs(d0 + g0) <= max_angle) & (abs(d1 + g1) <= max_angle)
    ok &= (abs(d2 + g2) <= max_angle) & (abs(d3 + g3) <= max_angle)
    return eps, g0, g1, g2, g3, ok & (abs(eps) <= max_eps)


@pjit
def _analytic_solve(
    dbeta, force, force_cbrt, nominal_angle, ball_radius, semi_major_coefficient, elliptic_e,
    k_f, max_ratio, max_angle, max_eps, out_eps, out_eps22, out_gamma, out_valid,
):
    """Per-ball closed-form solve of Eqs. (17), (18), (21) (:func:`analytic_ball`); epsilon
    from (23) and (22)."""
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    with_eq22 = out_eps22.shape[0] > 0
    with_gamma = out_gamma.shape[0] > 0
    for n in prange(dbeta.shape[0]):
        s0, c0 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 0])
        s1, c1 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 1])
        s2, c2 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 2])
        s3, c3 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 3])
        eps, g0, g1, g2, g3, ok = analytic_ball(
            dbeta[n, 0], dbeta[n, 1], dbeta[n, 2], dbeta[n, 3], s0, c0, s1, c1, s2, c2, s3,
            c3, force[n, 0], force[n, 1], force[n, 2], force[n, 3], force_cbrt[n, 0],
            force_cbrt[n, 1], force_cbrt[n, 2], force_cbrt[n, 3], half_tan, ball_radius,
            semi_major_coefficient, elliptic_e, k_f, max_ratio, max_angle, max_eps)
        if with_gamma:
            out_gamma[n, 0] = g0
            out_gamma[n, 1] = g1
            out_gamma[n, 2] = g2
            out_gamma[n, 3] = g3
        out_eps[n] = eps
        if with_eq22:
            out_eps22[n] = eq22_velocity_deviation(nominal_angle + dbeta[n, 0] + g0,
                                                   nominal_angle + dbeta[n, 1] + g1,
                                                   nominal_angle + dbeta[n, 3] + g3)
        out_valid[n] = ok


#: Balls per tile of :func:`analytic_tile` (its scratch, (4, TILE) angles and forces, stays
#: in the L1 cache).
ANALYTIC_TILE = 256


@jit(inline="always")
def analytic_tile(dbeta, force, m, nominal_angle, ball_radius, semi_major_coefficient,
                  elliptic_e, k_f, max_ratio, max_angle, max_eps, out_eps, out_valid, at,
                  paired=False):
    """epsilon and validity of the m balls of a tile, written to ``out_eps[at + i]``,
    ``out_valid[at + i]`` (the numbers of :func:`_analytic_solve`, bit for bit).

    ``dbeta``, ``force`` (4, >= m): the tile's balls contact by contact (so that the loop
    vectorises). One branch-free loop with the series sin and cos
    (:func:`~tolsim.physics._fastmath.sin_cos_series`) and the Halley cube root
    (:func:`~tolsim.physics._fastmath.cbrt_halley`), then the tile's balls outside their
    ranges (|dbeta_i| > SMALL_ANGLE, F_i outside CBRT_RANGE, NaN) again with
    :func:`~tolsim.physics._fastmath.sin_cos_near` and
    :func:`~tolsim.physics._fastmath.cbrt_one`, which are the same functions inside them.
    """
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    odd = False
    for i in range(m):
        d0, d1, d2, d3 = dbeta[0, i], dbeta[1, i], dbeta[2, i], dbeta[3, i]
        f0, f1, f2, f3 = force[0, i], force[1, i], force[2, i], force[3, i]
        s0, c0 = sin_cos_series(sin_b0, cos_b0, d0)
        s1, c1 = sin_cos_series(sin_b0, cos_b0, d1)
        s2, c2 = sin_cos_series(sin_b0, cos_b0, d2)
        s3, c3 = sin_cos_series(sin_b0, cos_b0, d3)
        r0, r1 = cbrt_halley(f0), cbrt_halley(f1)
        r2 = r0 if paired else cbrt_halley(f2)
        r3 = r1 if paired else cbrt_halley(f3)
        eps, _, _, _, _, ok = analytic_ball(
            d0, d1, d2, d3, s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, r0, r1, r2, r3,
            half_tan, ball_radius, semi_major_coefficient, elliptic_e, k_f, max_ratio,
            max_angle, max_eps)
        out_eps[at + i] = eps
        out_valid[at + i] = ok
        odd |= _outside_series(d0, d1, d2, d3, f0, f1, f2, f3)
    if not odd:
        return
    for i in range(m):
        d0, d1, d2, d3 = dbeta[0, i], dbeta[1, i], dbeta[2, i], dbeta[3, i]
        f0, f1, f2, f3 = force[0, i], force[1, i], force[2, i], force[3, i]
        if not _outside_series(d0, d1, d2, d3, f0, f1, f2, f3):
            continue
        s0, c0 = sin_cos_near(sin_b0, cos_b0, nominal_angle, d0)
        s1, c1 = sin_cos_near(sin_b0, cos_b0, nominal_angle, d1)
        s2, c2 = sin_cos_near(sin_b0, cos_b0, nominal_angle, d2)
        s3, c3 = sin_cos_near(sin_b0, cos_b0, nominal_angle, d3)
        eps, _, _, _, _, ok = analytic_ball(
            d0, d1, d2, d3, s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, cbrt_one(f0),
            cbrt_one(f1), cbrt_one(f2), cbrt_one(f3), half_tan, ball_radius,
            semi_major_coefficient, elliptic_e, k_f, max_ratio, max_angle, max_eps)
        out_eps[at + i] = eps
        out_valid[at + i] = ok


@jit(inline="always")
def _outside_series(d0, d1, d2, d3, f0, f1, f2, f3):
    """Whether a ball needs more than :func:`analytic_tile`'s branch-free loop: an angle
    beyond SMALL_ANGLE (or NaN), a force outside CBRT_RANGE."""
    angles = ((abs(d0) <= SMALL_ANGLE) & (abs(d1) <= SMALL_ANGLE) & (abs(d2) <= SMALL_ANGLE)
              & (abs(d3) <= SMALL_ANGLE))
    forces = cbrt_in_range(f0) & cbrt_in_range(f1) & cbrt_in_range(f2) & cbrt_in_range(f3)
    return not (angles & forces)


@pjit
def _analytic_tiles(dbeta, force, nominal_angle, ball_radius, semi_major_coefficient,
                    elliptic_e, k_f, max_ratio, max_angle, max_eps, out_eps, out_valid):
    """:func:`analytic_kernel` without Eq. (22) and dgamma: the balls in tiles
    (:func:`analytic_tile`), each gathered contact by contact."""
    n = dbeta.shape[0]
    for k in prange((n + ANALYTIC_TILE - 1) // ANALYTIC_TILE):
        at = k * ANALYTIC_TILE
        m = min(ANALYTIC_TILE, n - at)
        d = np.empty((4, ANALYTIC_TILE))
        f = np.empty((4, ANALYTIC_TILE))
        for i in range(m):
            for c in range(4):
                d[c, i] = dbeta[at + i, c]
                f[c, i] = force[at + i, c]
        analytic_tile(d, f, m, nominal_angle, ball_radius, semi_major_coefficient, elliptic_e,
                      k_f, max_ratio, max_angle, max_eps, out_eps, out_valid, at)


#: Columns of ``out_load`` of :func:`analytic_loaded_kernel`.
LOAD_COLUMNS = ("free_rolling_velocity_deviation", "creep_stiffness", "braking_sensitivity",
                "carriage_force", "free_rolling_carriage_force", "carriage_force_per_push",
                "carriage_force_per_neighbour_force", "traction_capacity", "braking_capacity")


@jit(inline="always")
def creep_frame(dbeta, force, force_cbrt, n, sin_b0, cos_b0, nominal_angle, ball_radius,
                semi_major_coefficient, k_f, inv_mu):
    """What the creep kernels compute first for ball ``n``, with the free solve's arithmetic:
    the sines and cosines of its contact angles, its forces, the semi-major axes a_i and
    friction weights q_i, the null vector n_i (with d012) of the rows (1, 1, 1, 1), (x_i),
    (y_i), w_i = +-1 / q_i with w . n, and the unit push's particular solution pp_0..2 and
    multiplier tp (:func:`_analytic_loaded_solve`, :func:`creep_coefficients_kernel`,
    :func:`tolsim.physics.velocity.creep_stiffness.creep_stiffness_kernel`)."""
    s0, c0 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 0])
    s1, c1 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 1])
    s2, c2 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 2])
    s3, c3 = sin_cos_near(sin_b0, cos_b0, nominal_angle, dbeta[n, 3])
    x0, y0 = c0, -s0
    x1, y1 = c1, s1
    x2, y2 = -c2, s2
    x3, y3 = -c3, -s3
    f0, f1, f2, f3 = force[n, 0], force[n, 1], force[n, 2], force[n, 3]
    a0 = semi_major_coefficient * force_cbrt[n, 0]
    a1 = semi_major_coefficient * force_cbrt[n, 1]
    a2 = semi_major_coefficient * force_cbrt[n, 2]
    a3 = semi_major_coefficient * force_cbrt[n, 3]
    q0 = -k_f * ball_radius * f0 / a0
    q1 = -k_f * ball_radius * f1 / a1
    q2 = k_f * ball_radius * f2 / a2
    q3 = k_f * ball_radius * f3 / a3
    d012 = det3(1.0, 1.0, 1.0, x0, x1, x2, y0, y1, y2)
    n0 = det3(1.0, 1.0, 1.0, x1, x2, x3, y1, y2, y3)
    n1 = -det3(1.0, 1.0, 1.0, x0, x2, x3, y0, y2, y3)
    n2 = det3(1.0, 1.0, 1.0, x0, x1, x3, y0, y1, y3)
    n3 = -d012
    w0, w1, w2, w3 = 1.0 / q0, -1.0 / q1, -1.0 / q2, 1.0 / q3
    wn = w0 * n0 + w1 * n1 + w2 * n2 + w3 * n3
    pp0 = det3(-inv_mu, 1.0, 1.0, 0.0, x1, x2, 0.0, y1, y2) / d012
    pp1 = det3(1.0, -inv_mu, 1.0, x0, 0.0, x2, y0, 0.0, y2) / d012
    pp2 = det3(1.0, 1.0, -inv_mu, x0, x1, 0.0, y0, y1, 0.0) / d012
    tp = -(w0 * pp0 + w1 * pp1 + w2 * pp2) / wn
    return (s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1, a2, a3, q0, q1, q2, q3,
            d012, n0, n1, n2, n3, w0, w1, w2, w3, wn, pp0, pp1, pp2, tp)


def analytic_loaded_kernel(
    dbeta, force, push, neighbour_force_sum, nominal_angle, ball_radius, semi_major_coefficient,
    elliptic_e, k_f, friction_coefficient, ball_friction, max_ratio, max_angle, max_eps,
    out_eps, out_eps22, out_gamma, out_valid, out_load, out_sliding,
):
    """The analytic model under external loads; unchecked fast path (trains call it).

    Eqs. (17), (18) [ERRATA 8], (21) with the push P in the z-force row and the ball-ball
    braking moment in the moment rows (:mod:`tolsim.physics.velocity.ball_loads`):

        sum u_i = -P / mu,  sum u_i x_i + sum m_i y_i = -(mu_bb / mu)(Q_back + Q_front) e,

    e the rolling axis (:func:`~tolsim.physics.velocity.ball_loads.rolling_axis`). The system is
    linear in the loads, so each ball is solved three times on the same matrix: free (the
    arithmetic of :func:`analytic_kernel`, so P = Q = 0 reproduces its epsilon bit for bit),
    per unit P and per unit Q_back + Q_front; the loaded state is their superposition, and
    the creep stiffness K = 1 / (d epsilon / dP) follows exactly from the unit-push solve.

    ``dbeta``, ``force``: C-contiguous (n, 4) float64; ``push``, ``neighbour_force_sum``: (n,)
    [N]; ``friction_coefficient`` mu > 0 (raceways) and ``ball_friction`` mu_bb >= 0.
    Outputs as :func:`analytic_kernel` (``out_eps22`` and ``out_gamma`` always written), and
    ``out_load`` (n, 9) with the columns ``LOAD_COLUMNS`` (epsilon free [-], K [N], d epsilon
    / d(Q_back + Q_front) [1/N], F_c and F_c free [N], dF_c/dP and dF_c/d(Q_back + Q_front)
    [-], traction capacity and braking capacity [N]), ``out_sliding`` (n,) bool: |P| >=
    traction capacity or Q_back + Q_front >= braking capacity.
    ``out_valid``: the criteria of :func:`analytic_kernel` on the loaded dgamma_i (|c_i/a_i|,
    |dbeta_i + dgamma_i|) and on the free epsilon (|eps| <= ``max_eps``, the deviation-driven
    part the budget was measured for), and not sliding.
    """
    force_cbrt = cbrt_nonnegative(force)
    _analytic_loaded_solve(dbeta, force, force_cbrt, push, neighbour_force_sum, nominal_angle,
                           ball_radius, semi_major_coefficient, elliptic_e, k_f,
                           friction_coefficient, ball_friction, max_ratio, max_angle, max_eps,
                           out_eps, out_eps22, out_gamma, out_valid, out_load, out_sliding)


@pjit
def _analytic_loaded_solve(
    dbeta, force, force_cbrt, push, neighbour_force_sum, nominal_angle, ball_radius,
    semi_major_coefficient, elliptic_e, k_f, friction_coefficient, ball_friction, max_ratio,
    max_angle, max_eps, out_eps, out_eps22, out_gamma, out_valid, out_load, out_sliding,
):
    """Per-ball solve of :func:`analytic_loaded_kernel` (free, unit push, unit braking)."""
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    inv_mu = 1.0 / friction_coefficient
    braking_ratio = ball_friction * inv_mu  # (mu_bb / mu) per newton of Q_back + Q_front
    for n in prange(dbeta.shape[0]):
        # --- the system of analytic_kernel, same arithmetic; the unit push: rhs (-1/mu, 0,
        # 0), Eq. (21) homogeneous (creep_frame) ---
        (s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1, a2, a3, q0, q1, q2, q3, d012,
         n0, n1, n2, n3, w0, w1, w2, w3, wn, pp0, pp1, pp2, tp) = creep_frame(
            dbeta, force, force_cbrt, n, sin_b0, cos_b0, nominal_angle, ball_radius,
            semi_major_coefficient, k_f, inv_mu)
        x0, y0 = c0, -s0
        x1, y1 = c1, s1
        x2, y2 = -c2, s2
        ok = min(min(f0, f1), min(f2, f3)) > 0.0
        p0, p1, p2 = spin_particular(s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1,
                                     a2, a3, d012, elliptic_e, ball_radius)
        rhs = -(dbeta[n, 0] + dbeta[n, 3] - dbeta[n, 1] - dbeta[n, 2])
        t = (rhs - (w0 * p0 + w1 * p1 + w2 * p2)) / wn
        g0 = (p0 + t * n0) / q0
        g1 = (p1 + t * n1) / q1
        g2 = (p2 + t * n2) / q2
        g3 = (t * n3) / q3
        eps = half_tan * (-dbeta[n, 1] - g1 + dbeta[n, 3] + g3)
        # --- unit Q_back + Q_front: braking -(mu_bb/mu) e in the moment rows ---
        beta = np.empty(4)
        for i in range(4):
            beta[i] = nominal_angle + dbeta[n, i]
        ex, ey = rolling_axis(beta, force[n])
        bx = -braking_ratio * ex
        by = -braking_ratio * ey
        pb0 = det3(0.0, 1.0, 1.0, bx, x1, x2, by, y1, y2) / d012
        pb1 = det3(1.0, 0.0, 1.0, x0, bx, x2, y0, by, y2) / d012
        pb2 = det3(1.0, 1.0, 0.0, x0, x1, bx, y0, y1, by) / d012
        tb = -(w0 * pb0 + w1 * pb1 + w2 * pb2) / wn
        # --- superposition ---
        load_p = push[n]
        load_q = neighbour_force_sum[n]
        g0 = g0 + (load_p * (pp0 + tp * n0) / q0 + load_q * (pb0 + tb * n0) / q0)
        g1 = g1 + (load_p * (pp1 + tp * n1) / q1 + load_q * (pb1 + tb * n1) / q1)
        g2 = g2 + (load_p * (pp2 + tp * n2) / q2 + load_q * (pb2 + tb * n2) / q2)
        g3 = g3 + (load_p * (tp * n3) / q3 + load_q * (tb * n3) / q3)
        deps_dp = half_tan * (-(pp1 + tp * n1) / q1 + (tp * n3) / q3)
        deps_dq = half_tan * (-(pb1 + tb * n1) / q1 + (tb * n3) / q3)
        out_eps[n] = eps + (load_p * deps_dp + load_q * deps_dq)
        out_gamma[n, 0] = g0
        out_gamma[n, 1] = g1
        out_gamma[n, 2] = g2
        out_gamma[n, 3] = g3
        out_eps22[n] = eq22_velocity_deviation(nominal_angle + dbeta[n, 0] + g0,
                                               nominal_angle + dbeta[n, 1] + g1,
                                               nominal_angle + dbeta[n, 3] + g3)
        # carriage force: the top contacts' friction along z, mu (u_TR + u_TL), u = p + t n
        fc_free = friction_coefficient * ((p2 + t * n2) + t * n3)
        fc_p = friction_coefficient * ((pp2 + tp * n2) + tp * n3)
        fc_q = friction_coefficient * ((pb2 + tb * n2) + tb * n3)
        capacity, _, _ = point_traction_capacity(beta, force[n], braking_ratio * load_q, ex, ey)
        capacity *= friction_coefficient
        stall = stall_moment(beta, force[n]) * friction_coefficient
        braking_capacity = stall / ball_friction if ball_friction > 0.0 else np.inf
        sliding = abs(load_p) >= capacity or load_q >= braking_capacity
        out_load[n, 0] = eps
        out_load[n, 1] = 1.0 / deps_dp
        out_load[n, 2] = deps_dq
        out_load[n, 3] = fc_free + (load_p * fc_p + load_q * fc_q)
        out_load[n, 4] = fc_free
        out_load[n, 5] = fc_p
        out_load[n, 6] = fc_q
        out_load[n, 7] = capacity
        out_load[n, 8] = braking_capacity
        out_sliding[n] = sliding
        ok = ok and ball_radius * abs(g0) <= max_ratio * a0
        ok = ok and ball_radius * abs(g1) <= max_ratio * a1
        ok = ok and ball_radius * abs(g2) <= max_ratio * a2
        ok = ok and ball_radius * abs(g3) <= max_ratio * a3
        ok = ok and abs(dbeta[n, 0] + g0) <= max_angle and abs(dbeta[n, 1] + g1) <= max_angle
        ok = ok and abs(dbeta[n, 2] + g2) <= max_angle and abs(dbeta[n, 3] + g3) <= max_angle
        out_valid[n] = ok and abs(eps) <= max_eps and not sliding


# --------------------------------------------------------------------------------------------
# Creep coefficients at zero load: the loaded model's fast path for a study's trains
# --------------------------------------------------------------------------------------------
@pjit
def creep_coefficients_kernel(dbeta, force, force_cbrt, nominal_angle, ball_radius,
                              semi_major_coefficient, elliptic_e, k_f, friction_coefficient,
                              ball_friction, out_load):
    """The loaded analytic model's coefficients at zero load, a study's fast path; unchecked.

    The columns of :func:`analytic_loaded_kernel` (``LOAD_COLUMNS``)
    with push and neighbour forces zero, written into ``out_load`` (n, 9): the free, unit-push
    and unit-braking solves with the same arithmetic (so epsilon, K, c, F_0, a, b agree with
    it to round-off, tests/study/test_friction_study.py), the rolling axis and the stall moment of
    :mod:`tolsim.physics.velocity.ball_loads` from the same sines and cosines. What it leaves out is
    what a study does not need and what costs most there (the vertex search of
    :func:`tolsim.physics.velocity.ball_loads.point_traction_capacity`, Eq. 22, dgamma, validity):
    column ``traction_capacity`` holds a **lower bound** of the point-contact traction
    capacity instead, from a dual-feasible point of its linear programme. With
    u_i = 1 + a_i . w (a_i = (p_y, -p_x)) and any lambda_i in [-1, 1],

        Phi_0(w) = sum_i F_i |u_i| (+ braking >= 0) >= sum_i lambda_i F_i
                   + w . sum_i lambda_i F_i a_i,

    so every lambda with sum_i lambda_i F_i a_i = 0 gives P_cap >= mu sum_i lambda_i F_i.
    lambda = 1 - delta with delta on two contacts j, k solving sum F_i a_i = g_j a_j + g_k a_k
    (g = delta F >= 0, delta <= 2) gives mu (sum F_i - g_j - g_k); the best pair is taken (0 if
    none is feasible). For a ball in static equilibrium sum F_i a_i = 0 and the bound is the
    capacity, mu sum F_i. Otherwise it is the optimum of the dual whenever an optimal lambda
    has its two free entries on one pair and +1 elsewhere; on 20 000 random balls (dbeta ~
    0.6 deg, forces 0.3-1.7 x 141 N, far from equilibrium) it equalled the vertex search to
    1e-15 (tests/study/test_friction_study.py), 1/3 of its cost.

    ``dbeta``, ``force``, ``force_cbrt`` (:func:`tolsim.physics._fastmath.cbrt_nonnegative` of
    ``force``): C-contiguous (n, 4) float64; ``out_load`` (n, 9). Called by
    :mod:`tolsim.study.pipeline.track_friction` (``creep_model = "analytic"``), one call per chunk.
    """
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    inv_mu = 1.0 / friction_coefficient
    braking_ratio = ball_friction * inv_mu
    for n in prange(dbeta.shape[0]):
        # --- the free solve of analytic_kernel, same arithmetic ---
        (s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1, a2, a3, q0, q1, q2, q3, d012,
         n0, n1, n2, n3, w0, w1, w2, w3, wn, pp0, pp1, pp2, tp) = creep_frame(
            dbeta, force, force_cbrt, n, sin_b0, cos_b0, nominal_angle, ball_radius,
            semi_major_coefficient, k_f, inv_mu)
        x0, y0 = c0, -s0
        x1, y1 = c1, s1
        x2, y2 = -c2, s2
        x3, y3 = -c3, -s3
        p0, p1, p2 = spin_particular(s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1,
                                     a2, a3, d012, elliptic_e, ball_radius)
        rhs = -(dbeta[n, 0] + dbeta[n, 3] - dbeta[n, 1] - dbeta[n, 2])
        t = (rhs - (w0 * p0 + w1 * p1 + w2 * p2)) / wn
        g1 = (p1 + t * n1) / q1
        g3 = (t * n3) / q3
        eps = half_tan * (-dbeta[n, 1] - g1 + dbeta[n, 3] + g3)
        # --- rolling axis (ball_loads.rolling_axis): rows (1, p_y, -p_x), p_y = -x, p_x = y ---
        ex, ey = _creep_rolling_axis(x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3)
        # --- unit Q_back + Q_front ---
        bx = -braking_ratio * ex
        by = -braking_ratio * ey
        pb0 = det3(0.0, 1.0, 1.0, bx, x1, x2, by, y1, y2) / d012
        pb1 = det3(1.0, 0.0, 1.0, x0, bx, x2, y0, by, y2) / d012
        pb2 = det3(1.0, 1.0, 0.0, x0, x1, bx, y0, y1, by) / d012
        tb = -(w0 * pb0 + w1 * pb1 + w2 * pb2) / wn
        deps_dp = half_tan * (-(pp1 + tp * n1) / q1 + (tp * n3) / q3)
        deps_dq = half_tan * (-(pb1 + tb * n1) / q1 + (tb * n3) / q3)
        fc_free = friction_coefficient * ((p2 + t * n2) + t * n3)
        fc_p = friction_coefficient * ((pp2 + tp * n2) + tp * n3)
        fc_q = friction_coefficient * ((pb2 + tb * n2) + tb * n3)
        # --- stall moment (ball_loads.stall_moment): |sum_bottom F x - sum_top F x| ---
        stall = np.hypot(f0 * x0 + f1 * x1 - f2 * x2 - f3 * x3,
                         f0 * y0 + f1 * y1 - f2 * y2 - f3 * y3) * friction_coefficient
        out_load[n, 0] = eps
        out_load[n, 1] = 1.0 / deps_dp
        out_load[n, 2] = deps_dq
        out_load[n, 3] = fc_free
        out_load[n, 4] = fc_free
        out_load[n, 5] = fc_p
        out_load[n, 6] = fc_q
        out_load[n, 7] = friction_coefficient * _creep_traction_bound(
            x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3)
        out_load[n, 8] = stall / ball_friction if ball_friction > 0.0 else np.inf


@jit(inline="always")
def _creep_rolling_axis(x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3):
    """:func:`tolsim.physics.velocity.ball_loads.rolling_axis` from the local x axes
    x_i = (-p_y, p_x)
    (same least squares, same Cramer's rule); (1, 0) if singular."""
    a00 = a01 = a02 = a11 = a12 = a22 = 0.0
    b0 = b1 = b2 = 0.0
    for i in range(4):
        if i == 0:
            xx, xy, f, target = x0, y0, f0, 0.0
        elif i == 1:
            xx, xy, f, target = x1, y1, f1, 0.0
        elif i == 2:
            xx, xy, f, target = x2, y2, f2, 1.0
        else:
            xx, xy, f, target = x3, y3, f3, 1.0
        if f > 0.0:
            r1, r2 = -xx, -xy  # (1, p_y, -p_x)
            b0 += target
            b1 += r1 * target
            b2 += r2 * target
            a00 += 1.0
            a01 += r1
            a02 += r2
            a11 += r1 * r1
            a12 += r1 * r2
            a22 += r2 * r2
    det = (a00 * (a11 * a22 - a12 * a12) - a01 * (a01 * a22 - a12 * a02)
           + a02 * (a01 * a12 - a11 * a02))
    if not (abs(det) > 1e-300):
        return 1.0, 0.0
    wx = (a00 * (b1 * a22 - a12 * b2) - b0 * (a01 * a22 - a12 * a02)
          + a02 * (a01 * b2 - b1 * a02)) / det
    wy = (a00 * (a11 * b2 - b1 * a12) - a01 * (a01 * b2 - b1 * a02)
          + b0 * (a01 * a12 - a11 * a02)) / det
    norm = np.hypot(wx, wy)
    if not norm > 0.0:
        return 1.0, 0.0
    return wx / norm, wy / norm


@jit(inline="always")
def _creep_traction_bound(x0, y0, x1, y1, x2, y2, x3, y3, f0, f1, f2, f3):
    """Lower bound of min_w sum_i F_i |1 + a_i . w| with a_i = -x_i (kernel docstring)."""
    rx = -(f0 * x0 + f1 * x1 + f2 * x2 + f3 * x3)
    ry = -(f0 * y0 + f1 * y1 + f2 * y2 + f3 * y3)
    total = f0 + f1 + f2 + f3
    if rx == 0.0 and ry == 0.0:
        return total
    best = 0.0
    for j in range(4):
        for k in range(j + 1, 4):
            ajx, ajy, fj = ((-x0, -y0, f0) if j == 0 else (-x1, -y1, f1) if j == 1
                            else (-x2, -y2, f2))
            akx, aky, fk = ((-x1, -y1, f1) if k == 1 else (-x2, -y2, f2) if k == 2
                            else (-x3, -y3, f3))
            det = ajx * aky - ajy * akx
            if abs(det) < 1e-12:
                continue
            gj = (rx * aky - ry * akx) / det
            gk = (ajx * ry - ajy * rx) / det
            if 0.0 <= gj <= 2.0 * fj and 0.0 <= gk <= 2.0 * fk:
                bound = total - gj - gk
                if bound > best:
                    best = bound
    return best


@jit
def _point_one(beta, force):
    """Point-contact model for one ball (v = 1). Returns eps, eps22, gamma[4], slider, margin."""
    sx = (-1.0, 1.0, 1.0, -1.0)
    sy = (-1.0, -1.0, 1.0, 1.0)
    target = (0.0, 0.0, 1.0, 1.0)  # groove velocity along z at each contact
    px = np.empty(4)
    py = np.empty(4)
    xx = np.empty(4)
    xy = np.empty(4)
    for i in range(4):
        px[i] = sx[i] * np.sin(beta[i])
        py[i] = sy[i] * np.cos(beta[i])
        # local x = y_i x z with y_i = -p_i: x = (y_y, -y_x) = (-p_y, p_x)
        xx[i] = -py[i]
        xy[i] = px[i]
    best = -1
    best_margin = -np.inf
    second_margin = -np.inf
    best_state = np.zeros(3)
    for j in range(4):
        # rolling at the three contacts k != j: v_B + w_x p_y - w_y p_x = target_k (R = 1)
        ks = [k for k in range(4) if k != j]
        k0, k1, k2 = ks[0], ks[1], ks[2]
        det = det3(1.0, py[k0], -px[k0], 1.0, py[k1], -px[k1], 1.0, py[k2], -px[k2])
        vb = det3(target[k0], py[k0], -px[k0], target[k1], py[k1], -px[k1],
                  target[k2], py[k2], -px[k2]) / det
        wx = det3(1.0, target[k0], -px[k0], 1.0, target[k1], -px[k1],
                  1.0, target[k2], -px[k2]) / det
        wy = det3(1.0, py[k0], target[k0], 1.0, py[k1], target[k1],
                  1.0, py[k2], target[k2]) / det
        slip = vb + wx * py[j] - wy * px[j] - target[j]
        fj = -force[j] * np.sign(slip)  # friction / mu on the ball, along z
        # equilibrium of the other three: sum f = 0, sum f x_i = 0 (x and y components)
        det_e = det3(1.0, 1.0, 1.0, xx[k0], xx[k1], xx[k2], xy[k0], xy[k1], xy[k2])
        r1, r2, r3 = -fj, -fj * xx[j], -fj * xy[j]
        fk0 = det3(r1, 1.0, 1.0, r2, xx[k1], xx[k2], r3, xy[k1], xy[k2]) / det_e
        fk1 = det3(1.0, r1, 1.0, xx[k0], r2, xx[k2], xy[k0], r3, xy[k2]) / det_e
        fk2 = det3(1.0, 1.0, r1, xx[k0], xx[k1], r2, xy[k0], xy[k1], r3) / det_e
        margin = min(
            (force[k0] - abs(fk0)) / force[k0],
            (force[k1] - abs(fk1)) / force[k1],
            (force[k2] - abs(fk2)) / force[k2],
        )
        if margin > best_margin + 1e-12:
            second_margin = best_margin
            best_margin = margin
            best = j
            best_state[0] = vb
            best_state[1] = wx
            best_state[2] = wy
        elif margin > second_margin:
            second_margin = margin
    vb, wx, wy = best_state[0], best_state[1], best_state[2]
    gamma = np.zeros(4)
    # zero-velocity point of the sliding contact: on the circle, where v_z = target
    j = best
    amp_c = wx * sy[j]  # coefficient of cos(b)
    amp_s = -wy * sx[j]  # coefficient of sin(b)
    rhs = target[j] - vb
    amp = np.hypot(amp_c, amp_s)
    phase = np.arctan2(amp_s, amp_c)
    ratio = min(1.0, max(-1.0, rhs / amp))
    cand1 = phase + np.arccos(ratio)
    cand2 = phase - np.arccos(ratio)
    d1 = (cand1 - beta[j] + np.pi) % (2 * np.pi) - np.pi
    d2 = (cand2 - beta[j] + np.pi) % (2 * np.pi) - np.pi
    gamma[j] = d1 if abs(d1) < abs(d2) else d2
    eps = 2.0 * vb - 1.0
    return eps, gamma, best, best_margin, second_margin


@pjit
def point_kernel(dbeta, force, nominal_angle, out_eps, out_eps22, out_gamma, out_slider,
                 out_valid):
    """Prior point-contact model: three contacts roll at their centres, one slides."""
    for n in prange(dbeta.shape[0]):
        beta = np.empty(4)
        for i in range(4):
            beta[i] = nominal_angle + dbeta[n, i]
        eps, gamma, slider, margin, runner_up = _point_one(beta, force[n])
        out_eps[n] = eps
        for i in range(4):
            out_gamma[n, i] = gamma[i]
        out_eps22[n] = eq22_velocity_deviation(beta[0] + gamma[0], beta[1] + gamma[1],
                                               beta[3] + gamma[3])
        out_slider[n] = slider
        # invalid when no candidate is admissible, a force is zero, or two candidates tie
        # (equal diagonal forces: which contact slides is undetermined, eps jumps there)
        tie = runner_up >= margin - 1e-9 and abs(eps) > 1e-12
        out_valid[n] = (margin >= -1e-9 and not tie
                        and min(min(force[n, 0], force[n, 1]), min(force[n, 2], force[n, 3])) > 0)
