"""The section readers of a study config (``[bearing]``, ``[motion]``, ``[train]``, ``[loads]``,
``[carriage]``, ``[tolerances]``, ``[[correlation]]``, ``[study]``, ``[contact]``): each
reads its :class:`~tolsim.io.config.reader.Table` into the frozen dataclasses of
:mod:`tolsim.study.spec`, values in SI; :func:`tolsim.io.config.parse_config` combines them.
"""

import csv
import hashlib
import io
import math
from collections import OrderedDict
from contextvars import ContextVar
from dataclasses import replace
from pathlib import Path

import numpy as np

from tolsim.io.config.plausibility import (
    RANGES,
    check_carriage_load,
    check_count,
    check_hertz_pressure,
    check_quantity,
    check_value,
)
from tolsim.io.config.reader import UNITS, Table, show
from tolsim.physics.carriage import CarriageLayout, CarriageLoad
from tolsim.physics.geometry import Bearing
from tolsim.study.analyses.rare_events import MIN_CHAINS
from tolsim.study.pipeline.propagation_rules import MAX_TIME_STEPS
from tolsim.study.spec import (
    CREEP_MODELS,
    DISTRIBUTIONS,
    ESTIMATORS,
    MAX_SEED,
    PLAUSIBLE_NORMAL_RANGE,
    PROPAGATIONS,
    SAMPLINGS,
    SCOPES,
    SOURCES,
    STATIC_MODELS,
    VELOCITY_MODELS,
    Carriage,
    Circuit,
    ContactSettings,
    Correlation,
    Distribution,
    Loads,
    Motion,
    StudySettings,
    Tolerance,
    Train,
    correlation_matrix_problem,
)

#: Fewest measured values an ``empirical`` distribution accepts.
MIN_EMPIRICAL_VALUES = 10
#: Largest std of a ``truncated_normal`` per unit of its band's width (high - low). Wider,
#: the density varies across the band by less than 1 part in 1e12 (a uniform distribution),
#: and the band's probability, about 0.4 (high - low) / std, is the difference of two
#: numbers near 0.5: at 1e6 its rounding is 3e-10 of it, at 1e300 it was 0 (NaN draws).
MAX_TRUNCATED_STD_PER_BAND = 1e6


def _distribution(table: Table, kind: str) -> Distribution:
    """Read a distribution table; values in SI of the quantity ``kind``."""
    name = table.string("distribution", DISTRIBUTIONS)
    q = lambda key, **kw: table.quantity(key, kind, **kw)  # noqa: E731
    if name == "fixed":
        d = Distribution("fixed", value=q("value"))
    elif name == "normal":
        d = Distribution("normal", mean=q("mean", default=0.0), std=q("std", minimum=0.0))
    elif name == "uniform":
        low, high = q("low"), q("high")
        _check_order(table, kind)
        d = Distribution("uniform", low=low, high=high)
    elif name == "truncated_normal":
        mean, std = q("mean", default=0.0), q("std", positive=True)
        low, high = q("low"), q("high")
        _check_order(table, kind)
        if std > MAX_TRUNCATED_STD_PER_BAND * (high - low):
            std_key = table.key_for("std", kind)
            raise table.error(std_key, f"= {table.data[std_key]!r} is more than "
                                       f"{MAX_TRUNCATED_STD_PER_BAND:.0e} times the band "
                                       f"{table.key_for('high', kind)} - "
                                       f"{table.key_for('low', kind)}: the distribution is "
                                       f"uniform on the band then (write distribution = "
                                       f"\"uniform\")")
        d = Distribution("truncated_normal", mean=mean, std=std, low=low, high=high)
    elif name == "cpk":
        low, high = q("low"), q("high")
        _check_order(table, kind)
        mean = q("mean", default=0.5 * (low + high))
        if not low < mean < high:
            mean_key = table.key_for("mean", kind)
            raise table.error(mean_key, f"= {table.data[mean_key]!r} must lie inside the "
                                        f"band ({table.key_for('low', kind)} to "
                                        f"{table.key_for('high', kind)})")
        cpk = table.quantity("cpk", "dimensionless", positive=True)
        std = min(high - mean, mean - low) / (3.0 * cpk)
        d = Distribution("cpk", mean=mean, std=std, low=low, high=high, cpk=cpk,
                         truncate=table.boolean("truncate"))
    else:  # empirical
        d = _empirical(table, kind)
    return d


def _check_order(table: Table, kind: str):
    """Raise unless the ``high`` of a distribution table exceeds its ``low`` (as written)."""
    high_key, low_key = table.key_for("high", kind), table.key_for("low", kind)
    high = table.quantity("high", kind)
    low = table.quantity("low", kind)
    if not high > low:
        raise table.error(high_key, f"= {table.data[high_key]!r} must be greater than "
                                    f"{low_key} = {table.data[low_key]!r}")


#: While a config's text is read back (:func:`tolsim.io.config.text_mismatch`): {data file as
#: written: SHA-256} of the data that config was read with. Such a file's bytes are taken from
#: :data:`_DATA_READ` by their SHA-256, not from the disk, which may have changed since (or be
#: out of reach: another working directory).
READ_BACK: ContextVar = ContextVar("tolsim_config_read_back", default=None)
#: The bytes of the data files read in this process, by SHA-256 (the latest 64 files).
_DATA_READ: OrderedDict = OrderedDict()


def _empirical(table: Table, kind: str) -> Distribution:
    """Measured values from a CSV column: ``file``, ``column_<unit>``, optional ``sha256``."""
    file = table.text("file")
    column_key, factor = table.unit_key("column", kind)
    column = table.text(column_key)
    path = Path(file)
    if not path.is_absolute():  # relative to the config file (a string config: to the cwd)
        path = Path(table.source.path).parent / path
    raw = _DATA_READ.get((READ_BACK.get() or {}).get(file))
    if raw is None:
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise table.error("file", f"= {file!r}: cannot read {path}: "
                                      f"{exc.strerror or exc.__class__.__name__}") from None
    sha256 = hashlib.sha256(raw).hexdigest()
    _DATA_READ[sha256] = raw
    _DATA_READ.move_to_end(sha256)
    while len(_DATA_READ) > 64:
        _DATA_READ.popitem(last=False)
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


def _check_range(table: Table, source: str, kind: str, dist: Distribution, bearing):
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
    name = _reach_name(dist, edge, limit)
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


def _reach_name(dist: Distribution, edge: str, limit: float) -> str:
    """The key (without its unit) that sets how far ``dist`` reaches at its ``edge`` (low
    or high), for a message about its reach beyond ``limit``."""
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
    return name


def read_bearing(t: Table) -> Bearing:
    diameter = t.quantity("ball_diameter", "length", positive=True)
    check_quantity(t, "ball_diameter", "length", diameter, "bearing.ball_diameter")
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
    kinds = {"conformity": "dimensionless", "nominal_contact_angle": "angle",
             "youngs_modulus": "pressure", "poisson_ratio": "dimensionless",
             "friction_coefficient": "dimensionless"}
    for name, kind in kinds.items():  # the ranges hold those of Bearing
        check_quantity(t, name, kind, values[name], f"bearing.{name}")
    try:
        return Bearing(**values)
    except ValueError as exc:  # a default outside Bearing's range cannot happen: say so
        raise t.error(None, " ".join(str(exc).split())) from None


def read_motion(t: Table) -> Motion:
    v = t.quantity("groove_velocity", "velocity", positive=True)
    check_quantity(t, "groove_velocity", "velocity", v, "motion.groove_velocity")
    has_stroke = any(t.has(f"stroke_{u}") for u in UNITS["length"])
    has_duration = any(t.has(f"duration_{u}") for u in UNITS["time"])
    if has_stroke and has_duration:
        raise t.error(t.key_for("stroke", "length"), "given together with duration: use one")
    if has_stroke:
        stroke = t.quantity("stroke", "length", positive=True)
        check_quantity(t, "stroke", "length", stroke, "motion.stroke")
        duration = stroke / v
    else:  # the stroke's range at this speed
        duration = t.quantity("duration", "time", positive=True)
        check_quantity(t, "duration", "time", duration, "motion.duration", 1.0 / v)
    t.finish()
    return Motion(groove_velocity=v, duration=duration)


def read_train(t: Table, bearing: Bearing) -> Train:
    balls = t.integer("balls", minimum=1)
    check_count(t, "balls", balls, "train.balls")
    gap_table = t.table("initial_gap")
    gap = _distribution(gap_table, "length")
    gap_table.finish()

    def gap_error(name, value):
        key = gap_table.key_for(name, "length")
        unit, factor = gap_table.unit_of(key, "length")
        shown = repr(gap_table.data[key])
        if name == "column":
            shown = f"{gap_table.data[key]!r} holds {show(value / factor)} {unit}"
        return gap_table.error(key, f"= {shown}: gaps must be >= 0 (balls cannot overlap)")

    if gap.kind == "fixed" and gap.value < 0:
        raise gap_error("value", gap.value)
    if gap.kind in ("uniform", "truncated_normal") and gap.low < 0:
        raise gap_error("low", gap.low)
    if gap.kind == "empirical" and gap.data[0] < 0:
        raise gap_error("column", gap.data[0])
    diameter = 2.0 * bearing.ball_radius
    name = _reach_name(gap, "high", diameter * RANGES["train.initial_gap"].usual_high)
    check_value(gap_table, name if name == "cpk" else gap_table.key_for(name, "length"),
                "length", gap.support[1], "train.initial_gap", diameter)
    pitch = diameter + max(gap.expected, 0.0)
    length = t.quantity("loaded_zone_length", "length", default=balls * pitch, positive=True)
    length_key = t.key_for("loaded_zone_length", "length")
    if length_key in t.data and length < balls * diameter * (1.0 - 1e-12):
        unit, factor = t.unit_of(length_key, "length")
        raise t.error(length_key, f"= {t.data[length_key]!r} is shorter than the "
                                  f"{balls} balls in it ({show(balls * diameter / factor)} "
                                  f"{unit}): they would overlap")
    t.finish()
    return Train(balls=balls, initial_gap=gap, loaded_zone_length=length)


def read_loads(t: Table, train: Train, bearing: Bearing) -> Loads:
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
    parts = {t.key_for("normal_load", "force"): normal}  # what drives the ball forces
    if has_ratio:
        ratio = t.quantity("side_force_ratio", "dimensionless", allow_list=True)
        side = normal * per_ball(ratio, "side_force_ratio")
        parts["side_force_ratio"] = side
    else:
        total = t.quantity("side_load", "force", default=0.0, allow_list=True)
        side = per_ball(total, "side_load_<unit>")
        if has_side:
            parts[t.key_for("side_load", "force")] = side
    yaw = t.quantity("yaw_moment", "moment", default=0.0)
    if yaw:
        z = train.slot_positions(2.0 * bearing.ball_radius)
        if n < 2:
            raise t.error("yaw_moment_<unit>", "needs train.balls >= 2")
        side = side + yaw * z / np.sum(z * z)
        parts[t.key_for("yaw_moment", "moment")] = yaw * z / np.sum(z * z)
    t.finish()
    check_hertz_pressure(t, normal, side, bearing, parts)
    return Loads(normal_load=tuple(map(float, normal)), side_load=tuple(map(float, side)),
                 yaw_moment=float(yaw))


def read_carriage(t: Table, bearing: Bearing) -> Carriage:
    """``[carriage]``, ``[carriage.load]`` and ``[[carriage.track]]`` (tolsim issue 12)."""
    n = t.integer("balls_per_track", minimum=1)
    check_count(t, "balls_per_track", n, "carriage.balls_per_track")
    pitch = t.quantity("ball_pitch", "length")
    pitch_key = t.key_for("ball_pitch", "length")
    if pitch < 0:
        raise t.error(pitch_key, f"= {t.data[pitch_key]!r} must be >= 0")
    diameter = 2.0 * bearing.ball_radius
    if n > 1 and pitch < diameter * (1.0 - 1e-12):
        raise t.error(pitch_key, f"= {t.data[pitch_key]!r} is less than the ball diameter "
                                 f"({diameter * 1e3:g} mm): neighbouring balls would overlap")
    if n > 1:
        check_quantity(t, "ball_pitch", "length", pitch, "carriage.ball_pitch", diameter)
    preload = t.quantity("preload_oversize", "length", default=0.0)
    limit = 0.25 * (bearing.groove_radius - bearing.ball_radius)
    if abs(preload) > limit:
        key = t.key_for("preload_oversize", "length")
        unit, factor = t.unit_of(key, "length")
        raise t.error(key, f"= {t.data[key]!r} {unit} is outside the possible range "
                           f"[{show(-limit / factor)}, {show(limit / factor)}] {unit} (a "
                           "quarter of the ball-groove centre distance, the static model's "
                           "range): is the unit right?")
    check_quantity(t, "preload_oversize", "length", preload, "carriage.preload_oversize")
    # end relief (crowning) of the carriage grooves; the length is checked against the
    # loaded zone in parse_config, once [train] is read
    relief_depth = t.quantity("end_relief_depth", "length", default=0.0, minimum=0.0)
    relief_length = t.quantity("end_relief_length", "length", default=0.0, minimum=0.0)
    depth_key = t.key_for("end_relief_depth", "length")
    length_key = t.key_for("end_relief_length", "length")
    if relief_depth > limit:
        unit, factor = t.unit_of(depth_key, "length")
        raise t.error(depth_key, f"= {t.data[depth_key]!r} {unit} is outside the possible "
                                 f"range [0, {show(limit / factor)}] {unit} (a quarter of the "
                                 "ball-groove centre distance): is the unit right?")
    if relief_depth > 0 and not relief_length > 0:
        raise t.error(depth_key, "needs end_relief_length_<unit> > 0 (the relieved length at "
                                 "each end of the loaded zone)")
    if relief_length > 0 and not relief_depth > 0:
        raise t.error(length_key, "has no effect without end_relief_depth_<unit> > 0")

    circuit_table = t.table("circuit", required=False)
    circuit = None if circuit_table is None else read_circuit(circuit_table, bearing)

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
        tr = Table(item, f"{t.name}.track[{number}]", t.source)
        xs.append(tr.quantity("x", "length"))
        ys.append(tr.quantity("y", "length", default=0.0))
        phis.append(tr.quantity("orientation", "angle"))
        for name, kind, value in (("x", "length", xs[-1]), ("y", "length", ys[-1]),
                                  ("orientation", "angle", phis[-1])):
            check_quantity(tr, name, kind, value, f"carriage.track.{name}")
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
            raise t.error(key, f"gives a ball oversize of {show((preload + value) * 1e6)} um, "
                               f"outside the possible range [{show(-limit * 1e6)}, "
                               f"{show(limit * 1e6)}] um (a quarter of the ball-groove centre "
                               "distance, the static model's range)")
    t.finish()
    try:
        layout = CarriageLayout(np.array(xs), np.array(ys), np.array(phis), n, pitch)
    except ValueError as exc:
        raise t.error(None, " ".join(str(exc).split())) from None
    if load_table is not None:
        check_carriage_load(load_table, load, layout, bearing)
    return Carriage(layout=layout, load=load, preload_oversize=preload,
                    ball_oversize_deviation=tuple(map(float, deviation)),
                    end_relief_depth=relief_depth, end_relief_length=relief_length,
                    circuit=circuit)


def read_circuit(t: Table, bearing: Bearing) -> Circuit:
    """``[carriage.circuit]`` (issue 24): balls per circuit, its total clearance and the drag
    of an unloaded ball; a key left out takes the default of :class:`Circuit`."""
    default = Circuit()
    balls = t.integer("balls", default=default.balls, minimum=2)
    check_count(t, "balls", balls, "carriage.circuit.balls")
    slack = t.quantity("slack", "length", default=default.slack, minimum=0.0)
    check_quantity(t, "slack", "length", slack, "carriage.circuit.slack",
                   2.0 * bearing.ball_radius)
    drag = t.quantity("return_drag", "force", default=default.return_drag, minimum=0.0)
    check_quantity(t, "return_drag", "force", drag, "carriage.circuit.return_drag")
    t.finish()
    return Circuit(balls=balls, slack=slack, return_drag=drag)


def check_carriage_propagation(t: Table, carriage: Carriage, train: Train, study_table: Table,
                          study: StudySettings):
    """Raise for what a [carriage] study cannot combine with its propagation: end relief
    without along_track or longer than half the loaded zone; one ball per track, fixed
    per-ball oversizes with along_track (the default of a [carriage] study, so the message
    says how to choose constant when ``study_table`` does not name the propagation)."""
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
    # along_track by default (issue 24): say how to keep the constant propagation
    hint = ("" if "propagation" in study_table.data else
            " (along_track is a [carriage] study's default; study.propagation = 'constant' "
            "keeps each ball's starting epsilon)")
    if carriage.layout.balls_per_track < 2:
        raise t.error("balls_per_track", "= 1: with propagation = 'along_track' a track needs "
                                         "at least 2 balls (one ball cannot hold the "
                                         "carriage's pitch and yaw as it rolls)" + hint)
    if carriage.ball_oversize_deviation:
        raise t.error(t.key_for("ball_oversize_deviation", "length"),
                      "fixes the size of the balls at their slots, but with propagation = "
                      "'along_track' the balls roll through the carriage: give the size "
                      "scatter as [tolerances.ball_oversize] instead" + hint)


def check_circuit(t: Table, carriage: Carriage, train: Train, study: StudySettings,
                  bearing: Bearing):
    """Raise for a ``[carriage.circuit]`` (``t``) a study cannot run: without along_track, or
    with no more balls than the loaded zone holds."""
    circuit = carriage.circuit
    if study.propagation != "along_track":
        raise t.error(None, "moves the balls round their circuit: it needs "
                            "study.propagation = 'along_track'")
    diameter = 2.0 * bearing.ball_radius
    holds = max(int(np.floor(train.loaded_zone_length / diameter * (1 + 1e-12))) + 1,
                train.balls)
    if circuit.balls <= holds:
        raise t.error("balls", f"= {circuit.balls} is not more than the loaded zone holds "
                               f"({holds} balls of {diameter * 1e3:g} mm in "
                               f"{train.loaded_zone_length * 1e3:g} mm)")


def read_tolerances(t: Table | None, bearing: Bearing) -> tuple:
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
        if corr:
            check_quantity(sub, "correlation_length", "length", corr,
                           "tolerances.correlation_length", 2.0 * bearing.ball_radius)
        sub.finish()
        out.append(Tolerance(source, dist, scope, corr))
    t.finish()
    return tuple(out)


#: Keys that were plain fractions and now carry a unit (``_percent`` or ``_ppm``).
FRACTION_KEYS = ("velocity_deviation_range", "velocity_deviation_limit",
                 "contact_probability_limit", "out_of_spec_limit")


def read_contact(t: Table) -> ContactSettings:
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
    check_quantity(t, "ball_friction_coefficient", "dimensionless",
                   s.ball_friction_coefficient, "contact.ball_friction_coefficient")
    t.finish()
    return s


def _time_steps(t):
    """``study.time_steps``: an integer >= 1, or ``"auto"`` (the default): None, the count
    then chosen by :func:`tolsim.study.pipeline.propagation_rules.time_steps`."""
    if t.data.get("time_steps", "auto") == "auto":
        t.used.add("time_steps")
        return None
    if isinstance(t.data["time_steps"], str):
        raise t.error("time_steps", f'= {t.data["time_steps"]!r} must be "auto" or an integer '
                                    f"from 1 to {MAX_TIME_STEPS}")
    return t.integer("time_steps", minimum=1, maximum=MAX_TIME_STEPS)


def read_study(t: Table) -> StudySettings:
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
        seed=t.integer("seed", minimum=0, maximum=MAX_SEED),
        block_size=t.integer("block_size", default=1024, minimum=1),
        velocity_model=t.string("velocity_model", VELOCITY_MODELS, default="analytic"),
        static_model=t.string("static_model", STATIC_MODELS, default="paired"),
        propagation=t.string("propagation", PROPAGATIONS, default="constant"),
        sampling=t.string("sampling", SAMPLINGS, default="random"),
        spot_checks=t.integer("spot_checks", default=0, minimum=0),
        time_steps=_time_steps(t),
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


#: Keys of ``[study]`` read by each rare-event estimator (importance falls back to subset;
#: rare runs both).
ESTIMATOR_KEYS = {"monte_carlo": (), "subset": ("samples_per_level", "p0", "max_levels"),
                  "importance": ("samples_per_level", "p0", "max_levels", "importance_samples"),
                  "rare": ("samples_per_level", "p0", "max_levels", "importance_samples")}


def _estimator(t: Table, s: StudySettings) -> StudySettings:
    """``[study] estimator`` and its settings (issue 15;
    :mod:`tolsim.study.analyses.limit_state`)."""
    estimator = t.string("estimator", ESTIMATORS, default="monte_carlo")
    for key in ("samples_per_level", "p0", "max_levels", "importance_samples"):
        if t.has(key) and key not in ESTIMATOR_KEYS[estimator]:
            raise t.error(key, f"has no effect with estimator = {estimator!r}; remove it or "
                               "choose an estimator that uses it (subset: samples_per_level, "
                               "p0, max_levels; importance and rare: also "
                               "importance_samples)")
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


def read_correlations(root: Table, tolerances: tuple) -> tuple:
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
        t = Table(item, f"correlation[{number}]", root.source)
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
        asymmetric = next(((i, j) for i in range(n) for j in range(i) if matrix[i][j]
                           != matrix[j][i]), None)
        if asymmetric:  # said here with the numbers as written (no numpy reprs)
            i, j = asymmetric
            raise t.error(key, f"must be symmetric: [{i}][{j}] = {show(matrix[i][j])} but "
                               f"[{j}][{i}] = {show(matrix[j][i])}")
        problem = correlation_matrix_problem(matrix)
        if problem:
            raise t.error(key, problem)
        t.finish()
        out.append(Correlation(tuple(sources), tuple(tuple(row) for row in matrix)))
    return tuple(out)
