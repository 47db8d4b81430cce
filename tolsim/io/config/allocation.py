"""``[allocate]``: the settings of ``tolsim allocate`` (issue 14), and the allocated config.

:func:`parse_allocation` reads the section (called by :func:`tolsim.io.config.parse_config`)
into a :class:`tolsim.study.design.allocate.AllocationSettings`::

    [allocate]
    target = "contact_probability <= 1%"   # optional; --target overrides it
    confidence = 0.95                      # one-sided, of the upper bound that must meet it
    samples = 20000                        # per evaluation (default: [study] samples)
    verify_samples = 80000                 # fresh assemblies (default: 4 x samples)
    max_evaluations = 120

    [allocate.sources.bottom_rotation]     # a decision variable; all keys optional
    min_scale = 0.25                       # bounds of "the tolerance times scale"
    max_scale = 4.0                        # (default: 4, or less where the static model's
                                           #  range demands it)
    cost_exponent = 2.0                    # k of the cost w / scale^k
    cost_weight = 1.0                      # w: its cost at the config's tolerance

Sources listed under ``[allocate.sources]`` are the decision variables and the config's other
sources keep their tolerances; without ``[allocate.sources]`` every random source is one,
with the defaults above (:mod:`tolsim.study.design.allocate`). Every bad key or value is a one-line
:class:`~tolsim.io.config.ConfigError` naming it.

:func:`allocated_config_text` writes the optimum as a config: the original text with
``scale = <s>`` in each allocated ``[tolerances.<source>]`` table (an existing ``scale``
line has its value replaced by the product; layout and comments stay), and
:func:`tolerance_lines` gives the resulting tolerances in the config's own units
(``std_deg = 0.0734``).
"""

import math
import re
import tomllib

from tolsim.io.config.reader import UNITS
from tolsim.study.design.allocate import (
    DEFAULT_CONFIDENCE,
    DEFAULT_COST_EXPONENT,
    DEFAULT_COST_WEIGHT,
    DEFAULT_MAX_EVALUATIONS,
    DEFAULT_MAX_SCALE,
    DEFAULT_MIN_SCALE,
    SCALE_DIGITS,
    AllocationSettings,
    SourceCost,
    parse_target,
)
from tolsim.study.design.allocate.targets import (
    MAX_COST_SPAN,
    cost_exponent_limit,
    largest_scale,
)
from tolsim.study.spec import SOURCES, set_study_value, toml_lines

#: Keys of an ``[allocate.sources.<source>]`` table and their defaults (``max_scale``:
#: :data:`~tolsim.study.design.allocate.DEFAULT_MAX_SCALE`, lowered to the static model's range).
SOURCE_KEYS = {"min_scale": DEFAULT_MIN_SCALE, "max_scale": None,
               "cost_exponent": DEFAULT_COST_EXPONENT, "cost_weight": DEFAULT_COST_WEIGHT}


def parse_allocation(table, tolerances, bearing) -> AllocationSettings:
    """Read ``[allocate]`` (a :class:`tolsim.io.config.reader.Table`) for the config's
    ``tolerances``.

    Raises
    ------
    tolsim.io.config.ConfigError
        One line naming the key: an unknown key, a bad target, a confidence outside
        (0.5, 1), bounds that are not 0 < min_scale < max_scale, a source the config does
        not draw at random.
    """
    target = None
    if table.has("target"):
        text = table.text("target")
        try:
            target = parse_target(text)
        except ValueError as exc:
            raise table.error("target", f"= {text!r}: {_after_target(exc)}") from None
    confidence = table.quantity("confidence", "dimensionless", default=DEFAULT_CONFIDENCE)
    if not 0.5 < confidence < 1:
        raise table.error("confidence", f"= {confidence!r} must be in (0.5, 1), e.g. 0.95 "
                                        "(one-sided)")
    samples = table.integer("samples", default=0, minimum=1) or None
    verify_samples = table.integer("verify_samples", default=0, minimum=1) or None
    max_evaluations = table.integer("max_evaluations", default=DEFAULT_MAX_EVALUATIONS,
                                    minimum=20)
    given = {t.source: t for t in tolerances}
    sources = []
    sub = table.table("sources", required=False)
    if sub is not None:
        for name in list(sub.data):
            if name not in SOURCES:
                raise sub.error(name, f"is not a known error source ({', '.join(SOURCES)})")
            if name not in given:
                raise sub.error(name, f"has no [tolerances.{name}] in the config to scale")
            if not given[name].distribution.is_random:
                raise sub.error(name, f"has no spread to scale ([tolerances.{name}] is a fixed "
                                      "value: distribution = 'fixed', or a spread of 0)")
            t = sub.table(name)
            values = {key: t.quantity(key, "dimensionless", default=default, positive=True,
                                      required=default is not None)
                      for key, default in SOURCE_KEYS.items()}
            high = DEFAULT_MAX_SCALE if values["max_scale"] is None else values["max_scale"]
            if not values["min_scale"] < high:
                bad = "max_scale" if t.has("max_scale") else "min_scale"
                raise t.error(bad, f"= {t.data.get(bad, values[bad])!r}: min_scale "
                                   f"({values['min_scale']:g}) must be less than max_scale "
                                   f"({high:g})")
            limit = cost_exponent_limit(values["min_scale"], high)
            if values["cost_exponent"] > limit:  # (blame the key written: k, or a bound)
                bad = ("cost_exponent" if t.has("cost_exponent") else "min_scale"
                       if abs(math.log(values["min_scale"])) >= abs(math.log(high))
                       else "max_scale")
                raise t.error(bad, f"= {t.data.get(bad, values[bad])!r}: a cost exponent of "
                                   f"{values['cost_exponent']:g} is beyond {limit:.4g}, the "
                                   f"most the scale range [{values['min_scale']:g}, "
                                   f"{high:g}] allows: the cost w scale^-k would change by "
                                   f"more than e^{MAX_COST_SPAN:g} across it")
            top = largest_scale(given[name], bearing)
            if values["max_scale"] is not None and values["max_scale"] > top:
                raise t.error("max_scale", f"= {t.data['max_scale']!r} takes the tolerance "
                                           "beyond the errors the static model accepts: at "
                                           f"most {top:.4g}")
            t.finish()
            sources.append(SourceCost(name, **values))
        sub.finish()
        if not sources:
            raise table.error("sources", "is empty: list at least one "
                                         "[allocate.sources.<source>], or remove it to "
                                         "allocate every random source")
    table.finish()
    return AllocationSettings(target=target, confidence=float(confidence),
                              sources=tuple(sources), samples=samples,
                              verify_samples=verify_samples, max_evaluations=max_evaluations)


def _after_target(exc) -> str:
    """The message of a target error without its leading ``target '...':``."""
    return re.sub(r"^target '.*?': ", "", str(exc))


# --------------------------------------------------------------------------------------------
# The allocated config
# --------------------------------------------------------------------------------------------
#: A ``scale = ...`` line of a tolerance table.
_SCALE_LINE = re.compile(r"""^(\s*(?:scale|"scale"|'scale')\s*=\s*)([^\s#]+)([ \t]*)(#.*)?"""
                         r"(\r?\n)?$")


def _headers(lines) -> list:
    """(line number, table name, is array) of every table header, outside multi-line
    strings."""
    return [(n, name, array) for n, _, name, array, header in toml_lines(lines) if header]


def format_scale(value: float) -> str:
    """A scale factor as written: :data:`SCALE_DIGITS` significant digits."""
    return f"{float(value):.{SCALE_DIGITS}g}"


def given_scales(text: str) -> dict:
    """source -> the ``scale`` the config text already sets in ``[tolerances.<source>]``
    (1 where it sets none)."""
    tolerances = tomllib.loads(text).get("tolerances", {})
    return {name: float(t.get("scale", 1.0)) for name, t in tolerances.items()
            if isinstance(t, dict)}


def allocated_config_text(text: str, scales: dict, *, samples=None, seed=None,
                          comment: str = "") -> str:
    """The config ``text`` with each source's tolerance times ``scales[source]``.

    In each ``[tolerances.<source>]`` table a ``scale = <s0 s>`` line is inserted after the
    header, or an existing ``scale = s0`` line gets the product s0 s (the scale is relative
    to the config as given). ``samples`` and ``seed`` replace those of ``[study]``
    (:func:`tolsim.study.spec.set_study_value`); ``comment`` lines go on top, each prefixed
    with ``# ``. Everything else, comments included, stays as it is.

    Raises
    ------
    ValueError
        If a source is not written as a ``[tolerances.<source>]`` table (an inline table
        or dotted keys) or is written twice.
    """
    eol = "\r\n" if "\r\n" in text else "\n"
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines[-1] += eol
    headers = _headers(lines)
    before = given_scales(text)
    edits = {}  # line number -> replacement text (may hold two lines)
    for source, scale in scales.items():
        name = f"tolerances.{source}"
        found = [i for i, (_, table, array) in enumerate(headers) if table == name
                 and not array]
        if len(found) != 1:
            how = ("is written twice" if found else "is not written as a "
                   f"[tolerances.{source}] table (an inline table or dotted keys)")
            raise ValueError(f"{name} {how}: write it as one [{name}] table to get an "
                             "allocated config")
        start = headers[found[0]][0]
        end = headers[found[0] + 1][0] if found[0] + 1 < len(headers) else len(lines)
        value = format_scale(before.get(source, 1.0) * scale)
        for number in range(start + 1, end):
            m = _SCALE_LINE.match(lines[number])
            if m:
                head, old, gap, note, end_of_line = m.groups()
                if note:
                    gap = " " * max(1, len(gap) + len(old) - len(value))
                edits[number] = head + value + (gap or "") + (note or "") + (end_of_line or eol)
                break
        else:
            header_eol = "\r\n" if lines[start].endswith("\r\n") else eol
            edits[start] = (lines[start] + f"scale = {value}    # tolsim allocate: the "
                            f"tolerance below times {value}" + header_eol)
    out = "".join(edits.get(i, line) for i, line in enumerate(lines))
    if samples is not None:
        out = set_study_value(out, "samples", int(samples))
    if seed is not None:
        out = set_study_value(out, "seed", int(seed))
    if comment:
        out = "".join(f"# {line}".rstrip() + eol for line in comment.splitlines()) + eol + out
    return out


#: Keys of a distribution that a scale changes, by kind (``mean`` and ``cpk`` stay).
_SCALED_KEYS = {"normal": ("std",), "uniform": ("low", "high"),
                "truncated_normal": ("std", "low", "high"), "cpk": ("low", "high")}


def tolerance_lines(text: str, config, scales: dict) -> dict:
    """The tolerances of ``config`` as given and times ``scales``, in the config's own units.

    Parameters
    ----------
    text : str
        The config's TOML text (for the units its keys are written in).
    config : StudyConfig
        The config as given (its distributions in SI).
    scales : dict
        source -> scale factor relative to the config as given.

    Returns
    -------
    dict
        source -> list of (key, value as given, value allocated) strings, e.g.
        ``("std_deg", "0.1", "0.0734")``; a ``cpk`` source also gets its implied std, an
        ``empirical`` one a note on its measured values.
    """
    raw = tomllib.loads(text).get("tolerances", {})
    out = {}
    for tolerance in config.tolerances:
        if tolerance.source not in scales:
            continue
        s = scales[tolerance.source]
        given, allocated = tolerance.distribution, tolerance.distribution.scaled(s)
        kind = SOURCES[tolerance.source][0]
        keys = raw.get(tolerance.source, {})
        keys = keys if isinstance(keys, dict) else {}
        rows = []
        for name in _SCALED_KEYS.get(given.kind, ()):
            unit = next((k[len(name) + 1:] for k in keys if k.startswith(f"{name}_")
                         and k[len(name) + 1:] in UNITS[kind]), None)
            if unit is None:  # not written (cpk std): in the unit of another key
                unit = next((k.rpartition("_")[2] for k in keys
                             if k.rpartition("_")[2] in UNITS[kind]), next(iter(UNITS[kind])))
            factor = UNITS[kind][unit]
            label = f"{name}_{unit}" if f"{name}_{unit}" in keys else f"{name}_{unit} (implied)"
            rows.append((label, _number(getattr(given, name) / factor),
                         _number(getattr(allocated, name) / factor)))
        if given.kind == "cpk":
            unit = next((k.rpartition("_")[2] for k in keys
                         if k.rpartition("_")[2] in UNITS[kind]), next(iter(UNITS[kind])))
            factor = UNITS[kind][unit]
            rows.append((f"std_{unit} (implied, cpk {given.cpk:g})",
                         _number(given.std / factor), _number(allocated.std / factor)))
        if given.kind == "empirical":
            rows.append(("measured values", "as measured",
                         f"{format_scale(s)} x their spread about their mean"))
        out[tolerance.source] = rows
    return out


def _number(value: float) -> str:
    text = f"{value:.4g}"
    return "0" if text in ("-0", "0") or math.isclose(value, 0.0, abs_tol=1e-300) else text
