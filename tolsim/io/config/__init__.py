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
:mod:`~tolsim.io.config.plausibility`.
"""

import functools
import numbers
import os
import re
import tomllib
import warnings
from dataclasses import fields, is_dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

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
from tolsim.study.spec import Distribution, StudyConfig, Train, set_study_value, toml_lines

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


def with_study_settings(config: StudyConfig, **settings) -> StudyConfig:
    """``config`` with ``[study]`` settings changed in its text, which is then read again:
    every value is checked as in a file, and the result file records the change.

    ``with_study_settings(config, spot_checks=0, propagation="along_track")``. The keys are
    those of ``[study]``; a fraction (:data:`FRACTION_KEYS`) is given by its name without unit,
    as a fraction [-] (``velocity_deviation_limit=0.002``). ``None`` removes a key (its
    default then applies: ``time_steps=None`` is the automatic step). A key the text lacks
    is added under ``[study]``; the other lines, comments included, stay.
    Unlike ``dataclasses.replace``, the change is in the text the result file embeds
    (:func:`text_mismatch`).

    Raises
    ------
    ConfigError
        For a value the config reader refuses (naming the key), or a point of a sweep (change
        the sweep's text instead).
    """
    if config.sweep is None and _has_sweep(config.text):
        raise ConfigError(f"{config.path}: a point of a sweep: change the sweep's config, "
                          "then take its point")
    text = config.text
    for key, value in settings.items():
        if key in FRACTION_KEYS:  # a fraction [-], written with the unit the text uses
            text = _set_fraction(text, key, value)
        else:
            text = _set_study_text(text, key, value)
    return parse_config(text, config.path, study=False)


def _set_fraction(text, key, value):
    """``text`` with fraction key ``key`` (its SI name) set to ``value`` [-]: as
    ``key_percent`` unless the text writes it in ppm, with the decimal that reads back as
    ``value`` exactly where there is one."""
    units = UNITS["fraction"]
    given = [unit for unit in units if _has_study_key(text, f"{key}_{unit}")]
    unit = given[0] if given else "percent"
    if value is None:
        return _set_study_text(text, f"{key}_{unit}", None)
    x, factor = float(value), units[unit]
    near = (x / factor, np.nextafter(x / factor, np.inf), np.nextafter(x / factor, -np.inf))
    # the value that reads back as x, where one does (else x / factor: the config then holds
    # the value a file with this text gives, 0.35 % for 0.0035, say)
    written = next((float(w) for w in near if float(w) * factor == x), x / factor)
    return _set_study_text(text, f"{key}_{unit}", written)


def _has_study_key(text, key):
    try:
        set_study_value(text, key, 0)
    except ValueError:
        return False
    return True


def _has_sweep(text):
    return any(name == "sweep" for _, _, name, _, _ in toml_lines(text.splitlines()))


#: Stands for a value to remove, in :func:`_set_study_text`.
_REMOVED = "tolsim-removed-value"


def _set_study_text(text, key, value):
    """``text`` with ``[study]`` key ``key`` set to ``value`` (a TOML scalar; None removes
    the key)."""
    if not re.fullmatch(r"[A-Za-z0-9_]+", key):
        raise ConfigError(f"study.{key}: not a key of [study]")
    if value is None:
        literal = _REMOVED
    elif isinstance(value, bool | np.bool_):
        literal = "true" if value else "false"
    elif isinstance(value, numbers.Integral):
        literal = str(int(value))
    elif isinstance(value, numbers.Real):
        literal = repr(float(value))
    elif isinstance(value, str) and re.fullmatch(r"[^\s\"\\#,}]*", value):
        literal = f'"{value}"'
    else:
        raise ConfigError(f"study.{key} = {value!r}: give a number, a bool, a plain string or "
                          "None")
    try:
        text = set_study_value(text, key, literal)
    except ValueError as exc:
        if "is found 0 times" not in str(exc):
            raise ConfigError(str(exc)) from None
        if value is None:
            return text
        lines = text.splitlines(keepends=True)
        header = next((n for n, _, name, array, is_header in toml_lines(lines)
                       if is_header and name == "study" and not array), None)
        if header is None:  # a config without [study]: add it at the end
            return f"{text.rstrip()}\n\n[study]\n{key} = {literal}\n"
        lines.insert(header + 1, f"{key} = {literal}\n")
        return "".join(lines)
    if value is None:
        lines = text.splitlines(keepends=True)
        (number,) = (n for n, line in enumerate(lines) if _REMOVED in line)
        if "{" in lines[number]:
            raise ConfigError(f"study.{key}: cannot remove a key of an inline table")
        del lines[number]
        text = "".join(lines)
    return text


def text_mismatch(config: StudyConfig) -> str | None:
    """None if ``config`` is what its own ``text`` reads as (a sweep's text: one of its
    points), else the first setting that differs, as a clause.

    A result file embeds the config text and nothing else of the config, so a file is
    reproducible from itself only when the text says what ran. :meth:`StudyConfig.
    with_overrides` keeps the text right; ``dataclasses.replace`` changes the settings alone,
    and is caught here (:func:`tolsim.io.netcdf.write_result` refuses such a config). The text
    is read again (warnings silenced: they were given when it was first read) and compared
    by ``repr``, which holds every setting.
    """
    try:
        read, points = _read_back(config.text, config.path)
    except ConfigError as exc:
        return f"its text is not a valid config ({exc})"
    if repr(config) in (points if config.sweep is None and points else {repr(read)}):
        return None
    name, given, read = _first_difference(read, config, "config")
    return f"{name} = {_short(given)}, but its text gives {_short(read)}"


@functools.lru_cache(maxsize=2)
def _read_back(text, path):
    """(the config ``text`` reads as, the reprs of its sweep's points): read once per text,
    so a sweep's parts, each checked as it is written, cost one reading of the sweep."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # given when the text was first read
        read = parse_config(text, path, study=False)
    points = frozenset() if read.sweep is None else frozenset(map(repr, read.sweep.points))
    return read, points


def _first_difference(read, given, name, depth=3):
    """(dotted name, given value, read value) of the first field in which ``given``
    differs from ``read``."""
    if depth and is_dataclass(read) and type(read) is type(given):
        for f in fields(read):
            a, b = getattr(read, f.name), getattr(given, f.name)
            if repr(a) != repr(b):
                return _first_difference(a, b, f"{name}.{f.name}", depth - 1)
    return name, given, read


def _short(value):
    text = " ".join(repr(value).split())
    return text if len(text) <= 50 else text[:47] + "..."


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
    if study.estimator != "monte_carlo":  # a rare-event estimator needs a limit state
        try:
            check_supported(config)
        except ValueError as exc:
            raise study_table.error("estimator", str(exc).removeprefix("estimator ")) from None
    return config


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
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read config: {exc.__class__.__name__}: "
                          f"{getattr(exc, 'strerror', None) or exc}") from None
    return parse_config(text, str(path), study=study)
