"""The HTML page of the sweep report (``report.html``): what was swept, the figures, the
table per point and the verdict per point."""

import html
import os
from datetime import UTC, datetime

import numpy as np

from tolsim import __version__
from tolsim.reports.result_view import attribute, integer, number, quantile_value
from tolsim.reports.study import (
    CSS,
    ReportTable,
    study_facts,
    table_html,
    tolerance_rows,
    unverified_html,
)
from tolsim.reports.style import data_uri
from tolsim.reports.sweep.figures import FIGURES, point_column
from tolsim.reports.sweep.points import (
    CHECK_NAMES,
    CSV_NAME,
    FRICTION_LEVELS,
    STATUS_ORDER,
    any_unresolved,
    value_text,
)
from tolsim.reports.verdict import (
    FAIL,
    NO_LIMIT,
    PASS,
    STATUS_LABELS,
    UNDECIDED,
    contact_unit,
    estimator_label,
)
from tolsim.study.design.sweep import Sweep
from tolsim.study.statistics.intervals import format_fraction

# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------
EXTRA_CSS = """
td.status { white-space: nowrap; } td .ci { color: #666; font-size: 0.88em; }
td.lines { white-space: pre-line; }
"""


def _esc(text) -> str:
    return html.escape(str(text))


def _status_cell(check, below="") -> str:
    """A table cell with a check's (or a verdict's) status, its reason on hover and the
    text ``below`` under it."""
    cls = {PASS: "status-pass", FAIL: "status-fail",
           UNDECIDED: "status-undecided"}.get(check.status, "status-none")
    reason = getattr(check, "reason", "")
    title = f" title='{_esc(reason)}'" if reason else ""
    below = f"<br><span class='ci'>{_esc(below)}</span>" if below else ""
    return (f"<td class='status'{title}><span class='{cls}'>"
            f"{_esc(STATUS_LABELS.get(check.status, check.status))}</span>{below}</td>")


def _judged(points) -> list:
    """Indices of the verdict's checks that have a limit at some point."""
    width = max(len(p.verdict.checks) for p in points)
    return [c for c in range(width) if any(
        c < len(p.verdict.checks) and p.verdict.checks[c].status != NO_LIMIT for p in points)]


def _ranges(numbers) -> str:
    """'1-3, 5' of sorted point numbers."""
    out, start = [], None
    for i, n in enumerate(numbers):
        if start is None:
            start = n
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            out.append(f"{start}" if start == n else f"{start}–{n}")
            start = None
    return ", ".join(out)


def _check_title(c, points) -> str:
    """'P(contact) ≤ 70 %', 'fraction of balls with |ε| > 0.5 % ≤ 200 ppm': check ``c``
    with its requirement (the name alone when the requirement varies between points)."""
    checks = [p.verdict.checks[c] for p in points
              if c < len(p.verdict.checks) and p.verdict.checks[c].status != NO_LIMIT]
    requirements = {ch.requirement for ch in checks}
    if len(requirements) != 1:
        return f"{CHECK_NAMES[c]} (its limit varies between the points)"
    requirement = next(iter(requirements))
    if requirement.startswith(("≤", "≥")):
        return f"{checks[0].quantity} {requirement}"
    return requirement


def verdict_summary(points) -> list:
    """One sentence per judged check and one overall: at which points it passes, is
    undecided, fails ([] when the config sets no spec limit)."""
    lines = []
    for c in _judged(points):
        lines.append(f"{_check_title(c, points)}: " + _status_counts(
            [(p.number, p.verdict.checks[c].status) for p in points
             if c < len(p.verdict.checks)]) + ".")
    if lines:
        lines.append("All spec limits together: " + _status_counts(
            [(p.number, p.verdict.status) for p in points]) + ".")
    return lines


def _status_counts(pairs) -> str:
    parts = []
    for status in (*STATUS_ORDER, NO_LIMIT):
        numbers = [n for n, s in pairs if s == status]
        if numbers:
            label = STATUS_LABELS[status] if status != NO_LIMIT else "no limit"
            parts.append(f"{label} at {len(numbers)} point{'s' if len(numbers) > 1 else ''} "
                         f"({_ranges(numbers)})")
    return "; ".join(parts)


def headline(layout: Sweep, points) -> list:
    """The key sentences at the top: how far P(contact) moves over the sweep."""
    one, _ = contact_unit(points[0].ds)
    p = point_column(points, lambda q: number(q.ds, "contact_probability"))
    out = []
    if np.any(np.isfinite(p)):
        lo, hi = int(np.nanargmin(p)), int(np.nanargmax(p))

        def at(k):
            ds = points[k].ds
            text = format_fraction(p[k], number(ds, "contact_probability_ci_lower"),
                                   number(ds, "contact_probability_ci_upper"))
            return f"{text} at point {points[k].number} ({layout.describe(k, units=True)})"

        out.append(f"Over the {layout.size} points, P(ball-to-ball contact within the stroke) "
                   f"per {one} ranges from {at(lo)} to {at(hi)}.")
        if layout.mode == "outer" and len(layout.axes) == 1 and layout.size > 1:
            out.append(f"At the first value of {layout.axes[0].key} it is "
                       f"{format_fraction(p[0])}, at the last {format_fraction(p[-1])}.")
    if any_unresolved(points):
        numbers = [q.number for q in points if integer(q.ds, "n_assemblies_unresolved") > 0]
        out.append(f"Points {_ranges(numbers)} have unresolved {contact_unit(points[0].ds)[1]}"
                   ": there P(contact) is known only within its bounds (table, grey band).")
    return out


def _keys_table(layout: Sweep) -> ReportTable:
    rows = tuple((key.key, key.name, key.units, ", ".join(value_text(v) for v in key.values),
                  str(len(key.values))) for key in layout.axes)
    return ReportTable("Swept keys", ("config key", "coordinate in the file", "units",
                                      "values", "count"), rows, (0.3, 0.25, 0.1, 0.25, 0.1),
                       numeric=(4,))


def _facts_rows(points) -> list:
    """study_facts of every point: one value where the points agree, else the span."""
    per_point = [study_facts(p.ds) for p in points]
    rows = []
    for j, (label, value, numeric) in enumerate(per_point[0]):
        values = [str(facts[j][1]) for facts in per_point]
        if len(set(values)) == 1:
            rows.append((label, value, numeric))
        else:
            rows.append((label, f"per point: {', '.join(values)}", False))
    return rows


def _row(label, value, num=True) -> str:
    cls = " class='num'" if num else ""
    return f"<tr><th>{_esc(label)}</th><td{cls}>{_esc(value)}</td></tr>"


def _points_table(layout: Sweep, points) -> list:
    """HTML of the table per point."""
    one, many = contact_unit(points[0].ds)
    unresolved = any_unresolved(points)
    friction = any(p.friction is not None for p in points)
    judged = bool(_judged(points))
    header = ["point", *(k.label for k in layout.axes), f"P(contact) per {one} (95 % CI)",
              f"contacts / {many} with a known outcome"]
    if unresolved:
        header.append(f"unresolved {many}: bounds over all (95 %)")
    header += ["ε std (95 % CI)", "median first contact, given contact (95 % CI)"]
    if friction:
        header += ["P(friction increase > limit) (95 % CI)",
                   f"friction increase, {100 * FRICTION_LEVELS[-1]:g} % quantile"]
    if judged:
        header.append("verdict")
    parts = ["<table><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in header) + "</tr>"]
    for p in points:
        ds = p.ds
        n_asm, u = integer(ds, "n_assemblies"), integer(ds, "n_assemblies_unresolved")
        cells = [f"<td class='num'>{p.number}</td>"]
        cells += [f"<td class='num'>{value_text(v)}</td>" for v in p.values]
        contact = format_fraction(*(number(ds, n) for n in (
            "contact_probability", "contact_probability_ci_lower",
            "contact_probability_ci_upper")))
        cells.append(f"<td class='num'>{_esc(contact)}</td>")
        cells.append(f"<td class='num'>{integer(ds, 'n_contact'):,} / {n_asm - u:,}</td>")
        if unresolved:
            if u:
                b = [format_fraction(number(ds, f"contact_probability_{end}")) for end in (
                    "bound_lower", "bound_upper", "bounds_ci_lower", "bounds_ci_upper")]
                cells.append(f"<td class='num'>{u:,}: {_esc(b[0])} to {_esc(b[1])}<br>"
                             f"<span class='ci'>95 % {_esc(b[2])} to {_esc(b[3])}</span></td>")
            else:
                cells.append("<td class='num'>0</td>")
        std, slo, shi = (p.stat("velocity_deviation_std", w)
                         for w in ("estimate", "ci_lower", "ci_upper"))
        cells.append(f"<td class='num'>{_percent(std)}<br><span class='ci'>"
                     f"{_percent(slo)} to {_percent(shi)}</span></td>")
        t, tlo, thi = (p.stat("time_to_contact_quantile_0.5", w)
                       for w in ("estimate", "ci_lower", "ci_upper"))
        if integer(ds, "n_contact") and np.isfinite(t):
            travel = 1e3 * quantile_value(ds, "travel_to_contact_quantile", 0.5)
            cells.append(f"<td class='num'>{t:.4g} s ({travel:.4g} mm)<br><span class='ci'>"
                         f"{_sig(tlo)} to {_sig(thi)} s</span></td>")
        elif integer(ds, "n_contact"):  # contacts without a first-contact time (none recorded)
            cells.append("<td class='num'>n/a</td>")
        else:
            cells.append("<td class='num'>no contact</td>")
        if friction:
            fr = p.friction
            if fr is None:
                cells += ["<td>–</td>", "<td>–</td>"]
            else:
                fp = (format_fraction(fr["probability"], fr["ci_lower"], fr["ci_upper"])
                      if np.isfinite(fr["limit"]) and fr["limit"] > 0 else "no limit")
                cells.append(f"<td class='num'>{_esc(fp)}</td>")
                cells.append(f"<td class='num'>{_sig(fr['quantiles'][FRICTION_LEVELS[-1]])} N"
                             "</td>")
        if judged:
            cells.append(_status_cell(p.verdict))
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table>")
    return parts


def _percent(x) -> str:
    return f"{100 * x:.4f} %" if np.isfinite(x) else "n/a"


def _sig(x, digits=4) -> str:
    return f"{x:.{digits}g}" if np.isfinite(x) else "n/a"


def _verdict_table(layout: Sweep, points) -> list:
    """HTML of the verdict per point: each judged check and the overall status."""
    judged = _judged(points)
    header = ["point", *(k.label for k in layout.axes)]
    header += [_check_title(c, points) for c in judged]
    header.append("all limits")
    parts = ["<table><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in header) + "</tr>"]
    for p in points:
        cells = [f"<td class='num'>{p.number}</td>"]
        cells += [f"<td class='num'>{value_text(v)}</td>" for v in p.values]
        for c in judged:
            check = p.verdict.checks[c]
            cells.append(_status_cell(check, check.estimate))
        cells.append(_status_cell(p.verdict))
        parts.append("<tr>" + "".join(cells) + "</tr>")
    parts.append("</table><p class='muted'>Each point judged as the single study it is "
                 "(tolsim.reports.verdict, as in the report of a study): pass when the whole "
                 "95 % interval meets the limit, fail when it violates it, undecided when it "
                 "straddles it. Hover over a status for the reason.</p>")
    return parts


def _crn_text(ds, points) -> str:
    a = ds.attrs
    seeds = {str(attribute(p.ds, "seed")) for p in points}
    n = {integer(p.ds, "n_assemblies") for p in points}
    sizes = ", ".join(f"{v:,}" for v in sorted(n))
    if len(seeds) == 1:
        crn = (f"Every point ran with the same seed ({next(iter(seeds))}), block size "
               f"({a.get('block_size', '?')}) and sampling ({a.get('sampling', '?')}): "
               "assembly i of one point has the random numbers of assembly i of every other "
               "point (<b>common random numbers</b>, <code>tolsim.study.design.sweep</code>). Only "
               "the mapping of those numbers to values (a scaled spread, a shifted load) "
               "changes with the key, so the curves are smooth and a <i>difference</i> "
               "between two points carries far less noise than the two intervals suggest: "
               "each interval shown is the point's own (marginal) interval, not that of a "
               "difference. This holds when the swept key leaves the structure of the draws "
               "alone; a key that changes which variates are drawn gives independent streams "
               "in effect.")
    else:
        crn = ("The points ran with different seeds: their random numbers are independent, "
               "and the intervals of two points are those of independent runs.")
    return f"{crn} Assemblies per point: {sizes}."


def sweep_html(ds, path, layout: Sweep, points, pngs: dict) -> str:
    a = ds.attrs
    one, many = contact_unit(points[0].ds)
    title = str(a.get("title", "tolsim sweep"))
    mode = ("outer: every combination of the keys' values, the first key slowest"
            if layout.mode == "outer" else
            "zip: the i-th values of all keys together, one point each")
    lines = headline(layout, points)
    summary = verdict_summary(points)
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{_esc(title)}</title><style>{CSS}{EXTRA_CSS}</style></head><body>",
        f"<h1>{_esc(title)}</h1>",
        f"<p class='muted'>Sweep report of <code>{_esc(os.path.basename(path))}</code>, made by "
        f"tolsim {__version__} on {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}. The "
        f"table per point as CSV: <code>{CSV_NAME}</code>; the figures as PNG beside this "
        "page. A sweep has no PDF: the sign-off report is that of a single study.</p>",
        *unverified_html(ds),
        "<div class='verdict-box' id='verdict'>",
        f"<p class='verdict-label'>{layout.size} points: "
        + (_esc(summary[-1].removeprefix("All spec limits together: ").rstrip("."))
           if summary else "no spec limit given") + "</p>",
        *(f"<p>{_esc(s)}</p>" for s in lines),
        *(f"<p>{_esc(s)}</p>" for s in summary[:-1]),
        "</div>",
    ]
    section = iter(range(1, 20))
    parts += [f"<h2 id='swept'>{next(section)}. What was swept</h2>",
              *table_html(_keys_table(layout)),
              f"<p>Mode {_esc(mode)}: {layout.size} points"
              + (f" ({' × '.join(str(n) for n in layout.shape)})"
                 if len(layout.shape) > 1 else "")
              + f". Dimensions in the file: <code>{_esc(' '.join(layout.dimensions))}</code>; "
              "each variable has them in front (<code>ds.contact_probability.plot()</code> "
              "draws the curve).</p>",
              f"<p>{_crn_text(ds, points)}</p>",
              "<h3>The study at every point</h3><table>",
              *(_row(label, value, num) for label, value, num in _facts_rows(points)),
              "</table>"]
    tolerances = tolerance_rows(points[0].ds)
    if tolerances:
        parts += ["<h3>Sampled inputs (as in the config; a swept key takes the values above)"
                  "</h3><table><tr><th>input</th><th>scope</th><th>distribution</th>"
                  "<th>parameters</th><th>config</th></tr>"]
        parts += [f"<tr><td>{_esc(r.source)}</td><td>{_esc(r.scope)}</td>"
                  f"<td>{_esc(r.distribution)}</td><td>{_esc(r.parameters)}</td>"
                  f"<td><code>{_esc(r.key)}</code></td></tr>" for r in tolerances]
        parts.append("</table>")
    parts += ["<details><summary>The sweep's config (TOML, as stored in the file: rerun it "
              "with <code>tolsim run</code>)</summary>",
              f"<pre>{_esc(a.get('config', ''))}</pre></details>"]

    def fig(name):
        if name in pngs:
            caption = FIGURES[name][1]
            parts.append(f"<figure><img alt='{_esc(caption)}' src='{data_uri(pngs[name])}'>"
                         f"<figcaption class='muted'>{_esc(caption)}</figcaption></figure>")

    parts.append(f"<h2 id='contact'>{next(section)}. Ball-to-ball contact against the swept "
                 "key" + ("s" if len(layout.axes) > 1 else "") + "</h2>")
    fig("contact_probability")
    parts.append("<h3 id='points'>Per point</h3>")
    parts += _points_table(layout, points)
    parts.append(f"<p class='muted'>P(contact) over the {many} whose outcome is known, "
                 f"95 % {_esc(estimator_label(points[0].ds))}"
                 + (f"; with unresolved {many}, the bounds count them as no contact / contact "
                    "(the interval covers both)" if any_unresolved(points) else "")
                 + ". ε std: delta method over assemblies, t(A − 1). Median first contact "
                 "(time since the start of the stroke, travel in brackets): Woodruff's "
                 "interval on the histogram of the first-contact times. Fractions below "
                 "0.1 % in ppm.</p>")
    if _judged(points):
        parts.append(f"<h2 id='verdicts'>{next(section)}. Verdict per point</h2>")
        parts += _verdict_table(layout, points)
    parts.append(f"<h2 id='velocity-deviation'>{next(section)}. Ball velocity deviation ε"
                 "</h2>")
    fig("velocity_deviation")
    if "friction" in pngs:
        parts.append(f"<h2 id='friction'>{next(section)}. What contact costs: carriage "
                     "friction after the balls touch</h2>")
        fig("friction")
    parts += _checks_table(layout, points, next(section))
    parts.append("<h2>Provenance</h2><table>")
    for key in ("Conventions", "source", "history", "seed", "references",
                "contact_probability_interval", "elapsed_seconds", "workers"):
        if key in a:
            parts.append(f"<tr><th>{_esc(key)}</th><td class='lines'>{_esc(a[key])}</td></tr>")
    parts.append("</table></body></html>")
    return "\n".join(parts)


def _checks_table(layout, points, section_number) -> list:
    """The model checks per point: balls re-solved with the full model, balls answered by the
    solved static model (a column only where a point has any), unresolved balls, spot
    checks."""
    fallback = any(integer(p.ds, "n_balls_static_fallback") for p in points)
    rows = []
    for p in points:
        ds = p.ds
        rows.append((str(p.number), *(value_text(v) for v in p.values),
                     f"{integer(ds, 'n_balls_resolved_full'):,} of "
                     f"{integer(ds, 'n_balls_outside_validity'):,}",
                     *((f"{integer(ds, 'n_balls_static_fallback'):,}",) if fallback else ()),
                     f"{integer(ds, 'n_balls_not_converged')} / "
                     f"{integer(ds, 'n_balls_loss_of_contact')}"
                     f" / {integer(ds, 'n_balls_full_failed')}",
                     f"{integer(ds, 'spot_check_n_valid')} of {ds.sizes.get('spot_check', 0)}",
                     _percent(number(ds, "spot_check_rms_difference")),
                     _percent(number(ds, "spot_check_max_abs_difference"))))
    model = str(points[0].ds.attrs.get("velocity_model", "?"))
    table = ReportTable(
        f"{section_number}. Model checks per point", (
            "point", *(k.label for k in layout.axes),
            f"balls outside the {model} model's validity, re-solved with the full model",
            *(("balls the static model left without balance, answered by the solved model",)
              if fallback else ()),
            "unresolved balls (not converged / loss of contact / full model failed)",
            "spot checks valid in both models", "RMS ε difference", "largest |ε difference|"),
        tuple(rows), (), "Spot checks: balls re-solved with the full friction model, half of "
        "them near the spec limit on |ε| (as in the study report's model check).",
        tuple(range(len(rows[0]))) if rows else ())
    html_parts = table_html(table)
    html_parts[0] = html_parts[0].replace("<h3>", "<h2 id='checks'>", 1).replace(
        "</h3>", "</h2>", 1)
    return html_parts
