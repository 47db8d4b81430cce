import numpy as np
from numpy.testing import assert_allclose

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
