"""``tolsim ball``: the velocity deviation of one ball.

The ball's four contact-angle deviations come from ``--dbeta-deg``; its four normal forces
from ``--forces-n`` or from the top-groove load ``--load-n NX NY``.
"""

import json
import math
import sys

import numpy as np

from tolsim.cli import UsageError
from tolsim.physics.geometry import (
    CONTACTS,
    TABLE1,
    TABLE1_GROOVE_VELOCITY,
    TABLE1_NORMAL_LOAD,
    contact_force_resultant,
    paired_forces,
)
from tolsim.physics.velocity.ball_loads import DEFAULT_BALL_FRICTION
from tolsim.physics.velocity.models import (
    BALL_REGIME_LABELS,
    MODELS,
    VALIDITY_NOTES,
    ball_regime,
)
from tolsim.physics.velocity.regimes import stick_criterion

DESCRIPTION = """\
Velocity deviation epsilon of one ball in a four-point-contact linear ball bearing:
v_B = (1 + epsilon) v / 2, with the top groove moving at v and the bottom groove fixed.
Contacts are always given in the order BL BR TR TL (Bottom/Top, Left/Right).

Models:
  eq24      Eq. (24) of Lin et al. (2018): paired diagonal forces F1 = (F_BL+F_TR)/2,
            F2 = (F_BR+F_TL)/2.
  analytic  the improved model: Eqs. (17), (18), (21) solved for the zero-velocity offsets
            dgamma_i with four distinct forces; epsilon from Eq. (23), Eq. (22) alongside.
  point     the authors' prior point-contact model (three contacts roll, one slides).
  full      the comprehensive friction model: Coulomb friction integrated over the four
            Hertz ellipses, equilibrium solved without linearisation (--surface).

Loads: --forces-n gives the four normal forces directly; --load-n NX NY gives the load on the
top groove per ball (N_x toward +x, i.e. toward BR/TR; N_y pressing down), turned into forces
with the paper's paired approximation F_BL = F_TR = sqrt(2)/2 (N_y - N_x),
F_BR = F_TL = sqrt(2)/2 (N_y + N_x) (at 45 deg).

Static contact (--static): 'paired' (default) is the paper's approximation above; 'solved'
computes the loaded contact angles and forces of the ball between the two grooves (exact
Hertz contact, tolsim.physics.static) from --load-n and the geometric errors; the angles and
forces that enter the velocity model are reported. Geometric errors can replace --dbeta-deg:
--bottom-rotation-deg / --top-rotation-deg turn a whole groove profile about the nominal ball
centre (counter-clockwise positive, x right, y up: dbeta_BL = -theta, dbeta_BR = +theta for the
bottom, dbeta_TR = -theta, dbeta_TL = +theta for the top, as in Fig. 6; equal rotations are
Table 2 case (b)); --arc-offset-um moves each flank's arc centre along its contact line
(+ opens clearance) and --arc-offset-tangential-um across it (+ towards larger beta_i,
0.143 deg per um); --ball-oversize-um is the ball diameter deviation. With 'paired' the
geometric (rigid) contact angles of those errors are used. With 'solved' and no geometric
errors, --dbeta-deg is read as rigid contact-angle deviations, realised by turning each
flank about the ball centre.

Neighbours (--model analytic or full): --push-n P pushes the ball along the rail through its
centre (P > 0 from behind, the direction the top groove moves); --neighbour-forces-n Q_BACK
Q_FRONT gives the normal forces of the balls behind and in front (P = Q_BACK - Q_FRONT), whose
ball-to-ball friction (--ball-friction, mu_bb, default 0.1) brakes the ball's rolling. The
output then adds the carriage friction force of the ball (the friction between the ball and
the moving top groove along the rail, positive when it opposes the carriage motion), its
free-rolling value, the creep stiffness K = dP/d(epsilon), the traction capacity beyond which
the ball slides, and with --model full the power dissipated in the contacts.

Defaults are the paper's Table 1 (R_B = 5 mm, f = 0.54, beta_0 = 45 deg, E = 210 GPa,
nu = 0.28, mu = 0.1, v = 10 mm/s); --config FILE takes the [bearing] and [motion] sections of
a study config instead.

Examples:
  tolsim ball                                     # Table 2, case (a), ball 1
  tolsim ball --dbeta-deg -2 2 0 0 --load-n 120 200 --json
  tolsim ball --model analytic --dbeta-deg -1 1 0.5 0 --forces-n 150 60 140 55
  tolsim ball --static solved                     # case (a), ball 1, loaded angles
  tolsim ball --static solved --bottom-rotation-deg 2 --load-n 120 200 --json
  tolsim ball --push-n 2 --json                   # case (a) ball 1 pushed from behind
  tolsim ball --model full --neighbour-forces-n 5 1 --ball-friction 0.1
"""

#: Models that take external loads (push, neighbour forces): they have friction forces.
LOADED_MODELS = ("analytic", "full")

#: The paper's case study (Table 2, case (a), ball 1): theta = 2 deg, rho = -0.6, N_y = 200 N.
DEFAULT_DBETA_DEG = (-2.0, 2.0, 0.0, 0.0)
DEFAULT_LOAD_N = (-0.6 * TABLE1_NORMAL_LOAD, TABLE1_NORMAL_LOAD)


def add_parser(subparsers, formatter_class=None):
    p = subparsers.add_parser(
        "ball",
        help="velocity deviation of one ball from its contact angles and forces",
        description=DESCRIPTION,
        formatter_class=formatter_class,
    )
    p.add_argument("--model", default="analytic", choices=sorted(MODELS),
                   help="velocity model")
    p.add_argument("--dbeta-deg", nargs=4, type=float, metavar=CONTACTS, default=None,
                   help="contact-angle deviations dbeta_i [deg], BL BR TR TL (default: "
                        f"{' '.join(f'{d:g}' for d in DEFAULT_DBETA_DEG)}, unless geometric "
                        "errors are given); each within +/-22.5 deg")
    loads = p.add_mutually_exclusive_group()
    loads.add_argument("--forces-n", nargs=4, type=float, metavar=CONTACTS,
                       help="normal contact forces F_i [N], BL BR TR TL")
    loads.add_argument("--load-n", nargs=2, type=float, metavar=("NX", "NY"),
                       help="load on the top groove per ball [N] (default: the paper's "
                            f"case, {DEFAULT_LOAD_N[0]:g} {DEFAULT_LOAD_N[1]:g})")
    p.add_argument("--velocity-mm-s", type=float, default=None,
                   help=f"top-groove velocity v [mm/s] (default {TABLE1_GROOVE_VELOCITY*1e3:g}, "
                        "or the config's)")
    p.add_argument("--surface", choices=("planar", "curved"), default=None,
                   help="contact surface of --model full: the paper's plane (default) or the "
                        "deformed-surface arc of radius 2fD/(2f+1)")
    p.add_argument("--config", metavar="FILE",
                   help="study config (TOML) whose [bearing] and [motion] sections to use")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _add_static_arguments(p)
    _add_load_arguments(p)
    return p


def _add_load_arguments(p):
    """Options of the external loads on the ball (issue 13, part 1)."""
    g = p.add_argument_group("neighbours: push and ball-to-ball contact "
                             "(--model analytic or full)")
    loads = g.add_mutually_exclusive_group()
    loads.add_argument("--push-n", type=float, metavar="P",
                       help="net push on the ball along the rail through its centre [N], "
                            "+ from behind (along the top groove's motion)")
    loads.add_argument("--neighbour-forces-n", nargs=2, type=float,
                       metavar=("Q_BACK", "Q_FRONT"),
                       help="normal contact forces of the balls behind and in front [N] "
                            "(>= 0; push = Q_BACK - Q_FRONT, and their friction brakes the "
                            "ball's rolling)")
    g.add_argument("--ball-friction", type=float, metavar="MU",
                   help="Coulomb coefficient of the ball-to-ball contacts, with "
                        "--neighbour-forces-n (default 0.1)")


def _external_loads(args):
    """Keyword arguments of the external loads for the model, or {} without them."""
    if args.ball_friction is not None and args.neighbour_forces_n is None:
        raise UsageError("--ball-friction applies to the ball-to-ball contacts: give "
                         "--neighbour-forces-n Q_BACK Q_FRONT")
    flag = ("--push-n" if args.push_n is not None else
            "--neighbour-forces-n" if args.neighbour_forces_n is not None else None)
    if flag is None:
        return {}
    if args.model not in LOADED_MODELS:
        raise UsageError(f"{flag} needs --model {' or '.join(LOADED_MODELS)} (the {args.model} "
                         "model has no friction forces to carry a load)")
    if args.push_n is not None:
        if not math.isfinite(args.push_n):
            raise UsageError(f"--push-n must be a finite force in N, got {args.push_n:g}")
        return {"push": args.push_n}
    q_back, q_front = args.neighbour_forces_n
    if not (math.isfinite(q_back) and math.isfinite(q_front) and q_back >= 0 and q_front >= 0):
        raise UsageError("--neighbour-forces-n must be two finite forces >= 0 N (Q_BACK "
                         f"Q_FRONT), got {q_back:g} {q_front:g}")
    mu_bb = DEFAULT_BALL_FRICTION if args.ball_friction is None else args.ball_friction
    if not (math.isfinite(mu_bb) and mu_bb >= 0):
        raise UsageError(f"--ball-friction must be a finite coefficient >= 0, got {mu_bb:g}")
    _within_config_range("--ball-friction", mu_bb, "contact.ball_friction_coefficient", 1.0,
                         "")
    return {"neighbour_force": [q_back, q_front], "ball_friction": mu_bb}


#: Geometric-error options (argparse dest) -> (flag, unit, largest magnitude accepted)
STATIC_ERROR_OPTIONS = {
    "bottom_rotation_deg": ("--bottom-rotation-deg", "deg", 22.5),
    "top_rotation_deg": ("--top-rotation-deg", "deg", 22.5),
    "arc_offset_um": ("--arc-offset-um", "um", 50.0),
    "arc_offset_tangential_um": ("--arc-offset-tangential-um", "um", 50.0),
    "ball_oversize_um": ("--ball-oversize-um", "um", 50.0),
}


def _add_static_arguments(p):
    """Options of the static contact model (tolsim issue 3)."""
    g = p.add_argument_group("static contact and geometric errors")
    g.add_argument("--static", choices=("paired", "solved"), default="paired",
                   help="forces (and angles) from --load-n: the paper's paired approximation, "
                        "or the solved static equilibrium with Hertz contact")
    g.add_argument("--bottom-rotation-deg", type=float, metavar="THETA",
                   help="rotation of the bottom (rail) groove profile about the nominal ball "
                        "centre [deg], ccw positive: dbeta_BL = -theta, dbeta_BR = +theta")
    g.add_argument("--top-rotation-deg", type=float, metavar="THETA",
                   help="rotation of the top (carriage) groove profile [deg], ccw positive: "
                        "dbeta_TR = -theta, dbeta_TL = +theta")
    g.add_argument("--arc-offset-um", nargs=4, type=float, metavar=CONTACTS,
                   help="arc-centre offset of each flank along its contact line [um], "
                        "+ moves the flank away from the ball (clearance)")
    g.add_argument("--arc-offset-tangential-um", nargs=4, type=float, metavar=CONTACTS,
                   help="arc-centre offset of each flank across its contact line [um], "
                        "+ towards larger beta_i (about 0.143 deg per um for Table 1)")
    g.add_argument("--ball-oversize-um", type=float, metavar="DD",
                   help="ball diameter deviation [um], + = oversize (None: 0, a nominal ball)")


def _angles_and_forces(args, bearing):
    """Contact-angle deviations [deg], forces [N], force source, extra output, warnings."""
    given = {k: getattr(args, k) for k in STATIC_ERROR_OPTIONS if getattr(args, k) is not None}
    if given and args.dbeta_deg is not None:
        raise UsageError("give either --dbeta-deg or geometric errors ("
                         + ", ".join(STATIC_ERROR_OPTIONS[k][0] for k in given) + "), not both")
    if args.static == "solved" and args.forces_n is not None:
        raise UsageError("--static solved computes the forces from --load-n; drop --forces-n")
    dbeta_deg = np.array(DEFAULT_DBETA_DEG if args.dbeta_deg is None else args.dbeta_deg,
                         dtype=float)
    if not np.all(np.isfinite(dbeta_deg)):
        raise UsageError("--dbeta-deg must be four finite angles in degrees")
    limit = STATIC_ERROR_OPTIONS["bottom_rotation_deg"][2]
    if np.any(np.abs(dbeta_deg) > limit):
        worst = float(dbeta_deg[np.argmax(np.abs(dbeta_deg))])
        raise UsageError(f"--dbeta-deg {worst:g} is outside the model's range: contact-angle "
                         f"deviations must lie within +/-{limit:g} deg (pi/8, the range of "
                         "the static model and of the tolerance sources)")
    if not given and args.static == "paired":
        forces, source = _forces(args, bearing)
        warnings = []
        if source == "given":
            warnings.extend(_imbalance_warning(dbeta_deg, forces, bearing))
        return dbeta_deg, forces, source, {"contact_angle_source": "given"}, warnings
    for key, value in given.items():
        flag, unit, limit = STATIC_ERROR_OPTIONS[key]
        arr = np.atleast_1d(np.asarray(value, dtype=float))
        if not (np.all(np.isfinite(arr)) and np.all(np.abs(arr) <= limit)):
            raise UsageError(f"{flag} must be finite and within +/-{limit:g} {unit}")
    nx, ny = args.load_n if args.load_n is not None else DEFAULT_LOAD_N
    if not (math.isfinite(nx) and math.isfinite(ny)):
        raise UsageError("--load-n must be two finite numbers")

    from tolsim.physics.static import GrooveErrors, solve_static, turned_flank_offsets  # noqa: PLC0415

    normal = np.array(given.get("arc_offset_um", [0.0] * 4)) * 1e-6
    tangential = np.array(given.get("arc_offset_tangential_um", [0.0] * 4)) * 1e-6
    if not given:  # rigid dbeta_i realised by turning each flank about the ball centre
        normal, tangential = turned_flank_offsets(np.deg2rad(dbeta_deg), bearing)
    errors = GrooveErrors(
        arc_centre_offset_normal=normal,
        arc_centre_offset_tangential=tangential,
        bottom_rotation=np.deg2rad(given.get("bottom_rotation_deg", 0.0)),
        top_rotation=np.deg2rad(given.get("top_rotation_deg", 0.0)),
        ball_oversize=given.get("ball_oversize_um", 0.0) * 1e-6,
    )
    solved = args.static == "solved"
    sol = solve_static(nx, ny, errors, bearing, rigid=not solved)
    if not bool(sol.converged):
        raise UsageError(f"--load-n {nx:g} {ny:g}: no static equilibrium with compressive "
                         "contact forces (the load must press the top groove down)")
    dbeta_deg = np.rad2deg(sol.contact_angle_deviation)
    if solved:  # held to the ranges a given ball is (load 0 0: loose; 1e6 N: no Hertz ellipse)
        forces, source = sol.normal_force, "solved"
        _check_forces(np.asarray(forces, dtype=float), f"--load-n {nx:g} {ny:g} (solved forces)",
                      bearing)
        limit = STATIC_ERROR_OPTIONS["bottom_rotation_deg"][2]
        if np.any(np.abs(dbeta_deg) > limit):
            raise UsageError(f"--load-n {nx:g} {ny:g}: the solved contact angles move by "
                             f"{float(np.max(np.abs(dbeta_deg))):.3g} deg, beyond the models' "
                             f"+/-{limit:g} deg")
    else:
        forces, source = _forces(args, bearing)
    warnings = []
    if solved and not bool(sol.four_point):
        warnings.append(f"static solution in {int(sol.contact_count)}-point contact (a flank "
                        "carries no force): the analytical velocity models assume four-point "
                        "contact")
    extra = {
        "contact_angle_source": "solved" if solved else "geometric",
        "static": {
            "mode": args.static,
            "load_n": [float(nx), float(ny)],
            "converged": bool(sol.converged),
            "four_point": bool(sol.four_point),
            "contact_count": int(sol.contact_count),
            "newton_iterations": int(sol.iterations),
            "residual_n": float(sol.residual),
            "approach_um": [float(a) * 1e6 for a in sol.approach],
            "ball_displacement_um": [float(a) * 1e6 for a in sol.ball_displacement],
            "groove_displacement_um": [float(a) * 1e6 for a in sol.groove_displacement],
            "errors": {STATIC_ERROR_OPTIONS[k][0].lstrip("-"): v for k, v in given.items()},
        },
    }
    return dbeta_deg, forces, source, extra, warnings


def _bearing_and_velocity(args):
    """Bearing and top-groove velocity [m/s] from --config or Table 1."""
    bearing, velocity = TABLE1, TABLE1_GROOVE_VELOCITY
    if args.config is not None:
        if not args.config.strip():
            raise UsageError("--config: the path is empty")
        from tolsim.io.config import ConfigError, load_config  # io layer, only when asked # noqa: PLC0415

        try:
            config = load_config(args.config)
        except ConfigError as exc:
            raise UsageError(str(exc)) from None
        except OSError as exc:
            raise UsageError(f"--config: cannot read {args.config!r}: {exc.strerror}") from None
        bearing, velocity = config.bearing, config.motion.groove_velocity
    if args.velocity_mm_s is not None:
        if not (math.isfinite(args.velocity_mm_s) and args.velocity_mm_s > 0):
            raise UsageError(f"--velocity-mm-s must be a positive number, got "
                             f"{args.velocity_mm_s:g}")
        _within_config_range("--velocity-mm-s", args.velocity_mm_s, "motion.groove_velocity",
                             1e3, " mm/s")
        velocity = args.velocity_mm_s * 1e-3
    return bearing, velocity


def _within_config_range(flag, value, key, factor, unit):
    """Refuse ``value`` (in the option's unit: SI times ``factor``) beyond the possible
    interval that a config's ``key`` is held to (:data:`tolsim.io.config.plausibility.RANGES`),
    with its reason: an option takes what the config would."""
    from tolsim.io.config.plausibility import RANGES  # io layer, only when asked # noqa: PLC0415

    bound = RANGES[key]
    if bound.high is not None and value > bound.high * factor:
        raise UsageError(f"{flag} {value:g} is beyond {bound.high * factor:g}{unit}, the most "
                         f"the config's {key} takes ({bound.source})")


def largest_force(bearing) -> float:
    """Contact force [N] at which the Hertz ellipse's semi-major axis reaches R_B / 2, the
    edge of every velocity model (:func:`tolsim.physics.velocity.full.full` refuses beyond)."""
    from tolsim.physics.hertz import hertz_constants  # noqa: PLC0415

    hc = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                         bearing.poisson_ratio)
    return (0.5 * bearing.ball_radius / hc.semi_major_coefficient) ** 3


def _check_forces(forces, flag, bearing):
    """Reject force sets that mean nothing for a ball between two grooves.

    Negative or non-finite forces; no force at all (a loose ball: epsilon is undefined); a
    groove whose two flanks both carry nothing (the ball is not held between the grooves:
    no equilibrium); a force beyond :func:`largest_force`. A single zero force is a loss of
    contact at that flank, a real state that each model treats in its own way (see the
    warnings of :func:`evaluate`).
    """
    text = " ".join(f"{f:g}" for f in forces)
    if not np.all(np.isfinite(forces)) or np.any(forces < 0):
        raise UsageError(f"{flag} must be four finite forces >= 0 N, got {text}")
    if not np.any(forces > 0):
        raise UsageError(f"{flag} {text}: no contact carries a force, so the ball is loose "
                         "and its velocity is undefined")
    for groove, pair in (("bottom (BL, BR)", forces[:2]), ("top (TR, TL)", forces[2:])):
        if not np.any(pair > 0):
            raise UsageError(f"{flag} {text}: the {groove} groove carries no force, so the "
                             "ball is not held between the grooves (no equilibrium)")
    limit = largest_force(bearing)
    if np.any(forces > limit):
        raise UsageError(f"{flag} {text}: a force above {limit:.4g} N makes the Hertz "
                         "contact ellipse wider than R_B / 2, outside every model")


def _forces(args, bearing):
    """Four normal forces [N] and a description of where they came from."""
    if args.forces_n is not None:
        forces = np.array(args.forces_n, dtype=float)
        _check_forces(forces, "--forces-n", bearing)
        return forces, "given"
    nx, ny = args.load_n if args.load_n is not None else DEFAULT_LOAD_N
    if not (math.isfinite(nx) and math.isfinite(ny)):
        raise UsageError("--load-n must be two finite numbers")
    forces = paired_forces(nx, ny, bearing.nominal_contact_angle)
    if np.any(forces <= 0):
        raise UsageError(f"--load-n {nx:g} {ny:g}: |N_x| must be < N_y (tan beta_0 N_y) for "
                         "four-point contact; the paired approximation gives a force <= 0")
    _check_forces(forces, f"--load-n {nx:g} {ny:g} (paired forces)", bearing)
    return forces, "paired"


#: Net contact force over sum F above which --forces-n is said to be out of balance (the
#: round-off of four typed forces is far below it).
IMBALANCE_WARNING = 1e-6


def _imbalance_warning(dbeta_deg, forces, bearing):
    """[warning] when --forces-n cannot balance the ball in its cross-section, else []."""
    beta = bearing.nominal_contact_angle + np.deg2rad(dbeta_deg)
    fx, fy = contact_force_resultant(beta, forces)
    net = math.hypot(fx, fy)
    if not net > IMBALANCE_WARNING * float(np.sum(forces)):
        return []
    return [f"--forces-n: the forces do not balance the ball in its cross-section: net "
            f"contact force {net:.3g} N (x {fx:+.3g} N, y {fy:+.3g} N) at these contact "
            "angles; the result is for the forces as given"]


def _loss_of_contact_warning(model, forces, eps):
    """The warning for unloaded flanks or an undefined epsilon (None if neither)."""
    unloaded = [c for c, f in zip(CONTACTS, forces, strict=True) if not f > 0]
    if not unloaded and math.isfinite(eps):
        return None
    where = (f"{', '.join(unloaded)} {'carries' if len(unloaded) == 1 else 'carry'} no force "
             "(loss of contact)") if unloaded else "no value for these angles and forces"
    if math.isfinite(eps):
        runs = f"the ball runs on {4 - len(unloaded)} contacts"
        return (f"{where}: {runs}" if model == "full" else
                f"{where}: {runs}, the {model} model is derived for four; treat epsilon "
                "with caution")
    hint = "; --model full treats one unloaded contact" if (
        len(unloaded) == 1 and model != "full") else ""
    needs = "finds no solution" if model == "full" else "needs all four loaded"
    return f"epsilon is undefined: {where}, and the {model} model {needs}{hint}"


def evaluate(args):
    """Run the model for the parsed arguments; returns the JSON-ready dict."""
    bearing, velocity = _bearing_and_velocity(args)
    loads = _external_loads(args)
    dbeta_deg, forces, force_source, static_out, warnings = _angles_and_forces(args, bearing)
    dbeta = np.deg2rad(dbeta_deg)
    model = MODELS[args.model]
    # options only the full friction model takes (tolsim.physics.velocity.full.full)
    options = {}
    if args.model == "full":
        options = {"groove_velocity": velocity, "surface": args.surface or "planar"}
    elif args.surface is not None:
        raise UsageError("--surface applies to --model full only")
    try:
        result = model(dbeta, forces, bearing, **options, **loads)
    except ValueError as exc:  # inputs outside the model's domain, named by the model
        raise UsageError(f"--model {args.model}: {' '.join(str(exc).split())}") from None
    eps = float(result.velocity_deviation)
    sliding = bool(loads) and bool(result.sliding)
    contact_warning = None if sliding else _loss_of_contact_warning(args.model, forces, eps)
    if contact_warning:
        warnings.append(contact_warning)
    if sliding:
        warnings.append(_sliding_warning(result))
    elif not bool(result.valid) and math.isfinite(eps):
        warnings.append(f"{VALIDITY_NOTES.get(args.model, 'not valid')}: treat epsilon "
                        "with caution")
    gamma = result.zero_velocity_offset
    out = {
        "model": args.model,
        "velocity_deviation": eps,
        "velocity_deviation_percent": 100.0 * eps,
        "ball_velocity_m_s": (1.0 + eps) * velocity / 2.0,
        "groove_velocity_m_s": velocity,
        "normal_force_n": [float(f) for f in forces],
        "normal_force_source": force_source,
        "contact_angle_deg": [float(np.rad2deg(bearing.nominal_contact_angle) + d)
                              for d in dbeta_deg],
        "contact_angle_deviation_deg": [float(d) for d in dbeta_deg],
        "zero_velocity_offset_deg": (None if gamma is None
                                     else [float(g) for g in np.rad2deg(gamma)]),
        "valid": bool(result.valid),
        "warnings": warnings,
    }
    out.update(static_out)
    if result.velocity_deviation_eq22 is not None:
        out["velocity_deviation_eq22"] = float(result.velocity_deviation_eq22)
    if "sliding_contact" in result.extra:
        out["sliding_contact"] = CONTACTS[int(result.extra["sliding_contact"])]
    chi = float(stick_criterion(np.maximum(forces, 0.0), bearing))
    out["stick_criterion"] = chi if math.isfinite(chi) else None
    if args.model == "full":
        stuck = int(np.asarray(result.stuck_contact))
        out.update({
            "regime": BALL_REGIME_LABELS[int(ball_regime(np.asarray(forces)[None],
                                                         np.atleast_1d(result.regime))[0])],
            "stuck_contact": (CONTACTS[stuck] if 0 <= stuck < 4 else
                              "+".join(CONTACTS[k] for k in (stuck - 4, stuck - 2))
                              if stuck >= 4 else None),
            "surface": options["surface"],
            "converged": bool(result.converged),
            "residual": float(result.residual),
            "iterations": int(result.iterations),
            "angular_velocity_rad_s": [float(w) for w in result.angular_velocity],
            "contact_offset_ratio": [float(c) for c in result.contact_offset_ratio],
            "spin_to_roll": [float(c) for c in result.spin_to_roll],
            "drag_force_n": float(result.drag_force),
        })
        if not out["converged"]:
            warnings.append(f"full model did not converge: residual {out['residual']:.3g} "
                            f"after {out['iterations']} iterations")
    if loads:
        out.update(_load_output(args.model, loads, result))
    return out


def _sliding_warning(result):
    """The warning for a ball whose loads exceed what the raceway traction can carry."""
    push, capacity = float(result.push), float(result.traction_capacity)
    if abs(push) >= capacity:
        return (f"gross sliding: |push| {abs(push):.4g} N >= traction capacity {capacity:.4g} "
                "N, the raceways cannot hold the ball at a rolling speed (it is carried along "
                "by its neighbours)")
    return (f"gross sliding: Q_BACK + Q_FRONT = {float(result.neighbour_force_sum):.4g} N >= "
            f"braking capacity {float(result.braking_capacity):.4g} N, the ball-to-ball "
            "friction stalls the ball's rolling")


def _load_output(model, loads, result):
    """JSON fields of a loaded ball (tolsim.physics.velocity.ball_loads)."""
    out = {"push_n": float(result.push)}
    if "neighbour_force" in loads:
        out["neighbour_forces_n"] = [float(q) for q in loads["neighbour_force"]]
        out["ball_friction"] = float(loads["ball_friction"])
    out.update({
        "carriage_force_n": float(result.carriage_force),
        "free_rolling_carriage_force_n": float(result.free_rolling_carriage_force),
        "free_rolling_velocity_deviation": float(result.free_rolling_velocity_deviation),
        "creep_stiffness_n": float(result.creep_stiffness),
        "traction_capacity_n": float(result.traction_capacity),
        "braking_capacity_n": float(result.braking_capacity),
        "sliding": bool(result.sliding),
    })
    if model == "full":
        out.update({
            "dissipated_power_w": float(result.dissipated_power),
            "contact_dissipated_power_w": [float(p) for p in result.contact_dissipated_power],
            "ball_contact_dissipated_power_w": float(result.ball_contact_dissipated_power),
        })
    return out


def _percent(value):
    """A percentage to 4 decimals; a nonzero one that 4 decimals would show as 0.0000 in 3
    significant digits instead (an epsilon of -1e-17 % printed as -0.0000 %); an exact zero,
    of either sign, as +0.0000 %."""
    if value == 0.0 or abs(value) >= 5e-5:
        return f"{value + 0.0:+.4f} %"
    return f"{value:+.3g} %"


def _text(out):
    eps = out["velocity_deviation_percent"]
    # not printed as a number where it is none: the full model did not converge, or the ball
    # slides as a whole (the analytic model's epsilon then means nothing; the JSON keeps it
    # with "converged" and "sliding")
    defined = math.isfinite(eps) and out.get("converged") is not False and not out.get(
        "sliding", False)
    lines = [
        f"model                 {out['model']}",
        f"velocity deviation    {_percent(eps)}" if defined else
        "velocity deviation    undefined (see the warning)",
        (f"ball velocity         {out['ball_velocity_m_s'] * 1e3:.6f} mm/s " if defined else
         "ball velocity         undefined ")
        + f"(v/2 = {out['groove_velocity_m_s'] * 500:.6f} mm/s)",
        "contact               " + "  ".join(f"{c:>9}" for c in CONTACTS),
        "contact angle [deg]   " + "  ".join(f"{b:9.4f}" for b in out["contact_angle_deg"]),
        "normal force [N]      " + "  ".join(f"{f:9.3f}" for f in out["normal_force_n"]),
    ]
    if out["zero_velocity_offset_deg"] is not None:
        lines.append("dgamma [deg]          "
                     + "  ".join(f"{g:9.4f}" if math.isfinite(g) else f"{'undefined':>9}"
                                 for g in out["zero_velocity_offset_deg"]))
    if "velocity_deviation_eq22" in out and math.isfinite(out["velocity_deviation_eq22"]):
        lines.append(f"epsilon, Eq. (22)     {_percent(100 * out['velocity_deviation_eq22'])}")
    if "sliding_contact" in out:
        lines.append(f"sliding contact       {out['sliding_contact']}")
    if "drag_force_n" in out and math.isfinite(out["drag_force_n"]):
        lines.append(f"drag force            {out['drag_force_n']:.6g} N ({out['surface']} "
                     f"contact, residual {out['residual']:.2g})")
        lines.append("c/a                   "
                     + "  ".join(f"{c:9.4f}" if math.isfinite(c) else f"{'undefined':>9}"
                                 for c in out["contact_offset_ratio"]))
    chi = out.get("stick_criterion")
    regime = out.get("regime")
    if regime is not None:
        stuck = f", {out['stuck_contact']} stuck" if out.get("stuck_contact") else ""
        lines.append(f"regime                {regime}{stuck} (chi = "
                     f"{'inf' if chi is None else format(chi, '.4g')}; A: all contacts slip, "
                     "B: one sticks, chi < 1 favours B)")
    elif chi is not None:
        lines.append(f"stick criterion chi   {chi:.4g} (the {out['model']} model assumes every "
                     "contact slips, regime A; below 1 one contact sticks: --model full)")
    if "carriage_force_n" in out:
        lines += _load_text(out)
    if "static" in out:
        st = out["static"]
        lines.append(f"static contact        {st['mode']}: {st['contact_count']} loaded flanks, "
                     f"{st['newton_iterations']} Newton steps, approach [um] "
                     + " ".join(f"{a:.3f}" for a in st["approach_um"]))
    lines += [f"warning: {w}" for w in out["warnings"]]
    return "\n".join(lines)


def _load_text(out):
    """Text lines of a loaded ball."""
    def number(value, fmt):
        return format(value, fmt) if math.isfinite(value) else "undefined"

    push = (f"push                  {out['push_n']:+.6g} N" if "neighbour_forces_n" not in out
            else "neighbour forces      back {:.6g} N, front {:.6g} N (push {:+.6g} N, "
                 "mu_bb {:g})".format(*out["neighbour_forces_n"], out["push_n"],
                                      out["ball_friction"]))
    lines = [
        push,
        f"carriage force        {number(out['carriage_force_n'], '.6g')} N (free rolling "
        f"{number(out['free_rolling_carriage_force_n'], '.6g')} N; + opposes the carriage)",
        f"creep stiffness       {number(out['creep_stiffness_n'], '.6g')} N per unit epsilon",
        f"traction capacity     {number(out['traction_capacity_n'], '.6g')} N"
        + ("  (sliding)" if out["sliding"] else ""),
    ]
    if "dissipated_power_w" in out:
        lines.append(f"dissipated power      {number(out['dissipated_power_w'], '.6g')} W "
                     "(raceways and ball contacts)")
    return lines


def _strict_json(value):
    """NaN/inf (an undefined quantity, e.g. dgamma at an unloaded contact) -> null."""
    if isinstance(value, dict):
        return {k: _strict_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_strict_json(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def run(args):
    out = evaluate(args)
    if out.get("converged") is False and args.json:  # (the text prints its warnings)
        for w in out["warnings"]:
            print(f"tolsim ball: warning: {w}", file=sys.stderr)
    if args.json:
        print(json.dumps(_strict_json(out), indent=2, allow_nan=False))
    else:
        print(_text(out))
    return 0
