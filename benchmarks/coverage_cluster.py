"""Coverage of the cluster (assembly-as-sampling-unit) intervals on a correlated train.

The synthetic train of ``tests/study/test_estimators.py``: equicorrelated standard normals
x_ab = sqrt(rho) z_a + sqrt(1 - rho) e_ab, rho = 0.9, trains of 10 balls; with
L = -Phi^-1(p / 2) the true fraction out of spec is p and the true Cpk = Cp = L / 3. A second
Cpk case shifts every ball by mu = 0.5 (true Cpk = (L - 0.5) / 3).

For each case, R seeded repeats (default 400, the full count of the requirement; the test
keeps 150) of A assemblies, and the share of repeats whose 95 % interval covers the truth,
with its binomial sd sqrt(c (1 - c) / R), for

* proportion: the cluster interval (:func:`tolsim.study.statistics.intervals.cluster_proportion`:
  ratio estimator, delta method, Korn-Graubard effective n, Wilson, effective df), the same
  with Clopper-Pearson, the same with K&G's design df (A - 1), and the old independent-ball
  Wilson interval of k of N;
* Cpk: the delta method over assemblies
(:func:`~tolsim.study.statistics.intervals.cluster_capability`)
  and the old Bissell interval (independent balls), plus the cluster Cp interval.

Also printed: the mean width of each proportion interval relative to p, the mean estimated
design effect against its closed form (one-dimensional quadrature), and the time.

Run: ``python benchmarks/coverage_cluster.py [--repeats 400] [--sweep] [--rare]``
(``--sweep``: p = 1e-3 with A = 1000 ... 50 000, expected counts 10 ... 500; ``--rare``:
p = 1e-4 with A = 200 000, ~20 s per 400 repeats).
"""

import argparse
import time

import numpy as np
from scipy.integrate import quad
from scipy.special import ndtr, ndtri
from scipy.stats import norm

from tolsim.study.statistics.intervals import (
    ClusterMoments,
    assembly_totals,
    cluster_capability,
    cluster_proportion,
    ratio_variance,
    wilson_interval,
)
from tolsim.study.statistics.quality import capability

BALLS = 10
RHO = 0.9
SHIFT = 0.5


def closed_form_design_effect(p, rho=RHO, balls=BALLS):
    """Var(k_a) / (m p (1 - p)); k_a | z ~ Bin(m, q(z)), q(z) = P(|x| > L | z)."""
    lim, a, b = -ndtri(p / 2), np.sqrt(rho), np.sqrt(1 - rho)

    def q(z):
        return ndtr((-lim - a * z) / b) + ndtr((-lim + a * z) / b)

    def expect(f):
        return quad(lambda z: f(z) * norm.pdf(z), -12, 12, epsabs=0, epsrel=1e-10, limit=200,
                    points=[-lim / a, lim / a])[0]

    eq, eq2 = expect(q), expect(lambda z: q(z) ** 2)
    return (balls * (eq - eq2) + balls ** 2 * (eq2 - eq * eq)) / (balls * p * (1 - p))


def run_case(p, assemblies, repeats, seed):
    lim = float(-ndtri(p / 2))
    cpk_true, cpk_shift = lim / 3, (lim - SHIFT) / 3
    names = ("cluster, Wilson", "cluster, Clopper-Pearson", "cluster, Wilson, design df",
             "old: Wilson k of N")
    hits = {k: 0 for k in names + ("Cpk cluster", "Cpk Bissell (old)", "Cp cluster",
                                   f"Cpk cluster, mu = {SHIFT}")}
    width = {k: 0.0 for k in names}
    deff = 0.0
    start = time.perf_counter()
    for r in range(repeats):
        rng = np.random.default_rng([seed, r])
        x = (np.sqrt(RHO) * rng.standard_normal((assemblies, 1))
             + np.sqrt(1 - RHO) * rng.standard_normal((assemblies, BALLS)))
        m = ClusterMoments.from_totals(assembly_totals(x, lim))
        w = cluster_proportion(m)
        intervals = {
            names[0]: (w.lower, w.upper),
            names[1]: (lambda q: (q.lower, q.upper))(
                cluster_proportion(m, interval="clopper-pearson")),
            names[2]: (lambda q: (q.lower, q.upper))(cluster_proportion(m, df_rule="design")),
            names[3]: wilson_interval(w.successes, w.trials),
        }
        for k, (lo, hi) in intervals.items():
            hits[k] += lo <= p <= hi
            width[k] += (hi - lo) / p
        deff += ratio_variance(m)[1] * w.trials / (p * (1 - p))
        cap = cluster_capability(m, lim)
        mu = m.mean[2] / m.mean[0]
        old = capability(mu, np.sqrt(m.mean[3] / m.mean[0] - mu * mu), w.trials, lim)
        shifted = cluster_capability(ClusterMoments.from_totals(assembly_totals(x + SHIFT, lim)),
                                     lim)
        hits["Cpk cluster"] += cap.cpk_lower <= cpk_true <= cap.cpk_upper
        hits["Cpk Bissell (old)"] += old.cpk_lower <= cpk_true <= old.cpk_upper
        hits["Cp cluster"] += cap.cp_lower <= cpk_true <= cap.cp_upper
        hits[f"Cpk cluster, mu = {SHIFT}"] += shifted.cpk_lower <= cpk_shift <= shifted.cpk_upper
    seconds = time.perf_counter() - start
    print(f"\np = {p:g}, A = {assemblies} assemblies x {BALLS} balls, rho = {RHO}, expected "
          f"k = {p * assemblies * BALLS:g}; {repeats} repeats, {seconds:.1f} s")
    print(f"  design effect: mean estimate {deff / repeats:.3f}, closed form "
          f"{closed_form_design_effect(p):.3f}")
    for k, h in hits.items():
        c = h / repeats
        extra = f"   mean width {width[k] / repeats:.3f} p" if k in width else ""
        print(f"  {k:32s} coverage {c:6.3f} +- {np.sqrt(c * (1 - c) / repeats):.3f}{extra}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=400)
    ap.add_argument("--seed", type=int, default=20181109)
    ap.add_argument("--sweep", action="store_true",
                    help="p = 1e-3 at expected counts 10 ... 500 (small-count behaviour)")
    ap.add_argument("--rare", action="store_true", help="p = 1e-4 with 200 000 assemblies")
    args = ap.parse_args(argv)
    cases = [(1e-3, 20_000), (1e-2, 2_000)]
    if args.sweep:
        cases += [(1e-3, a) for a in (1_000, 2_000, 5_000, 10_000, 50_000)]
    if args.rare:
        cases += [(1e-4, 200_000)]
    for p, a in cases:
        run_case(p, a, args.repeats, args.seed)


if __name__ == "__main__":
    main()
