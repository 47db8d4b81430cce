"""The report of a tolerance allocation (``tolsim allocate``, issue 14).

:func:`write_allocation` takes an :class:`tolsim.study.design.allocate.AllocationResult` and writes,
into a folder (made whole in a temporary folder beside it, then renamed into place, so an
error leaves no half-written output):

* ``allocate.html``: one self-contained page (the figure embedded as a data URI): the verdict
  of the verification run, the allocated tolerances in the config's own units, the cost, the
  trade-off figure, the method with its references, the allocated config and every
  evaluation;
* ``trade_off.png``: (a) the cost against the upper bound of the target's probability, for
  every evaluation, for the config's proportions times a common factor and for the optimum's
  proportions times a common factor, with the limit, the config as given, the optimum and
  the verification's interval; (b) the optimum scale factor of each source within its
  bounds;
* ``allocated.toml``: the optimum as a ready-to-run config (:func:`tolsim.io.config.allocation.
  allocated_config_text`), with the verification's seed and samples, so ``tolsim run`` on it
  reproduces the verification;
* ``allocate.json``: every number of the page; ``allocate.csv``: one row per decision
  variable; ``evaluations.csv``: one row per evaluation on the common sample.
"""

import csv
import html
import io
import json
import math
import os
import shutil
import tempfile
from datetime import UTC, datetime

import numpy as np
from matplotlib.ticker import FixedFormatter, FixedLocator, NullFormatter

from tolsim import __version__
from tolsim.reports.study import CSS
from tolsim.reports.style import (
    LIMIT_COLOUR,
    SERIES_COLOURS,
    data_uri,
    new_figure,
    render_png,
    styled,
)
from tolsim.study.design.allocate import DEFAULT_COST_EXPONENT

HTML_NAME = "allocate.html"
JSON_NAME = "allocate.json"
CSV_NAME = "allocate.csv"
EVALUATIONS_NAME = "evaluations.csv"
CONFIG_NAME = "allocated.toml"
FIGURE_NAME = "trade_off.png"

EXTRA_CSS = """
td.num { text-align: right; font-variant-numeric: tabular-nums; white-space: nowrap; }
td.key { font-family: monospace; } details summary { cursor: pointer; margin: 0.5em 0; }
"""


def _esc(text) -> str:
    return html.escape(str(text))


def _g(x, digits=4) -> str:
    return f"{x:.{digits}g}" if x is not None and np.isfinite(x) else "n/a"


def _pct_confidence(result) -> str:
    return f"{100 * result.confidence:g} %"


def _two_sided(result) -> str:
    return f"{100 * (2 * result.confidence - 1):g} %"


# --------------------------------------------------------------------------------------------
# Numbers
# --------------------------------------------------------------------------------------------
def _evaluation(e) -> dict:
    return {"estimate": e.estimate, "lower": e.lower, "upper": e.upper}


def allocation_numbers(result, *, tolerance_rows=None, written_scales=None, command="",
                       config_path="") -> dict:
    """Every number of the report, as plain JSON-able values."""
    search = result.search
    limit = result.limit
    reference = search.reference_cost
    sources = []
    for cost, scale in zip(result.sources, search.optimum.scales, strict=True):
        sources.append({
            "source": cost.source, "scale": scale,
            "written_scale": (written_scales or {}).get(cost.source, scale),
            "min_scale": cost.min_scale, "max_scale": cost.max_scale,
            "cost_exponent": cost.cost_exponent, "cost_weight": cost.cost_weight,
            "cost_share": cost.cost_weight * scale ** -cost.cost_exponent / search.optimum.cost,
            "at_bound": ("min_scale" if scale <= cost.min_scale else
                         "max_scale" if scale >= cost.max_scale else ""),
            "tolerances": [{"key": k, "given": g, "allocated": a}
                           for k, g, a in (tolerance_rows or {}).get(cost.source, [])],
        })
    return {
        "tolsim_version": __version__,
        "command": command,
        "config": config_path,
        "target": str(result.target),
        "target_description": result.target.describe(),
        "variable": result.target.variable,
        "limit": result.target.limit,
        "quantile_level": result.target.level,
        "probability_limit": limit,
        "confidence": result.confidence,
        "samples": result.samples,
        "seed": result.seed,
        "verify_samples": result.verify_samples,
        "verify_seed": result.verify_seed,
        "sources": sources,
        "fixed_sources": list(result.fixed_sources),
        "cost": search.optimum.cost,
        "cost_as_given": reference,
        "cost_ratio": result.cost_ratio,
        "optimisation": _evaluation(search.optimum.evaluation),
        "verification": {**_evaluation(result.verification), "meets_target": result.verified},
        "status": search.status,
        "evaluations": len(search.points),
        "search_seconds": result.search_seconds,
        "verify_seconds": result.verify_seconds,
        "points": [{"stage": p.stage,
                    "scales": dict(zip([c.source for c in result.sources], p.scales, strict=True)),
                    "cost": p.cost, "cost_ratio": p.cost / reference,
                    **_evaluation(p.evaluation), "meets_target": p.meets(limit)}
                   for p in search.points],
    }


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"not JSON: {value!r}")


def json_text(numbers: dict) -> str:
    """The numbers as JSON (NaN written as null)."""
    def clean(x):
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        if isinstance(x, float | np.floating) and not math.isfinite(x):
            return None
        return x

    return json.dumps(clean(numbers), indent=2, default=_json_default) + "\n"


def csv_text(numbers: dict) -> str:
    """One row per decision variable: its scale, bounds, cost and tolerances."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["source", "scale", "written_scale", "min_scale", "max_scale",
                     "cost_exponent", "cost_weight", "cost_share", "at_bound",
                     "tolerances_given", "tolerances_allocated"])
    for s in numbers["sources"]:
        writer.writerow([s["source"], s["scale"], s["written_scale"], s["min_scale"],
                         s["max_scale"], s["cost_exponent"], s["cost_weight"],
                         f"{s['cost_share']:.6g}", s["at_bound"],
                         "; ".join(f"{t['key']} = {t['given']}" for t in s["tolerances"]),
                         "; ".join(f"{t['key']} = {t['allocated']}" for t in s["tolerances"])])
    return buf.getvalue()


def evaluations_csv(numbers: dict) -> str:
    """One row per evaluation on the common sample."""
    names = [s["source"] for s in numbers["sources"]]
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["index", "stage", *[f"scale_{n}" for n in names], "cost", "cost_ratio",
                     "estimate", "lower", "upper", "meets_target"])
    for i, p in enumerate(numbers["points"]):
        writer.writerow([i, p["stage"], *[p["scales"][n] for n in names], f"{p['cost']:.6g}",
                         f"{p['cost_ratio']:.6g}", p["estimate"], p["lower"], p["upper"],
                         int(p["meets_target"])])
    return buf.getvalue()


# --------------------------------------------------------------------------------------------
# Figure
# --------------------------------------------------------------------------------------------
@styled
def plot_trade_off(result):
    """(a) cost ratio against the upper bound, (b) the optimum scales within their bounds."""
    search = result.search
    reference = search.reference_cost
    limit = result.limit
    fig, (ax, bx) = new_figure(11.0, 5.2, ncols=2, width_ratios=(1.5, 1.0))
    floor = 0.3 / result.samples  # where an upper bound of 0 events would be drawn

    def xy(points):
        pts = sorted(points, key=lambda p: p.cost)
        return (np.array([p.cost / reference for p in pts]),
                np.array([max(p.evaluation.upper, floor) for p in pts]))

    x, y = xy(search.points)
    ax.scatter(x, y, s=12, color="#999999", label="every evaluation", zorder=2)
    diagonal = [p for p in search.points if p.stage in ("as given", "sweep", "bracket")
                and len(set(p.scales)) == 1]
    optimum_ray = search.stage("trade-off") + [search.optimum]
    for pts, colour, label in ((diagonal, SERIES_COLOURS[0],
                                "the config's proportions x a common factor"),
                               (optimum_ray, SERIES_COLOURS[2],
                                "the optimum's proportions x a common factor")):
        if len(pts) > 1:
            x, y = xy(pts)
            ax.plot(x, y, "-o", color=colour, ms=4, label=label, zorder=3)
    given = next((p for p in search.points if p.stage == "as given"), None)
    if given is not None:
        ax.plot(given.cost / reference, max(given.evaluation.upper, floor), "s", ms=9,
                mfc="none", mec="k", mew=1.5, label="the config as given", zorder=4)
    opt = search.optimum
    ax.plot(opt.cost / reference, opt.evaluation.upper, "*", ms=15, color=SERIES_COLOURS[1],
            mec="k", label=f"optimum: cost {result.cost_ratio:.3g} of as given", zorder=5)
    v = result.verification
    ax.errorbar(opt.cost / reference * 1.15, v.estimate,
                yerr=[[max(v.estimate - v.lower, 0)], [max(v.upper - v.estimate, 0)]],
                fmt="D", ms=5, color=SERIES_COLOURS[3], capsize=3, zorder=5,
                label=f"verification: estimate, {_two_sided(result)} interval")
    ax.axhline(limit, color=LIMIT_COLOUR, ls="--", lw=1.2, label=f"limit {limit:.3g}")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("tolerance cost / cost of the config as given")
    ax.set_ylabel(f"{_pct_confidence(result)} upper bound of P")
    ax.set_title(f"(a) cost against the {result.target.variable} bound")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncols=2, fontsize=7.5)

    names = [c.source for c in result.sources]
    ypos = np.arange(len(names))[::-1]
    for yy, cost, scale in zip(ypos, result.sources, opt.scales, strict=True):
        bx.plot([cost.min_scale, cost.max_scale], [yy, yy], color="#bbbbbb", lw=6,
                solid_capstyle="butt", zorder=1)
        bx.plot(scale, yy, "o", color=SERIES_COLOURS[1], mec="k", ms=9, zorder=3)
        bx.annotate(f"x {scale:.3g}", (scale, yy), textcoords="offset points", xytext=(0, 8),
                    ha="center", fontsize=8)
    bx.axvline(1.0, color="k", lw=1, ls=":")
    bx.set_xscale("log")
    low = min(c.min_scale for c in result.sources)
    high = max(c.max_scale for c in result.sources)
    ticks = [t for t in (0.1, 0.25, 0.5, 1, 2, 4, 10) if low * 0.99 <= t <= high * 1.01]
    bx.xaxis.set_major_locator(FixedLocator(ticks))
    bx.xaxis.set_major_formatter(FixedFormatter([f"{t:g}" for t in ticks]))
    bx.xaxis.set_minor_formatter(NullFormatter())
    bx.set_yticks(ypos, names, fontsize=8)
    bx.set_xlabel("scale factor (1: as given; bar: its bounds)")
    bx.set_title("(b) the allocated tolerances")
    bx.grid(axis="y", visible=False)
    return fig


# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------
def _verdict(result) -> tuple:
    v = result.verification
    head = (f"{result.target.variable}: estimate {_g(v.estimate)}, {_pct_confidence(result)} "
            f"upper bound {_g(v.upper)} on {result.verify_samples:,} fresh assemblies")
    if result.verified:
        return "pass", "Verified", (
            f"{head} ≤ the limit {_g(result.limit)}. The allocated tolerances meet the target "
            f"with {_pct_confidence(result)} confidence on an independent sample.")
    if v.estimate <= result.limit:
        return "undecided", "Not verified", (
            f"{head} > the limit {_g(result.limit)}, though the estimate is below it: the "
            "optimum sits at the limit of the optimisation sample, and the fresh sample "
            "cannot confirm it. Rerun with more samples (--samples, --verify-samples), or "
            "allocate against a slightly lower limit.")
    return "fail", "Not verified", (
        f"{head}: the estimate exceeds the limit {_g(result.limit)}. The optimisation sample "
        "was optimistic; rerun with more samples (--samples).")


def _sources_table(result, numbers) -> list:
    parts = ["<table><tr><th>source</th><th>scale</th><th>tolerance as given</th>"
             "<th>allocated</th><th>bounds</th><th>cost w / s<sup>k</sup></th>"
             "<th>share of the cost</th></tr>"]
    for s in numbers["sources"]:
        given = "<br>".join(f"<code>{_esc(t['key'])} = {_esc(t['given'])}</code>"
                            for t in s["tolerances"]) or "—"
        allocated = "<br>".join(f"<code>{_esc(t['key'])} = {_esc(t['allocated'])}</code>"
                                for t in s["tolerances"]) or "—"
        move = ("looser" if s["scale"] > 1 else "tighter" if s["scale"] < 1 else "unchanged")
        bound = f" (at its {s['at_bound']})" if s["at_bound"] else ""
        written = (f"<br><span class='muted'>written scale = {s['written_scale']:.4g}</span>"
                   if not math.isclose(s["written_scale"], s["scale"], rel_tol=1e-9) else "")
        parts.append(
            f"<tr><td class='key'>{_esc(s['source'])}</td>"
            f"<td class='num'><b>{s['scale']:.4g}</b><br><span class='muted'>{move}{bound}"
            f"</span>{written}</td><td>{given}</td><td>{allocated}</td>"
            f"<td class='num'>{s['min_scale']:g} – {s['max_scale']:g}</td>"
            f"<td class='num'>w = {s['cost_weight']:g}, k = {s['cost_exponent']:g}</td>"
            f"<td class='num'>{100 * s['cost_share']:.3g} %</td></tr>")
    parts.append("</table>")
    if numbers["fixed_sources"]:
        parts.append("<p class='muted'>Not decision variables (kept as given): "
                     + ", ".join(f"<code>{_esc(n)}</code>" for n in numbers["fixed_sources"])
                     + ".</p>")
    return parts


def _method(result) -> str:
    return (
        "<p><b>Problem.</b> Each decision variable is a scale factor s of a tolerance source "
        "(every value x of the source becomes centre + s (x − centre): a std, a band, a cpk "
        "band scale by s; s = 1 is the config as given), within its bounds. The cost is the "
        "reciprocal power model of the tolerance-dependent cost, C(s) = Σ w<sub>i</sub> "
        "s<sub>i</sub><sup>−k<sub>i</sub></sup>: the model C = A + B / T<sup>k</sup> of "
        "Chase, Greenwood, Loosli &amp; Hauglund (1990) with the fixed part A dropped (it "
        "does not move the optimum) and w the source's cost at its given tolerance; the "
        f"default k = {DEFAULT_COST_EXPONENT:g} is the reciprocal square of Spotts (1973). "
        "The reported cost is C(s) / C(1), relative to the config as given. The constraint "
        f"is on the <b>{_pct_confidence(result)} one-sided upper confidence bound</b> of the "
        "target's probability, not its estimate: for P(contact) the Clopper-Pearson upper "
        "end of k + u of N, the unresolved trains counted as contacts.</p>"
        "<p><b>Search.</b> Every evaluation is a study of the same "
        f"{result.samples:,} assemblies from seed {result.seed} (common random numbers), so "
        "the bound is a deterministic function of the scales and the search optimises one "
        "sample-average approximation of the chance-constrained problem (Luedtke &amp; "
        "Ahmed 2008). A common-factor sweep of all sources finds where the config's own "
        "proportions cross the limit; from there a trust-region response surface (a plane "
        "fitted to probit(upper bound) in ln s around the current design, the least-cost "
        "point under it solved exactly from its KKT conditions) moves the proportions; a "
        "ray search along a common factor puts the last design on the limit. The optimum is "
        "the cheapest <i>evaluated</i> design within the bounds that meets the limit on the "
        f"common sample. Search: {_esc(result.search.status)}.</p>"
        "<p><b>Verification.</b> The optimum is chosen on the optimisation sample, where its "
        "bound is optimistic, so it is evaluated again on "
        f"{result.verify_samples:,} fresh assemblies from seed {result.verify_seed}: the "
        "first 32-bit word of <code>SeedSequence(seed, spawn_key=(5,))</code>, independent of "
        "the optimisation sample. The allocated config carries that seed and sample count: "
        f"<code>tolsim run {CONFIG_NAME}</code> reproduces the verification (with the "
        "config's spot checks and report).</p>"
        "<p class='muted'>References: K. W. Chase, W. H. Greenwood, B. G. Loosli, L. F. "
        "Hauglund, Least cost tolerance allocation for mechanical assemblies with automated "
        "process selection, Manufacturing Review 3(1) (1990) 49–59 (reciprocal power cost, "
        "Lagrange multipliers). K. W. Chase, W. H. Greenwood, Design issues in mechanical "
        "tolerance analysis, Manufacturing Review 1(1) (1988) 50–59. M. F. Spotts, "
        "Allocation of tolerances to minimize cost of assembly, ASME J. Eng. Ind. 95(3) "
        "(1973) 762–764 (reciprocal square cost). F. H. Speckhart, Calculation of tolerance "
        "based on a minimum cost approach, ASME J. Eng. Ind. 94(2) (1972) 447–453 "
        "(exponential cost, not used here: it needs the absolute tolerance in the exponent). "
        "J. Luedtke, S. Ahmed, A sample approximation approach for optimization with "
        "probabilistic constraints, SIAM J. Optim. 19(2) (2008) 674–699. A. M. Law, "
        "Simulation Modeling and Analysis, 5th ed. (2015), Sec. 11.2 (common random "
        "numbers).</p>")


def allocation_html(result, numbers, *, optimum_text, png) -> str:
    """The self-contained HTML page."""
    cls, label, text = _verdict(result)
    opt = result.search.optimum.evaluation
    v = result.verification
    title = f"Tolerance allocation: {result.target}"
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{_esc(title)}</title><style>{CSS}{EXTRA_CSS}</style></head><body>",
        f"<h1>{_esc(title)}</h1>",
        f"<p class='muted'>Made by tolsim {__version__} on "
        f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')} from "
        f"<code>{_esc(numbers['config'] or result.config.path)}</code>"
        + (f" with <code>{_esc(numbers['command'])}</code>" if numbers["command"] else "")
        + f". The numbers: <code>{JSON_NAME}</code>, <code>{CSV_NAME}</code>, "
        f"<code>{EVALUATIONS_NAME}</code>; the allocated config: <code>{CONFIG_NAME}</code>."
        "</p>",
        f"<div class='verdict-box {cls}'><div class='verdict-label'>{_esc(label)}</div>"
        f"<p>{_esc(text)}</p>"
        f"<p>Target: {_esc(result.target.describe())}, met by the "
        f"{_pct_confidence(result)} upper bound. Cost of the allocated tolerances: "
        f"<b>{result.cost_ratio:.3g}</b> of the config as given.</p></div>",
        "<h2>1. The allocated tolerances</h2>",
    ]
    parts += _sources_table(result, numbers)
    parts += [
        "<h2>2. Cost and probability</h2>",
        "<table><tr><th></th><th>assemblies</th><th>seed</th><th>estimate</th>"
        f"<th>{_two_sided(result)} interval</th><th>{_pct_confidence(result)} upper bound"
        "</th><th>meets the limit</th></tr>",
    ]
    given = next((p for p in result.search.points if p.stage == "as given"), None)
    rows = []
    if given is not None:
        rows.append(("config as given (optimisation sample)", result.samples, result.seed,
                     given.evaluation))
    rows += [("optimum (optimisation sample)", result.samples, result.seed, opt),
             ("optimum (verification sample)", result.verify_samples, result.verify_seed, v)]
    for name, n, seed, e in rows:
        parts.append(f"<tr><td>{_esc(name)}</td><td class='num'>{n:,}</td>"
                     f"<td class='num'>{seed}</td><td class='num'>{_g(e.estimate)}</td>"
                     f"<td class='num'>[{_g(e.lower)}, {_g(e.upper)}]</td>"
                     f"<td class='num'>{_g(e.upper)}</td>"
                     f"<td>{'yes' if e.upper <= result.limit else 'no'}</td></tr>")
    parts.append("</table>")
    parts.append(f"<p>Limit on the probability: {_g(result.limit)}. Cost C(s) = "
                 f"{result.search.optimum.cost:.4g} against C(1) = "
                 f"{result.search.reference_cost:.4g} for the config as given "
                 f"(ratio {result.cost_ratio:.4g}); {len(result.search.points)} evaluations in "
                 f"{result.search_seconds:.1f} s, verification {result.verify_seconds:.1f} s."
                 "</p>")
    caption = ("(a) Every evaluation on the common sample: tolerance cost against the upper "
               "bound of the probability; the config's proportions and the optimum's "
               "proportions each times a common factor (the optimum's curve lies left of the "
               "config's where it matters: the same bound for less cost); the limit; the "
               "verification's estimate and interval beside the optimum. (b) The optimum "
               "scale factor of each source within its bounds.")
    parts += [
        "<h2>3. Trade-off</h2>",
        f"<figure><img alt='{_esc(caption)}' src='{data_uri(png)}'>"
        f"<figcaption class='muted'>{_esc(caption)}</figcaption></figure>",
        "<h2>4. Method</h2>", _method(result),
        f"<h2>5. The allocated config (<code>{CONFIG_NAME}</code>)</h2>",
        f"<pre>{_esc(optimum_text)}</pre>",
        "<h2>6. Every evaluation</h2><details><summary>"
        f"{len(result.search.points)} evaluations on the common sample</summary>",
        "<table><tr><th>#</th><th>stage</th>"
        + "".join(f"<th>{_esc(c.source)}</th>" for c in result.sources)
        + "<th>cost ratio</th><th>estimate</th><th>upper bound</th></tr>",
    ]
    for i, p in enumerate(numbers["points"]):
        parts.append(f"<tr><td class='num'>{i}</td><td>{_esc(p['stage'])}</td>"
                     + "".join(f"<td class='num'>{v:.4g}</td>" for v in p["scales"].values())
                     + f"<td class='num'>{p['cost_ratio']:.4g}</td>"
                     f"<td class='num'>{_g(p['estimate'])}</td>"
                     f"<td class='num'>{_g(p['upper'])}</td></tr>")
    parts.append("</table></details></body></html>")
    return "\n".join(parts)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------
def write_folder(folder, files: dict) -> dict:
    """Write {name: bytes} into ``folder`` as a whole: into a temporary folder beside it,
    then renamed into place (a new folder), or each file renamed in (an existing folder).
    On an error nothing is left behind but what was already in ``folder``.

    Returns
    -------
    dict
        name -> path.
    """
    folder = os.path.abspath(os.fspath(folder))
    parent = os.path.dirname(folder)
    tmp = tempfile.mkdtemp(prefix=f".{os.path.basename(folder)}.", dir=parent)
    try:
        for name, data in files.items():
            with open(os.path.join(tmp, name), "wb") as fh:
                fh.write(data)
        if not os.path.exists(folder):
            os.rename(tmp, folder)
        else:
            for name in files:
                os.replace(os.path.join(tmp, name), os.path.join(folder, name))
            os.rmdir(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {name: os.path.join(folder, name) for name in files}


def write_allocation(result, folder, *, optimum_text, tolerance_rows=None,
                     written_scales=None, command="", config_path="") -> dict:
    """Write the allocation's files (module docstring) into ``folder``.

    Parameters
    ----------
    result : tolsim.study.design.allocate.AllocationResult
    folder : str or path
        Created if missing; files of the same names in it are replaced.
    optimum_text : str
        The allocated config (:func:`tolsim.io.config.allocation.allocated_config_text`).
    tolerance_rows : dict, optional
        :func:`tolsim.io.config.allocation.tolerance_lines` of the optimum.
    written_scales : dict, optional
        source -> the scale written in the allocated config (the optimum times a scale the
        config already set).
    command, config_path : str
        For the provenance.

    Returns
    -------
    dict
        file name -> path.
    """
    numbers = allocation_numbers(result, tolerance_rows=tolerance_rows,
                                 written_scales=written_scales, command=command,
                                 config_path=config_path)
    png = render_png(plot_trade_off(result))
    files = {
        HTML_NAME: allocation_html(result, numbers, optimum_text=optimum_text,
                                   png=png).encode("utf-8"),
        FIGURE_NAME: png,
        CONFIG_NAME: optimum_text.encode("utf-8"),
        JSON_NAME: json_text(numbers).encode("utf-8"),
        CSV_NAME: csv_text(numbers).encode("utf-8"),
        EVALUATIONS_NAME: evaluations_csv(numbers).encode("utf-8"),
    }
    return write_folder(folder, files)
