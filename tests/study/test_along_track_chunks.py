"""Along-track studies integrate a chunk's blocks together (issue 24, "Speed").

One integration over several blocks pays the per-step overhead once instead of once per block;
it must give every assembly the result it has when its block is integrated alone, bit for bit,
so the result does not depend on ``chunk_blocks``.
"""

import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.testing import assert_array_equal

from tolsim.io.config import load_config, parse_config
from tolsim.study.execution.runner import run_study
from tolsim.study.pipeline.block import evaluates_blocks_together

ROOT = Path(__file__).resolve().parents[2]


def study(name, samples, block, steps, extra=""):
    c = load_config(ROOT / "configs" / name)
    if extra:  # (a circuit needs along_track when it is read)
        text = c.text.replace("[study]\n", '[study]\npropagation = "along_track"\n')
        c = parse_config(text + extra, name)
    c = replace(c, study=replace(c.study, propagation="along_track", spot_checks=0,
                                 sensitivity_samples=0, time_steps=steps, block_size=block))
    return c.with_overrides(samples=samples)


def assert_same_statistics(a, b):
    sa, sb = a.statistics.state(), b.statistics.state()
    assert sa.keys() == sb.keys()
    for k in sa:
        assert_array_equal(np.asarray(sa[k]), np.asarray(sb[k]), err_msg=k)  # NaN == NaN


def test_which_studies_integrate_blocks_together():
    # the rule of evaluates_blocks_together: constant always; along_track unless an
    # assembly's integration depends on its batch
    free = study("whatif_along_track.toml", 8, 4, 2)
    carriage = study("carriage_preload.toml", 8, 4, 2)
    assert evaluates_blocks_together(replace(free, study=replace(free.study,
                                                                 propagation="constant")))
    assert evaluates_blocks_together(free)
    assert evaluates_blocks_together(carriage)
    assert not evaluates_blocks_together(
        replace(free, study=replace(free.study, static_model="linearised")))
    assert evaluates_blocks_together(
        study("carriage_preload.toml", 8, 4, 2, "\n[carriage.circuit]\n"))


def test_free_balls_with_contact_same_in_one_chunk_or_block_by_block():
    # configs/friction_yaw.toml along the track (trains after contact, friction figures):
    # 4 blocks of 16 as one integration and one by one: every statistic bit for bit
    c = study("friction_yaw.toml", 64, 16, 12)
    assert c.contact is not None
    one = run_study(c, chunk_blocks=1)
    four = run_study(c, chunk_blocks=4)
    assert_same_statistics(one, four)
    assert int(one.statistics.n_contact) > 0


def test_carriage_with_contact_same_in_one_chunk_or_block_by_block():
    # configs/carriage_preload.toml along the track with [contact]: each assembly followed
    # over the whole stroke with its own warm starts; 3 blocks of 6 together and alone
    c = study("carriage_preload.toml", 18, 6, 8, "\n[contact]\n")
    one = run_study(c, chunk_blocks=1)
    three = run_study(c, chunk_blocks=3)
    assert_same_statistics(one, three)
    assert int(one.statistics.n_contact) > 0


def test_circuit_same_in_one_chunk_or_block_by_block():
    # configs/carriage_circuit.toml (30-ball circuits, drag) with [contact]: every circuit
    # followed over the stroke, a ball without a creep stiffness at its own assembly's mean
    # K; 3 blocks of 6 together and alone, every statistic bit for bit
    c = load_config(ROOT / "configs" / "carriage_circuit.toml")
    c = parse_config(c.text + "\n[contact]\n", "carriage_circuit.toml")
    c = replace(c, study=replace(c.study, spot_checks=0, sensitivity_samples=0, time_steps=8,
                                 block_size=6)).with_overrides(samples=18)
    one = run_study(c, chunk_blocks=1)
    three = run_study(c, chunk_blocks=3)
    assert_same_statistics(one, three)
    assert int(one.statistics.n_contact) > 0


def test_first_chunk_in_two_parts_gives_the_same_study(monkeypatch):
    # source: the same study block by block (chunk_blocks=1); tolerance: every statistic bit
    # for bit. With chunk_blocks=4 prefetched evaluates the first chunk as its first block,
    # then the other three (drawn meanwhile), and yields the chunk as one.
    import tolsim.study.execution.chunks as chunks

    c = study("whatif_along_track.toml", 8 * 16, 16, 6)
    evaluated, yielded = [], []
    run_chunk, prefetched = chunks.run_chunk, chunks.prefetched

    def recording_run(config, blocks, *args, **kwargs):
        evaluated.append(list(blocks))
        return run_chunk(config, blocks, *args, **kwargs)

    def recording_prefetched(*args, **kwargs):
        for result in prefetched(*args, **kwargs):
            yielded.append([index for index, _, _ in result])
            yield result

    one = run_study(c, chunk_blocks=1)
    monkeypatch.setattr(chunks, "run_chunk", recording_run)
    monkeypatch.setattr("tolsim.study.execution.runner.prefetched", recording_prefetched)
    four = run_study(c, chunk_blocks=4)
    assert evaluated == [[0], [1, 2, 3], [4, 5, 6, 7]]
    assert yielded == [[0, 1, 2, 3], [4, 5, 6, 7]]
    assert_same_statistics(one, four)
    assert int(one.statistics.n_contact) > 0


def test_openmp_threads_wait_passively_unless_told_otherwise():
    # tolsim._jit sets OMP_WAIT_POLICY before any parallel kernel runs, unless it is set
    code = "import os, tolsim._jit; print(os.environ['OMP_WAIT_POLICY'])"
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "PASSIVE"
    out = subprocess.run([sys.executable, "-c", code], env=dict(env, OMP_WAIT_POLICY="active"),
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "active"
