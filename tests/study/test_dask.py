"""Studies on dask.distributed (issue 16): the same bits as in this process, whatever happens.

A LocalCluster of 2 single-threaded worker processes (``--scheduler local:2``), started once
for the module, runs the studies; each result is compared bit for bit with the in-process run
(the Accumulator's state arrays and the spot checks, or the netCDF files' data variables).
The faults are real: a worker process killed with SIGKILL mid-run, a client process killed
with SIGKILL after some checkpoints. The one-line errors need no cluster.
"""

import logging
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from test_config import MINIMAL
from test_interrupt import assert_same_result, tiny
from test_study import make

from tolsim.cli import main
from tolsim.study.execution import distributed as tolsim_distributed
from tolsim.study.execution.distributed import (
    INSTALL_HINT,
    TASK_BALLS,
    SchedulerError,
    chunks_per_task,
    parse_scheduler,
    task_size,
)
from tolsim.study.execution.runner import run_study

#: Seconds a test may wait for the cluster (workers restarting, tasks finishing).
WAIT = 60


@pytest.fixture(scope="module")
def client():
    """A connected Client of a LocalCluster of 2 single-threaded worker processes, started
    through ``--scheduler local:2``'s own path, and closed after the module's tests."""
    pytest.importorskip("distributed")
    session = tolsim_distributed.DaskSession("local:2")
    try:
        session.client.wait_for_workers(2, timeout=WAIT)
        # the workers import tolsim and load the kernels once, before the timed tests
        run_study(make(samples=512), scheduler=session.client, chunk_blocks=1)
        yield session.client
    finally:
        session.close()


@pytest.fixture
def two_workers(client):
    """The module's client, with both workers up (a test may have killed one)."""
    client.wait_for_workers(2, timeout=WAIT)
    return client


def slowed_task(config, chunks, *args):
    """The task of ``tolsim.study.execution.distributed``, slowed so that earlier blocks finish
    later:
    the tasks end out of order, and a worker killed early is still busy. (Runs on the
    workers, which import it from this module.)"""
    time.sleep(0.25 if chunks[0][0] == 0 else 0.05)
    return tolsim_distributed._run_task(config, chunks, *args)


@pytest.mark.parametrize("chunk_blocks", [1, 5])
def test_bit_identical_on_two_workers(two_workers, chunk_blocks):
    # tiny(): 12 blocks of 64 assemblies with 5 spot checks (re-solved by a task); chunk_blocks
    # 1 gives 12 tasks of one block, 5 gives 3 tasks of 5, 5 and 2 blocks
    config = tiny()
    reference = run_study(config)
    result = run_study(config, scheduler=two_workers, chunk_blocks=chunk_blocks)
    assert int(result.statistics.n_assemblies) == config.study.samples
    assert len(result.spot_checks.ball_index) == 5
    assert_same_result(result, reference)
    assert result.workers == 2


def test_a_cluster_object_is_used_and_left_running(two_workers):
    # run_study(scheduler=cluster), as with a dask_jobqueue.SLURMCluster
    config = tiny()
    result = run_study(config, scheduler=two_workers.cluster)
    assert_same_result(result, run_study(config))
    assert two_workers.cluster.status.name == "running" and len(two_workers.nthreads()) == 2


def test_bit_identical_along_the_track_with_lhs(two_workers):
    # the other propagation (per-block evaluation) and sampling scheme
    config = make("paired", "along_track", "lhs", samples=300)
    assert_same_result(run_study(config, scheduler=two_workers, chunk_blocks=1),
                       run_study(config))


def test_bit_identical_with_a_precision_target(two_workers):
    # the run stops at a block inside a task, the look-ahead's tasks are cancelled, and the
    # result is that of the in-process run with the same target
    from tolsim.study.execution.runner import PrecisionTarget

    config = make(samples=3000)
    target = PrecisionTarget(0.05)
    reference = run_study(config, target=target)
    result = run_study(config, scheduler=two_workers, chunk_blocks=1, target=target)
    assert int(result.statistics.n_assemblies) < 3000 and result.target_reached
    assert_same_result(result, reference)
    assert result.config.study.samples == reference.config.study.samples


def test_bit_identical_when_tasks_finish_out_of_order(two_workers, monkeypatch):
    from distributed import get_task_stream

    monkeypatch.setattr(tolsim_distributed, "_run_task", slowed_task)
    config = tiny()
    with get_task_stream(two_workers) as stream:
        result = run_study(config, scheduler=two_workers, chunk_blocks=1)
    assert_same_result(result, run_study(config))
    ends = {int(str(t["key"]).split("-")[2]): t["startstops"][-1]["stop"]
            for t in stream.data if str(t["key"]).startswith("tolsim-blocks")}
    assert len(ends) == 12 and sorted(ends, key=ends.get) != sorted(ends)  # out of order


def test_look_ahead_is_bounded(two_workers):
    # at most LOOKAHEAD_PER_THREAD x threads + 1 = 5 of the 12 tasks are out at once (the
    # results the client has not merged yet live on the workers, not in the client)
    def tasks_out(dask_scheduler):
        return sum(str(key).startswith("tolsim-blocks") and task.state != "released"
                   for key, task in dask_scheduler.tasks.items())

    seen = []
    config = tiny()
    result = run_study(config, scheduler=two_workers, chunk_blocks=1,
                       progress=lambda n: seen.append(two_workers.run_on_scheduler(tasks_out)))
    assert_same_result(result, run_study(config))
    window = tolsim_distributed.LOOKAHEAD_PER_THREAD * 2 + 1
    assert len(seen) == 12 and 2 <= max(seen) <= window


def test_bit_identical_when_a_worker_is_killed(two_workers, monkeypatch):
    # After the first block is merged the look-ahead has 5 tasks out, on both workers; one
    # worker process gets SIGKILL. Its running task and the results it held are lost, the
    # nanny restarts it, the scheduler reruns them, and the result is the same.
    monkeypatch.setattr(tolsim_distributed, "_run_task", slowed_task)
    config = tiny()
    reference = run_study(config)
    killed = []

    def kill_a_worker(assemblies):
        if killed:
            return
        busy = {w: len(keys) for w, keys in two_workers.processing().items()}
        for w, keys in two_workers.has_what().items():
            busy[w] = busy.get(w, 0) + sum(str(k).startswith("tolsim-blocks") for k in keys)
        victim = max(busy, key=busy.get)
        pid = two_workers.run(os.getpid, workers=[victim])[victim]
        os.kill(pid, signal.SIGKILL)
        killed.append((victim, busy[victim]))

    result = run_study(config, scheduler=two_workers, chunk_blocks=1, progress=kill_a_worker)
    ((victim, work),) = killed
    assert work >= 1  # the killed worker was running or holding tasks of this run
    assert_same_result(result, reference)
    two_workers.wait_for_workers(2, timeout=WAIT)
    assert victim not in two_workers.nthreads()  # its nanny started a new worker process


def test_resume_after_the_client_is_killed(two_workers, tmp_path):
    # A client process with a checkpoint after every chunk kills itself (SIGKILL, no chance
    # to clean up) after merging 5 of 10 blocks; `tolsim run --resume --scheduler` continues
    # from the checkpoint (4 blocks) and writes the same file as an in-process run.
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL.replace("samples = 100", "samples = 1000\nblock_size = 100"))
    out = tmp_path / "s.nc"
    address = two_workers.scheduler.address
    client_process = textwrap.dedent(f"""\
        import os, signal
        from tolsim.io.config import load_config
        from tolsim.study.execution.runner import run_study

        merged = []

        def progress(assemblies):
            merged.append(assemblies)
            if len(merged) == 5:
                os.kill(os.getpid(), signal.SIGKILL)

        run_study(load_config({str(cfg)!r}), scheduler={address!r}, chunk_blocks=1,
                  checkpoint_path={f"{out}.partial"!r}, checkpoint_interval=0,
                  progress=progress)
        """)
    killed = subprocess.run([sys.executable, "-c", client_process], capture_output=True,
                            text=True, timeout=300)
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert os.path.exists(f"{out}.partial") and not out.exists()
    assert main(["run", str(cfg), "-o", str(out), "--resume", "--scheduler", address]) == 0
    fresh = tmp_path / "fresh.nc"
    assert main(["run", str(cfg), "-o", str(fresh), "--quiet"]) == 0
    with xr.open_dataset(out) as a, xr.open_dataset(fresh) as b:
        assert a.attrs["workers"] == 2 and "--scheduler" in a.attrs["history"]
        for name in b.data_vars:
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


def test_ctrl_c_on_a_local_cluster(tmp_path):
    # Ctrl-C in a terminal reaches the whole process group, workers included: the client
    # saves the checkpoint and says so in one line, exit code 130, and no worker process
    # prints a traceback of its own. The study (10^8 assemblies, 10^9 balls: minutes after
    # its first checkpoint on any machine; tasks are submitted a few at a time) is still
    # running when the interrupt lands (10^7 finished first on a CI run).
    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "y.nc"
    # A shell that starts a job in the background (CI, nohup ... &) hands it SIGINT ignored,
    # and Python keeps an ignored SIGINT ignored: the study is started with Ctrl-C restored,
    # as in a terminal.
    command = [sys.executable, "-c", "import signal, sys; from tolsim.cli import main; "
               "signal.signal(signal.SIGINT, signal.default_int_handler); sys.exit(main())", "run",
               str(root / "configs" / "yaw_moment_tolerances.toml"), "--samples", "100000000",
               "--scheduler", "local:2", "-o", str(out), "--checkpoint-interval", "0"]
    # PYTHONFAULTHANDLER: a process that does not stop is made to print where it hangs
    env = dict(os.environ, PYTHONWARNINGS="ignore", PYTHONFAULTHANDLER="1")
    # The same study, small, first: its workers compile the kernels a cold cache lacks (a
    # fresh CI machine), so the interrupt below lands on running tasks, not on workers
    # compiling. (An interrupt during a worker's compilation waits for the compilation to
    # end: minutes on a cold cache and a busy machine; a known gap, not what this tests.)
    warm = [*command[:6], "2048", *command[7:10], str(tmp_path / "warm.nc")]
    subprocess.run(warm, env=env, check=True, capture_output=True, timeout=30 * WAIT)
    run = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 5 * WAIT
        while not os.path.exists(f"{out}.partial") and run.poll() is None:
            assert time.monotonic() < deadline, "no checkpoint"
            time.sleep(0.05)
        assert run.poll() is None, run.communicate()
        os.killpg(run.pid, signal.SIGINT)
        try:
            _, err = run.communicate(timeout=5 * WAIT)
        except subprocess.TimeoutExpired:  # every thread's stack, of every process
            os.killpg(run.pid, signal.SIGABRT)
            _, err = run.communicate(timeout=WAIT)
            pytest.fail(f"still running {5 * WAIT} s after Ctrl-C:\n{err}")
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
            run.wait()
    assert run.returncode == 130, err
    assert "Traceback" not in err and err.rstrip().endswith(
        "run the same command again to resume"), err
    assert os.path.exists(f"{out}.partial") and not out.exists()


def test_cli_says_where_it_runs(two_workers, tmp_path, capsys):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    address = two_workers.scheduler.address
    assert main(["run", str(cfg), "-o", str(tmp_path / "s.nc"), "--scheduler", address]) == 0
    err = capsys.readouterr().err
    assert f"running on the dask scheduler {address}: 2 workers, 2 threads" in err
    if "dashboard" in two_workers.scheduler_info()["services"]:  # bokeh installed
        assert "; dashboard http" in err


@pytest.mark.filterwarnings("ignore:Port 8787 is already in use")  # the module's cluster has it
def test_readme_local_cluster_example_runs(tmp_path, monkeypatch, capsys):
    # the README's LocalCluster command, as written (the config found from the checkout),
    # gives the file of the same command without --scheduler
    pytest.importorskip("distributed")
    root = Path(__file__).resolve().parents[2]
    text = (root / "README.md").read_text(encoding="utf-8")
    section = re.search(r"^## Running on a cluster\n(.*?)(?=^## )", text, re.M | re.S).group(1)
    line = next(x for x in section.splitlines() if x.startswith("tolsim run") and "local:" in x)
    argv = [str(root / a) if a.startswith("configs/") else a for a in shlex.split(line)[1:]]
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 0
    assert "running on a LocalCluster: 2 workers, 2 threads" in capsys.readouterr().err
    written = tmp_path / Path(argv[1]).with_suffix(".nc").name
    in_process = argv[:argv.index("--scheduler")] + ["-o", "in_process.nc", "--quiet"]
    assert main(in_process) == 0
    with xr.open_dataset(written) as a, xr.open_dataset(tmp_path / "in_process.nc") as b:
        assert int(a.n_assemblies) == 200_000
        for name in b.data_vars:
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


# --- one-line errors, no cluster needed -------------------------------------------------------
def _run_cli(tmp_path, capsys, *flags):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    rc = main(["run", str(cfg), "-o", str(tmp_path / "s.nc"), *flags])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith("tolsim run: error: "), err
    assert sorted(os.listdir(tmp_path)) == ["s.toml"]  # nothing written
    return err


def test_unreachable_scheduler_is_one_line(tmp_path, capsys):
    dask = pytest.importorskip("dask")
    with socket.socket() as s:  # a port on this machine that nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    t0 = time.perf_counter()
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}):
        err = _run_cli(tmp_path, capsys, "--scheduler", address)
    assert f"cannot reach the dask scheduler at {address}" in err
    assert "local:N" in err and time.perf_counter() - t0 < WAIT


def test_missing_extra_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if not installed
    err = _run_cli(tmp_path, capsys, "--scheduler", "local:2")
    assert INSTALL_HINT in err and "dask.distributed" in err
    with pytest.raises(ImportError, match="tolsim\\[dask\\]"):
        run_study(tiny(), scheduler="local:2")


@pytest.mark.parametrize("flags, message", [
    (["--scheduler", "local:0"], "local:N must be a positive integer"),
    (["--scheduler", "nowhere"], "expected tcp://HOST:PORT"),
    (["--scheduler", "/no/such/scheduler.json"], "no such scheduler file"),
    (["--scheduler", "local:2", "--workers", "2"], "--workers and --scheduler"),
])
def test_bad_scheduler_values_are_one_line(tmp_path, capsys, flags, message):
    pytest.importorskip("distributed")
    assert message in _run_cli(tmp_path, capsys, *flags)


def test_parse_scheduler(tmp_path):
    scheduler_file = tmp_path / "scheduler.json"
    scheduler_file.write_text("{}")
    assert parse_scheduler("local:3") == ("local", 3)
    assert parse_scheduler("local")[0] == "local"
    assert parse_scheduler("tcp://10.0.0.1:8786") == ("address", "tcp://10.0.0.1:8786")
    assert parse_scheduler("head-node:8786") == ("address", "tcp://head-node:8786")
    assert parse_scheduler(str(scheduler_file)) == ("file", str(scheduler_file))
    with pytest.raises(SchedulerError, match="local:N"):
        parse_scheduler("local:two")
    with pytest.raises(ValueError):  # SchedulerError is a ValueError: the CLI's one line
        run_study(tiny(), scheduler="local:1", workers=2)


def test_tasks_group_chunks_but_keep_every_thread_busy():
    chunks = [[k] for k in range(1000)]
    # big studies: about TASK_BALLS per task
    assert chunks_per_task(chunks, 1 << 18, threads=2) == (1 << 21) // (1 << 18)
    # small ones: at least TASKS_PER_THREAD tasks per thread, one chunk per task at least
    assert chunks_per_task(chunks, 1 << 10, threads=100) == 1000 // (4 * 100)
    assert chunks_per_task(chunks[:3], 1 << 10, threads=2) == 1


def test_a_sweep_on_the_cluster_is_bit_identical(two_workers, tmp_path):
    # issue 14: every point of a sweep runs its chunks as tasks (one cluster for all points)
    from tolsim.io.config import parse_config
    from tolsim.io.sweep import run_sweep

    text = (Path(__file__).resolve().parents[2] / "configs" / "known_answer.toml"
            ).read_text().replace("samples = 20000", "samples = 2048").replace(
        "spot_checks = 10", "spot_checks = 2")
    config = parse_config(text + '\n[sweep]\n"loads.normal_load_N" = [150, 250]\n')
    here, _ = run_sweep(config, tmp_path / "here.nc")
    there, _ = run_sweep(config, tmp_path / "there.nc", scheduler=two_workers, chunk_blocks=1)
    for name in here.data_vars:
        np.testing.assert_array_equal(there[name].values, here[name].values, err_msg=name)


def test_a_single_block_probe_does_not_size_the_tasks():
    # run_study's require_answer puts block 0 alone in front of chunks of 25 blocks; sizing
    # the tasks by that first chunk put 200 full chunks (5e7 balls) into one task, and a
    # Ctrl-C on a LocalCluster then waited for it (tests/study/test_dask.py ctrl-c test: 30 s
    # to the first checkpoint, a 300 s hang on a busy machine)
    per_block = 1024 * 10
    chunks = [[0]] + [list(range(i, i + 25)) for i in range(1, 25 * 4000, 25)]
    size = task_size(chunks, per_block, threads=2)
    assert size == TASK_BALLS // (25 * per_block)
    assert max(sum(len(c) for c in chunks[i:i + size]) for i in range(0, len(chunks), size)
               ) * per_block <= TASK_BALLS


def test_a_second_local_cluster_takes_another_dashboard_port_quietly(client, recwarn):
    # With the dashboard's port taken (here by the module's cluster, or another run on the
    # machine) dask takes a free port and warns "Port 8787 is already in use"; the link
    # connect returns is the port it took, so tolsim silences that one warning (it showed
    # in CI when two test processes started clusters at once).
    first = client.dashboard_link
    second, cluster, link = tolsim_distributed.connect("local:1")
    try:
        assert not [w for w in recwarn if "already in use" in str(w.message)]
        if first is not None and link is not None:
            assert link != first
    finally:
        second.close()
        cluster.close()


def test_a_worker_s_heartbeat_failure_at_close_is_not_shown():
    # The record a LocalCluster's worker logs (with its traceback) when the client closed the
    # cluster between two heartbeats (seen on Ctrl-C, test_ctrl_c_on_a_local_cluster): dropped
    # by the workers' filter; any other record of the worker passes
    quiet_heartbeat = tolsim_distributed.quiet_heartbeat

    def record(message):
        return logging.LogRecord("distributed.worker", logging.ERROR, __file__, 1, message,
                                 None, None)

    assert not quiet_heartbeat(record("Failed to communicate with scheduler during heartbeat."))
    assert quiet_heartbeat(record("Worker stream died during communication"))


def test_an_address_that_is_not_a_scheduler_is_one_line(tmp_path, capsys):
    # A dask worker's address (found when the free port of
    # test_unreachable_scheduler_is_one_line was taken by another test's worker, session 28):
    # the client's handshake failed inside dask with "TypeError: Worker.identity() got an
    # unexpected keyword argument", a traceback. Now one line naming the address.
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, processes=False, dashboard_address=":0") as c:
        address = next(iter(c.workers.values())).address
        err = _run_cli(tmp_path, capsys, "--scheduler", address)
    assert f"{address} answered, but not as a dask scheduler" in err
    assert "local:N" in err
