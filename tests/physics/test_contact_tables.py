"""Tables of the planar contact integrals (issue 25's fast path of the full model).

Source of every reference value: the quadrature the tables fit,
:func:`tolsim.physics.velocity._full_kernels.planar_contact_integrals` on the same grid (the
tables must give its answer to round-off), and central differences of it for the derivatives.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from tolsim.physics.geometry import TABLE1, paired_forces
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity._contact_tables import (
    TABLE_PIECES,
    table_ball_loads,
    table_integrals,
)
from tolsim.physics.velocity._full_kernels import ball_loads_kernel, planar_contact_integrals
from tolsim.physics.velocity._regime_kernels import (
    CERTIFICATE_DIRECTIONS,
    scan_constants,
    stick_certificate,
)
from tolsim.physics.velocity.full import (
    DEFAULT_ANGULAR_NODES,
    contact_table,
    full,
    quadrature_grid,
)

HC = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                     TABLE1.poisson_ratio)
Q = HC.ellipticity
SIGMA = 1.5 / np.pi


@pytest.fixture(scope="module")
def tables():
    grid = quadrature_grid(DEFAULT_ANGULAR_NODES, 2, Q)[:5]
    return contact_table(DEFAULT_ANGULAR_NODES, Q), grid


def _both(p, a, table, grid, nout=6):
    out = np.empty(nout)
    table_integrals(p, a, a * Q, table, *grid, out)
    s4 = np.empty(4)
    planar_contact_integrals(p, 0.0, a, a * Q, *grid, s4)
    return out, s4[1:]


def _poles(rng):
    near = np.r_[1.0 - np.arange(0, 40) * 2.0**-53, 1.0 + np.arange(1, 40) * 2.0**-52,
                 1.0 - np.exp(rng.uniform(-34, -2, 200)), 1.0 + np.exp(rng.uniform(-34, -2, 200))]
    return np.r_[rng.uniform(-1, 1, 400), 1.0 / rng.uniform(-1, 1, 400), near, -near,
                 rng.uniform(-30, 30, 200), 0.0, 0.5, 2.0**-TABLE_PIECES]


@pytest.mark.parametrize("angular_nodes", [8, DEFAULT_ANGULAR_NODES, 128])
def test_tables_reproduce_the_quadrature(angular_nodes, rng):
    # Round-off: 2e-14 of the integrals' scale (S_z ~ 1, S_n ~ a, S_d ~ a max(1, |p|)) at
    # random poles inside, outside, next to |p| = 1 (the floats there are stored exactly) and
    # far out; measured 7e-15. Far out the quadrature's own S_n loses digits to cancellation
    # (two terms of size a |p| cancel to ~a / |p|: noise ~1e-16 a p^2), and the smooth fit
    # differs from it by that noise.
    table = contact_table(angular_nodes, Q)
    grid = quadrature_grid(angular_nodes, 2, Q)[:5]
    for p in _poles(rng):
        for a in (0.05, 0.11):
            got, ref = _both(p, a, table, grid)
            scale = np.array([1.0, a, a * max(1.0, abs(p))])
            tol = np.array([2e-14, max(2e-14, 1e-16 * p * p), 2e-14])
            assert np.all(np.abs(got[:3] - ref) <= tol * scale), (p, a, got[:3] - ref)
            values_only, _ = _both(p, a, table, grid, nout=3)
            assert_allclose(values_only, got[:3], rtol=0, atol=0)


def test_table_derivative_is_the_derivative_of_the_quadrature(tables, rng):
    # dS/dp of the fit against central differences of the quadrature (step 1e-6 |p|, error
    # ~1e-9 relative), away from |p| = 1 where the integrals are singular.
    table, grid = tables
    a = 0.08
    for p in np.r_[rng.uniform(-0.95, 0.95, 50), 1.0 / rng.uniform(-0.95, 0.95, 50)]:
        got, _ = _both(p, a, table, grid)
        h = 1e-6 * max(1.0, abs(p))
        _, up = _both(p + h, a, table, grid)
        _, down = _both(p - h, a, table, grid)
        fd = (up - down) / (2 * h)
        scale = np.array([1.0, a, a]) / min(1.0, 1 - abs(p) if abs(p) < 1 else 1 - 1 / abs(p))
        assert np.all(np.abs(got[3:] - fd) <= 1e-7 * scale), (p, got[3:] - fd)


def test_table_ball_loads_match_the_kernel_and_its_jacobian(tables, rng):
    # table_ball_loads against ball_loads_kernel (the quadrature): loads to 1e-13 of mu sum F;
    # its Jacobian against central differences of ball_loads_kernel (1e-6 relative).
    table, grid = tables
    full_grid = quadrature_grid(DEFAULT_ANGULAR_NODES, 2, Q)
    vgroove = np.array([0.0, 0.0, 1.0, 1.0])
    for _ in range(20):
        beta = TABLE1.nominal_contact_angle + rng.uniform(-0.04, 0.04, 4)
        force = rng.uniform(20.0, 400.0, 4)
        force[rng.integers(4)] *= rng.integers(2)  # three-point balls too
        px = np.array([-1.0, 1.0, 1.0, -1.0]) * np.sin(beta)
        py = np.array([-1.0, -1.0, 1.0, 1.0]) * np.cos(beta)
        a = HC.semi_major_coefficient * np.cbrt(force) / TABLE1.ball_radius
        b = a * Q
        state = np.array([0.5 + rng.uniform(-0.02, 0.02), *rng.uniform(-1.0, 1.0, 2), 0.0])
        loads, ref = np.empty(5), np.empty(5)
        contact, ref_contact = np.empty((4, 6)), np.empty((4, 6))
        jac = np.empty((3, 3))
        table_ball_loads(state, px, py, vgroove, force, a, b, SIGMA, table, *grid, loads,
                         contact, jac, np.empty(6))
        ball_loads_kernel(state, px, py, vgroove, force, a, b, SIGMA, False, 1.0, np.zeros(4),
                          *full_grid, ref, ref_contact)
        total = force.sum()
        assert_allclose(loads[[0, 1, 2, 4]] / total, ref[[0, 1, 2, 4]] / total, rtol=0,
                        atol=1e-13)
        assert_allclose(contact[:, [2, 3, 4, 5]], ref_contact[:, [2, 3, 4, 5]], rtol=0,
                        atol=1e-13 * total)
        for c in range(3):
            h = 1e-6
            up, down = np.empty(5), np.empty(5)
            for sign, out in ((1, up), (-1, down)):
                trial = state.copy()
                trial[c] += sign * h
                ball_loads_kernel(trial, px, py, vgroove, force, a, b, SIGMA, False, 1.0,
                                  np.zeros(4), *full_grid, out, np.empty((4, 5)))
            assert_allclose(jac[:, c], (up[:3] - down[:3]) / (2 * h), rtol=1e-6,
                            atol=1e-6 * total)


def test_certificate_scan_constants_change_nothing(tables, rng):
    # The certificate from the scan constants against the same certificate with every
    # direction evaluated per ball (usable flags cleared): equal to 1e-13 of the force.
    table, grid = tables
    scan = scan_constants(Q, table, *grid)
    assert scan[:, 5].sum() == CERTIFICATE_DIRECTIONS - 6  # sliding and |cot phi| = 1
    direct = scan.copy()
    direct[:, 5] = 0.0
    for _ in range(50):
        force = rng.uniform(50.0, 400.0)
        a = HC.semi_major_coefficient * np.cbrt(force) / TABLE1.ball_radius
        qu, qw = rng.uniform(-1.0, 1.0) * force, rng.uniform(-0.3, 0.3) * force * a
        got = stick_certificate(qu, qw, force, a, a * Q, SIGMA, table, *grid, scan)
        ref = stick_certificate(qu, qw, force, a, a * Q, SIGMA, table, *grid, direct)
        assert abs(got - ref) <= 1e-13 * force


def test_regime_a_newton_converges_in_few_steps():
    # The Newton on the tables has the exact Jacobian: on random Fig. 7 balls it needs at most
    # 8 steps (measured median 3, max 6 with the polishing step), where the Broyden iteration
    # it replaced needed a median of 7.
    rng = np.random.default_rng(12)
    dbeta = rng.uniform(-np.deg2rad(2.0), np.deg2rad(2.0), (300, 4))
    force = paired_forces(rng.uniform(-0.6, 0.6, 300) * 200.0, 200.0)
    res = full(dbeta, force)
    assert (res.regime == 1).all()
    assert np.median(res.iterations) <= 4 and res.iterations.max() <= 8
