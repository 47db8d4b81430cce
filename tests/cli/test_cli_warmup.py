"""``tolsim warmup``: compiles the kernels of the studies ahead of a first run (issue 26)."""

from pathlib import Path

import pytest

from tolsim.cli import main

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.mark.slow  # spawns two processes (a few seconds each on a warm cache)
def test_warmup_runs_the_given_studies_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["warmup", str(CONFIGS / "paper_case_study.toml"), "--jobs", "1"]) == 0
    err = capsys.readouterr().err
    assert "tolsim warmup: kernels of 1 study compiled and cached" in err
    assert list(tmp_path.iterdir()) == []  # its studies' files went to a temporary folder


def test_warmup_bad_config_is_one_line_before_any_work(tmp_path, capsys):
    assert main(["warmup", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tolsim warmup: error:") and "missing.toml" in err
    assert len(err.splitlines()) == 1
    assert main(["warmup", "--jobs", "0"]) == 2
