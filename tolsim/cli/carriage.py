"""``tolsim carriage``: the load distribution of one carriage on its ball tracks (issue 12)."""

import json
import math
import os

import numpy as np

from tolsim.cli import UsageError, path_argument
from tolsim.physics.carriage import DOFS
from tolsim.physics.geometry import CONTACTS
from tolsim.physics.velocity.models import BALL_REGIME_LABELS, BALL_UNLOADED, BALL_UNRESOLVED

DESCRIPTION = """\
Load distribution of one rigid carriage on its preloaded ball tracks (tolsim issue 12), for
a study config with a [carriage] section: the nominal assembly (the config's preload class
and per-ball oversize deviations; no sampled tolerances), or with --seed N one sampled
assembly: the first assembly of `tolsim run CONFIG --seed N` (its groove errors per track
and ball sizes drawn from the config's [tolerances]). The config needs no [study] section.

Per ball (track t, ball j, ball 0 trailing, at z along the rail): the four contact forces
F_BL F_BR F_TR F_TL and contact-angle deviations dbeta in the ball's module frame, the
side-force ratio rho = N_x / N_y, the velocity deviation epsilon (the analytical model; the
full friction model where the analytical one is outside its validity or a contact is open)
and the ball's regime: A (all four contacts slip), B (one contact sticks), 3-point, 2-point
(rolls at v/2, epsilon = 0) or unloaded (pushed along, no epsilon). For the carriage:
its displacement (u_x, u_y [um]; pitch, yaw, roll [urad]) and tangent stiffness in the
catalogue's units (N/um for forces against translations, N m/urad for moments against
rotations), the DOFs the layout cannot resist (locked), and convergence.

Frame: z along the rail, x lateral, y up; loads at the reference point midway between the
tracks. A carriage with clearance (a negative preload_oversize_um) settles onto its
contacts. A load the tracks cannot carry, one that lifts the carriage off (pulls it away from
every contact), or one with no equilibrium within the gothic arch is an error.

Examples:
  tolsim carriage configs/carriage_preload.toml
  tolsim carriage configs/carriage_preload.toml --json
  tolsim carriage configs/carriage_preload.toml --plot load_distribution.png
  tolsim carriage configs/carriage_preload.toml --seed 7   # one sampled assembly
  tolsim carriage configs/carriage_circuit.toml --circuit-figure circuit.png

With --circuit-figure (a config with [carriage.circuit]) it also follows the first assembly
of `tolsim run CONFIG` (or of --seed N) along the stroke, its balls round their circuits, and
draws one circuit: every ball's place round it against the carriage travel, the loaded zone
shaded and the contacts marked by where they form.
"""

#: JSON names of the displacement, in DOFS order, and the factor from SI.
DISPLACEMENT_KEYS = ("u_x_um", "u_y_um", "pitch_urad", "yaw_urad", "roll_urad")
DOF_UNITS = ("um", "um", "urad", "urad", "urad")
LOAD_UNITS = ("N", "N", "N m", "N m", "N m")


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser(
        "carriage",
        help="load distribution of one carriage on its ball tracks, with preload",
        description=DESCRIPTION,
        formatter_class=formatter_class,
    )
    p.add_argument("config", type=path_argument, metavar="CONFIG",
                   help="study config (TOML) with [carriage]")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--seed", type=int, metavar="N",
                   help="solve one sampled assembly instead of the nominal one: the first "
                        "assembly of 'tolsim run CONFIG --seed N' (N >= 0)")
    p.add_argument("--plot", type=path_argument, metavar="FILE.png",
                   help="also write the load distribution (ball force against position, per "
                        "track) to this PNG file")
    p.add_argument("--circuit-figure", type=path_argument, metavar="FILE.png",
                   help="also write the balls of one circuit (track 0) against the carriage "
                        "travel over the stroke to this PNG file (a config with "
                        "[carriage.circuit]: the first assembly of the study, or of --seed N)")
    return p


def _circuit_figure(config, args):
    """Write ``--circuit-figure``: one assembly traced round its circuits."""
    from tolsim.reports.carriage import plot_circuit  # noqa: PLC0415
    from tolsim.study.pipeline.circuit_trace import trace_circuit  # noqa: PLC0415

    if config.carriage.circuit is None:
        raise UsageError(f"--circuit-figure: {args.config} has no [carriage.circuit] section "
                         "(see configs/carriage_circuit.toml)")
    try:
        plot_circuit(trace_circuit(config, args.seed), args.circuit_figure)
    except OSError as exc:
        raise UsageError(f"--circuit-figure: cannot write {args.circuit_figure}: "
                         f"{exc.strerror or exc}") from None


def _finite(value):
    value = float(value)
    return value if math.isfinite(value) else None


def evaluate(config, seed=None) -> dict:
    """The JSON-ready result of the nominal carriage of ``config`` (issue 12's interface).

    Raises
    ------
    UsageError
        A load the layout cannot carry, lift-off, or no equilibrium within the gothic arch.
    """
    from tolsim.study.pipeline.carriage import solve_config_carriage  # noqa: PLC0415

    try:
        result = solve_config_carriage(config, seed)
    except ValueError as exc:
        raise UsageError(f"{config.path}: {exc}") from None
    sol = result.solution
    beta0 = math.degrees(config.bearing.nominal_contact_angle)
    balls = []
    t_count, n = sol.normal_force.shape[:2]
    for t in range(t_count):
        for j in range(n):
            dbeta = np.rad2deg(sol.contact_angle_deviation[t, j])
            balls.append({
                "track": t,
                "ball": j,
                "z_mm": float(sol.ball_z[j] * 1e3),
                "normal_force_n": [float(f) for f in sol.normal_force[t, j]],
                "contact_angle_deg": [float(beta0 + d) for d in dbeta],
                "contact_angle_deviation_deg": [float(d) for d in dbeta],
                "contact_count": int(sol.contact_count[t, j]),
                "side_load_n": float(sol.side_load[t, j]),
                "normal_load_n": float(sol.normal_load[t, j]),
                "side_force_ratio": _finite(sol.side_force_ratio[t, j]),
                "velocity_deviation": _finite(result.velocity_deviation[t, j]),
                "velocity_model": str(result.velocity_model[t, j]) or None,
                "regime": BALL_REGIME_LABELS[int(result.regime[t, j])],
            })
    carriage = config.carriage
    return {
        "config": config.path,
        "seed": seed,
        "preload_oversize_um": carriage.preload_oversize * 1e6,
        "load": {"lateral_n": carriage.load.lateral_force,
                 "vertical_n": carriage.load.vertical_force,
                 "pitch_moment_n_m": carriage.load.pitch_moment,
                 "yaw_moment_n_m": carriage.load.yaw_moment,
                 "roll_moment_n_m": carriage.load.roll_moment},
        "contacts": list(CONTACTS),
        "balls": balls,
        "displacement": {k: float(v * 1e6)
                         for k, v in zip(DISPLACEMENT_KEYS, sol.displacement, strict=True)},
        "stiffness": {
            "dofs": list(DOFS),
            # dQ_i/dq_j: rows the load (N or N m), columns the motion (um or urad)
            "matrix": [[float(v * 1e-6) for v in row] for row in sol.stiffness],
            "units": [[f"{lu}/{du}" for du in DOF_UNITS] for lu in LOAD_UNITS],
        },
        "locked": list(sol.locked),
        "converged": bool(sol.converged),
        "iterations": int(sol.iterations),
    }


def _force(value):
    """A contact force [N] for the table: 'open' where the contact carries none."""
    return f"{value:8.2f}" if value > 0 else f"{'open':>8}"


def _number(value, fmt):
    return format(value, fmt) if value is not None else f"{'-':>{len(format(0.0, fmt))}}"


def _text(out) -> str:
    load = out["load"]
    lines = [
        f"carriage of {out['config']}: {len({b['track'] for b in out['balls']})} tracks, "
        f"preload oversize {out['preload_oversize_um']:g} um, "
        + ("nominal assembly" if out.get("seed") is None else
           f"sampled assembly (the first of seed {out['seed']})"),
        f"load: lateral {load['lateral_n']:g} N, vertical {load['vertical_n']:g} N, pitch "
        f"{load['pitch_moment_n_m']:g} N m, yaw {load['yaw_moment_n_m']:g} N m, roll "
        f"{load['roll_moment_n_m']:g} N m",
        "",
        "track ball   z [mm]     F_BL     F_BR     F_TR     F_TL [N]  "
        "dbeta_BL  dbeta_BR  dbeta_TR  dbeta_TL [deg]      rho  epsilon [%]  regime",
    ]
    for b in out["balls"]:
        eps = b["velocity_deviation"]
        lines.append(
            f"{b['track']:>5} {b['ball']:>4} {b['z_mm']:8.2f} "
            + " ".join(_force(f) for f in b["normal_force_n"]) + "     "
            + " ".join(f"{d:+9.4f}" for d in b["contact_angle_deviation_deg"]) + "       "
            + _number(b["side_force_ratio"], "+8.4f") + "  "
            + (_number(None, "+9.5f") if eps is None else f"{round(100 * eps, 5) + 0.0:+9.5f}")
            + f"  {b['regime']}"
            + ("" if b["velocity_model"] in ("analytic", None) else f" ({b['velocity_model']})"))
    opened = sum(b["contact_count"] < 4 for b in out["balls"])
    by_full = sum(b["velocity_model"] == "full" for b in out["balls"])
    counts = {}
    for b in out["balls"]:
        counts[b["regime"]] = counts.get(b["regime"], 0) + 1
    lines.append("regimes: " + ", ".join(f"{label} {counts[label]}"
                                         for label in BALL_REGIME_LABELS.values()
                                         if label in counts)
                 + " (A: all four contacts slip; B: one contact sticks; 2-point rolls at v/2)")
    if by_full:
        lines.append(f"(full): epsilon of {by_full} balls from the full friction model (outside "
                     "the analytical model's validity, or with an open contact)")
    if opened:
        lines.append(f"{opened} of {len(out['balls'])} balls have open contacts (F = 0, shown "
                     "as 'open')")
    unloaded = counts.get(BALL_REGIME_LABELS[BALL_UNLOADED], 0)
    if unloaded:
        lines.append(f"epsilon is undefined (-) for the {unloaded} unloaded balls: no contact "
                     "carries load, so they are pushed along by their neighbours")
    unsolved = counts.get(BALL_REGIME_LABELS[BALL_UNRESOLVED], 0)
    if unsolved:
        lines.append(f"epsilon is undefined (-) for {unsolved} balls: the full friction model "
                     "found no certified minimum of the dissipated power there")
    d = out["displacement"]
    lines += [
        "",
        f"displacement: u_x {d['u_x_um']:+.4f} um, u_y {d['u_y_um']:+.4f} um, pitch "
        f"{d['pitch_urad']:+.3f} urad, yaw {d['yaw_urad']:+.3f} urad, roll "
        f"{d['roll_urad']:+.3f} urad",
        "stiffness (rows: load, columns: motion):",
        "          " + "".join(f"{name:>12}" for name in out["stiffness"]["dofs"]),
    ]
    for name, row, units in zip(out["stiffness"]["dofs"], out["stiffness"]["matrix"],
                                out["stiffness"]["units"], strict=True):
        lines.append(f"  {name:<8}" + "".join(f"{v:12.4g}" for v in row) + f"   [{units[0]} .. "
                     f"{units[-1]}]")
    k = out["stiffness"]["matrix"]
    lines.append(f"catalogue: vertical {k[1][1]:.4g} N/um, lateral {k[0][0]:.4g} N/um, pitch "
                 f"{k[2][2]:.4g}, yaw {k[3][3]:.4g}, roll {k[4][4]:.4g} N m/urad")
    lines.append("DOFs the tracks cannot resist (locked): "
                 + (", ".join(out["locked"]) if out["locked"] else "none"))
    lines.append(f"converged: {'yes' if out['converged'] else 'NO'} "
                 f"({out['iterations']} Newton steps)")
    return "\n".join(lines)


def run(args) -> int:
    from tolsim.io.config import ConfigError, load_config  # noqa: PLC0415

    try:
        config = load_config(args.config, study=False)  # a load distribution needs no study
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    if not config.has_carriage:
        raise UsageError(f"{args.config}: has no [carriage] section (tolsim carriage needs "
                         "one; see configs/carriage_preload.toml)")
    if args.seed is not None and args.seed < 0:
        raise UsageError(f"--seed = {args.seed} must be >= 0")
    for flag, path in (("--circuit-figure", args.circuit_figure), ("--plot", args.plot)):
        # checked before anything is written: one bad path leaves no other figure behind
        if path and (os.path.isdir(path) or not os.path.isdir(
                os.path.dirname(os.path.abspath(path)))):
            raise UsageError(f"{flag}: cannot write {path}: "
                             + ("it is a folder" if os.path.isdir(path) else
                                "its folder does not exist"))
        if path and not path.lower().endswith(".png"):
            raise UsageError(f"{flag}: {path} must end in .png (the figure is written as "
                             "PNG)")
    out = evaluate(config, args.seed)
    if args.circuit_figure:
        _circuit_figure(config, args)
    if args.plot:
        from tolsim.reports.carriage import plot_load_distribution  # noqa: PLC0415

        try:
            plot_load_distribution(out, args.plot)
        except OSError as exc:
            raise UsageError(f"--plot: cannot write {args.plot}: "
                             f"{exc.strerror or exc}") from None
    if args.json:
        print(json.dumps(out, indent=2, allow_nan=False))
    else:
        print(_text(out))
        for written in (args.plot, args.circuit_figure):
            if written:
                print(f"wrote {written}")
    return 0
