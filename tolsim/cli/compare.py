"""``tolsim compare``: studies side by side in one self-contained HTML report and a CSV.

A thin layer over :func:`tolsim.reports.compare.compare_runs`.
"""

import os
import sys
import time

from tolsim.cli import UsageError, path_argument

DESCRIPTION = """\
Put two or more result files of 'tolsim run' side by side. The first file is the reference;
every other run is compared with it. Writes into the output folder:

  compare.html   one self-contained page (figures embedded): the runs and whether they share
                 random numbers with the reference, the config keys whose values differ
                 (taken from the config text stored in each file; keys set in one run only
                 included), the key statistics of every run with their 95 % intervals, the
                 difference of each to the reference with its own 95 % interval, and the
                 overlaid distributions
  compare.csv    one row per statistic and run: estimate, ci_lower, ci_upper, units, and the
                 difference to the reference with its interval
  contact_probability.png, velocity_deviation.png, survival.png
                 P(contact) with intervals as a forest plot, the epsilon histograms and the
                 survival curves of the time to first contact, overlaid

Statistics: P(contact) (with its bounds when trains are unresolved), the mean, standard
deviation and quantiles of epsilon, the fraction out of spec and Cpk (with a limit on
|epsilon|), the quantiles of the time to first contact, and the carriage stiffness (a study
with a [carriage]).

The differences are unpaired (the files hold aggregates, a paired interval needs the
outcome of every assembly in both runs): Newcombe's hybrid score interval for P(contact),
Welch's for means and standard deviations, the MOVER of Zou & Donner for quantiles,
fraction out of spec and Cpk. Runs with the reference's seed, block size and sampling share
its random numbers; for them the unpaired interval is conservative, and the report says so.

Every file's data are verified against the SHA-256 checksums 'tolsim run' stored in it: a
file that fails (damaged, or altered after it was written) is refused, naming the file and
the variable; --no-verify compares anyway, for forensics. A file written before tolsim stored
checksums is compared with a warning.

The file of a what-if sweep (a config with [sweep]) is refused: 'tolsim report SWEEP.nc'
puts its points side by side (a table, and curves against the swept key).

examples:
  tolsim run configs/yaw_moment_tolerances.toml -o yaw.nc
  tolsim run configs/whatif_no_yaw_moment.toml -o no_yaw.nc
  tolsim compare yaw.nc no_yaw.nc -o yaw-vs-no-yaw
  tolsim run configs/yaw_moment_tolerances.toml --seed 2 -o yaw_seed2.nc
  tolsim compare yaw.nc yaw_seed2.nc no_yaw.nc -o compare
"""


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser("compare", help="compare study result files side by side",
                              description=DESCRIPTION, formatter_class=formatter_class)
    p.add_argument("results", type=path_argument, metavar="RESULTS.nc", nargs="+",
                   help="two or more result files of 'tolsim run', the reference first")
    p.add_argument("-o", "--out", type=path_argument, metavar="DIR", required=True,
                   help="output folder (created if missing)")
    p.add_argument("--no-verify", action="store_true",
                   help="do not verify the files' checksums (forensics: a damaged file)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    return p


def run(args) -> int:
    if len(args.results) < 2:
        raise UsageError(f"needs at least two result files to compare, got "
                         f"{len(args.results)} ({args.results[0]})")
    out = args.out
    if os.path.exists(out) and not os.path.isdir(out):
        raise UsageError(f"--out {out} exists and is not a folder")
    from tolsim.reports.compare import NotAResult, compare_runs  # noqa: PLC0415
    from tolsim.reports.result_view import FailsChecksum  # noqa: PLC0415

    started = time.perf_counter()

    def say(msg):
        if not args.quiet:
            print(f"[{time.perf_counter() - started:5.1f} s] {msg}", file=sys.stderr)

    try:
        result = compare_runs(args.results, out, progress=say, verify=not args.no_verify)
    except FailsChecksum as exc:
        raise UsageError(f"{exc}; --no-verify compares anyway (forensics)") from None
    except NotAResult as exc:
        raise UsageError(str(exc)) from None
    except OSError as exc:
        raise UsageError(f"cannot write to {out}: {exc}") from None
    if not args.quiet:
        print(f"wrote {result.html}, {result.csv} and {len(result.figures)} figures "
              f"({time.perf_counter() - started:.1f} s)")
    return 0
