"""``tolsim paper``: reproduce the source paper's Fig. 4, 7, 9 and Table 2, and go one step
beyond it (the balls of Sec. 3.2 after they touch, labelled as tolsim's extension).

A thin layer over :func:`tolsim.reports.paper.make_paper`.
"""

import os
import sys
import time

from tolsim.cli import UsageError, path_argument

DESCRIPTION = """\
Reproduce the results of Lin, Okwudire, Duan and Wou (IMECE2018-88033) from tolsim's models
and write them, with the paper's own numbers beside ours, to a folder:

  fig4.png    friction force and spin moment of one contact against c/a (Fig. 4)
  fig7.png    epsilon over rho and theta: full model, point model, formula, difference (Fig. 7)
  fig9.png    ball-to-ball contact of the two balls of Sec. 3.2, cases (a) and (b) (Fig. 9)
  after_contact.png
              beyond the paper (tolsim's extension): the two balls of Sec. 3.2 case (a)
              after they touch, their contact force and the carriage friction force
  table2.csv  Table 2, ours and the paper's values (table2.md: the same in Markdown)
  README.md   what matches the paper, what does not, by how much and why

examples:
  tolsim paper                         # writes reports/paper/
  tolsim paper --out /tmp/paper --quick
"""


#: Where ``tolsim paper`` writes when not told: a folder of the working directory.
DEFAULT_OUT = os.path.join("reports", "paper")


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser("paper", help="reproduce the source paper's figures and Table 2",
                              description=DESCRIPTION, formatter_class=formatter_class)
    p.add_argument("--out", type=path_argument, default=DEFAULT_OUT, metavar="DIR",
                   help=f"output folder, created if missing (any other than {DEFAULT_OUT} "
                        "must be in an existing folder)")
    p.add_argument("--quick", action="store_true",
                   help="coarse grids (seconds; for tests and previews)")
    p.add_argument("--quiet", action="store_true", help="print nothing but errors")
    return p


def run(args) -> int:
    out = args.out
    if os.path.exists(out) and not os.path.isdir(out):
        raise UsageError(f"--out {out} exists and is not a folder")
    parent = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(parent) and out != DEFAULT_OUT:  # (a typo, not a new tree)
        raise UsageError(f"--out {out}: parent folder {parent} does not exist")
    from tolsim.reports.paper import make_paper  # noqa: PLC0415

    started = time.perf_counter()

    def say(msg):
        if not args.quiet:
            print(f"[{time.perf_counter() - started:5.1f} s] {msg}", file=sys.stderr)

    try:
        result = make_paper(out, quick=args.quick, progress=say)
    except OSError as exc:
        raise UsageError(f"cannot write to {out}: {exc}") from None
    if not args.quiet:
        checks = result.summary["table2_checks"]
        bad = [c for c in checks if not c["ok"]]
        print(f"wrote {len(result.files)} files to {out} in {result.elapsed:.1f} s")
        print(f"Table 2: {len(checks) - len(bad)} of {len(checks)} comparisons with the paper "
              "within tolerance" + ("" if not bad else "; outside: " + ", ".join(
                  f"case ({c['case']}) ball {c['ball']} {c['what']}: {c['difference']:+.3f} pp"
                  for c in bad)))
    return 0
