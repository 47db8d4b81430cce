"""The core of a result file: the variables and global attributes of every study (epsilon,
loads, contact, counts, spec limits, spot checks) and the code that fills them.
"""

import os
import shlex
import sys
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version

import numpy as np

from tolsim import __version__
from tolsim.io.schema.declaration import Section, V
from tolsim.physics.geometry import CONTACTS
from tolsim.physics.velocity.models import BALL_REGIMES
from tolsim.study.analyses.limit_state import EVENT_PROBABILITY
from tolsim.study.pipeline.propagation_rules import (
    fine_step_reason,
    propagation_assumption,
    propagation_caveat,
    time_steps,
)
from tolsim.study.sampling import SPOT_CHECK_STRATA
from tolsim.study.statistics.accumulator import QUANTILES

#: Value of the ``Conventions`` global attribute.
CONVENTIONS = "CF-1.10"
#: Global attribute that marks a tolsim result (``tolsim_schema``) and its version.
SCHEMA_VERSION = "2"  # 2: elapsed_time, contact_name, factor_name
#: Required global attributes (all strings except ``seed``).
GLOBAL_ATTRIBUTES = ("Conventions", "title", "source", "history", "seed", "config",
                     "tolsim_schema")
#: Provenance global attributes written since issue 17 (optional: older files lack them).
#: ``config`` is the effective config (overrides included: ``tolsim run`` on it reproduces
#: every data variable); these pin the software and the measured data.
PROVENANCE_ATTRIBUTES = {
    "tolsim_version": "version of tolsim that wrote the file",
    "python_version": "Python version",
    "numpy_version": "NumPy version (random streams: PCG64 and SeedSequence)",
    "scipy_version": "SciPy version (special functions, quasi-random designs)",
    "numba_version": "Numba version (compiled kernels)",
    "data_files": "measured-data files of empirical distributions, one line each: "
                  "'<sha256>  <path relative to the config file>' (sha256sum format); "
                  "only when the config uses some",
}

_Q = ("quantile",)
_SC = ("spot_check",)

#: The coordinates of every result file (the sections add theirs).
CORE_COORDINATES = {
    "quantile": V(_Q, "1", "quantile level"),
    "velocity_deviation_bin": V(("velocity_deviation_bin",), "1",
                                "centre of a velocity deviation histogram bin"),
    "velocity_deviation_bin_bounds": V(("velocity_deviation_bin", "bounds"), "1",
                                       "edges of a velocity deviation histogram bin"),
    "elapsed_time": V(("elapsed_time",), "s", "time since the start of the stroke"),
    "time_bin": V(("time_bin",), "s", "centre of a time-to-contact histogram bin"),
    "time_bin_bounds": V(("time_bin", "bounds"), "s", "edges of a time-to-contact histogram bin"),
    "ball": V(("ball",), "1", "ball position in the train (0 = trailing end)", "i"),
    "pair": V(("pair",), "1", "adjacent ball pair, named by its trailing ball", "i"),
    "spot_check": V(_SC, "1", "spot check number", "i"),
    "contact": V(("contact",), "1", "contact index (names in contact_name)", "i"),
    "contact_name": V(("contact",), "1", "contact (BL, BR, TR, TL)", "U"),
    "factor": V(("factor",), "1", "tolerance source index (names in factor_name)", "i",
                required=False),
    "factor_name": V(("factor",), "1", "tolerance source", "U", required=False),
    "ball_regime": V(("ball_regime",), "1", "regime of a ball (flag_meanings)", "i",
                     required=False),
}

#: The data variables of every result file (the sections add theirs).
CORE_VARIABLES = {
    # epsilon
    "velocity_deviation_mean": V((), "1", "mean ball velocity deviation epsilon over valid balls"),
    "velocity_deviation_std": V((), "1", "standard deviation of epsilon over valid balls"),
    "velocity_deviation_min": V((), "1", "smallest epsilon of a valid ball"),
    "velocity_deviation_max": V((), "1", "largest epsilon of a valid ball"),
    "velocity_deviation_quantile": V(_Q, "1", "quantile of epsilon (from the histogram; NaN "
                                     "where it lies below or above the histogram's range, "
                                     "velocity_deviation_underflow and _overflow)"),
    "velocity_deviation_histogram": V(("velocity_deviation_bin",), "1",
                                      "number of valid balls per epsilon bin", "i"),
    "velocity_deviation_underflow": V((), "1", "valid balls below the histogram range", "i"),
    "velocity_deviation_overflow": V((), "1", "valid balls above the histogram range", "i"),
    "velocity_deviation_mean_by_ball": V(("ball",), "1", "mean epsilon per train position",
                                         track_axis=0),
    "velocity_deviation_std_by_ball": V(("ball",), "1",
                                        "standard deviation of epsilon per train position",
                                        track_axis=0),
    # loads (a study with a carriage: of its nominal assembly, per track)
    "normal_load": V(("ball",), "N", "load N_y pressing the top groove down, per ball",
                     track_axis=0),
    "side_load": V(("ball",), "N", "lateral load N_x on the top groove, per ball",
                   track_axis=0),
    "side_force_ratio": V(("ball",), "1", "side force ratio rho = N_x / N_y per ball",
                          track_axis=0),
    # contact
    "contact_probability": V((), "1",
                             "probability of ball-to-ball contact within the horizon per "
                             "train, over the trains whose outcome is known"),
    "contact_probability_ci_lower": V((), "1",
                                      "lower end of the 95 % Clopper-Pearson interval"),
    "contact_probability_ci_upper": V((), "1",
                                      "upper end of the 95 % Clopper-Pearson interval"),
    "contact_probability_bound_lower": V((), "1", "lower partial-identification bound of the "
                                         "contact probability: unresolved trains without "
                                         "contact"),
    "contact_probability_bound_upper": V((), "1", "upper partial-identification bound of the "
                                         "contact probability: unresolved trains with "
                                         "contact"),
    "contact_probability_bounds_ci_lower": V((), "1", "lower end of the 95 % Clopper-Pearson "
                                             "interval of the lower bound"),
    "contact_probability_bounds_ci_upper": V((), "1", "upper end of the 95 % Clopper-Pearson "
                                             "interval of the upper bound"),
    "time_to_contact_quantile": V(_Q, "s", "quantile of the time to first contact, given "
                                           "contact within the horizon"),
    "travel_to_contact_quantile": V(_Q, "m", "quantile of the carriage travel to first "
                                             "contact, given contact within the horizon"),
    "time_to_contact_min": V((), "s", "earliest first contact"),
    "time_to_contact_max": V((), "s", "latest first contact within the horizon"),
    "time_to_contact_histogram": V(("time_bin",), "1",
                                   "number of trains per time-to-first-contact bin", "i"),
    "survival_probability": V(("elapsed_time",), "1", "probability of no contact by time t"),
    "contact_pair_count": V(("pair",), "1", "first contacts per adjacent pair", "i",
                            track_axis=0),
    "horizon": V((), "s", "duration of the stroke considered"),
    "groove_velocity": V((), "m s-1", "velocity v of the top groove (carriage)"),
    # counts
    "n_assemblies": V((), "1", "number of assemblies (trains) sampled", "i"),
    "n_assemblies_valid": V((), "1", "trains whose balls are all resolved: the population of "
                                     "the time-to-contact statistics and the survival curve",
                            "i"),
    "n_assemblies_unresolved": V((), "1", "trains with an unresolved ball and no certain "
                                          "contact", "i"),
    "n_assemblies_contact_untimed": V((), "1", "trains with an unresolved ball and a contact "
                                               "that is certain without it: in n_contact and "
                                               "the known outcomes, not in the time "
                                               "statistics; n_assemblies = n_assemblies_valid + "
                                               "this + n_assemblies_unresolved", "i",
                                      required=False),
    "n_contact": V((), "1", "trains with a contact within the horizon", "i"),
    "n_velocity_deviation_exceedance": V((), "1", "assemblies with a resolved ball with "
                                                  "|epsilon| above its limit (0 without a "
                                                  "limit)", "i", required=False),
    "n_assemblies_velocity_deviation_unresolved": V((), "1", "assemblies without a resolved "
                                                             "ball with |epsilon| above its "
                                                             "limit and with an unresolved "
                                                             "ball (an unloaded ball is within "
                                                             "it; 0 without a limit)", "i",
                                                    required=False),
    "n_balls": V((), "1", "number of balls evaluated", "i"),
    "n_balls_valid": V((), "1", "balls with a resolved epsilon (fast or full model)", "i"),
    "n_balls_not_converged": V((), "1", "balls whose static solution did not converge", "i"),
    "n_balls_loss_of_contact": V((), "1", "balls the static model left without balance (a "
                                          "contact in tension, or one loaded contact)", "i"),
    "n_balls_outside_validity": V((), "1", "balls sent to the full model: outside the fast "
                                           "velocity model's validity limits, or with two or "
                                           "three loaded contacts", "i"),
    "n_balls_resolved_full": V((), "1", "balls solved with the full friction model", "i"),
    "n_balls_full_failed": V((), "1", "balls sent to the full model that it could not "
                                      "solve", "i"),
    "n_balls_unloaded": V((), "1", "balls without a loaded contact: no epsilon of their own, "
                                   "pushed along by their neighbours", "i", required=False),
    "n_balls_static_fallback": V((), "1", "balls the study's static model left without "
                                          "balance (a contact in tension, one loaded contact, "
                                          "or not converged) and the 'solved' model answered "
                                          "instead, each once: at the start of the stroke or, "
                                          "along the track, at any evaluation", "i",
                                 required=False),
    "n_balls_unresolved_along_track": V((), "1", "balls resolved at the start of the stroke "
                                                 "but unresolved at an evaluation along the "
                                                 "track (along_track propagation; with a "
                                                 "carriage before the first contact), each "
                                                 "once; the other ball counts are of the "
                                                 "balls at the start", "i", required=False),
    "n_balls_regime": V(("ball_regime",), "1", "number of balls in each regime", "i",
                        required=False),
    # per-assembly totals (tolsim.study.statistics.intervals.CLUSTER_COLUMNS): the assembly as the
    # sampling unit of ball-level proportions and Cpk
    "assembly_count": V((), "1", "number of assemblies behind the per-assembly moments", "i"),
    "assembly_total_mean": V(("assembly_total",), "1",
                             "mean over assemblies of the per-assembly totals: valid balls, "
                             "balls with |epsilon| above the limit, sum of epsilon, sum of "
                             "epsilon squared"),
    "assembly_total_comoment": V(("assembly_total", "assembly_total_b"), "1",
                                 "sum over assemblies of the products of the deviations of "
                                 "the per-assembly totals from their means"),
    # spec limits (NaN: none)
    "velocity_deviation_limit": V((), "1", "specification limit on |epsilon|"),
    "contact_probability_limit": V((), "1", "specification limit on the contact probability"),
    "velocity_deviation_out_of_spec_limit": V((), "1", "allowed fraction of balls with "
                                              "|epsilon| above its limit", required=False),
    "velocity_deviation_cpk_minimum": V((), "1", "required minimum Cpk of epsilon",
                                        required=False),
    # spot checks
    "spot_check_ball_index": V(_SC, "1", "global index of the spot-checked ball "
                                         "(assembly * balls + ball)", "i"),
    "spot_check_contact_angle_deviation": V(_SC + ("contact",), "rad",
                                            "loaded contact angle deviation of the ball"),
    "spot_check_normal_force": V(_SC + ("contact",), "N", "contact force of the ball"),
    "spot_check_velocity_deviation_analytic": V(_SC, "1", "epsilon from the study's model"),
    "spot_check_velocity_deviation_full": V(_SC, "1", "epsilon from the full friction model"),
    "spot_check_valid_analytic": V(_SC, "1", "1 if the study's model is valid for the ball",
                                   "i"),
    "spot_check_valid_full": V(_SC, "1", "1 if the full model converged and is valid", "i"),
    "spot_check_n_valid": V((), "1", "spot checks valid in both models", "i"),
    # stratified spot checks (tolsim.study.sampling.SpotCheckPlan); optional: older files
    "spot_check_stratum": V(_SC, "1", "stratum of the spot check (flag_meanings)", "i",
                            required=False),
    "spot_check_band_lower": V((), "1", "lower end of the |epsilon| band of the near-limit "
                                        "spot checks", required=False),
    "spot_check_band_upper": V((), "1", "upper end of the |epsilon| band of the near-limit "
                                        "spot checks", required=False),
    "spot_check_band_balls": V((), "1", "balls of the fast model with |epsilon| in the "
                                        "near-limit band", "i", required=False),
    "spot_check_rms_difference": V((), "1", "RMS of epsilon analytic - full over valid checks"),
    "spot_check_max_abs_difference": V((), "1", "largest |epsilon analytic - full|"),
}

#: The probability variables of the plain run (contact, friction exceedance): each carries the
#: attribute ``estimator`` (``monte_carlo`` unless a rare-event estimator made it, issue 15).
PLAIN_PROBABILITY_VARIABLES = tuple(
    f"{prefix}{suffix}" for prefix in (EVENT_PROBABILITY["contact"],
                                       EVENT_PROBABILITY["friction_exceedance"])
    for suffix in ("", "_ci_lower", "_ci_upper", "_bound_lower", "_bound_upper",
                   "_bounds_ci_lower", "_bounds_ci_upper"))


def plain_probability_attributes(name) -> dict:
    """The labels of a probability variable of the plain run (``name``: the probability, an
    end of its interval, a bound or an end of the bounds' interval): ``estimator``
    ``monte_carlo``, and ``interval`` Clopper-Pearson on the probability and its interval."""
    interval = name.endswith(("probability", "_ci_lower", "_ci_upper")) and "bounds" not in name
    return {"estimator": "monte_carlo", **({"interval": "Clopper-Pearson"} if interval else {})}


def _nan_if_zero(value):
    return float(value) if value else float("nan")


def provenance_attributes(config) -> dict:
    """Global attributes that pin down how to rerun: package versions (``*_version``) and,
    for measured data, ``data_files`` (lines ``<sha256>  <path>`` as ``sha256sum`` writes
    them, paths relative to the config file: ``sha256sum -c`` there checks them)."""
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


def collect(result, history=None) -> tuple:
    """(coordinates, data variables, global attributes) of every study result (the core of
    :func:`tolsim.io.netcdf.result_to_dataset`).

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
    carriage = cfg.has_carriage
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
        "n_assemblies_contact_untimed": acc.n_contact_untimed,
        "n_contact": acc.n_contact,
        "n_velocity_deviation_exceedance": acc.n_exceedance,
        "n_assemblies_velocity_deviation_unresolved": acc.n_exceedance_unresolved,
        "n_balls": acc.n_balls,
        "n_balls_valid": acc.n_balls_valid,
        "n_balls_not_converged": acc.n_not_converged,
        "n_balls_loss_of_contact": acc.n_loss_of_contact,
        "n_balls_outside_validity": acc.n_outside_validity,
        "n_balls_resolved_full": acc.n_resolved_full,
        "n_balls_full_failed": acc.n_full_failed,
        "n_balls_unloaded": acc.n_unloaded,
        "n_balls_static_fallback": acc.n_static_fallback,
        "n_balls_unresolved_along_track": acc.n_unresolved_along_track,
        "n_balls_regime": (("ball_regime",), acc.regime_count),
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
        "ball_regime": (("ball_regime",), np.array(list(BALL_REGIMES), dtype=np.int8)),
    }
    attrs = {
        "Conventions": CONVENTIONS,
        "title": f"tolsim Monte Carlo tolerance study: {os.path.basename(cfg.path)}",
        "source": f"tolsim {__version__}",
        "history": history_line(history),
        "seed": int(st.seed),
        "config": cfg.text,
        "tolsim_schema": SCHEMA_VERSION,
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
        "propagation_assumption": propagation_assumption(
            st.propagation, time_steps(cfg) if cfg.is_along_track else None,
            automatic=st.time_steps is None,
            reason=fine_step_reason(cfg) if cfg.is_along_track else ""),
        "propagation_caveat": propagation_caveat(cfg),
        "elapsed_seconds": float(result.elapsed),
        # Numba compilation (a cold kernel cache) and kernel-cache loading in the run, not part
        # of the times above;
        # the throughput of the work done in this process (after a resume, only that)
        "compile_seconds": float(getattr(result, "compile_seconds", 0.0)),
        "balls_per_second": float(getattr(result, "balls_per_second", float("nan"))),
        "workers": int(result.workers),
    }
    attrs.update(provenance_attributes(cfg))
    return coords, data, attrs


def assign(result, ds):
    """The stopping rule of a run with a precision target (global attributes)."""
    if getattr(result, "target", None) is not None:  # tolsim run --target-ci-width
        ds.attrs.update(stopping_rule=result.stopping_rule, target_ci_width=str(result.target),
                        samples_maximum=int(result.samples_maximum))
    return ds


def finish(result, ds) -> None:
    """Which estimator made each probability (``monte_carlo`` where no rare-event estimator
    set its own, :mod:`tolsim.io.schema.rare_events`) and the CF 3.5 flags of the spot
    checks' strata."""
    for name in PLAIN_PROBABILITY_VARIABLES:  # which estimator made each number
        if name in ds and "estimator" not in ds[name].attrs:
            ds[name].attrs.update(plain_probability_attributes(name))
    ds["spot_check_stratum"].attrs.update(  # CF 3.5 flags
        flag_values=np.arange(len(SPOT_CHECK_STRATA), dtype=np.int8),
        flag_meanings=" ".join(SPOT_CHECK_STRATA))
    if "ball_regime" in ds.coords:
        ds["ball_regime"].attrs.update(flag_values=np.array(list(BALL_REGIMES), dtype=np.int8),
                                       flag_meanings=" ".join(BALL_REGIMES.values()))


SECTION = Section(collect=collect, assign=assign, finish=finish)
