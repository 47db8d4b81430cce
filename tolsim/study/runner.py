"""Run a study: blocks of assemblies -> balls -> contact -> streamed statistics.

:func:`run_study` is the Python API behind ``tolsim run``. Work is cut into chunks of whole
random blocks (:mod:`tolsim.study.sampling`); each chunk is sampled, evaluated through the
static model and the Numba velocity kernel in one go, propagated, and reduced to one
:class:`~tolsim.study.statistics.Accumulator` per block. Blocks are merged strictly in
block order, so the result does not depend on ``chunk_blocks`` or ``workers``.

Long runs are resumable: after merged blocks the state is saved (at most every
``checkpoint_interval`` seconds, and at the end of every chunk when the interval is 0) to a
checkpoint file; a later call with the same checkpoint path and an identical study (same
fingerprint: config, seed, samples, version) continues from it, giving a bit-identical
result. The caller deletes the checkpoint after writing the final output.
"""

import hashlib
import os
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from tolsim import __version__
from tolsim.study.evaluate import (
    MODEL_FAST,
    BallState,
    evaluate_balls,
    friction_module,
    loads_at,
    loads_per_ball,
)
from tolsim.study.propagation import first_contact_along_track, first_contact_constant
from tolsim.study.sampling import (
    block_size_of,
    choose_spot_checks,
    error_values,
    n_blocks,
    sample_block,
)
from tolsim.study.statistics import Accumulator

#: Balls evaluated together in one chunk (sets the default ``chunk_blocks``).
CHUNK_BALLS = 1 << 18

SPOT_FIELDS = ("ball_index", "contact_angle_deviation", "normal_force",
               "velocity_deviation_analytic", "valid_analytic")


@dataclass
class SpotChecks:
    """Balls re-solved with the full model (``tolsim.physics.friction.full``).

    Arrays have length k (the ``spot_check`` dimension); ``status`` explains a k of zero.
    """

    ball_index: np.ndarray
    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    velocity_deviation_analytic: np.ndarray
    valid_analytic: np.ndarray
    velocity_deviation_full: np.ndarray
    converged_full: np.ndarray
    valid_full: np.ndarray
    status: str = ""


@dataclass
class StudyResult:
    """Everything a study produced (in SI); :mod:`tolsim.io.netcdf` turns it into a file."""

    config: object
    statistics: Accumulator
    spot_checks: SpotChecks
    elapsed: float = 0.0  # [s], sampling to statistics (spot checks excluded)
    workers: int = 1
    resumed_blocks: int = 0
    meta: dict = field(default_factory=dict)
    sensitivity: object = None  # tolsim.study.sensitivity.SensitivityResult, if asked for


class StudyInterrupted(RuntimeError):
    """Raised when ``max_blocks`` stops a run early (the checkpoint holds the progress)."""


def fingerprint(config) -> str:
    """Identity of a study for resuming: config text and settings, tolsim version."""
    h = hashlib.sha256()
    h.update(config.text.encode())
    h.update(repr(config).encode())
    h.update(__version__.encode())
    return h.hexdigest()


def default_chunk_blocks(config) -> int:
    """Blocks per chunk so that a chunk holds about :data:`CHUNK_BALLS` balls."""
    per_block = config.study.block_size * config.train.balls
    return max(1, CHUNK_BALLS // per_block)


def _empty_spot():
    return {"ball_index": np.empty(0, np.int64),
            "contact_angle_deviation": np.empty((0, 4)), "normal_force": np.empty((0, 4)),
            "velocity_deviation_analytic": np.empty(0), "valid_analytic": np.empty(0, bool)}


def _spot_rows(state: BallState, start_ball: int, spot_indices) -> dict:
    """Records of the spot-check balls inside a block."""
    n = state.velocity_deviation.size
    lo, hi = np.searchsorted(spot_indices, [start_ball, start_ball + n])
    idx = spot_indices[lo:hi]
    if len(idx) == 0:
        return _empty_spot()
    local = idx - start_ball
    fast = state.model.reshape(-1)[local] == MODEL_FAST
    return {
        "ball_index": idx.astype(np.int64),
        "contact_angle_deviation": state.contact_angle_deviation.reshape(-1, 4)[local],
        "normal_force": state.normal_force.reshape(-1, 4)[local],
        # the study's fast model where it was valid (re-solved balls: NaN, not valid)
        "velocity_deviation_analytic": np.where(
            fast, state.velocity_deviation.reshape(-1)[local], np.nan),
        "valid_analytic": fast,
    }


def _concat_spots(parts):
    if not parts:
        return _empty_spot()
    return {k: np.concatenate([p[k] for p in parts]) for k in SPOT_FIELDS}


def draw_chunk(config, block_indices):
    """The draws and error-source values of consecutive blocks (constant propagation)."""
    block = sample_block(config, block_indices[0], len(block_indices))
    return block, error_values(config, block)


def run_chunk(config, block_indices, spot_indices, drawn=None):
    """Evaluate consecutive blocks; return [(block, Accumulator, spot rows)] in order.

    ``drawn``: ``draw_chunk(config, block_indices)`` when the caller has it already
    (constant propagation only).
    """
    out = []
    balls = config.train.balls
    if config.study.propagation == "constant":
        # One pass over the whole chunk, then split per block.
        block, values = drawn if drawn is not None else draw_chunk(config, block_indices)
        shape = block.initial_gap.shape[:1] + (balls,)
        nx, ny = loads_per_ball(config, shape)
        state = evaluate_balls(config, values, nx, ny)
        t, pair = first_contact_constant(block.initial_gap, state.velocity_deviation,
                                         config.motion.groove_velocity, config.motion.duration)
        offset = 0
        for index in block_indices:
            size = block_size_of(config, index)
            sl = slice(offset, offset + size)
            sub = state.rows(sl)
            acc = Accumulator.for_config(config)
            acc.add(sub, t[sl], pair[sl])
            if offset == 0:  # the chunk's re-solves, counted once
                acc.resolve_seconds = state.resolve_seconds
            start = index * config.study.block_size
            out.append((index, acc, _spot_rows(sub, start * balls, spot_indices)))
            offset += size
    else:
        for k in block_indices:
            b = sample_block(config, k)
            values = error_values(config, b)
            # loads at the carriage positions, as during the integration
            nx, ny = loads_at(config, b.initial_position)
            state = evaluate_balls(config, values, nx, ny)
            t, pair, ok, seconds = first_contact_along_track(config, b, state)
            acc = Accumulator.for_config(config)
            acc.add(state, t, pair, ok)
            acc.resolve_seconds += seconds
            out.append((b.index, acc, _spot_rows(state, b.start * balls, spot_indices)))
    return out


def _prefetched(config, chunks, spot_indices):
    """``run_chunk`` over the chunks in order, drawing chunk i + 1 in a second thread while
    chunk i is evaluated (NumPy's generators and ufuncs and the Numba kernels release the
    GIL, so drawing overlaps the kernels). The draws are the same as without the thread.
    Drawing must not launch parallel (``prange``) kernels: Numba's ``workqueue`` threading
    layer, the fallback where no OpenMP or TBB is installed, cannot run two at once."""
    if config.study.propagation != "constant" or len(chunks) < 2:
        for c in chunks:
            yield run_chunk(config, c, spot_indices)
        return
    with ThreadPoolExecutor(1, thread_name_prefix="tolsim-draw") as pool:
        pending = pool.submit(draw_chunk, config, chunks[0])
        for i, c in enumerate(chunks):
            drawn = pending.result()
            if i + 1 < len(chunks):
                pending = pool.submit(draw_chunk, config, chunks[i + 1])
            yield run_chunk(config, c, spot_indices, drawn)


#: glibc ``mallopt`` parameters and the values :func:`retain_freed_memory` sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20  # the largest glibc accepts on 64-bit systems
_TRIM_THRESHOLD = 1 << 30


def retain_freed_memory() -> bool:
    """Let glibc keep freed memory for reuse instead of returning it to the system.

    Every chunk of a study allocates the same few hundred MB of arrays and frees them. By
    default glibc serves arrays of this size with fresh ``mmap`` pages and trims the heap on
    free, so every chunk pays a page fault (and zeroing) per 4 kB touched, serialised in the
    kernel across the Numba threads; on a 2-core VM that was 15-22 % of a study's run time
    (``benchmarks/bench_study.py``). With allocations up to 32 MB from the heap and no
    trimming below 1 GB the second chunk reuses the first one's pages. Peak memory does not
    change; the process just keeps it until it exits. Returns False (and does nothing) where
    the C library is not glibc.
    """
    import ctypes
    import platform

    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)
                    and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
    except (OSError, AttributeError):
        return False


def _worker_init(threads):
    import numba

    retain_freed_memory()
    numba.set_num_threads(threads)


def _save_checkpoint(path, fp, next_block, acc, spots):
    tmp = f"{path}.tmp-{os.getpid()}"
    state = acc.state()
    arrays = {f"acc_{k}": v for k, v in state.items()}
    arrays["resolve_seconds"] = np.float64(acc.resolve_seconds)
    arrays.update({f"spot_{k}": v for k, v in spots.items()})
    with open(tmp, "wb") as fh:
        np.savez(fh, fingerprint=np.array(fp), next_block=np.int64(next_block), **arrays)
    os.replace(tmp, path)


def _load_checkpoint(path, fp):
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["fingerprint"]) != fp:
                return None
            acc = Accumulator.from_state(
                {k[4:]: data[k] for k in data.files if k.startswith("acc_")})
            acc.resolve_seconds = float(data["resolve_seconds"])
            spots = {k[5:]: data[k] for k in data.files if k.startswith("spot_")}
            return int(data["next_block"]), acc, spots
    except (OSError, KeyError, ValueError):
        return None


def run_study(config, *, workers: int = 1, chunk_blocks: int | None = None, progress=None,
              checkpoint_path=None, checkpoint_interval: float = 30.0,
              max_blocks: int | None = None) -> StudyResult:
    """Run a Monte Carlo tolerance study.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
    workers : int
        Processes; 1 runs in this process with Numba's threads over all cores, N > 1 starts
        N processes (spawned) sharing the cores. The result does not depend on it.
    chunk_blocks : int, optional
        Blocks evaluated together (default: about 2^18 balls). No effect on the result.
    progress : callable, optional
        Called with the number of assemblies merged since the last call.
    checkpoint_path : str, optional
        Resume from / save progress to this file (see the module docstring).
    checkpoint_interval : float
        Minimum seconds between checkpoint writes (0: after every chunk).
    max_blocks : int, optional
        Stop with :class:`StudyInterrupted` after merging this many blocks in this call
        (after saving the checkpoint); for tests of resuming.

    Returns
    -------
    StudyResult
    """
    if not (isinstance(workers, int) and workers >= 1):
        raise ValueError(f"workers = {workers!r} must be a positive integer")
    retain_freed_memory()
    st = config.study
    total_blocks = n_blocks(st.samples, st.block_size)
    chunk_blocks = chunk_blocks or default_chunk_blocks(config)
    if not chunk_blocks >= 1:
        raise ValueError(f"chunk_blocks = {chunk_blocks!r} must be >= 1")
    spot_indices = choose_spot_checks(config)
    fp = fingerprint(config)
    acc = Accumulator.for_config(config)
    spot_parts = []
    next_block = 0
    if checkpoint_path is not None and os.path.exists(checkpoint_path):
        loaded = _load_checkpoint(checkpoint_path, fp)
        if loaded is not None:
            next_block, acc, spots = loaded
            spot_parts.append(spots)
            if progress:
                progress(min(next_block * st.block_size, st.samples))
    resumed = next_block
    started = time.perf_counter()
    chunks = [list(range(i, min(i + chunk_blocks, total_blocks)))
              for i in range(next_block, total_blocks, chunk_blocks)]
    if workers == 1:
        results = _prefetched(config, chunks, spot_indices)
        executor = None
    else:
        import multiprocessing

        threads = max(1, (os.cpu_count() or 1) // workers)
        executor = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                                       initializer=_worker_init, initargs=(threads,))
        results = executor.map(run_chunk, [config] * len(chunks), chunks,
                               [spot_indices] * len(chunks))
    last_save = time.perf_counter()
    merged_here = 0
    try:
        for chunk_result in results:
            for index, block_acc, spots in chunk_result:
                assert index == next_block
                acc.merge(block_acc)
                spot_parts.append(spots)
                next_block += 1
                merged_here += 1
                if progress:
                    progress(int(block_acc.n_assemblies))
            stop = max_blocks is not None and merged_here >= max_blocks
            now = time.perf_counter()
            if checkpoint_path is not None and next_block < total_blocks and (
                    stop or now - last_save >= checkpoint_interval):
                spot_parts = [_concat_spots(spot_parts)]
                _save_checkpoint(checkpoint_path, fp, next_block, acc, spot_parts[0])
                last_save = now
            if stop and next_block < total_blocks:
                raise StudyInterrupted(f"stopped after {next_block} of {total_blocks} blocks")
    except KeyboardInterrupt:
        if checkpoint_path is not None and merged_here:  # keep what is merged (Ctrl-C)
            _save_checkpoint(checkpoint_path, fp, next_block, acc, _concat_spots(spot_parts))
        raise
    finally:
        if executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)
        else:
            results.close()  # stops the drawing thread of an unfinished run
    elapsed = time.perf_counter() - started
    spots = finish_spot_checks(config, _concat_spots(spot_parts))
    meta = {"spot_check_seconds": time.perf_counter() - started - elapsed}
    sensitivity = None
    if config.study.sensitivity_samples:
        from tolsim.study.sensitivity import study_sensitivity

        t0 = time.perf_counter()
        sensitivity = study_sensitivity(config, samples=config.study.sensitivity_samples)
        meta["sensitivity_seconds"] = time.perf_counter() - t0
    return StudyResult(config, acc, spots, elapsed, workers, resumed, meta, sensitivity)


def finish_spot_checks(config, rows: dict) -> SpotChecks:
    """Re-solve the recorded spot-check balls with the full model, if it is installed."""
    k = len(rows["ball_index"])
    module = friction_module()
    if k == 0 or module is None or not hasattr(module, "full"):
        status = ("no spot checks requested" if config.study.spot_checks == 0 else
                  "full model not available (tolsim.physics.friction.full missing): "
                  "0 spot checks")
        if k and module is None:
            rows = {key: v[:0] for key, v in rows.items()}
        return SpotChecks(**rows, velocity_deviation_full=np.empty(0),
                          converged_full=np.empty(0, bool), valid_full=np.empty(0, bool),
                          status=status)
    res = module.full(rows["contact_angle_deviation"], np.maximum(rows["normal_force"], 0.0),
                      config.bearing, groove_velocity=config.motion.groove_velocity)
    eps_full = np.asarray(res.velocity_deviation, dtype=float)
    converged = np.asarray(getattr(res, "converged", np.ones(k, bool)), dtype=bool)
    valid = np.asarray(getattr(res, "valid", converged), dtype=bool) & converged
    return SpotChecks(**rows, velocity_deviation_full=eps_full, converged_full=converged,
                      valid_full=valid, status=f"{k} balls re-solved with the full model")
