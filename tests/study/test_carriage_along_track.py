"""Along-track propagation with a carriage (tolsim issue 12, point 4).

Balls roll through the carriage's loaded zone at -(1 - epsilon) v / 2, leave at its trailing
end, new ones enter at its leading end, the carriage is re-solved at every evaluation
(:mod:`tolsim.study.pipeline.carriage_track`), with the carriage solve taking each ball at its own z
(:func:`tolsim.physics.carriage.solve_carriage_batch` with ``ball_z`` and ``loaded``) and an
optional end relief of the carriage grooves. Each test names its reference and tolerance.
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.io.config import ConfigError, load_config, parse_config
from tolsim.io.netcdf import result_to_dataset
from tolsim.physics.carriage import (
    CARRIAGE_TOLERANCE,
    STATUS_CONVERGED,
    CarriageLayout,
    CarriageLoad,
    end_relief,
    solve_carriage_batch,
)
from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static import DEFAULT_TOLERANCE, GrooveErrors
from tolsim.physics.velocity.models import BALL_THREE_POINT
from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.carriage_track import (
    CarriageBalls,
    CarriageFirstContact,
    CarriageFrame,
    TrackTrace,
    first_contact_carriage_track,
    slot_capacity,
)
from tolsim.study.pipeline.carriage_track_kernels import advance_kernel, carry_slots_kernel
from tolsim.study.pipeline.evaluate import settle_unresolved_loads
from tolsim.study.pipeline.propagation import (
    StepObserver,
    first_contact_tracks,
    integrate,
    pushed_velocity_deviation,
)
from tolsim.study.pipeline.propagation_rules import time_steps
from tolsim.study.sampling import (
    _ar1,
    block_generator,
    entering_capacity,
    error_values,
    field_grid,
    fixed_ball_values,
    moving_ball_values,
    sample_block,
)

ROOT = Path(__file__).resolve().parents[2]
K = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                    TABLE1.poisson_ratio).load_deflection_constant
#: Agreement of two carriage solves of the same balls that stop at the solver's tolerances
#: (tests/physics/test_carriage_batch.py: 1e-9 of the largest force).
AGREEMENT = 1e-9

BASE = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
nominal_contact_angle_deg = 45.0
[motion]
groove_velocity_mm_per_s = 200.0
stroke_mm = {stroke}
[carriage]
balls_per_track = {n}
ball_pitch_mm = 10.05
preload_oversize_um = {preload}
{relief}
[carriage.load]
vertical_N = {vertical}
[[carriage.track]]
x_mm = -20.0
orientation_deg = 90.0
[[carriage.track]]
x_mm = 20.0
orientation_deg = -90.0
[train]
balls = {n}
initial_gap = {gap}
{zone}
{tolerances}
[study]
samples = {samples}
seed = 3
block_size = {block}
propagation = "along_track"
time_steps = {steps}
"""
FIXED_GAP = '{ distribution = "fixed", value_um = 50.0 }'
#: Per-ball tangential offsets of both carriage flanks (made equal per ball in the test that
#: needs the ball's force unchanged), a rail field per track, ball sizes.
TOP_FLANKS = """\
[tolerances.arc_centre_offset_tangential_TR]
distribution = "normal"
std_um = 1.0
scope = "ball"
[tolerances.arc_centre_offset_tangential_TL]
distribution = "normal"
std_um = 1.0
scope = "ball"
"""
ALL_KINDS = TOP_FLANKS + """\
[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.1
scope = "rail"
correlation_length_mm = 30.0
[tolerances.arc_centre_offset_tangential_BL]
distribution = "normal"
std_um = 1.0
scope = "rail"
[tolerances.top_rotation]
distribution = "normal"
std_deg = 0.05
[tolerances.ball_oversize]
distribution = "truncated_normal"
std_um = 0.1
low_um = -0.25
high_um = 0.25
"""


def config(n=6, stroke=100.0, preload=2.0, vertical=0.0, gap=FIXED_GAP, zone="",
           tolerances="", samples=8, block=None, steps=40, relief=""):
    text = BASE.format(n=n, stroke=stroke, preload=preload, vertical=vertical, gap=gap,
                       zone=zone, tolerances=tolerances, samples=samples,
                       block=block or samples, steps=steps, relief=relief)
    return parse_config(text, "along.toml")


def wrapped(n=6, pitch=0.0125):
    """The two-row wrapped guide of tests/physics/test_carriage.py ([Lin2018] Table 1 balls)."""
    return CarriageLayout([-0.025, 0.025], [0.0, 0.0], np.deg2rad([90.0, -90.0]), n, pitch)


# --------------------------------------------------------------------------------------------
# The carriage solve with balls at their own z, in or out of the loaded zone
# --------------------------------------------------------------------------------------------
def sampled_errors(rng, shape, size=1e-6):
    return GrooveErrors(
        arc_centre_offset_normal=rng.normal(0.0, size, shape + (4,)),
        arc_centre_offset_tangential=rng.normal(0.0, size, shape + (4,)),
        bottom_rotation=rng.normal(0.0, 1.75e-3, shape),
        top_rotation=rng.normal(0.0, 1.75e-3, shape),
        bottom_offset=rng.normal(0.0, 2 * size, shape + (2,)),
        top_offset=rng.normal(0.0, 2 * size, shape + (2,)),
        ball_oversize=rng.normal(0.0, 0.5 * size, shape),
    )


FIELDS = ("contact_angle_deviation", "normal_force", "side_load", "normal_load",
          "contact_count", "ball_converged", "displacement", "stiffness", "residual",
          "status", "iterations", "fallback")


@pytest.mark.parametrize("joint", [True, False])
def test_nominal_ball_z_is_the_fixed_path_bit_for_bit(joint):
    # The same equations by the per-assembly groove maps: with every ball at its nominal z
    # and loaded, every output is bit-identical to the default path (measured: 0 difference).
    layout, load = wrapped(), CarriageLoad(120.0, 600.0, 4.0, -2.0, 1.5)
    shape = (12, layout.n_tracks, layout.balls_per_track)
    errors = sampled_errors(np.random.default_rng([12, int(joint)]), shape)
    a = solve_carriage_batch(layout, load, oversize=2e-6, groove_errors=errors, joint=joint)
    b = solve_carriage_batch(layout, load, oversize=2e-6, groove_errors=errors, joint=joint,
                             ball_z=np.broadcast_to(layout.ball_z, shape),
                             loaded=np.ones(shape, bool))
    for name in FIELDS:
        assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)


@pytest.mark.parametrize("joint", [True, False])
def test_an_unloaded_ball_is_a_ball_removed(joint):
    # Twin: the same carriage without the last ball of each track (a layout of n - 1 balls at
    # the same z). Forces agree to AGREEMENT of the largest force and the displacement to
    # 1e-15 m, 1e-13 rad (both solves stop at the solver tolerances; measured 2.3e-14 of the
    # force, 7e-20 m and 3e-18 rad); the unloaded ball carries nothing.
    layout, load = wrapped(), CarriageLoad(-80.0, 900.0, 3.0, 1.0, -1.0)
    n = layout.balls_per_track
    shape = (10, layout.n_tracks, n)
    errors = sampled_errors(np.random.default_rng(5), shape)
    z = np.broadcast_to(layout.ball_z + 0.003, shape)  # the balls moved along the carriage
    mask = np.ones(shape, bool)
    mask[:, :, -1] = False
    out = solve_carriage_batch(layout, load, oversize=2e-6, groove_errors=errors, ball_z=z,
                               loaded=mask, joint=joint)
    small = CarriageLayout(layout.track_x, layout.track_y, layout.track_orientation, n - 1,
                           layout.ball_pitch)
    less = GrooveErrors(**{k: np.asarray(getattr(errors, k))[:, :, :-1]
                           for k in GrooveErrors.__dataclass_fields__})
    ref = solve_carriage_batch(small, load, oversize=2e-6, groove_errors=less,
                               ball_z=z[:, :, :-1], joint=joint)
    assert (out.status == STATUS_CONVERGED).all() and (ref.status == STATUS_CONVERGED).all()
    fmax = ref.normal_force.max()
    assert_allclose(out.normal_force[:, :, :-1], ref.normal_force, rtol=0,
                    atol=AGREEMENT * fmax)
    assert_allclose(out.displacement[:, :2], ref.displacement[:, :2], rtol=0, atol=1e-15)
    assert_allclose(out.displacement[:, 2:], ref.displacement[:, 2:], rtol=0, atol=1e-13)
    assert_array_equal(out.normal_force[:, :, -1], 0.0)
    assert_array_equal(out.contact_count[:, :, -1], 0)
    assert out.ball_converged[:, :, -1].all()
    assert np.isnan(out.contact_angle_deviation[:, :, -1]).all()
    assert np.isnan(out.normal_load[:, :, -1]).all()


def test_ball_z_and_loaded_are_validated():
    layout = wrapped()
    with pytest.raises(ValueError, match="ball_z"):
        solve_carriage_batch(layout, CarriageLoad(vertical_force=100.0), oversize=2e-6,
                             ball_z=np.zeros((3, 4)))
    with pytest.raises(ValueError, match="loaded must be an array of bool"):
        solve_carriage_batch(layout, CarriageLoad(vertical_force=100.0), oversize=2e-6,
                             loaded=np.ones((2, 6)))
    with pytest.raises(ValueError, match="start"):
        solve_carriage_batch(layout, CarriageLoad(vertical_force=100.0), oversize=2e-6,
                             ball_z=layout.ball_z, start=np.zeros(4))


# --------------------------------------------------------------------------------------------
# End relief
# --------------------------------------------------------------------------------------------
def test_end_relief_profile():
    # h(z) = depth ((|z| - (L/2 - l)) / l)^2 beyond L/2 - l (Notes of
    # tolsim.physics.carriage.end_relief): 0 inside, depth at the ends, continuous with a
    # continuous slope (0 at L/2 - l), even in z; exact arithmetic up to round-off (1e-15 relative).
    zone, depth, length = 0.1, 3e-6, 0.02
    z = np.array([0.0, 0.029, 0.03, 0.035, 0.04, 0.05, -0.04, 0.06])
    h = end_relief(z, zone, depth, length)
    assert_allclose(h, [0, 0, 0, depth / 16, depth / 4, depth, depth / 4, depth],
                    rtol=1e-15, atol=0)
    eps = 1e-7
    assert end_relief(0.03 + eps, zone, depth, length) == pytest.approx(
        depth * (eps / length) ** 2, rel=1e-6)
    assert_array_equal(end_relief(z, zone, 0.0, length), 0.0)


def test_end_relief_unloads_the_end_balls_gradually():
    # Wrapped guide, preload o = 3 um, no load: by the mirror symmetry of the tracks the
    # carriage does not move and each ball is alone in its module. Both carriage flanks
    # receding by h re-centre the ball to approaches (o - h)/2 (Notes of
    # tolsim.physics.carriage.end_relief): F = K ((o - h)/2)^1.5, to second order in h/d
    # (measured 7.7e-4 of the unrelieved force; tolerance 2e-3). As a ball rolls towards the
    # end its force falls monotonically; before the relief it is exactly the unrelieved one.
    layout = wrapped()
    zone, o, depth, length = 6 * 0.0125, 3e-6, 2e-6, 0.02
    shift = np.linspace(0.0, 0.0312, 53)  # ball 3 from z = 6.25 mm to the end (37.45 mm)
    shape = (len(shift), 2, 6)
    z = np.broadcast_to(layout.ball_z + shift[:, None, None], shape)
    loaded = np.abs(z) <= 0.5 * zone
    h = end_relief(z, zone, depth, length)
    offset = np.zeros(shape + (4,))
    offset[..., 2:] = h[..., None]
    out = solve_carriage_batch(layout, CarriageLoad(), oversize=o, ball_z=z, loaded=loaded,
                               groove_errors=GrooveErrors(arc_centre_offset_normal=offset))
    plain = solve_carriage_batch(layout, CarriageLoad(), oversize=o, ball_z=z, loaded=loaded,
                                 groove_errors=GrooveErrors(
                                     arc_centre_offset_normal=np.zeros(shape + (4,))))
    assert (out.status == STATUS_CONVERGED).all()
    f = out.normal_force[:, 0, 3, 2]  # F_TR of ball 3 of the left track
    f0 = plain.normal_force[:, 0, 3, 2]
    zb = z[:, 0, 3]
    inside = zb <= 0.5 * zone - length
    relieved = ~inside
    assert inside.sum() >= 5 and relieved.sum() >= 20
    assert_allclose(f[inside], f0[inside], rtol=1e-14)  # (round-off of q ~ 1e-20)
    assert np.all(np.diff(f[relieved]) < 0)
    assert_allclose(f, K * ((o - h[:, 0, 3]) / 2) ** 1.5, rtol=0, atol=2e-3 * f0.max())
    # h = 1.99 um of o = 3 um at the last position: ((3 - 1.99) / 3)^1.5 = 0.195
    assert 0.18 * f0[-1] < f[-1] < 0.21 * f0[-1]
    # zero relief changes nothing, bit for bit
    zero = np.zeros(shape + (4,))
    zero[..., 2:] = end_relief(z, zone, 0.0, length)[..., None]
    none = solve_carriage_batch(layout, CarriageLoad(), oversize=o, ball_z=z, loaded=loaded,
                                groove_errors=GrooveErrors(arc_centre_offset_normal=zero))
    for name in FIELDS:
        assert_array_equal(getattr(none, name), getattr(plain, name), err_msg=name)


def test_end_relief_in_the_study_unloads_a_ball_on_its_way_out():
    # The same in the study (trace of N_y): a perfect ball leaving at the trailing end carries
    # its full preload load until -(L/2 - l) and then less at every step (no load, preload
    # 3 um, relief 2 um over 20 mm; the identical mirrored tracks keep the carriage still).
    c = config(preload=3.0, relief="end_relief_depth_um = 2.0\nend_relief_length_mm = 20.0",
               samples=2, steps=50)
    trace = TrackTrace()
    first_contact_carriage_track(c, sample_block(c, 0), trace)
    half, start = 0.5 * c.train.loaded_zone_length, 0.5 * c.train.loaded_zone_length - 0.02
    zs, ny = [], []
    for k in range(len(trace.time)):  # ball 2, from z = -5.025 mm to its exit
        slot = np.flatnonzero(trace.ball_id[k][0, 0] == 2)
        if slot.size:
            zs.append(trace.midpoint_z[k][0, 0, slot[0]])
            ny.append(trace.normal_load[k][0, 0, slot[0]])
    zs, ny = np.array(zs), np.array(ny)
    inside = zs >= -start
    relieved = (zs < -start) & (zs >= -half)
    assert inside.sum() >= 3 and relieved.sum() >= 3
    assert_allclose(ny[inside], ny[0], rtol=1e-9)
    assert np.all(np.diff(ny[relieved]) < 0) and ny[relieved][0] < ny[0]


# --------------------------------------------------------------------------------------------
# Propagation
# --------------------------------------------------------------------------------------------
def test_perfect_balls_under_a_symmetric_load_never_touch():
    # No tolerances, no relief, a vertical load on the wrapped guide: every ball is the
    # perfect module, whose epsilon is 0 under any load ([Lin2018] Sec. 2.4, insight (1)
    # after Eq. 24); while balls leave and enter and the carriage pitches with them, all balls keep
    # the same epsilon (|epsilon| <= 1e-12; measured 1.1e-16) and no pair closes.
    c = config(vertical=300.0, gap='{ distribution = "uniform", low_um = 0.0, high_um = 100.0 }',
               samples=8, steps=40)
    trace = TrackTrace()
    time, pair, valid, _, state, carriage = first_contact_carriage_track(
        c, sample_block(c, 0), trace)
    assert np.isinf(time).all() and (pair == -1).all() and valid.all()
    eps = np.concatenate([e.ravel() for e in trace.velocity_deviation])
    assert np.nanmax(np.abs(eps)) <= 1e-12
    assert len(trace.exits) >= 8 and len(trace.entries) >= 8
    assert state.valid.all() and (carriage.status == 0).all()


def test_exit_and_entry_times_by_hand():
    # Four perfect balls (epsilon = 0, so each drifts at -v/2 = -0.1 m/s relative to the
    # carriage), fixed gap g = 50 um, D = 10 mm, zone L = 50 mm, stroke 100 mm (0.5 s).
    # At t = 0 the train is centred: z_j = (j - 1.5)(D + g) = -15.075, -5.025, 5.025, 15.075 mm.
    # Exit of ball j when z_j - 0.1 t = -L/2: t = (z_j + 0.025) / 0.1 = 0.09925, 0.19975,
    # 0.30025, 0.40075 s. Entering ball k enters when the ball ahead is at L/2 - D - g =
    # 14.95 mm: the first at (15.075 - 14.95) / 0.1 = 0.00125 s, then every (D + g) / 0.1 =
    # 0.1005 s: 0.00125, 0.10175, 0.20225, 0.30275, 0.40325 s (the next at 0.50375 s is
    # beyond the stroke); each enters at L/2 and sits D + g behind the ball ahead. Linear
    # interpolation within a step is exact here: tolerance 1e-12 s.
    c = config(n=4, zone="loaded_zone_length_mm = 50.0", samples=2, steps=100)
    trace = TrackTrace()
    first_contact_carriage_track(c, sample_block(c, 0), trace)
    exits, entries = trace.events("exits"), trace.events("entries")
    for a in range(2):
        for track in range(2):
            mine = exits[(exits[:, 0] == a) & (exits[:, 1] == track)]
            assert_array_equal(mine[:, 2], [0, 1, 2, 3])
            assert_allclose(mine[:, 3], [0.09925, 0.19975, 0.30025, 0.40075], rtol=0,
                            atol=1e-12)
            mine = entries[(entries[:, 0] == a) & (entries[:, 1] == track)]
            assert_array_equal(mine[:, 2], [4, 5, 6, 7, 8])
            assert_allclose(mine[:, 3], 0.00125 + 0.1005 * np.arange(5), rtol=0, atol=1e-12)
    # after every step the balls are D + g apart (the entering ones too), and 4 or 5 are in
    # the zone
    for z in trace.ball_z:
        gaps = np.diff(z, axis=2) - 0.01
        assert_allclose(gaps[np.isfinite(gaps)], 50e-6, rtol=0, atol=1e-12)
        count = np.isfinite(z).sum(axis=2)
        assert np.all((count == 4) | (count == 5))


class Following(StepObserver):
    """Follows the given rows and records the rows of every step it sees."""

    def __init__(self, rows):
        self.rows, self.seen = rows, []

    def begin(self, block, position):
        self.mask = np.isin(np.arange(block.size), self.rows)

    def following(self):
        return self.mask

    def observe(self, step):
        self.seen.append(step.rows.tolist())


class _StartSolved(CarriageFrame):
    """The carriage frame with the carriage solved at the start of every step as well (two
    solves per step, as before issue 24's speed work), counting the solves."""

    def __init__(self, config, block, start_solved):
        super().__init__(config, block)
        self.start_solved, self.calls = start_solved, 0
        call = self.evaluation

        def counted(*args):
            self.calls += 1
            return call(*args)

        self.evaluation = counted

    def start(self, k, t, position):
        if k > 0 and self.start_solved:
            self._carried()  # the balls that entered (``fresh``), which move from their entry
            return CarriageBalls(*self.evaluation(position, self.ids, t, self.rows))
        return super().start(k, t, position)


class _StartStates(StepObserver):
    """Checks every step's start balls as the observers see them: loaded exactly where a
    ball is in the zone at the step's start (so an entering ball is in its first step's
    trains), and epsilon_1 finite wherever a loaded ball is resolved."""

    def __init__(self, half_zone):
        self.half_zone, self.steps, self.fresh = half_zone, 0, 0

    def observe(self, step):
        with np.errstate(invalid="ignore"):
            inside = (step.ball_id >= 0) & (np.abs(step.position) <= self.half_zone)
        assert_array_equal(step.state1.loaded, inside)
        state = step.state1
        assert np.isfinite(state.velocity_deviation[state.loaded & state.valid]).all()
        assert len(state.balls.velocity_deviation) == state.loaded.sum()
        unloaded = np.zeros(state.loaded.shape, dtype=bool)
        unloaded[state.loaded] = state.balls.unloaded
        assert_array_equal(state.unloaded, unloaded)
        self.steps += 1


def test_the_carriage_is_solved_once_per_step():
    # issue 24 (speed): the carriage frame solves the carriage once per step (the midpoint;
    # epsilon_1 is the previous midpoint's, carried by ball id through the exits and
    # entries, Notes of first_contact_carriage_track), plus once at t = 0; before, twice per
    # step. epsilon_1 only places the midpoint, so the first contacts are those with the
    # start solved: on configs/carriage_preload.toml (2 000 assemblies, seed 12, the
    # automatic 10 steps) the same 509 assemblies touch at the same pairs, times within
    # 7.0e-4 s, mean 5.8e-6 s (measured); here one block of 256. Tolerance 1e-3 s: the
    # step's own error of the time to contact there is some 7 ms (time_steps' Notes).
    c = load_config(ROOT / "configs" / "carriage_preload.toml").with_overrides(samples=256)
    b = sample_block(c, 0)
    out = []
    for start_solved in (False, True):
        frame = _StartSolved(c, b, start_solved)
        first, starts = CarriageFirstContact(frame), _StartStates(frame.half_zone)
        integrate(c, frame, [first, starts])
        out.append((first.time, first.pair, first.valid, frame.calls, starts.steps))
    (t1, p1, v1, calls1, n1), (t2, p2, v2, calls2, n2) = out
    steps = time_steps(c)
    assert (calls1, calls2) == (steps + 1, 2 * steps)
    assert n1 == n2 > 0
    assert_array_equal(p1, p2)
    assert_array_equal(v1, v2)
    assert_array_equal(np.isfinite(t1), np.isfinite(t2))
    assert 30 < np.isfinite(t1).sum() < 220  # contacts are exercised
    hit = np.isfinite(t1)
    assert_allclose(t1[hit], t2[hit], rtol=0, atol=1e-3)


@pytest.mark.parametrize("tolerance, bound", [(None, 1e-4), (1e-2, None)])
def test_the_track_tolerance_moves_the_first_contacts_far_less_than_the_step(
        monkeypatch, tolerance, bound):
    # The solves along the track stop at TRACK_TOLERANCE (1e-4) instead of the solver's
    # defaults (1e-11 for the carriage, 1e-12 for each ball; carriage_track's Notes). On
    # configs/carriage_preload.toml (2 x 4 096 assemblies, seed 12, measured against 1e-8)
    # the same assemblies touched at the same pairs, first-contact times within 3.3e-5 s,
    # initial epsilon within 2.6e-7. Here one block of 256 against the defaults, bound 1e-4 s:
    # the step's own error there is some 7 ms (time_steps' Notes). The test can fail: at 1e-2
    # the times move by more than the bound.
    import tolsim.study.pipeline.carriage_track as track

    c = load_config(ROOT / "configs" / "carriage_preload.toml").with_overrides(samples=256)
    b = sample_block(c, 0)
    solve = track.solve_carriage_batch
    out = []
    for tol, ball_tol in ((None, None), (CARRIAGE_TOLERANCE, DEFAULT_TOLERANCE)):
        if tol is None and tolerance is not None:
            tol = ball_tol = tolerance
        if tol is not None:
            monkeypatch.setattr(track, "solve_carriage_batch", partial_tolerance(
                solve, tol, ball_tol))
        out.append(first_contact_carriage_track(c, b)[:2])
        monkeypatch.setattr(track, "solve_carriage_batch", solve)
    (t1, p1), (t2, p2) = out
    hit = np.isfinite(t2)
    assert 20 < hit.sum() < 200  # contacts are exercised
    change = np.abs(t1[hit] - t2[hit]).max()
    if bound is None:
        assert change > 1e-4
    else:
        assert_array_equal(np.isfinite(t1), hit)
        assert_array_equal(p1, p2)
        assert change <= bound


def partial_tolerance(solve, tol, ball_tol):
    """``solve`` (solve_carriage_batch) with its tolerances replaced."""
    def solved(*args, **kwargs):
        kwargs.update(tol=tol, ball_tol=ball_tol)
        return solve(*args, **kwargs)
    return solved


class _Growing(StepObserver):
    """Follows row 1, then rows 0 and 1: a row followed again after a step without it."""

    def __init__(self):
        self.steps = 0

    def following(self):
        return np.array([self.steps > 0, True, False])

    def observe(self, step):
        self.steps += 1


def test_a_row_followed_again_is_refused():
    # The carried states (CarriageFrame._carried) need the rows followed to shrink only, as
    # every observer's do; a row followed again would read another row's balls: refused.
    c = config(samples=3, steps=4)
    with pytest.raises(RuntimeError, match="followed again"):
        integrate(c, CarriageFrame(c, sample_block(c, 0)), [_Growing()])


def test_carry_slots_follows_the_balls_by_id():
    # carry_slots_kernel against a plain lookup: old slots with exits at the trailing end
    # (ids shift down), entries at the end (new ids, fresh), empty slots (-1), unloaded
    # slots, and a subset of the old rows in a new order of rows.
    rng = np.random.default_rng(3)
    m, tracks, slots = 5, 2, 6
    old_id = np.full((m, tracks, slots), -1, dtype=np.int64)
    new_id = np.full((m, tracks, slots), -1, dtype=np.int64)
    for a in range(m):
        for t in range(tracks):
            n = rng.integers(2, slots + 1)
            old_id[a, t, :n] = 10 * t + np.arange(n)
            gone, came = rng.integers(0, 3), rng.integers(0, 3)
            ids = list(range(10 * t + gone, 10 * t + n)) + [100 + k for k in range(came)]
            ids = ids[:slots]
            new_id[a, t, :len(ids)] = ids
    old_loaded = (old_id >= 0) & (rng.random(old_id.shape) < 0.8)
    old_eps = np.where(old_loaded, rng.normal(size=old_id.shape), np.nan)
    old_valid = ~old_loaded | (rng.random(old_id.shape) < 0.9)
    old_unloaded = old_loaded & (rng.random(old_id.shape) < 0.2)
    rows = np.array([0, 2, 3])
    new = new_id[rows]
    shape = new.shape
    loaded, valid, unloaded, fresh = (np.empty(shape, dtype=bool) for _ in range(4))
    eps, index = np.empty(shape), np.empty(shape, dtype=np.int64)
    carry_slots_kernel(old_id, old_loaded, old_eps, old_valid, old_unloaded, rows, new, loaded,
                       eps, valid, unloaded, fresh, index)
    flat = np.cumsum(old_loaded.reshape(-1)).reshape(old_id.shape) - 1
    for r, a in enumerate(rows):
        for t in range(tracks):
            for j in range(slots):
                ident = new[r, t, j]
                where = np.flatnonzero(old_id[a, t] == ident) if ident >= 0 else []
                if len(where) == 0:
                    assert (loaded[r, t, j], np.isnan(eps[r, t, j]), valid[r, t, j],
                            unloaded[r, t, j], fresh[r, t, j], index[r, t, j]) == (
                                False, True, True, False, ident >= 0, -1)
                    continue
                p = where[0]
                assert not fresh[r, t, j]
                assert loaded[r, t, j] == old_loaded[a, t, p]
                assert valid[r, t, j] == old_valid[a, t, p]
                assert unloaded[r, t, j] == old_unloaded[a, t, p]
                assert_array_equal(eps[r, t, j], old_eps[a, t, p])
                assert index[r, t, j] == (flat[a, t, p] if old_loaded[a, t, p] else -1)
    assert fresh.any() and (~fresh & (new >= 0)).any() and (new < 0).any() and unloaded.any()


def test_the_one_loop_integrates_the_rows_an_observer_follows():
    # issue 22 (one along-track loop, propagation.integrate): in the carriage frame only the
    # assemblies some observer still follows are evaluated (exact row indices, every step), and
    # the loop stops before any evaluation when no observer follows a row.
    c = config(samples=3, steps=4)
    one = Following([1])
    integrate(c, CarriageFrame(c, sample_block(c, 0)), [one])
    assert one.seen == [[1]] * 4
    none, frame = Following([]), CarriageFrame(c, sample_block(c, 0))
    integrate(c, frame, [none])
    assert none.seen == [] and frame.initial_state is None


def test_along_track_agrees_with_constant_propagation_before_any_ball_moves_on():
    # Construction: preload only, no load, every ball with equal tangential offsets of both
    # carriage flanks (TR = TL: by the mirror symmetry of the module its forces change only to
    # second order, (e_t/d)^2 ~ 6e-6, so the carriage stays put and each ball's epsilon is
    # its own, ~ e_t / (2 d)); no rail fields; a stroke of 8 mm, so that the balls drift 4 mm
    # and none leaves or enters (the train fills the zone with about 5 mm to spare at each
    # end). Then epsilon is constant along the track and the contact time is the constant
    # propagation's closed form with the t = 0 epsilon (tolsim.study.pipeline.propagation, mode a).
    # Measured agreement 7.2e-7 relative (the small changes of epsilon as the train moves
    # under the carriage's yaw and pitch from the balls' own errors; 5.9e-7 with the solves
    # at 1e-8 instead of TRACK_TOLERANCE, 1e-4); tolerance 5e-6. With the
    # drift of a ball of the wrong sign, -(1 + epsilon) v / 2, the other pairs would close.
    c = config(stroke=8.0, gap='{ distribution = "uniform", low_um = 0.0, high_um = 40.0 }',
               tolerances=TOP_FLANKS, samples=48, steps=40)
    block = sample_block(c, 0)
    block.normals["arc_centre_offset_tangential_TL"] = block.normals[
        "arc_centre_offset_tangential_TR"]
    trace = TrackTrace()
    time, pair, valid, _, state, _ = first_contact_carriage_track(c, block, trace)
    assert not trace.exits and not trace.entries
    assert valid.all() and state.valid.all()
    t_ref, pair_ref = first_contact_tracks(block.initial_gap, state.velocity_deviation,
                                           c.motion.groove_velocity, c.motion.duration,
                                           c.n_tracks)
    hit = np.isfinite(t_ref)
    assert 5 <= hit.sum() <= len(hit) - 5  # both outcomes exercised
    assert_array_equal(np.isfinite(time), hit)
    assert_array_equal(pair, pair_ref)
    assert_allclose(time[hit], t_ref[hit], rtol=5e-6)


def test_an_unloaded_ball_in_the_zone_is_pushed_along_as_in_constant_propagation():
    # issue 25: the construction of the test above, with one ball of each track undersized
    # by more than the preload (2 um preload, -3 um: 1 um of clearance, so no loaded
    # contact): it is unloaded, pushed along between its loaded neighbours, and the first
    # contact that carries force is the constant propagation's with its pushed epsilon
    # (pushed_velocity_deviation, first_contact_tracks). Measured agreement 7.0e-6 relative:
    # the solves' TRACK_TOLERANCE (1e-4; 2.8e-7 with the solves at 1e-8); tolerance 2e-5.
    # Before, every assembly with an unloaded ball in its zone was unresolved (valid False).
    sizes = '[tolerances.ball_oversize]\ndistribution = "normal"\nstd_um = 1.0\nscope = "ball"\n'
    c = config(stroke=8.0, gap='{ distribution = "uniform", low_um = 0.0, high_um = 40.0 }',
               tolerances=TOP_FLANKS + sizes, samples=48, steps=40)
    block = sample_block(c, 0)
    block.normals["arc_centre_offset_tangential_TL"] = block.normals[
        "arc_centre_offset_tangential_TR"]
    block.normals["ball_oversize"][:] = 0.0
    block.normals["ball_oversize"][:, [2, 6 + 3]] = -3.0  # -3 um
    trace = TrackTrace()
    time, pair, valid, _, state, _ = first_contact_carriage_track(c, block, trace)
    assert not trace.exits and not trace.entries
    unloaded = state.unloaded
    assert_array_equal(np.flatnonzero(unloaded[0]), [2, 6 + 3]) and unloaded.sum() == 2 * 48
    assert valid.all() and state.accounted.all()
    eps = pushed_velocity_deviation(block.initial_gap, state.velocity_deviation, unloaded,
                                    c.n_tracks)
    t_ref, pair_ref = first_contact_tracks(block.initial_gap, eps, c.motion.groove_velocity,
                                           c.motion.duration, c.n_tracks)
    hit = np.isfinite(t_ref)
    assert 5 <= hit.sum() <= len(hit) - 5  # both outcomes exercised
    assert_array_equal(np.isfinite(time), hit)
    assert_allclose(time[hit], t_ref[hit], rtol=2e-5)
    # the pair: the same contact (a run's pairs close together, named by either)
    run = {1: 1, 2: 1, 5 + 2: 5 + 2, 5 + 3: 5 + 2}
    same = [run.get(a, a) == run.get(b, b) for a, b in zip(pair[hit], pair_ref[hit],
                                                         strict=True)]
    assert all(same)
    # the unloaded ball stays between its neighbours until the first contact
    d = 2 * c.bearing.ball_radius
    for k, t in enumerate(trace.time):
        rows = trace.rows[k][t < time[trace.rows[k]]]
        z = trace.ball_z[k][np.isin(trace.rows[k], rows)]
        gaps = np.diff(z, axis=2) - d
        assert (gaps[np.isfinite(gaps)] >= -1e-12).all()  # (NaN: the empty slot)


def test_end_relief_deeper_than_the_approach_leaves_nothing_unresolved():
    # issue 25: configs/carriage_preload.toml without preload and with an end relief of 2 um
    # over 15 mm: the relief opens every contact of some balls near the ends (measured: 97 of
    # 100 assemblies had one, tolsim run --samples 100); they are unloaded, pushed along, and
    # no assembly is left unresolved (before: 97 of 100).
    text = (ROOT / "configs" / "carriage_preload.toml").read_text().replace(
        "preload_oversize_um = 2.0", "preload_oversize_um = 0.0").replace(
        "# end_relief_depth_um = 1.0", "end_relief_depth_um = 2.0").replace(
        "# end_relief_length_mm", "end_relief_length_mm").replace(
        "[study]", '[study]\npropagation = "along_track"\ntime_steps = 20')
    c = parse_config(text, "carriage_preload.toml").with_overrides(samples=8)
    frame, seen = CarriageFrame(c, sample_block(c, 0)), Unloaded()
    first = CarriageFirstContact(frame)
    integrate(c, frame, [first, seen])
    assert seen.count > 0  # unloaded balls in the zone
    assert first.valid.all()


def test_settle_unresolved_loads_opens_the_balls_below_the_solves_resolution():
    # source: the Notes of settle_unresolved_loads: a loaded ball whose every force is at or
    # below tolerance x the largest force of its assembly (here 1e-4 x 2.0 N = 2e-4 N) is
    # unloaded (forces 0); a ball with one force above it, the balls outside the zone and an
    # assembly that was not solved (NaN) keep theirs, bit for bit
    force = np.zeros((3, 2, 3, 4))
    force[0, 0, 0] = [3e-14, 1e-19, 0.0, 6.3e-5]  # all below 2e-4 N: unloaded
    force[0, 0, 1] = [2.0, 0.0, 2.0, 1e-9]  # the assembly's largest force
    force[0, 1, 0] = [1e-5, 1e-5, 1e-5, 3e-4]  # one force above the floor: kept
    force[0, 1, 1] = [1e-6, 0.0, 0.0, 0.0]  # outside the zone: not a loaded ball
    force[1] = np.nan  # not solved
    force[2, 0, 0] = [1e-9, 0.0, 1e-9, 0.0]  # the assembly's only load: its own scale
    loaded = np.ones((3, 2, 3), dtype=bool)
    loaded[0, 1, 1] = False
    got = settle_unresolved_loads(force, loaded, 1e-4)
    want = force.copy()
    want[0, 0, 0] = 0.0
    assert_array_equal(got, want)
    untouched = force.copy()
    untouched[0, 0, 0] = [3e-14, 1e-19, 0.0, 3e-4]
    assert settle_unresolved_loads(untouched, loaded, 1e-4) is untouched


def _without_preload_or_load():
    """configs/carriage_preload.toml without preload or load, 100 assemblies (seed 12)."""
    text = (ROOT / "configs" / "carriage_preload.toml").read_text().replace(
        "preload_oversize_um = 2.0", "preload_oversize_um = 0.0").replace(
        "vertical_N = 300.0", "vertical_N = 0.0").replace(
        "pitch_moment_N_m = 2.0", "pitch_moment_N_m = 0.0")
    return parse_config(text, "carriage_preload.toml").with_overrides(samples=100)


def test_a_ball_below_the_solves_force_resolution_is_unloaded():
    # found by an edge-case audit: configs/carriage_preload.toml without preload or load, seed 12,
    # 100 assemblies (tolsim run --samples 100 --save-samples 100): assembly 41's ball 6 of
    # track 1 had the forces [3e-14, 1e-19, 0, 6.3e-5] N beside a largest force of 0.73 N,
    # was taken for a three-point ball and got epsilon = -1.0044 from the full model (a ball
    # rolling backwards; epsilon std 2.8 % over the study instead of 0.13 %). Its forces are
    # below TRACK_TOLERANCE (1e-4) of the largest: unloaded. Bound: every resolved ball's
    # |epsilon| below 1 % (measured after the fix: 0.71 % at most). Since session 28 an
    # assembly with a contact below LIGHT_CONTACT of its largest is solved on to
    # POLISH_TOLERANCE (1e-8), whose floor (7e-9 N here) resolves the ball: three-point,
    # 2.2e-5 N on BR and TL and 1.5e-8 N on TR (the two of a diagonal equal, as a balance
    # with no load between them demands), epsilon 3.4e-4: a load, no longer the solve's noise.
    c = _without_preload_or_load()
    state = first_contact_carriage_track(c, sample_block(c, 0))[4]
    force = state.normal_force[41, 18]
    assert not state.unloaded[41, 18] and state.regime[41, 18] == BALL_THREE_POINT
    assert force[0] == 0.0 and 0.0 < force[2] < 1e-7
    assert_allclose(force[[1, 3]], 2.21e-5, rtol=0.01)
    assert abs(state.velocity_deviation[41, 18]) < 1e-3
    assert np.nanmax(np.abs(state.velocity_deviation)) < 0.01


def test_an_assembly_with_a_ball_unresolved_along_the_track_says_why():
    # An edge-case audit: configs/carriage_preload.toml with 2 deg rail rotation, 12 um rail
    # offsets, +-6 deg and +-30 um carriage tolerances, seed 12, 100 assemblies: assembly 6
    # has a ball (track 1, slot 11) that the full model cannot solve at the first midpoint
    # (t = 0.025 s, 12 to 39 N on its four contacts) and, in the same step, a contact of two
    # resolved balls at 0.0442 s. Its contact is certain and counted; it was neither valid
    # nor unresolved (100 contacts, 99 valid, 0 unresolved of 100) and no ball count showed
    # the ball. Exact counts (measured with tolsim run --samples 100).
    text = (ROOT / "configs" / "carriage_preload.toml").read_text()
    for old, new in (("std_deg = 0.1", "std_deg = 2.0"), ("std_um = 1.0", "std_um = 12.0"),
                     ("low_deg = -0.3", "low_deg = -6.0"), ("high_deg = 0.3", "high_deg = 6.0"),
                     ("low_um = -3.0\nhigh_um = 3.0", "low_um = -30.0\nhigh_um = 30.0")):
        text = text.replace(old, new, 1 if "um = -3" in old else -1)
    c = parse_config(text, "carriage_preload.toml").with_overrides(samples=100)
    unresolved = np.zeros(100, dtype=np.int64)
    time, _, valid, _, state, _ = first_contact_carriage_track(c, sample_block(c, 0),
                                                               unresolved=unresolved)
    assert state.accounted.all()  # every ball at t = 0 has an answer
    assert np.flatnonzero(~valid).tolist() == [6] and np.isfinite(time[6])
    assert unresolved.tolist() == [0] * 6 + [1] + [0] * 93
    acc = run_study(c).statistics
    assert (acc.n_assemblies, acc.n_assemblies_valid, acc.n_contact_untimed, acc.n_unresolved,
            acc.n_contact, acc.n_unresolved_along_track) == (100, 99, 1, 0, 100, 1)
    ds = result_to_dataset(run_study(c))
    assert int(ds.n_assemblies_contact_untimed) == 1
    assert int(ds.n_balls_unresolved_along_track) == 1


def test_unresolved_trains_along_the_track_are_counted_by_their_balls():
    # An edge-case audit: configs/carriage_preload.toml without preload or load, seed 12,
    # 100 assemblies: 8 trains (5 after the force floor of settle_unresolved_loads) were
    # unresolved while every ball count at t = 0 was 0. Each is unresolved by a lightly
    # loaded ball (forces 1e-5 to 5e-4 N beside 0.2 to 0.7 N) that the full model could not
    # certify at a midpoint along the track; no slots or entering balls ran out. Exact counts:
    # 6 since session 28, whose polishing solves (LIGHT_CONTACT) resolve loads down to 1e-8
    # of the largest instead of 1e-4, and so one more lightly loaded ball. 11 since session
    # 30, at the automatic 40 steps of a light preload (propagation_rules.light_preload;
    # before, 10): more evaluations meet more such balls, the same 11 assemblies at 80 steps
    # (and 6 at 10 steps, with the full model's divergence guard as without it).
    c = _without_preload_or_load()
    assert time_steps(c) == 40
    unresolved = np.zeros(100, dtype=np.int64)
    time, _, valid, _, state, _ = first_contact_carriage_track(c, sample_block(c, 0),
                                                               unresolved=unresolved)
    assert state.accounted.all()
    assert (~valid).sum() == 11
    assert np.all(unresolved[~valid] >= 1) and np.all(unresolved[valid] == 0)


class Unloaded(StepObserver):
    """Counts the unloaded balls in the zone at the start of every step."""

    count = 0

    def following(self):
        return False

    def observe(self, step):
        self.count += int(step.state1.unloaded.sum())


def test_results_do_not_depend_on_batching_or_threads(other_thread_count):
    # Each assembly's Newton starts from its own previous solution and every kernel solves an
    # assembly by the same operations in any batch and on any number of threads
    # (solve_carriage_batch Notes, "Many assemblies at once"): the first block alone, as part of
    # two blocks drawn together, and on one thread give bit-identical results.
    c = config(vertical=300.0, gap='{ distribution = "uniform", low_um = 0.0, high_um = 30.0 }',
               tolerances=ALL_KINDS, relief="end_relief_depth_um = 1.0\n"
               "end_relief_length_mm = 15.0", samples=24, block=12, steps=30)
    alone = first_contact_carriage_track(c, sample_block(c, 0))
    both = first_contact_carriage_track(c, sample_block(c, 0, 2))
    serial = other_thread_count(first_contact_carriage_track, c, sample_block(c, 0))
    assert np.isfinite(alone[0]).sum() >= 2  # contacts happen
    for other, rows in ((both, slice(0, 12)), (serial, slice(None))):
        for k in range(3):
            assert_array_equal(other[k][rows], alone[k])
        assert_array_equal(other[4].velocity_deviation[rows], alone[4].velocity_deviation)
        assert_array_equal(other[5].displacement[rows], alone[5].displacement)


def test_run_study_with_a_carriage_along_track():
    # The runner's along_track branch: per block the carriage integration, the t = 0 balls
    # into the epsilon statistics and the t = 0 carriages into the carriage statistics; the
    # result does not depend on the chunking (blocks merged in order) and writes a dataset.
    c = config(vertical=300.0, gap='{ distribution = "uniform", low_um = 0.0, high_um = 60.0 }',
               tolerances=ALL_KINDS, samples=24, block=8, steps=20)
    one = run_study(c, chunk_blocks=1)
    three = run_study(c, chunk_blocks=3)
    a, b = one.statistics, three.statistics
    assert int(a.n_assemblies) == 24 and int(a.carriage_count) == 24
    for name in ("n_contact", "n_unresolved", "time_histogram", "pair_count", "eps_histogram",
                 "carriage_mean", "carriage_max"):
        assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
    assert a.eps_mean == b.eps_mean
    hits = sum(int(np.isfinite(first_contact_carriage_track(c, sample_block(c, k))[0]).sum())
               for k in range(3))
    assert hits == int(a.n_contact) > 0
    assert len(a.pair_count) == c.n_tracks * (c.train.balls - 1)
    ds = result_to_dataset(one)
    assert "contact_probability" in ds


# --------------------------------------------------------------------------------------------
# Sampling: entering balls and rail fields per track
# --------------------------------------------------------------------------------------------
def test_entering_draws_come_after_the_others():
    # sampling.py module docstring, draw 5: the entering balls are drawn after everything
    # else, so the per-assembly, ball and gap draws of a carriage study are those of the
    # same study with constant propagation (whose draw 4, the gaps, precedes the fields).
    c = config(tolerances=ALL_KINDS, gap='{ distribution = "uniform", low_um = 0.0, '
               'high_um = 60.0 }', samples=16)
    constant = replace(c, study=replace(c.study, propagation="constant"))
    a, b = sample_block(c, 0), sample_block(constant, 0)
    assert_array_equal(a.initial_gap, b.initial_gap)
    for t in c.tolerances:
        if t.correlation_length == 0:
            assert_array_equal(a.normals[t.source], b.normals[t.source])
    capacity = entering_capacity(c)
    assert capacity == int(np.floor(1.05 * 0.1 / 0.02)) + 2
    assert a.entering_gap.shape == (16, 2 * capacity) and b.entering_gap is None
    assert set(a.entering) == {t.source for t in c.tolerances if t.scope == "ball"}


def test_rail_fields_per_track_twin():
    # Twin of the documented recipe (sampling.py draws 1-5): one generator per block, the
    # draws in order, a field per track by the stationary AR(1) recursion on its grid
    # (phi = exp(-spacing / l)); the two tracks' fields are those rows, independent.
    c = config(tolerances=ALL_KINDS, gap='{ distribution = "uniform", low_um = 0.0, '
               'high_um = 60.0 }', samples=16)
    block = sample_block(c, 0)
    rng = block_generator(c.study.seed, 0)
    tracks, n = 2, c.train.balls
    origin, spacing, points = field_grid(c)["bottom_rotation"]
    rng.standard_normal((16, tracks * 2))  # factors: BL and top_rotation, per track
    for _ in range(3):  # ball sources: TR, TL, ball_oversize
        rng.standard_normal((16, tracks * n))
    rng.standard_normal((16, tracks * (n - 1)))  # gaps
    innovations = rng.standard_normal((16, tracks * points)).reshape(32, points)
    phi = np.full((1, points - 1), np.exp(-spacing / 0.03))
    ref = _ar1(phi, np.sqrt(1.0 - phi * phi), innovations)
    field = block.fields["bottom_rotation"]
    assert field.tracks == 2
    assert_array_equal(field.values, ref)
    gaps = rng.standard_normal((16, tracks * entering_capacity(c)))
    assert_array_equal(block.entering_gap,
                       np.maximum(c.train.initial_gap.from_normal(gaps), 0.0))
    # track t of assembly a reads row a * tracks + t
    s = np.array([[origin + 3 * spacing, origin + 7.5 * spacing]])
    pos = np.repeat(s, 16, axis=0)  # track 0 at one position, track 1 at another
    at = field.at(pos)
    assert_allclose(at[:, 0], ref[0::2, 3], rtol=1e-13)  # (round-off of the grid index)
    assert_allclose(at[:, 1], 0.5 * (ref[1::2, 7] + ref[1::2, 8]), rtol=1e-13)


def test_moving_ball_values_at_the_start_are_the_study_values():
    # The initial balls at their t = 0 rail positions: the values of error_values (every
    # source, correlated or not), bit for bit.
    c = config(tolerances=ALL_KINDS, gap='{ distribution = "uniform", low_um = 0.0, '
               'high_um = 60.0 }', samples=16)
    block = sample_block(c, 0)
    ref = error_values(c, block)
    n, slots = c.train.balls, slot_capacity(c)
    ids = np.full((16, 2, slots), -1)
    ids[:, :, :n] = np.arange(n)
    pos = np.zeros((16, 2, slots))
    pos[:, :, :n] = block.initial_position.reshape(16, 2, n)
    values = moving_ball_values(c, block, ids, pos)
    for source, v in ref.items():
        assert_array_equal(values[source][:, :, :n].reshape(16, 2 * n),
                           np.broadcast_to(v, (16, 2 * n)), err_msg=source)


def correlated_study():
    """The study of every source kind with TR and TL correlated (16 assemblies) and its first
    block."""
    group = ('[[correlation]]\nsources = ["arc_centre_offset_tangential_TR", '
             '"arc_centre_offset_tangential_TL"]\ncoefficient = 0.8\n')
    c = config(tolerances=ALL_KINDS + group, gap='{ distribution = "uniform", low_um = 0.0, '
               'high_um = 60.0 }', samples=16)
    return c, sample_block(c, 0)


def random_slots(c, seed, rows):
    """Random ball ids (initial, entering and empty slots) and rail positions (rows, 2, S)."""
    rng = np.random.default_rng(seed)
    slots = slot_capacity(c)
    ids = rng.integers(-1, c.train.balls + entering_capacity(c), size=(rows, 2, slots))
    return ids, rng.uniform(-0.05, 0.05, size=(rows, 2, slots))


def test_fixed_ball_values_give_the_same_values_bit_for_bit():
    # The carriage frame transforms the sources that do not move with the balls once per block
    # (fixed_ball_values) and reads them at every step: the values of moving_ball_values
    # without them, bit for bit, for initial and entering balls, empty slots and a subset of
    # the rows (the transforms are elementwise; correlated sources are left to it).
    c, block = correlated_study()
    fixed = fixed_ball_values(c, block)
    assert set(fixed) == {"ball_oversize", "top_rotation", "arc_centre_offset_tangential_BL"}
    rows = np.array([1, 4, 5, 11, 15])
    ids, pos = random_slots(c, 3, len(rows))
    ref = moving_ball_values(c, block, ids, pos, rows)
    got = moving_ball_values(c, block, ids, pos, rows, fixed)
    assert list(got) == list(ref)
    for source, v in ref.items():
        assert_array_equal(got[source], v, err_msg=source)


def test_moving_ball_values_of_some_sources_are_those_of_all():
    # ``sources=``: only those sources, and every source of a correlation group holding one
    # (the group is transformed whole), with the values of the call for all sources, bit for
    # bit (the circuit's filling reads ball_oversize alone). Without the group rule the
    # correlated TR would not be its correlated value.
    c, block = correlated_study()
    ids, pos = random_slots(c, 5, 16)
    every = moving_ball_values(c, block, ids, pos)
    some = moving_ball_values(c, block, ids, pos, sources=("ball_oversize",))
    assert list(some) == ["ball_oversize"]
    assert_array_equal(some["ball_oversize"], every["ball_oversize"])
    tied = moving_ball_values(c, block, ids, pos, sources=("arc_centre_offset_tangential_TL",))
    assert set(tied) == {"arc_centre_offset_tangential_TR", "arc_centre_offset_tangential_TL"}
    for source, v in tied.items():
        assert_array_equal(v, every[source], err_msg=source)

def advance_twin(z0, z1, ids, ok, count, entered, gap, half, d, balls, t0, dt):
    """Plain-Python twin of advance_kernel
    (Notes of tolsim.study.pipeline.carriage_track.first_contact_carriage_track):
    returns the new slots, the exits and entries [(a, track, id, time)] and the overflow."""
    m, tracks, slots = z1.shape
    out_z, out_id = np.full(z1.shape, np.nan), np.full(z1.shape, -1)
    out_ok, out_count = np.ones(z1.shape, bool), count.copy()
    out_entered, overflow = entered.copy(), np.zeros(m, bool)
    exits, entries = [], []
    for a in range(m):
        for t in range(tracks):
            balls_in = []
            for j in range(count[a, t]):
                if z1[a, t, j] < -half:
                    frac = (z0[a, t, j] + half) / (z0[a, t, j] - z1[a, t, j])
                    exits.append((a, t, ids[a, t, j], t0 + min(max(frac, 0), 1) * dt))
                else:
                    balls_in.append([z0[a, t, j], z1[a, t, j], ids[a, t, j], ok[a, t, j]])
            if not balls_in:
                overflow[a] = True
            else:
                drift = balls_in[-1][0] - balls_in[-1][1]
                while True:
                    k = out_entered[a, t]
                    if k >= gap.shape[2]:
                        overflow[a] = True
                        break
                    new = balls_in[-1][1] + d + gap[a, t, k]
                    if new > half:
                        break
                    if len(balls_in) >= slots:
                        overflow[a] = True
                        break
                    when = t0 + dt - (half - new) / drift * dt
                    if when < t0:
                        when, new = t0, half - drift
                    balls_in.append([new + drift, new, balls + k, True])
                    entries.append((a, t, balls + k, when))
                    out_entered[a, t] = k + 1
            for j, (_, z, ident, good) in enumerate(balls_in):
                out_z[a, t, j], out_id[a, t, j], out_ok[a, t, j] = z, ident, good
            out_count[a, t] = len(balls_in)
    return out_z, out_id, out_ok, out_count, out_entered, overflow, exits, entries


def test_advance_kernel_matches_its_twin():
    # Random trains from near the trailing end of a 60 mm zone, ball drift up to 3 mm per
    # step: exits, entries (within the step and, with room before it, at its start), full
    # slots and exhausted draws all occur.
    rng = np.random.default_rng(11)
    m, tracks, slots, balls, cap = 400, 2, 6, 4, 3
    half, d, t0, dt = 0.03, 0.01, 0.3, 0.01
    count = rng.integers(1, slots + 1, (m, tracks))
    z0 = np.full((m, tracks, slots), np.nan)
    ids = np.full((m, tracks, slots), -1, dtype=np.int64)
    for a in range(m):
        for t in range(tracks):
            c = count[a, t]
            start = rng.uniform(-half - 0.014, -half - 0.004)
            z0[a, t, :c] = start + np.cumsum(rng.uniform(d, d + 0.002, c))
            ids[a, t, :c] = np.arange(c)
    z1 = z0 - rng.uniform(0.0, 0.003, (m, tracks, 1))
    ok = rng.random((m, tracks, slots)) < 0.9
    entered = rng.integers(0, cap + 1, (m, tracks))
    gap = rng.uniform(0.0, 0.003, (m, tracks, cap))
    ref = advance_twin(z0, z1, ids, ok, count, entered, gap, half, d, balls, t0, dt)
    a0, a1, aid, aok = z0.copy(), z1.copy(), ids.copy(), ok.copy()
    acount, aentered = count.astype(np.int64), entered.astype(np.int64)
    overflow = np.zeros(m, bool)
    events = [np.empty(z0.shape, np.int64), np.empty(z0.shape), np.empty(z0.shape, np.int64),
              np.empty(z0.shape)]
    advance_kernel(a0, a1, aid, aok, acount, aentered, gap, half, d, balls, t0, dt,
                   overflow, *events)
    assert_allclose(a1, ref[0], rtol=0, atol=1e-17)
    assert_array_equal(aid, ref[1])
    assert_array_equal(aok, ref[2])
    assert_array_equal(acount, ref[3])
    assert_array_equal(aentered, ref[4])
    assert_array_equal(overflow, ref[5])
    for (ident, when), rows in (((events[0], events[1]), ref[6]),
                                ((events[2], events[3]), ref[7])):
        got = sorted((a, t, ident[a, t, j], when[a, t, j])
                     for a, t, j in zip(*np.nonzero(ident >= 0), strict=True))
        want = sorted(rows)
        assert len(got) == len(want) > 50
        assert_array_equal([g[:3] for g in got], [w[:3] for w in want])
        assert_allclose([g[3] for g in got], [w[3] for w in want], rtol=0, atol=1e-15)
    assert overflow.any() and (aentered > entered).any()


# --------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("relief, study, message", [
    ("end_relief_depth_um = -1.0\nend_relief_length_mm = 10.0", "",
     r"along\.toml:\d+: carriage\.end_relief_depth_um = -1\.0 must be >= 0"),
    ("end_relief_depth_um = 1.0", "",
     r"carriage\.end_relief_depth_um needs end_relief_length_<unit>"),
    ("end_relief_length_mm = 10.0", "",
     r"carriage\.end_relief_length_mm has no effect without end_relief_depth"),
    ("end_relief_depth_um = 1.0\nend_relief_length_mm = 40.0", "",
     r"carriage\.end_relief_length_mm = 40\.0 is longer than half the loaded zone "
     r"\(30\.15 mm"),
    ("end_relief_depth_mm = 1.0\nend_relief_length_mm = 10.0", "",
     r"carriage\.end_relief_depth_mm = 1\.0 mm is outside the possible range \[0, 0\.1\] mm"),
    ("end_relief_depth_um = 1.0\nend_relief_length_mm = 10.0", "constant",
     r"carriage\.end_relief_depth_um acts on balls rolling through the carriage: it needs "
     r"study\.propagation = 'along_track'"),
    ("ball_oversize_deviation_um = [0.0, 0.1, 0.0, 0.1, 0.0, 0.1, 0.0, 0.1, 0.0, 0.1, 0.0, "
     "0.1]", "", r"carriage\.ball_oversize_deviation_um fixes the size of the balls"),
    ("", "one ball", r"carriage\.balls_per_track = 1: with propagation = 'along_track' a "
     r"track needs at least 2 balls"),
])
def test_config_errors_are_one_line(relief, study, message):
    text = BASE.format(n=6, stroke=100.0, preload=2.0, vertical=0.0, gap=FIXED_GAP, zone="",
                       tolerances="", samples=8, block=8, steps=10, relief=relief)
    if study == "constant":
        text = text.replace('propagation = "along_track"', 'propagation = "constant"')
    elif study == "one ball":
        text = text.replace("balls_per_track = 6", "balls_per_track = 1").replace(
            "balls = 6", "balls = 1")
    with pytest.raises(ConfigError, match=message) as err:
        parse_config(text, "along.toml")
    assert "\n" not in str(err.value)


def test_config_end_relief_is_stored_in_si():
    c = config(relief="end_relief_depth_um = 1.5\nend_relief_length_mm = 12.0")
    assert c.carriage.end_relief_depth == pytest.approx(1.5e-6, rel=1e-15)
    assert c.carriage.end_relief_length == pytest.approx(0.012, rel=1e-15)
    assert config().carriage.end_relief_depth == 0.0
    with pytest.raises(ValueError, match="give both"):
        replace(c.carriage, end_relief_length=0.0)


def test_sobol_indices_of_an_along_track_carriage_study():
    # The sensitivity design swaps a factor between blocks A and B; a ball source carries the
    # entering balls' values with it and the initial gap the entering gaps, so the indices of
    # an along-track carriage study are those of its whole stroke. With a fixed gap and one
    # random ball source, that source is the only factor: AB = B, so its total index is 1 up
    # to the sampling noise of the estimator (16 base samples: measured 0.92), and the run is
    # seeded (bit-identical when repeated).
    from tolsim.study.analyses.sensitivity import study_sensitivity

    tolerances = ('[tolerances.arc_centre_offset_tangential_BL]\ndistribution = "normal"\n'
                  'std_um = 2.0\nscope = "ball"\n')
    text = BASE.format(n=6, stroke=100.0, preload=2.0, vertical=0.0, gap=FIXED_GAP, zone="",
                       tolerances=tolerances, samples=8, block=8, steps=10, relief="")
    c = parse_config(text, "along.toml")
    first = study_sensitivity(c, samples=16, n_resamples=20)
    again = study_sensitivity(c, samples=16, n_resamples=20)
    assert first.factors == ("arc_centre_offset_tangential_BL",)
    np.testing.assert_array_equal(first.total, again.total)
    eps = first.outputs.index("velocity_deviation")
    assert first.total[eps, 0] == pytest.approx(1.0, abs=0.3)


def test_two_point_balls_along_the_track_are_answered_in_closed_form(monkeypatch):
    # No preload under 3 000 N: every loaded ball sits on one diagonal (two-point, epsilon =
    # 0). The solves along the track stop at TRACK_TOLERANCE (1e-4), which leaves a pair up
    # to 2e-4 rad apart (Notes of tolsim.physics.velocity.full.exactly_two_point), most beyond
    # its tight 1e-9 rad: they went to the full model, which gave |epsilon| <= 2e-10 in 90 %
    # of the run (session 28; configs/carriage_preload.toml so: 12.7 k balls/s). To the
    # solve's balance they are two-point in closed form, and nearly none reaches the kernel.
    from tolsim.physics.velocity import full as full_module

    reached = []
    kernel = full_module.full

    def spy(dbeta, force, *args, **kwargs):
        loaded = np.asarray(force) > 0.0
        reached.append(int(np.count_nonzero(
            (np.count_nonzero(loaded, axis=1) == 2)
            & ((loaded[:, 0] & loaded[:, 2]) | (loaded[:, 1] & loaded[:, 3])))))
        return kernel(dbeta, force, *args, **kwargs)

    monkeypatch.setattr(full_module, "full", spy)
    c = config(n=6, preload=0.0, vertical=3000.0, tolerances=ALL_KINDS, samples=16, steps=10)
    result = run_study(c)
    total = 16 * 2 * 6 * 11  # assemblies x balls x (10 midpoints and the start), about
    assert sum(reached) <= 0.01 * total, (sum(reached), total)
    assert result.statistics.contact_probability()[0] == 0.0  # epsilon = 0: no contact


def test_assemblies_with_light_contacts_are_solved_on_to_the_tight_tolerance(monkeypatch):
    # configs/carriage_preload.toml without preload (300 N, 2 N m): light diagonals of 0.2 to
    # 0.3 N beside 12 to 15 N. The solves along the track stop at TRACK_TOLERANCE (1e-4) of
    # the carriage's force scale, which leaves such a contact's force off by up to ~10 % of
    # itself, and a ball near the boundary of regimes A and B moves by 2e-3 in epsilon
    # (session 28, 2 048 assemblies at t = 0). An assembly with a contact below LIGHT_CONTACT
    # of its largest is solved on to POLISH_TOLERANCE (1e-8): its balls then agree with a
    # solve of every assembly to 1e-8 within 1e-7 (measured 3.8e-9 over 20 000 assemblies).
    import tolsim.study.pipeline.carriage_track as track

    text = (ROOT / "configs" / "carriage_preload.toml").read_text().replace(
        "preload_oversize_um = 2.0", "preload_oversize_um = 0.0")
    c = parse_config(text, "none.toml").with_overrides(samples=2048)
    block = sample_block(c, 0)

    def initial_epsilon(tolerance, light):
        monkeypatch.setattr(track, "TRACK_TOLERANCE", tolerance)
        monkeypatch.setattr(track, "LIGHT_CONTACT", light)
        frame = track.CarriageFrame(c, block)
        rows = np.arange(block.size)
        return frame.evaluation(frame.position, frame.ball_id, 0.0, rows)[0]

    tight = initial_epsilon(1e-8, 0.0)
    loose = initial_epsilon(1e-4, 0.0)
    polished = initial_epsilon(1e-4, 0.1)
    both = np.isfinite(tight)
    assert_array_equal(np.isfinite(polished), both)
    assert np.max(np.abs(loose[both] - tight[both])) > 1e-4  # (what the polish is for)
    assert np.max(np.abs(polished[both] - tight[both])) < 1e-7


def test_an_assembly_whose_polishing_solve_fails_keeps_its_loose_solution(monkeypatch):
    # A polishing solve that does not converge must not turn a converged assembly into an
    # unsolved one: its loose solution stays (forced here: the polish of the first light
    # assembly reports FAILED).
    import tolsim.study.pipeline.carriage_track as track

    text = (ROOT / "configs" / "carriage_preload.toml").read_text().replace(
        "preload_oversize_um = 2.0", "preload_oversize_um = 0.0")
    c = parse_config(text, "none.toml").with_overrides(samples=64)
    block = sample_block(c, 0)
    solve = track.solve_carriage_batch
    seen = {}

    def failing(*args, **kwargs):
        batch = solve(*args, **kwargs)
        if kwargs.get("tol") == track.POLISH_TOLERANCE:
            batch.status[0] = 3  # STATUS_FAILED
            seen["polished"] = len(batch.status)
        else:
            seen["loose"] = batch
        return batch

    monkeypatch.setattr(track, "solve_carriage_batch", failing)
    frame = track.CarriageFrame(c, block)
    rows = np.arange(block.size)
    _, _, loaded, batch, _, _ = frame.evaluation(frame.position, frame.ball_id, 0.0, rows)
    assert seen["polished"] >= 2  # (assemblies with light contacts were polished)
    loose = seen["loose"]
    _, light = track.settle_and_find_light(loose.normal_force, loaded, track.TRACK_TOLERANCE,
                                           track.LIGHT_CONTACT)
    first, others = np.flatnonzero(light)[0], np.flatnonzero(light)[1:]
    assert batch.status[first] == STATUS_CONVERGED
    assert_array_equal(batch.displacement[first], loose.displacement[first])
    assert_array_equal(batch.normal_force[first], loose.normal_force[first])
    assert not np.array_equal(batch.displacement[others], loose.displacement[others])
