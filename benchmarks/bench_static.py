"""Throughput of the static contact solver (tolsim issue 3).

Solves the load-controlled static problem (:func:`tolsim.physics.static.solve_static`) for
many balls with tolerance-sized random errors and loads, and prints balls per second on all
Numba threads and on one (and with the vectorised path switched off), the Newton iterations,
the memory of the result, and the ratio to a plain SciPy baseline (``scipy.optimize.root``
ball by ball on the same equations, as in ``tests/physics/test_static.py``) measured in the same
run.

Like ``tolsim run`` (:func:`tolsim.study.execution.chunks.retain_freed_memory`), the benchmark lets
glibc keep freed memory: otherwise each call's fresh output arrays are paid for in page
faults, which on a small VM bound the two-thread figure near the one-thread one.

Run: ``python benchmarks/bench_static.py [--balls 1000000] [--repeat 3]``
"""

import argparse
import time

import numba
import numpy as np
from scipy.optimize import root

from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static import (
    GrooveErrors,
    linearised_static,
    solve_static,
    static_sensitivity,
)
from tolsim.study.execution.chunks import retain_freed_memory

SX = np.array([-1.0, 1.0, 1.0, -1.0])
SY = np.array([-1.0, -1.0, 1.0, 1.0])


def sample(n, seed):
    """Loads and errors of a precision guide: um offsets, tenths of a degree, um ball sizes."""
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    ny = rng.uniform(50.0, 400.0, n)
    nx = rng.uniform(-0.6, 0.6, n) * ny
    errors = GrooveErrors(
        arc_centre_offset_normal=rng.normal(0, 1.5e-6, (n, 4)),
        arc_centre_offset_tangential=rng.normal(0, 1.5e-6, (n, 4)),
        bottom_rotation=rng.normal(0, np.deg2rad(0.5), n),
        top_rotation=rng.normal(0, np.deg2rad(0.5), n),
        bottom_offset=rng.normal(0, 2e-6, (n, 2)),
        top_offset=rng.normal(0, 2e-6, (n, 2)),
        ball_oversize=rng.normal(0, 1e-6, n),
    )
    return nx, ny, errors


def best_time(func, repeat, clock=time.perf_counter):
    times = []
    for _ in range(repeat):
        t0 = clock()
        out = func()
        times.append(clock() - t0)
    return min(times), out


def scipy_baseline(nx, ny, errors, bearing=TABLE1):
    """scipy.optimize.root (Levenberg-Marquardt) on the 4 equilibrium equations, ball by ball.

    ('hybr' is faster but fails from this start on a few per cent of the balls, where
    tolerance-sized errors leave a flank open.)
    """
    d = bearing.groove_radius - bearing.ball_radius
    b0 = bearing.nominal_contact_angle
    k = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                        bearing.poisson_ratio).load_deflection_constant
    n_vec = np.stack([SX * np.sin(b0), SY * np.cos(b0)], axis=1)
    t_vec = np.stack([SX * np.cos(b0), -SY * np.sin(b0)], axis=1)
    out = np.empty((len(nx), 4))
    for j in range(len(nx)):
        e_n = errors.arc_centre_offset_normal[j]
        e_t = errors.arc_centre_offset_tangential[j]
        base = -(d - e_n)[:, None] * n_vec - e_t[:, None] * t_vec
        cen = np.empty((4, 2))
        for rows, th, off in (((0, 1), errors.bottom_rotation[j], errors.bottom_offset[j]),
                              ((2, 3), errors.top_rotation[j], errors.top_offset[j])):
            rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
            for i in rows:
                cen[i] = rot @ base[i] + off
        ell = d - errors.ball_oversize[j] / 2
        load = np.array([nx[j], -ny[j]])

        def equations(z, cen=cen, ell=ell, load=load, scale=ny[j]):
            p, g = z[:2] * 1e-6, z[2:] * 1e-6
            c = cen.copy()
            c[2:] += g
            w = p - c
            dist = np.linalg.norm(w, axis=1)
            u = w / dist[:, None]
            f = k * np.clip(dist - ell, 0, None) ** 1.5
            fu = f[:, None] * u
            return np.concatenate([-fu.sum(axis=0), fu[2:].sum(axis=0) + load]) / scale

        delta0 = (ny[j] / (2 * np.cos(b0)) / k) ** (2 / 3)
        z0 = np.array([0.0, -delta0 / np.cos(b0), 0.0, -2 * delta0 / np.cos(b0)]) * 1e6
        z0[:2] += errors.bottom_offset[j] * 1e6
        z0[2:] += (errors.bottom_offset[j] - errors.top_offset[j]) * 1e6
        sol = root(equations, z0, method="lm", options={"xtol": 1e-14, "ftol": 1e-14})
        p = sol.x[:2] * 1e-6
        w = p - cen[:, :] - np.vstack([np.zeros((2, 2)), np.tile(sol.x[2:] * 1e-6, (2, 1))])
        out[j] = np.arctan2(SX * w[:, 0], SY * w[:, 1])
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balls", type=int, default=1_000_000)
    parser.add_argument("--baseline-balls", type=int, default=300)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=20181)
    args = parser.parse_args(argv)

    retained = retain_freed_memory()
    nx, ny, errors = sample(args.balls, args.seed)
    threads = numba.get_num_threads()
    t0 = time.perf_counter()
    solve_static(nx[:8], ny[:8], GrooveErrors(**{k: getattr(errors, k)[:8]
                                                 for k in errors.__dataclass_fields__}))
    solve_static(nx[:8], ny[:8], rigid=True)
    print(f"first call (compile or load from cache): {time.perf_counter() - t0:.2f} s")

    t_all, sol = best_time(lambda: solve_static(nx, ny, errors), args.repeat)
    t_cpu, _ = best_time(lambda: solve_static(nx, ny, errors), args.repeat, time.process_time)
    numba.set_num_threads(1)
    t_one, _ = best_time(lambda: solve_static(nx, ny, errors), args.repeat)
    numba.set_num_threads(threads)
    t_scalar, scalar = best_time(lambda: solve_static(nx, ny, errors, vectorised=False),
                                 args.repeat)
    t_rigid, _ = best_time(lambda: solve_static(nx, ny, errors, rigid=True), args.repeat)
    sens = static_sensitivity(0.0, 200.0)
    t_lin, (lin_db, _) = best_time(lambda: linearised_static(sens, nx, ny, errors), 1)

    nb = args.baseline_balls
    t_base, beta_base = best_time(
        lambda: scipy_baseline(nx[:nb], ny[:nb], GrooveErrors(
            **{k: np.asarray(getattr(errors, k))[:nb] for k in errors.__dataclass_fields__})),
        1)
    diff = np.max(np.abs(beta_base - sol.contact_angle[:nb]), axis=1)
    agree = np.max(diff)
    rate = args.balls / t_all
    base_rate = nb / t_base
    nbytes = sum(np.asarray(getattr(sol, f)).nbytes for f in sol.__dataclass_fields__)

    print(f"balls                     {args.balls}")
    print(f"numba threads             {threads}")
    print(f"freed memory retained     {retained} (glibc mallopt, as in tolsim run)")
    print(f"solve_static (elastic)    {rate / 1e6:.2f} M balls/s on {threads} threads "
          f"({t_all:.3f} s), {args.balls / t_one / 1e6:.2f} M balls/s on 1 thread")
    print(f"  CPU time per ball       {t_cpu / args.balls * 1e6:.3f} us (all threads; "
          f"{args.balls / t_cpu / 1e6:.2f} M balls per CPU-second; wall-clock figures "
          f"depend on what else the machine runs)")
    print(f"  scalar path only        {args.balls / t_scalar / 1e6:.2f} M balls/s on {threads} "
          f"threads (vectorised=False): the vectorised path is {t_scalar / t_all:.1f}x faster; "
          f"max |dbeta difference| "
          f"{np.max(np.abs(scalar.contact_angle_deviation - sol.contact_angle_deviation)):.1e} "
          f"rad")
    print(f"solve_static (rigid)      {args.balls / t_rigid / 1e6:.2f} M balls/s")
    err = np.abs(lin_db - sol.contact_angle_deviation)
    print(f"linearised_static         {args.balls / t_lin / 1e6:.2f} M balls/s "
          f"(NumPy matrix product about N = (0, 200) N; no unloading)")
    print(f"  its dbeta error         mean {np.rad2deg(err.mean()):.4f} deg, 99.9 % "
          f"{np.rad2deg(np.quantile(err, 0.999)):.4f} deg, max {np.rad2deg(err.max()):.4f} deg "
          f"(loads here span N_y 50-400 N, |rho| <= 0.6; dbeta spans "
          f"{np.rad2deg(np.ptp(sol.contact_angle_deviation)):.2f} deg)")
    print(f"Newton steps per groove   mean {sol.iterations.mean():.3f}, max "
          f"{sol.iterations.max()}; converged {sol.converged.mean() * 100:.3f} %; "
          f"four-point {sol.four_point.mean() * 100:.2f} %")
    print(f"max force imbalance       {np.max(sol.residual / ny):.2e} of N_y")
    print(f"result memory             {nbytes / args.balls:.0f} bytes per ball")
    print(f"baseline scipy root       {base_rate:.0f} balls/s ({nb} balls, 'lm', 1 thread); "
          f"max |beta - beta_numba| = {agree:.1e} rad")
    print(f"speed-up over baseline    {rate / base_rate:.0f}x")


if __name__ == "__main__":
    main()
