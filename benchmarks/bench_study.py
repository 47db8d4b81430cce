"""Throughput and peak memory of the whole Monte Carlo study pipeline (tolsim issue 5).

Pipeline per ball: block sampling (rail random fields, per-carriage and per-ball sources,
gaps), the solved static contact model, the analytic epsilon kernel, propagation mode (a) and
the streamed statistics; the study is ``configs/yaw_moment_tolerances.toml`` (10 balls per
track) with the spot checks and the Sobol' sensitivity analysis (separate post-processing
steps with their own cost) off. Each size runs in a fresh process (after a small warm-up run
that loads or compiles the Numba kernels), which reports its wall time and its peak resident
memory (``ru_maxrss``), so the memory of one size does not hide in another's.

The pipeline is timed as ``tolsim run`` runs it (:func:`tolsim.study.execution.runner.run_study`):
with
one worker the Numba kernels use every core and the next chunk is drawn in a thread
meanwhile; the process keeps freed memory for reuse (``retain_freed_memory``). With two
workers each process starts in 1-2 s, which the 1e6 figure includes.

The baseline, measured in the same run, is the same pipeline with the two stages that tolsim
compiles replaced by plain NumPy: the analytic model (Eqs. 17, 18 with ERRATA 8, 21, 23)
solved as batched 4x4 systems with ``numpy.linalg.solve``, and mode (a) propagation with
array operations.

The paired static model (the paper's approximation, no solver) is timed as well, to separate
the cost of the static solver from the rest of the pipeline.

The cost of re-solving balls outside the fast model's validity with the full friction model
(issue "Honest numbers") is reported on the packaged default study and on
``configs/known_answer.toml`` at sigma = 2 deg: balls/s, how many balls were re-solved and the
share of the run time their re-solves took.

With ``--friction`` it times instead the study after contact (issue 13):
``configs/friction_yaw.toml``, the same study with ``[contact]`` (every train followed over the
stroke, each ball's creep coefficients, the carriage friction and its statistics), against the
same study without ``[contact]`` in the same run, at each size (target: >= 1.5 M balls/s on 2
cores, peak memory flat from 1e6 to 1e7 balls).

With ``--along-track`` it times the along-track studies against the constant study of the
same config in the same run (issue 24, "Speed": along_track at most 5x the cost per ball of
constant; targets >= 500 k balls/s free balls, >= 200 k balls/s carriage, on 2 cores):
``configs/whatif_along_track.toml`` (free balls, 6 per train),
``configs/carriage_preload.toml`` (a carriage, 2 x 12 balls entering and leaving its loaded
zone) and the same with a default ``[carriage.circuit]``, each as shipped (its own static
model: ``whatif_along_track`` the paired one) at its automatic step count
(``study.time_steps = "auto"``; each line says it) (the constant study of a
circuit is that of the config without it: a circuit needs along_track). Each line gives
balls/s of the along_track study, of the constant one, and their ratio (the cost per ball of
along_track over that of constant). The along_track studies follow an assembly until its
first contact (the circuit: over the whole stroke). For a carriage two lines more split the
along_track study's time: its carriage solves (one per step and assembly, counted) and its
evaluations (the errors at the balls, the solve and epsilon), each against the whole constant
study per assembly; the second is the ratio that would remain if the integrator's own work
(slots, exits and entries, gaps, contacts) cost nothing. Then ``configs/friction_yaw.toml`` and
``configs/carriage_preload.toml`` (also with a default circuit) along the track with
``[contact]`` against the same without it (the automatic step count is finer with
``[contact]``, except with a circuit: the steps are printed). Sizes are
assemblies (default 2000), times a factor per study so that every timed run lasts a second
or more (a run of 0.2-0.3 s moved by +-15 % from one reading to the next): the free balls
run 100 times more (200 000 assemblies, 1.2e6 balls), the carriage 10 times and the
circuit 5 times; the constant studies run ``--constant-factor`` times more assemblies than
their along_track study (default per study: 2 for the free balls, 5 for the carriage, 10 for
the circuit, about a second each); one worker; each of these two runs three times in its
process and the fastest counts (``ALONG_REPEATS``). Report the
load average with the numbers (the machine is shared).

Run: ``python benchmarks/bench_study.py [--sizes 1e6 1e7] [--workers 1 2]
[--static solved paired] [--friction] [--along-track [--sizes 2000] [--constant-factor 20]]``
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "yaw_moment_tolerances.toml"
FRICTION_CONFIG = ROOT / "configs" / "friction_yaw.toml"
RESOLVE_STUDIES = {"default": ROOT / "tolsim" / "data" / "default.toml",
                   "known_answer": ROOT / "configs" / "known_answer.toml"}


def study(balls_total, static_model="solved", config=CONFIG, along_track=None):
    """The benchmark's study (``static_model`` "config": the config's own); ``along_track``:
    None (as the config), "contact" / "free" for
    along_track propagation with or without [contact], "circuit" along_track with a default
    ``[carriage.circuit]`` ("circuit_contact": and [contact]), "constant" constant
    propagation."""
    from tolsim.io.config import load_config, parse_config

    c = load_config(config)
    contact = along_track in ("contact", "circuit_contact")
    if contact and c.contact is None:
        c = parse_config(c.text + "\n[contact]\n", str(config))
    if (along_track in ("circuit", "circuit_contact")
            and c.carriage.circuit is None):  # (needs along_track to parse)
        text = c.text.replace("[study]\n", '[study]\npropagation = "along_track"\n', 1)
        c = parse_config(text + "\n[carriage.circuit]\n", str(config))
    c = replace(c, study=replace(c.study, spot_checks=0, sensitivity_samples=0,
                                 static_model=(c.study.static_model if static_model == "config"
                                               else static_model)))
    if along_track is not None:
        propagation = "constant" if along_track == "constant" else "along_track"
        c = replace(c, study=replace(c.study, propagation=propagation),
                    contact=c.contact if contact else None)
    return c.with_overrides(samples=max(1, int(balls_total) // c.balls))


def numpy_analytic(dbeta, force, bearing):
    """Plain-NumPy analytic model: batched 4x4 solve for dgamma, epsilon from Eq. (23)."""
    from tolsim.physics.geometry import FRICTION_SIGN, K_F_PAPER
    from tolsim.physics.hertz import hertz_constants

    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    r, b0 = bearing.ball_radius, bearing.nominal_contact_angle
    beta = b0 + dbeta
    s, c = np.sin(beta), np.cos(beta)
    a = hc.semi_major_coefficient * np.cbrt(force)
    q = K_F_PAPER * r * force / a * FRICTION_SIGN  # friction / mu per unit dgamma
    xx = np.stack([c[:, 0], c[:, 1], -c[:, 2], -c[:, 3]], 1)  # local x axes (x comp.)
    xy = np.stack([-s[:, 0], s[:, 1], s[:, 2], -s[:, 3]], 1)
    m = 0.375 * hc.elliptic_e / r * force * a * np.array([1.0, -1.0, -1.0, 1.0])
    rhs = np.zeros((len(beta), 4))
    rhs[:, 1] = -(m[:, 0] * s[:, 0] - m[:, 1] * s[:, 1] - m[:, 2] * s[:, 2] + m[:, 3] * s[:, 3])
    rhs[:, 2] = -(m[:, 0] * c[:, 0] + m[:, 1] * c[:, 1] - m[:, 2] * c[:, 2] - m[:, 3] * c[:, 3])
    rhs[:, 3] = -(dbeta[:, 0] + dbeta[:, 3] - dbeta[:, 1] - dbeta[:, 2])
    mat = np.empty((len(beta), 4, 4))
    mat[:, 0] = q
    mat[:, 1] = q * xx
    mat[:, 2] = q * xy
    mat[:, 3] = [1.0, -1.0, -1.0, 1.0]
    gamma = np.linalg.solve(mat, rhs[..., None])[..., 0]
    return 0.5 * np.tan(b0) * (-dbeta[:, 1] - gamma[:, 1] + dbeta[:, 3] + gamma[:, 3])


def numpy_pipeline(config):
    """Baseline: same sampling and static solver, NumPy velocity model and propagation."""
    from tolsim.study.pipeline.evaluate import STATIC_MODELS, groove_error_fields, loads_per_ball
    from tolsim.study.sampling import error_values, n_blocks, sample_block

    total = 0
    for k in range(n_blocks(config.study.samples, config.study.block_size)):
        b = sample_block(config, k)
        values = error_values(config, b)
        shape = b.initial_position.shape
        nx, ny = loads_per_ball(config, shape)
        errors = groove_error_fields(values, shape)
        st = STATIC_MODELS["solved"](errors, nx.reshape(-1), ny.reshape(-1), config.bearing)
        eps = numpy_analytic(st.contact_angle_deviation, st.normal_force, config.bearing)
        eps = eps.reshape(shape)
        rate = (eps[:, :-1] - eps[:, 1:]) * config.motion.groove_velocity / 2
        with np.errstate(divide="ignore"):
            t = np.where(rate > 0, b.initial_gap / rate, np.inf).min(axis=1)
        total += np.count_nonzero(t <= config.motion.duration)
    return total


def _count_carriage_solves():
    """Count the carriage solves of this process: every batched solve calls the compiled
    kernel through the name in :mod:`tolsim.physics.carriage.solve`, wrapped here to add the
    assemblies it solves and its wall time to the returned dict; and time the along-track
    evaluations, each a call of ``tolsim.study.pipeline.carriage_track._Evaluation`` (the
    errors at the balls, the carriage solve and epsilon of the balls of some assemblies at one
    time, with or without a circuit), into ``evaluation_seconds``."""
    from tolsim.physics.carriage import solve
    from tolsim.study.pipeline import carriage_track

    tally = {"solve_assemblies": 0, "solve_seconds": 0.0, "evaluation_seconds": 0.0}
    kernel = solve.carriage_batch_kernel
    evaluation = carriage_track._Evaluation.__call__

    def counted(*args):
        start = time.perf_counter()
        kernel(*args)
        tally["solve_seconds"] += time.perf_counter() - start
        tally["solve_assemblies"] += len(args[-3])  # out_status: one per assembly

    def timed(self, *args, **kwargs):
        start = time.perf_counter()
        try:
            return evaluation(self, *args, **kwargs)
        finally:
            tally["evaluation_seconds"] += time.perf_counter() - start

    solve.carriage_batch_kernel = counted
    carriage_track._Evaluation.__call__ = timed
    return tally


def child(balls_total, workers, baseline, static_model, config=CONFIG, along_track=None,
          repeats=1):
    """Time the study ``repeats`` times in this process (after a warm-up run); print the
    fastest run's time and tallies as JSON."""
    from tolsim.study.execution.runner import run_study

    c = study(balls_total, static_model, config, along_track)
    warm = 2048 if along_track in (None, "constant") else min(c.study.block_size,
                                                               c.study.samples)
    run_study(c.with_overrides(samples=warm), workers=workers)  # load / compile kernels
    tally = _count_carriage_solves() if c.carriage is not None and workers == 1 else {}
    elapsed, best = np.inf, {}
    for _ in range(repeats):
        for key in tally:
            tally[key] = 0
        start = time.perf_counter()
        if baseline:
            numpy_pipeline(c)
        else:
            run_study(c, workers=workers)
        seconds = time.perf_counter() - start
        if seconds < elapsed:
            elapsed, best = seconds, dict(tally)
    tally = best
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    balls = c.study.samples * c.balls
    print(json.dumps({"balls": balls, "seconds": elapsed, "peak_mib": peak_kib / 1024,
                      "child_peak_mib": children / 1024, "assemblies": c.study.samples,
                      **tally}))


def resolve_child(name, balls_total):
    """One run of a re-solve study; prints balls, seconds, re-solved balls and their time."""
    from tolsim.io.config import load_config
    from tolsim.study.execution.runner import run_study

    c = load_config(RESOLVE_STUDIES[name])
    c = replace(c, study=replace(c.study, spot_checks=0, sensitivity_samples=0))
    run_study(c.with_overrides(samples=2048))  # load / compile kernels
    c = c.with_overrides(samples=max(1, int(balls_total) // c.train.balls))
    start = time.perf_counter()
    acc = run_study(c).statistics
    elapsed = time.perf_counter() - start
    print(json.dumps({"balls": int(acc.n_balls), "seconds": elapsed,
                      "resolved": int(acc.n_resolved_full),
                      "outside": int(acc.n_outside_validity),
                      "resolve_seconds": acc.resolve_seconds,
                      "unresolved_trains": int(acc.n_unresolved),
                      "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def measure(balls, workers=1, baseline=False, static_model="solved", resolve=None,
            config=None, along_track=None, repeats=1):
    cmd = [sys.executable, __file__, "--child", str(balls), str(workers), static_model,
           "--repeats", str(repeats)]
    if baseline:
        cmd.append("--baseline")
    if resolve:
        cmd += ["--resolve", resolve]
    if config is not None:
        cmd += ["--config", str(config)]
    if along_track is not None:
        cmd += ["--along-track-child", along_track]
    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=float, nargs="+", default=[1e6, 1e7])
    p.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    p.add_argument("--baseline-size", type=float, default=1e6)
    p.add_argument("--static", nargs="+", default=["solved", "paired"],
                   help="static models to time (the issue's target is for 'solved')")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    p.add_argument("--baseline", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--resolve", help=argparse.SUPPRESS)
    p.add_argument("--resolve-size", type=float, default=1e6,
                   help="balls of the re-solve cost runs (default and known-answer studies)")
    p.add_argument("--friction", action="store_true",
                   help="time the study after contact (configs/friction_yaw.toml) against "
                        "the same study without [contact], at --sizes with one worker")
    p.add_argument("--along-track", action="store_true",
                   help="time along_track studies against constant ones of the same config "
                        "(whatif_along_track, carriage_preload, with a circuit) and with "
                        "against without [contact]; --sizes in assemblies")
    p.add_argument("--constant-factor", type=float, default=None,
                   help="with --along-track: the constant studies run this many times more "
                        "assemblies than the along_track ones (default per study: 2 free "
                        "balls, 5 carriage, 10 circuit)")
    p.add_argument("--config", help=argparse.SUPPRESS)
    p.add_argument("--along-track-child", help=argparse.SUPPRESS)
    p.add_argument("--repeats", type=int, default=1, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        if args.resolve:
            resolve_child(args.resolve, float(args.child[0]))
        else:
            child(float(args.child[0]), int(args.child[1]), args.baseline, args.child[2],
                  Path(args.config) if args.config else CONFIG, args.along_track_child,
                  args.repeats)
        return
    if args.friction:
        friction(args.sizes)
        return
    if args.along_track:
        along_track(args.sizes if "--sizes" in sys.argv else [2000], args.constant_factor)
        return
    print(f"tolsim study pipeline: {CONFIG.name} (solved static, analytic epsilon, "
          f"propagation a), {os.cpu_count()} cores")
    base = measure(args.baseline_size, baseline=True)
    base_rate = base["balls"] / base["seconds"]
    print(f"baseline (solved static, NumPy velocity + propagation): {base['balls']:.2e} balls "
          f"{base['seconds']:.2f} s  {base_rate / 1e6:.3f} M balls/s  "
          f"peak {base['peak_mib']:.0f} MiB")
    for static_model in args.static:
        for workers in args.workers:
            for size in args.sizes:
                r = measure(size, workers, static_model=static_model)
                rate = r["balls"] / r["seconds"]
                peak = max(r["peak_mib"], r["child_peak_mib"])
                ratio = f"({rate / base_rate:.2f}x baseline)  " if static_model == "solved" else ""
                print(f"{static_model} static, workers {workers}: {r['balls']:.2e} balls  "
                      f"{r['seconds']:.2f} s  "
                      f"{rate / 1e6:.3f} M balls/s  {ratio}"
                      f"peak RSS {peak:.0f} MiB")
    print("re-solves with the full model (balls outside the fast model's validity):")
    for name in RESOLVE_STUDIES:
        r = measure(args.resolve_size, resolve=name)
        print(f"  {name}: {r['balls']:.2e} balls  {r['seconds']:.2f} s  "
              f"{r['balls'] / r['seconds'] / 1e6:.3f} M balls/s  re-solved {r['resolved']} of "
              f"{r['outside']} outside validity ({r['resolved'] / r['balls']:.2%} of balls) in "
              f"{r['resolve_seconds']:.2f} s ({r['resolve_seconds'] / r['seconds']:.0%} of the "
              f"run); unresolved trains {r['unresolved_trains']}; peak {r['peak_mib']:.0f} MiB")


def friction(sizes):
    """Print the study with [contact] against the same study without it, size by size."""
    print(f"tolsim study after contact: {FRICTION_CONFIG.name} against "
          f"{CONFIG.name} (the same study without [contact]); solved static, analytic "
          f"epsilon, one worker, {os.cpu_count()} cores")
    for size in sizes:
        base = measure(size, config=CONFIG)
        with_contact = measure(size, config=FRICTION_CONFIG)
        for label, r in (("without [contact]", base), ("with [contact]   ", with_contact)):
            print(f"  {r['balls']:.2e} balls {label}: {r['seconds']:7.2f} s  "
                  f"{r['balls'] / r['seconds'] / 1e6:.3f} M balls/s  peak RSS "
                  f"{max(r['peak_mib'], r['child_peak_mib']):.0f} MiB")
        ratio = base["seconds"] / with_contact["seconds"]
        print(f"  throughput with [contact]: {ratio:.2f}x the study without it "
              "(target: >= 1.5 M balls/s)")


def _steps(config, kind) -> int:
    """The integration steps of the benchmark's along-track study ``kind`` of ``config``."""
    from tolsim.study.pipeline.propagation_rules import time_steps

    return time_steps(study(1, "config", config, kind))


#: Timed runs of each along_track study and of its constant one, in one process each: the
#: fastest counts (single runs moved by 10-25 % from one reading to the next on the idle
#: 2-core VM, with whatever else the machine did; the fastest of three of each side is the
#: steadier ratio).
ALONG_REPEATS = 3


def along_track(sizes, constant_factor=None):
    """Print along_track studies against constant ones, and with [contact] against without
    it; ``sizes`` in assemblies."""
    load = os.getloadavg()
    print(f"tolsim along_track studies against constant; one worker, {os.cpu_count()} cores, "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    carriage = ROOT / "configs" / "carriage_preload.toml"
    # (config, kind, label, assemblies per --sizes assembly, constant factor): each run
    # lasts a second or more on an idle machine
    cases = ((ROOT / "configs" / "whatif_along_track.toml", "free", "free balls", 100, 2),
             (carriage, "free", "carriage", 10, 5),
             (carriage, "circuit", "carriage with [carriage.circuit]", 5, 10))
    for config, kind, label, factor, const_factor in cases:
        balls = _balls_per_assembly(config) * factor
        const_factor = const_factor if constant_factor is None else constant_factor
        for size in sizes:
            along = measure(size * balls, config=config, along_track=kind,
                            static_model="config", repeats=ALONG_REPEATS)
            const = measure(size * const_factor * balls, config=config,
                            along_track="constant", static_model="config",
                            repeats=ALONG_REPEATS)
            rate_a = along["balls"] / along["seconds"]
            rate_c = const["balls"] / const["seconds"]
            print(f"  {config.name} ({label}): {along['balls'] // (balls // factor):.0f} "
                  f"assemblies "
                  f"{along['balls']:.2e} balls along_track {along['seconds']:7.2f} s "
                  f"{rate_a:9.0f} balls/s; constant {rate_c:9.0f} balls/s "
                  f"({const['balls']:.2e} balls); cost per ball {rate_c / rate_a:6.1f}x "
                  f"constant (target <= 5x); {_steps(config, kind)} steps, "
                  f"{_static_model(config)} static")
            if along.get("solve_assemblies") and const.get("solve_assemblies"):
                alone = (along["solve_seconds"] / along["assemblies"]) / (
                    const["seconds"] / const["assemblies"])
                print(f"    carriage solves per assembly {_solves(along)} along_track, "
                      f"{_solves(const)} constant; the along_track solves alone cost "
                      f"{alone:.1f}x the whole constant study per assembly")
                evaluations = (along["evaluation_seconds"] / along["assemblies"]) / (
                    const["seconds"] / const["assemblies"])
                print(f"    its evaluations alone (the errors at the balls, the solve and "
                      f"epsilon; {along['evaluation_seconds'] / along['seconds']:.0%} of the "
                      f"run) cost {evaluations:.1f}x the whole constant study per assembly: "
                      "the ratio if the integrator's own work cost nothing")
    print(f"tolsim along_track study after contact, with and without [contact]; one worker, "
          f"{os.cpu_count()} cores")
    for config, plain, with_contact, name in (
            (FRICTION_CONFIG, "free", "contact", ""), (carriage, "free", "contact", ""),
            (carriage, "circuit", "circuit_contact", " with [carriage.circuit]")):
        balls = _balls_per_assembly(config)
        for size in sizes:
            free = measure(size * balls, config=config, along_track=plain,
                           static_model="config")
            contact = measure(size * balls, config=config, along_track=with_contact,
                              static_model="config")
            for label, r, kind in (("without [contact]", free, plain),
                                   ("with [contact]   ", contact, with_contact)):
                print(f"  {config.name}{name}: {r['balls']:.2e} balls {label} "
                      f"({_steps(config, kind):>3} steps): {r['seconds']:7.2f} s "
                      f" {r['balls'] / r['seconds']:9.0f} balls/s  peak RSS "
                      f"{max(r['peak_mib'], r['child_peak_mib']):.0f} MiB")
            print(f"  throughput with [contact]: {free['seconds'] / contact['seconds']:.2f}x "
                  "the study without it")
    load = os.getloadavg()
    print(f"load average at the end {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")


def _solves(r):
    """Carriage solves per assembly of a child's run, their wall time per solve and their
    share of the run, as text."""
    per = r["solve_assemblies"] / r["assemblies"]
    each = r["solve_seconds"] / r["solve_assemblies"] * 1e6
    return f"{per:.1f} ({each:.1f} us each, {r['solve_seconds'] / r['seconds']:.0%} of the run)"


def _balls_per_assembly(config):
    from tolsim.io.config import load_config

    return load_config(config).balls


def _static_model(config):
    from tolsim.io.config import load_config

    return load_config(config).study.static_model


if __name__ == "__main__":
    main()
