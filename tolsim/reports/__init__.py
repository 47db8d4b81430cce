"""Figures and reports (matplotlib), the top of the tolsim layers below the CLI.

* :mod:`tolsim.reports.paper`: the source paper's Fig. 4, 7 and 9 and Table 2 reproduced
  from the models (``tolsim paper``).
* :mod:`tolsim.reports.study`: the HTML report of a study result file (``tolsim report``),
  with the verdict against the spec limits (:mod:`tolsim.reports.verdict`), the sampled
  inputs and the assumptions with their sources (:mod:`tolsim.reports.assumptions`), and the
  same report as PDF with a sign-off block (:mod:`tolsim.reports.pdf`).
* :mod:`tolsim.reports.compare`: studies side by side with the differences and their
  intervals (``tolsim compare``).
* :mod:`tolsim.reports.sweep`: the report of a what-if sweep's file (``tolsim report`` on
  it): the curves against the swept keys and a verdict per point.
* :mod:`tolsim.reports.allocate`: the least-cost tolerances against a probabilistic target,
  with the trade-off curve and the allocated config (``tolsim allocate``).
* :mod:`tolsim.reports.result_view`: the one reader of a result file for the reports, and
  the typed accessors (scalars, attributes, the embedded config) they all read it through.

Figures are built on :class:`matplotlib.figure.Figure` objects directly, never through
``pyplot``: no global state, no GUI backend, nothing to close, and the caller's backend is
left alone. PNGs are rendered by the Agg canvas.
"""

from tolsim.reports.style import new_figure, save_png

__all__ = ["new_figure", "save_png"]
