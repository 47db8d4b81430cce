"""The generic least-cost search of a tolerance allocation: common-factor sweep, trust-region
probit surrogate, ray search (:func:`allocate_scales`)."""

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq
from scipy.special import ndtri

from tolsim.study.design.allocate.targets import (
    BRACKET_STEPS,
    DEFAULT_MAX_EVALUATIONS,
    MIN_RADIUS,
    PROBIT_CLIP,
    RAY_RESOLUTION,
    START_RADIUS,
    SWEEP_POINTS,
    TRADE_OFF_FACTORS,
    AllocationInfeasible,
    Evaluation,
    round_scale,
    tolerance_cost,
)


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
    """Step 3 of :func:`allocate_scales` (Notes); returns (last design, sentence)."""
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
    """The least-cost scale factors whose upper bound meets ``limit``.

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

    Notes
    -----
    **The problem.**
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
      sampling units (Korn-Graubard,
      :func:`tolsim.study.statistics.intervals.cluster_proportion`) with the unresolved balls
      counted as out of spec;
    * ``velocity_deviation_abs_quantile(q) <= L``: the q-quantile of |epsilon| at most L, which
      is the same statement as "the fraction of balls with |epsilon| > L is at most 1 - q", and
      is evaluated so (the upper bound of that fraction against 1 - q).

    **Method.**
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


