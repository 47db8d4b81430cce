"""Study configuration: TOML (read with :mod:`tomllib`) -> validated frozen dataclasses.

Every dimensional key carries its unit as a suffix (``ball_diameter_mm``, ``std_um``,
``yaw_moment_N_m``); values are converted to SI once, here, and nothing downstream sees a
unit again. Any problem raises :class:`ConfigError`, a :class:`ValueError` whose message is
one line naming the file, the line (where it can be found) and the key, e.g.::

    study.toml:12: tolerances.top_rotation.std_deg = -0.1 must be >= 0

The sections and their keys are documented in ``tolsim/data/default.toml`` (the packaged
default study) and in ``configs/*.toml``. They are read by :mod:`~tolsim.io.config.sections`,
``[sweep]`` by :mod:`~tolsim.io.config.sweep` and ``[allocate]`` by
:mod:`~tolsim.io.config.allocation`, all on :mod:`~tolsim.io.config.reader` (the units, the
errors and the TOML line scanner); this module puts them together. Every physical key is
checked against its possible range (an error) and its usual one (a
:class:`~tolsim.io.config.reader.ConfigWarning`), kept with their sources in
:mod:`~tolsim.io.config.plausibility`. :mod:`~tolsim.io.config.edit` changes a config through
its text and checks that a config is what its text says (the record a result file embeds).
"""

import math
import os
import re
import tomllib
from dataclasses import replace
from importlib import resources
from pathlib import Path

from tolsim.io.config.allocation import parse_allocation
from tolsim.io.config.reader import UNITS, ConfigError, ConfigWarning, Source, Table
from tolsim.io.config.sections import (
    ESTIMATOR_KEYS,
    FRACTION_KEYS,
    MIN_EMPIRICAL_VALUES,
    check_carriage_propagation,
    check_circuit,
    read_bearing,
    read_carriage,
    read_contact,
    read_correlations,
    read_loads,
    read_motion,
    read_study,
    read_tolerances,
    read_train,
)
from tolsim.io.config.sweep import parse_sweep
from tolsim.study.analyses.limit_state import check_supported
from tolsim.study.spec import Distribution, StudyConfig, Train

__all__ = ["ESTIMATOR_KEYS", "FRACTION_KEYS", "MIN_EMPIRICAL_VALUES", "NO_STUDY", "UNITS",
           "ConfigError", "ConfigWarning", "StudyConfig", "default_config_text", "load_config",
           "parse_config", "text_mismatch", "with_study_settings"]


def parse_config(text: str, path: str = "<string>", *, study: bool = True) -> StudyConfig:
    """Validate a study given as TOML text.

    Parameters
    ----------
    text : str
        The TOML document.
    path : str
        Name used in error messages.
    study : bool
        False accepts a config without ``[study]`` (``tolsim carriage``: a load distribution
        needs no samples or seed); its settings are then the defaults, with one sample and
        seed 0 (:data:`NO_STUDY`).

    Returns
    -------
    StudyConfig

    Raises
    ------
    ConfigError
        One line: ``path:line: section.key problem``.
    """
    if not isinstance(text, str):  # bytes included: tomllib reads text
        raise ConfigError(f"{path}: the config text must be a str (the TOML document), not "
                          f"{type(text).__name__}; tolsim.load_config reads a file")
    source = Source(text, path)
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
        return _build(data, source, text, path, study)
    # a what-if sweep (issue 14): the base study, then one complete config per point
    base = {key: value for key, value in data.items() if key != "sweep"}
    config = _build(base, source, text, path, study)
    sweep = parse_sweep(Table(data["sweep"], "sweep", source), base,
                        lambda point: _build(point, source, text, path, study))
    return replace(config, sweep=sweep)


#: The propagation of a ``[carriage]`` study whose ``[study]`` does not name one (issue 24):
#: constant epsilon would follow balls beyond the loaded zone.
CARRIAGE_PROPAGATION = "along_track"

#: ``[study]`` of a config read without one (``parse_config(..., study=False)``).
NO_STUDY = {"samples": 1, "seed": 0}


def _build(data: dict, source: "Source", text: str, path: str,
           study_required: bool = True) -> StudyConfig:
    """The StudyConfig of a parsed TOML document (``data``); errors name ``source``'s lines."""
    root = Table(data, "", source)
    bearing = read_bearing(root.table("bearing"))
    motion = read_motion(root.table("motion"))
    carriage = None
    if root.has("carriage"):  # loads from [carriage.load]; [train] optional
        if root.has("loads"):
            raise source.error("loads", None, "section beside [carriage]: a carriage takes "
                                              "its loads from [carriage.load]; remove [loads]")
        carriage = read_carriage(root.table("carriage"), bearing)
        layout = carriage.layout
        if root.has("train"):
            train = read_train(root.table("train"), bearing)
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
        train = read_train(root.table("train"), bearing)
        loads = read_loads(root.table("loads"), train, bearing)
    tolerances = read_tolerances(root.table("tolerances", required=False), bearing)
    correlations = read_correlations(root, tolerances)
    if study_required or root.has("study"):
        study_table = root.table("study")
    else:
        study_table = Table(dict(NO_STUDY), "study", source)
    study = read_study(study_table)
    if carriage is not None and "propagation" not in study_table.data and root.has("study"):
        # a carriage's balls roll through its loaded zone: followed along the track unless
        # the config says constant (issue 24); a config read without [study] keeps constant
        study = replace(study, propagation=CARRIAGE_PROPAGATION)
    if carriage is not None:  # the carriage solve is the static model of its balls
        given = study_table.data.get("static_model")
        if given not in (None, "solved"):
            raise study_table.error("static_model", f"= {given!r}: a study with a [carriage] "
                                    "solves every ball with the carriage (elastic, "
                                    "displacement-controlled); remove the key or set 'solved'")
        study = replace(study, static_model="solved")
        check_carriage_propagation(Table(data["carriage"], "carriage", source), carriage, train,
                              study_table, study)
    contact = None
    if root.has("contact"):  # after contact: trains and friction (issue 13)
        contact = read_contact(root.table("contact"))
        if not bearing.friction_coefficient > 0:
            raise source.error("bearing", "friction_coefficient", "= 0: a study with [contact] "
                               "needs raceway friction (> 0) to carry the balls' pushes")
    if carriage is not None and carriage.circuit is not None:  # issue 24
        check_circuit(Table(data["carriage"]["circuit"], "carriage.circuit", source), carriage,
                      train, study, bearing)
    allocation = None
    if root.has("allocate"):  # read by `tolsim allocate` (issue 14); `tolsim run` ignores it
        allocation = parse_allocation(root.table("allocate"), tolerances, bearing)
    for key in data:
        if key not in root.used:
            raise source.error(key, None, "is not a known section (bearing, motion, train, "
                                          "loads, carriage, tolerances, correlation, study, "
                                          "contact, sweep, allocate)")
    config = StudyConfig(bearing, motion, train, loads, tolerances, study, text, path,
                         correlations, carriage, contact, allocation)
    _check_step_count(config, root)
    _warn_coarse_fields(config, root)
    if study.estimator != "monte_carlo":  # a rare-event estimator needs a limit state
        try:
            check_supported(config)
        except ValueError as exc:
            raise study_table.error("estimator", str(exc).removeprefix("estimator ")) from None
    return config


def _check_step_count(config, root):
    """Refuse, naming the length that sets it, an automatic step count along the track above
    :data:`tolsim.study.pipeline.propagation_rules.MAX_TIME_STEPS` (a rail field's
    correlation length of 1e-30 mm gave 2e32 steps, and the study ran on without end)."""
    from tolsim.study.pipeline.propagation_rules import (  # noqa: PLC0415
        MAX_TIME_STEPS,
        check_step_count,
    )

    found = check_step_count(config)
    if found is None:
        return
    cause, length, count, shortest = found
    if cause.startswith("rail field "):
        table = root.table("tolerances").table(cause.removeprefix("rail field "))
        key = table.key_for("correlation_length", "length")
    else:  # the carriage's ball pitch or end relief, or a train's ball spacing
        table = root.table("carriage" if config.carriage is not None else "train")
        name = {"ball pitch": "ball_pitch", "end relief": "end_relief_length"}.get(cause)
        key = table.key_for(name, "length") if name else None
    what = f"= {table.data[key]!r}" if key else f"({cause} {1e3 * length:.3g} mm)"
    length_name = (f"correlation length of the rail field {cause.removeprefix('rail field ')}"
                   if cause.startswith("rail field ") else cause)
    raise table.error(key, f"{what}: along the track the automatic step count would be "
                           f"{count:.3g}, more than {MAX_TIME_STEPS}: the {length_name} is the "
                           "shortest length over which epsilon changes, and a step moves a "
                           f"ball a fraction of it; use at least {1e3 * shortest:.3g} mm, or "
                           "set study.time_steps")


def _warn_coarse_fields(config, root):
    """Warn, naming its ``correlation_length``, of a rail random field whose along-track grid
    is coarser than :data:`tolsim.study.sampling.FIELD_POINTS_PER_CORRELATION_LENGTH` points
    per correlation length: :data:`~tolsim.study.sampling.MAX_FIELD_POINTS` spreads them
    over the rail the balls visit (a short correlation length, a long stroke). Read between
    two points, linearly, the field's variance falls to (1 + rho) / 2 at a cell's middle, rho
    = exp(-spacing / l): the rail's errors come out smaller than configured there."""
    if not config.is_along_track:
        return
    from tolsim.study.sampling import (  # noqa: PLC0415 - the sampler's own grid rule
        FIELD_POINTS_PER_CORRELATION_LENGTH,
        MAX_FIELD_POINTS,
        field_grid,
    )

    grid = field_grid(config)
    for t in config.tolerances:
        if t.source not in grid:
            continue
        origin, spacing, points = grid[t.source]
        per_length = t.correlation_length / spacing
        if per_length >= FIELD_POINTS_PER_CORRELATION_LENGTH * (1 - 1e-9):
            continue
        loss = 0.5 * (1.0 - math.exp(-spacing / t.correlation_length))
        sub = root.table("tolerances").table(t.source)
        key = sub.key_for("correlation_length", "length")
        sub.warn(key, f"= {sub.data[key]!r}: the rail field's grid ({MAX_FIELD_POINTS} points "
                      f"at most, over the {1e3 * (points - 1) * spacing:.4g} mm the balls "
                      f"visit) has {per_length:.3g} points per correlation length, not "
                      f"{FIELD_POINTS_PER_CORRELATION_LENGTH}: read between them the field's "
                      f"variance is up to {100 * loss:.3g} % low (rail errors drawn smaller "
                      "than configured); a longer correlation length or a shorter stroke "
                      "avoids it")


def default_config_text() -> str:
    """The TOML text of the packaged default study (``tolsim/data/default.toml``)."""
    return resources.files("tolsim").joinpath("data/default.toml").read_text(encoding="utf-8")


def load_config(path=None, *, study: bool = True) -> StudyConfig:
    """Read and validate a study config file (the packaged default when ``path`` is None).

    ``study=False`` accepts a file without ``[study]`` (see :func:`parse_config`).

    Raises
    ------
    ConfigError
        For a missing or unreadable file or any invalid content (one line, names the key).
    """
    if path is None:
        return parse_config(default_config_text(), "default.toml", study=study)
    if not isinstance(path, str | os.PathLike):
        raise ConfigError(f"path = {path!r}: a config file's path must be a str or "
                          "os.PathLike (None: the packaged default)")
    p = Path(path)
    try:
        # "utf-8-sig": a byte-order mark (Windows editors save "UTF-8 with BOM") is not part
        # of the TOML, which tomllib refused at line 1 with "Invalid statement"
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        line = exc.object[:exc.start].count(b"\n") + 1
        raise ConfigError(f"{path}:{line}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x}): "
                          "a TOML config is UTF-8 text; save it as UTF-8") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.__class__.__name__}: "
                          f"{getattr(exc, 'strerror', None) or exc}") from None
    return parse_config(text, str(path), study=study)


# the text of a config changed and checked (reads configs: after parse_config is defined)
from tolsim.io.config.edit import text_mismatch, with_study_settings  # noqa: E402
