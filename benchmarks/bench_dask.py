"""Throughput of a study on dask.distributed against the in-process run (tolsim issue 16).

The study is that of ``benchmarks/bench_study.py`` (``configs/yaw_moment_tolerances.toml``,
10 balls per track, solved static model, analytic epsilon, spot checks and sensitivity off),
run three ways on the same balls, each in a fresh process:

* in-process: :func:`tolsim.study.execution.runner.run_study` as ``tolsim run`` runs it by default
(the
  Numba kernels on every core, the next chunk drawn in a thread meanwhile): the baseline;
* ``--scheduler local:1`` and ``local:2``: a LocalCluster of 1 and 2 single-threaded worker
  processes (Numba threads = cores / workers), the tasks merged in block order by the client.

Every run is timed after a small warm-up run that loads the kernels (in each worker, for the
clusters); the start of the cluster and the warm-up are printed apart. The result of each
cluster run is checked to be bit-identical to the in-process one.

Overheads, for estimating larger clusters:

* per task: the worker-thread time a task costs beyond its own computation,
  (threads x wall time - sum of the tasks' compute times) / tasks, from dask's task stream: it
  holds the scheduling, the transfer of the results, the client's merge while workers wait,
  and the idle tail at the end of the run;
* per empty task: the scheduler's throughput on 1000 tasks that do nothing;
* per block on the client: unpickling and merging one block's accumulator and spot rows, the
  serial part of the design (a run cannot go faster than blocks / this time).

The CPU time of each run (the client's and, for the clusters, the workers' processes) is
printed too: on a machine shared with other work the wall times vary a lot, the CPU times
much less.

Run: ``python benchmarks/bench_dask.py [--balls 1e7] [--modes in-process local:1 local:2]
[--repeats 3]``
"""

import argparse
import json
import os
import pickle
import resource
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / "configs" / "yaw_moment_tolerances.toml"


def study(balls_total):
    from tolsim.io.config import load_config

    c = load_config(CONFIG)
    c = replace(c, study=replace(c.study, spot_checks=0, sensitivity_samples=0,
                                 static_model="solved"))
    return c.with_overrides(samples=max(1, int(balls_total) // c.train.balls))


def _noop(x):
    return x


def _cpu_seconds():
    """CPU time (user + system) of this process so far [s]."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _cluster_cpu_seconds(session):
    """CPU time of this process and of the cluster's worker processes so far [s]."""
    return _cpu_seconds() + sum(session.client.run(_cpu_seconds).values())


def child(balls_total, mode, state_file):
    """One mode in this process; prints a JSON line and saves the result's state arrays."""
    from tolsim.study.execution.runner import run_study

    config = study(balls_total)
    out = {"mode": mode}
    session = None
    if mode == "in-process":
        run = dict()
    else:
        from tolsim.study.execution.distributed import DaskSession

        t0 = time.perf_counter()
        session = DaskSession(mode)
        out["start_seconds"] = time.perf_counter() - t0
        out["threads"] = session.threads()
        run = dict(scheduler=session.client)
    t0 = time.perf_counter()
    run_study(config.with_overrides(samples=2048), **run)  # load the kernels (in the workers)
    out["warm_seconds"] = time.perf_counter() - t0
    if session is None:
        cpu, t0 = _cpu_seconds(), time.perf_counter()
        result = run_study(config)
        out["seconds"] = time.perf_counter() - t0
        out["cpu_seconds"] = _cpu_seconds() - cpu
    else:
        from distributed import get_task_stream

        with get_task_stream(session.client) as stream:
            cpu, t0 = _cluster_cpu_seconds(session), time.perf_counter()
            result = run_study(config, **run)
            out["seconds"] = time.perf_counter() - t0
            out["cpu_seconds"] = _cluster_cpu_seconds(session) - cpu
        computes = [sum(s["stop"] - s["start"] for s in task["startstops"]
                        if s["action"] == "compute")
                    for task in stream.data if str(task["key"]).startswith("tolsim-blocks")]
        out["tasks"] = len(computes)
        out["compute_seconds"] = float(np.sum(computes))
        client = session.client
        client.gather([client.submit(_noop, i, pure=False) for i in range(50)])
        t0 = time.perf_counter()
        client.gather([client.submit(_noop, i, pure=False) for i in range(1000)])
        out["empty_task_ms"] = (time.perf_counter() - t0)  # per 1000 tasks: ms per task
        session.close()
    out["balls"] = int(result.statistics.n_balls)
    out["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    np.savez(state_file, **result.statistics.state())
    print(json.dumps(out))


def client_cost_per_block(balls_total):
    """[s] to unpickle and merge one block's result on the client (the serial part)."""
    from tolsim.study.execution import chunks, runner
    from tolsim.study.sampling import spot_check_plan
    from tolsim.study.statistics.accumulator import Accumulator

    config = study(balls_total)
    plan = spot_check_plan(config)
    chunk = list(range(runner.default_chunk_blocks(config)))
    payload = pickle.dumps(chunks.run_chunk(config, chunk, plan))
    best = np.inf
    for _ in range(5):
        t0 = time.perf_counter()
        state = runner._Progress(0, Accumulator.for_config(config), [])
        for _, block, rows in pickle.loads(payload):
            state = state.after(block, rows)
        best = min(best, (time.perf_counter() - t0) / len(chunk))
    return best, len(payload) / len(chunk), config.study.block_size * config.train.balls


def measure(balls, mode, folder, repeat=0):
    state_file = Path(folder) / f"{mode.replace(':', '_')}-{repeat}.npz"
    cmd = [sys.executable, __file__, "--child", str(balls), mode, str(state_file)]
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    done = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=3600)
    if done.returncode:
        sys.exit(f"{mode} failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1]), state_file


def same_state(a, b) -> bool:
    with np.load(a) as x, np.load(b) as y:
        return x.files == y.files and all(np.array_equal(x[k], y[k], equal_nan=True)
                                          for k in x.files)


def main():
    import tempfile

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--balls", type=float, default=1e7)
    p.add_argument("--modes", nargs="+", default=["in-process", "local:1", "local:2"])
    p.add_argument("--repeats", type=int, default=1,
                   help="runs of each mode, in turn; the best is reported (a shared machine)")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child:
        child(float(args.child[0]), args.child[1], args.child[2])
        return
    print(f"tolsim on dask.distributed: {CONFIG.name} (solved static, analytic epsilon, "
          f"propagation a), {args.balls:.0e} balls, {os.cpu_count()} cores")
    per_block, payload, balls_per_block = client_cost_per_block(args.balls)
    print(f"client, per block of {balls_per_block} balls: {1e6 * per_block:.0f} us to unpickle "
          f"and merge ({payload / 1e3:.1f} kB): at most {balls_per_block / per_block / 1e6:.0f} "
          "M balls/s whatever the cluster")
    runs = {mode: [] for mode in args.modes}
    with tempfile.TemporaryDirectory() as folder:
        for repeat in range(args.repeats):  # the modes in turn: the same load on each
            for mode in args.modes:
                runs[mode].append(measure(args.balls, mode, folder, repeat))
        base, base_state = min(runs[args.modes[0]], key=lambda r: r[0]["seconds"])
        for mode in args.modes:
            r, state = min(runs[mode], key=lambda run: run[0]["seconds"])
            rate = r["balls"] / r["seconds"]
            line = (f"{mode:>10}: {r['seconds']:6.2f} s  {rate / 1e6:.2f} M balls/s  "
                    f"CPU {r['cpu_seconds']:.2f} s")
            if mode == args.modes[0]:
                line += "  (baseline)"
            else:
                line += (f"  {r['seconds'] / base['seconds']:.2f}x the {args.modes[0]} time; "
                         "bit-identical: "
                         f"{all(same_state(s, base_state) for _, s in runs[mode])}")
            print(line)
            if "tasks" in r:
                lost = r["threads"] * r["seconds"] - r["compute_seconds"]
                print(f"{'':12}{r['tasks']} tasks of {r['balls'] / r['tasks']:.3g} balls, "
                      f"{r['compute_seconds'] / r['tasks']:.2f} s each; overhead per task "
                      f"{1e3 * lost / r['tasks']:.0f} ms of worker-thread time "
                      f"({lost / (r['threads'] * r['seconds']):.1%} of it); empty task "
                      f"{r['empty_task_ms']:.1f} ms; cluster start {r['start_seconds']:.1f} s, "
                      f"warm-up {r['warm_seconds']:.1f} s; client peak {r['peak_mib']:.0f} MiB")
            else:
                print(f"{'':12}warm-up {r['warm_seconds']:.1f} s; peak {r['peak_mib']:.0f} MiB")
        if args.repeats > 1:
            print(f"best of {args.repeats} runs each; all runs: " + "; ".join(
                f"{mode} " + " ".join(f"{r['seconds']:.2f}" for r, _ in runs[mode])
                for mode in args.modes) + " s")

if __name__ == "__main__":
    main()
