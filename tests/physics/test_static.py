"""Tests of the static contact model (tolsim issue 3), :mod:`tolsim.physics.static`.

Reference values carry their source; every tolerance is explicit. The numbers quoted in
comments were measured with this code (Table 1 bearing) and are repeated in the report.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from scipy.optimize import root

from tolsim.physics.geometry import TABLE1, Bearing, paired_forces
from tolsim.physics.hertz import contact_ellipse, hertz_constants
from tolsim.physics.static import (
    SENSITIVITY_COLUMNS,
    SENSITIVITY_ROWS,
    GrooveErrors,
    linearised_static,
    solve_static,
    solve_static_displacement,
    static_sensitivity,
)
from tolsim.physics.velocity.analytic import analytic

B0 = TABLE1.nominal_contact_angle
R_B = TABLE1.ball_radius
D = TABLE1.groove_radius - TABLE1.ball_radius  # (f - 1/2) 2 R_B = 0.4 mm
K = hertz_constants(R_B, TABLE1.conformity, TABLE1.youngs_modulus,
                    TABLE1.poisson_ratio).load_deflection_constant
SX = np.array([-1.0, 1.0, 1.0, -1.0])
SY = np.array([-1.0, -1.0, 1.0, 1.0])
MIRROR = [1, 0, 3, 2]  # x -> -x swaps BL <-> BR and TR <-> TL


# --------------------------------------------------------------------------------------------
# Plain-NumPy twin of the geometry (independent of the kernel code)
# --------------------------------------------------------------------------------------------
def twin_arc_centres(e, g=(0.0, 0.0), bearing=TABLE1):
    """Arc centres (4, 2) of one ball's flanks from a dict of single-ball errors."""
    b0 = bearing.nominal_contact_angle
    d = bearing.groove_radius - bearing.ball_radius
    n = np.stack([SX * np.sin(b0), SY * np.cos(b0)], axis=1)
    t = np.stack([SX * np.cos(b0), -SY * np.sin(b0)], axis=1)  # dn/dbeta
    c = -(d - e["en"])[:, None] * n - e["et"][:, None] * t
    out = np.empty((4, 2))
    for rows, th, off in (((0, 1), e["rb"], e["ob"]), ((2, 3), e["rt"], e["ot"])):
        rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        for i in rows:
            out[i] = rot @ c[i] + off
    out[2:] += np.asarray(g)
    return out


def twin_forces(p, cen, oversize, bearing=TABLE1):
    """u_i, approaches and Hertz forces at ball centre p."""
    d = bearing.groove_radius - bearing.ball_radius
    k = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                        bearing.poisson_ratio).load_deflection_constant
    w = p[None, :] - cen
    dist = np.linalg.norm(w, axis=1)
    u = w / dist[:, None]
    delta = dist - d + oversize / 2
    return u, delta, k * np.clip(delta, 0, None) ** 1.5


def random_errors(rng, n, scale=1.0):
    """Errors of the size of a precision guide: um offsets, tenths of a degree."""
    return dict(
        en=rng.normal(0, 1.5e-6 * scale, (n, 4)), et=rng.normal(0, 1.5e-6 * scale, (n, 4)),
        rb=rng.normal(0, np.deg2rad(0.5) * scale, n), rt=rng.normal(0, np.deg2rad(0.5) * scale, n),
        ob=rng.normal(0, 2e-6 * scale, (n, 2)), ot=rng.normal(0, 2e-6 * scale, (n, 2)),
        dd=rng.normal(0, 1e-6 * scale, n),
    )


def to_groove_errors(e):
    return GrooveErrors(arc_centre_offset_normal=e["en"], arc_centre_offset_tangential=e["et"],
                        bottom_rotation=e["rb"], top_rotation=e["rt"], bottom_offset=e["ob"],
                        top_offset=e["ot"], ball_oversize=e["dd"])


def ball(e, j):
    return {k: np.asarray(v)[j] for k, v in e.items()}


def unit_vectors(beta):
    return np.stack([SX * np.sin(beta), SY * np.cos(beta)], axis=-1)


# --------------------------------------------------------------------------------------------
# Nominal states
# --------------------------------------------------------------------------------------------
def test_perfect_bearing_zero_load_is_nominal():
    # No errors, no load: the geometric four-point position, beta_i = beta_0, F_i = 0.
    s = solve_static(0.0, 0.0)
    assert s.converged and s.iterations == 0
    assert_allclose(s.contact_angle, B0, atol=1e-15)
    assert_allclose(s.normal_force, 0.0, atol=0)
    assert_allclose(s.ball_displacement, 0.0, atol=1e-18)


def test_preload_no_errors_zero_load_equal_forces():
    # Top groove held at its nominal place, ball 2 um oversize (preload): by symmetry
    # beta_i = beta_0 and F_i = K (dD/2)^1.5 at every flank (Hertz, [Johnson1985]).
    dd = 2e-6
    s = solve_static_displacement([0.0, 0.0], GrooveErrors(ball_oversize=dd))
    assert s.converged and s.four_point
    assert_allclose(s.contact_angle, B0, atol=1e-14)
    assert_allclose(s.normal_force, K * (dd / 2) ** 1.5, rtol=1e-12)
    # the load that holds the top groove: N_y = 2 F cos(beta_0), N_x = 0
    assert_allclose(s.groove_load, [0.0, 2 * K * (dd / 2) ** 1.5 * np.cos(B0)],
                    rtol=1e-12, atol=1e-12)


def test_oversize_with_free_top_groove_raises_contact_angles():
    # Load control, no load, oversize dD: all four flanks touch with |P - C_i| = d - dD/2.
    # By symmetry the ball rises by h = d cos b0 - sqrt((d - dD/2)^2 - d^2 sin^2 b0) and
    # cos(beta) = (d cos b0 - h)/(d - dD/2) (closed form from the circle geometry).
    dd = 4e-6
    ell = D - dd / 2
    h = D * np.cos(B0) - np.sqrt(ell**2 - (D * np.sin(B0)) ** 2)
    beta = np.arccos((D * np.cos(B0) - h) / ell)
    s = solve_static(0.0, 0.0, GrooveErrors(ball_oversize=dd), rigid=True)
    assert_allclose(s.contact_angle, beta, atol=1e-13)
    assert_allclose(s.ball_displacement, [0.0, h], atol=1e-15)
    assert_allclose(s.groove_displacement, [0.0, 2 * h], atol=1e-15)
    assert np.rad2deg(beta - B0) > 0.25  # 0.286 deg for 4 um: oversize raises the angles


# --------------------------------------------------------------------------------------------
# Sign conventions of the errors ([Lin2018] Fig. 6, Table 2)
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("theta_deg", [-3.0, -0.5, 0.7, 2.0])
@pytest.mark.parametrize("rho", [-0.6, 0.0, 0.6])
def test_lin2018_fig6_bottom_rotation_rigid(theta_deg, rho):
    # [Lin2018] Sec. 3.1 / Fig. 6: rotating the bottom groove by theta gives
    # dbeta_BL = -theta, dbeta_BR = +theta, dbeta_TR = dbeta_TL = 0 (rigid grooves).
    th = np.deg2rad(theta_deg)
    s = solve_static(rho * 200.0, 200.0, GrooveErrors(bottom_rotation=th), rigid=True)
    assert s.converged and s.four_point
    assert_allclose(s.contact_angle_deviation, [-th, th, 0.0, 0.0], atol=1e-13)
    assert_allclose(s.approach, 0.0, atol=1e-18)


@pytest.mark.parametrize("theta_deg", [-1.0, 2.0])
def test_top_rotation_and_case_b_rigid(theta_deg):
    # Issue 3: a positive top rotation gives dbeta_TR = -theta, dbeta_TL = +theta, so equal
    # top and bottom rotations are [Lin2018] Table 2 case (b).
    th = np.deg2rad(theta_deg)
    s = solve_static(0.0, 200.0, GrooveErrors(top_rotation=th), rigid=True)
    assert_allclose(s.contact_angle_deviation, [0.0, 0.0, -th, th], atol=1e-13)
    s = solve_static(-120.0, 200.0, GrooveErrors(top_rotation=th, bottom_rotation=th),
                     rigid=True)
    assert_allclose(s.contact_angle_deviation, [-th, th, -th, th], atol=1e-13)


def test_tangential_arc_offset_rigid_is_e_over_d():
    # Issue 3: dbeta ~ e_perp / ((f - 1/2) 2 R_B), 0.1432 deg per um for Table 1. Rigid,
    # exactly atan(e/d) for the offset flank (the ball stays at the centre to 2nd order).
    e = 1e-6
    assert_allclose(np.rad2deg(1e-6 / D), 0.1432, atol=5e-5)
    for i in range(4):
        et = np.zeros(4)
        et[i] = e
        s = solve_static(0.0, 200.0, GrooveErrors(arc_centre_offset_tangential=et), rigid=True)
        expected = np.zeros(4)
        expected[i] = np.arctan(e / D)
        # second order: |C_i| grows to sqrt(d^2 + e^2), the ball moves and the other flank
        # of the groove turns by (e/d)^2/2 = 3.1e-6 rad (measured), 1.25e-3 of e/d
        assert_allclose(s.contact_angle_deviation, expected, atol=(e / D) ** 2)


def test_normal_arc_offset_opens_clearance():
    # Issue 3 API: + along the contact line opens clearance: the approach drops by e_n.
    en = np.array([1e-6, 0.0, 0.0, 0.0])
    s = solve_static_displacement([0.0, 0.0], GrooveErrors(arc_centre_offset_normal=en,
                                                            ball_oversize=4e-6))
    s0 = solve_static_displacement([0.0, 0.0], GrooveErrors(ball_oversize=4e-6))
    assert s.normal_force[0] < s0.normal_force[0]
    # rigid, top groove free: BL moves out by 1 um along n_BL, the ball follows it down the BR
    # flank: dbeta_BR = -e_n/d to first order (0.1432 deg/um), BL keeps its angle.
    s = solve_static(0.0, 200.0, GrooveErrors(arc_centre_offset_normal=en), rigid=True)
    # (to second order: (e/d)^2 = 6e-6 rad; BL measured 3.1e-6 rad)
    assert_allclose(s.contact_angle_deviation[:2], [0.0, -1e-6 / D], atol=(1e-6 / D) ** 2)


# --------------------------------------------------------------------------------------------
# Equilibrium, Hertz law, symmetry
# --------------------------------------------------------------------------------------------
def _random_state(seed, n, scale=1.0):
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    ny = rng.uniform(20.0, 500.0, n)
    nx = rng.uniform(-0.8, 0.8, n) * ny
    return nx, ny, random_errors(rng, n, scale)


@pytest.mark.parametrize("rigid, vectorised", [(False, True), (False, False), (True, True)])
def test_force_and_moment_balance_random(rigid, vectorised):
    # Seeded random errors and loads: ball and top groove in force balance to round-off
    # (1e-12 of the largest force), all converged; the line of action of every force passes
    # through the ball centre (zero moment) and starts at the flank's arc centre.
    nx, ny, e = _random_state(11, 2000)
    s = solve_static(nx, ny, to_groove_errors(e), rigid=rigid, vectorised=vectorised)
    assert s.converged.all()
    u = unit_vectors(s.contact_angle)  # (n, 4, 2)
    f = s.normal_force[..., None] * u
    load = np.stack([nx, -ny], axis=1)
    scale = np.maximum(ny, s.normal_force.max(axis=1))[:, None]
    assert np.all(np.abs(f.sum(axis=1)) <= 1e-12 * scale)  # ball: -sum F_i u_i = 0
    assert np.all(np.abs(f[:, 2:].sum(axis=1) + load) <= 1e-12 * scale)  # top groove
    assert np.all(s.residual <= 1e-12 * scale[:, 0])
    for j in range(0, 2000, 97):
        cen = twin_arc_centres(ball(e, j), s.groove_displacement[j] + 0.0)
        w = s.ball_displacement[j][None, :] - cen
        cross = w[:, 0] * u[j, :, 1] - w[:, 1] * u[j, :, 0]  # moment arm x direction
        assert_allclose(cross / np.linalg.norm(w, axis=1), 0.0, atol=1e-12)
        assert np.all(np.sum(w * u[j], axis=1) > 0)  # u points from C_i through the centre


def test_forces_obey_hertz_law():
    # F = K delta^1.5 with K from hertz.hertz_constants, and the approach agrees with
    # hertz.contact_ellipse(F).approach ([Johnson1985] Sec. 4.2).
    nx, ny, e = _random_state(12, 500)
    s = solve_static(nx, ny, to_groove_errors(e))
    assert_allclose(s.normal_force, K * np.clip(s.approach, 0, None) ** 1.5, rtol=1e-13,
                    atol=0)
    loaded = s.normal_force > 0
    h = contact_ellipse(s.normal_force[loaded], R_B, TABLE1.conformity)
    assert_allclose(h.approach, s.approach[loaded], rtol=1e-12)
    # and the approach is |P - C_i| - d + dD/2 of the NumPy twin geometry
    for j in range(0, 500, 37):
        cen = twin_arc_centres(ball(e, j), s.groove_displacement[j])
        _, delta, force = twin_forces(s.ball_displacement[j], cen, e["dd"][j])
        assert_allclose(s.approach[j], delta, atol=1e-17)
        assert_allclose(s.normal_force[j], force, rtol=1e-10, atol=1e-9)


def mirror(e):
    return dict(en=e["en"][..., MIRROR], et=e["et"][..., MIRROR], rb=-e["rb"], rt=-e["rt"],
                ob=e["ob"] * [-1.0, 1.0], ot=e["ot"] * [-1.0, 1.0], dd=e["dd"])


@settings(max_examples=60, deadline=None)
@given(rho=st.floats(-0.9, 0.9), ny=st.floats(1.0, 800.0),
       seed=st.integers(0, 2**32 - 1), scale=st.floats(0.0, 2.0), rigid=st.booleans())
def test_mirror_symmetry(rho, ny, seed, scale, rigid):
    # x -> -x: N_x -> -N_x with mirrored errors mirrors the solution (BL<->BR, TL<->TR).
    e = random_errors(np.random.default_rng(np.random.SeedSequence(seed)), 1, scale)
    a = solve_static(rho * ny, ny, to_groove_errors(e), rigid=rigid)
    b = solve_static(-rho * ny, ny, to_groove_errors(mirror(e)), rigid=rigid)
    assert a.converged.all() and b.converged.all()
    assert_allclose(b.contact_angle, a.contact_angle[..., MIRROR], atol=1e-12)
    assert_allclose(b.normal_force, a.normal_force[..., MIRROR], rtol=1e-9, atol=1e-9 * ny)
    assert_allclose(b.ball_displacement, a.ball_displacement * [-1, 1], atol=1e-15)
    assert_allclose(b.groove_displacement, a.groove_displacement * [-1, 1], atol=1e-15)


def test_loads_without_errors_paired_forces_and_elastic_angle_effect(capsys):
    # [Lin2018] Sec. 3.1: F_BL ~ F_TR ~ F_1 = sqrt(2)/2 (N_y - N_x), F_BR ~ F_TL ~ F_2.
    # Without errors the top problem is the bottom one turned by 180 deg, so the diagonal
    # pairs are exactly equal; the difference from F_1, F_2 is the elastic change of the
    # contact angles. Measured at N_y = 200 N (Table 1): at rho = -0.6, dbeta_BL = -0.248 deg,
    # dbeta_BR = -0.645 deg and F_1 is 0.27 % high, F_2 1.7 % low; at rho = 0, -0.466 deg and
    # +0.83 % on both.
    rho = np.linspace(-0.6, 0.6, 7)
    ny = 200.0
    s = solve_static(rho * ny, ny)
    f12 = paired_forces(rho * ny, ny)
    assert_allclose(s.normal_force[:, 2], s.normal_force[:, 0], rtol=1e-12)
    assert_allclose(s.normal_force[:, 3], s.normal_force[:, 1], rtol=1e-12)
    dev = s.normal_force / f12 - 1
    with capsys.disabled():
        print("\n  rho   dbeta_BL  dbeta_BR [deg]   F_BL/F_1-1  F_BR/F_2-1 [%]")
        for r, db, d in zip(rho, np.rad2deg(s.contact_angle_deviation), dev, strict=True):
            print(f"  {r:+.1f}  {db[0]:+8.4f}  {db[1]:+8.4f}        {100 * d[0]:+7.3f}"
                  f"     {100 * d[1]:+7.3f}")
    # the deviation is the statics of the loaded angles (2x2 solve with beta_BL, beta_BR)
    a, b = s.contact_angle[:, 0], s.contact_angle[:, 1]
    nx = rho * ny
    assert_allclose(s.normal_force[:, 0], (ny * np.sin(b) - nx * np.cos(b)) / np.sin(a + b),
                    rtol=1e-11)
    assert_allclose(s.normal_force[:, 1], (nx * np.cos(a) + ny * np.sin(a)) / np.sin(a + b),
                    rtol=1e-11)
    # measured size of the elastic-angle effect (max 1.7 % at |rho| = 0.6, N_y = 200 N)
    assert np.max(np.abs(dev)) < 0.02
    assert np.max(np.abs(dev)) > 0.01  # it is not negligible either
    assert np.max(np.abs(np.rad2deg(s.contact_angle_deviation))) < 0.7


def test_elastic_angle_shift_small_load_limit():
    # Pure N_y, no errors: the ball sinks by s = delta / cos(b0) into the bottom groove and
    # the contact line turns by -s sin(b0) / d, i.e. dbeta = -delta tan(b0) / d to first order
    # (GrooveErrors Notes). The ratio tends to 1 as the load falls; measured
    # 1 - 3.6e-4 at 1 N, 1 - 1.7e-3 at 10 N, 1 - 1.2e-2 at 200 N (-0.466 deg).
    for ny, rel in ((1.0, 1e-3), (10.0, 3e-3), (200.0, 2e-2)):
        s = solve_static(0.0, ny)
        first_order = -s.approach * np.tan(B0) / D
        assert_allclose(s.contact_angle_deviation, first_order, rtol=rel)


def test_lin2018_table2_case_a_loaded_angles(capsys):
    # [Lin2018] Table 2, case (a): theta = 2 deg bottom rotation, rho = -0.6 (ball 1) and
    # +0.6 (ball 2), N_y = 200 N, no preload, elastic (Hertz) contact. Leblanc's comprehensive
    # model: +0.85 % / -0.77 %; Eq. (26) with paired forces: +/-0.754 % (ERRATA 2).
    # Measured here with the loaded angles and forces into `analytic`: +0.802 % / -0.730 %.
    th = np.deg2rad(2.0)
    rho = np.array([-0.6, 0.6])
    s = solve_static(rho * 200.0, 200.0, GrooveErrors(bottom_rotation=th))
    assert s.converged.all() and s.four_point.all()
    eps = analytic(s.contact_angle_deviation, s.normal_force).velocity_deviation
    eps_paired = analytic([-th, th, 0, 0], paired_forces(rho * 200.0, 200.0)).velocity_deviation
    with capsys.disabled():
        print("\n  Table 2 case (a), loaded static solution (Table 1 bearing)")
        print("  ball rho    dbeta BL BR TR TL [deg]              F BL BR TR TL [N]"
              "                 eps [%]")
        for j in range(2):
            db = np.rad2deg(s.contact_angle_deviation[j])
            print(f"  {j + 1}  {rho[j]:+.1f}  " + " ".join(f"{v:+7.3f}" for v in db) + "   "
                  + " ".join(f"{v:7.2f}" for v in s.normal_force[j])
                  + f"   {100 * eps[j]:+.3f}")
    assert_allclose(100 * eps_paired, [0.754, -0.754], atol=5e-4)  # Eq. (26), ERRATA 2
    # Same sign of asymmetry as Leblanc (|eps_1| > |eps_2|), each within 0.06 percentage
    # points of Leblanc's values (the measured gaps are 0.048 and 0.040).
    assert eps[0] + eps[1] > 0.0005
    assert_allclose(100 * eps, [0.85, -0.77], atol=0.06)


# --------------------------------------------------------------------------------------------
# The Numba kernel against a scipy.optimize.root twin
# --------------------------------------------------------------------------------------------
def twin_load_control(nx, ny, e, start, bearing=TABLE1):
    """scipy.optimize.root on the full 4-unknown system (ball + top-groove equilibrium)."""
    k = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                        bearing.poisson_ratio).load_deflection_constant
    load = np.array([nx, -ny])
    unit = 1e-6  # unknowns in micrometres

    def equations(z):
        p, g = z[:2] * unit, z[2:] * unit
        cen = twin_arc_centres(e, g, bearing)
        u, _, f = twin_forces(p, cen, e["dd"], bearing)
        ball_eq = -(f[:, None] * u).sum(axis=0)
        groove_eq = (f[2:, None] * u[2:]).sum(axis=0) + load
        return np.concatenate([ball_eq, groove_eq]) / ny

    # start: the rigid (zero-approach) positions, moved down by the paired elastic approach
    # delta0 of a 45-deg contact so that the flanks are compressed (the elastic problem has
    # one solution, so the start only has to be close enough for Levenberg-Marquardt)
    c0 = np.cos(bearing.nominal_contact_angle)
    delta0 = (ny / (2 * c0) / k) ** (2 / 3)
    z0 = np.concatenate([start[0] - [0.0, delta0 / c0], start[1] - [0.0, 2 * delta0 / c0]])
    sol = root(equations, z0 / unit, method="lm", options={"xtol": 1e-15, "ftol": 1e-15})
    p, g = sol.x[:2] * unit, sol.x[2:] * unit
    cen = twin_arc_centres(e, g, bearing)
    u, delta, f = twin_forces(p, cen, e["dd"], bearing)
    beta = np.arctan2(SX * u[:, 0], SY * u[:, 1])
    return sol.success, beta, f, delta, p, g


@pytest.mark.parametrize("vectorised", [True, False])
def test_kernel_matches_scipy_root_twin(vectorised):
    nx, ny, e = _random_state(13, 40)
    s = solve_static(nx, ny, to_groove_errors(e), vectorised=vectorised)
    r = solve_static(nx, ny, to_groove_errors(e), rigid=True)
    for j in range(40):
        ok, beta, f, delta, p, g = twin_load_control(
            nx[j], ny[j], ball(e, j), (r.ball_displacement[j], r.groove_displacement[j]))
        assert ok
        assert_allclose(s.contact_angle[j], beta, atol=1e-9)
        assert_allclose(s.normal_force[j], f, rtol=1e-7, atol=1e-7 * ny[j])
        assert_allclose(s.approach[j], delta, atol=1e-13)
        assert_allclose(s.ball_displacement[j], p, atol=1e-13)
        assert_allclose(s.groove_displacement[j], g, atol=1e-13)


def test_displacement_kernel_matches_scipy_root_twin():
    rng = np.random.default_rng(np.random.SeedSequence(14))
    n = 30
    e = random_errors(rng, n)
    e["dd"] = rng.uniform(1e-6, 6e-6, n)  # preloaded
    disp = rng.normal(0, 0.5e-6, (n, 2))
    s = solve_static_displacement(disp, to_groove_errors(e))
    assert s.converged.all()
    for j in range(n):
        ej = ball(e, j)
        cen = twin_arc_centres(ej, disp[j])

        def eq(z, cen=cen, ej=ej):
            u, _, f = twin_forces(z * 1e-6, cen, ej["dd"])
            return -(f[:, None] * u).sum(axis=0)

        # start: the bottom groove's offset, 1 um lower (bottom flanks compressed)
        sol = root(eq, ej["ob"] / 1e-6 - [0.0, 1.0], method="lm",
                   options={"xtol": 1e-15, "ftol": 1e-15})
        assert sol.success
        u, delta, f = twin_forces(sol.x * 1e-6, cen, ej["dd"])
        if s.contact_count[j] == 0:  # a loose ball (2 of 30 here): any gap-free spot will do
            assert_allclose(f, 0.0, atol=0)
            continue
        assert_allclose(s.ball_displacement[j], sol.x * 1e-6, atol=1e-13)
        assert_allclose(s.normal_force[j], f, rtol=1e-7, atol=1e-6)
        assert_allclose(s.contact_angle[j], np.arctan2(SX * u[:, 0], SY * u[:, 1]), atol=1e-9)
        # groove_load is what holds the top groove: (N_x, -N_y) = -sum_top F_i u_i
        assert_allclose(s.groove_load[j] * [1, -1], -(f[2:, None] * u[2:]).sum(axis=0),
                        rtol=1e-7, atol=1e-6)


def test_newton_iterations_and_convergence():
    # Start from the rigid-groove solution: 3 Newton steps per groove for every ball at
    # tol = 1e-12 (measured: mean 3.0, max 3 over 20 000 balls).
    nx, ny, e = _random_state(15, 20000)
    s = solve_static(nx, ny, to_groove_errors(e))
    assert s.converged.all()
    assert s.iterations.max() <= 5
    assert 2.0 <= s.iterations.mean() <= 4.0


# --------------------------------------------------------------------------------------------
# Vectorised fast path (``_lane_*`` kernels) against the scalar solver
# --------------------------------------------------------------------------------------------
def _lane_tile(nx, ny, e, bearing=TABLE1, tol=1e-12):
    """Run the lane kernels on one tile; (verified per lane, work array)."""
    import tolsim.physics.static._kernels as lanes
    from tolsim.physics import static as st_

    fields = to_groove_errors(e)
    m = len(nx)
    assert m <= lanes._TILE
    items = [("side_load", nx, 0), ("normal_load", ny, 0)] + st_.error_items(fields, bearing)
    (lx, ly, e_n, e_t, rb, rt, ob, ot, dd), _ = st_.prepare_inputs(items, bearing)
    d = bearing.groove_radius - bearing.ball_radius
    s0, c0 = np.sin(bearing.nominal_contact_angle), np.cos(bearing.nominal_contact_angle)
    w = np.empty((lanes._ROWS, lanes._TILE))
    lanes._lane_gather(0, m, lx[:, 0], ly[:, 0], e_n, e_t, rb[:, 0], rt[:, 0], ob, ot,
                       dd[:, 0], K, w)
    for groove in range(2):
        lanes._lane_start(m, groove, s0, c0, d, K, w)
        lanes._lane_newton(m, groove, s0, c0, d, K, w)
    lanes._lane_outputs(m, s0, c0, d, K, w)
    outs = (np.empty((m, 4)), np.empty((m, 4)), np.empty((m, 4)), np.empty((m, 2)),
            np.empty((m, 2)), np.empty(m, bool), np.empty(m, np.int64), np.empty(m, np.int64),
            np.empty(m))
    ok = np.array([lanes._lane_store(0, j, tol, K * 1e-9**1.5, w, *outs) for j in range(m)])
    return ok, w


def test_lane_newton_reaches_round_off_in_three_steps():
    # The fast path's claim: from the elastic start, three full Newton steps bring every
    # tolerance-sized four-point ball to a force imbalance of 2e-12 of its largest force
    # (measured: all 64 of each tile verify; the scalar solver is not needed).
    for seed in range(5):
        nx, ny, e = _random_state(100 + seed, 64)
        ok, _ = _lane_tile(nx, ny, e)
        assert ok.all()


def test_lane_path_hands_hard_balls_to_the_scalar_solver():
    # Outside the fast path's assumptions the lane is rejected (verified False): a groove
    # rotation beyond the series range (0.25 rad > 0.2), two-point contact (rho = 0.98: a
    # rigid flank force < 0), no load (no force scale for the elastic start).
    nx, ny, e = _random_state(7, 4)
    e["rb"][0] = 0.25
    nx[1] = 0.98 * ny[1]
    nx[2] = ny[2] = 0.0
    ok, _ = _lane_tile(nx, ny, e)
    assert_allclose(ok, [False, False, False, True])
    # and the public solver still solves them, with the scalar Newton
    s = solve_static(nx, ny, to_groove_errors(e))
    assert s.converged.all() and s.contact_count[1] < 4
    assert_allclose(s.normal_force[2], 0.0, atol=1e-9)


@pytest.mark.parametrize("scale", [1.0, 5.0])
def test_vectorised_and_scalar_agree(scale):
    # Same equilibrium from both paths, within what the force tolerance (imbalance <= 2e-12
    # of the largest force) leaves open: forces within 4e-12 N_y; angles within 5e-15 rad
    # where every flank carries >= 10 % of the largest force (measured 2.6e-15), within
    # 1e-13 rad near two-point contact, where a flank with 1 % of the load makes the angle
    # ill-conditioned (measured 5.7e-14); identical flags. scale = 5 adds balls that need
    # the scalar path (rotations beyond 0.2 rad, loss of contact).
    nx, ny, e = _random_state(21, 5000, scale)
    nx[:50] = 0.97 * ny[:50]  # near two-point contact
    fast = solve_static(nx, ny, to_groove_errors(e))
    slow = solve_static(nx, ny, to_groove_errors(e), vectorised=False)
    f = slow.normal_force
    well = f.min(axis=1) >= 0.1 * f.max(axis=1)
    assert well.mean() > 0.9
    assert_allclose(fast.contact_angle_deviation[well], slow.contact_angle_deviation[well],
                    rtol=0, atol=5e-15)
    assert_allclose(fast.contact_angle_deviation, slow.contact_angle_deviation, rtol=0,
                    atol=1e-13)
    assert np.all(np.abs(fast.normal_force - f) <= 4e-12 * ny[:, None])
    assert_allclose(fast.ball_displacement, slow.ball_displacement, rtol=0, atol=1e-16)
    assert (fast.converged == slow.converged).all()
    assert (fast.contact_count == slow.contact_count).all()


def test_vectorised_result_does_not_depend_on_the_tile():
    # A ball's result is bit-identical wherever it sits in a tile of 64 lanes (full tiles,
    # the partial last tile, a single ball): the loops over lanes compute lane by lane.
    nx, ny, e = _random_state(22, 300)
    whole = solve_static(nx, ny, to_groove_errors(e))
    for lo, hi in ((37, 300), (1, 66), (250, 251)):
        part = solve_static(nx[lo:hi], ny[lo:hi],
                            to_groove_errors({k: v[lo:hi] for k, v in e.items()}))
        for name in ("contact_angle_deviation", "normal_force", "approach",
                     "ball_displacement", "groove_displacement", "residual"):
            assert np.array_equal(getattr(part, name), getattr(whole, name)[lo:hi]), name


def test_rigid_is_the_stiff_limit():
    # rigid=True is the K -> infinity limit: with E 1e6 times larger the elastic approaches
    # shrink 1e-4 times (delta ~ E^(-2/3)) and the elastic angles approach the rigid ones.
    nx, ny, e = _random_state(16, 200)
    stiff = Bearing(youngs_modulus=TABLE1.youngs_modulus * 1e6)
    r = solve_static(nx, ny, to_groove_errors(e), rigid=True)
    s = solve_static(nx, ny, to_groove_errors(e), stiff)
    s0 = solve_static(nx, ny, to_groove_errors(e))
    assert r.converged.all() and s.converged.all()
    gap0 = np.max(np.abs(s0.contact_angle - r.contact_angle))  # ~1e-2 rad at steel stiffness
    gap = np.max(np.abs(s.contact_angle - r.contact_angle))
    assert gap < 2e-4 * gap0
    assert_allclose(s.normal_force, r.normal_force, rtol=1e-3, atol=1e-3)


# --------------------------------------------------------------------------------------------
# Loss of contact
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("rigid", [False, True])
def test_two_point_contact_under_large_side_load(rigid):
    # N_x = 1.5 N_y lies outside both grooves' force cones: only BR and TL carry the load;
    # each then points along the load, beta = atan(1.5) = 56.3 deg, F = |N|.
    ny = 100.0
    s = solve_static(1.5 * ny, ny, rigid=rigid)
    assert s.converged and not s.four_point and s.contact_count == 2
    assert_allclose(s.normal_force[[0, 2]], 0.0, atol=0)
    assert_allclose(s.normal_force[[1, 3]], np.hypot(1.5, 1.0) * ny, rtol=1e-11)
    assert_allclose(s.contact_angle[[1, 3]], np.arctan(1.5), atol=1e-11)
    assert np.all(s.approach[[0, 2]] < 0)  # gaps
    assert s.residual <= 1e-11 * ny


@pytest.mark.parametrize("rigid", [False, True])
def test_three_point_contact(rigid):
    # Bottom turned by -2 deg (beta_BR = 43 deg) with N_x = 0.97 N_y (44.1 deg from vertical):
    # the load leaves the bottom cone, BL lifts off, the top groove keeps both flanks.
    s = solve_static(97.0, 100.0, GrooveErrors(bottom_rotation=np.deg2rad(-2.0)), rigid=rigid)
    assert s.converged and s.contact_count == 3 and not s.four_point
    assert s.normal_force[0] == 0.0 and np.all(s.normal_force[1:] > 0)
    assert s.residual <= 1e-11 * 100.0


def test_loose_ball_and_pulling_load_flagged():
    # Undersize ball with the top groove held in place: a rattling ball, no force, converged.
    s = solve_static_displacement([0.0, 0.0], GrooveErrors(ball_oversize=-2e-6))
    assert s.converged and s.contact_count == 0
    assert_allclose(s.normal_force, 0.0, atol=0)
    # A load pulling the top groove up has no compressive equilibrium: not converged.
    s = solve_static(0.0, -50.0)
    assert not s.converged


# --------------------------------------------------------------------------------------------
# Sensitivities and the linearised mode
# --------------------------------------------------------------------------------------------
def test_sensitivity_matrix_rigid_reference_values():
    s = static_sensitivity(0.0, 200.0, rigid=True)
    assert s.matrix.shape == (len(SENSITIVITY_ROWS), len(SENSITIVITY_COLUMNS)) == (8, 17)
    # Issue 3: dbeta_i/de_perp = 1/((f - 1/2) 2 R_B) = 2500 rad/m (0.1432 deg/um)
    for c in ("BL", "BR", "TR", "TL"):
        assert_allclose(s.entry(f"contact_angle_deviation_{c}",
                                f"arc_centre_offset_tangential_{c}"), 1 / D, rtol=1e-6)
    # [Lin2018] Fig. 6: d dbeta / d theta = -1, +1
    assert_allclose(s.entry("contact_angle_deviation_BL", "bottom_rotation"), -1, rtol=1e-7)
    assert_allclose(s.entry("contact_angle_deviation_BR", "bottom_rotation"), 1, rtol=1e-7)
    assert_allclose(s.entry("contact_angle_deviation_TR", "top_rotation"), -1, rtol=1e-7)
    assert_allclose(s.entry("contact_angle_deviation_TL", "top_rotation"), 1, rtol=1e-7)
    # paired statics at 45 deg: dF_1/dN_x = -sqrt(2)/2, dF_2/dN_y = sqrt(2)/2
    assert_allclose(s.entry("normal_force_BL", "side_load"), -np.sqrt(0.5), rtol=1e-7)
    assert_allclose(s.entry("normal_force_TL", "normal_load"), np.sqrt(0.5), rtol=1e-7)
    # groove offsets only shift the bodies in load control
    cols = [SENSITIVITY_COLUMNS.index(c) for c in SENSITIVITY_COLUMNS if "offset_" in c
            and "arc" not in c]
    assert_allclose(s.matrix[:, cols], 0.0, atol=1e-6)
    assert "bottom_rotation" in s.table()


def test_sensitivity_matches_solver_and_linearised_error():
    # Elastic sensitivities at the loaded Table 1 state (N_y = 200 N, rho = -0.6) predict the
    # full solution for errors of 1.5 um / 0.5 deg (1 sigma) to within 2 % of the range of the
    # angle deviations. Measured over 5000 balls: max |dbeta_lin - dbeta| = 0.022 deg where
    # dbeta spans 2.54 deg (0.9 %), max |F_lin - F| = 0.16 N.
    sens = static_sensitivity(-120.0, 200.0)
    nx, ny, e = _random_state(17, 5000, scale=1.0)
    nx, ny = np.full(5000, -120.0), np.full(5000, 200.0)
    full = solve_static(nx, ny, to_groove_errors(e))
    lin_db, lin_f = linearised_static(sens, nx, ny, to_groove_errors(e))
    err_db = np.max(np.abs(lin_db - full.contact_angle_deviation))
    err_f = np.max(np.abs(lin_f - full.normal_force))
    span = np.max(np.abs(full.contact_angle_deviation - sens.nominal.contact_angle_deviation))
    print(f"linearised: max |ddbeta| = {np.rad2deg(err_db):.4f} deg over a span of "
          f"{np.rad2deg(span):.3f} deg; max |dF| = {err_f:.3f} N")
    assert err_db < 0.02 * span
    assert err_f < 0.02 * 200.0


# --------------------------------------------------------------------------------------------
# Validation of the public functions
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(side_load=np.nan, normal_load=1.0), "side_load"),
        (dict(side_load=0.0, normal_load="x"), "normal_load"),
        (dict(side_load=0.0, normal_load=1.0,
              errors=GrooveErrors(arc_centre_offset_normal=np.zeros(3))),
         "arc_centre_offset_normal"),
        (dict(side_load=0.0, normal_load=1.0, errors=GrooveErrors(bottom_rotation=1.0)),
         "bottom_rotation"),
        (dict(side_load=np.array([0.0, np.inf, 1.0]), normal_load=1.0), "side_load"),
        (dict(side_load=0.0, normal_load=1.0,  # below -pi/8, contiguous and a broadcast view
              errors=GrooveErrors(top_rotation=np.array([0.1, -0.5]))), "top_rotation"),
        (dict(side_load=0.0, normal_load=1.0, errors=GrooveErrors(
            bottom_rotation=np.broadcast_to(np.array([0.0, -0.5]), (3, 2)))),
         "bottom_rotation"),
        (dict(side_load=np.zeros(3), normal_load=np.ones(4)), "broadcast"),
        (dict(side_load=0.0, normal_load=1.0, tol=0.0), "tol"),
        (dict(side_load=0.0, normal_load=1.0, max_iter=0), "max_iter"),
        (dict(side_load=0.0, normal_load=1.0, errors="none"), "errors"),
    ],
)
def test_validation_names_the_bad_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        solve_static(**kwargs)


def test_shapes_broadcast():
    s = solve_static(np.zeros((3, 1)), np.full((1, 5), 100.0),
                     GrooveErrors(arc_centre_offset_normal=np.zeros((5, 4))))
    assert s.contact_angle.shape == (3, 5, 4) and s.converged.shape == (3, 5)
    assert s.ball_displacement.shape == (3, 5, 2)
    s = solve_static(0.0, 100.0)
    assert s.contact_angle.shape == (4,) and s.converged.shape == ()


# --------------------------------------------------------------------------------------------
# `tolsim ball --static` wiring
# --------------------------------------------------------------------------------------------
def _ball_json(capsys, *argv):
    import json

    from tolsim.cli import main

    assert main(["ball", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_cli_static_solved_reports_loaded_angles_and_forces(capsys):
    # Table 2 case (a), ball 1 via the bottom rotation: the JSON carries the loaded angles and
    # forces that went into the velocity model (same numbers as solve_static).
    out = _ball_json(capsys, "--static", "solved", "--bottom-rotation-deg", "2",
                     "--load-n", "-120", "200")
    s = solve_static(-120.0, 200.0, GrooveErrors(bottom_rotation=np.deg2rad(2.0)))
    assert out["normal_force_source"] == "solved" and out["contact_angle_source"] == "solved"
    assert_allclose(out["contact_angle_deg"], np.rad2deg(s.contact_angle), rtol=1e-12)
    assert_allclose(out["normal_force_n"], s.normal_force, rtol=1e-12)
    eps = analytic(s.contact_angle_deviation, s.normal_force).velocity_deviation
    assert_allclose(out["velocity_deviation"], eps, rtol=1e-12)
    assert out["static"]["four_point"] and out["static"]["converged"]
    # the default --dbeta-deg (-2 2 0 0), realised as flanks turned about the ball centre,
    # is the same geometry as the 2-deg bottom rotation
    out2 = _ball_json(capsys, "--static", "solved")
    assert_allclose(out2["contact_angle_deg"], out["contact_angle_deg"], atol=1e-10)


def test_cli_geometric_errors_with_paired_forces(capsys):
    # --static paired with geometric errors: rigid (geometric) angles, paired forces;
    # a top rotation equal to the bottom one is Table 2 case (b): epsilon = 0.
    out = _ball_json(capsys, "--bottom-rotation-deg", "2", "--top-rotation-deg", "2")
    assert_allclose(out["contact_angle_deviation_deg"], [-2, 2, -2, 2], atol=1e-10)
    assert_allclose(out["normal_force_n"], paired_forces(-120.0, 200.0), rtol=1e-12)
    assert abs(out["velocity_deviation"]) < 1e-12
    out = _ball_json(capsys, "--arc-offset-tangential-um", "1", "0", "0", "0")
    assert_allclose(out["contact_angle_deviation_deg"][0], np.rad2deg(np.arctan(1e-6 / D)),
                    atol=1e-6)


@pytest.mark.parametrize("argv", [
    ["--dbeta-deg", "1", "1", "1", "1", "--bottom-rotation-deg", "1"],
    ["--static", "solved", "--forces-n", "1", "2", "3", "4"],
    ["--bottom-rotation-deg", "nan"],
    ["--ball-oversize-um", "1e4"],
    ["--static", "solved", "--load-n", "0", "-50"],
    ["--static", "exact"],
])
def test_cli_static_bad_input_is_one_line_exit_2(capsys, argv):
    from tolsim.cli import main

    assert main(["ball", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tolsim ball: error:") and "\n" not in err
