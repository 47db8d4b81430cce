"""Ball-to-ball contact propagation (tolsim.study.pipeline.propagation), modes (a) and (b)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.io.config import load_config, parse_config
from tolsim.physics.velocity.models import BALL_UNLOADED
from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.evaluate import evaluate_balls, loads_at
from tolsim.study.pipeline.propagation import (
    FirstContact,
    FreeBalls,
    StepObserver,
    first_contact_along_track,
    first_contact_constant,
    force_gaps,
    integrate,
    pushed_along,
    pushed_velocity_deviation,
    time_steps,
)
from tolsim.study.sampling import error_values, sample_block

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def constant_twin(gap, eps, v, horizon):
    """Plain-NumPy twin of the mode (a) kernel."""
    rate = (eps[:, :-1] - eps[:, 1:]) * v / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(rate > 0, gap / rate, np.inf)
    first = np.argmin(t, axis=1)
    tmin = t[np.arange(len(t)), first]
    hit = tmin <= horizon
    return np.where(hit, tmin, np.inf), np.where(hit, first, -1)


def test_constant_kernel_matches_numpy_twin(rng):
    gap = rng.uniform(0, 1e-4, (5000, 7))
    eps = rng.normal(0, 2e-3, (5000, 8))
    eps[rng.random(eps.shape) < 0.01] = np.nan  # invalid balls never close a gap
    t, pair = first_contact_constant(gap, eps, 0.2, 0.05)
    t_ref, pair_ref = constant_twin(gap, eps, 0.2, 0.05)
    assert_allclose(t, t_ref, rtol=1e-15)
    assert_array_equal(pair, pair_ref)
    assert 0.1 < np.isfinite(t).mean() < 0.9  # both outcomes are exercised


def test_lin2018_case_a_contact_time():
    # [Lin2018] Sec. 3.2: eps_1 = -eps_2 = 0.754 % (Eq. 26, ERRATA 2), gap 0.1 R_B = 0.5 mm,
    # v = 10 mm/s: t = gap / ((eps_1 - eps_2) v / 2) = 6.63 s.
    eps = 0.00754
    t, pair = first_contact_constant([[0.5e-3]], [[eps, -eps]], 0.01, 10.0)
    assert_allclose(t, 0.5e-3 / (2 * eps * 0.005), rtol=1e-14)
    assert_allclose(t, 6.63, atol=0.01)
    assert pair[0] == 0
    # the faster ball leading: no contact
    t, pair = first_contact_constant([[0.5e-3]], [[-eps, eps]], 0.01, 10.0)
    assert np.isinf(t[0]) and pair[0] == -1


@pytest.mark.parametrize("bad", [
    dict(initial_gap=[[-1e-6]]),
    dict(velocity_deviation=[[0.0, 0.0, 0.0]]),
    dict(groove_velocity=0.0),
    dict(horizon=-1.0),
])
def test_constant_validates(bad):
    args = dict(initial_gap=[[1e-6]], velocity_deviation=[[0.0, 0.0]], groove_velocity=0.1,
                horizon=1.0)
    args.update(bad)
    with pytest.raises(ValueError, match=next(iter(bad))):
        first_contact_constant(**args)


TRAIN = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
[motion]
groove_velocity_mm_per_s = 100.0
stroke_mm = 400.0
[train]
balls = 3
initial_gap = {{ distribution = "uniform", low_um = 0.0, high_um = 400.0 }}
[loads]
normal_load_N = 200.0
{loads}
[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.5
{field}
[study]
samples = 64
seed = 5
block_size = 64
velocity_model = "eq24"
static_model = "paired"
propagation = "along_track"
time_steps = {steps}
"""


def test_along_track_equals_constant_when_epsilon_is_constant():
    # No rail field and equal loads on every ball: epsilon does not change as the balls roll,
    # so mode (b) must reproduce the closed form of mode (a) (midpoint rule and linear event
    # location are exact for constant velocities).
    per_ball = ('[tolerances.arc_centre_offset_tangential_TL]\ndistribution = "normal"\n'
                'std_um = 1.0\nscope = "ball"')
    c = parse_config(TRAIN.format(loads="", field=per_ball, steps=50))
    b = sample_block(c, 0)
    v = error_values(c, b)
    nx, ny = loads_at(c, b.initial_position)
    state = evaluate_balls(c, v, nx, ny)
    t_b, pair_b, ok, _ = first_contact_along_track(c, b)
    t_a, pair_a = first_contact_constant(b.initial_gap, state.velocity_deviation,
                                         c.motion.groove_velocity, c.motion.duration)
    assert ok.all()
    assert 0 < np.isfinite(t_a).sum() < len(t_a)
    assert_allclose(t_b, t_a, rtol=1e-9)
    assert_array_equal(pair_b, pair_a)


def test_balls_unresolved_along_the_track_are_counted_once_apart_from_the_start(monkeypatch):
    # Closed form of the paired model: side force ratio 1.5 at the trailing slot, 0 at the
    # others, interpolated along the carriage; rho > 1 puts a contact in tension (loss of
    # contact). The solved model answers such a ball (STATIC_FALLBACK): every train resolved.
    # With that fallback taken away (a ball no model solves), ball 0 starts at the trailing
    # slot: unresolved at t = 0 (the ball counters of the start have it). Balls 1 and 2 start
    # at rho <= 0.75 and drift back through the carriage at v / 2, 200 mm over the 400 mm
    # stroke, past rho = 1: each unresolved along the track, counted once (2 per train),
    # every train unresolved.
    import tolsim.study.pipeline.evaluate as evaluate

    c = parse_config(TRAIN.format(loads="side_force_ratio = [1.5, 0.0, 0.0]", field="",
                                  steps=40)).with_overrides(samples=16)
    b = sample_block(c, 0)
    unresolved = np.zeros(b.size, dtype=np.int64)
    fallback = np.zeros((b.size, 3), dtype=bool)
    _, _, ok, _ = first_contact_along_track(c, b, unresolved=unresolved,
                                            static_fallback=fallback)
    assert ok.all()
    assert_array_equal(unresolved, 0)
    # answered by the solved model: ball 0 from the start, balls 1 and 2 along the track;
    # the study counts each once
    assert fallback.all()
    assert int(run_study(c).statistics.n_static_fallback) == 3 * 16
    monkeypatch.setattr(evaluate, "STATIC_FALLBACK", {})
    _, _, ok, _ = first_contact_along_track(c, b, unresolved=unresolved)
    assert not ok.any()
    assert_array_equal(unresolved, 2)


def rk4_reference(c, b, steps):
    """Independent reference for mode (b): classical RK4 on a fine grid, contact located by
    linear interpolation of the gap inside the fine step where it changes sign."""
    v, horizon, d = c.motion.groove_velocity, c.motion.duration, 2 * c.bearing.ball_radius

    def rate(pos, t):
        nx, ny = loads_at(c, pos - v * t)
        eps = evaluate_balls(c, error_values(c, b, rail_position=pos), nx, ny)
        return (1 + eps.velocity_deviation) * v / 2

    h = horizon / steps
    z = b.initial_position.copy()
    time = np.full(b.size, np.inf)
    pair = np.full(b.size, -1)
    for k in range(steps):
        t = k * h
        k1 = rate(z, t)
        k2 = rate(z + h / 2 * k1, t + h / 2)
        k3 = rate(z + h / 2 * k2, t + h / 2)
        k4 = rate(z + h * k3, t + h)
        new = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        g0, g1 = np.diff(z, axis=1) - d, np.diff(new, axis=1) - d
        for m in np.flatnonzero(np.isinf(time)):
            crossing = [(t + h * g0[m, j] / (g0[m, j] - g1[m, j]), j)
                        for j in range(g0.shape[1]) if g1[m, j] <= 0 < g0[m, j]]
            if crossing:
                time[m], pair[m] = min(crossing)
        z = new
    return time, pair


def test_along_track_matches_rk4_reference():
    # Varying epsilon (rail random field with 50 mm correlation length, yaw moment along the
    # carriage): the midpoint rule with 200 steps against RK4 with 1000 steps. Measured
    # agreement 1.5e-4 of the horizon; tolerance 1e-3 of it (a fifth of one midpoint step).
    text = TRAIN.format(loads="yaw_moment_N_m = 1.5", field="correlation_length_mm = 50.0",
                        steps=200).replace("high_um = 400.0", "high_um = 100.0")
    c = parse_config(text).with_overrides(samples=32)
    b = sample_block(c, 0)
    t_b, pair_b, ok, _ = first_contact_along_track(c, b)
    t_ref, pair_ref = rk4_reference(c, b, 1000)
    assert ok.all()
    hit = np.isfinite(t_ref)
    assert 3 <= hit.sum() < b.size  # both outcomes exercised
    assert_array_equal(np.isfinite(t_b), hit)
    assert_array_equal(pair_b, pair_ref)
    assert_allclose(t_b[hit], t_ref[hit], rtol=0, atol=1e-3 * c.motion.duration)


# --------------------------------------------------------------------------------------------
# Unloaded balls: pushed along (issue 25)
# --------------------------------------------------------------------------------------------
def test_unloaded_ball_closes_both_of_its_gaps_at_once():
    # Hand computation: balls 0 and 2 loaded (eps 1 %, 0), ball 1 unloaded, gaps 1 and 3 mm.
    # The unloaded ball carries force only when both gaps have closed, at
    # t = (1 + 3) mm / ((0.01 - 0) v / 2) = 80 s at v = 10 mm/s; it gets
    # eps = 0.01 + (0 - 0.01) * 1 / 4 = 0.0075, which closes gap 0 at 1 mm / (0.0025 v / 2) and
    # gap 1 at 3 mm / (0.0075 v / 2), both 80 s (exact to round-off).
    eps = np.array([[0.01, np.nan, 0.0]])
    gap = np.array([[1e-3, 3e-3]])
    filled = pushed_velocity_deviation(gap, eps, np.array([[False, True, False]]))
    assert_allclose(filled, [[0.01, 0.0075, 0.0]], rtol=1e-15)
    t, pair = first_contact_constant(gap, filled, 0.01, 100.0)
    assert_allclose(t, [80.0], rtol=1e-12)
    assert pair[0] in (0, 1)
    # diverging neighbours: never
    t, _ = first_contact_constant(gap, pushed_velocity_deviation(
        gap, np.array([[0.0, np.nan, 0.01]]), np.array([[False, True, False]])), 0.01, 1e9)
    assert np.isinf(t[0])


def test_unloaded_runs_ends_and_whole_trains():
    # a run of two between loaded balls: gaps 1, 1, 2 mm -> eps at G_i / G = 1/4 and 2/4;
    # an unloaded end ball moves with its one neighbour; a train without a loaded ball stays
    # at 0; a NaN neighbour (unresolved ball) stays NaN; two tracks are independent
    gap = np.array([[1e-3, 1e-3, 2e-3, 1e-3, 5e-3, 1e-3]])
    eps = np.array([[0.004, 9.0, 9.0, 0.0, 0.002, 9.0, 9.0, 9.0]])
    unloaded = np.array([[False, True, True, False, False, True, True, True]])
    out = pushed_velocity_deviation(gap, eps, unloaded, tracks=2)
    assert_allclose(out, [[0.004, 0.003, 0.002, 0.0, 0.002, 0.002, 0.002, 0.002]], rtol=1e-15)
    out = pushed_velocity_deviation(gap[:, :3], np.array([[9.0, 9.0, 9.0, 9.0]]),
                                    np.ones((1, 4), bool))
    assert_array_equal(out, 0.0)
    out = pushed_velocity_deviation(gap[:, :2], np.array([[np.nan, 9.0, 0.0]]),
                                    np.array([[False, True, False]]))
    assert np.isnan(out[0, 1])


class FixedBalls(FreeBalls):
    """Free balls whose evaluation is the same ``state`` wherever they are: epsilon constant
    per ball along the track, with its unloaded balls (the limit in which mode (b) must be
    mode (a))."""

    def __init__(self, config, block, state):
        super().__init__(config, block, state)
        self.fixed = state

    def evaluate(self, position, t):
        return self.fixed


class Positions(StepObserver):
    """The positions at the end of every step."""

    def begin(self, block, position):
        self.seen = [position.copy()]

    def moved(self, step):
        self.seen.append(step.free.copy())


def _group(pair, unloaded):
    """The contact of ``pair`` that carries force: the loaded ball behind its run."""
    j = int(pair)
    while j > 0 and unloaded[j]:
        j -= 1
    return j


@pytest.mark.parametrize("where", [[2], [2, 3], [0], [5], [1, 4]])
def test_along_track_with_unloaded_balls_equals_constant_propagation(where):
    # issue 25: an unloaded ball is pushed along in mode (b) as in mode (a). With epsilon
    # constant per ball (the same evaluation at every position) and unloaded balls inside the
    # train (a run of one or two) or at its ends, the first contact that carries force along
    # the track is the constant propagation's (pushed_velocity_deviation, first_contact_constant)
    # to round-off: both are exact for constant velocities (the gaps of a run close together,
    # linearly within the step). Tolerance 1e-9 relative, as
    # test_along_track_equals_constant_when_epsilon_is_constant. Before, every such train was
    # unresolved (ok False) and had no contact.
    per_ball = ('[tolerances.arc_centre_offset_tangential_TL]\ndistribution = "normal"\n'
                'std_um = 1.0\nscope = "ball"')
    c = parse_config(TRAIN.format(loads="", field=per_ball, steps=50).replace(
        "balls = 3", "balls = 6"))
    b = sample_block(c, 0)
    nx, ny = loads_at(c, b.initial_position)
    state = evaluate_balls(c, error_values(c, b), nx, ny)
    state.velocity_deviation[:, where] = np.nan
    state.valid[:, where] = False
    state.regime[:, where] = BALL_UNLOADED
    frame, first, seen = FixedBalls(c, b, state), FirstContact(), Positions()
    integrate(c, frame, [first, seen])
    eps = pushed_velocity_deviation(b.initial_gap, state.velocity_deviation, state.unloaded)
    t_a, pair_a = first_contact_constant(b.initial_gap, eps, c.motion.groove_velocity,
                                         c.motion.duration)
    assert frame.ball_ok.all()
    hit = np.isfinite(t_a)
    assert 5 <= hit.sum() <= b.size - 5  # both outcomes exercised
    assert_array_equal(np.isfinite(first.time), hit)
    assert_allclose(first.time[hit], t_a[hit], rtol=1e-9)
    unloaded = state.unloaded[0]
    for m in np.flatnonzero(hit):
        assert _group(first.pair[m], unloaded) == _group(pair_a[m], unloaded)
    # the unloaded balls stay between their neighbours: no gap below -1e-15 m before contact
    d = 2 * c.bearing.ball_radius
    for k, z in enumerate(seen.seen):
        before = k * c.motion.duration / c.study.time_steps <= np.where(hit, first.time, np.inf)
        assert (np.diff(z, axis=1)[before] - d >= -1e-15).all()


def test_force_gaps_by_hand():
    # gaps 1, 2, 3, 4 mm, ball 2 unloaded: pairs 1 and 2 carry force when 2 + 3 mm have
    # closed; ball 0 unloaded (an end): pair 0 never; a run with an unresolved neighbour: NaN
    gap = np.array([[1.0, 2.0, 3.0, 4.0]])
    out = force_gaps(gap, np.array([[True, False, True, False, False]]),
                     ok=np.array([[True] * 5]))
    assert_array_equal(out, [[np.inf, 5.0, 5.0, 4.0]])
    out = force_gaps(gap, np.array([[False, False, True, False, False]]),
                     ok=np.array([[True, True, True, False, True]]))
    assert_array_equal(out, [[1.0, np.nan, np.nan, 4.0]])
    assert force_gaps(gap, np.zeros((1, 5), bool)) is gap  # nothing unloaded: untouched
    # an edge ball (outside the zone) ends the run like the end of the train
    out = force_gaps(gap, np.array([[False, False, True, False, False]]),
                     edge=np.array([[False, False, False, True, False]]))
    assert_array_equal(out, [[1.0, np.inf, np.inf, 4.0]])
    eps = pushed_along(gap, np.array([[0.1, 0.2, 9.0, 0.3, 0.4]]),
                       np.array([[False, False, True, False, False]]),
                       np.array([[False, False, False, True, False]]))
    assert_array_equal(eps, [[0.1, 0.2, 0.2, 0.3, 0.4]])


class _StartEvaluated(FreeBalls):
    """Free balls whose predictor is evaluated at the start of every step (two evaluations
    per step, as before issue 24's speed work), counting the evaluations."""

    def __init__(self, config, block, start_evaluated):
        super().__init__(config, block)
        self.start_evaluated, self.calls = start_evaluated, 0

    def evaluate(self, position, t):
        self.calls += 1
        return super().evaluate(position, t)

    def start(self, k, t, position):
        if k > 0 and self.start_evaluated:
            return self.evaluate(position, t)
        return super().start(k, t, position)


def test_free_balls_are_evaluated_once_per_step():
    # issue 24 (speed): the free-ball frame evaluates its balls once per step (the midpoint;
    # the predictor is the previous midpoint's epsilon, Notes of integrate_along_track), plus
    # once at t = 0; before, twice per step. The predictor only places the midpoint, so the
    # first contacts are those with the start evaluated: on configs/whatif_along_track.toml
    # (2 000 assemblies, 20 steps) the same 403 trains touch at the same pairs, times within
    # 3.3e-5 s (8.4e-5 relative; measured). Tolerance 1e-3 relative: the step's own error of
    # the time to contact there is some 8 ms of 500 (1.6e-2, time_steps' Notes), 16x more.
    c = load_config(CONFIGS / "whatif_along_track.toml").with_overrides(samples=2000)
    c = replace(c, study=replace(c.study, block_size=2000))
    b = sample_block(c, 0)
    out = []
    for start_evaluated in (False, True):
        frame, first = _StartEvaluated(c, b, start_evaluated), FirstContact()
        integrate(c, frame, [first])
        out.append((first.time, first.pair, frame.calls))
    (t1, p1, calls1), (t2, p2, calls2) = out
    steps = time_steps(c)
    assert (calls1, calls2) == (steps + 1, 2 * steps)
    assert_array_equal(p1, p2)
    assert_array_equal(np.isfinite(t1), np.isfinite(t2))
    assert 300 < np.isfinite(t1).sum() < 500  # contacts are exercised
    hit = np.isfinite(t1)
    assert_allclose(t1[hit], t2[hit], rtol=1e-3)
