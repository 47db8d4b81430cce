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
  epsilon and on the contact indicator (:mod:`tolsim.study.sensitivity`);
* ``quality.png`` (with a limit on |epsilon|): the tails of epsilon on a log scale against
  the limit, the fraction out of spec and Cpk (:mod:`tolsim.study.quality`);
* ``report.html`` with all of them embedded as data URIs: at the top the verdict against the
  config's spec limits (:mod:`tolsim.reports.verdict`), then what was studied with the
  sampled inputs (the initial gap included) and the assumptions table
  (:mod:`tolsim.reports.assumptions`), the config and provenance, and a sign-off table;
* ``report.pdf``: the same for review and sign-off (:mod:`tolsim.reports.pdf`).

Sensitivity indices are taken from the file when ``tolsim run`` stored them (``factor``
dimension, ``sensitivity_first_order`` / ``sensitivity_total``); otherwise they are computed
here from the config embedded in the file (same seed), unless disabled.
"""

import html
import os
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from tolsim import __version__
from tolsim.reports.assumptions import assumption_table, config_of, tolerance_table
from tolsim.reports.style import (
    LIMIT_COLOUR,
    MODEL_COLOURS,
    SERIES_COLOURS,
    data_uri,
    new_canvas,
    new_figure,
    render_png,
    styled,
)
from tolsim.reports.verdict import FAIL, PASS, STATUS_LABELS, UNDECIDED, study_verdict
from tolsim.study import quality
from tolsim.study.estimators import wilson_interval
from tolsim.study.quality import format_fraction

#: Default base-sample size of the sensitivity analysis per propagation mode (the cost is
#: samples x (factors + 2) assemblies; along-track propagation is ~100x dearer per assembly).
SENSITIVITY_SAMPLES = {"constant": 1024, "along_track": 64}
#: Names of the tolsim result-file variables this report needs.
REQUIRED = ("velocity_deviation_histogram", "contact_probability", "survival_probability",
            "spot_check_velocity_deviation_analytic", "spot_check_velocity_deviation_full")


class NotAResult(ValueError):
    """The file is missing, not netCDF, or not a tolsim study result."""


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


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def read_result_file(path):
    """Open a tolsim result file, or raise :class:`NotAResult` with a one-line reason."""
    path = os.fspath(path)
    if not os.path.exists(path):
        raise NotAResult(f"{path}: no such file")
    if os.path.isdir(path):
        raise NotAResult(f"{path}: is a folder, not a result file")
    with open(path, "rb") as fh:
        magic = fh.read(8)
    if not (magic.startswith(b"\x89HDF\r\n\x1a\n") or magic[:3] == b"CDF"):
        raise NotAResult(f"{path}: not a netCDF file")
    import xarray as xr

    from tolsim.io import schema

    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
    except (OSError, ValueError) as exc:
        raise NotAResult(f"{path}: cannot be read as netCDF ({' '.join(str(exc).split())})"
                         ) from None
    missing = [a for a in schema.GLOBAL_ATTRIBUTES if a not in ds.attrs]
    if missing:
        raise NotAResult(f"{path}: not a tolsim study result (netCDF without the global "
                         f"attribute(s) {', '.join(missing)})")
    absent = [v for v in REQUIRED if v not in ds.variables]
    if absent:
        raise NotAResult(f"{path}: not a complete tolsim study result (missing "
                         f"{', '.join(absent)})")
    # The full schema check (tolsim.io.schema.validate) is not applied here: the report
    # needs only the variables above, and reads older or partial files as far as it can.
    return ds


def _f(ds, name, default=np.nan):
    if name not in ds.variables:
        return default
    return float(np.asarray(ds[name]))


def _i(ds, name, default=0):
    if name not in ds.variables:
        return default
    return int(np.asarray(ds[name]))


def _edges(ds, bounds):
    b = np.asarray(ds[bounds])
    return np.concatenate([b[:, 0], b[-1:, 1]])


# --------------------------------------------------------------------------------------------
# Sensitivity
# --------------------------------------------------------------------------------------------
@dataclass
class _FileSensitivity:
    """Sensitivity indices as stored in a result file (epsilon only)."""

    factors: tuple
    outputs: tuple
    first_order: np.ndarray
    total: np.ndarray
    first_order_ci: np.ndarray
    total_ci: np.ndarray
    n: int = 0
    evaluations: int = 0
    confidence_level: float = 0.95


def sensitivity_from_file(ds):
    """The indices stored in the file (``factor`` dimension, names in ``factor_name``), or None.

    Reads the variables of :data:`tolsim.study.sensitivity.SENSITIVITY_VARIABLES`: epsilon's
    ``sensitivity_first_order`` / ``sensitivity_total`` and, when present, the contact
    indicator's ``sensitivity_contact_*`` and the ``*_ci_lower`` / ``*_ci_upper`` ends.
    """
    # the source names: the factor_name label (schema 2), or the string factor coordinate of
    # older files
    label = "factor_name" if "factor_name" in ds.variables else "factor"
    if "sensitivity_total" not in ds.variables or label not in ds.variables:
        return None
    factors = tuple(str(f) for f in np.asarray(ds[label]))
    d = len(factors)

    def get(name):
        return np.asarray(ds[name], dtype=float) if name in ds.variables else np.full(d, np.nan)

    outputs, first, total, first_ci, total_ci = [], [], [], [], []
    for prefix, output in (("", "velocity_deviation"), ("_contact", "contact")):
        if f"sensitivity{prefix}_total" not in ds.variables:
            continue
        outputs.append(output)
        first.append(get(f"sensitivity{prefix}_first_order"))
        total.append(get(f"sensitivity{prefix}_total"))
        first_ci.append(np.stack([get(f"sensitivity{prefix}_first_order_ci_lower"),
                                  get(f"sensitivity{prefix}_first_order_ci_upper")], axis=-1))
        total_ci.append(np.stack([get(f"sensitivity{prefix}_total_ci_lower"),
                                  get(f"sensitivity{prefix}_total_ci_upper")], axis=-1))
    return _FileSensitivity(factors, tuple(outputs), np.array(first), np.array(total),
                            np.array(first_ci), np.array(total_ci))


def _config_error(ds) -> str:
    """Why the embedded config cannot be parsed, or '' when it can."""
    from tolsim.io.config import ConfigError

    try:
        config_of(ds)
    except (ConfigError, KeyError, ValueError) as exc:
        return " ".join(str(exc).split())
    return ""


def compute_sensitivity(ds, samples=None):
    """Sobol' indices from the config embedded in the file (see the module docstring)."""
    from tolsim.study.sensitivity import study_sensitivity

    config = config_of(ds)
    if samples is None:
        samples = SENSITIVITY_SAMPLES.get(config.study.propagation, 256)
    return study_sensitivity(config, samples=int(samples))


# --------------------------------------------------------------------------------------------
# Figures
# --------------------------------------------------------------------------------------------
@styled
def plot_velocity_deviation(ds):
    """epsilon histogram with the spec limit; epsilon (mean +- std) and the side force ratio
    rho per ball position, in two panels with their own, separately labelled scales (on
    twin axes, a rho of 0.4 drawn level with a 0.5 % limit line read as "rho reaches the
    limit")."""
    fig = new_canvas(11.0, 5.2)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.6, 1.0], height_ratios=[1.45, 1.0])
    ax = fig.add_subplot(grid[:, 0])
    ax2 = fig.add_subplot(grid[0, 1])
    ax3 = fig.add_subplot(grid[1, 1], sharex=ax2)
    counts = np.asarray(ds["velocity_deviation_histogram"], dtype=float)
    edges = 100.0 * _edges(ds, "velocity_deviation_bin_bounds")
    limit = _f(ds, "velocity_deviation_limit")
    n = counts.sum()
    if n > 0:
        nz = np.nonzero(counts)[0]
        lo, hi = edges[nz[0]], edges[nz[-1] + 1]
        span = max(hi - lo, 20 * (edges[1] - edges[0]))
        lo, hi = lo - 0.15 * span, hi + 0.15 * span
        if np.isfinite(limit) and limit > 0:
            lo, hi = min(lo, -120 * limit), max(hi, 120 * limit)
        lo, hi = max(lo, edges[0]), min(hi, edges[-1])
        width = edges[1] - edges[0]
        ax.stairs(counts / (n * width), edges, fill=True, color=MODEL_COLOURS["full"],
                  alpha=0.8, label="valid balls")
        ax.set_xlim(lo, hi)
        ax.set_ylim(0, 1.35 * np.max(counts / (n * width)))  # room for the legend
    mean, std = 100 * _f(ds, "velocity_deviation_mean"), 100 * _f(ds, "velocity_deviation_std")
    q = np.asarray(ds["velocity_deviation_quantile"]) * 100
    levels = np.asarray(ds["quantile"])
    if np.isfinite(mean):
        m3 = round(mean, 3) or 0.0  # no "-0.000"
        ax.axvline(mean, color="k", lw=1.0, label=f"mean {m3:+.3f} %, std {std:.3f} %")
    for lev, style in ((0.001, ":"), (0.999, ":")):
        k = int(np.argmin(np.abs(levels - lev)))
        if np.isfinite(q[k]):
            ax.axvline(q[k], color="0.3", lw=1.0, ls=style,
                       label="0.1 % and 99.9 % quantiles" if lev < 0.5 else None)
    if np.isfinite(limit) and limit > 0:
        for s in (-1, 1):
            ax.axvline(100 * s * limit, color=LIMIT_COLOUR, lw=2.0, ls="--",
                       label=f"spec limit |ε| ≤ {100 * limit:.3g} %" if s > 0 else None)
    under, over = _i(ds, "velocity_deviation_underflow"), _i(ds, "velocity_deviation_overflow")
    title = f"(a) ε of {int(n + under + over):,} valid balls"
    if under or over:
        title += f" ({under + over} outside the histogram range)"
    ax.set_title(title)
    ax.set_xlabel("velocity deviation ε [%]  (v_B = (1 + ε) v/2)")
    ax.set_ylabel("probability density [1/%]")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)

    balls = np.asarray(ds["ball"])
    m = 100 * np.asarray(ds["velocity_deviation_mean_by_ball"], dtype=float)
    sd = 100 * np.asarray(ds["velocity_deviation_std_by_ball"], dtype=float)
    ax2.errorbar(balls + 1, m, yerr=np.nan_to_num(sd), fmt="o-", color=SERIES_COLOURS[2],
                 capsize=3, lw=1.2, ms=4, label="mean ± 1 std")
    ax2.axhline(0, color="0.5", lw=0.6)
    if np.isfinite(limit) and limit > 0:
        for s in (-1, 1):
            ax2.axhline(100 * s * limit, color=LIMIT_COLOUR, lw=1.5, ls="--",
                        label="spec limit on |ε|" if s > 0 else None)
        ax2.legend(loc="lower right", fontsize=7.5, ncols=2, framealpha=0.9)
        top = max(120 * limit, np.nanmax(np.abs(m) + np.nan_to_num(sd), initial=0) * 1.1)
        ax2.set_ylim(-1.45 * top if top else -1, top if top else 1)  # room for the legend
    ax2.set_ylabel("ε [%]")
    ax2.set_title("(b) ε along the train: mean ± 1 std per position", fontsize=10)
    ax2.tick_params(labelbottom=False)
    ticks = balls + 1 if len(balls) <= 20 else np.linspace(1, len(balls), 6).round()
    rho = np.asarray(ds["side_force_ratio"], dtype=float)
    ax3.plot(balls + 1, rho, "s-", color=SERIES_COLOURS[3], lw=1.2, ms=4)
    ax3.axhline(0, color="0.5", lw=0.6)
    reach = float(np.nanmax(np.abs(rho), initial=0.0))
    ax3.set_ylim(-1.25 * reach if reach > 0 else -0.1, 1.25 * reach if reach > 0 else 0.1)
    ax3.set_xticks(ticks)
    ax3.set_xlabel("ball position in the train [-] (1 = trailing)")
    ax3.set_ylabel("ρ = N_x / N_y [-]")
    ax3.set_title("(c) side force ratio ρ per position (the load, not ε)", fontsize=10)
    return fig


@styled
def plot_contact(ds):
    """Survival curve with a pointwise band; P(contact) and its CI; first-contact pairs."""
    fig, (ax, ax_p, ax_pair) = new_figure(12.0, 4.2, ncols=3, width_ratios=[1.7, 0.7, 1.0])
    # the survival curve's times: elapsed_time (schema 2), time in older files
    t = np.asarray(ds[ds["survival_probability"].dims[0]], dtype=float)
    s = np.asarray(ds["survival_probability"], dtype=float)
    n = _i(ds, "n_assemblies_valid")
    v = _f(ds, "groove_velocity")
    if n > 0:
        k = np.round((1.0 - s) * n)
        band = np.array([wilson_interval(kk, n) for kk in k])
        ax.fill_between(t, 1 - band[:, 1], 1 - band[:, 0], step="post", color="0.8",
                        label="95 % interval (Wilson, pointwise)")
    ax.step(t, s, where="post", color=MODEL_COLOURS["full"], lw=1.8,
            label=f"P(no contact by t), {n:,} resolved trains")
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlim(t[0], t[-1])
    ax.set_xlabel("time since the start of the stroke t [s]")
    ax.set_ylabel("survival probability [-]")
    ax.set_title("(a) survival: no ball-to-ball contact yet")
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    if np.isfinite(v) and v > 0:
        sec = ax.secondary_xaxis("top", functions=(lambda x: 1e3 * v * x,
                                                   lambda y: y / (1e3 * v)))
        sec.set_xlabel("carriage travel [mm]")

    p, lo, hi = (_f(ds, x) for x in ("contact_probability", "contact_probability_ci_lower",
                                      "contact_probability_ci_upper"))
    limit = _f(ds, "contact_probability_limit")
    if np.isfinite(p):
        ax_p.bar([0], [p], color=SERIES_COLOURS[1], width=0.5, alpha=0.85)
        ax_p.errorbar([0], [p], yerr=[[p - lo], [hi - p]], color="k", capsize=6, lw=1.5)
        ax_p.set_xticks([0], [f"P = {format_fraction(p)}\n95 % CI\n{format_fraction(lo)} to "
                              f"{format_fraction(hi)}"], fontsize=8.5)
    top = max(hi if np.isfinite(hi) else 0.0, limit if np.isfinite(limit) else 0.0)
    ax_p.set_ylim(0, min(1.0, 1.45 * top) if top > 0 else 1.0)
    if np.isfinite(limit) and limit > 0:
        ax_p.axhline(limit, color=LIMIT_COLOUR, ls="--", lw=2,
                     label=f"limit {format_fraction(limit)}")
        ax_p.legend(loc="upper center", fontsize=8)  # above the bar: ylim leaves room
    ax_p.set_xlim(-0.8, 0.8)
    ax_p.set_xlabel("contact within the horizon")
    ax_p.set_ylabel("P(contact within the horizon) per train [-]")
    ax_p.set_title("(b) contact probability\n(95 % Clopper-Pearson)", fontsize=10)

    if "contact_pair_count" in ds.variables and ds.sizes.get("pair", 0) > 0:
        pairs = np.asarray(ds["pair"])
        cnt = np.asarray(ds["contact_pair_count"], dtype=float)
        ax_pair.bar(pairs + 1, cnt, color=SERIES_COLOURS[2], alpha=0.85)
        ax_pair.set_xticks(pairs + 1 if len(pairs) <= 20 else
                           np.linspace(1, len(pairs), 6).round())
    ax_pair.set_xlabel("pair of balls j, j+1 [-] (1 = trailing pair)")
    ax_pair.set_ylabel("trains whose first contact is here [-]")
    ax_pair.set_title("(c) where the first contact happens")
    return fig


#: Markers of the spot-check strata (``spot_check_stratum``).
STRATUM_MARKERS = {0: ("o", "drawn uniformly"), 1: ("D", "near the spec limit")}


@styled
def plot_spot_checks(ds):
    """The study's model against the full friction model on the spot-checked balls: identity
    plot, difference, and the counts beside them (nothing drawn over the points).

    Circles are balls drawn uniformly, diamonds balls drawn near the spec limit on |epsilon|
    (``spot_check_stratum``); crosses are balls flagged invalid by one model.
    """
    from matplotlib.ticker import MaxNLocator

    from tolsim.physics.analytic import VALIDITY_ERROR_BUDGET

    fig = new_canvas(11.5, 4.9)
    ax, ax2, ax_text = fig.subplots(1, 3, width_ratios=[1.0, 1.0, 0.62])
    ea = 100 * np.asarray(ds["spot_check_velocity_deviation_analytic"], dtype=float)
    ef = 100 * np.asarray(ds["spot_check_velocity_deviation_full"], dtype=float)
    k = ea.size
    va = np.asarray(ds["spot_check_valid_analytic"], dtype=bool) if k else np.zeros(0, bool)
    vf = np.asarray(ds["spot_check_valid_full"], dtype=bool) if k else np.zeros(0, bool)
    stratum = (np.asarray(ds["spot_check_stratum"], dtype=int) if "spot_check_stratum" in ds
               else np.zeros(k, int))
    both = va & vf
    model = ds.attrs.get("velocity_model", "analytic")
    limit = 100 * _f(ds, "velocity_deviation_limit")
    budget = 100 * VALIDITY_ERROR_BUDGET
    diff = ea - ef
    finite = np.isfinite(ea) & np.isfinite(ef)
    if k:
        for code, (marker, name) in STRATUM_MARKERS.items():
            sel = both & (stratum == code)
            if sel.any():
                kw = dict(ms=5, color=MODEL_COLOURS["analytic"], ls="none", marker=marker,
                          mfc=MODEL_COLOURS["analytic"] if code == 0 else "white", mew=1.3)
                ax.plot(ef[sel], ea[sel], label=f"{name}, valid in both ({sel.sum()})", **kw)
                ax2.plot(ef[sel], diff[sel], **kw)
        other = ~both & finite
        if other.any():
            ax.plot(ef[other], ea[other], "x", ms=6, color=LIMIT_COLOUR,
                    label=f"invalid in one model ({other.sum()})")
            ax2.plot(ef[other], diff[other], "x", ms=6, color=LIMIT_COLOUR)
        values = np.concatenate([ea[np.isfinite(ea)], ef[np.isfinite(ef)]])
        if values.size:
            lo, hi = values.min(), values.max()
            pad = 0.08 * max(hi - lo, 1e-3)
            line = np.array([lo - pad, hi + pad])
            ax.plot(line, line, color="k", lw=0.8, label="identity")
            ax.set_xlim(*line)
            ax.set_ylim(*line)
            ax2.set_xlim(*line)
            if np.isfinite(limit) and limit > 0:
                shown = [x for x in (-limit, limit) if line[0] <= x <= line[1]]
                for j, x in enumerate(shown):
                    for a in (ax, ax2):
                        a.axvline(x, color=LIMIT_COLOUR, lw=1.2, ls="--",
                                  label="spec limit on |ε|" if a is ax and j == 0 else None)
        ax2.axhline(0, color="k", lw=0.8)
        if finite.any() and np.nanmax(np.abs(diff[finite])) > 0.25 * budget:
            for y in (-budget, budget):
                ax2.axhline(y, color="0.45", lw=1.0, ls=":")
            ax.plot([], [], color="0.45", lw=1.0, ls=":",
                    label=f"validity budget ±{budget:.2g} pp (in b)")
    for a in (ax, ax2):
        a.xaxis.set_major_locator(MaxNLocator(nbins=5))
        a.yaxis.set_major_locator(MaxNLocator(nbins=6))
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("ε, full friction model [%]")
    ax.set_ylabel(f"ε, study model '{model}' [%]")
    ax.set_title(f"(a) spot checks: {k} balls re-solved", fontsize=10.5)
    ax2.set_xlabel("ε, full friction model [%]")
    ax2.set_ylabel(f"ε '{model}' − ε full [percentage points]")
    ax2.set_title("(b) difference", fontsize=10.5)
    if ax.get_legend_handles_labels()[0]:
        fig.legend(*ax.get_legend_handles_labels(), loc="outside lower center", ncols=3,
                   fontsize=8, frameon=False)
    ax_text.set_axis_off()
    ax_text.set_title("(c) counts", fontsize=10.5)
    ax_text.text(0.0, 1.0, _spot_check_counts(ds, model, stratum, va, vf, diff, budget),
                 transform=ax_text.transAxes, ha="left", va="top", fontsize=8.5,
                 linespacing=1.45, wrap=True)
    return fig


def _spot_check_counts(ds, model, stratum, va, vf, diff, budget):
    """The text beside the spot-check plots."""
    k = stratum.size
    if not k:
        return str(ds.attrs.get("spot_check_status", "no spot checks"))
    both = va & vf
    near = stratum == 1
    lines = [f"spot checks: {k}"]
    if near.any():
        lines.append(f"  drawn uniformly: {int((~near).sum())}")
        band = (100 * _f(ds, "spot_check_band_lower"), 100 * _f(ds, "spot_check_band_upper"))
        lines.append(f"  near the limit: {int(near.sum())}")
        lines.append(f"    ({band[0]:.3g} % ≤ |ε| ≤ {band[1]:.3g} %,")
        lines.append(f"    {_i(ds, 'spot_check_band_balls'):,} balls in that band)")
    lines += [f"valid in both models: {int(both.sum())}",
              f"'{model}' invalid (re-solved): {int((~va).sum())}",
              f"full invalid / not converged: {int((~vf).sum())}",
              "",
              f"'{model}' − full [pp]:"]
    for name, sel in (("uniform", both & ~near), ("near limit", both & near)):
        if sel.any():
            d = diff[sel]
            lines.append(f"  {name}: RMS {np.sqrt(np.mean(d * d)):.4f},")
            lines.append(f"    max |·| {np.max(np.abs(d)):.4f}")
    inside = int(np.sum(np.abs(diff[both]) <= budget))
    lines.append(f"inside the ±{budget:.2g} pp budget: {inside} of {int(both.sum())}")
    return "\n".join(lines)


OUTPUT_TITLES = {"velocity_deviation": "share of the variance of ε",
                 "contact": "influence on ball-to-ball contact (indicator per train)"}
OUTPUT_SHORT = {"velocity_deviation": "the scatter of ε", "contact": "ball-to-ball contact"}


@styled
def plot_sensitivity(sens):
    """Ranked bars of the total-effect and first-order indices, one panel per output."""
    outputs = list(sens.outputs)
    d = len(sens.factors)
    fig, axes = new_figure(5.2 * len(outputs) + 1.0, max(3.4, 1.5 + 0.42 * d),
                           ncols=len(outputs), squeeze=False)
    for ax, output in zip(axes[0], outputs, strict=True):
        k = outputs.index(output)
        total = sens.total[k]
        order = np.argsort(np.nan_to_num(total, nan=-1.0))  # largest at the top
        y = np.arange(d)
        tot, first = total[order], sens.first_order[k][order]
        ci_t = sens.total_ci[k][order]
        err = np.abs(np.stack([tot - ci_t[:, 0], ci_t[:, 1] - tot]))
        ax.barh(y + 0.18, np.nan_to_num(tot), height=0.36, color=SERIES_COLOURS[0],
                label="total effect S_T")
        ax.errorbar(np.nan_to_num(tot), y + 0.18, xerr=np.nan_to_num(err), fmt="none",
                    ecolor="k", capsize=2, lw=0.8)
        ax.barh(y - 0.18, np.nan_to_num(first), height=0.36, color=SERIES_COLOURS[4],
                label="first order S")
        ci_f = sens.first_order_ci[k][order]
        err_f = np.abs(np.stack([first - ci_f[:, 0], ci_f[:, 1] - first]))
        ax.errorbar(np.nan_to_num(first), y - 0.18, xerr=np.nan_to_num(err_f), fmt="none",
                    ecolor="k", capsize=2, lw=0.8)
        ax.set_yticks(y, [sens.factors[i].replace("_", " ") for i in order], fontsize=8.5)
        ends = np.concatenate([sens.total_ci[k].ravel(), sens.first_order_ci[k].ravel()])
        ends = ends[np.isfinite(ends)]
        ax.set_xlim(max(-1.0, min(-0.05, ends.min() - 0.02)) if ends.size else -0.05,
                    min(2.0, max(1.05, ends.max() + 0.02)) if ends.size else 1.05)
        ax.axvline(0, color="0.4", lw=0.8)
        ax.set_xlabel("Sobol' index [-] (bars: 95 % bootstrap interval)")
        ax.set_ylabel("tolerance source")
        ax.set_title(OUTPUT_TITLES.get(output, output), fontsize=10)
        if np.all(np.isnan(total)):
            ax.text(0.5, 0.5, "output does not vary:\nno index", transform=ax.transAxes,
                    ha="center", va="center")
        ax.legend(loc="lower right", fontsize=8)
    fig.suptitle(f"What drives the risk: Sobol' indices, n = {sens.n} per base sample "
                 f"({sens.evaluations:,} assemblies evaluated)" if sens.n else
                 "What drives the risk: Sobol' indices stored in the result file",
                 fontsize=10.5)
    return fig


@styled
def plot_quality(ds, q):
    """Tails of epsilon on a log scale against the limit, with the normal fit and Cpk."""
    fig, ax = new_figure(7.5, 4.3)
    counts = np.asarray(ds["velocity_deviation_histogram"], dtype=float)
    edges = 100.0 * _edges(ds, "velocity_deviation_bin_bounds")
    n = counts.sum()
    limit = 100 * _f(ds, "velocity_deviation_limit")
    width = edges[1] - edges[0]
    centres = 0.5 * (edges[:-1] + edges[1:])
    dens = np.where(counts > 0, counts / (max(n, 1) * width), np.nan)
    ax.semilogy(centres, dens, ".", ms=3, color=MODEL_COLOURS["full"],
                label="histogram (valid balls)")
    mean, std = 100 * _f(ds, "velocity_deviation_mean"), 100 * _f(ds, "velocity_deviation_std")
    if std > 0:
        x = np.linspace(min(edges[0], -1.3 * limit), max(edges[-1], 1.3 * limit), 600)
        pdf = np.exp(-0.5 * ((x - mean) / std) ** 2) / (std * np.sqrt(2 * np.pi))
        ax.semilogy(x, pdf, color="k", lw=1.0, label="normal with the same mean and std")
    for s in (-1, 1):
        ax.axvline(s * limit, color=LIMIT_COLOUR, lw=2, ls="--",
                   label=f"spec limit |ε| ≤ {limit:.3g} %" if s > 0 else None)
    floor = 0.3 / (max(n, 1) * width)
    ax.set_ylim(floor, None)
    span = max(1.4 * limit, np.nanmax(np.abs(centres[counts > 0])) * 1.1 if n else limit)
    ax.set_xlim(-span, span)
    ax.set_xlabel("velocity deviation ε [%]")
    ax.set_ylabel("probability density [1/%] (log)")
    prop, cap = q.get("_proportion"), q.get("_capability")
    lines = [f"out of spec: {prop.text()}" if prop is not None else ""]
    if cap is not None:
        lines.append(f"Cpk = {cap.cpk:.2f} (95 % CI {cap.cpk_lower:.2f} to "
                     f"{cap.cpk_upper:.2f}), Cp = {cap.cp:.2f}")
        if np.isfinite(cap.cpk_percentile):
            lines.append(f"percentile Cpk = {cap.cpk_percentile:.2f}")
        lines.append(f"normal theory out of spec: {format_fraction(cap.normal_out_of_spec)}")
    ax.set_title("Quality: tails of ε against the specification", fontsize=10.5)
    ax.text(0.02, 0.97, "\n".join(lines), transform=ax.transAxes, va="top", ha="left",
            fontsize=8, bbox=dict(boxstyle="round", fc="white", ec="0.7", alpha=0.9))
    ax.legend(loc="upper right", fontsize=8)
    return fig


# --------------------------------------------------------------------------------------------
# HTML
# --------------------------------------------------------------------------------------------
CSS = """
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
#: Fields of the sign-off block (HTML and PDF).
SIGN_OFF_ROLES = ("Prepared by", "Reviewed by", "Approved by")
SIGN_OFF_FIELDS = ("name", "function", "date", "signature")
SIGN_OFF_DECISIONS = ("accepted", "accepted with conditions", "rejected")


def _row(label, value, num=True):
    cls = ' class="num"' if num else ""
    return f"<tr><th>{html.escape(label)}</th><td{cls}>{html.escape(str(value))}</td></tr>"


def _pct(x, digits=3):
    if not np.isfinite(x):
        return "n/a"
    v = round(100 * x, digits) or 0.0  # no "-0.000"
    return f"{v:+.{digits}f} %"


def _tolerance_rows(ds):
    """Tolerance table rows (:func:`tolsim.reports.assumptions.tolerance_table`), the initial
    gap included; the config's keys as written when it cannot be parsed."""
    try:
        config = config_of(ds)
    except Exception:  # noqa: BLE001 - the report must not fail on an old config
        config = None
    return tolerance_table(config, ds)


def section_titles(ds) -> dict:
    """Figure name -> heading of its section; the model check names the study's velocity
    model (``velocity_model`` attribute)."""
    model = ds.attrs.get("velocity_model", "?")
    return {"velocity_deviation": "3. Ball velocity deviation ε",
            "contact": "4. Ball-to-ball contact",
            "quality": "5. Quality engineering",
            "sensitivity": "6. What drives the risk",
            "spot_checks": f"7. Model check: {model} versus the full friction model"}


def study_facts(ds) -> list:
    """(label, value, numeric) rows of "what was studied" (HTML and PDF)."""
    a = ds.attrs
    return [
        ("assemblies (trains) sampled", f"{_i(ds, 'n_assemblies'):,}", True),
        ("balls per train", ds.sizes.get("ball", "?"), True),
        ("balls evaluated", f"{_i(ds, 'n_balls'):,}", True),
        ("stroke duration (horizon)", f"{_f(ds, 'horizon'):.4g} s", True),
        ("carriage speed v", f"{1e3 * _f(ds, 'groove_velocity'):.4g} mm/s", True),
        ("carriage travel", f"{1e3 * _f(ds, 'horizon') * _f(ds, 'groove_velocity'):.4g} mm",
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
    n_asm = _i(ds, "n_assemblies")
    n_unres = _i(ds, "n_assemblies_unresolved")
    p, lo, hi = (_f(ds, x) for x in ("contact_probability", "contact_probability_ci_lower",
                                      "contact_probability_ci_upper"))
    travel = 1e3 * _f(ds, "horizon") * _f(ds, "groove_velocity")
    out = [f"P(ball-to-ball contact within the {travel:.4g} mm stroke) = "
           f"{format_fraction(p, lo, hi)} per train ({_i(ds, 'n_contact'):,} of "
           f"{n_asm - n_unres:,} trains whose outcome is known)."]
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


def _stackup_rows(ds):
    """Worst case and RSS of the linear stack-up beside the Monte Carlo (HTML parts)."""
    if "critical_ball" not in ds:
        return []
    b, pr = _i(ds, "critical_ball"), _i(ds, "critical_pair")

    def at(name, k):
        return float(np.asarray(ds[name])[k])

    return [
        "<h3>Linear stack-up beside the Monte Carlo</h3><table>",
        "<tr><th>quantity</th><th>nominal</th><th>worst case (± over the tolerance bands)"
        "</th><th>RSS (1σ)</th><th>Monte Carlo std</th></tr>",
        f"<tr><td>ε of ball {b} (largest RSS)</td>"
        f"<td class='num'>{_pct(at('velocity_deviation_nominal', b))}</td>"
        f"<td class='num'>±{100 * at('velocity_deviation_worst_case', b):.3f} %</td>"
        f"<td class='num'>{100 * at('velocity_deviation_rss', b):.3f} %</td>"
        f"<td class='num'>{100 * at('velocity_deviation_std_by_ball', b):.3f} %</td></tr>",
        f"<tr><td>gap closure of pair {pr} over the stroke</td>"
        f"<td class='num'>{1e6 * at('gap_closure_nominal', pr):.3g} µm</td>"
        f"<td class='num'>±{1e6 * at('gap_closure_worst_case', pr):.3g} µm</td>"
        f"<td class='num'>{1e6 * at('gap_closure_rss', pr):.3g} µm</td><td>–</td></tr>",
        "</table><p class='muted'>Linearised sensitivities at the mean state (central "
        "differences through the study's own models, <code>tolsim.study.worst_case</code>): "
        "the worst case adds every source at the edge of its band, RSS adds them as "
        "independent standard deviations (with the rail fields' correlation). Where RSS and "
        "the Monte Carlo std agree, the model is near-linear over the tolerances; the "
        "Monte Carlo figures are the ones to use.</p>",
    ]


def _html(ds, figures, sens, sens_source, q, path, verdict=None):
    a = ds.attrs
    n_asm = _i(ds, "n_assemblies")
    model = str(a.get("velocity_model", "?"))
    verdict = verdict if verdict is not None else study_verdict(ds, q)
    tolerances = _tolerance_rows(ds)
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(a.get('title', 'tolsim report'))}</title>",
        f"<style>{CSS}</style></head><body>",
        f"<h1>{html.escape(a.get('title', 'tolsim study'))}</h1>",
        f"<p class='muted'>Report of <code>{html.escape(os.path.basename(path))}</code>, "
        f"made by tolsim {__version__} on "
        f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}. The same report as PDF, with "
        "the sign-off fields: <code>report.pdf</code>.</p>",
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
        parts.append("</table><p class='muted'>Scope: rail and carriage errors are drawn once "
                     "per assembly (or as a random field along the rail with a correlation "
                     "length), ball errors per ball, the gap per adjacent pair.</p>")
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
    # key numbers
    p, lo, hi = (_f(ds, x) for x in ("contact_probability", "contact_probability_ci_lower",
                                      "contact_probability_ci_upper"))
    tq = np.asarray(ds["time_to_contact_quantile"], dtype=float)
    lev = np.asarray(ds["quantile"])
    med = tq[int(np.argmin(np.abs(lev - 0.5)))]
    n_unres = _i(ds, "n_assemblies_unresolved")
    bounds = [_f(ds, f"contact_probability_{x}") for x in (
        "bound_lower", "bound_upper", "bounds_ci_lower", "bounds_ci_upper")]
    parts += [
        "<h2>2. Results at a glance</h2><table>",
        _row("P(ball-to-ball contact within the stroke)",
             f"{format_fraction(p, lo, hi)}  ({_i(ds, 'n_contact'):,} of "
             f"{n_asm - n_unres:,} trains whose outcome is known; Clopper-Pearson)"),
        *([_row(f"bounds over all {n_asm:,} trains ({n_unres:,} unresolved counted as no "
                "contact / contact)",
                f"{format_fraction(bounds[0])} to {format_fraction(bounds[1])} (95 % interval "
                f"{format_fraction(bounds[2])} to {format_fraction(bounds[3])})")]
          if n_unres else []),
        _row("propagation model", a.get("propagation_assumption", a.get("propagation", "?")),
             False),
        _row("earliest / median first contact (given contact)",
             f"{_f(ds, 'time_to_contact_min'):.4g} s / {med:.4g} s"
             if _i(ds, "n_contact") else "no contact"),
        _row("ε mean / std", f"{_pct(_f(ds, 'velocity_deviation_mean'))} / "
                             f"{100 * _f(ds, 'velocity_deviation_std'):.3f} %"),
        _row("ε range", f"{_pct(_f(ds, 'velocity_deviation_min'))} to "
                        f"{_pct(_f(ds, 'velocity_deviation_max'))}"),
        _row(f"balls outside the {model} model's validity, re-solved with the full model",
             f"{_i(ds, 'n_balls_resolved_full'):,} of {_i(ds, 'n_balls_outside_validity'):,} "
             f"in {float(a.get('full_model_resolve_seconds', 0.0)):.2f} s"),
        _row("unresolved balls (static not converged / loss of contact / full model failed)",
             f"{_i(ds, 'n_balls_not_converged')} / {_i(ds, 'n_balls_loss_of_contact')} / "
             f"{_i(ds, 'n_balls_full_failed')}; {n_unres} trains unresolved (none left out: "
             "see the bounds)"),
        "</table>",
        *([f"<p class='verdict'>{html.escape(a['propagation_caveat'])}</p>"]
          if a.get("propagation_caveat") else []),
    ]

    def fig(name, caption=None):
        caption = caption or CAPTIONS.get(name, name)
        if name in figures:
            parts.append(f"<figure><img alt='{html.escape(caption)}' "
                         f"src='{data_uri(figures[name])}'><figcaption class='muted'>"
                         f"{html.escape(caption)}</figcaption></figure>")

    titles = section_titles(ds)
    parts.append(f"<h2>{html.escape(titles['velocity_deviation'])}</h2>")
    fig("velocity_deviation")
    parts.append(f"<h2>{html.escape(titles['contact'])}</h2>")
    fig("contact")
    parts.append(f"<h2>{html.escape(titles['quality'])}</h2>")
    if q:
        prop, cap = q["_proportion"], q["_capability"]
        limit = 100 * _f(ds, "velocity_deviation_limit")
        parts += ["<table>", _row("spec limit", f"|ε| ≤ {limit:.4g} %"),
                  _row("balls out of spec", f"{prop.text()} ({prop.method}"
                       + (f"; design effect {prop.design_effect:.2f}"
                          if np.isfinite(getattr(prop, "design_effect", np.nan)) else "")
                       + ")")]
        if cap is not None:
            parts += [_row("Cpk = (L − |μ|)/(3σ)", f"{cap.cpk:.3f} (95 % CI {cap.cpk_lower:.3f} "
                                                   f"to {cap.cpk_upper:.3f}, {cap.method})"),
                      _row("Cp = L/(3σ)", f"{cap.cp:.3f}"),
                      _row("percentile Cpk (ISO 22514-2)", f"{cap.cpk_percentile:.3f}"),
                      _row("out of spec if ε were normal", format_fraction(
                          cap.normal_out_of_spec))]
        parts.append("</table>")
        parts.append("<p class='muted'>Balls of one assembly share its rail and carriage "
                     "errors, so they are correlated: the intervals take the assembly as the "
                     "sampling unit (ratio estimator with Korn &amp; Graubard's effective "
                     "sample size for the fraction out of spec, delta method over assemblies "
                     "for Cpk; Cochran, Sampling Techniques, 1977, Ch. 6 and 9). "
                     "Cpk: distance from the mean of ε to the nearer spec "
                     "limit in units of 3σ; 1.33 means 4σ. Where the two Cpk differ, ε is "
                     "not normal and the percentile index is the one to use. "
                     "Fractions below 0.1 % are shown in ppm.</p>")
        fig("quality")
    else:
        parts.append("<p>No limit on |ε| in the config (<code>[study] "
                     "velocity_deviation_limit_percent</code> or <code>_ppm</code>): no "
                     "fraction out of spec or capability index.</p>")
    parts += _stackup_rows(ds)
    parts.append(f"<h2>{html.escape(titles['sensitivity'])}</h2>")
    if sens is None:
        parts.append(f"<p>{html.escape(sens_source)}</p>")
    elif len(sens.factors) == 0:
        parts.append("<p>The study has no random tolerance: every assembly is the same, "
                     "nothing to rank.</p>")
    else:
        parts.append(f"<p class='muted'>{html.escape(sens_source)}</p>")
        fig("sensitivity")
        for k, output in enumerate(sens.outputs):
            if np.all(np.isnan(sens.total[k])):
                parts.append(f"<p>{html.escape(OUTPUT_TITLES.get(output, output))}: the "
                             "output does not vary, no ranking.</p>")
                continue
            top = int(np.nanargmax(sens.total[k]))
            parts.append(
                f"<p class='verdict'>Largest driver of "
                f"{html.escape(OUTPUT_SHORT.get(output, output))}: "
                f"{html.escape(sens.factors[top])} (total effect {sens.total[k, top]:.2f}, "
                f"alone {sens.first_order[k, top]:.2f}).</p>")
            parts.append(f"<h3>Ranked by {html.escape(OUTPUT_TITLES.get(output, output))}"
                         "</h3><table><tr><th>rank</th><th>tolerance</th>"
                         "<th>total effect S_T [95 % CI]</th><th>first order S</th></tr>")
            order = np.argsort(-np.nan_to_num(sens.total[k], nan=-1.0), kind="stable")
            for rank, i in enumerate(order, 1):
                t, (tl, th) = sens.total[k, i], sens.total_ci[k, i]
                parts.append(f"<tr><td class='num'>{rank}</td><td>{html.escape(sens.factors[i])}"
                             f"</td><td class='num'>{t:.3f} [{tl:.3f}, {th:.3f}]</td>"
                             f"<td class='num'>{sens.first_order[k, i]:.3f}</td></tr>")
            parts.append("</table>")
    parts.append(f"<h2>{html.escape(titles['spot_checks'])}</h2>")
    fig("spot_checks")
    parts.append(f"<p class='muted'>{html.escape(str(a.get('spot_check_status', '')))}</p>")
    parts.append("<h2 id='sign-off'>8. Review and sign-off</h2><table class='signoff'><tr>"
                 "<th></th>" + "".join(f"<th>{f}</th>" for f in SIGN_OFF_FIELDS) + "</tr>")
    for role in SIGN_OFF_ROLES:
        parts.append(f"<tr><th>{role}</th>" + "<td></td>" * len(SIGN_OFF_FIELDS) + "</tr>")
    parts.append("</table><p>Decision: " + " &nbsp; ".join(
        f"&#9744; {d}" for d in SIGN_OFF_DECISIONS) + "</p>")
    parts.append("<h2>Provenance</h2><table>")
    for key in ("Conventions", "source", "history", "seed", "references",
                "contact_probability_interval", "velocity_deviation_quantile_resolution",
                "time_to_contact_quantile_resolution", "elapsed_seconds", "workers"):
        if key in a:
            parts.append(_row(key, a[key], False))
    parts.append("</table></body></html>")
    return "\n".join(parts)


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------
def make_report(path, folder, *, sensitivity=True, sensitivity_samples=None,
                progress=None, pdf=True, out_of_spec_limit=None,
                cpk_minimum=None) -> ReportOutputs:
    """Write ``report.html``, ``report.pdf`` and the PNGs of a result file into ``folder``.

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

    Returns
    -------
    ReportOutputs

    Raises
    ------
    NotAResult
        If ``path`` is not a tolsim result.
    """
    say = progress or (lambda msg: None)
    ds = read_result_file(path)
    os.makedirs(folder, exist_ok=True)
    out = ReportOutputs(os.fspath(folder))
    sens = sensitivity_from_file(ds)
    if sens is not None:
        source = "Sobol' indices stored in the result file by tolsim run."
    elif sensitivity and (config_error := _config_error(ds)):
        source = ("Sensitivity indices not computed: the config stored in the file cannot "
                  f"be parsed by this tolsim version ({config_error}).")
    elif sensitivity:
        say("sensitivity (Sobol' indices from the embedded config)")
        sens = compute_sensitivity(ds, sensitivity_samples)
        source = (f"Computed by tolsim report from the config stored in the file (seed "
                  f"{ds.attrs.get('seed')}): Saltelli/Jansen estimators, n = {sens.n} "
                  f"assemblies per base sample, {sens.evaluations:,} assemblies in all, "
                  f"95 % bootstrap intervals. ε is pooled over the train positions (the "
                  f"share of the variance at a fixed position, so the load's variation "
                  f"along the train is not counted as a tolerance effect).")
    else:
        source = "Sensitivity analysis not requested (--no-sensitivity)."
    out.sensitivity, out.sensitivity_source = sens, source
    q = quality.dataset_quality(ds)
    out.quality = q
    out.verdict = study_verdict(ds, q, out_of_spec_limit=out_of_spec_limit,
                                cpk_minimum=cpk_minimum)

    say("figures")
    figs = {"velocity_deviation": plot_velocity_deviation(ds), "contact": plot_contact(ds),
            "spot_checks": plot_spot_checks(ds)}
    if q:
        figs["quality"] = plot_quality(ds, q)
    if sens is not None and len(sens.factors):
        figs["sensitivity"] = plot_sensitivity(sens)
    pngs = {}
    for name, fig in figs.items():
        pngs[name] = render_png(fig)
        p = os.path.join(folder, f"{name}.png")
        with open(p, "wb") as fh:
            fh.write(pngs[name])
        out.figures[name] = p
    say("report.html")
    out.html = os.path.join(folder, "report.html")
    with open(out.html, "w", encoding="utf-8") as fh:
        fh.write(_html(ds, pngs, sens, source, q, os.fspath(path), out.verdict))
    if pdf:
        say("report.pdf")
        out.pdf = write_report_pdf(ds, figs, sens, out.verdict, path,
                                   os.path.join(folder, "report.pdf"))
    return out


def write_report_pdf(ds, figs, sens, verdict, path, pdf_path) -> str:
    """The PDF of a report (:func:`tolsim.reports.pdf.write_pdf`): ``figs`` are the report's
    Figures by name, rendered again at :data:`tolsim.reports.pdf.FIGURE_DPI`."""
    from tolsim.reports import pdf

    return pdf.write_pdf(pdf_path, **pdf_content(ds, figs, sens, verdict, path))


def pdf_content(ds, figs, sens, verdict, path) -> dict:
    """The arguments of :func:`tolsim.reports.pdf.report_pages` for a result file."""
    from tolsim.reports import pdf

    order = ("velocity_deviation", "contact", "quality", "sensitivity", "spot_checks")
    pngs = {name: render_png(figs[name], dpi=pdf.FIGURE_DPI) for name in order if name in figs}
    a = ds.attrs
    subtitle = (f"Result file {os.path.basename(os.fspath(path))}, report by tolsim "
                f"{__version__} on {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}; "
                f"study run by {a.get('source', '?')}: {a.get('history', '?')}")
    return dict(
        title=str(a.get("title", "tolsim study")), subtitle=subtitle,
        verdict=verdict, headline=headline(ds, sens),
        facts=[(label, str(value)) for label, value, _ in study_facts(ds)],
        tolerances=_tolerance_rows(ds), assumptions=assumption_table(ds), figures=pngs,
        captions=CAPTIONS, sections=section_titles(ds), result_path=os.fspath(path),
        sign_off=(SIGN_OFF_ROLES, SIGN_OFF_FIELDS, SIGN_OFF_DECISIONS))
