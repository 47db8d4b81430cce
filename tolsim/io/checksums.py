"""SHA-256 checksums of a result file's variables and global attributes: written with the
file, verified on reading.

:func:`sign_file` stores in every variable of a netCDF file the attribute :data:`ATTRIBUTE`
(``sha256``), in the file the global attribute :data:`GLOBAL_ATTRIBUTE`
(``attributes_sha256``) over its other global attributes (the embedded config, the seed, the
settings: what a report re-reads) and the global attribute :data:`SCHEME_ATTRIBUTE`
(``checksum_scheme``, :data:`SCHEME`); :func:`verify_file` recomputes them and raises
:class:`IntegrityError` naming the first variable, or the global attributes, that fail. A file
without them (written before tolsim had checksums) is read with an
:class:`UnverifiedResultWarning`; a file of the first scheme (:data:`SCHEME_NAME_VARIABLES`,
variables only) is verified on its variables.

The checksums are computed from the file alone, with any netCDF library, so that anyone can
check a result without tolsim::

    import hashlib, netCDF4, numpy as np

    def digest(a):
        a, h = np.asarray(a), hashlib.sha256()
        if a.dtype.kind in "OU":  # text
            for item in a.ravel():
                h.update(str(item).encode("utf-8") + b"\\0")
        else:
            h.update(np.ascontiguousarray(a, a.dtype.newbyteorder("<")).tobytes())
        return h.hexdigest()

    with netCDF4.Dataset("result.nc") as nc:
        nc.set_auto_maskandscale(False)
        for name, var in nc.variables.items():
            assert digest(var[...]) == var.sha256, name
        h = hashlib.sha256()
        for name in sorted(set(nc.ncattrs()) - {"checksum_scheme", "attributes_sha256"}):
            h.update(name.encode("utf-8") + b"\\0" + bytes.fromhex(digest(nc.getncattr(name))))
        assert h.hexdigest() == nc.attributes_sha256
"""

import hashlib
import os
import warnings

import netCDF4
import numpy as np

#: Variable attribute holding the hex SHA-256 of the variable's stored values.
ATTRIBUTE = "sha256"
#: Global attribute holding the hex SHA-256 of the other global attributes.
GLOBAL_ATTRIBUTE = "attributes_sha256"
#: Global attribute naming the scheme.
SCHEME_ATTRIBUTE = "checksum_scheme"
#: The scheme's name (before the colon) and what it is.
SCHEME_NAME = "sha256-per-variable/2"
SCHEME = (f"{SCHEME_NAME}: hex SHA-256 (FIPS 180-4) in each variable's attribute {ATTRIBUTE}, "
          "over its values as stored in the file (no scale, offset or fill value applied) in "
          "C order, little-endian; text as UTF-8, each value followed by a NUL byte; and in "
          f"the global attribute {GLOBAL_ATTRIBUTE}, over the other global attributes but "
          f"{SCHEME_ATTRIBUTE} by name: each name in UTF-8, a NUL byte and the 32 bytes of its "
          "value's SHA-256 taken as a variable's")
#: The first scheme: the variables only (files of tolsim before the global attributes were
#: covered; verified on their variables).
SCHEME_NAME_VARIABLES = "sha256-per-variable/1"


class IntegrityError(ValueError):
    """A result file's data fail their checksums (the file was damaged or altered)."""


class UnverifiedResultWarning(UserWarning):
    """A result file has no checksums (written before tolsim stored them)."""


def digest(values) -> str:
    """The hex SHA-256 of a variable's stored values (module docstring)."""
    a = np.asarray(values)
    h = hashlib.sha256()
    if a.dtype.kind in "OU":
        for item in a.ravel():
            h.update((item if isinstance(item, bytes) else str(item).encode("utf-8")) + b"\0")
    else:
        h.update(np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes())
    return h.hexdigest()


def _stored(var) -> np.ndarray:
    return np.asarray(var[...])


def attributes_digest(nc) -> str:
    """The hex SHA-256 of the global attributes of an open netCDF4 Dataset ``nc`` but the
    checksum scheme and this one (module docstring)."""
    h = hashlib.sha256()
    for name in sorted(set(nc.ncattrs()) - {SCHEME_ATTRIBUTE, GLOBAL_ATTRIBUTE}):
        h.update(name.encode("utf-8") + b"\0" + bytes.fromhex(digest(nc.getncattr(name))))
    return h.hexdigest()


def sign_file(path) -> dict:
    """Store the checksum of every variable of the netCDF file ``path`` and of its global
    attributes in it (in place); return them ({variable: hex digest}, the global attributes'
    under :data:`GLOBAL_ATTRIBUTE`)."""
    sums = {}
    with netCDF4.Dataset(os.fspath(path), "a") as nc:
        nc.set_auto_maskandscale(False)
        for name, var in nc.variables.items():
            sums[name] = digest(_stored(var))
            var.setncattr(ATTRIBUTE, sums[name])
        nc.setncattr(SCHEME_ATTRIBUTE, SCHEME)
        sums[GLOBAL_ATTRIBUTE] = attributes_digest(nc)
        nc.setncattr(GLOBAL_ATTRIBUTE, sums[GLOBAL_ATTRIBUTE])
    return sums


def add_checksums(ds, sums: dict) -> None:
    """Put the checksums ``sums`` of :func:`sign_file` on ``ds`` (in place), as in the file."""
    for name, value in sums.items():
        if name == GLOBAL_ATTRIBUTE:
            ds.attrs[GLOBAL_ATTRIBUTE] = value
        else:
            ds.variables[name].attrs[ATTRIBUTE] = value
    ds.attrs[SCHEME_ATTRIBUTE] = SCHEME


def verify_file(path) -> bool:
    """Check the checksums of the netCDF file ``path``.

    Returns
    -------
    bool
        True when every variable matches; False, with an :class:`UnverifiedResultWarning`,
        when the file has no checksums at all.

    Raises
    ------
    IntegrityError
        Naming the first variable whose values fail their checksum or that has none, or an
        unknown scheme.
    """
    path = os.fspath(path)
    with netCDF4.Dataset(path) as nc:
        nc.set_auto_maskandscale(False)
        scheme = nc.getncattr(SCHEME_ATTRIBUTE) if SCHEME_ATTRIBUTE in nc.ncattrs() else None
        signed = [name for name, var in nc.variables.items() if ATTRIBUTE in var.ncattrs()]
        if scheme is None and not signed:
            warnings.warn(f"{path}: no checksums (written before tolsim stored them): its "
                          "data cannot be verified", UnverifiedResultWarning, stacklevel=3)
            return False
        name = str(scheme).split(":")[0]
        if name not in (SCHEME_NAME, SCHEME_NAME_VARIABLES):
            raise IntegrityError(f"{path}: unknown checksum scheme {str(scheme)[:60]!r} "
                                 f"(expected {SCHEME_NAME}): the data cannot be verified")
        if name == SCHEME_NAME and (GLOBAL_ATTRIBUTE not in nc.ncattrs() or attributes_digest(
                nc) != str(nc.getncattr(GLOBAL_ATTRIBUTE))):
            raise IntegrityError(f"{path}: the global attributes (the embedded config, seed "
                                 "and settings) fail their SHA-256 checksum: they were damaged "
                                 "or altered after tolsim wrote the file")
        for name, var in nc.variables.items():
            if ATTRIBUTE not in var.ncattrs():
                raise IntegrityError(f"{path}: variable {name} has no {ATTRIBUTE} checksum "
                                     "(added or altered after tolsim wrote the file)")
            if digest(_stored(var)) != str(var.getncattr(ATTRIBUTE)):
                raise IntegrityError(f"{path}: variable {name} fails its SHA-256 checksum: "
                                     "its data were damaged or altered after tolsim wrote "
                                     "the file")
    return True


def without_checksums(attrs: dict) -> dict:
    """``attrs`` without the checksum attributes (a Dataset's or a variable's): they belong
    to a file, and a Dataset combined from files or changed in memory gets new ones when it
    is written."""
    return {k: v for k, v in attrs.items()
            if k not in (ATTRIBUTE, SCHEME_ATTRIBUTE, GLOBAL_ATTRIBUTE)}
