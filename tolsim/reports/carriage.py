"""The load distribution of a carriage (``tolsim carriage --plot``, tolsim issue 12)."""

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


__all__ = ["plot_load_distribution"]
