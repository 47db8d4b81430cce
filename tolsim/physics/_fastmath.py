"""Vectorisable elementwise functions for the hot kernels: cube root, small-angle series.

libm ``cbrt`` costs ~24 ns a call and does not vectorise; the analytical kernels need one to
four cube roots per ball (a_i ~ F_i^(1/3), F^(2/3) weights), which made ``cbrt`` their floor.
Here the seed comes from the integer bit pattern (dividing the exponent by three,
the classic "magic constant" trick), refined by three Halley steps
y <- y (y^3 + 2x) / (2 y^3 + x) (cubic convergence: ~3e-2 -> ~1e-5 -> ~1e-15 -> round-off).
Written as the ratio form so that nothing overflows or underflows for any normal double.
Accuracy against ``np.cbrt``: a few ulp (tests/physics/test_fastmath.py).

Per value (:func:`cbrt_one`, which the fused kernels call inline), or over an array
(:func:`cbrt_nonnegative`).
"""

import numpy as np
from numba import prange

from tolsim._jit import jit, pjit

_CBRT_MAGIC = 0x2A9F7893782DA1CE  # bit pattern of ~1 shifted so that bits/3 + magic ~ cbrt


#: Where :func:`cbrt_halley` is used; libm ``cbrt`` outside (0, subnormals: a bad seed; near
#: overflow: y^3 overflows). The bounds are exclusive.
CBRT_RANGE = (1e-300, 1e300)


@jit(inline="always")
def cbrt_seed(x):
    """The magic-constant seed of cbrt x (x >= 0): the int64 bit pattern b of x mapped to
    b // 3 + magic, read back as a float.

    The division by 3 is written as two exact float divisions of 32-bit halves, so that loops
    calling it vectorise (an int64 division does not): b = h 2^32 + l with h < 2^31, and
    b // 3 = (h // 3) 2^32 + ((h mod 3) 2^32 + l) // 3, each quotient below 2^32 and taken as
    floor of a correctly rounded double quotient, which is exact there (k + 2/3 with k < 2^32
    rounds to below k + 1). The same integer as ``b // 3`` for every b >= 0.
    """
    bits = np.float64(x).view(np.int64)
    high = bits >> 32
    q_high = np.int64(np.floor(np.float64(high) / 3.0))
    low = (high - 3 * q_high) * 4294967296 + (bits & 0xFFFFFFFF)
    q_low = np.int64(np.floor(np.float64(low) / 3.0))
    return np.int64(q_high * 4294967296 + q_low + _CBRT_MAGIC).view(np.float64)


@jit(inline="always")
def cbrt_halley(x):
    """cbrt x for x inside :data:`CBRT_RANGE`: :func:`cbrt_seed` and three Halley steps, no
    branch (loops over it vectorise); callers redo values outside the range with
    :func:`cbrt_one`."""
    y = cbrt_seed(x)
    for _ in range(3):
        y3 = y * y * y
        y = y * ((y3 + 2.0 * x) / (2.0 * y3 + x))
    return y


@jit(inline="always")
def cbrt_in_range(x):
    """Whether :func:`cbrt_halley` takes x (False for NaN)."""
    return CBRT_RANGE[0] < x < CBRT_RANGE[1]


@jit(inline="always")
def cbrt_one(x):
    """cbrt x of a finite x >= 0 (:func:`cbrt_halley` in :data:`CBRT_RANGE`, libm outside)."""
    if cbrt_in_range(x):
        return cbrt_halley(x)
    return np.cbrt(x)


#: Values per tile of :func:`_cbrt_tiles` (its scratch stays in the L1 cache).
_CBRT_TILE = 512


@pjit
def _cbrt_tiles(src, dst):
    """:func:`cbrt_one` of every value: per tile a branch-free (vectorised) loop of
    :func:`cbrt_halley`, then libm for the tile's values outside :data:`CBRT_RANGE`."""
    n = src.size
    for k in prange((n + _CBRT_TILE - 1) // _CBRT_TILE):
        lo = k * _CBRT_TILE
        hi = min(lo + _CBRT_TILE, n)
        odd = False
        for i in range(lo, hi):
            x = src[i]
            dst[i] = cbrt_halley(x)
            odd |= not cbrt_in_range(x)
        if odd:
            for i in range(lo, hi):
                if not cbrt_in_range(src[i]):
                    dst[i] = np.cbrt(src[i])


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
    _cbrt_tiles(values.reshape(-1), out.reshape(-1))
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
def sin_cos_series(sin0, cos0, t):
    """sin and cos of base + t by angle addition with the series (|t| <= SMALL_ANGLE; the
    branch of :func:`sin_cos_near` there, without its test: loops over it vectorise)."""
    st, cm1 = sin_cosm1_small(t)
    return sin0 + (sin0 * cm1 + cos0 * st), cos0 + (cos0 * cm1 - sin0 * st)


@jit(inline="always")
def sin_cos_near(sin0, cos0, base, t):
    """sin and cos of base + t from sin0 = sin(base), cos0 = cos(base).

    Angle addition with the series for |t| <= SMALL_ANGLE (more accurate than rounding
    base + t first, :func:`sin_cos_series`), libm beyond (and for a NaN t).
    """
    if abs(t) <= SMALL_ANGLE:
        return sin_cos_series(sin0, cos0, t)
    return np.sin(base + t), np.cos(base + t)


@jit(inline="always")
def atan_small(x):
    """atan x by its Taylor series to x^17, round-off accurate for |x| <= 0.1."""
    x2 = x * x
    p = 1.0 / 17.0  # Horner over the coefficients (-1)^j / (2 j + 1), j = 8 .. 0
    for j in range(7, -1, -1):
        p = (1.0 if j % 2 == 0 else -1.0) / (2.0 * j + 1.0) + x2 * p
    return x * p
