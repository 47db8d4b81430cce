"""The report says which estimator produced a probability (issue 15): a subset-simulation
number is never labelled as a Clopper-Pearson interval of the plain run."""

import re
from pathlib import Path

import pytest

from tolsim.io.config import parse_config
from tolsim.io.netcdf import result_to_dataset
from tolsim.reports.verdict import estimator_label
from tolsim.study.execution.runner import run_study

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "rare_contact.toml"


@pytest.fixture(scope="module")
def subset_file():
    text = re.sub(r"samples_per_level = \d+", "samples_per_level = 500", CONFIG.read_text())
    c = parse_config(text, str(CONFIG)).with_overrides(samples=2000)
    return result_to_dataset(run_study(c))


def test_the_label_names_the_estimator_and_its_interval(subset_file):
    ds = subset_file
    assert ds.contact_probability.attrs["estimator"] == "subset"
    label = estimator_label(ds)
    assert label.startswith("subset simulation: ") and "Clopper-Pearson" not in label
    assert ds.contact_probability.attrs["interval"] in label
    assert f"{int(ds.contact_probability_evaluations):,} model evaluations" in label


def test_a_plain_file_keeps_the_clopper_pearson_label(subset_file):
    plain = subset_file.copy()
    plain["contact_probability"].attrs = {k: v for k, v in plain.contact_probability.attrs
                                          .items() if k not in ("estimator", "interval")}
    assert estimator_label(plain) == "Clopper-Pearson"
    plain["contact_probability"].attrs["estimator"] = "monte_carlo"
    assert estimator_label(plain) == "Clopper-Pearson"


def test_the_report_page_names_the_estimator(subset_file, tmp_path):
    from tolsim.reports.study import make_report

    nc = tmp_path / "rare.nc"
    subset_file.to_netcdf(nc)  # written by hand: its checksums (if any) are not verified
    out = make_report(str(nc), str(tmp_path / "report"), sensitivity=False, pdf=False,
                      verify=False)
    page = Path(out.html).read_text(encoding="utf-8")
    assert "subset simulation: lognormal" in page
    assert "the plain run:" in page


def test_an_importance_report_lists_the_design_point(tmp_path):
    # importance sampling: the rare-events table and the design point, most important first
    from tolsim.reports.study import rare_events_html

    text = re.sub(r"^(samples_per_level|p0|max_levels) = .*$", "", CONFIG.read_text(),
                  flags=re.M)
    text = re.sub(r'^estimator = "subset"', 'estimator = "importance"\nimportance_samples = 500',
                  text, flags=re.M)
    ds = result_to_dataset(run_study(parse_config(text, str(CONFIG)).with_overrides(
        samples=1000)))
    page = "".join(rare_events_html(ds))
    assert "importance sampling" in page and "The most likely way to fail" in page
    beta = float(ds.contact_reliability_index)
    assert f"β = {beta:.3f}" in page
    alpha = ds.contact_importance_factor.values
    first = str(ds.factor_name.values[int(alpha.argmax())])
    table = page[page.index("The most likely way to fail"):]
    assert table.index(first) < min(table.index(str(n)) for n in ds.factor_name.values
                                    if str(n) != first)


def test_a_plain_file_has_no_rare_events_section():
    from tolsim.io.config import load_config
    from tolsim.reports.study import rare_events_html

    c = load_config(CONFIG.parent / "yaw_moment_tolerances.toml").with_overrides(samples=256)
    assert rare_events_html(result_to_dataset(run_study(c))) == []


# --- estimator = "rare" (issue 23): status, diagnostics and the verdict -------------------------
def _rare_file():
    text = re.sub(r'^estimator = "subset"', 'estimator = "rare"\nimportance_samples = 1000',
                  CONFIG.read_text(), flags=re.M)
    text = re.sub(r"samples_per_level = \d+", "samples_per_level = 500", text)
    return result_to_dataset(run_study(parse_config(text, str(CONFIG)).with_overrides(
        samples=1000)))


def _times_100(*args, **kwargs):
    import dataclasses

    from tolsim.study.analyses.rare_events import subset_simulation

    r = subset_simulation(*args, **kwargs)
    return dataclasses.replace(r, probability=100 * r.probability,
                               standard_error=100 * r.standard_error,
                               ci_lower=100 * r.ci_lower, ci_upper=100 * r.ci_upper)


@pytest.fixture(scope="module")
def rare_files():
    from tolsim.study.analyses import limit_state

    agreeing = _rare_file()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(limit_state, "subset_simulation", _times_100)
        disagreeing = _rare_file()
    return agreeing, disagreeing


def test_the_rare_table_shows_status_and_diagnostics(rare_files):
    from tolsim.reports.study import rare_events_html

    ds = rare_files[0]
    page = "".join(rare_events_html(ds))
    assert "<th>status</th><th>diagnostics</th>" in page
    assert "subset simulation and importance sampling" in page
    row = page[page.index("ball-to-ball contact"):].split("</tr>")[0]
    assert "<td>ok</td>" in row
    assert "effective failing samples" in row and "level-0 ancestors" in row
    assert "P_FORM / P_IS" in row and "CV with independent levels" in row
    assert "subset simulation " in row and "(ok)" in row and "importance sampling " in row


def test_agreeing_estimators_can_pass(rare_files):
    from tolsim.reports.verdict import PASS, contact_check, estimator_flag

    ds = rare_files[0]
    assert estimator_flag(ds, "contact_probability") is None
    # P(contact) ~ 1.2e-3 with a CV of about 0.05 against the config's limit of 2e-3
    assert contact_check(ds).status == PASS


def test_disagreeing_estimators_are_undecided(rare_files, tmp_path):
    from tolsim.reports.study import make_report, rare_events_html
    from tolsim.reports.verdict import PASS, UNDECIDED, contact_check, study_verdict

    ds = rare_files[1]
    assert ds.contact_probability.attrs["estimator_status"] == "estimators_disagree"
    check = contact_check(ds)
    assert check.status == UNDECIDED
    assert check.reason.startswith("the estimator does not back the number "
                                   "(estimators_disagree: ")
    assert study_verdict(ds).status != PASS
    page = "".join(rare_events_html(ds))
    assert "<b>ESTIMATORS_DISAGREE</b>: " in page
    nc = tmp_path / "disagree.nc"
    ds.to_netcdf(nc)
    out = make_report(str(nc), str(tmp_path / "report"), sensitivity=False, pdf=False,
                      verify=False)  # a file built here, not signed by tolsim run
    html_page = Path(out.html).read_text(encoding="utf-8")
    assert "UNDECIDED" in html_page and "ESTIMATORS_DISAGREE" in html_page


def test_a_failed_diagnostic_is_undecided(subset_file):
    from tolsim.reports.verdict import UNDECIDED, contact_check

    ds = subset_file.copy()
    ds["contact_probability"].attrs.update(estimator_status="diagnostic_failed",
                                           estimator_message="constructed")
    assert contact_check(ds).status == UNDECIDED
    assert "(diagnostic_failed: constructed)" in contact_check(ds).reason


def test_an_unchecked_subset_number_says_so(subset_file):
    # estimator_mode_check (issue 23): "design_points" where FORM's design points checked
    # subset simulation for a lost mode (rare_contact's pairs), "none" where there were none
    # (a limit state that is not smooth): the verdict and the table say it is unchecked
    from tolsim.reports.study import rare_events_html
    from tolsim.reports.verdict import contact_check

    ds = subset_file
    assert ds.contact_probability.attrs["estimator_mode_check"] == "design_points"
    checked = contact_check(ds)
    assert "unchecked" not in checked.reason
    assert "checked for a lost mode against FORM design points" in "".join(
        rare_events_html(ds))
    unchecked = ds.copy()
    unchecked["contact_probability"].attrs = {**ds.contact_probability.attrs,
                                              "estimator_mode_check": "none"}
    verdict = contact_check(unchecked)
    assert verdict.status == checked.status
    assert "unchecked for a lost failure mode" in verdict.reason
    assert "unchecked for a lost mode (no FORM design points)" in "".join(
        rare_events_html(unchecked))


def test_replicated_subset_numbers_say_so(subset_file):
    # estimator_mode_check "replicates" (issue 23): two independent subset simulation runs
    # checked each other (a limit state that is not smooth). Agreeing: the verdict as
    # checked, the table names the check; disagreeing: UNDECIDED, as for estimator = "rare"
    from tolsim.reports.study import rare_events_html
    from tolsim.reports.verdict import UNDECIDED, contact_check

    ds = subset_file.copy()
    ds["contact_probability"].attrs = {**subset_file.contact_probability.attrs,
                                       "estimator_mode_check": "replicates"}
    verdict = contact_check(ds)
    assert verdict.status == contact_check(subset_file).status
    assert "unchecked" not in verdict.reason
    assert "checked for a lost mode by two independent runs" in "".join(rare_events_html(ds))
    ds["contact_probability"].attrs.update(estimator_status="estimators_disagree",
                                           estimator_message="first run 1e-7, second 1e-5")
    assert contact_check(ds).status == UNDECIDED
    assert "estimators_disagree: first run 1e-7" in contact_check(ds).reason
