"""Balls entering the zone of a circuit within a step (tolsim issue 24, item 4: the step).

The midpoint's carriage solve holds the ring balls that have entered by then, which move from
their entry at their own epsilon; a ball that enters after the midpoint makes up for the
entry ball's epsilon in the next step; a pair pushed into the zone closed touches when its
later ball enters (Notes of
:func:`tolsim.study.pipeline.carriage_circuit.first_contact_carriage_circuit`, "Entry").
The kernels are checked against values worked by hand (tolerance 0 or 1e-15 m), the study
against its own fine-step run.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from test_carriage_circuit import config, run_frame

from tolsim.study.pipeline.circuit_kernels import (
    entering_inputs_kernel,
    late_entries_kernel,
    late_entry_kernel,
    midpoint_entering_kernel,
    step_contacts_kernel,
)

L, HALF_ZONE, SLOTS = 0.1, 0.025, 5


def one_circuit(diameter=0.00476, speed=0.5, travel=0.006):
    """By hand: ring balls 1, 2, 3 loaded at sigma 0.004, 0.014, 0.024 (z = L_z / 2 - sigma:
    0.021, 0.011, 0.001, so the slots in z order hold 3, 2, 1), the entry ball 1 moved to
    z = 0.020 at the midpoint; upstream of it ball 0 at sigma 0.098 (2 mm before the entry,
    L_c = 0.1 m), then ball 5 at 0.090 and ball 4 at 0.060."""
    sigma = np.array([[0.098, 0.004, 0.014, 0.024, 0.060, 0.090]])
    loaded = np.array([[False, True, True, True, False, False]])
    z = np.full((1, 1, SLOTS), np.nan)
    z[0, 0, :3] = [0.001, 0.011, 0.020]
    ids = np.array([[[30, 20, 10, -1, -1]]])
    slot_ring = np.array([[[3, 2, 1, -1, -1]]])
    out = (np.empty(z.shape), np.empty(ids.shape, dtype=np.int64),
           np.empty(ids.shape, dtype=np.int64), np.empty(z.shape, dtype=bool))
    midpoint_entering_kernel(z, ids, slot_ring, np.array([[3]]), np.array([0]), sigma, loaded,
                             np.full(sigma.shape, speed), np.array([L]),
                             np.full(sigma.shape, diameter), HALF_ZONE, travel,
                             np.array([0, 10, 20, 30, 40, 50]), *out)
    return out


def test_a_ball_that_has_entered_by_the_midpoint_takes_the_next_slot():
    # ball 0 at 0.098 + 0.5 x 0.006 = 0.101 passes L_c: 1 mm into the zone, z = 0.024; a
    # diameter's sum behind ball 1 is 0.020 + 0.002 = 0.022, farther from the entry, so 0.024
    # stands; ball 5 at 0.093 has not entered
    z, ids, ring, entering = one_circuit(diameter=0.002)
    assert_allclose(z[0, 0, 3], 0.024, rtol=0, atol=1e-15)
    assert (ids[0, 0, 3], ring[0, 0, 3]) == (0, 0)
    assert_array_equal(entering[0, 0], [False, False, False, True, False])
    assert_array_equal(z[0, 0, :3], [0.001, 0.011, 0.020])
    assert np.isnan(z[0, 0, 4]) and ids[0, 0, 4] == -1 and ring[0, 0, 4] == -1


def test_an_entering_ball_does_not_overlap_the_ball_it_pushes():
    # D = 4.76 mm: touching ball 1 puts it at 0.020 + 0.00476 = 0.02476 <= L_z / 2: there;
    # D = 12 mm would put it at 0.032, outside the zone: it has not entered
    z, _, _, entering = one_circuit(diameter=0.00476)
    assert_allclose(z[0, 0, 3], 0.02476, rtol=0, atol=1e-15)
    assert entering[0, 0, 3]
    assert not one_circuit(diameter=0.012)[3].any()


@pytest.mark.parametrize("speed, travel", [(0.0, 0.006), (0.5, 0.0), (0.5, 0.003)])
def test_a_ball_at_rest_or_short_of_the_entry_does_not_enter(speed, travel):
    # at rest, no travel, or 0.098 + 0.5 x 0.003 = 0.0995 < L_c
    z, ids, ring, entering = one_circuit(speed=speed, travel=travel)
    assert not entering.any() and (ring == -1).all()
    assert_array_equal(ids, [[[30, 20, 10, -1, -1]]])


def test_entering_balls_take_their_own_values():
    # slot 3 holds ring ball 0 with epsilon 0.01, K 50 N; slot 4 ring ball 5, unresolved
    # (keeps the fill); a K of NaN would take the fallback
    take = np.array([[False, False, False, True, True]])
    ring = np.array([[3, 2, 1, 0, 5]])
    eps = np.array([[0.0, 0.0, 0.0, 0.01, np.nan]])
    k = np.array([[1.0, 1.0, 1.0, 50.0, np.nan]])
    valid = np.array([[True, True, True, True, False]])
    unloaded = np.zeros((1, 5), dtype=bool)
    out_eps, out_k = np.full((1, 6), 0.3), np.full((1, 6), 7.0)
    out_pushed, own = np.zeros((1, 6), dtype=bool), np.zeros((1, 6), dtype=bool)
    entering_inputs_kernel(take, ring, eps, k, valid, unloaded, np.array([9.0]), out_eps,
                           out_k, out_pushed, own)
    assert_array_equal(out_eps, [[0.01, 0.3, 0.3, 0.3, 0.3, 0.3]])
    assert_array_equal(out_k, [[50.0, 7.0, 7.0, 7.0, 7.0, 7.0]])
    assert_array_equal(own, [[True, False, False, False, False, False]])
    k[0, 3] = np.nan
    entering_inputs_kernel(take, ring, eps, k, valid, unloaded, np.array([9.0]), out_eps,
                           out_k, out_pushed, own)
    assert out_k[0, 0] == 9.0


def test_a_late_entry_is_made_up_in_the_next_step():
    # By hand: a ball that moved lambda = 2 mm after its entry at epsilon_a = 0.001 and has
    # its own epsilon 0.003 moves in the next step of s = 8 mm at 0.003 + (2 / 8) (0.003 -
    # 0.001) = 0.0035, so that over lambda + s it travels at 0.003 on average:
    # (2 x 0.001 + 8 x 0.0035) / 10 = 0.003. Not loaded, unresolved or pushed: unchanged;
    # lambda is cleared either way.
    late = np.array([[0.002, 0.002, 0.002, 0.0]])
    late_eps = np.full((1, 4), 0.001)
    loaded = np.array([[True, False, True, True]])
    ok = np.array([[True, True, False, True]])
    eps = np.full((1, 4), 0.003)
    late_entry_kernel(late, late_eps, loaded, ok, np.zeros((1, 4), dtype=bool), eps, 0.008)
    assert_allclose(eps, [[0.0035, 0.003, 0.003, 0.003]], rtol=0, atol=1e-15)
    assert_allclose((0.002 * 0.001 + 0.008 * eps[0, 0]) / 0.010, 0.003, rtol=0, atol=1e-15)
    assert (late == 0).all()


def test_late_entries_are_recorded_without_own_values():
    # slot 0 (ring 2) entered at 0.3 s of a step ending at 0.5 s, v = 0.2 m/s: 40 mm late at
    # the entry ball's epsilon 0.002; slot 1 (ring 4) had its own values; slot 2 no entry
    entry = np.array([[0.3, 0.4, np.nan]])
    slot_ring = np.array([[2, 4, 1]])
    own = np.zeros((1, 5), dtype=bool)
    own[0, 4] = True
    eps = np.full((1, 5), 0.002)
    late, late_eps = np.zeros((1, 5)), np.zeros((1, 5))
    late_entries_kernel(entry, slot_ring, own, eps, np.zeros((1, 5), dtype=bool), 0.5, 0.2,
                        late, late_eps)
    assert_allclose(late, [[0, 0, 0.04, 0, 0]], rtol=0, atol=1e-15)
    assert late_eps[0, 2] == 0.002 and late_eps[0, 4] == 0.0


def test_a_pair_pushed_in_closed_touches_when_its_later_ball_enters():
    # ring pair 1 (balls 1, 2) closed, loaded, resolved, with force at the end of the step
    # (t_end 0.5 s); ball 2 entered at 0.42 s, ball 1 at 0.31 s: the contact is at 0.42 s;
    # with no entry in the step, the step's end
    n = 4
    ok = np.ones((1, n), dtype=bool)
    loaded = np.array([[True, True, True, False]])
    closed = np.array([[False, True, False, False]])
    force = np.array([[0.0, 0.3, 0.0, 0.0]])
    pair = np.full((1, n), -1, dtype=np.int64)
    where = np.full((1, n), -1, dtype=np.int8)
    travel = np.full((1, n), np.nan)
    for entry, want in (([np.nan, 0.31, 0.42, np.nan], 0.42), ([np.nan, 0.31, np.nan, np.nan],
                                                                0.31), ([np.nan] * 4, 0.5)):
        out = (np.empty((1, 4), dtype=np.int64), np.empty(1), np.empty(1, dtype=np.int64))
        step_contacts_kernel(ok, loaded, closed, force, pair, where, travel, 0.2, 0.5, 4,
                             np.array([entry]), *out)
        assert out[1][0] == want and out[2][0] == 1


def test_entering_balls_move_at_their_own_epsilon():
    # Issue 24 item 4 (the step): with the preload alone (no rail field) each ball's epsilon
    # is set by its own flank offsets (std 1 um), nearly constant while it is in the zone;
    # the gaps at the end of the stroke at 10 steps agree with 320 steps to 1.5e-6 m
    # (measured 4.9e-7 m). Entering balls on the ball ahead's epsilon outside the midpoint's
    # solve (the earlier rule) were 9.2e-6 m off, and 4.9e-6 m with the midpoint's entering
    # balls but without the late entries made up.
    own = ('[tolerances.arc_centre_offset_tangential_TR]\ndistribution = "normal"\n'
           'std_um = 1.0\nscope = "ball"\n')
    gaps = [run_frame(config(samples=4, steps=steps, tolerances=own, vertical=0.0))[2].gaps[-1]
            for steps in (10, 320)]
    assert_allclose(gaps[0], gaps[1], rtol=0, atol=1.5e-6)
