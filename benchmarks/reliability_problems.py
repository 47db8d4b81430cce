"""Public reliability benchmark problems with exact answers, for the rare-event estimators.

Each :class:`Problem` is a limit state over independent standard normals u (failure where
g <= 0), its exact failure probability computed here (closed form, or one-dimensional
quadrature with :func:`scipy.integrate.quad` to 1e-10 relative), and, where it is a published
problem, the published value and its source. Used by ``tests/study/test_rare_benchmarks.py``
(CI-sized) and ``benchmarks/rare_event_coverage.py`` (full-sized).

Sources
-------
RP35, RP89, RP110: the reliability problem repository of Rozsas & Slobbe (RPRepo,
https://rprepo.readthedocs.io, "Reliability problem repository", TU Delft / TNO, 2019) as
packaged in otbenchmark (``ReliabilityProblem35``, ``...89``, ``...110``,
https://github.com/mbaudin47/otbenchmark); the published probabilities are those of the
issue (tolsim issue 23) and RPRepo. The linear, two-sided and parabolic problems are
textbook cases with closed forms (e.g. Ditlevsen & Madsen, "Structural reliability methods",
1996, ch. 5-6).
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import quad
from scipy.special import ndtr, ndtri


@dataclass(frozen=True)
class Problem:
    """A limit state over independent standard normals with its exact P(g <= 0)."""

    name: str
    dimension: int
    g: object = field(repr=False)
    truth: float
    published: float = float("nan")
    published_digits: int = 3
    source: str = ""

    def __call__(self, u):
        return self.g(u)


def _phi(x):
    return np.exp(-0.5 * x * x) / np.sqrt(2.0 * np.pi)


def _quad(f):
    """int_R phi(x) f(x) dx, split at 0 and integrated to 1e-10 relative."""
    total = 0.0
    for a, b in ((-np.inf, -8.0), (-8.0, 0.0), (0.0, 8.0), (8.0, np.inf)):
        value, _ = quad(lambda x: _phi(x) * f(x), a, b, epsabs=0.0, epsrel=1e-10, limit=400)
        total += value
    return total


# --- RP89: g = min(-x1^2 - x2 + 8, -x1/5 - x2 + 6); fails iff x2 >= min(8 - x1^2, 6 - x1/5)
def rp89(u):
    x1, x2 = u[:, 0], u[:, 1]
    return np.minimum(-x1 ** 2 - x2 + 8.0, -x1 / 5.0 - x2 + 6.0)


RP89_TRUTH = _quad(lambda x: ndtr(-min(8.0 - x * x, 6.0 - x / 5.0)))


# --- RP35: g = min(2 - x2 + exp(-0.1 x1^2) + (0.2 x1)^4, 4.5 - x1 x2)
def rp35(u):
    x1, x2 = u[:, 0], u[:, 1]
    return np.minimum(2.0 - x2 + np.exp(-0.1 * x1 ** 2) + (0.2 * x1) ** 4, 4.5 - x1 * x2)


def _rp35_conditional(x):
    """P(fail | x1 = x): x2 >= h(x) or x x2 >= 4.5."""
    h = 2.0 + np.exp(-0.1 * x * x) + (0.2 * x) ** 4
    if x > 0:
        return ndtr(-min(h, 4.5 / x))
    if x < 0:
        return ndtr(-h) + ndtr(4.5 / x)         # x2 <= 4.5 / x < 0 < h: disjoint
    return ndtr(-h)


RP35_TRUTH = _quad(_rp35_conditional)


# --- RP110: g = min(g1, g2), g1 = 0.85 - 0.1 x1 (x1 <= 3.5) else 4 - x1,
#     g2 = 2.3 - x2 (x2 <= 2) else 0.5 - 0.1 x2. g1 <= 0 iff x1 >= 4 (0.85 - 0.1 x1 >= 0.5 for
#     x1 <= 3.5), g2 <= 0 iff x2 >= 5: P = 1 - (1 - Phi(-4)) (1 - Phi(-5)), exact.
def rp110(u):
    x1, x2 = u[:, 0], u[:, 1]
    g1 = np.where(x1 <= 3.5, 0.85 - 0.1 * x1, 4.0 - x1)
    g2 = np.where(x2 <= 2.0, 2.3 - x2, 0.5 - 0.1 * x2)
    return np.minimum(g1, g2)


RP110_TRUTH = float(1.0 - ndtr(4.0) * ndtr(5.0))


# --- linear: g = beta - a.u, |a| = 1, in d = 6: P = Phi(-beta) exactly
LINEAR_DIMENSION = 6
LINEAR_DIRECTION = np.array([0.5, -0.3, 0.2, 0.6, -0.4, 0.3])
LINEAR_DIRECTION = LINEAR_DIRECTION / np.linalg.norm(LINEAR_DIRECTION)


def linear(probability):
    beta = float(-ndtri(probability))
    return lambda u: beta - u @ LINEAR_DIRECTION


# --- two-sided: g = b - |u1| (d = 2): two design points (+-b, 0), P = 2 Phi(-b) exactly
def two_sided(u):
    return 4.0 - np.abs(u[:, 0])


# --- concave parabola: g = 8 - u1^2 - u2 alone (RP89's first branch): (0, 8) is a maximum of
#     |u| along g = 0, the design points are (+-sqrt(7.5), 0.5), beta = 2.78
def parabola(u):
    return 8.0 - u[:, 0] ** 2 - u[:, 1]


PARABOLA_TRUTH = _quad(lambda x: ndtr(-(8.0 - x * x)))

PROBLEMS = {
    "RP89": Problem("RP89", 2, rp89, RP89_TRUTH, 5.47e-3, 3,
                    "RPRepo RP89 / otbenchmark ReliabilityProblem89"),
    "RP35": Problem("RP35", 2, rp35, RP35_TRUTH, 3.48e-3, 3,
                    "RPRepo RP35 / otbenchmark ReliabilityProblem35"),
    "RP110": Problem("RP110", 2, rp110, RP110_TRUTH, 3.20e-5, 3,
                     "RPRepo RP110 / otbenchmark ReliabilityProblem110"),
    "linear_1e-3": Problem("linear_1e-3", LINEAR_DIMENSION, linear(1e-3), 1e-3),
    "linear_1e-5": Problem("linear_1e-5", LINEAR_DIMENSION, linear(1e-5), 1e-5),
    "linear_1e-7": Problem("linear_1e-7", LINEAR_DIMENSION, linear(1e-7), 1e-7),
    "two_sided": Problem("two_sided", 2, two_sided, float(2.0 * ndtr(-4.0))),
    "parabola": Problem("parabola", 2, parabola, PARABOLA_TRUTH),
}
