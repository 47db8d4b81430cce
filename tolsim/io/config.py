"""Study configuration: TOML (read with :mod:`tomllib`) -> validated frozen dataclasses.

Every dimensional key carries its unit as a suffix (``ball_diameter_mm``, ``std_um``,
``yaw_moment_N_m``); values are converted to SI once, here, and nothing downstream sees a
unit again. Any problem raises :class:`ConfigError`, a :class:`ValueError` whose message is
one line naming the file, the line (where it can be found) and the key, e.g.::

    study.toml:12: tolerances.top_rotation.std_deg = -0.1 must be >= 0

The sections and their keys are documented in ``tolsim/data/default.toml`` (the packaged
default study) and in ``configs/*.toml``.
"""

import csv
import hashlib
import io
import math
import re
import tomllib
from dataclasses import replace
from importlib import resources
from pathlib import Path

import numpy as np

from tolsim.physics.carriage import CarriageLayout, CarriageLoad
from tolsim.physics.geometry import Bearing
from tolsim.study.analyses.rare_events import MIN_CHAINS
from tolsim.study.spec import (
    CREEP_MODELS,
    DISTRIBUTIONS,
    ESTIMATORS,
    PLAUSIBLE_NORMAL_RANGE,
    PROPAGATIONS,
    SAMPLINGS,
    SCOPES,
    SOURCES,
    STATIC_MODELS,
    VELOCITY_MODELS,
    Carriage,
    ContactSettings,
    Correlation,
    Distribution,
    Loads,
    Motion,
    StudyConfig,
    StudySettings,
    Tolerance,
    Train,
    correlation_matrix_problem,
)

__all__ = ["ConfigError", "StudyConfig", "default_config_text", "load_config", "parse_config"]

#: Unit suffixes of config keys: quantity kind -> {suffix: factor to SI}.
UNITS = {
    "length": {"m": 1.0, "mm": 1e-3, "um": 1e-6},
    "angle": {"rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180.0, "arcmin": math.pi / 10800.0},
    "force": {"N": 1.0, "kN": 1e3},
    "moment": {"N_m": 1.0, "N_mm": 1e-3},
    "pressure": {"Pa": 1.0, "MPa": 1e6, "GPa": 1e9},
    "velocity": {"m_per_s": 1.0, "mm_per_s": 1e-3},
    "time": {"s": 1.0, "min": 60.0},
    "fraction": {"percent": 1e-2, "ppm": 1e-6},
    "dimensionless": {"": 1.0},
}

#: Fewest measured values an ``empirical`` distribution accepts.
MIN_EMPIRICAL_VALUES = 10


class ConfigError(ValueError):
    """A bad study configuration; the message is one line naming the key (file:line: key)."""


# --------------------------------------------------------------------------------------------
# Reader
# --------------------------------------------------------------------------------------------
class _Source:
    """The TOML text, for error messages with file and line."""

    def __init__(self, text, path):
        self.text, self.path = text, path
        self.lines = text.splitlines()

    def line_of(self, table, key=None):
        """Line number (1-based) of ``key`` in ``[table]`` (or of the header), else None.

        The k-th ``[[name]]`` of an array of tables is the table ``name[k]`` (k from 1).
        """
        header = re.compile(r"""^\s*\[(\[?)\s*([A-Za-z0-9_.\s"']+?)\s*\]\]?\s*(#.*)?$""")
        current, found_header, counts = "", None, {}
        for number, line in enumerate(self.lines, 1):
            m = header.match(line)
            if m:
                current = ".".join(p.strip().strip("\"'") for p in m.group(2).split("."))
                if m.group(1):
                    counts[current] = counts.get(current, 0) + 1
                    current = f"{current}[{counts[current]}]"
                if current == table and found_header is None:
                    found_header = number
                continue
            if key is not None:
                quoted = rf"""(?:{re.escape(key)}|"{re.escape(key)}"|'{re.escape(key)}')"""
                if current == table and re.match(rf"^\s*{quoted}\s*=", line):
                    return number
                # dotted parent tables (a.b.key = ...)
                rel = (table + "." + key)[len(current) + 1 :] if current else table + "." + key
                if table.startswith(current) and re.match(rf"^\s*{re.escape(rel)}\s*=", line):
                    return number
        return found_header

    def error(self, table, key, message):
        """A ConfigError 'file:line: table.key message'."""
        line = self.line_of(table, key)
        if line is None and key is not None:  # key is itself a [table.key] header
            line = self.line_of(f"{table}.{key}" if table else key)
        if line is None and "." in table:  # inline table: point at its parent key
            parent, _, last = table.rpartition(".")
            line = self.line_of(parent, last)
        where = f"{self.path}:{line}" if line else self.path
        name = f"{table}.{key}" if key else table
        return ConfigError(f"{where}: {name} {message}")


class _Table:
    """One TOML table being read: typed getters with units; unknown keys are errors."""

    def __init__(self, data, name, source):
        if not isinstance(data, dict):
            raise source.error(name, None, f"must be a table, got {type(data).__name__}")
        self.data, self.name, self.source = data, name, source
        self.used = set()

    def error(self, key, message):
        return self.source.error(self.name, key, message)

    def has(self, key):
        return key in self.data

    def _number(self, key, value, *, integer=False):
        ok_types = (int,) if integer else (int, float)
        if isinstance(value, bool) or not isinstance(value, ok_types):
            kind = "an integer" if integer else "a number"
            raise self.error(key, f"= {value!r} must be {kind}, got {type(value).__name__}")
        if not math.isfinite(value):
            raise self.error(key, f"= {value!r} must be finite")
        return value

    def quantity(self, name, kind, *, default=None, required=True, allow_list=False,
                 minimum=None, positive=False):
        """Read ``name_<unit>`` and return it in SI (a float, or a tuple with allow_list)."""
        found = self.unit_key(name, kind, required=required and default is None)
        if found is None:
            return default
        key, factor = found
        raw = self.data[key]
        values = raw if (allow_list and isinstance(raw, list)) else [raw]
        if allow_list and isinstance(raw, list) and not raw:
            raise self.error(key, "must not be an empty list")
        out = []
        for v in values:
            v = self._number(key, v)
            if positive and not v > 0:
                raise self.error(key, f"= {v!r} must be > 0")
            if minimum is not None and v < minimum:
                raise self.error(key, f"= {v!r} must be >= {minimum}")
            out.append(float(v) * factor)
        return tuple(out) if (allow_list and isinstance(raw, list)) else out[0]

    def unit_key(self, name, kind, *, required=True):
        """(key, factor to SI) of the one ``name_<unit>`` key given, or None if absent.

        Raises for two units, no unit, an unknown unit suffix, or a missing required key.
        """
        units = UNITS[kind]
        keys = [f"{name}_{u}" if u else name for u in units]
        present = [k for k in keys if k in self.data]
        if len(present) > 1:
            raise self.error(present[1], f"given together with {present[0]}: use one")
        if not present:
            if name in self.data and kind != "dimensionless":
                raise self.error(name, f"needs a unit suffix: one of {', '.join(keys)}")
            for k in self.data:
                if k.startswith(f"{name}_") and k[len(name) + 1 :] not in units:
                    raise self.error(k, f"has an unknown unit suffix (use one of "
                                        f"{', '.join(keys)})")
            if required:
                raise self.error(keys[0] if kind == "dimensionless" else f"{name}_<unit>",
                                 f"is missing (one of {', '.join(keys)})")
            return None
        key = present[0]
        self.used.add(key)
        return key, units[key[len(name) + 1 :] if key != name else ""]

    def text(self, key, *, default=None):
        """A free string (a file name, a column name); missing -> ``default`` or an error."""
        if key not in self.data:
            if default is None:
                raise self.error(key, "is missing")
            return default
        self.used.add(key)
        v = self.data[key]
        if not isinstance(v, str) or not v.strip():
            raise self.error(key, f"= {v!r} must be a non-empty string")
        return v

    def key_for(self, name, kind):
        """The key actually used for quantity ``name`` (``name_<unit>`` if absent)."""
        for u in UNITS[kind]:
            if (f"{name}_{u}" if u else name) in self.data:
                return f"{name}_{u}" if u else name
        return f"{name}_<unit>"

    def integer(self, key, *, default=None, minimum=None):
        if key not in self.data:
            if default is None:
                raise self.error(key, "is missing")
            return default
        self.used.add(key)
        v = self._number(key, self.data[key], integer=True)
        if minimum is not None and v < minimum:
            raise self.error(key, f"= {v!r} must be >= {minimum}")
        return int(v)

    def string(self, key, choices, *, default=None):
        if key not in self.data:
            if default is None:
                raise self.error(key, f"is missing (one of {', '.join(choices)})")
            return default
        self.used.add(key)
        v = self.data[key]
        if not isinstance(v, str):
            raise self.error(key, f"= {v!r} must be a string, one of {', '.join(choices)}")
        if v not in choices:
            raise self.error(key, f"= {v!r} is not one of {', '.join(choices)}")
        return v

    def boolean(self, key, *, default=False):
        if key not in self.data:
            return default
        self.used.add(key)
        v = self.data[key]
        if not isinstance(v, bool):
            raise self.error(key, f"= {v!r} must be true or false")
        return v

    def table(self, key, *, required=True):
        if key not in self.data:
            if required:
                raise self.source.error(f"{self.name}.{key}" if self.name else key, None,
                                        "section is missing")
            return None
        self.used.add(key)
        return _Table(self.data[key], f"{self.name}.{key}" if self.name else key, self.source)

    def finish(self):
        """Raise on the first key that was not read."""
        for key in self.data:
            if key not in self.used:
                raise self.error(key, "is not a known key")


def _distribution(table: _Table, kind: str) -> Distribution:
    """Read a distribution table; values in SI of the quantity ``kind``."""
    name = table.string("distribution", DISTRIBUTIONS)
    q = lambda key, **kw: table.quantity(key, kind, **kw)  # noqa: E731
    if name == "fixed":
        d = Distribution("fixed", value=q("value"))
    elif name == "normal":
        d = Distribution("normal", mean=q("mean", default=0.0), std=q("std", minimum=0.0))
    elif name == "uniform":
        low, high = q("low"), q("high")
        if not high > low:
            raise table.error(table.key_for("high", kind),
                              f"= {high!r} must be greater than low ({low!r}) [SI]")
        d = Distribution("uniform", low=low, high=high)
    elif name == "truncated_normal":
        mean, std = q("mean", default=0.0), q("std", positive=True)
        low, high = q("low"), q("high")
        if not high > low:
            raise table.error(table.key_for("high", kind),
                              f"= {high!r} must be greater than low ({low!r}) [SI]")
        d = Distribution("truncated_normal", mean=mean, std=std, low=low, high=high)
    elif name == "cpk":
        low, high = q("low"), q("high")
        if not high > low:
            raise table.error(table.key_for("high", kind),
                              f"= {high!r} must be greater than low ({low!r}) [SI]")
        mean = q("mean", default=0.5 * (low + high))
        if not low < mean < high:
            raise table.error(table.key_for("mean", kind), f"= {mean!r} must lie inside the band")
        cpk = table.quantity("cpk", "dimensionless", positive=True)
        std = min(high - mean, mean - low) / (3.0 * cpk)
        d = Distribution("cpk", mean=mean, std=std, low=low, high=high, cpk=cpk,
                         truncate=table.boolean("truncate"))
    else:  # empirical
        d = _empirical(table, kind)
    return d


def _empirical(table: _Table, kind: str) -> Distribution:
    """Measured values from a CSV column: ``file``, ``column_<unit>``, optional ``sha256``."""
    file = table.text("file")
    column_key, factor = table.unit_key("column", kind)
    column = table.text(column_key)
    path = Path(file)
    if not path.is_absolute():  # relative to the config file (a string config: to the cwd)
        path = Path(table.source.path).parent / path
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise table.error("file", f"= {file!r}: cannot read {path}: "
                                  f"{exc.strerror or exc.__class__.__name__}") from None
    sha256 = hashlib.sha256(raw).hexdigest()
    if table.has("sha256"):
        pinned = table.text("sha256").strip().lower()
        if pinned != sha256:
            raise table.error("sha256", f"= {pinned!r} but {file} has SHA-256 {sha256}: the "
                                        "measured data changed")

    def bad(message):
        return table.error(column_key, f"= {column!r}: {file}{message}")

    try:
        reader = csv.reader(io.StringIO(raw.decode("utf-8-sig")))
        header, values = None, []
        for row in reader:
            cells = [c.strip() for c in row]
            if not any(cells) or cells[0].startswith("#"):  # blank and comment lines
                continue
            if header is None:
                header = cells
                if column not in header:
                    raise bad(f":{reader.line_num}: no column {column!r} in the header "
                              f"({', '.join(repr(h) for h in header)})")
                j = header.index(column)
                continue
            cell = cells[j] if j < len(cells) else ""
            if not cell:  # a shorter column of a file with several
                continue
            try:
                v = float(cell)
            except ValueError:
                raise bad(f":{reader.line_num}: {cell!r} is not a number") from None
            if not math.isfinite(v):
                raise bad(f":{reader.line_num}: {cell!r} is not a finite number")
            values.append(v * factor)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise bad(f": not a readable CSV file ({' '.join(str(exc).split())})") from None
    if header is None:
        raise bad(": the file is empty (expected a header line, then one value per line)")
    if len(values) < MIN_EMPIRICAL_VALUES:
        raise bad(f": {len(values)} values; at least {MIN_EMPIRICAL_VALUES} are needed")
    return Distribution("empirical", data=tuple(sorted(values)), data_file=file,
                        data_sha256=sha256)


def _check_range(table: _Table, source: str, kind: str, dist: Distribution, bearing):
    """Raise if ``dist`` reaches beyond the errors the static model accepts.

    Lengths: a quarter of the ball-groove centre distance (f - 1/2) D, angles pi/8, as
    :func:`tolsim.physics.static.solve_static` demands of every ball. A normal reaches
    :data:`tolsim.study.spec.PLAUSIBLE_NORMAL_RANGE` standard deviations. Catches unit slips
    (``std_mm`` for ``std_um``) at load time, with the key and its line.
    """
    limit = math.pi / 8 if kind == "angle" else 0.25 * (bearing.groove_radius
                                                          - bearing.ball_radius)
    low, high = dist.support
    if max(abs(low), abs(high)) <= limit:
        return
    edge = "low" if abs(low) >= abs(high) else "high"
    if dist.kind == "fixed":
        name = "value"
    elif dist.kind == "empirical":
        name = "column"
    elif dist.kind == "normal":
        name = "mean" if abs(dist.mean) > limit else "std"
    elif dist.kind == "cpk" and not dist.truncate:  # the band, or the spread beyond it
        name = edge if max(abs(dist.low), abs(dist.high)) > limit else "cpk"
    else:
        name = edge
    key = name if name == "cpk" else table.key_for(name, kind)
    # the unit the user wrote (of this key, or of the table's other keys of this kind)
    suffixes = [k.rpartition("_")[2] for k in (key, *table.data) if "_" in k]
    unit = next((u for u in suffixes if u in UNITS[kind]), next(iter(UNITS[kind])))
    factor = UNITS[kind][unit]
    reach = {"column": "the data reach", "value": "the value is",
             "std": f"mean +/- {PLAUSIBLE_NORMAL_RANGE:g} std reaches",
             "cpk": f"mean +/- {PLAUSIBLE_NORMAL_RANGE:g} std reaches"}.get(name,
                                                                          "the values reach")
    span = f"{low / factor:.4g}" if low == high else f"{low / factor:.4g} .. {high / factor:.4g}"
    what = "pi/8" if kind == "angle" else "a quarter of the ball-groove centre distance"
    raise table.error(key, f"= {table.data.get(key)!r}: {reach} {span} {unit}, beyond the "
                           f"+/-{limit / factor:.4g} {unit} ({what}) that the static model "
                           f"accepts for {source}: is the unit right?")


def _bearing(t: _Table) -> Bearing:
    diameter = t.quantity("ball_diameter", "length", positive=True)
    values = dict(
        ball_radius=0.5 * diameter,
        conformity=t.quantity("conformity", "dimensionless"),
        nominal_contact_angle=t.quantity("nominal_contact_angle", "angle",
                                         default=math.pi / 4),
        youngs_modulus=t.quantity("youngs_modulus", "pressure", default=210e9, positive=True),
        poisson_ratio=t.quantity("poisson_ratio", "dimensionless", default=0.28),
        friction_coefficient=t.quantity("friction_coefficient", "dimensionless", default=0.1,
                                        minimum=0.0),
    )
    t.finish()
    try:
        return Bearing(**values)
    except ValueError as exc:  # Bearing names the field
        field_name = str(exc).split(" ", 1)[0]
        key = {"ball_radius": "ball_diameter"}.get(field_name, field_name)
        kind = {"nominal_contact_angle": "angle", "youngs_modulus": "pressure",
                "ball_diameter": "length"}.get(key, "dimensionless")
        raise t.error(t.key_for(key, kind), f"= {values.get(field_name)!r} [SI] is out of "
                                            "range") from None


def _motion(t: _Table) -> Motion:
    v = t.quantity("groove_velocity", "velocity", positive=True)
    has_stroke = any(t.has(f"stroke_{u}") for u in UNITS["length"])
    has_duration = any(t.has(f"duration_{u}") for u in UNITS["time"])
    if has_stroke and has_duration:
        raise t.error(t.key_for("stroke", "length"), "given together with duration: use one")
    if has_stroke:
        duration = t.quantity("stroke", "length", positive=True) / v
    else:
        duration = t.quantity("duration", "time", positive=True)
    t.finish()
    return Motion(groove_velocity=v, duration=duration)


def _train(t: _Table, bearing: Bearing) -> Train:
    balls = t.integer("balls", minimum=1)
    gap_table = t.table("initial_gap")
    gap = _distribution(gap_table, "length")
    gap_table.finish()
    if gap.kind == "fixed" and gap.value < 0:
        raise gap_table.error(gap_table.key_for("value", "length"),
                              f"= {gap.value!r} m must be >= 0")
    if gap.kind in ("uniform", "truncated_normal") and gap.low < 0:
        raise gap_table.error(gap_table.key_for("low", "length"),
                              f"= {gap.low!r} m must be >= 0 (gaps cannot overlap)")
    if gap.kind == "empirical" and gap.data[0] < 0:
        raise gap_table.error(gap_table.key_for("column", "length"),
                              f"holds {gap.data[0]!r} m: gaps must be >= 0 (cannot overlap)")
    pitch = 2.0 * bearing.ball_radius + max(gap.expected, 0.0)
    length = t.quantity("loaded_zone_length", "length", default=balls * pitch, positive=True)
    t.finish()
    return Train(balls=balls, initial_gap=gap, loaded_zone_length=length)


def _loads(t: _Table, train: Train, bearing: Bearing) -> Loads:
    n = train.balls

    def per_ball(value, key):
        if isinstance(value, tuple):
            if len(value) != n:
                raise t.error(key, f"has {len(value)} values but train.balls = {n}")
            return np.asarray(value)
        return np.full(n, value)

    normal = per_ball(t.quantity("normal_load", "force", allow_list=True, positive=True),
                      "normal_load_<unit>")
    has_ratio = t.has("side_force_ratio")
    has_side = any(t.has(f"side_load_{u}") for u in UNITS["force"])
    if has_ratio and has_side:
        raise t.error("side_force_ratio", "given together with side_load: use one")
    if has_ratio:
        ratio = t.quantity("side_force_ratio", "dimensionless", allow_list=True)
        side = normal * per_ball(ratio, "side_force_ratio")
    else:
        total = t.quantity("side_load", "force", default=0.0, allow_list=True)
        side = per_ball(total, "side_load_<unit>")
    yaw = t.quantity("yaw_moment", "moment", default=0.0)
    if yaw:
        z = train.slot_positions(2.0 * bearing.ball_radius)
        if n < 2:
            raise t.error("yaw_moment_<unit>", "needs train.balls >= 2")
        side = side + yaw * z / np.sum(z * z)
    t.finish()
    return Loads(normal_load=tuple(map(float, normal)), side_load=tuple(map(float, side)),
                 yaw_moment=float(yaw))


def _carriage(t: _Table, bearing: Bearing) -> Carriage:
    """``[carriage]``, ``[carriage.load]`` and ``[[carriage.track]]`` (tolsim issue 12)."""
    n = t.integer("balls_per_track", minimum=1)
    pitch = t.quantity("ball_pitch", "length")
    pitch_key = t.key_for("ball_pitch", "length")
    if pitch < 0:
        raise t.error(pitch_key, f"= {t.data[pitch_key]!r} must be >= 0")
    diameter = 2.0 * bearing.ball_radius
    if n > 1 and pitch < diameter * (1.0 - 1e-12):
        raise t.error(pitch_key, f"= {t.data[pitch_key]!r} is less than the ball diameter "
                                 f"({diameter * 1e3:g} mm): neighbouring balls would overlap")
    preload = t.quantity("preload_oversize", "length", default=0.0)
    limit = 0.25 * (bearing.groove_radius - bearing.ball_radius)
    if abs(preload) > limit:
        key = t.key_for("preload_oversize", "length")
        raise t.error(key, f"= {t.data[key]!r} is beyond +/- {limit * 1e6:g} um, a quarter of "
                           "the ball-groove centre distance (a unit slip?)")
    # end relief (crowning) of the carriage grooves; the length is checked against the
    # loaded zone in parse_config, once [train] is read
    relief_depth = t.quantity("end_relief_depth", "length", default=0.0, minimum=0.0)
    relief_length = t.quantity("end_relief_length", "length", default=0.0, minimum=0.0)
    depth_key = t.key_for("end_relief_depth", "length")
    length_key = t.key_for("end_relief_length", "length")
    if relief_depth > limit:
        raise t.error(depth_key, f"= {t.data[depth_key]!r} is beyond {limit * 1e6:g} um, a "
                                 "quarter of the ball-groove centre distance (a unit slip?)")
    if relief_depth > 0 and not relief_length > 0:
        raise t.error(depth_key, "needs end_relief_length_<unit> > 0 (the relieved length at "
                                 "each end of the loaded zone)")
    if relief_length > 0 and not relief_depth > 0:
        raise t.error(length_key, "has no effect without end_relief_depth_<unit> > 0")

    load_table = t.table("load", required=False)
    if load_table is None:
        load = CarriageLoad()
    else:
        force = lambda name: load_table.quantity(name, "force", default=0.0)  # noqa: E731
        moment = lambda name: load_table.quantity(name, "moment", default=0.0)  # noqa: E731
        load = CarriageLoad(lateral_force=force("lateral"), vertical_force=force("vertical"),
                            pitch_moment=moment("pitch_moment"), yaw_moment=moment("yaw_moment"),
                            roll_moment=moment("roll_moment"))
        load_table.finish()

    raw = t.data.get("track")
    if raw is None or raw == []:
        raise t.error("track", "is missing: give one [[carriage.track]] per row of balls "
                               "(x_mm, y_mm, orientation_deg)")
    t.used.add("track")
    if not (isinstance(raw, list) and all(isinstance(item, dict) for item in raw)):
        raise t.error("track", "must be an array of tables: start each track with "
                               "[[carriage.track]]")
    xs, ys, phis, per_track = [], [], [], []
    for number, item in enumerate(raw, 1):
        tr = _Table(item, f"{t.name}.track[{number}]", t.source)
        xs.append(tr.quantity("x", "length"))
        ys.append(tr.quantity("y", "length", default=0.0))
        phis.append(tr.quantity("orientation", "angle"))
        dev = tr.quantity("ball_oversize_deviation", "length", allow_list=True, required=False)
        if dev is not None:
            key = tr.key_for("ball_oversize_deviation", "length")
            if not isinstance(dev, tuple) or len(dev) != n:
                count = len(dev) if isinstance(dev, tuple) else 1
                raise tr.error(key, f"has {count} values but balls_per_track = {n} (one "
                                    "per ball, ball 0 trailing)")
            per_track.append((number, key, dev))
        tr.finish()
    deviation = ()
    flat = t.quantity("ball_oversize_deviation", "length", allow_list=True, required=False)
    if flat is not None:
        key = t.key_for("ball_oversize_deviation", "length")
        if per_track:
            raise t.error(key, f"given together with carriage.track[{per_track[0][0]}]."
                               f"{per_track[0][1]}: give one list over all balls here, or a "
                               "list in every track")
        total = n * len(raw)
        if not isinstance(flat, tuple) or len(flat) != total:
            count = len(flat) if isinstance(flat, tuple) else 1
            raise t.error(key, f"has {count} values but the carriage has {total} balls "
                               f"({len(raw)} tracks x {n}, track by track)")
        deviation = flat
    elif per_track:
        if len(per_track) != len(raw):
            missing = next(k for k in range(1, len(raw) + 1)
                           if k not in {p[0] for p in per_track})
            raise t.source.error(f"{t.name}.track[{missing}]", "ball_oversize_deviation_um",
                                 "is missing: give it in every track or in none")
        deviation = tuple(v for _, _, dev in per_track for v in dev)
    for value in deviation:
        if abs(preload + value) > limit:
            key = t.key_for("ball_oversize_deviation", "length")
            raise t.error(key, f"gives a ball oversize of {(preload + value) * 1e6:g} um, "
                               f"beyond +/- {limit * 1e6:g} um")
    t.finish()
    try:
        layout = CarriageLayout(np.array(xs), np.array(ys), np.array(phis), n, pitch)
    except ValueError as exc:
        raise t.error(None, " ".join(str(exc).split())) from None
    return Carriage(layout=layout, load=load, preload_oversize=preload,
                    ball_oversize_deviation=tuple(map(float, deviation)),
                    end_relief_depth=relief_depth, end_relief_length=relief_length)


def _carriage_propagation(t: _Table, carriage: Carriage, train: Train, study_table: _Table,
                          study: StudySettings):
    """Raise for what a [carriage] study cannot combine with its propagation: end relief
    without along_track or longer than half the loaded zone; one ball per track, fixed
    per-ball oversizes with along_track."""
    if carriage.end_relief_depth > 0:
        half = 0.5 * train.loaded_zone_length
        key = t.key_for("end_relief_length", "length")
        if carriage.end_relief_length > half:
            raise t.error(key, f"= {t.data[key]!r} is longer than half the loaded zone "
                               f"({half * 1e3:g} mm, train.loaded_zone_length / 2)")
        if study.propagation != "along_track":
            raise t.error(t.key_for("end_relief_depth", "length"),
                          "acts on balls rolling through the carriage: it needs "
                          "study.propagation = 'along_track'")
    if study.propagation != "along_track":
        return
    if carriage.layout.balls_per_track < 2:
        raise t.error("balls_per_track", "= 1: with propagation = 'along_track' a track needs "
                                         "at least 2 balls (one ball cannot hold the "
                                         "carriage's pitch and yaw as it rolls)")
    if carriage.ball_oversize_deviation:
        raise t.error(t.key_for("ball_oversize_deviation", "length"),
                      "fixes the size of the balls at their slots, but with propagation = "
                      "'along_track' the balls roll through the carriage: give the size "
                      "scatter as [tolerances.ball_oversize] instead")


def _tolerances(t: _Table | None, bearing: Bearing) -> tuple:
    if t is None:
        return ()
    out = []
    for source in list(t.data):
        if source not in SOURCES:
            raise t.error(source, f"is not a known error source ({', '.join(SOURCES)})")
        sub = t.table(source)
        kind, side = SOURCES[source]
        dist = _distribution(sub, kind)
        scale = sub.quantity("scale", "dimensionless", default=1.0, positive=True)
        if scale != 1.0:  # "this tolerance times scale" (sweeps, allocated configs)
            if not dist.is_random:
                raise sub.error("scale", f"= {scale!r}: a {dist.kind} value has no spread "
                                         "to scale")
            dist = dist.scaled(scale)
        _check_range(sub, source, kind, dist, bearing)
        scope = sub.string("scope", SCOPES, default=side)
        if side != "ball" and scope == "rail" and side == "carriage":
            raise sub.error("scope", "= 'rail' but this is a carriage-side error source")
        if side == "ball" and scope != "ball":
            raise sub.error("scope", f"= {scope!r} but this is a per-ball error source")
        corr = sub.quantity("correlation_length", "length", default=0.0, minimum=0.0)
        if corr and scope != "rail":
            raise sub.error(sub.key_for("correlation_length", "length"),
                            "applies only with scope = 'rail'")
        sub.finish()
        out.append(Tolerance(source, dist, scope, corr))
    t.finish()
    return tuple(out)


#: Keys that were plain fractions and now carry a unit (``_percent`` or ``_ppm``).
FRACTION_KEYS = ("velocity_deviation_range", "velocity_deviation_limit",
                 "contact_probability_limit", "out_of_spec_limit")


def _contact(t: _Table) -> ContactSettings:
    """``[contact]``: after balls touch (issue 13; :class:`ContactSettings`)."""
    s = ContactSettings(
        ball_friction_coefficient=t.quantity("ball_friction_coefficient", "dimensionless",
                                             default=0.1, minimum=0.0),
        friction_increase_limit=t.quantity("friction_increase_limit", "force", default=0.0,
                                           positive=True),
        creep_model=t.string("creep_model", CREEP_MODELS, default="analytic"),
        examples=t.integer("examples", default=4, minimum=0),
        travel_points=t.integer("travel_points", default=201, minimum=2),
    )
    t.finish()
    return s


def _study(t: _Table) -> StudySettings:
    for name in FRACTION_KEYS:
        if t.has(name):  # a bare 0.5 was read as 50 % where 0.5 % was meant
            v = t.data[name]

            def percent(x):
                number = isinstance(x, int | float) and not isinstance(x, bool)
                return f"{100 * x:.10g}" if number else repr(x)

            pct = ("[" + ", ".join(map(percent, v)) + "]") if isinstance(v, list) else percent(v)
            raise t.error(name, f"= {v!r} has no unit: write {name}_percent = {pct} if "
                                f"{v!r} is a fraction, {name}_percent = {v!r} if it is in "
                                "percent (or use _ppm)")
    lo_hi = t.quantity("velocity_deviation_range", "fraction", allow_list=True,
                       default=(-0.02, 0.02))
    range_key = t.key_for("velocity_deviation_range", "fraction")
    if not (isinstance(lo_hi, tuple) and len(lo_hi) == 2 and lo_hi[1] > lo_hi[0]):
        raise t.error(range_key, f"= {t.data.get(range_key)!r} must be [low, high], low < high")
    if not (-1.0 <= lo_hi[0] and lo_hi[1] <= 1.0):
        raise t.error(range_key, f"= {t.data.get(range_key)!r} must lie within "
                                 "[-100 %, 100 %] (|epsilon| > 1 stops or reverses a ball)")
    s = StudySettings(
        samples=t.integer("samples", minimum=1),
        seed=t.integer("seed", minimum=0),
        block_size=t.integer("block_size", default=1024, minimum=1),
        velocity_model=t.string("velocity_model", VELOCITY_MODELS, default="analytic"),
        static_model=t.string("static_model", STATIC_MODELS, default="paired"),
        propagation=t.string("propagation", PROPAGATIONS, default="constant"),
        sampling=t.string("sampling", SAMPLINGS, default="random"),
        spot_checks=t.integer("spot_checks", default=0, minimum=0),
        time_steps=t.integer("time_steps", default=200, minimum=1),
        velocity_deviation_range=tuple(lo_hi),
        velocity_deviation_bins=t.integer("velocity_deviation_bins", default=400, minimum=1),
        time_bins=t.integer("time_bins", default=200, minimum=1),
        velocity_deviation_limit=t.quantity("velocity_deviation_limit", "fraction",
                                            default=0.0, minimum=0.0),
        contact_probability_limit=t.quantity("contact_probability_limit", "fraction",
                                             default=0.0, minimum=0.0),
        out_of_spec_limit=t.quantity("out_of_spec_limit", "fraction", default=0.0,
                                     minimum=0.0),
        cpk_minimum=t.quantity("cpk_minimum", "dimensionless", default=0.0, minimum=0.0),
        sensitivity_samples=t.integer("sensitivity_samples", default=0, minimum=0),
    )
    if s.sensitivity_samples == 1:
        raise t.error("sensitivity_samples", "must be 0 (off) or >= 2")
    if s.velocity_deviation_limit >= 1:
        key = t.key_for("velocity_deviation_limit", "fraction")
        raise t.error(key, f"= {t.data[key]!r} must be < 100 % (|epsilon| >= 1 stops or "
                           "reverses a ball)")
    for name in ("contact_probability_limit", "out_of_spec_limit"):
        if getattr(s, name) > 1:
            key = t.key_for(name, "fraction")
            raise t.error(key, f"= {t.data[key]!r} must be <= 100 %")
    if s.out_of_spec_limit > 0 and s.velocity_deviation_limit == 0:
        key = t.key_for("out_of_spec_limit", "fraction")
        raise t.error(key, "needs a limit on |epsilon| (velocity_deviation_limit_percent) "
                           "to say which balls are out of spec")
    if s.cpk_minimum > 0 and s.velocity_deviation_limit == 0:
        raise t.error("cpk_minimum", "needs a limit on |epsilon| "
                                     "(velocity_deviation_limit_percent) to define Cpk")
    s = _estimator(t, s)
    t.finish()
    return s


#: Keys of ``[study]`` read by each rare-event estimator (importance falls back to subset).
ESTIMATOR_KEYS = {"monte_carlo": (), "subset": ("samples_per_level", "p0", "max_levels"),
                  "importance": ("samples_per_level", "p0", "max_levels", "importance_samples")}


def _estimator(t: _Table, s: StudySettings) -> StudySettings:
    """``[study] estimator`` and its settings (issue 15;
    :mod:`tolsim.study.analyses.limit_state`)."""
    estimator = t.string("estimator", ESTIMATORS, default="monte_carlo")
    for key in ("samples_per_level", "p0", "max_levels", "importance_samples"):
        if t.has(key) and key not in ESTIMATOR_KEYS[estimator]:
            raise t.error(key, f"has no effect with estimator = {estimator!r}; remove it or "
                               "choose an estimator that uses it (subset: samples_per_level, "
                               "p0, max_levels; importance: also importance_samples)")
    n = t.integer("samples_per_level", default=1000, minimum=1)
    p0 = t.quantity("p0", "dimensionless", default=0.1)
    if not 0 < p0 <= 0.5:
        raise t.error("p0", f"= {t.data['p0']!r} must be in (0, 0.5]")
    chains = n * p0
    if round(chains) < MIN_CHAINS:
        raise t.error("samples_per_level", f"= {n} gives {chains:g} chains at p0 = {p0:g}; "
                                           f"at least {MIN_CHAINS} are needed "
                                           f"(samples_per_level >= {math.ceil(MIN_CHAINS / p0)})")
    if abs(chains - round(chains)) > 1e-9 * n or n % round(chains):
        raise t.error("samples_per_level", f"= {n} with p0 = {p0:g}: samples_per_level * p0 "
                                           f"= {chains:g} must be a whole number of chains "
                                           "that divides samples_per_level")
    return replace(s, estimator=estimator, samples_per_level=n, p0=float(p0),
                   max_levels=t.integer("max_levels", default=20, minimum=1),
                   importance_samples=t.integer("importance_samples", default=2000,
                                                minimum=2))


def _draw_scope(tolerance) -> str:
    """How a source is drawn: per assembly (rail or carriage), per ball, or a rail field."""
    if tolerance.scope == "rail" and tolerance.correlation_length > 0:
        return f"a rail random field of correlation_length {tolerance.correlation_length:g} m"
    return {"rail": "one value per rail", "carriage": "one value per carriage",
            "ball": "one value per ball"}[tolerance.scope]


def _correlations(root: _Table, tolerances: tuple) -> tuple:
    """The ``[[correlation]]`` groups: validated Gaussian-copula correlation matrices.

    A group correlates sources drawn alike (one scope; rail random fields of one correlation
    length): a value per carriage correlated with a value per rail, or with a field along
    the rail, has no one matrix that describes it.
    """
    if not root.has("correlation"):
        return ()
    root.used.add("correlation")
    raw = root.data["correlation"]
    if not (isinstance(raw, list) and all(isinstance(item, dict) for item in raw)):
        raise root.source.error("correlation", None, "must be an array of tables: start "
                                                     "each group with [[correlation]]")
    given = {t.source: t for t in tolerances}
    owner, out = {}, []
    for number, item in enumerate(raw, 1):
        t = _Table(item, f"correlation[{number}]", root.source)
        sources = t.data.get("sources")
        t.used.add("sources")
        if not (isinstance(sources, list) and len(sources) >= 2
                and all(isinstance(x, str) for x in sources)):
            raise t.error("sources", f"= {sources!r} must be a list of at least two source "
                                     "names")
        for name in sources:
            if name not in SOURCES:
                raise t.error("sources", f"has {name!r}, not a known error source")
            if name not in given:
                raise t.error("sources", f"has {name!r}, which has no [tolerances.{name}]")
            if not given[name].distribution.is_random:
                raise t.error("sources", f"has {name!r}, whose distribution is not random: "
                                         "nothing to correlate")
            if name in owner:
                raise t.error("sources", f"has {name!r} again (already in correlation"
                                         f"[{owner[name]}]): put sources correlated with "
                                         "each other in one matrix")
            owner[name] = number
        scopes = {_draw_scope(given[name]) for name in sources}
        if len(scopes) > 1:
            raise t.error("sources", "mixes sources drawn as " + " and ".join(sorted(scopes))
                          + ": a group's sources must be drawn alike (one scope; rail fields "
                          "of one correlation_length)")
        n = len(sources)
        if t.has("coefficient") == t.has("matrix"):
            raise t.error("coefficient", "or matrix: give exactly one (a coefficient for "
                                         "every pair, or the full matrix)")
        if t.has("coefficient"):
            rho = t.quantity("coefficient", "dimensionless")
            matrix = [[1.0 if i == j else rho for j in range(n)] for i in range(n)]
            key = "coefficient"
        else:
            key = "matrix"
            matrix = t.data["matrix"]
            t.used.add(key)
            if not (isinstance(matrix, list) and len(matrix) == n and all(
                    isinstance(row, list) and len(row) == n for row in matrix)):
                raise t.error(key, f"must be {n} x {n} (one row per source), got {matrix!r}")
            matrix = [[float(t._number(key, v)) for v in row] for row in matrix]
        problem = correlation_matrix_problem(matrix)
        if problem:
            raise t.error(key, problem)
        t.finish()
        out.append(Correlation(tuple(sources), tuple(tuple(row) for row in matrix)))
    return tuple(out)


def parse_config(text: str, path: str = "<string>") -> StudyConfig:
    """Validate a study given as TOML text.

    Parameters
    ----------
    text : str
        The TOML document.
    path : str
        Name used in error messages.

    Returns
    -------
    StudyConfig

    Raises
    ------
    ConfigError
        One line: ``path:line: section.key problem``.
    """
    source = _Source(text, path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = " ".join(str(exc).split())
        at = re.search(r" \(at line (\d+), column (\d+)\)$", message)
        if at:  # "path:line: ..." like every other config error
            message = f"{message[: at.start()]} (column {at.group(2)})"
            path = f"{path}:{at.group(1)}"
        raise ConfigError(f"{path}: invalid TOML: {message}") from None
    if "sweep" not in data:
        return _build(data, source, text, path)
    # a what-if sweep (issue 14): the base study, then one complete config per point
    from tolsim.io.sweep import parse_sweep

    base = {key: value for key, value in data.items() if key != "sweep"}
    config = _build(base, source, text, path)
    sweep = parse_sweep(_Table(data["sweep"], "sweep", source), base,
                        lambda point: _build(point, source, text, path))
    return replace(config, sweep=sweep)


def _build(data: dict, source: "_Source", text: str, path: str) -> StudyConfig:
    """The StudyConfig of a parsed TOML document (``data``); errors name ``source``'s lines."""
    root = _Table(data, "", source)
    bearing = _bearing(root.table("bearing"))
    motion = _motion(root.table("motion"))
    carriage = None
    if root.has("carriage"):  # loads from [carriage.load]; [train] optional
        if root.has("loads"):
            raise source.error("loads", None, "section beside [carriage]: a carriage takes "
                                              "its loads from [carriage.load]; remove [loads]")
        carriage = _carriage(root.table("carriage"), bearing)
        layout = carriage.layout
        if root.has("train"):
            train = _train(root.table("train"), bearing)
            if train.balls != layout.balls_per_track:
                raise source.error("train", "balls", f"= {train.balls} but "
                                   f"carriage.balls_per_track = {layout.balls_per_track}")
        else:  # the balls of one track at the nominal pitch
            gap = max(layout.ball_pitch - 2.0 * bearing.ball_radius, 0.0)
            train = Train(balls=layout.balls_per_track,
                          initial_gap=Distribution(kind="fixed", value=gap),
                          loaded_zone_length=max(layout.balls_per_track * layout.ball_pitch,
                                                 2.0 * bearing.ball_radius))
        loads = None
    else:
        train = _train(root.table("train"), bearing)
        loads = _loads(root.table("loads"), train, bearing)
    tolerances = _tolerances(root.table("tolerances", required=False), bearing)
    correlations = _correlations(root, tolerances)
    study_table = root.table("study")
    study = _study(study_table)
    if carriage is not None:  # the carriage solve is the static model of its balls
        given = study_table.data.get("static_model")
        if given not in (None, "solved"):
            raise study_table.error("static_model", f"= {given!r}: a study with a [carriage] "
                                    "solves every ball with the carriage (elastic, "
                                    "displacement-controlled); remove the key or set 'solved'")
        study = replace(study, static_model="solved")
        _carriage_propagation(_Table(data["carriage"], "carriage", source), carriage, train,
                              study_table, study)
    contact = None
    if root.has("contact"):  # after contact: trains and friction (issue 13)
        contact = _contact(root.table("contact"))
        if not bearing.friction_coefficient > 0:
            raise source.error("bearing", "friction_coefficient", "= 0: a study with [contact] "
                               "needs raceway friction (> 0) to carry the balls' pushes")
    allocation = None
    if root.has("allocate"):  # read by `tolsim allocate` (issue 14); `tolsim run` ignores it
        from tolsim.io.allocation import parse_allocation

        allocation = parse_allocation(root.table("allocate"), tolerances)
    for key in data:
        if key not in root.used:
            raise source.error(key, None, "is not a known section (bearing, motion, train, "
                                          "loads, carriage, tolerances, correlation, study, "
                                          "contact, sweep, allocate)")
    config = StudyConfig(bearing, motion, train, loads, tolerances, study, text, path,
                         correlations, carriage, contact, allocation)
    if study.estimator != "monte_carlo":  # a rare-event estimator needs a limit state
        from tolsim.study.analyses.limit_state import check_supported

        try:
            check_supported(config)
        except ValueError as exc:
            raise study_table.error("estimator", str(exc).removeprefix("estimator ")) from None
    return config


def default_config_text() -> str:
    """The TOML text of the packaged default study (``tolsim/data/default.toml``)."""
    return resources.files("tolsim").joinpath("data/default.toml").read_text(encoding="utf-8")


def load_config(path=None) -> StudyConfig:
    """Read and validate a study config file (the packaged default when ``path`` is None).

    Raises
    ------
    ConfigError
        For a missing or unreadable file or any invalid content (one line, names the key).
    """
    if path is None:
        return parse_config(default_config_text(), "default.toml")
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.__class__.__name__}: "
                          f"{getattr(exc, 'strerror', None) or exc}") from None
    return parse_config(text, str(path))
