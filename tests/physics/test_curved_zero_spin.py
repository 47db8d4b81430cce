"""The curved contact surface at zero spin (issue 25): the quadrature converges.

A contact without spin (Omega along its x axis) on the deformed-surface arc slips along the
rail at u_z(x) = v_B - V - (h + sqrt(R_d^2 - x^2)) w: zero on two lines x = +-x_0 (one double
line x = 0 when the contact is stuck, the regime-B state). Reference: an independent NumPy
midpoint rule in 3-D vectors (slip = (v_B - V) z + Omega x r projected on the tangent plane of
the arc, Hertz pressure on the projected ellipse), with its cells aligned to the zero lines,
on a 3000 x 3000 grid (its error: 3e-6 relative or less here, from its difference to a
1500 x 1500 grid; the kernel at 256 nodes agrees with it to 1.4e-6). Tolerances at each assertion.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity.full import deformed_surface_radius, friction_loads

V = 0.01
F = 141.4
BETA = TABLE1.nominal_contact_angle
W = 0.5  # rolling rate about the contact's x axis [v / R]


def _geometry():
    radius = TABLE1.ball_radius
    hc = hertz_constants(radius, TABLE1.conformity, TABLE1.youngs_modulus,
                         TABLE1.poisson_ratio)
    a = hc.semi_major_coefficient * np.cbrt(F) / radius
    b = hc.semi_minor_coefficient * np.cbrt(F) / radius
    rd = deformed_surface_radius(TABLE1) / radius
    h = np.sqrt(1 - a * a) - np.sqrt(rd * rd - a * a)
    return a, b, rd, h


def _state(x0):
    """v_B [v] and Omega [v / R] of a BL contact without spin, zero lines at x = +-x0 a."""
    a, _, rd, h = _geometry()
    vb = (h + np.sqrt(rd * rd - (x0 * a) ** 2)) * W
    omega = W * np.array([np.cos(BETA), -np.sin(BETA), 0.0])  # along x_BL = (cos, -sin)
    return vb, omega


def _kernel(x0, nodes, radial=8):
    vb, omega = _state(x0)
    force = np.array([F, 0.0, 0.0, 0.0])
    _, moment, contact, _ = friction_loads(vb * V, omega * V / TABLE1.ball_radius,
                                           np.full(4, BETA), force, TABLE1, groove_velocity=V,
                                           surface="curved", grid=(nodes, radial))
    return contact[0], moment[2]


def _midpoint_reference(x0, cells):
    """f_z [N] of the BL contact by the 3-D midpoint rule (R = v = 1 inside)."""
    a, b, rd, h = _geometry()
    vb, omega = _state(x0)
    p = np.array([-np.sin(BETA), -np.cos(BETA), 0.0])  # BL: (sx sin, sy cos)
    xa = np.array([-p[1], p[0], 0.0])  # x_i = y_i x z with y_i = -p
    edges = np.unique(np.clip([-1.0, -x0, 0.0, x0, 1.0], -1.0, 1.0))
    pieces = [np.linspace(lo, hi, max(2, int(cells * (hi - lo) / 2) + 1))
              for lo, hi in zip(edges[:-1], edges[1:], strict=False)]
    xs = np.concatenate([0.5 * (e[1:] + e[:-1]) for e in pieces])
    dx = np.concatenate([np.diff(e) for e in pieces])
    zs = (np.arange(cells) + 0.5) / cells * 2.0 - 1.0
    xn, zn = np.meshgrid(xs, zs, indexing="ij")
    weight = np.sqrt(np.clip(1.0 - xn**2 - zn**2, 0.0, None)) * dx[:, None] * (2.0 / cells)
    x = a * xn
    s = np.sqrt(rd * rd - x * x)
    r = ((h + s)[..., None] * p + x[..., None] * xa
         + (b * zn)[..., None] * np.array([0.0, 0.0, 1.0]))
    slip = np.cross(omega, r)
    slip[..., 2] += vb
    normal = (s[..., None] * p - x[..., None] * xa) / rd  # arc normal (outward)
    slip -= np.sum(slip * normal, axis=-1)[..., None] * normal
    speed = np.linalg.norm(slip, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit_z = np.where(speed > 0, slip[..., 2] / speed, 0.0)
    sigma_ab = 1.5 / np.pi * F  # sigma_0 a b (normalised area)
    return -TABLE1.friction_coefficient * sigma_ab * np.sum(weight * unit_z)


@pytest.mark.parametrize("x0", [0.0, 0.1, 0.5])
def test_zero_spin_contact_friction_against_the_midpoint_reference(x0):
    # 1e-5 relative: the reference's own error (about 1e-6) plus the kernel's at 256 nodes.
    ref = _midpoint_reference(x0, 3000)
    fz, _ = _kernel(x0, 256)
    assert_allclose(fz, ref, rtol=1e-5)


def test_stuck_contact_converges_exponentially():
    # The stuck contact (x0 = 0, the regime-B state): the polar rule split at the zero line
    # through the pole. 64 nodes agree with 1024 to 1e-9 relative; by z -> -z symmetry the
    # moment about y from this contact's x-z friction pair vanishes to round-off (old code:
    # 7e-3 N off at 64 nodes, a spurious moment halving with each doubling: first order).
    f64, m64 = _kernel(0.0, 64)
    f1024, m1024 = _kernel(0.0, 1024)
    assert_allclose(f64, f1024, rtol=1e-9)
    assert abs(m64) < 1e-12 and abs(m1024) < 1e-12


@pytest.mark.parametrize("x0", [0.1, 0.5])
def test_zero_spin_does_not_depend_on_the_radial_nodes(x0):
    # Two zero lines: the product rule split at them, which uses no radial rule; the old polar
    # rule about one of them changed by 4 % from 8 to 32 radial nodes (x0 = 0.5: 4.977 N,
    # 5.173 N, 5.190 N at 128). 1e-12 relative; and third-order convergence in the nodes:
    # 128 against 1024 to 2e-5 relative.
    f8, _ = _kernel(x0, 128, radial=8)
    f32, _ = _kernel(x0, 128, radial=32)
    assert_allclose(f8, f32, rtol=1e-12)
    fine, _ = _kernel(x0, 1024)
    assert_allclose(f8, fine, rtol=2e-5)
