"""The names of a what-if sweep's result file beside the declared variables (issue 14,
:mod:`tolsim.io.sweep` writes it)."""

#: Global attributes of a sweep's result file (issue 14, :mod:`tolsim.io.sweep`): its sweep
#: dimensions and the coordinates of the swept keys (space-separated names).
SWEEP_DIMENSIONS, SWEEP_COORDINATES = "sweep_dimensions", "sweep_coordinates"
#: Variables of a sweep's result file besides the declared ones: the zip dimension's index
#: and each point's count of spot checks.
SWEEP_VARIABLES = ("sweep_point", "spot_check_count")
