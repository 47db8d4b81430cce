"""Study results to and from netCDF (via xarray), following :mod:`tolsim.io.schema`.

:func:`write_result` builds the Dataset, validates it against the schema and writes it to a
temporary file in the output folder, then renames it over the target (:func:`os.replace`,
atomic on POSIX), so a crash or a full disk never leaves a truncated result; before the
rename every variable gets its SHA-256 checksum (:mod:`tolsim.io.checksums`). :func:`read_result`
opens a file, verifies the checksums and checks that it is a tolsim result.
"""

import os
import tempfile

import numpy as np
import xarray as xr

from tolsim._interrupts import interrupts_held
from tolsim.io import schema
from tolsim.io.checksums import (
    IntegrityError,
    UnverifiedResultWarning,
    add_checksums,
    sign_file,
    verify_file,
)
from tolsim.io.config import text_mismatch
from tolsim.io.schema import SWEEP_COORDINATES, SWEEP_DIMENSIONS
from tolsim.io.schema.core import (
    PLAIN_PROBABILITY_VARIABLES,
    PROVENANCE_ATTRIBUTES,
    history_line,
    provenance_attributes,
)

__all__ = ["IntegrityError", "NUMERIC_ATTRIBUTES", "PLAIN_PROBABILITY_VARIABLES",
           "TEXT_ATTRIBUTES", "UnverifiedResultWarning", "check_attributes", "history_line",
           "provenance_attributes", "read_result", "result_to_dataset", "verify_checksums",
           "write_dataset", "write_result"]

#: Global attributes written as numbers (in a sweep's file, one that differs between the
#: points is text: lines ``point K: value``).
NUMERIC_ATTRIBUTES = ("seed", "samples", "block_size", "workers", "sensitivity_samples",
                      "samples_maximum", "elapsed_seconds", "full_model_resolve_seconds",
                      "compile_seconds", "balls_per_second",
                      "velocity_deviation_quantile_resolution",
                      "time_to_contact_quantile_resolution")
#: Global attributes written as text.
TEXT_ATTRIBUTES = (
    *(a for a in schema.GLOBAL_ATTRIBUTES if a not in NUMERIC_ATTRIBUTES),
    *PROVENANCE_ATTRIBUTES, "references", "velocity_model", "static_model", "propagation",
    "sampling", "spot_check_status", "contact_probability_interval", "propagation_assumption",
    "propagation_caveat", "stopping_rule", "target_ci_width", "estimator", "estimator_settings",
    "rare_event_seed_streams", "contact_creep_model", "friction_assumptions",
    SWEEP_DIMENSIONS, SWEEP_COORDINATES, "sweep_mode", "sweep_keys", "checksum_scheme",
    "attributes_sha256")


def result_to_dataset(result, *, history: str | None = None,
                      sweep_point: int | None = None) -> xr.Dataset:
    """The Dataset of a :class:`tolsim.study.execution.runner.StudyResult` (validated).

    Parameters
    ----------
    result : StudyResult
    history : str, optional
        Command line to record (default: this process's argv).
    sweep_point : int, optional
        The index of the sweep point whose result this is (its config must be that point of
        its text's sweep, :func:`tolsim.io.config.text_mismatch`).

    Notes
    -----
    Each section of :data:`tolsim.io.schema.SECTIONS`
    (:class:`~tolsim.io.schema.declaration.Section`) fills its part, in three passes: what
    the Dataset is made of (``collect``), what is added to it (``assign``) and, once every
    declared variable has its ``units`` and ``long_name``, the other variable attributes
    (``finish``, in reverse order).

    Raises
    ------
    ValueError
        If the result's config is not what its text reads as (changed with
        ``dataclasses.replace``, :func:`tolsim.io.config.text_mismatch`): the file embeds the
        text alone, and would not say what ran.
    """
    mismatch = text_mismatch(result.config, sweep_point)
    if mismatch:
        raise ValueError(f"not written: {mismatch}; the file embeds the config text alone, "
                         "so it would not say what ran (change a study through its text, "
                         "with_overrides or tolsim.with_study_settings)")
    coords, data, attrs = {}, {}, {}
    for section in schema.SECTIONS:  # what the Dataset is made of
        if section.collect is not None:
            more_coords, more_data, more_attrs = section.collect(result, history)
            coords.update(more_coords)
            data.update(more_data)
            attrs.update(more_attrs)
    ds = xr.Dataset(data, coords=coords)
    ds.attrs = attrs
    for section in schema.SECTIONS:  # what is added to it
        if section.assign is not None:
            ds = section.assign(result, ds)
    schema.apply_attributes(ds)
    for section in reversed(schema.SECTIONS):  # attributes; the core's defaults last
        if section.finish is not None:
            section.finish(result, ds)
    return schema.validate(ds)


def write_dataset(ds: xr.Dataset, path) -> dict:
    """Validate ``ds`` and write it to ``path`` through a temporary file and a rename.

    Every variable gets the SHA-256 checksum of its values as written
    (:func:`tolsim.io.checksums.sign_file`), replacing any it had. On an error (a full disk,
    say) the temporary file is removed and the target is left as it was; an OSError names
    the target.

    Ctrl-C during the write takes effect after it (:func:`interrupts_held`).

    Coordinates are written without ``_FillValue`` (CF 2.5.1; xarray adds one to every float
    variable by default): they never hold missing values.

    Returns
    -------
    dict
        The checksums written, {variable: hex SHA-256}
        (:func:`tolsim.io.checksums.add_checksums` puts them on a Dataset).
    """
    schema.validate(ds)
    ds = ds.copy(deep=False)  # shallow: the encodings below do not touch the caller's Dataset
    for name in ds.coords:
        ds.variables[name].encoding["_FillValue"] = None
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp",
                                   dir=folder)
    except OSError as exc:  # a folder that does not exist, say: name the target
        raise OSError(exc.errno, exc.strerror or str(exc), path) from None
    os.close(fd)
    try:
        with interrupts_held():
            ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4")
            sums = sign_file(tmp)
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual file mode
            os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):  # name the target, not the temporary file
            raise OSError(exc.errno, exc.strerror or str(exc), path) from None
        raise
    return sums


def write_result(result, path, *, history: str | None = None) -> xr.Dataset:
    """Write a study result to netCDF (atomic); return the Dataset written (with its
    checksums)."""
    ds = result_to_dataset(result, history=history)
    add_checksums(ds, write_dataset(ds, path))
    return ds


def check_attributes(ds, path) -> None:
    """Raise ValueError when a global attribute tolsim writes has the wrong type.

    :data:`TEXT_ATTRIBUTES` must be text; :data:`NUMERIC_ATTRIBUTES` real numbers (``seed``
    a whole number >= 0), or text in a sweep's file. Attributes tolsim does not write are
    not checked.
    """
    sweep = bool(ds.attrs.get(SWEEP_DIMENSIONS))
    for name, value in ds.attrs.items():
        if name in TEXT_ATTRIBUTES and not isinstance(value, str):
            raise ValueError(f"{path}: global attribute {name} is {_shown(value)}, expected "
                             "text (the file was altered or damaged)")
        if name in NUMERIC_ATTRIBUTES and not (sweep and isinstance(value, str)):
            number = isinstance(value, int | float | np.integer | np.floating) and not \
                isinstance(value, bool | np.bool_)
            if not number or (name == "seed" and not (isinstance(value, int | np.integer)
                                                      and value >= 0)):
                raise ValueError(f"{path}: global attribute {name} is {_shown(value)}, "
                                 f"expected a{' whole' if name == 'seed' else ''} number (the "
                                 "file was altered or damaged)")


def _shown(value) -> str:
    text = " ".join(repr(value).split())
    return text if len(text) <= 40 else text[:37] + "..."


def read_result(path, *, verify=True) -> xr.Dataset:
    """Open a tolsim result file (loaded into memory) and check it against the schema.

    Parameters
    ----------
    path : str or path
    verify : bool
        Verify the variables' checksums (:func:`tolsim.io.checksums.verify_file`); a file
        written before tolsim stored them is read with an
        :class:`~tolsim.io.checksums.UnverifiedResultWarning`. False reads a damaged file
        for forensics.

    Raises
    ------
    ValueError
        If the file cannot be opened or is not a tolsim study result (its global attributes
        of the wrong type included); :class:`~tolsim.io.checksums.IntegrityError` (a
        ValueError) if a variable fails its checksum.
    """
    if not isinstance(path, str | os.PathLike):
        raise ValueError(f"path = {path!r}: a result file's path must be a str or os.PathLike")
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
    except (OSError, ValueError, RuntimeError) as exc:
        raise ValueError(f"{path}: cannot open as netCDF: {' '.join(str(exc).split())}"
                         ) from None
    if "tolsim_schema" not in ds.attrs:
        raise ValueError(f"{path}: not a tolsim study result (no tolsim_schema attribute)")
    if verify:
        verify_checksums(path)
    try:
        schema.validate(ds)
    except schema.SchemaError as exc:
        raise ValueError(f"{path}: not a valid tolsim study result: {exc}") from None
    check_attributes(ds, path)
    return ds


def verify_checksums(path) -> bool:
    """:func:`tolsim.io.checksums.verify_file`, with a file netCDF cannot read as a
    ValueError (one line)."""
    try:
        return verify_file(path)
    except (OSError, RuntimeError) as exc:
        raise ValueError(f"{path}: cannot read as netCDF: {' '.join(str(exc).split())}"
                         ) from None
