"""Validity thresholds of the fast velocity models from an error budget against ``full``.

    python benchmarks/validity_budget.py [--budget 2e-4] [--save grid.npz | --load grid.npz]

``eq24`` and ``analytic`` (:mod:`tolsim.physics.velocity.analytic`) flag each ball ``valid`` or
not; in
a study an invalid ball is re-solved with the comprehensive model
:func:`tolsim.physics.velocity.full.full`. The thresholds therefore trade speed (the share of balls
the fast model keeps) against accuracy (its error on those balls), not truth against bias.
This script measures the error of both fast models against ``full`` on a grid and derives
the thresholds that keep it inside a budget (default ``VALIDITY_ERROR_BUDGET`` = 2e-4, i.e.
|eps_model - eps_full| <= 0.02 percentage points).

Grid (Table 1 bearing, 45 deg):

* rho = N_x / N_y: -0.95 .. 0.95 step 0.05 (39 values);
* rail and carriage groove rotations theta_bottom, theta_top: -4 .. 4 deg step 0.5 deg
  (17 x 17);
* N_y: 50, 100, 200, 500, 1000 N;
* four contact states per (rho, theta_b, theta_t, N_y):

  - ``paired``: the paper's paired forces (Sec. 3.1) with the rigid angles
    dbeta = (-theta_b, +theta_b, -theta_t, +theta_t);
  - ``solved``: :func:`tolsim.physics.static.solve_static` with the two rotations (loaded
    angles, four distinct forces);
  - ``solved+arc#1``, ``#2``: the same plus errors drawn per grid point (seed 2018): arc-centre
    offsets tangential U(-3, 3) um and normal U(-2, 2) um on each flank, ball oversize
    U(-0.5, 0.5) um. These unpair the diagonal forces (pairing asymmetry P up to ~0.1).

  Multiplicative perturbations of the paired forces are not used: such forces are not in
  equilibrium with the angles, and ``full`` then gives eps != 0 with no angle deviation at
  all (1.9e-3 for +-20 %), an artefact that no static model of a study produces.
  Points where the static solution did not converge or lost a contact are dropped; points
  where ``full`` did not converge (about 8 %, near |rho| -> 1 with large rotations) are
  counted but do not constrain the thresholds (a re-solve would not help them either).

Criteria (a ball is valid when every one is inside its threshold; all per ball, all cheap):

* ``analytic``: max_i |c_i / a_i| (c_i = R_B dgamma_i), max_i |dbeta_i + dgamma_i| and
  |eps_analytic|;
* ``eq24``: q = min(F_1, F_2) / max(F_1, F_2) (F_1 = F_BL + F_TR, F_2 = F_BR + F_TL),
  max_i |dbeta_i|, the pairing asymmetry
  P = max(|F_BL - F_TR| / (F_BL + F_TR), |F_BR - F_TL| / (F_BR + F_TL)) and |eps_eq24|.

Why |eps| is among them: the error of both models against ``full`` is close to proportional
to epsilon itself (a relative 5-7 % even at small |c/a|, more at large |c/a| and |rho|), so
a box in (|c/a|, |dbeta + dgamma|) alone is a weak proxy for the error. ``eq24`` has no
dgamma, and it ignores unpaired forces, hence the pairing asymmetry P.

Derivation. Each criterion is put on a lattice of round values. A set of thresholds is
admissible when no grid point and no fresh random ball inside all of them (with ``full``
converged) has an error above the budget: that is the hard constraint. Among the admissible
sets, the default objective (``--objective realistic``) takes the one that keeps the most
balls of a realistic population (the tolerances of ``tolsim/data/default.toml``; ties broken
by the share of the grid): the choice among admissible sets is about speed only, since an
invalid ball costs a full-model re-solve in a study. Each threshold is then lowered to the
extent of the grid and fresh points inside it (never to the realistic population's), beyond
which nothing was measured. ``--objective grid`` keeps the most grid points instead (a set
that suits the grid's extremes and re-solves about a fifth of a realistic study's balls).
The result is checked on the fresh sample and on the realistic population, and the same
derivation is shown for other criterion sets, to show what each criterion buys.

Runtime: 40 s to 2 min on two cores (mostly ``full`` on 218 478 + 24 000 balls).
"""

import argparse
import time

import numpy as np

from tolsim.physics.geometry import TABLE1, paired_forces
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static import GrooveErrors, solve_static
from tolsim.physics.velocity import analytic as A
from tolsim.physics.velocity.full import full

RHO = np.round(np.arange(-0.95, 0.951, 0.05), 10)
THETA_DEG = np.arange(-4.0, 4.01, 0.5)
NORMAL_LOAD = np.array([50.0, 100.0, 200.0, 500.0, 1000.0])
ARC_DRAWS = 2
SEED = 2018
FRESH_SEED, FRESH_BALLS = 20240611, 20000
REALISTIC_SEED, REALISTIC_BALLS = 7, 20000

#: Lattices of round threshold values. A point is inside a threshold T when its value x <= T
#: (for eq24's ratio q: when 1 - q <= T).
LATTICES = {
    "": np.zeros(1),  # a dummy axis (one-criterion sets)
    "c/a": np.round(np.arange(0.0, 1.501, 0.01), 10),
    "|dbeta+dgamma| [deg]": np.round(np.arange(0.0, 8.001, 0.05), 10),
    "1 - q": np.round(np.arange(0.0, 0.991, 0.02), 10),
    "|dbeta| [deg]": np.round(np.arange(0.0, 7.751, 0.25), 10),
    "P": np.round(np.arange(0.0, 0.2451, 0.005), 10),
    "|eps| [%]": np.round(np.arange(0.0, 2.001, 0.01), 10),
}
#: The criteria the kernels test (the last one is solved for, the others enumerated).
CRITERIA = {
    "analytic": ("|dbeta+dgamma| [deg]", "c/a", "|eps| [%]"),
    "eq24": ("1 - q", "|dbeta| [deg]", "P", "|eps| [%]"),
}
ALTERNATIVES = {
    "analytic": [("|dbeta+dgamma| [deg]", "c/a"), ("c/a",)],
    "eq24": [("|dbeta| [deg]", "1 - q"), ("1 - q", "|dbeta| [deg]", "P"),
             ("1 - q", "|dbeta| [deg]", "|eps| [%]")],
}


def _flatten(states, params):
    """Concatenate contact states (name, dbeta, force, keep) over the points they keep."""
    cols = {k: [] for k in ("dbeta", "force", *params, "state")}
    n = len(next(iter(params.values())))
    for k, (_, dbeta, force, keep) in enumerate(states):
        cols["dbeta"].append(dbeta[keep])
        cols["force"].append(force[keep])
        for key, val in params.items():
            cols[key].append(np.broadcast_to(val, (n,))[keep])
        cols["state"].append(np.full(int(keep.sum()), k))
    out = {k: np.concatenate(v) for k, v in cols.items()}
    out["dbeta"] = np.ascontiguousarray(out["dbeta"])
    out["force"] = np.ascontiguousarray(out["force"])
    return out, [s[0] for s in states]


def random_errors(rng, n, theta_b, theta_t):
    """Rotations plus random arc-centre offsets and ball oversize (the ``solved+arc`` state)."""
    return GrooveErrors(
        bottom_rotation=theta_b, top_rotation=theta_t,
        arc_centre_offset_tangential=rng.uniform(-3e-6, 3e-6, (n, 4)),
        arc_centre_offset_normal=rng.uniform(-2e-6, 2e-6, (n, 4)),
        ball_oversize=rng.uniform(-0.5e-6, 0.5e-6, n))


def solved_state(name, side_load, normal_load, errors, bearing=TABLE1):
    sol = solve_static(side_load, normal_load, errors, bearing)
    return name, sol.contact_angle_deviation, sol.normal_force, sol.converged & sol.four_point


def grid(bearing=TABLE1):
    """The contact states of the grid (module docstring): dict of flat arrays over the points
    with four positive forces (``dbeta``, ``force`` (n, 4), ``rho``, ``theta_b``, ``theta_t``,
    ``normal_load``, ``state``) and the list of state names."""
    rho, tb, tt, ny = (a.ravel() for a in np.meshgrid(RHO, np.deg2rad(THETA_DEG),
                                                       np.deg2rad(THETA_DEG), NORMAL_LOAD,
                                                       indexing="ij"))
    n = len(rho)
    rigid = np.stack([-tb, tb, -tt, tt], axis=1)
    paired = paired_forces(rho * ny, ny, bearing.nominal_contact_angle)
    states = [("paired", rigid, paired, np.all(paired > 0, axis=1)),
              solved_state("solved", rho * ny, ny,
                           GrooveErrors(bottom_rotation=tb, top_rotation=tt), bearing)]
    rng = np.random.default_rng(SEED)
    for k in range(ARC_DRAWS):
        states.append(solved_state(f"solved+arc#{k + 1}", rho * ny, ny,
                                   random_errors(rng, n, tb, tt), bearing))
    return _flatten(states, {"rho": rho, "theta_b": tb, "theta_t": tt, "normal_load": ny})


def fresh_sample(n=FRESH_BALLS, seed=FRESH_SEED, bearing=TABLE1):
    """Random balls between the grid points: rho U(-0.95, 0.95), N_y log-uniform 50-1000 N,
    theta_b, theta_t U(-4, 4) deg, and the random errors of ``solved+arc``."""
    rng = np.random.default_rng(seed)
    rho = rng.uniform(-0.95, 0.95, n)
    ny = np.exp(rng.uniform(np.log(50.0), np.log(1000.0), n))
    tb, tt = rng.uniform(-np.deg2rad(4.0), np.deg2rad(4.0), (2, n))
    state = solved_state("fresh", rho * ny, ny, random_errors(rng, n, tb, tt), bearing)
    return _flatten([state], {"rho": rho, "theta_b": tb, "theta_t": tt, "normal_load": ny})[0]


def realistic_population(n=REALISTIC_BALLS, seed=REALISTIC_SEED, bearing=TABLE1):
    """Balls with the tolerances of ``tolsim/data/default.toml``: theta_b ~ N(0, 0.1 deg),
    theta_t ~ N(0, 0.075 deg) (cpk 1.33 on +-0.3 deg), tangential arc-centre offsets
    ~ N(0, 1 um) on each flank, ball oversize ~ N(0, 0.1 um) clipped to +-0.25 um; N_y = 200 N,
    rho U(-0.4, 0.4) (the default yaw moment), loaded state from the static solve."""
    rng = np.random.default_rng(seed)
    rho = rng.uniform(-0.4, 0.4, n)
    errors = GrooveErrors(
        bottom_rotation=rng.normal(0.0, np.deg2rad(0.1), n),
        top_rotation=rng.normal(0.0, np.deg2rad(0.075), n),
        arc_centre_offset_tangential=rng.normal(0.0, 1e-6, (n, 4)),
        ball_oversize=np.clip(rng.normal(0.0, 0.1e-6, n), -0.25e-6, 0.25e-6))
    state = solved_state("realistic", rho * 200.0, 200.0, errors, bearing)
    return _flatten([state], {"rho": rho})[0]


def criteria(dbeta, force, bearing=TABLE1):
    """eps of both fast models and the criterion values per ball (what the kernels test)."""
    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    an = A.analytic(dbeta, force, bearing)
    eq = A.eq24(dbeta, force, bearing)
    a = hc.semi_major_coefficient * np.cbrt(force)
    gamma = an.zero_velocity_offset
    f1, f2 = force[:, 0] + force[:, 2], force[:, 1] + force[:, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        pairing = np.maximum(np.abs(force[:, 0] - force[:, 2]) / f1,
                             np.abs(force[:, 1] - force[:, 3]) / f2)
        q = np.minimum(f1, f2) / np.maximum(f1, f2)
    x = {
        "analytic": {
            "c/a": np.max(bearing.ball_radius * np.abs(gamma) / a, axis=1),
            "|dbeta+dgamma| [deg]": np.rad2deg(np.max(np.abs(dbeta + gamma), axis=1)),
            "|eps| [%]": 100 * np.abs(an.velocity_deviation),
        },
        "eq24": {
            "1 - q": 1.0 - q,
            "|dbeta| [deg]": np.rad2deg(np.max(np.abs(dbeta), axis=1)),
            "P": pairing,
            "|eps| [%]": 100 * np.abs(eq.velocity_deviation),
        },
    }
    return {"analytic": an.velocity_deviation, "eq24": eq.velocity_deviation}, x


def inside(values, thresholds):
    """Points inside every threshold (NaN is outside)."""
    out = np.ones(len(next(iter(values.values()))), dtype=bool)
    for name, limit in thresholds.items():
        out &= np.nan_to_num(values[name], nan=np.inf) <= limit
    return out


def derive(values, names, counted, bad, needed=None, weights=None):
    """Largest lattice thresholds with no ``bad`` point inside, keeping most ``counted`` in.

    Parameters
    ----------
    values : dict
        criterion name -> (n,) values (inside when value <= threshold).
    names : sequence of str
        Criteria, keys of ``values`` and :data:`LATTICES`; the last is solved for, the others
        are enumerated on their lattices (all combinations at once, by cumulative counts).
    counted, bad : ndarray of bool, (n,)
        Points that count for the share (the objective) and points above the budget.
    needed : ndarray of bool, (n,), optional
        Points whose extent each threshold is lowered to at the end (default ``counted``).
    weights : ndarray (n,), optional
        Weight of each counted point in the objective (default 1).

    Returns
    -------
    thresholds : dict name -> float
    inside : ndarray of bool, (n,)
    """
    if len(names) == 1:  # one criterion: through the two-axis code with a dummy first axis
        thresholds, ins = derive({**values, "": np.zeros(len(counted))}, ("", *names),
                                 counted, bad)
        del thresholds[""]
        return thresholds, ins
    lat = [LATTICES[k] for k in names]
    sizes = tuple(len(v) for v in lat)
    idx = np.stack([np.searchsorted(v, np.nan_to_num(values[k], nan=np.inf), side="left")
                    for k, v in zip(names, lat, strict=True)], axis=1)
    # cum[t] = number of counted points with idx <= t on every axis
    sel = counted & np.all(idx < np.array(sizes), axis=1)
    w = np.ones(len(counted)) if weights is None else np.asarray(weights, dtype=float)
    cum = np.bincount(np.ravel_multi_index(tuple(idx[sel].T), sizes), weights=w[sel],
                      minlength=int(np.prod(sizes))).reshape(sizes)
    for ax in range(len(sizes)):
        np.cumsum(cum, axis=ax, out=cum)
    # bmin[t'] = lowest last-axis index of a bad point with idx <= t' on the other axes
    last = sizes[-1]
    bmin = np.full(sizes[:-1], last, dtype=np.int64)
    sel = bad & np.all(idx[:, :-1] < np.array(sizes[:-1]), axis=1)
    np.minimum.at(bmin, tuple(idx[sel, :-1].T), np.minimum(idx[sel, -1], last))
    for ax in range(len(sizes) - 1):
        np.minimum.accumulate(bmin, axis=ax, out=bmin)
    top = bmin - 1  # largest admissible last-axis index (-1: none)
    count = np.take_along_axis(cum, np.maximum(top, 0)[..., None], axis=-1)[..., 0]
    count = np.where(top >= 0, count, -1)
    best = np.unravel_index(int(np.argmax(count)), count.shape)
    t = np.array([*best, top[best]])
    if count[best] <= 0:
        return {k: float("nan") for k in names}, np.zeros(len(counted), dtype=bool)
    ins = np.all(idx <= t, axis=1)
    # lower each threshold to what the points inside need (the same set of points)
    needed = counted if needed is None else needed
    t = idx[ins & needed].max(axis=0) if np.any(ins & needed) else t
    ins = np.all(idx <= t, axis=1)
    return {k: float(v[i]) for k, v, i in zip(names, lat, t, strict=True)}, ins


def derive_for_speed(model, names, x, counted, bad, samples, budget):
    """Thresholds that hold the budget on the grid and the fresh sample and keep the most of
    the realistic population (ties: the most grid points).

    The budget is the hard constraint, measured on every grid point and fresh ball; the
    choice among the admissible sets is speed only (fewer full-model re-solves in a realistic
    study). Thresholds are lowered to the extent of the grid and fresh points inside, never to
    the realistic population's, so a study with larger deviations is not penalised beyond
    what was measured.
    """
    f_x, f_err, f_ok = samples["fresh random balls"]
    r_x, _, r_ok = samples["realistic population"]
    parts = (x[model], f_x[model], r_x[model])
    values = {k: np.concatenate([p[k] for p in parts]) for k in names}
    n_g, n_f, n_r = len(counted), len(f_ok), len(r_ok)
    bad_all = np.concatenate([bad, f_ok & ~(f_err[model] <= budget), np.zeros(n_r, bool)])
    objective = np.concatenate([counted, np.zeros(n_f, bool), r_ok])
    weights = np.concatenate([np.ones(n_g), np.zeros(n_f), np.full(n_r, 10.0 * n_g)])
    needed = np.concatenate([counted, f_ok, np.zeros(n_r, bool)])
    thresholds, ins = derive(values, names, objective, bad_all, needed, weights)
    return thresholds, ins[:n_g]


def _fmt(thresholds):
    return ", ".join(f"{k} <= {v:g}" for k, v in thresholds.items())


def check(label, thresholds, x, err, counted, budget):
    """One line: share inside and max error inside on a sample."""
    ins = inside(x, thresholds) & counted
    worst = np.max(err[ins]) if ins.any() else 0.0
    flag = "ok" if worst <= budget else "OVER BUDGET"
    return (f"{label}: {ins.sum()} of {counted.sum()} inside ({ins.sum() / counted.sum():.1%}),"
            f" max error inside {worst:.3g} [{flag}]")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--budget", type=float, default=A.VALIDITY_ERROR_BUDGET,
                        help="budget on |eps_model - eps_full| (a fraction; default "
                             "%(default)g = 0.02 pp)")
    parser.add_argument("--save", help="write the grid and its full results to this .npz")
    parser.add_argument("--load", help="reuse the grid and full results of --save")
    parser.add_argument("--fresh", type=int, default=FRESH_BALLS,
                        help="size of the fresh random check sample (default %(default)s)")
    parser.add_argument("--objective", choices=("realistic", "grid"), default="realistic",
                        help="among the threshold sets that hold the budget, keep the most of "
                             "the realistic population (default) or of the grid")
    args = parser.parse_args(argv)
    budget = args.budget
    t0 = time.perf_counter()
    if args.load:
        with np.load(args.load) as f:
            g = {k: f[k] for k in f.files}
        state_names = [str(s) for s in g.pop("state_names")]
    else:
        g, state_names = grid()
    n = len(g["rho"])
    print(f"grid: rho {RHO[0]:g}..{RHO[-1]:g} step 0.05, theta_b, theta_t "
          f"{THETA_DEG[0]:g}..{THETA_DEG[-1]:g} deg step 0.5, N_y "
          f"{', '.join(f'{v:g}' for v in NORMAL_LOAD)} N; states {', '.join(state_names)}")
    if "eps_full" not in g:
        t1 = time.perf_counter()
        ref = full(g["dbeta"], g["force"], TABLE1)
        g["eps_full"] = ref.velocity_deviation
        g["full_valid"] = np.asarray(ref.valid) & np.isfinite(ref.velocity_deviation)
        print(f"  full on {n} points: {time.perf_counter() - t1:.0f} s")
    if args.save:
        np.savez(args.save, state_names=np.array(state_names), **g)
    counted = g["full_valid"]
    print(f"  {n} points with four positive forces; full converged on {counted.sum()} "
          f"({counted.mean():.1%})")
    eps, x = criteria(g["dbeta"], g["force"])

    samples = {}
    for name, sample in (("fresh random balls", fresh_sample(args.fresh)),
                         ("realistic population", realistic_population())):
        ref = full(sample["dbeta"], sample["force"], TABLE1)
        s_eps, s_x = criteria(sample["dbeta"], sample["force"])
        ok = np.asarray(ref.valid) & np.isfinite(ref.velocity_deviation)
        samples[name] = (s_x, {m: np.abs(e - ref.velocity_deviation) for m, e in s_eps.items()},
                         ok)

    derived = {}
    for model, names in CRITERIA.items():
        err = np.abs(eps[model] - g["eps_full"])
        bad = counted & ~(err <= budget)
        print(f"\n{model}: {bad.sum()} of {counted.sum()} grid points "
              f"({bad.sum() / counted.sum():.1%}) exceed the budget {budget:g}")
        if args.objective == "realistic":
            thresholds, ins = derive_for_speed(model, names, x, counted, bad, samples, budget)
        else:
            thresholds, ins = derive(x[model], names, counted, bad)
        derived[model] = thresholds
        ok = ins & counted
        print(f"  derived: {_fmt(thresholds)}")
        print(f"    grid: {ok.sum()} of {counted.sum()} inside ({ok.sum() / counted.sum():.1%}); "
              f"max |eps_model - eps_full| inside {err[ok].max():.3g} "
              f"({100 * err[ok].max():.4f} pp)")
        print(f"    inside but full not converged (not checked): {(ins & ~counted).sum()}")
        shares = [f"{s} {np.mean(ins[(g['state'] == k) & counted]):.1%}"
                  for k, s in enumerate(state_names)]
        print("    share inside per state: " + ", ".join(shares))
        for label, (s_x, s_err, s_ok) in samples.items():
            print("    " + check(label, thresholds, s_x[model], s_err[model], s_ok, budget))
        for alt in ALTERNATIVES[model]:
            th, ins = derive(x[model], alt, counted, bad)
            print(f"  alternative: {_fmt(th)}: grid {np.mean(ins[counted]):.1%} inside")
            for label, (s_x, s_err, s_ok) in samples.items():
                print("    " + check(label, th, s_x[model], s_err[model], s_ok, budget))

    print("\nLin2018 Table 2 case (a) (theta_b = 2 deg, N_y = 200 N, paired forces):")
    for rho in (-0.6, 0.6):
        sel = np.flatnonzero((g["state"] == 0) & np.isclose(g["rho"], rho)
                             & np.isclose(g["theta_b"], np.deg2rad(2.0))
                             & (g["theta_t"] == 0.0) & (g["normal_load"] == 200.0))[0]
        for model, thresholds in derived.items():
            err = abs(eps[model][sel] - g["eps_full"][sel])
            where = ("inside" if inside({k: v[[sel]] for k, v in x[model].items()},
                                        thresholds)[0] else "outside: re-solved with full")
            print(f"  rho {rho:+.1f} {model}: eps {100 * eps[model][sel]:+.4f} %, full "
                  f"{100 * g['eps_full'][sel]:+.4f} %, error {err:.3g}; {where}")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
