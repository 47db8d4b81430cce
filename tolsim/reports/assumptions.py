"""What a study assumed, and where each assumption comes from: the report's tolerance and
assumptions tables (HTML and PDF share them).

:func:`tolerance_table` lists every sampled input of the study, the initial gap between the
balls included (``[train] initial_gap``, often the largest driver of contact).
:func:`assumption_table` lists the geometry, loads, gap model, static, velocity and
propagation models, the validity budget of the fast velocity model with its re-solve counts,
the spot checks, the sampling and the spec limits, each with its source: the config key that
set it, a model default (and whether it equals the paper's Table 1 bearing), a model of
tolsim (module and equation), or the result file.

Both read the config text stored in the result file (``config`` attribute) with
:func:`tolsim.io.config.parse_config` and :mod:`tomllib` (to tell a given key from a
default); a config that no longer parses leaves the tables to what the file's attributes and
variables say.
"""

import math
import tomllib
from dataclasses import dataclass

import numpy as np

from tolsim.physics import analytic
from tolsim.physics.geometry import TABLE1
from tolsim.study.estimators import format_fraction

#: The paper.
PAPER = "Lin, Okwudire, Duan & Wou, IMECE2018-88033"

#: Short descriptions of the models, by name.
VELOCITY_MODEL_TEXT = {
    "analytic": "the paper's analytical model: Eqs. (17), (18), (21) solved for the four "
                "Δγ with four distinct forces, ε from Eq. (23) (tolsim.physics.analytic)",
    "eq24": "the paper's closed form Eq. (24), paired diagonal forces "
            "(tolsim.physics.analytic.eq24)",
    "full": "the full friction model on every ball: Coulomb friction over the four Hertz "
            "ellipses, equilibrium solved (tolsim.physics.friction.full)",
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


# --------------------------------------------------------------------------------------------
# Reading the config
# --------------------------------------------------------------------------------------------
def config_of(ds):
    """The :class:`~tolsim.study.spec.StudyConfig` embedded in a result (seed of the file)."""
    from tolsim.io.config import parse_config

    name = ds.attrs.get("title", "result").split(": ", 1)[-1]
    config = parse_config(str(ds.attrs["config"]), name)
    return config.with_overrides(seed=int(ds.attrs["seed"]))


def _config_or_none(ds):
    try:
        return config_of(ds)
    except Exception:  # noqa: BLE001 - the report must not fail on an old or foreign config
        return None


def _toml(ds) -> dict:
    try:
        return tomllib.loads(str(ds.attrs.get("config", "")))
    except tomllib.TOMLDecodeError:
        return {}


def _key(data, section, name):
    """``[section] key`` of the config key for quantity ``name`` (any unit suffix), or ''."""
    table = data
    for part in section.split("."):
        table = table.get(part, {}) if isinstance(table, dict) else {}
    if not isinstance(table, dict):
        return ""
    for key in table:
        if key == name or key.startswith(f"{name}_"):
            value = table[key]
            shown = value if not isinstance(value, dict | list) else None
            return f"[{section}] {key}" + (f" = {shown}" if shown is not None else "")
    return ""


def _source(data, section, name, default_text):
    return _key(data, section, name) or default_text


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
    from tolsim.study.spec import SOURCES

    data = _toml(ds) if ds is not None else {}
    if config is None:
        return raw_tolerance_table(data)
    gap = config.train.initial_gap
    rows = [ToleranceRow(
        "initial_gap", "pair", gap.kind,
        distribution_text(gap, "length") + "; per adjacent pair of balls at the start of "
        "the stroke, clipped at 0", _key(data, "train", "initial_gap") or "[train] "
                                     "initial_gap")]
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
    if values.size == 0:
        return "n/a"
    lo, hi = float(values.min()), float(values.max())
    if math.isclose(lo, hi, rel_tol=1e-12, abs_tol=1e-15):
        return fmt.format(lo) + unit
    return f"{fmt.format(lo)} to {fmt.format(hi)}{unit}"


def _i(ds, name):
    return int(np.asarray(ds[name])) if name in ds.variables else None


def _f(ds, name):
    return float(np.asarray(ds[name])) if name in ds.variables else float("nan")


def validity_text(velocity_model) -> str:
    """The validity thresholds of a fast velocity model (:mod:`tolsim.physics.analytic`)."""
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


def assumption_table(ds, config=None) -> list:
    """The assumptions behind a result file, as :class:`Assumption` rows.

    Parameters
    ----------
    ds : xarray.Dataset
        A result file of ``tolsim run`` (:func:`tolsim.reports.study.read_result_file`).
    config : StudyConfig, optional
        The embedded config (parsed from ``ds.attrs["config"]`` when not given).
    """
    config = config if config is not None else _config_or_none(ds)
    data = _toml(ds)
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
            key = _key(data, "bearing", name)
            where = (key + ("; as the paper's Table 1 bearing" if same else "; differs "
                            "from the paper's Table 1 bearing")) if key else (
                f"{default} (the paper's Table 1 bearing)")
            add("geometry", item, text, where)
        m = config.motion
        add("motion", "carriage speed v", f"{1e3 * m.groove_velocity:.4g} mm/s",
            _source(data, "motion", "groove_velocity", "config"))
        add("motion", "stroke (horizon)", f"{1e3 * m.stroke:.4g} mm in {m.duration:.4g} s",
            _key(data, "motion", "stroke") or _key(data, "motion", "duration") or "config")
        tr = config.train
        add("train", "balls per track (loaded zone)", tr.balls,
            _source(data, "train", "balls", "config"))
        add("train", "loaded zone length", f"{1e3 * tr.loaded_zone_length:.4g} mm",
            _key(data, "train", "loaded_zone_length")
            or "default: balls × (D + mean initial gap)")
        lo = config.loads
        add("loads", "normal load N_y per ball", _range(lo.normal_load, unit=" N"),
            _source(data, "loads", "normal_load", "config"))
        side = _range(lo.side_load, fmt="{:+.4g}", unit=" N")
        if lo.yaw_moment:
            side += (f" (yaw moment {lo.yaw_moment:.4g} N m shared linearly over the nominal "
                     "ball slots: N_x,j = M z_j / Σ z², rigid carriage)")
        add("loads", "side load N_x per ball", side,
            " and ".join(k for k in (_key(data, "loads", "side_load"),
                                     _key(data, "loads", "side_force_ratio"),
                                     _key(data, "loads", "yaw_moment")) if k)
            or "default: no side load")
        add("loads", "side force ratio ρ = N_x / N_y", _range(lo.side_force_ratio,
                                                               fmt="{:+.3g}"),
            "from the two rows above")
        gap = tr.initial_gap
        add("gap model", "initial gap between adjacent balls",
            f"{gap.kind}: {distribution_text(gap, 'length')}; independent per pair, clipped "
            "at 0; balls start at pitch D + gap, the train centred on the carriage",
            _key(data, "train", "initial_gap") or "[train] initial_gap")
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
            if name in ds.variables:
                add("loads", item, _range(np.asarray(ds[name]), unit=unit),
                    f"result file ({name})")
        gap = data.get("train", {}).get("initial_gap")
        if isinstance(gap, dict):
            add("gap model", "initial gap between adjacent balls", _raw_text(gap)
                + f" ({gap.get('distribution', '?')})", "[train] initial_gap")

    sm = str(a.get("static_model", "?"))
    add("models", f"static contact: {sm}", STATIC_MODEL_TEXT.get(sm, sm),
        _source(data, "study", "static_model", f"{default} (paired)"))
    if config is not None and sm == "paired":
        ignored = [t.source for t in config.tolerances
                   if t.source.startswith(PAIRED_IGNORES) and t.distribution.is_random]
        if ignored:
            add("models", "error sources the static model ignores", ", ".join(ignored),
                "the paired model maps only rotations and tangential arc-centre offsets "
                "(tolsim.study.evaluate)")
    vm = str(a.get("velocity_model", "?"))
    add("models", f"ball velocity: {vm}", VELOCITY_MODEL_TEXT.get(vm, vm),
        _source(data, "study", "velocity_model", f"{default} (analytic)") + f"; {PAPER}")
    pm = str(a.get("propagation", "?"))
    add("models", f"propagation: {pm}", a.get("propagation_assumption", pm),
        _source(data, "study", "propagation", f"{default} (constant)")
        + " (tolsim.study.propagation)")
    if a.get("propagation_caveat"):
        add("models", "caveat of the propagation", a["propagation_caveat"],
            "tolsim.study.propagation.propagation_caveat")

    budget = analytic.VALIDITY_ERROR_BUDGET
    add("validity budget", "error budget of the fast model",
        f"|ε_{vm} − ε_full| ≤ {100 * budget:.2g} percentage points "
        f"(VALIDITY_ERROR_BUDGET = {budget:g})", "tolsim.physics.analytic")
    table1 = config is None or all(_table1(getattr(config.bearing, f), getattr(TABLE1, f))
                                   for f in ("ball_radius", "conformity",
                                             "nominal_contact_angle"))
    add("validity budget", f"validity thresholds of {vm}", validity_text(vm),
        "derived by benchmarks/validity_budget.py against the full model on a grid of the "
        "paper's Table 1 bearing (218 478 contact states, 20 000 fresh balls)"
        + ("" if table1 else "; this bearing differs from Table 1, so the budget is not "
           "proven for it: see the spot checks"))
    outside, redone = _i(ds, "n_balls_outside_validity"), _i(ds, "n_balls_resolved_full")
    failed, n = _i(ds, "n_balls_full_failed") or 0, _i(ds, "n_balls") or 0
    if outside is not None:
        redone = "?" if redone is None else f"{redone:,}"  # older files lack the counts
        add("validity budget", "balls outside the thresholds, re-solved with the full model",
            f"{outside:,} of {n:,} balls; {redone} re-solved, {failed:,} that the full "
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
        f"{_i(ds, 'n_assemblies') or 0:,} assemblies, seed {a.get('seed', '?')}, "
        f"blocks of {a.get('block_size', '?')}",
        "; ".join(k for k in (_key(data, "study", "samples"), _key(data, "study", "seed"),
                              _key(data, "study", "block_size")) if k)
        + " (--samples and --seed on the command line override them: see history)")
    add("sampling", "sampling of the per-assembly factors", a.get("sampling", "?"),
        _source(data, "study", "sampling", f"{default} (random)"))

    eps_limit, p_limit = _f(ds, "velocity_deviation_limit"), _f(ds, "contact_probability_limit")
    add("spec limits", "limit on |ε| per ball",
        f"{100 * eps_limit:.4g} %" if np.isfinite(eps_limit) else "no spec limit given",
        _source(data, "study", "velocity_deviation_limit", "not set"))
    add("spec limits", "limit on P(contact) per train",
        format_fraction(p_limit) if np.isfinite(p_limit) else "no spec limit given",
        _source(data, "study", "contact_probability_limit", "not set"))
    oos, cpk_min = (_f(ds, "velocity_deviation_out_of_spec_limit"),
                    _f(ds, "velocity_deviation_cpk_minimum"))
    add("spec limits", "allowed fraction of balls beyond the limit on |ε|",
        format_fraction(oos) if np.isfinite(oos) else "no spec limit given",
        _source(data, "study", "out_of_spec_limit", "not set"))
    add("spec limits", "required minimum Cpk of ε",
        f"{cpk_min:.3g}" if np.isfinite(cpk_min) else "no spec limit given",
        _source(data, "study", "cpk_minimum", "not set"))
    return rows
