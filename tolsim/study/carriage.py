"""One carriage assembly of a config with ``[carriage]`` (tolsim issue 12): its load
distribution and every ball's velocity deviation.

The Python API behind ``tolsim carriage``: :func:`solve_config_carriage` solves the nominal
assembly (the config's preload and per-ball oversize deviations, no sampled tolerances) with
:func:`tolsim.physics.carriage.solve_carriage`, then takes epsilon of each ball from the
improved analytical model (:func:`tolsim.physics.analytic.analytic`) and, where that model is
outside its validity, from the full friction model (:func:`tolsim.study.evaluate.
full_velocity`), as a study does for its spot checks.
"""

from dataclasses import dataclass

import numpy as np

from tolsim.physics.analytic import analytic
from tolsim.physics.carriage import CarriageSolution, solve_carriage
from tolsim.study.evaluate import full_velocity


@dataclass(frozen=True)
class CarriageResult:
    """The solved carriage and its balls' velocity deviations.

    Attributes
    ----------
    solution : tolsim.physics.carriage.CarriageSolution
    velocity_deviation : ndarray, (n_tracks, n)
        epsilon of each ball [-] (NaN where neither model gives one, e.g. a ball in
        two-point contact).
    velocity_model : ndarray of str, (n_tracks, n)
        ``analytic``, ``full`` or ``""`` (no value), per ball.
    """

    solution: CarriageSolution
    velocity_deviation: np.ndarray
    velocity_model: np.ndarray


def ball_velocity_deviation(solution: CarriageSolution, bearing, groove_velocity=0.01):
    """epsilon [-] and the model that gave it, per ball of a solved carriage.

    Returns
    -------
    eps : ndarray, (n_tracks, n)
    model : ndarray of str, (n_tracks, n)
    """
    shape = solution.normal_force.shape[:2]
    dbeta = np.ascontiguousarray(solution.contact_angle_deviation.reshape(-1, 4))
    force = np.ascontiguousarray(solution.normal_force.reshape(-1, 4))
    with np.errstate(all="ignore"):
        res = analytic(dbeta, force, bearing)
    eps = np.asarray(res.velocity_deviation, dtype=float).copy()
    good = np.asarray(res.valid, dtype=bool) & np.isfinite(eps)
    model = np.where(good, "analytic", "")
    redo = np.flatnonzero(~good)
    eps[redo] = np.nan
    if redo.size:
        eps_full, ok = full_velocity(dbeta[redo], force[redo], bearing, groove_velocity)
        eps[redo[ok]] = eps_full[ok]
        model[redo[ok]] = "full"
    return eps.reshape(shape), model.reshape(shape)


def solve_config_carriage(config) -> CarriageResult:
    """Solve the nominal carriage assembly of a config with ``[carriage]``.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        With ``config.carriage`` set.

    Returns
    -------
    CarriageResult

    Raises
    ------
    ValueError
        A config without ``[carriage]``; a load the track layout cannot carry; a carriage
        that lifts off (messages from :func:`tolsim.physics.carriage.solve_carriage`).
    """
    carriage = config.carriage
    if carriage is None:
        raise ValueError(f"{config.path} has no [carriage] section")
    solution = solve_carriage(carriage.layout, carriage.load, config.bearing,
                              oversize=carriage.oversize)
    eps, model = ball_velocity_deviation(solution, config.bearing,
                                         config.motion.groove_velocity)
    return CarriageResult(solution, eps, model)


__all__ = ["CarriageResult", "ball_velocity_deviation", "solve_config_carriage"]
