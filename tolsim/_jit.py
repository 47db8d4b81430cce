"""Numba jit defaults, in one place.

Kernels are compiled lazily on first call and cached on disk (``cache=True``), so a CLI call
pays compilation once per machine, not once per call.
"""

import numba

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
