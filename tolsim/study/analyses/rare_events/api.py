"""One call for a user's own limit state: :func:`estimate` picks an estimator by name and adds
the cross-checks that keep a wrong number from being reported as ``ok``
(:mod:`tolsim.rare_events` is its public home)."""

import math
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from tolsim.study.analyses.rare_events.common import (
    check_confidence,
    check_dimension,
    clip_unit,
    seed_sequence,
)
from tolsim.study.analyses.rare_events.form import find_design_points
from tolsim.study.analyses.rare_events.importance import importance_sampling
from tolsim.study.analyses.rare_events.monte_carlo import monte_carlo
from tolsim.study.analyses.rare_events.result import (
    STATUS_ESTIMATORS_DISAGREE,
    STATUS_NO_FAILURE,
    STATUS_OK,
    STATUSES,
    RareEventResult,
)
from tolsim.study.analyses.rare_events.subset import MODE_LIMIT, subset_simulation

#: ``method`` names of :func:`estimate`.
METHODS = ("subset", "importance", "rare", "monte_carlo")
#: Subset simulation is flagged when the probability of the design points FORM finds (the sum
#: of Breitung's SORM estimates, FORM's where the curvatures are not known) exceeds the upper
#: end of subset's interval by this factor (a lost failure mode). On RP110 runs that lost the
#: dominant mode it is 8-1000; on the sound problems (and a ball of failure off the origin,
#: where FORM alone is 100 times too high) below 2.
FORM_SUBSET_LIMIT = 5.0
#: Confidence level of the agreement test of ``method="rare"`` (:func:`agree`).
AGREEMENT_LEVEL = 0.99
#: ``method="rare"``: subset simulation at half its own default size (500 samples per level),
#: importance sampling at its own (2000 samples), and one FORM search (importance sampling's,
#: at most as many evaluations as its samples) whose design points serve both, so that
#: ``rare`` costs about one estimator alone plus FORM. The combination's variance is mostly
#: importance sampling's (CV ~0.05 against subset's ~0.2-0.5); subset simulation is there
#: to cross-check it. With importance sampling at 1000 samples too, the combination covered
#: only 90 % on RP35 (100 repeats, ``benchmarks/rare_event_coverage.py``).
RARE_SAMPLES_PER_LEVEL = 500
RARE_IMPORTANCE_SAMPLES = 2000
#: Key of the FORM cross-check's seed under the caller's seed (so it does not share streams
#: with the estimator itself).
CHECK_STREAM = 0x63686B  # 'chk'


def estimate(g, dimension, method="rare", seed=0, **options) -> RareEventResult:
    """P(g(U) <= 0), U ~ N(0, I_d), by a rare-event estimator with its diagnostics.

    Parameters
    ----------
    g : callable
        The limit state: an (n, d) array of independent standard-normal points -> (n,)
        values; **failure where g <= 0**, NaN for a point that cannot be evaluated (counted
        and bounded, :mod:`~tolsim.study.analyses.rare_events.result`). Map your physical
        inputs from u inside g (e.g. ``x = mean + std * u``, or ``scipy.stats`` ``ppf(ndtr(u))``).
    dimension : int
        d.
    method : {"rare", "subset", "importance", "monte_carlo"}
        ``"subset"``
            FORM from several starts (at most n evaluations, seeded from the child
            (CHECK_STREAM,) of ``seed``), then subset simulation (any limit state, smooth or
            not; cost about n (1 + 0.9 log10(1 / P))) checked against every design point
            (:func:`~tolsim.study.analyses.rare_events.subset.lost_modes`:
            ``"diagnostic_failed"`` when one holds far more than the chains found near it),
            and flagged ``"estimators_disagree"`` when the design points hold (second order)
            more than :data:`FORM_SUBSET_LIMIT` times the upper end of subset's interval.
            ``form_check=False`` skips both.
        ``"importance"``
            FORM from several starts and importance sampling around every design point found
            (smooth limit states; the cheapest for a small P), with its diagnostics.
        ``"rare"`` (default)
            Both, from the two children of :func:`estimator_seeds` (subset simulation the
            first, importance sampling the second), sharing one FORM search (its design
            points serve importance sampling and subset's mode check), subset simulation at
            :data:`RARE_SAMPLES_PER_LEVEL` samples per level unless ``subset=`` says
            otherwise. Cross-checked: when both are ``ok`` and agree (:func:`agree`), the
            inverse-variance combination of the two (status ``ok``); when subset simulation
            is flagged for a failure mode it lost that explains its gap to importance
            sampling (:func:`lost_mode_explains`), importance sampling's result (``ok``, the
            message naming subset simulation as set aside); when one is flagged by
            its own diagnostics but agrees with the other, the other's result;
            otherwise status ``"estimators_disagree"`` (or the flag of a failing one, when
            neither has a trusted number), with both numbers in the message.
        ``"monte_carlo"``
            Plain Monte Carlo (``samples``, default 100 000): the reference for P >~ 1e-3.
    seed : int or numpy.random.SeedSequence
        Same seed, same result (bit for bit).
    **options
        Passed on to the estimator: :func:`subset_simulation` (``samples_per_level``,
        ``p0``, ``max_levels``, ``sampler``), :func:`importance_sampling` (``samples``,
        ``restarts``, ``gradient``), :func:`monte_carlo` (``samples``); all take
        ``batch_size`` and ``confidence_level``. ``"rare"`` takes ``subset=`` and
        ``importance=`` dicts of options for each; ``"subset"`` takes ``form_check``.

    Returns
    -------
    RareEventResult
        With ``status`` ``"ok"`` only when every diagnostic passed (the statuses and fields
        are documented on :class:`~tolsim.study.analyses.rare_events.result.RareEventResult`).

    Examples
    --------
    >>> import numpy as np
    >>> from tolsim.rare_events import estimate
    >>> r = estimate(lambda u: 4.0 - u[:, 0], 2, method="importance", seed=1)
    >>> r.ok, 2e-5 < r.probability < 5e-5          # Phi(-4) = 3.17e-5
    (True, True)
    """
    d = check_dimension(dimension)
    root = seed_sequence(seed)
    if method == "monte_carlo":
        return monte_carlo(g, d, root, **options)
    if method == "importance":
        return importance_sampling(g, d, root, **options)
    if method == "subset":
        if not options.pop("form_check", True):
            return subset_simulation(g, d, root, **options)
        found = find_design_points(g, d, check_sequence(root),
                                   max_evaluations=options.get("samples_per_level", 1000),
                                   batch_size=options.get("batch_size"))
        result = subset_simulation(g, d, root, design_points=found.points, **options)
        return form_cross_check(result, found)
    if method == "rare":
        unknown = set(options) - {"subset", "importance", "batch_size", "confidence_level"}
        if unknown:
            raise TypeError(f"method 'rare' takes subset=, importance=, batch_size= and "
                            f"confidence_level=; got {sorted(unknown)}")
        for name in ("subset", "importance"):
            if not isinstance(options.get(name, {}), Mapping):
                raise TypeError(f"{name} = {options[name]!r} must be a dict of the options of "
                                f"method {name!r} (or left out)")
        common = {k: options[k] for k in ("batch_size", "confidence_level") if k in options}
        sub_options = {"samples_per_level": RARE_SAMPLES_PER_LEVEL,
                       **options.get("subset", {})}
        imp_options = {"samples": RARE_IMPORTANCE_SAMPLES, **options.get("importance", {})}
        search = {k: imp_options.pop(k) for k in ("restarts", "gradient", "step")
                  if k in imp_options}
        sub_seed, imp_seed = estimator_seeds(root)
        # one FORM search, seeded and budgeted as importance sampling's own would be (so its
        # part is the number method "importance" gives with imp_seed); its design points
        # serve importance sampling and subset's mode check
        found = find_design_points(g, d, imp_seed, max_evaluations=imp_options["samples"],
                                   batch_size=options.get("batch_size"), **search)
        sub = subset_simulation(g, d, sub_seed, design_points=found.points, **common,
                                **sub_options)
        imp = importance_sampling(g, d, imp_seed, design_points=found, **common,
                                  **imp_options)
        imp = replace(imp, evaluations=imp.evaluations + found.evaluations)
        return combine(sub, imp)
    raise ValueError(f"method = {method!r}; choose one of {METHODS}")


def estimator_seeds(root):
    """The SeedSequences of subset simulation and importance sampling in ``method="rare"``
    (and ``estimator = "rare"``): the two children that ``root.spawn(2)`` gives a fresh copy
    of ``root`` (spawn keys (..., 0) and (..., 1)), so that the estimators draw from
    independent streams and the caller's sequence is not advanced (same seed, same result)."""
    return np.random.SeedSequence(root.entropy, spawn_key=root.spawn_key,
                                  pool_size=root.pool_size).spawn(2)


def check_sequence(root):
    """The child (CHECK_STREAM,) of ``root``: the seed of the FORM search of
    ``method="subset"`` (not a stream of subset simulation itself)."""
    return np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, CHECK_STREAM),
                                  pool_size=root.pool_size)


def form_cross_check(result, found):
    """Subset's ``result`` with FORM's design points ``found`` (a
    :class:`~tolsim.study.analyses.rare_events.form.DesignPointSet`; their evaluations
    added), flagged ``"estimators_disagree"`` when their probability far exceeds its interval.

    Only a FORM probability far *above* subset's interval flags: FORM is often far off on a
    curved limit state, but design points that hold much more than subset found mean the
    chains never reached that part of the failure domain. (Per design point, the check of
    :func:`~tolsim.study.analyses.rare_events.subset.lost_modes` has already run in
    subset simulation.)
    """
    result = replace(result, evaluations=result.evaluations + found.evaluations,
                     form_probability=found.form_probability,
                     design_points=(np.array([p.point for p in found.points])
                                    if found.points else None),
                     betas=tuple(float(b) for b in found.betas))
    if not (result.ok and found.points):
        return result
    # second order where the curvatures are known (FORM alone is 100 times too high on a
    # ball of failure off the origin), first order elsewhere
    second = float(np.sum([p.sorm_probability if np.isfinite(p.sorm_probability)
                           else p.form_probability for p in found.points]))
    if second > FORM_SUBSET_LIMIT * result.ci_upper:
        return replace(result, status=STATUS_ESTIMATORS_DISAGREE, message=(
            f"FORM's {len(found.points)} design point(s) give P = {second:.3g} (second "
            f"order), more than {FORM_SUBSET_LIMIT:g} times the upper end "
            f"{result.ci_upper:.3g} of subset simulation's interval: the chains may have "
            "lost a failure mode; use method 'importance' or 'rare'"))
    return result


def agree(a, b) -> bool:
    """Whether two estimates agree: |ln P_a - ln P_b| <= z sqrt(s_a^2 + s_b^2) with
    s^2 = ln(1 + CV^2) and z the two-sided 99 % normal quantile (:data:`AGREEMENT_LEVEL`), a
    test of equal P at a 1 % false-alarm rate when both CVs are right. Their 95 % intervals
    failing to overlap is a stricter, 0.5 % test only for equal CVs, and with a lognormal and a
    normal interval side by side it alarmed in 2-7 % of the runs on the sound problems."""
    if not (a.probability > 0 and b.probability > 0):
        return not (a.ci_upper < b.ci_lower or b.ci_upper < a.ci_lower)
    s2 = math.log1p(a.coefficient_of_variation ** 2) + math.log1p(b.coefficient_of_variation ** 2)
    z = check_confidence(AGREEMENT_LEVEL)
    return abs(math.log(a.probability / b.probability)) <= z * math.sqrt(s2)


def replicated_subset(g, dimension, seed, *, samples_per_level=1000, **options):
    """Subset simulation twice, from the two children of :func:`estimator_seeds` (the same
    streams as ``method="rare"``), at ``samples_per_level`` each, cross-checked by
    :func:`combine_replicates`: the check for a lost failure mode where FORM has no design
    point (a limit state that is not smooth).

    Parameters
    ----------
    g : callable
    dimension : int
    seed : int or numpy.random.SeedSequence
    samples_per_level : int
        Of each run (a study runs each at its configured size: twice one run's cost).
    **options
        Of :func:`~tolsim.study.analyses.rare_events.subset_simulation` (no
        ``design_points``: with design points, their own check applies).

    Returns
    -------
    (RareEventResult, (RareEventResult, RareEventResult))
        The cross-checked result and the two runs.

    Notes
    -----
    A run that loses a failure mode (its chains never reach it, e.g. RP110 of RPRepo, where
    the mode that holds most of P is a small share of the failing samples at the first
    levels) returns a number far below the truth with an interval that does not cover it, and
    nothing in the run itself shows it. Two independent runs lose the mode independently:
    when one finds it and the other does not, their numbers differ beyond their CVs
    (:func:`agree`) and the result is ``"estimators_disagree"``. What the check cannot see is
    a mode that *both* runs miss: with a probability q that one run misses it, both miss with
    about q^2 and then agree on the same wrong number, ``ok``. Over 200 seeds at 1 000 samples
    per level: on a two-mode variant of RP110 one run was wrongly ``ok`` 34 times and the pair
    13 times; on RP110 itself one run 125 times and the pair 52 times
    (``tests/study/test_rare_replicates.py``). Replication narrows, never closes, the gap that
    a design-point check closes on a smooth limit state; halving each run to keep the cost of
    one made it no better on RP110 (each half-size run loses the mode about 95 % of the time).
    """
    root = seed_sequence(seed)
    first, second = (subset_simulation(g, dimension, child, samples_per_level=samples_per_level,
                                       **options) for child in estimator_seeds(root))
    return combine_replicates(first, second), (first, second)


def estimate_text(name, result) -> str:
    """'importance sampling 0.0012 [0.0011, 0.0013]': an estimate with its interval for a
    message that names both estimates, or what the estimator found instead of a number
    ('importance sampling found no failure', or the status's meaning), never
    'nan [nan, nan]'."""
    if np.isfinite(result.probability):
        return (f"{name} {result.probability:.3g} [{result.ci_lower:.3g}, "
                f"{result.ci_upper:.3g}]")
    if result.status == STATUS_NO_FAILURE:
        return f"{name} found no failure"
    why = STATUSES.get(result.status, result.status).split(":")[0]
    return f"{name} gave no estimate ({why})"


def combine_replicates(first, second) -> RareEventResult:
    """The cross-check of two independent subset simulations (:func:`replicated_subset`).

    Both ``ok`` and agreeing (:func:`agree`): their mean, ``ok`` (P = (P_1 + P_2) / 2,
    se = (se_1^2 + se_2^2)^(1/2) / 2, a normal interval: the inverse-variance combination
    with the two runs' true variances, equal by design; the levels, thresholds and chain
    diagnostics are the first run's, ``ancestors`` the two runs' sum). Both ``ok`` and
    disagreeing: the run with the larger P (a lost mode makes a run low, never high), status
    ``"estimators_disagree"``, both numbers in the message. One or both not ``ok``: the flag
    of a failing one, with the other's number when it is ``ok`` and the failing one has a
    number (then ``"estimators_disagree"``: a run that could not finish is no check), as in
    :func:`combine`.
    """
    both = f"{estimate_text('first run', first)}, {estimate_text('second run', second)}"
    evaluations = first.evaluations + second.evaluations
    ancestors = first.ancestors + second.ancestors
    if not first.ok or not second.ok:
        bad, keep, status = flagged_pair(first, second)
        which = "first" if bad is first else "second"
        return replace(keep, status=status, evaluations=evaluations, ancestors=ancestors,
                       message=f"{which} subset simulation run not ok: {bad.message}; {both}")
    if not agree(first, second):
        high = first if first.probability >= second.probability else second
        return replace(high, status=STATUS_ESTIMATORS_DISAGREE, evaluations=evaluations,
                       ancestors=ancestors, message=(
                           "two independent subset simulation runs differ beyond their CVs "
                           f"(99 % test; one may have lost a failure mode): {both}; the "
                           "larger is given"))
    # equal weights: the inverse-variance weights of the two runs' true variances, which are
    # equal (same design); weights from the estimated variances (se ~ CV P) favour the lower
    # run and biased the combination low (linear problem at 1e-5, 200 repeats: median 0.86
    # of the truth, coverage 79 %)
    p = 0.5 * (first.probability + second.probability)
    se = 0.5 * math.hypot(first.standard_error, second.standard_error)
    z = check_confidence(first.confidence_level)
    ci = (clip_unit(p - z * se), clip_unit(p + z * se))  # a probability: in [0, 1]
    unresolved = first.unresolved + second.unresolved
    bounds = ((p, p, *ci) if not unresolved else
              (min(first.bound_lower, second.bound_lower),
               max(first.bound_upper, second.bound_upper),
               min(first.bounds_ci_lower, second.bounds_ci_lower),
               max(first.bounds_ci_upper, second.bounds_ci_upper)))
    se_independent = 0.5 * math.hypot(*(r.level_independent_cv * r.probability
                                        for r in (first, second)))
    return replace(
        first, probability=p, standard_error=se,
        coefficient_of_variation=se / p if p > 0 else float("inf"),
        ci_lower=ci[0], ci_upper=ci[1],
        interval="mean of two independent subset simulation runs, normal (approximate)",
        evaluations=evaluations, unresolved=unresolved,
        failures=first.failures + second.failures, bound_lower=bounds[0],
        bound_upper=bounds[1], bounds_ci_lower=bounds[2], bounds_ci_upper=bounds[3],
        ancestors=ancestors, level_independent_cv=se_independent / p if p > 0 else float("nan"),
        message="")


def lost_mode_explains(sub, imp) -> bool:
    """Whether subset simulation's lost failure mode explains its gap to importance sampling.

    True when importance sampling passed all of its diagnostics, subset simulation was flagged
    by its check against the design points for a lost mode (``lost_mode_mass`` > 0,
    :func:`~tolsim.study.analyses.rare_events.subset.lost_modes`: design points that hold far
    more than the chains found near them), importance sampling's P is above subset's (a lost
    mode makes subset low, never high) and within a factor :data:`MODE_LIMIT` of subset's P plus
    the mass it lost (FORM's estimate of the lost modes is first or second order, so only a
    factor is asked). Then importance sampling, which sampled around those design points,
    stands (RP110 of RPRepo: 70 of 100 runs of ``method="rare"`` refused before; see
    :func:`combine`). Any other gap between the two is a disagreement.
    """
    if not (imp.ok and sub.lost_mode_mass > 0 and np.isfinite(sub.probability)
            and imp.probability > sub.probability):
        return False
    explained = sub.probability + sub.lost_mode_mass
    return explained / MODE_LIMIT <= imp.probability <= MODE_LIMIT * explained


def flagged_pair(a, b):
    """(the failing one, the one whose number is kept, the status) of two estimates of which
    at least one is not ``ok``: the other's number when it is ``ok``, with status
    ``"estimators_disagree"`` when the failing one has a number too (it does not back the
    other), else the failing one's status (and its number when neither is ``ok``)."""
    bad = a if not a.ok else b
    other = b if bad is a else a
    keep = other if other.ok else bad
    status = bad.status if not np.isfinite(bad.probability) or not other.ok \
        else STATUS_ESTIMATORS_DISAGREE
    return bad, keep, status


def _diagnostics_for(subset_stands, diagnostics) -> dict:
    """The cross-check's ``diagnostics`` that go with the result of the estimator that
    stands: with subset simulation's, all but ``level_independent_cv`` (already its own);
    with importance sampling's, all but subset's ``ancestors``."""
    return {k: v for k, v in diagnostics.items()
            if (k == "ancestors") == subset_stands or k not in
            ("ancestors", "level_independent_cv")}


def combine(sub, imp) -> RareEventResult:
    """The cross-check of subset simulation and importance sampling (``method="rare"``).

    Both ``ok`` and agreeing (:func:`agree`): their inverse-variance combination (when one
    has a standard error of 0, an event that is not rare, the other's result). Subset
    simulation flagged for a lost failure mode that explains its gap
    (:func:`lost_mode_explains`): importance sampling's result, ``ok``, its message naming
    the subset simulation set aside. One flagged by its own diagnostics but agreeing with the
    other: the other's result. Otherwise ``"estimators_disagree"`` (or the flag of a failing
    one, when neither has a trusted number), both numbers in the message.
    """
    both = (f"{estimate_text('subset simulation', sub)}, "
            f"{estimate_text('importance sampling', imp)}")
    evaluations = sub.evaluations + imp.evaluations
    diagnostics = dict(design_point=imp.design_point, beta=imp.beta,
                       form_probability=imp.form_probability,
                       importance_factors=imp.importance_factors,
                       design_points=imp.design_points, betas=imp.betas,
                       effective_sample_size=imp.effective_sample_size,
                       largest_weight_share=imp.largest_weight_share,
                       form_ratio=imp.form_ratio, ancestors=sub.ancestors,
                       level_independent_cv=sub.level_independent_cv)
    overlap = agree(sub, imp)
    if lost_mode_explains(sub, imp):
        # subset simulation lost a failure mode that FORM found and importance sampling
        # sampled around, and the mass it lost accounts for the gap: subset is the suspect
        return replace(imp, estimator="rare", evaluations=evaluations, message=(
            f"subset simulation set aside ({sub.status}): {sub.message}; the design points' "
            f"mass it lost, {sub.lost_mode_mass:.3g}, accounts for the gap: {both}"),
            **{k: v for k, v in diagnostics.items()
               if k not in ("ancestors", "level_independent_cv")})
    if sub.ok != imp.ok and overlap:
        # one flagged by its own diagnostic, but its number agrees with the other's, which
        # passed all of its own: the one that passed stands
        good, bad = (sub, imp) if sub.ok else (imp, sub)
        names = ("subset simulation", "importance sampling")
        kept, aside = names if good is sub else names[::-1]
        return replace(good, estimator="rare", evaluations=evaluations, message=(
            f"{aside} set aside ({bad.status}: {bad.message}); its number agrees with "
            f"{kept}'s, which is given: {both}"), **_diagnostics_for(good is sub, diagnostics))
    if not sub.ok or not imp.ok:
        bad, keep, status = flagged_pair(sub, imp)
        message = (f"{'subset simulation' if bad is sub else 'importance sampling'} not ok: "
                   f"{bad.message}; {both}")
        return replace(keep, estimator="rare", status=status, message=message,
                       evaluations=evaluations,
                       **{k: v for k, v in diagnostics.items() if k != "ancestors"
                          or keep is imp})
    if not overlap:
        return replace(sub, estimator="rare", status=STATUS_ESTIMATORS_DISAGREE,
                       message=f"the estimates differ beyond their CVs (99 % test): {both}",
                       evaluations=evaluations, **diagnostics)
    if not (sub.standard_error > 0 and imp.standard_error > 0):
        # a standard error of 0 (every or no sample failing at subset's level 0, an event
        # that is not rare) has no inverse-variance weight: the other number, which agrees
        zero = "subset simulation" if not sub.standard_error > 0 else "importance sampling"
        good = imp if zero == "subset simulation" else sub
        return replace(good, estimator="rare", evaluations=evaluations, message=(
            f"{zero} has a standard error of 0 (every or no sample failed): not combined, "
            f"the other estimate is given; {both}"), **_diagnostics_for(good is sub, diagnostics))
    weights = np.array([1.0 / sub.standard_error ** 2, 1.0 / imp.standard_error ** 2])
    p = float(np.dot(weights, [sub.probability, imp.probability]) / weights.sum())
    se = 1.0 / math.sqrt(float(weights.sum()))
    z = check_confidence(sub.confidence_level)
    ci = (clip_unit(p - z * se), clip_unit(p + z * se))  # a probability: in [0, 1]
    unresolved = sub.unresolved + imp.unresolved
    # the bounds: the combined estimate and its interval when every row was resolved (the
    # three coincide, :mod:`~tolsim.study.analyses.rare_events.result`), else the hull of the
    # two estimators' bounds
    bounds = ((p, p, *ci) if not unresolved else
              (min(sub.bound_lower, imp.bound_lower), max(sub.bound_upper, imp.bound_upper),
               min(sub.bounds_ci_lower, imp.bounds_ci_lower),
               max(sub.bounds_ci_upper, imp.bounds_ci_upper)))
    return RareEventResult(
        estimator="rare", probability=p, standard_error=se,
        coefficient_of_variation=se / p if p > 0 else float("inf"),
        ci_lower=ci[0], ci_upper=ci[1], confidence_level=sub.confidence_level,
        interval="inverse-variance combination of subset simulation and importance "
                 "sampling, normal (approximate)",
        evaluations=evaluations, dimension=sub.dimension, status=STATUS_OK,
        message="", unresolved=unresolved, failures=imp.failures, bound_lower=bounds[0],
        bound_upper=bounds[1], bounds_ci_lower=bounds[2], bounds_ci_upper=bounds[3],
        samples_per_level=sub.samples_per_level, thresholds=sub.thresholds,
        level_probabilities=sub.level_probabilities,
        level_coefficients_of_variation=sub.level_coefficients_of_variation,
        chain_correlation_factors=sub.chain_correlation_factors,
        acceptance_rates=sub.acceptance_rates, **diagnostics)
