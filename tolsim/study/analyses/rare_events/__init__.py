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


The estimators live in :mod:`~tolsim.study.analyses.rare_events.monte_carlo`,
:mod:`~tolsim.study.analyses.rare_events.subset` (theory in its docstring),
:mod:`~tolsim.study.analyses.rare_events.form` and
:mod:`~tolsim.study.analyses.rare_events.importance`; the result type, its statuses and the
treatment of unresolved rows in :mod:`~tolsim.study.analyses.rare_events.result`.

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

from tolsim.study.analyses.rare_events.common import BLOCK_ROWS, RARE_EVENT_STREAM
from tolsim.study.analyses.rare_events.form import (
    FORM_ALIGNMENT_TOLERANCE,
    FORM_DISTANCE_TOLERANCE,
    GRADIENT_STEP,
    SECOND_ORDER_TOLERANCE,
    SMOOTHNESS_TOLERANCE,
    DesignPoint,
    DesignPointSet,
    find_design_point,
    find_design_points,
)
from tolsim.study.analyses.rare_events.importance import (
    FORM_RATIO_LIMIT,
    MAX_WEIGHT_SHARE,
    MIN_EFFECTIVE_SAMPLES,
    SeriesDesignPoints,
    importance_sampling,
    series_importance_sampling,
)
from tolsim.study.analyses.rare_events.monte_carlo import monte_carlo
from tolsim.study.analyses.rare_events.result import (
    ESTIMATOR_TITLES,
    INTERVAL_CLOPPER_PEARSON,
    INTERVAL_LOGNORMAL,
    INTERVAL_NORMAL,
    INTERVAL_NORMAL_CLIPPED,
    STATUS_DIAGNOSTIC_FAILED,
    STATUS_ESTIMATORS_DISAGREE,
    STATUS_FORM_FAILED,
    STATUS_NO_FAILURE,
    STATUS_OK,
    STATUS_PLATEAU,
    STATUS_UNRESOLVED,
    STATUSES,
    RareEventError,
    RareEventResult,
)
from tolsim.study.analyses.rare_events.subset import (
    INITIAL_SCALE,
    METROPOLIS_HALF_WIDTH,
    MIN_ANCESTORS,
    MIN_CHAINS,
    SAMPLERS,
    TARGET_ACCEPTANCE,
    LevelStatistics,
    ancestral_log_variance,
    chain_correlation_factor,
    level_statistics,
    subset_simulation,
)

#: The estimators by their config name (``[study] estimator``).
ESTIMATORS = {"monte_carlo": monte_carlo, "subset": subset_simulation,
              "importance": importance_sampling}

__all__ = [
    "SECOND_ORDER_TOLERANCE",
    "DesignPointSet",
    "find_design_points",
    "STATUS_DIAGNOSTIC_FAILED",
    "STATUS_ESTIMATORS_DISAGREE",
    "STATUSES",
    "MIN_ANCESTORS",
    "ancestral_log_variance",
    "FORM_RATIO_LIMIT",
    "MAX_WEIGHT_SHARE",
    "MIN_EFFECTIVE_SAMPLES",
    "BLOCK_ROWS",
    "DesignPoint",
    "ESTIMATORS",
    "ESTIMATOR_TITLES",
    "FORM_ALIGNMENT_TOLERANCE",
    "FORM_DISTANCE_TOLERANCE",
    "GRADIENT_STEP",
    "INITIAL_SCALE",
    "INTERVAL_CLOPPER_PEARSON",
    "INTERVAL_LOGNORMAL",
    "INTERVAL_NORMAL",
    "INTERVAL_NORMAL_CLIPPED",
    "LevelStatistics",
    "METROPOLIS_HALF_WIDTH",
    "MIN_CHAINS",
    "RARE_EVENT_STREAM",
    "RareEventError",
    "RareEventResult",
    "SAMPLERS",
    "SMOOTHNESS_TOLERANCE",
    "STATUS_FORM_FAILED",
    "STATUS_NO_FAILURE",
    "STATUS_OK",
    "STATUS_PLATEAU",
    "STATUS_UNRESOLVED",
    "SeriesDesignPoints",
    "TARGET_ACCEPTANCE",
    "chain_correlation_factor",
    "find_design_point",
    "importance_sampling",
    "level_statistics",
    "monte_carlo",
    "series_importance_sampling",
    "subset_simulation",
]
