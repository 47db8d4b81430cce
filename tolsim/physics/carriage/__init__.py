"""The carriage: a rigid body on its ball tracks, with preload (tolsim issue 12, physics core).

Every ball of every track is the basic module of [Lin2018] (:mod:`tolsim.physics.static`): a
ball between a rail groove (flanks BL, BR, fixed) and a carriage groove (TR, TL). The
carriage grooves move with one rigid carriage; this package finds the carriage displacement
that balances the external load, and with it the four contacts of every ball.

The conventions, the equilibrium and how carriage loads map to the balls are in the Notes of
:func:`solve_carriage`; the batched solve and balls moving through the carriage in those of
:func:`solve_carriage_batch`; the end relief in :func:`end_relief`; a carriage with clearance
settling onto its contacts, and lift-off, in the Notes of :func:`solve_carriage` ("Settling").
Every solve ends with a :class:`CarriageStatus` (CONVERGED, NOT_CONVERGED, LIFT_OFF, FAILED):
per assembly in :attr:`CarriageBatch.status`, in :attr:`CarriageSolution.status`, and as
:attr:`CarriageError.status` where :func:`solve_carriage` raises. Layout: ``layout`` (the
dataclasses and geometry), ``solve`` (the validated solves), ``_kernels`` and
``_batch_kernels`` (the Numba loops), ``_map_kernels`` (the groove maps of balls at their
own z, the singular-tangent test).

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033 (Sec. 2.1, Fig. 6).
.. [Johnson1985] K. L. Johnson, Contact Mechanics, Cambridge University Press, 1985.
"""

from tolsim.physics.carriage._batch_kernels import carriage_batch_kernel
from tolsim.physics.carriage._kernels import (
    BATCH_STATUS,
    STATUS_CONVERGED,
    STATUS_FAILED,
    STATUS_LIFT_OFF,
    STATUS_NOT_CONVERGED,
    carriage_balls_kernel,
    condensed_ball,
    schur_complement,
)
from tolsim.physics.carriage.layout import (
    DOF_UNITS,
    DOFS,
    LOAD_UNITS,
    CarriageBatch,
    CarriageError,
    CarriageLayout,
    CarriageLoad,
    CarriageSolution,
    CarriageStatus,
    end_relief,
    locked_dofs,
)
from tolsim.physics.carriage.solve import (
    CARRIAGE_MAX_ITER,
    CARRIAGE_TOLERANCE,
    solve_carriage,
    solve_carriage_batch,
    uncarried_motions,
)

__all__ = [
    "BATCH_STATUS",
    "CARRIAGE_MAX_ITER",
    "CARRIAGE_TOLERANCE",
    "DOFS",
    "DOF_UNITS",
    "LOAD_UNITS",
    "STATUS_CONVERGED",
    "STATUS_FAILED",
    "STATUS_LIFT_OFF",
    "STATUS_NOT_CONVERGED",
    "CarriageBatch",
    "CarriageError",
    "CarriageLayout",
    "CarriageLoad",
    "CarriageSolution",
    "CarriageStatus",
    "carriage_balls_kernel",
    "carriage_batch_kernel",
    "condensed_ball",
    "end_relief",
    "locked_dofs",
    "schur_complement",
    "solve_carriage",
    "solve_carriage_batch",
    "uncarried_motions",
]
