"""Quality-engineering figures of a study: fraction out of spec and process capability of epsilon.

Pure NumPy/SciPy; works on counts and on the streamed histogram of a result file.

Definitions
-----------
* **Spec limit on epsilon.** A two-sided symmetric limit |epsilon| <= L (LSL = -L, USL = +L):
  a ball whose speed deviates by more than L from v/2 is out of spec.
* **Fraction out of spec** p = k / n over the valid balls, with a two-sided confidence
  interval: Wilson's score interval ([Wilson1927]) by default, or the exact Clopper-Pearson
  interval ([ClopperPearson1934]). Shown in ppm (parts per million, 1e6 p) when p < 1e-3.
  From a histogram, k is known exactly only when L falls on bin edges; otherwise the balls of
  the bins that straddle +-L are split linearly and the interval is widened to cover both
  extremes (all of them in, all of them out), so it stays conservative.
* **Capability index** (normal theory, ISO 22514-2 / [Montgomery2009] Sec. 8.2)::

      Cp  = (USL - LSL) / (6 sigma) = L / (3 sigma)
      Cpk = min(USL - mu, mu - LSL) / (3 sigma) = (L - |mu|) / (3 sigma)

  with mu, sigma the mean and standard deviation of epsilon. Cpk = 1.33 means the nearer
  limit is 4 sigma away (63 ppm out of spec for a normal epsilon). Its confidence interval
  is Bissell's ([Bissell1990]): Cpk +- z sqrt(1/(9n) + Cpk^2 / (2(n - 1))).
  Epsilon need not be normal (it is a ratio of loads and angle sums), so the percentile
  (ISO 22514-2 "M3/l" method) index is given beside it, which uses the 0.135 % and 99.865 %
  quantiles q_lo, q_hi and the median m in place of mu -+ 3 sigma::

      Cpk_percentile = min((USL - m) / (q_hi - m), (m - LSL) / (m - q_lo))

  When the two differ, the percentile index is the one to believe.
* **Independent balls.** Both intervals above take the balls as independent. The balls of
  one assembly are correlated (they share the rail and carriage errors), which makes them
  too narrow; :func:`tolsim.study.statistics.intervals.cluster_proportion` and
  :func:`tolsim.study.statistics.intervals.cluster_capability` give the intervals with the assembly
  as the sampling unit (cluster ratio estimator, delta method, Korn-Graubard effective
  sample size).
* **Spec limit on the contact probability** P_max: the study meets it with 95 % confidence
  when the upper end of the interval of P(contact) is below P_max.

References
----------
.. [Wilson1927] E. B. Wilson, "Probable inference, the law of succession, and statistical
   inference", J. Am. Stat. Assoc. 22 (1927) 209-212.
.. [ClopperPearson1934] C. J. Clopper, E. S. Pearson, "The use of confidence or fiducial
   limits illustrated in the case of the binomial", Biometrika 26 (1934) 404-413.
.. [Bissell1990] A. F. Bissell, "How reliable is your capability index?", Appl. Stat. 39
   (1990) 331-340.
.. [Montgomery2009] D. C. Montgomery, Introduction to Statistical Quality Control, 6th ed.,
   Wiley, 2009.
"""

import numpy as np
from scipy.special import ndtr, ndtri

# the result types, the binomial intervals and the histogram quantiles live in
# tolsim.study.statistics.intervals (no tolsim imports, so tolsim.study.statistics.accumulator can
# use them too);
# re-exported here
from tolsim.study.statistics.intervals import (  # noqa: F401
    PPM_BELOW,
    Capability,
    ClusterMoments,
    Proportion,
    check_counts,
    clopper_pearson_interval,
    cluster_capability,
    cluster_proportion,
    format_fraction,
    histogram_quantiles,
    wilson_interval,
)

#: Quantile levels of the percentile capability index (mu -+ 3 sigma of a normal) [-].
PERCENTILE_LEVELS = (ndtr(-3.0), 0.5, ndtr(3.0))
INTERVALS = ("wilson", "clopper-pearson")


_INTERVAL_FUNCTIONS = {"wilson": wilson_interval, "clopper-pearson": clopper_pearson_interval}


def proportion(successes, trials, confidence_level=0.95, method="wilson") -> Proportion:
    """A proportion k / n with its confidence interval (``wilson`` or ``clopper-pearson``)."""
    try:
        interval = _INTERVAL_FUNCTIONS[method]
    except KeyError:
        raise ValueError(f"method = {method!r}; choose one of {INTERVALS}") from None
    lo, hi = interval(successes, trials, confidence_level)
    frac = float(successes) / trials if trials else float("nan")
    return Proportion(frac, lo, hi, float(successes), int(trials), confidence_level, method)


def out_of_spec_from_histogram(counts, edges, limit, underflow=0, overflow=0,
                               confidence_level=0.95, method="wilson") -> Proportion:
    """Fraction of values with |x| > ``limit`` from a fixed-bin histogram.

    Parameters
    ----------
    counts : array_like of int, shape (bins,)
    edges : array_like, shape (bins + 1,)
        Increasing bin edges.
    limit : float
        L > 0; out of spec means x < -L or x > L.
    underflow, overflow : int
        Values below ``edges[0]`` and above ``edges[-1]``.
    confidence_level : float
    method : str
        Interval for the count: see :func:`proportion`.

    Returns
    -------
    Proportion
        ``successes`` is the count beyond +-L, with the bins that straddle +-L split linearly;
        the interval runs from the lower end for "none of the straddling bins out" to the
        upper end for "all of them out" (exact when +-L fall on edges).
    """
    counts = np.asarray(counts, dtype=float)
    edges = np.asarray(edges, dtype=float)
    if edges.shape != (counts.size + 1,) or np.any(np.diff(edges) <= 0):
        raise ValueError("edges must be increasing with one more entry than counts")
    if not (np.isfinite(limit) and limit > 0):
        raise ValueError(f"limit = {limit!r} must be > 0")
    lo_e, hi_e = edges[:-1], edges[1:]
    full = (hi_e <= -limit) | (lo_e >= limit)
    # share of a bin beyond the limits (linear inside the bin)
    share = np.clip((-limit - lo_e) / (hi_e - lo_e), 0, 1) + np.clip(
        (hi_e - limit) / (hi_e - lo_e), 0, 1)
    # a limit within round-off of a bin edge is on the edge (edges from linspace)
    share = np.where(share < 1e-9, 0.0, np.where(share > 1 - 1e-9, 1.0, share))
    full |= share >= 1.0
    partial = ~full & (share > 0)
    certain = float(counts[full].sum())
    straddling = float(counts[partial].sum())
    k = certain + float((counts[partial] * share[partial]).sum())
    # values outside the histogram range are beyond +-L when the range reaches +-L;
    # otherwise unknown (counted as straddling, and as out in the estimate)
    for extra, beyond in ((float(underflow), edges[0] <= -limit),
                          (float(overflow), edges[-1] >= limit)):
        certain += extra if beyond else 0.0
        straddling += 0.0 if beyond else extra
        k += extra
    n = int(counts.sum() + underflow + overflow)
    base = proportion(k, n, confidence_level, method)
    if straddling == 0 or n == 0:
        return base
    lo = proportion(certain, n, confidence_level, method).lower
    hi = proportion(certain + straddling, n, confidence_level, method).upper
    return Proportion(base.fraction, lo, hi, k, n, confidence_level,
                      f"{method}, widened over {int(straddling)} values in the bins at the limit")


def capability(mean, std, n, limit, quantiles=None, confidence_level=0.95) -> Capability:
    """Cp, Cpk (with Bissell's interval) and the percentile Cpk of epsilon for |eps| <= L.

    Parameters
    ----------
    mean, std : float
        mu and sigma of epsilon [-].
    n : int
        Number of values behind mu and sigma.
    limit : float
        L > 0 [-].
    quantiles : (q_lo, median, q_hi), optional
        epsilon at :data:`PERCENTILE_LEVELS` (0.135 %, 50 %, 99.865 %) [-].
    confidence_level : float

    Returns
    -------
    Capability
    """
    if not (np.isfinite(limit) and limit > 0):
        raise ValueError(f"limit = {limit!r} must be > 0")
    if not (np.isfinite(std) and std >= 0):
        raise ValueError(f"std = {std!r} must be finite and >= 0")
    if not 0 < confidence_level < 1:
        raise ValueError(f"confidence_level = {confidence_level!r} must be in (0, 1)")
    with np.errstate(divide="ignore", invalid="ignore"):
        cp = limit / (3.0 * std) if std > 0 else np.inf
        cpk = (limit - abs(mean)) / (3.0 * std) if std > 0 else (
            np.inf if abs(mean) < limit else -np.inf)
    z = float(ndtri(0.5 + confidence_level / 2))
    if n > 1 and np.isfinite(cpk):
        half = z * np.sqrt(1.0 / (9.0 * n) + cpk * cpk / (2.0 * (n - 1)))
        lo, hi = cpk - half, cpk + half
    else:
        lo = hi = float("nan")
    pct = float("nan")
    if quantiles is not None:
        q_lo, med, q_hi = (float(q) for q in quantiles)
        if np.all(np.isfinite([q_lo, med, q_hi])) and q_hi > med > q_lo:
            pct = min((limit - med) / (q_hi - med), (med + limit) / (med - q_lo))
    normal = float(ndtr(-(limit - mean) / std) + ndtr(-(limit + mean) / std)) if std > 0 \
        else float(abs(mean) > limit)
    return Capability(float(limit), float(cp), float(cpk), float(lo), float(hi), pct, normal,
                      int(n))


def contact_probability_verdict(probability, upper, limit) -> str:
    """One sentence: does P(contact) meet the limit P_max with 95 % confidence?"""
    if not (limit is not None and np.isfinite(limit) and limit > 0):
        return "no limit on the contact probability"
    if not np.isfinite(probability):
        return "no valid trains: contact probability unknown"
    lim = format_fraction(limit)
    if upper < limit:
        return f"meets P(contact) <= {lim}: the 95 % upper bound is {format_fraction(upper)}"
    if probability > limit:
        return f"fails P(contact) <= {lim}: the estimate is {format_fraction(probability)}"
    return (f"inconclusive against P(contact) <= {lim}: the estimate is "
            f"{format_fraction(probability)} but the 95 % upper bound is "
            f"{format_fraction(upper)}; run more samples")


def dataset_quality(ds) -> dict:
    """The quality variables (:data:`tolsim.io.schema.quality.QUALITY_VARIABLES`) of a result
    Dataset (needs no xarray: any mapping of name -> array-like with the result-file variables
    works).

    Balls of one assembly share its rail and carriage errors and are correlated, so the
    intervals treat the assembly as the sampling unit: the fraction out of spec is the ratio
    estimator over assemblies with Korn & Graubard's effective sample size
    (:func:`tolsim.study.statistics.intervals.cluster_proportion`), Cp and Cpk have delta-method
    intervals over assemblies (:func:`~tolsim.study.statistics.intervals.cluster_capability`), from
    the
    per-assembly moments the file stores. A file without them (schema 1) gets the
    independent-ball intervals of the histogram (Wilson, Bissell), which are too narrow for
    correlated balls.

    Returns
    -------
    dict
        name -> float, empty when the file has no limit on |epsilon|; plus the
        :class:`Proportion` and :class:`Capability` under ``"_proportion"`` and
        ``"_capability"``.
    """
    limit = float(np.asarray(ds["velocity_deviation_limit"]))
    if not (np.isfinite(limit) and limit > 0):
        return {}
    counts = np.asarray(ds["velocity_deviation_histogram"])
    bounds = np.asarray(ds["velocity_deviation_bin_bounds"])
    edges = np.concatenate([bounds[:, 0], bounds[-1:, 1]])
    under = int(np.asarray(ds["velocity_deviation_underflow"]))
    over = int(np.asarray(ds["velocity_deviation_overflow"]))
    quants = histogram_quantiles(counts, edges, PERCENTILE_LEVELS, under, over)
    n = int(np.asarray(ds["n_balls_valid"]))
    if "assembly_total_mean" in ds:
        moments = ClusterMoments(int(np.asarray(ds["assembly_count"])),
                                 np.asarray(ds["assembly_total_mean"], dtype=float),
                                 np.asarray(ds["assembly_total_comoment"], dtype=float))
        prop = cluster_proportion(moments)
        cap = cluster_capability(moments, limit, quantiles=quants) if n > 1 else None
    else:
        prop = out_of_spec_from_histogram(counts, edges, limit, under, over)
        std = float(np.asarray(ds["velocity_deviation_std"]))
        cap = capability(float(np.asarray(ds["velocity_deviation_mean"])), std, n, limit,
                         quants) if n > 1 and np.isfinite(std) else None
    out = {
        "velocity_deviation_out_of_spec_fraction": prop.fraction,
        "velocity_deviation_out_of_spec_ci_lower": prop.lower,
        "velocity_deviation_out_of_spec_ci_upper": prop.upper,
        "_proportion": prop,
        "_capability": cap,
    }
    if cap is not None:
        out.update({
            "velocity_deviation_cp": cap.cp,
            "velocity_deviation_cpk": cap.cpk,
            "velocity_deviation_cpk_ci_lower": cap.cpk_lower,
            "velocity_deviation_cpk_ci_upper": cap.cpk_upper,
            "velocity_deviation_cpk_percentile": cap.cpk_percentile,
        })
    return out
