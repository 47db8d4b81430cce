"""The result-file variables of a study with a carriage (issue 12): its tracks, loads,
displacements and stiffnesses (:mod:`tolsim.study.pipeline.carriage`)."""

import numpy as np

from tolsim.io.schema.declaration import Section
from tolsim.physics.carriage import DOFS
from tolsim.physics.hertz import hertz_constants
from tolsim.study.pipeline.carriage import CarriageResult
from tolsim.study.pipeline.carriage_circuit import WHERE_NAMES

_TRANSLATION = ("carriage_translation",)
_ROTATION = ("carriage_rotation",)
_TRACK = ("track",)
#: name -> (dims, units, long_name, dtype kind): the carriage variables of a result file
#: (:mod:`tolsim.io.schema` declares them, optional).
CARRIAGE_VARIABLES = {
    "track_x": (_TRACK, "m", "lateral position x of the track's ball centres", "f"),
    "track_y": (_TRACK, "m", "vertical position y of the track's ball centres", "f"),
    "track_orientation": (_TRACK, "rad", "orientation phi of the track's module", "f"),
    "preload_oversize": ((), "m", "nominal diametral ball oversize (preload class)", "f"),
    "preload_contact_force": ((), "N", "contact force of the nominal preload alone, "
                                       "K (o / 2)^1.5", "f"),
    "n_assemblies_carriage_failed": ((), "1", "assemblies whose carriage did not converge or "
                                              "lifted off (their trains are unresolved)", "i"),
    "carriage_load_force": (("carriage_force_component",), "N", "force on the carriage at "
                            "the reference point (names in carriage_force_component_name)",
                            "f"),
    "carriage_load_moment": (("carriage_moment_component",), "N m", "moment on the carriage "
                             "about the reference point (names in "
                             "carriage_moment_component_name)", "f"),
}
for _dims, _what, _units, _stiff_units in (
        (_TRANSLATION, "translation", "m", "N m-1"), (_ROTATION, "rotation", "rad", "N m rad-1")):
    CARRIAGE_VARIABLES[f"carriage_{_what}_nominal"] = (
        _dims, _units, f"carriage {_what} of the nominal assembly", "f")
    CARRIAGE_VARIABLES[f"carriage_{_what}al_stiffness_nominal"] = (
        _dims, _stiff_units, f"carriage {_what}al stiffness (diagonal of the tangent "
                             "stiffness) of the nominal assembly", "f")
    for _stat, _label in (("mean", "mean"), ("std", "standard deviation"),
                          ("min", "smallest"), ("max", "largest")):
        CARRIAGE_VARIABLES[f"carriage_{_what}_{_stat}"] = (
            _dims, _units, f"{_label} carriage {_what} over the solved assemblies", "f")
        CARRIAGE_VARIABLES[f"carriage_{_what}al_stiffness_{_stat}"] = (
            _dims, _stiff_units, f"{_label} carriage {_what}al stiffness over the solved "
                                 "assemblies", "f")
# along the track (issue 24): where first contacts happen; a [carriage.circuit]'s figures
CARRIAGE_VARIABLES.update({
    "contact_zone_end_fraction": ((), "1", "fraction of the first contacts that happen at a "
                                  "pair at either end of a track's loaded zone (its first or "
                                  "last pair)", "f"),
    "circuit_balls": ((), "1", "balls per circuit of each track", "i"),
    "circuit_slack": ((), "m", "total clearance of each circuit (its length minus the "
                               "balls' diameters)", "f"),
    "circuit_return_drag": ((), "N", "drag of one unloaded ball moving through the circuit",
                            "f"),
    "circuit_contact_count": (("circuit_contact_where",), "1", "contact events of the "
                              "circuits over the stroke, by where they formed", "i"),
    "circuit_column_force_max": (("zone_end",), "N", "largest force between the column of "
                                 "unloaded balls and the loaded zone at its end, at the ends "
                                 "of the steps", "f"),
    "circuit_column_force_mean": (("zone_end",), "N", "mean over the assemblies of the "
                                  "column force at the end of the loaded zone averaged over "
                                  "the stroke (the larger track's)", "f"),
    "circuit_slack_error_max": ((), "m", "largest departure of a circuit's total gap from "
                                "its slack at any step", "f"),
    "circuit_column_friction_mean": ((), "N", "mean over the assemblies of the carriage "
                                     "friction that the column's forces at the ends of the "
                                     "loaded zone cost, averaged over the stroke (the larger "
                                     "track's; with [contact])", "f"),
})
#: Coordinates of the carriage dimensions (index and name label, as ``contact``).
CARRIAGE_COORDINATES = {
    "track": (_TRACK, "1", "track (row of balls) of the carriage, in config order", "i"),
    "carriage_translation": (_TRANSLATION, "1", "carriage translation index (names in "
                                                "carriage_translation_name)", "i"),
    "carriage_translation_name": (_TRANSLATION, "1", "carriage translation (u_x, u_y)", "U"),
    "carriage_rotation": (_ROTATION, "1", "carriage rotation index (names in "
                                          "carriage_rotation_name)", "i"),
    "carriage_rotation_name": (_ROTATION, "1", "carriage rotation (pitch about x, yaw about "
                                               "y, roll about z)", "U"),
    "carriage_force_component": (("carriage_force_component",), "1", "carriage force "
                                 "component index (names in carriage_force_component_name)",
                                 "i"),
    "carriage_force_component_name": (("carriage_force_component",), "1",
                                      "carriage force component (lateral +x, vertical +y: "
                                      "minus the downward load)", "U"),
    "carriage_moment_component": (("carriage_moment_component",), "1", "carriage moment "
                                  "component index (names in carriage_moment_component_name)",
                                  "i"),
    "carriage_moment_component_name": (("carriage_moment_component",), "1",
                                       "carriage moment component (about +x, +y, +z)", "U"),
    "circuit_contact_where": (("circuit_contact_where",), "1", "where a contact event of "
                              "the circuit formed (names in circuit_contact_where_name)", "i"),
    "circuit_contact_where_name": (("circuit_contact_where",), "1", "where a contact event "
                                   "formed: inside the loaded zone, at its entry or exit "
                                   "(a loaded and an unloaded ball), in the return path", "U"),
    "zone_end": (("zone_end",), "1", "end of the loaded zone (names in zone_end_name)", "i"),
    "zone_end_name": (("zone_end",), "1", "end of the loaded zone (entry: leading, exit: "
                                          "trailing)", "U"),
}
#: Names along ``carriage_force_component`` and ``carriage_moment_component`` (the
#: generalised load Q, conjugate to the DOFS).
LOAD_NAMES = ("lateral_force", "vertical_force_upward", "pitch_moment", "yaw_moment",
              "roll_moment")


def carriage_variables(config, statistics, nominal: CarriageResult | None) -> tuple:
    """(coordinates, data variables) of a carriage study for its result file.

    ``statistics``: the study's :class:`~tolsim.study.statistics.accumulator.Accumulator`;
    ``nominal``: the nominal assembly
    (:func:`tolsim.study.pipeline.carriage.solve_config_carriage`), or None when it could not
    be solved (its variables are then NaN).
    """
    carriage = config.carriage
    layout = carriage.layout
    tracks = layout.n_tracks
    coords = {
        "track": (_TRACK, np.arange(tracks, dtype=np.int64)),
        "carriage_translation": (_TRANSLATION, np.arange(2, dtype=np.int64)),
        "carriage_translation_name": (_TRANSLATION, np.array(DOFS[:2])),
        "carriage_rotation": (_ROTATION, np.arange(3, dtype=np.int64)),
        "carriage_rotation_name": (_ROTATION, np.array(DOFS[2:])),
        "carriage_force_component": (("carriage_force_component",),
                                     np.arange(2, dtype=np.int64)),
        "carriage_force_component_name": (("carriage_force_component",),
                                          np.array(LOAD_NAMES[:2])),
        "carriage_moment_component": (("carriage_moment_component",),
                                      np.arange(3, dtype=np.int64)),
        "carriage_moment_component_name": (("carriage_moment_component",),
                                           np.array(LOAD_NAMES[2:])),
    }
    k = _hertz_constant(config.bearing)
    o = float(carriage.preload_oversize)
    data = {
        "track_x": (_TRACK, np.asarray(layout.track_x, dtype=float)),
        "track_y": (_TRACK, np.asarray(layout.track_y, dtype=float)),
        "track_orientation": (_TRACK, np.asarray(layout.track_orientation, dtype=float)),
        "preload_oversize": o,
        "preload_contact_force": k * max(0.5 * o, 0.0) ** 1.5,
        "n_assemblies_carriage_failed": np.int64(statistics.carriage_failed),
        "carriage_load_force": (("carriage_force_component",),
                                carriage.load.generalised()[:2]),
        "carriage_load_moment": (("carriage_moment_component",),
                                 carriage.load.generalised()[2:]),
    }
    acc = statistics
    solved = int(acc.carriage_count) > 0
    columns = {"mean": acc.carriage_mean, "std": acc.carriage_std,
               "min": acc.carriage_min, "max": acc.carriage_max}
    if nominal is not None:
        q = nominal.solution.displacement
        kdiag = np.diag(nominal.solution.stiffness)
    else:
        q = kdiag = np.full(5, np.nan)
    for what, sl, dims in (("translation", slice(0, 2), _TRANSLATION),
                           ("rotation", slice(2, 5), _ROTATION)):
        data[f"carriage_{what}_nominal"] = (dims, np.asarray(q[sl], dtype=float))
        data[f"carriage_{what}al_stiffness_nominal"] = (dims, np.asarray(kdiag[sl], float))
        for stat, values in columns.items():
            v = np.asarray(values, dtype=float) if solved else np.full(10, np.nan)
            data[f"carriage_{what}_{stat}"] = (dims, v[:5][sl])
            data[f"carriage_{what}al_stiffness_{stat}"] = (dims, v[5:][sl])
    if config.is_along_track:
        coords_circuit, data_circuit = circuit_variables(config, acc)
        coords.update(coords_circuit)
        data.update(data_circuit)
    return coords, data


def zone_end_counts(pair_count, tracks: int) -> tuple:
    """(first contacts at the first or last pair of a track's loaded zone, all first
    contacts) of ``pair_count`` (first contacts per pair, track by track); (0, 0) without
    pairs."""
    pairs = np.asarray(pair_count, dtype=float).reshape(tracks, -1)
    if pairs.shape[1] == 0:
        return 0, 0
    ends = pairs[:, 0].sum() + (pairs[:, -1].sum() if pairs.shape[1] > 1 else 0.0)
    return int(ends), int(pairs.sum())


def zone_end_fraction(pair_count, tracks: int) -> float:
    """Fraction of the first contacts at the first or last pair of a track's loaded zone
    (:func:`zone_end_counts`; NaN without contacts)."""
    ends, total = zone_end_counts(pair_count, tracks)
    return float(ends / total) if total else np.nan


def circuit_variables(config, acc) -> tuple:
    """(coordinates, data variables) of an along-track carriage study: the fraction of first
    contacts at the zone's ends, and with ``[carriage.circuit]`` the circuit's figures
    (:meth:`tolsim.study.statistics.accumulator.Accumulator.add_circuit`)."""
    tracks, balls = config.n_tracks, config.train.balls
    data = {"contact_zone_end_fraction": zone_end_fraction(
        acc.pair_count[: tracks * max(balls - 1, 0)], tracks)}
    circuit = config.carriage.circuit
    if circuit is None:
        return {}, data
    where, end = ("circuit_contact_where",), ("zone_end",)
    coords = {"circuit_contact_where": (where, np.arange(len(WHERE_NAMES), dtype=np.int64)),
              "circuit_contact_where_name": (where, np.array(WHERE_NAMES)),
              "zone_end": (end, np.arange(2, dtype=np.int64)),
              "zone_end_name": (end, np.array(("entry", "exit")))}
    figures = acc.circuit
    count = 0 if figures is None else int(figures["circuit_count"])
    data.update({
        "circuit_balls": np.int64(circuit.balls),
        "circuit_slack": float(circuit.slack),
        "circuit_return_drag": float(circuit.return_drag),
        "circuit_contact_count": (where, np.zeros(len(WHERE_NAMES), np.int64) if not count
                                  else np.asarray(figures["circuit_where_count"], np.int64)),
        "circuit_column_force_max": (end, np.full(2, np.nan) if not count
                                     else np.asarray(figures["circuit_column_max"], float)),
        "circuit_column_force_mean": (end, np.full(2, np.nan) if not count else
                                      np.asarray(figures["circuit_column_mean_sum"], float)
                                      / count),
        "circuit_slack_error_max": np.nan if not count else float(
            figures["circuit_slack_error"]),
    })
    if config.contact is not None:
        data["circuit_column_friction_mean"] = (
            float(figures["circuit_column_friction_sum"]) / count
            if count and "circuit_column_friction_sum" in figures else np.nan)
    return coords, data


def _hertz_constant(bearing) -> float:
    return float(hertz_constants(bearing.ball_radius, bearing.conformity,
                                 bearing.youngs_modulus,
                                 bearing.poisson_ratio).load_deflection_constant)


def collect(result, history=None) -> tuple:
    """(coordinates, data variables, no attributes) of a study with a carriage."""
    cfg = result.config
    if not cfg.has_carriage:
        return {}, {}, {}
    coords, data = carriage_variables(cfg, result.statistics,
                                      getattr(result, "carriage_nominal", None))
    return coords, data, {}


SECTION = Section(collect=collect)
