"""Vectorisable elementwise functions for the hot kernels: cube root, small-angle series.

libm ``cbrt`` costs ~24 ns a call and does not vectorise; the analytical kernels need one to
four cube roots per ball (a_i ~ F_i^(1/3), F^(2/3) weights), which made ``cbrt`` their floor.
Here the seed comes from the integer bit pattern (dividing the exponent by three,
the classic "magic constant" trick), refined by three Halley steps
y <- y (y^3 + 2x) / (2 y^3 + x) (cubic convergence: ~3e-2 -> ~1e-5 -> ~1e-15 -> round-off).
Written as the ratio form so that nothing overflows or underflows for any normal double.
Accuracy against ``np.cbrt``: a few ulp (tests/physics/test_fastmath.py).

The seed pass reads the input through an int64 view. It is a separate kernel from the
refinement because Numba assumes distinct arrays do not alias, and the float and int views of
the output do.
"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit

_CBRT_MAGIC = 0x2A9F7893782DA1CE  # bit pattern of ~1 shifted so that bits/3 + magic ~ cbrt


@pjit
def _cbrt_seed(src_bits, dst_bits):
    for i in prange(src_bits.size):
        dst_bits[i] = src_bits[i] // 3 + _CBRT_MAGIC


@pjit
def _cbrt_refine(src, dst):
    for i in prange(src.size):
        x = src[i]
        y = dst[i]
        for _ in range(3):
            y3 = y * y * y
            y = y * ((y3 + 2.0 * x) / (2.0 * y3 + x))
        dst[i] = y


@pjit
def _cbrt_fixup(src, dst):
    # A separate pass keeps the refinement loop branch-free (it vectorises).
    for i in prange(src.size):
        x = src[i]
        if not (1e-300 < x < 1e300):  # 0, subnormals (bad seed), near overflow: libm
            dst[i] = np.cbrt(x)


def cbrt_nonnegative(values, out=None):
    """Cube root of a C-contiguous float64 array of finite values >= 0.

    Parameters
    ----------
    values : ndarray
        Finite, non-negative, C-contiguous float64 (not checked: callers validate).
    out : ndarray, optional
        Output of the same shape (may not be ``values`` itself).

    Returns
    -------
    ndarray
        cbrt(values), within a few ulp of ``np.cbrt``.
    """
    if out is None:
        out = np.empty_like(values)
    flat_in = values.reshape(-1)
    flat_out = out.reshape(-1)
    _cbrt_seed(flat_in.view(np.int64), flat_out.view(np.int64))
    _cbrt_refine(flat_in, flat_out)
    _cbrt_fixup(flat_in, flat_out)
    return out


# --------------------------------------------------------------------------------------------
# Small-angle series. Contact-angle deviations and groove rotations are a few degrees at most,
# where short Taylor series are exact to round-off, cost a few multiply-adds instead of a libm
# call (~20 ns each) and, having no calls or branches, let LLVM vectorise the loops around them.
# Callers check the stated ranges and fall back to libm outside them.
# --------------------------------------------------------------------------------------------
#: |t| up to which :func:`sin_cosm1_small` is exact to round-off [rad].
SMALL_ANGLE = 0.2
#: |x| up to which :func:`atan_small` is exact to round-off [-].
SMALL_TAN = 0.1


@jit(inline="always")
def sin_cosm1_small(t):
    """sin t and cos t - 1 by their Taylor series, round-off accurate for |t| <= 0.2.

    The first omitted terms are below 1e-18 relative (t^13/13! and t^14/14! at t = 0.2).
    """
    t2 = t * t
    s = t * (1.0 + t2 * (-1.0 / 6.0 + t2 * (1.0 / 120.0 + t2 * (-1.0 / 5040.0 + t2 * (
        1.0 / 362880.0 + t2 * (-1.0 / 39916800.0))))))
    c = t2 * (-0.5 + t2 * (1.0 / 24.0 + t2 * (-1.0 / 720.0 + t2 * (1.0 / 40320.0 + t2 * (
        -1.0 / 3628800.0 + t2 * (1.0 / 479001600.0))))))
    return s, c


@jit(inline="always")
def sin_cos_near(sin0, cos0, base, t):
    """sin and cos of base + t from sin0 = sin(base), cos0 = cos(base).

    Angle addition with the series for |t| <= SMALL_ANGLE (more accurate than rounding
    base + t first), libm beyond.
    """
    if abs(t) <= SMALL_ANGLE:
        st, cm1 = sin_cosm1_small(t)
        return sin0 + (sin0 * cm1 + cos0 * st), cos0 + (cos0 * cm1 - sin0 * st)
    return np.sin(base + t), np.cos(base + t)


@jit(inline="always")
def atan_small(x):
    """atan x by its Taylor series to x^17, round-off accurate for |x| <= 0.1."""
    x2 = x * x
    p = 1.0 / 17.0  # Horner over the coefficients (-1)^j / (2 j + 1), j = 8 .. 0
    for j in range(7, -1, -1):
        p = (1.0 if j % 2 == 0 else -1.0) / (2.0 * j + 1.0) + x2 * p
    return x * p
