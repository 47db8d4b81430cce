"""Issue 26 ("Nothing accepted silently"): plausibility of every physical key, the Hertz
pressure limit, and the messages of item 10.

Impossible values are one-line errors with exit code 2 and no output file; unusual ones are
one-line warnings (:class:`tolsim.io.config.reader.ConfigWarning`). The ranges are
:data:`tolsim.io.config.plausibility.RANGES`.
"""

import json
import os
import warnings
from pathlib import Path

import numpy as np
import pytest
from test_cli_carriage import CARRIAGE, HEAD
from test_config import MINIMAL

from tolsim.cli import main
from tolsim.io.config import ConfigError, load_config, parse_config
from tolsim.io.config.plausibility import MAX_HERTZ_PRESSURE, RANGES, range_rows, ranges_markdown
from tolsim.io.config.reader import ConfigWarning, show
from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants

ROOT = Path(__file__).resolve().parents[2]
CONFIGS = ROOT / "configs"
CARRIAGE_CONFIG = HEAD + CARRIAGE
SWEEP = '\n[sweep]\n'
#: Two sources drawn alike (one value per rail) with an asymmetric matrix, before [study].
CORRELATED = ('[tolerances.arc_centre_offset_tangential_BL]\ndistribution = "normal"\n'
              'std_um = 1.0\n\n[[correlation]]\nsources = ["bottom_rotation", '
              '"arc_centre_offset_tangential_BL"]\nmatrix = [[1.0, 0.5], [0.4, 1.0]]\n\n'
              '[study]')

#: (id, base text, (old, new) replacement, key named in the message). Every one loads with
#: exit 0 and no message before issue 26 unless marked "was" (then the message was poorer).
BAD = [
    # [bearing]: geometry and material
    ("ball_10_m", MINIMAL, ("ball_diameter_mm = 10.0", "ball_diameter_m = 10"),
     "bearing.ball_diameter_m"),
    ("ball_200_mm", MINIMAL, ("ball_diameter_mm = 10.0", "ball_diameter_mm = 200"),
     "bearing.ball_diameter_mm"),
    ("ball_0.1_mm", MINIMAL, ("ball_diameter_mm = 10.0", "ball_diameter_mm = 0.1"),
     "bearing.ball_diameter_mm"),
    ("ball_10_um", MINIMAL, ("ball_diameter_mm = 10.0", "ball_diameter_um = 10"),
     "bearing.ball_diameter_um"),
    ("conformity_1.5", MINIMAL, ("conformity = 0.54", "conformity = 1.5"),
     "bearing.conformity"),
    ("conformity_in_percent", MINIMAL, ("conformity = 0.54", "conformity = 54"),
     "bearing.conformity"),
    ("conformity_0.5_was", MINIMAL, ("conformity = 0.54", "conformity = 0.5"),
     "bearing.conformity"),
    ("contact_angle_90_deg_was", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\nnominal_contact_angle_deg = 90"),
     "bearing.nominal_contact_angle_deg"),
    ("contact_angle_0_deg_was", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\nnominal_contact_angle_deg = 0"),
     "bearing.nominal_contact_angle_deg"),
    ("contact_angle_45_rad_was", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\nnominal_contact_angle_rad = 45"),
     "bearing.nominal_contact_angle_rad"),
    ("youngs_modulus_x1000", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\nyoungs_modulus_GPa = 210000"),
     "bearing.youngs_modulus_GPa"),
    ("youngs_modulus_2000_GPa", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\nyoungs_modulus_GPa = 2000"),
     "bearing.youngs_modulus_GPa"),
    ("youngs_modulus_MPa_for_GPa", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\nyoungs_modulus_MPa = 210"),
     "bearing.youngs_modulus_MPa"),
    ("youngs_modulus_Pa_for_GPa", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\nyoungs_modulus_Pa = 210"),
     "bearing.youngs_modulus_Pa"),
    ("poisson_0.5_was", MINIMAL, ("conformity = 0.54", "conformity = 0.54\npoisson_ratio = 0.5"),
     "bearing.poisson_ratio"),
    ("poisson_in_percent_was", MINIMAL,
     ("conformity = 0.54", "conformity = 0.54\npoisson_ratio = 28"), "bearing.poisson_ratio"),
    ("mu_10", MINIMAL, ("conformity = 0.54", "conformity = 0.54\nfriction_coefficient = 10"),
     "bearing.friction_coefficient"),
    ("mu_1.5", MINIMAL, ("conformity = 0.54", "conformity = 0.54\nfriction_coefficient = 1.5"),
     "bearing.friction_coefficient"),
    # [motion]
    ("speed_200_m_per_s", MINIMAL,
     ("groove_velocity_mm_per_s = 10.0", "groove_velocity_m_per_s = 200"),
     "motion.groove_velocity_m_per_s"),
    ("speed_1e6_mm_per_s", MINIMAL,
     ("groove_velocity_mm_per_s = 10.0", "groove_velocity_mm_per_s = 1e6"),
     "motion.groove_velocity_mm_per_s"),
    ("duration_1000_min", MINIMAL, ("duration_s = 10.0", "duration_min = 1000"),
     "motion.duration_min"),
    ("duration_1e6_s", MINIMAL, ("duration_s = 10.0", "duration_s = 1e6"),
     "motion.duration_s"),
    ("stroke_500_m", MINIMAL, ("duration_s = 10.0", "stroke_m = 500"), "motion.stroke_m"),
    ("stroke_1e6_mm", MINIMAL, ("duration_s = 10.0", "stroke_mm = 1e6"), "motion.stroke_mm"),
    # [train]: gaps against the ball size, the loaded zone
    ("gap_100_mm", MINIMAL, ("value_mm = 0.5", "value_mm = 100"),
     "train.initial_gap.value_mm"),
    ("gap_0.5_m", MINIMAL, ("value_mm = 0.5", "value_m = 0.5"), "train.initial_gap.value_m"),
    ("gap_uniform_mm_for_um", MINIMAL,
     ('{ distribution = "fixed", value_mm = 0.5 }',
      '{ distribution = "uniform", low_mm = 0.0, high_mm = 100.0 }'),
     "train.initial_gap.high_mm"),
    ("gap_normal_std_5_mm", MINIMAL,
     ('{ distribution = "fixed", value_mm = 0.5 }',
      '{ distribution = "normal", mean_mm = 0.05, std_mm = 5 }'),
     "train.initial_gap.std_mm"),
    ("gap_truncated_high_20_mm", MINIMAL,
     ('{ distribution = "fixed", value_mm = 0.5 }',
      '{ distribution = "truncated_normal", std_um = 10, low_um = 0, high_mm = 20 }'),
     "train.initial_gap.high_mm"),
    ("loaded_zone_shorter_than_balls", MINIMAL,
     ("balls = 2", "balls = 2\nloaded_zone_length_mm = 15"), "train.loaded_zone_length_mm"),
    ("5000_balls", MINIMAL.replace("side_force_ratio = [-0.6, 0.6]", ""),
     ("balls = 2", "balls = 5000"), "train.balls = 5000 is outside"),
    # [loads]: Hertz pressure above 4 200 MPa
    ("load_kN_for_N", MINIMAL, ("normal_load_N = 200.0", "normal_load_kN = 200.0"),
     "loads.normal_load_kN"),
    ("load_1e6_N", MINIMAL, ("normal_load_N = 200.0", "normal_load_N = 1e6"),
     "loads.normal_load_N"),
    ("load_one_ball_200_kN", MINIMAL,
     ("normal_load_N = 200.0", "normal_load_N = [200.0, 200000.0]"), "loads.normal_load_N"),
    ("yaw_1500_N_m", MINIMAL, ("side_force_ratio = [-0.6, 0.6]", "yaw_moment_N_m = 1500"),
     "loads.yaw_moment_N_m"),
    ("side_ratio_in_percent", MINIMAL,
     ("side_force_ratio = [-0.6, 0.6]", "side_force_ratio = [-60, 60]"),
     "loads.side_force_ratio"),
    ("side_load_20_kN", MINIMAL, ("side_force_ratio = [-0.6, 0.6]", "side_load_kN = 20"),
     "loads.side_load_kN"),
    # [contact]
    ("ball_to_ball_mu_5", MINIMAL,
     ("[study]", "[contact]\nball_friction_coefficient = 5\n\n[study]"),
     "contact.ball_friction_coefficient"),
    # [sweep]: a misspelt setting, implausible points
    ("sweep_modee", MINIMAL + SWEEP + 'modee = "zip"\n"loads.normal_load_N" = [100, 200]\n',
     ("", ""), "sweep.modee"),
    ("sweep_mode_misspelt_as_table", MINIMAL + SWEEP + '"loads.normal_load_N" = [100, 200]\n'
     'mod = "outer"\n', ("", ""), "sweep.mod"),
    ("sweep_point_ball_10_m", MINIMAL + SWEEP + '"bearing.ball_diameter_mm" = [10, 10000]\n',
     ("", ""), "bearing.ball_diameter_mm"),
    ("sweep_point_speed", MINIMAL + SWEEP
     + '"motion.groove_velocity_mm_per_s" = { start = 10, stop = 1e6, num = 3 }\n',
     ("", ""), "motion.groove_velocity_mm_per_s"),
    # [[correlation]]: an asymmetric matrix (was: np.float64(0.5) in the message)
    ("correlation_asymmetric_was", MINIMAL,
     ("[study]", CORRELATED), "correlation[1].matrix"),
    # [carriage]: pitch, layout, load, balls
    ("pitch_500_mm", CARRIAGE_CONFIG, ("ball_pitch_mm = 11.0", "ball_pitch_mm = 500"),
     "carriage.ball_pitch_mm"),
    ("pitch_11_m", CARRIAGE_CONFIG, ("ball_pitch_mm = 11.0", "ball_pitch_m = 11"),
     "carriage.ball_pitch_m"),
    ("track_x_20_m", CARRIAGE_CONFIG, ("x_mm = -20.0", "x_m = -20.0"),
     "carriage.track[1].x_m"),
    ("track_y_5_m", CARRIAGE_CONFIG, ("y_mm = 0.0\norientation_deg = -90.0",
                                      "y_m = 5\norientation_deg = -90.0"),
     "carriage.track[2].y_m"),
    ("track_orientation_9000_deg", CARRIAGE_CONFIG, ("orientation_deg = 90.0",
                                                     "orientation_deg = 9000"),
     "carriage.track[1].orientation_deg"),
    ("carriage_vertical_kN_for_N", CARRIAGE_CONFIG, ("vertical_N = 500.0",
                                                     "vertical_kN = 500.0"),
     "carriage.load.vertical_kN"),
    ("carriage_roll_N_m_for_N_mm", CARRIAGE_CONFIG, ("roll_moment_N_m = 1.5",
                                                     "roll_moment_N_m = 150000"),
     "carriage.load.roll_moment_N_m"),
    ("carriage_5000_balls", CARRIAGE_CONFIG, ("balls_per_track = 4", "balls_per_track = 5000"),
     "carriage.balls_per_track"),
]


@pytest.mark.parametrize("text, replace_, key", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_implausible_input_exit_2_one_line_no_file(tmp_path, capsys, text, replace_, key):
    old, new = replace_
    assert old in text
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text.replace(old, new, 1))
    out = tmp_path / "bad.nc"
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConfigWarning)  # an error, not a warning
        rc = main(["run", str(cfg), "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith(f"tolsim run: error: {cfg}:"), err
    assert key in err
    assert "Traceback" not in err and "np.float64" not in err
    assert sorted(os.listdir(tmp_path)) == ["bad.toml"]


def test_at_least_40_new_bad_inputs():
    assert len(BAD) >= 40


def test_packaged_configs_load_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_config()
        for path in sorted(CONFIGS.glob("*.toml")):
            load_config(path)


def test_every_range_has_a_source_and_usual_inside_possible():
    for name, rng in RANGES.items():
        assert rng.source, name
        for usual in (rng.usual_low, rng.usual_high):
            if usual is not None:
                assert rng.possible(usual), name


# --------------------------------------------------------------------------------------------
# Messages: the value and the range in the user's unit
# --------------------------------------------------------------------------------------------
def error(text, path="x.toml"):
    with pytest.raises(ConfigError) as info:
        parse_config(text, path)
    return str(info.value)


def test_impossible_value_message_names_line_key_value_and_range():
    msg = error(MINIMAL.replace("ball_diameter_mm = 10.0", "ball_diameter_m = 10"))
    assert msg.startswith("x.toml:2: bearing.ball_diameter_m = 10 m is outside the possible "
                          "range [0.0003, 0.104775] m (ISO 3290-1")
    assert "\n" not in msg


def test_gap_in_mm_for_um_is_an_error_naming_the_ball():
    # issue 26: low_mm = 0, high_mm = 100 (meant um) changed P(contact) silently
    msg = error(MINIMAL.replace('{ distribution = "fixed", value_mm = 0.5 }',
                                '{ distribution = "uniform", low_mm = 0.0, high_mm = 100.0 }'))
    assert msg.startswith("x.toml:11: train.initial_gap.high_mm = 100.0 mm is outside the "
                          "possible range [0, 10] mm (no wider than one ball")


def test_values_are_echoed_without_float_noise():
    # was: "= -4.9999999999999996e-05 m must be >= 0" (the SI value, with float noise)
    msg = error(MINIMAL.replace('{ distribution = "fixed", value_mm = 0.5 }',
                                '{ distribution = "uniform", low_um = -50, high_um = 100 }'))
    assert "train.initial_gap.low_um = -50: gaps must be >= 0" in msg
    assert "e-05" not in msg and "[SI]" not in msg
    msg = error(MINIMAL.replace('std_deg = 0.5', 'distribution = "uniform"\nlow_deg = 0.3\n'
                                'high_deg = 0.1').replace('distribution = "normal"\n', ""))
    assert "tolerances.bottom_rotation.high_deg = 0.1 must be greater than low_deg = 0.3" in msg
    assert "[SI]" not in msg and "0.0017" not in msg
    assert show(-4.9999999999999996e-05) == "-5e-05" and show(3) == "3"


def test_out_of_range_message_gives_the_range():
    # was: "bearing.poisson_ratio = 0.6 [SI] is out of range"
    msg = error(MINIMAL.replace("conformity = 0.54", "conformity = 0.54\npoisson_ratio = 0.6"))
    assert "bearing.poisson_ratio = 0.6 is outside the possible range (-1, 0.5)" in msg
    assert "out of range" not in msg


def test_correlation_matrix_message_has_no_numpy_repr():
    msg = error(MINIMAL.replace("[study]", CORRELATED))
    assert msg.endswith("correlation[1].matrix must be symmetric: [1][0] = 0.4 but [0][1] = 0.5")


def test_sweep_unknown_setting_names_it_and_the_valid_ones():
    msg = error(MINIMAL + SWEEP + 'modee = "zip"\n"loads.normal_load_N" = [100, 200]\n')
    assert "sweep.modee is not a known key: [sweep] takes mode ('outer' or 'zip')" in msg
    assert '"loads.normal_load_N"' in msg


# --------------------------------------------------------------------------------------------
# Warnings: unusual but possible
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("old, new, key", [
    ("value_mm = 0.5", "value_mm = 2", "train.initial_gap.value_mm = 2 mm is unusual"),
    ("conformity = 0.54", "conformity = 0.54\nfriction_coefficient = 0.6",
     "bearing.friction_coefficient = 0.6 is unusual"),
    ("conformity = 0.54", "conformity = 0.54\nyoungs_modulus_GPa = 70",
     "bearing.youngs_modulus_GPa = 70 GPa is unusual"),
    ("groove_velocity_mm_per_s = 10.0\nduration_s = 10.0",
     "groove_velocity_m_per_s = 8\nduration_s = 0.1",
     "motion.groove_velocity_m_per_s = 8 m_per_s is unusual"),
    ("ball_diameter_mm = 10.0", "ball_diameter_mm = 40",
     "bearing.ball_diameter_mm = 40 mm is unusual"),
    ("conformity = 0.54", "conformity = 0.7", "bearing.conformity = 0.7 is unusual"),
    # a rail field correlated over 1 um (below a tenth of the 10 mm ball): 200 000 steps
    ("std_deg = 0.5", "std_deg = 0.5\nscope = \"rail\"\ncorrelation_length_mm = 0.001",
     "tolerances.bottom_rotation.correlation_length_mm = 0.001 mm is unusual: outside "
     "[1, inf] mm"),
])
def test_unusual_value_warns_one_line(old, new, key):
    with pytest.warns(ConfigWarning) as record:
        parse_config(MINIMAL.replace(old, new, 1), "w.toml")
    messages = [str(w.message) for w in record if issubclass(w.category, ConfigWarning)]
    assert len(messages) == 1 and messages[0].startswith("w.toml:") and key in messages[0]
    assert "\n" not in messages[0]


def test_cli_prints_a_warning_once_and_runs(tmp_path, capsys):
    cfg = tmp_path / "w.toml"
    cfg.write_text(MINIMAL.replace("value_mm = 0.5", "value_mm = 2"))
    rc = main(["run", str(cfg), "-o", str(tmp_path / "w.nc"), "--quiet", "--samples", "16"])
    err = capsys.readouterr().err
    assert rc == 0
    assert err.splitlines() == [line for line in err.splitlines() if line]
    lines = [line for line in err.splitlines() if "warning" in line]
    assert len(lines) == 1 and lines[0].startswith(
        f"tolsim run: warning: {cfg}:11: train.initial_gap.value_mm = 2 mm is unusual")


# --------------------------------------------------------------------------------------------
# Hertz pressure: 4 200 MPa (ISO 76 / ISO 14728-2)
# --------------------------------------------------------------------------------------------
def test_hertz_limit_at_the_paired_force():
    c = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                        TABLE1.poisson_ratio)
    f_max = (MAX_HERTZ_PRESSURE / c.pressure_coefficient) ** 3  # about 6 136 N per contact
    n_max = 2.0 * np.cos(np.pi / 4) * f_max  # N_y with paired forces N_y / (2 cos b0)
    below = MINIMAL.replace("normal_load_N = 200.0", f"normal_load_N = {0.99 * n_max:.1f}")
    above = MINIMAL.replace("normal_load_N = 200.0", f"normal_load_N = {1.01 * n_max:.1f}")
    below = below.replace("side_force_ratio = [-0.6, 0.6]", "")
    above = above.replace("side_force_ratio = [-0.6, 0.6]", "")
    parse_config(below)
    msg = error(above)
    assert msg.startswith("x.toml:14: loads.normal_load_N = ")
    assert "ball 0 (ball 0 trailing)" in msg and "Hertz pressure of 4214 MPa above the 4200 " \
                                                "MPa of ISO 76 / ISO 14728-2" in msg


def test_hertz_names_the_ball_and_the_driving_key():
    msg = error(MINIMAL.replace("side_force_ratio = [-0.6, 0.6]", "yaw_moment_N_m = 1500"))
    assert "loads.yaw_moment_N_m = 1500: ball" in msg and "MPa" in msg


# --------------------------------------------------------------------------------------------
# tolsim ball and tolsim carriage
# --------------------------------------------------------------------------------------------
@pytest.mark.parametrize("dbeta", [["90", "0", "0", "0"], ["0", "0", "-23", "0"]])
def test_ball_refuses_contact_angle_deviation_outside_the_model(capsys, dbeta):
    # issue 26: --dbeta-deg 90 0 0 0 printed epsilon = -56 %
    rc = main(["ball", "--dbeta-deg", *dbeta])
    captured = capsys.readouterr()
    assert rc == 2 and captured.out == ""
    assert captured.err.count("\n") == 1
    assert captured.err.startswith("tolsim ball: error: --dbeta-deg ")
    assert "+/-22.5 deg" in captured.err


def test_carriage_reads_a_config_without_study(tmp_path, capsys):
    text = CARRIAGE_CONFIG.replace("[study]\nsamples = 10\nseed = 1\n", "")
    assert "[study]" not in text
    path = tmp_path / "c.toml"
    path.write_text(text)
    assert main(["carriage", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    path.write_text(CARRIAGE_CONFIG)
    assert main(["carriage", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["balls"] == out["balls"]
    with pytest.raises(ConfigError, match="study section is missing"):
        parse_config(text)


def test_readme_table_of_ranges_is_the_code_s():
    # issue 26: the README's table of plausibility ranges is generated from RANGES
    # (ranges_markdown); a range changed in the code without the README fails here.
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    start = readme.index("<!-- plausibility-table:")
    start = readme.index("\n", start) + 1
    end = readme.index("<!-- end plausibility-table -->")
    assert readme[start:end].strip() == ranges_markdown()
    # every entry of RANGES has its row, with both intervals and its source
    rows = {row[0]: row for row in range_rows()}
    assert set(RANGES) <= set(rows)
    assert rows["bearing.ball_diameter"][1:3] == ("[0.3, 104.775] mm", "[1, 25.4] mm")
    assert rows["bearing.friction_coefficient"][1] == "[0, 1]"


def test_a_rail_field_spread_beyond_its_grid_is_warned_of():
    # configs/carriage_preload.toml with a 1 mm correlation length over a 2 m stroke: its
    # rail field needs 16 points per correlation length over some 2.1 m, 34 000 points, and
    # gets 4 096 (MAX_FIELD_POINTS), 1.91 per correlation length. Read linearly between two
    # points the field's variance is (1 + rho) / 2 at a cell's middle, rho = exp(-spacing /
    # l): 20.4 % low. The warning names the key and that figure; the packaged config, at
    # 100 mm, has its 16 points and is not warned of.
    import math

    from tolsim.study.sampling import field_grid

    root = Path(__file__).resolve().parents[2]
    text = (root / "configs" / "carriage_preload.toml").read_text()
    coarse = (text.replace("stroke_mm = 100.0", "stroke_mm = 2000.0", 1)
              .replace("correlation_length_mm = 100.0", "correlation_length_mm = 1.0", 1))
    with pytest.warns(ConfigWarning, match="grid") as caught:
        config = parse_config(coarse, "coarse.toml")
    _, spacing, points = field_grid(config)["bottom_rotation"]
    assert points == 4096
    loss = 0.5 * (1.0 - math.exp(-spacing / 1e-3))
    message = str(next(w.message for w in caught if "grid" in str(w.message)))
    assert message.startswith("coarse.toml:")
    assert "tolerances.bottom_rotation.correlation_length_mm = 1.0" in message
    assert f"variance is up to {100 * loss:.3g} % low" in message and 0.20 < loss < 0.21
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        parse_config(text, "carriage_preload.toml")


@pytest.mark.parametrize("length_mm, refused", [(1e-5, True), (0.0019, True),
                                                 (0.0021, False)])
def test_an_automatic_step_count_beyond_its_maximum_is_refused_naming_the_length(length_mm,
                                                                               refused):
    # configs/whatif_along_track.toml (free balls, 100 mm stroke: the balls travel 50 mm) with
    # its rail field's correlation length l: the automatic count is 4 steps per l of travel,
    # 4 x 50 / l (closed form, Notes of time_steps), 2e7 at 1e-5 mm (the shortest possible:
    # 1e-6 of its 10 mm ball); 2e32 at 1e-30 mm ran on without end before.
    # MAX_TIME_STEPS = 100 000 allows l >= 0.002 mm.
    from tolsim.study.pipeline.propagation_rules import MAX_TIME_STEPS, time_steps

    root = Path(__file__).resolve().parents[2]
    text = (root / "configs" / "whatif_along_track.toml").read_text()
    assert "correlation_length_mm = 20.0" in text
    text = text.replace("correlation_length_mm = 20.0", f"correlation_length_mm = {length_mm!r}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConfigWarning)  # (unusual, coarse grid: warned of)
        if not refused:
            assert time_steps(parse_config(text, "short.toml")) == int(
                np.ceil(4 * 50.0 / length_mm * (1 - 1e-12))) <= MAX_TIME_STEPS
            return
        with pytest.raises(ConfigError) as exc:
            parse_config(text, "short.toml")
    message = str(exc.value)
    count = f"{4 * 50.0 / length_mm:.3g}"
    assert message.startswith("short.toml:")
    assert (f"tolerances.bottom_rotation.correlation_length_mm = {length_mm!r}: along the "
            f"track the automatic step count would be {count}, more than 100000") in message
    assert "use at least 0.002 mm, or set study.time_steps" in message
    # a count given is bounded alike, and the same text with it loads
    explicit = text.replace('propagation = "along_track"',
                            'propagation = "along_track"\ntime_steps = 100', 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConfigWarning)
        assert time_steps(parse_config(explicit, "short.toml")) == 100
        with pytest.raises(ConfigError, match="study.time_steps = 100001 must be <= 100000"):
            parse_config(explicit.replace("time_steps = 100", "time_steps = 100001"), "x")


def test_a_carriage_end_relief_too_short_for_the_steps_is_refused():
    # c = 8 steps per end relief length of travel (50 mm): 4e11 at 1e-9 mm
    root = Path(__file__).resolve().parents[2]
    text = (root / "configs" / "carriage_preload.toml").read_text()
    relief = (text.replace("# end_relief_depth_um = 1.0 ", "end_relief_depth_um = 1.0", 1)
              .replace("# end_relief_length_mm = 15.0 ", "end_relief_length_mm = 1e-9", 1))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConfigWarning)
        with pytest.raises(ConfigError, match=r"carriage.end_relief_length_mm = 1e-09: along "
                           r"the track the automatic step count would be 4e\+11, more than "
                           r"100000: the end relief is the shortest length .* use at least "
                           r"0.004 mm"):
            parse_config(relief, "relief.toml")


@pytest.mark.parametrize("length_mm", [1e-30, 1e-320, 9.9e-6])
@pytest.mark.parametrize("propagation", ["constant", "along_track"])
def test_a_correlation_length_below_a_millionth_of_the_ball_is_impossible(length_mm,
                                                                        propagation):
    # 1e-320 mm (a subnormal) overflowed 1 / length in the worst-case stack-up (a traceback)
    # and in the rail field's grid; 1e-30 mm along the track asked for 2e32 steps. Balls 1e-6 D
    # apart already draw independent errors, so nothing is lost below it (10 mm balls).
    root = Path(__file__).resolve().parents[2]
    text = (root / "configs" / "whatif_along_track.toml").read_text()
    text = text.replace("correlation_length_mm = 20.0", f"correlation_length_mm = {length_mm!r}")
    text = text.replace('propagation = "along_track"', f'propagation = "{propagation}"')
    with pytest.raises(ConfigError, match=rf"tolerances.bottom_rotation.correlation_length_mm = "
                       rf"{length_mm!r} mm is outside the possible range \[1e-05, inf\] mm"):
        parse_config(text, "short.toml")
