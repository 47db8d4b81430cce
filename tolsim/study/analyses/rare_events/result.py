"""What a rare-event estimator returns: :class:`RareEventResult`, its statuses and interval
kinds (:mod:`tolsim.study.analyses.rare_events`).

Unresolved rows
---------------
A row where g is NaN is counted (``unresolved``, over all evaluated rows) and bounded:
counted as a failure it gives the upper bound P(F or N), as safe the lower bound
P(F and not N) (``bound_lower`` / ``bound_upper``, with ``bounds_ci_lower`` the lower end of
the lower bound's interval and ``bounds_ci_upper`` the upper end of the upper bound's). Subset
simulation runs with NaN counted as failure at every level (a NaN candidate is accepted:
the intermediate domains are {g <= b} or N), so one run estimates both: the last level
counts its failures with and without the NaN rows. ``probability`` itself is the estimate
over the resolved rows, P(F | not N) = P(F and not N) / (1 - P(N)) (for Monte Carlo k of the
n - m resolved samples, as ``tolsim run`` reports P(contact)); for subset and importance
sampling its CV and interval are those of the lower bound divided by the estimated
1 - P(N), which neglects the variance of the estimate of P(N). Base decisions on the bounds
interval; with no unresolved row the three coincide. When unresolved rows are more frequent
than failures, subset simulation reaches its last level on them and the lower bound rests on
the few failures of that level (or is 0); importance sampling sees only the unresolved rows
near u*.

"""

from dataclasses import dataclass, field

import numpy as np

STATUS_OK = "ok"
STATUS_NO_FAILURE = "no_failure"
STATUS_PLATEAU = "plateau"
STATUS_FORM_FAILED = "form_failed"
STATUS_UNRESOLVED = "unresolved"
STATUS_DIAGNOSTIC_FAILED = "diagnostic_failed"
STATUS_ESTIMATORS_DISAGREE = "estimators_disagree"
#: Every status and what it means (the docstring of :class:`RareEventResult`).
STATUSES = {
    STATUS_OK: "the estimator backs its number and interval",
    STATUS_NO_FAILURE: "no sample failed: no probability estimated",
    STATUS_PLATEAU: "subset simulation: the limit state is flat at a level's quantile",
    STATUS_FORM_FAILED: "FORM found no accepted design point: no probability estimated",
    STATUS_UNRESOLVED: "every sample unresolved (g NaN): P only known to lie in [0, 1]",
    STATUS_DIAGNOSTIC_FAILED: "a number was computed but a diagnostic says not to trust it "
                              "(message: which one)",
    STATUS_ESTIMATORS_DISAGREE: "two estimators (or FORM and an estimator) disagree beyond "
                                "their intervals",
}

INTERVAL_CLOPPER_PEARSON = "Clopper-Pearson"
INTERVAL_LOGNORMAL = "lognormal with the CV and a Student-t quantile (approximate)"
INTERVAL_NORMAL = "normal approximation, estimate -+ z se (approximate)"
#: A normal interval (or the estimate) that passed 1 and was clipped to [0, 1] (a probability).
INTERVAL_NORMAL_CLIPPED = ("normal approximation, estimate -+ z se, estimate and interval "
                           "clipped to [0, 1] (approximate)")


class RareEventError(RuntimeError):
    """An estimator could not back a number (raised by :meth:`RareEventResult.raise_for_status`)."""


@dataclass(frozen=True, eq=False)
class RareEventResult:
    """A failure probability from one estimator, with its interval and what it cost.

    Attributes
    ----------
    estimator : str
        ``"monte_carlo"``, ``"subset"`` or ``"importance"`` (:data:`ESTIMATORS`).
    probability : float
        P(g <= 0) over the resolved rows [-]; NaN when the estimator is flagged.
    standard_error, coefficient_of_variation : float
        Of ``probability`` [-] (the CV is inf for an estimate of 0).
    ci_lower, ci_upper : float
        Interval of ``probability`` at ``confidence_level`` [-], of the kind ``interval``.
    confidence_level : float
    interval : str
        How the interval is made (approximate for subset and importance sampling).
    evaluations : int
        Rows on which the limit state was evaluated (model calls), FORM included.
    dimension : int
    status : str
        One of :data:`STATUSES` (:meth:`raise_for_status` raises unless ``"ok"``):

        ``"ok"``
            The estimator backs its number and interval.
        ``"no_failure"``
            No sample failed (subset: within ``max_levels``); probability NaN.
        ``"plateau"``
            Subset: the limit state is flat at a level's p0-quantile; probability NaN.
        ``"form_failed"``
            Importance sampling: FORM found no accepted design point; probability NaN.
        ``"unresolved"``
            Monte Carlo: every sample unresolved; probability NaN, bounds [0, 1].
        ``"diagnostic_failed"``
            A number was computed (``probability`` and its interval are kept, for
            inspection) but a diagnostic says it may be wrong: importance sampling with too
            few effective samples or one dominating weight, or a FORM/IS ratio far from 1;
            subset simulation whose failures descend from too few level-0 samples. The
            message names the diagnostic and its threshold.
        ``"estimators_disagree"``
            Two estimators (subset simulation and importance sampling, or subset simulation
            and FORM's design points) disagree beyond their intervals; both numbers are in
            the message, ``probability`` is the first estimator's.
    message : str
        One line: why the estimator is flagged ("" when ok; an ``ok`` result of
        ``method="rare"`` that set subset simulation aside for a lost failure mode says so).
    unresolved : int
        Evaluated rows where g was NaN.
    failures : int
        Resolved samples with g <= 0: of all samples (Monte Carlo, importance sampling) or of
        the last level (subset).
    bound_lower, bound_upper : float
        P with the unresolved rows counted as safe / as failures [-].
    bounds_ci_lower, bounds_ci_upper : float
        Lower end of the lower bound's interval, upper end of the upper bound's [-].
    samples_per_level : int
        n (subset); the number of samples (the others).
    thresholds : tuple of float
        Subset: b_1, ..., b_m, 0: the threshold each level's samples were tested against.
    level_probabilities : tuple of float
        Subset: p0, ..., p0, P_m (their product is the probability; the last over all rows,
        unresolved counted as failures).
    level_coefficients_of_variation : tuple of float
        Subset: delta_j of each level (over chain families,
        :mod:`~tolsim.study.analyses.rare_events.subset`).
    chain_correlation_factors : tuple of float
        Subset: Au & Beck's gamma_j of each level (0 for level 0), for comparison.
    acceptance_rates : tuple of float
        Subset: mean acceptance of the chains of levels 1 .. m.
    degrees_of_freedom : float
        Subset: of the variance behind the interval (Student-t quantile); inf for the
        others.
    design_point : ndarray (d,) or None
        Importance sampling: u* in the standard space (the caller maps it to physical units).
    beta, form_probability : float
        Importance sampling: |u*| and Phi(-beta).
    importance_factors : ndarray (d,) or None
        Importance sampling: alpha_k^2, alpha = u* / beta.
    design_points : ndarray (k, d) or None
        Importance sampling: every design point sampled around (the mixture components),
        by increasing beta; ``design_point`` is the first.
    betas : tuple of float
        Their reliability indices.
    effective_sample_size : float
        Importance sampling: Kish's effective number of the failing samples' weights,
        (sum w_i)^2 / sum w_i^2 over the failing samples.
    largest_weight_share : float
        Importance sampling: the largest failing weight over their sum.
    form_ratio : float
        Importance sampling: ``form_probability`` / ``probability`` (first-order estimate
        over the importance-sampling estimate).
    ancestors : int
        Subset: distinct level-0 samples that the last level's failing samples descend from.
    level_independent_cv : float
        Subset: the CV with the levels taken as independent (the family estimate of each
        level), for comparison with ``coefficient_of_variation``.
    lost_mode_mass : float
        Subset checked against FORM's design points: the probability those design points
        hold beyond what the chains found around them, sum_k (P_k - subset's mass near
        u*_k), when that flagged the result ``"diagnostic_failed"`` for a lost failure mode
        (:func:`~tolsim.study.analyses.rare_events.subset.lost_modes`); 0 otherwise [-].
    """

    estimator: str
    probability: float
    standard_error: float
    coefficient_of_variation: float
    ci_lower: float
    ci_upper: float
    confidence_level: float
    interval: str
    evaluations: int
    dimension: int
    status: str = STATUS_OK
    message: str = ""
    unresolved: int = 0
    failures: int = 0
    bound_lower: float = float("nan")
    bound_upper: float = float("nan")
    bounds_ci_lower: float = float("nan")
    bounds_ci_upper: float = float("nan")
    samples_per_level: int = 0
    thresholds: tuple = ()
    level_probabilities: tuple = ()
    level_coefficients_of_variation: tuple = ()
    chain_correlation_factors: tuple = ()
    acceptance_rates: tuple = ()
    degrees_of_freedom: float = float("inf")
    design_point: np.ndarray | None = field(default=None, repr=False)
    beta: float = float("nan")
    form_probability: float = float("nan")
    importance_factors: np.ndarray | None = field(default=None, repr=False)
    design_points: np.ndarray | None = field(default=None, repr=False)
    betas: tuple = ()
    effective_sample_size: float = float("nan")
    largest_weight_share: float = float("nan")
    form_ratio: float = float("nan")
    ancestors: int = 0
    level_independent_cv: float = float("nan")
    lost_mode_mass: float = 0.0

    @property
    def ok(self) -> bool:
        """True when the estimator backs its number."""
        return self.status == STATUS_OK

    @property
    def levels(self) -> int:
        """Subset: the number of sampling levels (level 0 included); 0 for the others."""
        return len(self.thresholds)

    def raise_for_status(self) -> "RareEventResult":
        """Self when ok, else raise :class:`RareEventError` with the one-line message."""
        if not self.ok:
            raise RareEventError(self.message)
        return self

    def describe(self) -> str:
        """One line: the estimate, its interval and the cost, or why there is none."""
        name = ESTIMATOR_TITLES.get(self.estimator, self.estimator)
        if not self.ok and not np.isfinite(self.probability):
            return f"{name}: {self.message}"
        head = name
        if self.estimator == "importance":
            head += f" at the design point (beta {self.beta:.4g}, FORM {self.form_probability:.3g})"
        level = f"{100 * self.confidence_level:g} %"
        cv = self.coefficient_of_variation
        cv_text = f"CV {cv:.2g}; " if np.isfinite(cv) else ""
        upper = f"{self.ci_upper:.3g}" if np.isfinite(self.ci_upper) else "n/a"
        line = (f"{head}: P = {self.probability:.3g} ({cv_text}{level} CI {self.ci_lower:.3g} "
                f"to {upper}, {self.interval}); ")
        if self.estimator == "subset":
            line += (f"{self.evaluations:,} evaluations over {self.levels} levels of "
                     f"{self.samples_per_level:,}")
        elif self.estimator == "importance":
            line += (f"{self.failures:,} of {self.samples_per_level:,} samples fail, "
                     f"{self.evaluations:,} evaluations with FORM")
        else:
            line += (f"{self.failures:,} of {self.samples_per_level - self.unresolved:,} "
                     "resolved samples fail")
        if self.unresolved:
            line += (f"; {self.unresolved:,} unresolved rows: P between {self.bound_lower:.3g} "
                     f"(as safe) and {self.bound_upper:.3g} (as failures), {level} "
                     f"{self.bounds_ci_lower:.3g} to {self.bounds_ci_upper:.3g}")
        if not self.ok:
            line += f"; NOT OK ({self.status}): {self.message}"
        return line


#: How :meth:`RareEventResult.describe` names them.
ESTIMATOR_TITLES = {"monte_carlo": "Monte Carlo", "subset": "subset simulation",
                    "importance": "importance sampling",
                    "rare": "subset simulation and importance sampling"}


def flagged(status, message, evaluations, unresolved, common=None, **extra):
    """A result without a probability: ``status`` and a one-line ``message``."""
    nan = float("nan")
    return RareEventResult(
        probability=nan, standard_error=nan, coefficient_of_variation=nan, ci_lower=nan,
        ci_upper=nan, interval="none", evaluations=evaluations, status=status,
        message=message, unresolved=unresolved, **(common or {}), **extra)

