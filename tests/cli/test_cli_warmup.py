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


def test_warmup_of_a_sweep_runs_each_point(tmp_path, monkeypatch):
    # `tolsim warmup configs/*.toml` (its --help's example) takes the sweep configs too; a
    # sweep's fast path raised "has a [sweep] of 9 points" in the pool (a traceback). Each
    # point now runs one block (a 2-point sweep of the known-answer study: 2 runs).
    import tolsim.cli.warmup as warmup
    import tolsim.study.execution.runner as runner

    cfg = tmp_path / "sweep.toml"
    cfg.write_text((CONFIGS / "known_answer.toml").read_text()
                   + '\n[sweep]\n"loads.normal_load_N" = [150.0, 250.0]\n')
    seen = []
    monkeypatch.setattr(runner, "run_study", lambda config, **kw: seen.append(config))
    warmup._fast_path(str(cfg))
    assert [c.loads.normal_load[0] for c in seen] == [150.0, 250.0]
    assert all(c.study.samples == c.study.block_size and c.sweep is None for c in seen)
