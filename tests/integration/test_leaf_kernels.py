"""Leaf kernels (``tolsim._jit.jit(leaf=True)``): compiled without Numba's runtime, so that no
reference counts are taken on the arrays they are handed (session 26: about 20 % of the
circuit study and 8 % of the carriage study along the track went to those counts).

Numba's ``_nrt`` option is private. These tests fail if a Numba release stops honouring it
(a leaf kernel could then allocate) or if a leaf kernel computes other numbers than the same
function compiled with the runtime.
"""

import numpy as np
import pytest
from numba.core.errors import TypingError

from tolsim._jit import JIT, LEAF, jit


def test_the_leaf_options_differ_from_the_defaults_only_in_the_runtime():
    assert LEAF == dict(JIT, _nrt=False)


def test_a_leaf_kernel_cannot_allocate():
    # without the runtime an array could never be freed: Numba must refuse to compile one
    @jit(leaf=True, cache=False)
    def allocates(n):
        x = np.empty(n)
        x[0] = 1.0
        return x[0]

    with pytest.raises(TypingError):
        allocates(3)


def test_a_leaf_kernel_cannot_receive_a_new_array():
    @jit(cache=False)
    def make(n):
        return np.ones(n)

    @jit(leaf=True, cache=False)
    def takes(n):
        return make(n)[0]

    with pytest.raises(TypingError):
        takes(3)


def test_a_leaf_kernel_cannot_call_one_that_allocates():
    # its callees are compiled without the runtime too (tolsim._jit.jit, leaf)
    @jit(cache=False)
    def allocates(n):
        x = np.empty(n)
        x[:] = 2.0
        return x.sum()

    @jit(leaf=True, cache=False)
    def calls(n):
        return allocates(n)

    with pytest.raises(TypingError):
        calls(3)


def _weighted_runs(values, weight, out_mean, out_count):
    """Means of the runs of non-decreasing values (a branchy loop over four arrays)."""
    n = values.shape[0]
    runs = 0
    start = 0
    for i in range(1, n + 1):
        if i == n or values[i] < values[i - 1]:
            total = 0.0
            mass = 0.0
            for j in range(start, i):
                total += weight[j] * values[j]
                mass += weight[j]
            out_mean[runs] = total / mass if mass > 0.0 else np.nan
            out_count[runs] = i - start
            runs += 1
            start = i
    return runs


leaf_runs = jit(_weighted_runs, leaf=True, cache=False)
plain_runs = jit(_weighted_runs, cache=False)


@jit(cache=False)
def _rows(kernel_is_leaf, values, weight, out_mean, out_count, out_runs):
    # rows of 2-D arrays handed over as views, from a kernel with the runtime
    for r in range(values.shape[0]):
        if kernel_is_leaf:
            out_runs[r] = leaf_runs(values[r], weight[r], out_mean[r], out_count[r])
        else:
            out_runs[r] = plain_runs(values[r], weight[r], out_mean[r], out_count[r])


def test_a_leaf_kernel_gives_the_numbers_of_the_same_kernel_with_the_runtime():
    rng = np.random.default_rng(26)
    values = rng.normal(size=(200, 17))
    weight = rng.uniform(0.0, 2.0, size=(200, 17))
    weight[::7, 3] = 0.0
    outs = []
    for leaf in (True, False):
        mean, count = np.full((200, 17), np.nan), np.zeros((200, 17), dtype=np.int64)
        runs = np.zeros(200, dtype=np.int64)
        _rows(leaf, values, weight, mean, count, runs)
        outs.append((mean, count, runs))
    for a, b in zip(*outs, strict=True):
        assert np.array_equal(a, b, equal_nan=True)
    # and they are the runs: a NumPy twin of one row
    row = values[5]
    breaks = np.flatnonzero(np.diff(row) < 0) + 1
    pieces = np.split(np.arange(17), breaks)
    expected = [np.sum(weight[5, p] * row[p]) / np.sum(weight[5, p]) for p in pieces]
    assert outs[0][2][5] == len(pieces)
    np.testing.assert_allclose(outs[0][0][5, :len(pieces)], expected, rtol=1e-12)
