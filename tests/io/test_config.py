"""Study config: TOML -> frozen dataclasses in SI, and one-line errors for bad files."""

import math
import re
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import special, stats

from tolsim.io.config import (
    ConfigError,
    default_config_text,
    load_config,
    parse_config,
    text_mismatch,
    with_study_settings,
)
from tolsim.physics.geometry import Bearing
from tolsim.study.spec import MAX_SEED, Distribution

CONFIGS = Path(__file__).resolve().parents[2] / "configs"

MINIMAL = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54

[motion]
groove_velocity_mm_per_s = 10.0
duration_s = 10.0

[train]
balls = 2
initial_gap = { distribution = "fixed", value_mm = 0.5 }

[loads]
normal_load_N = 200.0
side_force_ratio = [-0.6, 0.6]

[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.5

[study]
samples = 100
seed = 1
"""


def test_minimal_config_in_si():
    c = parse_config(MINIMAL)
    # [Lin2018] Table 1 bearing from the defaults and the 10 mm diameter.
    assert c.bearing == Bearing()
    assert c.motion.groove_velocity == pytest.approx(0.01, rel=1e-15)
    assert c.motion.duration == 10.0
    assert c.train.initial_gap.value == pytest.approx(5e-4, rel=1e-15)
    assert c.loads.side_load == pytest.approx((-120.0, 120.0), rel=1e-15)
    (tol,) = c.tolerances
    assert tol.source == "bottom_rotation" and tol.scope == "rail"
    assert tol.distribution.std == pytest.approx(math.radians(0.5), rel=1e-15)
    assert c.study.samples == 100 and c.study.velocity_model == "analytic"
    assert c.text == MINIMAL


def test_stroke_converted_to_duration():
    text = MINIMAL.replace("duration_s = 10.0", "stroke_mm = 50.0")
    assert parse_config(text).motion.duration == pytest.approx(5.0, rel=1e-14)


def test_yaw_moment_distribution_is_linear_and_balanced():
    # Rigid carriage: N_x,j = M z_j / sum z_j^2, so sum N_x,j z_j = M and sum N_x,j = 0.
    text = MINIMAL.replace("side_force_ratio = [-0.6, 0.6]", "yaw_moment_N_m = 12.0").replace(
        "balls = 2", "balls = 5")
    c = parse_config(text)
    z = c.train.slot_positions(2 * c.bearing.ball_radius)
    nx = np.asarray(c.loads.side_load)
    assert_allclose(np.sum(nx * z), 12.0, rtol=1e-12)
    assert_allclose(np.sum(nx), 0.0, atol=1e-9)
    assert nx[0] < 0 < nx[-1]  # positive yaw: trailing ball pushed to -x


def test_default_config_is_packaged_and_valid():
    c = load_config()
    assert c.text == default_config_text()
    assert c.study.samples >= 10_000
    assert c.train.balls >= 2


def test_load_config_is_what_tolsim_ball_needs():
    c = load_config()
    assert isinstance(c.bearing, Bearing)
    assert c.motion.groove_velocity > 0


def test_with_overrides():
    c = parse_config(MINIMAL).with_overrides(samples=7, seed=9)
    assert (c.study.samples, c.study.seed) == (7, 9)
    with pytest.raises(ValueError, match="samples"):
        parse_config(MINIMAL).with_overrides(samples=0)


def test_cpk_band_std():
    # Cpk = min(USL - mu, mu - LSL) / (3 sigma): a centred +/-3 um band at Cpk 1 has sigma = 1 um.
    text = MINIMAL.replace('distribution = "normal"\nstd_deg = 0.5',
                           'distribution = "cpk"\nlow_deg = -3\nhigh_deg = 3\ncpk = 1.5')
    d = parse_config(text).tolerances[0].distribution
    assert d.std == pytest.approx(math.radians(3) / 4.5, rel=1e-14)


def test_distributions_from_normal_match_scipy(rng):
    z = rng.standard_normal(50_000)
    # uniform: Phi(z) ~ U(0, 1); KS test against scipy's uniform on [2, 5].
    u = Distribution("uniform", low=2.0, high=5.0).from_normal(z)
    assert stats.kstest(u, stats.uniform(2, 3).cdf).pvalue > 1e-3
    t = Distribution("truncated_normal", mean=1.0, std=2.0, low=0.0, high=3.0).from_normal(z)
    ref = stats.truncnorm((0 - 1) / 2, (3 - 1) / 2, loc=1, scale=2)
    assert stats.kstest(t, ref.cdf).pvalue > 1e-3
    assert t.min() >= 0.0 and t.max() <= 3.0
    # expected value of the truncated normal against scipy's, to round-off
    d = Distribution("truncated_normal", mean=1.0, std=2.0, low=0.0, high=3.0)
    assert d.expected == pytest.approx(ref.mean(), rel=1e-12)


def _tail_moments(a, b):
    """Mean and standard deviation of N(0, 1) truncated to [a, b], 0 < a < b, by adaptive
    quadrature in y = x - a, whose weight exp(-a y - y^2 / 2) on [0, b - a] has
    exp(-a^2 / 2) taken out: no CDF near 1 or below the smallest double is formed, and the
    variance E[y^2] - E[y]^2 cancels only about a factor 2 (the closed form of Johnson, Kotz
    and Balakrishnan 1994, Eq. 13.134, cancels 1371 against 7e-4 at a = 37)."""
    from scipy.integrate import quad

    def moment(k):
        return quad(lambda y: y**k * math.exp(-a * y - 0.5 * y * y), 0.0, b - a, epsabs=0.0,
                    epsrel=1e-13, limit=200)[0]

    m0, m1, m2 = moment(0), moment(1), moment(2)
    return a + m1 / m0, math.sqrt(m2 / m0 - (m1 / m0) ** 2)


@pytest.mark.parametrize("a, b", [(3.0, 4.0), (8.5, 9.0), (10.0, 20.0), (37.0, 38.0)])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_truncated_normal_in_a_tail(rng, a, b, side):
    # A band wholly on one side of the mean (a production shift, a sorted grade): beyond
    # about 8.3 std Phi(a) and Phi(b) both round to 1, and the draws were once all at the
    # band's far end (a [10, 20] std band: every draw 20 std, the mean infinite). Against
    # the quadrature of _tail_moments: the mean to 1e-12, the standard deviation to 1e-6
    # (scipy's truncnorm.std, measured: 1.2e-7 off at 37 std, 4e-11 at 10), and 200 000
    # draws within the band, spread over it, with their mean within 4 standard errors and
    # their standard deviation within 2 %.
    from tolsim.study.analyses.worst_case import standard_deviation

    mean, std = 2.0, 0.5
    low, high = sorted((mean + side * std * a, mean + side * std * b))
    d = Distribution("truncated_normal", mean=mean, std=std, low=low, high=high)
    mills, unit_std = _tail_moments(a, b)
    assert d.one_sided
    assert d.expected == pytest.approx(mean + side * std * mills, rel=1e-12)
    assert standard_deviation(d) == pytest.approx(std * unit_std, rel=1e-6)
    x = d.from_normal(rng.standard_normal(200_000))
    assert x.min() >= low and x.max() <= high
    assert np.unique(x).size > 100_000
    assert abs(x.mean() - d.expected) <= 4 * std * unit_std / math.sqrt(x.size)
    assert x.std() == pytest.approx(std * unit_std, rel=0.02)


def test_truncated_normal_across_its_mean_keeps_the_direct_inverse_cdf(rng):
    # Every packaged config's truncated normal lies across its mean: those draws are the
    # inverse CDF on [Phi(a), Phi(b)], bit for bit (their results do not change).
    z = rng.standard_normal(1000)
    for low, high in ((-0.25e-6, 0.25e-6), (0.0, 1e-6), (-1e-6, 0.0)):
        d = Distribution("truncated_normal", mean=0.0, std=0.1e-6, low=low, high=high)
        lo, hi = special.ndtr(low / 0.1e-6), special.ndtr(high / 0.1e-6)
        direct = np.clip(0.1e-6 * special.ndtri(lo + (hi - lo) * special.ndtr(z)), low, high)
        assert not d.one_sided
        assert np.array_equal(d.from_normal(z), direct)


# ---------------------------------------------------------------------------------------------
# Malformed configs: (replace this, with that) -> the error names this key (and line).
# ---------------------------------------------------------------------------------------------
BAD = [
    ("unknown_key", ("conformity = 0.54", "conformity = 0.54\ncolour = 'red'"),
     "bearing.colour", 4),
    ("wrong_type", ("balls = 2", "balls = 'two'"), "train.balls", 10),
    ("float_for_int", ("samples = 100", "samples = 100.5"), "study.samples", 22),
    ("negative_std", ("std_deg = 0.5", "std_deg = -0.5"), "tolerances.bottom_rotation.std_deg",
     19),
    ("missing_section", ("[motion]\ngroove_velocity_mm_per_s = 10.0\nduration_s = 10.0\n", ""),
     "motion", None),
    ("missing_unit", ("ball_diameter_mm = 10.0", "ball_diameter = 10.0"),
     "bearing.ball_diameter", 2),
    ("wrong_unit", ("duration_s = 10.0", "duration_mm = 10.0"), "motion.duration_mm", 7),
    ("two_units", ("ball_diameter_mm = 10.0", "ball_diameter_mm = 10.0\nball_diameter_m = 0.01"),
     "bearing.ball_diameter_m", 2),
    ("bad_model", ("seed = 1", "seed = 1\nvelocity_model = 'magic'"), "study.velocity_model",
     24),
    ("negative_seed", ("seed = 1", "seed = -1"), "study.seed", 23),
    # issue 26, item 5: a seed the result file cannot store (uint64), refused at load time
    ("seed_beyond_uint64", ("seed = 1", "seed = 18446744073709551616"), "study.seed", 23),
    ("zero_samples", ("samples = 100", "samples = 0"), "study.samples", 22),
    ("unknown_source", ("[tolerances.bottom_rotation]", "[tolerances.rail_wobble]"),
     "tolerances.rail_wobble", 17),
    ("bad_distribution", ('distribution = "normal"', 'distribution = "lognormal"'),
     "tolerances.bottom_rotation.distribution", 18),
    ("loads_length", ("side_force_ratio = [-0.6, 0.6]", "side_force_ratio = [-0.6, 0.6, 0.1]"),
     "loads.side_force_ratio", 15),
    ("negative_load", ("normal_load_N = 200.0", "normal_load_N = -200.0"),
     "loads.normal_load_N", 14),
    ("conformity_range", ("conformity = 0.54", "conformity = 0.45"), "bearing.conformity", 3),
    ("unknown_section", ("[study]", "[plot]\ncolour = 1\n[study]"), "plot", 21),
    ("negative_gap", ("value_mm = 0.5", "value_mm = -0.5"), "train.initial_gap.value_mm", 11),
    ("bool_as_number", ("seed = 1", "seed = true"), "study.seed", 23),
    ("wrong_scope", ('std_deg = 0.5', 'std_deg = 0.5\nscope = "everywhere"'),
     "tolerances.bottom_rotation.scope", 20),
    ("corr_without_rail", ('std_deg = 0.5', 'std_deg = 0.5\nscope = "carriage"\n'
                           'correlation_length_mm = 5'),
     "tolerances.bottom_rotation.correlation_length_mm", 21),
    # a truncated normal a million times wider than its band is a uniform one; at 1e300 its
    # band's probability rounded to 0 and every draw was NaN
    ("truncated_std_beyond_band", ('distribution = "normal"\nstd_deg = 0.5',
                                   'distribution = "truncated_normal"\nstd_deg = 2e6\n'
                                   'low_deg = -0.5\nhigh_deg = 0.5'),
     "tolerances.bottom_rotation.std_deg", 19),
    ("uniform_reversed", ('distribution = "normal"\nstd_deg = 0.5',
                          'distribution = "uniform"\nlow_deg = 1\nhigh_deg = -1'),
     "tolerances.bottom_rotation.high_deg", 20),
    ("syntax", ("balls = 2", "balls = = 2"), "invalid TOML", None),
    ("stroke_and_duration", ("duration_s = 10.0", "duration_s = 10.0\nstroke_mm = 5"),
     "motion.stroke_mm", 8),
    ("sensitivity_one_sample", ("seed = 1", "seed = 1\nsensitivity_samples = 1"),
     "study.sensitivity_samples", 24),
    # issue 17: a bare fraction is ambiguous (0.5 meant as 0.5 % gave "Cpk 134")
    ("limit_without_unit", ("seed = 1", "seed = 1\nvelocity_deviation_limit = 0.5"),
     "study.velocity_deviation_limit", 24),
    ("probability_limit_without_unit", ("seed = 1", "seed = 1\ncontact_probability_limit = 0.01"),
     "study.contact_probability_limit", 24),
    ("range_without_unit", ("seed = 1", "seed = 1\nvelocity_deviation_range = [-0.02, 0.02]"),
     "study.velocity_deviation_range", 24),
    ("limit_of_100_percent", ("seed = 1", "seed = 1\nvelocity_deviation_limit_percent = 100"),
     "study.velocity_deviation_limit_percent", 24),
    ("probability_above_100_percent", ("seed = 1",
                                       "seed = 1\ncontact_probability_limit_percent = 101"),
     "study.contact_probability_limit_percent", 24),
    ("limit_bad_unit", ("seed = 1", "seed = 1\nvelocity_deviation_limit_permille = 5"),
     "study.velocity_deviation_limit_permille", 24),
    # issue 17: a unit slip (std_mm for std_um) beyond the static model's range, at load time
    ("std_mm_for_std_um", ('[tolerances.bottom_rotation]\ndistribution = "normal"\n'
                           'std_deg = 0.5', '[tolerances.arc_centre_offset_tangential_BL]\n'
                                            'distribution = "normal"\nstd_mm = 1.0'),
     "tolerances.arc_centre_offset_tangential_BL.std_mm", 19),
    ("std_mm_inline", ('[tolerances.bottom_rotation]\ndistribution = "normal"\nstd_deg = 0.5',
                       '[tolerances]\narc_centre_offset_normal_TL = { distribution = "normal", '
                       'std_mm = 1.0 }'),
     "tolerances.arc_centre_offset_normal_TL.std_mm", 18),
    ("band_in_mm", ('distribution = "normal"\nstd_deg = 0.5',
                    'distribution = "uniform"\nlow_deg = -1\nhigh_deg = 30'),
     "tolerances.bottom_rotation.high_deg", 20),
    ("quoted_key", ("std_deg = 0.5", '"std_deg" = -0.5'), "tolerances.bottom_rotation.std_deg",
     19),
    ("syntax_line", ("balls = 2", "balls = = 2"), "invalid TOML", 10),
    # issue 24: study.time_steps is "auto" or an integer >= 1
    ("time_steps_word", ("seed = 1", 'seed = 1\ntime_steps = "fine"'), "study.time_steps", 24),
    ("time_steps_zero", ("seed = 1", "seed = 1\ntime_steps = 0"), "study.time_steps", 24),
]


@pytest.mark.parametrize("replace_, key, line", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_config_one_line_error_naming_key(replace_, key, line):
    old, new = replace_
    assert old in MINIMAL
    text = MINIMAL.replace(old, new, 1)
    with pytest.raises(ConfigError) as info:
        parse_config(text, "bad.toml")
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith("bad.toml")
    assert key in msg
    if line is not None:
        assert re.match(rf"bad\.toml:{line}: ", msg), msg


def test_count_of_malformed_examples():
    assert len(BAD) >= 15


def test_largest_seed_is_accepted():
    # 2^64 - 1 is the largest seed the result file stores (uint64); the CLI's --seed and the
    # config's study.seed share the bound (tolsim.study.spec.MAX_SEED)
    text = MINIMAL.replace("seed = 1", f"seed = {2**64 - 1}")
    assert parse_config(text).study.seed == MAX_SEED == 2**64 - 1


def test_missing_file_is_config_error(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "nope.toml")


def test_a_config_saved_with_a_byte_order_mark_is_read(tmp_path):
    # Windows editors save "UTF-8 with BOM"; tomllib refused such a file at line 1 ("Invalid
    # statement"). The mark is not part of the text: the config and its stored text are
    # those of the file without it.
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + MINIMAL.encode())
    config = load_config(path)
    assert config == parse_config(MINIMAL, str(path))
    assert config.text == MINIMAL


@pytest.mark.parametrize("raw, where, byte", [
    (b"\xff\xfe[study]\n", ":1:", "0xff"),  # UTF-16
    (MINIMAL.encode() + b"# caf\xe9\n", f":{MINIMAL.count(chr(10)) + 1}:", "0xe9"),  # Latin-1
])
def test_a_config_that_is_not_utf8_is_one_line_with_its_line(tmp_path, raw, where, byte):
    # it said "cannot read config: UnicodeDecodeError: 'utf-8' codec can't decode ..."
    path = tmp_path / "bad.toml"
    path.write_bytes(raw)
    with pytest.raises(ConfigError) as exc:
        load_config(path)
    message = str(exc.value)
    assert message == (f"{path}{where} not UTF-8 text (byte {byte}): a TOML config is UTF-8 "
                       "text; save it as UTF-8")


def test_config_error_is_value_error():
    assert issubclass(ConfigError, ValueError)


# ---------------------------------------------------------------------------------------------
# Issue 17: unit-suffixed fractions, plausible tolerances, the effective config
# ---------------------------------------------------------------------------------------------
def test_fraction_keys_in_si():
    text = MINIMAL.replace("seed = 1", "seed = 1\nvelocity_deviation_limit_percent = 0.5\n"
                                       "contact_probability_limit_ppm = 250\n"
                                       "velocity_deviation_range_percent = [-3, 1.5]")
    st = parse_config(text).study
    # SI inside: fractions [-]; 0.5 % = 0.005, 250 ppm = 2.5e-4 (exact to a rounding)
    assert st.velocity_deviation_limit == pytest.approx(0.005, rel=1e-15)
    assert st.contact_probability_limit == pytest.approx(2.5e-4, rel=1e-15)
    assert st.velocity_deviation_range == pytest.approx((-0.03, 0.015), rel=1e-15)


def test_bare_fraction_error_says_the_new_key():
    text = MINIMAL.replace("seed = 1", "seed = 1\nvelocity_deviation_limit = 0.005")
    with pytest.raises(ConfigError) as info:
        parse_config(text, "bad.toml")
    msg = str(info.value)
    assert msg.startswith("bad.toml:24: study.velocity_deviation_limit = 0.005 has no unit")
    assert "velocity_deviation_limit_percent = 0.5 if 0.005 is a fraction" in msg


def test_default_config_limits_unchanged_by_the_rename():
    # default.toml: velocity_deviation_limit_percent = 0.5 (was the fraction 0.005), the
    # histogram range +/-2 % (was +/-0.02): the same SI values as before the rename
    st = load_config().study
    assert st.velocity_deviation_limit == 0.005
    assert st.velocity_deviation_range == (-0.02, 0.02)
    assert st.contact_probability_limit == 0.0


@pytest.mark.parametrize("std_um, ok", [(12.5, True), (12.6, False)])
def test_tolerance_range_edge(std_um, ok):
    # Table 1 bearing: (f - 1/2) D = 0.4 mm, a quarter is 100 um = 8 x 12.5 um
    text = MINIMAL.replace("[tolerances.bottom_rotation]\ndistribution = \"normal\"\n"
                           "std_deg = 0.5", "[tolerances.ball_oversize]\n"
                                            f"distribution = \"normal\"\nstd_um = {std_um}")
    if ok:
        parse_config(text)
    else:
        with pytest.raises(ConfigError, match=r"^x:19: tolerances.ball_oversize.std_um = 12.6: "
                                              r"mean \+/- 8 std reaches -100.8 .. 100.8 um"):
            parse_config(text, "x")


def test_with_overrides_writes_the_effective_text():
    base = parse_config(MINIMAL.replace("seed = 1", "seed = 1      # the seed"), "a.toml")
    c = base.with_overrides(samples=12345, seed=7)
    assert (c.study.samples, c.study.seed) == (12345, 7)
    changed = [(a, b) for a, b in zip(base.text.splitlines(), c.text.splitlines(), strict=True)
               if a != b]
    # only the two value lines change; the comment keeps its column
    assert changed == [("samples = 100", "samples = 12345"),
                       ("seed = 1      # the seed", "seed = 7      # the seed")]
    assert parse_config(c.text, "a.toml") == c  # the text is the study that runs
    assert base.with_overrides().text == base.text


@pytest.mark.parametrize("layout", [
    "[study]\nsamples = 100 # n\nseed = 1\n",
    "[ \"study\" ]\n\"samples\" = 100\nseed=1\n",
    "study.samples = 100\nstudy.seed = 1\n",
    "study = { samples = 100, seed = 1 }\n",
])
def test_with_overrides_any_study_layout(layout):
    body = MINIMAL.split("[study]")[0]
    text = (layout + body) if layout.startswith("study") else (body + layout)
    c = parse_config(text).with_overrides(samples=5, seed=99)
    again = parse_config(c.text)
    assert (again.study.samples, again.study.seed) == (5, 99)
    assert again == c


def test_with_overrides_default_config_round_trips():
    c = load_config().with_overrides(samples=3, seed=4)
    assert parse_config(c.text, "default.toml") == c


@pytest.mark.parametrize("call, message", [
    (lambda: parse_config(None), "<string>: the config text must be a str (the TOML document), "
                                 "not NoneType"),
    (lambda: parse_config(b"[study]"), "not bytes"),
    (lambda: load_config(5), "path = 5: a config file's path must be a str or os.PathLike"),
])
def test_config_readers_name_a_wrong_argument_type(call, message):
    # API audit, session 24: AttributeError 'NoneType' has no 'splitlines', tomllib's TypeError
    # for bytes, pathlib's for an int
    with pytest.raises(ConfigError, match=re.escape(message)):
        call()


def test_study_settings_are_changed_in_the_text_and_checked():
    # Session 24 left this: a config changed with dataclasses.replace is neither checked nor
    # recorded. with_study_settings edits [study] in the text and reads it again.
    import tolsim

    assert tolsim.with_study_settings is with_study_settings  # the README's name
    config = load_config()
    changed = with_study_settings(config, spot_checks=0, propagation="along_track",
                                  time_steps=12, velocity_deviation_limit=0.002)
    assert (changed.study.spot_checks, changed.study.propagation, changed.study.time_steps,
            changed.study.velocity_deviation_limit) == (0, "along_track", 12, 0.002)
    assert text_mismatch(changed) is None and changed.text != config.text
    # every other line stays; None removes a key (time_steps: back to the automatic step)
    back = with_study_settings(changed, time_steps=None)
    assert back.study.time_steps is None
    assert not [line for line in back.text.splitlines() if line.startswith("time_steps")]
    assert {line.split("#")[0].strip() for line in set(back.text.splitlines())
            - set(config.text.splitlines())} == {  # values changed, comments kept
        "spot_checks = 0", 'propagation = "along_track"',
        "velocity_deviation_limit_percent = 0.2"}
    # values are checked as in a file, naming the key
    with pytest.raises(ConfigError, match=r"study.spot_checks = -1 must be >= 0"):
        with_study_settings(config, spot_checks=-1)
    with pytest.raises(ConfigError, match=r"study.nonsense is not a known key"):
        with_study_settings(config, nonsense=3)
    with pytest.raises(ConfigError, match="samples_per_level has no effect with estimator"):
        with_study_settings(config, samples_per_level=100)
    with pytest.raises(ConfigError, match="a point of a sweep"):
        with_study_settings(load_config(CONFIGS / "sweep_preload.toml").sweep.points[0],
                            samples=5)


def test_text_mismatch_names_the_setting_the_text_does_not_say():
    from dataclasses import replace

    config = load_config(CONFIGS / "carriage_preload.toml")
    assert text_mismatch(config) is None
    assert text_mismatch(config.with_overrides(samples=77, seed=3)) is None
    sweep = load_config(CONFIGS / "sweep_preload.toml")
    assert text_mismatch(sweep) is None
    assert {text_mismatch(p) for p in sweep.sweep.points} == {None}
    assert text_mismatch(replace(config, study=replace(config.study, time_steps=7))) == (
        "config.study.time_steps = 7, but its text gives None")
    bearing = replace(config.bearing, friction_coefficient=0.2)
    assert text_mismatch(replace(config, bearing=bearing)) == (
        "config.bearing.friction_coefficient = 0.2, but its text gives 0.1")
    assert text_mismatch(replace(config, text="[study\n")).startswith(
        "the config's text is not a valid config")


def test_study_settings_edge_cases_of_the_text():
    # audit of with_study_settings (session 25, /tmp/s25/audit/FINDINGS.md D1-D5, C1-C3)
    head = MINIMAL[:MINIMAL.index("[study]")]
    # D5: a comment with an odd number of triple quotes hid every later line
    quoted = parse_config(MINIMAL.replace("[train]", "# strings may use ''' quotes\n[train]"))
    assert quoted.with_overrides(samples=5).study.samples == 5
    assert with_study_settings(quoted, spot_checks=1).study.spot_checks == 1
    # D1: [study] as dotted keys or an inline table: a key it lacks is refused, named
    for text in ("study.samples = 100\nstudy.seed = 1\n" + head,
                 "study = { samples = 100, seed = 1 }\n" + head):
        config = parse_config(text)
        assert with_study_settings(config, samples=7).study.samples == 7  # a key it has
        with pytest.raises(ConfigError, match="study.spot_checks: the text gives .study. as "
                                              "dotted keys or an inline table"):
            with_study_settings(config, spot_checks=1)
    # D4: no [study] at all (tolsim carriage reads such configs)
    with pytest.raises(ConfigError, match=r"the text has no \[study\] table to add "
                                          r"study.samples to"):
        with_study_settings(parse_config(head, study=False), samples=5)
    # D2: an array value is not silently left as it was
    ranged = parse_config(MINIMAL + "velocity_deviation_range_percent = [-1, 1]\n")
    for value in (None, (-0.02, 0.02)):
        with pytest.raises(ConfigError, match="study.velocity_deviation_range"):
            with_study_settings(ranged, velocity_deviation_range=value)
    # D3: a fraction is a number
    for value in (True, "0.5"):
        with pytest.raises(ConfigError, match="must be a number"):
            with_study_settings(ranged, velocity_deviation_limit=value)
    # a fraction in one form only (with and without its unit, the order decided)
    with pytest.raises(ConfigError, match="study.velocity_deviation_limit_percent: give "
                                          "velocity_deviation_limit as a fraction"):
        with_study_settings(ranged, velocity_deviation_limit_percent=None)
    # C1: the shortest decimal that reads back exactly
    ppm = parse_config(MINIMAL + "velocity_deviation_limit_ppm = 1000\n")
    changed = with_study_settings(ppm, velocity_deviation_limit=0.002)
    assert "velocity_deviation_limit_ppm = 2000.0\n" in changed.text
    assert changed.study.velocity_deviation_limit == 0.002
    # C2, C3: keys added at the end of [study] in the order given, with the text's line ends;
    # a removed key takes the comment lines that continue it
    crlf = parse_config((MINIMAL + "time_steps = 9   # a step\n    # its note\n")
                        .replace("\n", "\r\n"))
    changed = with_study_settings(crlf, sampling="sobol", spot_checks=2, time_steps=None)
    assert changed.text.endswith('seed = 1\r\nsampling = "sobol"\r\nspot_checks = 2\r\n')
    assert "\n" not in changed.text.replace("\r\n", "")


def test_text_mismatch_of_sweep_points_checks_their_order(tmp_path):
    # audit D9: points permuted with dataclasses.replace were accepted (a point had only to
    # match some point of the text)
    from dataclasses import replace

    sweep = load_config(CONFIGS / "sweep_yaw_moment.toml")
    points = sweep.sweep.points
    reversed_points = replace(sweep, sweep=sweep.sweep.with_points(tuple(reversed(points))))
    assert text_mismatch(reversed_points) == (
        "the config's sweep points are not those of its text (in order)")
    assert text_mismatch(points[1], 1) is None
    assert text_mismatch(points[1], 0).startswith("config.loads")
    # D6: an override of a swept study key would collapse the sweep
    swept = parse_config(MINIMAL + '\n[sweep]\n"study.seed" = [1, 2]\n', "sw.toml")
    with pytest.raises(ValueError, match="seed = 5: the sweep varies study.seed"):
        swept.with_overrides(seed=5)
    assert swept.with_overrides(samples=50).sweep.points[1].study.seed == 2


def test_text_mismatch_reads_data_files_as_the_config_read_them(tmp_path):
    # audit D8: the read-back read the measured data from the disk again, so a file edited
    # or out of reach (another working directory) after the run made the result unwritable.
    # The data are taken by their SHA-256, which the result file records.
    data = tmp_path / "d.csv"
    data.write_text("rotation_deg\n" + "\n".join(str(0.01 * i) for i in range(40)) + "\n")
    (tmp_path / "s.toml").write_text(MINIMAL.replace(
        'distribution = "normal"\nstd_deg = 0.5',
        'distribution = "empirical"\nfile = "d.csv"\ncolumn_deg = "rotation_deg"'))
    config = load_config(tmp_path / "s.toml")
    data.write_text("rotation_deg\n" + "\n".join(str(0.02 * i) for i in range(40)) + "\n")
    assert text_mismatch(config) is None
    data.unlink()
    assert text_mismatch(config) is None
