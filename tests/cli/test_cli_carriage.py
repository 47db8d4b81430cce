"""``tolsim carriage`` and the ``[carriage]`` config (tolsim issue 12).

The JSON interface (issue 12, "Interfaces"), the carriage balance recomputed from the printed
numbers, the preload-only closed form, and one-line errors with exit code 2.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tolsim.cli import main
from tolsim.io.config import ConfigError, load_config, parse_config
from tolsim.physics.carriage import CarriageLayout, CarriageLoad
from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "carriage_preload.toml"
K = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                    TABLE1.poisson_ratio).load_deflection_constant
SX = np.array([-1.0, 1.0, 1.0, -1.0])  # BL BR TR TL: u_i = (sx sin beta_i, sy cos beta_i)
SY = np.array([-1.0, -1.0, 1.0, 1.0])

HEAD = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
nominal_contact_angle_deg = 45.0
youngs_modulus_GPa = 210.0
poisson_ratio = 0.28
friction_coefficient = 0.1

[motion]
groove_velocity_mm_per_s = 10.0
duration_s = 10.0

[study]
samples = 10
seed = 1
"""

CARRIAGE = """
[carriage]
balls_per_track = 4
ball_pitch_mm = 11.0
preload_oversize_um = 3.0

[carriage.load]
lateral_N = 120.0
vertical_N = 500.0
pitch_moment_N_m = 3.0
yaw_moment_N_m = -2.0
roll_moment_N_m = 1.5

[[carriage.track]]
x_mm = -20.0
y_mm = 0.0
orientation_deg = 90.0

[[carriage.track]]
x_mm = 20.0
y_mm = 0.0
orientation_deg = -90.0
"""


def write(tmp_path, body, name="c.toml"):
    path = tmp_path / name
    path.write_text(HEAD + body, encoding="utf-8")
    return path


def run_json(capsys, path):
    assert main(["carriage", str(path), "--json"]) == 0
    out = capsys.readouterr().out
    return json.loads(out)  # exactly one JSON object: json.loads rejects anything after it


def one_line_error(capsys, argv):
    assert main(argv) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert "\n" not in err and captured.out == ""
    return err


# --------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------
def test_carriage_config_to_si_dataclasses():
    c = parse_config(HEAD + CARRIAGE)
    assert c.loads is None
    # no [train]: one track's balls at the nominal pitch, gap = pitch - D (11 mm - 10 mm)
    assert c.train.balls == 4 and c.train.initial_gap.kind == "fixed"
    assert c.train.initial_gap.value == pytest.approx(1e-3, rel=1e-12)
    assert (c.n_tracks, c.balls) == (2, 8)
    layout, load = c.carriage.layout, c.carriage.load
    assert isinstance(layout, CarriageLayout) and isinstance(load, CarriageLoad)
    assert_allclose(layout.track_x, [-0.02, 0.02], rtol=1e-15)  # mm -> m
    assert_allclose(layout.track_orientation, np.deg2rad([90.0, -90.0]), rtol=1e-15)
    assert (layout.balls_per_track, layout.ball_pitch) == (4, pytest.approx(0.011, rel=1e-15))
    assert load == CarriageLoad(120.0, 500.0, 3.0, -2.0, 1.5)
    assert_allclose(c.carriage.oversize, np.full((2, 4), 3e-6), rtol=1e-15)


def test_carriage_config_oversize_deviation_per_track_and_flat():
    per_track = CARRIAGE.replace("orientation_deg = 90.0", "orientation_deg = 90.0\n"
                                 "ball_oversize_deviation_um = [0.1, 0.2, 0.3, 0.4]").replace(
        "orientation_deg = -90.0", "orientation_deg = -90.0\n"
        "ball_oversize_deviation_um = [-0.1, -0.2, -0.3, -0.4]")
    flat = CARRIAGE.replace("preload_oversize_um = 3.0", "preload_oversize_um = 3.0\n"
                            "ball_oversize_deviation_um = [0.1, 0.2, 0.3, 0.4, -0.1, -0.2, "
                            "-0.3, -0.4]")
    expected = 3e-6 + 1e-6 * np.array([[0.1, 0.2, 0.3, 0.4], [-0.1, -0.2, -0.3, -0.4]])
    # fixed sizes at the slots: constant propagation only (a carriage's default is along_track)
    head = HEAD.replace("[study]\n", '[study]\npropagation = "constant"\n')
    for text in (per_track, flat):
        assert_allclose(parse_config(head + text).carriage.oversize, expected, rtol=1e-14)
    with pytest.raises(ConfigError) as info:  # without the key: says how to choose constant
        parse_config(HEAD + flat, "c.toml")
    message = str(info.value)
    assert "\n" not in message and "carriage.ball_oversize_deviation_um" in message
    assert "along_track is a [carriage] study's default" in message


BAD = [
    ("negative_pitch", ("ball_pitch_mm = 11.0", "ball_pitch_mm = -11.0"),
     "carriage.ball_pitch_mm"),
    ("no_tracks", ("[[carriage.track]]\nx_mm = 20.0\ny_mm = 0.0\norientation_deg = -90.0\n", ""),
     None),  # filled in below: both tracks removed
    ("loads_beside_carriage", ("[carriage]", "[loads]\nnormal_load_N = 200.0\n\n[carriage]"),
     "loads"),
    ("per_track_list_length", ("orientation_deg = 90.0", "orientation_deg = 90.0\n"
                               "ball_oversize_deviation_um = [0.1, 0.2, 0.3]"),
     "carriage.track[1].ball_oversize_deviation_um"),
    ("flat_list_length", ("preload_oversize_um = 3.0", "preload_oversize_um = 3.0\n"
                          "ball_oversize_deviation_um = [0.1, 0.2, 0.3]"),
     "carriage.ball_oversize_deviation_um"),
    ("unknown_load_key", ("roll_moment_N_m = 1.5", "roll_moment_N_m = 1.5\nspin_N = 3.0"),
     "carriage.load.spin_N"),
    ("pitch_below_diameter", ("ball_pitch_mm = 11.0", "ball_pitch_mm = 9.0"),
     "carriage.ball_pitch_mm"),
]


def bad_text(case):
    _, (old, new), _ = case
    text = CARRIAGE
    if case[0] == "no_tracks":
        text = text[: text.index("[[carriage.track]]")]
    else:
        assert old in text
        text = text.replace(old, new, 1)
    return HEAD + text


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_bad_carriage_config_one_line_error(case):
    # file:line: key problem, one line (like every config error)
    with pytest.raises(ConfigError) as exc:
        parse_config(bad_text(case), "bad.toml")
    message = str(exc.value)
    key = case[2] or "carriage.track"
    assert re.match(rf"^bad\.toml:\d+: {re.escape(key)} ", message), message
    assert "\n" not in message


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_bad_carriage_config_cli_exit_2(case, tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text(bad_text(case), encoding="utf-8")
    err = one_line_error(capsys, ["carriage", str(path)])
    assert err.startswith(f"tolsim carriage: error: {path}:")


def test_every_existing_config_still_has_no_carriage():
    # but the carriage config and its preload sweep (issue 25), the circuit config and its
    # sweep (issue 24)
    carriages = (CONFIG, CONFIG.parent / "sweep_preload.toml",
                 CONFIG.parent / "carriage_circuit.toml", CONFIG.parent / "sweep_circuit.toml")
    for path in [None, *sorted(CONFIG.parent.glob("*.toml"))]:
        c = load_config(path)
        assert (c.carriage is not None) == (path in carriages)


def test_run_refuses_an_along_track_carriage_with_one_ball(capsys, tmp_path):
    # one line naming the key, exit 2, nothing written
    text = CONFIG.read_text().replace("[study]\n", '[study]\npropagation = "along_track"\n')
    text = text.replace("balls_per_track = 12", "balls_per_track = 1").replace(
        "balls = 12", "balls = 1").replace(  # (a pitch moment is refused before: see below)
        "pitch_moment_N_m = 2.0", "pitch_moment_N_m = 0.0")
    path = tmp_path / "along.toml"
    path.write_text(text)
    err = one_line_error(capsys, ["run", str(path), "-o", str(tmp_path / "x.nc")])
    assert "carriage.balls_per_track" in err and "along_track" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["along.toml"]


def test_carriage_refuses_a_config_without_carriage(capsys):
    err = one_line_error(capsys, ["carriage", str(CONFIG.parent / "known_answer.toml")])
    assert "no [carriage] section" in err


# --------------------------------------------------------------------------------------------
# JSON interface (issue 12, "Interfaces")
# --------------------------------------------------------------------------------------------
def test_json_interface_names_and_shapes(capsys):
    out = run_json(capsys, CONFIG)
    config = load_config(CONFIG)
    t, n = config.carriage.layout.n_tracks, config.carriage.layout.balls_per_track
    assert {"balls", "displacement", "stiffness", "locked", "converged"} <= set(out)
    assert len(out["balls"]) == t * n == 24
    assert [(b["track"], b["ball"]) for b in out["balls"]] == [
        (i, j) for i in range(t) for j in range(n)]
    for b in out["balls"]:
        assert {"track", "ball", "z_mm", "normal_force_n", "contact_angle_deg",
                "side_force_ratio", "velocity_deviation"} <= set(b)
        assert len(b["normal_force_n"]) == 4 and len(b["contact_angle_deg"]) == 4
        assert isinstance(b["side_force_ratio"], float)
        assert isinstance(b["velocity_deviation"], float)
    z = [b["z_mm"] for b in out["balls"][:n]]
    pitch_mm = 1e3 * load_config(CONFIG).carriage.layout.ball_pitch
    assert_allclose(z, (np.arange(n) - (n - 1) / 2) * pitch_mm, rtol=1e-12)  # ball 0 trailing
    assert set(out["displacement"]) == {"u_x_um", "u_y_um", "pitch_urad", "yaw_urad",
                                        "roll_urad"}
    k = np.array(out["stiffness"]["matrix"])
    assert k.shape == (5, 5) and np.array(out["stiffness"]["units"]).shape == (5, 5)
    assert out["stiffness"]["units"][1][1] == "N/um"
    assert out["stiffness"]["units"][2][2] == "N m/urad"
    assert out["stiffness"]["dofs"] == ["u_x", "u_y", "pitch", "yaw", "roll"]
    assert out["locked"] == [] and out["converged"] is True
    # the config's vertical load pushes the carriage down (u_y < 0); its positive pitch moment
    # loads the leading balls (z > 0) more
    assert out["displacement"]["u_y_um"] < 0
    forces = np.array([b["normal_force_n"] for b in out["balls"][:n]])
    assert forces.max(axis=1)[-1] > forces.max(axis=1)[0]


def printed_balance(out, config):
    """Q + sum of the ball forces and moments from the printed F_i, beta_i and z (SI).

    The ball pushes its carriage groove with f = F_TR u_TR + F_TL u_TL (module frame);
    E_t f acts at (x_t, y_t, z_j): generalised force (f_x, f_y, -z f_y, z f_x, x f_y - y f_x).
    """
    layout = config.carriage.layout
    total = np.zeros(5)
    for b in out["balls"]:
        beta = np.deg2rad(b["contact_angle_deg"])
        u = np.stack([SX * np.sin(beta), SY * np.cos(beta)], axis=-1)
        f = np.asarray(b["normal_force_n"])[2:] @ u[2:]
        phi = layout.track_orientation[b["track"]]
        fx = f[0] * np.cos(phi) - f[1] * np.sin(phi)
        fy = f[0] * np.sin(phi) + f[1] * np.cos(phi)
        x, y, z = layout.track_x[b["track"]], layout.track_y[b["track"]], b["z_mm"] * 1e-3
        total += [fx, fy, -z * fy, z * fx, x * fy - y * fx]
    return config.carriage.load.generalised() + total


@pytest.mark.parametrize("which", ["shipped", "all_loads"])
def test_printed_result_balances_the_load(which, capsys, tmp_path):
    # Issue 12: the carriage is in equilibrium under the ball forces and the external load;
    # recomputed from the printed numbers, to 1e-9 of the load scale (forces: the largest
    # load force, moments: that times the length scale of the layout)
    path = CONFIG if which == "shipped" else write(tmp_path, CARRIAGE)
    config = load_config(path)
    out = run_json(capsys, path)
    length = config.carriage.layout.length_scale()
    q = config.carriage.load.generalised()
    scale = max(np.abs(q[:2]).max(), np.abs(q[2:]).max() / length)
    residual = printed_balance(out, config) / np.array([1.0, 1.0, length, length, length])
    assert np.abs(residual).max() <= 1e-9 * scale


@pytest.mark.parametrize("oversize_um", [2.0, 4.0])
def test_preload_only_prints_closed_form(oversize_um, capsys, tmp_path):
    # Issue 12, "Done means" 1: preload only, symmetric two-row guide: every contact carries
    # F = K (o/2)^1.5 (K: tolsim.physics.hertz, the exact Hertz constant of the ball in its
    # groove), all angles at beta_0, zero displacement. Tolerance 1e-9 relative.
    text = CARRIAGE.replace("preload_oversize_um = 3.0", f"preload_oversize_um = {oversize_um}")
    text = re.sub(r"\[carriage\.load\][^\[]*", "", text)
    out = run_json(capsys, write(tmp_path, text))
    expected = K * (0.5 * oversize_um * 1e-6) ** 1.5
    forces = np.array([b["normal_force_n"] for b in out["balls"]])
    assert_allclose(forces, expected, rtol=1e-9)
    assert_allclose([b["contact_angle_deg"] for b in out["balls"]], 45.0, atol=1e-9)
    assert_allclose(list(out["displacement"].values()), 0.0, atol=1e-9)
    assert_allclose([b["velocity_deviation"] for b in out["balls"]], 0.0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Text, plot, and loads that cannot be carried
# --------------------------------------------------------------------------------------------
def test_text_output_and_plot(capsys, tmp_path):
    png = tmp_path / "load.png"
    assert main(["carriage", str(CONFIG), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "F_BL" in text and "rho" in text and "epsilon" in text
    assert "N/um" in text and "N m/urad" in text
    assert "(locked): none" in text and "converged: yes" in text
    assert len([line for line in text.splitlines() if re.match(r"^\s+[01]\s+\d+\s", line)]) == 24
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def png_size(data: bytes) -> tuple:
    """(width, height) of a PNG from its IHDR chunk (PNG spec, sec. 11.2.2)."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_the_readme_circuit_figure_is_drawn_by_the_tool(capsys, tmp_path):
    # The README's figure of the balls round their circuit
    # (reports/examples/carriage_circuit/circuit.png) is the output of
    # `tolsim carriage configs/carriage_circuit.toml --seed 1 --circuit-figure FILE`: the
    # command writes a PNG of the same size (the pixels depend on the fonts of the machine).
    png = tmp_path / "circuit.png"
    circuit = CONFIG.parent / "carriage_circuit.toml"
    assert main(["carriage", str(circuit), "--seed", "1", "--circuit-figure", str(png)]) == 0
    assert f"wrote {png}" in capsys.readouterr().out
    readme = CONFIG.parents[1] / "reports/examples/carriage_circuit/circuit.png"
    assert png_size(png.read_bytes()) == png_size(readme.read_bytes())
    assert "reports/examples/carriage_circuit/circuit.png" in (
        CONFIG.parents[1] / "README.md").read_text(encoding="utf-8")


def test_a_circuit_figure_needs_a_circuit(capsys, tmp_path):
    png = tmp_path / "circuit.png"
    err = one_line_error(capsys, ["carriage", str(CONFIG), "--circuit-figure", str(png)])
    assert "--circuit-figure" in err and "no [carriage.circuit]" in err
    assert not png.exists()


SINGLE_TRACK = """
[carriage]
balls_per_track = 3
ball_pitch_mm = 12.0

[carriage.load]
{load}

[[carriage.track]]
x_mm = 0.0
orientation_deg = 0.0
"""


def test_single_track_locks_roll(capsys, tmp_path):
    out = run_json(capsys, write(tmp_path, SINGLE_TRACK.format(load="vertical_N = 300.0")))
    assert out["locked"] == ["roll"] and out["converged"]
    assert_allclose([b["side_force_ratio"] for b in out["balls"]], 0.0, atol=1e-9)


@pytest.mark.parametrize("load, words", [
    # one straight track has no roll stiffness: the config names the load key and its line
    ("roll_moment_N_m = 5.0", "carriage.load.roll_moment_N_m = 5.0 acts along a motion the "
                              "balls cannot resist (roll) with carriage.balls_per_track = 3"),
    ("vertical_N = -300.0", "lifts off"),  # pulled off a single track without preload
])
def test_loads_that_cannot_be_carried_one_line_exit_2(load, words, capsys, tmp_path):
    path = write(tmp_path, SINGLE_TRACK.format(load=load))
    err = one_line_error(capsys, ["carriage", str(path)])
    assert err.startswith(f"tolsim carriage: error: {path}:") and words in err


def test_one_ball_per_track_under_a_pitch_moment_names_its_keys(capsys, tmp_path):
    # Two rows of one ball each cannot resist pitch or yaw: a pitch moment is refused when the
    # config is read, at the load's line, with the layout's keys (tolsim run refuses it too).
    text = CONFIG.read_text(encoding="utf-8")
    for old, new in (("balls_per_track = 12 ", "balls_per_track = 1 "),
                     ("balls = 12\n", "balls = 1\n"),
                     ("[study]\n", "[study]\npropagation = \"constant\"\n")):
        assert old in text, old
        text = text.replace(old, new, 1)
    path = tmp_path / "one.toml"
    path.write_text(text, encoding="utf-8")
    line = 1 + text[:text.index("pitch_moment_N_m = 2.0")].count("\n")
    for command in ("carriage", "run"):
        err = one_line_error(capsys, [command, str(path)])
        assert err.startswith(f"tolsim {command}: error: {path}:{line}: "
                              "carriage.load.pitch_moment_N_m = 2.0 acts along a motion the "
                              "balls cannot resist (pitch, yaw) with "
                              "carriage.balls_per_track = 1 and 2 carriage.track rows"), err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.toml"]


def test_clearance_settles_every_ball_two_point(capsys, tmp_path):
    # issue 25: the shipped config at -5 um (a clearance class) under its 300 N press: the
    # carriage settles (the old solver called it a lift-off), every ball two-point on one
    # diagonal, and the table prints the displacement (u_y = -9.3529 um: 7.07 um of clearance
    # closing along the diagonal plus the Hertz approach, tests/physics/
    # test_carriage_clearance.py) and every ball's forces
    text = CONFIG.read_text(encoding="utf-8").replace("preload_oversize_um = 2.0",
                                                      "preload_oversize_um = -5.0")
    path = tmp_path / "clearance.toml"
    path.write_text(text, encoding="utf-8")
    out = run_json(capsys, path)
    assert out["converged"] and out["preload_oversize_um"] == -5.0
    assert all(b["contact_count"] == 2 for b in out["balls"])
    assert_allclose(out["displacement"]["u_y_um"], -9.3529, atol=5e-5)  # printed to 4 places
    assert main(["carriage", str(path)]) == 0
    table = capsys.readouterr().out
    assert "u_y -9.3529 um" in table and "converged: yes" in table
    assert len(re.findall(r"(?m)^\s+[01]\s+\d+\s+-?\d+\.\d\d ", table)) == 24


def test_no_preload_every_ball_is_two_point_with_zero_epsilon(capsys, tmp_path):
    # preload class "none" under the shipped load: one diagonal of each ball opens. Issue 25:
    # an exactly two-point ball (two opposite contacts, equal angles and forces, as statics
    # force) rolls at v/2, so epsilon = 0 exactly (the closed form of
    # tolsim.physics.velocity.regimes.two_point_loaded with no load), regime "2-point"; the
    # table marks the open contacts and no longer says that no model takes the ball
    text = CONFIG.read_text(encoding="utf-8").replace("preload_oversize_um = 2.0",
                                                      "preload_oversize_um = 0.0")
    path = tmp_path / "none.toml"
    path.write_text(text, encoding="utf-8")
    out = run_json(capsys, path)
    assert all(b["contact_count"] == 2 for b in out["balls"])
    assert all(b["velocity_deviation"] == 0.0 for b in out["balls"])
    assert all(b["regime"] == "2-point" for b in out["balls"])
    assert main(["carriage", str(path)]) == 0
    text = capsys.readouterr().out
    assert "24 of 24 balls have open contacts" in text
    assert "regimes: 2-point 24" in text
    assert text.count("    open ") >= 48  # two open contacts per ball
    assert "no velocity model takes" not in text


def test_figure_paths_are_checked_before_any_figure_is_written(capsys, tmp_path):
    # CLI audit, session 25: --circuit-figure was written before --plot's missing folder was
    # found, so the command failed with one figure left behind
    png = tmp_path / "circuit.png"
    circuit = CONFIG.parent / "carriage_circuit.toml"
    err = one_line_error(capsys, ["carriage", str(circuit), "--circuit-figure", str(png),
                                  "--plot", str(tmp_path / "no" / "x.png")])
    assert "--plot: cannot write" in err and "its folder does not exist" in err
    assert not png.exists()


def test_a_figure_path_that_is_not_png_is_refused_before_any_work(tmp_path, capsys):
    # CLI audit, session 25: --plot out.pdf wrote PNG bytes into out.pdf
    pdf = tmp_path / "load.pdf"
    err = one_line_error(capsys, ["carriage", str(CONFIG), "--plot", str(pdf)])
    assert "--plot" in err and "must end in .png" in err
    assert not pdf.exists()
