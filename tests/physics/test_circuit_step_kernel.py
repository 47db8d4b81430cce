"""The circuit's step kernel (:func:`tolsim.physics.circuit.step_circuit_kernel`) against
the kernel it replaced, bit for bit.

``reference_*`` below is :func:`step_circuit_kernel` as it was at tolsim commit bb94a7b (its
functions unchanged, without the Numba decorators, run as plain Python on NumPy scalars: the
same IEEE operations in the same order, and Python's float ``%`` is Numba's). The new kernel
must give every output bit for bit (tolerance 0: ``assert_array_equal``, NaN where NaN) on
random circuits with the edge cases: open and closed rings (zero slack), no drag, a reversed
stroke, pushed balls, the cascade of a first step with open gaps, an event overflow.
"""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.physics import circuit
from tolsim.physics.circuit import (
    SPEED_TOLERANCE,
    STATUS_EVENT_OVERFLOW,
    STATUS_ITERATIONS,
    STATUS_JAMMED,
    TIE_TOLERANCE,
    WHERE_ENTRY,
    WHERE_EXIT,
    WHERE_INSIDE,
    WHERE_RETURN,
    wrap,
)

D = 0.010
ZONE = 12 * 10.05e-3


# ------------------------------------------------- the kernel at tolsim bb94a7b, as Python
def _block_speed(weight, weighted_speed, unloaded, coast, coasting, drag):
    """Speed per unit travel of a block: the minimiser of its objective (eq. 5 of
    :func:`tolsim.physics.circuit.step`); a block without loaded balls rests when it holds
    unloaded balls and there is drag, else its ``coasting`` balls (unloaded with no drag,
    pushed balls in the zone) keep the mean of their speeds ``coast``."""
    if weight > 0.0:
        value = (weighted_speed - unloaded * drag) / weight
        return value if value > 0.0 else 0.0
    if (drag > 0.0 and unloaded > 0.0) or coasting == 0.0:
        return 0.0
    return coast / coasting


def _solve_blocks(free_speed, weight, loaded, pushed, closed, drag, cut, n, label, speed,
                  force, block_start, block_weight, block_sum, block_unloaded, block_coast,
                  block_coasting, block_speed):
    """Generalised pool adjacent violators on the ring, cut at ring pair ``cut`` (-1: the
    closed ring). Writes ``speed`` and ``label`` per ring ball and ``force`` per ring pair;
    returns True when a block holding loaded balls is jammed (speed 0). A ``pushed`` ball (in
    the zone without a groove contact: weight 0, no drag) coasts at its ``free_speed``."""
    start = cut + 1 if cut >= 0 else 0
    top = -1
    r = start if start < n else 0
    for m in range(n):
        top += 1
        block_start[top] = m
        block_weight[top] = weight[r]
        block_sum[top] = weight[r] * free_speed[r]
        block_unloaded[top] = 0.0 if loaded[r] else 1.0
        coasting = pushed[r] or not loaded[r]
        block_coast[top] = free_speed[r] if coasting else 0.0
        block_coasting[top] = 1.0 if coasting else 0.0
        block_speed[top] = _block_speed(block_weight[top], block_sum[top],
                                        block_unloaded[top], block_coast[top],
                                        block_coasting[top], drag)
        while top > 0:
            pair = r - (m - block_start[top]) - 1  # ring pair ahead of the lower block
            if pair < 0:
                pair += n
            if cut < 0 or (closed[pair] and block_speed[top - 1] > block_speed[top]):
                block_weight[top - 1] += block_weight[top]
                block_sum[top - 1] += block_sum[top]
                block_unloaded[top - 1] += block_unloaded[top]
                block_coast[top - 1] += block_coast[top]
                block_coasting[top - 1] += block_coasting[top]
                top -= 1
                block_speed[top] = _block_speed(block_weight[top], block_sum[top],
                                                block_unloaded[top], block_coast[top],
                                                block_coasting[top], drag)
            else:
                break
        r += 1
        if r == n:
            r = 0
    jammed = False
    lowest = 0.0
    r = start if start < n else 0
    for b in range(top + 1):
        first = block_start[b]
        last = block_start[b + 1] - 1 if b < top else n - 1
        value = block_speed[b]
        share = 0.0  # static friction of each unloaded ball of a block at rest
        if value == 0.0 and block_weight[b] > 0.0:
            jammed = True
            share = block_sum[b] / block_unloaded[b] if block_unloaded[b] > 0.0 else 0.0
        resultant = 0.0
        for m in range(first, last + 1):
            speed[r] = value
            label[r] = first
            if loaded[r]:
                resultant -= weight[r] * (value - free_speed[r])
            elif value > 0.0:
                resultant -= drag
            else:
                resultant -= share
            if m < last or cut < 0:
                force[r] = resultant
                if resultant < lowest:
                    lowest = resultant
            else:
                force[r] = 0.0
            r += 1
            if r == n:
                r = 0
    for r in range(n):
        f = force[r] - lowest if cut < 0 else force[r]  # closed ring: least prestress
        force[r] = f if f > 0.0 else 0.0
    return jammed


def _gap(position, half_sum, length, n, r):
    """Gap of ring pair r [m] (ring pair n - 1 closes the circuit)."""
    if r < n - 1:
        return position[r + 1] - position[r] - half_sum[r]
    return position[0] + length - position[n - 1] - half_sum[r]


def _widest_open(q, half_sum, length, closed, n):
    """The open ring pair with the widest gap (-1 when every pair is closed)."""
    cut = -1
    widest = -np.inf
    for r in range(n):
        if not closed[r]:
            g = _gap(q, half_sum, length, n, r)
            if g > widest:
                widest = g
                cut = r
    return cut


def _pushed_speeds(q, half_sum, length, pushed, closed, speed, n, out):
    """The speeds ``out`` of the pushed balls: each run of pushed balls between the
    non-pushed balls a (behind) and b (ahead) at xi_a + (xi_b - xi_a) G_i / G (G_i the gaps
    from a to ball i, G those from a to b, a closed pair's 0; equal shares when G = 0), so
    that every gap of the run closes at once, when a and b would touch with the run between
    them (the rule of :func:`tolsim.study.pipeline.propagation.pushed_along`, on the ring).
    A closed pair counts 0 whatever the rounding of its gap (about 1e-16 m), so a closed run
    that opens does so in equal shares."""
    start = -1
    for r in range(n):
        if not pushed[r]:
            start = r
            break
    if start < 0:
        return
    m = 0
    a = start
    while m < n:
        count = 0
        b = a + 1 if a + 1 < n else 0
        while pushed[b] and count < n:
            count += 1
            b = b + 1 if b + 1 < n else 0
        if count > 0:
            total = 0.0
            r = a
            for _ in range(count + 1):
                g = 0.0 if closed[r] else _gap(q, half_sum, length, n, r)
                total += g if g > 0.0 else 0.0
                r = r + 1 if r + 1 < n else 0
            run = 0.0
            r = a
            for i in range(1, count + 1):
                g = 0.0 if closed[r] else _gap(q, half_sum, length, n, r)
                run += g if g > 0.0 else 0.0
                r = r + 1 if r + 1 < n else 0
                share = run / total if total > 0.0 else i / (count + 1.0)
                out[r] = speed[a] + share * (speed[b] - speed[a])
        m += count + 1
        a = b


def _solve_ring(q, half_sum, length, loaded_speed, coast, stiffness, ball, ring_loaded,
                pushed_in, ring_pushed, ring_closed, drag, n, label, speed, force, block_start,
                block_weight, block_sum, block_unloaded, block_coast, block_coasting,
                block_speed, free_speed, weight):
    """The ring's speeds and forces for its closed pairs (eq. 4 of
    :func:`tolsim.physics.circuit.step`), with the pushed balls' speeds of
    :func:`_pushed_speeds` (solved again after them); returns (cut, jammed)."""
    any_pushed = False
    for r in range(n):
        ring_pushed[r] = ring_loaded[r] and pushed_in[ball[r]]
        if ring_pushed[r]:
            any_pushed = True
            free_speed[r] = coast[r]
            weight[r] = 0.0
        elif ring_loaded[r]:
            free_speed[r] = loaded_speed[r]
            weight[r] = 2.0 * stiffness[ball[r]]
        else:
            free_speed[r] = coast[r]
            weight[r] = 0.0
    cut = _widest_open(q, half_sum, length, ring_closed, n)
    jammed = _solve_blocks(free_speed, weight, ring_loaded, ring_pushed, ring_closed, drag,
                           cut, n, label, speed, force, block_start, block_weight, block_sum,
                           block_unloaded, block_coast, block_coasting, block_speed)
    if any_pushed:
        _pushed_speeds(q, half_sum, length, ring_pushed, ring_closed, speed, n, free_speed)
        jammed = _solve_blocks(free_speed, weight, ring_loaded, ring_pushed, ring_closed,
                               drag, cut, n, label, speed, force, block_start, block_weight,
                               block_sum, block_unloaded, block_coast, block_coasting,
                               block_speed)
    return cut, jammed


def _run_closed(r, ring_pushed, ring_closed, t_pair, limit, n):
    """For a pair r that closes in this advance: the run of pushed balls through it, from the
    non-pushed ball a behind to b ahead (both r and r + 1 when neither is pushed). Returns
    (a, b, record): record when every pair of the run is closed and no later pair of the run
    closes in this advance (one event per run, at its last pair)."""
    a = r
    count = 0
    while ring_pushed[a] and count < n:
        a = a - 1 if a > 0 else n - 1
        count += 1
    b = r + 1 if r + 1 < n else 0
    while ring_pushed[b] and count < n:
        b = b + 1 if b + 1 < n else 0
        count += 1
    record = True
    k = a
    later = False
    for _ in range(n):
        if k == b:
            break
        if not ring_closed[k]:
            record = False
        if later and t_pair[k] <= limit:
            record = False
        if k == r:
            later = True
        k = k + 1 if k + 1 < n else 0
    return a, b, record


def step_circuit_one(position, diameter, eps, stiffness, pushed, loaded, closed, length, zone,
                     drag, travel, travel_start, speed_out, velocity_out, force_out,
                     mean_force_out, column_out, event_pair, event_where, event_travel, work_f,
                     work_i, work_b):
    """One step of one circuit, in place (Notes of :func:`tolsim.physics.circuit.step`).

    ``position``, ``diameter``, ``eps``, ``stiffness``, ``pushed`` (in the zone without a
    groove contact: no epsilon or K of its own), ``loaded`` (ball order, N),
    ``closed`` (ball pair k: balls k, k + 1 mod N) and ``speed_out`` (the balls' circuit
    speeds, read as the coasting speeds of unloaded balls when ``drag`` is 0) are the state,
    updated in place; ``column_out`` (4,) gets the entry and exit column forces at the end of
    the step and their step means. Returns (events, status). Work arrays: ``work_f`` (16, N)
    float, ``work_i`` (3, N) int64, ``work_b`` (3, N) bool.
    """
    n = position.shape[0]
    capacity = event_pair.shape[0]
    forward = travel >= 0.0
    total = abs(travel)
    entry = 0.0 if forward else -zone
    q, half_sum, free_speed, weight, speed, force, mean_force = (
        work_f[0], work_f[1], work_f[2], work_f[3], work_f[4], work_f[5], work_f[6])
    t_pair, t_ball, block_weight, block_sum, coast, loc, block_speed, loaded_speed = (
        work_f[7], work_f[8], work_f[9], work_f[10], work_f[11], work_f[12], work_f[13],
        work_f[14])
    block_coasting = work_f[15]
    ball, label, block_start = work_i[0], work_i[1], work_i[2]
    ring_loaded, ring_closed, ring_pushed = work_b[0], work_b[1], work_b[2]
    # gather in the direction of flow: ring r = ball r (forward) or ball N - 1 - r; loc is
    # the travel from the entry (loaded balls in [0, L_z], unloaded ones in [L_z, L_c])
    for r in range(n):
        b = r if forward else n - 1 - r
        ball[r] = b
        q[r] = position[b] if forward else -position[b]
        ring_loaded[r] = loaded[b]
        coast[r] = speed_out[b]
        mean_force[r] = 0.0
        loaded_speed[r] = 0.5 * (1.0 - eps[b])
        x = (q[r] - entry) % length
        if ring_loaded[r]:
            loc[r] = x - length if x > 0.5 * (zone + length) else x
        else:
            loc[r] = x + length if x < 0.5 * zone else x
    for r in range(n):
        r1 = r + 1 if r + 1 < n else 0
        b, b1 = ball[r], ball[r1]
        half_sum[r] = 0.5 * (diameter[b] + diameter[b1])
        ring_closed[r] = closed[b if forward else b1]
    events = 0
    status = 0
    remaining = total
    tie = TIE_TOLERANCE * total
    column_out[2] = 0.0
    column_out[3] = 0.0
    changed = True  # the state changed since the last solve
    for _iteration in range(4 * n + 16):
        # t_ball and t_pair hold the blocks' unloaded counts and coasting speeds during the
        # solve (they are rewritten after it)
        cut, jammed = _solve_ring(q, half_sum, length, loaded_speed, coast, stiffness, ball,
                                  ring_loaded, pushed, ring_pushed, ring_closed, drag, n,
                                  label, speed, force, block_start, block_weight, block_sum,
                                  t_ball, t_pair, block_coasting, block_speed, free_speed,
                                  weight)
        if jammed:
            status |= STATUS_JAMMED
        best = remaining
        for r in range(n):
            coast[r] = speed[r]
            r1 = r + 1 if r + 1 < n else 0
            # a pair stays closed inside a block, or resting at zero force between two
            # blocks of one speed (a column at rest); it opens where the one ahead is faster
            ring_closed[r] = cut < 0 or (r != cut and label[r] == label[r1]) or (
                ring_closed[r] and speed[r1] - speed[r] <= SPEED_TOLERANCE)
            t_pair[r] = np.inf
            if not ring_closed[r] and speed[r] - speed[r1] > SPEED_TOLERANCE:
                g = _gap(q, half_sum, length, n, r)
                t = (g if g > 0.0 else 0.0) / (speed[r] - speed[r1])
                t_pair[r] = t
                if t < best:
                    best = t
            t_ball[r] = np.inf
            if speed[r] > 0.0:
                d = (zone if ring_loaded[r] else length) - loc[r]
                t = (d if d > 0.0 else 0.0) / speed[r]
                t_ball[r] = t
                if t < best:
                    best = t
        # advance to the event (or the end of the step)
        for r in range(n):
            q[r] += speed[r] * best
            loc[r] += speed[r] * best
            mean_force[r] += force[r] * best
            r1 = r + 1 if r + 1 < n else 0
            if ring_loaded[r] != ring_loaded[r1]:
                column_out[2 if ring_loaded[r1] else 3] += force[r] * best
        done = total - remaining
        remaining -= best
        limit = best + tie
        changed = False
        for r in range(n):
            if t_pair[r] <= limit:
                changed = True
                ring_closed[r] = True
        for r in range(n):
            if t_pair[r] <= limit:
                # a pair with a pushed ball carries force once its run has closed: one event
                # for the run, at its last pair, labelled by the balls at its ends
                a, r1, record = _run_closed(r, ring_pushed, ring_closed, t_pair, limit, n)
                if not record:
                    continue
                last = r1 - 1 if r1 > 0 else n - 1
                if events < capacity:
                    event_pair[events] = ball[last] if forward else ball[r1]
                    if ring_loaded[a] and ring_loaded[r1]:
                        event_where[events] = WHERE_INSIDE
                    elif ring_loaded[r1]:
                        event_where[events] = WHERE_ENTRY
                    elif ring_loaded[a]:
                        event_where[events] = WHERE_EXIT
                    else:
                        event_where[events] = WHERE_RETURN
                    event_travel[events] = travel_start + (done + best if forward
                                                           else -(done + best))
                    events += 1
                else:
                    status |= STATUS_EVENT_OVERFLOW
        for r in range(n):
            if t_ball[r] <= limit:
                changed = True
                ring_loaded[r] = not ring_loaded[r]
                if ring_loaded[r]:
                    loc[r] -= length  # entered: the entry is loc = L_c = 0
        if remaining <= tie:
            break
    else:
        status |= STATUS_ITERATIONS
    # scatter back in ball order, with the end-of-step speeds and forces (solved again only
    # if the last advance ended with an event)
    for r in range(n):
        b = ball[r]
        position[b] = q[r] if forward else -q[r]
        loaded[b] = ring_loaded[r]
    if changed:
        cut, jammed = _solve_ring(q, half_sum, length, loaded_speed, coast, stiffness, ball,
                                  ring_loaded, pushed, ring_pushed, ring_closed, drag, n,
                                  label, speed, force, block_start, block_weight, block_sum,
                                  t_ball, t_pair, block_coasting, block_speed, free_speed,
                                  weight)
        if jammed:
            status |= STATUS_JAMMED
    column_out[0] = 0.0
    column_out[1] = 0.0
    for r in range(n):
        b = ball[r]
        r1 = r + 1 if r + 1 < n else 0
        pair = b if forward else ball[r1]
        speed_out[b] = speed[r]
        velocity_out[b] = 1.0 - 2.0 * speed[r] if ring_loaded[r] else np.nan
        force_out[pair] = force[r]
        mean_force_out[pair] = mean_force[r] / total if total > 0.0 else force[r]
        closed[pair] = ring_closed[r]
        if ring_loaded[r] != ring_loaded[r1]:
            column_out[0 if ring_loaded[r1] else 1] = force[r]
    if total > 0.0:
        column_out[2] /= total
        column_out[3] /= total
    else:
        column_out[2] = column_out[0]
        column_out[3] = column_out[1]
    return events, status


def reference_step(state, eps, stiffness, pushed, travel, drag, travel_start, capacity):
    """The outputs of the old ``step_circuit_kernel`` on ``state`` (a dict of arrays)."""
    m, n = state["position"].shape
    out = {k: v.copy() for k, v in state.items()}
    out.update(velocity=np.empty((m, n)), force=np.empty((m, n)), mean=np.empty((m, n)),
               column=np.empty((m, 4)), count=np.empty(m, dtype=np.int64),
               pair=np.full((m, capacity), -1, dtype=np.int64),
               where=np.full((m, capacity), -1, dtype=np.int8),
               when=np.full((m, capacity), np.nan), status=np.empty(m, dtype=np.int64))
    work_f = np.empty((16, n))
    work_i = np.empty((3, n), dtype=np.int64)
    work_b = np.empty((3, n), dtype=np.bool_)
    with np.errstate(all="ignore"):
        for c in range(m):
            out["count"][c], out["status"][c] = step_circuit_one(
                out["position"][c], state["diameter"][c], eps[c], stiffness[c], pushed[c],
                out["loaded"][c], out["closed"][c], state["length"][c], ZONE, drag, travel,
                travel_start, out["speed"][c], out["velocity"][c], out["force"][c],
                out["mean"][c], out["column"][c], out["pair"][c], out["where"][c],
                out["when"][c], work_f, work_i, work_b)
    return out


def circuits(seed, m=16, balls=30, slack=1.0e-3, zero_slack_rows=2):
    """Circuits of the paper's balls (D +- 1 um) with random gaps summing to ``slack`` (the
    first rows none), random speeds, epsilon, K and pushed balls."""
    rng = np.random.default_rng(seed)
    diameter = D + rng.uniform(-1e-6, 1e-6, (m, balls))
    gap = rng.dirichlet(np.full(balls, 0.5), m) * slack
    gap[:zero_slack_rows] = 0.0
    state = circuit.circuit_state(diameter, gap, ZONE, first_position=rng.uniform(-0.1, 0.3, m),
                                  speed=rng.uniform(0.0, 0.6, (m, balls)))
    eps = rng.normal(0.0, 1e-3, (m, balls))
    stiffness = rng.uniform(300.0, 700.0, (m, balls))
    pushed = rng.random((m, balls)) < 0.08
    return state, eps, stiffness, pushed


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("travel", [2.5e-3, -2.5e-3, 0.02])
@pytest.mark.parametrize("drag", [0.0, 0.02])
def test_step_matches_the_old_kernel_bit_for_bit(seed, travel, drag):
    state, eps, stiffness, pushed = circuits(seed)
    capacity = 4 if seed == 3 else 30  # seed 3: events overflow
    statuses = 0
    for i in range(5):
        want = reference_step(
            {"position": state.position, "diameter": state.diameter, "loaded": state.loaded,
             "closed": state.closed, "speed": state.speed, "length": state.circuit_length},
            eps, stiffness, pushed, travel, drag, i * travel, capacity)
        got = circuit.step(state, eps, stiffness, travel, drag, travel_start=i * travel,
                           event_capacity=capacity, pushed=pushed)
        for name, value in (("position", got.state.position), ("loaded", got.state.loaded),
                            ("closed", got.state.closed), ("speed", got.circuit_speed),
                            ("velocity", got.velocity), ("force", got.contact_force),
                            ("mean", got.mean_contact_force), ("count", got.event_count),
                            ("pair", got.event_pair), ("where", got.event_where),
                            ("when", got.event_travel), ("status", got.status)):
            assert_array_equal(value, want[name], err_msg=name)
        column = np.stack([got.entry_force, got.exit_force, got.entry_force_mean,
                           got.exit_force_mean], axis=1)
        assert_array_equal(column, want["column"])
        statuses |= np.bitwise_or.reduce(got.status)
        state = got.state
    if seed == 3:
        assert statuses & STATUS_EVENT_OVERFLOW  # the case is exercised


@pytest.mark.parametrize("length", [0.3, 0.30409, 1e-3, 7.0])
def test_wrap_is_python_modulo(length):
    # Reference: Python's float %, which Numba's % follows; tolerance 0 (bits, signs of zero)
    rng = np.random.default_rng(5)
    values = np.concatenate([
        rng.uniform(-3.0, 3.0, 2000) * length,
        [0.0, -0.0, length, -length, 2.0 * length, -2.0 * length, np.nextafter(length, 0),
         np.nextafter(length, 3 * length), np.nextafter(2 * length, 0), 5e-324, -5e-324,
         np.nextafter(-length, 0), np.inf, -np.inf, np.nan, 1e300, -1e300]])
    got = np.array([wrap(float(x), length) for x in values])
    want = np.array([float(x) % length for x in values])
    assert_array_equal(got, want)
    assert_array_equal(np.signbit(got), np.signbit(want))
