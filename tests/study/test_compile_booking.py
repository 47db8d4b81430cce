"""Compilation is booked apart from model time; throughput counts the work done here (issue 26).

A cold Numba cache compiles kernels inside the timed sections of a study. Here a compilation is
simulated by Numba's own event (``numba:compile``, what the dispatcher sends while it
compiles) around a sleep of ``COMPILE`` seconds inside the full-model re-solve.
"""

import time

import numpy as np
import pytest
from numba.core import event as numba_event
from test_study import make

import tolsim._jit as jit_defaults
import tolsim.study.pipeline.evaluate as evaluate
from tolsim.cli.run import summary
from tolsim.io.config import parse_config
from tolsim.io.netcdf import write_result
from tolsim.study.execution.runner import StudyInterrupted, run_study

#: Simulated compile time [s]; far above the real re-solve time of the few balls below
#: (300 balls at ~24 000 balls/s: ~0.01 s), so the checks do not depend on machine speed.
COMPILE = 2.0


def resolving_config(samples=300):
    """The 6-ball study of test_study with one ball outside eq24's validity (re-solved)."""
    text = make().text.replace("yaw_moment_N_m = 6.0", "side_force_ratio = [0, 0, 0, 0, 0, 0.8]")
    text = text.replace('velocity_model = "analytic"', 'velocity_model = "eq24"')
    return parse_config(text).with_overrides(samples=samples)


@pytest.fixture
def compiling_full_model(monkeypatch):
    """The full-model re-solve, preceded by a (simulated) compilation of COMPILE seconds."""
    original = evaluate.full_velocity
    calls = []

    def full_velocity(*args, **kwargs):
        if not calls:  # compiles once, as Numba does
            numba_event.start_event("numba:compile")
            time.sleep(COMPILE)
            numba_event.end_event("numba:compile")
        calls.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr(evaluate, "full_velocity", full_velocity)
    return calls


def test_resolve_time_excludes_compilation(compiling_full_model):
    result = run_study(resolving_config())
    assert compiling_full_model  # the re-solve ran
    assert result.statistics.n_resolved_full == 300
    # was ~2 s: the compilation booked as "re-solved with the full model"
    assert result.statistics.resolve_seconds < COMPILE / 2
    assert result.compile_seconds >= COMPILE and result.loop_compile_seconds >= COMPILE
    assert jit_defaults.compile_seconds(thread=False) >= COMPILE  # the process's total
    # and the throughput is over the model time (elapsed without compilation)
    assert result.balls_per_second == pytest.approx(
        300 * 6 / (result.elapsed - result.loop_compile_seconds), rel=1e-12)


def test_summary_books_compilation_on_its_own_line(compiling_full_model, tmp_path):
    result = run_study(resolving_config())
    ds = write_result(result, tmp_path / "r.nc")
    text = summary(ds, "r.nc", result.elapsed - result.loop_compile_seconds)
    line = next(x for x in text.splitlines() if x.startswith("compiled kernels:"))
    assert float(line.split()[2]) >= COMPILE
    resolve = next(x for x in text.splitlines() if "sent to the full model" in x)
    seconds = float(resolve.split("of them solved (")[1].split(" s)")[0])
    assert seconds < COMPILE / 2
    rate = float(text.splitlines()[-1].split(", ")[-1].split(" balls/s")[0].replace(",", ""))
    assert rate == pytest.approx(ds.attrs["balls_per_second"], rel=1e-3)


def test_resumed_throughput_counts_only_the_resumed_work(tmp_path):
    c = make(samples=2000)  # 16 blocks of 128 assemblies, 6 balls each
    ckpt = tmp_path / "out.nc.partial"
    with pytest.raises(StudyInterrupted):
        run_study(c, chunk_blocks=2, checkpoint_path=str(ckpt), max_blocks=5)
    resumed = run_study(c, chunk_blocks=3, checkpoint_path=str(ckpt))
    done_before = resumed.resumed_blocks * 128  # 6 blocks in the checkpoint
    # the rate in the file and the summary (was n_balls, all 12 000, most of them from the
    # checkpoint, over this run's time: 33.5 M balls/s in issue 26)
    ds = write_result(resumed, tmp_path / "r.nc")
    seconds = resumed.elapsed - getattr(resumed, "loop_compile_seconds", 0.0)
    assert ds.attrs.get("balls_per_second", np.inf) == pytest.approx(
        (2000 - done_before) * 6 / seconds, rel=1e-12)
    assert resumed.assemblies_run == 2000 - done_before
    fresh = run_study(c)
    assert fresh.assemblies_run == 2000
    assert np.isfinite(fresh.balls_per_second)
