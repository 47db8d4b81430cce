"""Static contact model: from groove errors and loads to loaded contact angles and forces.

[Lin2018] takes the contact angles beta_i and the normal forces F_i as given "a priori from
static load distribution models" (its ref. [12]). This package computes them, per ball, in the
cross-section of the bearing (global x lateral, y up, ball centre nominally at the origin).

The gothic-arch geometry and the groove errors are in the Notes of :class:`GrooveErrors`, the
static solutions in those of :func:`solve_static`. Layout: ``solve`` (the errors, the
validated inputs and the solves), ``sensitivity`` (the sensitivity matrix and the linearised
model), ``_kernels`` (the Numba loops).

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033 (Sec. 2.1, Fig. 2,
   Fig. 6, Table 2).
.. [Johnson1985] K. L. Johnson, Contact Mechanics, Cambridge University Press, 1985 (Hertz).
"""

from tolsim.physics.geometry import CONTACTS
from tolsim.physics.static._kernels import (
    FLOOR_LENGTH,
    arc_centres,
    ball_outputs,
    displacement_one,
    flank,
    flank_newton,
    move_top_groove,
    static_displacement_kernel,
    static_load_kernel,
)
from tolsim.physics.static.sensitivity import (
    SENSITIVITY_COLUMN_UNITS,
    SENSITIVITY_COLUMNS,
    SENSITIVITY_ROW_UNITS,
    SENSITIVITY_ROWS,
    StaticSensitivity,
    linearised_static,
    static_sensitivity,
)
from tolsim.physics.static.solve import (
    DEFAULT_MAX_ITER,
    DEFAULT_TOLERANCE,
    GrooveErrors,
    StaticSolution,
    as_float,
    check_solver_options,
    error_items,
    hertz_k,
    prepare_inputs,
    solve_static,
    solve_static_displacement,
    turned_flank_offsets,
)

__all__ = [
    "CONTACTS",
    "DEFAULT_MAX_ITER",
    "DEFAULT_TOLERANCE",
    "FLOOR_LENGTH",
    "SENSITIVITY_COLUMNS",
    "SENSITIVITY_COLUMN_UNITS",
    "SENSITIVITY_ROWS",
    "SENSITIVITY_ROW_UNITS",
    "GrooveErrors",
    "StaticSensitivity",
    "StaticSolution",
    "arc_centres",
    "as_float",
    "ball_outputs",
    "check_solver_options",
    "displacement_one",
    "error_items",
    "flank",
    "flank_newton",
    "hertz_k",
    "linearised_static",
    "move_top_groove",
    "prepare_inputs",
    "solve_static",
    "solve_static_displacement",
    "static_displacement_kernel",
    "static_load_kernel",
    "static_sensitivity",
    "turned_flank_offsets",
]
