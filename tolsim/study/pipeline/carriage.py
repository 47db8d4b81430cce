"""One carriage assembly of a config with ``[carriage]`` (tolsim issue 12): its load
distribution and every ball's velocity deviation.

The Python API behind ``tolsim carriage``: :func:`solve_config_carriage` solves the nominal
assembly (the config's preload and per-ball oversize deviations, no sampled tolerances) with
:func:`tolsim.physics.carriage.solve_carriage`, then takes epsilon of each ball from the
improved analytical model (:func:`tolsim.physics.velocity.analytic.analytic`) and, where that model
is outside its validity or a contact is open, from the full friction model
(:func:`tolsim.study.pipeline.evaluate.full_velocity`), as a study does.
"""

from dataclasses import dataclass

import numpy as np

from tolsim.physics.carriage import (
    DOFS,
    CarriageSolution,
    CarriageStatus,
    solve_carriage,
    solve_carriage_batch,
)
from tolsim.physics.static import GrooveErrors
from tolsim.physics.velocity.analytic import analytic
from tolsim.physics.velocity.models import BALL_REGIME_A, BALL_UNRESOLVED
from tolsim.study.pipeline.evaluate import (
    StaticResult,
    ball_velocities,
    full_velocity,
    groove_error_fields,
    serial_if_small,
)
from tolsim.study.sampling import error_values, sample_block


@dataclass(frozen=True)
class CarriageResult:
    """The solved carriage and its balls' velocity deviations.

    Attributes
    ----------
    solution : tolsim.physics.carriage.CarriageSolution
    velocity_deviation : ndarray, (n_tracks, n)
        epsilon of each ball [-] (NaN where the ball is unloaded, or no model solves it).
    velocity_model : ndarray of str, (n_tracks, n)
        ``analytic``, ``full`` or ``""`` (no value), per ball.
    regime : ndarray of int8, (n_tracks, n)
        The ball's regime (:data:`tolsim.physics.velocity.models.BALL_REGIMES`).
    """

    solution: CarriageSolution
    velocity_deviation: np.ndarray
    velocity_model: np.ndarray
    regime: np.ndarray


def ball_velocity_deviation(solution: CarriageSolution, bearing, groove_velocity=0.01):
    """epsilon [-], the model that gave it and the regime, per ball of a solved carriage.

    The analytical model where it is valid (regime A), else the full model, which also takes
    the balls with two or three loaded contacts (issue 25).

    Returns
    -------
    eps : ndarray, (n_tracks, n)
        NaN for an unloaded ball (no epsilon of its own) or one no model solves.
    model : ndarray of str, (n_tracks, n)
    regime : ndarray of int8, (n_tracks, n)
        :data:`tolsim.physics.velocity.models.BALL_REGIMES` code.
    """
    shape = solution.normal_force.shape[:2]
    dbeta = np.ascontiguousarray(solution.contact_angle_deviation.reshape(-1, 4))
    force = np.ascontiguousarray(solution.normal_force.reshape(-1, 4))
    with np.errstate(all="ignore"):
        res = analytic(dbeta, force, bearing)
    eps = np.asarray(res.velocity_deviation, dtype=float).copy()
    good = np.asarray(res.valid, dtype=bool) & np.isfinite(eps)
    model = np.where(good, "analytic", "")
    regime = np.where(good, np.int8(BALL_REGIME_A), np.int8(BALL_UNRESOLVED))
    redo = np.flatnonzero(~good)
    eps[redo] = np.nan
    if redo.size:
        eps_full, ok, regime_full = full_velocity(dbeta[redo], np.where(
            np.isfinite(force[redo]), force[redo], 0.0), bearing, groove_velocity)
        eps[redo[ok]] = eps_full[ok]
        model[redo[ok]] = "full"
        regime[redo] = regime_full
    return eps.reshape(shape), model.reshape(shape), regime.reshape(shape)


def solve_config_carriage(config, seed: int | None = None) -> CarriageResult:
    """Solve the nominal carriage assembly of a config with ``[carriage]``, or one sampled.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        With ``config.carriage`` set.
    seed : int, optional
        Solve the first assembly of the study run with this seed (assembly 0 of ``tolsim run
        CONFIG --seed SEED``: the same draws, so ``--save-samples`` of that run holds its
        errors) instead of the nominal one.

    Returns
    -------
    CarriageResult

    Raises
    ------
    ValueError
        A config without ``[carriage]``; a load the track layout cannot carry; a carriage
        that lifts off or fails (:class:`tolsim.physics.carriage.CarriageError`, whose
        ``status`` says which; messages from :func:`tolsim.physics.carriage.solve_carriage`).
    """
    carriage = config.carriage
    if carriage is None:
        raise ValueError(f"{config.path} has no [carriage] section")
    errors = None
    if seed is not None:
        first = config.with_overrides(seed=seed, samples=1)
        values = error_values(first, sample_block(first, 0))
        sampled = carriage_groove_errors(first, values, 1)
        errors = GrooveErrors(**{f: np.asarray(getattr(sampled, f))[0]
                                 for f in GrooveErrors.TRAILING})
    solution = solve_carriage(carriage.layout, carriage.load, config.bearing,
                              oversize=carriage.oversize, groove_errors=errors)
    eps, model, regime = ball_velocity_deviation(solution, config.bearing,
                                                 config.motion.groove_velocity)
    return CarriageResult(solution, eps, model, regime)


#: Codes of :attr:`CarriageState.status`: those of ``solve_carriage_batch``
#: (:class:`tolsim.physics.carriage.CarriageStatus`): solved, Newton not converged, lifted off
#: (no equilibrium: the load pulls the carriage off every contact), failed (the motion leaves
#: the gothic arch, or a ball solve failed).
CARRIAGE_SOLVED, CARRIAGE_NOT_CONVERGED, CARRIAGE_LIFT_OFF, CARRIAGE_FAILED = (
    int(CarriageStatus.CONVERGED), int(CarriageStatus.NOT_CONVERGED),
    int(CarriageStatus.LIFT_OFF), int(CarriageStatus.FAILED))


@dataclass
class CarriageState:
    """Per-assembly carriage results of a chunk of a study.

    Attributes
    ----------
    displacement : ndarray, (m, 5)
        q = (u_x, u_y [m], pitch, yaw, roll [rad]) (NaN where not solved).
    stiffness : ndarray, (m, 5)
        Diagonal of the tangent carriage stiffness [N/m, N m/rad] (NaN where not solved).
    status : ndarray of int8, (m,)
        :data:`CARRIAGE_SOLVED`, :data:`CARRIAGE_NOT_CONVERGED`, :data:`CARRIAGE_LIFT_OFF` or
        :data:`CARRIAGE_FAILED`.
    """

    displacement: np.ndarray
    stiffness: np.ndarray
    status: np.ndarray

    def rows(self, sl):
        return CarriageState(self.displacement[sl], self.stiffness[sl], self.status[sl])


def carriage_groove_errors(config, values: dict, assemblies: int) -> GrooveErrors:
    """The sampled errors of every ball of a carriage study as :class:`GrooveErrors` fields of
    shape (m, tracks, balls) (+ trailing axis), ``values`` of shape (m, tracks * balls)."""
    tracks, balls = config.n_tracks, config.train.balls
    shape = (assemblies, tracks * balls)
    flat = groove_error_fields({k: np.broadcast_to(v, shape) for k, v in values.items()}, shape)
    return GrooveErrors(**{k: v.reshape((assemblies, tracks, balls) + v.shape[1:])
                           for k, v in flat.items()})


def _solve_batch(carriage, bearing, oversize, errors, assemblies):
    """Solve every assembly (:func:`tolsim.physics.carriage.solve_carriage_batch`); a
    carriage that does not converge or lifts off is a status, not an error."""
    batch = solve_carriage_batch(carriage.layout, carriage.load, bearing, oversize=oversize,
                                 groove_errors=errors)
    if batch.status.shape != (assemblies,):
        raise ValueError(f"carriage batch of {batch.status.shape} for {assemblies} assemblies")
    stiffness = np.diagonal(batch.stiffness, axis1=1, axis2=2)
    return (batch.contact_angle_deviation, batch.normal_force, batch.ball_converged,
            batch.displacement, np.ascontiguousarray(stiffness), batch.status.astype(np.int8))


def evaluate_carriage(config, values: dict):
    """Balls of a chunk of carriage assemblies: carriage solve, then the velocity model.

    Every assembly's carriage is solved with its own sampled groove errors and ball
    oversizes (the nominal preload and the config's per-ball deviations plus the sampled
    ``ball_oversize``); its balls' loaded contact states go through the study's velocity model
    and the full-model re-solves as any ball's
    (:func:`tolsim.study.pipeline.evaluate.ball_velocities`).
    An assembly whose carriage does not converge or lifts off is not dropped: its balls count
    as not converged, so its trains are unresolved (counted and bounded).

    Parameters
    ----------
    config : StudyConfig
        With ``carriage``.
    values : dict
        source -> ndarray (m, tracks * balls) [m or rad] (:func:`tolsim.study.sampling.
        error_values`).

    Returns
    -------
    (BallState, CarriageState)
        Balls of shape (m, tracks * balls), track by track.
    """
    carriage = config.carriage
    m = next(iter(values.values())).shape[0] if values else 0
    if not values:
        raise ValueError("evaluate_carriage needs the error values of the chunk")
    errors = carriage_groove_errors(config, values, m)
    nball = config.balls
    with serial_if_small(m * nball):
        dbeta, force, ball_ok, q, k, status = _solve_batch(
            carriage, config.bearing, carriage.oversize, errors, m)
    ok = ball_ok.reshape(-1) & np.repeat(status == CARRIAGE_SOLVED, nball)
    f = force.reshape(-1, 4)
    static = StaticResult(np.ascontiguousarray(dbeta.reshape(-1, 4)),
                          np.ascontiguousarray(np.where(np.isfinite(f), f, 0.0)), ok)
    state = ball_velocities(config, static, (m, nball))
    return state, CarriageState(q, k, status)


__all__ = ["CARRIAGE_FAILED", "CARRIAGE_LIFT_OFF", "CARRIAGE_NOT_CONVERGED", "CARRIAGE_SOLVED",
           "DOFS",
           "CarriageResult", "CarriageState", "ball_velocity_deviation",
           "carriage_groove_errors", "evaluate_carriage", "solve_config_carriage"]
