"""The driver of ``tolsim compare``: :func:`compare_runs` reads the result files and writes
``compare.html``, ``compare.csv`` and the PNGs."""

import os
from dataclasses import dataclass, field

import numpy as np

from tolsim.io.sweep import is_sweep
from tolsim.reports.compare.comparison import Comparison, compare_datasets, run_labels
from tolsim.reports.compare.figures import FIGURES
from tolsim.reports.compare.page import CSV_NAME, HTML_NAME, comparison_html, csv_text
from tolsim.reports.compare.statistics import CONFIDENCE_LEVEL
from tolsim.reports.files import check_folder, write_files
from tolsim.reports.result_view import NotAResult, read_result_file
from tolsim.reports.style import (
    render_png,
)


# --------------------------------------------------------------------------------------------
# Driver
# --------------------------------------------------------------------------------------------
@dataclass
class CompareOutputs:
    """Files written by :func:`compare_runs`, and the comparison shown."""

    folder: str
    html: str = ""
    csv: str = ""
    figures: dict = field(default_factory=dict)
    comparison: Comparison | None = None


def read_runs(paths, *, verify=True) -> list:
    """Read result files (:func:`tolsim.reports.result_view.read_result_file` with the schema
    check of :func:`tolsim.io.netcdf.read_result`), or raise :class:`NotAResult` with a
    one-line reason naming the first bad file. The file of a what-if sweep
    (:func:`tolsim.io.sweep.is_sweep`) is refused: its points are compared by its own report
    (:mod:`tolsim.reports.sweep`). ``verify`` verifies each file's checksums
    (:mod:`tolsim.io.checksums`); False for forensics."""
    out = []
    for path in paths:
        path = os.fspath(path)
        ds = read_result_file(path, validate=True, verify=verify)
        if is_sweep(ds):  # several studies along sweep dimensions (issue 14)
            dims = str(ds.attrs.get("sweep_dimensions", "")).split()
            points = int(np.prod([ds.sizes[d] for d in dims if d in ds.sizes]))
            raise NotAResult(f"{path} is a sweep of {points} points "
                             f"({ds.attrs.get('sweep_keys', '?')}): tolsim compare puts "
                             "single studies side by side; use 'tolsim report "
                             f"{path}' for a sweep (its points in one table and curve)")
        out.append(ds)
    return out


def compare_runs(paths, folder, *, progress=None, confidence_level=CONFIDENCE_LEVEL,
                 verify=True) -> CompareOutputs:
    """Write ``compare.html``, ``compare.csv`` and the PNGs of two or more result files.

    The first file is the reference. Every file is read and every output made in memory
    before anything is written, so a bad input leaves no folder behind.

    Parameters
    ----------
    paths : sequence of str or path
        At least two result files of ``tolsim run``.
    folder : str or path
        Output folder (created if missing).
    progress : callable, optional
        Called with a short message before each step.
    confidence_level : float
    verify : bool
        Verify the files' checksums (:func:`read_runs`); False for forensics.

    Returns
    -------
    CompareOutputs

    Raises
    ------
    NotAResult
        If a file is missing, not a tolsim result, fails its checksums, or is the file of a
        sweep.
    ValueError
        If fewer than two files are given.

    Notes
    -----
    :func:`compare_runs` reads two or more result files of ``tolsim run``
    (:func:`tolsim.io.netcdf.read_result`) and writes, into a folder:

    * ``compare.html``: one self-contained page (figures embedded as data URIs): the runs, how
      their random numbers relate, the config keys that differ, the key statistics of every run
      with their 95 % intervals and the difference of each to the first run (the reference) with
      its own interval, and the figures below;
    * ``compare.csv``: one row per statistic and run: estimate, ci_lower, ci_upper, units, and the
      difference to the reference with its interval (empty for the reference itself);
    * ``contact_probability.png``: P(contact) of every run with its interval, and the difference
      to the reference (a forest plot);
    * ``velocity_deviation.png``: the epsilon histograms overlaid (densities);
    * ``survival.png``: the survival curves P(no contact by t) overlaid.

    Everything but the reading and writing is pure:
    :func:`~tolsim.reports.compare.statistics.run_statistics` takes the statistics out of a
    Dataset, :func:`~tolsim.reports.compare.comparison.compare_datasets` compares Datasets held in
    memory, and the interval functions
    (:func:`~tolsim.study.statistics.intervals.newcombe_difference`,
    :func:`~tolsim.study.statistics.intervals.welch_difference`,
    :func:`~tolsim.study.statistics.intervals.mover_difference`,
    :func:`~tolsim.study.statistics.intervals.histogram_quantile_interval`,
    :func:`~tolsim.study.statistics.intervals.cluster_mean_and_std`, in
    :mod:`tolsim.study.statistics.intervals`) take plain numbers.
    """
    say = progress or (lambda msg: None)
    paths = [os.fspath(p) for p in paths]
    if len(paths) < 2:
        raise ValueError(f"need at least two result files to compare, got {len(paths)}")
    check_folder(folder)
    datasets = read_runs(paths, verify=verify)
    say(f"read {len(datasets)} result files")
    comparison = compare_datasets(datasets, run_labels(paths), paths, confidence_level)
    say("figures")
    pngs = {name: render_png(plot(comparison)) for name, (plot, _) in FIGURES.items()}
    say(f"{HTML_NAME} and {CSV_NAME}")
    files = {HTML_NAME: comparison_html(comparison, pngs).encode("utf-8"),
             CSV_NAME: csv_text(comparison).encode("utf-8"),
             **{f"{name}.png": png for name, png in pngs.items()}}
    folder = os.fspath(folder)
    written = write_files(folder, files)
    return CompareOutputs(folder, written[HTML_NAME], written[CSV_NAME],
                          {name: written[f"{name}.png"] for name in pngs}, comparison)
