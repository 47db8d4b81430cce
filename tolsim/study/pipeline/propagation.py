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
    step in which it changes sign (exact for piecewise-constant epsilon).

Unresolved balls (epsilon NaN: no model could solve them, :mod:`tolsim.study.pipeline.evaluate`)
never
close a gap: a contact is reported only for a pair whose two balls are resolved (in mode (b):
at every evaluation so far, since an unresolved step leaves the ball's position unknown from
then on). A reported contact is therefore certain; whether the train's first contact is
known, or whether it touches at all when no resolved pair does, is for the statistics to
bound (:mod:`tolsim.study.statistics.accumulator`).

Travel to contact is the carriage travel v t [m].

After contact (a study with ``[contact]``, issue 13): mode (a) leaves the trains to the
event-driven solution of :mod:`tolsim.physics.trains`; mode (b) follows them inside its own
integration when it is given a :class:`tolsim.study.pipeline.track_friction.TrackFriction` (the
step rule
of :mod:`tolsim.physics.trains`, "Varying epsilon"). The first contact is still located on
each step's free motion, so it is the same with and without ``[contact]``.
"""

import numpy as np
from numba import prange

from tolsim._jit import pjit
from tolsim.study.pipeline.evaluate import evaluate_balls, loads_at
from tolsim.study.sampling import error_values

#: What each propagation model assumes, in one sentence (summary, report, netCDF attribute).
PROPAGATION_ASSUMPTIONS = {
    "constant": ("constant: each ball keeps the epsilon of its position at the start of the "
                 "stroke (the paper's Fig. 9); rail errors along the track and the load "
                 "distribution of the carriage do not change it"),
    "along_track": ("along_track: epsilon is re-evaluated as each ball rolls past the rail "
                    "errors and through the carriage's load distribution (midpoint rule, "
                    "study.time_steps steps)"),
}


def propagation_assumption(propagation: str) -> str:
    """The one-sentence assumption of a propagation model (:data:`PROPAGATION_ASSUMPTIONS`)."""
    return PROPAGATION_ASSUMPTIONS[propagation]


def propagation_caveat(config) -> str:
    """A sentence for studies whose epsilon changes along the track but which use
    ``constant``: rail random fields (a rail-scope source with a correlation length) or loads
    that vary between the balls. Empty otherwise."""
    if config.study.propagation != "constant":
        return ""
    fields = [t.source for t in config.tolerances
              if t.scope == "rail" and t.correlation_length > 0 and t.distribution.is_random]
    if config.carriage is not None:  # balls enter and leave the carriage's load zone
        loads = config.train.balls > 1
        what = "a carriage whose balls pass through its load distribution"
    else:
        loads = (len(set(np.atleast_1d(config.loads.side_load))) > 1
                 or len(set(np.atleast_1d(config.loads.normal_load))) > 1)
        what = "loads that vary along the train"
    causes = ([f"rail random fields ({', '.join(fields)})"] if fields else []) + (
        [what] if loads else [])
    if not causes:
        return ""
    return (f"This study has {' and '.join(causes)}, so a ball's epsilon changes as it moves "
            "along the track; the constant propagation keeps each ball's starting value. "
            "propagation = \"along_track\" answers with the change included.")


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


def first_contact_along_track(config, block, initial_state=None, *, friction=None):
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
        accumulated in ``friction`` (module docstring of
        :mod:`tolsim.study.pipeline.track_friction`). The
        first contact is the same as without it (it is located on the free motion of the
        step, which is the motion up to it).

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
    v = config.motion.groove_velocity
    horizon = config.motion.duration
    steps = config.study.time_steps
    dt = horizon / steps
    diameter = 2.0 * config.bearing.ball_radius
    size = block.size

    resolve_seconds = 0.0

    def evaluate(position, t):
        nonlocal resolve_seconds
        values = error_values(config, block, rail_position=position)
        nx, ny = loads_at(config, position - v * t)
        state = evaluate_balls(config, values, nx, ny)
        resolve_seconds += state.resolve_seconds
        return state

    position = block.initial_position.copy()
    time = np.full(size, np.inf)
    pair = np.full(size, -1, dtype=np.int64)
    ball_ok = np.ones(position.shape, dtype=bool)  # resolved at every evaluation so far
    if friction is not None:
        everyone = np.ones(position.shape, dtype=bool)
        friction.begin(size, np.asarray(block.initial_gap) <= 0.0)
    t = 0.0
    for k in range(steps):
        if k == 0 and initial_state is not None:
            state1 = initial_state
        else:
            state1 = evaluate(position, t)
        eps1, ok1 = state1.velocity_deviation, state1.valid
        w1 = eps1
        if friction is not None:  # touching balls move together (predictor)
            load = friction.coefficients(state1, everyone, friction.touching())
            w1 = friction.predict(eps1, load, everyone, everyone)
        mid = position + 0.5 * dt * (1.0 + np.nan_to_num(w1)) * 0.5 * v
        state2 = evaluate(mid, t + 0.5 * dt)
        eps2, ok2 = state2.velocity_deviation, state2.valid
        ball_ok &= ok1 & ok2
        new = position + dt * (1.0 + np.nan_to_num(eps2)) * 0.5 * v
        gap_old = np.diff(position, axis=1) - diameter
        gap_new = np.diff(new, axis=1) - diameter
        closing = (gap_new <= 0.0) & (gap_old > gap_new) & ball_ok[:, :-1] & ball_ok[:, 1:]
        with np.errstate(divide="ignore", invalid="ignore"):
            frac = np.where(gap_old <= 0.0, 0.0, gap_old / (gap_old - gap_new))
        tc = np.where(closing, t + frac * dt, np.inf)
        first = np.argmin(tc, axis=1)
        tmin = tc[np.arange(size), first]
        hit = np.isfinite(tmin) & ~np.isfinite(time)
        time[hit] = tmin[hit]
        pair[hit] = first[hit]
        if friction is not None:  # the step of the trains: cluster rule, then projection
            w2 = friction.velocity(eps2, friction.coefficients(state2, everyone), everyone,
                                   everyone)
            new = friction.advance(position,
                                   position + dt * (1.0 + np.nan_to_num(w2)) * 0.5 * v)
        position = new
        t = (k + 1) * dt
    return time, pair, ball_ok.all(axis=1), resolve_seconds
