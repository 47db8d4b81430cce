"""Per-assembly export, ``tolsim run --save-samples N`` (issue 17)."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.cli import main
from tolsim.io.config import load_config, parse_config, with_study_settings
from tolsim.io.netcdf import read_result, write_result
from tolsim.physics.velocity.models import BALL_THREE_POINT, BALL_TWO_POINT
from tolsim.study.execution.runner import StudyInterrupted, run_study
from tolsim.study.pipeline.block import evaluate_block
from tolsim.study.pipeline.evaluate import evaluate_balls, loads_per_ball
from tolsim.study.pipeline.propagation import first_contact_constant
from tolsim.study.sampling import error_values, sample_block

ROOT = Path(__file__).resolve().parents[2]
#: Three blocks of 1024 assemblies; the saved ones span blocks 0 and 1.
SAMPLES, SAVED = 3000, 1500


def small_default(samples=SAMPLES):
    config = load_config()
    return with_study_settings(config, samples=samples, spot_checks=0,
                               sensitivity_samples=0)


@pytest.fixture(scope="module")
def config():
    return small_default()


@pytest.fixture(scope="module")
def saved(config):
    return run_study(config, save_samples=SAVED, chunk_blocks=1).samples


def test_saved_assemblies_equal_an_independent_evaluation(config, saved):
    # The first N assemblies drawn and evaluated on their own (sampling.sample_block,
    # error_values, evaluate.evaluate_balls) give exactly the saved rows.
    assert_array_equal(saved["sample_index"], np.arange(SAVED))
    block = sample_block(config, 0, 2)
    values = error_values(config, block)
    nx, ny = loads_per_ball(config, (block.size, config.train.balls))
    state = evaluate_balls(config, values, nx, ny)
    assert_array_equal(saved["sample_velocity_deviation"], state.velocity_deviation[:SAVED])
    assert_array_equal(saved["sample_model"], state.model[:SAVED])
    assert_array_equal(saved["sample_regime"], state.regime[:SAVED])
    assert_array_equal(saved["sample_contact_angle_deviation"],
                       state.contact_angle_deviation[:SAVED])
    assert_array_equal(saved["sample_normal_force"], state.normal_force[:SAVED])
    assert_array_equal(saved["sample_initial_gap"], block.initial_gap[:SAVED])
    for t in config.tolerances:
        assert_array_equal(saved[f"sample_error_{t.source}"],
                           np.broadcast_to(values[t.source], state.model.shape)[:SAVED])
    t, pair = first_contact_constant(block.initial_gap, state.velocity_deviation,
                                     config.motion.groove_velocity, config.motion.duration)
    assert_array_equal(saved["sample_contact_time"], t[:SAVED])
    assert_array_equal(saved["sample_contact_pair"], pair[:SAVED])


def test_saved_assemblies_do_not_depend_on_chunking_or_workers(config, saved):
    # bit-identical whatever the chunking (one chunk of all blocks here against one block per
    # chunk in the fixture) and the number of worker processes
    for kwargs in ({"chunk_blocks": 3}, {"chunk_blocks": 2, "workers": 2}):
        other = run_study(config, save_samples=SAVED, **kwargs).samples
        assert other.keys() == saved.keys()
        for name, values in saved.items():
            assert_array_equal(other[name], values, err_msg=name)


def test_saved_contact_times_agree_with_the_counts_and_the_gaps(config):
    # All assemblies saved: the contacts among them are the study's counts, per pair too,
    # and each contact time is the closed form t = gap / ((eps_j - eps_j+1) v / 2) of the
    # first pair to close ([Lin2018] Sec. 3.2, constant epsilon).
    result = run_study(config, save_samples=SAMPLES + 10)  # more than the study has
    rows = result.samples
    acc = result.statistics
    t, pair = rows["sample_contact_time"], rows["sample_contact_pair"]
    assert len(t) == SAMPLES
    hit = np.isfinite(t)
    assert acc.n_contact == np.count_nonzero(hit) > 0
    assert_array_equal(np.bincount(pair[hit], minlength=config.train.balls - 1),
                       acc.pair_count[: config.train.balls - 1])
    assert np.all(pair[~hit] == -1)
    assert np.all(t[hit] <= config.motion.duration)
    eps, gap = rows["sample_velocity_deviation"], rows["sample_initial_gap"]
    closing = (eps[:, :-1] - eps[:, 1:]) * 0.5 * config.motion.groove_velocity
    with np.errstate(divide="ignore", invalid="ignore"):
        times = np.where(closing > 0, gap / closing, np.inf)
    first = np.nanmin(times, axis=1)
    np.testing.assert_allclose(t[hit], first[hit], rtol=1e-12)
    assert_array_equal(pair[hit], np.nanargmin(times[hit], axis=1))
    assert np.all(first[~hit] > config.motion.duration)


def test_resumed_run_saves_the_same_assemblies(config, saved, tmp_path):
    # A run interrupted after one block and resumed from its checkpoint (which keeps only
    # the spot-check rows) saves the same rows as an uninterrupted one.
    checkpoint = str(tmp_path / "run.partial")
    with pytest.raises(StudyInterrupted):
        run_study(config, chunk_blocks=1, checkpoint_path=checkpoint, checkpoint_interval=0,
                  max_blocks=1)
    resumed = run_study(config, chunk_blocks=1, checkpoint_path=checkpoint,
                        save_samples=SAVED)
    assert resumed.resumed_blocks == 1
    for name, values in saved.items():
        assert_array_equal(resumed.samples[name], values, err_msg=name)


def test_result_file_round_trip(config, saved, tmp_path):
    result = run_study(config, save_samples=SAVED)
    ds = write_result(result, tmp_path / "r.nc", history="test")
    back = read_result(tmp_path / "r.nc")
    assert back.sizes["sample"] == SAVED
    assert_array_equal(back["sample"].values, np.arange(SAVED))
    assert back["sample_velocity_deviation"].dims == ("sample", "ball")
    assert back["sample_contact_angle_deviation"].dims == ("sample", "ball", "contact")
    assert back["sample_error_bottom_rotation"].attrs["units"] == "rad"
    assert back["sample_error_ball_oversize"].attrs["units"] == "m"
    assert_array_equal(back["sample_velocity_deviation"].values,
                       saved["sample_velocity_deviation"])
    # no contact within the horizon is a missing time in the file
    t = saved["sample_contact_time"]
    assert_array_equal(np.isnan(back["sample_contact_time"].values), ~np.isfinite(t))
    assert_array_equal(back["sample_contact_time"].values[np.isfinite(t)], t[np.isfinite(t)])
    assert back["sample_model"].attrs["flag_meanings"] == "unresolved fast_model full_model"
    assert back["sample_regime"].dims == ("sample", "ball")
    assert back["sample_regime"].attrs["flag_meanings"].split()[:3] == [
        "unresolved", "four_point_regime_A", "four_point_regime_B"]
    assert_array_equal(back["sample_regime"].values, saved["sample_regime"])
    # without the flag the file has no sample dimension
    assert "sample" not in write_result(run_study(small_default(64)), tmp_path / "s.nc",
                                        history="test").dims
    assert ds.sizes["sample"] == SAVED


def test_along_track_run_saves_samples():
    # along-track propagation: the state at the start of the stroke, the contact over it
    config = load_config(ROOT / "configs" / "whatif_along_track.toml")
    config = with_study_settings(config, samples=6, spot_checks=0,
                                 sensitivity_samples=0)
    result = run_study(config, save_samples=4)
    rows = result.samples
    assert_array_equal(rows["sample_index"], np.arange(4))
    assert rows["sample_velocity_deviation"].shape == (4, config.train.balls)
    block = sample_block(config, 0)
    assert_array_equal(rows["sample_initial_gap"], block.initial_gap[:4])


@pytest.mark.parametrize("oversize_um, regimes", [(-5.0, {BALL_TWO_POINT}),
                                                  (0.0, {BALL_TWO_POINT, BALL_THREE_POINT})])
def test_saved_samples_record_each_balls_regime(oversize_um, regimes):
    # issue 25: the saved rows hold each ball's regime, that of the study's own evaluation of
    # the same assemblies (evaluate_block without propagation). configs/carriage_preload.toml
    # with clearance (-5 um: every ball two-point, `tolsim carriage` on the nominal carriage)
    # and without preload (two- and three-point balls side by side, issue 25's 0 to 16 of 24
    # three- or four-point balls per assembly).
    text = (ROOT / "configs" / "carriage_preload.toml").read_text().replace(
        "preload_oversize_um = 2.0", f"preload_oversize_um = {oversize_um}")
    config = parse_config(text, "carriage_preload.toml")
    config = with_study_settings(config, samples=6, block_size=6,
                                 spot_checks=0, sensitivity_samples=0)
    rows = run_study(config, save_samples=5).samples
    state = evaluate_block(config, sample_block(config, 0), propagate=False).state
    assert rows["sample_regime"].shape == (5, config.balls)
    assert_array_equal(rows["sample_regime"], state.regime[:5])
    assert regimes <= set(np.unique(rows["sample_regime"]).tolist())


def test_cli_save_samples(tmp_path, capsys):
    out = tmp_path / "case.nc"
    assert main(["run", str(ROOT / "configs" / "paper_case_study.toml"), "-o", str(out),
                 "--save-samples", "5", "--quiet"]) == 0
    ds = read_result(out)
    assert ds.sizes["sample"] == 5
    assert "--save-samples 5" in ds.attrs["history"]
    assert main(["run", "--save-samples", "-1", "-o", str(out)]) == 2
    assert "--save-samples" in capsys.readouterr().err
