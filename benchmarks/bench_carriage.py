"""Throughput of the batched carriage solve (:func:`tolsim.physics.carriage.solve_carriage_batch`).

Solves many sampled assemblies of the two-row wrapped guide of ``configs/carriage_preload.toml``
(2 tracks x 12 balls, preload class "light") under one carriage load, each ball with random
groove errors of a precision guide, and prints assemblies and balls per second on all Numba
threads and on one, the CPU time per assembly, the Newton steps, the statuses, the peak
memory, and the ratio to a plain SciPy baseline measured in the same run:
``scipy.optimize.root`` ('hybr') on the 5-DOF carriage residual Q + sum_b A_b^T f_b(A_b q),
assembly by assembly, with every ball solved by the public per-ball solver
(:func:`tolsim.physics.static.solve_static_displacement`), as a user would write it. The
single-assembly :func:`tolsim.physics.carriage.solve_carriage` (a Python Newton over the same
kernels) is timed on the same subset.

Like ``tolsim run`` (:func:`tolsim.study.execution.chunks.retain_freed_memory`), the benchmark lets
glibc keep freed memory. Wall-clock figures depend on what else the machine runs; the CPU
time per assembly less so.

``--along-track N`` (default 200; 0 skips it) times the study path with ``along_track``
propagation (:mod:`tolsim.study.pipeline.carriage_track`: the balls rolling through the carriage,
the carriage re-solved twice per time step; ``--time-steps``, default the automatic step
count) on N assemblies of the same config, as ``tolsim run``
runs them (sampling, integration, statistics; one block), and the same assemblies with
``constant`` propagation as the baseline of the same run. ``--skip-batch`` runs only that.

``--preload-um X`` replaces the config's preload class (a negative X: a clearance class, whose
carriages settle onto their contacts, issue 25).

Run: ``python benchmarks/bench_carriage.py [--assemblies 10000 100000] [--baseline 200]
[--along-track 200] [--time-steps auto] [--skip-batch] [--preload-um X]``
"""

import argparse
import os
import re
import resource
import time
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np
from scipy.optimize import root

from tolsim.io.config import parse_config
from tolsim.physics.carriage import CarriageStatus, solve_carriage, solve_carriage_batch
from tolsim.physics.static import GrooveErrors, solve_static_displacement
from tolsim.study.execution.chunks import retain_freed_memory
from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.propagation_rules import time_steps as resolved_steps

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "carriage_preload.toml"
#: Standard deviations of the sampled errors (normal, independent per ball): arc-centre
#: offsets [m], groove offsets [m], groove-profile rotations [rad], ball size [m].
ARC_OFFSET = 1e-6
GROOVE_OFFSET = 2e-6
ROTATION = np.deg2rad(0.15)
BALL_SIZE = 0.5e-6


def sample(m, shape, seed):
    """Groove errors of m assemblies (each ball its own), one Generator per run."""
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    s = (m,) + shape
    return GrooveErrors(
        arc_centre_offset_normal=rng.normal(0.0, ARC_OFFSET, s + (4,)),
        arc_centre_offset_tangential=rng.normal(0.0, ARC_OFFSET, s + (4,)),
        bottom_rotation=rng.normal(0.0, ROTATION, s),
        top_rotation=rng.normal(0.0, ROTATION, s),
        bottom_offset=rng.normal(0.0, GROOVE_OFFSET, s + (2,)),
        top_offset=rng.normal(0.0, GROOVE_OFFSET, s + (2,)),
        ball_oversize=rng.normal(0.0, BALL_SIZE, s),
    )


def take(errors, index):
    return GrooveErrors(**{name: np.asarray(getattr(errors, name))[index]
                           for name in GrooveErrors.__dataclass_fields__})


def best_time(func, repeat, clock=time.perf_counter):
    times = []
    for _ in range(repeat):
        t0 = clock()
        out = func()
        times.append(clock() - t0)
    return min(times), out


def scipy_baseline(layout, load, oversize, errors):
    """scipy.optimize.root ('hybr', finite-difference Jacobian) on the carriage balance.

    Unknowns: q with the rotations times L, in um. Each residual evaluation solves every ball
    of the assembly with solve_static_displacement at its groove translation g_b = A_b q.
    Returns the normal forces (m, n_tracks, n, 4) and the number of residual evaluations.
    """
    t, n = layout.n_tracks, layout.balls_per_track
    length = layout.length_scale()
    scale = np.array([1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
    a_s = layout.groove_map().reshape(t * n, 2, 5) * scale
    q_ext = load.generalised() * scale
    m = np.asarray(errors.bottom_rotation).shape[0]
    forces = np.empty((m, t, n, 4))
    calls = 0
    for j in range(m):
        ball = take(errors, j)
        ball = GrooveErrors(**{**ball.__dict__, "ball_oversize": ball.ball_oversize + oversize})

        def residual(x, ball=ball):
            groove = (a_s @ (x * 1e-6)).reshape(t, n, 2)
            sol = solve_static_displacement(groove, ball)
            f = np.stack([-sol.groove_load[..., 0], sol.groove_load[..., 1]], axis=-1)
            return (q_ext + np.einsum("bik,bi->k", a_s, f.reshape(t * n, 2))) / 100.0

        out = root(residual, np.zeros(5), method="hybr", options={"xtol": 1e-13})
        calls += out.nfev
        groove = (a_s @ (out.x * 1e-6)).reshape(t, n, 2)
        forces[j] = solve_static_displacement(groove, ball).normal_force
    return forces, calls


def _probability(acc):
    """P(contact) with its 95 % interval and the count (as the README quotes it)."""
    p, low, high = acc.contact_probability()
    return f"{p:.3f} [{low:.3f}, {high:.3f}] ({int(acc.n_contact)} of {int(acc.n_assemblies)})"


def along_track_study(assemblies, time_steps):
    """assemblies/s of the study path with along_track propagation (and constant, the
    baseline), ``configs/carriage_preload.toml`` with ``assemblies`` samples in one block."""
    steps = f'"{time_steps}"' if time_steps == "auto" else time_steps
    text = CONFIG.read_text().replace("seed = 12", "seed = 12\nblock_size = "
                                      f"{assemblies}\ntime_steps = {steps}")
    # each propagation named (a [carriage] study's default is along_track)
    constant = parse_config(text.replace("[study]", '[study]\npropagation = "constant"'),
                            str(CONFIG)).with_overrides(samples=assemblies)
    along = parse_config(text.replace("[study]", '[study]\npropagation = "along_track"'),
                         str(CONFIG)).with_overrides(samples=assemblies)
    time_steps = resolved_steps(along)
    t0 = time.perf_counter()
    for warm in (along, constant):
        small = warm.with_overrides(samples=2)
        run_study(replace(small, study=replace(small.study, block_size=2, time_steps=2)))
    print(f"first calls                  {time.perf_counter() - t0:.2f} s (compile or cache)")
    t0 = time.perf_counter()
    result = run_study(along)
    t_along = time.perf_counter() - t0
    t0 = time.perf_counter()
    base = run_study(constant)
    t_const = time.perf_counter() - t0
    acc, ref = result.statistics, base.statistics
    rate = assemblies / t_along
    # the evaluations actually made: two per step while an assembly has no contact yet
    print(f"along_track study            {rate:,.1f} assemblies/s ({assemblies} assemblies x "
          f"{time_steps} steps in {t_along:.2f} s on {numba.get_num_threads()} threads; "
          f"{rate * time_steps:,.0f} assembly-steps/s, an assembly followed until its first "
          f"contact); P(contact) {_probability(acc)}, unresolved {int(acc.n_unresolved)}")
    print(f"constant study (baseline)    {assemblies / t_const:,.0f} assemblies/s "
          f"({t_const:.2f} s); P(contact) {_probability(ref)}; along_track "
          f"is {t_along / t_const:,.0f}x dearer")
    return rate


def _steps_argument(text):
    """``--time-steps``: "auto" or a positive integer."""
    if text == "auto":
        return text
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError("must be a positive integer or 'auto'")
    return value


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--assemblies", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--baseline", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--seed", type=int, default=20240)
    parser.add_argument("--along-track", type=int, default=200)
    parser.add_argument("--time-steps", type=_steps_argument, default="auto",
                        help='steps of the along_track study: a number, or "auto" (the '
                             "automatic step count, the default)")
    parser.add_argument("--skip-batch", action="store_true")
    parser.add_argument("--preload-um", type=float, default=None,
                        help="ball oversize of the preload class instead of the config's "
                             "(negative: a clearance class, whose carriage settles)")
    args = parser.parse_args(argv)

    retained = retain_freed_memory()
    if args.skip_batch:
        if args.along_track:
            along_track_study(args.along_track, args.time_steps)
        return
    text = CONFIG.read_text()
    if args.preload_um is not None:
        text = re.sub(r"(?m)^preload_oversize_um = \S+", f"preload_oversize_um = {args.preload_um}",
                      text)
    carriage = parse_config(text, str(CONFIG)).carriage
    layout, load, oversize = carriage.layout, carriage.load, carriage.oversize
    shape = (layout.n_tracks, layout.balls_per_track)
    nball = shape[0] * shape[1]
    threads = numba.get_num_threads()
    t0 = time.perf_counter()
    solve_carriage_batch(layout, load, oversize=oversize, groove_errors=sample(4, shape, 0))
    print(f"first call (compile or load from cache): {time.perf_counter() - t0:.2f} s")
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"guide                     {CONFIG.name}: {shape[0]} tracks x {shape[1]} balls, "
          f"preload oversize {carriage.preload_oversize * 1e6:g} um, load "
          f"({load.describe()})")
    print(f"sampled errors (1 sigma)  arc-centre offsets {ARC_OFFSET * 1e6:g} um, groove "
          f"offsets {GROOVE_OFFSET * 1e6:g} um, rotations {np.rad2deg(ROTATION):g} deg, ball "
          f"size {BALL_SIZE * 1e6:g} um, every ball its own")
    print(f"numba threads             {threads}")
    print(f"freed memory retained     {retained} (glibc mallopt, as in tolsim run)")

    rates = {}
    for m in args.assemblies:
        errors = sample(m, shape, args.seed)

        def solve(errors=errors):
            return solve_carriage_batch(layout, load, oversize=oversize, groove_errors=errors)

        repeat = args.repeat if m <= 20_000 else 1
        t_all, sol = best_time(solve, repeat)
        before = os.times()
        solve()
        after = os.times()
        t_user, t_sys = after.user - before.user, after.system - before.system
        numba.set_num_threads(1)
        t_one, _ = best_time(solve, 1)
        numba.set_num_threads(threads)
        rates[m] = m / t_all
        counts = np.bincount(sol.contact_count.ravel(), minlength=5) / sol.contact_count.size
        print(f"m = {m:<7d}               {m / t_all:,.0f} assemblies/s, "
              f"{m * nball / t_all / 1e6:.2f} M balls/s on {threads} threads ({t_all:.3f} s); "
              f"{m / t_one:,.0f} assemblies/s, {m * nball / t_one / 1e6:.2f} M balls/s on 1 "
              f"thread")
        t_cpu = t_user + t_sys
        nbytes = sum(np.asarray(getattr(sol, f)).nbytes for f in sol.__dataclass_fields__)
        print(f"  CPU time per assembly   {t_cpu / m * 1e6:.1f} us (all threads; "
              f"{m * nball / t_cpu / 1e6:.2f} M balls per CPU-second), of which system "
              f"{t_sys / m * 1e6:.1f} us (page faults of fresh result arrays over glibc's "
              f"32 MB heap limit); result {nbytes / m:.0f} bytes per assembly")
        steps = np.bincount(sol.iterations)
        print(f"  Newton steps            mean {sol.iterations.mean():.2f}, max "
              f"{sol.iterations.max()}, histogram {dict(enumerate(steps.tolist()))}; "
              f"nested fallback {sol.fallback.mean() * 100:.2f} %")
        status = np.bincount(sol.status, minlength=len(CarriageStatus))
        print("  status                  " + ", ".join(
            f"{int(code)} {code.name.lower()}: {status[code]}" for code in CarriageStatus))
        print("  flanks loaded per ball  " + ", ".join(
            f"{c}: {counts[c] * 100:.1f} %" for c in range(5)))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    inputs = max(args.assemblies) * nball * 15 * 8 / 2**20
    print(f"peak RSS                  {peak:.0f} MB ({rss0:.0f} MB after the first call: "
          f"Python, NumPy, SciPy, Numba, kernels; the largest batch's sampled errors "
          f"{inputs:.0f} MB; freed memory is kept, see above)")

    nb = args.baseline
    errors = sample(nb, shape, args.seed + 1)
    t_batch, batch = best_time(lambda: solve_carriage_batch(
        layout, load, oversize=oversize, groove_errors=errors), 1)
    try:
        t_base, (forces, calls) = best_time(
            lambda: scipy_baseline(layout, load, oversize, errors), 1)
    except ValueError as exc:  # with clearance 'hybr' starts on a zero Jacobian and wanders off
        t_base = None
        print(f"baseline scipy root       failed: {exc}")
    t_single, singles = best_time(lambda: [
        solve_carriage(layout, load, oversize=oversize, groove_errors=take(errors, j))
        for j in range(nb)], 1)
    ok = batch.converged
    fscale = np.nanmax(batch.normal_force)
    single_err = max(np.abs(s.normal_force - batch.normal_force[j]).max() / fscale
                     for j, s in enumerate(singles))
    if t_base is not None:
        base_err = np.abs(forces[ok] - batch.normal_force[ok]).max() / fscale
        base_rate = nb / t_base
        print(f"baseline scipy root       {base_rate:.1f} assemblies/s ({nb} assemblies, "
              f"'hybr', {calls / nb:.1f} residual evaluations each, 1 thread); max |F - "
              f"F_batch| = {base_err:.1e} of max F")
    print(f"solve_carriage            {nb / t_single:.1f} assemblies/s (one at a time); max "
          f"|F - F_batch| = {single_err:.1e} of max F")
    if t_base is not None:
        print(f"speed-up over baseline    {rates[max(rates)] / base_rate:,.0f}x (batch of "
              f"{max(rates)} on {threads} threads; {nb / t_batch / base_rate:,.0f}x on the "
              f"{nb}-assembly subset)")
    print(f"speed-up over solve_carriage  {rates[max(rates)] / (nb / t_single):,.0f}x")
    if args.along_track:
        along_track_study(args.along_track, args.time_steps)


if __name__ == "__main__":
    main()
