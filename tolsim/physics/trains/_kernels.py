"""Numba kernels of the ball trains: cluster pooling, the along-track step, event-driven trains."""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit

#: Trains per parallel work item of the kernels (one workspace allocation per chunk).
CHUNK = 256
#: Events closer than this fraction of the horizon are treated as simultaneous.
TIE_TOLERANCE = 1e-12

#: States of a pair in the kernels: open gap, closed gap (may separate), in contact.
_OPEN, _TOUCHING, _BONDED = 0, 1, 2


# ----------------------------------------------------------------------------- kernels


#: Tiers of a ball in the cluster rule (Notes of ``cluster_velocities``, "Anchors and balls
#: pushed along"): an anchor (K = inf), a ball with a finite creep stiffness, a ball pushed
#: along (K = 0, no epsilon of its own).
ANCHOR, SOFT, PUSHED = 1, 0, -1


@jit
def _effective_stiffness(creep_stiffness, braking_sensitivity, out_weight, out_scale, out_tier):
    """kappa_i, lambda_j of (2) and the tier of each ball of one train (kappa = K, lambda = 1
    exactly when c = 0). An anchor (K = inf) gets weight 1 / lambda within its tier (equal
    anchor stiffnesses, eq. 6a), a pushed ball (K = 0) weight 1; both leave lambda unchanged
    (their c is ignored)."""
    scale = 1.0
    n = creep_stiffness.shape[0]
    for i in range(n):
        k = creep_stiffness[i]
        if k == np.inf:
            out_tier[i] = ANCHOR
            out_weight[i] = 1.0 / scale
        elif k == 0.0:
            out_tier[i] = PUSHED
            out_weight[i] = 1.0
        else:
            out_tier[i] = SOFT
            ck = braking_sensitivity[i] * k
            out_weight[i] = k / ((1.0 + ck) * scale)
            scale = scale * (1.0 + ck) / (1.0 - ck)
        if i < n - 1:
            out_scale[i] = scale


@jit(leaf=True)
def _pav(values, weight, tier, link, tolerance, block_start, block_weight, block_sum,
         block_mean, block_tier, block_soft):
    """Pool adjacent violators of ``values`` on one train; returns the number of blocks.

    ``link[j]``: _OPEN, _TOUCHING (pooled when the lower block's mean exceeds the upper's by
    more than ``tolerance``) or _BONDED (pooled unconditionally). A block's mean is the
    weighted mean over its balls of the highest tier it holds (the limit K_anchor -> inf,
    K_pushed -> 0 of eq. 5); two anchor blocks of equal mean (within ``tolerance``) are
    compared by their next order, the soft balls' imbalance per anchor (eq. 6b).
    ``block_soft`` (n, 2) holds each block's sums of kappa and of kappa * value over its soft
    balls.
    """
    n = values.shape[0]
    top = -1
    for i in range(n):
        top += 1
        block_start[top] = i
        block_weight[top] = weight[i]
        block_sum[top] = weight[i] * values[i]
        block_mean[top] = values[i]
        block_tier[top] = tier[i]
        soft = tier[i] == SOFT
        block_soft[top, 0] = weight[i] if soft else 0.0
        block_soft[top, 1] = weight[i] * values[i] if soft else 0.0
        while top > 0:
            j = block_start[top] - 1
            pool = link[j] == _BONDED
            if link[j] == _TOUCHING:
                lower_mean, upper_mean = block_mean[top - 1], block_mean[top]
                pool = lower_mean - upper_mean > tolerance
                if (not pool and abs(lower_mean - upper_mean) <= tolerance
                        and block_tier[top - 1] == ANCHOR and block_tier[top] == ANCHOR):
                    pool = ((block_soft[top - 1, 1] - lower_mean * block_soft[top - 1, 0])
                            / block_weight[top - 1]
                            > (block_soft[top, 1] - upper_mean * block_soft[top, 0])
                            / block_weight[top])
            if not pool:
                break
            lower, upper = block_tier[top - 1], block_tier[top]
            block_soft[top - 1, 0] += block_soft[top, 0]
            block_soft[top - 1, 1] += block_soft[top, 1]
            if lower == upper:
                same = block_mean[top - 1] == block_mean[top]
                block_weight[top - 1] += block_weight[top]
                block_sum[top - 1] += block_sum[top]
                if upper == ANCHOR and same:  # agreeing anchors keep their speed exactly
                    block_mean[top - 1] = block_mean[top]
                else:
                    block_mean[top - 1] = block_sum[top - 1] / block_weight[top - 1]
            elif upper > lower:
                block_weight[top - 1] = block_weight[top]
                block_sum[top - 1] = block_sum[top]
                block_mean[top - 1] = block_mean[top]
                block_tier[top - 1] = upper
            top -= 1
    return top + 1


@jit(leaf=True)
def _block_terms(first, last, values, weight, tier, mean, block_tier, tolerance, out_r):
    """R_j of eq. (6) inside one block, j = first .. last - 1, into ``out_r[j]``.

    A block of finite stiffnesses: the prefix sums of kappa_i (values_i - mean) over its soft
    balls (pushed balls add nothing). A block held by anchors (eq. 6a of the Notes): the soft
    balls as before and each anchor -I kappa_a / sum kappa_a, I the soft balls' sum; +inf
    throughout when its anchors disagree by more than ``tolerance`` (they cannot roll
    together: the cluster slides).
    A block of pushed balls only: 0.
    """
    r = 0.0
    if block_tier == SOFT:
        for i in range(first, last):
            if tier[i] == SOFT:
                r += weight[i] * (values[i] - mean)
            out_r[i] = r
    elif block_tier == ANCHOR:
        total = 0.0
        anchors = 0.0
        agree = True
        for i in range(first, last + 1):
            if tier[i] == SOFT:
                total += weight[i] * (values[i] - mean)
            elif tier[i] == ANCHOR:
                anchors += weight[i]
                if abs(values[i] - mean) > tolerance:
                    agree = False
        share = -total / anchors
        for i in range(first, last):
            if not agree:
                out_r[i] = np.inf
                continue
            if tier[i] == SOFT:
                r += weight[i] * (values[i] - mean)
            elif tier[i] == ANCHOR:
                r += share * weight[i]
            out_r[i] = r
    else:
        for i in range(first, last):
            out_r[i] = 0.0


@jit(leaf=True)
def _pool(eps, weight, scale, tier, link, out_velocity, out_force, out_label,
          block_start, block_weight, block_sum, block_mean, block_tier, block_soft, terms):
    """Pool adjacent violators on one train; returns the number of blocks.

    ``link[j]``: _OPEN, _TOUCHING (closed, may separate) or _BONDED (pooled
    unconditionally). Writes the velocity w_i, the contact forces Q_j = lambda_j R_j
    (eq. 6, rounding below zero clipped) and the label (trailing ball) of each ball's block.
    """
    n = eps.shape[0]
    top = _pav(eps, weight, tier, link, 0.0, block_start, block_weight, block_sum, block_mean,
               block_tier, block_soft) - 1
    for b in range(top + 1):
        first = block_start[b]
        last = block_start[b + 1] - 1 if b < top else n - 1
        w = block_mean[b]
        _block_terms(first, last, eps, weight, tier, w, block_tier[b], 0.0, terms)
        for i in range(first, last + 1):
            out_velocity[i] = w
            out_label[i] = first
            if i < last:
                q = scale[i] * terms[i]
                out_force[i] = q if q > 0.0 else 0.0
        if last < n - 1:
            out_force[last] = 0.0
    return top + 1


@jit(inline="always")
def _usable(eps, stiffness, braking):
    """A ball the cluster rule can take: epsilon and c finite, K not NaN (inf: an anchor)."""
    return np.isfinite(eps) and not np.isnan(stiffness) and np.isfinite(braking)


@pjit
def cluster_velocities_kernel(eps, creep_stiffness, braking_sensitivity, touching,
                              out_velocity, out_force):
    """Kernel of :func:`cluster_velocities` on (trains, balls) arrays (NaN trains -> NaN)."""
    m, n = eps.shape
    for chunk in prange((m + CHUNK - 1) // CHUNK):
        weight = np.empty(n)
        scale = np.empty(max(n - 1, 1))
        link = np.empty(max(n - 1, 1), dtype=np.int8)
        label = np.empty(n, dtype=np.int64)
        block_start = np.empty(n, dtype=np.int64)
        block_weight = np.empty(n)
        block_sum = np.empty(n)
        block_mean = np.empty(n)
        tier = np.empty(n, dtype=np.int8)
        block_tier = np.empty(n, dtype=np.int8)
        block_soft = np.empty((n, 2))
        terms = np.empty(n)
        for t in range(chunk * CHUNK, min(m, (chunk + 1) * CHUNK)):
            ok = True
            for i in range(n):
                if not _usable(eps[t, i], creep_stiffness[t, i], braking_sensitivity[t, i]):
                    ok = False
            if not ok:
                out_velocity[t, :] = np.nan
                out_force[t, :] = np.nan
                continue
            _effective_stiffness(creep_stiffness[t], braking_sensitivity[t], weight, scale,
                                 tier)
            for j in range(n - 1):
                link[j] = _TOUCHING if touching[t, j] else _OPEN
            _pool(eps[t], weight, scale, tier, link, out_velocity[t], out_force[t], label,
                  block_start, block_weight, block_sum, block_mean, block_tier, block_soft, terms)


# ------------------------------------------------------------- the step rule of along_track


@jit
def _step_weights(stiffness, braking, loaded, usable, work_k, work_c, weight, scale, tier):
    """kappa and lambda of one row: K and c of its loaded balls when ``usable``, the
    placeholders K = 1, c = 0 elsewhere (such balls are never pooled: their links are open)."""
    for i in range(stiffness.shape[0]):
        if usable and loaded[i]:
            work_k[i] = stiffness[i]
            work_c[i] = braking[i]
        else:
            work_k[i] = 1.0
            work_c[i] = 0.0
    _effective_stiffness(work_k, work_c, weight, scale, tier)


@pjit
def step_clusters_kernel(eps, stiffness, braking, loaded, member, closed, active,
                         out_velocity, out_force, out_label, out_ok):
    """Stage 1 of the ``along_track`` step (Notes): the cluster rule on rows of
    ball slots; unchecked.

    ``eps`` (R, S) the balls' free epsilon (NaN allowed), ``stiffness``/``braking`` (R, S)
    K and c (NaN K: a ball that leaves its train unresolved), ``loaded`` (R, S) the balls
    that must be usable, ``member`` (R, S) the balls of the train, ``closed`` (R, S - 1)
    the closed pairs, ``active`` (R,) the rows still followed. A row is ``out_ok`` when it is
    active and its loaded balls have finite epsilon, K and c; then its member pairs that are
    closed are pooled by PAV (eq. 4). Otherwise no pair is: w = eps, Q = 0 (free motion).
    Writes w (R, S), Q (R, S - 1), the block label (R, S) and ``out_ok``.

    Notes
    -----
    **Varying epsilon: the step rule of ``along_track``**

    With ``along_track`` propagation epsilon and K of every ball change as it rolls, and the trains
    are followed with the integrator's steps of dt (:class:`tolsim.study.pipeline.track_friction.
    TrackFriction` drives the two kernels below from :mod:`tolsim.study.pipeline.propagation` and
    :mod:`tolsim.study.pipeline.carriage_track`). A pair is *closed* at the start of a step when the
    previous step ended with it in contact (at t = 0: a zero initial gap). Per step:

    1. *Cluster rule* (:func:`step_clusters_kernel`, the rule of :func:`cluster_velocities`):
       PAV of eq. (4) on the closed pairs, with epsilon_i, K_i and c_i of each ball at the
       step's midpoint, gives the velocities w_i and the forces Q_j^(1). The free end positions
       are y_i = z_i + dt (1 + w_i) v / 2 (the predictor of the midpoint rule uses the same rule
       with the values at the start of the step). Balls of one cluster move together; a closed
       pair that PAV leaves in two blocks separates (its leading ball is faster): this is how a
       cluster splits, and its forces return to zero, when epsilon changes along the track.
    2. *Projection* (:func:`step_project_kernel`): a gap that closes inside the step leaves y
       overlapping. The end positions are the kappa-weighted projection of y onto
       non-overlapping balls,

           minimise  sum_i kappa_i (z'_i - y_i)^2 / 2   subject to  z'_{j+1} - z'_j >= D,      (7)

       the weighted isotonic regression of s_i = y_i - i D, solved by PAV in O(n) (the
       clusters of step 1 pooled unconditionally; a pair whose overlap is below
       ``tolerance``, 1e-12 D, is rounding and left alone). A pair pooled in (7) ends the step
       closed. The multipliers of (7), R_j^(2) = sum_{i<=j in its block} kappa_i (s_i - s'_i)
       [N m], give the step-mean contact force

           Qbar_j = Q_j^(1) + lambda_j R_j^(2) / (dt v / 2).                                  (8)

    *The step is exact for constant epsilon and K*, whatever dt. Over a step the event-driven
    motion of the section above ends with its balls grouped in final clusters. Summing (2) over
    a final cluster, its internal forces cancel and no force acts across the boundary to the
    next final cluster (those balls never touched during the step), so the cluster's
    kappa-weighted centroid moves exactly as the free balls' would: it ends at the centroid of
    the free end positions y^free = z + dt (1 + epsilon) v / 2, with zero gaps inside. Its
    multipliers, the time integrals (v / 2) int R_j(t) dt, are >= 0 inside the clusters and 0
    between them, and the gaps between clusters are >= 0: these are the KKT conditions of (7)
    with y^free, whose solution is unique. Projecting y instead of y^free changes nothing:
    within a chain of closed pairs s is constant, so step 1 only pools adjacent violators of
    (7), and PAV's result does not depend on the order in which adjacent violators are pooled
    (Barlow et al. 1972). Hence the positions at the end of every step are the event-driven
    ones, and by (8) so is the time integral of every contact force over the step (a gap that
    closes at a fraction f of the step contributes (1 - f) of its new force). What a step
    cannot resolve is *when* inside it a force changed: a maximum taken over the step means
    misses an event inside the last step, a minimum one inside the first, and two merges of one
    cluster in one step count as one formation. With epsilon varying along the track the
    midpoint rule adds its own error, O(dt^2) per step between contacts and O(dt) over the
    stroke from the steps in which a contact starts or ends
    (tests/study/test_friction_along_track.py).
    """
    rows, slots = eps.shape
    for chunk in prange((rows + CHUNK - 1) // CHUNK):
        npair = max(slots - 1, 1)
        work_k = np.empty(slots)
        work_c = np.empty(slots)
        weight = np.empty(slots)
        scale = np.empty(npair)
        link = np.empty(npair, dtype=np.int8)
        block_start = np.empty(slots, dtype=np.int64)
        block_weight = np.empty(slots)
        block_sum = np.empty(slots)
        block_mean = np.empty(slots)
        tier = np.empty(slots, dtype=np.int8)
        block_tier = np.empty(slots, dtype=np.int8)
        block_soft = np.empty((slots, 2))
        terms = np.empty(slots)
        for r in range(chunk * CHUNK, min(rows, (chunk + 1) * CHUNK)):
            ok = active[r]
            if ok:
                for i in range(slots):
                    if loaded[r, i] and not _usable(eps[r, i], stiffness[r, i], braking[r, i]):
                        ok = False
            out_ok[r] = ok
            _step_weights(stiffness[r], braking[r], loaded[r], ok, work_k, work_c, weight,
                          scale, tier)
            for j in range(slots - 1):
                pooled = ok and closed[r, j] and member[r, j] and member[r, j + 1]
                link[j] = _TOUCHING if pooled else _OPEN
            _pool(eps[r], weight, scale, tier, link, out_velocity[r], out_force[r],
                  out_label[r], block_start, block_weight, block_sum, block_mean, block_tier,
                  block_soft, terms)


@pjit
def step_project_kernel(start, end, stiffness, braking, loaded, member, ok, label,
                        contact_before, diameter, tolerance, half_step, out_position,
                        out_force, out_closed, out_formed, out_contact):
    """Stage 2 of the ``along_track`` step (:func:`step_clusters_kernel` Notes): the
    kappa-weighted projection of the end positions onto non-overlapping balls; unchecked.

    ``start``/``end`` (R, S) the ball centres at the start of the step and at its end with
    the stage-1 velocities [m], ``stiffness``, ``braking``, ``loaded``, ``member`` as
    :func:`step_clusters_kernel`, ``ok`` (R,) and ``label`` (R, S) its outputs,
    ``contact_before`` (R, S - 1) the pairs in contact in the previous step, ``diameter``
    D [m], ``tolerance`` the overlap [m] below which a pair is left alone (rounding),
    ``half_step`` dt v / 2 [m]. ``out_force`` holds the stage-1 forces Q on entry and the
    step-mean forces on exit [N]. Writes the positions at the end of the step, the pairs in
    contact at its end (``out_closed``), the multi-ball clusters formed in the step (R,) and
    the fraction of the step with a contact force (R,). Rows that are not ``ok`` keep
    ``end``, get no force, no contact.
    """
    rows, slots = end.shape
    for chunk in prange((rows + CHUNK - 1) // CHUNK):
        npair = max(slots - 1, 1)
        work_k = np.empty(slots)
        work_c = np.empty(slots)
        weight = np.empty(slots)
        scale = np.empty(npair)
        link = np.empty(npair, dtype=np.int8)
        s = np.empty(slots)
        block_start = np.empty(slots, dtype=np.int64)
        block_weight = np.empty(slots)
        block_sum = np.empty(slots)
        block_mean = np.empty(slots)
        tier = np.empty(slots, dtype=np.int8)
        block_tier = np.empty(slots, dtype=np.int8)
        block_soft = np.empty((slots, 2))
        terms = np.empty(slots)
        for r in range(chunk * CHUNK, min(rows, (chunk + 1) * CHUNK)):
            for i in range(slots):
                out_position[r, i] = end[r, i]
            out_formed[r] = 0
            out_contact[r] = 0.0
            if not ok[r]:
                for j in range(slots - 1):
                    out_force[r, j] = 0.0
                    out_closed[r, j] = False
                continue
            _step_weights(stiffness[r], braking[r], loaded[r], True, work_k, work_c, weight,
                          scale, tier)
            held = False  # a stage-1 cluster pushes through the step
            for j in range(slots - 1):
                if not (member[r, j] and member[r, j + 1]):
                    link[j] = _OPEN
                elif label[r, j] == label[r, j + 1]:
                    link[j] = _BONDED
                    if out_force[r, j] > 0.0:
                        held = True
                else:
                    link[j] = _TOUCHING
            for i in range(slots):
                s[i] = end[r, i] - i * diameter
            # PAV of s (weights kappa) under s_j <= s_{j+1}: pool a bonded pair always, a
            # constrained one when the overlap exceeds the tolerance
            top = _pav(s, weight, tier, link, tolerance, block_start, block_weight, block_sum,
                       block_mean, block_tier, block_soft) - 1
            first_new = 1.0  # earliest closing in the step, as a fraction of it
            for b in range(top + 1):
                first = block_start[b]
                last = block_start[b + 1] - 1 if b < top else slots - 1
                if last < slots - 1:
                    out_force[r, last] = 0.0
                    out_closed[r, last] = False
                if last == first:
                    continue
                mean = block_mean[b]
                _block_terms(first, last, s, weight, tier, mean, block_tier[b], tolerance,
                             terms)
                formed = False
                for i in range(first, last + 1):
                    out_position[r, i] = mean + i * diameter
                    if i < last:
                        q = scale[i] * terms[i] / half_step
                        out_force[r, i] += q if q > 0.0 else 0.0
                        out_closed[r, i] = True
                        if not contact_before[r, i]:
                            formed = True
                        if label[r, i] != label[r, i + 1]:  # closed in this step
                            g1 = end[r, i + 1] - end[r, i] - diameter
                            if g1 < 0.0:
                                g0 = start[r, i + 1] - start[r, i] - diameter
                                f = g0 / (g0 - g1) if g0 > 0.0 else 0.0
                                if f < first_new:
                                    first_new = f
                if formed:
                    out_formed[r] += 1
            out_contact[r] = 1.0 if held else 1.0 - first_new


@jit
def _first_contact_pairwise(gap, eps, half_speed, horizon):
    """The rule of :func:`tolsim.study.pipeline.propagation.constant_contact_kernel` for one
    train."""
    best = np.inf
    pair = -1
    for j in range(gap.shape[0]):
        rate = (eps[j] - eps[j + 1]) * half_speed
        if rate > 0.0:
            t = gap[j] / rate
            if t < best:
                best = t
                pair = j
    if best <= horizon:
        return best, pair
    return np.inf, -1


@pjit
def train_constant_kernel(
    gap, eps, creep_stiffness, braking_sensitivity, half_speed, horizon, sample_time,
    out_first_time, out_first_pair, out_contact_time, out_contact_fraction, out_force_max,
    out_clusters_formed, out_cluster_count, out_valid,
    out_velocity, out_force, out_displacement, out_label,
    out_grid_displacement, out_grid_force, out_grid_push, out_grid_label,
    out_segment_time, out_segment_force,
):
    """Event-driven trains with constant epsilon (Notes of ``train_contact_constant``).

    Grid outputs have shape (m, samples, .) with samples = ``sample_time.shape[0]`` (0: off);
    segment outputs have shape (m, n) and (m, n, n - 1), or (m, 0) and (m, 0, n - 1) when off.
    """
    m, n = eps.shape
    samples = sample_time.shape[0]
    record_segments = out_segment_time.shape[1] > 0
    tie = TIE_TOLERANCE * horizon
    for chunk in prange((m + CHUNK - 1) // CHUNK):
        npair = max(n - 1, 1)
        weight = np.empty(n)
        scale = np.empty(npair)
        link = np.empty(npair, dtype=np.int8)
        label = np.empty(n, dtype=np.int64)
        block_start = np.empty(n, dtype=np.int64)
        block_weight = np.empty(n)
        block_sum = np.empty(n)
        block_mean = np.empty(n)
        w = np.empty(n)
        q = np.empty(npair)
        u = np.empty(n)
        g = np.empty(npair)
        event_time = np.empty(npair)
        tier = np.empty(n, dtype=np.int8)
        block_tier = np.empty(n, dtype=np.int8)
        block_soft = np.empty((n, 2))
        terms = np.empty(n)
        for t_ in range(chunk * CHUNK, min(m, (chunk + 1) * CHUNK)):
            ok = True
            for i in range(n):
                if not _usable(eps[t_, i], creep_stiffness[t_, i], braking_sensitivity[t_, i]):
                    ok = False
            if not ok:
                ft, fp = _first_contact_pairwise(gap[t_], eps[t_], half_speed, horizon)
                _fill_invalid(t_, ft, fp, out_first_time, out_first_pair, out_contact_time,
                              out_contact_fraction, out_force_max, out_clusters_formed,
                              out_cluster_count, out_valid, out_velocity, out_force,
                              out_displacement, out_label, out_grid_displacement,
                              out_grid_force, out_grid_push, out_grid_label,
                              out_segment_time, out_segment_force)
                continue
            e = eps[t_]
            _effective_stiffness(creep_stiffness[t_], braking_sensitivity[t_], weight, scale,
                                 tier)
            bonded = 0
            for i in range(n):
                u[i] = 0.0
            for j in range(n - 1):
                g[j] = gap[t_, j]
                link[j] = _TOUCHING if g[j] <= 0.0 else _OPEN
                out_contact_time[t_, j] = np.inf
            _pool(e, weight, scale, tier, link, w, q, label,
                  block_start, block_weight, block_sum, block_mean, block_tier, block_soft, terms)
            first_time = np.inf
            first_pair = -1
            formed = 0
            # contacts at t = 0 (initial zero gaps pooled by PAV)
            last_label = -1
            for j in range(n - 1):
                if label[j] == label[j + 1]:
                    link[j] = _BONDED
                    bonded += 1
                    out_contact_time[t_, j] = 0.0
                    if label[j] != last_label:
                        formed += 1
                        last_label = label[j]
            if bonded > 0:
                first_time = 0.0
                for j in range(n - 1):
                    if gap[t_, j] <= 0.0 and e[j] > e[j + 1]:
                        first_pair = j
                        break
                if first_pair < 0:  # rounding only; see train_contact_constant's Notes
                    for j in range(n - 1):
                        if link[j] == _BONDED:
                            first_pair = j
                            break
            t = 0.0
            k = 0
            segment = 0
            contact_duration = 0.0
            force_max = 0.0
            finished = False
            for _iteration in range(2 * n + 2):
                for j in range(n - 1):
                    if q[j] > force_max:
                        force_max = q[j]
                if record_segments and segment < n:
                    out_segment_time[t_, segment] = t
                    for j in range(n - 1):
                        out_segment_force[t_, segment, j] = q[j]
                    segment += 1
                # next event: the earliest closing of an approaching pair of two clusters
                t_next = np.inf
                pair_next = -1
                for j in range(n - 1):
                    event_time[j] = np.inf
                    if label[j] != label[j + 1] and w[j] > w[j + 1]:
                        rate = (w[j] - w[j + 1]) * half_speed
                        te = t + g[j] / rate
                        event_time[j] = te
                        if te < t_next:
                            t_next = te
                            pair_next = j
                last = t_next > horizon
                t_end = horizon if last else t_next
                # grid samples in [t, t_next): the state of this segment
                while k < samples and sample_time[k] < t_next:
                    dtk = sample_time[k] - t
                    for i in range(n):
                        out_grid_displacement[t_, k, i] = u[i] + half_speed * w[i] * dtk
                        out_grid_label[t_, k, i] = label[i]
                        push = 0.0
                        if i > 0:
                            push += q[i - 1]
                        if i < n - 1:
                            push -= q[i]
                        out_grid_push[t_, k, i] = push
                    for j in range(n - 1):
                        out_grid_force[t_, k, j] = q[j]
                    k += 1
                dt = t_end - t
                if bonded > 0:
                    contact_duration += dt
                for i in range(n):
                    u[i] += half_speed * w[i] * dt
                if last:
                    finished = True
                    break
                # advance the gaps of pairs in different clusters; close the event's pairs
                for j in range(n - 1):
                    if link[j] == _BONDED:
                        continue
                    if label[j] != label[j + 1]:
                        g[j] += half_speed * (w[j + 1] - w[j]) * dt
                    if j == pair_next or event_time[j] <= t_next + tie or g[j] <= 0.0:
                        g[j] = 0.0
                        link[j] = _TOUCHING
                    else:
                        link[j] = _OPEN
                t = t_next
                _pool(e, weight, scale, tier, link, w, q, label, block_start, block_weight,
                      block_sum, block_mean, block_tier, block_soft, terms)
                last_label = -1
                for j in range(n - 1):
                    if label[j] == label[j + 1] and link[j] != _BONDED:
                        link[j] = _BONDED
                        bonded += 1
                        out_contact_time[t_, j] = t
                        if label[j] != last_label:
                            formed += 1
                            last_label = label[j]
                if first_pair < 0:
                    first_time = t
                    first_pair = pair_next
            if not finished:  # the event loop did not terminate (not expected; flagged)
                ft, fp = _first_contact_pairwise(gap[t_], e, half_speed, horizon)
                _fill_invalid(t_, ft, fp, out_first_time, out_first_pair, out_contact_time,
                              out_contact_fraction, out_force_max, out_clusters_formed,
                              out_cluster_count, out_valid, out_velocity, out_force,
                              out_displacement, out_label, out_grid_displacement,
                              out_grid_force, out_grid_push, out_grid_label,
                              out_segment_time, out_segment_force)
                continue
            out_valid[t_] = True
            out_first_time[t_] = first_time
            out_first_pair[t_] = first_pair
            out_contact_fraction[t_] = contact_duration / horizon
            out_force_max[t_] = force_max
            out_clusters_formed[t_] = formed
            multi = 0
            for i in range(n):
                out_velocity[t_, i] = w[i]
                out_displacement[t_, i] = u[i]
                out_label[t_, i] = label[i]
                if label[i] == i - 1:
                    multi += 1
            out_cluster_count[t_] = multi
            for j in range(n - 1):
                out_force[t_, j] = q[j]
            if record_segments:
                for s in range(segment, n):
                    out_segment_time[t_, s] = np.inf
                    for j in range(n - 1):
                        out_segment_force[t_, s, j] = np.nan


@jit
def _fill_invalid(t_, first_time, first_pair, out_first_time, out_first_pair,
                  out_contact_time, out_contact_fraction, out_force_max, out_clusters_formed,
                  out_cluster_count, out_valid, out_velocity, out_force, out_displacement,
                  out_label, out_grid_displacement, out_grid_force, out_grid_push,
                  out_grid_label, out_segment_time, out_segment_force):
    """Outputs of a train that could not be followed: NaN, -1, and the pairwise first
    contact of :func:`tolsim.study.pipeline.propagation.first_contact_constant`."""
    out_valid[t_] = False
    out_first_time[t_] = first_time
    out_first_pair[t_] = first_pair
    out_contact_time[t_, :] = np.nan
    out_contact_fraction[t_] = np.nan
    out_force_max[t_] = np.nan
    out_clusters_formed[t_] = -1
    out_cluster_count[t_] = -1
    out_velocity[t_, :] = np.nan
    out_force[t_, :] = np.nan
    out_displacement[t_, :] = np.nan
    out_label[t_, :] = -1
    out_grid_displacement[t_] = np.nan
    out_grid_force[t_] = np.nan
    out_grid_push[t_] = np.nan
    out_grid_label[t_] = -1
    out_segment_time[t_] = np.nan
    out_segment_force[t_] = np.nan
