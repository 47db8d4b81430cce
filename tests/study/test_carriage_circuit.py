"""The ball circuit in the along-track carriage study (tolsim issue 24).

``[carriage.circuit]`` is read in SI with one-line errors; the study's balls run round their
circuits (:mod:`tolsim.study.pipeline.carriage_circuit` over :mod:`tolsim.physics.circuit`)
through the one along-track loop. Each test names its reference and tolerance.
"""

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.io.config import ConfigError, ConfigWarning, parse_config
from tolsim.io.netcdf import result_to_dataset
from tolsim.physics.circuit import WHERE_ENTRY, WHERE_EXIT
from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.carriage_circuit import (
    CircuitContact,
    CircuitFrame,
    circuit_ball_ids,
    entering_velocity,
    first_contact_carriage_circuit,
)
from tolsim.study.pipeline.carriage_track import TrackTrace, first_contact_carriage_track
from tolsim.study.pipeline.circuit_trace import trace_circuit
from tolsim.study.pipeline.propagation import StepObserver, integrate
from tolsim.study.sampling import entering_capacity, sample_block

BASE = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
nominal_contact_angle_deg = 45.0
[motion]
groove_velocity_mm_per_s = 200.0
stroke_mm = {stroke}
[carriage]
balls_per_track = 6
ball_pitch_mm = 10.05
preload_oversize_um = 2.0
{circuit}
[carriage.load]
vertical_N = {vertical}
[[carriage.track]]
x_mm = -20.0
orientation_deg = 90.0
[[carriage.track]]
x_mm = 20.0
orientation_deg = -90.0
[train]
balls = 6
initial_gap = {gap}
{tolerances}
[study]
samples = {samples}
seed = 3
block_size = {samples}
propagation = "{propagation}"
time_steps = {steps}
"""
UNIFORM_GAP = '{ distribution = "uniform", low_um = 0.0, high_um = 100.0 }'
FIXED_GAP = '{ distribution = "fixed", value_um = 50.0 }'
#: Ball sizes and per-ball flank offsets (so each ball has its own epsilon and size), a rail
#: field and a carriage source.
TOLERANCES = """\
[tolerances.ball_oversize]
distribution = "truncated_normal"
std_um = 0.1
low_um = -0.25
high_um = 0.25
[tolerances.arc_centre_offset_tangential_TR]
distribution = "normal"
std_um = 1.0
scope = "ball"
[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.1
scope = "rail"
correlation_length_mm = 30.0
[tolerances.top_rotation]
distribution = "normal"
std_deg = 0.05
"""
CIRCUIT = "[carriage.circuit]\nballs = 16\nslack_mm = {slack}\nreturn_drag_N = {drag}\n"


def config(slack=1.0, drag=0.02, circuit=True, tolerances=TOLERANCES, gap=UNIFORM_GAP,
           vertical=300.0, samples=8, steps=40, stroke=100.0, propagation="along_track",
           extra=""):
    text = BASE.format(stroke=stroke, vertical=vertical, gap=gap, tolerances=tolerances,
                       samples=samples, steps=steps, propagation=propagation,
                       circuit=CIRCUIT.format(slack=slack, drag=drag) + extra if circuit
                       else "")
    return parse_config(text, "circuit.toml")


class Record(StepObserver):
    """Per step, after the circuits moved: the frame's gaps, slots and circuit outputs."""

    def __init__(self, frame):
        self.frame = frame
        self.gaps, self.slots, self.ids, self.sigma, self.circuit = [], [], [], [], []

    def following(self):
        return False

    def moved(self, step):
        f = self.frame
        self.gaps.append(f.gaps())
        self.slots.append(f.slot_ring.copy())
        self.ids.append(f.ball_id.copy())
        self.sigma.append(f.sigma.copy())
        self.circuit.append(step.circuit)


def run_frame(c):
    block = sample_block(c, 0)
    frame = CircuitFrame(c, block)
    contact = CircuitContact(frame)
    record = Record(frame)
    start = frame.gaps().copy(), frame.diameter_ring.copy()
    integrate(c, frame, [contact, record])
    return frame, contact, record, start


# --------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------
def test_config_is_read_in_si_with_its_defaults():
    c = config(slack=1.5, drag=0.03)
    assert c.carriage.circuit.balls == 16
    assert c.carriage.circuit.slack == pytest.approx(1.5e-3, rel=1e-15)
    assert c.carriage.circuit.return_drag == pytest.approx(0.03, rel=1e-15)
    assert config(circuit=False).carriage.circuit is None
    text = BASE.format(stroke=100.0, vertical=300.0, gap=FIXED_GAP, tolerances="", samples=8,
                       steps=10, propagation="along_track", circuit="[carriage.circuit]")
    default = parse_config(text, "circuit.toml").carriage.circuit  # the documented defaults
    assert (default.balls, default.slack, default.return_drag) == (30, 1e-3, 0.02)


@pytest.mark.parametrize("change, message", [
    ("constant", r"circuit\.toml:\d+: carriage\.circuit moves the balls round their circuit: "
                 r"it needs study\.propagation = 'along_track'"),
    ("balls = 7", r"circuit\.toml:\d+: carriage\.circuit\.balls = 7 is not more than the "
                  r"loaded zone holds \(7 balls"),
    ("slack_mm = 10.0", r"carriage\.circuit\.slack_mm = 10\.0 mm is outside the possible "
                        r"range \[0, 10\) mm"),
    ("return_drag_N = -0.1", r"carriage\.circuit\.return_drag_N = -0\.1 must be >= 0"),
    ("return_drag_mm = 0.1", r"carriage\.circuit\.return_drag_mm has an unknown unit"),
    ("colour = 1", r"carriage\.circuit\.colour is not a known key"),
])
def test_config_errors_are_one_line(change, message):
    circuit = "[carriage.circuit]\n"
    if change != "constant":
        circuit += change + "\n"
    text = BASE.format(stroke=100.0, vertical=300.0, gap=FIXED_GAP, tolerances="", samples=8,
                       steps=10, propagation="along_track", circuit=circuit)
    if change == "constant":
        text = text.replace('"along_track"', '"constant"')
    with pytest.raises(ConfigError, match=message) as err:
        parse_config(text, "circuit.toml")
    assert "\n" not in str(err.value)


def test_without_a_circuit_the_draws_are_those_of_the_open_trains():
    # The circuit's balls outside the zone take the entering draws: at least B - n + 1 of them
    # with a circuit, the open trains' count (floor(1.05 s / 2D) + 2 = 7 for 100 mm, 10 mm
    # balls) without, so a study without [carriage.circuit] draws what it drew before.
    assert entering_capacity(config(circuit=False)) == 7
    assert entering_capacity(config()) == 16 - 6 + 1


# --------------------------------------------------------------------------------------------
# The circuit in the study
# --------------------------------------------------------------------------------------------
def test_conservation_identity_and_size_at_every_step():
    # Issue 24, "Conservation": the sum of each circuit's gaps equals the slack to 1e-12 m at
    # every step (by construction; measured about 2e-16 m), the balls keep their sizes
    # (bit for bit) and order (no gap below -1e-12 m), and the slots hold the circuit's loaded
    # balls with their own ids, in z order: consecutive in ring order.
    c = config()
    frame, contact, record, (gap0, diameter0) = run_frame(c)
    slack = c.carriage.circuit.slack
    assert_allclose(gap0.sum(axis=1), slack, rtol=0, atol=1e-12)
    for gaps in record.gaps:
        assert_allclose(gaps.sum(axis=1), slack, rtol=0, atol=1e-12)
        assert gaps.min() > -1e-12
    assert contact.slack_error.max() < 1e-12
    assert_allclose(contact.total_gap_end, slack, rtol=0, atol=1e-12)
    assert_array_equal(frame.diameter_ring, diameter0)
    assert np.ptp(frame.diameter_ring) > 0  # sizes sampled per ball
    ids = circuit_ball_ids(6, 16)
    n = 16
    for ring, slot_id, sigma in zip(record.slots, record.ids, record.sigma, strict=True):
        occupied = ring >= 0
        assert_array_equal(slot_id[occupied], ids[ring[occupied]])
        for row in ring.reshape(-1, ring.shape[-1]):
            r = row[row >= 0]
            assert_array_equal(np.diff(r) % n, np.full(len(r) - 1, n - 1))  # z order
        assert (np.diff(sigma, axis=1) >= 0).all()
    # the balls went round by about stroke / 2 = 50 mm (less the first step, 1.25 mm)
    assert (record.sigma[-1] - record.sigma[0]).min() > 0.045
    # balls left and came back: a ball of the initial train's return side was loaded
    assert any((s >= 6).any() for s in record.slots)


def test_equal_epsilon_and_no_drag_change_no_gap():
    # Issue 24, "Equal speeds": no tolerances, no load, preload alone: every ball has the same
    # epsilon (0 by symmetry), so with no drag every ball moves at 1/2 and no gap changes
    # (to 1e-12 m over the stroke) and nothing touches.
    c = config(drag=0.0, tolerances="", gap=FIXED_GAP, vertical=0.0)
    frame, contact, record, (gap0, _) = run_frame(c)
    assert_allclose(record.gaps[-1], gap0, rtol=0, atol=1e-12)
    assert_array_equal(contact.where_count, 0)
    assert not np.isfinite(contact.time).any()


def test_no_slack_closed_form():
    # Issue 24, "No slack": with slack = 0 every pair stays closed at every step, and the
    # column's forces obey eq. (7) of tolsim.physics.circuit.step: Q_exit - Q_entry = n_u f,
    # n_u the unloaded balls (the column pushed through the channel); tolerance 1e-12 N
    # (sums of a few 0.02 N terms). Every assembly then has a contact between loaded balls
    # (they touch all the time).
    c = config(slack=0.0, drag=0.02)
    frame, contact, record, (gap0, _) = run_frame(c)
    assert np.abs(gap0).max() < 1e-15  # the filling's rounding (CLOSED_AT_START)
    for gaps, circuit in zip(record.gaps, record.circuit, strict=True):
        assert np.abs(gaps).max() < 1e-12
        assert circuit["closed"].all()
        unloaded = (~circuit["loaded"]).sum(axis=1)
        column = circuit["column"]
        assert_allclose(column[:, 1] - column[:, 0], unloaded * 0.02, rtol=0, atol=1e-12)
    assert np.isfinite(contact.time).all()


def test_with_drag_the_column_pushes_at_the_exit():
    # With drag the exiting balls stop and the loaded balls behind push the whole column: the
    # exit force, averaged over the stroke, is about n_u f = (16 - 6) x 0.02 = 0.2 N (eq. 7,
    # to within the entry force and the times the column is open: 30 %), and contacts form at
    # the exit; without drag the column coasts and carries nothing (zero to round-off: the
    # column forces are sums of K (w - epsilon) terms of about 1 N, 1e-12 N allows 1e4 ulp).
    c = config(drag=0.02)
    contact = first_contact_carriage_circuit(c, sample_block(c, 0))[-1]
    figures = contact.figures()
    assert figures["column_mean"][:, 1].mean() == pytest.approx(0.2, rel=0.3)
    assert contact.where_count[:, WHERE_EXIT].sum() > 0
    free = config(drag=0.0)
    contact = first_contact_carriage_circuit(free, sample_block(free, 0))[-1]
    assert_allclose(contact.column_max, 0.0, rtol=0, atol=1e-12)
    assert contact.where_count[:, WHERE_ENTRY].sum() >= 0


def test_a_long_return_without_drag_approaches_the_open_trains():
    # Issue 24, "Limit of today's model": with no drag and a return channel nearly a ball long
    # per gap (slack 9.9 mm over 11 gaps outside the zone) the balls that enter have gaps of
    # about 0.9 mm, wider than any closing in the stroke, as the open model's (draw U(0, 100
    # um) ahead of a ball that enters with a fresh epsilon): the first contacts are those of
    # the initial trains, so P(contact) agrees with the open model's within 2 assemblies of
    # 24. (Measured on configs/carriage_preload.toml along the track, 2 000 assemblies, seed
    # 12, 50 steps, 30 balls, 9.9 mm: 0.223 [0.205, 0.242] against the open model's 0.256
    # [0.237, 0.276]; with a 1 mm slack and no drag 0.576.)
    with pytest.warns(ConfigWarning, match="slack_mm = 9.9 mm is unusual"):
        c = config(slack=9.9, drag=0.0, samples=24)
    open_ = config(circuit=False, samples=24)
    t_c = first_contact_carriage_circuit(c, sample_block(c, 0))[0]
    t_o = first_contact_carriage_track(open_, sample_block(open_, 0))[0]
    assert abs(int(np.isfinite(t_c).sum()) - int(np.isfinite(t_o).sum())) <= 2


def test_a_study_with_a_circuit_writes_its_figures():
    # The result file carries the circuit's figures (CF units and long names) and the
    # fraction of first contacts at the zone's ends; --save-samples each circuit's total gap
    # at the start and end of the stroke (= the slack, 1e-12 m).
    c = config(samples=8, steps=20)
    result = run_study(c, save_samples=3)
    ds = result_to_dataset(result)
    for name in ("circuit_contact_count", "circuit_column_force_max",
                 "circuit_column_force_mean", "circuit_slack_error_max",
                 "contact_zone_end_fraction", "sample_circuit_total_gap_start",
                 "sample_circuit_total_gap_end"):
        assert "units" in ds[name].attrs and ds[name].attrs["long_name"], name
    assert list(ds.circuit_contact_where_name.values) == ["inside", "entry", "exit", "return"]
    assert ds.sample_circuit_total_gap_end.shape == (3, 2)
    assert_allclose(ds.sample_circuit_total_gap_start, 1e-3, rtol=0, atol=1e-12)
    assert_allclose(ds.sample_circuit_total_gap_end, 1e-3, rtol=0, atol=1e-12)
    assert float(ds.circuit_slack_error_max) < 1e-12
    assert "ignores the ball circuit" not in ds.attrs["propagation_caveat"]
    open_ = result_to_dataset(run_study(replace(config(circuit=False, samples=4, steps=10))))
    assert "ignores the ball circuit" in open_.attrs["propagation_caveat"]
    assert "circuit_balls" not in open_ and "contact_zone_end_fraction" in open_


def test_a_mirrored_carriage_gives_the_mirrored_result():
    # Issue 24, "Mirror": the carriage mirrored left-right (x -> -x, each track's orientation
    # negated) and its load mirrored (lateral force, yaw and roll moments negated; vertical
    # force and pitch kept): listing the two tracks in the other order puts each set of
    # draws (gaps, ball sizes, which a mirror leaves alone) on the mirror image of its track,
    # so every assembly is the mirror image of the original one and its first contact, pair,
    # contact events and column forces are the same, to 1e-9 of the time (the solver's
    # tolerance; measured equal). Negative control: the tracks swapped without mirroring the
    # load move the contact times by up to 0.28 % (measured), so the test can fail.
    sizes = TOLERANCES.split("[tolerances.arc_centre")[0]  # ball sizes only
    c = config(tolerances=sizes, samples=16)
    load = "lateral_N = {f}\nroll_moment_N_m = {r}\nyaw_moment_N_m = {y}\n"
    text = c.text.replace("vertical_N = 300.0\n", "vertical_N = 300.0\n" + load.format(
        f=60.0, r=1.5, y=0.5))
    swapped = text.replace("x_mm = -20.0\norientation_deg = 90.0", "X").replace(
        "x_mm = 20.0\norientation_deg = -90.0", "x_mm = -20.0\norientation_deg = 90.0").replace(
        "X", "x_mm = 20.0\norientation_deg = -90.0")
    mirrored = swapped.replace(load.format(f=60.0, r=1.5, y=0.5),
                               load.format(f=-60.0, r=-1.5, y=-0.5))
    assert len({text, swapped, mirrored}) == 3
    c, mirrored = parse_config(text, "circuit.toml"), parse_config(mirrored, "mirror.toml")
    a = first_contact_carriage_circuit(c, sample_block(c, 0))
    b = first_contact_carriage_circuit(mirrored, sample_block(mirrored, 0))
    hit = np.isfinite(a[0])
    assert_array_equal(np.isfinite(b[0]), hit)
    assert hit.sum() > 0
    assert_allclose(b[0][hit], a[0][hit], rtol=1e-9, atol=0)
    assert_array_equal(b[1], a[1])
    assert_array_equal(b[-1].where_count, a[-1].where_count)
    assert_allclose(b[-1].column_max, a[-1].column_max, rtol=1e-9, atol=1e-12)


def test_the_trace_records_exits_and_entries_in_the_circuit():
    # By hand (as test_exit_and_entry_times_by_hand of the open carriage): perfect balls, no
    # drag, a 300 N vertical load (every ball's epsilon 0 ([Lin2018] Sec. 2.4), so every ball
    # moves round the circuit at d sigma / dt = v / 2 = 100 mm/s), D = 10 mm, fixed gaps of
    # 50 um, a zone L_z = 65 mm and 16 balls with a slack of 16 x 50 um = 0.8 mm, so every
    # gap is 50 um (the filling shares the rest of the slack equally) and L_c = 160.8 mm.
    # The centred train's leading ball (ring 0) sits at z = 2.5 x 10.05 = 25.125 mm, sigma_0
    # = 32.5 - 25.125 = 7.375 mm, and ring ball c at sigma_c = 7.375 + 10.05 c mm. Ring ball
    # c < 6 (train ball 5 - c) leaves at sigma = 65 mm: t = (57.625 - 10.05 c) / 100 s, so
    # train balls 0..4 at 0.07375 + 0.1005 k s (ball 5 at 0.57625 s, after the 0.5 s
    # stroke); ring ball c >= 6 (id c) enters at sigma = 160.8 mm: t = (153.425 - 10.05 c)
    # / 100 s, so ids 15..11 at 0.02675 + 0.1005 k s. Linear interpolation is exact at
    # constant speed: tolerance 1e-12 s.
    text = BASE.format(stroke=100.0, vertical=300.0, gap=FIXED_GAP,
                       tolerances="loaded_zone_length_mm = 65.0", samples=2, steps=100,
                       propagation="along_track",
                       circuit=CIRCUIT.format(slack=0.8, drag=0.0))
    c = parse_config(text, "circuit.toml")
    trace = TrackTrace()
    time = first_contact_carriage_circuit(c, sample_block(c, 0), [trace])[0]
    assert not np.isfinite(time).any()
    exits, entries = trace.events("exits"), trace.events("entries")
    for a in range(2):
        for track in range(2):
            mine = exits[(exits[:, 0] == a) & (exits[:, 1] == track)]
            assert_array_equal(mine[:, 2], [0, 1, 2, 3, 4])
            assert_allclose(mine[:, 3], 0.07375 + 0.1005 * np.arange(5), rtol=0, atol=1e-12)
            mine = entries[(entries[:, 0] == a) & (entries[:, 1] == track)]
            assert_array_equal(mine[:, 2], [15, 14, 13, 12, 11])
            assert_allclose(mine[:, 3], 0.02675 + 0.1005 * np.arange(5), rtol=0, atol=1e-12)
    # the ids in the slots follow the events: a ball is in the zone between its entry and
    # its exit
    for t, ids in zip(trace.time, trace.ball_id, strict=True):
        inside = set(ids[0, 0][ids[0, 0] >= 0].tolist())
        expect = {k for k, when in enumerate(0.07375 + 0.1005 * np.arange(5)) if when > t}
        expect |= {5} | {15 - k for k, when in enumerate(0.02675 + 0.1005 * np.arange(5))
                         if when <= t}
        assert inside == expect


def test_the_circuit_trace_is_the_study_s_first_assembly():
    # trace_circuit (the circuit figure's data) follows the first assembly of the study: its
    # first contact and its contact events by where they form are those of the study's
    # integration of that assembly (exactly: the same draws and steps); its places round the
    # circuit lie in [0, L_c), the loaded ones in [0, L_z) (to the rounding of sigma mod L_c,
    # 1e-15 m), and the gaps between them sum to the slack at every step (1e-12 m, as the
    # conservation test).
    c = config(samples=1, steps=40)
    trace = trace_circuit(c)
    time, _, _, _, _, _, contact = first_contact_carriage_circuit(c, sample_block(c, 0))
    assert trace.first_contact_travel == c.motion.groove_velocity * time[0]
    for code in range(len(trace.where_names)):
        assert np.count_nonzero(trace.events["where"] == code) == contact.where_count[0, code]
    assert trace.travel.shape == (41,) and trace.position.shape == (41, 2, 16)
    length = trace.length[None, :, None]
    assert (trace.position >= 0).all() and (trace.position < length).all()
    loaded = trace.position[trace.loaded]
    assert loaded.max() < trace.zone_length + 1e-15
    assert trace.position[~trace.loaded].min() > trace.zone_length - 1e-15
    ahead = np.roll(trace.position, -1, axis=2)
    half = 0.5 * (trace.diameter + np.roll(trace.diameter, -1, axis=1))
    gaps = np.mod(ahead - trace.position, length) - half
    assert_allclose(gaps.sum(axis=2), trace.slack, rtol=0, atol=1e-12)


def test_an_entering_ball_moves_with_the_ball_ahead():
    # By hand: ring balls 2..4 loaded (in ring order, the direction of flow, the run enters
    # at ball 2), so the unloaded balls 0, 1, 5 take the epsilon and K of ball 2, the zone's
    # entry ball; the loaded ones keep theirs. A run across the ring's end (balls 4, 5, 0)
    # enters at 4.
    eps = np.array([[0.0, 0.0, 0.3, 0.4, 0.5, 0.0], [0.0, 0.2, 0.3, 0.0, 0.5, 0.6]])
    k = np.array([[1.0, 1.0, 30.0, 40.0, 50.0, 1.0], [10.0, 1.0, 1.0, 1.0, 50.0, 60.0]])
    loaded = np.array([[0, 0, 1, 1, 1, 0], [1, 0, 0, 0, 1, 1]], dtype=bool)
    entering_velocity(eps, k, loaded)
    assert_array_equal(eps, [[0.3, 0.3, 0.3, 0.4, 0.5, 0.3], [0.0, 0.5, 0.5, 0.5, 0.5, 0.6]])
    assert_array_equal(k, [[30.0, 30.0, 30.0, 40.0, 50.0, 30.0],
                           [10.0, 50.0, 50.0, 50.0, 50.0, 60.0]])


def test_with_one_epsilon_for_every_ball_the_step_does_not_matter():
    # Issue 24 item 4 (a ball entering within a step): with the carriage grooves turned by a
    # fixed 1.5 deg and no load but the preload, every loaded ball has the same epsilon at
    # every step (the carriage's equilibrium does not depend on which balls are loaded), and
    # the circuit's step is exact for constant epsilon (Notes of tolsim.physics.circuit.step),
    # so the gaps at the end of the stroke do not depend on the number of steps: 10 and 80
    # steps agree to 1e-8 m (measured 7e-10 m, epsilon to the solvers' tolerance). A ball
    # entering at epsilon = 0 for the rest of its step (the earlier rule) put them 4.5e-7 m
    # apart.
    turned = '[tolerances.top_rotation]\ndistribution = "fixed"\nvalue_deg = 1.5\n'
    gaps = []
    for steps in (10, 80):
        c = config(samples=2, steps=steps, tolerances=turned, vertical=0.0)
        gaps.append(run_frame(c)[2].gaps[-1])
    assert_allclose(gaps[0], gaps[1], rtol=0, atol=1e-8)


def relief_config(depth=8.0, **kwargs):
    """The circuit with an end relief of ``depth`` um over 15 mm at both ends of its 60.3 mm
    zone (deeper than the balls' approach under the 2 um preload and 300 N: the end balls
    lose their four contacts)."""
    extra = f"end_relief_depth_um = {depth}\nend_relief_length_mm = 15.0\n"
    text = config(**kwargs).text.replace("[carriage.circuit]", extra + "[carriage.circuit]")
    return parse_config(text, "relief.toml")


def test_unloaded_balls_in_the_zone_are_pushed_not_unresolved():
    # Issue 25 ("an unloaded ball has no epsilon of its own: it is pushed along, and it is
    # counted as such, not as unresolved") in the circuit (issue 24): with 8 um of end relief
    # the balls near the zone's ends lose their contacts (38 of the 24 x 12 balls at the
    # start; measured). Every assembly stays resolved (before: 24 of 24 invalid at 8 um,
    # 18 of 24 at 5 um; measured with the circuit's pushes_unloaded = False), the gaps sum
    # to the slack at every step (1e-12 m) and never overlap, and no contact event forms on a
    # pair of a pushed ball before the gaps to its loaded neighbours have closed (the events
    # inside the zone are those of runs that closed: checked in tests/physics/test_circuit).
    c = relief_config(samples=24)
    frame, contact, record, (gap0, _) = run_frame(c)
    assert int(frame.initial_state.unloaded.sum()) > 20
    pushed_steps = [step["pushed"] for step in record.circuit]
    assert contact.valid.all() and frame.ring_ok.all()
    assert np.isfinite(contact.time).sum() > 12
    slack = c.carriage.circuit.slack
    for gaps in record.gaps:
        assert_allclose(gaps.sum(axis=1), slack, rtol=0, atol=1e-12)
        assert gaps.min() > -1e-12
    assert any(p.any() for p in pushed_steps)



def test_an_entering_ball_takes_the_entry_ball_s_pushed_flag():
    # As test_an_entering_ball_moves_with_the_ball_ahead: the balls outside the zone take the
    # pushed flag (no groove contact) of the zone's entry ball with its epsilon and K, so a
    # ball that enters under an end relief within a step is pushed along, as the ball ahead.
    eps = np.zeros((2, 6))
    k = np.ones((2, 6))
    loaded = np.array([[0, 0, 1, 1, 1, 0], [1, 0, 0, 0, 1, 1]], dtype=bool)
    pushed = np.array([[0, 0, 1, 0, 0, 0], [0, 0, 0, 0, 0, 1]], dtype=bool)
    entering_velocity(eps, k, loaded, pushed)
    assert_array_equal(pushed, [[1, 1, 1, 0, 0, 1], [0, 0, 0, 0, 0, 1]])



class CountedStart(CircuitFrame):
    """The frame, counting the computations of the start's K (:meth:`stiffness` at given
    slots)."""

    def stiffness(self, balls, loaded, where=None):
        self.computed = getattr(self, "computed", 0) + (where is not None)
        return super().stiffness(balls, loaded, where)


class ComputedStart(CountedStart):
    """The frame with the start's K always computed (the code before it reused the previous
    midpoint's)."""

    def _start_stiffness(self, state1, state2, missing, stiff):
        return self.stiffness(state1.balls, state1.loaded, missing)


def test_the_start_s_creep_stiffness_is_the_previous_midpoint_s():
    # Reference: the same study with the start's K computed at every step; tolerance 0 (bit
    # for bit): K depends on each ball's own state alone
    c = config(samples=6, steps=30)
    runs = []
    for frame_type in (CountedStart, ComputedStart):
        frame = frame_type(c, sample_block(c, 0))
        record = Record(frame)
        integrate(c, frame, [CircuitContact(frame), record])
        runs.append((np.array(record.sigma), frame.ring_speed.copy(),
                     getattr(frame, "computed", 0)))
    assert_array_equal(runs[0][0], runs[1][0])
    assert_array_equal(runs[0][1], runs[1][1])
    assert runs[0][2] < runs[1][2]  # the reuse happened


def test_a_circuit_study_does_not_depend_on_the_thread_count(other_thread_count):
    # The circuits' kernels run their rows on Numba's threads, each row writing only its own
    # entries (circuit_kernels module docstring): on one thread every output of the study is
    # bit-identical to the ambient thread count's (16 circuits, so both threads get rows).
    c = config(samples=8, drag=0.05)
    ambient = first_contact_carriage_circuit(c, sample_block(c, 0))
    serial = other_thread_count(first_contact_carriage_circuit, c, sample_block(c, 0))
    assert np.isfinite(ambient[0]).sum() >= 1  # contacts happen
    for k in range(3):
        assert_array_equal(serial[k], ambient[k])
    assert_array_equal(serial[4].velocity_deviation, ambient[4].velocity_deviation)
    for name in ("where_count", "column_max", "column_mean", "total_gap_end", "slack_error"):
        assert_array_equal(getattr(serial[-1], name), getattr(ambient[-1], name), err_msg=name)


def _without_preload(vertical):
    """The study of config() without preload under ``vertical`` [N], 16 assemblies, 20 steps:
    its result and its dataset."""
    text = config(vertical=vertical, samples=16, steps=20).text.replace(
        "preload_oversize_um = 2.0", "preload_oversize_um = 0.0")
    result = run_study(parse_config(text, "circuit.toml"))
    return result, result_to_dataset(result)


def test_two_point_balls_hold_their_speed_against_the_column():
    # Without preload under 3 000 N every loaded ball sits on one diagonal: exactly two-point,
    # epsilon = 0, and a push below 2 mu F (some 30 N here) leaves it rolling at v / 2 (an
    # anchor, regime_creep_coefficients). The analytic model has no creep stiffness for it
    # (NaN), and the circuit's step moved it with the stand-in K of 1 N, so the column's
    # push (0.02 N per return ball) slowed the balls at the exit and a wave of closing pairs
    # ran back through the zone: every assembly touched within 5 ms (session 28). As an
    # anchor (ANCHOR_STIFFNESS) the loaded balls keep their gaps: no contact inside the zone
    # or at its entry; the exiting balls still push the column (contacts at the exit).
    result, ds = _without_preload(3000.0)
    assert int(ds.n_balls_regime.sel(ball_regime=3)) == 16 * 2 * 6  # all two-point
    assert result.statistics.contact_probability()[0] == 0.0
    where = dict(zip(ds.circuit_contact_where_name.values.tolist(),
                     ds.circuit_contact_count.values.tolist(), strict=True))
    assert where["inside"] == 0 and where["entry"] == 0 and where["exit"] > 0


def test_balls_of_every_regime_move_with_their_regimes_stiffness():
    # Without preload under 300 N the balls are two-, three- and four-point. The analytic
    # model gives K to the four-point ones only; the circuit's step gave the others the
    # assembly's mean K (or 1 N) and, once the anchors had theirs, that mean held the
    # anchors' 1e9 N: three-point balls beside anchors were pressed with up to 8 000 N
    # (session 28). With each regime's K (the trains' columns) the column carries its drag
    # and the pushes it passes on: a few newtons at most (0.58 N measured on 100 assemblies)
    # against 16 x 0.02 N of drag, and far fewer assemblies touch than the 100 % of before.
    result, ds = _without_preload(300.0)
    regimes = ds.n_balls_regime.sel(ball_regime=[2, 3]).values  # three- and two-point
    assert (regimes > 0).all()
    assert float(ds.circuit_column_force_max.max()) < 2.0
    assert result.statistics.contact_probability()[0] < 0.5


@pytest.mark.parametrize("kind", ["circuit", "contact"])
def test_the_trains_take_the_full_models_solves_without_solving_again(kind, monkeypatch):
    # A ball in regime B or three-point gets its train coefficients (the circuit's K, the
    # trains after contact) from its own minimum of D, which full_velocity has just found
    # with the same inputs; regime_creep_coefficients solved it again, a quarter of the time
    # of a carriage without preload with [contact] (session 29). Now the BallState carries
    # the solves and the trains take them: the same result, bit for bit, with fewer balls
    # solved again (a state assembled from others carries none and is still solved; here
    # none was: 0 balls against 37 in the circuit and 134 with [contact]).
    import tolsim.physics.trains.ball_minimum as bm
    from tolsim.study.pipeline.evaluate import BallState

    if kind == "circuit":
        text = config(vertical=300.0, samples=6, steps=10).text
    else:
        text = config(vertical=300.0, samples=6, steps=10, circuit=False).text + "\n[contact]\n"
    c = parse_config(text.replace("preload_oversize_um = 2.0", "preload_oversize_um = 0.0"),
                     "circuit.toml")
    solve = bm.full
    counted = []

    def spy(dbeta, *args, **kwargs):
        counted.append(len(dbeta))
        return solve(dbeta, *args, **kwargs)

    monkeypatch.setattr(bm, "full", spy)
    reused = result_to_dataset(run_study(c))
    reused_solves = sum(counted)
    counted.clear()
    monkeypatch.setattr(BallState, "solved_rows", lambda self, index=None: None)
    again = result_to_dataset(run_study(c))
    assert reused_solves < sum(counted) / 2, (reused_solves, sum(counted))
    assert int(again.n_balls_regime.sel(ball_regime=2)) > 0  # three-point balls
    for name, value in again.data_vars.items():
        assert_array_equal(reused[name].values, value.values, err_msg=name)
