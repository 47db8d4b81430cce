"""The comprehensive friction model ("full model") of one ball with four, three or two contacts.

One ball between a fixed bottom groove and a top groove moving at v along the rail (z), with
given contact angles beta_i and normal forces F_i ([Lin2018] Sec. 2, Fig. 2). Unknowns: the
ball velocity v_B and its angular velocity Omega = (omega_x, omega_y[, omega_z]). The model
(kinematics, friction, equilibrium, external loads), the quadrature and the solver are in the
Notes of :func:`full`; the Numba loops in :mod:`tolsim.physics.velocity._full_kernels`.

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033.
.. [Jones1959] A. B. Jones, "Ball motion and sliding friction in ball bearings", J. Basic
   Eng. 81 (1959) 1-12.
.. [Harris2007] T. A. Harris, M. N. Kotzalas, Advanced Concepts of Bearing Technology, 5th
   ed., CRC Press, 2007, Ch. 2 (rolling radius on the deformed surface).
.. [LeblancNelias2007] A. Leblanc, D. Nelias, "Ball motion and sliding friction in a
   four-contact-point ball bearing", J. Tribol. 129 (2007) 801-808.
"""

import operator
from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np

from tolsim.physics.geometry import (
    SIDE_SIGN_X,
    SIDE_SIGN_Y,
    TABLE1,
    ZERO_VELOCITY_SIGN,
    Bearing,
    check_bearing,
)
from tolsim.physics.hertz import bearing_constants
from tolsim.physics.velocity._contact_tables import (
    NEAR_FLOATS,
    TABLE_DEGREE,
    TABLE_PIECES,
    TABLE_SUBPIECES,
    near_kernel,
    sample_kernel,
)
from tolsim.physics.velocity._full_kernels import ball_loads_kernel, contact_friction_kernel
from tolsim.physics.velocity._regime_kernels import (
    REGIME_SMOOTH,
    REGIME_UNSOLVED,
    TWO_POINT_ANGLE_TOLERANCE,
    regime_kernel,
)
from tolsim.physics.velocity._smooth_kernels import (
    FULL_LOAD_COLUMNS,
    full_kernel,
    full_loaded_kernel,
)
from tolsim.physics.velocity.analytic import VelocityResult, as_ball_arrays
from tolsim.physics.velocity.ball_loads import DEFAULT_BALL_FRICTION, BallLoadFields, as_ball_loads

#: Default number of angular nodes per contact (full circle; see the convergence study in
#: ``tests/physics/test_full.py::test_grid_convergence`` and the Notes of :func:`full`).
DEFAULT_ANGULAR_NODES = 32
#: Default number of radial nodes per ray for the curved surface.
DEFAULT_RADIAL_NODES = 8
#: Exponent k of the angle map tan(phi) = tan(chi) / (b/a)^k (chosen by experiment: 0.3
#: gives the fastest convergence for b/a = 0.1-0.3).
ANGLE_MAP_EXPONENT = 0.3
#: Default tolerance on the normalised equilibrium residual max|load| / (mu sum F).
DEFAULT_TOLERANCE = 1e-10
#: Default iteration cap of the Newton solver.
DEFAULT_MAX_ITER = 60
#: Names of the surface models.
SURFACES = ("planar", "curved")


# --------------------------------------------------------------------------------------------
# Quadrature grid
# --------------------------------------------------------------------------------------------
@lru_cache(maxsize=32)
def quadrature_grid(angular_nodes, radial_nodes, ellipticity):
    """Nodes and weights of the polar quadrature about the zero-velocity point.

    Parameters
    ----------
    angular_nodes : int
        Nodes of the mapped trapezoidal rule over the full circle (pole inside); the cone
        rule (pole outside) uses ``max(8, angular_nodes // 2)`` Gauss-Legendre nodes.
    radial_nodes : int
        Gauss-Legendre nodes in theta along each ray (curved surface only).
    ellipticity : float
        b/a [-] (sets the angle map).

    Returns
    -------
    tuple of ndarray
        (cos phi, sin phi, weight) inside, (x, weight) of Gauss-Legendre on [-1, 1] for the
        cone, (t, weight) of Gauss-Legendre on [0, 1] for the radial rule.
    """
    q = ellipticity**ANGLE_MAP_EXPONENT
    chi = 2.0 * np.pi * np.arange(angular_nodes) / angular_nodes
    phi = np.arctan2(np.sin(chi), q * np.cos(chi))
    dphi = q / (q * q * np.cos(chi) ** 2 + np.sin(chi) ** 2)
    w_in = 2.0 * np.pi / angular_nodes * dphi
    xo, wo = np.polynomial.legendre.leggauss(max(8, angular_nodes // 2))
    xr, wr = np.polynomial.legendre.leggauss(radial_nodes)
    out = (np.cos(phi), np.sin(phi), w_in, xo, wo, 0.5 * (xr + 1.0), 0.5 * wr)
    for arr in out:
        arr.setflags(write=False)
    return out


@lru_cache(maxsize=32)
def contact_table(angular_nodes, ellipticity):
    """Piecewise Chebyshev fit of the planar contact integrals at d = 0 (issue 25's fast path).

    Parameters
    ----------
    angular_nodes : int
        As in :func:`quadrature_grid`: the fit is of that quadrature.
    ellipticity : float
        b/a [-].

    Returns
    -------
    ndarray, shape (4, TABLE_PIECES, 6, TABLE_DEGREE + 1)
        For x = p >= 0, x = p < 0 (|p| <= 1, pole inside), x = 1/p > 0 and x = 1/p < 0 (pole
        outside), on the dyadic pieces y = 1 - |x| in [2^-(k+1), 2^-k] (local variable
        s = 2^(k+2) y - 3 in [-1, 1]), the Chebyshev coefficients of (S_z, S_n / a, S_d / a)
        (outside: the last two times |x|) and of their derivatives in y.

    Notes
    -----
    With omega_z = 0 the pole (c, d) of a planar contact lies on its semi-major axis, d = 0,
    and the normalised integrals of ``planar_contact_integrals`` (S_z, and S_n / a, S_d / a)
    are functions of p = c/a and b/a alone; b/a is the same for every contact of a bearing.
    Each is smooth in p except at |p| = 1, where the pole crosses the edge of the ellipse and
    the quadrature changes rule; its singularities lie at |p| = 1 and, for the trapezoidal
    rule's nodes, at |p| = 1/|sin phi_j| > 1. In y = 1 - |x| every dyadic piece is therefore
    as far from the nearest singularity as it is wide, and a Chebyshev series of degree
    ``TABLE_DEGREE`` on it converges like 5.8^-n: the fit reproduces the quadrature to
    round-off (measured on 75 000 random poles: 1e-15 of the integrals' scale, S_d 3e-15
    relative; at |p| > 30 the quadrature's own S_n loses digits to cancellation, ~1e-16 p^2
    relative, and the smooth fit differs from it by that noise).
    Outside the ellipse S_n and S_d grow like |p|, so |x| S_n and |x| S_d are fitted (analytic
    at x = 0). Within 2^-TABLE_PIECES of |p| = 1 :func:`table_integrals` falls back to the
    quadrature. An evaluation costs about 0.2 us against 4 us for the quadrature of 32 nodes,
    and it gives the derivative in p, so the Newton of regime A has its exact Jacobian.
    """
    cin, sin_, win, xo, wo, _, _ = quadrature_grid(angular_nodes, 2, ellipticity)
    q = float(ellipticity)
    ndeg = TABLE_DEGREE + 1
    nodes = np.polynomial.chebyshev.chebpts1(ndeg)
    sub = TABLE_SUBPIECES
    npieces = TABLE_PIECES * sub
    # piece k sub + j: y 2^(k+1) = 1 + (j + (s + 1) / 2) / sub, s in [-1, 1]
    scale = np.repeat(2.0 ** (np.arange(TABLE_PIECES) + 1), sub)
    shift = np.tile(np.arange(sub), TABLE_PIECES)
    ys = (1.0 + (shift[:, None] + 0.5 * (nodes[None, :] + 1.0)) / sub) / scale[:, None]
    extra = -(-NEAR_FLOATS // ndeg)
    out = np.zeros((4, npieces + extra, 6, ndeg))
    vals = np.empty((ys.size, 4))
    for t, (table, sign) in enumerate(((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):
        sample_kernel(table, sign, ys.ravel(), q, cin, sin_, win, xo, wo, vals)
        vals3 = vals.reshape(npieces, ndeg, 4)
        # fitted at the y actually evaluated (x = 1 - y rounds near |p| = 1)
        s = 2.0 * ((vals3[:, :, 0] * scale[:, None] - 1.0) * sub - shift[:, None]) - 1.0
        coef = np.linalg.solve(np.polynomial.chebyshev.chebvander(s, TABLE_DEGREE),
                               vals3[:, :, 1:]).transpose(0, 2, 1)
        out[t, :npieces, :3] = coef
        out[t, :npieces, 3:, :-1] = (np.polynomial.chebyshev.chebder(coef, axis=2)
                                     * (2.0 * sub * scale)[:, None, None])
    near = np.zeros((4, extra * ndeg, 6))
    near_kernel(q, cin, sin_, win, xo, wo, near)
    out[:, npieces:] = near.reshape(4, extra, ndeg, 6).transpose(0, 1, 3, 2)
    out.setflags(write=False)
    return out


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class FullResult(VelocityResult):
    """Result of the full friction model for n balls.

    Besides the fields of :class:`~tolsim.physics.velocity.analytic.VelocityResult`
    (``zero_velocity_offset`` holds dgamma_i = s_i c_i / R_B [rad], ERRATA 6;
    ``velocity_deviation_eq22`` is None; ``valid`` is ``converged`` with four positive forces).

    Attributes
    ----------
    ball_velocity : ndarray, shape (n,)
        v_B [m/s].
    angular_velocity : ndarray, shape (n, 3)
        Omega = (omega_x, omega_y, omega_z) [rad/s].
    contact_offset_ratio : ndarray, shape (n, 4)
        c_i / a_i [-], the zero-velocity point's offset from the contact centre along x_i.
    spin_to_roll : ndarray, shape (n, 4)
        |omega_i| / |Omega - omega_i y_i| [-]: spin about the contact normal over the rolling
        angular velocity (tan beta_0 in the nominal case).
    drag_force : ndarray, shape (n,)
        Friction force of the ball on the moving (top) groove, along -z [N] (the bearing's
        friction per ball).
    residual : ndarray, shape (n,)
        max |equilibrium load| / (mu sum F) at the returned state [-] (moments over R_B).
    converged : ndarray of bool, shape (n,)
        residual <= tol.
    iterations : ndarray of int, shape (n,)
        Newton iterations (line-search evaluations in regime B).
    regime : ndarray of int, shape (n,)
        0 unsolved, 1 smooth minimum (every loaded contact slips: regime A), 2 one contact
        sticks (regime B), 3 exactly two-point rolling at v/2
        (:mod:`tolsim.physics.velocity.regimes`).
    stuck_contact : ndarray of int, shape (n,)
        Index (BL, BR, TR, TL) of the stuck contact in regime B, 4 (BL and TR) or 5 (BR and
        TL) when both contacts of an opposite pair with equal angles stick, else -1.
    certificate : ndarray, shape (n,)
        Least directional slope of D over the checked unit directions, over sum F [-]:
        ``-residual`` in regime A, the stuck contact's margin in regime B, 0 when two-point.
    """

    ball_velocity: np.ndarray
    angular_velocity: np.ndarray
    contact_offset_ratio: np.ndarray
    spin_to_roll: np.ndarray
    drag_force: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    regime: np.ndarray
    stuck_contact: np.ndarray
    certificate: np.ndarray

    def take(self, index):
        """The balls ``index`` (along the first axis) of this result, as a result."""
        return replace(self, **{f.name: getattr(self, f.name)[index] for f in fields(self)
                                if isinstance(getattr(self, f.name), np.ndarray)})


@dataclass(frozen=True, kw_only=True)
class LoadedFullResult(FullResult, BallLoadFields):
    """Result of :func:`full` for n balls under external loads (push, neighbours).

    The fields of :class:`FullResult` at the loaded state (``drag_force`` is
    ``carriage_force``), those of :class:`tolsim.physics.velocity.ball_loads.BallLoadFields`, and
    the
    dissipated powers. ``creep_stiffness`` and ``braking_sensitivity`` are the tangents at the
    loaded state (from the solver's Jacobian, :func:`_load_sensitivities`). A sliding ball
    has no rolling quasi-static state and ``valid`` False, ``creep_stiffness`` 0 (saturated),
    Omega and the powers NaN; ``converged``, ``residual`` and ``iterations`` are those of the
    capacity solve. Pushed beyond ``traction_capacity`` it runs away: epsilon and v_B are
    +-inf (the sign of P) and ``carriage_force`` is the saturated value of its sliding
    state. Braked beyond ``braking_capacity`` its rotation stalls: epsilon and
    ``carriage_force`` are NaN (its speed is not set by rolling).

    Attributes
    ----------
    contact_dissipated_power : ndarray, shape (n, 4)
        D_i = int mu sigma |slip| dA in each raceway contact [W], BL, BR, TR, TL.
    ball_contact_dissipated_power : ndarray, shape (n,)
        The ball's share of the ball-contact dissipation, mu_bb (Q_back + Q_front) R_B
        |Omega_perp| [W] (each contact dissipates the sum of its two balls' shares).
    dissipated_power : ndarray, shape (n,)
        sum D_i + the ball's share [W]; equals v F_c + P v_B (power balance).
    """

    contact_dissipated_power: np.ndarray
    ball_contact_dissipated_power: np.ndarray
    dissipated_power: np.ndarray


def _parse_grid(grid):
    if grid is None:
        return DEFAULT_ANGULAR_NODES, DEFAULT_RADIAL_NODES
    if np.ndim(grid) == 0:
        grid = (grid, DEFAULT_RADIAL_NODES)
    try:
        n_ang, n_rad = (operator.index(g) for g in grid)
    except (TypeError, ValueError):
        raise ValueError(f"grid must be None, an int or (angular, radial), got {grid!r}") from None
    if n_ang < 8 or n_rad < 2:
        raise ValueError(f"grid = {grid!r}: need >= 8 angular and >= 2 radial nodes (integers)")
    return n_ang, n_rad


def contact_friction(contact_offset_ratio, semi_major, semi_minor, *, lateral_offset_ratio=0.0,
                     grid=None):
    """Friction force and spin moment of one planar contact ([Lin2018] Eqs. 12-15, Fig. 4).

    Coulomb friction mu sigma (Eq. 11) against the rotational slip field omega_i about the
    zero-velocity point (c, d) (Eq. 8), integrated exactly over the Hertz ellipse (no
    linearisation); normalised by sgn(omega_i) mu F as in Fig. 4.

    Parameters
    ----------
    contact_offset_ratio : array_like
        c/a, offset of the zero-velocity point along the semi-major axis [-].
    semi_major, semi_minor : array_like
        a (across the groove) and b (along the rail) [m]; broadcast with the ratio.
    lateral_offset_ratio : array_like
        d/b, offset along the rail (non-zero only when omega_z != 0) [-].
    grid : None or int
        Angular nodes (default ``DEFAULT_ANGULAR_NODES``).

    Returns
    -------
    force_x, force_z : ndarray
        f_x / (sgn mu F) and f_z / (sgn mu F) [-], friction on the ball along x_i and z_i.
    spin_moment : ndarray
        M_O / (sgn mu F) [m], the resisting spin moment about the contact normal (Eq. 13,
        equal to 3/8 a E(e) at c = d = 0, Eq. 14).
    """
    n_ang, _ = _parse_grid(grid)
    try:
        arrays = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (
            contact_offset_ratio, lateral_offset_ratio, semi_major, semi_minor)))
    except ValueError:
        raise ValueError("contact_offset_ratio, lateral_offset_ratio, semi_major and "
                         "semi_minor do not broadcast") from None
    names = ("contact_offset_ratio", "lateral_offset_ratio", "semi_major", "semi_minor")
    for name, arr in zip(names, arrays, strict=True):
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite")
    ratio, lateral, a, b = (np.ascontiguousarray(arr.ravel()) for arr in arrays)
    if np.any(a <= 0) or np.any(b <= 0) or np.any(b > a):
        raise ValueError("need 0 < semi_minor <= semi_major")
    shape = arrays[0].shape
    cin, sin_, win, xo, wo, _, _ = quadrature_grid(n_ang, 2, float(np.median(b / a)))
    out = np.empty((ratio.size, 3))
    contact_friction_kernel(ratio, lateral, a, b, cin, sin_, win, xo, wo, out)
    return out[:, 0].reshape(shape), out[:, 1].reshape(shape), out[:, 2].reshape(shape)


def friction_loads(ball_velocity, angular_velocity, contact_angle, normal_force,
                   bearing: Bearing = TABLE1, *, groove_velocity=0.01, surface="planar",
                   grid=None):
    """Resultant friction loads on one ball in a given motion (the residual of Eq. 18).

    Parameters
    ----------
    ball_velocity : float
        v_B [m/s].
    angular_velocity : array_like, shape (3,)
        Omega [rad/s].
    contact_angle : array_like, shape (4,)
        beta_i [rad].
    normal_force : array_like, shape (4,)
        F_i [N].
    bearing, groove_velocity, surface, grid
        As in :func:`full`.

    Returns
    -------
    force_z : float
        Sum of the friction forces on the ball along z [N].
    moment : ndarray, shape (3,)
        Friction moment on the ball about its centre [N m].
    contact_force_z : ndarray, shape (4,)
        Friction force on the ball along z at each contact [N].
    dissipated_power : float
        sum int mu sigma |slip| dA [W]; the equilibrium of :func:`full` minimises it.
    """
    if surface not in SURFACES:
        raise ValueError(f"surface = {surface!r}; choose one of {SURFACES}")
    if not (np.isfinite(groove_velocity) and groove_velocity > 0):
        raise ValueError(f"groove_velocity = {groove_velocity!r} must be finite and > 0")
    omega = np.asarray(angular_velocity, dtype=np.float64)
    beta = np.asarray(contact_angle, dtype=np.float64)
    force = np.asarray(normal_force, dtype=np.float64)
    if omega.shape != (3,) or beta.shape != (4,) or force.shape != (4,):
        raise ValueError("angular_velocity must have shape (3,), contact_angle and "
                         "normal_force shape (4,)")
    if np.any(force < 0) or not np.all(np.isfinite(force)):
        raise ValueError("normal_force must be finite and >= 0")
    n_ang, n_rad = _parse_grid(grid)
    hc = bearing_constants(bearing)
    radius, v = bearing.ball_radius, float(groove_velocity)
    a = hc.semi_major_coefficient * np.cbrt(force) / radius
    b = hc.semi_minor_coefficient * np.cbrt(force) / radius
    rd = deformed_surface_radius(bearing) / radius
    hoff = np.sqrt(1.0 - a * a) - np.sqrt(rd * rd - a * a)
    state = np.array([ball_velocity / v, *(omega * radius / v)])
    px = SIDE_SIGN_X * np.sin(beta)
    py = SIDE_SIGN_Y * np.cos(beta)
    loads = np.empty(5)
    contact = np.empty((4, 5))
    grid_arrays = quadrature_grid(n_ang, n_rad, hc.ellipticity)
    with np.errstate(divide="ignore", invalid="ignore"):
        ball_loads_kernel(state, px, py, np.array([0.0, 0.0, 1.0, 1.0]), force, a, b,
                          1.5 / np.pi, surface == "curved", rd, hoff, *grid_arrays, loads,
                          contact)
    mu = bearing.friction_coefficient
    return mu * loads[0], mu * radius * loads[1:4], mu * contact[:, 2], mu * v * loads[4]


def deformed_surface_radius(bearing: Bearing = TABLE1):
    """Radius of the deformed contact surface in the cross-section, 2 f D / (2 f + 1) [m].

    ([Harris2007] Ch. 2, after [Jones1959]; D = 2 R_B the ball diameter.)
    """
    f = bearing.conformity
    return 2.0 * f * (2.0 * bearing.ball_radius) / (2.0 * f + 1.0)


def within_model(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1):
    """The balls whose contacts the full model describes, per ball: (angles, ellipses).

    ``angles``: every contact angle beta_0 + dbeta inside (0, 90) deg; ``ellipses``: every
    contact ellipse's semi-major axis a = c F^(1/3) below R_B / 2 (Hertz's half-space no
    longer holds beyond). NaN inputs are outside. :func:`full` raises for a ball outside;
    a study counts such a ball unresolved instead (:func:`tolsim.study.pipeline.evaluate.
    full_velocity`, :func:`tolsim.study.execution.chunks.finish_spot_checks`).

    Parameters
    ----------
    contact_angle_deviation, normal_force : ndarray (..., 4)
        [rad], [N].
    bearing : Bearing

    Returns
    -------
    angles, ellipses : ndarray of bool (...)
    """
    beta = bearing.nominal_contact_angle + np.asarray(contact_angle_deviation, dtype=float)
    force = np.asarray(normal_force, dtype=float)
    with np.errstate(invalid="ignore"):
        angles = np.all((beta > 0) & (beta < 0.5 * np.pi), axis=-1)
        ellipses = np.all(bearing_constants(bearing).semi_major_coefficient * np.cbrt(force)
                          < 0.5 * bearing.ball_radius, axis=-1)
    return angles, ellipses


def full(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1, *,
         groove_velocity=0.01, surface="planar", free_spin=False, grid=None,
         tol=DEFAULT_TOLERANCE, max_iter=DEFAULT_MAX_ITER, push=None, neighbour_force=None,
         ball_friction=DEFAULT_BALL_FRICTION, nonsmooth=True) -> FullResult:
    """Velocity and friction of balls from the comprehensive friction model.

    Solves the quasi-static equilibrium of each ball (z force, x and y moments, and the z
    moment when ``free_spin``) under Coulomb friction integrated over the four Hertz
    ellipses ([Lin2018] Eqs. 1-13 and 18, nothing linearised; see the Notes of :func:`full`).
    Balls are solved in parallel over all cores.

    External loads (:mod:`tolsim.physics.velocity.ball_loads`): the push P adds to the z force, the
    ball-ball braking -mu_bb (Q_back + Q_front) R_B Omega_perp / |Omega_perp| to the moments.
    The ball is then solved three times (:func:`full_loaded_kernel`): free rolling (the
    baseline, the unloaded solve), the traction capacity (sliding between grooves at rest)
    and, unless |P| reaches the capacity (gross sliding), the loaded equilibrium.

    Parameters
    ----------
    contact_angle_deviation : array_like, shape (..., 4)
        dbeta_i [rad], BL, BR, TR, TL.
    normal_force : array_like, shape (..., 4)
        F_i [N] (>= 0; a zero force opens the contact, which is dropped: three- and two-point
        balls are solved, an unloaded or one-point ball is not).
    bearing : Bearing
        Geometry, material and friction coefficient.
    groove_velocity : float
        v, velocity of the top groove [m/s] (> 0). epsilon does not depend on it.
    surface : {"planar", "curved"}
        Contact surface: the paper's plane, or the deformed-surface arc of radius
        2 f D / (2 f + 1).
    free_spin : bool
        Leave omega_z free (and enforce the z moment); otherwise omega_z = 0 as in the paper.
    grid : None, int or (int, int)
        Angular nodes (and radial nodes, curved surface only); None for the defaults
        ``DEFAULT_ANGULAR_NODES``, ``DEFAULT_RADIAL_NODES``.
    tol : float
        Convergence tolerance on the normalised residual max|load| / (mu sum F) [-].
    max_iter : int
        Maximum Newton iterations.
    push : None or array_like, broadcast to the balls
        P = Q_back - Q_front [N], the neighbours' net push along +z. None: no push.
    neighbour_force : None or array_like, shape (..., 2)
        (Q_back, Q_front) >= 0 [N]; sets P and the ball-ball braking. Not with ``push``.
    ball_friction : float
        mu_bb [-] of the ball-ball contacts.
    nonsmooth : bool
        Solve every regime (default; :func:`tolsim.physics.velocity.regimes.stick_criterion`):
        open contacts, a sticking contact (regime B) and exactly two-point balls. False: the
        smooth Newton alone, on balls with four loaded contacts as before issue 25 (the
        baseline of the regime tests). Balls under ``push`` or ``neighbour_force`` are always
        solved by the smooth Newton (the loaded regimes are not built yet).

    Returns
    -------
    FullResult or LoadedFullResult
        ``valid`` is ``converged`` (the certificate of a minimum of D, see ``regime``; with
        ``nonsmooth=False`` or loads, also all four forces positive; with loads, the free
        solve converged and the ball not sliding). Non-convergence never raises. Without
        ``push`` and ``neighbour_force``: :class:`FullResult`, exactly as before; with either:
        :class:`LoadedFullResult`, whose epsilon is the unloaded one bit for bit when the loads
        are zero.

    Notes
    -----
    One ball between a fixed bottom groove and a top groove moving at v along the rail (z), with
    given contact angles beta_i and normal forces F_i ([Lin2018] Sec. 2, Fig. 2). Unknowns: the
    ball velocity v_B and its angular velocity Omega = (omega_x, omega_y[, omega_z]). Nothing is
    linearised:

    * **Kinematics** (Eqs. 1-9). The slip of the ball over groove i at a point r of the contact is
      dv = v_B z + Omega x r - V_i z (V = 0 bottom, v top), projected on the contact's tangent
      plane. Planar contact (default, as in the paper): r = R p_i + x x_i + z z_i, and the slip
      field is a rotation omega_i = Omega . y_i about the zero-velocity point (c_i, d_i) (Eq. 8),
      c_i = (v_B - V_i - R Omega . x_i) / omega_i, d_i = -R omega_z / omega_i.
      Curved contact (``surface="curved"``): the contact follows the deformed-surface radius
      R_d = 2 f D / (2 f + 1) in the cross-section ([Harris2007], after [Jones1959]),
      r = (h + sqrt(R_d^2 - x^2)) p_i + x x_i + z z_i with h = sqrt(R^2 - a^2) - sqrt(R_d^2 - a^2)
      (the ellipse's edges lie on the undeformed ball), so the rolling radius varies across the
      ellipse (Heathcote slip).
    * **Friction** (Eq. 11-13). Coulomb: traction -mu sigma dv/|dv| on the ball, with the Hertz
      pressure sigma = sigma_0 sqrt(1 - x^2/a^2 - z^2/b^2), sigma_0 = 3 F / (2 pi a b) (Eq. 11;
      the ellipse lies in the x-z plane, a across the groove, ERRATA 3-4). Forces and moments
      about the ball centre are the full 3-D sums of r x dF: the moment of contact i is
      -R f_i x_i - M_i y_i + R f_x,i z (planar), which is where ERRATA 8's sign comes from.
    * **Equilibrium** (Eq. 18 in full nonlinear form): sum of z forces, x and y moments (and the
      z moment when omega_z is free) vanish. Normal forces pass through the ball centre.

    External loads (issue 13; :mod:`tolsim.physics.velocity.ball_loads`): the neighbours' push P
    adds to the z force and their ball-to-ball braking -mu_bb (Q_back + Q_front) R_B Omega_perp /
    |Omega_perp| to the moments; the equations stay the gradient of a convex potential (D plus the
    braking term minus P v_B), which the solver minimises as before (:func:`full_loaded_kernel`).
    The ball's traction capacity is the same minimisation with both grooves at rest and v_B fixed;
    beyond it the ball slides.

    Quadrature (the direction field is singular at the zero-velocity point). The integrals are
    taken in polar coordinates *centred on the zero-velocity point*, in the coordinates
    (x/a, z/b) where the ellipse is the unit disc. For planar contact the slip direction is
    constant along each ray, so the radial integrals of the Hertz pressure are closed-form
    (``_full_kernels._ray_moments``); only the angular integral is numerical:

    * pole inside the ellipse: the angular integrand is smooth and periodic; the trapezoidal rule
      on a mapped angle tan(phi) = tan(chi) / q, q = (b/a)^0.3, clusters nodes where the
      direction field turns fast (phi ~ +-90 deg for a long thin ellipse); exponential
      convergence;
    * pole outside: the rays cover a cone of half-angle asin(1/|P|); Gauss-Legendre on it (the
      integrand vanishes linearly at the cone's edges and is analytic inside).

    For the curved surface the pole is the exact zero of the slip field (a quadratic), the
    direction still varies along each ray, and the radial integral uses Gauss-Legendre in
    theta (s = cos theta, which absorbs the sqrt of the pressure at the edge).
    Without spin (omega_i = omega_z = 0 to round-off: a contact rolling about its own x axis,
    as the stuck contact of regime B) the slip vanishes on the lines u_z(x) = 0, x = +-x_0,
    not at a point, and its direction jumps across them: the polar rule about one point of
    them converged at first order, and not at all in the radial nodes (4 % between 8 and 32
    at x_0 = a / 2; issue 25). There x is split at -x_0, 0 and x_0 and each piece integrated
    by a Gauss-Legendre product rule (third order in the nodes, independent of the radial
    ones), and a stuck contact (x_0 = 0, one double line through the pole) by the polar rule
    split at that line, Gauss-Legendre on each side (exponential)
    (:mod:`tolsim.physics.velocity._curved_kernels`, tests/physics/test_curved_zero_spin.py).

    The equilibrium is solved per ball by a damped Newton method (central-difference Jacobian,
    backtracking line search, Levenberg-Marquardt fallback) from pure rolling at the contact
    centres (least squares over the four contacts). The equations are the gradient of the
    dissipated power D(v_B, Omega) = sum int mu sigma |slip| dA, which is convex, so a step is
    also accepted when it decreases D (Armijo). Non-convergence is a flag (``converged``), never
    an exception. Without loads on the planar surface with omega_z = 0 (issue 25's fast path)
    every pole lies on its contact's semi-major axis, and the contact integrals of the given
    grid are taken from a piecewise Chebyshev fit of them in c/a (:func:`contact_table`; the
    quadrature's values to round-off, 20 times cheaper, with their exact derivative). The same
    equations, start and step acceptance are then iterated by Newton's method with the exact
    Jacobian of the fit to 1e-2 ``tol``, plus one step that takes the answer to the root to
    round-off (median 3 steps of one evaluation each, against 7 steps and ~20 evaluations of
    the quadrature before;
    :func:`~tolsim.physics.velocity._contact_tables.table_newton_solve`); Broyden's method on
    the quadrature (:func:`~tolsim.physics.velocity._smooth_kernels.quasi_newton_solve`) and
    the damped Newton are the fallbacks. Regime B's stick line and certificate use the same
    tables.

    Near two-point contact (|rho| above about 0.87-0.90 with paired forces, issue 25; the
    switch is set by the criterion chi of :func:`tolsim.physics.velocity.regimes.stick_criterion`)
    one contact of the heavily loaded pair *sticks* (zero spin and zero slip at its centre):
    the minimum of D sits on a kink where the friction is set-valued, and the smooth residual
    cannot vanish. With ``nonsmooth`` (default) such balls are solved on the stick line and
    certified (regime B, :func:`tolsim.physics.velocity.regimes.stick_criterion`); without it
    they are returned with ``converged = False`` (residual ~1e-2).
    """
    if surface not in SURFACES:
        raise ValueError(f"surface = {surface!r}; choose one of {SURFACES}")
    if not (np.isfinite(groove_velocity) and groove_velocity > 0):
        raise ValueError(f"groove_velocity = {groove_velocity!r} must be finite and > 0")
    if not (np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol = {tol!r} must be finite and > 0")
    if not (int(max_iter) == max_iter and max_iter >= 1):
        raise ValueError(f"max_iter = {max_iter!r} must be a positive integer")
    n_ang, n_rad = _parse_grid(grid)
    check_bearing(bearing)
    dbeta, force, shape = as_ball_arrays(contact_angle_deviation, normal_force)
    loaded = push is not None or neighbour_force is not None
    if loaded:
        load_p, load_q = as_ball_loads(push, neighbour_force, ball_friction, shape)
        if not bearing.friction_coefficient > 0:
            raise ValueError(f"friction_coefficient = {bearing.friction_coefficient!r}: a push "
                             "needs raceway friction (mu > 0) to be carried")
    angles_inside, ellipses_inside = within_model(dbeta, force, bearing)
    if not angles_inside.all():
        raise ValueError("contact_angle_deviation puts a contact angle outside (0, 90) deg")
    if not ellipses_inside.all():
        raise ValueError("normal_force too large: the contact ellipse exceeds R_B / 2")
    hc = bearing_constants(bearing)
    radius = bearing.ball_radius
    grid_arrays = quadrature_grid(n_ang, n_rad, hc.ellipticity)
    table = contact_table(n_ang, hc.ellipticity)
    n = len(dbeta)
    state = np.empty((n, 4))
    contact = np.empty((n, 4, 5))
    info = np.empty((n, 3))
    options = (surface == "curved", deformed_surface_radius(bearing) / radius, bool(free_spin),
               float(tol), int(max_iter))
    regime = None
    with np.errstate(divide="ignore", invalid="ignore"):
        if nonsmooth and not loaded:
            regime = np.empty((n, 3))
            regime_kernel(dbeta, force, bearing.nominal_contact_angle,
                          hc.semi_major_coefficient / radius, hc.semi_minor_coefficient / radius,
                          hc.elliptic_e, *options, *grid_arrays, table, state, contact, info,
                          regime)
        else:
            full_kernel(dbeta, force, bearing.nominal_contact_angle,
                        hc.semi_major_coefficient / radius, hc.semi_minor_coefficient / radius,
                        *options, *grid_arrays, table, state, contact, info)
    free = _full_fields(state, contact, info, force, shape, bearing, hc, groove_velocity,
                        regime)
    if not loaded:
        return FullResult(**free)
    mu = bearing.friction_coefficient
    braking = float(ball_friction) / mu * load_q
    state = np.empty((n, 4))
    contact = np.empty((n, 4, 6))
    info = np.empty((n, 3))
    load = np.empty((n, len(FULL_LOAD_COLUMNS)))
    with np.errstate(divide="ignore", invalid="ignore"):
        full_loaded_kernel(dbeta, force, load_p / mu, braking, bearing.nominal_contact_angle,
                           hc.semi_major_coefficient / radius,
                           hc.semi_minor_coefficient / radius, *options, *grid_arrays, table,
                           state, contact, info, load)
    return _loaded_full_result(state, contact, info, load, force, shape, bearing, hc,
                               groove_velocity, load_p, load_q, float(ball_friction), free)


def exactly_two_point(contact_angle_deviation, normal_force, bearing: Bearing = TABLE1,
                      ball_tolerance=None):
    """Balls that :func:`full` answers in closed form: exactly two-point, rolling at v/2.

    Parameters
    ----------
    contact_angle_deviation, normal_force : ndarray, shape (n, 4)
        dbeta_i [rad], F_i [N].
    bearing : Bearing
    ball_tolerance : float, optional
        The relative ball balance to which the static solve that gave the angles converged
        (``ball_tol`` of :func:`tolsim.physics.carriage.solve_carriage_batch`), when it is
        looser than round-off: the angles of an opposite pair are then taken as equal within
        2 ``ball_tolerance`` rad (Notes), if that is wider than the default 1e-9 rad.

    Returns
    -------
    ndarray of bool, shape (n,)
        Exactly two loaded contacts (F > 0), opposite (BL-TR or BR-TL), whose loaded angles
        differ by at most :data:`~tolsim.physics.velocity._regime_kernels.TWO_POINT_ANGLE_TOLERANCE`
        (1e-9 rad): the test of :func:`full`'s regime kernel on the planar surface, to the
        same floats (beta = beta_0 + dbeta). Such a ball has epsilon = 0, D = 0 and
        Omega = (v / 2R_B)(cos b*, -+sin b*, 0), ``regime`` two-point, ``converged`` and
        ``valid`` True, certificate 0 (issue 25); its other fields are those of :func:`full`.

    Notes
    -----
    Static equilibrium of a ball on two contacts makes them opposite and equal; the carriage
    solve leaves them equal to round-off (|dbeta_1 - dbeta_3| <= 1.1e-12 rad over 302 600
    two-point balls of ``configs/carriage_preload.toml`` at 0 and -5 um oversize along the
    track, at 20 steps), far inside the tolerance; a ball outside it (a two-point ball out of
    balance) is left to the full model.

    A solve to a looser ball balance leaves them further apart. The balance is relative:
    |r|_inf <= tol max(F_max, f_ref) (F_max the ball's largest force, f_ref the solve's
    reference ball force), with r = F_1 n_1 + F_3 n_3 for the opposite pair (1, 3) and n_3
    turned from -n_1 by delta = beta_3 - beta_1. The part of r across n_1 is F_3 sin(delta)
    and |r|_2 <= sqrt(2) |r|_inf, so for a ball that carries f_ref or more F_3 |delta| <=
    sqrt(2) tol F_max, and with F_3 / F_max >= 1 - tol, |delta| <= sqrt(2) tol / (1 - tol)
    < 2 tol (a lighter ball, up to 2 tol f_ref / F, is left to the full model beyond it).
    Such a ball is two-point to the solve's own accuracy (a balanced ball on two contacts
    has them opposite), and the full model's answer for the unbalanced one is the solve's
    error: along the track
    (:data:`tolsim.study.pipeline.carriage_track.TRACK_TOLERANCE`, 1e-4) the two-point balls
    of ``configs/carriage_preload.toml`` without preload under 3 000 N (200 assemblies, 52 800
    balls, session 28) had |delta| up to 6.6e-5 rad (median 2.7e-9, so most fell outside 1e-9
    rad), and the full model gave them |epsilon| <= 2.1e-10, in 90 % of the run's time.
    """
    beta = bearing.nominal_contact_angle + np.asarray(contact_angle_deviation, dtype=float)
    loaded = np.asarray(normal_force) > 0.0
    tolerance = TWO_POINT_ANGLE_TOLERANCE if ball_tolerance is None else max(
        TWO_POINT_ANGLE_TOLERANCE, 2.0 * float(ball_tolerance))
    with np.errstate(invalid="ignore"):
        equal = np.abs(beta[:, :2] - beta[:, 2:]) <= tolerance
    pair = loaded[:, :2] & loaded[:, 2:] & equal
    return (np.count_nonzero(loaded, axis=1) == 2) & (pair[:, 0] | pair[:, 1])


def _per_second(state, scale):
    """``state * scale``: a Newton that ran off leaves its last iterate (not converged, up to
    1e307, or +-inf for a ball that slides), whose units overflow to +-inf without a warning."""
    with np.errstate(over="ignore"):
        return state * scale


def _full_fields(state, contact, info, force, shape, bearing, hc, groove_velocity, regime=None):
    """The fields of :class:`FullResult` from the kernel's internal-unit outputs.

    ``regime`` (n, 3) from :func:`regime_kernel`; None for the smooth Newton alone (every
    converged ball is then regime A, and ``valid`` also needs four loaded contacts).
    """
    radius = bearing.ball_radius
    v = float(groove_velocity)
    mu = bearing.friction_coefficient
    converged = info[:, 2] > 0.5
    ratio = contact[:, :, 0]
    gamma = ZERO_VELOCITY_SIGN * ratio * (hc.semi_major_coefficient * np.cbrt(force)) / radius
    om = contact[:, :, 3]
    roll = contact[:, :, 4]
    # omega_i y_i removed from Omega leaves the in-plane part along x_i (omega_x, omega_y) and
    # omega_z; |Omega - omega_i y_i| = hypot(roll_i, omega_z).
    with np.errstate(divide="ignore", invalid="ignore"):
        spin_to_roll = np.abs(om) / np.hypot(roll, state[:, 3:4])
    drag = mu * (contact[:, 2, 2] + contact[:, 3, 2])
    if regime is None:
        valid = converged & np.all(force > 0, axis=1)
        code = np.where(converged, REGIME_SMOOTH, REGIME_UNSOLVED)
        stuck = np.full(len(state), -1)
        certificate = -info[:, 0]
    else:
        valid = converged
        code = regime[:, 0].astype(np.int64)
        stuck = regime[:, 1].astype(np.int64)
        certificate = regime[:, 2]
    eps = 2.0 * state[:, 0] - 1.0

    def shaped(arr, *tail):
        return arr.reshape(shape + tail)

    return dict(
        velocity_deviation=shaped(eps),
        valid=shaped(valid),
        zero_velocity_offset=shaped(gamma, 4),
        velocity_deviation_eq22=None,
        ball_velocity=shaped(state[:, 0] * v),
        angular_velocity=shaped(_per_second(state[:, 1:], v / radius), 3),
        contact_offset_ratio=shaped(ratio, 4),
        spin_to_roll=shaped(spin_to_roll, 4),
        drag_force=shaped(drag),
        residual=shaped(info[:, 0]),
        converged=shaped(converged),
        iterations=shaped(info[:, 1].astype(np.int64)),
        regime=shaped(code),
        stuck_contact=shaped(stuck),
        certificate=shaped(certificate),
    )


def _loaded_full_result(state, contact, info, load, force, shape, bearing, hc,
                        groove_velocity, load_p, load_q, ball_friction, free):
    """:class:`LoadedFullResult` from :func:`full_loaded_kernel`'s outputs (SI units)."""
    mu = bearing.friction_coefficient
    v = float(groove_velocity)
    sliding = load[:, 5] > 0.5
    runaway = (load[:, 5] > 0.5) & (load[:, 5] < 1.5)
    direction = np.where(load_p < 0, -1.0, 1.0)
    # a ball pushed beyond its capacity runs away: v_B -> +-inf, the friction saturates at
    # its sliding state; a stalled ball (braking) keeps NaN: its speed is not set by rolling
    state = state.copy()
    state[runaway, 0] = direction[runaway] * np.inf
    fields = _full_fields(state, contact[:, :, :5], info, force, shape, bearing, hc, v)
    carriage = fields["drag_force"].reshape(-1).copy()
    carriage[runaway] = mu * direction[runaway] * load[runaway, 1]
    with np.errstate(divide="ignore"):
        braking_capacity = (mu * load[:, 6] / ball_friction if ball_friction > 0
                            else np.full(len(load), np.inf))
    spin_perp = np.hypot(state[:, 1], state[:, 2])  # units of v / R_B
    ball_power = v * ball_friction * load_q * spin_perp
    contact_power = mu * v * contact[:, :, 5]
    with np.errstate(divide="ignore", invalid="ignore"):
        stiffness = np.where(sliding, 0.0, mu / load[:, 3])
    braking_sensitivity = ball_friction / mu * load[:, 4]
    braking_sensitivity[sliding] = np.nan
    free_valid = np.asarray(free["valid"]).reshape(-1)
    valid = fields["valid"].reshape(-1) & free_valid & ~sliding

    def shaped(arr, *tail):
        return np.asarray(arr).reshape(shape + tail)

    fields.update(valid=shaped(valid), drag_force=shaped(carriage))
    return LoadedFullResult(
        **fields,
        push=shaped(load_p),
        neighbour_force_sum=shaped(load_q),
        free_rolling_velocity_deviation=free["velocity_deviation"],
        carriage_force=shaped(carriage),
        free_rolling_carriage_force=free["drag_force"],
        creep_stiffness=shaped(stiffness),
        braking_sensitivity=shaped(braking_sensitivity),
        traction_capacity=shaped(mu * load[:, 0]),
        braking_capacity=shaped(braking_capacity),
        sliding=shaped(sliding),
        contact_dissipated_power=shaped(contact_power, 4),
        ball_contact_dissipated_power=shaped(ball_power),
        dissipated_power=shaped(contact_power.sum(axis=1) + ball_power),
    )
