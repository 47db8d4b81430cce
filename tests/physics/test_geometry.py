"""Sign conventions of the four contacts, derived from the kinematics (Eqs. 1-9, ERRATA 6, 8)."""

import numpy as np
from numpy.testing import assert_allclose

from tolsim.physics.geometry import (
    FRICTION_SIGN,
    SPIN_SIGN,
    TABLE1,
    ZERO_VELOCITY_SIGN,
    contact_frames,
    paired_forces,
)


def test_lin2018_eq1_eq3_frames():
    # Eq. (1) and the columns of Eq. (3) for BL; the others by the mirror rules of Fig. 2.
    beta = np.deg2rad([30.0, 40.0, 50.0, 60.0])
    pos, x_axis, y_axis = contact_frames(beta)
    b = beta[0]
    assert_allclose(pos[0], [-np.sin(b), -np.cos(b)], atol=1e-15)
    assert_allclose(x_axis[0], [np.cos(b), -np.sin(b)], atol=1e-15)  # Eq. (3), column 1
    assert_allclose(y_axis[0], [np.sin(b), np.cos(b)], atol=1e-15)  # Eq. (3), column 2
    # x = y cross z for every contact (right-handed local frames)
    y3 = np.concatenate([y_axis, np.zeros((4, 1))], axis=1)
    x3 = np.cross(y3, [0.0, 0.0, 1.0])
    assert_allclose(x3[:, :2], x_axis, atol=1e-15)


def test_errata6_zero_velocity_sign_from_contact_motion():
    # ERRATA 6: d(contact point)/d(beta_i) = s_i R x_i, so c_i = s_i R dgamma_i.
    beta = np.full(4, np.pi / 4)
    h = 1e-7
    p_plus, x_axis, _ = contact_frames(beta + h)
    p_minus, _, _ = contact_frames(beta - h)
    derivative = (p_plus - p_minus) / (2 * h)
    s = np.einsum("ij,ij->i", derivative, x_axis)
    assert_allclose(s, ZERO_VELOCITY_SIGN, atol=1e-8)


def test_spin_sign_from_nominal_rolling():
    # Nominal rolling (v_B = v/2, Omega about x) must give zero slip at all four contact
    # centres; then omega_i = Omega . y_i has the signs SPIN_SIGN (Eq. 7, 9).
    R, v, b0 = TABLE1.ball_radius, 0.01, TABLE1.nominal_contact_angle
    omega = np.array([v / (2 * R * np.cos(b0)), 0.0, 0.0])
    pos, _, y_axis = contact_frames(np.full(4, b0))
    groove = np.array([0.0, 0.0, v, v])
    for i in range(4):
        p = np.array([*pos[i] * R, 0.0])
        slip = np.array([0, 0, v / 2]) + np.cross(omega, p) - [0, 0, groove[i]]
        assert_allclose(slip, 0.0, atol=1e-15)
    spin = y_axis @ omega[:2]
    assert_allclose(np.sign(spin), SPIN_SIGN)
    # and the friction sign used in Eq. (17): g = s sgn(omega)
    assert_allclose(FRICTION_SIGN, [-1, -1, 1, 1])


def test_zero_velocity_point_moves_with_sign_s():
    # Perturb the ball motion so that the zero-velocity point of each contact moves; its local
    # x from Eq. (7), c_i = (v_B - v_g - R Omega.x_i)/omega_i, must equal s_i R dgamma_i where
    # dgamma_i is the angular position of the zero-velocity point on the ball circle, found
    # independently by root-finding v_z(angle) = v_g along the circle. Small perturbation
    # (dgamma ~ 1e-4 rad), so tangent plane and circle agree to ~dgamma/2 relative: 1e-3.
    from scipy.optimize import brentq

    R, v, b0 = 5e-3, 0.01, np.pi / 4
    vb = 0.5 * v * 1.00004
    omega = np.array([v / (2 * R * np.cos(b0)) * 0.99998, 3e-5 * v / R])
    pos0, x_axis, y_axis = contact_frames(np.full(4, b0))
    groove = np.array([0.0, 0.0, v, v])
    for i in range(4):
        def vz(beta, i=i):
            p = contact_frames(np.full(4, beta))[0][i] * R
            return vb + omega[0] * p[1] - omega[1] * p[0] - groove[i]

        zero_angle = brentq(vz, b0 - 0.3, b0 + 0.3, xtol=1e-15)
        spin = y_axis[i] @ omega
        c = (vb - groove[i] - R * (x_axis[i] @ omega)) / spin
        assert_allclose(c, ZERO_VELOCITY_SIGN[i] * R * (zero_angle - b0), rtol=1e-3)


def test_lin2018_sec31_paired_forces():
    # Sec. 3.1: F1 = sqrt(2)/2 (Ny - Nx) on BL/TR, F2 = sqrt(2)/2 (Ny + Nx) on BR/TL
    f = paired_forces(-120.0, 200.0)
    assert_allclose(f, np.sqrt(2) / 2 * np.array([320.0, 80.0, 320.0, 80.0]), rtol=1e-14)
