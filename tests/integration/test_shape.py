"""The package's shape (issue 22): layers that import one way, no imports hidden in functions.

The contracts are declared in ``pyproject.toml`` (``[tool.importlinter]``: physics < study <
io < reports < cli, and the stages inside study; physics without xarray, pandas, matplotlib,
tomllib); ruff's PLC0415 forbids imports inside the package's functions except where a
``# noqa: PLC0415`` marks a deliberate lazy import (CLI start-up, the top-level API). Both run
here, so ``python -m pytest`` (and CI) fails on a new cycle, an upward import or a hidden one.
"""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
LINT = ("import sys; from importlinter.cli import lint_imports; "
        "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")


def _lint_imports(root: Path) -> subprocess.CompletedProcess:
    # cwd first on sys.path: the checkout's tolsim, not an installed copy
    return subprocess.run([sys.executable, "-c", LINT], cwd=root, capture_output=True,
                          text=True, timeout=300)


def test_import_contracts_hold():
    pytest.importorskip("importlinter")
    done = _lint_imports(ROOT)
    assert done.returncode == 0, done.stdout + done.stderr


def test_import_contracts_catch_an_upward_import(tmp_path):
    # the same contracts on a copy of the package in which physics imports reports: broken
    pytest.importorskip("importlinter")
    shutil.copytree(ROOT / "tolsim", tmp_path / "tolsim",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    geometry = tmp_path / "tolsim" / "physics" / "geometry.py"
    geometry.write_text(geometry.read_text() + "\nimport tolsim.reports.style  # noqa\n")
    done = _lint_imports(tmp_path)
    assert done.returncode != 0
    assert "tolsim.physics.geometry -> tolsim.reports.style" in done.stdout


def test_no_imports_hidden_in_functions():
    pytest.importorskip("ruff")
    done = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--quiet",
                           "--select", "PLC0415", "tolsim"], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
