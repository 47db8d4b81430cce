"""The work of a study: chunks of random blocks evaluated, and their spot checks.

:func:`run_chunk` evaluates consecutive blocks (:func:`tolsim.study.pipeline.block.
evaluate_block`) and reduces each to an Accumulator and its spot-check rows;
:func:`prefetched` runs it over chunks, drawing the next while one is evaluated;
:func:`finish_spot_checks` re-solves the chosen spot checks with the full model. The
orchestrator (:func:`tolsim.study.execution.runner.run_study`) and the dask tasks
(:mod:`tolsim.study.execution.distributed`) both call them.
"""

import ctypes
import platform
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from tolsim.physics.velocity.models import MODEL_FAST
from tolsim.study.analyses.friction_examples import choose_examples
from tolsim.study.execution import saved_samples
from tolsim.study.pipeline.block import evaluate_block, evaluates_blocks_together
from tolsim.study.pipeline.evaluate import BallState, friction_module
from tolsim.study.sampling import (
    block_size_of,
    error_values,
    near_limit_candidates,
    sample_block,
    select_spot_checks,
    spot_check_plan,
)
from tolsim.study.statistics.friction import study_accumulator

#: The spot-check rows that a block records (:func:`spot_rows`).
SPOT_FIELDS = ("ball_index", "contact_angle_deviation", "normal_force",
               "velocity_deviation_analytic", "valid_analytic", "stratum", "band_balls")


@dataclass
class SpotChecks:
    """Balls re-solved with the full model (``tolsim.physics.velocity.full.full``).

    Arrays have length k (the ``spot_check`` dimension); ``status`` explains a k of zero.
    ``stratum``: 0 uniform, 1 near the spec limit (:class:`tolsim.study.sampling.
    SpotCheckPlan`); ``band``: the near-limit band of |epsilon| [-] and ``band_balls`` the
    balls of the fast model in it.
    """

    ball_index: np.ndarray
    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    velocity_deviation_analytic: np.ndarray
    valid_analytic: np.ndarray
    velocity_deviation_full: np.ndarray
    converged_full: np.ndarray
    valid_full: np.ndarray
    stratum: np.ndarray = field(default_factory=lambda: np.empty(0, np.int8))
    band: tuple = (float("nan"), float("nan"))
    band_balls: int = 0
    status: str = ""


def _empty_spot():
    return {"ball_index": np.empty(0, np.int64),
            "contact_angle_deviation": np.empty((0, 4)), "normal_force": np.empty((0, 4)),
            "velocity_deviation_analytic": np.empty(0), "valid_analytic": np.empty(0, bool),
            "stratum": np.empty(0, np.int8), "band_balls": np.empty(0, np.int64)}


def spot_rows(state: BallState, start_ball: int, plan) -> dict:
    """Records of the spot-check candidates inside a block (``plan``: a
    :class:`~tolsim.study.sampling.SpotCheckPlan`): its uniform candidates, then its
    near-limit candidates; ``band_balls`` holds the block's count of balls in the band."""
    eps = state.velocity_deviation.reshape(-1)
    fast_all = state.model.reshape(-1) == MODEL_FAST
    n = eps.size
    lo, hi = np.searchsorted(plan.uniform, [start_ball, start_ball + n])
    uniform = plan.uniform[lo:hi] - start_ball
    near, in_band = near_limit_candidates(plan, eps, fast_all, start_ball, exclude=uniform)
    local = np.concatenate([uniform, near]).astype(np.int64)
    fast = fast_all[local]
    return {
        "ball_index": (local + start_ball).astype(np.int64),
        "contact_angle_deviation": state.contact_angle_deviation.reshape(-1, 4)[local],
        "normal_force": state.normal_force.reshape(-1, 4)[local],
        # the study's fast model where it was valid (re-solved balls: NaN, not valid)
        "velocity_deviation_analytic": np.where(fast, eps[local], np.nan),
        "valid_analytic": fast,
        "stratum": np.repeat(np.array([0, 1], np.int8), [len(uniform), len(near)]),
        "band_balls": np.array([in_band], np.int64),
    }


def concat_spots(parts):
    """The spot-check rows of blocks (:func:`spot_rows`), concatenated in order."""
    if not parts:
        return _empty_spot()
    return {k: np.concatenate([p[k] for p in parts]) for k in SPOT_FIELDS}


def draw_chunk(config, block_indices):
    """The draws and error-source values of consecutive blocks, drawn as one."""
    block = sample_block(config, block_indices[0], len(block_indices))
    return block, error_values(config, block)


#: Key of the spot rows of block 0 of a study with ``[contact]``: the examples chosen from
#: its friction figures (:func:`tolsim.study.analyses.friction_examples.friction_examples`).
EXAMPLE_ORDER = "example_order"


def example_order(parts):
    """The examples chosen in the first block's records ``parts[0]`` (kept in a checkpoint
    too), or None."""
    return parts[0].get(EXAMPLE_ORDER) if parts else None


def run_chunk(config, block_indices, spot_indices, drawn=None, save_samples=0):
    """Evaluate consecutive blocks; return [(block, Accumulator, spot rows)] in order.

    ``drawn``: ``draw_chunk(config, block_indices)`` when the caller has it already
    (constant propagation only). ``save_samples``: the spot rows of a block also hold the
    rows of its assemblies among the first ``save_samples``
    (:func:`tolsim.study.execution.saved_samples.sample_rows`).
    """
    out = []
    balls = config.balls
    # one pass over the whole chunk, then split per block, unless an assembly's result
    # depends on its batch (evaluates_blocks_together): then block by block
    if evaluates_blocks_together(config):
        groups = [list(block_indices)]
    else:
        groups = [[k] for k in block_indices]
        drawn = None
    for group in groups:
        block, values = drawn if drawn is not None else draw_chunk(config, group)
        outcome = evaluate_block(config, block, values)
        state, t, pair = outcome.state, outcome.time, outcome.pair
        offset = 0
        for index in group:
            size = block_size_of(config, index)
            sl = slice(offset, offset + size)
            sub = state.rows(sl)
            acc = study_accumulator(config)
            acc.add(sub, t[sl], pair[sl],
                    None if outcome.train_valid is None else outcome.train_valid[sl],
                    None if outcome.unresolved_along_track is None
                    else outcome.unresolved_along_track[sl])
            if outcome.carriage is not None:  # the carriages at the start of the stroke
                acc.add_carriage(outcome.carriage.rows(sl))
            if outcome.friction is not None:
                acc.add_friction(outcome.friction.rows(sl))
            if outcome.circuit is not None:  # a [carriage.circuit] (issue 24)
                acc.add_circuit({k: v[sl] for k, v in outcome.circuit.items()})
            if offset == 0:  # the group's re-solves, counted once
                acc.resolve_seconds = state.resolve_seconds + outcome.resolve_seconds
            start = index * config.study.block_size
            rows = spot_rows(sub, start * balls, spot_indices)
            rows.update(saved_samples.sample_rows(config, save_samples, start, values,
                                                  block.initial_gap, state, t, pair, sl,
                                                  circuit=outcome.circuit))
            if index == 0 and outcome.friction is not None:  # the friction examples' choice
                rows[EXAMPLE_ORDER] = choose_examples(outcome.friction.rows(sl),
                                                      config.contact.examples)
            out.append((index, acc, rows))
            offset += size
    return out


#: The first chunk of :func:`prefetched` is evaluated in two parts, the first holding this
#: share of its blocks: only that part's draw is waited for, the rest is drawn meanwhile.
FIRST_PART = 0.25


def prefetched(config, chunks, spot_indices, save_samples=0):
    """``run_chunk`` over the chunks in order, drawing chunk i + 1 in a second thread while
    chunk i is evaluated (NumPy's generators and ufuncs and the Numba kernels release the
    GIL, so drawing overlaps the kernels). The draws are the same as without the thread.
    Drawing must not launch parallel (``prange``) kernels: Numba's ``workqueue`` threading
    layer, the fallback where no OpenMP or TBB is installed, cannot run two at once.

    Nothing is evaluated before the first draw: the first chunk of several blocks is drawn and
    evaluated in two parts (the first :data:`FIRST_PART` of its blocks, then the rest, drawn
    while the first part is evaluated), and yielded as one (the same rows: blocks evaluated
    together do not depend on their batch,
    :func:`tolsim.study.pipeline.block.evaluates_blocks_together`)."""
    if not evaluates_blocks_together(config) or len(chunks) < 2:
        for c in chunks:
            yield run_chunk(config, c, spot_indices, None, save_samples)
        return
    split = 0 if len(chunks[0]) > 1 else 1  # after a probe block alone, the chunk after it
    parts = []
    for i, c in enumerate(chunks):
        cut = int(len(c) * FIRST_PART) if i == split else 0
        parts += [(i, list(c[:cut])), (i, list(c[cut:]))] if cut >= 1 else [(i, list(c))]
    with ThreadPoolExecutor(1, thread_name_prefix="tolsim-draw") as pool:
        pending = pool.submit(draw_chunk, config, parts[0][1])
        done = []
        for k, (i, blocks) in enumerate(parts):
            drawn = pending.result()
            if k + 1 < len(parts):
                pending = pool.submit(draw_chunk, config, parts[k + 1][1])
            done += run_chunk(config, blocks, spot_indices, drawn, save_samples)
            if k + 1 == len(parts) or parts[k + 1][0] != i:
                yield done
                done = []


#: glibc ``mallopt`` parameters and the values :func:`retain_freed_memory` sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_MMAP_THRESHOLD = 32 << 20  # the largest glibc accepts on 64-bit systems
_TRIM_THRESHOLD = 1 << 30


def retain_freed_memory() -> bool:
    """Let glibc keep freed memory for reuse instead of returning it to the system.

    Every chunk of a study allocates the same few hundred MB of arrays and frees them. By
    default glibc serves arrays of this size with fresh ``mmap`` pages and trims the heap on
    free, so every chunk pays a page fault (and zeroing) per 4 kB touched, serialised in the
    kernel across the Numba threads; on a 2-core VM that was 15-22 % of a study's run time
    (``benchmarks/bench_study.py``). With allocations up to 32 MB from the heap and no
    trimming below 1 GB the second chunk reuses the first one's pages. Peak memory does not
    change; the process just keeps it until it exits. Returns False (and does nothing) where
    the C library is not glibc.
    """
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL("libc.so.6")
        return bool(libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_THRESHOLD)
                    and libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_THRESHOLD))
    except (OSError, AttributeError):
        return False


def finish_spot_checks(config, rows: dict) -> SpotChecks:
    """Select the spot checks among the recorded candidates
    (:func:`tolsim.study.sampling.select_spot_checks`) and re-solve them with the full model,
    if it is installed."""
    plan = spot_check_plan(config)
    band_balls = int(np.sum(rows["band_balls"]))
    chosen = select_spot_checks(plan, rows["ball_index"], rows["stratum"])
    rows = {key: v[chosen] for key, v in rows.items() if key != "band_balls"}
    rows.update(band=plan.band, band_balls=band_balls)
    k = len(rows["ball_index"])
    module = friction_module()
    if k == 0 or module is None or not hasattr(module, "full"):
        status = ("no spot checks requested" if config.study.spot_checks == 0 else
                  "full model not available (tolsim.physics.velocity.full.full missing): "
                  "0 spot checks")
        if k and module is None:
            rows = {key: v[:0] if isinstance(v, np.ndarray) else v for key, v in rows.items()}
        return SpotChecks(**rows, velocity_deviation_full=np.empty(0),
                          converged_full=np.empty(0, bool), valid_full=np.empty(0, bool),
                          status=status)
    # a ball without a contact state (its carriage was not solved) has nothing to check, nor
    # one whose contacts the full model does not describe (it would raise for it)
    finite = (np.all(np.isfinite(rows["contact_angle_deviation"]), axis=1)
              & np.all(np.isfinite(rows["normal_force"]), axis=1))
    angles, ellipses = module.within_model(rows["contact_angle_deviation"],
                                           np.maximum(rows["normal_force"], 0.0),
                                           config.bearing)
    outside = finite & ~(angles & ellipses)
    finite &= ~outside
    eps_full = np.full(k, np.nan)
    converged = np.zeros(k, bool)
    valid = np.zeros(k, bool)
    if finite.any():
        res = module.full(rows["contact_angle_deviation"][finite],
                          np.maximum(rows["normal_force"][finite], 0.0), config.bearing,
                          groove_velocity=config.motion.groove_velocity)
        eps_full[finite] = np.asarray(res.velocity_deviation, dtype=float)
        conv = np.asarray(getattr(res, "converged", np.ones(finite.sum(), bool)), dtype=bool)
        converged[finite] = conv
        valid[finite] = np.asarray(getattr(res, "valid", conv), dtype=bool) & conv
    n_near = int(np.count_nonzero(rows["stratum"] == 1))
    status = f"{k} balls re-solved with the full model"
    if plan.near_limit:
        status += (f": {k - n_near} drawn uniformly, {n_near} from the {band_balls:,} balls "
                   f"of the fast model with {100 * plan.band[0]:.3g} % ≤ |ε| ≤ "
                   f"{100 * plan.band[1]:.3g} % (near the spec limit)")
    if outside.any():
        status += (f"; {int(outside.sum())} of them outside the full model (a contact angle "
                   f"outside (0, 90) deg or a contact ellipse wider than R_B / 2): no "
                   f"full-model value")
    return SpotChecks(**rows, velocity_deviation_full=eps_full, converged_full=converged,
                      valid_full=valid, status=status)
