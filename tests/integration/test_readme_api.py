"""The Python API of the README runs as written (issue 17), and ``import tolsim`` stays light."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

import tolsim

ROOT = Path(__file__).resolve().parents[2]


def api_blocks():
    """The ```python blocks of README.md under its ``## Python API`` heading."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    match = re.search(r"^## Python API\n(.*?)(?=^## |\Z)", text, re.M | re.S)
    assert match, "README.md has no '## Python API' section"
    return re.findall(r"^```python\n(.*?)^```", match.group(1), re.M | re.S)


def test_readme_python_api_example_runs(tmp_path, monkeypatch, capsys):
    blocks = api_blocks()
    assert blocks
    monkeypatch.chdir(tmp_path)  # the example writes study.nc
    for code in blocks:
        exec(compile(code, "README.md (Python API)", "exec"), {"__name__": "__readme__"})
    out = capsys.readouterr().out
    assert re.search(r"P\(contact\) = 0\.\d{4}, 95 % interval \[0\.\d{4}, 0\.\d{4}\]", out)
    assert re.search(r"ball \d: RSS of ε 0\.\d{3} %, worst case ±\d\.\d{3} %", out)
    # Lin2018 Table 2, case (a), ball 1: formula +0.75 % (ours +0.754 %); our full model with
    # the paired forces +0.789 % (reports/paper/README.md)
    assert "ε = +0.754 % (analytic), +0.789 % (full model)" in out
    assert tolsim.read_result(tmp_path / "study.nc").sizes["ball"] == 10


@pytest.mark.parametrize("name", sorted(tolsim.API))
def test_api_names_resolve(name):
    assert callable(getattr(tolsim, name)) or name == "TABLE1"
    assert name in dir(tolsim) and name in tolsim.__all__


def test_unknown_attribute_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        tolsim.nothing  # noqa: B018


def test_import_tolsim_is_light():
    # the API is imported on first use: no Numba compilation or xarray on `import tolsim`
    code = ("import sys, tolsim; heavy = [m for m in ('numba', 'xarray', 'matplotlib', "
            "'tolsim.study.execution.runner') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
