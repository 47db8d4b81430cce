"""FORM on every component of a series limit state (:mod:`tolsim.study.analyses.rare_events`):
one design point per component.

A study's series event (any pair of a train touches, any ball beyond its limit) has a smooth
component per pair or ball, all computed by one evaluation of an assembly
(:meth:`tolsim.study.analyses.limit_state.LimitState.components`).
:func:`component_design_points` searches the design point of each component with
:func:`~tolsim.study.analyses.rare_events.form.find_design_point` (SLSQP and every check of its
module docstring: on the limit state, normal to it, smooth there, a minimum of |u| along it).
Two savings leave the checks as they are:

* the rows at the origin ([0, h e_k, -h e_k], 2 d + 1), the same for every component, are
  evaluated once for all (``origin_values``);
* SLSQP stops at a tolerance of 1e-4 on |u|^2 / 2 (``ftol``; :func:`find_design_point`'s
  default 1e-9), about 1e-5 in beta: the checks (distance to g = 0 and 1 - cos each at most
  1e-3) still decide whether the end point is a design point.

On ``configs/rare_contact.toml`` (nine pairs, d = 52) the searches cost 5 793 rows instead of
8 541 (7 701 with the shared origin alone), the betas change by at most 3e-6.

Tried and rejected (same config): forward differences in the search (d rows per gradient
instead of 2 d) made SLSQP take up to 120 steps on the end pairs (22 187 rows in all); the
improved HLRF iteration ([ZhangDerKiureghian1995], an Armijo step on the merit function
|u|^2 / 2 + c |g|) needed 11 gradient steps per pair against SLSQP's 7 (11 508 rows), plain
HLRF oscillating between beta 2.79 and 3.15 (the pairs' margins are strongly curved in u:
the uniform initial gap enters through Phi).

References
----------
.. [ZhangDerKiureghian1995] Y. Zhang, A. Der Kiureghian, "Two improved algorithms for
   reliability analysis", in: Reliability and Optimization of Structural Systems (Proc.
   IFIP WG 7.5), 1995 (the iHLRF algorithm; editors and pages not checked here).
"""

import numpy as np

from tolsim.study.analyses.rare_events.common import check_batch_size, check_count
from tolsim.study.analyses.rare_events.form import GRADIENT_STEP, find_design_point

#: SLSQP's tolerance on |u|^2 / 2 in the searches (module docstring).
SERIES_FTOL = 1e-4


def component_design_points(components, dimension, count, *, step=GRADIENT_STEP,
                            max_iterations=100, batch_size=None, second_order=True):
    """The design point of each of ``count`` components of a series limit state.

    Parameters
    ----------
    components : callable
        u of shape (rows, d) -> (rows, count): the components' g; the event fails where any
        is <= 0.
    dimension : int
        d.
    count : int
        k, the components.
    step, max_iterations, batch_size, second_order
        As :func:`~tolsim.study.analyses.rare_events.form.find_design_point`.

    Returns
    -------
    (tuple of DesignPoint, rows evaluated, NaN rows)
        One DesignPoint per component, in order (``converged`` False with a one-line
        ``message`` where the search or a check failed); each point's ``evaluations`` are the
        rows of its own search, the second item all rows evaluated (the origin's 2 d + 1
        once).
    """
    d = int(dimension)
    k = check_count("count", count, 1)
    check_batch_size(batch_size)
    eye = step * np.eye(d)
    origin = evaluate_components(components, np.concatenate([np.zeros((1, d)), eye, -eye]),
                                 k, batch_size)
    rows = origin.shape[0]
    nans = int(np.count_nonzero(np.isnan(origin).any(axis=1)))
    out = []
    for j in range(k):
        point = find_design_point(lambda u, j=j: evaluate_components(components, u, k,
                                                                      batch_size)[:, j],
                                  d, step=step, max_iterations=max_iterations,
                                  batch_size=None, second_order=second_order,
                                  origin_values=origin[:, j], ftol=SERIES_FTOL)
        rows += point.evaluations
        nans += point.unresolved
        out.append(point)
    return tuple(out), rows, nans


def evaluate_components(components, rows, count, batch_size):
    """``components`` on ``rows`` in batches of at most ``batch_size`` rows -> (m, count)."""
    if rows.shape[0] == 0:
        return np.empty((0, count))
    size = rows.shape[0] if batch_size is None else batch_size
    out = np.concatenate([np.asarray(components(rows[i:i + size]), dtype=float)
                          for i in range(0, rows.shape[0], size)])
    if out.shape != (rows.shape[0], count):
        raise ValueError(f"the components returned shape {out.shape} for {rows.shape[0]} "
                         f"rows; expected ({rows.shape[0]}, {count})")
    return out
