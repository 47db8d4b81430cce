r"""What contact costs: the carriage friction of ball trains in a study (issue 13, part 3).

A study with ``[contact]`` (:class:`tolsim.study.spec.ContactSettings`) follows every train of
every sampled assembly over the stroke after its balls touch and records what the carriage pays
for it. :func:`evaluate_friction` gives one row per assembly (:class:`FrictionState`): with
constant epsilon from :func:`follow_trains`, with ``along_track`` propagation from
:class:`TrackFriction` (:func:`follow_along_track`); :func:`ball_creep_coefficients` gives the
balls' creep coefficients. The theory is in the Notes of those.
"""

from dataclasses import dataclass

import numpy as np

from tolsim.physics._fastmath import cbrt_nonnegative
from tolsim.physics.geometry import K_F_PAPER
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.trains import (
    step_clusters_kernel,
    step_project_kernel,
    train_contact_constant,
)
from tolsim.physics.trains.regimes import (
    TRAIN_COLUMNS,
    directional_braking,
    pair_braking,
    regime_creep_coefficients,
    settle_release_pushes,
)
from tolsim.physics.velocity.analytic import LOAD_COLUMNS, creep_coefficients_kernel
from tolsim.study.pipeline.carriage_track import first_contact_carriage_track
from tolsim.study.pipeline.carriage_track_kernels import carry_pairs_kernel
from tolsim.study.pipeline.evaluate import BallState, evaluate_balls_at
from tolsim.study.pipeline.friction_kernels import (
    RELEASED,
    ROLLING,
    SLIDING,
    step_friction_kernel,
    step_pushed,
    stroke_friction_kernel,
    stroke_pushed,
    train_inputs_kernel,
)
from tolsim.study.pipeline.propagation import (
    first_contact_along_track,
    pushed_velocity_deviation,
)
from tolsim.study.pipeline.propagation_rules import time_steps
from tolsim.study.sampling import error_values
from tolsim.study.statistics.friction import COLUMNS

#: Columns of the per-ball creep coefficients
# (:data:`tolsim.physics.velocity.analytic.LOAD_COLUMNS`, the first of TRAIN_COLUMNS).
_K, _C, _F0, _A, _B, _PCAP, _BCAP = (LOAD_COLUMNS.index(name) for name in (
    "creep_stiffness", "braking_sensitivity", "free_rolling_carriage_force",
    "carriage_force_per_push", "carriage_force_per_neighbour_force", "traction_capacity",
    "braking_capacity"))


# --------------------------------------------------------------------------------------------
# Per-ball creep coefficients (one vectorised kernel call per chunk)
# --------------------------------------------------------------------------------------------
def _creep_analytic(dbeta, force, bearing, ball_friction):
    """LOAD_COLUMNS of the loaded analytic model at zero load, (balls, 9)
    (:func:`tolsim.physics.velocity.analytic.creep_coefficients_kernel`)."""
    n = len(dbeta)
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    load = np.empty((n, len(LOAD_COLUMNS)))
    with np.errstate(divide="ignore", invalid="ignore"):
        creep_coefficients_kernel(dbeta, force, cbrt_nonnegative(force),
                                  bearing.nominal_contact_angle, bearing.ball_radius,
                                  hc.semi_major_coefficient, hc.elliptic_e, K_F_PAPER,
                                  bearing.friction_coefficient, float(ball_friction), load)
    return load


def _creep_full(dbeta, force, bearing, ball_friction):
    """As :func:`_creep_analytic`, with K, c, F_0 and the capacities from the full model
    (NaN where it cannot take the ball or does not converge); the slopes a, b analytic."""
    from tolsim.physics.velocity.full import full  # noqa: PLC0415  optional full model

    load = _creep_analytic(dbeta, force, bearing, ball_friction)
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    beta = bearing.nominal_contact_angle + dbeta
    with np.errstate(invalid="ignore"):
        takes = (np.all(np.isfinite(dbeta) & np.isfinite(force) & (force > 0), axis=1)
                 & np.all((beta > 0) & (beta < 0.5 * np.pi), axis=1)
                 & np.all(hc.semi_major_coefficient * np.cbrt(force)
                          < 0.5 * bearing.ball_radius, axis=1))
    columns = [_K, _C, _F0, _PCAP, _BCAP]
    load[:, columns] = np.nan
    idx = np.flatnonzero(takes)
    if len(idx):
        res = full(dbeta[idx], force[idx], bearing, push=0.0, ball_friction=ball_friction)
        good = np.asarray(res.valid, dtype=bool)
        rows = idx[good]
        for col, name in zip(columns, ("creep_stiffness", "braking_sensitivity",
                                       "free_rolling_carriage_force", "traction_capacity",
                                       "braking_capacity"), strict=True):
            load[rows, col] = np.asarray(getattr(res, name))[good]
    return load


#: Creep models by name (``contact.creep_model``): f(dbeta, force, bearing, mu_bb) ->
#: (balls, len(LOAD_COLUMNS)) at zero load.
CREEP_MODELS = {"analytic": _creep_analytic, "full": _creep_full}


def ball_creep_coefficients(config, state, rates=False) -> np.ndarray:
    """Creep coefficients of every ball from its own loaded contact state.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        With ``contact`` settings.
    state : tolsim.study.pipeline.evaluate.BallState
        Balls of shape (m, tracks * balls).
    rates : bool
        The rolling rates of balls in regime A also when ``state`` holds no other
        (:func:`tolsim.physics.trains.regimes.regime_creep_coefficients`).

    Returns
    -------
    ndarray, shape (m * tracks * balls, len(TRAIN_COLUMNS))
        The columns of :data:`tolsim.physics.trains.regimes.TRAIN_COLUMNS`: those of
        :data:`tolsim.physics.velocity.analytic.LOAD_COLUMNS` at zero load (K [N], c [1/N],
        F_0 [N], a, b [-], P_cap, braking capacity [N]) and the rolling rates; NaN for an
        unresolved ball (neither ``state.valid`` nor unloaded: its contact state may be
        missing or partial).

    Notes
    -----
    **Which creep model.**
    ``creep_model = "analytic"`` (default): K, the braking sensitivity c, F_0, a, b and the
    capacities from the loaded analytic model at the ball's own loaded contact state (dbeta_i, F_i
    from the study's static model;
    :func:`tolsim.physics.velocity.analytic.creep_coefficients_kernel`, one
    vectorised call per chunk, about 7 M balls/s on 2 cores), for every ball, also those whose
    epsilon the study took from the full model (K is a smooth property of the contact state: the
    analytic K is 2.6-5.7 % below the full model's on the paper's ball,
    tests/physics/test_ball_push.py).
    ``"full"``: K, c, F_0 and the traction and braking capacities from
    :func:`tolsim.physics.velocity.full.full` at zero load (slow: about 1e4 balls/s); the
    carriage-force slopes a, b stay the analytic ones (the full model gives the force at a load, not
    its slopes). The train's epsilon is always the study's epsilon of the ball.

    **By regime** (issue 25): the creep model's columns hold for a ball in regime A. A ball in
    regime B creeps with the stiffness of its stick line, an exactly two-point ball is an
    anchor (K = inf), an unloaded ball is pushed along (K = 0), with the columns of
    :func:`tolsim.physics.trains.regimes.regime_creep_coefficients` (a three-point ball with
    those of its own minimum of D, :func:`tolsim.physics.trains.regimes.
    three_point_coefficients`). Next to a ball that is not in regime A the braking acts along
    the pair's actual rotation (:func:`tolsim.physics.trains.regimes.directional_braking`).
    """
    dbeta = np.ascontiguousarray(state.contact_angle_deviation.reshape(-1, 4))
    force = np.ascontiguousarray(state.normal_force.reshape(-1, 4))
    mu_bb = config.contact.ball_friction_coefficient
    load = CREEP_MODELS[config.contact.creep_model](dbeta, force, config.bearing, mu_bb)
    load = regime_creep_coefficients(load, np.asarray(state.regime).reshape(-1), dbeta, force,
                                     config.bearing, ball_friction=mu_bb, lazy_release=True,
                                     rates=rates, solved=state.solved_rows())
    unresolved = ~np.asarray(state.accounted).reshape(-1)
    if unresolved.any():
        load[unresolved] = np.nan
    return load


@dataclass
class FrictionState:
    """Friction figures of m assemblies over the stroke, one row each (its worst track).

    Attributes
    ----------
    baseline : ndarray (m,)
        Carriage friction force of the worst track without ball-to-ball contact,
        sum_i F_0,i [N].
    increase_max, increase_mean : ndarray (m,)
        Largest and time-mean increase of the track's friction force over its baseline [N].
    ripple : ndarray (m,)
        max - min of the track's friction force over the stroke [N].
    contact_force_max : ndarray (m,)
        Largest ball-to-ball force of the track over the stroke [N].
    contact_fraction : ndarray (m,)
        Fraction of the stroke with any contact in the track [-].
    clusters_formed : ndarray (m,)
        Multi-ball clusters formed in the track over the stroke.
    worst_track : ndarray of int (m,)
        The track of the row (-1 when unresolved).
    resolved : ndarray of bool (m,)
        Every track followed over the whole stroke; the figures above are NaN otherwise.
    exceeds : ndarray of bool (m,)
        The increase certainly exceeds the spec limit (False without a limit).
    sliding : ndarray of bool (m,)
        Some ball of some track slides during the stroke (beyond a capacity; the assembly is
        unresolved).
    released : ndarray of bool (m,)
        No track has a sliding ball, but in some track a ball on a stick line is pushed past
        a release push (unresolved as well; ``sliding | released`` are the assemblies that
        were counted as sliding before the two were told apart).
    """

    baseline: np.ndarray
    increase_max: np.ndarray
    increase_mean: np.ndarray
    ripple: np.ndarray
    contact_force_max: np.ndarray
    contact_fraction: np.ndarray
    clusters_formed: np.ndarray
    worst_track: np.ndarray
    resolved: np.ndarray
    exceeds: np.ndarray
    sliding: np.ndarray
    released: np.ndarray

    def rows(self, sl) -> "FrictionState":
        """The assemblies ``sl`` (a slice)."""
        return FrictionState(**{k: v[sl] for k, v in self.__dict__.items()})

    def columns(self) -> np.ndarray:
        """The :data:`COLUMNS` as an (m, 7) float array."""
        return np.stack([np.asarray(getattr(self, c), dtype=float) for c in COLUMNS], axis=1)


@dataclass
class _Trains:
    """What :func:`follow_trains` computed per train (trains = m * tracks)."""

    load: np.ndarray  # (trains, n, len(TRAIN_COLUMNS))
    valid: np.ndarray  # (trains,) the train was followed
    velocity_deviation: np.ndarray  # (trains, n)
    stiffness: np.ndarray  # (trains, n), NaN for a ball that makes the train unresolved
    braking: np.ndarray  # (trains, n)


def _worst_tracks(config, m, *, track_ok, baseline, increase_max, increase_mean, ripple,
                  contact_force_max, contact_fraction, clusters_formed, bounded, rolling,
                  onset) -> FrictionState:
    """One row per assembly from per-train figures (m * tracks trains): its worst track
    (Notes of :func:`evaluate_friction`). ``track_ok``: the train was followed over the whole
    stroke; ``bounded``: it was not, and ``rolling`` is its largest increase before the onset (a
    lower bound of its maximum, for the certain exceedances); ``onset``: why it was not
    (:data:`tolsim.study.pipeline.friction_kernels.SLIDING`, ``RELEASED``; else ``ROLLING``)."""
    tracks = config.n_tracks
    limit = config.contact.friction_increase_limit
    if limit > 0:
        certain = (track_ok & (increase_max > limit)) | (bounded & (rolling > limit))
    else:
        certain = np.zeros(len(track_ok), dtype=bool)

    def per_assembly(x):
        return x.reshape(m, tracks)

    ok = per_assembly(track_ok)
    resolved = ok.all(axis=1)
    sliding = per_assembly(onset == SLIDING).any(axis=1)
    increase = np.where(ok, per_assembly(increase_max), -np.inf)
    ties = increase == increase.max(axis=1, keepdims=True)
    worst = np.argmax(np.where(ties, per_assembly(baseline), -np.inf), axis=1)
    rows = np.arange(m)

    def pick(x, fill=np.nan):
        return np.where(resolved, per_assembly(x)[rows, worst], fill)

    return FrictionState(
        baseline=pick(baseline),
        increase_max=pick(increase_max),
        increase_mean=pick(increase_mean),
        ripple=pick(ripple),
        contact_force_max=pick(contact_force_max),
        contact_fraction=pick(contact_fraction),
        clusters_formed=pick(clusters_formed),
        worst_track=np.where(resolved, worst, -1).astype(np.int64),
        resolved=resolved,
        exceeds=per_assembly(certain).any(axis=1),
        sliding=sliding,
        released=per_assembly(onset == RELEASED).any(axis=1) & ~sliding,
    )


def follow_trains(config, initial_gap, state):
    """(FrictionState of the assemblies, _Trains): the trains of ``state`` over the stroke."""
    tracks, n = config.n_tracks, config.train.balls
    m = state.velocity_deviation.shape[0]
    trains = m * tracks
    load = ball_creep_coefficients(config, state).reshape(trains, n, len(TRAIN_COLUMNS))
    eps = state.velocity_deviation
    unloaded = state.unloaded
    if unloaded.any():  # pushed along at the speed that closes both its gaps at once
        eps = pushed_velocity_deviation(initial_gap, eps, unloaded, tracks)
    eps = np.ascontiguousarray(eps.reshape(trains, n))
    stiffness, braking = np.empty((trains, n)), np.empty((trains, n))
    train_inputs_kernel(eps, load, stiffness, braking)
    stiffness, braking = directional_braking(load, stiffness, braking)
    horizon = config.motion.duration
    result = train_contact_constant(np.asarray(initial_gap).reshape(trains, max(n - 1, 0)),
                                    eps, stiffness, config.motion.groove_velocity, horizon,
                                    braking_sensitivity=braking, segments=True)
    baseline, mean, high, low = (np.empty(trains) for _ in range(4))
    onset = np.empty(trains, dtype=np.int8)
    rolling = np.empty(trains)
    pairs = pair_braking(load, config.contact.ball_friction_coefficient)
    settle_release_pushes(load, stroke_pushed(result.segment_start, result.segment_contact_force,
                                              result.valid, horizon), config.bearing)
    stroke_friction_kernel(result.segment_start, result.segment_contact_force, result.valid,
                           load, pairs, horizon, baseline, mean, high, low, onset, rolling)
    stopped = result.valid & (onset != ROLLING)
    # (a train whose increase is not finite, a coefficient not usable, is unresolved: never
    # a resolved train with NaN figures)
    track_ok = (result.valid & ~stopped & np.isfinite(baseline) & np.isfinite(mean)
                & np.isfinite(high) & np.isfinite(low))
    figures = _worst_tracks(config, m, track_ok=track_ok, baseline=baseline, increase_max=high,
                            increase_mean=mean, ripple=high - low,
                            contact_force_max=result.contact_force_max,
                            contact_fraction=result.contact_fraction,
                            clusters_formed=result.clusters_formed.astype(float),
                            bounded=stopped, rolling=rolling,
                            onset=np.where(result.valid, onset, ROLLING))
    return figures, _Trains(load, result.valid, eps, stiffness, braking)


def evaluate_friction(config, initial_gap, state, block=None) -> FrictionState:
    """Friction figures of assemblies over the stroke (Notes).

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        With ``contact`` settings.
    initial_gap : ndarray, shape (m, tracks * (balls - 1))
        Gaps at the start of the stroke [m], track by track.
    state : tolsim.study.pipeline.evaluate.BallState
        The evaluated balls at the start of the stroke, shape (m, tracks * balls).
    block : tolsim.study.sampling.Block, optional
        The block of the assemblies; needed with ``along_track`` propagation, whose trains
        are followed by integrating the block again (:func:`follow_along_track`; ``state``
        serves as its balls at t = 0 without a carriage).

    Returns
    -------
    FrictionState

    Raises
    ------
    ValueError
        With ``along_track`` propagation and no ``block``.

    Notes
    -----
    Each ball's creep coefficients come from the single-ball physics (the loaded analytic
    model, :mod:`tolsim.physics.velocity.ball_loads`, through
    :func:`tolsim.physics.velocity.analytic.creep_coefficients_kernel`, its fast path at zero load;
    or :func:`tolsim.physics.velocity.full.full`), the trains from :mod:`tolsim.physics.trains`;
    what is added here is the carriage friction force of a track over the stroke, its reduction to
    one row per assembly, the streamed statistics (:class:`FrictionStatistics`); the result-file
    variables are :mod:`tolsim.io.schema.friction`'s.

    Nomenclature: F_c,i -> ``carriage_force`` of ball i [N] (> 0 opposes the carriage motion);
    F_0,i -> ``free_rolling_carriage_force``; a_i = dF_c/dP -> ``carriage_force_per_push``;
    b_i = dF_c/d(Q_back + Q_front) -> ``carriage_force_per_neighbour_force``; Q_j -> contact
    force of pair j (balls j, j + 1) [N]; F_track -> the track's carriage friction force [N].

    **The friction force of a track.**
    The loaded analytic model is linear in the loads (:mod:`tolsim.physics.velocity.ball_loads`): a
    ball with net push P_i = Q_{i-1} - Q_i and neighbour-force sum S_i = Q_{i-1} + Q_i carries

        F_c,i = F_0,i + a_i P_i + b_i S_i.

    The track's carriage friction force is the sum over its balls. Each contact force Q_j
    enters P and S of its two balls (P_{j+1} += Q_j, P_j -= Q_j, S_j += Q_j, S_{j+1} += Q_j),
    so the increase over the baseline F_0 = sum_i F_0,i is a sum over the pairs

        F_track(t) - F_0 = sum_j k_j Q_j(t),   k_j = (a_{j+1} - a_j) + (b_j + b_{j+1}).     (1)

    For the nominal ball a_i = -1/2 and b_i = mu_bb / (2 cos beta_0), so k_j = mu_bb / cos beta_0
    (0.141 for mu_bb = 0.1 at 45 deg): the push itself costs nothing on net (both balls of a
    pair share it between the grooves alike, and a cluster's pushes sum to zero), while the
    Coulomb friction at the ball-ball contact brakes both balls, and the grooves pay for that
    couple. Deviations from the nominal ball add (a_{j+1} - a_j) Q_j, 1e-3 to 1e-2 Q_j.
    Example, the two balls of [Lin2018] Sec. 3.2 case (a) (configs/paper_case_study.toml with
    ``[contact]``; epsilon +-0.789 % from the full model, K = 673 N each from the analytic one):
    they touch at 6.34 s and then push with Q = K epsilon_1 = 5.31 N; with a = -0.504, -0.496
    and b = 0.0707, k = 0.149 and the track's friction rises by 0.79 N over its 2.82 N baseline
    (+28 %) for the rest of the stroke (tests/study/test_friction_study.py).

    With constant epsilon the contact forces are piecewise constant between events
    (:func:`tolsim.physics.trains.train_contact_constant` with ``segments=True``), so (1) is too,
    and every figure over the stroke is exact (no time step): the time mean of the increase
    (the segment durations as weights), its maximum and minimum, the ripple of F_track
    (max - min over the stroke; the baseline is constant), the largest ball-to-ball force, the
    fraction of the stroke with any contact, and the multi-ball clusters formed.

    **One row per assembly: the worst track.**
    An assembly with a carriage has several tracks (trains). Its row is that of its **worst
    track: the one with the largest maximum increase** (ties, e.g. no contact anywhere: the larger
    baseline, then the first track). All figures of the row (baseline, mean increase, ripple,
    largest contact force, contact fraction, clusters) belong to that one track, so they stay
    consistent with each other. Without a carriage the assembly is its train.

    **Unresolved and sliding trains (counted, bounded, never dropped).**

    * A ball without epsilon (unresolved in :mod:`tolsim.study.pipeline.evaluate`), or whose creep
      coefficients are not finite (K <= 0, |c K| >= 1 where the train model does not apply, a
      ``full`` creep solve that failed), leaves its train unresolved: the train is not followed.
    * **Anchors and balls pushed along** (issue 25; the columns of
      :func:`tolsim.physics.trains.regimes.regime_creep_coefficients`): a ball in regime B
      creeps with the stiffness of its stick line (about 3e4 N) while the push on it,
      P = Q_back - Q_front, stays between the pushes at which its stuck contact lets go
      (:func:`tolsim.physics.trains.ball_minimum.stick_line_release`, as little as +2.9 N;
      so does a three-point ball with a stuck contact); beyond them the train is unresolved
      as with a sliding ball (below) but counted apart (``released``); the pushes are
      computed only for the balls that carry a push once the train's forces are known
      (:func:`tolsim.physics.trains.regimes.settle_release_pushes`); an exactly two-point ball
      keeps its epsilon (K = inf) and slides when |P| / P_cap + S / S_cap >= 1 (exact:
      |P| + mu_bb S >= 2 mu F); an
      unloaded ball gets the epsilon that closes both its gaps at once
      (:func:`tolsim.study.pipeline.propagation.pushed_velocity_deviation`), K = 0 and no
      friction, and transmits the force. A pair with a ball in regime B or two-point pays the
      ball-ball friction of the two balls' actual rotations, one with a pushed ball none
      (:func:`tolsim.physics.trains.regimes.pair_braking`). Along the track the first
      contact takes unloaded balls as pushed along
      (:func:`tolsim.study.pipeline.propagation.pushed_along`); so does the step rule after
      contact (their free epsilon, K = 0 in the cluster rule).
    * **Sliding.** The linear creep law holds while each ball rolls. It stops when the push on a
      ball reaches its traction capacity, |P_i| >= P_cap,i, or the neighbour forces stall its
      rotation, S_i >= braking capacity (:mod:`tolsim.physics.velocity.ball_loads`). Every segment
      of a train is checked against the capacities at zero neighbour force (the traction capacity
      through a lower bound, :func:`tolsim.physics.velocity.analytic.creep_coefficients_kernel`).
      The braking only raises the traction capacity (it adds a non-negative term to the function
      whose minimum is P_cap), so this check is conservative: it may flag a ball that would still
      roll, never miss one. A train with a sliding ball is **unresolved from the onset of sliding**:
      the quasi-static creep model says nothing about a sliding ball's speed, and capping its force
      would invent a result. Up to the onset the figures are exact, so the largest increase before
      it is a lower bound of the train's maximum.
    * An assembly is resolved when all its tracks are. Its friction figures enter the
      histograms, quantiles and moments only then (estimates over the resolved assemblies, as for
      the time to contact). The exceedance of the spec limit L (``friction_increase_limit_N``)
      is counted like P(contact) in :mod:`tolsim.study.statistics.accumulator`: an assembly
      *certainly* exceeds when a resolved track, or a sliding track before its onset, has an
      increase above L; with k such assemblies, u unresolved ones without a certain exceedance and N
      in all, P(increase > L) is k / (N - u) with its Clopper-Pearson interval, and the
      partial-identification bounds [k / N, (k + u) / N] hold whatever the unresolved ones did.
    """
    if config.study.propagation == "along_track":
        if block is None:
            raise ValueError("evaluate_friction with propagation = 'along_track' needs the "
                             "block (block=...): the trains are followed along the track")
        initial = None if config.carriage is not None else state
        return follow_along_track(config, block, initial)[-1].figures()
    return follow_trains(config, initial_gap, state)[0]


# --------------------------------------------------------------------------------------------
# along_track: the trains followed step by step (Notes of TrackFriction)
# --------------------------------------------------------------------------------------------
#: Overlap below which the step rule leaves a pair alone, as a fraction of the ball diameter
#: (1e-14 m for a 10 mm ball, some 700 ulps of a position of 0.1 m: rounding, not contact).
STEP_TOLERANCE = 1e-12


def _flat_balls(state, index):
    """The balls ``index`` (into the flattened balls) of a BallState, as a flat BallState."""
    def flat(x, tail=()):
        return np.asarray(x).reshape((-1,) + tail)[index]

    solved = None if state.solved is None else (flat(state.solved[0]), state.solved[1])
    return BallState(flat(state.velocity_deviation), flat(state.valid),
                     flat(state.converged), flat(state.loss_of_contact),
                     flat(state.contact_angle_deviation, (4,)), flat(state.normal_force, (4,)),
                     flat(state.model), 0.0, flat(state.regime), flat(state.static_fallback),
                     solved)


class TrackFriction:
    """The trains of a block followed after contact, step by step (``along_track``).

    The integrators (:func:`tolsim.study.pipeline.propagation.first_contact_along_track`,
    :func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`) call it at every
    midpoint step when they are given one: :meth:`begin` with the closed pairs at t = 0,
    then per step :meth:`predict` (the velocities of the predictor), :meth:`velocity` (those
    of the step, at the midpoint) and :meth:`advance` (the projection and the step's
    friction), and with a carriage :meth:`carry` after balls left or entered the loaded
    zone. :meth:`figures` gives the per-assembly rows. Rows are trains, R = assemblies *
    tracks, over S ball slots (the train's balls, or a carriage track's slots).

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        With ``contact`` settings and ``along_track`` propagation.
    record : bool
        Keep every step's positions, forces and friction for :func:`friction_examples`.

    Notes
    -----
    **With along_track propagation.**
    Epsilon, K and the other creep coefficients of a ball change as it rolls past the rail errors
    and through the carriage's load distribution, and with a carriage balls leave and enter its
    loaded zone. The trains are then followed step by step, inside the propagation's midpoint
    integration (:class:`TrackFriction`, driven by :func:`tolsim.study.pipeline.propagation.
    first_contact_along_track` and :func:`tolsim.study.pipeline.carriage_track.
    first_contact_carriage_track`). At every step of dt = T / ``study.time_steps`` each ball's
    epsilon and creep coefficients come from its loaded state at its position, at the start of
    the step (predictor, only for trains with a closed pair) and at its midpoint; the cluster rule
    (:func:`tolsim.physics.trains.cluster_velocities`, touching = the closed pairs) gives the loaded
    velocities w_i, the balls advance at (1 + w_i) v / 2, and a gap that closes inside the step
    is closed by the kappa-weighted projection of the end positions, whose multipliers give the
    step-mean forces Qbar_j (eqs. 7, 8 of :mod:`tolsim.physics.trains`, "Varying epsilon", with the
    derivation). A contact ends when the cluster rule leaves its balls apart: its force returns to
    zero and the gap opens. Per step k, with the coefficients at the midpoint,

        F_track,k = B_k + I_k,   B_k = sum_i F_0,i,   I_k = sum_j k_j Qbar_j  (eq. 1 per step)

    (i over the loaded balls, j over the pairs of the train). The figures of a train:

    * **baseline**: the time mean of B_k over the stroke (it varies now: loads, rail errors,
      which balls are in the zone; with a carriage, over the windows below in a step in
      which a ball leaves or enters);
    * **increase**: I_k = F_track,k - B_k, the friction over the step's own baseline, i.e. what
      the contacts add; ``increase_max`` its maximum over the steps, ``increase_mean`` its time
      mean;
    * **ripple**: max_k F_track,k - min_k F_track,k, the ripple of the friction force itself
      (with the variation of the baseline, e.g. balls passing through the load zone; with a
      carriage over the windows below);
    * ``contact_force_max``: the largest Qbar_j; ``contact_fraction``: the time with a contact
      force (a step counts whole when a cluster pushes through it, else from its earliest
      closing, interpolated as the first contact is, to its end); ``clusters_formed``: clusters
      at the end of a step that hold a pair not in contact at its start (a cluster that splits
      and forms again counts again);
    * sliding is checked at every step with the step's forces against the capacities at zero
      neighbour force, as for constant epsilon. A train is unresolved from the step at which a
      ball slides, at which one of its loaded balls has no epsilon or no usable creep
      coefficients, or (a carriage) at which its assembly runs out of entering balls or slots;
      its balls then move freely, as without ``[contact]``, and its largest increase before that
      step is a lower bound of its maximum (certain exceedance, Notes of
      :func:`evaluate_friction`).

    *Error of the step.* For constant epsilon and K the step is exact whatever dt (derivation in
    :mod:`tolsim.physics.trains`): the positions at step ends and the step-mean forces are the
    event-driven ones, so the baseline, ``increase_mean`` and ``contact_fraction`` agree with
    the exact figures (Notes of :func:`evaluate_friction`) to rounding (1e-8 relative,
    tests/study/test_friction_along_track.py). Maxima and minima are taken over step means, so a
    contact that forms inside the last step (for the minimum of the ripple, the first) is averaged
    away: O(1) in a fraction O(dt / T) of the assemblies; two merges of one cluster inside one step
    count once. With varying epsilon the midpoint rule adds O(dt) over the stroke, mostly from the
    steps in which a contact starts or ends; a force that peaks at contact is underestimated by the
    step mean (the paper's pair with a 20 um gap: the largest force 4.35 N at 100 steps, 4.44 N at
    400).

    *First contact.* It is located on the free motion of each step, as without ``[contact]``:
    up to the first contact the balls are free and the trajectories are the same to the last
    bit, so P(contact) and the time to contact do not change when ``[contact]`` is added at the
    same ``study.time_steps`` (the automatic count is finer with ``[contact]``, except with a
    circuit: :func:`tolsim.study.pipeline.propagation_rules.time_steps`). (With
    free balls the train's validity also counts the evaluations after its first contact,
    which are now those of the trajectory with trains: an assembly whose ball is unresolved
    only on one of the two after contact is valid in one run and not in the other. Its contact
    is counted either way.)

    *With a carriage* the train of a track is its loaded balls. A ball is in its train for a
    step when it is in the loaded zone at the step's start, midpoint and end: a ball leaving at
    the trailing end drops its contacts in the step in which it leaves, a ball entering at the
    leading end joins from the step after, with an open gap. Beyond the ends of the train no
    force acts (Q = 0, :mod:`tolsim.physics.trains`, "Ends of the loaded zone"). Unloaded balls
    (in the return path, or of a train longer than the zone at t = 0) are in no train and are
    passed through as by the first-contact propagation. K comes from each ball's own loaded
    state in the carriage solved at its position. Every assembly is followed over the whole
    stroke (without ``[contact]``: up to its first contact).

    *Windows* (a carriage). The extremes of a carriage's friction are set by short windows
    in which the zone holds a ball fewer (one has left at the trailing end, the next has not
    yet entered) or one more, about one ball's F_0 (0.07-0.1 N) for about 2 ms. The
    midpoint solve of a step sees only the zone of its midpoint, and its baseline does not
    count a ball that entered before the midpoint (it joins the slots at the step's end): a
    spurious low by about one F_0 wherever an entry falls in a step's first half, so the
    ripple did not converge (0.148 N at 10 steps, 0.165 N at 200 against 0.178 N at 800 on
    ``configs/carriage_preload.toml``, 600 assemblies, the reference outside each interval).
    So in a step in which a ball leaves or enters, the extremes are taken instead from every
    interval between those events (:meth:`window`), each solved at its own midpoint with the
    balls that have entered by then
    (:meth:`tolsim.study.pipeline.carriage_track.CarriageTrains.windows`, the events of
    :func:`tolsim.study.pipeline.carriage_track_kernels.window_points_kernel`): its baseline
    there with the step's increase. The ripple is then 0.1490 N at 10 steps and 0.1489 N at
    200 against 0.1489 N [0.1466, 0.1511] at 800, inside at every step count, and the
    baseline 1.443 N at each
    (``benchmarks/convergence_along_track.py --configs carriage_preload --contact``). The
    steps' solves, the other figures and the first contacts do not change (those solves
    leave the Newton starts alone), except the baseline's time mean: in those steps it is
    the mean of the intervals' baselines over their shares of the step, instead of the
    midpoint's (which lacked a ball that entered before it).

    *Cost.* Per step the creep coefficients of every loaded ball at the midpoint and, for the
    trains with a closed pair, at the start; two O(n) passes per train. The propagation's
    evaluations (one per step for free balls, two for a carriage) still dominate
    (benchmarks/bench_study.py ``--along-track``).
    """

    def __init__(self, config, record=False):
        motion = config.motion
        self.config = config
        self.record = record
        self.steps = time_steps(config)
        self.half_step = 0.5 * motion.duration / self.steps * motion.groove_velocity
        self.diameter = 2.0 * config.bearing.ball_radius
        self.tolerance = STEP_TOLERANCE * self.diameter
        self.weight = 1.0 / self.steps
        self.assemblies = 0
        self._step = None

    def begin(self, assemblies, closed, carriage_frame=False):
        """Start: ``closed`` (R, S - 1) the pairs closed at t = 0 (zero initial gaps);
        ``carriage_frame``: positions are in the carriage's frame (else the rail's)."""
        self.assemblies = int(assemblies)
        self.closed = np.ascontiguousarray(closed, dtype=np.bool_)
        rows = self.closed.shape[0]
        self.before = np.zeros_like(self.closed)  # in contact in the previous step
        self.alive = np.ones(rows, dtype=np.bool_)
        self.onset = np.zeros(rows, dtype=np.int8)  # ROLLING, SLIDING or RELEASED
        self.rolling = np.full(rows, -np.inf)
        for name in ("baseline_sum", "increase_sum", "contact_sum", "formed_sum"):
            setattr(self, name, np.zeros(rows))
        self.increase_high = np.full(rows, -np.inf)
        self.friction_high = np.full(rows, -np.inf)
        self.friction_low = np.full(rows, np.inf)
        self.force_high = np.zeros(rows)
        self._window_rows, self._window_mean = np.empty(0, dtype=np.int64), np.zeros(rows)
        self.carriage_frame = carriage_frame
        self.trace = {k: [] for k in ("ids", "start", "end", "force", "friction")}

    def touching(self) -> np.ndarray:
        """Rows still followed that have a closed pair (R,)."""
        return self.alive & self.closed.any(axis=1)

    def stop(self, rows):
        """Rows (a boolean mask) that can no longer be followed (unresolved from now on)."""
        self.alive &= ~np.asarray(rows, dtype=bool)

    def halt(self, rows, onset):
        """Rows (a boolean mask) of followed trains in which a ball stopped rolling on its K
        inside the last step (``onset`` (R,): SLIDING or RELEASED, else 0 for a row whose
        forces there are not known): unresolved from now on, as at a step's sliding check
        (:func:`tolsim.study.pipeline.friction_kernels.step_friction_kernel`)."""
        rows = np.asarray(rows, dtype=bool) & self.alive
        self.onset[rows] = np.asarray(onset)[rows]
        self.alive &= ~rows

    def coefficients(self, state, mask, rows=None, rates=False) -> np.ndarray:
        """(R, S, len(TRAIN_COLUMNS)) creep coefficients of the balls ``mask`` (R, S), NaN
        elsewhere. ``state``: the BallState of those balls (of shape ``mask.shape``, or
        flattened in ``mask`` order); only the rows ``rows`` (R,) when given; ``rates``: as
        :func:`tolsim.physics.trains.regimes.regime_creep_coefficients`'s."""
        mask = np.asarray(mask, dtype=bool)
        load = np.full(mask.shape + (len(TRAIN_COLUMNS),), np.nan)
        select = mask if rows is None else mask & np.asarray(rows)[:, None]
        if select.any():
            flat_select = select[mask] if np.size(state.valid) != mask.size else \
                select.reshape(-1)
            if flat_select.all():
                sub = state
            else:
                sub = _flat_balls(state, np.flatnonzero(flat_select))
            load[select] = ball_creep_coefficients(self.config, sub, rates)
        return load

    def _clusters(self, eps, load, loaded, member):
        eps = np.ascontiguousarray(eps, dtype=float)
        load = np.ascontiguousarray(load)
        rows, slots = eps.shape
        stiffness, braking = np.empty((rows, slots)), np.empty((rows, slots))
        train_inputs_kernel(eps, load, stiffness, braking)
        stiffness, braking = (np.ascontiguousarray(x) for x in
                              directional_braking(load, stiffness, braking))
        velocity = np.empty((rows, slots))
        force = np.empty((rows, max(slots - 1, 0)))
        label = np.empty((rows, slots), dtype=np.int64)
        ok = np.empty(rows, dtype=np.bool_)
        loaded = np.ascontiguousarray(loaded, dtype=np.bool_)
        member = np.ascontiguousarray(member, dtype=np.bool_)
        step_clusters_kernel(eps, stiffness, braking, loaded, member, self.closed, self.alive,
                             velocity, force, label, ok)
        return velocity, force, label, ok, stiffness, braking, load, loaded, member

    def predict(self, eps, load, loaded, member) -> np.ndarray:
        """Loaded epsilon w (R, S) at the start of the step (the predictor's): the cluster
        rule on the closed pairs; the free epsilon (NaN kept) where nothing is pooled."""
        return self._clusters(eps, load, loaded, member)[0]

    def velocity(self, eps, load, loaded, member) -> np.ndarray:
        """Loaded epsilon w (R, S) of the step (at its midpoint), kept for :meth:`advance`.

        ``eps`` the free epsilon (NaN: unresolved), ``load`` the creep coefficients,
        ``loaded`` the balls that carry load, ``member`` the balls of the trains.
        """
        self._step = self._clusters(eps, load, loaded, member)
        return self._step[0]

    def advance(self, start, end, ids=None) -> np.ndarray:
        """Close the step: the positions at its end (R, S) [m], from those at its start and
        at its end with the velocities of :meth:`velocity`; its friction into the figures.
        ``ids`` (R, S): the balls in the slots (a carriage), for the examples."""
        _, force, label, ok, stiffness, braking, load, loaded, member = self._step
        self._step = None
        start = np.ascontiguousarray(start, dtype=float)
        end = np.ascontiguousarray(end, dtype=float)
        rows = len(ok)
        position = np.empty_like(end)
        closed = np.empty_like(self.closed)
        formed = np.empty(rows, dtype=np.int64)
        contact = np.empty(rows)
        step_project_kernel(start, end, stiffness, braking, loaded, member, ok, label,
                            self.before, self.diameter, self.tolerance, self.half_step,
                            position, force, closed, formed, contact)
        baseline, increase = self.account(loaded, member, load, force, ok, contact, formed)
        self.closed = closed & self.alive[:, None]
        self.before = self.closed.copy()
        if self.record:
            self.trace["ids"].append(None if ids is None else np.array(ids))
            self.trace["start"].append(start.copy())
            self.trace["end"].append(position.copy())
            self.trace["force"].append(np.where(self.alive[:, None], force, np.nan))
            self.trace["friction"].append(baseline + increase)
        return position

    def account(self, loaded, member, load, force, ok, contact, formed):
        """The friction of a step into the figures (:func:`step_friction_kernel`): ``loaded``,
        ``member`` (R, S), ``load`` (R, S, len(TRAIN_COLUMNS)), the step-mean pair forces
        ``force`` (R, S - 1) [N], ``ok``, ``contact`` and ``formed`` (R,); returns the step's
        baseline and increase (R,) [N] (NaN where not alive)."""
        rows = len(ok)
        baseline, increase = np.empty(rows), np.empty(rows)
        pairs = pair_braking(load, self.config.contact.ball_friction_coefficient)
        settle_release_pushes(load, step_pushed(member, force, ok, self.alive),
                              self.config.bearing)
        step_friction_kernel(loaded, member, load, pairs, force, ok, contact,
                             np.asarray(formed, dtype=float), self.weight, self.alive,
                             self.onset, self.baseline_sum, self.increase_sum,
                             self.increase_high, self.friction_high, self.friction_low,
                             self.force_high, self.contact_sum, self.formed_sum, self.rolling,
                             baseline, increase)
        self.increase = increase  # the step's, for :meth:`window`
        return baseline, increase

    def figures_before(self):
        """The running extremes and baseline sum, copied before a step (for :meth:`reopen`)."""
        return self.friction_high.copy(), self.friction_low.copy(), self.baseline_sum.copy()

    def reopen(self, rows, before):
        """Rows ``rows`` (R_k,) whose last step holds other loaded zones (a carriage: a ball
        left or entered in it): their extremes and baseline sum back to ``before``
        (:meth:`figures_before`), for :meth:`window` to give them each zone's instead of the
        step's own (Notes, "Windows")."""
        for target, value in zip((self.friction_high, self.friction_low, self.baseline_sum),
                                 before, strict=True):
            target[rows] = value[rows]
        self._window_rows = rows
        self._window_mean = np.zeros(len(self.alive))

    def window(self, rows, baseline, share, low=None, high=None):
        """A loaded zone of the last step, of rows reopened (:meth:`reopen`): its baseline
        there [N] (R_k,), with the step's increase into the ripple's maximum and minimum,
        and over ``share`` (R_k,) of the step into the time mean. ``low``, ``high`` (R_k,):
        the least and largest increase in that zone, where known (finite), instead of the
        step's (a circuit's windows, :meth:`extremes`). A row whose baseline is unknown
        there (a ball not resolved) is no longer followed, as at a step."""
        rows = np.asarray(rows)
        alive = self.alive[rows]
        baseline = np.asarray(baseline, dtype=float)
        increase = self.increase[rows]
        total = baseline + increase
        known = alive & np.isfinite(total)
        at = rows[known]
        top, bottom = (total if x is None else
                       baseline + np.where(np.isfinite(x), x, increase) for x in (high, low))
        self.friction_high[at] = np.maximum(self.friction_high[at], top[known])
        self.friction_low[at] = np.minimum(self.friction_low[at], bottom[known])
        self.baseline_sum[at] += baseline[known] * np.asarray(share)[known] * self.weight
        self._window_mean[rows] += baseline * share
        self.alive[rows[alive & ~np.isfinite(total)]] = False

    def extremes(self, baseline, low, high, peak):
        """The last step's least and largest increase and largest pair force (R,) [N]
        between its events, where known (finite), into the rows' extremes with the step's
        ``baseline`` (R,) [N] (:meth:`account`'s; NaN: not followed): a step's forces are
        its means, which hide a dip or a peak shorter than the step (a circuit's step gives
        them: :func:`tolsim.physics.circuit.step`, ``pair_slopes``)."""
        known = self.alive & np.isfinite(baseline)
        for target, value, pick in ((self.friction_high, baseline + high, np.maximum),
                                    (self.friction_low, baseline + low, np.minimum),
                                    (self.increase_high, high, np.maximum),
                                    (self.force_high, peak, np.maximum)):
            at = known & np.isfinite(value)
            target[at] = pick(target[at], value[at])

    def close_windows(self):
        """After the last :meth:`window` of a step: a recording keeps the step's friction of
        the reopened rows over its zones (their baselines over their shares, with the
        increase), not the midpoint's."""
        rows = self._window_rows
        if self.record and len(rows):
            self.trace["friction"][-1][rows] = np.where(
                self.alive[rows], self._window_mean[rows] + self.increase[rows], np.nan)

    def carry(self, old_id, new_id):
        """Follow the pair flags to the balls' new slots (after exits and entries)."""
        old_id = np.ascontiguousarray(old_id).reshape(len(self.closed), -1)
        new_id = np.ascontiguousarray(new_id).reshape(len(self.closed), -1)
        for name in ("closed", "before"):
            out = np.empty_like(self.closed)
            carry_pairs_kernel(old_id, getattr(self, name), new_id, out)
            setattr(self, name, out)

    def figures(self) -> FrictionState:
        """The per-assembly rows (the worst track, Notes of :func:`evaluate_friction`)."""
        alive = self.alive.copy()
        nan = np.nan

        def live(x):
            return np.where(alive, x, nan)

        return _worst_tracks(
            self.config, self.assemblies, track_ok=alive, baseline=live(self.baseline_sum),
            increase_max=live(self.increase_high), increase_mean=live(self.increase_sum),
            ripple=live(self.friction_high - self.friction_low),
            contact_force_max=live(self.force_high), contact_fraction=live(self.contact_sum),
            clusters_formed=live(self.formed_sum), bounded=~alive, rolling=self.rolling,
            onset=self.onset)


def follow_along_track(config, block, initial_state=None, record=False):
    """Integrate a block with ``along_track`` propagation and its trains after contact.

    Returns (time, pair, train_valid, resolve_seconds, state, carriage, friction): the
    outputs of :func:`tolsim.study.pipeline.propagation.first_contact_along_track` (free balls;
    state the balls at t = 0, carriage None) or of
    :func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`, and the
    :class:`TrackFriction` that followed the trains (an observer of the one loop,
    :func:`tolsim.study.pipeline.propagation.integrate`).
    """
    friction = TrackFriction(config, record=record)
    if config.carriage is not None:
        *out, state, carriage = first_contact_carriage_track(config, block, friction=friction)
        return (*out, state, carriage, friction)
    state = initial_state
    if state is None:  # loads at the carriage positions, as during the integration
        state = evaluate_balls_at(config, error_values(config, block), block.initial_position)
    out = first_contact_along_track(config, block, state, friction=friction)
    return (*out, state, None, friction)


__all__ = ["CREEP_MODELS", "STEP_TOLERANCE", "FrictionState", "TrackFriction",
           "ball_creep_coefficients", "evaluate_friction", "follow_along_track", "follow_trains",
           "step_friction_kernel", "stroke_friction_kernel"]
