r"""Along-track propagation with a carriage whose balls recirculate (issue 24).

With ``[carriage.circuit]`` each track's balls run in a closed circuit (the loaded zone, two
turnarounds and a return channel; :mod:`tolsim.physics.circuit`): the balls that leave the
loaded zone come back in their order, with their sizes and tolerances, and the column of
unloaded balls pushes against a drag. :func:`first_contact_carriage_circuit` integrates a
block of assemblies with the one along-track loop
(:func:`tolsim.study.pipeline.propagation.integrate`) in the carriage frame of
:mod:`tolsim.study.pipeline.carriage_track`, extended by :class:`CircuitFrame` (the balls
move by the circuit's step, not by the free motion and fresh entering balls) and observed by
:class:`CircuitContact`. The theory is in the Notes of
:func:`first_contact_carriage_circuit`.
"""

import numpy as np
from numba import prange

from tolsim._jit import kernel_array, pjit
from tolsim.physics.circuit import (
    STATUS_ITERATIONS,
    STATUS_JAMMED,
    WHERE,
    FrictionWindows,
    circuit_length,
    step_circuit_kernel,
    window_arrays,
    wrap,
)
from tolsim.physics.trains.regimes import regime_creep_coefficients
from tolsim.physics.velocity.analytic import LOAD_COLUMNS
from tolsim.physics.velocity.creep_stiffness import creep_stiffness
from tolsim.physics.velocity.models import BALL_REGIME_B, BALL_THREE_POINT, BALL_TWO_POINT
from tolsim.study.pipeline.carriage_track import (
    CarriageBalls,
    CarriageFrame,
    count_unresolved_balls,
)
from tolsim.study.pipeline.circuit_friction import CircuitTrains
from tolsim.study.pipeline.circuit_kernels import (
    assembly_stiffness_kernel,
    circuit_events_kernel,
    circuit_figures_kernel,
    circuit_gaps_kernel,
    entering_fill_kernel,
    entering_inputs_kernel,
    late_entries_kernel,
    late_entry_kernel,
    midpoint_entering_kernel,
    ring_inputs_kernel,
    step_contacts_kernel,
)
from tolsim.study.pipeline.propagation import StepObserver, integrate
from tolsim.study.pipeline.track_friction import CREEP_MODELS
from tolsim.study.sampling import entering_capacity, moving_ball_values
from tolsim.study.spec import ContactSettings

_K = LOAD_COLUMNS.index("creep_stiffness")
#: The creep stiffness K [N] that moves an exactly two-point ball in the circuit's step: rigid
#: to 1e-9 of epsilon per newton of push. Such a ball rolls at v / 2 with both contacts
#: stuck while |P| + mu_bb S <= 2 mu F (:func:`tolsim.physics.trains.regimes.
#: regime_creep_coefficients`: an anchor, K = inf), some 30 N for a 10 mm ball on 150 N
#: against column forces below 1 N. The analytic model has no K for a ball without four
#: contacts (NaN), and the step gave two- and three-point balls the assembly's mean K as a
#: stand-in (1 N where no ball had one), so the column's push moved them: on
#: ``carriage_preload.toml`` without preload and a default circuit (100 assemblies, session
#: 28) every assembly touched, half of them within 4 ms, as waves of closing pairs from the
#: exit back through the zone (3 000 N: every ball two-point, epsilon = 0; 300 N: two-,
#: three- and four-point). With the regimes' K (:meth:`CircuitFrame.stiffness`) P is 0 and
#: 0.07, with column forces of 0.38 and 0.58 N at most.
ANCHOR_STIFFNESS = 1e9
#: Gaps at the start of the stroke at or below this are closed [m]: the positions are sums
#: of diameters and gaps (about 0.3 m, ulp 6e-17 m), so a zero gap comes out within a few
#: 1e-17 m of 0.
CLOSED_AT_START = 1e-15
#: The circuit's contact events by where they form, in the order of the result file's
#: ``circuit_contact_where`` (:data:`tolsim.physics.circuit.WHERE`).
WHERE_NAMES = tuple(WHERE[k] for k in sorted(WHERE))


def circuit_ball_ids(balls: int, circuit_balls: int) -> np.ndarray:
    """The study ball id of each ball of a circuit, in ring order (the direction of flow).

    Ring ball c < n (n = ``balls``, the train) is the train's ball n - 1 - c (the train is
    numbered from the trailing end, the ring from the entry); ring ball c >= n is the study's
    entering ball c (draw 5 k = c - n: :func:`tolsim.study.sampling.moving_ball_values`).
    """
    ring = np.arange(circuit_balls, dtype=np.int64)
    return np.where(ring < balls, balls - 1 - ring, ring)


@pjit
def slots_kernel(position, loaded, length, circuits, half_zone, ring_id, ring_ok, out_z,
                 out_id, out_ring, out_ok, out_count):
    """The loaded balls of the circuits ``circuits`` (K,) of (C, N) arrays as carriage slots
    (K, S) in z order (trailing first): z = L_z / 2 - (sigma mod L_c), the study id, the ring
    index and ``ring_ok`` of each (NaN, -1, -1, True past ``out_count``); ``out_count`` is set
    to -1 where a circuit has more loaded balls than slots. The circuits run on Numba's
    threads, each writing only its own row."""
    n = position.shape[1]
    slots = out_z.shape[1]
    for c in prange(len(circuits)):
        line = circuits[c]
        count = 0
        for r in range(n):
            if loaded[line, r]:
                x = wrap(position[line, r], length[line])  # (= %)
                z = half_zone - x
                if count >= slots:
                    count = -1
                    break
                # insertion in z order
                j = count
                while j > 0 and out_z[c, j - 1] > z:
                    out_z[c, j] = out_z[c, j - 1]
                    out_id[c, j] = out_id[c, j - 1]
                    out_ring[c, j] = out_ring[c, j - 1]
                    j -= 1
                out_z[c, j] = z
                out_id[c, j] = ring_id[r]
                out_ring[c, j] = r
                count += 1
        out_count[c] = count
        for j in range(max(count, 0), slots):
            out_z[c, j] = np.nan
            out_id[c, j] = -1
            out_ring[c, j] = -1
        for j in range(slots):
            out_ok[c, j] = True if out_ring[c, j] < 0 else ring_ok[line, out_ring[c, j]]


def initial_circuits(config, block, fixed=None):
    """Positions (M, N), diameters (M, N) and lengths (M,) of the block's circuits at t = 0
    (M = assemblies x tracks, N = ``carriage.circuit.balls``), in ring order (Notes of
    :func:`first_contact_carriage_circuit`, "Filling"); ``fixed``: the block's
    :func:`tolsim.study.sampling.fixed_ball_values`, if made (the same sizes, read instead of
    transformed again)."""
    circuit = config.carriage.circuit
    m, tracks, n, nb = block.size, config.n_tracks, config.train.balls, circuit.balls
    count = m * tracks
    nominal = 2.0 * config.bearing.ball_radius
    ids = np.broadcast_to(circuit_ball_ids(n, nb), (m, tracks, nb))
    diameter = np.full((count, nb), nominal)
    if "ball_oversize" in {t.source for t in config.tolerances if t.scope == "ball"}:
        values = moving_ball_values(config, block, np.ascontiguousarray(ids),
                                    np.zeros((m, tracks, nb)), fixed=fixed,
                                    sources=("ball_oversize",))
        diameter += values["ball_oversize"].reshape(count, nb)
    # the zone's gaps in ring order (the train's gaps reversed), and those outside it
    zone = block.initial_gap.reshape(count, n - 1)[:, ::-1]
    slack = circuit.slack
    total = zone.sum(axis=1)
    scale = np.where(total > slack, slack / np.where(total > 0, total, 1.0), 1.0)
    zone = zone * scale[:, None]
    rest = np.maximum(slack - zone.sum(axis=1), 0.0)
    draws = block.entering_gap.reshape(count, -1)[:, : nb - n + 1]
    weight = draws.sum(axis=1)
    share = np.where(weight[:, None] > 0, draws / np.where(weight > 0, weight, 1.0)[:, None],
                     1.0 / (nb - n + 1))
    gaps = np.concatenate([zone, rest[:, None] * share], axis=1)  # gap c: balls c, c + 1
    step = 0.5 * (diameter + np.roll(diameter, -1, axis=1)) + gaps
    # the train's leading ball (ring 0) where the block put it
    lead = block.initial_position.reshape(count, n)[:, -1]
    first = 0.5 * config.train.loaded_zone_length - lead
    position = first[:, None] + np.concatenate(
        [np.zeros((count, 1)), np.cumsum(step[:, :-1], axis=1)], axis=1)
    return position, diameter, circuit_length(diameter, gaps.sum(axis=1))


def entering_velocity(eps, stiffness, loaded, pushed=None):
    """Give the unloaded balls of circuits the epsilon and creep stiffness of the zone's entry
    ball (in place), for a ball that enters the zone within the step.

    Parameters
    ----------
    eps, stiffness : ndarray (C, N)
        Each ring ball's epsilon [-] and K [N] of the step (those of the unloaded balls are
        replaced).
    loaded : ndarray of bool (C, N)
        In the zone at the start of the step (one run of ring balls per circuit).
    pushed : ndarray of bool (C, N), optional
        The balls in the zone without a groove contact (pushed along); the balls outside the
        zone take the entry ball's flag as its epsilon.

    Notes
    -----
    The step of :func:`tolsim.physics.circuit.step_circuit_kernel` uses a ball's epsilon and K
    only while it is loaded, so only a ball that enters within the step is affected. One that
    entered by the midpoint then takes its own values of the midpoint's solve (Notes of
    :func:`first_contact_carriage_circuit`, "Entry"); one that enters after it was outside the
    zone at the step's evaluations, so it has none of its own, and moves for the
    rest of the step with those of the ball ahead of it (the zone's entry ball, the last to
    have entered), as the open carriage's entering ball
    (:func:`tolsim.study.pipeline.carriage_track_kernels.advance_kernel`). Its position error is at
    most |epsilon_k - epsilon_ahead| v dt / 4 (dt / 2 before the midpoint held the entering
    balls), against |epsilon_k| v dt / 2 at epsilon = 0:
    neighbours at the zone's entry share the carriage's load there and their track's rail and
    carriage errors, so only the ball's own part of epsilon remains. (Measured with
    ``benchmarks/convergence_along_track.py`` on ``configs/carriage_circuit.toml``, 300
    assemblies, seed 12, paired against the 800-step reference, before the midpoint held the
    entering balls: at epsilon = 0 the entering balls added 27 contacts and removed 1 at 25
    steps, added 10 at 50 steps; with the ball ahead's epsilon 2 and 3 at 25 steps, 1 and 2 at
    50.)
    """
    entering_fill_kernel(loaded, eps, stiffness,
                         np.zeros(loaded.shape, dtype=bool) if pushed is None else pushed)


def circuit_events(sigma0, sigma1, loaded0, loaded1, length, zone, ring_id, previous_id,
                   slot_ring, t, dt, crossing=None, v=None):
    """The exits and entries of a step of circuits, as the open carriage's
    (:func:`tolsim.study.pipeline.carriage_track_kernels.advance_kernel`, for a
    :class:`tolsim.study.pipeline.carriage_track.TrackTrace`).

    Parameters
    ----------
    sigma0, sigma1 : ndarray (C, N)
        Circuit positions at the start and the end of the step [m], ring order; C = k x
        tracks circuits of k assemblies.
    loaded0, loaded1 : ndarray of bool (C, N)
        Loaded there.
    length : ndarray (C,)
        L_c [m].
    zone : float
        L_z [m].
    ring_id : ndarray of int (N,)
        Study id of each ring ball (:func:`circuit_ball_ids`).
    previous_id : ndarray of int (k, tracks, slots)
        The slots' ids at the start of the step.
    slot_ring : ndarray of int (k, tracks, slots)
        The ring ball in each slot at the end of the step (-1: empty).
    t, dt : float
        Start and length of the step [s].
    crossing : ndarray (C, N), optional
        The travel at which each ball crossed an end of the zone in the step [m]
        (:class:`tolsim.physics.circuit.CircuitStep`, ``crossing_travel``; NaN: none).
    v : float
        The carriage's speed [m/s], with ``crossing``.

    Returns
    -------
    list of ndarray (k, tracks, slots)
        Exit ids at the slot the ball left, exit times [s], entry ids at the slot it took,
        entry times [s] (-1 / NaN elsewhere).

    Notes
    -----
    A ball leaves when its sigma mod L_c passes L_z, enters when it passes L_c (= 0). With
    ``crossing`` the time is the circuit step's own, travel / v (exact for constant epsilon
    and K). Without it the time is interpolated linearly on the ball's sigma within the
    step, as the open carriage's, which is exact only while the ball's speed is constant in
    the step: a ball's speed changes where it crosses (a leaving ball slows to the column's
    speed, often 0 against the drag), so on ``configs/carriage_preload.toml`` with a default
    circuit the interpolation put exits at the step's end that the step had 0.17 ms into
    it (at 1 600 steps), and the friction window after them was lost.
    """
    shape = previous_id.shape
    slots = shape[-1]
    exit_id, entry_id = (np.empty(shape, dtype=np.int64) for _ in range(2))
    exit_time, entry_time = np.empty(shape), np.empty(shape)
    exact = np.empty((0, 0)) if crossing is None else np.ascontiguousarray(crossing,
                                                                           dtype=float)
    circuit_events_kernel(sigma0, sigma1, loaded0, loaded1, np.asarray(length, dtype=float),
                          float(zone), ring_id, previous_id.reshape(-1, slots),
                          slot_ring.reshape(-1, slots), float(t), float(dt), exact,
                          float(1.0 if v is None else v),
                          exit_id.reshape(-1, slots), exit_time.reshape(-1, slots),
                          entry_id.reshape(-1, slots), entry_time.reshape(-1, slots))
    return [exit_id, exit_time, entry_id, entry_time]


class CircuitFrame(CarriageFrame):
    """The carriage frame with the balls in circuits (Notes of
    :func:`first_contact_carriage_circuit`): the slots of :class:`CarriageFrame` are the
    circuit's loaded balls, re-read from the circuit at every step; :meth:`advance` moves the
    circuits by the step's travel with each loaded ball's epsilon and creep stiffness of the
    step (:func:`tolsim.physics.circuit.step_circuit_kernel`) instead of the free motion.

    Circuit arrays (C = assemblies x tracks rows, N balls in ring order): ``sigma``,
    ``diameter``, ``ring_loaded``, ``ring_closed``, ``ring_speed``, ``length`` (C,),
    ``ring_ok`` (resolved at every evaluation so far); ``ring_id`` the study id of each ring
    ball (:func:`circuit_ball_ids`); ``slot_ring`` (size, tracks, slots) the ring ball in each
    slot. An unloaded ball in the zone (no groove contact) is resolved: it is pushed along
    by the circuit's step (:func:`tolsim.physics.circuit.step`, "Pushed balls"), and its
    pairs carry force once the gaps between its neighbours have closed.
    """

    pushes_unloaded = True
    draws_entries = False  # the circuit brings its balls (advance)

    def __init__(self, config, block):
        super().__init__(config, block)
        circuit = config.carriage.circuit
        self.drag = circuit.return_drag
        self.zone = config.train.loaded_zone_length
        self.ring_id = circuit_ball_ids(self.balls, circuit.balls)
        self.sigma, self.diameter_ring, self.length = initial_circuits(
            config, block, self.evaluation.fixed)
        self.slack = self.length - self.diameter_ring.sum(axis=1)
        shape = self.sigma.shape
        self.ring_loaded = np.mod(self.sigma, self.length[:, None]) < self.zone
        self.ring_closed = np.zeros(shape, dtype=bool)
        # touching at the start: a gap of the filling's rounding (a few 1e-17 m) is closed
        self.ring_closed[:] = self.gaps() <= CLOSED_AT_START
        self.ring_speed = np.full(shape, 0.5)
        self.ring_ok = np.ones(shape, dtype=bool)
        self.slot_ring = np.full(self.ball_id.shape, -1, dtype=np.int64)
        self.status = np.zeros(block.size, dtype=np.int64)
        self.model = CREEP_MODELS[ContactSettings().creep_model]
        self._rows = self._rows_circuits = None
        self.midpoint_stiffness = None  # (the midpoint's balls, K of its loaded balls)
        self.joined = None
        self.step_start = 0.0
        self.entering = None  # the balls entered by the midpoint and their values (evaluate)
        self.entering_balls = None  # their BallState (a function: made when first read)
        # travel [m] each ring ball moved after its entry with the entry ball's epsilon
        # (late_eps) in the step before (late_entries_kernel)
        self.late_travel, self.late_eps = np.zeros(shape), np.zeros(shape)
        self._slots(np.arange(block.size))

    def gaps(self, rows=None) -> np.ndarray:
        """Gaps (C_k, N) of the circuits of assemblies ``rows`` (all: None) [m], ring order
        (gap c between balls c and c + 1; they sum to the slack)."""
        circuits = np.arange(len(self.sigma)) if rows is None else self._circuits(rows)
        out = np.empty((len(circuits), self.sigma.shape[1]))
        circuit_gaps_kernel(self.sigma, self.diameter_ring, self.length, circuits, out)
        return out

    def _circuits(self, rows):
        """The circuits (rows of the circuit arrays) of assemblies ``rows``; the last answer
        again for the same ``rows`` object (a step's rows, read by the frame and observers)."""
        if rows is not self._rows:
            self._rows = rows
            self._rows_circuits = (np.asarray(rows)[:, None] * self.tracks
                                   + np.arange(self.tracks)).reshape(-1)
        return self._rows_circuits

    def _slots(self, rows):
        """Re-read the slots of assemblies ``rows`` from their circuits."""
        circuits = self._circuits(rows)
        k, tracks, slots = len(rows), self.tracks, self.slots
        z = np.empty((k * tracks, slots))
        ids = np.empty((k * tracks, slots), dtype=np.int64)
        ring = np.empty((k * tracks, slots), dtype=np.int64)
        ok = np.empty((k * tracks, slots), dtype=bool)
        count = np.empty(k * tracks, dtype=np.int64)
        slots_kernel(self.sigma, self.ring_loaded, self.length, circuits, self.half_zone,
                     self.ring_id, self.ring_ok, z, ids, ring, ok, count)
        at = slice(None) if len(rows) == len(self.status) else rows  # (every row: in order)
        self.position[at] = z.reshape(k, tracks, slots)
        self.ball_id[at] = ids.reshape(k, tracks, slots)
        self.slot_ring[at] = ring.reshape(k, tracks, slots)
        self.count[at] = np.maximum(count, 0).reshape(k, tracks)
        self.ball_ok[at] = ok.reshape(k, tracks, slots)
        overflow = (count < 0).reshape(k, tracks).any(axis=1)
        self.status[np.asarray(rows)[overflow]] |= STATUS_OVERFLOW_SLOTS

    def slots_at(self, circuits, sigma, inside=None):
        """The balls in the zone of circuits ``circuits`` (K,) with their ring balls at
        ``sigma`` (K, N) [m] as slots (K, S) in z order: z [m], study ids and the number
        held (-1: more than the slots) (:func:`slots_kernel`). ``inside`` (K, N): the balls
        in the zone, where known otherwise than from ``sigma`` (an interpolated sigma lags a
        ball that crossed an end and changed speed there); one inside that ``sigma`` puts
        outside is taken at the nearer end of the zone."""
        k, slots = len(circuits), self.slots
        length = self.length[circuits]
        x = np.mod(sigma, length[:, None])
        if inside is None:
            inside = x < self.zone
        else:
            late = inside & (x >= self.zone)
            if late.any():
                lap = (length[:, None] - x) < (x - self.zone)  # nearer the entry (L_c = 0)
                end = np.where(lap, length[:, None] + 1e-12 * self.zone,
                               (1.0 - 1e-12) * self.zone)
                sigma = np.where(late, sigma - x + end, sigma)
        z, ok = np.empty((k, slots)), np.empty((k, slots), dtype=bool)
        ids, ring = (np.empty((k, slots), dtype=np.int64) for _ in range(2))
        held = np.empty(k, dtype=np.int64)
        slots_kernel(sigma, inside, length, np.arange(k), self.half_zone, self.ring_id,
                     self.ring_ok[circuits], z, ids, ring, ok, held)
        return z, ids, held

    def stiffness(self, balls, loaded, where=None):
        """Creep stiffness K [N] of the loaded slots (NaN elsewhere and where unresolved):
        the analytic model at each ball's own contact state (:data:`tolsim.study.pipeline.
        track_friction.CREEP_MODELS`) in regime A, and its regime's for a ball in regime B,
        three- or two-point (:meth:`_regime_stiffness`), as the trains after contact; only
        at the slots ``where`` (a subset of ``loaded``) when given."""
        out = np.full(loaded.shape, np.nan)
        take = loaded if where is None else where
        if take.any():
            # the loaded balls (flattened in ``loaded`` order) wanted: all without ``where``
            pick = slice(None) if where is None else take[loaded]
            dbeta = np.ascontiguousarray(balls.contact_angle_deviation.reshape(-1, 4)[pick])
            force = np.ascontiguousarray(balls.normal_force.reshape(-1, 4)[pick])
            if self.model is CREEP_MODELS["analytic"]:  # its column K alone, bit for bit
                k = creep_stiffness(dbeta, force, self.config.bearing)
            else:
                k = self.model(dbeta, force, self.config.bearing, 0.0)[:, _K]
            regime = np.asarray(balls.regime).reshape(-1)[pick]
            other = np.isin(regime, (BALL_REGIME_B, BALL_THREE_POINT, BALL_TWO_POINT))
            if other.any():  # the K of its regime (Notes of ANCHOR_STIFFNESS)
                k = k.copy()
                solved = balls.solved_rows(pick)
                k[other] = self._regime_stiffness(
                    dbeta[other], force[other], regime[other],
                    np.asarray(balls.velocity_deviation).reshape(-1)[pick][other],
                    None if solved is None else (solved[0], solved[1][other]))
            out[take] = np.where(np.asarray(balls.valid).reshape(-1)[pick], k, np.nan)
        return out

    def _regime_stiffness(self, dbeta, force, regime, eps, solved=None):
        """K [N] of balls in regime B, three- or two-point: their regime's, as the trains
        after contact take it (:func:`tolsim.physics.trains.regimes.
        regime_creep_coefficients`: B its stick line, three-point its own minimum of D, an
        exactly two-point ball an anchor, here :data:`ANCHOR_STIFFNESS`). A two-point ball
        that the full model answered off balance (epsilon not 0: the static solve's error)
        keeps its stand-in (NaN): its epsilon times an anchor's K would be a force of that
        error. ``solved``: the balls' full-model solves (:meth:`BallState.solved_rows
        <tolsim.study.pipeline.evaluate.BallState.solved_rows>`), not solved again."""
        bearing = self.config.bearing
        load = self.model(dbeta, force, bearing, 0.0)
        k = regime_creep_coefficients(load, regime, dbeta, force, bearing, ball_friction=0.0,
                                      lazy_release=True, solved=solved)[:, _K]
        two = regime == BALL_TWO_POINT
        k = np.where(two & (eps == 0.0), ANCHOR_STIFFNESS, k)
        return np.where(two & (eps != 0.0), np.nan, k)

    def start(self, k, t, position):
        self.step_start = t
        return super().start(k, t, position)

    def evaluate(self, position, t):
        """The midpoint's balls, solved with the ring balls that have entered the zone by
        then (:func:`midpoint_entering_kernel`), which are then taken out of the returned
        slots (they are not in the step's start slots) and keep their own epsilon and K
        for the circuit's step (``entering``; :meth:`advance`): Notes of
        :func:`first_contact_carriage_circuit`, "Entry"."""
        self.midpoint, self.entering = position, None
        rows = self.rows
        z, ids = np.empty_like(position), np.empty_like(self.ids)
        ring = np.empty(position.shape, dtype=np.int64)
        entering = np.empty(position.shape, dtype=bool)
        midpoint_entering_kernel(kernel_array(position), self.ids, self.slot_ring[rows],
                                 self.count[rows], self._circuits(rows), self.sigma,
                                 self.ring_loaded, self.ring_speed, self.length,
                                 self.diameter_ring, float(self.half_zone),
                                 float(self.v * (t - self.step_start)), self.ring_id, z, ids,
                                 ring, entering)
        if not entering.any():
            z, ids = position, self.ids
        balls = CarriageBalls(*self.evaluation(z, ids, t, rows))
        self.resolve_seconds += balls.balls.resolve_seconds
        if not entering.any():
            return balls
        take = entering & balls.loaded
        if take.any():
            self.entering = (take, ring, balls.velocity_deviation,
                             self.stiffness(balls.balls, balls.loaded, take), balls.valid,
                             balls.unloaded)
            index = np.flatnonzero(take[balls.loaded])
            self.entering_balls = lambda: balls.balls.rows(index)  # in ``take`` order
        return balls.without(entering)

    def _joined(self, state1, state2, take):
        joined = super()._joined(state1, state2, take)
        self.joined = (joined, state1)  # the step's start balls and the carried ones
        return joined

    def _start_stiffness(self, state1, state2, missing, stiff):
        """:meth:`stiffness` of the step's start balls ``state1`` at the slots ``missing``,
        ``stiff`` that of the midpoint balls ``state2``. A ball carried from the previous
        step's midpoint (:meth:`CarriageFrame._carried`) has the K computed there, one that
        entered and is taken at this midpoint (:meth:`CarriageFrame._joined`) this
        midpoint's: K depends on each ball's own state alone, so both are the values
        :meth:`stiffness` gives. Computed when the start is not the carried balls."""
        carried, known, joined = self.carried, self.midpoint_stiffness, self.joined
        if (carried is None or known is None or joined is None or joined[0] is not state1
                or carried[0] is not joined[1] or known[0] is not carried[1]):
            return self.stiffness(state1.balls, state1.loaded, missing)
        out = np.full(missing.shape, np.nan)
        fresh = (np.zeros(missing.shape, dtype=bool) if self.fresh is None
                 else self.fresh & state2.loaded)  # taken at the midpoint (_joined)
        kept = missing & ~fresh
        out[kept] = known[1][carried[2][kept]]
        out[missing & fresh] = stiff[missing & fresh]
        return out

    def advance(self, step, new):
        # the circuits' step: the loaded balls at their epsilon and K of the step (the free
        # motion ``new`` is not used)
        rows = step.rows
        circuits = self._circuits(rows)
        state1, state2 = step.state1, step.state2
        eps = self.velocity(state1, state2)
        stiff = self.stiffness(state2.balls, state2.loaded)
        missing = ~np.isfinite(stiff) & state1.loaded  # K of the start where none at midpoint
        midpoint = (state2, stiff[state2.loaded])  # (K of each loaded ball, for the next step)
        if missing.any():
            stiff = np.where(missing, self._start_stiffness(state1, state2, missing, stiff),
                             stiff)
        self.midpoint_stiffness = midpoint
        c, n = len(circuits), self.sigma.shape[1]
        fallback = np.empty(c)  # each assembly's own mean K for a ball without one
        assembly_stiffness_kernel(kernel_array(stiff).reshape(c, -1), self.tracks,
                                  ANCHOR_STIFFNESS, fallback)
        unresolved = ~(state1.valid & state2.valid)
        # every assembly (as the circuit is followed over the stroke): the state in place,
        # else the rows' copies, written back after the step
        every = len(rows) == len(self.status)
        take = slice(None) if every else circuits
        at = slice(None) if every else rows
        ring = (self.slot_ring.copy() if every else self.slot_ring[rows]).reshape(c, -1)
        pushed = self.unloaded(state1, state2)  # no groove contact: pushed by the step
        if pushed is None:
            pushed = np.zeros(ring.shape, dtype=bool)
        before = ((self.sigma.copy(), self.ring_loaded.copy()) if every
                  else (self.sigma[circuits], self.ring_loaded[circuits]))  # copies
        sigma, loaded = (self.sigma, self.ring_loaded) if every else (x.copy() for x in before)
        ok = self.ring_ok[take]
        ring_eps, ring_k = np.empty((c, n)), np.empty((c, n))
        ring_pushed = np.empty((c, n), dtype=bool)
        # the slot balls' values in ring order, those entering within the step from the
        # entry ball (entering_velocity)
        ring_inputs_kernel(ring, eps.reshape(c, -1), stiff.reshape(c, -1), fallback,
                           pushed.reshape(c, -1), unresolved.reshape(c, -1), loaded, ok,
                           ring_eps, ring_k, ring_pushed)
        own = np.zeros((c, n), dtype=bool)
        entering = None  # (take, ring ball, BallState) of the balls entered by the midpoint
        if self.entering is not None:  # entered by the midpoint: their own values
            shape = (c, -1)
            entering_inputs_kernel(*(x.reshape(shape) for x in self.entering), fallback,
                                   ring_eps, ring_k, ring_pushed, own)
            entering = (self.entering[0].reshape(shape), self.entering[1].reshape(shape),
                        self.entering_balls)
            self.entering = self.entering_balls = None
        travel = self.v * step.dt
        late_travel, late_eps = self.late_travel[take], self.late_eps[take]
        # entered after the previous midpoint: its own epsilon makes up for the entry ball's
        late_entry_kernel(late_travel, late_eps, loaded, ok, ring_pushed, ring_eps,
                          float(travel))
        if not every:
            self.ring_ok[circuits] = ok
        closed, speed = self.ring_closed[take], self.ring_speed[take]
        velocity, force, mean_force = (np.empty((c, n)) for _ in range(3))
        column = np.empty((c, 4))
        count = np.empty(c, dtype=np.int64)
        capacity = n
        pair = np.full((c, capacity), -1, dtype=np.int64)
        where = np.full((c, capacity), -1, dtype=np.int8)
        when = np.full((c, capacity), np.nan)
        status = np.empty(c, dtype=np.int64)
        windows = window_arrays(c, n, step.pair_slopes, capacity=64)
        crossing = np.empty((c, n))
        step_circuit_kernel(sigma, np.ascontiguousarray(self.diameter_ring[take]),
                            ring_eps, ring_k, ring_pushed, loaded, closed,
                            np.ascontiguousarray(self.length[take]), float(self.zone),
                            float(self.drag), float(travel), float(self.v * step.t), speed,
                            velocity, force, mean_force, column, count, pair, where, when,
                            status, *windows, crossing)
        if not every:
            self.sigma[circuits], self.ring_loaded[circuits] = sigma, loaded
            self.ring_closed[circuits], self.ring_speed[circuits] = closed, speed
        else:  # (the step's record keeps its own copies)
            sigma, loaded, ok, closed = sigma.copy(), loaded.copy(), ok.copy(), closed.copy()
        self.status[rows] |= np.bitwise_or.reduce(status.reshape(len(rows), -1), axis=1)
        step.previous_id = step.ball_id.copy()
        self._slots(rows)
        bad = (self.status[rows] & (STATUS_JAMMED | STATUS_ITERATIONS
                                    | STATUS_OVERFLOW_SLOTS)) != 0
        step.overflow = bad
        step.events = circuit_events(before[0], sigma, before[1], loaded, self.length[take],
                                     self.zone, self.ring_id, step.previous_id,
                                     self.slot_ring[at], step.t, step.dt, crossing,
                                     self.v)
        late_entries_kernel(step.events[3].reshape(c, -1), self.slot_ring[at].reshape(c, -1),
                            own, ring_eps, ring_pushed, float(step.t + step.dt),
                            float(self.v), late_travel, late_eps)
        if not every:
            self.late_travel[circuits], self.late_eps[circuits] = late_travel, late_eps
        step.circuit = {"ok": ok, "loaded": loaded, "closed": closed, "force": force,
                        "mean_force": mean_force, "column": column, "count": count,
                        "pair": pair, "where": where, "travel": when,
                        "circuits": circuits, "pushed": ring_pushed, "slot_ring": ring,
                        "status": status, "sigma_start": before[0], "entering": entering,
                        "entry_time": ring_entry_time(step.events[3], self.slot_ring[at], n),
                        "loaded_start": before[1], "crossing": crossing,
                        "windows": (None if step.pair_slopes is None
                                    else FrictionWindows(*windows[1:]))}


def ring_entry_time(entry_time, slot_ring, balls):
    """Each ring ball's time of entry into the zone in the step (C, N) [s] (NaN: none), from
    the slots' entry times and ring balls (k, tracks, slots) at the step's end."""
    slots = entry_time.shape[-1]
    entry_time, slot_ring = entry_time.reshape(-1, slots), slot_ring.reshape(-1, slots)
    out = np.full((len(entry_time), balls), np.nan)
    c, j = np.nonzero(np.isfinite(entry_time) & (slot_ring >= 0))
    out[c, slot_ring[c, j]] = entry_time[c, j]
    return out


#: Status bit of an assembly whose loaded balls outnumbered the carriage's slots.
STATUS_OVERFLOW_SLOTS = 8


class CircuitContact(StepObserver):
    """The contacts of each assembly's circuits (:class:`CircuitFrame`), over the whole
    stroke: the first contact between loaded balls (``time``, ``pair``, ``valid`` as
    :class:`tolsim.study.pipeline.carriage_track.CarriageFirstContact`), the circuit's
    contact events by where they form (``where_count`` (size, 4), :data:`WHERE_NAMES`), the
    column forces at the ends of the zone (``column_max``, ``column_mean`` (size, 2):
    entry, exit, the largest over the tracks at the ends of the steps and the mean over the
    stroke of the larger track's), each circuit's total gap at the start and end of the
    stroke (``total_gap_start``, ``total_gap_end`` (size, tracks)) and the largest departure
    of the total gap from the slack at any step (``slack_error`` (size,)) [m]; with
    ``[contact]`` the friction of the column's forces at the zone's ends (``column_friction``
    (size,) [N], :meth:`tolsim.study.pipeline.circuit_friction.CircuitTrains.
    column_friction`); ``unresolved`` (size,) the balls unresolved along the track before the
    first contact (:func:`tolsim.study.pipeline.carriage_track.count_unresolved_balls`)."""

    def __init__(self, frame):
        self.frame = frame
        self.half_zone, self.slots, self.balls = frame.half_zone, frame.slots, frame.balls
        self.column_friction = None  # (size,) [N] with [contact] (CircuitTrains)

    def begin(self, block, position):
        m, tracks = block.size, self.frame.tracks
        self.time = np.full(m, np.inf)
        self.pair = np.full(m, -1, dtype=np.int64)
        self.valid = np.ones(m, dtype=bool)
        self.where_count = np.zeros((m, len(WHERE_NAMES)), dtype=np.int64)
        self.column_max = np.zeros((m, 2))
        self.column_mean = np.zeros((m, 2))
        self.total_gap_start = self.frame.gaps().sum(axis=1).reshape(m, tracks)
        self.total_gap_end = self.total_gap_start.copy()
        self.slack_error = np.zeros(m)
        self.travel = 0.0
        self.unresolved = np.zeros(m, dtype=np.int64)
        self._seen = set()

    def following(self):
        return True  # every assembly over the whole stroke

    def observe(self, step):
        searching = ~np.isfinite(self.time[step.rows])
        self.searching = searching
        resolved = step.state1.valid & step.state2.valid
        self.valid[step.rows[searching]] &= resolved.all(axis=(1, 2))[searching]
        count_unresolved_balls(self.unresolved, self._seen, step, searching)

    def moved(self, step):
        frame, rows, circ = self.frame, step.rows, step.circuit
        tracks, k = frame.tracks, len(rows)
        loaded = circ["loaded"]
        # contact events: where they formed; a first contact is an event inside the zone
        # (both balls loaded) of resolved balls, or a closed pair of loaded, resolved balls
        # that carries force at the end of the step (pushed in closed by the column, or
        # closed before the step)
        t_end = step.t + step.dt
        hits = np.empty((k * tracks, len(WHERE_NAMES)), dtype=np.int64)
        t_all, ring_pair = np.empty(k * tracks), np.empty(k * tracks, dtype=np.int64)
        step_contacts_kernel(circ["ok"], loaded, circ["closed"], circ["force"], circ["pair"],
                             circ["where"], circ["travel"], float(frame.v), float(t_end),
                             len(WHERE_NAMES), circ["entry_time"], hits, t_all, ring_pair)
        t_all = t_all.reshape(k, tracks)
        first_track = np.argmin(t_all, axis=1)
        t_first = t_all[np.arange(k), first_track]
        new = np.flatnonzero(np.isfinite(t_first) & ~np.isfinite(self.time[rows])
                             & (t_first <= t_end))
        if len(new):
            track = first_track[new]
            self.time[rows[new]] = t_first[new]
            self.pair[rows[new]] = track * (self.balls - 1) + self._slot_index(
                rows[new], track, (ring_pair[new * tracks + track] + 1) % loaded.shape[1])
        # the events by where, the column forces (circuit_figures_kernel)
        circuit_figures_kernel(rows, tracks, hits, circ["column"], float(frame.v * step.dt),
                               self.where_count, self.column_max, self.column_mean)
        self.travel = max(self.travel, frame.v * t_end)
        total = frame.gaps(rows).sum(axis=1).reshape(k, tracks)
        self.total_gap_end[rows] = total
        error = np.abs(total - frame.slack[frame._circuits(rows)].reshape(k, tracks))
        self.slack_error[rows] = np.maximum(self.slack_error[rows], error.max(axis=1))
        searching = self.searching  # as without the circuit: up to the first contact
        self.valid[rows[searching]] &= ~step.overflow[searching]

    def _slot_index(self, row, track, ring_ball):
        """The zone position j (from the trailing end, at most balls - 2) of ring balls
        ``ring_ball`` (the pairs' trailing balls) of tracks ``track`` of assemblies ``row``
        (arrays of one length) at the end of the step; 0 for one that has left."""
        match = self.frame.slot_ring[row, track] == ring_ball[:, None]
        j = np.where(match.any(axis=1), np.argmax(match, axis=1), 0)  # the first match
        return np.minimum(j, max(self.balls - 2, 0))

    def figures(self):
        """The circuit figures of the block (:meth:`tolsim.study.statistics.accumulator.
        Accumulator.add_circuit`)."""
        travel = self.travel if self.travel > 0 else 1.0
        out = {"where_count": self.where_count, "column_max": self.column_max,
               "column_mean": self.column_mean / travel,
               "total_gap_start": self.total_gap_start, "total_gap_end": self.total_gap_end,
               "slack_error": self.slack_error}
        if self.column_friction is not None:  # with [contact]
            out["column_friction"] = self.column_friction
        return out


def first_contact_carriage_circuit(config, block, observers=(), *, friction=None):
    r"""First contact of a block's carriage assemblies whose balls run in circuits.

    Parameters
    ----------
    config : StudyConfig
        With ``[carriage]``, ``[carriage.circuit]`` and ``propagation = "along_track"``.
    block : tolsim.study.sampling.Block
        With the circuits' balls outside the zone as its entering draws
        (:func:`tolsim.study.sampling.entering_capacity`).
    observers : sequence of StepObserver
        More observers (a :class:`tolsim.study.pipeline.carriage_track.TrackTrace`).
    friction : tolsim.study.pipeline.track_friction.TrackFriction, optional
        With it (a study with ``[contact]``) the friction figures of the trains after contact
        are accumulated in ``friction`` (:class:`tolsim.study.pipeline.circuit_friction.
        CircuitTrains`); the motion, first contact and circuit figures are the same as
        without it.

    Returns
    -------
    time, pair, train_valid, resolve_seconds, state, carriage
        As :func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`.
    contact : CircuitContact
        The circuit figures (:meth:`CircuitContact.figures`).

    Notes
    -----
    **The circuit in the carriage frame.** Each track's N balls run round a closed circuit
    (:mod:`tolsim.physics.circuit`, its state, rules and what it neglects in the Notes of
    :func:`tolsim.physics.circuit.step`): arc length sigma from the entry of the loaded zone
    (z = +L/2) in the direction of flow, so a loaded ball sits at z = L/2 - (sigma mod L_c).
    The carriage frame of :func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`
    holds the loaded balls in slots; here the slots are re-read from the circuits at the end
    of every step (:func:`slots_kernel`), and the carriage is solved with those balls at
    their own z as there. Each ball keeps its study id (:func:`circuit_ball_ids`), so its
    ``ball`` tolerances (its size among them) and its track's rail and carriage values go with
    it, and it reads the rail fields at its rail position s = z + v t.

    **Filling.** At t = 0 the train's balls are where the block put them (the loaded zone's
    gaps are the sampled ``initial_gap`` of the train) and the N - n balls outside the zone are
    the block's entering balls; the N - n + 1 gaps outside the zone share the rest of the slack,
    slack - sum of the zone's gaps, in proportion to the block's entering gaps (equally if those
    are all 0). Should the zone's gaps exceed the slack, they are scaled down to it and the
    balls outside the zone touch. The diameters are D + the ball's ``ball_oversize`` (if a
    source), so the slack is the circuit's length minus the true diameters. The total gap of
    every circuit equals the slack at every step (by construction of the circuit's state; the
    ``slack_error`` of :class:`CircuitContact` records the rounding).

    **The step.** The one loop, :func:`tolsim.study.pipeline.propagation.integrate`, evaluates
    the loaded balls at the start and at the midpoint of each step as without the circuit
    (epsilon_1, the midpoint positions on the free motion, epsilon_2; a ball outside the zone
    at the midpoint keeps epsilon_1); then the circuits move by the step's carriage travel
    v dt with each loaded ball's epsilon of the step and its creep stiffness K (the analytic
    model at its own contact state at the midpoint, as the trains after contact; the mean K
    of its assembly's loaded balls for a ball without one, so that an assembly's result does
    not depend on the assemblies it is integrated with), by
    :func:`tolsim.physics.circuit.step_circuit_kernel`: exact for constant epsilon and K in
    the step, contacts located at their exact travel, balls crossing the zone's ends at their
    exact travel.

    **Entry.** The midpoint's carriage solve holds the ring balls that have entered the zone
    by then (:meth:`CircuitFrame.evaluate`, :func:`tolsim.study.pipeline.circuit_kernels.
    midpoint_entering_kernel`), as the open carriage's midpoint holds its entering draws: an
    unloaded ball upstream of the entry ball is predicted at sigma + xi (v dt / 2), xi its
    circuit speed at the end of the previous step (pushed by the column, coasting or at
    rest), no nearer the entry than touching the ball ahead. So the balls in the zone are
    solved with the load distribution of the balls that are there at the midpoint, and a
    ball that entered by then moves from its entry (located exactly by the circuit's step)
    at its own epsilon and K of that solve. A ball that enters in the second half of the
    step was outside the zone at both evaluations: it moves for the rest of the step, a
    travel lambda, with the epsilon and K of the ball ahead of it (:func:`entering_velocity`),
    and makes up for it in the next step, which it crosses at epsilon + (lambda / s)
    (epsilon - epsilon_ahead) (s the step's travel; :func:`tolsim.study.pipeline.
    circuit_kernels.late_entry_kernel`), so that at the end of that step it is where its own
    epsilon from its entry puts it, to O(lambda s) in the change of epsilon. A pair pushed into
    the zone closed by the column touches (a contact of loaded balls) when its later ball
    enters, at that ball's entry time (interpolated on its sigma in the step), not at the
    end of the step. Before these rules (every entering ball with the ball ahead's values for
    the rest of its step, the midpoint solved without it, a pushed-in pair at the step's end)
    the circuit needed twice the steps (``benchmarks/convergence_along_track.py``, 600
    assemblies against 800 steps; the mean change of the time to first contact over the
    assemblies that touch in both, and the paired change): ``configs/carriage_circuit.toml``
    2.4 ms (+4/-0) at 21 steps against 4.5 ms (+3/-5) at the former 42;
    ``configs/carriage_preload.toml`` with a default circuit 1.8 ms (+0/-0) at 10 steps
    against 1.0 ms (+2/-1) at the former 20 and 3.7 ms (+4/-1) at 10 (Notes of
    :func:`tolsim.study.pipeline.propagation_rules.time_steps`).

    An unresolved ball moves at epsilon = 0 (as without the circuit) and makes its assembly
    invalid if it happens before the first contact. A ball in the zone without a groove
    contact (unloaded, issue 25: under an end relief, an undersized ball) is resolved: it has
    no epsilon or K of its own and the circuit's step pushes it along between its neighbours
    (:func:`tolsim.physics.circuit.step`, "Pushed balls"; the rule of
    :func:`tolsim.study.pipeline.propagation.pushed_along` on the ring),
    so its pairs carry force, and count as a contact, only when the gaps from one neighbour
    to the other have all closed.

    **Contact.** P(contact) and the time to first contact keep their meaning: the first contact
    between two loaded balls that are resolved so far, either a gap between them closing inside
    the zone (an ``inside`` event of the circuit, at its exact travel), or a closed pair of loaded
    balls that carries force at the end of a step (balls pushed into the zone in contact by the
    column; its time the entry of its later ball in the step, "Entry", else the end of the
    step, at most dt late). Contacts of unloaded balls (at the
    entry, the exit or in the return channel) carry no friction of loaded balls and are counted
    apart, by where they form (``where_count``); a run of pushed balls closes as one event,
    labelled by the balls at its ends. The pair index is that of the open model,
    track * (balls - 1) + j, j the position of the pair's trailing ball from the trailing end at
    the end of the step (at most balls - 2). Every assembly is followed over the whole stroke.

    **After contact.** The circuit's step moves the loaded balls as trains (the cluster rule
    on the ring) with or without ``[contact]``; with it (``friction``) the friction figures of
    the open carriage's trains are accumulated from the step's forces, with the column's force
    at the zone's ends on the end balls (:class:`tolsim.study.pipeline.circuit_friction.
    CircuitTrains`).

    Cost: the evaluation of the open model plus one circuit step per assembly and step
    (O(N) per event, a few events per step), and every assembly is followed to the end.
    """
    if config.carriage is None or config.carriage.circuit is None:
        raise ValueError("first_contact_carriage_circuit needs a config with "
                         "[carriage.circuit]")
    if block.entering_gap is None or block.entering_gap.shape[1] < config.n_tracks * (
            entering_capacity(config)):
        raise ValueError("the block holds no circuit balls: draw it with sample_block from a "
                         "config with [carriage.circuit]")
    frame = CircuitFrame(config, block)
    contact = CircuitContact(frame)
    trains = [] if friction is None else [CircuitTrains(frame, friction)]
    integrate(config, frame, [contact, *trains, *observers])
    if trains:
        contact.column_friction = trains[0].column_friction()
    return (contact.time, contact.pair, contact.valid, frame.resolve_seconds,
            frame.initial_state, frame.initial_carriage, contact)


__all__ = ["WHERE_NAMES", "CircuitContact", "CircuitFrame", "circuit_ball_ids",
           "circuit_events", "entering_velocity", "first_contact_carriage_circuit",
           "initial_circuits", "slots_kernel"]
