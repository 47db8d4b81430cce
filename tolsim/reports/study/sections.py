"""The tables of a study report (HTML and PDF share them), the section titles, and the
section "Carriage" of a carriage study."""

from dataclasses import dataclass

import numpy as np

from tolsim.physics.hertz import hertz_constants
from tolsim.reports.assumptions import (
    carriage_load_items,
    distribution_text,
)
from tolsim.reports.result_view import (
    config_key,
    config_toml,
    integer,
    number,
)
from tolsim.reports.verdict import (
    any_train,
    counted,
    has_friction,
    tracks_of,
)


# --------------------------------------------------------------------------------------------
# Carriage (a study with [carriage]: HTML and PDF share these tables)
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReportTable:
    """A table of the report (HTML and PDF).

    Attributes
    ----------
    heading : str
    header : tuple of str
    rows : tuple of tuple of str
    widths : tuple of float
        Column widths as fractions of the text width (PDF).
    note : str
        A sentence below the table.
    numeric : tuple of int
        Columns right-aligned in HTML.
    """

    heading: str
    header: tuple
    rows: tuple
    widths: tuple
    note: str = ""
    numeric: tuple = ()


def section_titles(ds) -> dict:
    """Figure name -> heading of its section; the model check names the study's velocity
    model (``velocity_model`` attribute). A carriage study has a section 3 "Carriage"
    (figure ``carriage``), and the sections after it move down by one; a study with
    ``[contact]`` has a section "What contact costs" (figure ``friction``) after the contact
    section, and the sections after it move down by one more."""
    model = ds.attrs.get("velocity_model", "?")
    k = 1 if tracks_of(ds) else 0  # a carriage study has its section 3 "Carriage"
    c = 1 if has_friction(ds) else 0  # a study with [contact]: "What contact costs"
    titles = {"velocity_deviation": f"{3 + k}. Ball velocity deviation ε",
              "contact": f"{4 + k}. Ball-to-ball contact",
              "quality": f"{5 + k + c}. Quality engineering",
              "sensitivity": f"{6 + k + c}. What drives the risk",
              "spot_checks": f"{7 + k + c}. Model check: {model} versus the full friction "
                             "model"}
    if c:
        titles["friction"] = (f"{5 + k}. What contact costs: carriage friction after the "
                              "balls touch")
    if k:
        titles = {"carriage": "3. Carriage: load case, preload, load distribution and "
                              "stiffness", **titles}
    return titles


#: Labels of the carriage degrees of freedom (``carriage_translation_name``,
#: ``carriage_rotation_name``): name -> (displacement, stiffness).
CARRIAGE_DOF_LABELS = {
    "u_x": ("lateral displacement u_x [µm]", "lateral stiffness [N/µm]"),
    "u_y": ("vertical displacement u_y [µm] (+ up)", "vertical stiffness [N/µm]"),
    "pitch": ("pitch rotation (about x) [µrad]", "pitching stiffness [N m/µrad]"),
    "yaw": ("yaw rotation (about y) [µrad]", "yawing stiffness [N m/µrad]"),
    "roll": ("roll rotation (about z) [µrad]", "rolling stiffness [N m/µrad]"),
}
CARRIAGE_STATISTICS = ("nominal", "mean", "std", "min", "max")


def _fixed(x, digits=4):
    """A value with fixed decimals, 'n/a' for NaN, never '-0.0000'."""
    if not np.isfinite(x):
        return "n/a"
    return f"{round(float(x), digits) + 0.0:.{digits}f}"


def significant(x, digits=4):
    return f"{float(x):.{digits}g}" if np.isfinite(x) else "n/a"


def _span(values, fmt="{:.4g}"):
    """'lo to hi' of an array (one value when they agree), 'n/a' when empty or NaN."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "n/a"
    lo, hi = fmt.format(v.min() + 0.0), fmt.format(v.max() + 0.0)
    return lo if lo == hi else f"{lo} to {hi}"


def _carriage_names(ds, what):
    label = f"carriage_{what}_name"
    return [str(n) for n in np.asarray(ds[label])] if label in ds.variables else []


def carriage_dof_rows(ds) -> list:
    """(label, [nominal, mean, std, min, max]) of every carriage displacement and stiffness
    in display units (µm, µrad, N/µm, N m/µrad), displacements first."""
    rows = []
    for kind in ("displacement", "stiffness"):
        for what, stiffness in (("translation", "translational_stiffness"),
                                ("rotation", "rotational_stiffness")):
            name = what if kind == "displacement" else stiffness
            scale = 1e6 if kind == "displacement" else 1e-6  # m, rad -> µm, µrad; per µ
            for j, dof in enumerate(_carriage_names(ds, what)):
                values = [float(np.asarray(ds[f"carriage_{name}_{stat}"])[j]) * scale
                          if f"carriage_{name}_{stat}" in ds.variables else np.nan
                          for stat in CARRIAGE_STATISTICS]
                label = CARRIAGE_DOF_LABELS.get(dof, (dof, dof))[kind == "stiffness"]
                rows.append((kind, dof, label, values))
    return rows


def _carriage_geometry(config):
    """(ball_z [m], N_0 [N] or None, Hertz constant K [N/m^1.5] or None) of a parsed
    carriage config; (None, None, None) without one."""
    if config is None or getattr(config, "carriage", None) is None:
        return None, None, None
    b = config.bearing
    k = float(hertz_constants(b.ball_radius, b.conformity, b.youngs_modulus,
                              b.poisson_ratio).load_deflection_constant)
    o = float(config.carriage.preload_oversize)
    f0 = k * max(0.5 * o, 0.0) ** 1.5
    return config.carriage.layout.ball_z, 2.0 * f0 * np.cos(b.nominal_contact_angle), k


def carriage_summary(ds) -> str:
    """One sentence on the carriage of a carriage study (the headline): its load case,
    preload and nominal vertical stiffness."""
    loads = ", ".join(f"{term.split(' (')[0].split(',')[0]} {value:.4g} {unit}"
                      for term, value, unit, _ in carriage_load_items(ds) if value)
    rows = {dof: values for kind, dof, _, values in carriage_dof_rows(ds)
            if kind == "stiffness"}
    stiff = rows.get("u_y", [np.nan])[0]
    failed = integer(ds, "n_assemblies_carriage_failed")
    text = (f"Carriage on {counted(tracks_of(ds), 'track')} under "
            f"{loads or 'no external load'}, preload "
            f"{1e6 * number(ds, 'preload_oversize'):.3g} µm "
            f"({number(ds, 'preload_contact_force'):.3g} "
            f"N per contact); nominal vertical stiffness {significant(stiff)} N/µm")
    if failed:
        text += f"; {failed:,} of {integer(ds, 'n_assemblies'):,} carriages not solved"
    return text + "."


def carriage_content(ds, config=None) -> dict:
    """The "Carriage" section of a carriage study's report (HTML and PDF).

    Parameters
    ----------
    ds : xarray.Dataset
        A result file with a ``track`` dimension (the variables of
        :data:`tolsim.io.schema.carriage.CARRIAGE_VARIABLES`).
    config : StudyConfig, optional
        The embedded config (ball positions, N_0, K, per-ball oversizes); without it the
        section shows what the file holds.

    Returns
    -------
    dict
        ``heading`` (str), ``paragraphs`` (list of str), ``tables`` (list of
        :class:`ReportTable`: load case, preload, tracks, displacement and stiffness, solved
        carriages), ``figure_after`` (index of the table the figure follows), ``ball_z``
        (nominal ball positions [m] or None) and ``preload_ball_load`` (N_0 [N] or None).
    """
    data = config_toml(ds)
    tracks, balls = tracks_of(ds), ds.sizes.get("ball", 0)
    n_asm = integer(ds, "n_assemblies")
    failed = integer(ds, "n_assemblies_carriage_failed")
    ball_z, n0, k = _carriage_geometry(config)
    paragraphs = [
        f"Each assembly is a rigid carriage on {counted(tracks, 'track')} of "
        f"{counted(balls, 'ball')}, one "
        "train per track. The carriage is solved for every sampled assembly with that "
        "assembly's groove errors and ball sizes (tolsim.physics.carriage), and its balls "
        "then go through the velocity model. P(contact) and the time to first contact are "
        f"per assembly: contact in {any_train(tracks)}. The load "
        "distribution is that "
        "of the nominal assembly (no errors); the displacement and stiffness are given for "
        "the nominal assembly and over the sampled ones."]
    tables = []
    # load case
    rows = tuple((term, f"{value:.4g} {unit}", key)
                 for term, value, unit, key in carriage_load_items(ds, data))
    tables.append(ReportTable(
        "Load case at the reference point", ("load (catalogue term)", "value", "config"), rows,
        (0.5, 0.15, 0.35),
        "Reference point: x = y = 0 of the track coordinates, in the middle of the rows "
        "(z = 0); x lateral, y up, z along the rail, moments right-handed about +x, +y, +z "
        "(tolsim.physics.carriage). Every sampled carriage carries the same load.", (1,)))
    # preload
    o, f0 = number(ds, "preload_oversize"), number(ds, "preload_contact_force")
    rows = [("preload class: diametral ball oversize o", f"{1e6 * o:.4g} µm",
             config_key(data, "carriage", "preload_oversize") or "default: 0 (no preload)"),
            ("preload force on each contact, F₀ = K (o/2)^1.5", f"{f0:.4g} N",
             "result file (preload_contact_force)")]
    if n0 is not None:
        beta0 = np.rad2deg(config.bearing.nominal_contact_angle)
        rows.append(("normal ball load of the preload alone, N₀ = 2 F₀ cos β₀",
                     f"{n0:.4g} N", f"derived (β₀ = {beta0:.4g}°)"))
        rows.append(("Hertz constant K of a ball in its flank", f"{k:.4g} N/m^1.5",
                     "tolsim.physics.hertz.hertz_constants (from D, f, E, ν)"))
    if config is not None:
        dev = config.carriage.ball_oversize_deviation
        rows.append(("per-ball oversize deviations from o (nominal assembly)",
                     _span(1e6 * np.asarray(dev), "{:+.3g}") + " µm" if dev else "none",
                     "[carriage] or [[carriage.track]] ball_oversize_deviation_um" if dev
                     else "not given"))
        for t in config.tolerances:
            if t.source == "ball_oversize" and t.distribution.is_random:
                rows.append(("sampled ball size variation (adds to o)",
                             f"{t.distribution.kind}: "
                             + distribution_text(t.distribution, "length"),
                             "[tolerances.ball_oversize]"))
    tables.append(ReportTable(
        "Preload", ("quantity", "value", "source"), tuple(rows), (0.45, 0.2, 0.35),
        "o = 0: no preload (zero clearance), the load closes one diagonal of each ball; with "
        "o > 0 every ball carries F₀ on all four contacts before any load, which stiffens "
        "the carriage and keeps the contacts closed.", (1,)))
    # tracks and the nominal load distribution
    x, y, phi = (np.asarray(ds[n], dtype=float) if n in ds.variables else np.full(tracks, np.nan)
                 for n in ("track_x", "track_y", "track_orientation"))
    ny, nx, rho = (np.atleast_2d(np.asarray(ds[n], dtype=float)) for n in (
        "normal_load", "side_load", "side_force_ratio"))
    first = (np.atleast_2d(np.asarray(ds["contact_pair_count"])).sum(axis=1)
             if "contact_pair_count" in ds.variables else np.zeros(tracks, int))
    rows = tuple((str(t), significant(1e3 * x[t]), significant(1e3 * y[t] + 0.0),
                  significant(np.rad2deg(phi[t])), _span(ny[t]), _span(nx[t], "{:+.4g}"),
                  _span(rho[t], "{:+.3f}"), f"{int(first[t]):,}") for t in range(tracks))
    tables.append(ReportTable(
        "Tracks and the nominal load distribution",
        ("track", "x [mm]", "y [mm]", "orientation φ [°]", "normal load N_y [N]",
         "side load N_x [N]", "ρ = N_x / N_y [-]", "first contacts [assemblies]"), rows,
        (0.07, 0.09, 0.09, 0.12, 0.17, 0.17, 0.14, 0.15),
        "The nominal assembly (no groove errors, the config's ball oversizes), ranges over "
        "the track's balls. N_y presses the ball into its rail groove and N_x is lateral, "
        "both in the module frame of the track (its up is (−sin φ, cos φ) in the carriage "
        f"frame). First contacts: assemblies whose first contact is in this track (of "
        f"{integer(ds, 'n_contact'):,} with contact).", tuple(range(8))))
    # displacement and stiffness
    dofs = carriage_dof_rows(ds)
    rows = tuple((label, *[(_fixed(v) if kind == "displacement" else significant(v))
                           for v in values])
                 for kind, _, label, values in dofs)
    locked = [dof for kind, dof, _, values in dofs
              if kind == "stiffness" and np.all(np.asarray(values) == 0.0)]
    solved = n_asm - (failed or 0)
    tables.append(ReportTable(
        "Carriage displacement and stiffness", ("degree of freedom", *CARRIAGE_STATISTICS),
        rows, (0.35, 0.13, 0.13, 0.13, 0.13, 0.13),
        f"Nominal: the assembly without errors; mean, std, min and max over the {solved:,} "
        f"solved carriages of {n_asm:,}. Displacements are measured from the geometry with "
        "balls of nominal size (o = 0), so they include the shift of the unloaded carriage by "
        "the preload where the tracks do not balance it (a single track, say); the change "
        "under the load is what the stiffness gives. Stiffness: the diagonal of the tangent "
        "stiffness matrix dQ/dq at the equilibrium, each degree of freedom alone (the "
        "couplings are not in the result file)."
        + (f" {', '.join(locked)}: stiffness 0, a degree of freedom the track layout cannot "
           "resist, held at zero (locked, tolsim.physics.carriage)." if locked else ""),
        (1, 2, 3, 4, 5)))
    tables.append(ReportTable(
        "Solved carriages", ("carriages", "count"), (
            ("sampled (assemblies)", f"{n_asm:,}"),
            ("solved: the statistics above are over these", f"{solved:,}"),
            ("not solved (Newton not converged, or lifted off): their balls count as not "
             "converged and their trains as unresolved (see the bounds in section 2)",
             f"{failed:,}" if failed is not None else "n/a")),
        (0.8, 0.2), "", (1,)))
    return dict(heading=section_titles(ds)["carriage"], paragraphs=paragraphs, tables=tables,
                figure_after=2, ball_z=ball_z, preload_ball_load=n0)
