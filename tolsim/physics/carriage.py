r"""The carriage: a rigid body on its ball tracks, with preload (tolsim issue 12, physics core).

Every ball of every track is the basic module of [Lin2018] (:mod:`tolsim.physics.static`): a
ball between a rail groove (flanks BL, BR, fixed) and a carriage groove (TR, TL). The
carriage grooves move with one rigid carriage; this module finds the carriage displacement
that balances the external load, and with it the four contacts of every ball.

Conventions (issue 12; kept exactly)
------------------------------------
*Carriage frame*: z along the rail, x lateral, y up (rail to carriage). The reference point
is midway between the tracks, at ball-centre height, in the middle of the rows.

*Track* t at (x_t, y_t) with orientation phi_t: the module's up (its +y, rail groove to
carriage groove) is e_2 = (-sin phi, cos phi) and its +x is e_1 = (cos phi, sin phi). E_t =
[e_1 e_2] maps module to carriage components. phi = 0 is the paper's module; the wrapped
two-row guide has the left track at x = -s/2 with phi = +90 deg, the right one at +s/2 with
phi = -90 deg. Ball j sits at z_j = (j - (n - 1)/2) pitch, ball 0 trailing.

*Carriage motion* q = (u_x, u_y, theta_x pitch, theta_y yaw, theta_z roll) (axial motion
free). A carriage point p = (x, y, z) moves by

    d(p) = B(p) q,   B(p) = [[1, 0, 0, z, -y], [0, 1, -z, 0, x]]

and the carriage groove of a ball translates by g = E_t^T d(p) in its module frame (the
groove's own small rotation is neglected, as the issue states).

*Ball forces*: the ball pushes its carriage groove with f = F_TR u_TR + F_TL u_TL (module
frame, u_i the unit vector from the ball centre to contact i). As in [Lin2018] Fig. 6 and
:func:`tolsim.physics.static.solve_static`, the load the top groove transmits to the ball is
(N_x, -N_y) = -f, i.e. N_x = -f_x (lateral, module +x) and N_y = f_y (normal, pressing the
groove onto the ball); the side-force ratio is rho = N_x / N_y. f acts on the carriage at the
ball's nominal centre p, as E_t f in the carriage frame; its generalised force is
B(p)^T E_t f = (f_x, f_y, -z f_y, z f_x, x f_y - y f_x) (carriage components), i.e. the
force and its moment about the reference point.

*External load* at the reference point: lateral force (+x), vertical force V (positive
downward, pressing the carriage onto the rail), pitch, yaw and roll moments about +x, +y, +z
(right-handed): Q = (lateral, -V, pitch, yaw, roll).

*Contact*: a ball of radius R_B + o/2 touches a flank arc of radius R_G centred at C with the
approach delta = |b - C| + R_B + o/2 - R_G and force F = K delta^1.5 while delta > 0, with K
the exact Hertz load-deflection constant of the ball in its gothic-arch flank
(:func:`tolsim.physics.hertz.hertz_constants`, ``load_deflection_constant``; [Johnson1985]
Sec. 4.2), the same K as :mod:`tolsim.physics.static`.

Equilibrium
-----------
Each ball: its centre P is in equilibrium against its four flanks for the groove translation
g (displacement control, :func:`tolsim.physics.static.solve_static_displacement`'s kernel,
reused here ball by ball). Its condensed tangent stiffness follows from the flank stiffnesses
k_i = F_i' u_i u_i^T + (F_i / |P - C_i|)(I - u_i u_i^T) (symmetric 2 x 2): with K_b, K_t the
sums over the rail and carriage flanks, the Schur complement of the ball's block

    S = K_t - K_t (K_b + K_t)^-1 K_t = -df/dg        (symmetric, positive semidefinite)

The carriage: R(q) = Q + sum_balls A^T f(A q) = 0 with A = E_t^T B(p), solved by Newton with
the analytic tangent K_c = sum_balls A^T S A (the carriage stiffness matrix, [N/m], [N m/rad]
and mixed [N/rad] = [N m/m] entries). R is minus the gradient of the convex potential
sum_i (2/5) K max(delta_i, 0)^2.5 - Q . q (the ball positions minimised out), which the line
search uses; a zero tangent (no preload, unloaded start) is regularised by the stiffness of
balls at a reference approach.

*Locked DOFs*: a ball in its gothic arch resists both translations of its groove in the module
plane, so the carriage can move without loading any ball exactly along the null space of the
stacked A (scaled so rotations are lengths). The DOFs are kept greedily in the order u_x, u_y,
pitch, yaw, roll while they raise the rank; the others are locked (held at zero). A load with
a component along that null space cannot be carried: ValueError. One straight track, for
example, locks roll, and carries a vertical load only if it passes through the track line.

A contact that opens is reported (``contact_count``), not an error. A carriage that lifts off
entirely (no carriage flank loaded, or the motion leaves the gothic arch) is a ValueError
naming the load.

How carriage loads map to the balls' side-force ratio
-----------------------------------------------------
Small-displacement rigid-body kinematics, linearised at the ball; each step is tested in
``tests/test_carriage.py`` (numbers for the [Lin2018] Table 1 ball, K = 2.345e10 N/m^1.5,
d = R_G - R_B = 0.4 mm).

1. *Which DOF a load excites.* By d(p) = B(p) q a yaw theta_y moves the grooves sideways by
   d_x = theta_y z, a pitch theta_x moves them vertically by d_y = -theta_x z (both odd in z,
   zero at the reference point), a vertical load moves them all by u_y, a lateral one by u_x.
   The external moment is balanced by the ball forces' moments: yaw by sum z f_x, pitch by
   -sum z f_y (f the ball's force on the carriage, carriage frame).
2. *Into the module frame.* g = E_t^T d: g_1 = cos(phi) d_x + sin(phi) d_y (side), g_2 =
   -sin(phi) d_x + cos(phi) d_y (normal). phi = 0: yaw -> g_1 = theta_y z, pitch and vertical
   -> g_2. Wrapped guide (phi = +/-90 deg): g_1 = +/-d_y (vertical and pitch become side
   displacements), g_2 = -/+d_x (lateral and yaw become normal displacements).
3. *Linearised ball.* With f = (-N_x, N_y) and S = -df/dg: dN_x = S_11 g_1 + S_12 g_2, dN_y =
   -S_12 g_1 - S_22 g_2. In the (BL, TR) and (BR, TL) diagonal directions a, b (at 45 deg) the
   flank stiffnesses are diagonal and the rail and carriage flanks of a pair act in series:
   S ~ (k_1 a a^T + k_2 b b^T) / 2 with k ~ F^(1/3), F_1 ~ 1 - rho, F_2 ~ 1 + rho ([Lin2018]
   Sec. 3.1), so S_12 / S_22 = +/-(k_1 - k_2)/(k_1 + k_2): zero without a side load (mirror
   symmetry). Preloaded, unloaded and at beta_0 = 45 deg, exactly K_t = K_b = (k_n + F0/d) I,
   S = (k_n + F0/d)/2 I with F0 = K (o/2)^1.5, k_n = 1.5 K (o/2)^0.5 (F0/d is 0.25 % of k_n
   at o = 3 um, where F0 = 43.1 N, N0 = 2 F0 cos(beta_0) = 60.9 N, k_n = 43.1 N/um, S =
   21.6 N/um).
4. *Wrapped guide, yaw moment M.* g_2 = -/+theta_y z, g_1 = 0, so it changes N_y along z and
   leaves N_x alone: N_y,j = N0 +/- M z_j / (2 sum z^2) (left/right track), theta_y = M / (2 S
   sum z^2) (K_yaw = 2 S sum z^2 = 0.118 N m/urad for six balls at 12.5 mm, o = 3 um), and
   N_x = 0 exactly for any M (module mirror symmetry). The Hertz correction to N_y is second
   order in M (1.6 % of the linear change at 1 N m). Once the balls already carry side load
   (a vertical load), S_12 != 0 drags N_x along: dN_x/dN_y = -(k_1 - k_2)/(k_1 + k_2) =
   -0.140 at rho0 = -0.40 (measured -0.138); each track still carries V/2.
5. *Wrapped guide, pitch moment P.* g_1 = -/+theta_x z: N_x,j = -/+P z_j / (2 sum z^2), N_y =
   N0 + O(P^2), so rho_j = N_x,j / N_y,j is nearly linear in z. Measured (o = 3 um, six balls
   at 12.5 mm): P = 5 N m, |rho| <= 0.45: R^2 = 0.99985 and the largest deviation from the
   least-squares line 0.54 % of the rho range (the end balls' N_y rises 3.5 %); P = 10 N m:
   R^2 = 0.9975, 2.2 %; P = 20 N m: the end balls go to two-point contact, R^2 = 0.947, 11.6 %.
6. *phi = 0 track, vertical load V and yaw M ([Lin2018] Fig. 8; the old per-ball rule).* g_1
   = theta_y z, g_2 = u_y for every ball and S_12 = 0 at rho = 0, so to first order N_x,j =
   S_11 theta_y z_j and, from sum z N_x = M, N_x,j = M z_j / sum z^2 at N_y = V/n: the old rule
   (``tolsim/io/config.py`` ``_loads``) is exactly the linearised carriage. Beyond it: N_y of
   a ball is even and convex in g_1 (the pair approaches are delta_v +/- c g_1 and F ~
   delta^1.5), so at the common u_y the end balls take more N_y and the middle ones less
   (sum N_y = V); rho is odd in M, so rho - rho_old = O(M^3). Default study (10 balls at
   10.05 mm, V = 10 x 200 N, M = 15 N m, no preload): theta_y = 57.3 urad, u_y = -9.21 um,
   max |rho - rho_old| = 0.0071 at the end balls (z = -/+45.2 mm: -/+0.4000 against
   -/+0.4071; 0.87 % of the rho range), 95 % of it from N_y = 203.4 N there (197.8 N in the
   middle); N_x is within 0.067 N of the old rule. With two balls (Fig. 8) the track is
   statically determinate: V = 400 N and M = 0.6 x 200 N x 10.5 mm = 1.26 N m give rho =
   (-0.6, +0.6) exactly, reading ball 0 (trailing) as the paper's Ball 1 (the faster ball
   behind, which runs into Ball 2).

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, IMECE2018-88033 (Sec. 2.1, Fig. 6).
.. [Johnson1985] K. L. Johnson, Contact Mechanics, Cambridge University Press, 1985.
"""

from dataclasses import dataclass

import numpy as np

from tolsim._jit import jit
from tolsim.physics.geometry import TABLE1, Bearing
from tolsim.physics.static import (
    _FLOOR_LENGTH,
    DEFAULT_MAX_ITER,
    DEFAULT_TOLERANCE,
    GrooveErrors,
    _check_solver_options,
    _displacement_one,
    _error_items,
    _flank,
    _hertz_k,
    _prepare,
)

#: Names of the carriage DOFs, in the order of the displacement vector and stiffness matrix.
DOFS = ("u_x", "u_y", "pitch", "yaw", "roll")
#: Units of the DOFs (displacement) and of the generalised loads.
DOF_UNITS = ("m", "m", "rad", "rad", "rad")
LOAD_UNITS = ("N", "N", "N m", "N m", "N m")
#: Default relative tolerance of the carriage force and moment balance.
CARRIAGE_TOLERANCE = 1e-11
#: Default cap on carriage Newton steps.
CARRIAGE_MAX_ITER = 60
#: Largest groove displacement [fraction of d = R_G - R_B] a Newton step may take, and the
#: largest total groove displacement before the carriage counts as lifted off.
_STEP_CAP = 0.05
_LIFT_OFF = 0.25


# --------------------------------------------------------------------------------------------
# Kernel
# --------------------------------------------------------------------------------------------
@jit
def carriage_balls_kernel(groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, beta0,
                          dist, k, tol, max_iter, out_dbeta, out_force, out_approach, out_ball,
                          out_load, out_converged, out_iter, out_count, out_residual,
                          out_stiffness, out_energy):
    """Displacement-controlled balls with their condensed stiffness and Hertz energy.

    Each ball is solved by :mod:`tolsim.physics.static`'s ``_displacement_one``; then
    out_stiffness[n] = K_t - K_t (K_b + K_t)^-1 K_t [N/m] (= -d f / d g, f the force of the
    ball on its carriage groove) and out_energy[n] = sum_i (2/5) K delta_i^2.5 [J].
    """
    floor = k * _FLOOR_LENGTH**1.5
    s0, c0 = np.sin(beta0), np.cos(beta0)
    cen = np.empty((4, 6))
    unit = np.empty((4, 2))
    for n in range(out_dbeta.shape[0]):
        _displacement_one(n, groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, s0,
                          c0, dist, k, tol, max_iter, floor, cen, unit, out_dbeta, out_force,
                          out_approach, out_ball, out_load, out_converged, out_iter, out_count,
                          out_residual)
        h = 0.5 * oversize[n if oversize.shape[0] > 1 else 0]
        px, py = out_ball[n, 0], out_ball[n, 1]
        kb11 = kb12 = kb22 = kt11 = kt12 = kt22 = 0.0
        energy = 0.0
        for i in range(4):  # cen holds the arc centres moved with the groove
            ux, uy, inv, delta, f, df = _flank(px, py, cen, i, dist, h, k)
            if f > 0.0:
                g = f * inv
                a11 = df * ux * ux + g * (1.0 - ux * ux)
                a12 = (df - g) * ux * uy
                a22 = df * uy * uy + g * (1.0 - uy * uy)
                energy += 0.4 * f * delta
                if i < 2:
                    kb11 += a11
                    kb12 += a12
                    kb22 += a22
                else:
                    kt11 += a11
                    kt12 += a12
                    kt22 += a22
        s11 = s12 = s22 = 0.0
        m11, m12, m22 = kb11 + kt11, kb12 + kt12, kb22 + kt22
        det = m11 * m22 - m12 * m12
        if kt11 + kt22 > 0.0 and det > 1e-14 * (m11 + m22) ** 2:
            # K_t M^-1 K_t with M^-1 = [[m22, -m12], [-m12, m11]] / det
            i11, i12, i22 = m22 / det, -m12 / det, m11 / det
            w11 = kt11 * i11 + kt12 * i12  # W = K_t M^-1
            w12 = kt11 * i12 + kt12 * i22
            w21 = kt12 * i11 + kt22 * i12
            w22 = kt12 * i12 + kt22 * i22
            s11 = kt11 - (w11 * kt11 + w12 * kt12)
            s12 = kt12 - 0.5 * ((w11 * kt12 + w12 * kt22) + (w21 * kt11 + w22 * kt12))
            s22 = kt22 - (w21 * kt12 + w22 * kt22)
        out_stiffness[n, 0, 0] = s11
        out_stiffness[n, 0, 1] = s12
        out_stiffness[n, 1, 0] = s12
        out_stiffness[n, 1, 1] = s22
        out_energy[n] = energy


# --------------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CarriageLayout:
    """Tracks and balls of a carriage (SI units; conventions in the module docstring).

    Attributes
    ----------
    track_x, track_y : array_like, (n_tracks,)
        Ball-centre line of each track in the carriage frame [m].
    track_orientation : array_like, (n_tracks,)
        phi [rad]: module up = (-sin phi, cos phi), module +x = (cos phi, sin phi).
    balls_per_track : int
        n, balls in each track.
    ball_pitch : float
        Axial distance between neighbouring balls [m], >= 0.
    """

    track_x: np.ndarray
    track_y: np.ndarray
    track_orientation: np.ndarray
    balls_per_track: int
    ball_pitch: float

    def __post_init__(self):
        arrays = [np.atleast_1d(np.asarray(getattr(self, name), dtype=float))
                  for name in ("track_x", "track_y", "track_orientation")]
        if len({a.shape for a in arrays}) != 1 or arrays[0].ndim != 1 or arrays[0].size == 0:
            raise ValueError("track_x, track_y and track_orientation must be 1-D arrays of one "
                             f"common length >= 1, got shapes {[a.shape for a in arrays]}")
        if not all(np.all(np.isfinite(a)) for a in arrays):
            raise ValueError("track positions and orientations must be finite")
        if int(self.balls_per_track) != self.balls_per_track or self.balls_per_track < 1:
            raise ValueError(f"balls_per_track = {self.balls_per_track!r} must be a positive "
                             "integer")
        if not (np.isfinite(self.ball_pitch) and self.ball_pitch >= 0):
            raise ValueError(f"ball_pitch = {self.ball_pitch!r} must be >= 0")
        for name, arr in zip(("track_x", "track_y", "track_orientation"), arrays, strict=True):
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "balls_per_track", int(self.balls_per_track))
        object.__setattr__(self, "ball_pitch", float(self.ball_pitch))

    @property
    def n_tracks(self) -> int:
        return self.track_x.size

    @property
    def ball_z(self) -> np.ndarray:
        """z_j = (j - (n - 1)/2) pitch [m], ball 0 trailing."""
        n = self.balls_per_track
        return (np.arange(n) - 0.5 * (n - 1)) * self.ball_pitch

    def module_axes(self):
        """(e_1, e_2): module +x and up in the carriage frame, each (n_tracks, 2)."""
        c, s = np.cos(self.track_orientation), np.sin(self.track_orientation)
        return np.stack([c, s], axis=-1), np.stack([-s, c], axis=-1)

    def groove_map(self) -> np.ndarray:
        """A = E_t^T B(p) for every ball, (n_tracks, n, 2, 5): g = A q (module frame)."""
        t, n = self.n_tracks, self.balls_per_track
        x = np.broadcast_to(self.track_x[:, None], (t, n))
        y = np.broadcast_to(self.track_y[:, None], (t, n))
        z = np.broadcast_to(self.ball_z[None, :], (t, n))
        b = np.zeros((t, n, 2, 5))
        b[..., 0, 0] = 1.0
        b[..., 0, 3] = z
        b[..., 0, 4] = -y
        b[..., 1, 1] = 1.0
        b[..., 1, 2] = -z
        b[..., 1, 4] = x
        e1, e2 = self.module_axes()
        rot_t = np.stack([e1, e2], axis=1)  # rows e_1, e_2: E^T, (n_tracks, 2, 2)
        return np.einsum("tij,tnjk->tnik", rot_t, b)

    def length_scale(self) -> float:
        """Length [m] that makes rotations comparable with translations (>= 1 mm)."""
        z = self.ball_z
        r = np.hypot(self.track_x, self.track_y).max()
        return float(max(r, np.abs(z).max() if z.size else 0.0, 1e-3))


@dataclass(frozen=True)
class CarriageLoad:
    """External load on the carriage at the reference point (SI units).

    Attributes
    ----------
    lateral_force : float
        Along +x [N].
    vertical_force : float
        Positive downward, pressing the carriage onto the rail [N].
    pitch_moment, yaw_moment, roll_moment : float
        About +x, +y, +z, right-handed [N m].
    """

    lateral_force: float = 0.0
    vertical_force: float = 0.0
    pitch_moment: float = 0.0
    yaw_moment: float = 0.0
    roll_moment: float = 0.0

    def generalised(self) -> np.ndarray:
        """Q = (lateral, -vertical, pitch, yaw, roll), conjugate to q."""
        q = np.array([self.lateral_force, -self.vertical_force, self.pitch_moment,
                      self.yaw_moment, self.roll_moment], dtype=float)
        if not np.all(np.isfinite(q)):
            raise ValueError(f"load must be finite, got {self}")
        return q

    def describe(self) -> str:
        return (f"lateral {self.lateral_force:g} N, vertical {self.vertical_force:g} N, pitch "
                f"{self.pitch_moment:g} N m, yaw {self.yaw_moment:g} N m, roll "
                f"{self.roll_moment:g} N m")


@dataclass(frozen=True)
class CarriageSolution:
    """Equilibrium of one carriage assembly (ball arrays over (n_tracks, n); BL, BR, TR, TL).

    Attributes
    ----------
    contact_angle_deviation : ndarray, (n_tracks, n, 4)
        dbeta_i = beta_i - beta_0 [rad] of each ball in its module frame.
    normal_force : ndarray, (n_tracks, n, 4)
        F_i [N].
    approach : ndarray, (n_tracks, n, 4)
        delta_i [m] (negative: a gap, F_i = 0).
    contact_count : ndarray of int, (n_tracks, n)
        Flanks that carry force; fewer than 4 means contacts opened.
    side_load, normal_load : ndarray, (n_tracks, n)
        N_x, N_y [N]: the load the carriage groove transmits to the ball, lateral (module +x)
        and normal (pressing down in the module frame); (N_x, -N_y) = -(F_TR u_TR + F_TL u_TL).
    side_force_ratio : ndarray, (n_tracks, n)
        rho = N_x / N_y [-] (NaN where N_y <= 0).
    ball_displacement, groove_displacement : ndarray, (n_tracks, n, 2)
        Ball centre and carriage-groove translation in the module frame [m].
    ball_z : ndarray, (n,)
        Axial ball positions [m].
    displacement : ndarray, (5,)
        q = (u_x [m], u_y [m], pitch, yaw, roll [rad]).
    stiffness : ndarray, (5, 5)
        Tangent carriage stiffness dQ_ext/dq (rows and columns in ``DOFS`` order; N/m,
        N m/rad, and N/rad or N m/m off the diagonal blocks).
    locked : tuple of str
        DOFs held at zero because the layout cannot resist them.
    converged : bool
    iterations : int
        Carriage Newton steps.
    residual : ndarray, (5,)
        Q + sum of the ball forces and moments at the solution [N, N m].
    """

    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    approach: np.ndarray
    contact_count: np.ndarray
    side_load: np.ndarray
    normal_load: np.ndarray
    side_force_ratio: np.ndarray
    ball_displacement: np.ndarray
    groove_displacement: np.ndarray
    ball_z: np.ndarray
    displacement: np.ndarray
    stiffness: np.ndarray
    locked: tuple
    converged: bool
    iterations: int
    residual: np.ndarray


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------
def locked_dofs(layout: CarriageLayout):
    """DOFs the layout cannot resist, and the null space (scaled) they belong to.

    Returns
    -------
    locked : tuple of str
        Names from ``DOFS`` held at zero.
    null_space : ndarray, (5, m)
        Orthonormal basis of the carriage motions that load no ball, in scaled coordinates
        (rotations multiplied by ``layout.length_scale()``).
    """
    scale = np.array([1.0, 1.0] + [1.0 / layout.length_scale()] * 3)
    g = (layout.groove_map() * scale).reshape(-1, 5)
    sv = np.linalg.svd(g, compute_uv=False)
    tol = 1e-9 * sv[0]
    rank = int(np.sum(sv > tol))
    free = []
    for j in range(5):
        trial = free + [j]
        if np.linalg.matrix_rank(g[:, trial], tol=tol) == len(trial):
            free = trial
    _, _, vt = np.linalg.svd(g)
    null = vt[rank:].T
    return tuple(DOFS[j] for j in range(5) if j not in free), null


def _ball_inputs(layout, oversize, groove_errors, bearing):
    t, n = layout.n_tracks, layout.balls_per_track
    errors = GrooveErrors() if groove_errors is None else groove_errors
    items = [("groove_displacement", np.zeros((t, n, 2)), 2)]
    items += _error_items(errors, bearing)
    items.append(("oversize", 0.0 if oversize is None else oversize, 0))
    arrays, shape = _prepare(items, bearing)
    if shape != (t, n):
        raise ValueError(f"oversize and groove errors must broadcast to the balls (n_tracks, "
                         f"balls_per_track) = {(t, n)}, got {shape}")
    _, e_n, e_t, rot_b, rot_t, off_b, off_t, dd, extra = arrays
    total = np.ascontiguousarray(np.broadcast_to(dd[:, 0] + extra[:, 0], (t * n,)))
    return e_n, e_t, rot_b[:, 0].copy(), rot_t[:, 0].copy(), off_b, off_t, total


class _Balls:
    """Evaluates all balls of one assembly at a carriage displacement."""

    def __init__(self, inputs, bearing, nball, tol, max_iter):
        self.inputs = inputs
        self.beta0 = bearing.nominal_contact_angle
        self.dist = bearing.groove_radius - bearing.ball_radius
        self.k = _hertz_k(bearing)
        self.tol, self.max_iter, self.nball = tol, max_iter, nball

    def __call__(self, groove):
        n = self.nball
        out = dict(dbeta=np.empty((n, 4)), force=np.empty((n, 4)), approach=np.empty((n, 4)),
                   ball=np.empty((n, 2)), load=np.empty((n, 2)),
                   converged=np.empty(n, dtype=np.bool_), iterations=np.empty(n, np.int64),
                   count=np.empty(n, np.int64), residual=np.empty(n),
                   stiffness=np.empty((n, 2, 2)), energy=np.empty(n))
        carriage_balls_kernel(np.ascontiguousarray(groove), *self.inputs, self.beta0, self.dist,
                              self.k, self.tol, self.max_iter, *out.values())
        # force of the ball on its carriage groove, module frame: (-N_x, N_y)
        out["groove_force"] = np.stack([-out["load"][:, 0], out["load"][:, 1]], axis=-1)
        return out


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------
def solve_carriage(layout: CarriageLayout, load: CarriageLoad, bearing: Bearing = TABLE1, *,
                   oversize=None, groove_errors: GrooveErrors | None = None,
                   tol: float = CARRIAGE_TOLERANCE, max_iter: int = CARRIAGE_MAX_ITER,
                   ball_tol: float = DEFAULT_TOLERANCE,
                   ball_max_iter: int = DEFAULT_MAX_ITER) -> CarriageSolution:
    """Equilibrium of a rigid carriage on its preloaded ball tracks under a carriage load.

    Parameters
    ----------
    layout : CarriageLayout
        Tracks and balls.
    load : CarriageLoad
        External load at the reference point [N, N m].
    bearing : Bearing
        Ball, groove and material of every module (default [Lin2018] Table 1).
    oversize : array_like, optional
        Ball diametral oversize o [m] (nominal preload plus deviation), broadcast to
        (n_tracks, n); added to ``groove_errors.ball_oversize``. Default 0.
    groove_errors : GrooveErrors, optional
        Errors of each ball's module (fields broadcast to (n_tracks, n) + trailing axis), in
        the module frame as in :mod:`tolsim.physics.static`.
    tol : float
        Relative tolerance of the carriage balance: |force rows| <= tol F and |moment rows|
        <= tol F L, F the largest of the load and the contact forces, L
        ``layout.length_scale()``.
    max_iter : int
        Carriage Newton steps.
    ball_tol, ball_max_iter
        Tolerance and step cap of each ball's solve.

    Returns
    -------
    CarriageSolution

    Raises
    ------
    ValueError
        Bad input; a load the layout cannot carry (a component along a locked mechanism);
        a carriage that lifts off.
    """
    _check_solver_options(tol, max_iter)
    _check_solver_options(ball_tol, ball_max_iter)
    q_ext = load.generalised()
    t, n = layout.n_tracks, layout.balls_per_track
    nball = t * n
    inputs = _ball_inputs(layout, oversize, groove_errors, bearing)
    balls = _Balls(inputs, bearing, nball, ball_tol, ball_max_iter)
    length = layout.length_scale()
    scale = np.array([1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
    a = layout.groove_map().reshape(nball, 2, 5)
    a_s = a * scale  # groove map in scaled coordinates (rotations times L)
    q_s_ext = q_ext * scale  # moments / L
    locked, null = locked_dofs(layout)
    free = np.array([name not in locked for name in DOFS])
    load_norm = np.abs(q_s_ext).max()
    if null.shape[1] and load_norm > 0:
        along = null.T @ q_s_ext
        if np.abs(along).max() > 1e-9 * load_norm:
            raise ValueError(f"the track layout cannot carry the load ({load.describe()}): "
                             f"it has no stiffness against a motion of {', '.join(locked)}")
    dist = balls.dist
    k = balls.k

    def evaluate(q_s):
        groove = np.einsum("bik,k->bi", a_s, q_s)
        if np.abs(groove).max() > _LIFT_OFF * dist:
            return None
        out = balls(groove)
        out["groove"] = groove
        out["residual_q"] = q_s_ext + np.einsum("bik,bi->k", a_s, out["groove_force"])
        out["tangent"] = np.einsum("bik,bij,bjl->kl", a_s, out["stiffness"], a_s)
        out["potential"] = out["energy"].sum() - q_s_ext @ q_s
        return out

    def lift_off():
        return ValueError(f"the carriage lifts off the rail under the load ({load.describe()})")

    # reference approach and ball stiffness for the regularised start
    total_o = inputs[-1]
    f_ref = max(load_norm / nball, k * max(0.5 * float(total_o.max()), 0.0) ** 1.5)
    delta_ref = max((f_ref / k) ** (2.0 / 3.0), _FLOOR_LENGTH)
    k_ref = 1.5 * k * np.sqrt(delta_ref) * 0.5
    geometric = k_ref * np.einsum("bik,bil->kl", a_s, a_s)

    def scaled_norm(out):
        fmax = max(load_norm, float(out["force"].max()), k * _FLOOR_LENGTH**1.5)
        return np.abs(out["residual_q"][free]).max() / fmax

    q_s = np.zeros(5)
    out = evaluate(q_s)
    if out is None or not out["converged"].all():
        raise lift_off()
    converged = False
    it = 0
    while True:
        err = scaled_norm(out)
        if err <= tol:
            converged = True
            break
        if it >= max_iter:
            break
        it += 1
        kff = out["tangent"][np.ix_(free, free)]
        rf = out["residual_q"][free]
        w = np.linalg.eigvalsh(kff)
        wg = np.linalg.eigvalsh(geometric[np.ix_(free, free)])
        if w[0] <= 1e-10 * wg[-1]:  # zero (unloaded) or singular tangent: regularise
            if not (out["groove_force"] ** 2).sum() > 0 and it > 1:
                raise lift_off()
            kff = kff + geometric[np.ix_(free, free)]
        step = np.zeros(5)
        step[free] = np.linalg.solve(kff, rf)
        move = np.abs(np.einsum("bik,k->bi", a_s, step)).max()
        if move > _STEP_CAP * dist:
            step *= _STEP_CAP * dist / move
        slope = -rf @ step[free]  # d potential / d alpha at 0
        r2 = err
        alpha = 1.0
        trial = None
        for _ in range(40):
            cand = evaluate(q_s + alpha * step)
            if cand is not None and cand["converged"].all():
                trial = cand
                if (cand["potential"] <= out["potential"] + 1e-4 * alpha * slope
                        or scaled_norm(cand) < (1.0 - 1e-4 * alpha) * r2):
                    break
            alpha *= 0.5
        if trial is None:
            raise lift_off()
        q_s = q_s + alpha * step
        out = trial
    if not (out["groove_force"] ** 2).sum() > 0 and load_norm > 0:
        raise lift_off()

    shape4, shape2 = (t, n, 4), (t, n, 2)
    nx, ny = out["load"][:, 0], out["load"][:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(ny > 0, nx / np.where(ny > 0, ny, 1.0), np.nan)
    stiffness = out["tangent"] / np.outer(scale, scale)
    return CarriageSolution(
        contact_angle_deviation=out["dbeta"].reshape(shape4),
        normal_force=out["force"].reshape(shape4),
        approach=out["approach"].reshape(shape4),
        contact_count=out["count"].reshape(t, n),
        side_load=nx.reshape(t, n).copy(),
        normal_load=ny.reshape(t, n).copy(),
        side_force_ratio=rho.reshape(t, n),
        ball_displacement=out["ball"].reshape(shape2),
        groove_displacement=out["groove"].reshape(shape2),
        ball_z=layout.ball_z,
        displacement=q_s * scale,
        stiffness=stiffness,
        locked=locked,
        converged=bool(converged),
        iterations=it,
        residual=out["residual_q"] / scale,
    )


__all__ = [
    "CARRIAGE_MAX_ITER",
    "CARRIAGE_TOLERANCE",
    "DOFS",
    "CarriageLayout",
    "CarriageLoad",
    "CarriageSolution",
    "carriage_balls_kernel",
    "locked_dofs",
    "solve_carriage",
]
