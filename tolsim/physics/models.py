"""Registry of ball-velocity models: name -> function.

Every entry has the signature ``model(contact_angle_deviation, normal_force, bearing=TABLE1,
**options) -> VelocityResult`` (:class:`tolsim.physics.analytic.VelocityResult`); callers pick
a model by name from here, never with an if/elif chain.
"""

from tolsim.physics import analytic, friction

MODELS = {
    "eq24": analytic.eq24,
    "analytic": analytic.analytic,
    "point": analytic.point,
    "full": friction.full,
}


#: What ``valid == False`` means for each model (shown to users next to the flag).
VALIDITY_NOTES = {
    "eq24": "outside Eq. (24)'s regime: a zero force, diagonal force ratio < 0.25 or "
            "|dbeta| > 3 deg",
    "analytic": "outside the linearised model's regime: a zero force, |c/a| > 0.5 or "
                "|dbeta + dgamma| > 3 deg at some contact",
    "point": "point model undetermined: no sliding contact keeps the others inside their "
             "friction cones, or two candidates tie (equal diagonal forces)",
    "full": "full friction model did not converge (or a contact carries no force)",
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
