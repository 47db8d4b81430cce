"""Example trajectories of a study with ``[contact]``: a few assemblies of the first block,
their worst track followed again on a grid of carriage positions, for the report."""

from contextlib import contextmanager
from dataclasses import dataclass, replace

import numba
import numpy as np

from tolsim.physics.trains import (
    train_contact_constant,
)
from tolsim.physics.trains.regimes import pair_braking
from tolsim.physics.velocity.analytic import LOAD_COLUMNS
from tolsim.study.pipeline.block import evaluate_block, evaluates_blocks_together
from tolsim.study.pipeline.carriage_circuit import first_contact_carriage_circuit
from tolsim.study.pipeline.track_friction import (
    FrictionState,
    TrackFriction,
    follow_along_track,
    follow_trains,
)
from tolsim.study.sampling import sample_block

#: Column of the carriage force per push in the analytic loads.
PUSH_COLUMN = LOAD_COLUMNS.index("carriage_force_per_push")


# --------------------------------------------------------------------------------------------
# Examples
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FrictionExamples:
    """Example trajectories of the worst track of a few assemblies (Notes of
    :func:`friction_examples`).

    Shapes: k examples, S travel points, n balls per track.

    Attributes
    ----------
    assembly, track : ndarray of int (k,)
        Which assembly of the study (its index) and which of its tracks.
    travel : ndarray (S,)
        Carriage travel v t [m], 0 to the stroke.
    baseline : ndarray (k,)
        The track's friction force without ball-to-ball contact [N].
    friction_force : ndarray (k, S)
        The track's carriage friction force [N].
    contact_force : ndarray (k, S, n - 1)
        Ball-to-ball forces Q_j [N].
    ball_position : ndarray (k, S, n)
        Ball centres along the rail less the nominal travel v t / 2 of a free ball [m]
        (the train's centroid at 0 at the start; ball 0 trailing).
    """

    assembly: np.ndarray
    track: np.ndarray
    travel: np.ndarray
    baseline: np.ndarray
    friction_force: np.ndarray
    contact_force: np.ndarray
    ball_position: np.ndarray


def _evaluate_assemblies(config, block):
    """The balls of a block, as :func:`tolsim.study.execution.chunks.run_chunk` evaluates them."""
    # block imports this module

    return evaluate_block(config, block, propagate=False).state


#: Assemblies of the first block looked at first for the examples (all of it if too few touch).
EXAMPLE_WINDOW = 128


@contextmanager
def _one_thread():
    """Run the kernels on one thread (a few thousand balls: the thread pool costs more)."""
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(threads)


def _first_assemblies(block, count):
    """The first ``count`` assemblies of a block (with its rail fields and entering balls)."""
    fields = {k: replace(f, values=f.values[:count * f.tracks])
              for k, f in block.fields.items()}
    entering_gap = None if block.entering_gap is None else block.entering_gap[:count]
    return replace(block, size=count, normals={k: v[:count] for k, v in block.normals.items()},
                   fields=fields, initial_gap=block.initial_gap[:count],
                   initial_position=block.initial_position[:count],
                   entering_gap=entering_gap,
                   entering={k: v[:count] for k, v in block.entering.items()})


def choose_examples(figures: FrictionState, count: int) -> np.ndarray:
    """Indices of the example assemblies: the first resolved ones with a contact in their
    worst track, in order, then the first resolved ones without."""
    resolved = np.asarray(figures.resolved, dtype=bool)
    touched = resolved & (np.nan_to_num(figures.contact_fraction) > 0)
    order = np.concatenate([np.flatnonzero(touched), np.flatnonzero(resolved & ~touched)])
    return order[:max(int(count), 0)]


def friction_examples(config, order=None) -> FrictionExamples | None:
    """The example trajectories of a study with ``[contact]`` (None with ``examples = 0``).

    From the first random block of the study (Notes); each example's worst track
    is followed again on a grid of ``travel_points`` carriage positions. ``order``: the
    examples the study chose from its own evaluation of that block (:func:`choose_examples`
    of its figures, kept by :func:`tolsim.study.execution.chunks.run_chunk`), or None.

    Notes
    -----
    **Examples.**
    :func:`friction_examples` stores ``examples`` trajectories for plots: the friction force of
    the worst track, its ball positions and contact forces on a grid of ``travel_points``
    carriage positions. They are taken from the first random block of the study (so they depend
    on the seed only, not on the chunking or the number of samples): the first assemblies, in
    order, whose worst track has a ball-to-ball contact, then, if there are too few, the first
    resolved ones without. Given the study's own choice (``order``), only the assemblies up to
    the last chosen one are followed again, and they are used if they choose the same examples
    (they do when an assembly's evaluation does not depend on its batch,
    :func:`tolsim.study.pipeline.block.evaluates_blocks_together`; a resumed run has it from
    its checkpoint); otherwise, and without it, the first :data:`EXAMPLE_WINDOW` assemblies,
    then the whole block if too few of them touch. Either way the same examples, and the same
    trajectories: a study whose few assemblies touch does not follow a whole block again
    (a carriage without preload with ``[contact]``, 2 000 assemblies: 25 s of its 55 s).
    With ``along_track`` they come from the integration of those
    assemblies with :class:`~tolsim.study.pipeline.track_friction.TrackFriction` recording its
    steps: at a travel point the forces and the friction force of the step that holds it, the
    positions interpolated linearly within the step. With a carriage the ``ball`` columns are the
    track's initial balls while they are in the loaded zone (NaN once they have left it); the balls
    that entered since are in the friction force, not in the positions and pair forces. With
    a ``[carriage.circuit]`` the trains are the circuit's
    (:class:`tolsim.study.pipeline.circuit_friction.CircuitTrains`), whose friction force
    counts the column's forces at the zone's ends.
    """
    count = config.contact.examples
    if count == 0:
        return None
    whole = sample_block(config, 0)
    along = config.is_along_track
    # the first assemblies of the block, then all of it if too few of them touch: the
    # examples are the same either way (choose_examples takes them in order)
    sizes = sorted({min(EXAMPLE_WINDOW, whole.size), whole.size})
    study_chose = order is not None and len(order) > 0 and evaluates_blocks_together(config)
    if study_chose:
        sizes.insert(0, min(int(np.max(order)) + 1, whole.size))
    with _one_thread():
        for k, size in enumerate(sizes):
            block = _first_assemblies(whole, size)
            if along:
                trains = _follow_recorded(config, block)
                figures = trains.figures()
            else:
                state = _evaluate_assemblies(config, block)
                figures, trains = follow_trains(config, block.initial_gap, state)
            chosen = choose_examples(figures, count)
            if study_chose and k == 0:
                if np.array_equal(chosen, order):
                    break
            elif np.count_nonzero(figures.contact_fraction[chosen] > 0) == count:
                break
        if along:
            return _track_examples(config, block, figures, trains, chosen)
        return _example_trajectories(config, block, figures, trains, chosen)


def _follow_recorded(config, block):
    """The recording TrackFriction of a block's along-track integration, with or without a
    ball circuit."""
    if config.carriage is not None and config.carriage.circuit is not None:
        friction = TrackFriction(config, record=True)
        first_contact_carriage_circuit(config, block, friction=friction)
        return friction
    return follow_along_track(config, block, record=True)[-1]


def _track_examples(config, block, figures, friction, chosen):
    """:class:`FrictionExamples` of the assemblies ``chosen`` of ``block`` from the steps
    of their along-track integration (``friction``, a recording :class:`TrackFriction`):
    the forces of the step holding each travel point, the positions interpolated linearly
    within it. With a carriage the balls are the track's initial balls (ids 0 to n - 1) while
    they are in its loaded zone (NaN after they left it; the balls that entered since count
    in the friction force, not in the positions and pair forces)."""
    tracks, n = config.n_tracks, config.train.balls
    rows = chosen * tracks + figures.worst_track[chosen]
    motion, trace, steps = config.motion, friction.trace, friction.steps
    points = config.contact.travel_points
    time = motion.duration * np.arange(points) / (points - 1)
    time[-1] = motion.duration
    dt = motion.duration / steps
    step = np.minimum(np.floor(time / dt).astype(np.int64), steps - 1)
    theta = np.clip(time / dt - step, 0.0, 1.0)[None, :, None]

    def along(name):
        return np.stack([trace[name][k][rows] for k in step], axis=1)

    position = (1.0 - theta) * along("start") + theta * along("end")
    shift = (0.5 if friction.carriage_frame else -0.5) * motion.groove_velocity * time
    force = along("force")
    if trace["ids"] and trace["ids"][0] is not None:  # slots of a carriage track: by ball id
        ids = along("ids")
        slots = ids.shape[2]
        ball_position = np.full(ids.shape[:2] + (n,), np.nan)
        contact_force = np.full(ids.shape[:2] + (max(n - 1, 0),), np.nan)
        for j in range(n):
            here = ids == j
            has = here.any(axis=2)
            slot = np.argmax(here, axis=2)[..., None]
            ball_position[..., j] = np.where(
                has, np.take_along_axis(position, slot, 2)[..., 0] + shift, np.nan)
            if j < n - 1:
                ahead = np.take_along_axis(ids, np.minimum(slot + 1, slots - 1), 2)[..., 0]
                pair = has & (slot[..., 0] < slots - 1) & (ahead == j + 1)
                q = np.take_along_axis(force, np.minimum(slot, slots - 2), 2)[..., 0]
                contact_force[..., j] = np.where(pair, q, np.nan)
    else:
        ball_position = position + shift[None, :, None]
        contact_force = force
    return FrictionExamples(
        assembly=(block.start + chosen).astype(np.int64),
        track=figures.worst_track[chosen].astype(np.int64),
        travel=motion.groove_velocity * time,
        baseline=figures.baseline[chosen],
        friction_force=along("friction").reshape(len(rows), points),
        contact_force=contact_force,
        ball_position=ball_position,
    )


def _example_trajectories(config, block, figures, trains, chosen):
    """:class:`FrictionExamples` of the assemblies ``chosen`` of ``block``."""
    tracks, n = config.n_tracks, config.train.balls
    rows = chosen * tracks + figures.worst_track[chosen]
    gap = np.asarray(block.initial_gap).reshape(-1, max(n - 1, 0))[rows]
    result = train_contact_constant(gap, trains.velocity_deviation[rows],
                                    trains.stiffness[rows], config.motion.groove_velocity,
                                    config.motion.duration,
                                    braking_sensitivity=trains.braking[rows],
                                    samples=config.contact.travel_points)
    load = trains.load[rows]
    coefficient = ((load[:, 1:, PUSH_COLUMN] - load[:, :-1, PUSH_COLUMN])
                   + pair_braking(load, config.contact.ball_friction_coefficient))
    baseline = figures.baseline[chosen]
    force = baseline[:, None] + np.einsum("ksj,kj->ks", result.grid_contact_force, coefficient)
    start = np.asarray(block.initial_position).reshape(-1, n)[rows]
    return FrictionExamples(
        assembly=(block.start + chosen).astype(np.int64),
        track=figures.worst_track[chosen].astype(np.int64),
        travel=result.travel,
        baseline=baseline,
        friction_force=force,
        contact_force=result.grid_contact_force,
        ball_position=start[:, None, :] + result.grid_displacement,
    )


__all__ = ["EXAMPLE_WINDOW", "FrictionExamples", "choose_examples", "friction_examples"]
