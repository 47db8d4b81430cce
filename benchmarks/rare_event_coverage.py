"""Coverage of the rare-event estimators on public reliability problems (tolsim issue 23).

For every problem of ``benchmarks/reliability_problems.py`` and every estimator, ``--repeats``
seeded runs; the table gives, per problem x estimator: the mean of P / truth over the runs
with a number, the share of runs ``ok``, the coverage of the ``ok`` runs (their interval holds
the truth), the ``ok`` runs whose interval misses the truth by more than a factor of 3
(must be 0), and the mean evaluations. Estimators:

``importance_1``   FORM from the origin only, IS around that one design point (as before
                   issue 23, now with its diagnostics)
``importance``     FORM from several starts, IS over the mixture of every design point
``subset_alone``   :func:`subset_simulation` without design points (genealogy CV, ancestor
                   count): a reference, not a method of ``estimate``. It cannot see a mode
                   that its intermediate levels lost (RP110) and returns ``ok`` there.
``subset``         :func:`tolsim.rare_events.estimate` ``method="subset"``: FORM first, then
                   subset simulation with its per-design-point check (``lost_modes``) and
                   the FORM cross-check of the total
``rare``           ``method="rare"``: one FORM search shared, subset simulation (half size,
                   own seed) and importance sampling (own seed) cross-checked
``monte_carlo``    100 000 plain samples (Clopper-Pearson)

Run: ``python benchmarks/rare_event_coverage.py [--repeats 100] [--only RP89 RP35]``.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from reliability_problems import PROBLEMS  # noqa: E402

from tolsim.rare_events import estimate, importance_sampling, subset_simulation  # noqa: E402

SEED = 23_2026
ESTIMATORS = {
    "importance_1": lambda p, s: importance_sampling(p.g, p.dimension, s, restarts=0),
    "importance": lambda p, s: estimate(p.g, p.dimension, "importance", s),
    "subset_alone": lambda p, s: subset_simulation(p.g, p.dimension, s),
    "subset": lambda p, s: estimate(p.g, p.dimension, "subset", s),
    "rare": lambda p, s: estimate(p.g, p.dimension, "rare", s),
    "monte_carlo": lambda p, s: estimate(p.g, p.dimension, "monte_carlo", s),
}


def misses_by_3(result, truth):
    """The interval misses the truth by more than a factor of 3."""
    return result.ci_upper < truth / 3.0 or result.ci_lower > 3.0 * truth


def run(problem, estimator, repeats):
    """The row of the table for one problem and estimator."""
    results = [ESTIMATORS[estimator](problem, np.random.SeedSequence(SEED, spawn_key=(r,)))
               for r in range(repeats)]
    truth = problem.truth
    ok = [r for r in results if r.ok]
    numbers = [r.probability for r in results if np.isfinite(r.probability)]
    statuses = {}
    for r in results:
        statuses[r.status] = statuses.get(r.status, 0) + 1
    return dict(
        mean_ratio=float(np.mean(numbers)) / truth if numbers else float("nan"),
        ok_mean_ratio=float(np.mean([r.probability for r in ok])) / truth if ok else float("nan"),
        ok_share=len(ok) / repeats,
        coverage=(float(np.mean([r.ci_lower <= truth <= r.ci_upper for r in ok]))
                  if ok else float("nan")),
        wrong_ok=sum(misses_by_3(r, truth) for r in ok),
        evaluations=float(np.mean([r.evaluations for r in results])),
        statuses=statuses)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=100)
    parser.add_argument("--only", nargs="*", default=None, help="problems to run")
    parser.add_argument("--estimators", nargs="*", default=list(ESTIMATORS))
    args = parser.parse_args(argv)
    names = args.only or list(PROBLEMS)
    print(f"{args.repeats} seeded repeats per problem and estimator\n")
    print("| problem | P exact | estimator | mean P/truth (all with a number) | mean P/truth "
          "(ok) | ok runs | coverage of ok | ok off > 3x | evaluations | statuses |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    failed = False
    for name in names:
        problem = PROBLEMS[name]
        for estimator in args.estimators:
            t0 = time.perf_counter()
            row = run(problem, estimator, args.repeats)
            failed |= row["wrong_ok"] > 0
            statuses = ", ".join(f"{k} {v}" for k, v in sorted(row["statuses"].items()))
            print(f"| {name} | {problem.truth:.3g} | {estimator} | {row['mean_ratio']:.3f} | "
                  f"{row['ok_mean_ratio']:.3f} | {100 * row['ok_share']:.0f} % | "
                  f"{100 * row['coverage']:.0f} % | {row['wrong_ok']} | "
                  f"{row['evaluations']:,.0f} | {statuses} |", flush=True)
            print(f"<!-- {time.perf_counter() - t0:.1f} s -->", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
