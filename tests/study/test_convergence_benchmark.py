"""The step-size convergence study of the along-track propagation (issue 24, item 4).

CI-sized: ``benchmarks/convergence_along_track.py`` on a few dozen assemblies and short step
ladders (the script prints the full table; the README and the issue's closing note quote
it). Nothing here depends on the machine's speed.
"""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_spec = importlib.util.spec_from_file_location(
    "convergence_along_track", Path(__file__).resolve().parents[2] / "benchmarks"
    / "convergence_along_track.py")
convergence = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(convergence)


def row(steps, p, low, high, times):
    return {"time_steps": steps, "p": p, "low": low, "high": high,
            "contact_time": np.asarray(times, dtype=float)}


def test_the_checks_against_the_reference():
    # By hand: the reference P = 0.30 lies in [0.25, 0.35] (ok) and not in [0.31, 0.40];
    # the paired change counts the assemblies that touch only in the row (+) or only in the
    # reference (-), and the mean |change| of the contact time over those that touch in both
    # (|0.2 - 0.1| and |0.5 - 0.5|: 0.05 s; then 0.025 s, an observed order of 1).
    inf = np.inf
    reference = row(400, 0.30, 0.2, 0.4, [0.1, 0.5, inf, 0.3])
    rows = [row(100, 0.35, 0.31, 0.40, [0.2, 0.5, 0.4, inf]),
            row(200, 0.30, 0.25, 0.35, [0.15, 0.5, inf, 0.3])]
    table = convergence.compare(rows, reference)
    assert [e["p_ok"] for e in table] == [False, True]
    assert (table[0]["gained"], table[0]["lost"]) == (1, 1)
    assert (table[1]["gained"], table[1]["lost"]) == (0, 0)
    assert table[0]["time_change"] == pytest.approx(0.05, abs=1e-15)
    assert table[1]["time_change"] == pytest.approx(0.025 * 2 / 3, abs=1e-15)
    assert np.isnan(table[0]["order"])
    assert table[1]["order"] == pytest.approx(np.log2(0.05 / (0.025 * 2 / 3)), abs=1e-12)
    assert [e["median_ok"] for e in table] == [False, False]  # fewer than 6 times: no interval


def test_the_median_interval_by_hand():
    # k = 10 times 1..10 (shuffled, with assemblies that do not touch): the 2.5 % quantile of
    # binomial(10, 1/2) is 2 (P(B <= 1) = 11/1024 < 0.025 <= P(B <= 2) = 56/1024), so the
    # interval is [t_(2), t_(9)] = [2, 9], of coverage 1 - 2 * 11/1024 = 0.979 >= 0.95; the
    # median 5.5. Five times give none.
    times = np.array([7, np.inf, 3, 10, 1, 5, np.inf, 9, 2, 8, 4, 6], dtype=float)
    assert convergence.median_interval(times) == (5.5, 2.0, 9.0)
    median, low, high = convergence.median_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    assert median == 3.0 and np.isnan(low) and np.isnan(high)


def test_the_study_keys_are_set_in_the_config_text():
    # Replaced where present (layout and comment kept), added to [study] otherwise.
    text = "[bearing]\nx = 1\n\n[study]\nsamples = 2000   # note\n"
    out = convergence.with_study_keys(text, samples=64, time_steps=50,
                                      propagation="along_track")
    assert "samples = 64     # note" in out
    assert "\ntime_steps = 50" in out and '\npropagation = "along_track"' in out
    assert convergence.with_study_keys("[bearing]\n", seed=3).endswith("[study]\nseed = 3\n")


def test_a_finer_step_moves_p_by_less_than_its_interval():
    # configs/whatif_along_track.toml (free balls, a rail field of 20 mm correlation length)
    # on 64 assemblies: at 100 steps P(contact) is within its own 95 % interval of the
    # 200-step reference, the paired change is at most one assembly (of 64), and the
    # contact times move less from 100 to 200 steps than from 50 (the step-size error falls).
    path = convergence.CONFIGS["whatif_along_track"]
    rows = [convergence.measure(convergence.study_config(path, h, samples=64))
            for h in (50, 100)]
    reference = convergence.measure(convergence.study_config(path, 200, samples=64))
    table = convergence.compare(rows, reference)
    assert table[1]["p_ok"]
    assert abs(rows[1]["p"] - reference["p"]) <= 0.5 * (rows[1]["high"] - rows[1]["low"])
    assert table[1]["gained"] + table[1]["lost"] <= 1
    assert table[1]["time_change"] < table[0]["time_change"]
    assert reference["n"] == 64 and reference["time_steps"] == 200
    text = convergence._text("whatif_along_track", rows, reference, table)
    assert "(reference)" in text and text.count("\n") == 8


def test_the_circuit_study_reports_its_column_and_ends():
    # configs/carriage_circuit.toml on 4 assemblies and 10 steps: the circuit's figures come
    # out (column forces >= 0 at the entry and the exit, the fraction of first contacts at
    # the zone's ends within [0, 1] or NaN without contacts).
    path = convergence.CONFIGS["carriage_circuit"]
    out = convergence.measure(convergence.study_config(path, 10, samples=4))
    assert out["time_steps"] == 10 and out["n"] == 4
    assert out["column"]["entry"] >= 0 and out["column"]["exit"] >= 0
    fraction = out["zone_end_fraction"]
    assert np.isnan(fraction) or 0 <= fraction <= 1


def test_the_circuit_and_relief_variants():
    # --circuit adds a default [carriage.circuit], --relief 1 15 sets 1 um / 15 mm (SI after
    # loading: 1e-6 m, 0.015 m); the automatic step of that carriage is the relief's c = 8:
    # 8 x 50 / 10.05 = 39.8 -> 40 (its ball pitch the shortest length)
    path = convergence.CONFIGS["carriage_preload"]
    c = convergence.study_config(path, "auto", samples=4, circuit=True, relief=(1.0, 15.0))
    assert c.carriage.circuit is not None
    assert c.carriage.end_relief_depth == pytest.approx(1e-6, rel=1e-12)
    assert c.carriage.end_relief_length == pytest.approx(0.015, rel=1e-12)
    assert convergence.resolved_steps(c) == 40
    plain = convergence.study_config(path, "auto", samples=4)
    assert plain.carriage.circuit is None and plain.carriage.end_relief_depth == 0
    # a key already set is replaced, one not set is added after the [carriage] header
    text = "[carriage]\nend_relief_depth_um = 2.0   # note\n[carriage.load]\n"
    out = convergence.with_carriage_keys(text, end_relief_depth_um=1.0,
                                         end_relief_length_mm=7.0)
    assert out.startswith("[carriage]\nend_relief_length_mm = 7.0\nend_relief_depth_um = 1.0 ")
    assert out.count("end_relief_depth_um") == 1
    with pytest.raises(ValueError, match="end_relief_depth_um"):
        convergence.with_carriage_keys("[bearing]\n", end_relief_depth_um=1.0)


def test_a_light_preload_circuit_converges_at_its_automatic_steps():
    # configs/carriage_preload.toml at 0.5 um of preload with a default circuit (400
    # assemblies, seed 12, paired against 200 steps): at 10 steps, the factor of a preloaded
    # carriage, the error is first order and biased, the coarse step losing contacts (+16/-32,
    # the first contacts 28.6 ms off on average; session 30's 4 000 assemblies put P outside
    # its interval there: 0.4145 [0.3992, 0.4299] against 0.4517); at its automatic 40 steps
    # (light_preload: the relief's factor) +7/-9 and 7.1 ms. Bounds: a net change of at most 5
    # assemblies and 10 ms at the automatic step, 10 or more and 20 ms at 10 steps.
    path = convergence.CONFIGS["carriage_preload"]

    def study(steps):
        return convergence.study_config(path, steps, samples=400, seed=12, circuit=True,
                                        preload=0.5)

    rows = [convergence.measure(study(h)) for h in (10, "auto")]
    reference = convergence.measure(study(200))
    coarse, auto = convergence.compare(rows, reference)
    assert rows[1]["time_steps"] == 40 and rows[1]["auto"]
    assert auto["p_ok"] and abs(auto["gained"] - auto["lost"]) <= 5
    assert auto["time_change"] < 0.010
    assert coarse["lost"] - coarse["gained"] >= 10 and coarse["time_change"] > 0.020
