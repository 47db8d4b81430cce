"""The IOOS compliance checker (``cf:1.10``) as the tests run it, with its dataset queries
memoised for the duration of one check.

compliance-checker 6.1 answers questions such as "which variables are geophysical?" or
"which are auxiliary coordinates?" by scanning every variable's attributes, and asks them
again in nearly every check: ``is_geophysical`` alone runs 1 000 times on a carriage result
file, each run scanning the file twice. On tolsim's files (100-200 variables) a check took
8-21 s, most of the CF tests' time, 90 % of it in these repeated scans (cProfile of
``configs/carriage_preload.toml``'s file). The answers depend on the open dataset only,
which the checker never changes, so :func:`check` keeps them while one file is checked (as
the checker does itself for ``get_coordinate_variables``, with ``functools.lru_cache``) and
hands every caller its own copy. ``test_memoised_check_reports_what_the_checker_reports``
(tests/io/test_cf_compliance.py) shows that the report is the checker's own.
"""

import copy
import functools
import json
import warnings
from contextlib import contextmanager
from pathlib import Path

from compliance_checker.cf import util as cfutil
from compliance_checker.runner import CheckSuite, ComplianceChecker

CHECKER = "cf:1.10"
#: the queries of ``compliance_checker.cf.util`` that the checks repeat: each reads the
#: dataset (and a variable name) only. The checks call them through the module, so replacing
#: the module's attribute reaches every caller.
QUERIES = ("get_auxiliary_coordinate_variables", "get_forecast_metadata_variables",
           "get_cell_boundary_variables", "get_bounds_variables", "get_geophysical_variables",
           "get_z_variables", "get_platform_variables", "get_instrument_variables",
           "get_time_variable", "get_time_variables", "get_axis_variables",
           "get_climatology_variable", "get_axis_map", "is_geophysical")


def load_checkers():
    """Load the checker's plugins once (its deprecated ioos_sos checker warns on loading)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        CheckSuite.load_all_available_checkers()


def _memoised(query, answers):
    @functools.wraps(query)
    def ask(nc, *args):
        key = (query.__name__, id(nc), args)
        if key not in answers:
            answers[key] = query(nc, *args)
        return copy.deepcopy(answers[key])  # a caller may change the list it gets

    return ask


@contextmanager
def memoised_queries():
    """The checker's dataset queries (:data:`QUERIES`) memoised, while the block runs; the
    answers are forgotten on leaving it (the next file is another dataset)."""
    answers = {}
    originals = {name: getattr(cfutil, name) for name in QUERIES}
    try:
        for name, query in originals.items():
            setattr(cfutil, name, _memoised(query, answers))
        yield
    finally:
        for name, query in originals.items():
            setattr(cfutil, name, query)


def report(path, report_path, memoise=True):
    """The checker's JSON report of ``path`` (written to ``report_path``) and whether a
    check raised: (errors, report)."""
    run = functools.partial(ComplianceChecker.run_checker, str(path), [CHECKER], verbose=0,
                            criteria="strict", output_filename=str(report_path),
                            output_format="json")
    if memoise:
        with memoised_queries():
            _, errors = run()
    else:
        _, errors = run()
    return errors, json.loads(Path(report_path).read_text())[CHECKER]


def check(path, tmp_path, memoise=True):
    """The checker's report of ``path``: (exceptions occurred, {weight: [failed checks]})."""
    errors, out = report(path, Path(tmp_path) / f"{Path(path).name}.json", memoise)
    failed = {}
    for weight, key in ((3, "high_priorities"), (2, "medium_priorities"),
                        (1, "low_priorities")):
        failed[weight] = [f"{r['name']}: {r['msgs']}" for r in out[key]
                          if r["value"][0] < r["value"][1]]
    return errors, failed
