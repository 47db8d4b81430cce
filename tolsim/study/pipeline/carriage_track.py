r"""Along-track propagation with a carriage: balls rolling through its loaded zone (issue 12).

With ``propagation = "along_track"`` and a ``[carriage]``, each assembly's balls roll through
the carriage's loaded zone while the carriage makes its stroke; the carriage is re-solved as
they move, balls leave the zone at its trailing end and new ones enter at its leading end.
:func:`first_contact_carriage_track` integrates a block of assemblies and finds the first
ball-to-ball contact of each, as :func:`tolsim.study.pipeline.propagation.first_contact_along_track`
does for single trains, with the same loop (:func:`tolsim.study.pipeline.propagation.integrate`)
in the carriage frame (:class:`CarriageFrame`).
The theory (frames, the loaded zone with its exits and entries, the integration, the trains
after contact) is in the Notes of :func:`first_contact_carriage_track`.

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033 (Eq. 23, Sec. 3.2).
"""

from dataclasses import dataclass, field

import numpy as np

from tolsim._jit import kernel_array
from tolsim.physics.carriage import (
    STATUS_CONVERGED,
    CarriageLayout,
    end_relief,
    solve_carriage,
    solve_carriage_batch,
)
from tolsim.physics.static import GrooveErrors
from tolsim.physics.velocity.analytic import LOAD_COLUMNS
from tolsim.physics.velocity.models import BALL_UNLOADED, BALL_UNRESOLVED, MODEL_UNRESOLVED
from tolsim.study.pipeline.ball_kernels import nan_to_num, scatter_loaded_balls_kernel
from tolsim.study.pipeline.carriage import CarriageState
from tolsim.study.pipeline.carriage_track_kernels import (
    advance_frame_kernel,
    carriage_motion_kernel,
    carry_slots_kernel,
    entering_by_kernel,
    entry_shift_kernel,
    first_contact_kernel,
    initial_balls_kernel,
    joined_kernel,
    newton_start_kernel,
    remember_kernel,
    slot_inputs_kernel,
    step_velocity_kernel,
    window_points_kernel,
)
from tolsim.study.pipeline.evaluate import (
    BallState,
    concatenated_balls,
    groove_error_buffers,
    loaded_ball_velocities,
    serial_if_small,
    settle_and_find_light,
    settle_unresolved_loads,
)
from tolsim.study.pipeline.propagation import (
    AlongTrackFrame,
    Step,
    StepObserver,
    force_gaps,
    gaps,
    integrate,
    pushed_along,
)
from tolsim.study.sampling import entering_capacity, fixed_ball_values, moving_ball_values

#: Relative tolerance of the carriage's and every ball's balance in the solves along the track
#: (``tol`` and ``ball_tol`` of :func:`tolsim.physics.carriage.solve_carriage_batch`, whose
#: defaults are 1e-11 and 1e-12). The Newton converges quadratically from the assembly's own
#: solution of a pitch earlier (:meth:`_Evaluation.newton_start`), so at 1e-4 most solves stop
#: after one joint step: on ``configs/carriage_preload.toml`` (40 assemblies, 379 solves) 1.29
#: joint steps and 2.29 flank passes per solve, against 2.0 and 3.0 at 1e-6 and 2.10 and 3.10
#: at 1e-8 (the former value). The solution moves by about the tolerance. Measured against 1e-8
#: on the same study (2 x 4 096 assemblies, seed 12): the contact forces by at most 1.5e-4 of
#: the assembly's largest, the contact angles by at most 4.9e-7 rad, the initial epsilon by at
#: most 2.6e-7, and the first contacts at the same pairs of the same assemblies, within 3.3e-5
#: s. With ``benchmarks/convergence_along_track.py``'s studies (2 000 assemblies, the automatic
#: steps) with and without a circuit, an end relief (1 um, 15 mm) or ``[contact]``: the same
#: contacts, the mean change of the first contact 1.7e-6 s at most, and the means of the
#: friction figures by at most 1/200 of their 95 % half-widths (the ripple's by 5.5e-6 against
#: 1.2e-3). The largest change is some 200 times below the step's own error (7 ms at the
#: automatic 10 steps; Notes of :func:`tolsim.study.pipeline.propagation_rules.time_steps`);
#: ``tests/study/test_carriage_along_track.py`` bounds it. At 1e-3 the largest change was 0.9
#: ms.
TRACK_TOLERANCE = 1e-4
#: An assembly whose solve at TRACK_TOLERANCE leaves a contact of a loaded ball (one it does
#: not settle as unloaded) below this fraction of its largest contact force is solved on,
#: from that solution, to POLISH_TOLERANCE. The loose solve's force errors scale with the
#: carriage's force scale, not with each contact's force, so a light contact's force is off
#: by a large fraction of itself, and a ball near the boundary of regimes A and B is
#: sensitive to it. On ``configs/carriage_preload.toml`` without preload (two-, three- and
#: four-point balls with light diagonals of 0.2-0.3 N beside 12-15 N; 20 000 assemblies, seed
#: 12; session 28) the loose solve against one to 1e-8 moved 30 initial epsilons by more
#: than 1e-4 (the largest 4.0e-3, a four-point ball read in regime A instead of B), changed
#: the regime of 1 607 of 480 000 balls and the outcome of 3 assemblies (P 0.01440 against
#: 0.01425). Polished at 0.1, the largest change was 3.8e-9, no outcome changed and the
#: contact times moved by 1.1e-8 s at most, for 6 % more time (16.1 s against 15.2 s; the
#: tight solve everywhere 16.8 s). With preload no contact is that light (the lightest some
#: 0.36 of the largest on ``carriage_preload.toml``), so those studies solve as before, bit
#: for bit.
LIGHT_CONTACT = 0.1
#: The relative tolerance of the polishing solves (LIGHT_CONTACT).
POLISH_TOLERANCE = 1e-8
#: The column of a ball's free-rolling carriage force F_0 (the baseline's) in its coefficients.
_F0 = LOAD_COLUMNS.index("free_rolling_carriage_force")
#: Solutions of each assembly kept for the Newton's start: one pitch back at up to four solves
#: per pitch (:meth:`_Evaluation.newton_start`).
_REMEMBERED = 5


def slot_capacity(config) -> int:
    """Ball slots per track: the most balls a track's loaded zone can hold.

    Centres at least a diameter D apart within [-L/2, L/2]: floor(L / D) + 1, and at least
    the train's balls (a train longer than the zone at t = 0).
    """
    diameter = 2.0 * config.bearing.ball_radius
    return max(int(config.train.balls),
               int(np.floor(config.train.loaded_zone_length / diameter * (1 + 1e-12))) + 1)


@dataclass
class TrackTrace(StepObserver):
    """What the integration did, for tests and plots (``trace`` of
    :func:`first_contact_carriage_track`).

    Per step k (lists of length ``time_steps``, over the assemblies still followed,
    ``rows``): ``time`` its start t_k [s]; ``ball_z`` (m_k, tracks, slots) the positions
    there and ``midpoint_z`` at its midpoint [m] (NaN: empty slot); ``ball_id``
    (m_k, tracks, slots) (-1 empty; j < balls the initial ball j, balls + k the k-th
    entering ball of the track); ``velocity_deviation`` epsilon_2, at the midpoint [-] (NaN:
    outside the zone or unresolved), and ``normal_load`` N_y of the loaded balls there [N]
    (NaN elsewhere): the balls of the step's one evaluation.
    ``exits`` and ``entries``: one row (assembly, track, ball id, time [s]) per event.
    """

    time: list = field(default_factory=list)
    rows: list = field(default_factory=list)
    ball_z: list = field(default_factory=list)
    midpoint_z: list = field(default_factory=list)
    ball_id: list = field(default_factory=list)
    velocity_deviation: list = field(default_factory=list)
    normal_load: list = field(default_factory=list)
    exits: list = field(default_factory=list)
    entries: list = field(default_factory=list)

    def events(self, kind: str) -> np.ndarray:
        """``exits`` or ``entries`` as an array (k, 4): assembly, track, ball id, time [s]."""
        rows = getattr(self, kind)
        return np.array(rows, dtype=float).reshape(-1, 4)

    def following(self):
        return False  # it records the rows the others follow

    def observe(self, step):
        state = step.state2
        self.time.append(step.t)
        self.rows.append(step.rows)
        self.ball_z.append(step.position.copy())
        self.midpoint_z.append(step.midpoint.copy())
        self.ball_id.append(step.ball_id.copy())
        self.velocity_deviation.append(state.velocity_deviation)
        self.normal_load.append(np.where(state.loaded, state.batch.normal_load, np.nan))

    def moved(self, step):
        rows, events = step.rows, step.events
        for ident, when, out in ((events[0], events[1], self.exits),
                                 (events[2], events[3], self.entries)):
            for a, tr, j in zip(*np.nonzero(ident >= 0), strict=True):
                out.append((rows[a], tr, ident[a, tr, j], when[a, tr, j]))


class _Evaluation:
    """The loaded balls of a block's assemblies at given positions: carriage, then epsilon."""

    def __init__(self, config, block, pushes_unloaded=True):
        carriage = config.carriage
        self.config, self.block = config, block
        self.pushes_unloaded = pushes_unloaded
        self.tracks, self.balls = config.n_tracks, config.train.balls
        self.slots = slot_capacity(config)
        self.half_zone = 0.5 * config.train.loaded_zone_length
        lay = carriage.layout
        self.layout = CarriageLayout(lay.track_x, lay.track_y, lay.track_orientation,
                                     self.slots, lay.ball_pitch)
        try:  # the start of every Newton until an assembly has its own solution
            nominal = solve_carriage(lay, carriage.load, config.bearing,
                                     oversize=carriage.oversize)
            q0 = nominal.displacement if nominal.converged else np.zeros(5)
        except ValueError:
            q0 = np.zeros(5)
        self.start = np.tile(q0, (block.size, 1))
        # the latest solutions of each assembly and their times (newton_start)
        self.solution = np.full((_REMEMBERED, block.size, 5), np.nan)
        self.solved_at = np.full((_REMEMBERED, block.size), np.nan)
        # the time in which the balls move one pitch through the carriage (at v / 2) [s]
        self.period = 2.0 * lay.ball_pitch / config.motion.groove_velocity
        self.fixed = fixed_ball_values(config, block)  # transformed once, read every step
        self.resolve_seconds = 0.0

    def __call__(self, ball_z, ball_id, t, rows, remember=True):
        """Evaluate the balls in slots (m_k, T, S) of assemblies ``rows`` at time t [s].

        Returns (eps, ok, loaded, batch, state, unloaded): epsilon (NaN unless loaded and
        resolved), resolved (True where not loaded; an unloaded ball in the zone is accounted
        for, pushed along, unless ``pushes_unloaded`` is False), loaded, the carriage batch,
        the BallState of the loaded balls (flattened) and the unloaded balls in slots.
        ``remember`` False (a solve off the integration's steps: t (m_k,), one time per
        row): the Newton starts from each assembly's latest solution, which it leaves as
        it is, so the steps' solves do not change.
        """
        config, carriage = self.config, self.config.carriage
        shape = ball_z.shape
        loaded, z, rail = np.empty(shape, dtype=bool), np.empty(shape), np.empty(shape)
        shift = config.motion.groove_velocity * np.asarray(t, dtype=float)
        slot_inputs_kernel(kernel_array(ball_z).reshape(-1),
                           kernel_array(ball_id, np.int64).reshape(-1), self.half_zone,
                           float(shift) if shift.ndim == 0 else 0.0, loaded.reshape(-1),
                           z.reshape(-1), rail.reshape(-1))
        if shift.ndim:  # each row at its own time
            rail += shift.reshape((-1,) + (1,) * (rail.ndim - 1))
        # the values straight into the GrooveErrors fields (absent fields: 0)
        fields, columns = groove_error_buffers({s.source for s in config.tolerances}, shape)
        moving_ball_values(config, self.block, ball_id, rail, rows, self.fixed, columns)
        if carriage.end_relief_depth > 0:  # the carriage flanks TR, TL recede at the ends
            h = end_relief(z, config.train.loaded_zone_length, carriage.end_relief_depth,
                           carriage.end_relief_length)
            normal = fields.setdefault("arc_centre_offset_normal", np.zeros((z.size, 4)))
            normal[:, 2:4] += h.reshape(-1, 1)
        errors = GrooveErrors(**{k: v.reshape(shape + v.shape[1:]) for k, v in fields.items()})
        with serial_if_small(z.size):  # as evaluate_carriage (no effect on the results)
            batch = solve_carriage_batch(self.layout, carriage.load, config.bearing,
                                         oversize=carriage.preload_oversize,
                                         groove_errors=errors, ball_z=z, loaded=loaded,
                                         start=(self.newton_start(rows, t) if remember
                                                else self.start[rows]),
                                         tol=TRACK_TOLERANCE, ball_tol=TRACK_TOLERANCE)
        # a ball with less load than the solve resolves is unloaded (settle_unresolved_loads);
        # an assembly with a light contact is solved on to POLISH_TOLERANCE
        force, light = settle_and_find_light(batch.normal_force, loaded, TRACK_TOLERANCE,
                                             LIGHT_CONTACT)
        light &= batch.status == STATUS_CONVERGED
        if light.any():
            batch, force = self.polished(batch, force, light, errors, z, loaded)
        solved = batch.status == STATUS_CONVERGED
        if remember:
            self.remember(rows, t, batch, solved)
        # (TRACK_TOLERANCE bounds the polished assemblies' balance too)
        state = loaded_ball_velocities(config, loaded, batch.contact_angle_deviation, force,
                                       batch.ball_converged, solved, TRACK_TOLERANCE)
        eps, ok, unloaded = np.empty(shape), np.empty(shape, dtype=bool), np.empty(
            shape, dtype=bool)
        scatter_loaded_balls_kernel(loaded, state.velocity_deviation, state.valid,
                                    state.regime, BALL_UNLOADED, self.pushes_unloaded, eps, ok,
                                    unloaded)
        return eps, ok, loaded, batch, state, unloaded


    def polished(self, batch, force, light, errors, z, loaded):
        """``batch`` and its settled ``force`` with the assemblies ``light`` (m_k,) solved on
        from their solution to :data:`POLISH_TOLERANCE` (Notes of :data:`LIGHT_CONTACT`); an
        assembly whose polishing solve does not converge keeps its loose solution."""
        carriage, m = self.config.carriage, len(light)
        sub_errors = GrooveErrors(**{
            name: (value[light] if np.ndim(value) and np.shape(value)[0] == m else value)
            for name, value in ((n, getattr(errors, n)) for n in errors.__dataclass_fields__)})
        sub = solve_carriage_batch(self.layout, carriage.load, self.config.bearing,
                                   oversize=carriage.preload_oversize,
                                   groove_errors=sub_errors, ball_z=z[light],
                                   loaded=loaded[light], start=batch.displacement[light],
                                   tol=POLISH_TOLERANCE, ball_tol=POLISH_TOLERANCE)
        done = sub.status == STATUS_CONVERGED
        rows = np.flatnonzero(light)[done]
        fields = {}
        for name in batch.__dataclass_fields__:
            value = getattr(batch, name)
            if isinstance(value, np.ndarray):
                value = value.copy()
                value[rows] = getattr(sub, name)[done]
            fields[name] = value
        force = np.array(force)  # (a copy: it may be batch.normal_force)
        force[rows] = settle_unresolved_loads(sub.normal_force[done], loaded[rows],
                                              POLISH_TOLERANCE)
        return type(batch)(**fields), force

    def newton_start(self, rows, t):
        """Where the carriage Newton of assemblies ``rows`` starts at time t [s]: the
        assembly's own solution of one ball pitch earlier, when the solves are at least a
        quarter pitch apart; else its solution extrapolated linearly in time from its two
        latest ones, or its latest alone (the nominal solution before its first).

        Notes
        -----
        The carriage moves smoothly between two solves except when a ball enters or leaves
        the zone. A ball enters and one leaves every pitch of the balls' travel through the
        carriage (``period`` = 2 pitch / v), so at the automatic two steps per pitch
        (:func:`tolsim.study.pipeline.propagation_rules.time_steps`) an entry or exit falls
        between every two solves and the line through them helps nothing (3.0 joint Newton
        steps on average either way on ``configs/carriage_preload.toml``, session 12). One
        pitch earlier the balls held the same places, each shifted by one ball: only the
        rail errors under them and the sizes of the ball that entered and the one that left
        differ. Started there (the solve nearest to t - period, within period / 8), the
        Newton took 2.60 steps instead of 2.98 at the default tolerances and 2.10 instead of
        2.79 at 1e-8 (:data:`TRACK_TOLERANCE` then; the same study, 1 024 assemblies, seed
        12). With solves closer than a quarter pitch (an end relief, ``[contact]``) the line
        is kept: most pairs of solves have no entry between them, and measured in session 12
        it gave 2.74 steps instead of 3.0 at 20 steps per stroke.
        The Newton's convergence test is the same either way, so the solution changes only
        within its tolerance, and an assembly's start depends only on its own history (not on
        the batch, chunking or threads).
        """
        start = np.empty((len(rows), 5))
        newton_start_kernel(self.solution, self.solved_at, self.start, rows, float(t),
                            self.period, start)
        return start

    def remember(self, rows, t, batch, solved):
        """Keep the converged (``solved``) solutions of assemblies ``rows`` at time t [s]; an
        assembly that did not converge starts its next Newton from its latest solution."""
        remember_kernel(rows, float(t), batch.displacement, solved, self.start, self.solution,
                        self.solved_at)


def _initial_state(config, ball_z, loaded, batch, state):
    """The BallState of the initial balls (slots 0..n-1 at t = 0), shape (m, tracks * n),
    and the CarriageState of the t = 0 solve."""
    m, tracks, slots = ball_z.shape
    n = config.train.balls
    first = (m, tracks, n)
    out = (np.empty(first), np.empty(first, dtype=bool), np.empty(first, dtype=bool),
           np.empty(first, dtype=bool), np.empty(first + (4,)), np.empty(first + (4,)),
           np.empty(first, dtype=state.model.dtype), np.empty(first, dtype=state.regime.dtype))
    # outside the zone: lost (no contact with the grooves), its regime as ``lost``
    initial_balls_kernel(loaded, *(kernel_array(x, x.dtype) for x in (
        state.velocity_deviation, state.valid, state.converged, state.loss_of_contact,
        state.contact_angle_deviation, state.normal_force, state.model, state.regime)),
        MODEL_UNRESOLVED, BALL_UNRESOLVED, *out)
    eps, valid, converged, lost, dbeta, force, model, regime = (
        x.reshape((m, tracks * n) + x.shape[3:]) for x in out)
    balls = BallState(eps, valid, converged, lost, dbeta, force, model, state.resolve_seconds,
                      regime)
    stiffness = np.ascontiguousarray(np.diagonal(batch.stiffness, axis1=1, axis2=2))
    carriage = CarriageState(batch.displacement, stiffness, batch.status.astype(np.int8))
    return balls, carriage


class CarriageBalls:
    """The balls of the assemblies integrated in a step, in slots (m_k, tracks, slots):
    ``velocity_deviation`` epsilon (NaN unless loaded and resolved), ``valid`` (True where
    not loaded), ``loaded``; ``batch`` the carriage solve (None for balls carried from an
    earlier solve); ``balls`` the BallState of the loaded balls (flattened), given or made
    when first read (``balls`` a function); ``unloaded`` given or made from it."""

    def __init__(self, velocity_deviation, valid, loaded, batch, balls, unloaded=None):
        self.velocity_deviation, self.valid, self.loaded = velocity_deviation, valid, loaded
        self.batch, self._balls, self._unloaded = batch, balls, unloaded

    @property
    def balls(self) -> BallState:
        if callable(self._balls):
            self._balls = self._balls()
        return self._balls

    @property
    def unloaded(self) -> np.ndarray:
        """Balls in the zone without a loaded contact (pushed along), in slots."""
        if self._unloaded is None:
            out = np.zeros(self.loaded.shape, dtype=bool)
            out[self.loaded] = self.balls.unloaded
            self._unloaded = out
        return self._unloaded

    def without(self, slots):
        """These balls with those in ``slots`` (a mask) taken out, as empty slots."""
        keep = self.loaded & ~slots
        index = np.flatnonzero(keep[self.loaded])
        return CarriageBalls(np.where(slots, np.nan, self.velocity_deviation),
                             self.valid | slots, keep, self.batch,
                             lambda: self.balls.rows(index), self.unloaded & ~slots)


@dataclass
class CarriageStep(Step):
    """A :class:`tolsim.study.pipeline.propagation.Step` of the carriage frame: ``rows`` the
    assemblies integrated, ``ball_id`` their balls' ids (re-mapped in place by the frame's
    advance); after it, ``previous_id`` the ids before, ``overflow`` (m_k,) and ``events``
    (exit ids, exit times, entry ids, entry times) of :func:`advance_kernel`; ``closed``
    (m_k, T, S - 1) the time a pair closed in the previous step after an entry, NaN elsewhere
    (:func:`entry_shift_kernel`; None: none)."""

    rows: np.ndarray = None
    ball_id: np.ndarray = None
    midpoint: np.ndarray = None
    previous_id: np.ndarray = None
    overflow: np.ndarray = None
    events: list = None
    closed: np.ndarray = None


class CarriageFrame(AlongTrackFrame):
    """The carriage frame of :func:`first_contact_carriage_track` (its Notes): the balls in
    slots (size, tracks, slots) at carriage-frame positions z, moving at
    dz/dt = -(1 - epsilon) v / 2; the rows still followed, each evaluation one batched,
    warm-started carriage solve (:class:`_Evaluation`); exits and entries at the end of each
    step (:func:`advance_kernel`).

    ``initial_state``, ``initial_carriage``: the balls and the carriages at t = 0;
    ``resolve_seconds``: full-model re-solves after the start of the stroke [s]. An unloaded
    ball in the zone is pushed along (:func:`tolsim.study.pipeline.propagation.pushed_along`)
    and its pairs close as one (:func:`tolsim.study.pipeline.propagation.force_gaps`), unless
    ``pushes_unloaded`` is False: then it is unresolved.
    """

    pushes_unloaded = True
    #: The balls enter with the drawn gaps, in the midpoint solves from their entry and at
    #: their own epsilon from it (:func:`entering_by_kernel`, :func:`entry_shift_kernel`).
    draws_entries = True

    def __init__(self, config, block):
        self.config = config
        self.evaluation = _Evaluation(config, block, self.pushes_unloaded)
        self.tracks, self.balls, self.slots = (self.evaluation.tracks, self.evaluation.balls,
                                               self.evaluation.slots)
        self.half_zone = self.evaluation.half_zone
        self.v = config.motion.groove_velocity
        self.diameter = 2.0 * config.bearing.ball_radius
        m, tracks, n, slots = block.size, self.tracks, self.balls, self.slots
        capacity = entering_capacity(config)
        ball_z = np.full((m, tracks, slots), np.nan)
        ball_z[:, :, :n] = block.initial_position.reshape(m, tracks, n)
        super().__init__(block, ball_z)
        self.ball_id = np.full((m, tracks, slots), -1, dtype=np.int64)
        self.ball_id[:, :, :n] = np.arange(n)
        self.ball_ok = np.ones((m, tracks, slots), dtype=bool)  # resolved so far
        self.count = np.full((m, tracks), n, dtype=np.int64)
        self.entered = np.zeros((m, tracks), dtype=np.int64)
        self.entering_gap = np.ascontiguousarray(block.entering_gap.reshape(m, tracks,
                                                                            capacity))
        self.initial_state = self.initial_carriage = None
        self.resolve_seconds = 0.0
        self.rows = self.ids = None
        self.midpoint = self.last = self.fresh = self.carried = None
        # each slot's entry in the step before (its time, the ball ahead's epsilon)
        self.entry_time, self.entry_velocity = np.full(ball_z.shape, np.nan), np.zeros(
            ball_z.shape)

    def select(self, following):
        rows = np.flatnonzero(following)
        if rows.size == 0:
            return None
        self.rows, self.ids = rows, self.ball_id[rows]
        return self.position[rows]

    def evaluate(self, position, t):
        self.midpoint = position
        z, ids, entering = (self._entering(position) if self.draws_entries
                            else (position, self.ids, None))
        balls = CarriageBalls(*self.evaluation(z, ids, t, self.rows))
        self.resolve_seconds += balls.balls.resolve_seconds
        return balls if entering is None else balls.without(entering)

    def zone_baseline(self, ball_z, ball_id, t, rows, friction):
        """The baseline sum F_0 of each track's loaded zone (m_k T,) [N], the balls in slots
        (m_k, T, S) of assemblies ``rows`` at times t (m_k,) [s], solved off the steps (their
        Newton starts unchanged) with the coefficients of ``friction``
        (:class:`tolsim.study.pipeline.track_friction.TrackFriction`; NaN where a ball is
        not resolved): a window of the friction (Notes there, "Windows")."""
        balls = CarriageBalls(*self.evaluation(ball_z, ball_id, t, rows, remember=False))
        self.resolve_seconds += balls.balls.resolve_seconds
        loaded = balls.loaded.reshape(-1, self.slots)
        f0 = friction.coefficients(balls.balls, loaded)[..., _F0]
        return np.where(loaded, f0, 0.0).sum(axis=1)

    def _entering(self, position):
        """The slots at ``position`` (the midpoint) with the balls that have entered by then
        (:func:`entering_by_kernel`), and those (None: none)."""
        z, ids = np.empty_like(position), np.empty_like(self.ids)
        entering = np.empty(position.shape, dtype=bool)
        entering_by_kernel(position, self.ids, self.rows, self.count, self.entered,
                           self.entering_gap, self.half_zone, self.diameter, self.balls, z,
                           ids, entering)
        return (z, ids, entering) if entering.any() else (position, self.ids, None)

    def start(self, k, t, position):
        if k > 0:  # the previous midpoint's balls (Notes of first_contact_carriage_track)
            return self._carried()
        balls = CarriageBalls(*self.evaluation(position, self.ids, t, self.rows))
        self.initial_state, self.initial_carriage = _initial_state(
            self.config, position, balls.loaded, balls.batch, balls.balls)
        self.fresh = None
        return balls

    def _carried(self):
        """The previous step's midpoint balls in this step's slots, carried by id through the
        exits and entries (:func:`carry_slots_kernel`); an entered ball is ``fresh``."""
        last = self.last
        old_row = np.searchsorted(last.rows, self.rows)  # the rows followed only shrink
        if not np.array_equal(last.rows[np.minimum(old_row, len(last.rows) - 1)], self.rows):
            raise RuntimeError("carriage frame: a row is followed again after a step without it")
        shape, mid = self.ids.shape, last.state2
        loaded, valid, unloaded, fresh = (np.empty(shape, dtype=bool) for _ in range(4))
        eps, index = np.empty(shape), np.empty(shape, dtype=np.int64)
        carry_slots_kernel(last.previous_id, mid.loaded, mid.velocity_deviation, mid.valid,
                           mid.unloaded, old_row, self.ids, loaded, eps, valid, unloaded,
                           fresh, index)
        self.fresh = fresh
        balls = CarriageBalls(eps, valid, loaded, None,
                              lambda: mid.balls.rows(index[loaded]), unloaded)
        # which of the midpoint's loaded balls each slot holds (for a frame that keeps
        # per-ball values of the midpoint)
        self.carried = (balls, mid, index)
        return balls

    def _joined(self, state1, state2, take):
        """``state1`` with the balls that entered at the end of the previous step
        (``fresh``), those loaded at this step's midpoint (``take``, None: none), taken there,
        so that they are in the step's trains and checks as balls that were there at its
        start (:func:`joined_kernel`)."""
        if take is None:
            return state1
        shape = take.shape
        loaded, valid, unloaded = (np.empty(shape, dtype=bool) for _ in range(3))
        eps, src = np.empty(shape), np.empty(take.size, dtype=np.int64)
        flags = (kernel_array(x, np.bool_) for x in (take, state1.loaded, state2.loaded))
        src = src[:joined_kernel(*flags, *(kernel_array(x) for x in (
            state1.velocity_deviation, state2.velocity_deviation)), *(
            kernel_array(x, np.bool_) for x in (state1.valid, state2.valid, state1.unloaded,
                                                state2.unloaded)),
            loaded, eps, valid, unloaded, src)]
        return CarriageBalls(eps, valid, loaded, None,
                             lambda: concatenated_balls(state1.balls, state2.balls).rows(src),
                             unloaded)

    def predictor(self, state):
        unloaded = self.unloaded(state)
        if unloaded is None:
            return nan_to_num(state.velocity_deviation)
        return nan_to_num(self.pushed(state.velocity_deviation, unloaded, ~state.loaded))

    def move(self, position, w, h):
        position = kernel_array(position)
        out = np.empty(position.shape)
        carriage_motion_kernel(position.reshape(-1), kernel_array(w).reshape(-1), float(h),
                               float(self.v), out.reshape(-1))
        return out

    def velocity(self, state1, state2):
        # a ball outside the zone at the midpoint keeps epsilon_1
        unloaded = self.unloaded(state1, state2)
        if unloaded is None:
            out = np.empty(state2.loaded.shape)
            step_velocity_kernel(kernel_array(state2.loaded, np.bool_).reshape(-1),
                                 *(kernel_array(x).reshape(-1) for x in (
                                     state2.velocity_deviation, state1.velocity_deviation)),
                                 out.reshape(-1))
            return out
        eps = np.where(state2.loaded, state2.velocity_deviation, state1.velocity_deviation)
        return nan_to_num(self.pushed(eps, unloaded, ~(state1.loaded | state2.loaded)))

    def unloaded(self, state1, state2=None):
        """The unloaded balls in the zone of the step (at the midpoint, or at its start for a
        ball outside the zone there), None if there are none or they are not pushed."""
        if not self.pushes_unloaded:
            return None
        unloaded = state1.unloaded
        if state2 is not None:
            unloaded = np.where(state2.loaded, state2.unloaded, unloaded)
        return unloaded if unloaded.any() else None

    def pushed(self, eps, unloaded, edge):
        """epsilon in slots with the unloaded balls pushed along between their loaded
        neighbours at the start of the step (``edge``: outside the zone or empty)."""
        position = self.position[self.rows]
        with np.errstate(invalid="ignore"):
            gap = position[..., 1:] - position[..., :-1] - self.diameter
        return pushed_along(gap, eps, unloaded, edge)

    def step(self, k, t, dt, position, new, state1, state2):
        take = None if self.fresh is None else self.fresh & state2.loaded
        take = take if take is not None and take.any() else None
        state1 = self._joined(state1, state2, take)
        closed = None
        if self.draws_entries and take is not None:
            closed = np.empty(position.shape[:2] + (max(self.slots - 1, 0),))
            entry_shift_kernel(position, new, take, nan_to_num(state2.velocity_deviation),
                               self.entry_time, self.entry_velocity, self.rows, t,
                               self.diameter, 0.5 * self.v, closed)
        ok = self.ball_ok[self.rows] & state1.valid & state2.valid
        gap_old, gap_new = (gaps(x.reshape(-1, self.slots), self.diameter).reshape(
            x.shape[:-1] + (-1,)) for x in (position, new))
        unloaded = self.unloaded(state1, state2)
        if unloaded is not None:  # pairs with an unloaded ball close as one
            edge = ~(state1.loaded | state2.loaded)
            gap_old = force_gaps(gap_old, unloaded, edge, ok)
            gap_new = force_gaps(gap_new, unloaded, edge, ok)
        self.last = CarriageStep(k, t, dt, position, new, gap_old, gap_new, ok, state1,
                                 state2, rows=self.rows, ball_id=self.ids,
                                 midpoint=self.midpoint, closed=closed)
        return self.last

    def advance(self, step, new):
        # exits at the trailing end, entries at the leading end
        # (written back to the frame; the entry's time and the ball ahead's epsilon from
        # its travel: advance_frame_kernel)
        rows, z0, ids, ok = step.rows, step.position, step.ball_id, step.ball_ok
        step.previous_id = ids.copy()
        overflow = np.zeros(len(rows), dtype=bool)
        events = [np.empty(z0.shape, np.int64), np.empty(z0.shape),
                  np.empty(z0.shape, np.int64), np.empty(z0.shape)]
        advance_frame_kernel(rows, z0, kernel_array(new), ids, ok, self.count, self.entered,
                             self.entering_gap, self.half_zone, self.diameter, self.balls,
                             step.t, step.dt, 0.5 * self.v * step.dt, overflow, *events,
                             self.position, self.ball_id, self.ball_ok, self.entry_time,
                             self.entry_velocity)
        step.overflow, step.events = overflow, events


def count_unresolved_balls(unresolved, seen, step, searching):
    """Count the balls that make an assembly unresolved along the track, each once.

    Adds to ``unresolved`` (size,) [balls], for every row a of ``step`` with ``searching[a]``,
    the loaded balls unresolved at the step's midpoint evaluation (``state2``) that are not in
    ``seen`` (a set of (assembly, track, ball id), updated): each ball once, however many
    evaluations it is unresolved at. The balls unresolved at the start of the stroke
    (``state1`` of the first step) go into ``seen`` uncounted: the ball counters of the balls
    at t = 0 (static not converged, loss of contact, full model failed) have them. So a train
    that is unresolved because of a ball along the track (``train_valid`` False; an edge-case
    audit found 8 of 100 assemblies of ``configs/carriage_preload.toml`` without preload or
    load so, every ball counter at t = 0 zero) says why.
    """
    rows = step.rows
    if step.index == 0:
        for a, tr, j in np.argwhere(~step.state1.valid):
            seen.add((int(rows[a]), int(tr), int(step.ball_id[a, tr, j])))
    bad = ~step.state2.valid & np.asarray(searching, dtype=bool)[:, None, None]
    for a, tr, j in np.argwhere(bad):
        key = (int(rows[a]), int(tr), int(step.ball_id[a, tr, j]))
        if key not in seen:
            seen.add(key)
            unresolved[rows[a]] += 1


class CarriageFirstContact(StepObserver):
    """The first contact of each assembly in the carriage frame (``time``, ``pair``) and
    whether it is known (``valid``), as in the Notes of :func:`first_contact_carriage_track`:
    contacts between adjacent balls, both resolved so far and inside the zone at the time of
    contact; an assembly is no longer followed after its first contact (by this observer).
    ``unresolved`` (size,): the balls unresolved along the track before the first contact
    (:func:`count_unresolved_balls`)."""

    def __init__(self, frame):
        self.half_zone, self.slots, self.balls = frame.half_zone, frame.slots, frame.balls

    def begin(self, block, position):
        m = block.size
        self.time = np.full(m, np.inf)
        self.pair = np.full(m, -1, dtype=np.int64)
        self.valid = np.ones(m, dtype=bool)
        self.searching = None
        self.unresolved = np.zeros(m, dtype=np.int64)
        self._seen = set()

    def following(self):
        return ~np.isfinite(self.time)

    def observe(self, step):
        # contacts between adjacent loaded balls, both resolved so far, of the rows with no
        # first contact yet (``searching``; first_contact_kernel)
        rows = step.rows
        self.searching = np.empty(len(rows), dtype=bool)
        first_contact_kernel(rows, *(kernel_array(x) for x in (
            step.position, step.free, step.gap_old, step.gap_new)),
            *(kernel_array(x, np.bool_) for x in (step.ball_ok, step.state1.valid,
                                                   step.state2.valid)),
            self.half_zone, float(step.t), float(step.dt), self.balls, self.time, self.pair,
            self.valid, self.searching,
            np.empty((0, 0, 0)) if step.closed is None else step.closed)
        count_unresolved_balls(self.unresolved, self._seen, step, self.searching)

    def moved(self, step):
        searching = self.searching
        self.valid[step.rows[searching]] &= ~step.overflow[searching]


class CarriageTrains(StepObserver):
    """The loaded balls of each track as trains after contact (Notes of
    :func:`first_contact_carriage_track`, "After contact") through a
    :class:`tolsim.study.pipeline.track_friction.TrackFriction`; it follows every assembly
    over the whole stroke."""

    def __init__(self, frame, friction):
        self.friction, self.frame = friction, frame
        self.tracks, self.slots, self.balls = frame.tracks, frame.slots, frame.balls
        self.half_zone, self.v = frame.half_zone, frame.v

    def begin(self, block, position):
        # the closed pairs at t = 0
        m, tracks, n = block.size, self.tracks, self.balls
        closed = np.zeros((m, tracks, max(self.slots - 1, 0)), dtype=bool)
        closed[:, :, :n - 1] = block.initial_gap.reshape(m, tracks, n - 1) <= 0.0
        self.friction.begin(m, closed.reshape(m * tracks, -1), carriage_frame=True)

    def predict(self, state, w):
        friction, trains = self.friction, (-1, self.slots)
        loaded = state.loaded.reshape(trains)
        load = friction.coefficients(state.balls, loaded, friction.touching())
        eps = state.velocity_deviation
        unloaded = self.frame.unloaded(state)  # pushed along as without the trains (``w``)
        if unloaded is not None:
            eps = np.where(unloaded, w, eps)
        return np.nan_to_num(friction.predict(eps.reshape(trains), load, loaded, loaded)
                             ).reshape(w.shape)

    def advance(self, step, new):
        # the step of the trains: cluster rule, then projection; the trains: balls loaded
        # through the step (a ball leaving or entering the zone in it is in none, and drops
        # its contacts)
        friction, trains, v, dt = self.friction, (-1, self.slots), self.v, step.dt
        state1, state2, z0 = step.state1, step.state2, step.position
        loaded2 = state2.loaded.reshape(trains)
        with np.errstate(invalid="ignore"):
            member = (state1.loaded & state2.loaded
                      & (np.abs(step.free) <= self.half_zone)).reshape(trains)
        free = np.where(state2.loaded, state2.velocity_deviation,
                        np.nan_to_num(state1.velocity_deviation))  # NaN: unresolved
        unloaded = self.frame.unloaded(state1, state2)
        if unloaded is not None:  # pushed along, as in the free motion
            free = np.where(unloaded, self.frame.velocity(state1, state2), free)
        free = free.reshape(trains)
        w2 = np.nan_to_num(friction.velocity(free, friction.coefficients(state2.balls, loaded2),
                                             loaded2, member))
        before = friction.figures_before()
        end = friction.advance(z0.reshape(trains),
                               (z0 - dt * (1.0 - w2.reshape(z0.shape)) * 0.5 * v
                                ).reshape(trains), step.ball_id.reshape(trains)
                               ).reshape(z0.shape)
        self.windows(step, end, before)
        return end

    def windows(self, step, end, before):
        """The friction of a step in which a ball leaves or enters (Notes of
        :class:`tolsim.study.pipeline.track_friction.TrackFriction`, "Windows"): the rows'
        extremes and baseline sum as they were before the step (``before``: friction
        maximum, minimum, baseline sum), then each interval between those events solved at
        its own midpoint (:func:`window_points_kernel`; the balls moving linearly from the
        step's start to ``end``, those that have entered by then in the zone), without
        changing the steps' solves: its baseline with the step's increase, and its baseline
        over its share of the step (and, recorded, the step's friction over its intervals)."""
        frame, friction, rows = self.frame, self.friction, step.rows
        points, share = np.empty((2, len(rows), 4 * self.tracks + 2))
        count = np.empty(len(rows), dtype=np.int64)
        z0, end = kernel_array(step.position), kernel_array(end)
        window_points_kernel(rows, z0, end, frame.count, frame.entered, frame.entering_gap,
                             self.half_zone, frame.diameter, float(step.t), float(step.dt),
                             points, share, count)
        friction.reopen((rows[count > 0][:, None] * self.tracks + np.arange(self.tracks)
                         ).reshape(-1), before)
        for e in range(int(count.max(initial=0))):
            sel = np.flatnonzero(count > e)
            tau = points[sel, e]
            frac = ((tau - step.t) / step.dt)[:, None, None]
            at = z0[sel] + frac * (end[sel] - z0[sel])
            ids, entering = step.ball_id[sel], np.empty(at.shape, dtype=bool)
            z, slot_id = np.empty_like(at), np.empty_like(ids)
            entering_by_kernel(at, ids, rows[sel], frame.count, frame.entered,
                               frame.entering_gap, self.half_zone, frame.diameter, self.balls,
                               z, slot_id, entering)
            friction.window((rows[sel][:, None] * self.tracks + np.arange(self.tracks)
                             ).reshape(-1), frame.zone_baseline(z, slot_id, tau, rows[sel],
                                                                friction),
                            np.repeat(share[sel, e], self.tracks))
        friction.close_windows()

    def moved(self, step):
        self.friction.carry(step.previous_id, step.ball_id)
        self.friction.stop(np.repeat(step.overflow, self.tracks))


def first_contact_carriage_track(config, block, trace: TrackTrace | None = None, *,
                                 friction=None, unresolved=None):
    """First contact of a block's carriage assemblies, balls rolling through the carriage.

    Parameters
    ----------
    config : StudyConfig
        With ``[carriage]`` and ``propagation = "along_track"``.
    block : tolsim.study.sampling.Block
        With the entering balls' draws (:func:`tolsim.study.sampling.sample_block`).
    trace : TrackTrace, optional
        Filled with the positions, epsilon and events of every step.
    friction : tolsim.study.pipeline.track_friction.TrackFriction, optional
        With it (a study with ``[contact]``) every assembly is followed over the whole stroke
        and its loaded balls move as trains after they touch (Notes, "After contact"); the friction
        figures are accumulated in ``friction``. The first contact and ``train_valid`` are the same
        as without it.
    unresolved : ndarray of int64 (size,), optional
        Filled with the balls of each assembly unresolved along the track before its first
        contact and not at t = 0 (:func:`count_unresolved_balls`): with those at t = 0, why
        ``train_valid`` is False unless the slots or the entering balls ran out.

    Returns
    -------
    time : ndarray (size,)
        First contact [s], inf if none within the horizon.
    pair : ndarray of int (size,)
        track * (balls - 1) + j, j the position of the pair's trailing ball in the zone
        counted from the trailing end (at most balls - 2: while a ball has entered and none
        has left yet the zone holds more balls than the train, and its leading pairs share
        the index balls - 2); -1 if none.
    train_valid : ndarray of bool (size,)
        False where a loaded ball was unresolved before the first contact, or the drawn
        entering balls or the slots ran out (Notes).
    resolve_seconds : float
        Full-model re-solves after the start of the stroke [s] (those at t = 0 are in the
        BallState).
    state : BallState
        The initial balls at t = 0, shape (size, tracks * balls), for the epsilon statistics.
    carriage : tolsim.study.pipeline.carriage.CarriageState
        The carriages at t = 0.

    Notes
    -----
    **Frames and sign convention.**
    Rail frame s (fixed) and carriage frame z = s - v t: the carriage's reference point is at
    s = v t, so at t = 0 the two coincide. The carriage moves towards +z; its leading end is at
    z = +L/2 and its trailing end at -L/2, L = ``train.loaded_zone_length`` (ball 0, the
    trailing ball, has the smallest z).

    A ball's centre moves along the rail at v_B = (1 + epsilon) v / 2 ([Lin2018] Eq. 23; the
    convention of :mod:`tolsim.study.pipeline.propagation`, whose rail positions advance at that
    speed), so relative to the carriage

        dz/dt = v_B - v = -(1 - epsilon) v / 2.

    Every ball drifts backwards through the carriage at about v/2; a ball with a larger epsilon
    (faster along the rail) drifts more slowly. (Written as -(1 + epsilon') v / 2, epsilon' =
    -epsilon.) The gap of pair j (trailing ball j, leading ball j + 1) changes at dg_j/dt =
    -(epsilon_j - epsilon_{j+1}) v / 2 in either frame: it closes when the trailing ball is the
    faster, as in the constant propagation.

    **Loaded zone, exit and entry.**
    A ball is loaded only while its centre is inside the loaded zone [-L/2, L/2]: the carriage is
    solved with the balls inside, each at its own z (:func:`tolsim.physics.carriage.
    solve_carriage_batch` with ``ball_z`` and ``loaded``; a ball outside carries nothing).

    * *Exit.* Drifting backwards, a ball leaves at the trailing end: when its centre passes
      -L/2 (the time interpolated linearly within the step, exact for a constant epsilon).
    * *Entry.* A new ball enters at the leading end with a gap g_k drawn from the train's gap
      distribution (draw 5 of :mod:`tolsim.study.sampling`, one independent gap per entering
      ball, in order of entry): the k-th ball to enter a track enters when the ball ahead of it
      (the zone's leading ball) has drifted to L/2 - D - g_k, so that it sits at L/2 with the gap
      g_k: as soon as there is room for it. Its entry time is interpolated as the exit's. The
      carriage solve at a step's midpoint holds the balls that have entered by then (z_ahead +
      D + g_k <= L/2 at the midpoint, :func:`entering_by_kernel`), as it drops the balls that
      have left, so the carriage sees an entry at the first midpoint after it; their own
      epsilon there is not used (the step's balls leave them out). At the end of the step the
      entering ball is placed at z_ahead + D + g_k, having moved with the ball ahead since its
      entry; in the next step, once its own epsilon is known at the midpoint, it is moved by
      tau (epsilon_k - epsilon_ahead) v / 2 (tau the time since its entry,
      :func:`entry_shift_kernel`), so that it moves at its own epsilon from its entry, to
      O(tau dt); a pair that this closes closed at the time interpolated linearly since the
      entry, its first contact then. Without either the step's error of
      the time to first contact falls at first order (Notes of
      :func:`.propagation_rules.time_steps`). In a zone longer than the initial train the
      balls enter one by one at the start of a step in which there is room, each at L/2.
      It brings its own ``ball`` tolerances (draw 5), its track's rail and carriage values, and
      reads the rail fields at its rail position.

    *The return path.* A ball that has left the zone runs through the end cap's turnaround and
    the return channel back to the leading end. There it is unloaded: no groove carries load on
    it, so it exerts nothing on the carriage and has no velocity deviation of its own (it is
    pushed along by the balls behind). Its contacts with other balls are contacts of free balls,
    which can spin and give way, not the contacts of loaded balls whose opposed surface
    velocities cost friction ([Lin2018] Sec. 3.2): they are not counted. Its order in the
    circuit is preserved (balls cannot pass each other in a channel), but it is not tracked
    further within the horizon: the balls that enter are new, independent draws. A ball could
    only come round again if the balls' drift over the stroke, about stroke/2, exceeds the
    length of the return path and the turnarounds (more than L): for such long strokes the
    re-entering balls are modelled as independent of the ones that left. The ones that left
    bring back the same tolerances (and so the same neighbours' epsilon differences) in their
    order; independent balls give every new pair a fresh epsilon difference, more chances of a
    fast-closing pair, so P(contact) is if anything overestimated (conservative). With
    stroke/2 <= L (``configs/carriage_preload.toml``: 50 mm against 120.6 mm) no ball comes
    round and the question does not arise.

    **Integration.**
    The one along-track integration of single trains,
    :func:`tolsim.study.pipeline.propagation.integrate`, in the :class:`CarriageFrame`, with
    the first contact (:class:`CarriageFirstContact`), the trains after contact
    (:class:`CarriageTrains`) and the ``trace`` as its observers: the explicit midpoint rule over
    ``study.time_steps`` steps of dt: the positions at the midpoint with epsilon_1, epsilon_2
    with the carriage solved there (a ball outside the zone at the midpoint keeps epsilon_1),
    then the step with epsilon_2. epsilon_1 is the previous step's epsilon_2, each ball's own,
    carried through the exits and entries by its id (:func:`carry_slots_kernel`; at t = 0 the
    carriage solved at the start), as for free balls (Notes of
    :func:`tolsim.study.pipeline.propagation.integrate_along_track`): it only places the
    midpoint, half a step early, so the step stays second order between the exits and entries
    and costs one carriage solve instead of two. A ball that entered at the end of the previous
    step has no epsilon_1: it moves to the midpoint at epsilon = 0 and then takes its midpoint
    state for the step's start as well, so that it is in the step's trains and checks as when
    the start was solved (:func:`.propagation_rules.time_steps` gives the step's error). Each
    evaluation is one batched carriage solve over the assemblies still being followed, and
    every Newton starts from the assembly's own solution of its previous evaluation (so an
    assembly's results depend only on its own history, not on the batch, chunking or
    threads). Exits and entries are applied at the end of each step (the entering balls'
    motion and the midpoint solves from their entry: "Entry" above). Contacts are counted
    between loaded balls: adjacent balls of a track (in z order), both inside the zone at the
    time of contact and both resolved at every evaluation so far; the contact time is the
    linear interpolation of the gap within the step. An assembly's first contact is the
    earliest over its tracks; it is not followed after it.

    Unresolved balls (no velocity model takes them, :mod:`tolsim.study.pipeline.evaluate`; every
    loaded ball of an assembly whose carriage did not converge or lifted off) are treated as in the
    single-train propagation: such a ball moves at the nominal -v/2 (epsilon = 0), closes no gap,
    and its assembly is invalid (``train_valid`` False) if a loaded ball was unresolved at any
    evaluation before the assembly's first contact. A ball in the loaded zone whose four contacts
    have opened (under an end relief deeper than the ball's approach, or with clearance) is
    unloaded (issue 25): it has no epsilon of its own and is pushed along between its loaded
    neighbours (:func:`tolsim.study.pipeline.propagation.pushed_along`; with one loaded
    neighbour in the zone it moves with it), and its pairs count as one contact, when the gaps
    from one loaded neighbour to the other have all closed: the first contact that carries
    force (:func:`tolsim.study.pipeline.propagation.force_gaps`). An assembly is invalid, too,
    if it needs more entering balls than were drawn (:func:`tolsim.study.sampling.
    entering_capacity`) or more balls in its zone than it has slots (:func:`slot_capacity`).

    **After contact.**
    With ``[contact]`` (a :class:`tolsim.study.pipeline.track_friction.TrackFriction` passed as
    ``friction``)
    every assembly is followed over the whole stroke, and the loaded balls of each track move as
    a train (:mod:`tolsim.physics.trains`, "Varying epsilon"): at every step the cluster rule on
    the closed pairs with each ball's epsilon and creep coefficients from its own loaded state
    (the carriage solved at the balls' positions), then the projection of the closing gaps. A
    ball belongs to its track's train for a step when it is in the zone at the step's start,
    midpoint and (free motion) end, so a ball leaving at the trailing end drops its contacts in
    the step in which it leaves, and an entering ball joins from the next step with its drawn
    gap open; the pair flags follow the balls through the exits and entries
    (:func:`carry_pairs_kernel`). Unloaded balls are in no train and pass through as above. The
    first contact, its pair and ``train_valid`` are located on the free motion of each step and
    counted only up to the first contact, so they are those of the run without ``[contact]``,
    bit for bit. The friction figures: Notes of
    :class:`tolsim.study.pipeline.track_friction.TrackFriction`.

    Cost: one batched carriage solve per step (each about 10 us of CPU per assembly of
    ``configs/carriage_preload.toml``, 2 x 13 ball slots) plus the velocity model of the loaded
    balls and the bookkeeping; an assembly is followed until its first contact (with
    ``[contact]``: over the whole stroke, plus the creep coefficients of its loaded balls).
    ``benchmarks/bench_carriage.py --along-track`` measures the study path.

    The balls at t = 0 are the block's trains at their sampled positions (each train's centroid
    at z = 0), not the nominal slots z_j of the constant propagation. A ball of a train longer
    than the zone that starts outside it is unloaded; in the t = 0 ball statistics it counts as a
    ball that lost contact.
    """
    if config.carriage is None or config.study.propagation != "along_track":
        raise ValueError("first_contact_carriage_track needs a config with [carriage] and "
                         "propagation = 'along_track'")
    if block.entering_gap is None:
        raise ValueError("the block holds no entering balls: draw it with sample_block from "
                         "a config with [carriage] and propagation = 'along_track'")
    frame = CarriageFrame(config, block)
    first = CarriageFirstContact(frame)
    observers = [first]
    if friction is not None:  # every assembly followed over the stroke, trains after contact
        observers.append(CarriageTrains(frame, friction))
    if trace is not None:
        observers.append(trace)
    integrate(config, frame, observers)
    if unresolved is not None:
        unresolved[:] = first.unresolved
    return (first.time, first.pair, first.valid, frame.resolve_seconds, frame.initial_state,
            frame.initial_carriage)


__all__ = ["CarriageBalls", "CarriageFirstContact", "CarriageFrame", "CarriageStep",
           "CarriageTrains", "TrackTrace", "count_unresolved_balls", "first_contact_carriage_track",
           "slot_capacity"]
