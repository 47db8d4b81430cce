"""The creep stiffness kernel of the circuit against the creep kernel it is a column of."""

import numpy as np
from numpy.testing import assert_array_equal

from tolsim.physics.geometry import TABLE1, Bearing
from tolsim.physics.velocity.analytic import LOAD_COLUMNS
from tolsim.physics.velocity.creep_stiffness import creep_stiffness
from tolsim.study.pipeline.track_friction import CREEP_MODELS


def test_creep_stiffness_is_the_creep_kernels_column_bit_for_bit():
    # Source: tolsim.physics.velocity.analytic.creep_coefficients_kernel (through
    # CREEP_MODELS["analytic"]), column "creep_stiffness"; tolerance 0 (the same operations):
    # random four-point balls, balls beyond the small-angle series, three- and two-point
    # balls (zero forces: inf and NaN alike), on Table 1 and on another bearing.
    rng = np.random.default_rng(24)
    n = 5000
    dbeta = rng.normal(0.0, np.radians(0.6), (n, 4))
    dbeta[:20] = rng.normal(0.0, 0.3, (20, 4))  # beyond SMALL_ANGLE: libm sin and cos
    force = 141.4 * rng.uniform(0.3, 1.7, (n, 4))
    force[20:40, 2] = 0.0
    force[40:60, 1:3] = 0.0
    other = Bearing(ball_radius=3.0e-3, conformity=0.52, nominal_contact_angle=np.radians(40),
                    friction_coefficient=0.15)
    column = LOAD_COLUMNS.index("creep_stiffness")
    for bearing in (TABLE1, other):
        want = CREEP_MODELS["analytic"](dbeta, force, bearing, 0.0)[:, column]
        got = creep_stiffness(dbeta, force, bearing)
        assert_array_equal(got.view(np.int64), want.view(np.int64))  # bit for bit, NaN too
        assert np.isfinite(want).sum() > n // 2
