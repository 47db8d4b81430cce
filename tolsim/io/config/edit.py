"""A config's TOML text, changed and checked: the text a result file embeds is its only
record of the study, so it must say what ran.

:func:`with_study_settings` changes ``[study]`` keys in the text and reads it again (every
value checked as in a file); :func:`text_mismatch` tells whether a config is what its text
reads as (:func:`tolsim.io.netcdf.write_result` refuses one that is not). Plain text
processing on top of :func:`tolsim.study.spec.toml_lines`; the reading is
:func:`tolsim.io.config.parse_config`'s.
"""

import functools
import numbers
import re
import warnings
from dataclasses import fields, is_dataclass

import numpy as np

from tolsim.io.config import parse_config
from tolsim.io.config.reader import UNITS, ConfigError
from tolsim.io.config.sections import FRACTION_KEYS, READ_BACK
from tolsim.study.spec import StudyConfig, set_study_value, toml_key, toml_lines

__all__ = ["text_mismatch", "with_study_settings"]


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
        base = next((k for k in FRACTION_KEYS if key.startswith(f"{k}_")), None)
        if base is not None:  # one form only: the order of two would decide
            raise ConfigError(f"study.{key}: give {base} as a fraction [-], without a unit")
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
