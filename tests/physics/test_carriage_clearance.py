"""A carriage with clearance settles onto its contacts; lift-off only where nothing can close.

Issue 25: a guide with clearance (a negative ball oversize, catalogue clearance classes) under a
load that presses the carriage onto the rail. The guide is the one of
``configs/carriage_preload.toml`` (the [Lin2018] Table 1 ball, two wrapped tracks of 12 balls).
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.optimize import brentq

from tolsim.physics.carriage import (
    CarriageError,
    CarriageLayout,
    CarriageLoad,
    CarriageStatus,
    solve_carriage,
    solve_carriage_batch,
)
from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static import GrooveErrors

B0 = TABLE1.nominal_contact_angle
D = TABLE1.groove_radius - TABLE1.ball_radius  # d = R_G - R_B = 0.4 mm
K = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                    TABLE1.poisson_ratio).load_deflection_constant
SX = np.array([-1.0, 1.0, 1.0, -1.0])
SY = np.array([-1.0, -1.0, 1.0, 1.0])
CLEARANCE = -5e-6  # ball oversize [m]: 2.5 um of clearance at each of the four contacts
#: The packaged load of configs/carriage_preload.toml, and the pure vertical part of it.
PACKAGED = CarriageLoad(vertical_force=300.0, pitch_moment=2.0)
VERTICAL = CarriageLoad(vertical_force=300.0)
#: The carriage balance is solved to 1e-11 of the force scale (CARRIAGE_TOLERANCE); checked
#: from the reported forces and angles alone, whose round-off is about 1e-13 of the force.
BALANCE = 1e-9


def packaged():
    """The layout of configs/carriage_preload.toml: tracks at x = -/+20 mm, phi = +/-90 deg,
    12 balls at 10.05 mm."""
    return CarriageLayout([-0.02, 0.02], [0.0, 0.0], np.deg2rad([90.0, -90.0]), 12, 0.01005)


def straight(n=4, pitch=0.0125):
    """One phi = 0 track (the paper's module: the carriage groove above its balls)."""
    return CarriageLayout([0.0], [0.0], [0.0], n, pitch)


def independent_balance(layout, load, sol):
    """Q + sum of the ball forces and moments from the reported F_i and beta_i only (as in
    tests/physics/test_carriage.py)."""
    beta = B0 + sol.contact_angle_deviation
    u = np.stack([SX * np.sin(beta), SY * np.cos(beta)], axis=-1)
    f = np.einsum("tni,tnic->tnc", sol.normal_force[..., 2:], u[..., 2:, :])
    phi = layout.track_orientation
    e1 = np.stack([np.cos(phi), np.sin(phi)], -1)
    e2 = np.stack([-np.sin(phi), np.cos(phi)], -1)
    fc = f[..., :1] * e1[:, None, :] + f[..., 1:] * e2[:, None, :]
    x, y, z = layout.track_x[:, None], layout.track_y[:, None], layout.ball_z[None, :]
    fx, fy = fc[..., 0], fc[..., 1]
    total = np.array([fx.sum(), fy.sum(), (-z * fy).sum(), (z * fx).sum(),
                      (x * fy - y * fx).sum()])
    return load.generalised() + total


def two_point_settling(vertical, balls, oversize):
    """Exact vertical travel [m] of the wrapped guide with clearance under a pure vertical load.

    Every ball carries the side load V / n_balls on one diagonal pair (BL-TR or BR-TL), two-point.
    Equal and opposite forces put its centre midway on the line between the two arc centres,
    whose distance is rho(s) = |2 d e + s x| = sqrt(4 d^2 + 4 d s sin(beta_0) + s^2) after a
    side travel s of the carriage groove (e the unit diagonal at beta_0 from the module normal),
    so each contact's approach is delta = rho / 2 - d + h (h = o / 2 < 0) and the side load
    balances F (2 d sin(beta_0) + s) / rho with F = K delta^1.5 ([Johnson1985] Sec. 4.2, the
    constant K of tolsim.physics.hertz). Root of that balance in s.
    """
    h = 0.5 * oversize

    def imbalance(s):
        rho = np.sqrt(4 * D * D + 4 * D * s * np.sin(B0) + s * s)
        delta = max(rho / 2 - D + h, 0.0)
        return K * delta**1.5 * (2 * D * np.sin(B0) + s) / rho - vertical / balls

    return brentq(imbalance, -2 * h / np.sin(B0), 1e-4, xtol=1e-16, rtol=1e-15)


def check_settled(layout, load, sol):
    """Equilibrium, closed contacts pressed, open ones apart."""
    assert sol.converged and sol.status == CarriageStatus.CONVERGED
    fscale = max(np.abs(load.generalised()).max(), sol.normal_force.max())
    balance = independent_balance(layout, load, sol)
    length = layout.length_scale()
    assert np.abs(balance[:2]).max() <= BALANCE * fscale
    assert np.abs(balance[2:]).max() <= BALANCE * fscale * length
    closed = sol.normal_force > 0
    assert (sol.approach[closed] > 0).all()  # a closed contact is pressed: F = K delta^1.5
    assert (sol.approach[~closed] < 0).all()  # an open one has a positive gap
    assert_array_equal(sol.contact_count, closed.sum(-1))


# --------------------------------------------------------------------------------------------
# Settling
# --------------------------------------------------------------------------------------------
def test_clearance_settles_under_the_packaged_load():
    # configs/carriage_preload.toml at -5 um (the THK HSR "normal" class's clearance end):
    # the 300 N press the carriage onto the rail; the old solver called it a lift-off.
    layout = packaged()
    sol = solve_carriage(layout, PACKAGED, oversize=CLEARANCE)
    check_settled(layout, PACKAGED, sol)
    # the vertical load is each ball's side load: every ball two-point, on one diagonal
    assert_array_equal(sol.contact_count, 2)
    loaded = sol.normal_force > 0
    assert (loaded[..., 0] == loaded[..., 2]).all() and (loaded[..., 1] == loaded[..., 3]).all()
    # down by more than the clearance closing along the diagonal, -2 h / sin(beta_0)
    assert sol.displacement[1] < CLEARANCE / np.sin(B0)


def test_clearance_settling_closed_form():
    # Pure vertical load: all balls equal by symmetry, two-point (two_point_settling). To
    # first order in s / d the travel is the clearance closing plus the Hertz approach of the
    # loaded pair along the diagonal: s1 = (-2 h + 2 (F / K)^(2/3)) / sin(beta_0) with F =
    # V / (n sin(beta_0)): 7.071 + 2.343 = 9.414 um; the exact geometry gives 9.3626 um (the
    # line of the pair turns by s cos(beta_0) / (2 d), 0.5 % here).
    layout = packaged()
    sol = solve_carriage(layout, VERTICAL, oversize=CLEARANCE)
    check_settled(layout, VERTICAL, sol)
    assert_array_equal(sol.contact_count, 2)
    s = two_point_settling(300.0, 24, CLEARANCE)
    # solver tolerance 1e-11 of the force; the travel follows to about 1e-9 of itself
    assert_allclose(-sol.displacement[1], s, rtol=1e-8)
    assert_allclose(sol.displacement[[0, 2, 3, 4]], 0.0, atol=1e-9 * s)
    f = 300.0 / (24 * np.sin(B0))
    first_order = (-CLEARANCE + 2 * (f / K) ** (2 / 3)) / np.sin(B0)
    assert_allclose(first_order, 9.414e-6, rtol=1e-3)  # the numbers in the comment above
    assert_allclose(s, 9.3626e-6, rtol=1e-4)
    assert abs(s / first_order - 1) < 0.01  # first order, within the turn of the line (1 %)
    # every loaded contact carries F of the exact geometry
    rho = np.sqrt(4 * D * D + 4 * D * s * np.sin(B0) + s * s)
    delta = rho / 2 - D + CLEARANCE / 2
    assert_allclose(sol.normal_force[sol.normal_force > 0], K * delta**1.5, rtol=1e-8)


def test_clearance_pulled_up_settles_on_the_other_diagonal():
    # A four-point gothic-arch guide carries a pull as well as a press (catalogues rate it
    # equally in four directions): the wrapped guide with clearance pulled up settles on the
    # other diagonal, by the mirror symmetry of the module exactly as far.
    layout = packaged()
    down = solve_carriage(layout, VERTICAL, oversize=CLEARANCE)
    up = solve_carriage(layout, CarriageLoad(vertical_force=-300.0), oversize=CLEARANCE)
    check_settled(layout, CarriageLoad(vertical_force=-300.0), up)
    assert_allclose(up.displacement[1], -down.displacement[1], rtol=1e-9)
    assert_allclose(up.normal_force, down.normal_force[..., [1, 0, 3, 2]], rtol=1e-9, atol=0)


def test_batch_settles_clearance_by_both_newtons():
    # The study's path: the batched kernel, from the settled nominal solution (joint Newton)
    # and from q = 0 by the nested Newton (which must settle itself), agrees with
    # solve_carriage (AGREEMENT of tests/physics/test_carriage_batch.py: 1e-9).
    layout = packaged()
    ref = solve_carriage(layout, PACKAGED, oversize=CLEARANCE)
    for kwargs in (dict(), dict(joint=False, start=np.zeros(5)),
                   dict(joint=True, start=np.zeros(5))):
        batch = solve_carriage_batch(layout, PACKAGED, oversize=CLEARANCE, **kwargs)
        assert_array_equal(batch.status, CarriageStatus.CONVERGED)
        assert_allclose(batch.displacement[0], ref.displacement, rtol=0,
                        atol=1e-9 * np.abs(ref.displacement).max())
        assert_allclose(batch.normal_force[0], ref.normal_force, rtol=0,
                        atol=1e-9 * ref.normal_force.max())
        assert_array_equal(batch.contact_count[0], 2)


def test_sampled_assemblies_with_clearance_settle():
    # Sampled errors of a precision guide (1 um offsets, 0.1 deg, 0.1 um ball sizes): every
    # assembly settles. A ball cannot balance on one contact: a single loaded flank is a loose
    # ball's last, ending at delta -> 0 (F below 1e-9 of the largest force; the batch test's
    # AGREEMENT). The carriage rests on the balls whose grooves are tightest: 15 % of them
    # touch nothing here (seed 25: 145 of 960 unloaded, 12 loose, 803 two-point).
    rng = np.random.default_rng(25)
    shape = (40, 2, 12)
    errors = GrooveErrors(
        arc_centre_offset_normal=rng.normal(0.0, 1e-6, shape + (4,)),
        arc_centre_offset_tangential=rng.normal(0.0, 1e-6, shape + (4,)),
        bottom_rotation=rng.normal(0.0, 1.75e-3, shape),
        top_rotation=rng.normal(0.0, 1.75e-3, shape),
        ball_oversize=rng.normal(0.0, 0.1e-6, shape))
    batch = solve_carriage_batch(packaged(), PACKAGED, oversize=CLEARANCE, groove_errors=errors)
    assert_array_equal(batch.status, CarriageStatus.CONVERGED)
    one = batch.contact_count == 1
    assert (batch.normal_force[one] <= 1e-9 * batch.normal_force.max()).all()
    assert (batch.contact_count >= 2).mean() > 0.75


# --------------------------------------------------------------------------------------------
# Continuity from clearance to preload
# --------------------------------------------------------------------------------------------
def test_settled_state_is_continuous_from_clearance_to_preload():
    # Oversize from -5 um (clearance) to +4 um (medium preload) in steps of 0.25 um. Bounds of
    # the slopes: in clearance the travel grows by the closing, |du_y/do| = 1 / sin(beta_0)
    # = 1.414 (two_point_settling at fixed load); with preload less. A contact force changes
    # at most as the preload F0 = K (o/2)^1.5 of both diagonals, |dF/do| <= 1.5 K (o/2)^0.5
    # at o = 4 um: 49.7 N/um. A jump (a solver landing on another branch, a lift-off) breaks
    # these bounds by orders of magnitude; 5 % margin for the curvature of the geometry.
    layout = packaged()
    step = 0.25e-6
    oversizes = np.arange(-5e-6, 4e-6 + step / 2, step)
    uy, force = [], []
    for o in oversizes:
        sol = solve_carriage(layout, PACKAGED, oversize=o)
        check_settled(layout, PACKAGED, sol)
        uy.append(sol.displacement[1])
        force.append(sol.normal_force)
    uy, force = np.array(uy), np.array(force)
    assert np.abs(np.diff(uy)).max() <= 1.05 * step / np.sin(B0)
    assert np.abs(np.diff(force, axis=0)).max() <= 1.05 * 1.5 * K * np.sqrt(2e-6) * step
    # the carriage rises monotonically as the balls grow, and closes every contact with preload
    assert (np.diff(uy) > 0).all()
    assert (sol.contact_count == 4).sum() > 0


# --------------------------------------------------------------------------------------------
# Lift-off and failure
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("oversize", [0.0, 1e-6, CLEARANCE])
def test_pull_off_is_lift_off(oversize):
    # The paper's module (phi = 0: the carriage groove above its balls) pulled upwards: every
    # carriage flank moves away from its ball, nothing can close, no equilibrium.
    layout = straight()
    load = CarriageLoad(vertical_force=-100.0)
    with pytest.raises(CarriageError, match="lifts off.*vertical -100 N") as err:
        solve_carriage(layout, load, oversize=oversize)
    assert err.value.status == CarriageStatus.LIFT_OFF
    batch = solve_carriage_batch(layout, load, oversize=oversize)
    assert_array_equal(batch.status, CarriageStatus.LIFT_OFF)
    assert np.isnan(batch.displacement).all()


def test_clearance_beyond_the_arch_is_a_failure_not_lift_off():
    # Balls 150 um undersize on a phi = 0 track pressed down: the carriage grooves approach the
    # balls but would have to travel further than the gothic arch allows (a quarter of d):
    # no answer within the model (FAILED), not a lift-off (the load presses).
    layout = straight()
    load = CarriageLoad(vertical_force=200.0)
    with pytest.raises(CarriageError, match="leaves the gothic arch") as err:
        solve_carriage(layout, load, oversize=-150e-6)
    assert err.value.status == CarriageStatus.FAILED
    batch = solve_carriage_batch(layout, load, oversize=-150e-6)
    assert_array_equal(batch.status, CarriageStatus.FAILED)
