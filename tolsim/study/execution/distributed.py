"""Run the chunks of a study on a dask.distributed cluster (``tolsim run --scheduler``).

:func:`tolsim.study.execution.runner.run_study` stays the orchestrator: it cuts the study into
chunks of
whole random blocks, merges the per-block accumulators strictly in block order, checkpoints and
stops at a precision target. This module only changes where the chunk results come from: a
:class:`DaskSession` submits them as dask tasks and hands them back in block order
(:meth:`DaskSession.chunk_results`), so the result is bit-identical to the in-process run for
the same seed whatever the number of workers, the task size or the order in which tasks
finish. The full-model spot checks run as one more task (:meth:`DaskSession.spot_checks`).

Design
------
* A task is a run of consecutive chunks (:func:`chunks_per_task`): about :data:`TASK_BALLS`
  balls, fewer when the study is small, so that every worker thread gets at least
  :data:`TASKS_PER_THREAD` tasks. It returns the chunks' ``(block_index, Accumulator,
  spot_rows)`` lists, as :func:`tolsim.study.execution.chunks.run_chunk` does: about 12 kB per
  block,
  never an array per ball (the rows of ``save_samples`` assemblies aside, which are asked for).
* Look-ahead: at most :data:`LOOKAHEAD_PER_THREAD` x (worker threads) + 1 tasks are submitted
  and not yet merged. A task that finishes out of turn keeps its result on its worker until
  the tasks before it are merged; the client fetches one task's result at a time. The client
  thus holds the merged state and at most one task's result, whatever the study's size.
* Faults: the client holds a future for every unmerged task, so when a worker dies the
  scheduler reruns the tasks it was running and those whose results it held (up to
  ``distributed.scheduler.allowed-failures`` deaths per task). A task is a pure function of
  (config, blocks): a rerun gives the same bits. A killed client loses only what its
  checkpoint does not hold; the scheduler drops its tasks.
* Threads: a task runs Numba's kernels on its machine's cores divided by the dask worker
  threads on that machine (so ``dask worker --nworkers N --nthreads T`` in any combination
  fills the cores once), and never on more than ``NUMBA_NUM_THREADS``. Where Numba has only
  its ``workqueue`` threading layer (no OpenMP or TBB), which cannot run two parallel kernels
  at once, the tasks of one worker process run one at a time.
* Versions: a task refuses to run (``ValueError``) on a worker whose tolsim, NumPy, SciPy or
  Numba version differs from the client's: the random streams and the kernels must be the
  same for the result to be.

dask.distributed is an optional dependency (``pip install "tolsim[dask]"``); this module
imports it only when it is used (:func:`require_distributed`).
"""

import importlib.util
import logging
import os
import signal
import threading
import time
import uuid
import warnings
from collections import deque
from concurrent.futures import CancelledError

import numba
import numpy as np
import scipy

from tolsim import __version__
from tolsim.study.execution.chunks import finish_spot_checks, prefetched, retain_freed_memory

#: What to install for ``--scheduler`` (the package's optional extra).
INSTALL_HINT = 'pip install "tolsim[dask]"'
#: Balls per task, about: 1 s on one core of the development machine, so that the cost of a
#: task to the cluster (13-30 ms of worker time, ``benchmarks/bench_dask.py``) stays a few
#: per cent. The scheduler then sees (worker threads) tasks per second: on hundreds of
#: threads, larger tasks keep that within its means (about 1000 tasks/s).
TASK_BALLS = 1 << 21
#: Smallest number of tasks per worker thread before tasks are made smaller (load balance,
#: and the work that a lost worker takes with it).
TASKS_PER_THREAD = 4
#: Tasks submitted ahead per worker thread (see the module docstring).
LOOKAHEAD_PER_THREAD = 2
#: Seconds between two looks at the cluster's workers during a run (it may grow or shrink).
REFRESH_SECONDS = 2.0
#: ``--scheduler`` value that starts a LocalCluster (``local`` or ``local:N``).
LOCAL = "local"

_USAGE = ("expected tcp://HOST:PORT (a running dask scheduler), the path of a scheduler file "
          "(dask scheduler --scheduler-file FILE), or local[:N] (a LocalCluster of N worker "
          "processes on this machine)")


class SchedulerError(ValueError):
    """A ``--scheduler`` that cannot be used: a bad value, an unreachable scheduler, a task
    the cluster lost."""


class MissingExtraError(ImportError):
    """dask.distributed is not installed (``pip install "tolsim[dask]"``)."""


def require_distributed():
    """Import and return ``distributed``, or raise :class:`MissingExtraError` saying what to
    install."""
    try:
        import distributed  # noqa: PLC0415  optional extra (tolsim[dask])
    except ImportError:
        raise MissingExtraError(f"--scheduler needs dask.distributed, which is not installed: "
                                f"{INSTALL_HINT}") from None
    return distributed


def parse_scheduler(text: str):
    """What a ``--scheduler`` value asks for.

    Parameters
    ----------
    text : str
        ``local`` or ``local:N``, a scheduler address (``tcp://host:8786``, ``tls://...``,
        ``host:8786``), or the path of an existing scheduler file.

    Returns
    -------
    (kind, value) : ("local", workers), ("address", address) or ("file", path)
        ``workers``: N, or the number of cores for plain ``local``.

    Raises
    ------
    SchedulerError
        Naming the value, for anything else.
    """
    raw = str(text).strip()
    if raw == LOCAL or raw.startswith(LOCAL + ":"):
        count = raw[len(LOCAL) + 1:] if raw != LOCAL else str(_cores())
        if not (count.isdigit() and int(count) >= 1):
            raise SchedulerError(f"--scheduler {text!r}: the number of workers in local:N must "
                                 "be a positive integer")
        return LOCAL, int(count)
    if "://" in raw:
        return "address", raw
    if os.path.isfile(raw):
        return "file", raw
    host, _, port = raw.rpartition(":")
    if host and port.isdigit() and os.sep not in raw:
        return "address", f"tcp://{raw}"
    if raw.endswith(".json") or os.sep in raw:
        raise SchedulerError(f"--scheduler {text!r}: no such scheduler file")
    raise SchedulerError(f"--scheduler {text!r}: {_USAGE}")


def connect(scheduler: str, *, timeout=None):
    """A dask client for ``scheduler`` (see :func:`parse_scheduler`).

    Parameters
    ----------
    scheduler : str
    timeout : float, optional
        Seconds to reach the scheduler (default: dask's ``distributed.comm.timeouts.connect``,
        30 s).

    Returns
    -------
    (client, cluster, dashboard_link)
        ``cluster``: the LocalCluster started for ``local[:N]`` (None otherwise);
        ``dashboard_link``: the scheduler's dashboard URL, or None when it runs none.

    Raises
    ------
    MissingExtraError
        dask.distributed is not installed.
    SchedulerError
        A bad value, or no scheduler answered in time.
    """
    distributed = require_distributed()
    kind, value = parse_scheduler(scheduler)
    cluster = None
    wait = {} if timeout is None else {"timeout": timeout}
    try:
        if kind == LOCAL:
            # single-threaded worker processes, their kernels sharing the cores; with the
            # dashboard's port 8787 taken (another run) dask takes a free one and warns: the
            # link returned is the one it took, so the warning says nothing more
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message=r"Port \d+ is already in use",
                                        category=UserWarning)
                cluster = distributed.LocalCluster(
                    n_workers=value, threads_per_worker=1, processes=True,
                    env={"NUMBA_NUM_THREADS": str(max(1, _cores() // value))},
                    preload=[__name__], silence_logs=logging.ERROR)
            client = distributed.Client(cluster, set_as_default=False)
        elif kind == "file":
            client = distributed.Client(scheduler_file=value, set_as_default=False, **wait)
        else:
            client = distributed.Client(value, set_as_default=False, **wait)
    except (OSError, TimeoutError) as exc:
        if cluster is not None:
            cluster.close()
        where = f"the scheduler file {value}" if kind == "file" else value
        raise SchedulerError(f"cannot reach the dask scheduler at {where}: {_one_line(exc)}. "
                             "Is it running, and is the address right (tcp://HOST:PORT, "
                             "default port 8786)? On this machine alone, use --scheduler "
                             "local:N") from None
    except Exception as exc:  # noqa: BLE001 - something answered, but not as a scheduler
        if cluster is not None or kind == "local":
            raise
        where = f"the scheduler file {value}" if kind == "file" else value
        raise SchedulerError(f"{where} answered, but not as a dask scheduler "
                             f"({exc.__class__.__name__}: {_one_line(exc)}): a worker's or "
                             "another service's address? Give the scheduler's (tcp://HOST:PORT, "
                             "default port 8786), or on this machine alone --scheduler "
                             "local:N") from None
    return client, cluster, _dashboard_link(client)


def chunks_per_task(chunks, balls_per_chunk: int, threads: int) -> int:
    """Chunks grouped into one task: about :data:`TASK_BALLS` balls, but few enough that
    each of ``threads`` worker threads gets :data:`TASKS_PER_THREAD` tasks."""
    by_size = max(1, TASK_BALLS // max(1, balls_per_chunk))
    by_count = max(1, len(chunks) // (TASKS_PER_THREAD * max(1, threads)))
    return min(by_size, by_count)


def task_size(chunks, balls_per_block: int, threads: int) -> int:
    """:func:`chunks_per_task` for ``run_study``'s chunks, sized by the largest chunk: the
    first may be a single block (the probe of ``require_answer``), far smaller than the rest,
    and sizing by it would put hundreds of full chunks into one task (a task of 5e7 balls
    where 2e6 was meant, slow to interrupt)."""
    largest = max(len(c) for c in chunks[:2])  # only the first chunk can differ
    return chunks_per_task(chunks, largest * balls_per_block, threads)


class DaskSession:
    """A connection to a dask cluster, for one or more studies.

    Parameters
    ----------
    scheduler : str, distributed.Client or a dask cluster object
        A ``--scheduler`` value (:func:`parse_scheduler`); a connected Client, used as it is
        and left open by :meth:`close`; or a cluster (a ``dask_jobqueue.SLURMCluster``, say),
        to which the session connects a client of its own (the cluster is left running).
    notify : callable, optional
        Called with one-line messages: the cluster and its dashboard, waiting for workers.
    timeout : float, optional
        Seconds to reach the scheduler (:func:`connect`).
    """

    def __init__(self, scheduler, notify=None, timeout=None):
        distributed = require_distributed()
        say = notify or (lambda message: None)
        self.cluster = None  # a LocalCluster started here (closed by close())
        if isinstance(scheduler, distributed.Client):
            self.client, self.owned = scheduler, False
        elif isinstance(scheduler, distributed.deploy.Cluster):
            self.client, self.owned = distributed.Client(scheduler, set_as_default=False), True
        else:
            self.client, self.cluster, _ = connect(scheduler, timeout=timeout)
            self.owned = True
        try:
            self.dashboard_link = _dashboard_link(self.client)
            self.versions = _versions()
            self.address = self.client.scheduler.address
            if not self.client.nthreads():
                say(f"waiting for dask workers to join the scheduler {self.address}")
                self.client.wait_for_workers(1)
        except BaseException:  # Ctrl-C while waiting, say: nothing left running
            self.close()
            raise
        self._looked = -np.inf
        self._layout = {}
        self.workers = len(self.client.nthreads())
        where = ("a LocalCluster" if self.cluster is not None
                 else f"the dask scheduler {self.address}")
        message = f"running on {where}: {self.workers} workers, {self.threads()} threads"
        if self.dashboard_link:
            message += f"; dashboard {self.dashboard_link}"
            if self.cluster is not None and importlib.util.find_spec("bokeh") is None:
                message += " (after pip install bokeh)"
        say(message)

    def threads_per_host(self) -> dict:
        """{host: dask worker threads on it}, looked up at most every
        :data:`REFRESH_SECONDS`."""
        now = time.monotonic()
        if now - self._looked >= REFRESH_SECONDS:
            from distributed.comm import get_address_host  # noqa: PLC0415  optional dask

            layout = {}
            for address, threads in self.client.nthreads().items():
                host = get_address_host(address)
                layout[host] = layout.get(host, 0) + int(threads)
            self._layout, self._looked = layout, now
        return self._layout

    def threads(self) -> int:
        """Worker threads in the cluster (at least 1)."""
        return max(1, sum(self.threads_per_host().values()))

    def chunk_results(self, config, chunks, spot_indices, save_samples=0):
        """The results of ``chunks.run_chunk`` over ``chunks``, in order, computed by tasks.

        Parameters
        ----------
        config : tolsim.study.spec.StudyConfig
        chunks : list of list of int
            Consecutive block indices, as :func:`tolsim.study.execution.runner.run_study` cuts them.
        spot_indices : tolsim.study.sampling.SpotCheckPlan
        save_samples : int

        Yields
        ------
        list of (block_index, Accumulator, spot_rows)
            One chunk's result, in chunk order, as ``run_chunk`` returns it.

        Closing the generator early (a precision target, an interrupt) cancels the tasks not
        yet merged.
        """
        if not chunks:
            return
        balls = getattr(config, "balls", config.train.balls)  # per assembly
        size = task_size(chunks, config.study.block_size * balls, self.threads())
        tasks = [chunks[i:i + size] for i in range(0, len(chunks), size)]
        token = uuid.uuid4().hex[:8]
        pending = deque()  # futures of the submitted tasks not yet merged, in task order
        submitted = 0
        try:
            for _ in range(len(tasks)):
                window = LOOKAHEAD_PER_THREAD * self.threads() + 1
                while submitted < len(tasks) and len(pending) < window:
                    task = tasks[submitted]
                    pending.append(self.client.submit(
                        _run_task, config, task, spot_indices, save_samples,
                        self._context(), key=f"tolsim-blocks-{task[0][0]}-{task[-1][-1]}-"
                                             f"{token}", priority=-submitted, pure=False))
                    submitted += 1
                future = pending.popleft()
                result = self._result(future)  # waits for it; later tasks keep running
                future.release()
                yield from result
        finally:
            if pending:
                self.client.cancel(list(pending))

    def spot_checks(self, config, rows):
        """:func:`tolsim.study.execution.chunks.finish_spot_checks` as a task (the full-model
        re-solves of the recorded candidates)."""
        future = self.client.submit(_run_spot_checks, config, rows, self._context(),
                                    key=f"tolsim-spot-checks-{uuid.uuid4().hex[:8]}",
                                    pure=False)
        try:
            return self._result(future)
        finally:
            future.release()

    def close(self):
        """Close the client and a LocalCluster this session started (not a Client that was
        passed in). Safe to call twice."""
        if self.owned:
            self.owned = False
            self.client.close()
            if self.cluster is not None:
                self.cluster.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def _context(self) -> dict:
        """What a task checks and needs on its worker (:class:`_TaskContext`)."""
        return {"versions": self.versions, "threads_per_host": self.threads_per_host()}

    def _result(self, future):
        """The result of a task. A task dask gave up on, or one lost with the scheduler,
        raises a one-line :class:`SchedulerError`; an error of the task itself passes as it
        is."""
        distributed = require_distributed()
        try:
            return future.result()
        except distributed.KilledWorker as exc:
            raise SchedulerError(
                f"dask gave up on task {future.key}: all {exc.allowed_failures + 1} workers "
                f"that ran it died (the last one {exc.last_worker.address}); out of memory? "
                "Its worker's log says more") from None
        except CancelledError as exc:
            raise SchedulerError(
                f"lost task {future.key} on the dask scheduler {self.address} "
                f"({_one_line(exc)}); run again to resume from the last checkpoint") from None


# --- on the workers ---------------------------------------------------------------------------
_prepared = False
_one_task_at_a_time = threading.Lock()


def dask_setup(worker):
    """Preload of the LocalCluster's workers: Ctrl-C in the terminal reaches the whole
    process group, and only the client is to act on it (save the checkpoint, close the
    cluster), not the workers, each with a traceback of its own; nor does a worker whose
    heartbeat finds the scheduler already closed (:func:`quiet_heartbeat`)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker").addFilter(quiet_heartbeat)


#: What a LocalCluster's worker logs, with a traceback, when its heartbeat finds the scheduler
#: closed: on Ctrl-C the client closes the cluster while a worker may be between heartbeats.
HEARTBEAT_FAILURE = "Failed to communicate with scheduler during heartbeat"


def quiet_heartbeat(record) -> bool:
    """Logging filter of a LocalCluster's workers: drop the heartbeat failure
    (:data:`HEARTBEAT_FAILURE`), which at the cluster's close is expected; a scheduler lost
    during a run reaches the client as a one-line :class:`SchedulerError` (its tasks are
    lost), so nothing is hidden that the user would not see."""
    return not record.getMessage().startswith(HEARTBEAT_FAILURE)


def _run_task(config, chunks, spot_indices, save_samples, context):
    """One task: ``run_chunk`` over consecutive chunks, the next chunk drawn in a thread while
    one is evaluated (:func:`tolsim.study.execution.chunks.prefetched`)."""
    with _TaskContext(context):
        return list(prefetched(config, chunks, spot_indices, save_samples))


def _run_spot_checks(config, rows, context):
    with _TaskContext(context):
        return finish_spot_checks(config, rows)


class _TaskContext:
    """A task on a worker: the same versions as the client, freed memory retained for the
    next task, Numba's threads set for this task (tasks of a process serialised where Numba's
    threading layer needs it).

    ``context``: {"versions": the client's :func:`_versions`, "threads_per_host": {host: dask
    worker threads}}.
    """

    def __init__(self, context):
        expected, found = context["versions"], _versions()
        if found != expected:
            differ = ", ".join(f"{name} {found[name]} (client {expected.get(name)})"
                               for name in found if found[name] != expected.get(name))
            raise ValueError(f"a dask worker has other versions: {differ}; install the same "
                             "tolsim, NumPy, SciPy and Numba on the workers as on the client, "
                             "or the results would differ")
        self.threads_per_host = context["threads_per_host"]
        self.lock = None

    def __enter__(self):
        global _prepared
        if not _prepared:
            retain_freed_memory()
            _prepared = True
        host, worker_threads = _this_worker()
        on_host = self.threads_per_host.get(host, 0)
        # cores per dask thread on this machine (without the layout: NUMBA_NUM_THREADS's)
        share = (_cores() / on_host if on_host >= worker_threads
                 else numba.config.NUMBA_NUM_THREADS / worker_threads)
        if _workqueue_only():
            self.lock = _one_task_at_a_time
            self.lock.acquire()
            share *= worker_threads  # this process's threads are idle meanwhile
        numba.set_num_threads(min(numba.config.NUMBA_NUM_THREADS, max(1, int(share))))
        return self

    def __exit__(self, *exc):
        if self.lock is not None:
            self.lock.release()
        return False


def _workqueue_only() -> bool:
    """True when Numba's threading layer is (or may become) ``workqueue``, which cannot run
    parallel kernels from two threads at once."""
    try:
        return numba.threading_layer() == "workqueue"
    except ValueError:  # no parallel kernel has run in this process yet: be safe
        return True


def _this_worker():
    """(host, dask threads) of the worker running this task; (None, 1) outside one."""
    try:
        from distributed import get_worker  # noqa: PLC0415  optional dask
        from distributed.comm import get_address_host  # noqa: PLC0415  optional dask

        worker = get_worker()
        return get_address_host(worker.address), max(1, int(worker.state.nthreads))
    except (ImportError, ValueError, AttributeError):
        return None, 1


# --- helpers ----------------------------------------------------------------------------------
def _versions() -> dict:
    """The versions that decide the bits of a result."""
    return {"tolsim": __version__, "numpy": np.__version__, "scipy": scipy.__version__,
            "numba": numba.__version__}


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _dashboard_link(client):
    """The scheduler's dashboard URL, or None when it runs none (bokeh not installed)."""
    try:
        services = client.scheduler_info().get("services", {})
    except (OSError, TimeoutError, AttributeError):
        return None
    return client.dashboard_link if "dashboard" in services else None


def _one_line(exc) -> str:
    return " ".join(str(exc).split()).rstrip(".") or type(exc).__name__
