"""The figures of ``tolsim compare``: P(contact) as a forest plot, the epsilon histograms
and the survival curves of the runs, overlaid."""


import numpy as np

from tolsim.reports.compare.comparison import Comparison
from tolsim.reports.result_view import bin_edges, integer, number
from tolsim.reports.style import (
    LIMIT_COLOUR,
    SERIES_COLOURS,
    new_figure,
    styled,
)
from tolsim.reports.verdict import contact_unit
from tolsim.study.statistics.intervals import (
    wilson_interval,
)

#: Colours of the runs: the series colours without the spec-limit colour.
RUN_COLOURS = tuple(c for c in SERIES_COLOURS if c != LIMIT_COLOUR)
RUN_LINESTYLES = ("-", "--", "-.", ":")


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
def _run_style(i):
    return dict(color=RUN_COLOURS[i % len(RUN_COLOURS)],
                ls=RUN_LINESTYLES[i % len(RUN_LINESTYLES)])


@styled
def plot_contact_probability(comparison: Comparison):
    """Forest plot: (a) P(contact) of every run with its interval (and the bounds with
    unresolved trains), (b) the difference to the reference with its interval."""
    runs = comparison.runs
    height = 1.6 + 0.55 * len(runs)
    fig, (ax, ax_d) = new_figure(11.0, height, ncols=2, sharey=True)
    stats = [r.statistics.get("contact_probability") for r in runs]
    ends = [x for s in stats if s is not None for x in (s.ci_upper, s.estimate)
            if np.isfinite(x)]
    for r in runs:
        b = r.statistics.get("contact_probability_bound_upper")
        if b is not None and np.isfinite(b.ci_upper):
            ends.append(b.ci_upper)
    ppm = bool(ends) and max(ends) < 1e-3
    scale, unit = (1e6, "ppm") if ppm else (1e2, "%")
    y = np.arange(len(runs))[::-1]
    bounds_label = "bounds with unresolved trains (95 %)"
    for i, (run, stat) in enumerate(zip(runs, stats, strict=True)):
        if stat is None:
            continue
        colour = _run_style(i)["color"]
        lower = run.statistics.get("contact_probability_bound_lower")
        upper = run.statistics.get("contact_probability_bound_upper")
        if lower is not None and upper is not None and upper.estimate > lower.estimate:
            ax.plot([scale * lower.ci_lower, scale * upper.ci_upper], [y[i], y[i]],
                    color="0.75", lw=7, solid_capstyle="butt", zorder=1,
                    label=bounds_label)
            bounds_label = None
        ax.errorbar([scale * stat.estimate], [y[i]],
                    # clipped at 0: a file read with --no-verify may hold an estimate
                    # outside its interval (its report says it is unverified)
                    xerr=[[scale * max(stat.estimate - stat.ci_lower, 0.0)],
                          [scale * max(stat.ci_upper - stat.estimate, 0.0)]],
                    fmt="o", color=colour, capsize=4, lw=1.6, ms=6, zorder=3)
    limits = {x for x in (number(r.ds, "contact_probability_limit") for r in runs)
              if np.isfinite(x) and x > 0}
    for k, limit in enumerate(sorted(limits)):
        ax.axvline(scale * limit, color=LIMIT_COLOUR, ls="--", lw=1.5,
                   label="spec limit" if k == 0 else None)
    ax.set_yticks(y, [r.label for r in runs])
    ax.set_ylim(-0.7, len(runs) - 0.3)
    ax.set_xlabel(f"P(contact within the stroke) [{unit}]")
    plain = all(s is None or s.interval == "Clopper-Pearson" for s in stats)
    ax.set_title("(a) contact probability, 95 % " + ("Clopper-Pearson" if plain else
                 "interval (Clopper-Pearson or the rare-event estimator's)"), fontsize=10)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize=8, framealpha=0.9)

    ax_d.axvline(0.0, color="0.4", lw=1.0)
    d_ends = []
    for i, run in enumerate(runs):
        diff = comparison.differences.get(("contact_probability", run.label))
        if i == 0:
            ax_d.annotate("reference", (0.0, y[i]), ha="center", va="center", fontsize=8.5,
                          color="0.3", bbox=dict(boxstyle="round", fc="white", ec="0.7"))
            continue
        if diff is None or not np.isfinite(diff.estimate):
            continue
        d_ends += [abs(x) for x in (diff.ci_lower, diff.ci_upper) if np.isfinite(x)]
        lo = diff.ci_lower if np.isfinite(diff.ci_lower) else diff.estimate
        hi = diff.ci_upper if np.isfinite(diff.ci_upper) else diff.estimate
        ax_d.errorbar([scale * diff.estimate], [y[i]],
                      xerr=[[scale * max(diff.estimate - lo, 0.0)],
                            [scale * max(hi - diff.estimate, 0.0)]],
                      fmt="D", color=_run_style(i)["color"], capsize=4, lw=1.6, ms=5)
    span = scale * max(d_ends, default=0.0)
    if span > 0:
        ax_d.set_xlim(-1.15 * span, 1.15 * span)
    ax_d.set_xlabel(f"difference to {runs[0].label} [{'ppm' if ppm else 'percentage points'}]")
    ax_d.set_title("(b) difference to the reference, 95 % " + (
        "Newcombe" if plain else "Newcombe or MOVER") + " (unpaired)", fontsize=10)
    ax_d.tick_params(labelleft=False)
    return fig


@styled
def plot_velocity_deviation(comparison: Comparison):
    """The epsilon histograms of the runs overlaid (densities), with the spec limits."""
    fig, ax = new_figure(9.0, 4.6)
    lo, hi = np.inf, -np.inf
    widths = []
    for i, run in enumerate(comparison.runs):
        ds = run.ds
        counts = np.asarray(ds["velocity_deviation_histogram"], dtype=float)
        edges = 100.0 * bin_edges(ds, "velocity_deviation_bin_bounds")
        n = counts.sum()
        if n <= 0:
            continue
        width = np.diff(edges)
        widths.append(float(np.median(width)))
        nz = np.flatnonzero(counts)
        lo, hi = min(lo, edges[nz[0]]), max(hi, edges[nz[-1] + 1])
        st = _run_style(i)
        mean = 100 * number(ds, "velocity_deviation_mean")
        std = 100 * number(ds, "velocity_deviation_std")
        ax.stairs(counts / (n * width), edges, color=st["color"], ls=st["ls"], lw=1.6,
                  label=f"{run.label}: mean {mean:+.3f} %, std {std:.3f} %".replace("-", "−"))
    limits = sorted({x for x in (number(r.ds, "velocity_deviation_limit")
                                 for r in comparison.runs) if np.isfinite(x) and x > 0})
    for limit in limits:
        for s in (-1, 1):
            ax.axvline(100 * s * limit, color=LIMIT_COLOUR, lw=1.6, ls="--",
                       label=(f"spec limit |ε| ≤ {100 * limit:.3g} %" if s > 0 else None))
        lo, hi = min(lo, -120 * limit), max(hi, 120 * limit)
    if np.isfinite(lo) and np.isfinite(hi):
        span = max(hi - lo, 20 * max(widths, default=0.0))
        ax.set_xlim(lo - 0.1 * span, hi + 0.1 * span)
    top = ax.get_ylim()[1]
    ax.set_ylim(0, 1.3 * top)  # room for the legend
    ax.set_xlabel("velocity deviation ε [%]  (v_B = (1 + ε) v/2)")
    ax.set_ylabel("probability density [1/%]")
    ax.set_title("ε of the valid balls, every run")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    return fig


@styled
def plot_survival(comparison: Comparison):
    """The survival curves P(no contact by t) of the runs overlaid, each with a pointwise
    95 % Wilson band."""
    fig, ax = new_figure(9.0, 4.6)
    t_max = 0.0
    for i, run in enumerate(comparison.runs):
        ds = run.ds
        t = np.asarray(ds[ds["survival_probability"].dims[0]], dtype=float)
        s = np.asarray(ds["survival_probability"], dtype=float)
        n = integer(ds, "n_assemblies_valid")
        st = _run_style(i)
        if n > 0:
            k = np.round((1.0 - s) * n)
            band = np.array([wilson_interval(kk, n) for kk in np.clip(k, 0, n)])
            ax.fill_between(t, 1 - band[:, 1], 1 - band[:, 0], step="post",
                            color=st["color"], alpha=0.15, lw=0)
        ax.step(t, s, where="post", color=st["color"], ls=st["ls"], lw=1.8,
                label=f"{run.label} ({n:,} resolved {contact_unit(ds)[1]})")
        t_max = max(t_max, float(t[-1]) if t.size else 0.0)
    ax.set_ylim(-0.02, 1.02)
    if t_max > 0:
        ax.set_xlim(0, t_max)
    ax.set_xlabel("time since the start of the stroke t [s]")
    ax.set_ylabel("survival probability P(no contact by t) [-]")
    ax.set_title("Survival: no ball-to-ball contact yet (bands: 95 % Wilson, pointwise)")
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    return fig


#: Figure name -> (plotting function, caption).
FIGURES = {
    "contact_probability": (plot_contact_probability,
                            "(a) P(contact) of every run with its 95 % Clopper-Pearson "
                            "interval, or its rare-event estimator's (grey: the bounds when "
                            "trains are unresolved); (b) the difference to the reference with "
                            "its 95 % Newcombe interval, or the MOVER from the two intervals "
                            "where a rare-event estimator made a P (unpaired)."),
    "velocity_deviation": (plot_velocity_deviation,
                           "The ε histograms of the runs as densities, with the spec limits."),
    "survival": (plot_survival, "Survival curves of the time to first contact, with pointwise "
                                "95 % Wilson bands."),
}
