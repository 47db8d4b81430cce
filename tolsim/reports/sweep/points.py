"""The layout of a sweep file and each point as the single study it is, the numbers per
point and ``points.csv`` (the sweep report)."""

import csv
import io
import os
from dataclasses import dataclass

import numpy as np
import xarray as xr

from tolsim.reports.compare import run_statistics
from tolsim.reports.result_view import (
    integer,
    number,
    quantile_value,
)
from tolsim.reports.verdict import (
    FAIL,
    PASS,
    UNDECIDED,
    has_friction,
    study_verdict,
)
from tolsim.study.design.sweep import Sweep, SweepAxis
from tolsim.study.statistics.intervals import clopper_pearson_interval

#: Files of the report.
HTML_NAME, CSV_NAME = "report.html", "points.csv"
#: Global attributes that make a file a sweep (:mod:`tolsim.io.sweep`); a point has none.
SWEEP_ATTRIBUTES = ("sweep_dimensions", "sweep_coordinates", "sweep_mode", "sweep_keys")
#: Each point's count of spot checks (:data:`tolsim.io.sweep.SPOT_CHECK_COUNT`).
SPOT_CHECK_COUNT = "spot_check_count"
#: Quantile levels of epsilon drawn against the key [-] (the first and last as a band).
VELOCITY_DEVIATION_LEVELS = (0.001, 0.5, 0.999)
#: Quantile levels of the friction increase drawn and tabulated [-].
FRICTION_LEVELS = (0.5, 0.9, 0.99)
#: Short names of the verdict's checks, in the order of
#: :func:`tolsim.reports.verdict.study_verdict`.
CHECK_NAMES = ("P(contact)", "balls out of spec", "Cpk of ε", "P(friction increase > limit)")
#: Statuses in the order a summary lists them.
STATUS_ORDER = (PASS, UNDECIDED, FAIL)


class NotASweep(ValueError):
    """The result file holds a single study, not a sweep."""


# --------------------------------------------------------------------------------------------
# Reading: the sweep's layout and each point as a single study
# --------------------------------------------------------------------------------------------
def value_text(value) -> str:
    return f"{float(value):g}"


def unit_text(units) -> str:
    return "" if units in ("", "1") else f" {units}"


def is_sweep_dataset(ds) -> bool:
    """Whether a result Dataset is a sweep (its ``sweep_dimensions`` attribute is set)."""
    return bool(str(ds.attrs.get("sweep_dimensions", "")).strip())


def is_sweep_file(path) -> bool:
    """Whether ``path`` is a netCDF sweep file; False for anything that cannot be opened
    (the study report then says what is wrong with it). Reads the attributes only."""
    try:
        with xr.open_dataset(os.fspath(path), engine="netcdf4") as ds:
            return is_sweep_dataset(ds)
    except (OSError, ValueError, TypeError, RuntimeError):
        return False


def sweep_layout(ds) -> Sweep:
    """The :class:`Sweep` of a sweep file, or :class:`NotASweep`."""
    if not is_sweep_dataset(ds):
        raise NotASweep("the result file holds a single study, not a sweep")
    a = ds.attrs
    dims = tuple(str(a["sweep_dimensions"]).split())
    names = str(a.get("sweep_coordinates", "")).split()
    keys = str(a.get("sweep_keys", "")).split()
    missing = [n for n in (*dims, *names) if n not in ds.variables and n not in ds.dims]
    if missing or len(keys) != len(names):
        raise NotASweep("the sweep attributes do not match the file's variables "
                        f"(sweep_coordinates {names}, sweep_keys {keys}"
                        + (f"; missing {', '.join(missing)}" if missing else "") + ")")
    mode = str(a.get("sweep_mode", "zip" if dims == ("sweep_point",) else "outer"))
    swept = tuple(SweepAxis(key, name, tuple(float(v) for v in np.asarray(ds[name], dtype=float)),
                            units=str(ds[name].attrs.get("units", "1")))
                  for key, name in zip(keys, names, strict=True))
    layout = Sweep(swept, mode)
    if layout.dimensions != dims:
        raise NotASweep(f"the sweep's dimensions {dims} do not match its mode {mode!r} and keys")
    return layout


def _point_value(value, k: int, size: int):
    """Point ``k``'s value of an attribute merged as lines ``point K: value``
    (:func:`tolsim.io.sweep.combine_points`); the value itself when it is not one."""
    if not (isinstance(value, str) and value.startswith("point 1: ")):
        return value
    spans, pos = [], 0
    for j in range(1, size + 1):
        marker = "point 1: " if j == 1 else f"\npoint {j}: "
        at = value.find(marker, pos)
        if at < 0 or (j == 1 and at != 0):
            return value
        spans.append((at, at + len(marker)))
        pos = at + len(marker)
    end = spans[k + 1][0] if k + 1 < size else len(value)
    return value[spans[k][1]:end]


def point_dataset(ds, k: int, layout: Sweep | None = None):
    """Point ``k`` (0-based, the file's order) of a sweep file as the single study it is.

    The sweep dimensions are selected away (``ds.isel``; the swept keys stay as scalar
    coordinates), the spot checks cut to the point's own count (the rest is padding), and
    every attribute merged as lines ``point K: value`` set to the point's value; the sweep
    attributes go, so the result reads like the file ``tolsim run`` writes for one study.
    """
    layout = layout or sweep_layout(ds)
    point = ds.isel(dict(zip(layout.dimensions, layout.index(k), strict=True)))
    if SPOT_CHECK_COUNT in point.variables:
        count = int(np.asarray(point[SPOT_CHECK_COUNT]))
        if "spot_check" in point.dims and 0 <= count <= point.sizes["spot_check"]:
            point = point.isel(spot_check=slice(0, count))
        point = point.drop_vars(SPOT_CHECK_COUNT)
    point = point.copy()
    for var in point.variables.values():
        var.attrs = {n: _point_value(v, k, layout.size) for n, v in var.attrs.items()}
    attrs = {n: _point_value(v, k, layout.size) for n, v in ds.attrs.items()
             if n not in SWEEP_ATTRIBUTES}
    attrs["title"] = f"{ds.attrs.get('title', 'tolsim sweep')}, point {k + 1}: " \
                     f"{layout.describe(k, units=True)}"
    point.attrs = attrs
    return point


# --------------------------------------------------------------------------------------------
# The numbers per point
# --------------------------------------------------------------------------------------------
@dataclass
class Point:
    """One point of a sweep with the numbers the report shows.

    Attributes
    ----------
    number : int
        1-based, the file's order (outer: the first key slowest).
    values : tuple of float
        The swept keys' values (:attr:`tolsim.study.design.sweep.Sweep.axes`).
    ds : xarray.Dataset
        The point as a single study (:func:`point_dataset`).
    statistics : dict
        name -> :class:`tolsim.reports.compare.Statistic` (:func:`~tolsim.reports.compare.
        run_statistics`).
    verdict : tolsim.reports.verdict.Verdict
    friction : dict or None
        A study with ``[contact]``: the exceedance probability with its interval (the one
        covering the bounds over all assemblies when some are unresolved, as in the
        verdict) and the increase's quantiles.
    """

    number: int
    values: tuple
    ds: object
    statistics: dict
    verdict: object
    friction: dict | None = None

    def stat(self, name, what="estimate") -> float:
        s = self.statistics.get(name)
        return float(getattr(s, what)) if s is not None else float("nan")


def _friction_numbers(ds) -> dict | None:
    if not has_friction(ds):
        return None
    p = number(ds, "friction_exceedance_probability")
    lo = number(ds, "friction_exceedance_probability_ci_lower")
    hi = number(ds, "friction_exceedance_probability_ci_upper")
    k, u = integer(ds, "n_friction_exceedance"), integer(ds, "n_assemblies_friction_unresolved")
    n = integer(ds, "n_assemblies")
    covering = (float("nan"), float("nan"))
    if u > 0 and n > 0:  # as tolsim.reports.verdict.friction_check
        covering = (clopper_pearson_interval(k, n)[0], clopper_pearson_interval(k + u, n)[1])
    return dict(probability=p, ci_lower=lo, ci_upper=hi, exceedances=k, unresolved=u,
                bound_lower=number(ds, "friction_exceedance_probability_bound_lower"),
                bound_upper=number(ds, "friction_exceedance_probability_bound_upper"),
                bounds_ci_lower=covering[0], bounds_ci_upper=covering[1],
                limit=number(ds, "friction_increase_limit"),
                quantiles={level: quantile_value(ds, "friction_increase_quantile", level)
                           for level in FRICTION_LEVELS},
                mean=number(ds, "friction_increase_mean"))


def sweep_points(ds, layout: Sweep | None = None) -> list:
    """Every point of a sweep file as a :class:`Point`, in the file's order."""
    layout = layout or sweep_layout(ds)
    points = []
    for k in range(layout.size):
        pt = point_dataset(ds, k, layout)
        stats = {s.name: s for s in run_statistics(pt, bounds=True)}
        values = tuple(layout.values_at(k).values())
        points.append(Point(k + 1, values, pt, stats, study_verdict(pt), _friction_numbers(pt)))
    return points


def any_unresolved(points) -> bool:
    return any(integer(p.ds, "n_assemblies_unresolved") > 0 for p in points)


# --------------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------------
#: Columns of ``points.csv`` after ``point`` and the swept keys (named as in the config).
CSV_COLUMNS = (
    "contact_probability", "contact_probability_ci_lower", "contact_probability_ci_upper",
    "n_contact", "n_assemblies", "n_assemblies_unresolved",
    "contact_probability_bound_lower", "contact_probability_bound_upper",
    "contact_probability_bounds_ci_lower", "contact_probability_bounds_ci_upper",
    "contact_probability_limit",
    "velocity_deviation_mean", "velocity_deviation_std",
    "velocity_deviation_std_ci_lower", "velocity_deviation_std_ci_upper",
    *(f"velocity_deviation_quantile_{level:g}" for level in VELOCITY_DEVIATION_LEVELS),
    "velocity_deviation_out_of_spec_fraction", "velocity_deviation_cpk",
    "time_to_contact_median_s", "time_to_contact_median_ci_lower_s",
    "time_to_contact_median_ci_upper_s", "travel_to_contact_median_m",
    "n_balls_outside_validity", "n_balls_resolved_full", "n_balls_unresolved",
    "n_balls_static_fallback", "spot_check_count", "spot_check_n_valid",
    "spot_check_rms_difference",
    "verdict", "contact_verdict",
)
#: Columns added for a study with ``[contact]``.
FRICTION_CSV_COLUMNS = (
    "friction_exceedance_probability", "friction_exceedance_probability_ci_lower",
    "friction_exceedance_probability_ci_upper", "n_friction_exceedance",
    "n_assemblies_friction_unresolved", "friction_increase_limit_N",
    "friction_increase_mean_N",
    *(f"friction_increase_quantile_{level:g}_N" for level in FRICTION_LEVELS),
)


def _number(x) -> str:
    """A CSV number: ``repr`` of the float (round trip exact), empty for NaN."""
    x = float(x)
    return repr(x) if np.isfinite(x) else ""


def csv_rows(layout: Sweep, points) -> list:
    """One dict per point (keys: ``point``, the swept keys, :data:`CSV_COLUMNS` and, with
    ``[contact]``, :data:`FRICTION_CSV_COLUMNS`)."""
    rows = []
    for p in points:
        ds = p.ds
        row = {"point": str(p.number)}
        row.update({key.key: _number(v) for key, v in zip(layout.axes, p.values, strict=True)})
        for name in ("contact_probability", "contact_probability_ci_lower",
                     "contact_probability_ci_upper", "contact_probability_bound_lower",
                     "contact_probability_bound_upper", "contact_probability_bounds_ci_lower",
                     "contact_probability_bounds_ci_upper", "contact_probability_limit",
                     "velocity_deviation_mean", "velocity_deviation_std",
                     "velocity_deviation_out_of_spec_fraction", "velocity_deviation_cpk",
                     "spot_check_rms_difference"):
            row[name] = _number(number(ds, name))
        for name in ("n_contact", "n_assemblies", "n_assemblies_unresolved",
                     "n_balls_outside_validity", "n_balls_resolved_full",
                     "n_balls_static_fallback", "spot_check_n_valid"):
            row[name] = str(integer(ds, name))
        row["n_balls_unresolved"] = str(sum(integer(ds, n) for n in (
            "n_balls_not_converged", "n_balls_loss_of_contact", "n_balls_full_failed")))
        row["spot_check_count"] = str(ds.sizes.get("spot_check", 0))
        row["velocity_deviation_std_ci_lower"] = _number(p.stat("velocity_deviation_std",
                                                                "ci_lower"))
        row["velocity_deviation_std_ci_upper"] = _number(p.stat("velocity_deviation_std",
                                                                "ci_upper"))
        for level in VELOCITY_DEVIATION_LEVELS:
            row[f"velocity_deviation_quantile_{level:g}"] = _number(
                quantile_value(ds, "velocity_deviation_quantile", level))
        median = "time_to_contact_quantile_0.5"
        row["time_to_contact_median_s"] = _number(p.stat(median))
        row["time_to_contact_median_ci_lower_s"] = _number(p.stat(median, "ci_lower"))
        row["time_to_contact_median_ci_upper_s"] = _number(p.stat(median, "ci_upper"))
        row["travel_to_contact_median_m"] = _number(
            quantile_value(ds, "travel_to_contact_quantile", 0.5))
        row["verdict"] = p.verdict.status
        row["contact_verdict"] = p.verdict.checks[0].status
        if p.friction is not None:
            fr = p.friction
            row.update({
                "friction_exceedance_probability": _number(fr["probability"]),
                "friction_exceedance_probability_ci_lower": _number(fr["ci_lower"]),
                "friction_exceedance_probability_ci_upper": _number(fr["ci_upper"]),
                "n_friction_exceedance": str(fr["exceedances"]),
                "n_assemblies_friction_unresolved": str(fr["unresolved"]),
                "friction_increase_limit_N": _number(fr["limit"]),
                "friction_increase_mean_N": _number(fr["mean"]),
                **{f"friction_increase_quantile_{level:g}_N": _number(v)
                   for level, v in fr["quantiles"].items()}})
        rows.append(row)
    return rows


def csv_text(layout: Sweep, points) -> str:
    """``points.csv`` as text."""
    columns = ["point", *(key.key for key in layout.axes), *CSV_COLUMNS]
    if any(p.friction is not None for p in points):
        columns += FRICTION_CSV_COLUMNS
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=columns, lineterminator="\n", restval="")
    writer.writeheader()
    writer.writerows(csv_rows(layout, points))
    return buffer.getvalue()
