r"""The recirculating ball circuit of one carriage track (issue 24): its state and one step.

A carriage holds each track's balls in a closed circuit: the loaded zone, a turnaround in
each end cap and an unloaded return channel. The balls keep their order and their sizes, and
the circuit's total clearance (its *slack*) is fixed when it is filled. This package moves the
balls of many circuits by one step of carriage travel at a time. It is a pure layer over
arrays (epsilon and the creep stiffnesses come in, positions, contact forces and contact
events go out), like :mod:`tolsim.physics.trains`, whose cluster rule it extends to the ring
and to the unloaded balls. The theory is in the Notes of :func:`step`; the proposed
configuration in those of :func:`circuit_length`. The Numba loops are in ``_kernels``.

Nomenclature
------------
sigma_k -> ``position`` (arc length along the circuit, carriage frame); D_k ->
``diameter``; g_k -> ``gap``; L_c -> ``circuit_length``; L_z -> ``zone_length``; f ->
``return_drag``; epsilon_k -> ``velocity_deviation``; K_k -> ``creep_stiffness``; xi_k ->
``circuit_speed``; w_k -> ``velocity`` (loaded epsilon); Q_k -> ``contact_force``; s ->
travel (carriage, relative to the rail).

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033.
.. [Ohta2017] H. Ohta, Y. Nakajima, S. Kato, H. Tajimi, "Sticking of a linear-guideway type
   recirculating ball bearing", J. Tribol. 139 (2017); the paper's ref. [4].
.. [Best1990] M. J. Best, N. Chakravarti, "Active set algorithms for isotonic regression; a
   unifying framework", Math. Program. 47 (1990) 425-439, doi:10.1007/BF01580873.
.. [Ahuja2001] R. K. Ahuja, J. B. Orlin, "A fast scaling algorithm for minimizing separable
   convex functions subject to chain constraints", Oper. Res. 49 (2001) 784-789,
   doi:10.1287/opre.49.5.784.10601.
"""

from dataclasses import dataclass

import numpy as np

from tolsim._jit import kernel_array
from tolsim.physics.circuit._kernels import (
    SPEED_TOLERANCE,
    STATUS_EVENT_OVERFLOW,
    STATUS_ITERATIONS,
    STATUS_JAMMED,
    TIE_TOLERANCE,
    WHERE_ENTRY,
    WHERE_EXIT,
    WHERE_INSIDE,
    WHERE_RETURN,
    step_circuit_kernel,
    wrap,
)

#: Names of the ``where`` codes of a contact event.
WHERE = {WHERE_INSIDE: "inside", WHERE_ENTRY: "entry", WHERE_EXIT: "exit",
         WHERE_RETURN: "return"}


@dataclass(frozen=True)
class CircuitState:
    """Balls of M circuits of N balls (SI units; conventions in the Notes of :func:`step`).

    Attributes
    ----------
    position : ndarray (M, N)
        sigma_k [m]: arc length of ball k's centre along its circuit, in the carriage frame,
        from the entry of the loaded zone in the direction of flow of a forward stroke. It is
        not wrapped: sigma_0 <= sigma_1 <= ... <= sigma_{N-1} <= sigma_0 + L_c, and the ball
        sits at sigma_k mod L_c.
    diameter : ndarray (M, N)
        D_k [m], the ball's sampled size; it moves with the ball.
    loaded : ndarray of bool (M, N)
        The ball is in the loaded zone (sigma mod L_c in [0, L_z)); switched by the step at
        the exact travel at which the ball crosses a boundary of the zone.
    closed : ndarray of bool (M, N)
        Pair k (balls k and k + 1 mod N) is in contact.
    speed : ndarray (M, N)
        xi_k = |d sigma_k / d s| [-] at the end of the last step; with no drag, the speed at
        which an unloaded ball coasts.
    circuit_length : ndarray (M,)
        L_c [m] = sum of the diameters + slack.
    zone_length : float
        L_z [m], the loaded zone.
    """

    position: np.ndarray
    diameter: np.ndarray
    loaded: np.ndarray
    closed: np.ndarray
    speed: np.ndarray
    circuit_length: np.ndarray
    zone_length: float

    def gap(self) -> np.ndarray:
        """g_k [m], (M, N): sigma_{k+1} - sigma_k - (D_k + D_{k+1}) / 2, and for k = N - 1
        sigma_0 + L_c - sigma_{N-1} - (D_{N-1} + D_0) / 2. They sum to the slack."""
        ahead = np.roll(self.position, -1, axis=-1)
        ahead[:, -1] += self.circuit_length
        return ahead - self.position - 0.5 * (self.diameter + np.roll(self.diameter, -1, -1))

    @property
    def slack(self) -> np.ndarray:
        """L_c - sum of the diameters [m], (M,), fixed when the circuit is filled."""
        return self.circuit_length - self.diameter.sum(axis=-1)


def circuit_length(diameter, slack):
    """Length L_c [m] of the circuit that holds ``diameter`` with total clearance ``slack``.

    Parameters
    ----------
    diameter : array_like (..., N)
        Ball diameters [m], > 0.
    slack : array_like, broadcastable to (...)
        Total clearance [m], >= 0.

    Returns
    -------
    ndarray (...)
        L_c = sum_k D_k + slack [m].

    Notes
    -----
    **The circuit's length.** L_c = L_z + 2 L_t + L_r (loaded zone, two turnarounds, return
    channel, all measured along the path of the ball centres). The circuit is filled to a
    clearance, so the slack, not L_c, is the controlled figure: L_c is taken as the balls'
    diameters plus the slack, and the return channel absorbs the difference
    (L_r = L_c - L_z - 2 L_t). The circuit's own length tolerance is part of the slack.

    **Configuration (a proposal, not yet read by the loader).** ::

        [carriage.circuit]
        balls = 30              # balls per circuit, more than the loaded zone holds
        slack_mm = 1.0          # total clearance of the circuit
        return_drag_N = 0.02    # resistance of one unloaded ball moving in the circuit

    Without ``[carriage.circuit]`` today's open trains stay. ``slack_mm`` and
    ``return_drag_N`` become ``slack`` and ``return_drag`` in SI at load time; the loaded zone
    is the carriage's (``balls_per_track`` x ``ball_pitch_mm``).

    **A realistic circuit (the numbers of configs/carriage_preload.toml, D = 10 mm).**

    * Loaded zone: L_z = 12 x 10.05 mm = 120.6 mm (the config's ``balls_per_track`` and
      ``ball_pitch_mm``).
    * Turnarounds: a half circle of the ball centres between the loaded row and the return
      row. The return hole sits beside the loaded groove, about 1.5 to 2 D from it
      (estimate from catalogue cross-sections of 20-size carriages), so the radius is about
      D and each turnaround is pi x 10 mm = 31.4 mm (estimate).
    * Return channel: as long as the carriage body, about the loaded zone, 120.6 mm
      (estimate; the end caps add to the turnarounds).
    * L_c = 120.6 + 2 x 31.4 + 120.6 = 304 mm (an estimate to a few mm), so 30 balls of
      10 mm; the slack is not derived from this sum (below). 12 balls are loaded and 18
      are in the turnarounds and the return channel.
    * Slack: a circuit is filled ball by ball until no further ball fits, so
      0 <= slack < D = 10 mm; the designer sizes the circuit for the ball count plus a
      small clearance, so the slack sits at the low end (estimate, no catalogue gives it).
      For comparison, today's open model draws the zone's gaps U(0, 100 um)
      (``[train] initial_gap`` of configs/carriage_preload.toml), a mean of 50 um per
      pair, which over the 30 pairs of this circuit is 1.5 mm. Proposed default 1.0 mm
      (0.1 D, estimate); a sweep of 0 to 3 mm covers the plausible range.
    * The 20-size guides of the catalogues carry smaller balls (about 3 to 4.8 mm, estimate)
      and about as many balls per circuit; the circuit above is that of the paper's 10 mm
      ball, to match the project's configs.

    **Default ``return_drag_N`` = 0.02 N per unloaded ball (order-of-magnitude estimate).**

    * Weight friction: a 10 mm steel ball weighs m g = 7850 kg/m^3 x (pi/6)(0.01 m)^3 x
      9.81 m/s^2 = 0.040 N; on the plastic wall of a horizontal return channel with a
      sliding or rolling-with-slip friction coefficient 0.1 to 0.3 (steel on greased
      POM/nylon, estimate) it costs 0.004 to 0.012 N.
    * Grease: a ball pushed through grease of yield stress 100 to 500 Pa (NLGI 1 to 2,
      estimate) over its cross-section pi (5 mm)^2 = 7.9e-5 m^2 needs 0.008 to 0.04 N in
      a channel packed with grease, less in one that holds only a film (0 to 0.04 N); the
      viscous part, 3 pi eta D u with eta = 0.1 Pa s and u = 0.1 m/s, is 1e-3 N.
    * The turnarounds add wall friction from the ball being turned (its centripetal force
      is negligible, m u^2 / r = 4e-3 kg x 0.01 / 0.01 = 4e-3 N at u = 0.1 m/s) and from
      the push of the column against the curved wall, which the drag per ball absorbs.

    Hence 0.004 to 0.05 N per ball; the default 0.02 N is weight friction at mu = 0.2
    (0.008 N) plus a partly greased channel (0.01 N). It gives 18 x 0.02 = 0.36 N for the
    column of the circuit above, in the issue's 0.1 to 0.5 N (16 balls x 0.004 to 0.03 N
    plus grease and turnarounds), and comparable with K sigma_epsilon ~ 0.3 N. A sweep of
    0.005 to 0.05 N covers the range.
    """
    d = np.asarray(diameter, dtype=np.float64)
    return d.sum(axis=-1) + np.asarray(slack, dtype=np.float64)


def circuit_state(diameter, gap, zone_length, first_position=0.0, speed=0.5) -> CircuitState:
    """Circuits filled with balls of sizes ``diameter`` and gaps ``gap`` (slack = sum).

    Parameters
    ----------
    diameter : array_like (M, N)
        D_k [m], > 0, finite.
    gap : array_like (M, N)
        g_k [m], >= 0, finite: gap k is between balls k and k + 1 (mod N). A zero gap is a
        pair in contact.
    zone_length : float
        L_z [m], > 0 and < L_c of every circuit.
    first_position : array_like, broadcastable to (M,)
        sigma_0 [m] of ball 0.
    speed : array_like, broadcastable to (M, N)
        Initial xi_k [-], >= 0 (default 1/2, the nominal circuit speed); it matters only
        for unloaded balls with no drag, which coast at it until pushed.

    Returns
    -------
    CircuitState
    """
    d = np.array(diameter, dtype=np.float64, ndmin=2)
    g = np.array(gap, dtype=np.float64, ndmin=2)
    if d.ndim != 2 or g.shape != d.shape or d.shape[1] < 2:
        raise ValueError(f"diameter {d.shape} and gap {g.shape} must have one shape "
                         "(circuits, balls) with balls >= 2")
    if not (np.all(np.isfinite(d)) and np.all(d > 0)):
        raise ValueError("diameter must be finite and > 0")
    if not (np.all(np.isfinite(g)) and np.all(g >= 0)):
        raise ValueError("gap must be finite and >= 0")
    first = np.broadcast_to(np.asarray(first_position, dtype=np.float64), d.shape[:1])
    if not np.all(np.isfinite(first)):
        raise ValueError("first_position must be finite")
    length = circuit_length(d, g.sum(axis=1))
    if not (np.isfinite(zone_length) and 0 < zone_length < length.min()):
        raise ValueError(f"zone_length = {zone_length!r} m must be > 0 and shorter than "
                         f"the circuit ({length.min()!r} m)")
    step_ = 0.5 * (d + np.roll(d, -1, axis=1)) + g
    position = first[:, None] + np.concatenate(
        [np.zeros((d.shape[0], 1)), np.cumsum(step_[:, :-1], axis=1)], axis=1)
    loaded = np.mod(position, length[:, None]) < zone_length
    xi = np.array(np.broadcast_to(np.asarray(speed, dtype=np.float64), d.shape))
    if not (np.all(np.isfinite(xi)) and np.all(xi >= 0)):
        raise ValueError("speed must be finite and >= 0")
    return CircuitState(position=position, diameter=d, loaded=loaded, closed=g <= 0.0,
                        speed=xi, circuit_length=length, zone_length=float(zone_length))


@dataclass(frozen=True)
class CircuitStep:
    """One step of :func:`step` (M circuits, N balls, E event slots).

    Attributes
    ----------
    state : CircuitState
        At the end of the step.
    circuit_speed : ndarray (M, N)
        xi_k = |d sigma_k / d s| [-] at the end of the step (1/2 for a nominal loaded ball,
        0 for an unloaded ball at rest).
    velocity : ndarray (M, N)
        Loaded epsilon w_k = 1 - 2 xi_k [-] of the loaded balls (NaN for unloaded ones).
    contact_force, mean_contact_force : ndarray (M, N)
        Q_k of pair k [N] at the end of the step, and its mean over the step's travel.
    entry_force, exit_force : ndarray (M,)
        Q of the pair at the entry (last unloaded ball, first loaded ball) and at the exit
        (last loaded, first unloaded) of the loaded zone [N] at the end of the step.
    entry_force_mean, exit_force_mean : ndarray (M,)
        Their means over the step's travel [N].
    event_count : ndarray of int (M,)
        Contacts that formed in the step (pairs whose gap closed).
    event_pair, event_where : ndarray of int (M, E)
        The pair k of each event and where it happened (``WHERE``), -1 past the count.
    event_travel : ndarray (M, E)
        The carriage travel of each event [m] (exact for constant epsilon and K).
    status : ndarray of int (M,)
        Bits ``STATUS_EVENT_OVERFLOW`` (more than E events; the first E are kept),
        ``STATUS_JAMMED`` (the drag stopped loaded balls; not expected with real numbers),
        ``STATUS_ITERATIONS`` (the event loop did not finish; not expected).
    crossing_travel : ndarray (M, N)
        The carriage travel at which each ball last crossed an end of the loaded zone in the
        step [m] (exact for constant epsilon and K; NaN: it did not cross).
    windows : FrictionWindows or None
        With ``pair_slopes``: the friction increase over the intervals between the step's
        events.
    """

    state: CircuitState
    circuit_speed: np.ndarray
    velocity: np.ndarray
    contact_force: np.ndarray
    mean_contact_force: np.ndarray
    entry_force: np.ndarray
    exit_force: np.ndarray
    entry_force_mean: np.ndarray
    exit_force_mean: np.ndarray
    event_count: np.ndarray
    event_pair: np.ndarray
    event_where: np.ndarray
    event_travel: np.ndarray
    status: np.ndarray
    crossing_travel: np.ndarray = None
    windows: "FrictionWindows | None" = None


@dataclass(frozen=True)
class FrictionWindows:
    """The friction increase of each circuit's track over the intervals between the events
    of a step (M circuits, W windows; :func:`step` with ``pair_slopes``).

    The step's forces are constant between events, so the increase sum_p k_p Q_p (over the
    pairs with a ball in the loaded zone, the slopes k_p of ``pair_slopes``) is piecewise
    constant: one window per interval of nonzero length holds its value, exact for constant
    epsilon and K, where a step mean hides a short dip or peak (the column's push stopping
    after an exit, Notes of :class:`tolsim.study.pipeline.circuit_friction.CircuitTrains`).

    Attributes
    ----------
    low, high : ndarray (M, W)
        Least and largest increase [N] in each window: its interval's value, or the extremes
        of the intervals merged into the last window beyond the capacity W (NaN: a slope was
        not finite).
    peak : ndarray (M, W)
        The largest force Q_p of those pairs [N].
    start : ndarray (M, W)
        The carriage travel at each window's start [m]; a window ends where the next one
        starts, the last one at the end of the step.
    force : ndarray (M, W, N)
        Each ball-order pair's Q_p in the window [N] (NaN at pair 0 where intervals were
        merged into it).
    count : ndarray of int (M,)
        Windows of each circuit (its intervals of nonzero length, at most W).
    """

    low: np.ndarray
    high: np.ndarray
    peak: np.ndarray
    start: np.ndarray
    force: np.ndarray
    count: np.ndarray


def window_arrays(m, n, pair_slopes=None, capacity=16):
    """The kernel's friction-window arguments for M circuits of N balls: ``(slopes, low,
    high, peak, start, force, count)``, empty (nothing tracked) without ``pair_slopes``
    (3, M, N)."""
    if pair_slopes is None:
        empty = np.empty((0, 0))
        return (np.empty((3, 0, 0)), empty, empty, empty, empty, np.empty((0, 0, 0)),
                np.empty(0, dtype=np.int64))
    slopes = np.ascontiguousarray(pair_slopes, dtype=np.float64)
    if slopes.shape != (3, m, n):
        raise ValueError(f"pair_slopes {slopes.shape} must be (3, {m}, {n})")
    shape = (m, int(capacity))
    return (slopes, np.full(shape, np.inf), np.full(shape, -np.inf), np.zeros(shape),
            np.full(shape, np.nan), np.full(shape + (n,), np.nan), np.zeros(m, dtype=np.int64))


def _ball_arrays(state, velocity_deviation, creep_stiffness):
    shape = state.position.shape
    try:
        eps = np.ascontiguousarray(np.broadcast_to(
            np.asarray(velocity_deviation, dtype=np.float64), shape))
        stiffness = np.ascontiguousarray(np.broadcast_to(
            np.asarray(creep_stiffness, dtype=np.float64), shape))
    except ValueError:
        raise ValueError(f"velocity_deviation {np.shape(velocity_deviation)} and "
                         f"creep_stiffness {np.shape(creep_stiffness)} must broadcast to "
                         f"the circuits {shape}") from None
    if not (np.all(np.isfinite(eps)) and np.all(np.abs(eps) < 1.0)):
        raise ValueError("velocity_deviation must be finite with |epsilon| < 1")
    if not (np.all(np.isfinite(stiffness)) and np.all(stiffness > 0.0)):
        raise ValueError("creep_stiffness must be finite and > 0")
    return eps, stiffness


def step(state: CircuitState, velocity_deviation, creep_stiffness, travel, return_drag, *,
         travel_start=0.0, event_capacity=None, pushed=None, pair_slopes=None,
         window_capacity=16) -> CircuitStep:
    """Move the balls of every circuit by one step of carriage travel (Notes).

    Parameters
    ----------
    state : CircuitState
    velocity_deviation : array_like, broadcastable to (M, N)
        epsilon_k [-] of each ball over the step (used while it is loaded), |epsilon| < 1.
    creep_stiffness : array_like, broadcastable to (M, N)
        K_k [N], > 0 (used while the ball is loaded).
    travel : float
        Carriage travel of the step relative to the rail [m]; negative for a reversed stroke.
    return_drag : float
        f [N], >= 0: the resistance of one unloaded ball moving in the circuit.
    travel_start : float
        Carriage travel at the start of the step [m] (labels the events).
    event_capacity : int, optional
        Event slots per circuit (default N).
    pushed : array_like of bool, broadcastable to (M, N), optional
        Balls without a groove contact while they are in the loaded zone (issue 25: under an
        end relief, an undersized ball): no epsilon or K of their own, pushed along (Notes,
        "Pushed balls"); default none.
    pair_slopes : array_like (3, M, N), optional
        The carriage friction per newton of each ball-order pair p (balls p and p + 1 mod N)
        while both balls are in the loaded zone, while ball p alone is, while ball p + 1
        alone is [-]; with it the step returns its :class:`FrictionWindows`.
    window_capacity : int
        Windows per circuit with ``pair_slopes`` (intervals beyond it merge into the last).

    Returns
    -------
    CircuitStep

    Notes
    -----
    **Frames.** Rail frame s, carriage frame z = s - v t; the carriage runs towards +z and
    the loaded zone is z in [-L_z/2, L_z/2] (the convention of
    :func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`). A loaded
    ball's centre moves along the rail at (1 + w) v / 2 ([Lin2018] Eq. 23, w its loaded
    epsilon), so through the carriage at dz/dt = -(1 - w) v / 2: it enters the zone at the
    leading end z = +L_z/2 and leaves it at the trailing end z = -L_z/2. The circuit
    coordinate sigma is the arc length of the ball-centre path in the carriage frame,
    sigma = L_z/2 - z in the loaded zone (so sigma = 0 at the entry and L_z at the exit),
    then the trailing turnaround, the return channel and the leading turnaround back to
    sigma = L_c = 0. Balls flow towards +sigma. Per unit travel s = v t,

        d sigma_k / d s = xi_k,   xi_k = (1 - w_k) / 2 for a loaded ball.                    (1)

    Everything is rate-independent (creep and Coulomb drag), so the motion depends on the
    travel, not on v. A reversed stroke (travel < 0) moves every ball the other way; balls
    then enter at sigma = L_z and leave at sigma = 0 (the step runs in the coordinate
    -sigma, with the balls in reversed order: the mirror image).

    **Gaps and conservation.** Ball k + 1 is ahead of ball k in the direction of flow;
    g_k = sigma_{k+1} - sigma_k - (D_k + D_{k+1}) / 2, with sigma_N = sigma_0 + L_c. Their
    sum telescopes to L_c - sum_k D_k, the slack, whatever the positions: the state holds
    positions, not gaps, so the slack is conserved by construction (to the rounding of one
    sum, about N ulp(sigma); the tests check 1e-12 m over 800 steps). A closed pair
    never overlaps, so the balls never change order.

    **One ball.** A pair k in contact carries a compressive force Q_k >= 0 (ball k pushes
    ball k + 1 towards +sigma); the net force on ball k towards +sigma is
    F_k = Q_{k-1} - Q_k.

    * Loaded ball (the linear creep model of :func:`tolsim.physics.trains.cluster_velocities`,
      eq. 1, without ball-to-ball friction): a push towards +z raises w by P / K, and +sigma
      is -z, so w_k = epsilon_k - F_k / K_k, i.e. by (1)

          F_k = 2 K_k (xi_k - xi_k^free),   xi_k^free = (1 - epsilon_k) / 2.                 (2)

    * Unloaded ball (turnarounds and return channel): no creep; it is pushed through the
      channel against a Coulomb drag f (``return_drag``, assumed the same everywhere outside
      the loaded zone):

          F_k = f if xi_k > 0,   |F_k| <= f if xi_k = 0.                                   (3)

      An unloaded ball rests in the carriage unless the balls behind push it (inertia
      neglected, below). With no drag (f = 0) nothing stops it: it coasts at the speed it
      had (``CircuitState.speed``), as a ball of vanishing mass that keeps its momentum;
      touching coasting balls share the mean of their speeds. This is the f -> 0 limit with
      inertia (the coasting distance m (v/2)^2 / (2 f) grows without bound), and it makes a
      circuit with equal epsilon and no drag move as one, without any gap changing.

    **Clusters on the ring.** Touching balls cannot overlap (xi_k <= xi_{k+1} for a closed
    pair k) and a contact only pushes; (2), (3) and these conditions are the KKT conditions
    of the separable convex problem

        minimise  sum_loaded K_k (xi_k - xi_k^free)^2 + sum_unloaded f |xi_k|
        subject to xi_k <= xi_{k+1} for every closed pair k,                               (4)

    with Q_k the multiplier of pair k. Pool adjacent violators solves a separable convex
    isotonic problem exactly when every block takes the minimiser of its own summed
    objective ([Best1990]; [Ahuja2001]); for a block B (W = sum 2 K_k over its loaded balls,
    n_u its unloaded balls)

        xi_B = max(0, (sum_B 2 K_k xi_k^free - n_u f) / W),   xi_B = 0 if W = 0,            (5)

    the K-weighted mean of the loaded balls' free speeds, slowed by the drag of the balls
    they push. With f = 0 and no unloaded ball this is the cluster rule of
    :mod:`tolsim.physics.trains` (w_B the K-weighted mean epsilon); with f = 0 a pushed
    unloaded ball adds nothing. The forces inside a block follow by summing F_k from its
    upstream ball, Q_j = -sum_{k <= j} F_k. If any pair of the ring is open, the ring is cut
    there and is a chain (the cut pair carries no constraint); the widest open pair is used.
    If every pair is closed (slack = 0), the constraints go round the ring and force one
    common speed xi_ring by (5); the forces are then fixed only up to a uniform prestress
    (a ring of rigid balls filled with no clearance), and the least one is taken: the
    smallest Q of the ring is 0 (a circuit filled without interference). A block in which the
    drag stops loaded balls is "jammed" (``STATUS_JAMMED``; needs n_u f > sum K (1 - eps),
    some 1e2 N, against 0.2 N in practice).

    **No slack in closed form.** With slack = 0 every pair stays closed and the ring moves at
    xi_ring: the loaded balls' common epsilon and the ends' column forces are

        w_ring = epsilon_K + n_u f / sum K,   epsilon_K = sum K_k epsilon_k / sum K_k,        (6)
        Q_entry = max(0, max_j sum_{k <= j} K_k (epsilon_k - w_ring)),
        Q_exit = Q_entry + n_u f,                                                           (7)

    the loaded balls k = 1..n numbered from the entry, sums over them, n_u the unloaded
    balls. (Force balance on the loaded balls: the creep forces K_k (epsilon_k - w) sum to
    the column's drag n_u f; along the zone Q rises by K_k (w - epsilon_k) at ball k, and
    along the column it falls by f per ball, so the least force sits at the entry or inside
    the zone.) For equal epsilon, Q_entry = 0 and Q_exit = n_u f: the trailing balls push the
    whole column, and the column arrives at the entry with no force.

    **Pushed balls (issue 25).** A ball in the loaded zone whose four groove contacts have
    opened (under an end relief deeper than its approach, an undersized ball, a guide with
    clearance) carries no groove force: it has no epsilon or K of its own and no drag (it
    rolls or slides freely between the grooves). In (4) it adds nothing (weight 0, no f), so
    it transmits a force unchanged (F_k = 0) and every speed is an equilibrium of it while it
    touches nothing; the speed chosen is that of
    :func:`tolsim.study.pipeline.propagation.pushed_along` on the ring: a run of pushed balls
    between the nearest balls a (behind) and b (ahead) that are not pushed moves at
    xi_a + (xi_b - xi_a) G_i / G, G_i the gaps from a to ball i and G those from a to b (with
    the speeds of a and b of the solve of (4), solved again with these), so every gap of the
    run closes at once, when a and b would touch with the run between them. Its pairs then
    carry force only when all of them have closed, the first contact that carries force, and
    that is the one contact event recorded for the run (at its last pair, labelled by a and
    b: ``inside`` when both are loaded, ``entry`` when the column reaches the zone's first
    loaded ball through it). A run with a pushed ball touching one neighbour only moves
    with it (G_i = 0 or G). A ball that leaves the zone is an unloaded ball of the column.
    Conservation and order are as above (positions, not gaps, are the state).

    **The step.** Within a step epsilon and K of each ball are constant; the motion is
    followed event by event: solve (4) on the closed pairs, move every ball by (1) to the
    earliest event, which is a gap closing (a contact event) or a ball crossing a zone
    boundary (a loaded ball reaching the exit becomes unloaded and stops unless pushed; an
    unloaded ball pushed over the entry becomes loaded), update, repeat. A closed pair that
    (4) leaves in two blocks separates. So a step is exact for constant epsilon and K,
    whatever its length (the test of step-size independence). The contacts are inelastic
    and quasi-static (Notes of :func:`tolsim.physics.trains.train_contact_constant`). Events
    closer than 1e-12 of the step's travel are simultaneous, and speeds closer than 1e-12
    are equal (``SPEED_TOLERANCE``: a resting pair is not opened and closed again by
    rounding). A ball enters the zone with the
    gap the circuit gives it: no fresh draw. Cost: O(N) per event and per step; a step
    of up to about one ball diameter has a few events.

    **Where.** A contact event is labelled by the pair's balls at the moment it forms
    (upstream ball first): both loaded ``inside``; unloaded then loaded ``entry`` (the column
    catches the zone's first ball); loaded then unloaded ``exit`` (a loaded ball catches the
    column, which happens each time a ball leaves the zone, as it stops); both unloaded
    ``return``. The column forces are those of the entry and exit pairs (0 if open).

    **Neglected.**

    * Inertia: a 10 mm ball (4.1 g) leaving at v/2 = 0.1 m/s against f = 0.02 N coasts
      m (v/2)^2 / (2 f) = 1.0 mm, for about 20 ms, before it stops (0.003 mm at
      v = 10 mm/s, the paper's speed). The quasi-static model stops it at once; the
      coasting changes where the exit contact happens (by up to a tenth of a ball at
      0.2 m/s), not the slack or the order (estimate, not modelled).
    * Gravity along the column: none in the straight channels of a horizontal guide; in the
      turnarounds of a horizontal guide it acts across the path (it is part of the wall
      friction in f). For a vertical guide the column's weight, 18 x 0.04 N = 0.7 N, would
      act along it: not modelled.
    * Turnaround friction beyond the drag: the column pressed against the curved wall by
      its own force Q adds a capstan-like friction mu Q pi; with Q ~ 0.4 N and mu ~ 0.1 it is
      ~0.1 N per turnaround, within the drag's factor-of-ten uncertainty, and it is lumped
      into f (a force-dependent drag would need a second parameter).
    * Ball-to-ball friction in the circuit (``braking_sensitivity`` of the trains) and the
      unloaded balls' spin; elastic deformation of the balls (the least-prestress rule for
      slack = 0 replaces it).
    """
    if not isinstance(state, CircuitState):
        raise ValueError("state must be a CircuitState (circuit_state)")
    eps, stiffness = _ball_arrays(state, velocity_deviation, creep_stiffness)
    if not np.isfinite(travel):
        raise ValueError(f"travel = {travel!r} must be finite")
    if not (np.isfinite(return_drag) and return_drag >= 0):
        raise ValueError(f"return_drag = {return_drag!r} N must be >= 0")
    m, n = state.position.shape
    capacity = n if event_capacity is None else int(event_capacity)
    if capacity < 1:
        raise ValueError(f"event_capacity = {event_capacity!r} must be >= 1")
    try:
        flags = np.ascontiguousarray(np.broadcast_to(
            np.asarray(False if pushed is None else pushed, dtype=np.bool_),
            state.position.shape))
    except ValueError:
        raise ValueError(f"pushed {np.shape(pushed)} must broadcast to the circuits "
                         f"{state.position.shape}") from None
    position = state.position.copy()
    loaded = state.loaded.copy()
    closed = state.closed.copy()
    speed = state.speed.copy()
    velocity = np.empty((m, n))
    force = np.empty((m, n))
    mean_force = np.empty((m, n))
    column = np.empty((m, 4))
    count = np.empty(m, dtype=np.int64)
    pair = np.full((m, capacity), -1, dtype=np.int64)
    where = np.full((m, capacity), -1, dtype=np.int8)
    when = np.full((m, capacity), np.nan)
    status = np.empty(m, dtype=np.int64)
    if int(window_capacity) < 1:
        raise ValueError(f"window_capacity = {window_capacity!r} must be >= 1")
    windows = window_arrays(m, n, pair_slopes, window_capacity)
    crossing = np.empty((m, n))
    step_circuit_kernel(position, kernel_array(state.diameter), kernel_array(eps),
                        kernel_array(stiffness), flags, loaded, closed,
                        state.circuit_length, float(state.zone_length), float(return_drag),
                        float(travel), float(travel_start), speed, velocity, force,
                        mean_force, column, count, pair, where, when, status, *windows,
                        crossing)
    new = CircuitState(position=position, diameter=state.diameter, loaded=loaded,
                       closed=closed, speed=speed, circuit_length=state.circuit_length,
                       zone_length=state.zone_length)
    return CircuitStep(state=new, circuit_speed=speed, velocity=velocity,
                       contact_force=force, mean_contact_force=mean_force,
                       entry_force=column[:, 0], exit_force=column[:, 1],
                       entry_force_mean=column[:, 2], exit_force_mean=column[:, 3],
                       event_count=count, event_pair=pair, event_where=where,
                       event_travel=when, status=status, crossing_travel=crossing,
                       windows=None if pair_slopes is None else FrictionWindows(*windows[1:]))


@dataclass(frozen=True)
class CircuitRun:
    """A stroke of :func:`run` (S steps, M circuits, N balls).

    Attributes
    ----------
    travel : ndarray (S + 1,)
        Carriage travel at the start and after each step [m].
    position, gap : ndarray (S + 1, M, N)
        sigma_k and g_k [m] at the start and after each step.
    loaded, closed : ndarray of bool (S + 1, M, N)
    contact_force : ndarray (S, M, N)
        Q_k at the end of each step [N].
    entry_force, exit_force, entry_force_mean, exit_force_mean : ndarray (S, M)
        Column forces per step [N] (:class:`CircuitStep`).
    events : dict of ndarray
        One entry per contact event: ``circuit``, ``pair``, ``where``, ``travel``, ``step``.
    status : ndarray of int (M,)
        The status bits of all steps, or-ed.
    state : CircuitState
        At the end of the stroke.
    """

    travel: np.ndarray
    position: np.ndarray
    gap: np.ndarray
    loaded: np.ndarray
    closed: np.ndarray
    contact_force: np.ndarray
    entry_force: np.ndarray
    exit_force: np.ndarray
    entry_force_mean: np.ndarray
    exit_force_mean: np.ndarray
    events: dict
    status: np.ndarray
    state: CircuitState


def run(state: CircuitState, velocity_deviation, creep_stiffness, stroke, steps,
        return_drag, *, event_capacity=None, pushed=None) -> CircuitRun:
    """A stroke of constant epsilon and K in ``steps`` equal steps of :func:`step`, recorded.

    Parameters
    ----------
    state : CircuitState
    velocity_deviation, creep_stiffness : array_like, broadcastable to (M, N)
        As :func:`step`, constant over the stroke.
    stroke : float
        Carriage travel [m] (negative: reversed).
    steps : int
        Number of steps, >= 1.
    return_drag : float
        f [N].
    event_capacity : int, optional
        Event slots per circuit and step (default N).
    pushed : array_like of bool, optional
        As :func:`step`, constant over the stroke.

    Returns
    -------
    CircuitRun
    """
    if int(steps) != steps or steps < 1:
        raise ValueError(f"steps = {steps!r} must be an integer >= 1")
    steps = int(steps)
    travel = stroke * np.arange(steps + 1) / steps
    m, n = state.position.shape
    position = np.empty((steps + 1, m, n))
    gap = np.empty((steps + 1, m, n))
    loaded = np.empty((steps + 1, m, n), dtype=bool)
    closed = np.empty((steps + 1, m, n), dtype=bool)
    force = np.empty((steps, m, n))
    column = np.empty((4, steps, m))
    status = np.zeros(m, dtype=np.int64)
    events = {key: [] for key in ("circuit", "pair", "where", "travel", "step")}
    position[0], gap[0], loaded[0], closed[0] = (state.position, state.gap(), state.loaded,
                                                 state.closed)
    for i in range(steps):
        out = step(state, velocity_deviation, creep_stiffness, travel[i + 1] - travel[i],
                   return_drag, travel_start=travel[i], event_capacity=event_capacity,
                   pushed=pushed)
        state = out.state
        position[i + 1], gap[i + 1] = state.position, state.gap()
        loaded[i + 1], closed[i + 1] = state.loaded, state.closed
        force[i] = out.contact_force
        column[:, i] = (out.entry_force, out.exit_force, out.entry_force_mean,
                        out.exit_force_mean)
        status |= out.status
        rows, slots = np.nonzero(out.event_pair >= 0)
        events["circuit"].append(rows)
        events["pair"].append(out.event_pair[rows, slots])
        events["where"].append(out.event_where[rows, slots])
        events["travel"].append(out.event_travel[rows, slots])
        events["step"].append(np.full(rows.size, i))
    return CircuitRun(travel=travel, position=position, gap=gap, loaded=loaded,
                      closed=closed, contact_force=force, entry_force=column[0],
                      exit_force=column[1], entry_force_mean=column[2],
                      exit_force_mean=column[3],
                      events={k: np.concatenate(v) for k, v in events.items()},
                      status=status, state=state)


__all__ = [
    "SPEED_TOLERANCE",
    "STATUS_EVENT_OVERFLOW",
    "STATUS_ITERATIONS",
    "STATUS_JAMMED",
    "TIE_TOLERANCE",
    "WHERE",
    "WHERE_ENTRY",
    "WHERE_EXIT",
    "WHERE_INSIDE",
    "WHERE_RETURN",
    "CircuitRun",
    "CircuitState",
    "CircuitStep",
    "FrictionWindows",
    "circuit_length",
    "circuit_state",
    "run",
    "step",
    "step_circuit_kernel",
    "window_arrays",
    "wrap",
]
