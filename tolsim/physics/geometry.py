"""Bearing parameters, contact ordering and the sign conventions of the four contacts.

Coordinates (paper Fig. 2, Eqs. 1-9). Global frame fixed in space, origin at the ball centre:
x lateral (to the right), y up, z along the rail (the direction the top groove moves).
Contact i sits on the ball surface at

    BL: R(-sin b, -cos b)   BR: R(+sin b, -cos b)   TR: R(+sin b, +cos b)   TL: R(-sin b, +cos b)

(cross-section coordinates x, y), with b = beta_i measured from the -y axis (bottom) or the
+y axis (top). The local frame of contact i has y_i pointing from the contact centre to the
ball centre, z_i along the rail, and x_i = y_i x z_i.

Sign conventions derived here (ERRATA items 6 and 8) and checked in
``tests/physics/test_geometry.py``:

* ``ZERO_VELOCITY_SIGN`` s_i.  d(contact point)/d(beta_i) = s_i R x_i, so a zero-velocity point
  offset by dgamma_i (positive towards increasing beta_i, ERRATA 6) sits at local
  x_i = c_i = s_i R dgamma_i.  s = (-1, +1, -1, +1) for (BL, BR, TR, TL).
* ``SPIN_SIGN`` sgn(omega_i). omega_i = Omega . y_i is the spin of the ball about the inward
  contact normal (Eq. 7, 9).  Nominal rolling with the top groove moving at v > 0 needs
  Omega = (v / (2 R cos b0), 0, 0), which gives sgn(omega) = (+1, -1, -1, +1).
* Friction on the ball along z_i is f_i = sgn(omega_i) mu F_i k_f c_i / a_i (Eq. 17), i.e.
  f_i = mu k_f (R / a_i) F_i g_i dgamma_i with g_i = s_i sgn(omega_i) = (-1, -1, +1, +1).
* The moment about the ball centre from contact i is -R f_i x_i - M_i y_i, with M_i the spin
  moment of Eq. (13) (signed with omega_i).  The equilibrium rows of Eq. (18) are therefore
  sum f_i x_i + sum (M_i / R) y_i = 0: the spin-moment block enters with the sign opposite to
  the one printed (ERRATA 8); friction resists the spin.
"""

from dataclasses import dataclass

import numpy as np

from tolsim._jit import jit

#: Contact order used everywhere (paper Fig. 2).
CONTACTS = ("BL", "BR", "TR", "TL")

#: c_i = s_i R_B dgamma_i (ERRATA 6, derived in the module docstring).
ZERO_VELOCITY_SIGN = np.array([-1.0, 1.0, -1.0, 1.0])
#: sgn(omega_i) of the spin about the inward normal for a top groove moving at v > 0.
SPIN_SIGN = np.array([1.0, -1.0, -1.0, 1.0])
#: g_i = s_i sgn(omega_i): f_i = mu k_f (R/a_i) F_i g_i dgamma_i.
FRICTION_SIGN = ZERO_VELOCITY_SIGN * SPIN_SIGN
#: Lateral (x) sign of each contact position: BL, TL on the left.
SIDE_SIGN_X = np.array([-1.0, 1.0, 1.0, -1.0])
#: Vertical (y) sign of each contact position: bottom contacts below the centre.
SIDE_SIGN_Y = np.array([-1.0, -1.0, 1.0, 1.0])
#: Coefficients of the linearised parallel-zero-velocity-lines constraint (Eq. 21).
CONSTRAINT_SIGN = np.array([1.0, -1.0, -1.0, 1.0])

#: Linear slope of the normalised friction force against c/a over |c/a| < 0.5 ([Lin2018],
#: Sec. 2.3, read off Fig. 4).  See ERRATA 7: the slope at c/a = 0 is steeper.
K_F_PAPER = -1.38


@dataclass(frozen=True)
class Bearing:
    """Geometry, material and friction of one four-point-contact ball track.

    Defaults are [Lin2018] Table 1 (with ERRATA 1: E = 210 GPa).

    Parameters
    ----------
    ball_radius : float
        Ball radius R_B [m].
    conformity : float
        Groove conformity f = R_G / (2 R_B) [-], must exceed 0.5.
    nominal_contact_angle : float
        beta_0 [rad].
    youngs_modulus : float
        Young's modulus of ball and grooves [Pa].
    poisson_ratio : float
        Poisson's ratio of ball and grooves [-].
    friction_coefficient : float
        Coulomb coefficient mu of metal-to-metal contact [-].
    """

    ball_radius: float = 5.0e-3
    conformity: float = 0.54
    nominal_contact_angle: float = np.pi / 4
    youngs_modulus: float = 210.0e9
    poisson_ratio: float = 0.28
    friction_coefficient: float = 0.1

    def __post_init__(self):
        checks = {
            "ball_radius": self.ball_radius > 0,
            "conformity": self.conformity > 0.5,
            "nominal_contact_angle": 0 < self.nominal_contact_angle < np.pi / 2,
            "youngs_modulus": self.youngs_modulus > 0,
            "poisson_ratio": -1 < self.poisson_ratio < 0.5,
            "friction_coefficient": self.friction_coefficient >= 0,
        }
        for name, ok in checks.items():
            if not (ok and np.isfinite(getattr(self, name))):
                raise ValueError(f"{name} = {getattr(self, name)!r} is out of range")

    @property
    def groove_radius(self) -> float:
        """Groove (flank arc) radius R_G = 2 f R_B [m]."""
        return 2.0 * self.conformity * self.ball_radius


#: [Lin2018] Table 1 bearing.
TABLE1 = Bearing()
#: [Lin2018] Table 1: top-groove velocity v = 10 mm/s [m/s] and normal load N_y = 200 N.
TABLE1_GROOVE_VELOCITY = 10.0e-3
TABLE1_NORMAL_LOAD = 200.0


def check_bearing(bearing) -> None:
    """Raise a ValueError naming ``bearing`` unless it is a :class:`Bearing` (None, say)."""
    if not isinstance(bearing, Bearing):
        raise ValueError(f"bearing = {bearing!r:.60} must be a Bearing (tolsim.TABLE1 is the "
                         "paper's)")


def contact_frames(contact_angle):
    """Position and local axes of the four contacts in the cross-section.

    Parameters
    ----------
    contact_angle : array_like, shape (..., 4)
        beta_i [rad], ordered BL, BR, TR, TL.

    Returns
    -------
    position, x_axis, y_axis : ndarray, shape (..., 4, 2)
        Unit vector from the ball centre to the contact centre, and the local x_i and y_i
        axes (y_i inward), as (x, y) components in the global frame.
    """
    beta = np.asarray(contact_angle, dtype=float)
    s, c = np.sin(beta), np.cos(beta)
    sx, sy = SIDE_SIGN_X, SIDE_SIGN_Y
    position = np.stack([sx * s, sy * c], axis=-1)
    y_axis = -position
    # x = y x z  ->  (y_y, -y_x)
    x_axis = np.stack([y_axis[..., 1], -y_axis[..., 0]], axis=-1)
    return position, x_axis, y_axis


@jit(inline="always")
def paired_force_pair(side_load, normal_load, sin0, cos0):
    """The paired forces of one ball (:func:`paired_forces`): F_1 = F_BL = F_TR and
    F_2 = F_BR = F_TL [N] from N_x, N_y [N] and sin b0, cos b0 (the one definition of the
    formula; the kernels of the study call it per ball)."""
    # Top-groove equilibrium: the ball pushes the groove outward at TR, (+sin, +cos) F_TR, and
    # at TL, (-sin, +cos) F_TL, against the load (N_x, -N_y).  Ball equilibrium with equal
    # angles makes the diagonals equal: F_BL = F_TR, F_BR = F_TL.
    return ((normal_load / cos0 - side_load / sin0) / 2.0,
            (normal_load / cos0 + side_load / sin0) / 2.0)


@jit
def paired_forces_kernel(side_load, normal_load, sin0, cos0, out):
    """:func:`paired_force_pair` of n balls: ``side_load``, ``normal_load`` (n,) [N] into
    ``out`` (n, 4) as F_BL, F_BR, F_TR, F_TL."""
    for b in range(out.shape[0]):
        f1, f2 = paired_force_pair(side_load[b], normal_load[b], sin0, cos0)
        out[b, 0] = f1
        out[b, 1] = f2
        out[b, 2] = f1
        out[b, 3] = f2


def paired_forces(side_load, normal_load, nominal_contact_angle=np.pi / 4):
    """The paper's paired approximation of the four contact forces (Sec. 3.1).

    F_BL = F_TR = (N_y cos b0 - N_x sin b0) / sin(2 b0) and
    F_BR = F_TL = (N_y cos b0 + N_x sin b0) / sin(2 b0); at b0 = 45 deg this is the paper's
    F_1 = sqrt(2)/2 (N_y - N_x), F_2 = sqrt(2)/2 (N_y + N_x).

    Parameters
    ----------
    side_load : array_like
        N_x, lateral load on the top groove per ball [N] (positive towards +x).
    normal_load : array_like
        N_y, downward load on the top groove per ball [N].
    nominal_contact_angle : float
        beta_0 [rad].

    Returns
    -------
    ndarray, shape (..., 4)
        Normal forces F_BL, F_BR, F_TR, F_TL [N] (:func:`paired_force_pair` per ball). Not
        validated: a value <= 0 means the paired approximation predicts loss of contact.

    Raises
    ------
    ValueError
        For a missing load (None: numpy would read it as NaN) or a nominal contact angle
        outside (0, pi/2) (sin 2 b0 = 0 at either end).
    """
    for name, value in (("side_load", side_load), ("normal_load", normal_load)):
        if value is None:
            raise ValueError(f"{name} = None: give the load per ball [N]")
    if not 0.0 < nominal_contact_angle < 0.5 * np.pi:
        raise ValueError(f"nominal_contact_angle = {nominal_contact_angle!r} must lie in "
                         "(0, pi/2) [rad]")
    nx, ny = np.broadcast_arrays(np.asarray(side_load, dtype=float),
                                 np.asarray(normal_load, dtype=float))
    out = np.empty(nx.shape + (4,))
    paired_forces_kernel(np.ascontiguousarray(nx).reshape(-1),
                         np.ascontiguousarray(ny).reshape(-1),
                         np.sin(nominal_contact_angle), np.cos(nominal_contact_angle),
                         out.reshape(-1, 4))
    return out


@jit(inline="always")
def rigid_angle_deviations(tangential0, tangential1, tangential2, tangential3,
                           bottom_rotation, top_rotation, centre_distance):
    """Contact angle deviations of one ball in rigid grooves [rad], BL, BR, TR, TL.

    dbeta_BL = -theta_b, dbeta_BR = +theta_b ([Lin2018] Sec. 3.1, Fig. 6), likewise
    dbeta_TR = -theta_t, dbeta_TL = +theta_t for the top groove, plus t_i / (R_G - R_B) for
    a tangential offset t_i [m] of arc centre i (positive toward increasing beta_i; the
    contact lies on the line through the ball and arc centres, which are
    ``centre_distance`` = R_G - R_B apart). The one definition of the mapping (the study's
    ``paired`` model calls it, vectorised or per ball).
    """
    return (tangential0 / centre_distance - bottom_rotation,
            tangential1 / centre_distance + bottom_rotation,
            tangential2 / centre_distance - top_rotation,
            tangential3 / centre_distance + top_rotation)


@jit
def rigid_angle_deviations_kernel(tangential, bottom_rotation, top_rotation, centre_distance,
                                  out):
    """:func:`rigid_angle_deviations` of n balls: ``tangential`` (n, 4) [m], the rotations
    (n,) [rad], into ``out`` (n, 4) [rad]."""
    for b in range(out.shape[0]):
        d0, d1, d2, d3 = rigid_angle_deviations(
            tangential[b, 0], tangential[b, 1], tangential[b, 2], tangential[b, 3],
            bottom_rotation[b], top_rotation[b], centre_distance)
        out[b, 0] = d0
        out[b, 1] = d1
        out[b, 2] = d2
        out[b, 3] = d3


def contact_force_resultant(contact_angle, normal_force):
    """Net force of the four contacts on a ball in its cross-section [N], (..., 2) as (x, y).

    Contact i sits at p_i = (sx_i sin beta_i, sy_i cos beta_i) on the ball (unit vector from
    the centre, :data:`SIDE_SIGN_X`, :data:`SIDE_SIGN_Y`) and pushes it inward with F_i along
    -p_i, so the net force is -sum F_i p_i; static equilibrium of a ball without other loads
    in the cross-section needs it to vanish. Two opposite contacts of force F whose angles
    differ by Delta leave |2 F sin(Delta / 2)|.

    Parameters
    ----------
    contact_angle : array_like, (..., 4)
        beta_i [rad], BL, BR, TR, TL.
    normal_force : array_like, (..., 4)
        F_i [N].
    """
    beta = np.asarray(contact_angle, dtype=float)
    force = np.asarray(normal_force, dtype=float)
    fx = -np.sum(force * SIDE_SIGN_X * np.sin(beta), axis=-1)
    fy = -np.sum(force * SIDE_SIGN_Y * np.cos(beta), axis=-1)
    return np.stack([fx, fy], axis=-1)
