"""Hertz contact of a ball in a straight circular-arc groove."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.integrate import quad

from tolsim.physics.hertz import (
    contact_ellipse,
    hamrock_brewe,
    hamrock_dowson,
    hertz_constants,
)

R, F_CONF, E, NU = 5e-3, 0.54, 210e9, 0.28  # Lin2018 Table 1 (ERRATA 1: E in GPa)


def _independent_hertz(force, ball_radius, conformity, youngs, poisson):
    """Hertz by direct quadrature of the elliptic integrals (no scipy.special), bisection on k."""

    def ell_k(m):
        return quad(lambda t: 1 / np.sqrt(1 - m * np.sin(t) ** 2), 0, np.pi / 2, epsabs=1e-14)[0]

    def ell_e(m):
        return quad(lambda t: np.sqrt(1 - m * np.sin(t) ** 2), 0, np.pi / 2, epsabs=1e-14)[0]

    rg = 2 * conformity * ball_radius
    A = 0.5 * (1 / ball_radius - 1 / rg)
    B = 0.5 / ball_radius
    lo, hi = 1e-4, 1 - 1e-12
    for _ in range(200):  # bisection on k = b/a
        k = 0.5 * (lo + hi)
        m = 1 - k * k
        ratio = (ell_e(m) / k**2 - ell_k(m)) / (ell_k(m) - ell_e(m))
        lo, hi = (k, hi) if ratio > B / A else (lo, k)
    m = 1 - k * k
    estar = youngs / (2 * (1 - poisson**2))
    # Johnson (1985) Sec. 4.2: A = p0 b (K - E) / (E* e^2 a^2), F = 2/3 pi a b p0
    a = (3 * force * (ell_k(m) - ell_e(m)) / (2 * np.pi * estar * m * A)) ** (1 / 3)
    b = k * a
    p0 = 3 * force / (2 * np.pi * a * b)
    delta = p0 * b * ell_k(m) / estar
    return a, b, p0, delta


@pytest.mark.parametrize("force", [10.0, 141.42, 500.0])
def test_table1_against_independent_quadrature(force):
    # Independent computation (quadrature + bisection) for Lin2018 Table 1 inputs; 1e-9 rel.
    a, b, p0, delta = _independent_hertz(force, R, F_CONF, E, NU)
    h = contact_ellipse(force, R, F_CONF, E, NU)
    assert_allclose([h.semi_major, h.semi_minor, h.max_pressure, h.approach],
                    [a, b, p0, delta], rtol=1e-9)
    # load-deflection law F = K delta^1.5 with the independent approach (1.5e-9: 1.5 x the
    # tolerance on delta)
    assert_allclose(h.load_deflection_constant * delta**1.5, force, rtol=1.5e-9)


def test_table1_numbers():
    # Lin2018 Table 1 ball at F = 100 sqrt(2) N (the nominal Ny = 200 N case).
    # ERRATA 4: b/a ~ 0.18 for conformity 0.54.
    c = hertz_constants(R, F_CONF, E, NU)
    assert c.ellipticity == pytest.approx(0.18, abs=0.01)
    h = contact_ellipse(100 * np.sqrt(2), R, F_CONF, E, NU)
    # Values of this implementation, cross-checked above against quadrature and below
    # against Hamrock-Dowson; kept as a regression guard at 1e-6.
    assert_allclose(h.semi_major, 5.5392659e-4, rtol=1e-6)
    assert_allclose(h.semi_minor, 1.0198618e-4, rtol=1e-6)
    assert_allclose(h.approach, 3.3129674e-6, rtol=1e-6)


@pytest.mark.parametrize("conformity", [0.515, 0.52, 0.54, 0.57, 0.6])
def test_hamrock_dowson_published_accuracy(conformity):
    # Hamrock & Dowson (1981) fits: a few per cent on k and F, fractions of a per cent on E(e)
    # for moderate alpha = R_y/R_x; 3 % here for alpha <= 35 (conformity >= 0.515). At
    # conformity 0.505 (alpha ~ 100, the end of their fitted range) a is off by 4.2 %.
    force = np.array([20.0, 200.0, 2000.0])
    h = contact_ellipse(force, R, conformity, E, NU)
    a, b, d = hamrock_dowson(force, R, conformity, E, NU)
    assert_allclose(a, h.semi_major, rtol=0.03)
    assert_allclose(b, h.semi_minor, rtol=0.03)
    assert_allclose(d, h.approach, rtol=0.03)


@pytest.mark.parametrize("conformity", [0.52, 0.54, 0.57])
def test_hamrock_brewe_published_accuracy(conformity):
    # Hamrock & Brewe (1983): simplified formulas with errors of a few per cent (their
    # Table 1 shows < 3 % on k and E, larger on F for high alpha); 5 % here.
    force = 200.0
    h = contact_ellipse(force, R, conformity, E, NU)
    a, b, d = hamrock_brewe(force, R, conformity, E, NU)
    assert_allclose([a, b, d], [h.semi_major, h.semi_minor, h.approach], rtol=0.05)


def _circle(force, radius, youngs, poisson):
    """Hertz circular contact (Johnson 1985, Sec. 4.2(a), solids of revolution):
    a = (3 P R / (4 E*))^(1/3), delta = a^2 / R, p0 = 3 P / (2 pi a^2), hence
    P = (4/3) E* R^(1/2) delta^(3/2); 1/E* = (1 - nu_1^2)/E_1 + (1 - nu_2^2)/E_2, i.e.
    2 (1 - nu^2) / E for two equal materials. Written out here, independently of
    tolsim.physics.hertz."""
    estar = youngs / (2.0 * (1.0 - poisson**2))
    a = (3.0 * force * radius / (4.0 * estar)) ** (1.0 / 3.0)
    return a, a**2 / radius, 3.0 * force / (2.0 * np.pi * a**2), 4.0 / 3.0 * estar * radius**0.5


def test_circle_limit_ball_on_flat():
    # Conformity -> infinity: the groove becomes a flat plate, A = B = 1/(2 R_B), and the
    # contact is Hertz's sphere on a flat with R = R_B (hertz_constants takes its k = 1 branch,
    # (K - E)/e^2 -> pi/4). a = b, delta, p0 and the load-deflection constant K must be the
    # circle formulas; tolerance 1e-12 relative (round-off).
    force = np.array([1.0, 50.0, 700.0])
    h = contact_ellipse(force, R, 1e12, E, NU)
    a, delta, p0, k = _circle(force, R, E, NU)
    assert hertz_constants(R, 1e12, E, NU).ellipticity == 1.0
    assert_allclose(h.semi_major, a, rtol=1e-12)
    assert_allclose(h.semi_minor, a, rtol=1e-12)
    assert_allclose(h.approach, delta, rtol=1e-12)
    assert_allclose(h.max_pressure, p0, rtol=1e-12)
    assert_allclose(h.load_deflection_constant, k, rtol=1e-12)


@pytest.mark.parametrize("conformity", [2.0, 5.0, 10.0, 20.0, 30.0])
def test_near_circle_equivalent_radius(conformity):
    # Approach to the circle through the general (elliptic) branch. Greenwood, "Formulas for
    # moderately elliptical Hertzian contacts", J. Tribol. 107 (1985) 501, and Johnson (1985)
    # Sec. 4.2(b): for small ellipticity the circle formulas hold with the equivalent radius
    # R_e = (R' R'')^(1/2) for the contact size sqrt(a b), the approach and the pressure, and
    # a/b ~ (B/A)^(2/3). Here R' = 1/(2A) across the groove, R'' = R_B along the rail. The
    # errors of those approximations are second order in eta = B/A - 1 (first-order terms
    # cancel: a and b move by +-eta/3 each), so we require |error| <= 0.05 eta^2 (measured
    # 0.010-0.027 eta^2, the largest for p0; a/b: 1e-3 eta^2); eta = 0.33 (f = 2) down to
    # 0.017 (f = 30). A first-order slip (e.g. using R' or R'' alone) would be ~eta.
    # Not tested above f = 30: for 36 < f < 5e11 (1e-12 < B/A - 1 < 0.014) hertz_constants
    # raises (brentq bracket: _curvature_ratio at k = 1 - 1e-14 is 1.014, cancellation).
    force = np.array([1.0, 50.0, 700.0])
    across = 0.5 * (1.0 / R - 1.0 / (2.0 * conformity * R))
    along = 0.5 / R
    eta = along / across - 1.0
    r_eff = np.sqrt(0.5 / across * R)
    a, delta, p0, k = _circle(force, r_eff, E, NU)
    h = contact_ellipse(force, R, conformity, E, NU)
    assert_allclose(np.sqrt(h.semi_major * h.semi_minor), a, rtol=0.05 * eta**2)
    assert_allclose(h.approach, delta, rtol=0.05 * eta**2)
    assert_allclose(h.max_pressure, p0, rtol=0.05 * eta**2)
    assert_allclose(h.load_deflection_constant, k, rtol=0.05 * eta**2)
    assert_allclose(h.semi_major / h.semi_minor, (1.0 + eta) ** (2 / 3), rtol=0.05 * eta**2)
    # and the semi-axes straddle the equivalent circle, a > sqrt(ab) > b
    assert np.all(h.semi_major > a) and np.all(h.semi_minor < a)


def test_bad_inputs():
    with pytest.raises(ValueError, match="conformity"):
        hertz_constants(R, 0.5, E, NU)
    with pytest.raises(ValueError, match="normal_force"):
        contact_ellipse(-1.0, R, F_CONF, E, NU)
