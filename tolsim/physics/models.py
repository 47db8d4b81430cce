"""Registry of ball-velocity models: name -> function.

Every entry has the signature ``model(contact_angle_deviation, normal_force, bearing=TABLE1,
**options) -> VelocityResult`` (:class:`tolsim.physics.analytic.VelocityResult`); callers pick
a model by name from here, never with an if/elif chain.
"""

from tolsim.physics import analytic

MODELS = {
    "eq24": analytic.eq24,
    "analytic": analytic.analytic,
    "point": analytic.point,
}


def register(name, func):
    """Add a model to the registry (used by modules that are imported lazily)."""
    MODELS[name] = func
    return func


def get_model(name):
    """Return the model called ``name``; raise ValueError listing the known ones."""
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; choose one of {sorted(MODELS)}") from None
