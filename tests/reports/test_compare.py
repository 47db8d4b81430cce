"""``tolsim compare`` (issue 14, part 2): the difference intervals, the statistics of a run, the
config diff, a comparison of real runs, and the one-line errors."""

import base64
import csv
import math
import os
import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from scipy import stats

from tolsim.cli import main
from tolsim.reports.compare import (
    ABSENT,
    CSV_COLUMNS,
    PAIRING_INDEPENDENT,
    PAIRING_SHARED,
    VELOCITY_DEVIATION_LEVELS,
    compare_datasets,
    config_differences,
    flatten_config,
    run_labels,
    run_statistics,
    shares_random_numbers,
)
from tolsim.study.statistics.intervals import (
    ClusterMoments,
    assembly_totals,
    cluster_mean_and_std,
    histogram_quantile_interval,
    mover_difference,
    newcombe_difference,
    welch_difference,
    wilson_interval,
)

CONFIGS = os.path.join(os.path.dirname(__file__), "..", "..", "configs")


# --------------------------------------------------------------------------------------------
# Interval functions
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("k1, n1, k2, n2, difference, lower, upper", [
    # Newcombe, Stat. Med. 17 (1998) 873-890, Table II, contrasts (a) and (b), method 10
    # (score interval without continuity correction), printed to 4 decimals. The same values
    # are checked in the test suite of the R package propint (ci.two.indep.props).
    # ERRATA (task note): the note gave 56/70 - 48/80 as "0.1833, 0.0336 to 0.3183"; the
    # difference is 0.8 - 0.6 = 0.2 exactly, and the paper's method 10 interval is
    # 0.0524 to 0.3339.
    (56, 70, 48, 80, 0.2, 0.0524, 0.3339),
    (9, 10, 3, 10, 0.6, 0.1705, 0.8090),
])
def test_newcombe1998_table2_method10(k1, n1, k2, n2, difference, lower, upper):
    d, lo, hi = newcombe_difference(k1, n1, k2, n2)
    assert_allclose(d, difference, rtol=1e-12)
    assert_allclose([lo, hi], [lower, upper], atol=5e-5)


@given(st.integers(1, 400), st.integers(1, 400), st.data())
def test_newcombe_properties(n1, n2, data):
    # contains the estimate, lies within [-1, 1], and swapping the runs mirrors it
    k1 = data.draw(st.integers(0, n1))
    k2 = data.draw(st.integers(0, n2))
    d, lo, hi = newcombe_difference(k1, n1, k2, n2)
    assert -1.0 <= lo <= d <= hi <= 1.0
    d_swap, lo_swap, hi_swap = newcombe_difference(k2, n2, k1, n1)
    assert_allclose([d_swap, lo_swap, hi_swap], [-d, -hi, -lo], atol=1e-12)


def test_newcombe_is_the_mover_of_wilson_intervals():
    # Zou & Donner (2008), Stat. Med. 27:1693: Newcombe's method 10 is the MOVER applied
    # to the Wilson intervals
    l1, u1 = wilson_interval(17, 120)
    l2, u2 = wilson_interval(9, 150)
    assert_allclose(newcombe_difference(17, 120, 9, 150),
                    mover_difference(17 / 120, l1, u1, 9 / 150, l2, u2), rtol=1e-12)
    assert all(math.isnan(x) for x in newcombe_difference(3, 10, 0, 0)[1:])


def test_mover_of_symmetric_intervals_is_wald():
    # symmetric intervals t -+ z se: the MOVER gives d -+ z sqrt(se1^2 + se2^2)
    z = stats.norm.ppf(0.975)
    d, lo, hi = mover_difference(1.3, 1.3 - z * 0.04, 1.3 + z * 0.04,
                                 1.2, 1.2 - z * 0.03, 1.2 + z * 0.03)
    assert_allclose([d, lo, hi], [0.1, 0.1 - z * 0.05, 0.1 + z * 0.05], rtol=1e-12)


def test_welch_difference_twin_scipy(rng):
    # Twin: scipy.stats.ttest_ind(equal_var=False), Welch's t with the Welch-Satterthwaite df
    x = rng.normal(1.0, 0.5, size=23)
    y = rng.normal(0.7, 1.4, size=61)
    ref = stats.ttest_ind(x, y, equal_var=False)
    ci = ref.confidence_interval(0.95)
    d, lo, hi, df = welch_difference(x.mean(), x.std(ddof=1) / np.sqrt(x.size), x.size - 1,
                                     y.mean(), y.std(ddof=1) / np.sqrt(y.size), y.size - 1)
    assert_allclose(d, x.mean() - y.mean(), rtol=1e-12)
    assert_allclose([lo, hi], [ci.low, ci.high], rtol=1e-10)
    assert_allclose(df, ref.df, rtol=1e-10)


def test_welch_difference_limits():
    # known standard errors (df = inf): the normal interval; no error at all: exact
    z = stats.norm.ppf(0.975)
    d, lo, hi, df = welch_difference(2.0, 0.3, np.inf, 1.0, 0.4, np.inf)
    assert_allclose([lo, hi], [1.0 - 0.5 * z, 1.0 + 0.5 * z], rtol=1e-12)
    assert df == np.inf
    assert welch_difference(2.0, 0.0, 5, 1.5, 0.0, 7)[:3] == (0.5, 0.5, 0.5)


def test_cluster_mean_and_std_one_ball_per_assembly(rng):
    # Assemblies of one ball are independent values: the delta-method standard errors are
    # then the textbook ones, s / sqrt(n) for the mean and, for sigma (divisor N),
    # sd((x - mean)^2) / sqrt(n) / (2 sigma)
    x = rng.gamma(2.0, 1e-3, size=500)
    moments = ClusterMoments.from_totals(assembly_totals(x[:, None], limit=1.0))
    mean, se_mean, std, se_std = cluster_mean_and_std(moments)
    sigma = np.sqrt(np.mean((x - x.mean()) ** 2))
    assert_allclose([mean, std], [x.mean(), sigma], rtol=1e-10)
    assert_allclose(se_mean, x.std(ddof=1) / np.sqrt(x.size), rtol=1e-10)
    assert_allclose(se_std, np.std((x - x.mean()) ** 2, ddof=1) / np.sqrt(x.size)
                    / (2 * sigma), rtol=1e-8)


def test_cluster_mean_se_counts_assemblies_not_balls(rng):
    # ten balls that all share their assembly's value carry the information of one value:
    # the standard error is that of the assembly means, not sqrt(10) smaller
    values = rng.normal(0.0, 1e-3, size=400)
    eps = np.repeat(values[:, None], 10, axis=1)
    _, se_mean, _, _ = cluster_mean_and_std(
        ClusterMoments.from_totals(assembly_totals(eps, limit=1.0)))
    assert_allclose(se_mean, values.std(ddof=1) / np.sqrt(values.size), rtol=1e-10)


def test_histogram_quantile_interval_uniform():
    # 1000 values, one per bin of width 1e-3 on [0, 1]: the histogram's distribution function
    # is the identity, so the interval is Wilson's interval of the level, moved out to the bin
    # edges (multiples of 1e-3)
    counts = np.ones(1000, dtype=np.int64)
    edges = np.linspace(0.0, 1.0, 1001)
    lo, hi = histogram_quantile_interval(counts, edges, 0.5, 100)
    wl, wu = wilson_interval(50, 100)
    assert_allclose([lo, hi], [math.floor(wl * 1000) / 1000, math.ceil(wu * 1000) / 1000],
                    atol=1e-12)
    # fewer effective trials: wider
    lo_10, hi_10 = histogram_quantile_interval(counts, edges, 0.5, 10)
    assert lo_10 < lo and hi_10 > hi
    # a lower end below the smallest value is not bounded by the data
    lo_tail, hi_tail = histogram_quantile_interval(counts, edges, 0.001, 1000)
    assert math.isnan(lo_tail) and hi_tail > 0.001


def test_histogram_quantile_interval_coverage_of_a_normal_median(rng):
    # independent normal values on a fine histogram: the interval of the median covers 0 in
    # about 95 % of 400 repeats (binomial sd 1.1 %: 92-98 % is a 2.7 sd band)
    edges = np.linspace(-5, 5, 2001)
    hits = 0
    for _ in range(400):
        counts, _ = np.histogram(rng.standard_normal(300), edges)
        lo, hi = histogram_quantile_interval(counts, edges, 0.5, 300)
        hits += lo <= 0.0 <= hi
    assert 0.92 <= hits / 400 <= 0.98


# --------------------------------------------------------------------------------------------
# Config differences and pairing
# --------------------------------------------------------------------------------------------
REFERENCE_CONFIG = """
[loads]
normal_load_N = 200.0
yaw_moment_N_m = 15.0
[tolerances.top_rotation]
distribution = "cpk"
low_deg = -0.3
[study]
seed = 1
samples = 2000
cpk_minimum = 1.33
"""


def test_config_differences_changed_and_one_sided_keys():
    other = (REFERENCE_CONFIG.replace("yaw_moment_N_m = 15.0", "yaw_moment_N_m = 25.0")
             .replace("cpk_minimum = 1.33\n", "")
             .replace("samples = 2000", "samples = 2000.0")  # the same number
             + "[[carriage.track]]\nx_mm = -20.0\n")
    rows, unreadable = config_differences([REFERENCE_CONFIG, other, "not = [toml"])
    found = {row.key: row.values for row in rows}
    assert unreadable == [2]
    assert found["loads.yaw_moment_N_m"] == (15.0, 25.0, ABSENT)  # changed
    assert found["study.cpk_minimum"] == (1.33, ABSENT, ABSENT)  # only in the reference
    assert found["carriage.track[0].x_mm"] == (ABSENT, -20.0, ABSENT)  # only in the other
    assert set(found) == {"loads.yaw_moment_N_m", "study.cpk_minimum",
                          "carriage.track[0].x_mm"}
    row = next(r for r in rows if r.key == "study.cpk_minimum")
    assert row.texts == ("1.33", "—", "—")


def test_flatten_config_dotted_keys():
    flat = flatten_config({"a": {"b": 1, "c": {"d": "x"}}, "e": [1, 2],
                           "f": [{"g": True}, {"g": False}], "odd key": {"h.i": 2}})
    assert flat == {"a.b": 1, "a.c.d": "x", "e": [1, 2], "f[0].g": True, "f[1].g": False,
                    '"odd key"."h.i"': 2}


def test_shares_random_numbers_and_labels():
    a = {"seed": 1, "block_size": 1024, "sampling": "random"}
    assert shares_random_numbers(a, dict(a))
    assert not shares_random_numbers(a, {**a, "seed": 2})
    assert not shares_random_numbers(a, {**a, "sampling": "sobol"})
    assert not shares_random_numbers(a, {"seed": 1})  # unknown: not shared
    assert run_labels(["x/a.nc", "y/a.nc", "b.nc"]) == ["a (1)", "a (2)", "b"]


# --------------------------------------------------------------------------------------------
# Real runs
# --------------------------------------------------------------------------------------------
def _run(text, samples, seed, out, path):
    from tolsim.io.config import parse_config
    from tolsim.io.netcdf import write_result
    from tolsim.study.execution.runner import run_study

    config = parse_config(text, path).with_overrides(samples=samples, seed=seed)
    write_result(run_study(config), out, history="test_compare")
    return out


@pytest.fixture(scope="module")
def yaw_runs(tmp_path_factory):
    """Three small runs of the yaw-moment study: a (seed 1), b (seed 2: independent of a) and
    c (seed 1, common random numbers with a; yaw moment 25 N m instead of 15, and no
    cpk_minimum)."""
    path = os.path.join(CONFIGS, "yaw_moment_tolerances.toml")
    with open(path, encoding="utf-8") as fh:
        text = fh.read().replace("sensitivity_samples = 1024", "sensitivity_samples = 0")
    changed = re.sub(r"\ncpk_minimum = [^\n]*", "", text.replace(
        "yaw_moment_N_m = 15.0", "yaw_moment_N_m = 25.0"))
    assert changed.count("cpk_minimum") == 0 and "yaw_moment_N_m = 25.0" in changed
    folder = tmp_path_factory.mktemp("compare")
    return (_run(text, 2000, 1, folder / "a.nc", path),
            _run(text, 2000, 2, folder / "b.nc", path),
            _run(changed, 2000, 1, folder / "c.nc", path))


#: The statistics of the yaw-moment study (a limit on |epsilon|, no carriage, no unresolved).
YAW_STATISTICS = (
    ["contact_probability", "velocity_deviation_mean", "velocity_deviation_std"]
    + [f"velocity_deviation_quantile_{q:g}" for q in VELOCITY_DEVIATION_LEVELS]
    + ["velocity_deviation_out_of_spec_fraction", "velocity_deviation_cpk"]
    + [f"time_to_contact_quantile_{q:g}" for q in (0.1, 0.5, 0.9)])


def test_compare_cli_html_and_csv(yaw_runs, tmp_path, capsys):
    import xarray as xr

    a, b, c = yaw_runs
    out = tmp_path / "cmp"
    assert main(["compare", str(a), str(b), str(c), "-o", str(out), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    # CSV: one row per statistic and run, in that order
    with open(out / "compare.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0]) == CSV_COLUMNS
    assert [(r["statistic"], r["run"]) for r in rows] == [
        (s, run) for s in YAW_STATISTICS for run in ("a", "b", "c")]
    by = {(r["statistic"], r["run"]): r for r in rows}
    files = {}
    for label, path in zip("abc", yaw_runs, strict=True):
        with xr.open_dataset(path) as ds:
            files[label] = ds.load()
    for label, ds in files.items():
        row = by[("contact_probability", label)]
        assert float(row["estimate"]) == float(ds.contact_probability)
        assert float(row["ci_lower"]) == float(ds.contact_probability_ci_lower)
        assert float(row["ci_upper"]) == float(ds.contact_probability_ci_upper)
        assert row["units"] == "1" and row["interval"] == "Clopper-Pearson"
        assert float(by[("velocity_deviation_cpk", label)]["estimate"]) == float(
            ds.velocity_deviation_cpk)
        assert by[("time_to_contact_quantile_0.5", label)]["units"] == "s"
    for r in rows:  # every interval holds its estimate
        if r["ci_lower"] and r["ci_upper"]:
            assert float(r["ci_lower"]) <= float(r["estimate"]) <= float(r["ci_upper"])
        if r["difference_ci_lower"] and r["difference_ci_upper"]:
            assert (float(r["difference_ci_lower"]) <= float(r["difference"])
                    <= float(r["difference_ci_upper"]))
    # the reference has no difference; the others: run - reference with Newcombe's interval
    assert all(by[(s, "a")]["difference"] == "" for s in YAW_STATISTICS)
    for label in "bc":
        row = by[("contact_probability", label)]
        ref, run = files["a"], files[label]
        expected = newcombe_difference(int(run.n_contact), int(run.n_assemblies),
                                       int(ref.n_contact), int(ref.n_assemblies))
        assert_allclose([float(row[k]) for k in ("difference", "difference_ci_lower",
                                                 "difference_ci_upper")], expected, rtol=1e-12)
    # b has another seed (independent), c shares a's random numbers
    assert by[("contact_probability", "b")]["difference_interval"] == (
        f"Newcombe hybrid score (method 10); {PAIRING_INDEPENDENT}")
    assert by[("contact_probability", "c")]["difference_interval"] == (
        f"Newcombe hybrid score (method 10); {PAIRING_SHARED}")
    assert by[("velocity_deviation_mean", "b")]["difference_interval"].startswith(
        "Welch-Satterthwaite")

    # HTML: self-contained, the figures embedded byte for byte
    page = (out / "compare.html").read_text(encoding="utf-8")
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert pngs == ["contact_probability.png", "survival.png", "velocity_deviation.png"]
    uris = re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", page)
    assert {base64.b64decode(u) for u in uris} == {(out / p).read_bytes() for p in pngs}
    assert "http://" not in page and "https://" not in page
    assert PAIRING_SHARED in page and "Newcombe" in page
    # the config keys that differ: a changed one, one only in a and b, and the seed
    for key, values in (("loads.yaw_moment_N_m", ("15.0", "15.0", "25.0")),
                        ("study.cpk_minimum", ("1.33", "1.33", "—")),
                        ("study.seed", ("1", "2", "1"))):
        cells = "".join(f"<td><code>{v}</code></td>" for v in values)
        assert f"<td class='key'>{key}</td>{cells}" in page
    assert "loads.normal_load_N" not in page  # the same in every run


def test_compare_carriage_runs_and_bounds(tmp_path):
    # two small carriage studies (a track dimension): the stiffness rows, the nominal one
    # exact; then the same Datasets with unresolved assemblies: the bounds of P(contact)
    from tolsim.io.netcdf import read_result
    from tolsim.reports.compare import compare_runs

    path = os.path.join(CONFIGS, "carriage_preload.toml")
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    a = _run(text, 64, 1, tmp_path / "car1.nc", path)
    b = _run(text, 64, 2, tmp_path / "car2.nc", path)
    result = compare_runs([a, b], tmp_path / "out")
    comparison = result.comparison
    names = comparison.names
    assert "carriage_translational_stiffness_mean_u_y" in names
    assert "carriage_rotational_stiffness_nominal_pitch" in names
    ref, run = comparison.runs
    stat = run.statistics["carriage_translational_stiffness_mean_u_y"]
    assert stat.units == "N m-1" and stat.ci_lower < stat.estimate < stat.ci_upper
    nominal = comparison.differences[("carriage_rotational_stiffness_nominal_pitch", "car2")]
    assert nominal.estimate == nominal.ci_lower == nominal.ci_upper == 0.0  # same config
    assert nominal.interval == "exact"
    description = comparison.statistic("contact_probability").description
    assert "P(contact within the stroke) per assembly" in description
    assert "over the assemblies whose outcome is known" in description  # not "assemblys"
    with open(result.csv, encoding="utf-8") as fh:
        assert "assemblys" not in fh.read()
    assert os.path.exists(result.html) and os.path.exists(result.csv)

    ds = read_result(a)
    ds["n_assemblies_unresolved"] = ds["n_assemblies_unresolved"] * 0 + 8
    by_name = {s.name: s for s in run_statistics(ds)}
    n, k = int(ds.n_assemblies), int(ds.n_contact)
    assert_allclose(by_name["contact_probability_bound_lower"].estimate, k / n)
    assert_allclose(by_name["contact_probability_bound_upper"].estimate, (k + 8) / n)
    other = read_result(b)  # no unresolved: its rows are added to match the reference
    both = compare_datasets([ds, other], ["x", "y"])
    assert ("contact_probability_bound_upper", "y") in both.differences
    # the difference lies in [lower_y - upper_x, upper_y - lower_x]
    k_y, n_y = int(other.n_contact), int(other.n_assemblies)
    lower, upper, ci_lower, ci_upper = both.bound_differences["y"]
    assert_allclose([lower, upper], [k_y / n_y - (k + 8) / n, k_y / n_y - k / n], rtol=1e-12)
    assert ci_lower == newcombe_difference(k_y, n_y, k + 8, n)[1]
    assert ci_upper == newcombe_difference(k_y, n_y, k, n)[2]


def test_a_rare_event_estimate_is_labelled_and_differenced_as_such(yaw_runs):
    # a run whose P(contact) an estimator made (here importance sampling, as the file of
    # rc_certain_imp.toml labels it) is not k / n of its plain run: its interval is the
    # estimator's, and its difference to a plain run the MOVER of the two intervals (the
    # compare before this fix labelled it Clopper-Pearson and took Newcombe's difference of
    # the counts)
    from tolsim.io.netcdf import read_result

    plain = read_result(yaw_runs[0])
    rare = read_result(yaw_runs[1])
    interval = "normal approximation, estimate -+ z se (approximate)"
    for name, value in (("contact_probability", 1.2e-3), ("contact_probability_ci_lower",
                                                          1.0e-3),
                        ("contact_probability_ci_upper", 1.4e-3)):
        rare[name] = rare[name] * 0 + value
        rare[name].attrs.update(estimator="importance", interval=interval)
    comparison = compare_datasets([plain, rare], ["plain", "rare"])
    stat = comparison.runs[1].statistics["contact_probability"]
    assert stat.interval == f"importance sampling: {interval}"
    assert "by importance sampling" in stat.description
    assert comparison.runs[0].statistics["contact_probability"].interval == "Clopper-Pearson"
    diff = comparison.differences[("contact_probability", "rare")]
    ref = comparison.runs[0].statistics["contact_probability"]
    expected = mover_difference(1.2e-3, 1.0e-3, 1.4e-3, ref.estimate, ref.ci_lower,
                                ref.ci_upper)
    assert_allclose([diff.estimate, diff.ci_lower, diff.ci_upper], expected, rtol=1e-12)
    assert diff.interval.startswith("MOVER from the two intervals")
    # the same with the rare-event run as the reference, and two rare-event runs
    back = compare_datasets([rare, plain], ["rare", "plain"]).differences[
        ("contact_probability", "plain")]
    assert_allclose(back.estimate, -diff.estimate, rtol=1e-12)
    assert back.interval.startswith("MOVER")
    both = compare_datasets([rare, rare], ["r1", "r2"]).differences[
        ("contact_probability", "r2")]
    assert both.estimate == 0.0 and both.interval.startswith("MOVER")


# --------------------------------------------------------------------------------------------
# Errors: one line, exit code 2, nothing written
# --------------------------------------------------------------------------------------------
def _one_line_error(capsys, argv, match):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("tolsim compare: error: ")
    assert re.search(match, err), err


def test_compare_errors(yaw_runs, tmp_path, capsys):
    import xarray as xr

    a, b, _ = yaw_runs
    out = tmp_path / "never"
    junk = tmp_path / "junk.nc"
    junk.write_text("not netCDF\n")
    foreign = tmp_path / "foreign.nc"
    xr.Dataset({"x": ("t", np.arange(3.0))}).to_netcdf(foreign)
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    _one_line_error(capsys, ["compare", str(a), "-o", str(out)], "at least two result files")
    _one_line_error(capsys, ["compare", "-o", str(out)], "required")
    _one_line_error(capsys, ["compare", str(a), str(tmp_path / "missing.nc"), "-o", str(out)],
                    r"missing\.nc: no such file")
    _one_line_error(capsys, ["compare", str(a), str(junk), "-o", str(out)],
                    r"junk\.nc: not a netCDF file")
    # CLI audit, session 25: a checkpoint gave netCDF's "Unknown file format" (report said it)
    partial = tmp_path / "run.nc.partial"
    np.savez(partial, fingerprint=np.array("x"))
    (tmp_path / "run.nc.partial.npz").rename(partial)  # (savez adds .npz to a path)
    _one_line_error(capsys, ["compare", str(a), str(partial), "-o", str(out)],
                    r"run\.nc\.partial: the checkpoint of an interrupted tolsim run")
    _one_line_error(capsys, ["compare", str(foreign), str(a), "-o", str(out)],
                    r"foreign\.nc: not a tolsim study result")
    _one_line_error(capsys, ["compare", str(a), str(tmp_path), "-o", str(out)],
                    "is a folder, not a result file")
    assert not out.exists()  # no half-written output folder
    _one_line_error(capsys, ["compare", str(a), str(b), "-o", str(a_file)],
                    "exists and is not a folder")
