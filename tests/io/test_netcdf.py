"""netCDF output: declared schema, atomic write, round trip with xarray and netCDF4."""

import os

import netCDF4
import numpy as np
import pytest
import xarray as xr

from tolsim import __version__
from tolsim.io import schema
from tolsim.io.config import parse_config
from tolsim.io.netcdf import read_result, result_to_dataset, write_dataset, write_result
from tolsim.study.execution.runner import run_study

CONFIG = """\
# a small study
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
[motion]
groove_velocity_mm_per_s = 200.0
stroke_mm = 100.0
[train]
balls = 4
initial_gap = { distribution = "uniform", low_um = 0.0, high_um = 100.0 }
[loads]
normal_load_N = 200.0
yaw_moment_N_m = 4.0
[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.2
correlation_length_mm = 40.0
[tolerances.top_rotation]
distribution = "normal"
std_deg = 0.1
[study]
samples = 500
seed = 8
block_size = 128
spot_checks = 3
velocity_deviation_limit_percent = 0.4
"""


@pytest.fixture(scope="module")
def result():
    return run_study(parse_config(CONFIG, "small.toml"))


def test_dataset_follows_schema(result):
    ds = result_to_dataset(result, history="test")
    for name, decl in schema.VARIABLES.items():
        if decl.required:
            assert ds[name].attrs["units"] == decl.units
            assert ds[name].attrs["long_name"] == decl.long_name
    for name in ds.variables:
        assert "units" in ds[name].attrs and "long_name" in ds[name].attrs
    a = ds.attrs
    assert a["Conventions"] == "CF-1.10"
    assert a["source"] == f"tolsim {__version__}"
    assert a["seed"] == 8
    assert a["config"] == CONFIG
    assert a["history"].endswith(" test")
    assert int(ds.n_assemblies) == 500 and int(ds.n_balls) == 2000
    assert float(ds.velocity_deviation_limit) == 0.004
    assert np.isnan(float(ds.contact_probability_limit))
    assert ds.sizes["spot_check"] == 3 and ds.sizes["ball"] == 4 and ds.sizes["pair"] == 3


def test_round_trip_xarray_and_netcdf4(result, tmp_path):
    path = tmp_path / "r.nc"
    ds = write_result(result, path, history="test")
    umask = os.umask(0)
    os.umask(umask)
    assert os.stat(path).st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's 0600
    assert os.listdir(tmp_path) == ["r.nc"]  # no temporary file left
    back = read_result(path)
    xr.testing.assert_identical(ds, back)
    # netCDF4 alone
    with netCDF4.Dataset(path) as nc:
        assert nc.Conventions == "CF-1.10"
        assert nc.config == CONFIG
        v = nc.variables["contact_probability"]
        assert v.units == "1" and v.long_name
        assert float(v[...]) == float(ds.contact_probability)
        assert nc.variables["time_to_contact_quantile"].units == "s"
        np.testing.assert_array_equal(nc.variables["velocity_deviation_histogram"][:],
                                      ds.velocity_deviation_histogram.values)
    # the run can be reproduced from the file alone
    again = parse_config(back.attrs["config"]).with_overrides(seed=int(back.attrs["seed"]))
    assert again.study == result.config.study


def test_schema_rejects_undeclared_and_missing(result):
    ds = result_to_dataset(result, history="test")
    with pytest.raises(schema.SchemaError, match="not declared"):
        schema.validate(ds.assign(extra=1.0))
    with pytest.raises(schema.SchemaError, match="contact_probability.*missing"):
        schema.validate(ds.drop_vars("contact_probability"))
    bad = ds.copy()
    bad["n_balls"].attrs["units"] = "m"
    with pytest.raises(schema.SchemaError, match="n_balls"):
        schema.validate(bad)
    bad = ds.copy()
    del bad.attrs["config"]
    with pytest.raises(schema.SchemaError, match="config"):
        schema.validate(bad)


def test_optional_factor_dimension_is_accepted(result):
    ds = result_to_dataset(result, history="test")
    ds = ds.assign_coords(factor=("factor", [0, 1]),
                          factor_name=("factor", ["bottom_rotation", "top_rotation"]))
    ds["sensitivity_total"] = ("factor", [0.7, 0.3])
    schema.apply_attributes(ds)
    schema.validate(ds)


def test_a_write_into_a_missing_folder_names_the_target(result, tmp_path):
    # the error named the temporary file (.x.nc.XXXX.tmp), not the file asked for
    target = tmp_path / "missing" / "x.nc"
    with pytest.raises(OSError) as error:
        write_dataset(result_to_dataset(result, history="test"), target)
    assert error.value.filename == str(target)


def test_failed_write_leaves_nothing(result, tmp_path, monkeypatch):
    path = tmp_path / "r.nc"
    ds = result_to_dataset(result, history="test")

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        write_dataset(ds, path)
    assert os.listdir(tmp_path) == []


def test_ctrl_c_during_a_write_takes_effect_after_it(result, tmp_path, monkeypatch):
    # Ctrl-C inside the netCDF library could leave xarray's HDF5 lock held, and the next write
    # (a sweep's next part) waited on it for ever. SIGINT during the write now waits for the
    # write to end: the file is whole and verified, nothing else is left, and the
    # KeyboardInterrupt follows; the next write works.
    import signal

    # Python's own handler, as in an interactive run: a process started in the background
    # by a non-interactive shell inherits SIGINT ignored (the write keeps either)
    original = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        _interrupted_write(result, tmp_path, monkeypatch)
    finally:
        signal.signal(signal.SIGINT, original)


def _interrupted_write(result, tmp_path, monkeypatch):
    import signal

    path = tmp_path / "r.nc"
    ds = result_to_dataset(result, history="test")
    to_netcdf = xr.Dataset.to_netcdf

    def interrupted(self, *args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)  # delivered at once without the hold
        return to_netcdf(self, *args, **kwargs)

    monkeypatch.setattr(xr.Dataset, "to_netcdf", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_dataset(ds, path)
    assert os.listdir(tmp_path) == ["r.nc"]
    assert int(read_result(path).n_balls) == int(ds.n_balls)
    monkeypatch.setattr(xr.Dataset, "to_netcdf", to_netcdf)
    write_dataset(ds, tmp_path / "again.nc")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_invalid_dataset_is_not_written(result, tmp_path):
    ds = result_to_dataset(result, history="test").drop_vars("n_balls")
    with pytest.raises(schema.SchemaError):
        write_dataset(ds, tmp_path / "r.nc")
    assert os.listdir(tmp_path) == []


def test_read_result_rejects_other_files(tmp_path):
    other = tmp_path / "other.nc"
    xr.Dataset({"x": ("t", [1.0, 2.0])}).to_netcdf(other)
    with pytest.raises(ValueError, match="not a tolsim study result"):
        read_result(other)
    text = tmp_path / "text.nc"
    text.write_text("hello")
    with pytest.raises(ValueError, match="cannot open"):
        read_result(text)


def test_sensitivity_and_quality_stored_and_round_trip(tmp_path):
    # [study] sensitivity_samples switches on the Sobol' analysis in the run; the indices go
    # into the file along 'factor' (one entry per random tolerance source and the initial
    # gap), and a limit on |epsilon| adds the quality-engineering figures. Indices are
    # shares of variance: within [0, 1] up to estimator noise (0.1 here, 128 samples).
    text = CONFIG.replace("spot_checks = 3", "spot_checks = 0\nsensitivity_samples = 128")
    res = run_study(parse_config(text, "small.toml"))
    path = tmp_path / "sens.nc"
    write_result(res, path)
    back = read_result(path)
    factors = list(back["factor_name"].values)  # the names; factor is an integer index
    assert list(back["factor"].values) == list(range(len(factors)))
    assert {"bottom_rotation", "top_rotation", "initial_gap"} <= set(factors)
    for name in ("sensitivity_first_order", "sensitivity_total", "sensitivity_total_ci_lower",
                 "sensitivity_contact_total"):
        values = back[name].values
        assert values.shape == (len(factors),)
        assert np.all(values > -0.1) and np.all(values < 1.1), name
        assert back[name].attrs["units"] == "1" and back[name].attrs["long_name"]
    total = back["sensitivity_total"].swap_dims(factor="factor_name").to_series()
    # epsilon does not depend on the initial gap at all
    assert abs(total["initial_gap"]) < 1e-12
    assert back.attrs["sensitivity_samples"] == 128
    assert 0.0 <= float(back["velocity_deviation_out_of_spec_fraction"]) <= 1.0
    assert np.isfinite(float(back["velocity_deviation_cpk"]))


def test_read_result_names_a_wrong_path_type():
    # API audit, session 24: xarray's "invalid filename for netCDF4 backend: None"
    with pytest.raises(ValueError, match="path = None: a result file's path must be a str"):
        read_result(None)


def test_a_config_its_text_does_not_say_is_not_written(tmp_path):
    # The file embeds the config text alone: a config changed with dataclasses.replace would
    # be recorded as the study it was read from (session 24's API audit). It is refused, and
    # nothing is written.
    from dataclasses import replace

    config = parse_config(CONFIG, "small.toml")
    result = run_study(config)
    changed = replace(result, config=replace(config, study=replace(config.study, seed=99)))
    out = tmp_path / "r.nc"
    with pytest.raises(ValueError, match=r"not written: config.study.seed = 99, but its text "
                                         r"gives \d+; the file embeds the config text alone"):
        write_result(changed, out, history="test")
    assert not out.exists() and not list(tmp_path.iterdir())
    write_result(result, out, history="test")  # the config as read
    assert out.exists()
