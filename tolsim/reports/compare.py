"""Studies side by side (``tolsim compare``): key statistics with their intervals, the
difference of each to a reference run with its own interval, the config keys that differ, and
overlaid distributions.

:func:`compare_runs` reads two or more result files of ``tolsim run``
(:func:`tolsim.io.netcdf.read_result`) and writes, into a folder:

* ``compare.html``: one self-contained page (figures embedded as data URIs): the runs, how
  their random numbers relate, the config keys that differ, the key statistics of every run
  with their 95 % intervals and the difference of each to the first run (the reference) with
  its own interval, and the figures below;
* ``compare.csv``: one row per statistic and run: estimate, ci_lower, ci_upper, units, and the
  difference to the reference with its interval (empty for the reference itself);
* ``contact_probability.png``: P(contact) of every run with its interval, and the difference
  to the reference (a forest plot);
* ``velocity_deviation.png``: the epsilon histograms overlaid (densities);
* ``survival.png``: the survival curves P(no contact by t) overlaid.

Everything but the reading and writing is pure: :func:`run_statistics` takes the statistics
out of a Dataset, :func:`compare_datasets` compares Datasets held in memory, and the interval
functions (:func:`newcombe_difference`, :func:`welch_difference`, :func:`mover_difference`,
:func:`histogram_quantile_interval`, :func:`cluster_mean_and_std`) take plain numbers.

Statistics and their intervals (95 %)
-------------------------------------
* **P(contact)** per train (per assembly in a carriage study): k of the n trains whose outcome
  is known, with the file's Clopper-Pearson interval. When a run has unresolved trains, also
  the partial-identification bounds k/N and (k + u)/N over all N trains, each with its
  Clopper-Pearson interval.
* **epsilon mean and standard deviation**: the file's estimates; their standard errors by the
  delta method over assemblies (the balls of an assembly are correlated, the assemblies are
  independent: ratio estimator, [Cochran1977] Sec. 6.3-6.4) from the per-assembly moments the
  file stores (:mod:`tolsim.study.statistics.intervals`), interval estimate -+ t(A - 1) se.
* **epsilon quantiles** (:data:`VELOCITY_DEVIATION_LEVELS`): read off the histogram; interval
  by Woodruff's method ([Woodruff1952]): a Wilson interval for the level, turned into values
  through the histogram, at the effective sample size N^2 / sum n_a^2 (each assembly one
  trial), the smallest any correlation of the balls of an assembly allows
  (Var k_a <= n_a^2 p (1 - p)), and widened to the edges of the histogram bins they fall in.
  An end beyond the smallest or largest value is not bounded by the data: NaN ("n/a").
* **fraction out of spec and Cpk** (with a limit on |epsilon|): the file's values and
  intervals (Korn-Graubard effective sample size; delta method over assemblies,
  :mod:`tolsim.study.statistics.quality`).
* **time-to-contact quantiles** (:data:`TIME_TO_CONTACT_LEVELS`, given contact): Woodruff's
  interval on the histogram of the first-contact times, one per assembly with contact
  (independent, so n is their number).
* **carriage stiffness** (a study with a ``[carriage]``): the mean over the solved carriages
  with a t interval (mean -+ t(n - 1) std / sqrt(n)), and the stiffness of the nominal
  assembly, which has no sampling error.

Differences to the reference: paired or unpaired?
-------------------------------------------------
Runs with the same ``seed``, ``block_size`` and ``sampling`` draw their assemblies from common
random numbers ([Law2015] Sec. 11.2): assembly i of one run uses the random numbers of
assembly i of the other, so their outcomes are correlated, positively when a change moves the
outcome the same way in every assembly. A paired interval would use that, but it needs
per-assembly data (for P(contact), the joint counts: contact in both runs, in one only); the
files hold aggregates only, and re-running the studies from their stored configs to get them
costs as much as the runs. So every difference here is **unpaired**: the two estimates are
taken as independent. For independent runs (different seeds) that is exact; for runs with
common random numbers it overstates the variance of the difference by 2 Cov, so the interval
is wider than a paired one (conservative) as long as the runs are positively correlated. The
report says which runs share random numbers with the reference. (A cheap paired interval would
need per-block totals in the files, the contact count of each block of ``block_size``
assemblies, say: with common random numbers block b of both runs uses the same stream, so the
per-block differences are independent across blocks and a t interval over them is paired.)

* P(contact) and its bounds: Newcombe's hybrid score interval ([Newcombe1998] method 10),
  from the Wilson intervals of the two proportions (:func:`newcombe_difference`).
* means and standard deviations (epsilon, carriage stiffness): Welch's interval with the
  Welch-Satterthwaite degrees of freedom ([Welch1947], [Satterthwaite1946];
  :func:`welch_difference`).
* quantiles, fraction out of spec, Cpk: the MOVER ([ZouDonner2008]; "method of variance
  estimates recovery", :func:`mover_difference`) from the two runs' own intervals, of which
  Newcombe's method 10 is the case with Wilson intervals; with symmetric intervals it is the
  Wald interval of the difference.
* nominal carriage stiffness: exact (no sampling error).

References
----------
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
.. [Cochran1977] W. G. Cochran, Sampling Techniques, 3rd ed., Wiley, 1977.
.. [Law2015] A. M. Law, Simulation Modeling and Analysis, 5th ed., McGraw-Hill, 2015.
"""

import csv
import html
import io
import math
import os
import tomllib
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np
from scipy.special import ndtri
from scipy.stats import t as t_distribution

from tolsim import __version__
from tolsim.reports.study import CSS, NotAResult
from tolsim.reports.style import (
    LIMIT_COLOUR,
    SERIES_COLOURS,
    data_uri,
    new_figure,
    render_png,
    styled,
)
from tolsim.reports.verdict import contact_unit, tracks_of
from tolsim.study.statistics.intervals import (
    ClusterMoments,
    clopper_pearson_interval,
    format_fraction,
    histogram_quantiles,
    ratio_variance,
    wilson_interval,
)

#: Quantile levels of epsilon compared [-].
VELOCITY_DEVIATION_LEVELS = (0.001, 0.01, 0.5, 0.99, 0.999)
#: Quantile levels of the time to first contact (given contact) compared [-].
TIME_TO_CONTACT_LEVELS = (0.1, 0.5, 0.9)
#: Confidence level of every interval [-].
CONFIDENCE_LEVEL = 0.95
#: Colours of the runs: the series colours without the spec-limit colour.
RUN_COLOURS = tuple(c for c in SERIES_COLOURS if c != LIMIT_COLOUR)
RUN_LINESTYLES = ("-", "--", "-.", ":")
#: Files written by :func:`compare_runs`.
HTML_NAME, CSV_NAME = "compare.html", "compare.csv"
#: Columns of ``compare.csv``.
CSV_COLUMNS = ("statistic", "description", "run", "file", "estimate", "ci_lower", "ci_upper",
               "units", "interval", "difference", "difference_ci_lower",
               "difference_ci_upper", "difference_interval")
#: What the differences are, by the relation of a run's random numbers to the reference's.
PAIRING_SHARED = "unpaired, conservative for runs with common random numbers"
PAIRING_INDEPENDENT = "unpaired"
#: Attributes that must agree for two runs to draw from common random numbers.
RANDOM_NUMBER_ATTRIBUTES = ("seed", "block_size", "sampling")


# --------------------------------------------------------------------------------------------
# Interval functions (pure)
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
                        confidence_level=CONFIDENCE_LEVEL):
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
                     confidence_level=CONFIDENCE_LEVEL):
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
                                overflow=0, confidence_level=CONFIDENCE_LEVEL):
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


# --------------------------------------------------------------------------------------------
# Statistics of a run
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Statistic:
    """One key statistic of a run with its interval.

    Attributes
    ----------
    name : str
        Key of the statistic (the CSV ``statistic`` column).
    description : str
    units : str
        UDUNITS, as in the result file (``1`` for dimensionless).
    estimate, ci_lower, ci_upper : float
        In ``units``; an end NaN where it is not available.
    interval : str
        How the interval was made.
    kind : str
        How the difference of two runs gets its interval: a key of :data:`DIFFERENCE_METHODS`.
    display : str
        How the HTML shows it: a key of :data:`DISPLAY`.
    successes, trials : float
        k and n of a proportion (``kind = "proportion"``).
    standard_error, df : float
        Standard error and its degrees of freedom (``kind = "welch"``).
    family : str
        The statistic without its level or degree of freedom (``velocity_deviation_quantile``),
        for the table of interval methods; '' when it is ``name``.
    """

    name: str
    description: str
    units: str
    estimate: float
    ci_lower: float
    ci_upper: float
    interval: str
    kind: str
    display: str
    successes: float = float("nan")
    trials: float = float("nan")
    standard_error: float = float("nan")
    df: float = float("nan")
    family: str = ""


@dataclass(frozen=True)
class Difference:
    """Difference of a statistic of a run to the reference's, with its interval."""

    estimate: float
    ci_lower: float
    ci_upper: float
    interval: str

    @property
    def excludes_zero(self) -> bool:
        """The interval lies wholly on one side of 0."""
        return bool(self.ci_lower > 0 or self.ci_upper < 0)


def _value(ds, name, default=float("nan")):
    if name not in ds.variables:
        return default
    return float(np.asarray(ds[name]))


def _count(ds, name, default=0):
    if name not in ds.variables:
        return default
    return int(np.asarray(ds[name]))


def _edges(ds, bounds):
    b = np.asarray(ds[bounds], dtype=float)
    return np.concatenate([b[:, 0], b[-1:, 1]])


def _level_name(level) -> str:
    return f"{float(level):g}"


def _quantile_index(ds, level):
    """Index of ``level`` along the file's ``quantile`` coordinate, or None."""
    levels = np.asarray(ds["quantile"], dtype=float)
    hit = np.flatnonzero(np.isclose(levels, level, rtol=0, atol=1e-12))
    return int(hit[0]) if hit.size else None


def _moments(ds):
    if "assembly_total_mean" not in ds.variables:
        return None
    return ClusterMoments(_count(ds, "assembly_count"),
                          np.asarray(ds["assembly_total_mean"], dtype=float),
                          np.asarray(ds["assembly_total_comoment"], dtype=float))


def _t_interval(estimate, se, df, confidence_level):
    if not (np.isfinite(se) and df >= 1):
        return float("nan"), float("nan")
    t = float(t_distribution.ppf(0.5 + confidence_level / 2, df))
    return estimate - t * se, estimate + t * se


def _contact_statistics(ds, bounds):
    one = contact_unit(ds)[0]
    n_asm, k, u = (_count(ds, n) for n in ("n_assemblies", "n_contact",
                                             "n_assemblies_unresolved"))
    out = [Statistic(
        "contact_probability", f"P(contact within the stroke) per {one}, over the {one}s "
        "whose outcome is known", "1", _value(ds, "contact_probability"),
        _value(ds, "contact_probability_ci_lower"), _value(ds, "contact_probability_ci_upper"),
        "Clopper-Pearson", "proportion", "probability", successes=k, trials=n_asm - u)]
    if bounds:
        for name, hits, what in (("lower", k, "unresolved counted as no contact"),
                                 ("upper", k + u, "unresolved counted as contact")):
            lo, hi = (clopper_pearson_interval(hits, n_asm) if n_asm
                      else (float("nan"), float("nan")))
            out.append(Statistic(
                f"contact_probability_bound_{name}",
                f"{name} bound of P(contact) over all {one}s ({what})", "1",
                hits / n_asm if n_asm else float("nan"), lo, hi, "Clopper-Pearson",
                "proportion", "probability", successes=hits, trials=n_asm))
    return out


def _velocity_deviation_statistics(ds, confidence_level):
    out = []
    moments = _moments(ds)
    a = int(moments.count) if moments is not None else 0
    if moments is not None:
        _, se_mean, _, se_std = cluster_mean_and_std(moments)
    else:
        se_mean = se_std = float("nan")
    method = "delta method over assemblies, t(A - 1)"
    for name, se, what in (("mean", se_mean, "mean"), ("std", se_std, "standard deviation")):
        estimate = _value(ds, f"velocity_deviation_{name}")
        lo, hi = _t_interval(estimate, se, a - 1, confidence_level)
        out.append(Statistic(f"velocity_deviation_{name}", f"{what} of epsilon over the "
                             "valid balls", "1", estimate, lo, hi, method, "welch",
                             "epsilon" if name == "mean" else "epsilon_spread",
                             standard_error=se, df=float(a - 1)))
    counts = np.asarray(ds["velocity_deviation_histogram"])
    edges = _edges(ds, "velocity_deviation_bin_bounds")
    under, over = (_count(ds, f"velocity_deviation_{x}") for x in ("underflow", "overflow"))
    if moments is not None and a > 0:
        n_bar = float(moments.mean[0])
        sum_n2 = float(moments.comoment[0, 0]) + a * n_bar * n_bar
        n_eff = (a * n_bar) ** 2 / sum_n2 if sum_n2 > 0 else 0.0
    else:
        n_eff = 0.0
    q = np.asarray(ds["velocity_deviation_quantile"], dtype=float)
    for level in VELOCITY_DEVIATION_LEVELS:
        k = _quantile_index(ds, level)
        if k is None:
            continue
        lo, hi = histogram_quantile_interval(counts, edges, level, n_eff, under, over,
                                             confidence_level)
        out.append(Statistic(
            f"velocity_deviation_quantile_{_level_name(level)}",
            f"{100 * level:g} % quantile of epsilon", "1", float(q[k]), lo, hi,
            "Woodruff, each assembly one trial, widened to the histogram bins", "mover",
            "epsilon", family="velocity_deviation_quantile"))
    return out


def _quality_statistics(ds):
    out = []
    if np.isfinite(_value(ds, "velocity_deviation_out_of_spec_fraction")):
        out.append(Statistic(
            "velocity_deviation_out_of_spec_fraction",
            "fraction of valid balls with |epsilon| above the spec limit", "1",
            _value(ds, "velocity_deviation_out_of_spec_fraction"),
            _value(ds, "velocity_deviation_out_of_spec_ci_lower"),
            _value(ds, "velocity_deviation_out_of_spec_ci_upper"),
            "Korn-Graubard effective sample size, assemblies as the sampling unit", "mover",
            "probability"))
    if np.isfinite(_value(ds, "velocity_deviation_cpk")):
        out.append(Statistic(
            "velocity_deviation_cpk", "process capability Cpk = (L - |mu|) / (3 sigma) of "
            "epsilon", "1", _value(ds, "velocity_deviation_cpk"),
            _value(ds, "velocity_deviation_cpk_ci_lower"),
            _value(ds, "velocity_deviation_cpk_ci_upper"), "delta method over assemblies",
            "mover", "index"))
    return out


def _time_statistics(ds, confidence_level):
    out = []
    counts = np.asarray(ds["time_to_contact_histogram"])
    edges = _edges(ds, "time_bin_bounds")
    contacts = float(counts.sum())  # one first contact per assembly with contact
    q = np.asarray(ds["time_to_contact_quantile"], dtype=float)
    for level in TIME_TO_CONTACT_LEVELS:
        k = _quantile_index(ds, level)
        if k is None:
            continue
        lo, hi = histogram_quantile_interval(counts, edges, level, contacts, 0, 0,
                                             confidence_level)
        out.append(Statistic(
            f"time_to_contact_quantile_{_level_name(level)}",
            f"{100 * level:g} % quantile of the time to first contact, given contact", "s",
            float(q[k]), lo, hi, "Woodruff over the first contacts, widened to the "
            "histogram bins", "mover", "seconds", family="time_to_contact_quantile"))
    return out


#: Carriage degrees of freedom: (file variable stem, name label, units, display).
_CARRIAGE_STIFFNESS = (("translational", "carriage_translation_name", "N m-1",
                        "stiffness_translation"),
                       ("rotational", "carriage_rotation_name", "N m rad-1",
                        "stiffness_rotation"))


def _carriage_statistics(ds, confidence_level):
    out = []
    if not tracks_of(ds):
        return out
    solved = _count(ds, "n_assemblies") - _count(ds, "n_assemblies_carriage_failed")
    for stem, label, units, display in _CARRIAGE_STIFFNESS:
        if label not in ds.variables or f"carriage_{stem}_stiffness_mean" not in ds.variables:
            continue
        names = [str(n) for n in np.asarray(ds[label])]
        mean = np.asarray(ds[f"carriage_{stem}_stiffness_mean"], dtype=float)
        std = np.asarray(ds[f"carriage_{stem}_stiffness_std"], dtype=float)
        nominal = np.asarray(ds[f"carriage_{stem}_stiffness_nominal"], dtype=float)
        for j, dof in enumerate(names):
            se = std[j] / math.sqrt(solved) if solved > 0 else float("nan")
            lo, hi = _t_interval(mean[j], se, solved - 1, confidence_level)
            out.append(Statistic(
                f"carriage_{stem}_stiffness_mean_{dof}",
                f"{dof} stiffness of the carriage, mean over the {solved:,} solved carriages",
                units, float(mean[j]), lo, hi, "t(n - 1) over the solved carriages", "welch",
                display, standard_error=se, df=float(solved - 1),
                family=f"carriage_{stem}_stiffness_mean"))
            out.append(Statistic(
                f"carriage_{stem}_stiffness_nominal_{dof}",
                f"{dof} stiffness of the nominal carriage (no errors)", units,
                float(nominal[j]), float(nominal[j]), float(nominal[j]),
                "exact: the nominal assembly has no sampling error", "exact", display,
                family=f"carriage_{stem}_stiffness_nominal"))
    return out


def run_statistics(ds, *, bounds=None, confidence_level=CONFIDENCE_LEVEL) -> list:
    """The key statistics of a result with their intervals (see the module docstring).

    Parameters
    ----------
    ds : xarray.Dataset
        A result of ``tolsim run`` (in memory; any mapping of the result-file variables
        with ``sizes`` works).
    bounds : bool, optional
        Include the partial-identification bounds of P(contact) (default: when the run has
        unresolved trains).
    confidence_level : float

    Returns
    -------
    list of Statistic
        P(contact) (and its bounds), epsilon mean, std and quantiles, the fraction out of
        spec and Cpk where the file has them, the time-to-contact quantiles, and the
        carriage stiffness of a carriage study.
    """
    if bounds is None:
        bounds = _count(ds, "n_assemblies_unresolved") > 0
    return [*_contact_statistics(ds, bounds),
            *_velocity_deviation_statistics(ds, confidence_level),
            *_quality_statistics(ds),
            *_time_statistics(ds, confidence_level),
            *_carriage_statistics(ds, confidence_level)]


# --------------------------------------------------------------------------------------------
# Differences
# --------------------------------------------------------------------------------------------
def _proportion_difference(run, reference, confidence_level):
    d, lo, hi = newcombe_difference(run.successes, run.trials, reference.successes,
                                    reference.trials, confidence_level)
    return d, lo, hi


def _welch_difference(run, reference, confidence_level):
    d, lo, hi, _ = welch_difference(run.estimate, run.standard_error, run.df,
                                    reference.estimate, reference.standard_error, reference.df,
                                    confidence_level)
    return d, lo, hi


def _mover_difference(run, reference, confidence_level):
    return mover_difference(run.estimate, run.ci_lower, run.ci_upper, reference.estimate,
                            reference.ci_lower, reference.ci_upper)


def _exact_difference(run, reference, confidence_level):
    d = run.estimate - reference.estimate
    return d, d, d


#: Statistic kind -> (difference function, name of its interval).
DIFFERENCE_METHODS = {
    "proportion": (_proportion_difference, "Newcombe hybrid score (method 10)"),
    "welch": (_welch_difference, "Welch-Satterthwaite"),
    "mover": (_mover_difference, "MOVER from the two intervals"),
    "exact": (_exact_difference, "exact"),
}


def difference(run: Statistic, reference: Statistic, pairing=PAIRING_INDEPENDENT,
               confidence_level=CONFIDENCE_LEVEL) -> Difference:
    """The difference run - reference of a statistic, with its (unpaired) interval.

    Parameters
    ----------
    run, reference : Statistic
        The same statistic (same ``name`` and ``kind``) of two runs.
    pairing : str
        What the runs' random numbers are to each other (:data:`PAIRING_SHARED` or
        :data:`PAIRING_INDEPENDENT`), appended to the interval's name.
    confidence_level : float

    Returns
    -------
    Difference
    """
    if run.name != reference.name or run.kind != reference.kind:
        raise ValueError(f"cannot take the difference of {run.name!r} ({run.kind}) and "
                         f"{reference.name!r} ({reference.kind})")
    function, method = DIFFERENCE_METHODS[run.kind]
    d, lo, hi = function(run, reference, confidence_level)
    if run.kind != "exact":
        method = f"{method}; {pairing}"
    return Difference(float(d), float(lo), float(hi), method)


def bounds_difference(run, reference, confidence_level=CONFIDENCE_LEVEL):
    """Where the difference of P(contact) lies when trains are unresolved.

    With u unresolved trains of N, P(contact) is only known to lie in [k/N, (k + u)/N]; the
    difference run - reference then lies in [lower_run - upper_ref, upper_run - lower_ref].
    The interval covering that set takes the lower end of Newcombe's interval of the first
    and the upper end of that of the second (each end misses with at most half the error
    rate, as for the bounds of one run).

    Parameters
    ----------
    run, reference : dict
        Statistic name -> :class:`Statistic` of the two runs, with
        ``contact_probability_bound_lower`` and ``contact_probability_bound_upper``.
    confidence_level : float

    Returns
    -------
    (lower, upper, ci_lower, ci_upper) : floats [-], or None without the bounds.
    """
    names = ("contact_probability_bound_lower", "contact_probability_bound_upper")
    if not all(n in run and n in reference for n in names):
        return None
    lb_run, ub_run = (run[n] for n in names)
    lb_ref, ub_ref = (reference[n] for n in names)
    lower, ci_lower, _ = newcombe_difference(lb_run.successes, lb_run.trials,
                                             ub_ref.successes, ub_ref.trials, confidence_level)
    upper, _, ci_upper = newcombe_difference(ub_run.successes, ub_run.trials,
                                             lb_ref.successes, lb_ref.trials, confidence_level)
    return lower, upper, ci_lower, ci_upper


def shares_random_numbers(reference_attrs, run_attrs) -> bool:
    """Do two runs draw their assemblies from common random numbers?

    True when the global attributes :data:`RANDOM_NUMBER_ATTRIBUTES` (seed, block size,
    sampling scheme) are present in both and agree: block b of both runs then uses the same
    random stream, and assembly i of one corresponds to assembly i of the other (as long as
    they sample the same tolerance sources).
    """
    for key in RANDOM_NUMBER_ATTRIBUTES:
        if key not in reference_attrs or key not in run_attrs:
            return False
        if str(reference_attrs[key]) != str(run_attrs[key]):
            return False
    return True


# --------------------------------------------------------------------------------------------
# Config differences
# --------------------------------------------------------------------------------------------
#: Marker of a key that a run's config does not have.
ABSENT = object()


def _key_part(key) -> str:
    bare = key.replace("_", "").replace("-", "").isalnum() and key.isascii()
    return key if bare else '"' + key.replace("\\", "\\\\").replace('"', '\\"') + '"'


def flatten_config(mapping, prefix="") -> dict:
    """A parsed TOML config as {dotted key: value}.

    Tables become dotted keys (``tolerances.top_rotation.cpk``); an array of tables gets an
    index (``carriage.track[0].x_mm``); other arrays stay values. Keys that are not bare TOML
    keys are quoted.
    """
    out = {}
    for key, value in mapping.items():
        name = f"{prefix}{_key_part(str(key))}"
        if isinstance(value, dict):
            out.update(flatten_config(value, f"{name}."))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for i, item in enumerate(value):
                out.update(flatten_config(item, f"{name}[{i}]."))
        else:
            out[name] = value
    return out


def toml_value(value) -> str:
    """A config value as TOML writes it (``"normal"``, ``0.1``, ``true``, ``[1, 2]``)."""
    if value is ABSENT:
        return "—"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key_part(k)} = {toml_value(v)}"
                                for k, v in value.items()) + " }"
    return str(value)


@dataclass(frozen=True)
class ConfigDifference:
    """A config key whose value differs between runs.

    Attributes
    ----------
    key : str
        Dotted key.
    values : tuple
        Its value in every run, :data:`ABSENT` where a run does not have it.
    """

    key: str
    values: tuple

    @property
    def texts(self) -> tuple:
        """The values as TOML text, "—" where absent."""
        return tuple(toml_value(v) for v in self.values)


def config_differences(texts) -> tuple:
    """The keys whose values differ between configs given as TOML text.

    Parameters
    ----------
    texts : sequence of str
        The config text of every run (the ``config`` attribute of a result file).

    Returns
    -------
    (differences, unreadable) : (list of ConfigDifference, list of int)
        The keys that differ, or that only some runs have, sorted as they first appear in
        the configs; and the indices of the texts that are not valid TOML (their keys are
        left out).
    """
    flat, unreadable = [], []
    for i, text in enumerate(texts):
        try:
            flat.append(flatten_config(tomllib.loads(str(text))))
        except tomllib.TOMLDecodeError:
            flat.append(None)
            unreadable.append(i)
    readable = [f for f in flat if f is not None]
    order = {}
    for f in readable:
        for key in f:
            order.setdefault(key, len(order))
    out = []
    for key in sorted(order, key=order.get):
        values = tuple(f.get(key, ABSENT) for f in readable)
        first = values[0]
        if any(v is ABSENT for v in values) or any(_differ(first, v) for v in values[1:]):
            out.append(ConfigDifference(key, tuple(
                ABSENT if f is None else f.get(key, ABSENT) for f in flat)))
    return out, unreadable


def _differ(a, b) -> bool:
    # 1 and 1.0 are the same number in a config; True and 1 are not the same value
    if isinstance(a, bool) or isinstance(b, bool):
        return type(a) is not type(b) or a != b
    return a != b


# --------------------------------------------------------------------------------------------
# The comparison
# --------------------------------------------------------------------------------------------
@dataclass
class Run:
    """One compared result: its label, file, Dataset and statistics."""

    label: str
    path: str
    ds: object
    statistics: dict = field(default_factory=dict)  # name -> Statistic
    shares_random_numbers: bool = False  # with the reference (False for the reference)

    @property
    def pairing(self) -> str:
        return PAIRING_SHARED if self.shares_random_numbers else PAIRING_INDEPENDENT


@dataclass
class Comparison:
    """Runs side by side (:func:`compare_datasets`).

    Attributes
    ----------
    runs : list of Run
        The reference first.
    names : list of str
        Statistic names in display order (the union over the runs).
    differences : dict
        (statistic name, run label) -> Difference to the reference, for every run but the
        reference that has the statistic when the reference has it too.
    bound_differences : dict
        run label -> :func:`bounds_difference` to the reference, when trains are unresolved.
    config : list of ConfigDifference
    unreadable_configs : list of str
        Labels of runs whose config text is not valid TOML.
    confidence_level : float
    """

    runs: list
    names: list
    differences: dict
    bound_differences: dict
    config: list
    unreadable_configs: list
    confidence_level: float = CONFIDENCE_LEVEL

    @property
    def reference(self) -> Run:
        return self.runs[0]

    def statistic(self, name):
        """The first run's :class:`Statistic` of that name (for its description, units)."""
        return next(r.statistics[name] for r in self.runs if name in r.statistics)


def run_labels(paths) -> list:
    """Short labels of result files: the file names without ``.nc``, numbered when two are
    the same."""
    stems = [os.path.splitext(os.path.basename(os.fspath(p)))[0] or "run" for p in paths]
    out = []
    for i, stem in enumerate(stems):
        label = stem if stems.count(stem) == 1 else f"{stem} ({stems[:i + 1].count(stem)})"
        out.append(label)
    return out


def compare_datasets(datasets, labels=None, paths=None,
                     confidence_level=CONFIDENCE_LEVEL) -> Comparison:
    """Compare results held in memory, the first one being the reference.

    Parameters
    ----------
    datasets : sequence of xarray.Dataset
        At least two results of ``tolsim run``.
    labels : sequence of str, optional
        Their names in the report (default: ``run 1``, ``run 2``, ...).
    paths : sequence of str, optional
        Their files (shown in the report; default: the labels).
    confidence_level : float

    Returns
    -------
    Comparison
    """
    datasets = list(datasets)
    if len(datasets) < 2:
        raise ValueError(f"need at least two results to compare, got {len(datasets)}")
    labels = list(labels) if labels is not None else [f"run {i + 1}"
                                                       for i in range(len(datasets))]
    paths = [os.fspath(p) for p in paths] if paths is not None else list(labels)
    bounds = any(_count(ds, "n_assemblies_unresolved") > 0 for ds in datasets)
    runs, names = [], []
    for i, (ds, label, path) in enumerate(zip(datasets, labels, paths, strict=True)):
        stats = run_statistics(ds, bounds=bounds, confidence_level=confidence_level)
        shared = i > 0 and shares_random_numbers(datasets[0].attrs, ds.attrs)
        runs.append(Run(label, path, ds, {s.name: s for s in stats}, shared))
        names += [s.name for s in stats if s.name not in names]
    reference = runs[0]
    differences, bound_differences = {}, {}
    for run in runs[1:]:
        for name, stat in run.statistics.items():
            ref = reference.statistics.get(name)
            if ref is not None:
                differences[(name, run.label)] = difference(stat, ref, run.pairing,
                                                            confidence_level)
        if bounds:
            bound_differences[run.label] = bounds_difference(run.statistics,
                                                             reference.statistics,
                                                             confidence_level)
    config, unreadable = config_differences([ds.attrs.get("config", "") for ds in datasets])
    return Comparison(runs, names, differences, bound_differences, config,
                      [labels[i] for i in unreadable], confidence_level)


# --------------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------------
def _csv_number(x) -> str:
    return repr(float(x)) if np.isfinite(x) else ""


def csv_rows(comparison: Comparison) -> list:
    """One dict per statistic and run (keys :data:`CSV_COLUMNS`), statistics in display
    order, runs in the given order; the difference columns empty for the reference."""
    rows = []
    for name in comparison.names:
        for run in comparison.runs:
            stat = run.statistics.get(name)
            if stat is None:
                continue
            diff = comparison.differences.get((name, run.label))
            rows.append({
                "statistic": name, "description": stat.description, "run": run.label,
                "file": run.path, "estimate": _csv_number(stat.estimate),
                "ci_lower": _csv_number(stat.ci_lower), "ci_upper": _csv_number(stat.ci_upper),
                "units": stat.units, "interval": stat.interval,
                "difference": _csv_number(diff.estimate) if diff else "",
                "difference_ci_lower": _csv_number(diff.ci_lower) if diff else "",
                "difference_ci_upper": _csv_number(diff.ci_upper) if diff else "",
                "difference_interval": diff.interval if diff else "",
            })
    return rows


def csv_text(comparison: Comparison) -> str:
    """``compare.csv`` as text."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(csv_rows(comparison))
    return buffer.getvalue()


# --------------------------------------------------------------------------------------------
# Display
# --------------------------------------------------------------------------------------------
#: display -> (scale, unit shown, format of a value, format of a difference).
DISPLAY = {
    "epsilon": (100.0, "%", "{:+.4f}", "{:+.4f}"),
    "epsilon_spread": (100.0, "%", "{:.4f}", "{:+.4f}"),
    "index": (1.0, "", "{:.3f}", "{:+.3f}"),
    "seconds": (1.0, "s", "{:.4g}", "{:+.3g}"),
    "stiffness_translation": (1e-6, "N/µm", "{:.4g}", "{:+.3g}"),
    "stiffness_rotation": (1e-6, "N m/µrad", "{:.4g}", "{:+.3g}"),
}


def _scaled(display, x, diff=False) -> str:
    if not np.isfinite(x):
        return "n/a"
    scale, _, fmt_value, fmt_diff = DISPLAY[display]
    text = (fmt_diff if diff else fmt_value).format(scale * x + 0.0)
    return text.replace("-", "−")


def _unit(display) -> str:
    unit = DISPLAY[display][1]
    return f" {unit}" if unit else ""


def format_value(stat: Statistic) -> tuple:
    """(estimate, '95 % CI lo to hi') of a statistic as the HTML shows them."""
    if stat.display == "probability":
        # in ppm below 0.1 %, else in % (tolsim.study.statistics.intervals.format_fraction)
        full = format_fraction(stat.estimate, stat.ci_lower, stat.ci_upper)
        est, _, ci = full.partition(" (")
        return est, ci.rstrip(")") or "95 % CI n/a"
    unit = _unit(stat.display)
    est = _scaled(stat.display, stat.estimate) + (unit if np.isfinite(stat.estimate) else "")
    if stat.kind == "exact":
        return est, "exact"
    lo, hi = (_scaled(stat.display, x) for x in (stat.ci_lower, stat.ci_upper))
    return est, f"95 % CI {lo} to {hi}{unit}"


def format_difference(stat: Statistic, diff: Difference) -> str:
    """'+1.2 pp (−0.3 to +2.7)': a difference with its interval, as the HTML shows it."""
    if stat.display == "probability":
        ends = [abs(x) for x in (diff.estimate, diff.ci_lower, diff.ci_upper)
                if np.isfinite(x)]
        scale, unit = (1e6, "ppm") if ends and max(ends) < 1e-3 else (1e2, "pp")

        def fmt(x):
            return f"{scale * x + 0.0:+.3g}".replace("-", "−") if np.isfinite(x) else "n/a"
    else:
        unit = DISPLAY[stat.display][1]

        def fmt(x):
            return _scaled(stat.display, x, diff=True)
    text = f"{fmt(diff.estimate)}{' ' + unit if unit else ''}"
    if stat.kind == "exact" or diff.ci_lower == diff.ci_upper == diff.estimate:
        return text + " (exact)"
    return f"{text} (95 % CI {fmt(diff.ci_lower)} to {fmt(diff.ci_upper)})"


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
def _run_style(i):
    return dict(color=RUN_COLOURS[i % len(RUN_COLOURS)],
                ls=RUN_LINESTYLES[i % len(RUN_LINESTYLES)])


@styled
def plot_contact_probability(comparison: Comparison):
    """Forest plot: (a) P(contact) of every run with its interval (and the bounds with
    unresolved trains), (b) the difference to the reference with its interval."""
    runs = comparison.runs
    height = 1.6 + 0.55 * len(runs)
    fig, (ax, ax_d) = new_figure(11.0, height, ncols=2, sharey=True)
    stats = [r.statistics.get("contact_probability") for r in runs]
    ends = [x for s in stats if s is not None for x in (s.ci_upper, s.estimate)
            if np.isfinite(x)]
    for r in runs:
        b = r.statistics.get("contact_probability_bound_upper")
        if b is not None and np.isfinite(b.ci_upper):
            ends.append(b.ci_upper)
    ppm = bool(ends) and max(ends) < 1e-3
    scale, unit = (1e6, "ppm") if ppm else (1e2, "%")
    y = np.arange(len(runs))[::-1]
    bounds_label = "bounds with unresolved trains (95 %)"
    for i, (run, stat) in enumerate(zip(runs, stats, strict=True)):
        if stat is None:
            continue
        colour = _run_style(i)["color"]
        lower = run.statistics.get("contact_probability_bound_lower")
        upper = run.statistics.get("contact_probability_bound_upper")
        if lower is not None and upper is not None and upper.estimate > lower.estimate:
            ax.plot([scale * lower.ci_lower, scale * upper.ci_upper], [y[i], y[i]],
                    color="0.75", lw=7, solid_capstyle="butt", zorder=1,
                    label=bounds_label)
            bounds_label = None
        ax.errorbar([scale * stat.estimate], [y[i]],
                    xerr=[[scale * (stat.estimate - stat.ci_lower)],
                          [scale * (stat.ci_upper - stat.estimate)]],
                    fmt="o", color=colour, capsize=4, lw=1.6, ms=6, zorder=3)
    limits = {x for x in (_value(r.ds, "contact_probability_limit") for r in runs)
              if np.isfinite(x) and x > 0}
    for k, limit in enumerate(sorted(limits)):
        ax.axvline(scale * limit, color=LIMIT_COLOUR, ls="--", lw=1.5,
                   label="spec limit" if k == 0 else None)
    ax.set_yticks(y, [r.label for r in runs])
    ax.set_ylim(-0.7, len(runs) - 0.3)
    ax.set_xlabel(f"P(contact within the stroke) [{unit}]")
    ax.set_title("(a) contact probability, 95 % Clopper-Pearson", fontsize=10)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8, framealpha=0.9)

    ax_d.axvline(0.0, color="0.4", lw=1.0)
    d_ends = []
    for i, run in enumerate(runs):
        diff = comparison.differences.get(("contact_probability", run.label))
        if i == 0:
            ax_d.annotate("reference", (0.0, y[i]), ha="center", va="center", fontsize=8.5,
                          color="0.3", bbox=dict(boxstyle="round", fc="white", ec="0.7"))
            continue
        if diff is None or not np.isfinite(diff.estimate):
            continue
        d_ends += [abs(x) for x in (diff.ci_lower, diff.ci_upper) if np.isfinite(x)]
        lo = diff.ci_lower if np.isfinite(diff.ci_lower) else diff.estimate
        hi = diff.ci_upper if np.isfinite(diff.ci_upper) else diff.estimate
        ax_d.errorbar([scale * diff.estimate], [y[i]],
                      xerr=[[scale * (diff.estimate - lo)], [scale * (hi - diff.estimate)]],
                      fmt="D", color=_run_style(i)["color"], capsize=4, lw=1.6, ms=5)
    span = scale * max(d_ends, default=0.0)
    if span > 0:
        ax_d.set_xlim(-1.15 * span, 1.15 * span)
    ax_d.set_xlabel(f"difference to {runs[0].label} [{'ppm' if ppm else 'percentage points'}]")
    ax_d.set_title("(b) difference to the reference, 95 % Newcombe (unpaired)", fontsize=10)
    ax_d.tick_params(labelleft=False)
    return fig


@styled
def plot_velocity_deviation(comparison: Comparison):
    """The epsilon histograms of the runs overlaid (densities), with the spec limits."""
    fig, ax = new_figure(9.0, 4.6)
    lo, hi = np.inf, -np.inf
    widths = []
    for i, run in enumerate(comparison.runs):
        ds = run.ds
        counts = np.asarray(ds["velocity_deviation_histogram"], dtype=float)
        edges = 100.0 * _edges(ds, "velocity_deviation_bin_bounds")
        n = counts.sum()
        if n <= 0:
            continue
        width = np.diff(edges)
        widths.append(float(np.median(width)))
        nz = np.flatnonzero(counts)
        lo, hi = min(lo, edges[nz[0]]), max(hi, edges[nz[-1] + 1])
        st = _run_style(i)
        mean = 100 * _value(ds, "velocity_deviation_mean")
        std = 100 * _value(ds, "velocity_deviation_std")
        ax.stairs(counts / (n * width), edges, color=st["color"], ls=st["ls"], lw=1.6,
                  label=f"{run.label}: mean {mean:+.3f} %, std {std:.3f} %".replace("-", "−"))
    limits = sorted({x for x in (_value(r.ds, "velocity_deviation_limit")
                                 for r in comparison.runs) if np.isfinite(x) and x > 0})
    for limit in limits:
        for s in (-1, 1):
            ax.axvline(100 * s * limit, color=LIMIT_COLOUR, lw=1.6, ls="--",
                       label=(f"spec limit |ε| ≤ {100 * limit:.3g} %" if s > 0 else None))
        lo, hi = min(lo, -120 * limit), max(hi, 120 * limit)
    if np.isfinite(lo) and np.isfinite(hi):
        span = max(hi - lo, 20 * max(widths, default=0.0))
        ax.set_xlim(lo - 0.1 * span, hi + 0.1 * span)
    top = ax.get_ylim()[1]
    ax.set_ylim(0, 1.3 * top)  # room for the legend
    ax.set_xlabel("velocity deviation ε [%]  (v_B = (1 + ε) v/2)")
    ax.set_ylabel("probability density [1/%]")
    ax.set_title("ε of the valid balls, every run")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    return fig


@styled
def plot_survival(comparison: Comparison):
    """The survival curves P(no contact by t) of the runs overlaid, each with a pointwise
    95 % Wilson band."""
    fig, ax = new_figure(9.0, 4.6)
    t_max = 0.0
    for i, run in enumerate(comparison.runs):
        ds = run.ds
        t = np.asarray(ds[ds["survival_probability"].dims[0]], dtype=float)
        s = np.asarray(ds["survival_probability"], dtype=float)
        n = _count(ds, "n_assemblies_valid")
        st = _run_style(i)
        if n > 0:
            k = np.round((1.0 - s) * n)
            band = np.array([wilson_interval(kk, n) for kk in np.clip(k, 0, n)])
            ax.fill_between(t, 1 - band[:, 1], 1 - band[:, 0], step="post",
                            color=st["color"], alpha=0.15, lw=0)
        ax.step(t, s, where="post", color=st["color"], ls=st["ls"], lw=1.8,
                label=f"{run.label} ({n:,} resolved {contact_unit(ds)[1]})")
        t_max = max(t_max, float(t[-1]) if t.size else 0.0)
    ax.set_ylim(-0.02, 1.02)
    if t_max > 0:
        ax.set_xlim(0, t_max)
    ax.set_xlabel("time since the start of the stroke t [s]")
    ax.set_ylabel("survival probability P(no contact by t) [-]")
    ax.set_title("Survival: no ball-to-ball contact yet (bands: 95 % Wilson, pointwise)")
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    return fig


#: Figure name -> (plotting function, caption).
FIGURES = {
    "contact_probability": (plot_contact_probability,
                            "(a) P(contact) of every run with its 95 % Clopper-Pearson "
                            "interval (grey: the bounds when trains are unresolved); (b) the "
                            "difference to the reference with its 95 % Newcombe interval "
                            "(unpaired)."),
    "velocity_deviation": (plot_velocity_deviation,
                           "The ε histograms of the runs as densities, with the spec limits."),
    "survival": (plot_survival, "Survival curves of the time to first contact, with pointwise "
                                "95 % Wilson bands."),
}


# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------
EXTRA_CSS = """
td.cell { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.cell .ci { color: #666; font-size: 0.88em; } td.cell .diff { font-size: 0.9em; }
td.cell .differs { font-weight: bold; } td.key { font-family: monospace; }
"""


def _esc(text) -> str:
    return html.escape(str(text))


def _run_rows(comparison):
    header = ("run", "file", "title", "assemblies", "unresolved", "seed", "block size",
              "sampling", "velocity model", "propagation", "random numbers")
    rows = []
    for i, run in enumerate(comparison.runs):
        a = run.ds.attrs
        if i == 0:
            relation = "reference"
        elif run.shares_random_numbers:
            relation = ("common with the reference (same seed, block size and sampling): "
                        + PAIRING_SHARED)
        else:
            why = [k.replace("_", " ") for k in RANDOM_NUMBER_ATTRIBUTES
                   if str(a.get(k, "?")) != str(comparison.reference.ds.attrs.get(k, "?"))]
            reason = (f"{', '.join(why)} {'differs' if len(why) == 1 else 'differ'}" if why
                      else "seed, block size or sampling not recorded")
            relation = f"independent of the reference ({reason}): {PAIRING_INDEPENDENT}"
        rows.append((run.label, os.path.basename(run.path), a.get("title", ""),
                     f"{_count(run.ds, 'n_assemblies'):,}",
                     f"{_count(run.ds, 'n_assemblies_unresolved'):,}", a.get("seed", "?"),
                     a.get("block_size", "?"), a.get("sampling", "?"),
                     a.get("velocity_model", "?"), a.get("propagation", "?"), relation))
    return header, rows


def _statistics_table(comparison):
    runs = comparison.runs
    parts = ["<table><tr><th>statistic</th>"
             + "".join(f"<th>{_esc(r.label)}{' (reference)' if i == 0 else ''}</th>"
                       for i, r in enumerate(runs)) + "</tr>"]
    for name in comparison.names:
        first = comparison.statistic(name)
        unit = "" if first.display == "probability" else _unit(first.display).strip()
        label = first.description + (f" [{unit}]" if unit else "")
        cells = []
        for run in runs:
            stat = run.statistics.get(name)
            if stat is None:
                cells.append("<td class='cell'>—</td>")
                continue
            est, ci = format_value(stat)
            cell = f"{_esc(est)}<br><span class='ci'>{_esc(ci)}</span>"
            diff = comparison.differences.get((name, run.label))
            if diff is not None:
                cls = "diff differs" if diff.excludes_zero else "diff"
                cell += f"<br><span class='{cls}'>Δ {_esc(format_difference(stat, diff))}</span>"
            cells.append(f"<td class='cell'>{cell}</td>")
        parts.append(f"<tr><th>{_esc(label)}<br><code class='muted'>{_esc(name)}</code></th>"
                     + "".join(cells) + "</tr>")
    parts.append("</table>")
    return parts


def _methods_table(comparison):
    rows, seen = [], set()
    for name in comparison.names:
        stat = comparison.statistic(name)
        family = stat.family or stat.name
        if family in seen:
            continue
        seen.add(family)
        rows.append((family, stat.interval, DIFFERENCE_METHODS[stat.kind][1]))
    return rows


def _html(comparison: Comparison, pngs: dict) -> str:
    runs = comparison.runs
    ref = comparison.reference
    shared = [r.label for r in runs[1:] if r.shares_random_numbers]
    independent = [r.label for r in runs[1:] if not r.shares_random_numbers]
    units = {contact_unit(r.ds)[0] for r in runs}
    title = f"Comparison of {len(runs)} tolsim studies"
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{_esc(title)}</title><style>{CSS}{EXTRA_CSS}</style></head><body>",
        f"<h1>{_esc(title)}</h1>",
        f"<p class='muted'>Made by tolsim {__version__} on "
        f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')} from "
        + ", ".join(f"<code>{_esc(os.path.basename(r.path))}</code>" for r in runs)
        + f". The reference is the first run, <b>{_esc(ref.label)}</b>: every difference Δ "
        "is a run minus the reference. The same numbers, one row per statistic and run: "
        f"<code>{CSV_NAME}</code>.</p>",
        "<h2>1. Runs</h2>",
    ]
    header, rows = _run_rows(comparison)
    parts.append("<table><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in header) + "</tr>")
    parts += ["<tr>" + "".join(f"<td>{_esc(c)}</td>" for c in row) + "</tr>" for row in rows]
    parts.append("</table>")
    if len(units) > 1:
        per = {u: [r.label for r in runs if contact_unit(r.ds)[0] == u] for u in sorted(units)}
        parts.append("<p class='verdict bad'>P(contact) is per train in "
                     f"{_esc(', '.join(per.get('train', [])))} and per assembly (a carriage "
                     f"with several trains: contact in any of them) in "
                     f"{_esc(', '.join(per.get('assembly', [])))}: these probabilities are "
                     "not directly comparable.</p>")

    parts.append("<h2>2. Paired or unpaired differences</h2>")
    text = ("The differences are <b>unpaired</b>: each run's estimate is taken as independent "
            "of the reference's. A paired interval needs per-assembly outcomes (for "
            "P(contact), how many assemblies have contact in both runs and in one only), and "
            "the result files hold aggregates only; recomputing them from the stored configs "
            "would cost as much as the runs. ")
    if shared:
        text += (f"{_esc(', '.join(shared))} share{'s' if len(shared) == 1 else ''} the "
                 "reference's seed, block size and sampling, so "
                 f"{'its' if len(shared) == 1 else 'their'} assemblies come from common "
                 "random numbers and correspond one to one to the reference's: the outcomes "
                 "are correlated, and the unpaired interval, which leaves out the covariance, "
                 "is <b>conservative</b> (wider than a paired one) when that correlation is "
                 "positive, as it is when a change moves the outcome the same way in every "
                 "assembly. Label: <i>" + PAIRING_SHARED + "</i>. ")
    if independent:
        text += (f"{_esc(', '.join(independent))} "
                 f"{'is' if len(independent) == 1 else 'are'} independent of the reference "
                 "(different random numbers): there the unpaired interval is the right one. "
                 "Label: <i>" + PAIRING_INDEPENDENT + "</i>. ")
    text += ("P(contact) and its bounds: Newcombe's hybrid score interval (Newcombe 1998, "
             "Stat. Med. 17:873, method 10). Means and standard deviations: Welch's interval "
             "with the Welch-Satterthwaite degrees of freedom. Quantiles, the fraction out of "
             "spec and Cpk: the MOVER of Zou &amp; Donner (2008, Stat. Med. 27:1693) from the "
             "two runs' own intervals. A Δ in bold has an interval that excludes 0.")
    parts.append(f"<p>{text}</p>")

    parts.append("<h2>3. Config keys that differ</h2>")
    if comparison.unreadable_configs:
        parts.append("<p class='bad'>Config text not readable as TOML in "
                     f"{_esc(', '.join(comparison.unreadable_configs))}: its keys are not "
                     "compared.</p>")
    if comparison.config:
        parts.append("<p class='muted'>From the config text stored in each file (the "
                     "effective config: command-line overrides included); — : the run's "
                     "config does not set the key (the model default applies).</p>")
        parts.append("<table><tr><th>key</th>" + "".join(f"<th>{_esc(r.label)}</th>"
                                                          for r in runs) + "</tr>")
        for row in comparison.config:
            parts.append(f"<tr><td class='key'>{_esc(row.key)}</td>"
                         + "".join(f"<td><code>{_esc(t)}</code></td>" for t in row.texts)
                         + "</tr>")
        parts.append("</table>")
    else:
        parts.append("<p>The configs stored in the files set the same keys to the same "
                     "values.</p>")

    parts.append("<h2>4. Key statistics</h2>")
    parts.append("<p class='muted'>Each cell: the estimate, its 95 % interval, and (Δ) the "
                 "difference to the reference with its own 95 % interval. pp: percentage "
                 "points. n/a: not available (an interval end beyond the data, or no contact "
                 "at all).</p>")
    parts += _statistics_table(comparison)
    found = {k: v for k, v in comparison.bound_differences.items() if v is not None}
    if found:
        def pp(x):
            return f"{100 * x + 0.0:+.3g}".replace("-", "−") if np.isfinite(x) else "n/a"

        parts.append("<p>With unresolved trains, P(contact) is known only within its bounds, "
                     "and the difference to the reference only within [lower bound of the "
                     "run − upper bound of the reference, upper bound of the run − lower "
                     "bound of the reference]: " + "; ".join(
                         f"{_esc(label)}: {pp(lo)} to {pp(hi)} pp (95 % interval {pp(cl)} "
                         f"to {pp(ch)} pp)" for label, (lo, hi, cl, ch) in found.items())
                     + ".</p>")
    parts.append("<h3>Intervals</h3><table><tr><th>statistic</th><th>interval of a run</th>"
                 "<th>interval of the difference</th></tr>")
    parts += [f"<tr><td><code>{_esc(g)}</code></td><td>{_esc(a)}</td><td>{_esc(b)}</td></tr>"
              for g, a, b in _methods_table(comparison)]
    parts.append("</table>")

    parts.append("<h2>5. Distributions</h2>")
    for name, (_, caption) in FIGURES.items():
        if name in pngs:
            parts.append(f"<figure><img alt='{_esc(caption)}' src='{data_uri(pngs[name])}'>"
                         f"<figcaption class='muted'>{_esc(caption)}</figcaption></figure>")

    parts.append("<h2>Provenance</h2><table><tr><th>run</th><th>source</th><th>history</th>"
                 "</tr>")
    for run in runs:
        a = run.ds.attrs
        parts.append(f"<tr><td>{_esc(run.label)}</td><td>{_esc(a.get('source', '?'))}</td>"
                     f"<td>{_esc(a.get('history', '?'))}</td></tr>")
    parts.append("</table></body></html>")
    return "\n".join(parts)


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------
@dataclass
class CompareOutputs:
    """Files written by :func:`compare_runs`, and the comparison shown."""

    folder: str
    html: str = ""
    csv: str = ""
    figures: dict = field(default_factory=dict)
    comparison: Comparison | None = None


def read_runs(paths) -> list:
    """Read result files (:func:`tolsim.io.netcdf.read_result`), or raise
    :class:`NotAResult` with a one-line reason naming the first bad file. The file of a
    what-if sweep (:func:`tolsim.io.sweep.is_sweep`) is refused: its points are compared
    by its own report (:mod:`tolsim.reports.sweep`)."""
    from tolsim.io.netcdf import read_result
    from tolsim.io.sweep import is_sweep

    out = []
    for path in paths:
        path = os.fspath(path)
        if not os.path.exists(path):
            raise NotAResult(f"{path}: no such file")
        if os.path.isdir(path):
            raise NotAResult(f"{path}: is a folder, not a result file")
        try:
            ds = read_result(path)
        except ValueError as exc:
            raise NotAResult(" ".join(str(exc).split())) from None
        if is_sweep(ds):  # several studies along sweep dimensions (issue 14)
            dims = str(ds.attrs.get("sweep_dimensions", "")).split()
            points = int(np.prod([ds.sizes[d] for d in dims if d in ds.sizes]))
            raise NotAResult(f"{path} is a sweep of {points} points "
                             f"({ds.attrs.get('sweep_keys', '?')}): tolsim compare puts "
                             "single studies side by side; use 'tolsim report "
                             f"{path}' for a sweep (its points in one table and curve)")
        out.append(ds)
    return out


def _write_files(folder, files: dict) -> dict:
    """Write {name: bytes} into ``folder`` (created if missing), each through a temporary
    file and a rename; on an error, remove what was written (and the folder if made here)."""
    created = not os.path.isdir(folder)
    os.makedirs(folder, exist_ok=True)
    written = {}
    try:
        for name, data in files.items():
            path = os.path.join(folder, name)
            tmp = f"{path}.tmp"
            with open(tmp, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
            written[name] = path
    except BaseException:
        for path in [*written.values(), *(os.path.join(folder, f"{n}.tmp") for n in files)]:
            if os.path.exists(path):
                os.unlink(path)
        if created and not os.listdir(folder):
            os.rmdir(folder)
        raise
    return written


def compare_runs(paths, folder, *, progress=None,
                 confidence_level=CONFIDENCE_LEVEL) -> CompareOutputs:
    """Write ``compare.html``, ``compare.csv`` and the PNGs of two or more result files.

    The first file is the reference. Every file is read and every output made in memory
    before anything is written, so a bad input leaves no folder behind.

    Parameters
    ----------
    paths : sequence of str or path
        At least two result files of ``tolsim run``.
    folder : str or path
        Output folder (created if missing).
    progress : callable, optional
        Called with a short message before each step.
    confidence_level : float

    Returns
    -------
    CompareOutputs

    Raises
    ------
    NotAResult
        If a file is missing, not a tolsim result, or the file of a sweep.
    ValueError
        If fewer than two files are given.
    """
    say = progress or (lambda msg: None)
    paths = [os.fspath(p) for p in paths]
    if len(paths) < 2:
        raise ValueError(f"need at least two result files to compare, got {len(paths)}")
    datasets = read_runs(paths)
    say(f"read {len(datasets)} result files")
    comparison = compare_datasets(datasets, run_labels(paths), paths, confidence_level)
    say("figures")
    pngs = {name: render_png(plot(comparison)) for name, (plot, _) in FIGURES.items()}
    say(f"{HTML_NAME} and {CSV_NAME}")
    files = {HTML_NAME: _html(comparison, pngs).encode("utf-8"),
             CSV_NAME: csv_text(comparison).encode("utf-8"),
             **{f"{name}.png": png for name, png in pngs.items()}}
    folder = os.fspath(folder)
    written = _write_files(folder, files)
    return CompareOutputs(folder, written[HTML_NAME], written[CSV_NAME],
                          {name: written[f"{name}.png"] for name in pngs}, comparison)
