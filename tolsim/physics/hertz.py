"""Hertz contact of a steel ball in a straight circular-arc groove.

The ball (radius R_B) touches a groove flank of radius R_G = 2 f R_B that is straight along
the rail. Principal relative curvatures (gap h = A x^2 + B z^2):

    A = (1/R_B - 1/R_G) / 2   across the groove (x, in the cross-section)
    B = 1 / (2 R_B)           along the rail (z)

A < B, so the contact ellipse is long across the groove: semi-axis a along x, b along z
(ERRATA 4). The exact solution follows [Johnson1985] Sec. 4.2 (Eqs. 4.39-4.41 in the notation
used here), with k = b/a and e^2 = 1 - k^2:

    B/A = (E(e)/k^2 - K(e)) / (K(e) - E(e))                       ellipticity
    a^3 = 3 F (K - E) / (2 pi E* e^2 A)                            semi-major axis
    p0  = 3 F / (2 pi a b)                                         maximum pressure
    delta = p0 b K(e) / E*                                         approach

with E* = E / (2 (1 - nu^2)) for ball and groove of the same material. Because a, b ~ F^(1/3)
and delta ~ F^(2/3) for a fixed geometry, everything reduces to a few coefficients computed
once (:class:`HertzConstants`), which the Numba kernels consume.

References
----------
.. [Johnson1985] K. L. Johnson, Contact Mechanics, Cambridge University Press, 1985.
.. [HamrockDowson1981] B. J. Hamrock, D. Dowson, Ball Bearing Lubrication, Wiley, 1981,
   Ch. 3 (curve fits k = 1.0339 alpha^0.6360, E = 1.0003 + 0.5968/alpha,
   F = 1.5277 + 0.6023 ln alpha, alpha = R_y/R_x).
.. [HamrockBrewe1983] B. J. Hamrock, D. E. Brewe, "Simplified solution for stresses and
   deformations", J. Lubr. Technol. 105 (1983) 171-177 (k = alpha^(2/pi),
   E = 1 + (pi/2 - 1)/alpha, F = pi/2 + (pi/2 - 1) ln alpha).
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import brentq
from scipy.special import ellipe, ellipk

from tolsim.physics.geometry import check_bearing


def effective_modulus(youngs_modulus, poisson_ratio):
    """Contact modulus E* of two bodies of the same material [Pa].

    1/E* = 2 (1 - nu^2) / E  ([Johnson1985] Eq. 3.15 with identical bodies).
    """
    return youngs_modulus / (2.0 * (1.0 - poisson_ratio**2))


def groove_curvatures(ball_radius, conformity):
    """Relative curvatures A (across the groove) and B (along the rail) [1/m].

    The gap between ball and flank near the contact is h = A x^2 + B z^2.
    """
    groove_radius = 2.0 * conformity * ball_radius
    across = 0.5 * (1.0 / ball_radius - 1.0 / groove_radius)
    along = 0.5 / ball_radius
    return across, along


def _curvature_ratio(ellipticity):
    """B/A as a function of k = b/a (the Hertz ellipticity equation)."""
    m = 1.0 - ellipticity**2
    kk, ee = ellipk(m), ellipe(m)
    return (ee / ellipticity**2 - kk) / (kk - ee)


def ellipticity_from_curvatures(across, along):
    """Solve the Hertz ellipticity equation for k = b/a <= 1 (b along the larger curvature)."""
    ratio = along / across
    if not ratio >= 1.0:
        raise ValueError(f"curvature ratio B/A = {ratio!r} must be >= 1")
    if ratio - 1.0 < 1e-12:
        return 1.0
    # _curvature_ratio falls monotonically from +inf (k -> 0) to 1 (k -> 1).
    return brentq(lambda k: _curvature_ratio(k) - ratio, 1e-6, 1.0 - 1e-14, xtol=1e-15, rtol=1e-15)


@dataclass(frozen=True)
class HertzConstants:
    """Load-independent coefficients of the Hertz contact of one ball/groove pair.

    With F the normal force [N]: a = semi_major_coefficient F^(1/3),
    b = semi_minor_coefficient F^(1/3), delta = approach_coefficient F^(2/3),
    p0 = pressure_coefficient F^(1/3), and F = load_deflection_constant delta^(3/2).
    """

    semi_major_coefficient: float  # [m N^-1/3], a along x (across the groove)
    semi_minor_coefficient: float  # [m N^-1/3], b along z (along the rail)
    approach_coefficient: float  # [m N^-2/3]
    pressure_coefficient: float  # [Pa N^-1/3]
    load_deflection_constant: float  # K [N m^-3/2]
    ellipticity: float  # k = b/a [-]
    eccentricity_squared: float  # e^2 = 1 - k^2 [-]
    elliptic_k: float  # K(e) [-]
    elliptic_e: float  # E(e) [-]


@lru_cache(maxsize=64)
def hertz_constants(ball_radius, conformity, youngs_modulus=210.0e9, poisson_ratio=0.28):
    """Hertz coefficients for a ball of radius R_B in a groove of conformity f.

    Parameters
    ----------
    ball_radius : float
        R_B [m].
    conformity : float
        f = R_G / (2 R_B) [-], > 0.5.
    youngs_modulus : float
        E of ball and groove [Pa].
    poisson_ratio : float
        nu of ball and groove [-].

    Returns
    -------
    HertzConstants
    """
    if not (ball_radius > 0 and conformity > 0.5 and youngs_modulus > 0):
        raise ValueError("need ball_radius > 0, conformity > 0.5 and youngs_modulus > 0")
    across, along = groove_curvatures(ball_radius, conformity)
    k = ellipticity_from_curvatures(across, along)
    m = 1.0 - k * k
    kk, ee = float(ellipk(m)), float(ellipe(m))
    e_star = effective_modulus(youngs_modulus, poisson_ratio)
    if m > 0:
        ca3 = 3.0 * (kk - ee) / (2.0 * np.pi * e_star * m * across)
    else:  # circle: (K - E)/e^2 -> pi/4
        ca3 = 3.0 / (8.0 * e_star * across)
    ca = ca3 ** (1.0 / 3.0)
    cb = k * ca
    cp = 3.0 / (2.0 * np.pi * ca * cb)
    cdelta = cp * cb * kk / e_star
    return HertzConstants(
        semi_major_coefficient=ca,
        semi_minor_coefficient=cb,
        approach_coefficient=cdelta,
        pressure_coefficient=cp,
        load_deflection_constant=cdelta**-1.5,
        ellipticity=k,
        eccentricity_squared=m,
        elliptic_k=kk,
        elliptic_e=ee,
    )


def bearing_constants(bearing):
    """:func:`hertz_constants` of a :class:`~tolsim.physics.geometry.Bearing`.

    Raises
    ------
    ValueError
        Naming ``bearing`` when it is not a Bearing (None, say).
    """
    check_bearing(bearing)
    return hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                           bearing.poisson_ratio)


@dataclass(frozen=True)
class HertzContact:
    """Hertz solution at given normal forces (arrays broadcast like the force)."""

    semi_major: np.ndarray  # a [m], across the groove
    semi_minor: np.ndarray  # b [m], along the rail
    max_pressure: np.ndarray  # p0 [Pa]
    approach: np.ndarray  # delta [m]
    load_deflection_constant: float  # K [N m^-3/2]


def contact_ellipse(
    normal_force, ball_radius, conformity, youngs_modulus=210.0e9, poisson_ratio=0.28
):
    """Hertz contact ellipse, pressure and approach of a ball in a groove.

    Parameters
    ----------
    normal_force : array_like
        F >= 0 [N].
    ball_radius, conformity, youngs_modulus, poisson_ratio : float
        As in :func:`hertz_constants`.

    Returns
    -------
    HertzContact
    """
    force = np.asarray(normal_force, dtype=float)
    if np.any(~np.isfinite(force)) or np.any(force < 0):
        raise ValueError("normal_force must be finite and >= 0")
    c = hertz_constants(ball_radius, conformity, youngs_modulus, poisson_ratio)
    f13 = np.cbrt(force)
    return HertzContact(
        semi_major=c.semi_major_coefficient * f13,
        semi_minor=c.semi_minor_coefficient * f13,
        max_pressure=c.pressure_coefficient * f13,
        approach=c.approach_coefficient * f13**2,
        load_deflection_constant=c.load_deflection_constant,
    )


def _hamrock_fit(normal_force, ball_radius, conformity, youngs_modulus, poisson_ratio, fit):
    """Shared evaluation of the Hamrock-Dowson / Hamrock-Brewe curve fits."""
    force = np.asarray(normal_force, dtype=float)
    across, along = groove_curvatures(ball_radius, conformity)
    r_small, r_large = 0.5 / along, 0.5 / across  # radii: along the rail, across the groove
    alpha = r_large / r_small
    k_ab, ell_e, ell_f = fit(alpha)  # k_ab = a/b
    r_eff = 1.0 / (1.0 / r_small + 1.0 / r_large)
    e_prime = 2.0 * effective_modulus(youngs_modulus, poisson_ratio)
    a = (6.0 * k_ab**2 * ell_e * force * r_eff / (np.pi * e_prime)) ** (1.0 / 3.0)
    b = (6.0 * ell_e * force * r_eff / (np.pi * k_ab * e_prime)) ** (1.0 / 3.0)
    delta = ell_f * (9.0 / (2.0 * ell_e * r_eff) * (force / (np.pi * k_ab * e_prime)) ** 2) ** (
        1.0 / 3.0
    )
    return a, b, delta


def hamrock_dowson(normal_force, ball_radius, conformity, youngs_modulus=210e9, poisson_ratio=0.28):
    """Semi-axes a, b and approach delta [m] from the Hamrock-Dowson (1981) curve fits."""
    return _hamrock_fit(
        normal_force, ball_radius, conformity, youngs_modulus, poisson_ratio,
        lambda al: (1.0339 * al**0.6360, 1.0003 + 0.5968 / al, 1.5277 + 0.6023 * np.log(al)),
    )


def hamrock_brewe(normal_force, ball_radius, conformity, youngs_modulus=210e9, poisson_ratio=0.28):
    """Semi-axes a, b and approach delta [m] from the Hamrock-Brewe (1983) formulas."""
    q = np.pi / 2 - 1.0
    return _hamrock_fit(
        normal_force, ball_radius, conformity, youngs_modulus, poisson_ratio,
        lambda al: (al ** (2 / np.pi), 1.0 + q / al, np.pi / 2 + q * np.log(al)),
    )
