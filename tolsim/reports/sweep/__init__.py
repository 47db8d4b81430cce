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

The package: :mod:`~tolsim.reports.sweep.points` (the layout, the points, their numbers and
``points.csv``), :mod:`~tolsim.reports.sweep.figures`, :mod:`~tolsim.reports.sweep.page`
(``report.html``) and :mod:`~tolsim.reports.sweep.report` (the driver,
:func:`make_sweep_report`).
"""

from tolsim.reports.sweep.figures import (
    FIGURES,
    Series,
    plot_contact_probability,
    plot_friction,
    plot_velocity_deviation,
    point_column,
    series_of,
)
from tolsim.reports.sweep.page import (
    EXTRA_CSS,
    headline,
    sweep_html,
    verdict_summary,
)
from tolsim.reports.sweep.points import (
    CHECK_NAMES,
    CSV_COLUMNS,
    CSV_NAME,
    FRICTION_CSV_COLUMNS,
    FRICTION_LEVELS,
    HTML_NAME,
    SPOT_CHECK_COUNT,
    STATUS_ORDER,
    SWEEP_ATTRIBUTES,
    VELOCITY_DEVIATION_LEVELS,
    NotASweep,
    Point,
    any_unresolved,
    csv_rows,
    csv_text,
    is_sweep_dataset,
    is_sweep_file,
    point_dataset,
    sweep_layout,
    sweep_points,
    unit_text,
    value_text,
)
from tolsim.reports.sweep.report import (
    SweepReportOutputs,
    make_sweep_report,
)

__all__ = [
    "CHECK_NAMES", "CSV_COLUMNS", "CSV_NAME", "EXTRA_CSS", "FIGURES", "FRICTION_CSV_COLUMNS",
    "FRICTION_LEVELS", "HTML_NAME", "NotASweep", "Point", "SPOT_CHECK_COUNT", "STATUS_ORDER",
    "SWEEP_ATTRIBUTES", "Series", "SweepReportOutputs", "VELOCITY_DEVIATION_LEVELS",
    "any_unresolved", "csv_rows", "csv_text", "headline", "is_sweep_dataset", "is_sweep_file",
    "make_sweep_report", "plot_contact_probability", "plot_friction",
    "plot_velocity_deviation", "point_column", "point_dataset", "series_of", "sweep_html",
    "sweep_layout", "sweep_points", "unit_text", "value_text", "verdict_summary",
]
