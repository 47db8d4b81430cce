"""The carriage's error values written straight into the GrooveErrors fields
(:func:`tolsim.study.pipeline.evaluate.groove_error_buffers` with
:func:`tolsim.study.sampling.moving_ball_values`) against the dict of values and
:func:`tolsim.study.pipeline.evaluate.groove_error_fields` they replace, bit for bit."""

from pathlib import Path

import numpy as np
from numpy.testing import assert_array_equal

from tolsim.io.config import parse_config
from tolsim.study.pipeline.carriage_track import slot_capacity
from tolsim.study.pipeline.evaluate import (
    GROOVE_ERROR_SOURCES,
    groove_error_buffers,
    groove_error_fields,
)
from tolsim.study.sampling import (
    entering_capacity,
    fixed_ball_values,
    moving_ball_values,
    sample_block,
)

ROOT = Path(__file__).resolve().parents[2]

#: configs/carriage_preload.toml (a rail field, per-track rail and carriage sources, a ball
#: source) with one normal arc-centre offset (a field with one of its four sources) and a
#: correlated pair (sources moving_ball_values transforms at every step).
EXTRA = """
[tolerances.arc_centre_offset_normal_TR]
distribution = "normal"
std_um = 0.5
scope = "carriage"

[[correlation]]
sources = ["arc_centre_offset_tangential_TR", "arc_centre_offset_tangential_TL"]
coefficient = 0.8
"""


def groove_error_fields_twin(values, shape, compact=False):
    """groove_error_fields as it was before groove_error_buffers (session 13)."""
    n = int(np.prod(shape))

    def group(names):
        out = np.empty(tuple(shape) + (len(names),))
        for i, name in enumerate(names):
            out[..., i] = values.get(name, 0.0)
        return out.reshape(n, len(names))

    return {field: group(names) if len(names) > 1 else group(names)[:, 0]
            for field, names in GROOVE_ERROR_SOURCES.items()
            if not compact or any(name in values for name in names)}


def _bits(fields):
    return {k: np.ascontiguousarray(v).view(np.uint64) for k, v in fields.items()}


def test_values_written_into_the_fields_are_the_fields_of_the_values():
    # source: moving_ball_values' dict through groove_error_fields (compact), the carriage's
    # evaluation before; tolerance: the bits, with initial and entering balls, empty slots
    # and a subset of the rows; and groove_error_fields itself against its twin
    text = (ROOT / "configs" / "carriage_preload.toml").read_text() + EXTRA
    c = parse_config(text.replace("samples = 2000", "samples = 16"), "glue.toml")
    block = sample_block(c, 0)
    fixed = fixed_ball_values(c, block)
    rng = np.random.default_rng(4)
    rows = np.array([0, 3, 4, 9, 15])
    shape = (len(rows), 2, slot_capacity(c))
    ids = rng.integers(-1, c.train.balls + entering_capacity(c), size=shape)
    pos = rng.uniform(-0.05, 0.05, size=shape)
    values = moving_ball_values(c, block, ids, pos, rows, fixed)
    want = groove_error_fields_twin(values, shape, compact=True)
    assert set(want) == {"arc_centre_offset_normal", "arc_centre_offset_tangential",
                         "bottom_rotation", "top_rotation", "ball_oversize"}
    fields, columns = groove_error_buffers({t.source for t in c.tolerances}, shape)
    moving_ball_values(c, block, ids, pos, rows, fixed, columns)
    assert list(fields) == list(want)
    got = _bits(fields)
    for name, w in _bits(want).items():
        assert fields[name].shape == want[name].shape
        assert_array_equal(got[name], w, err_msg=name)
    for compact in (True, False):
        assert_array_equal(list(groove_error_fields(values, shape, compact)),
                           list(groove_error_fields_twin(values, shape, compact)))
        for name, w in _bits(groove_error_fields_twin(values, shape, compact)).items():
            assert_array_equal(_bits(groove_error_fields(values, shape, compact))[name], w)
