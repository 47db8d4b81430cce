"""Studies side by side (``tolsim compare``): key statistics with their intervals, the
difference of each to a reference run with its own interval, the config keys that differ, and
overlaid distributions.

:func:`compare_runs` reads two or more result files of ``tolsim run`` and writes the page, the
CSV and the figures of the comparison into a folder (Notes of
:func:`~tolsim.reports.compare.report.compare_runs`); the statistics and their intervals: Notes
of :func:`~tolsim.reports.compare.statistics.run_statistics`; the differences to the reference
run: Notes of :func:`~tolsim.reports.compare.statistics.difference`.

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
