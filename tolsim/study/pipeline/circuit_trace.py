"""The balls of one assembly's circuits over the stroke, for the circuit figure (issue 24).

:func:`trace_circuit` runs one assembly of a ``[carriage.circuit]`` study through the one
along-track loop (the frame and the contacts of
:func:`tolsim.study.pipeline.carriage_circuit.first_contact_carriage_circuit`) with a
:class:`CircuitTrace`, which records every ball's place round its circuit after every step;
:func:`tolsim.reports.carriage.plot_circuit` draws it (``tolsim carriage CONFIG
--circuit-figure FILE.png``).
"""

from dataclasses import dataclass

import numpy as np

from tolsim.study.pipeline.carriage_circuit import (
    WHERE_NAMES,
    CircuitContact,
    CircuitFrame,
)
from tolsim.study.pipeline.propagation import StepObserver, integrate
from tolsim.study.sampling import sample_block


@dataclass(frozen=True)
class CircuitTraceResult:
    """One assembly's circuits over the stroke (S steps, T tracks, N balls per circuit).

    Attributes
    ----------
    travel : ndarray (S + 1,)
        Carriage travel at the start and after each step [m].
    position : ndarray (S + 1, T, N)
        Each ball's place round its circuit, sigma mod L_c [m]: 0 at the entry of the
        loaded zone (its leading end), L_z at its exit (the trailing end), then the trailing
        turnaround, the return channel and the leading turnaround back to L_c; ring order
        (the direction of flow).
    loaded, closed : ndarray of bool (S + 1, T, N)
        The ball is in the loaded zone; its pair with the next ball round the circuit is
        in contact.
    ball_id : ndarray of int (N,)
        Study id of each ring ball (:func:`tolsim.study.pipeline.carriage_circuit.
        circuit_ball_ids`).
    diameter : ndarray (T, N)
        The balls' diameters [m].
    length : ndarray (T,)
        L_c [m].
    zone_length : float
        L_z [m].
    events : dict of ndarray
        One entry per contact event: ``track``, ``pair`` (the ring ball behind), ``where``
        (index into ``where_names``), ``travel`` [m] and ``position`` (sigma mod L_c of
        the contact point, between the two balls, interpolated within the step) [m].
    where_names : tuple of str
        :data:`tolsim.study.pipeline.carriage_circuit.WHERE_NAMES`.
    first_contact_travel : float
        The study's first contact between loaded balls [m] (inf: none in the stroke).
    column_force : ndarray (S, T, 2)
        Column force at the zone's entry and exit at the end of each step [N].
    slack, return_drag : float
        The circuit's [m] and [N].
    seed : int or None
        The study seed of the assembly (None: the config's).
    """

    travel: np.ndarray
    position: np.ndarray
    loaded: np.ndarray
    closed: np.ndarray
    ball_id: np.ndarray
    diameter: np.ndarray
    length: np.ndarray
    zone_length: float
    events: dict
    where_names: tuple
    first_contact_travel: float
    column_force: np.ndarray
    slack: float
    return_drag: float
    seed: int | None


class CircuitTrace(StepObserver):
    """Records the circuits of assembly ``row`` of a :class:`tolsim.study.pipeline.
    carriage_circuit.CircuitFrame` after every step (it follows no row of its own)."""

    def __init__(self, frame, row=0):
        self.frame, self.row = frame, int(row)
        self.lines = self.row * frame.tracks + np.arange(frame.tracks)

    def _record(self, travel):
        f, lines = self.frame, self.lines
        self.sigma = f.sigma[lines].copy()  # unwrapped, at the end of the last step
        self.travel.append(travel)
        self.position.append(np.mod(f.sigma[lines], f.length[lines, None]))
        self.loaded.append(f.ring_loaded[lines].copy())
        self.closed.append(f.ring_closed[lines].copy())

    def begin(self, block, position):
        self.travel, self.position, self.loaded, self.closed = [], [], [], []
        self.events = {k: [] for k in ("track", "pair", "where", "travel", "position")}
        self.column = []
        self._record(0.0)

    def following(self):
        return False

    def moved(self, step):
        where = np.flatnonzero(step.rows == self.row)
        if where.size == 0:
            return
        f, tracks = self.frame, self.frame.tracks
        start, before = f.v * step.t, self.sigma
        self._record(f.v * (step.t + step.dt))
        circuit = step.circuit
        lines = where[0] * tracks + np.arange(tracks)
        self.column.append(circuit["column"][lines, :2])
        after, length = self.sigma, f.length[self.lines]
        diameter = f.diameter_ring[self.lines]
        for track, line in enumerate(lines):
            pairs = circuit["pair"][line]
            for k in np.flatnonzero(pairs >= 0):
                ring = int(pairs[k])
                # the ball behind at the event's travel (linear within the step)
                frac = (circuit["travel"][line, k] - start) / (f.v * step.dt)
                sigma = before[track, ring] + frac * (after[track, ring] - before[track, ring])
                point = sigma + 0.5 * diameter[track, ring]
                self.events["track"].append(track)
                self.events["pair"].append(ring)
                self.events["where"].append(int(circuit["where"][line, k]))
                self.events["travel"].append(float(circuit["travel"][line, k]))
                self.events["position"].append(float(np.mod(point, length[track])))


def trace_circuit(config, seed=None) -> CircuitTraceResult:
    """The first assembly of a ``[carriage.circuit]`` study over its stroke.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        With ``[carriage.circuit]`` (along the track); its ``study.time_steps``.
    seed : int, optional
        The assembly is the first of ``tolsim run CONFIG --seed SEED`` (default: the
        config's seed): the same draws and the same integration as in the study.

    Returns
    -------
    CircuitTraceResult
    """
    if config.carriage is None or config.carriage.circuit is None:
        raise ValueError(f"{config.path} has no [carriage.circuit] section")
    first = config.with_overrides(samples=1, seed=seed)
    frame = CircuitFrame(first, sample_block(first, 0))
    contact = CircuitContact(frame)
    trace = CircuitTrace(frame)
    integrate(first, frame, [contact, trace])
    events = {k: np.asarray(v, dtype=np.int64 if k in ("track", "pair", "where") else float)
              for k, v in trace.events.items()}
    circuit = config.carriage.circuit
    tracks = frame.tracks
    return CircuitTraceResult(
        travel=np.asarray(trace.travel), position=np.asarray(trace.position),
        loaded=np.asarray(trace.loaded), closed=np.asarray(trace.closed),
        ball_id=frame.ring_id.copy(), diameter=frame.diameter_ring[:tracks].copy(),
        length=frame.length[:tracks].copy(), zone_length=float(frame.zone), events=events,
        where_names=WHERE_NAMES,
        first_contact_travel=float(frame.v * contact.time[0]),
        column_force=np.asarray(trace.column).reshape(-1, tracks, 2),
        slack=float(circuit.slack), return_drag=float(circuit.return_drag), seed=seed)


__all__ = ["CircuitTrace", "CircuitTraceResult", "trace_circuit"]
