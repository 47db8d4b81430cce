"""The one declared schema of a tolsim study result file (netCDF, CF-1.10).

Every variable the writer may put in a result file is declared here with its dimensions,
``units`` (UDUNITS; ``1`` for dimensionless values and counts) and ``long_name``;
:func:`validate` checks a Dataset against the declaration before it is written and when a
file is read back. Variables marked ``required=False`` are optional (e.g. the sensitivity
variables along the ``factor`` dimension that the report issue adds); a variable that is not
declared is an error, so the schema stays the single place that defines the file.

Dimensions: ``quantile`` (levels), ``velocity_deviation_bin`` (histogram bins of epsilon),
``elapsed_time`` (survival-curve times since the start of the stroke = the edges of the time
bins), ``time_bin``, ``ball`` (position in the train, 0 = trailing), ``pair`` (adjacent pairs,
named by their trailing ball), ``spot_check``, ``contact`` (4), ``bounds`` (2), ``factor``
(tolerance sources, optional), ``sample`` (the saved assemblies, optional); a study with a
carriage adds ``track`` (its rows of balls; the per-ball and per-pair variables gain it as their
first dim), ``carriage_translation`` (u_x, u_y), ``carriage_rotation`` (pitch, yaw, roll),
``carriage_force_component`` and ``carriage_moment_component``; a study with ``[contact]``
adds ``force_bin`` (force histogram bins) and, with examples, ``example`` and ``travel``
(carriage travel of the example trajectories).

A study run with a rare-event estimator (``[study] estimator``, issue 15) reports that
estimator's numbers in the events' probability variables (``contact_probability`` ...,
attribute ``estimator``; every file marks its plain Monte Carlo numbers ``monte_carlo``) and
adds the variables declared in :mod:`tolsim.study.analyses.limit_state` (coefficient of variation,
evaluations, the |epsilon| exceedance, and for importance sampling the design point along
``factor``). The interval variables of the contact and friction probabilities are therefore
worded for any estimator (its method in their ``interval`` attribute); files written before
keep their "Clopper-Pearson" long names, which :func:`validate` still accepts.

The file passes the CF checker (``compliance-checker --test=cf:1.10``, see
``tests/test_cf_compliance.py``): coordinate variables are numeric, strictly monotonic and
without ``_FillValue`` (:func:`tolsim.io.netcdf.write_dataset`); the names along ``contact``
(BL, BR, TR, TL) and ``factor`` are string label variables ``contact_name`` / ``factor_name``
(CF 6.1 labels, auxiliary coordinates listed in the ``coordinates`` attribute of the variables
along those dimensions) beside integer index coordinates. The stroke time is ``elapsed_time``,
not ``time``: it is a duration in ``s``, not a CF time coordinate (``units`` "... since
<epoch>", ``standard_name = "time"``), and a variable named ``time`` is taken for one.
"""

from dataclasses import dataclass

from tolsim.study.analyses.limit_state import INTERVAL_VARIABLES, RARE_EVENT_VARIABLES
from tolsim.study.analyses.sensitivity import SENSITIVITY_VARIABLES
from tolsim.study.analyses.worst_case import STACKUP_VARIABLES
from tolsim.study.execution.saved_samples import SAMPLE_VARIABLES
from tolsim.study.pipeline.carriage import CARRIAGE_COORDINATES, CARRIAGE_VARIABLES
from tolsim.study.pipeline.track_friction import FRICTION_COORDINATES, FRICTION_VARIABLES
from tolsim.study.statistics.quality import QUALITY_VARIABLES

#: Value of the ``Conventions`` global attribute.
CONVENTIONS = "CF-1.10"
#: Global attribute that marks a tolsim result (``tolsim_schema``) and its version.
SCHEMA_VERSION = "2"  # 2: elapsed_time, contact_name, factor_name
#: Required global attributes (all strings except ``seed``).
GLOBAL_ATTRIBUTES = ("Conventions", "title", "source", "history", "seed", "config",
                     "tolsim_schema")
#: Provenance global attributes written since issue 17 (optional: older files lack them).
#: ``config`` is the effective config (overrides included: ``tolsim run`` on it reproduces
#: every data variable); these pin the software and the measured data.
PROVENANCE_ATTRIBUTES = {
    "tolsim_version": "version of tolsim that wrote the file",
    "python_version": "Python version",
    "numpy_version": "NumPy version (random streams: PCG64 and SeedSequence)",
    "scipy_version": "SciPy version (special functions, quasi-random designs)",
    "numba_version": "Numba version (compiled kernels)",
    "data_files": "measured-data files of empirical distributions, one line each: "
                  "'<sha256>  <path relative to the config file>' (sha256sum format); "
                  "only when the config uses some",
}


class SchemaError(ValueError):
    """A Dataset that does not follow the declared schema."""


@dataclass(frozen=True)
class Variable:
    """Declaration of one variable: dims, units, long_name, dtype kind, required."""

    dims: tuple
    units: str
    long_name: str
    kind: str = "f"  # numpy dtype kind: f float, i integer, U/O/S string
    required: bool = True
    track_axis: int | None = None  # where a study with a carriage inserts its ``track`` dim
    former_long_names: tuple = ()  # also accepted when a file is read (older files)

    def dims_in(self, ds) -> tuple:
        """The dims expected in ``ds``: with a ``track_axis`` and a ``track`` dimension in
        the Dataset (a study with a carriage), ``track`` inserted there."""
        if self.track_axis is not None and "track" in ds.dims:
            k = self.track_axis
            return self.dims[:k] + ("track",) + self.dims[k:]
        return self.dims


V = Variable
_Q = ("quantile",)
_SC = ("spot_check",)

COORDINATES = {
    "quantile": V(_Q, "1", "quantile level"),
    "velocity_deviation_bin": V(("velocity_deviation_bin",), "1",
                                "centre of a velocity deviation histogram bin"),
    "velocity_deviation_bin_bounds": V(("velocity_deviation_bin", "bounds"), "1",
                                       "edges of a velocity deviation histogram bin"),
    "elapsed_time": V(("elapsed_time",), "s", "time since the start of the stroke"),
    "time_bin": V(("time_bin",), "s", "centre of a time-to-contact histogram bin"),
    "time_bin_bounds": V(("time_bin", "bounds"), "s", "edges of a time-to-contact histogram bin"),
    "ball": V(("ball",), "1", "ball position in the train (0 = trailing end)", "i"),
    "pair": V(("pair",), "1", "adjacent ball pair, named by its trailing ball", "i"),
    "spot_check": V(_SC, "1", "spot check number", "i"),
    "contact": V(("contact",), "1", "contact index (names in contact_name)", "i"),
    "contact_name": V(("contact",), "1", "contact (BL, BR, TR, TL)", "U"),
    "factor": V(("factor",), "1", "tolerance source index (names in factor_name)", "i",
                required=False),
    "factor_name": V(("factor",), "1", "tolerance source", "U", required=False),
    # a study with a carriage (issue 12): declared in tolsim.study.pipeline.carriage, optional here
    **{name: V(dims, units, long_name, kind, required=False)
       for name, (dims, units, long_name, kind) in CARRIAGE_COORDINATES.items()},
    # a study with [contact] (issue 13): declared in tolsim.study.pipeline.track_friction, optional
    # here
    **{name: V(dims, units, long_name, kind, required=False)
       for name, (dims, units, long_name, kind) in FRICTION_COORDINATES.items()},
}

DATA_VARIABLES = {
    # epsilon
    "velocity_deviation_mean": V((), "1", "mean ball velocity deviation epsilon over valid balls"),
    "velocity_deviation_std": V((), "1", "standard deviation of epsilon over valid balls"),
    "velocity_deviation_min": V((), "1", "smallest epsilon of a valid ball"),
    "velocity_deviation_max": V((), "1", "largest epsilon of a valid ball"),
    "velocity_deviation_quantile": V(_Q, "1", "quantile of epsilon (from the histogram)"),
    "velocity_deviation_histogram": V(("velocity_deviation_bin",), "1",
                                      "number of valid balls per epsilon bin", "i"),
    "velocity_deviation_underflow": V((), "1", "valid balls below the histogram range", "i"),
    "velocity_deviation_overflow": V((), "1", "valid balls above the histogram range", "i"),
    "velocity_deviation_mean_by_ball": V(("ball",), "1", "mean epsilon per train position",
                                         track_axis=0),
    "velocity_deviation_std_by_ball": V(("ball",), "1",
                                        "standard deviation of epsilon per train position",
                                        track_axis=0),
    # loads (a study with a carriage: of its nominal assembly, per track)
    "normal_load": V(("ball",), "N", "load N_y pressing the top groove down, per ball",
                     track_axis=0),
    "side_load": V(("ball",), "N", "lateral load N_x on the top groove, per ball",
                   track_axis=0),
    "side_force_ratio": V(("ball",), "1", "side force ratio rho = N_x / N_y per ball",
                          track_axis=0),
    # contact
    "contact_probability": V((), "1",
                             "probability of ball-to-ball contact within the horizon per "
                             "train, over the trains whose outcome is known"),
    "contact_probability_ci_lower": V((), "1",
                                      "lower end of the 95 % Clopper-Pearson interval"),
    "contact_probability_ci_upper": V((), "1",
                                      "upper end of the 95 % Clopper-Pearson interval"),
    "contact_probability_bound_lower": V((), "1", "lower partial-identification bound of the "
                                         "contact probability: unresolved trains without "
                                         "contact"),
    "contact_probability_bound_upper": V((), "1", "upper partial-identification bound of the "
                                         "contact probability: unresolved trains with "
                                         "contact"),
    "contact_probability_bounds_ci_lower": V((), "1", "lower end of the 95 % Clopper-Pearson "
                                             "interval of the lower bound"),
    "contact_probability_bounds_ci_upper": V((), "1", "upper end of the 95 % Clopper-Pearson "
                                             "interval of the upper bound"),
    "time_to_contact_quantile": V(_Q, "s", "quantile of the time to first contact, given "
                                           "contact within the horizon"),
    "travel_to_contact_quantile": V(_Q, "m", "quantile of the carriage travel to first "
                                             "contact, given contact within the horizon"),
    "time_to_contact_min": V((), "s", "earliest first contact"),
    "time_to_contact_max": V((), "s", "latest first contact within the horizon"),
    "time_to_contact_histogram": V(("time_bin",), "1",
                                   "number of trains per time-to-first-contact bin", "i"),
    "survival_probability": V(("elapsed_time",), "1", "probability of no contact by time t"),
    "contact_pair_count": V(("pair",), "1", "first contacts per adjacent pair", "i",
                            track_axis=0),
    "horizon": V((), "s", "duration of the stroke considered"),
    "groove_velocity": V((), "m s-1", "velocity v of the top groove (carriage)"),
    # counts
    "n_assemblies": V((), "1", "number of assemblies (trains) sampled", "i"),
    "n_assemblies_valid": V((), "1", "trains whose balls are all resolved", "i"),
    "n_assemblies_unresolved": V((), "1", "trains with an unresolved ball and no certain "
                                          "contact", "i"),
    "n_contact": V((), "1", "trains with a contact within the horizon", "i"),
    "n_balls": V((), "1", "number of balls evaluated", "i"),
    "n_balls_valid": V((), "1", "balls with a resolved epsilon (fast or full model)", "i"),
    "n_balls_not_converged": V((), "1", "balls whose static solution did not converge", "i"),
    "n_balls_loss_of_contact": V((), "1", "balls with a contact force <= 0", "i"),
    "n_balls_outside_validity": V((), "1", "balls outside the fast velocity model's validity "
                                           "limits, sent to the full model", "i"),
    "n_balls_resolved_full": V((), "1", "balls re-solved with the full friction model", "i"),
    "n_balls_full_failed": V((), "1", "balls outside the fast model's validity that the full "
                                      "model could not solve", "i"),
    # per-assembly totals (tolsim.study.statistics.intervals.CLUSTER_COLUMNS): the assembly as the
    # sampling unit of ball-level proportions and Cpk
    "assembly_count": V((), "1", "number of assemblies behind the per-assembly moments", "i"),
    "assembly_total_mean": V(("assembly_total",), "1",
                             "mean over assemblies of the per-assembly totals: valid balls, "
                             "balls with |epsilon| above the limit, sum of epsilon, sum of "
                             "epsilon squared"),
    "assembly_total_comoment": V(("assembly_total", "assembly_total_b"), "1",
                                 "sum over assemblies of the products of the deviations of "
                                 "the per-assembly totals from their means"),
    # spec limits (NaN: none)
    "velocity_deviation_limit": V((), "1", "specification limit on |epsilon|"),
    "contact_probability_limit": V((), "1", "specification limit on the contact probability"),
    "velocity_deviation_out_of_spec_limit": V((), "1", "allowed fraction of balls with "
                                              "|epsilon| above its limit", required=False),
    "velocity_deviation_cpk_minimum": V((), "1", "required minimum Cpk of epsilon",
                                        required=False),
    # spot checks
    "spot_check_ball_index": V(_SC, "1", "global index of the spot-checked ball "
                                         "(assembly * balls + ball)", "i"),
    "spot_check_contact_angle_deviation": V(_SC + ("contact",), "rad",
                                            "loaded contact angle deviation of the ball"),
    "spot_check_normal_force": V(_SC + ("contact",), "N", "contact force of the ball"),
    "spot_check_velocity_deviation_analytic": V(_SC, "1", "epsilon from the study's model"),
    "spot_check_velocity_deviation_full": V(_SC, "1", "epsilon from the full friction model"),
    "spot_check_valid_analytic": V(_SC, "1", "1 if the study's model is valid for the ball",
                                   "i"),
    "spot_check_valid_full": V(_SC, "1", "1 if the full model converged and is valid", "i"),
    "spot_check_n_valid": V((), "1", "spot checks valid in both models", "i"),
    # stratified spot checks (tolsim.study.sampling.SpotCheckPlan); optional: older files
    "spot_check_stratum": V(_SC, "1", "stratum of the spot check (flag_meanings)", "i",
                            required=False),
    "spot_check_band_lower": V((), "1", "lower end of the |epsilon| band of the near-limit "
                                        "spot checks", required=False),
    "spot_check_band_upper": V((), "1", "upper end of the |epsilon| band of the near-limit "
                                        "spot checks", required=False),
    "spot_check_band_balls": V((), "1", "balls of the fast model with |epsilon| in the "
                                        "near-limit band", "i", required=False),
    "spot_check_rms_difference": V((), "1", "RMS of epsilon analytic - full over valid checks"),
    "spot_check_max_abs_difference": V((), "1", "largest |epsilon analytic - full|"),
    # sensitivity and quality-engineering figures (issue 6): declared in the study modules
    # that compute them, optional here
    **{name: V(dims, units, long_name, required=False)
       for name, (dims, units, long_name) in SENSITIVITY_VARIABLES.items()},
    **{name: V((), units, long_name, required=False)
       for name, (units, long_name) in QUALITY_VARIABLES.items()},
    # worst case and RSS of the linearised stack-up, and the per-assembly export along
    # ``sample`` (issue 17): declared in the study modules, optional here
    **{name: V(dims, units, long_name, kind, required=False)
       for name, (dims, units, long_name, kind) in STACKUP_VARIABLES.items()},
    **{name: V(dims, units, long_name, kind, required=False,
               track_axis=1 if {"ball", "pair"} & set(dims) else None)
       for name, (dims, units, long_name, kind) in SAMPLE_VARIABLES.items()},
    **{name: V(dims, units, long_name, kind, required=False)
       for name, (dims, units, long_name, kind) in CARRIAGE_VARIABLES.items()},
    **{name: V(dims, units, long_name, kind, required=False)
       for name, (dims, units, long_name, kind) in FRICTION_VARIABLES.items()},
}

# a rare-event estimator (issue 15): declared in tolsim.study.analyses.limit_state, optional here
DATA_VARIABLES.update({name: V(dims, units, long_name, kind, required=False)
                       for name, (dims, units, long_name, kind) in RARE_EVENT_VARIABLES.items()})
# the intervals of the contact and friction probabilities come from the study's estimator
# (Clopper-Pearson for plain Monte Carlo; its method in their ``interval`` attribute): worded
# for any estimator since issue 15, the former Clopper-Pearson wording still valid on reading
for _name, (_dims, _units, _long_name, _kind) in INTERVAL_VARIABLES.items():
    _old = DATA_VARIABLES[_name]
    DATA_VARIABLES[_name] = V(_dims, _units, _long_name, _kind, required=_old.required,
                              former_long_names=(_old.long_name,))

VARIABLES = {**COORDINATES, **DATA_VARIABLES}


def apply_attributes(ds):
    """Set ``units`` and ``long_name`` of every declared variable in ``ds`` (in place)."""
    for name, var in ds.variables.items():
        decl = VARIABLES.get(name)
        if decl is not None:
            var.attrs["units"] = decl.units
            var.attrs["long_name"] = decl.long_name
    # No CF ``bounds`` attribute on the bin centres: with it, xarray drops the ``units`` of the
    # bounds variables on writing (CF 7.1 lets bounds inherit units), and every variable of a
    # tolsim file carries its own units.
    return ds


#: Global attributes of a sweep's result file (issue 14, :mod:`tolsim.io.sweep`): its sweep
#: dimensions and the coordinates of the swept keys (space-separated names).
SWEEP_DIMENSIONS, SWEEP_COORDINATES = "sweep_dimensions", "sweep_coordinates"
#: Variables of a sweep's result file besides the declared ones: the zip dimension's index
#: and each point's count of spot checks.
SWEEP_VARIABLES = ("sweep_point", "spot_check_count")


def validate(ds):
    """Check a Dataset against the schema; raise :class:`SchemaError` naming the problem.

    A sweep's file (global attribute ``sweep_dimensions``) holds every declared variable
    with those dimensions in front (a coordinate that is the same at every point without
    them), the swept keys' coordinates (``sweep_coordinates``) and :data:`SWEEP_VARIABLES`,
    each with ``units`` and ``long_name``.
    """
    swept = tuple(ds.attrs.get(SWEEP_DIMENSIONS, "").split())
    extra = set(ds.attrs.get(SWEEP_COORDINATES, "").split()) | (
        set(SWEEP_VARIABLES) if swept else set())
    for name, decl in VARIABLES.items():
        if name not in ds.variables:
            if decl.required:
                raise SchemaError(f"variable {name!r} is missing")
            continue
        var = ds.variables[name]
        expected = decl.dims_in(ds)
        if tuple(var.dims) != expected and not (
                swept and tuple(var.dims) == swept + expected):
            raise SchemaError(f"variable {name!r} has dims {tuple(var.dims)}, "
                              f"expected {(swept + expected) if swept else expected}")
        kind = var.dtype.kind
        ok = kind in ("U", "O", "S") if decl.kind == "U" else kind == decl.kind or (
            decl.kind == "i" and kind == "u")
        if not ok:
            raise SchemaError(f"variable {name!r} has dtype {var.dtype}, expected kind "
                              f"{decl.kind!r}")
        for attr in ("units", "long_name"):
            if attr == "long_name" and var.attrs.get(attr) in decl.former_long_names:
                continue
            if var.attrs.get(attr) != getattr(decl, attr):
                raise SchemaError(f"variable {name!r} attribute {attr!r} is "
                                  f"{var.attrs.get(attr)!r}, expected {getattr(decl, attr)!r}")
    for name in ds.variables:
        if name in extra:
            for attr in ("units", "long_name"):
                if not ds.variables[name].attrs.get(attr):
                    raise SchemaError(f"sweep variable {name!r} has no {attr!r}")
        elif name not in VARIABLES:
            raise SchemaError(f"variable {name!r} is not declared in tolsim.io.schema")
    for attr in GLOBAL_ATTRIBUTES:
        if attr not in ds.attrs:
            raise SchemaError(f"global attribute {attr!r} is missing")
    if ds.attrs["Conventions"] != CONVENTIONS:
        raise SchemaError(f"Conventions is {ds.attrs['Conventions']!r}, expected {CONVENTIONS!r}")
    return ds
