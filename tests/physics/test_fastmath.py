import math

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.physics._fastmath import cbrt_nonnegative


def test_cbrt_matches_numpy_to_a_few_ulp(rng):
    # Reference: np.cbrt (libm). 4 ulp, i.e. rtol 1e-15, over 600 decades, subnormals and 0.
    x = np.concatenate([
        10.0 ** rng.uniform(-300, 300, 100_000),
        rng.uniform(0, 1, 10_000),
        [0.0, 5e-310, 1.0, 8.0, 27.0, 1.7e308],
    ])
    got = cbrt_nonnegative(x)
    assert_allclose(got, np.cbrt(x), rtol=1e-15, atol=0)
    assert got[-6] == 0.0 and got[-3] == 2.0 and got[-2] == 3.0


def _cbrt_three_passes(x):
    """The cube root as three array passes, in NumPy (the kernels before the one-pass tiles):
    seed b // 3 + magic on the int64 bit pattern, three Halley steps, libm outside
    (1e-300, 1e300)."""
    with np.errstate(all="ignore"):
        y = (x.view(np.int64) // 3 + 0x2A9F7893782DA1CE).view(np.float64)
        for _ in range(3):
            y3 = y * y * y
            y = y * ((y3 + 2.0 * x) / (2.0 * y3 + x))
    odd = ~((1e-300 < x) & (x < 1e300))
    y[odd] = [math.cbrt(v) for v in x[odd]]  # libm's, as in the kernel (NumPy has its own)
    return y


def test_cbrt_is_the_three_pass_algorithm_bit_for_bit(rng):
    # source: the seed, refine and fixup passes the one-pass kernel replaced (_cbrt_three_passes,
    # NumPy's elementwise IEEE arithmetic); tolerance: the bits. Over 628 decades, subnormals,
    # 0, the bounds of the Halley range, near overflow, inf and NaN; sizes not a multiple of
    # the tile.
    x = np.concatenate([
        10.0 ** rng.uniform(-320, 308.2, 100_001),
        rng.uniform(0, 1, 10_000),
        [0.0, 5e-310, 1e-300, np.nextafter(1e-300, 1), 1e300, np.nextafter(1e300, 0), 1.0,
         8.0, 27.0, 1.7e308, np.inf, np.nan],
    ])
    for part in (x, x[:7], x[:513]):
        assert_array_equal(cbrt_nonnegative(part).view(np.int64),
                           _cbrt_three_passes(part).view(np.int64))


def test_cbrt_seed_divides_the_bit_pattern_by_three_exactly(rng):
    # source: Python's integer b // 3 + magic on the bit pattern b of x >= 0 (the seed of the
    # three-pass kernel); tolerance: exact. Random patterns over [0, 2^63), and every residue of
    # the high half mod 3 with the low half at 0 and at 2^32 - 1 (the largest remainders).
    from tolsim.physics._fastmath import cbrt_seed

    bits = list(rng.integers(0, 2**63 - 1, 3000, dtype=np.int64))
    for high in (0, 1, 2, 3, 2**31 - 3, 2**31 - 2, 2**31 - 1):
        bits += [high << 32, (high << 32) | 0xFFFFFFFF]
    for b in bits:
        x = np.int64(b).view(np.float64)
        want = (int(b) // 3 + 0x2A9F7893782DA1CE) % 2**64
        assert int(np.float64(cbrt_seed(x)).view(np.uint64)) == want, hex(int(b))


def test_cbrt_keeps_shape_and_out():
    x = np.arange(12.0).reshape(3, 4)
    out = np.empty_like(x)
    assert cbrt_nonnegative(x, out) is out
    assert_allclose(out, np.cbrt(x), rtol=1e-15)


# --------------------------------------------------------------------------------------------
# Small-angle series (used by the static lanes and the analytic kernel)
# --------------------------------------------------------------------------------------------
def test_sin_cosm1_small_is_exact_to_round_off(rng):
    # Reference: libm sin, and cos t - 1 = -2 sin^2(t/2) (no cancellation). 2 ulp.
    from tolsim.physics._fastmath import SMALL_ANGLE, sin_cosm1_small

    t = np.concatenate([rng.uniform(-SMALL_ANGLE, SMALL_ANGLE, 20_000), [0.0, SMALL_ANGLE,
                                                                         -SMALL_ANGLE, 1e-9]])
    s, c = np.array([sin_cosm1_small(x) for x in t]).T
    assert_allclose(s, np.sin(t), rtol=4.5e-16, atol=0)
    assert_allclose(c, -2.0 * np.sin(0.5 * t) ** 2, rtol=4.5e-16, atol=0)


def test_sin_cos_near_matches_libm_inside_and_falls_back_outside(rng):
    from tolsim.physics._fastmath import sin_cos_near

    base = np.pi / 4
    t = np.concatenate([rng.uniform(-0.2, 0.2, 5_000), rng.uniform(-1.0, 1.0, 500)])
    s, c = np.array([sin_cos_near(np.sin(base), np.cos(base), base, x) for x in t]).T
    # libm of the rounded base + t: the rounding of the sum is up to 5.6e-17 rad
    assert_allclose(s, np.sin(base + t), rtol=0, atol=3e-16)
    assert_allclose(c, np.cos(base + t), rtol=0, atol=3e-16)


def test_atan_small_is_exact_to_round_off(rng):
    from tolsim.physics._fastmath import SMALL_TAN, atan_small

    x = np.concatenate([rng.uniform(-SMALL_TAN, SMALL_TAN, 20_000), [0.0, SMALL_TAN, 1e-12]])
    got = np.array([atan_small(v) for v in x])
    assert_allclose(got, np.arctan(x), rtol=4.5e-16, atol=0)
