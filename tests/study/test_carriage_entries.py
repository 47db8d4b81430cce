"""The carriage's entering balls along the track (issue 24, "Speed"): in the midpoint's
carriage solve from their entry, at their own epsilon from it, and the step-size error that
this removes."""

from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.io.config import load_config
from tolsim.study.pipeline.carriage_track import CarriageFrame, first_contact_carriage_track
from tolsim.study.pipeline.carriage_track_kernels import (
    entering_by_kernel,
    entry_shift_kernel,
    first_contact_kernel,
)
from tolsim.study.sampling import sample_block

ROOT = Path(__file__).resolve().parents[2]


def entering_by_twin(z, ids, rows, count, entered, gap, half, d, balls):
    """Plain-Python twin of entering_by_kernel: the slots with the balls that have entered
    by positions z (each next ball at z_lead + D + g_k while that is inside the zone)."""
    out_z, out_id = z.copy(), ids.copy()
    out_new = np.zeros(z.shape, dtype=bool)
    for r, a in enumerate(rows):
        for t in range(z.shape[1]):
            c, k = count[a, t], entered[a, t]
            while 0 < c < z.shape[2] and k < gap.shape[2]:
                place = out_z[r, t, c - 1] + d + gap[a, t, k]
                if place > half:
                    break
                out_z[r, t, c], out_id[r, t, c], out_new[r, t, c] = place, balls + k, True
                c, k = c + 1, k + 1
    return out_z, out_id, out_new


def test_entering_by_kernel_matches_its_twin():
    # Random trains whose leading ball lies up to 3 diameters short of the leading end: no
    # entry, one, several, full slots and exhausted draws all occur.
    rng = np.random.default_rng(5)
    size, tracks, slots, balls, cap = 300, 2, 7, 4, 3
    half, d = 0.03, 0.01
    count = rng.integers(0, slots + 1, (size, tracks))
    entered = rng.integers(0, cap + 1, (size, tracks))
    gap = rng.uniform(0.0, 0.004, (size, tracks, cap))
    z = np.full((size, tracks, slots), np.nan)
    ids = np.full((size, tracks, slots), -1, dtype=np.int64)
    for a in range(size):
        for t in range(tracks):
            c = count[a, t]
            lead = half - rng.uniform(0.0, 3 * d)
            z[a, t, :c] = lead - d * np.arange(c)[::-1] - rng.uniform(0, 0.001, c).cumsum()[::-1]
            ids[a, t, :c] = np.arange(c)
    rows = np.sort(rng.choice(size, 200, replace=False))
    z, ids = z[rows], ids[rows]
    out = (np.empty_like(z), np.empty_like(ids), np.empty(z.shape, dtype=bool))
    entering_by_kernel(z, ids, rows, count, entered, gap, half, d, balls, *out)
    ref = entering_by_twin(z, ids, rows, count, entered, gap, half, d, balls)
    for got, want in zip(out, ref, strict=True):
        assert_array_equal(got, want)
    assert 50 < out[2].sum() < z.size / 2 and (out[2].sum(axis=2) > 1).any()


def test_an_entering_ball_moves_at_its_own_epsilon_from_its_entry():
    # By hand (Notes of first_contact_carriage_track, "Entry"): a ball entered tau = 10 ms
    # before the step's start t = 0.2 s, moving with the ball ahead (epsilon_ahead = 1e-3)
    # with the gap g = 1 um; its own epsilon at the midpoint is -2e-3, v / 2 = 0.1 m/s. It
    # moves by tau (eps - eps_ahead) v / 2 = 0.01 x (-3e-3) x 0.1 = -3 um at t and at the
    # step's end: its gap closes linearly from 1 um at the entry to -2 um at t, so the pair
    # closed 1/3 of tau after the entry, at t - 2 tau / 3. The ball ahead does not move.
    d, g, t, tau, half_v = 0.01, 1e-6, 0.2, 0.01, 0.1
    position = np.array([[[0.0, d + g, np.nan]]])
    free = position - 0.001
    take = np.array([[[False, True, False]]])
    eps = np.array([[[5e-4, -2e-3, np.nan]]])
    entry_time = np.array([[[np.nan, t - tau, np.nan]]])
    entry_velocity = np.array([[[0.0, 1e-3, 0.0]]])
    closed = np.empty((1, 1, 2))
    want = position.copy()
    want[0, 0, 1] -= 3e-6  # -3 um
    entry_shift_kernel(position, free, take, eps, entry_time, entry_velocity, np.array([0]),
                       t, d, half_v, closed)
    assert_allclose(position, want, rtol=0, atol=1e-18)
    assert_allclose(free, want - 0.001, rtol=0, atol=1e-18)
    assert_allclose(closed[0, 0, 0], t - 2 * tau / 3, rtol=1e-12)
    assert np.isnan(closed[0, 0, 1])
    # a faster entering ball opens its gap: nothing closes
    position[0, 0, 1] = d + g
    entry_shift_kernel(position, free, take, -eps, entry_time, entry_velocity, np.array([0]),
                       t, d, half_v, closed)
    assert position[0, 0, 1] > d + g and np.isnan(closed).all()


def test_a_pair_closed_after_an_entry_is_a_first_contact():
    # One assembly, one track of three balls: pair 1 (an entering ball and the ball ahead)
    # closed at 0.19 s, before the step [0.2, 0.225] s in which pair 0 closes halfway (gap
    # 1 um -> -1 um): the first contact is pair 1's at 0.19 s; without it, pair 0's at
    # 0.2125 s; a pair with a ball not ok does not count.
    z0 = np.array([[[0.0, 0.0101, 0.0202]]])
    z1 = z0 - 0.001
    gap0, gap1 = np.array([[[1e-6, -1e-6]]]), np.array([[[-1e-6, -1e-6]]])
    ok = np.ones((1, 1, 3), dtype=bool)
    closed = np.array([[[np.nan, 0.19]]])

    def first(closed, ok=ok):
        time, pair = np.array([np.inf]), np.array([-1])
        valid, searching = np.array([True]), np.empty(1, dtype=bool)
        first_contact_kernel(np.array([0]), z0, z1, gap0, gap1, ok, ok, ok, 0.05, 0.2, 0.025,
                             3, time, pair, valid, searching, closed)
        return time[0], pair[0]

    assert first(closed) == (0.19, 1)
    assert first(np.empty((0, 0, 0))) == (0.2 + 0.5 * 0.025, 0)
    not_ok = ok.copy()
    not_ok[0, 0, 2] = False
    assert first(closed, not_ok) == (0.2 + 0.5 * 0.025, 0)


def test_the_midpoint_solve_holds_the_balls_entered_by_then():
    # A train whose leading ball is one gap short of room for the next ball: at a midpoint
    # where it has drifted by 2 mm the next ball is inside the zone; the carriage is solved
    # with it (its slot carries a normal load) and the step's balls leave it out (an empty
    # slot until the step's end places it).
    c = load_config(ROOT / "configs" / "carriage_preload.toml").with_overrides(samples=4)
    frame = CarriageFrame(c, sample_block(c, 0))
    frame.select(np.ones(4, dtype=bool))
    n, half = frame.balls, frame.half_zone
    gap = frame.entering_gap[:, :, 0]
    room = half - frame.diameter - gap  # where the leading ball lets the first one in
    mid = frame.position[frame.rows].copy()
    mid[:, :, :n] += (room - 0.002 - mid[:, :, n - 1])[..., None]  # 2 mm past that point
    state = frame.evaluate(mid, 0.01)
    assert not state.loaded[:, :, n].any() and np.isnan(state.velocity_deviation[:, :, n]).all()
    assert (state.batch.normal_load[:, :, n] > 0).all()
    assert len(state.balls.velocity_deviation) == state.loaded.sum()
    # 2 mm short of that point: nobody enters, the solve holds the train alone
    mid[:, :, :n] += 0.004
    state = frame.evaluate(mid, 0.01)
    assert not (state.batch.normal_load[:, :, n] > 0).any()


def test_the_carriage_converges_at_second_order_between_events():
    # Issue 24, "Speed": with the entering balls in the midpoint solve from their entry and
    # moving at their own epsilon from it, the step's error of the time to first contact on
    # configs/carriage_preload.toml (one block of 256, seed 12, against 320 steps) was
    # 5.1, 1.6 and 0.60 ms at 10, 20 and 40 steps (measured); before (entering balls solved
    # from the next step, moving with the ball ahead) 19.9, 12.6 and 3.9 ms: first order.
    # Bounds: 10 ms at 10 steps (2x the measured, half the first-order scheme's) and a
    # fall by more than 5x from 10 to 40 steps (8.4x measured; 5.1x before).
    c = load_config(ROOT / "configs" / "carriage_preload.toml").with_overrides(samples=256)
    block = sample_block(c, 0)

    def first(steps):
        cc = replace(c, study=replace(c.study, time_steps=steps))
        return first_contact_carriage_track(cc, block)[0]

    ref = first(320)
    errors = []
    for steps in (10, 40):
        t = first(steps)
        both = np.isfinite(t) & np.isfinite(ref)
        assert both.sum() > 50  # contacts are exercised
        assert (np.isfinite(t) != np.isfinite(ref)).sum() <= 6
        errors.append(np.mean(np.abs(t[both] - ref[both])))
    assert errors[0] < 0.010
    assert errors[0] / errors[1] > 5.0
