"""Rare-event estimators over a standard-normal space (tolsim.study.analyses.rare_events).

References used below, each with its tolerance at the test:

* **Two balls with constant epsilon** (issue 15, "Done means"): a linear limit state in
  independent standard normals, exact P = Phi(-beta). Coverage at CI size: 20 seeded repeats
  at P = 1e-3 and 1e-5 and 5 at 1e-7 (``benchmarks/bench_rare_events.py`` runs 50 at all
  three). A correct 95 % interval covers in >= 18 of 20 repeats with probability 0.92, so the
  requirement (>= 90 %) is not a formality; the same runs with intervals a third as wide
  (coverage ~50 %) must fail it, which shows the check can fail.
* **A ball of radius r off the origin** (failure inside it): exact P from the noncentral
  chi-square distribution, P = F_ncx2(r^2; d, |c|^2). The design point is unique and FORM
  (a half-space) overestimates P by a factor ~100; subset simulation does not.
* **The chi-square tail** g = r^2 - |u|^2: exact P = chi2.sf(r^2, d). Every point of the
  sphere is a design point: FORM must flag it, subset simulation must get it right.
"""

import dataclasses

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.special import ndtr, ndtri
from scipy.stats import chi2, ncx2

from tolsim.study.analyses.rare_events import (
    BLOCK_ROWS,
    ESTIMATORS,
    RARE_EVENT_STREAM,
    STATUS_FORM_FAILED,
    STATUS_NO_FAILURE,
    STATUS_PLATEAU,
    RareEventError,
    RareEventResult,
    chain_correlation_factor,
    find_design_point,
    importance_sampling,
    level_statistics,
    monte_carlo,
    subset_simulation,
)

SEED = 20240615
REPEATS = 20
#: >= 90 % of the repeats (the issue's requirement).
MIN_COVERED = 18

# --- the two-ball case ------------------------------------------------------------------------
# Six independent normal tolerance errors x_k = sigma_k u_k [m]; each ball's velocity deviation
# is linear in them, eps_b = sum_k a_bk x_k [-] (illustrative sensitivities a_bk [1/m]), and
# constant along the stroke. With a fixed gap g0 [m], the balls touch within the horizon T [s]
# at groove velocity v [m/s] iff (eps_1 - eps_2) v T / 2 >= g0, so
# g(u) = g0 - (v T / 2) (a_1 - a_2) . (sigma u) [m] is linear and P = Phi(-beta) with
# beta = g0 / ((v T / 2) |(a_1 - a_2) sigma|).
ERROR_STD = np.array([2e-6, 2e-6, 1e-6, 1e-6, 3e-6, 3e-6])                    # [m]
SENSITIVITY = np.array([[300.0, -150.0, 80.0, 0.0, 40.0, 0.0],
                        [-100.0, 200.0, 0.0, 60.0, 0.0, 40.0]])                # [1/m]
GROOVE_VELOCITY = 0.5                                                          # [m/s]
HORIZON = 2.0                                                                  # [s]
DIMENSION = ERROR_STD.size


def two_balls(probability):
    """(limit state g(u) [m], exact P, gap g0 [m], slope [m]) for the gap that gives P."""
    slope = 0.5 * GROOVE_VELOCITY * HORIZON * (SENSITIVITY[0] - SENSITIVITY[1]) * ERROR_STD
    gap = float(-ndtri(probability)) * float(np.linalg.norm(slope))

    def limit_state(u):
        # row by row (a BLAS product u @ slope may change in the last bit with the number of
        # rows, and the bit-identity tests need a limit state whose rows do not)
        return gap - np.sum(u * slope, axis=1)

    return limit_state, float(ndtr(-gap / np.linalg.norm(slope))), gap, slope


def seeds(count, key):
    return [np.random.SeedSequence(SEED, spawn_key=(key, r)) for r in range(count)]


def covered(results, exact):
    return sum(r.ci_lower <= exact <= r.ci_upper for r in results)


@pytest.fixture(scope="module")
def linear_runs():
    """Seeded repeats of subset simulation and importance sampling on the two-ball case."""
    runs = {}
    for key, (probability, count) in enumerate([(1e-3, REPEATS), (1e-5, REPEATS),
                                                 (1e-7, 5)]):
        g, exact, _, _ = two_balls(probability)
        runs["subset", probability] = (exact, [subset_simulation(g, DIMENSION, s)
                                               for s in seeds(count, key)])
        runs["importance", probability] = (exact, [importance_sampling(g, DIMENSION, s)
                                                   for s in seeds(count, 10 + key)])
    return runs


# ---------------------------------------------------------------------------------------------
# the closed-form two-ball case (issue 15)
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("estimator", ["subset", "importance"])
@pytest.mark.parametrize("probability", [1e-3, 1e-5])
def test_two_balls_coverage(linear_runs, estimator, probability):
    # issue 15: the 95 % intervals cover the exact Phi(-beta) in >= 90 % of seeded repeats
    exact, results = linear_runs[estimator, probability]
    assert all(r.ok for r in results)
    assert covered(results, exact) >= MIN_COVERED


@pytest.mark.parametrize("estimator", ["subset", "importance"])
def test_two_balls_coverage_at_1e7(linear_runs, estimator):
    # the full 50 repeats are in the benchmark; here 5, of which at most one may miss
    exact, results = linear_runs[estimator, 1e-7]
    assert covered(results, exact) >= 4


@pytest.mark.parametrize("estimator", ["subset", "importance"])
@pytest.mark.parametrize("probability", [1e-3, 1e-5])
def test_coverage_check_can_fail(linear_runs, estimator, probability):
    # the same runs with intervals a third as wide (on the scale the interval is made on)
    # cover ~50 %: the >= 90 % check above would fail them
    exact, results = linear_runs[estimator, probability]
    narrow = 0
    for r in results:
        if estimator == "subset":
            lower = r.probability * (r.ci_lower / r.probability) ** (1 / 3)
            upper = r.probability * (r.ci_upper / r.probability) ** (1 / 3)
        else:
            half = (r.ci_upper - r.probability) / 3
            lower, upper = r.probability - half, r.probability + half
        narrow += lower <= exact <= upper
    assert narrow < MIN_COVERED


#: Observed spread of ln(P_subset / P) on the two-ball case, n = 1000 (1000 seeded repeats,
#: as in benchmarks/bench_rare_events.py).
SUBSET_LOG_SPREAD = {1e-3: 0.24, 1e-5: 0.35, 1e-7: 0.47}


@pytest.mark.parametrize("probability", [1e-3, 1e-5, 1e-7])
def test_two_balls_relative_error(linear_runs, probability):
    # loose: the geometric mean of the subset estimates within 3 standard errors of P, each
    # within 4 sd; importance sampling (CV ~0.05-0.1 at n = 2000) within 6 % on average and
    # 30 % each
    exact, results = linear_runs["subset", probability]
    log_ratio = np.log([r.probability / exact for r in results])
    spread = SUBSET_LOG_SPREAD[probability]
    assert abs(np.mean(log_ratio)) < 3 * spread / np.sqrt(len(results))
    assert np.all(np.abs(log_ratio) < 4 * spread)
    exact, results = linear_runs["importance", probability]
    ratio = np.array([r.probability for r in results]) / exact
    assert abs(np.mean(ratio) - 1) < 0.06
    assert np.all(np.abs(ratio - 1) < 0.3)
    # the reported CV is near the observed spread (factor 2) for importance sampling
    if len(results) == REPEATS:
        reported = np.mean([r.coefficient_of_variation for r in results])
        assert 0.5 < np.std(ratio, ddof=1) / reported < 2


def test_two_balls_cost_below_monte_carlo(linear_runs):
    # issue 15: >= 100x cheaper than plain Monte Carlo at 1e-5 for the same relative error.
    # Cost for a CV of 0.2: n_eval (CV / 0.2)^2 (CV ~ 1 / sqrt(n_eval)); plain Monte Carlo
    # needs (1 - P) / (P 0.2^2). Uses the reported CV (the benchmark uses the observed one).
    for estimator in ("subset", "importance"):
        exact, results = linear_runs[estimator, 1e-5]
        cost = np.mean([r.evaluations * (r.coefficient_of_variation / 0.2) ** 2
                        for r in results])
        assert (1 - exact) / (exact * 0.2 ** 2) / cost >= 100


def test_two_balls_form_is_exact():
    # linear limit state: u* = beta a (a = -grad g / |grad g|), FORM P = Phi(-beta) exactly
    g, exact, gap, slope = two_balls(1e-5)
    point = find_design_point(g, DIMENSION)
    assert point.converged, point.message
    beta = gap / np.linalg.norm(slope)
    assert_allclose(point.beta, beta, rtol=1e-8)
    assert_allclose(point.point, beta * slope / np.linalg.norm(slope), atol=1e-7)
    assert_allclose(point.form_probability, exact, rtol=1e-7)
    assert_allclose(point.importance_factors, slope ** 2 / (slope @ slope), atol=1e-8)
    assert_allclose(point.importance_factors.sum(), 1.0, rtol=1e-12)


def test_design_point_with_the_callers_gradient():
    g, _, gap, slope = two_balls(1e-4)
    calls = []

    def gradient(u):
        calls.append(u.shape)
        return np.broadcast_to(-slope, u.shape)

    with_gradient = find_design_point(g, DIMENSION, gradient=gradient)
    assert with_gradient.converged and calls and all(c == (1, DIMENSION) for c in calls)
    assert_allclose(with_gradient.point, find_design_point(g, DIMENSION).point, atol=1e-8)
    assert_allclose(with_gradient.gradient, -slope, rtol=1e-12)


def test_importance_result_carries_the_design_point(linear_runs):
    exact, results = linear_runs["importance", 1e-5]
    r = results[0]
    assert_allclose(r.form_probability, exact, rtol=1e-6)
    assert_allclose(np.linalg.norm(r.design_point), r.beta, rtol=1e-12)
    assert r.evaluations > r.samples_per_level                   # FORM is counted
    assert 0 < r.failures < r.samples_per_level


# ---------------------------------------------------------------------------------------------
# nonlinear limit states with closed forms
# ---------------------------------------------------------------------------------------------

BALL_CENTRE = np.array([4.0, 0, 0, 0, 0, 0])
BALL_RADIUS = 1.0


def ball(u):
    """Failure inside the ball of radius r around c: g = |u - c|^2 - r^2."""
    return np.sum((u - BALL_CENTRE) ** 2, axis=1) - BALL_RADIUS ** 2


BALL_P = float(ncx2.cdf(BALL_RADIUS ** 2, BALL_CENTRE.size, BALL_CENTRE @ BALL_CENTRE))


def test_ball_form_is_biased_and_subset_is_right():
    # exact P = F_ncx2(1; 6, 16) = 1.3e-5; FORM: u* = (3, 0, ...), Phi(-3) = 1.35e-3
    point = find_design_point(ball, BALL_CENTRE.size)
    assert point.converged, point.message
    assert_allclose(point.point, [3.0, 0, 0, 0, 0, 0], atol=1e-6)
    assert_allclose(point.form_probability, ndtr(-3.0), rtol=1e-6)
    assert point.form_probability / BALL_P > 50
    results = [subset_simulation(ball, BALL_CENTRE.size, s) for s in seeds(10, 30)]
    assert covered(results, BALL_P) >= 8
    ratio = np.array([r.probability for r in results]) / BALL_P
    assert abs(np.mean(np.log(ratio))) < 0.35
    assert all(r.ci_upper < point.form_probability for r in results)


def test_ball_importance_sampling_removes_the_form_bias():
    # unbiased whatever the curvature (bounded weights here), but with few failing samples:
    # the mean of 10 repeats within -+35 % (observed CV of one run ~0.3 at n = 4000)
    results = [importance_sampling(ball, BALL_CENTRE.size, s, samples=4000)
               for s in seeds(10, 31)]
    ratio = np.array([r.probability for r in results]) / BALL_P
    assert abs(np.mean(ratio) - 1) < 0.35
    assert all(r.form_probability / BALL_P > 50 for r in results)


def test_chi_square_tail_subset_is_right_and_form_flags_it():
    # g = r^2 - |u|^2: P = chi2.sf(r^2, d) (here 1e-4); grad g(0) = 0, every point of the
    # sphere is a design point
    d = 6
    radius2 = float(chi2.isf(1e-4, d))
    exact = float(chi2.sf(radius2, d))

    def sphere(u):
        return radius2 - np.sum(u * u, axis=1)

    results = [subset_simulation(sphere, d, s) for s in seeds(10, 32)]
    assert covered(results, exact) >= 8
    assert abs(np.mean(np.log([r.probability / exact for r in results]))) < 0.35
    flagged = importance_sampling(sphere, d, 1)
    assert flagged.status == STATUS_FORM_FAILED and not flagged.ok
    assert np.isnan(flagged.probability)
    assert "\n" not in flagged.message and "subset" in flagged.message
    assert "P =" not in flagged.describe()


def test_form_flags_a_kink_at_the_design_point():
    # failure where both u1 and u2 exceed 3: g = 3 - min(u1, u2), a kink at u* = (3, 3)
    def corner(u):
        return 3.0 - np.minimum(u[:, 0], u[:, 1])

    point = find_design_point(corner, 2)
    assert not point.converged
    assert "not smooth" in point.message and "\n" not in point.message
    result = importance_sampling(corner, 2, 1)
    assert result.status == STATUS_FORM_FAILED and np.isnan(result.probability)


def test_form_flags_a_failing_origin():
    point = find_design_point(lambda u: -1.0 - u[:, 0], 3)
    assert not point.converged and "origin" in point.message


# ---------------------------------------------------------------------------------------------
# Monte Carlo
# ---------------------------------------------------------------------------------------------

def test_monte_carlo_twin():
    # the documented stream: block k from SeedSequence(entropy, spawn_key=(STREAM, 0, k)),
    # drawn whole (BLOCK_ROWS rows) and cut
    g, exact, _, _ = two_balls(2e-2)
    samples = BLOCK_ROWS + 5000
    result = monte_carlo(g, DIMENSION, SEED, samples=samples)
    failures = 0
    for k, rows in enumerate((BLOCK_ROWS, 5000)):
        generator = np.random.default_rng(
            np.random.SeedSequence(SEED, spawn_key=(RARE_EVENT_STREAM, 0, k)))
        failures += int(np.sum(g(generator.standard_normal((BLOCK_ROWS, DIMENSION))[:rows])
                               <= 0))
    assert result.failures == failures and result.evaluations == samples
    assert result.probability == failures / samples
    assert result.ci_lower <= exact <= result.ci_upper                   # Clopper-Pearson
    assert result.unresolved == 0
    assert result.bound_lower == result.bound_upper == result.probability


# ---------------------------------------------------------------------------------------------
# reproducibility
# ---------------------------------------------------------------------------------------------

class CountingNaN:
    """Wraps g; counts the rows, the rows returned as NaN and the largest call."""

    def __init__(self, function):
        self.function, self.nan, self.rows, self.largest = function, 0, 0, 0

    def __call__(self, u):
        values = self.function(u)
        self.nan += int(np.sum(np.isnan(values)))
        self.rows += u.shape[0]
        self.largest = max(self.largest, u.shape[0])
        return values


def assert_same_result(a: RareEventResult, b: RareEventResult):
    for f in dataclasses.fields(RareEventResult):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, str) or x is None:
            assert x == y, f.name
        else:
            assert_array_equal(np.asarray(x, dtype=float), np.asarray(y, dtype=float),
                               err_msg=f.name)


@pytest.mark.parametrize("estimator, options, batch_sizes", [
    ("monte_carlo", {"samples": BLOCK_ROWS + 3000}, (1000, 7777)),
    ("subset", {}, (1, 37)),
    ("subset", {"sampler": "metropolis"}, (1, 37)),
    ("importance", {"samples": 3000}, (1, 37)),
])
def test_bit_identical_whatever_the_batch_size(estimator, options, batch_sizes):
    g, _, _, _ = two_balls(1e-2 if estimator == "monte_carlo" else 1e-5)
    seed = np.random.SeedSequence(SEED, spawn_key=(40,))
    whole = ESTIMATORS[estimator](g, DIMENSION, seed, **options)
    assert whole.ok
    for batch_size in batch_sizes:
        counting = CountingNaN(g)
        split = ESTIMATORS[estimator](counting, DIMENSION, seed, batch_size=batch_size,
                                      **options)
        assert counting.largest <= batch_size
        assert_same_result(whole, split)


def test_seed_sequence_is_not_changed_and_int_seed_is_the_same():
    g, _, _, _ = two_balls(1e-4)
    seed = np.random.SeedSequence(SEED)
    first = subset_simulation(g, DIMENSION, seed)
    assert seed.n_children_spawned == 0
    assert_same_result(first, subset_simulation(g, DIMENSION, seed))
    assert_same_result(first, subset_simulation(g, DIMENSION, SEED))
    other = subset_simulation(g, DIMENSION, SEED + 1)
    assert other.probability != first.probability


def test_limit_state_gets_read_only_rows():
    def mutating(u):
        u[:, 0] = 0.0
        return 1.0 - u[:, 0]

    with pytest.raises(ValueError, match="read-only"):
        monte_carlo(mutating, 2, 1, samples=10)


# ---------------------------------------------------------------------------------------------
# unresolved rows (NaN): counted and bounded, never dropped
# ---------------------------------------------------------------------------------------------



def test_monte_carlo_unresolved_bounds():
    # NaN where u2 > 2 (q = Phi(-2), independent of the failure u1 >= beta, P = 0.02):
    # bounds P (1 - q) and P + q - P q
    beta, q = float(-ndtri(0.02)), float(ndtr(-2.0))

    def limit_state(u):
        return np.where(u[:, 1] > 2.0, np.nan, beta - u[:, 0])

    g = CountingNaN(limit_state)
    result = monte_carlo(g, 3, SEED, samples=50_000)
    n = 50_000
    assert result.unresolved == g.nan > 0 and result.evaluations == g.rows == n
    k = result.failures
    assert result.bound_lower == k / n and result.bound_upper == (k + g.nan) / n
    assert result.probability == k / (n - g.nan)
    assert result.bounds_ci_lower <= 0.02 * (1 - q) and 0.02 + q - 0.02 * q \
        <= result.bounds_ci_upper
    assert result.ci_lower <= 0.02 <= result.ci_upper       # resolved rows: P(F | not N)
    assert "unresolved" in result.describe() and "\n" not in result.describe()


def half_unevaluable(beta):
    """g = beta - u1, NaN on the half u2 > 0 of the failure domain: bounds P / 2 and P."""
    def limit_state(u):
        g = beta - u[:, 0]
        return np.where((g <= 0) & (u[:, 1] > 0), np.nan, g)

    return limit_state


def test_subset_unresolved_bounds():
    p = 1e-4
    beta = float(-ndtri(p))
    results = []
    for seed in seeds(5, 50):
        g = CountingNaN(half_unevaluable(beta))
        r = subset_simulation(g, 3, seed)
        assert r.ok and r.unresolved == g.nan > 0 and r.evaluations == g.rows
        results.append(r)
    for r in results:
        assert r.bound_lower < r.bound_upper
        assert r.bounds_ci_lower <= r.bound_lower and r.bound_upper <= r.bounds_ci_upper
    # the bounds' interval holds both exact bounds in >= 4 of 5 repeats
    assert sum(r.bounds_ci_lower <= p / 2 and p <= r.bounds_ci_upper for r in results) >= 4
    lower = np.exp(np.mean(np.log([r.bound_lower / (p / 2) for r in results])))
    upper = np.exp(np.mean(np.log([r.bound_upper / p for r in results])))
    assert abs(np.log(lower)) < 0.4 and abs(np.log(upper)) < 0.4


def test_importance_unresolved_bounds():
    p = 1e-4
    beta = float(-ndtri(p))
    g = CountingNaN(half_unevaluable(beta))
    r = importance_sampling(g, 3, SEED, samples=4000)
    assert r.ok and r.unresolved == g.nan > 0 and r.evaluations == g.rows
    assert r.bounds_ci_lower <= p / 2 <= r.bound_upper and p <= r.bounds_ci_upper
    assert_allclose(r.bound_lower, p / 2, rtol=0.15)
    assert_allclose(r.bound_upper, p, rtol=0.15)


def test_form_flags_unevaluable_points():
    # the model can not be evaluated beyond u1 = 1, before the limit state u1 = 3
    point = find_design_point(lambda u: np.where(u[:, 0] > 1.0, np.nan, 3.0 - u[:, 0]), 2)
    assert not point.converged and "\n" not in point.message
    assert "nan" in point.message or "not finite" in point.message


def test_all_unresolved_gives_no_number():
    r = monte_carlo(lambda u: np.full(u.shape[0], np.nan), 2, 1, samples=100)
    assert not r.ok and np.isnan(r.probability) and r.unresolved == 100
    assert r.bound_lower == 0 and r.bound_upper == 1


# ---------------------------------------------------------------------------------------------
# flags and one-line errors
# ---------------------------------------------------------------------------------------------

def test_subset_no_failure_found():
    # beta = 12 (P ~ 2e-33) is out of reach of 4 levels at p0 = 0.1
    r = subset_simulation(lambda u: 12.0 - u[:, 0], 2, 1, max_levels=4)
    assert r.status == STATUS_NO_FAILURE and not r.ok
    assert np.isnan(r.probability) and np.isnan(r.ci_upper)
    assert "no failure" in r.message and "\n" not in r.message
    assert "P =" not in r.describe() and r.describe().startswith("subset simulation: ")
    assert r.evaluations == 1000 + 3 * 900 and r.levels == 3
    # the thresholds were still falling (about 0.9 a level at b ~ 9): the budget ran out, and
    # the advice fits (the edge-case audit: it said "raise max_levels" whatever the cause)
    assert r.message.startswith("subset simulation found no failure")
    assert "raise max_levels to about" in r.message and "stalled" not in r.message
    with pytest.raises(RareEventError, match="no failure") as error:
        r.raise_for_status()
    assert "\n" not in str(error.value)


def test_subset_tells_a_stalled_limit_state_from_a_spent_budget():
    # g = 1 + 1e-3 exp(-u_1) > 1 everywhere: the levels creep towards g = 1, never 0. The
    # thresholds of levels 1-7 fall by ~1e-5 a level at b ~ 1: some 1e5 levels to go, far
    # beyond STALLED_LEVELS (100), so raising max_levels will not help and the message says
    # so; one level alone (max_levels = 1) shows no progress to judge by.
    r = subset_simulation(lambda u: 1.0 + 1e-3 * np.exp(-u[:, 0]), 2, SEED, max_levels=8)
    assert r.status == STATUS_NO_FAILURE and np.isnan(r.probability)
    assert r.message.startswith("subset simulation found no failure (g <= 0) in 8 level(s)")
    assert "g has stalled" in r.message and "more levels will not help" in r.message
    assert "raise max_levels" not in r.message and "\n" not in r.message
    one = subset_simulation(lambda u: 12.0 - u[:, 0], 2, SEED, max_levels=1)
    assert "the level budget ran out before its levels could show progress" in one.message
    assert one.message.endswith("raise max_levels")


def test_subset_says_when_its_last_level_has_too_few_failures():
    # g = 2.5 - u_1 (P = Phi(-2.5) = 6.2e-3): at max_levels = 1 about 6 of 1 000 samples of
    # level 0 fail, fewer than its n p0 = 100 chains. The message said "found no failure
    # (g <= 0) ... smallest g reached -0.3" (a contradiction); it says how many failed and
    # what an estimate needs.
    r = subset_simulation(lambda u: 2.5 - u[:, 0], 2, SEED, max_levels=1)
    assert r.status == STATUS_NO_FAILURE and np.isnan(r.probability)
    k = int(r.message.split("with only ")[1].split(" of ")[0])
    assert 0 < k < 100
    assert "found no failure" not in r.message and "an estimate needs n p0 = 100" in r.message
    assert r.message.endswith("raise max_levels to 2 or more") and "\n" not in r.message


def test_importance_sampling_names_itself_when_it_finds_no_failure():
    # the messages of importance sampling's flags name it, as subset simulation's do
    # (samples around the design point of beta = 3 never reach g = 12 - u_1 <= 0)
    r = importance_sampling(lambda u: 12.0 - u[:, 0], 2, SEED, samples=100,
                            design_point=find_design_point(lambda u: 3.0 - u[:, 0], 2))
    assert r.status == STATUS_NO_FAILURE
    assert r.message.startswith("importance sampling found no failure among the 100 samples")
    flat = importance_sampling(lambda u: np.ones(len(u)), 2, SEED, samples=100)
    assert flat.status == STATUS_FORM_FAILED
    assert flat.message.startswith("importance sampling: FORM found no design point")


def test_subset_on_a_frequent_event_is_level_zero():
    # P = Phi(-0.5) = 0.31 > p0: level 0 is the last, plain Monte Carlo of n = 1000 samples
    # (binomial CV, normal quantile); exact to the count
    g = CountingNaN(lambda u: 0.5 - u[:, 0])
    r = subset_simulation(g, 2, SEED)
    assert r.ok and r.levels == 1 and r.evaluations == g.rows == 1000
    assert r.probability == r.failures / 1000 and r.degrees_of_freedom == np.inf
    assert_allclose(r.coefficient_of_variation ** 2,
                    (1 - r.probability) / (1000 * r.probability), rtol=1e-12)
    assert r.ci_lower <= ndtr(-0.5) <= r.ci_upper


@pytest.mark.parametrize("estimator", ["importance", "subset", "rare"])
def test_a_near_certain_event_stays_in_the_unit_interval(estimator):
    # failure outside a disc of radius 0.02: exact P = exp(-0.02^2 / 2) = 0.9998 (chi-square,
    # 2 degrees of freedom). The design point lies at |u*| = 0.02, every importance sample
    # fails and the weights average 1 only to within their noise: before the fix seeds 2, 4
    # and 5 gave P = 1.00017 to 1.00036 by importance sampling, and every estimator an upper
    # interval end up to 1.0017; "rare" divided by subset's standard error of 0 when all of
    # its level-0 samples failed. A probability and its interval lie in [0, 1].
    from tolsim.rare_events import estimate

    def g(u):
        return 0.02 - np.hypot(u[:, 0], u[:, 1])

    exact = float(np.exp(-0.02 ** 2 / 2))
    for seed in range(6):
        r = (importance_sampling(g, 2, seed) if estimator == "importance" else
             subset_simulation(g, 2, seed) if estimator == "subset" else
             estimate(g, 2, method="rare", seed=seed))
        assert r.ok, r.message
        ends = (r.probability, r.ci_lower, r.ci_upper, r.bound_lower, r.bound_upper,
                r.bounds_ci_lower, r.bounds_ci_upper)
        assert all(0.0 <= x <= 1.0 for x in ends), ends
        # subset's level 0 with all 1000 samples failing is [1, 1]: a binomial interval of
        # 1000 of 1000 that misses 0.9998 (not this fix); importance sampling covers
        assert r.ci_lower <= exact <= r.ci_upper or r.probability == 1.0
    clipped = importance_sampling(g, 2, 2)
    assert clipped.probability == 1.0 and "clipped to [0, 1]" in clipped.interval


def test_subset_flags_a_flat_limit_state():
    # g = max(1 - u1, 0.5) never fails and is flat (0.5) on u1 > 0.5, P(u1 > 0.5) = 0.31
    r = subset_simulation(lambda u: np.maximum(1.0 - u[:, 0], 0.5), 2, 1)
    assert r.status == STATUS_PLATEAU and np.isnan(r.probability)
    assert "flat" in r.message and "\n" not in r.message


@pytest.mark.parametrize("options, match", [
    ({"p0": 0.6}, "p0"),
    ({"p0": 0.0}, "p0"),
    ({"p0": -0.1}, "p0"),
    ({"p0": 1.0}, "p0"),
    ({"samples_per_level": 50}, "too small"),
    ({"samples_per_level": 1005}, "whole number"),
    ({"samples_per_level": 0}, "samples_per_level"),
    ({"max_levels": 0}, "max_levels"),
    ({"sampler": "gibbs"}, "sampler"),
    ({"batch_size": 0}, "batch_size"),
    ({"confidence_level": 1.0}, "confidence_level"),
])
def test_subset_bad_input(options, match):
    with pytest.raises(ValueError, match=match) as error:
        subset_simulation(lambda u: 3.0 - u[:, 0], 2, 1, **options)
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("estimator", sorted(ESTIMATORS))
def test_bad_dimension_seed_and_limit_state(estimator):
    function = ESTIMATORS[estimator]
    with pytest.raises(ValueError, match="dimension"):
        function(lambda u: 3.0 - u[:, 0], 0, 1)
    with pytest.raises(ValueError, match="seed"):
        function(lambda u: 3.0 - u[:, 0], 2, "seven")
    with pytest.raises(ValueError, match="shape"):
        function(lambda u: (3.0 - u[:, 0])[:, None], 2, 1)


def test_registry_names_are_the_config_names():
    # issue 15: [study] estimator = "monte_carlo" | "subset" | "importance"
    assert sorted(ESTIMATORS) == ["importance", "monte_carlo", "subset"]


def test_describe_is_one_line(linear_runs):
    for key in (("subset", 1e-5), ("importance", 1e-5)):
        text = linear_runs[key][1][0].describe()
        assert "\n" not in text and "P = " in text and "95 % CI" in text


# ---------------------------------------------------------------------------------------------
# the CV of a level: Au & Beck's gamma and the family (cluster) estimate
# ---------------------------------------------------------------------------------------------

def au_beck_gamma_twin(indicator):
    """Au & Beck's gamma by explicit loops (the formula of the module docstring)."""
    chains, length = indicator.shape
    n = chains * length
    p = indicator.mean()
    gamma = 0.0
    for k in range(1, length):
        total = 0.0
        for c in range(chains):
            for l in range(length - k):
                total += indicator[c, l] * indicator[c, l + k]
        gamma += 2 * (1 - k * chains / n) * (total / (n - k * chains) - p * p) / (p * (1 - p))
    return gamma


def test_chain_correlation_factor_twin(rng):
    for _ in range(5):
        indicator = rng.random((12, 7)) < rng.uniform(0.1, 0.9)
        assert_allclose(chain_correlation_factor(indicator), au_beck_gamma_twin(indicator),
                        rtol=1e-12, atol=1e-12)


def test_constant_chains():
    # chains that never move: rho(k) = 1, gamma = N_s - 1, so (1 + gamma) / n = 1 / N_c (the
    # chains are the independent units); the family estimate with one chain per family is
    # that times N_c / (N_c - 1), and with two identical chains per family 1 / K for K
    # families, K / (K - 1) again. p = 0.5 makes every |residual| equal: Kish gives df = K - 1.
    length = 10
    states = np.array([1, 0] * 10, dtype=bool)                 # 20 chains, p = 0.5
    indicator = np.repeat(states, length)
    p, chains = 0.5, states.size
    assert chain_correlation_factor(indicator.reshape(chains, length)) == pytest.approx(
        length - 1)
    one = level_statistics(indicator, (chains, length, np.arange(chains)))
    assert one.coefficient_of_variation ** 2 == pytest.approx(
        (1 - p) / (chains * p) * chains / (chains - 1), rel=1e-12)
    assert one.degrees_of_freedom == pytest.approx(chains - 1)
    assert one.chain_correlation_factor == pytest.approx(length - 1)
    pairs = np.repeat(np.repeat(states[:10], 2), length)     # pairs of identical chains
    families = np.arange(chains) // 2
    two = level_statistics(pairs, (chains, length, families))
    k = chains // 2
    assert two.coefficient_of_variation ** 2 == pytest.approx(
        (1 - p) / (k * p) * k / (k - 1), rel=1e-12)
    # level 0: binomial
    zero = level_statistics(indicator, None)
    assert zero.coefficient_of_variation ** 2 == pytest.approx((1 - p) / (indicator.size * p))


def test_metropolis_sampler_agrees():
    # Au & Beck's modified Metropolis on the two-ball case at 1e-5: loose (its chains are more
    # correlated than conditional sampling's)
    g, exact, _, _ = two_balls(1e-5)
    results = [subset_simulation(g, DIMENSION, s, sampler="metropolis") for s in seeds(8, 60)]
    assert all(r.ok for r in results)
    assert abs(np.mean(np.log([r.probability / exact for r in results]))) < 0.4
    assert covered(results, exact) >= 6


def test_weight_diagnostics_of_deep_tail_weights():
    # Weights below 1e-154 square to 0 in floating point: Kish's effective sample size
    # (sum w)^2 / sum w^2 divided by zero (a traceback for a 5 % limit on |epsilon| with
    # importance sampling). It depends only on the weights' ratios: for k equal weights it is
    # k and the largest share 1 / k (closed form; 1e-12), at any scale.
    from tolsim.study.analyses.rare_events.importance import weight_diagnostics

    for scale in (1.0, 1e-200, 1e-300):
        ess, share, ratio, message = weight_diagnostics(np.full(40, scale), 1e-6, 1e-6)
        assert_allclose((ess, share, ratio), (40.0, 1 / 40, 1.0), rtol=1e-12)
        assert message == ""
    ess, share, _, _ = weight_diagnostics(np.array([3e-250, 1e-250]), 1e-6, 1e-6)
    assert_allclose((ess, share), (16 / 10, 0.75), rtol=1e-12)  # (3+1)^2 / (9+1)


def test_subset_at_level_0_is_plain_monte_carlo_with_its_exact_interval():
    # An event that is not rare is settled by level 0 (n p0 or more failures): plain Monte
    # Carlo. Every sample failing (g = -10 - u_1) gave P = 1 with CV 0 and the interval
    # [1, 1], and FORM's design points, overlapping when P is near 1, each holding more than
    # five times the share of the failures nearest to it, flagged the right answer as a lost
    # mode. Now the interval is Clopper-Pearson's ([1 - ...] of 1 000 of 1 000: lower end
    # 0.025^(1/1000); Clopper & Pearson 1934, 1e-12) and level 0 is not checked for modes.
    import dataclasses as dc

    g = lambda u: 0.08 - u[:, 0]  # noqa: E731 - P = Phi(-0.08) = 0.468
    point = find_design_point(g, 2)
    spread = [dc.replace(point, point=0.08 * np.array([np.cos(a), np.sin(a)]))
              for a in np.linspace(-1.2, 1.2, 20)]
    r = subset_simulation(g, 2, SEED, design_points=spread)
    assert r.ok and r.levels == 1 and r.interval == "Clopper-Pearson"
    k = round(r.probability * 1000)
    assert_allclose(r.probability, k / 1000, rtol=0, atol=1e-15)
    assert r.ci_lower < ndtr(-0.08) < r.ci_upper
    everything = subset_simulation(lambda u: -10.0 - u[:, 0], 2, SEED, design_points=spread)
    assert everything.ok and everything.probability == 1.0 and everything.ci_upper == 1.0
    assert_allclose(everything.ci_lower, 0.025 ** (1 / 1000), rtol=1e-12)


def test_weighted_mean_of_deep_tail_weights():
    # The standard error of weights near 1e-300 came out 0 (their squared deviations
    # underflow), so importance sampling gave P = 2.21e-303 with CV 0 and a zero-width
    # interval for a 5 % limit on |epsilon|. The mean and standard error scale with the
    # weights (exact: a power-of-two scale; 1e-12 here).
    from tolsim.study.analyses.rare_events.common import weighted_mean

    x = np.random.default_rng(3).exponential(size=500) * (np.arange(500) % 7 == 0)
    mean, se = weighted_mean(x)
    for scale in (1e-200, 1e-300):
        tiny_mean, tiny_se = weighted_mean(x * scale)
        assert_allclose((tiny_mean / scale, tiny_se / scale), (mean, se), rtol=1e-12)
        assert tiny_se > 0


def test_subset_ended_by_unresolved_rows_alone_says_so():
    # g NaN over the region that would fail (u_1 > 2.5; g = 3 - u_1 elsewhere never fails):
    # subset simulation's levels end on unresolved rows alone. It returned "ok" with P = 0 and
    # a NaN interval end, where P may be anything up to P(u_1 > 2.5) = 6.2e-3; with g NaN
    # everywhere it raised ZeroDivisionError. Both are "unresolved" now, with the bounds.
    r = subset_simulation(lambda u: np.where(u[:, 0] > 2.5, np.nan, 3.0 - u[:, 0]), 2, SEED)
    assert r.status == "unresolved" and np.isnan(r.probability) and not r.ok
    assert r.bound_lower == 0 and 0 < r.bound_upper < 1 and r.bounds_ci_upper >= r.bound_upper
    assert "P is only known to lie in [0, " in r.message and "\n" not in r.message
    nothing = subset_simulation(lambda u: np.full(len(u), np.nan), 2, SEED)
    assert nothing.status == "unresolved" and nothing.bound_upper == 1.0


@pytest.mark.parametrize("options", [{"subset": None}, {"importance": 5}])
def test_rare_method_names_options_that_are_not_a_dict(options):
    # API audit, session 24: subset=None gave "'NoneType' object is not a mapping"
    from tolsim.rare_events import estimate

    name = next(iter(options))
    with pytest.raises(TypeError, match=f"{name} = .* must be a dict of the options of method"):
        estimate(lambda u: 3.0 - u[:, 0], 2, method="rare", **options)
