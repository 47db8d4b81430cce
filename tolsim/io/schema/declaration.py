"""The building blocks of the result-file schema: a variable's declaration
(:class:`Variable`), the error of a Dataset that breaks the schema (:class:`SchemaError`) and
how a section of the schema fills a result Dataset (:class:`Section`).
"""

from collections.abc import Callable
from dataclasses import dataclass


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


@dataclass(frozen=True)
class Section:
    """How one section of the schema fills a result Dataset
    (:func:`tolsim.io.netcdf.result_to_dataset`, in three passes over the sections).

    Attributes
    ----------
    collect : callable, optional
        ``collect(result, history) -> (coordinates, data variables, global attributes)``:
        what goes into the Dataset when it is made (the sections in order).
    assign : callable, optional
        ``assign(result, ds) -> ds``: variables and global attributes added to the made
        Dataset (the sections in order).
    finish : callable, optional
        ``finish(result, ds)``: variable attributes set in place once every declared
        variable has its ``units`` and ``long_name`` (the sections in reverse order, so the
        core's defaults come last).
    """

    collect: Callable | None = None
    assign: Callable | None = None
    finish: Callable | None = None
