"""Streamed statistics of a study: memory independent of the number of samples.

One :class:`Accumulator` per block of assemblies, merged in block order, so the result is
bit-identical however the blocks were grouped into chunks or spread over workers.

* epsilon: exact count, mean and M2 (Chan et al.'s pairwise update), min and max, a
  fixed-bin histogram with underflow/overflow counts, and per-ball-position mean and M2.
  Quantiles are read off the histogram with linear interpolation inside a bin: they lie
  within one bin width (``velocity_deviation_range`` / ``velocity_deviation_bins``, 1e-4 by
  default) of the order statistics that bracket the empirical quantile, are clipped to the
  exact [min, max], and are NaN when the quantile falls outside the histogram range (the
  out-of-range counts are stored).
* contact: exact counts of valid trains and of trains with a contact within the horizon; a
  fixed-bin histogram of the time to first contact over [0, horizon], its exact min and max,
  and the count per touching pair. Time quantiles (given contact) have an error of at most
  one time bin (horizon / ``time_bins``); the survival curve S(t) = P(no contact by t) is
  exact at the bin edges.
* validity: counts of balls by cause (static not converged, loss of contact, outside the
  velocity model's validity) and of trains with an invalid ball, which are excluded.

Reference: T. F. Chan, G. H. Golub, R. J. LeVeque, "Updating formulae and a pairwise algorithm
for computing sample variances", Stanford CS report STAN-CS-79-773 (1979).
"""

import numpy as np

from tolsim.study.quality import clopper_pearson_interval

#: Quantile levels stored for epsilon and time to contact [-].
QUANTILES = (0.001, 0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 0.999)


def _merge_moments(n_a, mean_a, m2_a, n_b, mean_b, m2_b):
    """Chan et al. merge of (count, mean, M2); elementwise on arrays."""
    n = n_a + n_b
    with np.errstate(invalid="ignore", divide="ignore"):
        delta = mean_b - mean_a
        mean = np.where(n > 0, mean_a + delta * (n_b / np.maximum(n, 1)), 0.0)
        m2 = m2_a + m2_b + delta * delta * (n_a * n_b / np.maximum(n, 1))
    return n, mean, np.where(n > 0, m2, 0.0)


def _uniform_histogram(x, edges):
    """Counts of x in the equal-width bins ``edges`` (= np.linspace(lo, hi, bins + 1)).

    NumPy's equal-width path (bin count and range instead of the edge array): the same counts,
    since it rebuilds the edges with the same linspace and corrects the computed index against
    them, but no sort.
    """
    return np.histogram(x, bins=len(edges) - 1, range=(edges[0], edges[-1]))[0].astype(np.int64)


class Accumulator:
    """Mergeable statistics of a set of trains (see the module docstring).

    Parameters
    ----------
    balls : int
        Balls per train.
    velocity_deviation_range : (float, float)
        Histogram range of epsilon [-].
    velocity_deviation_bins : int
    horizon : float
        [s]; contact-time histogram range.
    time_bins : int
    """

    #: array attributes, in the order they are saved
    FIELDS = (
        "n_assemblies", "n_assemblies_valid", "n_contact", "n_balls", "n_balls_valid",
        "n_not_converged", "n_loss_of_contact", "n_outside_validity",
        "eps_mean", "eps_m2", "eps_min", "eps_max", "eps_histogram", "eps_underflow",
        "eps_overflow", "ball_count", "ball_mean", "ball_m2", "time_histogram", "time_min",
        "time_max", "pair_count",
    )

    def __init__(self, balls, velocity_deviation_range, velocity_deviation_bins, horizon,
                 time_bins):
        self.balls = int(balls)
        self.eps_edges = np.linspace(velocity_deviation_range[0], velocity_deviation_range[1],
                                     velocity_deviation_bins + 1)
        self.time_edges = np.linspace(0.0, horizon, time_bins + 1)
        i8 = np.int64
        self.n_assemblies = i8(0)
        self.n_assemblies_valid = i8(0)
        self.n_contact = i8(0)
        self.n_balls = i8(0)
        self.n_balls_valid = i8(0)
        self.n_not_converged = i8(0)
        self.n_loss_of_contact = i8(0)
        self.n_outside_validity = i8(0)
        self.eps_mean = 0.0
        self.eps_m2 = 0.0
        self.eps_min = np.inf
        self.eps_max = -np.inf
        self.eps_histogram = np.zeros(velocity_deviation_bins, dtype=i8)
        self.eps_underflow = i8(0)
        self.eps_overflow = i8(0)
        self.ball_count = np.zeros(self.balls, dtype=i8)
        self.ball_mean = np.zeros(self.balls)
        self.ball_m2 = np.zeros(self.balls)
        self.time_histogram = np.zeros(time_bins, dtype=i8)
        self.time_min = np.inf
        self.time_max = -np.inf
        self.pair_count = np.zeros(max(self.balls - 1, 1), dtype=i8)

    @classmethod
    def for_config(cls, config):
        st = config.study
        return cls(config.train.balls, st.velocity_deviation_range, st.velocity_deviation_bins,
                   config.motion.duration, st.time_bins)

    # ---------------------------------------------------------------------------------------
    def add(self, state, contact_time, contact_pair, train_valid=None):
        """Add one block of trains.

        Parameters
        ----------
        state : tolsim.study.evaluate.BallState
            Balls of shape (m, balls); epsilon is NaN for invalid balls.
        contact_time : ndarray (m,)
            [s], inf when no contact within the horizon.
        contact_pair : ndarray of int (m,)
        train_valid : ndarray of bool (m,), optional
            Extra validity of the train (along-track propagation).
        """
        eps, valid = state.velocity_deviation, state.valid
        block = Accumulator(self.balls, (self.eps_edges[0], self.eps_edges[-1]),
                            len(self.eps_histogram), self.time_edges[-1],
                            len(self.time_histogram))
        m = eps.shape[0]
        block.n_assemblies = np.int64(m)
        block.n_balls = np.int64(eps.size)
        block.n_balls_valid = np.int64(np.count_nonzero(valid))
        block.n_not_converged = np.int64(np.count_nonzero(~state.converged))
        block.n_loss_of_contact = np.int64(np.count_nonzero(state.loss_of_contact))
        block.n_outside_validity = block.n_balls - block.n_balls_valid - \
            block.n_not_converged - block.n_loss_of_contact
        x = eps[valid]
        if x.size:
            block.eps_mean = float(np.mean(x))
            block.eps_m2 = float(np.sum((x - block.eps_mean) ** 2))
            block.eps_min = float(np.min(x))
            block.eps_max = float(np.max(x))
            lo, hi = self.eps_edges[0], self.eps_edges[-1]
            block.eps_underflow = np.int64(np.count_nonzero(x < lo))
            block.eps_overflow = np.int64(np.count_nonzero(x > hi))
            block.eps_histogram = _uniform_histogram(x, self.eps_edges)
        cnt = valid.sum(axis=0).astype(np.int64)
        block.ball_count = cnt
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(cnt > 0, np.nansum(eps, axis=0) / np.maximum(cnt, 1), 0.0)
            block.ball_mean = mean
            block.ball_m2 = np.nansum((eps - mean) ** 2, axis=0)
        ok = valid.all(axis=1)
        if train_valid is not None:
            ok &= train_valid
        block.n_assemblies_valid = np.int64(np.count_nonzero(ok))
        t = contact_time[ok]
        hit = np.isfinite(t)
        block.n_contact = np.int64(np.count_nonzero(hit))
        if block.n_contact:
            th = t[hit]
            block.time_min = float(th.min())
            block.time_max = float(th.max())
            block.time_histogram = _uniform_histogram(th, self.time_edges)
            pairs = contact_pair[ok][hit]
            block.pair_count = np.bincount(pairs, minlength=len(self.pair_count)).astype(
                np.int64)
        self.merge(block)

    def merge(self, other):
        """Merge ``other`` into self (the order of merges is part of the result)."""
        for name in ("n_assemblies", "n_assemblies_valid", "n_contact", "n_balls",
                     "n_balls_valid", "n_not_converged", "n_loss_of_contact",
                     "n_outside_validity", "eps_histogram", "eps_underflow", "eps_overflow",
                     "time_histogram", "pair_count"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        n_a = self.n_balls_valid - other.n_balls_valid  # already added above
        _, mean, m2 = _merge_moments(n_a, self.eps_mean, self.eps_m2, other.n_balls_valid,
                                     other.eps_mean, other.eps_m2)
        self.eps_mean, self.eps_m2 = float(mean), float(m2)
        self.eps_min = min(self.eps_min, other.eps_min)
        self.eps_max = max(self.eps_max, other.eps_max)
        self.ball_count, self.ball_mean, self.ball_m2 = _merge_moments(
            self.ball_count, self.ball_mean, self.ball_m2, other.ball_count, other.ball_mean,
            other.ball_m2)
        self.time_min = min(self.time_min, other.time_min)
        self.time_max = max(self.time_max, other.time_max)

    # ---------------------------------------------------------------------------------------
    def state(self) -> dict:
        """All arrays, for a checkpoint (``np.savez``)."""
        out = {name: np.asarray(getattr(self, name)) for name in self.FIELDS}
        out["eps_edges"] = self.eps_edges
        out["time_edges"] = self.time_edges
        return out

    @classmethod
    def from_state(cls, state: dict):
        eps_edges, time_edges = state["eps_edges"], state["time_edges"]
        acc = cls(len(state["ball_count"]), (eps_edges[0], eps_edges[-1]), len(eps_edges) - 1,
                  time_edges[-1], len(time_edges) - 1)
        for name in cls.FIELDS:
            value = np.asarray(state[name])
            setattr(acc, name, value.copy() if value.ndim else value[()])
        for name in ("eps_mean", "eps_m2", "eps_min", "eps_max", "time_min", "time_max"):
            setattr(acc, name, float(getattr(acc, name)))
        return acc

    # ---------------------------------------------------------------------------------------
    @property
    def velocity_deviation_std(self) -> float:
        """Sample standard deviation of epsilon over valid balls [-] (NaN below 2)."""
        n = int(self.n_balls_valid)
        return float(np.sqrt(self.eps_m2 / (n - 1))) if n > 1 else float("nan")

    @property
    def velocity_deviation_mean(self) -> float:
        return float(self.eps_mean) if self.n_balls_valid else float("nan")

    def velocity_deviation_quantiles(self, levels=QUANTILES) -> np.ndarray:
        """Quantiles of epsilon from the histogram (error <= one bin width) [-].

        Clipped to the exact [min, max], so a deterministic study gets exact quantiles.
        """
        q = histogram_quantiles(self.eps_histogram, self.eps_edges, levels,
                                self.eps_underflow, self.eps_overflow)
        return np.clip(q, self.eps_min, self.eps_max) if self.n_balls_valid else q

    def contact_probability(self):
        """P(contact within the horizon) over valid trains and its 95 % Clopper-Pearson CI."""
        return clopper_pearson(int(self.n_contact), int(self.n_assemblies_valid))

    def time_to_contact_quantiles(self, levels=QUANTILES) -> np.ndarray:
        """Quantiles of the time to first contact given contact [s] (error <= one bin).

        Clipped to the exact [min, max] of the contact times.
        """
        q = histogram_quantiles(self.time_histogram, self.time_edges, levels, 0, 0)
        return np.clip(q, self.time_min, self.time_max) if self.n_contact else q

    def survival(self) -> np.ndarray:
        """S(t) = P(no contact by t) at the time bin edges, over valid trains [-]."""
        n = int(self.n_assemblies_valid)
        if n == 0:
            return np.full(len(self.time_edges), np.nan)
        cum = np.concatenate([[0], np.cumsum(self.time_histogram)])
        return 1.0 - cum / n


def histogram_quantiles(counts, edges, levels, underflow=0, overflow=0):
    """Quantiles from a histogram, linear inside a bin; NaN outside the histogram range.

    Parameters
    ----------
    counts : ndarray of int (bins,)
    edges : ndarray (bins + 1,)
    levels : sequence of float in [0, 1]
    underflow, overflow : int
        Samples below / above the range.

    Returns
    -------
    ndarray (len(levels),)
    """
    counts = np.asarray(counts, dtype=np.int64)
    total = int(counts.sum()) + int(underflow) + int(overflow)
    out = np.full(len(levels), np.nan)
    if total == 0:
        return out
    cum = int(underflow) + np.concatenate([[0], np.cumsum(counts)])
    for i, q in enumerate(levels):
        target = q * total
        if target < cum[0] or target > cum[-1]:
            continue
        k = int(np.searchsorted(cum, target, side="left"))
        k = min(max(k, 1), len(counts))
        c = counts[k - 1]
        frac = 0.5 if c == 0 else (target - cum[k - 1]) / c
        out[i] = edges[k - 1] + frac * (edges[k] - edges[k - 1])
    return out


def clopper_pearson(successes: int, trials: int, confidence: float = 0.95):
    """Proportion and its exact (Clopper-Pearson) two-sided confidence interval.

    Returns
    -------
    (p, lower, upper) : floats, NaN when ``trials`` is 0.
    """
    lower, upper = clopper_pearson_interval(successes, trials, confidence)
    return (successes / trials if trials else float("nan")), lower, upper
