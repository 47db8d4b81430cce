"""Study layer: sampling, evaluation, propagation and streamed statistics (+ physics).

:mod:`~tolsim.study.spec` (the study description), :mod:`~tolsim.study.sampling` (blocks of
reproducible draws), :mod:`~tolsim.study.evaluate` (static model and velocity kernel
registries), :mod:`~tolsim.study.propagation` (ball-to-ball contact, modes a and b),
:mod:`~tolsim.study.trains` (trains of balls after contact: clusters, ball-to-ball forces,
event-driven with constant epsilon), :mod:`~tolsim.study.friction` (what contact costs: the
carriage friction of the trains over the stroke, its streamed statistics and result-file
variables), :mod:`~tolsim.study.statistics` (mergeable accumulators),
:mod:`~tolsim.study.estimators` (binomial and cluster intervals, pure NumPy/SciPy) and
:mod:`~tolsim.study.runner` (:func:`~tolsim.study.runner.run_study`) and
:mod:`~tolsim.study.allocate` (least-cost tolerance allocation against a probabilistic
target, on common random numbers). Never imports tomllib, xarray or matplotlib.
"""
