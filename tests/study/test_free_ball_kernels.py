"""The compiled passes of the free-ball frame (issue 24, "Speed") against the NumPy chains
they replace, bit for bit: the loads along the carriage (``np.interp``), the ``paired`` model
with its contact counts (:func:`tolsim.study.pipeline.evaluate.paired_balls`), the motion,
the gaps and the first contact of a step."""

from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from tolsim.io.config import load_config
from tolsim.physics.geometry import K_F_PAPER, TABLE1
from tolsim.physics.hertz import hertz_constants
from tolsim.physics.velocity.analytic import (
    ANALYTIC_TILE,
    MAX_ANGLE_SUM,
    MAX_VELOCITY_DEVIATION,
    MAX_ZERO_VELOCITY_RATIO,
    analytic_kernel,
)
from tolsim.study.pipeline.ball_kernels import (
    contact_counts_kernel,
    loads_at_kernel,
    paired_analytic_kernel,
    paired_balls_kernel,
)
from tolsim.study.pipeline.evaluate import (
    PAIRED_SOURCES,
    StaticResult,
    ball_velocities,
    evaluate_balls,
    evaluate_balls_at,
    groove_error_fields,
    round_off_force,
)
from tolsim.study.pipeline.frame_kernels import first_contact_kernel
from tolsim.study.pipeline.propagation import free_motion, gaps
from tolsim.study.sampling import error_values, sample_block

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def _bits(x):
    x = np.ascontiguousarray(x)
    return x.view(np.uint64) if x.dtype == np.float64 else x


def _positions(rng, slots, n=3000):
    """Carriage positions with every case of ``np.interp``: inside, at the slots, beyond both
    end slots, at +-inf and NaN, -0.0."""
    lo, hi = slots[0], slots[-1]
    span = max(hi - lo, 1e-3)
    x = rng.uniform(lo - 0.3 * span, hi + 0.3 * span, n)
    x[:len(slots)] = slots
    x[len(slots):len(slots) + 5] = [np.nan, np.inf, -np.inf, -0.0, 0.0]
    x[rng.integers(0, n, 50)] = np.nan
    return x


def _paired_numpy(errors, side_load, normal_load, bearing):
    """The NumPy chain of ``paired_static`` before the kernels: rigid angles, paired forces."""
    dbeta = errors["arc_centre_offset_tangential"] / (bearing.groove_radius - bearing.ball_radius)
    dbeta[:, 0] -= errors["bottom_rotation"]
    dbeta[:, 1] += errors["bottom_rotation"]
    dbeta[:, 2] -= errors["top_rotation"]
    dbeta[:, 3] += errors["top_rotation"]
    b0 = bearing.nominal_contact_angle
    s0, c0 = np.sin(b0), np.cos(b0)
    f1 = (normal_load / c0 - side_load / s0) / 2.0
    f2 = (normal_load / c0 + side_load / s0) / 2.0
    return dbeta, np.stack([f1, f2, f1, f2], axis=-1)


@pytest.mark.parametrize("slots", [
    np.array([-0.03, 0.03]),
    np.linspace(-0.0275, 0.0275, 6),
    np.cumsum(np.random.default_rng(5).uniform(1e-3, 2e-2, 41)) - 0.2,  # uneven, 41 slots
])
def test_loads_at_kernel_is_numpy_interp(slots):
    # source: np.interp(x, slots, loads), the two calls of loads_at before the kernel;
    # tolerance: the bits (NaN, the end values, the values at the slots, an infinite load)
    rng = np.random.default_rng(len(slots))
    x = _positions(rng, slots)
    side = rng.uniform(-300.0, 300.0, len(slots))
    normal = rng.uniform(0.0, 300.0, len(slots))
    if len(slots) > 3:  # "if we get nan in one direction, try the other" (NumPy's fallback)
        normal[1:3] = np.inf
    out = np.empty(len(x)), np.empty(len(x))
    loads_at_kernel(x, slots, side, normal, *out)
    assert_array_equal(_bits(out[0]), _bits(np.interp(x, slots, side)))
    assert_array_equal(_bits(out[1]), _bits(np.interp(x, slots, normal)))


def test_loads_at_kernel_single_slot_is_its_loads():
    # source: loads_at with one slot (np.full of its loads, NaN positions included);
    # tolerance: exact
    x = _positions(np.random.default_rng(3), np.array([0.0]))
    out = np.empty(len(x)), np.empty(len(x))
    loads_at_kernel(x, np.array([0.0]), np.array([-12.5]), np.array([150.0]), *out)
    assert_array_equal(out[0], np.full(len(x), -12.5))
    assert_array_equal(out[1], np.full(len(x), 150.0))


def _values(rng, n, absent=()):
    """Source values of n balls: the paired model's sources (some absent) and one it ignores."""
    values = {name: rng.normal(0.0, 2e-6, n) for name in PAIRED_SOURCES[:4]}
    values["bottom_rotation"] = rng.normal(0.0, 3e-3, n)
    values["top_rotation"] = rng.normal(0.0, 3e-3, n)
    values["arc_centre_offset_normal_BL"] = rng.normal(0.0, 1e-6, n)  # ignored by ``paired``
    values["bottom_rotation"][:3] = [np.nan, -0.0, np.inf]
    for name in absent:
        values.pop(name)
    return values


@pytest.mark.parametrize("absent", [(), ("top_rotation", "arc_centre_offset_tangential_TR"),
                                    PAIRED_SOURCES])
@pytest.mark.parametrize("slots", [np.array([0.0]), np.linspace(-0.0275, 0.0275, 6)])
def test_paired_balls_kernel_is_the_numpy_chain(absent, slots):
    # source: loads_at (np.interp), groove_error_fields, the NumPy paired_static (rigid
    # angles, paired forces) and contact_counts_kernel, the chain of evaluate_balls before the
    # one-pass kernel; tolerance: the bits. Forces: positive, zero, negative (N_x > N_y),
    # round-off (settled), NaN (a NaN position); loads beyond the end slots; a single slot.
    rng = np.random.default_rng(21)
    n = 4000
    x = _positions(rng, slots, n)
    side = rng.uniform(-250.0, 250.0, len(slots))
    normal = rng.uniform(-20.0, 300.0, len(slots))
    if len(slots) > 1:
        side[2], normal[2] = 0.0, 0.0  # zero forces at a slot
        side[3], normal[3] = 1e-9, 2e-9  # round-off forces: settled
    values = _values(rng, n, absent)
    if len(slots) == 1:
        nx, ny = np.full(n, side[0]), np.full(n, normal[0])
    else:
        nx, ny = np.interp(x, slots, side), np.interp(x, slots, normal)
    errors = groove_error_fields(values, (n,))
    want_dbeta, want_force = _paired_numpy(errors, nx, ny, TABLE1)
    want = StaticResult(want_dbeta, want_force, np.ones(n, dtype=bool))
    want_count, want_clipped = np.empty(n, np.int8), np.empty((n, 4))
    limit = round_off_force(TABLE1)
    want_settled = contact_counts_kernel(want_force, limit, want_count, want_clipped)

    def per_ball(name):  # absent: (1,) zero; a value the same for all balls: (1,)
        if name not in values:
            return np.zeros(1)
        v = values[name]
        return v[:1].copy() if np.all(v == v[0]) else np.ascontiguousarray(v)

    if not absent:  # one value for every ball
        values["top_rotation"] = np.full(n, 1.5e-3)
        errors = groove_error_fields(values, (n,))
        want_dbeta, want_force = _paired_numpy(errors, nx, ny, TABLE1)
        want = StaticResult(want_dbeta, want_force, np.ones(n, dtype=bool))

    for along in (True, False):
        dbeta, force, clipped = np.empty((n, 4)), np.empty((n, 4)), np.empty((n, 4))
        four_point, count = np.empty(n, bool), np.empty(n, np.int8)
        b0 = TABLE1.nominal_contact_angle
        settled = paired_balls_kernel(
            *(per_ball(name) for name in PAIRED_SOURCES),
            TABLE1.groove_radius - TABLE1.ball_radius, nx, ny, x if along else np.empty(0),
            slots, side, normal, np.sin(b0), np.cos(b0), limit, dbeta, force, four_point,
            count, clipped)
        assert_array_equal(_bits(dbeta), _bits(want.contact_angle_deviation))
        assert_array_equal(_bits(force), _bits(want.normal_force))
        assert_array_equal(four_point, want.four_point)
        assert_array_equal(count, want_count)
        assert_array_equal(_bits(clipped), _bits(want_clipped))
        assert settled == want_settled
    if len(slots) > 1:  # every case is exercised
        assert want_settled > 0 and (want_count == -1).any() and (want_count == 0).any()
        assert np.isnan(want_force).any() and want.four_point.any()


@pytest.mark.parametrize("along", [True, False])
def test_paired_analytic_kernel_is_the_paired_pass_then_the_analytic_solve(along):
    # source: paired_balls_kernel, then analytic_kernel on its clipped forces through the
    # per-ball solve (Eq. (22) asked for: _analytic_solve, libm-fallback sin/cos, the array
    # cube root), the chain of ball_velocities before the fused kernel; tolerance: the bits of
    # every output. Balls settled, in tension, unloaded, with a NaN position or a NaN or
    # large rotation (libm sin/cos), one value for all balls (top_rotation); n not a multiple
    # of the tile.
    rng = np.random.default_rng(33)
    n = 5 * ANALYTIC_TILE + 41
    slots = np.linspace(-0.0275, 0.0275, 6)
    x = _positions(rng, slots, n)
    side = rng.uniform(-250.0, 250.0, len(slots))
    normal = rng.uniform(-20.0, 300.0, len(slots))
    side[2], normal[2] = 0.0, 0.0  # zero forces at a slot
    side[3], normal[3] = 1e-9, 2e-9  # round-off forces: settled
    values = _values(rng, n)
    values["bottom_rotation"][10:20] = rng.uniform(-0.4, 0.4, 10)  # beyond SMALL_ANGLE
    sources = [np.ascontiguousarray(values[name]) for name in PAIRED_SOURCES]
    sources[5] = np.array([1.5e-3])  # top_rotation: one value for all balls
    nx, ny = rng.uniform(-250.0, 250.0, n), rng.uniform(-20.0, 300.0, n)
    nx[100:150], ny[100:150] = 1e-9, 2e-9  # round-off forces: settled
    nx[150:160], ny[150:160] = 0.0, 0.0
    b0 = TABLE1.nominal_contact_angle
    paired = (*sources, TABLE1.groove_radius - TABLE1.ball_radius, nx, ny,
              x if along else np.empty(0), slots, side, normal, np.sin(b0), np.cos(b0),
              round_off_force(TABLE1))
    hc = hertz_constants(TABLE1.ball_radius, TABLE1.conformity, TABLE1.youngs_modulus,
                         TABLE1.poisson_ratio)
    analytic = (b0, TABLE1.ball_radius, hc.semi_major_coefficient, hc.elliptic_e, K_F_PAPER,
                MAX_ZERO_VELOCITY_RATIO, MAX_ANGLE_SUM, MAX_VELOCITY_DEVIATION)

    def outputs():
        return (np.empty((n, 4)), np.empty((n, 4)), np.empty(n, bool), np.empty(n, np.int8),
                np.empty(n), np.empty(n, bool))

    dbeta, force, four_point, count, eps, valid = want = outputs()
    clipped = np.empty((n, 4))
    with np.errstate(all="ignore"):
        want_settled = paired_balls_kernel(*paired, dbeta, force, four_point, count, clipped)
        analytic_kernel(dbeta, clipped, *analytic, eps, np.empty(n), np.empty((n, 4)), valid)
        got = outputs()
        settled = paired_analytic_kernel(*paired, *analytic, *got)
    for g, w in zip(got, want, strict=True):
        assert_array_equal(_bits(g), _bits(w))
    assert settled == want_settled > 0
    assert (count == -1).any() and (count == 0).any() and valid.any() and not valid.all()


def _whatif():
    return load_config(CONFIGS / "whatif_along_track.toml")


def _states_equal(got, want):
    for name in ("velocity_deviation", "valid", "converged", "loss_of_contact",
                 "contact_angle_deviation", "normal_force", "model", "regime"):
        assert_array_equal(_bits(getattr(got, name)), _bits(getattr(want, name)), err_msg=name)


def test_evaluate_balls_at_is_the_general_path():
    # source: loads_at as np.interp, then groove_error_fields, the NumPy paired_static and
    # ball_velocities (the general path of evaluate_balls); tolerance: the bits of every
    # field of the BallState, along the track and with per-ball loads
    config = _whatif()
    block = sample_block(config, 0)
    rng = np.random.default_rng(4)
    position = block.initial_position + rng.uniform(-0.05, 0.05, block.initial_position.shape)
    values = error_values(config, block, rail_position=position)
    shape = position.shape
    slots = config.train.slot_positions(2.0 * config.bearing.ball_radius)
    nx = np.interp(position, slots, config.loads.side_load)
    ny = np.interp(position, slots, config.loads.normal_load)
    n = position.size
    errors = groove_error_fields(values, shape)
    dbeta, force = _paired_numpy(errors, nx.reshape(n), ny.reshape(n), config.bearing)
    want = ball_velocities(config, StaticResult(dbeta, force, np.ones(n, dtype=bool)), shape)
    _states_equal(evaluate_balls_at(config, values, position), want)
    _states_equal(evaluate_balls(config, values, nx, ny), want)


def test_free_motion_and_gaps_are_the_numpy_expressions():
    # source: position + h * (1.0 + np.nan_to_num(w)) * 0.5 * v and np.diff(position,
    # axis=1) - diameter, FreeBalls.move and .step before the kernels; tolerance: the bits
    rng = np.random.default_rng(6)
    position = np.cumsum(rng.uniform(0.0, 0.011, (500, 7)), axis=1)
    w = rng.normal(0.0, 0.3, position.shape)  # large: the rounding of each product shows
    w.reshape(-1)[rng.integers(0, w.size, 40)] = np.nan
    w.reshape(-1)[:3] = [np.inf, -np.inf, -0.0]
    h, v = 0.0137, 0.2311
    assert_array_equal(_bits(free_motion(position, w, h, v)),
                       _bits(position + h * (1.0 + np.nan_to_num(w)) * 0.5 * v))
    assert_array_equal(_bits(gaps(position, 0.01)), _bits(np.diff(position, axis=1) - 0.01))
    one = position[:, :1]  # a single ball: no gaps
    assert gaps(one, 0.01).shape == (500, 0)


def _first_contact_numpy(gap_old, gap_new, ball_ok, t, dt, time, pair):
    """FirstContact.observe before the kernel."""
    closing = (gap_new <= 0.0) & (gap_old > gap_new) & ball_ok[:, :-1] & ball_ok[:, 1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(gap_old <= 0.0, 0.0, gap_old / (gap_old - gap_new))
    tc = np.where(closing, t + frac * dt, np.inf)
    first = np.argmin(tc, axis=1)
    tmin = tc[np.arange(len(tc)), first]
    hit = np.isfinite(tmin) & ~np.isfinite(time)
    time[hit] = tmin[hit]
    pair[hit] = first[hit]


def test_first_contact_kernel_is_the_numpy_observer():
    # source: FirstContact.observe before the kernel (argmin over the closing pairs' times);
    # tolerance: the bits. Gaps closing, already closed, opening, NaN and inf, ties, balls
    # not ok, rows that already touched.
    rng = np.random.default_rng(8)
    m, pairs = 4000, 5
    choices = np.array([-2e-6, -0.0, 0.0, 1e-6, 3e-6, np.nan, np.inf])
    gap_old = choices[rng.integers(0, len(choices), (m, pairs))]
    gap_new = choices[rng.integers(0, len(choices), (m, pairs))]
    gap_old[:10], gap_new[:10] = 2e-6, -2e-6  # ties: the first pair
    ball_ok = rng.random((m, pairs + 1)) < 0.9
    ball_ok[:10] = True
    time = np.where(rng.random(m) < 0.2, 0.01, np.inf)
    time[:10] = np.inf
    pair = np.where(np.isfinite(time), 1, -1).astype(np.int64)
    want_time, want_pair = time.copy(), pair.copy()
    _first_contact_numpy(gap_old, gap_new, ball_ok, 0.05, 0.025, want_time, want_pair)
    first_contact_kernel(gap_old, gap_new, ball_ok, 0.05, 0.025, time, pair)
    assert_array_equal(_bits(time), _bits(want_time))
    assert_array_equal(pair, want_pair)
    assert 0 < np.isfinite(want_time).sum() < m and (want_pair[:10] == 0).all()


def test_rail_field_read_in_parallel_is_the_serial_read():
    # source: RailField.at serial (the kernel of the draws); tolerance: the bits, at positions
    # inside, beyond both ends of the grid and NaN
    config = _whatif()
    block = sample_block(config, 0)
    field = next(iter(block.fields.values()))
    rng = np.random.default_rng(9)
    span = field.spacing * field.values.shape[1]
    position = field.origin + rng.uniform(-0.2 * span, 1.2 * span, block.initial_position.shape)
    position[0, :2] = np.nan, -np.inf
    assert_array_equal(_bits(field.at(position, parallel=True)), _bits(field.at(position)))
    values = error_values(config, block, rail_position=position)
    parallel = error_values(config, block, rail_position=position, parallel=True)
    for name, v in values.items():
        assert_array_equal(_bits(parallel[name]), _bits(v), err_msg=name)
