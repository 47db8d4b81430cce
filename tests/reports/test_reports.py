"""Figures of tolsim.reports: labelled axes with units, no overlapping labels, no global state."""

import base64
import itertools
import subprocess
import sys
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
import xarray as xr

from tolsim.reports import paper, style
from tolsim.reports import study as study_report
from tolsim.reports.verdict import (
    cpk_check,
    judge_lower_limit,
    judge_upper_limit,
    out_of_spec_check,
)
from tolsim.study.statistics import quality
from tolsim.study.statistics.intervals import format_fraction


def _renderer(fig):
    fig.canvas.draw()
    return fig.canvas.get_renderer()


def _labels(fig):
    """(name, bbox) of titles, axis labels and legends, for overlap checks."""
    r = _renderer(fig)
    items = []
    if fig._suptitle is not None and fig._suptitle.get_text():
        items.append(("suptitle", fig._suptitle.get_window_extent(r)))
    for k, ax in enumerate(fig.axes):
        for name, text in (("title", ax.title), ("xlabel", ax.xaxis.label),
                           ("ylabel", ax.yaxis.label)):
            if text.get_text() and text.get_visible():
                items.append((f"axes{k}.{name}", text.get_window_extent(r)))
        leg = ax.get_legend()
        if leg is not None:
            items.append((f"axes{k}.legend", leg.get_window_extent(r)))
    return items


def _categorical(fig, axis):
    """True when the axis has text (not numeric) tick labels, e.g. factor names."""
    _renderer(fig)
    for t in axis.get_ticklabels():
        text = t.get_text().replace("\u2212", "-").strip()
        if text:
            try:
                float(text)
            except ValueError:
                return True
    return False


def check_figure(fig, *, units=True):
    """Every data axes has x and y labels (with a unit in brackets when ``units``), and no
    title, axis label or legend overlaps another, and axes do not overlap each other."""
    problems = []
    for k, ax in enumerate(fig.axes):
        is_colorbar = hasattr(ax, "_colorbar") or ax.get_label() == "<colorbar>"
        xl, yl = ax.get_xlabel(), ax.get_ylabel()
        if is_colorbar:
            if not (xl or yl):
                problems.append(f"colorbar {k} has no label")
            continue
        if not ax.get_visible() or not ax.has_data():
            continue
        twin = any(other is not ax and other.bbox.bounds == ax.bbox.bounds
                   for other in fig.axes)
        shared_x = any(o is not ax and o.get_shared_x_axes().joined(ax, o) and o.get_xlabel()
                       for o in fig.axes)
        shared_y = any(o is not ax and o.get_shared_y_axes().joined(ax, o) and o.get_ylabel()
                       for o in fig.axes)
        if not yl and not shared_y:
            problems.append(f"axes {k} ({ax.get_title()!r}) has no y label")
        if not xl and not twin and not shared_x:
            problems.append(f"axes {k} ({ax.get_title()!r}) has no x label")
        if units:
            for lab, axis in ((xl, ax.xaxis), (yl, ax.yaxis)):
                if lab and "[" not in lab and not _categorical(fig, axis):
                    problems.append(f"axes {k}: label {lab!r} has no [unit]")
    items = _labels(fig)
    for (na, a), (nb, b) in itertools.combinations(items, 2):
        if a.overlaps(b) and a.intersection(a, b).width > 1 and a.intersection(a, b).height > 1:
            problems.append(f"{na} overlaps {nb}")
    r = _renderer(fig)
    boxes = [(k, ax.get_window_extent(r)) for k, ax in enumerate(fig.axes)]
    for (ka, a), (kb, b) in itertools.combinations(boxes, 2):
        if a.bounds == b.bounds:  # twin axes
            continue
        inter = a.intersection(a, b)
        if inter is not None and inter.width > 2 and inter.height > 2:
            problems.append(f"axes {ka} overlaps axes {kb}")
    return problems


# --------------------------------------------------------------------------------------------
# paper figures
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def paper_data_small():
    from tolsim.study.analyses import paper_data

    table = paper.table2_table()
    curves, slopes = paper_data.fig4_data(offset_ratio=np.linspace(-3, 3, 61))
    grid = paper_data.fig7_data(np.linspace(-0.8, 0.8, 9), np.linspace(-3, 3, 7))
    return table, curves, slopes, grid


def test_fig4_labels_and_layout(paper_data_small):
    _, curves, slopes, _ = paper_data_small
    fig = paper.plot_fig4(curves, slopes)
    assert check_figure(fig) == []
    legend = fig.axes[0].get_legend()
    texts = [t.get_text() for t in legend.get_texts()]
    # one entry per conformity plus the two line styles
    assert len(texts) == len(slopes) + 2 and all(f"{c:.2f}" in " ".join(texts)
                                                 for c in slopes["conformity"])


def test_fig7_labels_and_layout(paper_data_small):
    *_, grid = paper_data_small
    fig = paper.plot_fig7(grid)
    assert check_figure(fig) == []
    assert len([ax for ax in fig.axes if ax.get_label() == "<colorbar>"]) == 2


def test_fig9_labels_and_layout(paper_data_small):
    table = paper_data_small[0]
    fig = paper.plot_fig9(paper.fig9_data(table))
    assert check_figure(fig) == []


def test_table2_markdown_has_no_negative_zero(paper_data_small):
    md = paper.table2_markdown(paper_data_small[0])
    assert "-0.000" not in md and "+0.754" in md


# --------------------------------------------------------------------------------------------
# study figures on a synthetic result (no study run needed)
# --------------------------------------------------------------------------------------------
def synthetic_result(rng, limit=0.005):
    """A Dataset with the result-file variables the report reads, from known draws."""
    xr = pytest.importorskip("xarray")
    balls, n_asm = 5, 4000
    eps = rng.normal(0.0005, 0.0015, size=(n_asm, balls))
    edges = np.linspace(-0.02, 0.02, 401)
    hist, _ = np.histogram(eps, edges)
    t_edges = np.linspace(0, 2.0, 201)
    t_contact = rng.exponential(3.0, size=n_asm)
    t_hist, _ = np.histogram(t_contact[t_contact <= 2.0], t_edges)
    n_contact = int((t_contact <= 2.0).sum())
    levels = np.array([0.001, 0.01, 0.05, 0.1, 0.25, 0.5, 0.75, 0.9, 0.95, 0.99, 0.999])
    k = 20
    full = rng.normal(0, 0.002, k)
    ds = xr.Dataset(
        {
            "velocity_deviation_mean": eps.mean(), "velocity_deviation_std": eps.std(ddof=1),
            "velocity_deviation_min": eps.min(), "velocity_deviation_max": eps.max(),
            "velocity_deviation_quantile": ("quantile", np.quantile(eps, levels)),
            "velocity_deviation_histogram": ("velocity_deviation_bin", hist),
            "velocity_deviation_underflow": 0, "velocity_deviation_overflow": 0,
            "velocity_deviation_mean_by_ball": ("ball", eps.mean(axis=0)),
            "velocity_deviation_std_by_ball": ("ball", eps.std(axis=0, ddof=1)),
            "side_force_ratio": ("ball", np.linspace(-0.4, 0.4, balls)),
            "contact_probability": n_contact / n_asm,
            "contact_probability_ci_lower": 0.9 * n_contact / n_asm,
            "contact_probability_ci_upper": 1.1 * n_contact / n_asm,
            "time_to_contact_quantile": ("quantile", np.quantile(t_contact, levels)),
            "time_to_contact_min": t_contact.min(),
            "survival_probability": ("elapsed_time",
                                     1 - np.concatenate([[0], np.cumsum(t_hist)]) / n_asm),
            "contact_pair_count": ("pair", np.bincount(rng.integers(0, balls - 1, n_contact),
                                                       minlength=balls - 1)),
            "horizon": 2.0, "groove_velocity": 0.2,
            "n_assemblies": n_asm, "n_assemblies_valid": n_asm, "n_contact": n_contact,
            "n_balls": eps.size, "n_balls_valid": eps.size, "n_balls_not_converged": 0,
            "n_balls_loss_of_contact": 0, "n_balls_outside_validity": 0,
            "velocity_deviation_limit": limit, "contact_probability_limit": 0.5,
            "spot_check_velocity_deviation_analytic": ("spot_check", full + 1e-5),
            "spot_check_velocity_deviation_full": ("spot_check", full),
            "spot_check_valid_analytic": ("spot_check", np.ones(k, np.int8)),
            "spot_check_valid_full": ("spot_check", np.r_[np.ones(k - 1), 0].astype(np.int8)),
            "spot_check_rms_difference": 1e-5, "spot_check_max_abs_difference": 1e-5,
        },
        coords={
            "quantile": levels, "ball": np.arange(balls), "pair": np.arange(balls - 1),
            "elapsed_time": t_edges, "spot_check": np.arange(k),
            "velocity_deviation_bin_bounds": (("velocity_deviation_bin", "bounds"),
                                              np.stack([edges[:-1], edges[1:]], axis=1)),
        },
        attrs={"title": "tolsim Monte Carlo tolerance study: synthetic.toml",
               "velocity_model": "analytic", "spot_check_status": "20 balls re-solved"},
    )
    return ds


def test_study_figures_labels_and_layout(rng):
    ds = synthetic_result(rng)
    for plot in (study_report.plot_velocity_deviation, study_report.plot_contact,
                 study_report.plot_spot_checks):
        fig = plot(ds)
        assert check_figure(fig) == [], plot.__name__
    q = quality.dataset_quality(ds)
    fig = study_report.plot_quality(ds, q)
    assert check_figure(fig) == []
    # the quality annotation states the computed Cpk
    text = " ".join(t.get_text() for t in fig.axes[0].texts)
    assert f"Cpk = {q['velocity_deviation_cpk']:.2f}" in text


def test_sensitivity_figure(rng):
    from scipy import stats

    from tolsim.study.analyses.sensitivity import sobol_sensitivity

    res = sobol_sensitivity(lambda x: {"velocity_deviation": x @ [1.0, 0.5, 0.1],
                                       "contact": (x @ [1.0, 0.5, 0.1] > 1).astype(float)},
                            [stats.norm()] * 3, 256, rng, factors=["a_long_name", "b", "c"],
                            n_resamples=100)
    fig = study_report.plot_sensitivity(res)
    assert check_figure(fig) == []
    # ranked: the largest total effect at the top (last y tick)
    labels = [t.get_text() for t in fig.axes[0].get_yticklabels()]
    assert labels[-1] == "a long name"


def test_indices_not_estimable_are_said_so_in_file_report_and_figure():
    # rare_contact.toml with gaps U(0, 1 um) and importance sampling: contact varied in 3 of
    # 2 048 base rows; the report ranked
    # the sources by S_T = 1.669 [0.334, nan]. Now the indices are NaN with the reason, which
    # the result file carries (not_estimable attribute), the report's table and its figure say
    from scipy import stats

    from tolsim.io.schema import sensitivity as schema
    from tolsim.reports.study.sensitivity import sensitivity_from_file
    from tolsim.reports.study.shared import sensitivity_blocks
    from tolsim.study.analyses.sensitivity import sobol_sensitivity

    def func(x):
        contact = np.zeros(len(x))
        contact[[5, 17, 1024 + 40, 2048 + 40, 3072 + 40]] = 1.0  # rows 5, 17 of A, 40 of B
        return {"velocity_deviation": x @ [1.0, 0.5], "contact": contact}

    res = sobol_sensitivity(func, [stats.norm()] * 2, 1024, np.random.default_rng(7),
                            factors=["a", "b"], n_resamples=1000)
    reason = res.reasons[1]
    assert res.reasons[0] == "" and reason.startswith("the output varies in only 3 of 2,048")
    result = SimpleNamespace(sensitivity=res, config=SimpleNamespace(
        study=SimpleNamespace(sensitivity_samples=1024)))
    ds = schema.assign(result, xr.Dataset())
    schema.finish(result, ds)
    assert ds["sensitivity_contact_total"].attrs["not_estimable"] == reason
    assert "not_estimable" not in ds["sensitivity_total"].attrs
    sens = sensitivity_from_file(ds)
    assert sens.reasons == ("", reason) and np.all(np.isnan(sens.total[1]))
    blocks = sensitivity_blocks(sens, ds)
    assert blocks[1]["table"] is None and reason in blocks[1]["lead"]
    fig = study_report.plot_sensitivity(sens)
    assert check_figure(fig) == []
    assert "not estimable" in " ".join(t.get_text() for t in fig.axes[1].texts)
    for ax in fig.axes:
        assert np.all(np.isfinite(ax.get_xlim()))


def test_check_figure_catches_problems():
    # The checker itself must be able to fail: no labels, and a legend over a title.
    fig, ax = style.new_figure(4, 3)
    ax.plot([0, 1], [0, 1], label="x")
    assert any("no y label" in p for p in check_figure(fig))
    ax.set_xlabel("time")
    ax.set_ylabel("y [m]")
    assert any("no [unit]" in p for p in check_figure(fig))


# --------------------------------------------------------------------------------------------
# style and layers
# --------------------------------------------------------------------------------------------
def test_no_global_matplotlib_state():
    before = dict(matplotlib.rcParams)
    backend = matplotlib.get_backend()
    fig, ax = style.new_figure()
    ax.plot([0, 1], [1, 2])
    png = style.render_png(fig)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert matplotlib.get_backend() == backend
    assert dict(matplotlib.rcParams) == before
    uri = style.data_uri(png)
    assert base64.b64decode(uri.split(",", 1)[1]) == png


def test_layers_physics_and_study_do_not_import_plotting():
    # tolsim.study.analyses.sensitivity and .quality are NumPy/SciPy only (team layering rule).
    code = ("import sys, tolsim.study.analyses.sensitivity, tolsim.study.statistics.quality; "
            "bad = [m for m in ('matplotlib', 'xarray', 'tomllib') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_quality_and_verdict_on_the_page(rng, tmp_path):
    # The synthetic result through the whole report (no sensitivity): the quality section
    # shows the Cpk computed from the file's mean/std and the contact-probability verdict.
    from tolsim.io import schema

    ds = synthetic_result(rng)
    ds.attrs.update({a: "x" for a in schema.GLOBAL_ATTRIBUTES if a not in ds.attrs})
    ds.attrs.update(Conventions="CF-1.10", seed=1, config="")
    path = tmp_path / "synthetic.nc"
    ds.to_netcdf(path)  # a file made by hand: no checksums to verify
    out = study_report.make_report(path, tmp_path / "rep", sensitivity=False, verify=False)
    page = open(out.html, encoding="utf-8").read()
    mean, std = float(ds.velocity_deviation_mean), float(ds.velocity_deviation_std)
    cpk = (0.005 - abs(mean)) / (3 * std)
    assert f"{cpk:.3f}" in page
    # the verdict box: the synthetic file has no partial-identification bounds, so P(contact)
    # is judged on its Clopper-Pearson interval against the limit 0.5
    lo, hi = float(ds.contact_probability_ci_lower), float(ds.contact_probability_ci_upper)
    expected = "PASS" if hi <= 0.5 else "FAIL" if lo > 0.5 else "UNDECIDED"
    assert f"Verdict: {expected}" in page
    assert page.index("id='verdict'") < page.index("1. What was studied")
    assert set(out.figures) == {"velocity_deviation", "contact", "spot_checks", "quality"}


# --------------------------------------------------------------------------------------------
# issue 17, item 6: figure defects
# --------------------------------------------------------------------------------------------
#: Spot checks of ``configs/whatif_along_track.toml`` (2000 samples, seed 7): epsilon of the
#: full model and of the analytic model [-]. With these the old difference panel hid 4 of the
#: 10 points under its counts box, and the identity panel's x tick labels ran into each other.
WHATIF_FULL = np.array([-1.344989e-03, 5.186756e-04, 1.769682e-05, 2.272483e-04, -2.909830e-04,
                        1.800118e-04, 3.579608e-04, -3.059533e-04, -9.874521e-05, -3.055278e-04])
WHATIF_ANALYTIC = np.array([-1.327892e-03, 5.128464e-04, 1.750249e-05, 2.250345e-04,
                            -2.877312e-04, 1.782268e-04, 3.539890e-04, -3.029387e-04,
                            -9.781989e-05, -3.025173e-04])


def whatif_spot_checks(rng, stratum=None):
    ds = synthetic_result(rng).drop_dims("spot_check")
    k = WHATIF_FULL.size
    ds = ds.assign_coords(spot_check=np.arange(k))
    ds["spot_check_velocity_deviation_full"] = ("spot_check", WHATIF_FULL)
    ds["spot_check_velocity_deviation_analytic"] = ("spot_check", WHATIF_ANALYTIC)
    ds["spot_check_valid_analytic"] = ("spot_check", np.ones(k, np.int8))
    ds["spot_check_valid_full"] = ("spot_check", np.ones(k, np.int8))
    if stratum is not None:
        ds["spot_check_stratum"] = ("spot_check", np.asarray(stratum, np.int8))
    return ds


def _boxes_over_data(fig):
    """(what, number of data points under it) for every legend and framed text box."""
    r = _renderer(fig)
    boxes = [leg.get_window_extent(r) for leg in fig.legends]
    for ax in fig.axes:
        if ax.get_legend() is not None:
            boxes.append(("legend", ax.get_legend().get_window_extent(r)))
        boxes += [("text", t.get_window_extent(r)) for t in ax.texts
                  if t.get_bbox_patch() is not None]
    boxes = [b if isinstance(b, tuple) else ("figure legend", b) for b in boxes]
    out = []
    for name, box in boxes:
        hidden = 0
        for ax in fig.axes:
            for line in ax.lines:
                if line.get_marker() in (None, "None", "", " "):
                    continue
                xy = ax.transData.transform(np.column_stack(line.get_data()))
                hidden += int(np.sum([box.contains(x, y) for x, y in xy]))
        out.append((name, hidden))
    return out


def _tick_label_clashes(fig):
    r = _renderer(fig)
    clashes = []
    for k, ax in enumerate(fig.axes):
        for axis in (ax.xaxis, ax.yaxis):
            boxes = [t.get_window_extent(r) for t in axis.get_ticklabels()
                     if t.get_visible() and t.get_text()]
            for a, b in itertools.combinations(boxes, 2):
                inter = a.intersection(a, b)
                if inter is not None and inter.width > 0.5 and inter.height > 0.5:
                    clashes.append(f"axes {k}")
    return clashes


def test_spot_check_figure_hides_no_point_whatif_along_track(rng):
    # Issue 17: the whatif_along_track spot-check figure hid 4 of its 10 points under the
    # counts box and its x tick labels clashed. Every point must be visible, ticks apart.
    fig = study_report.plot_spot_checks(whatif_spot_checks(rng))
    assert [(name, n) for name, n in _boxes_over_data(fig) if n] == []
    assert _tick_label_clashes(fig) == []
    assert check_figure(fig) == []
    # both data panels still show all 10 points
    points = [sum(len(line.get_xdata()) for line in ax.lines if line.get_marker() not in
                  (None, "None", "", " ")) for ax in fig.axes[:2]]
    assert points == [10, 10]


def test_spot_check_figure_shows_the_strata(rng):
    # uniform checks as filled circles, near-limit checks as open diamonds, named in a legend
    fig = study_report.plot_spot_checks(whatif_spot_checks(rng, stratum=[0] * 5 + [1] * 5))
    markers = {line.get_marker(): len(line.get_xdata()) for line in fig.axes[0].lines
               if line.get_marker() not in (None, "None", "", " ")}
    assert markers == {"o": 5, "D": 5}
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    assert any("near the spec limit" in t and "(5)" in t for t in labels)
    assert any("drawn uniformly" in t and "(5)" in t for t in labels)
    counts = " ".join(t.get_text() for ax in fig.axes for t in ax.texts)
    assert "near the limit: 5" in counts and "drawn uniformly: 5" in counts


def test_side_force_ratio_has_its_own_axes(rng):
    # Issue 17: rho on a twin axis of the epsilon-along-the-train panel lined up rho = 0.4
    # with the 0.5 % limit line, as if rho reached the spec limit. rho now has its own axes
    # (no twin sharing a bounding box), labelled with rho, that draws no limit line.
    fig = study_report.plot_velocity_deviation(synthetic_result(rng))
    assert check_figure(fig) == []
    r = _renderer(fig)
    boxes = [ax.get_window_extent(r).bounds for ax in fig.axes]
    assert len(set(boxes)) == len(boxes), "twin axes"
    rho_axes = [ax for ax in fig.axes if "ρ" in ax.get_ylabel()]
    eps_axes = [ax for ax in fig.axes if ax.get_ylabel().startswith("ε")]
    assert len(rho_axes) == 1 and len(eps_axes) == 1
    rho_ax, eps_ax = rho_axes[0], eps_axes[0]
    assert rho_ax is not eps_ax
    limit_colour = matplotlib.colors.to_rgba(style.LIMIT_COLOUR)
    assert not [line for line in rho_ax.lines if matplotlib.colors.to_rgba(
        line.get_color()) == limit_colour]
    # the epsilon panel shows the limit, and the mean +- std markers are not in its colour
    assert [line for line in eps_ax.lines
            if matplotlib.colors.to_rgba(line.get_color()) == limit_colour]
    assert all(matplotlib.colors.to_rgba(c.get_color()[0] if np.ndim(c.get_color()) > 1
                                         else c.get_color()) != limit_colour
               for c in eps_ax.collections if hasattr(c, "get_color"))


@pytest.mark.parametrize("model", ["eq24", "analytic", "full"])
def test_model_check_heading_names_the_velocity_model(rng, tmp_path, model):
    # Issue 17: the section heading always said "analytic"; it names the study's model.
    from tolsim.io import schema

    ds = synthetic_result(rng)
    ds.attrs.update({a: "x" for a in schema.GLOBAL_ATTRIBUTES if a not in ds.attrs})
    ds.attrs.update(Conventions="CF-1.10", seed=1, config="", velocity_model=model)
    path = tmp_path / "synthetic.nc"
    ds.to_netcdf(path)  # a file made by hand: no checksums to verify
    out = study_report.make_report(path, tmp_path / "rep", sensitivity=False, pdf=False,
                                   verify=False)
    page = open(out.html, encoding="utf-8").read()
    assert f"<h2>7. Model check: {model} versus the full friction model</h2>" in page
    others = {"eq24", "analytic", "full"} - {model}
    assert not any(f"Model check: {m} versus" in page for m in others)


# ---------------------------------------------------------------------------------------------
# Issue 26, item 3: one verdict rule (the displayed interval shows the verdict)
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("upper, status", [(1.32969, "fail"), (1.33032, "undecided")])
def test_cpk_verdict_agrees_with_the_displayed_interval(upper, status):
    # two reports showed "1.309 to 1.330" against Cpk >= 1.33: one FAIL, one UNDECIDED
    cap = SimpleNamespace(cpk=1.3195, cpk_lower=1.30912, cpk_upper=upper, cpk_percentile=1.31)
    check = cpk_check(xr.Dataset(), {"_capability": cap}, cpk_minimum=1.33)
    assert check.status == status
    shown = check.estimate.split("interval ")[1].split(")")[0]  # "1.3091 to 1.3297"
    lo, hi = (float(x) for x in shown.split(" to "))
    assert judge_lower_limit(lo, hi, 1.33) == status  # the display gives the verdict
    assert hi != 1.33  # an end is never shown as the limit unless it is
    assert f"({shown})" in check.reason
    other = 1.33032 if upper == 1.32969 else 1.32969
    cap2 = SimpleNamespace(cpk=1.3195, cpk_lower=1.30912, cpk_upper=other, cpk_percentile=1.31)
    assert cpk_check(xr.Dataset(), {"_capability": cap2}, cpk_minimum=1.33).estimate \
        != check.estimate


@pytest.mark.parametrize("upper, status", [(0.0019996, "pass"), (0.0020004, "undecided")])
def test_fraction_verdict_agrees_with_the_displayed_interval(upper, status):
    ds = xr.Dataset({"velocity_deviation_limit": 0.005})
    prop = SimpleNamespace(fraction=0.0015, lower=0.001, upper=upper,
                           text=lambda d=3: format_fraction(0.0015, 0.001, upper, d))
    check = out_of_spec_check(ds, {"_proportion": prop}, out_of_spec_limit=0.002)
    assert check.status == status
    shown = check.reason.split("(")[1].split(")")[0]  # "0.1 % to 0.19996 %"
    lo, hi = (float(x.split()[0]) / 100 for x in shown.split(" to "))
    assert judge_upper_limit(lo, hi, 0.002) == status
    assert hi != 0.002


@pytest.mark.parametrize("name, value", [("out_of_spec_limit", -1.0),
                                         ("out_of_spec_limit", float("nan")),
                                         ("out_of_spec_limit", 2.0),
                                         ("cpk_minimum", -5.0),
                                         ("friction_exceedance_limit", 0.0)])
def test_make_report_refuses_a_spec_limit_out_of_its_range(tmp_path, name, value):
    # make_report took these as "no spec limit given" (or 2.0 as "<= 200 %"): refused,
    # naming the argument, before the file is read
    with pytest.raises(ValueError, match=f"{name} = .* must be in"):
        study_report.make_report(tmp_path / "none.nc", tmp_path / "rep", **{name: value})
    assert not (tmp_path / "rep").exists()


def test_a_report_into_a_file_fails_before_any_work(tmp_path):
    # API audit, session 24: os.makedirs' raw FileExistsError, after the figures were drawn
    from tolsim.reports.compare import compare_runs
    from tolsim.reports.sweep import make_sweep_report

    taken = tmp_path / "taken"
    taken.write_text("not a folder")
    missing = tmp_path / "missing.nc"  # not read: the folder is checked first
    for call in (lambda: study_report.make_report(missing, taken),
                 lambda: make_sweep_report(missing, taken),
                 lambda: compare_runs([missing, missing], taken)):
        with pytest.raises(ValueError, match=f"{taken} exists and is not a folder"):
            call()
    assert taken.read_text() == "not a folder"
