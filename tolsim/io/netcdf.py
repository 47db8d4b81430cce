"""Study results to and from netCDF (via xarray), following :mod:`tolsim.io.schema`.

:func:`write_result` builds the Dataset, validates it against the schema and writes it to a
temporary file in the output folder, then renames it over the target (:func:`os.replace`,
atomic on POSIX), so a crash never leaves a truncated result. :func:`read_result` opens a file
and checks that it is a tolsim result.
"""

import os
import tempfile

import xarray as xr

from tolsim.io import schema
from tolsim.io.schema.core import (
    PLAIN_PROBABILITY_VARIABLES,
    history_line,
    provenance_attributes,
)

__all__ = ["PLAIN_PROBABILITY_VARIABLES", "history_line", "provenance_attributes", "read_result",
           "result_to_dataset", "write_dataset", "write_result"]


def result_to_dataset(result, *, history: str | None = None) -> xr.Dataset:
    """The Dataset of a :class:`tolsim.study.execution.runner.StudyResult` (validated).

    Parameters
    ----------
    result : StudyResult
    history : str, optional
        Command line to record (default: this process's argv).

    Notes
    -----
    Each section of :data:`tolsim.io.schema.SECTIONS`
    (:class:`~tolsim.io.schema.declaration.Section`) fills its part, in three passes: what
    the Dataset is made of (``collect``), what is added to it (``assign``) and, once every
    declared variable has its ``units`` and ``long_name``, the other variable attributes
    (``finish``, in reverse order).
    """
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


def write_dataset(ds: xr.Dataset, path) -> None:
    """Validate ``ds`` and write it to ``path`` through a temporary file and a rename.

    Coordinates are written without ``_FillValue`` (CF 2.5.1; xarray adds one to every float
    variable by default): they never hold missing values.
    """
    schema.validate(ds)
    ds = ds.copy(deep=False)  # shallow: the encodings below do not touch the caller's Dataset
    for name in ds.coords:
        ds.variables[name].encoding["_FillValue"] = None
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp",
                               dir=folder)
    os.close(fd)
    try:
        ds.to_netcdf(tmp, engine="netcdf4", format="NETCDF4")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual file mode
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_result(result, path, *, history: str | None = None) -> xr.Dataset:
    """Write a study result to netCDF (atomic); return the Dataset written."""
    ds = result_to_dataset(result, history=history)
    write_dataset(ds, path)
    return ds


def read_result(path) -> xr.Dataset:
    """Open a tolsim result file (loaded into memory) and check it against the schema.

    Raises
    ------
    ValueError
        If the file cannot be opened or is not a tolsim study result.
    """
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot open as netCDF: {exc}") from None
    if "tolsim_schema" not in ds.attrs:
        raise ValueError(f"{path}: not a tolsim study result (no tolsim_schema attribute)")
    try:
        schema.validate(ds)
    except schema.SchemaError as exc:
        raise ValueError(f"{path}: not a valid tolsim study result: {exc}") from None
    return ds
