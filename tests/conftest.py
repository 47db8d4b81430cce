"""The suite's shared set-up: deterministic property tests, and parallel runs.

Parallel runs
-------------
``python -m pytest`` runs the tests on ``-n auto`` pytest-xdist worker processes with
``--dist loadgroup`` (pyproject.toml's ``addopts``); ``-n 0`` runs them in this one process.
Three rules keep a parallel run as correct as a serial one:

* **A module runs on one worker.** Every test gets the mark ``xdist_group(<its module>)``
  (``pytest_collection_modifyitems`` below) unless it has an ``xdist_group`` of its own: a
  module- or class-scoped fixture is built once, not once per worker, and the kernels a module
  needs are compiled by one worker, not by both at the same time. (Tests that must share a
  worker with another module's say so with ``@pytest.mark.xdist_group("name")``.)
* **Session-scoped fixtures are per worker.** A session fixture is built once in each worker
  that asks for it (at most twice on 2 cores); to run something once for the whole module,
  use a module-scoped fixture.
* **The kernels are compiled once, before the workers start** (``pytest_configure``:
  ``tolsim warmup`` on every packaged config), so that the workers do not both compile them.
* **One Numba thread per worker.** Two workers on two cores each fill one core; a parallel
  kernel on two threads in each would make every launch wait for a core, which costs
  milliseconds on a busy machine: tests that step along the track call small kernels
  thousands of times (80 s against 10 s for one test, measured). A test that checks that
  results do not depend on the thread count runs the other count with the fixture
  ``other_thread_count``.
* **The workers share one Numba cache, under a lock.** Numba writes each cache file
  atomically, but it reads, changes and rewrites a kernel's index without a lock: two processes
  that save two signatures of one kernel at the same moment can leave an index that points one
  signature to the other's machine code (numba/numba#4807, #10128). In a worker, the save
  (index and data) holds an exclusive ``flock`` on ``index.lock`` in the cache folder, so a
  kernel that one worker compiled is loaded, not compiled again, by the other. (One folder
  per worker would be safe too, but then each worker compiles every kernel: on a cold cache,
  compiling is most of the suite's time.)

Tests must not write outside ``tmp_path`` (each worker has its own ``basetemp``) and must not
depend on how busy the machine is: the other worker, and other programs, share the cores.
"""

import fcntl
import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from hypothesis import settings
from numba.core import caching as numba_caching


def _under_lock(save):
    """``IndexDataCacheFile.save`` holding an exclusive lock on the cache folder."""

    def save_locked(self, key, data):
        folder = getattr(self, "_cache_path", None)
        if folder is None:  # not the layout this lock was written for
            return save(self, key, data)
        with open(os.path.join(folder, "index.lock"), "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file is closed
            return save(self, key, data)

    return save_locked


# A private Numba method: if a Numba release renames it, the workers run without the lock
# (the race above is rare) rather than fail to start.
_SAVE = getattr(getattr(numba_caching, "IndexDataCacheFile", None), "save", None)
if os.environ.get("PYTEST_XDIST_WORKER") and _SAVE is not None:
    numba_caching.IndexDataCacheFile.save = _under_lock(_SAVE)
if os.environ.get("PYTEST_XDIST_WORKER"):
    numba.set_num_threads(1)  # one core per worker (module docstring)

# Deterministic property tests: CI must not flake, and a failure must reproduce.
settings.register_profile("tolsim", derandomize=True, deadline=None, max_examples=60)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "tolsim"))


def pytest_configure(config):
    """Before the xdist workers start: compile the studies' kernels once (``tolsim warmup``
    on every packaged config, two processes), so that the two workers load them from the
    shared cache instead of both compiling the same kernels at the same time (on a cold
    cache, compiling is most of the suite's time). Only in the controller of a parallel run;
    a failure here is left to the tests to show."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    configs = sorted(str(p) for p in (Path(__file__).resolve().parents[1] / "configs").glob(
        "*.toml"))
    subprocess.run([sys.executable, "-m", "tolsim", "warmup", *configs], check=False,
                   capture_output=True, timeout=1800)


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook turns the marks into groups
def pytest_collection_modifyitems(config, items):
    """Group the tests by module (xdist's ``--dist loadgroup``), unless a test has a group."""
    for item in items:
        if item.get_closest_marker("xdist_group") is None:
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))


@pytest.fixture
def rng():
    return np.random.default_rng(20181109)


@pytest.fixture
def other_thread_count():
    """``run(function, *args, **kwargs)``: ``function`` on a Numba thread count other than
    the ambient one (1 where several are in use, else all of Numba's), for the tests that
    results do not depend on the thread count (a one-core machine has only one count)."""

    def run(function, *args, **kwargs):
        ambient = numba.get_num_threads()
        numba.set_num_threads(1 if ambient > 1 else numba.config.NUMBA_NUM_THREADS)
        try:
            return function(*args, **kwargs)
        finally:
            numba.set_num_threads(ambient)

    return run


@pytest.fixture(scope="session")
def carriage_balls():
    """``balls(oversize, seed, assemblies)``: (dbeta, F), (n, 4) each, of every ball with
    finite forces in sampled assemblies of ``configs/carriage_preload.toml``'s guide (two
    wrapped tracks of 12 [Lin2018] Table 1 balls, 300 N and 2 N m; 1 um arc-centre offsets,
    0.1 deg rotations, 0.1 um ball sizes), solved by
    :func:`tolsim.physics.carriage.solve_carriage_batch` at ball oversize ``oversize`` [m]."""
    from tolsim.physics.carriage import CarriageLayout, CarriageLoad, solve_carriage_batch
    from tolsim.physics.static import GrooveErrors

    def balls(oversize, seed, assemblies):
        gen = np.random.default_rng(seed)
        shape = (assemblies, 2, 12)
        errors = GrooveErrors(
            arc_centre_offset_normal=gen.normal(0.0, 1e-6, shape + (4,)),
            arc_centre_offset_tangential=gen.normal(0.0, 1e-6, shape + (4,)),
            bottom_rotation=gen.normal(0.0, 1.75e-3, shape),
            top_rotation=gen.normal(0.0, 1.75e-3, shape),
            ball_oversize=gen.normal(0.0, 0.1e-6, shape))
        layout = CarriageLayout([-0.02, 0.02], [0.0, 0.0], np.deg2rad([90.0, -90.0]), 12,
                                0.01005)
        batch = solve_carriage_batch(layout, CarriageLoad(vertical_force=300.0,
                                                          pitch_moment=2.0),
                                     oversize=oversize, groove_errors=errors)
        force = batch.normal_force.reshape(-1, 4)
        keep = np.all(np.isfinite(force), axis=1)
        return batch.contact_angle_deviation.reshape(-1, 4)[keep], force[keep]

    return balls
