"""Rare-event probabilities of your own limit state: ``estimate(g, dimension, method=, seed=)``.

``g`` takes an (n, d) array of independent standard-normal points and returns the (n,)
limit-state values, failure where g <= 0. Which method to use when, and what each diagnostic
means: README.md (``## Rare events``) and :func:`estimate`. The estimators themselves live
in :mod:`tolsim.study.analyses.rare_events`.
"""

from tolsim.study.analyses.rare_events import (
    STATUSES,
    DesignPoint,
    DesignPointSet,
    RareEventError,
    RareEventResult,
    find_design_point,
    find_design_points,
    importance_sampling,
    monte_carlo,
    subset_simulation,
)
from tolsim.study.analyses.rare_events.api import METHODS, estimate

__all__ = ["METHODS", "STATUSES", "DesignPoint", "DesignPointSet", "RareEventError",
           "RareEventResult", "estimate", "find_design_point", "find_design_points",
           "importance_sampling", "monte_carlo", "subset_simulation"]
