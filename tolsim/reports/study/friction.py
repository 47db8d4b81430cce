"""The section "What contact costs" of a study with ``[contact]`` (HTML and PDF share it):
its figure, tables and headline sentence."""


import numpy as np
from matplotlib import colormaps
from matplotlib.ticker import LogFormatterSciNotation, LogLocator, NullFormatter

from tolsim.reports.result_view import (
    bin_edges,
    integer,
    number,
    quantile_value,
)
from tolsim.reports.study.sections import ReportTable, section_titles, significant
from tolsim.reports.study.sensitivity import (
    FileSensitivity,
    error_bar_lengths,
    not_estimable,
)
from tolsim.reports.style import (
    LIMIT_COLOUR,
    SERIES_COLOURS,
    new_canvas,
    styled,
)
from tolsim.reports.verdict import (
    contact_unit,
    counted,
    estimator_label,
    tracks_of,
)
from tolsim.study.statistics.quality import format_fraction

# --------------------------------------------------------------------------------------------
# Friction after contact (a study with [contact]: HTML and PDF share this section)
# --------------------------------------------------------------------------------------------
#: Output name of the friction increase among the Sobol' outputs
#: (:data:`tolsim.study.analyses.sensitivity.FRICTION_INCREASE`).
FRICTION_OUTPUT = "friction_increase"
#: Quantile levels of the friction table.
FRICTION_LEVELS = (0.5, 0.9, 0.95, 0.99, 0.999)
#: The force histograms of the friction section: variable prefix -> (label, line style).
FRICTION_HISTOGRAMS = {
    "friction_increase": ("increase of the friction force over its baseline", "-"),
    "friction_ripple": ("ripple of the friction force (max − min over the stroke)", ":"),
    "contact_force_max": ("largest ball-to-ball force Q_max", "--"),
}


def _readable_log_ticks(axis, decades):
    """Labels a log axis spanning ``decades`` at 1, 2 and 5 per decade up to three decades (at
    the decades beyond), and no minor labels: matplotlib's default labels the minor ticks of
    a short axis, whose wide 2x10^-3 labels overlap."""
    subs = (1.0, 2.0, 5.0) if decades <= 3.0 else (1.0,)
    axis.set_major_locator(LogLocator(base=10.0, subs=subs))
    axis.set_major_formatter(LogFormatterSciNotation(labelOnlyBase=False))
    axis.set_minor_formatter(NullFormatter())

def without_output(sens, output=FRICTION_OUTPUT):
    """``sens`` without one of its outputs (the same object when it does not have it): the
    section "What drives the risk" ranks epsilon and contact, the friction section its own
    output."""
    outputs = list(getattr(sens, "outputs", ()))
    if sens is None or output not in outputs:
        return sens
    keep = [k for k, name in enumerate(outputs) if name != output]
    return FileSensitivity(tuple(sens.factors), tuple(outputs[k] for k in keep),
                            np.asarray(sens.first_order)[keep], np.asarray(sens.total)[keep],
                            np.asarray(sens.first_order_ci)[keep],
                            np.asarray(sens.total_ci)[keep], n=int(sens.n),
                            evaluations=int(sens.evaluations),
                            confidence_level=float(sens.confidence_level),
                            reasons=tuple(not_estimable(sens, k) for k in keep))


def friction_indices(sens):
    """(first_order, total, first_order_ci, total_ci) of the friction increase, or None."""
    outputs = list(getattr(sens, "outputs", ()))
    if sens is None or FRICTION_OUTPUT not in outputs or not len(sens.factors):
        return None
    k = outputs.index(FRICTION_OUTPUT)
    return (np.asarray(sens.first_order[k], dtype=float), np.asarray(sens.total[k], dtype=float),
            np.asarray(sens.first_order_ci[k], dtype=float),
            np.asarray(sens.total_ci[k], dtype=float))


def _force_text(x, unit=" N"):
    """A force [N] to three significant digits, '0' for an exact zero, 'n/a' for NaN."""
    if not np.isfinite(x):
        return "n/a"
    return ("0" if x == 0 else f"{float(x):.3g}") + unit


def _force_survival(ds, prefix):
    """(x [N], P(X >= x), total) of a friction histogram: the fraction of the resolved
    assemblies at or above each bin edge (the overflow counted above every edge)."""
    counts = np.asarray(ds[f"{prefix}_histogram"], dtype=float)
    edges = bin_edges(ds, "force_bin_bounds")
    under, over = integer(ds, f"{prefix}_underflow"), integer(ds, f"{prefix}_overflow")
    total = counts.sum() + under + over
    above = np.concatenate([np.cumsum(counts[::-1])[::-1], [0.0]]) + over
    return edges, above / max(total, 1.0), total


def ball_diameter_of(ds, config):
    """D [m] from the config, else the smallest centre distance of the examples' balls
    (touching balls are exactly D apart), else NaN."""
    if config is not None:
        return 2.0 * float(config.bearing.ball_radius)
    if "example_ball_position" in ds.variables and ds.sizes.get("ball", 0) > 1:
        z = np.asarray(ds["example_ball_position"], dtype=float)
        return float(np.nanmin(np.diff(z, axis=-1)))
    return np.nan


def _busiest_example(ds) -> int:
    """The example whose track has a ball-to-ball contact over the longest part of the
    stroke (the first on a tie; 0 without contact forces in the file)."""
    if "example_contact_force" not in ds.variables or ds.sizes.get("pair", 0) == 0:
        return 0
    q = np.asarray(ds["example_contact_force"], dtype=float)  # (example, travel, pair)
    return int(np.argmax(np.mean(np.any(q > 0, axis=2), axis=1)))


def _example_label(ds, e):
    one = contact_unit(ds)[0]
    label = f"{one} {int(np.asarray(ds['example_assembly'])[e]):,}"
    if tracks_of(ds):
        label += f", track {int(np.asarray(ds['example_track'])[e])}"
    return label


@styled
def plot_friction(ds, sens=None, ball_diameter=np.nan):
    """What contact costs, four panels: (a) the distribution of the friction increase over
    the assemblies (the fraction at or above each force, log-log) with the spec limit and
    the exceedance probability with its interval, beside the ripple and the largest
    ball-to-ball force; (b) the example traces of the increase against the carriage travel;
    (c) the balls of the first example along the stroke, drawn as in the paper's Fig. 9 so
    that touching balls share a line; (d) the drivers, Sobol' indices of the increase.

    Parameters
    ----------
    ds : xarray.Dataset
        A result file with the friction variables (:data:`tolsim.io.schema.friction.
        FRICTION_VARIABLES`).
    sens : optional
        Sensitivity indices with the output ``friction_increase`` (panel d).
    ball_diameter : float
        D [m], for panel (c) (NaN: panel c draws the centres less their start).
    """
    fig = new_canvas(12.0, 8.6)
    (ax_d, ax_t), (ax_z, ax_s) = fig.subplots(2, 2)
    limit = number(ds, "friction_increase_limit")
    has_limit = np.isfinite(limit) and limit > 0
    one, many = contact_unit(ds)

    # (a) distribution: the fraction of assemblies at or above a force
    top, low = 0.0, np.inf
    floor = 1.0
    curves = {}
    for prefix, (label, ls) in FRICTION_HISTOGRAMS.items():
        if f"{prefix}_histogram" not in ds.variables:
            continue
        x, s, total = _force_survival(ds, prefix)
        if total <= 0:
            continue
        curves[prefix] = s
        if prefix == "friction_ripple" and np.array_equal(s, curves.get("friction_increase")):
            ax_d.plot([], [], color="0.3", ls=ls, lw=1.4,
                      label="ripple (max − min): the same curve here")
            continue
        colour = {"friction_increase": SERIES_COLOURS[0], "friction_ripple": SERIES_COLOURS[4],
                  "contact_force_max": SERIES_COLOURS[2]}[prefix]
        # at each bin's lower edge the fraction at or above it: an upper step within the bin
        ax_d.step(x[1:], s[1:], where="post", color=colour, ls=ls,
                  lw=1.6 if ls == "-" else 1.3, label=label)
        counts = np.asarray(ds[f"{prefix}_histogram"], dtype=float)
        nz = np.flatnonzero(counts[1:] > 0) + 1  # bins with a rise (bin 0: below 1 µN)
        if nz.size:
            low = min(low, x[nz[0]])
            top = max(top, x[nz[-1] + 1])
        floor = min(floor, 0.5 / total)
    resolved = integer(ds, "n_assemblies_friction_resolved")
    p, lo, hi = (number(ds, f"friction_exceedance_probability{s}") for s in ("", "_ci_lower",
                                                                         "_ci_upper"))
    if has_limit:
        ax_d.axvline(limit, color=LIMIT_COLOUR, lw=2.0, ls="--",
                     label=f"spec limit: increase ≤ {limit:.4g} N")
        if np.isfinite(p):
            ax_d.errorbar([limit], [max(p, floor)], yerr=[[max(p - lo, 0.0)], [hi - p]]
                          if p > 0 else None, fmt="o", color=LIMIT_COLOUR, ms=6, capsize=4,
                          label=f"P(increase > {limit:.4g} N) = {format_fraction(p)}\n"
                                f"(95 % CI {format_fraction(lo)} to {format_fraction(hi)})")
        top, low = max(top, limit), min(low, limit)
    if np.isfinite(low) and top > 0:
        ax_d.set_xscale("log")
        ax_d.set_yscale("log")
        ax_d.set_xlim(0.5 * low, 2.0 * top)
        ax_d.set_ylim(0.5 * floor, 1.6)
        _readable_log_ticks(ax_d.xaxis, np.log10(4.0 * top / low))
    zero = curves.get("friction_increase")
    no_rise = 1.0 - zero[1] if zero is not None else np.nan
    ax_d.set_title(f"(a) over the {resolved:,} resolved {many}: "
                   f"{format_fraction(no_rise)} with no rise (< 1 µN)", fontsize=10)
    ax_d.set_xlabel("force [N] (log)")
    ax_d.set_ylabel(f"fraction of {many} at or above [-] (log)")
    ax_d.legend(loc="lower left", fontsize=7.5, framealpha=0.9)

    # (b) example traces of the increase
    if "example_friction_force" in ds.variables:
        travel = 1e3 * np.asarray(ds["travel"], dtype=float)
        force = np.asarray(ds["example_friction_force"], dtype=float)
        base = np.asarray(ds["example_friction_force_baseline"], dtype=float)
        for e in range(force.shape[0]):
            ax_t.plot(travel, force[e] - base[e], color=SERIES_COLOURS[e % 6], lw=1.5,
                      label=f"example {e + 1} ({_example_label(ds, e)}): F₀ = {base[e]:.4g} N")
        if has_limit:
            ax_t.axhline(limit, color=LIMIT_COLOUR, lw=1.5, ls="--", label="spec limit")
        ax_t.axhline(0, color="0.5", lw=0.6)
        reach = max(float(np.nanmax(force - base[:, None], initial=0.0)),
                    limit if has_limit else 0.0)
        ax_t.set_ylim(-0.05 * reach if reach > 0 else -0.1, 1.5 * reach if reach > 0 else 1.0)
        ax_t.set_xlim(travel[0], travel[-1])
        ax_t.legend(loc="upper left", fontsize=7.5, framealpha=0.9)
    else:
        ax_t.text(0.5, 0.5, "no example trajectories in the file\n([contact] examples = 0)",
                  transform=ax_t.transAxes, ha="center", va="center")
    ax_t.set_xlabel("carriage travel [mm]")
    ax_t.set_ylabel("friction force F − F₀ [N]")
    ax_t.set_title("(b) examples: rise of the track's friction force over its baseline F₀",
                   fontsize=10)

    # (c) the balls of one example, as Fig. 9 of the paper draws them
    if "example_ball_position" in ds.variables:
        travel = 1e3 * np.asarray(ds["travel"], dtype=float)
        e = _busiest_example(ds)
        z = np.asarray(ds["example_ball_position"], dtype=float)[e]  # (travel, ball)
        n = z.shape[1]
        if np.isfinite(ball_diameter):
            y = 1e6 * (z - z[0, 0] - ball_diameter * np.arange(n))
            ylabel = "ball centre − v t/2 − (start of ball 1 + i D) [µm]"
            note = "touching balls share a line"
        else:
            y = 1e6 * (z - z[0])
            ylabel = "ball centre − v t/2 − its start [µm]"
            note = "D unknown: each ball from its own start"
        cmap = colormaps["viridis"]
        for i in range(n):
            ax_z.plot(travel, y[:, i], color=cmap(i / max(n - 1, 1)), lw=1.3,
                      label=(f"ball {i + 1}" + (" (trailing)" if i == 0 else
                                               " (leading)" if i == n - 1 else ""))
                      if i in (0, n - 1) else None)
        if "example_contact_force" in ds.variables and n > 1:
            q = np.asarray(ds["example_contact_force"], dtype=float)[e]  # (travel, pair)
            label = "a contact forms (first travel point with a force)"
            for j in range(n - 1):
                hit = np.flatnonzero(q[:, j] > 0)
                if hit.size:
                    ax_z.plot(travel[hit[0]], y[hit[0], j + 1], "o", color=LIMIT_COLOUR, ms=4,
                              zorder=5, label=label)
                    label = None
        ax_z.set_xlim(travel[0], travel[-1])
        low_y, high_y = float(np.nanmin(y)), float(np.nanmax(y))
        span = max(high_y - low_y, 1.0)
        ax_z.set_ylim(low_y - 0.05 * span, high_y + 0.3 * span)  # room for the legend
        ax_z.legend(loc="upper left", fontsize=7.5, framealpha=0.9, ncols=2)
        ax_z.set_ylabel(ylabel, fontsize=8.5)
        ax_z.set_title(f"(c) the {n} balls of example {e + 1} along the stroke ({note})",
                       fontsize=10)
    else:
        ax_z.set_title("(c) ball positions", fontsize=10)
        ax_z.text(0.5, 0.5, "no example trajectories in the file",
                  transform=ax_z.transAxes, ha="center", va="center")
    ax_z.set_xlabel("carriage travel [mm]")

    # (d) drivers
    indices = friction_indices(sens)
    if indices is not None:
        first, total, first_ci, total_ci = indices
        d = len(sens.factors)
        order = np.argsort(np.nan_to_num(total, nan=-1.0))  # largest at the top
        y = np.arange(d)
        for values, ci, shift, colour, label in (
                (total, total_ci, 0.18, SERIES_COLOURS[0], "total effect S_T"),
                (first, first_ci, -0.18, SERIES_COLOURS[4], "first order S")):
            v, c = values[order], ci[order]
            ax_s.barh(y + shift, np.nan_to_num(v), height=0.36, color=colour, label=label)
            err = np.abs(np.stack([v - c[:, 0], c[:, 1] - v]))
            ax_s.errorbar(np.nan_to_num(v), y + shift, xerr=error_bar_lengths(err), fmt="none",
                          ecolor="k", capsize=2, lw=0.8)
        ax_s.set_yticks(y, [sens.factors[i].replace("_", " ") for i in order], fontsize=8)
        ends = np.concatenate([total_ci.ravel(), first_ci.ravel()])
        ends = ends[np.isfinite(ends)]
        ax_s.set_xlim(max(-1.0, min(-0.05, ends.min() - 0.02)) if ends.size else -0.05,
                      min(2.0, max(1.05, ends.max() + 0.02)) if ends.size else 1.05)
        ax_s.axvline(0, color="0.4", lw=0.8)
        ax_s.legend(loc="lower right", fontsize=8)
        if np.all(np.isnan(total)):
            ax_s.text(0.5, 0.5, "the increase does not vary:\nno index",
                      transform=ax_s.transAxes, ha="center", va="center")
    else:
        ax_s.text(0.5, 0.5, "no Sobol' indices of the friction increase",
                  transform=ax_s.transAxes, ha="center", va="center")
        ax_s.set_yticks([])
    ax_s.set_xlabel("Sobol' index [-] (bars: 95 % bootstrap interval)")
    ax_s.set_ylabel("tolerance source")
    ax_s.set_title("(d) drivers: Sobol' indices of the friction increase", fontsize=10)
    whose = (f"the worst track of each {one}" if tracks_of(ds) else f"each {one}")
    fig.suptitle(f"What contact costs: the carriage friction force of {whose} after its balls "
                 f"touch, μ_bb = {number(ds, 'ball_friction_coefficient'):.3g}", fontsize=10.5)
    return fig


def friction_summary(ds) -> str:
    """One sentence on the friction after contact (the headline of a study with
    ``[contact]``)."""
    one = contact_unit(ds)[0]
    per = f"per {one}" + (" (its worst track)" if tracks_of(ds) else "")
    base = number(ds, "friction_force_baseline")
    median, q99 = (quantile_value(ds, "friction_increase_quantile", q) for q in (0.5, 0.99))
    text = (f"Friction after contact {per}: the carriage friction force rises over its "
            f"{significant(base)} N baseline by a median {_force_text(median)}, 99 % quantile "
            f"{_force_text(q99)} (largest {_force_text(number(ds, 'friction_increase_max'))})")
    limit = number(ds, "friction_increase_limit")
    if np.isfinite(limit) and limit > 0:
        p, lo, hi = (number(ds, f"friction_exceedance_probability{s}") for s in (
            "", "_ci_lower", "_ci_upper"))
        text += f"; P(increase > {limit:.4g} N) = {format_fraction(p, lo, hi)}"
    return text + "."


#: Caption of the friction figure (HTML and PDF).
FRICTION_CAPTION = (
    "(a) The fraction of assemblies whose friction force rises by at least a given force over "
    "its free-rolling baseline (the largest rise over the stroke), with the spec limit and "
    "P(increase > limit) with its 95 % interval; the ripple and the largest ball-to-ball "
    "force beside it. (b) The rise against the carriage travel for the stored examples. "
    "(c) The balls of the example with the longest contact along the stroke, each less the "
    "nominal travel v t/2 of a free ball and its place in a touching train, so that touching "
    "balls share a line (as the paper's Fig. 9 draws its two balls). (d) The tolerances that "
    "drive the rise: Sobol' indices of the increase.")


def friction_content(ds, sens=None) -> dict:
    """The section "What contact costs" of a study with ``[contact]`` (HTML and PDF).

    Parameters
    ----------
    ds : xarray.Dataset
        A result file with the friction variables (:data:`tolsim.io.schema.friction.
        FRICTION_VARIABLES`).
    sens : optional
        Sensitivity indices; those of the output ``friction_increase`` rank the drivers.

    Returns
    -------
    dict
        ``heading`` (str), ``paragraphs`` (list of str), ``tables`` (list of
        :class:`ReportTable`: the figures at a glance, their distribution over the
        assemblies, the drivers), ``figure_after`` (index of the table the figure follows)
        and ``notes`` (list of str, below the tables).
    """
    one, many = contact_unit(ds)
    tracks = tracks_of(ds)
    n_asm = integer(ds, "n_assemblies")
    resolved = integer(ds, "n_assemblies_friction_resolved")
    unresolved = integer(ds, "n_assemblies_friction_unresolved")
    sliding = integer(ds, "n_assemblies_sliding")
    released = integer(ds, "n_assemblies_released", None)
    exceed = integer(ds, "n_friction_exceedance")
    travel = 1e3 * number(ds, "horizon") * number(ds, "groove_velocity")
    mu_bb = number(ds, "ball_friction_coefficient")
    limit = number(ds, "friction_increase_limit")
    has_limit = np.isfinite(limit) and limit > 0
    worst = (f"the worst of its {counted(tracks, 'track')} (the one whose friction force "
             "rises most)" if tracks else "its track")
    paragraphs = [
        f"For every sampled {one} the study follows "
        + ("each of its trains" if tracks else "its balls")
        + f" over the {travel:.4g} mm stroke after the balls touch (tolsim's extension of the "
        "paper, which stops at the first contact). Balls in contact move together as a "
        "cluster and push each other with forces set by their creep stiffness; the Coulomb "
        f"friction at each ball-to-ball contact (μ_bb = {mu_bb:.3g}) brakes both balls, and "
        "the grooves pay for it in carriage friction. The model and its sources are in the "
        "assumptions table (topic \"after contact\").",
        ("Each assembly counts with " + worst if tracks else "Each train counts with its "
         "own friction force") + ": its free-rolling baseline F₀ (the friction force "
        "without ball-to-ball contact, from spin and differential slip), the increase (the "
        "largest rise of its friction force over F₀ during the stroke), the ripple (max − min "
        "over the stroke), the largest ball-to-ball force and the fraction of the stroke with "
        f"a contact. The statistics are over the {resolved:,} {many} whose balls were "
        f"followed over the whole stroke; P(increase > limit) is bounded over all {n_asm:,}.",
    ]
    p, lo, hi = (number(ds, f"friction_exceedance_probability{s}") for s in ("", "_ci_lower",
                                                                         "_ci_upper"))
    rows = [("ball-to-ball friction coefficient μ_bb", f"{mu_bb:.4g}",
             "config ([contact] ball_friction_coefficient)"),
            ("creep model (K, F₀ of each ball)", str(ds.attrs.get("contact_creep_model", "?")),
             "config ([contact] creep_model)"),
            ("free-rolling baseline F₀ of the track: mean ± std",
             f"{significant(number(ds, 'friction_force_baseline'))} N ± "
             f"{_force_text(number(ds, 'friction_force_baseline_std'))}",
             "friction_force_baseline"),
            ("increase over F₀: mean / median / 99 %",
             f"{_force_text(number(ds, 'friction_increase_mean'))} / "
             f"{_force_text(quantile_value(ds, 'friction_increase_quantile', 0.5))} / "
             f"{_force_text(quantile_value(ds, 'friction_increase_quantile', 0.99))}",
             "friction_increase_mean, _quantile"),
            (f"largest increase of any {one}", _force_text(number(ds, "friction_increase_max")),
             "friction_increase_max"),
            ("spec limit on the increase",
             f"{limit:.4g} N" if has_limit else "no spec limit given",
             "config ([contact] friction_increase_limit_N)")]
    if has_limit:
        rows.append((f"P(increase > {limit:.4g} N) per {one}",
                     f"{format_fraction(p, lo, hi)} ({exceed:,} of {n_asm - unresolved:,} "
                     f"{many} whose outcome is known; "
                     f"{estimator_label(ds, 'friction_exceedance_probability')})",
                     "friction_exceedance_probability, _ci_lower, _ci_upper"))
        if unresolved:
            bounds = (format_fraction(number(ds, f"friction_exceedance_probability_bound_{end}"))
                      for end in ("lower", "upper"))
            rows.append((f"bounds over all {n_asm:,} {many} ({unresolved:,} unresolved counted "
                         "as below / above the limit)", " to ".join(bounds),
                         "friction_exceedance_probability_bound_lower, _upper"))
    rows += [
        (f"time-mean increase over the stroke (mean over the {many})",
         _force_text(number(ds, "friction_increase_stroke_mean")), "friction_increase_stroke_mean"),
        ("largest ball-to-ball force: mean / median / 99 %",
         f"{_force_text(number(ds, 'contact_force_max_mean'))} / "
         f"{_force_text(quantile_value(ds, 'contact_force_max_quantile', 0.5))} / "
         f"{_force_text(quantile_value(ds, 'contact_force_max_quantile', 0.99))}",
         "contact_force_max_mean, _quantile"),
        ("ripple of the friction force: median / 99 %",
         f"{_force_text(quantile_value(ds, 'friction_ripple_quantile', 0.5))} / "
         f"{_force_text(quantile_value(ds, 'friction_ripple_quantile', 0.99))}",
         "friction_ripple_quantile"),
        ("fraction of the stroke with a ball-to-ball contact (mean)",
         format_fraction(number(ds, "contact_fraction_mean")), "contact_fraction_mean"),
        ("multi-ball clusters formed over the stroke (mean)",
         significant(number(ds, "clusters_formed_mean"), 3), "clusters_formed_mean"),
        (f"{many} resolved / unresolved / with a sliding ball",
         f"{resolved:,} / {unresolved:,} / {sliding:,} of {n_asm:,}",
         "n_assemblies_friction_resolved, _unresolved, n_assemblies_sliding"),
    ]
    if released is not None:
        rows.append((f"{many} with a ball pushed off its stick line (none sliding)",
                     f"{released:,} of {n_asm:,}", "n_assemblies_released"))
    tables = [ReportTable(
        "Friction after contact at a glance", ("quantity", "value", "result file"),
        tuple(rows), (0.42, 0.33, 0.25),
        "Forces in N. Unresolved: a train with a ball outside the creep model (or "
        "unresolved before contact), or one with a sliding ball, from the onset of sliding, "
        "or with a ball pushed past the release push of its stuck contact, from then on.",
        (1,))]
    header = ("quantity [N]", "mean", "std", *(f"{100 * q:g} %" if q != 0.5 else "median"
                                               for q in FRICTION_LEVELS))
    dist = []
    for prefix, (label, _) in FRICTION_HISTOGRAMS.items():
        if f"{prefix}_quantile" not in ds.variables:
            continue
        dist.append((label, _force_text(number(ds, f"{prefix}_mean"), ""),
                     _force_text(number(ds, f"{prefix}_std"), ""),
                     *(_force_text(quantile_value(ds, f"{prefix}_quantile", q), "")
                       for q in FRICTION_LEVELS)))
    tables.append(ReportTable(
        f"Distribution over the {resolved:,} resolved {many}", header, tuple(dist),
        (0.37, 0.09, 0.09, 0.09, 0.09, 0.09, 0.09, 0.09),
        "Quantiles from the fixed force histogram (50 bins per decade, within one bin: a "
        "relative 4.7 %; a value below 1 µN, no rise, is shown as 0); mean and std exact.",
        tuple(range(1, len(header)))))
    indices = friction_indices(sens)
    notes = []
    if indices is not None and not np.all(np.isnan(indices[1])):
        first, total, _, total_ci = indices
        order = np.argsort(-np.nan_to_num(total, nan=-1.0), kind="stable")
        tables.append(ReportTable(
            "Drivers of the friction increase: ranked by the total-effect index",
            ("rank", "tolerance", "total effect S_T [95 % CI]", "first order S"),
            tuple((str(r), sens.factors[i], f"{total[i]:.3f} [{total_ci[i, 0]:.3f}, "
                   f"{total_ci[i, 1]:.3f}]", f"{first[i]:.3f}")
                  for r, i in enumerate(order, 1)),
            (0.08, 0.5, 0.27, 0.15),
            "Sobol' indices of the increase per assembly (unresolved assemblies left out), "
            "from the same design as the indices of ε and contact (section \"What drives the "
            "risk\"). A total index well above the first order means the source acts through "
            "interactions: the rise needs a contact first, which takes both a difference in ε "
            "and a gap small enough to close.", (0, 2, 3)))
    elif indices is not None:
        reason = not_estimable(sens, list(sens.outputs).index(FRICTION_OUTPUT))
        notes.append(f"The friction increase: {reason}; no ranking of its drivers." if reason
                     else "The friction increase does not vary over the Sobol' samples: no "
                     "ranking of its drivers.")
    else:
        notes.append("No Sobol' indices of the friction increase (none stored in the result "
                     "file, or the sensitivity analysis was not requested).")
    ripple = ("friction_ripple_histogram" in ds.variables
              and np.array_equal(np.asarray(ds["friction_ripple_histogram"]),
                                 np.asarray(ds["friction_increase_histogram"])))
    if ripple:
        notes.append("The ripple equals the increase here: with constant ε a contact never "
                     "opens again, so a track's friction force only steps up during the "
                     "stroke, and where a stroke starts without contact (here every one) its "
                     "minimum is the baseline.")
    if "circuit_balls" in ds.variables:
        notes.append("With a ball circuit the friction's extremes are taken over the "
                     "intervals between the circuit step's events, so the short dip of the "
                     "column's push at the zone's exit after a ball leaves is resolved: on "
                     "configs/carriage_preload.toml with a default circuit the ripple is "
                     "0.3095 N at 10 steps against 0.3100 N at 1 600 (16 assemblies; "
                     "benchmarks/convergence_along_track.py). What remains is ε's change "
                     "within a step.")
    return dict(heading=section_titles(ds)["friction"], paragraphs=paragraphs, tables=tables,
                figure_after=0, notes=notes)
