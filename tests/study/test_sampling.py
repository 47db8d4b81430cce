"""Reproducible block sampling (tolsim.study.sampling)."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from tolsim.io.config import parse_config
from tolsim.study.sampling import (
    RailField,
    block_generator,
    choose_spot_checks,
    error_values,
    per_assembly_sources,
    sample_block,
)

STUDY = """\
[bearing]
ball_diameter_mm = 10.0
conformity = 0.54
[motion]
groove_velocity_mm_per_s = 100.0
stroke_mm = 200.0
[train]
balls = 5
initial_gap = { distribution = "uniform", low_um = 0.0, high_um = 100.0 }
[loads]
normal_load_N = 200.0
[tolerances.bottom_rotation]
distribution = "normal"
std_deg = 0.2
correlation_length_mm = 30.0
[tolerances.top_rotation]
distribution = "cpk"
low_deg = -0.3
high_deg = 0.3
cpk = 1.0
[tolerances.ball_oversize]
distribution = "normal"
std_um = 0.1
[study]
samples = 1000
seed = 42
block_size = 256
sampling = "{sampling}"
propagation = "{propagation}"
spot_checks = 25
"""


def config(sampling="random", propagation="constant", **override):
    c = parse_config(STUDY.replace("{sampling}", sampling).replace("{propagation}",
                                                                     propagation))
    return c.with_overrides(**override) if override else c


def test_block_generator_is_the_spawned_child():
    # SeedSequence(seed, spawn_key=(0, k)) is child k of child 0 of the root: the same stream
    # as spawning explicitly.
    root = np.random.SeedSequence(42)
    child = root.spawn(1)[0].spawn(4)[3]
    ref = np.random.Generator(np.random.PCG64(child)).standard_normal(5)
    assert_array_equal(block_generator(42, 3).standard_normal(5), ref)


def test_block_is_reproducible_and_independent_of_sample_count():
    a = sample_block(config(), 1)
    b = sample_block(config(samples=300), 1)  # block 1 holds only 44 assemblies here
    assert b.size == 44 and a.size == 256
    for name in a.normals:
        assert_array_equal(a.normals[name][:44], b.normals[name])
    assert_array_equal(a.initial_gap[:44], b.initial_gap)
    assert "bottom_rotation" in a.normals  # the rail field at the ball centres


def test_blocks_differ():
    a, b = sample_block(config(), 0), sample_block(config(), 1)
    assert not np.array_equal(a.initial_gap, b.initial_gap)


def test_shapes_and_ranges():
    c = config()
    b = sample_block(c, 0)
    assert b.normals["top_rotation"].shape == (256, 1)
    assert b.normals["ball_oversize"].shape == (256, 5)
    assert b.initial_gap.shape == (256, 4)
    assert b.initial_gap.min() >= 0 and b.initial_gap.max() <= 100e-6
    # centres: pitch = diameter + gap, centroid at 0
    assert_allclose(np.diff(b.initial_position, axis=1), 0.01 + b.initial_gap, rtol=1e-12)
    assert_allclose(b.initial_position.mean(axis=1), 0, atol=1e-15)
    v = error_values(c, b)
    assert all(x.shape == (256, 5) for x in v.values())
    # per-carriage value is the same for every ball of a train
    assert np.all(v["top_rotation"] == v["top_rotation"][:, :1])


def big_block(propagation):
    text = config(propagation=propagation).text.replace("block_size = 256", "block_size = 4096")
    c = parse_config(text).with_overrides(samples=4096)
    return sample_block(c, 0)


def test_rail_field_grid_is_ornstein_uhlenbeck():
    # along_track: stationary AR(1) on the grid, unit variance, corr(s, s + ds) = exp(-ds/l).
    f = big_block("along_track").fields["bottom_rotation"]
    x = f.values
    assert x.shape[1] > 50
    assert_allclose(x.var(axis=0).mean(), 1.0, atol=0.03)  # 4096 trains
    lag = 8
    rho = np.mean([np.corrcoef(x[:, k], x[:, k + lag])[0, 1]
                   for k in range(0, x.shape[1] - lag, 10)])
    assert_allclose(rho, np.exp(-lag * f.spacing / 0.03), atol=0.03)


def test_rail_field_at_ball_centres_is_exact():
    # constant propagation: the OU process drawn at the ball centres; adjacent balls a random
    # pitch apart have corr = E[exp(-pitch / l)], every ball unit variance.
    b = big_block("constant")
    x = b.normals["bottom_rotation"]
    assert x.shape == (4096, 5) and not b.fields
    assert_allclose(x.var(axis=0), 1.0, atol=0.07)  # 4 standard errors of a variance
    expected = np.exp(-np.diff(b.initial_position, axis=1) / 0.03).mean(axis=0)
    measured = [np.mean(x[:, j] * x[:, j + 1]) for j in range(4)]
    assert_allclose(measured, expected, atol=0.06)  # ~3.5 standard errors


def test_rail_field_interpolation_at_grid_points():
    values = np.arange(12.0).reshape(2, 6)
    f = RailField(origin=-1.0, spacing=0.5, values=values)
    assert_allclose(f.at(np.array([[-1.0, 0.0], [0.25, 1.5]])), [[0.0, 2.0], [8.5, 11.0]])


@pytest.mark.parametrize("kind", ["sobol", "lhs"])
def test_qmc_designs(kind):
    c = config(sampling=kind)
    b = sample_block(c, 0)
    z = b.normals["top_rotation"][:, 0]
    assert np.all(np.isfinite(z))
    # Stratification: an LHS/Sobol design of 256 points puts exactly 128 below the median
    # (Sobol: each half of [0, 1) holds half of a 2^k-point scrambled net).
    assert np.count_nonzero(z < 0) == 128
    assert [t.source for t in per_assembly_sources(c)] == ["top_rotation"]
    assert_array_equal(sample_block(c, 0).normals["top_rotation"], b.normals["top_rotation"])


def test_spot_checks_are_seeded_and_unique():
    c = config()
    a, b = choose_spot_checks(c), choose_spot_checks(c)
    assert_array_equal(a, b)
    assert len(np.unique(a)) == 25 and a.max() < 1000 * 5
    assert not np.array_equal(a, choose_spot_checks(config(seed=43)))


@pytest.mark.parametrize("propagation", ["constant", "along_track"])
def test_blocks_drawn_together_equal_blocks_drawn_alone(propagation):
    # A chunk draws each block from its own generator and transforms the draws together:
    # bit-identical to drawing the blocks one by one (1000 samples: the last of the four
    # blocks of 256 is partial), for the draws, the rail fields, gaps, positions and the
    # error-source values.
    c = config(propagation=propagation)
    together = sample_block(c, 0, 4)
    alone = [sample_block(c, k) for k in range(4)]
    assert together.size == 1000 and together.start == 0
    for name in together.normals:
        assert_array_equal(together.normals[name],
                           np.concatenate([b.normals[name] for b in alone]), err_msg=name)
    for name in together.fields:
        assert_array_equal(together.fields[name].values,
                           np.concatenate([b.fields[name].values for b in alone]))
    assert_array_equal(together.initial_gap, np.concatenate([b.initial_gap for b in alone]))
    assert_array_equal(together.initial_position,
                       np.concatenate([b.initial_position for b in alone]))
    v = error_values(c, together)
    parts = [error_values(c, b) for b in alone]
    for name in v:
        assert_array_equal(v[name], np.concatenate([p[name] for p in parts]), err_msg=name)
