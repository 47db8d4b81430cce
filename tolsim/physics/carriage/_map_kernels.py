"""Numba kernels of the batched carriage solve: the groove maps of balls at their own z and
their sum_b A_b^T A_b (its diagonal first, the rest when needed), and the singular-tangent
test against its largest eigenvalue."""

import numpy as np

from tolsim._jit import jit

#: Cyclic Jacobi sweeps of :func:`largest_eigenvalue` at most (a 5 x 5 matrix needs 4 to 6).
_JACOBI_SWEEPS = 30


@jit(inline="always")
def assembly_groove_rows(z, loaded, track, scale, length, rows, zetas):
    """Scaled groove maps of one assembly's balls at their own axial positions, by rows, for
    :func:`tolsim.physics.carriage._batch_kernels.carriage_batch_kernel`.

    ``z`` (n_balls,) [m] and ``loaded`` (n_balls,) the balls (ball b = t n + j); ``track``
    (n_tracks, 6) per track c, s (cos and sin of its orientation), -s, -c, s x - c y and
    c x + s y [m]; ``scale`` (5,) the DOF scales, ``length`` [m] the layout's length scale.
    Writes ``rows`` (10, n_balls), row 5 c + j holding A[:, c, j] (the layout of the joint
    Newton's ``amap``), the rows of A = E_t^T B(p) at each ball's z times ``scale`` (0 for a
    ball that is not loaded), and ``zetas`` (n_balls,) z / ``length``. The same operations,
    element by element, as :meth:`tolsim.physics.carriage.CarriageLayout.groove_map_at` times
    ``scale`` with ``np.where`` on the unloaded balls."""
    tracks = track.shape[0]
    n = z.shape[0] // tracks
    for t in range(tracks):
        c, s, ms, mc, gx, gy = (track[t, 0], track[t, 1], track[t, 2], track[t, 3],
                                track[t, 4], track[t, 5])
        for j in range(n):
            b = t * n + j
            zz = z[b]
            zetas[b] = zz / length
            for k in range(10):
                rows[k, b] = 0.0
            if loaded[b]:
                rows[0, b] = c * scale[0]
                rows[1, b] = s * scale[1]
                rows[2, b] = (ms * zz) * scale[2]
                rows[3, b] = (c * zz) * scale[3]
                rows[4, b] = gx * scale[4]
                rows[5, b] = ms * scale[0]
                rows[6, b] = c * scale[1]
                rows[7, b] = (mc * zz) * scale[2]
                rows[8, b] = (ms * zz) * scale[3]
                rows[9, b] = gy * scale[4]


@jit(inline="always")
def gram_of_rows(rows, out):
    """``out`` (5, 5) = sum_b A_b^T A_b of maps given by rows (10, n_balls), the balls summed
    in order."""
    for k in range(5):
        for l in range(k, 5):
            total = 0.0
            for b in range(rows.shape[1]):
                total += rows[k, b] * rows[l, b] + rows[5 + k, b] * rows[5 + l, b]
            out[k, l] = total
            out[l, k] = total


@jit(inline="always")
def gram_diagonal(rows, out):
    """The diagonal of :func:`gram_of_rows` (the same sums), all that :func:`trace_bounds`
    reads; the other entries NaN, marking ``out`` as not formed (:func:`formed_pivot`)."""
    for k in range(5):
        total = 0.0
        for b in range(rows.shape[1]):
            total += rows[k, b] * rows[k, b] + rows[5 + k, b] * rows[5 + k, b]
        for l in range(5):
            out[k, l] = np.nan
        out[k, k] = total


@jit(inline="always")
def largest_eigenvalue(mat, free, work):
    """Largest eigenvalue of the symmetric ``mat[free][:, free]`` (``work``: scratch of at
    least that size) by cyclic Jacobi rotations.

    Each rotation zeroes one off-diagonal entry (the stable form of [Press2007] Sec. 11.1);
    the sweeps stop when the off-diagonal entries carry less than 1e-34 of the squared
    Frobenius norm, or when a sweep rotated nothing. The eigenvalues of a symmetric positive
    semi-definite matrix come out to a few units of round-off of the largest one, as LAPACK's
    (``numpy.linalg.eigvalsh``; tested in ``tests/physics/carriage``).

    References
    ----------
    .. [Press2007] W. H. Press et al., Numerical Recipes, 3rd ed., Cambridge UP, 2007.
    """
    nf = free.shape[0]
    if nf == 0:
        return np.nan
    total = 0.0
    for i in range(nf):
        for j in range(nf):  # the lower triangle, as eigvalsh
            fi, fj = max(free[i], free[j]), min(free[i], free[j])
            work[i, j] = mat[fi, fj]
            total += work[i, j] * work[i, j]
    for _ in range(_JACOBI_SWEEPS):
        off = 0.0
        for p in range(nf):
            for q in range(p + 1, nf):
                off += work[p, q] * work[p, q]
        if not off > 1e-34 * total:
            break
        for p in range(nf):
            for q in range(p + 1, nf):
                apq = work[p, q]
                if apq == 0.0:
                    continue
                theta = (work[q, q] - work[p, p]) / (2.0 * apq)
                if abs(theta) > 1e150:
                    t = 0.5 / theta
                else:
                    t = 1.0 / (abs(theta) + np.sqrt(theta * theta + 1.0))
                    if theta < 0.0:
                        t = -t
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                tau = s / (1.0 + c)
                work[p, p] -= t * apq
                work[q, q] += t * apq
                work[p, q] = 0.0
                work[q, p] = 0.0
                for r in range(nf):
                    if r == p or r == q:
                        continue
                    arp, arq = work[r, p], work[r, q]
                    work[r, p] = arp - s * (arq + tau * arp)
                    work[r, q] = arq + s * (arp - tau * arq)
                    work[p, r] = work[r, p]
                    work[q, r] = work[r, q]
    top = -np.inf
    for i in range(nf):
        top = max(top, work[i, i])
    return top


@jit(inline="always")
def trace_bounds(geometric, free, k_ref, threshold):
    """``threshold`` (3,) of :func:`singular_pivot` from the trace of ``geometric[free][:,
    free]`` (the largest eigenvalue not computed yet)."""
    nf = free.shape[0]
    trace = 0.0
    for i in range(nf):
        trace += geometric[free[i], free[i]]
    threshold[0] = 1e-10 * k_ref * (trace / nf) * (1.0 - 1e-12)
    threshold[1] = 1e-10 * k_ref * trace * (1.0 + 1e-12)
    threshold[2] = np.nan


@jit(inline="always")
def singular_pivot(pmin, threshold, geometric, free, k_ref, work):
    """Whether a Cholesky pivot ``pmin`` makes a tangent singular: not pmin > 1e-10 k_ref
    lambda_max, lambda_max the largest eigenvalue of ``geometric[free][:, free]``.

    ``threshold`` (3,): a lower and an upper bound of 1e-10 k_ref lambda_max and its value
    (NaN until needed; then computed by :func:`largest_eigenvalue` into it, ``work`` (5, 5)
    scratch). For sum_b A_b^T A_b, positive semi-definite, lambda_max lies between its trace
    over the nf free DOFs and that trace (:func:`trace_bounds`, with a margin of 1e-12 for
    round-off), so the eigenvalue is needed only for a pivot in between: a tangent of
    condition about 1e10, which no solve of the packaged configs meets (a loaded tangent's
    pivots are of order k_ref lambda, an unloaded one's round-off). The test is the one of
    :func:`tolsim.physics.carriage.solve_carriage` (smallest eigenvalue of the tangent
    against 1e-10 times the largest of k_ref sum_b A_b^T A_b) at the cost of a trace.
    """
    if not pmin > threshold[0]:
        return True
    if pmin > threshold[1]:
        return False
    if np.isnan(threshold[2]):
        threshold[2] = 1e-10 * k_ref * largest_eigenvalue(geometric, free, work)
    return not pmin > threshold[2]


@jit(inline="always")
def formed_pivot(pmin, threshold, geometric, rows, free, k_ref, work):
    """:func:`singular_pivot` for a ``geometric`` that may hold only its diagonal
    (:func:`gram_diagonal`: NaN elsewhere): formed from ``rows`` by :func:`gram_of_rows`,
    in place, when the test needs its largest eigenvalue (a pivot between the trace
    bounds), so the answer is that of the formed matrix."""
    if (np.isnan(geometric[0, 1]) and np.isnan(threshold[2]) and pmin > threshold[0]
            and not pmin > threshold[1]):
        gram_of_rows(rows, geometric)
    return singular_pivot(pmin, threshold, geometric, free, k_ref, work)
