"""Sobol' indices of a study report: read from the result file, or computed from the
config embedded in it."""

from dataclasses import dataclass

import numpy as np

from tolsim.io.config import ConfigError
from tolsim.reports.result_view import (
    config_of,
)
from tolsim.study.analyses.sensitivity import study_sensitivity

#: Default base-sample size of the sensitivity analysis per propagation mode (the cost is
#: samples x (factors + 2) assemblies; along-track propagation is ~100x dearer per assembly).
SENSITIVITY_SAMPLES = {"constant": 1024, "along_track": 64}


# --------------------------------------------------------------------------------------------
# Sensitivity
# --------------------------------------------------------------------------------------------
@dataclass
class FileSensitivity:
    """Sensitivity indices as stored in a result file (epsilon only)."""

    factors: tuple
    outputs: tuple
    first_order: np.ndarray
    total: np.ndarray
    first_order_ci: np.ndarray
    total_ci: np.ndarray
    n: int = 0
    evaluations: int = 0
    confidence_level: float = 0.95
    reasons: tuple = ()  # why an output's indices are not estimable, '' when they are


def sensitivity_from_file(ds):
    """The indices stored in the file (``factor`` dimension, names in ``factor_name``), or None.

    Reads the variables of :data:`tolsim.io.schema.sensitivity.SENSITIVITY_VARIABLES`:
    epsilon's
    ``sensitivity_first_order`` / ``sensitivity_total`` and, when present, the contact
    indicator's ``sensitivity_contact_*``, the friction increase's ``sensitivity_friction_*``
    (a study with ``[contact]``) and the ``*_ci_lower`` / ``*_ci_upper`` ends.
    """
    # the source names: the factor_name label (schema 2), or the string factor coordinate of
    # older files
    label = "factor_name" if "factor_name" in ds.variables else "factor"
    if "sensitivity_total" not in ds.variables or label not in ds.variables:
        return None
    factors = tuple(str(f) for f in np.asarray(ds[label]))
    d = len(factors)

    def get(name):
        return np.asarray(ds[name], dtype=float) if name in ds.variables else np.full(d, np.nan)

    outputs, first, total, first_ci, total_ci, reasons = [], [], [], [], [], []
    for prefix, output in (("", "velocity_deviation"), ("_contact", "contact"),
                           ("_friction", "friction_increase")):
        if f"sensitivity{prefix}_total" not in ds.variables:
            continue
        outputs.append(output)
        reasons.append(str(ds[f"sensitivity{prefix}_total"].attrs.get("not_estimable", "")))
        first.append(get(f"sensitivity{prefix}_first_order"))
        total.append(get(f"sensitivity{prefix}_total"))
        first_ci.append(np.stack([get(f"sensitivity{prefix}_first_order_ci_lower"),
                                  get(f"sensitivity{prefix}_first_order_ci_upper")], axis=-1))
        total_ci.append(np.stack([get(f"sensitivity{prefix}_total_ci_lower"),
                                  get(f"sensitivity{prefix}_total_ci_upper")], axis=-1))
    return FileSensitivity(factors, tuple(outputs), np.array(first), np.array(total),
                            np.array(first_ci), np.array(total_ci), reasons=tuple(reasons))


def error_bar_lengths(values):
    """Interval half-lengths for an error bar, NaN and infinite ones as 0 (no axis of a
    figure is scaled by them)."""
    return np.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0)


def not_estimable(sens, k) -> str:
    """Why output ``k``'s indices are not estimable ('' when they are, or not known)."""
    reasons = tuple(getattr(sens, "reasons", ()) or ())
    return reasons[k] if k < len(reasons) else ""


def config_error_text(ds) -> str:
    """Why the embedded config cannot be parsed, or '' when it can."""
    try:
        config_of(ds)
    except (ConfigError, KeyError, ValueError) as exc:
        return " ".join(str(exc).split())
    return ""


def compute_sensitivity(ds, samples=None):
    """Sobol' indices from the config embedded in the file (see the module docstring)."""
    config = config_of(ds)
    if samples is None:
        samples = SENSITIVITY_SAMPLES.get(config.study.propagation, 256)
    return study_sensitivity(config, samples=int(samples))
