"""A result file as the reports see it: one reader and typed accessors.

:func:`read_result_file` opens a result file of ``tolsim run`` for a report, or raises
:class:`NotAResult` with a one-line reason. The accessors read a scalar variable
(:func:`number`, :func:`integer`), a global attribute (:func:`attribute`), bin edges and
stored quantiles, and the config embedded in the file (:func:`config_of`,
:func:`config_or_none`, :func:`config_toml`, :func:`config_key`) of the Dataset it returns,
or of any result Dataset (a point of a sweep, say), with a default where the file has not
got the item. Every report module reads a result through them.
"""

import os
import re
import tomllib

import numpy as np
import xarray as xr

from tolsim.io import schema
from tolsim.io.config import parse_config
from tolsim.io.netcdf import IntegrityError, check_attributes, read_result, verify_checksums
from tolsim.io.schema.carriage import zone_end_counts
from tolsim.physics.velocity.models import BALL_REGIME_LABELS, BALL_UNLOADED
from tolsim.study.statistics.accumulator import clopper_pearson

#: Names of the tolsim result-file variables the study report needs.
REQUIRED = ("velocity_deviation_histogram", "contact_probability", "survival_probability",
            "spot_check_velocity_deviation_analytic", "spot_check_velocity_deviation_full")


class NotAResult(ValueError):
    """The file is missing, not netCDF, or not a tolsim study result."""


class FailsChecksum(NotAResult):
    """A variable of the file fails its SHA-256 checksum (:mod:`tolsim.io.checksums`)."""


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------
def read_result_file(path, *, validate=False, verify=True):
    """Open a tolsim result file, or raise :class:`NotAResult` with a one-line reason.

    Parameters
    ----------
    path : str or path
        A result file of ``tolsim run``.
    validate : bool
        Read it with :func:`tolsim.io.netcdf.read_result`, which checks it against the whole
        schema (``tolsim compare``). By default only the global attributes and the variables
        :data:`REQUIRED` are checked (the study report and the sweep report), so that older or
        partial files are read as far as they can be. Global attributes of the wrong type
        are refused either way (:func:`tolsim.io.netcdf.check_attributes`).
    verify : bool
        Verify the variables' SHA-256 checksums (:mod:`tolsim.io.checksums`): a variable that
        fails is refused, a file without checksums is read with an
        :class:`~tolsim.io.checksums.UnverifiedResultWarning`. False for forensics. Without
        the study report's validation, the Dataset says why it is not verified
        (:func:`unverified_reason`), which the reports print on their pages.

    Returns
    -------
    xarray.Dataset
        Loaded into memory.

    Raises
    ------
    NotAResult
        If the file is missing, a folder, not netCDF, not a (complete) tolsim result, or
        fails its checksums.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise NotAResult(f"{path}: no such file")
    if os.path.isdir(path):
        raise NotAResult(f"{path}: is a folder, not a result file")
    with open(path, "rb") as fh:
        magic = fh.read(8)
    if magic.startswith(b"PK\x03\x04") and path.endswith(".partial"):
        raise NotAResult(f"{path}: the checkpoint of an interrupted tolsim run, not a result: "
                         "run the same command again to finish it")
    if not (magic.startswith(b"\x89HDF\r\n\x1a\n") or magic[:3] == b"CDF"):
        raise NotAResult(f"{path}: not a netCDF file")
    if validate:
        try:
            ds = read_result(path, verify=verify)
        except IntegrityError as exc:
            raise FailsChecksum(" ".join(str(exc).split())) from None
        except ValueError as exc:
            raise NotAResult(" ".join(str(exc).split())) from None
        broken = interval_inconsistency(ds)
        if broken and verify:  # as below
            raise FailsChecksum(f"{path}: inconsistent data: {broken}")
        return ds
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
    except (OSError, ValueError, RuntimeError) as exc:
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
    try:
        verified = verify_checksums(path) if verify else False
        check_attributes(ds, path)
    except IntegrityError as exc:
        raise FailsChecksum(" ".join(str(exc).split())) from None
    except ValueError as exc:
        raise NotAResult(" ".join(str(exc).split())) from None
    broken = interval_inconsistency(ds)
    if broken and verify:  # tolsim never writes these: altered (and signed again) or damaged
        raise FailsChecksum(f"{path}: inconsistent data: {broken}")
    ds.encoding[UNVERIFIED] = "" if verified else (
        "the file has no checksums (written before tolsim stored them)" if verify else
        "the report was made with --no-verify: the file's checksums were not checked")
    return ds


def interval_inconsistency(ds) -> str:
    """The first probability of a result outside its own interval or outside [0, 1], as a
    phrase ("" if none): ``X`` against ``X_ci_lower`` and ``X_ci_upper`` (1e-12 of slack),
    over every point of a sweep. tolsim writes none (estimates and interval ends of rare
    events are clipped to [0, 1] together)."""
    for name in ds.data_vars:
        if "probability" not in name or name.endswith(("_ci_lower", "_ci_upper")):
            continue
        low, high = f"{name}_ci_lower", f"{name}_ci_upper"
        if low not in ds.data_vars or high not in ds.data_vars:
            continue
        p, lo, hi = (np.asarray(ds[x], dtype=float) for x in (name, low, high))
        if p.shape != lo.shape or p.shape != hi.shape:
            continue
        with np.errstate(invalid="ignore"):
            bad = (p < lo - 1e-12) | (p > hi + 1e-12) | (p < 0.0) | (p > 1.0)
        if np.any(bad):
            k = int(np.flatnonzero(bad.ravel())[0])
            return (f"{name} = {p.ravel()[k]:.6g} lies outside its interval "
                    f"[{lo.ravel()[k]:.6g}, {hi.ravel()[k]:.6g}] or [0, 1]")
    return ""


#: ``Dataset.encoding`` key of :func:`read_result_file`: why the data of the file read are not
#: verified against their checksums ("" when they are).
UNVERIFIED = "tolsim_unverified"


def unverified_reason(ds) -> str:
    """Why the data of a result read by :func:`read_result_file` are not verified ("" when
    they are, or the Dataset did not come from it)."""
    return str(ds.encoding.get(UNVERIFIED, ""))


# --------------------------------------------------------------------------------------------
# Variables and attributes
# --------------------------------------------------------------------------------------------
def number(ds, name, default=np.nan) -> float:
    """The scalar variable ``name`` as a float, ``default`` when the file has not got it."""
    if name not in ds.variables:
        return default
    return float(np.asarray(ds[name]))


def integer(ds, name, default=0) -> int:
    """The scalar variable ``name`` as an int, ``default`` when the file has not got it."""
    if name not in ds.variables:
        return default
    return int(np.asarray(ds[name]))


def regime_counts_text(ds) -> str:
    """Balls per regime of a result (``n_balls_regime``, issue 25) in one line, the empty
    regimes left out; "" for a file without the counts."""
    if "n_balls_regime" not in ds.variables:
        return ""
    counts = dict(zip(np.asarray(ds["ball_regime"]).tolist(),
                      np.asarray(ds["n_balls_regime"]).tolist(), strict=True))
    names = {**BALL_REGIME_LABELS, BALL_UNLOADED: "unloaded (pushed along)"}
    return ", ".join(f"{names.get(code, code)} {count:,}" for code, count in counts.items()
                     if count)


def static_fallback_text(ds) -> str:
    """The balls whose static model left them without balance, answered by the ``solved``
    model (``n_balls_static_fallback``) in one line; "" for none or a file without the count."""
    n = int(ds["n_balls_static_fallback"]) if "n_balls_static_fallback" in ds.variables else 0
    if not n:
        return ""
    model = ds.attrs.get("static_model", "the study's")
    return (f"{n:,} of {int(ds['n_balls']):,} balls answered by the solved static model: the "
            f"{model} model left them without balance (a contact in tension, as where "
            "|N_x| >= N_y with paired forces, one loaded contact, or not converged)")


def _zone_end_text(ds, fraction) -> str:
    """The fraction of first contacts at the zone's ends with its 95 % Clopper-Pearson
    interval over the first contacts (``contact_pair_count``, track by pair)."""
    text = f"{100 * fraction:.1f} %"
    if "contact_pair_count" in ds.variables:
        counts = np.asarray(ds["contact_pair_count"])  # (track, pair)
        ends, total = zone_end_counts(counts, counts.shape[0] if counts.ndim else 1)
        if total:
            _, low, high = clopper_pearson(ends, total)
            text += f" [{100 * low:.1f}, {100 * high:.1f}] (95 %, of {total:,} first contacts)"
    return text


def circuit_rows(ds) -> list:
    """(label, text) of an along-track carriage result (issue 24): the fraction of first
    contacts at the ends of the loaded zone, and a ``[carriage.circuit]``'s figures; [] for
    a file without them."""
    rows = []
    if "contact_zone_end_fraction" in ds.variables:
        fraction = float(ds["contact_zone_end_fraction"])
        if np.isfinite(fraction):
            rows.append(("first contacts at the ends of the loaded zone (first or last pair)",
                         _zone_end_text(ds, fraction)))
    if "circuit_balls" in ds.variables:
        counts = ", ".join(f"{name} {int(n):,}" for name, n in zip(
            np.asarray(ds["circuit_contact_where_name"]).tolist(),
            np.asarray(ds["circuit_contact_count"]).tolist(), strict=True))
        mean = np.asarray(ds["circuit_column_force_mean"], dtype=float)
        peak = np.asarray(ds["circuit_column_force_max"], dtype=float)
        rows.append(("ball circuit", f"{int(ds['circuit_balls'])} balls, slack "
                     f"{1e3 * float(ds['circuit_slack']):g} mm, drag "
                     f"{float(ds['circuit_return_drag']):g} N per unloaded ball; contact "
                     f"events over the stroke: {counts}"))
        rows.append(("column force at the zone's entry / exit (mean over the stroke; max)",
                     f"{mean[0]:.3g} N / {mean[1]:.3g} N; {peak[0]:.3g} N / {peak[1]:.3g} N"))
        if "circuit_column_friction_mean" in ds.variables:
            rows.append(("carriage friction from the column's forces at the zone's ends "
                         "(mean over the stroke)",
                         f"{float(ds['circuit_column_friction_mean']):.3g} N"))
        rows.append(("sum of a circuit's gaps - its slack, at most",
                     f"{float(ds['circuit_slack_error_max']):.1e} m"))
    return rows


def attribute(ds, name, default="?"):
    """The global attribute ``name`` as stored, ``default`` when the file has not got it."""
    return ds.attrs.get(name, default)


def bin_edges(ds, bounds) -> np.ndarray:
    """The bin edges (bins + 1,) of a histogram from its ``(bins, 2)`` bounds variable."""
    b = np.asarray(ds[bounds], dtype=float)
    return np.concatenate([b[:, 0], b[-1:, 1]])


def quantile_index(ds, level):
    """Index of ``level`` along the file's ``quantile`` coordinate, or None."""
    levels = np.asarray(ds["quantile"], dtype=float)
    hit = np.flatnonzero(np.isclose(levels, level, rtol=0, atol=1e-12))
    return int(hit[0]) if hit.size else None


def quantile_value(ds, name, level) -> float:
    """``name`` (a variable along ``quantile``) at ``level``, NaN when the variable or the
    level is absent."""
    if name not in ds.variables:
        return float("nan")
    k = quantile_index(ds, level)
    return float(np.asarray(ds[name], dtype=float)[k]) if k is not None else float("nan")


# --------------------------------------------------------------------------------------------
# The embedded config
# --------------------------------------------------------------------------------------------
def config_of(ds):
    """The :class:`~tolsim.study.spec.StudyConfig` embedded in a result (seed of the file); of
    a sweep's point (:func:`tolsim.reports.sweep.points.point_dataset`), that point's.

    The config's warnings name the file by its title, a sweep's without the point's suffix:
    the embedded config is the whole sweep's, so a warning may be about another point.
    """
    name = ds.attrs.get("title", "result").split(": ", 1)[-1]
    point = re.search(r", point (\d+): .*$", name)
    if point:
        name = name[:point.start()]
    config = parse_config(str(ds.attrs["config"]), name)
    if point and config.sweep is not None:
        config = config.sweep.points[int(point.group(1)) - 1]
    return config.with_overrides(seed=int(ds.attrs["seed"]))


def config_or_none(ds):
    """:func:`config_of`, or None when the embedded config cannot be parsed."""
    try:
        return config_of(ds)
    except Exception:  # noqa: BLE001 - the report must not fail on an old or foreign config
        return None


def config_toml(ds) -> dict:
    """The embedded config as TOML tables ({} when it is not valid TOML)."""
    try:
        return tomllib.loads(str(ds.attrs.get("config", "")))
    except tomllib.TOMLDecodeError:
        return {}


def config_key(data, section, name):
    """``[section] key`` of the config key for quantity ``name`` (any unit suffix), or ''."""
    table = data
    for part in section.split("."):
        table = table.get(part, {}) if isinstance(table, dict) else {}
    if not isinstance(table, dict):
        return ""
    for key in table:
        if key == name or key.startswith(f"{name}_"):
            value = table[key]
            shown = value if not isinstance(value, dict | list) else None
            return f"[{section}] {key}" + (f" = {shown}" if shown is not None else "")
    return ""
