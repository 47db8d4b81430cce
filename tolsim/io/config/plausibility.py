"""Plausibility of the physical keys of a study config: one table of ranges, with sources.

Each :class:`Range` has a *possible* interval (outside it the value cannot describe a linear
ball guide, or the model does not hold: a :class:`~tolsim.io.config.reader.ConfigError`) and
a *usual* one (outside it the value is possible but unusual, often a unit slip: a
:class:`~tolsim.io.config.reader.ConfigWarning`). Both messages are one line with the file,
the line, the key, the value and the interval in the unit the user wrote, e.g.::

    study.toml:3: bearing.ball_diameter_m = 10 is outside the possible range 0.0003 to
    0.105 m (ISO 3290-1 ball sizes ...)

Ranges given per ball diameter (gaps, pitch) are scaled by the config's ball. The section
readers (:mod:`tolsim.io.config.sections`) call :func:`check_quantity` on every physical key
as they read it, and check the spreads of the tolerance sources against the static model's
range themselves; the loads are checked against the Hertz pressure limit by
:func:`check_hertz_pressure` (``[loads]``) and :func:`check_carriage_load` (``[carriage]``).
"""

import math
from dataclasses import dataclass

import numpy as np

from tolsim.io.config.reader import Table, show
from tolsim.physics.carriage import uncarried_motions
from tolsim.physics.geometry import CONTACTS, Bearing, paired_forces
from tolsim.physics.hertz import hertz_constants

#: Largest Hertz pressure of a ball/groove contact [Pa]. ISO 76 and ISO 14728-2 base the
#: static load rating of ball bearings and linear ball guides on 4 200 MPa at the centre of
#: the most heavily loaded contact (a permanent deformation of about 1e-4 of the ball
#: diameter); beyond it the elastic (Hertz) contact model of tolsim no longer holds.
MAX_HERTZ_PRESSURE = 4200e6


@dataclass(frozen=True)
class Range:
    """Possible and usual values of one config quantity, in SI (or per ``per``).

    Attributes
    ----------
    low, high : float or None
        The possible interval (None: unbounded); ``open_low`` / ``open_high`` exclude the end.
    usual_low, usual_high : float or None
        The usual interval, inside the possible one (None: the possible end).
    source : str
        Where the interval comes from, shown in the messages.
    per : str
        What the values are multiples of (``"ball diameter"``), or "" for SI values.
    """

    low: float | None
    high: float | None
    usual_low: float | None = None
    usual_high: float | None = None
    source: str = ""
    open_low: bool = False
    open_high: bool = False
    per: str = ""

    def scaled(self, factor: float) -> "Range":
        """The range in SI for a reference value ``factor`` (a ball diameter, 1 / speed)."""

        def f(x):
            return None if x is None else x * factor
        return Range(f(self.low), f(self.high), f(self.usual_low), f(self.usual_high),
                     self.source, self.open_low, self.open_high)

    def possible(self, value: float) -> bool:
        """``value`` (SI) lies in the possible interval."""
        lo_ok = self.low is None or (value > self.low if self.open_low else value >= self.low)
        hi_ok = self.high is None or (value < self.high if self.open_high
                                      else value <= self.high)
        return lo_ok and hi_ok

    def usual(self, value: float) -> bool:
        """``value`` (SI) lies in the usual interval."""
        return ((self.usual_low is None or value >= self.usual_low)
                and (self.usual_high is None or value <= self.usual_high))


MM, UM, DEG, GPA = 1e-3, 1e-6, math.pi / 180.0, 1e9

#: The ranges, by config key (without its unit suffix). SI unless ``per`` says otherwise.
RANGES = {
    # ISO 3290-1 (rolling bearing balls) lists nominal diameters from 0.3 mm to 104.775 mm
    # (4 1/8 in); linear guides of catalogue sizes 5 to 65 (THK, HIWIN, Bosch Rexroth, NSK)
    # run balls of about 1 mm to 25.4 mm (1 in).
    "bearing.ball_diameter": Range(0.3 * MM, 104.775 * MM, 1.0 * MM, 25.4 * MM,
                                   "ISO 3290-1 ball sizes; linear guides 1 to 25.4 mm"),
    # f = R_G / D > 0.5 or the ball does not fit its groove (and the Hertz curvature across
    # the groove vanishes); f = 1 is a groove radius of a whole ball diameter, an almost flat
    # flank. Ball bearings and linear guides use 0.51 to 0.56 (Harris & Kotzalas, Rolling
    # Bearing Analysis, Sec. 2.3; catalogue gothic-arch grooves 0.52 to 0.54).
    "bearing.conformity": Range(0.5, 1.0, 0.505, 0.6, "groove radius / ball diameter: > 0.5 "
                                "for the ball to fit, 0.51 to 0.56 in catalogues",
                                open_low=True),
    # 0 < beta_0 < 90 deg for contacts on both flanks; four-point (gothic-arch) guides use
    # 45 deg, two-row designs 30 to 50 deg (catalogues).
    "bearing.nominal_contact_angle": Range(0.0, 90.0 * DEG, 30.0 * DEG, 60.0 * DEG,
                                           "four-point contact needs 0 < beta_0 < 90 deg; "
                                           "catalogues 30 to 60 deg",
                                           open_low=True, open_high=True),
    # No solid is stiffer than diamond (about 1 050 GPa); rolling-bearing steels (100Cr6,
    # 440C) have 200 to 215 GPa, silicon-nitride balls about 310 GPa (ISO 683-17; ASTM
    # F2094). Below 1 GPa (polymers at most a few GPa) a steel contact model is wrong.
    "bearing.youngs_modulus": Range(1.0 * GPA, 1200.0 * GPA, 150.0 * GPA, 350.0 * GPA,
                                    "stiffer than diamond is impossible; bearing steels "
                                    "200 to 215 GPa, ceramic balls about 310 GPa"),
    # Thermodynamics bounds an isotropic Poisson ratio to (-1, 0.5); steels 0.27 to 0.30,
    # silicon nitride 0.26.
    "bearing.poisson_ratio": Range(-1.0, 0.5, 0.2, 0.35, "isotropic solids -1 to 0.5; "
                                   "steels 0.27 to 0.30", open_low=True, open_high=True),
    # Coulomb coefficients of steel on steel: about 0.6 dry and clean, 0.05 to 0.15 with
    # boundary lubrication (Machinery's Handbook, friction tables); a sliding contact above
    # 1 would need adhesion (clean metals in vacuum), not a lubricated guide.
    "bearing.friction_coefficient": Range(0.0, 1.0, 0.0, 0.3, "steel on steel: about 0.1 "
                                          "lubricated, 0.6 dry"),
    "contact.ball_friction_coefficient": Range(0.0, 1.0, 0.0, 0.3, "steel on steel: about "
                                              "0.1 lubricated, 0.6 dry"),
    # Catalogue speed limits of ball guides: 3 to 5 m/s (THK SHS/SSR 3 m/s, HIWIN HG 5 m/s);
    # linear-motor axes reach about 10 m/s. Below 1 mm/s a ball barely rolls.
    "motion.groove_velocity": Range(0.0, 10.0, 1.0 * MM, 5.0, "ball guides run at most 3 "
                                    "to 5 m/s (catalogues), linear-motor axes about 10 m/s",
                                    open_low=True),
    # Rails come in one piece up to about 4 to 6 m and are butted to longer axes; 100 m of
    # travel in one stroke is beyond any machine.
    "motion.stroke": Range(0.0, 100.0, None, 6.0, "one-piece rails are at most about 4 to "
                           "6 m long", open_low=True),
    # The same limits on the travel v T of a stroke given as a duration T (per 1 / v).
    "motion.duration": Range(0.0, 100.0, None, 6.0, "a stroke of at most 100 m, usually "
                             "6 m, at the groove velocity", open_low=True,
                             per="metres of stroke at the groove velocity"),
    # A gap between neighbouring balls of a full-complement train: the balls' total
    # clearance in a circuit is less than one ball, or another ball would be inserted; caged
    # (spacer) designs keep about 0.2 to 0.5 D between balls, full-complement ones a few
    # hundredths of D ([Lin2018]: 0.05 D).
    "train.initial_gap": Range(0.0, 1.0, 0.0, 0.1, "no wider than one ball, or another ball "
                               "would fit; full-complement trains a few hundredths of it",
                               per="ball diameter"),
    # Balls per track in the loaded zone: 5 to 30 in catalogue carriages (long blocks of
    # size 65 about 40).
    "train.balls": Range(1, 1000, 1, 60, "catalogue carriages have 5 to 40 balls per track"),
    "carriage.balls_per_track": Range(1, 1000, 1, 60, "catalogue carriages have 5 to 40 "
                                      "balls per track"),
    # The pitch of the balls in a track: at least a ball diameter (they would overlap), 1.0
    # to 1.05 D full-complement, up to about 1.5 D with spacers or cages.
    "carriage.ball_pitch": Range(1.0, 10.0, 1.0, 2.0, "at least one ball diameter; "
                                 "catalogues 1.0 to 1.5", per="ball diameter"),
    # Diametral oversize of the balls (preload class): catalogue classes run from a clearance
    # of a few um to heavy preload of about 8 um (THK/HIWIN preload tables for sizes 15 to
    # 45); the hard limit is the static model's range (a quarter of the ball-groove centre
    # distance, sections.read_carriage).
    "carriage.preload_oversize": Range(None, None, -10.0 * UM, 10.0 * UM, "catalogue "
                                       "classes: clearance to heavy preload"),
    # Track positions relative to the carriage's reference point: rails are 7 to 100 mm
    # wide; a track 1 m off the centre is no carriage.
    "carriage.track.x": Range(-1.0, 1.0, -0.2, 0.2, "catalogue carriages are at most about "
                              "0.2 m wide"),
    "carriage.track.y": Range(-1.0, 1.0, -0.2, 0.2, "catalogue carriages are at most about "
                              "0.2 m high"),
    "carriage.track.orientation": Range(-360.0 * DEG, 360.0 * DEG, None, None,
                                        "one turn either way"),
    # The recirculating circuit of a track (issue 24): the loaded zone, two turnarounds and a
    # return channel about as long as the zone, so about 2.5 times the loaded balls
    # (catalogue cross-sections; Notes of tolsim.physics.circuit.circuit_length).
    "carriage.circuit.balls": Range(2, 1000, 5, 200, "a circuit holds the loaded zone, two "
                                    "turnarounds and a return channel: about 2.5 times the "
                                    "loaded balls"),
    # A circuit is filled ball by ball until no further ball fits: its total clearance is
    # less than one ball; designers keep it small (0.1 D proposed, 0 to 0.3 D plausible).
    "carriage.circuit.slack": Range(0.0, 1.0, 0.0, 0.3, "less than one ball, or another "
                                    "ball would fit; a small fraction of it by design",
                                    open_high=True, per="ball diameter"),
    # Weight friction of an unloaded ball on the channel wall and grease: 0.004 to 0.05 N
    # for a 10 mm ball (estimate, Notes of tolsim.physics.circuit.circuit_length).
    "carriage.circuit.return_drag": Range(0.0, 10.0, 0.0, 0.2, "weight friction and grease: "
                                          "about 0.004 to 0.05 N per 10 mm ball"),
    # A rail random field's correlation length: a ball meets the groove over its contact
    # ellipse, a few tenths of a millimetre for a 10 mm ball under tens of newtons (its
    # semi-axes: tolsim.physics.hertz), so an error correlated over less than a tenth of the
    # ball is averaged by the contact; ground rails' form errors are waviness of millimetres
    # to metres. The automatic step follows the shortest length (4 steps per length along
    # half the stroke: 200 000 steps for 1 um on a 100 mm stroke, beyond MAX_TIME_STEPS).
    # Possible from 1e-6 D (10 nm for a 10 mm ball): ball centres that far apart already draw
    # independent errors (a constant study's way to say so), and shorter lengths overflowed
    # 1 / length in the worst-case stack-up (a traceback at 1e-320 mm).
    "tolerances.correlation_length": Range(1e-6, None, 0.1, None, "a ball's contact averages "
                                           "errors shorter than about a tenth of the ball, "
                                           "balls 1e-6 D apart draw independent ones; the "
                                           "automatic step count grows as 1 / length",
                                           per="ball diameter"),
}


#: How :func:`range_rows` shows each entry of :data:`RANGES`: (unit, SI per unit); the unit
#: of a relative range (``per``) is the reference itself.
DISPLAY_UNITS = {
    "bearing.ball_diameter": ("mm", MM), "bearing.conformity": ("", 1.0),
    "bearing.nominal_contact_angle": ("deg", DEG), "bearing.youngs_modulus": ("GPa", GPA),
    "bearing.poisson_ratio": ("", 1.0), "bearing.friction_coefficient": ("", 1.0),
    "contact.ball_friction_coefficient": ("", 1.0), "motion.groove_velocity": ("m/s", 1.0),
    "motion.stroke": ("m", 1.0), "motion.duration": ("m of stroke", 1.0),
    "train.initial_gap": ("D", 1.0), "train.balls": ("", 1.0),
    "carriage.balls_per_track": ("", 1.0), "carriage.ball_pitch": ("D", 1.0),
    "carriage.preload_oversize": ("um", UM), "carriage.track.x": ("m", 1.0),
    "carriage.track.y": ("m", 1.0), "carriage.track.orientation": ("deg", DEG),
    "carriage.circuit.balls": ("", 1.0), "carriage.circuit.slack": ("D", 1.0),
    "carriage.circuit.return_drag": ("N", 1.0), "tolerances.correlation_length": ("D", 1.0),
}


#: Possible ranges checked where the key is read, not in :data:`RANGES` (shown by
#: :func:`range_rows`).
POSSIBLE_ELSEWHERE = {
    "carriage.preload_oversize": "[-(f - 1/2) D / 4, (f - 1/2) D / 4] (the static model's "
                                 "range; 100 um for the default 10 mm ball, f = 0.54)",
}


def range_rows() -> list:
    """The table of :data:`RANGES` as text, one row per key: (key, possible, usual, source),
    the intervals in :data:`DISPLAY_UNITS` ("D": ball diameters), and last the Hertz
    pressure limit of the loads. The README's table is this one (a test compares them)."""

    def interval(low, high, open_low, open_high, unit, factor):
        lo = "-inf" if low is None else show(round(low / factor, 12))
        hi = "inf" if high is None else show(round(high / factor, 12))
        unit = f" {unit}" if unit else ""
        return f"{'(' if open_low else '['}{lo}, {hi}{')' if open_high else ']'}{unit}"

    rows = []
    for key, rng in RANGES.items():
        unit, factor = DISPLAY_UNITS[key]
        usual_low = rng.low if rng.usual_low is None else rng.usual_low
        usual_high = rng.high if rng.usual_high is None else rng.usual_high
        possible = POSSIBLE_ELSEWHERE.get(key) or interval(
            rng.low, rng.high, rng.open_low, rng.open_high, unit, factor)
        rows.append((key, possible,
                     interval(usual_low, usual_high, False, False, unit, factor), rng.source))
    rows.append(("[loads], carriage.load", f"Hertz pressure <= {MAX_HERTZ_PRESSURE / 1e6:.0f} "
                 "MPa", "", "ISO 76 / ISO 14728-2 static load rating: beyond it the elastic "
                 "contact model no longer holds"))
    return rows


def ranges_markdown() -> str:
    """:func:`range_rows` as a Markdown table (the README's)."""
    lines = ["| key | possible (error outside) | usual (warning outside) | source |",
             "|---|---|---|---|"]
    lines += [f"| `{key}` | {possible} | {usual} | {source} |"
              for key, possible, usual, source in range_rows()]
    return "\n".join(lines)


def _message(table, key, kind, value_si, rng: Range, possible: bool) -> str:
    """'= 10 m is outside the possible range [0.0003, 0.104775] m (source)': the value and
    the range in the unit the user wrote."""
    unit, factor = "", 1.0
    if kind:  # the unit the user wrote (of this key, or of the table's other keys)
        unit, factor = next((u for u in (table.unit_of(k, kind) for k in (key, *table.data))
                             if u[0]), table.unit_of(key, kind))
    unit_text = f" {unit}" if unit else ""
    raw = table.data.get(key)
    whole = (isinstance(raw, int | float) and not isinstance(raw, bool)
             and math.isclose(raw * factor, value_si, rel_tol=1e-9, abs_tol=0.0))
    if whole:  # the key is the value
        head = f"= {raw!r}{unit_text} is"
    elif isinstance(raw, list):  # one of a list (per ball)
        head = f"has {show(value_si / factor)}{unit_text},"
    else:  # the key sets the value in part (a spread, the end of a band)
        head = f"= {raw!r}: the values reach {show(value_si / factor)}{unit_text},"
    if possible:
        low, high = rng.low, rng.high
        opening, closing = "(" if rng.open_low else "[", ")" if rng.open_high else "]"
        what = "outside the possible range"
    else:
        low = rng.low if rng.usual_low is None else rng.usual_low
        high = rng.high if rng.usual_high is None else rng.usual_high
        opening, closing = "[", "]"
        what = "unusual: outside"
    lo = "-inf" if low is None else show(low / factor)
    hi = "inf" if high is None else show(high / factor)
    ask = ": is the unit right?" if kind else ""
    return f"{head} {what} {opening}{lo}, {hi}{closing}{unit_text} ({rng.source}){ask}"


def check_value(table: Table, key: str, kind: str | None, value_si: float, name: str,
                reference: float = 1.0):
    """Raise for an impossible value of ``table[key]``, warn for an unusual one.

    Parameters
    ----------
    table : Table
        The table that holds the key.
    key : str
        The key as written (``ball_diameter_mm``).
    kind : str or None
        Its quantity (:data:`~tolsim.io.config.reader.UNITS`), None for a count.
    value_si : float
        The value judged, in SI.
    name : str
        Its entry in :data:`RANGES`.
    reference : float
        The SI value a relative range (``per``) is a multiple of.
    """
    rng = RANGES[name]
    if rng.per:
        rng = rng.scaled(reference)
    if not rng.possible(value_si):
        raise table.error(key, _message(table, key, kind, value_si, rng, True))
    if not rng.usual(value_si):
        table.warn(key, _message(table, key, kind, value_si, rng, False))


def check_quantity(table: Table, name: str, kind: str, value_si, entry: str | None = None,
                   reference: float = 1.0):
    """:func:`check_value` of quantity ``name`` (its key with whatever unit the table gives);
    a tuple of values (per ball) is checked value by value, a missing key not at all."""
    key = table.key_for(name, kind)
    if key not in table.data or value_si is None:
        return
    entry = entry or f"{table.name}.{name}"
    for v in (value_si if isinstance(value_si, tuple) else (value_si,)):
        check_value(table, key, kind, v, entry, reference)


def check_count(table: Table, key: str, value: int, entry: str | None = None):
    """:func:`check_value` of an integer key (a number of balls)."""
    if key in table.data:
        check_value(table, key, None, value, entry or f"{table.name}.{key}")


def max_hertz_pressure(forces, bearing: Bearing) -> np.ndarray:
    """Largest Hertz pressure p0 [Pa] of contact forces ``forces`` [N] (negative: 0)."""
    c = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                        bearing.poisson_ratio)
    return c.pressure_coefficient * np.cbrt(np.maximum(np.asarray(forces, dtype=float), 0.0))


def check_hertz_pressure(table: Table, normal_load, side_load, bearing: Bearing,
                         parts: dict):
    """Raise if the paired contact forces of the nominal loads exceed
    :data:`MAX_HERTZ_PRESSURE` at any ball.

    Parameters
    ----------
    table : Table
        ``[loads]``.
    normal_load, side_load : array_like
        N_y and N_x per ball [N].
    bearing : Bearing
    parts : dict
        key as written -> its contribution to the side load per ball (or the normal load),
        to name the key that drives the largest force.

    Notes
    -----
    The forces are the paper's paired approximation
    (:func:`tolsim.physics.geometry.paired_forces`) of the nominal loads; the tolerances
    shift them by a few per cent, which the limit (a rating, not a breaking point) leaves
    room for. A carriage's ball forces need the carriage solve: its load is bounded by
    :func:`check_carriage_load` instead.
    """
    forces = paired_forces(side_load, normal_load, bearing.nominal_contact_angle)
    pressure = max_hertz_pressure(forces, bearing)
    ball, contact = np.unravel_index(int(np.argmax(pressure)), pressure.shape)
    p = float(pressure[ball, contact])
    if p <= MAX_HERTZ_PRESSURE:
        return
    key = max(parts, key=lambda k: abs(np.atleast_1d(parts[k])[ball]) if np.ndim(parts[k])
              else abs(parts[k]))
    raw = table.data[key]
    raise table.error(key, f"= {raw!r}: ball {ball} (ball 0 trailing) is pressed with "
                           f"{show(float(forces[ball, contact]))} N at {CONTACTS[contact]}, a "
                           f"Hertz pressure of {p / 1e6:.0f} MPa above the "
                           f"{MAX_HERTZ_PRESSURE / 1e6:.0f} MPa of ISO 76 / ISO 14728-2 (the "
                           "static load rating): the elastic contact model no longer holds")


#: The load component conjugate to each carriage DOF (:data:`tolsim.physics.carriage.DOFS`).
_LOAD_OF_DOF = {"u_x": ("lateral", "force"), "u_y": ("vertical", "force"),
                "pitch": ("pitch_moment", "moment"), "yaw": ("yaw_moment", "moment"),
                "roll": ("roll_moment", "moment")}


def _check_mechanism(table: Table, load, layout):
    """Raise for a load along a motion the tracks cannot resist (one ball per track has no
    stiffness against pitch and yaw), naming the load key and the layout's keys."""
    locked = uncarried_motions(layout, load)
    if not locked:
        return
    keys = [table.key_for(*_LOAD_OF_DOF[dof]) for dof in locked]
    given = [k for k in keys if k in table.data and table.data[k] != 0]
    key = given[0] if given else None
    raise table.error(key, f"{'= ' + repr(table.data[key]) + ' ' if key else ''}acts along a "
                           f"motion the balls cannot resist ({', '.join(locked)}) with "
                           f"carriage.balls_per_track = {layout.balls_per_track} and "
                           f"{layout.n_tracks} carriage.track rows: give more balls per "
                           "track or tracks that hold it, or remove that load")


def check_carriage_load(table: Table, load, layout, bearing: Bearing):
    """Raise for a carriage load no set of ball forces within :data:`MAX_HERTZ_PRESSURE`
    can carry.

    Each ball holds the carriage through its two carriage-side contacts, so it passes at
    most 2 F_max to it (F_max the contact force at :data:`MAX_HERTZ_PRESSURE`), at a lever
    arm of at most its distance from the reference point plus its radius. A force beyond
    n 2 F_max, or a moment beyond sum(2 F_max r), overloads some contact whatever the
    preload and the layout: a necessary condition (the exact forces need the carriage
    solve, :mod:`tolsim.study.pipeline.carriage`).
    """
    _check_mechanism(table, load, layout)
    c = hertz_constants(bearing.ball_radius, bearing.conformity, bearing.youngs_modulus,
                        bearing.poisson_ratio)
    f_max = (MAX_HERTZ_PRESSURE / c.pressure_coefficient) ** 3
    n = layout.balls_per_track
    z = (np.arange(n) - 0.5 * (n - 1)) * layout.ball_pitch
    x = np.asarray(layout.track_x, dtype=float)
    y = np.asarray(layout.track_y, dtype=float)
    arm = np.sqrt(x[:, None] ** 2 + y[:, None] ** 2 + z[None, :] ** 2) + bearing.ball_radius
    capacity = {"force": 2.0 * f_max * arm.size, "moment": 2.0 * f_max * float(arm.sum())}
    for name, kind in (("lateral", "force"), ("vertical", "force"),
                       ("pitch_moment", "moment"), ("yaw_moment", "moment"),
                       ("roll_moment", "moment")):
        key = table.key_for(name, kind)
        if key not in table.data:
            continue
        value = getattr(load, {"lateral": "lateral_force",
                               "vertical": "vertical_force"}.get(name, name))
        if abs(value) > capacity[kind]:
            unit, factor = table.unit_of(key, kind)
            raise table.error(key, f"= {table.data[key]!r} is beyond the "
                                   f"{show(capacity[kind] / factor)} {unit} that the "
                                   f"{arm.size} balls can carry at the "
                                   f"{MAX_HERTZ_PRESSURE / 1e6:.0f} MPa of ISO 76 / ISO "
                                   "14728-2 (each ball at most 2 x "
                                   f"{show(f_max)} N): is the unit right?")
