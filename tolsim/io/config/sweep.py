"""``[sweep]``: reading a what-if sweep (issue 14).

The section names config keys and their values::

    [sweep]
    mode = "outer"                                        # or "zip"; default "outer"
    "carriage.load.moment_z_N_m" = [0.0, 1.0, 2.0, 4.0]   # a list, in the key's unit
    "tolerances.bottom_rotation.scale" = { start = 0.5, stop = 2.0, num = 4 }
    "motion.groove_velocity" = { start_mm_per_s = 10, stop_mm_per_s = 100, num = 10 }

A key is the dotted path of a key the config sets (quoted, or as dotted keys). Its unit is
the suffix the key carries (``moment_z_N_m``); a ``start``/``stop``/``num`` table (evenly
spaced, ``numpy.linspace``) may give it instead on ``start_<unit>`` and ``stop_<unit>``,
with the key named without it; a unit of the same quantity replaces the config's
(``std_um`` for ``std_mm``). ``tolerances.<source>.scale`` is the tolerance's spread times a
factor (:meth:`tolsim.study.spec.Distribution.scaled`); it may be swept whether or not the
config sets it. Every point is validated when the config is read, like the config itself:

Running the points and writing their one result file is :mod:`tolsim.io.sweep`.
"""

import copy

import numpy as np

from tolsim.io.config.reader import UNITS, ConfigError
from tolsim.study.design.sweep import SWEEP_MODES, ZIP_DIMENSION, Sweep, SweepAxis

#: UDUNITS spelling of the config's unit suffixes (CF ``units`` of a sweep coordinate).
UDUNITS = {"m": "m", "mm": "mm", "um": "um", "rad": "rad", "mrad": "mrad", "deg": "degree",
           "arcmin": "arcminute", "N": "N", "kN": "kN", "N_m": "N m", "N_mm": "N mm",
           "Pa": "Pa", "MPa": "MPa", "GPa": "GPa", "m_per_s": "m s-1", "mm_per_s": "mm s-1",
           "s": "s", "min": "min", "percent": "percent", "ppm": "1e-6", "": "1"}



def _split_unit(name: str, parent: dict):
    """(quantity, unit, kind) of key ``name``: its unit suffix if it carries a known one."""
    suffixes = sorted(((unit, kind) for kind, table in UNITS.items()
                       for unit in table if unit), key=lambda x: len(x[0]), reverse=True)
    for unit, kind in suffixes:  # the longest first: moment_z_N_m is N_m, not m
        if name.endswith(f"_{unit}"):
            return name[: -len(unit) - 1], unit, kind
    return name, "", None


def _flatten(table: dict, prefix: str = ""):
    """(dotted key, spec) of a ``[sweep]`` table: dotted TOML keys come as nested tables; a
    table with ``num`` (or a ``start...`` key) is a spec, as is anything not a table."""
    for key, value in table.items():
        path = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and not ("num" in value or any(
                k.startswith("start") for k in value)):
            yield from _flatten(value, path)
        else:
            yield path, value


def _values(t, key, spec):
    """(values, unit given by the spec or None) of one swept key; one-line errors."""
    if isinstance(spec, list):
        if not spec:
            raise t.error(key, "is an empty list: give at least one value")
        for v in spec:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise t.error(key, f"has the value {v!r}: sweep values must be finite numbers")
        return [float(v) for v in spec], None
    if not isinstance(spec, dict):
        raise t.error(key, f"= {spec!r}: give a list of values or a table "
                           "{ start = .., stop = .., num = .. }")
    starts = [k for k in spec if k.startswith("start")]
    stops = [k for k in spec if k.startswith("stop")]
    unknown = sorted(set(spec) - set(starts) - set(stops) - {"num"})
    if unknown:
        raise t.error(key, f"has the unknown key {unknown[0]!r} (start, stop, num)")
    if len(starts) != 1 or len(stops) != 1 or "num" not in spec:
        raise t.error(key, "needs start, stop and num (with the unit on start and stop: "
                           "start_mm = .., stop_mm = ..)")
    unit = starts[0][len("start"):].lstrip("_")
    if stops[0][len("stop"):].lstrip("_") != unit:
        raise t.error(key, f"has {starts[0]} and {stops[0]}: give both in one unit")
    num = spec["num"]
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise t.error(key, f"num = {num!r} must be a positive integer")
    ends = [spec[starts[0]], spec[stops[0]]]
    for v in ends:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
            raise t.error(key, f"has start/stop {v!r}: they must be finite numbers")
    return [float(v) for v in np.linspace(ends[0], ends[1], num)], (unit or None)


def _resolve(t, key, given_unit, base):
    """(parent table path, key to set, key to remove or None, unit, whole) of a swept key;
    ``whole``: the config gives the key a whole number (``train.balls``, ``carriage.circuit.
    balls``), so its points take whole numbers too."""
    parts = key.split(".")
    parent = base
    for depth, part in enumerate(parts[:-1]):
        if not isinstance(parent, dict) or part not in parent:
            where = ".".join(parts[: depth + 1])
            raise t.error(key, f"is not a key of the config ({where} is not in it)")
        parent = parent[part]
    if not isinstance(parent, dict):
        raise t.error(key, "is not a key of the config")
    name = parts[-1]
    units = UNITS
    if name == "scale" and len(parts) == 3 and parts[0] == "tolerances":
        if given_unit:
            raise t.error(key, f"is a factor: no unit (got start_{given_unit})")
        return parts[:-1], name, None, "", False
    if name in parent:
        value = parent[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            what = type(value).__name__
            what = {"str": "a string", "dict": "a table", "list": "a list"}.get(what, what)
            raise t.error(key, f"is not numeric (the config has {what} there): only "
                               "numeric keys can be swept")
        quantity, unit, kind = _split_unit(name, parent)
        if given_unit:
            raise t.error(key, f"already carries its unit ({unit or 'none'}): write "
                               "start and stop without one")
        return parts[:-1], name, None, unit, isinstance(value, int)
    # the quantity under another unit: the key without its suffix, or with another one
    quantity, unit, kind = _split_unit(name, parent)
    if given_unit is not None and unit:
        raise t.error(key, f"carries the unit {unit} and start_{given_unit} gives another")
    unit = unit or given_unit or ""
    present = [k for k in parent if k.startswith(f"{quantity}_") and _split_unit(
        k, parent)[0] == quantity]
    if not present:
        if unit and given_unit is None:  # a key the config leaves at its default
            return parts[:-1], name, None, unit, False  # (each point's validation checks it)
        raise t.error(key, "is not a key of the config: sweep a key the config sets (with "
                           "its base value), a key with its unit suffix, or "
                           "tolerances.<source>.scale")
    old = present[0]
    _, old_unit, old_kind = _split_unit(old, parent)
    if old_kind is None or not isinstance(parent[old], (int, float)) or isinstance(
            parent[old], bool):
        raise t.error(key, f"is not numeric (the config's {old} is not a number)")
    if not unit:
        raise t.error(key, f"needs a unit: the config has {old}; write the key as "
                           f"{quantity}_<unit> or give start_<unit> and stop_<unit>")
    if unit not in units[old_kind]:
        raise t.error(key, f"has the unit {unit}, which does not fit {'.'.join(parts[:-1])}."
                           f"{quantity} ({'an' if old_kind[0] in 'aeiou' else 'a'} {old_kind}: "
                           f"{', '.join(u for u in units[old_kind] if u)})")
    return parts[:-1], f"{quantity}_{unit}", old, unit, False


def _coordinate_name(key: str, unit: str) -> str:
    name = key[: -len(unit) - 1] if unit and key.endswith(f"_{unit}") else key
    return name.replace(".", "_")


def parse_sweep(t, base: dict, build) -> Sweep:
    """Read ``[sweep]`` (a :class:`tolsim.io.config.reader.Table`) against the config's TOML data
    ``base``; ``build(data) -> StudyConfig`` validates a point. Returns the :class:`Sweep`
    with every point's config. Raises :class:`tolsim.io.config.ConfigError` (one line)."""
    mode = t.string("mode", SWEEP_MODES, default="outer")
    specs = [(k, v) for k, v in _flatten(t.data) if k != "mode"]
    if not specs:
        raise t.error(None, "names no key to sweep: add e.g. \"carriage.load.force_z_N\" = "
                            "[100, 200, 400]")
    for key, _ in specs:  # a plain name is a setting of [sweep]: only mode is one
        if "." not in key:
            example = next((k for k, _ in specs if "." in k), "loads.yaw_moment_N_m")
            modes = " or ".join(repr(m) for m in SWEEP_MODES)
            raise t.error(key, f"is not a known key: [sweep] takes mode ({modes}) and the "
                               "dotted paths of the config keys to sweep (such as "
                               f"\"{example}\")")
    axes, targets = [], []
    for key, spec in specs:
        values, given_unit = _values(t, key, spec)
        path, set_key, old_key, unit, whole = _resolve(t, key, given_unit, base)
        full = ".".join([*path, set_key])
        if mode != "zip" and len(set(values)) != len(values):
            raise t.error(key, "has repeated values: each point must differ")
        if whole and not all(float(v).is_integer() for v in values):
            odd = next(v for v in values if not float(v).is_integer())
            raise t.error(key, f"takes whole numbers (the config gives one), not {odd:g}")
        axes.append(SweepAxis(full, _coordinate_name(full, unit), tuple(values), unit,
                              UDUNITS.get(unit, unit)))
        targets.append((path, set_key, old_key, whole))
    names = [a.name for a in axes]
    for a in axes:
        if names.count(a.name) > 1:
            raise t.error(a.key, "is swept twice")
        if a.name in (ZIP_DIMENSION,):
            raise t.error(a.key, f"is named like the sweep dimension {ZIP_DIMENSION}")
    if mode == "zip" and len({len(a.values) for a in axes}) > 1:
        lengths = ", ".join(f"{a.key}: {len(a.values)}" for a in axes)
        raise t.error(axes[-1].key, f"mode = 'zip' needs as many values for every key ({lengths})")
    if mode == "zip":  # a key may repeat a value where another key differs
        tuples = list(zip(*(a.values for a in axes), strict=True))
        if len(set(tuples)) != len(tuples):
            raise t.error(axes[-1].key, "mode = 'zip' repeats a point (the same values of "
                                        "every key twice): each point must differ")
    sweep = Sweep(tuple(axes), mode)
    points = []
    for k in range(sweep.size):
        data = copy.deepcopy(base)
        for (path, set_key, old_key, whole), value in zip(
                targets, sweep.values_at(k).values(), strict=True):
            parent = data
            for part in path:
                parent = parent[part]
            if old_key is not None:
                del parent[old_key]
            parent[set_key] = int(value) if whole else value
        try:
            points.append(build(data))
        except ConfigError as exc:
            raise ConfigError(f"{exc} (sweep point {k + 1} of {sweep.size}: "
                              f"{sweep.describe(k)})") from None
    _check_axes(t, sweep, points)
    return sweep.with_points(points)


def _result_axes(config) -> dict:
    """What shapes a result file's axes, by the key that sets it."""
    st = config.study
    out = {"the balls and tracks": (config.balls, config.n_tracks),
           "the horizon (motion.duration, the time axis)": config.motion.duration,
           "the histogram ranges and bins ([study])": (
               tuple(st.velocity_deviation_range), st.velocity_deviation_bins, st.time_bins),
           "the tolerance sources (the Sobol' factors)": tuple(
               t.source for t in config.tolerances),
           "the Sobol' indices (study.sensitivity_samples)": bool(st.sensitivity_samples),
           "the estimator ([study] estimator)": st.estimator,
           "[contact]": config.has_contact}
    if config.has_contact:  # the friction examples' grid
        out["the friction examples' travel grid (stroke, contact.travel_points, "
            "contact.examples)"] = (config.motion.stroke, config.contact.travel_points,
                                    config.contact.examples)
    return out


def _check_axes(t, sweep, points):
    """Refuse keys whose points would need different axes in one result file."""
    first = _result_axes(points[0])
    for k, p in enumerate(points[1:], start=1):
        for what, value in _result_axes(p).items():
            if value != first.get(what):
                keys = ", ".join(a.key for a in sweep.axes)
                raise t.error(None, f"({keys}) changes {what} between points 1 and {k + 1}: "
                                    "such points cannot share one result file; run them as "
                                    "separate studies and compare them with tolsim compare")

