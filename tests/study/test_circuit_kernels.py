"""The compiled glue of the carriage's ball circuits (:mod:`tolsim.study.pipeline.circuit_kernels`).

Each kernel replaced a chain of NumPy calls in :mod:`tolsim.study.pipeline.carriage_circuit`;
the references below are those chains as they were (tolsim commit 1d166a1), and the kernels
must give their results bit for bit (tolerance 0: ``assert_array_equal``) on random circuits
with the edge cases: an empty zone, a full circuit, a zone across the ring's end.
"""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.study.pipeline.carriage_circuit import (
    circuit_events,
    entering_velocity,
    slots_kernel,
)
from tolsim.study.pipeline.circuit_kernels import (
    assembly_stiffness_kernel,
    circuit_figures_kernel,
    circuit_gaps_kernel,
    ring_inputs_kernel,
    step_contacts_kernel,
)

N, SLOTS, CODES = 11, 7, 4


def zones(rng, circuits):
    """Loaded masks (C, N): one cyclic run per circuit; row 0 empty, row 1 full, row 2 across
    the ring's end, the others random (empty and full among them)."""
    loaded = np.zeros((circuits, N), dtype=bool)
    loaded[1] = True
    loaded[2, [N - 2, N - 1, 0, 1]] = True
    for c in range(3, circuits):
        start, size = rng.integers(N), rng.integers(0, N + 1)
        loaded[c, (start + np.arange(size)) % N] = True
    return loaded


def slot_rings(rng, loaded):
    """The ring ball in each slot (C, S): a random subset of the loaded balls, -1 elsewhere."""
    ring = np.full((len(loaded), SLOTS), -1, dtype=np.int64)
    for c, row in enumerate(loaded):
        balls = rng.permutation(np.flatnonzero(row))[: rng.integers(0, SLOTS + 1)]
        ring[c, : len(balls)] = balls
    return ring


def reference_entering(eps, stiffness, loaded, pushed):
    # entering_velocity at tolsim 1d166a1
    entry = loaded & ~np.roll(loaded, 1, axis=1)
    rows = np.flatnonzero(entry.any(axis=1))
    first = np.argmax(entry[rows], axis=1)
    fill = ~loaded[rows]
    for values in (eps, stiffness, pushed):
        sub = values[rows]
        sub[fill] = np.broadcast_to(sub[np.arange(len(rows)), first][:, None], sub.shape)[fill]
        values[rows] = sub


def reference_ring_inputs(ring, eps, stiff, fallback, pushed, unresolved, loaded, ok):
    # CircuitFrame.advance at tolsim 1d166a1, from the slots to entering_velocity
    c = len(ring)
    finite = np.isfinite(stiff) & (stiff > 0)
    ring_eps, ring_k = np.zeros((c, N)), np.repeat(np.asarray(fallback)[:, None], N, axis=1)
    ring_pushed = np.zeros((c, N), dtype=bool)
    line, slot = np.nonzero(ring >= 0)
    target = ring[line, slot]
    ring_eps[line, target] = eps[line, slot]
    ring_k[line, target] = np.where(finite, stiff, np.asarray(fallback)[:, None])[line, slot]
    ring_pushed[line, target] = pushed[line, slot]
    ok[line, target] &= ~unresolved[line, slot]
    reference_entering(ring_eps, ring_k, loaded, ring_pushed)
    return ring_eps, ring_k, ring_pushed, ok


@pytest.mark.parametrize("seed", range(4))
def test_ring_inputs_and_entering_fill_match_the_numpy_chain(seed):
    rng = np.random.default_rng(seed)
    c = 40
    loaded = zones(rng, c)
    ring = slot_rings(rng, loaded)
    eps = rng.normal(size=(c, SLOTS))
    stiff = rng.normal(5.0, 5.0, size=(c, SLOTS))
    stiff[rng.random((c, SLOTS)) < 0.2] = np.nan
    pushed, unresolved = (rng.random((c, SLOTS)) < 0.3 for _ in range(2))
    ok = rng.random((c, N)) < 0.8
    fallback = rng.uniform(1.0, 3.0, size=c)  # each circuit's own
    want = reference_ring_inputs(ring, eps, stiff, fallback, pushed, unresolved, loaded,
                                 ok.copy())
    got = [np.empty((c, N)), np.empty((c, N)), np.empty((c, N), dtype=bool)]
    got_ok = ok.copy()
    ring_inputs_kernel(ring, eps, stiff, fallback, pushed, unresolved, loaded, got_ok, *got)
    for a, b in zip([*got, got_ok], want, strict=True):
        assert_array_equal(a, b)
    # entering_velocity alone, with and without the pushed flags
    values = [rng.normal(size=(c, N)), rng.normal(size=(c, N)), rng.random((c, N)) < 0.5]
    expect = [v.copy() for v in values]
    reference_entering(*expect[:2], loaded, expect[2])
    entering_velocity(values[0], values[1], loaded, values[2])
    for a, b in zip(values, expect, strict=True):
        assert_array_equal(a, b)


def reference_events(sigma0, sigma1, loaded0, loaded1, length, zone, ring_id, previous_id,
                     slot_ring, t, dt):
    # circuit_events at tolsim 1d166a1
    shape = previous_id.shape
    slots = shape[-1]
    exit_id = np.full(shape, -1, dtype=np.int64)
    entry_id = np.full(shape, -1, dtype=np.int64)
    exit_time, entry_time = np.full(shape, np.nan), np.full(shape, np.nan)
    flat = (exit_id.reshape(-1, slots), exit_time.reshape(-1, slots),
            entry_id.reshape(-1, slots), entry_time.reshape(-1, slots))
    length = np.asarray(length)[:, None]
    x0 = np.mod(sigma0, length)
    span = sigma1 - sigma0
    for leaving, boundary, (ids, times, where) in (
            (loaded0 & ~loaded1, zone, (flat[0], flat[1], previous_id.reshape(-1, slots))),
            (~loaded0 & loaded1, length, (flat[2], flat[3], None))):
        line, ring = np.nonzero(leaving)
        if line.size == 0:
            continue
        crossing = np.broadcast_to(boundary, sigma0.shape)[line, ring] - x0[line, ring]
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(span[line, ring] > 0, crossing / span[line, ring], 1.0)
        when = t + np.clip(frac, 0.0, 1.0) * dt
        if where is None:
            match = slot_ring.reshape(-1, slots)[line] == ring[:, None]
        else:
            match = where[line] == ring_id[ring][:, None]
        found = match.any(axis=1)
        slot = np.argmax(match, axis=1)
        ids[line[found], slot[found]] = ring_id[ring[found]]
        times[line[found], slot[found]] = when[found]
    return [exit_id, exit_time, entry_id, entry_time]


@pytest.mark.parametrize("seed", range(4))
def test_circuit_events_match_the_numpy_chain(seed):
    rng = np.random.default_rng(seed)
    k, tracks = 12, 2
    c = k * tracks
    length = rng.uniform(0.2, 0.3, c)
    sigma0 = rng.uniform(-0.1, 0.6, (c, N))  # negative positions and several laps
    sigma1 = sigma0 + rng.uniform(-1e-3, 5e-3, (c, N))
    loaded0, loaded1 = zones(rng, c), zones(rng, c)
    still = (loaded0 != loaded1) & (rng.random((c, N)) < 0.3)
    sigma1[still] = sigma0[still]  # a crossing without motion: at the end of the step
    ring_id = rng.permutation(3 * N)[:N].astype(np.int64)
    slot_ring = slot_rings(rng, loaded1)
    previous_id = np.where(slot_rings(rng, loaded0) >= 0, ring_id[slot_rings(rng, loaded0)], -1)
    args = (sigma0, sigma1, loaded0, loaded1, length, 0.06, ring_id,
            previous_id.reshape(k, tracks, SLOTS), slot_ring.reshape(k, tracks, SLOTS), 0.3,
            0.01)
    for a, b in zip(circuit_events(*args), reference_events(*args), strict=True):
        assert_array_equal(a, b)


def test_circuit_gaps_match_the_numpy_chain():
    # CircuitFrame.gaps at tolsim 1d166a1, on a subset of the circuits in any order
    rng = np.random.default_rng(7)
    sigma = np.cumsum(rng.uniform(0.005, 0.02, (9, N)), axis=1) - 0.05
    d = rng.uniform(0.0049, 0.0051, (9, N))
    length = sigma[:, -1] - sigma[:, 0] + 0.02
    circuits = np.array([4, 0, 8, 8, 2])
    s, dd, ln = sigma[circuits], d[circuits], length[circuits]
    ahead = np.roll(s, -1, axis=1)
    ahead[:, -1] += ln
    want = ahead - s - 0.5 * (dd + np.roll(dd, -1, axis=1))
    got = np.empty((len(circuits), N))
    circuit_gaps_kernel(sigma, d, length, circuits, got)
    assert_array_equal(got, want)


def reference_contacts(ok, loaded, closed, force, pair, where, travel, v, t_end):
    # CircuitContact.moved and _ring_pair at tolsim 1d166a1, per circuit
    both_ok = ok & np.roll(ok, -1, axis=1)
    count = np.stack([(where == code).sum(axis=1) for code in range(CODES)], axis=1)
    pair_ok = np.take_along_axis(both_ok, np.maximum(pair, 0), axis=1) & (pair >= 0)
    inside = (where == 0) & pair_ok
    t_event = np.where(inside, travel / v, np.inf)
    pressed = closed & loaded & np.roll(loaded, -1, axis=1) & both_ok & (force > 0.0)
    t_pressed = np.where(pressed, t_end, np.inf)
    t_all = np.minimum(t_event.min(axis=1), t_pressed.min(axis=1))
    ring_pair = np.full(len(ok), -1)
    for line in range(len(ok)):
        if inside[line].any():
            slots = np.flatnonzero(inside[line])
            ring_pair[line] = pair[line][slots[np.argmin(travel[line][slots])]]
        elif pressed[line].any():
            ring_pair[line] = np.flatnonzero(pressed[line])[0]
    return count, t_all, ring_pair


@pytest.mark.parametrize("seed", range(4))
def test_step_contacts_match_the_numpy_chain(seed):
    rng = np.random.default_rng(seed)
    c, events = 60, N
    loaded = zones(rng, c)
    ok = rng.random((c, N)) < 0.9
    closed = rng.random((c, N)) < 0.3
    force = rng.normal(0.0, 1.0, (c, N))
    count = rng.integers(0, 4, c)
    pair = np.full((c, events), -1, dtype=np.int64)
    where = np.full((c, events), -1, dtype=np.int8)
    travel = np.full((c, events), np.nan)
    for line in range(c):
        pair[line, : count[line]] = rng.integers(0, N, count[line])
        where[line, : count[line]] = rng.integers(0, CODES, count[line])
        travel[line, : count[line]] = rng.choice([1e-3, 2e-3, 2e-3, 5e-3], count[line])
    travel[5, 0], where[5, 0], pair[5, 0], ok[5] = np.nan, 0, 3, True  # NaN propagates
    want = reference_contacts(ok, loaded, closed, force, pair, where, travel, 0.2, 0.05)
    got = (np.empty((c, CODES), dtype=np.int64), np.empty(c), np.empty(c, dtype=np.int64))
    no_entry = np.full(ok.shape, np.nan)  # (no ball entered: the times of the chain)
    step_contacts_kernel(ok, loaded, closed, force, pair, where, travel, 0.2, 0.05, CODES,
                         no_entry, *got)
    for a, b in zip(got, want, strict=True):
        assert_array_equal(a, b)


def test_slots_match_the_numpy_chain():
    # CircuitFrame._slots at tolsim 1d166a1: the loaded balls of each circuit in z order (a
    # stable sort: equal z in ring order), then ``ring_ok`` gathered with take_along_axis
    # (True at empty slots); more loaded balls than slots empties the circuit (count -1)
    rng = np.random.default_rng(3)
    c = 50
    loaded = zones(rng, c)
    loaded[3] = False
    loaded[3, :3] = True
    length = rng.uniform(0.2, 0.3, c)
    sigma = rng.uniform(-0.1, 0.6, (c, N))
    sigma[3, 1] = sigma[3, 0]  # equal z: ring order
    ring_id = rng.permutation(3 * N)[:N].astype(np.int64)
    ring_ok = rng.random((c, N)) < 0.7
    circuits = np.array([3, 0, 1, 2, *rng.integers(0, c, 30)])
    k = len(circuits)
    z, ids, ring = np.empty((k, SLOTS)), np.empty((k, SLOTS), dtype=np.int64), np.empty(
        (k, SLOTS), dtype=np.int64)
    ok, count = np.empty((k, SLOTS), dtype=bool), np.empty(k, dtype=np.int64)
    slots_kernel(sigma, loaded, length, circuits, 0.03, ring_id, ring_ok, z, ids, ring, ok,
                 count)
    for i, line in enumerate(circuits):
        balls = np.flatnonzero(loaded[line])
        if len(balls) > SLOTS:
            want_ring = np.full(SLOTS, -1)
            assert count[i] == -1
        else:
            zz = 0.03 - np.mod(sigma[line, balls], length[line])
            order = np.argsort(zz, kind="stable")
            want_ring = np.full(SLOTS, -1)
            want_ring[: len(balls)] = balls[order]
            assert count[i] == len(balls)
            assert_array_equal(z[i, : len(balls)], zz[order])
            assert np.isnan(z[i, len(balls):]).all()
        assert_array_equal(ring[i], want_ring)
        assert_array_equal(ids[i], np.where(want_ring >= 0, ring_id[want_ring], -1))
        want_ok = np.take_along_axis(ring_ok[line], np.maximum(want_ring, 0), axis=0)
        assert_array_equal(ok[i], np.where(want_ring >= 0, want_ok, True))


@pytest.mark.parametrize("tracks", [1, 2, 3])
def test_circuit_figures_match_the_numpy_chain(tracks):
    # CircuitContact.moved at tolsim bb94a7b: where_count += hits summed over the tracks,
    # column_max = np.maximum(column_max, max over the tracks), column_mean += max over the
    # tracks x travel; NaN propagates (a NaN force, a NaN figure before)
    rng = np.random.default_rng(tracks)
    size, rows = 12, np.array([0, 2, 3, 7, 8, 11])
    k = len(rows)
    hits = rng.integers(0, 4, (k * tracks, CODES))
    column = rng.uniform(0.0, 1.0, (k * tracks, 4))
    column[rng.random(column.shape) < 0.2] = 0.0
    column[3] = np.nan
    where_count = rng.integers(0, 9, (size, CODES))
    column_max = rng.uniform(0.0, 1.0, (size, 2))
    column_max[rows[-1], 0] = np.nan
    column_mean = rng.uniform(0.0, 1.0, (size, 2))
    travel = 0.2 * 0.0125
    want = [where_count.copy(), column_max.copy(), column_mean.copy()]
    want[0][rows] += hits.reshape(k, tracks, -1).sum(axis=1)
    c = column.reshape(k, tracks, 4)
    want[1][rows] = np.maximum(want[1][rows], c[:, :, :2].max(axis=1))
    want[2][rows] += c[:, :, 2:].max(axis=1) * travel
    circuit_figures_kernel(rows, tracks, hits, column, travel, where_count, column_max,
                           column_mean)
    for a, b in zip((where_count, column_max, column_mean), want, strict=True):
        assert_array_equal(a, b)


def test_a_ball_without_stiffness_takes_its_own_assemblys_mean():
    # closed form: the mean of the finite, positive K of the assembly's slots over all its
    # tracks (exact here: sums of small binary fractions), 1.0 for an assembly with none;
    # tolerance 0. The value of one assembly does not change with the assemblies beside it.
    nan = np.nan
    stiff = np.array([[1.0, 2.0, nan], [3.0, -1.0, 0.0],  # assembly 0: (1 + 2 + 3) / 3
                      [nan, nan, nan], [0.0, -2.0, nan],  # assembly 1: none -> 1.0
                      [0.5, 0.25, 0.25], [nan, 1.0, nan]])  # assembly 2: 2 / 4
    out = np.empty(6)
    assembly_stiffness_kernel(stiff, 2, np.inf, out)
    assert_array_equal(out, [2.0, 2.0, 1.0, 1.0, 0.5, 0.5])
    alone = np.empty(2)
    assembly_stiffness_kernel(np.ascontiguousarray(stiff[4:]), 2, np.inf, alone)
    assert_array_equal(alone, out[4:])
    # an anchor's K (ANCHOR_STIFFNESS and above) is left out of the mean (session 28: it made
    # the stand-in of a three-point ball beside anchors nearly rigid)
    anchored = stiff.copy()
    anchored[0, 2] = anchored[4, 0] = 1e9
    assembly_stiffness_kernel(anchored, 2, 1e9, out)
    assert_array_equal(out, [2.0, 2.0, 1.0, 1.0, 1.5 / 3, 1.5 / 3])
