"""The result-file variables of a study with Sobol' indices (``[study]
sensitivity_samples``, issue 6; :mod:`tolsim.study.analyses.sensitivity`)."""

import numpy as np

from tolsim.io.schema.declaration import Section
from tolsim.study.analyses.sensitivity import (
    CONTACT,
    FRICTION_INCREASE,
    VELOCITY_DEVIATION,
    SensitivityResult,
)

#: Declarations for :mod:`tolsim.io.schema` of the variables :func:`sensitivity_variables`
#: returns: name -> (dims, units, long_name). All along the ``factor`` dimension (an integer
#: index coordinate; the tolerance source names are the ``factor_name`` label variable). The
#: first two are already declared in the schema.
SENSITIVITY_VARIABLES = {
    f"sensitivity{prefix}_{index}{suffix}": (
        ("factor",), "1",
        f"{label} variance-based index of {what}" + (f", {end} end of the 95 % bootstrap "
                                                     "interval" if end else ""))
    for prefix, what in (("", "epsilon"), ("_contact", "the contact indicator"))
    for index, label in (("first_order", "first-order"), ("total", "total-effect"))
    for suffix, end in (("", ""), ("_ci_lower", "lower"), ("_ci_upper", "upper"))
}


def sensitivity_variables(result: SensitivityResult) -> dict:
    """The result-file variables of a
    :func:`tolsim.study.analyses.sensitivity.study_sensitivity` result.

    Returns
    -------
    dict
        ``"factor"`` -> ndarray of str (the source names, written as the ``factor_name``
        label along ``factor``) and every name of
        :data:`SENSITIVITY_VARIABLES` -> ndarray (d,) (with ``[contact]`` also
        ``sensitivity_friction_*``, declared in :mod:`tolsim.io.schema.friction`), ready for
        ``xarray.Dataset.assign(**{k: (("factor",), v) ...})``.
    """
    out = {"factor": np.array(result.factors, dtype=str)}
    for prefix, output in (("", VELOCITY_DEVIATION), ("_contact", CONTACT),
                           ("_friction", FRICTION_INCREASE)):
        if output not in result.outputs:
            continue
        k = result.outputs.index(output)
        for index, value, ci in (("first_order", result.first_order, result.first_order_ci),
                                 ("total", result.total, result.total_ci)):
            out[f"sensitivity{prefix}_{index}"] = value[k]
            out[f"sensitivity{prefix}_{index}_ci_lower"] = ci[k, :, 0]
            out[f"sensitivity{prefix}_{index}_ci_upper"] = ci[k, :, 1]
    return out


#: Attribute of an output's index variables that says why they are NaN (not estimable,
#: :mod:`tolsim.study.analyses.sensitivity`).
NOT_ESTIMABLE = "not_estimable"
#: Output -> prefix of its variables.
PREFIXES = {VELOCITY_DEVIATION: "", CONTACT: "_contact", FRICTION_INCREASE: "_friction"}


def assign(result, ds):
    """The Sobol' indices along ``factor`` (with its names) and ``sensitivity_samples``."""
    if result.sensitivity is None:
        return ds
    st = result.config.study
    variables = sensitivity_variables(result.sensitivity)
    names = variables.pop("factor")
    ds = ds.assign_coords(factor=("factor", np.arange(len(names), dtype=np.int64)),
                          factor_name=("factor", names))
    ds = ds.assign({name: (("factor",), values) for name, values in variables.items()})
    ds.attrs["sensitivity_samples"] = int(st.sensitivity_samples)
    return ds


def finish(result, ds) -> None:
    """Why an output's indices are not estimable: the :data:`NOT_ESTIMABLE` attribute of its
    index variables and their interval ends."""
    sens = result.sensitivity
    if sens is None:
        return
    for output, reason in zip(sens.outputs, sens.reasons, strict=False):
        if not reason or output not in PREFIXES:
            continue
        for index in ("first_order", "total"):
            for suffix in ("", "_ci_lower", "_ci_upper"):
                name = f"sensitivity{PREFIXES[output]}_{index}{suffix}"
                if name in ds.variables:
                    ds[name].attrs[NOT_ESTIMABLE] = reason


SECTION = Section(assign=assign, finish=finish)
