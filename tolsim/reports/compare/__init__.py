"""Studies side by side (``tolsim compare``): key statistics with their intervals, the
difference of each to a reference run with its own interval, the config keys that differ, and
overlaid distributions.

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

Everything but the reading and writing is pure: :func:`run_statistics` takes the statistics
out of a Dataset, :func:`compare_datasets` compares Datasets held in memory, and the interval
functions (:func:`~tolsim.study.statistics.intervals.newcombe_difference`,
:func:`~tolsim.study.statistics.intervals.welch_difference`,
:func:`~tolsim.study.statistics.intervals.mover_difference`,
:func:`~tolsim.study.statistics.intervals.histogram_quantile_interval`,
:func:`~tolsim.study.statistics.intervals.cluster_mean_and_std`, in
:mod:`tolsim.study.statistics.intervals`) take plain numbers.

Statistics and their intervals (95 %)
-------------------------------------
* **P(contact)** per train (per assembly in a carriage study): k of the n trains whose outcome
  is known, with the file's Clopper-Pearson interval. When a run has unresolved trains, also
  the partial-identification bounds k/N and (k + u)/N over all N trains, each with its
  Clopper-Pearson interval.
* **epsilon mean and standard deviation**: the file's estimates; their standard errors by the
  delta method over assemblies (the balls of an assembly are correlated, the assemblies are
  independent: ratio estimator, [Cochran1977] Sec. 6.3-6.4) from the per-assembly moments the
  file stores (:mod:`tolsim.study.statistics.intervals`), interval estimate -+ t(A - 1) se.
* **epsilon quantiles** (:data:`VELOCITY_DEVIATION_LEVELS`): read off the histogram; interval
  by Woodruff's method ([Woodruff1952]): a Wilson interval for the level, turned into values
  through the histogram, at the effective sample size N^2 / sum n_a^2 (each assembly one
  trial), the smallest any correlation of the balls of an assembly allows
  (Var k_a <= n_a^2 p (1 - p)), and widened to the edges of the histogram bins they fall in.
  An end beyond the smallest or largest value is not bounded by the data: NaN ("n/a").
* **fraction out of spec and Cpk** (with a limit on |epsilon|): the file's values and
  intervals (Korn-Graubard effective sample size; delta method over assemblies,
  :mod:`tolsim.study.statistics.quality`).
* **time-to-contact quantiles** (:data:`TIME_TO_CONTACT_LEVELS`, given contact): Woodruff's
  interval on the histogram of the first-contact times, one per assembly with contact
  (independent, so n is their number).
* **carriage stiffness** (a study with a ``[carriage]``): the mean over the solved carriages
  with a t interval (mean -+ t(n - 1) std / sqrt(n)), and the stiffness of the nominal
  assembly, which has no sampling error.

Differences to the reference: paired or unpaired?
-------------------------------------------------
Runs with the same ``seed``, ``block_size`` and ``sampling`` draw their assemblies from common
random numbers ([Law2015] Sec. 11.2): assembly i of one run uses the random numbers of
assembly i of the other, so their outcomes are correlated, positively when a change moves the
outcome the same way in every assembly. A paired interval would use that, but it needs
per-assembly data (for P(contact), the joint counts: contact in both runs, in one only); the
files hold aggregates only, and re-running the studies from their stored configs to get them
costs as much as the runs. So every difference here is **unpaired**: the two estimates are
taken as independent. For independent runs (different seeds) that is exact; for runs with
common random numbers it overstates the variance of the difference by 2 Cov, so the interval
is wider than a paired one (conservative) as long as the runs are positively correlated. The
report says which runs share random numbers with the reference. (A cheap paired interval would
need per-block totals in the files, the contact count of each block of ``block_size``
assemblies, say: with common random numbers block b of both runs uses the same stream, so the
per-block differences are independent across blocks and a t interval over them is paired.)

* P(contact) and its bounds: Newcombe's hybrid score interval ([Newcombe1998] method 10),
  from the Wilson intervals of the two proportions
  (:func:`~tolsim.study.statistics.intervals.newcombe_difference`).
* means and standard deviations (epsilon, carriage stiffness): Welch's interval with the
  Welch-Satterthwaite degrees of freedom ([Welch1947], [Satterthwaite1946];
  :func:`~tolsim.study.statistics.intervals.welch_difference`).
* quantiles, fraction out of spec, Cpk: the MOVER ([ZouDonner2008]; "method of variance
  estimates recovery", :func:`~tolsim.study.statistics.intervals.mover_difference`) from the
  two runs' own intervals, of which Newcombe's method 10 is the case with Wilson intervals;
  with symmetric intervals it is the Wald interval of the difference.
* nominal carriage stiffness: exact (no sampling error).

References
----------
.. [Newcombe1998] R. G. Newcombe, "Interval estimation for the difference between
   independent proportions: comparison of eleven methods", Stat. Med. 17 (1998) 873-890.
.. [ZouDonner2008] G. Y. Zou, A. Donner, "Construction of confidence limits about effect
   measures: a general approach", Stat. Med. 27 (2008) 1693-1702.
.. [Welch1947] B. L. Welch, "The generalization of 'Student's' problem when several different
   population variances are involved", Biometrika 34 (1947) 28-35.
.. [Satterthwaite1946] F. E. Satterthwaite, "An approximate distribution of estimates of
   variance components", Biometrics Bulletin 2 (1946) 110-114.
.. [Woodruff1952] R. S. Woodruff, "Confidence intervals for medians and other position
   measures", J. Am. Stat. Assoc. 47 (1952) 635-646.
.. [Cochran1977] W. G. Cochran, Sampling Techniques, 3rd ed., Wiley, 1977.
.. [Law2015] A. M. Law, Simulation Modeling and Analysis, 5th ed., McGraw-Hill, 2015.

The package: :mod:`~tolsim.reports.compare.statistics` (the statistics of a run and the
differences), :mod:`~tolsim.reports.compare.comparison` (config differences and the
comparison), :mod:`~tolsim.reports.compare.figures`, :mod:`~tolsim.reports.compare.page`
(CSV and HTML) and :mod:`~tolsim.reports.compare.report` (the driver, :func:`compare_runs`).
"""

from tolsim.reports.compare.comparison import (
    ABSENT,
    Comparison,
    ConfigDifference,
    Run,
    compare_datasets,
    config_differences,
    flatten_config,
    run_labels,
    toml_value,
)
from tolsim.reports.compare.figures import (
    FIGURES,
    RUN_COLOURS,
    RUN_LINESTYLES,
    plot_contact_probability,
    plot_survival,
    plot_velocity_deviation,
)
from tolsim.reports.compare.page import (
    CSV_COLUMNS,
    CSV_NAME,
    DISPLAY,
    EXTRA_CSS,
    HTML_NAME,
    comparison_html,
    csv_rows,
    csv_text,
    format_difference,
    format_value,
)
from tolsim.reports.compare.report import (
    CompareOutputs,
    compare_runs,
    read_runs,
    write_files,
)
from tolsim.reports.compare.statistics import (
    CONFIDENCE_LEVEL,
    DIFFERENCE_METHODS,
    PAIRING_INDEPENDENT,
    PAIRING_SHARED,
    RANDOM_NUMBER_ATTRIBUTES,
    TIME_TO_CONTACT_LEVELS,
    VELOCITY_DEVIATION_LEVELS,
    Difference,
    Statistic,
    bounds_difference,
    difference,
    run_statistics,
    shares_random_numbers,
)
from tolsim.reports.result_view import NotAResult

__all__ = [
    "ABSENT", "CONFIDENCE_LEVEL", "CSV_COLUMNS", "CSV_NAME", "CompareOutputs", "Comparison",
    "ConfigDifference", "DIFFERENCE_METHODS", "DISPLAY", "Difference", "EXTRA_CSS", "FIGURES",
    "HTML_NAME", "NotAResult", "PAIRING_INDEPENDENT", "PAIRING_SHARED",
    "RANDOM_NUMBER_ATTRIBUTES", "RUN_COLOURS", "RUN_LINESTYLES", "Run", "Statistic",
    "TIME_TO_CONTACT_LEVELS", "VELOCITY_DEVIATION_LEVELS", "bounds_difference",
    "compare_datasets", "compare_runs", "comparison_html", "config_differences", "csv_rows",
    "csv_text", "difference", "flatten_config", "format_difference", "format_value",
    "plot_contact_probability", "plot_survival", "plot_velocity_deviation", "read_runs",
    "run_labels", "run_statistics", "shares_random_numbers", "toml_value", "write_files",
]
