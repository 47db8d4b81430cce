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
* it is a local *minimum* of |u| on g = 0 (second-order check, ``second_order=True``): the
  Hessian of the Lagrangian L = |u|^2 / 2 + lambda g, lambda = beta / |grad g(u*)|, projected
  on the tangent space of g = 0, A = I + lambda T' H_g T (T an orthonormal basis of the
  tangent space), is positive definite: its smallest eigenvalue is >= 0.05. A saddle or a
  maximum of |u| along g = 0 (e.g. (0, 8) on g = 8 - u_1^2 - u_2, where |u| decreases along
  the parabola) is rejected. H_g is taken by central second differences of step 0.01 along
  the tangent directions (2 (d - 1) rows for the diagonal, 4 per pair for the off-diagonal
  entries) when d - 1 <= :data:`FULL_HESSIAN_DIMENSION`; in higher dimension only the
  diagonal, in the tangent directions closest to the coordinate axes (a necessary
  condition: a saddle whose negative direction is oblique to every axis can pass). The
  eigenvalues 1 - beta kappa_i give the main curvatures kappa_i and Breitung's SORM estimate
  Phi(-beta) / sqrt(det A) ([Breitung1984]).

and is flagged otherwise (``converged`` False, ``message`` one line). beta = |u*|, the FORM
estimate Phi(-beta), and the importance factors alpha_k^2, alpha = u* / beta (the shares of
the tolerances in "the most likely way to fail"; the caller maps u* to physical units).

Where g depends on some columns only (a component of a series event,
:mod:`~tolsim.study.analyses.rare_events.series_form`), ``columns=`` takes the difference rows
along those and verifies the structure at the end point (:func:`verified_stencil`), so the
checks are those above.

One search finds one local design point: the one whose basin holds the start. A limit state
with several (a series system, a parabola bent towards the origin, |u_1| >= b) has more, and
the one found from the origin need not be the global one. :func:`find_design_points`
restarts the search from seeded points and keeps every distinct design point accepted
(:class:`DesignPointSet`); importance sampling then samples around all of them.

References
----------
.. [HasoferLind1974] A. M. Hasofer, N. C. Lind, "Exact and invariant second-moment code
   format", J. Eng. Mech. Div. ASCE 100 (1974) 111-121.
.. [RackwitzFiessler1978] R. Rackwitz, B. Fiessler, "Structural reliability under combined
   random load sequences", Computers & Structures 9 (1978) 489-494,
   doi:10.1016/0045-7949(78)90046-9.
.. [Kraft1988] D. Kraft, "A software package for sequential quadratic programming",
   DFVLR-FB 88-28, 1988.
.. [Breitung1984] K. Breitung, "Asymptotic approximations for multinormal integrals",
   J. Eng. Mech. 110 (1984) 357-366, doi:10.1061/(ASCE)0733-9399(1984)110:3(357).
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.special import ndtr

from tolsim.study.analyses.rare_events.common import (
    check_batch_size,
    check_count,
    check_dimension,
    child_sequence,
    evaluate,
    seed_sequence,
)

#: Design-point acceptance (module docstring): distance to g = 0 in u, 1 - cos of the angle
#: between u* and -grad g, relative disagreement of the one-sided difference quotients.
FORM_DISTANCE_TOLERANCE = 1e-3
FORM_ALIGNMENT_TOLERANCE = 1e-3
SMOOTHNESS_TOLERANCE = 0.05
#: SLSQP's default tolerance on |u|^2 / 2 in :func:`find_design_point`.
SLSQP_FTOL = 1e-9
#: Default finite-difference step of the design-point search, in standard-normal units.
GRADIENT_STEP = 1e-4
#: Second-order check: smallest eigenvalue of the projected Hessian of the Lagrangian accepted
#: (1 for a plane; 0 where |u| is constant along g = 0 to second order, e.g. a sphere about
#: the origin, where no design point is isolated), and the step of its second differences.
SECOND_ORDER_TOLERANCE = 0.05
HESSIAN_STEP = 1e-2
#: Largest change of g along the columns a search left out, as a share of HESSIAN_STEP |grad g|
#: (:func:`verified_stencil`).
STRUCTURE_TOLERANCE = 1e-6
#: Largest tangent dimension d - 1 with the full projected Hessian (above it, its diagonal).
FULL_HESSIAN_DIMENSION = 12
#: Searches of :func:`find_design_points` besides the one from the origin; after them it
#: goes on while one of the last RESTART_PATIENCE searches found a new point, up to
#: MAX_RESTART_FACTOR times as many.
DEFAULT_RESTARTS = 8
RESTART_PATIENCE = 4
MAX_RESTART_FACTOR = 3
#: Two accepted design points are the same when their directions differ by less than this
#: (1 - cos) and their betas by less than this share.
DISTINCT_DIRECTION = 1e-3
DISTINCT_BETA = 1e-2
#: Points of the line search along each restart direction.
RAY_POINTS = 16
#: The scan of :func:`find_design_points`: rays, points along each, neighbours compared.
SCAN_DIRECTIONS = 32
SCAN_POINTS = 16
SCAN_NEIGHBOURS = 4
#: Stream key (under RARE_EVENT_STREAM) of the restart points ('form' in ASCII).
RESTART_STREAM = 0x666F726D


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
    curvature_eigenvalues : ndarray or None
        Eigenvalues 1 - beta kappa_i of the projected Hessian of the Lagrangian (ascending;
        in high dimension its diagonal entries); None when not checked.
    sorm_probability : float
        Breitung's Phi(-beta) / sqrt(prod(eigenvalues)) [-] (NaN when not computed or when
        only the diagonal was taken).
    unresolved : int
        Of the evaluated rows, those where g was NaN.
    """

    point: np.ndarray
    beta: float
    form_probability: float
    gradient: np.ndarray
    converged: bool
    message: str
    evaluations: int
    curvature_eigenvalues: np.ndarray | None = None
    sorm_probability: float = float("nan")
    unresolved: int = 0

    @property
    def importance_factors(self) -> np.ndarray:
        """alpha_k^2 with alpha = u* / beta [-]; they sum to 1."""
        if not self.beta > 0:
            return np.full_like(self.point, np.nan)
        return (self.point / self.beta) ** 2



class _Unevaluable(Exception):
    """g (or its gradient) is NaN at a point of the design-point search."""


def find_design_point(limit_state, dimension, *, gradient=None, step=GRADIENT_STEP,
                      max_iterations=100, batch_size=None, start=None,
                      second_order=True, origin_values=None,
                      ftol=SLSQP_FTOL, known=(), columns=None,
                      coarse_distance=None) -> DesignPoint:
    """The most probable failure point u* by SLSQP, with the checks of the module docstring.

    Minimises |u|^2 / 2 subject to g(u) = 0 ([HasoferLind1974]) with
    :func:`scipy.optimize.minimize` (method ``"SLSQP"``, [Kraft1988]) from u = 0 (or
    ``start``).

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
    start : array_like (d,), optional
        First iterate (default the origin); the origin is checked (g(0) > 0) either way.
    second_order : bool
        Reject a point that is not a local minimum of |u| on g = 0 (module docstring).
    origin_values : array_like (2 d + 1,), optional
        g at [0, h e_k, -h e_k] when already evaluated (e.g. once for every component of a
        series event); not evaluated nor counted again.
    ftol : float
        SLSQP's tolerance on |u|^2 / 2 (``ftol``); the checks decide whether the end point is
        a design point whatever it is.
    known : sequence of DesignPoint
        Accepted design points found before (:func:`find_design_points`): a search that ends
        at one of them (the same direction and beta, as :func:`find_design_points` tells
        them apart) stops there, flagged ``converged`` False with the message "already
        found", without the checks' rows (the point passed them before).
    columns : array_like of int, optional
        The columns g depends on (a sparse structure, e.g. one pair of a series event,
        :mod:`~tolsim.study.analyses.rare_events.series_form`): the difference rows are taken
        along these alone (2 m rows per gradient, the centre reused from the constraint's
        row), the others' derivatives taken as 0. At the end point the structure is verified
        (:func:`verified_stencil`: g unchanged, bit for bit, by a step of
        :data:`HESSIAN_STEP` along every other column, 2 rows); where it is not, the missing
        rows are evaluated and every check runs on the full stencil. Default: every column.
    coarse_distance : float, optional
        With ``columns``: at an iterate farther than this from g = 0 (|g| / |grad g| with the
        last gradient, in u) the gradient is taken by forward differences (m rows, the
        centre reused), central ones nearer; the checks at the end point always use the
        central rows. Default: central differences throughout.

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
    calls = [0, 0]

    def values(rows):
        calls[0] += rows.shape[0]
        out = evaluate(limit_state, rows, batch_size)
        calls[1] += int(np.count_nonzero(np.isnan(out)))
        return out

    def value_and_gradient(u):
        """g(u) and its gradient: the caller's, or central differences (one batch
        [u, u + h e_k, u - h e_k], k over ``columns``)."""
        if gradient is not None:
            return values(u[None]), _user_gradient(gradient, u)
        g = last.get(u.tobytes())
        if g is None and columns is not None and coarse_distance is not None:
            centre = cache.get(u.tobytes())
            if centre is None:
                centre = values(u[None])[0]
            if abs(centre) > coarse_distance * norm[0]:
                basis = step * np.eye(d)[columns]
                forward = np.zeros(d)
                forward[columns] = (values(u + basis) - centre) / step
                norm[0] = float(np.linalg.norm(forward))
                return np.array([centre]), forward
            g = _sparse_stencil(values, u, step, columns, centre)
        elif g is None and columns is not None:
            g = _sparse_stencil(values, u, step, columns, cache.get(u.tobytes()))
        elif g is None:
            g = values(np.concatenate([u[None], u + step * np.eye(d), u - step * np.eye(d)]))
        last.clear()
        last[u.tobytes()] = g
        grad = (g[1:d + 1] - g[d + 1:]) / (2 * step)
        norm[0] = float(np.linalg.norm(grad))
        return g, grad

    # the rows [u, u + h e_k, u - h e_k] of the last gradient, not evaluated twice: SLSQP's
    # first gradient is at the start (the origin, already evaluated) and its last one at its
    # result, where the checks below need the same rows
    last = {}
    cache = {}            # g at the last point of the constraint (one row)
    norm = [np.inf]       # |grad g| at the last gradient (coarse_distance)
    if columns is not None:
        columns = np.unique(np.asarray(columns, dtype=np.intp))
        if columns.ndim != 1 or columns.size == 0 or columns[0] < 0 or columns[-1] >= d:
            raise ValueError(f"columns must be column indices in [0, {d})")

    def fail(u, g_grad, why):
        beta = float(np.linalg.norm(u))
        return DesignPoint(u, beta, float(ndtr(-beta)), g_grad, False, why, calls[0],
                           unresolved=calls[1])

    origin = np.zeros(d)
    if origin_values is not None:
        origin_values = np.asarray(origin_values, dtype=float)
        if origin_values.shape != (2 * d + 1,):
            raise ValueError(f"origin_values of shape {origin_values.shape}; expected "
                             f"({2 * d + 1},)")
        last[origin.tobytes()] = origin_values
    g_rows, grad0 = value_and_gradient(origin)
    g0 = g_rows[0]
    if not np.isfinite(g0):
        return fail(origin, grad0, f"the limit state is {g0} at the origin (nominal design)")
    if g0 <= 0:
        return fail(origin, grad0, f"the origin (nominal design) fails, g(0) = {g0:.3g} <= 0: "
                                   "not a rare event; use Monte Carlo")
    scale = float(np.linalg.norm(grad0))
    if start is not None and not scale > 0:       # e.g. |u_1| >= b: flat at the origin only
        scale = float(np.linalg.norm(value_and_gradient(
            np.asarray(start, dtype=float).reshape(d))[1]))
    if not (np.isfinite(scale) and scale > 0):
        return fail(origin, grad0, "the gradient of the limit state vanishes at the origin: "
                                   "FORM can not start (several or no design points)")

    def constraint(u):
        key = u.tobytes()
        if key not in cache:
            g = last[key][0] if key in last else values(u[None])[0]
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

    first = origin if start is None else np.asarray(start, dtype=float).reshape(d)
    try:
        result = minimize(lambda u: 0.5 * float(u @ u), first, jac=lambda u: u,
                          method="SLSQP",
                          constraints=[{"type": "eq", "fun": constraint,
                                        "jac": constraint_gradient}],
                          options={"maxiter": max_iterations, "ftol": ftol})
    except _Unevaluable as error:
        return fail(origin, grad0, f"FORM search stopped: {error}")
    point = np.asarray(result.x, dtype=float)
    beta = float(np.linalg.norm(point))
    if beta > 0 and any(_near(point, beta, p.point, p.beta) for p in known):
        return fail(point, np.full(d, np.nan), "the search ended at a design point already "
                                               "found")
    g = last.get(point.tobytes())
    if g is None and columns is None:
        g = values(np.concatenate([point[None], point + step * np.eye(d),
                                   point - step * np.eye(d)]))
    elif columns is not None:
        g, columns = verified_stencil(values, point, step, columns, g)
    central_user = None if gradient is None else _user_gradient(gradient, point)
    solver = "" if result.success else f" (SLSQP: {result.message})"
    return checked_design_point(values, point, g, step, second_order, calls,
                                central_user=central_user, solver=solver, columns=columns)


def checked_design_point(values, point, g, step, second_order, calls, *, central_user=None,
                         solver="", columns=None) -> DesignPoint:
    """The end point of a design-point search with the checks of the module docstring.

    Parameters
    ----------
    values : callable
        g on rows (m, d) -> (m,), counting its rows in ``calls`` (used for the second-order
        check only).
    point : ndarray (d,)
        u*, the end of the search.
    g : ndarray (2 d + 1,)
        g at [u*, u* + h e_k, u* - h e_k] (h = ``step``).
    step : float
    second_order : bool
    calls : list [rows evaluated, NaN rows]
        Updated by ``values``; the counts of the result.
    central_user : ndarray (d,), optional
        The caller's gradient at u* (default the central differences of ``g``).
    solver : str
        Appended to the messages of a point not on the limit state or not normal to it.
    columns : ndarray of int, optional
        The only columns g depends on around u* (verified, :func:`verified_stencil`): the
        second differences along the other axes are 0 and not evaluated.

    Returns
    -------
    DesignPoint
    """
    d = point.size

    def fail(u, g_grad, why):
        beta = float(np.linalg.norm(u))
        return DesignPoint(u, beta, float(ndtr(-beta)), g_grad, False, why, calls[0],
                           unresolved=calls[1])

    g_star = float(g[0])
    forward = (g[1:d + 1] - g_star) / step
    backward = (g_star - g[d + 1:]) / step
    central = 0.5 * (forward + backward)
    if central_user is None:
        central_user = central
    beta = float(np.linalg.norm(point))
    norm = float(np.linalg.norm(central_user))
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
    eigenvalues, sorm = None, float("nan")
    if second_order and d > 1:
        eigenvalues, full = _projected_hessian(values, point, g_star, central_user, beta / norm,
                                               columns)
        smallest = float(eigenvalues[0])
        if not smallest >= SECOND_ORDER_TOLERANCE:
            kind = "a maximum" if eigenvalues[-1] < SECOND_ORDER_TOLERANCE else "a saddle"
            if np.isfinite(smallest) and smallest > 0:
                kind = "almost flat (no isolated minimum)"
            elif not np.isfinite(smallest):
                kind = "not finite around it"
            return fail(point, central_user, f"the point found (beta {beta:.4g}) is not a "
                                             f"minimum of |u| on g = 0: it is {kind} along "
                                             f"the limit state (smallest eigenvalue of the "
                                             f"projected Hessian {smallest:.3g} < "
                                             f"{SECOND_ORDER_TOLERANCE:g})")
        if full:
            sorm = float(ndtr(-beta) / np.sqrt(np.prod(eigenvalues)))
    return DesignPoint(point, beta, float(ndtr(-beta)), central_user, True, "", calls[0],
                       eigenvalues, sorm, calls[1])


def _sparse_stencil(values, u, step, columns, centre=None):
    """g at [u, u + h e_k, u - h e_k] (2 d + 1) with the rows of k in ``columns`` evaluated
    (and the centre, unless given) and g(u) in the others' places."""
    d = u.size
    basis = step * np.eye(d)[columns]
    rows = np.concatenate([u + basis, u - basis])
    if centre is None:
        g = values(np.concatenate([u[None], rows]))
        centre, g = g[0], g[1:]
    else:
        g = values(rows)
    out = np.full(2 * d + 1, centre, dtype=float)
    out[1 + columns] = g[:columns.size]
    out[1 + d + columns] = g[columns.size:]
    return out


def verified_stencil(values, point, step, columns, g=None):
    """The stencil at the end point of a search along ``columns`` alone, verified.

    g at u* -+ :data:`HESSIAN_STEP` v, v = sum of +-e_k over the other columns (alternating
    signs), must differ from g(u*) by at most :data:`STRUCTURE_TOLERANCE` times
    HESSIAN_STEP |grad g(u*)| (a change in the last bits, e.g. through a sum over all balls'
    positions, passes): then the derivatives along them are below that share of the gradient
    (their effect on the checks' 1e-3 tolerances and the second-order check's 0.05 is
    nil), their stencil rows are taken as g(u*) and their second differences as 0.
    Otherwise the other rows are evaluated.

    Returns
    -------
    (g at [u*, u* + h e_k, u* - h e_k] (2 d + 1), the columns verified, or None for all)
    """
    d = point.size
    if g is None:
        g = _sparse_stencil(values, point, step, columns)
    others = np.setdiff1d(np.arange(d), columns)
    if not others.size:
        return g, None
    v = np.zeros(d)
    v[others] = np.where(np.arange(others.size) % 2 == 0, 1.0, -1.0)
    check = values(np.stack([point + HESSIAN_STEP * v, point - HESSIAN_STEP * v]))
    slope = float(np.linalg.norm(g[1:d + 1] - g[d + 1:])) / (2 * step)
    if np.all(np.abs(check - g[0]) <= STRUCTURE_TOLERANCE * HESSIAN_STEP * slope):
        return g, columns
    basis = step * np.eye(d)[others]
    rest = values(np.concatenate([point + basis, point - basis]))
    g = g.copy()
    g[1 + others] = rest[:others.size]
    g[1 + d + others] = rest[others.size:]
    return g, None


def tangent_directions(normal, full) -> np.ndarray:
    """Directions (rows) of the tangent space of the plane with unit normal ``normal``.

    ``full``: an orthonormal basis (d - 1 rows, from a QR factorisation of [normal, I]);
    else the coordinate axes projected on the plane and normalised, without the axis most
    aligned with the normal (d - 1 rows, not orthogonal).
    """
    d = normal.size
    if full:
        q, _ = np.linalg.qr(np.column_stack([normal, np.eye(d)]))
        return q[:, 1:d].T
    keep = np.delete(np.arange(d), int(np.argmax(np.abs(normal))))
    axes = np.eye(d)[keep] - np.outer(normal[keep], normal)
    return axes / np.linalg.norm(axes, axis=1, keepdims=True)


def _projected_hessian(values, point, g_star, gradient, multiplier, columns=None):
    """Eigenvalues of A = I + lambda T' H_g T at u* (ascending) and whether A was taken
    whole (module docstring); second differences of step :data:`HESSIAN_STEP`. With
    ``columns`` (diagonal only): the tangent directions along the other axes are those axes
    (the normal has no component there), g is constant along them, and A's entry is 1
    without evaluation."""
    d = point.size
    normal = gradient / float(np.linalg.norm(gradient))
    full = d - 1 <= FULL_HESSIAN_DIMENSION
    t = tangent_directions(normal, full)
    if columns is not None and not full:
        axes = np.delete(np.arange(d), int(np.argmax(np.abs(normal))))
        inside = np.isin(axes, columns)
        diagonal = np.ones(axes.size)
        if inside.any():
            t = t[inside]
            g = values(np.concatenate([point + HESSIAN_STEP * t, point - HESSIAN_STEP * t]))
            second = (g[:t.shape[0]] + g[t.shape[0]:] - 2.0 * g_star) / HESSIAN_STEP ** 2
            diagonal[inside] = 1.0 + multiplier * second
        if not np.all(np.isfinite(diagonal)):
            return np.full(axes.size, np.nan), full
        return np.sort(diagonal), full
    h = HESSIAN_STEP
    k = t.shape[0]
    rows = [point + h * t, point - h * t]
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k)] if full else []
    for i, j in pairs:
        rows += [point[None] + h * (t[i] + t[j]), point[None] - h * (t[i] + t[j]),
                 point[None] + h * (t[i] - t[j]), point[None] - h * (t[i] - t[j])]
    g = values(np.concatenate(rows))
    hessian = np.zeros((k, k))
    hessian[np.diag_indices(k)] = (g[:k] + g[k:2 * k] - 2.0 * g_star) / (h * h)
    for n, (i, j) in enumerate(pairs):
        a, b, c, e = g[2 * k + 4 * n:2 * k + 4 * n + 4]
        hessian[i, j] = hessian[j, i] = ((a + b) - (c + e)) / (4.0 * h * h)
    a = np.eye(k) + multiplier * hessian
    if not np.all(np.isfinite(a)):
        return np.full(k, np.nan), full
    return (np.linalg.eigvalsh(a) if full else np.sort(np.diag(a))), full


@dataclass(frozen=True, eq=False)
class DesignPointSet:
    """The distinct design points of :func:`find_design_points`.

    Attributes
    ----------
    points : tuple of DesignPoint
        The accepted, distinct design points, by increasing beta (may be empty).
    evaluations : int
        Rows evaluated by all searches.
    searches : int
        Searches run (the one from the origin and the restarts).
    message : str
        Why the search from the origin was not accepted ("" when it was); with no point,
        why there is none.
    unresolved : int
        Of the evaluated rows, those where g was NaN.
    """

    points: tuple
    evaluations: int
    searches: int
    message: str = ""
    unresolved: int = 0

    @property
    def betas(self) -> np.ndarray:
        """beta of each design point [-]."""
        return np.array([p.beta for p in self.points])

    @property
    def form_probability(self) -> float:
        """The first-order series estimate min(1, sum_k Phi(-beta_k)) [-] (NaN without a
        point): the union of the half-spaces beyond each design point, their overlaps
        counted twice (an upper bound of the FORM probability of the union)."""
        if not self.points:
            return float("nan")
        return float(min(1.0, np.sum(ndtr(-self.betas))))


def find_design_points(limit_state, dimension, seed, *, restarts=DEFAULT_RESTARTS,
                       max_evaluations=None, gradient=None, step=GRADIENT_STEP,
                       max_iterations=100, batch_size=None,
                       second_order=True) -> DesignPointSet:
    """Every distinct design point found from the origin and ``restarts`` seeded starts.

    The first search starts at the origin (:func:`find_design_point`). The restarts begin at
    -u*_0 (the mirror image of the first point found: symmetric limit states such as
    |u_1| >= b have a second design point there), then at the crossings of g = 0 of a scan
    of :data:`SCAN_DIRECTIONS` rays (antithetic pairs; 16 points each from r / 2 to 2 r and a
    regula-falsi step) that lie nearer to the origin than those of their 4 nearest rays (a local
    design point lies below each such crossing; starts close to it end in it, where SLSQP
    from farther away jumps to a larger basin), then at points r s_i, s_i uniform on the unit
    sphere in antithetic pairs (s, -s; drawn from the child (RARE_EVENT_STREAM,
    RESTART_STREAM) of ``seed``): where the ray t s first reaches g <= 0 for t between r / 2
    and 2 r (16 points, one batch, linear interpolation; r the smallest beta found so far, 3
    when none), else r s. A start on the limit state ends in the design point nearest to it
    along g = 0, which finds the small basins that points r s miss. After ``restarts`` searches it
    goes on while one of the last :data:`RESTART_PATIENCE` found a new point (at most
    :data:`MAX_RESTART_FACTOR` ``restarts``). Accepted points that differ in direction
    (1 - cos > 1e-3) or beta (relative 1e-2) are kept; a restart whose SLSQP search ends at
    a point already kept stops there, without the rows of the checks (``known`` of
    :func:`find_design_point`). No finite number of starts is sure to
    find every design point: importance sampling's diagnostics and the cross-check with
    subset simulation (:func:`tolsim.rare_events.estimate`, ``method="rare"``) are the
    safety net.

    Parameters
    ----------
    limit_state, dimension, gradient, step, max_iterations, batch_size, second_order
        As :func:`find_design_point`.
    seed : numpy.random.SeedSequence or int
    restarts : int
        Searches besides the one from the origin (0: FORM as before).
    max_evaluations : int, optional
        No restart begins once the searches have evaluated this many rows (the cost bound
        of :func:`~tolsim.study.analyses.rare_events.importance.importance_sampling`).

    Returns
    -------
    DesignPointSet
    """
    d = check_dimension(dimension)
    restarts = check_count("restarts", restarts, 0)
    root = seed_sequence(seed)
    options = dict(gradient=gradient, step=step, max_iterations=max_iterations,
                   batch_size=batch_size, second_order=second_order)
    first = find_design_point(limit_state, d, **options)
    evaluations, searches, unresolved = first.evaluations, 1, first.unresolved
    message = "" if first.converged else first.message
    if not first.converged and ("origin" in first.message and "fails" in first.message):
        return DesignPointSet((), evaluations, searches, message, unresolved)
    found = [first] if first.converged else []
    budget = np.inf if max_evaluations is None else max_evaluations
    # scan: the rays whose crossing of g = 0 is nearer than their neighbours' point at the
    # local design points; their crossings are the first starts
    scan = []
    if restarts:
        radius = min((p.beta for p in found), default=3.0)
        scan, cost, nans = _ray_scan(limit_state, child_sequence(root, RESTART_STREAM, 1), d,
                                     radius, batch_size)
        evaluations += cost
        unresolved += nans
    # antithetic pairs of directions, drawn for the longest run of restarts
    half = np.random.default_rng(child_sequence(root, RESTART_STREAM)).standard_normal(
        (MAX_RESTART_FACTOR * restarts // 2 + 1, d))
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    directions = np.stack([half, -half], axis=1).reshape(-1, d)
    starts = ([-first.point] if first.converged else []) + list(scan)
    last_new, k = 0, 0
    while (k < restarts or (k - last_new < RESTART_PATIENCE
                            and k < MAX_RESTART_FACTOR * restarts)) and evaluations < budget:
        radius = min((p.beta for p in found), default=3.0)
        if k < len(starts):
            start = starts[k]
        else:
            start, cost, nans = _ray_start(limit_state, directions[k - len(starts)], radius,
                                           batch_size)
            evaluations += cost
            unresolved += nans
        point = find_design_point(limit_state, d, start=start, known=found, **options)
        evaluations += point.evaluations
        unresolved += point.unresolved
        searches += 1
        k += 1
        if point.converged and not any(_same(point, p) for p in found):
            found.append(point)
            last_new = k
    found.sort(key=lambda p: p.beta)
    if not found and not message:
        message = "no search ended in an accepted design point"
    return DesignPointSet(tuple(found), evaluations, searches, message, unresolved)


def _ray_scan(limit_state, sequence, d, radius, batch_size):
    """Starts near the local design points from SCAN_DIRECTIONS rays (antithetic pairs from
    ``sequence``; in the plane evenly spaced with a random phase): the crossing t_i s_i of g = 0
    along each ray (t from r / 2 to 2 r, SCAN_POINTS points, one batch, then one regula-falsi
    step), kept where t_i is no larger than that of the SCAN_NEIGHBOURS nearest rays (by angle),
    nearest first. Returns (starts, rows evaluated, NaN rows)."""
    rng = np.random.default_rng(sequence)
    if d == 2:                        # evenly spaced, a random phase: no gap between rays
        angle = rng.uniform(0.0, 2.0 * np.pi) + 2.0 * np.pi * np.arange(SCAN_DIRECTIONS) \
            / SCAN_DIRECTIONS
        rays = np.column_stack([np.cos(angle), np.sin(angle)])
    else:
        half = rng.standard_normal((SCAN_DIRECTIONS // 2, d))
        half /= np.linalg.norm(half, axis=1, keepdims=True)
        rays = np.concatenate([half, -half])
    t = np.linspace(0.5 * radius, 2.0 * radius, SCAN_POINTS)
    g = evaluate(limit_state, (t[None, :, None] * rays[:, None, :]).reshape(-1, d),
                 batch_size).reshape(len(rays), t.size)
    nans = int(np.count_nonzero(np.isnan(g)))
    crossing = np.full(len(rays), np.inf)
    bracket = np.zeros((len(rays), 4))                   # t_lo, g_lo, t_hi, g_hi
    for i, row in enumerate(g):
        inside = np.flatnonzero(row <= 0)
        if inside.size:
            j = int(inside[0])
            if j == 0 or not np.isfinite(row[j - 1]):
                crossing[i] = t[j]
            else:
                bracket[i] = t[j - 1], row[j - 1], t[j], row[j]
                crossing[i] = t[j - 1] + (t[j] - t[j - 1]) * row[j - 1] / (row[j - 1] - row[j])
    # one secant (regula falsi) step on the bracketed rays, one batch
    refine = np.flatnonzero(bracket[:, 2] > 0)
    if refine.size:
        g_mid = evaluate(limit_state, crossing[refine, None] * rays[refine], batch_size)
        nans += int(np.count_nonzero(np.isnan(g_mid)))
        for i, value in zip(refine, g_mid, strict=True):
            t_lo, g_lo, t_hi, g_hi = bracket[i]
            if not np.isfinite(value):
                continue
            if value > 0:
                t_lo, g_lo = crossing[i], value
            else:
                t_hi, g_hi = crossing[i], value
            crossing[i] = t_lo + (t_hi - t_lo) * g_lo / (g_lo - g_hi) if g_lo != g_hi else t_hi
    rows = g.size + refine.size
    near = np.argsort(-(rays @ rays.T), axis=1)[:, 1:SCAN_NEIGHBOURS + 1]
    local = [i for i in np.argsort(crossing) if np.isfinite(crossing[i])
             and crossing[i] <= crossing[near[i]].min()]
    return [crossing[i] * rays[i] for i in local], rows, nans


def _ray_start(limit_state, direction, radius, batch_size):
    """Where the ray t s, t in [0.5 r, 2 r], first reaches g <= 0 (linear interpolation
    between the grid points of RAY_POINTS), else r s; the rows evaluated and the NaN ones."""
    t = np.linspace(0.5 * radius, 2.0 * radius, RAY_POINTS)
    g = evaluate(limit_state, t[:, None] * direction[None], batch_size)
    inside = np.flatnonzero(g <= 0)
    nans = int(np.count_nonzero(np.isnan(g)))
    if not inside.size:
        return radius * direction, t.size, nans
    i = int(inside[0])
    if i == 0 or not np.isfinite(g[i - 1]):
        return t[i] * direction, t.size, nans
    crossing = t[i - 1] + (t[i] - t[i - 1]) * g[i - 1] / (g[i - 1] - g[i])
    return crossing * direction, t.size, nans


def _same(a, b) -> bool:
    return _near(a.point, a.beta, b.point, b.beta)


def _near(a, beta_a, b, beta_b) -> bool:
    """Two points are the same design point (:data:`DISTINCT_DIRECTION`,
    :data:`DISTINCT_BETA`)."""
    cos = float(a @ b) / (beta_a * beta_b)
    return 1.0 - cos <= DISTINCT_DIRECTION and abs(beta_a - beta_b) <= DISTINCT_BETA * max(
        beta_a, beta_b)


def _user_gradient(gradient, u):
    """The caller's gradient at one point u (d,) -> (d,)."""
    values = np.asarray(gradient(u[None]), dtype=float)
    if values.shape != (1, u.size):
        raise ValueError(f"gradient returned shape {values.shape} for one row; expected "
                         f"(1, {u.size})")
    return values[0]

