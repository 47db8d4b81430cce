"""The one declared schema of a tolsim study result file (netCDF, CF-1.10).

Every variable the writer may put in a result file is declared here with its dimensions,
``units`` (UDUNITS; ``1`` for dimensionless values and counts) and ``long_name``;
:func:`validate` checks a Dataset against the declaration before it is written and when a
file is read back. Variables marked ``required=False`` are optional (e.g. the sensitivity
variables along the ``factor`` dimension that the report issue adds); a variable that is not
declared is an error, so the schema stays the single place that defines the file.

One module per section of the file holds its declarations and the code that fills them
(:class:`~tolsim.io.schema.declaration.Section`): :mod:`~tolsim.io.schema.core` (every
study), :mod:`~tolsim.io.schema.carriage`, :mod:`~tolsim.io.schema.friction`,
:mod:`~tolsim.io.schema.sensitivity`, :mod:`~tolsim.io.schema.rare_events`,
:mod:`~tolsim.io.schema.stackup`, :mod:`~tolsim.io.schema.samples`,
:mod:`~tolsim.io.schema.quality`; :mod:`~tolsim.io.schema.sweep` names a sweep's extras.
:data:`SECTIONS` lists them in the order :func:`tolsim.io.netcdf.result_to_dataset` runs them.

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
adds the variables declared in :mod:`tolsim.io.schema.rare_events` (coefficient of variation,
evaluations, the |epsilon| exceedance, and for importance sampling the design point along
``factor``). The interval variables of the contact and friction probabilities are therefore
worded for any estimator (its method in their ``interval`` attribute); files written before
keep their "Clopper-Pearson" long names, which :func:`validate` still accepts.

The file passes the CF checker (``compliance-checker --test=cf:1.10``, see
``tests/io/test_cf_compliance.py``): coordinate variables are numeric, strictly monotonic and
without ``_FillValue`` (:func:`tolsim.io.netcdf.write_dataset`); the names along ``contact``
(BL, BR, TR, TL) and ``factor`` are string label variables ``contact_name`` / ``factor_name``
(CF 6.1 labels, auxiliary coordinates listed in the ``coordinates`` attribute of the variables
along those dimensions) beside integer index coordinates. The stroke time is ``elapsed_time``,
not ``time``: it is a duration in ``s``, not a CF time coordinate (``units`` "... since
<epoch>", ``standard_name = "time"``), and a variable named ``time`` is taken for one.
"""

from tolsim.io.schema import (
    carriage,
    core,
    friction,
    quality,
    rare_events,
    samples,
    sensitivity,
    stackup,
)
from tolsim.io.schema.carriage import CARRIAGE_COORDINATES, CARRIAGE_VARIABLES
from tolsim.io.schema.core import (
    CONVENTIONS,
    CORE_COORDINATES,
    CORE_VARIABLES,
    GLOBAL_ATTRIBUTES,
    PROVENANCE_ATTRIBUTES,
    SCHEMA_VERSION,
)
from tolsim.io.schema.declaration import SchemaError, Section, V, Variable
from tolsim.io.schema.friction import FRICTION_COORDINATES, FRICTION_VARIABLES
from tolsim.io.schema.quality import QUALITY_VARIABLES
from tolsim.io.schema.rare_events import INTERVAL_VARIABLES, RARE_EVENT_VARIABLES
from tolsim.io.schema.samples import SAMPLE_VARIABLES
from tolsim.io.schema.sensitivity import SENSITIVITY_VARIABLES
from tolsim.io.schema.stackup import STACKUP_VARIABLES
from tolsim.io.schema.sweep import SWEEP_COORDINATES, SWEEP_DIMENSIONS, SWEEP_VARIABLES

__all__ = ["CONVENTIONS", "COORDINATES", "DATA_VARIABLES", "GLOBAL_ATTRIBUTES",
           "PROVENANCE_ATTRIBUTES", "SCHEMA_VERSION", "SECTIONS", "SWEEP_COORDINATES",
           "SWEEP_DIMENSIONS", "SWEEP_VARIABLES", "VARIABLES", "SchemaError", "Section",
           "Variable", "apply_attributes", "validate"]

COORDINATES = {
    **CORE_COORDINATES,
    # a study with a carriage (issue 12): declared in tolsim.io.schema.carriage, optional here
    **{name: V(dims, units, long_name, kind, required=False)
       for name, (dims, units, long_name, kind) in CARRIAGE_COORDINATES.items()},
    # a study with [contact] (issue 13): declared in tolsim.io.schema.friction, optional here
    **{name: V(dims, units, long_name, kind, required=False)
       for name, (dims, units, long_name, kind) in FRICTION_COORDINATES.items()},
}

DATA_VARIABLES = {
    **CORE_VARIABLES,
    # sensitivity and quality-engineering figures (issue 6): declared in
    # tolsim.io.schema.sensitivity and .quality, optional here
    **{name: V(dims, units, long_name, required=False)
       for name, (dims, units, long_name) in SENSITIVITY_VARIABLES.items()},
    **{name: V((), units, long_name, required=False)
       for name, (units, long_name) in QUALITY_VARIABLES.items()},
    # worst case and RSS of the linearised stack-up, and the per-assembly export along
    # ``sample`` (issue 17): declared in tolsim.io.schema.stackup and .samples, optional here
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

# a rare-event estimator (issue 15): declared in tolsim.io.schema.rare_events, optional here
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



#: The sections that fill a result Dataset, in the order they fill it
#: (:func:`tolsim.io.netcdf.result_to_dataset`).
SECTIONS = (core.SECTION, carriage.SECTION, friction.SECTION, sensitivity.SECTION,
            rare_events.SECTION, stackup.SECTION, samples.SECTION, quality.SECTION)


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
