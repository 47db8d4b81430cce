"""The result-file variables of a study run with a rare-event estimator (issue 15,
:mod:`tolsim.study.analyses.limit_state`)."""

import numpy as np

from tolsim.io.schema.declaration import Section
from tolsim.study.analyses.limit_state import EVENT_KEYS, EVENT_PROBABILITY
from tolsim.study.analyses.rare_events import ESTIMATOR_TITLES


def _probability_declarations(prefix, what):
    """The probability, interval and bounds of an event (name -> (dims, units, long_name,
    kind)), worded for any estimator (its method in the ``interval`` attribute)."""
    return {
        f"{prefix}_ci_lower": ((), "1", f"lower end of the 95 % interval of the {what} "
                                        "(its method in the interval attribute)", "f"),
        f"{prefix}_ci_upper": ((), "1", f"upper end of the 95 % interval of the {what} "
                                        "(its method in the interval attribute)", "f"),
        f"{prefix}_bounds_ci_lower": ((), "1", f"lower end of the 95 % interval of the lower "
                                               f"bound of the {what}", "f"),
        f"{prefix}_bounds_ci_upper": ((), "1", f"upper end of the 95 % interval of the upper "
                                               f"bound of the {what}", "f"),
    }


#: The interval variables of the contact and friction probabilities, worded for any estimator
#: (:mod:`tolsim.io.schema` declares them so, and accepts the former "Clopper-Pearson" wording
#: in files written before issue 15).
INTERVAL_VARIABLES = {
    **_probability_declarations("contact_probability", "contact probability"),
    **{name: decl for name, decl in _probability_declarations(
        "friction_exceedance_probability", "friction exceedance probability").items()
       if "bounds" not in name},
}

_FACTOR = ("factor",)
#: name -> (dims, units, long_name, dtype kind): the variables of a rare-event estimator
#: (:mod:`tolsim.io.schema` declares them, optional), for each event of
#: :data:`tolsim.study.analyses.limit_state.EVENTS`.
RARE_EVENT_VARIABLES = {
    "velocity_deviation_exceedance_probability": (
        (), "1", "probability that an assembly has a ball with |epsilon| above its limit, over "
                 "the assemblies whose outcome is known", "f"),
    "velocity_deviation_exceedance_probability_bound_lower": (
        (), "1", "lower partial-identification bound of the velocity deviation exceedance "
                 "probability: unresolved assemblies within the limit", "f"),
    "velocity_deviation_exceedance_probability_bound_upper": (
        (), "1", "upper partial-identification bound of the velocity deviation exceedance "
                 "probability: unresolved assemblies beyond the limit", "f"),
    **_probability_declarations("velocity_deviation_exceedance_probability",
                                "velocity deviation exceedance probability"),
    **{name: decl for name, decl in _probability_declarations(
        "friction_exceedance_probability", "friction exceedance probability").items()
       if "bounds" in name},
}
for _event, _prefix in EVENT_PROBABILITY.items():
    _what = _prefix.replace("_", " ")
    RARE_EVENT_VARIABLES.update({
        f"{_prefix}_coefficient_of_variation": ((), "1", f"coefficient of variation of the "
                                                         f"{_what} estimate", "f"),
        f"{_prefix}_evaluations": ((), "1", f"assemblies evaluated by the estimator of the "
                                            f"{_what}", "i"),
        f"{_prefix}_unresolved_evaluations": ((), "1", f"assemblies evaluated by the estimator "
                                                       f"of the {_what} that no model could "
                                                       "resolve", "i"),
        f"{_event}_reliability_index": ((), "1", f"reliability index beta of the {_what}: "
                                                 "distance of the most probable design point "
                                                 "from the origin of the standard-normal "
                                                 "space", "f"),
        f"{_event}_form_probability": ((), "1", f"first-order (FORM) estimate of the {_what}: "
                                                "sum over the components of Phi(-beta)", "f"),
        f"{_event}_design_point_length": (_FACTOR, "m", f"value of a length tolerance source "
                                                        f"at the design point of the {_what} "
                                                        "(NaN for angles)", "f"),
        f"{_event}_design_point_angle": (_FACTOR, "rad", f"value of an angle tolerance source "
                                                         f"at the design point of the {_what} "
                                                         "(NaN for lengths)", "f"),
        f"{_event}_design_point_standard_normal": (_FACTOR, "1", f"standard-normal coordinate "
                                                                 f"of the source's value at "
                                                                 f"the design point of the "
                                                                 f"{_what}", "f"),
        f"{_event}_design_point_element": (_FACTOR, "1", "ball, pair or track whose value is "
                                                         f"given at the design point of the "
                                                         f"{_what}", "i"),
        f"{_event}_importance_factor": (_FACTOR, "1", f"FORM importance factor (sum of alpha "
                                                      f"squared over the source's columns) at "
                                                      f"the design point of the {_what}", "f"),
    })

#: Where the seeds of the estimators come from, for the result file.
SEED_STREAMS = ("SeedSequence(seed, spawn_key=(4, k)), k: "
                + ", ".join(f"{event} {key}" for event, key in EVENT_KEYS.items()))


def estimator_settings(config) -> str:
    """The estimator's settings in one line (result-file attribute)."""
    st = config.study
    text = (f"samples_per_level {st.samples_per_level}, p0 {st.p0:g}, max_levels "
            f"{st.max_levels}")
    if st.estimator == "importance":
        text = f"importance_samples {st.importance_samples}; fallback subset: {text}"
    return text


def rare_event_variables(result) -> tuple:
    """(factor names or None, data variables, variable attributes, global attributes) of a
    study run with a rare-event estimator (``result.rare_events``).

    The events' probability variables (``contact_probability`` ...) are the estimator's, with
    the attributes ``estimator``, ``estimator_status``, ``interval``, ``estimator_seconds``
    (wall time) and, when it has something to say, ``estimator_note`` (a fallback) or
    ``estimator_message`` (no number); the plain run's
    counts (``n_contact`` ...) stay. Importance sampling adds the design point along
    ``factor`` (names: :func:`tolsim.study.analyses.sensitivity.study_factors`).
    """
    config = result.config
    data, attrs, factors = {}, {}, None
    for event, estimate in result.rare_events.items():
        r = estimate.result
        prefix = EVENT_PROBABILITY[event]
        values = {
            prefix: r.probability, f"{prefix}_ci_lower": r.ci_lower,
            f"{prefix}_ci_upper": r.ci_upper, f"{prefix}_bound_lower": r.bound_lower,
            f"{prefix}_bound_upper": r.bound_upper, f"{prefix}_bounds_ci_lower":
            r.bounds_ci_lower, f"{prefix}_bounds_ci_upper": r.bounds_ci_upper,
            f"{prefix}_coefficient_of_variation": r.coefficient_of_variation,
        }
        data.update({name: float(value) for name, value in values.items()})
        data[f"{prefix}_evaluations"] = np.int64(r.evaluations)
        data[f"{prefix}_unresolved_evaluations"] = np.int64(r.unresolved)
        tag = {"estimator": r.estimator, "estimator_status": r.status}
        for name in values:
            attrs[name] = dict(tag)
        attrs[prefix].update(interval=r.interval, estimator_seconds=float(estimate.seconds))
        attrs[f"{prefix}_ci_lower"].update(interval=r.interval)
        attrs[f"{prefix}_ci_upper"].update(interval=r.interval)
        if estimate.note:
            attrs[prefix]["estimator_note"] = estimate.note
        if not r.ok:
            attrs[prefix]["estimator_message"] = r.message
        if r.estimator == "importance" and r.ok:
            design = estimate.design_point
            factors = design.factors
            length = np.array([k == "length" for k in design.kinds], dtype=bool)
            data.update({
                f"{event}_reliability_index": float(r.beta),
                f"{event}_form_probability": float(r.form_probability),
                f"{event}_design_point_length": (_FACTOR, np.where(length, design.value,
                                                                   np.nan)),
                f"{event}_design_point_angle": (_FACTOR, np.where(length, np.nan,
                                                                  design.value)),
                f"{event}_design_point_standard_normal": (_FACTOR, design.standard_normal),
                f"{event}_design_point_element": (_FACTOR, design.element),
                f"{event}_importance_factor": (_FACTOR, design.importance_factor),
            })
            attrs[f"{event}_reliability_index"] = {
                "design_point_component": design.component,
                "design_point_description": design.describe(tracks=config.n_tracks)}
    contact = result.rare_events.get("contact")
    glob = {"estimator": config.study.estimator,
            "estimator_settings": estimator_settings(config),
            "rare_event_seed_streams": SEED_STREAMS}
    if contact is not None:
        glob["contact_probability_interval"] = (
            f"{ESTIMATOR_TITLES[contact.result.estimator]}: {contact.result.interval}, 95 %, "
            "over the assemblies whose outcome is known; bounds with the unresolved ones "
            "counted as no contact / contact, and the interval covering them")
    return factors, data, attrs, glob


def assign(result, ds):
    """The estimator's variables (and the design point's ``factor``) and global attributes."""
    if not getattr(result, "rare_events", None):
        return ds
    factors, rare_data, _, rare_globals = rare_event_variables(result)
    if factors is not None and "factor" not in ds.coords:
        ds = ds.assign_coords(factor=("factor", np.arange(len(factors), dtype=np.int64)),
                              factor_name=("factor", np.array(factors, dtype=str)))
    ds = ds.assign(rare_data)
    ds.attrs.update(rare_globals)
    return ds


def finish(result, ds) -> None:
    """The estimator's attributes of its variables (``estimator``, ``interval`` ...)."""
    if not getattr(result, "rare_events", None):
        return
    for name, attrs in rare_event_variables(result)[2].items():
        ds[name].attrs.update(attrs)


SECTION = Section(assign=assign, finish=finish)
