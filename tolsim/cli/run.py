"""``tolsim run``: a Monte Carlo tolerance study from a TOML config to a netCDF result.

A thin layer over :func:`tolsim.io.config.load_config`,
:func:`tolsim.study.execution.runner.run_study`
and :func:`tolsim.io.netcdf.write_result`.
"""

import argparse
import math
import os
import shlex
import sys
import tempfile
from pathlib import Path

from tolsim.cli import UsageError, integer_at_least, path_argument
from tolsim.study.spec import MAX_SEED, MAX_WORKERS

DESCRIPTION = """\
Run a Monte Carlo tolerance study: sample assemblies (tolerances, gaps), solve each ball's
contact state and velocity deviation epsilon, propagate the balls of each track and record
ball-to-ball contact. Writes a netCDF file (CF-1.10) with the statistics, the config and the
seed, and prints a short summary.

Without CONFIG the packaged default study runs. The output's folder is checked before any
work starts. The first run on a machine (or after an update of tolsim) compiles the kernels
for a few tens of seconds, and says so; later runs load them from Numba's cache.

Stopping and resuming: progress is saved next to the output in OUT.partial, every 30 s
(--checkpoint-interval) and when you press Ctrl-C. Rerunning the same command resumes from
it (and says from where), with a result bit-identical to an uninterrupted run. A checkpoint
of another study (other config, seed or --samples) is refused and kept: --fresh discards it.

Precision target: with --target-ci-width the run stops at the first block of assemblies at
which the 95 % interval of P(contact) is that narrow, and --samples (or study.samples) is
the maximum. The file records the number of assemblies actually run: a fixed run of that
many gives the same result.

On a cluster: --scheduler runs the chunks of random blocks as tasks on dask.distributed
(pip install "tolsim[dask]", on the workers too): a running scheduler (tcp://HOST:8786 or
its scheduler file), or local:N for N worker processes on this machine. The result is
bit-identical to the run in this process; a worker lost mid-run costs only the tasks dask
reruns, and stopping and resuming work as above. The dashboard's address is printed.

What-if sweeps: a config with a [sweep] section (configs/sweep_yaw_moment.toml) runs the
study at every point, all with the same seed (common random numbers: the same assemblies at
every point, so curves are smooth and differences between points carry little noise), and
writes one file whose variables gain a dimension per swept key:
ds.contact_probability.plot() draws the curve. Stopping and resuming work per point: finished
points are kept in OUT.sweep/ until the file is written. --samples and --seed apply to every
point.

examples:
  tolsim run                                   # the packaged default study
  tolsim run configs/paper_case_study.toml -o case.nc
  tolsim run study.toml --samples 1000000 --seed 7 -o seed7.nc
  tolsim run study.toml --samples 10000000 --target-ci-width 0.002   # P(contact) +- 0.001
  tolsim run study.toml --samples 10000000 --target-ci-width 10%     # width 10 % of P
  tolsim run study.toml --samples 100000000 --scheduler tcp://head-node:8786
  tolsim run configs/sweep_yaw_moment.toml -o yaw.nc          # 7 yaw moments, one file
"""


_positive_int = integer_at_least(1, "a positive integer")
_seed = integer_at_least(0, f"an integer from 0 to {MAX_SEED}", maximum=MAX_SEED)
_count = integer_at_least(0, "a non-negative integer")
_workers = integer_at_least(1, f"a number of processes from 1 to {MAX_WORKERS}",
                            maximum=MAX_WORKERS)


def _seconds(text):
    """An argparse ``type``: a number of seconds >= 0."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (0 <= value < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a number of seconds >= 0, got {text!r}")
    return value


def _target(text):
    """An argparse ``type``: a :class:`tolsim.study.execution.runner.PrecisionTarget` (``0.005`` or
    ``10%``); imported only when the flag is given."""
    from tolsim.study.execution.runner import PrecisionTarget  # noqa: PLC0415

    try:
        return PrecisionTarget.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser(
        "run", help="Monte Carlo tolerance study from a TOML config to a netCDF result",
        description=DESCRIPTION, formatter_class=formatter_class)
    p.add_argument("config", type=path_argument, nargs="?", metavar="CONFIG",
                   help="study config (TOML); default: the packaged default study")
    p.add_argument("-o", "--output", type=path_argument, metavar="OUT.nc",
                   help="result file (default: CONFIG's name with .nc, or tolsim-result.nc for the "
                        "default study, in the current folder)")
    p.add_argument("--samples", type=_positive_int, metavar="N",
                   help="number of assemblies (overrides study.samples); the maximum with "
                        "--target-ci-width")
    p.add_argument("--seed", type=_seed, metavar="S", help="random seed (overrides study.seed)")
    p.add_argument("--workers", type=_workers, default=1, metavar="N",
                   help="worker processes, sharing the cores (the result does not depend on "
                        "it). 1 is fastest on a few cores: the compiled kernels already run on "
                        "every core and the next chunk is drawn meanwhile; each extra process "
                        "costs 1-2 s to start and pays off only for long runs on many cores. "
                        "Not with --scheduler, whose workers do the work")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the tasks on dask.distributed (needs pip install "
                        "\"tolsim[dask]\"): tcp://HOST:8786 for a running scheduler ('dask "
                        "scheduler' on the head node, 'dask worker tcp://HOST:8786' on each "
                        "machine), the path of a scheduler file (dask scheduler "
                        "--scheduler-file FILE), or local:N to start a LocalCluster of N "
                        "worker processes here (local: one per core). Same result as without "
                        "it; for small studies the process alone is faster")
    p.add_argument("--chunk-blocks", type=_positive_int, metavar="N",
                   help="random blocks evaluated together (default: ~260k balls per chunk)")
    p.add_argument("--target-ci-width", type=_target, metavar="W",
                   help="stop once the 95 %% interval of P(contact) (the one that covers its "
                        "bounds when some trains are unresolved) is at most W wide: a width "
                        "such as 0.005, or a share of the estimate such as 10%%. Checked after "
                        "each block of study.block_size assemblies, in order; --samples is "
                        "then the maximum. Zero contacts never meet a relative target")
    p.add_argument("--checkpoint-interval", type=_seconds, default=30.0, metavar="SECONDS",
                   help="save the progress to OUT.partial at most every SECONDS seconds (0: "
                        "after every chunk); Ctrl-C saves it too. Default: 30")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--resume", action="store_true",
                       help="require a matching checkpoint OUT.partial and continue from it")
    group.add_argument("--fresh", action="store_true",
                       help="ignore and delete a checkpoint OUT.partial")
    p.add_argument("--save-samples", type=_count, default=0, metavar="N",
                   help="also store the first N assemblies' inputs and outputs (tolerance "
                        "values, gaps, contact angles and forces, epsilon per ball, first "
                        "contact) along a 'sample' dimension of the result file")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar, messages or summary (errors are still shown)")
    return p


#: Share of unresolved trains above which the summary warns.
UNRESOLVED_WARNING = 1e-3


def _strata_text(ds) -> str:
    """'; near the limit: RMS .., max ..' when some spot checks were drawn near the limit."""
    if "spot_check_stratum" not in ds:
        return ""
    import numpy as np  # noqa: PLC0415

    near = np.asarray(ds.spot_check_stratum) == 1
    both = (np.asarray(ds.spot_check_valid_analytic, dtype=bool)
            & np.asarray(ds.spot_check_valid_full, dtype=bool))
    diff = (np.asarray(ds.spot_check_velocity_deviation_analytic)
            - np.asarray(ds.spot_check_velocity_deviation_full))
    parts = []
    for name, sel in (("uniform", ~near & both), ("near the limit", near & both)):
        if sel.any() and near.any():
            d = diff[sel]
            parts.append(f"{name} {sel.sum()}: RMS {100 * np.sqrt(np.mean(d * d)):.4f} %, "
                         f"max {100 * np.max(np.abs(d)):.4f} %")
    return ("; " + "; ".join(parts)) if parts else ""


def _circuit_text(ds) -> list:
    """The along-track carriage's lines: where first contacts happen, and the circuit's
    figures (issue 24)."""
    from tolsim.reports.result_view import circuit_rows  # noqa: PLC0415

    return [f"{label}: {text}" for label, text in circuit_rows(ds)]


def _carriage_text(ds) -> str:
    """One line on the carriage of a study with one: preload, displacement, stiffness."""
    t = ds.carriage_translation_nominal.values
    k = ds.carriage_translational_stiffness_nominal.values
    k_mean = ds.carriage_translational_stiffness_mean.values
    line = (f"carriage: preload {1e6 * float(ds.preload_oversize):.3g} um oversize "
            f"({float(ds.preload_contact_force):.3g} N per contact); nominal u_x "
            f"{1e6 * t[0]:+.3f} um, u_y {1e6 * t[1]:+.3f} um; stiffness k_xx "
            f"{1e-6 * k[0]:.4g}, k_yy {1e-6 * k[1]:.4g} N/um (nominal), "
            f"{1e-6 * k_mean[0]:.4g}, {1e-6 * k_mean[1]:.4g} N/um (mean over assemblies)")
    failed = int(ds.n_assemblies_carriage_failed)
    if failed:
        line += f"; {failed} carriages not solved (their trains are unresolved)"
    return line


def _pct(x):
    return f"{100 * x:+.3f} %"


def _epsilon_line(ds, q01, q99) -> str:
    """Mean, std, 1-99 % quantiles and range of epsilon; or why there is none: a study whose
    balls are all unloaded (a carriage with clearance and no load) has no epsilon to give."""
    if int(ds.n_balls_valid) == 0:
        n_unloaded = int(ds.n_balls_unloaded) if "n_balls_unloaded" in ds else 0
        why = (f"all {n_unloaded:,} balls unloaded (no loaded contact: no velocity of "
               "their own)" if n_unloaded == int(ds.n_balls)
               else f"{n_unloaded:,} of {int(ds.n_balls):,} balls unloaded, the others "
               "unresolved (below)")
        return f"epsilon: no ball with an epsilon: {why}"
    return (f"epsilon: mean {_pct(float(ds.velocity_deviation_mean))}, "
            f"std {100 * float(ds.velocity_deviation_std):.3f} %, "
            f"1-99 % {_quantile_text(ds, q01, 0)} .. {_quantile_text(ds, q99, 1)}, "
            f"range {_pct(float(ds.velocity_deviation_min))} .. "
            f"{_pct(float(ds.velocity_deviation_max))}")


def _histogram_range(ds):
    """The lower and upper edge of the epsilon histogram [-]."""
    bounds = ds["velocity_deviation_bin_bounds"]
    return float(bounds[0, 0]), float(bounds[-1, 1])


def _quantile_text(ds, value, side) -> str:
    """A quantile of epsilon; one outside the histogram's range (NaN in the file) as the bound
    the histogram gives, e.g. "< -2.000 %" (side 0: lower tail, 1: upper tail)."""
    if math.isfinite(value):
        return _pct(value)
    tail = int(ds["velocity_deviation_overflow" if side else "velocity_deviation_underflow"])
    if tail:
        return ("> " if side else "< ") + _pct(_histogram_range(ds)[side])
    return _pct(value)


def _outside_histogram_line(ds) -> str:
    """Why a quantile of epsilon is missing: valid balls beyond the histogram's range."""
    under = int(ds["velocity_deviation_underflow"])
    over = int(ds["velocity_deviation_overflow"])
    if not under + over:
        return ""
    lo, hi = _histogram_range(ds)
    valid = under + over + int(ds["velocity_deviation_histogram"].sum())
    return (f"  {under + over} of {valid} valid balls ({under} below, {over} above) outside "
            f"the epsilon histogram's range {100 * lo:+.3g} .. {100 * hi:+.3g} %: the quantiles "
            "there are not known (NaN in the file); widen "
            "study.velocity_deviation_range_percent to cover "
            f"{_pct(float(ds.velocity_deviation_min))} .. "
            f"{_pct(float(ds.velocity_deviation_max))}")


def _probability(x) -> str:
    """A probability with 3 significant digits, and as many more as keep a value just below
    1 from reading as 1 (0.99992, not 1)."""
    if not (math.isfinite(x) and 0.5 < x < 1):
        return f"{x:.3g}"
    return f"{x:.{min(12, 3 - math.floor(math.log10(1 - x)))}g}"


def _plain_run_line(k, known, trains, events="contacts") -> str:
    """The plain run's count beside a rare-event estimate: k ``events`` of the trains (or
    assemblies) whose outcome is known, its Clopper-Pearson interval, and whether the event is
    rare at all (>= 25 events: the plain estimate has a CV of at most 0.2, the 25 / P rule of
    :mod:`tolsim.study.analyses.rare_events`, and no rare-event estimator is needed)."""
    from tolsim.study.statistics.intervals import clopper_pearson_interval  # noqa: PLC0415

    line = f"  plain run: {k} {events} in {known} {trains} whose outcome is known"
    if not known:
        return line
    lower, upper = clopper_pearson_interval(k, known, 0.95)
    line += (f", P = {_probability(k / known)}, 95 % CI [{_probability(lower)}, "
             f"{_probability(upper)}] (Clopper-Pearson)")
    if k >= RARE_COUNT:
        line += ("; not a rare event: the plain run resolves it, a rare-event estimator is "
                 "not needed")
    return line


#: Events in the plain run from which a study's event is not rare (CV of k / n <= 0.2).
RARE_COUNT = 25


def _unreached_lines(ds, prefix) -> list:
    """Lines under a plain-run probability that a rare-event estimator did not reach
    (:func:`tolsim.io.schema.rare_events.plain_run_kept`): which estimator, its status, cost
    and why; [] otherwise."""
    from tolsim.study.analyses.rare_events import ESTIMATOR_TITLES  # noqa: PLC0415

    status = f"{prefix}_status"
    if status not in ds or _estimated(ds, prefix):
        return []
    a = ds[status].attrs
    name = ESTIMATOR_TITLES.get(a.get("estimator"), a.get("estimator"))
    lines = [f"  the plain run's estimate (Monte Carlo, Clopper-Pearson): {name} did not reach "
             f"the event ({a.get('estimator_status')}, "
             f"{int(ds[f'{prefix}_evaluations']):,} evaluations): "
             f"{a.get('estimator_message', '')}"]
    if ds[prefix].attrs.get("estimator_note"):
        lines.append(f"  note: {ds[prefix].attrs['estimator_note']}")
    return lines


def _estimated(ds, name) -> bool:
    """Whether a rare-event estimator (not the plain run) made the probability ``name``."""
    return name in ds and ds[name].attrs.get("estimator", "monte_carlo") != "monte_carlo"


def _estimator_lines(ds, prefix, title) -> list:
    """Lines on a probability made by a rare-event estimator (issue 15): which estimator, P
    with its CV and interval, the evaluations; importance sampling's design point; a
    fallback; or why there is no number."""
    from tolsim.study.analyses.rare_events import ESTIMATOR_TITLES  # noqa: PLC0415

    var = ds[prefix]
    a = var.attrs
    name = ESTIMATOR_TITLES.get(a["estimator"], a["estimator"])
    evaluations = int(ds[f"{prefix}_evaluations"])
    unresolved = int(ds[f"{prefix}_unresolved_evaluations"])
    status = a.get("estimator_status", "ok")
    if status != "ok" and not math.isfinite(float(var)):
        lines = [f"{title}: no estimate ({name}, {evaluations:,} evaluations): "
                 f"{a.get('estimator_message', status)}"]
    else:
        cv = float(ds[f"{prefix}_coefficient_of_variation"])
        interval = a.get("interval", "").split(" (")[0]
        lines = [f"{title} = {_probability(float(var))} by {name}: CV {cv:.2g}, 95 % CI "
                 f"[{_probability(float(ds[f'{prefix}_ci_lower']))}, "
                 f"{_probability(float(ds[f'{prefix}_ci_upper']))}] ({interval}, approximate), "
                 f"{evaluations:,} evaluations ({float(a.get('estimator_seconds', 0)):.2g} s)"]
        if status != "ok":  # a number its estimator does not back (issue 23)
            lines.append(f"  NOT OK ({status}): {a.get('estimator_message', '')}")
        elif a.get("estimator_message"):  # ok, with a word on how (one estimator set aside)
            lines.append(f"  {a['estimator_message']}")
        if unresolved:
            lines.append(f"  {unresolved:,} evaluated assemblies unresolved: bounds "
                         f"[{float(ds[f'{prefix}_bound_lower']):.3g}, "
                         f"{float(ds[f'{prefix}_bound_upper']):.3g}], 95 % interval "
                         f"[{float(ds[f'{prefix}_bounds_ci_lower']):.3g}, "
                         f"{float(ds[f'{prefix}_bounds_ci_upper']):.3g}]")
    if a.get("estimator_note"):
        lines.append(f"  note: {a['estimator_note']}")
    event = {"contact_probability": "contact", "friction_exceedance_probability":
             "friction_exceedance"}.get(prefix, "velocity_deviation_exceedance")
    beta = f"{event}_reliability_index"
    if beta in ds:
        b = ds[beta].attrs
        form = float(ds[f"{event}_form_probability"])
        lines.append(f"  design point ({b.get('design_point_component', '')}, beta "
                     f"{float(ds[beta]):.3g}; FORM {form:.3g}, summed over the components): "
                     f"{b.get('design_point_description', '')}")
    return lines


def _exceedance_lines(ds) -> list:
    """Lines on P(an assembly has |epsilon| > limit), which a study with a rare-event
    estimator and a velocity_deviation_limit estimates (issue 15): the estimator's number with
    the plain run's count beside it, or, where the estimator did not reach the event, the
    plain run's k of the assemblies whose outcome is known with its Clopper-Pearson interval,
    why, and the bounds with the unresolved ones; [] otherwise."""
    prefix = "velocity_deviation_exceedance_probability"
    if prefix not in ds:
        return []
    title = f"P(an assembly has |epsilon| > {100 * float(ds.velocity_deviation_limit):.3g} %)"
    counted = "n_velocity_deviation_exceedance" in ds  # files before the plain count: none
    n_asm = int(ds.n_assemblies)
    k = int(ds.n_velocity_deviation_exceedance) if counted else 0
    unresolved = int(ds.n_assemblies_velocity_deviation_unresolved) if counted else 0
    if _estimated(ds, prefix):
        lines = _estimator_lines(ds, prefix, title)
        if counted:
            lines.append(_plain_run_line(k, n_asm - unresolved, "assemblies",
                                         "exceeding assemblies"))
        return lines
    if n_asm == unresolved:  # no number over the known ones: the bounds below say it all
        lines = [f"{title}: no assembly has a known outcome (all {n_asm} unresolved)"]
    else:
        lines = [f"{title} = {float(ds[prefix]):.4f}  95 % CI "
                 f"[{float(ds[f'{prefix}_ci_lower']):.4f}, "
                 f"{float(ds[f'{prefix}_ci_upper']):.4f}]  ({k} of {n_asm - unresolved} "
                 "assemblies whose outcome is known)"]
    lines.extend(_unreached_lines(ds, prefix))
    if unresolved:
        lines.append(
            f"  bounds over all {n_asm} assemblies, with the {unresolved} unresolved ones "
            f"counted as within / beyond the limit: [{float(ds[f'{prefix}_bound_lower']):.4f}, "
            f"{float(ds[f'{prefix}_bound_upper']):.4f}], 95 % interval "
            f"[{float(ds[f'{prefix}_bounds_ci_lower']):.4f}, "
            f"{float(ds[f'{prefix}_bounds_ci_upper']):.4f}]")
    return lines


def _friction_text(ds) -> list:
    """Lines on the friction of a study with [contact]: increase and P(increase > limit)."""
    inc = ds["friction_increase_quantile"]
    resolved = int(ds.n_assemblies_friction_resolved)
    unresolved = int(ds.n_assemblies_friction_unresolved)
    n_asm = int(ds.n_assemblies)

    def at(level):
        return float(inc.sel(quantile=level, method="nearest"))

    lines = [
        f"friction (worst track of each assembly, mu_bb {float(ds.ball_friction_coefficient):g}): "
        f"baseline {float(ds.friction_force_baseline):.4g} N; increase median {at(0.5):.3g} N, "
        f"99 % {at(0.99):.3g} N, largest {float(ds.friction_increase_max):.3g} N; contact "
        f"during {100 * float(ds.contact_fraction_mean):.3g} % of the stroke on average "
        f"({resolved} of {n_asm} assemblies resolved)"]
    limit = float(ds.friction_increase_limit)
    if limit == limit and _estimated(ds, "friction_exceedance_probability"):
        lines.extend(_estimator_lines(ds, "friction_exceedance_probability",
                                      f"P(friction increase > {limit:.4g} N)"))
        lines.append(f"  plain run: {int(ds.n_friction_exceedance)} of "
                     f"{n_asm - unresolved} assemblies whose outcome is known exceed it")
    elif limit == limit:  # a limit is set (NaN otherwise)
        k = int(ds.n_friction_exceedance)
        lines.append(
            f"P(friction increase > {limit:.4g} N) = "
            f"{float(ds.friction_exceedance_probability):.4f}  95 % CI "
            f"[{float(ds.friction_exceedance_probability_ci_lower):.4f}, "
            f"{float(ds.friction_exceedance_probability_ci_upper):.4f}]  ({k} of "
            f"{n_asm - unresolved} assemblies whose outcome is known)")
        lines.extend(_unreached_lines(ds, "friction_exceedance_probability"))
        if unresolved:
            lines.append(
                f"  bounds over all {n_asm} assemblies, the {unresolved} unresolved counted as "
                f"below / above: [{float(ds.friction_exceedance_probability_bound_lower):.4f}, "
                f"{float(ds.friction_exceedance_probability_bound_upper):.4f}]")
    sliding = int(ds.n_assemblies_sliding)
    if sliding:
        lines.append(f"  {sliding} assemblies with a sliding ball (push beyond its traction "
                     "capacity): unresolved from the onset of sliding")
    released = int(ds.n_assemblies_released) if "n_assemblies_released" in ds else 0
    if released:
        lines.append(f"  {released} assemblies with a ball pushed off its stick line (push "
                     "beyond the release push of its stuck contact): unresolved from then on")
    return lines


def _stackup_line(ds) -> str:
    """The linear stack-up's line: the critical ball and pair, or why there is none (a
    one-ball train has no pair; -1 marks a ball or pair without a finite value)."""
    b, pr = int(ds.critical_ball), int(ds.critical_pair)
    if b >= 0:
        ball = (f"epsilon of ball {b} RSS {100 * float(ds.velocity_deviation_rss[b]):.3f} % "
                f"(Monte Carlo std {100 * float(ds.velocity_deviation_std_by_ball[b]):.3f} %), "
                f"worst case +-{100 * float(ds.velocity_deviation_worst_case[b]):.3f} %")
    else:
        ball = "epsilon: no ball with a finite RSS (a perturbed ball unresolved)"
    if pr >= 0:
        pair = (f"gap closure of pair {pr} RSS {1e6 * float(ds.gap_closure_rss[pr]):.3g} um, "
                f"worst case +-{1e6 * float(ds.gap_closure_worst_case[pr]):.3g} um")
    elif ds.sizes.get("pair", 0) == 0:
        pair = "no gap closure (a train of one ball has no pair)"
    else:
        pair = "gap closure: no pair with a finite RSS (a perturbed ball unresolved)"
    return f"linear stack-up: {ball}; {pair}"


def summary(ds, output, elapsed, save_requested=0) -> str:
    """Short plain-text summary of a result Dataset (``save_requested``: --save-samples)."""
    a = ds.attrs
    q = ds["velocity_deviation_quantile"]
    tq = ds["time_to_contact_quantile"]

    def at(var, level):
        return float(var.sel(quantile=level, method="nearest"))

    n_asm, n_unres = int(ds.n_assemblies), int(ds.n_assemblies_unresolved)
    balls = ds.sizes["ball"]
    tracks = ds.sizes.get("track", 0)
    trains = "assemblies" if tracks else "trains"  # a carriage: any of its trains touches
    shape = f"{tracks} tracks x {balls} balls" if tracks else f"{balls} balls"
    lines = [
        f"study: {a['title'].split(': ', 1)[-1]}  {n_asm} assemblies x {shape}  "
        f"({a['velocity_model']}, {a['static_model']} static, {a['propagation']} "
        f"propagation, {a['sampling']} sampling, seed {a['seed']})",
        _epsilon_line(ds, at(q, 0.01), at(q, 0.99)),
    ]
    outside = _outside_histogram_line(ds)
    if outside:
        lines.append(outside)
    contact = (f"P(contact within {float(ds.horizon):.4g} s, stroke "
               f"{1e3 * float(ds.horizon * ds.groove_velocity):.4g} mm)")
    rare = _estimated(ds, "contact_probability")
    if rare:  # a rare-event estimator (issue 15); the plain run's count beside it
        lines.extend(_estimator_lines(ds, "contact_probability", contact))
        lines.append(_plain_run_line(int(ds.n_contact), n_asm - n_unres, trains))
    else:
        lines.append(
            f"{contact} = {float(ds.contact_probability):.4f}  95 % CI "
            f"[{float(ds.contact_probability_ci_lower):.4f}, "
            f"{float(ds.contact_probability_ci_upper):.4f}]  "
            f"({int(ds.n_contact)} of {n_asm - n_unres} {trains} whose outcome is known)")
        lines.extend(_unreached_lines(ds, "contact_probability"))
    lines.extend(_exceedance_lines(ds))
    if tracks:
        lines.append(_carriage_text(ds))
    if n_unres and not rare:
        lines.append(
            f"  bounds over all {n_asm} trains, with the {n_unres} unresolved ones counted "
            f"as no contact / contact: [{float(ds.contact_probability_bound_lower):.4f}, "
            f"{float(ds.contact_probability_bound_upper):.4f}], 95 % interval "
            f"[{float(ds.contact_probability_bounds_ci_lower):.4f}, "
            f"{float(ds.contact_probability_bounds_ci_upper):.4f}]")
    if a.get("stopping_rule"):  # --target-ci-width
        lines.append(a["stopping_rule"])
    lines.append(f"propagation: {a['propagation_assumption']}")
    if a.get("propagation_caveat"):
        lines.append(f"  note: {a['propagation_caveat']}")
    lines.extend(_circuit_text(ds))
    if "friction_increase_quantile" in ds:  # [contact]: after the first contact
        lines.extend(_friction_text(ds))
    if int(ds.n_contact) and math.isfinite(float(ds.time_to_contact_min)):
        lines.append(
            f"time to first contact: earliest {float(ds.time_to_contact_min):.4g} s, "
            f"median {at(tq, 0.5):.4g} s, 95 % by {at(tq, 0.95):.4g} s (given contact, "
            "resolved trains)")
    elif int(ds.n_contact):  # every train that touches has an unresolved ball
        lines.append("time to first contact: not known (no train with every ball resolved "
                     "touches)")
    n_balls = int(ds.n_balls)
    n_unloaded = int(ds.n_balls_unloaded) if "n_balls_unloaded" in ds else 0
    n_unresolved_balls = n_balls - int(ds.n_balls_valid) - n_unloaded
    lines.append(
        f"balls: {int(ds.n_balls_outside_validity)} of {n_balls} sent to the full model "
        f"(outside the {a['velocity_model']} model's validity or with an open contact), "
        f"{int(ds.n_balls_resolved_full)} of them solved "
        f"({float(a['full_model_resolve_seconds']):.2f} s); "
        f"unresolved {n_unresolved_balls} (static not converged "
        f"{int(ds.n_balls_not_converged)}, loss of contact {int(ds.n_balls_loss_of_contact)}, "
        f"full model failed {int(ds.n_balls_full_failed)})"
        + (f", and {int(ds.n_balls_unresolved_along_track)} more along the track"
           if a["propagation"] == "along_track" and "n_balls_unresolved_along_track" in ds
           else "")
        + f"; unresolved trains u = {n_unres}")
    from tolsim.reports.result_view import static_fallback_text  # noqa: PLC0415

    fallback = static_fallback_text(ds)
    if fallback:
        lines.append(f"  {fallback}")
    untimed = (int(ds.n_assemblies_contact_untimed) if "n_assemblies_contact_untimed" in ds
               else 0)
    if untimed:
        lines.append(
            f"  {untimed} of the {n_asm - n_unres} {trains} whose outcome is known have an "
            "unresolved ball and a contact certain without it: counted as contact, outside "
            f"the time statistics ({int(ds.n_assemblies_valid)} {trains} with every ball "
            "resolved)")
    if "n_balls_regime" in ds:
        from tolsim.reports.result_view import regime_counts_text  # noqa: PLC0415

        lines.append(f"balls by regime: {regime_counts_text(ds)} (A: every contact slips; B: "
                     "one sticks)")
    if n_asm and n_unres / n_asm > UNRESOLVED_WARNING:
        lines.append(
            f"warning: {n_unres} of {n_asm} trains ({100 * n_unres / n_asm:.2g} %) are "
            "unresolved; P(contact) is known only within the bounds above")
    if n_balls and n_unresolved_balls / n_balls > UNRESOLVED_WARNING:
        lines.append(
            f"warning: {n_unresolved_balls} of {n_balls} balls "
            f"({100 * n_unresolved_balls / n_balls:.2g} %) have no epsilon from any model; "
            "the epsilon statistics, ppm and Cpk below are over the resolved balls only")
    n_sc = ds.sizes["spot_check"]
    if n_sc and int(ds.spot_check_n_valid):
        lines.append(
            f"spot checks: {int(ds.spot_check_n_valid)} of {n_sc} valid in both models, "
            f"{a['velocity_model']} - full: RMS "
            f"{100 * float(ds.spot_check_rms_difference):.4f} %, "
            f"max {100 * float(ds.spot_check_max_abs_difference):.4f} % (of v/2)"
            + _strata_text(ds))
    else:
        lines.append(f"spot checks: {a['spot_check_status']}")
    if "velocity_deviation_out_of_spec_fraction" in ds:
        from tolsim.study.statistics.quality import format_fraction  # noqa: PLC0415

        line = (f"|epsilon| > {_pct(float(ds.velocity_deviation_limit))}: " + format_fraction(
            float(ds.velocity_deviation_out_of_spec_fraction),
            float(ds.velocity_deviation_out_of_spec_ci_lower),
            float(ds.velocity_deviation_out_of_spec_ci_upper)) + " of balls")
        if "velocity_deviation_cpk" in ds:
            line += f", Cpk {float(ds.velocity_deviation_cpk):.3f}"
        lines.append(line)
    if "critical_ball" in ds:
        lines.append(_stackup_line(ds))
    if "sensitivity_total" in ds.variables and ds.sizes.get("factor", 0):
        for var, what in (("sensitivity_total", "epsilon"),
                          ("sensitivity_contact_total", "contact"),
                          ("sensitivity_friction_total", "the friction increase")):
            if var in ds and ds[var].attrs.get("not_estimable"):  # NaN indices: why
                lines.append(f"drivers of {what} (total Sobol' index): "
                             f"{ds[var].attrs['not_estimable']}")
            elif var in ds:
                # indexed by the source names (the factor_name label), not the factor index
                by_name = ds[var].swap_dims(factor="factor_name").to_series()
                ranked = by_name.sort_values(ascending=False).head(3)
                lines.append(f"drivers of {what} (total Sobol' index): " + ", ".join(
                    f"{name} {value:.2f}" for name, value in ranked.items()))
    compiled = float(a.get("compile_seconds", 0.0))
    if compiled > 0:  # compiling: a cold kernel cache, once per machine (tolsim warmup does
        # it ahead); loading from Numba's cache: the first call of each kernel in a process
        lines.append(f"compiled kernels: {compiled:.1f} s (compiling on a first run, loading "
                     "from the kernel cache after it; not in the times above and below)")
    # over the work done in this process (after a resume, only that), compilation excluded
    rate = float(a.get("balls_per_second", float("nan")))
    if not math.isfinite(rate):  # a file from before the attribute
        rate = int(ds.n_balls) / elapsed if elapsed > 0 else float("nan")
    saved = ds.sizes.get("sample", 0)
    if saved:
        lines.append(f"saved samples: the inputs and outputs of the first {saved:,} assemblies "
                     "(dimension 'sample')" + (
                         f"; --save-samples {save_requested:,} asked for more than the run has"
                         if save_requested > saved else ""))
    lines.append(f"wrote {output} ({elapsed:.1f} s, {rate:,.0f} balls/s)")
    return "\n".join(lines)


def _command_line(args, output) -> str:
    """The command that reproduces this run (for the history attribute)."""
    parts = ["tolsim", "run"] + ([args.config] if args.config else []) + ["-o", str(output)]
    for flag, value in (("--samples", args.samples), ("--seed", args.seed),
                        ("--save-samples", args.save_samples or None)):
        if value is not None:
            parts += [flag, str(value)]
    if args.workers != 1:
        parts += ["--workers", str(args.workers)]
    if args.scheduler:
        parts += ["--scheduler", args.scheduler]
    if args.target_ci_width is not None:
        parts += ["--target-ci-width", str(args.target_ci_width)]
    return shlex.join(parts)


def os_error_line(exc: OSError, path=None) -> str:
    """One line on an OSError while writing: the file (the error's, else ``path``) and the
    reason, e.g. ``cannot write out.nc: No space left on device``."""
    where = exc.filename or path
    reason = " ".join(str(exc.strerror or exc).split())
    if reason.startswith("cannot write"):  # the checkpoint's: says what it was writing
        return f"{where}: {reason}"
    return f"cannot write {where}: {reason}" if where else f"cannot write: {reason}"


def _check_output(output: Path, checkpoint: Path):
    """Fail before any work if the result or its checkpoint cannot be written there.

    The folder is tried by creating and removing a file in it (permissions alone do not
    tell: root, ACLs, read-only file systems). An existing result is replaced by a rename,
    which a write-protected file, or another user's file in a sticky folder such as /tmp,
    would not allow or should not get.
    """
    folder = output.parent
    if output.is_dir():
        raise UsageError(f"output {output} is a folder")
    if not folder.exists():
        raise UsageError(f"output folder {folder} does not exist")
    if not folder.is_dir():
        raise UsageError(f"output folder {folder} is not a folder")
    if checkpoint.is_dir():
        raise UsageError(f"checkpoint {checkpoint} is a folder")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{output.name}.", suffix=".check", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise UsageError(f"cannot write to output folder {folder}: {exc.strerror}") from None
    if output.exists():
        if not os.access(output, os.W_OK):
            raise UsageError(f"output {output} exists and is write-protected; delete it or "
                             "choose another -o")
        sticky = folder.stat()
        if (sticky.st_mode & 0o1000 and hasattr(os, "geteuid")
                and os.geteuid() not in (0, sticky.st_uid, output.stat().st_uid)):
            raise UsageError(f"output {output} belongs to another user in a sticky folder "
                             "and cannot be replaced; choose another -o")


def run(args) -> int:
    from tolsim.io.config import ConfigError, load_config  # noqa: PLC0415

    try:
        config = load_config(args.config).with_overrides(samples=args.samples, seed=args.seed)
    except (ConfigError, ValueError) as exc:
        raise UsageError(str(exc)) from None
    if args.output:
        output = Path(args.output)
    elif args.config:
        output = Path(Path(args.config).stem + ".nc")
    else:
        output = Path("tolsim-result.nc")
    checkpoint = Path(f"{output}.partial")
    _check_output(output, checkpoint)
    if args.scheduler is not None:  # before any work: the extra, the value, the flags
        from tolsim.study.execution import distributed  # noqa: PLC0415

        if args.workers != 1:
            raise UsageError("--workers and --scheduler: the scheduler's workers do the work; "
                             "for N worker processes on this machine use --scheduler local:N")
        try:
            distributed.require_distributed()
            distributed.parse_scheduler(args.scheduler)
        except (distributed.MissingExtraError, ValueError) as exc:
            raise UsageError(str(exc)) from None

    if config.sweep is not None:  # a what-if sweep: its points into one file
        return _run_sweep(args, config, output)

    import tqdm  # noqa: PLC0415

    from tolsim.io.netcdf import write_result  # noqa: PLC0415
    from tolsim.study.execution.runner import (  # noqa: PLC0415
        DamagedCheckpoint,
        checkpoint_mismatch,
        run_study,
    )

    if args.fresh and checkpoint.exists():
        checkpoint.unlink()
    if args.resume or checkpoint.exists():
        flag = "--resume: " if args.resume else ""
        try:
            mismatch = checkpoint_mismatch(checkpoint, config)
        except FileNotFoundError:
            raise UsageError(f"--resume: no checkpoint {checkpoint}") from None
        except Exception as exc:  # noqa: BLE001 - zipfile, zlib, numpy and OS errors alike
            raise UsageError(f"{flag}checkpoint {checkpoint} cannot be read, it is damaged "
                             f"or truncated ({type(exc).__name__}); --fresh discards it"
                             ) from None
        if mismatch:  # another study's progress: never discarded unasked
            raise UsageError(f"{flag}{checkpoint} is the checkpoint of another study "
                             f"({mismatch}); --fresh discards its progress, or write this "
                             "study to another -o")

    bar = tqdm.tqdm(total=config.study.samples, unit="asm", unit_scale=True, file=sys.stderr,
                    desc="tolsim run", disable=True if args.quiet else None, smoothing=0.1)

    def notify(message):  # resumed checkpoint, compiling kernels: on stderr, past the bar
        if not args.quiet:
            tqdm.tqdm.write(f"tolsim run: {message}", file=sys.stderr)

    try:
        result = run_study(config, workers=args.workers, chunk_blocks=args.chunk_blocks,
                           progress=bar.update, checkpoint_path=str(checkpoint),
                           checkpoint_interval=args.checkpoint_interval,
                           target=args.target_ci_width, notify=notify,
                           save_samples=args.save_samples, scheduler=args.scheduler,
                           require_answer=True)
    except DamagedCheckpoint as exc:
        raise UsageError(f"{exc}; --fresh discards it") from None
    except ValueError as exc:  # also a scheduler that cannot be reached
        raise UsageError(str(exc)) from None
    except OSError as exc:  # a full disk at a checkpoint, say
        raise UsageError(os_error_line(exc)) from None
    except KeyboardInterrupt:
        if not checkpoint.exists():
            raise
        bar.close()
        print(f"tolsim run: interrupted; the progress is in {checkpoint}, run the same "
              "command again to resume", file=sys.stderr)
        return 130
    finally:
        bar.close()
    try:
        ds = write_result(result, output, history=_command_line(args, output))
    except OSError as exc:  # a full disk, say: nothing is left half-written
        raise UsageError(os_error_line(exc, output)) from None
    if checkpoint.exists():
        os.unlink(checkpoint)
    if not args.quiet:
        print(summary(ds, output, result.elapsed - result.loop_compile_seconds,
                      args.save_samples))
    return 0


def sweep_summary(ds, output, work) -> str:
    """Short plain-text summary of a sweep's result: one line per point."""
    import numpy as np  # noqa: PLC0415

    keys = ds.attrs["sweep_keys"].split()
    names = ds.attrs["sweep_coordinates"].split()
    dims = ds.attrs["sweep_dimensions"].split()
    shape = tuple(ds.sizes[d] for d in dims)
    n = int(np.prod(shape))
    lines = [f"sweep: {ds.attrs['title'].split(': ', 1)[-1]}  ({ds.attrs['sweep_mode']}; "
             "every point with the same seed: common random numbers)"]
    head = [f"{key}" for key in keys] + ["P(contact)", "95 % CI", "eps std %"]
    has_friction = "friction_increase_quantile" in ds
    if has_friction:
        head.append("friction +99% N")
    # the unresolved trains of each point (P and its interval are over the others)
    unresolved = (ds.n_assemblies_unresolved.values if "n_assemblies_unresolved" in ds
                  else np.zeros(shape, dtype=np.int64))
    if unresolved.any():
        head.append("unresolved")
    rows = []
    for index in np.ndindex(*shape):
        pt = ds.isel(dict(zip(dims, index, strict=True)))
        row = [f"{float(pt[name]):g}" for name in names]
        row += [f"{float(pt.contact_probability):.4f}",
                f"[{float(pt.contact_probability_ci_lower):.4f}, "
                f"{float(pt.contact_probability_ci_upper):.4f}]",
                f"{100 * float(pt.velocity_deviation_std):.3f}"]
        if has_friction:
            q99 = pt.friction_increase_quantile.sel(quantile=0.99, method="nearest")
            row.append(f"{float(q99):.3g}")
        if unresolved.any():
            row.append(f"{int(pt.n_assemblies_unresolved)} of {int(pt.n_assemblies)}")
        rows.append(row)
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    lines.append("  ".join(h.rjust(w) for h, w in zip(head, widths, strict=True)))
    lines.extend("  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows)
    if unresolved.any():
        everything = int((unresolved == ds.n_assemblies.values).sum())
        none_known = (f"; at {everything} of {n} points no train has a known outcome (nan)"
                      if everything else "")
        lines.append(
            "warning: trains unresolved (a ball no model answers): P(contact) and its 95 % CI "
            "are over the trains whose outcome is known, the bounds with the unresolved ones "
            f"are in the file (tolsim report){none_known}")
    # the points run in this process only: a resumed sweep's earlier points took no time here
    lines.append(f"wrote {output} ({n} point{'' if n == 1 else 's'}, {work.elapsed:.1f} s, "
                 f"{work.balls_per_second:,.0f} balls/s)")
    return "\n".join(lines)


def _run_sweep(args, config, output) -> int:
    """``tolsim run`` on a config with ``[sweep]``: every point, one file (tolsim.io.sweep)."""
    import tqdm  # noqa: PLC0415

    from tolsim.io.sweep import parts_folder, run_sweep  # noqa: PLC0415
    from tolsim.study.execution.runner import DamagedCheckpoint  # noqa: PLC0415

    sweep = config.sweep
    folder = parts_folder(output)
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"{folder} exists and is not a folder; delete it or choose another -o")
    if args.resume and not any(folder.glob("point-*")):
        raise UsageError(f"--resume: no finished or started sweep point in {folder}")
    total = sweep.size * config.study.samples
    bar = tqdm.tqdm(total=total, unit="asm", unit_scale=True, file=sys.stderr,
                    desc="tolsim run", disable=True if args.quiet else None, smoothing=0.1)

    def on_point(k, sweep):
        bar.set_description(f"point {k + 1}/{sweep.size}")

    def notify(message):
        if not args.quiet:
            tqdm.tqdm.write(f"tolsim run: {message}", file=sys.stderr)

    try:
        ds, work = run_sweep(
            config, output, history=_command_line(args, output), progress=bar.update,
            on_point=on_point, notify=notify, fresh=args.fresh, workers=args.workers,
            chunk_blocks=args.chunk_blocks, checkpoint_interval=args.checkpoint_interval,
            target=args.target_ci_width, save_samples=args.save_samples,
            scheduler=args.scheduler)
    except DamagedCheckpoint as exc:
        raise UsageError(f"{exc}; --fresh discards it (and the sweep's finished points)"
                         ) from None
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    except OSError as exc:  # a full disk at a point, a checkpoint or the result, say
        raise UsageError(os_error_line(exc, output)) from None
    except KeyboardInterrupt:
        bar.close()
        print(f"tolsim run: interrupted; the finished points and the progress of the running "
              f"one are in {folder}, run the same command again to resume", file=sys.stderr)
        return 130
    finally:
        bar.close()
    if not args.quiet:
        print(sweep_summary(ds, output, work))
    return 0
