"""Study layer: sampling, evaluation, propagation and streamed statistics (+ physics).

:mod:`~tolsim.study.spec` (the study description), :mod:`~tolsim.study.sampling` (blocks of
reproducible draws), :mod:`~tolsim.study.pipeline.evaluate` (static model and velocity kernel
registries), :mod:`~tolsim.study.pipeline.propagation` (ball-to-ball contact, modes a and b),
:mod:`~tolsim.physics.trains` (trains of balls after contact: clusters, ball-to-ball forces,
event-driven with constant epsilon), :mod:`~tolsim.study.pipeline.track_friction` (what contact
costs: the
carriage friction of the trains over the stroke, its streamed statistics and result-file
variables), :mod:`~tolsim.study.statistics.accumulator` (mergeable accumulators),
:mod:`~tolsim.study.statistics.intervals` (binomial and cluster intervals, pure NumPy/SciPy) and
:mod:`~tolsim.study.execution.runner` (:func:`~tolsim.study.execution.runner.run_study`) and
:mod:`~tolsim.study.design.allocate` (least-cost tolerance allocation against a probabilistic
target, on common random numbers). Never imports tomllib, xarray or matplotlib.
"""
