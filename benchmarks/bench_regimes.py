"""Throughput of the full model across regimes (issue 25): smooth (A) and sticking (B) balls.

Prints, measured in this run, on all cores:

* balls per second of :func:`tolsim.physics.velocity.full.full` on a batch of random balls
  from exact statics (bottom groove turned by up to 3 deg, top by up to 1 deg, |rho| <= 0.985,
  N_y = 200 N), which mixes regimes A and B, and on its regime-A and regime-B parts alone;
* the same batches with ``nonsmooth=False`` (the smooth Newton alone, as before issue 25,
  which leaves the regime-B balls unconverged);
* the baseline: the NumPy/SciPy minimiser of D
  (:func:`tolsim.physics.velocity.regimes.minimise_dissipation`) on a few of the balls, and
  the largest |epsilon| difference to ``full`` on them;
* three-point balls as a carriage without preload has them (``configs/carriage_preload.toml``
  at 0 um oversize along the track, seed 12; most on a stick line, many nearly two-point):
  balls per second, the stick line's evaluations per ball (``iterations``; 9.7 before the
  line stopped at the neighbouring float of a Newton step below round-off, 4.9 after), and
  the baseline on the ball of most evaluations.

Run: ``python benchmarks/bench_regimes.py [--balls N] [--reference-balls M]
[--three-point-assemblies K]``.
"""

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np
from bench_full import regime_balls as random_balls  # run from benchmarks/
from bench_full import timed

from tolsim.io.config import load_config
from tolsim.physics.velocity import full as full_module
from tolsim.physics.velocity.full import full
from tolsim.physics.velocity.regimes import minimise_dissipation
from tolsim.study.execution.runner import run_study

CARRIAGE = Path(__file__).resolve().parent.parent / "configs" / "carriage_preload.toml"


def three_point_balls(assemblies):
    """(dbeta, force) of the three-point balls that a study of ``configs/carriage_preload.toml``
    at 0 um oversize along the track hands to the full model (``assemblies``, seed 12)."""
    config = load_config(CARRIAGE)
    config = replace(config, carriage=replace(config.carriage, preload_oversize=0.0))
    config = config.with_overrides(samples=assemblies, seed=12)
    seen = []
    solve = full_module.full

    def spy(dbeta, force, *args, **kwargs):
        seen.append((np.array(dbeta), np.array(force)))
        return solve(dbeta, force, *args, **kwargs)

    full_module.full = spy
    try:
        run_study(config, workers=1)
    finally:
        full_module.full = solve
    dbeta = np.concatenate([d for d, _ in seen])
    force = np.concatenate([f for _, f in seen])
    three = (force > 0).sum(axis=1) == 3
    return dbeta[three], force[three]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--balls", type=int, default=4000)
    parser.add_argument("--reference-balls", type=int, default=2)
    parser.add_argument("--three-point-assemblies", type=int, default=500)
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

    dbeta, force = three_point_balls(args.three_point_assemblies)
    t_new, new = timed(full, dbeta, force)
    codes = {c: int((new.regime == c).sum()) for c in (0, 1, 2)}
    print(f"three-point balls of carriage_preload.toml at 0 um oversize along the track "
          f"({args.three_point_assemblies} assemblies): {len(dbeta)} balls, regime A "
          f"{codes[1]}, B {codes[2]}, unsolved {codes[0]}")
    stuck = new.regime == 2
    print(f"  full {len(dbeta) / t_new:9.0f} balls/s; stick line evaluations per ball in "
          f"regime B: mean {new.iterations[stuck].mean():.2f}, max {new.iterations[stuck].max()}")
    j = int(np.argmax(np.where(stuck, new.iterations, -1)))
    t0 = time.perf_counter()
    ref = minimise_dissipation(dbeta[j], force[j])
    print(f"  baseline NumPy/SciPy minimiser of D on its ball of most evaluations: "
          f"{1.0 / (time.perf_counter() - t0):.3f} balls/s; |eps_full - eps_ref| = "
          f"{abs(ref.velocity_deviation - new.velocity_deviation[j]):.1e}")


if __name__ == "__main__":
    main()
