"""The source paper's figures and Table 2 as tidy data ([Lin2018] Fig. 4, Table 2, Fig. 7).

Each function returns a pandas DataFrame, one row per observation, ready to plot or print.
The plots and the ``tolsim paper`` command live in :mod:`tolsim.reports` and :mod:`tolsim.cli`.

Conformity ratios of Fig. 4: the paper plots "four typical conformity ratios of bearings
[6]" without listing them. Leblanc and Nelias [6] study gothic-arch four-point-contact
bearings, whose conformities lie between about 0.51 and 0.54; the paper's own Table 1 value
0.54 is the largest. We use f = 0.51, 0.52, 0.53, 0.54 (b/a = 0.08 to 0.18), which spans
that range and includes Table 1.

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033.
"""

import numpy as np
import pandas as pd

from tolsim.physics.geometry import (
    TABLE1,
    TABLE1_NORMAL_LOAD,
    Bearing,
    paired_forces,
)
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.static import GrooveErrors, solve_static
from tolsim.physics.velocity.analytic import analytic, eq24, point
from tolsim.physics.velocity.full import contact_friction, full

#: Conformity ratios of Fig. 4 (see the module docstring).
FIG4_CONFORMITIES = (0.51, 0.52, 0.53, 0.54)
#: Range of |c/a| over which the paper fits k_f ([Lin2018] Sec. 2.3).
KF_FIT_RANGE = 0.5
#: Angular nodes for the Fig. 4 curves (finer than the solver default: b/a down to 0.08).
FIG4_GRID = 128

#: [Lin2018] Table 2: epsilon [%] of Leblanc's model and of the derived formula (Eq. 26).
TABLE2_PAPER = {
    ("a", 1): {"Leblanc": 0.85, "formula": 0.75},
    ("a", 2): {"Leblanc": -0.77, "formula": -0.75},
    ("b", 1): {"Leblanc": 0.0, "formula": 0.0},
    ("b", 2): {"Leblanc": 0.0, "formula": 0.0},
}
#: Table 2 setup: theta = 2 deg, rho = -0.6 (ball 1) and +0.6 (ball 2), N_y = 200 N.
TABLE2_THETA_DEG = 2.0
TABLE2_SIDE_FORCE_RATIO = {1: -0.6, 2: 0.6}


def fig4_data(conformities=FIG4_CONFORMITIES, offset_ratio=None, normal_force=None,
              bearing: Bearing = TABLE1):
    """Fig. 4: normalised friction force and spin moment against c/a.

    Parameters
    ----------
    conformities : sequence of float
        Groove conformity ratios f [-].
    offset_ratio : array_like, optional
        c/a values [-]; default 401 points on [-3, 3].
    normal_force : float, optional
        F [N] that sets a/R_B for the moment normalisation; default the paired force of
        Table 1, sqrt(2)/2 * 200 N.
    bearing : Bearing
        Ball radius and material (its conformity is replaced by each of ``conformities``).

    Returns
    -------
    curves : DataFrame
        Columns conformity, ellipticity (b/a), offset_ratio (c/a), force (f_z/(mu F)),
        moment (M_O/(mu F R_B)), both normalised with sgn(omega) as in the paper.
    slopes : DataFrame
        One row per conformity: ellipticity, fitted_slope (least-squares k_f through the
        origin over |c/a| <= 0.5, [Lin2018] Sec. 2.3), slope_at_zero (central difference,
        ERRATA 7) and spin_moment_eq14 (3/8 a E(e) / R_B).
    """
    if offset_ratio is None:
        offset_ratio = np.linspace(-3.0, 3.0, 401)
    ratio = np.asarray(offset_ratio, dtype=float)
    force = TABLE1_NORMAL_LOAD * np.sqrt(0.5) if normal_force is None else float(normal_force)
    if not force > 0:
        raise ValueError(f"normal_force = {normal_force!r} must be > 0")
    fit = np.linspace(-KF_FIT_RANGE, KF_FIT_RANGE, 201)
    h = 1e-5
    curves, slopes = [], []
    for f in conformities:
        hc = hertz_constants(bearing.ball_radius, float(f), bearing.youngs_modulus,
                             bearing.poisson_ratio)
        a = hc.semi_major_coefficient * np.cbrt(force)
        b = hc.semi_minor_coefficient * np.cbrt(force)
        _, fz, mo = contact_friction(ratio, a, b, grid=FIG4_GRID)
        curves.append(pd.DataFrame({
            "conformity": float(f), "ellipticity": hc.ellipticity, "offset_ratio": ratio,
            "force": fz, "moment": mo / bearing.ball_radius,
        }))
        _, fz_fit, _ = contact_friction(fit, a, b, grid=FIG4_GRID)
        _, fz0, _ = contact_friction(np.array([-h, h]), a, b, grid=FIG4_GRID)
        slopes.append({
            "conformity": float(f),
            "ellipticity": hc.ellipticity,
            "fitted_slope": float(np.sum(fz_fit * fit) / np.sum(fit * fit)),
            "slope_at_zero": float((fz0[1] - fz0[0]) / (2 * h)),
            "spin_moment_eq14": 0.375 * a * hc.elliptic_e / bearing.ball_radius,
        })
    return pd.concat(curves, ignore_index=True), pd.DataFrame(slopes)


def _table2_cases(theta):
    """(case, ball, rho, dbeta) of Table 2; case (b) matches the top to the bottom."""
    for case, top in (("a", 0.0), ("b", theta)):
        for ball, rho in TABLE2_SIDE_FORCE_RATIO.items():
            yield case, ball, rho, top, np.array([-theta, theta, -top, top])


def table2_data(bearing: Bearing = TABLE1, normal_load=TABLE1_NORMAL_LOAD,
                theta_deg=TABLE2_THETA_DEG, static=True):
    """Table 2: epsilon of both balls in cases (a) and (b) from every model.

    Forces (``forces`` column): ``paired`` = the paper's approximation with the rigid angles
    dbeta = (-theta, theta, -top, top); ``static`` = the loaded angles and forces of
    :func:`tolsim.physics.static.solve_static` (elastic, no preload), with the rail turned by
    theta (and, case (b), the carriage too); ``paper`` = the values printed in Table 2.

    Parameters
    ----------
    bearing : Bearing
        Table 1 by default.
    normal_load : float
        N_y [N].
    theta_deg : float
        Rotation theta of the bottom groove [deg].
    static : bool
        Include the rows fed by the static contact model.

    Returns
    -------
    DataFrame
        Columns case, ball, side_force_ratio, theta_deg, top_deviation_deg (dbeta_TL =
        -dbeta_TR), forces, model (full, full-curved, analytic, eq24, Leblanc, formula),
        velocity_deviation_percent, converged.
    """
    theta = np.deg2rad(theta_deg)
    rows = []
    loads = [("paired", None)]
    if static:
        loads.append(("static", (GrooveErrors, solve_static)))
    for case, ball, rho, top, dbeta in _table2_cases(theta):
        base = {"case": case, "ball": ball, "side_force_ratio": rho, "theta_deg": theta_deg,
                "top_deviation_deg": np.rad2deg(top)}
        for source, solver in loads:
            if solver is None:
                dev = dbeta
                force = paired_forces(rho * normal_load, normal_load,
                                      bearing.nominal_contact_angle)
                ok = True
            else:
                errors_cls, solve = solver
                sol = solve(rho * normal_load, normal_load,
                            errors_cls(bottom_rotation=theta, top_rotation=top), bearing)
                dev, force = sol.contact_angle_deviation, sol.normal_force
                ok = bool(sol.converged) and bool(sol.four_point)
            results = {
                "full": full(dev, force, bearing),
                "full-curved": full(dev, force, bearing, surface="curved"),
                "analytic": analytic(dev, force, bearing),
                "eq24": eq24(dev, force, bearing),
            }
            for model, res in results.items():
                conv = bool(getattr(res, "converged", True)) and ok
                rows.append({**base, "forces": source, "model": model,
                             "velocity_deviation_percent": 100.0 * float(res.velocity_deviation),
                             "converged": conv})
        for model, value in TABLE2_PAPER[(case, ball)].items():
            rows.append({**base, "forces": "paper", "model": model,
                         "velocity_deviation_percent": value, "converged": True})
    return pd.DataFrame(rows)


def fig7_data(side_force_ratio=None, theta_deg=None, bearing: Bearing = TABLE1,
              normal_load=TABLE1_NORMAL_LOAD, surface="planar"):
    """Fig. 7: epsilon over the side-force ratio and the bottom-groove rotation.

    dbeta = (-theta, +theta, 0, 0) with paired forces (the paper's Fig. 6 setup).

    Parameters
    ----------
    side_force_ratio : array_like, optional
        rho = N_x / N_y values [-]; default 17 points on [-0.8, 0.8].
    theta_deg : array_like, optional
        theta values [deg]; default 13 points on [-3, 3].
    bearing : Bearing
        Table 1 by default.
    normal_load : float
        N_y [N].
    surface : {"planar", "curved"}
        Contact surface of the full model.

    Returns
    -------
    DataFrame
        One row per grid point: side_force_ratio, theta_deg, full, analytic, eq24, point
        (epsilon [%] of each model), full_converged, and the differences
        full_minus_analytic, full_minus_eq24, full_minus_point [percentage points].
    """
    rho = np.linspace(-0.8, 0.8, 17) if side_force_ratio is None else np.asarray(
        side_force_ratio, dtype=float)
    theta = np.linspace(-3.0, 3.0, 13) if theta_deg is None else np.asarray(theta_deg,
                                                                           dtype=float)
    rr, tt = np.meshgrid(rho.ravel(), theta.ravel(), indexing="ij")
    rr, tt = rr.ravel(), tt.ravel()
    th = np.deg2rad(tt)
    dbeta = np.stack([-th, th, np.zeros_like(th), np.zeros_like(th)], axis=-1)
    force = paired_forces(rr * normal_load, normal_load, bearing.nominal_contact_angle)
    res_full = full(dbeta, force, bearing, surface=surface)
    out = pd.DataFrame({"side_force_ratio": rr, "theta_deg": tt})
    out["full"] = 100.0 * res_full.velocity_deviation
    out["full_converged"] = res_full.converged
    for name, model in (("analytic", analytic), ("eq24", eq24), ("point", point)):
        out[name] = 100.0 * model(dbeta, force, bearing).velocity_deviation
        out[f"full_minus_{name}"] = out["full"] - out[name]
    return out
