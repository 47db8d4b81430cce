"""The pipeline of a study: a block of sampled errors -> each ball's contact state and
epsilon -> propagation along the track -> contact and friction figures."""

from tolsim.study.pipeline.block import BlockOutcome, evaluate_block

__all__ = ["BlockOutcome", "evaluate_block"]
