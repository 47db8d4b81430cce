"""Running a what-if sweep (issue 14): its points, combined into one result file.

The ``[sweep]`` section is read by :mod:`tolsim.io.config.sweep`.

Running (:func:`run_sweep`): the points run one after the other, each as a study of its
own with the study's seed (common random numbers, :mod:`tolsim.study.design.sweep`), and are
combined into one Dataset (:func:`combine_points`) whose variables gain the sweep
dimensions. Each finished point is kept in ``OUT.sweep/point-K.nc`` and the point being run
checkpoints to ``OUT.sweep/point-K.partial``; a rerun resumes per point. Every point is
combined as read back from its part file, so a resumed sweep writes the same file as an
uninterrupted one. The folder goes when the result is written.
"""

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from tolsim.io import schema
from tolsim.io.checksums import add_checksums, without_checksums
from tolsim.io.config import text_mismatch
from tolsim.io.netcdf import history_line, read_result, result_to_dataset, write_dataset
from tolsim.io.schema import SWEEP_COORDINATES, SWEEP_DIMENSIONS, SWEEP_VARIABLES
from tolsim.study.design.sweep import ZIP_DIMENSION, Sweep
from tolsim.study.execution import runner
from tolsim.study.execution.distributed import connect

#: Global attribute naming the sweep dimensions of a result file (space-separated) and the
#: one naming its sweep coordinates (the swept keys' variables).
DIMENSIONS_ATTRIBUTE, COORDINATES_ATTRIBUTE = SWEEP_DIMENSIONS, SWEEP_COORDINATES
#: Each point's count of spot checks (the spot_check variables beyond it are padding).
SPOT_CHECK_COUNT = SWEEP_VARIABLES[1]


# --------------------------------------------------------------------------------------------
# One result file for all points
# --------------------------------------------------------------------------------------------
def _fill(dtype):
    if dtype.kind == "f":
        return np.nan
    if dtype.kind in "iu":
        return -1
    if dtype.kind == "b":
        return False
    return ""


def _pad_spot_checks(datasets):
    """The points' spot checks padded to the most of any point (a point's count is in
    :data:`SPOT_CHECK_COUNT`): NaN, -1, False or "" beyond a point's own."""
    counts = [ds.sizes.get("spot_check", 0) for ds in datasets]
    most = max(counts)
    out = []
    for ds, n in zip(datasets, counts, strict=True):
        if n < most:
            padded = {}
            for name, var in ds.variables.items():
                if "spot_check" not in var.dims or name == "spot_check":
                    continue
                axis = var.dims.index("spot_check")
                shape = list(var.shape)
                shape[axis] = most - n
                pad = np.full(shape, _fill(var.dtype), dtype=var.dtype)
                padded[name] = xr.Variable(var.dims, np.concatenate([var.values, pad], axis),
                                           var.attrs, var.encoding)
            index = datasets[counts.index(most)]["spot_check"]
            ds = ds.drop_dims("spot_check").assign_coords(spot_check=index).assign(padded)
        out.append(ds)
    return out, np.asarray(counts, dtype=np.int64)


def _same(values) -> bool:
    """Whether attribute values are equal, whatever their type: ``7`` and ``np.int64(7)``
    (as read from a file) are the same value."""
    first = values[0]
    return all(repr(v) == repr(first) or bool(np.array_equal(np.asarray(v), np.asarray(first)))
               for v in values[1:])


def _merge_attrs(all_attrs):
    """One attribute dict: a value that differs between points becomes the lines
    ``point K: value``. Checksums (:mod:`tolsim.io.checksums`) are left out: they belong to
    a point's file, and the combined file gets its own."""
    merged = {}
    all_attrs = [without_checksums(a) for a in all_attrs]
    for key in all_attrs[0]:
        values = [a.get(key, "") for a in all_attrs]
        if not _same(values):
            merged[key] = "\n".join(f"point {k + 1}: {v}" for k, v in enumerate(values))
        else:
            merged[key] = all_attrs[0][key]
    return merged


def combine_points(datasets, sweep: Sweep) -> xr.Dataset:
    """The points' result Datasets as one, with the sweep dimensions in front.

    Every data variable gains the sweep dimensions (outer: one per key, the key's values as
    its coordinate; zip: ``sweep_point`` with one coordinate per key); the index coordinates
    (quantiles, bins, balls, ...) are the same at every point
    (:func:`tolsim.io.config.sweep.parse_sweep` refuses keys that change them) and stay as
    they are. Spot checks are padded to the most of any point (:data:`SPOT_CHECK_COUNT` has
    each point's count). Global and variable attributes that differ between points become
    lines ``point K: value``.
    """
    datasets, counts = _pad_spot_checks(list(datasets))
    first = datasets[0]
    index = [n for n in first.coords if n in first.dims]
    for name in index:
        for k, ds in enumerate(datasets[1:], start=2):
            if not np.array_equal(ds[name].values, first[name].values):
                raise ValueError(f"sweep point {k} has another {name} axis than point 1")
    dims = sweep.dimensions
    shape = sweep.shape
    out = xr.Dataset(coords={n: first[n] for n in index})
    for name in first.variables:
        if name in index:
            continue
        var = first.variables[name]
        if name in first.coords and all(  # a coordinate the same at every point stays
                np.array_equal(ds.variables[name].values, var.values) for ds in datasets):
            out = out.assign_coords({name: var})
            continue
        stacked = np.stack([ds.variables[name].values for ds in datasets]).reshape(
            shape + var.shape)
        attrs = _merge_attrs([ds.variables[name].attrs for ds in datasets])
        out[name] = (dims + var.dims, stacked, attrs)
        if name in first.coords:
            out = out.set_coords(name)
    if sweep.mode == "zip":
        out = out.assign_coords({ZIP_DIMENSION: np.arange(sweep.size, dtype=np.int64)})
        out[ZIP_DIMENSION].attrs.update(units="1", long_name="sweep point (zip of the keys)")
    for axis in sweep.axes:
        attrs = {"units": axis.units, "long_name": f"swept config key {axis.key}"}
        along = axis.name if sweep.mode == "outer" else ZIP_DIMENSION
        out = out.assign_coords({axis.name: ((along,), np.asarray(axis.values, float), attrs)})
    out[SPOT_CHECK_COUNT] = (dims, counts.reshape(shape), {
        "units": "1", "long_name": "spot checks of the sweep point (the spot_check variables "
                                   "beyond it are padding)"})
    out.attrs = _merge_attrs([ds.attrs for ds in datasets])
    out.attrs["config"] = first.attrs["config"]
    out.attrs[DIMENSIONS_ATTRIBUTE] = " ".join(dims)
    out.attrs[COORDINATES_ATTRIBUTE] = " ".join(a.name for a in sweep.axes)
    out.attrs["sweep_mode"] = sweep.mode
    out.attrs["sweep_keys"] = " ".join(a.key for a in sweep.axes)
    out.attrs["title"] = (first.attrs["title"] + f" (sweep of {len(sweep.axes)} key"
                          f"{'s' if len(sweep.axes) > 1 else ''}, {sweep.size} points)")
    return schema.validate(out)


def is_sweep(ds) -> bool:
    """Whether a result Dataset holds a sweep (several studies along sweep dimensions)."""
    return bool(ds.attrs.get(DIMENSIONS_ATTRIBUTE))


# --------------------------------------------------------------------------------------------
# Running the points
# --------------------------------------------------------------------------------------------
def parts_folder(output) -> Path:
    """Where the finished points and the running point's checkpoint of a sweep live."""
    return Path(f"{output}.sweep")


@dataclass(frozen=True)
class SweepWork:
    """The work a :func:`run_sweep` call did in this process (a resumed sweep takes its
    finished points from their part files: they count here neither in time nor in balls).

    Attributes
    ----------
    elapsed : float
        Wall time of the points run here [s], compilation included.
    compile_seconds : float
        Numba compilation and kernel-cache loading inside ``elapsed`` [s].
    balls_run : int
        Balls of the assemblies evaluated here.
    """

    elapsed: float = 0.0
    compile_seconds: float = 0.0
    balls_run: int = 0

    @property
    def balls_per_second(self) -> float:
        """Balls evaluated here over ``elapsed`` without compilation (NaN if none ran)."""
        seconds = self.elapsed - self.compile_seconds
        return self.balls_run / seconds if self.balls_run and seconds > 0 else float("nan")


def run_sweep(config, output, *, history=None, progress=None, on_point=None, notify=None,
              fresh=False, **run_options):
    """Run every point of a swept config and write one result file (module docstring).

    Parameters
    ----------
    config : StudyConfig
        With ``sweep``.
    output : path
        The result file; ``OUT.sweep/`` holds the finished points until it is written.
    history : str, optional
        The command line for the file.
    progress : callable, optional
        Called with the assemblies merged since the last call (all points together).
    on_point : callable, optional
        Called with (k, sweep) before point k runs or is taken from its part file.
    notify : callable, optional
        One-line messages (resumed points, compiling).
    fresh : bool
        Delete the parts of an earlier run first.
    **run_options
        For :func:`tolsim.study.execution.runner.run_study` (workers, chunk_blocks, scheduler,
        checkpoint_interval, target, save_samples, max_blocks).

    Returns
    -------
    (xr.Dataset, SweepWork): the combined result, and the work done here
    """
    sweep = config.sweep
    if sweep is None:
        raise ValueError(f"{config.path} has no [sweep]: run it with "
                         "tolsim.study.execution.runner.run_study")
    mismatch = text_mismatch(config)  # before any point runs (its part would be refused)
    if mismatch:
        raise ValueError(f"not run: {mismatch}; the file embeds the config text alone (change "
                         "a sweep through its text or with_overrides)")
    if run_options.get("target") is not None and any(
            axis.key == "study.samples" for axis in sweep.axes):
        raise ValueError("a precision target sets each point's samples, which the sweep "
                         "varies (study.samples): drop one of them")
    scheduler = run_options.get("scheduler")
    cluster = None
    if isinstance(scheduler, str):  # one cluster for all points (a LocalCluster starts once)
        run_options["scheduler"], cluster, _ = connect(scheduler)
    folder = parts_folder(output)
    if fresh and folder.exists():
        shutil.rmtree(folder)
    created = not folder.exists()
    folder.mkdir(exist_ok=True)
    try:
        datasets, work = _run_points(config, folder, history, progress, on_point, notify,
                                     run_options)
    except BaseException:
        if created and not any(folder.iterdir()):  # (bad arguments: nothing to resume)
            folder.rmdir()
        raise
    finally:
        if cluster is not None or isinstance(scheduler, str):
            run_options["scheduler"].close()
            if cluster is not None:
                cluster.close()
    combined = combine_points(datasets, sweep)
    combined.attrs.pop("sweep_point_fingerprint", None)
    # the sweep's command once (each part has its own time stamp)
    combined.attrs["history"] = history_line(history)
    add_checksums(combined, write_dataset(combined, output))
    shutil.rmtree(folder, ignore_errors=True)
    return combined, work


def _run_points(config, folder, history, progress, on_point, notify, run_options):
    """Run or take from their part files every point of a sweep: (datasets, SweepWork)."""
    sweep = config.sweep
    datasets, elapsed, compiled, balls = [], 0.0, 0.0, 0
    for k, point in enumerate(sweep.points):
        if on_point is not None:
            on_point(k, sweep)
        part = folder / f"point-{k:04d}.nc"
        fp = runner.fingerprint(point)
        if part.exists():
            try:
                ds, why = read_result(part), "of another study (its config or tolsim differ)"
            except ValueError as exc:
                ds, why = None, f"damaged ({' '.join(str(exc).split())[:160]})"
            if ds is None or ds.attrs.get("sweep_point_fingerprint") != fp:
                if notify:  # (the point runs again; its part file is then replaced)
                    notify(f"point {k + 1} of {sweep.size}: {part} is {why}; running the "
                           "point again")
            else:
                datasets.append(ds)
                if notify:
                    notify(f"point {k + 1} of {sweep.size} ({sweep.describe(k)}) taken from "
                           f"{part}")
                if progress:
                    progress(int(ds.n_assemblies))
                continue
        result = runner.run_study(point, progress=progress, notify=notify,
                           checkpoint_path=str(folder / f"point-{k:04d}.partial"),
                           **run_options)
        elapsed += result.elapsed
        compiled += result.loop_compile_seconds
        done = (int(result.statistics.n_assemblies) if result.assemblies_run is None
                else result.assemblies_run)
        balls += done * point.balls
        ds = result_to_dataset(result, history=history, sweep_point=k)
        ds.attrs["sweep_point_fingerprint"] = fp
        write_dataset(ds, part)
        checkpoint = folder / f"point-{k:04d}.partial"
        if checkpoint.exists():
            os.unlink(checkpoint)
        # every point as read from its part file, whether it ran now or in an earlier,
        # interrupted run: the combined file is then the same (attribute types included)
        datasets.append(read_result(part))
    return datasets, SweepWork(elapsed, compiled, balls)
