"""Refuse a study that cannot answer: every train of its first block unresolved (issue 26).

:func:`check_answerable` is called by :func:`tolsim.study.execution.runner.run_study` (with
``require_answer``, as ``tolsim run`` does) after the first block of assemblies is merged.
"""

import tomllib

from tolsim.study.pipeline.carriage import solve_config_carriage


class UnanswerableStudy(ValueError):
    """Every train of the first block is unresolved: the study cannot estimate P(contact).

    The message is one line: the config, the cause (lift-off, loss of contact, loads beyond a
    limit of the models) and the config keys to change.
    """


def _key_values(config, section: str) -> list:
    """``section.key = value`` of every number in ``section`` (dotted) of the config's TOML
    text, as written (the user's units)."""
    try:
        table = tomllib.loads(config.text) if config.text else {}
    except tomllib.TOMLDecodeError:
        table = {}
    for part in section.split("."):
        table = table.get(part, {}) if isinstance(table, dict) else {}
    out = []
    for key, value in table.items() if isinstance(table, dict) else ():
        if isinstance(value, int | float | list) and not isinstance(value, bool):
            out.append(f"{section}.{key} = {value!r}")
    return out


def _load_keys(config) -> str:
    """The config keys that set the balls' loads, as written, for the message."""
    if config.has_carriage:
        keys = _key_values(config, "carriage.load")
        keys += [k for k in _key_values(config, "carriage")
                 if k.startswith("carriage.preload_oversize_")]
        default = "carriage.load (vertical_N, lateral_N, pitch/yaw/roll_moment_N_m) or " \
                  "carriage.preload_oversize_um"
    else:
        keys = _key_values(config, "loads")
        default = "loads (normal_load_N, side_load_N, side_force_ratio, yaw_moment_N_m)"
    return ", ".join(keys) if keys else default


def check_answerable(config, statistics) -> None:
    """Raise :class:`UnanswerableStudy` if no train of ``statistics`` (the merged first block)
    is resolved.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
    statistics : tolsim.study.statistics.accumulator.Accumulator
        The statistics after the first block of ``config.study.block_size`` assemblies.

    Raises
    ------
    UnanswerableStudy
        If every train is unresolved, naming the cause and the keys to change.

    Notes
    -----
    The decision is made on the first block, not the whole run: if none of its N trains
    resolves, the fraction of resolvable trains is below 3 / N at 95 % confidence (the rule
    of three; N = 1024 by default), and the bounds on P(contact), which count the unresolved
    trains as no contact and as contact, span nearly [0, 1] however many assemblies follow.

    The cause is the carriage solver's own classification where there is a carriage: the
    nominal assembly is solved by :func:`tolsim.study.pipeline.carriage.solve_config_carriage`,
    the function behind ``tolsim carriage``, and if that refuses the load (the carriage lifts
    off, or a load the tracks cannot carry), its message is the cause. Otherwise the cause is
    what most balls of the block had: a contact force <= 0 (loss of contact), a static model
    that did not converge, or no velocity model that takes them (loads beyond the models'
    limits). A carriage pressed onto the rail with clearance (negative preload) is not lift-off
    unless the solver says so.
    """
    n = int(statistics.n_assemblies)
    if n == 0 or int(statistics.n_unresolved) < n:
        return
    head = f"{config.path}: the study cannot answer: "
    what = (f"no assembly of the first block ({n:,} assemblies) resolves" if config.has_carriage
            else f"no train of the first block ({n:,} assemblies) resolves")
    keys = _load_keys(config)
    if config.has_carriage:
        try:
            solve_config_carriage(config)
        except ValueError as exc:  # the solver's lift-off (or a load it cannot carry)
            raise UnanswerableStudy(f"{head}{exc} (the carriage solver, nominal assembly), "
                                    f"and {what}; change {keys}") from None
        if int(statistics.carriage_count) == 0:
            raise UnanswerableStudy(f"{head}{what}: the carriage solver solves none of its "
                                    f"carriages (each lifts off or does not converge); "
                                    f"change {keys}")
    balls = int(statistics.n_balls)
    counts = {
        "loss": int(statistics.n_loss_of_contact),
        "static": int(statistics.n_not_converged),
        "full": int(statistics.n_full_failed),
    }
    cause = max(counts, key=counts.get)
    share = f"{counts[cause]:,} of {balls:,} balls"
    reason = {
        "loss": f"loss of contact: {share} have a contact force <= 0 under the load",
        "static": f"loads beyond a limit: the static contact model does not converge for "
                  f"{share}",
        "full": f"loads beyond a limit: {share} are outside the fast model's validity and "
                "the full model gives no value either",
    }[cause]
    raise UnanswerableStudy(f"{head}{what} ({reason}); change {keys}")


__all__ = ["UnanswerableStudy", "check_answerable"]

