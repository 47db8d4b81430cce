"""The driver of a study report: :func:`make_report` writes the PNGs, ``report.html`` and
``report.pdf`` of a result file."""

import math
import os
from dataclasses import dataclass, field
from datetime import UTC, datetime

from tolsim import __version__
from tolsim.reports import pdf
from tolsim.reports.assumptions import (
    assumption_table,
)
from tolsim.reports.files import check_folder, write_files
from tolsim.reports.result_view import (
    config_or_none,
    read_result_file,
    unverified_reason,
)
from tolsim.reports.study.figures import (
    plot_carriage_loads,
    plot_contact,
    plot_quality,
    plot_sensitivity,
    plot_spot_checks,
    plot_velocity_deviation,
)
from tolsim.reports.study.friction import (
    ball_diameter_of,
    friction_content,
    friction_indices,
    plot_friction,
    without_output,
)
from tolsim.reports.study.page import (
    SIGN_OFF_DECISIONS,
    SIGN_OFF_FIELDS,
    SIGN_OFF_ROLES,
    captions,
    headline,
    report_html,
    study_facts,
    tolerance_rows,
)
from tolsim.reports.study.sections import ReportTable, carriage_content, section_titles
from tolsim.reports.study.sensitivity import (
    compute_sensitivity,
    config_error_text,
    sensitivity_from_file,
)
from tolsim.reports.study.shared import (
    GLANCE_TITLE,
    NO_FACTORS_TEXT,
    NO_LIMIT_TEXT,
    glance_rows,
    provenance_rows,
    quality_note,
    quality_rows,
    scope_note,
    sensitivity_blocks,
    stackup_table,
)
from tolsim.reports.style import (
    render_png,
)
from tolsim.reports.verdict import (
    contact_unit,
    has_friction,
    study_verdict,
    tracks_of,
)
from tolsim.study.statistics import quality


@dataclass
class ReportOutputs:
    """Files written by :func:`make_report` and the numbers shown."""

    folder: str
    html: str = ""
    figures: dict = field(default_factory=dict)
    sensitivity: object = None
    sensitivity_source: str = ""
    quality: dict = field(default_factory=dict)
    verdict: object = None  # tolsim.reports.verdict.Verdict
    pdf: str = ""
    friction: dict | None = None  # friction_content of a study with [contact]



# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------
def make_report(path, folder, *, sensitivity=True, sensitivity_samples=None,
                progress=None, pdf=True, out_of_spec_limit=None,
                cpk_minimum=None, friction_exceedance_limit=None,
                verify=True) -> ReportOutputs:
    """Write ``report.html``, ``report.pdf`` and the PNGs of a result file into ``folder``.

    Every output is made in memory before anything is written, and then written through
    temporary files and renames (:func:`tolsim.reports.compare.write_files`): on an error (a
    full disk, say) no file is left half-written and what this call wrote is removed.

    Parameters
    ----------
    path : str or path
        A result file of ``tolsim run``.
    folder : str or path
        Output folder (created if missing).
    sensitivity : bool
        Compute the Sobol' indices from the embedded config when the file has none.
    sensitivity_samples : int, optional
        Base-sample size for that (default :data:`SENSITIVITY_SAMPLES`).
    progress : callable, optional
        Called with a short message before each step.
    pdf : bool
        Also write ``report.pdf`` with the sign-off block (:mod:`tolsim.reports.pdf`).
    out_of_spec_limit, cpk_minimum : float, optional
        Allowed fraction of balls out of spec and required Cpk for the verdict
        (:func:`tolsim.reports.verdict.study_verdict`); the config has no keys for them.
    friction_exceedance_limit : float, optional
        Allowed fraction of assemblies whose friction increase exceeds the config's limit
        (a study with ``[contact]``), for the verdict; the config has no key for it.
    verify : bool
        Verify the file's checksums (:func:`tolsim.reports.result_view.read_result_file`);
        False for forensics.

    Returns
    -------
    ReportOutputs

    Raises
    ------
    NotAResult
        If ``path`` is not a tolsim result.
    ValueError
        Naming a spec limit that is not a number in its range (a fraction in (0, 1), a Cpk
        > 0); it was taken as "no spec limit given".
    """
    for name, value, top in (("out_of_spec_limit", out_of_spec_limit, 1.0),
                             ("friction_exceedance_limit", friction_exceedance_limit, 1.0),
                             ("cpk_minimum", cpk_minimum, math.inf)):
        if value is not None and not 0.0 < float(value) < top:
            raise ValueError(f"{name} = {value!r} must be in (0, {top:g})")
    check_folder(folder)
    say = progress or (lambda msg: None)
    ds = read_result_file(path, verify=verify)
    folder = os.fspath(folder)
    out = ReportOutputs(folder)
    sens = sensitivity_from_file(ds)
    if sens is not None:
        source = "Sobol' indices stored in the result file by tolsim run."
    elif sensitivity and (config_error := config_error_text(ds)):
        source = ("Sensitivity indices not computed: the config stored in the file cannot "
                  f"be parsed by this tolsim version ({config_error}).")
    elif sensitivity:
        say("sensitivity (Sobol' indices from the embedded config)")
        sens = compute_sensitivity(ds, sensitivity_samples)
        source = (f"Computed by tolsim report from the config stored in the file (seed "
                  f"{ds.attrs.get('seed')}): Saltelli/Jansen estimators, n = {sens.n} "
                  f"assemblies per base sample, {sens.evaluations:,} assemblies in all, "
                  f"95 % bootstrap intervals. ε is pooled over the train positions"
                  + (" of every track" if tracks_of(ds) else "")
                  + " (the share of the variance at a fixed position, so the load's "
                    "variation along the train is not counted as a tolerance effect).")
    else:
        source = "Sensitivity analysis not requested (--no-sensitivity)."
    out.sensitivity, out.sensitivity_source = sens, source
    q = quality.dataset_quality(ds)
    out.quality = q
    out.verdict = study_verdict(ds, q, out_of_spec_limit=out_of_spec_limit,
                                cpk_minimum=cpk_minimum,
                                friction_exceedance_limit=friction_exceedance_limit)

    say("figures")
    figs = {}
    carriage = None
    if tracks_of(ds):  # a carriage study: its section and the load distribution
        carriage = carriage_content(ds, config_or_none(ds))
        figs["carriage"] = plot_carriage_loads(ds, carriage["ball_z"],
                                               carriage["preload_ball_load"])
    figs.update({"velocity_deviation": plot_velocity_deviation(ds),
                 "contact": plot_contact(ds), "spot_checks": plot_spot_checks(ds)})
    if has_friction(ds):  # a study with [contact]: what contact costs
        out.friction = friction_content(ds, sens)
        figs["friction"] = plot_friction(ds, sens, ball_diameter_of(ds, config_or_none(ds)))
    if q:
        figs["quality"] = plot_quality(ds, q)
    if sens is not None and len(sens.factors):
        figs["sensitivity"] = plot_sensitivity(without_output(sens), contact_unit(ds)[0])
    pngs = {name: render_png(fig) for name, fig in figs.items()}
    say("report.html")
    files = {f"{name}.png": png for name, png in pngs.items()}
    files["report.html"] = report_html(ds, pngs, sens, source, q, os.fspath(path), out.verdict,
                                       carriage, out.friction, pdf=pdf).encode("utf-8")
    if pdf:
        say("report.pdf")
        files["report.pdf"] = render_report_pdf(ds, figs, sens, out.verdict, path, carriage,
                                                out.friction, q, source)
    written = write_files(folder, files)
    out.figures = {name: written[f"{name}.png"] for name in pngs}
    out.html = written["report.html"]
    out.pdf = written.get("report.pdf", "")
    return out


def render_report_pdf(ds, figs, sens, verdict, path, carriage=None, friction=None,
                      q=None, sens_source="") -> bytes:
    """The PDF of a report as bytes (:func:`tolsim.reports.pdf.render_pdf`; the arguments
    as for :func:`pdf_content`)."""
    return pdf.render_pdf(**pdf_content(ds, figs, sens, verdict, path, carriage, friction, q,
                                        sens_source))


def write_report_pdf(ds, figs, sens, verdict, path, pdf_path, carriage=None,
                     friction=None) -> str:
    """The PDF of a report (:func:`tolsim.reports.pdf.write_pdf`): ``figs`` are the report's
    Figures by name, rendered again at :data:`tolsim.reports.pdf.FIGURE_DPI`; ``carriage``
    the section of a carriage study (:func:`carriage_content`, made when not given),
    ``friction`` that of a study with ``[contact]`` (:func:`friction_content`, likewise)."""
    return pdf.write_pdf(pdf_path, **pdf_content(ds, figs, sens, verdict, path, carriage,
                                                 friction))


def pdf_content(ds, figs, sens, verdict, path, carriage=None, friction=None, q=None,
                sens_source="") -> dict:
    """The arguments of :func:`tolsim.reports.pdf.report_pages` for a result file (with
    ``carriage``, the section of :func:`carriage_content`, in a carriage study, and
    ``friction``, the section of :func:`friction_content`, in a study with ``[contact]``;
    ``q`` the quality of :func:`tolsim.study.statistics.quality.dataset_quality`, made when
    not given; ``sens_source`` where the Sobol' indices come from). The PDF holds what the
    HTML page holds (:mod:`tolsim.reports.study.shared`)
    but the config's TOML text and the rare-event tables (README "Reports")."""
    order = ("carriage", "velocity_deviation", "contact", "friction", "quality",
             "sensitivity", "spot_checks")
    pngs = {name: render_png(figs[name], dpi=pdf.FIGURE_DPI) for name in order if name in figs}
    extra = {}
    if tracks_of(ds):
        extra["carriage"] = carriage if carriage is not None else carriage_content(
            ds, config_or_none(ds))
    if has_friction(ds):
        extra["friction"] = friction if friction is not None else friction_content(ds, sens)
    a = ds.attrs
    subtitle = (f"Result file {os.path.basename(os.fspath(path))}, report by tolsim "
                f"{__version__} on {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}; "
                f"study run by {a.get('source', '?')}: {a.get('history', '?')}")
    titles = section_titles(ds)
    q = quality.dataset_quality(ds) if q is None else q
    return dict(
        title=str(a.get("title", "tolsim study")), subtitle=subtitle,
        verdict=verdict, headline=headline(ds, sens),
        facts=[(label, str(value)) for label, value, _ in study_facts(ds)],
        tolerances=tolerance_rows(ds), assumptions=assumption_table(ds), figures=pngs,
        captions=captions(ds),
        sections={"glance": GLANCE_TITLE, **{n: titles[n] for n in order if n in titles}},
        result_path=os.fspath(path),
        sign_off=(SIGN_OFF_ROLES, SIGN_OFF_FIELDS, SIGN_OFF_DECISIONS),
        glance=[(label, str(value)) for label, value, _ in glance_rows(ds)],
        glance_notes=[str(a["propagation_caveat"])] if a.get("propagation_caveat") else [],
        tolerance_note=scope_note(ds) if tolerance_rows(ds) else "",
        section_tables=_section_tables(ds, sens, verdict, q, sens_source),
        provenance=provenance_rows(ds), unverified=unverified_reason(ds), **extra)


def _section_tables(ds, sens, verdict, q, sens_source="") -> dict:
    """What follows the figures of the PDF's sections (:func:`tolsim.reports.pdf.
    report_pages`), as on the HTML page: the quality table and the linear stack-up, the
    ranked Sobol' tables, the spot-check status."""
    out = {}
    if q:
        out["quality"] = [ReportTable("Fraction out of spec and capability", ("quantity",
                                                                               "value"),
                                      tuple(quality_rows(ds, q, verdict)), (0.4, 0.6),
                                      quality_note(ds))]
    else:
        out["quality"] = [NO_LIMIT_TEXT]
    stackup = stackup_table(ds)
    if stackup is not None:
        out["quality"].append(stackup)
    lead = []
    if friction_indices(sens) is not None:
        lead.append("The drivers of the friction increase are ranked in section "
                    f"{section_titles(ds)['friction'].split('.')[0]}.")
    ranked = without_output(sens)
    if ranked is not None and len(ranked.factors) == 0:
        lead.append(NO_FACTORS_TEXT)
    elif sens_source:
        lead.append(sens_source)
    blocks = sensitivity_blocks(sens, ds)
    out["sensitivity"] = lead + [x for b in blocks for x in (b["lead"], b["table"]) if x]
    if ds.attrs.get("spot_check_status"):
        out["spot_checks"] = [str(ds.attrs["spot_check_status"])]
    return out
