"""Figures of a carriage: its load distribution (``tolsim carriage --plot``, tolsim issue 12)
and its balls round their circuit (``--circuit-figure``, issue 24)."""

import numpy as np

from tolsim.reports.style import SERIES_COLOURS, new_figure, save_png, styled


@styled
def plot_load_distribution(out: dict, path) -> None:
    """Ball force against position along the rail, one line per track, written as a PNG.

    Top: the load the carriage groove puts on each ball, |N| = sqrt(N_x^2 + N_y^2) [N]
    (module frame); bottom: the largest of its four contact forces [N].

    Parameters
    ----------
    out : dict
        The result of :func:`tolsim.cli.carriage.evaluate` (the ``--json`` object).
    path : str or path-like
        PNG file to write (:func:`tolsim.reports.style.save_png`: nothing half-written).
    """
    fig, (top, bottom) = new_figure(6.4, 5.6, nrows=2, sharex=True)
    tracks = sorted({b["track"] for b in out["balls"]})
    for t in tracks:
        balls = [b for b in out["balls"] if b["track"] == t]
        z = np.array([b["z_mm"] for b in balls])
        load = np.hypot([b["side_load_n"] for b in balls], [b["normal_load_n"] for b in balls])
        largest = np.array([max(b["normal_force_n"]) for b in balls])
        colour = SERIES_COLOURS[t % len(SERIES_COLOURS)]
        # tracks often coincide (a symmetric guide): shrinking markers keep each visible
        style = dict(color=colour, marker="osD^v"[t % 5], markersize=max(7.0 - 2.0 * t, 3.0),
                     label=f"track {t}")
        top.plot(z, load, "-", **style)
        bottom.plot(z, largest, "--", **style)
    top.set_ylabel("ball load |N| [N]")
    bottom.set_ylabel("largest contact force [N]")
    bottom.set_xlabel("z along the rail [mm] (ball 0 trailing)")
    load = out["load"]
    top.set_title(f"Load distribution: vertical {load['vertical_n']:g} N, pitch "
                  f"{load['pitch_moment_n_m']:g} N m, yaw {load['yaw_moment_n_m']:g} N m, "
                  f"preload {out['preload_oversize_um']:g} um", fontsize=9)
    for ax in (top, bottom):
        ax.set_ylim(bottom=0)
        ax.legend(loc="best")
    save_png(fig, path)


#: Markers of the circuit's contact events, by where they form (``where_names`` of the trace).
WHERE_MARKERS = {"inside": ("X", "#D55E00"), "entry": ("^", "#009E73"),
                 "exit": ("v", "#CC79A7"), "return": ("o", "#E69F00")}


def _wrapped(x, y, length):
    """x, y with NaN breaks where y wraps round the circuit (a jump of more than L_c / 2)."""
    jumps = np.flatnonzero(np.abs(np.diff(y)) > 0.5 * length) + 1
    return np.insert(x, jumps, np.nan), np.insert(y, jumps, np.nan)


@styled
def plot_circuit(trace, path, track=0) -> None:
    """The balls of one circuit against the carriage travel, written as a PNG.

    Every ball's place round its circuit (0 at the loaded zone's entry, its leading end;
    L_z at its exit; then the trailing turnaround, the return channel and the leading
    turnaround back to the entry), the loaded zone shaded, the balls of the initial train
    drawn in blue, and the contact events marked by where they form (inside the zone, at its
    entry or exit, in the return path), the study's first contact between loaded balls
    ringed.

    Parameters
    ----------
    trace : tolsim.study.pipeline.circuit_trace.CircuitTraceResult
        Of :func:`tolsim.study.pipeline.circuit_trace.trace_circuit`.
    path : str or path-like
        PNG file to write (:func:`tolsim.reports.style.save_png`: nothing half-written).
    track : int
        The circuit (track) drawn.
    """
    fig, ax = new_figure(7.2, 5.0)
    mm = 1e3
    travel = trace.travel * mm
    length, zone = trace.length[track] * mm, trace.zone_length * mm
    ax.axhspan(0.0, zone, color="#56B4E9", alpha=0.18, lw=0, label="loaded zone")
    for ring in range(trace.position.shape[2]):
        x, y = _wrapped(travel, trace.position[:, track, ring] * mm, length)
        initial = bool(trace.loaded[0, track, ring])
        ax.plot(x, y, "-", lw=1.2 if initial else 0.8,
                color="#0072B2" if initial else "#666666")
    ax.plot([], [], "-", color="#0072B2", lw=1.2, label="ball loaded at the start")
    ax.plot([], [], "-", color="#666666", lw=0.8, label="ball outside the zone at the start")
    events = trace.events
    mine = events["track"] == track
    for code, name in enumerate(trace.where_names):
        hit = mine & (events["where"] == code)
        if hit.any():
            marker, colour = WHERE_MARKERS[name]
            ax.plot(events["travel"][hit] * mm, events["position"][hit] * mm, marker,
                    color=colour, ms=6, ls="none",
                    label=f"contact {name} ({int(np.count_nonzero(hit))})")
    if np.isfinite(trace.first_contact_travel):
        first = mine & (events["where"] == 0) & np.isclose(
            events["travel"], trace.first_contact_travel, rtol=0, atol=1e-12)
        if first.any():
            k = np.flatnonzero(first)[0]
            ax.plot(events["travel"][k] * mm, events["position"][k] * mm, "o", ms=14,
                    mfc="none", mec="#000000", mew=1.5, label="first contact (study)")
    ax.set_xlim(travel[0], travel[-1])
    ax.set_ylim(0.0, length)
    ax.set_xlabel("carriage travel [mm]")
    ax.set_ylabel("place round the circuit [mm] (0: entry of the loaded zone)")
    right = ax.secondary_yaxis("right")
    right.set_ticks([0.0, zone, length], labels=["entry", "exit", "entry"])
    seed = "" if trace.seed is None else f", seed {trace.seed}"
    ax.set_title(f"Balls of one circuit (track {track}): {trace.position.shape[2]} balls, "
                 f"slack {trace.slack * mm:g} mm, drag {trace.return_drag:g} N per ball"
                 f"{seed}", fontsize=9)
    ax.legend(loc="upper left", bbox_to_anchor=(1.08, 1.0), fontsize=8)
    save_png(fig, path)


__all__ = ["WHERE_MARKERS", "plot_circuit", "plot_load_distribution"]
