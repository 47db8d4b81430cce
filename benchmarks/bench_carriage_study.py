"""Throughput and peak memory of a whole Monte Carlo study with a carriage (tolsim issue 12).

The study is ``configs/carriage_preload.toml`` (two tracks of 12 balls, light preload, 300 N
vertical load and a 2 N m pitch moment, groove and ball tolerances per track), constant
propagation, spot checks and the Sobol' analysis off, run as ``tolsim run`` runs it
(:func:`tolsim.study.execution.runner.run_study`, one process, Numba threads on every core). Per
assembly: sampling per track, the batched carriage solve
(:func:`tolsim.physics.carriage.solve_carriage_batch`), the analytic epsilon kernel with the
full-model re-solves, first contact per track and the streamed statistics.

Each size runs in a fresh process after a small warm-up (kernels loaded or compiled), which
reports its wall time and peak resident memory (``ru_maxrss``). The issue's targets: >= 1 M
balls/s on 2 cores, memory flat from 1e5 to 1e6 assemblies.

The baseline, measured in the same run, is the single-train pipeline of the same balls with
the carriage replaced by per-ball loads (``configs/yaw_moment_tolerances.toml``, 10 balls):
what a study cost before a carriage had to be solved.

Run: ``python benchmarks/bench_carriage_study.py [--assemblies 1e5 1e6] [--preload 2 4]``
"""

import argparse
import json
import re
import resource
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "carriage_preload.toml"
BASELINE = ROOT / "configs" / "yaw_moment_tolerances.toml"


def study(path, assemblies, preload_um=None):
    from tolsim.io.config import load_config, parse_config

    if preload_um is None:
        c = load_config(path)
    else:
        text = re.sub(r"preload_oversize_um = [0-9.]+", f"preload_oversize_um = {preload_um}",
                      Path(path).read_text())
        c = parse_config(text, str(path))
    c = replace(c, study=replace(c.study, spot_checks=0, sensitivity_samples=0))
    return c.with_overrides(samples=int(assemblies))


def child(path, assemblies, preload_um):
    from tolsim.study.execution.runner import run_study

    run_study(study(path, 256, preload_um))  # warm-up: kernels loaded or compiled
    c = study(path, assemblies, preload_um)
    t0 = time.perf_counter()
    r = run_study(c)
    dt = time.perf_counter() - t0
    acc = r.statistics
    print(json.dumps({
        "seconds": dt, "balls": int(acc.n_balls), "balls_per_second": int(acc.n_balls) / dt,
        "rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "contact_probability": acc.contact_probability()[0],
        "resolved_full": int(acc.n_resolved_full), "carriage_failed": int(acc.carriage_failed),
        "unresolved": int(acc.n_unresolved)}))


def measure(path, assemblies, preload_um=None):
    cmd = [sys.executable, __file__, "--child", str(path), str(assemblies), str(preload_um)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--assemblies", type=float, nargs="+", default=[1e5, 1e6])
    p.add_argument("--preload", type=float, nargs="+", default=[2.0, 4.0],
                   help="preload oversize classes [um] to time")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    a = p.parse_args()
    if a.child:
        path, n, preload = a.child
        child(path, int(float(n)), None if preload == "None" else float(preload))
        return
    print(f"study with a carriage: {CONFIG.name}, 2 tracks x 12 balls, constant propagation")
    for preload in a.preload:
        for n in a.assemblies:
            r = measure(CONFIG, int(n), preload)
            print(f"  preload {preload:g} um, {int(n):>9,d} assemblies ({r['balls']:,d} balls): "
                  f"{r['seconds']:7.2f} s, {r['balls_per_second'] / 1e6:5.2f} M balls/s, "
                  f"peak RSS {r['rss_mib']:6.0f} MiB; P(contact) "
                  f"{r['contact_probability']:.4f}, re-solved {r['resolved_full']}, "
                  f"carriages failed {r['carriage_failed']}, unresolved {r['unresolved']}")
    n = int(a.assemblies[-1] * 24 / 10)
    r = measure(BASELINE, n)
    print(f"baseline without a carriage: {BASELINE.name}, {r['balls']:,d} balls: "
          f"{r['seconds']:.2f} s, {r['balls_per_second'] / 1e6:.2f} M balls/s, peak RSS "
          f"{r['rss_mib']:.0f} MiB")


if __name__ == "__main__":
    main()
