"""Quality-engineering figures (tolsim.study.statistics.quality)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.special import ndtr
from scipy.stats import binomtest

from tolsim.study.statistics.quality import (
    PERCENTILE_LEVELS,
    capability,
    clopper_pearson_interval,
    contact_probability_verdict,
    dataset_quality,
    format_fraction,
    out_of_spec_from_histogram,
    proportion,
    wilson_interval,
)


@pytest.mark.parametrize("k, n, lower, upper", [
    # Newcombe, Stat. Med. 17 (1998) 857-872, Table I, method 3 (Wilson score, no
    # continuity correction), printed to 4 decimals.
    (81, 263, 0.2553, 0.3662),
    (15, 148, 0.0624, 0.1605),
    (0, 20, 0.0000, 0.1611),
    (1, 29, 0.0061, 0.1718),
])
def test_wilson_newcombe1998(k, n, lower, upper):
    lo, hi = wilson_interval(k, n)
    assert_allclose([lo, hi], [lower, upper], atol=6e-5)


@pytest.mark.parametrize("k, n", [(0, 20), (1, 29), (15, 148), (81, 263), (263, 263),
                                  (3, 1_000_000)])
def test_clopper_pearson_twin_scipy(k, n):
    # Twin: scipy.stats.binomtest(k, n).proportion_ci(method="exact"), which root-finds the
    # binomial tail (ours inverts the beta distribution): agreement to its solver tolerance,
    # measured 8e-8 relative at k = 3, n = 1e6.
    ref = binomtest(k, n).proportion_ci(confidence_level=0.95, method="exact")
    assert_allclose(clopper_pearson_interval(k, n), [ref.low, ref.high], rtol=1e-6, atol=0)


def test_clopper_pearson_zero_successes_closed_form():
    # k = 0: upper = 1 - (alpha/2)^(1/n) (Clopper & Pearson 1934); n = 20 -> 0.1684.
    assert_allclose(clopper_pearson_interval(0, 20)[1], 1 - 0.025 ** (1 / 20), rtol=1e-12)


def test_proportion_and_ppm_text():
    p = proportion(3, 1_000_000)
    assert p.fraction == 3e-6 and p.method == "wilson"
    assert "ppm" in p.text() and p.text().startswith("3 ppm")
    assert format_fraction(0.25, 0.2, 0.3).startswith("25 %")
    with pytest.raises(ValueError, match="method"):
        proportion(1, 2, method="agresti")
    with pytest.raises(ValueError, match="successes"):
        proportion(3, 2)


def test_capability_closed_form():
    # mu = 0.001, sigma = 0.001, L = 0.005: Cp = 0.005 / 0.003 = 5/3,
    # Cpk = (0.005 - 0.001) / 0.003 = 4/3 (Montgomery 2009, Sec. 8.2 definitions);
    # Bissell (1990) half-width at n = 100: 1.96 sqrt(1/900 + (16/9)/198) = 0.19646.
    cap = capability(0.001, 0.001, 100, 0.005)
    assert_allclose([cap.cp, cap.cpk], [5 / 3, 4 / 3], rtol=1e-12)
    half = 1.959963984540054 * np.sqrt(1 / 900 + (16 / 9) / 198)
    assert_allclose([cap.cpk_lower, cap.cpk_upper], [4 / 3 - half, 4 / 3 + half], rtol=1e-12)
    # normal fraction out of spec: Phi(-4) + Phi(-6)
    assert_allclose(cap.normal_out_of_spec, ndtr(-4.0) + ndtr(-6.0), rtol=1e-12)
    # symmetric in the sign of the mean
    assert capability(-0.001, 0.001, 100, 0.005).cpk == cap.cpk


def test_bissell_interval_coverage():
    # Normal samples of n = 200, true Cpk = (L - |mu|)/(3 sigma) = 1.0; the 95 % Bissell
    # interval should cover it ~95 % of the time (it is an approximation; measured 0.95).
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(6)))
    x = rng.normal(0.5, 1.0, size=(2000, 200))
    hits = 0
    for row in x:
        c = capability(row.mean(), row.std(ddof=1), row.size, 3.5)
        hits += c.cpk_lower <= 1.0 <= c.cpk_upper
    assert 0.93 <= hits / len(x) <= 0.97, hits / len(x)


def test_percentile_cpk_normal_equals_cpk():
    # For a normal epsilon the percentile quantiles are mu -+ 3 sigma and the median mu, so
    # Cpk_percentile == Cpk exactly.
    mu, sd, lim = 0.001, 0.002, 0.008
    q = mu + sd * np.array([-3.0, 0.0, 3.0])
    cap = capability(mu, sd, 10_000, lim, q)
    assert_allclose(cap.cpk_percentile, cap.cpk, rtol=1e-12)
    assert_allclose(PERCENTILE_LEVELS, [0.00134990, 0.5, 0.99865010], atol=1e-8)


def test_out_of_spec_from_histogram(rng):
    x = rng.normal(0.001, 0.003, size=200_000)
    edges = np.linspace(-0.02, 0.02, 401)  # bin width 1e-4
    counts, _ = np.histogram(x, edges)
    under, over = int((x < edges[0]).sum()), int((x >= edges[-1]).sum())
    # limit on an edge: exact count
    lim = 0.008
    exact = int((np.abs(x) > lim).sum())
    p = out_of_spec_from_histogram(counts, edges, lim, under, over)
    assert_allclose(p.successes, exact, rtol=1e-9)
    assert p.trials == x.size
    assert_allclose([p.lower, p.upper], wilson_interval(exact, x.size), rtol=1e-12)
    # limits that land on linspace edges only up to round-off (0.005 is 0.005000000000000001
    # there) are still on an edge: exact count, no widening
    for lim in (0.005, 0.0031, 0.0127):
        exact = int((np.abs(x) > lim).sum())
        p = out_of_spec_from_histogram(counts, edges, lim, under, over)
        assert_allclose(p.successes, exact, rtol=1e-9, atol=1e-6)
        assert_allclose([p.lower, p.upper], wilson_interval(exact, x.size), rtol=1e-12)
    # limit inside a bin: the estimate is near the true count and the interval covers the
    # true fraction's own interval ends (it is widened over the straddling bins)
    lim = 0.00805
    true = int((np.abs(x) > lim).sum())
    p = out_of_spec_from_histogram(counts, edges, lim, under, over)
    assert abs(p.successes - true) <= 0.5 * (counts[np.searchsorted(edges, lim) - 1]
                                             + counts[np.searchsorted(edges, -lim) - 1])
    lo, hi = wilson_interval(true, x.size)
    assert p.lower <= lo and p.upper >= hi
    # a limit beyond the histogram range: underflow/overflow are unknown, the interval
    # reaches from none to all of them
    p = out_of_spec_from_histogram(counts, edges, 0.05, under, over)
    assert p.lower == 0.0 and p.upper >= (under + over) / x.size
    with pytest.raises(ValueError, match="limit"):
        out_of_spec_from_histogram(counts, edges, 0.0)


def test_contact_probability_verdict():
    assert contact_probability_verdict(0.01, 0.02, 0.05).startswith("meets")
    assert contact_probability_verdict(0.10, 0.12, 0.05).startswith("fails")
    assert contact_probability_verdict(0.04, 0.06, 0.05).startswith("inconclusive")
    assert "no limit" in contact_probability_verdict(0.04, 0.06, float("nan"))


def test_dataset_quality_from_mapping(rng):
    # A result-file-like mapping (the study's variables) built from a normal sample.
    x = rng.normal(0.0005, 0.0015, size=100_000)
    edges = np.linspace(-0.02, 0.02, 401)
    counts, _ = np.histogram(x, edges)
    ds = {"velocity_deviation_limit": 0.005, "velocity_deviation_histogram": counts,
          "velocity_deviation_bin_bounds": np.stack([edges[:-1], edges[1:]], axis=1),
          "velocity_deviation_underflow": 0, "velocity_deviation_overflow": 0,
          "n_balls_valid": x.size, "velocity_deviation_mean": x.mean(),
          "velocity_deviation_std": x.std(ddof=1)}
    q = dataset_quality(ds)
    assert_allclose(q["velocity_deviation_out_of_spec_fraction"] * x.size,
                    int((np.abs(x) > 0.005).sum()), rtol=1e-9)
    # Cpk = (0.005 - 0.0005) / 0.0045 = 1.0 up to sampling error (sd of Cpk ~ 0.0025)
    assert_allclose(q["velocity_deviation_cpk"], 1.0, atol=0.01)
    # percentile index from the histogram (bin 1e-4 = 0.07 sigma) agrees within 0.05
    assert_allclose(q["velocity_deviation_cpk_percentile"], 1.0, atol=0.05)
    ds["velocity_deviation_limit"] = float("nan")
    assert dataset_quality(ds) == {}
