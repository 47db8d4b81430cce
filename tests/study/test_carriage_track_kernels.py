"""The compiled glue of the carriage along the track against the NumPy code it replaced."""

import numpy as np
from numpy.testing import assert_array_equal

from tolsim.study.pipeline.carriage_track_kernels import (
    carriage_motion_kernel,
    first_contact_kernel,
    newton_start_kernel,
    remember_kernel,
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
        newton_start_kernel(solution, solved_at, start, rows, t, got)
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


def first_contact_twin(rows, z0, z1, gap0, gap1, ok, valid1, valid2, half, t, dt, balls,
                       time, pair, valid):
    """The NumPy code of CarriageFirstContact.observe (session 12)."""
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
    pair[rows[hit]] = track * (balls - 1) + np.minimum(slot, max(balls - 2, 0))
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
