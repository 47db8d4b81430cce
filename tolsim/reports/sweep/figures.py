"""The figures of the sweep report: P(contact), epsilon and the friction increase against
the swept key."""

from dataclasses import dataclass

import numpy as np

from tolsim.reports.compare import RUN_COLOURS, RUN_LINESTYLES
from tolsim.reports.result_view import number
from tolsim.reports.style import LIMIT_COLOUR, new_figure, styled
from tolsim.reports.sweep.points import (
    FRICTION_LEVELS,
    VELOCITY_DEVIATION_LEVELS,
    any_unresolved,
    unit_text,
    value_text,
)
from tolsim.reports.verdict import (
    contact_unit,
    estimator_label,
)
from tolsim.study.design.sweep import Sweep
from tolsim.study.statistics.intervals import format_fraction


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
            label = f"{value_text(others[0].values[rest[0]])}{unit_text(others[0].units)}"
        else:
            label = ", ".join(f"{key.key} = {value_text(key.values[j])}"
                              f"{unit_text(key.units)}"
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
            ax.set_xticks(x, [f"{int(v)}\n" + "\n".join(value_text(w) for w in
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
        ax.set_xticks(x, [value_text(v) for v in x])
        ax.minorticks_off()
    elif x.size <= 12:
        ax.set_xticks(x, [value_text(v) for v in x])
    ax.set_xlabel(f"swept: {first.label}")


def _style(j):
    return dict(color=RUN_COLOURS[j % len(RUN_COLOURS)],
                ls=RUN_LINESTYLES[(j // len(RUN_COLOURS)) % len(RUN_LINESTYLES)])


def _band_alpha(series) -> float:
    """Opacity of the interval bands: lighter when several curves overlap."""
    return 0.22 if len(series) == 1 else 0.13


def point_column(points, getter) -> np.ndarray:
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
    p = point_column(points, lambda q: number(q.ds, "contact_probability"))
    lo = point_column(points, lambda q: number(q.ds, "contact_probability_ci_lower"))
    hi = point_column(points, lambda q: number(q.ds, "contact_probability_ci_upper"))
    blo = point_column(points, lambda q: number(q.ds, "contact_probability_bounds_ci_lower"))
    bhi = point_column(points, lambda q: number(q.ds, "contact_probability_bounds_ci_upper"))
    limits = sorted({x for x in point_column(
                        points, lambda q: number(q.ds, "contact_probability_limit"))
                     if np.isfinite(x) and x > 0})
    unresolved = any_unresolved(points)
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
    std = 100 * point_column(points, lambda q: q.stat("velocity_deviation_std"))
    slo = 100 * point_column(points, lambda q: q.stat("velocity_deviation_std", "ci_lower"))
    shi = 100 * point_column(points, lambda q: q.stat("velocity_deviation_std", "ci_upper"))
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
            q = 100 * point_column(points, lambda pt, n=name: pt.stat(n))
            qlo = 100 * point_column(points, lambda pt, n=name: pt.stat(n, "ci_lower"))
            qhi = 100 * point_column(points, lambda pt, n=name: pt.stat(n, "ci_upper"))
            ax_q.fill_between(s.x, qlo[k], qhi[k], color=colour, alpha=0.15, lw=0)
            ax_q.plot(s.x, q[k], color=colour, ls=ls, marker="o", ms=3.5, lw=1.5,
                      label=f"{100 * level:g} % quantile" if j == 0 else None)
    limits = sorted({x for x in point_column(
                        points, lambda q: number(q.ds, "velocity_deviation_limit"))
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
            q = point_column(points, lambda pt, lv=level: pt.friction["quantiles"][lv])
            ax_q.plot(s.x, q[k], color=colour, ls=ls, marker="o", ms=3.5, lw=1.5,
                      label=f"{100 * level:g} % quantile" if j == 0 else None)
    limits = sorted({x for x in point_column(points, lambda q: q.friction["limit"])
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
        p = point_column(points, lambda q: q.friction["probability"])
        lo = point_column(points, lambda q: q.friction["ci_lower"])
        hi = point_column(points, lambda q: q.friction["ci_upper"])
        blo = point_column(points, lambda q: q.friction["bounds_ci_lower"])
        bhi = point_column(points, lambda q: q.friction["bounds_ci_upper"])
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
