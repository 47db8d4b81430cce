"""The creep stiffness K of loaded balls alone, for a caller that needs no other coefficient
(the recirculating circuit's step, :mod:`tolsim.study.pipeline.carriage_circuit`)."""

import numpy as np
from numba import prange

from tolsim._jit import pjit
from tolsim.physics._fastmath import cbrt_nonnegative, sin_cos_near
from tolsim.physics.geometry import K_F_PAPER
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity._analytic_kernels import det3


@pjit
def creep_stiffness_kernel(dbeta, force, force_cbrt, nominal_angle, ball_radius,
                           semi_major_coefficient, k_f, friction_coefficient, out):
    """Column ``creep_stiffness`` of :func:`tolsim.physics.velocity.analytic.
    creep_coefficients_kernel` alone, bit for bit: K = 1 / (d epsilon / d P) from the free
    solve's matrix and the unit-push solve, with the same operations in the same order (the
    moments, the free and braking solves, the rolling axis, the carriage forces and the
    capacities of that kernel are not formed: K does not depend on them). Inputs as there;
    writes ``out`` (n,); unchecked.
    """
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    inv_mu = 1.0 / friction_coefficient
    for n in prange(dbeta.shape[0]):
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
        deps_dp = half_tan * (-(pp1 + tp * n1) / q1 + (tp * n3) / q3)
        out[n] = 1.0 / deps_dp


def creep_stiffness(dbeta, force, bearing):
    """Creep stiffness K [N] of n loaded balls at zero load by the analytic model: the
    ``creep_stiffness`` column of :func:`tolsim.physics.velocity.analytic.
    creep_coefficients_kernel` (``creep_model = "analytic"``), bit for bit, at a fraction of
    its cost (:func:`creep_stiffness_kernel`).

    Parameters
    ----------
    dbeta, force : ndarray, shape (n, 4)
        C-contiguous float64 [rad], [N]; the forces finite and >= 0.
    bearing : Bearing

    Returns
    -------
    ndarray, shape (n,)
    """
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    out = np.empty(len(dbeta))
    creep_stiffness_kernel(dbeta, force, cbrt_nonnegative(force),
                           bearing.nominal_contact_angle, bearing.ball_radius,
                           hc.semi_major_coefficient, K_F_PAPER, bearing.friction_coefficient,
                           out)
    return out
