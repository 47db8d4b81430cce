"""Every value of two packaged configs, mutated one at a time: ``tolsim run`` runs it (exit 0)
or refuses it in one line that names the key (exit 2), with no traceback and no file.

A CI-sized version of session 27's fuzz of the configs (every leaf of seven configs deleted or
set to 0, -1, +-1e300, 1e-30, nan, inf, a string, "", true, an array or a table: 2 970 runs
of ``tolsim run`` and 1 404 of ``tolsim carriage``). That fuzz found a truncated normal whose
std was 1e300 times its band: NaN draws, RuntimeWarnings and an error naming no key (now
refused at load, tests/io/test_config.py). The mutations here are the ones that reach the
most code: the key deleted, 0, -1, 1e300, nan and a string.
"""

import re
from pathlib import Path

import pytest

import tolsim
from tolsim.cli import main

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
DEFAULT = Path(tolsim.__file__).parent / "data" / "default.toml"
#: A ``key = value`` line of a table (not a header, a comment or a continuation).
ASSIGNMENT = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.+?)\s*(#.*)?$")
MUTATIONS = (None, "0", "-1", "1e300", "nan", '"abc"')


def _mutants(path):
    """(table.key, mutation, text) for every assignment line of the config at ``path``."""
    lines = path.read_text().splitlines()
    table = ""
    for i, line in enumerate(lines):
        header = re.match(r"^\[\[?([^\]]+)\]\]?", line)
        if header:
            table = header.group(1)
            continue
        m = ASSIGNMENT.match(line)
        if not m:
            continue
        for value in MUTATIONS:
            changed = lines[:i] + ([] if value is None else [f"{m.group(1)} = {value}"]) \
                + lines[i + 1:]
            yield f"{table}.{m.group(1)}", value, "\n".join(changed) + "\n"


@pytest.mark.parametrize("name", ["default", "carriage_preload.toml"])
def test_every_mutated_value_runs_or_is_refused_in_one_line(name, tmp_path, capsys):
    path = DEFAULT if name == "default" else CONFIGS / name
    cfg, out = tmp_path / "c.toml", tmp_path / "o.nc"
    problems, runs = [], 0
    for key, value, text in _mutants(path):
        cfg.write_text(text)
        code = main(["run", str(cfg), "-o", str(out), "--samples", "8", "--quiet", "--fresh"])
        runs += 1
        err = capsys.readouterr().err
        errors = [x for x in err.splitlines() if x.strip() and ": warning: " not in x]
        leaf = key.rsplit(".", 1)[-1]
        if code == 0:
            ok = out.exists() and not errors
            out.unlink(missing_ok=True)
        else:
            ok = (code == 2 and len(errors) == 1 and not out.exists()
                  and (leaf in errors[0] or key.split(".")[0] in errors[0]))
        if not ok or "Traceback" in err:
            problems.append(f"{key} = {value}: exit {code}: {err.strip()[-300:]}")
    assert runs > 100
    assert not problems, "\n".join(problems)
