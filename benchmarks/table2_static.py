"""[Lin2018] Table 2 with loaded contact angles and forces from the static contact model.

Case (a): the bottom groove turned by theta = 2 deg (dbeta_BL = -2, dbeta_BR = +2 deg when
rigid), N_y = 200 N, rho = N_x/N_y = -0.6 (ball 1) and +0.6 (ball 2), no preload, Table 1
bearing, rigid grooves apart from Hertz contact. Case (b): the top groove turned by the same
angle. For each ball the script prints the loaded dbeta_i and F_i of
:func:`tolsim.physics.static.solve_static` and epsilon from ``analytic`` (Eq. 23; Eq. 22
alongside), next to the paper's inputs (rigid angles, paired forces) and, when registered, the
comprehensive ``full`` model fed the same loaded state.

Paper, Table 2 case (a): Leblanc's comprehensive model eps_1 = +0.85 %, eps_2 = -0.77 %;
derived formula (paired forces) +/-0.75 %. Case (b): 0 and 0.

Run: ``python benchmarks/table2_static.py``
"""

import numpy as np

from tolsim.physics.geometry import CONTACTS, TABLE1, TABLE1_NORMAL_LOAD, paired_forces
from tolsim.physics.static import GrooveErrors, solve_static
from tolsim.physics.velocity.analytic import analytic
from tolsim.physics.velocity.models import MODELS

THETA = np.deg2rad(2.0)
RHO = np.array([-0.6, 0.6])
LEBLANC = {"a": (0.85, -0.77), "b": (0.0, 0.0)}


def rows(case):
    errors = GrooveErrors(bottom_rotation=THETA,
                          top_rotation=THETA if case == "b" else 0.0)
    ny = TABLE1_NORMAL_LOAD
    nx = RHO * ny
    rigid = solve_static(nx, ny, errors, rigid=True)
    loaded = solve_static(nx, ny, errors)
    out = []
    for label, db, force in (
        ("rigid angles, paired forces", rigid.contact_angle_deviation, paired_forces(nx, ny)),
        ("rigid angles, solved rigid forces", rigid.contact_angle_deviation, rigid.normal_force),
        ("loaded angles and forces (Hertz)", loaded.contact_angle_deviation,
         loaded.normal_force),
    ):
        res = analytic(db, force, TABLE1)
        extra = {}
        if "full" in MODELS:
            full = MODELS["full"](db, force, TABLE1)
            extra["full"] = 100 * np.asarray(full.velocity_deviation)
        out.append((label, np.rad2deg(db), force, 100 * res.velocity_deviation,
                    100 * res.velocity_deviation_eq22, res.valid, extra))
    return out, loaded


def main():
    for case in ("a", "b"):
        print(f"\nTable 2, case ({case}): theta = 2 deg bottom"
              + (" and top" if case == "b" else "") + " rotation, N_y = 200 N, no preload")
        print(f"Leblanc (paper): eps_1 = {LEBLANC[case][0]:+.2f} %, "
              f"eps_2 = {LEBLANC[case][1]:+.2f} %")
        table, loaded = rows(case)
        for label, db, force, eps, eps22, valid, extra in table:
            print(f"\n  {label}")
            print("  ball  rho    " + "".join(f"dbeta_{c:<4}" for c in CONTACTS)
                  + "".join(f"F_{c:<7}" for c in CONTACTS) + "eps(23)  eps(22)  valid"
                  + ("   full" if extra else ""))
            for j in range(2):
                line = (f"  {j + 1}    {RHO[j]:+.1f}  "
                        + "".join(f"{v:+9.3f} " for v in db[j])
                        + "".join(f"{v:8.2f} " for v in force[j])
                        + f"{eps[j]:+7.3f}  {eps22[j]:+7.3f}  {bool(valid[j])!s:5}")
                if extra:
                    line += f"  {extra['full'][j]:+7.3f}"
                print(line)
        print("  static solution: converged", loaded.converged.tolist(), "four-point",
              loaded.four_point.tolist(), "Newton steps", loaded.iterations.tolist(),
              "approach [um]", np.round(loaded.approach * 1e6, 3).tolist())


if __name__ == "__main__":
    main()
