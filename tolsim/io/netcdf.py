"""Study results to and from netCDF (via xarray), following :mod:`tolsim.io.schema`.

:func:`write_result` builds the Dataset, validates it against the schema and writes it to a
temporary file in the output folder, then renames it over the target (:func:`os.replace`,
atomic on POSIX), so a crash never leaves a truncated result. :func:`read_result` opens a file
and checks that it is a tolsim result.
"""

import os
import shlex
import sys
import tempfile
from datetime import UTC, datetime

import numpy as np
import xarray as xr

from tolsim import __version__
from tolsim.io import schema
from tolsim.physics.geometry import CONTACTS
from tolsim.study.analyses.limit_state import EVENT_PROBABILITY, rare_event_variables
from tolsim.study.analyses.sensitivity import sensitivity_variables
from tolsim.study.analyses.worst_case import stackup_variables
from tolsim.study.execution import saved_samples
from tolsim.study.pipeline.carriage import carriage_variables
from tolsim.study.pipeline.propagation import propagation_assumption, propagation_caveat
from tolsim.study.pipeline.track_friction import friction_variables
from tolsim.study.sampling import SPOT_CHECK_STRATA
from tolsim.study.statistics.accumulator import QUANTILES
from tolsim.study.statistics.quality import dataset_quality

#: The probability variables of the plain run (contact, friction exceedance): each carries the
#: attribute ``estimator`` (``monte_carlo`` unless a rare-event estimator made it, issue 15).
PLAIN_PROBABILITY_VARIABLES = tuple(
    f"{prefix}{suffix}" for prefix in (EVENT_PROBABILITY["contact"],
                                       EVENT_PROBABILITY["friction_exceedance"])
    for suffix in ("", "_ci_lower", "_ci_upper", "_bound_lower", "_bound_upper",
                   "_bounds_ci_lower", "_bounds_ci_upper"))


def _nan_if_zero(value):
    return float(value) if value else float("nan")


def provenance_attributes(config) -> dict:
    """Global attributes that pin down how to rerun: package versions (``*_version``) and,
    for measured data, ``data_files`` (lines ``<sha256>  <path>`` as ``sha256sum`` writes
    them, paths relative to the config file: ``sha256sum -c`` there checks them)."""
    from importlib.metadata import PackageNotFoundError, version

    out = {"tolsim_version": __version__, "python_version": sys.version.split()[0]}
    for package in ("numpy", "scipy", "numba"):
        try:
            out[f"{package}_version"] = version(package)
        except PackageNotFoundError:
            out[f"{package}_version"] = "not installed"
    files = config.data_files
    if files:
        out["data_files"] = "\n".join(f"{sha}  {path}" for path, sha in files.items())
    return out


def history_line(history: str | None = None) -> str:
    """The ``history`` attribute: a UTC time stamp and the command (default: this process's
    argv)."""
    if history is None:
        history = " ".join(shlex.quote(a) for a in [os.path.basename(sys.argv[0])] + sys.argv[1:])
    return f"{datetime.now(UTC).strftime('%Y-%m-%dT%H:%M:%SZ')} {history}"


def result_to_dataset(result, *, history: str | None = None) -> xr.Dataset:
    """The Dataset of a :class:`tolsim.study.execution.runner.StudyResult` (validated).

    Parameters
    ----------
    result : StudyResult
    history : str, optional
        Command line to record (default: this process's argv).
    """
    cfg = result.config
    acc = result.statistics
    st = cfg.study
    levels = np.asarray(QUANTILES)
    p, lo, hi = acc.contact_probability()
    bounds = acc.contact_probability_bounds()
    t_q = acc.time_to_contact_quantiles(levels)
    n_ball = acc.ball_count
    with np.errstate(invalid="ignore", divide="ignore"):
        ball_std = np.where(n_ball > 1, np.sqrt(acc.ball_m2 / np.maximum(n_ball - 1, 1)),
                            np.nan)
        ball_mean = np.where(n_ball > 0, acc.ball_mean, np.nan)
    eps_edges, time_edges = acc.eps_edges, acc.time_edges
    sc = result.spot_checks
    both = sc.valid_analytic & sc.valid_full
    diff = sc.velocity_deviation_analytic[both] - sc.velocity_deviation_full[both]
    balls = cfg.train.balls  # per track
    tracks = cfg.n_tracks
    carriage = cfg.carriage is not None
    ball_dims = ("track", "ball") if carriage else ("ball",)
    pair_dims = ("track", "pair") if carriage else ("pair",)

    def by_ball(values):
        return (ball_dims, np.asarray(values).reshape((tracks, balls) if carriage else -1))

    pairs = acc.pair_count[: tracks * max(balls - 1, 0)]
    if carriage:
        nominal = getattr(result, "carriage_nominal", None)
        if nominal is not None:
            sol = nominal.solution
            loads = (sol.normal_load, sol.side_load, sol.side_force_ratio)
        else:
            loads = (np.full((tracks, balls), np.nan),) * 3
    else:
        loads = (np.asarray(cfg.loads.normal_load), np.asarray(cfg.loads.side_load),
                 cfg.loads.side_force_ratio)
    data = {
        "velocity_deviation_mean": acc.velocity_deviation_mean,
        "velocity_deviation_std": acc.velocity_deviation_std,
        "velocity_deviation_min": acc.eps_min if acc.n_balls_valid else np.nan,
        "velocity_deviation_max": acc.eps_max if acc.n_balls_valid else np.nan,
        "velocity_deviation_quantile": (("quantile",), acc.velocity_deviation_quantiles(levels)),
        "velocity_deviation_histogram": (("velocity_deviation_bin",), acc.eps_histogram),
        "velocity_deviation_underflow": acc.eps_underflow,
        "velocity_deviation_overflow": acc.eps_overflow,
        "velocity_deviation_mean_by_ball": by_ball(ball_mean),
        "velocity_deviation_std_by_ball": by_ball(ball_std),
        "normal_load": by_ball(loads[0]),
        "side_load": by_ball(loads[1]),
        "side_force_ratio": by_ball(loads[2]),
        "contact_probability": p,
        "contact_probability_ci_lower": lo,
        "contact_probability_ci_upper": hi,
        "contact_probability_bound_lower": bounds[0],
        "contact_probability_bound_upper": bounds[1],
        "contact_probability_bounds_ci_lower": bounds[2],
        "contact_probability_bounds_ci_upper": bounds[3],
        "time_to_contact_quantile": (("quantile",), t_q),
        "travel_to_contact_quantile": (("quantile",), t_q * cfg.motion.groove_velocity),
        "time_to_contact_min": acc.time_min if acc.n_contact else np.nan,
        "time_to_contact_max": acc.time_max if acc.n_contact else np.nan,
        "time_to_contact_histogram": (("time_bin",), acc.time_histogram),
        "survival_probability": (("elapsed_time",), acc.survival()),
        "contact_pair_count": (pair_dims, pairs.reshape(
            (tracks, max(balls - 1, 0)) if carriage else -1)),
        "horizon": cfg.motion.duration,
        "groove_velocity": cfg.motion.groove_velocity,
        "n_assemblies": acc.n_assemblies,
        "n_assemblies_valid": acc.n_assemblies_valid,
        "n_assemblies_unresolved": acc.n_unresolved,
        "n_contact": acc.n_contact,
        "n_balls": acc.n_balls,
        "n_balls_valid": acc.n_balls_valid,
        "n_balls_not_converged": acc.n_not_converged,
        "n_balls_loss_of_contact": acc.n_loss_of_contact,
        "n_balls_outside_validity": acc.n_outside_validity,
        "n_balls_resolved_full": acc.n_resolved_full,
        "n_balls_full_failed": acc.n_full_failed,
        "assembly_count": np.int64(acc.cluster.count),
        "assembly_total_mean": (("assembly_total",), acc.cluster.mean),
        "assembly_total_comoment": (("assembly_total", "assembly_total_b"),
                                    acc.cluster.comoment),
        "velocity_deviation_limit": _nan_if_zero(st.velocity_deviation_limit),
        "contact_probability_limit": _nan_if_zero(st.contact_probability_limit),
        "velocity_deviation_out_of_spec_limit": _nan_if_zero(st.out_of_spec_limit),
        "velocity_deviation_cpk_minimum": _nan_if_zero(st.cpk_minimum),
        "spot_check_ball_index": (("spot_check",), sc.ball_index.astype(np.int64)),
        "spot_check_contact_angle_deviation": (("spot_check", "contact"),
                                               sc.contact_angle_deviation.reshape(-1, 4)),
        "spot_check_normal_force": (("spot_check", "contact"), sc.normal_force.reshape(-1, 4)),
        "spot_check_velocity_deviation_analytic": (("spot_check",),
                                                   sc.velocity_deviation_analytic),
        "spot_check_velocity_deviation_full": (("spot_check",), sc.velocity_deviation_full),
        "spot_check_valid_analytic": (("spot_check",), sc.valid_analytic.astype(np.int8)),
        "spot_check_valid_full": (("spot_check",), sc.valid_full.astype(np.int8)),
        "spot_check_n_valid": np.int64(both.sum()),
        "spot_check_stratum": (("spot_check",), np.asarray(sc.stratum, dtype=np.int8)),
        "spot_check_band_lower": float(sc.band[0]),
        "spot_check_band_upper": float(sc.band[1]),
        "spot_check_band_balls": np.int64(sc.band_balls),
        "spot_check_rms_difference": float(np.sqrt(np.mean(diff**2))) if diff.size else np.nan,
        "spot_check_max_abs_difference": float(np.max(np.abs(diff))) if diff.size else np.nan,
    }
    coords = {
        "quantile": (("quantile",), levels),
        "velocity_deviation_bin": (("velocity_deviation_bin",),
                                   0.5 * (eps_edges[:-1] + eps_edges[1:])),
        "velocity_deviation_bin_bounds": (("velocity_deviation_bin", "bounds"),
                                          np.stack([eps_edges[:-1], eps_edges[1:]], axis=1)),
        "elapsed_time": (("elapsed_time",), time_edges),
        "time_bin": (("time_bin",), 0.5 * (time_edges[:-1] + time_edges[1:])),
        "time_bin_bounds": (("time_bin", "bounds"),
                            np.stack([time_edges[:-1], time_edges[1:]], axis=1)),
        "ball": (("ball",), np.arange(balls, dtype=np.int64)),
        "pair": (("pair",), np.arange(max(balls - 1, 0), dtype=np.int64)),
        "spot_check": (("spot_check",), np.arange(len(sc.ball_index), dtype=np.int64)),
        # CF coordinate variables are numeric: an index, and the names as a label variable
        "contact": (("contact",), np.arange(len(CONTACTS), dtype=np.int64)),
        "contact_name": (("contact",), np.array(CONTACTS)),
    }
    if carriage:
        more_coords, more_data = carriage_variables(cfg, acc, getattr(result, "carriage_nominal",
                                                                      None))
        coords.update(more_coords)
        data.update(more_data)
    friction_attrs = {}
    if getattr(acc, "friction", None) is not None:  # [contact]: trains and friction (issue 13)
        more_coords, more_data, friction_attrs = friction_variables(result)
        coords.update(more_coords)
        data.update(more_data)
    ds = xr.Dataset(data, coords=coords)
    ds.attrs = {
        "Conventions": schema.CONVENTIONS,
        "title": f"tolsim Monte Carlo tolerance study: {os.path.basename(cfg.path)}",
        "source": f"tolsim {__version__}",
        "history": history_line(history),
        "seed": int(st.seed),
        "config": cfg.text,
        "tolsim_schema": schema.SCHEMA_VERSION,
        "references": "B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033",
        "samples": int(st.samples),
        "block_size": int(st.block_size),
        "velocity_model": st.velocity_model,
        "static_model": st.static_model,
        "propagation": st.propagation,
        "sampling": st.sampling,
        "spot_check_status": result.spot_checks.status,
        "velocity_deviation_quantile_resolution": float(eps_edges[1] - eps_edges[0]),
        "time_to_contact_quantile_resolution": float(time_edges[1] - time_edges[0]),
        "contact_probability_interval": (
            "Clopper-Pearson, 95 %, over the trains whose outcome is known; bounds "
            "[k/N, (k+u)/N] over all N trains with u unresolved, and the interval covering "
            "them"),
        "full_model_resolve_seconds": float(acc.resolve_seconds),
        "propagation_assumption": propagation_assumption(st.propagation),
        "propagation_caveat": propagation_caveat(cfg),
        "elapsed_seconds": float(result.elapsed),
        "workers": int(result.workers),
    }
    ds.attrs.update(provenance_attributes(cfg))
    ds.attrs.update(friction_attrs)
    if getattr(result, "target", None) is not None:  # tolsim run --target-ci-width
        ds.attrs.update(stopping_rule=result.stopping_rule, target_ci_width=str(result.target),
                        samples_maximum=int(result.samples_maximum))
    if result.sensitivity is not None:
        variables = sensitivity_variables(result.sensitivity)
        names = variables.pop("factor")
        ds = ds.assign_coords(factor=("factor", np.arange(len(names), dtype=np.int64)),
                              factor_name=("factor", names))
        ds = ds.assign({name: (("factor",), values) for name, values in variables.items()})
        ds.attrs["sensitivity_samples"] = int(st.sensitivity_samples)
    rare_attrs = {}
    if getattr(result, "rare_events", None):  # a rare-event estimator (issue 15)
        factors, rare_data, rare_attrs, rare_globals = rare_event_variables(result)
        if factors is not None and "factor" not in ds.coords:
            ds = ds.assign_coords(factor=("factor", np.arange(len(factors), dtype=np.int64)),
                                  factor_name=("factor", np.array(factors, dtype=str)))
        ds = ds.assign(rare_data)
        ds.attrs.update(rare_globals)
    if getattr(result, "stackup", None) is not None:  # worst case and RSS
        ds = ds.assign(stackup_variables(result.stackup))
    if getattr(result, "samples", None):  # the saved assemblies, along ``sample``
        rows = saved_samples.dataset_variables(cfg, result.samples)
        ds = ds.assign_coords(sample=rows.pop("sample")).assign(rows)
    quality = {k: v for k, v in dataset_quality(ds).items() if not k.startswith("_")}
    ds = ds.assign({name: float(value) for name, value in quality.items()})
    schema.apply_attributes(ds)
    for name in PLAIN_PROBABILITY_VARIABLES:  # which estimator made each number
        if name in ds:
            ds[name].attrs.update(rare_attrs.get(name, {"estimator": "monte_carlo"}))
            if name.endswith(("probability", "_ci_lower", "_ci_upper")) and \
                    "bounds" not in name and name not in rare_attrs:
                ds[name].attrs["interval"] = "Clopper-Pearson"
    for name, attrs in rare_attrs.items():
        ds[name].attrs.update(attrs)
    if "sample_model" in ds:
        ds["sample_model"].attrs.update(saved_samples.flag_attributes())  # CF 3.5 flags
    ds["spot_check_stratum"].attrs.update(  # CF 3.5 flags
        flag_values=np.arange(len(SPOT_CHECK_STRATA), dtype=np.int8),
        flag_meanings=" ".join(SPOT_CHECK_STRATA))
    return schema.validate(ds)


def write_dataset(ds: xr.Dataset, path) -> None:
    """Validate ``ds`` and write it to ``path`` through a temporary file and a rename.

    Coordinates are written without ``_FillValue`` (CF 2.5.1; xarray adds one to every float
    variable by default): they never hold missing values.
    """
    schema.validate(ds)
    ds = ds.copy(deep=False)  # shallow: the encodings below do not touch the caller's Dataset
    for name in ds.coords:
        ds.variables[name].encoding["_FillValue"] = None
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp",
                               dir=folder)
    os.close(fd)
    try:
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual file mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_result(result, path, *, history: str | None = None) -> xr.Dataset:
    """Write a study result to netCDF (atomic); return the Dataset written."""
    ds = result_to_dataset(result, history=history)
    write_dataset(ds, path)
    return ds


def read_result(path) -> xr.Dataset:
    """Open a tolsim result file (loaded into memory) and check it against the schema.

    Raises
    ------
    ValueError
        If the file cannot be opened or is not a tolsim study result.
    """
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot open as netCDF: {exc}") from None
    if "tolsim_schema" not in ds.attrs:
        raise ValueError(f"{path}: not a tolsim study result (no tolsim_schema attribute)")
    try:
        schema.validate(ds)
    except schema.SchemaError as exc:
        raise ValueError(f"{path}: not a valid tolsim study result: {exc}") from None
    return ds
