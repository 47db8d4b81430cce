"""The full model's closed forms on carriage balls (issue 24 "Speed", issue 25).

Balls from the carriage solve of ``configs/carriage_preload.toml``'s guide (two wrapped tracks
of 12 [Lin2018] Table 1 balls, 300 N and 2 N m) with sampled groove and ball errors, at 0 um
oversize (no preload: two-, three- and four-point balls) and at -5 um (clearance: every loaded
ball two-point), from the ``carriage_balls`` fixture (tests/conftest.py).
"""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.physics.geometry import TABLE1
from tolsim.physics.velocity._regime_kernels import (
    REGIME_STICK,
    REGIME_TWO_POINT,
    candidate_order,
)
from tolsim.physics.velocity.full import exactly_two_point, full


def loaded(dbeta, force):
    """The balls with two or more loaded contacts (the ones ``full`` solves)."""
    keep = np.count_nonzero(force > 0.0, axis=1) >= 2
    return dbeta[keep], force[keep]


@pytest.fixture(scope="module", params=[0.0, -5e-6], ids=["no_preload", "clearance"])
def balls(request, carriage_balls):
    dbeta, force = loaded(*carriage_balls(request.param, 25, 20))
    return dbeta, force, full(dbeta, force)


def test_closed_form_is_the_full_models_two_point_answer(balls):
    # The balls exactly_two_point picks are the ones full's kernel answers in closed form,
    # bit for bit (the same test, to the same floats): regime two-point, epsilon = 0 exactly,
    # certificate 0, converged and valid (issue 25: an exactly two-point ball rolls at v/2,
    # D = 0). The carriage solve leaves opposite contacts equal to ~1e-12 rad, inside the
    # tolerance of 1e-9 rad, so every two-point ball here qualifies.
    dbeta, force, res = balls
    two = exactly_two_point(dbeta, force)
    assert two.sum() >= 100
    assert_array_equal(two, res.regime == REGIME_TWO_POINT)
    loaded = force > 0.0
    opposite = (np.count_nonzero(loaded, axis=1) == 2) & (
        (loaded[:, 0] & loaded[:, 2]) | (loaded[:, 1] & loaded[:, 3]))
    assert_array_equal(two, opposite)  # (not opposite: a loose ball's round-off, 1e-23 N)
    assert (res.velocity_deviation[two] == 0.0).all()
    assert (res.certificate[two] == 0.0).all()
    assert res.converged[two].all() and res.valid[two].all()


def test_closed_form_falls_back_outside_its_tolerance():
    # Opposite contacts 1e-8 rad apart (10x the tolerance): not exactly two-point, left to the
    # full model (which answers it in regime B with both flags consistent).
    dbeta = np.array([[0.0, 0.0, 1e-8, 0.0], [0.0, 0.0, 1e-10, 0.0]])
    force = np.array([[100.0, 0.0, 100.0, 0.0], [100.0, 0.0, 100.0, 0.0]])
    assert_array_equal(exactly_two_point(dbeta, force, TABLE1), [False, True])
    assert_array_equal(full(dbeta, force).regime == REGIME_TWO_POINT, [False, True])


def test_three_point_balls_stick_at_the_first_candidate(carriage_balls):
    # The stick solve tries a three-point ball's pair contact on the other groove than its
    # single contact first (candidate_order); it is the contact that sticks on these carriage
    # balls, so one stick line is solved per ball instead of two where the heavier contact of
    # the pair does not stick (which happens here too: the order is not by force).
    dbeta, force = loaded(*carriage_balls(0.0, 25, 20))
    res = full(dbeta, force)
    three = (np.count_nonzero(force > 0.0, axis=1) == 3) & (res.regime == REGIME_STICK)
    assert three.sum() >= 50
    first = np.array([candidate_order(f)[0] for f in force[three]])
    assert_array_equal(res.stuck_contact[three], first)
    heaviest = np.argmax(force[three], axis=1)
    assert (first != heaviest).any()


@pytest.mark.parametrize("single, first", [(0, 3), (1, 2), (2, 1), (3, 0)])
def test_candidate_order_of_three_point_balls(single, first):
    # Contacts BL, BR (bottom), TR, TL (top); the pair opposite the single contact's diagonal
    # holds one contact on each groove, and the one on the other groove than the single
    # contact comes first, the rest by decreasing force (four-point balls: by force alone).
    force = np.array([300.0, 200.0, 150.0, 100.0])
    force[(single + 2) % 4] = 0.0
    order = candidate_order(force)
    rest = [k for k in np.argsort(-force) if k != first]
    assert_array_equal(order, [first] + rest)
    assert_array_equal(candidate_order(np.array([300.0, 200.0, 150.0, 100.0])), [0, 1, 2, 3])


@pytest.mark.parametrize("mismatch, tolerance, expected", [
    (1.9e-4, 1e-4, True), (2.1e-4, 1e-4, False),  # within 2 ball_tolerance (Notes)
    (5e-10, 1e-13, True), (2e-9, 1e-13, False),  # a tight solve: the default 1e-9 rad
    (2e-9, None, False),
])
def test_closed_form_to_the_solve_s_own_balance(mismatch, tolerance, expected):
    dbeta = np.array([[0.0, 0.0, mismatch, 0.0], [0.0, mismatch, 0.0, 0.0]])
    force = np.array([[100.0, 0.0, 100.0, 0.0], [0.0, 100.0, 0.0, 100.0]])
    assert_array_equal(exactly_two_point(dbeta, force, TABLE1, tolerance), [expected] * 2)


def test_a_loose_solve_leaves_two_point_balls_within_twice_its_balance():
    # The along-track solves stop at a relative ball balance of 1e-4 (TRACK_TOLERANCE): each
    # ball's |r|_inf <= tol max(F_max of the ball, f_ref), f_ref the solve's reference ball
    # force. A ball on two opposite contacts that carries at least f_ref then has its contact
    # angles at most sqrt(2) tol / (1 - tol) < 2 tol apart (Notes of exactly_two_point); a
    # lighter one up to 2 tol f_ref / F. At a clearance of -5 um most balls of the guide are
    # two-point; solved to 1e-4, after the pipeline's settle_unresolved_loads (balls below
    # tol x the largest force are unloaded), those that carry 1 % of the largest force or more
    # lie within the bound, some beyond the 1e-9 rad of a tight solve, and with the solve's
    # balance they are two-point in closed form (epsilon = 0), as the same assemblies solved
    # tight (1e-12) say; nearly every lighter one too.
    from tolsim.physics.carriage import CarriageLayout, CarriageLoad, solve_carriage_batch
    from tolsim.physics.static import GrooveErrors
    from tolsim.study.pipeline.carriage_track import TRACK_TOLERANCE
    from tolsim.study.pipeline.evaluate import settle_unresolved_loads

    gen = np.random.default_rng(28)
    shape = (40, 2, 12)
    errors = GrooveErrors(arc_centre_offset_normal=gen.normal(0.0, 1e-6, shape + (4,)),
                          bottom_rotation=gen.normal(0.0, 1.75e-3, shape),
                          top_rotation=gen.normal(0.0, 1.75e-3, shape),
                          ball_oversize=gen.normal(0.0, 0.1e-6, shape))
    layout = CarriageLayout([-0.02, 0.02], [0.0, 0.0], np.deg2rad([90.0, -90.0]), 12, 0.01005)
    load = CarriageLoad(vertical_force=300.0, pitch_moment=2.0)
    out = {}
    for name, tol in (("loose", TRACK_TOLERANCE), ("tight", 1e-12)):
        batch = solve_carriage_batch(layout, load, oversize=-5e-6, groove_errors=errors,
                                     tol=tol, ball_tol=tol)
        assert (batch.status == 0).all()
        force = settle_unresolved_loads(batch.normal_force, np.ones(shape, dtype=bool), tol)
        largest = np.max(force, axis=(1, 2, 3))
        out[name] = (batch.contact_angle_deviation.reshape(-1, 4), force.reshape(-1, 4),
                     (force.max(axis=3) / largest[:, None, None]).reshape(-1))
    dbeta, force, share = out["loose"]
    loaded = force > 0.0
    on = (np.count_nonzero(loaded, axis=1) == 2) & (
        (loaded[:, 0] & loaded[:, 2]) | (loaded[:, 1] & loaded[:, 3]))  # opposite pairs
    beta = TABLE1.nominal_contact_angle + dbeta
    pair = np.where(loaded[:, 0], 0, 1)
    rows = np.arange(len(beta))
    delta = np.abs(beta[rows, pair] - beta[rows, pair + 2])
    heavy = on & (share >= 0.01)
    assert heavy.sum() > 500
    assert delta[heavy].max() < 2.0 * TRACK_TOLERANCE  # the bound
    assert np.count_nonzero(delta[heavy] > 1e-9) >= 20  # (the tight rule misses them)
    two = exactly_two_point(dbeta, force, TABLE1, TRACK_TOLERANCE)
    assert two[heavy].all()
    assert np.mean(two[on]) > 0.99
    tight_dbeta, tight_force, _ = out["tight"]
    assert exactly_two_point(tight_dbeta[heavy], tight_force[heavy], TABLE1).all()
