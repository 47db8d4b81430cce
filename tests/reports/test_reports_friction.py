"""``tolsim report`` of a study with ``[contact]`` (tolsim issue 13): the section "What contact
costs" with the numbers of the result file, the friction row of the verdict, the contact
model in the assumptions table, the friction figure, the PDF; and files without friction
reported as before.

The study is ``configs/friction_yaw.toml`` at 600 assemblies (Sobol' indices at n = 64): one
train of 10 balls per assembly, [Lin2018] Table 1 bearing, a 15 N m yaw moment, rail, carriage
and ball tolerances, mu_bb = 0.1 and a limit of 0.2 N on the friction increase. Expected
values are read from the result file itself and formatted here: the report must show the
file's numbers, not numbers of its own.
"""

import os
import re

import numpy as np
import pytest
import xarray as xr
from scipy.stats import binomtest
from test_reports import check_figure

from tolsim.io.config import load_config, parse_config, with_study_settings
from tolsim.io.netcdf import write_result
from tolsim.io.schema.friction import FRICTION_COORDINATES, FRICTION_VARIABLES
from tolsim.reports import assumptions as A
from tolsim.reports import study as study_report
from tolsim.reports import verdict as V
from tolsim.study.execution.runner import run_study
from tolsim.study.statistics.intervals import format_fraction

CONFIGS = os.path.join(os.path.dirname(__file__), "..", "..", "configs")
FRICTION_HEADING = "5. What contact costs: carriage friction after the balls touch"


@pytest.fixture(scope="module")
def friction_result(tmp_path_factory):
    """The friction study, small: 600 assemblies, Sobol' indices at n = 64."""
    config = load_config(os.path.join(CONFIGS, "friction_yaw.toml")).with_overrides(
        samples=600)
    config = with_study_settings(config, sensitivity_samples=64)
    path = tmp_path_factory.mktemp("friction") / "friction.nc"
    write_result(run_study(config), path, history="test")
    with xr.open_dataset(path) as ds:
        return path, ds.load()


@pytest.fixture(scope="module")
def friction_report(friction_result, tmp_path_factory):
    path, _ = friction_result
    out = study_report.make_report(path, tmp_path_factory.mktemp("rep"), sensitivity=False,
                                   pdf=False)
    return out, open(out.html, encoding="utf-8").read()


def _text(html_part):
    """The text of an HTML fragment, cells separated by ' | ', entities decoded."""
    import html

    return html.unescape(re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " | ", html_part)))


def _section(page, start_marker):
    start = page.index(start_marker)
    return page[start: page.index("<h2", start + 1)]


def _f(ds, name):
    return float(np.asarray(ds[name]))


def _q(ds, name, level):
    k = int(np.argmin(np.abs(np.asarray(ds["quantile"]) - level)))
    return float(np.asarray(ds[name])[k])


def _n(x):
    """A force as the report prints it: three significant digits, '0' for an exact zero."""
    return "0" if x == 0 else f"{x:.3g}"


# --------------------------------------------------------------------------------------------
# the page
# --------------------------------------------------------------------------------------------
def test_sections_and_figures(friction_report):
    out, page = friction_report
    headings = re.findall(r"<h2[^>]*>([^<]*)</h2>", page)
    assert headings == [
        "1. What was studied", "2. Results at a glance", "3. Ball velocity deviation ε",
        "4. Ball-to-ball contact", FRICTION_HEADING, "6. Quality engineering",
        "7. What drives the risk", "8. Model check: analytic versus the full friction model",
        "9. Review and sign-off", "Provenance"]
    section = _section(page, "id='friction'")
    for h3 in ("Friction after contact at a glance", "Distribution over the 600 resolved "
               "trains", "Drivers of the friction increase: ranked by the total-effect index"):
        assert f"<h3>{h3}</h3>" in section, h3
    # the friction figure is written and embedded in its section, once
    assert set(out.figures) == {"velocity_deviation", "contact", "friction", "quality",
                                "spot_checks", "sensitivity"}
    assert os.path.getsize(out.figures["friction"]) > 50_000
    with open(out.figures["friction"], "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    assert section.count("src='data:image/png;base64,") == 1
    assert len(re.findall(r"src='data:image/png;base64,", page)) == len(out.figures)
    assert out.friction is not None and out.friction["heading"] == FRICTION_HEADING


def test_section_shows_the_files_numbers(friction_result, friction_report):
    _, ds = friction_result
    _, page = friction_report
    text = _text(_section(page, "id='friction'"))
    n = int(ds.n_assemblies)
    k, u = int(ds.n_friction_exceedance), int(ds.n_assemblies_friction_unresolved)
    p, lo, hi = (_f(ds, f"friction_exceedance_probability{s}") for s in ("", "_ci_lower",
                                                                         "_ci_upper"))
    assert 0 < k < n  # the limit of 0.2 N is exceeded by some assemblies, not all
    expected = [
        f"{_f(ds, 'friction_force_baseline'):.4g} N ± "
        f"{_n(_f(ds, 'friction_force_baseline_std'))} N",
        f"{_n(_f(ds, 'friction_increase_mean'))} N / "
        f"{_n(_q(ds, 'friction_increase_quantile', 0.5))} N / "
        f"{_n(_q(ds, 'friction_increase_quantile', 0.99))} N",
        f"{_n(_f(ds, 'friction_increase_max'))} N",
        f"{format_fraction(p, lo, hi)} ({k:,} of {n - u:,} trains whose outcome is known",
        format_fraction(_f(ds, "contact_fraction_mean")),
        f"{_f(ds, 'clusters_formed_mean'):.3g}",
        f"{int(ds.n_assemblies_friction_resolved):,} / {u:,} / "
        f"{int(ds.n_assemblies_sliding):,} of {n:,}",
        f"{int(ds.n_assemblies_released):,} of {n:,}",  # pushed off a stick line, apart
    ]
    released = ds["n_assemblies_released"]
    assert released.attrs["units"] == "1" and "stick line" in released.attrs["long_name"]
    for what in expected:
        assert what in text, what
    # the distribution table: mean, std and the quantiles of each force, as in the file
    for prefix in ("friction_increase", "friction_ripple", "contact_force_max"):
        row = [_n(_f(ds, f"{prefix}_mean")), _n(_f(ds, f"{prefix}_std"))] + [
            _n(_q(ds, f"{prefix}_quantile", q)) for q in (0.5, 0.9, 0.95, 0.99, 0.999)]
        assert " | ".join(row) in re.sub(r"\s*(\|\s*)+", " | ", text), prefix
    # the drivers: ranked by the file's total-effect indices of the friction increase
    total = np.asarray(ds["sensitivity_friction_total"], dtype=float)
    names = [str(f) for f in np.asarray(ds["factor_name"])]
    order = np.argsort(-total, kind="stable")
    ranked = re.findall(r"\| (\d+) \| \| (\w+) \| \| ([\d.]+) \[", text)
    assert [r[1] for r in ranked] == [names[i] for i in order]
    assert [r[2] for r in ranked] == [f"{total[i]:.3f}" for i in order]


def test_headline_and_verdict_row(friction_result, friction_report):
    _, ds = friction_result
    out, page = friction_report
    p, lo, hi = (_f(ds, f"friction_exceedance_probability{s}") for s in ("", "_ci_lower",
                                                                         "_ci_upper"))
    box = _text(page[page.index("id='verdict'"): page.index("<h2>1.")])
    assert (f"rises over its {_f(ds, 'friction_force_baseline'):.4g} N baseline by a median "
            f"{_n(_q(ds, 'friction_increase_quantile', 0.5))} N, 99 % quantile "
            f"{_n(_q(ds, 'friction_increase_quantile', 0.99))} N") in box
    assert f"P(increase > 0.2 N) = {format_fraction(p, lo, hi)}" in box
    # the friction row: the file's estimate and interval, no verdict without an allowed
    # fraction (the config has no key for it), so the overall verdict is that of the others
    row = out.verdict.checks[-1]
    assert row.quantity.startswith("P(friction increase > 0.2 N) per train")
    assert row.estimate == (f"{format_fraction(p)} (95 % Clopper-Pearson interval: "
                            f"{format_fraction(lo)} to {format_fraction(hi)})")
    assert row.status == V.NO_LIMIT and len(out.verdict.checks) == 4
    assert out.verdict.status == V.overall(c.status for c in out.verdict.checks[:3])
    assert f"{int(ds.n_friction_exceedance):,} of 600 trains" in row.reason
    assert row.quantity in box


def test_verdict_with_an_allowed_fraction(friction_result):
    # judged like P(contact): pass when the whole 95 % interval is below the allowed fraction,
    # fail when it is all above, undecided when it straddles it
    _, ds = friction_result
    lo, hi = (_f(ds, f"friction_exceedance_probability_ci_{e}") for e in ("lower", "upper"))
    for allowed, status in ((hi * 1.01, V.PASS), (lo * 0.99, V.FAIL),
                            (0.5 * (lo + hi), V.UNDECIDED)):
        check = V.friction_check(ds, allowed)
        assert check.status == status, allowed
        # the allowed fraction as configured, to 6 significant digits (issue 26: a limit is
        # never shown rounded to a neighbour of itself)
        assert check.requirement == (f"P(increase > 0.2 N) ≤ "
                                     f"{format_fraction(allowed, digits=6)}")
        verdict = V.study_verdict(ds, friction_exceedance_limit=allowed)
        assert verdict.checks[-1] == check


def test_verdict_interval_covers_the_bounds_with_unresolved(friction_result):
    # with u unresolved assemblies the interval is the Clopper-Pearson lower end of k of N
    # and upper end of k + u of N (scipy.stats.binomtest, exact), as for P(contact)
    _, ds = friction_result
    ds = ds.copy()
    k, n, u = int(ds.n_friction_exceedance), int(ds.n_assemblies), 7
    ds["n_assemblies_friction_unresolved"] = np.int64(u)
    check = V.friction_check(ds, 0.5)
    low = binomtest(k, n).proportion_ci(0.95, "exact").low
    high = binomtest(k + u, n).proportion_ci(0.95, "exact").high
    assert (f"interval covering the bounds over all trains: {format_fraction(low)} to "
            f"{format_fraction(high)}") in check.estimate
    assert check.status == V.PASS


def test_no_limit_no_row(friction_result):
    _, ds = friction_result
    ds = ds.copy()
    ds["friction_increase_limit"] = np.nan
    assert V.friction_check(ds) is None
    assert len(V.study_verdict(ds).checks) == 3
    rows = {r.item: r for r in A.assumption_table(ds)}
    assert rows["limit on the friction increase per train"].value == "no spec limit given"


def test_assumptions_have_the_contact_model(friction_result):
    _, ds = friction_result
    rows = A.assumption_table(ds)
    contact = {r.item: r for r in rows if r.topic == "after contact"}
    assert list(contact) == [
        "trains of balls after contact (quasi-static)", "ball-to-ball friction μ_bb",
        "creep stiffness K = dP/dε and carriage-force slopes",
        "carriage friction force of a track", "worst track per assembly", "sliding balls"]
    assert "tolsim.physics.trains" in contact["trains of balls after contact (quasi-static)"].source
    assert contact["ball-to-ball friction μ_bb"].value.startswith("0.1:")
    assert contact["ball-to-ball friction μ_bb"].source == (
        "[contact] ball_friction_coefficient = 0.1")
    creep = contact["creep stiffness K = dP/dε and carriage-force slopes"]
    assert creep.value.startswith("analytic:") and "[contact] creep_model" in creep.source
    assert "μ_bb / cos β₀ = 0.141" in contact["carriage friction force of a track"].value
    assert "unresolved from the onset of sliding" in contact["sliding balls"].value
    limit = next(r for r in rows if r.item == "limit on the friction increase per train")
    assert limit.topic == "spec limits" and limit.value.startswith("0.2 N")
    assert limit.source == "[contact] friction_increase_limit_N = 0.2"
    # the contact model follows the models; the spec limit closes the table
    topics = [r.topic for r in rows]
    assert topics.index("after contact") > max(i for i, t in enumerate(topics)
                                               if t == "models")
    assert rows[-1] is limit


# --------------------------------------------------------------------------------------------
# figure
# --------------------------------------------------------------------------------------------
def test_friction_figure(friction_result):
    _, ds = friction_result
    sens = study_report.sensitivity_from_file(ds)
    assert sens.outputs == ("velocity_deviation", "contact", "friction_increase")
    fig = study_report.plot_friction(ds, sens, 0.01)
    assert check_figure(fig) == []
    ax_d, ax_t, ax_z, ax_s = fig.axes
    # (a) the spec limit at 0.2 N, the file's P(exceedance) drawn at it
    assert any(np.allclose(line.get_xdata(), 0.2) for line in ax_d.lines)
    p = _f(ds, "friction_exceedance_probability")
    assert any(np.allclose(line.get_ydata(), p) for line in ax_d.lines)
    # (b) one trace per stored example: the file's force less its baseline
    force = np.asarray(ds.example_friction_force) - np.asarray(
        ds.example_friction_force_baseline)[:, None]
    traces = [line for line in ax_t.lines if len(line.get_xdata()) == ds.sizes["travel"]]
    assert len(traces) == ds.sizes["example"]
    for line, f in zip(traces, force, strict=True):
        np.testing.assert_allclose(line.get_ydata(), f)
    # (c) one line per ball; (d) the factors ranked by the file's friction indices
    assert len([ln for ln in ax_z.lines if len(ln.get_xdata()) > 1]) == ds.sizes["ball"]
    total = np.asarray(ds["sensitivity_friction_total"], dtype=float)
    names = [str(f).replace("_", " ") for f in np.asarray(ds["factor_name"])]
    labels = [t.get_text() for t in ax_s.get_yticklabels()]
    assert labels == [names[i] for i in np.argsort(total)]
    # without indices or the ball diameter the figure still stands
    assert check_figure(study_report.plot_friction(ds, None, np.nan)) == []


def test_sensitivity_section_keeps_epsilon_and_contact(friction_result, friction_report):
    _, ds = friction_result
    _, page = friction_report
    sens = study_report.sensitivity_from_file(ds)
    fig = study_report.plot_sensitivity(study_report.without_output(sens))
    assert len(fig.axes) == 2
    section = _text(_section(page, "<h2>7. What drives the risk"))
    assert "The drivers of the friction increase are ranked in section 5." in section
    assert "Ranked by share of the variance of ε" in section
    assert "friction_increase" not in section


# --------------------------------------------------------------------------------------------
# PDF
# --------------------------------------------------------------------------------------------
def test_pdf_has_the_friction_section(friction_result, friction_report):
    path, ds = friction_result
    out, _ = friction_report
    sens = study_report.sensitivity_from_file(ds)
    figs = {"contact": study_report.plot_contact(ds),
            "friction": study_report.plot_friction(ds, sens, 0.01)}
    content = study_report.pdf_content(ds, figs, sens, out.verdict, path)
    from tolsim.reports.pdf import report_pages

    pages = report_pages(**content)
    texts = [" ".join(t.get_text() for t in fig.texts) for fig in pages]
    start = next(k for k, t in enumerate(texts) if FRICTION_HEADING in t)
    section = " ".join(texts[start:start + 3])
    for what in ("Friction after contact at a glance", "Distribution over the 600 resolved",
                 "Drivers of the friction increase", "μ_bb = 0.1",
                 f"{_f(ds, 'friction_force_baseline'):.4g} N"):
        assert what in section, what
    assert sum(t.count(FRICTION_HEADING) for t in texts) == 1
    assert sum(len(fig.axes) for fig in pages) == 2  # contact and friction, once each
    verdict_page = texts[0]
    assert "P(friction increase > 0.2 N) per train" in verdict_page


# --------------------------------------------------------------------------------------------
# files without friction and a carriage with friction
# --------------------------------------------------------------------------------------------
def test_a_file_without_friction_is_reported_as_before(friction_result):
    # the friction variables dropped: no section, no row, no assumptions, the standard
    # numbering and captions. (When the section was added, the reports of
    # configs/yaw_moment_tolerances.toml at 2000 assemblies and of
    # configs/carriage_preload.toml were compared with those of the tolsim before it: HTML
    # and PNGs byte for byte the same apart from the date line, the PDF text likewise.)
    _, ds = friction_result
    names = [v for v in ds.variables if v in FRICTION_VARIABLES or v in FRICTION_COORDINATES]
    plain = ds.drop_vars(names)
    assert not V.has_friction(plain)
    assert study_report.section_titles(plain) == {
        "velocity_deviation": "3. Ball velocity deviation ε",
        "contact": "4. Ball-to-ball contact", "quality": "5. Quality engineering",
        "sensitivity": "6. What drives the risk",
        "spot_checks": "7. Model check: analytic versus the full friction model"}
    assert study_report.page._sign_off_title(plain) == "8. Review and sign-off"
    assert study_report.captions(plain) == study_report.CAPTIONS
    assert len(V.study_verdict(plain).checks) == 3
    assert not [r for r in A.assumption_table(plain) if r.topic == "after contact"
                or "friction increase" in r.item]
    sens = study_report.sensitivity_from_file(plain)
    assert sens.outputs == ("velocity_deviation", "contact")
    assert study_report.without_output(sens) is sens
    assert not any("Friction after contact" in s for s in study_report.headline(plain, sens))


def test_carriage_with_friction_counts_the_worst_track(tmp_path):
    # configs/carriage_preload.toml with [contact]: an assembly is a carriage with two
    # tracks, and its friction figures are those of its worst track
    text = load_config(os.path.join(CONFIGS, "carriage_preload.toml")).text
    config = parse_config(text + "\n[contact]\nfriction_increase_limit_N = 0.1\n",
                          "carriage_contact.toml").with_overrides(samples=60)
    config = with_study_settings(config, sensitivity_samples=0)
    path = tmp_path / "carriage_contact.nc"
    write_result(run_study(config), path, history="test")
    out = study_report.make_report(path, tmp_path / "rep", sensitivity=False, pdf=False)
    page = open(out.html, encoding="utf-8").read()
    headings = re.findall(r"<h2[^>]*>([^<]*)</h2>", page)
    assert headings[3:7] == ["4. Ball velocity deviation ε", "5. Ball-to-ball contact",
                             "6. What contact costs: carriage friction after the balls touch",
                             "7. Quality engineering"]
    assert headings[-2] == "10. Review and sign-off"
    section = _text(_section(page, "id='friction'"))
    assert "Each assembly counts with the worst of its 2 tracks" in section
    assert out.verdict.checks[-1].quantity.startswith(
        "P(friction increase > 0.1 N) per assembly (its worst track)")
    with xr.open_dataset(path) as ds:
        worst = {r.item: r.value for r in A.assumption_table(ds.load())}
    assert worst["worst track per assembly"].startswith("each of the 2 tracks")
    assert "friction" in out.figures
