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
