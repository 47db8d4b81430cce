"""Subset simulation ([AuBeck2001]) of a failure probability over a standard-normal space
(:mod:`tolsim.study.analyses.rare_events`).

Subset simulation
-----------------
Level 0 draws n independent samples. While fewer than N_c = p0 n of the current level's
samples fail, the next threshold is b = (g_(N_c) + g_(N_c + 1)) / 2 (sorted values,
[AuBeck2001]), the N_c samples below it are the seeds, and each seed starts a chain of
N_s = n / N_c states (the seed is the chain's first state), so each level holds n samples
and costs n - N_c model calls. When g_(N_c) = g_(N_c + 1) (a chain state repeated by
rejections straddles the quantile) b is that value and P_j the share of samples at or
below it (a little above p0). The level at which at least N_c samples fail is the last
one, with P_m = (failures) / n.

Markov chains, ``sampler=``:

* ``"conditional"`` (default): adaptive conditional sampling in standard-normal space
  (aCS, [Papaioannou2015]). The candidate is
  v_k = rho_k u_k + sqrt(1 - rho_k^2) z_k, z ~ N(0, I), which leaves N(0, I) invariant, so
  it is accepted iff g(v) <= b. With sigma_k = sqrt(1 - rho_k^2) = min(1, lambda s_k),
  s_k the sample standard deviation of the seeds in component k, and lambda adapted towards
  the acceptance rate a* = 0.44: log lambda += (a_hat - a*) / sqrt(i) after adaptation
  step i (lambda = 0.6 at the first level, then carried over). One change from the paper:
  [Papaioannou2015] adapts after each group of N_a = 0.1 N_c chains run one after the
  other; here all chains advance together, one step at a time, so that the limit state is
  evaluated on all chains of a step as one batch, and lambda is adapted after each step
  from the acceptance rate over all chains (n / N_c - 1 = 9 adaptations per level at
  p0 = 0.1, as with the paper's ten groups).
* ``"metropolis"``: the modified Metropolis algorithm of [AuBeck2001]: component
  by component a uniform proposal of half-width 1 around the current state, accepted with
  probability min(1, phi(xi_k) / phi(u_k)), then the candidate accepted iff g <= b. A
  candidate equal to the current state is not evaluated.

Randomness: the initial level draws fixed-size blocks of :data:`BLOCK_ROWS` rows, block k
from the child (RARE_EVENT_STREAM, 0, k) of the given SeedSequence; chain c of level j
draws all its proposals from the child (RARE_EVENT_STREAM, j, c). Children are built from
the sequence's entropy and spawn key (the caller's SeedSequence is not spawned from, so it
is not changed). The candidates of all chains of a step are evaluated in one batch, in
chain order (split into ``batch_size`` rows if given): the result is bit-identical
whatever the batch size or the number of workers evaluating the rows, provided the limit
state's value of a row does not depend on the other rows of the call (beware a BLAS product
such as ``u @ a``, whose last bit may change with the number of rows).

Coefficient of variation and interval. Au & Beck's CV of the estimate of level j from n
correlated samples (N_c chains of N_s = n / N_c states; [AuBeck2001], Eq. 29 ff.) is ::

    delta_j^2 = (1 - P_j) / (n P_j) (1 + gamma_j),
    gamma_j   = 2 sum_{k=1}^{N_s - 1} (1 - k N_c / n) rho_j(k),

rho_j(k) = R_j(k) / R_j(0) the lag-k correlation of the level's indicator along the chains,
R_j(k) = sum_c sum_l I_{c,l} I_{c,l+k} / (n - k N_c) - P_j^2, R_j(0) = P_j (1 - P_j)
(:func:`chain_correlation_factor`). It takes the N_c chains as independent. They are not:
chains whose seeds come from one chain of the level before (often copies of one repeated
state) are correlated. tolsim therefore estimates the variance of P_j over chain
*families*, the chains seeded from one chain of the level before, as a cluster-sampling
variance (the assembly as the sampling unit of :mod:`tolsim.study.statistics.intervals`, here the
family), which holds the correlation along each chain as well (:func:`level_statistics`)::

    delta_j^2 = K / (K - 1) sum_F (S_F - P_j n_F)^2 / (n P_j)^2

(S_F the indicator sum and n_F the samples of family F, K families; level 0 is binomial,
(1 - P_0) / (n P_0)). Au & Beck's gamma_j is reported beside it
(``chain_correlation_factors``). The CV of P = prod P_j is delta^2 = prod (1 + delta_j^2) - 1
(independent factors), and the interval is lognormal, P exp(-+ t s) with
s^2 = sum_j ln(1 + delta_j^2) and t the Student-t quantile at the Satterthwaite degrees of
freedom (sum_j s_j^2)^2 / sum_j (s_j^4 / df_j), df_j = Kish's effective number of families
of level j minus 1 (a variance from a few dozen families is itself uncertain; typically 30-40
df, a 4-5 % wider interval than the normal quantile).

**Correlation across levels and generations (issue 23).** The per-level CVs above neglect
the correlation between levels (a level's seeds are the samples of the one before, and all
chains of a level share its threshold, proposal spread and scale): measured on the linear
limit state (d = 6, n = 1000, p0 = 0.1, 1000 repeats) they covered 95.2 / 93.4 %,
94.3 / 93.7 % and 92.6 / 91.9 % at 1e-3, 1e-5 and 1e-7, with a reported CV of 0.42 at 1e-7
for an observed 0.49-0.50, and 90.8-92.4 % on RP25/35/107/111 of RPRepo. The CV is now the
larger of that and the *genealogical* CV (:func:`ancestral_log_variance`): every sample of
every level descends from one level-0 sample (its "Eve"); ln P linearised is a sum over all
samples, and grouping its terms by Eve gives independent clusters whose spread holds the
correlation along the chains of all generations and between the levels, as the variance
estimators of particle filters do ([ChanLai2013], [LeeWhiteley2018]; subset simulation is a
sequential Monte Carlo sampler). The Student-t degrees of freedom stay those of the levels.
On the same linear case (150 repeats) this covers 96 % at 1e-5 and 95 % at 1e-7 (reported CV
0.46 for an observed 0.47), 93 % on the ball off the origin.

**A lost mode.** ``ancestors`` counts the distinct Eves of the last level's failing samples.
With fewer than :data:`MIN_ANCESTORS` (3), the chains have collapsed onto the offspring of one
or two level-0 samples: the result is ``"diagnostic_failed"`` (its number kept). On the linear
case at 1e-7 the count is 6-25 (median 10). Subset simulation cannot see a failure mode that
its intermediate levels never visited (RP110 of RPRepo, where the mode that dominates at
g <= 0 is rare at the intermediate thresholds, is lost in about half of the runs with many
ancestors). Given FORM's design points (``design_points=``; :func:`tolsim.rare_events.estimate`
passes them with ``method="subset"`` and ``"rare"``), :func:`lost_modes` compares each design
point's own probability with subset's estimate of the mass near it, and a mode the chains
lost, or kept with too few of them, makes the result ``"diagnostic_failed"`` when the mass
missing there, sum (P_k - subset's mass around u*_k) over those design points, exceeds
ci_upper - P (it would put the truth above subset's interval): on RP110 (100
repeats) subset simulation alone was ``ok`` in 81 runs with 27 % coverage, with the check
in 23 with 96 % (``method="subset"``). The second condition (added with the studies' series
events) keeps a mode that holds a small share of P from flagging a number whose interval
covers it anyway: the nine pairs of ``configs/rare_contact.toml`` (each 1/9 to 1/5 of P)
flagged 5 of 6 runs without it, every estimate within 0.77-1.1 of the truth; on RP35 the
check alone flagged 15 runs of 100 (one of the three design points with almost no failing
sample near it; the other 85 covered 98 %), with the condition none, and all 100 covered
97 %.

The interval also neglects the estimate's bias of order 1 / n.

If no level has N_c failures within ``max_levels`` levels, or the limit state is flat at a
p0-quantile (no threshold between tied values), the result is flagged (``status``), its
probability NaN, and ``message`` says why in one line. Without a failure the message tells
two causes apart, since they call for opposite advice (:func:`no_failure_message`): the
level budget ran out while the thresholds were still closing in on 0 (raise ``max_levels``,
to about the number of levels the last ones' rate extrapolates to), or g has *stalled*: at
the mean fall of the last :data:`STALL_WINDOW` thresholds, g = 0 lies so far that the levels
run and those to go exceed :data:`STALLED_LEVELS` (P of order p0^50 = 1e-50 at p0 = 0.1 or
less, far below any probability a design is judged by), and more levels do not help. On a
train whose gaps (5-6 mm) no tolerance can close, the thresholds fell by about 9e-6 m a
level at g ~ 4.7e-3 m: some 500 levels to go; with gaps of 0.9-1 mm, about 95 (P ~ 1e-100).
The extrapolation is linear, while the thresholds of a smooth limit state fall ever more
slowly: the number of levels it gives is a lower bound, the P it implies an upper one.

References
----------
.. [AuBeck2001] S.-K. Au, J. L. Beck, "Estimation of small failure probabilities in high
   dimensions by subset simulation", Prob. Eng. Mech. 16 (2001) 263-277,
   doi:10.1016/S0266-8920(01)00019-4.
.. [Papaioannou2015] I. Papaioannou, W. Betz, K. Zwirglmaier, D. Straub, "MCMC algorithms
   for Subset Simulation", Prob. Eng. Mech. 41 (2015) 89-103,
   doi:10.1016/j.probengmech.2015.06.006.
.. [ChanLai2013] H. P. Chan, T. L. Lai, "A general theory of particle filters in hidden Markov
   models and some applications", Ann. Statist. 41 (2013) 2877-2904, doi:10.1214/13-AOS1172.
.. [LeeWhiteley2018] A. Lee, N. Whiteley, "Variance estimation in the particle filter",
   Biometrika 105 (2018) 609-625, doi:10.1093/biomet/asy028.
"""

import math
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from scipy.special import ndtri
from scipy.stats import t as t_distribution

from tolsim.study.analyses.rare_events.common import (
    check_batch_size,
    check_confidence,
    check_count,
    check_dimension,
    child_sequence,
    evaluate,
    normal_blocks,
    seed_sequence,
)
from tolsim.study.analyses.rare_events.result import (
    INTERVAL_CLOPPER_PEARSON,
    INTERVAL_LOGNORMAL,
    STATUS_DIAGNOSTIC_FAILED,
    STATUS_NO_FAILURE,
    STATUS_OK,
    STATUS_PLATEAU,
    STATUS_UNRESOLVED,
    RareEventResult,
    flagged,
)
from tolsim.study.statistics.intervals import clopper_pearson_interval

#: Fewest chains (n p0) of subset simulation.
MIN_CHAINS = 10
#: Fewest distinct level-0 ancestors of the last level's failures before the result is
#: flagged (module docstring).
MIN_ANCESTORS = 3
#: A FORM design point whose probability (second order where known) exceeds this many times
#: subset simulation's estimate of the mass around it flags a lost mode
#: (:func:`lost_modes`).
MODE_LIMIT = 5.0
#: Without a failure: the thresholds whose mean fall per level extrapolates to g = 0, and the
#: most levels, run and to go at that rate, before g is called stalled (module docstring).
STALL_WINDOW = 5
STALLED_LEVELS = 50
#: Adaptive conditional sampling ([Papaioannou2015]): initial scale and target acceptance.
INITIAL_SCALE = 0.6
TARGET_ACCEPTANCE = 0.44
#: Half-width of the uniform component proposal of the modified Metropolis algorithm.
METROPOLIS_HALF_WIDTH = 1.0


def subset_simulation(limit_state, dimension, seed, *, samples_per_level=1000, p0=0.1,
                      max_levels=20, sampler="conditional", batch_size=None,
                      confidence_level=0.95, design_points=None) -> RareEventResult:
    """Subset simulation ([AuBeck2001]) with seeded chains; see the module docstring.

    Parameters
    ----------
    limit_state : callable
        g(u) for u of shape (rows, d) -> (rows,); failure where g <= 0, NaN unresolved.
    dimension : int
        d.
    seed : numpy.random.SeedSequence or int
    samples_per_level : int
        n; n p0 (the number of chains, at least :data:`MIN_CHAINS`) must be a whole number
        that divides n.
    p0 : float
        Conditional probability of each intermediate level, in (0, 0.5].
    max_levels : int
        Most sampling levels (level 0 included) before the result is flagged
        ``"no_failure"``: the smallest P it can reach is about p0^max_levels.
    sampler : {"conditional", "metropolis"}
        Adaptive conditional sampling ([Papaioannou2015]) or the modified Metropolis
        algorithm ([AuBeck2001]).
    batch_size : int, optional
        Most rows per call of ``limit_state``; the result does not depend on it.
    confidence_level : float
    design_points : sequence of DesignPoint, optional
        FORM's design points (e.g. ``find_design_points(...).points``): an ``ok`` result
        that they contradict (:func:`lost_modes`) becomes ``"diagnostic_failed"``. Costs no
        evaluation.

    Returns
    -------
    RareEventResult
        With ``thresholds``, ``level_probabilities``, ``level_coefficients_of_variation``,
        ``chain_correlation_factors`` and ``acceptance_rates``; the interval is the
        lognormal one with the CV (approximate), or Clopper-Pearson's when level 0 settles
        it (plain Monte Carlo: an event that is not rare). Flagged (``status``
        ``"no_failure"`` or ``"plateau"``, probability NaN) when no level reaches the failure
        domain, ``"unresolved"`` (with the bounds) when unresolved rows alone end the levels.
    """
    d = check_dimension(dimension)
    n = check_count("samples_per_level", samples_per_level, 1)
    if not (isinstance(p0, int | float | np.floating) and 0 < p0 <= 0.5):
        raise ValueError(f"p0 = {p0!r} must be in (0, 0.5]")
    chains = int(round(n * p0))
    if chains < MIN_CHAINS:
        raise ValueError(f"samples_per_level = {n} is too small for p0 = {p0:g}: it gives "
                         f"{chains} chains, at least {MIN_CHAINS} are needed "
                         f"(samples_per_level >= {math.ceil(MIN_CHAINS / p0)})")
    if abs(n * p0 - chains) > 1e-9 * n or n % chains:
        raise ValueError(f"samples_per_level = {n} with p0 = {p0:g}: n p0 = {n * p0:g} must "
                         "be a whole number of chains that divides n")
    max_levels = check_count("max_levels", max_levels, 1)
    try:
        step_chains = SAMPLERS[sampler]
    except (KeyError, TypeError):
        raise ValueError(f"sampler = {sampler!r}; choose one of {tuple(SAMPLERS)}") from None
    check_batch_size(batch_size)
    check_confidence(confidence_level)
    root = seed_sequence(seed)
    chain_length = n // chains

    u = np.concatenate(list(normal_blocks(root, (0,), n, d)))
    g = evaluate(limit_state, u, batch_size)
    evaluations = n
    unresolved = int(np.count_nonzero(np.isnan(g)))
    levels = _Levels()
    eve = np.arange(n)              # the level-0 sample each sample descends from
    scale = INITIAL_SCALE
    families = None                 # level 0: independent samples
    common = dict(estimator="subset", confidence_level=confidence_level, dimension=d,
                  samples_per_level=n)
    for level in range(max_levels):
        structure = None if families is None else (chains, chain_length, families)
        unevaluable = np.isnan(g)
        failed = g <= 0
        if np.count_nonzero(failed | unevaluable) >= chains:
            result = _subset_result(failed, unevaluable, structure, levels, evaluations,
                                    unresolved, confidence_level, common, eve)
            # level 0 is plain Monte Carlo: no chain to lose a mode (FORM's design points of
            # an event that is not rare overlap, and their sum flagged a right answer)
            return _check_modes(result, u[failed], design_points if level else None)
        key = np.where(unevaluable, -np.inf, g)
        order = np.argsort(key, kind="stable")
        below, above = key[order[chains - 1]], key[order[chains]]
        if level == max_levels - 1:
            return flagged(STATUS_NO_FAILURE,
                           no_failure_message(levels.thresholds, key[order[0]], max_levels, n,
                                              p0, int(np.count_nonzero(failed))),
                           evaluations, unresolved, common, **levels.fields())
        # b between the N_c-th and the next value; at a tie (a repeated chain state, or a
        # flat limit state) b is the tied value and P_j the share of samples at or below it
        threshold = 0.5 * (below + above) if below < above < np.inf else below
        if levels.thresholds and not threshold < levels.thresholds[-1]:
            return flagged(STATUS_PLATEAU,
                            f"the limit state is flat at the p0-quantile of level {level} "
                            f"(threshold {threshold:.6g} not below the previous one): no "
                            "progress towards g <= 0; no probability estimated",
                            evaluations, unresolved, common, **levels.fields())
        # N_c rows inside, more at a tie
        levels.add(threshold, level_statistics(key <= threshold, structure), key <= threshold,
                   eve)
        seeds = np.sort(order[:chains])              # the N_c lowest, in sample order
        # the family of a chain: the chain of the level before that holds its seed
        families = seeds if level == 0 else seeds // chain_length
        chain_seeds = [child_sequence(root, level + 1, c) for c in range(chains)]
        u, g, scale, rate, calls, nan_calls = step_chains(
            limit_state, u[seeds], g[seeds], threshold, chain_length, chain_seeds, scale,
            batch_size)
        levels.acceptance.append(rate)
        eve = np.repeat(eve[seeds], chain_length)
        evaluations += calls
        unresolved += nan_calls
    raise AssertionError("unreachable")  # the loop returns at its last level


def no_failure_message(thresholds, smallest, max_levels, samples_per_level, p0,
                       failures=0) -> str:
    """Why subset simulation found no failure, in one line: the level budget ran out, or g has
    stalled (module docstring); or, with ``failures`` > 0, why the few failures of its last
    level give no estimate.

    Parameters
    ----------
    thresholds : sequence of float
        b_1, ..., b_m of the levels run (decreasing; may be empty).
    smallest : float
        The smallest g of the last level.
    max_levels, samples_per_level : int
    p0 : float
    failures : int
        Samples of the last level with g <= 0 (fewer than its chains, n p0).
    """
    if failures:
        chains = int(round(samples_per_level * p0))
        return (f"subset simulation reached g <= 0 with only {failures} of {samples_per_level} "
                f"samples at its last level (level {max_levels} of max_levels = {max_levels}; "
                f"an estimate needs n p0 = {chains}); no probability estimated; raise "
                f"max_levels to {max_levels + 1} or more")
    head = (f"subset simulation found no failure (g <= 0) in {max_levels} level(s) of "
            f"{samples_per_level} samples (smallest g reached {smallest:.3g})")
    falls = -np.diff(np.asarray(thresholds, dtype=float))[-STALL_WINDOW:]
    if not falls.size or not np.all(falls > 0) or not thresholds[-1] > 0:
        return (f"{head}: the level budget ran out before its levels could show progress; no "
                "probability estimated; raise max_levels")
    rate = float(np.mean(falls))
    to_go = thresholds[-1] / rate
    exponent = (max_levels + to_go) * math.log10(p0)
    if max_levels + to_go > STALLED_LEVELS:
        return (f"{head}: g has stalled, its last {falls.size} thresholds fell by {rate:.3g} a "
                f"level on average, so g = 0 lies some {to_go:.0f} levels further (P of order "
                f"1e{exponent:.0f} or less); no probability estimated; more levels will not "
                "help: the event is out of reach of the inputs (check the limit state)")
    return (f"{head}: the level budget ran out while the thresholds were still falling "
            f"({rate:.3g} a level, g = 0 about {to_go:.0f} levels further, P of order "
            f"1e{exponent:.0f} or less); no probability estimated; raise max_levels to about "
            f"{max_levels + math.ceil(to_go) + 1}")


@dataclass
class _Levels:
    """What subset simulation records per level."""

    thresholds: list = field(default_factory=list)
    statistics: list = field(default_factory=list)
    acceptance: list = field(default_factory=list)
    indicators: list = field(default_factory=list)
    eves: list = field(default_factory=list)

    def add(self, threshold, statistics, indicator=None, eve=None):
        self.thresholds.append(float(threshold))
        self.statistics.append(statistics)
        if indicator is not None:
            self.indicators.append(indicator)
            self.eves.append(eve)

    def fields(self):
        return dict(thresholds=tuple(self.thresholds),
                    level_probabilities=tuple(x.probability for x in self.statistics),
                    level_coefficients_of_variation=tuple(x.coefficient_of_variation
                                                          for x in self.statistics),
                    chain_correlation_factors=tuple(x.chain_correlation_factor
                                                    for x in self.statistics),
                    acceptance_rates=tuple(self.acceptance))


def _subset_result(failed, unevaluable, structure, levels, evaluations, unresolved,
                   confidence_level, common, eve):
    """The last level: P_m with and without the unresolved rows, CVs, intervals, ancestors."""
    prefix = float(np.prod([x.probability for x in levels.statistics]))
    last_upper = level_statistics(failed | unevaluable, structure)
    last_lower = level_statistics(failed, structure)
    upper = prefix * last_upper.probability
    lower = prefix * last_lower.probability
    chained = bool(levels.indicators)          # level 0 alone: binomial, nothing to add
    up_hi = _lognormal_interval(
        upper, [*levels.statistics, last_upper], confidence_level,
        ancestral_log_variance([*levels.indicators, failed | unevaluable],
                               [*levels.eves, eve]) if chained else None)[1]
    independent_cv = _lognormal_interval(lower, [*levels.statistics, last_lower],
                                         confidence_level)[2]
    lo_lo, lo_hi, cv_lower, df = _lognormal_interval(
        lower, [*levels.statistics, last_lower], confidence_level,
        ancestral_log_variance([*levels.indicators, failed], [*levels.eves, eve])
        if chained else None)
    resolved = 1.0 - (upper - lower)                               # 1 - P(N), estimated
    if not np.any(failed):
        # the levels were ended by unresolved rows alone (g NaN over the region that would
        # fail, say): P = 0 with a NaN interval said "ok" for what may be up to the bound
        levels.add(0.0, last_upper)
        n = int(np.count_nonzero(unevaluable))
        return flagged(STATUS_UNRESOLVED, (
            f"no sample of the last level failed with a resolved g; its {n} unresolved ones "
            f"(g NaN) ended the levels: P is only known to lie in [0, {upper:.3g}]"),
            evaluations, unresolved, common, bound_lower=0.0, bound_upper=upper,
            bounds_ci_lower=0.0, bounds_ci_upper=up_hi if chained else
            clopper_pearson_interval(n, failed.size, confidence_level)[1], **levels.fields())
    p = lower / resolved
    interval = INTERVAL_LOGNORMAL
    ci = (lo_lo / resolved, lo_hi / resolved)
    bounds_ci = (lo_lo, up_hi)
    if not chained:
        # level 0 alone is plain Monte Carlo: the exact binomial intervals of
        # monte_carlo_probability, which the lognormal one is not near 0 or 1 (every sample
        # failing gave CV 0 and [1, 1])
        n, k = failed.size, int(np.count_nonzero(failed))
        m = int(np.count_nonzero(unevaluable & ~failed))
        ci = clopper_pearson_interval(k, n - m, confidence_level)
        bounds_ci = (clopper_pearson_interval(k, n, confidence_level)[0],
                     clopper_pearson_interval(k + m, n, confidence_level)[1])
        interval = INTERVAL_CLOPPER_PEARSON
    levels.add(0.0, last_upper)
    ancestors = int(np.unique(eve[failed]).size)
    status, message = STATUS_OK, ""
    if levels.indicators and 0 < ancestors < MIN_ANCESTORS:
        status = STATUS_DIAGNOSTIC_FAILED
        message = (f"the {int(np.count_nonzero(failed))} failing samples descend from only "
                   f"{ancestors} level-0 sample(s) (< {MIN_ANCESTORS}): the chains may have "
                   "lost a failure mode; raise samples_per_level or cross-check with "
                   "importance sampling")
    return RareEventResult(
        probability=p, standard_error=p * cv_lower if lower > 0 else float("nan"),
        coefficient_of_variation=cv_lower, ci_lower=float(ci[0]), ci_upper=float(ci[1]),
        interval=interval, evaluations=evaluations,
        unresolved=unresolved, failures=int(np.count_nonzero(failed)), bound_lower=lower,
        bound_upper=upper, bounds_ci_lower=float(bounds_ci[0]),
        bounds_ci_upper=float(bounds_ci[1]),
        degrees_of_freedom=df, ancestors=ancestors, level_independent_cv=independent_cv,
        status=status, message=message, **levels.fields(), **common)


def lost_modes(probability, failing, design_points, limit=MODE_LIMIT):
    """The design points that hold more than subset simulation found around them.

    Each failing sample of the last level is assigned to its nearest design point; with n_k of
    the m failing samples nearest to u*_k, subset's estimate of the mass around u*_k is at
    most P (n_k + 1) / m (one sample added, so that an empty neighbourhood is not read as
    zero). Design point k contradicts the result when its own probability P_k (Breitung's
    SORM where the curvatures are known, else Phi(-beta_k)) exceeds ``limit`` times that.
    Such a mode is one that the intermediate levels never visited, or visited with so few
    chains that its share came out far too small (RP110 of RPRepo: the mode u_1 >= 4 holds
    99 % of P = 3.2e-5 but is 150 times rarer than the mode u_2 >= 5 at the first
    thresholds; in most runs subset simulation returns the other mode's 3e-7 with a CV of
    0.5, and no diagnostic of its own can tell). A design point far less probable than P
    (RP89's local one, 2e-9 against 5.5e-3) never flags.

    Parameters
    ----------
    probability : float
        Subset simulation's P.
    failing : ndarray (m, d)
        The failing samples of its last level.
    design_points : sequence of DesignPoint
        Converged design points.
    limit : float

    Returns
    -------
    list of (beta_k, P_k, subset's mass bound around u*_k)
    """
    points = [p for p in design_points if p.converged]
    if not points or not probability > 0 or failing.shape[0] == 0:
        return []
    centres = np.array([p.point for p in points])
    nearest = np.argmin(((failing[:, None, :] - centres[None]) ** 2).sum(axis=2), axis=1)
    counts = np.bincount(nearest, minlength=len(points))
    out = []
    for k, point in enumerate(points):
        p_k = point.sorm_probability if np.isfinite(point.sorm_probability) \
            else point.form_probability
        mass = probability * (counts[k] + 1.0) / failing.shape[0]
        if p_k > limit * mass:
            out.append((float(point.beta), float(p_k), float(mass)))
    return out


def _check_modes(result, failing, design_points):
    """``result`` flagged ``"diagnostic_failed"`` when :func:`lost_modes` finds design points
    whose missing mass, sum_k (P_k - subset's mass around u*_k), exceeds the distance from P to
    the upper end of subset's interval (module docstring)."""
    if design_points is None or not result.ok:
        return result
    lost = lost_modes(result.probability, failing, design_points)
    missing = sum(p_k - mass for _, p_k, mass in lost)
    if not lost or missing <= result.ci_upper - result.probability:
        return result
    beta, p_k, mass = max(lost, key=lambda x: x[1] / x[2])
    message = (f"{len(lost)} FORM design point(s) hold more than {MODE_LIMIT:g} times what "
               f"subset simulation found around them (beta {beta:.3g}: P_FORM {p_k:.3g} "
               f"against at most {mass:.3g} from the chains): the chains lost a failure mode; "
               "use importance sampling or method 'rare'")
    return replace(result, status=STATUS_DIAGNOSTIC_FAILED, message=message,
                   lost_mode_mass=float(missing))


def ancestral_log_variance(indicators, eves):
    """Variance of ln P over the genealogy of the samples, and its degrees of freedom.

    ln P = sum_j ln P_j, linearised: the error of ln P is sum_j (P_j_hat - P_j) / P_j, a sum
    over all samples of all levels. Grouping its terms by the level-0 sample ("Eve") each
    sample descends from, e_r = sum_j sum_{i in level j, eve(i) = r} (I_ji - P_j) / (n P_j),
    and taking the Eve trees as the independent clusters ([ChanLai2013], [LeeWhiteley2018]
    for particle filters), v = K / (K - 1) sum_r e_r^2 with K = n Eves, and Kish's effective
    number of clusters (sum e_r^2)^2 / sum e_r^4 minus 1 as degrees of freedom. Unlike the
    per-level variance it holds the correlation along the chains of all generations and
    between the levels (a level's samples descend from the level before).

    Parameters
    ----------
    indicators : list of ndarray of bool
        Per level, the samples inside its domain (the last level: the failures).
    eves : list of ndarray of int
        Per level, the Eve of each sample.

    Returns
    -------
    (variance of ln P, degrees of freedom); (inf, nan) when some P_j is 0.
    """
    n = indicators[0].size
    e = np.zeros(n)
    for indicator, eve in zip(indicators, eves, strict=True):
        p = float(np.count_nonzero(indicator)) / indicator.size
        if p <= 0:
            return float("inf"), float("nan")
        e += np.bincount(eve, weights=(indicator - p) / (indicator.size * p), minlength=n)
    square = float(np.sum(e ** 2))
    if square <= 0:
        return 0.0, float("inf")
    return n / (n - 1.0) * square, max(square ** 2 / float(np.sum(e ** 4)) - 1.0, 1.0)


def chain_correlation_factor(indicator) -> float:
    """Au & Beck's gamma of one level from its indicator along the chains.

    ([AuBeck2001], Eq. 29 ff.) gamma = 2 sum_{k=1}^{N_s - 1} (1 - k N_c / n) rho(k), with
    rho(k) = R(k) / R(0), R(k) = sum_c sum_l I_{c,l} I_{c,l+k} / (n - k N_c) - P^2 and
    R(0) = P (1 - P).

    Parameters
    ----------
    indicator : array_like of bool (N_c, N_s)
        I_{c,l}: sample l of chain c inside the level's domain.

    Returns
    -------
    float
        gamma (may be negative; 0 when P is 0 or 1).
    """
    x = np.asarray(indicator, dtype=float)
    if x.ndim != 2:
        raise ValueError(f"indicator of shape {x.shape}: expected (chains, chain_length)")
    chains, length = x.shape
    n = chains * length
    p = float(x.mean())
    variance = p * (1.0 - p)
    if variance <= 0:
        return 0.0
    gamma = 0.0
    for lag in range(1, length):
        covariance = float(np.sum(x[:, :-lag] * x[:, lag:])) / (n - lag * chains) - p * p
        gamma += 2.0 * (1.0 - lag * chains / n) * covariance / variance
    return gamma


class LevelStatistics(NamedTuple):
    """Statistics of one level's estimate (:func:`level_statistics`)."""

    #: P_j = mean of the indicator [-].
    probability: float
    #: delta_j [-] (inf for P_j = 0).
    coefficient_of_variation: float
    #: Of delta_j^2: the effective number of chain families - 1 (inf for level 0).
    degrees_of_freedom: float
    #: Au & Beck's gamma_j (0 for level 0), for comparison.
    chain_correlation_factor: float


def level_statistics(indicator, structure=None) -> LevelStatistics:
    """P_j, its CV delta_j with degrees of freedom, and Au & Beck's gamma_j of one level.

    Level 0 (``structure`` None): independent samples, delta^2 = (1 - P) / (n P). A level of
    chains: the variance of P_j over the chain families F (the chains whose seeds come from
    one chain of the level before; module docstring), a cluster estimate ::

        v = K / (K - 1) sum_F e_F^2 / n^2,   e_F = S_F - P n_F,   delta^2 = v / P^2,

    S_F the indicator sum and n_F the samples of family F, K the number of families, with
    (sum e_F^2)^2 / sum e_F^4 - 1 degrees of freedom (Kish's effective number of families:
    most families hold no sample in a small domain). With K < 2 it falls back to Au & Beck's
    delta^2 = (1 - P) / (n P) (1 + max(gamma, 0)) at 1 degree of freedom.

    Parameters
    ----------
    indicator : ndarray of bool (n,)
        In chain-major order (chain c holds rows c N_s .. (c + 1) N_s - 1).
    structure : (N_c, N_s, families) or None
        families (N_c,): the family of each chain.

    Returns
    -------
    LevelStatistics
    """
    indicator = np.asarray(indicator, dtype=bool)
    n = indicator.size
    p = float(np.count_nonzero(indicator)) / n
    inf = float("inf")
    if structure is None:
        return LevelStatistics(p, math.sqrt((1.0 - p) / (n * p)) if p > 0 else inf, inf, 0.0)
    chains, length, families = structure
    gamma = chain_correlation_factor(indicator.reshape(chains, length))
    if p <= 0:
        return LevelStatistics(p, inf, inf, gamma)
    _, family = np.unique(families, return_inverse=True)
    k = int(family.max()) + 1
    if k < 2:
        return LevelStatistics(p, math.sqrt((1.0 - p) / (n * p) * (1.0 + max(gamma, 0.0))),
                               1.0, gamma)
    sums = np.bincount(family, weights=indicator.reshape(chains, length).sum(axis=1),
                       minlength=k)
    residuals = sums - p * np.bincount(family, minlength=k) * float(length)
    square = float(np.sum(residuals ** 2))
    if square <= 0:                                  # every family at P: no spread seen
        return LevelStatistics(p, 0.0, inf, gamma)
    delta = math.sqrt(k / (k - 1.0) * square) / (n * p)
    effective = square ** 2 / float(np.sum(residuals ** 4))
    return LevelStatistics(p, delta, max(effective - 1.0, 1.0), gamma)


def _lognormal_interval(p, statistics, confidence_level, ancestral=None):
    """Lognormal interval of a product of level estimates (module docstring).

    s^2 = sum_j ln(1 + delta_j^2), delta = sqrt(exp(s^2) - 1), df by Satterthwaite from the
    levels' df; with ``ancestral`` (variance of ln P, df) of :func:`ancestral_log_variance`
    the larger of the two variances, with the levels' df (the Eve clusters' own effective
    number is often 1-3, one tree dominating the sum of e_r^4, and its t quantile would blow
    the interval up by a factor of 10 or more). The interval p exp(-+ t s), its upper end at
    most 1. Returns (lower, upper, delta, df); (0, NaN, inf, NaN) for p = 0.
    """
    if not p > 0:
        return 0.0, float("nan"), float("inf"), float("nan")
    parts = np.log1p(np.square([x.coefficient_of_variation for x in statistics]))
    dfs = np.array([x.degrees_of_freedom for x in statistics])
    total = float(np.sum(parts))
    spread = float(np.sum(parts ** 2 / dfs))                # 0 when every df is inf
    df = total ** 2 / spread if spread > 0 else float("inf")
    if ancestral is not None and ancestral[0] > total:
        total = ancestral[0]           # with the levels' df: Kish's over Eves can be ~1
    if total <= 0:
        return p, p, 0.0, float("inf")
    quantile = float(t_distribution.ppf(0.5 + confidence_level / 2, df)) if np.isfinite(df) \
        else float(ndtri(0.5 + confidence_level / 2))
    s = math.sqrt(total)
    # a probability: the upper end cut at 1 (it passes 1 only for an event that is not rare)
    return p * math.exp(-quantile * s), min(p * math.exp(quantile * s), 1.0), \
        math.sqrt(math.expm1(total)), df


def _conditional_sampling(limit_state, seeds_u, seeds_g, threshold, chain_length,
                          chain_seeds, scale, batch_size):
    """One level of adaptive conditional sampling ([Papaioannou2015], adapted after each
    step over all chains; module docstring).

    Returns
    -------
    (u (n, d), g (n,), scale, acceptance rate, evaluations, NaN evaluations), the samples in
    chain-major order (chain c holds rows c N_s .. (c + 1) N_s - 1).
    """
    chains, d = seeds_u.shape
    steps = chain_length - 1
    noise = np.empty((chains, steps, d))
    for c, sequence in enumerate(chain_seeds):
        noise[c] = np.random.default_rng(sequence).standard_normal((steps, d))
    spread = seeds_u.std(axis=0, ddof=1)
    u = np.empty((chains, chain_length, d))
    g = np.empty((chains, chain_length))
    u[:, 0], g[:, 0] = seeds_u, seeds_g
    accepted = unresolved = 0
    for t in range(1, chain_length):
        sigma = np.minimum(1.0, scale * spread)
        rho = np.sqrt(1.0 - sigma * sigma)
        candidate = rho * u[:, t - 1] + sigma * noise[:, t - 1]
        g_candidate = evaluate(limit_state, candidate, batch_size)
        unevaluable = np.isnan(g_candidate)
        accept = unevaluable | (g_candidate <= threshold)
        u[:, t] = np.where(accept[:, None], candidate, u[:, t - 1])
        g[:, t] = np.where(accept, g_candidate, g[:, t - 1])
        rate = float(np.count_nonzero(accept)) / chains
        accepted += int(np.count_nonzero(accept))
        unresolved += int(np.count_nonzero(unevaluable))
        scale = math.exp(math.log(scale) + (rate - TARGET_ACCEPTANCE) / math.sqrt(t))
    calls = chains * steps
    return (u.reshape(chains * chain_length, d), g.reshape(-1), scale, accepted / calls,
            calls, unresolved)


def _modified_metropolis(limit_state, seeds_u, seeds_g, threshold, chain_length, chain_seeds,
                         scale, batch_size):
    """One level of the modified Metropolis algorithm ([AuBeck2001]); ``scale`` is passed
    through. Returns as :func:`_conditional_sampling`."""
    chains, d = seeds_u.shape
    steps = chain_length - 1
    noise = np.empty((chains, steps, 2, d))
    for c, sequence in enumerate(chain_seeds):
        noise[c] = np.random.default_rng(sequence).random((steps, 2, d))
    u = np.empty((chains, chain_length, d))
    g = np.empty((chains, chain_length))
    u[:, 0], g[:, 0] = seeds_u, seeds_g
    accepted = calls = unresolved = 0
    for t in range(1, chain_length):
        current = u[:, t - 1]
        proposal = current + METROPOLIS_HALF_WIDTH * (2.0 * noise[:, t - 1, 0] - 1.0)
        ratio = np.exp(-0.5 * (proposal * proposal - current * current))
        candidate = np.where(noise[:, t - 1, 1] < ratio, proposal, current)
        moved = np.flatnonzero(np.any(candidate != current, axis=1))
        accept = np.zeros(chains, dtype=bool)
        g_next = g[:, t - 1].copy()
        if moved.size:
            g_moved = evaluate(limit_state, candidate[moved], batch_size)
            unevaluable = np.isnan(g_moved)
            ok = unevaluable | (g_moved <= threshold)
            accept[moved[ok]] = True
            g_next[moved[ok]] = g_moved[ok]
            calls += moved.size
            unresolved += int(np.count_nonzero(unevaluable))
        u[:, t] = np.where(accept[:, None], candidate, current)
        g[:, t] = g_next
        accepted += int(np.count_nonzero(accept))
    return (u.reshape(chains * chain_length, d), g.reshape(-1), scale,
            accepted / (chains * steps), calls, unresolved)


#: Markov-chain samplers of subset simulation, by their ``sampler=`` name.
SAMPLERS = {"conditional": _conditional_sampling, "metropolis": _modified_metropolis}
