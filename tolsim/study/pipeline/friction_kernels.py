"""Numba kernels of the trains' carriage friction in a study (:mod:`.track_friction`)."""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics.trains.regimes import TRAIN_COLUMNS

#: Columns of the per-ball train coefficients (:data:`TRAIN_COLUMNS`).
_K = TRAIN_COLUMNS.index("creep_stiffness")
_C = TRAIN_COLUMNS.index("braking_sensitivity")
_F0 = TRAIN_COLUMNS.index("free_rolling_carriage_force")
_A = TRAIN_COLUMNS.index("carriage_force_per_push")
_B = TRAIN_COLUMNS.index("carriage_force_per_neighbour_force")
_PCAP = TRAIN_COLUMNS.index("traction_capacity")
_BCAP = TRAIN_COLUMNS.index("braking_capacity")
_RF = TRAIN_COLUMNS.index("release_push_forward")
_RB = TRAIN_COLUMNS.index("release_push_backward")


#: Why a train is unresolved from a step on (its ``onset``): a ball slides (beyond a
#: capacity), or none does but a ball on a stick line is pushed past a release push.
ROLLING, SLIDING, RELEASED = 0, 1, 2


@jit(inline="always")
def slides(back, front, coefficients):
    """Whether a ball with neighbour forces ``back``, ``front`` [N] stops rolling on its K:
    ``SLIDING``, ``RELEASED`` or 0 (``ROLLING``).

    A soft ball (finite K) slides when |P| >= P_cap or S >= S_cap, the capacities at zero
    neighbour force (Notes of :func:`tolsim.study.pipeline.track_friction.evaluate_friction`).
    An anchor (K = inf): |P| / P_cap + S / S_cap >= 1, or a force that is not finite (anchors
    that cannot roll together), the line of
    :func:`tolsim.physics.trains.regimes.regime_creep_coefficients`. Else a ball on a stick line
    (regime B, or three-point with a stuck contact) is released, leaves its stick line (its K
    no longer holds), once P = back - front reaches a release push, P >= P_fwd or P <= P_bwd
    (:func:`tolsim.physics.trains.ball_minimum.stick_line_release`; +-inf for every other
    ball, NaN while not computed, which only a push of 0 leaves so,
    :func:`tolsim.physics.trains.regimes.settle_release_pushes`).
    """
    push = back - front
    if coefficients[_K] == np.inf:
        use = (abs(back - front) / coefficients[_PCAP]
               + (back + front) / coefficients[_BCAP])
        if not use < 1.0:
            return SLIDING
    elif abs(back - front) >= coefficients[_PCAP] or back + front >= coefficients[_BCAP]:
        return SLIDING
    if push >= coefficients[_RF] or push <= coefficients[_RB]:
        return RELEASED
    return ROLLING


def stroke_pushed(segment_start, segment_force, valid, horizon):
    """The balls whose push P = back - front is nonzero (not NaN) in some segment that
    :func:`stroke_friction_kernel` checks: (trains, n) bool, for
    :func:`tolsim.physics.trains.regimes.settle_release_pushes` (a push of 0 or NaN crosses
    no release push, so only these can let go)."""
    force = np.asarray(segment_force, dtype=np.float64)
    pad = np.zeros(force.shape[:-1] + (1,))
    neighbours = np.concatenate([pad, force, pad], axis=-1)
    push = neighbours[..., :-1] - neighbours[..., 1:]
    checked = np.logical_and.accumulate(np.asarray(segment_start) <= horizon, axis=1)
    with np.errstate(invalid="ignore"):
        moved = (push != 0.0) & ~np.isnan(push) & checked[..., None]
    return moved.any(axis=1) & np.asarray(valid, dtype=bool)[:, None]


def step_pushed(member, force, ok, alive):
    """As :func:`stroke_pushed` for one step of :func:`step_friction_kernel`: the members
    of the rows ``ok`` and ``alive`` with a nonzero push from the step-mean forces (R, S)."""
    member = np.asarray(member, dtype=bool)
    force = np.asarray(force, dtype=np.float64)
    on = np.where(member[:, :-1] & member[:, 1:], force, 0.0)
    pad = np.zeros((len(member), 1))
    neighbours = np.concatenate([pad, on, pad], axis=1)
    push = neighbours[:, :-1] - neighbours[:, 1:]
    with np.errstate(invalid="ignore"):
        moved = (push != 0.0) & ~np.isnan(push)
    return moved & member & (np.asarray(ok, dtype=bool) & np.asarray(alive, dtype=bool))[:, None]


@pjit
def train_inputs_kernel(eps, load, out_stiffness, out_braking):
    """K and c of the balls for :func:`tolsim.physics.trains.train_contact_constant`: NaN K
    (and c = 0) for a ball that leaves its train unresolved (Notes of
    :func:`tolsim.study.pipeline.track_friction.evaluate_friction`): epsilon, c, F_0, a or b
    not finite, K NaN or < 0, or a finite K with |c K| >= 1. An anchor (K = inf) and a ball
    pushed along (K = 0) keep their K with c = 0."""
    for t in prange(eps.shape[0]):
        for i in range(eps.shape[1]):
            k = load[t, i, _K]
            c = load[t, i, _C]
            fixed = k == np.inf or k == 0.0
            usable = (np.isfinite(eps[t, i])
                      and (fixed or (np.isfinite(k) and k > 0.0 and abs(c * k) < 1.0))
                      and np.isfinite(c)
                      and np.isfinite(load[t, i, _F0]) and np.isfinite(load[t, i, _A])
                      and np.isfinite(load[t, i, _B]))
            out_stiffness[t, i] = k if usable else np.nan
            out_braking[t, i] = (0.0 if fixed else c) if usable else 0.0


@pjit
def stroke_friction_kernel(segment_start, segment_force, valid, load, braking, horizon,
                           out_baseline, out_mean, out_max, out_min, out_onset,
                           out_max_rolling):
    """Carriage friction of trains over the stroke from their segments; unchecked.

    ``segment_start`` (trains, S) [s] padded with inf, ``segment_force`` (trains, S, n - 1)
    [N], ``valid`` (trains,), ``load`` (trains, n, len(TRAIN_COLUMNS)), ``braking`` (trains,
    n - 1) the pairs' ball-ball term B_j (:func:`tolsim.physics.trains.regimes.pair_braking`,
    k_j = (a_{j+1} - a_j) + B_j). Writes per train the
    baseline sum_i F_0,i [N], the time mean, maximum and minimum over [0, horizon] of the
    increase (1) [N] (NaN for an invalid train), whether a ball stops rolling on its K in some
    segment (``out_onset``: :func:`slides` of the first such segment, ``SLIDING`` when some
    ball of it slides, else ``RELEASED``; the capacities at zero neighbour force, Notes of
    :func:`evaluate_friction`) and the largest increase before that segment (-inf if it is
    the first).
    """
    trains, segments = segment_start.shape
    n = load.shape[1]
    for t in prange(trains):
        base = 0.0
        for i in range(n):
            base += load[t, i, _F0]
        out_baseline[t] = base
        if not valid[t]:
            out_mean[t] = np.nan
            out_max[t] = np.nan
            out_min[t] = np.nan
            out_onset[t] = ROLLING
            out_max_rolling[t] = np.nan
            continue
        total = 0.0
        high = -np.inf
        low = np.inf
        slid = False
        onset = ROLLING
        rolling = -np.inf
        for s in range(segments):
            start = segment_start[t, s]
            if not start <= horizon:  # padding
                break
            end = horizon
            if s + 1 < segments and segment_start[t, s + 1] < horizon:
                end = segment_start[t, s + 1]
            increase = 0.0
            for j in range(n - 1):
                k = (load[t, j + 1, _A] - load[t, j, _A]) + braking[t, j]
                increase += k * segment_force[t, s, j]
            if not slid:
                for i in range(n):
                    back = segment_force[t, s, i - 1] if i > 0 else 0.0
                    front = segment_force[t, s, i] if i < n - 1 else 0.0
                    code = slides(back, front, load[t, i])
                    if code != ROLLING:
                        slid = True
                        if onset != SLIDING:
                            onset = code
                if not slid and increase > rolling:
                    rolling = increase
            total += increase * (end - start)
            if increase > high:
                high = increase
            if increase < low:
                low = increase
        out_mean[t] = total / horizon
        out_max[t] = high
        out_min[t] = low
        out_onset[t] = onset
        out_max_rolling[t] = rolling


@pjit
def step_friction_kernel(loaded, member, load, braking, force, ok, contact, formed, weight, alive,
                         onset, baseline_sum, increase_sum, increase_high, friction_high,
                         friction_low, force_high, contact_sum, formed_sum, rolling,
                         out_baseline, out_increase):
    """One step of the carriage friction of trains (``along_track``); unchecked.

    ``loaded`` (R, S) the balls that carry load (their F_0 is the baseline), ``member``
    (R, S) the balls of the train, ``load`` (R, S, len(TRAIN_COLUMNS)) their creep
    coefficients, ``braking`` (R, S - 1) the pairs' B_j, ``force`` (R, S - 1) the step-mean
    contact forces [N], ``ok`` (R,) the row
    was followed in this step, ``contact`` (R,) the fraction of the step with a force,
    ``formed`` (R,) the clusters formed in it, ``weight`` dt / T. Updates, for the rows still
    ``alive``: the running time means (baseline, increase, contact fraction), maxima and
    minima, the clusters, and the largest increase before an onset (``rolling``); a row that
    is not ``ok``, whose baseline or increase is not finite (a coefficient not usable:
    never silently left out of the figures), or in which a ball slides (capacities at zero
    neighbour force, as
    :func:`stroke_friction_kernel`) is no longer alive from this step on (``onset`` set
    for the latter, as :func:`stroke_friction_kernel`'s). Writes the step's baseline and
    increase [N] (NaN when not alive).
    """
    rows, slots = loaded.shape
    for r in prange(rows):
        out_baseline[r] = np.nan
        out_increase[r] = np.nan
        if not alive[r]:
            continue
        if not ok[r]:
            alive[r] = False
            continue
        base = 0.0
        for i in range(slots):
            if loaded[r, i]:
                base += load[r, i, _F0]
        increase = 0.0
        high = 0.0
        for j in range(slots - 1):
            if member[r, j] and member[r, j + 1]:
                k = (load[r, j + 1, _A] - load[r, j, _A]) + braking[r, j]
                increase += k * force[r, j]
                if force[r, j] > high:
                    high = force[r, j]
        if not (np.isfinite(base) and np.isfinite(increase)):  # a coefficient not usable
            alive[r] = False
            continue
        cause = ROLLING
        for i in range(slots):
            if not member[r, i]:
                continue
            back = force[r, i - 1] if i > 0 and member[r, i - 1] else 0.0
            front = force[r, i] if i < slots - 1 and member[r, i + 1] else 0.0
            code = slides(back, front, load[r, i])
            if code != ROLLING and cause != SLIDING:
                cause = code
        if cause != ROLLING:
            alive[r] = False
            onset[r] = cause
            continue
        out_baseline[r] = base
        out_increase[r] = increase
        if increase > rolling[r]:
            rolling[r] = increase
        baseline_sum[r] += base * weight
        increase_sum[r] += increase * weight
        if increase > increase_high[r]:
            increase_high[r] = increase
        total = base + increase
        if total > friction_high[r]:
            friction_high[r] = total
        if total < friction_low[r]:
            friction_low[r] = total
        if high > force_high[r]:
            force_high[r] = high
        contact_sum[r] += contact[r] * weight
        formed_sum[r] += formed[r]
