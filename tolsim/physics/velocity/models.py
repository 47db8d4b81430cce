"""Registry of ball-velocity models: name -> function.

Every entry has the signature ``model(contact_angle_deviation, normal_force, bearing=TABLE1,
**options) -> VelocityResult`` (:class:`tolsim.physics.velocity.analytic.VelocityResult`);
callers pick a model by name from here, never with an if/elif chain.
"""

import numpy as np

from tolsim.physics.velocity import analytic
from tolsim.physics.velocity import full as friction

#: Codes of the model that gave a ball's epsilon in a study (``BallState.model``): a fast
#: model (``eq24``/``analytic``), the full model (a re-solve), or none (unresolved).
MODEL_FAST, MODEL_FULL, MODEL_UNRESOLVED = 0, 1, -1

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
