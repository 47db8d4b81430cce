"""Cost of a what-if sweep against separate runs (issue 14, part 1).

The sweep: ``configs/sweep_rail_roll.toml``'s study (``configs/yaw_moment_tolerances.toml``
with the rail roll std swept) at ``--points`` values of the std from 0.025 to 0.25 deg, each
point ``--samples`` assemblies, run as ``tolsim run`` runs it (:func:`tolsim.io.sweep.
run_sweep`: every point a study, its part file written, then one combined file). Measured in
the same process, after a warm-up that loads the compiled kernels:

* ``sweep``: the wall time of the whole sweep, files included;
* ``separate``: the same points as separate :func:`tolsim.study.execution.runner.run_study` calls,
each
  written to its own file (what a user would do by hand);
* ``sampling``: the time to draw the points' random blocks alone
  (:func:`tolsim.study.sampling.sample_block` and ``error_values``), which common random
  numbers would let a sweep share;
* ``sampling-free``: separate - sampling, the cost of the separate runs without drawing.

Target (issue 14): sweep < 2 x sampling-free. The sweep draws every point's blocks again from
the same streams (common random numbers by construction, not by caching draws), so it pays
the sampling at each point, which the target allows for.

Run: ``python benchmarks/bench_sweep.py [--points 10] [--samples 100000] [--repeats 3]``
(the sweep and the separate runs alternate; the best time of each is reported)
"""

import argparse
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "sweep_rail_roll.toml"


def sweep_text(points: int, samples: int) -> str:
    text = CONFIG.read_text()
    text = text.replace("samples = 20000", f"samples = {samples}").replace(
        "spot_checks = 50", "spot_checks = 0")
    head, _, _ = text.partition("\n[sweep]")
    return head + ("\n[sweep]\n\"tolerances.bottom_rotation.std\" = "
                   f"{{ start_deg = 0.025, stop_deg = 0.25, num = {points} }}\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=10)
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    from tolsim.io.config import parse_config
    from tolsim.io.netcdf import write_result
    from tolsim.io.sweep import run_sweep
    from tolsim.study.execution.runner import run_study
    from tolsim.study.sampling import block_size_of, error_values, n_blocks, sample_block

    config = parse_config(sweep_text(args.points, args.samples), str(CONFIG))
    warm = parse_config(sweep_text(2, 2048), str(CONFIG))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        run_sweep(warm, tmp / "warm.nc")  # load (or compile) the kernels
        sweep, separate = [], []
        for _ in range(args.repeats):  # alternated, the best of each (a busy VM is noisy)
            t0 = time.perf_counter()
            run_sweep(config, tmp / "sweep.nc")
            sweep.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            for k, point in enumerate(config.sweep.points):
                write_result(run_study(point), tmp / f"alone-{k}.nc")
            separate.append(time.perf_counter() - t0)
        sweep, separate = min(sweep), min(separate)
        t0 = time.perf_counter()
        for point in config.sweep.points:
            st = point.study
            for b in range(n_blocks(st.samples, st.block_size)):
                block = sample_block(point, b)
                error_values(point, block)
                assert block.size == block_size_of(point, b)
        sampling = time.perf_counter() - t0
    balls = args.points * args.samples * config.balls
    free = separate - sampling
    print(f"sweep of {args.points} points x {args.samples:,} assemblies "
          f"({config.balls} balls each, {balls:,} balls)")
    print(f"  sweep (tolsim run, one file)     {sweep:8.2f} s   {balls / sweep:,.0f} balls/s")
    print(f"  separate runs, one file each     {separate:8.2f} s   {balls / separate:,.0f} balls/s")
    print(f"  sampling alone                   {sampling:8.2f} s")
    print(f"  separate runs without sampling   {free:8.2f} s")
    print(f"  sweep / sampling-free separate = {sweep / free:.2f} (target < 2); "
          f"sweep / separate = {sweep / separate:.2f}")


if __name__ == "__main__":
    main()
