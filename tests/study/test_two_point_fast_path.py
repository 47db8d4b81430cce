"""full_velocity answers exactly two-point balls in closed form (issue 24 "Speed").

Balls from the carriage solve of ``configs/carriage_preload.toml``'s guide at 0 um and -5 um
oversize with sampled errors (:func:`tests.physics.test_two_point_closed_form.carriage_balls`'s
recipe, repeated here: tests do not import each other).
"""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.physics.carriage import CarriageLayout, CarriageLoad, solve_carriage_batch
from tolsim.physics.geometry import TABLE1
from tolsim.physics.static import GrooveErrors
from tolsim.physics.velocity import full as full_module
from tolsim.physics.velocity.models import BALL_TWO_POINT, ball_regime
from tolsim.study.pipeline import evaluate


def carriage_balls(oversize, seed=7, assemblies=10):
    rng = np.random.default_rng(seed)
    shape = (assemblies, 2, 12)
    errors = GrooveErrors(
        arc_centre_offset_normal=rng.normal(0.0, 1e-6, shape + (4,)),
        arc_centre_offset_tangential=rng.normal(0.0, 1e-6, shape + (4,)),
        bottom_rotation=rng.normal(0.0, 1.75e-3, shape),
        top_rotation=rng.normal(0.0, 1.75e-3, shape),
        ball_oversize=rng.normal(0.0, 0.1e-6, shape))
    layout = CarriageLayout([-0.02, 0.02], [0.0, 0.0], np.deg2rad([90.0, -90.0]), 12, 0.01005)
    batch = solve_carriage_batch(layout, CarriageLoad(vertical_force=300.0, pitch_moment=2.0),
                                 oversize=oversize, groove_errors=errors)
    force = batch.normal_force.reshape(-1, 4)
    keep = np.all(np.isfinite(force), axis=1)
    return batch.contact_angle_deviation.reshape(-1, 4)[keep], force[keep]


@pytest.mark.parametrize("oversize", [0.0, -5e-6])
def test_two_point_balls_skip_the_kernel_with_the_same_answer(monkeypatch, oversize):
    dbeta, force = carriage_balls(oversize)
    many = np.count_nonzero(force > 0, axis=1) >= 2
    reference = full_module.full(dbeta[many], force[many])
    seen = []
    original = full_module.full

    def recording_full(d, f, *args, **kwargs):
        seen.append((np.asarray(d), np.asarray(f)))
        return original(d, f, *args, **kwargs)

    monkeypatch.setattr(full_module, "full", recording_full)
    eps, ok, regime = evaluate.full_velocity(dbeta, force, TABLE1)
    # no exactly two-point ball reaches the kernel ...
    assert not any(full_module.exactly_two_point(d, f).any() for d, f in seen)
    assert sum(len(f) for _, f in seen) < many.sum()
    # ... and every ball's answer is the full model's, bit for bit (epsilon 0 exactly for the
    # two-point ones, issue 25)
    assert_array_equal(eps[many], reference.velocity_deviation)
    assert_array_equal(ok[many], reference.valid)
    assert_array_equal(regime[many], ball_regime(force[many], reference.regime))
    assert (regime == BALL_TWO_POINT).sum() >= 50
