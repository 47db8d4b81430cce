"""The compiled glue of the ball evaluations (:mod:`tolsim.study.pipeline.ball_kernels`)
against the NumPy chains it replaces, bit for bit."""

import numpy as np
from numpy.testing import assert_array_equal

from tolsim.physics.geometry import TABLE1
from tolsim.physics.velocity.analytic import ANALYTIC_TILE, analytic_kernel
from tolsim.physics.velocity.models import (
    BALL_REGIME_A,
    BALL_UNLOADED,
    BALL_UNRESOLVED,
    MODEL_FAST,
    MODEL_UNRESOLVED,
)
from tolsim.study.pipeline.ball_kernels import (
    ball_outcomes_kernel,
    contact_counts_kernel,
    gather_analytic_kernel,
    gather_loaded_kernel,
    nan_to_num,
    scatter_loaded_balls_kernel,
)
from tolsim.study.pipeline.evaluate import (
    analytic_arguments,
    loaded_contacts,
    round_off_force,
    settle_round_off_contacts,
)


def _bits(x):
    x = np.ascontiguousarray(x)
    return x.view(np.uint64) if x.dtype == np.float64 else x


def _forces(rng, n=4000):
    """Forces with every case of the glue: loaded, open (0, -0.0), tension, NaN, round-off
    (below K 1e-12^1.5 = 2.4e-8 N), infinite."""
    choices = np.array([0.0, -0.0, -1.0, np.nan, 1e-9, 2e-8, 1e-3, 50.0, 300.0, np.inf])
    return choices[rng.integers(0, len(choices), (n, 4))] * rng.uniform(0.5, 1.5, (n, 4))


def test_contact_counts_are_the_numpy_counts_settled_and_clipped():
    # source: loaded_contacts, settle_round_off_contacts and np.maximum(F, 0), the chain of
    # ball_velocities before the kernel; tolerance: the bits (-0.0 and NaN included)
    rng = np.random.default_rng(11)
    force = _forces(rng)
    force[0] = [1e-9, 0.0, 1e-9, 2e-8]  # settled: round-off only
    force[1] = [-0.0, -0.0, 0.0, 0.0]  # open, clipped to +0.0 as np.maximum does
    with np.errstate(invalid="ignore"):
        want_force, want_count = settle_round_off_contacts(force, loaded_contacts(force),
                                                           TABLE1)
        want_clipped = np.maximum(want_force, 0.0)
    count, clipped = np.empty(len(force), np.int8), np.empty_like(force)
    settled = contact_counts_kernel(force, round_off_force(TABLE1), count, clipped)
    assert settled == np.count_nonzero((loaded_contacts(force) > 0) & (want_count == 0)) > 0
    assert_array_equal(count, want_count)
    assert_array_equal(_bits(clipped), _bits(want_clipped))


def test_ball_outcomes_are_the_numpy_outcomes():
    # source: the NumPy lines of ball_velocities before the full-model re-solves (valid,
    # model, regime, loss of contact, the balls to re-solve); tolerance: exact
    rng = np.random.default_rng(12)
    n = 5000
    count = rng.integers(-1, 5, n).astype(np.int8)
    converged = rng.random(n) < 0.9
    four_point = count == 4
    for fast in (True, False):
        eps = np.where(rng.random(n) < 0.1, np.nan, rng.normal(0, 1e-4, n))
        valid = rng.random(n) < 0.8
        want_valid = valid & converged & four_point & np.isfinite(eps) if fast else valid
        want_model = np.where(want_valid, np.int8(MODEL_FAST), np.int8(MODEL_UNRESOLVED))
        want_regime = np.where(want_valid, np.int8(BALL_REGIME_A), np.int8(BALL_UNRESOLVED))
        want_regime[converged & (count == 0)] = BALL_UNLOADED
        want_redo = np.flatnonzero(converged & ~want_valid & (count >= 2))
        want_lost = converged & ((count == 1) | (count < 0))
        want_eps = np.where(want_valid, eps, np.nan)
        model, regime = np.empty(n, np.int8), np.empty(n, np.int8)
        lost, redo = np.empty(n, bool), np.empty(n, np.int64)
        k = ball_outcomes_kernel(eps, valid, converged, four_point, count, fast, MODEL_FAST,
                                 MODEL_UNRESOLVED, BALL_REGIME_A, BALL_UNRESOLVED,
                                 BALL_UNLOADED, model, regime, lost, redo)
        assert_array_equal(valid, want_valid)
        assert_array_equal(model, want_model)
        assert_array_equal(regime, want_regime)
        assert_array_equal(lost, want_lost)
        assert_array_equal(redo[:k], want_redo)
        assert_array_equal(_bits(eps), _bits(want_eps))


def test_gather_is_boolean_indexing():
    # source: x[loaded] of NumPy (C order), with the force's non-finite values set to 0 and
    # four_point all F > 0; tolerance: the bits
    rng = np.random.default_rng(13)
    shape = (9, 2, 7)
    loaded = rng.random(shape) < 0.7
    dbeta = rng.normal(size=shape + (4,))
    force = _forces(rng, int(np.prod(shape))).reshape(shape + (4,))
    ball_converged = rng.random(shape) < 0.9
    solved = rng.random(shape[0]) < 0.8
    n = int(loaded.sum())
    out = np.empty((n, 4)), np.empty((n, 4)), np.empty(n, bool), np.empty(n, bool)
    gather_loaded_kernel(loaded, dbeta, force, ball_converged, solved, *out)
    want_force = np.where(np.isfinite(force[loaded]), force[loaded], 0.0)
    assert_array_equal(_bits(out[0]), _bits(dbeta[loaded]))
    assert_array_equal(_bits(out[1]), _bits(want_force))
    assert_array_equal(out[2], (ball_converged & solved[:, None, None])[loaded])
    assert_array_equal(out[3], np.all(want_force > 0.0, axis=1))


def test_nan_to_num_is_numpy_nan_to_num():
    # source: np.nan_to_num (NaN -> 0, +-inf -> +-the largest double); tolerance: the bits
    rng = np.random.default_rng(14)
    x = rng.normal(size=(50, 3, 7))
    x.reshape(-1)[rng.integers(0, x.size, 60)] = np.nan
    x.reshape(-1)[:4] = [np.inf, -np.inf, -0.0, 0.0]
    assert_array_equal(_bits(nan_to_num(x)), _bits(np.nan_to_num(x)))
    view = x[:, :, ::2]  # not contiguous: NumPy's own
    assert_array_equal(_bits(nan_to_num(view)), _bits(np.nan_to_num(view)))


def test_gather_analytic_is_gather_then_counts_then_analytic():
    # source: gather_loaded_kernel, contact_counts_kernel and analytic_kernel one after the
    # other, the chain of the carriage's evaluation before the fused kernel; tolerance: the bits
    # (epsilon's NaN included). Loaded forces of the size of the carriage's (about 100 N)
    # beside every odd case of _forces, over several tiles.
    rng = np.random.default_rng(15)
    shape = (90, 2, 13)
    loaded = rng.random(shape) < 0.8
    dbeta = rng.normal(0.0, 2e-3, shape + (4,))
    force = np.where(rng.random(shape + (4,)) < 0.8, rng.uniform(20.0, 200.0, shape + (4,)),
                     _forces(rng, int(np.prod(shape))).reshape(shape + (4,)))
    force[0, 0, 0] = [1e-9, 0.0, 1e-9, 2e-8]  # settled: round-off only
    ball_converged = rng.random(shape) < 0.95
    solved = rng.random(shape[0]) < 0.9
    n = int(loaded.sum())
    assert n > 3 * ANALYTIC_TILE
    want = np.empty((n, 4)), np.empty((n, 4)), np.empty(n, bool), np.empty(n, bool)
    gather_loaded_kernel(loaded, dbeta, force, ball_converged, solved, *want)
    count, clipped = np.empty(n, np.int8), np.empty((n, 4))
    limit = round_off_force(TABLE1)
    settled = contact_counts_kernel(want[1], limit, count, clipped)
    eps, valid = np.empty(n), np.empty(n, bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        analytic_kernel(want[0], clipped, *analytic_arguments(TABLE1), eps, np.empty(0),
                        np.empty((0, 4)), valid)
    got = np.empty((n, 4)), np.empty((n, 4)), np.empty(n, bool), np.empty(n, bool)
    got_count, got_eps, got_valid = np.empty(n, np.int8), np.empty(n), np.empty(n, bool)
    got_settled = gather_analytic_kernel(loaded, dbeta, force, ball_converged, solved, limit,
                                         *analytic_arguments(TABLE1), *got, got_count,
                                         got_eps, got_valid)
    assert got_settled == settled > 0
    for g, w in zip(got, want, strict=True):
        assert_array_equal(_bits(g), _bits(w))
    assert_array_equal(got_count, count)
    assert valid.sum() > n // 4 and np.isnan(eps).any()
    assert_array_equal(got_valid, valid)
    assert_array_equal(_bits(got_eps), _bits(eps))


def test_scatter_loaded_balls_is_three_scatters():
    # source: out[loaded] = values of NumPy (C order) of epsilon (NaN elsewhere), of
    # BallState.accounted or valid (True elsewhere) and of the unloaded balls (regime
    # BALL_UNLOADED; False elsewhere), the carriage's evaluation before the fused kernel
    # (which scattered the first two with scatter_loaded_kernel); tolerance: the bits
    rng = np.random.default_rng(16)
    shape = (11, 2, 9)
    loaded = rng.random(shape) < 0.7
    n = int(loaded.sum())
    eps = np.where(rng.random(n) < 0.2, np.nan, rng.normal(size=n))
    valid = rng.random(n) < 0.7
    regime = rng.integers(0, 6, n).astype(np.int8)
    unloaded = regime == BALL_UNLOADED
    assert (unloaded & ~valid).any()
    for pushes in (True, False):
        want_eps, want_ok = np.full(shape, np.nan), np.ones(shape, bool)
        want_eps[loaded] = eps
        want_ok[loaded] = valid | unloaded if pushes else valid
        want_unloaded = np.zeros(shape, bool)
        want_unloaded[loaded] = unloaded
        got = np.empty(shape), np.empty(shape, bool), np.empty(shape, bool)
        scatter_loaded_balls_kernel(loaded, eps, valid, regime, BALL_UNLOADED, pushes, *got)
        assert_array_equal(_bits(got[0]), _bits(want_eps))
        assert_array_equal(got[1], want_ok)
        assert_array_equal(got[2], want_unloaded)
