"""Measured data as a distribution: ``distribution = "empirical"`` with a CSV column.

The distribution is the data's interpolated empirical quantile function, numpy.quantile's
default method="linear" (Hyndman & Fan 1996, The American Statistician 50, 361, definition
7), reached from the standard normal z through u = Phi(z). Sampling error of the p-quantile
of N draws: sd ~ sqrt(p (1 - p) / N) / f(q_p) (the asymptotic variance of a sample quantile,
Stuart & Ord, Kendall's Advanced Theory of Statistics, Vol. 1, Sec. 10.10), with the density
f = 1 / ((n - 1) (x_(k+1) - x_(k))) of the interpolated distribution on the segment holding
q_p. Each check allows 4 sd.
"""

import hashlib
import math
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.special import ndtri

from tolsim.io.config import ConfigError, load_config
from tolsim.study.sampling import error_values, sample_block

STUDY = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
[motion]
groove_velocity_mm_per_s = 100.0
stroke_mm = 100.0
[train]
balls = 3
initial_gap = { distribution = "uniform", low_um = 0.0, high_um = 100.0 }
[loads]
normal_load_N = 200.0
[tolerances.bottom_rotation]
distribution = "empirical"
file = "rail_rotation.csv"
column_deg = "rotation"
[study]
samples = 16384
seed = 5
block_size = 8192
sampling = "{sampling}"
"""

#: Quantile levels checked.
LEVELS = (0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99)


def measured(n=250):
    """Skewed 'measurements' [deg]: a shifted gamma, 6 decimals (no ties)."""
    rng = np.random.default_rng(1)
    x = np.round(rng.gamma(3.0, 0.02, n) - 0.05, 6)
    assert len(np.unique(x)) == n
    return x


def write_study(folder, values=None, sampling="random", csv=None, extra=""):
    values = measured() if values is None else values
    if csv is None:
        csv = "# rail groove rotation, measured on a CMM\nrail,rotation\n" + "".join(
            f"R{i},{float(v)!r}\n" for i, v in enumerate(values))
    (folder / "rail_rotation.csv").write_text(csv)
    path = folder / "study.toml"
    path.write_text(STUDY.replace("{sampling}", sampling).replace(
        'column_deg = "rotation"', 'column_deg = "rotation"' + extra))
    return path


def draws(config):
    v = [error_values(config, sample_block(config, k))["bottom_rotation"][:, 0]
         for k in range(2)]
    return np.concatenate(v)


def test_quantile_function_is_numpys_linear_quantile(tmp_path):
    # Exactly (to rounding) the data's np.quantile at u = Phi(z), everywhere in (0, 1).
    data = np.radians(measured())
    d = load_config(write_study(tmp_path)).tolerances[0].distribution
    assert d.kind == "empirical" and len(d.data) == 250
    p = np.linspace(1e-4, 1 - 1e-4, 1001)
    assert_allclose(d.from_normal(ndtri(p)), np.quantile(data, p), rtol=1e-13, atol=1e-18)
    # the range of the data, never beyond
    assert d.from_normal(-40.0) == data.min() and d.from_normal(40.0) == data.max()


@pytest.mark.parametrize("sampling", ["random", "sobol"])
def test_draws_reproduce_the_data_quantiles(tmp_path, sampling):
    data = np.sort(np.radians(measured()))
    n = len(data)
    x = draws(load_config(write_study(tmp_path, sampling=sampling)))
    big_n = len(x)
    assert big_n == 16384
    for p in LEVELS:
        q = np.quantile(data, p)
        k = min(int(np.floor((n - 1) * p)), n - 2)
        density = 1.0 / ((n - 1) * (data[k + 1] - data[k]))
        sd = math.sqrt(p * (1 - p) / big_n) / density
        assert abs(np.quantile(x, p) - q) < 4 * sd, (p, np.quantile(x, p), q, sd)
        # and the share of draws at or below the data quantile is p (binomial sd)
        share = np.mean(x <= q)
        assert abs(share - p) < 4 * math.sqrt(p * (1 - p) / big_n), (p, share)


def test_expected_value_is_the_mean_of_the_quantile_function(tmp_path):
    d = load_config(write_study(tmp_path)).tolerances[0].distribution
    u = (np.arange(1_000_000) + 0.5) / 1_000_000  # midpoint rule on (0, 1)
    mean = np.interp(u * (len(d.data) - 1), np.arange(len(d.data)), d.data).mean()
    assert d.expected == pytest.approx(mean, rel=1e-9)


def test_unit_suffix_and_hash(tmp_path):
    values = measured()
    c = load_config(write_study(tmp_path))
    d = c.tolerances[0].distribution
    assert d.data_sha256 == hashlib.sha256((tmp_path / "rail_rotation.csv").read_bytes()
                                           ).hexdigest()
    assert c.data_files == {"rail_rotation.csv": d.data_sha256}
    # the same values in arcmin, read with column_arcmin, give the same distribution
    (tmp_path / "arcmin").mkdir()
    csv = "rotation\n" + "".join(f"{60 * float(v)!r}\n" for v in values)
    path = write_study(tmp_path / "arcmin", csv=csv)
    path.write_text(path.read_text().replace("column_deg", "column_arcmin"))
    assert_allclose(load_config(path).tolerances[0].distribution.data, d.data, rtol=1e-14)
    # a pinned hash that matches is accepted
    load_config(write_study(tmp_path, extra=f'\nsha256 = "{d.data_sha256}"'))


def test_path_is_relative_to_the_config_file(tmp_path, monkeypatch):
    path = write_study(tmp_path)
    monkeypatch.chdir("/")
    assert load_config(path).tolerances[0].distribution.kind == "empirical"


def bad(tmp_path, **kw):
    with pytest.raises(ConfigError) as info:
        load_config(write_study(tmp_path, **kw))
    msg = str(info.value)
    assert "\n" not in msg
    return msg


def test_missing_file(tmp_path):
    path = write_study(tmp_path)
    (tmp_path / "rail_rotation.csv").unlink()
    with pytest.raises(ConfigError, match=r"study.toml:14: tolerances.bottom_rotation.file = "
                                          r"'rail_rotation.csv': cannot read .*rail_rotation"):
        load_config(path)


@pytest.mark.parametrize("csv, line, needle", [
    ("rail,angle\nR1,0.1\n", 15, r"rail_rotation.csv:1: no column 'rotation' in the header "
                                 r"\('rail', 'angle'\)"),
    ("rotation\n" + "0.01\n" * 5 + "abc\n" + "0.02\n" * 10, 15,
     r"rail_rotation.csv:7: 'abc' is not a number"),
    ("rotation\n" + "0.01\n" * 5 + "nan\n" + "0.02\n" * 10, 15,
     r"rail_rotation.csv:7: 'nan' is not a finite number"),
    ("rotation\n" + "0.01\n0.02\n" * 4 + "\n", 15, r"8 values; at least 10 are needed"),
    ("", 15, r"the file is empty"),
    # 30 deg: beyond the pi/8 (22.5 deg) the static model accepts (a unit slip)
    ("rotation\n" + "0.1\n" * 10 + "30\n", 15, r"the data reach 0.1 .. 30 deg, beyond the "
                                               r"\+/-22.5 deg"),
])
def test_bad_data_one_line_error(tmp_path, csv, line, needle):
    msg = bad(tmp_path, csv=csv)
    assert re.match(rf"^.*study\.toml:{line}: tolerances\.bottom_rotation\.column_deg = "
                    r"'rotation': ", msg), msg
    assert re.search(needle, msg), msg


def test_changed_file_against_pinned_hash(tmp_path):
    msg = bad(tmp_path, extra='\nsha256 = "' + "0" * 64 + '"')
    assert re.search(r"study\.toml:16: tolerances\.bottom_rotation\.sha256 = '0+' but "
                     r"rail_rotation\.csv has SHA-256 [0-9a-f]{64}: the measured data changed",
                     msg), msg


def test_column_needs_a_unit(tmp_path):
    path = write_study(tmp_path)
    path.write_text(path.read_text().replace("column_deg", "column"))
    with pytest.raises(ConfigError, match=r"study.toml:15: tolerances.bottom_rotation.column "
                                          r"needs a unit suffix: one of column_rad"):
        load_config(path)
    path.write_text(path.read_text().replace("column =", "column_um ="))
    with pytest.raises(ConfigError, match=r"column_um has an unknown unit suffix"):
        load_config(path)  # a length unit for an angle source


def test_measured_gaps(tmp_path):
    # The initial gaps can be measured too; a negative gap (overlapping balls) is an error.
    path = write_study(tmp_path)
    gaps = tmp_path / "gaps.csv"
    gaps.write_text("gap\n" + "".join(f"{g}\n" for g in range(5, 65, 5)))
    path.write_text(path.read_text().replace(
        'initial_gap = { distribution = "uniform", low_um = 0.0, high_um = 100.0 }',
        'initial_gap = { distribution = "empirical", file = "gaps.csv", column_um = "gap" }'))
    c = load_config(path)
    assert c.train.initial_gap.data[0] == pytest.approx(5e-6, rel=1e-15)
    assert c.train.initial_gap.expected == pytest.approx(32.5e-6, rel=1e-12)  # symmetric data
    assert list(c.data_files) == ["gaps.csv", "rail_rotation.csv"]
    gaps.write_text("gap\n-1\n" + "".join(f"{g}\n" for g in range(5, 65, 5)))
    with pytest.raises(ConfigError, match=r"study.toml:9: train.initial_gap.column_um = 'gap' "
                                          r"holds -1 um: gaps must be >= 0"):
        load_config(path)
