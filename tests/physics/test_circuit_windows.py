"""The friction windows of the circuit's step (tolsim.physics.circuit.step, ``pair_slopes``).

Between events a step's forces are constant (Notes of :func:`tolsim.physics.circuit.step`,
"The step"), so the friction increase sum_p k_p Q_p is piecewise constant and its extremes
are values of single intervals. The reference is the same travel cut into many short steps:
with constant epsilon and K the steps are event-exact (tests/physics/test_circuit.py,
``test_step_size_independent``), and a short step without a crossing has as its mean force
a mean of its intervals' forces, so its increase lies within their extremes and equals an
interval's value wherever it holds one interval only.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tests.physics.test_circuit import random_circuits
from tolsim.physics import circuit


def _increase(slopes, loaded, force):
    """sum_p k_p Q_p (M,) over the ball-order pairs with a ball in the zone, and their
    largest force (M,): the kernel's _track_interval, vectorised over the circuits."""
    upper = np.roll(loaded, -1, axis=1)
    k = np.where(loaded & upper, slopes[0], np.where(loaded, slopes[1], slopes[2]))
    touching = loaded | upper
    return (np.where(touching, k * force, 0.0).sum(axis=1),
            np.where(touching, force, 0.0).max(axis=1))


def _fine(state, eps, stiffness, travel, drag, slopes, pieces):
    """The increase (M, pieces) and largest pair force of each of ``pieces`` short steps
    over ``travel``, NaN for a short step in which a ball crossed an end of the zone (its
    layout changed inside it)."""
    m = state.position.shape[0]
    value, peak = np.empty((m, pieces)), np.empty((m, pieces))
    ds = travel / pieces
    for i in range(pieces):
        got = circuit.step(state, eps, stiffness, ds, drag, travel_start=i * ds)
        crossed = (got.state.loaded != state.loaded).any(axis=1)
        value[:, i], peak[:, i] = _increase(slopes, state.loaded, got.mean_contact_force)
        value[crossed, i] = peak[crossed, i] = np.nan
        state = got.state
    return value, peak


@pytest.mark.parametrize("travel", [0.03, -0.03])
def test_windows_hold_the_increase_of_each_interval(travel):
    # Reference: 3 000 steps of 10 um (module docstring). Tolerance 1e-9 N on the
    # increase (forces to 1e-9 N, as the twin test of test_circuit.py, times |k| < 3).
    # Each window longer than three short steps holds the value of the short steps
    # inside it; every short step without a crossing lies within the windows it overlaps.
    state, eps, stiffness = random_circuits(8, 31)
    m, n = state.position.shape
    slopes = np.random.default_rng(3).uniform(-1.0, 2.0, (3, m, n))
    got = circuit.step(state, eps, stiffness, travel, 0.01, pair_slopes=slopes,
                       window_capacity=64)
    pieces = 3000
    value, peak = _fine(state, eps, stiffness, travel, 0.01, slopes, pieces)
    w = got.windows
    assert w.count.max() < 64  # no window merged
    ds = abs(travel) / pieces
    piece = np.arange(pieces) * ds  # each short step's start (unsigned travel)
    checked = 0
    for c in range(m):
        k = w.count[c]
        begin = np.abs(w.start[c, :k])
        end = np.append(begin[1:], abs(travel))
        assert begin[0] == 0.0 and np.all(np.diff(begin) > 0.0)
        assert_allclose(w.low[c, :k], w.high[c, :k], rtol=0, atol=0)  # one interval each
        for j in range(k):
            inside = (piece >= begin[j]) & (piece + ds <= end[j]) & np.isfinite(value[c])
            if end[j] - begin[j] > 3 * ds:
                assert inside.any()
                assert_allclose(value[c, inside], w.low[c, j], rtol=0, atol=1e-9)
                assert_allclose(peak[c, inside], w.peak[c, j], rtol=0, atol=1e-9)
                checked += 1
        for i in np.flatnonzero(np.isfinite(value[c])):
            over = (begin < piece[i] + ds) & (end > piece[i])
            assert w.low[c, :k][over].min() - 1e-9 <= value[c, i]
            assert value[c, i] <= w.high[c, :k][over].max() + 1e-9
    assert checked > 3 * m  # several intervals per circuit
    # the step's own means hide the extremes: the increase at its mean forces lies strictly
    # inside [least, largest] for some circuits without a crossing
    single = ~np.isfinite(got.crossing_travel).any(axis=1)
    low = np.where(np.arange(w.low.shape[1]) < w.count[:, None], w.low, np.inf).min(axis=1)
    high = np.where(np.arange(w.low.shape[1]) < w.count[:, None], w.high, -np.inf).max(axis=1)
    mean, _ = _increase(slopes, state.loaded, got.mean_contact_force)
    assert np.all((low <= mean + 1e-12) & (mean <= high + 1e-12) | ~single)
    assert np.any(high - low > 1e-3)


def test_crossing_travel_is_where_the_ball_crossed():
    # The step's crossing travel against its short steps' (3 000 of 10 um): each ball that
    # crossed an end of the zone did so within the short step in which its loaded flag
    # changed (to its 1e-12 m rounding).
    state, eps, stiffness = random_circuits(6, 43)
    travel, pieces = 0.03, 3000
    got = circuit.step(state, eps, stiffness, travel, 0.01)
    crossed = np.isfinite(got.crossing_travel)
    assert np.array_equal(crossed, got.state.loaded != state.loaded) and crossed.any()
    ds = travel / pieces
    where = np.full(state.position.shape, np.nan)
    for i in range(pieces):
        short = circuit.step(state, eps, stiffness, ds, 0.01, travel_start=i * ds)
        where[short.state.loaded != state.loaded] = i * ds
        state = short.state
    assert np.all(got.crossing_travel[crossed] >= where[crossed] - 1e-12)
    assert np.all(got.crossing_travel[crossed] <= where[crossed] + ds + 1e-12)


def test_windows_merge_beyond_their_capacity_and_keep_their_extremes():
    # Capacity 1: every interval merges into the one window, whose extremes are then those
    # of all windows with the full capacity (exact: the same intervals).
    state, eps, stiffness = random_circuits(6, 37)
    m, n = state.position.shape
    slopes = np.random.default_rng(5).uniform(-1.0, 2.0, (3, m, n))
    full = circuit.step(state, eps, stiffness, 0.05, 0.0, pair_slopes=slopes).windows
    one = circuit.step(state, eps, stiffness, 0.05, 0.0, pair_slopes=slopes,
                       window_capacity=1).windows
    valid = np.arange(full.low.shape[1]) < full.count[:, None]
    assert full.count.max() > 1 and np.all(one.count == 1)
    assert_allclose(one.low[:, 0], np.where(valid, full.low, np.inf).min(axis=1), rtol=0,
                    atol=0)
    assert_allclose(one.high[:, 0], np.where(valid, full.high, -np.inf).max(axis=1), rtol=0,
                    atol=0)


def test_a_step_without_slopes_has_no_windows_and_bad_slopes_are_refused():
    state, eps, stiffness = random_circuits(2, 41)
    assert circuit.step(state, eps, stiffness, 0.01, 0.0).windows is None
    with pytest.raises(ValueError, match="pair_slopes"):
        circuit.step(state, eps, stiffness, 0.01, 0.0, pair_slopes=np.zeros((3, 2, 5)))
    with pytest.raises(ValueError, match="window_capacity"):
        circuit.step(state, eps, stiffness, 0.01, 0.0, pair_slopes=np.zeros((3, 2, 30)),
                     window_capacity=0)
    nan = np.full((3, 2, 30), np.nan)
    w = circuit.step(state, eps, stiffness, 0.01, 0.0, pair_slopes=nan).windows
    assert np.isnan(w.low[:, 0]).all() and np.isnan(w.high[:, 0]).all()
