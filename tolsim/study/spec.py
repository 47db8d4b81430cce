"""The description of a Monte Carlo tolerance study: frozen dataclasses in SI units.

Built by :func:`tolsim.io.config.load_config` from TOML (where the unit suffixes are
converted), or directly in Python. Nothing here knows about files or units.
"""

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import ndtr, ndtri

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
DISTRIBUTIONS = ("fixed", "normal", "uniform", "truncated_normal", "cpk")
VELOCITY_MODELS = ("eq24", "analytic", "full")
STATIC_MODELS = ("paired", "rigid", "solved", "linearised")
PROPAGATIONS = ("constant", "along_track")
SAMPLINGS = ("random", "sobol", "lhs")


# --------------------------------------------------------------------------------------------
# Dataclasses
# --------------------------------------------------------------------------------------------
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
        inspection (parts outside the band are rejected).
    """

    kind: str = "fixed"
    value: float = 0.0
    mean: float = 0.0
    std: float = 0.0
    low: float = 0.0
    high: float = 0.0
    cpk: float = 0.0
    truncate: bool = False

    @property
    def is_random(self) -> bool:
        return self.kind != "fixed" and not (self.kind == "normal" and self.std == 0.0)

    @property
    def expected(self) -> float:
        """Mean of the distribution (used for nominal ball positions) [SI]."""
        if self.kind == "fixed":
            return self.value
        if self.kind == "uniform":
            return 0.5 * (self.low + self.high)
        if self.kind == "normal" or (self.kind == "cpk" and not self.truncate):
            return self.mean
        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        z = ndtr(b) - ndtr(a)
        phi = lambda x: np.exp(-0.5 * x * x) / np.sqrt(2 * np.pi)  # noqa: E731
        return float(self.mean + self.std * (phi(a) - phi(b)) / z)

    def from_normal(self, z):
        """Map standard normal variates z to values of this distribution [SI]."""
        z = np.asarray(z, dtype=np.float64)
        if self.kind == "fixed":
            return np.full(z.shape, self.value)
        if self.kind == "normal" or (self.kind == "cpk" and not self.truncate):
            return self.mean + self.std * z
        if self.kind == "uniform":
            return self.low + (self.high - self.low) * ndtr(z)
        # truncated normal (also cpk with truncate): inverse CDF on [Phi(a), Phi(b)]
        lo = ndtr((self.low - self.mean) / self.std)
        hi = ndtr((self.high - self.mean) / self.std)
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
    time_steps : int
        Integration steps over the horizon for ``along_track`` propagation.
    velocity_deviation_range : tuple of float
        Histogram range of epsilon [-].
    velocity_deviation_bins, time_bins : int
        Histogram bins of epsilon and of time to first contact.
    velocity_deviation_limit : float
        Spec limit on |epsilon| [-] (0: none); stored for reports.
    contact_probability_limit : float
        Spec limit on P(contact) [-] (0: none); stored for reports.
    sensitivity_samples : int
        Base sample size of the variance-based sensitivity analysis run after the study
        (0: none); it costs sensitivity_samples (d + 2) extra assemblies for d random
        tolerance sources (:func:`tolsim.study.sensitivity.study_sensitivity`).
    """

    samples: int = 10_000
    seed: int = 0
    block_size: int = 1024
    velocity_model: str = "analytic"
    static_model: str = "paired"
    propagation: str = "constant"
    sampling: str = "random"
    spot_checks: int = 0
    time_steps: int = 200
    velocity_deviation_range: tuple = (-0.02, 0.02)
    velocity_deviation_bins: int = 400
    time_bins: int = 200
    velocity_deviation_limit: float = 0.0
    contact_probability_limit: float = 0.0
    sensitivity_samples: int = 0


@dataclass(frozen=True)
class StudyConfig:
    """A validated study: everything in SI units. ``text`` is the TOML source."""

    bearing: Bearing
    motion: Motion
    train: Train
    loads: Loads
    tolerances: tuple
    study: StudySettings
    text: str = field(default="", repr=False)
    path: str = "<string>"

    def with_overrides(self, *, samples=None, seed=None):
        """A copy with run-level settings replaced (the CLI flags)."""
        changes = {}
        if samples is not None:
            if not (isinstance(samples, int) and samples > 0):
                raise ValueError(f"samples = {samples!r} must be a positive integer")
            changes["samples"] = samples
        if seed is not None:
            if not (isinstance(seed, int) and seed >= 0):
                raise ValueError(f"seed = {seed!r} must be a non-negative integer")
            changes["seed"] = seed
        return replace(self, study=replace(self.study, **changes))


