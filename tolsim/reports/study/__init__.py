"""The report of a study result file (``tolsim report``): a self-contained HTML page, the
same report as PDF with the reviewers' sign-off block, and PNGs.

:func:`make_report` reads a result written by ``tolsim run`` (:mod:`tolsim.io.netcdf`) and
writes, into a folder:

* ``velocity_deviation.png``: the epsilon distribution (histogram) with the spec limit,
  epsilon along the train (mean and standard deviation per ball position) and, in a panel of
  its own, the side force ratio rho per position;
* ``contact.png``: the survival curve P(no contact by t) with a pointwise 95 % band, the
  contact probability with its interval against a spec limit, and which pair touches first;
* ``spot_checks.png``: the study's velocity model against the full model on the spot-checked
  balls (circles drawn uniformly, diamonds near the spec limit), with the counts beside it;
* ``sensitivity.png``: the tolerance sources ranked by their Sobol' total-effect index on
  epsilon and on the contact indicator (:mod:`tolsim.study.analyses.sensitivity`);
* ``quality.png`` (with a limit on |epsilon|): the tails of epsilon on a log scale against
  the limit, the fraction out of spec and Cpk (:mod:`tolsim.study.statistics.quality`);
* ``report.html`` with all of them embedded as data URIs: at the top the verdict against the
  config's spec limits (:mod:`tolsim.reports.verdict`), then what was studied with the
  sampled inputs (the initial gap included) and the assumptions table
  (:mod:`tolsim.reports.assumptions`), the config and provenance, and a sign-off table;
* ``report.pdf``: the same for review and sign-off (:mod:`tolsim.reports.pdf`).

A study with ``[contact]`` (the friction variables of :mod:`tolsim.io.schema.friction` in the
file) gets a section "What contact costs" after the contact section (:func:`friction_content`,
``friction.png`` from :func:`plot_friction`): the distribution of the friction increase
against its spec limit with P(increase > limit), example traces of the friction force and the
balls against the carriage travel, the quantiles of the ripple and of the largest
ball-to-ball force, the contact fraction, and the drivers (Sobol' indices of the increase);
the verdict gets the friction row (:func:`tolsim.reports.verdict.friction_check`) and the
assumptions table the contact model. Files without them are reported as before.

A study with a ``[carriage]`` (a ``track`` dimension in the file: an assembly is a carriage
with one train per track) gets, besides, a section "Carriage" after the results at a glance
(:func:`carriage_content`): the load case in catalogue terms, the preload, the tracks with the
nominal load distribution (``carriage.png``, :func:`plot_carriage_loads`: N_y, N_x and rho
against the ball position along the rail, per track), the carriage displacement and stiffness
of the nominal assembly with their scatter over the sampled ones, and the carriages not
solved. Its per-ball and per-pair figures draw one series per track, and P(contact) is per
assembly (any of its trains). A study of single trains is reported exactly as before.

Sensitivity indices are taken from the file when ``tolsim run`` stored them (``factor``
dimension, ``sensitivity_first_order`` / ``sensitivity_total``); otherwise they are computed
here from the config embedded in the file (same seed), unless disabled.

The package: :mod:`~tolsim.reports.study.report` (the driver, :func:`make_report`),
:mod:`~tolsim.reports.study.figures`, :mod:`~tolsim.reports.study.sections` (the tables, the
section titles and the carriage section), :mod:`~tolsim.reports.study.friction`,
:mod:`~tolsim.reports.study.page` (the HTML page and what it shares with the PDF) and
:mod:`~tolsim.reports.study.sensitivity`; the result file is read through
:mod:`tolsim.reports.result_view`.
"""

from tolsim.reports.result_view import (
    NotAResult,
    read_result_file,
)
from tolsim.reports.study.figures import (
    OUTPUT_SHORT,
    OUTPUT_TITLES,
    STRATUM_MARKERS,
    TRACK_COLOURS,
    output_titles,
    plot_carriage_loads,
    plot_contact,
    plot_quality,
    plot_sensitivity,
    plot_spot_checks,
    plot_velocity_deviation,
    track_labels,
)
from tolsim.reports.study.friction import (
    FRICTION_CAPTION,
    FRICTION_HISTOGRAMS,
    FRICTION_LEVELS,
    FRICTION_OUTPUT,
    friction_content,
    friction_indices,
    friction_summary,
    plot_friction,
    without_output,
)
from tolsim.reports.study.page import (
    CAPTIONS,
    CARRIAGE_CAPTIONS,
    CSS,
    RARE_EVENTS,
    SIGN_OFF_DECISIONS,
    SIGN_OFF_FIELDS,
    SIGN_OFF_ROLES,
    captions,
    headline,
    rare_events_html,
    report_html,
    study_facts,
    table_html,
    tolerance_rows,
    unverified_html,
)
from tolsim.reports.study.report import (
    ReportOutputs,
    make_report,
    pdf_content,
    render_report_pdf,
    write_report_pdf,
)
from tolsim.reports.study.sections import (
    CARRIAGE_DOF_LABELS,
    CARRIAGE_STATISTICS,
    ReportTable,
    carriage_content,
    carriage_dof_rows,
    carriage_summary,
    section_titles,
)
from tolsim.reports.study.sensitivity import (
    SENSITIVITY_SAMPLES,
    FileSensitivity,
    compute_sensitivity,
    sensitivity_from_file,
)

__all__ = [
    "CAPTIONS", "CARRIAGE_CAPTIONS", "CARRIAGE_DOF_LABELS", "CARRIAGE_STATISTICS", "CSS",
    "FRICTION_CAPTION", "FRICTION_HISTOGRAMS", "FRICTION_LEVELS", "FRICTION_OUTPUT",
    "FileSensitivity", "NotAResult", "OUTPUT_SHORT", "OUTPUT_TITLES", "RARE_EVENTS",
    "ReportOutputs", "ReportTable", "SENSITIVITY_SAMPLES", "SIGN_OFF_DECISIONS",
    "SIGN_OFF_FIELDS", "SIGN_OFF_ROLES", "STRATUM_MARKERS", "TRACK_COLOURS", "captions",
    "carriage_content", "carriage_dof_rows", "carriage_summary", "compute_sensitivity",
    "friction_content", "friction_indices", "friction_summary", "headline", "make_report",
    "output_titles", "pdf_content", "plot_carriage_loads", "plot_contact", "plot_friction",
    "plot_quality", "plot_sensitivity", "plot_spot_checks", "plot_velocity_deviation",
    "rare_events_html", "read_result_file", "report_html", "section_titles",
    "sensitivity_from_file", "study_facts", "table_html", "tolerance_rows", "track_labels",
    "without_output", "render_report_pdf", "write_report_pdf", "unverified_html",
]
