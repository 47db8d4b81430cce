"""Compiled glue of the carriage along the track (:mod:`tolsim.study.pipeline.carriage_track`):
the balls' motion in the carriage frame, the exits and entries of a step, the balls that have
entered by its midpoint and an entering ball's own motion from its entry, the balls and pair
flags carried to new slots by their ids, each assembly's Newton start and the step's first
contacts.

Each kernel does in one pass, element by element, what a chain of NumPy calls did: the same
comparisons and the same values, so the results are bit-identical to those calls. The
``pjit`` kernels run their rows (assemblies) on Numba's threads; each row writes only its own
entries (``rows`` are distinct assemblies), so the results do not depend on the thread count
either. (The kernels over flat arrays, and those that do little per row, stay serial: on two
cores their threads cost more than they saved.)"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.study.pipeline.ball_kernels import nan_to_num_one


@jit
def advance_kernel(z0, z1, ball_id, ball_ok, count, entered, entering_gap, half_zone,
                   diameter, balls, t0, dt, overflow, exit_id, exit_time, entry_id,
                   entry_time):
    """Exits and entries at the end of a step, per assembly and track (in place).

    ``z0``, ``z1`` (m, T, S): positions at the start and end of the step [m], slots in z
    order (``count`` occupied); ``ball_id``, ``ball_ok`` move with their balls. A ball with
    z1 < -half_zone leaves (exit time interpolated); the remaining ones close up; then, while
    the leading ball is at or behind half_zone - diameter - g (g = ``entering_gap`` of the
    next entering ball, ``entered`` so far), a ball enters with id balls + k: at the time the
    leading ball passed that point, at z = half_zone, and moves with the leading ball for the
    rest of the step (at its start if there was room before it: a zone longer than the
    train; the next step moves it at its own epsilon from its entry,
    :func:`entry_shift_kernel`, from ``entry_time`` and the slots' travel ``z0`` - ``z1``).
    ``overflow`` is set where the slots or the drawn entering balls run out, or
    the zone is empty. Events: ``exit_id``/``exit_time`` at the slot the ball left,
    ``entry_id``/``entry_time`` at the slot it took (-1 / NaN elsewhere). The model: Notes of
    :func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`, "Loaded zone,
    exit and entry".
    """
    m, tracks = z1.shape[:2]
    for a in range(m):
        for tr in range(tracks):
            _advance_track(z0, z1, ball_id, ball_ok, count, entered, entering_gap, half_zone,
                           diameter, balls, t0, dt, overflow, exit_id, exit_time, entry_id,
                           entry_time, a, a, tr)


@jit(inline="always")
def _advance_track(z0, z1, ball_id, ball_ok, count, entered, entering_gap, half_zone,
                   diameter, balls, t0, dt, overflow, exit_id, exit_time, entry_id,
                   entry_time, a, r, tr):
    """:func:`advance_kernel` of row ``a``, track ``tr``; ``count``, ``entered`` and
    ``entering_gap`` at row ``r``."""
    slots = z1.shape[2]
    capacity = entering_gap.shape[2]
    for j in range(slots):
        exit_id[a, tr, j] = -1
        exit_time[a, tr, j] = np.nan
        entry_id[a, tr, j] = -1
        entry_time[a, tr, j] = np.nan
    c = count[r, tr]
    keep = 0
    lead0 = np.nan
    for j in range(c):
        if z1[a, tr, j] < -half_zone:
            exit_id[a, tr, j] = ball_id[a, tr, j]
            span = z0[a, tr, j] - z1[a, tr, j]
            frac = (z0[a, tr, j] + half_zone) / span if span > 0.0 else 0.0
            exit_time[a, tr, j] = t0 + min(max(frac, 0.0), 1.0) * dt
            continue
        z0[a, tr, keep] = z0[a, tr, j]
        z1[a, tr, keep] = z1[a, tr, j]
        ball_id[a, tr, keep] = ball_id[a, tr, j]
        ball_ok[a, tr, keep] = ball_ok[a, tr, j]
        keep += 1
    c = keep
    if c == 0:
        overflow[a] = True
    else:
        lead0 = z0[a, tr, c - 1]
        drift = lead0 - z1[a, tr, c - 1]  # the leading ball's travel in the step
        while True:
            k = entered[r, tr]
            if k >= capacity:
                overflow[a] = True
                break
            znew = z1[a, tr, c - 1] + diameter + entering_gap[r, tr, k]
            if znew > half_zone:
                break
            if c >= slots:
                overflow[a] = True
                break
            # it enters at L/2 when there is room, then moves with the ball ahead
            frac = (half_zone - znew) / drift if drift > 0.0 else 1.0
            if frac > 1.0:  # room since before the step: enters at its start
                frac = 1.0
                znew = half_zone - max(drift, 0.0)
            z1[a, tr, c] = znew
            z0[a, tr, c] = znew + drift
            ball_id[a, tr, c] = balls + k
            ball_ok[a, tr, c] = True
            entry_id[a, tr, c] = balls + k
            entry_time[a, tr, c] = t0 + dt - frac * dt
            entered[r, tr] = k + 1
            c += 1
    for j in range(c, slots):
        z0[a, tr, j] = np.nan
        z1[a, tr, j] = np.nan
        ball_id[a, tr, j] = -1
        ball_ok[a, tr, j] = True
    count[r, tr] = c


@pjit
def advance_frame_kernel(rows, z0, z1, ball_id, ball_ok, count, entered, entering_gap,
                         half_zone, diameter, balls, t0, dt, scale, overflow, exit_id,
                         exit_time, entry_id, entry_time, position, frame_id, frame_ok,
                         frame_entry_time, frame_entry_velocity):
    """:func:`advance_kernel` of the rows ``rows`` of a frame, written back to it, in one pass.

    ``z0``, ``z1``, ``ball_id``, ``ball_ok``, ``overflow`` and the events (m_k, ...) as in
    :func:`advance_kernel`; the frame's ``count``, ``entered``, ``entering_gap`` (size, ...)
    indexed by assembly, and updated in place as there. Then per row a, r = ``rows[a]``:
    ``position[r]`` = z1, ``frame_id[r]`` = ball_id, ``frame_ok[r]`` = ball_ok,
    ``frame_entry_time[r]`` = entry_time and ``frame_entry_velocity[r]`` = 1 - (z0 - z1) /
    ``scale`` (the epsilon of the slots' travel, ``scale`` = v dt / 2), as
    :meth:`tolsim.study.pipeline.carriage_track.CarriageFrame.advance` did with NumPy. The
    rows run on Numba's threads: each writes only its own entries (``rows`` are distinct).
    """
    m, tracks, slots = z1.shape
    for a in prange(m):
        r = rows[a]
        for tr in range(tracks):
            _advance_track(z0, z1, ball_id, ball_ok, count, entered, entering_gap, half_zone,
                           diameter, balls, t0, dt, overflow, exit_id, exit_time, entry_id,
                           entry_time, a, r, tr)
            for j in range(slots):
                position[r, tr, j] = z1[a, tr, j]
                frame_id[r, tr, j] = ball_id[a, tr, j]
                frame_ok[r, tr, j] = ball_ok[a, tr, j]
                frame_entry_time[r, tr, j] = entry_time[a, tr, j]
                frame_entry_velocity[r, tr, j] = 1.0 - (z0[a, tr, j] - z1[a, tr, j]) / scale


@jit
def joined_kernel(take, loaded1, loaded2, eps1, eps2, valid1, valid2, unloaded1, unloaded2,
                  out_loaded, out_eps, out_valid, out_unloaded, out_source):
    """A step's start balls (m, T, S) with the balls ``take`` taken from its midpoint
    (:meth:`tolsim.study.pipeline.carriage_track.CarriageFrame.step`): ``out_loaded`` =
    loaded1 | take, epsilon, valid and unloaded those of the midpoint (2) where ``take``, else
    of the start (1); ``out_source`` the index of each loaded ball's BallState in the start's
    loaded balls followed by the midpoint's (both in C order). Returns their number. As
    ``np.where`` of each and the index from ``np.cumsum`` of the loaded masks."""
    m, tracks, slots = take.shape
    n1 = 0
    for a in range(m):
        for t in range(tracks):
            for j in range(slots):
                n1 += loaded1[a, t, j]
    k1 = k2 = n = 0
    for a in range(m):
        for t in range(tracks):
            for j in range(slots):
                k1 += loaded1[a, t, j]
                k2 += loaded2[a, t, j]
                if take[a, t, j]:
                    out_eps[a, t, j] = eps2[a, t, j]
                    out_valid[a, t, j] = valid2[a, t, j]
                    out_unloaded[a, t, j] = unloaded2[a, t, j]
                else:
                    out_eps[a, t, j] = eps1[a, t, j]
                    out_valid[a, t, j] = valid1[a, t, j]
                    out_unloaded[a, t, j] = unloaded1[a, t, j]
                out_loaded[a, t, j] = loaded1[a, t, j] or take[a, t, j]
                if out_loaded[a, t, j]:
                    out_source[n] = k2 - 1 + n1 if take[a, t, j] else k1 - 1
                    n += 1
    return n


@jit
def step_velocity_kernel(loaded2, eps2, eps1, out):
    """``out`` = nan_to_num(eps2) where ``loaded2`` else nan_to_num(eps1) (flat arrays), as
    ``np.where(loaded2, np.nan_to_num(eps2), np.nan_to_num(eps1))``: the balls' epsilon of a
    step, a ball outside the zone at the midpoint keeping its epsilon_1."""
    for i in range(out.shape[0]):
        out[i] = nan_to_num_one(eps2[i]) if loaded2[i] else nan_to_num_one(eps1[i])


@jit
def carry_pairs_kernel(old_id, old_flag, new_id, out_flag):
    """Flags of adjacent slot pairs (rows, S - 1) moved with their balls: the pair of new
    slots j, j + 1 keeps the flag of the old slots of the same two balls when they were
    adjacent there, False otherwise (a ball that entered, an empty slot)."""
    rows, slots = new_id.shape
    for r in range(rows):
        for j in range(slots - 1):
            out_flag[r, j] = False
            a, b = new_id[r, j], new_id[r, j + 1]
            if a < 0 or b < 0:
                continue
            for p in range(slots - 1):
                if old_id[r, p] == a:
                    out_flag[r, j] = old_flag[r, p] and old_id[r, p + 1] == b
                    break


@pjit
def carry_slots_kernel(old_id, old_loaded, old_eps, old_valid, old_unloaded, old_row, new_id,
                       out_loaded, out_eps, out_valid, out_unloaded, out_fresh, out_index):
    """The balls of slot arrays (m, T, S) carried to new slots by their ids: new slot j of
    row r, track t takes the values of the old slot of row ``old_row[r]`` and track t that
    held the same ball (``loaded``, epsilon, ``valid``, ``unloaded``) and ``out_index`` its
    loaded ball's index among the old loaded slots in C order (-1: not loaded); a ball that
    was in no old slot (it entered) or an empty slot is ``out_fresh`` (a ball id >= 0 only)
    and takes not loaded, NaN, valid, not unloaded. (The balls keep their order: each is
    searched for from the old slot of the one before, then from the first.) The new rows run
    on Numba's threads, each writing only its own entries."""
    rows, tracks, slots = new_id.shape
    first = np.empty(old_id.shape[:2], dtype=np.int64)  # each old track's first loaded index
    k = 0
    for a in range(old_id.shape[0]):
        for t in range(tracks):
            first[a, t] = k
            for p in range(slots):
                if old_loaded[a, t, p]:
                    k += 1
    for r in prange(rows):
        a = old_row[r]
        for t in range(tracks):
            p, kk = 0, first[a, t]  # the old slot searched from, its first loaded index
            for j in range(slots):
                ident = new_id[r, t, j]
                out_loaded[r, t, j] = False
                out_eps[r, t, j] = np.nan
                out_valid[r, t, j] = True
                out_unloaded[r, t, j] = False
                out_fresh[r, t, j] = ident >= 0
                out_index[r, t, j] = -1
                if ident < 0:
                    continue
                found = False
                for _ in range(2):  # from where the previous ball was found, then from 0
                    while p < slots and old_id[a, t, p] != ident:
                        kk += old_loaded[a, t, p]
                        p += 1
                    if p < slots:
                        found = True
                        break
                    p, kk = 0, first[a, t]
                if not found:
                    continue
                out_fresh[r, t, j] = False
                out_loaded[r, t, j] = old_loaded[a, t, p]
                out_eps[r, t, j] = old_eps[a, t, p]
                out_valid[r, t, j] = old_valid[a, t, p]
                out_unloaded[r, t, j] = old_unloaded[a, t, p]
                if old_loaded[a, t, p]:
                    out_index[r, t, j] = kk


@jit
def newton_start_kernel(solution, solved_at, start, rows, t, period, out):
    """Where the carriage Newton of assemblies ``rows`` starts at time t [s]
    (:meth:`tolsim.study.pipeline.carriage_track._Evaluation.newton_start`).

    ``solution`` (R, size, 5) and ``solved_at`` (R, size) hold each assembly's R latest
    solutions, the latest in row R - 1 (NaN where there is none). If t is at least a
    quarter of ``period`` (the time in which the balls move one pitch through the carriage)
    after the latest solve, ``out[a]`` is the solution solved nearest to t - ``period``, if
    one lies within an eighth of it; else q1 + w (q1 - q0), w = (t - t1) / (t1 - t0), from
    the two latest solutions where w is finite and > 0 and q0 finite; else ``start[rows[a]]``.
    ``period`` <= 0 (no pitch) leaves the line alone."""
    last = solution.shape[0] - 1
    for a in range(rows.shape[0]):
        r = rows[a]
        t0, t1 = solved_at[last - 1, r], solved_at[last, r]
        best = -1
        if period > 0.0 and t - t1 >= 0.25 * period:
            off = 0.125 * period
            for i in range(last + 1):
                d = abs(solved_at[i, r] - (t - period))
                if d <= off:  # (NaN: no solution there)
                    best, off = i, d
        if best >= 0:
            for j in range(5):
                out[a, j] = solution[best, r, j]
            continue
        w = (t - t1) / (t1 - t0)
        line = np.isfinite(w) and w > 0.0
        for j in range(5):
            line = line and np.isfinite(solution[last - 1, r, j])
        for j in range(5):
            if line:
                q1 = solution[last, r, j]
                out[a, j] = q1 + w * (q1 - solution[last - 1, r, j])
            else:
                out[a, j] = start[r, j]


@jit
def remember_kernel(rows, t, displacement, solved, start, solution, solved_at):
    """Keep the solutions ``displacement`` (m, 5) of assemblies ``rows`` solved at time t
    [s], in place: where ``solved``, the start of the next Newton and the latest of the R
    solutions of ``solution`` (R, size, 5) at ``solved_at`` (R, size), the others moving one
    row back (the oldest dropped); elsewhere all R solutions NaN."""
    last = solution.shape[0] - 1
    for a in range(rows.shape[0]):
        r = rows[a]
        if solved[a]:
            for i in range(last):
                for j in range(5):
                    solution[i, r, j] = solution[i + 1, r, j]
                solved_at[i, r] = solved_at[i + 1, r]
            for j in range(5):
                start[r, j] = displacement[a, j]
                solution[last, r, j] = displacement[a, j]
            solved_at[last, r] = t
        else:
            for i in range(last + 1):
                for j in range(5):
                    solution[i, r, j] = np.nan
                solved_at[i, r] = np.nan


@jit(inline="always")
def _exited_before(z0, z1, a, tr, j, frac, half):
    """How many of the balls in slots 0 .. j - 1 of track ``tr`` of row ``a`` have left the
    zone (their centre behind -``half``) at ``frac`` of the step: the slots hold the balls of
    the step's start in z order, and exits are applied at the step's end, so a pair's slot j
    less these is its place among the balls in the zone at that time (a NaN slot counts not)."""
    count = 0
    for k in range(j):
        if z0[a, tr, k] + frac * (z1[a, tr, k] - z0[a, tr, k]) < -half:
            count += 1
    return count


@pjit
def first_contact_kernel(rows, z0, z1, gap0, gap1, ok, valid1, valid2, half, t, dt, balls,
                         time, pair, valid, searching, closed):
    """The first contacts of a step (:class:`tolsim.study.pipeline.carriage_track.
    CarriageFirstContact`), in place.

    Per row a (assembly ``rows[a]``) still searching (``time`` not finite; ``searching[a]``
    written): ``valid`` &= every ball resolved at both evaluations (``valid1``, ``valid2``
    (m, T, S)); a pair j of track tr (gaps ``gap0`` -> ``gap1`` (m, T, S - 1) [m], both balls
    ``ok``) closes when gap1 <= 0 < gap0 - gap1, at frac = 0 (gap0 <= 0) or gap0 / (gap0 -
    gap1) of the step, if both balls, interpolated from ``z0`` to ``z1``, are in [-half,
    half] then; the earliest, t + frac dt (first track, then trailing pair, on ties), is the
    row's ``time`` and ``pair`` tr (balls - 1) + min(j - e, balls - 2), e the balls behind it
    that have left the zone by then (:func:`_exited_before`). ``closed`` (m, T, S - 1),
    when it has rows: a pair (both balls ``ok``) that closed before the step at that time
    (:func:`entry_shift_kernel`; NaN elsewhere) counts as closing then.
    """
    m, tracks, pairs = gap0.shape
    cap = max(balls - 2, 0)
    for a in prange(m):
        r = rows[a]
        searching[a] = not np.isfinite(time[r])
        if not searching[a]:
            continue
        resolved = True
        for tr in range(tracks):
            for j in range(pairs + 1):
                resolved = resolved and valid1[a, tr, j] and valid2[a, tr, j]
        valid[r] = valid[r] and resolved
        best = np.inf
        where = -1
        for tr in range(tracks):
            for j in range(pairs):
                g0, g1 = gap0[a, tr, j], gap1[a, tr, j]
                if closed.shape[0] and ok[a, tr, j + 1] and ok[a, tr, j] and (
                        closed[a, tr, j] < best):  # (False for NaN)
                    best = closed[a, tr, j]
                    before = _exited_before(z0, z1, a, tr, j, (best - t) / dt, half)
                    where = tr * (balls - 1) + min(j - before, cap)
                if not (g1 <= 0.0 and g0 > g1 and ok[a, tr, j + 1] and ok[a, tr, j]):
                    continue
                frac = 0.0 if g0 <= 0.0 else g0 / (g0 - g1)
                behind = z0[a, tr, j] + frac * (z1[a, tr, j] - z0[a, tr, j])
                ahead = z0[a, tr, j + 1] + frac * (z1[a, tr, j + 1] - z0[a, tr, j + 1])
                if not (behind >= -half and ahead <= half):
                    continue
                tc = t + frac * dt
                if tc < best:
                    best = tc
                    where = tr * (balls - 1) + min(
                        j - _exited_before(z0, z1, a, tr, j, frac, half), cap)
        if np.isfinite(best):
            time[r] = best
            pair[r] = where


@jit
def carriage_motion_kernel(position, w, h, v, out):
    """``out`` = position - h (1 - nan_to_num(w)) / 2 v, as ``position - h * (1.0 -
    np.nan_to_num(w)) * 0.5 * v``: the balls' motion in the carriage frame (flat arrays;
    positions [m], epsilon [-], h [s], v [m/s])."""
    for i in range(position.shape[0]):
        out[i] = position[i] - h * (1.0 - nan_to_num_one(w[i])) * 0.5 * v


@pjit
def entering_by_kernel(z, ball_id, rows, count, entered, entering_gap, half_zone, diameter,
                       balls, out_z, out_id, out_entering):
    """The slots (m_k, T, S) at positions ``z`` with the balls that have entered by then.

    ``z``, ``ball_id``: the slots of assemblies ``rows`` (the frame's ``count``, ``entered``
    and ``entering_gap`` (size, T, capacity) are indexed by assembly); copied to ``out_z``,
    ``out_id``, then, as in :func:`advance_kernel`, while the next entering ball's place
    z_lead + D + g_k is inside the zone (<= ``half_zone``) it takes the next free slot there
    with id ``balls`` + k (``out_entering`` True), as long as slots and drawn balls remain.
    The step's midpoint carriage solve thus holds the balls that entered in its first half.
    """
    m, tracks, slots = z.shape
    capacity = entering_gap.shape[2]
    for r in prange(m):
        a = rows[r]
        for tr in range(tracks):
            for j in range(slots):
                out_z[r, tr, j] = z[r, tr, j]
                out_id[r, tr, j] = ball_id[r, tr, j]
                out_entering[r, tr, j] = False
            c, k = count[a, tr], entered[a, tr]
            while 0 < c < slots and k < capacity:
                znew = out_z[r, tr, c - 1] + diameter + entering_gap[a, tr, k]
                if znew > half_zone:
                    break
                out_z[r, tr, c], out_id[r, tr, c], out_entering[r, tr, c] = znew, balls + k, True
                c += 1
                k += 1


@pjit
def entry_shift_kernel(position, free, take, eps, entry_time, entry_velocity, rows, t,
                       diameter, half_v, out_closed):
    """An entering ball's own motion from its entry, in place (rows m_k, T, S).

    A ball that entered in the previous step at ``entry_time`` moved with the ball ahead of it
    (epsilon ``entry_velocity``, the ball ahead's over that step) until that step's end t; where
    ``take`` (it is loaded at this step's midpoint) it is moved by
    tau (epsilon - epsilon_ahead) v / 2, tau = t - entry_time, at its own ``eps`` of this
    midpoint, in ``position`` (at t) and ``free`` (the end of this step): the position it
    would have had at its own epsilon, to O(tau dt). The frame arrays ``entry_time`` and
    ``entry_velocity`` (size, T, S) are indexed by assembly (``rows``); ``half_v`` = v / 2.
    ``out_closed`` (m_k, T, S - 1): for a pair whose gap that moves to below zero, the time in
    (t - tau, t] at which it closed (linear in between; tau the later entry's); NaN elsewhere.
    """
    m, tracks, slots = position.shape
    for r in prange(m):
        a = rows[r]
        for tr in range(tracks):
            for j in range(slots - 1):
                out_closed[r, tr, j] = np.nan
            for j in range(slots):
                if not take[r, tr, j]:
                    continue
                tau = t - entry_time[a, tr, j]
                shift = tau * (eps[r, tr, j] - entry_velocity[a, tr, j]) * half_v
                position[r, tr, j] += shift
                free[r, tr, j] += shift
                if j == 0:
                    continue
                after = position[r, tr, j] - position[r, tr, j - 1] - diameter
                if after < 0.0:
                    before = after - shift  # the pair's gap without the shifts
                    if take[r, tr, j - 1]:  # the ball ahead entered too (shifted already)
                        ahead = t - entry_time[a, tr, j - 1]
                        before += ahead * (eps[r, tr, j - 1] - entry_velocity[a, tr, j - 1]) * (
                            half_v)
                        tau = min(tau, ahead)
                    frac = -after / (before - after) if before > after else 1.0
                    out_closed[r, tr, j - 1] = t - min(frac, 1.0) * tau


@jit
def initial_balls_kernel(loaded, eps, valid, converged, lost, dbeta, force, model, regime,
                         model_fill, regime_fill, out_eps, out_valid, out_converged, out_lost,
                         out_dbeta, out_force, out_model, out_regime):
    """The BallState arrays of the first n slots (m, T, n) from the loaded balls' (flat, C
    order over ``loaded`` (m, T, S), S >= n): each value where loaded, else epsilon NaN, not
    valid, converged, lost (no contact with the grooves), dbeta NaN, force 0, ``model_fill``,
    ``regime_fill``. As ``np.full`` of each and ``x[loaded] = values``, then ``x[:, :, :n]``
    (:func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`'s t = 0 balls).
    """
    m, tracks, slots = loaded.shape
    n = out_eps.shape[2]
    k = 0
    for a in range(m):
        for t in range(tracks):
            for j in range(slots):
                if j >= n:
                    k += loaded[a, t, j]
                    continue
                if loaded[a, t, j]:
                    out_eps[a, t, j] = eps[k]
                    out_valid[a, t, j] = valid[k]
                    out_converged[a, t, j] = converged[k]
                    out_lost[a, t, j] = lost[k]
                    for c in range(4):
                        out_dbeta[a, t, j, c] = dbeta[k, c]
                        out_force[a, t, j, c] = force[k, c]
                    out_model[a, t, j] = model[k]
                    out_regime[a, t, j] = regime[k]
                    k += 1
                else:
                    out_eps[a, t, j] = np.nan
                    out_valid[a, t, j] = False
                    out_converged[a, t, j] = True
                    out_lost[a, t, j] = True
                    for c in range(4):
                        out_dbeta[a, t, j, c] = np.nan
                        out_force[a, t, j, c] = 0.0
                    out_model[a, t, j] = model_fill
                    out_regime[a, t, j] = regime_fill


@jit
def slot_inputs_kernel(ball_z, ball_id, half_zone, shift, out_loaded, out_z, out_rail):
    """The carriage solve's inputs of slots (flat arrays): ``out_loaded`` occupied (id >= 0)
    and |z| <= ``half_zone`` (False for a NaN z), ``out_z`` z where occupied else 0 and
    ``out_rail`` = out_z + ``shift`` (the rail position, shift = v t), as the NumPy
    expressions of :class:`tolsim.study.pipeline.carriage_track.CarriageFrame`'s
    evaluation."""
    for i in range(ball_z.shape[0]):
        occupied = ball_id[i] >= 0
        z = ball_z[i]
        out_loaded[i] = occupied and abs(z) <= half_zone
        z = z if occupied else 0.0
        out_z[i] = z
        out_rail[i] = z + shift


@jit
def window_points_kernel(rows, z0, z1, count, entered, entering_gap, half_zone, diameter, t,
                         dt, out_point, out_share, out_count):
    """The times at which a step's loaded zones are evaluated for the ripple (its windows).

    The loaded zone of an assembly changes inside a step (t, t + dt) when a ball leaves at
    the trailing end or one enters at the leading end, and the step's solve at its midpoint
    sees only one of its zones (without a ball that enters before it: not yet in the
    slots). Per row a (assembly ``rows[a]``), over its tracks, with the balls moving
    linearly from ``z0`` to ``z1`` (m_k, T, S) [m] (slots in z order, the frame's ``count``
    occupied, ``entered`` and ``entering_gap`` (size, T, capacity) as in
    :func:`advance_kernel`): a ball leaves when it passes -``half_zone``, at frac = (z0 +
    half_zone) / (z0 - z1) of the step (the exit time of :func:`advance_kernel`); the next
    entering ball k enters when the leading ball reaches half_zone - D - g_k (then the one
    after it, D + g_(k+1) further), as :func:`advance_kernel` enters it at the step's end.
    Where the open step holds such events, they cut it into intervals and
    ``out_point[a, :out_count[a]]`` are the midpoints of all of them (sorted; intervals of
    zero length skipped) and ``out_share`` their lengths over dt (summing to 1); else
    ``out_count[a]`` is 0. A row with more intervals than ``out_point`` has columns (more
    than T S + T capacity - 1 events) has its last interval end at the step's end.
    """
    m, tracks, slots = z0.shape
    capacity = entering_gap.shape[2]
    events = np.empty(tracks * (slots + capacity))
    for a in range(m):
        r = rows[a]
        n = 0
        for tr in range(tracks):
            c = count[r, tr]
            for j in range(c):
                s0, s1 = z0[a, tr, j], z1[a, tr, j]
                if s0 >= -half_zone and s1 < -half_zone:  # (False for NaN)
                    frac = (s0 + half_zone) / (s0 - s1)
                    if 0.0 < frac < 1.0 and n < events.shape[0]:
                        events[n] = frac
                        n += 1
            if c == 0:
                continue
            lead0, lead1 = z0[a, tr, c - 1], z1[a, tr, c - 1]
            drift = lead0 - lead1
            offset = 0.0
            for k in range(entered[r, tr], capacity):
                if not drift > 0.0:
                    break
                offset += diameter + entering_gap[r, tr, k]
                frac = (lead0 + offset - half_zone) / drift
                if not frac < 1.0:
                    break
                if frac > 0.0 and n < events.shape[0]:
                    events[n] = frac
                    n += 1
        out_count[a] = _interval_points(events, n, t, dt, out_point, out_share, a)


@jit
def _interval_points(events, n, t, dt, out_point, out_share, a):
    """Row a of :func:`window_points_kernel`'s points and shares from the events' fractions
    ``events[:n]`` of the step (sorted here, in place); returns their number (0 without
    events)."""
    for i in range(1, n):  # insertion sort (a few events)
        x = events[i]
        j = i - 1
        while j >= 0 and events[j] > x:
            events[j + 1] = events[j]
            j -= 1
        events[j + 1] = x
    room = out_point.shape[1]
    k = 0
    lower = 0.0
    for i in range(n + 1 if n > 0 else 0):
        upper = events[i] if i < n and k < room - 1 else 1.0
        if upper > lower:
            out_point[a, k] = t + 0.5 * (lower + upper) * dt
            out_share[a, k] = upper - lower
            k += 1
        lower = upper
        if upper == 1.0:
            break
    return k


@jit
def interval_points_kernel(times, t, dt, out_point, out_share, out_count):
    """:func:`window_points_kernel`'s points and shares for events given as times (m, K)
    [s] (NaN: none; those outside the open step (t, t + dt) are ignored)."""
    m, width = times.shape
    events = np.empty(width)
    for a in range(m):
        n = 0
        for i in range(width):
            frac = (times[a, i] - t) / dt
            if 0.0 < frac < 1.0:  # (False for NaN)
                events[n] = frac
                n += 1
        out_count[a] = _interval_points(events, n, t, dt, out_point, out_share, a)
