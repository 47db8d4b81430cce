"""The default study on a cold Numba cache against a warm one (issue 26, "a first run that does
not wait").

Runs ``tolsim run`` (the packaged default study) in a subprocess with ``NUMBA_CACHE_DIR``
pointed at an empty temporary directory (cold: every kernel compiles), then again on that
cache (warm), and, unless ``--no-warmup``, once more on a fresh empty cache after
``tolsim warmup`` (the install step of the README quick start). Prints the wall and CPU
seconds of each (CPU: user + system of the child, which a busy machine inflates less than the
wall time) and the ratios cold / warm. The target is a ratio of at most 3.

    python benchmarks/bench_cold_start.py [--no-warmup] [--samples N]
"""

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

TARGET = 3.0


def timed(cmd, cache):
    """(wall s, CPU s, stdout) of ``cmd`` with the Numba cache in ``cache``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True)
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, out.stdout + out.stderr


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--no-warmup", action="store_true", help="skip the run after tolsim warmup")
    p.add_argument("--samples", type=int, default=None,
                   help="assemblies (default: the default study's 100 000)")
    args = p.parse_args(argv)
    tolsim = [sys.executable, "-m", "tolsim"]
    print(f"load average at the start: {os.getloadavg()[0]:.2f} "
          f"({os.cpu_count()} cores)")
    with tempfile.TemporaryDirectory(prefix="tolsim-cold-") as tmp:
        run = [*tolsim, "run", "-o", os.path.join(tmp, "study.nc"), "--fresh"]
        if args.samples:
            run += ["--samples", str(args.samples)]
        cache = os.path.join(tmp, "cache")
        os.mkdir(cache)
        rows = [("cold (empty cache)", *timed(run, cache))]
        rows.append(("warm (same cache)", *timed(run, cache)))
        if not args.no_warmup:
            fresh = os.path.join(tmp, "cache-warmup")
            os.mkdir(fresh)
            wall, cpu, _ = timed([*tolsim, "warmup"], fresh)
            print(f"tolsim warmup on an empty cache: {wall:.1f} s wall, {cpu:.1f} s CPU")
            rows.append(("after tolsim warmup", *timed(run, fresh)))
    warm_wall, warm_cpu = rows[1][1], rows[1][2]
    for name, wall, cpu, text in rows:
        compiled = next((x for x in text.splitlines() if x.startswith("compiled kernels")), "")
        print(f"{name:22s} {wall:7.1f} s wall ({wall / warm_wall:5.2f}x warm), {cpu:7.1f} s CPU "
              f"({cpu / warm_cpu:5.2f}x warm)  {compiled}")
    ratio = rows[0][1] / warm_wall
    print(f"cold / warm: {ratio:.2f} (wall), {rows[0][2] / warm_cpu:.2f} (CPU); target <= "
          f"{TARGET:g}: {'met' if ratio <= TARGET else 'NOT met'} without a warm-up")
    if not args.no_warmup:
        ratio = rows[2][1] / warm_wall
        print(f"after tolsim warmup / warm: {ratio:.2f} (wall): "
              f"{'met' if ratio <= TARGET else 'NOT met'} with the warm-up")


if __name__ == "__main__":
    main()
