"""``tolsim report``: a self-contained HTML report of a study result file, and its PDF; or
of a sweep file, the sweep report.

A thin layer over :func:`tolsim.reports.study.make_report` and, for a file of a what-if sweep
(issue 14), :func:`tolsim.reports.sweep.make_sweep_report`.
"""

import argparse
import os
import sys
import time

from tolsim.cli import UsageError, integer_at_least, path_argument

DESCRIPTION = """\
Write an HTML report (report.html, figures embedded, plus the PNGs) and the same report as
PDF with fields for the reviewers' sign-off (report.pdf) of a result file of 'tolsim run': the
verdict against the config's spec limits (pass / fail / undecided at 95 % confidence, or "no
spec limit given"), what was studied with the sampled inputs and an assumptions table (each
with where it comes from), the epsilon distribution with any spec limit, the contact
probability with its confidence interval, the survival curve of the time to first contact,
spot checks of the study's velocity model against the full model (half of them near the spec
limit), the tolerances that drive the risk (Sobol' indices) and, with a limit on |epsilon|,
the fraction out of spec and Cpk.

For a study with a [carriage] (an assembly is a carriage with one train per track) the
report adds a section on the carriage: the load case in catalogue terms (radial and lateral
load, pitching, yawing and rolling moments), the preload (ball oversize and force per
contact), the tracks with the nominal load distribution (ball normal load N_y and side force
ratio rho along the rail, per track: carriage.png), the carriage displacement and stiffness
(N/um, N m/urad) of the nominal assembly with their mean, std, min and max over the sampled
carriages, and the carriages not solved. Per-ball and per-pair figures then draw one series
per track, and P(contact) is per assembly: contact in any of its trains.

The file's data are verified against the SHA-256 checksums 'tolsim run' stored in it: a file
that fails (damaged, or altered after it was written) is refused, naming the variable;
--no-verify reports on it anyway, for forensics. A file written before tolsim stored
checksums is reported on with a warning.

When the file holds no sensitivity indices they are computed from the config stored in the
file (same seed); --sensitivity-samples sets the cost, --no-sensitivity skips it.

For the file of a what-if sweep (a config with [sweep]) the report is a sweep report:
report.html with what was swept (keys, values, units, outer or zip, and the common random
numbers every point shares), P(contact) with its 95 % interval band against the swept key
(contact_probability.png; two or more outer keys: one curve per value of the others; zip:
against the point number), the std and quantiles of epsilon against the key
(velocity_deviation.png), the friction increase and P(friction exceedance) of a study with
[contact] (friction.png), a table per point (also as points.csv) and the verdict of every
point against the config's spec limits. A sweep has no PDF and no Sobol' analysis
(--sensitivity-samples, --no-sensitivity and --no-pdf do not apply).

examples:
  tolsim run configs/yaw_moment_tolerances.toml -o yaw.nc
  tolsim report yaw.nc -o yaw-report
  tolsim run configs/carriage_preload.toml -o carriage.nc
  tolsim report carriage.nc
  tolsim run configs/sweep_yaw_moment.toml -o sweep_yaw.nc
  tolsim report sweep_yaw.nc -o sweep_yaw-report
"""


_sample_count = integer_at_least(2, "an integer >= 2")


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser("report", help="HTML and PDF report of a study result file "
                                             "(HTML of a sweep)",
                              description=DESCRIPTION, formatter_class=formatter_class)
    p.add_argument("result", type=path_argument, metavar="RESULTS.nc",
                   help="result file of 'tolsim run' (a study or a sweep)")
    p.add_argument("-o", "--out", type=path_argument, metavar="DIR", default=argparse.SUPPRESS,
                   help="output folder (default: RESULTS-report next to the file)")
    p.add_argument("--sensitivity-samples", type=_sample_count, metavar="N",
                   default=argparse.SUPPRESS,
                   help="assemblies per base sample of the Sobol' analysis (default 1024, "
                        "64 for along-track propagation)")
    p.add_argument("--no-sensitivity", action="store_true",
                   help="do not compute sensitivity indices missing from the file")
    p.add_argument("--no-pdf", action="store_true", help="write no report.pdf")
    p.add_argument("--no-verify", action="store_true",
                   help="do not verify the file's checksums (forensics: a damaged file)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    return p


def run(args) -> int:
    from tolsim.reports.result_view import FailsChecksum  # noqa: PLC0415
    from tolsim.reports.study import NotAResult, make_report  # noqa: PLC0415

    out = getattr(args, "out", None) or os.path.splitext(args.result)[0] + "-report"
    if os.path.exists(out) and not os.path.isdir(out):
        raise UsageError(f"--out {out} exists and is not a folder")
    started = time.perf_counter()

    def say(msg):
        if not args.quiet:
            print(f"[{time.perf_counter() - started:5.1f} s] {msg}", file=sys.stderr)

    from tolsim.reports.sweep import is_sweep_file  # noqa: PLC0415

    if is_sweep_file(args.result):
        return _sweep_report(args, out, say, started)
    try:
        result = make_report(args.result, out, sensitivity=not args.no_sensitivity,
                             sensitivity_samples=getattr(args, "sensitivity_samples", None),
                             progress=say, pdf=not args.no_pdf, verify=not args.no_verify)
    except FailsChecksum as exc:
        raise UsageError(f"{exc}; --no-verify reports on it anyway (forensics)") from None
    except NotAResult as exc:
        raise UsageError(str(exc)) from None
    except OSError as exc:
        raise UsageError(f"cannot write to {out}: {exc}") from None
    if not args.quiet:
        print(f"wrote {result.html}{f', {result.pdf}' if result.pdf else ''} and "
              f"{len(result.figures)} figures ({time.perf_counter() - started:.1f} s)")
    return 0


def _sweep_report(args, out, say, started) -> int:
    """``tolsim report`` on a sweep file (:func:`tolsim.reports.sweep.make_sweep_report`)."""
    from tolsim.reports.result_view import FailsChecksum  # noqa: PLC0415
    from tolsim.reports.study import NotAResult  # noqa: PLC0415
    from tolsim.reports.sweep import NotASweep, make_sweep_report  # noqa: PLC0415

    try:
        result = make_sweep_report(args.result, out, progress=say, verify=not args.no_verify)
    except FailsChecksum as exc:
        raise UsageError(f"{exc}; --no-verify reports on it anyway (forensics)") from None
    except (NotAResult, NotASweep) as exc:
        raise UsageError(f"{args.result}: {exc}" if isinstance(exc, NotASweep)
                         else str(exc)) from None
    except OSError as exc:
        raise UsageError(f"cannot write to {out}: {exc}") from None
    if not args.quiet:
        figures = ", ".join(result.figures.values())
        print(f"wrote {result.html}, {result.csv} and {len(result.figures)} figures "
              f"({figures}): the sweep report of {result.layout.size} "
              f"point{'' if result.layout.size == 1 else 's'} "
              f"({time.perf_counter() - started:.1f} s)")
    return 0
