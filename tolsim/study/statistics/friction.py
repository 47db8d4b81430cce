"""Streamed friction statistics of a study with ``[contact]``: the per-assembly figures of
:mod:`tolsim.study.pipeline.track_friction` merged block by block (moments and fixed-bin
histograms), memory independent of the number of assemblies."""


import numpy as np

from tolsim.study.statistics.accumulator import (
    QUANTILES,
    Accumulator,
    clopper_pearson,
    merge_moments,
)
from tolsim.study.statistics.intervals import histogram_quantiles

#: Per-assembly figures with streamed moments, in :attr:`FrictionStatistics.COLUMNS` order.
COLUMNS = ("baseline", "increase_max", "increase_mean", "ripple", "contact_force_max",
           "contact_fraction", "clusters_formed")
#: Per-assembly figures with a histogram (all forces [N], on :data:`FORCE_EDGES`).
HISTOGRAM_COLUMNS = ("increase_max", "ripple", "contact_force_max")
#: Edges of the force histograms [N]: a first bin [0, 1e-6 N) for "no force", then 50 bins
#: per decade up to 1e4 N (quantiles within one bin: a relative 4.7 %, or 1e-6 N; a quantile
#: in the first bin is reported as 0). Below 0 and from 1e4 N up the values are counted as
#: underflow and overflow.
FORCE_EDGES = np.concatenate([[0.0], np.logspace(-6.0, 4.0, 10 * 50 + 1)])


# --------------------------------------------------------------------------------------------
# Streamed statistics
# --------------------------------------------------------------------------------------------
class FrictionStatistics:
    """Mergeable statistics of the friction figures of assemblies (module docstring).

    Exact counts (assemblies, resolved, sliding, released from a stick line, certain
    exceedances); over the resolved
    assemblies the count, mean and M2 (Chan et al.), min and max of every column of
    :data:`COLUMNS`, and fixed-bin histograms (:data:`FORCE_EDGES`, with underflow and
    overflow counts) of :data:`HISTOGRAM_COLUMNS`. Merging in block order makes the result
    independent of the chunking, as :class:`tolsim.study.statistics.accumulator.Accumulator`.

    Parameters
    ----------
    friction_increase_limit : float
        Spec limit L on the increase [N] (0: none).
    """

    #: array attributes, in the order they are saved
    FIELDS = ("n_assemblies", "n_resolved", "n_unresolved", "n_sliding", "n_released",
              "n_exceed", "count", "mean", "m2", "minimum", "maximum", "histogram", "underflow",
              "overflow")

    def __init__(self, friction_increase_limit=0.0):
        self.friction_increase_limit = float(friction_increase_limit)
        self.edges = FORCE_EDGES.copy()
        c, h = len(COLUMNS), len(HISTOGRAM_COLUMNS)
        i8 = np.int64
        self.n_assemblies = i8(0)
        self.n_resolved = i8(0)
        self.n_unresolved = i8(0)  # unresolved without a certain exceedance
        self.n_sliding = i8(0)  # a ball beyond a capacity
        self.n_released = i8(0)  # none, but a ball pushed off its stick line
        self.n_exceed = i8(0)
        self.count = i8(0)
        self.mean = np.zeros(c)
        self.m2 = np.zeros(c)
        self.minimum = np.full(c, np.inf)
        self.maximum = np.full(c, -np.inf)
        self.histogram = np.zeros((h, len(self.edges) - 1), dtype=i8)
        self.underflow = np.zeros(h, dtype=i8)
        self.overflow = np.zeros(h, dtype=i8)

    @classmethod
    def for_config(cls, config) -> "FrictionStatistics":
        return cls(config.contact.friction_increase_limit)

    def add(self, figures):
        """Add one block of assemblies."""
        block = FrictionStatistics(self.friction_increase_limit)
        resolved = np.asarray(figures.resolved, dtype=bool)
        exceeds = np.asarray(figures.exceeds, dtype=bool)
        block.n_assemblies = np.int64(len(resolved))
        block.n_resolved = np.int64(np.count_nonzero(resolved))
        block.n_unresolved = np.int64(np.count_nonzero(~resolved & ~exceeds))
        block.n_sliding = np.int64(np.count_nonzero(figures.sliding))
        block.n_released = np.int64(np.count_nonzero(figures.released))
        block.n_exceed = np.int64(np.count_nonzero(exceeds))
        x = figures.columns()[resolved]
        block.count = np.int64(len(x))
        if len(x):
            block.mean = x.mean(axis=0)
            block.m2 = ((x - block.mean) ** 2).sum(axis=0)
            block.minimum = x.min(axis=0)
            block.maximum = x.max(axis=0)
            top = len(self.edges) - 1
            for h, name in enumerate(HISTOGRAM_COLUMNS):
                v = x[:, COLUMNS.index(name)]
                k = np.searchsorted(self.edges, v, side="right") - 1  # bin [e_k, e_k+1)
                block.underflow[h] = np.count_nonzero(k < 0)
                block.overflow[h] = np.count_nonzero(k >= top)
                block.histogram[h] = np.bincount(k[(k >= 0) & (k < top)], minlength=top)
        self.merge(block)

    def merge(self, other: "FrictionStatistics"):
        """Merge ``other`` into self (the order of merges is part of the result)."""
        for name in ("n_assemblies", "n_resolved", "n_unresolved", "n_sliding", "n_released",
                     "n_exceed", "histogram", "underflow", "overflow"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        count, self.mean, self.m2 = merge_moments(self.count, self.mean, self.m2,
                                                   other.count, other.mean, other.m2)
        self.count = np.int64(count)
        self.minimum = np.minimum(self.minimum, other.minimum)
        self.maximum = np.maximum(self.maximum, other.maximum)

    def state(self) -> dict:
        """All arrays, for a checkpoint."""
        out = {name: np.asarray(getattr(self, name)) for name in self.FIELDS}
        out["edges"] = self.edges
        out["friction_increase_limit"] = np.float64(self.friction_increase_limit)
        return out

    @classmethod
    def from_state(cls, state: dict) -> "FrictionStatistics":
        out = cls(float(state["friction_increase_limit"]))
        out.edges = np.array(state["edges"], dtype=float)
        for name in cls.FIELDS:
            if name == "n_released" and name not in state:  # a checkpoint from before it
                continue
            value = np.asarray(state[name])
            setattr(out, name, value.copy() if value.ndim else value[()])
        return out

    # ---------------------------------------------------------------------------------------
    def column_mean(self, name) -> float:
        """Mean of a column over the resolved assemblies (NaN with none)."""
        return float(self.mean[COLUMNS.index(name)]) if self.count else float("nan")

    def column_std(self, name) -> float:
        """Sample standard deviation of a column (NaN below 2 resolved assemblies)."""
        n = int(self.count)
        return (float(np.sqrt(self.m2[COLUMNS.index(name)] / (n - 1))) if n > 1
                else float("nan"))

    def quantiles(self, name, levels=QUANTILES) -> np.ndarray:
        """Quantiles of a histogram column from its histogram (within one bin; 0 in the first
        bin, "no force"), clipped to the exact [min, max] [N]."""
        h = HISTOGRAM_COLUMNS.index(name)
        q = histogram_quantiles(self.histogram[h], self.edges, levels, self.underflow[h],
                                self.overflow[h])
        q = np.where((q >= 0) & (q < self.edges[1]), 0.0, q)
        c = COLUMNS.index(name)
        return np.clip(q, self.minimum[c], self.maximum[c]) if self.count else q

    def exceedance_probability(self, confidence: float = 0.95):
        """P(increase > limit) over the assemblies whose outcome is known, k / (N - u), and
        its Clopper-Pearson interval; NaN without a limit."""
        if not self.friction_increase_limit > 0:
            return float("nan"), float("nan"), float("nan")
        known = int(self.n_assemblies) - int(self.n_unresolved)
        return clopper_pearson(int(self.n_exceed), known, confidence)

    def exceedance_bounds(self, confidence: float = 0.95):
        """(k / N, (k + u) / N, CP lower end of k of N, CP upper end of k + u of N)."""
        if not self.friction_increase_limit > 0:
            return (float("nan"),) * 4
        n, k, u = int(self.n_assemblies), int(self.n_exceed), int(self.n_unresolved)
        low, ci_low, _ = clopper_pearson(k, n, confidence)
        high, _, ci_high = clopper_pearson(k + u, n, confidence)
        return low, high, ci_low, ci_high


class FrictionAccumulator(Accumulator):
    """:class:`~tolsim.study.statistics.accumulator.Accumulator` with the friction statistics
    of a study
    with ``[contact]`` in :attr:`friction` (a :class:`FrictionStatistics`), merged and
    checkpointed with it (state keys ``friction_*``)."""

    def __init__(self, *args, friction=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.friction = friction

    @classmethod
    def for_config(cls, config):
        acc = super().for_config(config)
        acc.friction = FrictionStatistics.for_config(config)
        return acc

    def add_friction(self, figures):
        """Add the friction figures of the block's assemblies."""
        self.friction.add(figures)

    def merge(self, other):
        super().merge(other)
        extra = getattr(other, "friction", None)
        if extra is not None:
            self.friction.merge(extra)

    def state(self) -> dict:
        out = super().state()
        out.update({f"friction_{k}": v for k, v in self.friction.state().items()})
        return out

    @classmethod
    def from_state(cls, state: dict):
        acc = super().from_state(state)
        acc.friction = FrictionStatistics.from_state(
            {k[len("friction_"):]: v for k, v in state.items() if k.startswith("friction_")})
        return acc


def study_accumulator(config) -> Accumulator:
    """An empty accumulator for a study: with friction statistics when it has ``[contact]``
    (either propagation)."""
    return (FrictionAccumulator if config.has_contact else Accumulator).for_config(config)


def accumulator_from_state(state: dict) -> Accumulator:
    """The accumulator saved in ``state`` (a checkpoint), with or without friction."""
    cls = FrictionAccumulator if "friction_n_assemblies" in state else Accumulator
    return cls.from_state(state)


__all__ = ["COLUMNS", "FORCE_EDGES", "HISTOGRAM_COLUMNS", "FrictionAccumulator",
           "FrictionStatistics", "accumulator_from_state", "study_accumulator"]
