"""Tolerance allocation (``tolsim allocate``, issue 14): the loosest set of tolerances that
meets a probabilistic target at the least manufacturing cost.

The problem
-----------
Decision variables: a scale factor s_i > 0 per tolerance source i, "the tolerance times s_i":
every value x of the source becomes centre + s_i (x - centre)
(:meth:`tolsim.study.spec.Distribution.scaled`), so a normal's std, a band, a cpk band and
measured values all scale by s_i. s_i = 1 is the config as given; each s_i lies within the
source's bounds [``min_scale``, ``max_scale``].

Cost: the reciprocal power model of each source's tolerance-dependent cost,

    C(s) = sum_i w_i s_i^(-k_i),

with ``cost_weight`` w_i (the source's cost at the config's tolerance, relative to the
others) and ``cost_exponent`` k_i (how fast the cost grows as the tolerance shrinks). It is
the model C_i = A_i + B_i / T_i^k_i of the tolerance-allocation literature ([Chase1990]; the
reciprocal square k = 2 of [Spotts1973] is its best-known member) with T_i = s_i T_i,0, the
fixed part A_i dropped (it does not move the optimum) and w_i = B_i / T_i,0^k_i. The cost is
reported as C(s) / C(1), its ratio to the config as given. Default: k_i = 2
(:data:`DEFAULT_COST_EXPONENT`, Spotts's reciprocal square) and w_i = 1 for every source, a
neutral start that a shop replaces by fits to its own process costs. The exponential model of
[Speckhart1972], C = A exp(-B T), is not offered: it needs the tolerance's absolute size in
the exponent, where the reciprocal power depends only on the ratio s_i.

Constraint: a reported probability, or a quantile turned into one, must stay at or below a
limit *with stated confidence*: its one-sided upper confidence bound U(s) at ``confidence``
(not the point estimate) must satisfy U(s) <= limit. For P(contact) and P(friction increase
> its limit) U is the Clopper-Pearson upper end of k + u of N, the unresolved trains u
counted as events (the partial-identification bound that holds whatever they would have
done, :meth:`tolsim.study.statistics.accumulator.Accumulator.contact_probability_bounds`). The
targets
(:data:`TARGETS`):

* ``contact_probability <= p``;
* ``friction_exceedance_probability <= p`` (a config with ``[contact]`` and a
  ``friction_increase_limit_N``);
* ``velocity_deviation_out_of_spec_fraction <= p``: the fraction of balls with |epsilon|
  above ``velocity_deviation_limit`` (the config's), its upper bound over assemblies as
  sampling units (Korn-Graubard, :func:`tolsim.study.statistics.intervals.cluster_proportion`) with
  the unresolved balls counted as out of spec;
* ``velocity_deviation_abs_quantile(q) <= L``: the q-quantile of |epsilon| at most L, which
  is the same statement as "the fraction of balls with |epsilon| > L is at most 1 - q", and
  is evaluated so (the upper bound of that fraction against 1 - q).

Method
------
1. **Common random numbers**: every evaluation is a study of the same ``samples`` assemblies
   with the same seed: the same standard normals, mapped through the scaled distributions.
   U(s) is then a deterministic function of s (a step function: counts change by whole
   assemblies), and differences between evaluations carry far less noise than independent
   runs would ([Law2015] Sec. 11.2). The allocation is the optimum of this sample-average
   approximation of the chance-constrained problem ([Luedtke2008]).
2. **A common-factor sweep** of all sources (each clipped to its bounds) from every source at
   its ``min_scale`` to every source at its ``max_scale``, and a bisection of where it
   crosses the limit: a first feasible design, and the trade-off curve of the config's own
   proportions. If even every source at its ``min_scale`` misses the target, there is no
   allocation (:class:`AllocationInfeasible`); if every source at its ``max_scale`` meets it,
   that is the optimum (the cost falls with every s_i).
3. **A trust-region response surface** in log s: around the current design x_c, the 2 d
   axial points x_c +- rho e_i; a plane fitted by weighted least squares (Gaussian weights of
   width 1.5 rho) to probit(U) = Phi^-1(U) over all evaluations so far; then the smooth
   convex sub-problem "least cost with the plane at or below Phi^-1(limit), within the
   bounds and |x - x_c| <= 2 rho", solved exactly from its KKT conditions (one Lagrange
   multiplier, found by Brent's method: x_i = -ln(lambda g_i / (w_i k_i)) / k_i, clipped).
   The solution is evaluated and becomes the next centre; rho halves when the step ends
   inside the trust region, and the search stops at rho < :data:`MIN_RADIUS` (3 % in s) or
   when the evaluation budget is spent.
4. **A ray search** from the last design along the common factor (all s_i times one
   factor, clipped to the bounds): the largest factor whose U meets the limit, to 0.25 %.
5. The optimum is the **cheapest evaluated design within the bounds that meets the limit**
   on the common sample: whatever the surrogate did, the reported optimum is a design whose
   constraint was evaluated, not predicted. Scales are rounded to
   :data:`SCALE_DIGITS` significant digits *before* every evaluation, so the optimum is
   exactly the design written to the allocated config.
6. A **trade-off sweep** along the optimum's proportions (the optimum times 0.5 to 2) for the
   report's curve of cost against U.

Verification
------------
The optimum was chosen *on* the optimisation sample, so its U there is optimistic (the
design sits where that sample's U just meets the limit). It is re-evaluated on a **fresh,
independent sample** of ``verify_samples`` assemblies (default :data:`VERIFY_SAMPLES_FACTOR`
times ``samples``: with 4 times the assemblies the upper bound is about half as far above
the estimate, so a design at the limit on the optimisation sample usually meets it on the
verification sample too) drawn from the seed :func:`verification_seed`: the first 32-bit word
of ``SeedSequence(seed, spawn_key=(5,))`` (:data:`VERIFY_SPAWN_KEY`; the plain run uses the
spawn keys (0, k) and (1, ...), the sensitivity analysis (2,) and (3,), the rare-event
estimators (4, ...)). That seed is a study seed: the allocated config carries it and the
verification's samples, so the plain Monte Carlo counts of ``tolsim run`` on it are the
verification's. Its estimate, its interval and whether its upper bound meets the limit are
the allocation's honest result (an independent sample and a binomial bound certify a
candidate's feasibility, as in [Luedtke2008]).

Every evaluation (and the verification) is plain Monte Carlo without spot checks or
sensitivity analysis (:func:`evaluation_config`): a config's rare-event estimator is not
used, since common random numbers need the plain run. A config with a ``[sweep]`` is
refused (:func:`check_allocation`).

Everything here works on plain numbers and :class:`~tolsim.study.spec.StudyConfig` objects:
:func:`allocate_scales` is the generic core (it takes any evaluator scales -> (estimate,
bounds), so the tests drive it with a closed-form limit state), :func:`run_allocation` runs
it on a study. No file, TOML or plotting here (:mod:`tolsim.io.allocation` reads
``[allocate]`` and writes the allocated config, :mod:`tolsim.reports.allocate` the report).

References
----------
.. [Chase1990] K. W. Chase, W. H. Greenwood, B. G. Loosli, L. F. Hauglund, "Least cost
   tolerance allocation for mechanical assemblies with automated process selection",
   Manufacturing Review 3(1) (1990) 49-59. Reciprocal power cost C = A + B / T^k per
   process, allocation by Lagrange multipliers.
.. [ChaseGreenwood1988] K. W. Chase, W. H. Greenwood, "Design issues in mechanical tolerance
   analysis", Manufacturing Review 1(1) (1988) 50-59. Review of tolerance analysis and of
   least-cost allocation with cost-tolerance curves.
.. [Spotts1973] M. F. Spotts, "Allocation of tolerances to minimize cost of assembly", ASME
   Journal of Engineering for Industry 95(3) (1973) 762-764. Reciprocal square cost
   C = A + B / T^2.
.. [Speckhart1972] F. H. Speckhart, "Calculation of tolerance based on a minimum cost
   approach", ASME Journal of Engineering for Industry 94(2) (1972) 447-453. Exponential
   cost C = A exp(-B T).
.. [Law2015] A. M. Law, Simulation Modeling and Analysis, 5th ed., McGraw-Hill, 2015,
   Sec. 11.2 (common random numbers).
.. [Luedtke2008] J. Luedtke, S. Ahmed, "A sample approximation approach for optimization with
   probabilistic constraints", SIAM Journal on Optimization 19(2) (2008) 674-699,
   doi:10.1137/070702928.
"""

import math
import re
import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import brentq
from scipy.special import ndtri

from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.block import has_contact
from tolsim.study.spec import SOURCES
from tolsim.study.statistics.intervals import clopper_pearson_interval, cluster_proportion

# --------------------------------------------------------------------------------------------
# Defaults (module docstring)
# --------------------------------------------------------------------------------------------
#: Bounds of a source's scale factor when ``[allocate.sources]`` does not list any source [-].
DEFAULT_MIN_SCALE = 0.25
DEFAULT_MAX_SCALE = 4.0
#: Reciprocal square cost, C = A + B / T^2 ([Spotts1973]).
DEFAULT_COST_EXPONENT = 2.0
DEFAULT_COST_WEIGHT = 1.0
#: One-sided confidence of the upper bound that must meet the limit [-].
DEFAULT_CONFIDENCE = 0.95
#: Evaluations (studies on the common sample) at most.
DEFAULT_MAX_EVALUATIONS = 120
#: Verification assemblies per optimisation assembly (default ``verify_samples``).
VERIFY_SAMPLES_FACTOR = 4
#: Spawn key of the verification seed under the study's seed (module docstring).
VERIFY_SPAWN_KEY = 5
#: Significant digits of every evaluated (and written) scale factor.
SCALE_DIGITS = 4
#: Points of the common-factor sweep (from all sources at min_scale to all at max_scale).
SWEEP_POINTS = 7
#: Bisection steps (in log s) of the sweep's crossing of the limit.
BRACKET_STEPS = 3
#: Starting and smallest trust-region radius [in ln s].
START_RADIUS = 0.4
MIN_RADIUS = 0.03
#: Resolution of the final ray search [in ln s] (0.25 %).
RAY_RESOLUTION = 0.0025
#: Factors of the trade-off sweep along the optimum's proportions.
TRADE_OFF_FACTORS = (0.5, 0.7, 0.85, 1.2, 1.45, 2.0)
#: U is kept within (PROBIT_CLIP, 1 - PROBIT_CLIP) before its probit is taken.
PROBIT_CLIP = 1e-12


class AllocationInfeasible(ValueError):
    """No design within the bounds meets the target on the optimisation sample."""


# --------------------------------------------------------------------------------------------
# Targets
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Evaluation:
    """A probability (or fraction) from one sample, with its one-sided confidence bounds.

    Attributes
    ----------
    estimate : float
        The point estimate [-] (NaN when undefined).
    lower, upper : float
        One-sided lower and upper confidence bounds at the confidence used [-]; together the
        two-sided interval at 2 confidence - 1. ``upper`` is the one a target must meet: for
        P(contact) it counts the unresolved trains as contacts.
    """

    estimate: float
    lower: float
    upper: float


def binomial_evaluation(successes, trials, confidence, unresolved=0) -> Evaluation:
    """Estimate k / (n - u) and the Clopper-Pearson bounds of the partial-identification
    bounds k / n and (k + u) / n, each one-sided at ``confidence``.

    Parameters
    ----------
    successes : int
        Events k among the trials whose outcome is known.
    trials : int
        All trials n (known and unresolved).
    confidence : float
        One-sided confidence level of each bound, in (0.5, 1).
    unresolved : int
        Trials u whose outcome is unknown (counted as events in the upper bound).
    """
    k, n, u = int(successes), int(trials), int(unresolved)
    two_sided = 2.0 * confidence - 1.0
    lower = clopper_pearson_interval(k, n, two_sided)[0]
    upper = clopper_pearson_interval(k + u, n, two_sided)[1]
    estimate = k / (n - u) if n > u else float("nan")
    return Evaluation(estimate, lower, upper)


def _contact_probability(statistics, target, confidence) -> Evaluation:
    return binomial_evaluation(statistics.n_contact, statistics.n_assemblies, confidence,
                               statistics.n_unresolved)


def _friction_exceedance(statistics, target, confidence) -> Evaluation:
    f = statistics.friction
    return binomial_evaluation(f.n_exceed, f.n_assemblies, confidence, f.n_unresolved)


def _out_of_spec(statistics, target, confidence) -> Evaluation:
    prop = cluster_proportion(statistics.cluster, 2.0 * confidence - 1.0)
    balls, valid = int(statistics.n_balls), int(statistics.n_balls_valid)
    if not (balls and valid and np.isfinite(prop.upper)):
        return Evaluation(float("nan"), 0.0, 1.0)
    missing = (balls - valid) / balls  # unresolved balls: out of spec in the upper bound
    return Evaluation(prop.fraction, prop.lower * (1.0 - missing),
                      prop.upper * (1.0 - missing) + missing)


def _needs_friction_limit(config, target):
    if not has_contact(config) or not config.contact.friction_increase_limit > 0:
        return ("needs a config with [contact] and a friction_increase_limit_N (the "
                "friction increase whose exceedance it bounds)")
    return None


def _needs_epsilon_limit(config, target):
    if not config.study.velocity_deviation_limit > 0:
        return ("needs a limit on |epsilon| in the config ([study] "
                "velocity_deviation_limit_percent), or use velocity_deviation_abs_quantile(q)"
                " <= L")
    return None


@dataclass(frozen=True)
class TargetVariable:
    """A variable a target can bound: how to read it off a study, what it needs."""

    description: str
    evaluate: object  # (statistics, target, confidence) -> Evaluation
    quantile: bool = False
    requires: object = None  # (config, target) -> problem text or None


#: The variables a target can bound (module docstring), by their result-file names.
TARGETS = {
    "contact_probability": TargetVariable(
        "P(contact within the horizon) per train (per assembly with a carriage)",
        _contact_probability),
    "friction_exceedance_probability": TargetVariable(
        "P(friction increase > its limit) per assembly", _friction_exceedance,
        requires=_needs_friction_limit),
    "velocity_deviation_out_of_spec_fraction": TargetVariable(
        "fraction of balls with |epsilon| above the config's limit", _out_of_spec,
        requires=_needs_epsilon_limit),
    "velocity_deviation_abs_quantile": TargetVariable(
        "quantile of |epsilon| over the balls", _out_of_spec, quantile=True),
}

_TARGET_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?:\(\s*([^()]*?)\s*\))?\s*"
                        r"(<=|>=|==|!=|<|>|=)\s*(.*?)\s*$")
_NUMBER_RE = re.compile(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(%|ppm)?$")
_NUMBER_UNITS = {None: 1.0, "%": 1e-2, "ppm": 1e-6}


def _number(text, what):
    m = _NUMBER_RE.match(text.strip())
    if not m:
        raise ValueError(f"{what} {text!r} is not a number (such as 0.01, 1%, 200ppm)")
    return float(m.group(1)) * _NUMBER_UNITS[m.group(2)]


@dataclass(frozen=True)
class Target:
    """An upper limit on a reported probability or quantile (:func:`parse_target`).

    Attributes
    ----------
    variable : str
        A key of :data:`TARGETS`.
    limit : float
        The limit [-]: on the probability, or for a quantile on |epsilon| (a fraction,
        0.005 = 0.5 %).
    level : float or None
        The quantile level q of a quantile target, else None.
    """

    variable: str
    limit: float
    level: float | None = None

    def __post_init__(self):
        if self.variable not in TARGETS:
            raise ValueError(f"unknown target variable {self.variable!r} (one of "
                             f"{', '.join(TARGETS)})")
        spec = TARGETS[self.variable]
        if spec.quantile != (self.level is not None):
            raise ValueError(
                f"{self.variable} needs a quantile level: {self.variable}(0.999) <= 0.5%"
                if spec.quantile else
                f"{self.variable} is a probability and takes no level in parentheses")
        if spec.quantile and not 0 < self.level < 1:
            raise ValueError(f"quantile level {self.level!r} must be in (0, 1)")
        if not (np.isfinite(self.limit) and 0 < self.limit < 1):
            raise ValueError(f"limit {self.limit!r} must be in (0, 1) (0.01, 1%, 200ppm)")

    @property
    def probability_limit(self) -> float:
        """The limit on the probability actually bounded: ``limit``, or 1 - q for a
        quantile target (the fraction of balls with |epsilon| > limit)."""
        return self.limit if self.level is None else 1.0 - self.level

    @property
    def epsilon_limit(self) -> float | None:
        """The |epsilon| limit [-] a quantile target sets for its evaluation, else None."""
        return self.limit if self.level is not None else None

    def __str__(self):
        if self.level is None:
            return f"{self.variable} <= {self.limit:.6g}"
        return f"{self.variable}({self.level:.6g}) <= {self.limit:.6g}"

    def describe(self) -> str:
        """The target in words, for reports."""
        if self.level is None:
            return f"{TARGETS[self.variable].description} <= {self.limit:.4g}"
        return (f"the {self.level:.6g} quantile of |epsilon| <= {100 * self.limit:.4g} %, "
                f"i.e. at most {self.probability_limit:.4g} of the balls with |epsilon| > "
                f"{100 * self.limit:.4g} %")

    def problem(self, config) -> str | None:
        """Why ``config`` cannot be allocated against this target (one line), or None."""
        check = TARGETS[self.variable].requires
        return None if check is None else check(config, self)


def parse_target(text: str) -> Target:
    """A :class:`Target` from ``NAME <= VALUE`` or ``NAME(LEVEL) <= VALUE``.

    VALUE is a number, optionally with ``%`` or ``ppm``: ``contact_probability<=0.01``,
    ``friction_exceedance_probability <= 5%``, ``velocity_deviation_abs_quantile(0.999) <=
    0.5%``.

    Raises
    ------
    ValueError
        One line naming what is wrong.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError("target is empty: write NAME <= VALUE, e.g. contact_probability<=0.01")
    m = _TARGET_RE.match(text)
    if not m:
        raise ValueError(f"target {text!r} is not NAME <= VALUE (e.g. contact_probability"
                         "<=0.01 or velocity_deviation_abs_quantile(0.999)<=0.5%)")
    name, level_text, op, value_text = m.groups()
    if name not in TARGETS:
        raise ValueError(f"target {text!r}: unknown variable {name!r} (one of "
                         f"{', '.join(TARGETS)})")
    if op not in ("<=", "<"):
        raise ValueError(f"target {text!r}: only an upper limit can be allocated against "
                         f"('<='), got {op!r}")
    if not value_text:
        raise ValueError(f"target {text!r} has no value after {op!r}")
    try:
        limit = _number(value_text, "value")
        level = None if level_text is None else _number(level_text, "quantile level")
        return Target(name, limit, level)
    except ValueError as exc:
        raise ValueError(f"target {text!r}: {exc}") from None


# --------------------------------------------------------------------------------------------
# Sources and their costs
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SourceCost:
    """A decision variable: a tolerance source's scale factor, its bounds and its cost.

    Attributes
    ----------
    source : str
        A key of :data:`tolsim.study.spec.SOURCES`.
    min_scale, max_scale : float
        Bounds of the scale factor s [-], 0 < min_scale < max_scale. ``max_scale`` None:
        :data:`DEFAULT_MAX_SCALE`, lowered where the static model's range demands it
        (:func:`resolve_sources`).
    cost_exponent : float
        k > 0 of the cost w s^-k (module docstring).
    cost_weight : float
        w > 0: the source's cost at s = 1 (the config's tolerance), relative to the others.
    """

    source: str
    min_scale: float = DEFAULT_MIN_SCALE
    max_scale: float | None = DEFAULT_MAX_SCALE
    cost_exponent: float = DEFAULT_COST_EXPONENT
    cost_weight: float = DEFAULT_COST_WEIGHT

    def __post_init__(self):
        for name in ("min_scale", "max_scale", "cost_exponent", "cost_weight"):
            value = getattr(self, name)
            if name == "max_scale" and value is None:
                continue
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{self.source} {name} = {value!r} must be finite and > 0")
        if self.max_scale is not None and not self.min_scale < self.max_scale:
            raise ValueError(f"{self.source} min_scale = {self.min_scale!r} must be less than "
                             f"max_scale = {self.max_scale!r}")


def tolerance_cost(scales, sources) -> float:
    """C(s) = sum_i w_i s_i^-k_i [-], the tolerance-dependent cost (module docstring)."""
    s = np.asarray(scales, dtype=float)
    w = np.array([c.cost_weight for c in sources])
    k = np.array([c.cost_exponent for c in sources])
    return float(np.sum(w * s ** -k))


def largest_scale(tolerance, bearing) -> float:
    """The largest scale factor that keeps ``tolerance`` within the errors the static model
    accepts (a quarter of the ball-groove centre distance for lengths, pi/8 for angles; an
    unbounded normal reaching :data:`tolsim.study.spec.PLAUSIBLE_NORMAL_RANGE` std), the
    rule the config reader applies to every tolerance [-]; inf for a fixed value."""
    kind = SOURCES[tolerance.source][0]
    limit = math.pi / 8 if kind == "angle" else 0.25 * (bearing.groove_radius
                                                         - bearing.ball_radius)
    d = tolerance.distribution
    c = d.centre
    out = math.inf
    for edge in d.support:
        if edge > c:
            out = min(out, (limit - c) / (edge - c))
        elif edge < c:
            out = min(out, (limit + c) / (c - edge))
    return out


@dataclass(frozen=True)
class AllocationSettings:
    """The settings of ``tolsim allocate`` (``[allocate]``, :mod:`tolsim.io.allocation`).

    Attributes
    ----------
    target : Target or None
        The limit to meet (None: must come from the caller, ``--target``).
    confidence : float
        One-sided confidence of the upper bound that must meet the limit, in (0.5, 1).
    sources : tuple of SourceCost
        The decision variables; the config's other sources keep their tolerances. Empty:
        every random source of the config, with the defaults of :class:`SourceCost`
        (:func:`resolve_sources`).
    samples : int or None
        Assemblies of every evaluation on the common sample (None: the config's
        ``[study] samples``).
    verify_samples : int or None
        Assemblies of the verification run (None: :data:`VERIFY_SAMPLES_FACTOR` x samples).
    max_evaluations : int
        Studies on the common sample at most.
    """

    target: Target | None = None
    confidence: float = DEFAULT_CONFIDENCE
    sources: tuple = ()
    samples: int | None = None
    verify_samples: int | None = None
    max_evaluations: int = DEFAULT_MAX_EVALUATIONS

    def __post_init__(self):
        if not (isinstance(self.confidence, float | int) and 0.5 < self.confidence < 1):
            raise ValueError(f"confidence = {self.confidence!r} must be in (0.5, 1), e.g. 0.95")
        for name in ("samples", "verify_samples"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, int) and value >= 1):
                raise ValueError(f"{name} = {value!r} must be a positive integer")
        if not (isinstance(self.max_evaluations, int) and self.max_evaluations >= 20):
            raise ValueError(f"max_evaluations = {self.max_evaluations!r} must be an integer "
                             ">= 20")
        names = [c.source for c in self.sources]
        if len(set(names)) != len(names):
            raise ValueError(f"sources {names!r} repeat a source")

    def with_overrides(self, **changes) -> "AllocationSettings":
        """A copy with the settings given (not None) replaced: the command-line flags."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


def resolve_sources(config, settings: AllocationSettings) -> tuple:
    """The decision variables of ``config``: ``settings.sources``, or every random source of
    the config with the defaults; a ``max_scale`` of None becomes the default, lowered to
    just below :func:`largest_scale` where the static model's range demands it.

    Raises
    ------
    ValueError
        For a config without a random source, a listed source the config does not draw at
        random, or a ``max_scale`` beyond the static model's range (naming the key).
    """
    given = {t.source: t for t in config.tolerances}
    random = [t.source for t in config.tolerances if t.distribution.is_random]
    if not random:
        raise ValueError("the config has no random tolerance source to allocate (every "
                         "[tolerances.*] is fixed, or there is none)")
    listed = settings.sources or tuple(SourceCost(name, max_scale=None) for name in random)
    out = []
    for cost in listed:
        if cost.source not in given:
            raise ValueError(f"allocate.sources.{cost.source}: the config has no "
                             f"[tolerances.{cost.source}]")
        if not given[cost.source].distribution.is_random:
            raise ValueError(f"allocate.sources.{cost.source}: the tolerance is fixed, there "
                             "is no spread to scale")
        top = largest_scale(given[cost.source], config.bearing)
        if cost.max_scale is None:  # the default, within the static model's range
            high = min(DEFAULT_MAX_SCALE, round_scale(0.999 * top))
            if not cost.min_scale < high:
                raise ValueError(f"allocate.sources.{cost.source}.min_scale = "
                                 f"{cost.min_scale:g}: the static model's range allows at "
                                 f"most a scale of {top:.4g} for this tolerance")
            cost = replace(cost, max_scale=high)
        elif cost.max_scale > top:
            raise ValueError(f"allocate.sources.{cost.source}.max_scale = {cost.max_scale:g} "
                             f"takes the tolerance beyond the errors the static model "
                             f"accepts: at most {top:.4g}")
        out.append(cost)
    return tuple(out)


# --------------------------------------------------------------------------------------------
# The generic core
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Point:
    """One evaluation on the common sample.

    Attributes
    ----------
    scales : tuple of float
        Scale factor per source, in the order of the sources [-].
    cost : float
        C(s), :func:`tolerance_cost` [-].
    evaluation : Evaluation
    stage : str
        Where it came from: ``as given``, ``sweep``, ``bracket``, ``design`` (a trust
        region's axial point), ``step`` (a sub-problem's solution), ``ray``, ``trade-off``.
    """

    scales: tuple
    cost: float
    evaluation: Evaluation
    stage: str

    def meets(self, limit) -> bool:
        """The upper bound is at or below ``limit`` (a NaN bound never meets it)."""
        return bool(self.evaluation.upper <= limit)


@dataclass
class AllocationSearch:
    """What :func:`allocate_scales` found.

    Attributes
    ----------
    sources : tuple of SourceCost
    limit : float
        The limit on the upper bound [-].
    points : list of Point
        Every evaluation, in order.
    optimum : Point
        The cheapest evaluated design within the bounds whose upper bound meets the limit.
    status : str
        One sentence on how the search ended.
    """

    sources: tuple
    limit: float
    points: list = field(default_factory=list)
    optimum: Point | None = None
    status: str = ""

    @property
    def reference_cost(self) -> float:
        """C(1): the cost of the config as given [-]."""
        return tolerance_cost(np.ones(len(self.sources)), self.sources)

    @property
    def cost_ratio(self) -> float:
        """C(optimum) / C(1) [-]."""
        return self.optimum.cost / self.reference_cost

    def stage(self, name) -> list:
        """The points of one stage, in order."""
        return [p for p in self.points if p.stage == name]


def round_scale(value: float) -> float:
    """``value`` to :data:`SCALE_DIGITS` significant digits (the grid of evaluated scales)."""
    return float(f"{float(value):.{SCALE_DIGITS}g}")


def _probit(upper) -> float:
    u = 1.0 if not np.isfinite(upper) else float(upper)
    return float(ndtri(min(max(u, PROBIT_CLIP), 1.0 - PROBIT_CLIP)))


def fit_probit_plane(xs, ys, centre, width):
    """Weighted least-squares plane y = a + g . (x - centre) (Gaussian weights of ``width``).

    Parameters
    ----------
    xs : ndarray (m, d)
        Designs [ln s].
    ys : ndarray (m,)
        Probits of their upper bounds.
    centre : ndarray (d,)
    width : float
        [ln s].

    Returns
    -------
    (a, g) : float, ndarray (d,)
    """
    d = np.asarray(xs, dtype=float) - centre
    w = np.sqrt(np.exp(-0.5 * np.sum(d * d, axis=1) / width ** 2))
    design = np.column_stack([np.ones(len(d)), d]) * w[:, None]
    coef = np.linalg.lstsq(design, np.asarray(ys, dtype=float) * w, rcond=None)[0]
    return float(coef[0]), coef[1:]


def solve_cost_subproblem(intercept, slope, centre, threshold, low, high, weight, exponent):
    """argmin sum_i w_i exp(-k_i x_i) subject to a + g . (x - c) <= t and low <= x <= high.

    Convex and separable: for a multiplier lambda >= 0 each x_i minimises
    w_i exp(-k_i x_i) + lambda g_i x_i on [low_i, high_i], that is x_i = high_i where
    g_i <= 0, else x_i = -ln(lambda g_i / (w_i k_i)) / k_i clipped; the constraint is then
    decreasing in lambda, and Brent's method finds the lambda where it is active. Where even
    every x_i with g_i > 0 at its low end misses the constraint, that corner is returned.

    Returns
    -------
    ndarray (d,)
        x [ln s].
    """
    g = np.asarray(slope, dtype=float)
    w, k = np.asarray(weight, dtype=float), np.asarray(exponent, dtype=float)
    low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
    pos = g > 0

    def x_of(log_lambda):
        x = high.copy()
        x[pos] = np.clip(-(log_lambda + np.log(g[pos] / (w[pos] * k[pos]))) / k[pos],
                         low[pos], high[pos])
        return x

    def excess(x):
        return intercept + float(g @ (x - centre)) - threshold

    if excess(high) <= 0:
        return high
    corner = np.where(pos, low, high)
    if excess(corner) >= 0:
        return corner
    base = np.log(w[pos] * k[pos] / g[pos])
    a = float(np.min(base - k[pos] * high[pos])) - 1.0  # every x_i at its high end
    b = float(np.max(base - k[pos] * low[pos])) + 1.0  # every x_i at its low end
    return x_of(brentq(lambda t: excess(x_of(t)), a, b, xtol=1e-10))


class _Budget(Exception):
    """The evaluation budget is spent."""


class _Search:
    """State of one :func:`allocate_scales` run: evaluations on the grid, with a cache."""

    def __init__(self, evaluate, sources, limit, max_evaluations, progress):
        self.evaluate, self.sources, self.limit = evaluate, sources, limit
        self.max_evaluations, self.progress = max_evaluations, progress
        self.low = np.log([c.min_scale for c in sources])
        self.high = np.log([c.max_scale for c in sources])
        self.bounds = [(c.min_scale, c.max_scale) for c in sources]
        self.points, self.cache = [], {}

    def grid(self, x) -> tuple:
        """ln-scales -> the scales evaluated: clipped to the bounds, then rounded."""
        s = np.exp(np.clip(x, self.low, self.high))
        return tuple(min(max(round_scale(v), lo), hi)
                     for v, (lo, hi) in zip(s, self.bounds, strict=True))

    def __call__(self, x, stage, *, clip=True) -> Point:
        scales = self.grid(x) if clip else tuple(round_scale(v) for v in np.exp(x))
        if scales in self.cache:
            return self.cache[scales]
        if len(self.points) >= self.max_evaluations:
            raise _Budget
        evaluation = self.evaluate(np.array(scales))
        point = Point(scales, tolerance_cost(scales, self.sources), evaluation, stage)
        self.cache[scales] = point
        self.points.append(point)
        if self.progress is not None:
            self.progress(point)
        return point

    def x(self, point) -> np.ndarray:
        return np.log(np.array(point.scales))

    def inside(self, point) -> bool:
        return all(lo <= s <= hi for s, (lo, hi) in zip(point.scales, self.bounds, strict=True))

    def best(self):
        ok = [p for p in self.points if self.inside(p) and p.meets(self.limit)]
        return min(ok, key=lambda p: (p.cost, p.scales)) if ok else None


def _bracket(search, feasible_f, infeasible_f):
    """Bisect ln f between a feasible and an infeasible common factor; the feasible end."""
    a, b = math.log(feasible_f), math.log(infeasible_f)
    ones = np.ones(len(search.sources))
    for _ in range(BRACKET_STEPS):
        mid = 0.5 * (a + b)
        if search(mid * ones, "bracket").meets(search.limit):
            a = mid
        else:
            b = mid
    return search(a * ones, "bracket")


def _trust_region(search, start: Point, reserve: int) -> tuple:
    """Steps 3 of the module docstring; returns (last design, sentence)."""
    d = len(search.sources)
    w = np.array([c.cost_weight for c in search.sources])
    k = np.array([c.cost_exponent for c in search.sources])
    threshold = _probit(search.limit)
    centre, radius, rounds = search.x(start), START_RADIUS, 0
    while radius >= MIN_RADIUS:
        if len(search.points) + 2 * d + 1 + reserve > search.max_evaluations:
            return centre, (f"the evaluation budget ran out at a trust-region radius of "
                            f"{100 * (math.exp(radius) - 1):.2g} % after {rounds} rounds")
        evaluated = len(search.points)
        for i in range(d):
            for sign in (1.0, -1.0):
                step = np.zeros(d)
                step[i] = sign * radius
                search(centre + step, "design")
        xs = np.array([search.x(p) for p in search.points])
        ys = np.array([_probit(p.evaluation.upper) for p in search.points])
        intercept, slope = fit_probit_plane(xs, ys, centre, 1.5 * radius)
        low = np.maximum(search.low, centre - 2 * radius)
        high = np.minimum(search.high, centre + 2 * radius)
        x_new = solve_cost_subproblem(intercept, slope, centre, threshold, low, high, w, k)
        point = search(x_new, "step")
        x_new = search.x(point)
        at_edge = np.any((np.abs(x_new - centre) > 0.99 * 2 * radius)
                         & (x_new > search.low + 1e-9) & (x_new < search.high - 1e-9))
        if not at_edge or len(search.points) == evaluated:  # (nothing new: shrink anyway)
            radius *= 0.5
        centre, rounds = x_new, rounds + 1
    return centre, (f"converged: the trust region shrank below "
                    f"{100 * (math.exp(MIN_RADIUS) - 1):.2g} % in the scales after "
                    f"{rounds} rounds")


def _ray(search, x0):
    """Step 4: the largest common factor from x0 whose upper bound meets the limit."""
    limit = search.limit

    def at(t):
        return search(np.clip(x0 + t, search.low, search.high), "ray")

    if at(0.0).meets(limit):
        a, step = 0.0, 2 * RAY_RESOLUTION
        while True:
            b = a + step
            if np.all(np.clip(x0 + a, search.low, search.high) >= search.high):
                return
            if not at(b).meets(limit):
                break
            a, step = b, 2 * step
    else:
        b, step = 0.0, 2 * RAY_RESOLUTION
        while True:
            a = b - step
            if np.all(np.clip(x0 + b, search.low, search.high) <= search.low):
                return
            if at(a).meets(limit):
                break
            b, step = a, 2 * step
    while b - a > RAY_RESOLUTION:
        mid = 0.5 * (a + b)
        if at(mid).meets(limit):
            a = mid
        else:
            b = mid


def allocate_scales(evaluate, sources, limit, *, max_evaluations=DEFAULT_MAX_EVALUATIONS,
                    progress=None) -> AllocationSearch:
    """The least-cost scale factors whose upper bound meets ``limit`` (module docstring).

    Parameters
    ----------
    evaluate : callable
        scales (ndarray (d,), in the order of ``sources``) -> :class:`Evaluation`. It must
        use common random numbers (the same sample for every call), so that it is a
        deterministic function of the scales.
    sources : sequence of SourceCost
        The decision variables, their bounds and costs.
    limit : float
        The upper bound must be at or below it [-].
    max_evaluations : int
        Calls of ``evaluate`` at most.
    progress : callable, optional
        Called with every new :class:`Point`.

    Returns
    -------
    AllocationSearch

    Raises
    ------
    AllocationInfeasible
        If every source at its ``min_scale`` misses the limit.
    """
    sources = tuple(sources)
    if not sources:
        raise ValueError("no source to allocate")
    if not 0 < limit < 1:
        raise ValueError(f"limit = {limit!r} must be in (0, 1)")
    search = _Search(evaluate, sources, limit, max_evaluations, progress)
    out = AllocationSearch(sources, limit, search.points)
    d = len(sources)
    search(np.zeros(d), "as given", clip=False)
    lo = min(c.min_scale for c in sources)
    hi = max(c.max_scale for c in sources)
    factors = np.geomspace(lo, hi, SWEEP_POINTS)
    sweep = [search(np.full(d, math.log(f)), "sweep") for f in factors]
    if not sweep[0].meets(limit):
        scales = ", ".join(f"{c.source} {c.min_scale:g}" for c in sources)
        raise AllocationInfeasible(
            f"the target is not met even with every source at its min_scale ({scales}): the "
            f"upper bound is {sweep[0].evaluation.upper:.4g} > {limit:.4g}; lower min_scale, "
            "add samples (the bound cannot fall below 1 - (1 - confidence)^(1/N)) or relax "
            "the target")
    reserve = 12 + len(TRADE_OFF_FACTORS)
    try:
        if sweep[-1].meets(limit):
            out.status = ("every source at its max_scale meets the target: the loosest "
                          "tolerances allowed are the optimum")
        else:
            first = next(i for i, p in enumerate(sweep) if not p.meets(limit))
            start = _bracket(search, factors[first - 1], factors[first])
            centre, out.status = _trust_region(search, start, reserve)
            _ray(search, centre)
    except _Budget:
        out.status = "the evaluation budget ran out"
    optimum = search.best()
    try:
        x_opt = search.x(optimum)
        for f in TRADE_OFF_FACTORS:
            search(x_opt + math.log(f), "trade-off")
    except _Budget:
        pass
    out.optimum = search.best()  # the same, unless U is not monotone along that ray
    return out


# --------------------------------------------------------------------------------------------
# On a study
# --------------------------------------------------------------------------------------------
def verification_seed(seed: int) -> int:
    """The study seed of the verification run: the first 32-bit word of
    ``SeedSequence(seed, spawn_key=(VERIFY_SPAWN_KEY,))`` (module docstring)."""
    sequence = np.random.SeedSequence(int(seed), spawn_key=(VERIFY_SPAWN_KEY,))
    return int(sequence.generate_state(1, dtype=np.uint32)[0])


def evaluation_config(config, target: Target, samples: int, seed: int):
    """The study one evaluation runs: ``samples`` assemblies from ``seed``, plain Monte
    Carlo (a rare-event estimator of the config is not used: common random numbers need
    the plain run), no spot checks, no sensitivity analysis, no stored friction examples;
    for a quantile target the |epsilon| limit of the target."""
    config = config.with_overrides(samples=samples, seed=seed)
    study = replace(config.study, spot_checks=0, sensitivity_samples=0,
                    estimator="monte_carlo")
    if target.epsilon_limit is not None:
        study = replace(study, velocity_deviation_limit=target.epsilon_limit)
    contact = replace(config.contact, examples=0) if has_contact(config) else None
    return replace(config, study=study, contact=contact)


def evaluate_study(config, target: Target, confidence: float, *, workers=1, progress=None):
    """Run the study ``config`` and read the target's variable off it.

    Returns
    -------
    (Evaluation, StudyResult)
    """
    result = run_study(config, workers=workers, progress=progress)
    return TARGETS[target.variable].evaluate(result.statistics, target, confidence), result


def minimum_samples(limit: float, confidence: float) -> int:
    """Fewest trials whose Clopper-Pearson upper bound with no event, 1 - (1 - c)^(1/n), is
    at most ``limit``."""
    return math.ceil(math.log(1.0 - confidence) / math.log1p(-limit))


def check_allocation(config, settings: AllocationSettings) -> tuple:
    """Everything about an allocation that can be wrong before any work.

    Returns
    -------
    (target, sources, samples, verify_samples)
        The :class:`Target`, the :func:`resolve_sources`, the assemblies of every evaluation
        and of the verification.

    Raises
    ------
    ValueError
        One line: no target, a target the config cannot report, a config with a
        ``[sweep]`` or without random sources, bounds beyond the static model's range,
        too few samples to show the limit at the confidence.
    """
    target = settings.target
    if target is None:
        raise ValueError("no target: give one, e.g. contact_probability<=0.01 (--target, or "
                         "target = ... in [allocate])")
    problem = target.problem(config)
    if problem:
        raise ValueError(f"target {target}: {problem}")
    if getattr(config, "sweep", None) is not None:
        raise ValueError("the config has a [sweep]: allocation scales the tolerances itself; "
                         "remove [sweep] (or allocate each point's config)")
    sources = resolve_sources(config, settings)
    samples = settings.samples or config.study.samples
    limit, confidence = target.probability_limit, float(settings.confidence)
    if target.variable in ("contact_probability", "friction_exceedance_probability"):
        need = minimum_samples(limit, confidence)
        if samples < need:
            raise ValueError(f"samples = {samples} cannot show P <= {limit:g} at {confidence:g} "
                             f"confidence even with no event (the upper bound is then "
                             f"1 - (1 - c)^(1/N)); use at least {need}, better 10 times that")
    verify_samples = settings.verify_samples or VERIFY_SAMPLES_FACTOR * samples
    return target, sources, samples, verify_samples


@dataclass
class AllocationResult:
    """Everything :func:`run_allocation` produced.

    Attributes
    ----------
    config : StudyConfig
        The config as given (with the run-level overrides).
    target : Target
    confidence : float
    sources : tuple of SourceCost
        The decision variables.
    search : AllocationSearch
    samples, seed : int
        The common sample of the optimisation.
    verify_samples, verify_seed : int
        The verification run.
    verification : Evaluation
        The target's variable at the optimum on the verification sample.
    verification_result : StudyResult
    optimum_config : StudyConfig
        The config the verification ran: the optimum.
    search_seconds, verify_seconds : float
        Wall times [s].
    """

    config: object
    target: Target
    confidence: float
    sources: tuple
    search: AllocationSearch
    samples: int
    seed: int
    verify_samples: int
    verify_seed: int
    verification: Evaluation
    verification_result: object
    optimum_config: object
    search_seconds: float = 0.0
    verify_seconds: float = 0.0

    @property
    def scales(self) -> dict:
        """The optimum: source -> scale factor [-]."""
        return {c.source: s for c, s in zip(self.sources, self.search.optimum.scales, strict=True)}

    @property
    def cost_ratio(self) -> float:
        """Cost of the optimum over the cost of the config as given [-]."""
        return self.search.cost_ratio

    @property
    def limit(self) -> float:
        return self.target.probability_limit

    @property
    def verified(self) -> bool:
        """The verification's upper bound meets the limit."""
        return bool(self.verification.upper <= self.limit)

    @property
    def fixed_sources(self) -> tuple:
        """Random sources of the config that are not decision variables."""
        names = {c.source for c in self.sources}
        return tuple(t.source for t in self.config.tolerances
                     if t.distribution.is_random and t.source not in names)


def run_allocation(config, settings: AllocationSettings | None = None, *, workers: int = 1,
                   progress=None, study_progress=None, optimum_config=None,
                   notify=None) -> AllocationResult:
    """Allocate the tolerances of a study (module docstring).

    Parameters
    ----------
    config : StudyConfig
        The study; its ``[study] seed`` seeds the common sample.
    settings : AllocationSettings, optional
        Default: ``config.allocation`` (its ``[allocate]``), else the defaults; needs a
        target.
    workers : int
        Processes of each study (:func:`tolsim.study.execution.runner.run_study`).
    progress : callable, optional
        Called with every new :class:`Point` of the search.
    study_progress : callable, optional
        Called with the number of assemblies merged, during the verification run.
    optimum_config : callable, optional
        {source: scale} -> the StudyConfig the verification runs (default
        ``config.with_scales``); ``tolsim allocate`` passes the allocated config file, read
        back, so that the verification runs exactly what it writes.
    notify : callable, optional
        Called with a one-line message at each phase.

    Raises
    ------
    ValueError
        For a missing or unsupported target, a config without random sources, bad bounds,
        too few samples for the limit.
    AllocationInfeasible
        When no design within the bounds meets the target.
    """
    settings = settings or config.allocation or AllocationSettings()
    target, sources, samples, verify_samples = check_allocation(config, settings)
    seed = config.study.seed
    confidence = float(settings.confidence)
    limit = target.probability_limit
    say = notify or (lambda message: None)
    base = evaluation_config(config, target, samples, seed)
    names = [c.source for c in sources]

    def evaluate(scales):
        scaled = base.with_scales(dict(zip(names, map(float, scales), strict=True)))
        return evaluate_study(scaled, target, confidence, workers=workers)[0]

    say(f"searching on a common sample of {samples} assemblies (seed {seed}), "
        f"{len(sources)} sources")
    started = time.perf_counter()
    search = allocate_scales(evaluate, sources, limit, max_evaluations=settings.max_evaluations,
                             progress=progress)
    search_seconds = time.perf_counter() - started
    scales = {c.source: s for c, s in zip(sources, search.optimum.scales, strict=True)}
    optimum = (optimum_config or config.with_scales)(scales)
    verify_seed = verification_seed(seed)
    say(f"verifying the optimum on {verify_samples} fresh assemblies (seed {verify_seed})")
    started = time.perf_counter()
    verification, result = evaluate_study(
        evaluation_config(optimum, target, verify_samples, verify_seed), target, confidence,
        workers=workers, progress=study_progress)
    return AllocationResult(config, target, confidence, sources, search, samples, seed,
                            verify_samples, verify_seed, verification, result, optimum,
                            search_seconds, time.perf_counter() - started)
