"""Targets, tolerance costs and settings of a tolerance allocation (``tolsim allocate``)."""

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from tolsim.study.pipeline.block import has_contact
from tolsim.study.spec import SOURCES
from tolsim.study.statistics.intervals import clopper_pearson_interval, cluster_proportion

# --------------------------------------------------------------------------------------------
# Defaults (tolsim.study.design.allocate.search.allocate_scales, Notes)
# --------------------------------------------------------------------------------------------
#: Bounds of a source's scale factor when ``[allocate.sources]`` does not list any source [-].
DEFAULT_MIN_SCALE = 0.25
DEFAULT_MAX_SCALE = 4.0
#: Reciprocal square cost, C = A + B / T^2 ([Spotts1973]).
DEFAULT_COST_EXPONENT = 2.0
#: Largest change of a source's cost w s^-k between s = 1 and an end of its scale range, as a
#: power of e: k max(|ln min_scale|, |ln max_scale|) <= 300 (a factor 2e130). Cost models
#: stay far below (k = 2 on [0.25, 4]: e^2.8 = 16); beyond, the costs and the search's sums
#: leave double precision (k = 1e300 overflowed, and the ray search stopped with brentq's
#: "failed to converge").
MAX_COST_SPAN = 300.0
DEFAULT_COST_WEIGHT = 1.0
#: One-sided confidence of the upper bound that must meet the limit [-].
DEFAULT_CONFIDENCE = 0.95
#: Evaluations (studies on the common sample) at most.
DEFAULT_MAX_EVALUATIONS = 120
#: Verification assemblies per optimisation assembly (default ``verify_samples``).
VERIFY_SAMPLES_FACTOR = 4
#: Spawn key of the verification seed under the study's seed (``run_allocation``, Notes).
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


def round_scale(value: float) -> float:
    """``value`` to :data:`SCALE_DIGITS` significant digits (the grid of evaluated scales)."""
    return float(f"{float(value):.{SCALE_DIGITS}g}")


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


#: The variables a target can bound (``allocate_scales``, Notes), by their result-file names.
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
        k > 0 of the cost w s^-k (``allocate_scales``, Notes).
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
        high = DEFAULT_MAX_SCALE if self.max_scale is None else self.max_scale
        limit = cost_exponent_limit(self.min_scale, high)
        if self.cost_exponent > limit:
            raise ValueError(f"{self.source} cost_exponent = {self.cost_exponent!r} is beyond "
                             f"{limit:.4g}, the most its scale range [{self.min_scale:g}, "
                             f"{high:g}] allows ({MAX_COST_SPAN:g} / the larger |ln scale|)")


def cost_exponent_limit(min_scale: float, max_scale: float) -> float:
    """The largest cost exponent k for scales in [min_scale, max_scale]:
    :data:`MAX_COST_SPAN` / max(|ln min_scale|, |ln max_scale|)."""
    return MAX_COST_SPAN / max(abs(math.log(min_scale)), abs(math.log(max_scale)))


def tolerance_cost(scales, sources) -> float:
    """C(s) = sum_i w_i s_i^-k_i [-], the tolerance-dependent cost
    (:func:`~tolsim.study.design.allocate.search.allocate_scales`, Notes)."""
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
    """The settings of ``tolsim allocate`` (``[allocate]``, :mod:`tolsim.io.config.allocation`).

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


