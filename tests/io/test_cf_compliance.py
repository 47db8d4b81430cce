"""Every result file passes the IOOS compliance checker, ``compliance-checker --test=cf:1.10``.

For the packaged default and every config in configs/ (small, fast runs; the Sobol' indices
stay on where the config asks for them, with few samples, so the ``factor`` variables are
checked too), the file written by :func:`tolsim.io.netcdf.write_result` must give no checker
exception and no failed check of high (3) or medium (2) priority. (With ``-c strict`` the
files pass every check; the only remark, in a passed check, is CF 7.1's "the bin edges might
be cell bounds": no ``bounds`` attribute on purpose, see tolsim.io.schema.apply_attributes.)
The negative controls show that the check can fail.
"""

import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

pytest.importorskip("compliance_checker", reason="compliance-checker is not installed")
from cf_checker import check, load_checkers, report  # noqa: E402

from tolsim.io.config import parse_config, with_study_settings  # noqa: E402
from tolsim.io.netcdf import result_to_dataset, write_result  # noqa: E402
from tolsim.study.execution.runner import run_study  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
#: (configs with a [carriage] included: their files add the ``track`` and carriage variables)
CONFIG_FILES = [ROOT / "tolsim" / "data" / "default.toml",
                *sorted((ROOT / "configs").glob("*.toml"))]
#: small runs: assemblies per propagation model (along-track is ~100x dearer per assembly),
#: Sobol' base samples (each costs d + 2 assemblies) and spot checks
SAMPLES = {"constant": 64, "along_track": 8}
SENSITIVITY_SAMPLES = 16
SPOT_CHECKS = 3
#: a rare-event estimator (configs/rare_contact.toml): the fewest samples per level of subset
#: simulation at p0 = 0.1 (10 chains), and few importance samples
SAMPLES_PER_LEVEL = 100
IMPORTANCE_SAMPLES = 100
#: a config without random tolerances, run with the indices on: an empty ``factor`` dimension
EMPTY_FACTORS = "paper_mitigated.toml"


@pytest.fixture(scope="module", autouse=True)
def checkers():
    load_checkers()


def small(path, **settings):
    # a sweep's base study (its file: below): the text without its [sweep], the last table
    config = parse_config(re.split(r"^\[sweep\]", path.read_text(), flags=re.M)[0], str(path))
    st = config.study
    estimator = settings.get("estimator", st.estimator)
    if estimator != "monte_carlo":
        settings.update(samples_per_level=SAMPLES_PER_LEVEL, p0=0.1)
    if estimator in ("importance", "rare"):
        settings.update(importance_samples=IMPORTANCE_SAMPLES)
    return with_study_settings(
        config, samples=SAMPLES[st.propagation], spot_checks=min(st.spot_checks, SPOT_CHECKS),
        sensitivity_samples=SENSITIVITY_SAMPLES if path.name == EMPTY_FACTORS
        else min(st.sensitivity_samples, SENSITIVITY_SAMPLES), **settings)


def test_configs_are_covered_with_sensitivity():
    assert len(CONFIG_FILES) >= 3
    with_sensitivity = [p.name for p in CONFIG_FILES
                        if p.name != EMPTY_FACTORS and small(p).study.sensitivity_samples]
    assert with_sensitivity, "no config checks the sensitivity (factor) variables"
    # and one the variables of a rare-event estimator (the importance sampling file with its
    # design point is checked in tests/study/test_rare_study.py)
    assert [p.name for p in CONFIG_FILES if small(p).study.estimator != "monte_carlo"]


@pytest.mark.slow  # the checker takes about a second per file (tests/io/cf_checker.py)
@pytest.mark.parametrize("path", CONFIG_FILES, ids=lambda p: p.name)
def test_result_file_passes_cf_checker(path, tmp_path, capsys):
    result = run_study(small(path))
    out = tmp_path / "result.nc"
    ds = write_result(result, out, history="test")
    if result.sensitivity is not None:
        assert ds.sizes["factor"] == len(result.sensitivity.factors)
    errors, failed = check(out, tmp_path)
    assert not errors, capsys.readouterr().err  # a checker exception hides a check
    assert failed[3] == [] and failed[2] == [], failed


def test_negative_control_fill_value_on_coordinates(tmp_path):
    # a part of a result written by xarray's defaults, without write_dataset's encoding, has
    # _FillValue on its float coordinates (CF 2.5.1 forbids it): the check must see that
    ds = result_to_dataset(run_study(small(CONFIG_FILES[0])), history="test")
    part = ds[["velocity_deviation_quantile", "survival_probability"]]
    out = tmp_path / "default_encoding.nc"
    part.to_netcdf(out, engine="netcdf4")
    errors, failed = check(out, tmp_path)
    assert not errors
    flagged = " ".join(failed[3])
    assert "'quantile' must not have the _FillValue" in flagged, failed
    assert "'elapsed_time' must not have the _FillValue" in flagged, failed


def test_negative_control_string_coordinate_and_time(tmp_path):
    # a string coordinate variable (CF coordinate variables are strictly monotonic numbers;
    # checker 6.1 raises on it) and a coordinate named time in plain seconds (not a CF time
    # coordinate: units "<unit> since <epoch>") are both caught
    ds = xr.Dataset({"y": (("contact", "time"), np.zeros((2, 3)), {"units": "1"})},
                    coords={"contact": ("contact", ["BL", "BR"]),
                            "time": ("time", [0.0, 1.0, 2.0], {"units": "s"})},
                    attrs={"Conventions": "CF-1.10"})
    out = tmp_path / "bad.nc"
    ds.to_netcdf(out, engine="netcdf4", encoding={"time": {"_FillValue": None}})
    errors, failed = check(out, tmp_path)
    assert errors or any("contact" in f for f in failed[3]), failed
    assert any("time" in f for f in failed[3]), failed


@pytest.mark.slow
def test_result_file_with_saved_samples_passes_cf_checker(tmp_path, capsys):
    # issue 17: the per-assembly export (a ``sample`` dimension beside ``ball``, ``pair`` and
    # ``contact``, flags on ``sample_model``, missing contact times) and the worst-case / RSS
    # variables keep the file CF-clean
    result = run_study(small(CONFIG_FILES[0]), save_samples=SAMPLES["constant"] // 2)
    out = tmp_path / "samples.nc"
    ds = write_result(result, out, history="test")
    assert ds.sizes["sample"] == SAMPLES["constant"] // 2
    assert "velocity_deviation_rss" in ds and "gap_closure_worst_case" in ds
    errors, failed = check(out, tmp_path)
    assert not errors, capsys.readouterr().err
    assert failed[3] == [] and failed[2] == [], failed


@pytest.mark.slow
def test_rare_estimator_file_passes_cf_checker(tmp_path, capsys):
    # issue 23: estimator = "rare": each event's status (a CF flag variable), diagnostics and
    # both estimators' numbers, with the design point along ``factor``
    config = small(ROOT / "configs" / "rare_contact.toml", estimator="rare")
    out = tmp_path / "rare.nc"
    ds = write_result(run_study(config), out, history="test")
    assert {"contact_probability_status", "contact_probability_subset",
            "contact_probability_importance_status",
            "contact_probability_effective_sample_size"} <= set(ds.data_vars)
    errors, failed = check(out, tmp_path)
    assert not errors, capsys.readouterr().err
    assert failed[3] == [] and failed[2] == [], failed


def test_sweep_file(tmp_path):
    """A sweep's file (issue 14; tolsim.io.sweep): every variable with the sweep dimension
    in front, the swept key as a coordinate with UDUNITS units, padded spot checks."""
    from tolsim.io.config import parse_config
    from tolsim.io.sweep import run_sweep

    text = (ROOT / "configs" / "known_answer.toml").read_text().replace(
        "samples = 20000", "samples = 256").replace("spot_checks = 10", "spot_checks = 2")
    text += '\n[sweep]\n"tolerances.bottom_rotation.std_deg" = [1.0, 2.0]\n'
    run_sweep(parse_config(text), tmp_path / "sweep.nc")
    errors, failed = check(tmp_path / "sweep.nc", tmp_path)
    assert not errors
    assert not failed[3] and not failed[2], failed


def test_memoised_check_reports_what_the_checker_reports(tmp_path):
    # tests/io/cf_checker.py memoises the checker's dataset queries while it checks a file
    # (15.6 s -> 1.0 s on friction_yaw.toml's file). Its report must be the checker's own,
    # every field but the time stamp: on the packaged default's result file (17 check groups,
    # 1 590 of 1 590 points) and on the negative control's file (104 of 106 points: the
    # _FillValue on its coordinates fails).
    result = run_study(small(CONFIG_FILES[0]))
    full = write_result(result, tmp_path / "result.nc", history="test")
    part = full[["velocity_deviation_quantile", "survival_probability"]]
    part.to_netcdf(tmp_path / "part.nc", engine="netcdf4")
    for name in ("result.nc", "part.nc"):
        errors, fast = report(tmp_path / name, tmp_path / "fast.json")
        errors_plain, plain = report(tmp_path / name, tmp_path / "plain.json", memoise=False)
        assert errors == errors_plain
        del fast["report_timestamp"], plain["report_timestamp"]
        assert fast == plain
        assert fast["high_priorities"] and fast["scored_points"] > 100  # checks were run
    assert fast["scored_points"] < fast["possible_points"]  # the part fails one
