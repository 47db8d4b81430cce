"""Sobol' sensitivity indices (tolsim.study.analyses.sensitivity) on cases with known answers."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats
from scipy.stats import sobol_indices

from tolsim.study.analyses.sensitivity import (
    CONTACT,
    VELOCITY_DEVIATION,
    indices_from_evaluations,
    sobol_sensitivity,
    study_factors,
    study_sensitivity,
)

# Linear model Y = sum a_i X_i, X_i ~ N(0, s_i^2) independent: Var(Y) = sum a_i^2 s_i^2 and
# S_i = S_Ti = a_i^2 s_i^2 / Var(Y) (no interactions). Unequal shares, one small and one null.
COEFFS = np.array([1.0, 2.0, 0.5, 0.3, 0.0])
STDS = np.array([1.0, 0.5, 2.0, 1.0, 3.0])
LINEAR_TRUE = (COEFFS * STDS) ** 2 / np.sum((COEFFS * STDS) ** 2)  # 0.32, 0.32, 0.32, 0.029, 0


def _gen(*key):
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(20181109, spawn_key=key)))


def _inside(ci, value):
    return (ci[..., 0] <= value + 1e-12) & (value <= ci[..., 1] + 1e-12)


def test_linear_known_answer_inside_confidence_intervals():
    # Analytic answer above; the estimates must lie within their own 95 % intervals' reach:
    # every true index inside its interval, and the intervals narrow enough to mean something.
    dists = [stats.norm(0.0, s) for s in STDS]
    res = sobol_sensitivity(lambda x: x @ COEFFS, dists, 4096, _gen(0),
                            factors=[f"x{i}" for i in range(5)])
    assert res.first_order.shape == (1, 5) and res.evaluations == 4096 * 7
    assert np.all(_inside(res.first_order_ci[0], LINEAR_TRUE)), (res.first_order_ci,
                                                                 LINEAR_TRUE)
    assert np.all(_inside(res.total_ci[0], LINEAR_TRUE)), (res.total_ci, LINEAR_TRUE)
    assert np.all(res.total_ci[0, :, 1] - res.total_ci[0, :, 0] < 0.06)
    assert np.all(res.first_order_ci[0, :, 1] - res.first_order_ci[0, :, 0] < 0.08)
    # the null factor has exactly zero total effect (f(A) == f(AB_4) row by row)
    assert res.total[0, 4] == 0.0
    # variance: sum a_i^2 s_i^2 = 3.09; sampling error of a variance at n = 8192 is ~1.6 %
    assert_allclose(res.variance[0], np.sum((COEFFS * STDS) ** 2), rtol=0.06)
    # ranking by S_T: the coefficients give (a_i s_i)^2 = 1, 1, 1, 0.09, 0, so x0, x1, x2 tie
    # for the top three (any order; their true gap is 0, the estimates differ by noise),
    # then x3 (true 0.029, > 10 CI widths below the others), then the null x4
    names = [r[0] for r in res.ranking()]
    assert set(names[:3]) == {"x0", "x1", "x2"} and names[3:] == ["x3", "x4"], names


def test_linear_interval_coverage():
    # The 95 % bootstrap intervals must cover the analytic answer about 95 % of the time.
    # 60 independent repetitions x 8 non-degenerate indices; measured 0.95 when written.
    # Binomial (if independent) sd of the mean is 0.01; the bounds are > 5 sd away.
    dists = [stats.norm(0.0, s) for s in STDS[:4]]
    truth = (COEFFS[:4] * STDS[:4]) ** 2 / np.sum((COEFFS[:4] * STDS[:4]) ** 2)
    hits = []
    for k in range(60):
        res = sobol_sensitivity(lambda x: x @ COEFFS[:4], dists, 512, _gen(1, k),
                                n_resamples=400)
        hits.append(np.concatenate([_inside(res.first_order_ci[0], truth),
                                    _inside(res.total_ci[0], truth)]))
    coverage = np.mean(hits)
    assert 0.88 <= coverage <= 0.995, coverage


def test_grouped_factors_and_marginal_kinds():
    # Y = X0 + 2 X1 + X2 with groups {0, 1} and {2}: S_{01} = (1 + 4 * 0.25) / V, S_2 = 4 / V
    # for X0 ~ N(0, 1), X1 ~ U(-sqrt(3)/2*..): use unit-variance-free explicit variances below.
    from tolsim.study.spec import Distribution

    dists = [stats.norm(0.0, 1.0),                      # var 1
             Distribution("uniform", low=-0.5, high=0.5),  # var 1/12 (tolsim from_normal)
             stats.norm(0.0, 2.0)]                      # var 4
    coef = np.array([1.0, 2.0, 1.0])
    var = np.array([1.0, 1.0 / 12.0, 4.0]) * coef**2
    truth = np.array([var[0] + var[1], var[2]]) / var.sum()
    res = sobol_sensitivity(lambda x: x @ coef, dists, 4096, _gen(2), groups=[[0, 1], [2]],
                            factors=["pair", "single"])
    assert res.factors == ("pair", "single")
    assert np.all(_inside(res.first_order_ci[0], truth)), (res.first_order_ci, truth)
    assert np.all(_inside(res.total_ci[0], truth)), (res.total_ci, truth)


def test_pooled_replicates_are_variance_weighted_average():
    # Two replicate columns: column 0 = X0 + X1 (S = 0.5, 0.5, Var 2), column 1 = 3 X0
    # (S = 1, 0, Var 9). Pooled: S_0 = (0.5*2 + 1*9) / 11 = 10/11, S_1 = 1/11.
    dists = [stats.norm(), stats.norm()]
    res = sobol_sensitivity(lambda x: np.stack([x[:, 0] + x[:, 1], 3 * x[:, 0]], axis=1),
                            dists, 4096, _gen(3))
    truth = np.array([10.0 / 11.0, 1.0 / 11.0])
    assert np.all(_inside(res.total_ci[0], truth)), (res.total_ci, truth)
    assert np.all(_inside(res.first_order_ci[0], truth)), (res.first_order_ci, truth)


def test_ishigami_function():
    # Ishigami & Homma (1990), a = 7, b = 0.1, X_i ~ U(-pi, pi); analytic indices from
    # Saltelli et al., Global Sensitivity Analysis: The Primer (2008), Sec. 4.9:
    # S = (0.3139, 0.4424, 0), S_T = (0.5576, 0.4424, 0.2437). Non-linear, with interaction.
    def ishigami(x):
        return np.sin(x[:, 0]) + 7 * np.sin(x[:, 1]) ** 2 + 0.1 * x[:, 2] ** 4 * np.sin(x[:, 0])

    dists = [stats.uniform(-np.pi, 2 * np.pi)] * 3
    res = sobol_sensitivity(ishigami, dists, 1 << 14, _gen(4), n_resamples=500)
    s_true = np.array([0.3139, 0.4424, 0.0])
    st_true = np.array([0.5576, 0.4424, 0.2437])
    assert np.all(_inside(res.first_order_ci[0], s_true)), (res.first_order_ci, s_true)
    assert np.all(_inside(res.total_ci[0], st_true)), (res.total_ci, st_true)
    assert_allclose(res.total[0], st_true, atol=0.03)


def test_estimator_twin_scipy_sobol_indices(rng):
    # Same evaluations into scipy.stats.sobol_indices (dict form, method saltelli_2010):
    # identical point estimates (same estimator) for one unpooled, all-finite output.
    n, d = 512, 4
    f_a, f_b = rng.normal(size=n), rng.normal(size=n)
    f_ab = rng.normal(size=(d, n)) * 0.5 + f_a
    ref = sobol_indices(func={"f_A": f_a[None], "f_B": f_b[None], "f_AB": f_ab[:, None, :]},
                        n=n)
    ours = indices_from_evaluations(f_a, f_b, f_ab, rng, n_resamples=0)
    assert_allclose(ours["first_order"], np.ravel(ref.first_order), rtol=1e-12, atol=1e-14)
    assert_allclose(ours["total"], np.ravel(ref.total_order), rtol=1e-12, atol=1e-14)


def test_non_finite_evaluations_are_excluded(rng):
    n = 400
    f_a, f_b = rng.normal(size=n), rng.normal(size=n)
    f_ab = np.stack([f_a + 0.1 * rng.normal(size=n), f_b])
    clean = indices_from_evaluations(f_a[:300], f_b[:300], f_ab[:, :300], rng, n_resamples=0)
    f_a2 = f_a.copy()
    f_a2[300:350] = np.nan
    f_ab2 = f_ab.copy()
    f_ab2[1, 350:] = np.inf
    dirty = indices_from_evaluations(f_a2, f_b, f_ab2, rng, n_resamples=0)
    assert dirty["excluded"] == 100 and dirty["used"] == 300
    assert_allclose(dirty["first_order"], clean["first_order"], rtol=1e-12)
    assert_allclose(dirty["total"], clean["total"], rtol=1e-12)


def test_constant_output_gives_nan_indices(rng):
    res = sobol_sensitivity(lambda x: np.zeros(len(x)), [stats.norm()] * 2, 64, rng)
    assert np.all(np.isnan(res.first_order)) and np.all(np.isnan(res.total))
    assert res.reasons == ("the output does not vary: indices not estimable",)
    # a constant that is not 0: its centred values are rounding residue, still no variance
    res = sobol_sensitivity(lambda x: np.full(len(x), 0.1), [stats.norm()] * 2, 64, rng)
    assert np.all(np.isnan(res.total)) and res.reasons[0].startswith("the output does not")


def _nearly_constant(n, rows_a, rows_b):
    """A 0/1 output, 1 only in the given rows of A and B (contact nearly impossible), with
    factor 0 inert and factor 1 carrying B's rows into AB_1."""
    f_a, f_b = np.zeros(n), np.zeros(n)
    f_a[rows_a], f_b[rows_b] = 1.0, 1.0
    f_ab = np.stack([f_a, np.maximum(f_a, f_b)])
    return f_a, f_b, f_ab


def test_nearly_constant_output_is_not_estimable():
    # rare_contact.toml with gaps U(0, 1 um): the contact indicator differed in 3 of 2 048 base rows
    # and the report showed S_T = 1.669 with CI [0.334, nan]. A resample misses those 3 rows
    # with probability ~e^-3 = 5 % > 2.5 %: no variance there, the interval has no upper end.
    f_a, f_b, f_ab = _nearly_constant(1024, [5, 17], [40])
    res = indices_from_evaluations(f_a, f_b, f_ab, _gen(7), n_resamples=1000)
    assert res["variance"] > 0
    assert res["reason"].startswith("the output varies in only 3 of 2,048 rows: indices not "
                                    "estimable (")
    for key in ("first_order", "total", "first_order_ci", "total_ci"):
        assert np.all(np.isnan(res[key])), (key, res[key])
    # ... and the reason is carried to the result of several outputs
    evaluations = np.concatenate([f_a, f_b, *f_ab])
    both = sobol_sensitivity(
        lambda x: {"constant": evaluations, "sum": x.sum(axis=1)},
        lambda rng, n: np.zeros((n, 2)), 1024, _gen(7))
    assert both.reasons[0].startswith("the output varies in only 3 of 2,048 rows")
    assert both.reasons[1] == "the output does not vary: indices not estimable"


def test_an_output_varying_in_enough_rows_keeps_finite_indices():
    # 12 varying rows: a resample misses them all with probability ~e^-12; every resample has
    # a variance and the indices and both ends of their intervals are finite
    f_a, f_b, f_ab = _nearly_constant(1024, [3, 50, 90, 200, 300, 400], [7, 60, 95, 600,
                                                                         700, 800])
    res = indices_from_evaluations(f_a, f_b, f_ab, _gen(8), n_resamples=1000)
    assert res["reason"] == ""
    assert np.all(np.isfinite(res["total"])) and np.all(np.isfinite(res["total_ci"]))
    assert np.all(np.isfinite(res["first_order_ci"]))
    assert res["total"][0] == 0.0 and 0.0 < res["total"][1] <= res["total_ci"][1, 1]


@pytest.mark.parametrize("kwargs, word", [
    (dict(n=1), "n ="),
    (dict(rng=0), "rng"),
    (dict(groups=[[0], [0]]), "groups"),
    (dict(factors=["a"]), "factors"),
    (dict(confidence_level=1.5), "confidence_level"),
    (dict(sampler=[object()]), "dists[0]"),
])
def test_validation(kwargs, word):
    args = dict(func=lambda x: x.sum(axis=1), sampler=[stats.norm()] * 2, n=16,
                rng=np.random.default_rng(0))
    args.update(kwargs)
    with pytest.raises(ValueError, match=word.replace("[", r"\[")):
        sobol_sensitivity(args.pop("func"), args.pop("sampler"), args.pop("n"),
                          args.pop("rng"), **args)


# --------------------------------------------------------------------------------------------
# On a tolsim study
# --------------------------------------------------------------------------------------------
CONFIG_LINEAR = """
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
nominal_contact_angle_deg = 45.0
youngs_modulus_GPa = 210.0
poisson_ratio = 0.28
friction_coefficient = 0.1
[motion]
groove_velocity_mm_per_s = 10.0
duration_s = 10.0
[train]
balls = 2
initial_gap = { distribution = "fixed", value_mm = 0.5 }
[loads]
normal_load_N = 200.0
side_force_ratio = [0.0, 0.0]
[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.2
scope = "carriage"
[tolerances.top_rotation]
distribution = "normal"
std_deg = 0.1
scope = "carriage"
[tolerances.ball_oversize]
distribution = "fixed"
value_um = 0.0
[study]
samples = 16
seed = 7
velocity_model = "eq24"
static_model = "paired"
"""


def _config(text):
    config_module = pytest.importorskip("tolsim.io.config",
                                        reason="tolsim.io.config (issue 5) not installed")
    return config_module.parse_config(text, "test.toml")


def test_study_sensitivity_linear_rotations():
    # rho = 0 (equal forces), paired static, eq24: Eq. (24) with F1 = F2 reads
    # eps = tan(b0)/4 * [(-dBL + dTR) + (-dBR + dTL)] and the rotations enter as
    # dBL = -tb, dBR = +tb, dTR = -tt, dTL = +tt, so eps = tan(b0)/4 * [(tb - tt) + (tt - tb)]
    # = 0 for every draw: the output has zero variance and the indices are undefined (NaN).
    config = _config(CONFIG_LINEAR)
    assert study_factors(config) == ("bottom_rotation", "top_rotation")
    res = study_sensitivity(config, samples=256, n_resamples=200)
    k = res.output_index(VELOCITY_DEVIATION)
    assert res.variance[k] == 0.0 or res.variance[k] < 1e-30
    assert np.all(np.isnan(res.first_order[k]))


CONFIG_SIDE = CONFIG_LINEAR.replace(
    "side_force_ratio = [0.0, 0.0]", "side_force_ratio = [-0.6, 0.6]").replace(
    "value_mm = 0.5 }", "value_mm = 0.05 }")


def test_study_sensitivity_known_shares_under_side_load():
    # With rho = -/+0.6 the diagonals differ (F1^(2/3) != F2^(2/3)) and Eq. (24) becomes
    # eps = (tan b0 / 2) (w1 (tb - tt) + w2 (tt - tb)) = (tan b0 / 2)(w1 - w2)(tb - tt),
    # w = F^(2/3) / (F1^(2/3) + F2^(2/3)). Linear in (tb, tt) with equal and opposite
    # coefficients, so the shares follow from the variances: S(bottom) = 0.2^2 / (0.2^2 +
    # 0.1^2) = 0.8, S(top) = 0.2, for the eps of either ball.
    config = _config(CONFIG_SIDE)
    res = study_sensitivity(config, samples=1024, n_resamples=400)
    k = res.output_index(VELOCITY_DEVIATION)
    truth = np.array([0.8, 0.2])
    assert np.all(_inside(res.first_order_ci[k], truth)), (res.first_order_ci[k], truth)
    assert np.all(_inside(res.total_ci[k], truth)), (res.total_ci[k], truth)
    # Contact: the trailing ball 0 (rho = -0.6) closes the 0.05 mm gap on ball 1 within
    # T = 10 s when (eps_0 - eps_1) v/2 T >= gap, i.e. (Eq. 26, ERRATA 2, both balls seeing
    # the same tb, tt) Y = 1{tb - tt > c}, c = gap / (2 kappa v/2 T), kappa = (1/2)(1 -
    # 0.25^(2/3))/(1 + 0.25^(2/3)): c = 0.1327 deg, against sd(tb - tt) = 0.2236 deg. Closed
    # forms of this indicator of two independent normals in _threshold_indices (1-D quad).
    # (A ball outside eq24's validity is re-solved by the full model, whose eps is 1-2 %
    # larger here: c lower by <= 2 %, which moves the indices by < 0.001 and P by 0.003.)
    c = res.output_index(CONTACT)
    assert res.used[c] == 1024
    kappa = 0.5 * (1 - 0.25 ** (2 / 3)) / (1 + 0.25 ** (2 / 3))
    threshold = 0.05e-3 / (2 * kappa * 10e-3 / 2 * 10.0)
    prob, first, total = _threshold_indices(np.deg2rad([0.2, 0.1]), threshold)
    # P = 0.2764, S = (0.573, 0.116), S_T = (0.884, 0.427): not additive (S_T > S)
    # mean of 2n = 2048 Bernoulli draws: sd sqrt(P(1-P)/2048) = 0.0099; 4 sd (this seed's
    # draws sit 2.4-2.7 sd below P, with c from Eq. 26 or from the full model)
    assert abs(res.mean[c] - prob) <= 4 * np.sqrt(prob * (1 - prob) / 2048), res.mean[c]
    # Indices within 3 standard errors of the estimator, the standard error read off the
    # 95 % bootstrap interval the result carries, se = (upper - lower) / (2 * 1.96)
    # (se 0.027-0.047 here; estimates are 1.2 and 1.8 se from S_T, 0.6 and 0.4 se from S)
    for est, ci, truth in ((res.total[c], res.total_ci[c], total),
                           (res.first_order[c], res.first_order_ci[c], first)):
        se = (ci[:, 1] - ci[:, 0]) / (2 * 1.959964)
        assert np.all(np.abs(est - truth) <= 3 * se), (est, truth, se)
    assert res.ranking(CONTACT)[0][0] == "bottom_rotation"
    # reproducible
    again = study_sensitivity(config, samples=1024, n_resamples=400)
    assert_allclose(again.total, res.total, rtol=0, atol=0)


def _threshold_indices(stds, threshold):
    """Sobol' indices of Y = 1{X_1 - X_2 > c}, X_i ~ N(0, s_i^2) independent, by 1-D quad.

    With p_1(x_2) = P(Y = 1 | X_2 = x_2) = Phi((-c - x_2)/s_1) and p_2(x_1) = P(Y = 1 |
    X_1 = x_1) = Phi((x_1 - c)/s_2), Y Bernoulli(P), P = Phi(-c / sqrt(s_1^2 + s_2^2)):
    S_T1 = E[Var(Y | X_2)] / Var(Y) = E[p_1 (1 - p_1)] / (P (1 - P)) (likewise S_T2 with p_2),
    S_1 = Var(E[Y | X_1]) / Var(Y) = E[(p_2 - P)^2] / (P (1 - P)) (likewise S_2 with p_1).
    Returns P, (S_1, S_2), (S_T1, S_T2).
    """
    from scipy.integrate import quad

    s1, s2 = stds
    prob = stats.norm.sf(threshold / np.hypot(s1, s2))
    var = prob * (1 - prob)

    def mean_over(func, sd):
        return quad(lambda x: func(x) * stats.norm.pdf(x, 0.0, sd), -12 * sd, 12 * sd,
                    epsabs=1e-13, limit=200)[0]

    def p1(x2):
        return stats.norm.sf((threshold + x2) / s1)

    def p2(x1):
        return stats.norm.cdf((x1 - threshold) / s2)

    total = np.array([mean_over(lambda x: p1(x) * (1 - p1(x)), s2),
                      mean_over(lambda x: p2(x) * (1 - p2(x)), s1)]) / var
    first = np.array([mean_over(lambda x: (p2(x) - prob) ** 2, s1),
                      mean_over(lambda x: (p1(x) - prob) ** 2, s2)]) / var
    return prob, first, total


def test_threshold_indices_closed_form_limits():
    # Checks of the helper itself: a factor with no variance has no effect (S_T = 0) and the
    # other explains everything (S = S_T = 1); the total effects exceed the first-order ones
    # (the event is not additive) and S_1 + S_2 <= 1; with equal spreads they are equal.
    prob, first, total = _threshold_indices([1.0, 1e-9], 0.3)
    assert prob == pytest.approx(stats.norm.sf(0.3), rel=1e-9)
    assert_allclose(total, [1.0, 0.0], atol=1e-6)
    assert_allclose(first, [1.0, 0.0], atol=1e-6)
    prob, first, total = _threshold_indices([1.0, 1.0], 0.5)
    assert total[0] == pytest.approx(total[1], rel=1e-9)
    assert np.all(total > first) and first.sum() <= 1.0
    # Monte Carlo cross-check of the formulas (Jansen estimator on 2e5 plain draws, sd of
    # the estimate ~0.003; 0.015)
    rng = _gen(9)
    n = 200_000
    a, b = rng.normal(size=(n, 2)), rng.normal(size=(n, 2))
    sd = np.array([0.2, 0.1])

    def f(x):
        return (x @ (sd * [1.0, -1.0]) > 0.1).astype(float)

    fa = f(a)
    prob, first, total = _threshold_indices(sd, 0.1)
    for i in range(2):
        ab = a.copy()
        ab[:, i] = b[:, i]
        st = 0.5 * np.mean((fa - f(ab)) ** 2) / fa.var()
        assert st == pytest.approx(total[i], abs=0.015)


def test_sensitivity_variables_for_the_result_file():
    from tolsim.io.schema.sensitivity import SENSITIVITY_VARIABLES, sensitivity_variables

    config = _config(CONFIG_SIDE)
    res = study_sensitivity(config, samples=64, n_resamples=50)
    out = sensitivity_variables(res)
    assert set(out) == set(SENSITIVITY_VARIABLES) | {"factor"}
    assert list(out["factor"]) == list(res.factors)
    k = res.output_index(CONTACT)
    assert_allclose(out["sensitivity_contact_total"], res.total[k])
    assert_allclose(out["sensitivity_total_ci_upper"],
                    res.total_ci[res.output_index(VELOCITY_DEVIATION), :, 1])
    # the two names the schema already declares keep their dims
    assert SENSITIVITY_VARIABLES["sensitivity_total"][0] == ("factor",)
