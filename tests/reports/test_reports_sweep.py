"""The report of a what-if sweep (issue 14): ``tolsim report SWEEP.nc`` writes an HTML page,
a CSV per point and PNGs, its numbers are the file's, each point is read as the single study
it is; ``tolsim compare`` refuses a sweep with one line."""

import base64
import csv
import glob
import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from tolsim.cli import main
from tolsim.io.config import load_config, parse_config
from tolsim.io.netcdf import read_result, result_to_dataset, write_dataset
from tolsim.io.sweep import combine_points, run_sweep
from tolsim.reports.sweep import (
    CSV_NAME,
    HTML_NAME,
    is_sweep_file,
    make_sweep_report,
    point_dataset,
    series_of,
    sweep_layout,
)
from tolsim.reports.sweep.points import _point_value
from tolsim.reports.verdict import study_verdict
from tolsim.study.execution.runner import run_study
from tolsim.study.statistics.intervals import format_fraction

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
#: the closed-form study of tests/study/test_known_answer.py (two balls: fast)
KNOWN = (CONFIGS / "known_answer.toml").read_text()
#: the packaged sweeps (every config in configs/ with a [sweep])
PACKAGED_SWEEPS = sorted(os.path.basename(p) for p in glob.glob(str(CONFIGS / "*.toml"))
                         if "sweep" in tomllib.loads(Path(p).read_text()))
#: two keys of known_answer.toml, as an outer product (2 x 3 points) and zipped (2 points)
TWO_KEYS = ('"loads.normal_load_N" = [150, 250]\n'
            '"tolerances.bottom_rotation.scale" = [0.5, 1.0, 1.25]')
ZIPPED = ('mode = "zip"\n"loads.normal_load_N" = [150, 250]\n'
          '"tolerances.bottom_rotation.scale" = [0.5, 1.25]')


def known(sweep: str, samples: int = 256) -> str:
    """known_answer.toml with ``samples`` assemblies, two spot checks and ``[sweep]``."""
    text = KNOWN.replace("samples = 20000", f"samples = {samples}").replace(
        "spot_checks = 10", "spot_checks = 2")
    return text + "\n[sweep]\n" + sweep + "\n"


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
    """Result files of small sweeps: one key (the packaged yaw-moment sweep, outer), two keys
    outer, two keys zipped; and the configs behind them."""
    folder = tmp_path_factory.mktemp("sweeps")
    configs = {
        "one_key": load_config(CONFIGS / "sweep_yaw_moment.toml").with_overrides(samples=256),
        "two_keys": parse_config(known(TWO_KEYS), "two.toml"),
        "zip": parse_config(known(ZIPPED), "zip.toml"),
    }
    out = {}
    for name, config in configs.items():
        run_sweep(config, folder / f"{name}.nc")
        out[name] = (folder / f"{name}.nc", config)
    return out


def _csv(path) -> list:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _embedded_pngs(page) -> set:
    return {base64.b64decode(u) for u in
            re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", page)}


# --------------------------------------------------------------------------------- pure parts
def test_point_value_of_merged_attributes():
    # tolsim.io.sweep.combine_points: an attribute that differs between points is stored as
    # lines "point K: value" (a value may itself span lines)
    merged = "point 1: a\npoint 2: b\nsecond line\npoint 3: c"
    assert [_point_value(merged, k, 3) for k in range(3)] == ["a", "b\nsecond line", "c"]
    assert _point_value("the same at every point", 1, 3) == "the same at every point"
    assert _point_value(0.5, 1, 3) == 0.5
    # not the lines of this sweep (fewer points than stored): left as it is
    assert _point_value("point 1: a\npoint 2: b", 0, 3) == "point 1: a\npoint 2: b"


def test_series_of_two_outer_keys_and_a_zip(sweeps):
    # outer 2 x 3: the first key on the x axis, one curve per value of the second; the
    # points in the file's order (first key slowest): curve j holds points j and 3 + j
    ds = read_result(sweeps["two_keys"][0])
    layout = sweep_layout(ds)
    assert layout.shape == (2, 3) and layout.mode == "outer"
    series = series_of(layout)
    assert [s.points for s in series] == [(0, 3), (1, 4), (2, 5)]
    assert [s.label for s in series] == ["0.5", "1", "1.25"]
    np.testing.assert_array_equal(series[0].x, [150.0, 250.0])
    # zip: one curve over the point numbers
    z = sweep_layout(read_result(sweeps["zip"][0]))
    assert z.dimensions == ("sweep_point",)
    (only,) = series_of(z)
    np.testing.assert_array_equal(only.x, [1.0, 2.0])
    assert tuple(z.values_at(1).values()) == (250.0, 1.25)


def test_point_dataset_is_the_study_of_its_point(sweeps):
    # Each point read out of the sweep file is the study 'tolsim run' writes for that
    # point's config alone (same seed): every variable, and so its verdict.
    path, config = sweeps["two_keys"]
    ds = read_result(path)
    layout = sweep_layout(ds)
    for k, point in enumerate(config.sweep.points):
        alone = result_to_dataset(run_study(point))
        pt = point_dataset(ds, k, layout)
        assert "sweep_dimensions" not in pt.attrs and "spot_check_count" not in pt
        assert set(alone.data_vars) == set(pt.data_vars)
        for name in alone.data_vars:
            np.testing.assert_array_equal(pt[name].values, alone[name].values, err_msg=name)
        assert study_verdict(pt) == study_verdict(alone)


def test_point_dataset_cuts_the_padded_spot_checks():
    c = parse_config(known('"loads.normal_load_N" = [150, 250]'))
    alone = [result_to_dataset(run_study(p)) for p in c.sweep.points]
    alone[1] = alone[1].isel(spot_check=slice(0, 1))  # point 2 has one spot check
    alone[1].attrs["spot_check_status"] = "only one"
    combined = combine_points(alone, c.sweep)
    for k in range(2):
        pt = point_dataset(combined, k)
        assert pt.sizes["spot_check"] == (2, 1)[k]
        for name in alone[k].data_vars:
            np.testing.assert_array_equal(pt[name].values, alone[k][name].values, err_msg=name)
        assert pt.attrs["spot_check_status"] == alone[k].attrs["spot_check_status"]


# --------------------------------------------------------------------------------- the report
@pytest.mark.parametrize("name", ["one_key", "two_keys", "zip"])
def test_report_of_each_layout(sweeps, name, tmp_path):
    path, config = sweeps[name]
    out = make_sweep_report(path, tmp_path / "report")
    ds = read_result(path)
    sweep = config.sweep
    assert len(out.points) == sweep.size
    page = Path(out.html).read_text(encoding="utf-8")
    # what was swept: every key with its values and units, the mode, the shared random numbers
    for axis in sweep.axes:
        assert axis.key in page and axis.units in page
        assert ", ".join(f"{v:g}" for v in axis.values) in page
    assert f"Mode {sweep.mode}" in page and "common random numbers" in page
    # self-contained: every PNG written is embedded byte for byte, nothing fetched
    pngs = sorted(Path(out.folder).glob("*.png"))
    assert {p.name for p in pngs} == {"contact_probability.png", "velocity_deviation.png"}
    assert {p.read_bytes() for p in pngs} <= _embedded_pngs(page)
    assert "http://" not in page and "https://" not in page
    # the table's numbers are the file's, point by point in the file's order
    rows = _csv(out.csv)
    p = ds.contact_probability.values.ravel()
    lo = ds.contact_probability_ci_lower.values.ravel()
    hi = ds.contact_probability_ci_upper.values.ravel()
    assert [r["point"] for r in rows] == [str(k + 1) for k in range(sweep.size)]
    np.testing.assert_array_equal([float(r["contact_probability"]) for r in rows], p)
    np.testing.assert_array_equal([float(r["contact_probability_ci_lower"]) for r in rows], lo)
    np.testing.assert_array_equal([float(r["contact_probability_ci_upper"]) for r in rows], hi)
    np.testing.assert_array_equal([int(r["n_contact"]) for r in rows],
                                  ds.n_contact.values.ravel())
    np.testing.assert_array_equal([float(r["velocity_deviation_std"]) for r in rows],
                                  ds.velocity_deviation_std.values.ravel())
    for k, row in enumerate(rows):
        assert {a.key: float(row[a.key]) for a in sweep.axes} == sweep.values_at(k)
        assert format_fraction(p[k], lo[k], hi[k]) in page
    # the verdict per point is that of the point's study
    for point, row in zip(out.points, rows, strict=True):
        assert row["verdict"] == point.verdict.status
        assert row["contact_verdict"] == point.verdict.checks[0].status


def test_verdict_per_point_against_the_contact_limit(sweeps, tmp_path):
    # configs/sweep_yaw_moment.toml sets contact_probability_limit_percent = 70: each point
    # gets the verdict of its study, and the page says where P(contact) <= 70 % holds
    path, _ = sweeps["one_key"]
    out = make_sweep_report(path, tmp_path / "report")
    ds = read_result(path)
    page = Path(out.html).read_text(encoding="utf-8")
    assert "Verdict per point" in page and "P(contact) ≤ 70 %" in page
    for k, point in enumerate(out.points):
        check = point.verdict.checks[0]
        hi = float(ds.contact_probability_ci_upper[k])
        lo = float(ds.contact_probability_ci_lower[k])
        expected = "pass" if hi <= 0.7 else "fail" if lo > 0.7 else "undecided"
        assert check.status == expected
    # known_answer.toml sets no limit: no verdict section
    other = make_sweep_report(sweeps["zip"][0], tmp_path / "zip")
    text = Path(other.html).read_text(encoding="utf-8")
    assert "Verdict per point" not in text and "no spec limit given" in text


def _paired_yaw_moment_sweep(out):
    """configs/sweep_yaw_moment.toml at 30 and 45 N m with the paired static model, 128
    assemblies per point, run to ``out``: its Dataset."""
    text = re.sub(r"(?ms)^\[sweep\].*", "", (CONFIGS / "sweep_yaw_moment.toml").read_text())
    text = text.replace("samples = 20000", "samples = 128").replace(
        "spot_checks = 50", "spot_checks = 2").replace('static_model = "solved"',
                                                       'static_model = "paired"')
    c = parse_config(text + '[sweep]\n"loads.yaw_moment_N_m" = [30.0, 45.0]\n', out.name)
    return run_sweep(c, out)[0]


def test_unresolved_points_show_their_bounds(tmp_path, monkeypatch):
    # Beyond about 35 N m the end balls lose a contact (configs/sweep_yaw_moment.toml). The
    # full model solves such balls (issue 25), but the paper's paired forces put a contact in
    # tension there (|rho| > 1: the static model out of its range). Their fallback to the
    # solved model taken away (a ball no model can solve), those trains are unresolved and
    # the table gives the bounds over all trains
    import tolsim.study.pipeline.evaluate as evaluate

    monkeypatch.setattr(evaluate, "STATIC_FALLBACK", {})
    ds = _paired_yaw_moment_sweep(tmp_path / "u.nc")
    unresolved = ds.n_assemblies_unresolved.values
    assert unresolved[0] == 0 and unresolved[1] > 0
    out = make_sweep_report(tmp_path / "u.nc", tmp_path / "report")
    page = Path(out.html).read_text(encoding="utf-8")
    assert "unresolved trains: bounds over all" in page
    lower, upper = (format_fraction(float(ds[f"contact_probability_bound_{x}"][1]))
                    for x in ("lower", "upper"))
    assert f"{int(unresolved[1]):,}: {lower} to {upper}" in page
    rows = _csv(out.csv)
    assert [int(r["n_assemblies_unresolved"]) for r in rows] == list(unresolved)


def test_points_whose_balls_the_solved_model_answered_say_so(tmp_path):
    # The sweep of test_unresolved_points_show_their_bounds with the paired model's fallback:
    # the balls whose paired forces are in tension at 45 N m are answered by the solved model,
    # no train is unresolved, and the model checks and points.csv give their number per point.
    ds = _paired_yaw_moment_sweep(tmp_path / "f.nc")
    fallback = ds.n_balls_static_fallback.values
    np.testing.assert_array_equal(ds.n_assemblies_unresolved.values, [0, 0])
    assert fallback[0] == 0 and fallback[1] > 0
    out = make_sweep_report(tmp_path / "f.nc", tmp_path / "report")
    page = Path(out.html).read_text(encoding="utf-8")
    assert "balls the static model left without balance, answered by the solved model" in page
    rows = _csv(out.csv)
    assert [int(r["n_balls_static_fallback"]) for r in rows] == list(fallback)


def test_a_points_config_is_its_own_and_warnings_name_the_sweep(tmp_path):
    # The report re-reads the embedded config per point. Its warning about point 2's value
    # came out named after point 1 ("..., point 1: carriage.preload_oversize_um = 0 um:32:
    # carriage.preload_oversize_um = 100.0 um is unusual"), and the point's config was the
    # sweep's base. The warning names the sweep now, and each point gets its own config
    # (here point 2's friction coefficient of 0.5, beyond the usual 0.3).
    import warnings

    from tolsim.io.config import ConfigWarning
    from tolsim.reports.result_view import config_of
    from tolsim.reports.sweep.points import point_dataset

    text = (CONFIGS / "known_answer.toml").read_text().replace("samples = 20000",
                                                                "samples = 64")
    text += '\n[sweep]\n"bearing.friction_coefficient" = [0.1, 0.5]\n'
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConfigWarning)
        ds, _ = run_sweep(parse_config(text, "big.toml"), tmp_path / "big.nc")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        configs = [config_of(point_dataset(ds, k)) for k in range(2)]
    assert [cfg.bearing.friction_coefficient for cfg in configs] == [0.1, 0.5]
    said = [str(w.message) for w in caught if issubclass(w.category, ConfigWarning)]
    assert said and all("point 1" not in s for s in said), said
    assert all(s.startswith("big.toml (sweep of 1 key, 2 points):") for s in said), said


def test_friction_of_a_contact_study(tmp_path):
    # a study with [contact] (configs/friction_yaw.toml): the friction increase and
    # P(friction increase > limit) per point
    text = (CONFIGS / "friction_yaw.toml").read_text()
    text = re.sub(r"(?m)^samples = .*$", "samples = 256", text)
    text = re.sub(r"(?m)^sensitivity_samples = .*$", "", text)
    text = re.sub(r"(?m)^spot_checks = .*$", "spot_checks = 2", text)
    c = parse_config(text + '\n[sweep]\n"loads.yaw_moment_N_m" = [5.0, 25.0]\n', "f.toml")
    ds, _ = run_sweep(c, tmp_path / "f.nc")
    out = make_sweep_report(tmp_path / "f.nc", tmp_path / "report")
    assert "friction" in out.figures
    page = Path(out.html).read_text(encoding="utf-8")
    assert "What contact costs" in page
    rows = _csv(out.csv)
    np.testing.assert_array_equal([float(r["friction_exceedance_probability"]) for r in rows],
                                  ds.friction_exceedance_probability.values)
    q99 = ds.friction_increase_quantile.sel(quantile=0.99).values
    np.testing.assert_array_equal([float(r["friction_increase_quantile_0.99_N"]) for r in rows],
                                  q99)
    for k in range(2):
        p, lo, hi = (float(ds[f"friction_exceedance_probability{x}"][k])
                     for x in ("", "_ci_lower", "_ci_upper"))
        assert format_fraction(p, lo, hi) in page


# --------------------------------------------------------------------------------- the CLI
@pytest.mark.parametrize("name", PACKAGED_SWEEPS)
def test_cli_report_of_each_packaged_sweep(name, tmp_path, capsys):
    config = load_config(CONFIGS / name).with_overrides(samples=256)
    nc = tmp_path / "s.nc"
    run_sweep(config, nc)
    assert is_sweep_file(nc)
    out = tmp_path / "report"
    assert main(["report", str(nc), "-o", str(out)]) == 0
    said = capsys.readouterr().out
    written = {out / HTML_NAME, out / CSV_NAME, out / "contact_probability.png",
               out / "velocity_deviation.png"}
    assert {p for p in out.iterdir()} == written
    for path in written:  # the CLI says what it wrote
        assert str(path) in said
    assert f"sweep report of {config.sweep.size} points" in said
    rows = _csv(out / CSV_NAME)
    assert len(rows) == config.sweep.size
    ds = read_result(nc)
    np.testing.assert_array_equal([float(r["contact_probability"]) for r in rows],
                                  ds.contact_probability.values.ravel())


def test_cli_report_of_a_study_is_the_study_report(sweeps, tmp_path, capsys):
    # a single study's file keeps its report (tests/cli/test_cli_report.py): report.html with
    # the study's figures and the PDF, no points.csv
    config = sweeps["zip"][1].sweep.points[0]
    nc = tmp_path / "study.nc"
    write_dataset(result_to_dataset(run_study(config)), nc)
    assert not is_sweep_file(nc)
    out = tmp_path / "report"
    assert main(["report", str(nc), "-o", str(out), "--no-sensitivity"]) == 0
    assert {"report.html", "report.pdf", "contact.png"} <= {p.name for p in out.iterdir()}
    assert not (out / CSV_NAME).exists()
    assert not is_sweep_file(tmp_path / "missing.nc")


def test_compare_refuses_a_sweep_with_one_line(sweeps, tmp_path, capsys):
    path, config = sweeps["zip"]
    study = tmp_path / "study.nc"
    write_dataset(result_to_dataset(run_study(config.sweep.points[0])), study)
    out = tmp_path / "never"
    for files in ([study, path], [path, study]):
        assert main(["compare", *map(str, files), "-o", str(out)]) == 2
        captured = capsys.readouterr()
        assert captured.out == ""
        assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
        assert captured.err.startswith("tolsim compare: error: ")
        assert f"{path} is a sweep of 2 points" in captured.err
        assert f"tolsim report {path}" in captured.err
        assert not out.exists()  # no output at all
