"""Per-assembly export: the inputs and outputs of the first N assemblies of a study.

``run_study(config, save_samples=N)`` (``tolsim run --save-samples N``) keeps, for the first
N assemblies in block order, every tolerance source's value at each ball, the initial gaps,
each ball's loaded contact angles and forces, its epsilon, which model gave it and its regime
(four-point A or B, three-point, two-point, unloaded or unresolved), and the train's first
contact (time and pair), so the user can do their own analysis of exactly the
assemblies behind the statistics. The rows are cut from the blocks as the runner merges them
(:func:`sample_rows`), so they are bit-identical whatever the chunking or workers; blocks
whose rows a resumed run does not have are evaluated again (:func:`take`). The result file
holds them along a ``sample`` dimension
(:data:`tolsim.io.schema.samples.SAMPLE_VARIABLES`).

With ``along_track`` propagation the source values, contact state and epsilon are those at
the start of the stroke (the balls' initial rail positions); the contact time follows the
whole stroke.
"""

import numpy as np

from tolsim.study.sampling import n_blocks

#: Prefix of the sample rows in a block's records (beside its spot-check rows) and of their
#: variables.
PREFIX = "sample_"
#: Codes of ``sample_regime``: :data:`tolsim.physics.velocity.models.BALL_REGIMES`.
#: Codes of ``sample_model`` (:data:`tolsim.physics.velocity.models.MODEL_UNRESOLVED`,
#: ``MODEL_FAST``, ``MODEL_FULL``) and their CF flag meanings.
MODEL_FLAGS = {-1: "unresolved", 0: "fast_model", 1: "full_model"}


def sample_rows(config, save_samples, start, values, initial_gap, state, contact_time,
                contact_pair, rows=slice(None), *, circuit=None) -> dict:
    """The saved rows of one block: the part of its assemblies among the first N.

    Parameters
    ----------
    config : StudyConfig
    save_samples : int
        N, assemblies to keep (0: none).
    start : int
        Global index of the block's first assembly.
    values : dict
        source -> ndarray (m, balls), the source values of the evaluated assemblies [SI].
    initial_gap : ndarray (m, balls - 1)
    state : tolsim.study.pipeline.evaluate.BallState
        Of shape (m, balls).
    contact_time, contact_pair : ndarray (m,)
        First contact (inf / -1: none).
    rows : slice
        The block's assemblies among the m.
    circuit : dict, optional
        The circuit figures of the m assemblies (a ``[carriage.circuit]``,
        :meth:`tolsim.study.pipeline.carriage_circuit.CircuitContact.figures`): each
        circuit's total gap at the start and at the end of the stroke is kept.

    Returns
    -------
    dict
        ``sample_*`` name -> ndarray with the block's first min(size, N - start) rows; empty
        when the block starts at or after N.
    """
    m = len(contact_time)
    first = np.arange(m)[rows][: max(save_samples - start, 0)]
    keep = len(first)
    if keep == 0:
        return {}
    balls = config.balls  # all tracks of a carriage, track by track
    out = {f"{PREFIX}index": np.arange(start, start + keep, dtype=np.int64)}
    for t in config.tolerances:
        v = np.broadcast_to(values[t.source], (m, balls))
        out[f"{PREFIX}error_{t.source}"] = np.array(v[first], dtype=np.float64)
    out[f"{PREFIX}initial_gap"] = np.array(initial_gap[first], dtype=np.float64).reshape(
        keep, config.n_tracks * max(config.train.balls - 1, 0))
    out[f"{PREFIX}contact_angle_deviation"] = np.array(state.contact_angle_deviation[first])
    out[f"{PREFIX}normal_force"] = np.array(state.normal_force[first])
    out[f"{PREFIX}velocity_deviation"] = np.array(state.velocity_deviation[first])
    out[f"{PREFIX}model"] = np.array(state.model[first], dtype=np.int8)
    out[f"{PREFIX}regime"] = np.array(state.regime[first], dtype=np.int8)
    out[f"{PREFIX}contact_time"] = np.array(contact_time[first], dtype=np.float64)
    out[f"{PREFIX}contact_pair"] = np.array(contact_pair[first], dtype=np.int64)
    if circuit is not None:  # (keep, tracks) [m]
        for when in ("start", "end"):
            out[f"{PREFIX}circuit_total_gap_{when}"] = np.array(
                circuit[f"total_gap_{when}"][first], dtype=np.float64)
    return out


def concatenate(parts) -> dict:
    """The ``sample_*`` rows of block records, concatenated in order."""
    names = [k for p in parts for k in p if k.startswith(PREFIX)]
    names = list(dict.fromkeys(names))
    return {k: np.concatenate([p[k] for p in parts if k in p]) for k in names}


def take(config, parts, save_samples: int, spot_plan, run_chunk) -> dict | None:
    """The first ``save_samples`` assemblies' rows from the merged blocks' records ``parts``
    (None when not asked for).

    A block whose records lack them (a run resumed from a checkpoint, which keeps the
    spot-check rows only, or blocks evaluated again for a shorter run) is evaluated again
    through the same pipeline: same draws, same result. ``run_chunk``:
    :func:`tolsim.study.execution.chunks.run_chunk` (passed in: it calls :func:`sample_rows`
    of this module).
    """
    if not save_samples:
        return None
    wanted = min(save_samples, config.study.samples)
    rows = concatenate(parts)
    index = rows.get(f"{PREFIX}index", np.empty(0, np.int64))
    if not np.array_equal(index[:wanted], np.arange(wanted)):
        blocks = list(range(n_blocks(wanted, config.study.block_size)))
        rows = concatenate([spots for _, _, spots in run_chunk(
            config, blocks, spot_plan, save_samples=wanted)])
    return {k: v[:wanted] for k, v in rows.items()}
