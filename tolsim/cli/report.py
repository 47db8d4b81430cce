"""``tolsim report``: a self-contained HTML report of a study result file, and its PDF.

A thin layer over :func:`tolsim.reports.study.make_report`.
"""

import argparse
import os
import sys
import time

from tolsim.cli import UsageError, integer_at_least

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

When the file holds no sensitivity indices they are computed from the config stored in the
file (same seed); --sensitivity-samples sets the cost, --no-sensitivity skips it.

examples:
  tolsim run configs/yaw_moment_tolerances.toml -o yaw.nc
  tolsim report yaw.nc -o yaw-report
  tolsim run configs/carriage_preload.toml -o carriage.nc
  tolsim report carriage.nc
"""


_sample_count = integer_at_least(2, "an integer >= 2")


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser("report", help="HTML and PDF report of a study result file",
                              description=DESCRIPTION, formatter_class=formatter_class)
    p.add_argument("result", metavar="RESULTS.nc", help="result file of 'tolsim run'")
    p.add_argument("-o", "--out", metavar="DIR", default=argparse.SUPPRESS,
                   help="output folder (default: RESULTS-report next to the file)")
    p.add_argument("--sensitivity-samples", type=_sample_count, metavar="N",
                   default=argparse.SUPPRESS,
                   help="assemblies per base sample of the Sobol' analysis (default 1024, "
                        "64 for along-track propagation)")
    p.add_argument("--no-sensitivity", action="store_true",
                   help="do not compute sensitivity indices missing from the file")
    p.add_argument("--no-pdf", action="store_true", help="write no report.pdf")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    return p


def run(args) -> int:
    from tolsim.reports.study import NotAResult, make_report

    out = getattr(args, "out", None) or os.path.splitext(args.result)[0] + "-report"
    if os.path.exists(out) and not os.path.isdir(out):
        raise UsageError(f"--out {out} exists and is not a folder")
    started = time.perf_counter()

    def say(msg):
        if not args.quiet:
            print(f"[{time.perf_counter() - started:5.1f} s] {msg}", file=sys.stderr)

    try:
        result = make_report(args.result, out, sensitivity=not args.no_sensitivity,
                             sensitivity_samples=getattr(args, "sensitivity_samples", None),
                             progress=say, pdf=not args.no_pdf)
    except NotAResult as exc:
        raise UsageError(str(exc)) from None
    except OSError as exc:
        raise UsageError(f"cannot write to {out}: {exc}") from None
    if not args.quiet:
        print(f"wrote {result.html}{f', {result.pdf}' if result.pdf else ''} and "
              f"{len(result.figures)} figures ({time.perf_counter() - started:.1f} s)")
    return 0
