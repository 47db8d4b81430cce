"""Numba jit defaults, in one place.

Kernels are compiled lazily on first call and cached on disk (``cache=True``), so a CLI call
pays compilation once per machine, not once per call.
"""

import threading
import time

import numba
import numpy as np
from numba.core import event as numba_event

#: Options for every scalar/serial kernel.
JIT = dict(nogil=True, cache=True, fastmath=False, error_model="numpy")
#: Options for kernels that loop over balls with ``numba.prange``.
PJIT = dict(JIT, parallel=True)


def jit(func=None, **overrides):
    """Decorate a serial kernel with the project defaults."""
    opts = dict(JIT, **overrides)
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
    """Seconds Numba spent compiling in this process, per thread (``numba:compile`` events).

    Only the outermost compilation of a thread is timed (a kernel's callees compile inside
    it). Loading a kernel from the disk cache sends no event and costs nothing here.
    """

    def __init__(self):
        self._local = threading.local()
        self._lock = threading.Lock()
        self._process_total = 0.0

    def _state(self):
        state = self._local
        if not hasattr(state, "depth"):
            state.depth, state.started, state.total = 0, 0.0, 0.0
        return state

    def on_start(self, event):
        state = self._state()
        if state.depth == 0:
            state.started = time.perf_counter()
        state.depth += 1

    def on_end(self, event):
        state = self._state()
        state.depth -= 1
        if state.depth == 0:
            spent = time.perf_counter() - state.started
            state.total += spent
            with self._lock:
                self._process_total += spent

    def seconds(self, thread: bool = True) -> float:
        """Compile seconds so far (a running total) of the calling thread, or with
        ``thread=False`` of every thread of the process."""
        return self._state().total if thread else self._process_total


_CLOCK = _CompileClock()
numba_event.register("numba:compile", _CLOCK)


def compile_seconds(thread: bool = True) -> float:
    """Seconds spent compiling Numba kernels so far (a running total), by the calling thread
    or, with ``thread=False``, by every thread of this process.

    The difference of two readings is the compilation inside a timed section: subtract it
    to book model time apart from compilation (a first run with a cold kernel cache).
    """
    return _CLOCK.seconds(thread)
