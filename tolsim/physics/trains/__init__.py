r"""Trains of balls after contact: clusters, ball-to-ball forces, net pushes (issue 13, part 2).

The loaded balls of one track form a *train*, numbered from the trailing end (ball 0) to the
leading end (ball n - 1), as in :mod:`tolsim.study.pipeline.propagation`. Pair j is ball j and ball
j + 1, with gap g_j >= 0. This package moves the balls after they touch. It is a pure layer
over arrays: epsilon, the creep stiffnesses and the gaps come in, and trajectories and
contact forces go out. It imports nothing from io, cli or reports.

The conventions, the linear creep model of one ball and the contact problem of the clusters are
in the Notes of :func:`cluster_velocities`; the event-driven solution for constant epsilon, the
quasi-static assumption and the outputs in those of :func:`train_contact_constant`; the step
rule of ``along_track`` in those of :func:`step_clusters_kernel`. The Numba loops are in
``_kernels``.

Nomenclature
------------
epsilon_i -> ``velocity_deviation``; K_i -> ``creep_stiffness``; c_i ->
``braking_sensitivity``; g_j -> ``initial_gap``; Q_j -> ``contact_force``; P_i ->
``net_push``; w_i -> ``velocity`` (loaded epsilon); u_i -> ``displacement``; v ->
``groove_velocity``; T -> ``horizon``.

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033.
.. [Ayer1955] M. Ayer, H. D. Brunk, G. M. Ewing, W. T. Reid, E. Silverman, "An empirical
   distribution function for sampling with incomplete information", Ann. Math. Statist. 26
   (1955) 641-647, doi:10.1214/aoms/1177728423.
.. [Barlow1972] R. E. Barlow, D. J. Bartholomew, J. M. Bremner, H. D. Brunk, Statistical
   Inference under Order Restrictions, Wiley, 1972.
.. [Best1990] M. J. Best, N. Chakravarti, "Active set algorithms for isotonic regression; a
   unifying framework", Math. Program. 47 (1990) 425-439, doi:10.1007/BF01580873.
.. [Johnson1985] K. L. Johnson, Contact Mechanics, Cambridge University Press, 1985.
"""

from dataclasses import dataclass

import numpy as np

from tolsim._jit import kernel_array
from tolsim.physics.trains._kernels import (
    CHUNK,
    TIE_TOLERANCE,
    cluster_velocities_kernel,
    step_clusters_kernel,
    step_project_kernel,
    train_constant_kernel,
)

# ----------------------------------------------------------------------------- wrappers


def _train_arrays(velocity_deviation, creep_stiffness, braking_sensitivity):
    """Validate and broadcast epsilon, K and c to float64 (m, n) arrays."""
    eps = np.asarray(velocity_deviation, dtype=np.float64)
    if eps.ndim < 1 or eps.shape[-1] < 1:
        raise ValueError(f"velocity_deviation {eps.shape} must have shape (..., balls)")
    try:
        stiffness = np.broadcast_to(np.asarray(creep_stiffness, dtype=np.float64), eps.shape)
        braking = np.broadcast_to(
            np.asarray(0.0 if braking_sensitivity is None else braking_sensitivity,
                       dtype=np.float64), eps.shape)
    except ValueError:
        raise ValueError(
            f"creep_stiffness {np.shape(creep_stiffness)} and braking_sensitivity "
            f"{np.shape(braking_sensitivity)} must broadcast to velocity_deviation "
            f"{eps.shape}") from None
    finite = np.isfinite(stiffness)
    if np.any(stiffness[~np.isnan(stiffness)] < 0.0):
        bad = stiffness[stiffness < 0.0][0]
        raise ValueError(f"creep_stiffness = {bad!r} must be >= 0 (inf: an anchor, 0: a ball "
                         "pushed along, NaN: an unresolved or sliding ball)")
    with np.errstate(invalid="ignore"):
        out_of_range = np.isfinite(braking) & finite & (np.abs(braking * stiffness) >= 1.0)
    if np.any(out_of_range):
        raise ValueError(f"braking_sensitivity = {braking[out_of_range][0]!r} must have "
                         "|braking_sensitivity| * creep_stiffness < 1")
    shape = eps.shape
    n = shape[-1]
    return (kernel_array(eps.reshape(-1, n)), kernel_array(stiffness.reshape(-1, n)),
            kernel_array(braking.reshape(-1, n)), shape)


def cluster_velocities(velocity_deviation, creep_stiffness, touching,
                       braking_sensitivity=None):
    """Velocities and contact forces of balls whose closed pairs are given (the cluster rule).

    The quasi-static contact problem (eqs. 1-3 in the Notes), solved exactly by
    pool adjacent violators. Touching balls move together at the kappa-weighted mean of
    their epsilon (K-weighted for c = 0) and push with forces >= 0. A chain of closed pairs
    splits where a force would turn negative. This is the step rule of ``along_track``
    propagation: call it with ``touching = gap <= 0`` at every step.

    Parameters
    ----------
    velocity_deviation : array_like, shape (..., balls)
        Free-rolling epsilon per ball [-], ball 0 trailing. A train with a NaN gets NaN.
    creep_stiffness : array_like, broadcastable to ``velocity_deviation``
        K_i = dP/depsilon [N], > 0; inf for an anchor, 0 for a ball pushed along (Notes,
        "Anchors and balls pushed along"); NaN marks an unresolved or sliding ball.
    touching : array_like of bool, shape (..., balls - 1)
        True where the gap of pair j (balls j, j + 1) is closed.
    braking_sensitivity : array_like, optional
        c_i [1/N] of eq. (1), broadcastable to ``velocity_deviation``, with
        |c_i| K_i < 1; default 0 (no ball-to-ball friction). NaN as for K.

    Returns
    -------
    velocity : ndarray, shape (..., balls)
        Loaded epsilon w_i [-]; the ball moves at (1 + w_i) v / 2.
    contact_force : ndarray, shape (..., balls - 1)
        Compressive force Q_j of pair j [N], >= 0; zero for open pairs.

    Notes
    -----
    **Conventions (those of :mod:`tolsim.study.pipeline.propagation`)**

    The top groove (the carriage) moves at +v along z. A free ball's centre moves at
    (1 + epsilon_i) v / 2, so the gap of pair j closes at -dg_j/dt = (epsilon_j - epsilon_{j+1})
    v / 2. The brief's ``v (epsilon_i + P_i / K_i)`` is this rate with v in place of v / 2; the
    propagation convention is kept, so that the first contact is the same to the last bit. The
    positions returned are *displacements* u_i [m] from the nominal motion:
    z_i(t) = z_i(0) + v t / 2 + u_i(t), and du_i/dt = (v / 2) w_i. Here w_i [-] is the ball's
    *loaded* velocity deviation (its epsilon under the neighbour forces). Carriage travel is v t.

    **One ball (the linear creep model)**

    Neighbours press on ball i along its line of centres. The ball behind presses with
    Q_back,i = Q_{i-1} >= 0 and the ball in front with Q_front,i = Q_i >= 0 (Q_j is the
    compressive force of pair j [N]). The net push along the rolling direction is
    P_i = Q_{i-1} - Q_i [N]. With the creep stiffness K_i = dP/depsilon > 0 [N] (N per unit
    epsilon; from the single-ball physics), the ball rolls at

        w_i = epsilon_i + (Q_{i-1} - Q_i) / K_i + c_i (Q_{i-1} + Q_i)                        (1)

    The optional c_i [1/N] (``braking_sensitivity``, default 0; the field of the same name in
    :class:`tolsim.physics.velocity.ball_loads.BallLoadFields`, d epsilon / d(Q_back + Q_front) at
    fixed P) carries the ball-to-ball friction. Both balls of a pair spin the same way, so their
    surfaces slide at the contact. The Coulomb friction there (mu_bb Q) puts a moment on each ball,
    and that moment changes epsilon in proportion to the normal force, whichever side the force
    comes from. The single-ball physics supplies c_i with its sign. The module needs only the two
    compliances

        a_i = 1 / K_i + c_i  (response to a push from behind)
        b_i = 1 / K_i - c_i  (response to a push from in front)

    to be positive, i.e. |c_i| K_i < 1. Otherwise a push from behind would slow the ball down.
    Balls outside that range are refused with a ``ValueError``. The ends of the train get no
    force: Q_{-1} = Q_{n-1} = 0 (see "Ends of the loaded zone").

    **Reduction to the frictionless case**

    Put Q_j = lambda_j R_j, with lambda_{-1} = 1, lambda_i = lambda_{i-1} a_i / b_i > 0 and
    kappa_i = 1 / (a_i lambda_{i-1}) = 1 / (b_i lambda_i). Then (1) becomes

        w_i = epsilon_i + (R_{i-1} - R_i) / kappa_i                                          (2)

    This is the c = 0 law with stiffnesses kappa_i. Since lambda_j > 0, R_j >= 0 exactly when
    Q_j >= 0. With c = 0, kappa = K and lambda = 1 bit for bit. Everything below is stated for
    (2). A global rescaling of lambda changes nothing.

    **Clusters (the contact problem)**

    Touching balls cannot overlap, and a closed pair can only push. For every pair with a
    closed gap:

        R_j >= 0,   s_j = w_{j+1} - w_j >= 0,   R_j s_j = 0                                   (3)

    Pairs with an open gap carry R_j = 0. Equations (2) and (3) are the KKT conditions of the
    weighted isotonic regression

        minimise  sum_i kappa_i (w_i - epsilon_i)^2 / 2
        subject to w_j <= w_{j+1} for every closed pair j                                    (4)

    R_j is the multiplier of the constraint of pair j. Stationarity,
    kappa_i (w_i - epsilon_i) = R_{i-1} - R_i, is (2). The objective is strictly convex, so
    (4) has one solution, and so does the contact problem. For c = 0 the objective equals
    sum_i P_i^2 / (2 K_i).

    The solution groups the balls into *clusters* (blocks of consecutive balls with a common w).
    Summing (2) over a cluster C, the end forces vanish and

        w_C = sum_C kappa_i epsilon_i / sum_C kappa_i                                         (5)

    This is the kappa-weighted mean (the K-weighted mean for c = 0). The internal forces
    follow by summing (2) from the trailing ball of the cluster, s:

        R_j = sum_{i=s..j} kappa_i (epsilon_i - w_C)                                          (6)

    For two balls with c = 0: w = (K_1 eps_1 + K_2 eps_2) / (K_1 + K_2) and
    Q = K_1 K_2 (eps_1 - eps_2) / (K_1 + K_2). The faster trailing ball pushes, and Q > 0.

    (4) is solved exactly by *pool adjacent violators* (PAV; Ayer et al. 1955; Barlow et al.
    1972, Sec. 1.2; Best and Chakravarti 1990). Scan the balls from the trailing end, keeping a
    stack of blocks. Push each ball as a block of its own. While the pair between the top two
    blocks is closed and the lower block is faster (mean_lower > mean_top), pool them into one
    block at the weighted mean (5). Pooling adjacent violators never separates balls that share
    a block in the solution, and the scan ends with non-decreasing means across every closed
    boundary. Every block's prefix means are >= its mean, so (6) >= 0 (by induction over the
    poolings, with the sums of the theorem below). Hence (3) holds, and by uniqueness this is
    the solution. The cost is O(n) per train. A pair left as a boundary is either separating
    (w_j < w_{j+1}) or resting at zero force (w_j = w_{j+1}, a tie that is not pooled). A
    "cluster split" in the brief's sense is a touching chain that PAV leaves as several blocks.
    :func:`cluster_velocities` gives exactly this rule for any set of closed pairs.
    ``along_track`` propagation applies it at every step, where epsilon changes and clusters
    really do split.

    **Anchors and balls pushed along (issue 25)**

    An *anchor* (an exactly two-point ball, or one whose two opposite contacts both stick,
    :mod:`tolsim.physics.trains.regimes`; a ball in regime B is stiff, not rigid) keeps its
    epsilon under a push until its capacity: K = inf. A ball *pushed along* (unloaded: no
    raceway contact, no epsilon of its own)
    offers no resistance: K = 0. Both are limits of (2): give the anchors kappa_a = L k_a and
    the pushed balls kappa_u = k_u / L and let L -> inf. The problem (4) stays strictly convex
    for every L, so its limit is well defined, and PAV computes it with weights compared
    lexicographically: a block's mean (5) tends to the k-weighted mean of the balls of its
    *highest tier* (anchors > soft balls > pushed balls). For a block held by anchors that all
    have the same epsilon e,

        w_C = e + I / (L sum_a k_a) + O(L^-2),   I = sum_{soft i in C} kappa_i (epsilon_i - e),

    so the balls roll at e, and the forces (6) have the limit

        R_j = sum_{soft i <= j} kappa_i (epsilon_i - e) - I sum_{a <= j} k_a / sum_a k_a    (6a)

    A soft ball's term is as before; each anchor takes the share k_a / sum k_a of the soft
    balls' imbalance as its own net push (equal anchor stiffnesses: k_a = 1 / lambda_a, so
    that the pushes P_a are equal in newtons). Pushed balls add nothing: they transmit the
    force unchanged (P_u = 0) and move with their cluster; a block of pushed balls only keeps
    their mean epsilon and carries no force. Examples: a soft ball (K, eps_1) touching an
    anchor in front of it rolls at the anchor's e and pushes with Q = (eps_1 - e) / (1/K - c);
    an anchor between a faster and a slower ball carries K_1 (eps_1 - e) - K_3 (e - eps_3).

    PAV pools two blocks when the lower mean exceeds the upper one. Two anchor blocks of
    equal e (two-point balls: e = 0 exactly) tie at leading order; the next order decides,

        pool  iff  I_lower / sum_{a in lower} k_a  >  I_upper / sum_{a in upper} k_a,        (6b)

    so a fast ball behind a chain of touching anchors and a slow one in front of it load
    the whole chain, as the finite stiffness would. Anchors of *different* epsilon pooled into
    one block cannot roll together: their terms kappa_a (epsilon_a - w) are infinite, the
    block's forces are +inf, and the friction check reads the cluster as sliding (unresolved,
    counted and bounded). The same rule serves the projection (7) of ``along_track``. With
    only soft balls nothing changes: the same operations in the same order.

    **Ends of the loaded zone**

    The train is the loaded balls of one track. Ball 0 has no neighbour behind it and ball
    n - 1 none in front. The unloaded balls beyond the ends of the loaded zone (in the end caps
    and the return path) offer no creep resistance, and they are taken to transmit no force:
    Q_{-1} = Q_{n-1} = 0. Consequences, which the tests check:

    * every cluster's net pushes sum to zero, and so do the train's;
    * the trailing ball can only be held back (P_0 = -Q_0 <= 0), and the leading ball can only
      be pushed (P_{n-1} = Q_{n-2} >= 0);
    * a leading ball faster than the ball behind it runs away at its own epsilon, and a trailing
      ball slower than the ball in front falls behind. Neither ever carries a force.

    Not modelled: an end seal or retainer that would press on the end balls; with the event-driven
    solution, balls entering or leaving the loaded zone during the stroke (the set of balls is fixed
    over the horizon). With a carriage and ``along_track`` propagation balls do enter and leave
    (Notes of :func:`tolsim.study.pipeline.carriage_track.first_contact_carriage_track`, "After
    contact"): a ball leaving the zone drops its contacts, one entering it joins its train with
    an open gap.
    """
    eps, stiffness, braking, shape = _train_arrays(velocity_deviation, creep_stiffness,
                                                   braking_sensitivity)
    pairs = shape[:-1] + (shape[-1] - 1,)
    closed = np.asarray(touching, dtype=bool)
    if closed.shape != pairs:
        raise ValueError(f"touching {closed.shape} must have shape {pairs} (balls - 1 pairs)")
    closed = np.ascontiguousarray(closed.reshape(len(eps), -1))
    velocity = np.empty_like(eps)
    force = np.empty((len(eps), shape[-1] - 1))
    cluster_velocities_kernel(eps, stiffness, braking, closed, velocity, force)
    return velocity.reshape(shape), force.reshape(pairs)


def net_push(contact_force):
    """Net push P_i = Q_back,i - Q_front,i on each ball [N] from the pair forces.

    Parameters
    ----------
    contact_force : array_like, shape (..., balls - 1)
        Q_j [N] of pair j (balls j, j + 1).

    Returns
    -------
    ndarray, shape (..., balls)
        P_i = Q_{i-1} - Q_i, with no force beyond the ends of the train
        (Q_{-1} = Q_{n-1} = 0).
    """
    q = np.asarray(contact_force, dtype=np.float64)
    zero = np.zeros(q.shape[:-1] + (1,))
    return np.concatenate([zero, q], axis=-1) - np.concatenate([q, zero], axis=-1)


@dataclass(frozen=True)
class TrainResult:
    """Trains with constant epsilon over the horizon (:func:`train_contact_constant`).

    Shapes: m trains, n balls, n - 1 pairs, S grid samples. A train with an unresolved or
    sliding ball (non-finite epsilon or c, NaN K) has ``valid = False``. Its first contact follows
    :func:`tolsim.study.pipeline.propagation.first_contact_constant` (resolved pairs only), and
    everything else is NaN or -1.

    Attributes
    ----------
    valid : ndarray of bool (m,)
    first_contact_time : ndarray (m,)
        [s], inf if no contact within the horizon. Bit for bit equal to
        :func:`tolsim.study.pipeline.propagation.first_contact_constant`.
    first_contact_pair : ndarray of int (m,)
        Trailing ball of the first touching pair, -1 if none.
    contact_time : ndarray (m, n - 1)
        When pair j came into contact [s] (inf: never). Contacts persist to the horizon.
    contact_fraction : ndarray (m,)
        Fraction of the horizon with any ball-to-ball contact [-] (event-exact).
    contact_force_max : ndarray (m,)
        Largest ball-to-ball force over the horizon [N] (event-exact).
    clusters_formed : ndarray of int (m,)
        Multi-ball clusters that came into being (at t = 0 or at a merge); a merge of
        several clusters at one instant forms one cluster.
    cluster_count : ndarray of int (m,)
        Multi-ball clusters at the horizon.
    velocity, displacement, cluster : ndarray (m, n)
        At the horizon: loaded epsilon w_i [-], displacement u_i from the nominal motion [m]
        (z_i = z_i(0) + v t / 2 + u_i), and the cluster label (its trailing ball).
    contact_force : ndarray (m, n - 1)
        Q_j at the horizon [N].
    net_push : ndarray (m, n)
        P_i at the horizon [N].
    travel : ndarray (S,) or None
        Carriage travel of the grid, v t, from 0 to v T [m].
    grid_displacement, grid_net_push, grid_cluster : ndarray (m, S, n) or None
        u_i [m], P_i [N] and the cluster label on the grid. The state just after an event
        holds at the event.
    grid_contact_force : ndarray (m, S, n - 1) or None
        Q_j [N] on the grid.
    segment_start : ndarray (m, n) or None
        Start times [s] of the piecewise-constant segments (the first is 0, then one per
        event time), padded with inf.
    segment_contact_force : ndarray (m, n, n - 1) or None
        Q_j [N] in each segment (NaN padding). Integrate a friction law over
        ``net_push(segment_contact_force)`` exactly with the segment durations.
    """

    valid: np.ndarray
    first_contact_time: np.ndarray
    first_contact_pair: np.ndarray
    contact_time: np.ndarray
    contact_fraction: np.ndarray
    contact_force_max: np.ndarray
    clusters_formed: np.ndarray
    cluster_count: np.ndarray
    velocity: np.ndarray
    displacement: np.ndarray
    cluster: np.ndarray
    contact_force: np.ndarray
    net_push: np.ndarray
    travel: np.ndarray | None = None
    grid_displacement: np.ndarray | None = None
    grid_contact_force: np.ndarray | None = None
    grid_net_push: np.ndarray | None = None
    grid_cluster: np.ndarray | None = None
    segment_start: np.ndarray | None = None
    segment_contact_force: np.ndarray | None = None


def train_contact_constant(initial_gap, velocity_deviation, creep_stiffness, groove_velocity,
                           horizon, *, braking_sensitivity=None, samples=0, segments=False):
    """Trains of balls with constant epsilon, event-driven and exact (Notes).

    Parameters
    ----------
    initial_gap : array_like, shape (m, balls - 1)
        Gaps between adjacent balls at t = 0 [m], finite and >= 0; a zero gap is a touching
        pair (it may separate at once).
    velocity_deviation : array_like, shape (m, balls)
        Free-rolling epsilon per ball [-], ball 0 trailing.
    creep_stiffness : array_like, broadcastable to (m, balls)
        K_i [N], > 0; inf for an anchor, 0 for a ball pushed along (Notes of
        :func:`cluster_velocities`); NaN marks an unresolved or sliding ball (the train is not
        followed).
    groove_velocity : float
        v [m/s], > 0.
    horizon : float
        Duration T [s], > 0 (a stroke); events after it are ignored.
    braking_sensitivity : array_like, optional
        c_i [1/N] of eq. (1), |c_i| K_i < 1; default 0; NaN as for K.
    samples : int
        Points of the carriage-travel grid (0: no grid; otherwise >= 2, from 0 to v T).
    segments : bool
        Also return the piecewise-constant segments (m x n x (n - 1) floats).

    Returns
    -------
    TrainResult

    Notes
    -----
    **Constant epsilon: the event-driven solution**

    Between events the velocities are constant, so the positions are linear in t and exact.

    *Theorem (clusters never split after t = 0).* Let cluster A (speed w_A) catch cluster B
    (w_B < w_A). The merged cluster C has w_C in (w_B, w_A) by (5), and its internal forces are

    * in A: R_j^C = R_j^A + (sum_{i<=j, A} kappa_i)(w_A - w_C) > R_j^A >= 0,
    * at the junction: kappa_A (w_A - w_C) = kappa_B (w_C - w_B) > 0,
    * in B: R_j^C = R_j^B + (sum_{i>j, B} kappa_i)(w_C - w_B) > R_j^B >= 0.

    So every contact force of C is positive and at least its value before the merge. With
    constant epsilon the forces of a cluster stay constant until its next merge, so no force
    ever returns to zero. Several merges at the same instant compose. If A catches B while B
    catches D, then w_AB > w_B > w_D. A pair resting at zero force next to B is caught as soon as
    B speeds up. Hence:

    * a split happens only at formation, i.e. at t = 0. Initial zero gaps join balls whose
      isotonic solution is several blocks: a merged cluster that "must split immediately". PAV
      of the initial chains gives the correct partition;
    * the events after t = 0 are only gaps closing (quasi-static, inelastic: no bounce). Each
      event adds at least one contact, so there are at most n - 1 events, and a train costs
      O(n^2) at worst;
    * once a pair is in contact it stays in contact until the horizon. Its force is
      non-decreasing, so the largest contact force is reached by the end. The time with any
      contact is the horizon minus the first contact time.

    In floating point the kernel still re-runs PAV at every event. Pairs already in contact are
    *bonded* (pooled without comparing means), which the theorem makes redundant in exact
    arithmetic and which keeps rounding from undoing a contact. Gaps are advanced as gaps (not
    as differences of positions). The closing pair is set to exactly zero, and so is every pair
    predicted to close within 1e-12 x horizon of it (simultaneous events).

    First contact. Before the first event every ball is a singleton, so w_i = epsilon_i
    exactly, and pair j closes at g_j / ((eps_j - eps_{j+1}) v / 2). This is the same
    expression as :func:`tolsim.study.pipeline.propagation.first_contact_constant`, evaluated in the
    same
    order, ties going to the smallest j. A pair closed at t = 0 with eps_j > eps_{j+1} is always
    in one block (a block boundary needs eps_j <= w_j <= w_{j+1} <= eps_{j+1}). A closed pair
    with eps_j <= eps_{j+1} can be pooled only together with such a pair. So the first contact
    time agrees bit for bit, and at t = 0 the reported pair is the smallest such j, as in
    propagation.

    **Quasi-static assumption (numbers)**

    Take a 10 mm steel ball: m = 7850 kg/m^3 x (4/3) pi (5 mm)^3 = 4.11 g. The creep stiffness is K
    ~ 3e2 to 1e4 N. :func:`tolsim.physics.velocity.analytic.analytic` gives 673 N for each ball of
    the paper's pair ([Lin2018] Sec. 3.2 case (a): N_y = 200 N, rho = -/+0.6, theta = 2 deg, 57 and
    226 N per contact), 705 N for the nominal ball at N_y = 200 N (141 N per contact) and 280 N at
    50 N (K ~ F^(2/3)); up to 1e4 N when K epsilon ~ a few N at epsilon ~ 1e-3. The groove speeds
    are v = 0.2 m/s (the brief) and v = 10 mm/s ([Lin2018] Table 1). The figures below take the
    paper's pair, K = 673 N, at the larger v; the time constants scale as 1 / K (2.4 times longer at
    280 N, still about 1.5e-6 s).

    * The creep law acts on a ball's relative speed as a viscous damper:
      P = K (2 u' / v - epsilon), so dP/du' = 2 K / v = 6.7e3 N s/m (K = 673 N, v = 0.2 m/s).
      The inertial time constant is m / (2 K / v) = 6.1e-7 s. It is 3.1e-8 s at 10 mm/s, and
      smaller again for larger K. A stroke lasts 0.5 s to seconds (the paper's pair touches at
      6.3 to 6.6 s, depending on the model of epsilon), so inertia is about 1e-6 of the horizon.
    * Two balls meet at (v / 2) delta epsilon = 0.1 m/s x 2e-3 = 2e-4 m/s. The impact momentum
      is m/2 x 2e-4 = 4.1e-7 N s, and the creep forces (K delta epsilon ~ 1 N) absorb it within
      about 1e-6 s. Over that time the balls move 2e-4 x 6.1e-7 = 1.2e-10 m, against gaps of
      1e-6 to 1e-4 m.
    * No bounce. The paper's pair pushes with Q = K epsilon_1 = 673 N x 0.789 % = 5.31 N after
      contact (epsilon = +-0.789 % from the full model, as configs/paper_case_study.toml; 5.07 N
      with the formula's +-0.754 %). The Hertz stiffness of two 10 mm balls at that force is
      k = (6 E*^2 R* Q)^(1/3) = 1.0e7 N/m (E* = 1.14e11 Pa, R* = 2.5 mm; [Johnson1985] Ch. 4).
      The damping ratio of their relative motion is zeta = (2 K / v) / (2 sqrt(2 k m)) =
      6.7e3 / 577 = 11.7 (K = 673 N, v = 0.2 m/s). It is larger at smaller Q, larger K or
      smaller v. The motion is overdamped: the contact is inelastic with no rebound, as assumed.
    * The balls are rigid. The Hertz approach at 5.3 N is 0.79 um per contact, which is the
      error in the positions of a cluster.
    * Creep forces build up over about one contact length rolled ([Johnson1985] Ch. 8,
      transient rolling). That is about 4 b / v = 2 ms at v = 0.2 m/s, or 40 ms at 10 mm/s,
      with b ~ 0.1 mm the semi-axis of a raceway contact along the rolling direction (paper's
      ball, 70 to 200 N per contact). This is the slowest transient, 1e-3 to 1e-2 of the
      horizon, and it displaces the balls by (v/2) delta epsilon x 2 ms ~ 0.4 um. It is an
      order estimate and is not modelled.

    **Outputs**

    :func:`train_contact_constant` returns a :class:`TrainResult`. It holds event-exact figures
    per train (first contact, contact time per pair, fraction of the horizon with any contact,
    largest contact force, clusters formed), the state at the horizon, optionally the state on
    a carriage-travel grid, and optionally the piecewise-constant segments. From the segments a
    caller can integrate any nonlinear friction law exactly: the carriage friction increase is
    sum_i (friction(P_i) - friction(0)), and P follows from the contact forces by
    :func:`net_push`.
    """
    gap = np.ascontiguousarray(initial_gap, dtype=np.float64)
    eps, stiffness, braking, shape = _train_arrays(velocity_deviation, creep_stiffness,
                                                   braking_sensitivity)
    if len(shape) != 2 or gap.shape != (shape[0], shape[1] - 1):
        raise ValueError(f"initial_gap {gap.shape} and velocity_deviation {shape} must "
                         "have shapes (m, balls - 1) and (m, balls)")
    if not np.all(np.isfinite(gap)) or np.any(gap < 0):
        raise ValueError("initial_gap must be finite and >= 0")
    if not (np.isfinite(groove_velocity) and groove_velocity > 0):
        raise ValueError(f"groove_velocity = {groove_velocity!r} must be > 0")
    if not (np.isfinite(horizon) and horizon > 0):
        raise ValueError(f"horizon = {horizon!r} must be > 0")
    if int(samples) != samples or samples < 0 or samples == 1:
        raise ValueError(f"samples = {samples!r} must be 0 (no grid) or an integer >= 2")
    m, n = shape
    samples = int(samples)
    horizon = float(horizon)
    sample_time = (horizon * np.arange(samples) / (samples - 1) if samples else np.empty(0))
    if samples:
        sample_time[-1] = horizon
    nseg = n if segments else 0

    first_time = np.empty(m)
    first_pair = np.empty(m, dtype=np.int64)
    contact_time = np.empty((m, n - 1))
    contact_fraction = np.empty(m)
    force_max = np.empty(m)
    clusters_formed = np.empty(m, dtype=np.int64)
    cluster_count = np.empty(m, dtype=np.int64)
    valid = np.empty(m, dtype=bool)
    velocity = np.empty((m, n))
    force = np.empty((m, n - 1))
    displacement = np.empty((m, n))
    label = np.empty((m, n), dtype=np.int32)
    grid_displacement = np.empty((m, samples, n))
    grid_force = np.empty((m, samples, n - 1))
    grid_push = np.empty((m, samples, n))
    grid_label = np.empty((m, samples, n), dtype=np.int32)
    segment_time = np.empty((m, nseg))
    segment_force = np.empty((m, nseg, n - 1))
    train_constant_kernel(
        gap, eps, stiffness, braking, 0.5 * float(groove_velocity), horizon, sample_time,
        first_time, first_pair, contact_time, contact_fraction, force_max, clusters_formed,
        cluster_count, valid, velocity, force, displacement, label,
        grid_displacement, grid_force, grid_push, grid_label, segment_time, segment_force)
    grid = samples > 0
    return TrainResult(
        valid=valid, first_contact_time=first_time, first_contact_pair=first_pair,
        contact_time=contact_time, contact_fraction=contact_fraction,
        contact_force_max=force_max, clusters_formed=clusters_formed,
        cluster_count=cluster_count, velocity=velocity, displacement=displacement,
        cluster=label, contact_force=force, net_push=net_push(force),
        travel=float(groove_velocity) * sample_time if grid else None,
        grid_displacement=grid_displacement if grid else None,
        grid_contact_force=grid_force if grid else None,
        grid_net_push=grid_push if grid else None,
        grid_cluster=grid_label if grid else None,
        segment_start=segment_time if segments else None,
        segment_contact_force=segment_force if segments else None,
    )


__all__ = [
    "CHUNK",
    "TIE_TOLERANCE",
    "TrainResult",
    "cluster_velocities",
    "cluster_velocities_kernel",
    "net_push",
    "step_clusters_kernel",
    "step_project_kernel",
    "train_constant_kernel",
    "train_contact_constant",
]
