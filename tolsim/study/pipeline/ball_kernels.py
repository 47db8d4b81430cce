"""Compiled glue of the ball evaluations (:mod:`tolsim.study.pipeline.evaluate`,
:mod:`tolsim.study.pipeline.carriage_track`): contact counts, outcomes, loaded-ball gathers,
loads along the carriage and the ``paired`` model's balls in one pass (with the ``analytic``
velocity model too).

Each kernel does in one pass, element by element, what a chain of NumPy calls did: the same
comparisons and the same values, so the results are bit-identical to those calls.
"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics.geometry import paired_force_pair, rigid_angle_deviations
from tolsim.physics.velocity.analytic import ANALYTIC_TILE, analytic_tile


@jit(inline="always")
def _settle_ball(force, b, limit, out_count, out_clipped):
    """:func:`contact_counts_kernel` of ball ``b``; returns 1 if it is settled, else 0."""
    count = 0
    tension = False
    small = True
    for i in range(4):
        f = force[b, i]
        count += f > 0.0
        tension |= f < 0.0
        small &= f <= limit
    if tension:
        count = -1
    if count > 0 and small:
        out_count[b] = 0
        for i in range(4):
            out_clipped[b, i] = 0.0
        return 1
    out_count[b] = count
    for i in range(4):
        f = force[b, i]
        out_clipped[b, i] = f if (f > 0.0 or f != f) else 0.0  # as np.maximum(f, 0.0)
    return 0


@jit
def contact_counts_kernel(force, limit, out_count, out_clipped):
    """Loaded contacts of n balls with round-off contacts settled, and the forces clipped at 0.

    ``force`` (n, 4) [N]. ``out_count`` (n,) int8: the loaded contacts (F > 0), -1 for a ball
    with a contact in tension (F < 0), 0 for a loaded ball whose forces are all at or below
    ``limit`` [N] (it carries round-off only); ``out_clipped`` (n, 4): max(F, 0) as
    ``np.maximum`` (NaN stays NaN), 0 at a settled ball. Returns the number of settled balls.
    (:func:`tolsim.study.pipeline.evaluate.loaded_contacts` then
    :func:`tolsim.study.pipeline.evaluate.settle_round_off_contacts`.)
    """
    settled = 0
    for b in range(force.shape[0]):
        if _settle_ball(force, b, limit, out_count, out_clipped):  # (``settled +=`` the
            settled += 1  # returned int made the loop five times slower: 17 ns per ball)
    return settled


@jit(inline="always")
def interp_index(x, xp):
    """Where ``np.interp`` reads x in xp (strictly increasing, two or more points): -1 below
    xp[0], len(xp) - 1 at or above xp[-1], else the j with xp[j] <= x < xp[j + 1] (a finite
    x; NumPy's binary search finds the same j)."""
    last = xp.shape[0] - 1
    if x < xp[0]:
        return -1
    if x >= xp[last]:
        return last
    j = 0
    for k in range(1, last):  # a count, not a search: no branches (a few slots)
        j += xp[k] <= x
    return j


@jit(inline="always")
def interp_at(x, j, xp, fp):
    """``np.interp(x, xp, fp)`` of a finite x at j = :func:`interp_index`, bit for bit: fp[0]
    below xp[0], fp[-1] above xp[-1], fp[j] at a point, else the same slope and the same
    fallbacks as NumPy's (``arr_interp``)."""
    last = xp.shape[0] - 1
    if j < 0:
        return fp[0]
    if j >= last or xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    value = slope * (x - xp[j]) + fp[j]
    if np.isnan(value):  # NumPy: "if we get nan in one direction, try the other"
        value = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(value) and fp[j] == fp[j + 1]:
            value = fp[j]
    return value


@jit(inline="always")
def loads_at_one(x, slots, side_slots, normal_slots):
    """(N_x, N_y) [N] at carriage position x [m] as
    :func:`tolsim.study.pipeline.evaluate.loads_at`: the one slot's loads (a single slot),
    else ``np.interp`` between the slots (NaN at a NaN x)."""
    if slots.shape[0] == 1:
        return side_slots[0], normal_slots[0]
    if np.isnan(x):
        return x, x
    j = interp_index(x, slots)
    return interp_at(x, j, slots, side_slots), interp_at(x, j, slots, normal_slots)


@jit
def loads_at_kernel(position, slots, side_slots, normal_slots, out_side, out_normal):
    """(N_x, N_y) [N] at the n carriage ``position`` [m] from the loads ``side_slots``,
    ``normal_slots`` at the ``slots`` (:func:`loads_at_one` per ball)."""
    for b in range(position.shape[0]):
        out_side[b], out_normal[b] = loads_at_one(position[b], slots, side_slots,
                                                  normal_slots)


@jit(inline="always")
def _source_at(values, b):
    """Ball ``b``'s value of a source given per ball (n,) or once (1,)."""
    return values[b] if values.shape[0] > 1 else values[0]


@jit(inline="always")
def _paired_ball(tangential0, tangential1, tangential2, tangential3, bottom_rotation,
                 top_rotation, centre_distance, side_load, normal_load, position, slots,
                 side_slots, normal_slots, sin0, cos0, b, out_dbeta, out_force, out_four_point):
    """The ``paired`` static model of ball ``b`` (:func:`paired_balls_kernel`): writes
    ``out_dbeta[b]``, ``out_force[b]``, ``out_four_point[b]``."""
    d0, d1, d2, d3 = rigid_angle_deviations(
        _source_at(tangential0, b), _source_at(tangential1, b),
        _source_at(tangential2, b), _source_at(tangential3, b),
        _source_at(bottom_rotation, b), _source_at(top_rotation, b), centre_distance)
    out_dbeta[b, 0] = d0
    out_dbeta[b, 1] = d1
    out_dbeta[b, 2] = d2
    out_dbeta[b, 3] = d3
    if position.shape[0] > 0:
        nx, ny = loads_at_one(position[b], slots, side_slots, normal_slots)
    else:
        nx = side_load[b]
        ny = normal_load[b]
    f1, f2 = paired_force_pair(nx, ny, sin0, cos0)
    out_force[b, 0] = f1
    out_force[b, 1] = f2
    out_force[b, 2] = f1
    out_force[b, 3] = f2
    out_four_point[b] = f1 > 0.0 and f2 > 0.0  # the four forces are f1, f2, f1, f2


@pjit
def paired_balls_kernel(tangential0, tangential1, tangential2, tangential3, bottom_rotation,
                        top_rotation, centre_distance, side_load, normal_load, position, slots,
                        side_slots, normal_slots, sin0, cos0, limit, out_dbeta, out_force,
                        out_four_point, out_count, out_clipped):
    """The ``paired`` static model of n balls and their contact counts, in one pass.

    Per ball: the rigid angle deviations
    (:func:`tolsim.physics.geometry.rigid_angle_deviations`) from the tangential arc-centre
    offsets ``tangential0..3`` [m] and the groove rotations [rad] (each (n,), or (1,) for one
    value for all: 0.0 for a source the study does not have), the loads (N_x, N_y)
    [N], the ``side_load``, ``normal_load`` (n,) or, if ``position`` (n,) is not empty,
    :func:`loads_at_one` the carriage position [m]; the paired forces
    (:func:`tolsim.physics.geometry.paired_force_pair`); four-point (all forces > 0) and
    :func:`contact_counts_kernel`'s counts and clipped forces. Writes ``out_dbeta``,
    ``out_force``, ``out_clipped`` (n, 4), ``out_four_point``, ``out_count`` (n,); returns
    the number of settled balls. As ``paired_static`` of
    :mod:`tolsim.study.pipeline.evaluate` on the GrooveErrors fields, then
    :func:`contact_counts_kernel`, bit for bit.
    """
    settled = 0
    for b in prange(out_force.shape[0]):
        _paired_ball(tangential0, tangential1, tangential2, tangential3, bottom_rotation,
                     top_rotation, centre_distance, side_load, normal_load, position, slots,
                     side_slots, normal_slots, sin0, cos0, b, out_dbeta, out_force,
                     out_four_point)
        settled += _settle_ball(out_force, b, limit, out_count, out_clipped)
    return settled


@pjit
def paired_analytic_kernel(tangential0, tangential1, tangential2, tangential3, bottom_rotation,
                           top_rotation, centre_distance, side_load, normal_load, position,
                           slots, side_slots, normal_slots, sin0, cos0, limit, nominal_angle,
                           ball_radius, semi_major_coefficient, elliptic_e, k_f, max_ratio,
                           max_angle, max_eps, out_dbeta, out_force, out_four_point, out_count,
                           out_eps, out_valid):
    """:func:`paired_balls_kernel` and the ``analytic`` velocity model of n balls, in one pass.

    The arguments of :func:`paired_balls_kernel` up to ``limit`` and its outputs but the
    clipped forces, which stay in a tile's scratch; then those of
    :func:`tolsim.physics.velocity.analytic.analytic_kernel` from ``nominal_angle`` to
    ``max_eps``, writing epsilon and its validity into ``out_eps``, ``out_valid`` (n,).
    Per tile of ``ANALYTIC_TILE`` balls: the paired model of each ball, then
    :func:`tolsim.physics.velocity.analytic.analytic_tile` on their clipped forces. The
    numbers of :func:`paired_balls_kernel` then ``analytic_kernel`` on its clipped forces, bit
    for bit. Returns the number of settled balls.
    """
    n = out_force.shape[0]
    settled = 0
    for k in prange((n + ANALYTIC_TILE - 1) // ANALYTIC_TILE):
        at = k * ANALYTIC_TILE
        m = min(ANALYTIC_TILE, n - at)
        clipped = np.empty((ANALYTIC_TILE, 4))
        dbeta_t = np.empty((4, ANALYTIC_TILE))
        clipped_t = np.empty((4, ANALYTIC_TILE))
        force = out_force[at:at + m]
        count = out_count[at:at + m]
        for i in range(m):
            _paired_ball(tangential0, tangential1, tangential2, tangential3, bottom_rotation,
                         top_rotation, centre_distance, side_load, normal_load, position,
                         slots, side_slots, normal_slots, sin0, cos0, at + i, out_dbeta,
                         out_force, out_four_point)
            settled += _settle_ball(force, i, limit, count, clipped)
            for c in range(4):
                dbeta_t[c, i] = out_dbeta[at + i, c]
                clipped_t[c, i] = clipped[i, c]
        analytic_tile(dbeta_t, clipped_t, m, nominal_angle, ball_radius,
                      semi_major_coefficient, elliptic_e, k_f, max_ratio, max_angle, max_eps,
                      out_eps, out_valid, at, True)
    return settled


@pjit
def unresolved_loads_kernel(force, loaded, tolerance, light, out_small, out_light):
    """The loaded balls whose every force is finite and <= tolerance x the largest finite
    force of their assembly's loaded balls (at least 0), and > 0 somewhere: ``out_small``
    (m, k) and their number (:func:`tolsim.study.pipeline.evaluate.settle_unresolved_loads`,
    one pass over force (m, k, 4) instead of NumPy's reductions); ``out_light`` (m,): the
    assembly has a contact of a loaded ball left loaded (above the floor) that carries
    less than ``light`` x the largest force (0: none)."""
    m, k = loaded.shape
    count = 0
    for a in prange(m):
        largest = 0.0
        for b in range(k):
            if loaded[a, b]:
                for c in range(4):
                    f = force[a, b, c]
                    if np.isfinite(f) and f > largest:
                        largest = f
        floor = tolerance * largest
        low = light * largest
        any_light = False
        for b in range(k):
            small = False
            if loaded[a, b]:
                below, positive, lightest = True, False, np.inf
                for c in range(4):
                    f = force[a, b, c]
                    below = below and np.isfinite(f) and f <= floor
                    positive = positive or f > 0.0
                    if f > 0.0 and f < lightest:
                        lightest = f
                small = below and positive
                any_light = any_light or (not small and lightest < low)
            out_small[a, b] = small
            if small:
                count += 1
        out_light[a] = any_light
    return count


@jit
def ball_outcomes_kernel(eps, valid, converged, four_point, count, fast, model_fast,
                         model_unresolved, regime_a, regime_unresolved, regime_unloaded,
                         out_model, out_regime, out_lost, out_redo):
    """The outcome of n balls after the fast velocity model, before the full-model re-solves.

    In place: ``valid`` &= converged & four_point & finite epsilon (if ``fast``), ``eps`` NaN
    where not valid. Writes ``out_model``, ``out_regime`` (unloaded: converged with no loaded
    contact), ``out_lost`` (converged with one loaded contact or one in tension) and the
    indices of the balls to re-solve with the full model (converged, not valid, two or more
    loaded contacts) into ``out_redo``; returns their number. As
    :func:`tolsim.study.pipeline.evaluate.ball_velocities` did with NumPy.
    """
    redo = 0
    for b in range(eps.shape[0]):
        ok = valid[b]
        if fast:
            ok = ok and converged[b] and four_point[b] and np.isfinite(eps[b])
            valid[b] = ok
        c = count[b]
        out_model[b] = model_fast if ok else model_unresolved
        out_regime[b] = regime_a if ok else regime_unresolved
        if converged[b] and c == 0:
            out_regime[b] = regime_unloaded
        if converged[b] and not ok and c >= 2:
            out_redo[redo] = b
            redo += 1
        out_lost[b] = converged[b] and (c == 1 or c < 0)
        if not ok:
            eps[b] = np.nan
    return redo


@jit
def gather_loaded_kernel(loaded, dbeta, force, ball_converged, solved, out_dbeta, out_force,
                         out_converged, out_four_point):
    """The loaded balls of slot arrays, in C order (as ``x[loaded]``).

    ``loaded`` (m, T, S); ``dbeta``, ``force`` (m, T, S, 4); ``ball_converged`` (m, T, S);
    ``solved`` (m,). Writes per loaded ball: dbeta, the force with non-finite values set to 0,
    converged (the ball's and its assembly's) and four-point (every force > 0).
    """
    m, tracks, slots = loaded.shape
    k = 0
    for a in range(m):
        for t in range(tracks):
            for j in range(slots):
                if not loaded[a, t, j]:
                    continue
                _gather_ball(dbeta, force, ball_converged, solved, a, t, j, k, out_dbeta,
                             out_force, out_converged, out_four_point)
                k += 1


@jit(inline="always")
def _gather_ball(dbeta, force, ball_converged, solved, a, t, j, k, out_dbeta, out_force,
                 out_converged, out_four_point):
    """:func:`gather_loaded_kernel` of the ball in slot (a, t, j), the k-th loaded one."""
    four = True
    for i in range(4):
        out_dbeta[k, i] = dbeta[a, t, j, i]
        f = force[a, t, j, i]
        f = f if np.isfinite(f) else 0.0
        out_force[k, i] = f
        four &= f > 0.0
    out_converged[k] = ball_converged[a, t, j] and solved[a]
    out_four_point[k] = four


@jit(inline="always")
def row_starts(loaded):
    """The index of each row's first loaded ball among the loaded balls of ``loaded`` (m, T,
    S) in C order, and their number: (m + 1,)."""
    m, tracks, slots = loaded.shape
    start = np.empty(m + 1, dtype=np.int64)
    start[0] = 0
    for a in range(m):
        c = 0
        for t in range(tracks):
            for j in range(slots):
                c += loaded[a, t, j]
        start[a + 1] = start[a] + c
    return start


@pjit
def gather_analytic_kernel(loaded, dbeta, force, ball_converged, solved, limit, nominal_angle,
                           ball_radius, semi_major_coefficient, elliptic_e, k_f, max_ratio,
                           max_angle, max_eps, out_dbeta, out_force, out_converged,
                           out_four_point, out_count, out_eps, out_valid):
    """:func:`gather_loaded_kernel`, :func:`contact_counts_kernel` and the ``analytic``
    velocity model of the loaded balls of slot arrays, in one pass.

    The arguments and outputs of :func:`gather_loaded_kernel`, then ``limit`` of
    :func:`contact_counts_kernel` and its ``out_count`` (its clipped forces stay in a tile's
    scratch), then those of :func:`tolsim.physics.velocity.analytic.analytic_kernel` from
    ``nominal_angle`` to ``max_eps``, writing epsilon and its validity into ``out_eps``,
    ``out_valid`` (n,). Per tile of rows with at most ``ANALYTIC_TILE`` slots (or one row):
    the gather and the counts of each loaded ball (C order), then
    :func:`tolsim.physics.velocity.analytic.analytic_tile` on their clipped forces (each
    ball's numbers are its own, whatever the tile). The numbers of the three kernels one
    after the other, bit for bit. Returns the number of settled balls.
    """
    m, tracks, slots = loaded.shape
    per_row = tracks * slots
    start = row_starts(loaded)
    rows = max(1, ANALYTIC_TILE // per_row)  # the rows of a tile: at most one tile of balls
    tile = max(ANALYTIC_TILE, per_row)
    settled = 0
    for block in prange((m + rows - 1) // rows):
        first, last = block * rows, min(m, block * rows + rows)
        at = start[first]
        size = start[last] - at
        clipped = np.empty((tile, 4))
        dbeta_t = np.empty((4, tile))
        clipped_t = np.empty((4, tile))
        force_t = out_force[at:at + size]
        count_t = out_count[at:at + size]
        i = 0
        for a in range(first, last):
            for t in range(tracks):
                for j in range(slots):
                    if not loaded[a, t, j]:
                        continue
                    b = at + i
                    _gather_ball(dbeta, force, ball_converged, solved, a, t, j, b, out_dbeta,
                                 out_force, out_converged, out_four_point)
                    settled += _settle_ball(force_t, i, limit, count_t, clipped)
                    for c in range(4):
                        dbeta_t[c, i] = out_dbeta[b, c]
                        clipped_t[c, i] = clipped[i, c]
                    i += 1
        analytic_tile(dbeta_t, clipped_t, size, nominal_angle, ball_radius,
                      semi_major_coefficient, elliptic_e, k_f, max_ratio, max_angle, max_eps,
                      out_eps, out_valid, at)
    return settled


@pjit
def scatter_loaded_balls_kernel(loaded, eps, valid, regime, regime_unloaded, pushes, out_eps,
                                out_ok, out_unloaded):
    """The loaded balls' outcomes in their slots (m, T, S), in C order (as ``out[loaded] =
    values`` of each, in one pass): ``out_eps`` epsilon (NaN where not loaded),
    ``out_unloaded`` regime == ``regime_unloaded`` (False where not loaded) and ``out_ok``
    ``valid``, or unloaded too if ``pushes`` (an unloaded ball is accounted for, pushed
    along; True where not loaded). The rows run on Numba's threads, each from its first
    loaded ball (:func:`row_starts`)."""
    m, tracks, slots = loaded.shape
    start = row_starts(loaded)
    for a in prange(m):
        k = start[a]
        for t in range(tracks):
            for j in range(slots):
                if loaded[a, t, j]:
                    unloaded = regime[k] == regime_unloaded
                    out_eps[a, t, j] = eps[k]
                    out_ok[a, t, j] = valid[k] or (pushes and unloaded)
                    out_unloaded[a, t, j] = unloaded
                    k += 1
                else:
                    out_eps[a, t, j] = np.nan
                    out_ok[a, t, j] = True
                    out_unloaded[a, t, j] = False


@jit(inline="always")
def nan_to_num_one(v):
    """``np.nan_to_num`` of one float64: NaN -> 0, +-inf -> +-the largest double."""
    if np.isnan(v):
        return 0.0
    if v == np.inf:
        return np.finfo(np.float64).max
    if v == -np.inf:
        return -np.finfo(np.float64).max
    return v


@jit
def _nan_to_num_kernel(values, out):
    for i in range(values.size):
        out[i] = nan_to_num_one(values[i])


def nan_to_num(x):
    """``np.nan_to_num(x)`` (NaN -> 0, +-inf -> +-the largest double) of a float64 array, in
    one compiled pass where it is C-contiguous."""
    if not (isinstance(x, np.ndarray) and x.dtype == np.float64 and x.flags.c_contiguous):
        return np.nan_to_num(x)
    out = np.empty_like(x)
    _nan_to_num_kernel(x.reshape(-1), out.reshape(-1))
    return out
