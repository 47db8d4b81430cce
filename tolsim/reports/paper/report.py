"""The driver of ``tolsim paper``: :func:`make_paper` computes everything and writes the
figures, Table 2 and the README into a folder."""

import os
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from tolsim.reports.paper.figures import (
    GRIDS,
    after_contact_data,
    after_contact_summary,
    fig9_data,
    plot_after_contact,
    plot_fig4,
    plot_fig7,
    plot_fig9,
    table2_checks,
    table2_markdown,
    table2_table,
    without_round_off,
)
from tolsim.reports.paper.readme import fig7_summary, readme_text
from tolsim.reports.style import (
    save_png,
)
from tolsim.study.analyses import paper_data


@dataclass
class PaperOutputs:
    """What :func:`make_paper` wrote and the numbers behind the README."""

    folder: str
    files: list = field(default_factory=list)
    table2: pd.DataFrame | None = None
    summary: dict = field(default_factory=dict)
    elapsed: float = 0.0



# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------
def make_paper(folder="reports/paper", *, quick=False, progress=None) -> PaperOutputs:
    """Compute and write the reproduction of [Lin2018] into ``folder``.

    Parameters
    ----------
    folder : str or path
        Output folder (created if missing).
    quick : bool
        Coarse grids (for tests); the files are the same, the figures coarser.
    progress : callable, optional
        Called with a short message before each step.

    Returns
    -------
    PaperOutputs
    """
    started = time.perf_counter()
    say = progress or (lambda msg: None)
    os.makedirs(folder, exist_ok=True)
    grids = GRIDS[bool(quick)]
    out = PaperOutputs(os.fspath(folder))

    def path(name):
        p = os.path.join(folder, name)
        out.files.append(p)
        return p

    say("Table 2 (full model, static contact)")
    table = table2_table(paper_data.table2_data())
    without_round_off(table).to_csv(path("table2.csv"), index=False, float_format="%.6g")
    with open(path("table2.md"), "w", encoding="utf-8") as fh:
        fh.write("# Table 2 of Lin et al. (2018), reproduced\n\n"
                 "ε of the two balls of Sec. 3.2 (θ = 2°, ρ = ∓0.6, N_y = 200 N). Case (a): "
                 "top groove perfect; case (b): Δβ_TR = −θ, Δβ_TL = θ. The paper column is "
                 "Leblanc's model for the full model and the derived formula for Eq. (24) and "
                 "the analytic model.\n\n")
        fh.write(table2_markdown(table))
    checks = table2_checks(table)

    say("Fig. 4")
    curves, slopes = paper_data.fig4_data(
        offset_ratio=np.linspace(-3.0, 3.0, grids["fig4_points"]))
    save_png(plot_fig4(curves, slopes), path("fig4.png"))

    say("Fig. 7 (full model over the rho-theta grid)")
    grid = paper_data.fig7_data(grids["fig7_rho"], grids["fig7_theta"])
    save_png(plot_fig7(grid), path("fig7.png"))

    say("Fig. 9")
    f9 = fig9_data(table)
    save_png(plot_fig9(f9), path("fig9.png"))

    say("beyond the paper: after contact (tolsim's extension)")
    after = after_contact_data()
    save_png(plot_after_contact(after), path("after_contact.png"))

    with open(path("README.md"), "w", encoding="utf-8") as fh:
        fh.write(readme_text(table, checks, slopes, grid, f9, grids, curves, after))
    out.elapsed = time.perf_counter() - started
    out.table2 = table
    out.summary = {"table2_checks": checks, "fig7": fig7_summary(grid),
                   "fig9": f9.to_dict("records"), "fig4": slopes.to_dict("records"),
                   "after_contact": after_contact_summary(after)}
    return out
