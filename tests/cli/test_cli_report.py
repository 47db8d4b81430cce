"""``tolsim report``: works on the output of every config in configs/, and rejects non-results."""

import base64
import glob
import os
import re
import tomllib

import numpy as np
import pytest

from tolsim.cli import main


def _is_sweep(path) -> bool:
    with open(path, "rb") as fh:
        return "sweep" in tomllib.load(fh)


#: every config, those with a [carriage] (issue 12) included; the what-if sweeps (issue 14)
#: have a report of their own, run on every one of them in tests/reports/test_reports_sweep.py
CONFIGS = sorted(p for p in glob.glob(os.path.join(os.path.dirname(__file__), "..", "..", "configs",
                                                   "*.toml")) if not _is_sweep(p))
#: small sample counts keep the test fast (along-track propagation is ~100x dearer)
SAMPLES = {"constant": 64, "along_track": 8}


def _run_config(path, out):
    config_mod = pytest.importorskip("tolsim.io.config", reason="issue 5 config not installed")
    runner = pytest.importorskip("tolsim.study.execution.runner",
                                 reason="issue 5 runner not installed")
    netcdf = pytest.importorskip("tolsim.io.netcdf", reason="issue 5 writer not installed")
    config = config_mod.load_config(path)
    config = config.with_overrides(samples=SAMPLES[config.study.propagation])
    result = runner.run_study(config)
    netcdf.write_result(result, out, history="test")
    return config


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    folder = tmp_path_factory.mktemp("results")
    out = {}
    for path in CONFIGS:
        name = os.path.splitext(os.path.basename(path))[0]
        nc = folder / f"{name}.nc"
        config = _run_config(path, nc)
        out[name] = (nc, config)
    return out


def test_there_are_configs():
    assert len(CONFIGS) >= 2


@pytest.mark.parametrize("name", [os.path.splitext(os.path.basename(p))[0] for p in CONFIGS])
def test_report_every_config(results, name, tmp_path, capsys):
    nc, config = results[name]
    out = tmp_path / "report"
    assert main(["report", str(nc), "-o", str(out), "--sensitivity-samples", "16"]) == 0
    assert "wrote" in capsys.readouterr().out
    page = (out / "report.html").read_text(encoding="utf-8")
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert {"velocity_deviation.png", "contact.png", "spot_checks.png"} <= set(pngs)
    # self-contained: every PNG is embedded as a data URI, byte for byte
    uris = re.findall(r"src='data:image/png;base64,([A-Za-z0-9+/=]+)'", page)
    assert len(uris) == len(pngs)
    embedded = {base64.b64decode(u) for u in uris}
    assert all((out / p).read_bytes() in embedded for p in pngs)
    assert "http://" not in page and "https://" not in page  # nothing fetched from outside
    # what was studied: the config text and the seed are on the page
    first_key = next(line for line in config.text.splitlines() if line.startswith("["))
    assert first_key in page
    assert f"<td class=\"num\">{config.study.seed}</td>" in page
    # the numbers of the file are the numbers on the page
    import xarray as xr

    with xr.open_dataset(nc) as ds:
        p = float(ds.contact_probability)
        lo, hi = float(ds.contact_probability_ci_lower), float(ds.contact_probability_ci_upper)
        limit = float(ds.velocity_deviation_limit)
    from tolsim.study.statistics.quality import format_fraction

    assert format_fraction(p, lo, hi) in page
    random_factors = [t for t in config.tolerances if t.distribution.is_random]
    if random_factors:
        assert "sensitivity.png" in pngs and "Ranked by" in page
        assert random_factors[0].source in page
    else:
        assert "nothing to rank" in page
    if np.isfinite(limit) and limit > 0:
        assert "quality.png" in pngs and "Cpk" in page
    else:
        assert "quality.png" not in pngs
    # issue 17: the verdict box at the top, the initial gap among the sampled inputs, the
    # assumptions table, the model check named after the study's model, and the PDF
    assert page.index("id='verdict'") < page.index("1. What was studied")
    tolerances = page[page.index("id='tolerances'"):]
    assert "<td>initial_gap</td>" in tolerances[: tolerances.index("</table>")]
    assert "id='assumptions'" in page and "VALIDITY_ERROR_BUDGET" in page
    carriage = config.carriage is not None  # its section 3 moves the later ones down
    friction = config.contact is not None  # and so does "What contact costs" ([contact])
    model_check = f"{7 + carriage + friction}. Model check: {config.study.velocity_model} versus"
    assert model_check in page
    assert (out / "report.pdf").read_bytes()[:5] == b"%PDF-"
    # issue 17: worst case and RSS beside the Monte Carlo, from the file's stack-up (none for
    # a carriage, whose balls are coupled: the page says so)
    assert "Linear stack-up beside the Monte Carlo" in page
    assert ("Not computed for a carriage" in page) == carriage
    # issue 12: a carriage study has its section with the load distribution, per assembly
    if carriage:
        assert "3. Carriage: load case, preload, load distribution and stiffness" in page
        assert "carriage.png" in pngs and "per assembly" in page
    else:
        assert "carriage.png" not in pngs and "id='carriage'" not in page


def test_report_uses_stored_sensitivity(results, tmp_path):
    # A file that already holds indices along a 'factor' dimension is shown as is (nothing
    # recomputed): the ranking on the page follows the stored numbers.
    import xarray as xr

    nc, _ = results["yaw_moment_tolerances"] if "yaw_moment_tolerances" in results else next(
        iter(results.values()))
    with xr.open_dataset(nc) as ds:
        ds = ds.load().drop_dims("factor", errors="ignore")  # replace any computed indices
    ds = ds.assign_coords(factor=("factor", [0, 1]),
                          factor_name=("factor", np.array(["alpha_source", "beta_source"])))
    ds["sensitivity_first_order"] = ("factor", np.array([0.1, 0.6]))
    ds["sensitivity_total"] = ("factor", np.array([0.2, 0.7]))
    ds["sensitivity_total_ci_lower"] = ("factor", np.array([0.15, 0.65]))
    ds["sensitivity_total_ci_upper"] = ("factor", np.array([0.25, 0.75]))
    ds["sensitivity_contact_first_order"] = ("factor", np.array([0.5, 0.05]))
    ds["sensitivity_contact_total"] = ("factor", np.array([0.9, 0.1]))
    stored = tmp_path / "stored.nc"
    # edited by hand: without the checksums of the original (read with a warning)
    ds.attrs.pop("checksum_scheme", None)
    for var in ds.variables.values():
        var.attrs.pop("sha256", None)
    ds.to_netcdf(stored)
    out = tmp_path / "rep"
    assert main(["report", str(stored), "-o", str(out), "--quiet"]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert "stored in the result file" in page
    # epsilon ranking first (beta above alpha), then the contact ranking (alpha above beta)
    eps_part, contact_part = page.split("Ranked by")[1:3]
    assert eps_part.index("beta_source") < eps_part.index("alpha_source")
    assert contact_part.index("alpha_source") < contact_part.index("beta_source")
    assert "0.700 [0.650, 0.750]" in eps_part
    assert (out / "sensitivity.png").exists()


def test_no_sensitivity_flag(results, tmp_path):
    nc, _ = next(iter(results.values()))
    out = tmp_path / "rep"
    assert main(["report", str(nc), "-o", str(out), "--no-sensitivity", "--quiet"]) == 0
    assert not (out / "sensitivity.png").exists()
    assert "not requested" in (out / "report.html").read_text(encoding="utf-8")


def test_no_pdf_flag(results, tmp_path, capsys):
    nc, _ = next(iter(results.values()))
    out = tmp_path / "rep"
    assert main(["report", str(nc), "-o", str(out), "--no-sensitivity", "--no-pdf"]) == 0
    assert (out / "report.html").exists() and not (out / "report.pdf").exists()
    assert "report.pdf" not in capsys.readouterr().out


def _error(args, capsys):
    code = main(args)
    err = capsys.readouterr().err
    return code, err


def test_error_missing_file(tmp_path, capsys):
    code, err = _error(["report", str(tmp_path / "nope.nc")], capsys)
    assert code == 2 and err.count("\n") == 1 and "no such file" in err


def test_error_not_netcdf(tmp_path, capsys):
    f = tmp_path / "notes.nc"
    f.write_text("this is not netCDF\n")
    code, err = _error(["report", str(f)], capsys)
    assert code == 2 and err.count("\n") == 1 and "not a netCDF file" in err


def test_error_netcdf_without_tolsim_attributes(tmp_path, capsys):
    import xarray as xr

    f = tmp_path / "other.nc"
    xr.Dataset({"x": ("t", np.arange(3.0))}, attrs={"title": "someone else's"}).to_netcdf(f)
    code, err = _error(["report", str(f), "-o", str(tmp_path / "out")], capsys)
    assert code == 2 and err.count("\n") == 1 and "not a tolsim study result" in err
    assert not (tmp_path / "out").exists()


def test_error_folder_and_bad_out(results, tmp_path, capsys):
    code, err = _error(["report", str(tmp_path)], capsys)
    assert code == 2 and "folder" in err
    nc, _ = next(iter(results.values()))
    f = tmp_path / "file"
    f.write_text("x")
    code, err = _error(["report", str(nc), "-o", str(f)], capsys)
    assert code == 2 and "not a folder" in err
    code, err = _error(["report", str(nc), "--sensitivity-samples", "1"], capsys)
    assert code == 2 and err.count("\n") == 1
