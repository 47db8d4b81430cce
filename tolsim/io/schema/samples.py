"""The result-file variables of the saved assemblies along ``sample`` (``tolsim run
--save-samples``, issue 17; :mod:`tolsim.study.execution.saved_samples`)."""

import numpy as np

from tolsim.io.schema.declaration import Section
from tolsim.physics.velocity.models import BALL_REGIMES
from tolsim.study.execution.saved_samples import MODEL_FLAGS, PREFIX
from tolsim.study.spec import SOURCES

_UNITS = {"length": "m", "angle": "rad"}

#: Declarations for :mod:`tolsim.io.schema`: name -> (dims, units, long_name, dtype kind).
SAMPLE_VARIABLES = {
    "sample": (("sample",), "1", "assembly index (the first assemblies of the study, in "
               "block order)", "i"),
    **{f"{PREFIX}error_{source}": (("sample", "ball"), _UNITS[kind],
                                   f"value of the tolerance source {source} at the ball",
                                   "f")
       for source, (kind, _) in SOURCES.items()},
    f"{PREFIX}initial_gap": (("sample", "pair"), "m", "gap between adjacent balls at the "
                             "start of the stroke", "f"),
    f"{PREFIX}contact_angle_deviation": (("sample", "ball", "contact"), "rad",
                                         "loaded contact angle deviation of the ball", "f"),
    f"{PREFIX}normal_force": (("sample", "ball", "contact"), "N",
                              "contact force of the ball", "f"),
    f"{PREFIX}velocity_deviation": (("sample", "ball"), "1", "velocity deviation epsilon of "
                                    "the ball (missing: unresolved)", "f"),
    f"{PREFIX}model": (("sample", "ball"), "1", "model that gave epsilon (flag_meanings)",
                       "i"),
    f"{PREFIX}regime": (("sample", "ball"), "1", "regime of the ball at the start of the "
                        "stroke (flag_meanings)", "i"),
    f"{PREFIX}contact_time": (("sample",), "s", "time of the first ball-to-ball contact of "
                              "the train (missing: none within the horizon)", "f"),
    f"{PREFIX}contact_pair": (("sample",), "1", "adjacent pair of the first contact, named "
                              "by its trailing ball; with a carriage track * (balls - 1) + "
                              "trailing ball (-1: none within the horizon)", "i"),
    **{f"{PREFIX}circuit_total_gap_{when}": (("sample", "track"), "m", "sum of the gaps of "
                                             f"the track's ball circuit at the {when} of the "
                                             "stroke (equals the circuit's slack)", "f")
       for when in ("start", "end")},
}


def dataset_variables(config, samples: dict) -> dict:
    """name -> (dims, values) of the ``sample`` variables of a result file."""
    out = {}
    for name, values in samples.items():
        if name == f"{PREFIX}index":
            out["sample"] = (("sample",), values)
            continue
        values = np.array(values)
        dims = SAMPLE_VARIABLES[name][0]
        if config.has_carriage and {"ball", "pair"} & set(dims):
            # (sample, tracks * k, ...) -> (sample, track, k, ...)
            values = values.reshape((len(values), config.n_tracks, -1) + values.shape[2:])
            dims = dims[:1] + ("track",) + dims[1:]
        if name == f"{PREFIX}contact_time":
            values[~np.isfinite(values)] = np.nan  # no contact: missing
        out[name] = (dims, values)
    return out


def flag_attributes() -> dict:
    """CF 3.5 flag attributes of ``sample_model``."""
    return {"flag_values": np.array(list(MODEL_FLAGS), dtype=np.int8),
            "flag_meanings": " ".join(MODEL_FLAGS.values())}


def assign(result, ds):
    """The saved assemblies' variables along ``sample``."""
    if getattr(result, "samples", None):  # the saved assemblies, along ``sample``
        rows = dataset_variables(result.config, result.samples)
        ds = ds.assign_coords(sample=rows.pop("sample")).assign(rows)
    return ds


def finish(result, ds) -> None:
    """The CF 3.5 flags of ``sample_model`` and ``sample_regime``."""
    if "sample_model" in ds:
        ds["sample_model"].attrs.update(flag_attributes())  # CF 3.5 flags
    if "sample_regime" in ds:
        ds["sample_regime"].attrs.update(
            flag_values=np.array(list(BALL_REGIMES), dtype=np.int8),
            flag_meanings=" ".join(BALL_REGIMES.values()))


SECTION = Section(assign=assign, finish=finish)
