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
import multiprocessing
import numbers
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from numba.core import event as numba_event

from tolsim import __version__
from tolsim._interrupts import interrupts_held
from tolsim._jit import compile_seconds
from tolsim.study.analyses.friction_examples import friction_examples
from tolsim.study.analyses.limit_state import check_supported, estimate_events
from tolsim.study.analyses.sensitivity import study_sensitivity
from tolsim.study.analyses.worst_case import linear_stackup
from tolsim.study.execution import saved_samples
from tolsim.study.execution.answerable import check_answerable
from tolsim.study.execution.chunks import (
    EXAMPLE_ORDER,
    SPOT_FIELDS,
    SpotChecks,
    concat_spots,
    example_order,
    finish_spot_checks,
    prefetched,
    retain_freed_memory,
    run_chunk,
)
from tolsim.study.execution.distributed import DaskSession
from tolsim.study.pipeline.block import has_carriage, has_contact
from tolsim.study.pipeline.carriage import solve_config_carriage
from tolsim.study.sampling import (
    SPOT_CHECK_SCHEME,
    n_blocks,
    near_limit_cut,
    near_limit_kept,
    spot_check_plan,
)
from tolsim.study.spec import MAX_WORKERS, StudyConfig, whole_number
from tolsim.study.statistics.accumulator import Accumulator
from tolsim.study.statistics.friction import accumulator_from_state, study_accumulator

#: Balls evaluated together in one chunk (sets the default ``chunk_blocks``).
CHUNK_BALLS = 1 << 18



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
    # tolsim.study.analyses.friction_examples.FrictionExamples ([contact])
    friction_examples: object = None
    # a rare-event estimator (study.estimator): event ->
    # tolsim.study.analyses.limit_state.EventEstimate
    rare_events: dict | None = None
    # Numba compilation and kernel-cache loading in this process [s]: in the whole run, and
    # inside ``elapsed``
    compile_seconds: float = 0.0
    loop_compile_seconds: float = 0.0
    assemblies_run: int | None = None  # evaluated in this process (None: all of them)

    @property
    def balls_per_second(self) -> float:
        """Throughput of the work done in this process: the balls of the assemblies it
        evaluated (after a resume, only those) over ``elapsed`` without compilation."""
        done = (int(self.statistics.n_assemblies) if self.assemblies_run is None
                else self.assemblies_run)
        seconds = self.elapsed - self.loop_compile_seconds
        return done * self.config.balls / seconds if seconds > 0 else float("nan")

    @property
    def friction(self):
        """The friction statistics of a study with ``[contact]``
        (:class:`tolsim.study.statistics.friction.FrictionStatistics`), else None."""
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
            raise ValueError(f"target width {self.width!r} must be in (0, 1) when absolute "
                             "(such as 0.005), or > 0 when relative (such as 10%)")

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
        except ValueError:
            raise ValueError(f"expected a width such as 0.005 or a relative width such as "
                             f"10%, got {text!r}") from None
        return cls(value / 100 if relative else value, relative)  # (its range, said)

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
    """Identity of a study for resuming: config text and settings, tolsim version.

    Not the path the config was read from: ``study.toml``, ``./study.toml`` and its absolute
    path are one study (what the path reaches, the measured-data files, is in the settings by
    its SHA-256).
    """
    h = hashlib.sha256()
    h.update(config.text.encode())
    h.update(repr(replace(config, path="")).encode())
    h.update(__version__.encode())
    h.update(SPOT_CHECK_SCHEME.encode())
    return h.hexdigest()


def checkpoint_mismatch(path, config) -> str | None:
    """None if ``path`` is a checkpoint of ``config``'s study, else what differs, as a
    clause ("its config differs at line 3: ...").

    A checkpoint keeps its study's config text and tolsim version beside the fingerprint
    (checkpoints written before session 25 keep the fingerprint alone, and get the general
    clause).

    Raises
    ------
    OSError, ValueError and numpy's or zipfile's errors
        If ``path`` cannot be read as a checkpoint.
    """
    with np.load(path, allow_pickle=False) as data:
        if str(data["fingerprint"]) == fingerprint(config):
            return None
        if not {"config_text", "tolsim_version"} <= set(data.files):
            return "its config, seed, samples or tolsim version differ"
        text, version = str(data["config_text"]), str(data["tolsim_version"])
    if version != __version__:
        return f"it was written by tolsim {version}, this is tolsim {__version__}"
    if text != config.text:
        theirs, ours = text.splitlines(keepends=True), config.text.splitlines(keepends=True)
        line = next((i for i, (a, b) in enumerate(zip(theirs, ours, strict=False)) if a != b),
                    min(len(theirs), len(ours)))
        a, b = (lines[line] if line < len(lines) else None for lines in (theirs, ours))
        if a is None or b is None or a.rstrip("\r\n") != b.rstrip("\r\n"):
            a, b = (x and x.rstrip("\r\n") for x in (a, b))  # line ends: only if they differ
        # from a little before the first character that differs (trailing blanks and line
        # ends included), so the two never look the same
        column = next((i for i, (x, y) in enumerate(zip(a or "", b or "", strict=False))
                       if x != y),
                      min(len(a or ""), len(b or "")))
        start = max(0, column - 30) if column > 50 else 0

        def shown(part):
            return "the end" if part is None else repr(part[start:start + 60].lstrip(" "))

        return f"its config differs at line {line + 1}: {shown(a)} there, {shown(b)} here"
    return ("its settings differ with the same config text (a config changed in Python, or "
            "another spot-check scheme)")


def default_chunk_blocks(config) -> int:
    """Blocks per chunk so that a chunk holds about :data:`CHUNK_BALLS` balls."""
    per_block = config.study.block_size * config.balls
    return max(1, CHUNK_BALLS // per_block)


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


class _NearLimitPruner:
    """Drops the committed near-limit spot-check rows that can no longer be chosen.

    Each block records up to ``near_limit`` candidates near the spec limit, and only the
    ``near_limit`` smallest keys of all blocks are spot-checked
    (:func:`tolsim.study.sampling.near_limit_cut`): without pruning, a long study's
    memory and checkpoints grow by a block's candidates per block (22 MB after 18 000
    blocks of ``configs/yaw_moment_tolerances.toml``). The spot checks are the same.
    Called after each commit with the parts and ``next_block``; it looks only at the blocks
    committed since its last call and at those still holding near-limit rows.
    """

    def __init__(self, plan):
        self.plan = plan
        self.seen = 0
        self.holders = []  # committed blocks that still hold near-limit rows

    def __call__(self, parts, next_block: int):
        if not self.plan.near_limit or next_block <= self.seen:
            return
        blocks = self.holders + list(range(self.seen, next_block))
        self.seen = next_block
        cut = near_limit_cut(self.plan, *(np.concatenate([parts[i][k] for i in blocks])
                                          for k in ("ball_index", "stratum")))
        for i in blocks:
            part = parts[i]
            keep = near_limit_kept(self.plan, part["ball_index"], part["stratum"], cut)
            if not keep.all():
                parts[i] = {k: v[keep] if k in SPOT_FIELDS and k != "band_balls" else v
                            for k, v in part.items()}
        self.holders = [i for i in blocks if np.any(parts[i]["stratum"] == 1)]


class DamagedCheckpoint(ValueError):
    """A checkpoint file that cannot be read: truncated, damaged, or not a checkpoint."""


def _save_checkpoint(path, fp, state: _Progress, config_text: str):
    """Write ``state`` to ``path`` through a temporary file and a rename (atomic), with the
    study's fingerprint and, to say what differs when it is refused, its config text and
    tolsim version (:func:`checkpoint_mismatch`).

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
    arrays.update({f"spot_{k}": v for k, v in concat_spots(parts).items()})
    # rows per block and field, to split the rows into blocks again
    arrays["part_lengths"] = np.array([[len(p[k]) for k in SPOT_FIELDS] for p in parts],
                                      dtype=np.int64).reshape(len(parts), len(SPOT_FIELDS))
    order = example_order(parts)
    if order is not None:  # the friction examples' choice, for a resumed run
        arrays[EXAMPLE_ORDER] = order
    try:
        with interrupts_held():  # Ctrl-C inside the zip writer replaced itself with an error
            with open(tmp, "wb") as fh:
                np.savez(fh, fingerprint=np.array(fp), next_block=np.int64(state.next_block),
                         config_text=np.array(config_text),
                         tolsim_version=np.array(__version__), **arrays)
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
            order = data[EXAMPLE_ORDER] if EXAMPLE_ORDER in data.files else None
    except Exception as exc:  # noqa: BLE001 - zipfile, zlib, numpy and OS errors alike
        reason = " ".join(f"{type(exc).__name__}: {exc}".split())
        raise DamagedCheckpoint(f"checkpoint {path} cannot be read, it is damaged or "
                                f"truncated ({reason[:120]})") from None
    if lengths.shape != (next_block, len(SPOT_FIELDS)):
        raise DamagedCheckpoint(f"checkpoint {path} is inconsistent (part_lengths "
                                f"{lengths.shape} for {next_block} blocks)")
    broken = acc.inconsistency()
    if broken:
        raise DamagedCheckpoint(f"checkpoint {path} is inconsistent ({broken})")
    pieces = {k: np.split(v, np.cumsum(lengths[:, j])[:-1]) if next_block else []
              for j, (k, v) in enumerate(spots.items())}
    parts = [{k: pieces[k][i] for k in SPOT_FIELDS} for i in range(next_block)]
    if parts and order is not None:
        parts[0][EXAMPLE_ORDER] = order
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


def _checked_arguments(config, workers, save_samples, chunk_blocks, max_blocks, target,
                       progress, notify, checkpoint_interval, checkpoint_path, require_answer):
    """:func:`run_study`'s arguments checked before any work, each bad one named in a
    ValueError; returns (workers, save_samples, chunk_blocks, max_blocks) as ints (NumPy
    integers taken, bools refused: :func:`~tolsim.study.spec.whole_number`)."""
    if not isinstance(config, StudyConfig):
        raise ValueError(f"config = {config!r:.60} must be a StudyConfig: read it with "
                         "tolsim.load_config(path) or tolsim.parse_config(text)")
    workers = whole_number("workers", workers, 1, MAX_WORKERS)
    save_samples = whole_number("save_samples", save_samples, 0)
    if chunk_blocks is not None:
        chunk_blocks = whole_number("chunk_blocks", chunk_blocks, 1)
    if max_blocks is not None:
        max_blocks = whole_number("max_blocks", max_blocks, 1)
    if target is not None and not isinstance(target, PrecisionTarget):
        raise ValueError(f"target = {target!r} must be a PrecisionTarget (or None)")
    if not isinstance(require_answer, bool | np.bool_):
        raise ValueError(f"require_answer = {require_answer!r} must be True or False")
    for name, value in (("progress", progress), ("notify", notify)):
        if value is not None and not callable(value):
            raise ValueError(f"{name} = {value!r} must be callable (or None)")
    if isinstance(checkpoint_interval, bool) or not isinstance(
            checkpoint_interval, numbers.Real) or not checkpoint_interval >= 0:
        raise ValueError(f"checkpoint_interval = {checkpoint_interval!r} must be a number of "
                         "seconds >= 0")
    if checkpoint_path is not None:
        if not isinstance(checkpoint_path, str | os.PathLike) or not os.fspath(
                checkpoint_path) or os.path.isdir(checkpoint_path):
            raise ValueError(f"checkpoint_path = {checkpoint_path!r} must be the path of a "
                             "file (str or os.PathLike)")
        folder = os.path.dirname(os.path.abspath(os.fspath(checkpoint_path)))
        if not os.path.isdir(folder):
            raise ValueError(f"checkpoint_path = {os.fspath(checkpoint_path)!r}: the folder "
                             f"{folder} does not exist")
    return workers, save_samples, chunk_blocks, max_blocks


def run_study(config, *, workers: int = 1, chunk_blocks: int | None = None, progress=None,
              checkpoint_path=None, checkpoint_interval: float = 30.0,
              max_blocks: int | None = None, target: PrecisionTarget | None = None,
              notify=None, save_samples: int = 0, scheduler=None,
              require_answer: bool = False) -> StudyResult:
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
    require_answer : bool
        Refuse a study that cannot answer: if no train of the first block resolves, raise
        :class:`~tolsim.study.execution.answerable.UnanswerableStudy` (a ValueError naming the
        cause and the config keys) right after that block, before any checkpoint is written
        (:func:`~tolsim.study.execution.answerable.check_answerable`). The first block is then
        evaluated alone, as a chunk of its own (no effect on the result). ``tolsim run`` sets
        it for a single study (not for the points of a sweep); False (default) runs such a
        study to the end, its trains counted as unresolved.

    Returns
    -------
    StudyResult

    Raises
    ------
    UnanswerableStudy
        With ``require_answer``, if every train of the first block is unresolved.
    """
    workers, save_samples, chunk_blocks, max_blocks = _checked_arguments(
        config, workers, save_samples, chunk_blocks, max_blocks, target, progress, notify,
        checkpoint_interval, checkpoint_path, require_answer)
    if config.sweep is not None:
        raise ValueError(f"{config.path} has a [sweep] of {config.sweep.size} points: run them "
                         "with tolsim.io.sweep.run_sweep (tolsim run does), or one of "
                         "config.sweep.points")
    if scheduler is not None and workers != 1:
        raise ValueError(f"workers = {workers} and a scheduler: the scheduler's workers do the "
                         "work (local:N starts N of them); leave workers at 1")
    if config.study.estimator != "monte_carlo":  # before any work
        check_supported(config)
        if target is not None:
            raise ValueError(f"a precision target applies to plain Monte Carlo; with "
                             f"estimator = {config.study.estimator!r} the interval comes from "
                             "the estimator (set samples_per_level or importance_samples)")
    retain_freed_memory()
    st = config.study
    total_blocks = n_blocks(st.samples, st.block_size)
    if chunk_blocks is None:
        chunk_blocks = default_chunk_blocks(config)
    spot_indices = spot_check_plan(config)
    fp = fingerprint(config)
    # The committed state: replaced as a whole, never changed (module docstring).
    committed = _Progress(0, study_accumulator(config), [])
    if checkpoint_path is not None and os.path.exists(checkpoint_path):
        loaded = _load_checkpoint(checkpoint_path, fp)
        if loaded is None:
            _say(notify, f"replacing {checkpoint_path}: it is a checkpoint of another study "
                         f"({checkpoint_mismatch(checkpoint_path, config)}); starting afresh "
                         "(tolsim run refuses to)")
        elif loaded.next_block:
            committed = loaded
            done = int(committed.statistics.n_assemblies)
            _say(notify, f"resumed from {checkpoint_path}: {_count(done)} of "
                         f"{_count(st.samples)} assemblies already done")
            if progress:
                progress(done)
    resumed = committed.next_block
    done_before = int(committed.statistics.n_assemblies)
    compiled_before = compile_seconds(thread=False)
    # a checkpoint saved just after the target was met: nothing left to run
    reached = bool(target is not None and resumed and target.reached(committed.statistics))
    last_block = resumed if reached else total_blocks
    started = time.perf_counter()
    probe = require_answer and resumed == 0 and last_block > 1 and chunk_blocks > 1
    first = 1 if probe else resumed  # the first block alone: decided before the others run
    chunks = ([[0]] if probe else []) + [list(range(i, min(i + chunk_blocks, last_block)))
                                         for i in range(first, last_block, chunk_blocks)]
    notice = _CompileNotice(lambda: _say(notify, COMPILING_MESSAGE))
    prune = _NearLimitPruner(spot_indices)
    results = executor = watch = session = None
    loop_ended = False
    last_save = time.perf_counter()
    merged_here = 0
    numba_event.register("numba:compile", notice)
    try:
        if scheduler is not None:  # tasks on dask.distributed, merged below in block order
            session = DaskSession(scheduler, notify=notify)
            workers = session.workers  # recorded in the result
            results = session.chunk_results(config, chunks, spot_indices, save_samples)
        elif workers == 1:
            results = prefetched(config, chunks, spot_indices, save_samples)
        else:
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
                prune(committed.spot_parts, committed.next_block)
                merged_here += 1
                if require_answer and committed.next_block == 1:
                    check_answerable(config, committed.statistics)
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
                _save_checkpoint(checkpoint_path, fp, committed, config.text)
                last_save = now
            if stop and committed.next_block < total_blocks:
                raise StudyInterrupted(
                    f"stopped after {committed.next_block} of {total_blocks} blocks")
        loop_ended = True
    except KeyboardInterrupt:
        # Ctrl-C: keep what is merged; only a committed state, never one half-merged
        if checkpoint_path is not None and committed.next_block > resumed:
            _save_checkpoint(checkpoint_path, fp, committed, config.text)
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
    loop_compile = compile_seconds(thread=False) - compiled_before
    acc = committed.statistics
    n_done = int(acc.n_assemblies)
    result_config = config
    parts = committed.spots()
    if n_done < st.samples:  # stopped at the target: the study of n_done assemblies
        result_config = config.with_overrides(samples=n_done)
        parts = _spot_rows_of_shorter_run(result_config, spot_indices, parts)
    if session is None:
        spots = finish_spot_checks(result_config, concat_spots(parts))
    else:  # as a task; then the session is closed
        with session:
            spots = session.spot_checks(result_config, concat_spots(parts))
    samples = saved_samples.take(result_config, parts, save_samples, spot_indices, run_chunk)
    meta = {"spot_check_seconds": time.perf_counter() - started - elapsed}
    sensitivity = None
    if config.study.sensitivity_samples:
        t0 = time.perf_counter()
        sensitivity = study_sensitivity(result_config,
                                        samples=config.study.sensitivity_samples)
        meta["sensitivity_seconds"] = time.perf_counter() - t0
    # worst case and RSS: one small evaluation (of free balls; not for a carriage, whose
    # balls are coupled through it)
    stackup = None if has_carriage(config) else linear_stackup(result_config)
    nominal = None
    if has_carriage(config):  # the load distribution without tolerances
        try:
            nominal = solve_config_carriage(config)
        except ValueError:  # recorded as NaN; the sampled assemblies were counted anyway
            nominal = None
    examples = (friction_examples(result_config, example_order(parts))
                if has_contact(config) else None)
    rare = None
    if config.study.estimator != "monte_carlo":  # after the plain run (module docstring)
        t0 = time.perf_counter()
        rare = estimate_events(result_config, batch_size=st.block_size, notify=notify)
        meta["rare_event_seconds"] = time.perf_counter() - t0
    return StudyResult(result_config, acc, spots, elapsed, workers, resumed, meta, sensitivity,
                       target=target, target_reached=reached, samples_maximum=st.samples,
                       stackup=stackup, samples=samples, carriage_nominal=nominal,
                       friction_examples=examples, rare_events=rare,
                       compile_seconds=compile_seconds(thread=False) - compiled_before,
                       loop_compile_seconds=loop_compile,
                       assemblies_run=n_done - done_before)


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
