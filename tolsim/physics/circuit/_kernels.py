"""Numba kernels of the recirculating ball circuit: the cluster rule on a ring, one step."""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit

#: Circuits per parallel work item (one workspace allocation per chunk).
CHUNK = 64
#: Events closer than this fraction of the step's travel are simultaneous.
TIE_TOLERANCE = 1e-12
#: Speeds per unit travel closer than this are equal (a gap changing by less than 1e-12 m per
#: metre of travel does not change): rounding cannot open a resting pair or close it again.
SPEED_TOLERANCE = 1e-12

#: Where a contact happens (the pair's two balls, upstream first, in the direction of flow).
WHERE_INSIDE, WHERE_ENTRY, WHERE_EXIT, WHERE_RETURN = 0, 1, 2, 3
#: Status bits of a circuit's step.
STATUS_EVENT_OVERFLOW, STATUS_JAMMED, STATUS_ITERATIONS = 1, 2, 4


@jit
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


@jit(leaf=True)
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
            if cut < 0:  # closed ring: less the least prestress below
                force[r] = resultant
                if resultant < lowest:
                    lowest = resultant
            elif m < last:
                force[r] = resultant if resultant > 0.0 else 0.0
            else:
                force[r] = 0.0
            r += 1
            if r == n:
                r = 0
    if cut < 0:
        for r in range(n):
            f = force[r] - lowest
            force[r] = f if f > 0.0 else 0.0
    return jammed


@jit
def _gap(position, half_sum, length, n, r):
    """Gap of ring pair r [m] (ring pair n - 1 closes the circuit)."""
    if r < n - 1:
        return position[r + 1] - position[r] - half_sum[r]
    return position[0] + length - position[n - 1] - half_sum[r]


@jit
def wrap(x, length):
    """``x % length`` for ``length`` > 0 (Python's float modulo, as Numba's ``%``), bit for
    bit, without its call to ``fmod`` for x in (-L, 2 L): fmod is x there, or x - L, which
    is exact (Sterbenz), and Python adds L to a negative remainder. Zeros, L, NaN and the
    rest take ``%``."""
    if 0.0 < x < length:
        return x
    if length < x < 2.0 * length:
        return x - length
    if -length < x < 0.0:
        return x + length
    return x % length


@jit(leaf=True)
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


@jit(inline="always")  # (inlined: the call passed two dozen arrays per iteration)
def _solve_ring(q, half_sum, length, loaded_speed, coast, ring_stiffness, ring_loaded,
                ring_push, ring_pushed, ring_closed, drag, n, label, speed, force, block_start,
                block_weight, block_sum, block_unloaded, block_coast, block_coasting,
                block_speed, free_speed, weight):
    """The ring's speeds and forces for its closed pairs (eq. 4 of
    :func:`tolsim.physics.circuit.step`), cut at its widest open pair, with the pushed balls'
    speeds of :func:`_pushed_speeds` (solved again after them); ``ring_stiffness`` and
    ``ring_push`` are each ring ball's K and pushed flag. Returns (cut, jammed)."""
    any_pushed = False
    cut = -1  # the open ring pair with the widest gap (-1: every pair closed)
    widest = -np.inf
    for r in range(n):
        ring_pushed[r] = ring_loaded[r] and ring_push[r]
        if ring_pushed[r]:
            any_pushed = True
            free_speed[r] = coast[r]
            weight[r] = 0.0
        elif ring_loaded[r]:
            free_speed[r] = loaded_speed[r]
            weight[r] = 2.0 * ring_stiffness[r]
        else:
            free_speed[r] = coast[r]
            weight[r] = 0.0
        if not ring_closed[r]:
            g = _gap(q, half_sum, length, n, r)
            if g > widest:
                widest = g
                cut = r
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


@jit(leaf=True)
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


@jit(leaf=True)
def _open_window(c, w, start, window_low, window_high, window_peak, window_start):
    window_low[c, w] = np.inf
    window_high[c, w] = -np.inf
    window_peak[c, w] = 0.0
    window_start[c, w] = start


@jit(leaf=True)
def _track_interval(c, w, forward, ring_loaded, ball, force, slopes, n, window_low,
                    window_high, window_peak, window_force, record):
    """An interval of constant forces into window ``w`` of circuit ``c``: the friction
    increase sum_p k_p Q_p over the pairs with a ball in the loaded zone (k_p = ``slopes``
    [0, c, p] with both balls p, p + 1 mod N of ball-order pair p loaded, [1] with ball p
    alone, [2] with ball p + 1 alone) into its least and largest value, the largest such
    Q_p into its peak. A NaN increase makes the window's extremes NaN (unknown). With
    ``record`` (the window's first interval) every pair's Q_p goes to ``window_force``."""
    increase = 0.0
    peak = 0.0
    for r in range(n):
        r1 = r + 1 if r + 1 < n else 0
        p = ball[r] if forward else ball[r1]
        if record:
            window_force[c, w, p] = force[r]
        lower = ring_loaded[r] if forward else ring_loaded[r1]
        upper = ring_loaded[r1] if forward else ring_loaded[r]
        if not (lower or upper):
            continue
        k = slopes[0, c, p] if lower and upper else (slopes[1, c, p] if lower
                                                     else slopes[2, c, p])
        increase += k * force[r]
        if force[r] > peak:
            peak = force[r]
    if increase != increase:
        window_low[c, w] = np.nan
        window_high[c, w] = np.nan
    else:
        if increase < window_low[c, w]:
            window_low[c, w] = increase
        if increase > window_high[c, w]:
            window_high[c, w] = increase
    if peak > window_peak[c, w]:
        window_peak[c, w] = peak


@jit(leaf=True)
def step_circuit_one(c, position, diameter, eps, stiffness, pushed, loaded, closed, length,
                     zone, drag, travel, travel_start, speed_out, velocity_out, force_out,
                     mean_force_out, column_out, event_pair, event_where, event_travel, q,
                     half_sum, free_speed, weight, speed, force, mean_force, t_pair, t_ball,
                     block_weight, block_sum, coast, loc, block_speed, loaded_speed,
                     block_coasting, block_unloaded, block_coast, ring_stiffness, ball, label,
                     block_start, ring_loaded, ring_closed, ring_pushed, ring_push, slopes,
                     window_low, window_high, window_peak, window_start, window_force,
                     crossing_out):
    """One step of circuit ``c`` (row c of the (M, N) arrays of :func:`step_circuit_kernel`),
    in place (Notes of :func:`tolsim.physics.circuit.step`).

    ``position``, ``diameter``, ``eps``, ``stiffness``, ``pushed`` (in the zone without a
    groove contact: no epsilon or K of its own), ``loaded`` (ball order),
    ``closed`` (ball pair k: balls k, k + 1 mod N) and ``speed_out`` (the balls' circuit
    speeds, read as the coasting speeds of unloaded balls when ``drag`` is 0) are the state,
    updated in place; ``column_out`` row c gets the entry and exit column forces at the end of
    the step and their step means. With ``slopes`` (3, M, N) (else (3, 0, 0)) each interval
    of nonzero length between the step's events goes to ``window_*`` row c, its friction
    increase, its start and its pair forces (:func:`_track_interval`; the last window takes
    those beyond the capacity, its forces then NaN). ``crossing_out`` row c gets the
    carriage travel at which each ball last crossed an end of the zone in the step (NaN:
    none). Returns (events, status, windows). The rest are work arrays (N,)
    in ring order, the direction of flow: rows, never views, are passed (a view costs two
    atomic reference counts, which threads working on one array contend for).
    """
    n = position.shape[1]
    capacity = event_pair.shape[1]
    forward = travel >= 0.0
    total = abs(travel)
    entry = 0.0 if forward else -zone
    span = length[c]
    # gather in the direction of flow: ring r = ball r (forward) or ball N - 1 - r; loc is
    # the travel from the entry (loaded balls in [0, L_z], unloaded ones in [L_z, L_c])
    for r in range(n):
        b = r if forward else n - 1 - r
        r1 = r + 1 if r + 1 < n else 0
        b1 = r1 if forward else n - 1 - r1
        ball[r] = b
        q[r] = position[c, b] if forward else -position[c, b]
        ring_loaded[r] = loaded[c, b]
        coast[r] = speed_out[c, b]
        mean_force[r] = 0.0
        loaded_speed[r] = 0.5 * (1.0 - eps[c, b])
        ring_stiffness[r] = stiffness[c, b]
        ring_push[r] = pushed[c, b]
        x = wrap(q[r] - entry, span)
        if ring_loaded[r]:
            loc[r] = x - span if x > 0.5 * (zone + span) else x
        else:
            loc[r] = x + span if x < 0.5 * zone else x
        half_sum[r] = 0.5 * (diameter[c, b] + diameter[c, b1])
        ring_closed[r] = closed[c, b if forward else b1]
        crossing_out[c, b] = np.nan
    events = 0
    status = 0
    remaining = total
    tie = TIE_TOLERANCE * total
    entry_sum = 0.0  # the column forces times travel
    exit_sum = 0.0
    changed = True  # the state changed since the last solve
    track = slopes.shape[1] > 0
    capacity_w = window_low.shape[1] if track else 0
    w = 0  # the window: one per interval (the last takes any beyond the capacity)
    filled = False
    if track:
        _open_window(c, 0, travel_start, window_low, window_high, window_peak, window_start)
    for _iteration in range(4 * n + 16):
        cut, jammed = _solve_ring(q, half_sum, span, loaded_speed, coast, ring_stiffness,
                                  ring_loaded, ring_push, ring_pushed, ring_closed, drag, n,
                                  label, speed, force, block_start, block_weight, block_sum,
                                  block_unloaded, block_coast, block_coasting, block_speed,
                                  free_speed, weight)
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
                g = _gap(q, half_sum, span, n, r)
                t = (g if g > 0.0 else 0.0) / (speed[r] - speed[r1])
                t_pair[r] = t
                if t < best:
                    best = t
            t_ball[r] = np.inf
            if speed[r] > 0.0:
                d = (zone if ring_loaded[r] else span) - loc[r]
                t = (d if d > 0.0 else 0.0) / speed[r]
                t_ball[r] = t
                if t < best:
                    best = t
        if track and best > 0.0:  # the interval up to the event, at these forces
            fresh = not filled
            if filled and w + 1 < capacity_w:
                w += 1
                fresh = True
                done = total - remaining
                _open_window(c, w, travel_start + (done if forward else -done), window_low,
                             window_high, window_peak, window_start)
            elif filled:  # merged into the last window: its forces are no one interval's
                window_force[c, w, 0] = np.nan
            _track_interval(c, w, forward, ring_loaded, ball, force, slopes, n, window_low,
                            window_high, window_peak, window_force, fresh)
            filled = True
        # advance to the event (or the end of the step); the pairs that close there close
        done = total - remaining
        remaining -= best
        limit = best + tie
        closing = False
        crossing = False
        for r in range(n):
            q[r] += speed[r] * best
            loc[r] += speed[r] * best
            mean_force[r] += force[r] * best
            r1 = r + 1 if r + 1 < n else 0
            if ring_loaded[r] != ring_loaded[r1]:
                if ring_loaded[r1]:
                    entry_sum += force[r] * best
                else:
                    exit_sum += force[r] * best
            if t_pair[r] <= limit:
                closing = True
                ring_closed[r] = True
            if t_ball[r] <= limit:
                crossing = True
        changed = closing or crossing
        if closing:
            for r in range(n):
                if t_pair[r] <= limit:
                    # a pair with a pushed ball carries force once its run has closed: one
                    # event for the run, at its last pair, labelled by the balls at its ends
                    a, r1, record = _run_closed(r, ring_pushed, ring_closed, t_pair, limit, n)
                    if not record:
                        continue
                    last = r1 - 1 if r1 > 0 else n - 1
                    if events < capacity:
                        event_pair[c, events] = ball[last] if forward else ball[r1]
                        if ring_loaded[a] and ring_loaded[r1]:
                            event_where[c, events] = WHERE_INSIDE
                        elif ring_loaded[r1]:
                            event_where[c, events] = WHERE_ENTRY
                        elif ring_loaded[a]:
                            event_where[c, events] = WHERE_EXIT
                        else:
                            event_where[c, events] = WHERE_RETURN
                        event_travel[c, events] = travel_start + (done + best if forward
                                                                  else -(done + best))
                        events += 1
                    else:
                        status |= STATUS_EVENT_OVERFLOW
        if crossing:
            for r in range(n):
                if t_ball[r] <= limit:
                    ring_loaded[r] = not ring_loaded[r]
                    if ring_loaded[r]:
                        loc[r] -= span  # entered: the entry is loc = L_c = 0
                    crossing_out[c, ball[r]] = travel_start + (done + best if forward
                                                               else -(done + best))
        if remaining <= tie:
            break
    else:
        status |= STATUS_ITERATIONS
    # the end-of-step speeds and forces (solved again only if the last advance ended with
    # an event), scattered back in ball order
    if changed:
        cut, jammed = _solve_ring(q, half_sum, span, loaded_speed, coast, ring_stiffness,
                                  ring_loaded, ring_push, ring_pushed, ring_closed, drag, n,
                                  label, speed, force, block_start, block_weight, block_sum,
                                  block_unloaded, block_coast, block_coasting, block_speed,
                                  free_speed, weight)
        if jammed:
            status |= STATUS_JAMMED
    entry_force = 0.0
    exit_force = 0.0
    for r in range(n):
        b = ball[r]
        r1 = r + 1 if r + 1 < n else 0
        pair = b if forward else ball[r1]
        position[c, b] = q[r] if forward else -q[r]
        loaded[c, b] = ring_loaded[r]
        speed_out[c, b] = speed[r]
        velocity_out[c, b] = 1.0 - 2.0 * speed[r] if ring_loaded[r] else np.nan
        force_out[c, pair] = force[r]
        mean_force_out[c, pair] = mean_force[r] / total if total > 0.0 else force[r]
        closed[c, pair] = ring_closed[r]
        if ring_loaded[r] != ring_loaded[r1]:
            if ring_loaded[r1]:
                entry_force = force[r]
            else:
                exit_force = force[r]
    column_out[c, 0] = entry_force
    column_out[c, 1] = exit_force
    column_out[c, 2] = entry_sum / total if total > 0.0 else entry_force
    column_out[c, 3] = exit_sum / total if total > 0.0 else exit_force
    return events, status, w + 1 if track else 0


@pjit
def step_circuit_kernel(position, diameter, eps, stiffness, pushed, loaded, closed, length,
                        zone, drag, travel, travel_start, speed_out, velocity_out, force_out,
                        mean_force_out, column_out, event_count, event_pair, event_where,
                        event_travel, status_out, slopes, window_low, window_high,
                        window_peak, window_start, window_force, window_count,
                        crossing_out):
    """:func:`step_circuit_one` over M circuits (rows), in parallel chunks; unchecked.

    State (M, N) in place; ``pushed`` (M, N) bool; ``length`` (M,); ``column_out`` (M, 4);
    events (M, capacity); ``slopes`` (3, M, N) or (3, 0, 0), the windows (M, W), their pair
    forces (M, W, N) and their count (M,) (written with ``slopes`` only); ``crossing_out``
    (M, N).
    """
    n = position.shape[1]
    for chunk in prange((position.shape[0] + CHUNK - 1) // CHUNK):
        # the work arrays of the chunk (N,) by rows, in the order of step_circuit_one's
        # arguments: float, int and bool
        wf = np.empty((19, n))
        wi = np.empty((3, n), dtype=np.int64)
        wb = np.empty((4, n), dtype=np.bool_)
        _step_chunk(chunk, wf, wi, wb, position, diameter, eps, stiffness, pushed, loaded,
                    closed, length, zone, drag, travel, travel_start, speed_out, velocity_out,
                    force_out, mean_force_out, column_out, event_count, event_pair, event_where,
                    event_travel, status_out, slopes, window_low, window_high, window_peak,
                    window_start, window_force, window_count, crossing_out)


@jit(leaf=True)
def _step_chunk(chunk, wf, wi, wb, position, diameter, eps, stiffness, pushed, loaded,
                closed, length, zone, drag, travel, travel_start, speed_out, velocity_out,
                force_out, mean_force_out, column_out, event_count, event_pair, event_where,
                event_travel, status_out, slopes, window_low, window_high, window_peak,
                window_start, window_force, window_count, crossing_out):
    """The circuits of chunk ``chunk`` of :func:`step_circuit_kernel` (its arguments), with
    the chunk's work arrays ``wf``, ``wi``, ``wb``: a leaf kernel (:func:`tolsim._jit.jit`),
    so that handing some 55 arrays to :func:`step_circuit_one` for each circuit counts no
    references."""
    m = position.shape[0]
    (q, half_sum, free_speed, weight, speed, force, mean_force, t_pair, t_ball,
     block_weight, block_sum, coast, loc, block_speed, loaded_speed, block_coasting,
     block_unloaded, block_coast, ring_stiffness) = (
        wf[0], wf[1], wf[2], wf[3], wf[4], wf[5], wf[6], wf[7], wf[8], wf[9], wf[10],
        wf[11], wf[12], wf[13], wf[14], wf[15], wf[16], wf[17], wf[18])
    ball, label, block_start = wi[0], wi[1], wi[2]
    ring_loaded, ring_closed, ring_pushed, ring_push = wb[0], wb[1], wb[2], wb[3]
    for c in range(chunk * CHUNK, min(m, (chunk + 1) * CHUNK)):
        count, status, windows = step_circuit_one(
            c, position, diameter, eps, stiffness, pushed, loaded, closed, length, zone,
            drag, travel, travel_start, speed_out, velocity_out, force_out,
            mean_force_out, column_out, event_pair, event_where, event_travel, q,
            half_sum, free_speed, weight, speed, force, mean_force, t_pair, t_ball,
            block_weight, block_sum, coast, loc, block_speed, loaded_speed,
            block_coasting, block_unloaded, block_coast, ring_stiffness, ball, label,
            block_start, ring_loaded, ring_closed, ring_pushed, ring_push, slopes,
            window_low, window_high, window_peak, window_start, window_force,
            crossing_out)
        event_count[c] = count
        status_out[c] = status
        if windows:
            window_count[c] = windows
