"""The outputs of ``tolsim compare`` as text: ``compare.csv`` and the HTML page
``compare.html``, with how a statistic and its difference are shown."""

import csv
import html
import io
import os
from datetime import UTC, datetime

import numpy as np

from tolsim import __version__
from tolsim.reports.compare.comparison import Comparison
from tolsim.reports.compare.figures import FIGURES
from tolsim.reports.compare.statistics import (
    DIFFERENCE_METHODS,
    PAIRING_INDEPENDENT,
    PAIRING_SHARED,
    RANDOM_NUMBER_ATTRIBUTES,
    Difference,
    Statistic,
)
from tolsim.reports.result_view import (
    integer,
)
from tolsim.reports.study.page import CSS
from tolsim.reports.style import (
    data_uri,
)
from tolsim.reports.verdict import contact_unit
from tolsim.study.statistics.intervals import (
    format_fraction,
)

#: Files written by :func:`compare_runs`.
HTML_NAME, CSV_NAME = "compare.html", "compare.csv"
#: Columns of ``compare.csv``.
CSV_COLUMNS = ("statistic", "description", "run", "file", "estimate", "ci_lower", "ci_upper",
               "units", "interval", "difference", "difference_ci_lower",
               "difference_ci_upper", "difference_interval")


# --------------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------------
def _csv_number(x) -> str:
    return repr(float(x)) if np.isfinite(x) else ""


def csv_rows(comparison: Comparison) -> list:
    """One dict per statistic and run (keys :data:`CSV_COLUMNS`), statistics in display
    order, runs in the given order; the difference columns empty for the reference."""
    rows = []
    for name in comparison.names:
        for run in comparison.runs:
            stat = run.statistics.get(name)
            if stat is None:
                continue
            diff = comparison.differences.get((name, run.label))
            rows.append({
                "statistic": name, "description": stat.description, "run": run.label,
                "file": run.path, "estimate": _csv_number(stat.estimate),
                "ci_lower": _csv_number(stat.ci_lower), "ci_upper": _csv_number(stat.ci_upper),
                "units": stat.units, "interval": stat.interval,
                "difference": _csv_number(diff.estimate) if diff else "",
                "difference_ci_lower": _csv_number(diff.ci_lower) if diff else "",
                "difference_ci_upper": _csv_number(diff.ci_upper) if diff else "",
                "difference_interval": diff.interval if diff else "",
            })
    return rows


def csv_text(comparison: Comparison) -> str:
    """``compare.csv`` as text."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(csv_rows(comparison))
    return buffer.getvalue()


# --------------------------------------------------------------------------------------------
# Display
# --------------------------------------------------------------------------------------------
#: display -> (scale, unit shown, format of a value, format of a difference).
DISPLAY = {
    "epsilon": (100.0, "%", "{:+.4f}", "{:+.4f}"),
    "epsilon_spread": (100.0, "%", "{:.4f}", "{:+.4f}"),
    "index": (1.0, "", "{:.3f}", "{:+.3f}"),
    "seconds": (1.0, "s", "{:.4g}", "{:+.3g}"),
    "stiffness_translation": (1e-6, "N/µm", "{:.4g}", "{:+.3g}"),
    "stiffness_rotation": (1e-6, "N m/µrad", "{:.4g}", "{:+.3g}"),
}


def _scaled(display, x, diff=False) -> str:
    if not np.isfinite(x):
        return "n/a"
    scale, _, fmt_value, fmt_diff = DISPLAY[display]
    text = (fmt_diff if diff else fmt_value).format(scale * x + 0.0)
    return text.replace("-", "−")


def _unit(display) -> str:
    unit = DISPLAY[display][1]
    return f" {unit}" if unit else ""


def format_value(stat: Statistic) -> tuple:
    """(estimate, '95 % CI lo to hi') of a statistic as the HTML shows them."""
    if stat.display == "probability":
        # in ppm below 0.1 %, else in % (tolsim.study.statistics.intervals.format_fraction)
        full = format_fraction(stat.estimate, stat.ci_lower, stat.ci_upper)
        est, _, ci = full.partition(" (")
        return est, ci.rstrip(")") or "95 % CI n/a"
    unit = _unit(stat.display)
    est = _scaled(stat.display, stat.estimate) + (unit if np.isfinite(stat.estimate) else "")
    if stat.kind == "exact":
        return est, "exact"
    lo, hi = (_scaled(stat.display, x) for x in (stat.ci_lower, stat.ci_upper))
    return est, f"95 % CI {lo} to {hi}{unit}"


def format_difference(stat: Statistic, diff: Difference) -> str:
    """'+1.2 pp (−0.3 to +2.7)': a difference with its interval, as the HTML shows it."""
    if stat.display == "probability":
        ends = [abs(x) for x in (diff.estimate, diff.ci_lower, diff.ci_upper)
                if np.isfinite(x)]
        scale, unit = (1e6, "ppm") if ends and max(ends) < 1e-3 else (1e2, "pp")

        def fmt(x):
            return f"{scale * x + 0.0:+.3g}".replace("-", "−") if np.isfinite(x) else "n/a"
    else:
        unit = DISPLAY[stat.display][1]

        def fmt(x):
            return _scaled(stat.display, x, diff=True)
    text = f"{fmt(diff.estimate)}{' ' + unit if unit else ''}"
    if stat.kind == "exact" or diff.ci_lower == diff.ci_upper == diff.estimate:
        return text + " (exact)"
    return f"{text} (95 % CI {fmt(diff.ci_lower)} to {fmt(diff.ci_upper)})"




# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------
EXTRA_CSS = """
td.cell { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.cell .ci { color: #666; font-size: 0.88em; } td.cell .diff { font-size: 0.9em; }
td.cell .differs { font-weight: bold; } td.key { font-family: monospace; }
"""


def _esc(text) -> str:
    return html.escape(str(text))


def _run_rows(comparison):
    header = ("run", "file", "title", "assemblies", "unresolved", "seed", "block size",
              "sampling", "velocity model", "propagation", "random numbers")
    rows = []
    for i, run in enumerate(comparison.runs):
        a = run.ds.attrs
        if i == 0:
            relation = "reference"
        elif run.shares_random_numbers:
            relation = ("common with the reference (same seed, block size and sampling): "
                        + PAIRING_SHARED)
        else:
            why = [k.replace("_", " ") for k in RANDOM_NUMBER_ATTRIBUTES
                   if str(a.get(k, "?")) != str(comparison.reference.ds.attrs.get(k, "?"))]
            reason = (f"{', '.join(why)} {'differs' if len(why) == 1 else 'differ'}" if why
                      else "seed, block size or sampling not recorded")
            relation = f"independent of the reference ({reason}): {PAIRING_INDEPENDENT}"
        rows.append((run.label, os.path.basename(run.path), a.get("title", ""),
                     f"{integer(run.ds, 'n_assemblies'):,}",
                     f"{integer(run.ds, 'n_assemblies_unresolved'):,}", a.get("seed", "?"),
                     a.get("block_size", "?"), a.get("sampling", "?"),
                     a.get("velocity_model", "?"), a.get("propagation", "?"), relation))
    return header, rows


def _statistics_table(comparison):
    runs = comparison.runs
    parts = ["<table><tr><th>statistic</th>"
             + "".join(f"<th>{_esc(r.label)}{' (reference)' if i == 0 else ''}</th>"
                       for i, r in enumerate(runs)) + "</tr>"]
    for name in comparison.names:
        first = comparison.statistic(name)
        unit = "" if first.display == "probability" else _unit(first.display).strip()
        label = first.description + (f" [{unit}]" if unit else "")
        cells = []
        for run in runs:
            stat = run.statistics.get(name)
            if stat is None:
                cells.append("<td class='cell'>—</td>")
                continue
            est, ci = format_value(stat)
            cell = f"{_esc(est)}<br><span class='ci'>{_esc(ci)}</span>"
            diff = comparison.differences.get((name, run.label))
            if diff is not None:
                cls = "diff differs" if diff.excludes_zero else "diff"
                cell += f"<br><span class='{cls}'>Δ {_esc(format_difference(stat, diff))}</span>"
            cells.append(f"<td class='cell'>{cell}</td>")
        parts.append(f"<tr><th>{_esc(label)}<br><code class='muted'>{_esc(name)}</code></th>"
                     + "".join(cells) + "</tr>")
    parts.append("</table>")
    return parts


def _methods_table(comparison):
    # (family, the runs' intervals, the differences' intervals): a P(contact) may come from a
    # rare-event estimator in some runs only, with its own interval and difference
    rows = {}
    for name in comparison.names:
        stat = comparison.statistic(name)
        intervals, methods = rows.setdefault(stat.family or stat.name, ([], []))
        for run in comparison.runs:
            if name in run.statistics and run.statistics[name].interval not in intervals:
                intervals.append(run.statistics[name].interval)
            diff = comparison.differences.get((name, run.label))
            method = diff.interval.split(";")[0] if diff is not None else None
            if method is not None and method not in methods:
                methods.append(method)
        if not methods:
            methods.append(DIFFERENCE_METHODS[stat.kind][1])
    return [(family, "; ".join(intervals), "; ".join(methods))
            for family, (intervals, methods) in rows.items()]


def comparison_html(comparison: Comparison, pngs: dict) -> str:
    runs = comparison.runs
    ref = comparison.reference
    shared = [r.label for r in runs[1:] if r.shares_random_numbers]
    independent = [r.label for r in runs[1:] if not r.shares_random_numbers]
    units = {contact_unit(r.ds)[0] for r in runs}
    title = f"Comparison of {len(runs)} tolsim studies"
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{_esc(title)}</title><style>{CSS}{EXTRA_CSS}</style></head><body>",
        f"<h1>{_esc(title)}</h1>",
        f"<p class='muted'>Made by tolsim {__version__} on "
        f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')} from "
        + ", ".join(f"<code>{_esc(os.path.basename(r.path))}</code>" for r in runs)
        + f". The reference is the first run, <b>{_esc(ref.label)}</b>: every difference Δ "
        "is a run minus the reference. The same numbers, one row per statistic and run: "
        f"<code>{CSV_NAME}</code>.</p>",
        "<h2>1. Runs</h2>",
    ]
    header, rows = _run_rows(comparison)
    parts.append("<table><tr>" + "".join(f"<th>{_esc(h)}</th>" for h in header) + "</tr>")
    parts += ["<tr>" + "".join(f"<td>{_esc(c)}</td>" for c in row) + "</tr>" for row in rows]
    parts.append("</table>")
    if len(units) > 1:
        per = {u: [r.label for r in runs if contact_unit(r.ds)[0] == u] for u in sorted(units)}
        parts.append("<p class='verdict bad'>P(contact) is per train in "
                     f"{_esc(', '.join(per.get('train', [])))} and per assembly (a carriage "
                     f"with several trains: contact in any of them) in "
                     f"{_esc(', '.join(per.get('assembly', [])))}: these probabilities are "
                     "not directly comparable.</p>")

    parts.append("<h2>2. Paired or unpaired differences</h2>")
    text = ("The differences are <b>unpaired</b>: each run's estimate is taken as independent "
            "of the reference's. A paired interval needs per-assembly outcomes (for "
            "P(contact), how many assemblies have contact in both runs and in one only), and "
            "the result files hold aggregates only; recomputing them from the stored configs "
            "would cost as much as the runs. ")
    if shared:
        text += (f"{_esc(', '.join(shared))} share{'s' if len(shared) == 1 else ''} the "
                 "reference's seed, block size and sampling, so "
                 f"{'its' if len(shared) == 1 else 'their'} assemblies come from common "
                 "random numbers and correspond one to one to the reference's: the outcomes "
                 "are correlated, and the unpaired interval, which leaves out the covariance, "
                 "is <b>conservative</b> (wider than a paired one) when that correlation is "
                 "positive, as it is when a change moves the outcome the same way in every "
                 "assembly. Label: <i>" + PAIRING_SHARED + "</i>. ")
    if independent:
        text += (f"{_esc(', '.join(independent))} "
                 f"{'is' if len(independent) == 1 else 'are'} independent of the reference "
                 "(different random numbers): there the unpaired interval is the right one. "
                 "Label: <i>" + PAIRING_INDEPENDENT + "</i>. ")
    text += ("P(contact) and its bounds: Newcombe's hybrid score interval (Newcombe 1998, "
             "Stat. Med. 17:873, method 10); a P(contact) made by a rare-event estimator: "
             "the MOVER from the two runs' own intervals. Means and standard deviations: "
             "Welch's interval with the Welch-Satterthwaite degrees of freedom. Quantiles, "
             "the fraction out of spec and Cpk: the MOVER of Zou &amp; Donner (2008, Stat. "
             "Med. 27:1693) from the two runs' own intervals. A Δ in bold has an interval "
             "that excludes 0.")
    parts.append(f"<p>{text}</p>")

    parts.append("<h2>3. Config keys that differ</h2>")
    if comparison.unreadable_configs:
        parts.append("<p class='bad'>Config text not readable as TOML in "
                     f"{_esc(', '.join(comparison.unreadable_configs))}: its keys are not "
                     "compared.</p>")
    if comparison.config:
        parts.append("<p class='muted'>From the config text stored in each file (the "
                     "effective config: command-line overrides included); — : the run's "
                     "config does not set the key (the model default applies).</p>")
        parts.append("<table><tr><th>key</th>" + "".join(f"<th>{_esc(r.label)}</th>"
                                                          for r in runs) + "</tr>")
        for row in comparison.config:
            parts.append(f"<tr><td class='key'>{_esc(row.key)}</td>"
                         + "".join(f"<td><code>{_esc(t)}</code></td>" for t in row.texts)
                         + "</tr>")
        parts.append("</table>")
    else:
        parts.append("<p>The configs stored in the files set the same keys to the same "
                     "values.</p>")

    parts.append("<h2>4. Key statistics</h2>")
    parts.append("<p class='muted'>Each cell: the estimate, its 95 % interval, and (Δ) the "
                 "difference to the reference with its own 95 % interval. pp: percentage "
                 "points. n/a: not available (an interval end beyond the data, or no contact "
                 "at all).</p>")
    parts += _statistics_table(comparison)
    found = {k: v for k, v in comparison.bound_differences.items() if v is not None}
    if found:
        def pp(x):
            return f"{100 * x + 0.0:+.3g}".replace("-", "−") if np.isfinite(x) else "n/a"

        parts.append("<p>With unresolved trains, P(contact) is known only within its bounds, "
                     "and the difference to the reference only within [lower bound of the "
                     "run − upper bound of the reference, upper bound of the run − lower "
                     "bound of the reference]: " + "; ".join(
                         f"{_esc(label)}: {pp(lo)} to {pp(hi)} pp (95 % interval {pp(cl)} "
                         f"to {pp(ch)} pp)" for label, (lo, hi, cl, ch) in found.items())
                     + ".</p>")
    parts.append("<h3>Intervals</h3><table><tr><th>statistic</th><th>interval of a run</th>"
                 "<th>interval of the difference</th></tr>")
    parts += [f"<tr><td><code>{_esc(g)}</code></td><td>{_esc(a)}</td><td>{_esc(b)}</td></tr>"
              for g, a, b in _methods_table(comparison)]
    parts.append("</table>")

    parts.append("<h2>5. Distributions</h2>")
    for name, (_, caption) in FIGURES.items():
        if name in pngs:
            parts.append(f"<figure><img alt='{_esc(caption)}' src='{data_uri(pngs[name])}'>"
                         f"<figcaption class='muted'>{_esc(caption)}</figcaption></figure>")

    parts.append("<h2>Provenance</h2><table><tr><th>run</th><th>source</th><th>history</th>"
                 "</tr>")
    for run in runs:
        a = run.ds.attrs
        parts.append(f"<tr><td>{_esc(run.label)}</td><td>{_esc(a.get('source', '?'))}</td>"
                     f"<td>{_esc(a.get('history', '?'))}</td></tr>")
    parts.append("</table></body></html>")
    return "\n".join(parts)
