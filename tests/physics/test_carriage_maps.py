"""Tests of the compiled groove maps of balls at their own z and of the largest-eigenvalue
check of :func:`tolsim.physics.carriage.solve_carriage_batch`
(:mod:`tolsim.physics.carriage._map_kernels`)."""

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.physics.carriage import CarriageLayout
from tolsim.physics.carriage._map_kernels import (
    assembly_groove_rows,
    formed_pivot,
    gram_diagonal,
    gram_of_rows,
    largest_eigenvalue,
    singular_pivot,
    trace_bounds,
)


def _bits(x):
    return np.ascontiguousarray(x).view(np.uint64)


def test_assembly_groove_rows_are_the_numpy_maps_bit_for_bit():
    # source: the NumPy chain they replace in solve_carriage_batch (groove_map_at times the
    # DOF scales, np.where on the unloaded balls, z / L); tolerance: the
    # bits (same operations element by element), -0.0 included
    rng = np.random.default_rng(3)
    layout = CarriageLayout([-0.02, 0.02, 0.0], [0.0, 0.001, -0.03], np.deg2rad([90, -90, 30]),
                            5, 0.0105)
    m, t, n = 7, layout.n_tracks, layout.balls_per_track
    nball = t * n
    z = rng.uniform(-0.03, 0.03, (m, t, n))
    z[0, 0, 0] = 0.0
    z[1, 1, 2] = -0.0
    loaded = rng.random((m, t, n)) < 0.8
    length = 0.037
    scale = np.array([1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
    a_s = layout.groove_map_at(z).reshape(m, nball, 2, 5) * scale
    a_s = np.ascontiguousarray(np.where(loaded.reshape(-1, nball, 1, 1), a_s, 0.0))
    zeta = z.reshape(-1, nball) / length
    c, s = np.cos(layout.track_orientation), np.sin(layout.track_orientation)
    x, y = layout.track_x, layout.track_y
    track = np.stack([c, s, -s, -c, s * x - c * y, c * x + s * y], axis=1)
    out = np.empty((m, 10, nball)), np.empty((m, nball))
    for a in range(m):  # as the batch kernel calls it, one assembly at a time
        assembly_groove_rows(z[a].reshape(-1), loaded[a].reshape(-1), track, scale, length,
                             out[0][a], out[1][a])
    rows = a_s.reshape(m, nball, 10).transpose(0, 2, 1)  # row 5 c + j: A[:, c, j]
    for got, want in zip(out, (rows, zeta), strict=True):
        assert_array_equal(_bits(got), _bits(want))


def test_gram_is_the_sum_of_the_balls_a_transpose_a():
    # source: sum_b A_b^T A_b by NumPy (np.matmul of the stacked rows, as solve_carriage_batch
    # formed it before the kernel did); tolerance 1e-15 of the largest entry (the sums run in
    # another order); symmetric to the bit.
    rng = np.random.default_rng(5)
    maps = rng.normal(0.0, 1.0, (26, 2, 5))
    maps[3] = 0.0  # a ball outside the zone
    rows = np.ascontiguousarray(maps.reshape(26, 10).T)  # row 5 c + j: A[:, c, j]
    got = np.empty((5, 5))
    gram_of_rows(rows, got)
    flat = maps.reshape(-1, 5)
    want = flat.T @ flat
    assert_allclose(got, want, rtol=0, atol=1e-15 * np.abs(want).max())
    assert_array_equal(got, got.T)
    # its diagonal alone: the same sums to the bit, the rest NaN (not formed)
    diagonal = np.empty((5, 5))
    gram_diagonal(rows, diagonal)
    assert_array_equal(_bits(np.diag(diagonal)), _bits(np.diag(got)))
    assert np.isnan(diagonal[~np.eye(5, dtype=bool)]).all()


def _largest(mats, free):
    work = np.empty((5, 5))
    return np.array([largest_eigenvalue(m, free, work) for m in mats])


def test_largest_eigenvalue_matches_lapack():
    # source: numpy.linalg.eigvalsh (LAPACK); tolerance 1e-13 of the largest eigenvalue
    # (Jacobi and LAPACK both to a few units of round-off of it, 2.2e-16)
    rng = np.random.default_rng(5)
    a = rng.normal(size=(40, 12, 5))
    a[3, :, 4] = 0.0  # a singular matrix (a locked mechanism's zero eigenvalue)
    a[4] *= np.array([1.0, 1.0, 1e-4, 1e-4, 1e-4])  # badly scaled
    a[5, :, 2] = a[5, :, 1]  # two equal columns
    mats = np.ascontiguousarray(np.matmul(a.transpose(0, 2, 1), a))
    for free in (np.arange(5), np.array([0, 1, 3]), np.array([2])):
        want = np.linalg.eigvalsh(mats[:, free][:, :, free])[:, -1]
        assert_allclose(_largest(mats, free), want, rtol=1e-13, atol=0.0)
    diagonal = np.diag([1.0, 3.0, 2.0, 0.0, 0.5])[None]  # nothing to rotate: exact
    assert _largest(diagonal, np.arange(5))[0] == 3.0


def test_singular_pivot_is_the_eigenvalue_test():
    # source: the test it replaces, not pivot > 1e-10 k_ref lambda_max with lambda_max from
    # numpy.linalg.eigvalsh; tolerance: the same answer for pivots from 1e-14 to 1e-6 of
    # k_ref lambda_max (the window between the trace bounds included) but within 1e-12 of
    # the threshold (Jacobi and LAPACK differ there by round-off), and for NaN and 0
    rng = np.random.default_rng(6)
    a = rng.normal(size=(20, 12, 5)) * np.array([1.0, 1.0, 0.01, 0.01, 0.01])
    mats = np.ascontiguousarray(np.matmul(a.transpose(0, 2, 1), a))
    free, k_ref, work = np.arange(5), 3.7e7, np.empty((5, 5))
    computed = 0
    for mat in mats:
        exact = 1e-10 * k_ref * np.linalg.eigvalsh(mat)[-1]
        pivots = exact * np.geomspace(1e-4, 1e4, 41)
        pivots = pivots[np.abs(pivots / exact - 1.0) > 1e-12]
        for pivot in np.concatenate([pivots, [np.nan, 0.0]]):
            threshold = np.empty(3)
            trace_bounds(mat, free, k_ref, threshold)
            assert threshold[0] <= exact <= threshold[1]
            assert singular_pivot(pivot, threshold, mat, free, k_ref, work) == (
                not pivot > exact)
            computed += not np.isnan(threshold[2])
    assert computed > 0  # the window between the bounds was met


def test_formed_pivot_forms_the_gram_only_when_the_eigenvalue_is_needed():
    # source: singular_pivot on the whole sum_b A_b^T A_b (test above); tolerance: the same
    # answer for every pivot, the matrix formed (bit for bit that of gram_of_rows) exactly
    # for the pivots between the trace bounds and left with its diagonal alone elsewhere
    rng = np.random.default_rng(8)
    # row 5 c + j: A[:, c, j]; the rotations' columns small, as scaled maps of a carriage
    rows = rng.normal(size=(10, 24)) * np.tile([1.0, 1.0, 0.01, 0.01, 0.01], 2)[:, None]
    full = np.empty((5, 5))
    gram_of_rows(rows, full)
    free, k_ref, work = np.arange(5), 3.7e7, np.empty((5, 5))
    exact = 1e-10 * k_ref * np.linalg.eigvalsh(full)[-1]
    formed = 0
    for pivot in np.concatenate([exact * np.geomspace(1e-4, 1e4, 41), [np.nan, 0.0]]):
        if abs(pivot / exact - 1.0) <= 1e-12:
            continue
        geometric, threshold, ref = np.empty((5, 5)), np.empty(3), np.empty(3)
        gram_diagonal(rows, geometric)
        trace_bounds(geometric, free, k_ref, threshold)
        trace_bounds(full, free, k_ref, ref)
        assert_array_equal(_bits(threshold[:2]), _bits(ref[:2]))
        between = threshold[0] < pivot <= threshold[1]
        assert formed_pivot(pivot, threshold, geometric, rows, free, k_ref, work) == (
            singular_pivot(pivot, ref, full, free, k_ref, work)) == (not pivot > exact)
        if between:
            assert_array_equal(_bits(geometric), _bits(full))
            formed += 1
        else:
            assert np.isnan(geometric[0, 1])
    assert formed > 0  # the window between the bounds was met
