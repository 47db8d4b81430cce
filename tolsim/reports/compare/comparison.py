"""The runs of ``tolsim compare`` compared in memory: the config keys that differ and the
:class:`Comparison` of two or more result Datasets."""

import os
import tomllib
from dataclasses import dataclass, field

from tolsim.reports.compare.statistics import (
    CONFIDENCE_LEVEL,
    PAIRING_INDEPENDENT,
    PAIRING_SHARED,
    bounds_difference,
    difference,
    run_statistics,
    shares_random_numbers,
)
from tolsim.reports.result_view import integer

# --------------------------------------------------------------------------------------------
# Config differences
# --------------------------------------------------------------------------------------------
#: Marker of a key that a run's config does not have.
ABSENT = object()


def _key_part(key) -> str:
    bare = key.replace("_", "").replace("-", "").isalnum() and key.isascii()
    return key if bare else '"' + key.replace("\\", "\\\\").replace('"', '\\"') + '"'


def flatten_config(mapping, prefix="") -> dict:
    """A parsed TOML config as {dotted key: value}.

    Tables become dotted keys (``tolerances.top_rotation.cpk``); an array of tables gets an
    index (``carriage.track[0].x_mm``); other arrays stay values. Keys that are not bare TOML
    keys are quoted.
    """
    out = {}
    for key, value in mapping.items():
        name = f"{prefix}{_key_part(str(key))}"
        if isinstance(value, dict):
            out.update(flatten_config(value, f"{name}."))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            for i, item in enumerate(value):
                out.update(flatten_config(item, f"{name}[{i}]."))
        else:
            out[name] = value
    return out


def toml_value(value) -> str:
    """A config value as TOML writes it (``"normal"``, ``0.1``, ``true``, ``[1, 2]``)."""
    if value is ABSENT:
        return "—"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key_part(k)} = {toml_value(v)}"
                                for k, v in value.items()) + " }"
    return str(value)


@dataclass(frozen=True)
class ConfigDifference:
    """A config key whose value differs between runs.

    Attributes
    ----------
    key : str
        Dotted key.
    values : tuple
        Its value in every run, :data:`ABSENT` where a run does not have it.
    """

    key: str
    values: tuple

    @property
    def texts(self) -> tuple:
        """The values as TOML text, "—" where absent."""
        return tuple(toml_value(v) for v in self.values)


def config_differences(texts) -> tuple:
    """The keys whose values differ between configs given as TOML text.

    Parameters
    ----------
    texts : sequence of str
        The config text of every run (the ``config`` attribute of a result file).

    Returns
    -------
    (differences, unreadable) : (list of ConfigDifference, list of int)
        The keys that differ, or that only some runs have, sorted as they first appear in
        the configs; and the indices of the texts that are not valid TOML (their keys are
        left out).
    """
    flat, unreadable = [], []
    for i, text in enumerate(texts):
        try:
            flat.append(flatten_config(tomllib.loads(str(text))))
        except tomllib.TOMLDecodeError:
            flat.append(None)
            unreadable.append(i)
    readable = [f for f in flat if f is not None]
    order = {}
    for f in readable:
        for key in f:
            order.setdefault(key, len(order))
    out = []
    for key in sorted(order, key=order.get):
        values = tuple(f.get(key, ABSENT) for f in readable)
        first = values[0]
        if any(v is ABSENT for v in values) or any(_differ(first, v) for v in values[1:]):
            out.append(ConfigDifference(key, tuple(
                ABSENT if f is None else f.get(key, ABSENT) for f in flat)))
    return out, unreadable


def _differ(a, b) -> bool:
    # 1 and 1.0 are the same number in a config; True and 1 are not the same value
    if isinstance(a, bool) or isinstance(b, bool):
        return type(a) is not type(b) or a != b
    return a != b


# --------------------------------------------------------------------------------------------
# The comparison
# --------------------------------------------------------------------------------------------
@dataclass
class Run:
    """One compared result: its label, file, Dataset and statistics."""

    label: str
    path: str
    ds: object
    statistics: dict = field(default_factory=dict)  # name -> Statistic
    shares_random_numbers: bool = False  # with the reference (False for the reference)

    @property
    def pairing(self) -> str:
        return PAIRING_SHARED if self.shares_random_numbers else PAIRING_INDEPENDENT


@dataclass
class Comparison:
    """Runs side by side (:func:`compare_datasets`).

    Attributes
    ----------
    runs : list of Run
        The reference first.
    names : list of str
        Statistic names in display order (the union over the runs).
    differences : dict
        (statistic name, run label) -> Difference to the reference, for every run but the
        reference that has the statistic when the reference has it too.
    bound_differences : dict
        run label -> :func:`bounds_difference` to the reference, when trains are unresolved.
    config : list of ConfigDifference
    unreadable_configs : list of str
        Labels of runs whose config text is not valid TOML.
    confidence_level : float
    """

    runs: list
    names: list
    differences: dict
    bound_differences: dict
    config: list
    unreadable_configs: list
    confidence_level: float = CONFIDENCE_LEVEL

    @property
    def reference(self) -> Run:
        return self.runs[0]

    def statistic(self, name):
        """The first run's :class:`Statistic` of that name (for its description, units)."""
        return next(r.statistics[name] for r in self.runs if name in r.statistics)


def run_labels(paths) -> list:
    """Short labels of result files: the file names without ``.nc``, numbered when two are
    the same."""
    stems = [os.path.splitext(os.path.basename(os.fspath(p)))[0] or "run" for p in paths]
    out = []
    for i, stem in enumerate(stems):
        label = stem if stems.count(stem) == 1 else f"{stem} ({stems[:i + 1].count(stem)})"
        out.append(label)
    return out


def compare_datasets(datasets, labels=None, paths=None,
                     confidence_level=CONFIDENCE_LEVEL) -> Comparison:
    """Compare results held in memory, the first one being the reference.

    Parameters
    ----------
    datasets : sequence of xarray.Dataset
        At least two results of ``tolsim run``.
    labels : sequence of str, optional
        Their names in the report (default: ``run 1``, ``run 2``, ...).
    paths : sequence of str, optional
        Their files (shown in the report; default: the labels).
    confidence_level : float

    Returns
    -------
    Comparison
    """
    datasets = list(datasets)
    if len(datasets) < 2:
        raise ValueError(f"need at least two results to compare, got {len(datasets)}")
    labels = list(labels) if labels is not None else [f"run {i + 1}"
                                                       for i in range(len(datasets))]
    paths = [os.fspath(p) for p in paths] if paths is not None else list(labels)
    bounds = any(integer(ds, "n_assemblies_unresolved") > 0 for ds in datasets)
    runs, names = [], []
    for i, (ds, label, path) in enumerate(zip(datasets, labels, paths, strict=True)):
        stats = run_statistics(ds, bounds=bounds, confidence_level=confidence_level)
        shared = i > 0 and shares_random_numbers(datasets[0].attrs, ds.attrs)
        runs.append(Run(label, path, ds, {s.name: s for s in stats}, shared))
        names += [s.name for s in stats if s.name not in names]
    reference = runs[0]
    differences, bound_differences = {}, {}
    for run in runs[1:]:
        for name, stat in run.statistics.items():
            ref = reference.statistics.get(name)
            if ref is not None:
                differences[(name, run.label)] = difference(stat, ref, run.pairing,
                                                            confidence_level)
        if bounds:
            bound_differences[run.label] = bounds_difference(run.statistics,
                                                             reference.statistics,
                                                             confidence_level)
    config, unreadable = config_differences([ds.attrs.get("config", "") for ds in datasets])
    return Comparison(runs, names, differences, bound_differences, config,
                      [labels[i] for i in unreadable], confidence_level)
