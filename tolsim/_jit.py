"""Numba jit defaults, in one place.

Kernels are compiled lazily on first call and cached on disk (``cache=True``), so a CLI call
pays compilation once per machine, not once per call. A cached kernel is valid while every
kernel source of the package is unchanged (:class:`KernelTreeStamp`), not only its own file.
"""

import functools
import hashlib
import os
import re
import threading
import time
from pathlib import Path

import numba
import numpy as np
from numba.core import caching as numba_caching
from numba.core import event as numba_event

#: How idle OpenMP threads wait between parallel kernels, unless the environment says
#: otherwise. GNU OpenMP (Numba's ``omp`` threading layer) spins by default; on a machine whose
#: cores are busy with other processes a spinning thread holds a core that the thread it waits
#: for needs, and each launch of a parallel kernel took 2.5-14 ms instead of about 20 us
#: (measured on the 2-core VM at load average 8). Along-track studies launch tens of kernels
#: per step, so this decided their speed (issue 24, "Speed"). Read once, when the OpenMP
#: runtime loads (the first parallel kernel), so it is set here, before any kernel runs.
OMP_WAIT_POLICY = "PASSIVE"
os.environ.setdefault("OMP_WAIT_POLICY", OMP_WAIT_POLICY)

#: Options for every scalar/serial kernel.
JIT = dict(nogil=True, cache=True, fastmath=False, error_model="numpy")
#: Options for kernels that loop over balls with ``numba.prange``.
PJIT = dict(JIT, parallel=True)


#: A line that makes a function a kernel: ``@jit``, ``@pjit`` (with or without options).
_KERNEL_LINE = re.compile(rb"^@p?jit\b", re.M)


@functools.cache
def kernel_sources_digest(root: str) -> bytes:
    """SHA-256 over the kernel sources below ``root``: every ``.py`` file with a line ``@jit``
    or ``@pjit``, and this one (the jit options), by path relative to ``root`` and content.
    Read once per process."""
    digest = hashlib.sha256()
    for path in sorted(Path(root).rglob("*.py")):
        text = path.read_bytes()
        if _KERNEL_LINE.search(text) or path.resolve() == Path(__file__).resolve():
            digest.update(path.relative_to(root).as_posix().encode() + b"\0" + text + b"\0")
    return digest.digest()


class KernelTreeStamp:
    """Mixin of a Numba cache locator: a kernel's cache is stale when *any* kernel source
    below :attr:`root` changed, not only its own file.

    Numba stamps a cached kernel with its own file's hash, but the machine code it saves
    holds the code of every jitted function the kernel calls, from other modules too: after
    a change to a callee's module (a ``git checkout`` in a working tree, an editable
    install), the caller's cache was loaded with the old callee inside and gave the old
    numbers without a word. Here the stamp also holds :func:`kernel_sources_digest`, so a
    change to any kernel source compiles the package's kernels again. Files outside
    ``root`` keep Numba's own stamp.
    """

    #: The package folder whose kernel sources make up the stamp.
    root = str(Path(__file__).resolve().parent)

    def get_source_stamp(self):
        own = super().get_source_stamp()
        if not Path(self._py_file).resolve().is_relative_to(self.root):
            return own
        return own, kernel_sources_digest(self.root)


def _stamped(locator):
    return type(f"KernelTree{locator.__name__}", (KernelTreeStamp, locator), {})


def _install_locators():
    """Put the :class:`KernelTreeStamp` variants of Numba's file-backed locators first. The
    locator list is Numba's private API: if a release moves it, kernels keep Numba's own
    stamps (the gap this closes) rather than fail to load."""
    impl = getattr(numba_caching, "CacheImpl", getattr(numba_caching, "_CacheImpl", None))
    classes = getattr(impl, "_locator_classes", None)
    names = ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")
    found = [getattr(numba_caching, n, None) for n in names]
    if not isinstance(classes, list) or None in found:
        return
    if not any(issubclass(c, KernelTreeStamp) for c in classes):
        classes[:0] = [_stamped(c) for c in found]


_install_locators()


#: Options of a leaf kernel (:func:`jit` with ``leaf=True``): Numba's runtime off, through its
#: private ``_nrt`` option (``tests/integration/test_leaf_kernels.py`` fails if a Numba
#: release stops honouring it).
LEAF = dict(JIT, _nrt=False)


def jit(func=None, leaf=False, **overrides):
    """Decorate a serial kernel with the project defaults.

    ``leaf=True``: a kernel that allocates nothing and reads and writes only the arrays it is
    given, nor does anything it calls: Numba compiles its callees without the runtime too,
    and refuses (a TypingError naming the call) a leaf that allocates, receives a new array
    or calls a function that allocates. It is compiled without Numba's runtime, so it takes
    and releases no reference count on its array arguments. Numba counts a reference for
    every array a function receives or aliases, as an atomic increment and decrement, and
    its pruning pass leaves many of them in code with branches and early returns (numba
    issue #2350). In the circuit's ring step and the carriage's joint Newton, which are
    called per event and per assembly with two dozen arrays, those counts took about 20 % of
    the circuit study and 8 % of the carriage study along the track (perf, session 26). The
    arithmetic is the same: results are bit-identical.
    """
    opts = dict(LEAF if leaf else JIT, **overrides)
    return numba.njit(**opts)(func) if func is not None else numba.njit(**opts)


def pjit(func=None, **overrides):
    """Decorate a kernel that loops over balls in parallel (``prange``)."""
    opts = dict(PJIT, **overrides)
    return numba.njit(**opts)(func) if func is not None else numba.njit(**opts)


def kernel_array(a, dtype=np.float64):
    """``a`` as a writable, C-contiguous array of ``dtype``; a copy only where it is not one.

    Numba compiles a kernel once for every distinct argument type, and a read-only array (a
    broadcast view, say) or one of another layout is another type: inputs passed through
    this reach each kernel with one type, so each is compiled once, not once per caller.
    """
    return np.require(a, dtype=dtype, requirements=("C", "W"))


class _CompileClock(numba_event.Listener):
    """Seconds Numba spent compiling kernels or loading them from its disk cache, in this
    process.

    Numba sends ``numba:compile`` around a compilation only; loading a cached kernel (about
    1 s for a study's kernels in a fresh process) sends nothing of its own. Both happen while
    Numba holds (or waits for) its compiler lock, and it sends ``numba:compiler_lock`` around
    that, so this listens to both, on one nesting count: only the outermost span of a thread
    is timed (a kernel's callees compile or load inside it). Per thread it is the sum of that
    thread's spans; for the process, the time during which any thread was in one (the union
    of the spans, so that two threads waiting for the same lock do not count it twice).
    """

    def __init__(self):
        self._local = threading.local()
        self._lock = threading.Lock()
        self._active = 0  # threads inside a span
        self._process_started = 0.0
        self._process_total = 0.0

    def _state(self):
        state = self._local
        if not hasattr(state, "depth"):
            state.depth, state.started, state.total = 0, 0.0, 0.0
        return state

    def on_start(self, event):
        state = self._state()
        if state.depth == 0:
            now = time.perf_counter()
            state.started = now
            with self._lock:
                if self._active == 0:
                    self._process_started = now
                self._active += 1
        state.depth += 1

    def on_end(self, event):
        state = self._state()
        state.depth -= 1
        if state.depth == 0:
            now = time.perf_counter()
            state.total += now - state.started
            with self._lock:
                self._active -= 1
                if self._active == 0:
                    self._process_total += now - self._process_started

    def seconds(self, thread: bool = True) -> float:
        """Seconds so far (a running total) of the calling thread, or with ``thread=False``
        of the process (time in which any thread compiled or loaded a kernel)."""
        if thread:
            return self._state().total
        with self._lock:
            running = time.perf_counter() - self._process_started if self._active else 0.0
            return self._process_total + running


_CLOCK = _CompileClock()
numba_event.register("numba:compile", _CLOCK)
numba_event.register("numba:compiler_lock", _CLOCK)


def compile_seconds(thread: bool = True) -> float:
    """Seconds spent compiling Numba kernels or loading them from Numba's disk cache so far (a
    running total), by the calling thread or, with ``thread=False``, by this process.

    The difference of two readings is the compilation and loading inside a timed section:
    subtract it to book model time apart from them (compilation: a first run with a cold
    kernel cache; loading: the first call of each kernel in a process).
    """
    return _CLOCK.seconds(thread)
