"""Throughput of the eq24 and analytic kernels against plain vectorised NumPy.

    python benchmarks/bench_analytic.py [--balls 10000000] [--repeat 3]

Inputs are drawn inside the run (dbeta ~ N(0, 1 deg), F ~ U(20, 400) N). Prints balls/s for
the Numba kernels and for the same computation in NumPy, their ratio, and the time to just
draw the inputs. Kernels are compiled (or loaded from cache) before timing.
"""

import argparse
import time

import numba
import numpy as np

from tolsim.physics.geometry import (
    CONSTRAINT_SIGN,
    FRICTION_SIGN,
    K_F_PAPER,
    SPIN_SIGN,
    TABLE1,
    contact_frames,
)
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity import analytic as A


def draw(n, seed):
    rng = np.random.default_rng(seed)
    dbeta = rng.normal(0.0, np.deg2rad(1.0), (n, 4))
    force = rng.uniform(20.0, 400.0, (n, 4))
    return dbeta, force


def eq24_numpy(dbeta, force, beta0=np.pi / 4):
    f1 = 0.5 * (force[:, 0] + force[:, 2])
    f2 = 0.5 * (force[:, 1] + force[:, 3])
    w1, w2 = np.cbrt(f1 * f1), np.cbrt(f2 * f2)
    return 0.5 * np.tan(beta0) * (w1 * (dbeta[:, 2] - dbeta[:, 0])
                                  + w2 * (dbeta[:, 3] - dbeta[:, 1])) / (w1 + w2)


def analytic_numpy(dbeta, force, bearing=TABLE1, k_f=K_F_PAPER):
    """Eqs. (17), (18), (21) as a batched 4x4 np.linalg.solve."""
    hc = hertz_constants(bearing.ball_radius, bearing.conformity)
    R = bearing.ball_radius
    _, x_axis, y_axis = contact_frames(bearing.nominal_contact_angle + dbeta)
    a = hc.semi_major_coefficient * np.cbrt(force)
    fric = k_f * R * force / a * FRICTION_SIGN
    spin = 0.375 * force * a * hc.elliptic_e / R * SPIN_SIGN
    mat = np.empty((len(dbeta), 4, 4))
    mat[:, 0] = fric
    mat[:, 1] = fric * x_axis[..., 0]
    mat[:, 2] = fric * x_axis[..., 1]
    mat[:, 3] = CONSTRAINT_SIGN
    rhs = np.zeros((len(dbeta), 4, 1))
    rhs[:, 1, 0] = -(spin * y_axis[..., 0]).sum(-1)
    rhs[:, 2, 0] = -(spin * y_axis[..., 1]).sum(-1)
    rhs[:, 3, 0] = -(dbeta @ CONSTRAINT_SIGN)
    gamma = np.linalg.solve(mat, rhs)[..., 0]
    return 0.5 * np.tan(bearing.nominal_contact_angle) * (
        -dbeta[:, 1] - gamma[:, 1] + dbeta[:, 3] + gamma[:, 3])


def best_of(repeat, func):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = func()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balls", type=int, default=10_000_000)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--numpy-chunk", type=int, default=1_000_000,
                        help="chunk size for the NumPy analytic baseline (memory)")
    args = parser.parse_args()
    n = args.balls
    small = draw(16, 0)
    A.eq24(*small)
    A.analytic(*small)  # compile or load from cache before timing

    t_draw, (dbeta, force) = best_of(args.repeat, lambda: draw(n, 1))
    t_eq24, eps_nb = best_of(args.repeat, lambda: A.eq24(dbeta, force).velocity_deviation)
    t_eq24_np, eps_np = best_of(args.repeat, lambda: eq24_numpy(dbeta, force))
    assert np.allclose(eps_nb, eps_np, rtol=1e-12, atol=1e-15)
    t_an, res = best_of(args.repeat, lambda: A.analytic(dbeta, force).velocity_deviation)

    def analytic_np_chunked():
        step = args.numpy_chunk
        return np.concatenate([analytic_numpy(dbeta[i:i + step], force[i:i + step])
                               for i in range(0, n, step)])

    t_an_np, eps_an_np = best_of(1, analytic_np_chunked)
    assert np.allclose(res, eps_an_np, rtol=1e-8, atol=1e-13)

    print(f"balls: {n:,}   threads: {numba.get_num_threads()}   best of {args.repeat}")
    print(f"{'step':<28}{'time [s]':>10}{'balls/s':>16}{'vs NumPy':>10}")
    rows = [
        ("draw inputs only", t_draw, None),
        ("eq24 (numba)", t_eq24, t_eq24_np),
        ("eq24 (numpy)", t_eq24_np, None),
        ("analytic (numba)", t_an, t_an_np),
        ("analytic (numpy 4x4 solve)", t_an_np, None),
    ]
    for name, t, base in rows:
        ratio = f"{base / t:9.1f}x" if base else ""
        print(f"{name:<28}{t:10.3f}{n / t:16,.0f}{ratio:>10}")
    print(f"eq24 time / draw time: {t_eq24 / t_draw:.2f}  (target <= 1.5)")
    print(f"eq24 speed-up over NumPy: {t_eq24_np / t_eq24:.1f}x  (target >= 4)")
    print(f"analytic throughput: {n / t_an / 1e6:.1f} M balls/s  (target >= 5)")


if __name__ == "__main__":
    main()
