"""Sensitivities of the static solution to errors and loads, and the linearised model."""

from dataclasses import dataclass, fields

import numpy as np

from tolsim.physics.geometry import CONTACTS, TABLE1, Bearing
from tolsim.physics.static.solve import (
    GrooveErrors,
    StaticSolution,
    as_float,
    prepare_inputs,
    solve_static,
)

# --------------------------------------------------------------------------------------------
# Linear sensitivities and the linearised model
# --------------------------------------------------------------------------------------------
#: Output rows of the sensitivity matrix and their units.
SENSITIVITY_ROWS = tuple(f"contact_angle_deviation_{c}" for c in CONTACTS) + tuple(
    f"normal_force_{c}" for c in CONTACTS)
SENSITIVITY_ROW_UNITS = ("rad",) * 4 + ("N",) * 4
#: Input columns: (label, GrooveErrors field or load name, component index or None, unit).
_COLUMNS = (
    [(f"arc_centre_offset_normal_{c}", "arc_centre_offset_normal", i, "m")
     for i, c in enumerate(CONTACTS)]
    + [(f"arc_centre_offset_tangential_{c}", "arc_centre_offset_tangential", i, "m")
       for i, c in enumerate(CONTACTS)]
    + [("bottom_rotation", "bottom_rotation", None, "rad"),
       ("top_rotation", "top_rotation", None, "rad"),
       ("bottom_offset_x", "bottom_offset", 0, "m"), ("bottom_offset_y", "bottom_offset", 1, "m"),
       ("top_offset_x", "top_offset", 0, "m"), ("top_offset_y", "top_offset", 1, "m"),
       ("ball_oversize", "ball_oversize", None, "m"),
       ("side_load", "side_load", None, "N"), ("normal_load", "normal_load", None, "N")]
)
SENSITIVITY_COLUMNS = tuple(c[0] for c in _COLUMNS)
SENSITIVITY_COLUMN_UNITS = tuple(c[3] for c in _COLUMNS)


@dataclass(frozen=True)
class StaticSensitivity:
    """Linear sensitivities d(dbeta_i, F_i) / d(errors, loads) of one ball at a nominal state.

    Attributes
    ----------
    matrix : ndarray, (8, 17)
        ``matrix[r, c]`` = d row_r / d column_c, in row unit per column unit (e.g. rad/m).
    rows, row_units : tuple of str
        ``SENSITIVITY_ROWS`` (dbeta_BL..TL [rad], F_BL..TL [N]) and their units.
    columns, column_units : tuple of str
        ``SENSITIVITY_COLUMNS``: the 8 arc-centre offsets, the two rotations, the four groove
        offset components, the ball oversize, then N_x and N_y; and their units.
    nominal : StaticSolution
        The solution at the nominal state (ball shape ()).
    side_load, normal_load : float
        Nominal loads [N].
    errors : GrooveErrors
        Nominal errors.
    rigid : bool
        Whether the rigid (geometric) solution was differentiated.
    """

    matrix: np.ndarray
    rows: tuple
    row_units: tuple
    columns: tuple
    column_units: tuple
    nominal: StaticSolution
    side_load: float
    normal_load: float
    errors: GrooveErrors
    rigid: bool

    def entry(self, row: str, column: str) -> float:
        """One derivative by labels, e.g. ``entry("contact_angle_deviation_BL",
        "bottom_rotation")``."""
        return float(self.matrix[self.rows.index(row), self.columns.index(column)])

    def table(self) -> str:
        """Plain-text table in practical units (deg and N per um, per deg and per N)."""
        conv_row = [np.rad2deg(1.0)] * 4 + [1.0] * 4
        unit_row = ["deg"] * 4 + ["N"] * 4
        col_scale = {"m": (1e-6, "um"), "rad": (np.deg2rad(1.0), "deg"), "N": (1.0, "N")}
        head = f"{'d(row)/d(column)':<40}" + "".join(f"{'db_' + r[-2:]:>11}" for r in self.rows[:4])
        head += "".join(f"{'F_' + r[-2:]:>11}" for r in self.rows[4:])
        lines = [head, " " * 40 + "".join(f"{'[' + u + '/.]':>11}" for u in unit_row)]
        for j, (col, unit) in enumerate(zip(self.columns, self.column_units, strict=True)):
            scale, label = col_scale[unit]
            vals = self.matrix[:, j] * scale * np.array(conv_row)
            lines.append(f"{col + ' [./' + label + ']':<40}"
                         + "".join(f" {v:10.4g}" for v in vals))
        return "\n".join(lines)


def _single(errors, name):
    """Each field of ``errors`` reduced to one ball (raise if it holds several)."""
    errors = GrooveErrors() if errors is None else errors
    if not isinstance(errors, GrooveErrors):
        raise ValueError(f"{name} must be a GrooveErrors, got {type(errors).__name__}")
    out = {}
    for f in fields(GrooveErrors):
        trailing = GrooveErrors.TRAILING[f.name]
        arr = as_float(f"{name}.{f.name}", getattr(errors, f.name))[0]
        target = (trailing,) if trailing else ()
        try:
            out[f.name] = np.broadcast_to(arr, target).copy()
        except ValueError:
            raise ValueError(f"{name}.{f.name} must describe a single ball (shape {target} "
                             f"or broadcastable), got {arr.shape}") from None
    return out


def static_sensitivity(side_load: float, normal_load: float, errors: GrooveErrors | None = None,
                       bearing: Bearing = TABLE1, *, rigid: bool = False,
                       length_step: float = 1e-9, angle_step: float = 1e-7,
                       load_step: float | None = None) -> StaticSensitivity:
    """Matrix of d(dbeta_i, F_i)/d(errors, loads) at one nominal state, by central differences.

    All 2 x 17 perturbed states and the nominal one are solved in one vectorised call of
    :func:`solve_static`. For a rigid ball at the nominal centre the tangential arc-centre
    offset gives d beta_i / d e_t = 1 / ((f - 1/2) 2 R_B) (0.1432 deg/um for Table 1) and a
    groove rotation d beta = -/+ 1 ([Lin2018] Fig. 6); the elastic solution shows how the load
    changes those.

    Parameters
    ----------
    side_load, normal_load : float
        Nominal N_x, N_y [N].
    errors : GrooveErrors, optional
        Nominal errors of one ball (default: none).
    bearing : Bearing
        Geometry and material.
    rigid : bool
        Differentiate the rigid (geometric) solution instead of the elastic one.
    length_step, angle_step : float
        Central-difference steps for lengths [m] and rotations [rad].
    load_step : float, optional
        Step for the loads [N]; default 1e-6 max(|N_x|, N_y, 1 N).

    Returns
    -------
    StaticSensitivity
    """
    base = _single(errors, "errors")
    nx0 = float(as_float("side_load", side_load)[0])
    ny0 = float(as_float("normal_load", normal_load)[0])
    for name, step in (("length_step", length_step), ("angle_step", angle_step)):
        if not (np.isfinite(step) and step > 0):
            raise ValueError(f"{name} = {step!r} must be positive")
    if load_step is None:
        load_step = 1e-6 * max(abs(nx0), abs(ny0), 1.0)
    if not (np.isfinite(load_step) and load_step > 0):
        raise ValueError(f"load_step = {load_step!r} must be positive")
    ncol = len(_COLUMNS)
    nball = 2 * ncol + 1
    batch = {k: np.repeat(v[None, ...], nball, axis=0) for k, v in base.items()}
    loads = {"side_load": np.full(nball, nx0), "normal_load": np.full(nball, ny0)}
    steps = np.empty(ncol)
    for j, (_label, field, comp, unit) in enumerate(_COLUMNS):
        h = {"m": length_step, "rad": angle_step, "N": load_step}[unit]
        steps[j] = h
        arr = loads[field] if field in loads else batch[field]
        for sign, row in ((1.0, 1 + 2 * j), (-1.0, 2 + 2 * j)):
            if comp is None:
                arr[row] += sign * h
            else:
                arr[row, comp] += sign * h
    sol = solve_static(loads["side_load"], loads["normal_load"], GrooveErrors(**batch), bearing,
                       rigid=rigid)
    out = np.concatenate([sol.contact_angle_deviation, sol.normal_force], axis=1)  # (nball, 8)
    matrix = (out[1::2] - out[2::2]).T / (2.0 * steps)
    nominal = StaticSolution(*(getattr(sol, f.name)[0] for f in fields(StaticSolution)))
    return StaticSensitivity(matrix, SENSITIVITY_ROWS, SENSITIVITY_ROW_UNITS,
                             SENSITIVITY_COLUMNS, SENSITIVITY_COLUMN_UNITS, nominal, nx0, ny0,
                             GrooveErrors(**base), bool(rigid))


def linearised_static(sensitivity: StaticSensitivity, side_load=None, normal_load=None,
                      errors: GrooveErrors | None = None):
    """Cheap first-order prediction of dbeta_i and F_i from a :class:`StaticSensitivity`.

    dbeta = dbeta_nom + S_beta (x - x_nom), F = F_nom + S_F (x - x_nom), with x the 17
    inputs of the sensitivity columns. No flank unloading and no convergence check: use only
    where the full solution stays in four-point contact (its error against
    :func:`solve_static` is measured in ``tests/physics/test_static.py`` and
    ``benchmarks/bench_static.py``).

    Parameters
    ----------
    sensitivity : StaticSensitivity
        Linearisation point and matrix.
    side_load, normal_load : array_like, optional
        Loads [N] (default: the nominal ones).
    errors : GrooveErrors, optional
        Errors of the balls (default: the nominal ones).

    Returns
    -------
    contact_angle_deviation, normal_force : ndarray, s + (4,)
        dbeta_i [rad] and F_i [N] (F_i clipped at 0).
    """
    nominal = sensitivity.errors
    errors = nominal if errors is None else errors
    nx = sensitivity.side_load if side_load is None else side_load
    ny = sensitivity.normal_load if normal_load is None else normal_load
    items = [("side_load", nx, 0), ("normal_load", ny, 0)]
    items += [(f"errors.{f.name}", getattr(errors, f.name), GrooveErrors.TRAILING[f.name])
              for f in fields(GrooveErrors)]
    arrays, shape = prepare_inputs(items, TABLE1)
    values = dict(zip(["side_load", "normal_load"] + [f.name for f in fields(GrooveErrors)],
                      arrays, strict=True))
    base = _single(nominal, "sensitivity.errors")
    base["side_load"] = np.array(sensitivity.side_load)
    base["normal_load"] = np.array(sensitivity.normal_load)
    size = int(np.prod(shape))
    delta = np.zeros((size, len(_COLUMNS)))
    for j, (_label, field, comp, _unit) in enumerate(_COLUMNS):
        col = values[field][:, 0 if comp is None else comp]
        ref = base[field] if comp is None else base[field][comp]
        delta[:, j] = col - ref
    nom = np.concatenate([sensitivity.nominal.contact_angle_deviation,
                          sensitivity.nominal.normal_force])
    pred = nom + delta @ sensitivity.matrix.T
    return (pred[:, :4].reshape(shape + (4,)),
            np.maximum(pred[:, 4:], 0.0).reshape(shape + (4,)))
