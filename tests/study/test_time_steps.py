"""The along-track step count (study.time_steps, "auto" by default; issue 24, "Speed") and the
carriage Newton's extrapolated start."""

import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.io.config import parse_config
from tolsim.physics import carriage
from tolsim.physics.carriage import CarriageError, CarriageStatus, solve_carriage
from tolsim.study.pipeline.carriage_track import CarriageFrame
from tolsim.study.pipeline.propagation_rules import (
    LIGHT_PRELOAD_CONTACT,
    MIN_TIME_STEPS,
    epsilon_lengths,
    fine_step_reason,
    light_preload,
    propagation_assumption,
    propagation_caveat,
    time_steps,
)
from tolsim.study.sampling import sample_block

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def packaged(name, steps=None, contact=False):
    """A packaged config along the track, its ``time_steps`` line removed (or set)."""
    text = re.sub(r"(?m)^time_steps = .*\n", "", (CONFIGS / f"{name}.toml").read_text())
    if not re.search(r"(?m)^propagation = ", text):
        text = text.replace("[study]\n", '[study]\npropagation = "along_track"\n', 1)
    if steps is not None:
        text = text.replace("[study]\n", f"[study]\ntime_steps = {steps}\n", 1)
    return parse_config(text + ("\n[contact]\n" if contact else ""), f"{name}.toml")


def test_time_steps_is_auto_by_default_or_a_number():
    assert packaged("whatif_along_track").study.time_steps is None
    assert packaged("whatif_along_track", '"auto"').study.time_steps is None
    c = packaged("whatif_along_track", 37)
    assert c.study.time_steps == 37 and time_steps(c) == 37


def test_a_step_count_below_the_automatic_one_is_said():
    # whatif_along_track.toml takes 20 steps automatically (test below); fewer are a choice
    # the file, summary and report state (the propagation caveat), 20 or more are not
    coarse = propagation_caveat(packaged("whatif_along_track", 19))
    assert coarse == ("study.time_steps = 19 is coarser than the automatic step (20 steps, "
                      '"auto"), whose step error was measured against a fine-step reference: '
                      "the step error may move P(contact) and the first contacts beyond that "
                      '(README, "Step size").')
    for steps in (None, 20, 400):
        assert "coarser" not in propagation_caveat(packaged("whatif_along_track", steps))
    # a carriage keeps its circuit sentence before it
    both = propagation_caveat(packaged("carriage_preload", 2))
    assert both.startswith("This carriage study ignores the ball circuit")
    assert both.endswith("study.time_steps = 2 is coarser than the automatic step (10 steps, "
                         '"auto"), whose step error was measured against a fine-step '
                         'reference: the step error may move P(contact) and the first '
                         'contacts beyond that (README, "Step size").')


def test_the_assumption_says_whether_the_step_count_is_automatic():
    # the summary, report and file give the step count and where it came from
    auto = propagation_assumption("along_track", 20, automatic=True)
    given = propagation_assumption("along_track", 37)
    assert '20 steps chosen automatically: study.time_steps = "auto")' in auto
    assert "37 steps (study.time_steps)" in given and "automatic" not in given
    assert "steps" not in propagation_assumption("constant", 20, automatic=True)


def test_automatic_steps_of_the_packaged_configs():
    # n = max(8, ceil(c (s / 2) / l_min)), s = 100 mm, c = 4 (free balls), 2 (a carriage,
    # with or without a circuit), 40 with [contact] (but a circuit's own c: its step gives
    # the friction and the sliding check between its events); by hand: whatif_along_track:
    # l_min =
    # 10.05 mm, the spacing of its yaw-moment loads (D + the mean gap 50 um; its rail field
    # is 20 mm): 4 x 50 / 10.05 = 19.9 -> 20, with [contact] 199.0 -> 200; carriage_preload:
    # the ball pitch 10.05 mm, 2 x 50 / 10.05 = 9.95 -> 10, with [contact] 200;
    # carriage_circuit: the pitch 4.8 mm, 2 x 50 / 4.8 = 20.8 -> 21, with [contact] too.
    whatif = packaged("whatif_along_track")
    assert epsilon_lengths(whatif) == pytest.approx(
        {"rail field bottom_rotation": 0.02, "ball spacing": 0.01005}, rel=1e-12)
    assert time_steps(whatif) == 20
    assert time_steps(packaged("whatif_along_track", contact=True)) == 200
    preload = packaged("carriage_preload")
    assert epsilon_lengths(preload) == pytest.approx(
        {"rail field bottom_rotation": 0.1, "ball pitch": 0.01005}, rel=1e-12)
    assert time_steps(preload) == 10
    assert time_steps(packaged("carriage_preload", contact=True)) == 200
    assert time_steps(packaged("carriage_circuit")) == 21
    assert time_steps(packaged("carriage_circuit", contact=True)) == 21


def test_steps_follow_the_shortest_length_and_the_stroke():
    # An end relief of 2 mm is the shortest length, with the factor 8 of a relief (time_steps'
    # Notes: 1 um / 15 mm on carriage_preload needs ~40 steps): 8 x 50 / 2 = 200 steps; a
    # stroke of 400 mm with it 800; with a circuit the same factor: 200;
    # a 15 mm relief leaves the 10.05 mm pitch the shortest, 8 x 50 / 10.05 = 39.8 -> 40;
    # with nothing that changes epsilon along the track, the minimum.
    c = packaged("carriage_preload")
    text = c.text.replace("# end_relief_depth_um = 1.0", "end_relief_depth_um = 1.0").replace(
        "# end_relief_length_mm = 15.0", "end_relief_length_mm = 2.0")
    relief = parse_config(text, "relief.toml")
    assert epsilon_lengths(relief)["end relief"] == pytest.approx(0.002, rel=1e-12)
    assert time_steps(relief) == 200
    assert fine_step_reason(relief) == "the finer steps of an end relief"
    assert fine_step_reason(c) == ""
    longer = parse_config(text.replace("stroke_mm = 100.0", "stroke_mm = 400.0"), "long.toml")
    assert time_steps(longer) == 800
    circuit = parse_config(text + "\n[carriage.circuit]\n", "circuit.toml")
    assert time_steps(circuit) == 200
    fifteen = parse_config(text.replace("end_relief_length_mm = 2.0",
                                        "end_relief_length_mm = 15.0"), "fifteen.toml")
    assert time_steps(fifteen) == 40
    whatif = packaged("whatif_along_track")
    text = re.sub(r"(?ms)^\[tolerances\.bottom_rotation\].*?correlation_length_mm = 20\.0\n",
                  "", whatif.text).replace("yaw_moment_N_m = 6.0", "yaw_moment_N_m = 0.0")
    plain = parse_config(text, "plain.toml")
    assert epsilon_lengths(plain) == {}
    assert time_steps(plain) == MIN_TIME_STEPS


def preloaded(oversize_um, circuit=False):
    """configs/carriage_preload.toml along the track at a preload oversize [um]."""
    text = packaged("carriage_preload").text.replace(
        "preload_oversize_um = 2.0", f"preload_oversize_um = {oversize_um}", 1)
    return parse_config(text + ("\n[carriage.circuit]\n" if circuit else ""), "light.toml")


@pytest.mark.parametrize(("oversize_um", "light"), [(0.0, True), (0.5, True), (1.0, True),
                                                    (1.5, False), (2.0, False), (3.0, False)])
def test_a_light_preload_takes_the_steps_of_a_relief(oversize_um, light):
    # The nominal carriage of carriage_preload.toml (300 N, 2 N m) has its lightest contact
    # at 0 (two-point balls) up to 0.5 um, at 0.002 of the largest at 1 um, 0.185 at 1.5 um,
    # 0.359 at 2 um (as shipped) and 0.582 at 3 um (light_preload's docstring); below 0.1 the
    # carriage takes the relief's factor 8: 8 x 50 / 10.05 = 39.8 -> 40 steps, with or
    # without a circuit, else 10 (time_steps' Notes give the convergence behind it).
    c = preloaded(oversize_um)
    force = np.asarray(solve_carriage(c.carriage.layout, c.carriage.load, c.bearing,
                                      oversize=c.carriage.oversize).normal_force)
    assert (force.min() < LIGHT_PRELOAD_CONTACT * force.max()) == light
    assert light_preload(c) == light
    assert time_steps(c) == (40 if light else 10)
    assert time_steps(preloaded(oversize_um, circuit=True)) == (40 if light else 10)
    # the file, summary and report say why (the propagation assumption)
    said = propagation_assumption("along_track", time_steps(c), automatic=True,
                                  reason=fine_step_reason(c))
    assert said.endswith(
        "(midpoint rule, 40 steps chosen automatically (the finer steps of an end relief, "
        "for a light preload: a contact of the nominal carriage below 0.1 of its largest): "
        'study.time_steps = "auto")' if light else
        '(midpoint rule, 10 steps chosen automatically: study.time_steps = "auto")')


def test_a_carriage_without_a_nominal_solution_takes_the_fine_steps(monkeypatch):
    # A nominal carriage that lifts off or fails (CarriageError) has no lightest contact to
    # read: the cautious side, the fine steps.
    def fails(*args, **kwargs):
        raise CarriageError("lifted off", status=CarriageStatus.LIFT_OFF)

    monkeypatch.setattr(carriage, "solve_carriage", fails)
    assert time_steps(preloaded(2.0)) == 40


def test_the_carriage_newton_starts_on_the_line_through_its_two_latest_solutions():
    # By hand: solutions q(0) = a, q(dt/2) = b give the start 2b - a at t = dt (the line);
    # an assembly with one solution starts from it, one without any from the nominal q0; an
    # assembly whose solve failed forgets its line.
    c = packaged("carriage_preload").with_overrides(samples=4)
    evaluation = CarriageFrame(c, sample_block(c, 0)).evaluation
    nominal = evaluation.start[0].copy()
    a, b = np.arange(5.0) * 1e-6, np.arange(5.0) * 2e-6 + 1e-7
    rows = np.arange(4)

    def batch(q, n):
        return SimpleNamespace(displacement=np.tile(q, (n, 1)))

    evaluation.remember(rows[:3], 0.0, batch(a, 3), np.ones(3, dtype=bool))
    evaluation.remember(rows[:2], 0.005, batch(b, 2), np.ones(2, dtype=bool))
    start = evaluation.newton_start(rows, 0.01)
    assert_allclose(start[:2], np.tile(2 * b - a, (2, 1)), rtol=1e-12, atol=0)
    assert_array_equal(start[2], a)
    assert_array_equal(start[3], nominal)
    evaluation.remember(rows[:1], 0.01, batch(a, 1), np.zeros(1, dtype=bool))
    assert_array_equal(evaluation.newton_start(rows[:1], 0.015)[0], b)


def test_a_given_step_count_below_an_automatic_one_beyond_the_most_says_so():
    # The refusal of an automatic count beyond MAX_TIME_STEPS tells the user to set
    # study.time_steps; the caveat that compares the given count with the automatic one then
    # raised (the automatic count asked for, 2e7 at a 1e-5 mm correlation length on the 50 mm
    # travel of configs/whatif_along_track.toml: 4 x 50 / 1e-5): a traceback after the run
    # (session 28). Now it names the count and the bound.
    import warnings

    from tolsim.io.config import ConfigWarning

    text = (CONFIGS / "whatif_along_track.toml").read_text().replace(
        "correlation_length_mm = 20.0", "correlation_length_mm = 1e-5")
    text = text.replace('propagation = "along_track"',
                        'propagation = "along_track"\ntime_steps = 50', 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConfigWarning)
        c = parse_config(text, "short.toml")
    assert ("study.time_steps = 50 is coarser than the automatic step (2e+07 steps, beyond "
            "the most of 100000, \"auto\")") in propagation_caveat(c)
