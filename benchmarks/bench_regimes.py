"""Throughput of the full model across regimes (issue 25): smooth (A) and sticking (B) balls.

Prints, measured in this run, on all cores:

* balls per second of :func:`tolsim.physics.velocity.full.full` on a batch of random balls
  from exact statics (bottom groove turned by up to 3 deg, top by up to 1 deg, |rho| <= 0.985,
  N_y = 200 N), which mixes regimes A and B, and on its regime-A and regime-B parts alone;
* the same batches with ``nonsmooth=False`` (the smooth Newton alone, as before issue 25,
  which leaves the regime-B balls unconverged);
* the baseline: the NumPy/SciPy minimiser of D
  (:func:`tolsim.physics.velocity.regimes.minimise_dissipation`) on a few of the balls, and
  the largest |epsilon| difference to ``full`` on them.

Run: ``python benchmarks/bench_regimes.py [--balls N] [--reference-balls M]``.
"""

import argparse
import time

import numba
import numpy as np
from bench_full import regime_balls as random_balls  # run from benchmarks/
from bench_full import timed

from tolsim.physics.velocity.full import full
from tolsim.physics.velocity.regimes import minimise_dissipation


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balls", type=int, default=4000)
    parser.add_argument("--reference-balls", type=int, default=2)
    args = parser.parse_args(argv)

    dbeta, force = random_balls(args.balls)
    full(dbeta[:4], force[:4])  # compile / load the cache
    full(dbeta[:4], force[:4], nonsmooth=False)
    res = full(dbeta, force)
    parts = {"mixed": np.ones(len(dbeta), bool), "regime A": res.regime == 1,
             "regime B": res.regime == 2}
    print(f"full model, {len(dbeta)} random balls from exact statics, "
          f"{numba.config.NUMBA_NUM_THREADS} cores; regime A {parts['regime A'].sum()}, "
          f"B {parts['regime B'].sum()}, unsolved {(res.regime == 0).sum()}")
    for name, sel in parts.items():
        t_new, new = timed(full, dbeta[sel], force[sel])
        t_old, old = timed(full, dbeta[sel], force[sel], nonsmooth=False)
        print(f"  {name:9s} {sel.sum():6d} balls: full {sel.sum() / t_new:9.0f} balls/s "
              f"(converged {new.converged.mean():.3f}); Newton only {sel.sum() / t_old:9.0f} "
              f"balls/s (converged {old.converged.mean():.3f})")
    picks = np.r_[np.flatnonzero(parts["regime A"])[:1],
                  np.flatnonzero(parts["regime B"])[:max(1, args.reference_balls - 1)]]
    t0 = time.perf_counter()
    ref = [minimise_dissipation(dbeta[j], force[j]) for j in picks]
    t_ref = time.perf_counter() - t0
    diff = max(abs(r.velocity_deviation - res.velocity_deviation[j])
               for r, j in zip(ref, picks, strict=True))
    print(f"  baseline NumPy/SciPy minimiser of D: {len(picks) / t_ref:.3f} balls/s "
          f"({len(picks)} balls); max |eps_full - eps_ref| = {diff:.1e}")


if __name__ == "__main__":
    main()
