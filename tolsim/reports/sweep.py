"""The report of a what-if sweep (``tolsim report`` on a sweep file, issue 14).

A sweep file (``tolsim run`` on a config with ``[sweep]``, :mod:`tolsim.io.sweep`) holds one
study per *point*, the variables carrying the sweep dimensions in front.
:func:`make_sweep_report` writes, into a folder:

* ``contact_probability.png``: P(contact) with its 95 % interval band against the swept key
  (outer sweep of one key: one curve; of two or more keys: the first key on the x axis and one
  curve per value of the others; zip: against the point number, the keys' values in the
  table), with the bounds where assemblies are unresolved and the spec limit;
* ``velocity_deviation.png``: (a) the standard deviation of epsilon with its 95 % interval and
  (b) its 0.1 %, 50 % and 99.9 % quantiles with their intervals, against the same axis, with
  the spec limit on |epsilon|;
* ``friction.png`` (a study with ``[contact]``): (a) quantiles of the friction increase with
  its limit and (b) P(friction increase > limit) with its 95 % interval band;
* ``points.csv``: the table per point (:data:`CSV_COLUMNS`): the keys' values, P(contact)
  with its interval, bounds and counts, epsilon, time to first contact, friction, the model
  checks and the verdicts; values in the result file's units (SI; a ``_s``, ``_m`` or ``_N``
  suffix names the unit of a dimensional column, probabilities and epsilon are fractions);
* ``report.html``: one self-contained page (figures embedded) with what was swept (keys,
  values, units, mode, and the common random numbers the points share), the figures, the
  table per point and the verdict per point against the config's spec limits.

Each point is read as the single study it is (:func:`point_dataset`), so its numbers come
from the functions of the study report and of ``tolsim compare``: the verdict from
:func:`tolsim.reports.verdict.study_verdict`, the intervals of the epsilon statistics and of
the time to first contact from :func:`tolsim.reports.compare.run_statistics` (delta method
over assemblies; Woodruff's interval on the histograms). The intervals are each point's own
(marginal) ones: the points share their random numbers, so a *difference* between two points
is known far better than the two intervals suggest (``tolsim compare`` has no paired interval
for it either, see :mod:`tolsim.reports.compare`).

There is no PDF and no Sobol' analysis for a sweep; the study report of one point is the
report of that point's study (run the config without ``[sweep]`` at the point's values).
"""

import csv
import html
import io
import os
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from tolsim import __version__
from tolsim.reports.compare import (
    RUN_COLOURS,
    RUN_LINESTYLES,
    _write_files,
    run_statistics,
)
from tolsim.reports.study import (
    CSS,
    ReportTable,
    _table_html,
    read_result_file,
    study_facts,
)
from tolsim.reports.style import LIMIT_COLOUR, data_uri, new_figure, render_png, styled
from tolsim.reports.verdict import (
    FAIL,
    NO_LIMIT,
    PASS,
    STATUS_LABELS,
    UNDECIDED,
    contact_unit,
    estimator_label,
    has_friction,
    study_verdict,
)
from tolsim.study.design.sweep import Sweep, SweepAxis
from tolsim.study.statistics.intervals import clopper_pearson_interval, format_fraction

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
def _value_text(value) -> str:
    return f"{float(value):g}"


def _unit_text(units) -> str:
    return "" if units in ("", "1") else f" {units}"


def is_sweep_dataset(ds) -> bool:
    """Whether a result Dataset is a sweep (its ``sweep_dimensions`` attribute is set)."""
    return bool(str(ds.attrs.get("sweep_dimensions", "")).strip())


def is_sweep_file(path) -> bool:
    """Whether ``path`` is a netCDF sweep file; False for anything that cannot be opened
    (the study report then says what is wrong with it). Reads the attributes only."""
    import xarray as xr

    try:
        with xr.open_dataset(os.fspath(path), engine="netcdf4") as ds:
            return is_sweep_dataset(ds)
    except (OSError, ValueError, TypeError):
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
def _f(ds, name, default=float("nan")) -> float:
    if name not in ds.variables:
        return default
    return float(np.asarray(ds[name], dtype=float))


def _i(ds, name, default=0) -> int:
    if name not in ds.variables:
        return default
    return int(np.asarray(ds[name]))


def _quantile(ds, name, level) -> float:
    """``name`` (a variable along ``quantile``) at ``level``, NaN when the level is absent."""
    if name not in ds.variables:
        return float("nan")
    levels = np.asarray(ds["quantile"], dtype=float)
    hit = np.flatnonzero(np.isclose(levels, level, rtol=0, atol=1e-12))
    return float(np.asarray(ds[name], dtype=float)[hit[0]]) if hit.size else float("nan")


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
    p = _f(ds, "friction_exceedance_probability")
    lo = _f(ds, "friction_exceedance_probability_ci_lower")
    hi = _f(ds, "friction_exceedance_probability_ci_upper")
    k, u = _i(ds, "n_friction_exceedance"), _i(ds, "n_assemblies_friction_unresolved")
    n = _i(ds, "n_assemblies")
    covering = (float("nan"), float("nan"))
    if u > 0 and n > 0:  # as tolsim.reports.verdict.friction_check
        covering = (clopper_pearson_interval(k, n)[0], clopper_pearson_interval(k + u, n)[1])
    return dict(probability=p, ci_lower=lo, ci_upper=hi, exceedances=k, unresolved=u,
                bound_lower=_f(ds, "friction_exceedance_probability_bound_lower"),
                bound_upper=_f(ds, "friction_exceedance_probability_bound_upper"),
                bounds_ci_lower=covering[0], bounds_ci_upper=covering[1],
                limit=_f(ds, "friction_increase_limit"),
                quantiles={level: _quantile(ds, "friction_increase_quantile", level)
                           for level in FRICTION_LEVELS},
                mean=_f(ds, "friction_increase_mean"))


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


def _any_unresolved(points) -> bool:
    return any(_i(p.ds, "n_assemblies_unresolved") > 0 for p in points)


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
    "spot_check_count", "spot_check_n_valid", "spot_check_rms_difference",
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
            row[name] = _number(_f(ds, name))
        for name in ("n_contact", "n_assemblies", "n_assemblies_unresolved",
                     "n_balls_outside_validity", "n_balls_resolved_full", "spot_check_n_valid"):
            row[name] = str(_i(ds, name))
        row["n_balls_unresolved"] = str(sum(_i(ds, n) for n in (
            "n_balls_not_converged", "n_balls_loss_of_contact", "n_balls_full_failed")))
        row["spot_check_count"] = str(ds.sizes.get("spot_check", 0))
        row["velocity_deviation_std_ci_lower"] = _number(p.stat("velocity_deviation_std",
                                                                "ci_lower"))
        row["velocity_deviation_std_ci_upper"] = _number(p.stat("velocity_deviation_std",
                                                                "ci_upper"))
        for level in VELOCITY_DEVIATION_LEVELS:
            row[f"velocity_deviation_quantile_{level:g}"] = _number(
                _quantile(ds, "velocity_deviation_quantile", level))
        median = "time_to_contact_quantile_0.5"
        row["time_to_contact_median_s"] = _number(p.stat(median))
        row["time_to_contact_median_ci_lower_s"] = _number(p.stat(median, "ci_lower"))
        row["time_to_contact_median_ci_upper_s"] = _number(p.stat(median, "ci_upper"))
        row["travel_to_contact_median_m"] = _number(
            _quantile(ds, "travel_to_contact_quantile", 0.5))
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


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Series:
    """One curve of a figure: the points along the x axis at fixed values of the other keys.

    Attributes
    ----------
    label : str
        The other keys' values ('' for a single curve).
    x : numpy.ndarray
        The first key's values (outer) or the point numbers (zip).
    points : tuple of int
        0-based point indices along the curve.
    """

    label: str
    x: np.ndarray
    points: tuple


def series_of(layout: Sweep) -> list:
    """The curves of the sweep's figures (:class:`Series`): an outer sweep has the first
    key on the x axis and one curve per combination of the other keys' values; a zip sweep
    one curve over the point numbers."""
    if layout.mode == "zip":
        return [Series("", np.arange(1, layout.size + 1, dtype=float),
                       tuple(range(layout.size)))]
    first = layout.axes[0]
    others = layout.axes[1:]
    out = []
    for rest in np.ndindex(*layout.shape[1:]):
        points = tuple(int(np.ravel_multi_index((i, *rest), layout.shape))
                       for i in range(layout.shape[0]))
        if len(others) == 1:  # the legend's title names the key
            label = f"{_value_text(others[0].values[rest[0]])}{_unit_text(others[0].units)}"
        else:
            label = ", ".join(f"{key.key} = {_value_text(key.values[j])}"
                              f"{_unit_text(key.units)}"
                              for key, j in zip(others, rest, strict=True))
        out.append(Series(label, np.asarray(first.values, dtype=float), points))
    return out


def _log_axis(x) -> bool:
    """A log x axis for values spaced evenly in log (0.025, 0.05, 0.1, ...), not in line."""
    x = np.asarray(x, dtype=float)
    if x.size < 3 or np.any(x <= 0) or x.max() / x.min() < 8:
        return False
    order = np.sort(x)
    lin, log = np.diff(order), np.diff(np.log(order))
    return bool(np.std(log) / np.mean(log) < np.std(lin) / np.mean(lin))


def _x_axis(ax, layout: Sweep, series):
    """Label and scale the x axis: the first key (outer) or the point number (zip)."""
    if layout.mode == "zip":
        x = series[0].x
        if x.size <= 12 and len(layout.axes) <= 3:  # the keys' values under the numbers
            ax.set_xticks(x, [f"{int(v)}\n" + "\n".join(_value_text(w) for w in
                                                       layout.values_at(int(v) - 1).values())
                              for v in x], fontsize=8)
            names = "\n".join(k.label for k in layout.axes)
            ax.set_xlabel(f"sweep point (zip), with the values of\n{names}", fontsize=9)
        else:
            ax.set_xticks(x if x.size <= 25 else ax.get_xticks())
            ax.set_xlabel("sweep point (zip; the keys' values in the table)")
        return
    first = layout.axes[0]
    x = np.asarray(first.values, dtype=float)
    if _log_axis(x):
        ax.set_xscale("log")
        ax.set_xticks(x, [_value_text(v) for v in x])
        ax.minorticks_off()
    elif x.size <= 12:
        ax.set_xticks(x, [_value_text(v) for v in x])
    ax.set_xlabel(f"swept: {first.label}")


def _style(j):
    return dict(color=RUN_COLOURS[j % len(RUN_COLOURS)],
                ls=RUN_LINESTYLES[(j // len(RUN_COLOURS)) % len(RUN_LINESTYLES)])


def _band_alpha(series) -> float:
    """Opacity of the interval bands: lighter when several curves overlap."""
    return 0.22 if len(series) == 1 else 0.13


def _column(points, getter) -> np.ndarray:
    return np.array([getter(p) for p in points], dtype=float)


def _legend(ax, layout, series, **kwargs):
    if not ax.get_legend_handles_labels()[0]:
        return
    title = None
    if len(series) > 1:
        title = "other keys" if len(layout.axes) > 2 else layout.axes[1].label
    ax.legend(title=title, fontsize=8, title_fontsize=8, framealpha=0.9, **kwargs)


def _probability_scale(values) -> tuple:
    """(scale, unit) of probabilities: ppm when all are below 0.1 %, else %."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return (1e6, "ppm") if v.size and v.max() < 1e-3 else (1e2, "%")


@styled
def plot_contact_probability(layout: Sweep, points):
    """P(contact) with its 95 % interval band against the swept key (module docstring)."""
    fig, ax = new_figure(7.6, 4.6)
    series = series_of(layout)
    one, many = contact_unit(points[0].ds)
    p = _column(points, lambda q: _f(q.ds, "contact_probability"))
    lo = _column(points, lambda q: _f(q.ds, "contact_probability_ci_lower"))
    hi = _column(points, lambda q: _f(q.ds, "contact_probability_ci_upper"))
    blo = _column(points, lambda q: _f(q.ds, "contact_probability_bounds_ci_lower"))
    bhi = _column(points, lambda q: _f(q.ds, "contact_probability_bounds_ci_upper"))
    limits = sorted({x for x in _column(points, lambda q: _f(q.ds, "contact_probability_limit"))
                     if np.isfinite(x) and x > 0})
    unresolved = _any_unresolved(points)
    scale, unit = _probability_scale([*hi, *(bhi if unresolved else []), *limits])
    interval = estimator_label(points[0].ds)
    interval = interval if interval == "Clopper-Pearson" else interval.split(":")[0]
    bounds_label = f"bounds over all {many} (unresolved as no contact / contact), 95 %"
    for j, s in enumerate(series):
        k = list(s.points)
        st = _style(j)
        if unresolved:
            ax.fill_between(s.x, scale * blo[k], scale * bhi[k], color="0.88", lw=0,
                            label=bounds_label, zorder=1)
            bounds_label = None
        ax.fill_between(s.x, scale * lo[k], scale * hi[k], color=st["color"],
                        alpha=_band_alpha(series), lw=0, zorder=2)
        ax.plot(s.x, scale * p[k], marker="o", ms=4.5, lw=1.8, zorder=3,
                label=s.label or f"P(contact), 95 % {interval} band", **st)
    for i, limit in enumerate(limits):
        ax.axhline(scale * limit, color=LIMIT_COLOUR, ls="--", lw=1.6,
                   label=f"spec limit {format_fraction(limit)}" if i == 0 else None, zorder=4)
    _x_axis(ax, layout, series)
    ax.set_ylabel(f"P(contact within the stroke) per {one} [{unit}]")
    ax.set_title(f"P(ball-to-ball contact within the stroke) per {one}, 95 % interval band\n"
                 f"the same sampled {many} at every point (common random numbers)",
                 fontsize=10)
    _legend(ax, layout, series, loc="best")
    return fig


@styled
def plot_velocity_deviation(layout: Sweep, points):
    """(a) std of epsilon with its 95 % interval, (b) its 0.1 %, 50 % and 99.9 % quantiles
    with their 95 % intervals and the spec limit on |epsilon|, against the swept key."""
    fig, (ax_s, ax_q) = new_figure(12.0, 4.4, ncols=2)
    series = series_of(layout)
    std = 100 * _column(points, lambda q: q.stat("velocity_deviation_std"))
    slo = 100 * _column(points, lambda q: q.stat("velocity_deviation_std", "ci_lower"))
    shi = 100 * _column(points, lambda q: q.stat("velocity_deviation_std", "ci_upper"))
    for j, s in enumerate(series):
        k = list(s.points)
        st = _style(j)
        ax_s.fill_between(s.x, slo[k], shi[k], color=st["color"], alpha=_band_alpha(series), lw=0)
        ax_s.plot(s.x, std[k], marker="o", ms=4.5, lw=1.8, label=s.label or None, **st)
    _x_axis(ax_s, layout, series)
    ax_s.set_ylabel("standard deviation of ε [%]")
    ax_s.set_title("(a) scatter of ε with its 95 % interval (delta method over assemblies)",
                   fontsize=10)
    _legend(ax_s, layout, series, loc="best")

    level_styles = {VELOCITY_DEVIATION_LEVELS[0]: ":", VELOCITY_DEVIATION_LEVELS[1]: "-",
                    VELOCITY_DEVIATION_LEVELS[-1]: "--"}
    for j, s in enumerate(series):
        k = list(s.points)
        colour = _style(j)["color"]
        for level, ls in level_styles.items():
            name = f"velocity_deviation_quantile_{level:g}"
            q = 100 * _column(points, lambda pt, n=name: pt.stat(n))
            qlo = 100 * _column(points, lambda pt, n=name: pt.stat(n, "ci_lower"))
            qhi = 100 * _column(points, lambda pt, n=name: pt.stat(n, "ci_upper"))
            ax_q.fill_between(s.x, qlo[k], qhi[k], color=colour, alpha=0.15, lw=0)
            ax_q.plot(s.x, q[k], color=colour, ls=ls, marker="o", ms=3.5, lw=1.5,
                      label=f"{100 * level:g} % quantile" if j == 0 else None)
    limits = sorted({x for x in _column(points, lambda q: _f(q.ds, "velocity_deviation_limit"))
                     if np.isfinite(x) and x > 0})
    for i, limit in enumerate(limits):
        for sign in (-1, 1):
            ax_q.axhline(sign * 100 * limit, color=LIMIT_COLOUR, ls="--", lw=1.4,
                         label=f"spec limit ±{100 * limit:.3g} %" if i == 0 and sign > 0
                         else None)
    _x_axis(ax_q, layout, series)
    ax_q.set_ylabel("quantile of ε [%]")
    ax_q.set_title("(b) tails and median of ε, 95 % intervals (Woodruff)", fontsize=10)
    ax_q.legend(fontsize=8, framealpha=0.9, loc="best")
    return fig


@styled
def plot_friction(layout: Sweep, points):
    """(a) quantiles of the friction increase with its limit, (b) P(increase > limit) with
    its 95 % interval band, against the swept key (a study with ``[contact]``)."""
    fig, (ax_q, ax_p) = new_figure(12.0, 4.4, ncols=2)
    series = series_of(layout)
    one, many = contact_unit(points[0].ds)
    styles = dict(zip(FRICTION_LEVELS, (":", "-", "--"), strict=True))
    for j, s in enumerate(series):
        k = list(s.points)
        colour = _style(j)["color"]
        for level, ls in styles.items():
            q = _column(points, lambda pt, lv=level: pt.friction["quantiles"][lv])
            ax_q.plot(s.x, q[k], color=colour, ls=ls, marker="o", ms=3.5, lw=1.5,
                      label=f"{100 * level:g} % quantile" if j == 0 else None)
    limits = sorted({x for x in _column(points, lambda q: q.friction["limit"])
                     if np.isfinite(x) and x > 0})
    for i, limit in enumerate(limits):
        ax_q.axhline(limit, color=LIMIT_COLOUR, ls="--", lw=1.4,
                     label=f"limit {limit:.3g} N" if i == 0 else None)
    _x_axis(ax_q, layout, series)
    ax_q.set_ylabel(f"friction increase per {one} (worst track) [N]")
    ax_q.set_title("(a) rise of the carriage friction force over its free-rolling baseline",
                   fontsize=10)
    ax_q.legend(fontsize=8, framealpha=0.9, loc="best")

    if limits:
        p = _column(points, lambda q: q.friction["probability"])
        lo = _column(points, lambda q: q.friction["ci_lower"])
        hi = _column(points, lambda q: q.friction["ci_upper"])
        blo = _column(points, lambda q: q.friction["bounds_ci_lower"])
        bhi = _column(points, lambda q: q.friction["bounds_ci_upper"])
        unresolved = any(q.friction["unresolved"] > 0 for q in points)
        scale, unit = _probability_scale([*hi, *(bhi if unresolved else [])])
        bounds_label = f"bounds over all {many}, 95 %"
        for j, s in enumerate(series):
            k = list(s.points)
            st = _style(j)
            if unresolved:
                ax_p.fill_between(s.x, scale * np.fmin(blo[k], lo[k]),
                                  scale * np.fmax(bhi[k], hi[k]), color="0.88", lw=0,
                                  label=bounds_label)
                bounds_label = None
            ax_p.fill_between(s.x, scale * lo[k], scale * hi[k], color=st["color"],
                              alpha=_band_alpha(series), lw=0)
            ax_p.plot(s.x, scale * p[k], marker="o", ms=4.5, lw=1.8, label=s.label or None,
                      **st)
        ax_p.set_ylabel(f"P(friction increase > limit) per {one} [{unit}]")
        ax_p.set_title("(b) exceedance of the friction limit, 95 % Clopper-Pearson",
                       fontsize=10)
        _legend(ax_p, layout, series, loc="best")
    else:
        ax_p.text(0.5, 0.5, "no limit on the friction increase in the config\n"
                  "([contact] friction_increase_limit_N): no exceedance probability",
                  ha="center", va="center", transform=ax_p.transAxes, fontsize=9)
        ax_p.set_axis_off()
    _x_axis(ax_p, layout, series)
    return fig


#: Figure name -> (plotting function, caption, needs [contact]).
FIGURES = {
    "contact_probability": (
        plot_contact_probability,
        "P(ball-to-ball contact within the stroke) at every point with its 95 % "
        "Clopper-Pearson interval (band), the partial-identification bounds over all "
        "assemblies where some are unresolved (grey), and the spec limit (dashed).", False),
    "velocity_deviation": (
        plot_velocity_deviation,
        "(a) The standard deviation of ε with its 95 % interval; (b) the 0.1 %, 50 % and "
        "99.9 % quantiles of ε with their 95 % intervals and the spec limit on |ε|.", False),
    "friction": (
        plot_friction,
        "(a) Quantiles of the friction increase (worst track of an assembly) with its limit; "
        "(b) P(friction increase > limit) with its 95 % interval.", True),
}


# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------
EXTRA_CSS = """
td.status { white-space: nowrap; } td .ci { color: #666; font-size: 0.88em; }
td.lines { white-space: pre-line; }
"""


def _esc(text) -> str:
    return html.escape(str(text))


def _status_cell(check, below="") -> str:
    """A table cell with a check's (or a verdict's) status, its reason on hover and the
    text ``below`` under it."""
    cls = {PASS: "status-pass", FAIL: "status-fail",
           UNDECIDED: "status-undecided"}.get(check.status, "status-none")
    reason = getattr(check, "reason", "")
    title = f" title='{_esc(reason)}'" if reason else ""
    below = f"<br><span class='ci'>{_esc(below)}</span>" if below else ""
    return (f"<td class='status'{title}><span class='{cls}'>"
            f"{_esc(STATUS_LABELS.get(check.status, check.status))}</span>{below}</td>")


def _judged(points) -> list:
    """Indices of the verdict's checks that have a limit at some point."""
    width = max(len(p.verdict.checks) for p in points)
    return [c for c in range(width) if any(
        c < len(p.verdict.checks) and p.verdict.checks[c].status != NO_LIMIT for p in points)]


def _ranges(numbers) -> str:
    """'1-3, 5' of sorted point numbers."""
    out, start = [], None
    for i, n in enumerate(numbers):
        if start is None:
            start = n
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            out.append(f"{start}" if start == n else f"{start}–{n}")
            start = None
    return ", ".join(out)


def _check_title(c, points) -> str:
    """'P(contact) ≤ 70 %', 'fraction of balls with |ε| > 0.5 % ≤ 200 ppm': check ``c``
    with its requirement (the name alone when the requirement varies between points)."""
    checks = [p.verdict.checks[c] for p in points
              if c < len(p.verdict.checks) and p.verdict.checks[c].status != NO_LIMIT]
    requirements = {ch.requirement for ch in checks}
    if len(requirements) != 1:
        return f"{CHECK_NAMES[c]} (its limit varies between the points)"
    requirement = next(iter(requirements))
    if requirement.startswith(("≤", "≥")):
        return f"{checks[0].quantity} {requirement}"
    return requirement


def verdict_summary(points) -> list:
    """One sentence per judged check and one overall: at which points it passes, is
    undecided, fails ([] when the config sets no spec limit)."""
    lines = []
    for c in _judged(points):
        lines.append(f"{_check_title(c, points)}: " + _status_counts(
            [(p.number, p.verdict.checks[c].status) for p in points
             if c < len(p.verdict.checks)]) + ".")
    if lines:
        lines.append("All spec limits together: " + _status_counts(
            [(p.number, p.verdict.status) for p in points]) + ".")
    return lines


def _status_counts(pairs) -> str:
    parts = []
    for status in (*STATUS_ORDER, NO_LIMIT):
        numbers = [n for n, s in pairs if s == status]
        if numbers:
            label = STATUS_LABELS[status] if status != NO_LIMIT else "no limit"
            parts.append(f"{label} at {len(numbers)} point{'s' if len(numbers) > 1 else ''} "
                         f"({_ranges(numbers)})")
    return "; ".join(parts)


def headline(layout: Sweep, points) -> list:
    """The key sentences at the top: how far P(contact) moves over the sweep."""
    one, _ = contact_unit(points[0].ds)
    p = _column(points, lambda q: _f(q.ds, "contact_probability"))
    out = []
    if np.any(np.isfinite(p)):
        lo, hi = int(np.nanargmin(p)), int(np.nanargmax(p))

        def at(k):
            ds = points[k].ds
            text = format_fraction(p[k], _f(ds, "contact_probability_ci_lower"),
                                   _f(ds, "contact_probability_ci_upper"))
            return f"{text} at point {points[k].number} ({layout.describe(k, units=True)})"

        out.append(f"Over the {layout.size} points, P(ball-to-ball contact within the stroke) "
                   f"per {one} ranges from {at(lo)} to {at(hi)}.")
        if layout.mode == "outer" and len(layout.axes) == 1 and layout.size > 1:
            out.append(f"At the first value of {layout.axes[0].key} it is "
                       f"{format_fraction(p[0])}, at the last {format_fraction(p[-1])}.")
    if _any_unresolved(points):
        numbers = [q.number for q in points if _i(q.ds, "n_assemblies_unresolved") > 0]
        out.append(f"Points {_ranges(numbers)} have unresolved {contact_unit(points[0].ds)[1]}"
                   ": there P(contact) is known only within its bounds (table, grey band).")
    return out


def _keys_table(layout: Sweep) -> ReportTable:
    rows = tuple((key.key, key.name, key.units, ", ".join(_value_text(v) for v in key.values),
                  str(len(key.values))) for key in layout.axes)
    return ReportTable("Swept keys", ("config key", "coordinate in the file", "units",
                                      "values", "count"), rows, (0.3, 0.25, 0.1, 0.25, 0.1),
                       numeric=(4,))


def _facts_rows(points) -> list:
    """study_facts of every point: one value where the points agree, else the span."""
    per_point = [study_facts(p.ds) for p in points]
    rows = []
    for j, (label, value, numeric) in enumerate(per_point[0]):
        values = [str(facts[j][1]) for facts in per_point]
        if len(set(values)) == 1:
            rows.append((label, value, numeric))
        else:
            rows.append((label, f"per point: {', '.join(values)}", False))
    return rows


def _row(label, value, num=True) -> str:
    cls = " class='num'" if num else ""
    return f"<tr><th>{_esc(label)}</th><td{cls}>{_esc(value)}</td></tr>"


def _tolerance_rows(ds):
    """The sampled inputs of the sweep's config as written (its base values)."""
    from tolsim.reports.assumptions import config_of, tolerance_table

    try:
        config = config_of(ds)
    except Exception:  # noqa: BLE001 - the report must not fail on an old config
        config = None
    return tolerance_table(config, ds)


def _points_table(layout: Sweep, points) -> list:
    """HTML of the table per point."""
    one, many = contact_unit(points[0].ds)
    unresolved = _any_unresolved(points)
    friction = any(p.friction is not None for p in points)
    judged = bool(_judged(points))
    header = ["point", *(k.label for k in layout.axes), f"P(contact) per {one} (95 % CI)",
              f"contacts / {many} with a known outcome"]
    if unresolved:
        header.append(f"unresolved {many}: bounds over all (95 %)")
    header += ["ε std (95 % CI)", "median first contact, given contact (95 % CI)"]
    if friction:
        header += ["P(friction increase > limit) (95 % CI)",
                   f"friction increase, {100 * FRICTION_LEVELS[-1]:g} % quantile"]
    if judged:
        header.append("verdict")
    parts = ["<table><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in header) + "</tr>"]
    for p in points:
        ds = p.ds
        n_asm, u = _i(ds, "n_assemblies"), _i(ds, "n_assemblies_unresolved")
        cells = [f"<td class='num'>{p.number}</td>"]
        cells += [f"<td class='num'>{_value_text(v)}</td>" for v in p.values]
        contact = format_fraction(*(_f(ds, n) for n in (
            "contact_probability", "contact_probability_ci_lower",
            "contact_probability_ci_upper")))
        cells.append(f"<td class='num'>{_esc(contact)}</td>")
        cells.append(f"<td class='num'>{_i(ds, 'n_contact'):,} / {n_asm - u:,}</td>")
        if unresolved:
            if u:
                b = [format_fraction(_f(ds, f"contact_probability_{end}")) for end in (
                    "bound_lower", "bound_upper", "bounds_ci_lower", "bounds_ci_upper")]
                cells.append(f"<td class='num'>{u:,}: {_esc(b[0])} to {_esc(b[1])}<br>"
                             f"<span class='ci'>95 % {_esc(b[2])} to {_esc(b[3])}</span></td>")
            else:
                cells.append("<td class='num'>0</td>")
        std, slo, shi = (p.stat("velocity_deviation_std", w)
                         for w in ("estimate", "ci_lower", "ci_upper"))
        cells.append(f"<td class='num'>{_percent(std)}<br><span class='ci'>"
                     f"{_percent(slo)} to {_percent(shi)}</span></td>")
        t, tlo, thi = (p.stat("time_to_contact_quantile_0.5", w)
                       for w in ("estimate", "ci_lower", "ci_upper"))
        if _i(ds, "n_contact") and np.isfinite(t):
            travel = 1e3 * _quantile(ds, "travel_to_contact_quantile", 0.5)
            cells.append(f"<td class='num'>{t:.4g} s ({travel:.4g} mm)<br><span class='ci'>"
                         f"{_sig(tlo)} to {_sig(thi)} s</span></td>")
        elif _i(ds, "n_contact"):  # contacts without a first-contact time (none recorded)
            cells.append("<td class='num'>n/a</td>")
        else:
            cells.append("<td class='num'>no contact</td>")
        if friction:
            fr = p.friction
            if fr is None:
                cells += ["<td>–</td>", "<td>–</td>"]
            else:
                fp = (format_fraction(fr["probability"], fr["ci_lower"], fr["ci_upper"])
                      if np.isfinite(fr["limit"]) and fr["limit"] > 0 else "no limit")
                cells.append(f"<td class='num'>{_esc(fp)}</td>")
                cells.append(f"<td class='num'>{_sig(fr['quantiles'][FRICTION_LEVELS[-1]])} N"
                             "</td>")
        if judged:
            cells.append(_status_cell(p.verdict))
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table>")
    return parts


def _percent(x) -> str:
    return f"{100 * x:.4f} %" if np.isfinite(x) else "n/a"


def _sig(x, digits=4) -> str:
    return f"{x:.{digits}g}" if np.isfinite(x) else "n/a"


def _verdict_table(layout: Sweep, points) -> list:
    """HTML of the verdict per point: each judged check and the overall status."""
    judged = _judged(points)
    header = ["point", *(k.label for k in layout.axes)]
    header += [_check_title(c, points) for c in judged]
    header.append("all limits")
    parts = ["<table><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in header) + "</tr>"]
    for p in points:
        cells = [f"<td class='num'>{p.number}</td>"]
        cells += [f"<td class='num'>{_value_text(v)}</td>" for v in p.values]
        for c in judged:
            check = p.verdict.checks[c]
            cells.append(_status_cell(check, check.estimate))
        cells.append(_status_cell(p.verdict))
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table><p class='muted'>Each point judged as the single study it is "
                 "(tolsim.reports.verdict, as in the report of a study): pass when the whole "
                 "95 % interval meets the limit, fail when it violates it, undecided when it "
                 "straddles it. Hover over a status for the reason.</p>")
    return parts


def _crn_text(ds, points) -> str:
    a = ds.attrs
    seeds = {str(_point_attr(p.ds, "seed")) for p in points}
    n = {_i(p.ds, "n_assemblies") for p in points}
    sizes = ", ".join(f"{v:,}" for v in sorted(n))
    if len(seeds) == 1:
        crn = (f"Every point ran with the same seed ({next(iter(seeds))}), block size "
               f"({a.get('block_size', '?')}) and sampling ({a.get('sampling', '?')}): "
               "assembly i of one point has the random numbers of assembly i of every other "
               "point (<b>common random numbers</b>, <code>tolsim.study.design.sweep</code>). Only "
               "the mapping of those numbers to values (a scaled spread, a shifted load) "
               "changes with the key, so the curves are smooth and a <i>difference</i> "
               "between two points carries far less noise than the two intervals suggest: "
               "each interval shown is the point's own (marginal) interval, not that of a "
               "difference. This holds when the swept key leaves the structure of the draws "
               "alone; a key that changes which variates are drawn gives independent streams "
               "in effect.")
    else:
        crn = ("The points ran with different seeds: their random numbers are independent, "
               "and the intervals of two points are those of independent runs.")
    return f"{crn} Assemblies per point: {sizes}."


def _point_attr(ds, name):
    return ds.attrs.get(name, "?")


def _html(ds, path, layout: Sweep, points, pngs: dict) -> str:
    a = ds.attrs
    one, many = contact_unit(points[0].ds)
    title = str(a.get("title", "tolsim sweep"))
    mode = ("outer: every combination of the keys' values, the first key slowest"
            if layout.mode == "outer" else
            "zip: the i-th values of all keys together, one point each")
    lines = headline(layout, points)
    summary = verdict_summary(points)
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{_esc(title)}</title><style>{CSS}{EXTRA_CSS}</style></head><body>",
        f"<h1>{_esc(title)}</h1>",
        f"<p class='muted'>Sweep report of <code>{_esc(os.path.basename(path))}</code>, made by "
        f"tolsim {__version__} on {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}. The "
        f"table per point as CSV: <code>{CSV_NAME}</code>; the figures as PNG beside this "
        "page. A sweep has no PDF: the sign-off report is that of a single study.</p>",
        "<div class='verdict-box' id='verdict'>",
        f"<p class='verdict-label'>{layout.size} points: "
        + (_esc(summary[-1].removeprefix("All spec limits together: ").rstrip("."))
           if summary else "no spec limit given") + "</p>",
        *(f"<p>{_esc(s)}</p>" for s in lines),
        *(f"<p>{_esc(s)}</p>" for s in summary[:-1]),
        "</div>",
    ]
    section = iter(range(1, 20))
    parts += [f"<h2 id='swept'>{next(section)}. What was swept</h2>",
              *_table_html(_keys_table(layout)),
              f"<p>Mode {_esc(mode)}: {layout.size} points"
              + (f" ({' × '.join(str(n) for n in layout.shape)})"
                 if len(layout.shape) > 1 else "")
              + f". Dimensions in the file: <code>{_esc(' '.join(layout.dimensions))}</code>; "
              "each variable has them in front (<code>ds.contact_probability.plot()</code> "
              "draws the curve).</p>",
              f"<p>{_crn_text(ds, points)}</p>",
              "<h3>The study at every point</h3><table>",
              *(_row(label, value, num) for label, value, num in _facts_rows(points)),
              "</table>"]
    tolerances = _tolerance_rows(points[0].ds)
    if tolerances:
        parts += ["<h3>Sampled inputs (as in the config; a swept key takes the values above)"
                  "</h3><table><tr><th>input</th><th>scope</th><th>distribution</th>"
                  "<th>parameters</th><th>config</th></tr>"]
        parts += [f"<tr><td>{_esc(r.source)}</td><td>{_esc(r.scope)}</td>"
                  f"<td>{_esc(r.distribution)}</td><td>{_esc(r.parameters)}</td>"
                  f"<td><code>{_esc(r.key)}</code></td></tr>" for r in tolerances]
        parts.append("</table>")
    parts += ["<details><summary>The sweep's config (TOML, as stored in the file: rerun it "
              "with <code>tolsim run</code>)</summary>",
              f"<pre>{_esc(a.get('config', ''))}</pre></details>"]

    def fig(name):
        if name in pngs:
            caption = FIGURES[name][1]
            parts.append(f"<figure><img alt='{_esc(caption)}' src='{data_uri(pngs[name])}'>"
                         f"<figcaption class='muted'>{_esc(caption)}</figcaption></figure>")

    parts.append(f"<h2 id='contact'>{next(section)}. Ball-to-ball contact against the swept "
                 "key" + ("s" if len(layout.axes) > 1 else "") + "</h2>")
    fig("contact_probability")
    parts.append("<h3 id='points'>Per point</h3>")
    parts += _points_table(layout, points)
    parts.append(f"<p class='muted'>P(contact) over the {many} whose outcome is known, "
                 f"95 % {_esc(estimator_label(points[0].ds))}"
                 + (f"; with unresolved {many}, the bounds count them as no contact / contact "
                    "(the interval covers both)" if _any_unresolved(points) else "")
                 + ". ε std: delta method over assemblies, t(A − 1). Median first contact "
                 "(time since the start of the stroke, travel in brackets): Woodruff's "
                 "interval on the histogram of the first-contact times. Fractions below "
                 "0.1 % in ppm.</p>")
    if _judged(points):
        parts.append(f"<h2 id='verdicts'>{next(section)}. Verdict per point</h2>")
        parts += _verdict_table(layout, points)
    parts.append(f"<h2 id='velocity-deviation'>{next(section)}. Ball velocity deviation ε"
                 "</h2>")
    fig("velocity_deviation")
    if "friction" in pngs:
        parts.append(f"<h2 id='friction'>{next(section)}. What contact costs: carriage "
                     "friction after the balls touch</h2>")
        fig("friction")
    parts += _checks_table(layout, points, next(section))
    parts.append("<h2>Provenance</h2><table>")
    for key in ("Conventions", "source", "history", "seed", "references",
                "contact_probability_interval", "elapsed_seconds", "workers"):
        if key in a:
            parts.append(f"<tr><th>{_esc(key)}</th><td class='lines'>{_esc(a[key])}</td></tr>")
    parts.append("</table></body></html>")
    return "\n".join(parts)


def _checks_table(layout, points, number) -> list:
    """The model checks per point: balls re-solved with the full model, unresolved balls,
    spot checks."""
    rows = []
    for p in points:
        ds = p.ds
        rows.append((str(p.number), *(_value_text(v) for v in p.values),
                     f"{_i(ds, 'n_balls_resolved_full'):,} of "
                     f"{_i(ds, 'n_balls_outside_validity'):,}",
                     f"{_i(ds, 'n_balls_not_converged')} / {_i(ds, 'n_balls_loss_of_contact')}"
                     f" / {_i(ds, 'n_balls_full_failed')}",
                     f"{_i(ds, 'spot_check_n_valid')} of {ds.sizes.get('spot_check', 0)}",
                     _percent(_f(ds, "spot_check_rms_difference")),
                     _percent(_f(ds, "spot_check_max_abs_difference"))))
    model = str(points[0].ds.attrs.get("velocity_model", "?"))
    table = ReportTable(
        f"{number}. Model checks per point", (
            "point", *(k.label for k in layout.axes),
            f"balls outside the {model} model's validity, re-solved with the full model",
            "unresolved balls (not converged / loss of contact / full model failed)",
            "spot checks valid in both models", "RMS ε difference", "largest |ε difference|"),
        tuple(rows), (), "Spot checks: balls re-solved with the full friction model, half of "
        "them near the spec limit on |ε| (as in the study report's model check).",
        tuple(range(len(rows[0]))) if rows else ())
    html_parts = _table_html(table)
    html_parts[0] = html_parts[0].replace("<h3>", "<h2 id='checks'>", 1).replace(
        "</h3>", "</h2>", 1)
    return html_parts


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------
@dataclass
class SweepReportOutputs:
    """Files written by :func:`make_sweep_report` and the points shown."""

    folder: str
    html: str = ""
    csv: str = ""
    figures: dict = field(default_factory=dict)
    layout: Sweep | None = None
    points: list = field(default_factory=list)


def make_sweep_report(path, folder, *, progress=None) -> SweepReportOutputs:
    """Write ``report.html``, ``points.csv`` and the PNGs of a sweep file into ``folder``.

    Every output is made in memory before anything is written (module docstring).

    Parameters
    ----------
    path : str or path
        A result file of ``tolsim run`` on a config with ``[sweep]``.
    folder : str or path
        Output folder (created if missing).
    progress : callable, optional
        Called with a short message before each step.

    Returns
    -------
    SweepReportOutputs

    Raises
    ------
    tolsim.reports.study.NotAResult
        If ``path`` is not a tolsim result.
    NotASweep
        If it is the result of a single study (:func:`tolsim.reports.study.make_report`).
    """
    say = progress or (lambda msg: None)
    ds = read_result_file(path)
    layout = sweep_layout(ds)
    say(f"{layout.size} sweep points")
    points = sweep_points(ds, layout)
    say("figures")
    pngs = {name: render_png(plot(layout, points))
            for name, (plot, _, friction) in FIGURES.items()
            if not friction or any(p.friction is not None for p in points)}
    say(f"{HTML_NAME} and {CSV_NAME}")
    files = {HTML_NAME: _html(ds, os.fspath(path), layout, points, pngs).encode("utf-8"),
             CSV_NAME: csv_text(layout, points).encode("utf-8"),
             **{f"{name}.png": png for name, png in pngs.items()}}
    written = _write_files(os.fspath(folder), files)
    return SweepReportOutputs(os.fspath(folder), written[HTML_NAME], written[CSV_NAME],
                              {name: written[f"{name}.png"] for name in pngs}, layout, points)
