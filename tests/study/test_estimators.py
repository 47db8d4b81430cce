"""Interval estimators with the assembly as the sampling unit (tolsim.study.statistics.intervals).

The synthetic train: equicorrelated standard normals x_ab = sqrt(rho) z_a + sqrt(1 - rho) e_ab
(assembly a, ball b; z, e iid N(0, 1)), so every ball is N(0, 1), two balls of one assembly
have correlation rho, and with L = -Phi^-1(p / 2) the true fraction out of spec is
P(|x| > L) = 2 Phi(-L) = p and the true Cpk = Cp = L / 3 (mu = 0, sigma = 1).

Coverage tests (CI-sized; ``benchmarks/coverage_cluster.py`` runs 400 repeats and more cases):
R = 150 seeded repeats. A correct 95 % interval covers in R C ~ Binomial(R, 0.95) repeats, sd
sqrt(0.95 0.05 / 150) = 1.78 %, so the band [0.905, 0.995] (0.95 -+ 2.5 sd) fails a correct
interval with probability ~1 % (and, being seeded, never flakes). The independent-ball
intervals cover ~60 % here (Wilson) and ~50 % (Bissell): they must stay below 0.80, which a
95 % interval reaches with probability < 1e-10, so the coverage check can fail.
"""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy.integrate import quad
from scipy.special import ndtr, ndtri
from scipy.stats import norm

from tolsim.study.statistics.intervals import (
    CLUSTER_COLUMNS,
    ClusterMoments,
    assembly_totals,
    cluster_capability,
    cluster_proportion,
    ratio_variance,
    wilson_interval,
)
from tolsim.study.statistics.quality import Capability, Proportion, capability

BALLS = 10
RHO = 0.9
Z95 = float(ndtri(0.975))


def equicorrelated(rng, assemblies, rho=RHO, balls=BALLS):
    """x_ab = sqrt(rho) z_a + sqrt(1 - rho) e_ab, shape (assemblies, balls)."""
    return (np.sqrt(rho) * rng.standard_normal((assemblies, 1))
            + np.sqrt(1.0 - rho) * rng.standard_normal((assemblies, balls)))


def limit_for(p):
    """L with 2 Phi(-L) = p."""
    return float(-ndtri(p / 2.0))


def closed_form_design_effect(p, rho=RHO, balls=BALLS):
    """Var(k_a) / (m p (1 - p)) of the equicorrelated train, by one-dimensional quadrature.

    Given z_a, the balls are independent with q(z) = P(|x| > L | z); k_a | z ~ Bin(m, q(z)),
    so Var(k_a) = m (E q - E q^2) + m^2 (E q^2 - (E q)^2).
    """
    lim, a, b = limit_for(p), np.sqrt(rho), np.sqrt(1.0 - rho)

    def q(z):
        return ndtr((-lim - a * z) / b) + ndtr((-lim + a * z) / b)

    def expect(f):
        return quad(lambda z: f(z) * norm.pdf(z), -12, 12, epsabs=0, epsrel=1e-10, limit=200,
                    points=[-lim / a, lim / a])[0]

    eq, eq2 = expect(q), expect(lambda z: q(z) ** 2)
    assert abs(eq - p) < 1e-9 * p                      # the quadrature is right
    var_k = balls * (eq - eq2) + balls * balls * (eq2 - eq * eq)
    return var_k / (balls * p * (1.0 - p))


# ---------------------------------------------------------------------------------------------
# ClusterMoments
# ---------------------------------------------------------------------------------------------

def _totals(rng, assemblies):
    n = rng.integers(7, 11, assemblies).astype(float)
    k = np.floor(rng.uniform(0, 1, assemblies) * (n + 1))
    s = rng.normal(1e-3, 2e-3, assemblies) * n
    q = rng.chisquare(3, assemblies) * 1e-6 * n
    return np.stack([n, k, s, q], axis=1)


@pytest.mark.parametrize("cuts", [
    [],                                      # one block
    [0, 0, 5, 5, 997],                       # empty blocks everywhere
    list(range(1, 997)),                     # one assembly per block
    [1, 2, 500, 501, 996],
    "random",
])
def test_merge_any_split_equals_whole(rng, cuts):
    # Chan, Golub & LeVeque's pairwise update is exact algebra: any split, merged left to
    # right, equals the two-pass moments of the whole and NumPy's mean / cov (ddof 1) to
    # round-off (rtol 1e-12 on the mean, 1e-10 on the co-moments, atol 1e-12 of their scale).
    y = _totals(rng, 997)
    if cuts == "random":
        cuts = sorted(rng.integers(0, 998, 20))
    parts = np.split(y, cuts)
    merged = ClusterMoments.empty(4)
    for part in parts:
        merged = merged.merge(ClusterMoments.from_totals(part))
    whole = ClusterMoments.from_totals(y)
    assert merged.count == whole.count == 997
    scale = np.abs(whole.comoment).max()
    assert_allclose(merged.mean, whole.mean, rtol=1e-12)
    assert_allclose(merged.comoment, whole.comoment, rtol=1e-10, atol=1e-12 * scale)
    assert_allclose(whole.mean, y.mean(axis=0), rtol=1e-12)
    assert_allclose(whole.covariance, np.cov(y.T, ddof=1), rtol=1e-10, atol=1e-14 * scale)
    assert_allclose(whole.totals, y.sum(axis=0), rtol=1e-12)
    # deterministic: the same blocks merged in the same order give the same bits
    again = ClusterMoments.empty(4)
    for part in parts:
        again = again.merge(ClusterMoments.from_totals(part))
    assert_array_equal(again.mean, merged.mean)
    assert_array_equal(again.comoment, merged.comoment)


def test_merge_empty_and_shapes():
    e = ClusterMoments.empty()
    assert e.count == 0 and e.mean.shape == (len(CLUSTER_COLUMNS),)
    y = np.array([[10.0, 1, 0.1, 0.02], [9.0, 0, -0.1, 0.01]])
    m = ClusterMoments.from_totals(y)
    for got in (e.merge(m), m.merge(e)):
        assert got.count == 2
        assert_array_equal(got.mean, m.mean)
        assert_array_equal(got.comoment, m.comoment)
    assert e.merge(e).count == 0
    assert ClusterMoments.from_totals(np.zeros((0, 4))).count == 0
    with pytest.raises(ValueError):
        m.merge(ClusterMoments.empty(3))
    with pytest.raises(ValueError):
        ClusterMoments.from_totals(np.array([[np.nan, 1, 1, 1]]))


def test_assembly_totals_hand_example():
    eps = np.array([[0.1, -0.3, np.nan, 0.25],
                    [np.nan, np.nan, np.nan, np.nan]])
    y = assembly_totals(eps, 0.2)
    assert_allclose(y, [[3, 2, 0.05, 0.01 + 0.09 + 0.0625], [0, 0, 0, 0]], rtol=1e-14)


# ---------------------------------------------------------------------------------------------
# the ratio estimator and its variance
# ---------------------------------------------------------------------------------------------

def test_ratio_variance_is_cochrans_formula(rng):
    # [Cochran1977] Sec. 6.4 (f = 0): v(R) = sum (k_a - R n_a)^2 / ((A - 1) A nbar^2), written
    # out directly on the totals; the moment form must agree to round-off.
    y = _totals(rng, 3001)
    r, v = ratio_variance(ClusterMoments.from_totals(y), 1, 0)
    n, k = y[:, 0], y[:, 1]
    assert r == pytest.approx(k.sum() / n.sum(), rel=1e-14)
    direct = ((k - r * n) ** 2).sum() / ((len(y) - 1) * len(y) * n.mean() ** 2)
    assert v == pytest.approx(direct, rel=1e-9)


def test_independent_balls_reduce_to_binomial(rng):
    # rho = 0: the balls are independent, deff = 1 and the cluster interval is the binomial
    # (Wilson) interval of k of N. p = 0.01, A = 20 000, m = 10: K ~ 2000, and the variance
    # estimate has a relative sd of ~1/sqrt(K) = 2.2 %, so +-10 % is 4.5 sd; the interval ends
    # then move by at most sqrt(1.1) - 1 < 5 %.
    p, assemblies = 0.01, 20_000
    lim = limit_for(p)
    moments = ClusterMoments.from_totals(assembly_totals(equicorrelated(rng, assemblies, 0.0),
                                                         lim))
    prop = cluster_proportion(moments)
    _, v = ratio_variance(moments)
    binomial = prop.fraction * (1 - prop.fraction) / prop.trials
    assert v / binomial == pytest.approx(1.0, abs=0.10)
    assert 1.0 <= prop.design_effect <= 1.1
    assert_allclose([prop.lower, prop.upper], wilson_interval(prop.successes, prop.trials),
                    rtol=0.05)
    # Cpk: Bissell's variance 1/(9n) + Cpk^2/(2(n-1)) [Bissell1990] for independent normal
    # values; the delta method over assemblies must give the same half-width (+-10 %: the
    # variance estimate has a relative sd of ~sqrt(2 / A) ~ 1 %)
    cap = cluster_capability(moments, lim)
    mu = moments.mean[2] / moments.mean[0]
    sd = np.sqrt(moments.mean[3] / moments.mean[0] - mu * mu)
    ref = capability(mu, sd, cap.n, lim)
    assert cap.cpk == pytest.approx(ref.cpk, rel=1e-12)
    assert cap.cp == pytest.approx(ref.cp, rel=1e-12)
    assert (cap.cpk_upper - cap.cpk_lower) / (ref.cpk_upper - ref.cpk_lower) == \
        pytest.approx(1.0, abs=0.10)


@pytest.mark.parametrize("mu_over_sigma", [0.0, -2.0, 50.0])
def test_cpk_variance_equals_centred_linearisation(rng, mu_over_sigma):
    # The delta method written on the co-moments must equal the same linearisation computed
    # directly from the balls with centred values (the influence of assembly a on Cpk,
    # u_a = [-sign(mu) sum_b (x - mu) / (3 sigma) - Cpk (sum_b (x - mu)^2 - sigma^2 n_a)
    #        / (2 sigma^2)] / nbar, variance sum (u_a - ubar)^2 / ((A - 1) A)), on epsilon-like
    # scales (sigma = 1e-3), with invalid balls (unequal n_a) and a large |mu| / sigma that
    # would expose cancellation in Qbar / nbar - mu^2. Round-off only: rtol 1e-6.
    sigma, assemblies = 1e-3, 3000
    x = sigma * equicorrelated(rng, assemblies) + mu_over_sigma * sigma
    x[rng.uniform(size=x.shape) < 0.05] = np.nan
    lim = abs(mu_over_sigma) * sigma + 4 * sigma
    cap = cluster_capability(ClusterMoments.from_totals(assembly_totals(x, lim)), lim)
    valid = np.isfinite(x)
    mu = np.nanmean(x)
    d = np.where(valid, x - mu, 0.0)
    var = (d * d).sum() / valid.sum()
    cpk = (lim - abs(mu)) / (3 * np.sqrt(var))
    u = (-(1.0 if mu >= 0 else -1.0) * d.sum(axis=1) / (3 * np.sqrt(var))
         - cpk * ((d * d).sum(axis=1) - var * valid.sum(axis=1)) / (2 * var)) \
        / valid.sum(axis=1).mean()
    se = np.sqrt(((u - u.mean()) ** 2).sum() / ((assemblies - 1) * assemblies))
    assert cap.cpk == pytest.approx(cpk, rel=1e-9)
    assert (cap.cpk_upper - cap.cpk_lower) / 2 == pytest.approx(Z95 * se, rel=1e-6)


# ---------------------------------------------------------------------------------------------
# coverage on the correlated train (CI-sized; the benchmark has 400 repeats)
# ---------------------------------------------------------------------------------------------

REPEATS = 150
BAND = (0.905, 0.995)          # 0.95 -+ 2.5 binomial sd at R = 150 (module docstring)
SHIFT = 0.5                    # a second Cpk case with mu != 0 (a differentiable |mu|)


@pytest.fixture(scope="module", params=[(1e-3, 20_000), (1e-2, 2_000)],
                ids=["p=1e-3,A=20000", "p=1e-2,A=2000"])
def repeats(request):
    """R seeded repeats: coverage of the new and old intervals and the variance estimates."""
    p, assemblies = request.param
    lim = limit_for(p)
    rows = []
    for r in range(REPEATS):
        x = equicorrelated(np.random.default_rng([20181109, r]), assemblies)
        moments = ClusterMoments.from_totals(assembly_totals(x, lim))
        prop = cluster_proportion(moments)
        old = wilson_interval(prop.successes, prop.trials)
        cap = cluster_capability(moments, lim)
        mu = moments.mean[2] / moments.mean[0]
        bissell = capability(mu, np.sqrt(moments.mean[3] / moments.mean[0] - mu * mu),
                             prop.trials, lim)
        shifted = cluster_capability(ClusterMoments.from_totals(assembly_totals(x + SHIFT, lim)),
                                     lim)
        rows.append((p, lim, prop, old, cap, bissell, shifted, ratio_variance(moments)[1]))
    return rows


def _cover(lo, hi, truth):
    return np.mean([lo_ <= truth <= hi_ for lo_, hi_ in zip(lo, hi, strict=True)])


@pytest.mark.slow
def test_proportion_coverage_correlated_train(repeats):
    p = repeats[0][0]
    new = _cover([r[2].lower for r in repeats], [r[2].upper for r in repeats], p)
    old = _cover([r[3][0] for r in repeats], [r[3][1] for r in repeats], p)
    assert BAND[0] <= new <= BAND[1], new
    assert old < 0.80, old


@pytest.mark.slow
def test_cpk_coverage_correlated_train(repeats):
    lim = repeats[0][1]
    truth = lim / 3.0
    new = _cover([r[4].cpk_lower for r in repeats], [r[4].cpk_upper for r in repeats], truth)
    cp = _cover([r[4].cp_lower for r in repeats], [r[4].cp_upper for r in repeats], truth)
    old = _cover([r[5].cpk_lower for r in repeats], [r[5].cpk_upper for r in repeats], truth)
    shifted = _cover([r[6].cpk_lower for r in repeats], [r[6].cpk_upper for r in repeats],
                     (lim - SHIFT) / 3.0)
    assert BAND[0] <= new <= BAND[1], new
    assert BAND[0] <= cp <= BAND[1], cp
    assert BAND[0] <= shifted <= BAND[1], shifted
    assert old < 0.80, old


@pytest.mark.slow
def test_design_effect_matches_closed_form(repeats):
    # The mean over repeats of the delta-method variance estimate must match the true
    # Var(p) = deff p (1 - p) / N with deff from closed_form_design_effect (4.74 at p = 1e-3,
    # 5.53 at 1e-2). The per-repeat estimate has a relative sd of ~23 %, so the mean of 150
    # has ~1.9 %; rtol 8 % is > 4 sd (and the undercount of the old interval is a factor 4.7).
    p = repeats[0][0]
    n = repeats[0][2].trials
    truth = closed_form_design_effect(p)
    mean_deff = np.mean([r[7] for r in repeats]) * n / (p * (1 - p))
    assert mean_deff == pytest.approx(truth, rel=0.08)


# ---------------------------------------------------------------------------------------------
# edge cases
# ---------------------------------------------------------------------------------------------

def _moments(rows):
    return ClusterMoments.from_totals(np.asarray(rows, dtype=float))


def test_no_ball_out_counts_each_assembly_as_one_trial():
    # k = 0: deff unknown; n_eff = N^2 / sum n_a^2 (= A for equal sizes), the worst case for
    # non-negatively correlated balls, not N (independent balls).
    prop = cluster_proportion(_moments([[10, 0, 0, 0]] * 500))
    assert prop.fraction == 0 and prop.lower == 0
    assert prop.effective_trials == 500 and prop.design_effect == pytest.approx(10)
    assert prop.upper == pytest.approx(wilson_interval(0, 500)[1], rel=1e-12)
    assert prop.upper > 10 * wilson_interval(0, 5000)[1] / 2      # far from the naive bound
    sizes = np.array([10] * 300 + [5] * 200)
    prop = cluster_proportion(_moments([[s, 0, 0, 0] for s in sizes]))
    assert prop.effective_trials == pytest.approx(sizes.sum() ** 2 / (sizes ** 2).sum(),
                                                  rel=1e-12)
    # every ball out: the mirror image
    prop = cluster_proportion(_moments([[10, 10, 0, 0]] * 500))
    assert prop.fraction == 1 and prop.upper == 1
    assert prop.lower == pytest.approx(wilson_interval(500, 500)[0], rel=1e-12)


def test_all_in_or_all_out_assemblies_cap_the_design_effect():
    # k_a in {0, m}: Var(k_a) = m^2 p (1 - p), the largest possible, deff = m; the estimate
    # ((A - 1) divisor) is slightly larger and is capped at sum n_a^2 / N = m.
    rows = [[10, 10, 0, 0]] * 40 + [[10, 0, 0, 0]] * 960
    prop = cluster_proportion(_moments(rows))
    assert prop.fraction == pytest.approx(0.04)
    assert prop.effective_trials == pytest.approx(1000) and prop.design_effect == \
        pytest.approx(10)


def test_identical_assemblies_do_not_beat_independent_balls():
    # every assembly has exactly 1 of 10 balls out: the variance estimate is 0 (deff 0), but
    # deff is not taken below 1 (n_eff <= N)
    prop = cluster_proportion(_moments([[10, 1, 0, 0]] * 1000))
    assert prop.effective_trials <= prop.trials == 10_000
    assert 1.0 <= prop.design_effect < 1.01
    assert_allclose([prop.lower, prop.upper], wilson_interval(1000, 10_000), rtol=0.01)


def test_degenerate_inputs():
    empty = cluster_proportion(ClusterMoments.empty())
    assert np.isnan(empty.fraction) and empty.trials == 0 and isinstance(empty, Proportion)
    one = cluster_proportion(_moments([[10, 3, 0, 0]]))
    assert one.fraction == 0.3 and one.effective_trials == 1.0 and one.clusters == 1
    assert cluster_proportion(_moments([[10, 3, 0, 0]] * 4),
                              interval="clopper-pearson").method.endswith("clopper-pearson")
    cap = cluster_capability(_moments([[10, 0, 0.1, 0.2]]), 0.5)
    assert isinstance(cap, Capability) and np.isnan(cap.cpk_lower) and np.isfinite(cap.cpk)
    assert np.isnan(cluster_capability(ClusterMoments.empty(), 0.5).cpk)
    with pytest.raises(ValueError):
        cluster_proportion(ClusterMoments.empty(), interval="wald")
    with pytest.raises(ValueError):
        cluster_capability(ClusterMoments.empty(), 0.0)
    with pytest.raises(ValueError):
        cluster_proportion(ClusterMoments.empty(2))
