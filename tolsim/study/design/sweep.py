"""What-if sweeps: one study at many values of some config keys (issue 14, part 1).

A config with a ``[sweep]`` section (read by :mod:`tolsim.io.config.sweep`) is a family of
studies, its *points*: each point is the config with the swept keys set to one combination of
their values, as a complete :class:`~tolsim.study.spec.StudyConfig`. This module holds the
description of that family (:class:`Sweep`, :class:`SweepAxis`); running the points and
writing them into one result file is :func:`tolsim.io.sweep.run_sweep`.

Modes
-----
``outer`` (the default): every combination of the keys' values, the first key slowest; the
result has one dimension per key (``ds.contact_probability.plot()`` draws the curve of a
one-key sweep, or an image of a two-key one). ``zip``: the i-th values of all keys together
(the lists have one length); the result has one dimension ``sweep_point`` with one coordinate
per key.

Common random numbers
---------------------
Every point runs with the study's seed, so its random blocks are drawn from the same streams
(:mod:`tolsim.study.sampling`): the standard normal variates behind every tolerance, gap and
ball are the same at every point, and only their mapping to values (a scaled spread, a
shifted load) changes. Differences between points are then differences of the same
assemblies, which removes most of the sampling noise from a curve and from a difference
between points (``tests/io/test_sweep.py`` measures the variance reduction on the paired
outcomes). This holds when the swept key leaves the *structure* of the draws alone: keys that
change which variates are drawn (the number of balls, a distribution's kind) get independent
streams in effect.

Keys that change the result's axes (the balls and tracks, the horizon of the time axis, the
histogram ranges, the friction examples' travel grid, the Sobol' factors) cannot share one
file and are refused when the config is read.
"""

from dataclasses import dataclass, field

import numpy as np

#: Sweep modes: how the values of several keys combine into points.
SWEEP_MODES = ("outer", "zip")
#: The dimension of a ``zip`` sweep.
ZIP_DIMENSION = "sweep_point"


@dataclass(frozen=True)
class SweepAxis:
    """One swept config key.

    Attributes
    ----------
    key : str
        The config key as the points set it, with its unit suffix
        (``carriage.load.moment_z_N_m``, ``tolerances.bottom_rotation.scale``).
    name : str
        Its coordinate in the result file: the key's dots as underscores, without the unit
        suffix (``carriage_load_moment_z``).
    values : tuple of float
        In the config's unit (the key's suffix), as written or from ``start``/``stop``/``num``.
    unit : str
        The key's unit suffix (``N_m``; "" for dimensionless keys).
    units : str
        The same unit for UDUNITS / CF (``N m``; ``1`` for dimensionless keys).
    """

    key: str
    name: str
    values: tuple
    unit: str = ""
    units: str = "1"

    @property
    def label(self) -> str:
        """``key [units]`` for plots and tables."""
        return f"{self.key} [{self.units}]" if self.units != "1" else self.key


@dataclass(frozen=True)
class Sweep:
    """The points of a swept study (module docstring).

    Attributes
    ----------
    axes : tuple of SweepAxis
    mode : str
        ``outer`` or ``zip``.
    points : tuple of StudyConfig
        One complete config per point, in order (``outer``: the first key slowest).
    """

    axes: tuple
    mode: str = "outer"
    points: tuple = field(default=(), repr=False, compare=False)

    @property
    def shape(self) -> tuple:
        """Points along each dimension of the result."""
        if self.mode == "zip":
            return (len(self.axes[0].values),)
        return tuple(len(a.values) for a in self.axes)

    @property
    def dimensions(self) -> tuple:
        """The result's sweep dimensions (``outer``: one per key)."""
        if self.mode == "zip":
            return (ZIP_DIMENSION,)
        return tuple(a.name for a in self.axes)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape))

    def index(self, k: int) -> tuple:
        """The position of point ``k`` along :attr:`dimensions`."""
        return tuple(int(i) for i in np.unravel_index(k, self.shape))

    def values_at(self, k: int) -> dict:
        """``{key: value}`` of point ``k`` (config units)."""
        if self.mode == "zip":
            return {a.key: a.values[k] for a in self.axes}
        return {a.key: a.values[i] for a, i in zip(self.axes, self.index(k), strict=True)}

    def describe(self, k: int, units: bool = False) -> str:
        """``key = value, ...`` of point ``k``, for messages (``units``: with the values'
        units, ``key = value N m``)."""
        return ", ".join(
            f"{a.key} = {v:g}" + (f" {a.units}" if units and a.units not in ("", "1") else "")
            for a, v in zip(self.axes, self.values_at(k).values(), strict=True))

    def with_points(self, points) -> "Sweep":
        return Sweep(self.axes, self.mode, tuple(points))
