"""Trains of balls after contact (tolsim.physics.trains): clusters, forces, events.

References for the expected values:
* "module" = the derivation in the Notes of tolsim.physics.trains.cluster_velocities, eqs.
  (1)-(6);
* issue 13 ("After contact", Done means) for the two-ball result;
* [Lin2018] Sec. 3.2 for the paper's pair.
Each kernel has an independent twin here. ``cluster_velocities`` is checked against the
min-max formula of isotonic regression (Barlow et al. 1972, Thm 1.4.4). The event-driven
kernel is checked against a pure-Python event loop that pools in any order, and against a
brute-force small-step projection integration.
"""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.physics.trains import (
    TIE_TOLERANCE,
    cluster_velocities,
    net_push,
    train_contact_constant,
)
from tolsim.study.pipeline.propagation import first_contact_constant

V = 0.2  # groove velocity [m/s] (the brief's 200 mm/s)
HALF = V / 2


# ----------------------------------------------------------------------------- twins


def _ranges_open(touching):
    """open_count[:, k] = number of open pairs among pairs < k (shape (m, n))."""
    m = touching.shape[0]
    return np.concatenate([np.zeros((m, 1), int), np.cumsum(~touching, axis=1)], axis=1)


def isotonic_minmax(y, weight, touching=None):
    """Weighted non-decreasing isotonic regression of y on chains of closed pairs, by the
    min-max formula w_i = max_{a <= i} min_{b >= i} mean_w(y[a..b]) restricted to ranges
    inside one chain (Barlow et al. 1972, Thm 1.4.4). O(n^3) per train, no PAV."""
    m, n = y.shape
    if touching is None:
        touching = np.ones((m, n - 1), bool)
    zeros = np.zeros((m, 1))
    cw = np.concatenate([zeros, np.cumsum(weight, axis=1)], axis=1)
    cy = np.concatenate([zeros, np.cumsum(weight * y, axis=1)], axis=1)
    a = np.arange(n)[:, None]
    b = np.arange(n)[None, :]
    bb = np.broadcast_to(b, (n, n))
    aa = np.broadcast_to(a, (n, n))
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = (cy[:, bb + 1] - cy[:, aa]) / (cw[:, bb + 1] - cw[:, aa])  # (m, a, b)
    oc = _ranges_open(touching)
    crosses = (oc[:, bb] - oc[:, aa]) > 0  # range [a, b] spans an open pair
    mean = np.where((bb >= aa) & ~crosses, mean, np.inf)
    inner = np.minimum.accumulate(mean[:, :, ::-1], axis=2)[:, :, ::-1]  # min over b >= i
    crosses_ai = crosses  # same test for [a, i]
    inner = np.where((bb >= aa) & ~crosses_ai, inner, -np.inf)  # a <= i inside the chain
    return inner.max(axis=1)


def forces_from_velocities(eps, stiffness, velocity, touching):
    """Q_j from the balance of each ball (eq. 2 with c = 0), summed along each chain."""
    m, n = eps.shape
    q = np.zeros((m, n - 1))
    carry = np.zeros(m)
    for j in range(n - 1):
        carry = carry + stiffness[:, j] * (eps[:, j] - velocity[:, j])
        q[:, j] = np.where(touching[:, j], carry, 0.0)
        carry = np.where(touching[:, j], carry, 0.0)
    return q


def event_twin(gap, eps, stiffness, v, horizon):
    """Pure-Python event-driven twin of one train (c = 0): clusters as [first, last] lists,
    touching violators pooled in any order (leftmost first, repeatedly), no bonds."""
    n = len(eps)
    half = v / 2
    clusters = [[i, i] for i in range(n)]
    g = [float(x) for x in gap]
    contact = [np.inf] * (n - 1)

    def speed(c):
        idx = range(c[0], c[1] + 1)
        if c[0] == c[1]:
            return eps[c[0]]
        return sum(stiffness[i] * eps[i] for i in idx) / sum(stiffness[i] for i in idx)

    def pool(now):
        formed_pairs = []
        changed = True
        while changed:
            changed = False
            for k in range(len(clusters) - 1):
                a, b = clusters[k], clusters[k + 1]
                if g[a[1]] == 0.0 and speed(a) > speed(b):
                    formed_pairs.append(a[1])
                    clusters[k:k + 2] = [[a[0], b[1]]]
                    changed = True
                    break
        for j in formed_pairs:
            contact[j] = now
        # clusters containing a new contact
        return sum(1 for c in clusters if any(c[0] <= j < c[1] for j in formed_pairs))

    formed = pool(0.0)
    t = 0.0
    first = 0.0 if formed else np.inf
    while True:
        best, which = np.inf, -1
        for k in range(len(clusters) - 1):
            a, b = clusters[k], clusters[k + 1]
            rate = (speed(a) - speed(b)) * half
            if rate > 0:
                te = t + g[a[1]] / rate
                if te < best:
                    best, which = te, k
        if best > horizon:
            break
        for k in range(len(clusters) - 1):
            a, b = clusters[k], clusters[k + 1]
            rate = (speed(a) - speed(b)) * half
            simultaneous = rate > 0 and t + g[a[1]] / rate <= best + TIE_TOLERANCE * horizon
            g[a[1]] += (speed(b) - speed(a)) * half * (best - t)
            if k == which or simultaneous or g[a[1]] <= 0.0:
                g[a[1]] = 0.0
        t = best
        formed += pool(t)
        if not np.isfinite(first):
            first = t
    velocity = np.empty(n)
    force = np.zeros(n - 1)
    for c in clusters:
        w = speed(c)
        velocity[c[0]:c[1] + 1] = w
        r = 0.0
        for i in range(c[0], c[1]):
            r += stiffness[i] * (eps[i] - w)
            force[i] = r
    multi = sum(1 for c in clusters if c[1] > c[0])
    return dict(contact_time=np.array(contact), velocity=velocity, contact_force=force,
                clusters_formed=formed, cluster_count=multi, first_contact_time=first)


def projection_integration(gap, eps, stiffness, v, horizon, steps, record_every):
    """Brute force: each small step moves every ball freely, then projects the positions
    onto "no overlap" with weights K (y_i = u_i + sum of gaps before i must be
    non-decreasing; min-max isotonic regression, not PAV). No events, no clusters."""
    m, n = eps.shape
    dt = horizon / steps
    offset = np.concatenate([np.zeros((m, 1)), np.cumsum(gap, axis=1)], axis=1)
    y = offset.copy()
    contact = np.full((m, n - 1), np.inf)
    grid = [y - offset]
    closed_tol = 1e-14  # [m], far below any drawn gap and any step (~1e-9 m)
    previous = y
    for k in range(steps):
        previous = y
        y = isotonic_minmax(y + dt * v / 2 * eps, stiffness)
        closed = np.diff(y, axis=1) <= closed_tol
        contact = np.where(closed & np.isinf(contact), (k + 1) * dt, contact)
        if (k + 1) % record_every == 0:
            grid.append(y - offset)
    velocity = (y - previous) / (dt * v / 2)
    return np.stack(grid, axis=1), contact, velocity


def random_trains(rng, m, n, zero_gap_fraction=0.2):
    gap = rng.uniform(0.0, 2e-5, (m, n - 1))
    gap[rng.random(gap.shape) < zero_gap_fraction] = 0.0
    eps = rng.normal(0.0, 1e-3, (m, n))
    stiffness = rng.uniform(1e3, 1e4, (m, n))
    return gap, eps, stiffness


# ----------------------------------------------------------------------------- two balls


def test_two_balls_k_weighted_mean_and_force(rng):
    # issue 13, Done means; module eqs. (5), (6): w = (K1 e1 + K2 e2) / (K1 + K2),
    # Q = K1 K2 (e1 - e2) / (K1 + K2), to 1e-12.
    m = 200
    eps = rng.normal(0.0, 1e-3, (m, 2))
    eps[:, 0] = np.abs(eps[:, 0]) + 1e-4   # trailing ball faster: they touch
    eps[:, 1] = -np.abs(eps[:, 1]) - 1e-4
    stiffness = rng.uniform(1e3, 1e4, (m, 2))
    gap = rng.uniform(0.0, 2e-5, (m, 1))
    horizon = 1.0
    r = train_contact_constant(gap, eps, stiffness, V, horizon)
    k1, k2 = stiffness.T
    e1, e2 = eps.T
    mean = (k1 * e1 + k2 * e2) / (k1 + k2)
    force = k1 * k2 * (e1 - e2) / (k1 + k2)
    t_contact = gap[:, 0] / ((e1 - e2) * HALF)
    assert np.all(t_contact < horizon)
    assert_allclose(r.velocity, np.column_stack([mean, mean]), rtol=1e-12)
    assert_allclose(r.contact_force[:, 0], force, rtol=1e-12)
    assert_allclose(r.net_push, np.column_stack([-force, force]), rtol=1e-12)
    assert_allclose(r.contact_force_max, force, rtol=1e-12)
    assert_allclose(r.contact_time[:, 0], t_contact, rtol=1e-15)
    assert_allclose(r.contact_fraction, 1 - t_contact / horizon, rtol=1e-12)
    # positions: free until contact, then the cluster speed
    u1 = HALF * (e1 * t_contact + mean * (horizon - t_contact))
    assert_allclose(r.displacement[:, 0], u1, rtol=1e-12)
    assert_allclose(r.displacement[:, 1] - r.displacement[:, 0], -gap[:, 0],
                    rtol=1e-9, atol=1e-20)  # the gap is closed
    # the step rule gives the same
    w, q = cluster_velocities(eps, stiffness, np.ones((m, 1), bool))
    assert_allclose(w[:, 0], mean, rtol=1e-12)
    assert_allclose(q[:, 0], force, rtol=1e-12)


def test_two_balls_with_braking_sensitivity(rng):
    # module eq. (1) solved by hand for two touching balls: ball 0 gets only Q_front,
    # w = e0 - b0 Q, ball 1 only Q_back, w = e1 + a1 Q, with a = 1/K + c, b = 1/K - c:
    # Q = (e0 - e1) / (b0 + a1), w = (a1 e0 + b0 e1) / (a1 + b0). Tolerance 1e-12.
    m = 200
    eps = np.column_stack([rng.uniform(1e-4, 2e-3, m), rng.uniform(-2e-3, -1e-4, m)])
    stiffness = rng.uniform(1e3, 1e4, (m, 2))
    braking = rng.uniform(-0.6, 0.6, (m, 2)) / stiffness
    a1 = 1 / stiffness[:, 1] + braking[:, 1]
    b0 = 1 / stiffness[:, 0] - braking[:, 0]
    force = (eps[:, 0] - eps[:, 1]) / (b0 + a1)
    mean = (a1 * eps[:, 0] + b0 * eps[:, 1]) / (a1 + b0)
    w, q = cluster_velocities(eps, stiffness, np.ones((m, 1), bool), braking)
    assert_allclose(q[:, 0], force, rtol=1e-12)
    assert_allclose(w, np.column_stack([mean, mean]), rtol=1e-12)
    r = train_contact_constant(np.zeros((m, 1)), eps, stiffness, V, 1.0,
                               braking_sensitivity=braking)
    assert_allclose(r.contact_force[:, 0], force, rtol=1e-12)
    assert_allclose(r.velocity[:, 0], mean, rtol=1e-12)


def test_lin2018_sec32_pair_after_contact():
    # [Lin2018] Sec. 3.2: eps = +-0.754 % (Eq. 26, ERRATA 2), gap 0.5 mm, v = 10 mm/s: the
    # pair touches at t = 0.5e-3 / (2 * 0.00754 * 0.005) = 6.63 s. With equal K (here
    # 2000 N, a placeholder for the single-ball physics) the cluster stands at w = 0 and
    # Q = K * 0.00754 (module eq. 6), to 1e-12.
    eps, k = 0.00754, 2000.0
    r = train_contact_constant([[0.5e-3]], [[eps, -eps]], k, 0.01, 10.0, samples=11)
    assert_allclose(r.first_contact_time, 0.5e-3 / (2 * eps * 0.005), rtol=1e-14)
    assert_allclose(r.first_contact_time, 6.63, atol=0.01)
    assert_allclose(r.velocity, 0.0, atol=1e-18)
    assert_allclose(r.contact_force, [[k * eps]], rtol=1e-12)
    assert_allclose(r.contact_fraction, (10.0 - r.first_contact_time) / 10.0, rtol=1e-12)
    # on the grid (t = 0, 1, ..., 10 s): no force before 6.63 s, K eps after it
    expected = np.where(np.arange(11) >= 7, k * eps, 0.0)
    assert_allclose(r.grid_contact_force[0, :, 0], expected, rtol=1e-12)
    assert_allclose(r.travel, 0.01 * np.arange(11), rtol=1e-15)


# ----------------------------------------------------------------------------- hand cases


def test_three_balls_hand_computed_events():
    # Hand computation (module eqs. 5, 6), K = 1000 N each, v = 0.2 m/s (v/2 = 0.1 m/s),
    # eps = (2, 0, -1) e-3, gaps (40, 50) um, T = 1 s:
    # pair 0 closes at 40e-6 / (0.1 * 2e-3) = 0.2 s; cluster {0, 1} at w = 1e-3,
    # Q0 = 1000 * (2 - 1) e-3 = 1 N. Gap 1 is then 50 - 0.1 * 1e-3 * 0.2 * 1e6 = 30 um and
    # closes at rate 0.1 * (1 + 1) e-3: at 0.2 + 0.15 = 0.35 s. All three at w = 1/3 e-3:
    # Q0 = 1000 (2 - 1/3) e-3 = 5/3 N, Q1 = 5/3 + 1000 (0 - 1/3) e-3 = 4/3 N;
    # P = (-5/3, 1/3, 4/3) N. Ball 0 travels 0.1 (2e-3 * 0.2 + 1e-3 * 0.15 + 1/3e-3 * 0.65).
    r = train_contact_constant([[40e-6, 50e-6]], [[2e-3, 0.0, -1e-3]], 1000.0, V, 1.0,
                               samples=5, segments=True)
    assert_allclose(r.contact_time, [[0.2, 0.35]], rtol=1e-12)
    assert r.first_contact_pair[0] == 0
    assert_allclose(r.first_contact_time, [0.2], rtol=1e-15)
    assert_allclose(r.velocity, [[1 / 3 * 1e-3] * 3], rtol=1e-12)
    assert_allclose(r.contact_force, [[5 / 3, 4 / 3]], rtol=1e-12)
    assert_allclose(r.net_push, [[-5 / 3, 1 / 3, 4 / 3]], rtol=1e-12)
    assert_allclose(r.contact_force_max, [5 / 3], rtol=1e-12)
    assert_allclose(r.contact_fraction, [0.8], rtol=1e-12)
    assert r.clusters_formed[0] == 2 and r.cluster_count[0] == 1
    assert_array_equal(r.cluster, [[0, 0, 0]])
    u0 = 0.1 * (2e-3 * 0.2 + 1e-3 * 0.15 + 1e-3 / 3 * 0.65)
    assert_allclose(r.displacement[0, 0], u0, rtol=1e-12)
    # segments: [0, 0.2) free, [0.2, 0.35) one pair, then all three
    assert_allclose(r.segment_start, [[0.0, 0.2, 0.35]], rtol=1e-12)
    assert_allclose(r.segment_contact_force[0], [[0, 0], [1, 0], [5 / 3, 4 / 3]],
                    rtol=1e-12, atol=0)
    # grid at t = 0.25 s (travel 50 mm): cluster {0, 1}, ball 2 alone
    assert_array_equal(r.grid_cluster[0, 1], [0, 0, 2])
    assert_allclose(r.grid_net_push[0, 1], [-1.0, 1.0, 0.0], rtol=1e-12, atol=0)


def test_initial_cluster_must_split_immediately():
    # Three balls touching at t = 0, K = (1, 2, 1) kN, eps = (3, 0, 2) e-3. As one cluster:
    # w = (3 + 0 + 2) / 4 = 1.25e-3, Q0 = 1000 (3 - 1.25) e-3 = 1.75 N,
    # Q1 = 1.75 + 2000 (0 - 1.25) e-3 = -0.75 N < 0: impossible, so it splits at once.
    # PAV by hand: pool (3, 0) with weights (1, 2) -> 1e-3 < 2e-3, so clusters {0, 1} at
    # w = 1e-3 with Q0 = 1000 (3 - 1) e-3 = 2 N, and ball 2 leaving at 2e-3.
    eps = np.array([[3e-3, 0.0, 2e-3]])
    stiffness = np.array([[1000.0, 2000.0, 1000.0]])
    naive = np.sum(stiffness * eps) / np.sum(stiffness)
    assert 1000 * (3e-3 - naive) + 2000 * (0 - naive) < 0  # the naive cluster is invalid
    r = train_contact_constant([[0.0, 0.0]], eps, stiffness, V, 1.0, samples=3)
    assert_allclose(r.velocity, [[1e-3, 1e-3, 2e-3]], rtol=1e-12)
    assert_allclose(r.contact_force, [[2.0, 0.0]], rtol=1e-12, atol=0)
    assert_array_equal(r.contact_time, [[0.0, np.inf]])
    assert r.first_contact_time[0] == 0.0 and r.first_contact_pair[0] == 0
    assert r.clusters_formed[0] == 1 and r.cluster_count[0] == 1
    assert_allclose(r.contact_fraction, [1.0])
    # gap 1 opens at 0.1 m/s * 1e-3: 50 um at t = 0.5 s
    gap1 = r.grid_displacement[0, :, 2] - r.grid_displacement[0, :, 1]
    assert_allclose(gap1, [0.0, 50e-6, 100e-6], rtol=1e-12, atol=1e-20)
    w, q = cluster_velocities(eps, stiffness, [[True, True]])
    assert_allclose(w, r.velocity, rtol=1e-15)
    assert_allclose(q, r.contact_force, rtol=1e-15)


def test_simultaneous_contacts_form_one_cluster():
    # Hand computation: eps = (1, 0, -1) e-3, K = 1000 N, gaps 10 um each: both pairs close
    # at 10e-6 / (0.1 * 1e-3) = 0.1 s, in one event. Then w = 0, Q0 = 1000 * 1e-3 = 1 N and
    # Q1 = 1 + 1000 * (0 - 0) = 1 N; one cluster formed, two segments.
    r = train_contact_constant([[10e-6, 10e-6]], [[1e-3, 0.0, -1e-3]], 1000.0, V, 1.0,
                               segments=True)
    assert_allclose(r.contact_time, [[0.1, 0.1]], rtol=1e-12)
    assert_allclose(r.contact_force, [[1.0, 1.0]], rtol=1e-12)
    assert_allclose(r.velocity, 0.0, atol=1e-18)
    assert r.clusters_formed[0] == 1 and r.cluster_count[0] == 1
    assert_allclose(r.segment_start, [[0.0, 0.1, np.inf]], rtol=1e-12)


# ----------------------------------------------------------------------------- twins


def test_cluster_velocities_matches_minmax_twin(rng):
    # Twin: the min-max formula of isotonic regression (Barlow et al. 1972, Thm 1.4.4),
    # forces from each ball's balance. Tolerance: 1e-12 of eps, 1e-9 N on forces ~ 1 N.
    m, n = 3000, 9
    eps = rng.normal(0.0, 1e-3, (m, n))
    stiffness = rng.uniform(1e3, 1e4, (m, n))
    touching = rng.random((m, n - 1)) < 0.7
    w, q = cluster_velocities(eps, stiffness, touching)
    w_ref = isotonic_minmax(eps, stiffness, touching)
    assert_allclose(w, w_ref, rtol=0, atol=1e-15)
    q_ref = forces_from_velocities(eps, stiffness, w_ref, touching)
    assert_allclose(q, np.maximum(q_ref, 0), rtol=0, atol=1e-9)
    assert q.min() >= 0.0
    assert 0.2 < (q > 0).mean() < 0.8  # both outcomes exercised
    # leading dims are kept
    w3, q3 = cluster_velocities(eps.reshape(3, -1, n), stiffness.reshape(3, -1, n),
                                touching.reshape(3, -1, n - 1))
    assert_array_equal(w3.reshape(m, n), w)
    assert_array_equal(q3.reshape(m, n - 1), q)


def test_cluster_velocities_kkt_with_braking(rng):
    # With c != 0 (eq. 1) the solution is unique (module: reduction to eq. 2), so meeting
    # the contact conditions (3) and each ball's law (1) identifies it. Tolerances: 1e-12
    # relative on the law, 1e-15 on equal velocities inside a cluster.
    m, n = 2000, 8
    eps = rng.normal(0.0, 1e-3, (m, n))
    stiffness = rng.uniform(1e3, 1e4, (m, n))
    braking = rng.uniform(-0.5, 0.5, (m, n)) / stiffness
    touching = rng.random((m, n - 1)) < 0.8
    w, q = cluster_velocities(eps, stiffness, touching, braking)
    back = np.concatenate([np.zeros((m, 1)), q], axis=1)
    front = np.concatenate([q, np.zeros((m, 1))], axis=1)
    law = eps + (back - front) / stiffness + braking * (back + front)
    assert_allclose(w, law, rtol=0, atol=1e-12 * 1e-3)
    assert q.min() >= 0.0
    assert np.all(q[~touching] == 0.0)
    separation = np.diff(w, axis=1)
    assert np.all(separation[touching] >= -1e-15)          # no overlap
    assert np.all(np.abs(separation[q > 0]) <= 1e-15)       # complementarity
    # one whole chain: the (n x n) linear system of eq. (1) with unknowns (w, Q_0..Q_{n-2})
    k = 0
    whole = np.ones((1, n - 1), bool)
    while True:  # a train whose whole chain is one cluster
        w1, q1 = cluster_velocities(eps[k:k + 1], stiffness[k:k + 1], whole, braking[k:k + 1])
        if np.all(q1 > 0):
            break
        k += 1
    a = 1 / stiffness[k] + braking[k]
    b = 1 / stiffness[k] - braking[k]
    mat = np.zeros((n, n))
    mat[:, 0] = 1.0  # w
    for i in range(n):
        if i > 0:
            mat[i, i] -= a[i]       # -a_i Q_{i-1}
        if i < n - 1:
            mat[i, i + 1] += b[i]   # +b_i Q_i
    sol = np.linalg.solve(mat, eps[k])
    assert_allclose(w1[0], sol[0], rtol=1e-10)
    assert_allclose(q1[0], sol[1:], rtol=1e-9)


def test_event_kernel_matches_python_twin(rng):
    # Twin: pure-Python event loop with explicit clusters, pooling in any order, no bonds.
    # Same event times to 1e-12 relative, forces to 1e-9 relative, counts exactly.
    m, n, horizon = 400, 8, 0.4
    gap, eps, stiffness = random_trains(rng, m, n)
    r = train_contact_constant(gap, eps, stiffness, V, horizon)
    assert r.valid.all()
    for t in range(m):
        ref = event_twin(gap[t], eps[t], stiffness[t], V, horizon)
        assert_allclose(r.contact_time[t], ref["contact_time"], rtol=1e-12)
        assert_allclose(r.velocity[t], ref["velocity"], rtol=1e-10, atol=1e-18)
        assert_allclose(r.contact_force[t], ref["contact_force"], rtol=1e-9, atol=1e-12)
        assert r.clusters_formed[t] == ref["clusters_formed"]
        assert r.cluster_count[t] == ref["cluster_count"]
        assert r.first_contact_time[t] == ref["first_contact_time"]
    assert 0 < r.cluster_count.max() and r.clusters_formed.max() >= 3


small_values = st.integers(-3, 3)


@given(st.integers(2, 7).flatmap(lambda n: st.tuples(
    st.lists(st.integers(0, 2), min_size=n - 1, max_size=n - 1),
    st.lists(small_values, min_size=n, max_size=n),
    st.lists(st.integers(1, 3), min_size=n, max_size=n))))
def test_degenerate_trains_match_python_twin(train):
    # Property: small integer-valued trains (ties in speed and time, zero gaps, resting
    # pairs) give the twin's events, forces and counts; forces >= 0, pushes sum to zero.
    # Tolerances as in test_event_kernel_matches_python_twin.
    gap, eps, stiffness = (np.array([x], float) for x in train)
    gap, eps, stiffness = 1e-5 * gap, 1e-3 * eps, 1e3 * stiffness
    r = train_contact_constant(gap, eps, stiffness, V, 0.5)
    ref = event_twin(gap[0], eps[0], stiffness[0], V, 0.5)
    assert_allclose(r.contact_time[0], ref["contact_time"], rtol=1e-12)
    assert_allclose(r.velocity[0], ref["velocity"], rtol=1e-12, atol=1e-18)
    assert_allclose(r.contact_force[0], ref["contact_force"], rtol=1e-9, atol=1e-12)
    assert r.clusters_formed[0] == ref["clusters_formed"]
    assert r.cluster_count[0] == ref["cluster_count"]
    assert r.first_contact_time[0] == ref["first_contact_time"]
    assert r.contact_force.min() >= 0.0
    assert abs(r.net_push.sum()) <= 1e-12


def test_event_driven_matches_projection_integration(rng):
    # Brute force (module-independent): 4000 steps of free motion + weighted projection.
    # The projection keeps the K-weighted centre of every pooled block, so it is exact
    # between events and after a single event in a step; a step holding a chain of events
    # (cluster A catching cluster B that catches C within dt) lags by one step of relative
    # motion. Tolerances: positions dt (v/2) (max eps - min eps) (measured: 7e-16 m, no
    # chains in this draw); contact times within one step, 0 <= t_bf - t <= dt (measured
    # up to 1.0 dt; a chain within a step would add up to one more step and fail here);
    # velocities 1e-12 (measured 3e-14); forces 1e-9 N on forces up to 24 N (measured 4e-11).
    m, n, horizon, steps, every = 120, 7, 0.4, 4000, 100
    gap, eps, stiffness = random_trains(rng, m, n)
    r = train_contact_constant(gap, eps, stiffness, V, horizon, samples=steps // every + 1)
    grid, contact, velocity = projection_integration(gap, eps, stiffness, V, horizon, steps,
                                                    every)
    dt = horizon / steps
    step = dt * HALF * (eps.max() - eps.min())
    assert_allclose(r.grid_displacement, grid, rtol=0, atol=step)
    assert_array_equal(np.isfinite(r.contact_time), np.isfinite(contact))
    hit = np.isfinite(contact)
    assert 0.3 < hit.mean() < 0.95  # contacts and non-contacts, many events
    delay = contact[hit] - r.contact_time[hit]
    assert delay.min() >= -1e-12 and delay.max() <= dt * (1 + 1e-9)
    # velocities and forces at the horizon (trains without an event in the last 2 steps)
    quiet = ~np.any((r.contact_time > horizon - 2 * dt) & hit, axis=1)
    assert quiet.mean() > 0.9
    assert_allclose(velocity[quiet], r.velocity[quiet], rtol=0, atol=1e-12)
    closed = np.isfinite(r.contact_time)
    q_ref = forces_from_velocities(eps, stiffness, velocity, closed)
    assert_allclose(r.contact_force[quiet], q_ref[quiet], rtol=0, atol=1e-9)


def test_first_contact_equals_propagation(rng):
    # tolsim.study.pipeline.propagation.first_contact_constant is today's answer; bit for bit,
    # including zero gaps (contacts at t = 0), unresolved (NaN) balls and no contact.
    m, n = 20000, 11
    gap, eps, stiffness = random_trains(rng, m, n, zero_gap_fraction=0.05)
    eps[rng.random(eps.shape) < 0.002] = np.nan
    for horizon, contact in ((0.003, (0.1, 0.9)), (0.3, (0.99, 1.0))):
        r = train_contact_constant(gap, eps, stiffness, V, horizon)
        t_ref, pair_ref = first_contact_constant(gap, eps, V, horizon)
        assert_array_equal(r.first_contact_time, t_ref)
        assert_array_equal(r.first_contact_pair, pair_ref)
        assert contact[0] < np.isfinite(t_ref).mean() < contact[1]
        assert np.any(t_ref == 0.0) and np.any(~r.valid)


# ----------------------------------------------------------------------------- invariants


def test_mirrored_train_gives_mirrored_result(rng):
    # Reflecting the relative motion (z - v t / 2 -> -(z - v t / 2)): ball order reversed,
    # eps -> -eps, K and the gaps reversed. Back and front swap, so P -> -P, and for law (1)
    # to stay odd under the reflection its back/front-symmetric friction term must flip too:
    # c -> -c reversed. Expected: velocities and displacements negated and reversed, forces
    # reversed, pushes negated and reversed, the same times and counts. Tolerance 1e-12
    # relative on times and motion, 1e-10 on forces (block sums run in the other order).
    m, n, horizon = 2000, 10, 0.4
    gap, eps, stiffness = random_trains(rng, m, n)
    braking = rng.uniform(-0.3, 0.3, (m, n)) / stiffness
    r = train_contact_constant(gap, eps, stiffness, V, horizon, braking_sensitivity=braking,
                               samples=9)
    s = train_contact_constant(gap[:, ::-1], -eps[:, ::-1], stiffness[:, ::-1], V, horizon,
                               braking_sensitivity=-braking[:, ::-1], samples=9)
    assert_allclose(s.contact_time, r.contact_time[:, ::-1], rtol=1e-12)
    assert_allclose(s.velocity, -r.velocity[:, ::-1], rtol=1e-12, atol=1e-18)
    assert_allclose(s.displacement, -r.displacement[:, ::-1], rtol=1e-12, atol=1e-20)
    assert_allclose(s.contact_force, r.contact_force[:, ::-1], rtol=1e-10, atol=1e-12)
    assert_allclose(s.net_push, -r.net_push[:, ::-1], rtol=1e-10, atol=1e-12)
    assert_allclose(s.grid_contact_force, r.grid_contact_force[:, :, ::-1], rtol=1e-10,
                    atol=1e-12)
    assert_allclose(s.first_contact_time, r.first_contact_time, rtol=1e-12)
    assert_allclose(s.contact_force_max, r.contact_force_max, rtol=1e-10)
    assert_array_equal(s.clusters_formed, r.clusters_formed)
    assert_array_equal(s.cluster_count, r.cluster_count)
    assert r.cluster_count.max() > 0


def test_equal_eps_no_contact(rng):
    # Matched epsilon on every ball (e.g. matched top/bottom deviations): nothing moves
    # relative to anything else, whatever the gaps (zero gaps included): no contact, zero
    # forces, exactly.
    m, n, horizon = 500, 10, 0.4
    gap, _, stiffness = random_trains(rng, m, n, zero_gap_fraction=0.3)
    eps = np.repeat(rng.normal(0.0, 1e-3, (m, 1)), n, axis=1)
    r = train_contact_constant(gap, eps, stiffness, V, horizon, samples=5, segments=True)
    assert r.valid.all()
    assert np.all(np.isinf(r.first_contact_time)) and np.all(r.first_contact_pair == -1)
    assert np.all(np.isinf(r.contact_time))
    assert np.all(r.contact_fraction == 0.0) and np.all(r.contact_force_max == 0.0)
    assert np.all(r.contact_force == 0.0) and np.all(r.grid_contact_force == 0.0)
    assert np.all(r.net_push == 0.0) and np.all(r.clusters_formed == 0)
    assert_array_equal(r.velocity, eps)
    assert_allclose(r.displacement, HALF * eps * horizon, rtol=1e-15)
    assert np.all(np.isinf(r.segment_start[:, 1:]))


def test_ends_of_the_loaded_zone(rng):
    # Module, "Ends of the loaded zone": no force beyond the end balls, so the pushes of
    # every cluster (and of the train) sum to zero, the trailing ball is only held back,
    # the leading ball only pushed. Tolerance 1e-12 N on sums of forces ~ 1 N.
    m, n, horizon = 3000, 12, 0.4
    gap, eps, stiffness = random_trains(rng, m, n)
    r = train_contact_constant(gap, eps, stiffness, V, horizon, samples=7)
    p = r.grid_net_push
    assert_allclose(p.sum(axis=2), 0.0, atol=1e-12)
    for label in range(n):  # per cluster, at every grid point
        mask = r.grid_cluster == label
        assert_allclose(np.where(mask, p, 0.0).sum(axis=2), 0.0, atol=1e-12)
    assert p[..., 0].max() <= 0.0 and p[..., -1].min() >= 0.0
    assert p[..., 0].min() < 0.0  # exercised
    # a leading ball faster than its neighbour runs away force-free (touching at t = 0);
    # a trailing ball slower than its neighbour falls behind force-free
    eps = np.array([[-2e-3, 0.0, 0.0, 3e-3]])
    s = train_contact_constant(np.zeros((1, 3)), eps, 1e3, V, 1.0)
    assert_array_equal(s.contact_force, [[0.0, 0.0, 0.0]])
    assert_allclose(s.displacement, HALF * eps, rtol=1e-15)
    assert np.isinf(s.first_contact_time[0])


def test_forces_never_decrease_and_contacts_persist(rng):
    # Module theorem (constant eps): a contact, once made, lasts to the horizon and its
    # force never decreases. Checked on the segments of random trains.
    m, n, horizon = 2000, 12, 0.4
    gap, eps, stiffness = random_trains(rng, m, n)
    r = train_contact_constant(gap, eps, stiffness, V, horizon, segments=True)
    f = np.nan_to_num(r.segment_contact_force, nan=np.inf)
    # forward-fill the padding with the last segment, then check monotonicity
    last = np.isinf(f)
    f = np.where(last, r.contact_force[:, None, :], f)
    assert np.all(np.diff(f, axis=1) >= -1e-12)
    assert_allclose(r.contact_force_max, r.contact_force.max(axis=1), rtol=1e-15)
    first = np.where(np.isfinite(r.first_contact_time), r.first_contact_time, horizon)
    assert_allclose(r.contact_fraction, (horizon - first) / horizon, rtol=1e-12, atol=1e-15)
    # segment starts are the distinct contact times
    for t in range(200):
        times = np.unique(np.concatenate([[0.0], r.contact_time[t][np.isfinite(
            r.contact_time[t])]]))
        assert_allclose(r.segment_start[t, :len(times)], times, rtol=1e-15)


def test_segments_integrate_a_friction_law(rng):
    # The segments let a caller integrate any friction law exactly; here a nonlinear one,
    # f(P) = |P|^1.5, against a fine travel grid (2001 points: rectangle rule error
    # < max|f| * (events per train) / 2000).
    m, n, horizon = 300, 10, 0.4
    gap, eps, stiffness = random_trains(rng, m, n)
    r = train_contact_constant(gap, eps, stiffness, V, horizon, samples=2001, segments=True)
    start = r.segment_start
    end = np.concatenate([start[:, 1:], np.full((m, 1), np.inf)], axis=1)
    duration = np.clip(np.minimum(end, horizon) - start, 0.0, None)
    duration = np.nan_to_num(duration, posinf=0.0)
    push = net_push(np.nan_to_num(r.segment_contact_force))
    exact = (duration * (np.abs(push) ** 1.5).sum(axis=2)).sum(axis=1) / horizon
    fine = (np.abs(r.grid_net_push[:, :-1]) ** 1.5).sum(axis=2).mean(axis=1)
    peak = (np.abs(r.grid_net_push) ** 1.5).sum(axis=2).max(axis=1)
    assert_allclose(fine, exact, rtol=0, atol=float(peak.max()) * n / 2000)
    assert exact.max() > 0


# ----------------------------------------------------------------------------- errors


def test_invalid_trains_are_flagged(rng):
    gap, eps, stiffness = random_trains(rng, 50, 6)
    # unresolved (NaN eps or K) or sliding (NaN K and c, as the single-ball physics flags
    # them) balls: the train is not followed; everything else is untouched
    eps[3, 2] = np.nan
    stiffness[7, 0] = np.nan
    braking = np.zeros_like(eps)
    braking[11, 4] = np.nan
    r = train_contact_constant(gap, eps, stiffness, V, 0.4, samples=3,
                               braking_sensitivity=braking)
    assert_array_equal(np.flatnonzero(~r.valid), [3, 7, 11])
    assert np.all(np.isnan(r.contact_force[[3, 7]])) and np.all(r.cluster[[3, 7]] == -1)
    assert np.all(np.isnan(r.grid_displacement[[3, 7]]))
    assert np.all(np.isfinite(r.contact_force[r.valid]))
    t_ref, pair_ref = first_contact_constant(gap, eps, V, 0.4)
    assert_array_equal(r.first_contact_time, t_ref)
    assert_array_equal(r.first_contact_pair, pair_ref)
    w, q = cluster_velocities(eps, stiffness, gap == 0, braking)
    assert np.all(np.isnan(w[[3, 7, 11]])) and np.isfinite(w[r.valid]).all()


@pytest.mark.parametrize("bad, match", [
    (dict(initial_gap=[[-1e-6]]), "initial_gap"),
    (dict(initial_gap=[[1e-6, 1e-6]]), "initial_gap"),
    (dict(creep_stiffness=-1.0), "creep_stiffness"),
    (dict(creep_stiffness=[1.0, 2.0, 3.0]), "creep_stiffness"),
    (dict(braking_sensitivity=1.0), "braking_sensitivity"),
    (dict(groove_velocity=0.0), "groove_velocity"),
    (dict(horizon=-1.0), "horizon"),
    (dict(samples=1), "samples"),
])
def test_train_contact_constant_validates(bad, match):
    args = dict(initial_gap=[[1e-6]], velocity_deviation=[[1e-3, 0.0]], creep_stiffness=1e3,
                groove_velocity=0.1, horizon=1.0)
    args.update(bad)
    with pytest.raises(ValueError, match=match):
        train_contact_constant(**args)


def test_cluster_velocities_validates():
    with pytest.raises(ValueError, match="touching"):
        cluster_velocities([[0.0, 0.0]], 1e3, [[True, True]])
    with pytest.raises(ValueError, match="braking_sensitivity"):
        cluster_velocities([[0.0, 0.0]], 1e3, [[True]], braking_sensitivity=2e-3)
