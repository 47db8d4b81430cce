"""The key statistics of a run with their intervals, and the difference of each to the
reference run with its own (unpaired) interval (``tolsim compare``)."""

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import t as t_distribution

from tolsim.reports.result_view import bin_edges, integer, number, quantile_index
from tolsim.reports.verdict import contact_unit, tracks_of
from tolsim.study.analyses.rare_events import ESTIMATOR_TITLES
from tolsim.study.statistics.intervals import (
    ClusterMoments,
    clopper_pearson_interval,
    cluster_mean_and_std,
    histogram_quantile_interval,
    mover_difference,
    newcombe_difference,
    welch_difference,
)

#: Quantile levels of epsilon compared [-].
VELOCITY_DEVIATION_LEVELS = (0.001, 0.01, 0.5, 0.99, 0.999)
#: Quantile levels of the time to first contact (given contact) compared [-].
TIME_TO_CONTACT_LEVELS = (0.1, 0.5, 0.9)
#: Confidence level of every interval [-].
CONFIDENCE_LEVEL = 0.95
#: What the differences are, by the relation of a run's random numbers to the reference's.
PAIRING_SHARED = "unpaired, conservative for runs with common random numbers"
PAIRING_INDEPENDENT = "unpaired"
#: Attributes that must agree for two runs to draw from common random numbers.
RANDOM_NUMBER_ATTRIBUTES = ("seed", "block_size", "sampling")


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


def _level_name(level) -> str:
    return f"{float(level):g}"


def _moments(ds):
    if "assembly_total_mean" not in ds.variables:
        return None
    return ClusterMoments(integer(ds, "assembly_count"),
                          np.asarray(ds["assembly_total_mean"], dtype=float),
                          np.asarray(ds["assembly_total_comoment"], dtype=float))


def _t_interval(estimate, se, df, confidence_level):
    if not (np.isfinite(se) and df >= 1):
        return float("nan"), float("nan")
    t = float(t_distribution.ppf(0.5 + confidence_level / 2, df))
    return estimate - t * se, estimate + t * se


def contact_estimator(ds) -> tuple:
    """(estimator, interval) of the file's P(contact), from the ``estimator`` and ``interval``
    attributes of ``contact_probability``: ``("monte_carlo", "Clopper-Pearson")`` for a plain
    run (and a file without them), else the rare-event estimator that made the number
    (:mod:`tolsim.io.schema.rare_events`) and its interval."""
    attrs = (getattr(ds["contact_probability"], "attrs", {})
             if "contact_probability" in ds.variables else {})
    return (str(attrs.get("estimator", "monte_carlo")),
            str(attrs.get("interval", "Clopper-Pearson")))


def _contact_statistics(ds, bounds):
    one, many = contact_unit(ds)
    n_asm, k, u = (integer(ds, n) for n in ("n_assemblies", "n_contact",
                                             "n_assemblies_unresolved"))
    estimator, interval = contact_estimator(ds)
    by, kind = "", "proportion"
    if estimator != "monte_carlo":  # the difference from this estimate, not the plain counts
        title = ESTIMATOR_TITLES.get(estimator, estimator)
        by, kind, interval = f" by {title}", "mover", f"{title}: {interval}"
    out = [Statistic(
        "contact_probability", f"P(contact within the stroke) per {one}{by}, over the {many} "
        "whose outcome is known", "1", number(ds, "contact_probability"),
        number(ds, "contact_probability_ci_lower"), number(ds, "contact_probability_ci_upper"),
        interval, kind, "probability", successes=k, trials=n_asm - u)]
    if bounds:
        for name, hits, what in (("lower", k, "unresolved counted as no contact"),
                                 ("upper", k + u, "unresolved counted as contact")):
            lo, hi = (clopper_pearson_interval(hits, n_asm) if n_asm
                      else (float("nan"), float("nan")))
            out.append(Statistic(
                f"contact_probability_bound_{name}",
                f"{name} bound of P(contact) over all {many} ({what})", "1",
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
        estimate = number(ds, f"velocity_deviation_{name}")
        lo, hi = _t_interval(estimate, se, a - 1, confidence_level)
        out.append(Statistic(f"velocity_deviation_{name}", f"{what} of epsilon over the "
                             "valid balls", "1", estimate, lo, hi, method, "welch",
                             "epsilon" if name == "mean" else "epsilon_spread",
                             standard_error=se, df=float(a - 1)))
    counts = np.asarray(ds["velocity_deviation_histogram"])
    edges = bin_edges(ds, "velocity_deviation_bin_bounds")
    under, over = (integer(ds, f"velocity_deviation_{x}") for x in ("underflow", "overflow"))
    if moments is not None and a > 0:
        n_bar = float(moments.mean[0])
        sum_n2 = float(moments.comoment[0, 0]) + a * n_bar * n_bar
        n_eff = (a * n_bar) ** 2 / sum_n2 if sum_n2 > 0 else 0.0
    else:
        n_eff = 0.0
    q = np.asarray(ds["velocity_deviation_quantile"], dtype=float)
    for level in VELOCITY_DEVIATION_LEVELS:
        k = quantile_index(ds, level)
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
    if np.isfinite(number(ds, "velocity_deviation_out_of_spec_fraction")):
        out.append(Statistic(
            "velocity_deviation_out_of_spec_fraction",
            "fraction of valid balls with |epsilon| above the spec limit", "1",
            number(ds, "velocity_deviation_out_of_spec_fraction"),
            number(ds, "velocity_deviation_out_of_spec_ci_lower"),
            number(ds, "velocity_deviation_out_of_spec_ci_upper"),
            "Korn-Graubard effective sample size, assemblies as the sampling unit", "mover",
            "probability"))
    if np.isfinite(number(ds, "velocity_deviation_cpk")):
        out.append(Statistic(
            "velocity_deviation_cpk", "process capability Cpk = (L - |mu|) / (3 sigma) of "
            "epsilon", "1", number(ds, "velocity_deviation_cpk"),
            number(ds, "velocity_deviation_cpk_ci_lower"),
            number(ds, "velocity_deviation_cpk_ci_upper"), "delta method over assemblies",
            "mover", "index"))
    return out


def _time_statistics(ds, confidence_level):
    out = []
    counts = np.asarray(ds["time_to_contact_histogram"])
    edges = bin_edges(ds, "time_bin_bounds")
    contacts = float(counts.sum())  # one first contact per assembly with contact
    q = np.asarray(ds["time_to_contact_quantile"], dtype=float)
    for level in TIME_TO_CONTACT_LEVELS:
        k = quantile_index(ds, level)
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
    solved = integer(ds, "n_assemblies") - integer(ds, "n_assemblies_carriage_failed")
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
    """The key statistics of a result with their intervals (Notes).

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

    Notes
    -----
    **Statistics and their intervals (95 %).**

    * **P(contact)** per train (per assembly in a carriage study): k of the n trains whose outcome
      is known, with the file's Clopper-Pearson interval; or, in a run with a rare-event
      estimator, that estimator's number and interval (labelled by its method). When a run
      has unresolved trains, also the partial-identification bounds k/N and (k + u)/N over all
      N trains (from the plain run's counts), each with its Clopper-Pearson interval.
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

    References
    ----------
    .. [Woodruff1952] R. S. Woodruff, "Confidence intervals for medians and other position
       measures", J. Am. Stat. Assoc. 47 (1952) 635-646.
    .. [Cochran1977] W. G. Cochran, Sampling Techniques, 3rd ed., Wiley, 1977.
    """
    if bounds is None:
        bounds = integer(ds, "n_assemblies_unresolved") > 0
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

    Notes
    -----
    **Differences to the reference: paired or unpaired?**
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
      from the Wilson intervals of the two proportions
      (:func:`~tolsim.study.statistics.intervals.newcombe_difference`). A P(contact) made by
      a rare-event estimator (its ``estimator`` attribute, :func:`contact_estimator`) is not
      k / n of the plain run: its difference is the MOVER from the two runs' own intervals.
    * means and standard deviations (epsilon, carriage stiffness): Welch's interval with the
      Welch-Satterthwaite degrees of freedom ([Welch1947], [Satterthwaite1946];
      :func:`~tolsim.study.statistics.intervals.welch_difference`).
    * quantiles, fraction out of spec, Cpk: the MOVER ([ZouDonner2008]; "method of variance
      estimates recovery", :func:`~tolsim.study.statistics.intervals.mover_difference`) from the
      two runs' own intervals, of which Newcombe's method 10 is the case with Wilson intervals;
      with symmetric intervals it is the Wald interval of the difference.
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
    .. [Law2015] A. M. Law, Simulation Modeling and Analysis, 5th ed., McGraw-Hill, 2015.
    """
    kind = run.kind
    if run.name == reference.name and {run.kind, reference.kind} == {"proportion", "mover"}:
        kind = "mover"  # a rare-event estimate against a plain run's k / n: from the intervals
    elif run.name != reference.name or run.kind != reference.kind:
        raise ValueError(f"cannot take the difference of {run.name!r} ({run.kind}) and "
                         f"{reference.name!r} ({reference.kind})")
    function, method = DIFFERENCE_METHODS[kind]
    d, lo, hi = function(run, reference, confidence_level)
    if kind != "exact":
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
