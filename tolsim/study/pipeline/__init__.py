"""The pipeline of a study: a block of sampled errors -> each ball's contact state and
epsilon -> propagation along the track -> contact and friction figures."""
