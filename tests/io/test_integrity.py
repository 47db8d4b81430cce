"""Nothing accepted silently, nothing signed unverified (issue 26, items 2, 5 and 6).

A result's data variables carry SHA-256 checksums that ``tolsim report``, ``tolsim compare``
and :func:`tolsim.io.netcdf.read_result` verify; a full disk, a damaged checkpoint, corrupted
attributes and an out-of-range seed give one line and exit code 2, and leave nothing
half-written; a resumed sweep writes the same file as an uninterrupted one.
"""

import builtins
import errno
import hashlib
import re
import shutil
import warnings
from pathlib import Path

import netCDF4
import numpy as np
import pytest
import xarray as xr
from test_config import MINIMAL

from tolsim.cli import main
from tolsim.io.config import parse_config
from tolsim.io.netcdf import read_result
from tolsim.io.sweep import parts_folder, run_sweep
from tolsim.study.execution.runner import StudyInterrupted

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
#: Attributes that stamp a run (its time), not its result.
STAMPS = ("history", "date_created", "elapsed_seconds", "full_model_resolve_seconds",
          "compile_seconds", "balls_per_second",
          "attributes_sha256")  # (the checksum of the global attributes, stamps included)


def _one_line_error(capsys, argv, *words):
    rc = main(argv)
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert "\n" not in err and "Traceback" not in err, err
    for word in words:
        assert word in err, err
    return err


@pytest.fixture(scope="module")
def result_file(tmp_path_factory):
    """A small written result and a copy, for comparisons."""
    folder = tmp_path_factory.mktemp("integrity")
    cfg = folder / "s.toml"
    cfg.write_text(MINIMAL)
    out = folder / "s.nc"
    assert main(["run", str(cfg), "-o", str(out), "--samples", "64", "--quiet"]) == 0
    return out


def _copy(path, tmp_path, name="c.nc") -> Path:
    target = tmp_path / name
    shutil.copy(path, target)
    return target


# ------------------------------------------------------------------------ A: checksums
def _digest(values) -> str:
    """SHA-256 of a variable's stored values, computed here independently of tolsim."""
    h = hashlib.sha256()
    if values.dtype.kind in "OU":
        for item in values.ravel():
            h.update(str(item).encode("utf-8") + b"\0")
    else:
        h.update(np.ascontiguousarray(values, dtype=values.dtype.newbyteorder("<")).tobytes())
    return h.hexdigest()


def test_every_variable_carries_a_checksum_verifiable_from_the_file(result_file):
    with netCDF4.Dataset(result_file) as nc:
        nc.set_auto_maskandscale(False)
        assert nc.getncattr("checksum_scheme").startswith("sha256-per-variable/2")
        assert len(nc.variables) > 50
        for name, var in nc.variables.items():
            assert var.getncattr("sha256") == _digest(np.asarray(var[...])), name
    read_result(result_file)  # verifies


def _corrupt_data(path, name):
    """Overwrite 16 bytes inside the stored data of variable ``name`` (found by its bytes)."""
    with netCDF4.Dataset(path) as nc:
        nc.set_auto_maskandscale(False)
        stored = np.ascontiguousarray(nc.variables[name][...]).tobytes()
    data = bytearray(Path(path).read_bytes())
    assert data.count(stored) == 1 and len(stored) >= 32
    at = data.find(stored) + 8
    data[at:at + 16] = bytes(range(0xA0, 0xB0))
    Path(path).write_bytes(bytes(data))


def test_corrupted_data_is_refused_by_report_compare_and_read_result(result_file, tmp_path,
                                                                     capsys):
    bad = _copy(result_file, tmp_path)
    _corrupt_data(bad, "velocity_deviation_quantile")
    with pytest.raises(ValueError, match="velocity_deviation_quantile"):
        read_result(bad)
    _one_line_error(capsys, ["report", str(bad), "-o", str(tmp_path / "r"), "--no-pdf",
                             "--no-sensitivity"], "velocity_deviation_quantile", "--no-verify")
    assert not (tmp_path / "r").exists()
    _one_line_error(capsys, ["compare", str(result_file), str(bad), "-o", str(tmp_path / "c")],
                    "velocity_deviation_quantile", str(bad))
    assert not (tmp_path / "c").exists()
    # forensics: --no-verify reads it anyway
    assert main(["report", str(bad), "-o", str(tmp_path / "r"), "--no-pdf", "--no-sensitivity",
                 "--quiet", "--no-verify"]) == 0
    assert main(["compare", str(result_file), str(bad), "-o", str(tmp_path / "c"), "--quiet",
                 "--no-verify"]) == 0


def test_an_altered_and_signed_again_file_is_refused_or_marked(result_file, tmp_path, capsys):
    # P(contact) moved outside its own interval and the file signed again (or its checksums
    # stripped): the report's figure raised "'yerr' must not contain negative values". Such
    # data, which tolsim never writes, are refused in one line; --no-verify (forensics)
    # draws the report, which says on its page, in the PDF and its sign-off that the
    # checksums were not verified.
    from tolsim.io.checksums import sign_file

    bad = _copy(result_file, tmp_path)
    with netCDF4.Dataset(bad, "a") as nc:
        nc.variables["contact_probability"][...] = 0.9
    sign_file(bad)
    _one_line_error(capsys, ["report", str(bad), "-o", str(tmp_path / "r"), "--no-pdf",
                             "--no-sensitivity"], "inconsistent data: contact_probability = 0.9 "
                                                  "lies outside its interval")
    assert not (tmp_path / "r").exists()
    # compare likewise (CLI audit, session 25: with --no-verify its forest plot raised
    # "'xerr' must not contain negative values")
    assert main(["compare", str(result_file), str(bad), "-o", str(tmp_path / "c")]) == 2
    assert "inconsistent data: contact_probability = 0.9" in capsys.readouterr().err
    assert main(["compare", str(result_file), str(bad), "-o", str(tmp_path / "c"), "--quiet",
                 "--no-verify"]) == 0
    assert main(["report", str(bad), "-o", str(tmp_path / "r"), "--no-sensitivity",
                 "--quiet", "--no-verify"]) == 0
    page = (tmp_path / "r" / "report.html").read_text()
    assert "<b>Checksums NOT verified</b>: the report was made with --no-verify" in page
    assert (tmp_path / "r" / "report.pdf").stat().st_size > 0
    # a verified file's report has no such warning
    assert main(["report", str(result_file), "-o", str(tmp_path / "ok"), "--no-pdf",
                 "--no-sensitivity", "--quiet"]) == 0
    assert "NOT verified" not in (tmp_path / "ok" / "report.html").read_text()


def test_pdf_pages_of_an_unverified_file_say_so():
    # the PDF: under the title, above the sign-off and in every page's footer
    import matplotlib.pyplot as plt

    from tolsim.reports.pdf import report_pages

    texts = []
    for fig in _unverified_pages(report_pages):
        texts.append(" ".join(t.get_text() for t in fig.texts))
        plt.close(fig)
    assert "CHECKSUMS NOT VERIFIED: forensics" in texts[0]
    assert "CHECKSUMS NOT VERIFIED: forensics" in texts[-1]
    assert all("checksums NOT verified" in t for t in texts)


def _unverified_pages(report_pages):
    from tolsim.reports.verdict import Verdict

    return report_pages(
        title="t", subtitle="s", verdict=Verdict("pass", ()), headline=["h"], facts=[],
        tolerances=[], assumptions=[], figures={}, captions={}, sections={},
        result_path=__file__, sign_off=(("author",), ("name",), ("accept",)),
        unverified="forensics")


def test_a_file_without_checksums_is_read_with_a_warning(result_file, tmp_path, capsys):
    old = _copy(result_file, tmp_path)
    with netCDF4.Dataset(old, "a") as nc:
        nc.delncattr("checksum_scheme")
        for var in nc.variables.values():
            var.delncattr("sha256")
    with pytest.warns(UserWarning, match="no checksums"):
        read_result(old)
    assert main(["report", str(old), "-o", str(tmp_path / "r"), "--no-pdf", "--no-sensitivity",
                 "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "no checksums" in err and len(err.strip().splitlines()) == 1


def _set_attribute(path, name, value):
    with netCDF4.Dataset(path, "a") as nc:
        if value is None:
            nc.delncattr(name)
        else:
            nc.setncattr(name, value)


@pytest.mark.parametrize("name, value, word", [
    ("title", 3.5, "title"),
    ("propagation_caveat", 2.0, "propagation_caveat"),
    ("full_model_resolve_seconds", "garbage \x01 [[", "full_model_resolve_seconds"),
    ("seed", None, "seed"),
    ("config", None, "config"),
])
def test_corrupted_attributes_are_one_line(result_file, tmp_path, capsys, name, value, word):
    # The global attributes' checksum refuses any change to them; without the verification
    # (--no-verify) the attribute's own check names it, as it does a missing attribute always
    bad = _copy(result_file, tmp_path)
    _set_attribute(bad, name, value)
    fails = word if value is None else ("the global attributes (the embedded config, seed and "
                                        "settings) fail their SHA-256")
    _one_line_error(capsys, ["report", str(bad), "-o", str(tmp_path / "r"), "--no-pdf",
                             "--no-sensitivity"], fails)
    _one_line_error(capsys, ["compare", str(result_file), str(bad), "-o",
                             str(tmp_path / "c")], fails)
    _one_line_error(capsys, ["report", str(bad), "-o", str(tmp_path / "r"), "--no-pdf",
                             "--no-sensitivity", "--no-verify"], word)


def test_an_edited_config_attribute_fails_the_checksum(result_file, tmp_path, capsys):
    # The embedded config (the text a report re-reads for its assumptions, Sobol' indices
    # and spot checks) was outside the checksums: an edited limit went unnoticed, and the
    # report showed the file's 70 % beside the edited text's 50. Signed since scheme /2, with
    # the recipe of tolsim.io.checksums' docstring, which needs no tolsim.
    import hashlib

    from tolsim.io.checksums import digest

    bad = _copy(result_file, tmp_path)
    with netCDF4.Dataset(bad, "a") as nc:
        nc.setncattr("config", nc.getncattr("config") + "\n# edited\n")
    _one_line_error(capsys, ["report", str(bad), "-o", str(tmp_path / "r"), "--no-pdf",
                             "--no-sensitivity"], "global attributes", "fail their SHA-256")
    with netCDF4.Dataset(result_file) as nc:  # the docstring's recipe on the good file
        h = hashlib.sha256()
        for name in sorted(set(nc.ncattrs()) - {"checksum_scheme", "attributes_sha256"}):
            h.update(name.encode("utf-8") + b"\0" + bytes.fromhex(digest(nc.getncattr(name))))
        assert h.hexdigest() == nc.getncattr("attributes_sha256")


def test_damaged_header_is_one_line(result_file, tmp_path, capsys):
    """Bytes overwritten anywhere in the file: refused in one line (no RuntimeError)."""
    data = Path(result_file).read_bytes()
    rng = np.random.default_rng(5)
    for k, at in enumerate(rng.integers(0, len(data) - 16, 6)):
        bad = tmp_path / f"b{k}.nc"
        changed = bytearray(data)
        changed[at:at + 16] = rng.integers(0, 256, 16, dtype=np.uint8).tobytes()
        bad.write_bytes(bytes(changed))
        rc = main(["compare", str(result_file), str(bad), "-o", str(tmp_path / f"c{k}"),
                   "--quiet"])
        err = capsys.readouterr().err.strip()
        assert rc in (0, 2) and "Traceback" not in err and "\n" not in err, (at, err)


def test_sweep_files_carry_checksums(tmp_path):
    text = MINIMAL + '\n[sweep]\n"loads.normal_load_N" = [150, 250]\n'
    c = parse_config(text.replace("samples = 100", "samples = 32"))
    out = tmp_path / "sw.nc"
    run_sweep(c, out)
    ds = read_result(out)
    assert ds.attrs["checksum_scheme"].startswith("sha256-per-variable/2")
    assert all(re.fullmatch("[0-9a-f]{64}", ds[n].attrs["sha256"]) for n in ds.variables)
    _corrupt_data(out, "velocity_deviation_quantile")
    with pytest.raises(ValueError, match="velocity_deviation_quantile"):
        read_result(out)


# ------------------------------------------------------------------- B: one line everywhere
def _full_disk(*_args, **_kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_full_disk_at_the_final_write(tmp_path, capsys, monkeypatch):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    out = tmp_path / "s.nc"

    def half_written(self, path, *args, **kwargs):
        Path(path).write_bytes(b"\x89HDF\r\n\x1a\n half")
        _full_disk()

    monkeypatch.setattr(xr.Dataset, "to_netcdf", half_written)
    _one_line_error(capsys, ["run", str(cfg), "-o", str(out), "--samples", "20", "--quiet"],
                    str(out), "No space left on device")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_full_disk_at_a_checkpoint(tmp_path, capsys, monkeypatch):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL.replace("samples = 100", "samples = 64\nblock_size = 16"))
    out = tmp_path / "s.nc"

    def half_written(fh, *args, **kwargs):
        fh.write(b"PK\x03\x04 half")
        _full_disk()

    monkeypatch.setattr(np, "savez", half_written)
    _one_line_error(capsys, ["run", str(cfg), "-o", str(out),
                             "--chunk-blocks", "1", "--checkpoint-interval", "0", "--quiet"],
                    f"{out}.partial", "No space left on device")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


@pytest.fixture
def checkpointed(tmp_path):
    """A config, its output and a checkpoint of a run stopped half-way (the one `tolsim run`
    of the config resumes)."""
    from tolsim.io.config import load_config
    from tolsim.study.execution.runner import run_study

    cfg = tmp_path / "s.toml"
    text = MINIMAL.replace("samples = 100", "samples = 64\nblock_size = 16")
    cfg.write_text(text)
    out = tmp_path / "s.nc"
    with pytest.raises(StudyInterrupted):
        run_study(load_config(cfg), checkpoint_path=f"{out}.partial", chunk_blocks=1,
                  checkpoint_interval=0, max_blocks=2)
    return cfg, out, Path(f"{out}.partial")


def test_a_report_of_a_checkpoint_says_what_it_is(checkpointed, tmp_path, capsys):
    # `tolsim report OUT.nc.partial` said "not a netCDF file"
    _, _, partial = checkpointed
    _one_line_error(capsys, ["report", str(partial), "-o", str(tmp_path / "r")],
                    "the checkpoint of an interrupted tolsim run", "run the same command again")


def test_truncated_checkpoint_names_fresh(checkpointed, capsys):
    cfg, out, partial = checkpointed
    partial.write_bytes(partial.read_bytes()[:200])
    for extra in ([], ["--resume"]):
        _one_line_error(capsys, ["run", str(cfg), "-o", str(out), "--quiet", *extra],
                        str(partial), "--fresh")
        assert not out.exists()
    assert main(["run", str(cfg), "-o", str(out), "--quiet", "--fresh"]) == 0
    assert out.exists() and not partial.exists()


@pytest.mark.parametrize("name, value, words", [
    ("acc_n_contact", 10**6, "n_contact > n_assemblies - n_unresolved"),
    ("acc_n_balls", 3, "n_balls != n_assemblies x balls"),
    ("acc_n_unresolved", -1, "n_unresolved < 0"),
])
def test_an_inconsistent_checkpoint_is_refused(checkpointed, capsys, name, value, words):
    # A checkpoint that reads but breaks the counts' identities (edited, or damaged inside
    # the zip's checksums) was resumed: the run ended in a traceback after its last block
    # (n_contact > n_assemblies). It is refused before any work, naming the identity and
    # --fresh, as a truncated one is.
    cfg, out, partial = checkpointed
    with np.load(partial) as data:
        arrays = {k: data[k] for k in data.files}
    arrays[name] = np.int64(value)
    with open(partial, "wb") as fh:
        np.savez(fh, **arrays)
    _one_line_error(capsys, ["run", str(cfg), "-o", str(out), "--quiet"], str(partial),
                    f"is inconsistent ({words})")
    assert not out.exists()


@pytest.mark.parametrize("seed", [str(2**64), str(2**70), "-1"])
def test_seed_out_of_range_refused_before_any_work(tmp_path, capsys, monkeypatch, seed):
    import tolsim.study.execution.runner as runner

    monkeypatch.setattr(runner, "run_study", lambda *a, **k: pytest.fail("work started"))
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    _one_line_error(capsys, ["run", str(cfg), "-o", str(tmp_path / "s.nc"), "--seed", seed],
                    "--seed", str(2**64 - 1))


def test_largest_seed_is_written_and_read(tmp_path):
    cfg = tmp_path / "s.toml"
    cfg.write_text(MINIMAL)
    out = tmp_path / "s.nc"
    assert main(["run", str(cfg), "-o", str(out), "--seed", str(2**64 - 1), "--samples", "8",
                 "--quiet"]) == 0
    assert int(read_result(out).attrs["seed"]) == 2**64 - 1


def test_report_on_a_full_disk_leaves_no_png(result_file, tmp_path, capsys, monkeypatch):
    real_open = builtins.open
    folder = tmp_path / "r"

    class Full:  # a file on a full disk: opens, but nothing can be written
        def __init__(self, fh):
            self.fh = fh

        def write(self, data):
            _full_disk()

        def close(self):
            self.fh.close()

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    def full_open(file, mode="r", *args, **kwargs):
        fh = real_open(file, mode, *args, **kwargs)
        if "w" in mode and str(file).startswith(str(folder)):
            return Full(fh)
        return fh

    monkeypatch.setattr(builtins, "open", full_open)
    _one_line_error(capsys, ["report", str(result_file), "-o", str(folder), "--no-pdf",
                             "--no-sensitivity", "--quiet"], "No space left on device")
    assert not folder.exists() or not any(folder.iterdir())


# ------------------------------------------------------------------ C: sweeps resume alike
def test_resumed_sweep_equals_an_uninterrupted_one_attributes_included(tmp_path):
    text = MINIMAL.replace("samples = 100", "samples = 64\nblock_size = 16")
    c = parse_config(text + '\n[sweep]\n"loads.normal_load_N" = [150, 250]\n')
    run_sweep(c, tmp_path / "whole.nc")
    out = tmp_path / "cut.nc"
    for _ in range(2):  # point 1 ends in the second call, point 2 stops half-way
        with pytest.raises(StudyInterrupted):
            run_sweep(c, out, max_blocks=3, checkpoint_interval=0, chunk_blocks=1)
    assert (parts_folder(out) / "point-0000.nc").exists()
    run_sweep(c, out)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        whole, cut = read_result(tmp_path / "whole.nc"), read_result(out)
    for key in ("seed", "samples", "block_size", "workers"):
        assert cut.attrs[key] == whole.attrs[key] and "point" not in str(cut.attrs[key]), key
    assert {k: str(v) for k, v in cut.attrs.items() if k not in STAMPS} == {
        k: str(v) for k, v in whole.attrs.items() if k not in STAMPS}
    assert sorted(cut.variables) == sorted(whole.variables)
    for name in whole.variables:
        np.testing.assert_array_equal(cut[name].values, whole[name].values, err_msg=name)
        assert {k: str(v) for k, v in cut[name].attrs.items()} == {
            k: str(v) for k, v in whole[name].attrs.items()}, name


def test_a_damaged_sweep_part_is_said_and_run_again(tmp_path):
    # A damaged finished point (OUT.sweep/point-K.nc) was run again without a word; the
    # result was right, but the user did not learn why the resume took longer.
    text = MINIMAL.replace("samples = 100", "samples = 64\nblock_size = 16")
    c = parse_config(text + '\n[sweep]\n"loads.normal_load_N" = [150, 250]\n')
    out = tmp_path / "cut.nc"
    for _ in range(2):  # point 1 ends in the second call, point 2 stops half-way
        with pytest.raises(StudyInterrupted):
            run_sweep(c, out, max_blocks=3, checkpoint_interval=0, chunk_blocks=1)
    part = parts_folder(out) / "point-0000.nc"
    part.write_bytes(part.read_bytes()[:300])
    said = []
    run_sweep(c, out, notify=said.append)
    assert any(s.startswith(f"point 1 of 2: {part} is damaged (") and
               s.endswith("running the point again") for s in said), said
    run_sweep(c, tmp_path / "whole.nc")
    whole, again = read_result(tmp_path / "whole.nc"), read_result(out)
    np.testing.assert_array_equal(again.contact_probability.values,
                                  whole.contact_probability.values)


def test_resumed_sweep_counts_only_the_work_done_after_resuming(tmp_path):
    # issue 26, item 8 for sweeps: the summary's balls/s was all points' balls over the time
    # of the points run now, overstated after a resume. Point 1 (64 assemblies x 6 balls)
    # finishes in the first call; the resumed call runs point 2 only, from its checkpoint
    # (block 3 of 4 on, 16 assemblies per block): 1 block of 16 assemblies, 96 balls.
    text = MINIMAL.replace("samples = 100", "samples = 64\nblock_size = 16")
    c = parse_config(text + '\n[sweep]\n"loads.normal_load_N" = [150, 250]\n')
    out = tmp_path / "cut.nc"
    for _ in range(2):
        with pytest.raises(StudyInterrupted):
            run_sweep(c, out, max_blocks=3, checkpoint_interval=0, chunk_blocks=1)
    _, work = run_sweep(c, out)
    assert work.balls_run == 16 * c.balls
    assert work.balls_per_second == pytest.approx(
        work.balls_run / (work.elapsed - work.compile_seconds), rel=1e-12)
