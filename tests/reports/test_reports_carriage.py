"""``tolsim report`` of a study with a ``[carriage]`` (tolsim issue 12): the carriage section
with the numbers of the result file, one series per track in the per-ball and per-pair
figures, P(contact) per assembly in the verdict and the tables, and the PDF.

The study is ``configs/carriage_preload.toml`` at 300 assemblies: two wrapped tracks
(orientation +-90 deg) of 12 balls of the [Lin2018] Table 1 bearing at a 10.05 mm pitch,
preload 2 um, 300 N downward and a 2 N m pitching moment.
"""

import os
import re
from dataclasses import replace

import matplotlib
import numpy as np
import pytest
import xarray as xr
from scipy.stats import binomtest
from test_reports import check_figure, synthetic_result

from tolsim.io.config import load_config
from tolsim.io.netcdf import write_result
from tolsim.reports import assumptions as A
from tolsim.reports import study as study_report
from tolsim.reports import style
from tolsim.reports import verdict as V
from tolsim.reports.result_view import _zone_end_text, circuit_rows
from tolsim.study.execution.runner import run_study

CONFIG = os.path.join(os.path.dirname(__file__), "..", "..", "configs", "carriage_preload.toml")


@pytest.fixture(scope="module")
def carriage_result(tmp_path_factory):
    """The carriage study, small: 300 assemblies, no Sobol' indices."""
    config = load_config(CONFIG).with_overrides(samples=300)
    config = replace(config, study=replace(config.study, sensitivity_samples=0))
    path = tmp_path_factory.mktemp("carriage") / "carriage.nc"
    write_result(run_study(config), path, history="test")
    with xr.open_dataset(path) as ds:
        return path, ds.load(), config


@pytest.fixture(scope="module")
def carriage_report(carriage_result, tmp_path_factory):
    path, _, _ = carriage_result
    out = study_report.make_report(path, tmp_path_factory.mktemp("rep"), sensitivity=False)
    return out, open(out.html, encoding="utf-8").read()


def _text(html_part):
    """The text of an HTML fragment, cells separated by ' | '."""
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " | ", html_part))


def _carriage_section(page):
    start = page.index("id='carriage'")
    return page[start: page.index("<h2>", start)]


# --------------------------------------------------------------------------------------------
# the page
# --------------------------------------------------------------------------------------------
def test_sections_and_figures(carriage_report):
    out, page = carriage_report
    headings = re.findall(r"<h2[^>]*>([^<]*)</h2>", page)
    assert headings == [
        "1. What was studied", "2. Results at a glance",
        "3. Carriage: load case, preload, load distribution and stiffness",
        "4. Ball velocity deviation ε", "5. Ball-to-ball contact", "6. Quality engineering",
        "7. What drives the risk", "8. Model check: analytic versus the full friction model",
        "9. Review and sign-off", "Provenance"]
    carriage = _carriage_section(page)
    for h3 in ("Load case at the reference point", "Preload",
               "Tracks and the nominal load distribution", "Carriage displacement and stiffness",
               "Solved carriages"):
        assert f"<h3>{h3}</h3>" in carriage
    # the load distribution sits in the carriage section, every PNG embedded
    assert set(out.figures) == {"carriage", "velocity_deviation", "contact", "spot_checks"}
    assert all(os.path.getsize(p) > 10_000 for p in out.figures.values())
    assert "src='data:image/png;base64," in carriage
    assert len(re.findall(r"src='data:image/png;base64,", page)) == len(out.figures)
    # no linear stack-up for a carriage: the page says why
    assert "Not computed for a carriage" in page
    assert (open(out.pdf, "rb").read(5)) == b"%PDF-"


def test_the_load_case_and_the_preload_are_the_files(carriage_result, carriage_report):
    _, ds, config = carriage_result
    _, page = carriage_report
    text = _text(_carriage_section(page))
    # the config's load: 300 N pressing down is the file's vertical_force_upward = -300 N
    names = [str(n) for n in ds.carriage_force_component_name.values] + [
        str(n) for n in ds.carriage_moment_component_name.values]
    load = dict(zip(names, [*ds.carriage_load_force.values, *ds.carriage_load_moment.values],
                    strict=True))
    assert ds.carriage_load_force.attrs["units"] == "N"
    assert ds.carriage_load_moment.attrs["units"] == "N m"
    assert load["vertical_force_upward"] == -300.0 and load["pitch_moment"] == 2.0
    assert ("radial load, downward (pressing the carriage onto the rail; negative: reverse "
            "radial load) | | 300 N | | [carriage.load] vertical_N = 300.0") in text
    assert "pitching moment (about the lateral axis x) | | 2 N m" in text
    assert "rolling moment (about the rail axis z) | | 0 N m | | default: 0" in text
    # preload: o = 2 um; F0 = K (o/2)^1.5 with K = 2.345e10 N/m^1.5 for the Table 1 ball in
    # its flank (tolsim.physics.carriage.solve_carriage Notes, "numbers for the [Lin2018]
    # Table 1 ball")
    f0 = float(ds.preload_contact_force)
    np.testing.assert_allclose(f0, 2.345e10 * (1e-6) ** 1.5, rtol=1e-3)
    assert "preload class: diametral ball oversize o | | 2 µm" in text
    assert f"F₀ = K (o/2)^1.5 | | {f0:.4g} N" in text
    n0 = 2 * f0 * np.cos(np.deg2rad(45.0))  # N0 = 2 F0 cos(beta_0), same docstring, step 3
    assert f"N₀ = 2 F₀ cos β₀ | | {n0:.4g} N" in text
    assert "sampled ball size variation (adds to o)" in text


def test_tracks_table_and_stiffness_are_the_files(carriage_result, carriage_report):
    _, ds, _ = carriage_result
    _, page = carriage_report
    text = _text(_carriage_section(page))
    ny, nx, rho = (ds[n].values for n in ("normal_load", "side_load", "side_force_ratio"))
    first = ds.contact_pair_count.values.sum(axis=1)
    assert int(first.sum()) == int(ds.n_contact)  # each assembly's first contact, once
    for t, (x, phi) in enumerate(zip(ds.track_x.values, ds.track_orientation.values,
                                     strict=True)):
        row = (f"{t} | | {1e3 * x:.4g} | | 0 | | {np.rad2deg(phi):.4g} | | "
               f"{ny[t].min():.4g} to {ny[t].max():.4g} | | "
               f"{nx[t].min():+.4g} to {nx[t].max():+.4g} | | "
               f"{rho[t].min():+.3f} to {rho[t].max():+.3f} | | {int(first[t]):,}")
        assert row in text, row
    # displacement [um, urad] and stiffness [N/um, N m/urad], nominal .. max, from the file
    stats = ("nominal", "mean", "std", "min", "max")
    u_y = [f"{round(1e6 * float(ds[f'carriage_translation_{s}'][1]), 4) + 0.0:.4f}"
           for s in stats]
    assert "vertical displacement u_y [µm] (+ up) | | " + " | | ".join(u_y) in text
    k_y = [f"{1e-6 * float(ds[f'carriage_translational_stiffness_{s}'][1]):.4g}"
           for s in stats]
    assert "vertical stiffness [N/µm] | | " + " | | ".join(k_y) in text
    k_pitch = [f"{1e-6 * float(ds[f'carriage_rotational_stiffness_{s}'][0]):.4g}"
               for s in stats]
    assert "pitching stiffness [N m/µrad] | | " + " | | ".join(k_pitch) in text
    # the units are right: near the linearised preloaded stiffness of tolsim.physics.carriage
    # (docstring step 3: a ball's S = (k_n + F0/d)/2 in each direction, k_n = 1.5 K (o/2)^0.5,
    # d = 0.4 mm; wrapped tracks turn u_y into each ball's side displacement), 24 balls for
    # u_y, S sum z^2 over both tracks for the pitch (step 5). The 300 N load and the pitch
    # moment change it by < 2 %.
    k, half = 2.345e10, 1e-6
    s_ball = 0.5 * (1.5 * k * half**0.5 + k * half**1.5 / 0.4e-3)  # [N/m]
    z = (np.arange(12) - 5.5) * 10.05e-3
    np.testing.assert_allclose(float(k_y[0]), 24 * s_ball * 1e-6, rtol=0.02)
    np.testing.assert_allclose(float(k_pitch[0]), 2 * s_ball * np.sum(z**2) * 1e-6, rtol=0.02)
    failed, n = int(ds.n_assemblies_carriage_failed), int(ds.n_assemblies)
    assert (f"solved: the statistics above are over these | | {n - failed:,}") in text
    assert "lifted off): their balls count as not converged" in text


def test_assembly_wording(carriage_result, carriage_report):
    _, ds, _ = carriage_result
    _, page = carriage_report
    box = page[page.index("id='verdict'"): page.index("1. What was studied")]
    n_known = int(ds.n_assemblies) - int(ds.n_assemblies_unresolved)
    assert (f"per assembly: contact in any of the 2 trains of a carriage "
            f"({int(ds.n_contact):,} of {n_known:,} assemblies whose outcome is known)") in box
    assert "Carriage on 2 tracks under radial load 300 N, pitching moment 2 N m" in box
    assert "per assembly (a carriage with 2 trains: contact in any of them)" in box
    glance = _text(page[page.index("2. Results at a glance"): page.index("id='carriage'")])
    assert "per assembly (contact in any of its 2 trains)" in glance
    assert "assemblies whose outcome is known" in glance and " trains whose" not in glance
    facts = _text(page[page.index("1. What was studied"): page.index("id='tolerances'")])
    assert "tracks (trains) per carriage | | 2" in facts
    assert "balls per carriage | | 24" in facts
    assert "once per track and assembly" in page


def test_verdict_counts_assemblies(carriage_result):
    # A limit on P(contact) and unresolved assemblies: the reason names assemblies.
    _, ds, _ = carriage_result
    ds = ds.copy()
    p = float(ds.contact_probability)
    ds["contact_probability_limit"] = p
    ds["n_assemblies_unresolved"] = 7
    ds["contact_probability_bounds_ci_lower"] = p - 0.2
    ds["contact_probability_bounds_ci_upper"] = p + 0.2
    check = V.contact_check(ds)
    assert check.status == V.UNDECIDED
    assert "assemblies" in check.estimate and "trains" not in check.estimate
    assert check.quantity.endswith("per assembly (a carriage with 2 trains: contact in any "
                                   "of them)")
    assert V.contact_unit(ds) == ("assembly", "assemblies")
    assert V.contact_unit(synthetic_result(np.random.default_rng(1))) == ("train", "trains")


def test_assumptions_describe_the_carriage(carriage_result):
    _, ds, config = carriage_result
    rows = A.assumption_table(ds)
    topics = {r.topic for r in rows}
    assert "loads" not in topics and "carriage" in topics
    items = {r.item: r for r in rows if r.topic == "carriage"}
    for item in ("model", "tracks (x, y, orientation φ)",
                 "ball positions of the load distribution", "load case at the reference point",
                 "groove errors per track", "Hertz contact", "preload", "carriages not solved",
                 "contact per assembly"):
        assert item in items, item
    assert "rigid carriage" in items["model"].value
    assert "track 0: x -20 mm, y 0 mm, φ +90°" in items["tracks (x, y, orientation φ)"].value
    assert "10.05 mm" in items["ball positions of the load distribution"].value
    assert items["preload"].source == "[carriage] preload_oversize_um = 2.0"
    assert "K = 2.345e+10 N/m^1.5" in items["Hertz contact"].value
    static = next(r for r in rows if r.item.startswith("static contact"))
    assert "carriage" in static.value and "[carriage]" in static.source
    limit = [r.item for r in rows if r.topic == "spec limits"]
    assert "limit on P(contact) per assembly" in limit
    # carriage_preload.toml does not name the propagation: a [carriage] study's default,
    # along_track (issue 24), not the free balls' constant, which this row said before
    propagation = next(r for r in rows if r.item.startswith("propagation"))
    assert propagation.item == "propagation: along_track"
    assert propagation.source.startswith("model default of a [carriage] study (along_track)")



def test_a_config_this_version_cannot_parse_still_gives_the_carriage(carriage_result, tmp_path):
    # the assumptions and the carriage section fall back on what the file holds
    path, ds, _ = carriage_result
    broken = ds.copy()
    broken.attrs["config"] = ds.attrs["config"].replace("[motion]", "[motion]\nfuture_key = 1")
    rows = A.assumption_table(broken)
    assert rows[0].topic == "config" and "cannot be parsed" in rows[0].value
    assert {"model", "preload", "tracks (x, y, orientation φ)"} <= {
        r.item for r in rows if r.topic == "carriage"}
    content = study_report.carriage_content(broken, None)
    assert content["ball_z"] is None and content["preload_ball_load"] is None
    fig = study_report.plot_carriage_loads(broken)
    assert fig.axes[0].get_xlabel().startswith("ball position in the train")
    nc = tmp_path / "broken.nc"
    broken.to_netcdf(nc)  # edited by hand: its checksums (if any) are not the data's
    out = study_report.make_report(nc, tmp_path / "rep", sensitivity=True, pdf=False,
                                   verify=False)
    page = open(out.html, encoding="utf-8").read()
    assert "3. Carriage" in page and "cannot be parsed" in page


def test_unsolved_carriages_are_reported(carriage_result, tmp_path):
    path, ds, _ = carriage_result
    ds = ds.copy()
    ds["n_assemblies_carriage_failed"] = np.int64(3)
    nc = tmp_path / "failed.nc"
    ds.to_netcdf(nc)  # edited by hand: its checksums are not the data's
    out = study_report.make_report(nc, tmp_path / "rep", sensitivity=False, pdf=False,
                                   verify=False)
    page = open(out.html, encoding="utf-8").read()
    n = int(ds.n_assemblies)
    assert f"; 3 of {n:,} carriages not solved." in page  # the headline
    assert f"over the {n - 3:,} solved carriages of {n:,}" in page
    assert "3 carriages not solved" in page  # results at a glance


# --------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------
def test_figures_have_one_series_per_track(carriage_result):
    _, ds, config = carriage_result
    labels = study_report.track_labels(ds)
    assert labels == ["track 0 (x = -20 mm, φ = +90°)", "track 1 (x = +20 mm, φ = -90°)"]
    fig = study_report.plot_velocity_deviation(ds)
    assert check_figure(fig) == []
    eps_ax = next(ax for ax in fig.axes if ax.get_ylabel().startswith("ε"))
    rho_ax = next(ax for ax in fig.axes if "ρ" in ax.get_ylabel())
    assert len(eps_ax.containers) == 2  # an errorbar per track
    assert [line.get_label() for line in rho_ax.lines if line.get_label() in labels] == labels
    np.testing.assert_allclose(rho_ax.lines[1].get_ydata(), ds.side_force_ratio.values[1])
    assert [t.get_text() for t in fig.legends[0].get_texts()] == labels
    # no track is drawn in the colour of the spec limits
    limit = matplotlib.colors.to_rgba(style.LIMIT_COLOUR)
    assert all(matplotlib.colors.to_rgba(line.get_color()) != limit for line in rho_ax.lines)

    fig = study_report.plot_contact(ds)
    assert check_figure(fig) == []
    pair_ax = fig.axes[2]
    assert len(pair_ax.containers) == 2
    heights = [[bar.get_height() for bar in c] for c in pair_ax.containers]
    np.testing.assert_array_equal(heights, ds.contact_pair_count.values)
    assert pair_ax.get_ylabel() == "assemblies whose first contact is here [-]"
    assert "per assembly" in fig.axes[1].get_ylabel()

    ball_z, n0, _ = study_report.sections._carriage_geometry(config)
    fig = study_report.plot_carriage_loads(ds, ball_z, n0)
    assert check_figure(fig) == []
    ny_ax, rho_ax = fig.axes
    assert len(ny_ax.lines) == 3 and len(rho_ax.lines) == 3  # two tracks and a level line
    np.testing.assert_allclose(ny_ax.lines[0].get_xdata(), 1e3 * ball_z)
    np.testing.assert_allclose(ny_ax.lines[1].get_ydata(), ds.normal_load.values[1])
    np.testing.assert_allclose(ny_ax.lines[2].get_ydata(), [n0, n0])  # the preload alone
    assert "radial load 300 N, pitching moment 2 N m" in fig._suptitle.get_text()


def test_single_train_titles_are_unchanged(rng):
    # a study of single trains keeps its section numbers, captions and wording
    ds = synthetic_result(rng)
    assert study_report.section_titles(ds) == {
        "velocity_deviation": "3. Ball velocity deviation ε",
        "contact": "4. Ball-to-ball contact", "quality": "5. Quality engineering",
        "sensitivity": "6. What drives the risk",
        "spot_checks": "7. Model check: analytic versus the full friction model"}
    assert study_report.captions(ds) == study_report.CAPTIONS
    assert study_report.track_labels(ds) == []
    assert study_report.headline(ds)[0].endswith("trains whose outcome is known).")


# --------------------------------------------------------------------------------------------
# PDF
# --------------------------------------------------------------------------------------------
def test_pdf_has_the_carriage_section(carriage_result, carriage_report):
    path, ds, _ = carriage_result
    out, _ = carriage_report
    figs = {"carriage": study_report.plot_carriage_loads(ds),
            "contact": study_report.plot_contact(ds)}
    content = study_report.pdf_content(ds, figs, None, out.verdict, path)
    from tolsim.reports.pdf import report_pages

    pages = report_pages(**content)
    texts = [" ".join(t.get_text() for t in fig.texts) for fig in pages]
    start = next(k for k, t in enumerate(texts) if "3. Carriage: load case" in t)
    section = " ".join(texts[start:start + 3])
    for what in ("Load case at the reference point", "Preload", "Carriage displacement and "
                 "stiffness", "vertical stiffness [N/µm]", "Solved carriages"):
        assert what in section, what
    k_y = 1e-6 * float(ds.carriage_translational_stiffness_nominal[1])
    assert f"{k_y:.4g}" in section
    # the load distribution is drawn once, in its section, not again among the figures
    assert sum(t.count("5. Ball-to-ball contact") for t in texts) == 1
    images = [len(fig.axes) for fig in pages]
    assert sum(images) == 2
    assert all(f"page {i} of {len(pages)}" in t for i, t in enumerate(texts, 1))


def test_the_zone_end_fraction_has_its_interval():
    # By hand: first contacts per pair [[3, 1, 2], [1, 0, 3]] (track by pair): 10, of which
    # 3 + 2 + 1 + 3 = 9 at a first or last pair, 90 %; its 95 % Clopper-Pearson interval
    # (scipy's binomtest, exact) [55.5, 99.7] %, with or without a circuit.
    ds = xr.Dataset({"contact_zone_end_fraction": ((), 0.9),
                     "contact_pair_count": (("track", "pair"), np.array([[3, 1, 2], [1, 0, 3]]))})
    ci = binomtest(9, 10).proportion_ci(confidence_level=0.95, method="exact")
    label, text = circuit_rows(ds)[0]
    assert label == "first contacts at the ends of the loaded zone (first or last pair)"
    assert text == f"90.0 % [{100 * ci.low:.1f}, {100 * ci.high:.1f}] (95 %, of 10 first " \
                   "contacts)"
    assert (ci.low, ci.high) == pytest.approx((0.555, 0.9975), abs=5e-4)
    ds["circuit_balls"] = 30
    assert _zone_end_text(ds, 0.9) == f"90.0 % [{100 * ci.low:.1f}, {100 * ci.high:.1f}] " \
                                      "(95 %, of 10 first contacts)"
