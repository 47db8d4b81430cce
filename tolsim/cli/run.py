"""``tolsim run``: a Monte Carlo tolerance study from a TOML config to a netCDF result.

A thin layer over :func:`tolsim.io.config.load_config`, :func:`tolsim.study.runner.run_study`
and :func:`tolsim.io.netcdf.write_result`.
"""

import os
import shlex
import sys
from pathlib import Path

from tolsim.cli import UsageError, integer_at_least

DESCRIPTION = """\
Run a Monte Carlo tolerance study: sample assemblies (tolerances, gaps), solve each ball's
contact state and velocity deviation epsilon, propagate the balls of each track and record
ball-to-ball contact. Writes a netCDF file (CF-1.10) with the statistics, the config and the
seed, and prints a short summary.

Without CONFIG the packaged default study runs. Progress is checkpointed next to the output
(OUT.partial); rerunning the same command resumes from it with a bit-identical result.

examples:
  tolsim run                                   # the packaged default study
  tolsim run configs/paper_case_study.toml -o case.nc
  tolsim run study.toml --samples 1000000 --seed 7 -o seed7.nc
"""


_positive_int = integer_at_least(1, "a positive integer")
_seed = integer_at_least(0, "a non-negative integer")


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser(
        "run", help="Monte Carlo tolerance study from a TOML config to a netCDF result",
        description=DESCRIPTION, formatter_class=formatter_class)
    p.add_argument("config", nargs="?", metavar="CONFIG",
                   help="study config (TOML); default: the packaged default study")
    p.add_argument("-o", "--output", metavar="OUT.nc",
                   help="result file (default: CONFIG's name with .nc, or tolsim-result.nc for the "
                        "default study, in the current folder)")
    p.add_argument("--samples", type=_positive_int, metavar="N",
                   help="number of assemblies (overrides study.samples)")
    p.add_argument("--seed", type=_seed, metavar="S", help="random seed (overrides study.seed)")
    p.add_argument("--workers", type=_positive_int, default=1, metavar="N",
                   help="worker processes, sharing the cores (the result does not depend on "
                        "it). 1 is fastest on a few cores: the compiled kernels already run on "
                        "every core and the next chunk is drawn meanwhile; each extra process "
                        "costs 1-2 s to start and pays off only for long runs on many cores")
    p.add_argument("--chunk-blocks", type=_positive_int, metavar="N",
                   help="random blocks evaluated together (default: ~260k balls per chunk)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--resume", action="store_true",
                       help="require a matching checkpoint OUT.partial and continue from it")
    group.add_argument("--fresh", action="store_true",
                       help="ignore and delete a checkpoint OUT.partial")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    return p


#: Share of unresolved trains above which the summary warns.
UNRESOLVED_WARNING = 1e-3


def _pct(x):
    return f"{100 * x:+.3f} %"


def summary(ds, output, elapsed) -> str:
    """Short plain-text summary of a result Dataset."""
    a = ds.attrs
    q = ds["velocity_deviation_quantile"]
    tq = ds["time_to_contact_quantile"]

    def at(var, level):
        return float(var.sel(quantile=level, method="nearest"))

    n_asm, n_unres = int(ds.n_assemblies), int(ds.n_assemblies_unresolved)
    balls = ds.sizes["ball"]
    lines = [
        f"study: {a['title'].split(': ', 1)[-1]}  {n_asm} assemblies x {balls} balls  "
        f"({a['velocity_model']}, {a['static_model']} static, {a['propagation']} "
        f"propagation, {a['sampling']} sampling, seed {a['seed']})",
        f"epsilon: mean {_pct(float(ds.velocity_deviation_mean))}, "
        f"std {100 * float(ds.velocity_deviation_std):.3f} %, "
        f"1-99 % {_pct(at(q, 0.01))} .. {_pct(at(q, 0.99))}, "
        f"range {_pct(float(ds.velocity_deviation_min))} .. "
        f"{_pct(float(ds.velocity_deviation_max))}",
        f"P(contact within {float(ds.horizon):.4g} s, stroke "
        f"{1e3 * float(ds.horizon * ds.groove_velocity):.4g} mm) = "
        f"{float(ds.contact_probability):.4f}  95 % CI "
        f"[{float(ds.contact_probability_ci_lower):.4f}, "
        f"{float(ds.contact_probability_ci_upper):.4f}]  "
        f"({int(ds.n_contact)} of {n_asm - n_unres} trains whose outcome is known)",
    ]
    if n_unres:
        lines.append(
            f"  bounds over all {n_asm} trains, with the {n_unres} unresolved ones counted "
            f"as no contact / contact: [{float(ds.contact_probability_bound_lower):.4f}, "
            f"{float(ds.contact_probability_bound_upper):.4f}], 95 % interval "
            f"[{float(ds.contact_probability_bounds_ci_lower):.4f}, "
            f"{float(ds.contact_probability_bounds_ci_upper):.4f}]")
    lines.append(f"propagation: {a['propagation_assumption']}")
    if a.get("propagation_caveat"):
        lines.append(f"  note: {a['propagation_caveat']}")
    if int(ds.n_contact):
        lines.append(
            f"time to first contact: earliest {float(ds.time_to_contact_min):.4g} s, "
            f"median {at(tq, 0.5):.4g} s, 95 % by {at(tq, 0.95):.4g} s (given contact, "
            "resolved trains)")
    n_balls = int(ds.n_balls)
    n_unresolved_balls = n_balls - int(ds.n_balls_valid)
    lines.append(
        f"balls: {int(ds.n_balls_outside_validity)} of {n_balls} outside the "
        f"{a['velocity_model']} model's validity, {int(ds.n_balls_resolved_full)} of them "
        f"re-solved with the full model ({float(a['full_model_resolve_seconds']):.2f} s); "
        f"unresolved {n_unresolved_balls} (static not converged "
        f"{int(ds.n_balls_not_converged)}, loss of contact {int(ds.n_balls_loss_of_contact)}, "
        f"full model failed {int(ds.n_balls_full_failed)}); unresolved trains u = {n_unres}")
    if n_asm and n_unres / n_asm > UNRESOLVED_WARNING:
        lines.append(
            f"warning: {n_unres} of {n_asm} trains ({100 * n_unres / n_asm:.2g} %) are "
            "unresolved; P(contact) is known only within the bounds above")
    n_sc = ds.sizes["spot_check"]
    if n_sc and int(ds.spot_check_n_valid):
        lines.append(
            f"spot checks: {int(ds.spot_check_n_valid)} of {n_sc} valid in both models, "
            f"analytic - full: RMS {100 * float(ds.spot_check_rms_difference):.4f} %, "
            f"max {100 * float(ds.spot_check_max_abs_difference):.4f} % (of v/2)")
    else:
        lines.append(f"spot checks: {a['spot_check_status']}")
    if "velocity_deviation_out_of_spec_fraction" in ds:
        from tolsim.study.quality import format_fraction

        line = (f"|epsilon| > {_pct(float(ds.velocity_deviation_limit))}: " + format_fraction(
            float(ds.velocity_deviation_out_of_spec_fraction),
            float(ds.velocity_deviation_out_of_spec_ci_lower),
            float(ds.velocity_deviation_out_of_spec_ci_upper)) + " of balls")
        if "velocity_deviation_cpk" in ds:
            line += f", Cpk {float(ds.velocity_deviation_cpk):.3f}"
        lines.append(line)
    if "sensitivity_total" in ds.variables and ds.sizes.get("factor", 0):
        for var, what in (("sensitivity_total", "epsilon"),
                          ("sensitivity_contact_total", "contact")):
            if var in ds:
                # indexed by the source names (the factor_name label), not the factor index
                by_name = ds[var].swap_dims(factor="factor_name").to_series()
                ranked = by_name.sort_values(ascending=False).head(3)
                lines.append(f"drivers of {what} (total Sobol' index): " + ", ".join(
                    f"{name} {value:.2f}" for name, value in ranked.items()))
    rate = int(ds.n_balls) / elapsed if elapsed > 0 else float("nan")
    lines.append(f"wrote {output} ({elapsed:.1f} s, {rate:,.0f} balls/s)")
    return "\n".join(lines)


def _command_line(args, output) -> str:
    """The command that reproduces this run (for the history attribute)."""
    parts = ["tolsim", "run"] + ([args.config] if args.config else []) + ["-o", str(output)]
    for flag, value in (("--samples", args.samples), ("--seed", args.seed)):
        if value is not None:
            parts += [flag, str(value)]
    if args.workers != 1:
        parts += ["--workers", str(args.workers)]
    return shlex.join(parts)


def run(args) -> int:
    from tolsim.io.config import ConfigError, load_config

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
    if output.is_dir():
        raise UsageError(f"output {output} is a folder")
    if not output.parent.resolve().is_dir():
        raise UsageError(f"output folder {output.parent} does not exist")
    checkpoint = Path(f"{output}.partial")

    import tqdm

    from tolsim.io.netcdf import write_result
    from tolsim.study.runner import fingerprint, run_study

    if args.fresh and checkpoint.exists():
        checkpoint.unlink()
    if args.resume:
        import numpy as np

        try:
            with np.load(checkpoint) as data:
                matches = str(data["fingerprint"]) == fingerprint(config)
        except (OSError, KeyError, ValueError):
            matches = False
        if not matches:
            raise UsageError(f"--resume: no checkpoint {checkpoint} for this study")

    bar = tqdm.tqdm(total=config.study.samples, unit="asm", unit_scale=True, file=sys.stderr,
                    desc="tolsim run", disable=True if args.quiet else None, smoothing=0.1)
    try:
        result = run_study(config, workers=args.workers, chunk_blocks=args.chunk_blocks,
                           progress=bar.update, checkpoint_path=str(checkpoint))
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    finally:
        bar.close()
    ds = write_result(result, output, history=_command_line(args, output))
    if checkpoint.exists():
        os.unlink(checkpoint)
    if not args.quiet:
        print(summary(ds, output, result.elapsed))
    return 0
