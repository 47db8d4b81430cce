"""The report of a study result file (``tolsim report``): one self-contained HTML page + PNGs.

:func:`make_report` reads a result written by ``tolsim run`` (:mod:`tolsim.io.netcdf`) and
writes, into a folder:

* ``velocity_deviation.png``: the epsilon distribution (histogram) with the spec limit, and
  epsilon along the train (mean and standard deviation per ball position);
* ``contact.png``: the survival curve P(no contact by t) with a pointwise 95 % band, the
  contact probability with its interval against a spec limit, and which pair touches first;
* ``spot_checks.png``: analytic-versus-full identity plot with validity counts;
* ``sensitivity.png``: the tolerance sources ranked by their Sobol' total-effect index on
  epsilon and on the contact indicator (:mod:`tolsim.study.sensitivity`);
* ``quality.png`` (with a limit on |epsilon|): the tails of epsilon on a log scale against
  the limit, the fraction out of spec and Cpk (:mod:`tolsim.study.quality`);
* ``report.html`` with all of them embedded as data URIs, the study's config and provenance.

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
from tolsim.reports.style import (
    LIMIT_COLOUR,
    MODEL_COLOURS,
    SERIES_COLOURS,
    data_uri,
    new_figure,
    render_png,
    styled,
)
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


def config_of(ds):
    """The :class:`~tolsim.study.spec.StudyConfig` embedded in a result (seed of the file)."""
    from tolsim.io.config import parse_config

    name = ds.attrs.get("title", "result").split(": ", 1)[-1]
    config = parse_config(str(ds.attrs["config"]), name)
    return config.with_overrides(seed=int(ds.attrs["seed"]))


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
    """epsilon histogram with the spec limit; mean +- std of epsilon per ball position."""
    fig, (ax, ax2) = new_figure(11.0, 4.3, ncols=2, width_ratios=[1.6, 1.0])
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
    ax2.errorbar(balls + 1, m, yerr=np.nan_to_num(sd), fmt="o-", color=SERIES_COLOURS[1],
                 capsize=3, lw=1.2, ms=4)
    ax2.axhline(0, color="0.5", lw=0.6)
    if np.isfinite(limit) and limit > 0:
        for s in (-1, 1):
            ax2.axhline(100 * s * limit, color=LIMIT_COLOUR, lw=1.5, ls="--")
    ax2.set_xlabel("ball position in the train [-] (1 = trailing)")
    ax2.set_ylabel("ε [%], mean ± 1 std per position")
    ax2.set_title("(b) ε along the train")
    ax2.set_xticks(balls + 1 if len(balls) <= 20 else np.linspace(1, len(balls), 6).round())
    rho = np.asarray(ds["side_force_ratio"], dtype=float)
    if np.ptp(rho) > 0:
        ax3 = ax2.twinx()
        ax3.plot(balls + 1, rho, color="0.5", ls=":", lw=1.2)
        ax3.set_ylabel("side force ratio ρ [-] (dotted)", color="0.4")
        ax3.tick_params(axis="y", colors="0.4")
        ax3.spines["right"].set_visible(True)
        ax3.grid(False)
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
        ax_p.legend(loc="lower center", fontsize=8)
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


@styled
def plot_spot_checks(ds):
    """Identity plot epsilon analytic vs full, and the difference, with validity counts."""
    fig, (ax, ax2) = new_figure(10.5, 4.5, ncols=2)
    ea = 100 * np.asarray(ds["spot_check_velocity_deviation_analytic"], dtype=float)
    ef = 100 * np.asarray(ds["spot_check_velocity_deviation_full"], dtype=float)
    k = ea.size
    va = np.asarray(ds["spot_check_valid_analytic"], dtype=bool) if k else np.zeros(0, bool)
    vf = np.asarray(ds["spot_check_valid_full"], dtype=bool) if k else np.zeros(0, bool)
    both = va & vf
    model = ds.attrs.get("velocity_model", "analytic")
    if k:
        ax.plot(ef[both], ea[both], "o", ms=4, color=MODEL_COLOURS["analytic"],
                label=f"valid in both ({both.sum()})")
        other = ~both & np.isfinite(ea) & np.isfinite(ef)
        if other.any():
            ax.plot(ef[other], ea[other], "x", ms=6, color=LIMIT_COLOUR,
                    label=f"invalid in one model ({other.sum()})")
        finite = np.concatenate([ea[np.isfinite(ea)], ef[np.isfinite(ef)]])
        if finite.size:
            lo, hi = finite.min(), finite.max()
            pad = 0.08 * max(hi - lo, 1e-3)
            line = np.array([lo - pad, hi + pad])
            ax.plot(line, line, color="k", lw=0.8, label="identity")
            ax.set_xlim(*line)
            ax.set_ylim(*line)
        ax2.plot(ef[both], ea[both] - ef[both], "o", ms=4, color=MODEL_COLOURS["analytic"])
        ax2.axhline(0, color="k", lw=0.8)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("ε, full friction model [%]")
    ax.set_ylabel(f"ε, study model '{model}' [%]")
    ax.set_title(f"(a) spot checks: {k} balls re-solved")
    ax.legend(loc="upper left", fontsize=8)
    counts = (f"spot checks: {k}\nvalid in both: {int(both.sum())}\n"
              f"'{model}' invalid: {int((~va).sum())}\n"
              f"full invalid or not converged: {int((~vf).sum())}\n"
              f"RMS difference: {100 * _f(ds, 'spot_check_rms_difference'):.4f} pp\n"
              f"max |difference|: {100 * _f(ds, 'spot_check_max_abs_difference'):.4f} pp")
    ax2.text(0.98, 0.03, counts, transform=ax2.transAxes, ha="right", va="bottom", fontsize=8,
             bbox=dict(boxstyle="round", fc="white", ec="0.7", alpha=0.9))
    ax2.set_xlabel("ε, full friction model [%]")
    ax2.set_ylabel(f"ε '{model}' − ε full [percentage points]")
    ax2.set_title("(b) difference")
    if not k:
        ax2.text(0.5, 0.5, ds.attrs.get("spot_check_status", "no spot checks"),
                 transform=ax2.transAxes, ha="center", va="center")
    return fig


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
"""


def _row(label, value, num=True):
    cls = ' class="num"' if num else ""
    return f"<tr><th>{html.escape(label)}</th><td{cls}>{html.escape(str(value))}</td></tr>"


def _pct(x, digits=3):
    if not np.isfinite(x):
        return "n/a"
    v = round(100 * x, digits) or 0.0  # no "-0.000"
    return f"{v:+.{digits}f} %"


def _tolerance_rows(ds):
    """HTML rows describing the tolerances of the embedded config (empty if unreadable)."""
    try:
        config = config_of(ds)
    except Exception:  # noqa: BLE001 - the report must not fail on an old config
        return []
    from tolsim.study.spec import SOURCES

    scale = {"angle": (180 / np.pi, "deg"), "length": (1e6, "µm")}
    rows = []
    for t in config.tolerances:
        factor, unit = scale.get(SOURCES.get(t.source, ("length",))[0], (1.0, ""))
        dist = t.distribution
        fields = {"fixed": ("value",), "normal": ("mean", "std"), "uniform": ("low", "high"),
                  "truncated_normal": ("mean", "std", "low", "high"),
                  "cpk": ("low", "high", "mean", "cpk")}.get(dist.kind, ())
        params = ", ".join(
            f"{f} {getattr(dist, f):.3g}" if f == "cpk" else
            f"{f} {factor * getattr(dist, f):.3g} {unit}" for f in fields)
        if t.correlation_length > 0:
            params += f"; correlation length {1e3 * t.correlation_length:.3g} mm"
        rows.append(f"<tr><td>{html.escape(t.source)}</td><td>{html.escape(t.scope)}</td>"
                    f"<td>{html.escape(dist.kind)}</td><td>{html.escape(params)}</td></tr>")
    return rows


def _html(ds, figures, sens, sens_source, q, path):
    a = ds.attrs
    n_asm = _i(ds, "n_assemblies")
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>{html.escape(a.get('title', 'tolsim report'))}</title>",
        f"<style>{CSS}</style></head><body>",
        f"<h1>{html.escape(a.get('title', 'tolsim study'))}</h1>",
        f"<p class='muted'>Report of <code>{html.escape(os.path.basename(path))}</code>, "
        f"made by tolsim {__version__} on "
        f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}.</p>",
        "<h2>1. What was studied</h2><table>",
        _row("assemblies (trains) sampled", f"{n_asm:,}"),
        _row("balls per train", ds.sizes.get("ball", "?")),
        _row("balls evaluated", f"{_i(ds, 'n_balls'):,}"),
        _row("stroke duration (horizon)", f"{_f(ds, 'horizon'):.4g} s"),
        _row("carriage speed v", f"{1e3 * _f(ds, 'groove_velocity'):.4g} mm/s"),
        _row("carriage travel", f"{1e3 * _f(ds, 'horizon') * _f(ds, 'groove_velocity'):.4g} mm"),
        _row("velocity model", a.get("velocity_model", "?"), False),
        _row("static contact model", a.get("static_model", "?"), False),
        _row("propagation", a.get("propagation", "?"), False),
        _row("sampling", a.get("sampling", "?"), False),
        _row("seed", a.get("seed", "?")),
        _row("source", a.get("source", "?"), False),
        _row("history", a.get("history", "?"), False),
        "</table>",
        *(["<h3>Tolerances</h3><table><tr><th>source</th><th>scope</th>"
            "<th>distribution</th><th>parameters</th></tr>", *_tolerance_rows(ds), "</table>"]
          if _tolerance_rows(ds) else []),
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
    plimit = _f(ds, "contact_probability_limit")
    verdict = quality.contact_probability_verdict(p, hi, plimit)
    cls = "good" if verdict.startswith("meets") else "bad" if verdict.startswith(
        "fails") else ""
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
        _row(f"balls outside the {a.get('velocity_model', '?')} model's validity, "
             "re-solved with the full model",
             f"{_i(ds, 'n_balls_resolved_full'):,} of {_i(ds, 'n_balls_outside_validity'):,} "
             f"in {float(a.get('full_model_resolve_seconds', 0.0)):.2f} s"),
        _row("unresolved balls (static not converged / loss of contact / full model failed)",
             f"{_i(ds, 'n_balls_not_converged')} / {_i(ds, 'n_balls_loss_of_contact')} / "
             f"{_i(ds, 'n_balls_full_failed')}; {n_unres} trains unresolved (none left out: "
             "see the bounds)"),
        "</table>",
        *([f"<p class='verdict'>{html.escape(a['propagation_caveat'])}</p>"]
          if a.get("propagation_caveat") else []),
        f"<p class='verdict {cls}'>Contact-probability spec: {html.escape(verdict)}.</p>",
    ]

    def fig(name, caption):
        if name in figures:
            parts.append(f"<figure><img alt='{html.escape(caption)}' "
                         f"src='{data_uri(figures[name])}'><figcaption class='muted'>"
                         f"{html.escape(caption)}</figcaption></figure>")

    parts.append("<h2>3. Ball velocity deviation ε</h2>")
    fig("velocity_deviation", "ε distribution over all valid balls, and along the train.")
    parts.append("<h2>4. Ball-to-ball contact</h2>")
    fig("contact", "Survival curve of the time to first contact (travel on the top axis), "
                   "contact probability with its 95 % interval, and the pair that touches "
                   "first.")
    parts.append("<h2>5. Quality engineering</h2>")
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
        fig("quality", "Tails of ε on a log scale against the spec limit.")
    else:
        parts.append("<p>No limit on |ε| in the config (<code>study.velocity_deviation_limit"
                     "</code>): no fraction out of spec or capability index.</p>")
    parts.append("<h2>6. What drives the risk</h2>")
    if sens is None:
        parts.append(f"<p>{html.escape(sens_source)}</p>")
    elif len(sens.factors) == 0:
        parts.append("<p>The study has no random tolerance: every assembly is the same, "
                     "nothing to rank.</p>")
    else:
        parts.append(f"<p class='muted'>{html.escape(sens_source)}</p>")
        fig("sensitivity", "Sobol' indices: first order (the factor alone) and total effect "
                           "(with interactions).")
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
    parts.append("<h2>7. Model check: analytic versus full friction model</h2>")
    fig("spot_checks", "Randomly chosen balls re-solved with the full friction model.")
    parts.append(f"<p class='muted'>{html.escape(str(a.get('spot_check_status', '')))}</p>")
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
                progress=None) -> ReportOutputs:
    """Write ``report.html`` and the PNGs of a result file into ``folder``.

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
        fh.write(_html(ds, pngs, sens, source, q, os.fspath(path)))
    return out
