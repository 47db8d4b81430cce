"""Registry of ball-velocity models: name -> function.

Every entry has the signature ``model(contact_angle_deviation, normal_force, bearing=TABLE1,
**options) -> VelocityResult`` (:class:`tolsim.physics.velocity.analytic.VelocityResult`);
callers pick a model by name from here, never with an if/elif chain.
"""

import numpy as np

from tolsim.physics.velocity import analytic
from tolsim.physics.velocity import full as friction
from tolsim.physics.velocity._regime_kernels import REGIME_SMOOTH, REGIME_UNSOLVED

#: Codes of the model that gave a ball's epsilon in a study (``BallState.model``): a fast
#: model (``eq24``/``analytic``), the full model (a re-solve), or none (unresolved).
MODEL_FAST, MODEL_FULL, MODEL_UNRESOLVED = 0, 1, -1

#: Codes of a ball's regime in a study (``BallState.regime``, issue 25): unresolved (no
#: model solved it), four-point with every contact slipping (regime A), four-point with one
#: contact stuck (regime B), three-point, two-point (two opposite contacts, rolling at v/2),
#: unloaded (no loaded contact: no epsilon of its own, pushed along by its neighbours).
(BALL_UNRESOLVED, BALL_REGIME_A, BALL_REGIME_B, BALL_THREE_POINT, BALL_TWO_POINT,
 BALL_UNLOADED) = -1, 0, 1, 2, 3, 4
#: code -> CF flag meaning (``flag_meanings`` of the ``ball_regime`` coordinate).
BALL_REGIMES = {BALL_UNRESOLVED: "unresolved", BALL_REGIME_A: "four_point_regime_A",
                BALL_REGIME_B: "four_point_regime_B", BALL_THREE_POINT: "three_point",
                BALL_TWO_POINT: "two_point", BALL_UNLOADED: "unloaded"}
#: code -> the short label shown by ``tolsim carriage``, ``tolsim ball`` and the reports.
BALL_REGIME_LABELS = {BALL_UNRESOLVED: "unresolved", BALL_REGIME_A: "A",
                      BALL_REGIME_B: "B", BALL_THREE_POINT: "3-point",
                      BALL_TWO_POINT: "2-point", BALL_UNLOADED: "unloaded"}

def ball_regime(normal_force, full_regime):
    """The :data:`BALL_REGIMES` code of balls solved by the full model.

    Parameters
    ----------
    normal_force : ndarray, shape (n, 4)
        F_i [N] (>= 0; a zero force is an open contact).
    full_regime : ndarray of int, shape (n,)
        :attr:`tolsim.physics.velocity.full.FullResult.regime` (0 unsolved, 1 all slip,
        2 one contact stuck, 3 exactly two-point).

    Returns
    -------
    ndarray of int8, shape (n,)
        Four loaded contacts: A or B by ``full_regime``; three: three-point; two:
        two-point; none: unloaded; unresolved where ``full_regime`` is 0 (a ball with one
        loaded contact is unresolved too).
    """
    force = np.asarray(normal_force)
    count = np.count_nonzero(force > 0.0, axis=-1)
    code = np.asarray(full_regime)
    out = np.select([count == 0, code == REGIME_UNSOLVED, count == 4, count == 3, count == 2],
                    [BALL_UNLOADED, BALL_UNRESOLVED,
                     np.where(code == REGIME_SMOOTH, BALL_REGIME_A, BALL_REGIME_B),
                     BALL_THREE_POINT, BALL_TWO_POINT], BALL_UNRESOLVED)
    return out.astype(np.int8)


MODELS = {
    "eq24": analytic.eq24,
    "analytic": analytic.analytic,
    "point": analytic.point,
    "full": friction.full,
}


#: What ``valid == False`` means for each model (shown to users next to the flag).
VALIDITY_NOTES = {
    "eq24": (f"outside Eq. (24)'s error budget ({100 * analytic.VALIDITY_ERROR_BUDGET:g} pp "
             "against the full model): a zero force, diagonal force ratio < "
             f"{analytic.MIN_DIAGONAL_FORCE_RATIO:g}, |dbeta| > "
             f"{np.rad2deg(analytic.MAX_ANGLE_DEVIATION):g} deg, pairing asymmetry > "
             f"{analytic.MAX_PAIRING_ASYMMETRY:g} or |eps| > "
             f"{100 * analytic.MAX_EQ24_VELOCITY_DEVIATION:g} %; a study re-solves such "
             "balls with the full model"),
    "analytic": (f"outside the linearised model's error budget "
                 f"({100 * analytic.VALIDITY_ERROR_BUDGET:g} pp against the full model): a "
                 f"zero force, |c/a| > {analytic.MAX_ZERO_VELOCITY_RATIO:g} or |dbeta + dgamma| "
                 f"> {np.rad2deg(analytic.MAX_ANGLE_SUM):g} deg at some contact, or |eps| > "
                 f"{100 * analytic.MAX_VELOCITY_DEVIATION:g} %; a study re-solves such balls "
                 "with the full model"),
    "point": "point model undetermined: no sliding contact keeps the others inside their "
             "friction cones, or two candidates tie (equal diagonal forces)",
    "full": "full friction model found no certified minimum of the dissipated power (fewer "
            "than two loaded contacts, two that are not opposite, or the solver failed)",
}


def register(name, func, validity_note=""):
    """Add a model to the registry (used by modules that are imported lazily)."""
    MODELS[name] = func
    VALIDITY_NOTES[name] = validity_note
    return func


def get_model(name):
    """Return the model called ``name``; raise ValueError listing the known ones."""
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; choose one of {sorted(MODELS)}") from None
