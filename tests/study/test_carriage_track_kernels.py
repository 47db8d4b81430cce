"""The compiled glue of the carriage along the track against the NumPy code it replaced."""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.study.pipeline.carriage_track_kernels import (
    advance_frame_kernel,
    advance_kernel,
    carriage_motion_kernel,
    carry_slots_kernel,
    first_contact_kernel,
    initial_balls_kernel,
    joined_kernel,
    newton_start_kernel,
    remember_kernel,
    slot_inputs_kernel,
    step_velocity_kernel,
)


def _bits(x):
    return np.asarray(x, dtype=np.float64).view(np.int64)


def newton_start_twin(solution, solved_at, start, rows, t):
    """The NumPy code of CarriageFrame's Newton start (session 12)."""
    (q0, q1), (t0, t1) = solution[:, rows], solved_at[:, rows]
    with np.errstate(invalid="ignore", divide="ignore"):
        w = (t - t1) / (t1 - t0)
    line = np.isfinite(w) & (w > 0.0) & np.isfinite(q0).all(axis=1)
    out = start[rows]
    out[line] = q1[line] + w[line, None] * (q1[line] - q0[line])
    return out


def remember_twin(rows, t, displacement, solved, start, solution, solved_at):
    done, failed = rows[solved], rows[~solved]
    start[done] = displacement[solved]
    solution[0, done], solved_at[0, done] = solution[1, done], solved_at[1, done]
    solution[1, done], solved_at[1, done] = displacement[solved], t
    solution[:, failed], solved_at[:, failed] = np.nan, np.nan


def test_newton_start_and_remember_match_their_numpy_twins():
    # Source: the NumPy code they replaced (twins above); tolerance 0 (bit for bit): rows
    # with two solutions (a line), one, none (NaN), equal times (w not finite), a time
    # behind the latest (w <= 0), non-converged assemblies.
    rng = np.random.default_rng(3)
    size = 40
    solution = rng.normal(0.0, 1e-6, (2, size, 5))
    solved_at = np.sort(rng.uniform(0.0, 0.4, (2, size)), axis=0)
    solution[0, :8], solved_at[0, :8] = np.nan, np.nan
    solution[0, 8:12, 2] = np.nan
    solved_at[0, 12:16] = solved_at[1, 12:16]
    solved_at[1, 16:20] = 0.5
    start = rng.normal(0.0, 1e-6, (size, 5))
    rows = np.sort(rng.choice(size, 30, replace=False)).astype(np.int64)
    for t in (0.45, 0.5):
        got = np.empty((len(rows), 5))
        for period in (0.0, 10.0):  # no pitch; a pitch longer than any time held
            newton_start_kernel(solution, solved_at, start, rows, t, period, got)
            assert_array_equal(_bits(got), _bits(newton_start_twin(solution, solved_at, start,
                                                                    rows, t)))
    displacement = rng.normal(0.0, 1e-6, (len(rows), 5))
    solved = rng.uniform(size=len(rows)) < 0.7
    mine = [start.copy(), solution.copy(), solved_at.copy()]
    twin = [start.copy(), solution.copy(), solved_at.copy()]
    remember_kernel(rows, 0.45, displacement, solved, *mine)
    remember_twin(rows, 0.45, displacement, solved, *twin)
    for a, b in zip(mine, twin, strict=True):
        assert_array_equal(_bits(a), _bits(b))


def test_newton_start_one_pitch_back():
    # Source: the rule of newton_start_kernel's docstring, values worked by hand; tolerance 0.
    # Solves at 0, 0.5, 1.0, 1.5 s (latest last), period 1 s.
    q = np.arange(4.0)[:, None, None] + np.zeros((4, 1, 5))
    at = np.array([0.0, 0.5, 1.0, 1.5])[:, None]
    start = np.full((1, 5), -1.0)
    rows = np.array([0], dtype=np.int64)
    got = np.empty((1, 5))

    def start_at(t, period, solution=q, solved_at=at):
        newton_start_kernel(solution, solved_at, start, rows, t, period, got)
        return got[0, 0]

    assert start_at(2.0, 1.0) == 2.0  # the solve at t - period = 1.0 exactly
    assert start_at(2.1, 1.0) == 2.0  # nearest to 1.1, within period / 8
    assert start_at(2.2, 1.0) == 3.0 + 0.7 / 0.5  # none within 0.125 of 1.2: the line
    assert start_at(1.7, 1.0) == 3.0 + 0.2 / 0.5  # < period / 4 after the latest: the line
    assert start_at(2.0, 0.0) == 3.0 + 0.5 / 0.5  # no pitch: the line
    assert start_at(2.0, 1.6) == 1.0  # nearest to 0.4, within 0.2
    assert start_at(2.0, 1.2) == 3.0 + 0.5 / 0.5  # none within 0.15 of 0.8: the line
    bad = q.copy()
    bad[:2] = np.nan
    none = at.copy()
    none[:3] = np.nan  # the latest alone: its start
    assert start_at(2.0, 1.0, solution=bad, solved_at=none) == -1.0


def test_remember_keeps_the_latest_solutions_in_order():
    # Source: remember_kernel's docstring; tolerance 0. Three rows: two solved twice, one
    # failing at the second solve (all its solutions dropped).
    size, kept = 3, 3
    solution, solved_at = np.full((kept, size, 5), np.nan), np.full((kept, size), np.nan)
    start = np.zeros((size, 5))
    rows = np.arange(size, dtype=np.int64)
    for t, solved in ((0.1, [True] * 3), (0.2, [True, True, False])):
        remember_kernel(rows, t, np.full((size, 5), 10 * t), np.array(solved), start,
                        solution, solved_at)
    assert_array_equal(solved_at[:, :2], [[np.nan] * 2, [0.1] * 2, [0.2] * 2])
    assert_array_equal(solution[1:, :2, 0], [[1.0, 1.0], [2.0, 2.0]])
    assert np.isnan(solution[:, 2]).all() and np.isnan(solved_at[:, 2]).all()
    assert_array_equal(start[:, 0], [2.0, 2.0, 1.0])


def first_contact_twin(rows, z0, z1, gap0, gap1, ok, valid1, valid2, half, t, dt, balls,
                       time, pair, valid):
    """The NumPy code of CarriageFirstContact.observe (session 12), with the pair counted
    among the balls in the zone at the contact (session 30: less the slots behind it whose
    ball has left by then)."""
    slots = z0.shape[2]
    searching = ~np.isfinite(time[rows])
    resolved = valid1 & valid2
    valid[rows[searching]] &= resolved.all(axis=(1, 2))[searching]
    with np.errstate(invalid="ignore", divide="ignore"):
        closing = (gap1 <= 0.0) & (gap0 > gap1) & ok[..., 1:] & ok[..., :-1]
        frac = np.where(gap0 <= 0.0, 0.0, gap0 / (gap0 - gap1))
        behind = z0[..., :-1] + frac * (z1[..., :-1] - z0[..., :-1])
        ahead = z0[..., 1:] + frac * (z1[..., 1:] - z0[..., 1:])
        closing &= (behind >= -half) & (ahead <= half)
    tc = np.where(closing, t + frac * dt, np.inf).reshape(len(rows), -1)
    first = np.argmin(tc, axis=1)
    tmin = tc[np.arange(len(rows)), first]
    hit = np.isfinite(tmin) & searching
    time[rows[hit]] = tmin[hit]
    track, slot = np.divmod(first[hit], slots - 1)
    at = frac.reshape(len(rows), -1)[np.flatnonzero(hit), first[hit]]
    left = np.array([np.count_nonzero(z0[a, tr, :j] + f * (z1[a, tr, :j] - z0[a, tr, :j])
                                      < -half)
                     for a, tr, j, f in zip(np.flatnonzero(hit), track, slot, at, strict=True)],
                    dtype=np.int64)
    pair[rows[hit]] = track * (balls - 1) + np.minimum(slot - left, max(balls - 2, 0))
    return searching


def test_first_contact_kernel_matches_its_numpy_twin():
    # Source: the NumPy code it replaced (twin above); tolerance 0 (bit for bit): random
    # gaps closing and opening, pairs at the zone's ends, empty slots (NaN), unresolved
    # balls, rows already in contact, ties between tracks and pairs.
    rng = np.random.default_rng(12)
    size, m, tracks, slots, balls, half = 60, 50, 2, 13, 12, 0.06
    rows = np.sort(rng.choice(size, m, replace=False)).astype(np.int64)
    z0 = np.sort(rng.uniform(-0.065, 0.065, (m, tracks, slots)), axis=2)
    z1 = z0 - rng.uniform(0.0, 0.006, (m, tracks, slots))
    z0[:5, :, -1] = z1[:5, :, -1] = np.nan
    gap0 = rng.uniform(-1e-6, 4e-6, (m, tracks, slots - 1))
    gap1 = gap0 - rng.uniform(-1e-6, 5e-6, gap0.shape)
    gap0[5:8, 0, 3] = 0.0
    gap1[8:10] = gap1[8:10, :1, :1]  # ties
    gap0[8:10] = gap0[8:10, :1, :1]
    gap0[:5, :, -1] = gap1[:5, :, -1] = np.nan
    ok = rng.uniform(size=z0.shape) < 0.95
    valid1, valid2 = rng.uniform(size=z0.shape) < 0.99, rng.uniform(size=z0.shape) < 0.99
    time = np.where(rng.uniform(size=size) < 0.2, 0.1, np.inf)
    pair = np.where(np.isfinite(time), 3, -1).astype(np.int64)
    valid = rng.uniform(size=size) < 0.9
    mine, twin = [time.copy(), pair.copy(), valid.copy()], [time.copy(), pair.copy(),
                                                            valid.copy()]
    searching = np.empty(m, dtype=bool)
    first_contact_kernel(rows, z0, z1, gap0, gap1, ok, valid1, valid2, half, 0.2, 0.025, balls,
                         *mine, searching, np.empty((0, 0, 0)))
    want = first_contact_twin(rows, z0, z1, gap0, gap1, ok, valid1, valid2, half, 0.2, 0.025,
                              balls, *twin)
    assert_array_equal(searching, want)
    assert_array_equal(_bits(mine[0]), _bits(twin[0]))
    assert_array_equal(mine[1], twin[1])
    assert_array_equal(mine[2], twin[2])
    hits = np.isfinite(twin[0]) & ~np.isfinite(time)
    assert 10 < hits.sum() < m - 10  # both branches seen
    assert (twin[1][hits] >= balls - 1).any() and (twin[1][hits] < balls - 1).any()


def test_a_contact_after_an_exit_in_its_step_is_counted_among_the_balls_in_the_zone():
    # By hand (zone [-0.06, 0.06] m, a step of 0.025 s from t = 0.2 s, 12-ball trains): the
    # trailing ball (slot 0) drifts from -0.059 to -0.061 m and leaves the zone at half the
    # step; the pair of slots 1 and 2 closes at 0.75 of the step (gap 3 -> -1 um), when the
    # ball of slot 1 is the zone's trailing ball: its pair is the zone's first (index 0), not
    # 1 (the slot index, which the kernel gave before session 30: exits are applied at the
    # step's end, so within the step the slots still hold the ball that left). The same
    # contact at 0.25 of the step (gap 1 -> -3 um), before the exit, is pair 1.
    half, slots = 0.06, 13
    z0 = np.full((1, 1, slots), np.nan)
    z0[0, 0, :12] = -0.059 + 0.01005 * np.arange(12)
    z1 = z0 - 0.002
    for gap_start, gap_end, want in ((3e-6, -1e-6, 0), (1e-6, -3e-6, 1)):
        gap0 = np.full((1, 1, slots - 1), 5e-5)
        gap1 = gap0.copy()
        gap0[0, 0, 1], gap1[0, 0, 1] = gap_start, gap_end
        ok = np.isfinite(z0)
        time, pair, valid = np.full(1, np.inf), np.full(1, -1), np.ones(1, dtype=bool)
        first_contact_kernel(np.array([0]), z0, z1, gap0, gap1, ok, ok, ok, half, 0.2, 0.025,
                             12, time, pair, valid, np.empty(1, dtype=bool),
                             np.empty((0, 0, 0)))
        frac = gap_start / (gap_start - gap_end)
        assert time[0] == pytest.approx(0.2 + frac * 0.025, abs=1e-15)
        assert pair[0] == want


def test_carriage_motion_kernel_matches_the_numpy_expression():
    # Source: the NumPy expression of CarriageFrame.move it replaced; tolerance 0 (bit for
    # bit): epsilon finite, NaN (nominal), +-inf, -0.0.
    rng = np.random.default_rng(5)
    position = rng.uniform(-0.06, 0.06, 4000)
    w = rng.normal(0.0, 1e-3, 4000)
    w[:10], w[10:20], w[20:30], w[30:40] = np.nan, np.inf, -np.inf, -0.0
    for h in (0.0125, 0.025):
        got = np.empty(position.shape)
        carriage_motion_kernel(position, w, h, 0.2, got)
        assert_array_equal(_bits(got), _bits(position - h * (1.0 - np.nan_to_num(w)) * 0.5
                                             * 0.2))


def _trains(rng, m, tracks, slots):
    """Random slots near the trailing end of a 60 mm zone (as the advance_kernel test of
    tests/study/test_carriage_along_track.py): positions at the start and end of a step, ids,
    resolved flags, counts."""
    half, d = 0.03, 0.01
    count = rng.integers(1, slots + 1, (m, tracks)).astype(np.int64)
    z0 = np.full((m, tracks, slots), np.nan)
    ids = np.full((m, tracks, slots), -1, dtype=np.int64)
    for a in range(m):
        for t in range(tracks):
            c = count[a, t]
            z0[a, t, :c] = rng.uniform(-half - 0.014, -half - 0.004) + np.cumsum(
                rng.uniform(d, d + 0.002, c))
            ids[a, t, :c] = np.arange(c)
    z1 = z0 - rng.uniform(0.0, 0.003, (m, tracks, 1))
    return z0, z1, ids, rng.random((m, tracks, slots)) < 0.9, count


def test_advance_frame_kernel_is_advance_kernel_written_back():
    # Source: CarriageFrame.advance before the kernel (advance_kernel on the rows' copies of
    # count, entered and entering_gap, then the NumPy writes to the frame and the epsilon of
    # the slots' travel); tolerance 0 (bit for bit): exits, entries, overflow, a subset of rows.
    rng = np.random.default_rng(21)
    size, m, tracks, slots, balls, cap = 300, 220, 2, 6, 4, 3
    half, d, t0, dt, v = 0.03, 0.01, 0.3, 0.01, 0.2
    rows = np.sort(rng.choice(size, m, replace=False)).astype(np.int64)
    z0, z1, ids, ok, sub_count = _trains(rng, m, tracks, slots)
    count = np.zeros((size, tracks), np.int64)
    count[rows] = sub_count
    entered = rng.integers(0, cap + 1, (size, tracks)).astype(np.int64)
    gap = rng.uniform(0.0, 0.003, (size, tracks, cap))
    frame = [rng.normal(size=(size, tracks, slots)), np.zeros((size, tracks, slots), np.int64),
             np.zeros((size, tracks, slots), bool), rng.normal(size=(size, tracks, slots)),
             rng.normal(size=(size, tracks, slots))]  # position, id, ok, entry time, velocity
    want = [x.copy() for x in frame]
    want_count, want_entered = count.copy(), entered.copy()
    w0, w1, wid, wok = z0.copy(), z1.copy(), ids.copy(), ok.copy()
    w_overflow = np.zeros(m, bool)
    w_events = [np.empty(z0.shape, np.int64), np.empty(z0.shape),
                np.empty(z0.shape, np.int64), np.empty(z0.shape)]
    sub_count, sub_entered = want_count[rows], want_entered[rows]
    advance_kernel(w0, w1, wid, wok, sub_count, sub_entered, gap[rows], half, d, balls, t0, dt,
                   w_overflow, *w_events)
    want[0][rows], want[1][rows], want[2][rows] = w1, wid, wok
    want_count[rows], want_entered[rows] = sub_count, sub_entered
    want[3][rows] = w_events[3]
    want[4][rows] = 1.0 - (w0 - w1) / (0.5 * v * dt)
    overflow = np.zeros(m, bool)
    events = [np.empty(z0.shape, np.int64), np.empty(z0.shape), np.empty(z0.shape, np.int64),
              np.empty(z0.shape)]
    advance_frame_kernel(rows, z0, z1, ids, ok, count, entered, gap, half, d, balls, t0, dt,
                         0.5 * v * dt, overflow, *events, *frame)
    for got, ref in zip([z0, z1, ids, ok, count, entered, overflow, *events, *frame],
                        [w0, w1, wid, wok, want_count, want_entered, w_overflow, *w_events,
                         *want], strict=True):
        assert_array_equal(_bits(got) if got.dtype == np.float64 else got,
                           _bits(ref) if ref.dtype == np.float64 else ref)
    assert overflow.any() and (w_events[0] >= 0).sum() > 50 and (w_events[2] >= 0).sum() > 50


def joined_twin(take, loaded1, loaded2, eps1, eps2, valid1, valid2, unloaded1, unloaded2):
    """The NumPy code of CarriageFrame._joined (session 13)."""
    loaded = loaded1 | take
    n1 = int(np.count_nonzero(loaded1))
    src = np.where(take.reshape(-1), np.cumsum(loaded2) - 1 + n1,
                   np.cumsum(loaded1) - 1)[loaded.reshape(-1)]
    return (loaded, np.where(take, eps2, eps1), np.where(take, valid2, valid1),
            np.where(take, unloaded2, unloaded1), src)


def test_joined_kernel_matches_its_numpy_twin():
    # Source: the NumPy code it replaced (twin above); tolerance 0 (bit for bit), with NaN
    # epsilon, balls taken where the start had none loaded and where it had.
    rng = np.random.default_rng(22)
    shape = (40, 2, 13)
    loaded1, loaded2 = rng.random(shape) < 0.7, rng.random(shape) < 0.7
    take = loaded2 & (rng.random(shape) < 0.2)
    eps1, eps2 = (np.where(rng.random(shape) < 0.1, np.nan, rng.normal(size=shape))
                  for _ in range(2))
    flags = [rng.random(shape) < 0.5 for _ in range(4)]
    want = joined_twin(take, loaded1, loaded2, eps1, eps2, *flags)
    got = [np.empty(shape, bool), np.empty(shape), np.empty(shape, bool),
           np.empty(shape, bool), np.empty(take.size, np.int64)]
    n = joined_kernel(take, loaded1, loaded2, eps1, eps2, *flags, *got)
    got[4] = got[4][:n]
    assert (take & ~loaded1).any() and (take & loaded1).any()
    for g, w in zip(got, want, strict=True):
        assert_array_equal(_bits(g) if g.dtype == np.float64 else g,
                           _bits(w) if w.dtype == np.float64 else w)


def test_step_velocity_kernel_matches_the_numpy_expression():
    # Source: the NumPy expression of CarriageFrame.velocity it replaced; tolerance 0 (bit
    # for bit): epsilon finite, NaN, +-inf, -0.0.
    rng = np.random.default_rng(23)
    eps1, eps2 = rng.normal(size=4000), rng.normal(size=4000)
    for eps in (eps1, eps2):
        eps[rng.integers(0, 4000, 200)] = rng.choice([np.nan, np.inf, -np.inf, -0.0], 200)
    loaded2 = rng.random(4000) < 0.6
    got = np.empty(4000)
    step_velocity_kernel(loaded2, eps2, eps1, got)
    assert_array_equal(_bits(got), _bits(np.where(loaded2, np.nan_to_num(eps2),
                                                  np.nan_to_num(eps1))))


def initial_balls_twin(loaded, n, values, fills):
    """The NumPy code of _initial_state (session 13): full arrays, x[loaded] = values, the
    first n slots."""
    out = []
    for v, fill in zip(values, fills, strict=True):
        x = np.full(loaded.shape + v.shape[1:], fill, dtype=v.dtype)
        x[loaded] = v
        out.append(np.ascontiguousarray(x[:, :, :n]))
    return out


def test_initial_balls_kernel_matches_its_numpy_twin():
    # Source: the NumPy code it replaced (twin above); tolerance 0 (bit for bit): loaded
    # balls in the first n slots and beyond, NaN epsilon, every fill.
    rng = np.random.default_rng(24)
    shape, n = (30, 2, 13), 12
    loaded = rng.random(shape) < 0.7
    k = int(loaded.sum())
    values = [np.where(rng.random(k) < 0.1, np.nan, rng.normal(size=k)), rng.random(k) < 0.5,
              rng.random(k) < 0.5, rng.random(k) < 0.5, rng.normal(size=(k, 4)),
              rng.normal(size=(k, 4)), rng.integers(0, 3, k).astype(np.int8),
              rng.integers(0, 6, k).astype(np.int8)]
    fills = [np.nan, False, True, True, np.nan, 0.0, 2, 5]
    want = initial_balls_twin(loaded, n, values, fills)
    got = [np.empty(shape[:2] + (n,) + v.shape[1:], v.dtype) for v in values]
    initial_balls_kernel(loaded, *values, 2, 5, *got)
    assert loaded[:, :, n:].any()
    for g, w in zip(got, want, strict=True):
        assert_array_equal(_bits(g) if g.dtype == np.float64 else g,
                           _bits(w) if w.dtype == np.float64 else w)


def carry_slots_twin(old_id, old_loaded, old_eps, old_valid, old_unloaded, old_row, new_id):
    """carry_slots_kernel as a plain lookup (the kernel before it searched from the previous
    ball's slot): each new slot's ball in its old track, the index among the old loaded
    slots in C order."""
    flat = np.cumsum(old_loaded.reshape(-1)).reshape(old_id.shape) - 1
    out = [np.zeros(new_id.shape, bool), np.full(new_id.shape, np.nan),
           np.ones(new_id.shape, bool), np.zeros(new_id.shape, bool), new_id >= 0,
           np.full(new_id.shape, -1, np.int64)]
    for r, a in enumerate(old_row):
        for t, j in np.ndindex(new_id.shape[1:]):
            where = np.flatnonzero(old_id[a, t] == new_id[r, t, j])
            if new_id[r, t, j] < 0 or len(where) == 0:
                continue
            p = where[0]
            out[0][r, t, j], out[1][r, t, j] = old_loaded[a, t, p], old_eps[a, t, p]
            out[2][r, t, j], out[3][r, t, j] = old_valid[a, t, p], old_unloaded[a, t, p]
            out[4][r, t, j] = False
            out[5][r, t, j] = flat[a, t, p] if old_loaded[a, t, p] else -1
    return out


def test_carry_slots_kernel_matches_a_lookup_in_any_order():
    # Source: a plain lookup by id (twin above); tolerance 0 (bit for bit): the balls in their
    # order with exits and entries, and (not arising in the frame) shuffled, so that the
    # search from the previous ball's slot has to start again from the first.
    rng = np.random.default_rng(25)
    m, tracks, slots = 60, 2, 9
    old_id = np.full((m, tracks, slots), -1, dtype=np.int64)
    new_id = np.full((m, tracks, slots), -1, dtype=np.int64)
    for a, t in np.ndindex(m, tracks):
        n = rng.integers(1, slots + 1)
        old_id[a, t, :n] = 10 * t + np.arange(n)
        ids = list(range(10 * t + rng.integers(0, 3), 10 * t + n)) + [100, 101][
            :rng.integers(0, 3)]
        ids = ids[:slots]
        if a % 3 == 0:
            rng.shuffle(ids)
        new_id[a, t, :len(ids)] = ids
    old_loaded = (old_id >= 0) & (rng.random(old_id.shape) < 0.8)
    old_eps = np.where(old_loaded, rng.normal(size=old_id.shape), np.nan)
    old_valid = ~old_loaded | (rng.random(old_id.shape) < 0.9)
    old_unloaded = old_loaded & (rng.random(old_id.shape) < 0.2)
    rows = np.sort(rng.choice(m, 40, replace=False))
    new = new_id[rows]
    got = [np.empty(new.shape, bool), np.empty(new.shape), np.empty(new.shape, bool),
           np.empty(new.shape, bool), np.empty(new.shape, bool),
           np.empty(new.shape, np.int64)]
    carry_slots_kernel(old_id, old_loaded, old_eps, old_valid, old_unloaded, rows, new, *got)
    want = carry_slots_twin(old_id, old_loaded, old_eps, old_valid, old_unloaded, rows, new)
    assert want[4].any() and (want[5] >= 0).any()
    for g, w in zip(got, want, strict=True):
        assert_array_equal(_bits(g) if g.dtype == np.float64 else g,
                           _bits(w) if w.dtype == np.float64 else w)


def test_slot_inputs_kernel_matches_the_numpy_expressions():
    # Source: the NumPy expressions of the carriage evaluation it replaced; tolerance 0 (bit
    # for bit): empty slots (id -1, z NaN), the zone's ends, NaN z of an occupied slot.
    rng = np.random.default_rng(26)
    z = rng.uniform(-0.07, 0.07, 5000)
    ids = rng.integers(-1, 20, 5000)
    z[ids < 0] = np.nan
    z[:4], ids[:4] = [0.06, -0.06, np.nan, -0.0], [1, 2, 3, 4]
    half, shift = 0.06, 0.2 * 0.137
    occupied = ids >= 0
    with np.errstate(invalid="ignore"):
        want_loaded = occupied & (np.abs(z) <= half)
    want_z = np.where(occupied, z, 0.0)
    got = np.empty(5000, bool), np.empty(5000), np.empty(5000)
    slot_inputs_kernel(z, ids, half, shift, *got)
    assert want_loaded[:2].all() and not want_loaded[2]
    assert_array_equal(got[0], want_loaded)
    assert_array_equal(_bits(got[1]), _bits(want_z))
    assert_array_equal(_bits(got[2]), _bits(want_z + shift))
