"""A tolerance allocation on a study: evaluations on common random numbers, the search, and
the verification on a fresh sample (:func:`run_allocation`)."""

import math
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from tolsim.study.design.allocate.search import AllocationSearch, allocate_scales
from tolsim.study.design.allocate.targets import (
    TARGETS,
    VERIFY_SAMPLES_FACTOR,
    VERIFY_SPAWN_KEY,
    AllocationSettings,
    Evaluation,
    Target,
    resolve_sources,
)
from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.block import has_contact


# --------------------------------------------------------------------------------------------
# On a study
# --------------------------------------------------------------------------------------------
def verification_seed(seed: int) -> int:
    """The study seed of the verification run: the first 32-bit word of
    ``SeedSequence(seed, spawn_key=(VERIFY_SPAWN_KEY,))`` (:func:`run_allocation`, Notes)."""
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


class AllocationWarning(UserWarning):
    """An allocation that may not be able to show its target (the command line prints it
    as one line)."""


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
        too few samples (or verify_samples) to show a probability limit at the confidence.

    Warns
    -----
    AllocationWarning
        A fraction-of-balls target (a quantile, out of spec) with fewer assemblies than
        always suffice: it may not be shown (the balls of an assembly share its errors).
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
    verify_samples = settings.verify_samples or VERIFY_SAMPLES_FACTOR * samples
    need = minimum_samples(limit, confidence)
    per_assembly = target.variable in ("contact_probability", "friction_exceedance_probability")
    for key, n in (("samples", samples), ("verify_samples", verify_samples)):
        if per_assembly and n < need:
            raise ValueError(f"{key} = {n} cannot show P <= {limit:g} at {confidence:g} "
                             f"confidence even with no event (the upper bound is then "
                             f"1 - (1 - c)^(1/N)); use at least {need}, better 10 times that")
        if not per_assembly and n < need:
            # a fraction of balls: the balls of an assembly count as fewer than their number
            # (they share its errors), as one where they are fully correlated
            warnings.warn(
                f"{key} = {n} assemblies may not show {target} at {confidence:g} confidence: "
                f"were an assembly's balls as correlated as one, the upper bound could not "
                f"fall below {1 - (1 - confidence) ** (1 / n):.3g} > {limit:g} even with no "
                f"ball beyond; {need} assemblies would always do", AllocationWarning,
                stacklevel=2)
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
    """Allocate the tolerances of a study.

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

    Notes
    -----
    **Verification.**
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
    it on a study. No file, TOML or plotting here (:mod:`tolsim.io.config.allocation` reads
    ``[allocate]`` and writes the allocated config, :mod:`tolsim.reports.allocate` the report).

    References
    ----------
    .. [Luedtke2008] J. Luedtke, S. Ahmed, "A sample approximation approach for optimization with
       probabilistic constraints", SIAM Journal on Optimization 19(2) (2008) 674-699,
       doi:10.1137/070702928.
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
