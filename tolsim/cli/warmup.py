"""``tolsim warmup``: compile the Numba kernels of the studies once, ahead of the first run.

The kernels are compiled on first use and cached on disk (``cache=True``); a first run on a
cold cache otherwise spends most of its time compiling (README "Quick start"). The warm-up
runs each study a few assemblies long, in separate processes (one per core), so that every
kernel is compiled with the exact argument types the study uses and kept in the cache.
"""

import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

from tolsim.cli import UsageError, integer_at_least, path_argument

DESCRIPTION = """\
Compile the Numba kernels that the studies need, once, and keep them in Numba's disk cache,
so that the first `tolsim run` does not wait for compilation. Without CONFIG: the packaged
default study. With configs: each of them (a few assemblies each; nothing is written).
"""

EXAMPLES = """\
examples:
  tolsim warmup                      # the kernels of the packaged default study
  tolsim warmup configs/*.toml       # the kernels of every example study
"""


def add_parser(sub, formatter_class):
    p = sub.add_parser("warmup", help="compile the kernels of the studies ahead of a first run",
                       description=DESCRIPTION, epilog=EXAMPLES,
                       formatter_class=formatter_class)
    p.add_argument("configs", type=path_argument, nargs="*", metavar="CONFIG",
                   help="study configs (TOML) whose kernels to compile; default: the "
                        "packaged default study")
    p.add_argument("--jobs", type=integer_at_least(1, "a whole number >= 1"),
                   default=max(1, min(2, os.cpu_count() or 1)), metavar="N",
                   help="processes compiling at the same time (default: up to 2)")
    return p


def _full_model():
    """Compile the full friction model (the re-solves and spot checks of every study)."""
    import numpy as np  # noqa: PLC0415

    from tolsim.physics.geometry import TABLE1, paired_forces  # noqa: PLC0415
    from tolsim.physics.velocity.full import full  # noqa: PLC0415

    dbeta = np.deg2rad([[-2.0, 2.0, 0.0, 0.0]])  # (n, 4) float64, as the re-solves pass them
    full(dbeta, paired_forces(-120.0, 200.0)[None, :], TABLE1)


def _fast_path(path):
    """Compile a study's sampling, static and fast velocity kernels (no full model)."""
    from dataclasses import replace  # noqa: PLC0415

    from tolsim.io.config import load_config  # noqa: PLC0415
    from tolsim.study.execution.runner import run_study  # noqa: PLC0415

    config = load_config(path)
    # a sweep's points share its kernels but for the swept values: each point, one block
    for point in (config.sweep.points if config.sweep is not None else (config,)):
        point = point.with_overrides(samples=point.study.block_size)
        run_study(replace(point, study=replace(point.study, spot_checks=0,
                                               sensitivity_samples=0)))


def _study(path, out):
    """A study as ``tolsim run`` runs it, one block of assemblies long (all its kernels)."""
    from tolsim.cli import main  # noqa: PLC0415
    from tolsim.io.config import load_config  # noqa: PLC0415

    samples = load_config(path).study.block_size
    args = ["run", *([path] if path else []), "--samples", str(samples), "--quiet", "-o", out]
    code = main(args)
    if code:
        raise RuntimeError(f"tolsim run {path or '(default)'} failed with exit code {code}")


def _task(job):
    name, *args = job
    started = time.perf_counter()
    {"full": _full_model, "fast": _fast_path, "study": _study}[name](*args)
    return time.perf_counter() - started


def run(args) -> int:
    from tolsim.io.config import ConfigError, load_config  # noqa: PLC0415

    configs = [str(p) for p in args.configs] or [None]
    for path in configs:  # bad input: one line, before any compilation
        try:
            load_config(path)
        except ConfigError as exc:
            raise UsageError(str(exc)) from None
    started = time.perf_counter()
    context = get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="tolsim-warmup-") as tmp, \
            ProcessPoolExecutor(args.jobs, mp_context=context) as pool:
        # 1) the two large groups side by side: the full model, and the fast path of the
        #    first study; 2) every study in full (only what is still missing compiles)
        list(pool.map(_task, [("full",), ("fast", configs[0])]))
        jobs = [("study", path, os.path.join(tmp, f"{i}.nc")) for i, path in enumerate(configs)]
        list(pool.map(_task, jobs))
    print(f"tolsim warmup: kernels of {len(configs)} "
          f"{'study' if len(configs) == 1 else 'studies'} compiled and cached "
          f"({time.perf_counter() - started:.1f} s)", file=sys.stderr)
    return 0
