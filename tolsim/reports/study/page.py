"""The HTML page of a study report (``report.html``) and the parts it shares with the PDF:
captions, what was studied, the headline and the sign-off fields."""

import html
import os
from datetime import UTC, datetime

import numpy as np

from tolsim import __version__
from tolsim.reports.assumptions import (
    assumption_table,
    tolerance_table,
)
from tolsim.reports.result_view import (
    config_or_none,
    integer,
    number,
    unverified_reason,
)
from tolsim.reports.study.friction import (
    FRICTION_CAPTION,
    friction_content,
    friction_indices,
    friction_summary,
    without_output,
)
from tolsim.reports.study.sections import carriage_content, carriage_summary, section_titles
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
    data_uri,
)
from tolsim.reports.verdict import (
    ESTIMATOR_NAMES,
    FAIL,
    PASS,
    STATUS_LABELS,
    UNDECIDED,
    any_train,
    contact_unit,
    has_friction,
    study_verdict,
    tracks_of,
)
from tolsim.study.statistics.quality import format_fraction

# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------
CSS = """
p.unverified { border: 2px solid #b00020; color: #b00020; padding: 0.5em 0.8em; }
body { font-family: -apple-system, 'Segoe UI', Helvetica, Arial, sans-serif; max-width: 1150px;
       margin: 2em auto; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.6em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ddd;
     padding-bottom: 0.2em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.93em; }
td, th { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f3f3f3; } td.num { text-align: right; font-variant-numeric: tabular-nums; }
img { max-width: 100%; border: 1px solid #eee; } .muted { color: #666; font-size: 0.9em; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.verdict { font-weight: bold; } .bad { color: #b00; } .good { color: #070; }
.verdict-box { border: 3px solid #888; border-radius: 6px; padding: 0.6em 1.1em;
               margin: 1.2em 0; background: #fafafa; }
.verdict-box.pass { border-color: #070; background: #f3fbf3; }
.verdict-box.fail { border-color: #b00; background: #fdf3f3; }
.verdict-box.undecided { border-color: #c80; background: #fffaf0; }
.verdict-label { font-size: 1.45em; font-weight: bold; margin: 0.2em 0 0.4em 0; }
.status-pass { color: #070; font-weight: bold; } .status-fail { color: #b00; font-weight: bold; }
.status-undecided { color: #a60; font-weight: bold; } .status-none { color: #555; }
table.signoff td { height: 2.6em; min-width: 11em; }
"""

#: Captions of the figures (HTML and PDF).
CAPTIONS = {
    "velocity_deviation": "(a) ε distribution over all valid balls; (b) ε per position along "
                          "the train, mean ± 1 std; (c) the side force ratio ρ of the load "
                          "at each position, on its own scale (a load, not a deviation: it "
                          "has nothing to do with the spec limit on ε).",
    "contact": "Survival curve of the time to first contact (travel on the top axis), "
               "contact probability with its 95 % interval, and the pair that touches first.",
    "quality": "Tails of ε on a log scale against the spec limit.",
    "sensitivity": "Sobol' indices: first order (the factor alone) and total effect (with "
                   "interactions).",
    "spot_checks": "Balls re-solved with the full friction model: circles drawn uniformly "
                   "over all balls, diamonds drawn among the balls near the spec limit on "
                   "|ε|, where the ppm and Cpk claims are made.",
}
#: Captions of the figures of a carriage study, where they differ from :data:`CAPTIONS`.
CARRIAGE_CAPTIONS = {
    "carriage": "The nominal load distribution (the assembly without errors): (a) the normal "
                "load N_y of every ball against its position along the rail, with the load of "
                "the preload alone, and (b) its side force ratio ρ = N_x / N_y, one series "
                "per track.",
    "velocity_deviation": "(a) ε distribution over all valid balls of every track; (b) ε per "
                          "position along the train, mean ± 1 std, one series per track; "
                          "(c) the side force ratio ρ of the nominal carriage at each "
                          "position, per track, on its own scale (a load, not a deviation: "
                          "it has nothing to do with the spec limit on ε).",
    "contact": "Survival curve of the time to first contact of an assembly (the earliest of "
               "its trains; travel on the top axis), the contact probability per assembly "
               "with its 95 % interval, and the pair that touches first, per track.",
}


def captions(ds) -> dict:
    """Figure name -> caption (HTML and PDF): :data:`CAPTIONS`, with those of
    :data:`CARRIAGE_CAPTIONS` in a carriage study."""
    out = {**CAPTIONS, **CARRIAGE_CAPTIONS} if tracks_of(ds) else dict(CAPTIONS)
    if has_friction(ds):
        out["friction"] = FRICTION_CAPTION
    return out


#: Fields of the sign-off block (HTML and PDF).
SIGN_OFF_ROLES = ("Prepared by", "Reviewed by", "Approved by")
SIGN_OFF_FIELDS = ("name", "function", "date", "signature")
SIGN_OFF_DECISIONS = ("accepted", "accepted with conditions", "rejected")


#: The events a rare-event estimator can estimate (issue 15), with their names on the page.
RARE_EVENTS = (("contact_probability", "ball-to-ball contact within the stroke"),
               ("velocity_deviation_exceedance_probability",
                "|ε| over its limit (any ball of an assembly)"),
               ("friction_exceedance_probability", "friction increase over its limit"))


def rare_events_html(ds) -> list:
    """The rare-event estimates of a file (``[study] estimator``), as HTML parts: per event
    the estimator, P, CV, interval and model evaluations, its status (with the reason when
    not ``ok``) and diagnostics, with ``estimator = "rare"`` each estimator's own number,
    and for importance sampling the design point ("the most likely way to fail") per
    tolerance source. Empty for a plain Monte Carlo file."""
    rows, points = [], []
    for name, what in RARE_EVENTS:
        if name not in ds.variables or f"{name}_evaluations" not in ds.variables:
            continue
        attrs = ds[name].attrs
        fallback = str(attrs.get("estimator_fallback", ""))
        if attrs.get("estimator", "monte_carlo") == "monte_carlo" and not fallback:
            continue
        p = number(ds, name)
        lo, hi = number(ds, f"{name}_ci_lower"), number(ds, f"{name}_ci_upper")
        # an estimator that did not reach the event: its status and message are on the
        # _status variable, the numbers the plain run's (tolsim.io.schema.rare_events)
        own = ds[f"{name}_status"].attrs if fallback else attrs
        status = str(own.get("estimator_status", "ok"))
        flag = status if status == "ok" else f"<b>{html.escape(status.upper())}</b>"
        if own.get("estimator_message"):
            flag += f": {html.escape(str(own['estimator_message']))}"
        estimator = str(own.get("estimator", ""))
        value = format_fraction(p, lo, hi) + (" (the plain run's)" if fallback else "")
        if fallback:
            value += _plain_bounds_text(ds, name)
        cv = number(ds, f"{name}_coefficient_of_variation")
        rows.append(
            f"<tr><td>{html.escape(what)}</td>"
            f"<td>{html.escape(ESTIMATOR_NAMES.get(estimator, estimator))}"
            f"</td><td class='num'>{html.escape(value)}</td>"
            f"<td class='num'>{'n/a' if np.isnan(cv) else f'{cv:.3g}'}</td>"
            f"<td class='num'>{integer(ds, f'{name}_evaluations'):,}</td>"
            f"<td>{flag}</td><td>{html.escape(diagnostics_text(ds, name))}</td>"
            f"<td>{html.escape(fallback or str(attrs.get('interval', '')))}"
            f"{html.escape(' ' + str(attrs['note'])) if attrs.get('note') else ''}</td></tr>")
        prefix = name.removesuffix("_probability")  # contact_, ..._exceedance_
        if f"{prefix}_reliability_index" in ds.variables and "factor_name" in ds.variables:
            points.append(_design_point_table(ds, prefix, what))
    if not rows:
        return []
    return ["<h3>Rare events</h3><p>Estimated after the plain run by the estimator named, "
            "in the study's standard-normal input space (README \"Rare events\"); each "
            "interval is the estimator's own. A status other than ok means the estimator "
            "does not back the number (a failed diagnostic, or subset simulation and "
            "importance sampling disagree): the verdict on it is undecided.</p>"
            "<table><tr><th>event</th><th>estimator</th>"
            "<th>P (95 % interval)</th><th>CV</th><th>model evaluations</th>"
            "<th>status</th><th>diagnostics</th><th>interval</th></tr>", *rows, "</table>",
            *points]


def _plain_bounds_text(ds, name) -> str:
    """The bounds of a plain-run probability with unresolved trains or assemblies, counted as
    without and with the event ("" when every outcome is known, or the file has no bounds)."""
    low, high = number(ds, f"{name}_bound_lower"), number(ds, f"{name}_bound_upper")
    if not (np.isfinite(low) and np.isfinite(high)) or low == high:
        return ""
    upper = format_fraction(high)  # "1.17 %" or "117 ppm": the lower bound in its unit
    scale = 1e6 if upper.endswith("ppm") else 1e2
    return (f"; bounds with the unresolved ones counted as without / with it: "
            f"{scale * low:.3g} to {upper}")


#: The diagnostics of a rare-event estimate in the report: variable suffix -> format.
DIAGNOSTIC_FORMATS = {
    "effective_sample_size": "effective failing samples {:.4g}",
    "largest_weight_share": "largest weight {:.2%}",
    "form_ratio": "P_FORM / P_IS {:.3g}",
    "ancestors": "{:.0f} level-0 ancestors",
    "level_independent_coefficient_of_variation": "CV with independent levels {:.3g}",
}


#: The report's words for the ``estimator_mode_check`` attribute.
MODE_CHECK_TEXT = {
    "design_points": "checked for a lost mode against FORM design points",
    "replicates": "checked for a lost mode by two independent runs (a mode both miss is not "
                  "seen)",
    "none": "unchecked for a lost mode (no FORM design points)",
}


def diagnostics_text(ds, name) -> str:
    """The diagnostics of the estimate ``name`` in one line, and with ``estimator = "rare"``
    each estimator's number with its interval and status ("" when the file has none)."""
    values = {suffix: number(ds, f"{name}_{suffix}") for suffix in DIAGNOSTIC_FORMATS
              if f"{name}_{suffix}" in ds.variables}
    parts = [DIAGNOSTIC_FORMATS[suffix].format(value) for suffix, value in values.items()
             if np.isfinite(value) and (suffix != "ancestors" or value > 0)]
    check = ds[name].attrs.get("estimator_mode_check", "") if name in ds.variables else ""
    if check:
        parts.append(MODE_CHECK_TEXT.get(check, f"lost-mode check {check}"))
    for part, title in (("subset", "subset simulation"), ("importance", "importance sampling"),
                        ("replicate_1", "first run"), ("replicate_2", "second run")):
        var = f"{name}_{part}"
        if var in ds.variables:
            value = format_fraction(number(ds, var), number(ds, f"{var}_ci_lower"),
                                    number(ds, f"{var}_ci_upper"))
            parts.append(f"{title} {value} ({ds[var].attrs.get('estimator_status', '')})")
    return "; ".join(parts)


def _design_point_table(ds, name, what) -> str:
    """The design point of an importance-sampling estimate, most important source first
    (``name``: the event's variable prefix, e.g. ``contact``)."""
    names = [str(n) for n in np.asarray(ds["factor_name"])]
    alpha = np.asarray(ds[f"{name}_importance_factor"], dtype=float)
    u = np.asarray(ds[f"{name}_design_point_standard_normal"], dtype=float)
    length = np.asarray(ds[f"{name}_design_point_length"], dtype=float)
    angle = np.asarray(ds[f"{name}_design_point_angle"], dtype=float)
    element = np.asarray(ds[f"{name}_design_point_element"])
    out = [f"<p>The most likely way to fail ({html.escape(what)}): reliability index β = "
           f"{number(ds, f'{name}_reliability_index'):.3f}, FORM estimate "
           f"{html.escape(format_fraction(number(ds, f'{name}_form_probability')))}.</p>"
           "<table><tr><th>tolerance source</th><th>value at the design point</th>"
           "<th>standard normal u</th><th>importance factor α²</th><th>ball / pair / track"
           "</th></tr>"]
    for i in np.argsort(-np.nan_to_num(alpha), kind="stable"):
        value = (f"{1e6 * length[i]:+.3g} µm" if np.isfinite(length[i]) else
                 f"{np.rad2deg(angle[i]):+.3g}°" if np.isfinite(angle[i]) else "n/a")
        out.append(f"<tr><td>{html.escape(names[i])}</td><td class='num'>{value}</td>"
                   f"<td class='num'>{u[i]:+.3f}</td><td class='num'>{alpha[i]:.3f}</td>"
                   f"<td class='num'>{html.escape(str(element[i]))}</td></tr>")
    out.append("</table>")
    return "".join(out)


def _row(label, value, num=True):
    cls = ' class="num"' if num else ""
    return f"<tr><th>{html.escape(label)}</th><td{cls}>{html.escape(str(value))}</td></tr>"


def tolerance_rows(ds):
    """Tolerance table rows (:func:`tolsim.reports.assumptions.tolerance_table`), the initial
    gap included; the config's keys as written when it cannot be parsed."""
    return tolerance_table(config_or_none(ds), ds)


def _sign_off_title(ds) -> str:
    k = (1 if tracks_of(ds) else 0) + (1 if has_friction(ds) else 0)
    return f"{8 + k}. Review and sign-off"


def study_facts(ds) -> list:
    """(label, value, numeric) rows of "what was studied" (HTML and PDF)."""
    a = ds.attrs
    tracks = tracks_of(ds)
    if tracks:
        balls = ds.sizes.get("ball", 0)
        head = [("assemblies (carriages, one train per track) sampled",
                 f"{integer(ds, 'n_assemblies'):,}", True),
                ("tracks (trains) per carriage", tracks, True),
                ("balls per train (track)", balls, True),
                ("balls per carriage", tracks * balls, True)]
    else:
        head = [("assemblies (trains) sampled", f"{integer(ds, 'n_assemblies'):,}", True),
                ("balls per train", ds.sizes.get("ball", "?"), True)]
    return [
        *head,
        ("balls evaluated", f"{integer(ds, 'n_balls'):,}", True),
        ("stroke duration (horizon)", f"{number(ds, 'horizon'):.4g} s", True),
        ("carriage speed v", f"{1e3 * number(ds, 'groove_velocity'):.4g} mm/s", True),
        ("carriage travel", f"{1e3 * number(ds, 'horizon') * number(ds, 'groove_velocity'):.4g} mm",
         True),
        ("velocity model", a.get("velocity_model", "?"), False),
        ("static contact model", a.get("static_model", "?"), False),
        ("propagation", a.get("propagation", "?"), False),
        ("sampling", a.get("sampling", "?"), False),
        ("seed", a.get("seed", "?"), True),
        ("source", a.get("source", "?"), False),
        ("history", a.get("history", "?"), False),
    ]


def headline(ds, sens=None) -> list:
    """The key sentences of a report (the top of the HTML page and of the PDF)."""
    n_asm = integer(ds, "n_assemblies")
    n_unres = integer(ds, "n_assemblies_unresolved")
    p, lo, hi = (number(ds, x) for x in ("contact_probability", "contact_probability_ci_lower",
                                      "contact_probability_ci_upper"))
    travel = 1e3 * number(ds, "horizon") * number(ds, "groove_velocity")
    one, many = contact_unit(ds)
    tracks = tracks_of(ds)
    per = (f"per assembly: contact in {any_train(tracks, 'the')} of a carriage"
           if tracks else "per train")
    out = [f"P(ball-to-ball contact within the {travel:.4g} mm stroke) = "
           f"{format_fraction(p, lo, hi)} {per} ({integer(ds, 'n_contact'):,} of "
           f"{n_asm - n_unres:,} {many} whose outcome is known)."]
    if tracks_of(ds):
        out.append(carriage_summary(ds))
    if has_friction(ds):
        out.append(friction_summary(ds))
    if sens is not None and "contact" in getattr(sens, "outputs", ()):
        k = list(sens.outputs).index("contact")
        total = np.asarray(sens.total[k], dtype=float)
        if np.any(np.isfinite(total)):
            top = int(np.nanargmax(total))
            name = sens.factors[top]
            text = (f"It rests most on {name} (total Sobol' index {total[top]:.2f} for "
                    "contact)")
            if name == "initial_gap":
                text += (": the assumed initial gap between the balls ([train] initial_gap), "
                         "not a measured tolerance; see the tolerance and assumptions tables")
            out.append(text + ".")
    return out


def _verdict_html(verdict, lines):
    cls = {PASS: "pass", FAIL: "fail", UNDECIDED: "undecided"}.get(verdict.status, "none")
    parts = [f"<div class='verdict-box {cls}' id='verdict'>",
             f"<p class='verdict-label'>Verdict: {html.escape(verdict.label)}</p>",
             *(f"<p>{html.escape(s)}</p>" for s in lines),
             "<table><tr><th>quantity</th><th>requirement</th><th>estimate</th>"
             "<th>verdict</th><th>why</th></tr>"]
    for c in verdict.checks:
        scls = {PASS: "status-pass", FAIL: "status-fail",
                UNDECIDED: "status-undecided"}.get(c.status, "status-none")
        parts.append(f"<tr><td>{html.escape(c.quantity)}</td>"
                     f"<td>{html.escape(c.requirement)}</td><td>{html.escape(c.estimate)}</td>"
                     f"<td class='{scls}'>{html.escape(STATUS_LABELS.get(c.status, c.status))}"
                     "</td>"
                     f"<td>{html.escape(c.reason)}</td></tr>")
    parts.append("</table><p class='muted'>Pass: the whole 95 % interval meets the limit; "
                 "fail: the whole interval violates it; undecided: the interval straddles "
                 "it. The spec limits come from the config ([study] section); a quantity "
                 "without one gets no verdict.</p></div>")
    return parts


def _stackup_html(ds):
    """The linear stack-up beside the Monte Carlo (HTML parts; :func:`stackup_table`)."""
    table = stackup_table(ds)
    if table is None:
        return []
    if not table.rows:  # a carriage study: why there is none
        return [f"<h3>{html.escape(table.heading)}</h3>"
                f"<p class='muted'>{html.escape(table.note)}</p>"]
    return table_html(table)


def table_html(table):
    """HTML parts of a :class:`ReportTable` (its heading as h3, its note below)."""
    parts = [f"<h3>{html.escape(table.heading)}</h3><table><tr>"
             + "".join(f"<th>{html.escape(h)}</th>" for h in table.header) + "</tr>"]
    num = ' class="num"'
    for row in table.rows:
        parts.append("<tr>" + "".join(
            f"<td{num if j in table.numeric else ''}>{html.escape(str(c))}</td>"
            for j, c in enumerate(row)) + "</tr>")
    parts.append("</table>")
    if table.note:
        parts.append(f"<p class='muted'>{html.escape(table.note)}</p>")
    return parts


def unverified_html(ds) -> list:
    """The warning of a report on a file whose checksums were not verified (``--no-verify``,
    or a file without checksums; :func:`tolsim.reports.result_view.unverified_reason`); []
    for a verified file."""
    reason = unverified_reason(ds)
    if not reason:
        return []
    return [f"<p class='unverified'><b>Checksums NOT verified</b>: {html.escape(reason)}. The "
            "numbers of this report may not be those tolsim wrote: do not sign off on it.</p>"]


def report_html(ds, figures, sens, sens_source, q, path, verdict=None, carriage=None,
                friction=None, pdf=True):
    """The HTML page of a study report; ``pdf``: whether a ``report.pdf`` is made beside it
    (the page links to it only then)."""
    a = ds.attrs
    tracks = tracks_of(ds)
    verdict = verdict if verdict is not None else study_verdict(ds, q)
    tolerances = tolerance_rows(ds)
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(a.get('title', 'tolsim report'))}</title>",
        f"<style>{CSS}</style></head><body>",
        f"<h1>{html.escape(a.get('title', 'tolsim study'))}</h1>",
        f"<p class='muted'>Report of <code>{html.escape(os.path.basename(path))}</code>, "
        f"made by tolsim {__version__} on "
        f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}. "
        + ("The same report as PDF, with the sign-off fields: <code>report.pdf</code>.</p>"
           if pdf else "Made without a PDF (<code>--no-pdf</code>): the sign-off table is at "
                       "the end of this page.</p>"),
        *unverified_html(ds),
        *_verdict_html(verdict, headline(ds, sens)),
        "<h2>1. What was studied</h2><table>",
        *(_row(label, value, num) for label, value, num in study_facts(ds)),
        "</table>",
    ]
    if tolerances:
        parts += ["<h3 id='tolerances'>Sampled inputs (tolerances and the initial gap)</h3>",
                  "<table><tr><th>input</th><th>scope</th><th>distribution</th>"
                  "<th>parameters</th><th>config</th></tr>"]
        parts += [f"<tr><td>{html.escape(r.source)}</td><td>{html.escape(r.scope)}</td>"
                  f"<td>{html.escape(r.distribution)}</td><td>{html.escape(r.parameters)}</td>"
                  f"<td><code>{html.escape(r.key)}</code></td></tr>" for r in tolerances]
        parts.append(f"</table><p class='muted'>{html.escape(scope_note(ds))}</p>")
    parts += ["<h3 id='assumptions'>Assumptions and where they come from</h3>",
              "<table><tr><th>topic</th><th>assumption</th><th>value</th>"
              "<th>source</th></tr>"]
    parts += [f"<tr><td>{html.escape(r.topic)}</td><td>{html.escape(r.item)}</td>"
              f"<td>{html.escape(r.value)}</td><td>{html.escape(r.source)}</td></tr>"
              for r in assumption_table(ds)]
    parts += [
        "</table>",
        "<details><summary>The study's config (TOML, as stored in the file: rerun it with "
        "<code>tolsim run</code>)</summary>",
        f"<pre>{html.escape(str(a.get('config', '')))}</pre></details>",
    ]
    parts += [
        f"<h2>{GLANCE_TITLE}</h2><table>",
        *(_row(label, value, num) for label, value, num in glance_rows(ds)),
        "</table>",
        *([f"<p class='verdict'>{html.escape(a['propagation_caveat'])}</p>"]
          if a.get("propagation_caveat") else []),
        *rare_events_html(ds),
    ]

    caption_of = captions(ds)

    def fig(name, caption=None):
        caption = caption or caption_of.get(name, name)
        if name in figures:
            parts.append(f"<figure><img alt='{html.escape(caption)}' "
                         f"src='{data_uri(figures[name])}'><figcaption class='muted'>"
                         f"{html.escape(caption)}</figcaption></figure>")

    titles = section_titles(ds)
    if tracks:
        carriage = carriage if carriage is not None else carriage_content(
            ds, config_or_none(ds))
        parts.append(f"<h2 id='carriage'>{html.escape(carriage['heading'])}</h2>")
        parts += [f"<p>{html.escape(text)}</p>" for text in carriage["paragraphs"]]
        for k, table in enumerate(carriage["tables"]):
            parts += table_html(table)
            if k == carriage["figure_after"]:
                fig("carriage")
    parts.append(f"<h2>{html.escape(titles['velocity_deviation'])}</h2>")
    fig("velocity_deviation")
    parts.append(f"<h2>{html.escape(titles['contact'])}</h2>")
    fig("contact")
    if has_friction(ds):
        friction = friction if friction is not None else friction_content(ds, sens)
        parts.append(f"<h2 id='friction'>{html.escape(friction['heading'])}</h2>")
        parts += [f"<p>{html.escape(text)}</p>" for text in friction["paragraphs"]]
        for k, table in enumerate(friction["tables"]):
            parts += table_html(table)
            if k == friction["figure_after"]:
                fig("friction")
        parts += [f"<p class='muted'>{html.escape(text)}</p>" for text in friction["notes"]]
    parts.append(f"<h2>{html.escape(titles['quality'])}</h2>")
    if q:
        parts += ["<table>", *(_row(label, value) for label, value in
                               quality_rows(ds, q, verdict)), "</table>",
                  f"<p class='muted'>{html.escape(quality_note(ds))}</p>"]
        fig("quality")
    else:
        parts.append(f"<p>{html.escape(NO_LIMIT_TEXT)}</p>")
    parts += _stackup_html(ds)
    parts.append(f"<h2>{html.escape(titles['sensitivity'])}</h2>")
    if friction_indices(sens) is not None:
        parts.append("<p class='muted'>The drivers of the friction increase are ranked in "
                     f"section {html.escape(titles['friction'].split('.')[0])}.</p>")
    sens = without_output(sens)
    if sens is None:
        parts.append(f"<p>{html.escape(sens_source)}</p>")
    elif len(sens.factors) == 0:
        parts.append(f"<p>{html.escape(NO_FACTORS_TEXT)}</p>")
    else:
        parts.append(f"<p class='muted'>{html.escape(sens_source)}</p>")
        fig("sensitivity")
        for block in sensitivity_blocks(sens, ds):
            table = block["table"]
            if table is None:
                parts.append(f"<p>{html.escape(block['lead'])}</p>")
                continue
            parts.append(f"<p class='verdict'>{html.escape(block['lead'])}</p>")
            parts += table_html(table)
    parts.append(f"<h2>{html.escape(titles['spot_checks'])}</h2>")
    fig("spot_checks")
    parts.append(f"<p class='muted'>{html.escape(str(a.get('spot_check_status', '')))}</p>")
    parts.append(f"<h2 id='sign-off'>{_sign_off_title(ds)}</h2><table class='signoff'><tr>"
                 "<th></th>" + "".join(f"<th>{f}</th>" for f in SIGN_OFF_FIELDS) + "</tr>")
    for role in SIGN_OFF_ROLES:
        parts.append(f"<tr><th>{role}</th>" + "<td></td>" * len(SIGN_OFF_FIELDS) + "</tr>")
    parts.append("</table><p>Decision: " + " &nbsp; ".join(
        f"&#9744; {d}" for d in SIGN_OFF_DECISIONS) + "</p>")
    parts.append("<h2>Provenance</h2><table>")
    parts += [_row(key, value, False) for key, value in provenance_rows(ds)]
    parts.append("</table></body></html>")
    return "\n".join(parts)
