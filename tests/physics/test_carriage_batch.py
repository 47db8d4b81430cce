"""Tests of the batched carriage solve, :func:`tolsim.physics.carriage.solve_carriage_batch`.

Its reference (the "NumPy twin" of the kernel) is :func:`solve_carriage`, one assembly at a
time; each test names its source and an explicit tolerance.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.physics.carriage import (
    STATUS_CONVERGED,
    STATUS_FAILED,
    CarriageError,
    CarriageLayout,
    CarriageLoad,
    solve_carriage,
    solve_carriage_batch,
)
from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static import GrooveErrors

B0 = TABLE1.nominal_contact_angle
K = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                    TABLE1.poisson_ratio).load_deflection_constant
SX = np.array([-1.0, 1.0, 1.0, -1.0])
SY = np.array([-1.0, -1.0, 1.0, 1.0])
#: Agreement of the batch with solve_carriage: both stop at a carriage imbalance of 1e-11 of
#: the force scale and ball imbalances of 1e-12 of the ball force scale. Measured on CASES:
#: forces 2e-11 of the largest, displacements 5e-11 of the largest component, stiffness
#: 4e-11, contact angles 7e-11 (nested path; the joint one is closer); with 4 um errors on
#: a two-ball carriage the displacement differed by up to 8e-10 (the tolerance times the
#: condition of the stiffness).
AGREEMENT = 1e-9
FIELDS = ("contact_angle_deviation", "normal_force", "side_load", "normal_load",
          "contact_count", "ball_converged", "displacement", "stiffness", "residual",
          "converged", "iterations", "status", "fallback")


def wrapped(n=6, span=0.05, pitch=0.0125):
    """The two-row guide whose carriage wraps the rail (tests/physics/test_carriage.py)."""
    return CarriageLayout([-span / 2, span / 2], [0.0, 0.0], np.deg2rad([90.0, -90.0]), n,
                          pitch)


def straight(n=5, pitch=0.0125):
    """One phi = 0 track: roll is locked."""
    return CarriageLayout([0.0], [0.0], [0.0], n, pitch)


def sampled_errors(rng, shape, offset=1e-6, angle=1.75e-3, size=0.5e-6):
    """Groove errors of a precision guide: um offsets [m], a tenth of a degree [rad], ball
    sizes [m] (standard deviations; every ball its own)."""
    return GrooveErrors(
        arc_centre_offset_normal=rng.normal(0.0, offset, shape + (4,)),
        arc_centre_offset_tangential=rng.normal(0.0, offset, shape + (4,)),
        bottom_rotation=rng.normal(0.0, angle, shape),
        top_rotation=rng.normal(0.0, angle, shape),
        bottom_offset=rng.normal(0.0, 2 * offset, shape + (2,)),
        top_offset=rng.normal(0.0, 2 * offset, shape + (2,)),
        ball_oversize=rng.normal(0.0, size, shape),
    )


def one(errors, a):
    """Assembly a of batched groove errors."""
    return GrooveErrors(**{name: np.asarray(getattr(errors, name))[a]
                           for name in GrooveErrors.__dataclass_fields__})


def subset(batch, index):
    return {name: getattr(batch, name)[index] for name in FIELDS}


CASES = {
    # layout, load, oversize (nominal preload) [m]
    "wrapped_preloaded": (wrapped(), CarriageLoad(120.0, 600.0, 4.0, -2.0, 1.5), 2e-6),
    "wrapped_no_preload": (wrapped(), CarriageLoad(-80.0, 900.0, 3.0, 1.0, -1.0), 0.0),
    "straight_preloaded": (straight(), CarriageLoad(0.0, 800.0, 5.0, 3.0, 0.0), 2e-6),
    "straight_no_preload": (straight(), CarriageLoad(0.0, 800.0, -4.0, 2.0, 0.0), 0.0),
}


@pytest.mark.parametrize("joint", [True, False])
@pytest.mark.parametrize("case", sorted(CASES))
def test_agrees_with_solve_carriage(case, joint):
    # Twin: solve_carriage on each assembly alone, same inputs. Forces, loads, displacement,
    # stiffness to AGREEMENT of their scale; the flanks that carry force the same; contact
    # angles where the ball is held by a diagonal pair of flanks (BL-TR or BR-TL) carrying
    # force: a loose ball's position, hence the direction of its flanks, is not unique.
    layout, load, oversize = CASES[case]
    m = 8
    rng = np.random.default_rng([20240, len(case), int(joint)])
    shape = (m, layout.n_tracks, layout.balls_per_track)
    errors = sampled_errors(rng, shape)
    batch = solve_carriage_batch(layout, load, oversize=oversize, groove_errors=errors,
                                 joint=joint)
    assert batch.locked == (("roll",) if case.startswith("straight") else ())
    solved = 0
    for a in range(m):
        try:
            ref = solve_carriage(layout, load, oversize=oversize, groove_errors=one(errors, a))
        except CarriageError as err:
            assert batch.status[a] == err.status
            continue
        assert ref.converged and batch.status[a] == STATUS_CONVERGED
        solved += 1
        fmax = ref.normal_force.max()
        assert_allclose(batch.normal_force[a], ref.normal_force, rtol=0, atol=AGREEMENT * fmax)
        assert_allclose(batch.side_load[a], ref.side_load, rtol=0, atol=AGREEMENT * fmax)
        assert_allclose(batch.normal_load[a], ref.normal_load, rtol=0, atol=AGREEMENT * fmax)
        assert_array_equal(batch.contact_count[a], (batch.normal_force[a] > 0).sum(-1))
        # flanks that carry force beyond the agreement (a loose ball's last flank ends at
        # F ~ 1e-13 N in one solve and 0 in the other)
        assert_array_equal((batch.normal_force[a] > AGREEMENT * fmax).sum(-1),
                           (ref.normal_force > AGREEMENT * fmax).sum(-1))
        loaded = ref.normal_force > AGREEMENT * fmax
        held = (loaded[..., 0] & loaded[..., 2]) | (loaded[..., 1] & loaded[..., 3])
        dbeta = np.abs(ref.contact_angle_deviation).max()
        assert_allclose(batch.contact_angle_deviation[a][held],
                        ref.contact_angle_deviation[held], rtol=0, atol=AGREEMENT * dbeta)
        assert_allclose(batch.displacement[a], ref.displacement, rtol=0,
                        atol=AGREEMENT * np.abs(ref.displacement).max())
        assert_allclose(batch.stiffness[a], ref.stiffness, rtol=0,
                        atol=AGREEMENT * np.abs(ref.stiffness).max())
    assert solved >= m // 2


def test_bit_identical_alone_in_any_batch_and_thread_count(other_thread_count):
    # Each assembly is solved by the same operations whatever the batch and the number of
    # Numba threads (the kernel's contract): exact equality.
    layout, load, oversize = CASES["wrapped_preloaded"]
    m = 24
    rng = np.random.default_rng(31)
    errors = sampled_errors(rng, (m, 2, 6))
    full = solve_carriage_batch(layout, load, oversize=oversize, groove_errors=errors)
    order = rng.permutation(m)[:10]
    part = solve_carriage_batch(layout, load, oversize=oversize,
                                groove_errors=GrooveErrors(**{
                                    name: np.asarray(getattr(errors, name))[order]
                                    for name in GrooveErrors.__dataclass_fields__}))
    for name in FIELDS:
        assert_array_equal(getattr(part, name), getattr(full, name)[order], err_msg=name)
    for a in (0, 7):
        alone = solve_carriage_batch(layout, load, oversize=oversize,
                                     groove_errors=one(errors, slice(a, a + 1)))
        for name in FIELDS:
            assert_array_equal(getattr(alone, name)[0], getattr(full, name)[a], err_msg=name)
    other = other_thread_count(solve_carriage_batch, layout, load, oversize=oversize,
                               groove_errors=errors)
    for name in FIELDS:
        assert_array_equal(getattr(other, name), getattr(full, name), err_msg=name)


@pytest.mark.parametrize("oversize", [1e-6, 4e-6])
def test_preload_only_wrapped_guide_closed_form(oversize):
    # Closed form (tests/physics/test_carriage.py): at zero displacement every flank has delta =
    # o/2,
    # F = K (o/2)^1.5 at beta_0, and the two tracks' preloads cancel. 1e-9 relative.
    batch = solve_carriage_batch(wrapped(n=12), CarriageLoad(),
                                 oversize=np.full((3, 2, 12), oversize))
    assert batch.converged.all()
    assert_allclose(batch.normal_force, K * (0.5 * oversize) ** 1.5, rtol=1e-9)
    assert_allclose(batch.contact_angle_deviation, 0.0, atol=1e-12)  # rad
    assert_allclose(batch.displacement, 0.0, atol=1e-15)  # m, rad
    assert (batch.contact_count == 4).all()


def test_failed_assembly_is_reported_not_raised():
    # A phi = 0 track under 200 N whose balls of one sampled assembly are 150 um undersize:
    # its carriage would have to drop further than the gothic arch allows (a quarter of d =
    # R_G - R_B = 0.4 mm), and solve_carriage raises (status FAILED: the grooves approach the
    # balls, so it is not a lift-off, issue 25). The batch reports status FAILED for that
    # assembly and solves the others.
    layout = straight(n=4)
    load = CarriageLoad(vertical_force=200.0)
    oversize = np.array([2e-6, -150e-6, 0.0])[:, None, None]
    batch = solve_carriage_batch(layout, load, oversize=oversize)
    assert_array_equal(batch.status, [STATUS_CONVERGED, STATUS_FAILED, STATUS_CONVERGED])
    assert_array_equal(batch.converged, [True, False, True])
    assert np.isnan(batch.normal_force[1]).all() and np.isnan(batch.displacement[1]).all()
    with pytest.raises(ValueError, match="leaves the gothic arch"):
        solve_carriage(layout, load, oversize=oversize[1])
    for a in (0, 2):
        ref = solve_carriage(layout, load, oversize=oversize[a])
        assert_allclose(batch.normal_force[a], ref.normal_force, rtol=0,
                        atol=AGREEMENT * ref.normal_force.max())


@pytest.mark.parametrize("kwargs, message", [
    (dict(oversize=np.zeros((3, 2, 5))), "must broadcast to"),
    (dict(oversize=np.zeros((2, 3, 2, 6))), "must broadcast to"),
    (dict(oversize=np.array([1e-6, np.nan])[:, None, None]), "oversize must be finite"),
    (dict(groove_errors=GrooveErrors(top_rotation=np.full((2, 2, 6), np.inf))),
     "top_rotation must be finite"),
    (dict(groove_errors=GrooveErrors(bottom_offset=np.full((2, 2, 6, 3), 0.0))),
     "last axis of length 2"),
    (dict(groove_errors="none"), "must be a GrooveErrors"),
    (dict(tol=0.0), "tol = 0.0"),
    (dict(ball_max_iter=0), "max_iter = 0"),
])
def test_bad_input_is_a_one_line_value_error(kwargs, message):
    with pytest.raises(ValueError, match=message) as info:
        solve_carriage_batch(wrapped(), CarriageLoad(vertical_force=100.0), **kwargs)
    assert "\n" not in str(info.value)


def test_load_along_a_locked_mechanism_is_an_error():
    # As solve_carriage: one straight track has no roll stiffness.
    with pytest.raises(ValueError, match="cannot carry the load"):
        solve_carriage_batch(straight(), CarriageLoad(vertical_force=100.0, roll_moment=1.0),
                             oversize=np.full((4, 1, 1), 1e-6))
    with pytest.raises(ValueError, match="must be finite"):
        solve_carriage_batch(straight(), CarriageLoad(vertical_force=np.nan))


def independent_balance(layout, load, batch, a):
    """Q + sum of the ball forces and moments of assembly a, from its F_i and beta_i only
    (tests/physics/test_carriage.py)."""
    beta = B0 + batch.contact_angle_deviation[a]
    u = np.stack([SX * np.sin(beta), SY * np.cos(beta)], axis=-1)
    f = np.einsum("tni,tnic->tnc", batch.normal_force[a][..., 2:], u[..., 2:, :])
    phi = layout.track_orientation
    e1 = np.stack([np.cos(phi), np.sin(phi)], -1)
    e2 = np.stack([-np.sin(phi), np.cos(phi)], -1)
    fc = f[..., :1] * e1[:, None, :] + f[..., 1:] * e2[:, None, :]
    x, y, z = layout.track_x[:, None], layout.track_y[:, None], layout.ball_z[None, :]
    fx, fy = fc[..., 0], fc[..., 1]
    total = np.array([fx.sum(), fy.sum(), (-z * fy).sum(), (z * fx).sum(),
                      (x * fy - y * fx).sum()])
    return load.generalised() + total


@pytest.mark.parametrize("case", sorted(CASES))
def test_force_and_moment_balance_of_every_converged_assembly(case):
    # Balance to 1e-9 of the load scale (forces: max |F|, moments: max |F| L), recomputed from
    # the reported F_i and beta_i, on the locked DOFs excepted (their reaction is not modelled).
    layout, load, oversize = CASES[case]
    m = 40
    rng = np.random.default_rng([7, len(case)])
    errors = sampled_errors(rng, (m, layout.n_tracks, layout.balls_per_track))
    batch = solve_carriage_batch(layout, load, oversize=oversize, groove_errors=errors)
    assert batch.converged.mean() >= 0.9
    q = load.generalised()
    length = layout.length_scale()
    scale = max(np.abs(q[:2]).max(), np.abs(q[2:]).max() / length)
    units = np.array([1.0, 1.0] + [length] * 3)
    free = np.array([name not in batch.locked for name in
                     ("u_x", "u_y", "pitch", "yaw", "roll")])
    for a in np.flatnonzero(batch.converged):
        assert np.abs(independent_balance(layout, load, batch, a) / units)[free].max() \
            <= 1e-9 * scale
        assert np.abs(batch.residual[a] / units)[free].max() <= 1e-9 * scale


@pytest.mark.parametrize("beta0_deg", [45.0, 37.0])
def test_ball_start_is_the_equal_stiffness_balance(beta0_deg):
    """The joint Newton's ball start (``_ball_start``) is the least-squares balance of the
    four flanks at equal stiffness, sum_i n_i (n_i . (P - T_i)) = 0 with T_i = D_i - h n_i
    (derived in its docstring), so a tangential arc-centre offset (along t_i, which moves no
    approach to first order) leaves it where it is; the mean of the T_i (the former start)
    moves by a quarter of it. Tolerance: round-off of numbers of order 1e-4 m."""
    from tolsim.physics.carriage._batch_kernels import _L_DC, _L_ROWS, _ball_start

    b0 = np.radians(beta0_deg)
    s0, c0 = np.sin(b0), np.cos(b0)
    sx = np.array([-1.0, 1.0, 1.0, -1.0])  # BL, BR, TR, TL (GrooveErrors Notes)
    sy = np.array([-1.0, -1.0, 1.0, 1.0])
    n = np.stack([sx * s0, sy * c0], axis=1)
    t = np.stack([sx * c0, -sy * s0], axis=1)
    rng = np.random.default_rng(3)
    w = np.zeros((_L_ROWS, 4))
    d = rng.normal(scale=1e-4, size=(4, 4, 2))  # D_i of 4 balls [m]
    w[_L_DC:_L_DC + 8] = d.reshape(4, 8).T
    h = 1e-6
    for b in range(4):
        touching = d[b] - h * n
        expected = np.linalg.lstsq(n, np.einsum("ij,ij->i", n, touching), rcond=None)[0]
        assert_allclose(_ball_start(w, b, s0, c0), expected, rtol=0, atol=1e-18)
    shifted = w.copy()
    offsets = rng.normal(scale=3e-6, size=(4, 4))  # tangential offsets of each flank [m]
    shifted[_L_DC:_L_DC + 8] += (offsets[:, :, None] * t[None]).reshape(4, 8).T
    for b in range(4):
        assert_allclose(_ball_start(shifted, b, s0, c0), _ball_start(w, b, s0, c0), rtol=0,
                        atol=1e-18)
        mean_shift = np.abs((offsets[b][:, None] * t).mean(axis=0)).max()
        assert mean_shift > 1e-7  # the mean of the T_i would have moved


def test_a_loose_ball_within_the_tolerance_of_no_force_has_none():
    """``_settle_loose``: a loose ball (no diagonal pair BL-TR, BR-TL carries force) has its
    only balance at no force, so a loose ball whose imbalance max(|r_x|, |r_y|), r = sum_i
    F_i u_i, passes the Newton's test (<= ``limit``) has forces that are the solve's error,
    reported as none; a ball with a loaded diagonal pair, or a loose one beyond the limit
    (not converged), keeps its forces. (Without it a loose ball at the along-track tolerance
    was a one-point contact, unresolved: tests/study/test_carriage_circuit.py,
    test_unloaded_balls_in_the_zone_are_pushed_not_unresolved.) The u_i are unit vectors at
    contact angle deviations dbeta_i from n_i (here 45 deg and 30 deg), and dbeta_i is
    obtained from u_i as ``ball_outputs`` does (arctan2), so the test checks the kernel's
    rebuilt r against r itself, to round-off."""
    from tolsim.physics.carriage._batch_kernels import _settle_loose

    limit = 1.2e-7  # [N]: 1e-8 of a 12 N reference ball force
    for angle in (45.0, 30.0):
        s0, c0 = np.sin(np.radians(angle)), np.cos(np.radians(angle))
        n = np.array([[-s0, -c0], [s0, -c0], [s0, c0], [-s0, c0]])  # BL, BR, TR, TL
        sxy = np.array([1.0, -1.0, 1.0, -1.0])
        rng = np.random.default_rng(3)
        dbeta = rng.uniform(-0.05, 0.05, (1, 6, 4))
        rot = np.stack([np.cos(dbeta[0]), -np.sin(dbeta[0])], axis=-1)  # (6, 4, 2)
        u = np.empty((6, 4, 2))
        for i in range(4):  # u_i: n_i turned by a small random angle ...
            c, sn = rot[:, i, 0], rot[:, i, 1]
            u[:, i, 0] = c * n[i, 0] - sn * n[i, 1]
            u[:, i, 1] = sn * n[i, 0] + c * n[i, 1]
        # ... and dbeta_i read back from u_i as ball_outputs does (its sign convention)
        dbeta[0] = np.arctan2(sxy * (n[:, 1] * u[..., 0] - n[:, 0] * u[..., 1]),
                              n[:, 0] * u[..., 0] + n[:, 1] * u[..., 1])

        def imbalance(f, b, u=u):
            return np.abs((f[:, None] * u[b]).sum(axis=0)).max()

        one = np.array([0.0, 0.0, 0.0, 1.0])
        pair = np.array([1.0, 1.0, 0.0, 0.0])  # two rail flanks
        force = np.zeros((1, 6, 4))
        force[0, 0] = one * 0.999 * limit / imbalance(one, 0)  # loose, within
        force[0, 1] = np.array([0.0, 2e-8, 0.0, 3e-8])  # BR and TL: a diagonal pair, kept
        force[0, 2] = pair * 0.999 * limit / imbalance(pair, 2)  # loose, within
        force[0, 3] = one * 1.001 * limit / imbalance(one, 3)  # loose, just beyond: kept
        force[0, 4] = pair * 1.001 * limit / imbalance(pair, 4)  # the same
        assert force[0, 0, 3] > 1.05 * limit  # a bound on the forces alone would keep it
        side, normal = np.full((1, 6), 7.0), np.full((1, 6), 9.0)
        count = np.array([[1, 2, 2, 1, 2, 0]], dtype=np.int8)
        out = force.copy()
        _settle_loose(0, limit, s0, c0, out, dbeta, side, normal, count)
        settled = [0, 2]
        assert_array_equal(out[0, settled], 0.0)
        assert_array_equal(count[0], [0, 2, 0, 1, 2, 0])
        assert_array_equal(side[0], [0.0, 7.0, 0.0, 7.0, 7.0, 7.0])
        assert_array_equal(normal[0], [0.0, 9.0, 0.0, 9.0, 9.0, 9.0])
        assert_array_equal(out[0, [1, 3, 4, 5]], force[0, [1, 3, 4, 5]])
