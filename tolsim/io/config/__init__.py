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
    READ_BACK,
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
from tolsim.study.spec import (
    Distribution,
    StudyConfig,
    Train,
    set_study_value,
    toml_key,
    toml_lines,
)

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
    default then applies: ``time_steps=None`` is the automatic step), with the comment lines
    that continue it. A key the text lacks is added at the end of the ``[study]`` table; the
    other lines, comments included, stay. Unlike ``dataclasses.replace``, the change is in the
    text the result file embeds (:func:`text_mismatch`).

    Raises
    ------
    ConfigError
        For a value the config reader refuses (naming the key); a value that is not a number,
        a bool, a plain string or None; a key whose value in the text is not one (an array);
        a text without a ``[study]`` table to add a key to; a point of a sweep (change the
        sweep's text instead).
    """
    if not isinstance(config, StudyConfig):
        raise ConfigError(f"config = {config!r:.60} must be a StudyConfig (tolsim.load_config)")
    if not config.text:
        raise ConfigError("the config has no TOML text (built in Python): read it with "
                          "tolsim.load_config or tolsim.parse_config to change its settings")
    if config.sweep is None and _has_sweep(config.text):
        raise ConfigError(f"{config.path}: a point of a sweep: change the sweep's config, "
                          "then take its point")
    text = config.text
    for key, value in settings.items():
        if key in FRACTION_KEYS:  # a fraction [-], written with the unit the text uses
            text = _set_fraction(text, key, value, config.path)
        else:
            text = _set_study_text(text, key, value, config.path)
    return parse_config(text, config.path, study=False)


def _set_fraction(text, key, value, path):
    """``text`` with fraction key ``key`` (its SI name) set to ``value`` [-]: as
    ``key_percent`` unless the text writes it in ppm, as the shortest decimal that reads
    back as ``value`` (where one does)."""
    units = UNITS["fraction"]
    given = [unit for unit in units if _study_key_line(text, f"{key}_{unit}") is not None]
    unit = given[0] if given else "percent"
    if value is None:
        return _set_study_text(text, f"{key}_{unit}", None, path)
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise ConfigError(f"study.{key} = {value!r} must be a number (a fraction) or None")
    x, factor = float(value), units[unit]
    shortest = (float(f"{x / factor:.{digits}g}") for digits in range(1, 18))
    written = next((w for w in shortest if w * factor == x), x / factor)
    return _set_study_text(text, f"{key}_{unit}", written, path)


def _has_sweep(text):
    return any(name == "sweep" for _, _, name, _, _ in toml_lines(text.splitlines()))


#: Stands for a value to remove, in :func:`_set_study_text`.
_REMOVED = "tolsim-removed-value"


def _study_key_line(text, key):
    """The number of the line that gives ``[study]`` key ``key`` (in the table, as a dotted
    key or in an inline table), else None; whatever its value."""
    in_table = re.compile(rf"\s*{toml_key(key)}\s*=")
    dotted = re.compile(rf"\s*{toml_key('study')}\s*\.\s*{toml_key(key)}\s*=")
    inline = re.compile(rf"\s*{toml_key('study')}\s*=\s*{{.*[{{,]\s*{toml_key(key)}\s*=")
    for number, line, table, array, header in toml_lines(text.splitlines()):
        if header or array:
            continue
        if (table == "study" and in_table.match(line)) or (
                table == "" and (dotted.match(line) or inline.match(line))):
            return number
    return None


def _literal(key, value):
    """``value`` as a TOML scalar."""
    if value is None:
        return _REMOVED
    if isinstance(value, bool | np.bool_):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))
    if isinstance(value, str) and re.fullmatch(r"[^\s\"\\#,}\x00-\x1f]*", value):
        return f'"{value}"'
    raise ConfigError(f"study.{key} = {value!r}: give a number, a bool, a plain string or None "
                      "(an array: change it in the text)")


def _set_study_text(text, key, value, path):
    """``text`` with ``[study]`` key ``key`` set to ``value`` (a TOML scalar; None removes
    the key)."""
    if not re.fullmatch(r"[A-Za-z0-9_]+", key):
        raise ConfigError(f"study.{key}: not a key of [study]")
    literal = _literal(key, value)
    newline = "\r\n" if "\r\n" in text else "\n"
    try:
        text = set_study_value(text, key, literal)
    except ValueError as exc:
        if "is found 0 times" not in str(exc):
            raise ConfigError(str(exc)) from None
        if _study_key_line(text, key) is not None:
            raise ConfigError(f"study.{key}: its value in the text is not a plain number or "
                              "string (an array?): change it in the text") from None
        if value is None:
            return text
        return _add_study_key(text, f"{key} = {literal}", key, path, newline)
    if value is None:
        lines = text.splitlines(keepends=True)
        (number,) = (n for n, line in enumerate(lines) if _REMOVED in line)
        if "{" in lines[number]:
            raise ConfigError(f"study.{key}: cannot remove a key of an inline table")
        end = number + 1  # with the comment lines that continue its own
        while end < len(lines) and re.match(r"[ \t]+#", lines[end]):
            end += 1
        del lines[number:end]
        text = "".join(lines)
    return text


def _add_study_key(text, line, key, path, newline):
    """``text`` with ``line`` added after the last key line of its ``[study]`` table."""
    lines = text.splitlines(keepends=True)
    header, last = None, None
    for number, content, table, array, is_header in toml_lines(lines):
        if is_header and header is not None:
            break
        if is_header and table == "study" and not array:
            header = last = number
        elif header is not None and content.strip() and not content.lstrip().startswith("#"):
            last = number  # (comments before the next header are that table's)
    if header is None:
        if any(table == "" and re.match(rf"\s*{toml_key('study')}\s*[.=]", content)
               for _, content, table, _, _ in toml_lines(lines)):
            raise ConfigError(f"study.{key}: the text gives [study] as dotted keys or an "
                              "inline table: add the key there")
        raise ConfigError(f"{path}: the text has no [study] table to add study.{key} to "
                          "(add [study] with samples and seed)")
    while last + 1 < len(lines) and re.match(r"[ \t]+#", lines[last + 1]):
        last += 1  # the comment lines that continue the key's own
    if not lines[last].endswith("\n"):
        lines[last] += newline
    lines.insert(last + 1, line + newline)
    return "".join(lines)


def text_mismatch(config: StudyConfig, point: int | None = None) -> str | None:
    """None if ``config`` is what its own ``text`` reads as, else the first setting that
    differs, as a clause.

    A sweep's base must hold the text's points in order; a point of a sweep (its text is the
    sweep's) must be the text's point ``point``, or any of them when ``point`` is None.

    A result file embeds the config text and nothing else of the config, so a file is
    reproducible from itself only when the text says what ran. :meth:`StudyConfig.
    with_overrides` and :func:`with_study_settings` keep the text right; ``dataclasses.
    replace`` changes the settings alone, and is caught here
    (:func:`tolsim.io.netcdf.write_result` refuses such a config). The text is read again and
    compared by ``repr``, which holds every setting (a sweep's points apart). Measured-data
    files are read back as the config read them (by their SHA-256, which the result file
    records), not from the disk.
    """
    if not isinstance(config, StudyConfig):
        return f"the config {config!r:.60} is not a StudyConfig"
    if not config.text:
        return "the config has no TOML text (built in Python: read it with tolsim.load_config)"
    try:
        read, points = _read_back(config.text, config.path,
                                  tuple(config.data_files.items()))
    except ConfigError as exc:
        return f"the config's text is not a valid config ({exc})"
    given = repr(config)
    if config.sweep is not None:
        if given == repr(read) and tuple(map(repr, config.sweep.points)) == points:
            return None
        if given == repr(read):
            return "the config's sweep points are not those of its text (in order)"
    elif points:
        if given in (points if point is None else points[point:point + 1]):
            return None
        if point is not None:
            read = read.sweep.points[point]
    elif given == repr(read):
        return None
    name, value, text_value = _first_difference(read, config, "config")
    return f"{name} = {_short(value)}, but its text gives {_short(text_value)}"


@functools.lru_cache(maxsize=2)
def _read_back(text, path, data_files):
    """(the config ``text`` reads as, the reprs of its sweep's points, in order), its data
    files read as ``data_files`` ((file, SHA-256) pairs) give them. Read once per text, so a
    sweep's parts, each checked as it is written, cost one reading of the sweep."""
    token = READ_BACK.set(dict(data_files))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # given when the text was first read
            read = parse_config(text, path, study=False)
    finally:
        READ_BACK.reset(token)
    points = () if read.sweep is None else tuple(map(repr, read.sweep.points))
    return read, points


def _first_difference(read, given, name, depth=4):
    """(dotted name, given value, read value) of the first field in which ``given``
    differs from ``read`` (into dataclasses and tuples)."""
    if depth and is_dataclass(read) and type(read) is type(given):
        for f in fields(read):
            a, b = getattr(read, f.name), getattr(given, f.name)
            if repr(a) != repr(b):
                return _first_difference(a, b, f"{name}.{f.name}", depth - 1)
    if depth and isinstance(read, tuple) and isinstance(given, tuple) and len(read) == len(
            given):
        for i, (a, b) in enumerate(zip(read, given, strict=True)):
            if repr(a) != repr(b):
                return _first_difference(a, b, f"{name}[{i}]", depth - 1)
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
