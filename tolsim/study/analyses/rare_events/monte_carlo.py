"""Plain Monte Carlo estimate of a failure probability with the Clopper-Pearson interval
(:mod:`tolsim.study.analyses.rare_events`).

References
----------
.. [ClopperPearson1934] C. J. Clopper, E. S. Pearson, Biometrika 26 (1934) 404-413 (see
   :func:`tolsim.study.statistics.intervals.clopper_pearson_interval`).
"""

import math

import numpy as np

from tolsim.study.analyses.rare_events.common import (
    check_batch_size,
    check_confidence,
    check_count,
    check_dimension,
    cv_of,
    evaluate,
    normal_blocks,
    seed_sequence,
)
from tolsim.study.analyses.rare_events.result import (
    INTERVAL_CLOPPER_PEARSON,
    STATUS_UNRESOLVED,
    RareEventResult,
    flagged,
)
from tolsim.study.statistics.intervals import clopper_pearson_interval


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
    d = check_dimension(dimension)
    n = check_count("samples", samples, 1)
    check_batch_size(batch_size)
    check_confidence(confidence_level)
    root = seed_sequence(seed)
    failures = unresolved = 0
    for u in normal_blocks(root, (0,), n, d):
        g = evaluate(limit_state, u, batch_size)
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
        return flagged(STATUS_UNRESOLVED, f"all {n} samples unresolved (g is NaN): P is only "
                                           "known to lie in [0, 1]", n, unresolved, common,
                        **{k: v for k, v in bounds.items() if k != "unresolved"})
    p = failures / resolved
    se = math.sqrt(p * (1 - p) / resolved)
    lower, upper = clopper_pearson_interval(failures, resolved, confidence_level)
    return RareEventResult(probability=p, standard_error=se,
                           coefficient_of_variation=cv_of(p, se), ci_lower=lower,
                           ci_upper=upper, interval=INTERVAL_CLOPPER_PEARSON, evaluations=n,
                           **bounds, **common)
