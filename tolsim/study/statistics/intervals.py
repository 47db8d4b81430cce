"""Interval estimators of a study: binomial intervals, histogram quantiles, and intervals that
treat the assembly as the sampling unit. Pure NumPy/SciPy (no other tolsim import), so both
:mod:`tolsim.study.statistics.quality` and :mod:`tolsim.study.statistics.accumulator` can import it.

* Independent trials: :func:`wilson_interval`, :func:`clopper_pearson_interval`,
  :func:`histogram_quantiles`.
* Correlated balls, the assembly as the sampling unit: :class:`ClusterMoments`,
  :func:`cluster_proportion`, :func:`cluster_capability` (the theory in their Notes).
* Differences of two runs, and intervals on the aggregates a result file holds, for
  ``tolsim compare`` (:mod:`tolsim.reports.compare`), whose differences are unpaired (the two
  estimates taken as independent): :func:`mover_difference`, :func:`newcombe_difference`,
  :func:`welch_difference`, :func:`cluster_mean_and_std`, :func:`histogram_quantile_interval`.

References
----------
.. [Wilson1927] E. B. Wilson, "Probable inference, the law of succession, and statistical
   inference", J. Am. Stat. Assoc. 22 (1927) 209-212.
.. [ClopperPearson1934] C. J. Clopper, E. S. Pearson, "The use of confidence or fiducial
   limits illustrated in the case of the binomial", Biometrika 26 (1934) 404-413.
.. [Cochran1977] W. G. Cochran, Sampling Techniques, 3rd ed., Wiley, 1977.
.. [KornGraubard1998] E. L. Korn, B. I. Graubard, "Confidence intervals for proportions with
   small expected number of positive counts estimated from survey data", Survey Methodology
   24 (1998) 193-201.
.. [Kish1965] L. Kish, Survey Sampling, Wiley, 1965.
.. [Bissell1990] A. F. Bissell, "How reliable is your capability index?", Appl. Stat. 39
   (1990) 331-340.
.. [Chan1979] T. F. Chan, G. H. Golub, R. J. LeVeque, "Updating formulae and a pairwise
   algorithm for computing sample variances", Stanford CS report STAN-CS-79-773 (1979).
.. [Newcombe1998] R. G. Newcombe, "Interval estimation for the difference between
   independent proportions: comparison of eleven methods", Stat. Med. 17 (1998) 873-890.
.. [ZouDonner2008] G. Y. Zou, A. Donner, "Construction of confidence limits about effect
   measures: a general approach", Stat. Med. 27 (2008) 1693-1702.
.. [Welch1947] B. L. Welch, "The generalization of 'Student's' problem when several different
   population variances are involved", Biometrika 34 (1947) 28-35.
.. [Satterthwaite1946] F. E. Satterthwaite, "An approximate distribution of estimates of
   variance components", Biometrics Bulletin 2 (1946) 110-114.
.. [Woodruff1952] R. S. Woodruff, "Confidence intervals for medians and other position
   measures", J. Am. Stat. Assoc. 47 (1952) 635-646.
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri
from scipy.stats import beta as beta_distribution
from scipy.stats import t as t_distribution

#: Fractions below this are shown in ppm.
PPM_BELOW = 1e-3
#: Columns of the per-assembly totals y_a of :class:`ClusterMoments` for the quality figures:
#: valid balls n_a, balls with |epsilon| > L k_a, sum of epsilon S_a, sum of epsilon^2 Q_a.
CLUSTER_COLUMNS = ("n_valid", "n_out_of_spec", "eps_sum", "eps_sum_sq")
#: Interval at the effective sample size used by :func:`cluster_proportion`.
CLUSTER_INTERVALS = ("wilson", "clopper-pearson")


# ---------------------------------------------------------------------------------------------
# result types (re-exported by tolsim.study.statistics.quality)
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Proportion:
    """A proportion with its confidence interval.

    Attributes
    ----------
    fraction, lower, upper : float
        Estimate and interval ends [-] (NaN when ``trials`` is 0).
    successes : float
        Count (may be fractional when split from a histogram bin).
    trials : int
    confidence_level : float
    method : str
    design_effect : float
        trials / effective_trials: 1 for an interval that takes the trials as independent.
    effective_trials : float or None
        n_eff behind the interval when it is not ``trials`` (:func:`cluster_proportion`).
    clusters : int or None
        Number of assemblies (sampling units) behind a cluster interval.
    """

    fraction: float
    lower: float
    upper: float
    successes: float
    trials: int
    confidence_level: float
    method: str
    design_effect: float = 1.0
    effective_trials: float | None = None
    clusters: int | None = None

    def text(self, digits=3) -> str:
        """The proportion and interval, in ppm when small, else in %."""
        return format_fraction(self.fraction, self.lower, self.upper, digits)


@dataclass(frozen=True)
class Capability:
    """Capability of epsilon against |epsilon| <= L (see :mod:`tolsim.study.statistics.quality`).

    Attributes
    ----------
    limit : float
        L [-].
    cp, cpk : float
        Normal-theory indices [-].
    cpk_lower, cpk_upper : float
        Interval of Cpk [-]: Bissell's (independent values) or the delta method over
        assemblies (:func:`cluster_capability`), see ``method``.
    cpk_percentile : float
        Percentile index [-] (NaN when the quantiles are not available).
    normal_out_of_spec : float
        Fraction out of spec if epsilon were normal with this mu and sigma [-].
    n : int
    cp_lower, cp_upper : float
        Interval of Cp [-] (NaN when not computed).
    clusters : int or None
        Number of assemblies behind a cluster interval.
    method : str
    """

    limit: float
    cp: float
    cpk: float
    cpk_lower: float
    cpk_upper: float
    cpk_percentile: float
    normal_out_of_spec: float
    n: int
    cp_lower: float = float("nan")
    cp_upper: float = float("nan")
    clusters: int | None = None
    method: str = "Bissell (independent values)"


def format_fraction(fraction, lower=None, upper=None, digits=3) -> str:
    """'12.3 ppm [4.1, 28.7] ppm' below :data:`PPM_BELOW`, else '1.23 % [...] %'."""
    if fraction is None or not np.isfinite(fraction):
        return "n/a"
    ppm = max(fraction, upper if upper is not None and np.isfinite(upper) else 0) < PPM_BELOW
    scale, unit = (1e6, "ppm") if ppm else (1e2, "%")
    body = f"{scale * fraction:.{digits}g} {unit}"
    if lower is not None and upper is not None and np.isfinite(lower) and np.isfinite(upper):
        body += f" (95 % CI {scale * lower:.{digits}g} to {scale * upper:.{digits}g} {unit})"
    return body


# ---------------------------------------------------------------------------------------------
# independent trials
# ---------------------------------------------------------------------------------------------

def wilson_interval(successes, trials, confidence_level=0.95):
    """Wilson score interval of a binomial proportion ([Wilson1927]).

    Parameters
    ----------
    successes : float
        k, 0 <= k <= n (a non-integer k is accepted, for split histogram bins and
        effective counts).
    trials : float
        n (an effective sample size may be non-integer).
    confidence_level : float

    Returns
    -------
    (lower, upper) : floats [-], NaN when n = 0.
    """
    k, n = float(successes), float(trials)
    check_counts(k, n, confidence_level)
    if n == 0:
        return float("nan"), float("nan")
    z = float(ndtri(0.5 + confidence_level / 2))
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # exact ends at k = 0 and k = n (centre - half is 0 there up to round-off)
    lower = 0.0 if k <= 0 else max(0.0, float(centre - half))
    upper = 1.0 if k >= n else min(1.0, float(centre + half))
    return lower, upper


def clopper_pearson_interval(successes, trials, confidence_level=0.95):
    """Exact (Clopper-Pearson) interval of a binomial proportion ([ClopperPearson1934]).

    Non-integer k and n (effective counts) use the same beta quantiles.

    Returns
    -------
    (lower, upper) : floats [-], NaN when n = 0.
    """
    k, n = float(successes), float(trials)
    check_counts(k, n, confidence_level)
    if n == 0:
        return float("nan"), float("nan")
    alpha = 1.0 - confidence_level
    lower = 0.0 if k <= 0 else float(beta_distribution.ppf(alpha / 2, k, n - k + 1))
    upper = 1.0 if k >= n else float(beta_distribution.ppf(1 - alpha / 2, k + 1, n - k))
    return lower, upper


def check_counts(k, n, confidence_level):
    if not n >= 0:
        raise ValueError(f"trials = {n!r} must be >= 0")
    if not (0 <= k <= n) or not np.isfinite(k):
        raise ValueError(f"successes = {k!r} must be within [0, trials = {n}]")
    if not 0 < confidence_level < 1:
        raise ValueError(f"confidence_level = {confidence_level!r} must be in (0, 1)")


def histogram_quantiles(counts, edges, levels, underflow=0, overflow=0):
    """Quantiles from a histogram, linear inside a bin; NaN outside the histogram range.

    Parameters
    ----------
    counts : ndarray of int (bins,)
    edges : ndarray (bins + 1,)
    levels : sequence of float in [0, 1]
    underflow, overflow : int
        Samples below / above the range.

    Returns
    -------
    ndarray (len(levels),)
    """
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum()) + int(underflow) + int(overflow)
    out = np.full(len(levels), np.nan)
    if total == 0:
        return out
    cum = int(underflow) + np.concatenate([[0], np.cumsum(counts)])
    for i, q in enumerate(levels):
        target = q * total
        if target < cum[0] or target > cum[-1]:
            continue
        k = int(np.searchsorted(cum, target, side="left"))
        k = min(max(k, 1), len(counts))
        c = counts[k - 1]
        frac = 0.5 if c == 0 else (target - cum[k - 1]) / c
        out[i] = edges[k - 1] + frac * (edges[k] - edges[k - 1])
    return out


# ---------------------------------------------------------------------------------------------
# the assembly as the sampling unit
# ---------------------------------------------------------------------------------------------

@dataclass(eq=False)
class ClusterMoments:
    """Count, mean and co-moment matrix of per-assembly totals y_a (p columns), mergeable.

    Attributes
    ----------
    count : int
        A, the number of assemblies.
    mean : ndarray (p,)
        Mean over the assemblies of y_a.
    comoment : ndarray (p, p)
        sum_a (y_a - mean)(y_a - mean)^T; the sample covariance is comoment / (A - 1).

    Notes
    -----
    **Correlated balls: the assembly as the sampling unit.**
    The balls of one assembly share the rail and carriage errors, so their epsilons are
    correlated (about 0.9 between neighbours in the default study) and the ball-level intervals
    that assume independent balls are too narrow. Assemblies are independent draws, so they are
    the sampling unit (single-stage cluster sampling, clusters of unequal sizes n_a): each
    assembly a contributes its totals ::

        y_a = (n_a, k_a, S_a, Q_a)          (columns :data:`CLUSTER_COLUMNS`)

    n_a valid balls, k_a of them with |epsilon| > L, S_a = sum epsilon, Q_a = sum epsilon^2 over
    its valid balls. A ball-level figure is a smooth function of the means over assemblies
    (n, k, S, Q bars), estimated by plugging in the sample means; its variance is the delta
    method's (linearisation) with the covariance of the means taken from the assemblies,
    C / (A (A - 1)), C the co-moment matrix of the y_a and A the number of assemblies. The
    moments stream: :class:`ClusterMoments` keeps (A, mean, C) and merges with the pairwise
    update of Chan, Golub & LeVeque ([Chan1979], for a co-moment matrix instead of M2), so the
    memory does not grow with the number of assemblies and a fixed merge order gives bit-identical
    results.
    """

    count: int
    mean: np.ndarray
    comoment: np.ndarray

    @classmethod
    def empty(cls, p=None) -> "ClusterMoments":
        """No assemblies, p columns (default: :data:`CLUSTER_COLUMNS`)."""
        p = len(CLUSTER_COLUMNS) if p is None else p
        return cls(0, np.zeros(p), np.zeros((p, p)))

    @classmethod
    def from_totals(cls, y) -> "ClusterMoments":
        """From the totals y (A, p) of A assemblies (two passes: mean, then co-moment)."""
        y = np.asarray(y, dtype=float)
        if y.ndim != 2:
            raise ValueError(f"totals of shape {y.shape}: expected (assemblies, columns)")
        if y.shape[0] == 0:
            return cls.empty(y.shape[1])
        if not np.all(np.isfinite(y)):
            raise ValueError("totals must be finite")
        mean = y.mean(axis=0)
        d = y - mean
        return cls(int(y.shape[0]), mean, d.T @ d)

    def merge(self, other: "ClusterMoments") -> "ClusterMoments":
        """Pairwise update ([Chan1979]) of self (first) with other (second): a new object.

        Deterministic; the result depends on the order of merges only through round-off, so
        merging blocks in a fixed order gives bit-identical results however they were chunked.
        """
        if self.mean.shape != other.mean.shape:
            raise ValueError(f"cannot merge {self.mean.shape[0]} with {other.mean.shape[0]} "
                             "columns")
        if other.count == 0:
            return ClusterMoments(self.count, self.mean.copy(), self.comoment.copy())
        if self.count == 0:
            return ClusterMoments(other.count, other.mean.copy(), other.comoment.copy())
        n_a, n_b = self.count, other.count
        n = n_a + n_b
        delta = other.mean - self.mean
        mean = self.mean + delta * (n_b / n)
        comoment = self.comoment + other.comoment + np.outer(delta, delta) * (n_a * n_b / n)
        return ClusterMoments(n, mean, comoment)

    @property
    def totals(self) -> np.ndarray:
        """sum_a y_a (p,)."""
        return self.count * self.mean

    @property
    def covariance(self) -> np.ndarray:
        """Sample covariance of y_a (p, p), divisor A - 1 (NaN for A < 2)."""
        if self.count < 2:
            return np.full_like(self.comoment, np.nan)
        return self.comoment / (self.count - 1)


def assembly_totals(eps, limit) -> np.ndarray:
    """Per-assembly totals (:data:`CLUSTER_COLUMNS`) of epsilon (assemblies, balls).

    Parameters
    ----------
    eps : array_like (A, balls)
        epsilon [-], NaN for a ball without a valid value (not counted).
    limit : float
        L > 0 [-]; out of spec means |epsilon| > L.

    Returns
    -------
    ndarray (A, 4) of float: n_a, k_a, S_a, Q_a.
    """
    eps = np.asarray(eps, dtype=float)
    if eps.ndim != 2:
        raise ValueError(f"epsilon of shape {eps.shape}: expected (assemblies, balls)")
    valid = np.isfinite(eps)
    e = np.where(valid, eps, 0.0)
    return np.stack([valid.sum(axis=1).astype(float),
                     (valid & (np.abs(e) > limit)).sum(axis=1).astype(float),
                     e.sum(axis=1), (e * e).sum(axis=1)], axis=1)


def _columns(moments, p_min=4):
    if moments.mean.shape[0] < p_min:
        raise ValueError(f"moments have {moments.mean.shape[0]} columns; expected "
                         f"{CLUSTER_COLUMNS}")


def ratio_variance(moments: ClusterMoments, numerator=1, denominator=0):
    """Ratio R = sum y_num / sum y_den over assemblies and its delta-method variance.

    ([Cochran1977] Sec. 6.3-6.4; no finite-population correction)::

        v(R) = sum_a (y_num,a - R y_den,a)^2 / ((A - 1) A ybar_den^2)
             = (C_nn - 2 R C_nd + R^2 C_dd) / ((A - 1) A ybar_den^2)

    Parameters
    ----------
    moments : ClusterMoments
    numerator, denominator : int
        Columns (default: :data:`CLUSTER_COLUMNS` k over n, the fraction out of spec).

    Returns
    -------
    (ratio, variance) : floats; NaN ratio when sum y_den = 0, NaN variance when A < 2.
    """
    a = int(moments.count)
    num, den = float(moments.mean[numerator]), float(moments.mean[denominator])
    if a == 0 or den == 0:
        return float("nan"), float("nan")
    r = num / den
    if a < 2:
        return r, float("nan")
    c = moments.comoment
    ss = (float(c[numerator, numerator]) - 2 * r * float(c[numerator, denominator])
          + r * r * float(c[denominator, denominator]))
    return r, max(ss, 0.0) / ((a - 1) * a * den * den)


def cluster_proportion(moments: ClusterMoments, confidence_level=0.95, interval="wilson",
                       df_rule="effective") -> Proportion:
    """Ball-level fraction out of spec sum k_a / sum n_a with the assembly as sampling unit.

    Ratio estimator over clusters with its linearised (delta-method) variance, and the
    binomial interval at Korn & Graubard's effective sample size (see the Notes for the
    formulas, the bounds on the design effect and the k = 0 case).

    Parameters
    ----------
    moments : ClusterMoments
        Of the totals in :data:`CLUSTER_COLUMNS` order (columns 0 and 1 are used).
    confidence_level : float
    interval : {"wilson", "clopper-pearson"}
        Binomial interval at (p n_eff, n_eff).
    df_rule : {"effective", "design"}
        Degrees of freedom of the variance: min(A - 1, x_eff - 1) (default) or K&G's design
        df A - 1 (for comparison; undercovers at small counts, see the Notes).

    Returns
    -------
    Proportion
        ``successes`` and ``trials`` the total counts, ``design_effect`` = trials / n_eff,
        ``effective_trials`` = n_eff, ``clusters`` = A; NaN with no valid ball.

    Notes
    -----
    **Fraction out of spec** (:func:`cluster_proportion`). The ratio estimator
    p = sum k_a / sum n_a ([Cochran1977] Sec. 3.12, proportions in cluster sampling; Sec. 6.3,
    6.4, variance of a ratio estimate and its sample estimate; Ch. 9A, clusters of unequal
    sizes), with the linearised variance (no finite-population correction: the assemblies are
    draws from an infinite population) ::

        v(p) = sum_a (k_a - p n_a)^2 / ((A - 1) A nbar^2)
             = (C_kk - 2 p C_kn + p^2 C_nn) / ((A - 1) A nbar^2).

    A Wald interval p -+ z sqrt(v) undercovers for small p (its lower end goes negative, its
    upper end is too low), so the interval is Korn & Graubard's ([KornGraubard1998]): a
    binomial interval at the *effective sample size* ::

        deff  = v(p) / (p (1 - p) / N),          N = sum n_a   (design effect, [Kish1965])
        n_eff = N / deff * (z / t_df)^2,         x_eff = p n_eff

    where (z / t_df)^2 is their correction for the degrees of freedom of v(p).

    - **Degrees of freedom.** K&G take df from the design (A - 1 here, which makes the
      correction 1). For a rare fraction v(p) rests on the few assemblies that have a ball
      out, not on A, and with df = A - 1 the interval undercovers when the expected count is
      small: 86 % at an expected 10 balls out, 88 % at 20, 93 % at 50, 94 % at 100 (rho =
      0.9, trains of 10, p = 1e-3, 2000 repeats: ``python benchmarks/coverage_cluster.py
      --sweep --repeats 2000``), because a sample whose out-of-spec assemblies happen to have
      one ball out each estimates deff ~ 1 and p too low at once.
      tolsim uses df = min(A - 1, max(x_eff - 1, 1)) with x_eff = p n_eff before the
      correction. For small p, x_eff ~ (sum k_a)^2 / sum k_a^2, Kish's effective number of
      assemblies with a ball out, which is at most their number, so this df errs on the
      small (wide) side; for large counts it changes little (3 % wider at 200 balls out). This
      choice is tolsim's, not K&G's.
    - **Interval: Wilson** ([Wilson1927]) at (x_eff, n_eff) by default. In the same runs it
      covers 95.3-95.8 % for expected counts 50-500 (96.0 % at p = 1e-2) and 97.5 / 98.7 % at
      20 / 10; Clopper-Pearson at (x_eff, n_eff) (K&G's choice, ``interval=``) covers
      95.8-96.6 % (96.7 %) and 98.6 / 99.9 %, ~1 point more conservative and 2-5 % wider.
      Wilson is the default because it is closest to nominal without falling below it; the
      old independent-ball Wilson interval of k of N covers 60-65 % in all these cases.
    - **deff >= 1** (n_eff <= N): a design effect below 1 (negatively correlated balls) is
      not believed, as in the usual implementations of K&G's method (e.g. SAS PROC
      SURVEYFREQ's modified intervals); it can only widen the interval.
    - **n_eff >= N^2 / sum n_a^2** (= A for equal sizes): for 0 <= k_a <= n_a with mean p n_a,
      Var(k_a) <= n_a^2 p (1 - p) (all balls of an assembly in or out together), so deff
      can not exceed sum n_a^2 / N; a larger estimate is noise.
    - **k = 0 or k = N**: the variance estimate is 0 and the design effect unknown. deff = 1
      would be the optimistic case (independent balls); instead n_eff takes its lower bound
      N^2 / sum n_a^2, i.e. each assembly counts as one trial, which holds whatever the
      (non-negative) correlation of the balls of an assembly: with no ball out, the upper end
      is about z^2 / A (Wilson) rather than z^2 / N. The same bound is used when A < 2.
    """
    _columns(moments)
    if not 0 < confidence_level < 1:
        raise ValueError(f"confidence_level = {confidence_level!r} must be in (0, 1)")
    try:
        binomial = {"wilson": wilson_interval,
                    "clopper-pearson": clopper_pearson_interval}[interval]
    except KeyError:
        raise ValueError(f"interval = {interval!r}; choose one of {CLUSTER_INTERVALS}") \
            from None
    if df_rule not in ("effective", "design"):
        raise ValueError(f"df_rule = {df_rule!r}; choose 'effective' or 'design'")
    a = int(moments.count)
    n_bar, k_bar = float(moments.mean[0]), float(moments.mean[1])
    trials = int(np.rint(a * n_bar))
    successes = float(np.rint(a * k_bar))
    name = f"cluster ratio, Korn-Graubard n_eff ({df_rule} df), {interval}"
    if trials == 0:
        nan = float("nan")
        return Proportion(nan, nan, nan, successes, 0, confidence_level, name, nan, 0.0, a)
    p = successes / trials
    # n_eff bounds: all balls of an assembly in or out together (deff = sum n_a^2 / N), and
    # independent balls (deff = 1)
    sum_n2 = float(moments.comoment[0, 0]) + a * n_bar * n_bar
    n_min = min(float(trials), trials * float(trials) / sum_n2)
    if a >= 2 and 0 < successes < trials:
        var = ratio_variance(moments, 1, 0)[1]
        n_eff = float(np.clip(p * (1 - p) / var if var > 0 else np.inf, n_min, trials))
        # degrees of freedom of the variance estimate: the effective number of assemblies
        # with a ball out, p n_eff - 1, at most A - 1 (Notes)
        df = min(a - 1.0, max(p * n_eff - 1.0, 1.0)) if df_rule == "effective" else a - 1.0
        z = float(ndtri(0.5 + confidence_level / 2))
        t = float(t_distribution.ppf(0.5 + confidence_level / 2, df))
        n_eff = float(np.clip(n_eff * (z / t) ** 2, n_min, trials))
    else:
        # p = 0 or 1 (variance 0, design effect unknown) or a single assembly: each assembly
        # one trial, the worst case for non-negatively correlated balls
        n_eff = n_min
    lower, upper = binomial(p * n_eff, n_eff, confidence_level)
    return Proportion(p, lower, upper, successes, trials, confidence_level, name,
                      trials / n_eff, n_eff, a)


def cluster_capability(moments: ClusterMoments, limit, confidence_level=0.95,
                       quantiles=None) -> Capability:
    """Cp and Cpk of epsilon for |epsilon| <= L with delta-method intervals over assemblies.

    Parameters
    ----------
    moments : ClusterMoments
        Of the totals in :data:`CLUSTER_COLUMNS` order (columns 0, 2, 3 are used).
    limit : float
        L > 0 [-].
    confidence_level : float
    quantiles : (q_lo, median, q_hi), optional
        epsilon at the 0.135 %, 50 %, 99.865 % levels, for the percentile index.

    Returns
    -------
    Capability
        mu, sigma from the pooled sums (sigma with divisor N); intervals NaN for fewer than
        two assemblies or sigma = 0.

    Notes
    -----
    **Capability** (:func:`cluster_capability`). mu = Sbar / nbar,
    sigma^2 = Qbar / nbar - mu^2 (divisor N), Cp = L / (3 sigma),
    Cpk = (L - |mu|) / (3 sigma); the delta method over assemblies gives their variances from
    the gradients ::

        d mu      = (dSbar - mu dnbar) / nbar
        d sigma^2 = (dQbar - 2 mu dSbar + (2 mu^2 - m2) dnbar) / nbar,   m2 = Qbar / nbar
        d Cp      = -Cp d sigma^2 / (2 sigma^2)
        d Cpk     = -sign(mu) d mu / (3 sigma) - Cpk d sigma^2 / (2 sigma^2)

    and the interval is estimate -+ z se (with independent balls of a normal epsilon this is
    Bissell's [Bissell1990] variance 1/(9n) + Cpk^2/(2n), to first order). At mu = 0, |mu| has
    no derivative; sign(0) is taken as +1 (either sign gives the same variance to first order
    when mu and sigma^2 are uncorrelated, as for a symmetric epsilon). There the estimate is
    biased low by E|mu_hat| ~ 0.8 sd(mu_hat) / (3 sigma), so the misses fall mostly above the
    interval, but the coverage stays nominal: 94.6-95.9 % for Cp, Cpk at mu = 0 and at
    mu = 0.5 sigma in the runs of the Notes of :func:`cluster_proportion` (Bissell's
    independent-ball interval: 48-51 %).
    """
    _columns(moments)
    if not (np.isfinite(limit) and limit > 0):
        raise ValueError(f"limit = {limit!r} must be > 0")
    if not 0 < confidence_level < 1:
        raise ValueError(f"confidence_level = {confidence_level!r} must be in (0, 1)")
    nan = float("nan")
    a = int(moments.count)
    n_bar, s_bar, q_bar = (float(moments.mean[i]) for i in (0, 2, 3))
    n = int(np.rint(a * n_bar))
    pct = _percentile_index(limit, quantiles)
    method = "delta method over assemblies"
    if n == 0:
        return Capability(float(limit), nan, nan, nan, nan, pct, nan, 0, nan, nan, a, method)
    mu = s_bar / n_bar
    m2 = q_bar / n_bar
    var = max(m2 - mu * mu, 0.0)
    sigma = float(np.sqrt(var))
    if sigma > 0:
        cp = limit / (3.0 * sigma)
        cpk = (limit - abs(mu)) / (3.0 * sigma)
        normal = float(ndtr(-(limit - mu) / sigma) + ndtr(-(limit + mu) / sigma))
    else:
        cp = np.inf
        cpk = np.inf if abs(mu) < limit else -np.inf
        normal = float(abs(mu) > limit)
    cp_lo = cp_hi = cpk_lo = cpk_hi = nan
    if a >= 2 and sigma > 0:
        # gradients w.r.t. (nbar, kbar, Sbar, Qbar)
        g_mu = np.array([-mu, 0.0, 1.0, 0.0]) / n_bar
        g_var = np.array([2 * mu * mu - m2, 0.0, -2 * mu, 1.0]) / n_bar
        g_cp = -cp / (2 * var) * g_var
        sign = 1.0 if mu >= 0 else -1.0
        g_cpk = -sign / (3 * sigma) * g_mu - cpk / (2 * var) * g_var
        cov = moments.comoment[:4, :4] / ((a - 1) * a)         # covariance of the means
        z = float(ndtri(0.5 + confidence_level / 2))
        se_cp = float(np.sqrt(max(g_cp @ cov @ g_cp, 0.0)))
        se_cpk = float(np.sqrt(max(g_cpk @ cov @ g_cpk, 0.0)))
        cp_lo, cp_hi = cp - z * se_cp, cp + z * se_cp
        cpk_lo, cpk_hi = cpk - z * se_cpk, cpk + z * se_cpk
    return Capability(float(limit), float(cp), float(cpk), float(cpk_lo), float(cpk_hi), pct,
                      normal, n, float(cp_lo), float(cp_hi), a, method)


def _percentile_index(limit, quantiles):
    """ISO 22514-2 percentile Cpk from (q_lo, median, q_hi); NaN when not available."""
    if quantiles is None:
        return float("nan")
    q_lo, med, q_hi = (float(q) for q in quantiles)
    if np.all(np.isfinite([q_lo, med, q_hi])) and q_hi > med > q_lo:
        return float(min((limit - med) / (q_hi - med), (med + limit) / (med - q_lo)))
    return float("nan")


# --------------------------------------------------------------------------------------------
# Differences of two runs, and intervals on aggregates (tolsim compare)
# --------------------------------------------------------------------------------------------
def mover_difference(estimate_1, lower_1, upper_1, estimate_2, lower_2, upper_2):
    """Interval of theta_1 - theta_2 from the intervals of two independent estimates.

    The MOVER ([ZouDonner2008]; Newcombe's method 10 is the case with Wilson intervals)::

        L = d - sqrt((t1 - l1)^2 + (u2 - t2)^2),   U = d + sqrt((u1 - t1)^2 + (t2 - l2)^2)

    with d = t1 - t2.

    Parameters
    ----------
    estimate_1, lower_1, upper_1 : float
        theta_1 and its interval.
    estimate_2, lower_2, upper_2 : float
        theta_2 and its interval (same confidence level).

    Returns
    -------
    (difference, lower, upper) : floats; NaN where an end needed is NaN.
    """
    t1, l1, u1, t2, l2, u2 = (float(x) for x in (estimate_1, lower_1, upper_1, estimate_2,
                                                 lower_2, upper_2))
    d = t1 - t2
    lower = d - math.hypot(t1 - l1, u2 - t2)
    upper = d + math.hypot(u1 - t1, t2 - l2)
    return d, lower, upper


def newcombe_difference(successes_1, trials_1, successes_2, trials_2,
                        confidence_level=0.95):
    """Newcombe's hybrid score interval of p_1 - p_2 ([Newcombe1998] method 10).

    The MOVER (:func:`mover_difference`) on the Wilson score intervals (no continuity
    correction) of the two independent proportions p_i = k_i / n_i.

    Parameters
    ----------
    successes_1, trials_1 : float
        k_1 and n_1 of the first proportion.
    successes_2, trials_2 : float
        k_2 and n_2 of the second.
    confidence_level : float

    Returns
    -------
    (difference, lower, upper) : floats [-], within [-1, 1]; NaN when a trials count is 0.
    """
    k1, n1, k2, n2 = (float(x) for x in (successes_1, trials_1, successes_2, trials_2))
    if n1 == 0 or n2 == 0:
        nan = float("nan")
        return (k1 / n1 if n1 else nan) - (k2 / n2 if n2 else nan), nan, nan
    l1, u1 = wilson_interval(k1, n1, confidence_level)
    l2, u2 = wilson_interval(k2, n2, confidence_level)
    d, lower, upper = mover_difference(k1 / n1, l1, u1, k2 / n2, l2, u2)
    return d, max(lower, -1.0), min(upper, 1.0)


def welch_difference(estimate_1, standard_error_1, df_1, estimate_2, standard_error_2, df_2,
                     confidence_level=0.95):
    """Welch's interval of theta_1 - theta_2 from two independent estimates.

    d -+ t(nu) sqrt(se_1^2 + se_2^2) with the Welch-Satterthwaite degrees of freedom
    ([Welch1947], [Satterthwaite1946])::

        nu = (se_1^2 + se_2^2)^2 / (se_1^4 / df_1 + se_2^4 / df_2)

    Parameters
    ----------
    estimate_1, standard_error_1, df_1 : float
        theta_1, its standard error and the degrees of freedom of that (``inf``: known).
    estimate_2, standard_error_2, df_2 : float
        The same of theta_2.
    confidence_level : float

    Returns
    -------
    (difference, lower, upper, df) : floats; an exact difference (lower = upper) when both
    standard errors are 0.
    """
    d = float(estimate_1) - float(estimate_2)
    v1, v2 = float(standard_error_1) ** 2, float(standard_error_2) ** 2
    v = v1 + v2
    if v == 0.0:
        return d, d, d, float("inf")
    denominator = sum(vi * vi / float(df) for vi, df in ((v1, df_1), (v2, df_2))
                      if vi > 0.0 and np.isfinite(df))
    df = v * v / denominator if denominator > 0 else float("inf")
    q = 0.5 + confidence_level / 2
    t = float(ndtri(q)) if not np.isfinite(df) else float(t_distribution.ppf(q, df))
    half = t * math.sqrt(v)
    return d, d - half, d + half, float(df)


def cluster_mean_and_std(moments: ClusterMoments):
    """Mean and standard deviation of epsilon over balls, with delta-method standard errors
    over assemblies.

    mu = Sbar / nbar and sigma^2 = Qbar / nbar - mu^2 from the means of the per-assembly
    totals (n_a, k_a, S_a, Q_a) (:data:`tolsim.study.statistics.intervals.CLUSTER_COLUMNS`); their
    variances by linearisation with the covariance of the means C / (A (A - 1)) ([Cochran1977]
    Sec. 6.3-6.4; the gradients of :func:`tolsim.study.statistics.intervals.cluster_capability`)::

        d mu      = (dSbar - mu dnbar) / nbar
        d sigma^2 = (dQbar - 2 mu dSbar + (2 mu^2 - m2) dnbar) / nbar,   m2 = Qbar / nbar
        d sigma   = d sigma^2 / (2 sigma)

    Parameters
    ----------
    moments : ClusterMoments
        Of the totals in :data:`~tolsim.study.statistics.intervals.CLUSTER_COLUMNS` order.

    Returns
    -------
    (mean, se_mean, std, se_std) : floats [-]; NaN without valid balls, standard errors NaN
    for fewer than two assemblies (and se_std for sigma = 0).
    """
    nan = float("nan")
    a = int(moments.count)
    n_bar, s_bar, q_bar = (float(moments.mean[i]) for i in (0, 2, 3))
    if a == 0 or n_bar == 0:
        return nan, nan, nan, nan
    mu = s_bar / n_bar
    m2 = q_bar / n_bar
    sigma = math.sqrt(max(m2 - mu * mu, 0.0))
    if a < 2:
        return mu, nan, sigma, nan
    se_mu = math.sqrt(ratio_variance(moments, 2, 0)[1])
    g_var = np.array([2 * mu * mu - m2, 0.0, -2 * mu, 1.0]) / n_bar
    cov = np.asarray(moments.comoment, dtype=float)[:4, :4] / ((a - 1) * a)
    se_var = math.sqrt(max(float(g_var @ cov @ g_var), 0.0))
    se_sigma = se_var / (2 * sigma) if sigma > 0 else nan
    return mu, se_mu, sigma, se_sigma


def histogram_quantile_interval(counts, edges, level, effective_trials, underflow=0,
                                overflow=0, confidence_level=0.95):
    """Woodruff's interval of a quantile read off a fixed-bin histogram ([Woodruff1952]).

    The Wilson interval (p_L, p_U) of the proportion ``level`` at ``effective_trials`` is
    turned into values through the histogram's distribution function (linear in a bin,
    :func:`tolsim.study.statistics.intervals.histogram_quantiles`); each end is then moved out to
    the
    edge of its bin, since the histogram places a value only within its bin.

    Parameters
    ----------
    counts : array_like of int (bins,)
    edges : array_like (bins + 1,)
    level : float
        Quantile level q in (0, 1) [-].
    effective_trials : float
        n behind the proportion (the number of independent values, or an effective size).
    underflow, overflow : int
        Values below / above the histogram range.
    confidence_level : float

    Returns
    -------
    (lower, upper) : floats, in the units of ``edges``; an end NaN where it falls below the
    smallest or above the largest value (not bounded by the data) or outside the histogram.
    """
    counts = np.asarray(counts, dtype=np.int64)
    edges = np.asarray(edges, dtype=float)
    total = float(counts.sum()) + float(underflow) + float(overflow)
    nan = float("nan")
    n = float(effective_trials)
    if total == 0 or not n > 0:
        return nan, nan
    p_lower, p_upper = wilson_interval(level * n, n, confidence_level)
    ends = []
    for p, side in ((p_lower, "lower"), (p_upper, "upper")):
        rank = p * total
        if (side == "lower" and rank < 1.0) or (side == "upper" and rank > total - 1.0):
            ends.append(nan)  # beyond the extreme values: the data do not bound it
            continue
        q = float(histogram_quantiles(counts, edges, [p], underflow, overflow)[0])
        if not np.isfinite(q):
            ends.append(nan)
            continue
        if side == "lower":
            k = int(np.clip(np.searchsorted(edges, q, side="right") - 1, 0, len(edges) - 1))
        else:
            k = int(np.clip(np.searchsorted(edges, q, side="left"), 0, len(edges) - 1))
        ends.append(float(edges[k]))
    return ends[0], ends[1]
