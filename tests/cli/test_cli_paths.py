"""An empty path is refused by every command before any work (session 28's flag fuzz).

``-o "$OUT"`` with OUT unset hands a command an empty path. ``tolsim run -o ''`` then ran the
study and wrote ``tolsim-result.nc`` to the current folder, ``tolsim report -o ''`` wrote its
report next to the result file, ``tolsim compare -o ''`` read both files, drew its figures and
only then failed with ``cannot write to :`` after three progress lines, and an empty CONFIG
ended in ``: cannot read config: IsADirectoryError``. Each must be one line naming the
argument, exit code 2, and nothing written.
"""

import os
from pathlib import Path

import pytest

from tolsim.cli import main

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
PRELOAD = str(CONFIGS / "carriage_preload.toml")
RESULT = "result.nc"  # a stand-in: the empty argument is refused before any file is read

CASES = [
    (["run", ""], "argument CONFIG"),
    (["run", PRELOAD, "-o", ""], "argument -o/--output"),
    (["run", PRELOAD, "--output", " "], "argument -o/--output"),
    (["report", ""], "argument RESULTS.nc"),
    (["report", RESULT, "-o", ""], "argument -o/--out"),
    (["compare", RESULT, "", "-o", "out"], "argument RESULTS.nc"),
    (["compare", RESULT, RESULT, "-o", ""], "argument -o/--out"),
    (["paper", "--out", ""], "argument --out"),
    (["carriage", ""], "argument CONFIG"),
    (["carriage", PRELOAD, "--plot", ""], "argument --plot"),
    (["carriage", PRELOAD, "--circuit-figure", ""], "argument --circuit-figure"),
    (["allocate", "", "-o", "out"], "argument CONFIG"),
    (["allocate", PRELOAD, "-o", ""], "argument -o/--out"),
    (["warmup", ""], "argument CONFIG"),
]


@pytest.mark.parametrize("argv, name", CASES, ids=[" ".join(c[0][:1] + [c[1]]) for c in CASES])
def test_an_empty_path_is_one_line_and_writes_nothing(argv, name, tmp_path, monkeypatch,
                                                      capsys):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert f"error: {name}: expected a path, got '" in err, err
    assert captured.out == ""
    assert os.listdir(tmp_path) == []
