"""The result file reproduces the run (issue 17): its ``config`` attribute is the effective
config, overrides included, and ``tolsim run`` on it gives every data variable bit for bit."""

import hashlib

import numpy as np
import pytest
import xarray as xr

from tolsim.cli import main

STUDY = """\
# a small study with every issue-17 feature: measured data, correlated flanks, limits
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

[tolerances.bottom_rotation]      # measured on 40 rails
distribution = "empirical"
file = "rail_rotation.csv"
column_deg = "rotation"

[tolerances.arc_centre_offset_tangential_TR]
distribution = "normal"
std_um = 1.5

[tolerances.arc_centre_offset_tangential_TL]
distribution = "cpk"
low_um = -3.0
high_um = 3.0
cpk = 1.0

[[correlation]]                   # the two flanks of the carriage groove, ground together
sources = ["arc_centre_offset_tangential_TR", "arc_centre_offset_tangential_TL"]
coefficient = 0.7

[study]
samples = 1000                    # overridden on the command line
seed = 1                          # overridden on the command line
block_size = 128
static_model = "paired"
spot_checks = 3
velocity_deviation_limit_percent = 0.3
contact_probability_limit_percent = 5
sensitivity_samples = 64
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("effective")
    rng = np.random.default_rng(3)
    csv = "rotation\n" + "".join(f"{v:.5f}\n" for v in rng.normal(0.02, 0.1, 40))
    (folder / "rail_rotation.csv").write_text(csv)
    (folder / "study.toml").write_text(STUDY)
    first = folder / "a.nc"
    assert main(["run", str(folder / "study.toml"), "--samples", "300", "--seed", "9",
                 "-o", str(first), "--quiet"]) == 0
    with xr.open_dataset(first) as ds:
        a = ds.load()
    stored = folder / "stored.toml"  # next to the CSV: data paths are relative to the config
    stored.write_text(a.attrs["config"])
    second = folder / "b.nc"
    assert main(["run", str(stored), "-o", str(second), "--quiet"]) == 0
    with xr.open_dataset(second) as ds:
        b = ds.load()
    return a, b, csv


def test_stored_config_holds_the_overrides(runs):
    a, b, _ = runs
    text = a.attrs["config"]
    assert "samples = 300                     # overridden on the command line" in text
    assert "seed = 9                          # overridden on the command line" in text
    assert text.replace("300 ", "1000").replace("seed = 9", "seed = 1") == STUDY
    assert (a.attrs["samples"], a.attrs["seed"]) == (300, 9)
    assert b.attrs["config"] == text  # no overrides the second time: the same text


def test_rerun_from_the_file_is_bit_identical(runs):
    a, b, _ = runs
    assert int(a.n_assemblies) == 300
    assert set(a.variables) == set(b.variables)
    assert "sensitivity_total" in a.variables and a.sizes["spot_check"] == 3
    for name in a.variables:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    timing = {"history", "elapsed_seconds", "full_model_resolve_seconds", "title",
              "balls_per_second", "compile_seconds",  # stamps of the run, not results
              "attributes_sha256"}  # (the global attributes' checksum: of the stamps too)
    for key in set(a.attrs) - timing:
        assert np.array_equal(a.attrs[key], b.attrs[key]), key


def test_versions_and_data_hashes_are_stored(runs):
    a, _, csv = runs
    import numba
    import scipy

    from tolsim import __version__

    assert a.attrs["tolsim_version"] == __version__
    assert a.attrs["numpy_version"] == np.__version__
    assert a.attrs["scipy_version"] == scipy.__version__
    assert a.attrs["numba_version"] == numba.__version__
    sha = hashlib.sha256(csv.encode()).hexdigest()
    assert a.attrs["data_files"] == f"{sha}  rail_rotation.csv"  # sha256sum -c format
