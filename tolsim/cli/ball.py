"""``tolsim ball``: the velocity deviation of one ball.

The ball's four contact-angle deviations come from ``--dbeta-deg``; its four normal forces
from ``--forces-n`` or from the top-groove load ``--load-n NX NY``.
"""

import json
import math

import numpy as np

from tolsim.cli import UsageError
from tolsim.physics.geometry import (
    CONTACTS,
    TABLE1,
    TABLE1_GROOVE_VELOCITY,
    TABLE1_NORMAL_LOAD,
    paired_forces,
)
from tolsim.physics.models import MODELS, VALIDITY_NOTES

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

Loads: --forces-n gives the four normal forces directly; --load-n NX NY gives the load on the
top groove per ball (N_x toward +x, i.e. toward BR/TR; N_y pressing down), turned into forces
with the paper's paired approximation F_BL = F_TR = sqrt(2)/2 (N_y - N_x),
F_BR = F_TL = sqrt(2)/2 (N_y + N_x) (at 45 deg).

Defaults are the paper's Table 1 (R_B = 5 mm, f = 0.54, beta_0 = 45 deg, E = 210 GPa,
nu = 0.28, mu = 0.1, v = 10 mm/s); --config FILE takes the [bearing] and [motion] sections of
a study config instead.

Examples:
  tolsim ball                                     # Table 2, case (a), ball 1
  tolsim ball --dbeta-deg -2 2 0 0 --load-n 120 200 --json
  tolsim ball --model analytic --dbeta-deg -1 1 0.5 0 --forces-n 150 60 140 55
"""

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
    p.add_argument("--dbeta-deg", nargs=4, type=float, metavar=CONTACTS,
                   default=list(DEFAULT_DBETA_DEG),
                   help="contact-angle deviations dbeta_i [deg], BL BR TR TL")
    loads = p.add_mutually_exclusive_group()
    loads.add_argument("--forces-n", nargs=4, type=float, metavar=CONTACTS,
                       help="normal contact forces F_i [N], BL BR TR TL")
    loads.add_argument("--load-n", nargs=2, type=float, metavar=("NX", "NY"),
                       help="load on the top groove per ball [N] (default: the paper's "
                            f"case, {DEFAULT_LOAD_N[0]:g} {DEFAULT_LOAD_N[1]:g})")
    p.add_argument("--velocity-mm-s", type=float, default=None,
                   help=f"top-groove velocity v [mm/s] (default {TABLE1_GROOVE_VELOCITY*1e3:g}, "
                        "or the config's)")
    p.add_argument("--config", metavar="FILE",
                   help="study config (TOML) whose [bearing] and [motion] sections to use")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    return p


def _bearing_and_velocity(args):
    """Bearing and top-groove velocity [m/s] from --config or Table 1."""
    bearing, velocity = TABLE1, TABLE1_GROOVE_VELOCITY
    if args.config:
        from tolsim.io.config import ConfigError, load_config  # io layer, only when asked

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
        velocity = args.velocity_mm_s * 1e-3
    return bearing, velocity


def _forces(args, bearing):
    """Four normal forces [N] and a description of where they came from."""
    if args.forces_n is not None:
        forces = np.array(args.forces_n, dtype=float)
        if not np.all(np.isfinite(forces)) or np.any(forces < 0):
            raise UsageError(f"--forces-n must be four finite forces >= 0 N, got "
                             f"{' '.join(f'{f:g}' for f in args.forces_n)}")
        return forces, "given"
    nx, ny = args.load_n if args.load_n is not None else DEFAULT_LOAD_N
    if not (math.isfinite(nx) and math.isfinite(ny)):
        raise UsageError("--load-n must be two finite numbers")
    forces = paired_forces(nx, ny, bearing.nominal_contact_angle)
    if np.any(forces <= 0):
        raise UsageError(f"--load-n {nx:g} {ny:g}: |N_x| must be < N_y (tan beta_0 N_y) for "
                         "four-point contact; the paired approximation gives a force <= 0")
    return forces, "paired"


def evaluate(args):
    """Run the model for the parsed arguments; returns the JSON-ready dict."""
    dbeta_deg = np.array(args.dbeta_deg, dtype=float)
    if not np.all(np.isfinite(dbeta_deg)):
        raise UsageError("--dbeta-deg must be four finite angles in degrees")
    bearing, velocity = _bearing_and_velocity(args)
    forces, force_source = _forces(args, bearing)
    dbeta = np.deg2rad(dbeta_deg)
    model = MODELS[args.model]
    result = model(dbeta, forces, bearing)
    eps = float(result.velocity_deviation)
    warnings = []
    if not bool(result.valid):
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
    if result.velocity_deviation_eq22 is not None:
        out["velocity_deviation_eq22"] = float(result.velocity_deviation_eq22)
    if "sliding_contact" in result.extra:
        out["sliding_contact"] = CONTACTS[int(result.extra["sliding_contact"])]
    return out


def _text(out):
    lines = [
        f"model                 {out['model']}",
        f"velocity deviation    {out['velocity_deviation_percent']:+.4f} %",
        f"ball velocity         {out['ball_velocity_m_s'] * 1e3:.6f} mm/s "
        f"(v/2 = {out['groove_velocity_m_s'] * 500:.6f} mm/s)",
        "contact               " + "  ".join(f"{c:>9}" for c in CONTACTS),
        "contact angle [deg]   " + "  ".join(f"{b:9.4f}" for b in out["contact_angle_deg"]),
        "normal force [N]      " + "  ".join(f"{f:9.3f}" for f in out["normal_force_n"]),
    ]
    if out["zero_velocity_offset_deg"] is not None:
        lines.append("dgamma [deg]          "
                     + "  ".join(f"{g:9.4f}" for g in out["zero_velocity_offset_deg"]))
    if "velocity_deviation_eq22" in out:
        lines.append(f"epsilon, Eq. (22)     {100 * out['velocity_deviation_eq22']:+.4f} %")
    if "sliding_contact" in out:
        lines.append(f"sliding contact       {out['sliding_contact']}")
    lines += [f"warning: {w}" for w in out["warnings"]]
    return "\n".join(lines)


def run(args):
    out = evaluate(args)
    print(json.dumps(out, indent=2) if args.json else _text(out))
    return 0
