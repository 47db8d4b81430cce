"""Rare-event estimators of a failure probability over a standard-normal input space.

The study supplies

* the dimension d of its standard-normal space (every sampled source mapped to independent
  standard normals),
* a vectorised limit-state function ``limit_state(u) -> g`` on arrays u of shape (n, d),
  each row one assembly's independent standard normals, with **failure where g <= 0**. A row
  that no model can evaluate returns NaN: it is *unresolved*, counted and bounded, never
  dropped;
* a seed (a :class:`numpy.random.SeedSequence`, or an int).

and gets back a :class:`RareEventResult` of P = P(g(U) <= 0), U ~ N(0, I_d), from one of
three estimators with the same call, registered by their config names in
:data:`ESTIMATORS`:

``monte_carlo`` (:func:`monte_carlo`)
    Plain Monte Carlo, k of n with the Clopper-Pearson interval ([ClopperPearson1934]). About
    100 / P samples for a 95 % interval of -+20 % (25 / P for a coefficient of variation of
    0.2): the reference, and the right choice for P >~ 1e-3.
``subset`` (:func:`subset_simulation`)
    Subset simulation ([AuBeck2001]): P = P(F_1) prod P(F_j | F_{j-1}) over nested
    intermediate failure domains F_j = {g <= b_j}, with the thresholds b_j chosen as the
    p0-quantiles of the samples of each level (p0 = 0.1 by default) and the conditional
    samples drawn by Markov chains started from the level's seeds. Needs no smoothness and
    no design point; the cost grows with log(1 / P): ~ n (1 + 0.9 log10(1 / P)) model
    calls at p0 = 0.1.
``importance`` (:func:`importance_sampling`)
    FORM + importance sampling: the design point u* (the most probable failure point,
    :func:`find_design_point`) and the FORM estimate Phi(-beta), beta = |u*|
    ([HasoferLind1974], [RackwitzFiessler1978]), then importance sampling from N(u*, I)
    ([Melchers1989]). The cheapest for a smooth limit state with one design point; it says
    so (a flag, no number) when FORM does not converge or the limit state is not smooth
    there, and the caller falls back to subset simulation::

        result = importance_sampling(limit_state, d, seed)
        if not result.ok:                 # result.message says why, in one line
            result = subset_simulation(limit_state, d, seed)

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

**The interval is approximate.** Both CVs neglect the correlation between levels (a level's
seeds are the samples of the one before, and all chains of a level share its threshold,
proposal spread and scale) and the estimate's bias of order 1 / n. Measured on the linear
limit state (d = 6, n = 1000, p0 = 0.1; two sets of 1000 seeded repeats, the second
``python benchmarks/bench_rare_events.py --repeats 1000``): the intervals cover the exact P
in 95.2 / 93.4 %, 94.3 / 93.7 % and 92.6 / 91.9 % of the repeats at 1e-3, 1e-5 and 1e-7
(with Au & Beck's CV and the normal quantile: 93.5 / 91.7 %, 90.6 / 90.8 %, 88.8 / 87.6 %);
at 1e-7 the reported CV averages 0.42 for an observed 0.49-0.50. On a strongly curved limit
state (a ball off the origin, P = 1.2e-5) they cover 91.5 %.

If no level has N_c failures within ``max_levels`` levels, or the limit state is flat at a
p0-quantile (no threshold between tied values), the result is flagged (``status``), its
probability NaN, and ``message`` says why in one line.

FORM and importance sampling
----------------------------
:func:`find_design_point` minimises |u|^2 / 2 subject to g(u) = 0 with SLSQP
(:func:`scipy.optimize.minimize`, [Kraft1988]) from u = 0, the constraint scaled by
|grad g(0)|. The gradient is the caller's (``gradient=``) or central differences of step h,
the 2 d rows evaluated as one batch. The point is accepted only if

* the origin is safe (g(0) > 0; else it is not a rare event),
* u* lies on the limit state: |g(u*)| / |grad g(u*)| <= 1e-3 (a distance in u),
* it is a stationary point of the Lagrangian: u* parallel to -grad g(u*) (1 - cos <= 1e-3),
* the limit state is smooth there: the one-sided difference quotients at step h agree,
  |grad_forward - grad_backward| <= 0.05 |grad_central| (a kink or a noisy model fails it),

and is flagged otherwise (``converged`` False, ``message`` one line). beta = |u*|, the FORM
estimate Phi(-beta), and the importance factors alpha_k^2, alpha = u* / beta (the shares of
the tolerances in "the most likely way to fail"; the caller maps u* to physical units).

Importance sampling draws v ~ N(u*, I) (blocks as above) and averages
1{g(v) <= 0} w(v), w = phi(v) / phi(v - u*) = exp(-v . u* + beta^2 / 2). The standard error
is the sample standard deviation over sqrt(n); the 95 % interval the normal one,
P -+ z se (lower end clipped at 0). It is unbiased for any limit state, but efficient only
when the failure domain lies around u*: with several design points (or a failure domain
around the origin) the samples miss the other regions and the estimate is low with a
standard error that does not show it. FORM finds one design point; it can not tell. With
few failing samples (a strongly curved limit state) the normal interval is too short on the
high side: on the ball of ``benchmarks/bench_rare_events.py`` (about 2 % of 4000 samples
fail) it covers 93.2 % (1000 repeats), against 94-96 % on the linear case.

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

Nomenclature
------------
=================  ==========================================================
u, U               point of / random vector in the standard-normal space
g                  ``limit_state`` value; failure where g <= 0
p0                 ``p0``: conditional probability of each intermediate level
n                  ``samples_per_level`` (subset), ``samples`` (others)
N_c, N_s           number of chains (n p0) and their length (1 / p0)
b_j                ``thresholds``
F                  chain family: the chains seeded from one chain of the level before
gamma_j            ``chain_correlation_factors`` (Au & Beck's)
delta_j, delta     ``level_coefficients_of_variation``, ``coefficient_of_variation``
u*, beta           ``design_point``, ``beta`` (reliability index)
=================  ==========================================================

References
----------
.. [AuBeck2001] S.-K. Au, J. L. Beck, "Estimation of small failure probabilities in high
   dimensions by subset simulation", Prob. Eng. Mech. 16 (2001) 263-277,
   doi:10.1016/S0266-8920(01)00019-4.
.. [Papaioannou2015] I. Papaioannou, W. Betz, K. Zwirglmaier, D. Straub, "MCMC algorithms
   for Subset Simulation", Prob. Eng. Mech. 41 (2015) 89-103,
   doi:10.1016/j.probengmech.2015.06.006.
.. [HasoferLind1974] A. M. Hasofer, N. C. Lind, "Exact and invariant second-moment code
   format", J. Eng. Mech. Div. ASCE 100 (1974) 111-121.
.. [RackwitzFiessler1978] R. Rackwitz, B. Fiessler, "Structural reliability under combined
   random load sequences", Computers & Structures 9 (1978) 489-494,
   doi:10.1016/0045-7949(78)90046-9.
.. [Kraft1988] D. Kraft, "A software package for sequential quadratic programming",
   DFVLR-FB 88-28, 1988.
.. [Melchers1989] R. E. Melchers, "Importance sampling in structural systems", Structural
   Safety 6 (1989) 3-10, doi:10.1016/0167-4730(89)90003-9.
.. [ClopperPearson1934] C. J. Clopper, E. S. Pearson, Biometrika 26 (1934) 404-413 (see
   :func:`tolsim.study.statistics.intervals.clopper_pearson_interval`).
"""

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.optimize import minimize
from scipy.special import log_ndtr, logsumexp, ndtr, ndtri
from scipy.stats import t as t_distribution

from tolsim.study.statistics.intervals import clopper_pearson_interval

#: Key under the given SeedSequence of every stream drawn here ('rare' in ASCII), so that a
#: caller passing its study's root sequence does not collide with the study's own streams.
RARE_EVENT_STREAM = 0x72617265
#: Rows per independently seeded block of standard normals (Monte Carlo, importance
#: sampling, level 0 of subset simulation). Fixed: changing it changes the draws.
BLOCK_ROWS = 1 << 14
#: Fewest chains (n p0) of subset simulation.
MIN_CHAINS = 10
#: Adaptive conditional sampling ([Papaioannou2015]): initial scale and target acceptance.
INITIAL_SCALE = 0.6
TARGET_ACCEPTANCE = 0.44
#: Half-width of the uniform component proposal of the modified Metropolis algorithm.
METROPOLIS_HALF_WIDTH = 1.0
#: Design-point acceptance (module docstring): distance to g = 0 in u, 1 - cos of the angle
#: between u* and -grad g, relative disagreement of the one-sided difference quotients.
FORM_DISTANCE_TOLERANCE = 1e-3
FORM_ALIGNMENT_TOLERANCE = 1e-3
SMOOTHNESS_TOLERANCE = 0.05
#: Default finite-difference step of the design-point search, in standard-normal units.
GRADIENT_STEP = 1e-4

STATUS_OK = "ok"
STATUS_NO_FAILURE = "no_failure"
STATUS_PLATEAU = "plateau"
STATUS_FORM_FAILED = "form_failed"
STATUS_UNRESOLVED = "unresolved"

INTERVAL_CLOPPER_PEARSON = "Clopper-Pearson"
INTERVAL_LOGNORMAL = "lognormal with the CV and a Student-t quantile (approximate)"
INTERVAL_NORMAL = "normal approximation, estimate -+ z se (approximate)"


class RareEventError(RuntimeError):
    """An estimator could not back a number (raised by :meth:`RareEventResult.raise_for_status`)."""


# ---------------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------------

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
        ``"ok"`` or why there is no number (:meth:`raise_for_status`).
    message : str
        One line: why the estimator is flagged ("" when ok).
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
        Subset: delta_j of each level (over chain families, module docstring).
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
        if not self.ok:
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
        return line


@dataclass(frozen=True, eq=False)
class DesignPoint:
    """The most probable failure point of FORM (:func:`find_design_point`).

    Attributes
    ----------
    point : ndarray (d,)
        u* [-] in the standard-normal space (the last iterate when not converged).
    beta : float
        |u*| [-], the reliability index.
    form_probability : float
        Phi(-beta) [-].
    gradient : ndarray (d,)
        grad g(u*) (central differences, or the caller's gradient).
    converged : bool
        All checks passed (module docstring); when False, do not use the point.
    message : str
        One line: why it was not accepted ("" when converged).
    evaluations : int
        Rows on which the limit state was evaluated.
    """

    point: np.ndarray
    beta: float
    form_probability: float
    gradient: np.ndarray
    converged: bool
    message: str
    evaluations: int

    @property
    def importance_factors(self) -> np.ndarray:
        """alpha_k^2 with alpha = u* / beta [-]; they sum to 1."""
        if not self.beta > 0:
            return np.full_like(self.point, np.nan)
        return (self.point / self.beta) ** 2


# ---------------------------------------------------------------------------------------------
# plain Monte Carlo
# ---------------------------------------------------------------------------------------------

def monte_carlo(limit_state, dimension, seed, *, samples=100_000, batch_size=None,
                confidence_level=0.95) -> RareEventResult:
    """Plain Monte Carlo: k of n with the Clopper-Pearson interval ([ClopperPearson1934]).

    Parameters
    ----------
    limit_state : callable
        g(u) for u of shape (rows, d) -> (rows,); failure where g <= 0, NaN unresolved.
    dimension : int
        d.
    seed : numpy.random.SeedSequence or int
    samples : int
        n.
    batch_size : int, optional
        Most rows per call of ``limit_state`` (default: one block of :data:`BLOCK_ROWS`).
    confidence_level : float

    Returns
    -------
    RareEventResult
        ``probability`` k / (n - m) over the n - m resolved rows with its Clopper-Pearson
        interval; bounds k / n and (k + m) / n, their interval the Clopper-Pearson lower end
        of k of n and upper end of k + m of n.
    """
    d = _check_dimension(dimension)
    n = _check_count("samples", samples, 1)
    _check_batch_size(batch_size)
    _check_confidence(confidence_level)
    root = _seed_sequence(seed)
    failures = unresolved = 0
    for u in _normal_blocks(root, (0,), n, d):
        g = _evaluate(limit_state, u, batch_size)
        failures += int(np.count_nonzero(g <= 0))
        unresolved += int(np.count_nonzero(np.isnan(g)))
    resolved = n - unresolved
    bounds = dict(unresolved=unresolved, failures=failures, bound_lower=failures / n,
                  bound_upper=(failures + unresolved) / n,
                  bounds_ci_lower=clopper_pearson_interval(failures, n, confidence_level)[0],
                  bounds_ci_upper=clopper_pearson_interval(failures + unresolved, n,
                                                           confidence_level)[1])
    common = dict(estimator="monte_carlo", confidence_level=confidence_level, dimension=d,
                  samples_per_level=n)
    if not resolved:
        return _flagged(STATUS_UNRESOLVED, f"all {n} samples unresolved (g is NaN): P is only "
                                           "known to lie in [0, 1]", n, unresolved, common,
                        **{k: v for k, v in bounds.items() if k != "unresolved"})
    p = failures / resolved
    se = math.sqrt(p * (1 - p) / resolved)
    lower, upper = clopper_pearson_interval(failures, resolved, confidence_level)
    return RareEventResult(probability=p, standard_error=se, coefficient_of_variation=_cv(p, se),
                           ci_lower=lower, ci_upper=upper, interval=INTERVAL_CLOPPER_PEARSON,
                           evaluations=n, **bounds, **common)


# ---------------------------------------------------------------------------------------------
# subset simulation
# ---------------------------------------------------------------------------------------------

def subset_simulation(limit_state, dimension, seed, *, samples_per_level=1000, p0=0.1,
                      max_levels=20, sampler="conditional", batch_size=None,
                      confidence_level=0.95) -> RareEventResult:
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

    Returns
    -------
    RareEventResult
        With ``thresholds``, ``level_probabilities``, ``level_coefficients_of_variation``,
        ``chain_correlation_factors`` and ``acceptance_rates``; the interval is the
        lognormal one with the CV (approximate). Flagged (``status`` ``"no_failure"`` or
        ``"plateau"``, probability NaN) when no level reaches the failure domain.
    """
    d = _check_dimension(dimension)
    n = _check_count("samples_per_level", samples_per_level, 1)
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
    max_levels = _check_count("max_levels", max_levels, 1)
    try:
        step_chains = SAMPLERS[sampler]
    except (KeyError, TypeError):
        raise ValueError(f"sampler = {sampler!r}; choose one of {tuple(SAMPLERS)}") from None
    _check_batch_size(batch_size)
    _check_confidence(confidence_level)
    root = _seed_sequence(seed)
    chain_length = n // chains

    u = np.concatenate(list(_normal_blocks(root, (0,), n, d)))
    g = _evaluate(limit_state, u, batch_size)
    evaluations = n
    unresolved = int(np.count_nonzero(np.isnan(g)))
    levels = _Levels()
    scale = INITIAL_SCALE
    families = None                 # level 0: independent samples
    common = dict(estimator="subset", confidence_level=confidence_level, dimension=d,
                  samples_per_level=n)
    for level in range(max_levels):
        structure = None if families is None else (chains, chain_length, families)
        unevaluable = np.isnan(g)
        failed = g <= 0
        if np.count_nonzero(failed | unevaluable) >= chains:
            return _subset_result(failed, unevaluable, structure, levels, evaluations,
                                  unresolved, confidence_level, common)
        key = np.where(unevaluable, -np.inf, g)
        order = np.argsort(key, kind="stable")
        below, above = key[order[chains - 1]], key[order[chains]]
        if level == max_levels - 1:
            return _flagged(STATUS_NO_FAILURE,
                            f"no failure (g <= 0) in {max_levels} levels of {n} samples "
                            f"(smallest g reached {key[order[0]]:.3g}, threshold "
                            f"{below:.3g}); no probability estimated; raise max_levels or "
                            "check the limit state", evaluations, unresolved, common,
                            **levels.fields())
        # b between the N_c-th and the next value; at a tie (a repeated chain state, or a
        # flat limit state) b is the tied value and P_j the share of samples at or below it
        threshold = 0.5 * (below + above) if below < above < np.inf else below
        if levels.thresholds and not threshold < levels.thresholds[-1]:
            return _flagged(STATUS_PLATEAU,
                            f"the limit state is flat at the p0-quantile of level {level} "
                            f"(threshold {threshold:.6g} not below the previous one): no "
                            "progress towards g <= 0; no probability estimated",
                            evaluations, unresolved, common, **levels.fields())
        # N_c rows inside, more at a tie
        levels.add(threshold, level_statistics(key <= threshold, structure))
        seeds = np.sort(order[:chains])              # the N_c lowest, in sample order
        # the family of a chain: the chain of the level before that holds its seed
        families = seeds if level == 0 else seeds // chain_length
        chain_seeds = [_child(root, level + 1, c) for c in range(chains)]
        u, g, scale, rate, calls, nan_calls = step_chains(
            limit_state, u[seeds], g[seeds], threshold, chain_length, chain_seeds, scale,
            batch_size)
        levels.acceptance.append(rate)
        evaluations += calls
        unresolved += nan_calls
    raise AssertionError("unreachable")  # the loop returns at its last level


@dataclass
class _Levels:
    """What subset simulation records per level."""

    thresholds: list = field(default_factory=list)
    statistics: list = field(default_factory=list)
    acceptance: list = field(default_factory=list)

    def add(self, threshold, statistics):
        self.thresholds.append(float(threshold))
        self.statistics.append(statistics)

    def fields(self):
        return dict(thresholds=tuple(self.thresholds),
                    level_probabilities=tuple(x.probability for x in self.statistics),
                    level_coefficients_of_variation=tuple(x.coefficient_of_variation
                                                          for x in self.statistics),
                    chain_correlation_factors=tuple(x.chain_correlation_factor
                                                    for x in self.statistics),
                    acceptance_rates=tuple(self.acceptance))


def _subset_result(failed, unevaluable, structure, levels, evaluations, unresolved,
                   confidence_level, common):
    """The last level: P_m with and without the unresolved rows, CVs, intervals."""
    prefix = float(np.prod([x.probability for x in levels.statistics]))
    last_upper = level_statistics(failed | unevaluable, structure)
    last_lower = level_statistics(failed, structure)
    upper = prefix * last_upper.probability
    lower = prefix * last_lower.probability
    up_hi = _lognormal_interval(upper, [*levels.statistics, last_upper], confidence_level)[1]
    lo_lo, lo_hi, cv_lower, df = _lognormal_interval(
        lower, [*levels.statistics, last_lower], confidence_level)
    resolved = 1.0 - (upper - lower)                               # 1 - P(N), estimated
    p = lower / resolved
    levels.add(0.0, last_upper)
    return RareEventResult(
        probability=p, standard_error=p * cv_lower if lower > 0 else float("nan"),
        coefficient_of_variation=cv_lower, ci_lower=lo_lo / resolved,
        ci_upper=lo_hi / resolved, interval=INTERVAL_LOGNORMAL, evaluations=evaluations,
        unresolved=unresolved, failures=int(np.count_nonzero(failed)), bound_lower=lower,
        bound_upper=upper, bounds_ci_lower=lo_lo, bounds_ci_upper=up_hi,
        degrees_of_freedom=df, **levels.fields(), **common)


def _flagged(status, message, evaluations, unresolved, common=None, **extra):
    """A result without a probability: ``status`` and a one-line ``message``."""
    nan = float("nan")
    return RareEventResult(
        probability=nan, standard_error=nan, coefficient_of_variation=nan, ci_lower=nan,
        ci_upper=nan, interval="none", evaluations=evaluations, status=status,
        message=message, unresolved=unresolved, **(common or {}), **extra)


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


def _lognormal_interval(p, statistics, confidence_level):
    """Lognormal interval of a product of level estimates (module docstring).

    s^2 = sum_j ln(1 + delta_j^2), delta = sqrt(exp(s^2) - 1), df by Satterthwaite from the
    levels' df; the interval p exp(-+ t s). Returns (lower, upper, delta, df);
    (0, NaN, inf, NaN) for p = 0.
    """
    if not p > 0:
        return 0.0, float("nan"), float("inf"), float("nan")
    parts = np.log1p(np.square([x.coefficient_of_variation for x in statistics]))
    dfs = np.array([x.degrees_of_freedom for x in statistics])
    total = float(np.sum(parts))
    if total <= 0:
        return p, p, 0.0, float("inf")
    spread = float(np.sum(parts ** 2 / dfs))                # 0 when every df is inf
    df = total ** 2 / spread if spread > 0 else float("inf")
    quantile = float(t_distribution.ppf(0.5 + confidence_level / 2, df)) if np.isfinite(df) \
        else float(ndtri(0.5 + confidence_level / 2))
    s = math.sqrt(total)
    return p * math.exp(-quantile * s), p * math.exp(quantile * s), \
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
        g_candidate = _evaluate(limit_state, candidate, batch_size)
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
            g_moved = _evaluate(limit_state, candidate[moved], batch_size)
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


# ---------------------------------------------------------------------------------------------
# FORM and importance sampling
# ---------------------------------------------------------------------------------------------

class _Unevaluable(Exception):
    """g (or its gradient) is NaN at a point of the design-point search."""


def find_design_point(limit_state, dimension, *, gradient=None, step=GRADIENT_STEP,
                      max_iterations=100, batch_size=None) -> DesignPoint:
    """The most probable failure point u* by SLSQP, with the checks of the module docstring.

    Minimises |u|^2 / 2 subject to g(u) = 0 ([HasoferLind1974]) with
    :func:`scipy.optimize.minimize` (method ``"SLSQP"``, [Kraft1988]) from u = 0.

    Parameters
    ----------
    limit_state : callable
        g(u) for u of shape (rows, d) -> (rows,); failure where g <= 0.
    dimension : int
        d.
    gradient : callable, optional
        grad g(u) for u of shape (rows, d) -> (rows, d); default central differences of
        step ``step`` (2 d rows in one batch). The smoothness check always uses one-sided
        differences of step ``step``.
    step : float
        Finite-difference step h in standard-normal units.
    max_iterations : int
        SLSQP iterations.
    batch_size : int, optional
        Most rows per call of ``limit_state``.

    Returns
    -------
    DesignPoint
        ``converged`` False (with a one-line ``message``) when the search failed or a check
        did not pass: then neither u* nor the FORM estimate is to be used.
    """
    d = _check_dimension(dimension)
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"step = {step!r} must be > 0")
    max_iterations = _check_count("max_iterations", max_iterations, 1)
    _check_batch_size(batch_size)
    calls = [0]

    def values(rows):
        calls[0] += rows.shape[0]
        return _evaluate(limit_state, rows, batch_size)

    def value_and_gradient(u):
        """g(u) and its gradient: the caller's, or central differences (one batch
        [u, u + h e_k, u - h e_k])."""
        if gradient is not None:
            return values(u[None]), _user_gradient(gradient, u)
        g = values(np.concatenate([u[None], u + step * np.eye(d), u - step * np.eye(d)]))
        return g, (g[1:d + 1] - g[d + 1:]) / (2 * step)

    def fail(u, g_grad, why):
        beta = float(np.linalg.norm(u))
        return DesignPoint(u, beta, float(ndtr(-beta)), g_grad, False, why, calls[0])

    origin = np.zeros(d)
    g_rows, grad0 = value_and_gradient(origin)
    g0 = g_rows[0]
    if not np.isfinite(g0):
        return fail(origin, grad0, f"the limit state is {g0} at the origin (nominal design)")
    if g0 <= 0:
        return fail(origin, grad0, f"the origin (nominal design) fails, g(0) = {g0:.3g} <= 0: "
                                   "not a rare event; use Monte Carlo")
    scale = float(np.linalg.norm(grad0))
    if not (np.isfinite(scale) and scale > 0):
        return fail(origin, grad0, "the gradient of the limit state vanishes at the origin: "
                                   "FORM can not start (several or no design points)")
    cache = {}

    def constraint(u):
        key = u.tobytes()
        if key not in cache:
            g = values(u[None])[0]
            if not np.isfinite(g):
                raise _Unevaluable(f"the limit state is {g} at a point of the search")
            cache.clear()
            cache[key] = g
        return cache[key] / scale

    def constraint_gradient(u):
        g, grad = value_and_gradient(u)
        if not (np.isfinite(g[0]) and np.all(np.isfinite(grad))):
            raise _Unevaluable("the limit state or its gradient is not finite at a point of "
                               "the search")
        return grad / scale

    try:
        result = minimize(lambda u: 0.5 * float(u @ u), origin, jac=lambda u: u,
                          method="SLSQP",
                          constraints=[{"type": "eq", "fun": constraint,
                                        "jac": constraint_gradient}],
                          options={"maxiter": max_iterations, "ftol": 1e-9})
    except _Unevaluable as error:
        return fail(origin, grad0, f"FORM search stopped: {error}")
    point = np.asarray(result.x, dtype=float)
    rows = np.concatenate([point[None], point + step * np.eye(d), point - step * np.eye(d)])
    g = values(rows)
    g_star = float(g[0])
    forward = (g[1:d + 1] - g_star) / step
    backward = (g_star - g[d + 1:]) / step
    central = 0.5 * (forward + backward)
    central_user = central if gradient is None else _user_gradient(gradient, point)
    beta = float(np.linalg.norm(point))
    norm = float(np.linalg.norm(central_user))
    solver = "" if result.success else f" (SLSQP: {result.message})"
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(central_user))):
        return fail(point, central_user, f"the limit state is not finite around the design "
                                         f"point{solver}")
    if not (norm > 0 and beta > 0):
        return fail(point, central_user, f"zero gradient or beta at the end of the search"
                                         f"{solver}")
    distance = abs(g_star) / norm
    if distance > FORM_DISTANCE_TOLERANCE:
        return fail(point, central_user, f"FORM did not converge: the point found is "
                                         f"{distance:.2g} from the limit state{solver}")
    alignment = 1.0 - float(-(point @ central_user)) / (beta * norm)
    if alignment > FORM_ALIGNMENT_TOLERANCE:
        return fail(point, central_user, f"FORM did not converge: u* is not normal to the "
                                         f"limit state (1 - cos = {alignment:.2g}){solver}")
    kink = float(np.linalg.norm(forward - backward)) / max(float(np.linalg.norm(central)),
                                                             1e-300)
    if kink > SMOOTHNESS_TOLERANCE:
        return fail(point, central_user, f"the limit state is not smooth at the design point "
                                         f"(one-sided slopes differ by {100 * kink:.3g} % at "
                                         f"step {step:g})")
    return DesignPoint(point, beta, float(ndtr(-beta)), central_user, True, "", calls[0])


def _user_gradient(gradient, u):
    """The caller's gradient at one point u (d,) -> (d,)."""
    values = np.asarray(gradient(u[None]), dtype=float)
    if values.shape != (1, u.size):
        raise ValueError(f"gradient returned shape {values.shape} for one row; expected "
                         f"(1, {u.size})")
    return values[0]


def importance_sampling(limit_state, dimension, seed, *, samples=2000, design_point=None,
                        gradient=None, step=GRADIENT_STEP, batch_size=None,
                        confidence_level=0.95) -> RareEventResult:
    """FORM, then importance sampling from N(u*, I) ([Melchers1989]); see the module docstring.

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
        A converged design point from :func:`find_design_point` (then its evaluations are
        not counted again); by default it is searched here.
    gradient, step : optional
        Of :func:`find_design_point`.
    batch_size : int, optional
        Most rows per call of ``limit_state``; the result does not depend on it.
    confidence_level : float

    Returns
    -------
    RareEventResult
        P, its standard error and the normal interval, with ``design_point``, ``beta``,
        ``form_probability`` and ``importance_factors``. Flagged ``"form_failed"`` (no
        probability; use :func:`subset_simulation`) when FORM gives no design point, and
        ``"no_failure"`` when no importance sample fails.
    """
    d = _check_dimension(dimension)
    n = _check_count("samples", samples, 2)
    _check_batch_size(batch_size)
    z = _check_confidence(confidence_level)
    root = _seed_sequence(seed)
    if design_point is None:
        design_point = find_design_point(limit_state, d, gradient=gradient, step=step,
                                         batch_size=batch_size)
        evaluations = design_point.evaluations
    else:
        if np.shape(design_point.point) != (d,):
            raise ValueError(f"design point of shape {np.shape(design_point.point)} for "
                             f"dimension {d}")
        evaluations = 0
    common = dict(estimator="importance", confidence_level=confidence_level, dimension=d,
                  samples_per_level=n, design_point=design_point.point,
                  beta=design_point.beta, form_probability=design_point.form_probability,
                  importance_factors=design_point.importance_factors)
    if not design_point.converged:
        return _flagged(STATUS_FORM_FAILED, f"FORM found no design point: "
                                            f"{design_point.message}; no probability "
                                            "estimated, use subset simulation",
                        evaluations, 0, common)
    shift = np.asarray(design_point.point, dtype=float)
    beta2 = float(shift @ shift)
    failures, unevaluable, weights = [], [], []
    for normal in _normal_blocks(root, (0,), n, d):
        v = shift + normal
        g = _evaluate(limit_state, v, batch_size)
        failures.append(g <= 0)
        unevaluable.append(np.isnan(g))
        # phi(v) / phi(v - u*) = exp(-v.u* + beta^2 / 2) = exp(-z.u* - beta^2 / 2)
        weights.append(np.exp(-(normal @ shift) - 0.5 * beta2))
    failed, unevaluable, w = (np.concatenate(x) for x in (failures, unevaluable, weights))
    evaluations += n
    unresolved = int(np.count_nonzero(unevaluable))
    if not np.any(failed | unevaluable):
        return _flagged(STATUS_NO_FAILURE, f"no failure among the {n} samples around the "
                                           f"design point (beta {design_point.beta:.4g}): no "
                                           "probability estimated; check the design point or "
                                           "use subset simulation",
                        evaluations, unresolved, common)
    lower, se_lower = _weighted_mean(np.where(failed, w, 0.0))
    upper, se_upper = _weighted_mean(np.where(failed | unevaluable, w, 0.0))
    resolved = 1.0 - (upper - lower)
    p = lower / resolved
    se = se_lower / resolved
    return RareEventResult(
        probability=p, standard_error=se, coefficient_of_variation=_cv(p, se),
        ci_lower=max(p - z * se, 0.0), ci_upper=p + z * se, interval=INTERVAL_NORMAL,
        evaluations=evaluations, unresolved=unresolved,
        failures=int(np.count_nonzero(failed)), bound_lower=lower, bound_upper=upper,
        bounds_ci_lower=max(lower - z * se_lower, 0.0), bounds_ci_upper=upper + z * se_upper,
        **common)


def _weighted_mean(x):
    """Mean and its standard error (sample standard deviation / sqrt(n))."""
    return float(np.mean(x)), float(np.std(x, ddof=1)) / math.sqrt(x.size)


#: The estimators by their config name (``[study] estimator``).
ESTIMATORS = {"monte_carlo": monte_carlo, "subset": subset_simulation,
              "importance": importance_sampling}
#: How :meth:`RareEventResult.describe` names them.
ESTIMATOR_TITLES = {"monte_carlo": "Monte Carlo", "subset": "subset simulation",
                    "importance": "importance sampling"}


# ---------------------------------------------------------------------------------------------
# helpers: seeds, blocks, evaluation, checks
# ---------------------------------------------------------------------------------------------

def _seed_sequence(seed) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed >= 0:
        return np.random.SeedSequence(int(seed))
    raise ValueError(f"seed = {seed!r}: expected a numpy SeedSequence or an int >= 0")


def _child(root, *keys) -> np.random.SeedSequence:
    """The SeedSequence (RARE_EVENT_STREAM, *keys) under ``root``, without spawning from it."""
    return np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, RARE_EVENT_STREAM,
                                                           *keys), pool_size=root.pool_size)


def _normal_blocks(root, keys, n, d):
    """Standard normals (n, d) as blocks of :data:`BLOCK_ROWS` rows, block k from child
    (*keys, k); the last block is drawn whole and cut."""
    for k, start in enumerate(range(0, n, BLOCK_ROWS)):
        block = np.random.default_rng(_child(root, *keys, k)).standard_normal((BLOCK_ROWS, d))
        yield block[:min(BLOCK_ROWS, n - start)]


def _evaluate(limit_state, u, batch_size):
    """g on the rows of u, in order, at most ``batch_size`` rows per call; read-only input."""
    rows = u.shape[0]
    size = rows if batch_size is None else int(batch_size)
    out = np.empty(rows)
    for start in range(0, rows, max(size, 1)):
        block = u[start:start + size]
        block.flags.writeable = False
        values = np.asarray(limit_state(block), dtype=float)
        if values.shape != (block.shape[0],):
            raise ValueError(f"limit_state returned shape {values.shape} for {block.shape[0]} "
                             f"rows; expected ({block.shape[0]},)")
        out[start:start + size] = values
    return out


def _cv(p, se):
    if not np.isfinite(p):
        return float("nan")
    return se / p if p > 0 else float("inf")


def _check_dimension(dimension) -> int:
    if isinstance(dimension, bool) or not isinstance(dimension, int | np.integer) \
            or dimension < 1:
        raise ValueError(f"dimension = {dimension!r} must be an int >= 1")
    return int(dimension)


def _check_count(name, value, minimum) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} = {value!r} must be an int >= {minimum}")
    return int(value)


def _check_batch_size(batch_size):
    if batch_size is not None:
        _check_count("batch_size", batch_size, 1)


def _check_confidence(confidence_level) -> float:
    if not 0 < confidence_level < 1:
        raise ValueError(f"confidence_level = {confidence_level!r} must be in (0, 1)")
    return float(ndtri(0.5 + confidence_level / 2))
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
    """

    names: tuple
    points: np.ndarray
    betas: np.ndarray
    evaluations: int

    @property
    def most_probable(self) -> int:
        """The component with the smallest beta."""
        return int(np.argmin(self.betas))


def series_importance_sampling(limit_state, seed, *, samples=2000, batch_size=None,
                               confidence_level=0.95):
    """FORM on every component, then importance sampling from the mixture of N(u*_k, I).

    ``limit_state`` is a limit state of a series event with ``dimension``,
    ``component_names`` and ``component(k)`` (a limit state of component k alone; e.g.
    :class:`tolsim.study.analyses.limit_state.LimitState`). A series event (the union of its
    components: any pair touches, any ball beyond the limit) has a design point per
    component, often several of similar beta (the pairs of a train). Importance sampling
    around one of them misses the others' failure domains and is low by a factor of up to
    their number, with a standard error that does not show it (module docstring). Here each
    component's design point u*_k is found (:func:`find_design_point` on the component
    alone), and the samples are drawn from the mixture q(v) = sum_k pi_k phi(v - u*_k), pi_k
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

    Returns
    -------
    (RareEventResult, SeriesDesignPoints or None)
        The result's ``design_point``, ``beta`` and ``importance_factors`` are those of the
        most probable component; ``form_probability`` is the first-order series bound
        min(1, sum_k Phi(-beta_k)) (each component's FORM estimate, added). Flagged
        ``form_failed`` when FORM gives no design point for some component (its message
        names it), ``no_failure`` when no sample fails.
    """
    d = limit_state.dimension
    n = int(samples)
    if n < 2:
        raise ValueError(f"samples = {samples!r} must be >= 2")
    z = _check_confidence(confidence_level)
    root = _seed_sequence(seed)
    names = limit_state.component_names
    common = dict(estimator="importance", confidence_level=confidence_level, dimension=d,
                  samples_per_level=n)
    points, betas, evaluations = [], [], 0
    for k, name in enumerate(names):
        found = find_design_point(limit_state.component(k), d, batch_size=batch_size)
        evaluations += found.evaluations
        if not found.converged:
            return _flagged(STATUS_FORM_FAILED, f"FORM found no design point for {name}: "
                                                f"{found.message}", evaluations, 0,
                            common), None
        points.append(found.point)
        betas.append(found.beta)
    design = SeriesDesignPoints(tuple(names), np.array(points), np.array(betas), evaluations)
    best = design.most_probable
    shifts, beta = design.points, design.betas
    log_weight = log_ndtr(-beta)
    log_weight = log_weight - logsumexp(log_weight)
    star = shifts[best]
    common.update(design_point=star, beta=float(beta[best]),
                  form_probability=float(min(1.0, np.sum(ndtr(-beta)))),
                  importance_factors=(star / beta[best]) ** 2)
    labels = np.random.default_rng(_child(root, 1)).choice(len(names), size=n,
                                                           p=np.exp(log_weight))
    v = np.concatenate(list(_normal_blocks(root, (0,), n, d))) + shifts[labels]
    # log q(v) / phi(v), row by row
    log_ratio = logsumexp(log_weight + v @ shifts.T - 0.5 * beta * beta, axis=1)
    w = np.exp(-log_ratio)
    g = _evaluate(limit_state, v, batch_size)
    evaluations += n
    failed, unevaluable = g <= 0, np.isnan(g)
    unresolved = int(np.count_nonzero(unevaluable))
    if not np.any(failed | unevaluable):
        return _flagged(STATUS_NO_FAILURE, f"no failure among the {n} samples around the "
                                           f"{len(names)} design points: no probability "
                                           "estimated", evaluations, unresolved,
                        common), design
    lower, se_lower = _weighted_mean(np.where(failed, w, 0.0))
    upper, se_upper = _weighted_mean(np.where(failed | unevaluable, w, 0.0))
    resolved = 1.0 - (upper - lower)
    p = lower / resolved
    se = se_lower / resolved
    return RareEventResult(
        probability=p, standard_error=se, coefficient_of_variation=_cv(p, se),
        ci_lower=max(p - z * se, 0.0), ci_upper=p + z * se, interval=INTERVAL_NORMAL,
        evaluations=evaluations, unresolved=unresolved,
        failures=int(np.count_nonzero(failed)), bound_lower=lower, bound_upper=upper,
        bounds_ci_lower=max(lower - z * se_lower, 0.0), bounds_ci_upper=upper + z * se_upper,
        **common), design


