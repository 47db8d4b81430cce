"""The driver of the sweep report: :func:`make_sweep_report` writes the PNGs,
``points.csv`` and ``report.html`` of a sweep file."""

import os
from dataclasses import dataclass, field

from tolsim.reports.files import check_folder, write_files
from tolsim.reports.result_view import read_result_file
from tolsim.reports.style import render_png
from tolsim.reports.sweep.figures import FIGURES
from tolsim.reports.sweep.page import sweep_html
from tolsim.reports.sweep.points import CSV_NAME, HTML_NAME, csv_text, sweep_layout, sweep_points
from tolsim.study.design.sweep import Sweep


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


def make_sweep_report(path, folder, *, progress=None, verify=True) -> SweepReportOutputs:
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
    verify : bool
        Verify the file's checksums (:mod:`tolsim.io.checksums`); False for forensics.

    Returns
    -------
    SweepReportOutputs

    Raises
    ------
    tolsim.reports.result_view.NotAResult
        If ``path`` is not a tolsim result.
    NotASweep
        If it is the result of a single study (:func:`tolsim.reports.study.make_report`).
    """
    check_folder(folder)
    say = progress or (lambda msg: None)
    ds = read_result_file(path, verify=verify)
    layout = sweep_layout(ds)
    say(f"{layout.size} sweep point{'' if layout.size == 1 else 's'}")
    points = sweep_points(ds, layout)
    say("figures")
    pngs = {name: render_png(plot(layout, points))
            for name, (plot, _, friction) in FIGURES.items()
            if not friction or any(p.friction is not None for p in points)}
    say(f"{HTML_NAME} and {CSV_NAME}")
    files = {HTML_NAME: sweep_html(ds, os.fspath(path), layout, points, pngs).encode("utf-8"),
             CSV_NAME: csv_text(layout, points).encode("utf-8"),
             **{f"{name}.png": png for name, png in pngs.items()}}
    written = write_files(os.fspath(folder), files)
    return SweepReportOutputs(os.fspath(folder), written[HTML_NAME], written[CSV_NAME],
                              {name: written[f"{name}.png"] for name in pngs}, layout, points)
