"""The analytical velocity models: Table 2, the paper's invariants and NumPy twins."""

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.testing import assert_allclose

from tolsim.physics import analytic as A
from tolsim.physics.geometry import (
    CONSTRAINT_SIGN,
    FRICTION_SIGN,
    K_F_PAPER,
    SPIN_SIGN,
    TABLE1,
    contact_frames,
    paired_forces,
)
from tolsim.physics.hertz import hertz_constants

THETA = np.deg2rad(2.0)  # Lin2018 Sec. 3.2 / Table 2
NY = 200.0  # Lin2018 Table 1


def case_a(rho):
    return np.array([-THETA, THETA, 0.0, 0.0]), paired_forces(rho * NY, NY)


# ------------------------------------------------------------------ NumPy / SciPy twins
def eq24_twin(dbeta, force, beta0=np.pi / 4):
    f1 = (force[:, 0] + force[:, 2]) / 2
    f2 = (force[:, 1] + force[:, 3]) / 2
    w1, w2 = f1 ** (2 / 3), f2 ** (2 / 3)
    num = (-dbeta[:, 0] + dbeta[:, 2]) * w1 + (-dbeta[:, 1] + dbeta[:, 3]) * w2
    return np.tan(beta0) / 2 * num / (w1 + w2)


def analytic_twin(dbeta, force, bearing=TABLE1, k_f=K_F_PAPER):
    """Eqs. (17), (18) (ERRATA 8 sign) and (21) as an explicit 4x4 system, np.linalg.solve."""
    hc = hertz_constants(bearing.ball_radius, bearing.conformity)
    R = bearing.ball_radius
    beta = bearing.nominal_contact_angle + dbeta
    _, x_axis, y_axis = contact_frames(beta)  # (n, 4, 2)
    a = hc.semi_major_coefficient * force ** (1 / 3)
    fric = k_f * R * force / a * FRICTION_SIGN  # f_i / (mu dgamma_i), Eq. (17)
    spin = 3 / 8 * force * a * hc.elliptic_e / R * SPIN_SIGN  # M_i / (mu R), Eq. (14)
    n = len(dbeta)
    mat = np.zeros((n, 4, 4))
    rhs = np.zeros((n, 4))
    mat[:, 0] = fric
    mat[:, 1] = fric * x_axis[..., 0]
    mat[:, 2] = fric * x_axis[..., 1]
    mat[:, 3] = CONSTRAINT_SIGN
    rhs[:, 1] = -(spin * y_axis[..., 0]).sum(-1)
    rhs[:, 2] = -(spin * y_axis[..., 1]).sum(-1)
    rhs[:, 3] = -(dbeta @ CONSTRAINT_SIGN)
    gamma = np.linalg.solve(mat, rhs[..., None])[..., 0]
    b0 = bearing.nominal_contact_angle
    eps = np.tan(b0) / 2 * (-dbeta[:, 1] - gamma[:, 1] + dbeta[:, 3] + gamma[:, 3])
    return eps, gamma


def point_twin(dbeta, force, beta0=np.pi / 4):
    """Point-contact model by brute force: every sliding candidate with np.linalg.solve."""
    out = []
    for db, f in zip(dbeta, force, strict=True):
        beta = beta0 + db
        pos, x_axis, _ = contact_frames(beta)
        target = np.array([0.0, 0.0, 1.0, 1.0])
        best = None
        for j in range(4):
            k = [i for i in range(4) if i != j]
            kin = np.column_stack([np.ones(3), pos[k, 1], -pos[k, 0]])
            vb, wx, wy = np.linalg.solve(kin, target[k])
            slip = vb + wx * pos[j, 1] - wy * pos[j, 0] - target[j]
            fj = -f[j] * np.sign(slip)
            eq = np.vstack([np.ones(3), x_axis[k, 0], x_axis[k, 1]])
            fk = np.linalg.solve(eq, -fj * np.array([1.0, x_axis[j, 0], x_axis[j, 1]]))
            margin = np.min((f[k] - np.abs(fk)) / f[k])
            if best is None or margin > best[0] + 1e-12:
                best = (margin, 2 * vb - 1)
        out.append(best[1])
    return np.array(out)


angles = arrays(np.float64, (8, 4), elements=st.floats(-0.05, 0.05))
forces = arrays(np.float64, (8, 4), elements=st.floats(5.0, 800.0))


# ------------------------------------------------------------------ Table 2
@pytest.mark.parametrize("model", [A.eq24, A.analytic])
def test_lin2018_table2_case_a_derived_formula(model):
    # Lin2018 Table 2, case (a), "Derived formula": eps1 = +0.75 %, eps2 = -0.75 % (rounded to
    # 0.01 %): tolerance 0.005 percentage points. ERRATA 2: Eq. (26) gives +0.754 %.
    eps1 = model(*case_a(-0.6)).velocity_deviation * 100
    eps2 = model(*case_a(+0.6)).velocity_deviation * 100
    assert eps1 == pytest.approx(0.75, abs=0.005)
    assert eps2 == pytest.approx(-0.75, abs=0.005)


def test_lin2018_eq26_with_errata2():
    # ERRATA 2: eps = (theta/2) (1 - r^(2/3)) / (1 + r^(2/3)), r = (1 + rho)/(1 - rho);
    # +0.754 % at theta = 2 deg, rho = -0.6. Exact identity with Eq. (24): 1e-12.
    for rho in (-0.8, -0.6, -0.1, 0.3, 0.6):
        r = (1 + rho) / (1 - rho)
        eq26 = THETA / 2 * (1 - r ** (2 / 3)) / (1 + r ** (2 / 3))
        assert A.eq24(*case_a(rho)).velocity_deviation == pytest.approx(eq26, abs=1e-12)
    assert 100 * A.eq24(*case_a(-0.6)).velocity_deviation == pytest.approx(0.754, abs=5e-4)


@pytest.mark.parametrize("model", [A.eq24, A.analytic])
@pytest.mark.parametrize("rho", [-0.6, 0.6])
def test_lin2018_table2_case_b_zero(model, rho):
    # Lin2018 Table 2, case (b): dbeta_TR = -theta, dbeta_TL = +theta -> eps = 0 (1e-15).
    dbeta = np.array([-THETA, THETA, -THETA, THETA])
    eps = model(dbeta, paired_forces(rho * NY, NY)).velocity_deviation
    assert abs(eps) < 1e-15


# ------------------------------------------------------------------ invariants
@given(forces)
@pytest.mark.parametrize("model", [A.eq24, A.point])
def test_no_deviation_gives_nominal_velocity(model, force):
    # Lin2018 Sec. 2.4 insight (1): no contact-angle deviation -> eps = 0, v_B = v/2, for any
    # forces; round-off tolerance 1e-13.
    res = model(np.zeros((8, 4)), force)
    assert_allclose(res.velocity_deviation, 0.0, atol=1e-13)


@given(arrays(np.float64, (8, 2), elements=st.floats(5.0, 800.0)))
def test_no_deviation_gives_nominal_velocity_analytic(pair):
    # Same invariant for the 4x4 model, for every statically admissible set of forces: with
    # all beta_i = beta_0, ball equilibrium forces F_BL = F_TR and F_BR = F_TL, for any load.
    # (Four distinct forces with no deviation cannot balance the ball; fed such forces anyway,
    # the spin-moment terms give eps of order 1e-3 -- see the next test.) Tolerance 1e-13.
    force = np.column_stack([pair[:, 0], pair[:, 1], pair[:, 0], pair[:, 1]])
    res = A.analytic(np.zeros((8, 4)), force)
    assert_allclose(res.velocity_deviation, 0.0, atol=1e-13)
    assert_allclose(res.velocity_deviation_eq22, 0.0, atol=1e-13)


def test_inadmissible_distinct_forces_without_deviation():
    # Documents a property of the linearised model (not of the paper): unequal spin moments
    # of four distinct forces shift the zero-velocity points unevenly, so eps != 0 even with
    # no deviation. Values of this implementation, 1e-9 relative, as a regression guard.
    res = A.analytic(np.zeros(4), [100.0, 50.0, 300.0, 20.0])
    assert res.velocity_deviation == pytest.approx(-1.0769391783e-3, rel=1e-9)


@given(st.floats(-0.8, 0.8), st.floats(-0.06, 0.06))
@pytest.mark.parametrize("model", [A.eq24, A.analytic, A.point])
def test_load_side_mirror(model, rho, theta):
    # Swapping the load side mirrors eps under paired loading: eps(rho, theta) = -eps(-rho,
    # theta) (Lin2018 Eq. 26 and Fig. 7 symmetry); round-off tolerance 1e-12. The point model
    # jumps at rho = 0 (which contact slides is a tie there; flagged invalid), so it is
    # checked away from it.
    assume(model is not A.point or abs(rho) > 1e-6)
    dbeta = np.array([-theta, theta, 0.0, 0.0])
    e1 = model(dbeta, paired_forces(rho * NY, NY)).velocity_deviation
    e2 = model(dbeta, paired_forces(-rho * NY, NY)).velocity_deviation
    assert e1 == pytest.approx(-e2, abs=1e-12)


@given(arrays(np.float64, (8, 2), elements=st.floats(-0.05, 0.05)),
       arrays(np.float64, (8, 2), elements=st.floats(5.0, 800.0)))
@pytest.mark.parametrize("model", [A.eq24, A.analytic])
def test_matched_top_bottom_deviations_give_zero(model, bottom, pair):
    # Lin2018 Sec. 3.2: dbeta_TR = dbeta_BL and dbeta_TL = dbeta_BR -> eps = 0 "irrespective
    # of external loading" (paired forces, as Eq. 24 assumes); tolerance 1e-13.
    dbeta = np.column_stack([bottom[:, 0], bottom[:, 1], bottom[:, 0], bottom[:, 1]])
    force = np.column_stack([pair[:, 0], pair[:, 1], pair[:, 0], pair[:, 1]])
    assert_allclose(model(dbeta, force).velocity_deviation, 0.0, atol=1e-13)


@given(angles, arrays(np.float64, (8, 2), elements=st.floats(5.0, 800.0)))
def test_analytic_reduces_to_eq24_when_paired(dbeta, pair):
    # The requirement: with F_BL = F_TR and F_BR = F_TL the 4x4 solution gives Eq. (24)
    # exactly (module docstring of tolsim.physics.analytic); round-off tolerance 1e-13.
    force = np.column_stack([pair[:, 0], pair[:, 1], pair[:, 0], pair[:, 1]])
    assert_allclose(A.analytic(dbeta, force).velocity_deviation,
                    A.eq24(dbeta, force).velocity_deviation, atol=1e-13)


def test_errata8_moment_sign_matters_only_with_distinct_forces():
    # ERRATA 8: with the printed sign of the spin-moment block, eps changes for four distinct
    # forces but not for paired ones. The kernel must agree with the physical-sign twin (1e-12)
    # and differ from the printed-sign variant by more than 1e-4 (absolute eps) for this case.
    dbeta = np.array([[-THETA, THETA, 0.0, 0.0]])
    force = np.array([[230.0, 50.0, 200.0, 70.0]])
    eps_kernel = A.analytic(dbeta, force).velocity_deviation
    eps_twin, _ = analytic_twin(dbeta, force)
    assert_allclose(eps_kernel, eps_twin, atol=1e-12)

    hc = hertz_constants(TABLE1.ball_radius, TABLE1.conformity)
    # printed sign == physical solve with the spin moments negated (E(e) -> -E(e))
    eps_printed = np.empty(1)
    A.analytic_kernel(dbeta, force, np.pi / 4, TABLE1.ball_radius, hc.semi_major_coefficient,
                      -hc.elliptic_e, K_F_PAPER, 0.5, 1.0, eps_printed, np.empty(1),
                      np.empty((1, 4)), np.empty(1, dtype=bool))
    assert abs(eps_printed[0] - eps_kernel[0]) > 1e-4
    paired = np.array([[230.0, 50.0, 230.0, 50.0]])
    eps_paired = A.analytic(dbeta, paired).velocity_deviation
    A.analytic_kernel(dbeta, paired, np.pi / 4, TABLE1.ball_radius, hc.semi_major_coefficient,
                      -hc.elliptic_e, K_F_PAPER, 0.5, 1.0, eps_printed, np.empty(1),
                      np.empty((1, 4)), np.empty(1, dtype=bool))
    assert eps_printed[0] == pytest.approx(eps_paired[0], abs=1e-14)


# ------------------------------------------------------------------ twins
@given(angles, forces)
def test_eq24_kernel_matches_numpy_twin(dbeta, force):
    assert_allclose(A.eq24(dbeta, force).velocity_deviation, eq24_twin(dbeta, force),
                    rtol=1e-12, atol=1e-15)


@given(angles, forces)
def test_analytic_kernel_matches_numpy_twin(dbeta, force):
    eps, gamma = analytic_twin(dbeta, force)
    res = A.analytic(dbeta, force)
    assert_allclose(res.zero_velocity_offset, gamma, rtol=1e-9, atol=1e-13)
    assert_allclose(res.velocity_deviation, eps, rtol=1e-9, atol=1e-14)


@given(angles, forces)
def test_point_kernel_matches_twin(dbeta, force):
    assert_allclose(A.point(dbeta, force).velocity_deviation, point_twin(dbeta, force),
                    atol=1e-12)


@pytest.mark.parametrize("beta0_deg", [30.0, 45.0, 60.0])
def test_errata9_eq23_is_the_linearisation_of_eq22(beta0_deg):
    # ERRATA 9: linearising Eq. (22) about beta_0 gives the factor tan(beta0)/2. Check on
    # angles that satisfy the exact parallel-lines constraint (19) (TR follows): the remainder
    # after subtracting tan(beta0)/2 (-u_BR + u_TL) shrinks quadratically (ratio 4 +/- 0.5 on
    # halving), whereas the printed factor (1 - cos 2 beta0)/2 leaves a linear remainder
    # (ratio ~ 2) away from 45 deg.
    b0 = np.deg2rad(beta0_deg)
    u = np.array([0.013, -0.021, 0.0, 0.017])  # BL, BR, (TR unused by Eq. 22), TL [rad]

    def remainder(scale, factor):
        ub = scale * u
        exact = A.eq22_velocity_deviation(b0 + ub[0], b0 + ub[1], b0 + ub[3])
        return abs(exact - factor * (-ub[1] + ub[3]))

    good = remainder(1e-2, np.tan(b0) / 2) / remainder(5e-3, np.tan(b0) / 2)
    assert good == pytest.approx(4.0, abs=0.5)
    if beta0_deg != 45.0:
        printed = (1 - np.cos(2 * b0)) / 2
        assert remainder(1e-2, printed) / remainder(5e-3, printed) == pytest.approx(2.0, abs=0.1)


# ------------------------------------------------------------------ point model
def test_point_model_case_a_is_gross():
    # Linearising the point model with BR (or TL) sliding gives eps = theta/2 = 1.745 % for
    # Table 2 case (a), ball 1 (derivation in tolsim.physics.analytic.point); Eq. (22) is exact,
    # so the nonlinear value is within 5 % of that. It is "grossly inaccurate" (Fig. 7(b)):
    # more than twice the Table 2 formula value.
    res = A.point(*case_a(-0.6))
    assert res.velocity_deviation == pytest.approx(THETA / 2, rel=0.05)
    assert res.extra["sliding_contact"] in (1, 3)  # a lightly loaded contact (BR or TL) slides
    assert res.velocity_deviation > 2 * A.eq24(*case_a(-0.6)).velocity_deviation


# ------------------------------------------------------------------ validity
def test_validity_threshold_consistent_between_models():
    # MIN_DIAGONAL_FORCE_RATIO (eq24) is calibrated on the analytic |c/a| <= 0.5 criterion at
    # theta = 2 deg: valid at rho = 0.6 (ratio 0.25), invalid at rho = 0.65 (ratio 0.21).
    for model in (A.eq24, A.analytic):
        assert model(*case_a(0.6)).valid
        assert not model(*case_a(0.65)).valid


def test_zero_force_is_flagged_not_raised():
    res = A.analytic(np.zeros(4), [100.0, 0.0, 100.0, 50.0])
    assert not res.valid
    assert not A.eq24(np.zeros(4), [100.0, 0.0, 100.0, 50.0]).valid


@pytest.mark.parametrize("model", [A.eq24, A.analytic, A.point])
def test_bad_input_names_argument(model):
    with pytest.raises(ValueError, match="contact_angle_deviation"):
        model(np.zeros(3), np.ones(4))
    with pytest.raises(ValueError, match="normal_force"):
        model(np.zeros(4), [1.0, -1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="normal_force"):
        model(np.zeros(4), [1.0, np.nan, 1.0, 1.0])


def test_shapes_broadcast():
    res = A.analytic(np.zeros((3, 2, 4)), np.full(4, 100.0))
    assert res.velocity_deviation.shape == (3, 2)
    assert res.zero_velocity_offset.shape == (3, 2, 4)


def test_analytic_kernel_skips_eq22_and_gamma_on_request(rng):
    # A study passes empty eq22 / dgamma outputs: epsilon and validity are bit-identical.
    n = 1000
    dbeta = rng.normal(0, np.deg2rad(0.5), (n, 4))
    force = rng.uniform(20.0, 300.0, (n, 4))
    hc = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                         TABLE1.poisson_ratio)
    args = (dbeta, force, TABLE1.nominal_contact_angle, TABLE1.ball_radius,
            hc.semi_major_coefficient, hc.elliptic_e, K_F_PAPER, A.MAX_ZERO_VELOCITY_RATIO,
            A.MAX_ANGLE_SUM)
    eps, eps22, gamma, valid = np.empty(n), np.empty(n), np.empty((n, 4)), np.empty(n, bool)
    A.analytic_kernel(*args, eps, eps22, gamma, valid)
    eps_s, valid_s = np.empty(n), np.empty(n, bool)
    A.analytic_kernel(*args, eps_s, np.empty(0), np.empty((0, 4)), valid_s)
    assert np.array_equal(eps, eps_s) and np.array_equal(valid, valid_s)
    beta = TABLE1.nominal_contact_angle + dbeta + gamma  # Eq. (22) was computed
    assert_allclose(eps22, [A.eq22_velocity_deviation(b[0], b[1], b[3]) for b in beta],
                    rtol=1e-12, atol=1e-15)
