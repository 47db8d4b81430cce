"""What a study assumed, and where each assumption comes from: the report's tolerance and
assumptions tables (HTML and PDF share them).

:func:`tolerance_table` lists every sampled input of the study, the initial gap between the
balls included (``[train] initial_gap``, often the largest driver of contact).
:func:`assumption_table` lists the geometry, loads, gap model, static, velocity and
propagation models, the validity budget of the fast velocity model with its re-solve counts,
the spot checks, the sampling and the spec limits, each with its source: the config key that
set it, a model default (and whether it equals the paper's Table 1 bearing), a model of
tolsim (module and equation), or the result file. For a study with a ``[carriage]`` the
per-ball loads give way to the carriage model (:func:`carriage_assumptions`): the rigid
carriage solved per assembly, the track layout, the per-track groove errors, the nominal ball
positions of the load distribution, the load case, the Hertz constant and the preload. A
study with ``[contact]`` (friction figures in the file) adds the contact model after the
velocity and propagation models (:func:`friction_assumptions`): quasi-static trains, the
ball-to-ball Coulomb friction mu_bb, the creep stiffness and its model, the carriage friction
force of a track, the worst track per assembly and the treatment of sliding balls; and its
limit on the friction increase among the spec limits.

Both read the config text stored in the result file (``config`` attribute) with
:func:`tolsim.io.config.parse_config` and :mod:`tomllib` (to tell a given key from a
default); a config that no longer parses leaves the tables to what the file's attributes and
variables say.
"""

import math
from dataclasses import dataclass

import numpy as np

from tolsim.io.config import CARRIAGE_PROPAGATION
from tolsim.physics.geometry import TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity import analytic
from tolsim.reports.result_view import (
    config_key,
    config_or_none,
    config_toml,
    integer,
    number,
)
from tolsim.reports.verdict import any_train, contact_unit, counted, has_friction, tracks_of
from tolsim.study.spec import SOURCES
from tolsim.study.statistics.intervals import format_fraction

#: The paper.
PAPER = "Lin, Okwudire, Duan & Wou, IMECE2018-88033"

#: Short descriptions of the models, by name.
VELOCITY_MODEL_TEXT = {
    "analytic": "the paper's analytical model: Eqs. (17), (18), (21) solved for the four "
                "Δγ with four distinct forces, ε from Eq. (23) (tolsim.physics.velocity.analytic)",
    "eq24": "the paper's closed form Eq. (24), paired diagonal forces "
            "(tolsim.physics.velocity.analytic.eq24)",
    "full": "the full friction model on every ball: Coulomb friction over the four Hertz "
            "ellipses, equilibrium solved (tolsim.physics.velocity.full.full)",
}
STATIC_MODEL_TEXT = {
    "solved": "elastic, load-controlled: the ball between the two gothic-arch grooves with "
              "every error source, Hertz contacts, Newton per ball (tolsim.physics.static)",
    "rigid": "rigid grooves: geometric contact angles from every error source "
             "(tolsim.physics.static, rigid=True)",
    "paired": "the paper's paired forces (Sec. 3.1) and rigid angles from the rotations and "
              "tangential arc-centre offsets",
    "linearised": "first-order static solution about the error-free state at each load "
                  "(tolsim.physics.static.linearised_static)",
}
#: The static model of every ball of a study with a ``[carriage]`` (the config sets it).
CARRIAGE_STATIC_MODEL_TEXT = (
    "the carriage solve: every ball elastic and displacement-controlled by its carriage "
    "groove (Hertz contacts, every error source), the carriage in equilibrium with the load "
    "(tolsim.physics.carriage.solve_carriage)")
#: Error sources that the ``paired`` static model does not see (first order).
PAIRED_IGNORES = ("arc_centre_offset_normal", "bottom_offset", "top_offset", "ball_oversize")

_SCALE = {"angle": (180 / math.pi, "deg"), "length": (1e6, "µm")}
_FIELDS = {"fixed": ("value",), "normal": ("mean", "std"), "uniform": ("low", "high"),
           "truncated_normal": ("mean", "std", "low", "high"),
           "cpk": ("low", "high", "mean", "cpk")}


@dataclass(frozen=True)
class Assumption:
    """One row of the assumptions table."""

    topic: str
    item: str
    value: str
    source: str


@dataclass(frozen=True)
class ToleranceRow:
    """One sampled input: name, scope, distribution, its parameters and its config key."""

    source: str
    scope: str
    distribution: str
    parameters: str
    key: str


def _source(data, section, name, default_text):
    return config_key(data, section, name) or default_text


def _table1(value, reference, rel=1e-9):
    return math.isclose(value, reference, rel_tol=rel)


# --------------------------------------------------------------------------------------------
# Tolerances
# --------------------------------------------------------------------------------------------
def distribution_text(dist, kind) -> str:
    """Parameters of a :class:`~tolsim.study.spec.Distribution` in display units."""
    factor, unit = _SCALE.get(kind, (1.0, ""))
    if dist.kind == "empirical":
        data = np.asarray(getattr(dist, "data", ()), dtype=float)
        text = f"{data.size} measured values"
        if data.size:
            text += f", {factor * data.min():.3g} to {factor * data.max():.3g} {unit}"
        if getattr(dist, "data_file", ""):
            text += f", from {dist.data_file}"
        return text
    text = ", ".join(f"{f} {getattr(dist, f):.3g}" if f == "cpk" else
                     f"{f} {factor * getattr(dist, f):.3g} {unit}"
                     for f in _FIELDS.get(dist.kind, ()))
    if dist.kind == "cpk":
        text += f" (σ {factor * dist.std:.3g} {unit}" + (
            ", 100 % inspected)" if dist.truncate else ")")
    return text


def _raw_text(table) -> str:
    """``key = value`` pairs of a TOML table as written (units in the key names)."""
    return ", ".join(f"{k} = {v!r}" if isinstance(v, str) else f"{k} = {v}"
                     for k, v in table.items() if k != "distribution")


def raw_tolerance_table(data) -> list:
    """:class:`ToleranceRow` from the TOML as written, for a config this version cannot
    parse (an older file): the values as the config gives them, units in the key names."""
    rows = []
    gap = data.get("train", {}).get("initial_gap")
    if isinstance(gap, dict):
        rows.append(ToleranceRow("initial_gap", "pair", str(gap.get("distribution", "?")),
                                 _raw_text(gap), "[train] initial_gap"))
    for source, table in data.get("tolerances", {}).items():
        if isinstance(table, dict):
            rows.append(ToleranceRow(source, str(table.get("scope", "default")),
                                     str(table.get("distribution", "?")),
                                     _raw_text({k: v for k, v in table.items()
                                                if k != "scope"}),
                                     f"[tolerances.{source}]"))
    return rows


def tolerance_table(config, ds=None) -> list:
    """The sampled inputs of a study as :class:`ToleranceRow`, the initial gap first.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig or None
        None: the rows of :func:`raw_tolerance_table` of the file's config text.
    ds : xarray.Dataset, optional
        The result file (for the config keys as written).
    """
    data = config_toml(ds) if ds is not None else {}
    if config is None:
        return raw_tolerance_table(data)
    gap = config.train.initial_gap
    key = config_key(data, "train", "initial_gap") or "[train] initial_gap"
    if getattr(config, "carriage", None) is not None and "train" not in data:
        key = "default without [train]: the ball pitch − D ([carriage] ball_pitch)"
    rows = [ToleranceRow(
        "initial_gap", "pair", gap.kind,
        distribution_text(gap, "length") + "; per adjacent pair of balls at the start of "
        "the stroke, clipped at 0", key)]
    for t in config.tolerances:
        params = distribution_text(t.distribution, SOURCES.get(t.source, ("length",))[0])
        if t.correlation_length > 0:
            params += f"; correlation length {1e3 * t.correlation_length:.3g} mm"
        rows.append(ToleranceRow(t.source, t.scope, t.distribution.kind, params,
                                 f"[tolerances.{t.source}]"))
    return rows


# --------------------------------------------------------------------------------------------
# Assumptions
# --------------------------------------------------------------------------------------------
def _range(values, fmt="{:.4g}", unit=""):
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]  # rho = N_x / N_y of an unloaded ball is NaN
    if values.size == 0:
        return "n/a"
    lo, hi = float(values.min()) + 0.0, float(values.max()) + 0.0  # + 0.0: no "-0"
    if math.isclose(lo, hi, rel_tol=1e-12, abs_tol=1e-15):
        return fmt.format(lo) + unit
    return f"{fmt.format(lo)} to {fmt.format(hi)}{unit}"


def validity_text(velocity_model) -> str:
    """The validity thresholds of a fast velocity model
    (:mod:`tolsim.physics.velocity.analytic`)."""
    a = analytic
    if velocity_model == "analytic":
        return (f"|c/a| ≤ {a.MAX_ZERO_VELOCITY_RATIO:g}, |Δβ + Δγ| ≤ "
                f"{np.rad2deg(a.MAX_ANGLE_SUM):.3g}°, |ε| ≤ "
                f"{100 * a.MAX_VELOCITY_DEVIATION:.3g} %")
    if velocity_model == "eq24":
        return (f"diagonal force ratio ≥ {a.MIN_DIAGONAL_FORCE_RATIO:g}, |Δβ| ≤ "
                f"{np.rad2deg(a.MAX_ANGLE_DEVIATION):.3g}°, pairing asymmetry ≤ "
                f"{a.MAX_PAIRING_ASYMMETRY:g}, |ε| ≤ {100 * a.MAX_EQ24_VELOCITY_DEVIATION:.3g} %")
    return "none: every ball is solved with the full model"


def _track_text(ds, config) -> str:
    """'track 0: x -20 mm, y 0 mm, φ +90°; ...' from the file, or else the config."""
    if "track_x" in ds.variables:
        x, y, phi = (np.asarray(ds[n], dtype=float) for n in (
            "track_x", "track_y", "track_orientation"))
    elif config is not None and config.has_carriage:
        layout = config.carriage.layout
        x, y, phi = layout.track_x, layout.track_y, layout.track_orientation
    else:
        return "n/a"
    return "; ".join(f"track {t}: x {1e3 * x[t]:+.4g} mm, y {1e3 * y[t] + 0.0:.4g} mm, "
                     f"φ {np.rad2deg(phi[t]):+.4g}°" for t in range(len(x)))


#: The carriage load components of a result file (``carriage_force_component_name``,
#: ``carriage_moment_component_name``) in
#: catalogue terms: name -> (term, sign applied to the file's value, unit).
CARRIAGE_LOAD_TERMS = {
    "vertical_force_upward": ("radial load, downward (pressing the carriage onto the rail; "
                              "negative: reverse radial load)", -1.0, "N"),
    "lateral_force": ("lateral load (+x)", 1.0, "N"),
    "pitch_moment": ("pitching moment (about the lateral axis x)", 1.0, "N m"),
    "yaw_moment": ("yawing moment (about the vertical axis y)", 1.0, "N m"),
    "roll_moment": ("rolling moment (about the rail axis z)", 1.0, "N m"),
}
#: Config key (in ``[carriage.load]``) of each load component.
CARRIAGE_LOAD_KEYS = {"vertical_force_upward": "vertical", "lateral_force": "lateral",
                      "pitch_moment": "pitch_moment", "yaw_moment": "yaw_moment",
                      "roll_moment": "roll_moment"}


def carriage_load_items(ds, data=None) -> list:
    """The load case of a carriage study in catalogue terms, radial load first.

    Parameters
    ----------
    ds : xarray.Dataset
        A result file with ``carriage_load_force`` [N] and ``carriage_load_moment`` [N m]
        (names in ``carriage_force_component_name`` and ``carriage_moment_component_name``).
    data : dict, optional
        The config as parsed TOML (for the key that set each value).

    Returns
    -------
    list of (term, value [N or N m], unit, config key)
        The value with the catalogue sign: the radial load positive downward.
    """
    values, names = [], []
    for var, label in (("carriage_load_force", "carriage_force_component_name"),
                       ("carriage_load_moment", "carriage_moment_component_name")):
        if var in ds.variables and label in ds.variables:
            values += [float(v) for v in np.asarray(ds[var], dtype=float)]
            names += [str(n) for n in np.asarray(ds[label])]
    if not names:
        return []
    by_name = dict(zip(names, values, strict=False))
    out = []
    for name, (term, sign, unit) in CARRIAGE_LOAD_TERMS.items():
        if name in by_name:
            key = config_key(data or {}, "carriage.load", CARRIAGE_LOAD_KEYS[name])
            out.append((term, sign * float(by_name[name]) + 0.0, unit,
                        key or "default: 0"))
    return out


def carriage_assumptions(ds, config, data) -> list:
    """The assumptions of the carriage model of a study with ``[carriage]``, as
    :class:`Assumption` rows (topic "carriage"): they replace the per-ball loads of a study
    of single trains.

    Parameters
    ----------
    ds : xarray.Dataset
        The result file (track layout, preload, load case, nominal loads, counts).
    config : StudyConfig or None
        The embedded config; None when it does not parse (the rows then come from the file).
    data : dict
        The config as parsed TOML (the keys that set the values).
    """
    rows = []

    def add(item, value, source):
        rows.append(Assumption("carriage", item, str(value), source))

    tracks = tracks_of(ds)
    carriage = config.carriage if config is not None else None
    balls = ds.sizes.get("ball", "?")
    add("model", f"rigid carriage with five degrees of freedom (u_x, u_y, pitch, yaw, roll) on "
        f"{counted(tracks, 'track')} of {counted(balls, 'ball')}; every ball in equilibrium "
        "between its rail and carriage gothic-arch grooves, the carriage in equilibrium with "
        "the load (Newton with the analytic tangent stiffness); solved for every sampled "
        "assembly with its own groove errors and ball sizes, whose balls then go through the "
        "velocity model",
        "[carriage]; tolsim.physics.carriage.solve_carriage, "
        "tolsim.study.pipeline.carriage.evaluate_carriage")
    add("tracks (x, y, orientation φ)", _track_text(ds, config),
        "[[carriage.track]] x_mm, y_mm, orientation_deg; module up = (−sin φ, cos φ)")
    if carriage is not None:
        pitch = carriage.layout.ball_pitch
        add("ball positions of the load distribution",
            f"nominal, from the pitch: ball j at z_j = (j − (n − 1)/2) × {1e3 * pitch:.4g} mm "
            "(ball 0 trailing), the same in every assembly; the sampled initial gaps set "
            "when neighbouring balls touch but do not move the balls in the load distribution",
            config_key(data, "carriage", "ball_pitch") + "; tolsim.physics.carriage.CarriageLayout")
    loads = carriage_load_items(ds, data)
    if loads:
        add("load case at the reference point",
            "; ".join(f"{term.split(' (')[0]} {value:.4g} {unit}"
                      for term, value, unit, _ in loads)
            + "; the same for every assembly (reference point: x = y = 0, z = 0 in the "
              "middle of the rows)",
            "; ".join(sorted({k for *_, k in loads if not k.startswith("default")}))
            or "default: no load")
    add("ball loads N_x, N_y",
        "from the carriage equilibrium of each assembly; the result file's normal_load, "
        "side_load and side_force_ratio are those of the nominal assembly (no errors): N_y "
        + _range(np.asarray(ds["normal_load"]), unit=" N") + ", N_x "
        + _range(np.asarray(ds["side_load"]), fmt="{:+.4g}", unit=" N") + ", ρ "
        + _range(np.asarray(ds["side_force_ratio"]), fmt="{:+.3g}")
        if "normal_load" in ds.variables else "from the carriage equilibrium of each assembly",
        "result file (normal_load, side_load, side_force_ratio: nominal assembly)")
    add("groove errors per track",
        "each track has its own rail and carriage grooves: a 'rail' or 'carriage' tolerance "
        "is drawn once per track and assembly (a rail field: one field per track), a 'ball' "
        "tolerance per ball, the gaps per pair of each track",
        "tolsim.study.sampling (tolsim issue 12)")
    if config is not None:
        b = config.bearing
        k = float(hertz_constants(b.ball_radius, b.conformity, b.youngs_modulus,
                                  b.poisson_ratio).load_deflection_constant)
        add("Hertz contact", f"F = K δ^1.5 on each flank, K = {k:.4g} N/m^1.5 (the ball in "
            "its gothic-arch flank, from D, f, E and ν above)",
            "tolsim.physics.hertz.hertz_constants; Johnson, Contact Mechanics, 1985, Sec. 4.2")
    oversize, force = number(ds, "preload_oversize"), number(ds, "preload_contact_force")
    if carriage is not None:
        oversize = carriage.preload_oversize
    text = (f"diametral ball oversize o = {1e6 * oversize:.4g} µm on every ball: "
            f"F₀ = K (o/2)^1.5 = {force:.4g} N on each of its four contacts with no load")
    if carriage is not None and carriage.ball_oversize_deviation:
        text += ("; per-ball deviations from o: " + _range(
            1e6 * np.asarray(carriage.ball_oversize_deviation), fmt="{:+.3g}", unit=" µm"))
    if config is not None and any(t.source == "ball_oversize" and t.distribution.is_random
                                  for t in config.tolerances):
        text += "; the sampled ball_oversize adds to it (see the sampled inputs)"
    add("preload", text, config_key(data, "carriage", "preload_oversize")
        or "default: no preload (o = 0)")
    failed, n = integer(ds, "n_assemblies_carriage_failed", None), integer(ds, "n_assemblies", None)
    add("carriages not solved",
        "a carriage whose Newton does not converge or that lifts off is kept: its balls "
        "count as not converged and its trains as unresolved (bounded in P(contact))"
        + (f"; {failed:,} of {n or 0:,} here" if failed is not None else ""),
        "result file (n_assemblies_carriage_failed); "
        "tolsim.study.pipeline.carriage.evaluate_carriage")
    add("contact per assembly",
        f"an assembly is a carriage with {counted(tracks, 'train')} (one per track), each "
        "running on its own; P(contact) and the time to first contact are per assembly: contact in "
        f"{any_train(tracks)}, the first contact the earliest of its trains'",
        "tolsim.study.pipeline.propagation.first_contact_tracks")
    return rows


def friction_assumptions(ds, config, data) -> list:
    """The contact model of a study with ``[contact]`` (what happens after balls touch,
    :mod:`tolsim.physics.trains` and :mod:`tolsim.study.pipeline.track_friction`), as
    :class:`Assumption`
    rows (topic "after contact").

    Parameters
    ----------
    ds : xarray.Dataset
        The result file (mu_bb, the creep model, the resolved and sliding counts).
    config : StudyConfig or None
        The embedded config (the bearing of the nominal coupling factor); None when it does
        not parse.
    data : dict
        The config as parsed TOML (the keys that set the values).
    """
    rows = []

    def add(item, value, source):
        rows.append(Assumption("after contact", item, str(value), source))

    tracks = tracks_of(ds)
    mu_bb = number(ds, "ball_friction_coefficient")
    model = str(ds.attrs.get("contact_creep_model", "analytic"))
    along = ds.attrs.get("propagation") == "along_track"
    solved = ("with along_track the same rule at every time step, with each ball's ε and K "
              "at its position (a gap closing within a step is projected onto no overlap; "
              "the figures carry an O(dt) error), contacts ending where the ε change "
              "separates the balls" + ("; balls enter and leave the carriage's loaded zone "
                                       "and join or leave its train"
                                       if tracks else "") if along else
              "with constant ε solved event-driven and exact, no time step")
    ends = ("" if along and tracks else
            ", and no ball enters or leaves the loaded zone during the stroke")
    add("trains of balls after contact (quasi-static)",
        "balls that touch move together as a cluster at the K-weighted mean of their ε, "
        "and the ball-to-ball forces follow from the cluster's balance (a cluster splits "
        f"only where a force would turn negative); {solved}. No inertia (time constant "
        "m / (2K/v) ≈ 6e-7 s for the paper's ball at 0.2 m/s, against a stroke of 0.5 s and "
        "more), no bounce (damping ratio ≈ 12); the balls beyond the ends of the loaded zone "
        f"carry no force{ends}",
        "tolsim.physics.trains (module docstring: quasi-static assumption, ends of the loaded "
        "zone, varying epsilon)")
    add("ball-to-ball friction μ_bb",
        (f"{mu_bb:.4g}: Coulomb friction at each ball-to-ball contact (both balls spin the "
         "same way, so their surfaces slide there); it brakes both balls of a pair, and "
         "the grooves pay for that couple" if np.isfinite(mu_bb) else "n/a"),
        config_key(data, "contact", "ball_friction_coefficient")
        or "default: 0.1 (steel on steel, boundary lubrication)")
    beta = (config.bearing.nominal_contact_angle if config is not None
            else TABLE1.nominal_contact_angle)
    if config is not None and config.has_contact:
        model = config.contact.creep_model
    creep_text = {
        "analytic": "the loaded analytic model (Eqs. 17, 18, 21 with the push and the "
                    "braking moment) at each ball's own loaded contact state, for every ball "
                    "(also those whose ε came from the full model; the analytic K is "
                    "2.6-5.7 % below the full model's on the paper's ball)",
        "full": "the full friction model at zero load at each ball's own loaded contact "
                "state (the carriage-force slopes from the analytic model)",
    }.get(model, model)
    add("creep stiffness K = dP/dε and carriage-force slopes",
        f"{model}: {creep_text}; a ball rolls at ε_i + P_i / K_i (+ the braking by its "
        "neighbours' forces), linear in the loads",
        (config_key(data, "contact", "creep_model") or "default: analytic")
        + " (tolsim.physics.velocity.ball_loads, tolsim.physics.velocity.analytic)")
    add("carriage friction force of a track",
        "F = Σ F₀,i + Σ_j k_j Q_j over the balls i and the touching pairs j: F₀ the "
        "free-rolling drag of each ball (spin and differential slip, the baseline), Q_j the "
        f"ball-to-ball forces, k_j ≈ μ_bb / cos β₀ = {mu_bb / np.cos(beta):.3g} for the "
        "nominal ball (the push itself costs nothing on net); the increase is that of the "
        "track's largest friction force over its baseline",
        "tolsim.study.pipeline.track_friction, Eq. (1)")
    if tracks:
        add("worst track per assembly",
            f"each of the {counted(tracks, 'track')} is followed on its own; an assembly's "
            "friction figures (baseline, increase, ripple, largest force, contact fraction) "
            "all belong to its track with the largest increase",
            "tolsim.study.pipeline.track_friction (one row per assembly: the worst track)")
    else:
        add("worst track per assembly", "one train per assembly: the assembly is its train",
            "tolsim.study.pipeline.track_friction (one row per assembly: the worst track)")
    sliding = integer(ds, "n_assemblies_sliding", None)
    released = integer(ds, "n_assemblies_released", None)
    unresolved = integer(ds, "n_assemblies_friction_unresolved", None)
    add("sliding balls",
        "where a push reaches a ball's traction capacity, or its neighbours' forces stall its "
        "rotation, the linear creep law ends: the train is unresolved from the onset of "
        "sliding (never capped or dropped); its increase before the onset counts as a "
        "certain exceedance when above the limit, the rest is bounded in P(exceedance); so "
        "is a train with a ball pushed past the release push of its stuck contact (it leaves "
        "its stick line, whose K no longer holds)"
        + (f"; {sliding:,} {contact_unit(ds)[1]} with a sliding ball"
           + (f", {released:,} with a ball pushed off its stick line" if released is not None
              else "")
           + f" and {unresolved:,} unresolved without a certain exceedance here"
           if sliding is not None else ""),
        "tolsim.study.pipeline.track_friction (unresolved and sliding trains); result file "
        "(n_assemblies_sliding, n_assemblies_released, n_assemblies_friction_unresolved)")
    return rows


def assumption_table(ds, config=None) -> list:
    """The assumptions behind a result file, as :class:`Assumption` rows.

    Parameters
    ----------
    ds : xarray.Dataset
        A result file of ``tolsim run`` (:func:`tolsim.reports.result_view.read_result_file`).
    config : StudyConfig, optional
        The embedded config (parsed from ``ds.attrs["config"]`` when not given).
    """
    config = config if config is not None else config_or_none(ds)
    data = config_toml(ds)
    a = ds.attrs
    rows = []

    def add(topic, item, value, source):
        rows.append(Assumption(topic, item, str(value), source))

    default = "model default"
    if config is not None:
        b = config.bearing
        for item, name, value, reference, text in (
                ("ball diameter D", "ball_diameter", 2 * b.ball_radius,
                 2 * TABLE1.ball_radius, f"{2e3 * b.ball_radius:.4g} mm"),
                ("groove conformity f = R_G / D", "conformity", b.conformity,
                 TABLE1.conformity, f"{b.conformity:.4g}"),
                ("nominal contact angle β₀", "nominal_contact_angle",
                 b.nominal_contact_angle, TABLE1.nominal_contact_angle,
                 f"{np.rad2deg(b.nominal_contact_angle):.4g}°"),
                ("Young's modulus E", "youngs_modulus", b.youngs_modulus,
                 TABLE1.youngs_modulus, f"{b.youngs_modulus / 1e9:.4g} GPa"),
                ("Poisson's ratio ν", "poisson_ratio", b.poisson_ratio, TABLE1.poisson_ratio,
                 f"{b.poisson_ratio:.4g}"),
                ("friction coefficient μ", "friction_coefficient", b.friction_coefficient,
                 TABLE1.friction_coefficient, f"{b.friction_coefficient:.4g}")):
            same = _table1(value, reference)
            key = config_key(data, "bearing", name)
            where = (key + ("; as the paper's Table 1 bearing" if same else "; differs "
                            "from the paper's Table 1 bearing")) if key else (
                f"{default} (the paper's Table 1 bearing)")
            add("geometry", item, text, where)
        m = config.motion
        add("motion", "carriage speed v", f"{1e3 * m.groove_velocity:.4g} mm/s",
            _source(data, "motion", "groove_velocity", "config"))
        add("motion", "stroke (horizon)", f"{1e3 * m.stroke:.4g} mm in {m.duration:.4g} s",
            config_key(data, "motion", "stroke") or config_key(data, "motion", "duration")
            or "config")
        tr = config.train
        no_train = config.has_carriage and "train" not in data
        add("train", "balls per track (loaded zone)", tr.balls,
            config_key(data, "carriage", "balls_per_track") if no_train
            else _source(data, "train", "balls", "config"))
        add("train", "loaded zone length", f"{1e3 * tr.loaded_zone_length:.4g} mm",
            config_key(data, "train", "loaded_zone_length")
            or ("default without [train]: balls × ball pitch" if no_train
                else "default: balls × (D + mean initial gap)"))
        lo = config.loads
        if config.has_carriage:
            for row in carriage_assumptions(ds, config, data):
                rows.append(row)
        if lo is not None:
            add("loads", "normal load N_y per ball", _range(lo.normal_load, unit=" N"),
                _source(data, "loads", "normal_load", "config"))
            side = _range(lo.side_load, fmt="{:+.4g}", unit=" N")
            if lo.yaw_moment:
                side += (f" (yaw moment {lo.yaw_moment:.4g} N m shared linearly over the nominal "
                         "ball slots: N_x,j = M z_j / Σ z², rigid carriage)")
            add("loads", "side load N_x per ball", side,
                " and ".join(k for k in (config_key(data, "loads", "side_load"),
                                         config_key(data, "loads", "side_force_ratio"),
                                         config_key(data, "loads", "yaw_moment")) if k)
                or "default: no side load")
            add("loads", "side force ratio ρ = N_x / N_y", _range(lo.side_force_ratio,
                                                                   fmt="{:+.3g}"),
                "from the two rows above")
        gap = tr.initial_gap
        gap_text = (f"{gap.kind}: {distribution_text(gap, 'length')}; independent per pair, "
                    "clipped at 0; balls start at pitch D + gap, the train centred on the "
                    "carriage")
        gap_key = config_key(data, "train", "initial_gap") or "[train] initial_gap"
        if config.has_carriage:
            gap_text += "; one train per track, the gaps of each track drawn on their own"
            if "train" not in data:
                gap_key = "default without [train]: the ball pitch − D ([carriage] ball_pitch)"
        add("gap model", "initial gap between adjacent balls", gap_text, gap_key)
        groups = getattr(config, "correlations", ())
        add("tolerances", "dependence between the error sources",
            "; ".join(f"{', '.join(g.sources)} correlated (Gaussian copula, matrix "
                      f"{[list(r) for r in g.matrix]})" for g in groups)
            or "all independent", "[[correlation]]" if groups else "default: independent")
    else:
        add("config", "embedded config", "cannot be parsed by this tolsim version: the "
            "values below are the config's keys as written", "the file's config attribute")
        for section in ("bearing", "motion", "train"):
            table = data.get(section, {})
            if isinstance(table, dict) and table:
                add({"bearing": "geometry"}.get(section, section), f"[{section}]",
                    _raw_text({k: v for k, v in table.items() if not isinstance(v, dict)}),
                    "config as written")
        for name, item, unit in (("normal_load", "normal load N_y per ball", " N"),
                                 ("side_load", "side load N_x per ball", " N"),
                                 ("side_force_ratio", "side force ratio ρ = N_x / N_y", "")):
            if name in ds.variables and not tracks_of(ds):  # a carriage's: its rows below
                add("loads", item, _range(np.asarray(ds[name]), unit=unit),
                    f"result file ({name})")
        gap = data.get("train", {}).get("initial_gap")
        if isinstance(gap, dict):
            add("gap model", "initial gap between adjacent balls", _raw_text(gap)
                + f" ({gap.get('distribution', '?')})", "[train] initial_gap")
        if tracks_of(ds):
            rows.extend(carriage_assumptions(ds, None, data))

    sm = str(a.get("static_model", "?"))
    if tracks_of(ds):
        add("models", f"static contact: {sm}", CARRIAGE_STATIC_MODEL_TEXT,
            "set by [carriage]: a study with a carriage solves its balls with the carriage "
            "(tolsim.io.config)")
    else:
        add("models", f"static contact: {sm}", STATIC_MODEL_TEXT.get(sm, sm),
            _source(data, "study", "static_model", f"{default} (paired)"))
    if config is not None and sm == "paired":
        ignored = [t.source for t in config.tolerances
                   if t.source.startswith(PAIRED_IGNORES) and t.distribution.is_random]
        if ignored:
            add("models", "error sources the static model ignores", ", ".join(ignored),
                "the paired model maps only rotations and tangential arc-centre offsets "
                "(tolsim.study.pipeline.evaluate)")
    vm = str(a.get("velocity_model", "?"))
    add("models", f"ball velocity: {vm}", VELOCITY_MODEL_TEXT.get(vm, vm),
        _source(data, "study", "velocity_model", f"{default} (analytic)") + f"; {PAPER}")
    pm = str(a.get("propagation", "?"))
    # a [carriage] study follows its balls along the track unless the config says constant
    # (issue 24), a study of free balls keeps them constant
    carriage_default = config is not None and config.has_carriage
    add("models", f"propagation: {pm}", a.get("propagation_assumption", pm),
        _source(data, "study", "propagation",
                f"{default} of a [carriage] study ({CARRIAGE_PROPAGATION})" if carriage_default
                else f"{default} (constant)")
        + " (tolsim.study.pipeline.propagation)")
    if a.get("propagation_caveat"):
        add("models", "caveat of the propagation", a["propagation_caveat"],
            "tolsim.study.pipeline.propagation_rules.propagation_caveat")
    if has_friction(ds):
        rows.extend(friction_assumptions(ds, config, data))

    budget = analytic.VALIDITY_ERROR_BUDGET
    add("validity budget", "error budget of the fast model",
        f"|ε_{vm} − ε_full| ≤ {100 * budget:.2g} percentage points "
        f"(VALIDITY_ERROR_BUDGET = {budget:g})", "tolsim.physics.velocity.analytic")
    table1 = config is None or all(_table1(getattr(config.bearing, f), getattr(TABLE1, f))
                                   for f in ("ball_radius", "conformity",
                                             "nominal_contact_angle"))
    add("validity budget", f"validity thresholds of {vm}", validity_text(vm),
        "derived by benchmarks/validity_budget.py against the full model on a grid of the "
        "paper's Table 1 bearing (218 478 contact states, 20 000 fresh balls)"
        + ("" if table1 else "; this bearing differs from Table 1, so the budget is not "
           "proven for it: see the spot checks"))
    outside, redone = (integer(ds, "n_balls_outside_validity", None),
                       integer(ds, "n_balls_resolved_full", None))
    failed, n = integer(ds, "n_balls_full_failed", None) or 0, integer(ds, "n_balls", None) or 0
    if outside is not None:
        redone = "?" if redone is None else f"{redone:,}"  # older files lack the counts
        add("validity budget", "balls sent to the full model (outside the thresholds, or "
            "an open contact)",
            f"{outside:,} of {n:,} balls; {redone} solved, {failed:,} that the full "
            f"model could not solve (in {float(a.get('full_model_resolve_seconds', 0)):.2f} s)",
            "result file (n_balls_outside_validity, n_balls_resolved_full, "
            "n_balls_full_failed)")
    k = ds.sizes.get("spot_check", 0)
    strata = np.asarray(ds["spot_check_stratum"]) if "spot_check_stratum" in ds else None
    text = f"{k} balls re-solved with the full model and compared"
    if strata is not None and k:
        near = int(np.count_nonzero(strata == 1))
        text += f" ({k - near} drawn uniformly, {near} near the spec limit)"
    add("validity budget", "spot checks", text,
        _source(data, "study", "spot_checks", f"{default} (0)"))

    add("sampling", "assemblies, seed, block size",
        f"{integer(ds, 'n_assemblies', None) or 0:,} assemblies, seed {a.get('seed', '?')}, "
        f"blocks of {a.get('block_size', '?')}",
        "; ".join(k for k in (config_key(data, "study", "samples"),
                              config_key(data, "study", "seed"),
                              config_key(data, "study", "block_size")) if k)
        + " (--samples and --seed on the command line override them: see history)")
    add("sampling", "sampling of the per-assembly factors", a.get("sampling", "?"),
        _source(data, "study", "sampling", f"{default} (random)"))

    eps_limit, p_limit = (number(ds, "velocity_deviation_limit"),
                          number(ds, "contact_probability_limit"))
    add("spec limits", "limit on |ε| per ball",
        f"{100 * eps_limit:.4g} %" if np.isfinite(eps_limit) else "no spec limit given",
        _source(data, "study", "velocity_deviation_limit", "not set"))
    add("spec limits", f"limit on P(contact) per {contact_unit(ds)[0]}",
        format_fraction(p_limit) if np.isfinite(p_limit) else "no spec limit given",
        _source(data, "study", "contact_probability_limit", "not set"))
    oos, cpk_min = (number(ds, "velocity_deviation_out_of_spec_limit"),
                    number(ds, "velocity_deviation_cpk_minimum"))
    add("spec limits", "allowed fraction of balls beyond the limit on |ε|",
        format_fraction(oos) if np.isfinite(oos) else "no spec limit given",
        _source(data, "study", "out_of_spec_limit", "not set"))
    add("spec limits", "required minimum Cpk of ε",
        f"{cpk_min:.3g}" if np.isfinite(cpk_min) else "no spec limit given",
        _source(data, "study", "cpk_minimum", "not set"))
    if has_friction(ds):
        limit = number(ds, "friction_increase_limit")
        add("spec limits", f"limit on the friction increase per {contact_unit(ds)[0]}",
            f"{limit:.4g} N (allowed fraction beyond it: none in the config)"
            if np.isfinite(limit) and limit > 0 else "no spec limit given",
            _source(data, "contact", "friction_increase_limit", "not set"))
    return rows
