"""The creep stiffness K of loaded balls alone, for a caller that needs no other coefficient
(the recirculating circuit's step, :mod:`tolsim.study.pipeline.carriage_circuit`)."""

import numpy as np
from numba import prange

from tolsim._jit import pjit
from tolsim.physics._fastmath import cbrt_nonnegative
from tolsim.physics.geometry import K_F_PAPER
from tolsim.physics.hertz import bearing_constants
from tolsim.physics.velocity._analytic_kernels import creep_frame


@pjit
def creep_stiffness_kernel(dbeta, force, force_cbrt, nominal_angle, ball_radius,
                           semi_major_coefficient, k_f, friction_coefficient, out):
    """Column ``creep_stiffness`` of :func:`tolsim.physics.velocity.analytic.
    creep_coefficients_kernel` alone, bit for bit: K = 1 / (d epsilon / d P) from the free
    solve's matrix and the unit-push solve, with the same operations in the same order (one
    set-up for both, :func:`tolsim.physics.velocity._analytic_kernels.creep_frame`; the
    moments, the free and braking solves, the rolling axis, the carriage forces and the
    capacities of that kernel are not formed: K does not depend on them). Inputs as there;
    writes ``out`` (n,); unchecked.
    """
    half_tan = 0.5 * np.tan(nominal_angle)
    sin_b0, cos_b0 = np.sin(nominal_angle), np.cos(nominal_angle)
    inv_mu = 1.0 / friction_coefficient
    for n in prange(dbeta.shape[0]):
        (s0, c0, s1, c1, s2, c2, s3, c3, f0, f1, f2, f3, a0, a1, a2, a3, q0, q1, q2, q3, d012,
         n0, n1, n2, n3, w0, w1, w2, w3, wn, pp0, pp1, pp2, tp) = creep_frame(
            dbeta, force, force_cbrt, n, sin_b0, cos_b0, nominal_angle, ball_radius,
            semi_major_coefficient, k_f, inv_mu)
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
    hc = bearing_constants(bearing)
    out = np.empty(len(dbeta))
    creep_stiffness_kernel(dbeta, force, cbrt_nonnegative(force),
                           bearing.nominal_contact_angle, bearing.ball_radius,
                           hc.semi_major_coefficient, K_F_PAPER, bearing.friction_coefficient,
                           out)
    return out
