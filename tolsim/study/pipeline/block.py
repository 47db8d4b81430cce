"""One evaluation of a block of assemblies: the only place that picks the config's variant.

A study's assemblies are free balls (one train per assembly) or a ``[carriage]`` (its
tracks' trains coupled through the carriage), and their epsilon is ``constant`` over the
stroke or re-evaluated ``along_track``. :func:`evaluate_block` looks the pair up in
:data:`BLOCK_EVALUATIONS` (and :data:`START_EVALUATIONS` for the balls at the start of the
stroke alone) and returns a :class:`BlockOutcome` with everything its callers need: the run
(:func:`tolsim.study.execution.chunks.run_chunk`), the sensitivity indices, the rare-event
limit states and the friction examples.
"""

from dataclasses import dataclass

import numpy as np

from tolsim.study.pipeline.carriage import CarriageState, evaluate_carriage
from tolsim.study.pipeline.carriage_circuit import first_contact_carriage_circuit
from tolsim.study.pipeline.carriage_track import first_contact_carriage_track
from tolsim.study.pipeline.evaluate import (
    BallState,
    evaluate_balls,
    evaluate_balls_at,
    loads_per_ball,
)
from tolsim.study.pipeline.propagation import (
    first_contact_along_track,
    first_contact_tracks,
    pushed_velocity_deviation,
)
from tolsim.study.pipeline.track_friction import FrictionState, TrackFriction, evaluate_friction
from tolsim.study.sampling import error_values


def variant(config) -> tuple:
    """(mounting, propagation) of a config (:attr:`tolsim.study.spec.StudyConfig.mounting`):
    the key of :data:`BLOCK_EVALUATIONS`."""
    return config.mounting, config.study.propagation


def has_carriage(config) -> bool:
    """Whether the config's balls are those of a carriage (``[carriage]``)."""
    return config.has_carriage


def is_along_track(config) -> bool:
    """Whether the config's epsilon is re-evaluated along the track."""
    return config.is_along_track


def has_contact(config) -> bool:
    """Whether the config follows the trains after contact (``[contact]``)."""
    return config.has_contact


def evaluates_blocks_together(config) -> bool:
    """Whether :func:`evaluate_block` may take several consecutive blocks drawn as one (the
    same rows as each alone, bit for bit).

    ``constant``: always. ``along_track``: when an assembly's integration does not depend on
    the other assemblies it is integrated with: every evaluation is per ball (free balls) or
    per assembly (the carriage solve), each warm start the assembly's own, so one integration
    over a chunk's blocks costs the per-step overhead once instead of once per block (with
    ``[carriage.circuit]`` too: a ball without a creep stiffness takes its own assembly's
    mean, :class:`tolsim.study.pipeline.carriage_circuit.CircuitFrame`). Not with
    ``static_model = "linearised"`` (more distinct loads than it linearises about share the
    batch's mean load).
    """
    if config.study.propagation == "constant":
        return True
    return config.study.static_model != "linearised"


@dataclass
class BlockOutcome:
    """What :func:`evaluate_block` found for a block of m assemblies.

    Attributes
    ----------
    values : dict
        source -> ndarray (m, balls), the error-source values at the start of the stroke
        [m or rad].
    state : BallState
        The balls at the start of the stroke, shape (m, tracks * balls).
    time : ndarray (m,) or None
        First contact [s], inf if none within the horizon (None: not propagated).
    pair : ndarray of int (m,) or None
        The first touching pair, -1 if none.
    train_valid : ndarray of bool (m,) or None
        ``along_track``: every ball resolved at every evaluation of the integration (and,
        with a carriage, enough slots and entering balls); None with ``constant``.
    resolve_seconds : float
        Full-model re-solves during the integration after the start [s] (those at the start
        are ``state.resolve_seconds``).
    carriage : CarriageState or None
        The carriages at the start of the stroke (a ``[carriage]``).
    friction : FrictionState or None
        The friction figures of the trains after contact (``[contact]``).
    circuit : dict or None
        The circuit figures of a ``[carriage.circuit]`` (:meth:`tolsim.study.pipeline.
        carriage_circuit.CircuitContact.figures`).
    unresolved_along_track : ndarray of int (m,) or None
        ``along_track``: the balls of each assembly unresolved at an evaluation after the
        start and not at it (with a carriage: before its first contact), each once: with the
        balls at the start, why ``train_valid`` is False; None with ``constant``.
    """

    values: dict
    state: BallState
    time: np.ndarray | None = None
    pair: np.ndarray | None = None
    train_valid: np.ndarray | None = None
    resolve_seconds: float = 0.0
    carriage: CarriageState | None = None
    friction: FrictionState | None = None
    circuit: dict | None = None
    unresolved_along_track: np.ndarray | None = None

    @property
    def resolved(self) -> np.ndarray:
        """Assemblies (m,) whose every ball was resolved or unloaded (at the start, and
        along the track with ``along_track``)."""
        ok = self.state.accounted.all(axis=1)
        return ok if self.train_valid is None else self.train_valid & ok


# --------------------------------------------------------------------------------------------
# The balls at the start of the stroke
# --------------------------------------------------------------------------------------------
def _free_start_constant(config, block, values):
    nx, ny = loads_per_ball(config, (block.size, config.balls))
    return evaluate_balls(config, values, nx, ny), None


def _free_start_along_track(config, block, values):
    # loads at the carriage positions, as during the integration
    return evaluate_balls_at(config, values, block.initial_position), None


def _carriage_start(config, block, values):
    # one carriage per assembly, its tracks' trains
    return evaluate_carriage(config, values)


#: variant -> ``f(config, block, values) -> (BallState, CarriageState or None)``: the balls at
#: the start of the stroke. With a carriage and ``along_track`` this is the carriage solved
#: at the nominal slots, not the integration's balls at their sampled positions.
START_EVALUATIONS = {
    ("free", "constant"): _free_start_constant,
    ("free", "along_track"): _free_start_along_track,
    ("carriage", "constant"): _carriage_start,
    ("carriage", "along_track"): _carriage_start,
}


# --------------------------------------------------------------------------------------------
# The whole stroke
# --------------------------------------------------------------------------------------------
def _constant(config, block, values):
    state, carriage = START_EVALUATIONS[variant(config)](config, block, values)
    eps = state.velocity_deviation
    unloaded = state.unloaded
    if unloaded.any():  # pushed along: no epsilon of their own (issue 25)
        eps = pushed_velocity_deviation(block.initial_gap, eps, unloaded, config.n_tracks)
    t, pair = first_contact_tracks(block.initial_gap, eps, config.motion.groove_velocity,
                                   config.motion.duration, config.n_tracks)
    friction = (None if config.contact is None  # after contact: trains and friction
                else evaluate_friction(config, block.initial_gap, state))
    return BlockOutcome(values, state, t, pair, None, 0.0, carriage, friction)


def _track_friction(config):
    """The step-by-step trains of an along_track block with ``[contact]`` (issue 13), else
    None (:class:`tolsim.study.pipeline.track_friction.TrackFriction`)."""
    return None if config.contact is None else TrackFriction(config)


def _figures(trains):
    return None if trains is None else trains.figures()


def _free_along_track(config, block, values):
    # with [contact] the trains are followed after contact, step by step
    trains = _track_friction(config)
    state, _ = _free_start_along_track(config, block, values)
    unresolved = np.zeros(block.size, dtype=np.int64)
    fallback = state.static_fallback.copy()
    t, pair, ok, seconds = first_contact_along_track(config, block, state, friction=trains,
                                                     unresolved=unresolved,
                                                     static_fallback=fallback)
    state.static_fallback = fallback  # counted once per ball, at t = 0 or along the track
    return BlockOutcome(values, state, t, pair, ok, seconds, None, _figures(trains),
                        unresolved_along_track=unresolved)


def _carriage_along_track(config, block, values):
    # balls rolling through the carriage (issue 12), in their circuits (issue 24)
    trains = _track_friction(config)
    if config.carriage.circuit is not None:
        t, pair, ok, seconds, state, carriage, contact = first_contact_carriage_circuit(
            config, block, friction=trains)
        return BlockOutcome(values, state, t, pair, ok, seconds, carriage, _figures(trains),
                            circuit=contact.figures(), unresolved_along_track=contact.unresolved)
    unresolved = np.zeros(block.size, dtype=np.int64)
    t, pair, ok, seconds, state, carriage = first_contact_carriage_track(
        config, block, friction=trains, unresolved=unresolved)
    return BlockOutcome(values, state, t, pair, ok, seconds, carriage, _figures(trains),
                        unresolved_along_track=unresolved)


#: variant (:func:`variant`) -> ``f(config, block, values) -> BlockOutcome``.
BLOCK_EVALUATIONS = {
    ("free", "constant"): _constant,
    ("free", "along_track"): _free_along_track,
    ("carriage", "constant"): _constant,
    ("carriage", "along_track"): _carriage_along_track,
}


def evaluate_block(config, block, values=None, *, propagate=True) -> BlockOutcome:
    """Evaluate a block of assemblies the way its config says (:data:`BLOCK_EVALUATIONS`).

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
    block : tolsim.study.sampling.Block
        With ``constant`` propagation it may hold several consecutive blocks drawn as one
        (:func:`tolsim.study.sampling.sample_block` with ``count``).
    values : dict, optional
        The error-source values at the start of the stroke
        (default :func:`tolsim.study.sampling.error_values` of the block).
    propagate : bool
        False: the balls at the start of the stroke only (:data:`START_EVALUATIONS`; no
        contact, friction or integration).

    Returns
    -------
    BlockOutcome
    """
    if values is None:
        values = error_values(config, block)
    if not propagate:
        state, carriage = START_EVALUATIONS[variant(config)](config, block, values)
        return BlockOutcome(values, state, carriage=carriage)
    return BLOCK_EVALUATIONS[variant(config)](config, block, values)
