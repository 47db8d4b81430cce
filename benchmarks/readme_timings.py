"""The README's timings, measured by the benchmarks that produce them (issue 26, item 9).

Every machine-dependent number the README quotes (throughputs, per-item times, speed-ups and
ratios against a baseline) lives in one generated table of the README's Performance section,
between the markers ``<!-- timings -->`` and ``<!-- /timings -->``. Each row names the
benchmark command that measures it and the interval a re-run must fall in.

    python benchmarks/readme_timings.py --check    # re-run the benchmarks, compare each row
    python benchmarks/readme_timings.py --write    # re-run them and rewrite the table
    python benchmarks/readme_timings.py --check --only bench_full.py

``--check`` exits 1 when a row falls outside its interval or a benchmark's output no longer
has the line the row reads (the benchmark changed: fix :data:`ROWS`). Run it on an idle
machine: a busy one measures the load, not tolsim. Each benchmark runs once per invocation,
whatever the number of rows it feeds.
"""

import argparse
import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BEGIN, END = "<!-- timings -->", "<!-- /timings -->"
#: A re-run's accepted deviation from the README's value, relative (timings of an idle
#: 2-core machine vary 10-20 % from run to run).
TIMING = 0.3
#: For numbers of a seeded benchmark (model evaluations): they do not depend on the machine.
SEEDED = 0.01


@dataclass(frozen=True)
class Row:
    """One README number: what it is, the benchmark run that measures it and where in its
    output (``pattern``'s first group), shown as ``value`` in ``unit``."""

    key: str
    what: str
    command: tuple
    pattern: str
    unit: str
    digits: int = 0
    scale: float = 1.0
    reciprocal: bool = False  # the README shows 1 / (value * scale)
    tolerance: float = TIMING

    def measured(self, output: str) -> float:
        """The row's value in the benchmark's ``output`` (ValueError if it has no such
        line)."""
        found = re.search(self.pattern, output, re.M)
        if found is None:
            raise ValueError(f"{self.key}: no line matching {self.pattern!r} in the output of "
                             f"{' '.join(self.command)}")
        value = float(found.group(1).replace(",", "")) * self.scale
        return 1.0 / value if self.reciprocal else value

    def shown(self, value: float) -> str:
        """``value`` as the README shows it (spaces as thousands separators)."""
        digits = max(self.digits, 0)  # negative: rounded to tens, hundreds, ...
        text = f"{round(value, self.digits):,.{digits}f}".replace(",", " ")
        return f"{text}{self.unit}" if self.unit == "×" else f"{text} {self.unit}"


ANALYTIC = ("bench_analytic.py",)
STATIC = ("bench_static.py",)
FULL = ("bench_full.py",)
STUDY = ("bench_study.py",)
DASK = ("bench_dask.py", "--repeats", "3")
CARRIAGE = ("bench_carriage.py",)
ALONG = ("bench_carriage.py", "--skip-batch", "--along-track", "2000")
ALONG_STUDY = ("bench_study.py", "--along-track")
_ALONG = r"^\s+{} \({}\):.*?"
COLD = ("bench_cold_start.py",)
RARE = ("bench_rare_events.py",)
SWEEP = ("bench_sweep.py",)
_STUDY_1 = r"^solved static, workers 1: 1\.00e\+0{} balls"

#: The README's timings, in the order of its table.
ROWS = (
    Row("eq24", "`eq24`, 10^7 balls", ANALYTIC,
        r"^eq24 \(numba\)\s+\S+\s+([\d,]+)", "M balls/s", 0, 1e-6),
    Row("eq24_numpy", "`eq24` against its NumPy version", ANALYTIC,
        r"eq24 speed-up over NumPy: ([\d.]+)x", "×", 1),
    Row("analytic", "`analytic` (Eqs. 17, 18, 21), 10^7 balls", ANALYTIC,
        r"^analytic \(numba\)\s+\S+\s+([\d,]+)", "M balls/s", 1, 1e-6),
    Row("analytic_numpy", "`analytic` against a NumPy 4x4 solve", ANALYTIC,
        r"^analytic \(numba\)\s+\S+\s+\S+\s+([\d.]+)x", "×", 1),
    Row("static", "static contact (solved), 10^6 balls, 2 threads", STATIC,
        r"solve_static \(elastic\)\s+([\d.]+) M balls/s on", "M balls/s", 1),
    Row("static_vectorised", "its vectorised four-point path against the scalar Newton",
        STATIC, r"the vectorised path is ([\d.]+)x faster", "×", 1),
    Row("full", "full model (planar), random balls (Δβ within ±2°, ρ within ±0.6), 2 threads", FULL,
        r"^\s+planar\s+2 thread\(s\):\s+(\d+) solves/s", "solves/s", -3),
    Row("full_call", "full model, median single-ball call", FULL,
        r"median single-ball call[^:]*: ([\d.]+) ms", "ms", 2),
    Row("regimes_1", "full model, random regime-A and regime-B balls, 1 thread", FULL,
        r"^\s+A and B\s+1 thread\(s\):\s+(\d+) balls/s", "balls/s", -3),
    Row("regimes_2", "the same, 2 threads (target: 200 000)", FULL,
        r"^\s+A and B\s+2 thread\(s\):\s+(\d+) balls/s", "balls/s", -3),
    Row("study_1e6", "whole study pipeline, 10^6 balls, one process", STUDY,
        _STUDY_1.format(6) + r"\s+\S+ s\s+([\d.]+) M balls/s", "M balls/s", 1),
    Row("study_1e7", "whole study pipeline, 10^7 balls, one process", STUDY,
        _STUDY_1.format(7) + r"\s+\S+ s\s+([\d.]+) M balls/s", "M balls/s", 1),
    Row("study_numpy", "the same against the NumPy baseline of the run", STUDY,
        _STUDY_1.format(7) + r".*?\(([\d.]+)x baseline\)", "×", 1),
    Row("study_peak", "its peak memory", STUDY,
        _STUDY_1.format(7) + r".*?peak RSS (\d+) MiB", "MiB", -1),
    Row("study_workers", "whole study pipeline, 10^7 balls, 2 worker processes", STUDY,
        r"^solved static, workers 2: 1\.00e\+07 balls\s+\S+ s\s+([\d.]+) M balls/s",
        "M balls/s", 1),
    Row("resolve_default", "default study: re-solving its balls outside `analytic`'s validity",
        STUDY, r"^\s+default: .*? in ([\d.]+) s \(", "s", 2),
    Row("known_answer", "known-answer study at σ = 2° (91 % of its balls re-solved)", STUDY,
        r"^\s+known_answer: \S+ balls\s+\S+ s\s+([\d.]+) M balls/s", "balls/s", -3, 1e6),
    Row("dask_process", "dask: 10^7 balls in this process (best of 3)", DASK,
        r"^\s*in-process:\s+([\d.]+) s", "s", 2),
    Row("dask_1", "dask: a LocalCluster of 1 worker, against this process", DASK,
        r"^\s+local:1:.*?([\d.]+)x the", "×", 2),
    Row("dask_2", "dask: a LocalCluster of 2 workers, against this process", DASK,
        r"^\s+local:2:.*?([\d.]+)x the", "×", 2),
    Row("dask_merge", "dask: the client unpickles and merges a block of 10 240 balls", DASK,
        r"(\d+) us to unpickle", "µs", 0),
    Row("carriage", "carriage statics, 10^5 assemblies of 24 balls, 2 threads", CARRIAGE,
        r"^m = 100000\s+([\d,]+) assemblies/s", "µs per assembly", 1, 1e-6, True),
    Row("along_track", "carriage study along the track against constant, per assembly", ALONG,
        r"along_track is ([\d,.]+)x dearer", "×", 0),
    Row("sweep", "a sweep of 10 points x 10^5 assemblies (10^7 balls), one file", SWEEP,
        r"^\s+sweep \(tolsim run, one file\)\s+([\d.]+) s", "s", 1),
    Row("sweep_separate", "the sweep against ten separate runs", SWEEP,
        r"sweep / separate = ([\d.]+)", "×", 2),
    Row("sweep_free", "the sweep against ten separate runs without sampling (target: < 2)",
        SWEEP, r"sweep / sampling-free separate = ([\d.]+)", "×", 1),
    Row("along_free",
        "free balls along the track (`whatif_along_track.toml` as shipped: paired static model, "
        "automatic step: 20 steps)",
        ALONG_STUDY, _ALONG.format(r"whatif_along_track\.toml", "free balls")
        + r"along_track\s+\S+ s\s+(\d+) balls/s", "balls/s", -2),
    Row("along_free_ratio", "free balls: cost per ball along the track / constant (target: ≤ 5)",
        ALONG_STUDY, _ALONG.format(r"whatif_along_track\.toml", "free balls")
        + r"cost per ball\s+([\d.]+)x", "×", 0),
    Row("along_carriage", "`carriage_preload.toml` along the track (automatic step: 10 steps)",
        ALONG_STUDY,
        _ALONG.format(r"carriage_preload\.toml", "carriage")
        + r"along_track\s+\S+ s\s+(\d+) balls/s", "balls/s", -2),
    Row("along_carriage_ratio", "carriage: cost per ball along the track / constant (target: ≤ 5)",
        ALONG_STUDY, _ALONG.format(r"carriage_preload\.toml", "carriage")
        + r"cost per ball\s+([\d.]+)x", "×", 0),
    Row("along_circuit_ratio", "the same with a default `[carriage.circuit]`", ALONG_STUDY,
        _ALONG.format(r"carriage_preload\.toml", r"carriage with \[carriage\.circuit\]")
        + r"cost per ball\s+([\d.]+)x", "×", 0),
    Row("along_carriage_solves",
        "carriage: its carriage solves alone (one per step and assembly) against the whole "
        "constant study, per assembly", ALONG_STUDY,
        _ALONG.format(r"carriage_preload\.toml", "carriage")
        + r".*\n\s+carriage solves per assembly.*?solves alone cost ([\d.]+)x", "×", 1),
    Row("along_carriage_evaluations",
        "carriage: its evaluations alone (errors at the balls, carriage solve, epsilon; one per "
        "step and assembly) against the whole constant study, per assembly", ALONG_STUDY,
        _ALONG.format(r"carriage_preload\.toml", "carriage")
        + r".*\n.*\n\s+its evaluations alone.*? cost ([\d.]+)x", "×", 1),
    Row("along_circuit_evaluations",
        "the same with a default `[carriage.circuit]` (the ratio if its ring steps and the "
        "rest of the integrator cost nothing)", ALONG_STUDY,
        _ALONG.format(r"carriage_preload\.toml", r"carriage with \[carriage\.circuit\]")
        + r".*\n.*\n\s+its evaluations alone.*? cost ([\d.]+)x", "×", 1),
    Row("cold", "default study on a cold kernel cache against a warm one (CPU)", COLD,
        r"cold / warm: \S+ \(wall\), ([\d.]+) \(CPU\)", "×", 1),
    Row("warmed", "the same after `tolsim warmup` (wall)", COLD,
        r"after tolsim warmup / warm: ([\d.]+)", "×", 2),
    Row("rare_subset", "subset simulation at P = 1e-5: fewer evaluations than plain MC", RARE,
        r"^\s+subset\s+1e-05: ([\d,]+)x cheaper", "×", 0, tolerance=SEEDED),
    Row("rare_importance", "importance sampling at P = 1e-5: fewer evaluations than plain MC",
        RARE, r"^\s+importance\s+1e-05: ([\d,]+)x cheaper", "×", -3, tolerance=SEEDED),
)


def readme_table(text: str) -> dict:
    """{row key: (value, tolerance)} of the README's generated table."""
    try:
        block = text[text.index(BEGIN):text.index(END)]
    except ValueError as exc:
        raise SystemExit(f"README.md has no {BEGIN} ... {END} table") from exc
    keys = {row.what: row.key for row in ROWS}
    table = {}
    for line in block.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 4 or cells[0] not in keys:
            continue
        value = float(re.match(r"[\d .]+", cells[1]).group(0).replace(" ", ""))
        tolerance = float(re.search(r"±\s*([\d.]+) %", cells[2]).group(1)) / 100
        table[keys[cells[0]]] = (value, tolerance)
    return table


#: What an ``--only`` run adds to the stamp: its scripts, its date and the rest of its clause.
_ONLY_CLAUSE = re.compile(r" Rows of (.+?) re-measured on (\S+) (\(.*?\)\.)")


def _stamp(text: str, only=()) -> str:
    """The README table's stamp line: a full ``--write`` run's, with the clauses of earlier
    ``--only`` runs, less the scripts in ``only`` (re-measured now; a clause left without
    scripts goes)."""
    block = text[text.index(BEGIN) + len(BEGIN):text.index(END)]
    line = next(x for x in block.splitlines() if x.startswith("Measured with"))
    head = line.split(" Rows of ")[0]
    for scripts, date, rest in _ONLY_CLAUSE.findall(line):
        kept = [x for x in scripts.split(", ") if x not in set(only)]
        if kept:
            head += f" Rows of {', '.join(kept)} re-measured on {date} {rest}"
    return head


def render(values: dict, stamp: str) -> str:
    """The README's table of ``values`` {row key: measured value}."""
    lines = [BEGIN, "", stamp, "",
             "| measured | value | accepted on a re-run | command |", "|---|---|---|---|"]
    for row in ROWS:
        kind = "seeded" if row.tolerance == SEEDED else "timing"
        lines.append(f"| {row.what} | {row.shown(values[row.key])} | "
                     f"±{100 * row.tolerance:g} % ({kind}) | "
                     f"`python benchmarks/{' '.join(row.command)}` |")
    return "\n".join([*lines, "", END])


def run(command: tuple, keep: Path | None) -> str:
    """The output of one benchmark run (its own process, from the repository's root); with
    ``keep``, read from / saved to a file there (``--outputs``)."""
    saved = keep / ("_".join(command).replace("-", "").replace(".py", "") + ".txt") \
        if keep else None
    if saved is not None and saved.is_file():
        print(f"reading {saved}", flush=True)
        return saved.read_text(encoding="utf-8")
    print(f"running python benchmarks/{' '.join(command)} ...", flush=True)
    # the repository's tolsim, not another one installed in the interpreter's site-packages
    path = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / command[0]), *command[1:]],
                         capture_output=True, text=True, cwd=ROOT, check=False,
                         env=dict(os.environ, PYTHONPATH=path))
    if out.returncode:
        raise SystemExit(f"benchmarks/{' '.join(command)} failed:\n{out.stderr[-2000:]}")
    if saved is not None:
        saved.write_text(out.stdout, encoding="utf-8")
    return out.stdout


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--check", action="store_true",
                      help="re-run the benchmarks and compare each README row with its interval")
    what.add_argument("--write", action="store_true",
                      help="re-run the benchmarks and rewrite the README's table")
    p.add_argument("--outputs", type=Path, default=None, metavar="DIR",
                   help="keep each benchmark's output in DIR, and read it from there when it "
                        "is already there (a second --check or --write runs nothing)")
    p.add_argument("--only", nargs="+", metavar="SCRIPT", default=None,
                   help="only the rows of these benchmark scripts (e.g. bench_full.py)")
    args = p.parse_args(argv)
    rows = [r for r in ROWS if args.only is None or r.command[0] in args.only]
    if not rows:
        p.error(f"--only: no row is measured by {' '.join(args.only)}")
    load = os.getloadavg()[0]
    print(f"load average at the start: {load:.2f} ({os.cpu_count()} cores)")
    if args.outputs is not None:
        args.outputs.mkdir(parents=True, exist_ok=True)
    outputs = {}
    for row in rows:
        if row.command not in outputs:
            outputs[row.command] = run(row.command, args.outputs)
    values, unread = {}, []
    for row in rows:
        try:
            values[row.key] = row.measured(outputs[row.command])
        except ValueError as exc:
            unread.append(str(exc))
    if unread:  # a benchmark's output changed: the rows must follow it
        print("\n".join(unread))
        return 1
    text = README.read_text(encoding="utf-8")
    table = readme_table(text)
    failed = 0
    for row in rows:
        value = values[row.key]
        old, tolerance = table.get(row.key, (float("nan"), row.tolerance))
        ok = abs(value - old) <= tolerance * abs(old)
        failed += not ok
        print(f"{'ok  ' if ok else 'FAIL'} {row.what}: README {row.shown(old)}, measured "
              f"{row.shown(value)} ({value / old:.2f}x; accepted ±{100 * tolerance:g} %)")
    if args.write:
        if args.only:  # rows not re-run keep the README's values
            values = {**{k: v for k, (v, _) in table.items()}, **values}
        stamp = (f"Measured with `python benchmarks/readme_timings.py --write` on "
                 f"{time.strftime('%Y-%m-%d')}, on the 2-core development machine (load "
                 f"average {load:.1f} at the start). `--check` re-runs every benchmark and "
                 "compares.")
        if args.only:  # say which rows this run measured; the others keep their stamp's
            previous = _stamp(text, args.only)
            stamp = (f"{previous} Rows of {', '.join(sorted(set(args.only)))} re-measured "
                     f"on {time.strftime('%Y-%m-%d')} (`--only`, load average {load:.1f} at "
                     "the start).")
        start, end = text.index(BEGIN), text.index(END) + len(END)
        README.write_text(text[:start] + render(values, stamp) + text[end:], encoding="utf-8")
        print(f"wrote the table of {README}")
        return 0
    print(f"{len(rows) - failed} of {len(rows)} rows within their interval")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
