"""``tolsim run``: output file, summary, exit codes, bad configs, resuming."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from test_config import BAD, MINIMAL

from tolsim.cli import main
from tolsim.io.netcdf import read_result

CONFIGS = Path(__file__).resolve().parent.parent / "configs"


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


def test_overrides_and_quiet(tmp_path, capsys):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    out = tmp_path / "s.nc"
    rc = main(["run", str(cfg), "-o", str(out), "--samples", "50", "--seed", "3", "--quiet"])
    assert rc == 0
    assert capsys.readouterr().out == ""
    ds = read_result(out)
    assert int(ds.n_assemblies) == 50 and ds.attrs["seed"] == 3
    assert ds.attrs["config"] == MINIMAL


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
    (["--workers", "x"], "positive integer"),
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
    from tolsim.study.runner import StudyInterrupted, run_study

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
