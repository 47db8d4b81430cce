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

A study with ``[contact]`` (the friction variables of :mod:`tolsim.study.pipeline.track_friction`
in the
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
"""

import html
import os
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from tolsim import __version__
from tolsim.reports.assumptions import (
    _config_or_none,
    assumption_table,
    carriage_load_items,
    config_of,
    tolerance_table,
)
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
from tolsim.reports.verdict import (
    ESTIMATOR_NAMES,
    FAIL,
    PASS,
    STATUS_LABELS,
    UNDECIDED,
    any_train,
    contact_unit,
    counted,
    estimator_label,
    has_friction,
    study_verdict,
    tracks_of,
)
from tolsim.study.statistics import quality
from tolsim.study.statistics.intervals import wilson_interval
from tolsim.study.statistics.quality import format_fraction

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
    friction: dict | None = None  # friction_content of a study with [contact]


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


def track_labels(ds) -> list:
    """'track 0 (x = -20 mm, φ = +90°)' for every track of a carriage study ([] without)."""
    tracks = tracks_of(ds)
    if not tracks:
        return []
    x = (1e3 * np.asarray(ds["track_x"], dtype=float) if "track_x" in ds.variables
         else np.full(tracks, np.nan))
    phi = (np.rad2deg(np.asarray(ds["track_orientation"], dtype=float))
           if "track_orientation" in ds.variables else np.full(tracks, np.nan))
    return [f"track {t} (x = {x[t]:+.4g} mm, φ = {phi[t]:+.4g}°)" for t in range(tracks)]


#: Colours of the tracks of a carriage: the series colours without the spec-limit colour.
TRACK_COLOURS = tuple(c for c in SERIES_COLOURS if c != LIMIT_COLOUR)


def _track_style(t):
    """Colour, marker and marker size of track ``t``: tracks often coincide (a symmetric
    guide), so the markers shrink track by track and each one stays visible."""
    return dict(color=TRACK_COLOURS[t % len(TRACK_COLOURS)], marker="osD^v"[t % 5],
                ms=max(5.5 - 1.5 * t, 2.5))


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

    Reads the variables of :data:`tolsim.io.schema.sensitivity.SENSITIVITY_VARIABLES`:
    epsilon's
    ``sensitivity_first_order`` / ``sensitivity_total`` and, when present, the contact
    indicator's ``sensitivity_contact_*``, the friction increase's ``sensitivity_friction_*``
    (a study with ``[contact]``) and the ``*_ci_lower`` / ``*_ci_upper`` ends.
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
    for prefix, output in (("", "velocity_deviation"), ("_contact", "contact"),
                           ("_friction", "friction_increase")):
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
    from tolsim.study.analyses.sensitivity import study_sensitivity

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
    limit"). A carriage study draws one series per track (in (b) side by side, slightly
    apart), named in a legend below the figure."""
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
    rho = np.asarray(ds["side_force_ratio"], dtype=float)
    labels = track_labels(ds)
    if labels:  # a carriage: (track, ball), one series per track
        tracks = len(labels)
        for t in range(tracks):
            st = _track_style(t)
            shift = 0.5 * (t - 0.5 * (tracks - 1)) / tracks  # bars side by side
            ax2.errorbar(balls + 1 + shift, m[t], yerr=np.nan_to_num(sd[t]), fmt="-",
                         color=st["color"], marker=st["marker"], ms=0.8 * st["ms"],
                         capsize=2, lw=1.0)
    else:
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
    if labels:
        for t, label in enumerate(labels):
            ax3.plot(balls + 1, rho[t], "-", lw=1.0, label=label, **_track_style(t))
        fig.legend(*ax3.get_legend_handles_labels(), loc="outside lower center",
                   ncols=min(len(labels), 4), fontsize=8, frameon=False,
                   title="(b), (c): one series per track", title_fontsize=8)
    else:
        ax3.plot(balls + 1, rho, "s-", color=SERIES_COLOURS[3], lw=1.2, ms=4)
    ax3.axhline(0, color="0.5", lw=0.6)
    reach = float(np.nanmax(np.abs(rho), initial=0.0))
    ax3.set_ylim(-1.25 * reach if reach > 0 else -0.1, 1.25 * reach if reach > 0 else 0.1)
    ax3.set_xticks(ticks)
    ax3.set_xlabel("ball position in the train [-] (1 = trailing)")
    ax3.set_ylabel("ρ = N_x / N_y [-]")
    ax3.set_title("(c) side force ratio ρ per position (the load, not ε)" if not labels else
                  "(c) ρ per position, nominal carriage (the load, not ε)",
                  fontsize=10)
    return fig


@styled
def plot_contact(ds):
    """Survival curve with a pointwise band; P(contact) and its CI; first-contact pairs.

    In a carriage study the survival curve and P(contact) are per assembly (contact in any
    of its trains), and the first-contact pairs are drawn per track, side by side."""
    fig, (ax, ax_p, ax_pair) = new_figure(12.0, 4.2, ncols=3, width_ratios=[1.7, 0.7, 1.0])
    one, many = contact_unit(ds)
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
            label=f"P(no contact by t), {n:,} resolved {many}")
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
    ax_p.set_ylabel(f"P(contact within the horizon) per {one} [-]")
    label = estimator_label(ds)
    ax_p.set_title("(b) contact probability\n(95 % " + (
        label if label == "Clopper-Pearson" else
        ESTIMATOR_NAMES.get(ds["contact_probability"].attrs.get("estimator"), "estimator"))
        + ")", fontsize=10)

    if "contact_pair_count" in ds.variables and ds.sizes.get("pair", 0) > 0:
        pairs = np.asarray(ds["pair"])
        cnt = np.asarray(ds["contact_pair_count"], dtype=float)
        if cnt.ndim == 2:  # a carriage: (track, pair), the tracks side by side
            labels = track_labels(ds)
            tracks = cnt.shape[0]
            width = 0.8 / tracks
            for t in range(tracks):
                ax_pair.bar(pairs + 1 + (t - 0.5 * (tracks - 1)) * width, cnt[t], width=width,
                            color=_track_style(t)["color"], alpha=0.85,
                            label=f"{labels[t]}: {int(cnt[t].sum()):,}")
            top = float(np.max(cnt, initial=0.0))
            ax_pair.set_ylim(0, 1.2 * (1.0 + 0.12 * tracks) * top if top > 0 else 1.0)
            ax_pair.legend(loc="upper left", fontsize=7, framealpha=0.9)
        else:
            ax_pair.bar(pairs + 1, cnt, color=SERIES_COLOURS[2], alpha=0.85)
        ax_pair.set_xticks(pairs + 1 if len(pairs) <= 20 else
                           np.linspace(1, len(pairs), 6).round())
    ax_pair.set_xlabel("pair of balls j, j+1 [-] (1 = trailing pair)")
    ax_pair.set_ylabel(f"{many} whose first contact is here [-]")
    ax_pair.set_title("(c) where the first contact happens")
    return fig


@styled
def plot_carriage_loads(ds, ball_z=None, preload_ball_load=None):
    """The nominal load distribution of a carriage study, one series per track: (a) the
    normal load N_y of every ball, with the load of the preload alone, and (b) the side force
    ratio rho = N_x / N_y, against the ball position along the rail (N_x itself is in the
    tracks table of the report: it is rho N_y).

    Parameters
    ----------
    ds : xarray.Dataset
        A carriage study's result file: ``normal_load``, ``side_load`` and
        ``side_force_ratio`` of the nominal assembly (no errors), dims (track, ball).
    ball_z : array_like, optional
        Nominal axial ball positions z_j [m] (:attr:`tolsim.physics.carriage.CarriageLayout.
        ball_z`); without them the balls are drawn at their index.
    preload_ball_load : float, optional
        N_0 = 2 F_0 cos(beta_0) [N], the normal load of the preload alone (a dotted line).
    """
    fig, (ax, ax2) = new_figure(11.0, 4.6, ncols=2)
    ny = np.atleast_2d(np.asarray(ds["normal_load"], dtype=float))
    rho = np.atleast_2d(np.asarray(ds["side_force_ratio"], dtype=float))
    balls = np.asarray(ds["ball"])
    if ball_z is not None and len(ball_z) == len(balls):
        x = 1e3 * np.asarray(ball_z, dtype=float)
        xlabel = "ball position z along the rail [mm] (ball 0 trailing)"
    else:
        x = balls + 1
        xlabel = "ball position in the train [-] (1 = trailing)"
    from matplotlib.lines import Line2D

    handles = []
    for t, label in enumerate(track_labels(ds) or [f"track {k}" for k in range(len(ny))]):
        st = _track_style(t)
        ax.plot(x, ny[t], "-", lw=1.2, **st)
        ax2.plot(x, rho[t], "-", lw=1.2, **st)
        handles.append(Line2D([], [], ls="-", label=label, **st))
    if preload_ball_load is not None and np.isfinite(preload_ball_load):
        ax.axhline(preload_ball_load, color="0.45", lw=1.0, ls=":")
        handles.append(Line2D([], [], color="0.45", ls=":",
                              label=f"N_0 = {preload_ball_load:.4g} N: the preload alone"))
    ax2.axhline(0, color="0.5", lw=0.6)
    for a in (ax, ax2):
        a.set_xlabel(xlabel)
    ax.set_ylabel("normal load N_y [N]")
    ax.set_title("(a) ball normal load N_y", fontsize=10)
    reach = float(np.nanmax(np.abs(rho), initial=0.0))
    ax2.set_ylim(-1.2 * reach if reach > 0 else -0.1, 1.2 * reach if reach > 0 else 0.1)
    ax2.set_ylabel("ρ = N_x / N_y [-]")
    ax2.set_title("(b) side force ratio ρ", fontsize=10)
    fig.legend(handles=handles, loc="outside lower center", ncols=min(len(handles), 4),
               fontsize=8, frameon=False)
    loads = carriage_load_items(ds)
    text = ", ".join(f"{term.split(' (')[0].split(',')[0]} {value:.4g} {unit}"
                     for term, value, unit, _ in loads if value)
    fig.suptitle("Nominal load distribution of the carriage (no errors): "
                 + (text or "no external load")
                 + f", preload {1e6 * _f(ds, 'preload_oversize'):.3g} µm", fontsize=10.5)
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

    from tolsim.physics.velocity.analytic import VALIDITY_ERROR_BUDGET

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


def output_titles(unit="train") -> dict:
    """:data:`OUTPUT_TITLES` with the contact indicator counted per ``unit`` (a train, or an
    assembly in a carriage study)."""
    return {**OUTPUT_TITLES,
            "contact": f"influence on ball-to-ball contact (indicator per {unit})"}
OUTPUT_SHORT = {"velocity_deviation": "the scatter of ε", "contact": "ball-to-ball contact"}


@styled
def plot_sensitivity(sens, unit="train"):
    """Ranked bars of the total-effect and first-order indices, one panel per output; the
    contact indicator is per ``unit`` (``"assembly"`` in a carriage study)."""
    titles = output_titles(unit)
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
        ax.set_title(titles.get(output, output), fontsize=10)
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
# Carriage (a study with [carriage]: HTML and PDF share these tables)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReportTable:
    """A table of the report (HTML and PDF).

    Attributes
    ----------
    heading : str
    header : tuple of str
    rows : tuple of tuple of str
    widths : tuple of float
        Column widths as fractions of the text width (PDF).
    note : str
        A sentence below the table.
    numeric : tuple of int
        Columns right-aligned in HTML.
    """

    heading: str
    header: tuple
    rows: tuple
    widths: tuple
    note: str = ""
    numeric: tuple = ()


#: Labels of the carriage degrees of freedom (``carriage_translation_name``,
#: ``carriage_rotation_name``): name -> (displacement, stiffness).
CARRIAGE_DOF_LABELS = {
    "u_x": ("lateral displacement u_x [µm]", "lateral stiffness [N/µm]"),
    "u_y": ("vertical displacement u_y [µm] (+ up)", "vertical stiffness [N/µm]"),
    "pitch": ("pitch rotation (about x) [µrad]", "pitching stiffness [N m/µrad]"),
    "yaw": ("yaw rotation (about y) [µrad]", "yawing stiffness [N m/µrad]"),
    "roll": ("roll rotation (about z) [µrad]", "rolling stiffness [N m/µrad]"),
}
CARRIAGE_STATISTICS = ("nominal", "mean", "std", "min", "max")


def _fixed(x, digits=4):
    """A value with fixed decimals, 'n/a' for NaN, never '-0.0000'."""
    if not np.isfinite(x):
        return "n/a"
    return f"{round(float(x), digits) + 0.0:.{digits}f}"


def _sig(x, digits=4):
    return f"{float(x):.{digits}g}" if np.isfinite(x) else "n/a"


def _span(values, fmt="{:.4g}"):
    """'lo to hi' of an array (one value when they agree), 'n/a' when empty or NaN."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "n/a"
    lo, hi = fmt.format(v.min() + 0.0), fmt.format(v.max() + 0.0)
    return lo if lo == hi else f"{lo} to {hi}"


def _carriage_names(ds, what):
    label = f"carriage_{what}_name"
    return [str(n) for n in np.asarray(ds[label])] if label in ds.variables else []


def carriage_dof_rows(ds) -> list:
    """(label, [nominal, mean, std, min, max]) of every carriage displacement and stiffness
    in display units (µm, µrad, N/µm, N m/µrad), displacements first."""
    rows = []
    for kind in ("displacement", "stiffness"):
        for what, stiffness in (("translation", "translational_stiffness"),
                                ("rotation", "rotational_stiffness")):
            name = what if kind == "displacement" else stiffness
            scale = 1e6 if kind == "displacement" else 1e-6  # m, rad -> µm, µrad; per µ
            for j, dof in enumerate(_carriage_names(ds, what)):
                values = [float(np.asarray(ds[f"carriage_{name}_{stat}"])[j]) * scale
                          if f"carriage_{name}_{stat}" in ds.variables else np.nan
                          for stat in CARRIAGE_STATISTICS]
                label = CARRIAGE_DOF_LABELS.get(dof, (dof, dof))[kind == "stiffness"]
                rows.append((kind, dof, label, values))
    return rows


def _carriage_geometry(config):
    """(ball_z [m], N_0 [N] or None, Hertz constant K [N/m^1.5] or None) of a parsed
    carriage config; (None, None, None) without one."""
    if config is None or getattr(config, "carriage", None) is None:
        return None, None, None
    from tolsim.physics.hertz import hertz_constants

    b = config.bearing
    k = float(hertz_constants(b.ball_radius, b.conformity, b.youngs_modulus,
                              b.poisson_ratio).load_deflection_constant)
    o = float(config.carriage.preload_oversize)
    f0 = k * max(0.5 * o, 0.0) ** 1.5
    return config.carriage.layout.ball_z, 2.0 * f0 * np.cos(b.nominal_contact_angle), k


def carriage_summary(ds) -> str:
    """One sentence on the carriage of a carriage study (the headline): its load case,
    preload and nominal vertical stiffness."""
    loads = ", ".join(f"{term.split(' (')[0].split(',')[0]} {value:.4g} {unit}"
                      for term, value, unit, _ in carriage_load_items(ds) if value)
    rows = {dof: values for kind, dof, _, values in carriage_dof_rows(ds)
            if kind == "stiffness"}
    stiff = rows.get("u_y", [np.nan])[0]
    failed = _i(ds, "n_assemblies_carriage_failed")
    text = (f"Carriage on {counted(tracks_of(ds), 'track')} under "
            f"{loads or 'no external load'}, preload "
            f"{1e6 * _f(ds, 'preload_oversize'):.3g} µm ({_f(ds, 'preload_contact_force'):.3g} "
            f"N per contact); nominal vertical stiffness {_sig(stiff)} N/µm")
    if failed:
        text += f"; {failed:,} of {_i(ds, 'n_assemblies'):,} carriages not solved"
    return text + "."


def carriage_content(ds, config=None) -> dict:
    """The "Carriage" section of a carriage study's report (HTML and PDF).

    Parameters
    ----------
    ds : xarray.Dataset
        A result file with a ``track`` dimension (the variables of
        :data:`tolsim.io.schema.carriage.CARRIAGE_VARIABLES`).
    config : StudyConfig, optional
        The embedded config (ball positions, N_0, K, per-ball oversizes); without it the
        section shows what the file holds.

    Returns
    -------
    dict
        ``heading`` (str), ``paragraphs`` (list of str), ``tables`` (list of
        :class:`ReportTable`: load case, preload, tracks, displacement and stiffness, solved
        carriages), ``figure_after`` (index of the table the figure follows), ``ball_z``
        (nominal ball positions [m] or None) and ``preload_ball_load`` (N_0 [N] or None).
    """
    from tolsim.reports.assumptions import _key, _toml, distribution_text

    data = _toml(ds)
    tracks, balls = tracks_of(ds), ds.sizes.get("ball", 0)
    n_asm = _i(ds, "n_assemblies")
    failed = _i(ds, "n_assemblies_carriage_failed")
    ball_z, n0, k = _carriage_geometry(config)
    paragraphs = [
        f"Each assembly is a rigid carriage on {counted(tracks, 'track')} of "
        f"{counted(balls, 'ball')}, one "
        "train per track. The carriage is solved for every sampled assembly with that "
        "assembly's groove errors and ball sizes (tolsim.physics.carriage), and its balls "
        "then go through the velocity model. P(contact) and the time to first contact are "
        f"per assembly: contact in {any_train(tracks)}. The load "
        "distribution is that "
        "of the nominal assembly (no errors); the displacement and stiffness are given for "
        "the nominal assembly and over the sampled ones."]
    tables = []
    # load case
    rows = tuple((term, f"{value:.4g} {unit}", key)
                 for term, value, unit, key in carriage_load_items(ds, data))
    tables.append(ReportTable(
        "Load case at the reference point", ("load (catalogue term)", "value", "config"), rows,
        (0.5, 0.15, 0.35),
        "Reference point: x = y = 0 of the track coordinates, in the middle of the rows "
        "(z = 0); x lateral, y up, z along the rail, moments right-handed about +x, +y, +z "
        "(tolsim.physics.carriage). Every sampled carriage carries the same load.", (1,)))
    # preload
    o, f0 = _f(ds, "preload_oversize"), _f(ds, "preload_contact_force")
    rows = [("preload class: diametral ball oversize o", f"{1e6 * o:.4g} µm",
             _key(data, "carriage", "preload_oversize") or "default: 0 (no preload)"),
            ("preload force on each contact, F₀ = K (o/2)^1.5", f"{f0:.4g} N",
             "result file (preload_contact_force)")]
    if n0 is not None:
        beta0 = np.rad2deg(config.bearing.nominal_contact_angle)
        rows.append(("normal ball load of the preload alone, N₀ = 2 F₀ cos β₀",
                     f"{n0:.4g} N", f"derived (β₀ = {beta0:.4g}°)"))
        rows.append(("Hertz constant K of a ball in its flank", f"{k:.4g} N/m^1.5",
                     "tolsim.physics.hertz.hertz_constants (from D, f, E, ν)"))
    if config is not None:
        dev = config.carriage.ball_oversize_deviation
        rows.append(("per-ball oversize deviations from o (nominal assembly)",
                     _span(1e6 * np.asarray(dev), "{:+.3g}") + " µm" if dev else "none",
                     "[carriage] or [[carriage.track]] ball_oversize_deviation_um" if dev
                     else "not given"))
        for t in config.tolerances:
            if t.source == "ball_oversize" and t.distribution.is_random:
                rows.append(("sampled ball size variation (adds to o)",
                             f"{t.distribution.kind}: "
                             + distribution_text(t.distribution, "length"),
                             "[tolerances.ball_oversize]"))
    tables.append(ReportTable(
        "Preload", ("quantity", "value", "source"), tuple(rows), (0.45, 0.2, 0.35),
        "o = 0: no preload (zero clearance), the load closes one diagonal of each ball; with "
        "o > 0 every ball carries F₀ on all four contacts before any load, which stiffens "
        "the carriage and keeps the contacts closed.", (1,)))
    # tracks and the nominal load distribution
    x, y, phi = (np.asarray(ds[n], dtype=float) if n in ds.variables else np.full(tracks, np.nan)
                 for n in ("track_x", "track_y", "track_orientation"))
    ny, nx, rho = (np.atleast_2d(np.asarray(ds[n], dtype=float)) for n in (
        "normal_load", "side_load", "side_force_ratio"))
    first = (np.atleast_2d(np.asarray(ds["contact_pair_count"])).sum(axis=1)
             if "contact_pair_count" in ds.variables else np.zeros(tracks, int))
    rows = tuple((str(t), _sig(1e3 * x[t]), _sig(1e3 * y[t] + 0.0),
                  _sig(np.rad2deg(phi[t])), _span(ny[t]), _span(nx[t], "{:+.4g}"),
                  _span(rho[t], "{:+.3f}"), f"{int(first[t]):,}") for t in range(tracks))
    tables.append(ReportTable(
        "Tracks and the nominal load distribution",
        ("track", "x [mm]", "y [mm]", "orientation φ [°]", "normal load N_y [N]",
         "side load N_x [N]", "ρ = N_x / N_y [-]", "first contacts [assemblies]"), rows,
        (0.07, 0.09, 0.09, 0.12, 0.17, 0.17, 0.14, 0.15),
        "The nominal assembly (no groove errors, the config's ball oversizes), ranges over "
        "the track's balls. N_y presses the ball into its rail groove and N_x is lateral, "
        "both in the module frame of the track (its up is (−sin φ, cos φ) in the carriage "
        f"frame). First contacts: assemblies whose first contact is in this track (of "
        f"{_i(ds, 'n_contact'):,} with contact).", tuple(range(8))))
    # displacement and stiffness
    dofs = carriage_dof_rows(ds)
    rows = tuple((label, *[(_fixed(v) if kind == "displacement" else _sig(v)) for v in values])
                 for kind, _, label, values in dofs)
    locked = [dof for kind, dof, _, values in dofs
              if kind == "stiffness" and np.all(np.asarray(values) == 0.0)]
    solved = n_asm - (failed or 0)
    tables.append(ReportTable(
        "Carriage displacement and stiffness", ("degree of freedom", *CARRIAGE_STATISTICS),
        rows, (0.35, 0.13, 0.13, 0.13, 0.13, 0.13),
        f"Nominal: the assembly without errors; mean, std, min and max over the {solved:,} "
        f"solved carriages of {n_asm:,}. Displacements are measured from the geometry with "
        "balls of nominal size (o = 0), so they include the shift of the unloaded carriage by "
        "the preload where the tracks do not balance it (a single track, say); the change "
        "under the load is what the stiffness gives. Stiffness: the diagonal of the tangent "
        "stiffness matrix dQ/dq at the equilibrium, each degree of freedom alone (the "
        "couplings are not in the result file)."
        + (f" {', '.join(locked)}: stiffness 0, a degree of freedom the track layout cannot "
           "resist, held at zero (locked, tolsim.physics.carriage)." if locked else ""),
        (1, 2, 3, 4, 5)))
    tables.append(ReportTable(
        "Solved carriages", ("carriages", "count"), (
            ("sampled (assemblies)", f"{n_asm:,}"),
            ("solved: the statistics above are over these", f"{solved:,}"),
            ("not solved (Newton not converged, or lifted off): their balls count as not "
             "converged and their trains as unresolved (see the bounds in section 2)",
             f"{failed:,}" if failed is not None else "n/a")),
        (0.8, 0.2), "", (1,)))
    return dict(heading=section_titles(ds)["carriage"], paragraphs=paragraphs, tables=tables,
                figure_after=2, ball_z=ball_z, preload_ball_load=n0)


# --------------------------------------------------------------------------------------------
# Friction after contact (a study with [contact]: HTML and PDF share this section)
# --------------------------------------------------------------------------------------------
#: Output name of the friction increase among the Sobol' outputs
#: (:data:`tolsim.study.analyses.sensitivity.FRICTION_INCREASE`).
FRICTION_OUTPUT = "friction_increase"
#: Quantile levels of the friction table.
FRICTION_LEVELS = (0.5, 0.9, 0.95, 0.99, 0.999)
#: The force histograms of the friction section: variable prefix -> (label, line style).
FRICTION_HISTOGRAMS = {
    "friction_increase": ("increase of the friction force over its baseline", "-"),
    "friction_ripple": ("ripple of the friction force (max − min over the stroke)", ":"),
    "contact_force_max": ("largest ball-to-ball force Q_max", "--"),
}


def _without_output(sens, output=FRICTION_OUTPUT):
    """``sens`` without one of its outputs (the same object when it does not have it): the
    section "What drives the risk" ranks epsilon and contact, the friction section its own
    output."""
    outputs = list(getattr(sens, "outputs", ()))
    if sens is None or output not in outputs:
        return sens
    keep = [k for k, name in enumerate(outputs) if name != output]
    return _FileSensitivity(tuple(sens.factors), tuple(outputs[k] for k in keep),
                            np.asarray(sens.first_order)[keep], np.asarray(sens.total)[keep],
                            np.asarray(sens.first_order_ci)[keep],
                            np.asarray(sens.total_ci)[keep], n=int(sens.n),
                            evaluations=int(sens.evaluations),
                            confidence_level=float(sens.confidence_level))


def friction_indices(sens):
    """(first_order, total, first_order_ci, total_ci) of the friction increase, or None."""
    outputs = list(getattr(sens, "outputs", ()))
    if sens is None or FRICTION_OUTPUT not in outputs or not len(sens.factors):
        return None
    k = outputs.index(FRICTION_OUTPUT)
    return (np.asarray(sens.first_order[k], dtype=float), np.asarray(sens.total[k], dtype=float),
            np.asarray(sens.first_order_ci[k], dtype=float),
            np.asarray(sens.total_ci[k], dtype=float))


def _force_text(x, unit=" N"):
    """A force [N] to three significant digits, '0' for an exact zero, 'n/a' for NaN."""
    if not np.isfinite(x):
        return "n/a"
    return ("0" if x == 0 else f"{float(x):.3g}") + unit


def _quantile_of(ds, name, level):
    """The stored quantile of ``name`` at ``level`` (NaN when absent)."""
    if name not in ds.variables:
        return np.nan
    levels = np.asarray(ds["quantile"], dtype=float)
    k = int(np.argmin(np.abs(levels - level)))
    if abs(levels[k] - level) > 1e-9:
        return np.nan
    return float(np.asarray(ds[name], dtype=float)[k])


def _force_survival(ds, prefix):
    """(x [N], P(X >= x), total) of a friction histogram: the fraction of the resolved
    assemblies at or above each bin edge (the overflow counted above every edge)."""
    counts = np.asarray(ds[f"{prefix}_histogram"], dtype=float)
    edges = _edges(ds, "force_bin_bounds")
    under, over = _i(ds, f"{prefix}_underflow"), _i(ds, f"{prefix}_overflow")
    total = counts.sum() + under + over
    above = np.concatenate([np.cumsum(counts[::-1])[::-1], [0.0]]) + over
    return edges, above / max(total, 1.0), total


def _ball_diameter(ds, config):
    """D [m] from the config, else the smallest centre distance of the examples' balls
    (touching balls are exactly D apart), else NaN."""
    if config is not None:
        return 2.0 * float(config.bearing.ball_radius)
    if "example_ball_position" in ds.variables and ds.sizes.get("ball", 0) > 1:
        z = np.asarray(ds["example_ball_position"], dtype=float)
        return float(np.nanmin(np.diff(z, axis=-1)))
    return np.nan


def _busiest_example(ds) -> int:
    """The example whose track has a ball-to-ball contact over the longest part of the
    stroke (the first on a tie; 0 without contact forces in the file)."""
    if "example_contact_force" not in ds.variables or ds.sizes.get("pair", 0) == 0:
        return 0
    q = np.asarray(ds["example_contact_force"], dtype=float)  # (example, travel, pair)
    return int(np.argmax(np.mean(np.any(q > 0, axis=2), axis=1)))


def _example_label(ds, e):
    one = contact_unit(ds)[0]
    label = f"{one} {int(np.asarray(ds['example_assembly'])[e]):,}"
    if tracks_of(ds):
        label += f", track {int(np.asarray(ds['example_track'])[e])}"
    return label


@styled
def plot_friction(ds, sens=None, ball_diameter=np.nan):
    """What contact costs, four panels: (a) the distribution of the friction increase over
    the assemblies (the fraction at or above each force, log-log) with the spec limit and
    the exceedance probability with its interval, beside the ripple and the largest
    ball-to-ball force; (b) the example traces of the increase against the carriage travel;
    (c) the balls of the first example along the stroke, drawn as in the paper's Fig. 9 so
    that touching balls share a line; (d) the drivers, Sobol' indices of the increase.

    Parameters
    ----------
    ds : xarray.Dataset
        A result file with the friction variables (:data:`tolsim.io.schema.friction.
        FRICTION_VARIABLES`).
    sens : optional
        Sensitivity indices with the output ``friction_increase`` (panel d).
    ball_diameter : float
        D [m], for panel (c) (NaN: panel c draws the centres less their start).
    """
    fig = new_canvas(12.0, 8.6)
    (ax_d, ax_t), (ax_z, ax_s) = fig.subplots(2, 2)
    limit = _f(ds, "friction_increase_limit")
    has_limit = np.isfinite(limit) and limit > 0
    one, many = contact_unit(ds)

    # (a) distribution: the fraction of assemblies at or above a force
    top, low = 0.0, np.inf
    floor = 1.0
    curves = {}
    for prefix, (label, ls) in FRICTION_HISTOGRAMS.items():
        if f"{prefix}_histogram" not in ds.variables:
            continue
        x, s, total = _force_survival(ds, prefix)
        if total <= 0:
            continue
        curves[prefix] = s
        if prefix == "friction_ripple" and np.array_equal(s, curves.get("friction_increase")):
            ax_d.plot([], [], color="0.3", ls=ls, lw=1.4,
                      label="ripple (max − min): the same curve here")
            continue
        colour = {"friction_increase": SERIES_COLOURS[0], "friction_ripple": SERIES_COLOURS[4],
                  "contact_force_max": SERIES_COLOURS[2]}[prefix]
        # at each bin's lower edge the fraction at or above it: an upper step within the bin
        ax_d.step(x[1:], s[1:], where="post", color=colour, ls=ls,
                  lw=1.6 if ls == "-" else 1.3, label=label)
        counts = np.asarray(ds[f"{prefix}_histogram"], dtype=float)
        nz = np.flatnonzero(counts[1:] > 0) + 1  # bins with a rise (bin 0: below 1 µN)
        if nz.size:
            low = min(low, x[nz[0]])
            top = max(top, x[nz[-1] + 1])
        floor = min(floor, 0.5 / total)
    resolved = _i(ds, "n_assemblies_friction_resolved")
    p, lo, hi = (_f(ds, f"friction_exceedance_probability{s}") for s in ("", "_ci_lower",
                                                                         "_ci_upper"))
    if has_limit:
        ax_d.axvline(limit, color=LIMIT_COLOUR, lw=2.0, ls="--",
                     label=f"spec limit: increase ≤ {limit:.4g} N")
        if np.isfinite(p):
            ax_d.errorbar([limit], [max(p, floor)], yerr=[[max(p - lo, 0.0)], [hi - p]]
                          if p > 0 else None, fmt="o", color=LIMIT_COLOUR, ms=6, capsize=4,
                          label=f"P(increase > {limit:.4g} N) = {format_fraction(p)}\n"
                                f"(95 % CI {format_fraction(lo)} to {format_fraction(hi)})")
        top, low = max(top, limit), min(low, limit)
    if np.isfinite(low) and top > 0:
        ax_d.set_xscale("log")
        ax_d.set_yscale("log")
        ax_d.set_xlim(0.5 * low, 2.0 * top)
        ax_d.set_ylim(0.5 * floor, 1.6)
    zero = curves.get("friction_increase")
    no_rise = 1.0 - zero[1] if zero is not None else np.nan
    ax_d.set_title(f"(a) over the {resolved:,} resolved {many}: "
                   f"{format_fraction(no_rise)} with no rise (< 1 µN)", fontsize=10)
    ax_d.set_xlabel("force [N] (log)")
    ax_d.set_ylabel(f"fraction of {many} at or above [-] (log)")
    ax_d.legend(loc="lower left", fontsize=7.5, framealpha=0.9)

    # (b) example traces of the increase
    if "example_friction_force" in ds.variables:
        travel = 1e3 * np.asarray(ds["travel"], dtype=float)
        force = np.asarray(ds["example_friction_force"], dtype=float)
        base = np.asarray(ds["example_friction_force_baseline"], dtype=float)
        for e in range(force.shape[0]):
            ax_t.plot(travel, force[e] - base[e], color=SERIES_COLOURS[e % 6], lw=1.5,
                      label=f"example {e + 1} ({_example_label(ds, e)}): F₀ = {base[e]:.4g} N")
        if has_limit:
            ax_t.axhline(limit, color=LIMIT_COLOUR, lw=1.5, ls="--", label="spec limit")
        ax_t.axhline(0, color="0.5", lw=0.6)
        reach = max(float(np.nanmax(force - base[:, None], initial=0.0)),
                    limit if has_limit else 0.0)
        ax_t.set_ylim(-0.05 * reach if reach > 0 else -0.1, 1.5 * reach if reach > 0 else 1.0)
        ax_t.set_xlim(travel[0], travel[-1])
        ax_t.legend(loc="upper left", fontsize=7.5, framealpha=0.9)
    else:
        ax_t.text(0.5, 0.5, "no example trajectories in the file\n([contact] examples = 0)",
                  transform=ax_t.transAxes, ha="center", va="center")
    ax_t.set_xlabel("carriage travel [mm]")
    ax_t.set_ylabel("friction force F − F₀ [N]")
    ax_t.set_title("(b) examples: rise of the track's friction force over its baseline F₀",
                   fontsize=10)

    # (c) the balls of one example, as Fig. 9 of the paper draws them
    if "example_ball_position" in ds.variables:
        travel = 1e3 * np.asarray(ds["travel"], dtype=float)
        e = _busiest_example(ds)
        z = np.asarray(ds["example_ball_position"], dtype=float)[e]  # (travel, ball)
        n = z.shape[1]
        if np.isfinite(ball_diameter):
            y = 1e6 * (z - z[0, 0] - ball_diameter * np.arange(n))
            ylabel = "ball centre − v t/2 − (start of ball 1 + i D) [µm]"
            note = "touching balls share a line"
        else:
            y = 1e6 * (z - z[0])
            ylabel = "ball centre − v t/2 − its start [µm]"
            note = "D unknown: each ball from its own start"
        from matplotlib import colormaps

        cmap = colormaps["viridis"]
        for i in range(n):
            ax_z.plot(travel, y[:, i], color=cmap(i / max(n - 1, 1)), lw=1.3,
                      label=(f"ball {i + 1}" + (" (trailing)" if i == 0 else
                                               " (leading)" if i == n - 1 else ""))
                      if i in (0, n - 1) else None)
        if "example_contact_force" in ds.variables and n > 1:
            q = np.asarray(ds["example_contact_force"], dtype=float)[e]  # (travel, pair)
            label = "a contact forms (first travel point with a force)"
            for j in range(n - 1):
                hit = np.flatnonzero(q[:, j] > 0)
                if hit.size:
                    ax_z.plot(travel[hit[0]], y[hit[0], j + 1], "o", color=LIMIT_COLOUR, ms=4,
                              zorder=5, label=label)
                    label = None
        ax_z.set_xlim(travel[0], travel[-1])
        low_y, high_y = float(np.nanmin(y)), float(np.nanmax(y))
        span = max(high_y - low_y, 1.0)
        ax_z.set_ylim(low_y - 0.05 * span, high_y + 0.3 * span)  # room for the legend
        ax_z.legend(loc="upper left", fontsize=7.5, framealpha=0.9, ncols=2)
        ax_z.set_ylabel(ylabel, fontsize=8.5)
        ax_z.set_title(f"(c) the {n} balls of example {e + 1} along the stroke ({note})",
                       fontsize=10)
    else:
        ax_z.set_title("(c) ball positions", fontsize=10)
        ax_z.text(0.5, 0.5, "no example trajectories in the file",
                  transform=ax_z.transAxes, ha="center", va="center")
    ax_z.set_xlabel("carriage travel [mm]")

    # (d) drivers
    indices = friction_indices(sens)
    if indices is not None:
        first, total, first_ci, total_ci = indices
        d = len(sens.factors)
        order = np.argsort(np.nan_to_num(total, nan=-1.0))  # largest at the top
        y = np.arange(d)
        for values, ci, shift, colour, label in (
                (total, total_ci, 0.18, SERIES_COLOURS[0], "total effect S_T"),
                (first, first_ci, -0.18, SERIES_COLOURS[4], "first order S")):
            v, c = values[order], ci[order]
            ax_s.barh(y + shift, np.nan_to_num(v), height=0.36, color=colour, label=label)
            err = np.abs(np.stack([v - c[:, 0], c[:, 1] - v]))
            ax_s.errorbar(np.nan_to_num(v), y + shift, xerr=np.nan_to_num(err), fmt="none",
                          ecolor="k", capsize=2, lw=0.8)
        ax_s.set_yticks(y, [sens.factors[i].replace("_", " ") for i in order], fontsize=8)
        ends = np.concatenate([total_ci.ravel(), first_ci.ravel()])
        ends = ends[np.isfinite(ends)]
        ax_s.set_xlim(max(-1.0, min(-0.05, ends.min() - 0.02)) if ends.size else -0.05,
                      min(2.0, max(1.05, ends.max() + 0.02)) if ends.size else 1.05)
        ax_s.axvline(0, color="0.4", lw=0.8)
        ax_s.legend(loc="lower right", fontsize=8)
        if np.all(np.isnan(total)):
            ax_s.text(0.5, 0.5, "the increase does not vary:\nno index",
                      transform=ax_s.transAxes, ha="center", va="center")
    else:
        ax_s.text(0.5, 0.5, "no Sobol' indices of the friction increase",
                  transform=ax_s.transAxes, ha="center", va="center")
        ax_s.set_yticks([])
    ax_s.set_xlabel("Sobol' index [-] (bars: 95 % bootstrap interval)")
    ax_s.set_ylabel("tolerance source")
    ax_s.set_title("(d) drivers: Sobol' indices of the friction increase", fontsize=10)
    whose = (f"the worst track of each {one}" if tracks_of(ds) else f"each {one}")
    fig.suptitle(f"What contact costs: the carriage friction force of {whose} after its balls "
                 f"touch, μ_bb = {_f(ds, 'ball_friction_coefficient'):.3g}", fontsize=10.5)
    return fig


def friction_summary(ds) -> str:
    """One sentence on the friction after contact (the headline of a study with
    ``[contact]``)."""
    one = contact_unit(ds)[0]
    per = f"per {one}" + (" (its worst track)" if tracks_of(ds) else "")
    base = _f(ds, "friction_force_baseline")
    median, q99 = (_quantile_of(ds, "friction_increase_quantile", q) for q in (0.5, 0.99))
    text = (f"Friction after contact {per}: the carriage friction force rises over its "
            f"{_sig(base)} N baseline by a median {_force_text(median)}, 99 % quantile "
            f"{_force_text(q99)} (largest {_force_text(_f(ds, 'friction_increase_max'))})")
    limit = _f(ds, "friction_increase_limit")
    if np.isfinite(limit) and limit > 0:
        p, lo, hi = (_f(ds, f"friction_exceedance_probability{s}") for s in (
            "", "_ci_lower", "_ci_upper"))
        text += f"; P(increase > {limit:.4g} N) = {format_fraction(p, lo, hi)}"
    return text + "."


#: Caption of the friction figure (HTML and PDF).
FRICTION_CAPTION = (
    "(a) The fraction of assemblies whose friction force rises by at least a given force over "
    "its free-rolling baseline (the largest rise over the stroke), with the spec limit and "
    "P(increase > limit) with its 95 % interval; the ripple and the largest ball-to-ball "
    "force beside it. (b) The rise against the carriage travel for the stored examples. "
    "(c) The balls of the example with the longest contact along the stroke, each less the "
    "nominal travel v t/2 of a free ball and its place in a touching train, so that touching "
    "balls share a line (as the paper's Fig. 9 draws its two balls). (d) The tolerances that "
    "drive the rise: Sobol' indices of the increase.")


def friction_content(ds, sens=None) -> dict:
    """The section "What contact costs" of a study with ``[contact]`` (HTML and PDF).

    Parameters
    ----------
    ds : xarray.Dataset
        A result file with the friction variables (:data:`tolsim.io.schema.friction.
        FRICTION_VARIABLES`).
    sens : optional
        Sensitivity indices; those of the output ``friction_increase`` rank the drivers.

    Returns
    -------
    dict
        ``heading`` (str), ``paragraphs`` (list of str), ``tables`` (list of
        :class:`ReportTable`: the figures at a glance, their distribution over the
        assemblies, the drivers), ``figure_after`` (index of the table the figure follows)
        and ``notes`` (list of str, below the tables).
    """
    one, many = contact_unit(ds)
    tracks = tracks_of(ds)
    n_asm = _i(ds, "n_assemblies")
    resolved = _i(ds, "n_assemblies_friction_resolved")
    unresolved = _i(ds, "n_assemblies_friction_unresolved")
    sliding = _i(ds, "n_assemblies_sliding")
    exceed = _i(ds, "n_friction_exceedance")
    travel = 1e3 * _f(ds, "horizon") * _f(ds, "groove_velocity")
    mu_bb = _f(ds, "ball_friction_coefficient")
    limit = _f(ds, "friction_increase_limit")
    has_limit = np.isfinite(limit) and limit > 0
    worst = (f"the worst of its {counted(tracks, 'track')} (the one whose friction force "
             "rises most)" if tracks else "its track")
    paragraphs = [
        f"For every sampled {one} the study follows "
        + ("each of its trains" if tracks else "its balls")
        + f" over the {travel:.4g} mm stroke after the balls touch (tolsim's extension of the "
        "paper, which stops at the first contact). Balls in contact move together as a "
        "cluster and push each other with forces set by their creep stiffness; the Coulomb "
        f"friction at each ball-to-ball contact (μ_bb = {mu_bb:.3g}) brakes both balls, and "
        "the grooves pay for it in carriage friction. The model and its sources are in the "
        "assumptions table (topic \"after contact\").",
        ("Each assembly counts with " + worst if tracks else "Each train counts with its "
         "own friction force") + ": its free-rolling baseline F₀ (the friction force "
        "without ball-to-ball contact, from spin and differential slip), the increase (the "
        "largest rise of its friction force over F₀ during the stroke), the ripple (max − min "
        "over the stroke), the largest ball-to-ball force and the fraction of the stroke with "
        f"a contact. The statistics are over the {resolved:,} {many} whose balls were "
        f"followed over the whole stroke; P(increase > limit) is bounded over all {n_asm:,}.",
    ]
    p, lo, hi = (_f(ds, f"friction_exceedance_probability{s}") for s in ("", "_ci_lower",
                                                                         "_ci_upper"))
    rows = [("ball-to-ball friction coefficient μ_bb", f"{mu_bb:.4g}",
             "config ([contact] ball_friction_coefficient)"),
            ("creep model (K, F₀ of each ball)", str(ds.attrs.get("contact_creep_model", "?")),
             "config ([contact] creep_model)"),
            ("free-rolling baseline F₀ of the track: mean ± std",
             f"{_sig(_f(ds, 'friction_force_baseline'))} N ± "
             f"{_force_text(_f(ds, 'friction_force_baseline_std'))}", "friction_force_baseline"),
            ("increase over F₀: mean / median / 99 %",
             f"{_force_text(_f(ds, 'friction_increase_mean'))} / "
             f"{_force_text(_quantile_of(ds, 'friction_increase_quantile', 0.5))} / "
             f"{_force_text(_quantile_of(ds, 'friction_increase_quantile', 0.99))}",
             "friction_increase_mean, _quantile"),
            (f"largest increase of any {one}", _force_text(_f(ds, "friction_increase_max")),
             "friction_increase_max"),
            ("spec limit on the increase",
             f"{limit:.4g} N" if has_limit else "no spec limit given",
             "config ([contact] friction_increase_limit_N)")]
    if has_limit:
        rows.append((f"P(increase > {limit:.4g} N) per {one}",
                     f"{format_fraction(p, lo, hi)} ({exceed:,} of {n_asm - unresolved:,} "
                     f"{many} whose outcome is known; "
                     f"{estimator_label(ds, 'friction_exceedance_probability')})",
                     "friction_exceedance_probability, _ci_lower, _ci_upper"))
        if unresolved:
            bounds = (format_fraction(_f(ds, f"friction_exceedance_probability_bound_{end}"))
                      for end in ("lower", "upper"))
            rows.append((f"bounds over all {n_asm:,} {many} ({unresolved:,} unresolved counted "
                         "as below / above the limit)", " to ".join(bounds),
                         "friction_exceedance_probability_bound_lower, _upper"))
    rows += [
        (f"time-mean increase over the stroke (mean over the {many})",
         _force_text(_f(ds, "friction_increase_stroke_mean")), "friction_increase_stroke_mean"),
        ("largest ball-to-ball force: mean / median / 99 %",
         f"{_force_text(_f(ds, 'contact_force_max_mean'))} / "
         f"{_force_text(_quantile_of(ds, 'contact_force_max_quantile', 0.5))} / "
         f"{_force_text(_quantile_of(ds, 'contact_force_max_quantile', 0.99))}",
         "contact_force_max_mean, _quantile"),
        ("ripple of the friction force: median / 99 %",
         f"{_force_text(_quantile_of(ds, 'friction_ripple_quantile', 0.5))} / "
         f"{_force_text(_quantile_of(ds, 'friction_ripple_quantile', 0.99))}",
         "friction_ripple_quantile"),
        ("fraction of the stroke with a ball-to-ball contact (mean)",
         format_fraction(_f(ds, "contact_fraction_mean")), "contact_fraction_mean"),
        ("multi-ball clusters formed over the stroke (mean)",
         _sig(_f(ds, "clusters_formed_mean"), 3), "clusters_formed_mean"),
        (f"{many} resolved / unresolved / with a sliding ball",
         f"{resolved:,} / {unresolved:,} / {sliding:,} of {n_asm:,}",
         "n_assemblies_friction_resolved, _unresolved, n_assemblies_sliding"),
    ]
    tables = [ReportTable(
        "Friction after contact at a glance", ("quantity", "value", "result file"),
        tuple(rows), (0.42, 0.33, 0.25),
        "Forces in N. Unresolved: a train with a ball outside the creep model (or "
        "unresolved before contact), or one with a sliding ball, from the onset of sliding.",
        (1,))]
    header = ("quantity [N]", "mean", "std", *(f"{100 * q:g} %" if q != 0.5 else "median"
                                               for q in FRICTION_LEVELS))
    dist = []
    for prefix, (label, _) in FRICTION_HISTOGRAMS.items():
        if f"{prefix}_quantile" not in ds.variables:
            continue
        dist.append((label, _force_text(_f(ds, f"{prefix}_mean"), ""),
                     _force_text(_f(ds, f"{prefix}_std"), ""),
                     *(_force_text(_quantile_of(ds, f"{prefix}_quantile", q), "")
                       for q in FRICTION_LEVELS)))
    tables.append(ReportTable(
        f"Distribution over the {resolved:,} resolved {many}", header, tuple(dist),
        (0.37, 0.09, 0.09, 0.09, 0.09, 0.09, 0.09, 0.09),
        "Quantiles from the fixed force histogram (50 bins per decade, within one bin: a "
        "relative 4.7 %; a value below 1 µN, no rise, is shown as 0); mean and std exact.",
        tuple(range(1, len(header)))))
    indices = friction_indices(sens)
    notes = []
    if indices is not None and not np.all(np.isnan(indices[1])):
        first, total, _, total_ci = indices
        order = np.argsort(-np.nan_to_num(total, nan=-1.0), kind="stable")
        tables.append(ReportTable(
            "Drivers of the friction increase: ranked by the total-effect index",
            ("rank", "tolerance", "total effect S_T [95 % CI]", "first order S"),
            tuple((str(r), sens.factors[i], f"{total[i]:.3f} [{total_ci[i, 0]:.3f}, "
                   f"{total_ci[i, 1]:.3f}]", f"{first[i]:.3f}")
                  for r, i in enumerate(order, 1)),
            (0.08, 0.5, 0.27, 0.15),
            "Sobol' indices of the increase per assembly (unresolved assemblies left out), "
            "from the same design as the indices of ε and contact (section \"What drives the "
            "risk\"). A total index well above the first order means the source acts through "
            "interactions: the rise needs a contact first, which takes both a difference in ε "
            "and a gap small enough to close.", (0, 2, 3)))
    elif indices is not None:
        notes.append("The friction increase does not vary over the Sobol' samples: no "
                     "ranking of its drivers.")
    else:
        notes.append("No Sobol' indices of the friction increase (none stored in the result "
                     "file, or the sensitivity analysis was not requested).")
    ripple = ("friction_ripple_histogram" in ds.variables
              and np.array_equal(np.asarray(ds["friction_ripple_histogram"]),
                                 np.asarray(ds["friction_increase_histogram"])))
    if ripple:
        notes.append("The ripple equals the increase here: with constant ε a contact never "
                     "opens again, so a track's friction force only steps up during the "
                     "stroke, and where a stroke starts without contact (here every one) its "
                     "minimum is the baseline.")
    return dict(heading=section_titles(ds)["friction"], paragraphs=paragraphs, tables=tables,
                figure_after=0, notes=notes)


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
    the estimator, P, CV, interval and model evaluations, and for importance sampling the
    design point ("the most likely way to fail") per tolerance source. Empty for a plain
    Monte Carlo file."""
    rows, points = [], []
    for name, what in RARE_EVENTS:
        if name not in ds.variables or f"{name}_evaluations" not in ds.variables:
            continue
        attrs = ds[name].attrs
        if attrs.get("estimator", "monte_carlo") == "monte_carlo":
            continue
        p = _f(ds, name)
        lo, hi = _f(ds, f"{name}_ci_lower"), _f(ds, f"{name}_ci_upper")
        rows.append(
            f"<tr><td>{html.escape(what)}</td>"
            f"<td>{html.escape(ESTIMATOR_NAMES.get(attrs['estimator'], attrs['estimator']))}"
            f"</td><td class='num'>{html.escape(format_fraction(p, lo, hi))}</td>"
            f"<td class='num'>{_f(ds, f'{name}_coefficient_of_variation'):.3g}</td>"
            f"<td class='num'>{_i(ds, f'{name}_evaluations'):,}</td>"
            f"<td>{html.escape(str(attrs.get('interval', '')))}"
            f"{html.escape(' ' + str(attrs['note'])) if attrs.get('note') else ''}</td></tr>")
        prefix = name.removesuffix("_probability")  # contact_, ..._exceedance_
        if f"{prefix}_reliability_index" in ds.variables and "factor_name" in ds.variables:
            points.append(_design_point_table(ds, prefix, what))
    if not rows:
        return []
    return ["<h3>Rare events</h3><p>Estimated after the plain run by the estimator named, "
            "in the study's standard-normal input space (README \"Rare events\"); each "
            "interval is the estimator's own.</p><table><tr><th>event</th><th>estimator</th>"
            "<th>P (95 % interval)</th><th>CV</th><th>model evaluations</th>"
            "<th>interval</th></tr>", *rows, "</table>", *points]


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
           f"{_f(ds, f'{name}_reliability_index'):.3f}, FORM estimate "
           f"{html.escape(format_fraction(_f(ds, f'{name}_form_probability')))}.</p>"
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
    model (``velocity_model`` attribute). A carriage study has a section 3 "Carriage"
    (figure ``carriage``), and the sections after it move down by one; a study with
    ``[contact]`` has a section "What contact costs" (figure ``friction``) after the contact
    section, and the sections after it move down by one more."""
    model = ds.attrs.get("velocity_model", "?")
    k = 1 if tracks_of(ds) else 0  # a carriage study has its section 3 "Carriage"
    c = 1 if has_friction(ds) else 0  # a study with [contact]: "What contact costs"
    titles = {"velocity_deviation": f"{3 + k}. Ball velocity deviation ε",
              "contact": f"{4 + k}. Ball-to-ball contact",
              "quality": f"{5 + k + c}. Quality engineering",
              "sensitivity": f"{6 + k + c}. What drives the risk",
              "spot_checks": f"{7 + k + c}. Model check: {model} versus the full friction "
                             "model"}
    if c:
        titles["friction"] = (f"{5 + k}. What contact costs: carriage friction after the "
                              "balls touch")
    if k:
        titles = {"carriage": "3. Carriage: load case, preload, load distribution and "
                              "stiffness", **titles}
    return titles


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
                 f"{_i(ds, 'n_assemblies'):,}", True),
                ("tracks (trains) per carriage", tracks, True),
                ("balls per train (track)", balls, True),
                ("balls per carriage", tracks * balls, True)]
    else:
        head = [("assemblies (trains) sampled", f"{_i(ds, 'n_assemblies'):,}", True),
                ("balls per train", ds.sizes.get("ball", "?"), True)]
    return [
        *head,
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
    one, many = contact_unit(ds)
    tracks = tracks_of(ds)
    per = (f"per assembly: contact in {any_train(tracks, 'the')} of a carriage"
           if tracks else "per train")
    out = [f"P(ball-to-ball contact within the {travel:.4g} mm stroke) = "
           f"{format_fraction(p, lo, hi)} {per} ({_i(ds, 'n_contact'):,} of "
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


def _stackup_rows(ds):
    """Worst case and RSS of the linear stack-up beside the Monte Carlo (HTML parts); a
    carriage study has none (a note says why)."""
    if "critical_ball" not in ds:
        if tracks_of(ds):
            return ["<h3>Linear stack-up beside the Monte Carlo</h3><p class='muted'>Not "
                    "computed for a carriage: its balls are coupled through the carriage "
                    "(one ball's error moves the carriage and so loads the others), so the "
                    "free-ball sensitivities of the stack-up do not apply. The Monte Carlo "
                    "figures above are the ones to use.</p>"]
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
        "differences through the study's own models, "
        "<code>tolsim.study.analyses.worst_case</code>): "
        "the worst case adds every source at the edge of its band, RSS adds them as "
        "independent standard deviations (with the rail fields' correlation). Where RSS and "
        "the Monte Carlo std agree, the model is near-linear over the tolerances; the "
        "Monte Carlo figures are the ones to use.</p>",
    ]


def _table_html(table):
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


def _html(ds, figures, sens, sens_source, q, path, verdict=None, carriage=None,
          friction=None):
    a = ds.attrs
    n_asm = _i(ds, "n_assemblies")
    one, many = contact_unit(ds)
    tracks = tracks_of(ds)
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
                     + ("per track and assembly (each track has its own rail and carriage "
                        "groove; " if tracks else "per assembly (")
                     + "or as a random field along the rail with a correlation "
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
        _row("P(ball-to-ball contact within the stroke)" + (
                f" per assembly (contact in {any_train(tracks)})" if tracks else ""),
             f"{format_fraction(p, lo, hi)}  " + (
                 f"({_i(ds, 'n_contact'):,} of {n_asm - n_unres:,} {many} whose outcome is "
                 "known; Clopper-Pearson)" if estimator_label(ds) == "Clopper-Pearson" else
                 f"({estimator_label(ds)}; the plain run: {_i(ds, 'n_contact'):,} of "
                 f"{n_asm - n_unres:,} {many})")),
        *([_row(f"bounds over all {n_asm:,} {many} ({n_unres:,} unresolved counted as no "
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
             f"{_i(ds, 'n_balls_full_failed')}; {n_unres} {many} unresolved (none left out: "
             "see the bounds)" + (f"; {_i(ds, 'n_assemblies_carriage_failed'):,} carriages "
                                  "not solved" if tracks else "")),
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
            ds, _config_or_none(ds))
        parts.append(f"<h2 id='carriage'>{html.escape(carriage['heading'])}</h2>")
        parts += [f"<p>{html.escape(text)}</p>" for text in carriage["paragraphs"]]
        for k, table in enumerate(carriage["tables"]):
            parts += _table_html(table)
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
            parts += _table_html(table)
            if k == friction["figure_after"]:
                fig("friction")
        parts += [f"<p class='muted'>{html.escape(text)}</p>" for text in friction["notes"]]
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
                     + ("errors and its carriage's load distribution" if tracks else "errors")
                     + ", so they are correlated: the intervals take the assembly as the "
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
    titles_out = output_titles(one)
    if friction_indices(sens) is not None:
        parts.append("<p class='muted'>The drivers of the friction increase are ranked in "
                     f"section {html.escape(titles['friction'].split('.')[0])}.</p>")
    sens = _without_output(sens)
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
                parts.append(f"<p>{html.escape(titles_out.get(output, output))}: the "
                             "output does not vary, no ranking.</p>")
                continue
            top = int(np.nanargmax(sens.total[k]))
            parts.append(
                f"<p class='verdict'>Largest driver of "
                f"{html.escape(OUTPUT_SHORT.get(output, output))}: "
                f"{html.escape(sens.factors[top])} (total effect {sens.total[k, top]:.2f}, "
                f"alone {sens.first_order[k, top]:.2f}).</p>")
            parts.append(f"<h3>Ranked by {html.escape(titles_out.get(output, output))}"
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
    parts.append(f"<h2 id='sign-off'>{_sign_off_title(ds)}</h2><table class='signoff'><tr>"
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
                cpk_minimum=None, friction_exceedance_limit=None) -> ReportOutputs:
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
    friction_exceedance_limit : float, optional
        Allowed fraction of assemblies whose friction increase exceeds the config's limit
        (a study with ``[contact]``), for the verdict; the config has no key for it.

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
        carriage = carriage_content(ds, _config_or_none(ds))
        figs["carriage"] = plot_carriage_loads(ds, carriage["ball_z"],
                                               carriage["preload_ball_load"])
    figs.update({"velocity_deviation": plot_velocity_deviation(ds),
                 "contact": plot_contact(ds), "spot_checks": plot_spot_checks(ds)})
    if has_friction(ds):  # a study with [contact]: what contact costs
        out.friction = friction_content(ds, sens)
        figs["friction"] = plot_friction(ds, sens, _ball_diameter(ds, _config_or_none(ds)))
    if q:
        figs["quality"] = plot_quality(ds, q)
    if sens is not None and len(sens.factors):
        figs["sensitivity"] = plot_sensitivity(_without_output(sens), contact_unit(ds)[0])
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
        fh.write(_html(ds, pngs, sens, source, q, os.fspath(path), out.verdict, carriage,
                       out.friction))
    if pdf:
        say("report.pdf")
        out.pdf = write_report_pdf(ds, figs, sens, out.verdict, path,
                                   os.path.join(folder, "report.pdf"), carriage, out.friction)
    return out


def write_report_pdf(ds, figs, sens, verdict, path, pdf_path, carriage=None,
                     friction=None) -> str:
    """The PDF of a report (:func:`tolsim.reports.pdf.write_pdf`): ``figs`` are the report's
    Figures by name, rendered again at :data:`tolsim.reports.pdf.FIGURE_DPI`; ``carriage``
    the section of a carriage study (:func:`carriage_content`, made when not given),
    ``friction`` that of a study with ``[contact]`` (:func:`friction_content`, likewise)."""
    from tolsim.reports import pdf

    return pdf.write_pdf(pdf_path, **pdf_content(ds, figs, sens, verdict, path, carriage,
                                                 friction))


def pdf_content(ds, figs, sens, verdict, path, carriage=None, friction=None) -> dict:
    """The arguments of :func:`tolsim.reports.pdf.report_pages` for a result file (with
    ``carriage``, the section of :func:`carriage_content`, in a carriage study, and
    ``friction``, the section of :func:`friction_content`, in a study with ``[contact]``)."""
    from tolsim.reports import pdf

    order = ("carriage", "velocity_deviation", "contact", "friction", "quality",
             "sensitivity", "spot_checks")
    pngs = {name: render_png(figs[name], dpi=pdf.FIGURE_DPI) for name in order if name in figs}
    extra = {}
    if tracks_of(ds):
        extra["carriage"] = carriage if carriage is not None else carriage_content(
            ds, _config_or_none(ds))
    if has_friction(ds):
        extra["friction"] = friction if friction is not None else friction_content(ds, sens)
    a = ds.attrs
    subtitle = (f"Result file {os.path.basename(os.fspath(path))}, report by tolsim "
                f"{__version__} on {datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}; "
                f"study run by {a.get('source', '?')}: {a.get('history', '?')}")
    return dict(
        title=str(a.get("title", "tolsim study")), subtitle=subtitle,
        verdict=verdict, headline=headline(ds, sens),
        facts=[(label, str(value)) for label, value, _ in study_facts(ds)],
        tolerances=_tolerance_rows(ds), assumptions=assumption_table(ds), figures=pngs,
        captions=captions(ds), sections=section_titles(ds), result_path=os.fspath(path),
        sign_off=(SIGN_OFF_ROLES, SIGN_OFF_FIELDS, SIGN_OFF_DECISIONS), **extra)
