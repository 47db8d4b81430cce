"""Correlated tolerance sources: a Gaussian copula sampled through the per-block generators.

Sampling errors used below (n independent pairs):
- Pearson r of bivariate normals: sd(r) ~ (1 - rho^2) / sqrt(n) (Fisher 1915; Stuart & Ord,
  Kendall's Advanced Theory of Statistics, Vol. 1, Sec. 16.31);
- Spearman r_s of a Gaussian copula: E r_s ~ (6 / pi) asin(rho / 2) (Kruskal 1958, JASA 53,
  814, Eq. 4.7), and atanh(r_s) has sd ~ sqrt(1.06 / (n - 3)) (Fieller, Hartley & Pearson
  1957, Biometrika 44, 470).
Each check allows 4 sd (a false alarm about once in 16 000 runs; the draws are seeded, so a
run is reproducible).
"""

import re

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from scipy import stats

from tolsim.io.config import ConfigError, parse_config
from tolsim.study.sampling import error_values, sample_block
from tolsim.study.spec import Correlation

BASE = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
[motion]
groove_velocity_mm_per_s = 100.0
stroke_mm = 100.0
[train]
balls = 5
initial_gap = { distribution = "uniform", low_um = 0.0, high_um = 100.0 }
[loads]
normal_load_N = 200.0
[tolerances.top_rotation]
distribution = "normal"
std_deg = 0.1
[tolerances.arc_centre_offset_tangential_TR]
distribution = "normal"
mean_um = 0.5
std_um = 2.0
[tolerances.arc_centre_offset_tangential_TL]
distribution = "cpk"
low_um = -3.0
high_um = 3.0
cpk = 1.0
truncate = true
[tolerances.arc_centre_offset_tangential_BL]
distribution = "normal"
std_um = 1.0
correlation_length_mm = 50.0
[tolerances.arc_centre_offset_tangential_BR]
distribution = "uniform"
low_um = -2.0
high_um = 2.0
correlation_length_mm = 50.0
[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.1
scope = "rail"
[tolerances.ball_oversize]
distribution = "normal"
std_um = 0.1
{correlation}
[study]
samples = 8192
seed = 17
block_size = 8192
sampling = "{sampling}"
propagation = "{propagation}"
"""

CARRIAGE = """\
[[correlation]]   # one carriage: its profile rotation and the two top flanks
sources = ["top_rotation", "arc_centre_offset_tangential_TR", "arc_centre_offset_tangential_TL"]
matrix = [[1.0, 0.6, -0.3],
          [0.6, 1.0, 0.5],
          [-0.3, 0.5, 1.0]]
"""
FLANKS = """\
[[correlation]]   # the two flanks of one ground rail groove (random fields, l = 50 mm)
sources = ["arc_centre_offset_tangential_BL", "arc_centre_offset_tangential_BR"]
coefficient = 0.8
"""


def config(correlation=CARRIAGE + FLANKS, sampling="random", propagation="constant"):
    text = (BASE.replace("{correlation}", correlation).replace("{sampling}", sampling)
            .replace("{propagation}", propagation))
    return parse_config(text, "corr.toml")


def values(c, **kw):
    return error_values(c, sample_block(c, 0), **kw)


def pearson_tolerance(rho, n):
    return 4 * (1 - rho**2) / np.sqrt(n)


def test_config_reads_the_groups():
    c = config()
    carriage, flanks = c.correlations
    assert carriage.sources[0] == "top_rotation" and carriage.matrix[0][2] == -0.3
    assert flanks.matrix == ((1.0, 0.8), (0.8, 1.0))
    L = carriage.cholesky
    np.testing.assert_allclose(L @ L.T, np.asarray(carriage.matrix), atol=1e-15)


def test_carriage_group_recovers_pearson_matrix():
    # Normal marginals (top_rotation, TR): Pearson r of the values = the matrix entry.
    c = config()
    v = values(c)
    n = 8192
    x, y = v["top_rotation"][:, 0], v["arc_centre_offset_tangential_TR"][:, 0]
    r = np.corrcoef(x, y)[0, 1]
    assert abs(r - 0.6) < pearson_tolerance(0.6, n), r
    # the marginals stay what they were: mean 0.5 um, std 2 um (4 standard errors)
    assert abs(y.mean() - 0.5e-6) < 4 * 2e-6 / np.sqrt(n)
    assert abs(y.std() / 2e-6 - 1) < 4 / np.sqrt(2 * n)


def test_non_normal_marginal_keeps_rank_correlation():
    # TL is a truncated cpk band: the Spearman correlation with its partners is the Gaussian
    # copula's (6/pi) asin(rho/2), whatever the (monotone) marginal.
    v = values(config())
    n = 8192
    tl = v["arc_centre_offset_tangential_TL"][:, 0]
    assert tl.min() >= -3e-6 and tl.max() <= 3e-6
    for partner, rho in (("top_rotation", -0.3), ("arc_centre_offset_tangential_TR", 0.5)):
        rs = stats.spearmanr(tl, v[partner][:, 0]).statistic
        expected = 6 / np.pi * np.arcsin(rho / 2)
        assert abs(np.arctanh(rs) - np.arctanh(expected)) < 4 * np.sqrt(1.06 / (n - 3)), (
            partner, rs, expected)


@pytest.mark.parametrize("propagation", ["constant", "along_track"])
def test_rail_fields_are_cross_correlated(propagation):
    # BL (normal) and BR (uniform) are random fields of one correlation length: at the same
    # rail position their normals correlate with rho = 0.8, so the pair's Spearman
    # correlation is the copula's. Checked per ball (trains are independent, the balls of a
    # train are not), at ball 0 and ball 4.
    c = config(propagation=propagation)
    b = sample_block(c, 0)
    v = error_values(c, b)
    n = 8192
    bl, br = v["arc_centre_offset_tangential_BL"], v["arc_centre_offset_tangential_BR"]
    for ball in (0, 4):
        rs = stats.spearmanr(bl[:, ball], br[:, ball]).statistic
        expected = 6 / np.pi * np.arcsin(0.8 / 2)
        assert abs(np.arctanh(rs) - np.arctanh(expected)) < 4 * np.sqrt(1.06 / (n - 3)), rs
    # the BL field's own correlation along the rail is unchanged (first source: L[0,0] = 1)
    plain = config(correlation="", propagation=propagation)
    assert_array_equal(error_values(plain, sample_block(plain, 0))[
        "arc_centre_offset_tangential_BL"], bl)


def test_uncorrelated_sources_are_untouched():
    # Sources outside every group, and the first source of each group, get exactly the values
    # they have without the [[correlation]] tables: the copula only mixes the later ones.
    a, b = values(config()), values(config(correlation=""))
    for name in ("bottom_rotation", "ball_oversize", "top_rotation",
                 "arc_centre_offset_tangential_BL"):
        assert_array_equal(a[name], b[name], err_msg=name)
    assert not np.array_equal(a["arc_centre_offset_tangential_TR"],
                              b["arc_centre_offset_tangential_TR"])


@pytest.mark.parametrize("sampling", ["sobol", "lhs"])
def test_quasi_random_designs_are_correlated_too(sampling):
    v = values(config(sampling=sampling))
    r = np.corrcoef(v["top_rotation"][:, 0], v["arc_centre_offset_tangential_TR"][:, 0])[0, 1]
    assert abs(r - 0.6) < pearson_tolerance(0.6, 8192), r


@pytest.mark.parametrize("propagation", ["constant", "along_track"])
def test_chunking_does_not_change_correlated_values(propagation):
    # 3000 samples in blocks of 1024 (the last partial): drawn together or one by one, the
    # correlated values are bit-identical (elementwise combination, fixed order).
    text = config(propagation=propagation).text.replace("block_size = 8192",
                                                        "block_size = 1024")
    c = parse_config(text).with_overrides(samples=3000)
    together = error_values(c, sample_block(c, 0, 3))
    alone = [error_values(c, sample_block(c, k)) for k in range(3)]
    for name in together:
        assert_array_equal(together[name], np.concatenate([a[name] for a in alone]),
                           err_msg=name)


def test_python_api_validates():
    with pytest.raises(ValueError, match="positive definite"):
        Correlation(("top_rotation", "top_offset_x"), ((1.0, 1.0), (1.0, 1.0)))
    with pytest.raises(ValueError, match="repeat"):
        Correlation(("top_rotation", "top_rotation"), ((1.0, 0.5), (0.5, 1.0)))


# ---------------------------------------------------------------------------------------------
# Bad groups: one line, file:line, the key
# ---------------------------------------------------------------------------------------------
def _group(sources, rest="coefficient = 0.5"):
    return "[[correlation]]\nsources = [" + ", ".join(f'"{s}"' for s in sources) + "]\n" + rest


BAD = [
    ("unknown_source", _group(["top_rotation", "rail_wobble"]), "correlation[1].sources",
     "not a known error source"),
    ("not_in_tolerances", _group(["top_rotation", "top_offset_x"]), "correlation[1].sources",
     "no [tolerances.top_offset_x]"),
    ("one_source", _group(["top_rotation"]), "correlation[1].sources", "at least two"),
    ("rail_with_carriage", _group(["top_rotation", "bottom_rotation"]),
     "correlation[1].sources", "one value per carriage and one value per rail"),
    ("field_with_value", _group(["arc_centre_offset_tangential_BL", "bottom_rotation"]),
     "correlation[1].sources", "rail random field"),
    ("ball_with_carriage", _group(["ball_oversize", "top_rotation"]),
     "correlation[1].sources", "one value per ball"),
    ("coefficient_one", _group(["top_rotation", "arc_centre_offset_tangential_TR"],
                               "coefficient = 1.0"),
     "correlation[1].coefficient", "not positive definite"),
    ("coefficient_too_large", _group(["top_rotation", "arc_centre_offset_tangential_TR"],
                                     "coefficient = 1.5"),
     "correlation[1].coefficient", "within [-1, 1]"),
    ("not_positive_definite", _group(
        ["top_rotation", "arc_centre_offset_tangential_TR", "arc_centre_offset_tangential_TL"],
        "matrix = [[1, 0.9, -0.9], [0.9, 1, 0.9], [-0.9, 0.9, 1]]"),
     "correlation[1].matrix", "not positive definite"),
    ("asymmetric", _group(["top_rotation", "arc_centre_offset_tangential_TR"],
                          "matrix = [[1, 0.5], [0.4, 1]]"),
     "correlation[1].matrix", "symmetric"),
    ("diagonal", _group(["top_rotation", "arc_centre_offset_tangential_TR"],
                        "matrix = [[2, 0.5], [0.5, 1]]"),
     "correlation[1].matrix", "unit diagonal"),
    ("shape", _group(["top_rotation", "arc_centre_offset_tangential_TR"],
                     "matrix = [[1, 0.5, 0], [0.5, 1, 0], [0, 0, 1]]"),
     "correlation[1].matrix", "must be 2 x 2"),
    ("both", _group(["top_rotation", "arc_centre_offset_tangential_TR"],
                    "coefficient = 0.5\nmatrix = [[1, 0.5], [0.5, 1]]"),
     "correlation[1].coefficient", "exactly one"),
    ("unknown_key", _group(["top_rotation", "arc_centre_offset_tangential_TR"],
                           "coefficient = 0.5\nmethod = 'gauss'"),
     "correlation[1].method", "not a known key"),
    ("twice", _group(["top_rotation", "arc_centre_offset_tangential_TR"]) + "\n"
     + _group(["arc_centre_offset_tangential_TL", "top_rotation"]),
     "correlation[2].sources", "already in correlation[1]"),
    ("single_table", "[correlation]\nsources = []", "correlation", "[[correlation]]"),
]


@pytest.mark.parametrize("group, key, needle", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_correlation_one_line_error(group, key, needle):
    text = BASE.replace("{correlation}", group + "\n").replace("{sampling}", "random").replace(
        "{propagation}", "constant")
    with pytest.raises(ConfigError) as info:
        parse_config(text, "bad.toml")
    msg = str(info.value)
    assert "\n" not in msg
    m = re.match(r"bad\.toml:(\d+): (\S+)", msg)
    assert m, msg
    assert m.group(2) == key, msg
    assert needle in msg, msg
    # the line is that of the key in the failing [[correlation]] table (or its header)
    line = text.splitlines()[int(m.group(1)) - 1]
    last = key.rpartition(".")[2] if "." in key else "correlation"
    assert line.lstrip().lstrip("[").startswith(last), (line, msg)


def test_fixed_source_cannot_be_correlated():
    text = BASE.replace('mean_um = 0.5\nstd_um = 2.0', 'std_um = 0.0').replace(
        "{correlation}", _group(["top_rotation", "arc_centre_offset_tangential_TR"]) + "\n"
    ).replace("{sampling}", "random").replace("{propagation}", "constant")
    with pytest.raises(ConfigError, match=r"^x:\d+: correlation\[1\]\.sources .* not random"):
        parse_config(text, "x")


def test_fields_of_different_length_cannot_be_correlated():
    text = BASE.replace("correlation_length_mm = 50.0\n[tolerances.bottom_rotation]",
                        "correlation_length_mm = 20.0\n[tolerances.bottom_rotation]").replace(
        "{correlation}", FLANKS).replace("{sampling}", "random").replace(
        "{propagation}", "constant")
    with pytest.raises(ConfigError, match="correlation_length 0.02 m and a rail random field "
                                          "of correlation_length 0.05 m"):
        parse_config(text, "x")
