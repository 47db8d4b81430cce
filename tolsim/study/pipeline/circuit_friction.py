r"""The friction of the trains after contact in a ball circuit (issue 24, with ``[contact]``).

The circuit's step (:func:`tolsim.physics.circuit.step`) already moves the loaded balls of a
track as trains: the cluster rule on the ring, with the column of unloaded balls at the ends
of the loaded zone. :class:`CircuitTrains` turns each step's forces into the carriage friction
figures of the open carriage's trains, accumulated by the same
:class:`tolsim.study.pipeline.track_friction.TrackFriction`; the theory is in its Notes.
"""

import numpy as np

from tolsim._jit import jit
from tolsim.physics.circuit import WHERE_INSIDE
from tolsim.physics.trains.ball_minimum import RELEASE_INPUTS
from tolsim.physics.trains.regimes import (
    PUSHED_STIFFNESS,
    TRAIN_COLUMNS,
    pair_braking,
    settle_release_pushes,
)
from tolsim.physics.velocity.models import (
    BALL_REGIME_B,
    BALL_THREE_POINT,
    BALL_TWO_POINT,
    BALL_UNLOADED,
)
from tolsim.study.pipeline.carriage_track_kernels import interval_points_kernel
from tolsim.study.pipeline.friction_kernels import ROLLING, SLIDING, slides
from tolsim.study.pipeline.propagation import StepObserver

_COL = {name: k for k, name in enumerate(TRAIN_COLUMNS)}
#: The columns that must be finite for a ball's share of the friction (F_0, a, b), and K
#: (finite, 0 or inf; NaN: no usable creep model).
_USED = np.array([_COL[name] for name in ("free_rolling_carriage_force",
                                           "carriage_force_per_push",
                                           "carriage_force_per_neighbour_force")])
_K = _COL["creep_stiffness"]
_A = _COL["carriage_force_per_push"]
#: The regimes whose pairs brake along the pair's rotation (pair_braking's "other").
_NOT_A = (BALL_REGIME_B, BALL_TWO_POINT, BALL_THREE_POINT)


def column_coefficients() -> np.ndarray:
    """The train columns (:data:`tolsim.physics.trains.regimes.TRAIN_COLUMNS`) of the column of
    unloaded balls beyond an end of the loaded zone, as one ball of the track's train (Notes
    of :class:`CircuitTrains`): no raceway (F_0 = 0, no creep: K = 0, so no ball-ball braking
    at its pair), carriage force per push a = -1 (the carriage walls hold all of it), b = 0,
    nothing to slide on (capacities inf)."""
    row = np.zeros(len(TRAIN_COLUMNS))
    row[_COL["creep_stiffness"]] = PUSHED_STIFFNESS
    row[_COL["carriage_force_per_push"]] = -1.0
    row[_COL["traction_capacity"]] = np.inf
    row[_COL["braking_capacity"]] = np.inf
    row[_COL["release_push_forward"]] = np.inf
    row[_COL["release_push_backward"]] = -np.inf
    row[[_COL[name] for name in RELEASE_INPUTS]] = np.nan  # no release pending
    row[_COL["free_rolling_velocity_deviation"]] = np.nan
    row[_COL["regime"]] = BALL_UNLOADED
    return row


@jit
def nearest_coefficients_kernel(ring_load, f0, out):
    """``ring_load`` (C, N, columns) with each ball whose F_0 (column ``f0``) is NaN given
    the coefficients of the nearest ball around the ring that has them (the one ahead in
    ball order on a tie; all NaN when none has), into ``out``: a ball that entered the
    zone after the step's midpoint takes the entry ball's ahead of it (as
    :func:`circuit_trains_kernel` does), one that left before it the trailing ball's behind
    it."""
    circuits, n, columns = ring_load.shape
    for c in range(circuits):
        for b in range(n):
            source = -1
            for d in range(n // 2 + 1):
                ahead = b + d if b + d < n else b + d - n
                behind = b - d if b - d >= 0 else b - d + n
                if np.isfinite(ring_load[c, ahead, f0]):
                    source = ahead
                    break
                if np.isfinite(ring_load[c, behind, f0]):
                    source = behind
                    break
            for k in range(columns):
                out[c, b, k] = ring_load[c, source, k] if source >= 0 else np.nan


def nearest_coefficients(ring_load):
    """:func:`nearest_coefficients_kernel` of ``ring_load`` (C, N, columns), a new array."""
    load = np.empty_like(ring_load)
    nearest_coefficients_kernel(np.ascontiguousarray(ring_load), _USED[0], load)
    return load


@jit
def _in_zone(c, w, b, start, crossing, loaded_start, sign, tie):
    """Ball b of circuit c in the loaded zone in window w: as at the step's start unless it
    crossed an end by the window's start (``sign`` the direction of travel)."""
    inside = loaded_start[c, b]
    if np.isfinite(crossing[c, b]) and (crossing[c, b] - start[c, w]) * sign <= tie:
        inside = not inside
    return inside


@jit
def interval_pushed_kernel(force, count, start, crossing, loaded_start, sign, tie, alive,
                           out):
    """The balls (C, N) pushed (back - front != 0) in some window of the circuit step's
    (:class:`tolsim.physics.circuit.FrictionWindows`) while in the zone: those whose
    release pushes :func:`interval_slides_kernel` needs."""
    circuits, width, n = force.shape
    for c in range(circuits):
        for b in range(n):
            out[c, b] = False
        if not alive[c]:
            continue
        for w in range(count[c]):
            for b in range(n):
                if _in_zone(c, w, b, start, crossing, loaded_start, sign, tie):
                    push = force[c, w, b] - force[c, w, b - 1 if b > 0 else n - 1]
                    if push != 0.0 and push == push:
                        out[c, b] = True


@jit
def interval_slides_kernel(force, count, start, crossing, loaded_start, sign, tie, load,
                           alive, out_code):
    """Whether a zone ball of each circuit (C,) stops rolling in some window of the step
    (:func:`tolsim.study.pipeline.friction_kernels.slides` at that window's forces: back
    Q_b, front Q_{b-1}, as the rows of :func:`circuit_trains_kernel` have them):
    ``SLIDING`` (first), ``RELEASED``, ``ROLLING``, or -1 where a window's forces are not
    known (intervals merged beyond its capacity). ``load`` (C, N, columns) the balls'
    coefficients (:func:`nearest_coefficients`), release pushes settled."""
    circuits, width, n = force.shape
    for c in range(circuits):
        out_code[c] = ROLLING
        if not alive[c]:
            continue
        for w in range(count[c]):
            if force[c, w, 0] != force[c, w, 0]:
                out_code[c] = -1
                break
            for b in range(n):
                if not _in_zone(c, w, b, start, crossing, loaded_start, sign, tie):
                    continue
                code = slides(force[c, w, b], force[c, w, b - 1 if b > 0 else n - 1],
                              load[c, b])
                if code != ROLLING and out_code[c] != SLIDING:
                    out_code[c] = code
            if out_code[c] == SLIDING:
                break


def pair_slopes(load, column_row, ball_friction):
    """The carriage friction per newton of each ball-order pair p (balls p and p + 1 mod N
    of a circuit), (3, C, N) [-], for the friction windows of
    :func:`tolsim.physics.circuit.step` (``pair_slopes``): with both balls in the loaded
    zone, with ball p alone (the pair at the zone's exit, ball p + 1 in the column) and
    with ball p + 1 alone (at the entry). Each is k_j = (a_{j+1} - a_j) + B_j of
    :func:`tolsim.study.pipeline.friction_kernels.step_friction_kernel` on the pair as two
    slots of a row of :func:`circuit_trains_kernel` (slot j ball p + 1, slot j + 1 ball p,
    the column's coefficients for a ball out of the zone). ``load`` (C, N, columns) the
    balls' coefficients, a ball without its own given its nearest ball's
    (:func:`nearest_coefficients`), ``column_row`` :func:`column_coefficients`."""
    ahead = np.roll(load, -1, axis=1)  # ball p + 1
    column = np.broadcast_to(column_row, load.shape)
    out = np.empty((3,) + load.shape[:2])
    for k, (upper, lower) in enumerate(((ahead, load), (column, load), (ahead, column))):
        braking = pair_braking(np.stack([upper, lower], axis=2), ball_friction)[..., 0]
        out[k] = lower[..., _A] - upper[..., _A] + braking
    return out


def window_extremes(windows):
    """The least and largest friction increase and the largest pair force over all the
    windows of each circuit's step (:class:`tolsim.physics.circuit.FrictionWindows`), (C,)
    each [N]: inf, -inf where no interval had nonzero length, NaN where one is unknown."""
    valid = np.arange(windows.low.shape[1]) < windows.count[:, None]
    low = np.where(valid, windows.low, np.inf).min(axis=1)
    high = np.where(valid, windows.high, -np.inf).max(axis=1)
    peak = np.where(valid, windows.peak, 0.0).max(axis=1)
    return low, high, peak


@jit
def circuit_trains_kernel(loaded, ring_load, ring_ok, mean_force, pressed_end, pressed_start,
                          column, column_row, used, out_loaded, out_member, out_load,
                          out_force, out_ok, out_start, out_formed, out_ring):
    """The trains of circuits (C, N) as the rows (C, W) of
    :meth:`tolsim.study.pipeline.track_friction.TrackFriction.account` (W = slots + 2; Notes
    of :class:`CircuitTrains`): slot 0 the column at the exit, slots 1..m the zone's balls
    from the trailing end, slot m + 1 the column at the entry. Writes the rows' balls, their
    coefficients, the step-mean pair forces, whether the row can be followed (``out_ok``),
    whether a pair of the zone was pressed at the start of the step (``out_start``) and the
    clusters formed (``out_formed``: runs of pressed pairs of the zone at the end of the step
    that hold a pair not pressed at its start), and the ring ball in each row slot
    (``out_ring``, -1 for the columns and past them). ``used``: the columns F_0, a, b, then
    K."""
    circuits, n = loaded.shape
    width = out_loaded.shape[1]
    columns = ring_load.shape[2]
    for c in range(circuits):
        for j in range(width):
            out_loaded[c, j] = False
            out_member[c, j] = False
            out_ring[c, j] = -1
            for k in range(columns):
                out_load[c, j, k] = np.nan
            if j < width - 1:
                out_force[c, j] = 0.0
        out_ok[c] = True
        out_start[c] = False
        out_formed[c] = 0.0
        entry = -1  # the zone's first ball in the direction of flow
        count = 0
        for r in range(n):
            if loaded[c, r]:
                count += 1
                if not loaded[c, r - 1 if r > 0 else n - 1]:
                    entry = r
        if entry < 0 or count + 2 > width:
            out_ok[c] = count == 0 or count == n
            continue
        for j in range(count + 2):
            out_member[c, j] = True
        for k in range(columns):
            out_load[c, 0, k] = column_row[k]
            out_load[c, count + 1, k] = column_row[k]
        out_force[c, 0] = column[c, 3]
        out_force[c, count] = column[c, 2]
        run_new = False
        in_run = False
        for j in range(1, count + 1):
            r = (entry + count - j) % n  # slot j: the ball j - 1 from the trailing end
            out_ring[c, j] = r
            out_loaded[c, j] = True
            finite = True
            for k in range(columns):
                out_load[c, j, k] = ring_load[c, r, k]
            if not np.isfinite(ring_load[c, r, used[0]]) and j > 1 and ring_ok[c, r]:
                # entered after the step's midpoint: the coefficients of the ball ahead of
                # it in the flow (the zone's entry ball before it), as its epsilon and K
                for k in range(columns):
                    out_load[c, j, k] = out_load[c, j - 1, k]
            for k in range(3):
                if not np.isfinite(out_load[c, j, used[k]]):
                    finite = False
            if np.isnan(out_load[c, j, used[3]]):
                finite = False
            if not (finite and ring_ok[c, r]):
                out_ok[c] = False
            if j < count:  # the pair with the next ball towards the entry: ring pair r - 1
                p = r - 1 if r > 0 else n - 1
                out_force[c, j] = mean_force[c, p]
                if pressed_start[c, p]:
                    out_start[c] = True
                if pressed_end[c, p]:
                    if not in_run:
                        in_run = True
                        run_new = False
                    if not pressed_start[c, p]:
                        run_new = True
                elif in_run:
                    in_run = False
                    if run_new:
                        out_formed[c] += 1.0
        if in_run and run_new:
            out_formed[c] += 1.0


class CircuitTrains(StepObserver):
    """The friction figures of the trains after contact in circuits (``[contact]`` with
    ``[carriage.circuit]``), accumulated in a
    :class:`tolsim.study.pipeline.track_friction.TrackFriction` from the circuit's steps
    (:class:`tolsim.study.pipeline.carriage_circuit.CircuitFrame`); it follows every assembly
    over the whole stroke.

    Notes
    -----
    **The trains.** In a circuit the loaded balls of a track already move as trains: the
    circuit's step is the cluster rule of :mod:`tolsim.physics.trains` (K-weighted, on the
    closed pairs) extended to the ring, with the column of unloaded balls pushing against its
    drag at the zone's ends (:func:`tolsim.physics.circuit.step`, eq. 4-7). So the positions,
    and with them the first contact and P(contact), are those of the study without
    ``[contact]``, bit for bit. What ``[contact]`` adds is the carriage friction of each step,
    from the step-mean pair forces Qbar of the circuit and each ball's creep coefficients
    (:func:`tolsim.study.pipeline.track_friction.ball_creep_coefficients`, from its state at
    the step's midpoint; by regime, a pushed ball F_0 = a = b = 0), through
    :meth:`tolsim.study.pipeline.track_friction.TrackFriction.account`, the open carriage's
    eq. (1) per step: F_track = sum_i F_0,i + sum_j k_j Qbar_j, k_j = (a_{j+1} - a_j) + B_j.

    **The column at the ends.** The train of a track is the balls in its zone at the end of
    the step (trailing first) between two more "balls": the column at the exit and the column
    at the entry, whose pairs carry the column's step-mean forces (``column`` of the circuit's
    step). The trailing ball pushes the column at the exit with Q_x, so it is pushed back
    (P = +Q_x, towards +z); the column at the entry pushes the leading ball with Q_e
    (P = -Q_e). The column itself rolls on no raceway: the carriage's walls (return channel,
    turnarounds) hold it, so it passes every push to the carriage, a = -1, and its contacts
    cost no ball-ball braking (it turns freely, B = 0, as a pushed ball,
    :func:`tolsim.physics.trains.regimes.pair_braking`). Its two pairs then add

        (a_trail + 1) Q_x - (1 + a_lead) Q_e,

    the loaded balls' share a Q of the pushes plus the column's own force on the carriage,
    Q_x - Q_e (the free body of the column: the walls balance the two end forces). For
    nominal balls (a = -1/2) and a closed circuit (Q_x - Q_e = n_u f, eq. 7) that is
    n_u f / 2: the drag n_u f of the balls moving at v / 2 through the carriage costs the
    carriage n_u f / 2, the power balance (tests/study/test_circuit_friction.py). The largest
    contact force of a track counts the column's forces.

    **What is counted per step.** ``contact_fraction``: a step counts whole when a pair of
    two balls of the zone was pressed (closed with a force) at its start, else from its first
    ``inside`` contact event to its end, else not; ``clusters_formed``: the runs of pressed
    pairs of the zone at the end of the step that hold a pair not pressed at its start. A
    ball that entered the zone by the step's midpoint takes its own coefficients of the
    midpoint's solve, as its epsilon and K (Notes of :func:`tolsim.study.pipeline.
    carriage_circuit.first_contact_carriage_circuit`, "Entry"); one that entered after it was
    not evaluated in the step and takes the coefficients of the ball ahead of it, as its
    epsilon and K (:func:`tolsim.study.pipeline.carriage_circuit.entering_velocity`). A ball
    that left within the step is not in its train (its share of the step: O(dt)). A train is
    unresolved from the step at which a ball of its zone is unresolved or has no usable
    coefficients, a ball slides (as the open carriage's), or its circuit's step failed.

    **Windows.** A step's baseline counts the zone at its end with the loads of the
    midpoint's solve, so in a step in which a ball leaves or enters it mixes two zones: on
    ``configs/carriage_circuit.toml`` with ``[contact]`` (600 assemblies, seed 12) the
    baseline was 1.153, 1.151 and 1.152 N at 10, 21 and 42 steps against 1.147 N at 800,
    outside its interval, and the ripple's extremes came from such mixed zones and from
    the midpoint zones alone (0.042, 0.108, 0.124, 0.201 and 0.210 N at 10, 21, 42, 84 and
    417 steps against 0.232 N at 800). As for the open carriage
    (:meth:`tolsim.study.pipeline.track_friction.TrackFriction.window`, Notes there), in a
    step with an exit or entry each interval
    between them is solved at its own midpoint (:meth:`windows`, the balls at their
    circuit positions interpolated in the step) and gives its baseline to the time mean
    and, with the step's increase, to the extremes. The baseline is then 1.148, 1.146,
    1.148 and 1.147 N at 10, 21, 84 and 417 (the automatic step) steps against 1.147 N
    [1.145, 1.149] at 1 600, inside at each. The ripple is 0.1521, 0.1533, 0.1572, 0.1645
    and 0.1686 N at 10, 21, 84, 417 and 800 steps against 0.1726 N [0.1710, 0.1743] at
    1 600: still rising, at first order from below (4.7 % low at the automatic step,
    outside the interval). With ``configs/carriage_preload.toml`` and a default circuit it
    did not converge at all: 0.149, 0.184, 0.271 and 0.307 N at 40, 200 (automatic), 800
    and 1 600 steps. What the steps missed is the minimum: the column's push at an end of
    the zone (0.36 N at the exit there, most of the increase) stops for a short time after
    a ball leaves, until the next one closes onto the column, and a step's mean force
    hides such a dip unless the step is shorter than it.

    **Intervals.** So the circuit's step reports its friction between its events
    (:class:`tolsim.physics.circuit.FrictionWindows`, asked for by :meth:`observe` with
    each pair's slope k_j, :func:`pair_slopes`): its forces are constant between events,
    so the increase sum k_j Q_j of each interval is exact for constant epsilon and K. A
    step's extremes take the least and largest of its intervals with the step's baseline
    (:meth:`TrackFriction.extremes <tolsim.study.pipeline.track_friction.TrackFriction.
    extremes>`), and each window between exits and entries those of the intervals that
    overlap it (:meth:`window_increase`) with its own baseline. Two more things had to be
    exact for that: the times of exits and entries are the step's own
    (:func:`tolsim.study.pipeline.carriage_circuit.circuit_events` with the step's
    ``crossing_travel``; linear interpolation put an exit that slowed to the column's speed
    at the step's end), and a window's zone holds the balls by those crossings, not by
    their interpolated positions (:meth:`tolsim.study.pipeline.carriage_circuit.
    CircuitFrame.slots_at`, ``inside``). The ripple is then 0.3095, 0.3098, 0.3096 and
    0.3099 N at 10, 40, 200 and 800 steps against 0.3100 N at 1 600 (16 assemblies of
    ``configs/carriage_preload.toml`` with a default circuit; every train within 0.006 N
    of its value at 1 600, 0.002 N from 200 steps), and 0.1730 N and 0.1719 N at 10 and
    417 (automatic) steps against 0.1720 N [0.1677, 0.1762] at 800 on
    ``configs/carriage_circuit.toml`` (64 assemblies). What remains is epsilon's change
    within a step. The largest increase and the largest contact force take the
    intervals' too, and so does the sliding check (:meth:`interval_slides`: each zone ball
    at each interval's forces, its release pushes settled for the balls an interval
    pushes; on the steps' mean forces alone it missed pushes shorter than a step, 12 of
    200 assemblies sliding at 10 steps against 197 at 200 with a return drag of 1 N per
    ball, now 200 at 10, 40 and 200); the time means and the recorded examples keep the
    step means. A step with more than 64 intervals in one circuit (16 with
    :func:`tolsim.physics.circuit.step`'s default) merges the rest into its last: their
    extremes over a longer time (wider, never narrower), and the train is unresolved from
    that step (its sliding check has no forces for them).

    **Not modelled.** The circuit's step moves the balls with K alone: the ball-ball braking
    c of the open trains' cluster rule (kappa instead of K, |c K| < 1) is left out of the
    motion (the Notes of :func:`tolsim.physics.circuit.step`, "Neglected"); it enters the
    friction through B_j. The creep stiffness of the motion is its regime's, as the trains'
    (:meth:`tolsim.study.pipeline.carriage_circuit.CircuitFrame.stiffness`; an anchor rigid
    to 1e-9, :data:`tolsim.study.pipeline.carriage_circuit.ANCHOR_STIFFNESS`).
    """

    def __init__(self, frame, friction):
        self.frame, self.friction = frame, friction
        self.column_row = column_coefficients()
        self.used = np.append(_USED, _K)
        self.width = frame.slots + 2

    def begin(self, block, position):
        rows = block.size * self.frame.tracks
        self.friction.begin(block.size, np.zeros((rows, self.width - 1), dtype=bool),
                            carriage_frame=True)
        self.pressed = self.frame.ring_closed.copy()  # touching at t = 0
        self.column_sum = np.zeros(rows)

    def following(self):
        return True  # every assembly over the whole stroke

    def _ring_coefficients(self, state2, ring, entering):
        """(C, N, len(TRAIN_COLUMNS)) coefficients of the ring balls at the step's midpoint
        (NaN for the others: a ball in the zone at the end of the step was in it at the
        midpoint, or entered after it). ``ring`` (C, S) the ring ball of each slot at the
        step's start, ``entering`` the balls entered by the midpoint (the frame's, None)."""
        friction, slots = self.friction, self.frame.slots
        trains = (-1, slots)
        c, n = ring.shape[0], self.frame.sigma.shape[1]
        own = None
        if entering is not None:  # entered by the midpoint: their own, from its solve
            take, ring_e, balls = entering
            own = friction.coefficients(balls(), take, rates=True)
        # a pair across the two batches needs both balls' rolling rates where one is not in
        # regime A (pair_braking): the midpoint's then too (the entering ones always have
        # them, being few)
        code = None if own is None else own[..., _COL["regime"]]
        rates = code is not None and bool(np.isin(code, _NOT_A).any())
        load = friction.coefficients(state2.balls, state2.loaded.reshape(trains), rates=rates)
        out = np.full((c, n, len(TRAIN_COLUMNS)), np.nan)
        line, slot = np.nonzero(ring >= 0)
        out[line, ring[line, slot]] = load[line, slot]
        if own is not None:
            line, slot = np.nonzero(take)
            out[line, ring_e[line, slot]] = own[line, slot]
        return out

    def observe(self, step):
        """Before the circuit's step: the ring balls' coefficients at the midpoint, and the
        pairs' slopes for the step's friction windows (``step.pair_slopes``)."""
        frame = self.frame
        c = len(step.rows) * frame.tracks
        entering = None
        if frame.entering is not None:
            entering = (frame.entering[0].reshape(c, -1), frame.entering[1].reshape(c, -1),
                        frame.entering_balls)
        self.ring_load = self._ring_coefficients(step.state2, frame.slot_ring.reshape(c, -1),
                                                 entering)
        self.ring_filled = nearest_coefficients(self.ring_load)
        step.pair_slopes = pair_slopes(self.ring_filled, self.column_row,
                                       frame.config.contact.ball_friction_coefficient)

    def moved(self, step):
        frame, circ = self.frame, step.circuit
        if len(step.rows) != frame.block.size:
            raise ValueError("CircuitTrains needs every assembly in every step")
        ring_load, self.ring_load = self.ring_load, None
        pressed = circ["closed"] & (circ["force"] > 0.0)
        c, width = len(circ["circuits"]), self.width
        loaded, member = np.empty((c, width), bool), np.empty((c, width), bool)
        load = np.empty((c, width, len(TRAIN_COLUMNS)))
        force = np.empty((c, width - 1))
        ok, start = np.empty(c, bool), np.empty(c, bool)
        formed = np.empty(c)
        ring = np.empty((c, width), dtype=np.int64)
        circuit_trains_kernel(circ["loaded"], np.ascontiguousarray(ring_load), circ["ok"],
                              circ["mean_force"], pressed, self.pressed, circ["column"],
                              self.column_row, self.used, loaded, member, load, force, ok,
                              start, formed, ring)
        bad = np.repeat(step.overflow, frame.tracks) | (circ["status"] != 0)
        ok &= ~bad
        # the fraction of the step in contact: whole when pressed at its start, else from
        # its first contact inside the zone
        t_end = step.t + step.dt
        inside = np.where(circ["where"] == WHERE_INSIDE, circ["travel"] / frame.v, np.inf)
        first = inside.min(axis=1) if inside.shape[1] else np.full(c, np.inf)
        with np.errstate(invalid="ignore"):
            part = np.clip((t_end - first) / step.dt, 0.0, 1.0)
        contact = np.where(start, 1.0, np.where(np.isfinite(first), part, 0.0))
        friction = self.friction
        before = friction.figures_before()
        baseline, increase = friction.account(loaded, member, load, force, ok, contact, formed)
        if circ["windows"] is not None:
            friction.extremes(baseline, *window_extremes(circ["windows"]))
            self.interval_slides(step, circ)
        if friction.record:
            self.record(circ, ring, force, baseline + increase)
        self.windows(step, circ, before)
        self.pressed = pressed
        # the column's share: (a_trail + 1) Qbar_x - (1 + a_lead) Qbar_e
        lead = np.maximum(member.sum(axis=1) - 2, 1)
        line = np.arange(c)
        share = ((load[:, 1, _A] + 1.0) * force[:, 0]
                 - (1.0 + load[line, lead, _A]) * force[line, lead])
        self.column_sum += np.where(ok & (lead > 0), np.nan_to_num(share), 0.0) * \
            self.friction.weight

    def windows(self, step, circ, before):
        """The friction of a step in which a ball leaves or enters the zone, as the open
        carriage's (:meth:`tolsim.study.pipeline.carriage_track.CarriageTrains.windows`;
        Notes of :class:`tolsim.study.pipeline.track_friction.TrackFriction`, "Windows"):
        the rows' extremes and baseline sum as before the step (``before``), then each
        interval between the step's exits and entries (``step.events``) solved at its own
        midpoint, with the ring balls at their circuit positions interpolated linearly in
        the step (as the events' times are) and those in the zone then as its slots: its
        baseline with the step's increase, and over its share of the step."""
        frame, friction, rows = self.frame, self.friction, step.rows
        tracks, slots = frame.tracks, frame.slots
        k = len(rows)
        times = np.concatenate([step.events[1].reshape(k, -1), step.events[3].reshape(k, -1)],
                               axis=1)
        points, share = np.empty((2, k, times.shape[1] + 1))
        count = np.empty(k, dtype=np.int64)
        interval_points_kernel(times, float(step.t), float(step.dt), points, share, count)
        friction.reopen((rows[count > 0][:, None] * tracks + np.arange(tracks)).reshape(-1),
                        before)
        for e in range(int(count.max(initial=0))):
            sel = np.flatnonzero(count > e)
            tau = points[sel, e]
            circuits = (rows[sel][:, None] * tracks + np.arange(tracks)).reshape(-1)
            frac = np.repeat((tau - step.t) / step.dt, tracks)[:, None]
            start = circ["sigma_start"][circuits]
            sigma = start + frac * (frame.sigma[circuits] - start)
            with np.errstate(invalid="ignore"):  # the zone's balls from the exact crossings
                crossed = circ["crossing"][circuits] / frame.v < np.repeat(tau, tracks)[:, None]
            z, ids, held = frame.slots_at(circuits, sigma,
                                          circ["loaded_start"][circuits] ^ crossed)
            baseline = frame.zone_baseline(z.reshape(len(sel), tracks, slots),
                                           ids.reshape(len(sel), tracks, slots), tau,
                                           rows[sel], friction)
            half = 0.5 * share[sel, e] * step.dt
            low = high = None
            if circ["windows"] is not None:
                low, high = self.window_increase(circ["windows"], circuits, tau - half,
                                                 tau + half, step.t + step.dt)
            friction.window(circuits, np.where(held < 0, np.nan, baseline),
                            np.repeat(share[sel, e], tracks), low, high)
        friction.close_windows()

    def interval_slides(self, step, circ):
        """The sliding check of each interval of the step (:func:`interval_slides_kernel`):
        a train whose ball slides or is released at an interval's forces is no longer
        followed from this step on, as at a step's mean forces (which hide a push shorter
        than the step); one whose interval forces are not known (merged) is unresolved."""
        windows, friction, frame = circ["windows"], self.friction, self.frame
        sign = 1.0 if frame.v * step.dt >= 0.0 else -1.0
        tie = 1e-12 * abs(frame.v * step.dt)
        args = (windows.force, windows.count, windows.start, circ["crossing"],
                circ["loaded_start"], sign, tie)
        need = np.empty(circ["crossing"].shape, dtype=bool)
        interval_pushed_kernel(*args, friction.alive, need)
        load = self.ring_filled
        settle_release_pushes(load, need, frame.config.bearing)
        code = np.empty(len(need), dtype=np.int8)
        interval_slides_kernel(*args, load, friction.alive, code)
        friction.halt(code != ROLLING, np.maximum(code, ROLLING))

    def window_increase(self, windows, circuits, first, last, step_end):
        """The least and largest increase (K,) [N] of circuits ``circuits`` (K,) over the
        circuit step's windows (:class:`tolsim.physics.circuit.FrictionWindows`) that
        overlap the times [``first``, ``last``] (K / tracks,) [s] by more than rounding
        (inf and -inf where none does); ``step_end`` [s] the end of the step."""
        tracks, v = self.frame.tracks, self.frame.v
        a, b = np.repeat(first, tracks)[:, None], np.repeat(last, tracks)[:, None]
        count = windows.count[circuits]
        width = windows.start.shape[1]
        valid = np.arange(width) < count[:, None]
        begin = np.where(valid, windows.start[circuits] / v, np.inf)
        finish = np.full_like(begin, step_end)
        finish[:, :-1] = np.where(valid[:, 1:], begin[:, 1:], step_end)
        tie = 1e-9 * (step_end - np.min(first, initial=step_end))
        overlap = valid & (begin < b - tie) & (finish > a + tie)
        return (np.where(overlap, windows.low[circuits], np.inf).min(axis=1),
                np.where(overlap, windows.high[circuits], -np.inf).max(axis=1))

    def record(self, circ, ring, force, friction):
        """The step into the trace of a recording TrackFriction (its ``record``), as the open
        carriage's trains record theirs (:func:`tolsim.study.analyses.friction_examples.
        friction_examples`): per row slot (the train of :func:`circuit_trains_kernel`: the
        zone's balls at the end of the step between the two columns) the study id (-1 for
        the columns), the carriage-frame z at the start and at the end of the step [m] (NaN
        for the columns; z = L/2 - (sigma mod L_c) at the end, and back by the ball's travel
        sigma_end - sigma_start along the circuit: a ball that entered in the step starts
        beyond L/2), the step-mean pair forces [N] and the step's friction force [N]."""
        frame, trace = self.frame, self.friction.trace
        circuits = circ["circuits"]
        take = np.maximum(ring, 0)
        sigma = np.take_along_axis(frame.sigma[circuits], take, axis=1)
        moved = sigma - np.take_along_axis(circ["sigma_start"], take, axis=1)
        end = frame.half_zone - np.mod(sigma, frame.length[circuits][:, None])
        column = ring < 0
        trace["ids"].append(np.where(column, -1, frame.ring_id[take]))
        trace["start"].append(np.where(column, np.nan, end + moved))
        trace["end"].append(np.where(column, np.nan, end))
        trace["force"].append(np.where(self.friction.alive[:, None], force, np.nan))
        trace["friction"].append(friction)

    def column_friction(self) -> np.ndarray:
        """The friction the column's forces at the zone's ends cost the carriage, (size,) [N]:
        (a_trail + 1) Qbar_x - (1 + a_lead) Qbar_e averaged over the stroke (Notes), the
        larger of the tracks'."""
        return self.column_sum.reshape(-1, self.frame.tracks).max(axis=1)


__all__ = ["CircuitTrains", "circuit_trains_kernel", "column_coefficients"]
