"""The result-file variables of a study with ``[contact]`` (issue 13): the carriage friction
of its ball trains (:mod:`tolsim.study.pipeline.track_friction`)."""

import numpy as np

from tolsim.io.schema.declaration import Section
from tolsim.study.statistics.accumulator import QUANTILES
from tolsim.study.statistics.friction import COLUMNS, HISTOGRAM_COLUMNS

_HIST_WHAT = {"friction_increase": "the increase of the worst track's largest carriage "
                                   "friction force over its baseline",
              "friction_ripple": "the ripple (max - min over the stroke) of the worst track's "
                                 "carriage friction force",
              "contact_force_max": "the largest ball-to-ball force of the worst track over "
                                   "the stroke"}
_HIST_COLUMN = {"friction_increase": "increase_max", "friction_ripple": "ripple",
                "contact_force_max": "contact_force_max"}

#: Coordinates of the friction variables: name -> (dims, units, long_name, kind).
FRICTION_COORDINATES = {
    "force_bin": (("force_bin",), "N", "centre of a force histogram bin (friction increase, "
                                       "ripple, contact force)", "f"),
    "force_bin_bounds": (("force_bin", "bounds"), "N", "edges of a force histogram bin", "f"),
    "example": (("example",), "1", "example trajectory number", "i"),
    "travel": (("travel",), "m", "carriage travel since the start of the stroke", "f"),
}

#: Declarations for :mod:`tolsim.io.schema` of the variables of a study with ``[contact]``:
#: name -> (dims, units, long_name, kind). "Worst track": the track of an assembly with the
#: largest friction increase (:mod:`tolsim.study.pipeline.track_friction`); statistics over the
# assemblies
#: whose friction is resolved.
FRICTION_VARIABLES = {
    "ball_friction_coefficient": ((), "1", "Coulomb friction coefficient of the "
                                           "ball-to-ball contacts", "f"),
    "friction_increase_limit": ((), "N", "specification limit on the friction increase "
                                         "(NaN: none)", "f"),
    "friction_force_baseline": ((), "N", "mean over assemblies of the carriage friction "
                                         "force of the worst track without ball-to-ball "
                                         "contact (its free-rolling baseline)", "f"),
    "friction_force_baseline_std": ((), "N", "standard deviation over assemblies of the "
                                             "worst track's free-rolling baseline", "f"),
    "friction_increase_stroke_mean": ((), "N", "mean over assemblies of the time-mean "
                                               "increase of the worst track's carriage "
                                               "friction force over the stroke", "f"),
    "friction_increase_max": ((), "N", "largest friction increase of an assembly", "f"),
    "contact_fraction_mean": ((), "1", "mean over assemblies of the fraction of the stroke "
                                       "with a ball-to-ball contact in the worst track", "f"),
    "clusters_formed_mean": ((), "1", "mean over assemblies of the multi-ball clusters "
                                      "formed in the worst track over the stroke", "f"),
    "friction_exceedance_probability": ((), "1", "probability that the friction increase "
                                                 "exceeds its limit, over the assemblies "
                                                 "whose outcome is known", "f"),
    "friction_exceedance_probability_ci_lower": ((), "1", "lower end of the 95 % "
                                                          "Clopper-Pearson interval of the "
                                                          "friction exceedance probability",
                                                 "f"),
    "friction_exceedance_probability_ci_upper": ((), "1", "upper end of the 95 % "
                                                          "Clopper-Pearson interval of the "
                                                          "friction exceedance probability",
                                                 "f"),
    "friction_exceedance_probability_bound_lower": ((), "1", "lower partial-identification "
                                                             "bound of the friction "
                                                             "exceedance probability", "f"),
    "friction_exceedance_probability_bound_upper": ((), "1", "upper partial-identification "
                                                             "bound of the friction "
                                                             "exceedance probability", "f"),
    "n_assemblies_friction_resolved": ((), "1", "assemblies whose every track was followed "
                                                "over the whole stroke", "i"),
    "n_assemblies_friction_unresolved": ((), "1", "assemblies with an unresolved or sliding "
                                                  "track and no certain exceedance", "i"),
    "n_assemblies_sliding": ((), "1", "assemblies with a ball that slides (push beyond its "
                                      "traction capacity or braking beyond its stall)", "i"),
    "n_assemblies_released": ((), "1", "assemblies with no sliding ball but a ball pushed off "
                                       "its stick line (push beyond the release push of its "
                                       "stuck contact)", "i"),
    "n_friction_exceedance": ((), "1", "assemblies whose friction increase certainly "
                                       "exceeds its limit", "i"),
    "example_assembly": (("example",), "1", "assembly of the example (index in the study)",
                         "i"),
    "example_track": (("example",), "1", "track of the example (the assembly's worst)", "i"),
    "example_friction_force": (("example", "travel"), "N", "carriage friction force of the "
                                                           "example track", "f"),
    "example_friction_force_baseline": (("example",), "N", "carriage friction force of the "
                                                           "example track without "
                                                           "ball-to-ball contact", "f"),
    "example_ball_position": (("example", "travel", "ball"), "m", "ball centre along the rail "
                              "less the nominal travel of a free ball (half the carriage "
                              "travel)", "f"),
    "example_contact_force": (("example", "travel", "pair"), "N", "ball-to-ball contact force "
                              "of the example track", "f"),
}
for _name, _what in _HIST_WHAT.items():
    FRICTION_VARIABLES.update({
        f"{_name}_mean": ((), "N", f"mean over assemblies of {_what}", "f"),
        f"{_name}_std": ((), "N", f"standard deviation over assemblies of {_what}", "f"),
        f"{_name}_quantile": (("quantile",), "N", f"quantile of {_what} (from the "
                                                  "histogram)", "f"),
        f"{_name}_histogram": (("force_bin",), "1", f"number of assemblies per bin of {_what}",
                               "i"),
        f"{_name}_underflow": ((), "1", f"assemblies with {_what} below 0", "i"),
        f"{_name}_overflow": ((), "1", f"assemblies with {_what} above the histogram range",
                              "i"),
    })

# Sobol' indices of the friction increase (tolsim.study.analyses.sensitivity, output
# ``friction_increase``), named like its SENSITIVITY_VARIABLES
for _index, _label in (("first_order", "first-order"), ("total", "total-effect")):
    for _suffix, _end in (("", ""), ("_ci_lower", "lower"), ("_ci_upper", "upper")):
        FRICTION_VARIABLES[f"sensitivity_friction_{_index}{_suffix}"] = (
            ("factor",), "1", f"{_label} variance-based index of the friction increase"
            + (f", {_end} end of the 95 % bootstrap interval" if _end else ""), "f")

#: A sentence for the result file on what the friction figures are (constant propagation).
FRICTION_ASSUMPTIONS = (
    "per assembly the worst track (largest increase of its carriage friction force over its "
    "free-rolling baseline); constant epsilon, event-driven trains, the linear creep model of "
    "the loaded analytic model (K, braking, carriage-force slopes per ball); a train with a "
    "sliding ball is unresolved from the onset of sliding; statistics over the resolved "
    "assemblies, the exceedance probability bounded over all")
#: The same for ``along_track`` propagation.
FRICTION_ASSUMPTIONS_ALONG_TRACK = (
    "per assembly the worst track (largest increase of its carriage friction force over its "
    "free-rolling baseline at the same instant); epsilon and the creep coefficients of each "
    "ball re-evaluated along the track, the cluster rule applied at every midpoint step with "
    "the closing gaps projected (exact for constant epsilon), figures from the step-mean "
    "forces, baseline the time mean of the free-rolling friction; a train with a sliding or "
    "unresolved ball is unresolved from that step; statistics over the resolved assemblies, "
    "the exceedance probability bounded over all")


def friction_variables(result) -> tuple:
    """(coordinates, data variables, attributes) of a study with ``[contact]``.

    ``result``: a :class:`tolsim.study.execution.runner.StudyResult` whose statistics carry
    :class:`~tolsim.study.statistics.friction.FrictionStatistics`
    (``statistics.friction``) and, optionally, its ``friction_examples``.
    """
    config = result.config
    stats = result.statistics.friction
    levels = np.asarray(QUANTILES)
    edges = stats.edges
    coords = {
        "force_bin": (("force_bin",), 0.5 * (edges[:-1] + edges[1:])),
        "force_bin_bounds": (("force_bin", "bounds"), np.stack([edges[:-1], edges[1:]], 1)),
    }
    limit = config.contact.friction_increase_limit
    p, lo, hi = stats.exceedance_probability()
    bounds = stats.exceedance_bounds()
    c = COLUMNS.index
    known = int(stats.count) > 0
    data = {
        "ball_friction_coefficient": float(config.contact.ball_friction_coefficient),
        "friction_increase_limit": float(limit) if limit > 0 else np.nan,
        "friction_force_baseline": stats.column_mean("baseline"),
        "friction_force_baseline_std": stats.column_std("baseline"),
        "friction_increase_stroke_mean": stats.column_mean("increase_mean"),
        "friction_increase_max": float(stats.maximum[c("increase_max")]) if known else np.nan,
        "contact_fraction_mean": stats.column_mean("contact_fraction"),
        "clusters_formed_mean": stats.column_mean("clusters_formed"),
        "friction_exceedance_probability": p,
        "friction_exceedance_probability_ci_lower": lo,
        "friction_exceedance_probability_ci_upper": hi,
        "friction_exceedance_probability_bound_lower": bounds[0],
        "friction_exceedance_probability_bound_upper": bounds[1],
        "n_assemblies_friction_resolved": np.int64(stats.n_resolved),
        "n_assemblies_friction_unresolved": np.int64(stats.n_unresolved),
        "n_assemblies_sliding": np.int64(stats.n_sliding),
        "n_assemblies_released": np.int64(stats.n_released),
        "n_friction_exceedance": np.int64(stats.n_exceed),
    }
    for name, column in _HIST_COLUMN.items():
        h = HISTOGRAM_COLUMNS.index(column)
        data.update({
            f"{name}_mean": stats.column_mean(column),
            f"{name}_std": stats.column_std(column),
            f"{name}_quantile": (("quantile",), stats.quantiles(column, levels)),
            f"{name}_histogram": (("force_bin",), stats.histogram[h]),
            f"{name}_underflow": np.int64(stats.underflow[h]),
            f"{name}_overflow": np.int64(stats.overflow[h]),
        })
    examples = getattr(result, "friction_examples", None)
    if examples is not None and len(examples.assembly):
        coords["example"] = (("example",), np.arange(len(examples.assembly), dtype=np.int64))
        coords["travel"] = (("travel",), np.asarray(examples.travel, dtype=float))
        data.update({
            "example_assembly": (("example",), examples.assembly),
            "example_track": (("example",), examples.track),
            "example_friction_force": (("example", "travel"), examples.friction_force),
            "example_friction_force_baseline": (("example",), examples.baseline),
            "example_ball_position": (("example", "travel", "ball"), examples.ball_position),
            "example_contact_force": (("example", "travel", "pair"), examples.contact_force),
        })
    attrs = {"friction_assumptions": (FRICTION_ASSUMPTIONS_ALONG_TRACK
                                      if config.is_along_track
                                      else FRICTION_ASSUMPTIONS),
             "contact_creep_model": config.contact.creep_model}
    return coords, data, attrs


def collect(result, history=None) -> tuple:
    """(coordinates, data variables, global attributes) of a study with ``[contact]``."""
    if getattr(result.statistics, "friction", None) is None:
        return {}, {}, {}
    return friction_variables(result)


SECTION = Section(collect=collect)
