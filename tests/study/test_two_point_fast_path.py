"""full_velocity answers exactly two-point balls in closed form (issue 24 "Speed").

Balls from the carriage solve of ``configs/carriage_preload.toml``'s guide at 0 um and -5 um
oversize with sampled errors (the ``carriage_balls`` fixture of tests/conftest.py).
"""

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.physics.geometry import TABLE1
from tolsim.physics.velocity import full as full_module
from tolsim.physics.velocity.models import BALL_TWO_POINT, ball_regime
from tolsim.study.pipeline import evaluate


@pytest.mark.parametrize("oversize", [0.0, -5e-6])
def test_two_point_balls_skip_the_kernel_with_the_same_answer(monkeypatch, carriage_balls,
                                                             oversize):
    dbeta, force = carriage_balls(oversize, 7, 10)
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
