"""FORM: the design point (most probable failure point) of a limit state in standard-normal
space (:mod:`tolsim.study.analyses.rare_events`).

FORM
----
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

References
----------
.. [HasoferLind1974] A. M. Hasofer, N. C. Lind, "Exact and invariant second-moment code
   format", J. Eng. Mech. Div. ASCE 100 (1974) 111-121.
.. [RackwitzFiessler1978] R. Rackwitz, B. Fiessler, "Structural reliability under combined
   random load sequences", Computers & Structures 9 (1978) 489-494,
   doi:10.1016/0045-7949(78)90046-9.
.. [Kraft1988] D. Kraft, "A software package for sequential quadratic programming",
   DFVLR-FB 88-28, 1988.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.special import ndtr

from tolsim.study.analyses.rare_events.common import (
    check_batch_size,
    check_count,
    check_dimension,
    evaluate,
)

#: Design-point acceptance (module docstring): distance to g = 0 in u, 1 - cos of the angle
#: between u* and -grad g, relative disagreement of the one-sided difference quotients.
FORM_DISTANCE_TOLERANCE = 1e-3
FORM_ALIGNMENT_TOLERANCE = 1e-3
SMOOTHNESS_TOLERANCE = 0.05
#: Default finite-difference step of the design-point search, in standard-normal units.
GRADIENT_STEP = 1e-4


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
    d = check_dimension(dimension)
    if not (np.isfinite(step) and step > 0):
        raise ValueError(f"step = {step!r} must be > 0")
    max_iterations = check_count("max_iterations", max_iterations, 1)
    check_batch_size(batch_size)
    calls = [0]

    def values(rows):
        calls[0] += rows.shape[0]
        return evaluate(limit_state, rows, batch_size)

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

