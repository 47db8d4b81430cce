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
* contact: exact counts of resolved trains and of trains with a contact within the horizon; a
  fixed-bin histogram of the time to first contact over [0, horizon], its exact min and max,
  and the count per touching pair. Time quantiles (given contact) have an error of at most
  one time bin (horizon / ``time_bins``); the survival curve S(t) = P(no contact by t) is
  exact at the bin edges.
* every train counts. A ball outside the fast velocity model's validity is re-solved with the
  full model (:mod:`tolsim.study.pipeline.evaluate`); the counts say how many were, how many the
  full
  model could not take, and how long the re-solves took. A ball that no model resolves
  (static not converged, loss of contact, full model failed) leaves its train *unresolved*
  unless the train has a contact that is certain without it (a pair of resolved balls that
  touches within the horizon). With k trains with contact, u unresolved trains and N trains
  in all, P(contact) is reported as

  - the estimate k / (N - u) over the trains whose outcome is known, with its
    Clopper-Pearson interval (missing at random);
  - the partial-identification bounds [k / N, (k + u) / N], which hold whatever the
    unresolved trains would have done ([Manski2003] Ch. 1), and the interval that covers
    them: [CP lower end of k of N, CP upper end of k + u of N].

  With u = 0 all three coincide with the plain estimate k / N. Time-to-contact statistics
  and the survival curve are over the resolved trains.

  The trains add up: N = v + c + u, v the trains whose balls are all resolved
  (``n_assemblies_valid``: their outcome and, with a contact, its time and pair are known),
  c the trains with an unresolved ball and a certain contact (``n_contact_untimed``: counted
  in k and among the N - u trains whose outcome is known, but outside the time statistics,
  since the unresolved ball might have touched earlier) and u the unresolved ones. A ball
  can be unresolved at the start of the stroke (the ball counters say why: static not
  converged, loss of contact, full model failed) or, with ``along_track`` propagation, at an
  evaluation along the track (``n_unresolved_along_track``, each ball once; a carriage's
  train is also unresolved when its slots or entering balls run out).
* |epsilon| exceedance per assembly (with a spec limit L on |epsilon|): exact counts of the
  assemblies with a resolved ball with |epsilon| > L (``n_exceedance``, certain whatever
  the other balls did) and of the others with a ball without an answer
  (``n_exceedance_unresolved``: unresolved at the start of the stroke; an unloaded ball has
  no epsilon of its own and cannot exceed). P(an assembly has |epsilon| > L) is reported as
  P(contact) is, k / (N - u) with its Clopper-Pearson interval and the bounds
  [k / N, (k + u) / N] (:meth:`Accumulator.exceedance_probability`): the plain run's
  estimate of the event of the rare-event estimator, whose g = L - max |epsilon| <= 0 on the
  same assemblies (:func:`tolsim.study.analyses.limit_state.event_values`; |epsilon| = L, a
  tie of measure zero, is beyond for g and within here, as in the per-ball counts), kept when
  the estimator does not reach it.

References: T. F. Chan, G. H. Golub, R. J. LeVeque, "Updating formulae and a pairwise algorithm
for computing sample variances", Stanford CS report STAN-CS-79-773 (1979).
[Manski2003] C. F. Manski, Partial Identification of Probability Distributions, Springer, 2003.
"""

import copy

import numpy as np

from tolsim.physics.velocity.models import BALL_REGIMES, MODEL_FULL
from tolsim.study.statistics.intervals import (
    ClusterMoments,
    assembly_totals,
    clopper_pearson_interval,
    histogram_quantiles,
)

#: Quantile levels stored for epsilon and time to contact [-].
QUANTILES = (0.001, 0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 0.999)


#: The accumulator's circuit figures (:meth:`Accumulator.add_circuit`), in a checkpoint.
CIRCUIT_FIELDS = ("circuit_count", "circuit_where_count", "circuit_column_max",
                  "circuit_column_mean_sum", "circuit_slack_error",
                  "circuit_column_friction_sum")


def merge_moments(n_a, mean_a, m2_a, n_b, mean_b, m2_b):
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
    velocity_deviation_limit : float
        Spec limit L on |epsilon| [-] for the per-assembly out-of-spec counts (0: none).

    Besides the ball-level moments, the accumulator keeps the count, mean and co-moment matrix
    of the per-assembly totals (valid balls, balls out of spec, sum and sum of squares of
    epsilon; :class:`tolsim.study.statistics.intervals.ClusterMoments`), so that ball-level
    proportions
    and Cpk get intervals with the assembly as the sampling unit
    (:func:`tolsim.study.statistics.intervals.cluster_proportion`, ``cluster_capability``).
    """

    #: array attributes, in the order they are saved
    FIELDS = (
        "n_assemblies", "n_assemblies_valid", "n_contact", "n_unresolved", "n_balls",
        "n_balls_valid", "n_not_converged", "n_loss_of_contact", "n_outside_validity",
        "n_resolved_full", "n_full_failed", "n_unloaded", "regime_count",
        "n_contact_untimed", "n_unresolved_along_track", "n_static_fallback", "n_exceedance",
        "n_exceedance_unresolved",
        "eps_mean", "eps_m2", "eps_min", "eps_max", "eps_histogram", "eps_underflow",
        "eps_overflow", "ball_count", "ball_mean", "ball_m2", "time_histogram", "time_min",
        "time_max", "pair_count", "carriage_count", "carriage_failed", "carriage_mean",
        "carriage_m2", "carriage_min", "carriage_max",
    )
    #: Per-assembly carriage quantities of ``carriage_*`` (:meth:`add_carriage`): the
    #: displacement q and the diagonal of the carriage stiffness, in ``DOFS`` order.
    CARRIAGE_COLUMNS = 10

    def __init__(self, balls, velocity_deviation_range, velocity_deviation_bins, horizon,
                 time_bins, velocity_deviation_limit=0.0, tracks=1):
        self.balls = int(balls)
        self.tracks = int(tracks)
        if self.tracks < 1 or self.balls % self.tracks:
            raise ValueError(f"balls = {balls} must be a multiple of tracks = {tracks}")
        self.velocity_deviation_limit = float(velocity_deviation_limit)
        self.cluster = ClusterMoments.empty()
        self.eps_edges = np.linspace(velocity_deviation_range[0], velocity_deviation_range[1],
                                     velocity_deviation_bins + 1)
        self.time_edges = np.linspace(0.0, horizon, time_bins + 1)
        i8 = np.int64
        self.n_assemblies = i8(0)
        self.n_assemblies_valid = i8(0)
        self.n_contact = i8(0)
        self.n_unresolved = i8(0)
        self.n_balls = i8(0)
        self.n_balls_valid = i8(0)
        self.n_not_converged = i8(0)
        self.n_loss_of_contact = i8(0)
        self.n_outside_validity = i8(0)
        self.n_resolved_full = i8(0)
        self.n_full_failed = i8(0)
        self.n_unloaded = i8(0)  # balls without a loaded contact: pushed along, no epsilon
        # trains with an unresolved ball and a certain contact: known outcome, no time
        self.n_contact_untimed = i8(0)
        # balls unresolved at an evaluation along the track, not at the start (each once)
        self.n_unresolved_along_track = i8(0)
        # balls the study's static model left without balance, answered by its fallback
        self.n_static_fallback = i8(0)
        # assemblies with a resolved ball with |epsilon| > L, and the others with a ball
        # without an answer (L: velocity_deviation_limit; both 0 without one)
        self.n_exceedance = i8(0)
        self.n_exceedance_unresolved = i8(0)
        # balls per regime, in the order of BALL_REGIMES (unresolved, A, B, 3-, 2-point,
        # unloaded)
        self.regime_count = np.zeros(len(BALL_REGIMES), dtype=i8)
        # [s] wall time of the full-model re-solves: a timing, not part of the result (not in
        # FIELDS or state(); the runner's checkpoint keeps it apart)
        self.resolve_seconds = 0.0
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
        self.pair_count = np.zeros(max(self.balls - self.tracks, 1), dtype=i8)
        c = self.CARRIAGE_COLUMNS
        self.carriage_count = i8(0)  # assemblies with a solved carriage
        self.carriage_failed = i8(0)  # assemblies whose carriage was not solved
        self.carriage_mean = np.zeros(c)
        self.carriage_m2 = np.zeros(c)
        self.carriage_min = np.full(c, np.inf)
        self.carriage_max = np.full(c, -np.inf)
        # the figures of a [carriage.circuit] (add_circuit), None without one
        self.circuit = None

    @classmethod
    def for_config(cls, config):
        st = config.study
        return cls(config.balls, st.velocity_deviation_range, st.velocity_deviation_bins,
                   config.motion.duration, st.time_bins, st.velocity_deviation_limit,
                   config.n_tracks)

    def _empty_like(self):
        return Accumulator(self.balls, (self.eps_edges[0], self.eps_edges[-1]),
                           len(self.eps_histogram), self.time_edges[-1],
                           len(self.time_histogram), self.velocity_deviation_limit, self.tracks)

    def add_carriage(self, carriage):
        """Add the carriages of a block of assemblies (a :class:`tolsim.study.pipeline.carriage.
        CarriageState`): moments, min and max of the displacement and the diagonal
        stiffness over the solved ones, and the count of the others."""
        block = self._empty_like()
        solved = carriage.status == 0
        x = np.concatenate([carriage.displacement, carriage.stiffness], axis=1)[solved]
        block.carriage_count = np.int64(len(x))
        block.carriage_failed = np.int64(len(solved) - len(x))
        if len(x):
            block.carriage_mean = x.mean(axis=0)
            block.carriage_m2 = ((x - block.carriage_mean) ** 2).sum(axis=0)
            block.carriage_min = x.min(axis=0)
            block.carriage_max = x.max(axis=0)
        self._merge_carriage(block)

    def _merge_carriage(self, other):
        n_a = self.carriage_count
        self.carriage_count, self.carriage_mean, self.carriage_m2 = merge_moments(
            n_a, self.carriage_mean, self.carriage_m2, other.carriage_count,
            other.carriage_mean, other.carriage_m2)
        self.carriage_count = np.int64(self.carriage_count)
        self.carriage_failed = self.carriage_failed + other.carriage_failed
        self.carriage_min = np.minimum(self.carriage_min, other.carriage_min)
        self.carriage_max = np.maximum(self.carriage_max, other.carriage_max)

    def add_circuit(self, figures: dict):
        """Add the circuit figures of a block of assemblies (``[carriage.circuit]``;
        :meth:`tolsim.study.pipeline.carriage_circuit.CircuitContact.figures`): contact events
        by where they form, the column forces at the zone's entry and exit (largest, and the
        sum of each assembly's mean over the stroke), the largest slack error, and with
        ``[contact]`` the sum of each assembly's friction of the column's forces."""
        block = {
            "circuit_count": np.int64(len(figures["slack_error"])),
            "circuit_where_count": figures["where_count"].sum(axis=0).astype(np.int64),
            "circuit_column_max": (figures["column_max"].max(axis=0) if
                                   len(figures["column_max"]) else np.zeros(2)),
            "circuit_column_mean_sum": figures["column_mean"].sum(axis=0),
            "circuit_slack_error": np.float64(figures["slack_error"].max(initial=0.0)),
        }
        if "column_friction" in figures:  # with [contact]
            block["circuit_column_friction_sum"] = np.float64(
                np.sum(figures["column_friction"]))
        self._merge_circuit(block)

    def _merge_circuit(self, other):
        if other is None:
            return
        if self.circuit is None:
            self.circuit = {k: np.copy(v) for k, v in other.items()}
            return
        c = self.circuit
        for name in ("circuit_count", "circuit_where_count", "circuit_column_mean_sum",
                     "circuit_column_friction_sum"):
            if name in c:
                c[name] = c[name] + other[name]
        c["circuit_column_max"] = np.maximum(c["circuit_column_max"],
                                             other["circuit_column_max"])
        c["circuit_slack_error"] = np.maximum(c["circuit_slack_error"],
                                              other["circuit_slack_error"])

    @property
    def carriage_std(self) -> np.ndarray:
        """Sample standard deviation of the carriage columns (NaN below 2 carriages)."""
        n = int(self.carriage_count)
        return np.sqrt(self.carriage_m2 / (n - 1)) if n > 1 else np.full(
            self.CARRIAGE_COLUMNS, np.nan)

    # ---------------------------------------------------------------------------------------
    def add(self, state, contact_time, contact_pair, train_valid=None,
            unresolved_along_track=None):
        """Add one block of trains.

        Parameters
        ----------
        state : tolsim.study.pipeline.evaluate.BallState
            Balls of shape (m, balls); epsilon is NaN for unresolved balls.
        contact_time : ndarray (m,)
            [s], inf when no contact within the horizon. A finite time must be certain: the
            propagation only reports contacts of pairs whose balls are resolved.
        contact_pair : ndarray of int (m,)
        train_valid : ndarray of bool (m,), optional
            Extra validity of the train (along-track propagation: every ball resolved at
            every step).
        unresolved_along_track : ndarray of int (m,), optional
            Along-track propagation: the balls of each train unresolved at an evaluation
            after the start and not at it (:attr:`tolsim.study.pipeline.block.BlockOutcome.
            unresolved_along_track`).
        """
        # statistics sit below the pipeline, whose package imports this module

        eps, valid = state.velocity_deviation, state.valid
        block = self._empty_like()
        limit = self.velocity_deviation_limit if self.velocity_deviation_limit > 0 else np.inf
        totals = assembly_totals(eps, limit)
        block.cluster = ClusterMoments.from_totals(totals)
        if self.velocity_deviation_limit > 0:
            # a resolved ball beyond L is certain whatever the others did (as a certain
            # contact); else a ball without an answer leaves the assembly unresolved
            exceeds = totals[:, 1] > 0
            block.n_exceedance = np.int64(np.count_nonzero(exceeds))
            block.n_exceedance_unresolved = np.int64(np.count_nonzero(
                ~exceeds & ~state.accounted.all(axis=1)))
        m = eps.shape[0]
        block.n_assemblies = np.int64(m)
        block.n_balls = np.int64(eps.size)
        block.n_balls_valid = np.int64(np.count_nonzero(valid))
        block.n_not_converged = np.int64(np.count_nonzero(~state.converged))
        block.n_loss_of_contact = np.int64(np.count_nonzero(state.loss_of_contact))
        block.n_resolved_full = np.int64(np.count_nonzero(state.model == MODEL_FULL))
        block.n_unloaded = np.int64(np.count_nonzero(state.unloaded))
        block.n_static_fallback = np.int64(np.count_nonzero(state.static_fallback))
        block.regime_count = np.bincount(state.regime.reshape(-1).astype(np.int64) + 1,
                                         minlength=len(BALL_REGIMES)).astype(np.int64)
        block.n_full_failed = block.n_balls - block.n_balls_valid - \
            block.n_not_converged - block.n_loss_of_contact - block.n_unloaded
        block.n_outside_validity = block.n_resolved_full + block.n_full_failed
        block.resolve_seconds = float(state.resolve_seconds)
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
        ok = state.accounted.all(axis=1)  # unloaded balls are pushed along
        if train_valid is not None:
            ok &= train_valid
        hit = np.isfinite(contact_time)
        block.n_assemblies_valid = np.int64(np.count_nonzero(ok))
        block.n_contact = np.int64(np.count_nonzero(hit))
        block.n_unresolved = np.int64(np.count_nonzero(~ok & ~hit))
        block.n_contact_untimed = np.int64(np.count_nonzero(~ok & hit))
        if unresolved_along_track is not None:
            block.n_unresolved_along_track = np.int64(np.sum(unresolved_along_track))
        timed = ok & hit  # first-contact time and pair known
        if np.any(timed):
            th = contact_time[timed]
            block.time_min = float(th.min())
            block.time_max = float(th.max())
            block.time_histogram = _uniform_histogram(th, self.time_edges)
            block.pair_count = np.bincount(contact_pair[timed],
                                           minlength=len(self.pair_count)).astype(np.int64)
        self.merge(block)

    def merge(self, other):
        """Merge ``other`` into self (the order of merges is part of the result)."""
        for name in ("n_assemblies", "n_assemblies_valid", "n_contact", "n_unresolved",
                     "n_balls", "n_balls_valid", "n_not_converged", "n_loss_of_contact",
                     "n_outside_validity", "n_resolved_full", "n_full_failed",
                     "n_unloaded", "regime_count", "n_contact_untimed",
                     "n_unresolved_along_track", "n_static_fallback", "n_exceedance",
                     "n_exceedance_unresolved", "resolve_seconds", "eps_histogram",
                     "eps_underflow", "eps_overflow", "time_histogram", "pair_count"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        n_a = self.n_balls_valid - other.n_balls_valid  # already added above
        _, mean, m2 = merge_moments(n_a, self.eps_mean, self.eps_m2, other.n_balls_valid,
                                     other.eps_mean, other.eps_m2)
        self.eps_mean, self.eps_m2 = float(mean), float(m2)
        self.eps_min = min(self.eps_min, other.eps_min)
        self.eps_max = max(self.eps_max, other.eps_max)
        self.ball_count, self.ball_mean, self.ball_m2 = merge_moments(
            self.ball_count, self.ball_mean, self.ball_m2, other.ball_count, other.ball_mean,
            other.ball_m2)
        self.time_min = min(self.time_min, other.time_min)
        self.time_max = max(self.time_max, other.time_max)
        self.cluster = self.cluster.merge(other.cluster)
        self._merge_carriage(other)
        self._merge_circuit(other.circuit)

    def merged(self, other) -> "Accumulator":
        """A new accumulator: self followed by ``other`` (:meth:`merge` on a deep copy).

        Self is left unchanged, so a runner can replace its state by the successor in one
        assignment: a KeyboardInterrupt never leaves a half-merged state behind.
        """
        out = copy.deepcopy(self)
        out.merge(other)
        return out

    # ---------------------------------------------------------------------------------------
    def inconsistency(self) -> str:
        """What breaks the counts' identities (module docstring), or "" if none does: every
        count >= 0, N = v + c + u with k <= N - u, balls = N x balls per assembly, every ball
        in one regime, exceeding and undecided assemblies at most N. A state read back from
        a checkpoint is checked with it (an edited or damaged one is refused)."""
        counts = {name: int(np.asarray(getattr(self, name)).min(initial=0))
                  for name in self.FIELDS
                  if name.startswith("n_") or name in ("regime_count", "pair_count")}
        negative = [name for name, low in counts.items() if low < 0]
        if negative:
            return f"{negative[0]} < 0"
        n, u = int(self.n_assemblies), int(self.n_unresolved)
        rules = (
            (int(self.n_assemblies_valid) + int(self.n_contact_untimed) + u == n,
             "n_assemblies_valid + n_contact_untimed + n_unresolved != n_assemblies"),
            (int(self.n_contact) <= n - u, "n_contact > n_assemblies - n_unresolved"),
            (int(self.n_balls) == n * self.balls, "n_balls != n_assemblies x balls"),
            (int(self.n_balls_valid) <= int(self.n_balls), "n_balls_valid > n_balls"),
            (int(np.sum(self.regime_count)) == int(self.n_balls),
             "the balls per regime do not add up to n_balls"),
            (int(self.n_exceedance) + int(self.n_exceedance_unresolved) <= n,
             "n_exceedance + n_exceedance_unresolved > n_assemblies"),
        )
        return next((message for ok, message in rules if not ok), "")

    def state(self) -> dict:
        """All arrays, for a checkpoint (``np.savez``)."""
        out = {name: np.asarray(getattr(self, name)) for name in self.FIELDS}
        out["eps_edges"] = self.eps_edges
        out["time_edges"] = self.time_edges
        out["velocity_deviation_limit"] = np.float64(self.velocity_deviation_limit)
        out["tracks"] = np.int64(self.tracks)
        out["cluster_count"] = np.int64(self.cluster.count)
        out["cluster_mean"] = self.cluster.mean
        out["cluster_comoment"] = self.cluster.comoment
        if self.circuit is not None:
            out.update({name: np.asarray(v) for name, v in self.circuit.items()})
        return out

    @classmethod
    def from_state(cls, state: dict):
        eps_edges, time_edges = state["eps_edges"], state["time_edges"]
        acc = cls(len(state["ball_count"]), (eps_edges[0], eps_edges[-1]), len(eps_edges) - 1,
                  time_edges[-1], len(time_edges) - 1, float(state["velocity_deviation_limit"]),
                  int(state["tracks"]))
        acc.cluster = ClusterMoments(int(state["cluster_count"]),
                                     np.array(state["cluster_mean"], dtype=float),
                                     np.array(state["cluster_comoment"], dtype=float))
        for name in cls.FIELDS:
            value = np.asarray(state[name])
            setattr(acc, name, value.copy() if value.ndim else value[()])
        for name in ("eps_mean", "eps_m2", "eps_min", "eps_max", "time_min", "time_max"):
            setattr(acc, name, float(getattr(acc, name)))
        if "circuit_count" in state:
            acc.circuit = {name: np.array(state[name]) for name in CIRCUIT_FIELDS
                           if name in state}
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
        """P(contact within the horizon) over the trains whose outcome is known, k / (N - u),
        and its 95 % Clopper-Pearson interval."""
        known = int(self.n_assemblies) - int(self.n_unresolved)
        return clopper_pearson(int(self.n_contact), known)

    def contact_probability_bounds(self, confidence: float = 0.95):
        """Partial-identification bounds of P(contact) over all N trains, and their interval.

        Returns
        -------
        (lower, upper, ci_lower, ci_upper) : floats
            k / N and (k + u) / N, and the Clopper-Pearson lower end of k of N and upper end
            of k + u of N (NaN when N = 0).
        """
        return proportion_bounds(int(self.n_contact), int(self.n_unresolved),
                                 int(self.n_assemblies), confidence)

    def exceedance_probability(self, confidence: float = 0.95):
        """P(an assembly has a ball with |epsilon| > L) over the assemblies whose outcome is
        known, its Clopper-Pearson interval and the partial-identification bounds over all N
        (module docstring; NaN without a limit L).

        Returns
        -------
        (p, lower, upper, bound_lower, bound_upper, bounds_ci_lower, bounds_ci_upper) : floats
            k / (N - u) with its interval, k / N and (k + u) / N with the Clopper-Pearson lower
            end of k of N and upper end of k + u of N; k = ``n_exceedance``,
            u = ``n_exceedance_unresolved``.
        """
        if not self.velocity_deviation_limit > 0:
            return (float("nan"),) * 7
        n, k = int(self.n_assemblies), int(self.n_exceedance)
        u = int(self.n_exceedance_unresolved)
        return (*clopper_pearson(k, n - u, confidence),
                *proportion_bounds(k, u, n, confidence))

    def time_to_contact_quantiles(self, levels=QUANTILES) -> np.ndarray:
        """Quantiles of the time to first contact given contact [s] (error <= one bin).

        Clipped to the exact [min, max] of the contact times.
        """
        q = histogram_quantiles(self.time_histogram, self.time_edges, levels, 0, 0)
        return np.clip(q, self.time_min, self.time_max) if self.n_contact else q

    def survival(self) -> np.ndarray:
        """S(t) = P(no contact by t) at the time bin edges, over resolved trains [-]."""
        n = int(self.n_assemblies_valid)
        if n == 0:
            return np.full(len(self.time_edges), np.nan)
        cum = np.concatenate([[0], np.cumsum(self.time_histogram)])
        return 1.0 - cum / n


def proportion_bounds(successes: int, unresolved: int, trials: int,
                      confidence: float = 0.95):
    """Partial-identification bounds of a proportion with ``unresolved`` of the ``trials``
    unknown ([Manski2003] Ch. 1), and the interval that covers them.

    Returns
    -------
    (lower, upper, ci_lower, ci_upper) : floats
        k / n and (k + u) / n, and the Clopper-Pearson lower end of k of n and upper end of
        k + u of n (NaN when n = 0).
    """
    low, ci_low, _ = clopper_pearson(successes, trials, confidence)
    high, _, ci_high = clopper_pearson(successes + unresolved, trials, confidence)
    return low, high, ci_low, ci_high


def clopper_pearson(successes: int, trials: int, confidence: float = 0.95):
    """Proportion and its exact (Clopper-Pearson) two-sided confidence interval.

    Returns
    -------
    (p, lower, upper) : floats, NaN when ``trials`` is 0.
    """
    lower, upper = clopper_pearson_interval(successes, trials, confidence)
    return (successes / trials if trials else float("nan")), lower, upper
