"""What each propagation model assumes, and how finely ``along_track`` steps.

The one-sentence assumption of each model and the caveats of a study whose model misses
what changes along the track (summary, report, the file's attributes), and the automatic
step count of :func:`tolsim.study.pipeline.propagation.integrate` from the lengths over
which a ball's epsilon changes.
"""

from dataclasses import replace

import numpy as np

#: What each propagation model assumes, in one sentence (summary, report, netCDF attribute).
PROPAGATION_ASSUMPTIONS = {
    "constant": ("constant: each ball keeps the epsilon of its position at the start of the "
                 "stroke (the paper's Fig. 9); rail errors along the track and the load "
                 "distribution of the carriage do not change it"),
    "along_track": ("along_track: epsilon is re-evaluated as each ball rolls past the rail "
                    "errors and through the carriage's load distribution (midpoint rule, "
                    "study.time_steps steps)"),
}


def propagation_assumption(propagation: str, steps: int | None = None,
                           automatic: bool = False, reason: str = "") -> str:
    """The one-sentence assumption of a propagation model (:data:`PROPAGATION_ASSUMPTIONS`),
    with the number of steps of an ``along_track`` study when ``steps`` is given
    (:func:`time_steps`), and whether that number is the automatic one (``automatic``:
    ``study.time_steps = "auto"``, with ``reason``, :func:`fine_step_reason`, if any) or the
    config's."""
    text = PROPAGATION_ASSUMPTIONS[propagation]
    if steps is not None and propagation == "along_track":
        why = f" ({reason})" if reason else ""
        count = (f'{int(steps)} steps chosen automatically{why}: study.time_steps = "auto"'
                 if automatic else f"{int(steps)} steps (study.time_steps)")
        text = text.replace("study.time_steps steps", count)
    return text


#: Automatic ``study.time_steps``: steps per shortest length over which a ball's epsilon
#: changes (:func:`time_steps`, which gives the measurements): free balls.
STEPS_PER_LENGTH = 4.0
#: The same for a carriage, with or without ``[carriage.circuit]``, whose entering balls are
#: in the midpoint solve from their entry and move at their own epsilon from it.
STEPS_PER_LENGTH_CARRIAGE = 2.0
#: The same for a carriage with an end relief (balls unload and reload within it, and most
#: first contacts form there) or a light preload (:func:`light_preload`).
STEPS_PER_LENGTH_RELIEF = 8.0
#: A carriage's preload is light (:func:`light_preload`) when its nominal assembly has a
#: contact below this fraction of its largest contact force, open ones included.
LIGHT_PRELOAD_CONTACT = 0.1
#: The same with ``[contact]`` (the friction figures' extremes are taken over step means),
#: except with ``[carriage.circuit]``, whose step gives them between its events.
STEPS_PER_LENGTH_CONTACT = 40.0
#: The fewest automatic steps over the stroke.
MIN_TIME_STEPS = 8
#: The most integration steps of an ``along_track`` study, given (``study.time_steps``) or
#: automatic. A step of a block costs about a millisecond (free balls; a carriage several),
#: so 10^5 steps take minutes per block; the automatic count passes it only for a length far
#: below the balls' contacts (a rail field's correlation length of 1e-30 mm gave 2e32 steps,
#: and the study ran on without end).
MAX_TIME_STEPS = 100_000


def epsilon_lengths(config) -> dict:
    """The lengths over which a ball's epsilon changes as it rolls [m], by cause: the
    correlation length of each rail random field (read at the ball's rail position), and the
    load distribution read at its carriage position: a carriage's ball pitch (a ball enters
    or leaves the loaded zone every pitch of travel, and the load distribution jumps) and its
    end relief length, or the slot spacing of a train whose loads vary from ball to ball."""
    out = {f"rail field {t.source}": t.correlation_length for t in config.tolerances
           if t.scope == "rail" and t.correlation_length > 0 and t.distribution.is_random}
    if config.carriage is not None:
        out["ball pitch"] = config.carriage.layout.ball_pitch
        if config.carriage.end_relief_length > 0:
            out["end relief"] = config.carriage.end_relief_length
    elif config.train.balls > 1 and (len(set(np.atleast_1d(config.loads.side_load))) > 1
                                     or len(set(np.atleast_1d(config.loads.normal_load))) > 1):
        slots = config.train.slot_positions(2.0 * config.bearing.ball_radius)
        out["ball spacing"] = float(slots[1] - slots[0])
    return out


def time_steps(config) -> int:
    """The integration steps of an ``along_track`` study over its horizon:
    ``study.time_steps`` when the config gives a number, else (``"auto"``, the default) the
    automatic count of the Notes.

    Notes
    -----
    A ball moves along the rail and through the carriage at about v / 2, so over the stroke
    s it travels s / 2 in either frame, and its epsilon changes over the lengths l of
    :func:`epsilon_lengths`. The automatic step lets a ball travel 1 / c of the shortest of
    them: n = max(:data:`MIN_TIME_STEPS`, ceil(c (s / 2) / l_min)), with c =
    :data:`STEPS_PER_LENGTH` (4) for free balls, :data:`STEPS_PER_LENGTH_CARRIAGE` (2) for a
    carriage (with or without ``[carriage.circuit]``), :data:`STEPS_PER_LENGTH_RELIEF` (8) for
    a carriage with an end relief or a light preload (:func:`light_preload`), and
    :data:`STEPS_PER_LENGTH_CONTACT` (40) with ``[contact]`` unless the carriage has a
    circuit (which keeps its own c); :data:`MIN_TIME_STEPS` without any length (epsilon then
    changes only through the unloaded balls, the trains after contact, or not at all).

    The factors come from ``benchmarks/convergence_along_track.py`` (each config's seed,
    paired against a fine-step reference on the same assemblies, 600 assemblies, reference
    800 steps). P(contact) lay inside its own 95 % interval from 5 steps on everywhere.
    c = 4 gives 20 steps on ``configs/whatif_along_track.toml`` (the 10.05 mm ball spacing
    of its yaw-moment loads; its rail field: 20 mm): the paired change against the
    reference (assemblies that touch only at n / only in the reference) was +2/-5, the mean
    change of the time to first contact 8.1 ms of a 500 ms stroke (27 ms at 10 steps, 0.43
    ms at 40): second order. It gave 42 steps on ``configs/carriage_circuit.toml`` (4.8 mm
    pitch; +3/-5, 4.5 ms; 12 and 3.5 ms at 10 and 40 steps) while a circuit's balls entered
    at the step ends (first order). A carriage without a circuit
    solves its midpoint with the balls that have entered by then and moves an entering ball
    at its own epsilon from its entry (Notes of :func:`tolsim.study.pipeline.carriage_track.
    first_contact_carriage_track`, "Entry"), so its error falls at second order between the
    exits and entries: on ``configs/carriage_preload.toml`` (10.05 mm pitch) the mean change
    was 37, 7.0, 2.9 and 0.86 ms at 5, 10, 20 and 40 steps (+18/-9, +5/-8, +1/-3, +0/-0),
    where entering balls solved from the next step and moving with the ball ahead gave
    18, 10 and 4.4 ms at 10, 20 and 40 steps (+18/-11, +9/-5, +2/-3): first order. Hence
    c = 2 there (10 steps, more accurate than the former 20). A circuit's midpoint holds the
    ring balls that have entered by then too, and they move at their own epsilon from their
    entry (Notes of :func:`tolsim.study.pipeline.carriage_circuit.
    first_contact_carriage_circuit`, "Entry"); on ``configs/carriage_circuit.toml`` the mean
    change was 27, 2.4, 2.35 and 1.6 ms at 10, 21, 42 and 84 steps (+16/-23, +4/-0, +3/-0,
    +0/-1), where the entering balls taken with the ball ahead's epsilon, outside the midpoint's
    solve, gave 12, 4.5 and 3.5 ms at 10, 42 and 40 steps (+10/-10, +3/-5, +3/-4); on
    ``configs/carriage_preload.toml`` with a default circuit (``--configs carriage_preload
    --circuit``) 1.8, 1.1 and 0.37 ms at 10, 20 and 40 steps (+0/-0 each) against 3.7, 0.99 and
    0.38 ms (+4/-1, +2/-1, +0/-1) before. Hence c = 2 for a circuit too (21 and 10 steps,
    against 42 and 20 at c = 4). Below two steps per pitch the midpoint's entering balls do
    harm: on ``carriage_circuit.toml`` at 10 steps (a pitch per step) 27 ms (+16/-23) against 12
    ms (+10/-10) with the midpoint solved without them, since a ball predicted in by the
    midpoint may enter only at the step's end and the others are then solved with it for
    most of the step; at 21 steps they make 2.4 ms (+4/-0) of 13 ms (+8/-8). (The entering
    balls' late entries made up in the next step and the pushed-in pairs timed at their
    entry moved these figures by less than 0.02 ms. On ``carriage_preload.toml`` with a
    circuit every entry of 100 assemblies fell in the first fifth of its step, 95 % of them
    predicted by the midpoint: the balls start a pitch apart and a step is half a pitch, so
    the entries keep their phase. On the gaps of a small carriage with the preload
    alone they matter: 4.9e-7 m from a 320-step run at 10 steps with them, 4.9e-6 m
    without (``tests/study/test_circuit_entry.py``).)

    A light preload converges as slowly as a relief. Where the preload leaves a contact of the
    nominal carriage light or open (:func:`light_preload`), the tolerances open and close
    contacts along the track: balls cross between regimes A, B, three- and two-point as they
    roll through the zone and past its ends, and most first contacts of a circuit form at
    the ends. With c = 2 the error fell at first order, and P(contact) of a circuit lay
    outside its own interval, too low. ``configs/carriage_preload.toml`` at 0, 0.5 and 1 um of
    preload oversize (4 000 assemblies, seed 12, paired against 400 steps; session 30):

    * with a default circuit, P = 0.0732 [0.0654, 0.0818] at 10 steps against 0.0828
      (+26/-64, mean change of the first contact 34.6 ms), 0.0810 at 40 (+11/-18, 6.3 ms);
      at 0.5 um 0.4145 [0.3992, 0.4299] against 0.4517 (+145/-294, 27.6 ms), 0.4467 at 40
      (+60/-80, 7.1 ms); at 1 um 0.9922 and 0.9935 against 0.9930 (9.1 and 3.3 ms);
    * open, P inside its interval at 10 steps, the first contacts off by 27.2, 18.7 and 31.7
      ms on average at 10 steps, 7.1, 4.2 and 9.4 ms at 40.

    Hence c = 8 for them too (40 steps). At 1.5 um (lightest nominal contact 0.185 of the
    largest) the circuit had every figure inside at 10 steps (P 0.9280 against 0.9277, 2.1 ms)
    and the open trains P (0.3882 against 0.3857, 9.6 ms); so has the shipped 2 um. (The open
    trains' fraction of first contacts at the zone's ends had a first-order step error of its
    own, at every preload, until session 30: a contact in a step in which the trailing ball
    had left was given its slot's pair, one too far forward, since exits are applied at the
    step's end. Counted among the balls in the zone at the contact
    (:func:`~tolsim.study.pipeline.carriage_track_kernels.first_contact_kernel`), it lies
    inside its interval at 10 steps: 0.197 against 0.187 at 400 steps at 2 um, 0.123 against
    0.128 at 1 um, where it was 0.218 and 0.188 before.)

    With ``[contact]`` the largest increase and the ripple are extremes of step-mean friction
    forces, which converge at first order from below: on the free balls (1 000 assemblies)
    the ripple was 0.1711 N at 40 steps against 0.1737 N at 400, outside its own (narrow,
    +-0.0007 N) interval, and 0.1734 N at 200 steps against 0.1739 N at 800, inside; hence
    c = 40 (200 steps there, the former fixed default). On the open carriage the mean
    increase is inside its interval from 10 steps and the largest from 40 (0.00056, 0.00062
    and 0.00067 N at 10, 20 and 40 steps against 0.00074 N), and the ripple, its extremes
    taken over every zone of the steps in which a ball leaves or enters (Notes of
    :class:`tolsim.study.pipeline.track_friction.TrackFriction`, "Windows"), from 10 steps:
    0.1490, 0.1488 and 0.1489 N at 10, 40 and 200 steps against 0.1489 N [0.1466, 0.1511]
    at 800 (before the windows it did not converge: 0.148 N at 10 steps and 0.165 N at 200
    against 0.178 N at 800).

    A circuit's step gives its friction between its events (Notes of
    :class:`tolsim.study.pipeline.circuit_friction.CircuitTrains`, "Intervals"), and its
    sliding check takes each interval's forces
    (:meth:`~tolsim.study.pipeline.circuit_friction.CircuitTrains.interval_slides`), so with
    ``[contact]`` it keeps its own c (2, or 8 with a relief). Paired against 800 steps (300
    assemblies): ``configs/carriage_circuit.toml`` at 21 steps (c = 2) had every friction
    figure inside its interval (baseline 1.147 N, largest increase 0.02716 against 0.02711
    N, mean increase 0.02393 against 0.02394 N, ripple 0.1742 against 0.1744 N) and P =
    0.610 against 0.600 (+3/-0), at 10 steps the increases outside (0.02692 and 0.02387 N);
    ``configs/carriage_preload.toml`` with a default circuit at 10 steps (c = 2) every
    figure inside (ripple 0.3198 against 0.3198 N, largest increase 0.2070 against 0.2072 N)
    and P +0/-0; with 1 um / 15 mm of end relief too (``--relief 1 15``) at 40 steps (c = 8)
    every figure inside (ripple 0.2491 against 0.2500 N, largest increase 0.2035 against
    0.2044 N [0.2026, 0.2045]) and P 0.870 against 0.877 (+0/-2). They took c = 40 before
    (417, 200 and 200 steps). The sliding check on the steps' mean forces alone missed
    pushes shorter than a step: with a return drag of 1 N per ball (200 assemblies) 12
    trains slid at 10 steps against 197 at 200; on the intervals' forces 200 at 10, 40 and
    200 steps (0.5 N: 92 at 10 steps against 89 at 200, where 13 more were unresolved by a
    step with more than 16 intervals, since raised to 64).

    An end relief converges slowly: its balls unload near the zone's ends and load again, and
    most first contacts form there. ``configs/carriage_preload.toml`` with 1 um / 15 mm of
    relief (2 000 assemblies, seed 12): P(contact) 0.4465, 0.5315, 0.5520, 0.5580 and 0.5595
    at 10, 20, 40, 80 and 400 steps; 20 steps lie outside the 400-step reference's interval
    [0.5374, 0.5814] and 40 inside it, hence c = 8 (40 steps). Entering balls solved from the
    next step and moving with the ball ahead needed 200 steps (0.4845, 0.5275, 0.5430, 0.5545
    and 0.5560 at 20, 40, 80, 200 and 400), as a circuit with a relief did (c = 40) before
    its midpoint held its entering balls. With them, that relief and a default circuit
    (``--circuit --relief 1 15``, 600 assemblies, against 800 steps, P = 0.8700) gave 0.8650,
    0.8650, 0.8700 and 0.8700 at 20, 40, 80 and 200 steps (+0/-3, +0/-3, +0/-0, +0/-0; mean
    change 0.86, 0.43, 0.06 and 0.03 ms), against 0.8683, 0.8667, 0.8700 and 0.8700 (+2/-3,
    +0/-2, 0, 0; 1.4, 0.50, 0.07 and 0.05 ms) before: c = 8 for a circuit too.
    """
    if config.study.time_steps is not None:
        return int(config.study.time_steps)
    count = automatic_step_count(config)
    if not count <= MAX_TIME_STEPS:
        raise ValueError(f"the automatic step count {count:.3g} exceeds MAX_TIME_STEPS = "
                         f"{MAX_TIME_STEPS} (check_step_count names the length)")
    return _whole_steps(count)


def _whole_steps(count) -> int:
    """The automatic step count of an unrounded one (:func:`automatic_step_count`): at least
    :data:`MIN_TIME_STEPS`, rounded up (a count within 1e-12 of a whole number is that
    number)."""
    return max(MIN_TIME_STEPS, int(np.ceil(count * (1 - 1e-12))))


def steps_per_length(config) -> float:
    """The automatic steps per shortest length c of :func:`time_steps` (its Notes)."""
    carriage = config.carriage
    if config.contact is not None and (carriage is None or carriage.circuit is None):
        return STEPS_PER_LENGTH_CONTACT
    if carriage is not None:
        fine = carriage.end_relief_depth > 0 or light_preload(config)
        return STEPS_PER_LENGTH_RELIEF if fine else STEPS_PER_LENGTH_CARRIAGE
    return STEPS_PER_LENGTH


def fine_step_reason(config) -> str:
    """Why a carriage's automatic step is the finer one of :data:`STEPS_PER_LENGTH_RELIEF`
    (an end relief, a light preload), for the propagation assumption; "" otherwise."""
    carriage = config.carriage
    if carriage is None or steps_per_length(config) != STEPS_PER_LENGTH_RELIEF:
        return ""
    if carriage.end_relief_depth > 0:
        return "the finer steps of an end relief"
    return (f"the finer steps of an end relief, for a light preload: a contact of the nominal "
            f"carriage below {LIGHT_PRELOAD_CONTACT:g} of its largest")


def light_preload(config) -> bool:
    """Whether a carriage's preload leaves a contact of its nominal assembly (no tolerances,
    :func:`tolsim.physics.carriage.solve_carriage`, about 0.5 ms) below
    :data:`LIGHT_PRELOAD_CONTACT` of the largest contact force, open ones included; True
    also when the nominal assembly has no solution (a lift-off), the cautious side. Such a
    carriage takes :data:`STEPS_PER_LENGTH_RELIEF` (Notes of :func:`time_steps`).

    On ``configs/carriage_preload.toml`` (300 N, 2 N m) the lightest nominal contact is 0
    (every ball two-point) at 0, 0.25 and 0.5 um of preload oversize, 0.002 of the largest at 1
    um, 0.185 at 1.5 um, 0.359 at 2 um (as shipped) and 0.582 at 3 um.
    """
    from tolsim.physics.carriage import solve_carriage  # noqa: PLC0415 - config loading
    # imports this module, and the carriage's kernels are needed only here

    carriage = config.carriage
    try:
        solution = solve_carriage(carriage.layout, carriage.load, config.bearing,
                                  oversize=carriage.oversize)
    except ValueError:  # CarriageError: lift-off or failure
        return True
    force = np.asarray(solution.normal_force, dtype=float)
    largest = float(np.max(force)) if force.size else 0.0
    return not (largest > 0 and float(np.min(force)) >= LIGHT_PRELOAD_CONTACT * largest)


def automatic_step_count(config) -> float:
    """c (s / 2) / l_min of :func:`time_steps`, unrounded and unbounded (0 without any length
    of :func:`epsilon_lengths`; inf where it overflows)."""
    lengths = epsilon_lengths(config)
    if not lengths:
        return 0.0
    with np.errstate(over="ignore"):
        return float(np.float64(steps_per_length(config)) * (0.5 * config.motion.stroke)
                     / min(lengths.values()))


def check_step_count(config):
    """None if the automatic step count of ``config`` (along the track, ``study.time_steps``
    "auto") is at most :data:`MAX_TIME_STEPS`; else (cause, length [m], count, the shortest
    length that passes [m]): the cause of :func:`epsilon_lengths` that sets it."""
    if not config.is_along_track or config.study.time_steps is not None:
        return None
    count = automatic_step_count(config)
    if count <= MAX_TIME_STEPS:
        return None
    cause, length = min(epsilon_lengths(config).items(), key=lambda item: item[1])
    shortest = steps_per_length(config) * 0.5 * config.motion.stroke / MAX_TIME_STEPS
    return cause, length, count, shortest


def propagation_caveat(config) -> str:
    """A sentence for studies whose epsilon changes along the track but which use
    ``constant``: rail random fields (a rail-scope source with a correlation length) or loads
    that vary between the balls, and for a carriage the balls it follows beyond the loaded
    zone (always: its default is ``along_track``); for an ``along_track`` carriage without
    ``[carriage.circuit]``, that it ignores the circuit (issue 24). Empty otherwise."""
    if config.study.propagation != "constant":
        notes = []
        if config.carriage is not None and config.carriage.circuit is None:
            notes.append("This carriage study ignores the ball circuit: every ball that "
                         "enters the loaded zone is a fresh, independent draw with a fresh "
                         "gap, and nothing resists at the zone's ends (open trains). "
                         "[carriage.circuit] follows the balls round their circuit.")
        notes.append(_coarse_steps_caveat(config))
        return " ".join(n for n in notes if n)
    fields = [t.source for t in config.tolerances
              if t.scope == "rail" and t.correlation_length > 0 and t.distribution.is_random]
    if config.carriage is not None:
        return _constant_carriage_caveat(config, fields)
    loads = (len(set(np.atleast_1d(config.loads.side_load))) > 1
             or len(set(np.atleast_1d(config.loads.normal_load))) > 1)
    what = "loads that vary along the train"
    causes = ([f"rail random fields ({', '.join(fields)})"] if fields else []) + (
        [what] if loads else [])
    if not causes:
        return ""
    return (f"This study has {' and '.join(causes)}, so a ball's epsilon changes as it moves "
            "along the track; the constant propagation keeps each ball's starting value. "
            "propagation = \"along_track\" answers with the change included.")


def _coarse_steps_caveat(config) -> str:
    """A sentence when ``study.time_steps`` gives fewer steps than the automatic count (whose
    accuracy :func:`time_steps` documents); empty otherwise."""
    given = config.study.time_steps
    if given is None:
        return ""
    count = automatic_step_count(replace(config, study=replace(config.study, time_steps=None)))
    if count <= MAX_TIME_STEPS:
        auto = _whole_steps(count)
        if given >= auto:
            return ""
        steps = f"{auto} steps"
    else:  # (a length far below the contacts: "auto" is refused, MAX_TIME_STEPS)
        steps = f"{count:.3g} steps, beyond the most of {MAX_TIME_STEPS}"
    return (f"study.time_steps = {given} is coarser than the automatic step ({steps}, "
            "\"auto\"), whose step error was measured against a fine-step reference: the "
            "step error may move P(contact) and the first contacts beyond that (README, "
            "\"Step size\").")


def _constant_carriage_caveat(config, fields) -> str:
    """:func:`propagation_caveat` of a ``constant`` carriage study: the balls it follows
    beyond the loaded zone (issue 24)."""
    layout, n = config.carriage.layout, config.train.balls
    drift = 0.5 * config.motion.stroke  # a ball's travel through the carriage, at about v/2
    pitch = layout.ball_pitch if layout.ball_pitch > 0 else 2.0 * config.bearing.ball_radius
    leaving = min(drift / pitch, float(n))
    also = f", and it reads the rail random fields ({', '.join(fields)}) there" if fields else ""
    return (f"This carriage study uses constant propagation: it follows each ball over the "
            f"whole stroke at its starting epsilon, as if it stayed in the loaded zone. In the "
            f"{config.motion.stroke * 1e3:g} mm stroke the balls drift "
            f"{drift * 1e3:g} mm through the carriage, so about {leaving:.2f} of the {n} balls "
            f"per track (stroke / 2 / ball pitch) leave the loaded zone and are followed "
            f"beyond it, new balls enter unseen, and the load distribution a ball rolls "
            f"through is not re-read{also}. propagation = \"along_track\", the default of a "
            f"[carriage] study, follows the balls through the zone.")
