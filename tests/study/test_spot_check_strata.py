"""Spot checks stratified towards the spec limit (issue 17, item 6): half drawn uniformly,
half among the balls of the fast model with |epsilon| in a band around the limit, chosen by
seeded priorities so that the choice does not depend on the chunking or on resuming."""


import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.io.config import parse_config, with_study_settings
from tolsim.physics.velocity.models import MODEL_FAST
from tolsim.study import sampling
from tolsim.study.execution.runner import StudyInterrupted, run_study
from tolsim.study.pipeline.evaluate import evaluate_balls, loads_per_ball

STUDY = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
[motion]
groove_velocity_mm_per_s = 200.0
stroke_mm = 100.0
[train]
balls = 6
initial_gap = { distribution = "uniform", low_um = 0.0, high_um = 100.0 }
[loads]
normal_load_N = 200.0
yaw_moment_N_m = 6.0
[tolerances.top_rotation]
distribution = "normal"
std_deg = 0.3
[tolerances.arc_centre_offset_tangential_TL]
distribution = "normal"
std_um = 1.0
[study]
samples = 1500
seed = 5
block_size = 128
velocity_model = "analytic"
static_model = "paired"
spot_checks = 12
"""
#: Spec limit on |epsilon| [-]: the band 0.8 L .. 1.2 L holds a few per cent of the balls.
LIMIT = 0.002


def make(limit=LIMIT, **study):
    config = parse_config(STUDY)
    return with_study_settings(config, velocity_deviation_limit=limit,
                               **study)


def test_priority_is_splitmix64():
    # From the reference SplitMix64 (Steele, Lea & Flood 2014; Vigna's splitmix64.c) seeded
    # with 0: its first two outputs are 0xE220A8397B1DCDAF and 0x6E789E6AA1B965F4; the
    # priority of ball i under key 0 is output i + 1.
    p = sampling.spot_check_priority(0, np.array([0, 1]))
    assert p.dtype == np.uint64
    assert [int(x) for x in p] == [0xE220A8397B1DCDAF, 0x6E789E6AA1B965F4]


def test_priority_depends_only_on_key_and_index():
    idx = np.arange(100_000, dtype=np.int64)
    p = sampling.spot_check_priority(12345, idx)
    assert_array_equal(p[1000:1010], sampling.spot_check_priority(12345, idx[1000:1010]))
    assert len(np.unique(p)) == idx.size
    assert not np.array_equal(p, sampling.spot_check_priority(12346, idx))
    # roughly uniform over uint64: each quarter holds about a quarter of them
    quarters = np.bincount((p >> np.uint64(62)).astype(int), minlength=4)
    assert np.all(np.abs(quarters - idx.size / 4) < 5 * np.sqrt(idx.size / 4))


def test_plan_without_a_limit_is_the_uniform_draw():
    config = make(limit=0.0)
    plan = sampling.spot_check_plan(config)
    assert plan.near_limit == 0 and np.all(np.isnan(plan.band))
    assert_array_equal(plan.uniform, sampling.choose_spot_checks(config))
    with_limit = sampling.spot_check_plan(make())
    assert with_limit.near_limit == 6
    assert with_limit.band == pytest.approx((0.8 * LIMIT, 1.2 * LIMIT))


def _spots(result):
    sc = result.spot_checks
    return sc.ball_index, sc.stratum, sc.band_balls


def test_strata_do_not_depend_on_chunking_or_resuming(tmp_path):
    config = make()
    ref = run_study(config)
    idx, stratum, band_balls = _spots(ref)
    assert len(idx) == 12 and np.all(np.diff(idx) > 0)
    assert np.count_nonzero(stratum == 1) == 6 and np.count_nonzero(stratum == 0) == 6
    assert band_balls > 6
    # the near-limit balls are in the band, by the study's own epsilon
    sc = ref.spot_checks
    near = stratum == 1
    assert np.all(sc.valid_analytic[near])
    eps = np.abs(sc.velocity_deviation_analytic[near])
    assert np.all((eps >= 0.8 * LIMIT) & (eps <= 1.2 * LIMIT))
    # one block per chunk, and an interrupted run resumed from its checkpoint
    for other in (run_study(config, chunk_blocks=1), run_study(config, chunk_blocks=5)):
        for a, b in zip(_spots(ref), _spots(other), strict=True):
            assert_array_equal(a, b)
    ckpt = tmp_path / "run.partial"
    with pytest.raises(StudyInterrupted):
        run_study(config, chunk_blocks=2, checkpoint_path=str(ckpt), checkpoint_interval=0,
                  max_blocks=4)
    resumed = run_study(config, chunk_blocks=3, checkpoint_path=str(ckpt))
    assert resumed.resumed_blocks == 4
    for a, b in zip(_spots(ref), _spots(resumed), strict=True):
        assert_array_equal(a, b)
    assert_array_equal(ref.spot_checks.velocity_deviation_full,
                       resumed.spot_checks.velocity_deviation_full)


def test_near_limit_checks_are_the_smallest_priorities_in_the_band():
    # Brute force over every ball of the study: the near-limit stratum is the k balls of the
    # fast model in the band, outside the uniform candidates, with the smallest priorities.
    config = make()
    block = sampling.sample_block(config, 0, sampling.n_blocks(1500, 128))
    values = sampling.error_values(config, block)
    nx, ny = loads_per_ball(config, block.initial_gap.shape[:1] + (config.train.balls,))
    state = evaluate_balls(config, values, nx, ny)
    eps = state.velocity_deviation.reshape(-1)
    fast = state.model.reshape(-1) == MODEL_FAST
    plan = sampling.spot_check_plan(config)
    with np.errstate(invalid="ignore"):
        in_band = fast & (np.abs(eps) >= plan.band[0]) & (np.abs(eps) <= plan.band[1])
    candidates = np.setdiff1d(np.flatnonzero(in_band), plan.uniform)
    priority = sampling.spot_check_priority(plan.key, candidates)
    expected = np.sort(candidates[np.argsort(priority, kind="stable")[: plan.near_limit]])
    result = run_study(config)
    sc = result.spot_checks
    assert_array_equal(sc.ball_index[sc.stratum == 1], expected)
    assert sc.band_balls == in_band.sum()
    # the uniform stratum is the uniform candidates with the smallest priorities
    u_priority = sampling.spot_check_priority(plan.key, plan.uniform)
    kept = np.sort(plan.uniform[np.argsort(u_priority, kind="stable")[: 12 - len(expected)]])
    assert_array_equal(sc.ball_index[sc.stratum == 0], kept)


def test_uniform_fills_up_when_the_band_is_empty():
    # A limit far beyond every epsilon: no ball in the band, all 12 checks uniform, the same
    # balls as a study without a limit.
    far = run_study(make(limit=0.5))
    none = run_study(make(limit=0.0))
    assert far.spot_checks.band_balls == 0
    assert np.all(far.spot_checks.stratum == 0)
    assert_array_equal(far.spot_checks.ball_index, none.spot_checks.ball_index)
    assert_array_equal(none.spot_checks.ball_index,
                       sampling.choose_spot_checks(make(limit=0.0)))


def test_result_file_records_the_strata(tmp_path):
    from tolsim.io import netcdf

    ds = netcdf.write_result(run_study(make()), tmp_path / "r.nc", history="test")
    import xarray as xr

    with xr.open_dataset(tmp_path / "r.nc") as back:
        stratum = back["spot_check_stratum"]
        assert stratum.attrs["flag_meanings"] == "uniform near_limit"
        assert_array_equal(stratum.attrs["flag_values"], [0, 1])
        assert_array_equal(stratum.values, ds["spot_check_stratum"].values)
        assert np.count_nonzero(stratum.values == 1) == 6
        assert float(back.spot_check_band_lower) == pytest.approx(0.8 * LIMIT)
        assert float(back.spot_check_band_upper) == pytest.approx(1.2 * LIMIT)
        assert int(back.spot_check_band_balls) > 6
        assert "near the spec limit" in back.attrs["spot_check_status"]


def test_pruned_prefix_gives_the_same_choice():
    # select_spot_checks over all rows, against rows pruned after every prefix of blocks by
    # near_limit_cut / near_limit_kept (the runner's pruning): the same balls.
    rng = np.random.default_rng(3)
    plan = sampling.SpotCheckPlan(np.array([5, 70, 400]), 9, 4, (0.1, 0.2), 12345)
    free = [np.setdiff1d(np.arange(100 * b, 100 * b + 100), plan.uniform) for b in range(30)]
    blocks = [np.sort(rng.choice(f, rng.integers(0, 8), replace=False)) for f in free]
    strata = [np.ones(len(b), np.int8) for b in blocks]
    for index in plan.uniform:  # the uniform candidates, in their blocks
        k = index // 100
        blocks[k], strata[k] = np.append(blocks[k], index), np.append(strata[k], 0)
    full = np.concatenate(blocks)
    chosen = full[sampling.select_spot_checks(plan, full, np.concatenate(strata))]
    kept_b, kept_s = [], []
    for b, s in zip(blocks, strata, strict=True):
        kept_b.append(b), kept_s.append(s)
        cut = sampling.near_limit_cut(plan, np.concatenate(kept_b), np.concatenate(kept_s))
        masks = [sampling.near_limit_kept(plan, x, y, cut) for x, y in zip(kept_b, kept_s,
                                                                          strict=True)]
        kept_b = [x[m] for x, m in zip(kept_b, masks, strict=True)]
        kept_s = [y[m] for y, m in zip(kept_s, masks, strict=True)]
        assert np.count_nonzero(np.concatenate(kept_s) == 1) <= plan.near_limit
    rows_b, rows_s = np.concatenate(kept_b), np.concatenate(kept_s)
    assert_array_equal(rows_b[sampling.select_spot_checks(plan, rows_b, rows_s)], chosen)
    assert np.count_nonzero(rows_s == 0) == 3  # the uniform rows are all kept


def test_checkpoint_keeps_only_the_near_limit_rows_that_can_be_chosen(tmp_path):
    # Each of the 12 blocks records up to 6 near-limit candidates; the committed state (and
    # so its checkpoint) keeps the 6 that can still be chosen, not all of them.
    config = make()
    plan = sampling.spot_check_plan(config)
    ckpt = tmp_path / "run.partial"
    with pytest.raises(StudyInterrupted):
        run_study(config, chunk_blocks=1, checkpoint_path=str(ckpt), checkpoint_interval=0,
                  max_blocks=11)
    with np.load(ckpt) as saved:
        near = int(np.count_nonzero(saved["spot_stratum"] == 1))
        assert near == plan.near_limit
    resumed = run_study(config, checkpoint_path=str(ckpt))
    assert_array_equal(resumed.spot_checks.ball_index, run_study(config).spot_checks.ball_index)
