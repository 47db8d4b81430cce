"""Carriage layout, load and results: tracks, balls and the rigid-body groove map."""

import enum
from dataclasses import dataclass

import numpy as np

#: Names of the carriage DOFs, in the order of the displacement vector and stiffness matrix.
DOFS = ("u_x", "u_y", "pitch", "yaw", "roll")
#: Units of the DOFs (displacement) and of the generalised loads.
DOF_UNITS = ("m", "m", "rad", "rad", "rad")
LOAD_UNITS = ("N", "N", "N m", "N m", "N m")


def end_relief(ball_z, zone_length: float, depth: float, length: float) -> np.ndarray:
    """Recess of the carriage flanks at the ends of the loaded zone (crowning) [m].

    h(z) = depth ((|z| - (L/2 - l)) / l)^2 for |z| > L/2 - l, else 0, with |z| taken at most
    L/2 (Notes); apply it as ``arc_centre_offset_normal`` of the TR and
    TL flanks.

    Parameters
    ----------
    ball_z : array_like
        Axial ball positions in the carriage frame [m].
    zone_length : float
        L, length of the loaded zone [m], > 0.
    depth : float
        Relief at the ends of the zone [m], >= 0 (0: none).
    length : float
        l, length of the relieved part at each end [m], 0 < l <= L/2 (ignored for depth 0).

    Returns
    -------
    ndarray
        h [m], the shape of ``ball_z``.

    Notes
    -----
    *End relief (crowning)* of the carriage grooves over a length l at each end of the loaded
    zone [-L/2, L/2]: the carriage flanks recede by

        h(z) = depth ((|z| - (L/2 - l)) / l)^2    for |z| > L/2 - l, else 0

    (:func:`end_relief`), applied as a normal arc-centre offset e_n of the TR and TL flanks (the
    sign of :class:`tolsim.physics.static.GrooveErrors`: positive opens clearance, the approach of
    a rigid ball falls by h). A preloaded ball in the error-free module, whose four approaches are
    o/2, re-centres when both carriage flanks recede by h: its four approaches become
    (o - h)/2 to first order (rail and carriage flanks in series), so it unloads as
    F = K ((o - h)/2)^1.5 and is free once h >= o (under an external load, the carriage's
    approach replaces o/2). h and dh/dz are continuous at L/2 - l, so a ball's load falls smoothly
    as it rolls towards an end, instead of dropping to zero at the edge of the zone.
    """
    z = np.abs(np.asarray(ball_z, dtype=float))
    if not depth > 0:
        return np.zeros(z.shape)
    if not (zone_length > 0 and 0 < length <= 0.5 * zone_length):
        raise ValueError(f"end relief length {length!r} m must be in (0, L/2 = "
                         f"{0.5 * zone_length!r} m]")
    start = 0.5 * zone_length - length
    u = (np.minimum(z, 0.5 * zone_length) - start) / length
    return np.where(u > 0.0, depth * u * u, 0.0)


# --------------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CarriageLayout:
    """Tracks and balls of a carriage (SI units; conventions in :func:`solve_carriage`).

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

    def groove_map_at(self, ball_z) -> np.ndarray:
        """A = E_t^T B(p) for balls at axial positions ``ball_z`` [m], shape (..., n_tracks,
        n) -> (..., n_tracks, n, 2, 5): :meth:`groove_map` with each ball at its own z."""
        z = np.asarray(ball_z, dtype=float)
        # rows e_1^T B and e_2^T B of A, e_1 = (c, s), e_2 = (-s, c), B as groove_map's
        c = np.cos(self.track_orientation)[:, None]
        s = np.sin(self.track_orientation)[:, None]
        x, y = self.track_x[:, None], self.track_y[:, None]
        out = np.empty(z.shape + (2, 5))
        out[..., 0, 0] = c
        out[..., 0, 1] = s
        out[..., 0, 2] = -s * z
        out[..., 0, 3] = c * z
        out[..., 0, 4] = s * x - c * y
        out[..., 1, 0] = -s
        out[..., 1, 1] = c
        out[..., 1, 2] = -c * z
        out[..., 1, 3] = -s * z
        out[..., 1, 4] = c * x + s * y
        return out

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


class CarriageStatus(enum.IntEnum):
    """Outcome of a carriage solve (:attr:`CarriageBatch.status`, :attr:`CarriageSolution.status`,
    :attr:`CarriageError.status`).

    CONVERGED
        The force and moment balance of the carriage and of every ball within tolerance.
    NOT_CONVERGED
        The Newton did not reach the tolerance within its steps; the last iterate is reported.
    LIFT_OFF
        No equilibrium exists: the load pulls the carriage away from every contact. Certified
        by a descent ray of the convex potential along which no contact closes before the
        grooves leave the gothic arch (Notes of :func:`solve_carriage`, "Settling").
    FAILED
        No answer within the model: the motion leaves the gothic arch (a quarter of d = R_G -
        R_B of groove travel) before an equilibrium, with contacts loaded or approaching (a
        load beyond the arch, or a clearance larger than it), or a ball solve failed.
    """

    CONVERGED = 0
    NOT_CONVERGED = 1
    LIFT_OFF = 2
    FAILED = 3

    def describe(self) -> str:
        """One line for messages."""
        return _STATUS_TEXT[self]


_STATUS_TEXT = {
    CarriageStatus.CONVERGED: "converged",
    CarriageStatus.NOT_CONVERGED: "the carriage Newton did not converge within max_iter steps",
    CarriageStatus.LIFT_OFF: "lifted off: the load pulls the carriage away from every contact "
                             "(no equilibrium)",
    CarriageStatus.FAILED: "failed: the motion leaves the gothic arch before an equilibrium "
                           "(contacts out of its reach, or a load beyond it), or a ball solve "
                           "failed",
}


class CarriageError(ValueError):
    """A carriage solve without an answer (:func:`solve_carriage`); ``status`` is
    :attr:`CarriageStatus.LIFT_OFF` or :attr:`CarriageStatus.FAILED`."""

    def __init__(self, message: str, status: CarriageStatus):
        super().__init__(message)
        self.status = CarriageStatus(status)


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
    status : CarriageStatus
        CONVERGED or NOT_CONVERGED (lift-off and failure raise :class:`CarriageError`).
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
    status: CarriageStatus = CarriageStatus.CONVERGED


@dataclass(frozen=True)
class CarriageBatch:
    """Equilibria of m sampled carriage assemblies (:func:`solve_carriage_batch`).

    Ball arrays are over (m, n_tracks, n), contacts BL, BR, TR, TL. An assembly with status
    ``LIFT_OFF`` or ``FAILED`` has NaN forces, angles, loads, displacement, stiffness and residual,
    and contact count 0. A ball outside the loaded zone (``loaded`` False in
    :func:`solve_carriage_batch`) has zero forces, contact count 0, NaN angles and loads, and
    counts as converged.

    Attributes
    ----------
    contact_angle_deviation : ndarray, (m, n_tracks, n, 4)
        dbeta_i = beta_i - beta_0 [rad] of each ball in its module frame.
    normal_force : ndarray, (m, n_tracks, n, 4)
        F_i [N].
    side_load, normal_load : ndarray, (m, n_tracks, n)
        N_x, N_y [N], as in :class:`CarriageSolution`.
    contact_count : ndarray of int8, (m, n_tracks, n)
        Flanks that carry force.
    ball_converged : ndarray of bool, (m, n_tracks, n)
        The ball's Newton converged (at the reported state; for a lifted-off assembly, in its
        last evaluation, False for balls not solved).
    displacement : ndarray, (m, 5)
        q = (u_x [m], u_y [m], pitch, yaw, roll [rad]) (``DOFS`` order).
    stiffness : ndarray, (m, 5, 5)
        Tangent carriage stiffness dQ_ext/dq, as :attr:`CarriageSolution.stiffness`.
    residual : ndarray, (m, 5)
        Q + sum of the ball forces and moments at the solution [N, N m].
    converged : ndarray of bool, (m,)
        ``status == STATUS_CONVERGED``.
    iterations : ndarray of int32, (m,)
        Carriage Newton steps (of the nested Newton where ``fallback``).
    status : ndarray of int8, (m,)
        :class:`CarriageStatus` codes: ``CONVERGED`` (0), ``NOT_CONVERGED`` (1: max_iter steps
        without reaching tol; the last iterate is reported), ``LIFT_OFF`` (2: no equilibrium,
        the load pulls the carriage off every contact) or ``FAILED`` (3: the motion left the
        gothic arch with contacts loaded, or a ball solve failed); ``BATCH_STATUS`` describes
        each.
    fallback : ndarray of bool, (m,)
        The joint Newton did not converge and the nested Newton solved the assembly.
    locked : tuple of str
        DOFs held at zero because the layout cannot resist them (the same for all).
    """

    contact_angle_deviation: np.ndarray
    normal_force: np.ndarray
    side_load: np.ndarray
    normal_load: np.ndarray
    contact_count: np.ndarray
    ball_converged: np.ndarray
    displacement: np.ndarray
    stiffness: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    fallback: np.ndarray
    locked: tuple


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

    Notes
    -----
    Remembered per layout (its values), as the along-track propagation solves the same layout
    at every step; a copy of the null space is returned.
    """
    key = (layout.track_x.tobytes(), layout.track_y.tobytes(),
           layout.track_orientation.tobytes(), layout.balls_per_track, layout.ball_pitch)
    if key not in _LOCKED:
        if len(_LOCKED) >= 64:
            _LOCKED.clear()
        _LOCKED[key] = _locked_dofs(layout)
    locked, null = _LOCKED[key]
    return locked, null.copy()


#: locked_dofs per layout.
_LOCKED = {}


def _locked_dofs(layout: CarriageLayout):
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
