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
