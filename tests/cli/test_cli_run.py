"""``tolsim run``: output file, summary, exit codes, bad configs, resuming."""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from test_config import BAD, MINIMAL

from tolsim.cli import main
from tolsim.io.netcdf import read_result

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_run_writes_file_and_summary(tmp_path, capsys):
    out = tmp_path / "case.nc"
    rc = main(["run", str(CONFIGS / "paper_case_study.toml"), "-o", str(out)])
    assert rc == 0
    ds = read_result(out)
    assert int(ds.n_contact) == 16
    text = capsys.readouterr().out
    assert "P(contact" in text and "95 % CI" in text and "spot checks" in text
    assert "epsilon" in text and str(out) in text
    assert not Path(f"{out}.partial").exists()


def test_summary_says_why_sobol_indices_are_not_estimable(tmp_path):
    # rare_contact.toml with gaps U(0, 1 um), importance sampling and sensitivity_samples:
    # contact varied in 3 of 2 048 rows
    # and the summary ranked its drivers by noise; NaN indices now come with the reason
    from tolsim.cli.run import summary

    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    out = tmp_path / "s.nc"
    assert main(["run", str(cfg), "-o", str(out), "--samples", "20", "--quiet"]) == 0
    reason = ("the output varies in only 3 of 2,048 rows: indices not estimable (51 of 1,000 "
              "bootstrap resamples have no variance)")
    ds = read_result(out).assign_coords(factor=("factor", [0, 1]),
                                        factor_name=("factor", ["a", "b"]))
    ds["sensitivity_total"] = ("factor", [0.3, 0.6])
    ds["sensitivity_contact_total"] = ("factor", [np.nan, np.nan])
    ds["sensitivity_contact_total"].attrs["not_estimable"] = reason
    text = summary(ds, out, 1.0)
    assert "drivers of epsilon (total Sobol' index): b 0.60, a 0.30" in text
    assert f"drivers of contact (total Sobol' index): {reason}" in text


def test_overrides_and_quiet(tmp_path, capsys):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    out = tmp_path / "s.nc"
    rc = main(["run", str(cfg), "-o", str(out), "--samples", "50", "--seed", "3", "--quiet"])
    assert rc == 0
    assert capsys.readouterr().out == ""
    ds = read_result(out)
    assert int(ds.n_assemblies) == 50 and ds.attrs["seed"] == 3
    # the stored config is the effective one: the overrides are in it (issue 17, item 2)
    from tolsim.io.config import parse_config

    stored = parse_config(ds.attrs["config"])
    assert stored.study.samples == 50 and stored.study.seed == 3
    assert ds.attrs["config"] != MINIMAL


def test_default_output_name(tmp_path, monkeypatch):
    cfg = tmp_path / "mystudy.toml"
    cfg.write_text(MINIMAL)
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(cfg), "--quiet", "--samples", "10"]) == 0
    assert (tmp_path / "mystudy.nc").exists()


@pytest.mark.parametrize("replace_, key", [(b[1], b[2]) for b in BAD], ids=[b[0] for b in BAD])
def test_bad_config_exit_2_one_line_no_file(tmp_path, capsys, replace_, key):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(MINIMAL.replace(*replace_, 1))
    out = tmp_path / "bad.nc"
    rc = main(["run", str(cfg), "-o", str(out)])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("tolsim run: error: ")
    assert key in err
    assert sorted(os.listdir(tmp_path)) == ["bad.toml"]


@pytest.mark.parametrize("argv, message", [
    (["--samples", "0"], "positive integer"),
    (["--seed", "-4"], "--seed"),
    (["--workers", "x"], "--workers: expected a number of processes from 1 to 1024"),
    # 999999999999 overflowed the process pool's C int: a traceback (session 28's flag fuzz)
    (["--workers", "999999999999"], "from 1 to 1024, got '999999999999'"),
    (["-o", "/nonexistent-folder/x.nc"], "does not exist"),
    (["--resume"], "no checkpoint"),
])
def test_bad_flags(tmp_path, capsys, argv, message):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    if "-o" not in argv:
        argv = argv + ["-o", str(tmp_path / "s.nc")]
    assert main(["run", str(cfg)] + argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert sorted(os.listdir(tmp_path)) == ["s.toml"]


def test_rerun_resumes_from_checkpoint(tmp_path, capsys):
    # Interrupt a run after 3 blocks (through the Python API, as a crash would leave it), then
    # the same command picks the checkpoint up and gives the same data as a fresh run.
    from tolsim.io.config import load_config
    from tolsim.study.execution.runner import StudyInterrupted, run_study

    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL.replace("samples = 100", "samples = 1000\nblock_size = 100"))
    out = tmp_path / "s.nc"
    with pytest.raises(StudyInterrupted):
        run_study(load_config(cfg), chunk_blocks=1, checkpoint_path=f"{out}.partial",
                  max_blocks=3)
    assert main(["run", str(cfg), "-o", str(out), "--resume", "--quiet"]) == 0
    assert not Path(f"{out}.partial").exists()
    fresh = tmp_path / "fresh.nc"
    assert main(["run", str(cfg), "-o", str(fresh), "--quiet"]) == 0
    a, b = xr.open_dataset(out), xr.open_dataset(fresh)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    a.close()
    b.close()


def test_another_studys_checkpoint_is_kept_unless_fresh(tmp_path, capsys):
    # A rerun with another --samples said "ignoring ...partial" and then overwrote it: an
    # audit lost 1.08 M finished assemblies that way. Another study's checkpoint is now
    # refused (exit 2, one line naming it and --fresh) and kept; --fresh discards it.
    from tolsim.io.config import load_config
    from tolsim.study.execution.runner import StudyInterrupted, run_study

    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL.replace("samples = 100", "samples = 1000\nblock_size = 100"))
    out = tmp_path / "s.nc"
    partial = Path(f"{out}.partial")
    with pytest.raises(StudyInterrupted):
        run_study(load_config(cfg), chunk_blocks=1, checkpoint_path=str(partial),
                  max_blocks=3)
    saved = partial.read_bytes()
    for extra in ([], ["--resume"]):
        assert main(["run", str(cfg), "-o", str(out), "--samples", "500", *extra]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err
        assert f"{partial} is the checkpoint of another study" in err and "--fresh" in err
        # what differs, so the user can tell a typo from another study (session 25)
        assert "its config differs at line" in err, err
        assert "'samples = 1000' there, 'samples = 500' here" in err, err
        assert partial.read_bytes() == saved and not out.exists()
    assert main(["run", str(cfg), "-o", str(out), "--samples", "500", "--fresh", "--quiet"]) == 0
    assert out.exists() and not partial.exists()


def test_console_script_process(tmp_path):
    # The real process: exit codes and stderr as a user sees them (not a TTY: no progress bar).
    out = tmp_path / "m.nc"
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    ok = subprocess.run([sys.executable, "-m", "tolsim", "run",
                         str(CONFIGS / "paper_mitigated.toml"), "-o", str(out)],
                        capture_output=True, text=True, env=env, timeout=300)
    assert ok.returncode == 0, ok.stderr
    assert "P(contact" in ok.stdout and out.exists()
    bad = subprocess.run([sys.executable, "-m", "tolsim", "run", str(tmp_path / "none.toml")],
                         capture_output=True, text=True, env=env, timeout=300)
    assert bad.returncode == 2
    assert bad.stderr.count("\n") == 1 and "none.toml" in bad.stderr


def test_a_reader_that_leaves_early_gets_no_traceback(tmp_path):
    # `tolsim run ... | head -1`: the pipe closes before the summary is printed; the file is
    # written, and the process ends quietly with the shell's SIGPIPE status, 128 + 13.
    out = tmp_path / "m.nc"
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    proc = subprocess.Popen([sys.executable, "-m", "tolsim", "run",
                             str(CONFIGS / "paper_mitigated.toml"), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    proc.stdout.close()  # the reader is gone before the first line
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 141, err
    assert "Traceback" not in err and "Error" not in err, err
    assert out.exists()


# --- issue 17: output checked first, what a long run says, precision target -------------------
def _no_sampling(monkeypatch):
    """Make any study fail: the checks below must come before the work."""
    import tolsim.study.execution.runner

    def refuse(*args, **kwargs):
        raise AssertionError("the study ran")

    monkeypatch.setattr(tolsim.study.execution.runner, "run_study", refuse)


def _as_root():
    return hasattr(os, "geteuid") and os.geteuid() == 0


@pytest.mark.parametrize("case", ["parent_is_a_file", "output_is_a_folder",
                                  "read_only_file_system", "read_only_folder",
                                  "write_protected_output"])
def test_unwritable_output_fails_before_any_work(tmp_path, capsys, monkeypatch, case):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    if case == "parent_is_a_file":  # unwritable for root too
        (tmp_path / "notes.txt").write_text("")
        out, message = tmp_path / "notes.txt" / "s.nc", "is not a folder"
    elif case == "output_is_a_folder":
        out, message = tmp_path / "s.nc", "is a folder"
        out.mkdir()
    elif case == "read_only_file_system":  # as a read-only mount answers, root or not
        import errno
        import tempfile

        def refuse(*args, **kwargs):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS))

        monkeypatch.setattr(tempfile, "mkstemp", refuse)
        out, message = tmp_path / "s.nc", "cannot write to output folder"
    else:
        if _as_root():
            pytest.skip("permissions do not stop root")
        folder = tmp_path / "results"
        folder.mkdir()
        out = folder / "s.nc"
        if case == "read_only_folder":
            folder.chmod(0o555)
            message = "cannot write to output folder"
        else:
            out.write_text("an earlier result")
            out.chmod(0o444)
            message = "write-protected"
    _no_sampling(monkeypatch)
    before = sorted(p.name for p in tmp_path.rglob("*"))
    try:
        rc = main(["run", str(cfg), "-o", str(out)])
    finally:
        if case == "read_only_folder":
            folder.chmod(0o755)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith("tolsim run: error: ")
    assert message in err and str(out.parent if "folder" in message else out) in err
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # no probe, no partial


def test_checkpoint_interval_flag(tmp_path, capsys, monkeypatch):
    from tolsim.cli import build_parser
    from tolsim.study.execution import runner

    args = build_parser(["run"]).parse_args(["run"])
    assert args.checkpoint_interval == 30.0
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    help_text = capsys.readouterr().out
    assert "--checkpoint-interval SECONDS" in help_text and "Default: 30" in help_text
    assert "every 30 s" in help_text  # the description says it too
    saves = []
    save = runner._save_checkpoint
    monkeypatch.setattr(runner, "_save_checkpoint", lambda *a: saves.append(1) or save(*a))
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL.replace("samples = 100", "samples = 1000\nblock_size = 100"))
    out = tmp_path / "s.nc"
    common = ["run", str(cfg), "-o", str(out), "--chunk-blocks", "1", "--quiet"]
    assert main(common + ["--checkpoint-interval", "0"]) == 0
    assert len(saves) == 9  # after every chunk but the last
    saves.clear()
    assert main(common + ["--checkpoint-interval", "1e6"]) == 0
    assert saves == []
    assert main(common + ["--checkpoint-interval", "-1"]) == 2
    err = capsys.readouterr().err
    assert "--checkpoint-interval" in err and err.count("\n") == 1


def test_resume_says_what_was_resumed(tmp_path, capsys):
    from tolsim.io.config import load_config
    from tolsim.study.execution.runner import StudyInterrupted, run_study

    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL.replace("samples = 100", "samples = 1000\nblock_size = 100"))
    out = tmp_path / "s.nc"
    with pytest.raises(StudyInterrupted):
        run_study(load_config(cfg), chunk_blocks=1, checkpoint_path=f"{out}.partial",
                  max_blocks=3)
    assert main(["run", str(cfg), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"resumed from {out}.partial: 300 of 1 000 assemblies already done" in err


def _compiling_once(monkeypatch):
    """Make the next study compile a new kernel, as with a cold Numba cache."""
    import numba

    from tolsim.study.execution import chunks

    run_chunk = chunks.run_chunk
    pending = [True]

    def compile_then_run(*args, **kwargs):
        if pending:
            pending.clear()
            numba.njit(lambda x: x + 1)(1)  # new code: Numba compiles
        return run_chunk(*args, **kwargs)

    monkeypatch.setattr(chunks, "run_chunk", compile_then_run)


def test_compiling_is_said_once_and_only_when_it_happens(tmp_path, capsys, monkeypatch):
    from tolsim.study.execution.runner import COMPILING_MESSAGE

    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    argv = ["run", str(cfg), "-o", str(tmp_path / "s.nc"), "--chunk-blocks", "1"]
    assert main(argv) == 0  # kernels loaded from the cache (or compiled: not checked here)
    capsys.readouterr()
    _compiling_once(monkeypatch)
    assert main(argv) == 0
    assert capsys.readouterr().err.count(COMPILING_MESSAGE) == 1
    assert main(argv) == 0  # nothing left to compile: nothing said
    assert COMPILING_MESSAGE not in capsys.readouterr().err
    _compiling_once(monkeypatch)
    assert main(argv + ["--quiet"]) == 0
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_cold_kernel_cache_is_said_in_a_real_process(tmp_path):
    # An empty Numba cache (NUMBA_CACHE_DIR): the first run compiles and says so, the second
    # loads the kernels from the cache and says nothing. (Small tolerances: no ball needs the
    # full model, whose kernels would double the compile time.)
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL.replace("std_deg = 0.5", "std_deg = 0.02"))
    env = dict(os.environ, PYTHONWARNINGS="ignore", NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    argv = [sys.executable, "-m", "tolsim", "run", str(cfg), "-o", str(tmp_path / "s.nc")]
    first = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=600)
    assert first.returncode == 0, first.stderr
    assert "compiling kernels (first run only)" in first.stderr
    second = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=600)
    assert second.returncode == 0, second.stderr
    assert "compiling" not in second.stderr


def test_target_ci_width_stops_and_says_so(tmp_path, capsys):
    from test_study import STUDY

    text = (STUDY.replace("{static}", "paired").replace("{propagation}", "constant")
            .replace("{sampling}", "random"))
    cfg = tmp_path / "t.toml"
    cfg.write_text(text)
    out = tmp_path / "t.nc"
    assert main(["run", str(cfg), "-o", str(out), "--target-ci-width", "0.05"]) == 0
    text_out = capsys.readouterr().out
    ds = read_result(out)
    n_done = int(ds.n_assemblies)
    assert 0 < n_done < 3000 and ds.attrs["samples"] == n_done
    assert ds.attrs["samples_maximum"] == 3000 and ds.attrs["target_ci_width"] == "0.05"
    assert f"stopped at the target after {n_done:,} of at most 3,000".replace(",", " ") in \
        text_out
    assert "--target-ci-width 0.05" in ds.attrs["history"]
    # the same study run to that fixed size gives the same data
    fixed = tmp_path / "fixed.nc"
    assert main(["run", str(cfg), "-o", str(fixed), "--samples", str(n_done), "--quiet"]) == 0
    a = read_result(fixed)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, ds[name].values, err_msg=name)


@pytest.mark.parametrize("value", ["0", "abc", "-5%", "1.5"])
def test_bad_target_ci_width(tmp_path, capsys, value):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    out = tmp_path / "s.nc"
    assert main(["run", str(cfg), "-o", str(out), f"--target-ci-width={value}"]) == 2
    err = capsys.readouterr().err
    assert "--target-ci-width" in err and "10%" in err and err.count("\n") == 1
    assert sorted(os.listdir(tmp_path)) == ["s.toml"]
    if value == "1.5":  # the reason: an absolute width is below 1
        assert "must be in (0, 1) when absolute" in err


def test_summary_warns_when_balls_are_unresolved(tmp_path, capsys, monkeypatch):
    # Issue 17, item 4: a study in which many balls have no epsilon must say so next to its
    # ppm and Cpk. The third ball (rho = 1.5) loses a contact in every assembly (paired
    # forces put one flank in tension); with the solved model's fallback taken away (a ball
    # no model can solve) a third of the balls and every train without a certain contact are
    # unresolved.
    from pathlib import Path

    import tolsim.study.pipeline.evaluate as evaluate

    monkeypatch.setattr(evaluate, "STATIC_FALLBACK", {})
    text = (Path(__file__).resolve().parents[2] / "configs" / "known_answer.toml").read_text()
    text = text.replace("balls = 2", "balls = 3").replace(
        "side_force_ratio = [-0.6, 0.6]", "side_force_ratio = [-0.6, 0.6, 1.5]")
    cfg = tmp_path / "lossy.toml"
    cfg.write_text(text)
    assert main(["run", str(cfg), "-o", str(tmp_path / "l.nc"), "--samples", "2048"]) == 0
    out = capsys.readouterr().out
    assert "warning: 2048 of 6144 balls (33 %) have no epsilon from any model" in out
    assert "are unresolved; P(contact) is known only within the bounds" in out


def test_summary_splits_the_spot_checks_by_stratum(tmp_path, capsys):
    # The spot checks are stratified (half near the spec limit on |epsilon|); the summary
    # gives the agreement with the full model per stratum, not only mixed.
    import re

    assert main(["run", "-o", str(tmp_path / "d.nc"), "--samples", "2048"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("spot checks"))
    m = re.search(r"uniform (\d+): RMS [\d.]+ %, max [\d.]+ %; near the limit (\d+): RMS", line)
    assert m and int(m.group(1)) + int(m.group(2)) == 20, line


def test_contacts_without_a_time_are_said_so(tmp_path, capsys):
    # The packaged default at a nominal contact angle of 3 deg: most balls have a contact angle
    # at or below 0 (no model describes them), and every train known to touch has such a ball,
    # so no contact has a time. The run completes (its spot checks hold balls outside the full
    # model: it once stopped there with "puts a contact angle outside (0, 90) deg") and the
    # summary says the time is not known instead of "earliest inf s, median nan s".
    import tolsim

    text = (Path(tolsim.__file__).parent / "data" / "default.toml").read_text()
    line = next(x for x in text.splitlines() if x.startswith("nominal_contact_angle_deg"))
    cfg = tmp_path / "flat.toml"
    cfg.write_text(text.replace(line, "nominal_contact_angle_deg = 3.0", 1))
    assert main(["run", str(cfg), "-o", str(tmp_path / "f.nc"), "--samples", "2048"]) == 0
    out = capsys.readouterr().out
    assert "time to first contact: not known (no train with every ball resolved touches)" in out
    assert "earliest inf" not in out and "median nan" not in out
    assert "outside the full model (a contact angle outside (0, 90) deg" in out
    # the report's glance table says the same (it showed "inf s / nan s")
    from tolsim.reports.study.shared import glance_rows

    rows = dict((label, text) for label, text, _ in glance_rows(read_result(tmp_path / "f.nc")))
    assert rows["earliest / median first contact (given contact)"] == (
        "not known (no train with every ball resolved touches)")


def test_a_sweep_says_which_points_have_unresolved_trains(tmp_path, capsys):
    # A nominal contact angle of 1e-30 deg: no ball of any point has a model, so every P is
    # NaN. The table printed bare NaNs; it now gives each point's unresolved trains and a
    # warning that says what P is over and where the bounds are.
    cfg = _variant(tmp_path, "sweep_preload.toml", [("nominal_contact_angle_deg = 45.0",
                                                     "nominal_contact_angle_deg = 1e-30")])
    assert main(["run", str(cfg), "-o", str(tmp_path / "s.nc"), "--samples", "64"]) == 0
    out = capsys.readouterr().out
    rows = [x for x in out.splitlines() if x.rstrip().endswith("64 of 64")]
    assert len(rows) == 10 and "unresolved" in out.splitlines()[1]
    assert "at 10 of 10 points no train has a known outcome (nan)" in out


# --- issue 26, item 4: a study that cannot answer is refused after its first block ------------
def _variant(tmp_path, name, replacements):
    """A packaged config with ``(old, new)`` text replacements, written to tmp_path."""
    text = (CONFIGS / name).read_text()
    for old, new in replacements:
        assert old in text, old
        text = text.replace(old, new, 1)
    cfg = tmp_path / name
    cfg.write_text(text)
    return cfg


# The two cases of issue 26 printed nan, "(1e+02 %)" and "ball -1" with exit 0. Since issue 25
# the full model answers a ball with two loaded contacts (two-point, epsilon = 0), so a yaw
# moment of 1500 N m with solved statics and the -50 kN pull on the four-point carriage are
# answered now (tests below), and so are the paired statics under 1500 N m, which put a
# contact of every ball in tension: the solved model answers those balls
# (test_paired_forces_in_tension_are_answered_by_the_solved_model). What cannot answer: a
# carriage that truly lifts off (two upward-facing tracks pulled up: the carriage solver's
# LIFT_OFF, the same verdict as tolsim carriage's).
LIFT_OFF = [("orientation_deg = 90.0", "orientation_deg = 0.0"),
            ("orientation_deg = -90.0", "orientation_deg = 0.0"),
            ("vertical_N = 300.0 ", "vertical_N = -300.0 "),
            ("preload_oversize_um = 2.0 ", "preload_oversize_um = 0.0 "),
            ("samples = 2000", "samples = 300")]
PAIRED_IN_TENSION = [("yaw_moment_N_m = 15.0", "yaw_moment_N_m = 1500.0"),
                     ('static_model = "solved"', 'static_model = "paired"'),
                     ("samples = 20000", "samples = 3000"),
                     ("sensitivity_samples = 1024", "sensitivity_samples = 0")]
UNANSWERABLE = [
    pytest.param("yaw_moment_tolerances.toml", PAIRED_IN_TENSION,
                 ["no train of the first block (1,024 assemblies) resolves",
                  "loss of contact: 10,240 of 10,240 balls",
                  "change loads.normal_load_N = 200.0, loads.yaw_moment_N_m = 1500.0"],
                 id="paired_yaw_moment_1500_N_m_without_fallback"),
    pytest.param("carriage_preload.toml", LIFT_OFF,
                 ["the carriage lifts off the rail under the load",
                  "no assembly of the first block (300 assemblies) resolves",
                  "change carriage.load.vertical_N = -300.0",
                  "carriage.preload_oversize_um = 0.0"],
                 id="lift_off_vertical_minus_300_N"),
]


@pytest.mark.parametrize("name, replacements, words", UNANSWERABLE)
def test_study_that_cannot_answer_is_refused(tmp_path, capsys, monkeypatch, name,
                                             replacements, words):
    import tolsim.study.execution.runner as runner
    import tolsim.study.pipeline.evaluate as evaluate

    # a ball no model can solve: the paired model's fallback to the solved one taken away
    monkeypatch.setattr(evaluate, "STATIC_FALLBACK", {})
    cfg = _variant(tmp_path, name, replacements)
    chunks = []

    def recording(config, chunk_list, *args, **kwargs):  # the chunks as they are consumed
        for chunk, result in zip(chunk_list, runner_prefetched(config, chunk_list, *args,
                                                               **kwargs), strict=False):
            chunks.append(chunk)
            yield result

    runner_prefetched = runner.prefetched
    monkeypatch.setattr(runner, "prefetched", recording)
    rc = main(["run", str(cfg), "-o", str(tmp_path / "out.nc")])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith(f"tolsim run: error: {cfg}: the study "
                                                    "cannot answer: "), err
    for word in words:
        assert word in err, (word, err)
    assert chunks == [[0]]  # decided on the first block, alone, before any other ran
    assert sorted(os.listdir(tmp_path)) == [name]  # no result, no checkpoint


def test_lift_off_is_the_carriage_solvers_verdict_in_run_and_carriage(tmp_path, capsys):
    # tolsim run and tolsim carriage share one classification of lift-off: the carriage
    # solver's (CarriageStatus.LIFT_OFF), through solve_config_carriage; both say the same.
    cfg = _variant(tmp_path, "carriage_preload.toml", LIFT_OFF)
    assert main(["carriage", str(cfg)]) == 2
    said = capsys.readouterr().err.strip()
    message = said.split(f"{cfg}: ", 1)[1]
    assert "lifts off" in message
    assert main(["run", str(cfg), "-o", str(tmp_path / "out.nc")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"the study cannot answer: {message}" in err, err
    assert "carriage.load.vertical_N = -300.0" in err
    assert sorted(os.listdir(tmp_path)) == ["carriage_preload.toml"]


def test_paired_forces_in_tension_are_answered_by_the_solved_model(tmp_path, capsys):
    # Under a yaw moment of 1500 N m the paired forces put a contact of every ball in tension
    # (|N_x| >= N_y: loss of contact, which stopped the study before). Each such ball goes to
    # the solved model (STATIC_FALLBACK), which finds it on two or three contacts; every ball
    # is answered, and the summary says how many the solved model answered.
    cfg = _variant(tmp_path, "yaw_moment_tolerances.toml", PAIRED_IN_TENSION)
    assert main(["run", str(cfg), "-o", str(tmp_path / "out.nc"), "--samples", "64"]) == 0
    out = capsys.readouterr().out
    assert "unresolved 0 (static not converged 0, loss of contact 0, full model failed 0)" in out
    assert ("640 of 640 balls answered by the solved static model: the paired model left "
            "them without balance") in out
    ds = read_result(tmp_path / "out.nc")
    assert int(ds.n_balls_static_fallback) == 640 and int(ds.n_balls_valid) == 640


def test_a_pulling_load_held_by_the_upper_flanks_is_not_lift_off(tmp_path, capsys):
    # -50 kN pulls the carriage up; its four-point-contact balls hold it on their upper
    # flanks (two contacts each, the others open): the carriage solver converges, and since
    # issue 25 the study answers every ball (two-point, epsilon = 0 exactly: issue 25's
    # "exactly two-point ball rolls at v/2"), nothing unresolved, exit 0.
    cfg = _variant(tmp_path, "carriage_preload.toml",
                   [("vertical_N = 300.0", "vertical_N = -50000.0"),
                    ("samples = 2000", "samples = 300")])
    assert main(["carriage", str(cfg)]) == 0
    out = capsys.readouterr().out
    assert "converged: yes" in out
    assert len(re.findall(r"(?m)^.*\bopen\b.*2-point \(full\)$", out)) == 24
    assert main(["run", str(cfg), "-o", str(tmp_path / "out.nc")]) == 0
    out = capsys.readouterr().out
    assert "unresolved 0 (" in out and "balls by regime: 2-point 7,200" in out


def test_summary_bounds_the_quantiles_outside_the_histogram(tmp_path, capsys):
    # A quantile of epsilon beyond the histogram's range is unknown (NaN in the file): the
    # summary gives the bound the histogram does give and names the key that widens it. At
    # std 2 deg, epsilon spreads over about +-2 % (the paper's 0.754 % at 2 deg, rho -0.6),
    # far beyond a +-0.5 % range.
    cfg = tmp_path / "wide.toml"
    cfg.write_text(MINIMAL.replace("std_deg = 0.5", "std_deg = 2.0")
                   + "velocity_deviation_range_percent = [-0.5, 0.5]\n")
    assert main(["run", str(cfg), "-o", str(tmp_path / "w.nc")]) == 0
    out = capsys.readouterr().out
    ds = read_result(tmp_path / "w.nc")
    q = ds.velocity_deviation_quantile.sel(quantile=[0.01, 0.99]).values
    assert np.all(np.isnan(q))
    assert "1-99 % < -0.500 % .. > +0.500 %" in out
    under, over = int(ds.velocity_deviation_underflow), int(ds.velocity_deviation_overflow)
    assert (f"{under + over} of 200 valid balls ({under} below, {over} above) outside the "
            "epsilon histogram's range -0.5 .. +0.5 %") in out
    assert "widen study.velocity_deviation_range_percent" in out
    assert "nan" not in out.split("P(contact")[0]


def test_a_train_of_one_ball_has_a_summary_and_a_report(tmp_path, capsys):
    # One ball: epsilon only, no pair, so no gap closure in the linear stack-up (its critical
    # pair is -1); the summary and the report say so instead of failing on the file.
    cfg = tmp_path / "one.toml"
    cfg.write_text(MINIMAL.replace("balls = 2", "balls = 1").replace(
        "side_force_ratio = [-0.6, 0.6]", "side_force_ratio = [0.6]"))
    out = tmp_path / "one.nc"
    assert main(["run", str(cfg), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert int(read_result(out).critical_pair) == -1
    assert "no gap closure (a train of one ball has no pair)" in text
    assert main(["report", str(out), "-o", str(tmp_path / "rep")]) == 0
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "a train of one ball has no pair" in html


def test_a_carriage_with_clearance_and_no_load_says_it_has_no_epsilon(tmp_path, capsys):
    # 5 um of clearance and no load: no ball carries a load, so no ball has an epsilon of its
    # own (every one is counted unloaded). The summary and the report say so instead of
    # printing NaN for epsilon's statistics and for rho = N_x / N_y = 0 / 0.
    cfg = _variant(tmp_path, "carriage_preload.toml",
                   [("preload_oversize_um = 2.0 ", "preload_oversize_um = -5.0 "),
                    ("vertical_N = 300.0 ", "vertical_N = 0.0 "),
                    ("pitch_moment_N_m = 2.0 ", "pitch_moment_N_m = 0.0 "),
                    ("samples = 2000", "samples = 20")])
    out = tmp_path / "free.nc"
    assert main(["run", str(cfg), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    ds = read_result(out)
    assert int(ds.n_balls_valid) == 0 and int(ds.n_balls_unloaded) == int(ds.n_balls) == 480
    assert ("epsilon: no ball with an epsilon: all 480 balls unloaded (no loaded contact: no "
            "velocity of their own)") in text
    nan = re.compile(r"(?<![A-Za-z])nan(?![A-Za-z])", re.IGNORECASE)  # not "Provenance"
    assert not nan.search(text)
    assert main(["report", str(out), "-o", str(tmp_path / "rep")]) == 0
    html = re.sub(r"data:[^\"']*", "", (tmp_path / "rep" / "report.html").read_text())
    assert "no ball with an ε: every ball unloaded" in html  # (figures' base64 removed)
    assert not nan.search(html), nan.search(html)


def test_summary_probabilities_near_one_and_a_frequent_event():
    # an edge-case audit: importance sampling's P(contact) = 0.99992 (lower end of its
    # interval) read "1" at 3 significant digits; the plain run's 200 contacts of 200
    # (Clopper-Pearson lower end 0.025^(1/200) = 0.98172) show the event is not rare, and the
    # summary says so
    from tolsim.cli.run import RARE_COUNT, _plain_run_line, _probability

    assert _probability(0.9999151133427296) == "0.99991511"
    assert _probability(1.0) == "1" and _probability(0.000526) == "0.000526"
    line = _plain_run_line(200, 200, "trains")
    assert "P = 1, 95 % CI [0.98172, 1] (Clopper-Pearson)" in line
    assert "not a rare event" in line
    assert "not a rare event" not in _plain_run_line(RARE_COUNT - 1, 20000, "trains")


def test_summary_says_how_many_samples_were_saved(tmp_path, capsys):
    # --save-samples beyond the run's assemblies saves them all, and the summary says so
    cfg = tmp_path / "m.toml"
    cfg.write_text(MINIMAL)
    out = tmp_path / "m.nc"
    assert main(["run", str(cfg), "-o", str(out), "--samples", "30", "--save-samples",
                 "500"]) == 0
    text = capsys.readouterr().out
    assert read_result(out).sizes["sample"] == 30
    assert ("saved samples: the inputs and outputs of the first 30 assemblies (dimension "
            "'sample'); --save-samples 500 asked for more than the run has") in text
