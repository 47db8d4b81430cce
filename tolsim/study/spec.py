"""The description of a Monte Carlo tolerance study: frozen dataclasses in SI units.

Built by :func:`tolsim.io.config.load_config` from TOML (where the unit suffixes are
converted), or directly in Python. Nothing here knows about files or units. A result file
embeds the config's TOML text as its record, so only a config read from TOML (and changed
through its text: :meth:`StudyConfig.with_overrides`,
:func:`tolsim.io.config.with_study_settings`) can be written
(:func:`tolsim.io.config.text_mismatch`); one built in Python runs, for tests and scripts.
"""

import numbers
import re
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import ndtr, ndtri

from tolsim.physics.carriage import CarriageLayout, CarriageLoad
from tolsim.physics.geometry import Bearing

# --------------------------------------------------------------------------------------------
# Vocabulary
# --------------------------------------------------------------------------------------------
#: Error sources of the static contact model (:class:`tolsim.physics.static.GrooveErrors`):
#: name -> (quantity kind: ``length`` [m] or ``angle`` [rad], side). "rail" sources belong to
#: the bottom groove (the fixed rail), "carriage" sources to the top groove, "ball" to the
#: ball. Contacts BL, BR, TR, TL.
SOURCES = {
    "bottom_rotation": ("angle", "rail"),
    "top_rotation": ("angle", "carriage"),
    "arc_centre_offset_tangential_BL": ("length", "rail"),
    "arc_centre_offset_tangential_BR": ("length", "rail"),
    "arc_centre_offset_tangential_TR": ("length", "carriage"),
    "arc_centre_offset_tangential_TL": ("length", "carriage"),
    "arc_centre_offset_normal_BL": ("length", "rail"),
    "arc_centre_offset_normal_BR": ("length", "rail"),
    "arc_centre_offset_normal_TR": ("length", "carriage"),
    "arc_centre_offset_normal_TL": ("length", "carriage"),
    "bottom_offset_x": ("length", "rail"),
    "bottom_offset_y": ("length", "rail"),
    "top_offset_x": ("length", "carriage"),
    "top_offset_y": ("length", "carriage"),
    "ball_oversize": ("length", "ball"),
}

SCOPES = ("rail", "carriage", "ball")
DISTRIBUTIONS = ("fixed", "normal", "uniform", "truncated_normal", "cpk", "empirical")
VELOCITY_MODELS = ("eq24", "analytic", "full")
STATIC_MODELS = ("paired", "rigid", "solved", "linearised")
PROPAGATIONS = ("constant", "along_track")
SAMPLINGS = ("random", "sobol", "lhs")
#: Estimators of the event probabilities (``[study] estimator``; issue 15).
ESTIMATORS = ("monte_carlo", "subset", "importance", "rare")
#: Models that give a ball's creep stiffness in a study with ``[contact]`` (issue 13).
CREEP_MODELS = ("analytic", "full")
#: Standard deviations either side of the mean taken as the reach of an unbounded normal
#: (``normal``, untruncated ``cpk``) when its values are checked against the static model's
#: range: P(|z| > 8) = 1.2e-15, so even 10^9 balls never draw beyond it.
PLAUSIBLE_NORMAL_RANGE = 8.0
#: The largest seed: numpy's SeedSequence takes any, the result file stores it as uint64.
MAX_SEED = 2**64 - 1
#: The most worker processes of one run (``workers`` of :func:`tolsim.study.execution.runner
#: .run_study`, ``--workers``): beyond the cores of any one machine, and far below the limits
#: of the operating system's process pool (a C int), which a larger count overflowed.
MAX_WORKERS = 1024


def whole_number(name, value, minimum=0, maximum=None):
    """``value`` as an int if it is a whole number in [minimum, maximum]; else a ValueError
    naming ``name``.

    Python and NumPy integers pass (``len(a)``, an element of ``np.arange``); a bool, a
    float or a string does not, even when its value would (``True``, ``2.0``, ``"2"``).
    """
    limits = f"from {minimum} to {maximum}" if maximum is not None else f">= {minimum}"
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} = {value!r} must be an integer {limits}")
    value = int(value)
    if value < minimum or (maximum is not None and value > maximum):
        raise ValueError(f"{name} = {value!r} must be an integer {limits}")
    return value


# --------------------------------------------------------------------------------------------
# Dataclasses
# --------------------------------------------------------------------------------------------
def _truncnorm():
    """``scipy.stats.truncnorm``, imported when a one-sided band needs it
    (:attr:`Distribution.one_sided`): ``scipy.stats`` takes a good part of a second to import,
    which ``tolsim ball`` and ``--help`` do not pay."""
    from scipy.stats import truncnorm  # noqa: PLC0415

    return truncnorm


@dataclass(frozen=True)
class Distribution:
    """A one-dimensional distribution, SI units, sampled through a standard normal variate.

    Every kind maps a standard normal z to a value (:meth:`from_normal`), so independent,
    correlated (random field) and quasi-random (``u = Phi(z)``) draws share one code path.

    Attributes
    ----------
    kind : str
        ``fixed`` (``value``), ``normal`` (``mean``, ``std``), ``uniform`` (``low``,
        ``high``), ``truncated_normal`` (``mean``, ``std``, ``low``, ``high``) or ``cpk``: a
        tolerance band [``low``, ``high``] made by a normal process with capability index
        ``cpk`` around ``mean`` (default the band centre),
        std = min(high - mean, mean - low) / (3 cpk); ``truncate`` = true models 100 %
        inspection (parts outside the band are rejected); ``empirical``: measured values
        (``data``), sampled through their interpolated empirical quantile function
        (:meth:`from_normal`).
    data : tuple of float
        ``empirical`` only: the measured values, sorted ascending [SI].
    data_file, data_sha256 : str
        ``empirical`` only: where the values came from (the path as written in the config)
        and the SHA-256 of that file's bytes, for the result file's audit trail.
    """

    kind: str = "fixed"
    value: float = 0.0
    mean: float = 0.0
    std: float = 0.0
    low: float = 0.0
    high: float = 0.0
    cpk: float = 0.0
    truncate: bool = False
    data: tuple = ()
    data_file: str = ""
    data_sha256: str = ""

    @property
    def is_random(self) -> bool:
        if self.kind == "empirical":
            return len(self.data) > 1 and self.data[0] != self.data[-1]
        return self.kind != "fixed" and not (self.kind == "normal" and self.std == 0.0)

    @property
    def standard_band(self) -> tuple:
        """A truncated normal's band in standard deviations from its mean: (a, b)."""
        return (self.low - self.mean) / self.std, (self.high - self.mean) / self.std

    @property
    def one_sided(self) -> bool:
        """A truncated normal whose band lies wholly on one side of its mean (a > 0 or
        b < 0): sampled and summed up by ``scipy.stats.truncnorm``.

        The band's probability Phi(b) - Phi(a) is then the difference of two numbers near 1
        (or two tiny ones): beyond about 8.3 standard deviations Phi rounds both ends to 1.0,
        and the inverse CDF on [Phi(a), Phi(b)] returned the band's far end for every draw
        (a band [10, 20] sigma: every value 20 sigma, against a mean of 10.098 sigma), the
        closed-form mean infinity. scipy's ``truncnorm`` works in the tails (log-space CDFs);
        it is not used for a band across the mean, where the direct inverse CDF is exact to
        rounding and where ``truncnorm`` loses its variance for a band much narrower than
        the standard deviation (NaN at 5e-7 sigma wide, scipy 1.17). Every packaged config's
        truncated normal lies across its mean, so their draws are unchanged.
        """
        if self.kind not in ("truncated_normal", "cpk") or (self.kind == "cpk"
                                                            and not self.truncate):
            return False
        a, b = self.standard_band
        return a > 0.0 or b < 0.0

    @property
    def support(self) -> tuple:
        """(lowest, highest) value the distribution can give [SI]; for an unbounded normal
        the values at -/+ :data:`PLAUSIBLE_NORMAL_RANGE` standard deviations."""
        if self.kind == "fixed":
            return self.value, self.value
        if self.kind == "empirical":
            return self.data[0], self.data[-1]
        if self.kind == "uniform" or self.kind == "truncated_normal" or (
                self.kind == "cpk" and self.truncate):
            return self.low, self.high
        reach = PLAUSIBLE_NORMAL_RANGE * self.std
        return self.mean - reach, self.mean + reach

    @property
    def expected(self) -> float:
        """Mean of the distribution (used for nominal ball positions) [SI]."""
        if self.kind == "fixed":
            return self.value
        if self.kind == "empirical":
            # mean of the piecewise-linear quantile function: the trapezoidal rule over
            # the n - 1 equal steps in u between the order statistics
            x = np.asarray(self.data)
            return float((x.sum() - 0.5 * (x[0] + x[-1])) / (x.size - 1))
        if self.kind == "uniform":
            return 0.5 * (self.low + self.high)
        if self.kind == "normal" or (self.kind == "cpk" and not self.truncate):
            return self.mean
        if self.one_sided:
            return float(_truncnorm().mean(*self.standard_band, loc=self.mean, scale=self.std))
        a, b = self.standard_band
        z = ndtr(b) - ndtr(a)
        phi = lambda x: np.exp(-0.5 * x * x) / np.sqrt(2 * np.pi)  # noqa: E731
        return float(self.mean + self.std * (phi(a) - phi(b)) / z)

    @property
    def centre(self) -> float:
        """The point a tolerance's spread is scaled about (:meth:`scaled`) [SI]: ``value``
        (fixed), ``mean`` (normal, truncated normal, cpk), the band centre (uniform), the
        mean of the measured values (empirical)."""
        if self.kind == "fixed":
            return self.value
        if self.kind == "uniform":
            return 0.5 * (self.low + self.high)
        if self.kind == "empirical":
            return float(np.mean(self.data))
        return self.mean

    def scaled(self, factor: float) -> "Distribution":
        """This distribution with its spread scaled by ``factor`` about :attr:`centre`.

        Every value x becomes centre + factor (x - centre): a normal's std, a uniform's or
        truncated normal's band, a cpk band (so its std, at the same cpk) and measured values
        all scale by ``factor``; the centre stays. This is "the tolerance times ``factor``" of
        a what-if sweep (``[sweep]``) and of tolerance allocation (``tolsim allocate``). A
        ``fixed`` value has no spread and is returned unchanged.

        Raises
        ------
        ValueError
            For a factor that is not finite and > 0.
        """
        f = float(factor)
        if not (np.isfinite(f) and f > 0):
            raise ValueError(f"scale factor {factor!r} must be finite and > 0")
        if self.kind == "fixed" or f == 1.0:
            return self
        c = self.centre

        def about(x):
            return c + f * (x - c)

        if self.kind == "empirical":
            return replace(self, data=tuple(float(about(x)) for x in self.data))
        if self.kind == "normal":
            return replace(self, std=f * self.std)
        return replace(self, std=f * self.std, low=about(self.low), high=about(self.high))

    def from_normal(self, z):
        """Map standard normal variates z to values of this distribution [SI]."""
        z = np.asarray(z, dtype=np.float64)
        if self.kind == "fixed":
            return np.full(z.shape, self.value)
        if self.kind == "empirical":
            # u = Phi(z), then the sample quantile of definition 7 of Hyndman and Fan (1996),
            # numpy's default method="linear": Q(u) = x_(k) + (h - k)(x_(k+1) - x_(k)) with
            # h = (n - 1) u and the order statistics x_(0) <= ... <= x_(n-1). Values stay
            # within the measured range.
            x = np.asarray(self.data)
            return np.interp((x.size - 1) * ndtr(z), np.arange(x.size, dtype=np.float64), x)
        if self.kind == "normal" or (self.kind == "cpk" and not self.truncate):
            return self.mean + self.std * z
        if self.kind == "uniform":
            return self.low + (self.high - self.low) * ndtr(z)
        if self.one_sided:  # a band in one tail: Phi(a), Phi(b) may round to one number
            u = ndtr(z)
            return np.clip(_truncnorm().ppf(u, *self.standard_band, loc=self.mean,
                                            scale=self.std), self.low, self.high)
        # truncated normal (also cpk with truncate): inverse CDF on [Phi(a), Phi(b)]
        a, b = self.standard_band
        lo, hi = ndtr(a), ndtr(b)
        u = lo + (hi - lo) * ndtr(z)
        return np.clip(self.mean + self.std * ndtri(u), self.low, self.high)


@dataclass(frozen=True)
class Tolerance:
    """One error source drawn from a distribution.

    Attributes
    ----------
    source : str
        A key of :data:`SOURCES`.
    distribution : Distribution
        In SI units ([m] or [rad]).
    scope : str
        ``rail``: one value per assembly shared by every ball, or, with a
        ``correlation_length``, a random field along the rail (exponential correlation);
        ``carriage``: one value per assembly; ``ball``: independent per ball.
    correlation_length : float
        [m]; 0 means fully correlated (one value per rail).
    """

    source: str
    distribution: Distribution
    scope: str
    correlation_length: float = 0.0


def correlation_matrix_problem(matrix) -> str | None:
    """Why ``matrix`` is not a valid correlation matrix (one line), or None if it is.

    Valid: square, finite, symmetric (exactly, as typed), unit diagonal and positive
    definite (its Cholesky factorisation exists; a coefficient of +/-1 is only positive
    semi-definite: use one source instead of two perfectly correlated ones).
    """
    m = np.asarray(matrix, dtype=np.float64)
    n = m.shape[0] if m.ndim == 2 else 0
    if m.ndim != 2 or m.shape != (n, n) or n < 2:
        return f"must be a square matrix of at least 2 x 2, got shape {m.shape}"
    if not np.all(np.isfinite(m)):
        return "must hold finite numbers"
    if not np.all(np.diag(m) == 1.0):
        return f"must have a unit diagonal, got {np.diag(m).tolist()}"
    i, j = np.nonzero(m != m.T)
    if i.size:
        return f"must be symmetric: [{i[0]}][{j[0]}] = {m[i[0], j[0]]!r} but " \
               f"[{j[0]}][{i[0]}] = {m[j[0], i[0]]!r}"
    if np.any(np.abs(m) > 1.0):
        return "must have coefficients within [-1, 1]"
    try:
        np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        return ("is not positive definite (no Cholesky factor): the coefficients contradict "
                "each other, or one is +/-1 (then use one source)")
    return None


@dataclass(frozen=True)
class Correlation:
    """Correlated tolerance sources: a Gaussian copula of their standard normal variates.

    Each source keeps its own distribution (its marginal); the standard normals z that
    :meth:`Distribution.from_normal` maps are correlated with ``matrix``:
    z = L xi with L the lower Cholesky factor of ``matrix`` and xi independent standard
    normals (:func:`tolsim.study.sampling.error_values`). For normal marginals the values
    then have Pearson correlation ``matrix``; for others the Spearman rank correlation is
    (6 / pi) asin(rho / 2) (Kruskal 1958), which a monotone marginal does not change.

    Attributes
    ----------
    sources : tuple of str
        Keys of :data:`SOURCES`, all with the same scope (and, for rail random fields, the
        same correlation length), in the order of ``matrix``.
    matrix : tuple of tuple of float
        Correlation matrix of the standard normals [-], positive definite.
    """

    sources: tuple
    matrix: tuple

    def __post_init__(self):
        if len(set(self.sources)) != len(self.sources):
            raise ValueError(f"correlation sources {self.sources!r} repeat a source")
        problem = correlation_matrix_problem(self.matrix)
        if problem is None and len(self.matrix) != len(self.sources):
            problem = f"is {len(self.matrix)} x {len(self.matrix)} for {len(self.sources)} sources"
        if problem:
            raise ValueError(f"correlation matrix {problem}")

    @property
    def cholesky(self) -> np.ndarray:
        """Lower Cholesky factor L of ``matrix`` (L L^T = matrix)."""
        return np.linalg.cholesky(np.asarray(self.matrix, dtype=np.float64))


@dataclass(frozen=True)
class Motion:
    """Carriage motion. groove_velocity v [m/s]; duration of the horizon [s]."""

    groove_velocity: float
    duration: float

    @property
    def stroke(self) -> float:
        """Carriage travel over the horizon [m]."""
        return self.groove_velocity * self.duration


@dataclass(frozen=True)
class Train:
    """The balls of one track in the loaded zone, numbered from the trailing end (ball 0).

    Attributes
    ----------
    balls : int
        Number of balls per track.
    initial_gap : Distribution
        Gap between adjacent balls at t = 0 [m], drawn per pair.
    loaded_zone_length : float
        [m]; the nominal ball slots are spread evenly over it.
    """

    balls: int
    initial_gap: Distribution
    loaded_zone_length: float

    def slot_positions(self, ball_diameter: float) -> np.ndarray:
        """Nominal ball centres along the carriage, centred on 0 [m] (ball 0 trailing)."""
        pitch = ball_diameter + self.initial_gap.expected
        return (np.arange(self.balls) - 0.5 * (self.balls - 1)) * pitch


@dataclass(frozen=True)
class Loads:
    """Per-ball loads on the top groove, ordered like the train.

    Attributes
    ----------
    normal_load : tuple of float
        N_y per ball [N].
    side_load : tuple of float
        N_x per ball [N]; with a yaw moment M, N_x,j = N_x,total / n + M z_j / sum z_j^2 at
        the nominal slot positions z_j (rigid carriage, linear distribution).
    yaw_moment : float
        [N m], for the record.
    """

    normal_load: tuple
    side_load: tuple
    yaw_moment: float = 0.0

    @property
    def side_force_ratio(self) -> np.ndarray:
        """rho_j = N_x / N_y per ball [-]."""
        return np.asarray(self.side_load) / np.asarray(self.normal_load)


@dataclass(frozen=True)
class Circuit:
    """The recirculating ball circuit of each carriage track (``[carriage.circuit]``, issue 24;
    the physics in :mod:`tolsim.physics.circuit`, the defaults' derivation in the Notes of
    :func:`tolsim.physics.circuit.circuit_length`).

    Attributes
    ----------
    balls : int
        Balls per circuit (loaded zone, turnarounds and return channel), more than the loaded
        zone holds.
    slack : float
        The circuit's total clearance [m] (its length minus the balls' diameters), >= 0.
    return_drag : float
        Resistance of one unloaded ball moving through the turnarounds and the return
        channel [N], >= 0.
    """

    balls: int = 30
    slack: float = 1.0e-3
    return_drag: float = 0.02

    def __post_init__(self):
        if int(self.balls) != self.balls or self.balls < 2:
            raise ValueError(f"circuit balls = {self.balls!r} must be an integer >= 2")
        for name in ("slack", "return_drag"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"circuit {name} = {value!r} must be >= 0")


@dataclass(frozen=True)
class Carriage:
    """A rigid carriage on its ball tracks, with preload, under the loads a user knows
    (tolsim issue 12; conventions in :mod:`tolsim.physics.carriage`).

    Attributes
    ----------
    layout : tolsim.physics.carriage.CarriageLayout
        Tracks (x, y [m], orientation [rad]), balls per track, ball pitch [m].
    load : tolsim.physics.carriage.CarriageLoad
        External load at the reference point [N, N m].
    preload_oversize : float
        Nominal diametral ball oversize o of every ball [m] (the preload class).
    ball_oversize_deviation : tuple of float
        Per-ball deviation from ``preload_oversize`` [m], track by track (n_tracks x
        balls_per_track values), or () for none.
    end_relief_depth : float
        Recess of the carriage flanks at the ends of the loaded zone [m] (crowning,
        :func:`tolsim.physics.carriage.end_relief`; config key ``end_relief_depth_um``),
        >= 0; 0: none. Used by ``along_track`` propagation.
    end_relief_length : float
        Length of the relieved part at each end of the loaded zone [m] (config key
        ``end_relief_length_mm``), > 0 with a depth (at most half the loaded zone, checked
        with the train); 0 without.
    circuit : Circuit or None
        The closed ball circuit of every track (``[carriage.circuit]``, ``along_track``
        only); None: the open trains (fresh independent balls enter the loaded zone).
    """

    layout: CarriageLayout
    load: CarriageLoad
    preload_oversize: float = 0.0
    ball_oversize_deviation: tuple = ()
    end_relief_depth: float = 0.0
    end_relief_length: float = 0.0
    circuit: Circuit | None = None

    def __post_init__(self):
        for name in ("end_relief_depth", "end_relief_length"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} = {value!r} m must be >= 0")
        if (self.end_relief_depth > 0) != (self.end_relief_length > 0):
            raise ValueError(f"end_relief_depth = {self.end_relief_depth!r} m and "
                             f"end_relief_length = {self.end_relief_length!r} m: give both "
                             "(> 0) or neither")
        n = self.layout.n_tracks * self.layout.balls_per_track
        if self.ball_oversize_deviation and len(self.ball_oversize_deviation) != n:
            raise ValueError(f"ball_oversize_deviation has {len(self.ball_oversize_deviation)} "
                             f"values, the carriage has {n} balls")

    @property
    def oversize(self) -> np.ndarray:
        """Diametral oversize of every ball [m], (n_tracks, balls_per_track)."""
        shape = (self.layout.n_tracks, self.layout.balls_per_track)
        out = np.full(shape, float(self.preload_oversize))
        if self.ball_oversize_deviation:
            out += np.asarray(self.ball_oversize_deviation, dtype=float).reshape(shape)
        return out


@dataclass(frozen=True)
class ContactSettings:
    """What happens after balls touch (tolsim issue 13): trains, contact forces, friction.

    A study with ``[contact]`` follows every train over the stroke after its balls touch
    (:mod:`tolsim.physics.trains`) and reports the carriage friction force they cost
    (:mod:`tolsim.study.pipeline.track_friction`).

    Attributes
    ----------
    ball_friction_coefficient : float
        mu_bb [-], Coulomb coefficient of the ball-to-ball contacts (>= 0).
    friction_increase_limit : float
        Spec limit on the increase of a track's carriage friction force over its baseline
        [N] (0: none; config key ``friction_increase_limit_N``).
    creep_model : str
        Which model gives each ball's creep stiffness K, braking sensitivity and free-rolling
        carriage force: a name from :data:`CREEP_MODELS` (``full`` is slow).
    examples : int
        Example trajectories stored for plots (0: none).
    travel_points : int
        Points of the carriage-travel grid of the examples (>= 2).
    """

    ball_friction_coefficient: float = 0.1
    friction_increase_limit: float = 0.0
    creep_model: str = "analytic"
    examples: int = 4
    travel_points: int = 201

    def __post_init__(self):
        for name, ok in (
                ("ball_friction_coefficient", np.isfinite(self.ball_friction_coefficient)
                 and self.ball_friction_coefficient >= 0),
                ("friction_increase_limit", np.isfinite(self.friction_increase_limit)
                 and self.friction_increase_limit >= 0),
                ("creep_model", self.creep_model in CREEP_MODELS),
                ("examples", int(self.examples) == self.examples and self.examples >= 0),
                ("travel_points", int(self.travel_points) == self.travel_points
                 and self.travel_points >= 2)):
            if not ok:
                raise ValueError(f"contact {name} = {getattr(self, name)!r} is out of range")


@dataclass(frozen=True)
class StudySettings:
    """How the study runs.

    Attributes
    ----------
    samples : int
        Number of assemblies.
    seed : int
        Entropy of the root SeedSequence.
    block_size : int
        Assemblies per random block (the unit of reproducibility; changing it changes the
        draws, changing chunking or workers does not).
    velocity_model, static_model, propagation, sampling : str
        Names from :data:`VELOCITY_MODELS`, :data:`STATIC_MODELS`, :data:`PROPAGATIONS`,
        :data:`SAMPLINGS`.
    spot_checks : int
        Balls re-solved with the full model.
    time_steps : int or None
        Integration steps over the horizon for ``along_track`` propagation; None (config
        ``"auto"``, the default): sized from the lengths over which epsilon changes
        (:func:`tolsim.study.pipeline.propagation_rules.time_steps`).
    velocity_deviation_range : tuple of float
        Histogram range of epsilon [-] (a fraction; config key
        ``velocity_deviation_range_percent``).
    velocity_deviation_bins, time_bins : int
        Histogram bins of epsilon and of time to first contact.
    velocity_deviation_limit : float
        Spec limit on |epsilon| [-] (0: none), a fraction: 0.005 is 0.5 % (config key
        ``velocity_deviation_limit_percent`` or ``_ppm``); stored for reports.
    contact_probability_limit : float
        Spec limit on P(contact) [-] (0: none), a fraction (config key
        ``contact_probability_limit_percent`` or ``_ppm``); stored for reports.
    out_of_spec_limit : float
        Allowed fraction of balls with |epsilon| above ``velocity_deviation_limit`` [-] (0:
        none; config key ``out_of_spec_limit_percent`` or ``_ppm``); for the verdict.
    cpk_minimum : float
        Required minimum Cpk of epsilon [-] (0: none); for the verdict.
    sensitivity_samples : int
        Base sample size of the variance-based sensitivity analysis run after the study
        (0: none); it costs sensitivity_samples (d + 2) extra assemblies for d random
        tolerance sources (:func:`tolsim.study.analyses.sensitivity.study_sensitivity`).
    estimator : str
        Estimator of the event probabilities, a name from :data:`ESTIMATORS`: ``monte_carlo``
        (the plain run alone), ``subset``, ``importance`` or ``rare`` (both, cross-checked),
        run after the plain run on every event the study defines
        (:mod:`tolsim.study.analyses.limit_state`).
    samples_per_level : int
        Subset simulation: samples per level n (n p0 chains of 1 / p0 states; also the
        fallback of ``importance`` and half of ``rare``).
    p0 : float
        Subset simulation: conditional probability of each intermediate level [-].
    max_levels : int
        Subset simulation: most levels (the smallest P it reaches is about p0^max_levels).
    importance_samples : int
        Importance sampling: samples around the design point.
    """

    samples: int = 10_000
    seed: int = 0
    block_size: int = 1024
    velocity_model: str = "analytic"
    static_model: str = "paired"
    propagation: str = "constant"
    sampling: str = "random"
    spot_checks: int = 0
    time_steps: int | None = None
    velocity_deviation_range: tuple = (-0.02, 0.02)
    velocity_deviation_bins: int = 400
    time_bins: int = 200
    velocity_deviation_limit: float = 0.0
    contact_probability_limit: float = 0.0
    out_of_spec_limit: float = 0.0
    cpk_minimum: float = 0.0
    sensitivity_samples: int = 0
    estimator: str = "monte_carlo"
    samples_per_level: int = 1000
    p0: float = 0.1
    max_levels: int = 20
    importance_samples: int = 2000


@dataclass(frozen=True)
class StudyConfig:
    """A validated study: everything in SI units.

    ``text`` is the TOML source of exactly this study (the effective config: run-level
    overrides are written into it by :meth:`with_overrides`), so ``tolsim run`` on it
    reproduces the run. ``correlations`` holds the :class:`Correlation` groups of sources.
    ``carriage`` is the :class:`Carriage` of a config with ``[carriage]`` (issue 12); such a
    config has no per-ball ``loads`` (None); its ``train`` is the train of one track: the
    config's ``[train]`` (gap distribution, loaded zone) or, without one, ``balls_per_track``
    balls with the fixed gap ``ball_pitch - D``. An assembly then holds ``n_tracks`` trains
    (:attr:`balls` balls, track by track). ``contact`` holds the :class:`ContactSettings` of
    a config with ``[contact]`` (issue 13), None without (the study stops at first contact).
    ``allocation`` holds the settings of ``[allocate]`` for ``tolsim allocate`` (issue 14),
    None without. ``sweep``
    (a :class:`tolsim.study.design.sweep.Sweep`) holds the points of a config with ``[sweep]``:
    the config itself is then the base the points start from, and ``tolsim run`` runs the
    points.
    """

    bearing: Bearing
    motion: Motion
    train: Train | None
    loads: Loads | None
    tolerances: tuple
    study: StudySettings
    text: str = field(default="", repr=False)
    path: str = "<string>"
    correlations: tuple = ()
    carriage: Carriage | None = None
    contact: ContactSettings | None = None
    allocation: object = None  # tolsim.study.design.allocate.AllocationSettings ([allocate])
    sweep: object = None  # tolsim.study.design.sweep.Sweep ([sweep]): the points to run

    @property
    def mounting(self) -> str:
        """How the balls are held: ``"free"`` (one train, no ``[carriage]``) or
        ``"carriage"``. With ``study.propagation`` it is the variant of the study, which
        :mod:`tolsim.study.pipeline` dispatches on (its registries), and which every other
        module reads through the properties below."""
        return "free" if self.carriage is None else "carriage"

    @property
    def has_carriage(self) -> bool:
        """Whether the balls are those of a carriage (``[carriage]``)."""
        return self.mounting == "carriage"

    @property
    def is_along_track(self) -> bool:
        """Whether epsilon is re-evaluated along the track (``propagation = "along_track"``),
        rather than held constant over the stroke."""
        return self.study.propagation == "along_track"

    @property
    def has_contact(self) -> bool:
        """Whether the trains are followed after contact (``[contact]``)."""
        return self.contact is not None

    @property
    def circuit(self):
        """The carriage's ball circuit (``[carriage.circuit]``), or None."""
        return self.carriage.circuit if self.carriage is not None else None

    @property
    def n_tracks(self) -> int:
        """Tracks (trains) per assembly: the carriage's rows of balls, or 1."""
        return self.carriage.layout.n_tracks if self.has_carriage else 1

    @property
    def balls(self) -> int:
        """Balls per assembly: ``n_tracks`` trains of ``train.balls``, track by track."""
        return self.n_tracks * self.train.balls

    @property
    def data_files(self) -> dict:
        """Measured-data files of ``empirical`` distributions: path (as in the config) ->
        SHA-256 of its bytes, in config order."""
        dists = ([] if self.train is None else [self.train.initial_gap]) + [
            t.distribution for t in self.tolerances]
        return {d.data_file: d.data_sha256 for d in dists if d.kind == "empirical"
                and d.data_file}

    def with_scales(self, scales: dict) -> "StudyConfig":
        """A copy whose tolerance sources have their spread scaled (``{source: factor}``,
        :meth:`Distribution.scaled`); sources not named keep theirs.

        ``text`` is kept as it is: a scaled config is a point of a sweep or an allocation,
        which records its factors beside the text (the result file's sweep coordinates, the
        allocation's optimum config).

        Raises
        ------
        ValueError
            For a source that the config does not draw, or a bad factor.
        """
        known = {t.source for t in self.tolerances}
        for source in scales:
            if source not in known:
                raise ValueError(f"tolerance source {source!r} is not in the config "
                                 f"(it has {', '.join(sorted(known)) or 'none'})")
        tolerances = tuple(replace(t, distribution=t.distribution.scaled(scales[t.source]))
                           if t.source in scales else t for t in self.tolerances)
        return replace(self, tolerances=tolerances)

    def with_overrides(self, *, samples=None, seed=None):
        """A copy with run-level settings replaced (the CLI flags, or the samples actually
        run when a run stops early).

        The new values are also written into ``text`` (the value on the ``samples`` /
        ``seed`` line of ``[study]`` is replaced; layout and comments are kept), so the text
        stays the TOML of the study that runs. A config without text (built in Python) keeps an
        empty text.

        Raises
        ------
        ValueError
            For a value that is not a whole number in range, or a key the config's sweep
            varies (``"study.seed" = [1, 2]``: one value would replace the points' own).
        """
        changes = {}
        if samples is not None:
            changes["samples"] = whole_number("samples", samples, 1)
        if seed is not None:
            changes["seed"] = whole_number("seed", seed, 0, MAX_SEED)
        if self.sweep is not None:
            for key, value in changes.items():
                if any(axis.key == f"study.{key}" for axis in self.sweep.axes):
                    raise ValueError(f"{key} = {value}: the sweep varies study.{key}, and "
                                     "this would set it in every point")
        text = self.text
        for key, value in changes.items():
            if text:
                text = set_study_value(text, key, value)
        sweep = self.sweep
        if sweep is not None and changes:  # every point runs with them
            sweep = sweep.with_points(
                replace(p, study=replace(p.study, **changes), text=text) for p in sweep.points)
        return replace(self, study=replace(self.study, **changes), text=text, sweep=sweep)


# --------------------------------------------------------------------------------------------
# Effective config text
# --------------------------------------------------------------------------------------------
#: A table header ``[a.b]`` or ``[[a]]`` (not an array value: no commas).
_HEADER = re.compile(r"""^\s*\[(\[?)\s*([A-Za-z0-9_\-."'\s]+?)\s*\]\]?\s*(#.*)?$""")


def toml_lines(lines):
    """The lines of a TOML text outside multi-line strings, with their table.

    Yields (line number from 0, line, table, is_array, is_header): ``table`` is the dotted name
    of the table the line belongs to ("" before the first header), or of the header itself;
    ``is_array`` tells an array of tables (``[[name]]``). Plain text processing: no TOML parser
    below the I/O layer.
    """
    table, array, in_string = "", False, None
    for number, line in enumerate(lines):
        if in_string is not None:  # inside a multi-line string: not TOML structure
            end = line.find(in_string)
            if end >= 0:  # it closes here; the rest of the line may open another
                in_string = _open_string(line[end + 3:])
            continue
        in_string = _open_string(line)
        m = _HEADER.match(line)
        if m and in_string is None:
            table = ".".join(p.strip().strip("\"'") for p in m.group(2).split("."))
            array = bool(m.group(1))
            yield number, line, table, array, True
        else:
            yield number, line, table, array, False


def _open_string(line):
    """The delimiter (three double or three single quotes) of a multi-line string that
    ``line`` leaves open, else None. Quotes inside one-line strings and in a comment do not
    count."""
    i, n = 0, len(line)
    while i < n:
        c = line[i]
        if c == "#":  # a comment: the rest of the line is not TOML
            return None
        if c in "\"'" and line.startswith(c * 3, i):
            end = line.find(c * 3, i + 3)
            if end < 0:
                return c * 3
            i = end + 3
        elif c in "\"'":  # a one-line string (a basic one with escapes)
            j = i + 1
            while j < n and line[j] != c:
                j += 2 if c == '"' and line[j] == "\\" else 1
            i = j + 1
        else:
            i += 1
    return None


def toml_key(name):
    """Regex of a TOML key name, bare or quoted."""
    return rf"""(?:{name}|"{name}"|'{name}')"""


def set_study_value(text: str, key: str, value: int) -> str:
    """``text`` with the value of ``[study]`` key ``key`` replaced by ``value``.

    The key is found as a line of the ``[study]`` table (``samples = 100  # note``), as a
    dotted key before the first table (``study.samples = 100``) or in an inline table
    (``study = { samples = 100, ... }``); only the value changes, so comments and layout stay
    (the comment keeps its column where the value's width allows). Plain text processing:
    no TOML parser below the I/O layer.

    Raises
    ------
    ValueError
        If the key is not found exactly once.
    """
    lines = text.splitlines(keepends=True)
    hits = []
    value_re = r"([^\s,}#]+)"
    in_table = re.compile(rf"^(\s*{toml_key(key)}\s*=\s*){value_re}([ \t]*)(#.*)?(\r?\n)?$")
    dotted = re.compile(rf"^(\s*{toml_key('study')}\s*\.\s*{toml_key(key)}\s*=\s*){value_re}"
                        r"([ \t]*)(#.*)?(\r?\n)?$")
    inline = re.compile(rf"^\s*{toml_key('study')}\s*=\s*{{")
    inline_value = re.compile(rf"([{{,]\s*{toml_key(key)}\s*=\s*){value_re}")
    for number, line, name, array, header in toml_lines(lines):
        if header:
            continue
        table = "[]" if array else name  # an array of tables: never [study]
        pattern = in_table if table == "study" else dotted if table == "" else None
        if pattern is not None and (m := pattern.match(line)):
            hits.append((number, m))
        elif table == "" and inline.match(line) and inline_value.search(line):
            hits.append((number, None))
    if len(hits) != 1:
        raise ValueError(f"cannot record study.{key} = {value} in the config text: the key "
                         f"is found {len(hits)} times")
    number, m = hits[0]
    new = str(value)
    if m is None:
        lines[number] = inline_value.sub(lambda x: x.group(1) + new, lines[number], count=1)
    else:
        head, old, gap, comment, end = m.groups()
        if comment:
            gap = " " * max(1, len(gap) + len(old) - len(new))
        lines[number] = head + new + (gap or "") + (comment or "") + (end or "")
    return "".join(lines)


