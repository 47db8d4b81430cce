"""Seeds, blocks of standard normals, batched evaluation and argument checks shared by the
rare-event estimators (:mod:`tolsim.study.analyses.rare_events`)."""

import math

import numpy as np
from scipy.special import ndtri

#: Key under the given SeedSequence of every stream drawn here ('rare' in ASCII), so that a
#: caller passing its study's root sequence does not collide with the study's own streams.
RARE_EVENT_STREAM = 0x72617265
#: Rows per independently seeded block of standard normals (Monte Carlo, importance
#: sampling, level 0 of subset simulation). Fixed: changing it changes the draws.
BLOCK_ROWS = 1 << 14


def seed_sequence(seed) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, int | np.integer) and not isinstance(seed, bool) and seed >= 0:
        return np.random.SeedSequence(int(seed))
    raise ValueError(f"seed = {seed!r}: expected a numpy SeedSequence or an int >= 0")


def child_sequence(root, *keys) -> np.random.SeedSequence:
    """The SeedSequence (RARE_EVENT_STREAM, *keys) under ``root``, without spawning from it."""
    return np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, RARE_EVENT_STREAM,
                                                           *keys), pool_size=root.pool_size)


def normal_blocks(root, keys, n, d):
    """Standard normals (n, d) as blocks of :data:`BLOCK_ROWS` rows, block k from child
    (*keys, k); the last block is drawn whole and cut."""
    for k, start in enumerate(range(0, n, BLOCK_ROWS)):
        rng = np.random.default_rng(child_sequence(root, *keys, k))
        block = rng.standard_normal((BLOCK_ROWS, d))
        yield block[:min(BLOCK_ROWS, n - start)]


def evaluate(limit_state, u, batch_size):
    """g on the rows of u, in order, at most ``batch_size`` rows per call; read-only input."""
    rows = u.shape[0]
    size = rows if batch_size is None else int(batch_size)
    out = np.empty(rows)
    for start in range(0, rows, max(size, 1)):
        block = u[start:start + size]
        block.flags.writeable = False
        values = np.asarray(limit_state(block), dtype=float)
        if values.shape != (block.shape[0],):
            raise ValueError(f"limit_state returned shape {values.shape} for {block.shape[0]} "
                             f"rows; expected ({block.shape[0]},)")
        out[start:start + size] = values
    return out


def cv_of(p, se):
    if not np.isfinite(p):
        return float("nan")
    return se / p if p > 0 else float("inf")


def check_dimension(dimension) -> int:
    if isinstance(dimension, bool) or not isinstance(dimension, int | np.integer) \
            or dimension < 1:
        raise ValueError(f"dimension = {dimension!r} must be an int >= 1")
    return int(dimension)


def check_count(name, value, minimum) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} = {value!r} must be an int >= {minimum}")
    return int(value)


def check_batch_size(batch_size):
    if batch_size is not None:
        check_count("batch_size", batch_size, 1)


def check_confidence(confidence_level) -> float:
    if not 0 < confidence_level < 1:
        raise ValueError(f"confidence_level = {confidence_level!r} must be in (0, 1)")
    return float(ndtri(0.5 + confidence_level / 2))


def clip_unit(value) -> float:
    """``value`` clipped to [0, 1] (NaN stays NaN): a probability, or an end of its interval."""
    return float(np.clip(value, 0.0, 1.0)) if np.isfinite(value) else float(value)


#: Below this largest |x|, :func:`weighted_mean` works on x over its largest: squares of values
#: under about 1e-154 underflow to 0 (importance weights deep in the tail).
TINY_WEIGHTS = 1e-150


def weighted_mean(x):
    """Mean and its standard error (sample standard deviation / sqrt(n)).

    Values all below :data:`TINY_WEIGHTS` in size are scaled by their largest first: their
    squared deviations underflowed to 0, which gave a standard error (and CV) of 0, an interval
    of zero width around a P of 2e-303.
    """
    largest = float(np.max(np.abs(x), initial=0.0))
    if 0.0 < largest < TINY_WEIGHTS:
        mean, se = weighted_mean(x / largest)
        return mean * largest, se * largest
    return float(np.mean(x)), float(np.std(x, ddof=1)) / math.sqrt(x.size)

