"""The creep coefficients of a ball in a train from its own regime (issue 25, item 3).

A ball in regime A creeps (finite K); a ball in regime B is stiff (K from its stick line,
3e4 N and more); an exactly two-point ball is an *anchor* (K = inf: it keeps its speed under
a push until its capacity); an unloaded ball is *pushed along* (K = 0: no epsilon of its
own). :func:`regime_creep_coefficients` overrides the creep model's columns for those and
adds each ball's rolling angular velocity; a three-point ball creeps with the coefficients of
its own minimum of D (:mod:`tolsim.physics.trains.ball_minimum`, which also gives the pushes
at which a stuck contact lets go: train columns of a ball on a stick line, computed when a
push reaches it, :func:`settle_release_pushes`);
:func:`pair_braking` gives the ball-ball friction of a pair from the two balls' actual
rotations. The cluster rule with anchors is in the Notes of
:func:`tolsim.physics.trains.cluster_velocities`.
"""

import numpy as np

from tolsim.physics.geometry import TABLE1, Bearing
from tolsim.physics.trains.ball_minimum import (
    FREE_SOLVE_VELOCITY,
    RELEASE_INPUTS,
    contact_directions,
    release_pushes,
    stick_line_inputs,
    three_point_coefficients,
)
from tolsim.physics.velocity.analytic import LOAD_COLUMNS
from tolsim.physics.velocity.ball_loads import ball_contact_slip
from tolsim.physics.velocity.models import (
    BALL_REGIME_B,
    BALL_THREE_POINT,
    BALL_TWO_POINT,
    BALL_UNLOADED,
)

#: Columns of a train's per-ball coefficients: those of the creep model
#: (:data:`tolsim.physics.velocity.analytic.LOAD_COLUMNS`), then the ball's rolling angular
#: velocity Omega_perp R_B / v (x and y; NaN where no ball of the batch needs it), its
#: regime (:data:`tolsim.physics.velocity.models.BALL_REGIMES`; NaN: regime A only) and its
#: braking vector gamma [1/N] (x and y, NaN as the rates): d(epsilon)/dQ of a neighbour force Q
#: whose friction moment lies along the unit vector u is gamma . u (Notes of
#: :func:`directional_braking`), the pushes P = Q_back - Q_front [N] at which a ball on a stick
#: line (regime B, or three-point with a stuck contact) leaves it (forward > 0, backward < 0;
#: +-inf for every other ball; NaN while not yet computed, :func:`settle_release_pushes`), and
#: the inputs of those pushes (:data:`tolsim.physics.trains.ball_minimum.RELEASE_INPUTS`; NaN
#: where none are pending).
TRAIN_COLUMNS = (*LOAD_COLUMNS, "rolling_rate_x", "rolling_rate_y", "regime",
                 "braking_vector_x", "braking_vector_y", "release_push_forward",
                 "release_push_backward", *RELEASE_INPUTS)
#: Creep stiffness of an anchor and of a ball pushed along [N].
ANCHOR_STIFFNESS, PUSHED_STIFFNESS = np.inf, 0.0

_COL = {name: k for k, name in enumerate(TRAIN_COLUMNS)}
_INPUTS = slice(_COL[RELEASE_INPUTS[0]], _COL[RELEASE_INPUTS[-1]] + 1)


def rigid_rolling_rate(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """Omega_perp R_B / v of rigid rolling at the loaded contact centres (least squares).

    The rows v_B + w_x p_y - w_y p_x = V_i (V = 0 bottom, 1 top; R_B = v = 1) over the
    contacts with F_i > 0, as :func:`tolsim.physics.velocity.ball_loads.rolling_axis` but
    keeping the rate: (1 / (2 cos beta_0), 0) for the nominal ball. NaN where the rows do not
    fix (w_x, w_y) (fewer than three loaded contacts).

    Parameters
    ----------
    contact_angle_deviation, normal_force : array_like, shape (n, 4)

    Returns
    -------
    ndarray, shape (n, 2)
    """
    p = contact_directions(contact_angle_deviation, bearing)
    on = (np.asarray(normal_force, dtype=float) > 0.0)[..., None]
    rows = np.concatenate([np.ones(p.shape[:-1] + (1,)), p[..., 1:2], -p[..., 0:1]], axis=-1)
    rows = rows * on
    target = np.array([0.0, 0.0, 1.0, 1.0])[None, :, None] * on
    ata = np.einsum("nki,nkj->nij", rows, rows)
    atb = np.einsum("nki,nk->ni", rows, target[..., 0])
    out = np.full((len(p), 2), np.nan)
    good = np.abs(np.linalg.det(ata)) > 1e-12
    if good.any():
        out[good] = np.linalg.solve(ata[good], atb[good][..., None])[:, 1:, 0]
    return out


def two_point_rolling_rate(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """Omega R_B / v = (p_t,y, -p_t,x) / 2 of an exactly two-point ball (issue 25).

    p_t the direction to its loaded top contact: (cos beta, -sin beta) / 2 on the diagonal
    BL-TR, (cos beta, sin beta) / 2 on BR-TL. Both contacts stick, Omega . p = 0 (no spin),
    and the top contact moves at v: v_B + R (Omega x p_t)_z = v with v_B = v / 2.

    Returns
    -------
    ndarray, shape (n, 2)
    """
    p = contact_directions(contact_angle_deviation, bearing)
    force = np.asarray(normal_force, dtype=float)
    top = np.where(force[:, 2] > 0.0, 2, 3)
    pt = p[np.arange(len(p)), top]
    return 0.5 * np.stack([pt[:, 1], -pt[:, 0]], axis=-1)


def _solved_rows(solved, take):
    """The free solves of the balls ``take`` (a mask) from ``solved`` = (FullResult, rows), or
    None unless every one of them has its row."""
    if solved is None:
        return None
    result, rows = solved
    rows = np.asarray(rows).reshape(-1)[take]
    return result.take(rows) if (rows >= 0).all() else None


def regime_creep_coefficients(load, regime, contact_angle_deviation, normal_force,
                              bearing: Bearing = TABLE1, *, ball_friction=0.1,
                              lazy_release=False, rates=False, solved=None):
    """The train columns of balls from their regimes: anchors, soft balls, pushed balls.

    Parameters
    ----------
    load : ndarray, shape (n, len(LOAD_COLUMNS))
        The creep model's columns (regime A), NaN where it has none.
    regime : array_like of int, shape (n,)
        :data:`tolsim.physics.velocity.models.BALL_REGIMES` codes.
    contact_angle_deviation, normal_force : array_like, shape (n, 4)
        dbeta_i [rad], F_i [N].
    bearing : Bearing
    ball_friction : float
        mu_bb [-].
    lazy_release : bool
        Leave the release pushes of the balls on a stick line pending (NaN, with their
        inputs) for :func:`settle_release_pushes`, which computes them only for the balls a
        push reaches; else compute them here (the same numbers, bit for bit).
    rates : bool
        Give the rolling rates, regimes and braking vectors of the balls in regime A even
        when the batch holds no other (else left NaN there, their only use being a pair
        with a ball that is not in regime A): for balls that a train joins to balls of
        another batch (a circuit's entering balls), where :func:`pair_braking` would be
        NaN at such a pair.
    solved : (FullResult, ndarray of int (n,)), optional
        The free solves the caller already has (:func:`tolsim.physics.velocity.full.full`
        with its defaults, as the study's re-solves are made) and each ball's row in them (-1:
        none). The balls in regime B and three-point are not solved again when every one of
        them has its row (the same numbers, bit for bit); else they are.

    Returns
    -------
    ndarray, shape (n, len(TRAIN_COLUMNS))
        ``load`` unchanged for every ball in regime A (bit for bit), the columns of the Notes
        for the others, and the rolling rates and regimes when the batch holds any (or
        ``rates``).

    Notes
    -----
    **An exactly two-point ball** (both contacts stick, rolling at v / 2 with D = 0;
    :func:`tolsim.physics.velocity.regimes.two_point_loaded`). Under a push P and a
    neighbour-force sum S its force row f_b + f_t + P = 0 and its moment about the rolling
    axis -R (f_b - f_t) - mu_bb S R = 0 give F_c = f_t = (mu_bb S - P) / 2, and epsilon stays
    0 while |P| + mu_bb S <= 2 mu F. So its columns are exact: epsilon_free = 0, K = inf,
    c = 0, F_0 = 0, a = dF_c/dP = -1/2, b = dF_c/dS = mu_bb / 2, and the capacities
    P_cap = 2 mu F, S_cap = 2 mu F / mu_bb, between which the rolling range is the *line*
    |P| / P_cap + S / S_cap < 1 (the sliding check of an anchor in
    :mod:`tolsim.study.pipeline.track_friction`). F = the smaller of its two forces (they are
    equal in static equilibrium).

    **A ball in regime B** (one contact k stuck). Its states lie on the stick line
    v_B = V_k + w, Omega = (w / R) x_k; a push moves it along the line to the minimum of
    D_others(w) + mu_bb S |w| - P v_B, so dP - mu_bb dS = D''_others dw, and

        K = (v / 2) D''_others,   c = d(epsilon)/dS = -mu_bb / K                     (R1)

    (:func:`~tolsim.physics.trains.ball_minimum.stick_line_stiffness`): 3.3e4 N on case (a) at
    rho = -0.9 .. -0.98, against 110-750 N in regime A (issue 25), so it is a stiff ball rather
    than a rigid anchor: two balls in regime B of different epsilon pushed together share a
    finite force (as rigid anchors they could not roll together), and a soft neighbour's force
    is K_s K_B / (K_s + K_B) d(epsilon), 1-2 % below K_s d(epsilon). (Both contacts of a pair
    stuck, equal angles: rigid, K = inf, an anchor.) F_0 and Omega are those of its certified
    minimum of D (:func:`tolsim.physics.velocity.full.full`); a, b and the capacities are the
    creep model's (the loads split between the grooves about as in regime A). The pushes at
    which the stuck contact lets go before P_cap (columns ``release_push_forward``,
    ``_backward``, :func:`~tolsim.physics.trains.ball_minimum.stick_line_release`, the fast
    form of :func:`~tolsim.physics.trains.ball_minimum.stick_release`) are not symmetric and
    can be small: in case (a) at rho = -0.9 (K = 32 698 N, eps 0.030 %) +2.94 N and -22.6 N,
    at rho = -0.95 +33.4 N and -51.2 N, against P_cap ~ mu sum F = 56.6 N (checked with the
    independent minimiser of D - P v_B: eps 0.0386 % at +2.65 N, 2.09 % at +3.24 N). Beyond
    it the ball leaves the stick line for the other branch (regime A's larger epsilon),
    which a linear K cannot follow: a train in which a ball in regime B is pushed past one
    of them is unresolved from that step on, counted apart from those with a sliding ball
    (``RELEASED``, the sliding check of :mod:`tolsim.study.pipeline.friction_kernels`). The
    pushes cost a scan each (0.5-1.5 ms per ball), so with ``lazy_release`` they are left
    pending and computed only for the balls a push reaches (:func:`settle_release_pushes`,
    after a train's forces are known; a ball without a push cannot let go). Not modelled: the
    released state's own coefficients (regime A of the same contacts under that push).

    **A three-point ball** (one contact open) creeps with the coefficients of its own minimum
    of D (:func:`~tolsim.physics.trains.ball_minimum.three_point_coefficients`): K and c from
    the Hessian there (smooth) or from its stick line (one contact stuck), a =
    -(1 + epsilon) / 2 and b = mu_bb R_B |Omega_perp| / v exactly (envelope theorem), the
    capacities of its three loaded contacts, and its actual rotation. On a stick line it has
    release pushes as a ball in regime B: the line's minimum of D - P v_B stops being the
    minimum overall where the stuck contact's support function no longer outweighs the
    slope of the others off the line, the condition of
    :func:`~tolsim.physics.trains.ball_minimum.stick_release`, in which the open contact
    (F = 0) drops out of D and of sum F (case (a) at rho = -0.85 with BR open: K = 32 091 N,
    +17.08 N and -39.82 N, confirmed by the independent minimiser of D - P v_B: eps jumps
    off the line between 0.97 and 1.03 of each push).

    **The braking vector** gamma (:func:`directional_braking`): c Omega_perp / |Omega_perp|
    in regime A (the creep model gives the response to a moment along the ball's own axis
    only; the rest, the response to a tilt of the moment, is O(dbeta) and vanishes for a
    mirror-symmetric ball, whose v_B is even in the tilt) and in regime B (exact on the stick
    line), the full vector of (T2) for a three-point ball, 0 for an anchor or a pushed ball.

    **An unloaded ball** has no raceway contact, so no raceway friction: F_c = 0 whatever the
    loads (F_0 = a = b = 0), no creep resistance (K = 0: it moves with whatever it touches,
    a null weight in the cluster rule) and nothing to slide on (capacities inf).
    """
    load = np.asarray(load, dtype=np.float64)
    n = len(load)
    regime = np.asarray(regime).reshape(n)
    out = np.full((n, len(TRAIN_COLUMNS)), np.nan)
    out[:, :len(LOAD_COLUMNS)] = load
    out[:, _COL["release_push_forward"]] = np.inf
    out[:, _COL["release_push_backward"]] = -np.inf
    out[:, _INPUTS] = np.nan
    two = regime == BALL_TWO_POINT
    stick = regime == BALL_REGIME_B
    three = regime == BALL_THREE_POINT
    pushed = regime == BALL_UNLOADED
    if not (rates or two.any() or stick.any() or three.any() or pushed.any()):
        return out
    dbeta = np.asarray(contact_angle_deviation, dtype=np.float64).reshape(n, 4)
    force = np.asarray(normal_force, dtype=np.float64).reshape(n, 4)
    mu = bearing.friction_coefficient
    rate = np.full((n, 2), np.nan)
    gamma = np.zeros((n, 2))
    soft = ~(two | stick | three | pushed)
    if soft.any():
        rate[soft] = rigid_rolling_rate(dbeta[soft], force[soft], bearing)
    if two.any():
        loaded = np.where(force[two] > 0.0, force[two], np.inf).min(axis=1)
        capacity = 2.0 * mu * loaded
        with np.errstate(divide="ignore"):
            braking_capacity = (capacity / ball_friction if ball_friction > 0
                                else np.full(len(capacity), np.inf))
        values = {"free_rolling_velocity_deviation": 0.0, "creep_stiffness": ANCHOR_STIFFNESS,
                  "braking_sensitivity": 0.0, "carriage_force": 0.0,
                  "free_rolling_carriage_force": 0.0, "carriage_force_per_push": -0.5,
                  "carriage_force_per_neighbour_force": 0.5 * ball_friction,
                  "traction_capacity": capacity, "braking_capacity": braking_capacity}
        for name, value in values.items():
            out[two, _COL[name]] = value
        rate[two] = two_point_rolling_rate(dbeta[two], force[two], bearing)
    if stick.any():
        stiffness, inputs, res = stick_line_inputs(dbeta[stick], force[stick], bearing,
                                                   result=_solved_rows(solved, stick))
        rows = np.flatnonzero(stick)
        out[rows, _COL["release_push_forward"]] = np.nan  # pending (NaN where uncertified)
        out[rows, _COL["release_push_backward"]] = np.nan
        out[rows, _INPUTS] = inputs
        out[rows, _COL["creep_stiffness"]] = stiffness
        with np.errstate(divide="ignore", invalid="ignore"):
            out[rows, _COL["braking_sensitivity"]] = np.where(np.isfinite(stiffness),
                                                              -ball_friction / stiffness, 0.0)
        out[rows, _COL["free_rolling_velocity_deviation"]] = res.velocity_deviation
        out[rows, _COL["free_rolling_carriage_force"]] = res.drag_force
        out[rows, _COL["carriage_force"]] = res.drag_force
        rate[stick] = res.angular_velocity[:, :2] * bearing.ball_radius / FREE_SOLVE_VELOCITY
    if three.any():
        columns, rate[three] = three_point_coefficients(dbeta[three], force[three], bearing,
                                                        ball_friction=ball_friction,
                                                        release_inputs=True,
                                                        result=_solved_rows(solved, three))
        for name, value in columns.items():
            out[three, _COL[name]] = value
        gamma[three] = out[three, _COL["braking_vector_x"]:_COL["release_push_forward"]]
        stuck = three & np.isfinite(out[:, _COL[RELEASE_INPUTS[0]]])
        out[stuck, _COL["release_push_forward"]] = np.nan  # pending
        out[stuck, _COL["release_push_backward"]] = np.nan
    if pushed.any():
        values = {"free_rolling_velocity_deviation": np.nan, "creep_stiffness": PUSHED_STIFFNESS,
                  "braking_sensitivity": 0.0, "carriage_force": 0.0,
                  "free_rolling_carriage_force": 0.0, "carriage_force_per_push": 0.0,
                  "carriage_force_per_neighbour_force": 0.0, "traction_capacity": np.inf,
                  "braking_capacity": np.inf}
        for name, value in values.items():
            out[pushed, _COL[name]] = value
    out[:, _COL["rolling_rate_x"]:_COL["regime"]] = rate
    out[:, _COL["regime"]] = regime
    # the own-axis response of the creep model (regime A) and of a stick line (regime B)
    axial = soft | stick
    with np.errstate(divide="ignore", invalid="ignore"):
        gamma[axial] = (out[axial, _COL["braking_sensitivity"], None] * rate[axial]
                        / np.hypot(rate[axial, 0], rate[axial, 1])[:, None])
    out[:, _COL["braking_vector_x"]:_COL["release_push_forward"]] = gamma
    if not lazy_release:
        settle_release_pushes(out, np.ones(n, dtype=bool), bearing)
    return out


def settle_release_pushes(coefficients, need, bearing: Bearing = TABLE1):
    """Compute the pending release pushes of the balls ``need``, in place, once each.

    Parameters
    ----------
    coefficients : ndarray, shape (..., len(TRAIN_COLUMNS))
        Train columns from :func:`regime_creep_coefficients` with ``lazy_release=True``.
    need : array_like of bool, shape coefficients.shape[:-1]
        The balls whose pushes are needed (a train's sliding check: a nonzero push on them).
    bearing : Bearing

    Returns
    -------
    int
        The balls computed: those ``need`` with pending inputs; their release columns then
        hold :func:`~tolsim.physics.trains.ball_minimum.release_pushes` (those of the eager
        :func:`regime_creep_coefficients`, bit for bit) and their inputs are cleared (NaN), so
        a second call computes nothing. A ball not computed keeps NaN pushes, which the
        sliding check never crosses, as a push of 0 crosses no release push.
    """
    pending = np.isfinite(coefficients[..., _COL[RELEASE_INPUTS[0]]]) & np.asarray(need)
    where = np.nonzero(pending)
    if not len(where[0]):
        return 0
    release = release_pushes(coefficients[where][:, _INPUTS], bearing)
    coefficients[(*where, _COL["release_push_forward"])] = release[:, 0]
    coefficients[(*where, _COL["release_push_backward"])] = release[:, 1]
    for k in range(_INPUTS.start, _INPUTS.stop):
        coefficients[(*where, k)] = np.nan
    return len(where[0])


def directional_braking(coefficients, stiffness, braking):
    """The train rule's K and c of balls braked along their pairs' actual rotations.

    Parameters
    ----------
    coefficients : ndarray, shape (..., n, len(TRAIN_COLUMNS))
        The train columns of the balls of trains (or of a carriage track's slots).
    stiffness, braking : ndarray, shape (..., n)
        K [N] and c [1/N] of the train rule (NaN K: unusable).

    Returns
    -------
    stiffness, braking : ndarray, shape (..., n)
        The inputs themselves where no pair holds a ball in regime B, three- or two-point
        (regime A unchanged, bit for bit); else K', c' of the Notes for the soft balls of
        such pairs (NaN K', c' = 0 where a compliance is not positive: unusable).

    Notes
    -----
    The friction moment of pair j on each of its balls is -mu_bb Q_j R_B W_hat_j, W_hat_j
    the direction of W_j = Omega_j + Omega_{j+1} (Notes of :func:`pair_braking`), not of the
    ball's own axis. A ball's epsilon responds to a moment along the unit u with gamma . u
    per newton of Q (``braking_vector``; gamma . Omega_hat = c), so ball i rolls at

        w_i = epsilon_i + Q_{i-1} (1 / K_i + c_back) - Q_i (1 / K_i - c_front),
        c_back = gamma_i . W_hat_{i-1},   c_front = gamma_i . W_hat_i,                   (T4)

    instead of eq. (1) of :func:`tolsim.physics.trains.cluster_velocities` with one c. (T4)
    is eq. (1) with

        1 / K' = 1 / K + (c_back - c_front) / 2,   c' = (c_back + c_front) / 2,

    (the same compliances 1/K' + c' = 1/K + c_back to a push from behind and 1/K' - c' =
    1/K - c_front from in front), so the cluster rule and the step projection take (K', c')
    unchanged; they need both compliances positive, |c'| K' < 1. Between two balls in regime
    A, or next to a ball pushed along (whose slip direction the model does not resolve,
    Notes of :func:`pair_braking`), the own-axis c is kept. The issue's example: a
    regime-A ball (0.707 v / R_B about x) in front of a two-point ball (0.5 v / R_B tilted
    by 45 deg) is braked along W_hat = (0.949, -0.316), so c_back = 0.949 c for a
    mirror-symmetric ball, not c.
    """
    stiffness = np.asarray(stiffness, dtype=np.float64)
    braking = np.asarray(braking, dtype=np.float64)
    coefficients = np.asarray(coefficients, dtype=np.float64)
    code = coefficients[..., _COL["regime"]]
    other = (code == BALL_REGIME_B) | (code == BALL_TWO_POINT) | (code == BALL_THREE_POINT)
    pushed = coefficients[..., _COL["creep_stiffness"]] == PUSHED_STIFFNESS
    mixed = (other[..., :-1] | other[..., 1:]) & ~(pushed[..., :-1] | pushed[..., 1:])
    if not mixed.any():
        return stiffness, braking
    rate = coefficients[..., _COL["rolling_rate_x"]:_COL["regime"]]
    w = rate[..., :-1, :] + rate[..., 1:, :]
    norm = np.hypot(w[..., 0], w[..., 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = w / norm[..., None]
    gamma = coefficients[..., _COL["braking_vector_x"]:_COL["release_push_forward"]]
    use = mixed & np.isfinite(norm) & (norm > 0.0)
    c_front = braking.copy()
    c_back = braking.copy()
    with np.errstate(invalid="ignore"):
        front = np.sum(gamma[..., :-1, :] * unit, axis=-1)
        back = np.sum(gamma[..., 1:, :] * unit, axis=-1)
    c_front[..., :-1] = np.where(use, front, braking[..., :-1])
    c_back[..., 1:] = np.where(use, back, braking[..., 1:])
    soft = np.isfinite(stiffness) & (stiffness > 0.0)
    changed = soft & ((c_front != braking) | (c_back != braking))
    if not changed.any():
        return stiffness, braking
    with np.errstate(divide="ignore", invalid="ignore"):
        push_back = 1.0 / stiffness + c_back
        push_front = 1.0 / stiffness - c_front
        k_new = 1.0 / (0.5 * (push_back + push_front))
        c_new = 0.5 * (c_back + c_front)
    usable = (push_back > 0.0) & (push_front > 0.0)
    stiffness = np.where(changed, np.where(usable, k_new, np.nan), stiffness)
    braking = np.where(changed, np.where(usable, c_new, 0.0), braking)
    return stiffness, braking


def pair_braking(coefficients, ball_friction=0.1):
    """The ball-ball friction term of each pair's carriage-friction slope [-].

    Parameters
    ----------
    coefficients : ndarray, shape (..., n, len(TRAIN_COLUMNS))
        The train columns of the balls of trains (or of a carriage track's slots).
    ball_friction : float
        mu_bb [-].

    Returns
    -------
    ndarray, shape (..., n - 1)
        B_j, so that pair j adds k_j Q_j = ((a_{j+1} - a_j) + B_j) Q_j to the carriage
        friction: b_j + b_{j+1} (bit for bit) where both balls are in regime A (four-point,
        every contact slipping),
        mu_bb |Omega_j + Omega_{j+1}|_perp R_B / v where one is not (regime B, three- or
        two-point),
        0 where one is pushed along.

    Notes
    -----
    **Braking from the actual rotations.** The surfaces of a pair slide at the contact with
    s = (Omega_j + Omega_{j+1}) x (R_B z) (:func:`tolsim.physics.velocity.ball_loads.
    ball_contact_slip`), |s| = R_B |W_perp|, W = Omega_j + Omega_{j+1}. The Coulomb force
    mu_bb Q opposes s, so its moment on *each* ball is -mu_bb Q R_B W_perp / |W_perp|: the
    direction of the sum of the rotations, not of the ball's own axis. For the power balance
    of ball i (Notes of :class:`tolsim.physics.velocity.ball_loads.BallLoadFields`,
    v F_c + P v_B = sum D + D_bb, where D at the minimum is stationary in the state) the
    first-order change of v F_c from that moment is its power, mu_bb Q R_B W_hat . Omega_i;
    summed over the two balls, mu_bb Q R_B |W_perp|. So the pair costs the carriage

        B_j = mu_bb R_B |Omega_j + Omega_{j+1}|_perp / v  per newton of Q_j.

    Two nominal balls (parallel axes, 0.707 v / R_B each): 1.414 mu_bb = mu_bb / cos(beta_0),
    the soft balls' b_j + b_{j+1}. A four-point ball (0.707 v / R_B about x) and a two-point
    one (0.5 v / R_B, tilted by 45 deg): |W| R_B = |(1.0607, -0.3536)| v = 1.118 v, not the
    1.207 v of parallel axes (issue 25). Between two soft balls the creep model's b's are kept
    (their axes differ by O(dbeta), and the hard requirement is regime A unchanged to the
    bit).

    **A ball pushed along** turns freely: its moment balance with Q_back = Q_front = Q asks
    W_back_hat = -W_front_hat, met by Omega_u = -(Omega_back + Omega_front) / 2, which leaves
    the run slipping at |Omega_front - Omega_back| R_B / 2 on each side: O(dbeta) between two
    balls of one regime. B = 0 is taken for its pairs (not modelled: a run of two or more
    pushed balls, whose alternating rotations slip at |Omega_a + Omega_b| R_B at one contact).
    """
    coefficients = np.asarray(coefficients, dtype=np.float64)
    b = coefficients[..., _COL["carriage_force_per_neighbour_force"]]
    base = b[..., :-1] + b[..., 1:]
    code = coefficients[..., _COL["regime"]]
    other = (code == BALL_REGIME_B) | (code == BALL_TWO_POINT) | (code == BALL_THREE_POINT)
    pushed = coefficients[..., _COL["creep_stiffness"]] == PUSHED_STIFFNESS
    mixed = other[..., :-1] | other[..., 1:]
    null = pushed[..., :-1] | pushed[..., 1:]
    if not (mixed.any() or null.any()):
        return base
    rate = np.zeros(coefficients.shape[:-1] + (3,))
    rate[..., :2] = coefficients[..., _COL["rolling_rate_x"]:_COL["regime"]]
    slip = np.linalg.norm(ball_contact_slip(rate[..., :-1, :], rate[..., 1:, :], 1.0), axis=-1)
    out = np.where(mixed, ball_friction * slip, base)
    return np.ascontiguousarray(np.where(null, 0.0, out))


__all__ = ["ANCHOR_STIFFNESS", "PUSHED_STIFFNESS", "TRAIN_COLUMNS", "directional_braking",
           "pair_braking", "regime_creep_coefficients", "rigid_rolling_rate",
           "settle_release_pushes", "two_point_rolling_rate"]
