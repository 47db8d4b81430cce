"""Ball-to-ball contact in a track: propagation of ball positions ([Lin2018] Sec. 3.2).

Balls of one track are numbered from the trailing end (ball 0) to the leading end; the top
groove moves at +v along z and a ball's centre at v_B = (1 + epsilon) v / 2. Pair j is the
trailing ball j and the leading ball j + 1, with gap g_j = z_{j+1} - z_j - 2 R_B. The pair
touches when the gap closes.

(a) ``constant``: epsilon constant per ball over the horizon (the paper's Fig. 9). The gap
    closes at dg_j/dt = -(eps_j - eps_{j+1}) v / 2, so pair j touches at
    t_j = g_j / ((eps_j - eps_{j+1}) v / 2) when eps_j > eps_{j+1}; the first contact of the
    train is min_j t_j (no other ball can touch before an adjacent pair does).
(b) ``along_track``: epsilon of each ball is re-evaluated as it rolls past rail-side errors
    (rail random fields, read at the ball's rail position) and through the carriage's load
    distribution (read at its position in the carriage), integrated with the explicit
    midpoint rule; a contact event is located by linear interpolation of the gap within the
    step in which it changes sign (exact for piecewise-constant epsilon). One loop,
    :func:`integrate`, steps every along-track propagation: a frame says how its balls are
    evaluated and move (:class:`FreeBalls` here, the carriage's in
    :mod:`tolsim.study.pipeline.carriage_track`), observers what is recorded or changed.

Unresolved balls (epsilon NaN: no model could solve them, :mod:`tolsim.study.pipeline.evaluate`)
never
close a gap: a contact is reported only for a pair whose two balls are resolved (in mode (b):
at every evaluation so far, since an unresolved step leaves the ball's position unknown from
then on). A reported contact is therefore certain; whether the train's first contact is
known, or whether it touches at all when no resolved pair does, is for the statistics to
bound (:mod:`tolsim.study.statistics.accumulator`).

Unloaded balls (no loaded contact, issue 25) have no epsilon of their own: they are pushed
along by their neighbours and carry no force until a gap on each side has closed. Both modes
give them the epsilon that closes all the gaps between their loaded neighbours at once
(:func:`pushed_velocity_deviation`; mode (b) at every evaluation, :func:`pushed_along`), and
mode (b) locates a contact on the gap that carries force, the sum of the gaps between the
loaded neighbours (:func:`force_gaps`), so the first contact either reports is the first that
carries force, and mode (b) reproduces mode (a) when epsilon is constant.

Travel to contact is the carriage travel v t [m].

After contact (a study with ``[contact]``, issue 13): mode (a) leaves the trains to the
event-driven solution of :mod:`tolsim.physics.trains`; mode (b) follows them inside its own
integration when it is given a :class:`tolsim.study.pipeline.track_friction.TrackFriction` (the
step rule
of :mod:`tolsim.physics.trains`, "Varying epsilon"). The first contact is still located on
each step's free motion, so it is the same with and without ``[contact]``.
"""

from dataclasses import dataclass

import numpy as np
from numba import prange

from tolsim._jit import jit, kernel_array, pjit
from tolsim.study.pipeline.evaluate import evaluate_balls_at, serial_if_small
from tolsim.study.pipeline.frame_kernels import (
    first_contact_kernel,
    free_motion_kernel,
    gaps_kernel,
)
from tolsim.study.pipeline.propagation_rules import time_steps
from tolsim.study.sampling import error_values


@pjit
def constant_contact_kernel(gap, velocity_deviation, half_speed, horizon, out_time, out_pair):
    """Mode (a): first contact time per train (inf and -1 when none within the horizon)."""
    for m in prange(gap.shape[0]):
        best = np.inf
        pair = -1
        for j in range(gap.shape[1]):
            rate = (velocity_deviation[m, j] - velocity_deviation[m, j + 1]) * half_speed
            if rate > 0.0:
                t = gap[m, j] / rate
                if t < best:
                    best = t
                    pair = j
        if best <= horizon:
            out_time[m] = best
            out_pair[m] = pair
        else:
            out_time[m] = np.inf
            out_pair[m] = -1


def first_contact_constant(initial_gap, velocity_deviation, groove_velocity, horizon):
    """First ball-to-ball contact of trains with constant epsilon per ball (mode a).

    Parameters
    ----------
    initial_gap : array_like, shape (m, balls - 1)
        Gaps between adjacent balls at t = 0 [m], >= 0.
    velocity_deviation : array_like, shape (m, balls)
        epsilon per ball [-], ball 0 trailing; NaN balls never close a gap.
    groove_velocity : float
        v [m/s], > 0.
    horizon : float
        Duration considered [s], > 0.

    Returns
    -------
    time : ndarray, shape (m,)
        Time of the first contact [s], inf if none within the horizon.
    pair : ndarray of int, shape (m,)
        Trailing ball of the touching pair, -1 if none.
    """
    gap = np.ascontiguousarray(initial_gap, dtype=np.float64)
    eps = np.ascontiguousarray(velocity_deviation, dtype=np.float64)
    if gap.ndim != 2 or eps.ndim != 2 or eps.shape != (gap.shape[0], gap.shape[1] + 1):
        raise ValueError(f"initial_gap {gap.shape} and velocity_deviation {eps.shape} must "
                         "have shapes (m, balls - 1) and (m, balls)")
    if np.any(gap < 0) or not np.all(np.isfinite(gap)):
        raise ValueError("initial_gap must be finite and >= 0")
    if not (np.isfinite(groove_velocity) and groove_velocity > 0):
        raise ValueError(f"groove_velocity = {groove_velocity!r} must be > 0")
    if not horizon > 0:
        raise ValueError(f"horizon = {horizon!r} must be > 0")
    time = np.empty(len(gap))
    pair = np.empty(len(gap), dtype=np.int64)
    constant_contact_kernel(gap, eps, 0.5 * groove_velocity, float(horizon), time, pair)
    return time, pair


@pjit
def pushed_kernel(gap, eps, unloaded, edge, out):
    """Kernel of :func:`pushed_velocity_deviation` on (trains, balls) rows; a ball flagged in
    ``edge`` (outside the loaded zone, an empty slot) ends a run as the end of the train."""
    m, n = eps.shape
    for t in prange(m):
        for i in range(n):
            out[t, i] = eps[t, i]
        i = 0
        while i < n:
            if not unloaded[t, i]:
                i += 1
                continue
            last = i  # the run of unloaded balls i..last
            while last + 1 < n and unloaded[t, last + 1]:
                last += 1
            before = i - 1
            after = last + 1
            if before >= 0 and edge[t, before]:
                before = -1
            if after < n and edge[t, after]:
                after = n
            if before < 0 and after >= n:
                for k in range(i, last + 1):
                    out[t, k] = 0.0
            elif before < 0 or after >= n:
                side = after if before < 0 else before
                for k in range(i, last + 1):
                    out[t, k] = eps[t, side]
            else:
                total = 0.0
                for j in range(before, last + 1):
                    total += gap[t, j]
                run = 0.0
                for k in range(i, last + 1):
                    run += gap[t, k - 1]
                    f = run / total if total > 0.0 else (k - before) / (after - before)
                    out[t, k] = eps[t, before] + f * (eps[t, after] - eps[t, before])
            i = last + 1


def pushed_velocity_deviation(initial_gap, velocity_deviation, unloaded, tracks=1):
    """epsilon of the balls with those of unloaded balls filled in (``constant``, issue 25).

    Parameters
    ----------
    initial_gap : array_like, shape (m, tracks * (balls - 1))
        Gaps [m], track by track.
    velocity_deviation : array_like, shape (m, tracks * balls)
        epsilon per ball [-] (anything at the unloaded balls).
    unloaded : array_like of bool, shape (m, tracks * balls)
    tracks : int

    Returns
    -------
    ndarray, shape (m, tracks * balls)
        epsilon, with each unloaded ball's replaced as in the Notes.

    Notes
    -----
    An unloaded ball has no contact force, so no friction: it is pushed along by a neighbour
    without force. A run of unloaded balls k..l between loaded balls a = k - 1 and b = l + 1
    carries force only once all the gaps g_a..g_l between a and b have closed, at
    t = sum g / ((eps_a - eps_b) v / 2) when eps_a > eps_b, never otherwise. Giving ball
    i of the run eps_a + (eps_b - eps_a) G_i / G, G_i = g_a + ... + g_{i-1} the gaps from a to
    i and G their sum over the run, closes every one of those gaps at exactly that time (each
    gap closes at rate (eps_b - eps_a) g_j / G), so the constant propagation's first contact
    is the first contact that carries force. A run at the end of a train (one loaded
    neighbour) moves with that neighbour and never carries force; a train without a loaded
    ball keeps eps = 0 (nothing moves it). A NaN neighbour (an unresolved ball) gives NaN.
    """
    eps = np.ascontiguousarray(velocity_deviation, dtype=np.float64)
    m = eps.shape[0]
    balls = eps.shape[1] // tracks
    gap = np.ascontiguousarray(np.asarray(initial_gap, dtype=np.float64).reshape(
        m * tracks, max(balls - 1, 0)))
    flags = np.ascontiguousarray(np.asarray(unloaded, dtype=np.bool_).reshape(m * tracks, balls))
    out = np.empty((m * tracks, balls))
    pushed_kernel(gap, eps.reshape(m * tracks, balls), flags, np.zeros_like(flags), out)
    return out.reshape(eps.shape)


def pushed_along(gap, eps, unloaded, edge=None):
    """epsilon with the unloaded balls' filled in, at one evaluation of mode (b).

    Parameters
    ----------
    gap : ndarray, shape (..., balls - 1)
        The gaps at the start of the step [m] (NaN next to an empty slot).
    eps : ndarray, shape (..., balls)
        epsilon per ball [-] (anything at the unloaded balls).
    unloaded : ndarray of bool, shape (..., balls)
    edge : ndarray of bool, shape (..., balls), optional
        Balls that end a run like the end of the train: outside the loaded zone or an empty
        slot (a carriage's slots).

    Returns
    -------
    ndarray, shape (..., balls)
        ``eps`` itself when no ball is unloaded, else a copy with each unloaded ball's epsilon
        as :func:`pushed_velocity_deviation`.

    Notes
    -----
    An unloaded ball has no contact force, so nothing fixes its speed: every speed is in
    equilibrium, and the model leaves its free motion open. Its loaded neighbours a and b do not
    feel it (it carries no force), so the first contact that carries force, when the gaps from a
    to b have all closed, does not depend on that choice (:func:`force_gaps`); only where the
    unloaded ball is, which decides when it is loaded again, does. The choice here is the
    constant propagation's: ball i of a run between a and b moves at
    eps_a + (eps_b - eps_a) G_i / G with the gaps of the start of the step. Every gap of the
    run then closes at a rate in proportion to its size, so the shares G_i / G stay as they
    are (the midpoint's gaps give the same epsilon): the unloaded balls keep their places
    between their loaded neighbours, touch neither before the run closes, and a ball already
    touching a neighbour (G_i = 0 or G) moves with it, pushed. A run with one loaded
    neighbour moves with it; one with none at 0. In the limit of constant epsilon this is
    the motion of the constant propagation, step by step.
    """
    if not np.any(unloaded):
        return eps
    shape = np.shape(eps)
    n = shape[-1]
    flags = np.ascontiguousarray(np.reshape(unloaded, (-1, n)), dtype=np.bool_)
    ends = (np.zeros_like(flags) if edge is None
            else np.ascontiguousarray(np.reshape(edge, (-1, n)), dtype=np.bool_))
    out = np.empty(flags.shape)
    pushed_kernel(np.ascontiguousarray(np.reshape(gap, (-1, max(n - 1, 0))), dtype=np.float64),
                  np.ascontiguousarray(np.reshape(eps, (-1, n)), dtype=np.float64), flags,
                  ends, out)
    return out.reshape(shape)


@jit
def force_gap_kernel(gap, unloaded, edge, ok, out):
    """Kernel of :func:`force_gaps` on (trains, balls) rows."""
    m, n = unloaded.shape
    for t in range(m):
        for j in range(n - 1):
            out[t, j] = gap[t, j]
        i = 0
        while i < n:
            if not unloaded[t, i]:
                i += 1
                continue
            last = i  # the run of unloaded balls i..last
            while last + 1 < n and unloaded[t, last + 1]:
                last += 1
            before = i - 1
            after = last + 1
            value = np.inf  # a run at an end of the train never carries force
            if before >= 0 and after < n and not edge[t, before] and not edge[t, after]:
                value = 0.0
                for j in range(before, after):
                    value += gap[t, j]
                for k in range(before, after + 1):
                    if not ok[t, k]:
                        value = np.nan
            for j in range(max(before, 0), min(after, n - 1)):
                out[t, j] = value
            i = last + 1


def force_gaps(gap, unloaded, edge=None, ok=None):
    """The gaps whose closing carries force: those of the pairs with an unloaded ball replaced
    by the sum of the gaps between its loaded neighbours.

    Parameters
    ----------
    gap : ndarray, shape (..., balls - 1)
        Gaps [m].
    unloaded : ndarray of bool, shape (..., balls)
    edge : ndarray of bool, shape (..., balls), optional
        As :func:`pushed_along`.
    ok : ndarray of bool, shape (..., balls), optional
        Resolved so far; a run with a ball that is not gets NaN (never closes).

    Returns
    -------
    ndarray, shape (..., balls - 1)
        ``gap`` itself when no ball is unloaded; else a copy in which every pair of a run of
        unloaded balls between loaded balls a and b holds g_a + ... + g_{b-1} (they close
        together, when a and b would touch with the run in between: the first contact that
        carries force), and every pair of a run at an end of the train (one loaded neighbour
        or none, or an ``edge`` ball) inf (never carries force).
    """
    if not np.any(unloaded):
        return gap
    shape = np.shape(gap)
    n = np.shape(unloaded)[-1]
    flags = np.ascontiguousarray(np.reshape(unloaded, (-1, n)), dtype=np.bool_)
    ends = (np.zeros_like(flags) if edge is None
            else np.ascontiguousarray(np.reshape(edge, (-1, n)), dtype=np.bool_))
    good = (np.ones_like(flags) if ok is None
            else np.ascontiguousarray(np.reshape(ok, (-1, n)), dtype=np.bool_))
    out = np.empty((flags.shape[0], max(n - 1, 0)))
    force_gap_kernel(np.ascontiguousarray(np.reshape(gap, out.shape), dtype=np.float64), flags,
                     ends, good, out)
    return out.reshape(shape)


def first_contact_tracks(initial_gap, velocity_deviation, groove_velocity, horizon, tracks=1):
    """First contact of assemblies of ``tracks`` trains each (constant epsilon).

    Each train runs alone (:func:`first_contact_constant`); an assembly's first contact is
    the earliest of its trains'.

    Parameters
    ----------
    initial_gap : array_like, shape (m, tracks * (balls - 1))
        Gaps [m], track by track.
    velocity_deviation : array_like, shape (m, tracks * balls)
        epsilon per ball [-], track by track.
    groove_velocity, horizon : float
        As :func:`first_contact_constant`.
    tracks : int
        Trains per assembly.

    Returns
    -------
    time : ndarray, shape (m,)
        [s], inf if no train touches within the horizon.
    pair : ndarray of int, shape (m,)
        track * (balls - 1) + the trailing ball of the first touching pair; -1 if none.
    """
    if tracks == 1:
        return first_contact_constant(initial_gap, velocity_deviation, groove_velocity,
                                      horizon)
    eps = np.asarray(velocity_deviation)
    m = eps.shape[0]
    balls = eps.shape[1] // tracks
    time, pair = first_contact_constant(
        np.asarray(initial_gap).reshape(m * tracks, balls - 1), eps.reshape(m * tracks, balls),
        groove_velocity, horizon)
    time, pair = time.reshape(m, tracks), pair.reshape(m, tracks)
    first = np.argmin(time, axis=1)  # the first track on ties
    rows = np.arange(m)
    t = time[rows, first]
    return t, np.where(np.isfinite(t), first * (balls - 1) + pair[rows, first], -1)


def free_motion(position, w, h, v):
    """Free balls' positions after h [s] at epsilon ``w`` (NaN: nominal) [m]:
    z + h (1 + epsilon) v / 2 (:func:`~tolsim.study.pipeline.frame_kernels.free_motion_kernel`);
    ``position``, ``w`` of one shape, v [m/s]."""
    position = kernel_array(position)
    out = np.empty(position.shape)
    free_motion_kernel(position.reshape(-1), kernel_array(w).reshape(-1), float(h), float(v),
                       out.reshape(-1))
    return out


def gaps(position, diameter):
    """The gaps between adjacent balls of (m, balls) centres [m] (``np.diff`` less the
    diameter, :func:`~tolsim.study.pipeline.frame_kernels.gaps_kernel`)."""
    position = kernel_array(position)
    out = np.empty((position.shape[0], max(position.shape[1] - 1, 0)))
    gaps_kernel(position, float(diameter), out)
    return out


@dataclass
class Step:
    """One midpoint step of :func:`integrate`, as its observers see it.

    ``position`` and ``free``: the positions at the start of the step and at its end on the
    free motion (each ball at its own epsilon) [m], in the frame's shape ((m, balls) rail
    positions for free balls); ``gap_old``, ``gap_new``: the pairs' gaps there [m] (along
    the last axis), those of pairs with an unloaded ball the gaps that carry force
    (:func:`force_gaps`); ``ball_ok``: resolved at every evaluation so far; ``state1``, ``state2``:
    the balls of the predictor (the frame's :meth:`AlongTrackFrame.start`: the previous
    midpoint's, at t = 0 those at the start) and at the midpoint. ``pair_slopes``: what an
    observer asks of a circuit frame's step (:meth:`StepObserver.observe`; the friction
    slopes of :func:`tolsim.physics.circuit.step`), None by default.
    """

    index: int
    t: float
    dt: float
    position: np.ndarray
    free: np.ndarray
    gap_old: np.ndarray
    gap_new: np.ndarray
    ball_ok: np.ndarray
    state1: object
    state2: object
    pair_slopes: object = None


class StepObserver:
    """What :func:`integrate` calls at every step (each method may be left out: the base class
    does nothing)."""

    def begin(self, block, position):
        """Before the first step: the block and its balls' positions at t = 0 [m] (those of
        the frame: rail positions (m, balls) for free balls, carriage-frame slots
        (m, tracks, slots) for a carriage)."""

    def following(self):
        """The rows (assemblies) it still needs integrated: bool (size,), or True for all."""
        return True

    def predict(self, state, w):
        """The predictor's epsilon (m, balls) from the balls ``state`` at the start of the
        step; ``w`` the epsilon so far (the free one)."""
        return w

    def observe(self, step: Step):
        """After the free motion of a step (:class:`Step`)."""

    def advance(self, step: Step, new):
        """The positions at the end of the step (m, balls) [m]; ``new`` those so far (the
        free motion)."""
        return new

    def moved(self, step: Step):
        """After the frame has moved its balls to the end of the step (a carriage frame has
        then re-mapped its slots, the exits and entries in ``step``)."""


class AlongTrackFrame:
    """What one along-track propagation provides to :func:`integrate`: its balls, how they
    are evaluated and how they move. The base class holds the block and the positions.

    ``position``: every row's positions at the start of the next step [m].
    """

    def __init__(self, block, position):
        self.block = block
        self.position = position

    def select(self, following):
        """The positions of the rows to integrate in this step (``following``: bool (size,),
        the rows an observer still needs), None when there are none."""
        raise NotImplementedError

    def start(self, k, t, position):
        """The balls of the predictor of step ``k`` (time t [s], at ``position``): those at
        the start of the step, or any state as close to it to O(dt) (they only place the
        midpoint, and they are what the observers see as ``state1``)."""
        raise NotImplementedError

    def evaluate(self, position, t):
        """The balls at ``position`` at time t [s] (the midpoint of a step)."""
        raise NotImplementedError

    def predictor(self, state):
        """The epsilon that moves the balls to the midpoint (before the observers')."""
        return state.velocity_deviation

    def move(self, position, w, h):
        """The positions after h [s] at epsilon ``w`` (NaN: nominal)."""
        raise NotImplementedError

    def velocity(self, state1, state2):
        """The epsilon of the step's free motion, from the start and midpoint balls."""
        return state2.velocity_deviation

    def step(self, k, t, dt, position, new, state1, state2) -> Step:
        """The :class:`Step` the observers see (``new``: the free motion)."""
        raise NotImplementedError

    def advance(self, step, new):
        """Move to ``new`` at the end of the step."""
        raise NotImplementedError


def integrate(config, frame, observers=()):
    """The one explicit midpoint integration along the track (mode b), for any frame.

    Per step k of dt = T / n (t = k dt; n of :func:`.propagation_rules.time_steps`:
    ``study.time_steps``, or sized from the lengths over which epsilon changes): the rows
    some observer still follows (:meth:`StepObserver.following`; the frame may integrate
    more, or stop when none is left), the balls of the predictor (epsilon_1,
    :meth:`AlongTrackFrame.start`), the positions at the midpoint
    with it or with the observers' predictor (:meth:`StepObserver.predict`), the balls there
    (epsilon_2), the free motion of the step with the frame's epsilon of the step
    (:meth:`AlongTrackFrame.velocity`), which the observers see (:meth:`StepObserver.observe`)
    and may then replace (:meth:`StepObserver.advance`: trains after contact); then the frame
    moves to the end of the step (:meth:`AlongTrackFrame.advance`) and the observers see what
    it did (:meth:`StepObserver.moved`).

    Parameters
    ----------
    config : StudyConfig
    frame : AlongTrackFrame
        :class:`FreeBalls`, or the carriage's
        (:class:`tolsim.study.pipeline.carriage_track.CarriageFrame`).
    observers : sequence of StepObserver
    """
    steps = time_steps(config)
    dt = config.motion.duration / steps
    for observer in observers:
        observer.begin(frame.block, frame.position)
    t = 0.0
    for k in range(steps):
        following = np.zeros(frame.block.size, dtype=bool)
        for observer in observers:
            following |= observer.following()
        position = frame.select(following)
        if position is None:
            break
        state1 = frame.start(k, t, position)
        w1 = frame.predictor(state1)
        for observer in observers:  # touching balls move together (predictor)
            w1 = observer.predict(state1, w1)
        mid = frame.move(position, w1, 0.5 * dt)
        state2 = frame.evaluate(mid, t + 0.5 * dt)
        new = frame.move(position, frame.velocity(state1, state2), dt)
        step = frame.step(k, t, dt, position, new, state1, state2)
        for observer in observers:
            observer.observe(step)
        for observer in observers:
            new = observer.advance(step, new)
        frame.advance(step, new)
        for observer in observers:
            observer.moved(step)
        t = (k + 1) * dt


class FreeBalls(AlongTrackFrame):
    """The frame of free balls (single trains, the rail frame): every ball at its rail
    position and carriage position, epsilon from the error sources read at the rail position
    and the loads interpolated at the carriage position
    (:func:`tolsim.study.pipeline.evaluate.evaluate_balls_at`; with the ``paired`` model one
    compiled pass to the static model's inputs). The motion, the gaps and the first contact
    are compiled passes too (:func:`free_motion`, :func:`gaps`, :class:`FirstContact`). Whole
    blocks are integrated over the whole stroke (the error values are read for the block).

    ``ball_ok`` (size, balls): resolved at every evaluation so far; ``resolve_seconds``: time
    spent re-solving balls with the full model [s].
    """

    def __init__(self, config, block, initial_state=None):
        super().__init__(block, block.initial_position.copy())
        self.config = config
        self.initial_state = initial_state
        self.v = config.motion.groove_velocity
        self.diameter = 2.0 * config.bearing.ball_radius
        self.ball_ok = np.ones(self.position.shape, dtype=bool)
        self.resolve_seconds = 0.0

    def select(self, following):
        return self.position

    def evaluate(self, position, t):
        config, block = self.config, self.block
        with serial_if_small(position.size):
            values = error_values(config, block, rail_position=position, parallel=True)
        state = evaluate_balls_at(config, values, position - self.v * t)
        self.resolve_seconds += state.resolve_seconds
        return state

    def start(self, k, t, position):
        if k > 0:
            return self.midpoint  # the predictor's balls (Notes of integrate_along_track)
        if self.initial_state is not None:
            return self.initial_state
        return self.evaluate(position, t)

    def predictor(self, state):
        return self.pushed(state)

    def velocity(self, state1, state2):
        return self.pushed(state2)

    def pushed(self, state):
        """The balls' epsilon with the unloaded ones pushed along (:func:`pushed_along`)."""
        unloaded = state.unloaded
        if not unloaded.any():
            return state.velocity_deviation
        return pushed_along(gaps(self.position, self.diameter), state.velocity_deviation,
                            unloaded)

    def move(self, position, w, h):
        return free_motion(position, w, h, self.v)

    def step(self, k, t, dt, position, new, state1, state2):
        # an unloaded ball is accounted for (pushed along); its pairs close as one
        self.ball_ok &= state1.accounted & state2.accounted
        self.midpoint = state2
        unloaded = state2.unloaded
        gap_old = force_gaps(gaps(position, self.diameter), unloaded, ok=self.ball_ok)
        gap_new = force_gaps(gaps(new, self.diameter), unloaded, ok=self.ball_ok)
        return Step(k, t, dt, position, new, gap_old, gap_new, self.ball_ok, state1, state2)

    def advance(self, step, new):
        self.position = new


def integrate_along_track(config, block, initial_state=None, observers=()):
    """The explicit midpoint integration of a block's free trains along the track (mode b).

    :func:`integrate` in the :class:`FreeBalls` frame: per step of dt, the positions at the
    midpoint with the predictor epsilon_1 (or the observers' predictor), epsilon_2 of every
    ball there, at its rail position and carriage position (the error sources read at the
    rail position, the loads interpolated at the carriage position,
    :func:`tolsim.study.pipeline.evaluate.loads_at`), then the step with epsilon_2: the free
    motion, which the observers see (:meth:`StepObserver.observe`) and may then replace
    (:meth:`StepObserver.advance`: the trains after contact).

    One evaluation per step: epsilon_1 is the previous step's epsilon_2 (at t = 0 the balls
    at the start). The predictor only places the midpoint at which epsilon_2 is read, and a
    ball's epsilon changes over the lengths l of :func:`.propagation_rules.epsilon_lengths`
    while a step moves it l / c (c = 4 or 40): epsilon_1 taken half a step early moves the
    midpoint by (dt / 2) (v / 2) |d epsilon| <= l / (2 c) * (sigma_epsilon / c), some
    1e-5 l for c = 4 and sigma_epsilon ~ 1e-3. The step stays second order (the midpoint is off by
    O(dt^2)); evaluating the start of every step as well cost twice the evaluations for
    that. On ``configs/whatif_along_track.toml`` (2 000 assemblies, 20 steps) the same 403
    trains touch at the same pairs as with the start evaluated, their times within 3.3e-5 s
    (8.4e-5 relative) of a 0.5 s stroke, where the step's own error is some 8 ms
    (:func:`.propagation_rules.time_steps`); a run of 6 000 assemblies gives the same
    P(contact) and time-to-contact quantiles to five digits
    (tests/study/test_propagation.py).

    Parameters
    ----------
    config : StudyConfig
    block : tolsim.study.sampling.Block
    initial_state : BallState, optional
        The balls at t = 0 (evaluated here if not given).
    observers : sequence of StepObserver

    Returns
    -------
    ball_ok : ndarray of bool (size, balls)
        Balls resolved at every evaluation.
    resolve_seconds : float
        Time spent re-solving balls with the full model during the integration [s].
    """
    frame = FreeBalls(config, block, initial_state)
    integrate(config, frame, observers)
    return frame.ball_ok, frame.resolve_seconds


class FirstContact(StepObserver):
    """The first contact of each train: ``time`` [s] (inf: none) and ``pair`` (-1: none),
    located by linear interpolation of the gap within the step in which it closes, for a
    pair whose two balls are resolved so far (module docstring; one compiled pass per step,
    :func:`tolsim.study.pipeline.frame_kernels.first_contact_kernel`)."""

    def begin(self, block, position):
        self.time = np.full(block.size, np.inf)
        self.pair = np.full(block.size, -1, dtype=np.int64)

    def following(self):
        return ~np.isfinite(self.time)

    def observe(self, step):
        first_contact_kernel(kernel_array(step.gap_old), kernel_array(step.gap_new),
                             kernel_array(step.ball_ok, np.bool_), float(step.t),
                             float(step.dt), self.time, self.pair)


class TrainMotion(StepObserver):
    """The trains after contact (a study with ``[contact]``): the step rule of
    :mod:`tolsim.physics.trains` at every step through a
    :class:`tolsim.study.pipeline.track_friction.TrackFriction`, which accumulates the
    friction figures."""

    def __init__(self, friction, groove_velocity):
        self.friction = friction
        self.v = groove_velocity

    def begin(self, block, position):
        self.everyone = np.ones(position.shape, dtype=bool)
        self.friction.begin(block.size, np.asarray(block.initial_gap) <= 0.0)

    def predict(self, state, w):
        friction, everyone = self.friction, self.everyone
        load = friction.coefficients(state, everyone, friction.touching())
        eps = state.velocity_deviation
        unloaded = state.unloaded  # pushed along as without the trains (``w``)
        if unloaded.any():
            eps = np.where(unloaded, w, eps)
        return friction.predict(eps, load, everyone, everyone)

    def advance(self, step, new):
        # the step of the trains: cluster rule, then projection
        friction, everyone = self.friction, self.everyone
        position, dt, v = step.position, step.dt, self.v
        eps2 = step.state2.velocity_deviation
        unloaded = step.state2.unloaded
        if unloaded.any():  # pushed along, as in the free motion
            eps2 = pushed_along(gaps(position, friction.diameter), eps2, unloaded)
        w2 = friction.velocity(eps2, friction.coefficients(step.state2, everyone), everyone,
                               everyone)
        return friction.advance(position, free_motion(position, w2, dt, v))


def first_contact_along_track(config, block, initial_state=None, *, friction=None,
                              unresolved=None, static_fallback=None):
    """First contact of the trains of a block with epsilon re-evaluated along the track (b).

    Parameters
    ----------
    config : StudyConfig
    block : tolsim.study.sampling.Block
    initial_state : BallState, optional
        The balls at t = 0 (evaluated here if not given).
    friction : tolsim.study.pipeline.track_friction.TrackFriction, optional
        With it (a study with ``[contact]``) the balls move as trains after they touch: the
        step rule of :mod:`tolsim.physics.trains` at every step, each ball's creep
        coefficients from its loaded state at its position, and the friction figures
        accumulated in ``friction`` (Notes of
        :class:`tolsim.study.pipeline.track_friction.TrackFriction`). The
        first contact is the same as without it (it is located on the free motion of the
        step, which is the motion up to it).
    unresolved : ndarray of int64 (size,), optional
        Filled with the balls of each train unresolved at an evaluation after the start and
        not at t = 0 (the ball counters of the balls at t = 0 have those): with them, why
        ``valid`` is False.
    static_fallback : ndarray of bool (size, balls), optional
        Set where a ball was answered by its static model's fallback
        (:data:`tolsim.study.pipeline.evaluate.STATIC_FALLBACK`) at t = 0 or at any
        evaluation along the track.

    Returns
    -------
    time : ndarray (size,)
        [s], inf if no contact within the horizon.
    pair : ndarray of int (size,)
    valid : ndarray of bool (size,)
        False for a train in which some ball was unresolved at some evaluation (with
        ``friction``: of the trajectory with the trains, which after the first contact is
        not the free one).
    resolve_seconds : float
        Time spent re-solving balls with the full model during the integration [s].
    """
    first, start, fallback = FirstContact(), _StartUnresolved(), _StaticFallback()
    observers = [first, start, fallback]
    if friction is not None:
        observers.append(TrainMotion(friction, config.motion.groove_velocity))
    ball_ok, resolve_seconds = integrate_along_track(config, block, initial_state, observers)
    if unresolved is not None:
        unresolved[:] = np.count_nonzero(~ball_ok & ~start.at_start, axis=1)
    if static_fallback is not None:
        static_fallback |= fallback.marked
    return first.time, first.pair, ball_ok.all(axis=1), resolve_seconds


class _StaticFallback(StepObserver):
    """The balls answered by their static model's fallback at any evaluation, t = 0 included
    (``marked``: (size, balls))."""

    def begin(self, block, position):
        self.marked = np.zeros(position.shape, dtype=bool)

    def following(self):
        return False

    def observe(self, step):
        if step.index == 0:
            self.marked |= step.state1.static_fallback
        self.marked |= step.state2.static_fallback


class _StartUnresolved(StepObserver):
    """The balls without an answer at t = 0 (``at_start``: not ``accounted`` in the balls at
    the start of the first step)."""

    def begin(self, block, position):
        self.at_start = np.zeros(position.shape, dtype=bool)

    def following(self):
        return False

    def observe(self, step):
        if step.index == 0:
            self.at_start = ~np.asarray(step.state1.accounted, dtype=bool)
