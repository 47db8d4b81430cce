"""FORM on every component of a series limit state (:mod:`tolsim.study.analyses.rare_events`):
one design point per component.

A study's series event (any pair of a train touches, any ball beyond its limit) has a smooth
component per pair or ball, all computed by one evaluation of an assembly
(:meth:`tolsim.study.analyses.limit_state.LimitState.components`).
:func:`component_design_points` searches the design point of each component with
:func:`~tolsim.study.analyses.rare_events.form.find_design_point` (SLSQP and every check of its
module docstring: on the limit state, normal to it, smooth there, a minimum of |u| along it).
Four savings leave the checks as they are:

* the rows at the origin ([0, h e_k, -h e_k], 2 d + 1), the same for every component, are
  evaluated once for all (``origin_values``);
* SLSQP stops at a tolerance of 1e-4 on |u|^2 / 2 (``ftol``; :func:`find_design_point`'s
  default 1e-9), about 1e-5 in beta: the checks (distance to g = 0 and 1 - cos each at most
  1e-3) still decide whether the end point is a design point;
* each component depends on some of the d columns only (a pair of a train on the carriage's
  errors, its two balls, the gaps and rail-field innovations up to it: 12 to 44 of 52 on
  ``configs/rare_contact.toml``): its difference rows are taken along those (``columns`` of
  :func:`find_design_point`), found where the one-sided differences of the shared rows at the
  origin or at :func:`probe` (d + 1 rows, shared; at the origin the rail fields are 0 and the
  balls' positions do not show) change g. At the end point the structure is verified (2 rows,
  :func:`~tolsim.study.analyses.rare_events.form.verified_stencil`); where it does not hold
  there, the other rows are evaluated and every check runs on the full stencil;
* iterates farther than :data:`COARSE_DISTANCE` from the component's g = 0 take forward
  differences (half the rows); nearer ones, and the end point's checks, central ones.

On ``configs/rare_contact.toml`` (nine pairs, d = 52) the searches cost 2 471 rows instead of
5 793 with the first two savings alone (8 541 with none), the design points moving by at most
3e-6 (betas by 1e-7): subset simulation with its lost-mode check costs 5 271 evaluations
against 2 800 unchecked (8 593 before the last two savings), importance sampling 4 471 (was
7 793), ``rare`` 6 321 (was 9 643).

Tried and rejected (same config): forward differences throughout the search (d rows per
gradient instead of 2 d) made SLSQP take up to 120 steps on the end pairs (22 187 rows in all); the
improved HLRF iteration ([ZhangDerKiureghian1995], an Armijo step on the merit function
|u|^2 / 2 + c |g|) needed 11 gradient steps per pair against SLSQP's 7 (11 508 rows), plain
HLRF oscillating between beta 2.79 and 3.15 (the pairs' margins are strongly curved in u:
the uniform initial gap enters through Phi). Ending a search at the first iterate that
passes the distance and alignment checks saved nothing: SLSQP's last iterate but one lies
2.2e-3 to 3e-3 from g = 0 (tolerance 1e-3), its last one 2e-6 to 5e-6.

References
----------
.. [ZhangDerKiureghian1995] Y. Zhang, A. Der Kiureghian, "Two improved algorithms for
   reliability analysis", in: Reliability and Optimization of Structural Systems (Proc.
   IFIP WG 7.5), 1995 (the iHLRF algorithm; editors and pages not checked here).
"""

import numpy as np

from tolsim.study.analyses.rare_events.common import check_batch_size, check_count
from tolsim.study.analyses.rare_events.form import GRADIENT_STEP, HESSIAN_STEP, find_design_point

#: SLSQP's tolerance on |u|^2 / 2 in the searches (module docstring).
SERIES_FTOL = 1e-4
#: Forward differences at iterates farther than this from the component's g = 0, in u
#: (module docstring).
COARSE_DISTANCE = 0.02


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
        and the probe's d + 1 once).
    """
    d = int(dimension)
    k = check_count("count", count, 1)
    check_batch_size(batch_size)
    eye = step * np.eye(d)
    origin = evaluate_components(components, np.concatenate([np.zeros((1, d)), eye, -eye]),
                                 k, batch_size)
    probe_point = probe(d)
    probe_values = evaluate_components(
        components, np.concatenate([probe_point[None], probe_point + HESSIAN_STEP * np.eye(d)]),
        k, batch_size)
    rows = origin.shape[0] + probe_values.shape[0]
    nans = int(np.count_nonzero(np.isnan(origin).any(axis=1))) \
        + int(np.count_nonzero(np.isnan(probe_values).any(axis=1)))
    depends = (origin[1:d + 1] != origin[0]) | (origin[d + 1:] != origin[0]) \
        | (probe_values[1:] != probe_values[0])
    out = []
    for j in range(k):
        columns = np.flatnonzero(depends[:, j])
        point = find_design_point(lambda u, j=j: evaluate_components(components, u, k,
                                                                      batch_size)[:, j],
                                  d, step=step, max_iterations=max_iterations,
                                  batch_size=None, second_order=second_order,
                                  origin_values=origin[:, j], ftol=SERIES_FTOL,
                                  columns=columns if columns.size else None,
                                  coarse_distance=COARSE_DISTANCE)
        rows += point.evaluations
        nans += point.unresolved
        out.append(point)
    return tuple(out), rows, nans


def probe(dimension) -> np.ndarray:
    """The point where the columns each component depends on are probed (module docstring):
    entries of size 0.2 to 0.7 with alternating signs, none zero or repeated (a point where
    every column's effect shows; at the origin some are hidden, e.g. the positions of the balls
    when the rail fields are 0)."""
    k = np.arange(dimension)
    return np.where(k % 2 == 0, 1.0, -1.0) * (0.2 + 0.5 * ((k * 0.6180339887498949) % 1.0))


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
