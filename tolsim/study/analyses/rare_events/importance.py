"""Importance sampling around FORM design points ([Melchers1989]) over a standard-normal space
(:mod:`tolsim.study.analyses.rare_events`).

Importance sampling draws v from the mixture q(v) = sum_k pi_k phi(v - u*_k) over every
design point u*_k that :func:`~tolsim.study.analyses.rare_events.form.find_design_points`
found (blocks as in :mod:`~tolsim.study.analyses.rare_events.common`), pi_k = 0.9 Phi(-beta_k) /
sum_j Phi(-beta_j) + 0.1 / K (a defensive share, so that a point whose FORM estimate is too
low still gets samples), and averages 1{g(v) <= 0} w(v), w = phi(v) / q(v) =
1 / sum_k pi_k exp(v . u*_k - beta_k^2 / 2) ([Melchers1989]); with one design point that is
N(u*, I) and w = exp(-v . u* + beta^2 / 2). The standard error is the sample standard
deviation over sqrt(n); the 95 % interval the normal one, P -+ z se, the estimate and the
interval clipped to [0, 1] (:func:`weighted_result`).
It is unbiased for any limit state (but for that clip, which acts only where nearly every
sample fails), but efficient only when the failure domain lies around
the design points: a design point that no search found gets no samples, and the estimate is
low with a standard error that does not show it. Hence the restarts, and three diagnostics
(result fields; a failing one makes the status ``"diagnostic_failed"``, the number kept):

* ``effective_sample_size`` (Kish's, of the failing samples' weights) >= 30
  (:data:`MIN_EFFECTIVE_SAMPLES`): below it the normal interval rests on too few effective
  samples (on the sound benchmark problems it is 150-500 at n = 2000);
* ``largest_weight_share`` <= 10 % (:data:`MAX_WEIGHT_SHARE`): a sample in a failure region
  far from every design point has a weight orders of magnitude above the others (RP89 with
  FORM's local design point alone: 20-100 %; the sound problems: below 5 %);
* ``form_ratio`` = P_FORM / P_IS within 1/30 to 30 (:data:`FORM_RATIO_LIMIT`), P_FORM =
  min(1, sum_k Phi(-beta_k)): on the sound problems of issue 23 it was 0.11-1.12, on RP89
  with the local design point 5e-5.

With few failing samples (a strongly curved limit state) the normal interval is too short on
the high side: on the ball of ``benchmarks/bench_rare_events.py`` (about 2 % of 4000 samples
fail) it covers 93.2 % (1000 repeats), against 94-96 % on the linear case. RP35 of RPRepo has
three design points at beta = 3, one of them in a small basin: without the ray scan of
:func:`~tolsim.study.analyses.rare_events.form.find_design_points` the restarts found all
three in about two runs of three and IS covered 86 % of 100 runs; with it, all three in 60 of
60 runs and 95 % coverage (``benchmarks/rare_event_coverage.py``).

References
----------
.. [Melchers1989] R. E. Melchers, "Importance sampling in structural systems", Structural
   Safety 6 (1989) 3-10, doi:10.1016/0167-4730(89)90003-9.
"""

from dataclasses import dataclass

import numpy as np
from scipy.special import log_ndtr, logsumexp, ndtr

from tolsim.study.analyses.rare_events.common import (
    check_batch_size,
    check_confidence,
    check_count,
    check_dimension,
    child_sequence,
    clip_unit,
    cv_of,
    evaluate,
    normal_blocks,
    seed_sequence,
    weighted_mean,
)
from tolsim.study.analyses.rare_events.form import (
    DEFAULT_RESTARTS,
    GRADIENT_STEP,
    DesignPointSet,
    find_design_points,
)
from tolsim.study.analyses.rare_events.result import (
    INTERVAL_NORMAL,
    INTERVAL_NORMAL_CLIPPED,
    STATUS_DIAGNOSTIC_FAILED,
    STATUS_FORM_FAILED,
    STATUS_NO_FAILURE,
    STATUS_OK,
    RareEventResult,
    flagged,
)
from tolsim.study.analyses.rare_events.series_form import component_design_points

#: Defensive share of the mixture spread evenly over the design points (the rest in proportion
#: to Phi(-beta_k)), so that a point whose FORM estimate is too low still gets samples.
DEFENSIVE_SHARE = 0.1
#: Diagnostics of importance sampling (module docstring): fewest effective failing samples,
#: largest share of one weight, and the widest ratio P_FORM / P_IS (either way).
MIN_EFFECTIVE_SAMPLES = 30.0
MAX_WEIGHT_SHARE = 0.1
FORM_RATIO_LIMIT = 30.0


def importance_sampling(limit_state, dimension, seed, *, samples=2000, design_point=None,
                        design_points=None, restarts=DEFAULT_RESTARTS, gradient=None,
                        step=GRADIENT_STEP, batch_size=None,
                        confidence_level=0.95) -> RareEventResult:
    """FORM from several starts, then importance sampling from the mixture of N(u*_k, I) over
    every design point found ([Melchers1989]), with diagnostics; see the module docstring.

    Parameters
    ----------
    limit_state : callable
        g(u) for u of shape (rows, d) -> (rows,); failure where g <= 0, NaN unresolved.
    dimension : int
        d.
    seed : numpy.random.SeedSequence or int
    samples : int
        n importance samples.
    design_point : DesignPoint, optional
        One converged design point from :func:`find_design_point` (then its evaluations are
        not counted again, and only it is sampled around: importance sampling as before
        issue 23, with the diagnostics).
    design_points : DesignPointSet, optional
        The design points of :func:`find_design_points` (evaluations not counted again); by
        default they are searched here with ``restarts`` restarts.
    restarts : int
        Of :func:`find_design_points` (0: the single search from the origin). No restart
        begins once the searches have cost n evaluations, so that the whole costs at most
        about twice the single search and the n samples.
    gradient, step : optional
        Of :func:`find_design_point`.
    batch_size : int, optional
        Most rows per call of ``limit_state``; the result does not depend on it.
    confidence_level : float

    Returns
    -------
    RareEventResult
        P, its standard error and the normal interval, with ``design_point``, ``beta`` and
        ``importance_factors`` (of the most probable design point), ``design_points``,
        ``betas``, ``form_probability`` (min(1, sum_k Phi(-beta_k))) and the diagnostics
        ``effective_sample_size``, ``largest_weight_share`` and ``form_ratio``. Status
        ``"diagnostic_failed"`` (the number kept) when a diagnostic fails,
        ``"form_failed"`` (no probability; use :func:`subset_simulation`) when FORM gives no
        design point, ``"no_failure"`` when no importance sample fails.
    """
    d = check_dimension(dimension)
    n = check_count("samples", samples, 2)
    check_batch_size(batch_size)
    z = check_confidence(confidence_level)
    root = seed_sequence(seed)
    if design_point is not None:
        if np.shape(design_point.point) != (d,):
            raise ValueError(f"design point of shape {np.shape(design_point.point)} for "
                             f"dimension {d}")
        found = DesignPointSet((design_point,) if design_point.converged else (), 0, 1,
                               design_point.message)
    elif design_points is not None:
        found = DesignPointSet(design_points.points, 0, design_points.searches,
                               design_points.message)
    else:
        found = find_design_points(limit_state, d, root, restarts=restarts, max_evaluations=n,
                                   gradient=gradient, step=step, batch_size=batch_size)
    evaluations, form_unresolved = found.evaluations, found.unresolved
    common = dict(estimator="importance", confidence_level=confidence_level, dimension=d,
                  samples_per_level=n)
    if not found.points:
        point = design_point
        if point is not None:
            common.update(design_point=point.point, beta=point.beta,
                          form_probability=point.form_probability,
                          importance_factors=point.importance_factors)
        return flagged(STATUS_FORM_FAILED, f"importance sampling: FORM found no design point: "
                                           f"{found.message}; no "
                                           "probability estimated, use subset simulation",
                       evaluations, form_unresolved, common)
    best = found.points[0]
    shifts = np.array([p.point for p in found.points])
    beta = found.betas
    common.update(design_point=best.point, beta=best.beta,
                  form_probability=found.form_probability,
                  importance_factors=best.importance_factors, design_points=shifts,
                  betas=tuple(float(b) for b in beta))
    if len(shifts) == 1:                       # N(u*, I): the draws of issue 15
        shift = shifts[0]
        beta2 = float(shift @ shift)
        failures, unevaluable, weights = [], [], []
        for normal in normal_blocks(root, (0,), n, d):
            v = shift + normal
            g = evaluate(limit_state, v, batch_size)
            failures.append(g <= 0)
            unevaluable.append(np.isnan(g))
            # phi(v) / phi(v - u*) = exp(-v.u* + beta^2 / 2) = exp(-z.u* - beta^2 / 2)
            weights.append(np.exp(-(normal @ shift) - 0.5 * beta2))
        failed, unevaluable, w = (np.concatenate(x) for x in (failures, unevaluable, weights))
    else:
        share = np.exp(log_ndtr(-beta) - logsumexp(log_ndtr(-beta)))
        share = (1.0 - DEFENSIVE_SHARE) * share + DEFENSIVE_SHARE / len(beta)
        failed, unevaluable, w = mixture_samples(limit_state, root, shifts, share, n,
                                                 batch_size)
    evaluations += n
    unresolved = form_unresolved + int(np.count_nonzero(unevaluable))
    if not np.any(failed | unevaluable):
        return flagged(STATUS_NO_FAILURE, f"importance sampling found no failure among the "
                                          f"{n} samples around the "
                                          f"{len(shifts)} design point(s) (smallest beta "
                                          f"{best.beta:.4g}): no probability estimated; "
                                          "check the design points or use subset simulation",
                       evaluations, unresolved, common)
    return weighted_result(failed, unevaluable, w, z, evaluations, unresolved, common)


def mixture_samples(limit_state, root, shifts, share, n, batch_size):
    """Draw n samples from sum_k share_k N(u*_k, I) and evaluate them.

    Normals in blocks from the children (RARE_EVENT_STREAM, 0, b) of ``root``, the components
    from the child (RARE_EVENT_STREAM, 1). Returns (failed, unevaluable, weights) with the
    weight phi(v) / q(v) = 1 / sum_k share_k exp(v . u*_k - beta_k^2 / 2).
    """
    d = shifts.shape[1]
    beta = np.linalg.norm(shifts, axis=1)
    labels = np.random.default_rng(child_sequence(root, 1)).choice(len(shifts), size=n,
                                                                   p=share)
    v = np.concatenate(list(normal_blocks(root, (0,), n, d))) + shifts[labels]
    # log q(v) / phi(v), row by row
    log_ratio = logsumexp(np.log(share) + v @ shifts.T - 0.5 * beta * beta, axis=1)
    g = evaluate(limit_state, v, batch_size)
    return g <= 0, np.isnan(g), np.exp(-log_ratio)


def weight_diagnostics(failing_weights, form_probability, probability):
    """The diagnostics of importance sampling and the first one that fails.

    Parameters
    ----------
    failing_weights : ndarray
        w_i of the failing samples.
    form_probability, probability : float
        P_FORM and the importance-sampling estimate.

    Returns
    -------
    (effective sample size, largest weight share, FORM ratio, message)
        The message is "" when all pass (thresholds in the module docstring).
    """
    total = float(np.sum(failing_weights))
    if not total > 0:
        return 0.0, float("nan"), float("nan"), "no failing sample carries weight"
    # Kish's (sum w)^2 / sum w^2 on w / max w: the same number, without sum w^2 underflowing
    # to 0 for weights below 1e-154 (deep tails: a division by zero before)
    largest = float(np.max(failing_weights))
    scaled = failing_weights / largest
    ess = float(np.sum(scaled)) ** 2 / float(np.sum(scaled ** 2))
    share = largest / total
    ratio = form_probability / probability if probability > 0 else float("inf")
    message = ""
    if ess < MIN_EFFECTIVE_SAMPLES:
        message = (f"only {ess:.3g} effective failing samples (< {MIN_EFFECTIVE_SAMPLES:g}): "
                   "the failure domain is poorly covered by the sampling density")
    elif share > MAX_WEIGHT_SHARE:
        message = (f"one sample carries {100 * share:.3g} % of the estimate (> "
                   f"{100 * MAX_WEIGHT_SHARE:g} %): failures far from the design points "
                   "(a missed design point?)")
    elif not (1.0 / FORM_RATIO_LIMIT <= ratio <= FORM_RATIO_LIMIT):
        message = (f"FORM and importance sampling disagree: P_FORM / P_IS = {ratio:.3g} "
                   f"(outside 1/{FORM_RATIO_LIMIT:g} to {FORM_RATIO_LIMIT:g}; a missed "
                   "design point or a strongly curved limit state)")
    return ess, share, ratio, message


def weighted_result(failed, unevaluable, w, z, evaluations, unresolved, common):
    """P, its normal interval, the unresolved bounds and the diagnostics of weighted samples
    (``common`` holds ``form_probability``).

    Notes
    -----
    The weighted mean is unbiased but not bounded by 1: where nearly every sample fails
    (an event that is not rare, u* near the origin) the weights average 1 only to within
    their noise, and P = 1.00014, interval 0.99992 to 1.00037, came out of a study with the
    gaps 0 to 1 um. A probability lies in [0, 1], so the estimate, the bounds and the
    interval ends are clipped to it (:data:`INTERVAL_NORMAL_CLIPPED` names the interval
    then): min(P, 1) is never farther from the truth than P, and an interval cut at a value
    the truth cannot pass covers it as often as before. The self-normalised estimator
    sum 1{F} w / sum w is bounded by construction, but it is biased (O(1 / n)) and would
    change every importance-sampling number of the package; clipping changes none below 1.
    The diagnostics use the unclipped weights.
    """
    lower, se_lower = weighted_mean(np.where(failed, w, 0.0))
    upper, se_upper = weighted_mean(np.where(failed | unevaluable, w, 0.0))
    resolved = 1.0 - (upper - lower)
    p = lower / resolved
    se = se_lower / resolved
    ess, share, ratio, message = weight_diagnostics(w[failed], common["form_probability"], p)
    status = STATUS_DIAGNOSTIC_FAILED if message else STATUS_OK
    ends = (p, p + z * se, lower, upper, upper + z * se_upper)
    clipped = any(x > 1.0 for x in ends)
    return RareEventResult(
        probability=clip_unit(p), standard_error=se, coefficient_of_variation=cv_of(p, se),
        ci_lower=clip_unit(p - z * se), ci_upper=clip_unit(p + z * se),
        interval=INTERVAL_NORMAL_CLIPPED if clipped else INTERVAL_NORMAL,
        evaluations=evaluations, unresolved=unresolved,
        failures=int(np.count_nonzero(failed)), bound_lower=clip_unit(lower),
        bound_upper=clip_unit(upper), bounds_ci_lower=clip_unit(lower - z * se_lower),
        bounds_ci_upper=clip_unit(upper + z * se_upper),
        effective_sample_size=ess, largest_weight_share=share, form_ratio=ratio,
        status=status, message=message, **common)


@dataclass(frozen=True, eq=False)
class SeriesDesignPoints:
    """FORM on each component of a series event (:func:`series_importance_sampling`).

    Attributes
    ----------
    names : tuple of str
        The components (``limit_state.component_names``).
    points : ndarray (k, d)
        Their design points u*_k [-].
    betas : ndarray (k,)
        |u*_k| [-].
    evaluations : int
        Rows evaluated by the k searches.
    design_points : tuple of DesignPoint
        Each component's search (:func:`~tolsim.study.analyses.rare_events.series_form.
        component_design_points`), converged or not: the form subset simulation's lost-mode
        check takes (``design_points=``).
    unresolved : int
        Of the rows evaluated, those where a component was NaN.
    """

    names: tuple
    points: np.ndarray
    betas: np.ndarray
    evaluations: int
    design_points: tuple = ()
    unresolved: int = 0

    @property
    def failed(self):
        """The first component whose search was not accepted (None when all were)."""
        return next((k for k, p in enumerate(self.design_points) if not p.converged), None)

    @property
    def point_set(self) -> DesignPointSet:
        """The accepted design points as a :class:`~tolsim.study.analyses.rare_events.form.
        DesignPointSet` (by increasing beta; the evaluations of all the searches)."""
        found = sorted((p for p in self.design_points if p.converged), key=lambda p: p.beta)
        message = "" if self.failed is None else \
            f"{self.names[self.failed]}: {self.design_points[self.failed].message}"
        return DesignPointSet(tuple(found), self.evaluations, len(self.design_points), message,
                              self.unresolved)

    @property
    def most_probable(self) -> int:
        """The component with the smallest beta."""
        return int(np.argmin(self.betas))


def series_design_points(limit_state, *, batch_size=None) -> SeriesDesignPoints:
    """FORM on every component of a series event at once (:func:`~tolsim.study.analyses.
    rare_events.series_form.component_design_points`); ``limit_state`` as
    :func:`series_importance_sampling` takes it."""
    names = tuple(limit_state.component_names)
    found, rows, nans = component_design_points(limit_state.components, limit_state.dimension,
                                                len(names), batch_size=batch_size)
    return SeriesDesignPoints(names, np.array([p.point for p in found]),
                              np.array([p.beta for p in found]), rows, found, nans)


def series_importance_sampling(limit_state, seed, *, samples=2000, batch_size=None,
                               confidence_level=0.95, design=None):
    """FORM on every component, then importance sampling from the mixture of N(u*_k, I).

    ``limit_state`` is a limit state of a series event with ``dimension``,
    ``component_names`` and ``components(u)`` (all components' g, (rows, k); e.g.
    :class:`tolsim.study.analyses.limit_state.LimitState`). A series event (the union of its
    components: any pair touches, any ball beyond the limit) has a design point per
    component, often several of similar beta (the pairs of a train). Importance sampling
    around one of them misses the others' failure domains and is low by a factor of up to
    their number, with a standard error that does not show it (module docstring). Here each
    component's design point u*_k is found (SLSQP on the component alone with the checks of
    :func:`~tolsim.study.analyses.rare_events.form.find_design_point`, the origin's rows
    shared: :func:`series_design_points`), and the
    samples are drawn from the mixture q(v) = sum_k pi_k phi(v - u*_k), pi_k
    proportional to Phi(-beta_k), with the weight phi(v) / q(v) = 1 / sum_k pi_k
    exp(v . u*_k - beta_k^2 / 2) ([Melchers1989]'s
    multi-modal sampling density for systems). The estimate is unbiased whatever the
    mixture (it has full support); the mixture only makes it efficient. Standard error,
    interval and unresolved bounds as :func:`importance_sampling`.

    Randomness: the normals in blocks from the children (RARE_EVENT_STREAM, 0, b) of
    ``seed`` (as the other estimators here), the mixture components
    from the child (RARE_EVENT_STREAM, 1).

    Parameters
    ----------
    limit_state : object
        A smooth series event (see above).
    seed : numpy.random.SeedSequence or int
    samples : int
        n importance samples.
    batch_size : int, optional
        Most rows per model call; no effect on the result.
    confidence_level : float
    design : SeriesDesignPoints, optional
        Of :func:`series_design_points`, when already searched (its evaluations are counted
        here all the same).

    Returns
    -------
    (RareEventResult, SeriesDesignPoints or None)
        The result's ``design_point``, ``beta`` and ``importance_factors`` are those of the
        most probable component; ``form_probability`` is the first-order series bound
        min(1, sum_k Phi(-beta_k)) (each component's FORM estimate, added). Flagged
        ``form_failed`` when FORM gives no design point for some component (its message
        names it), ``no_failure`` when no sample fails.
    """
    n = int(samples)
    if n < 2:
        raise ValueError(f"samples = {samples!r} must be >= 2")
    z = check_confidence(confidence_level)
    root = seed_sequence(seed)
    names = limit_state.component_names
    common = dict(estimator="importance", confidence_level=confidence_level,
                  dimension=limit_state.dimension, samples_per_level=n)
    if design is None:
        design = series_design_points(limit_state, batch_size=batch_size)
    evaluations = design.evaluations
    if design.failed is not None:
        k = design.failed
        return flagged(STATUS_FORM_FAILED, f"importance sampling: FORM found no design point "
                                            f"for {names[k]}: "
                                            f"{design.design_points[k].message}", evaluations,
                       design.unresolved, common), None
    best = design.most_probable
    shifts, beta = design.points, design.betas
    log_weight = log_ndtr(-beta)
    log_weight = log_weight - logsumexp(log_weight)
    star = shifts[best]
    common.update(design_point=star, beta=float(beta[best]),
                  form_probability=float(min(1.0, np.sum(ndtr(-beta)))),
                  importance_factors=(star / beta[best]) ** 2)
    common.update(design_points=shifts, betas=tuple(float(b) for b in beta))
    failed, unevaluable, w = mixture_samples(limit_state, root, shifts, np.exp(log_weight), n,
                                             batch_size)
    evaluations += n
    unresolved = design.unresolved + int(np.count_nonzero(unevaluable))
    if not np.any(failed | unevaluable):
        return flagged(STATUS_NO_FAILURE, f"importance sampling found no failure among the "
                                          f"{n} samples around the "
                                          f"{len(names)} design points: no probability "
                                          "estimated", evaluations, unresolved,
                       common), design
    return weighted_result(failed, unevaluable, w, z, evaluations, unresolved, common), design


