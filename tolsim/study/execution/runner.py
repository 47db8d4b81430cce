"""Run a study: blocks of assemblies -> balls -> contact -> streamed statistics.

:func:`run_study` is the Python API behind ``tolsim run``. Work is cut into chunks of whole
random blocks (:mod:`tolsim.study.sampling`); each chunk is sampled, evaluated through the
static model and the Numba velocity kernel in one go, propagated, and reduced to one
:class:`~tolsim.study.statistics.accumulator.Accumulator` per block. Blocks are merged strictly in
block order, so the result does not depend on ``chunk_blocks`` or ``workers``.

Long runs are resumable: after merged blocks the state is saved (at most every
``checkpoint_interval`` seconds, and at the end of every chunk when the interval is 0) to a
checkpoint file; a later call with the same checkpoint path and an identical study (same
fingerprint: config, seed, samples, version) continues from it, giving a bit-identical
result. The caller deletes the checkpoint after writing the final output.

A checkpoint only ever holds a completely merged state. After each block the statistics
(merged into a copy, :meth:`~tolsim.study.statistics.accumulator.Accumulator.merged`), the next
block
and the spot-check rows are replaced together, by one assignment of a :class:`_Progress`; a
KeyboardInterrupt (Ctrl-C), wherever it lands, saves the last such state.

With a :class:`PrecisionTarget` the run stops after the first block, in block order, at
which the 95 % interval of P(contact) is narrow enough; ``samples`` is then the maximum. The
later blocks of that chunk are dropped, so the result, whose config says the assemblies
actually run, is bit-identical to a fixed run of that many (the spot checks are those of that
run too). The interval is not corrected for the data-dependent stopping.

Rare events (issue 15): with ``[study] estimator = "subset"`` or ``"importance"`` the plain
Monte Carlo run of ``samples`` assemblies is made as always (it gives the epsilon
statistics, the time to contact, the spot checks and a first P(contact)), and *after* it the
estimator runs on every event the study defines (:func:`tolsim.study.analyses.limit_state.
estimate_events`: contact within the horizon, |epsilon| and friction spec exceedance), in
this process (``workers`` and ``scheduler`` serve the plain run), seeded from the study's
seed with the spawn key documented there, and not checkpointed (it takes seconds where the
plain run would need millions of assemblies). Its results are ``rare_events`` of the
:class:`StudyResult`; the result file reports them as the events' probabilities. A precision
target applies to plain Monte Carlo only and is refused with another estimator.
"""

import hashlib
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
from numba.core import event as numba_event

from tolsim import __version__
from tolsim.study.analyses.limit_state import check_supported, estimate_events
from tolsim.study.analyses.worst_case import linear_stackup
from tolsim.study.execution import saved_samples
from tolsim.study.pipeline.carriage import evaluate_carriage, solve_config_carriage
from tolsim.study.pipeline.carriage_track import first_contact_carriage_track
from tolsim.study.pipeline.evaluate import (
    MODEL_FAST,
    BallState,
    evaluate_balls,
    friction_module,
    loads_at,
    loads_per_ball,
)
from tolsim.study.pipeline.propagation import first_contact_along_track, first_contact_tracks
from tolsim.study.pipeline.track_friction import (
    TrackFriction,
    accumulator_from_state,
    evaluate_friction,
    friction_examples,
    study_accumulator,
)
from tolsim.study.sampling import (
    SPOT_CHECK_SCHEME,
    block_size_of,
    error_values,
    n_blocks,
    near_limit_candidates,
    sample_block,
    select_spot_checks,
    spot_check_plan,
)
from tolsim.study.statistics.accumulator import Accumulator

#: Balls evaluated together in one chunk (sets the default ``chunk_blocks``).
CHUNK_BALLS = 1 << 18

SPOT_FIELDS = ("ball_index", "contact_angle_deviation", "normal_force",
               "velocity_deviation_analytic", "valid_analytic", "stratum", "band_balls")


@dataclass
class SpotChecks:
    """Balls re-solved with the full model (``tolsim.physics.velocity.full.full``).

    Arrays have length k (the ``spot_check`` dimension); ``status`` explains a k of zero.
    ``stratum``: 0 uniform, 1 near the spec limit (:class:`tolsim.study.sampling.
    SpotCheckPlan`); ``band``: the near-limit band of |epsilon| [-] and ``band_balls`` the
    balls of the fast model in it.
    """

    ball_index: np.ndarray
    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    velocity_deviation_analytic: np.ndarray
    valid_analytic: np.ndarray
    velocity_deviation_full: np.ndarray
    converged_full: np.ndarray
    valid_full: np.ndarray
    stratum: np.ndarray = field(default_factory=lambda: np.empty(0, np.int8))
    band: tuple = (float("nan"), float("nan"))
    band_balls: int = 0
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
    sensitivity: object = None  # tolsim.study.analyses.sensitivity.SensitivityResult, if asked for
    target: object = None  # the PrecisionTarget of the run, if it had one
    target_reached: bool = False
    samples_maximum: int = 0  # the samples asked for (= config.study.samples without target)
    stackup: object = None  # tolsim.study.analyses.worst_case.LinearStackup: worst case and RSS
    # the first assemblies' rows (tolsim.study.execution.saved_samples)
    samples: dict | None = None
    # tolsim.study.pipeline.carriage.CarriageResult: nominal assembly
    carriage_nominal: object = None
    # tolsim.study.pipeline.track_friction.FrictionExamples ([contact])
    friction_examples: object = None
    # a rare-event estimator (study.estimator): event ->
    # tolsim.study.analyses.limit_state.EventEstimate
    rare_events: dict | None = None

    @property
    def friction(self):
        """The friction statistics of a study with ``[contact]``
        (:class:`tolsim.study.pipeline.track_friction.FrictionStatistics`), else None."""
        return getattr(self.statistics, "friction", None)

    @property
    def stopping_rule(self) -> str:
        """What a precision target did to the run, in one sentence ("" without a target)."""
        if self.target is None:
            return ""
        width, limit = self.target.interval_width(self.statistics)
        n = int(self.statistics.n_assemblies)
        interval = f"the 95 % interval of P(contact) is {width:.3g} wide"
        if not self.target_reached:
            return (f"target not reached: {interval}, more than {self.target.describe(limit)}, "
                    f"after all {_count(n)} assemblies (the maximum)")
        if n < self.samples_maximum:
            return (f"stopped at the target after {_count(n)} of at most "
                    f"{_count(self.samples_maximum)} assemblies: {interval}, at most "
                    f"{self.target.describe(limit)}")
        return (f"target reached at the maximum of {_count(n)} assemblies: {interval}, at most "
                f"{self.target.describe(limit)}")


class StudyInterrupted(RuntimeError):
    """Raised when ``max_blocks`` stops a run early (the checkpoint holds the progress)."""


def _count(n) -> str:
    """A count with its thousands set apart (``12 288``), for messages."""
    return f"{int(n):,}".replace(",", " ")


@dataclass(frozen=True)
class PrecisionTarget:
    """Stop a study once P(contact) is known precisely enough.

    The interval is the 95 % interval that covers the partial-identification bounds of
    P(contact)
    (:meth:`~tolsim.study.statistics.accumulator.Accumulator.contact_probability_bounds`);
    with no unresolved trains it is the Clopper-Pearson interval of k contacts in N trains.

    Parameters
    ----------
    width : float
        Largest width of that interval [-]; with ``relative``, as a fraction of the estimate
        of P(contact) (k / (N - u), the summary's headline), so that zero contacts never
        meet a relative target.
    relative : bool
    """

    width: float
    relative: bool = False

    def __post_init__(self):
        if not (np.isfinite(self.width) and self.width > 0
                and (self.relative or self.width < 1)):
            raise ValueError(f"target width {self.width!r} must be in (0, 1), or > 0 when "
                             "relative")

    @classmethod
    def parse(cls, text: str) -> "PrecisionTarget":
        """From the ``--target-ci-width`` syntax: ``0.005`` (absolute) or ``10%`` (relative).

        Raises
        ------
        ValueError
            Naming the text, for anything else.
        """
        raw = str(text).strip()
        relative = raw.endswith("%")
        try:
            value = float(raw[:-1] if relative else raw)
            return cls(value / 100 if relative else value, relative)
        except ValueError:
            raise ValueError(f"expected a width such as 0.005 or a relative width such as "
                             f"10%, got {text!r}") from None

    def __str__(self):
        return f"{100 * self.width:g}%" if self.relative else f"{self.width:g}"

    def describe(self, limit: float) -> str:
        """The largest width allowed, in words (``limit``: from :meth:`interval_width`)."""
        if self.relative:
            return f"{100 * self.width:g} % of the estimate ({limit:.3g})"
        return f"{self.width:g}"

    def interval_width(self, statistics):
        """(width of the interval, largest width allowed) for an Accumulator's state [-]."""
        _, _, lower, upper = statistics.contact_probability_bounds()
        if not self.relative:
            return upper - lower, self.width
        known = int(statistics.n_assemblies) - int(statistics.n_unresolved)
        estimate = int(statistics.n_contact) / known if known else float("nan")
        return upper - lower, self.width * estimate

    def reached(self, statistics) -> bool:
        """True once the interval is no wider than the target (never with no trains)."""
        width, limit = self.interval_width(statistics)
        return bool(width <= limit)  # NaN: False


def fingerprint(config) -> str:
    """Identity of a study for resuming: config text and settings, tolsim version."""
    h = hashlib.sha256()
    h.update(config.text.encode())
    h.update(repr(config).encode())
    h.update(__version__.encode())
    h.update(SPOT_CHECK_SCHEME.encode())
    return h.hexdigest()


def default_chunk_blocks(config) -> int:
    """Blocks per chunk so that a chunk holds about :data:`CHUNK_BALLS` balls."""
    per_block = config.study.block_size * config.balls
    return max(1, CHUNK_BALLS // per_block)


def _empty_spot():
    return {"ball_index": np.empty(0, np.int64),
            "contact_angle_deviation": np.empty((0, 4)), "normal_force": np.empty((0, 4)),
            "velocity_deviation_analytic": np.empty(0), "valid_analytic": np.empty(0, bool),
            "stratum": np.empty(0, np.int8), "band_balls": np.empty(0, np.int64)}


def _spot_rows(state: BallState, start_ball: int, plan) -> dict:
    """Records of the spot-check candidates inside a block (``plan``: a
    :class:`~tolsim.study.sampling.SpotCheckPlan`): its uniform candidates, then its
    near-limit candidates; ``band_balls`` holds the block's count of balls in the band."""
    eps = state.velocity_deviation.reshape(-1)
    fast_all = state.model.reshape(-1) == MODEL_FAST
    n = eps.size
    lo, hi = np.searchsorted(plan.uniform, [start_ball, start_ball + n])
    uniform = plan.uniform[lo:hi] - start_ball
    near, in_band = near_limit_candidates(plan, eps, fast_all, start_ball, exclude=uniform)
    local = np.concatenate([uniform, near]).astype(np.int64)
    fast = fast_all[local]
    return {
        "ball_index": (local + start_ball).astype(np.int64),
        "contact_angle_deviation": state.contact_angle_deviation.reshape(-1, 4)[local],
        "normal_force": state.normal_force.reshape(-1, 4)[local],
        # the study's fast model where it was valid (re-solved balls: NaN, not valid)
        "velocity_deviation_analytic": np.where(fast, eps[local], np.nan),
        "valid_analytic": fast,
        "stratum": np.repeat(np.array([0, 1], np.int8), [len(uniform), len(near)]),
        "band_balls": np.array([in_band], np.int64),
    }


def _concat_spots(parts):
    if not parts:
        return _empty_spot()
    return {k: np.concatenate([p[k] for p in parts]) for k in SPOT_FIELDS}


def draw_chunk(config, block_indices):
    """The draws and error-source values of consecutive blocks (constant propagation)."""
    block = sample_block(config, block_indices[0], len(block_indices))
    return block, error_values(config, block)


def run_chunk(config, block_indices, spot_indices, drawn=None, save_samples=0):
    """Evaluate consecutive blocks; return [(block, Accumulator, spot rows)] in order.

    ``drawn``: ``draw_chunk(config, block_indices)`` when the caller has it already
    (constant propagation only). ``save_samples``: the spot rows of a block also hold the
    rows of its assemblies among the first ``save_samples``
    (:func:`tolsim.study.execution.saved_samples.sample_rows`).
    """
    out = []
    balls = config.balls
    carriage = None
    if config.study.propagation == "constant":
        # One pass over the whole chunk, then split per block.
        block, values = drawn if drawn is not None else draw_chunk(config, block_indices)
        if config.carriage is not None:  # one carriage per assembly, its tracks' trains
            state, carriage = evaluate_carriage(config, values)
        else:
            nx, ny = loads_per_ball(config, (block.size, balls))
            state = evaluate_balls(config, values, nx, ny)
        t, pair = first_contact_tracks(block.initial_gap, state.velocity_deviation,
                                       config.motion.groove_velocity, config.motion.duration,
                                       config.n_tracks)
        friction = (None if config.contact is None  # after contact: trains and friction
                    else evaluate_friction(config, block.initial_gap, state))
        offset = 0
        for index in block_indices:
            size = block_size_of(config, index)
            sl = slice(offset, offset + size)
            sub = state.rows(sl)
            acc = study_accumulator(config)
            acc.add(sub, t[sl], pair[sl])
            if carriage is not None:
                acc.add_carriage(carriage.rows(sl))
            if friction is not None:
                acc.add_friction(friction.rows(sl))
            if offset == 0:  # the chunk's re-solves, counted once
                acc.resolve_seconds = state.resolve_seconds
            start = index * config.study.block_size
            rows = _spot_rows(sub, start * balls, spot_indices)
            rows.update(saved_samples.sample_rows(config, save_samples, start, values,
                                                  block.initial_gap, state, t, pair, sl))
            out.append((index, acc, rows))
            offset += size
    else:
        for k in block_indices:
            b = sample_block(config, k)
            values = error_values(config, b)
            carriage = None
            # with [contact] the trains are followed after contact, step by step
            trains = None if config.contact is None else TrackFriction(config)
            if config.carriage is not None:  # balls rolling through the carriage
                t, pair, ok, seconds, state, carriage = first_contact_carriage_track(
                    config, b, friction=trains)
            else:
                # loads at the carriage positions, as during the integration
                nx, ny = loads_at(config, b.initial_position)
                state = evaluate_balls(config, values, nx, ny)
                t, pair, ok, seconds = first_contact_along_track(config, b, state,
                                                                 friction=trains)
            acc = study_accumulator(config)
            acc.add(state, t, pair, ok)
            if carriage is not None:  # the carriages at the start of the stroke
                acc.add_carriage(carriage)
            if trains is not None:
                acc.add_friction(trains.figures())
            acc.resolve_seconds += seconds
            rows = _spot_rows(state, b.start * balls, spot_indices)
            rows.update(saved_samples.sample_rows(config, save_samples, b.start, values,
                                                  b.initial_gap, state, t, pair))
            out.append((b.index, acc, rows))
    return out


def _prefetched(config, chunks, spot_indices, save_samples=0):
    """``run_chunk`` over the chunks in order, drawing chunk i + 1 in a second thread while
    chunk i is evaluated (NumPy's generators and ufuncs and the Numba kernels release the
    GIL, so drawing overlaps the kernels). The draws are the same as without the thread.
    Drawing must not launch parallel (``prange``) kernels: Numba's ``workqueue`` threading
    layer, the fallback where no OpenMP or TBB is installed, cannot run two at once."""
    if config.study.propagation != "constant" or len(chunks) < 2:
        for c in chunks:
            yield run_chunk(config, c, spot_indices, None, save_samples)
        return
    with ThreadPoolExecutor(1, thread_name_prefix="tolsim-draw") as pool:
        pending = pool.submit(draw_chunk, config, chunks[0])
        for i, c in enumerate(chunks):
            drawn = pending.result()
            if i + 1 < len(chunks):
                pending = pool.submit(draw_chunk, config, chunks[i + 1])
            yield run_chunk(config, c, spot_indices, drawn, save_samples)


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


#: What ``run_study`` tells ``notify`` when Numba starts compiling (a cold kernel cache).
COMPILING_MESSAGE = "compiling kernels (first run only)"


class _CompileNotice(numba_event.Listener):
    """Call ``say`` once, when Numba starts compiling a kernel in this process.

    The kernels are cached on disk (``cache=True``): Numba compiles only when the cache is
    cold (the first run on a machine, or after tolsim changed) and then announces it through
    its event API (``numba:compile``); loading from the cache compiles and says nothing.
    """

    def __init__(self, say):
        self.say = say
        self._lock = threading.Lock()
        self._said = False

    def on_start(self, event):
        with self._lock:
            first, self._said = not self._said, True
        if first:
            self.say()

    def on_end(self, event):
        pass


def _worker_init(threads, compiling=None):
    import numba

    retain_freed_memory()
    numba.set_num_threads(threads)
    if compiling is not None:  # a multiprocessing Event the parent watches
        numba_event.register("numba:compile", _CompileNotice(compiling.set))


@dataclass(frozen=True)
class _Progress:
    """A completely merged state of a run: the only thing a checkpoint may hold.

    Never changed in place: each merged block makes a new one (:meth:`after`), which the
    runner commits with one assignment. ``spot_parts`` (the spot-check rows of each block, in
    block order) is append-only and shared; its first ``next_block`` entries belong here.
    """

    next_block: int
    statistics: Accumulator
    spot_parts: list

    def after(self, block_statistics, spots) -> "_Progress":
        """The state with the next block merged."""
        merged = self.statistics.merged(block_statistics)
        del self.spot_parts[self.next_block:]  # rows of a block that was never committed
        self.spot_parts.append(spots)
        return _Progress(self.next_block + 1, merged, self.spot_parts)

    def spots(self) -> list:
        return self.spot_parts[:self.next_block]


class DamagedCheckpoint(ValueError):
    """A checkpoint file that cannot be read: truncated, damaged, or not a checkpoint."""


def _save_checkpoint(path, fp, state: _Progress):
    """Write ``state`` to ``path`` through a temporary file and a rename (atomic).

    Raises
    ------
    OSError
        Naming ``path`` (not the temporary file, which is removed), when it cannot be
        written: a full disk, say. An earlier checkpoint at ``path`` is kept.
    """
    tmp = f"{path}.tmp-{os.getpid()}"
    acc = state.statistics
    parts = state.spots()
    arrays = {f"acc_{k}": v for k, v in acc.state().items()}
    arrays["resolve_seconds"] = np.float64(acc.resolve_seconds)
    arrays.update({f"spot_{k}": v for k, v in _concat_spots(parts).items()})
    # rows per block and field, to split the rows into blocks again
    arrays["part_lengths"] = np.array([[len(p[k]) for k in SPOT_FIELDS] for p in parts],
                                      dtype=np.int64).reshape(len(parts), len(SPOT_FIELDS))
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, fingerprint=np.array(fp), next_block=np.int64(state.next_block),
                     **arrays)
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise OSError(exc.errno, f"cannot write the checkpoint: {exc.strerror or exc}",
                          os.fspath(path)) from None
        raise


def _load_checkpoint(path, fp) -> _Progress | None:
    """The state saved in ``path``, or None if it is a checkpoint of another study.

    Raises
    ------
    DamagedCheckpoint
        If ``path`` cannot be read as a checkpoint (truncated, damaged, not one).
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["fingerprint"]) != fp:
                return None
            acc = accumulator_from_state(
                {k[4:]: data[k] for k in data.files if k.startswith("acc_")})
            acc.resolve_seconds = float(data["resolve_seconds"])
            next_block = int(data["next_block"])
            lengths = data["part_lengths"]
            spots = {k: data[f"spot_{k}"] for k in SPOT_FIELDS}
    except Exception as exc:  # noqa: BLE001 - zipfile, zlib, numpy and OS errors alike
        reason = " ".join(f"{type(exc).__name__}: {exc}".split())
        raise DamagedCheckpoint(f"checkpoint {path} cannot be read, it is damaged or "
                                f"truncated ({reason[:120]})") from None
    if lengths.shape != (next_block, len(SPOT_FIELDS)):
        raise DamagedCheckpoint(f"checkpoint {path} is inconsistent (part_lengths "
                                f"{lengths.shape} for {next_block} blocks)")
    pieces = {k: np.split(v, np.cumsum(lengths[:, j])[:-1]) if next_block else []
              for j, (k, v) in enumerate(spots.items())}
    parts = [{k: pieces[k][i] for k in SPOT_FIELDS} for i in range(next_block)]
    return _Progress(next_block, acc, parts)


def _spot_rows_of_shorter_run(config, plan_used, parts):
    """The spot-check rows of blocks ``0 .. len(parts) - 1`` as a run of
    ``config.study.samples`` assemblies records them.

    ``parts``: the rows recorded per block under ``plan_used``, the spot-check plan of a
    longer run of the same study. The uniform stratum is drawn over all the balls of a study,
    so only the blocks that hold one of its candidates in either plan can differ (when the
    plans agree otherwise); those are evaluated again.
    """
    plan = spot_check_plan(config)
    parts = list(parts)
    if repr(replace(plan, uniform=())) == repr(replace(plan_used, uniform=())):
        balls_per_block = config.study.block_size * config.balls
        redo = np.unique(np.concatenate([plan.uniform, plan_used.uniform]) // balls_per_block)
        redo = redo[redo < len(parts)]
    else:
        redo = np.arange(len(parts))
    for k in redo.tolist():
        ((_, _, parts[k]),) = run_chunk(config, [k], plan)
    return parts


def run_study(config, *, workers: int = 1, chunk_blocks: int | None = None, progress=None,
              checkpoint_path=None, checkpoint_interval: float = 30.0,
              max_blocks: int | None = None, target: PrecisionTarget | None = None,
              notify=None, save_samples: int = 0, scheduler=None) -> StudyResult:
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
    target : PrecisionTarget, optional
        Stop after the first block at which P(contact) is this precise; ``config.study.
        samples`` is then the maximum, and the result's config says the assemblies run.
    notify : callable, optional
        Called with a one-line message when something takes a while or needs saying: a
        resumed or ignored checkpoint, Numba compiling the kernels (:data:`COMPILING_MESSAGE`).
    save_samples : int
        Keep the inputs and outputs of the first this many assemblies (``samples`` of the
        result, :mod:`tolsim.study.execution.saved_samples`); 0: none.
    scheduler : str or distributed.Client, optional
        Run the chunks, grouped into tasks, and the spot checks on dask.distributed
        (:mod:`tolsim.study.execution.distributed`; ``pip install "tolsim[dask]"``): a scheduler
        address
        (``tcp://host:8786``), a scheduler file, ``local[:N]`` (a LocalCluster of N worker
        processes, started and closed here), a connected Client or a dask cluster object
        (a ``dask_jobqueue.SLURMCluster``, say; both left running). The results
        are merged here in block order, so the result does not depend on it; ``workers``
        must then be 1 (the cluster's workers do the work).

    Returns
    -------
    StudyResult
    """
    if not (isinstance(workers, int) and workers >= 1):
        raise ValueError(f"workers = {workers!r} must be a positive integer")
    if config.sweep is not None:
        raise ValueError(f"{config.path} has a [sweep] of {config.sweep.size} points: run them "
                         "with tolsim.io.sweep.run_sweep (tolsim run does), or one of "
                         "config.sweep.points")
    if scheduler is not None and workers != 1:
        raise ValueError(f"workers = {workers} and a scheduler: the scheduler's workers do the "
                         "work (local:N starts N of them); leave workers at 1")
    if not (isinstance(save_samples, int) and save_samples >= 0):
        raise ValueError(f"save_samples = {save_samples!r} must be a non-negative integer")
    if config.study.estimator != "monte_carlo":  # before any work
        check_supported(config)
        if target is not None:
            raise ValueError(f"a precision target applies to plain Monte Carlo; with "
                             f"estimator = {config.study.estimator!r} the interval comes from "
                             "the estimator (set samples_per_level or importance_samples)")
    retain_freed_memory()
    st = config.study
    total_blocks = n_blocks(st.samples, st.block_size)
    chunk_blocks = chunk_blocks or default_chunk_blocks(config)
    if not chunk_blocks >= 1:
        raise ValueError(f"chunk_blocks = {chunk_blocks!r} must be >= 1")
    if not checkpoint_interval >= 0:
        raise ValueError(f"checkpoint_interval = {checkpoint_interval!r} must be >= 0")
    spot_indices = spot_check_plan(config)
    fp = fingerprint(config)
    # The committed state: replaced as a whole, never changed (module docstring).
    committed = _Progress(0, study_accumulator(config), [])
    if checkpoint_path is not None and os.path.exists(checkpoint_path):
        loaded = _load_checkpoint(checkpoint_path, fp)
        if loaded is None:
            _say(notify, f"ignoring {checkpoint_path}: it is not a checkpoint of this study "
                         "(config, seed, samples or tolsim version differ); starting afresh")
        elif loaded.next_block:
            committed = loaded
            done = int(committed.statistics.n_assemblies)
            _say(notify, f"resumed from {checkpoint_path}: {_count(done)} of "
                         f"{_count(st.samples)} assemblies already done")
            if progress:
                progress(done)
    resumed = committed.next_block
    # a checkpoint saved just after the target was met: nothing left to run
    reached = bool(target is not None and resumed and target.reached(committed.statistics))
    last_block = resumed if reached else total_blocks
    started = time.perf_counter()
    chunks = [list(range(i, min(i + chunk_blocks, last_block)))
              for i in range(resumed, last_block, chunk_blocks)]
    notice = _CompileNotice(lambda: _say(notify, COMPILING_MESSAGE))
    results = executor = watch = session = None
    loop_ended = False
    last_save = time.perf_counter()
    merged_here = 0
    numba_event.register("numba:compile", notice)
    try:
        if scheduler is not None:  # tasks on dask.distributed, merged below in block order
            from tolsim.study.execution.distributed import DaskSession

            session = DaskSession(scheduler, notify=notify)
            workers = session.workers  # recorded in the result
            results = session.chunk_results(config, chunks, spot_indices, save_samples)
        elif workers == 1:
            results = _prefetched(config, chunks, spot_indices, save_samples)
        else:
            import multiprocessing

            context = multiprocessing.get_context("spawn")
            threads = max(1, (os.cpu_count() or 1) // workers)
            compiling = context.Event() if notify else None
            executor = ProcessPoolExecutor(workers, mp_context=context,
                                           initializer=_worker_init,
                                           initargs=(threads, compiling))
            results = executor.map(run_chunk, [config] * len(chunks), chunks,
                                   [spot_indices] * len(chunks), [None] * len(chunks),
                                   [save_samples] * len(chunks))
            if compiling is not None:
                watch = _watch_workers(compiling, notice)
        for chunk_result in results:
            for index, block_acc, spots in chunk_result:
                assert index == committed.next_block
                committed = committed.after(block_acc, spots)  # the one commit of a block
                merged_here += 1
                if progress:
                    progress(int(block_acc.n_assemblies))
                if target is not None and target.reached(committed.statistics):
                    reached = True
                    break  # the later blocks of the chunk are dropped
            if reached:
                break
            stop = max_blocks is not None and merged_here >= max_blocks
            now = time.perf_counter()
            if checkpoint_path is not None and committed.next_block < total_blocks and (
                    stop or now - last_save >= checkpoint_interval):
                _save_checkpoint(checkpoint_path, fp, committed)
                last_save = now
            if stop and committed.next_block < total_blocks:
                raise StudyInterrupted(
                    f"stopped after {committed.next_block} of {total_blocks} blocks")
        loop_ended = True
    except KeyboardInterrupt:
        # Ctrl-C: keep what is merged; only a committed state, never one half-merged
        if checkpoint_path is not None and committed.next_block > resumed:
            _save_checkpoint(checkpoint_path, fp, committed)
        raise
    finally:
        if watch is not None:
            watch.set()
        numba_event.unregister("numba:compile", notice)
        if executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)
        elif results is not None:
            results.close()  # stops the drawing thread (or the tasks) of an unfinished run
        if session is not None and not loop_ended:
            session.close()
    elapsed = time.perf_counter() - started
    acc = committed.statistics
    n_done = int(acc.n_assemblies)
    result_config = config
    parts = committed.spots()
    if n_done < st.samples:  # stopped at the target: the study of n_done assemblies
        result_config = config.with_overrides(samples=n_done)
        parts = _spot_rows_of_shorter_run(result_config, spot_indices, parts)
    if session is None:
        spots = finish_spot_checks(result_config, _concat_spots(parts))
    else:  # as a task; then the session is closed
        with session:
            spots = session.spot_checks(result_config, _concat_spots(parts))
    samples = saved_samples.take(result_config, parts, save_samples, spot_indices)
    meta = {"spot_check_seconds": time.perf_counter() - started - elapsed}
    sensitivity = None
    if config.study.sensitivity_samples:
        from tolsim.study.analyses.sensitivity import study_sensitivity

        t0 = time.perf_counter()
        sensitivity = study_sensitivity(result_config,
                                        samples=config.study.sensitivity_samples)
        meta["sensitivity_seconds"] = time.perf_counter() - t0
    # worst case and RSS: one small evaluation (of free balls; not for a carriage, whose
    # balls are coupled through it)
    stackup = None if config.carriage is not None else linear_stackup(result_config)
    nominal = None
    if config.carriage is not None:  # the load distribution without tolerances
        try:
            nominal = solve_config_carriage(config)
        except ValueError:  # recorded as NaN; the sampled assemblies were counted anyway
            nominal = None
    examples = None if config.contact is None else friction_examples(result_config)
    rare = None
    if config.study.estimator != "monte_carlo":  # after the plain run (module docstring)
        t0 = time.perf_counter()
        rare = estimate_events(result_config, batch_size=st.block_size, notify=notify)
        meta["rare_event_seconds"] = time.perf_counter() - t0
    return StudyResult(result_config, acc, spots, elapsed, workers, resumed, meta, sensitivity,
                       target=target, target_reached=reached, samples_maximum=st.samples,
                       stackup=stackup, samples=samples, carriage_nominal=nominal,
                       friction_examples=examples, rare_events=rare)


def _say(notify, message):
    if notify is not None:
        notify(message)


def _watch_workers(compiling, notice) -> threading.Event:
    """Pass the workers' compile event on to ``notice`` (in a thread); set the returned
    Event to stop watching."""
    finished = threading.Event()

    def watch():
        while not finished.is_set():
            if compiling.wait(0.1):
                notice.on_start(None)
                return

    threading.Thread(target=watch, name="tolsim-compile-watch", daemon=True).start()
    return finished


def finish_spot_checks(config, rows: dict) -> SpotChecks:
    """Select the spot checks among the recorded candidates
    (:func:`tolsim.study.sampling.select_spot_checks`) and re-solve them with the full model,
    if it is installed."""
    plan = spot_check_plan(config)
    band_balls = int(np.sum(rows["band_balls"]))
    chosen = select_spot_checks(plan, rows["ball_index"], rows["stratum"])
    rows = {key: v[chosen] for key, v in rows.items() if key != "band_balls"}
    rows.update(band=plan.band, band_balls=band_balls)
    k = len(rows["ball_index"])
    module = friction_module()
    if k == 0 or module is None or not hasattr(module, "full"):
        status = ("no spot checks requested" if config.study.spot_checks == 0 else
                  "full model not available (tolsim.physics.velocity.full.full missing): "
                  "0 spot checks")
        if k and module is None:
            rows = {key: v[:0] if isinstance(v, np.ndarray) else v for key, v in rows.items()}
        return SpotChecks(**rows, velocity_deviation_full=np.empty(0),
                          converged_full=np.empty(0, bool), valid_full=np.empty(0, bool),
                          status=status)
    # a ball without a contact state (its carriage was not solved) has nothing to check
    finite = (np.all(np.isfinite(rows["contact_angle_deviation"]), axis=1)
              & np.all(np.isfinite(rows["normal_force"]), axis=1))
    eps_full = np.full(k, np.nan)
    converged = np.zeros(k, bool)
    valid = np.zeros(k, bool)
    if finite.any():
        res = module.full(rows["contact_angle_deviation"][finite],
                          np.maximum(rows["normal_force"][finite], 0.0), config.bearing,
                          groove_velocity=config.motion.groove_velocity)
        eps_full[finite] = np.asarray(res.velocity_deviation, dtype=float)
        conv = np.asarray(getattr(res, "converged", np.ones(finite.sum(), bool)), dtype=bool)
        converged[finite] = conv
        valid[finite] = np.asarray(getattr(res, "valid", conv), dtype=bool) & conv
    n_near = int(np.count_nonzero(rows["stratum"] == 1))
    status = f"{k} balls re-solved with the full model"
    if plan.near_limit:
        status += (f": {k - n_near} drawn uniformly, {n_near} from the {band_balls:,} balls "
                   f"of the fast model with {100 * plan.band[0]:.3g} % ≤ |ε| ≤ "
                   f"{100 * plan.band[1]:.3g} % (near the spec limit)")
    return SpotChecks(**rows, velocity_deviation_full=eps_full, converged_full=converged,
                      valid_full=valid, status=status)
