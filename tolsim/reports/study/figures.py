"""The figures of a study report: the epsilon distribution, contact, the carriage's load
distribution, the spot checks, the sensitivity indices and the quality tails."""


import textwrap

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator

from tolsim.physics.velocity.analytic import VALIDITY_ERROR_BUDGET
from tolsim.reports.assumptions import (
    carriage_load_items,
)
from tolsim.reports.result_view import (
    bin_edges,
    integer,
    number,
)
from tolsim.reports.study.sensitivity import error_bar_lengths, not_estimable
from tolsim.reports.style import (
    LIMIT_COLOUR,
    MODEL_COLOURS,
    SERIES_COLOURS,
    new_canvas,
    new_figure,
    styled,
)
from tolsim.reports.verdict import (
    ESTIMATOR_NAMES,
    contact_unit,
    estimator_label,
    tracks_of,
)
from tolsim.study.statistics.intervals import wilson_interval
from tolsim.study.statistics.quality import format_fraction


def track_labels(ds) -> list:
    """'track 0 (x = -20 mm, φ = +90°)' for every track of a carriage study ([] without)."""
    tracks = tracks_of(ds)
    if not tracks:
        return []
    x = (1e3 * np.asarray(ds["track_x"], dtype=float) if "track_x" in ds.variables
         else np.full(tracks, np.nan))
    phi = (np.rad2deg(np.asarray(ds["track_orientation"], dtype=float))
           if "track_orientation" in ds.variables else np.full(tracks, np.nan))
    return [f"track {t} (x = {x[t]:+.4g} mm, φ = {phi[t]:+.4g}°)" for t in range(tracks)]


#: Colours of the tracks of a carriage: the series colours without the spec-limit colour.
TRACK_COLOURS = tuple(c for c in SERIES_COLOURS if c != LIMIT_COLOUR)


def _track_style(t):
    """Colour, marker and marker size of track ``t``: tracks often coincide (a symmetric
    guide), so the markers shrink track by track and each one stays visible."""
    return dict(color=TRACK_COLOURS[t % len(TRACK_COLOURS)], marker="osD^v"[t % 5],
                ms=max(5.5 - 1.5 * t, 2.5))


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
@styled
def plot_velocity_deviation(ds):
    """epsilon histogram with the spec limit; epsilon (mean +- std) and the side force ratio
    rho per ball position, in two panels with their own, separately labelled scales (on
    twin axes, a rho of 0.4 drawn level with a 0.5 % limit line read as "rho reaches the
    limit"). A carriage study draws one series per track (in (b) side by side, slightly
    apart), named in a legend below the figure."""
    fig = new_canvas(11.0, 5.2)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.6, 1.0], height_ratios=[1.45, 1.0])
    ax = fig.add_subplot(grid[:, 0])
    ax2 = fig.add_subplot(grid[0, 1])
    ax3 = fig.add_subplot(grid[1, 1], sharex=ax2)
    counts = np.asarray(ds["velocity_deviation_histogram"], dtype=float)
    edges = 100.0 * bin_edges(ds, "velocity_deviation_bin_bounds")
    limit = number(ds, "velocity_deviation_limit")
    n = counts.sum()
    if n > 0:
        nz = np.nonzero(counts)[0]
        lo, hi = edges[nz[0]], edges[nz[-1] + 1]
        span = max(hi - lo, 20 * (edges[1] - edges[0]))
        lo, hi = lo - 0.15 * span, hi + 0.15 * span
        if np.isfinite(limit) and limit > 0:
            lo, hi = min(lo, -120 * limit), max(hi, 120 * limit)
        lo, hi = max(lo, edges[0]), min(hi, edges[-1])
        width = edges[1] - edges[0]
        ax.stairs(counts / (n * width), edges, fill=True, color=MODEL_COLOURS["full"],
                  alpha=0.8, label="valid balls")
        ax.set_xlim(lo, hi)
        ax.set_ylim(0, 1.35 * np.max(counts / (n * width)))  # room for the legend
    mean, std = (100 * number(ds, "velocity_deviation_mean"),
                 100 * number(ds, "velocity_deviation_std"))
    q = np.asarray(ds["velocity_deviation_quantile"]) * 100
    levels = np.asarray(ds["quantile"])
    if np.isfinite(mean):
        m3 = round(mean, 3) or 0.0  # no "-0.000"
        ax.axvline(mean, color="k", lw=1.0, label=f"mean {m3:+.3f} %, std {std:.3f} %")
    for lev, style in ((0.001, ":"), (0.999, ":")):
        k = int(np.argmin(np.abs(levels - lev)))
        if np.isfinite(q[k]):
            ax.axvline(q[k], color="0.3", lw=1.0, ls=style,
                       label="0.1 % and 99.9 % quantiles" if lev < 0.5 else None)
    if np.isfinite(limit) and limit > 0:
        for s in (-1, 1):
            ax.axvline(100 * s * limit, color=LIMIT_COLOUR, lw=2.0, ls="--",
                       label=f"spec limit |ε| ≤ {100 * limit:.3g} %" if s > 0 else None)
    under, over = (integer(ds, "velocity_deviation_underflow"),
                   integer(ds, "velocity_deviation_overflow"))
    title = f"(a) ε of {int(n + under + over):,} valid balls"
    if under or over:
        title += f" ({under + over} outside the histogram range)"
    ax.set_title(title)
    ax.set_xlabel("velocity deviation ε [%]  (v_B = (1 + ε) v/2)")
    ax.set_ylabel("probability density [1/%]")
    if ax.get_legend_handles_labels()[0]:  # none when no ball has an epsilon (all unloaded)
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    else:
        ax.text(0.5, 0.5, "no ball with an ε", transform=ax.transAxes, ha="center")

    balls = np.asarray(ds["ball"])
    m = 100 * np.asarray(ds["velocity_deviation_mean_by_ball"], dtype=float)
    sd = 100 * np.asarray(ds["velocity_deviation_std_by_ball"], dtype=float)
    rho = np.asarray(ds["side_force_ratio"], dtype=float)
    labels = track_labels(ds)
    if labels:  # a carriage: (track, ball), one series per track
        tracks = len(labels)
        for t in range(tracks):
            st = _track_style(t)
            shift = 0.5 * (t - 0.5 * (tracks - 1)) / tracks  # bars side by side
            ax2.errorbar(balls + 1 + shift, m[t], yerr=np.nan_to_num(sd[t]), fmt="-",
                         color=st["color"], marker=st["marker"], ms=0.8 * st["ms"],
                         capsize=2, lw=1.0)
    else:
        ax2.errorbar(balls + 1, m, yerr=np.nan_to_num(sd), fmt="o-", color=SERIES_COLOURS[2],
                     capsize=3, lw=1.2, ms=4, label="mean ± 1 std")
    ax2.axhline(0, color="0.5", lw=0.6)
    if np.isfinite(limit) and limit > 0:
        for s in (-1, 1):
            ax2.axhline(100 * s * limit, color=LIMIT_COLOUR, lw=1.5, ls="--",
                        label="spec limit on |ε|" if s > 0 else None)
        ax2.legend(loc="lower right", fontsize=7.5, ncols=2, framealpha=0.9)
        top = max(120 * limit, np.nanmax(np.abs(m) + np.nan_to_num(sd), initial=0) * 1.1)
        ax2.set_ylim(-1.45 * top if top else -1, top if top else 1)  # room for the legend
    ax2.set_ylabel("ε [%]")
    ax2.set_title("(b) ε along the train: mean ± 1 std per position", fontsize=10)
    ax2.tick_params(labelbottom=False)
    ticks = balls + 1 if len(balls) <= 20 else np.linspace(1, len(balls), 6).round()
    if labels:
        for t, label in enumerate(labels):
            ax3.plot(balls + 1, rho[t], "-", lw=1.0, label=label, **_track_style(t))
        fig.legend(*ax3.get_legend_handles_labels(), loc="outside lower center",
                   ncols=min(len(labels), 4), fontsize=8, frameon=False,
                   title="(b), (c): one series per track", title_fontsize=8)
    else:
        ax3.plot(balls + 1, rho, "s-", color=SERIES_COLOURS[3], lw=1.2, ms=4)
    ax3.axhline(0, color="0.5", lw=0.6)
    reach = float(np.nanmax(np.abs(rho), initial=0.0))
    ax3.set_ylim(-1.25 * reach if reach > 0 else -0.1, 1.25 * reach if reach > 0 else 0.1)
    ax3.set_xticks(ticks)
    ax3.set_xlabel("ball position in the train [-] (1 = trailing)")
    ax3.set_ylabel("ρ = N_x / N_y [-]")
    ax3.set_title("(c) side force ratio ρ per position (the load, not ε)" if not labels else
                  "(c) ρ per position, nominal carriage (the load, not ε)",
                  fontsize=10)
    return fig


@styled
def plot_contact(ds):
    """Survival curve with a pointwise band; P(contact) and its CI; first-contact pairs.

    In a carriage study the survival curve and P(contact) are per assembly (contact in any
    of its trains), and the first-contact pairs are drawn per track, side by side."""
    fig, (ax, ax_p, ax_pair) = new_figure(12.0, 4.2, ncols=3, width_ratios=[1.7, 0.7, 1.0])
    one, many = contact_unit(ds)
    # the survival curve's times: elapsed_time (schema 2), time in older files
    t = np.asarray(ds[ds["survival_probability"].dims[0]], dtype=float)
    s = np.asarray(ds["survival_probability"], dtype=float)
    n = integer(ds, "n_assemblies_valid")
    v = number(ds, "groove_velocity")
    if n > 0:
        k = np.round((1.0 - s) * n)
        band = np.array([wilson_interval(kk, n) for kk in k])
        ax.fill_between(t, 1 - band[:, 1], 1 - band[:, 0], step="post", color="0.8",
                        label="95 % interval (Wilson, pointwise)")
    ax.step(t, s, where="post", color=MODEL_COLOURS["full"], lw=1.8,
            label=f"P(no contact by t), {n:,} resolved {many}")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlim(t[0], t[-1])
    ax.set_xlabel("time since the start of the stroke t [s]")
    ax.set_ylabel("survival probability [-]")
    ax.set_title("(a) survival: no ball-to-ball contact yet")
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    if np.isfinite(v) and v > 0:
        sec = ax.secondary_xaxis("top", functions=(lambda x: 1e3 * v * x,
                                                   lambda y: y / (1e3 * v)))
        sec.set_xlabel("carriage travel [mm]")

    p, lo, hi = (number(ds, x) for x in ("contact_probability", "contact_probability_ci_lower",
                                      "contact_probability_ci_upper"))
    limit = number(ds, "contact_probability_limit")
    if np.isfinite(p):
        ax_p.bar([0], [p], color=SERIES_COLOURS[1], width=0.5, alpha=0.85)
        # (a file read with --no-verify may hold an estimate outside its interval)
        ax_p.errorbar([0], [p], yerr=[[max(p - lo, 0.0)], [max(hi - p, 0.0)]], color="k",
                      capsize=6, lw=1.5)
        ax_p.set_xticks([0], [f"P = {format_fraction(p)}\n95 % CI\n{format_fraction(lo)} to "
                              f"{format_fraction(hi)}"], fontsize=8.5)
    top = max(hi if np.isfinite(hi) else 0.0, limit if np.isfinite(limit) else 0.0)
    ax_p.set_ylim(0, min(1.0, 1.45 * top) if top > 0 else 1.0)
    if np.isfinite(limit) and limit > 0:
        ax_p.axhline(limit, color=LIMIT_COLOUR, ls="--", lw=2,
                     label=f"limit {format_fraction(limit)}")
        ax_p.legend(loc="upper center", fontsize=8)  # above the bar: ylim leaves room
    ax_p.set_xlim(-0.8, 0.8)
    ax_p.set_xlabel("contact within the horizon")
    ax_p.set_ylabel(f"P(contact within the horizon) per {one} [-]")
    label = estimator_label(ds)
    ax_p.set_title("(b) contact probability\n(95 % " + (
        label if label == "Clopper-Pearson" else
        ESTIMATOR_NAMES.get(ds["contact_probability"].attrs.get("estimator"), "estimator"))
        + ")", fontsize=10)

    if "contact_pair_count" in ds.variables and ds.sizes.get("pair", 0) > 0:
        pairs = np.asarray(ds["pair"])
        cnt = np.asarray(ds["contact_pair_count"], dtype=float)
        if cnt.ndim == 2:  # a carriage: (track, pair), the tracks side by side
            labels = track_labels(ds)
            tracks = cnt.shape[0]
            width = 0.8 / tracks
            for t in range(tracks):
                ax_pair.bar(pairs + 1 + (t - 0.5 * (tracks - 1)) * width, cnt[t], width=width,
                            color=_track_style(t)["color"], alpha=0.85,
                            label=f"{labels[t]}: {int(cnt[t].sum()):,}")
            top = float(np.max(cnt, initial=0.0))
            ax_pair.set_ylim(0, 1.2 * (1.0 + 0.12 * tracks) * top if top > 0 else 1.0)
            ax_pair.legend(loc="upper left", fontsize=7, framealpha=0.9)
        else:
            ax_pair.bar(pairs + 1, cnt, color=SERIES_COLOURS[2], alpha=0.85)
        ax_pair.set_xticks(pairs + 1 if len(pairs) <= 20 else
                           np.linspace(1, len(pairs), 6).round())
    ax_pair.set_xlabel("pair of balls j, j+1 [-] (1 = trailing pair)")
    ax_pair.set_ylabel(f"{many} whose first contact is here [-]")
    ax_pair.set_title("(c) where the first contact happens")
    return fig


@styled
def plot_carriage_loads(ds, ball_z=None, preload_ball_load=None):
    """The nominal load distribution of a carriage study, one series per track: (a) the
    normal load N_y of every ball, with the load of the preload alone, and (b) the side force
    ratio rho = N_x / N_y, against the ball position along the rail (N_x itself is in the
    tracks table of the report: it is rho N_y).

    Parameters
    ----------
    ds : xarray.Dataset
        A carriage study's result file: ``normal_load``, ``side_load`` and
        ``side_force_ratio`` of the nominal assembly (no errors), dims (track, ball).
    ball_z : array_like, optional
        Nominal axial ball positions z_j [m] (:attr:`tolsim.physics.carriage.CarriageLayout.
        ball_z`); without them the balls are drawn at their index.
    preload_ball_load : float, optional
        N_0 = 2 F_0 cos(beta_0) [N], the normal load of the preload alone (a dotted line).
    """
    fig, (ax, ax2) = new_figure(11.0, 4.6, ncols=2)
    ny = np.atleast_2d(np.asarray(ds["normal_load"], dtype=float))
    rho = np.atleast_2d(np.asarray(ds["side_force_ratio"], dtype=float))
    balls = np.asarray(ds["ball"])
    if ball_z is not None and len(ball_z) == len(balls):
        x = 1e3 * np.asarray(ball_z, dtype=float)
        xlabel = "ball position z along the rail [mm] (ball 0 trailing)"
    else:
        x = balls + 1
        xlabel = "ball position in the train [-] (1 = trailing)"
    handles = []
    for t, label in enumerate(track_labels(ds) or [f"track {k}" for k in range(len(ny))]):
        st = _track_style(t)
        ax.plot(x, ny[t], "-", lw=1.2, **st)
        ax2.plot(x, rho[t], "-", lw=1.2, **st)
        handles.append(Line2D([], [], ls="-", label=label, **st))
    if preload_ball_load is not None and np.isfinite(preload_ball_load):
        ax.axhline(preload_ball_load, color="0.45", lw=1.0, ls=":")
        handles.append(Line2D([], [], color="0.45", ls=":",
                              label=f"N_0 = {preload_ball_load:.4g} N: the preload alone"))
    ax2.axhline(0, color="0.5", lw=0.6)
    for a in (ax, ax2):
        a.set_xlabel(xlabel)
    ax.set_ylabel("normal load N_y [N]")
    ax.set_title("(a) ball normal load N_y", fontsize=10)
    reach = float(np.nanmax(np.abs(rho), initial=0.0))
    ax2.set_ylim(-1.2 * reach if reach > 0 else -0.1, 1.2 * reach if reach > 0 else 0.1)
    ax2.set_ylabel("ρ = N_x / N_y [-]")
    ax2.set_title("(b) side force ratio ρ", fontsize=10)
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4),
               fontsize=8, frameon=False)
    loads = carriage_load_items(ds)
    text = ", ".join(f"{term.split(' (')[0].split(',')[0]} {value:.4g} {unit}"
                     for term, value, unit, _ in loads if value)
    fig.suptitle("Nominal load distribution of the carriage (no errors): "
                 + (text or "no external load")
                 + f", preload {1e6 * number(ds, 'preload_oversize'):.3g} µm", fontsize=10.5)
    return fig


#: Markers of the spot-check strata (``spot_check_stratum``).
STRATUM_MARKERS = {0: ("o", "drawn uniformly"), 1: ("D", "near the spec limit")}


@styled
def plot_spot_checks(ds):
    """The study's model against the full friction model on the spot-checked balls: identity
    plot, difference, and the counts beside them (nothing drawn over the points).

    Circles are balls drawn uniformly, diamonds balls drawn near the spec limit on |epsilon|
    (``spot_check_stratum``); crosses are balls flagged invalid by one model.
    """
    fig = new_canvas(11.5, 4.9)
    ax, ax2, ax_text = fig.subplots(1, 3, width_ratios=[1.0, 1.0, 0.62])
    ea = 100 * np.asarray(ds["spot_check_velocity_deviation_analytic"], dtype=float)
    ef = 100 * np.asarray(ds["spot_check_velocity_deviation_full"], dtype=float)
    k = ea.size
    va = np.asarray(ds["spot_check_valid_analytic"], dtype=bool) if k else np.zeros(0, bool)
    vf = np.asarray(ds["spot_check_valid_full"], dtype=bool) if k else np.zeros(0, bool)
    stratum = (np.asarray(ds["spot_check_stratum"], dtype=int) if "spot_check_stratum" in ds
               else np.zeros(k, int))
    both = va & vf
    model = ds.attrs.get("velocity_model", "analytic")
    limit = 100 * number(ds, "velocity_deviation_limit")
    budget = 100 * VALIDITY_ERROR_BUDGET
    diff = ea - ef
    finite = np.isfinite(ea) & np.isfinite(ef)
    if k:
        for code, (marker, name) in STRATUM_MARKERS.items():
            sel = both & (stratum == code)
            if sel.any():
                kw = dict(ms=5, color=MODEL_COLOURS["analytic"], ls="none", marker=marker,
                          mfc=MODEL_COLOURS["analytic"] if code == 0 else "white", mew=1.3)
                ax.plot(ef[sel], ea[sel], label=f"{name}, valid in both ({sel.sum()})", **kw)
                ax2.plot(ef[sel], diff[sel], **kw)
        other = ~both & finite
        if other.any():
            ax.plot(ef[other], ea[other], "x", ms=6, color=LIMIT_COLOUR,
                    label=f"invalid in one model ({other.sum()})")
            ax2.plot(ef[other], diff[other], "x", ms=6, color=LIMIT_COLOUR)
        values = np.concatenate([ea[np.isfinite(ea)], ef[np.isfinite(ef)]])
        if values.size:
            lo, hi = values.min(), values.max()
            pad = 0.08 * max(hi - lo, 1e-3)
            line = np.array([lo - pad, hi + pad])
            ax.plot(line, line, color="k", lw=0.8, label="identity")
            ax.set_xlim(*line)
            ax.set_ylim(*line)
            ax2.set_xlim(*line)
            if np.isfinite(limit) and limit > 0:
                shown = [x for x in (-limit, limit) if line[0] <= x <= line[1]]
                for j, x in enumerate(shown):
                    for a in (ax, ax2):
                        a.axvline(x, color=LIMIT_COLOUR, lw=1.2, ls="--",
                                  label="spec limit on |ε|" if a is ax and j == 0 else None)
        ax2.axhline(0, color="k", lw=0.8)
        if finite.any() and np.nanmax(np.abs(diff[finite])) > 0.25 * budget:
            for y in (-budget, budget):
                ax2.axhline(y, color="0.45", lw=1.0, ls=":")
            ax.plot([], [], color="0.45", lw=1.0, ls=":",
                    label=f"validity budget ±{budget:.2g} pp (in b)")
    for a in (ax, ax2):
        a.xaxis.set_major_locator(MaxNLocator(nbins=5))
        a.yaxis.set_major_locator(MaxNLocator(nbins=6))
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("ε, full friction model [%]")
    ax.set_ylabel(f"ε, study model '{model}' [%]")
    ax.set_title(f"(a) spot checks: {k} balls re-solved", fontsize=10.5)
    ax2.set_xlabel("ε, full friction model [%]")
    ax2.set_ylabel(f"ε '{model}' − ε full [percentage points]")
    ax2.set_title("(b) difference", fontsize=10.5)
    if ax.get_legend_handles_labels()[0]:
        fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncols=3,
                   fontsize=8, frameon=False)
    ax_text.set_axis_off()
    ax_text.set_title("(c) counts", fontsize=10.5)
    ax_text.text(0.0, 1.0, _spot_check_counts(ds, model, stratum, va, vf, diff, budget),
                 transform=ax_text.transAxes, ha="left", va="top", fontsize=8.5,
                 linespacing=1.45, wrap=True)
    return fig


def _spot_check_counts(ds, model, stratum, va, vf, diff, budget):
    """The text beside the spot-check plots."""
    k = stratum.size
    if not k:
        return str(ds.attrs.get("spot_check_status", "no spot checks"))
    both = va & vf
    near = stratum == 1
    lines = [f"spot checks: {k}"]
    if near.any():
        lines.append(f"  drawn uniformly: {int((~near).sum())}")
        band = (100 * number(ds, "spot_check_band_lower"),
                100 * number(ds, "spot_check_band_upper"))
        lines.append(f"  near the limit: {int(near.sum())}")
        lines.append(f"    ({band[0]:.3g} % ≤ |ε| ≤ {band[1]:.3g} %,")
        lines.append(f"    {integer(ds, 'spot_check_band_balls'):,} balls in that band)")
    lines += [f"valid in both models: {int(both.sum())}",
              f"'{model}' invalid (re-solved): {int((~va).sum())}",
              f"full invalid / not converged: {int((~vf).sum())}",
              "",
              f"'{model}' − full [pp]:"]
    for name, sel in (("uniform", both & ~near), ("near limit", both & near)):
        if sel.any():
            d = diff[sel]
            lines.append(f"  {name}: RMS {np.sqrt(np.mean(d * d)):.4f},")
            lines.append(f"    max |·| {np.max(np.abs(d)):.4f}")
    inside = int(np.sum(np.abs(diff[both]) <= budget))
    lines.append(f"inside the ±{budget:.2g} pp budget: {inside} of {int(both.sum())}")
    return "\n".join(lines)


OUTPUT_TITLES = {"velocity_deviation": "share of the variance of ε",
                 "contact": "influence on ball-to-ball contact (indicator per train)"}


def output_titles(unit="train") -> dict:
    """:data:`OUTPUT_TITLES` with the contact indicator counted per ``unit`` (a train, or an
    assembly in a carriage study)."""
    return {**OUTPUT_TITLES,
            "contact": f"influence on ball-to-ball contact (indicator per {unit})"}
OUTPUT_SHORT = {"velocity_deviation": "the scatter of ε", "contact": "ball-to-ball contact"}


@styled
def plot_sensitivity(sens, unit="train"):
    """Ranked bars of the total-effect and first-order indices, one panel per output; the
    contact indicator is per ``unit`` (``"assembly"`` in a carriage study)."""
    titles = output_titles(unit)
    outputs = list(sens.outputs)
    d = len(sens.factors)
    fig, axes = new_figure(5.2 * len(outputs) + 1.0, max(3.4, 1.5 + 0.42 * d),
                           ncols=len(outputs), squeeze=False)
    for ax, output in zip(axes[0], outputs, strict=True):
        k = outputs.index(output)
        total = sens.total[k]
        order = np.argsort(np.nan_to_num(total, nan=-1.0))  # largest at the top
        y = np.arange(d)
        tot, first = total[order], sens.first_order[k][order]
        ci_t = sens.total_ci[k][order]
        err = np.abs(np.stack([tot - ci_t[:, 0], ci_t[:, 1] - tot]))
        ax.barh(y + 0.18, np.nan_to_num(tot), height=0.36, color=SERIES_COLOURS[0],
                label="total effect S_T")
        ax.errorbar(np.nan_to_num(tot), y + 0.18, xerr=error_bar_lengths(err), fmt="none",
                    ecolor="k", capsize=2, lw=0.8)
        ax.barh(y - 0.18, np.nan_to_num(first), height=0.36, color=SERIES_COLOURS[4],
                label="first order S")
        ci_f = sens.first_order_ci[k][order]
        err_f = np.abs(np.stack([first - ci_f[:, 0], ci_f[:, 1] - first]))
        ax.errorbar(np.nan_to_num(first), y - 0.18, xerr=error_bar_lengths(err_f), fmt="none",
                    ecolor="k", capsize=2, lw=0.8)
        ax.set_yticks(y, [sens.factors[i].replace("_", " ") for i in order], fontsize=8.5)
        ends = np.concatenate([sens.total_ci[k].ravel(), sens.first_order_ci[k].ravel()])
        ends = ends[np.isfinite(ends)]
        ax.set_xlim(max(-1.0, min(-0.05, ends.min() - 0.02)) if ends.size else -0.05,
                    min(2.0, max(1.05, ends.max() + 0.02)) if ends.size else 1.05)
        ax.axvline(0, color="0.4", lw=0.8)
        ax.set_xlabel("Sobol' index [-] (bars: 95 % bootstrap interval)")
        ax.set_ylabel("tolerance source")
        ax.set_title(titles.get(output, output), fontsize=10)
        if np.all(np.isnan(total)):
            reason = not_estimable(sens, k)
            ax.text(0.5, 0.5, textwrap.fill(f"indices not estimable: {reason.split(':')[0]}",
                                            36) if reason else "output does not vary:\nno index",
                    transform=ax.transAxes, ha="center", va="center")
        ax.legend(loc="lower right", fontsize=8)
    fig.suptitle(f"What drives the risk: Sobol' indices, n = {sens.n} per base sample "
                 f"({sens.evaluations:,} assemblies evaluated)" if sens.n else
                 "What drives the risk: Sobol' indices stored in the result file",
                 fontsize=10.5)
    return fig


@styled
def plot_quality(ds, q):
    """Tails of epsilon on a log scale against the limit, with the normal fit and Cpk."""
    fig, ax = new_figure(7.5, 4.3)
    counts = np.asarray(ds["velocity_deviation_histogram"], dtype=float)
    edges = 100.0 * bin_edges(ds, "velocity_deviation_bin_bounds")
    n = counts.sum()
    limit = 100 * number(ds, "velocity_deviation_limit")
    width = edges[1] - edges[0]
    centres = 0.5 * (edges[:-1] + edges[1:])
    dens = np.where(counts > 0, counts / (max(n, 1) * width), np.nan)
    ax.semilogy(centres, dens, ".", ms=3, color=MODEL_COLOURS["full"],
                label="histogram (valid balls)")
    mean, std = (100 * number(ds, "velocity_deviation_mean"),
                 100 * number(ds, "velocity_deviation_std"))
    if std > 0:
        x = np.linspace(min(edges[0], -1.3 * limit), max(edges[-1], 1.3 * limit), 600)
        pdf = np.exp(-0.5 * ((x - mean) / std) ** 2) / (std * np.sqrt(2 * np.pi))
        ax.semilogy(x, pdf, color="k", lw=1.0, label="normal with the same mean and std")
    for s in (-1, 1):
        ax.axvline(s * limit, color=LIMIT_COLOUR, lw=2, ls="--",
                   label=f"spec limit |ε| ≤ {limit:.3g} %" if s > 0 else None)
    floor = 0.3 / (max(n, 1) * width)
    ax.set_ylim(floor, None)
    span = max(1.4 * limit, np.nanmax(np.abs(centres[counts > 0])) * 1.1 if n else limit)
    ax.set_xlim(-span, span)
    ax.set_xlabel("velocity deviation ε [%]")
    ax.set_ylabel("probability density [1/%] (log)")
    prop, cap = q.get("_proportion"), q.get("_capability")
    lines = [f"out of spec: {prop.text()}" if prop is not None else ""]
    if cap is not None:
        lines.append(f"Cpk = {cap.cpk:.2f} (95 % CI {cap.cpk_lower:.2f} to "
                     f"{cap.cpk_upper:.2f}), Cp = {cap.cp:.2f}")
        if np.isfinite(cap.cpk_percentile):
            lines.append(f"percentile Cpk = {cap.cpk_percentile:.2f}")
        lines.append(f"normal theory out of spec: {format_fraction(cap.normal_out_of_spec)}")
    ax.set_title("Quality: tails of ε against the specification", fontsize=10.5)
    ax.text(0.02, 0.97, "\n".join(lines), transform=ax.transAxes, va="top", ha="left",
            fontsize=8, bbox=dict(boxstyle="round", fc="white", ec="0.7", alpha=0.9))
    ax.legend(loc="upper right", fontsize=8)
    return fig
