"""The README's numbers are measured, not remembered (issue 26, item 9).

Seeded study outputs are recomputed here (CI-sized runs) and looked up in the README text.
Machine-dependent timings cannot be checked on a CI machine: they all live in one table of the
README that ``benchmarks/readme_timings.py`` writes and re-checks (each row within its stated
interval); here, that no timing stands outside it and that its rows read their benchmarks.
"""

import csv
import importlib.util
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tolsim.io.config import load_config, parse_config
from tolsim.physics.geometry import TABLE1, paired_forces
from tolsim.physics.velocity.analytic import eq24
from tolsim.physics.velocity.full import full
from tolsim.study.execution.runner import run_study
from tolsim.study.statistics.intervals import clopper_pearson_interval

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")
CONFIGS = ROOT / "configs"


def paragraphs():
    """README paragraphs (blank-line separated; a fenced code block is one paragraph)."""
    return [p for p in re.split(r"\n\s*\n", README) if p.strip()]


def paragraph_with(pattern):
    found = [p for p in paragraphs() if re.search(pattern, p)]
    assert found, f"README has no paragraph matching {pattern!r}"
    return found[0]


def quick(config, samples):
    """``config`` at ``samples`` assemblies, without Sobol' indices and spot checks."""
    c = config.with_overrides(samples=samples)
    return replace(c, study=replace(c.study, sensitivity_samples=0, spot_checks=0))


# -- timings: one generated table, each row measured by its benchmark ----------------------
#: A throughput, a per-item time or a speed-up: machine-dependent (a time "of model time" is a
#: seeded result, not a timing).
TIMING = re.compile(r"\d\s*(?:M |k )?(?:balls|solves|assemblies|evaluations)/s"
                    r"|\d\s*[µm]s\b(?! of model time)"
                    r"|\d(?:\.\d+)?(?:x|×)(?=[\s,;)])|\d(?:\.\d+)?x (?:NumPy|the|a)\b"
                    r"|\d\s*times (?:more|fewer|dearer|faster|slower)")


def timings_module():
    spec = importlib.util.spec_from_file_location("readme_timings",
                                                  ROOT / "benchmarks" / "readme_timings.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_no_timing_outside_the_generated_table():
    # every machine-dependent number is a row of the table that benchmarks/readme_timings.py
    # writes and checks; the test suite's own run time names .ci/run, which measures it
    timings = timings_module()
    begin, end = README.index(timings.BEGIN), README.index(timings.END)
    outside = README[:begin] + README[end:]
    stray = [outside[max(0, m.start() - 40):m.end() + 10].replace("\n", " ")
             for m in TIMING.finditer(outside)]
    assert not stray, f"timings outside the table of benchmarks/readme_timings.py: {stray}"


def test_the_table_has_every_row_with_its_benchmark_and_interval():
    timings = timings_module()
    table = timings.readme_table(README)
    assert list(table) == [row.key for row in timings.ROWS]
    for row in timings.ROWS:
        assert (ROOT / "benchmarks" / row.command[0]).is_file(), row.command
        value, tolerance = table[row.key]
        assert value > 0 and tolerance == pytest.approx(row.tolerance)
        line = next(x for x in README.splitlines() if x.startswith(f"| {row.what} |"))
        assert f"`python benchmarks/{' '.join(row.command)}`" in line


def test_an_only_run_keeps_the_other_scripts_re_measured_before():
    # the stamp of a --write --only run names every script re-measured since the full run,
    # each with its own date: the scripts run now in a new clause, the others kept
    timings = timings_module()
    head = "Measured with `python benchmarks/readme_timings.py --write` on 2026-11-26 (x)."
    line = (f"{head} Rows of bench_a.py, bench_b.py re-measured on 2026-11-27 (`--only`, "
            "load average 1.0 at the start).")
    text = f"{timings.BEGIN}\n\n{line}\n\n{timings.END}"
    assert timings._stamp(text) == line
    assert timings._stamp(text, ["bench_b.py"]) == (
        f"{head} Rows of bench_a.py re-measured on 2026-11-27 (`--only`, load average 1.0 "
        "at the start).")
    assert timings._stamp(text, ["bench_a.py", "bench_b.py"]) == head
    assert timings._stamp(f"{timings.BEGIN}\n{head}\n{timings.END}", ["bench_a.py"]) == head


def test_the_rows_read_the_benchmarks_output():
    # a CI-sized run of the two cheapest benchmarks: every row they feed finds its line (a
    # benchmark whose output changed fails here, not only in --check on the idle machine)
    timings = timings_module()
    for script, args in [("bench_analytic.py", ["--balls", "20000", "--repeat", "1"]),
                         ("bench_static.py", ["--balls", "20000", "--baseline-balls", "5",
                                              "--repeat", "1"])]:
        out = timings.run((script, *args), None)  # as --check runs it
        rows = [row for row in timings.ROWS if row.command[0] == script]
        assert rows
        for row in rows:
            assert np.isfinite(row.measured(out))


def test_the_cold_start_benchmark_is_named_with_the_first_run_time():
    p = paragraph_with(r"first run\b")
    assert "benchmarks/bench_cold_start.py" in p and "tolsim warmup" in p


# -- the paper's pair (Sec. 3.2): deterministic --------------------------------------------
def test_paper_pair_contact_times_and_velocity_deviations():
    # Table 2 case (a): theta = 2 deg, rho = -0.6 (ball 1) and +0.6 (ball 2), N_y = 200 N;
    # gap 0.1 R_B = 0.5 mm at v = 10 mm/s (Sec. 3.2): t = gap / ((eps_1 - eps_2) v / 2).
    dbeta = np.deg2rad([-2.0, 2.0, 0.0, 0.0])
    f1, f2 = paired_forces(-120.0, 200.0), paired_forces(120.0, 200.0)
    e_formula = eq24(dbeta, f1, TABLE1).velocity_deviation
    e_full = float(full(dbeta, f1, TABLE1).velocity_deviation)
    e_full2 = float(full(dbeta, f2, TABLE1).velocity_deviation)
    t_formula = 0.5e-3 / (2 * float(e_formula) * 0.01 / 2)
    t_full = 0.5e-3 / ((e_full - e_full2) * 0.01 / 2)
    # README (Studies table and "What contact costs"): 6.63 s, 6.34 s, eps = +-0.789 %
    assert f"contact at {t_formula:.2f} s with the formula" in README
    assert f"{t_full:.2f} s with the full model" in README
    assert f"ε = ±{100 * e_full:.3f} % from the full model" in README
    assert e_full2 == pytest.approx(-e_full, abs=1e-12)  # the mirror image: the ± above
    # and why fig9.png of `tolsim paper` differs: its full model takes the solved static
    # contact, eps_1 = +0.835 %, eps_2 = -0.754 % (reports/paper/README.md)
    t_fig9 = 0.5e-3 / ((0.00835 + 0.00754) * 0.01 / 2)
    assert f"fig9.png` shows {t_fig9:.2f} s" in README


# -- seeded studies (CI-sized) --------------------------------------------------------------
def test_default_study_resolve_count():
    # "re-solves 60 of its 10^6 balls": the count is seeded (the time is not, and is named
    # with its benchmark above)
    acc = run_study(quick(load_config(), 100_000)).statistics
    m = re.search(r"default study\s+re-solves (\d+) of its 10\^6 balls", README)
    assert m and int(m.group(1)) == int(acc.n_resolved_full)


def test_carriage_preload_sizes_and_light_class():
    text = (CONFIGS / "carriage_preload.toml").read_text()
    config = parse_config(text, str(CONFIGS / "carriage_preload.toml"))
    p = paragraph_with(r"For `configs/carriage_preload.toml`")
    # the config's own size, and the size of the table's runs, are both stated
    assert f"{config.study.samples:,}".replace(",", " ") + " assemblies as configured" in p
    m = re.search(r"--samples (\d+)", p)
    assert m, "the table's sample count is named as the option that produced it"
    # light class (the config as given), along the track (a carriage's default), at the
    # table's size: the README's P(contact) and 95 % interval to the printed digits
    acc = run_study(quick(config, int(m.group(1)))).statistics
    prob, low, high = acc.contact_probability()
    assert f"| light | 2 µm | 23 N | 419 N/µm | 0.47 | {prob:.3f} [{low:.3f}, {high:.3f}] |" \
        in README


def test_along_track_probability_names_its_command():
    p = paragraph_with(r"\(along_track\)")
    assert "benchmarks/bench_carriage.py --skip-batch --along-track" in p
    m = re.search(r"--along-track (\d+)", p)
    n = int(m.group(1))
    # the two P(contact) are of the same n assemblies (one run of the benchmark); the
    # intervals are the Clopper-Pearson 95 % ones of k of n
    for value, low, high in re.findall(r"(0\.\d+) \[(0\.\d+), (0\.\d+)\]", p):
        k = round(float(value) * n)
        lo, hi = clopper_pearson_interval(k, n)
        assert (f"{lo:.3f}", f"{hi:.3f}") == (low, high)


def test_rare_contact_plain_run_beside_subset():
    # The plain run of configs/rare_contact.toml (20 000 assemblies, seeded) finds k
    # contacts; the README says k, its interval and why it differs from subset's estimate.
    config = load_config(CONFIGS / "rare_contact.toml")
    c = quick(config, config.study.samples)
    c = replace(c, study=replace(c.study, estimator="monte_carlo"))
    acc = run_study(c).statistics
    k, n = int(acc.n_contact), int(acc.n_assemblies)
    _, low, high = acc.contact_probability()
    p = paragraph_with(r"plain run of `configs/rare_contact.toml`")
    assert f"{k} of {n:,}".replace(",", " ") in p
    assert f"[{100 * low:.3f} %, {100 * high:.3f} %]" in p


def test_preload_sweep_numbers_are_those_of_its_figure():
    # The preload sweep paragraph quotes the sweep the README's figure was made from
    # (reports/examples/sweep_preload, `tolsim report` of `tolsim run configs/sweep_preload.toml
    # --samples 20000`): each quoted P(contact) [95 % interval] is that point's value in the
    # report's points.csv to the printed digits, and the figure exists.
    p = paragraph_with(r"^P\(contact\) per assembly: ")
    assert (ROOT / "reports/examples/sweep_preload.png").is_file()
    with open(ROOT / "reports/examples/sweep_preload/points.csv", newline="") as f:
        rows = {float(r["carriage.preload_oversize_um"]): r for r in csv.DictReader(f)}
    assert all(int(r["n_assemblies"]) == 20000 and int(r["n_assemblies_unresolved"]) == 0
               for r in rows.values())
    quoted = re.findall(r"(0(?:\.\d+)?) \[(0(?:\.\d+)?), (0\.\d+)\] (?:from|at) (−?\d)", p)
    assert len(quoted) == 7
    for value, low, high, point in quoted:
        r = rows[float(point.replace("−", "-"))]
        digits = len(value.split(".")[1]) if "." in value else 0
        for text, key in ((value, "contact_probability"), (low, "contact_probability_ci_lower"),
                          (high, "contact_probability_ci_upper")):
            d = len(text.split(".")[1]) if "." in text else digits
            assert f"{float(r[key]):.{d}f}" == text, (point, key)
