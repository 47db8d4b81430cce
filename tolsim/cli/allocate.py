"""``tolsim allocate``: the loosest tolerances that meet a probabilistic target at the least
cost.

A thin layer over :func:`tolsim.study.design.allocate.run_allocation`,
:func:`tolsim.io.config.allocation.allocated_config_text` and
:func:`tolsim.reports.allocate.write_allocation`.
"""

import argparse
import os
import shlex
import sys
import time
from pathlib import Path

from tolsim.cli import UsageError, integer_at_least, path_argument
from tolsim.study.spec import MAX_SEED, MAX_WORKERS

DESCRIPTION = """\
Find the loosest set of tolerances that meets a probabilistic target at the least cost.

Each tolerance source gets a scale factor s ("the tolerance times s": a std, a band, a cpk
band scaled about its centre; s = 1 is the config as given) within bounds, and a cost
w / s^k (the reciprocal power cost model of the tolerance-allocation literature; the default
k = 2 is Spotts's reciprocal square, w = 1). The allocation is the set of scales with the
least cost whose one-sided upper confidence bound of the target's probability (not its
estimate) meets the limit. For P(contact) the bound counts the unresolved trains as
contacts.

TARGET is NAME <= VALUE, VALUE a number or with % or ppm:
  contact_probability <= 0.01                 P(contact within the stroke)
  friction_exceedance_probability <= 5%       P(friction increase > its limit), [contact]
  velocity_deviation_out_of_spec_fraction <= 200ppm
                                              balls with |epsilon| above the config's limit
  velocity_deviation_abs_quantile(0.999) <= 0.5%
                                              the 0.999 quantile of |epsilon|; evaluated as
                                              "at most 0.1 % of balls beyond 0.5 %"

How: every evaluation is a study of the same assemblies (same seed: common random numbers),
so the bound is a deterministic function of the scales. A sweep of a common factor, a
trust-region response surface in the scales and a ray search find the cheapest design
that meets the limit on that sample. The optimum is then verified on a fresh, independent
sample (its seed derived from the study seed, printed), which is the honest result.
Runtime: about 20 + 12 d studies of --samples assemblies for d sources (at most
max_evaluations), plus the verification; configs/allocate_example.toml (3 sources, 10 000
assemblies) takes about 7 s on two cores. Large scales cost more: balls outside the fast
model's validity are re-solved with the full model.

The settings come from the config's [allocate] section (all optional):
  [allocate]
  target = "contact_probability <= 1%"
  confidence = 0.95          # one-sided
  samples = 20000            # per evaluation (default: [study] samples)
  verify_samples = 80000     # default: 4 x samples
  max_evaluations = 120
  [allocate.sources.bottom_rotation]   # a decision variable; sources not listed stay fixed
  min_scale = 0.25           # (without [allocate.sources]: every random source, with these
  max_scale = 4.0            #  defaults; max_scale lower where the static model's range
                             #  demands it)
  cost_exponent = 2.0        # k
  cost_weight = 1.0          # w: the source's cost at the given tolerance, relative

Writes into the output folder (whole, or not at all):
  allocate.html    the verdict of the verification, the allocated tolerances in the
                   config's units, the cost, the trade-off curve, the method and references
  allocated.toml   the optimum as a ready-to-run config ('scale = ...' in each allocated
                   [tolerances.*] table; the verification's seed and samples, so that
                   'tolsim run allocated.toml' reproduces the verification)
  allocate.json, allocate.csv, evaluations.csv, trade_off.png   the numbers and the figure

Exit codes: 0 when the verification on the fresh sample meets the target; 1 when it does not
(the files are written, and say so: the optimum of the search sample did not hold up on a
fresh one; more --samples usually helps); 2 for bad input or a target no scale can meet.

examples:
  tolsim allocate configs/allocate_example.toml -o allocation
  tolsim allocate study.toml --target "contact_probability<=0.01" -o alloc
  tolsim allocate study.toml --target "velocity_deviation_abs_quantile(0.999)<=0.5%" \\
      --samples 50000 --confidence 0.9 -o alloc
"""

_positive_int = integer_at_least(1, "a positive integer")
_seed = integer_at_least(0, f"an integer from 0 to {MAX_SEED}", maximum=MAX_SEED)
_workers = integer_at_least(1, f"a number of processes from 1 to {MAX_WORKERS}",
                            maximum=MAX_WORKERS)


def _confidence(text):
    """An argparse ``type``: a one-sided confidence level in (0.5, 1)."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not 0.5 < value < 1:
        raise argparse.ArgumentTypeError(f"expected a level in (0.5, 1) such as 0.95, got "
                                         f"{text!r}")
    return value


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser(
        "allocate", help="least-cost tolerances that meet a probabilistic target",
        description=DESCRIPTION, formatter_class=formatter_class)
    p.add_argument("config", type=path_argument, metavar="CONFIG", help="study config (TOML)")
    p.add_argument("-o", "--out", type=path_argument, metavar="DIR", required=True,
                   help="output folder (created if missing)")
    p.add_argument("--target", metavar="TARGET",
                   help="the limit to meet, e.g. \"contact_probability<=0.01\" (overrides "
                        "[allocate] target; one of the two is needed)")
    p.add_argument("--samples", type=_positive_int, metavar="N",
                   help="assemblies of every evaluation (overrides [allocate] samples; "
                        "default: [study] samples)")
    p.add_argument("--verify-samples", type=_positive_int, metavar="N",
                   help="fresh assemblies of the verification run (overrides [allocate] "
                        "verify_samples; default: 4 x samples)")
    p.add_argument("--seed", type=_seed, metavar="S",
                   help="seed of the common sample (overrides study.seed); the "
                        "verification's seed is derived from it")
    p.add_argument("--confidence", type=_confidence, metavar="C",
                   help="one-sided confidence of the upper bound that must meet the limit "
                        "(overrides [allocate] confidence; default: 0.95)")
    p.add_argument("--workers", type=_workers, default=1, metavar="N",
                   help="worker processes of each study (1 is fastest for small studies)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    return p


def _check_out(out: Path):
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} exists and is not a folder")
    parent = out.absolute().parent
    if not parent.is_dir():
        raise UsageError(f"--out {out}: folder {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"--out {out}: cannot write to {parent}")


def _command_line(args) -> str:
    parts = ["tolsim", "allocate", args.config, "-o", str(args.out)]
    for flag, value in (("--target", args.target), ("--samples", args.samples),
                        ("--verify-samples", args.verify_samples), ("--seed", args.seed),
                        ("--confidence", args.confidence)):
        if value is not None:
            parts += [flag, str(value)]
    if args.workers != 1:
        parts += ["--workers", str(args.workers)]
    return shlex.join(parts)


def summary(result, tolerance_rows, files, elapsed) -> str:
    """Plain-text summary of an allocation."""
    search = result.search
    opt = search.optimum.evaluation
    v = result.verification
    conf = f"{100 * result.confidence:g} %"
    lines = [f"target: {result.target.describe()} ({conf} upper bound)",
             f"search: {len(search.points)} evaluations of {result.samples:,} assemblies "
             f"(seed {result.seed}, {result.search_seconds:.1f} s); {search.status}"]
    width = max(len(c.source) for c in result.sources)
    for cost, scale in zip(result.sources, search.optimum.scales, strict=True):
        keys = ", ".join(f"{k} {g} -> {a}" for k, g, a in tolerance_rows.get(cost.source, []))
        lines.append(f"  {cost.source:<{width}}  x {scale:<6.4g} {keys}")
    if result.fixed_sources:
        lines.append(f"  kept as given: {', '.join(result.fixed_sources)}")
    lines.append(f"cost: {result.cost_ratio:.3g} of the config as given")
    lines.append(f"optimisation sample: estimate {opt.estimate:.4g}, upper bound "
                 f"{opt.upper:.4g} (limit {result.limit:.4g})")
    verdict = "meets the target" if result.verified else "does NOT meet the target"
    lines.append(f"verification ({result.verify_samples:,} fresh assemblies, seed "
                 f"{result.verify_seed}): estimate {v.estimate:.4g}, "
                 f"{100 * (2 * result.confidence - 1):g} % interval [{v.lower:.4g}, "
                 f"{v.upper:.4g}]: the upper bound {verdict}")
    lines.append(f"wrote {files['allocate.html']} and {len(files) - 1} more files to "
                 f"{os.path.dirname(files['allocate.html'])} ({elapsed:.1f} s)")
    return "\n".join(lines)


def run(args) -> int:
    from tolsim.io.config import ConfigError, load_config, parse_config  # noqa: PLC0415
    from tolsim.io.config.allocation import (  # noqa: PLC0415
        allocated_config_text,
        given_scales,
        tolerance_lines,
    )
    from tolsim.study.design.allocate import (  # noqa: PLC0415
        AllocationInfeasible,
        AllocationSettings,
        check_allocation,
        parse_target,
        verification_seed,
    )

    started = time.perf_counter()
    out = Path(args.out)
    _check_out(out)
    try:
        config = load_config(args.config).with_overrides(seed=args.seed)
        target = parse_target(args.target) if args.target is not None else None
        settings = (config.allocation or AllocationSettings()).with_overrides(
            target=target, samples=args.samples, verify_samples=args.verify_samples,
            confidence=args.confidence)
        target, sources, samples, verify_samples = check_allocation(config, settings)
        # the allocated config must be writable before any work (no inline tables)
        allocated_config_text(config.text, {c.source: 1.0 for c in sources})
    except (ConfigError, ValueError) as exc:
        raise UsageError(" ".join(str(exc).split())) from None
    verify_seed = verification_seed(config.study.seed)

    def optimum_text(scales, comment=""):
        return allocated_config_text(config.text, scales, samples=verify_samples,
                                     seed=verify_seed, comment=comment)

    def optimum_config(scales):
        return parse_config(optimum_text(scales), f"{args.config} (allocated)")

    import tqdm  # noqa: PLC0415

    from tolsim.study.design.allocate import run_allocation  # noqa: PLC0415

    quiet = True if args.quiet else None
    bar = tqdm.tqdm(total=settings.max_evaluations, unit="eval", file=sys.stderr,
                    desc="tolsim allocate", disable=quiet, smoothing=0.1)
    verify_bar = None

    def on_point(point):
        bar.update(1)
        bar.set_postfix_str(f"{point.stage}, upper {point.evaluation.upper:.3g}",
                            refresh=False)

    def finish_search():
        if not bar.disable and bar.total != bar.n:  # the search ended within its budget
            bar.total = bar.n
            bar.refresh()
        bar.close()

    def on_assemblies(n):
        nonlocal verify_bar
        if verify_bar is None:
            finish_search()
            verify_bar = tqdm.tqdm(total=verify_samples, unit="asm", unit_scale=True,
                                   file=sys.stderr, desc="verification", disable=quiet)
        verify_bar.update(n)

    try:
        result = run_allocation(config, settings, workers=args.workers, progress=on_point,
                                study_progress=on_assemblies, optimum_config=optimum_config)
    except (AllocationInfeasible, ValueError) as exc:
        raise UsageError(" ".join(str(exc).split())) from None
    finally:
        finish_search()
        if verify_bar is not None:
            verify_bar.close()
    scales = result.scales
    before = given_scales(config.text)
    written = {s: float(f"{before.get(s, 1.0) * v:.4g}") for s, v in scales.items()}
    verdict = "meets" if result.verified else "does NOT meet"
    v = result.verification
    comment = (f"tolsim allocate: the least-cost tolerances for {result.target} "
               f"({100 * result.confidence:g} % upper bound),\n"
               f"from {args.config}; cost {result.cost_ratio:.3g} of the config as given.\n"
               "Each allocated [tolerances.*] table has its 'scale'. [study] seed and samples "
               "are those of the\n"
               "verification run, so 'tolsim run' on this file reproduces it: estimate "
               f"{v.estimate:.4g}, upper bound\n{v.upper:.4g}, which {verdict} the limit "
               f"{result.limit:.4g}.\n"
               f"Made by: {_command_line(args)}")
    text = optimum_text(scales, comment)
    rows = tolerance_lines(config.text, config, scales)
    from tolsim.reports.allocate import write_allocation  # noqa: PLC0415

    try:
        files = write_allocation(result, out, optimum_text=text, tolerance_rows=rows,
                                 written_scales=written, command=_command_line(args),
                                 config_path=args.config)
    except OSError as exc:
        raise UsageError(f"cannot write to {out}: {exc.strerror or exc}") from None
    if not args.quiet:
        print(summary(result, rows, files, time.perf_counter() - started))
    return 0 if result.verified else 1  # a script can tell an unverified optimum
