"""Tests of the carriage (tolsim issue 12, "Done means"), :mod:`tolsim.physics.carriage`.

Each test names its source (the issue's list, or a closed form derived in the Notes of
:func:`tolsim.physics.carriage.solve_carriage` or here) and an explicit tolerance.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tolsim.physics.carriage import (
    DOFS,
    CarriageLayout,
    CarriageLoad,
    solve_carriage,
)
from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static import GrooveErrors, solve_static, solve_static_displacement

B0 = TABLE1.nominal_contact_angle
K = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                    TABLE1.poisson_ratio).load_deflection_constant
SX = np.array([-1.0, 1.0, 1.0, -1.0])
SY = np.array([-1.0, -1.0, 1.0, 1.0])
MIRROR = [1, 0, 3, 2]  # module x -> -x swaps BL <-> BR and TR <-> TL
SPAN = 0.05  # s [m], distance between the two tracks of the wrapped guide
PITCH = 0.0125  # [m]


def wrapped(n=6, span=SPAN, pitch=PITCH):
    """The issue's two-row guide whose carriage wraps the rail."""
    return CarriageLayout([-span / 2, span / 2], [0.0, 0.0], np.deg2rad([90.0, -90.0]), n,
                          pitch)


def random_errors(rng, shape, size=1e-6):
    return GrooveErrors(
        arc_centre_offset_normal=rng.uniform(-size, size, shape + (4,)),
        arc_centre_offset_tangential=rng.uniform(-size, size, shape + (4,)),
        bottom_rotation=rng.uniform(-1e-4, 1e-4, shape),
        top_rotation=rng.uniform(-1e-4, 1e-4, shape),
        ball_oversize=rng.uniform(-0.5 * size, 0.5 * size, shape),
    )


def independent_balance(layout, load, sol):
    """Q + sum of the ball forces and moments, from the reported F_i and beta_i only.

    Force of ball (t, j) on its carriage groove: f = sum_{TR, TL} F_i u_i with u_i =
    (sx sin beta_i, sy cos beta_i) in the module frame; E_t f at p = (x_t, y_t, z_j).
    """
    beta = B0 + sol.contact_angle_deviation
    u = np.stack([SX * np.sin(beta), SY * np.cos(beta)], axis=-1)  # (t, n, 4, 2)
    f = np.einsum("tni,tnic->tnc", sol.normal_force[..., 2:], u[..., 2:, :])
    phi = layout.track_orientation
    e1 = np.stack([np.cos(phi), np.sin(phi)], -1)
    e2 = np.stack([-np.sin(phi), np.cos(phi)], -1)
    fc = f[..., :1] * e1[:, None, :] + f[..., 1:] * e2[:, None, :]  # carriage frame
    x = layout.track_x[:, None]
    y = layout.track_y[:, None]
    z = layout.ball_z[None, :]
    fx, fy = fc[..., 0], fc[..., 1]
    total = np.array([fx.sum(), fy.sum(), (-z * fy).sum(), (z * fx).sum(),
                      (x * fy - y * fx).sum()])
    return load.generalised() + total


# --------------------------------------------------------------------------------------------
# Issue 12, "Done means" 1: preload only, symmetric two-row guide
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("oversize", [1e-6, 4e-6, 10e-6])
def test_preload_only_wrapped_guide_closed_form(oversize):
    # Closed form (issue 12): at zero displacement every flank has delta = o/2, so
    # F = K (o/2)^1.5 at beta_0, and the two tracks' preloads cancel. Tolerance 1e-9 relative.
    sol = solve_carriage(wrapped(), CarriageLoad(), oversize=oversize)
    assert sol.converged
    assert_allclose(sol.normal_force, K * (0.5 * oversize) ** 1.5, rtol=1e-9)
    assert_allclose(sol.contact_angle_deviation, 0.0, atol=1e-12)  # rad
    assert_allclose(sol.displacement, 0.0, atol=1e-15)  # m, rad
    assert sol.locked == ()
    assert_allclose(sol.side_force_ratio, 0.0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# "Done means" 2: one straight track equals today's single-ball solve
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("oversize", [0.0, 3e-6])
@pytest.mark.parametrize("n", [1, 5])
def test_single_straight_track_equals_solve_static(n, oversize):
    # Issue 12: equal load on a single straight track (phi = 0, roll locked): each ball equals
    # solve_static(0, V/n) (its top groove is free in x and y there too). 1e-9 relative.
    vertical = 1000.0
    layout = CarriageLayout([0.0], [0.0], [0.0], n, PITCH)
    sol = solve_carriage(layout, CarriageLoad(vertical_force=vertical), oversize=oversize)
    ref = solve_static(0.0, vertical / n, GrooveErrors(ball_oversize=oversize))
    assert sol.converged
    assert "roll" in sol.locked
    assert_allclose(sol.normal_force[0], np.broadcast_to(ref.normal_force, (n, 4)), rtol=1e-9)
    scale = np.abs(ref.contact_angle_deviation).max()
    assert_allclose(sol.contact_angle_deviation[0],
                    np.broadcast_to(ref.contact_angle_deviation, (n, 4)), atol=1e-9 * scale)
    assert_allclose(sol.normal_load, vertical / n, rtol=1e-9)
    assert_allclose(sol.side_load, 0.0, atol=1e-9 * vertical / n)


# --------------------------------------------------------------------------------------------
# "Done means" 3: force and moment balance; mirror symmetry
# --------------------------------------------------------------------------------------------
def random_load(rng, length):
    force = rng.uniform(-1.0, 1.0, 2) * [400.0, 300.0] + [0.0, 800.0]
    moment = rng.uniform(-1.0, 1.0, 3) * 0.2 * length * 300.0
    return CarriageLoad(force[0], force[1], *moment)


@pytest.mark.parametrize("case", range(6))
def test_force_and_moment_balance_random(case):
    # Issue 12: balance of the carriage to 1e-9 of the load scale (forces: max |F|, moments:
    # max |F| L), recomputed from the reported F_i and beta_i (independent_balance).
    rng = np.random.default_rng([12, case])
    if case % 2:
        layout = wrapped(n=int(rng.integers(3, 9)))
    else:  # four tracks, two of them tilted (a 45-degree four-row guide)
        layout = CarriageLayout([-0.03, -0.02, 0.02, 0.03], [0.01, -0.005, -0.005, 0.01],
                                np.deg2rad([45.0, 135.0, -135.0, -45.0]), 5, 0.01)
    load = random_load(rng, layout.length_scale())
    shape = (layout.n_tracks, layout.balls_per_track)
    sol = solve_carriage(layout, load, oversize=rng.uniform(1e-6, 4e-6, shape),
                         groove_errors=random_errors(rng, shape))
    assert sol.converged and sol.locked == ()
    q = load.generalised()
    scale = max(np.abs(q[:2]).max(), np.abs(q[2:]).max() / layout.length_scale())
    units = np.array([1.0, 1.0] + [layout.length_scale()] * 3)
    assert np.abs(independent_balance(layout, load, sol) / units).max() <= 1e-9 * scale
    assert np.abs(sol.residual / units).max() <= 1e-9 * scale


@pytest.mark.parametrize("case", range(3))
def test_mirror_left_right(case):
    # Mirror x -> -x of the wrapped guide (tracks swap): lateral, yaw and roll change sign,
    # vertical and pitch do not (a reflection keeps the axial vector's x component). In each
    # module frame x flips: BL <-> BR, TR <-> TL, N_x -> -N_x. Tolerance 1e-9 relative.
    rng = np.random.default_rng([121, case])
    layout = wrapped(n=5)
    load = random_load(rng, layout.length_scale())
    mirrored = CarriageLoad(-load.lateral_force, load.vertical_force, load.pitch_moment,
                            -load.yaw_moment, -load.roll_moment)
    oversize = rng.uniform(1e-6, 4e-6, (2, 5))
    a = solve_carriage(layout, load, oversize=oversize)
    b = solve_carriage(layout, mirrored, oversize=oversize[::-1])
    fmax = a.normal_force.max()
    assert_allclose(b.normal_force, a.normal_force[::-1][..., MIRROR], atol=1e-9 * fmax)
    assert_allclose(b.contact_angle_deviation, a.contact_angle_deviation[::-1][..., MIRROR],
                    atol=1e-9 * np.abs(a.contact_angle_deviation).max())
    assert_allclose(b.side_load, -a.side_load[::-1], atol=1e-9 * fmax)
    assert_allclose(b.normal_load, a.normal_load[::-1], atol=1e-9 * fmax)
    sign = np.array([-1.0, 1.0, 1.0, -1.0, -1.0])
    assert_allclose(b.displacement, sign * a.displacement,
                    atol=1e-9 * np.abs(a.displacement).max())


def test_mirror_front_back():
    # Mirror z -> -z: ball j <-> n - 1 - j, pitch and yaw moments change sign; the module
    # frames are unchanged. Tolerance 1e-9 relative.
    rng = np.random.default_rng(122)
    layout = wrapped(n=6)
    load = random_load(rng, layout.length_scale())
    mirrored = CarriageLoad(load.lateral_force, load.vertical_force, -load.pitch_moment,
                            -load.yaw_moment, load.roll_moment)
    oversize = rng.uniform(1e-6, 4e-6, (2, 6))
    a = solve_carriage(layout, load, oversize=oversize)
    b = solve_carriage(layout, mirrored, oversize=oversize[:, ::-1])
    fmax = a.normal_force.max()
    assert_allclose(b.normal_force, a.normal_force[:, ::-1], atol=1e-9 * fmax)
    sign = np.array([1.0, 1.0, -1.0, -1.0, 1.0])
    assert_allclose(b.displacement, sign * a.displacement,
                    atol=1e-9 * np.abs(a.displacement).max())


# --------------------------------------------------------------------------------------------
# "Done means" 4: stiffness
# --------------------------------------------------------------------------------------------
def test_condensed_ball_stiffness_matches_static_finite_differences():
    # NumPy twin of the kernel's Schur complement S = -df/dg: central differences of the
    # existing displacement-controlled solve (step 1e-10 m). Tolerance 1e-6 relative.
    layout = CarriageLayout([0.0], [0.0], [0.3], 1, 0.0)
    sol = solve_carriage(layout, CarriageLoad(lateral_force=80.0, vertical_force=300.0),
                         oversize=2e-6)
    g0 = sol.groove_displacement[0, 0]
    h = 1e-10
    cols = []
    for c in range(2):
        dg = np.zeros(2)
        dg[c] = h
        plus = solve_static_displacement(g0 + dg, GrooveErrors(ball_oversize=2e-6)).groove_load
        minus = solve_static_displacement(g0 - dg, GrooveErrors(ball_oversize=2e-6)).groove_load
        # force on the groove f = (-N_x, N_y); S = -df/dg
        df = (plus - minus) / (2 * h)
        cols.append(-np.array([-df[0], df[1]]))
    s_fd = np.array(cols).T
    c, s = np.cos(0.3), np.sin(0.3)
    rot = np.array([[c, -s], [s, c]])  # module -> carriage
    k_fd = rot @ s_fd @ rot.T
    assert_allclose(sol.stiffness[:2, :2], k_fd, atol=1e-6 * np.abs(k_fd).max())


def finite_difference_compliance(layout, load, oversize, rel_step=1e-5):
    """d q / d Q by central differences of the solve, columns for the free DOFs."""
    q = load.generalised()
    length = layout.length_scale()
    units = np.array([1.0, 1.0, length, length, length])
    step = rel_step * max(np.abs(q[:2]).max(), np.abs(q[2:]).max() / length, 1.0) * units
    names = ("lateral_force", "vertical_force", "pitch_moment", "yaw_moment", "roll_moment")
    sign = np.array([1.0, -1.0, 1.0, 1.0, 1.0])  # Q_1 = -vertical
    base = solve_carriage(layout, load, oversize=oversize, tol=1e-13)
    free = [j for j, d in enumerate(DOFS) if d not in base.locked]
    cols = []
    for j in free:
        out = []
        for direction in (1.0, -1.0):
            kw = {n: getattr(load, n) for n in names}
            kw[names[j]] += direction * sign[j] * step[j]
            out.append(solve_carriage(layout, CarriageLoad(**kw), oversize=oversize,
                                      tol=1e-13).displacement)
        cols.append((out[0] - out[1]) / (2 * step[j]))
    return base, free, np.array(cols).T[free], units


@pytest.mark.parametrize("which", ["wrapped_preloaded", "wrapped_no_preload", "single_track"])
def test_stiffness_matches_finite_differences_of_the_solve(which):
    # Issue 12: the assembled K agrees with central differences of the solve: K (dq/dQ) = I
    # on the free DOFs (scaled: rotations times L). Tolerance 1e-6 relative.
    load = CarriageLoad(150.0, 900.0, 6.0, -4.0, 3.0)
    if which == "single_track":
        layout = CarriageLayout([0.0], [0.0], [0.0], 6, PITCH)
        load = CarriageLoad(150.0, 900.0, 6.0, -4.0, 0.0)
        oversize = 2e-6
    else:
        layout = wrapped()
        oversize = 3e-6 if which == "wrapped_preloaded" else 0.0
    base, free, compliance, units = finite_difference_compliance(layout, load, oversize)
    # scaled: q_s = q units, Q_s = Q / units (step 1e-5 of the load: truncation ~3e-8,
    # measured 3e-6 at 1e-4 and 3e-8 at 1e-5, i.e. O(h^2))
    k_scaled = base.stiffness[np.ix_(free, free)] / np.outer(units[free], units[free])
    c_scaled = compliance * np.outer(units[free], units[free])
    assert_allclose(k_scaled @ c_scaled, np.eye(len(free)), atol=1e-6)
    assert_allclose(base.stiffness, base.stiffness.T, rtol=0,
                    atol=1e-12 * np.abs(base.stiffness).max())


def test_vertical_stiffness_grows_with_preload():
    # Issue 12: more oversize, stiffer carriage (Hertz: k ~ delta^0.5), while the preload
    # holds all four contacts closed. (Measured: at o = 1 um the 500 N load opens one diagonal
    # of every ball and k_yy is 0.2 % *below* the unpreloaded value, so the classes tested
    # here keep four-point contact.)
    sols = [solve_carriage(wrapped(), CarriageLoad(vertical_force=500.0), oversize=o)
            for o in (0.0, 2e-6, 4e-6, 8e-6)]
    k = [s.stiffness[1, 1] for s in sols]
    assert all((s.contact_count == 4).all() for s in sols[1:])
    assert np.all(np.diff(k) > 0), k


# --------------------------------------------------------------------------------------------
# "Done means" 5: loads to rho
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("oversize", [0.0, 3e-6])
def test_wrapped_vertical_load_is_side_load(oversize):
    # Derivation: module +x of track t is e_1 = (cos phi, sin phi), so the ball's force on the
    # carriage, E (-N_x, N_y), has the vertical component -N_x sin phi + N_y cos phi =
    # -N_x sin phi at phi = +-90 deg. By symmetry every ball carries V/(2n), so
    # N_x = -sin(phi) V/(2n): -V/(2n) on the left track (phi = +90), +V/(2n) on the right.
    # N_y is the preload-plus-deformation normal load, equal in both tracks. 1e-9 relative.
    n, vertical = 6, 1200.0
    layout = wrapped(n=n)
    sol = solve_carriage(layout, CarriageLoad(vertical_force=vertical), oversize=oversize)
    expected = -np.sin(layout.track_orientation)[:, None] * vertical / (2 * n)
    assert_allclose(sol.side_load, np.broadcast_to(expected, (2, n)), rtol=1e-9)
    assert_allclose(sol.normal_load, sol.normal_load[0, 0], rtol=1e-9)
    assert_allclose(sol.displacement[[0, 2, 3, 4]], 0.0, atol=1e-9 * abs(sol.displacement[1]))


# --------------------------------------------------------------------------------------------
# Errors
# --------------------------------------------------------------------------------------------
def test_load_the_layout_cannot_carry_is_an_error():
    # One straight track has no roll stiffness: a roll moment cannot be carried.
    layout = CarriageLayout([0.0], [0.0], [0.0], 4, PITCH)
    with pytest.raises(ValueError, match="cannot carry the load"):
        solve_carriage(layout, CarriageLoad(vertical_force=100.0, roll_moment=1.0))


def test_lift_off_is_an_error_naming_the_load():
    # A phi = 0 track pulled upwards: the carriage grooves leave the balls.
    layout = CarriageLayout([0.0], [0.0], [0.0], 4, PITCH)
    with pytest.raises(ValueError, match="lifts off.*vertical -100 N"):
        solve_carriage(layout, CarriageLoad(vertical_force=-100.0), oversize=1e-6)


def test_open_contacts_are_reported():
    # A large lateral load on the preloaded wrapped guide unloads flanks: reported, not raised.
    sol = solve_carriage(wrapped(), CarriageLoad(lateral_force=3000.0), oversize=1e-6)
    assert sol.converged
    assert (sol.contact_count < 4).any()


# --------------------------------------------------------------------------------------------
# "Done means" 5 (continued): yaw, pitch, Fig. 8 and the old linear rule. Derivations in the
# Notes of solve_carriage, section "How carriage loads map to the balls' side-force ratio".
# --------------------------------------------------------------------------------------------
D_ARC = TABLE1.groove_radius - TABLE1.ball_radius  # |P - C| at zero approach change [m]


def preloaded_ball(oversize):
    """Closed forms of the preloaded, unloaded ball (docstring, step 3).

    Returns the flank force F0 = K (o/2)^1.5, the normal load N0 = 2 F0 cos(beta_0) and the
    isotropic condensed stiffness S = (k_n + F0 / d) / 2 with k_n = 1.5 K (o/2)^0.5.
    """
    h = 0.5 * oversize
    flank = K * h**1.5
    return flank, 2.0 * flank * np.cos(B0), 0.5 * (1.5 * K * np.sqrt(h) + flank / D_ARC)


def test_wrapped_preloaded_stiffness_closed_form():
    # Docstring, step 3: at the preload state S = (k_n + F0/d)/2 I in every module, so
    # K_pitch = K_yaw = 2 S sum z_j^2 and N_y = 2 F0 cos(beta_0). Closed form; 1e-9 relative
    # (measured 7e-16).
    oversize = 3e-6
    layout = wrapped()
    z = layout.ball_z
    _, normal, stiffness = preloaded_ball(oversize)
    sol = solve_carriage(layout, CarriageLoad(), oversize=oversize)
    assert_allclose(sol.normal_load, normal, rtol=1e-9)
    assert_allclose(sol.stiffness[[2, 3], [2, 3]], 2 * stiffness * np.sum(z * z), rtol=1e-9)
    assert_allclose(sol.stiffness[2, 3], 0.0, atol=1e-9 * sol.stiffness[3, 3])


@pytest.mark.parametrize("moment", [0.1, 1.0])
def test_wrapped_yaw_moment_changes_normal_loads_only(moment):
    # Docstring, step 4: in the wrapped guide a yaw moment moves every carriage groove along
    # its module normal, g_2 = -/+ theta_y z, so N_y,j = N0 +/- M z_j / (2 sum z^2) and N_x
    # stays exactly 0 (mirror symmetry of the module). Tolerances: N_x 1e-9 N0 (exact);
    # first-order N_y within 0.02 (M / 1 N m) of the largest change (the Hertz correction is
    # second order in M: measured 0.0016 at 0.1 N m, 0.016 at 1 N m); theta_y = M / (2 S
    # sum z^2) within 2e-4 (M / 1 N m)^2 (odd in M, so the error is third order: measured
    # 1.2e-6 and 1.2e-4).
    oversize = 3e-6
    layout = wrapped()
    z = layout.ball_z
    _, normal, stiffness = preloaded_ball(oversize)
    sol = solve_carriage(layout, CarriageLoad(yaw_moment=moment), oversize=oversize)
    assert sol.converged and (sol.contact_count == 4).all()
    assert_allclose(sol.side_load, 0.0, atol=1e-9 * normal)
    linear = np.array([1.0, -1.0])[:, None] * moment * z / (2 * np.sum(z * z))
    assert np.abs(sol.normal_load - normal - linear).max() <= 0.02 * moment * linear.max()
    assert_allclose(sol.normal_load[0], sol.normal_load[1, ::-1], rtol=1e-9)
    theta = moment / (2 * stiffness * np.sum(z * z))
    assert abs(sol.displacement[3] / theta - 1) <= 2e-4 * moment**2


def test_wrapped_yaw_moment_with_side_load_couples_through_pair_stiffness():
    # Docstring, step 4: once a vertical load has put side loads on the balls (rho0 = -/+0.40
    # here, four-point contact), the ball's stiffness is no longer isotropic: the diagonal
    # pairs have Hertz stiffnesses k ~ F^(1/3) with F_1 ~ 1 - rho, F_2 ~ 1 + rho ([Lin2018]
    # Sec. 3.1), so a yaw moment's normal-load change drags the side load along with
    # dN_x / dN_y = -((1 - rho0)^(1/3) - (1 + rho0)^(1/3)) / ((1 - rho0)^(1/3) + (1 +
    # rho0)^(1/3)) (-0.140 at rho0 = -0.40). Tolerance 3 % (measured 1.2-1.9 %: the closed
    # form drops the flanks' tangential stiffness F/d and the contact-angle change). Each
    # track still carries exactly V/2 (statics and the x-z mirror symmetry; 1e-9).
    oversize, vertical, moment = 3e-6, 300.0, 0.1
    layout = wrapped()
    base = solve_carriage(layout, CarriageLoad(vertical_force=vertical), oversize=oversize)
    sol = solve_carriage(layout, CarriageLoad(vertical_force=vertical, yaw_moment=moment),
                         oversize=oversize)
    assert (sol.contact_count == 4).all()
    assert_allclose(sol.side_load.sum(axis=1), [-vertical / 2, vertical / 2], rtol=1e-9)
    rho0 = base.side_force_ratio
    a, b = (1 - rho0) ** (1 / 3), (1 + rho0) ** (1 / 3)
    coupling = (sol.side_load - base.side_load) / (sol.normal_load - base.normal_load)
    assert_allclose(coupling, -(a - b) / (a + b), rtol=0.03)


def linearity(z, rho):
    """R^2 of the least-squares line rho(z), and its max deviation / the rho range."""
    fit = np.polyval(np.polyfit(z, rho, 1), z)
    r2 = 1 - np.sum((rho - fit) ** 2) / np.sum((rho - rho.mean()) ** 2)
    return r2, np.abs(rho - fit).max() / np.ptp(rho)


def test_wrapped_pitch_moment_gives_nearly_linear_rho():
    # Docstring, step 5: a pitch moment moves the grooves along the module x, g_1 = -/+ theta_x
    # z, so N_x,j = -/+ P z_j / (2 sum z^2) (first order) and rho_j = N_x,j / N_y,j.
    # Measured at P = 5 N m, o = 3 um, six balls at 12.5 mm (|rho| <= 0.45, four-point
    # contact): R^2 = 0.99985, max deviation from the least-squares line 0.54 % of the rho
    # range, first-order rho = -/+ P z / (2 sum z^2 N0) within 3.6 % of its largest value (the
    # end balls' N_y rises 3.5 %, second order). Bounds: R^2 >= 0.9995, deviation <= 1 % of
    # the range, first order within 5 %. (At P = 10 N m: R^2 0.9975, 2.2 %; at 20 N m the end
    # balls reach two-point contact and R^2 falls to 0.947, 11.6 %.) At P = 0.1 N m the first
    # order holds to 1e-4 (measured 1.5e-5).
    oversize = 3e-6
    layout = wrapped()
    z = layout.ball_z
    _, normal, _ = preloaded_ball(oversize)
    for moment, first_order_tol in ((0.1, 1e-4), (5.0, 0.05)):
        sol = solve_carriage(layout, CarriageLoad(pitch_moment=moment), oversize=oversize)
        assert sol.converged and (sol.contact_count == 4).all()
        linear = np.array([-1.0, 1.0])[:, None] * moment * z / (2 * np.sum(z * z) * normal)
        rho = sol.side_force_ratio
        assert np.abs(rho - linear).max() <= first_order_tol * linear.max()
        for track in range(2):
            r2, deviation = linearity(z, rho[track])
            assert r2 >= 0.9995 and deviation <= 0.01, (moment, r2, deviation)


@pytest.mark.parametrize("oversize", [0.0, 2e-6])
def test_lin2018_fig8_yaw_moment_side_loads(oversize):
    # [Lin2018] Sec. 3.2, Fig. 8: two balls of the phi = 0 module (Table 1, N_y = 200 N each),
    # initial gap 0.1 R_B (pitch 2 R_B + 0.1 R_B = 10.5 mm), and opposite side loads rho_1 =
    # -0.6, rho_2 = +0.6, "a yaw moment applied to the top groove". With two balls the single
    # track is statically determinate: sum N_y = V and sum z N_x = M, and the x-z mirror
    # symmetry gives N_y,0 = N_y,1, N_x,0 = -N_x,1. So V = 400 N and M = 0.6 * 200 N * pitch =
    # 1.26 N m give exactly (-0.6, +0.6), for any preload. Ball 0 trails: it is the paper's
    # Ball 1, the faster one that runs into Ball 2 (Table 2). Tolerance 1e-9 (exact statics).
    pitch = 2.1 * TABLE1.ball_radius
    layout = CarriageLayout([0.0], [0.0], [0.0], 2, pitch)
    sol = solve_carriage(layout, CarriageLoad(vertical_force=400.0,
                                              yaw_moment=0.6 * 200.0 * pitch),
                         oversize=oversize)
    assert sol.converged and sol.locked == ("roll",)
    assert (sol.contact_count == 4).all()
    assert_allclose(sol.normal_load, 200.0, rtol=1e-9)
    assert_allclose(sol.side_force_ratio, [[-0.6, 0.6]], rtol=1e-9)


def default_equivalent_carriage(scale=1.0):
    """The packaged default study's loads on the equivalent phi = 0 single-track carriage.

    Returns the solution, the ball positions [m] and the old rule's rho_j = M z_j / (sum z^2
    N_y) (``tolsim/io/config/sections.py`` ``read_loads``) for the yaw moment times ``scale``.
    """
    from tolsim.io.config import load_config

    config = load_config()
    bearing = config.bearing
    z = config.train.slot_positions(2.0 * bearing.ball_radius)
    normal = np.asarray(config.loads.normal_load)
    moment = scale * config.loads.yaw_moment
    layout = CarriageLayout([0.0], [0.0], [0.0], config.train.balls, z[1] - z[0])
    assert_allclose(layout.ball_z, z, rtol=1e-12)
    sol = solve_carriage(layout, CarriageLoad(vertical_force=normal.sum(), yaw_moment=moment),
                         bearing)
    old = moment * z / np.sum(z * z) / normal
    if scale == 1.0:  # the config's own rule
        assert_allclose(old, config.loads.side_force_ratio, rtol=1e-12)
    return sol, z, old


def test_default_config_yaw_moment_against_the_old_linear_rule():
    # Docstring, step 6: the old rule N_x,j = M z_j / sum z^2 at N_y = 200 N is the carriage's
    # first-order answer; the carriage differs at third order in M (rho is odd in M).
    # Measured for the default (10 balls, pitch 10.05 mm, V = 2000 N, M = 15 N m, no
    # preload): max |drho| = 0.00706 at the end balls (z = -/+45.2 mm: carriage -/+0.4000, old
    # -/+0.4071), 0.87 % of the rho range; the end balls' N_y is 203.4 N and the middle ones'
    # 197.8 N, while N_x differs from the old rule by <= 0.067 N. Tolerances: |drho| <= 0.01
    # (the measured value plus margin: the old rule is good to about 1 % of the range);
    # statics exact to 1e-9; N_x within 0.1 N of the old rule; cubic scaling
    # drho(M/10) / drho(M) = 1e-3 within 2 % (measured 0.994e-3: fifth-order terms).
    sol, z, old = default_equivalent_carriage()
    assert sol.converged and sol.locked == ("roll",) and (sol.contact_count == 4).all()
    rho = sol.side_force_ratio[0]
    drho = rho - old
    assert np.abs(drho).max() <= 0.01
    assert np.argmax(np.abs(drho)) in (0, z.size - 1)
    assert abs(abs(drho).max() - 0.00706) <= 1e-4  # the reported number
    assert_allclose(np.sum(z * sol.side_load[0]), 15.0, rtol=1e-9)
    assert_allclose(sol.normal_load.sum(), 2000.0, rtol=1e-9)
    assert np.abs(sol.side_load[0] - old * 200.0).max() <= 0.1
    ny = sol.normal_load[0]
    assert ny[0] > 200.0 > ny[z.size // 2]  # ends gain N_y, middle loses: the mechanism
    small, _, old_small = default_equivalent_carriage(scale=0.1)
    ratio = np.abs(small.side_force_ratio[0] - old_small).max() / np.abs(drho).max()
    assert_allclose(ratio, 1e-3, rtol=0.02)
