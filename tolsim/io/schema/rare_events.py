"""The result-file variables of a study run with a rare-event estimator (issue 15,
:mod:`tolsim.study.analyses.limit_state`): per event the estimate, its status (a CF flag
variable) and diagnostics (issue 23), and with ``estimator = "rare"`` both estimators'
numbers."""

import numpy as np

from tolsim.io.schema.core import plain_probability_attributes
from tolsim.io.schema.declaration import Section
from tolsim.study.analyses.limit_state import EVENT_KEYS, EVENT_PROBABILITY
from tolsim.study.analyses.rare_events import ESTIMATOR_TITLES, STATUSES


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

#: The estimator's status as a CF 3.5 flag: value -> :data:`~tolsim.study.analyses.
#: rare_events.STATUSES` name (``flag_meanings``).
STATUS_FLAGS = dict(enumerate(STATUSES))
#: Diagnostics of an estimate: suffix -> (RareEventResult field, kind, long name, the
#: estimators that compute it).
DIAGNOSTICS = {
    "effective_sample_size": ("effective_sample_size", "f", "Kish effective number of the "
                              "failing importance samples", ("importance", "rare")),
    "largest_weight_share": ("largest_weight_share", "f", "largest failing importance weight "
                             "over their sum", ("importance", "rare")),
    "form_ratio": ("form_ratio", "f", "FORM estimate over the importance-sampling estimate",
                   ("importance", "rare")),
    "ancestors": ("ancestors", "i", "level-0 samples of subset simulation that its last "
                  "level's failing samples descend from", ("subset", "rare")),
    "level_independent_coefficient_of_variation": (
        "level_independent_cv", "f", "coefficient of variation of the subset-simulation "
        "estimate with its levels taken as independent", ("subset", "rare")),
}
#: ``estimator = "rare"``: each estimator's own estimate, suffix ``_subset`` /
#: ``_importance`` after the probability's name and before these; on an event that is not
#: smooth, the two subset simulation runs, ``_replicate_1`` / ``_replicate_2``.
PART_VALUES = {"": ("probability", "f", "estimate"),
               "_ci_lower": ("ci_lower", "f", "lower end of the 95 % interval"),
               "_ci_upper": ("ci_upper", "f", "upper end of the 95 % interval"),
               "_coefficient_of_variation": ("coefficient_of_variation", "f",
                                             "coefficient of variation"),
               "_evaluations": ("evaluations", "i", "assemblies evaluated"),
               "_status": ("status", "i", "status (flag_meanings; the message in the "
                                          "estimator_message attribute)")}
PART_TITLES = {"subset": "subset simulation", "importance": "importance sampling",
               "replicate_1": "the first subset simulation run",
               "replicate_2": "the second subset simulation run"}
#: When each part is written.
PART_WHEN = {"subset": "estimator = rare", "importance": "estimator = rare",
             "replicate_1": "a limit state that is not smooth",
             "replicate_2": "a limit state that is not smooth"}
for _event, _prefix in EVENT_PROBABILITY.items():
    _what = _prefix.replace("_", " ")
    RARE_EVENT_VARIABLES[f"{_prefix}_status"] = (
        (), "1", f"status of the estimate of the {_what} (flag_meanings; ok: the estimator "
                 "backs it; the reason in the estimator_message attribute)", "i")
    for _suffix, (_, _kind, _long, _) in DIAGNOSTICS.items():
        RARE_EVENT_VARIABLES[f"{_prefix}_{_suffix}"] = (
            (), "1", f"{_long}, for the {_what}", _kind)
    for _part, _title in PART_TITLES.items():
        for _suffix, (_, _kind, _long) in PART_VALUES.items():
            RARE_EVENT_VARIABLES[f"{_prefix}_{_part}{_suffix}"] = (
                (), "1", f"{_title}'s {_long} of the {_what} ({PART_WHEN[_part]})", _kind)


def status_flag(status) -> np.int8:
    """The flag value of a status name (:data:`STATUS_FLAGS`)."""
    return np.int8(list(STATUS_FLAGS.values()).index(status))


def flag_attributes() -> dict:
    """CF 3.5 flag attributes of a ``*_status`` variable."""
    return {"flag_values": np.array(list(STATUS_FLAGS), dtype=np.int8),
            "flag_meanings": " ".join(STATUS_FLAGS.values())}


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
    elif st.estimator == "rare":
        text = f"importance_samples {st.importance_samples}; subset: {text}"
    return text


#: The events whose probability the plain run estimates too (``n_contact`` of the trains,
#: ``n_velocity_deviation_exceedance`` and ``n_friction_exceedance`` of the assemblies, with
#: their Clopper-Pearson intervals).
PLAIN_RUN_EVENTS = ("contact", "velocity_deviation_exceedance", "friction_exceedance")
#: The probability variables' suffixes in the order of
#: :meth:`tolsim.study.statistics.accumulator.Accumulator.exceedance_probability`.
_PLAIN_SUFFIXES = ("", "_ci_lower", "_ci_upper", "_bound_lower", "_bound_upper",
                   "_bounds_ci_lower", "_bounds_ci_upper")


def plain_run_kept(event, estimate) -> bool:
    """Whether the event's probability variables keep the plain run's Monte Carlo numbers:
    the estimator gave no number (it did not reach the event) and the plain run has one."""
    return event in PLAIN_RUN_EVENTS and not np.isfinite(estimate.result.probability)


def plain_run_values(event, statistics) -> dict:
    """name -> value of the plain run's probability, interval and bounds of an event that
    only this section writes (``velocity_deviation_exceedance``: the plain run's counts
    ``n_velocity_deviation_exceedance`` of the assemblies whose outcome is known); {} for the
    events whose probability the core and friction sections write anyway."""
    if event != "velocity_deviation_exceedance":
        return {}
    prefix = EVENT_PROBABILITY[event]
    return {f"{prefix}{suffix}": float(value) for suffix, value in
            zip(_PLAIN_SUFFIXES, statistics.exceedance_probability(), strict=True)}


def plain_run_note(estimate) -> str:
    """The ``estimator_fallback`` of a probability that keeps the plain run's numbers."""
    r = estimate.result
    return (f"{ESTIMATOR_TITLES.get(r.estimator, r.estimator)} did not reach the event "
            f"({r.status}; why in the estimator_message attribute of the _status variable): "
            "the value, interval and bounds are the plain Monte Carlo run's, k of the n "
            "assemblies whose outcome is known with the Clopper-Pearson interval (an upper "
            "bound when k = 0)")


def rare_event_variables(result) -> tuple:
    """(factor names or None, data variables, variable attributes, global attributes) of a
    study run with a rare-event estimator (``result.rare_events``).

    The events' probability variables (``contact_probability`` ...) are the estimator's, with
    the attributes ``estimator``, ``estimator_status``, ``interval``, ``estimator_seconds``
    (wall time) and, when it has something to say, ``estimator_note`` (a fallback) or
    ``estimator_message`` (why the estimate is not ``ok``: no number, or a number kept with
    a failed diagnostic or a disagreement), and where subset simulation gave or checked the
    number ``estimator_mode_check``: ``design_points`` (checked for a lost failure mode against
    FORM's design points of the event's components), ``replicates`` (a limit state that is not
    smooth: checked by the agreement of two independent runs, ``*_replicate_1``,
    ``*_replicate_2``) or ``none`` (unchecked: no design point found); the plain run's counts
    (``n_contact`` ...) stay. Where the estimator gives no number (``no_failure``,
    ``plateau``, ``form_failed``: it did not reach the event) and the plain run has one
    (:data:`PLAIN_RUN_EVENTS`), the probability, interval and bounds stay the plain run's
    (``estimator`` ``monte_carlo``, ``interval`` Clopper-Pearson, with an
    ``estimator_fallback`` attribute saying so; for the |epsilon| exceedance, which only a
    study with an estimator writes, from the plain run's ``n_velocity_deviation_exceedance``
    and ``n_assemblies_velocity_deviation_unresolved``): a study whose estimator failed still
    reports what its plain run resolved, and its verdict rests on that interval; the
    estimator's own status, message and wall time are on ``*_status`` and its CV and
    evaluations on their variables.
    Per event also ``*_status`` (the status as a CF flag) and the diagnostics of the
    estimator (:data:`DIAGNOSTICS`); with ``estimator = "rare"`` each estimator's own
    estimate (``*_subset``, ``*_importance``: :data:`PART_VALUES`). Importance sampling adds
    the design point along ``factor`` (names:
    :func:`tolsim.study.analyses.sensitivity.study_factors`).
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
        tag = {"estimator": r.estimator, "estimator_status": r.status}
        kept = plain_run_kept(event, estimate)
        plain = {}
        if kept:  # the plain run's numbers stay: contact's and friction's written and labelled
            # monte_carlo by their sections, the |epsilon| exceedance's here
            values = {name: value for name, value in values.items()
                      if name == f"{prefix}_coefficient_of_variation"}
            plain = plain_run_values(event, result.statistics)  # those written here
        data.update({name: float(value) for name, value in values.items()})
        data.update(plain)
        data[f"{prefix}_evaluations"] = np.int64(r.evaluations)
        data[f"{prefix}_unresolved_evaluations"] = np.int64(r.unresolved)
        for name in values:
            attrs[name] = dict(tag)
        for name in plain:
            attrs[name] = plain_probability_attributes(name)
        if kept:
            attrs[prefix] = {"estimator_fallback": plain_run_note(estimate),
                             **({"estimator_note": estimate.note} if estimate.note else {}),
                             **attrs.get(prefix, {})}
        else:
            attrs[prefix].update(interval=r.interval,
                                 estimator_seconds=float(estimate.seconds))
            attrs[f"{prefix}_ci_lower"].update(interval=r.interval)
            attrs[f"{prefix}_ci_upper"].update(interval=r.interval)
            if estimate.note:
                attrs[prefix]["estimator_note"] = estimate.note
            if r.message:
                attrs[prefix]["estimator_message"] = r.message
            if estimate.mode_check:
                attrs[prefix]["estimator_mode_check"] = estimate.mode_check
        data[f"{prefix}_status"] = status_flag(r.status)
        attrs[f"{prefix}_status"] = {**tag, **flag_attributes(),
                                     **({"estimator_message": r.message} if r.message else {}),
                                     "estimator_seconds": float(estimate.seconds)}
        for suffix, (field, kind, _, estimators) in DIAGNOSTICS.items():
            if r.estimator in estimators:
                value = getattr(r, field)
                data[f"{prefix}_{suffix}"] = np.int64(value) if kind == "i" else float(value)
        for part, p in estimate.parts.items():
            for suffix, (field, kind, _) in PART_VALUES.items():
                name = f"{prefix}_{part}{suffix}"
                value = getattr(p, field)
                data[name] = (status_flag(value) if suffix == "_status" else
                              np.int64(value) if kind == "i" else float(value))
                attrs[name] = {"estimator": p.estimator, "estimator_status": p.status}
            attrs[f"{prefix}_{part}"]["interval"] = p.interval
            attrs[f"{prefix}_{part}_status"].update(flag_attributes())
            if p.message:
                attrs[f"{prefix}_{part}_status"]["estimator_message"] = p.message
        if estimate.design_point is not None:
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
    if contact is not None and not plain_run_kept("contact", contact):
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
