"""The verdict of a study against its spec limits: pass, fail or undecided at the stated
confidence, or "no spec limit given".

Each check compares a 95 % interval with a limit (two-sided intervals, so each one-sided
statement below holds with at least 97.5 % confidence):

* **P(contact) per train <= P_max** (``study.contact_probability_limit``). The interval is
  the one that covers the partial-identification bounds over all trains (unresolved trains
  counted as no contact / as contact: ``contact_probability_bounds_ci_lower`` /
  ``_ci_upper``), so an unresolved train can never turn a fail into a pass; files without
  the bounds use the Clopper-Pearson interval over the resolved trains. Pass when its upper
  end is at most P_max, fail when its lower end is above P_max, undecided otherwise.
* **fraction of balls with |epsilon| > L <= p_max**: the fraction out of spec and its
  interval with the assembly as the sampling unit (:func:`tolsim.study.statistics.quality.
  dataset_quality`) against an allowed fraction p_max (``study.out_of_spec_limit_percent``
  or ``_ppm``, stored as ``velocity_deviation_out_of_spec_limit``; or the
  ``out_of_spec_limit`` argument of :func:`study_verdict`).
* **Cpk >= Cpk_min**: Cpk with its interval (delta method over assemblies) against a
  required minimum (``study.cpk_minimum``, stored as ``velocity_deviation_cpk_minimum``; or
  the ``cpk_minimum`` argument). Pass when the lower end is at least Cpk_min, fail when the
  upper end is below it.
* **P(friction increase > L) <= p_max**, in a study with ``[contact]`` and a limit L on the
  increase of the carriage friction force (``contact.friction_increase_limit_N``, stored as
  ``friction_increase_limit``; :mod:`tolsim.study.pipeline.track_friction`): the row is there
  whenever L is
  set. The estimate is P(increase > L) per assembly (its worst track) with its
  Clopper-Pearson interval; with unresolved assemblies the interval that covers the
  partial-identification bounds (Clopper-Pearson lower end of k of N, upper end of k + u of
  N), as for P(contact). The config has no key for the allowed fraction p_max, so, as for
  the fraction of balls out of spec without an allowed fraction, the row shows the estimate
  without a verdict unless p_max is given (the ``friction_exceedance_limit`` argument of
  :func:`study_verdict`).

A check whose estimate comes from a rare-event estimator that does not back it (status
``diagnostic_failed`` or ``estimators_disagree``, or no number) is *undecided*, never pass or
fail (:func:`estimator_flag`).

The overall verdict is *fail* if any check fails, else *undecided* if any is undecided, else
*pass* if any passes, else "no spec limit given".

**One verdict rule**: the verdict is decided on the 95 % intervals as computed, and every
interval end is displayed with as many digits as it takes for the displayed numbers to give
the same verdict (:func:`decisive_ends`): a Cpk interval ending at 1.32969 against Cpk ≥ 1.33
shows "1.3297" (a FAIL), one ending at 1.33032 shows "1.3303" (UNDECIDED), never both
"1.330": an end is never shown equal to the limit unless it is.

In a study with a ``[carriage]`` (a ``track`` dimension in the file) an assembly is a carriage
with one train per track, and P(contact), its bounds and the unresolved count are per
assembly (contact in any of its trains): the wording says "assemblies" there
(:func:`contact_unit`).
"""

from dataclasses import dataclass

import numpy as np

from tolsim.reports.result_view import number
from tolsim.study.statistics.intervals import clopper_pearson_interval, format_fraction
from tolsim.study.statistics.quality import dataset_quality

PASS, FAIL, UNDECIDED, NO_LIMIT = "pass", "fail", "undecided", "no spec limit given"
#: How a status is shown in the table of checks.
STATUS_LABELS = {PASS: "PASS", FAIL: "FAIL", UNDECIDED: "UNDECIDED", NO_LIMIT: "no verdict"}
#: Confidence level of the intervals behind the verdict.
CONFIDENCE = 0.95


@dataclass(frozen=True)
class SpecCheck:
    """One spec limit against the study's estimate.

    Attributes
    ----------
    quantity : str
        What is judged.
    requirement : str
        The limit, or "no spec limit given".
    estimate : str
        The estimate with its interval.
    status : str
        :data:`PASS`, :data:`FAIL`, :data:`UNDECIDED` or :data:`NO_LIMIT`.
    reason : str
        One sentence: why this status.
    digits : int
        Digits of the interval ends shown (:func:`decisive_ends`), for other tables that
        show the same interval.
    """

    quantity: str
    requirement: str
    estimate: str
    status: str
    reason: str
    digits: int = 3


@dataclass(frozen=True)
class Verdict:
    """All checks and the overall status."""

    status: str
    checks: tuple
    confidence: float = CONFIDENCE

    @property
    def label(self) -> str:
        """Upper-case label for the box: PASS, FAIL, UNDECIDED or NO SPEC LIMIT GIVEN."""
        return self.status.upper()



ESTIMATOR_NAMES = {"subset": "subset simulation", "importance": "importance sampling",
                   "rare": "subset simulation and importance sampling"}


def estimator_flag(ds, name):
    """The status of a rare-event estimate that its estimator does not back (``"ok"`` and
    plain Monte Carlo: None): a check resting on it is undecided, never pass or fail
    (issue 23)."""
    attrs = ds[name].attrs if name in ds.variables else {}
    status = str(attrs.get("estimator_status", "ok"))
    return None if status == "ok" or attrs.get("estimator") in (None, "monte_carlo") else status


def _flagged(status, reason, ds, name):
    """(status, reason) of a check whose estimate :func:`estimator_flag` flags."""
    flag = estimator_flag(ds, name)
    fallback = ds[name].attrs.get("estimator_fallback") if name in ds.variables else None
    if flag is None and status != NO_LIMIT and fallback:
        # the rare-event estimator did not reach the event: the plain run's interval decides
        own = ds[f"{name}_status"].attrs
        return status, (f"{reason} (the plain run's Clopper-Pearson interval: "
                        f"{ESTIMATOR_NAMES.get(own.get('estimator'), own.get('estimator'))} "
                        f"did not reach the event, {own.get('estimator_status')}: "
                        f"{own.get('estimator_message', '')})")
    if flag is None and status != NO_LIMIT and name in ds.variables and \
            ds[name].attrs.get("estimator_mode_check") == "none":
        # subset simulation without FORM design points (a limit state that is not smooth):
        # its number is not checked for a lost failure mode, and the verdict says so
        return status, (reason + "; the estimate is unchecked for a lost failure mode (subset "
                                 "simulation without FORM design points)")
    if flag is None or status == NO_LIMIT:
        return status, reason
    why = ds[name].attrs.get("estimator_message", flag)
    return UNDECIDED, f"the estimator does not back the number ({flag}: {why}); " + reason


def estimator_label(ds, name="contact_probability"):
    """How a probability variable's interval was made, in words: "Clopper-Pearson" for the
    plain Monte Carlo, else the rare-event estimator with its interval, CV and model
    evaluations (the variable's ``estimator`` and ``interval`` attributes, issue 15)."""
    attrs = ds[name].attrs if name in ds.variables else {}
    estimator = str(attrs.get("estimator", "monte_carlo"))
    if estimator == "monte_carlo":
        return "Clopper-Pearson"
    label = ESTIMATOR_NAMES.get(estimator, estimator)
    parts = [f"{label}: {attrs.get('interval', 'interval of the estimator')}"]
    cv, evals = f"{name}_coefficient_of_variation", f"{name}_evaluations"
    if cv in ds.variables:
        parts.append(f"CV {float(ds[cv]):.2g}")
    if evals in ds.variables:
        parts.append(f"{int(ds[evals]):,} model evaluations")
    return ", ".join(parts)


def _interval_kind(label):
    return "Clopper-Pearson interval" if label == "Clopper-Pearson" else f"interval, {label}"


def judge_upper_limit(lower, upper, limit) -> str:
    """Status of "quantity <= limit" from an interval [lower, upper] of the quantity."""
    if not (limit is not None and np.isfinite(limit)):
        return NO_LIMIT
    if np.isfinite(upper) and upper <= limit:
        return PASS
    if np.isfinite(lower) and lower > limit:
        return FAIL
    return UNDECIDED


def judge_lower_limit(lower, upper, limit) -> str:
    """Status of "quantity >= limit" from an interval [lower, upper] of the quantity."""
    if not (limit is not None and np.isfinite(limit)):
        return NO_LIMIT
    if np.isfinite(lower) and lower >= limit:
        return PASS
    if np.isfinite(upper) and upper < limit:
        return FAIL
    return UNDECIDED


#: Fewest and most digits of an interval end (decimals of a Cpk, significant digits of a
#: fraction): :func:`decisive_ends` adds digits until the display shows the verdict.
DISPLAY_DIGITS = (3, 12)


def cpk_text(value, digits=3) -> str:
    """A Cpk with ``digits`` decimals."""
    return f"{value:.{digits}f}" if np.isfinite(value) else "n/a"


def _fraction_value(text) -> float:
    """The fraction shown by :func:`format_fraction` (``'12.3 ppm'``, ``'1.23 %'``)."""
    number_text, _, unit = text.partition(" ")
    try:
        value = float(number_text)
    except ValueError:
        return float("nan")
    return value / 1e6 if unit == "ppm" else value / 100.0


def _cpk_value(text) -> float:
    try:
        return float(text)
    except ValueError:
        return float("nan")


def decisive_ends(judge, lower, upper, limit, kind="fraction") -> tuple:
    """The interval ends as displayed, with the digits that make them show the verdict.

    Parameters
    ----------
    judge : callable
        :func:`judge_upper_limit` or :func:`judge_lower_limit`.
    lower, upper : float
        The interval.
    limit : float or None
        The limit.
    kind : str
        ``"fraction"`` (:func:`format_fraction`, significant digits) or ``"cpk"``
        (:func:`cpk_text`, decimals).

    Returns
    -------
    (lower_text, upper_text, digits)
        From :data:`DISPLAY_DIGITS` ``[0]`` digits on, the fewest for which ``judge`` of the
        displayed numbers equals ``judge`` of the interval and no end is shown equal to the
        limit unless it is (1.33032 against 1.33 shows "1.3303", not "1.330").
    """
    fmt, parse = ((cpk_text, _cpk_value) if kind == "cpk"
                  else (lambda x, d: format_fraction(x, digits=d), _fraction_value))
    status = judge(lower, upper, limit)
    first, last = DISPLAY_DIGITS
    for digits in range(first, last + 1):
        lo, hi = fmt(lower, digits), fmt(upper, digits)
        ties = limit is not None and any(  # an end shown as the limit but not equal to it
            parse(text) == limit != value for text, value in ((lo, lower), (hi, upper)))
        if judge(parse(lo), parse(hi), limit) == status and not ties:
            break
    return lo, hi, digits


def limit_text(limit, kind="fraction") -> str:
    """A limit as configured (up to 6 significant digits: never rounded to a neighbour)."""
    return f"{limit:.6g}" if kind == "cpk" else format_fraction(limit, digits=6)


def tracks_of(ds) -> int:
    """Trains per assembly of a carriage study (the size of its ``track`` dimension), or 0
    for a study of single trains."""
    sizes = getattr(ds, "sizes", {})
    return int(sizes.get("track", 0))


def counted(n, noun) -> str:
    """'1 train', '2 trains': a count with its noun (plural in -s)."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def any_train(n, owner="its") -> str:
    """'any of its 2 trains', or 'its train' for one."""
    return f"{owner} train" if n == 1 else f"any of {owner} {n} trains"


def contact_unit(ds) -> tuple:
    """(singular, plural) of what P(contact) is counted over: ``("train", "trains")``, or
    ``("assembly", "assemblies")`` in a carriage study (an assembly is a carriage with one
    train per track; it has contact when any of its trains has)."""
    return ("assembly", "assemblies") if tracks_of(ds) else ("train", "trains")


def contact_quantity(ds) -> str:
    """"P(ball-to-ball contact within the stroke) per train", or per assembly (carriage)."""
    tracks = tracks_of(ds)
    if not tracks:
        return "P(ball-to-ball contact within the stroke) per train"
    return (f"P(ball-to-ball contact within the stroke) per assembly (a carriage with "
            f"{counted(tracks, 'train')}" + (": contact in any of them)" if tracks > 1 else ")"))


def _limit(value):
    """A configured limit, or None (0 and NaN mean none)."""
    return float(value) if value is not None and np.isfinite(value) and value > 0 else None


def _sentence(status, what, lower, upper, limit_text, side):
    level = f"{100 * CONFIDENCE:.0f} %"
    if status == PASS:
        end = "upper" if side == "max" else "lower"
        return f"the whole {level} interval ({lower} to {upper}) meets {limit_text}: its " \
               f"{end} end is inside the limit"
    if status == FAIL:
        return f"the whole {level} interval ({lower} to {upper}) violates {limit_text}"
    if status == UNDECIDED:
        return (f"the {level} interval ({lower} to {upper}) straddles {limit_text}: more "
                "samples are needed to decide")
    return f"no limit on {what} in the config: the estimate is shown without a verdict"


def contact_check(ds) -> SpecCheck:
    """P(contact) per train (per assembly in a carriage study) against
    ``contact_probability_limit``."""
    p = number(ds, "contact_probability")
    lo, hi = number(ds, "contact_probability_bounds_ci_lower"), number(
        ds, "contact_probability_bounds_ci_upper")
    covering = np.isfinite(lo) and np.isfinite(hi)
    if not covering:
        lo, hi = (number(ds, "contact_probability_ci_lower"),
                  number(ds, "contact_probability_ci_upper"))
    limit = _limit(number(ds, "contact_probability_limit"))
    status = judge_upper_limit(lo, hi, limit)
    one, many = contact_unit(ds)
    kind = (f"interval covering the bounds over all {many}" if covering and number(
        ds, "n_assemblies_unresolved") > 0 else _interval_kind(estimator_label(ds)))
    lo_text, hi_text, digits = decisive_ends(judge_upper_limit, lo, hi, limit)
    estimate = (f"{format_fraction(p, digits=digits)} ({100 * CONFIDENCE:.0f} % {kind}: "
                f"{lo_text} to {hi_text})")
    req = f"P(contact) ≤ {limit_text(limit)}" if limit else NO_LIMIT
    reason = _sentence(status, "P(contact)", lo_text, hi_text, req, "max")
    unresolved = number(ds, "n_assemblies_unresolved")
    if status == UNDECIDED and covering and unresolved > 0 and judge_upper_limit(
            number(ds, "contact_probability_ci_lower"), number(ds, "contact_probability_ci_upper"),
            limit) != UNDECIDED:
        reason = reason.replace("more samples are needed to decide",
                                f"the {int(unresolved):,} unresolved {many} leave it open")
    if not np.isfinite(p) and status != NO_LIMIT:
        reason = f"no {one} has a known outcome: " + reason
    status, reason = _flagged(status, reason, ds, "contact_probability")
    return SpecCheck(contact_quantity(ds), req, estimate, status, reason, digits)


def out_of_spec_check(ds, q, out_of_spec_limit=None) -> SpecCheck:
    """Fraction of balls with |epsilon| above the limit L against an allowed fraction."""
    eps_limit = _limit(number(ds, "velocity_deviation_limit"))
    quantity = "fraction of balls out of spec"
    if eps_limit is None or not q:
        return SpecCheck(quantity + " (|ε| > L)", NO_LIMIT, "no limit L on |ε|: not computed",
                         NO_LIMIT, "no limit on |ε| in the config")
    quantity = f"fraction of balls with |ε| > {100 * eps_limit:.3g} %"
    prop = q["_proportion"]
    limit = _limit(number(ds, "velocity_deviation_out_of_spec_limit")
                   if out_of_spec_limit is None else out_of_spec_limit)
    status = judge_upper_limit(prop.lower, prop.upper, limit)
    req = f"≤ {limit_text(limit)}" if limit else NO_LIMIT
    lo_text, hi_text, digits = decisive_ends(judge_upper_limit, prop.lower, prop.upper, limit)
    reason = _sentence(status, "the allowed fraction out of spec", lo_text, hi_text,
                       f"the allowed fraction {req}", "max")
    return SpecCheck(quantity, req, prop.text(digits), status, reason, digits)


#: The quantity of the Cpk row.
CPK_QUANTITY = "process capability Cpk of ε"


def cpk_check(ds, q, cpk_minimum=None) -> SpecCheck:
    """Cpk of epsilon against a required minimum."""
    cap = q.get("_capability") if q else None
    if cap is None:
        return SpecCheck(CPK_QUANTITY, NO_LIMIT, "no limit L on |ε|: not computed", NO_LIMIT,
                         "no limit on |ε| in the config")
    limit = _limit(number(ds, "velocity_deviation_cpk_minimum")
                   if cpk_minimum is None else cpk_minimum)
    status = judge_lower_limit(cap.cpk_lower, cap.cpk_upper, limit)
    req = f"Cpk ≥ {limit_text(limit, 'cpk')}" if limit else NO_LIMIT
    lo_text, hi_text, digits = decisive_ends(judge_lower_limit, cap.cpk_lower, cap.cpk_upper,
                                             limit, "cpk")
    estimate = (f"{cpk_text(cap.cpk, digits)} ({100 * CONFIDENCE:.0f} % interval {lo_text} to "
                f"{hi_text}); percentile Cpk {cap.cpk_percentile:.3f}")
    reason = _sentence(status, "Cpk", lo_text, hi_text, req, "min")
    return SpecCheck(CPK_QUANTITY, req, estimate, status, reason, digits)


def has_friction(ds) -> bool:
    """The file holds the friction figures of a study with ``[contact]`` (issue 13)."""
    return "friction_increase_histogram" in getattr(ds, "variables", {})


def friction_check(ds, friction_exceedance_limit=None):
    """P(friction increase > L) per assembly against an allowed fraction, or None when the
    file has no friction figures or no limit L on the increase.

    Parameters
    ----------
    ds : xarray.Dataset
        A result file of a study with ``[contact]``.
    friction_exceedance_limit : float, optional
        Allowed fraction p_max of assemblies whose increase exceeds L [-] (none in the
        config: without it the estimate is shown with no verdict).
    """
    limit_n = _limit(number(ds, "friction_increase_limit"))
    if not has_friction(ds) or limit_n is None:
        return None
    p = number(ds, "friction_exceedance_probability")
    k, u = number(ds, "n_friction_exceedance"), number(ds, "n_assemblies_friction_unresolved")
    n = number(ds, "n_assemblies")
    covering = u > 0 and np.isfinite(k) and np.isfinite(n) and n > 0
    if covering:  # the interval covering the bounds over all assemblies
        lo = clopper_pearson_interval(int(k), int(n), CONFIDENCE)[0]
        hi = clopper_pearson_interval(int(k + u), int(n), CONFIDENCE)[1]
    else:
        lo, hi = (number(ds, "friction_exceedance_probability_ci_lower"),
                  number(ds, "friction_exceedance_probability_ci_upper"))
    allowed = _limit(friction_exceedance_limit)
    status = judge_upper_limit(lo, hi, allowed)
    one, many = contact_unit(ds)
    worst = " (its worst track)" if tracks_of(ds) else ""
    quantity = (f"P(friction increase > {limit_n:.4g} N) per {one}{worst}: the rise of the "
                "carriage friction force over its free-rolling baseline")
    kind = (f"interval covering the bounds over all {many}" if covering
            else _interval_kind(estimator_label(ds, "friction_exceedance_probability")))
    lo_text, hi_text, digits = decisive_ends(judge_upper_limit, lo, hi, allowed)
    estimate = (f"{format_fraction(p, digits=digits)} ({100 * CONFIDENCE:.0f} % {kind}: "
                f"{lo_text} to {hi_text})")
    if allowed:
        req = f"P(increase > {limit_n:.4g} N) ≤ {limit_text(allowed)}"
        reason = _sentence(status, "the friction exceedance", lo_text, hi_text, req, "max")
    else:
        req = f"increase ≤ {limit_n:.4g} N; no allowed fraction given"
        known = int(n - u) if np.isfinite(n) and np.isfinite(u) else 0
        reason = (f"{int(k) if np.isfinite(k) else 0:,} of {known:,} {many} whose outcome is "
                  f"known exceed {limit_n:.4g} N; the config sets no allowed fraction of "
                  f"{many} beyond the limit ([contact] has no key for it), so the estimate "
                  "is shown without a verdict")
    if not np.isfinite(p) and status != NO_LIMIT:
        reason = f"no {one} has a known friction outcome: " + reason
    status, reason = _flagged(status, reason, ds, "friction_exceedance_probability")
    return SpecCheck(quantity, req, estimate, status, reason, digits)


def overall(statuses) -> str:
    """Fail over undecided over pass over no limit."""
    statuses = list(statuses)
    for s in (FAIL, UNDECIDED, PASS):
        if s in statuses:
            return s
    return NO_LIMIT


def study_verdict(ds, q=None, *, out_of_spec_limit=None, cpk_minimum=None,
                  friction_exceedance_limit=None) -> Verdict:
    """The verdict of a result file against its spec limits.

    Parameters
    ----------
    ds : xarray.Dataset
        A result file of ``tolsim run``.
    q : dict, optional
        :func:`tolsim.study.statistics.quality.dataset_quality` of ``ds`` (computed when not given).
    out_of_spec_limit : float, optional
        Allowed fraction of balls with |epsilon| above the limit [-] (none in the config).
    cpk_minimum : float, optional
        Required Cpk of epsilon [-] (none in the config).
    friction_exceedance_limit : float, optional
        Allowed fraction of assemblies whose friction increase exceeds the config's limit
        [-] (a study with ``[contact]``; none in the config). The friction row is there
        whenever the config sets the limit (:func:`friction_check`).

    Returns
    -------
    Verdict
    """
    if q is None:
        q = dataset_quality(ds)
    checks = (contact_check(ds), out_of_spec_check(ds, q, out_of_spec_limit),
              cpk_check(ds, q, cpk_minimum))
    friction = friction_check(ds, friction_exceedance_limit)
    if friction is not None:
        checks += (friction,)
    return Verdict(overall(c.status for c in checks), checks)
