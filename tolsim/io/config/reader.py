"""The bottom of the config reader: the unit tables, :class:`ConfigError` and the TOML line
scanner (:class:`Source`: the line of a key, for one-line errors) with its typed, unit-aware
table reader (:class:`Table`). The section readers (:mod:`tolsim.io.config.sections`,
:mod:`~tolsim.io.config.sweep`, :mod:`~tolsim.io.config.allocation`) build on it.
"""

import math
import re
import warnings

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


class ConfigError(ValueError):
    """A bad study configuration; the message is one line naming the key (file:line: key)."""


class ConfigWarning(UserWarning):
    """An unusual but possible value in a study configuration (one line, like ConfigError).

    Issued with :func:`warnings.warn`; the command line prints each one once, as
    ``tolsim <command>: warning: <message>`` (:func:`tolsim.cli.warnings_as_lines`).
    """


def show(value) -> str:
    """A number as the user reads it: up to 6 significant digits, no float noise
    (``-5e-05``, not ``-4.9999999999999996e-05``); other values by their ``repr``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return repr(value)
    if isinstance(value, int):
        return str(value)
    return f"{value:.6g}"


# --------------------------------------------------------------------------------------------
# Reader
# --------------------------------------------------------------------------------------------
class Source:
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

    def warn(self, table, key, message):
        """Issue a :class:`ConfigWarning` 'file:line: table.key message'."""
        warnings.warn(ConfigWarning(str(self.error(table, key, message))), stacklevel=3)


class Table:
    """One TOML table being read: typed getters with units; unknown keys are errors."""

    def __init__(self, data, name, source):
        if not isinstance(data, dict):
            raise source.error(name, None, f"must be a table, got {type(data).__name__}")
        self.data, self.name, self.source = data, name, source
        self.used = set()

    def error(self, key, message):
        return self.source.error(self.name, key, message)

    def warn(self, key, message):
        """Issue a :class:`ConfigWarning` naming ``key`` (see :meth:`Source.warn`)."""
        self.source.warn(self.name, key, message)

    def unit_of(self, key, kind) -> tuple:
        """(unit suffix, factor to SI) of ``key`` as written (``""`` and 1 without one)."""
        for unit, factor in sorted(UNITS[kind].items(), key=lambda u: -len(u[0])):
            if unit and key.endswith(f"_{unit}"):
                return unit, factor
        return "", 1.0

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
            if positive and not v > 0:  # v as written (a TOML number has no float noise)
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

    def integer(self, key, *, default=None, minimum=None, maximum=None):
        if key not in self.data:
            if default is None:
                raise self.error(key, "is missing")
            return default
        self.used.add(key)
        v = self._number(key, self.data[key], integer=True)
        if minimum is not None and v < minimum:
            raise self.error(key, f"= {v!r} must be >= {minimum}")
        if maximum is not None and v > maximum:
            raise self.error(key, f"= {v!r} must be <= {maximum}")
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
        return Table(self.data[key], f"{self.name}.{key}" if self.name else key, self.source)

    def finish(self):
        """Raise on the first key that was not read."""
        for key in self.data:
            if key not in self.used:
                raise self.error(key, "is not a known key")
