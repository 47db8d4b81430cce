"""Compiled glue of the carriage's ball circuits (:mod:`tolsim.study.pipeline.carriage_circuit`):
the step's ring inputs, the exits and entries of a step, the contacts seen in a step, the gaps,
the step's circuit figures, and the balls that enter the zone by a step's midpoint or after it
(Notes of :func:`tolsim.study.pipeline.carriage_circuit.first_contact_carriage_circuit`,
"Entry").

Each of the first kernels does in one pass, element by element, what a chain of NumPy calls
did: the same comparisons and the same values (a float ``%`` as ``np.mod``, or
:func:`tolsim.physics.circuit.wrap`, which is ``%``), so the results are bit-identical to
those calls. The entry kernels (``midpoint_entering_kernel``, ``entering_inputs_kernel``,
``late_entry_kernel``, ``late_entries_kernel``) have no NumPy twin; their tests work their
values by hand (``tests/study/test_circuit_entry.py``). The ``pjit`` kernels run their
circuits (or slot rows) on Numba's threads, each writing only its own row, so the results do
not depend on the thread count.
"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics.circuit import wrap


@jit
def entering_fill_kernel(loaded, eps, stiffness, pushed):
    """Give the unloaded balls of circuits (C, N) the values of the zone's entry ball, in place
    (:func:`tolsim.study.pipeline.carriage_circuit.entering_velocity`): the entry ball is the
    first loaded ball in ring order whose upstream neighbour (ring index - 1, cyclic) is
    unloaded; a circuit without one (none or all loaded) is left as it is."""
    circuits, n = loaded.shape
    for c in range(circuits):
        first = -1
        for r in range(n):
            if loaded[c, r] and not loaded[c, r - 1 if r > 0 else n - 1]:
                first = r
                break
        if first < 0:
            continue
        for r in range(n):
            if not loaded[c, r]:
                eps[c, r] = eps[c, first]
                stiffness[c, r] = stiffness[c, first]
                pushed[c, r] = pushed[c, first]


@jit
def assembly_stiffness_kernel(stiffness, tracks, anchor, out):
    """Each circuit's stand-in creep stiffness K [N] for a ball without one: the mean of the
    finite, positive K below ``anchor`` of its assembly's slots (every track), 1.0 where there
    is none. (An anchor's K, ``anchor`` and above, is not a creep stiffness: averaged in, it
    made the stand-in nearly rigid, and a three-point ball beside anchors pressed them with
    thousands of newtons.)

    ``stiffness`` (C, S) per circuit (assembly a holds circuits a T .. a T + T - 1,
    ``tracks`` = T), ``out`` (C,). Summed slot by slot in the assembly's order, so an
    assembly's value does not depend on the other assemblies it is stepped with.
    """
    circuits, slots = stiffness.shape
    for a in range(circuits // tracks):
        total = 0.0
        count = 0
        for c in range(a * tracks, (a + 1) * tracks):
            for j in range(slots):
                k = stiffness[c, j]
                if np.isfinite(k) and k > 0 and k < anchor:
                    total += k
                    count += 1
        value = total / count if count > 0 else 1.0
        for c in range(a * tracks, (a + 1) * tracks):
            out[c] = value


@pjit
def ring_inputs_kernel(slot_ring, eps, stiffness, fallback, pushed, unresolved, loaded,
                       ring_ok, out_eps, out_k, out_pushed):
    """The circuits' step inputs (C, N) in ring order from the slots (C, S) of
    :meth:`tolsim.study.pipeline.carriage_circuit.CircuitFrame.advance`.

    ``slot_ring`` the ring ball in each slot (-1: empty); ``eps``, ``stiffness`` [N] (NaN or
    <= 0: the circuit's ``fallback`` (C,), :func:`assembly_stiffness_kernel`), ``pushed``
    and ``unresolved`` per slot. Writes each slot ball's epsilon, K and pushed flag to
    ``out_eps`` (0 elsewhere), ``out_k`` (``fallback`` elsewhere) and ``out_pushed`` (False
    elsewhere), clears ``ring_ok`` (C, N) of unresolved slot balls, then fills the unloaded
    balls from the entry ball (:func:`entering_fill_kernel`)."""
    circuits, n = out_eps.shape
    slots = slot_ring.shape[1]
    for c in prange(circuits):
        for r in range(n):
            out_eps[c, r] = 0.0
            out_k[c, r] = fallback[c]
            out_pushed[c, r] = False
        for j in range(slots):
            r = slot_ring[c, j]
            if r < 0:
                continue
            out_eps[c, r] = eps[c, j]
            k = stiffness[c, j]
            out_k[c, r] = k if (np.isfinite(k) and k > 0) else fallback[c]
            out_pushed[c, r] = pushed[c, j]
            ring_ok[c, r] = ring_ok[c, r] and not unresolved[c, j]
    entering_fill_kernel(loaded, out_eps, out_k, out_pushed)


@pjit
def circuit_events_kernel(sigma0, sigma1, loaded0, loaded1, length, zone, ring_id,
                          previous_id, slot_ring, t, dt, crossed, v, exit_id, exit_time,
                          entry_id, entry_time):
    """Kernel of :func:`tolsim.study.pipeline.carriage_circuit.circuit_events` on circuits
    (C, N) and their slots (C, S); fills the four outputs (C, S). ``crossed`` (C, N) the
    step's crossing travel of each ball (NaN: interpolate), or (0, 0)."""
    exact = crossed.shape[0] > 0
    circuits, n = sigma0.shape
    slots = previous_id.shape[1]
    for c in prange(circuits):
        for j in range(slots):
            exit_id[c, j] = -1
            entry_id[c, j] = -1
            exit_time[c, j] = np.nan
            entry_time[c, j] = np.nan
        for r in range(n):
            leaving = loaded0[c, r] and not loaded1[c, r]
            entering = loaded1[c, r] and not loaded0[c, r]
            if not (leaving or entering):
                continue
            boundary = zone if leaving else length[c]
            crossing = boundary - wrap(sigma0[c, r], length[c])
            span = sigma1[c, r] - sigma0[c, r]
            frac = crossing / span if span > 0 else 1.0
            when = t + min(max(frac, 0.0), 1.0) * dt
            if exact and np.isfinite(crossed[c, r]):
                when = min(max(crossed[c, r] / v, t), t + dt)
            if leaving:  # the slot it left
                for j in range(slots):
                    if previous_id[c, j] == ring_id[r]:
                        exit_id[c, j] = ring_id[r]
                        exit_time[c, j] = when
                        break
            else:  # the slot it took
                for j in range(slots):
                    if slot_ring[c, j] == r:
                        entry_id[c, j] = ring_id[r]
                        entry_time[c, j] = when
                        break


@pjit
def circuit_gaps_kernel(sigma, diameter, length, circuits, out):
    """Gaps (K, N) of the circuits ``circuits`` (K,) of (C, N) arrays [m], ring order (gap c
    between balls c and c + 1; the last one across L_c), as
    :meth:`tolsim.study.pipeline.carriage_circuit.CircuitFrame.gaps`."""
    n = sigma.shape[1]
    for i in prange(len(circuits)):
        c = circuits[i]
        for r in range(n):
            r1 = r + 1 if r + 1 < n else 0
            ahead = sigma[c, r1] + length[c] if r1 == 0 else sigma[c, r1]
            out[i, r] = ahead - sigma[c, r] - 0.5 * (diameter[c, r] + diameter[c, r1])


@pjit
def step_contacts_kernel(ok, loaded, closed, force, pair, where, travel, v, t_end, codes,
                         entry_time, out_count, out_time, out_pair):
    """The contacts of a circuit step (:meth:`tolsim.study.pipeline.carriage_circuit.
    CircuitContact.moved`) on circuits (C, N) and their events (C, E).

    ``out_count`` (C, codes): the events by where they form; ``out_time`` (C,) [s]: the
    earliest of an inside event of resolved balls (``where`` 0, at ``travel`` / ``v``) and,
    where a closed pair of loaded, resolved balls carries force at the end of the step, the
    time its later ball entered the zone in the step (``entry_time`` (C, N) [s], NaN: it did
    not enter in the step), else the end of the step ``t_end`` (``inf`` for neither; NaN
    propagates as in ``np.min``); ``out_pair`` (C,): the ring pair of the circuit's first
    contact: its inside event at the least travel (the first of equals, a NaN travel first),
    else its first pressed pair, else -1.

    A pair pushed into the zone closed by the column becomes a contact of loaded balls when
    its second ball enters; the step's end is only an upper bound (dt late at most), and a
    pair that was loaded at the start of the step and got its force within it keeps that
    bound (its time is not located).
    """
    circuits, n = ok.shape
    events = pair.shape[1]
    for c in prange(circuits):
        for code in range(codes):
            out_count[c, code] = 0
        t_min = np.inf
        best = -1
        best_travel = np.inf
        for e in range(events):
            code = where[c, e]
            if 0 <= code < codes:
                out_count[c, code] += 1
            p = pair[c, e]
            inside = False
            if code == 0 and p >= 0:
                inside = ok[c, p] and ok[c, p + 1 if p + 1 < n else 0]
            if inside:
                te = travel[c, e] / v
                if np.isnan(te) or te < t_min:
                    if not np.isnan(t_min):
                        t_min = te
                tr = travel[c, e]
                if best < 0 or (not np.isnan(best_travel) and (np.isnan(tr)
                                                                 or tr < best_travel)):
                    best = p
                    best_travel = tr
        first_pressed = -1
        for r in range(n):
            r1 = r + 1 if r + 1 < n else 0
            if (closed[c, r] and loaded[c, r] and loaded[c, r1] and ok[c, r] and ok[c, r1]
                    and force[c, r] > 0.0):
                if first_pressed < 0:
                    first_pressed = r
                te = t_end
                e0, e1 = entry_time[c, r], entry_time[c, r1]
                if np.isfinite(e0) or np.isfinite(e1):
                    te = e0 if not np.isfinite(e1) else (e1 if not np.isfinite(e0)
                                                         else max(e0, e1))
                if not np.isnan(t_min) and te < t_min:
                    t_min = te
        out_time[c] = t_min
        out_pair[c] = best if best >= 0 else first_pressed


@jit
def _np_max(a, b):
    """NumPy's ``maximum`` of two floats (its loop: ``a`` when a >= b or a is NaN)."""
    return a if (a >= b or np.isnan(a)) else b


@jit
def circuit_figures_kernel(rows, tracks, hits, column, travel, where_count, column_max,
                           column_mean):
    """A step's circuit figures of assemblies ``rows`` (k,) from their circuits (k x tracks,
    track by track), as :meth:`tolsim.study.pipeline.carriage_circuit.CircuitContact.moved`
    accumulates them: ``where_count`` (size, codes) += the events by where, ``hits``
    (k x tracks, codes), summed over the tracks; ``column_max`` (size, 2) the larger of
    itself and the largest over the tracks of the end-of-step column forces (``column``
    (k x tracks, 4), columns 0 and 1); ``column_mean`` (size, 2) += the largest over the
    tracks of the step means (columns 2 and 3) times ``travel``. The largest is NumPy's
    ``max`` over the tracks and then ``np.maximum`` (NaN propagates)."""
    codes = hits.shape[1]
    for a in range(len(rows)):
        row = rows[a]
        base = a * tracks
        for code in range(codes):
            total = 0
            for t in range(tracks):
                total += hits[base + t, code]
            where_count[row, code] += total
        for e in range(2):
            end = column[base, e]
            mean = column[base, e + 2]
            for t in range(1, tracks):
                end = _np_max(end, column[base + t, e])
                mean = _np_max(mean, column[base + t, e + 2])
            column_max[row, e] = _np_max(column_max[row, e], end)
            column_mean[row, e] += mean * travel


@pjit
def midpoint_entering_kernel(z, ball_id, slot_ring, count, circuits, sigma, ring_loaded,
                             ring_speed, length, diameter, half_zone, travel, ring_id, out_z,
                             out_id, out_ring, out_entering):
    """The circuits' slots (m_k, T, S) at the step's midpoint with the balls that have entered
    by then (:meth:`tolsim.study.pipeline.carriage_circuit.CircuitFrame.evaluate`).

    ``z``, ``ball_id``, ``slot_ring`` the slots (positions at the midpoint, ids and ring balls
    of the step's start), ``count`` (m_k, T) the loaded balls there, ``circuits``
    (m_k T,) the rows of the circuit arrays ``sigma``, ``ring_loaded``, ``ring_speed``
    (xi, at the end of the previous step), ``diameter`` (C, N) and ``length`` (C,);
    ``travel`` the carriage travel to the midpoint [m]. Copies the slots to ``out_z``,
    ``out_id`` (``out_ring`` -1, ``out_entering`` False), then, upstream of the zone's
    entry ball (the last slot), while the next unloaded ring ball's predicted position
    sigma + xi travel passes L_c, it takes the next free slot at z = L_z / 2 - (sigma +
    xi travel - L_c), or a diameter's sum behind the ball ahead if that is nearer the entry
    (it cannot overlap the ball it pushes), as long as that is in the zone and slots remain.
    """
    m, tracks, slots = z.shape
    n = sigma.shape[1]
    for r in prange(m):
        for tr in range(tracks):
            for j in range(slots):
                out_z[r, tr, j] = z[r, tr, j]
                out_id[r, tr, j] = ball_id[r, tr, j]
                out_ring[r, tr, j] = -1
                out_entering[r, tr, j] = False
            c = count[r, tr]
            if c <= 0 or travel <= 0.0:
                continue
            line = circuits[r * tracks + tr]
            ahead = slot_ring[r, tr, c - 1]
            z_ahead = out_z[r, tr, c - 1]
            while c < slots:
                b = ahead - 1 if ahead > 0 else n - 1
                if ring_loaded[line, b]:
                    break
                x = wrap(sigma[line, b], length[line]) + ring_speed[line, b] * travel
                if x < length[line]:
                    break
                znew = half_zone - (x - length[line])
                bound = z_ahead + 0.5 * (diameter[line, b] + diameter[line, ahead])
                if znew < bound:
                    znew = bound
                if znew > half_zone:
                    break
                out_z[r, tr, c], out_id[r, tr, c] = znew, ring_id[b]
                out_ring[r, tr, c], out_entering[r, tr, c] = b, True
                ahead, z_ahead = b, znew
                c += 1


@jit
def entering_inputs_kernel(take, ring, eps, stiffness, valid, unloaded, fallback, out_eps,
                           out_k, out_pushed, out_own):
    """Give the balls that entered the zone by the step's midpoint (``take`` (C, S), their
    ring balls ``ring``) their own epsilon, creep stiffness K [N] and pushed flag of the
    midpoint's solve in the circuits' step inputs (C, N), in place, and mark them in
    ``out_own`` (C, N); an unresolved one (``valid`` False, or a loaded one without a finite
    epsilon) keeps the entry ball's values (:func:`entering_fill_kernel`), and a K that is
    not finite and positive is the circuit's ``fallback``."""
    circuits, slots = take.shape
    for c in range(circuits):
        for j in range(slots):
            if not take[c, j]:
                continue
            r = ring[c, j]
            if unloaded[c, j]:
                out_pushed[c, r] = True
                out_own[c, r] = True
                continue
            if not (valid[c, j] and np.isfinite(eps[c, j])):
                continue
            out_eps[c, r] = eps[c, j]
            k = stiffness[c, j]
            out_k[c, r] = k if (np.isfinite(k) and k > 0) else fallback[c]
            out_pushed[c, r] = False
            out_own[c, r] = True


@jit
def late_entry_kernel(late_travel, late_eps, loaded, ring_ok, pushed, eps, travel):
    """Make up, in this step, for the travel a ball moved after its entry in the previous
    step with the entry ball's epsilon instead of its own, in place (C, N): a ball with
    ``late_travel`` lambda > 0 [m] of carriage travel at ``late_eps`` epsilon_a, loaded at the
    step's start, resolved (``ring_ok``) and not ``pushed``, moves in this step of
    ``travel`` s at epsilon + (lambda / s) (epsilon - epsilon_a), epsilon its own
    (``eps``): over the two steps it then travels what it would have at its own epsilon from
    its entry (to O(lambda s) in the change of epsilon). ``late_travel`` is cleared."""
    circuits, n = eps.shape
    for c in range(circuits):
        for r in range(n):
            lam = late_travel[c, r]
            if lam <= 0.0:
                continue
            late_travel[c, r] = 0.0
            if loaded[c, r] and ring_ok[c, r] and not pushed[c, r] and travel > 0.0:
                eps[c, r] += lam / travel * (eps[c, r] - late_eps[c, r])


@jit
def late_entries_kernel(entry_time, slot_ring, own, eps, pushed, t_end, v, late_travel,
                        late_eps):
    """Record the balls that entered the zone in the step without values of their own
    (:func:`late_entry_kernel`): for each slot (C, S) with an ``entry_time`` [s] (NaN:
    none) whose ring ball (``slot_ring``, at the step's end) was not given its own values
    (``own`` (C, N), :func:`entering_inputs_kernel`) and is not ``pushed``, the carriage
    travel v (t_end - entry_time) [m] it moved with the entry ball's epsilon ``eps`` (C, N)
    of the step."""
    circuits, slots = entry_time.shape
    for c in range(circuits):
        for j in range(slots):
            t = entry_time[c, j]
            r = slot_ring[c, j]
            if not np.isfinite(t) or r < 0 or own[c, r] or pushed[c, r]:
                continue
            late_travel[c, r] = v * (t_end - t)
            late_eps[c, r] = eps[c, r]


__all__ = ["circuit_events_kernel", "circuit_figures_kernel", "circuit_gaps_kernel",
           "entering_fill_kernel", "entering_inputs_kernel", "late_entries_kernel",
           "late_entry_kernel", "midpoint_entering_kernel", "ring_inputs_kernel",
           "step_contacts_kernel"]
