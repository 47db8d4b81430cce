"""The result-file variables of the worst case and RSS of the linearised stack-up (issue 17,
:mod:`tolsim.study.analyses.worst_case`)."""

import numpy as np

from tolsim.io.schema.declaration import Section
from tolsim.study.analyses.worst_case import LinearStackup

#: Declarations for :mod:`tolsim.io.schema` of the variables :func:`stackup_variables`
#: returns: name -> (dims, units, long_name, dtype kind).
STACKUP_VARIABLES = {
    "velocity_deviation_nominal": (("ball",), "1", "epsilon per train position with every "
                                   "tolerance source at its mean", "f"),
    "velocity_deviation_worst_case": (("ball",), "1", "worst-case excursion of epsilon from "
                                      "its nominal value over the tolerance bands, "
                                      "linearised", "f"),
    "velocity_deviation_rss": (("ball",), "1", "root-sum-square (linearised standard "
                               "deviation) of epsilon from the tolerance sources", "f"),
    "gap_closure_nominal": (("pair",), "m", "closure of the gap of an adjacent pair over "
                            "the horizon, (epsilon_j - epsilon_j+1) v/2 T, with every "
                            "tolerance source at its mean", "f"),
    "gap_closure_worst_case": (("pair",), "m", "worst-case excursion of the gap closure "
                               "from its nominal value over the tolerance bands, "
                               "linearised", "f"),
    "gap_closure_rss": (("pair",), "m", "root-sum-square (linearised standard deviation) "
                        "of the gap closure from the tolerance sources", "f"),
    "critical_ball": ((), "1", "train position with the largest RSS of epsilon", "i"),
    "critical_pair": ((), "1", "adjacent pair with the largest nominal + 3 RSS gap closure",
                      "i"),
}


def stackup_variables(stackup: LinearStackup) -> dict:
    """The result-file variables of a :class:`~tolsim.study.analyses.worst_case.LinearStackup`:
    name -> (dims, values)."""
    return {name: (dims, np.asarray(getattr(stackup, name),
                                    dtype=np.int64 if kind == "i" else np.float64))
            for name, (dims, _, _, kind) in STACKUP_VARIABLES.items()}


def assign(result, ds):
    """The stack-up's variables, when the study has one."""
    if getattr(result, "stackup", None) is not None:  # worst case and RSS
        ds = ds.assign(stackup_variables(result.stackup))
    return ds


SECTION = Section(assign=assign)
