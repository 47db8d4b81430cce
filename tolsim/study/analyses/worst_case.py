"""Worst case and RSS beside the Monte Carlo: a linear tolerance stack-up of a study.

For the outputs a quality engineer signs off,

* epsilon_j, the velocity deviation of the ball at train position j, and
* the gap closure of each adjacent pair over the horizon,
  c_j = (epsilon_j - epsilon_(j+1)) v/2 T, the distance by which the trailing ball j gains on
  ball j + 1 in the stroke (with constant epsilon the balls touch when it exceeds their
  initial gap, :func:`tolsim.study.pipeline.propagation.first_contact_constant`),

:func:`linear_stackup` linearises the study's own evaluation path
(:func:`tolsim.study.pipeline.evaluate.evaluate_balls`: its static model, its velocity model, the
full-model re-solves) at the nominal state, every tolerance source at its mean, by central
differences (one evaluation of 2 d + 1 trains for d sources: epsilon of a ball depends on
that ball's own source values only, so perturbing a source at every ball at once gives
d epsilon_j / d x_(i,j) for every position j). With y = y_0 + sum a_(i,b) (x_(i,b) - x0_i)
over sources i and balls b:

worst case
    The largest linear excursion of y from its nominal value over the tolerance box,
    max(sum max(a dlo, a dhi), -sum min(a dlo, a dhi)) with [dlo, dhi] = band - x0; for a
    band centred on the mean this is sum |a_(i,b)| w_i with w_i the half band
    (:func:`tolerance_band`). A source shared by the balls (``carriage``, ``rail`` without
    a correlation length) takes one value, so its coefficients add before the magnitude
    is taken and cancel in a pair difference where the sensitivities of the two balls are
    equal; a ``ball`` source and a rail random field take a value per ball anywhere in the
    band (the classical worst case ignores the correlation of the field).
RSS
    The linearised standard deviation sqrt(a^T C a), C the covariance of the source values:
    sigma_i^2 (:func:`standard_deviation`) on the diagonal, shared sources fully
    correlated between balls, ``ball`` sources independent, a rail field correlated as
    exp(-|s_a - s_b| / l) at the nominal ball pitch; sources of a correlated group
    (:class:`tolsim.study.spec.Correlation`) add rho_ik sigma_i sigma_k (exact for normal
    marginals, the copula correlation otherwise). For independent values this is the
    textbook sqrt(sum (dy/dx_i sigma_i)^2). It estimates the Monte Carlo standard deviation
    where the model is near-linear over the spread of the sources; 3 RSS is the classical
    statistical tolerance of y for normal inputs.

"Tolerance band" of each distribution kind (:func:`tolerance_band`): ``normal`` mean +/- 3
std; ``uniform`` [low, high]; ``truncated_normal`` its bounds; ``cpk`` its tolerance band
[low, high] (with or without ``truncate``: it is the band the part is toleranced to);
``empirical`` the measured range; ``fixed`` the value (no contribution).

The most critical ball is the position with the largest RSS of epsilon; the most critical
pair the one with the largest RSS-based upper value of the gap closure, nominal + 3 RSS (a
load or tolerance mean that differs along the train closes some gaps systematically). Mirror
images that tie go to the lower position.

With ``along_track`` propagation epsilon changes along the stroke; the stack-up is that of
the initial state (the balls at their nominal slots), i.e. the constant-epsilon picture.
"""

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr
from scipy.stats import truncnorm

from tolsim.study.pipeline.evaluate import evaluate_balls

#: Standard deviations either side of the mean taken as the tolerance band of a ``normal``.
NORMAL_BAND_STDS = 3.0
#: Central-difference step of a source as a fraction of its standard deviation (of its half
#: band when the standard deviation is 0): well inside the near-linear range, far above the
#: static solver's round-off (relative tolerance 1e-12).
STEP_FRACTION = 0.1


def _phi(x):
    return np.exp(-0.5 * x * x) / np.sqrt(2.0 * np.pi)


def _truncated_normal_std(mean, std, low, high):
    """Standard deviation of N(mean, std^2) truncated to [low, high] (Johnson, Kotz and
    Balakrishnan, *Continuous Univariate Distributions* 1, 2nd ed., 1994, Eq. 13.134)."""
    a, b = (low - mean) / std, (high - mean) / std
    z = ndtr(b) - ndtr(a)
    pa = _phi(a) if np.isfinite(a) else 0.0
    pb = _phi(b) if np.isfinite(b) else 0.0
    ta = a * pa if np.isfinite(a) else 0.0
    tb = b * pb if np.isfinite(b) else 0.0
    var = 1.0 + (ta - tb) / z - ((pa - pb) / z) ** 2
    return float(std * np.sqrt(max(var, 0.0)))


def standard_deviation(distribution) -> float:
    """Standard deviation of a :class:`tolsim.study.spec.Distribution` [SI].

    ``empirical``: exactly that of its interpolated quantile function (what
    :meth:`~tolsim.study.spec.Distribution.from_normal` samples), piecewise linear in u
    over n - 1 equal steps.
    """
    d = distribution
    if not d.is_random:
        return 0.0
    if d.kind == "normal" or (d.kind == "cpk" and not d.truncate):
        return float(d.std)
    if d.kind == "uniform":
        return float((d.high - d.low) / np.sqrt(12.0))
    if d.one_sided:  # (Distribution.one_sided: the closed form cancels in a tail)
        return float(truncnorm.std(*d.standard_band, scale=d.std))
    if d.kind in ("truncated_normal", "cpk"):
        return _truncated_normal_std(d.mean, d.std, d.low, d.high)
    if d.kind == "empirical":
        x = np.asarray(d.data, dtype=float)
        lo, hi = x[:-1], x[1:]
        mean = np.mean(0.5 * (lo + hi))
        second = np.mean((lo * lo + lo * hi + hi * hi) / 3.0)
        return float(np.sqrt(max(second - mean * mean, 0.0)))
    raise ValueError(f"unknown distribution kind {d.kind!r}")


def tolerance_band(distribution) -> tuple:
    """(low, high) of a distribution's tolerance band [SI] (module docstring)."""
    d = distribution
    if d.kind == "fixed" or not d.is_random:
        value = d.expected
        return float(value), float(value)
    if d.kind == "normal":
        return float(d.mean - NORMAL_BAND_STDS * d.std), float(d.mean + NORMAL_BAND_STDS * d.std)
    if d.kind in ("uniform", "truncated_normal", "cpk"):
        return float(d.low), float(d.high)
    if d.kind == "empirical":
        return float(d.data[0]), float(d.data[-1])
    raise ValueError(f"unknown distribution kind {d.kind!r}")


def _scope_kind(tolerance) -> str:
    """``shared`` (one value per assembly), ``ball`` or ``field`` (rail random field)."""
    if tolerance.scope == "ball":
        return "ball"
    if tolerance.scope == "rail" and tolerance.correlation_length > 0:
        return "field"
    return "shared"


@dataclass(frozen=True)
class LinearStackup:
    """Worst case and RSS of epsilon per ball and of the gap closure per adjacent pair.

    Attributes
    ----------
    sources : tuple of str, length d
        The random tolerance sources, in config order.
    sensitivity : ndarray, shape (d, balls)
        d epsilon_j / d x_i at the nominal state [1/m or 1/rad], NaN where a perturbed ball
        could not be resolved.
    standard_deviation, band_low, band_high, nominal_value : ndarray, shape (d,)
        sigma_i, the tolerance band and the linearisation point (the mean) [m or rad].
    velocity_deviation_nominal, velocity_deviation_worst_case, velocity_deviation_rss :
    ndarray, shape (balls,)
        epsilon_j at the nominal state, its worst-case excursion and RSS [-].
    gap_closure_nominal, gap_closure_worst_case, gap_closure_rss : ndarray, shape (balls - 1,)
        The same for c_j = (epsilon_j - epsilon_(j+1)) v/2 T [m].
    critical_ball : int
        Position with the largest RSS of epsilon.
    critical_pair : int
        Pair (named by its trailing ball) with the largest nominal + 3 RSS gap closure, -1
        for a single ball.
    """

    sources: tuple
    sensitivity: np.ndarray
    standard_deviation: np.ndarray
    band_low: np.ndarray
    band_high: np.ndarray
    nominal_value: np.ndarray
    velocity_deviation_nominal: np.ndarray
    velocity_deviation_worst_case: np.ndarray
    velocity_deviation_rss: np.ndarray
    gap_closure_nominal: np.ndarray
    gap_closure_worst_case: np.ndarray
    gap_closure_rss: np.ndarray
    critical_ball: int
    critical_pair: int


def _correlation(config, sources) -> np.ndarray:
    """rho_ik of the standard normals of the sources (identity outside correlated groups)."""
    rho = np.eye(len(sources))
    where = {s: k for k, s in enumerate(sources)}
    for group in getattr(config, "correlations", ()):
        m = np.asarray(group.matrix, dtype=float)
        for a, sa in enumerate(group.sources):
            for b, sb in enumerate(group.sources):
                if sa in where and sb in where:
                    rho[where[sa], where[sb]] = m[a, b]
    return rho


def _ball_covariance_shape(kind, correlation_length, positions) -> np.ndarray:
    """K(a, b): correlation of one source's values at balls a and b."""
    n = len(positions)
    if kind == "shared":
        return np.ones((n, n))
    if kind == "ball":
        return np.eye(n)
    return np.exp(-np.abs(positions[:, None] - positions[None, :]) / correlation_length)


def _combine(coefficients, kinds, kernels, sigma, rho, dlo, dhi):
    """Worst case and RSS of y = sum_(i,b) A_(i,b) (x_(i,b) - x0_i).

    ``coefficients``: A, shape (d, balls).
    """
    upper = lower = 0.0
    for i, kind in enumerate(kinds):
        a = coefficients[i]
        a = np.array([a.sum()]) if kind == "shared" else a
        upper += np.sum(np.maximum(a * dlo[i], a * dhi[i]))
        lower += np.sum(np.minimum(a * dlo[i], a * dhi[i]))
    var = 0.0
    for i in range(len(kinds)):
        for k in range(len(kinds)):
            if rho[i, k] != 0.0:
                var += (rho[i, k] * sigma[i] * sigma[k]
                        * coefficients[i] @ kernels[i] @ coefficients[k])
    return max(upper, -lower), float(np.sqrt(max(var, 0.0)))


#: Values within this fraction of the largest are ties when picking the critical ball or pair.
TIE_TOLERANCE = 1e-9


def _first_largest(values) -> int:
    """Position of the largest value, ties (within :data:`TIE_TOLERANCE`) to the first; -1 if
    none is finite.

    A train under a yaw moment is mirror-symmetric (ball j and ball n - 1 - j have the same
    RSS), and a bare argmax would pick between the mirror images by round-off.
    """
    values = np.asarray(values, dtype=float)
    if not np.any(np.isfinite(values)):
        return -1
    top = np.nanmax(values)
    with np.errstate(invalid="ignore"):
        return int(np.flatnonzero(values >= top - TIE_TOLERANCE * abs(top))[0])


def linear_stackup(config) -> LinearStackup:
    """Worst case and RSS of epsilon and of the gap closure from linearised sensitivities.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        The study; its tolerance sources, loads, models and motion are used.

    Returns
    -------
    LinearStackup
        See the module docstring for the definitions.
    """
    balls = config.train.balls
    tolerances = [t for t in config.tolerances if t.distribution.is_random]
    sources = tuple(t.source for t in tolerances)
    d = len(tolerances)
    sigma = np.array([standard_deviation(t.distribution) for t in tolerances])
    band = np.array([tolerance_band(t.distribution) for t in tolerances]).reshape(d, 2)
    x0 = np.array([t.distribution.expected for t in tolerances])
    step = STEP_FRACTION * np.where(sigma > 0, sigma, 0.5 * (band[:, 1] - band[:, 0]))
    # rows: nominal, then +step and -step of each source in turn
    rows = 1 + 2 * d
    values = {t.source: np.full((rows, balls), t.distribution.expected)
              for t in config.tolerances}
    for i, t in enumerate(tolerances):
        values[t.source][1 + 2 * i] += step[i]
        values[t.source][2 + 2 * i] -= step[i]
    shape = (rows, balls)
    side = np.broadcast_to(np.asarray(config.loads.side_load, dtype=float), shape)
    normal = np.broadcast_to(np.asarray(config.loads.normal_load, dtype=float), shape)
    eps = evaluate_balls(config, values, side, normal).velocity_deviation
    nominal = eps[0]
    sens = (eps[1::2] - eps[2::2]) / (2.0 * step[:, None]) if d else np.empty((0, balls))

    kinds = [_scope_kind(t) for t in tolerances]
    positions = config.train.slot_positions(2.0 * config.bearing.ball_radius)
    kernels = [_ball_covariance_shape(k, t.correlation_length, positions)
               for k, t in zip(kinds, tolerances, strict=True)]
    rho = _correlation(config, sources)
    dlo, dhi = band[:, 0] - x0, band[:, 1] - x0
    scale = 0.5 * config.motion.groove_velocity * config.motion.duration  # v/2 T [m]

    eps_wc, eps_rss = np.zeros(balls), np.zeros(balls)
    for j in range(balls):
        a = np.zeros((d, balls))
        a[:, j] = sens[:, j]
        eps_wc[j], eps_rss[j] = _combine(a, kinds, kernels, sigma, rho, dlo, dhi)
    pairs = max(balls - 1, 0)
    gap_wc, gap_rss = np.zeros(pairs), np.zeros(pairs)
    for j in range(pairs):
        a = np.zeros((d, balls))
        a[:, j] = scale * sens[:, j]
        a[:, j + 1] = -scale * sens[:, j + 1]
        gap_wc[j], gap_rss[j] = _combine(a, kinds, kernels, sigma, rho, dlo, dhi)
    if d and not np.all(np.isfinite(sens)):  # an unresolved perturbed ball: say so as NaN
        bad = ~np.all(np.isfinite(sens), axis=0)
        eps_wc[bad] = eps_rss[bad] = np.nan
        bad_pair = bad[:-1] | bad[1:]
        gap_wc[bad_pair] = gap_rss[bad_pair] = np.nan
    gap_nominal = scale * (nominal[:-1] - nominal[1:])
    critical_ball = _first_largest(eps_rss)
    critical_pair = _first_largest(gap_nominal + 3.0 * gap_rss)
    return LinearStackup(
        sources=sources, sensitivity=sens, standard_deviation=sigma,
        band_low=band[:, 0].copy(), band_high=band[:, 1].copy(), nominal_value=x0,
        velocity_deviation_nominal=nominal, velocity_deviation_worst_case=eps_wc,
        velocity_deviation_rss=eps_rss, gap_closure_nominal=gap_nominal,
        gap_closure_worst_case=gap_wc, gap_closure_rss=gap_rss,
        critical_ball=critical_ball, critical_pair=critical_pair)
