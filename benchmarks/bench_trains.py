"""Throughput of the event-driven trains (tolsim.physics.trains) against plain NumPy and Python.

    python benchmarks/bench_trains.py [--trains 200000] [--balls 10 12] [--repeat 3]

Inputs are drawn inside the run: gaps ~ U(0, 100 um) (all > 0), eps ~ N(0, 1e-3),
K ~ U(1e3, 1e4) N, v = 0.2 m/s, and a horizon of 2 s (a 400 mm stroke). Most pairs whose
eps descends close within the horizon, so the trains see many events (close to the worst
case of n - 1). The timings cover:

* the Numba kernel (:func:`train_contact_constant`) with statistics and the final state only,
  then with a 50-point travel grid, then with the segments;
* :func:`cluster_velocities` (the step rule of ``along_track``) with every pair closed;
* the baseline measured in the same run: the same event-driven algorithm vectorised over the
  trains in plain NumPy (one merge per pass, at most n - 1 passes), and a plain-Python loop
  over the trains on a subset. Both are checked against the kernel before they are timed.

Kernels are compiled (or loaded from the cache) before timing. The figure is balls/s, i.e.
trains x balls per second of wall time, with every core Numba is given (``NUMBA_NUM_THREADS``).
"""

import argparse
import os
import time

import numba
import numpy as np

from tolsim.physics.trains import cluster_velocities, train_contact_constant

V = 0.2
HORIZON = 2.0


def draw(m, n, seed):
    rng = np.random.default_rng(seed)
    gap = rng.uniform(1e-9, 100e-6, (m, n - 1))
    eps = rng.normal(0.0, 1e-3, (m, n))
    stiffness = rng.uniform(1e3, 1e4, (m, n))
    return gap, eps, stiffness


def numpy_events(gap, eps, stiffness, v, horizon):
    """The event-driven algorithm vectorised over trains in NumPy (c = 0, gaps > 0).

    Returns the contact time per pair, the final contact forces and displacements."""
    m, n = eps.shape
    half = v / 2
    rows = np.arange(m)
    ball = np.arange(n)
    label = np.tile(ball, (m, 1))  # each ball's cluster, named by its trailing ball
    zero = np.zeros((m, 1))
    ck = np.concatenate([zero, np.cumsum(stiffness, axis=1)], axis=1)
    cke = np.concatenate([zero, np.cumsum(stiffness * eps, axis=1)], axis=1)
    g = gap.copy()
    t = np.zeros(m)
    u = np.zeros((m, n))
    contact = np.full((m, n - 1), np.inf)

    def speeds(label):
        boundary = label[:, :-1] != label[:, 1:]
        last = np.where(boundary, ball[:-1], n - 1)
        last = np.concatenate([last, np.full((m, 1), n - 1)], axis=1)
        last = np.minimum.accumulate(last[:, ::-1], axis=1)[:, ::-1]
        single = label == ball
        single &= last == ball
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = ((np.take_along_axis(cke, last + 1, 1) - np.take_along_axis(cke, label, 1))
                    / (np.take_along_axis(ck, last + 1, 1) - np.take_along_axis(ck, label, 1)))
        return np.where(single, eps, mean), boundary

    for _ in range(n - 1):
        w, boundary = speeds(label)
        approaching = boundary & (w[:, :-1] > w[:, 1:])
        with np.errstate(invalid="ignore", divide="ignore"):
            te = np.where(approaching, t[:, None] + g / ((w[:, :-1] - w[:, 1:]) * half), np.inf)
        j = np.argmin(te, axis=1)
        tn = te[rows, j]
        active = tn <= horizon
        if not active.any():
            break
        dt = np.where(active, tn - t, 0.0)
        u += half * w * dt[:, None]
        g = np.where(boundary, g + half * (w[:, 1:] - w[:, :-1]) * dt[:, None], 0.0)
        a = rows[active]
        g[a, j[active]] = 0.0
        contact[a, j[active]] = tn[active]
        t = np.where(active, tn, t)
        right = label[rows, np.minimum(j + 1, n - 1)]
        label = np.where(active[:, None] & (label == right[:, None]),
                         label[rows, j][:, None], label)
    w, boundary = speeds(label)
    u += half * w * (horizon - t)[:, None]
    # eq. (6): Q_j = sum of K_i (eps_i - w) from the cluster's trailing ball to j
    running = np.concatenate([zero, np.cumsum(stiffness * (eps - w), axis=1)], axis=1)
    force = running[:, 1:n] - np.take_along_axis(running, label[:, :-1], axis=1)
    force = np.where(boundary, 0.0, np.maximum(force, 0.0))
    return contact, force, u


def python_events(gap, eps, stiffness, v, horizon):
    """A plain-Python loop over trains: clusters as [first, last] lists, O(n^2) per train."""
    half = v / 2
    out = []
    for gp, e, k in zip(gap.tolist(), eps.tolist(), stiffness.tolist(), strict=True):
        n = len(e)
        clusters = [[i, i, k[i], k[i] * e[i], e[i]] for i in range(n)]  # first, last, K, Ke, w
        g = list(gp)
        t = 0.0
        contact = [float("inf")] * (n - 1)
        while True:
            best, which = float("inf"), -1
            for c in range(len(clusters) - 1):
                dw = clusters[c][4] - clusters[c + 1][4]
                if dw > 0:
                    te = t + g[clusters[c][1]] / (dw * half)
                    if te < best:
                        best, which = te, c
            if best > horizon:
                break
            for c in range(len(clusters) - 1):
                g[clusters[c][1]] += (clusters[c + 1][4] - clusters[c][4]) * half * (best - t)
            a, b = clusters[which], clusters[which + 1]
            g[a[1]] = 0.0
            contact[a[1]] = best
            kk, kke = a[2] + b[2], a[3] + b[3]
            clusters[which:which + 2] = [[a[0], b[1], kk, kke, kke / kk]]
            t = best
        out.append(contact)
    return np.array(out)


def best_of(repeat, func):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = func()
        times.append(time.perf_counter() - t0)
    return min(times), out


def bench_size(n, args):
    """Time every variant for trains of n balls and print the table."""
    gap, eps, stiffness = draw(args.trains, n, seed=n)
    balls = args.trains * n
    small = tuple(a[:100] for a in (gap, eps, stiffness))
    train_contact_constant(*small, V, HORIZON, samples=50, segments=True)  # compile
    cluster_velocities(small[1], small[2], np.ones((100, n - 1), bool))

    t_stats, r = best_of(args.repeat, lambda: train_contact_constant(
        gap, eps, stiffness, V, HORIZON))
    q = min(args.grid_trains, args.trains)
    t_grid, _ = best_of(args.repeat, lambda: train_contact_constant(
        gap[:q], eps[:q], stiffness[:q], V, HORIZON, samples=50))
    t_seg, _ = best_of(args.repeat, lambda: train_contact_constant(
        gap, eps, stiffness, V, HORIZON, segments=True))
    closed = np.ones((args.trains, n - 1), bool)
    t_step, _ = best_of(args.repeat, lambda: cluster_velocities(eps, stiffness, closed))

    t_np, (contact_np, force_np, u_np) = best_of(
        1, lambda: numpy_events(gap, eps, stiffness, V, HORIZON))
    np.testing.assert_allclose(contact_np, r.contact_time, rtol=1e-9)
    np.testing.assert_allclose(force_np, r.contact_force, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(u_np, r.displacement, rtol=1e-8, atol=1e-15)
    p = args.python_trains
    t_py, contact_py = best_of(1, lambda: python_events(gap[:p], eps[:p], stiffness[:p],
                                                        V, HORIZON))
    np.testing.assert_allclose(contact_py, r.contact_time[:p], rtol=1e-9)

    events = np.isfinite(r.contact_time).sum(axis=1)
    print(f"\n{n} balls per train, {events.mean():.2f} events per train on average "
          f"(max {events.max()}), contact in {np.isfinite(r.first_contact_time).mean():.0%}"
          " of the trains")
    rows = [
        ("kernel, statistics + final state", t_stats, balls),
        (f"kernel, + 50-point grid ({q} trains)", t_grid, q * n),
        ("kernel, + segments", t_seg, balls),
        ("cluster_velocities (one step)", t_step, balls),
        ("NumPy, vectorised event loop", t_np, balls),
        (f"Python loop ({p} trains)", t_py, p * n),
    ]
    for name, seconds, count in rows:
        rate = count / seconds
        print(f"  {name:38s} {rate / 1e6:9.3f} M balls/s   "
              f"x{rate / (balls / t_np):8.1f} vs NumPy")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trains", type=int, default=200_000)
    parser.add_argument("--balls", type=int, nargs="+", default=[10, 12])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--python-trains", type=int, default=2000)
    parser.add_argument("--grid-trains", type=int, default=20_000,
                        help="trains for the 50-point grid timing (it writes ~190 floats "
                             "per ball: memory bound)")
    args = parser.parse_args()

    print(f"numba threads: {numba.get_num_threads()}; trains: {args.trains}; "
          f"v = {V} m/s, horizon = {HORIZON} s; load average before the run: "
          f"{os.getloadavg()[0]:.2f}")
    for n in args.balls:
        bench_size(n, args)


if __name__ == "__main__":
    main()
