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

*Ball tolerance*: a ball is in balance when its force imbalance is <= ball_tol times the
larger of its largest flank force and the assembly's reference ball force f_ref = max(Q_max /
n_balls, K (o_max/2)^1.5) (Q_max the largest load component, moments divided by L; the force
of the regularisation). A loose ball (errors larger than the preload) touching one flank has
its balance at that flank's delta = 0, a root of order 1.5 of F = K delta^1.5: judged against
its own vanishing force, Newton stalled near 1e-13 N and the assembly was reported as lifted
off.

A contact that opens is reported (``contact_count``), not an error. A carriage that lifts off
entirely (no carriage flank loaded, or the motion leaves the gothic arch) is a ValueError
naming the load (in :func:`solve_carriage_batch`: status ``STATUS_LIFT_OFF``).

Many assemblies at once
-----------------------
:func:`solve_carriage_batch` solves m sampled assemblies (one layout and load, each its own
errors and oversizes) in one compiled kernel, assemblies in parallel; an assembly's result is
bit-identical whatever batch it is in and however many threads run. Each assembly first
tries the *joint* Newton, ball centres P_b and q unknown together. Linearised, the ball
balance gives r_b + M_b dP_b - K_t,b A_b dq = 0 (M = K_b + K_t), so

    dP_b = M_b^-1 K_t,b A_b dq - M_b^-1 r_b,    K_c dq = R - sum_b A_b^T K_t,b M_b^-1 r_b

with the tangent K_c = sum A^T S A of the nested Newton (which has r_b = 0). A step costs one
evaluation of every ball's flanks, vectorised across the balls, instead of a Newton solve of
every ball. A ball whose loaded flanks hold no diagonal pair (BL-TR or BR-TL) is loose: its
only balance has no force, each loaded flank going to delta = 0, where a Newton step only
divides delta by 3; it takes 1.5 times its own correction, which lands on delta = 0 to first
order. A ball far from its balance (at the start, after a large step) is first moved by
ball-only Newton steps. The joint Newton ends on the certificate of the nested one (every
ball's imbalance and the carriage's within tolerance); an assembly where it does not within
12 steps (about 0.5 % of ``benchmarks/bench_carriage.py``'s, mostly balls changing contacts)
is solved again by the nested Newton of :func:`solve_carriage`, compiled. Both start from the
solution q0 of the error-free nominal assembly, which :func:`solve_carriage` finds once.
Measured there (``configs/carriage_preload.toml``, 24 balls, 1 um errors, 2 um preload; a
2-core VM): 4.9 joint steps on average, 9-10 us of CPU per assembly (about 190 k assemblies
or 4.5 M balls per second on 2 threads), 3.5 times less than the nested Newton alone and
about 90 times less than :func:`solve_carriage` one assembly at a time.

Balls moving through the carriage; end relief
---------------------------------------------
With ``along_track`` propagation the balls roll through the carriage (:mod:`tolsim.study.
carriage_track` derives their motion and how balls enter and leave the loaded zone).
:func:`solve_carriage_batch` then takes each assembly's balls at their own axial positions
(``ball_z``, replacing z_j in B(p) and in the moments) and a ``loaded`` mask: the layout's
``balls_per_track`` is the number of ball slots of a track, and a slot whose ball is outside
the loaded zone (or empty) carries nothing. Such a ball has zero rows in the groove map A (its
groove does not follow the carriage) and no flank touches it (the kernel gives it a radius of
R_B - d/2, so every approach is about -d/2 and F = K max(delta, 0)^1.5 = 0): it adds nothing
to the residual, the tangent or the reference force f_ref (formed over the loaded balls).

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
   (``tolsim/io/config/sections.py`` ``read_loads``) is exactly the linearised carriage.
   Beyond it: N_y of a ball is even and convex in g_1 (the pair approaches are delta_v +/-
   c g_1 and F ~ delta^1.5), so at the common u_y the end balls take more N_y and the middle
   ones less (sum N_y = V); rho is odd in M, so rho - rho_old = O(M^3). Default study (10 balls at
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
from numba import prange

from tolsim._jit import jit, pjit
from tolsim.physics._fastmath import SMALL_ANGLE, SMALL_TAN, atan_small, sin_cosm1_small
from tolsim.physics.geometry import TABLE1, Bearing
from tolsim.physics.static import (
    DEFAULT_MAX_ITER,
    DEFAULT_TOLERANCE,
    FLOOR_LENGTH,
    GrooveErrors,
    arc_centres,
    ball_outputs,
    check_solver_options,
    displacement_one,
    error_items,
    flank,
    flank_newton,
    hertz_k,
    move_top_groove,
    prepare_inputs,
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
@jit(inline="always")
def schur_complement(kb11, kb12, kb22, kt11, kt12, kt22):
    """S = K_t - K_t M^-1 K_t [N/m] and M^-1 K_t [-] of a ball, M = K_b + K_t.

    K_b, K_t: the (symmetric) stiffness sums of its rail and carriage flanks [N/m]. Both are
    0 where the carriage flanks carry nothing or M is singular (det M <= 1e-14 tr(M)^2).
    Branch-free (selects), so that it vectorises inside a loop over balls.

    Returns
    -------
    s11, s12, s22, r11, r12, r21, r22 : float
    """
    m11, m12, m22 = kb11 + kt11, kb12 + kt12, kb22 + kt22
    det = m11 * m22 - m12 * m12
    trace = m11 + m22
    ok = (kt11 + kt22 > 0.0) & (det > 1e-14 * (trace * trace))
    safe = det if ok else 1.0
    keep = 1.0 if ok else 0.0
    # K_t M^-1 K_t with M^-1 = [[m22, -m12], [-m12, m11]] / det
    i11, i12, i22 = m22 / safe, -m12 / safe, m11 / safe
    w11 = kt11 * i11 + kt12 * i12  # W = K_t M^-1 = (M^-1 K_t)^T
    w12 = kt11 * i12 + kt12 * i22
    w21 = kt12 * i11 + kt22 * i12
    w22 = kt12 * i12 + kt22 * i22
    s11 = keep * (kt11 - (w11 * kt11 + w12 * kt12))
    s12 = keep * (kt12 - 0.5 * ((w11 * kt12 + w12 * kt22) + (w21 * kt11 + w22 * kt12)))
    s22 = keep * (kt22 - (w21 * kt12 + w22 * kt22))
    return s11, s12, s22, keep * w11, keep * w21, keep * w12, keep * w22


@jit(inline="always")
def condensed_ball(px, py, cen, dist, h, k):
    """Condensed stiffness, response, groove force and Hertz energy of a ball at P.

    From the flank stiffnesses k_i = F_i' u_i u_i^T + (F_i / |P - C_i|)(I - u_i u_i^T) (module
    docstring), summed over the rail flanks (K_b) and the carriage flanks (K_t), M = K_b + K_t:
    the ball's balance sum_i F_i u_i = 0 moves by dP = M^-1 K_t dg under a groove translation
    dg (d(sum F_i u_i) = M dP - K_t dg), and the force of the ball on its groove, f = F_TR u_TR
    + F_TL u_TL, by df = -K_t dg + K_t dP = -S dg with the Schur complement S = K_t - K_t M^-1
    K_t (symmetric).

    Parameters
    ----------
    px, py : float
        Ball centre P (module frame) [m].
    cen : ndarray, (4, 6)
        Arc centres (``tolsim.physics.static.arc_centres``), carriage groove already moved.
    dist, h, k : float
        d = R_G - R_B [m], half the oversize [m], Hertz constant [N/m^1.5].

    Returns
    -------
    s11, s12, s22 : float
        S [N/m] (0 when the carriage flanks carry nothing or M is singular).
    r11, r12, r21, r22 : float
        M^-1 K_t [-] (0 likewise): the linear predictor of the ball position.
    fx, fy : float
        f [N].
    energy : float
        sum_i (2/5) K delta_i^2.5 = sum_i (2/5) F_i delta_i [J].
    fmax : float
        Largest flank force [N].
    bx, by : float
        Force imbalance of the ball, sum_i F_i u_i [N].
    m11, m12, m22 : float
        M [N/m].
    loaded : int
        Bit i set where flank i (BL, BR, TR, TL) carries force.
    """
    kb11 = kb12 = kb22 = kt11 = kt12 = kt22 = 0.0
    energy = fx = fy = bx = by = fmax = 0.0
    loaded = 0
    for i in range(4):
        ux, uy, inv, delta, f, df = flank(px, py, cen, i, dist, h, k)
        if f > 0.0:
            g = f * inv
            a11 = df * ux * ux + g * (1.0 - ux * ux)
            a12 = (df - g) * ux * uy
            a22 = df * uy * uy + g * (1.0 - uy * uy)
            energy += 0.4 * f * delta
            bx += f * ux
            by += f * uy
            fmax = max(fmax, f)
            loaded |= 1 << i
            if i < 2:
                kb11 += a11
                kb12 += a12
                kb22 += a22
            else:
                kt11 += a11
                kt12 += a12
                kt22 += a22
                fx += f * ux
                fy += f * uy
    s11, s12, s22, r11, r12, r21, r22 = schur_complement(kb11, kb12, kb22, kt11, kt12, kt22)
    return (s11, s12, s22, r11, r12, r21, r22, fx, fy, energy, fmax, bx, by, kb11 + kt11,
            kb12 + kt12, kb22 + kt22, loaded)


@jit
def carriage_balls_kernel(groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, beta0,
                          dist, k, tol, max_iter, floor, out_dbeta, out_force, out_approach,
                          out_ball, out_load, out_converged, out_iter, out_count, out_residual,
                          out_stiffness, out_energy):
    """Displacement-controlled balls with their condensed stiffness and Hertz energy.

    Each ball is solved by :func:`tolsim.physics.static.displacement_one` to a force
    imbalance <= tol max(F_max, floor) [N] (F_max its largest flank force); then
    out_stiffness[n] = K_t - K_t (K_b + K_t)^-1 K_t [N/m] (= -d f / d g, f the force of the
    ball on its carriage groove) and out_energy[n] = sum_i (2/5) K delta_i^2.5 [J]
    (:func:`condensed_ball`).
    """
    s0, c0 = np.sin(beta0), np.cos(beta0)
    cen = np.empty((4, 6))
    unit = np.empty((4, 2))
    for n in range(out_dbeta.shape[0]):
        displacement_one(n, groove_disp, e_n, e_t, rot_b, rot_t, off_b, off_t, oversize, s0,
                         c0, dist, k, tol, max_iter, floor, cen, unit, out_dbeta, out_force,
                         out_approach, out_ball, out_load, out_converged, out_iter, out_count,
                         out_residual)
        h = 0.5 * oversize[n if oversize.shape[0] > 1 else 0]
        # cen holds the arc centres moved with the groove
        s11, s12, s22, _, _, _, _, _, _, energy, _, _, _, _, _, _, _ = condensed_ball(
            out_ball[n, 0], out_ball[n, 1], cen, dist, h, k)
        out_stiffness[n, 0, 0] = s11
        out_stiffness[n, 0, 1] = s12
        out_stiffness[n, 1, 0] = s12
        out_stiffness[n, 1, 1] = s22
        out_energy[n] = energy


#: Assemblies per parallel work item of :func:`carriage_batch_kernel` (scratch arrays are
#: allocated once per item).
_ASSEMBLY_TILE = 8
#: Steps of the joint Newton (:func:`_joint_newton`) before the nested fallback.
_JOINT_MAX_ITER = 12
#: Relative ball imbalance above which the joint Newton first solves the ball alone.
_RESOLVE = 1e-3
#: Ball-only Newton steps from the geometric start before the first joint step, and after a
#: joint step that left a ball's relative imbalance above _RESOLVE.
_START_STEPS = 3
_LOCAL_STEPS = 2
#: Status codes of a batched assembly (:class:`CarriageBatch`).
STATUS_CONVERGED = 0
STATUS_NOT_CONVERGED = 1
STATUS_LIFT_OFF = 2
BATCH_STATUS = {
    STATUS_CONVERGED: "converged",
    STATUS_NOT_CONVERGED: "the carriage Newton did not converge within max_iter steps",
    STATUS_LIFT_OFF: "lifted off (no carriage flank loaded), left the gothic arch, or a ball "
                     "solve failed",
}


@jit
def _evaluate_balls(q, warm, src, dst, groove_map, base, half, dist, k, ball_tol,
                    ball_max_iter, floor, limit, q_ext, pos, grv, resp, ball_ok, work,
                    residual, tangent, state):
    """All balls of one assembly at the scaled carriage displacement q, into buffer ``dst``.

    Ball b's carriage groove moves by g_b = A_b q; its centre is solved by
    :func:`tolsim.physics.static.flank_newton` (all four flanks, displacement control),
    started, if ``warm``, from the solution in buffer ``src`` plus the linear predictor
    M^-1 K_t (g_b - g_b,src) (:func:`condensed_ball`), else from the mean of the four
    touching positions as :func:`tolsim.physics.static.displacement_one`, to an imbalance
    <= ball_tol max(F_max, floor) [N] (the last Newton step predicted, then verified here).
    Then residual[dst] = Q + sum_b A_b^T f_b, tangent[dst] = sum_b A_b^T S_b A_b and
    state[dst] = (Hertz energy [J], largest flank force [N], sum_b |f_b|^2 [N^2]).

    Returns 0 (every ball solved), 1 (a groove moved beyond ``limit``: no ball solved) or 2
    (a ball solve failed; ball_ok[dst] says which).
    """
    nball = groove_map.shape[0]
    gmax = 0.0
    for b in range(nball):
        ball_ok[dst, b] = False
        for c in range(2):
            g = 0.0
            for j in range(5):
                g += groove_map[b, c, j] * q[j]
            grv[dst, b, c] = g
            gmax = max(gmax, abs(g))
    if not gmax <= limit:
        return 1
    for i in range(5):
        residual[dst, i] = q_ext[i]
        for j in range(5):
            tangent[dst, i, j] = 0.0
    energy = fmax = force2 = 0.0
    status = 0
    reg = 1.5 * k * 1e-3  # as displacement_one: dF/ddelta at a 1 um approach
    for b in range(nball):
        gx, gy = grv[dst, b, 0], grv[dst, b, 1]
        for i in range(4):
            for c in range(6):
                work[i, c] = base[b, i, c]
        move_top_groove(work, gx, gy)
        h = half[b]
        if warm:
            dgx, dgy = gx - grv[src, b, 0], gy - grv[src, b, 1]
            px = pos[src, b, 0] + resp[src, b, 0] * dgx + resp[src, b, 1] * dgy
            py = pos[src, b, 1] + resp[src, b, 2] * dgx + resp[src, b, 3] * dgy
        else:
            px = py = 0.0
            for i in range(4):
                px += 0.25 * (work[i, 2] - h * work[i, 4])
                py += 0.25 * (work[i, 3] - h * work[i, 5])
        px, py, _, ok, _ = flank_newton(work, 0, 4, dist, h, k, 0.0, 0.0, px, py, ball_tol,
                                        ball_max_iter, floor, reg, True)
        s11, s12, s22, r11, r12, r21, r22, fx, fy, en, fm, bx, by, _, _, _, _ = condensed_ball(
            px, py, work, dist, h, k)
        if ok and max(abs(bx), abs(by)) > 2.0 * ball_tol * max(fm, floor):
            # the predicted last step of flank_newton missed: polish (as _load_one does)
            px, py, _, ok, _ = flank_newton(work, 0, 4, dist, h, k, 0.0, 0.0, px, py,
                                            ball_tol, ball_max_iter, floor, reg, False)
            s11, s12, s22, r11, r12, r21, r22, fx, fy, en, fm, bx, by, _, _, _, _ = condensed_ball(
                px, py, work, dist, h, k)
        ball_ok[dst, b] = ok
        if not ok:
            status = 2
            continue
        pos[dst, b, 0] = px
        pos[dst, b, 1] = py
        resp[dst, b, 0] = r11
        resp[dst, b, 1] = r12
        resp[dst, b, 2] = r21
        resp[dst, b, 3] = r22
        energy += en
        fmax = max(fmax, fm)
        force2 += fx * fx + fy * fy
        for j in range(5):
            a0, a1 = groove_map[b, 0, j], groove_map[b, 1, j]
            residual[dst, j] += a0 * fx + a1 * fy
            sa0 = s11 * a0 + s12 * a1  # (S A)_j
            sa1 = s12 * a0 + s22 * a1
            for i in range(j + 1):
                tangent[dst, i, j] += groove_map[b, 0, i] * sa0 + groove_map[b, 1, i] * sa1
    for j in range(5):
        for i in range(j):
            tangent[dst, j, i] = tangent[dst, i, j]
    state[dst, 0] = energy
    state[dst, 1] = fmax
    state[dst, 2] = force2
    return status


@jit(inline="always")
def _cholesky(mat, free, low):
    """L L^T = mat[free][:, free] into low; returns the smallest pivot (before its square
    root; <= 0 or NaN: not positive definite, low incomplete)."""
    nf = free.shape[0]
    pmin = np.inf
    for i in range(nf):
        for j in range(i + 1):
            s = mat[free[i], free[j]]
            for m in range(j):
                s -= low[i, m] * low[j, m]
            if i == j:
                pmin = min(pmin, s)
                if not s > 0.0:
                    return s
                low[i, i] = np.sqrt(s)
            else:
                low[i, j] = s / low[j, j]
    return pmin


@jit(inline="always")
def _cholesky_solve(low, free, rhs, x):
    """x[free] = (L L^T)^-1 rhs[free], x = 0 elsewhere (x has 5 entries)."""
    nf = free.shape[0]
    for j in range(5):
        x[j] = 0.0
    for i in range(nf):  # forward: L y = rhs, y stored in x[free]
        s = rhs[free[i]]
        for m in range(i):
            s -= low[i, m] * x[free[m]]
        x[free[i]] = s / low[i, i]
    for i in range(nf - 1, -1, -1):  # back: L^T x = y
        s = x[free[i]]
        for m in range(i + 1, nf):
            s -= low[m, i] * x[free[m]]
        x[free[i]] = s / low[i, i]


@jit(inline="always")
def _scaled_error(residual, free, scale):
    """max |residual[free]| / scale."""
    err = 0.0
    for i in range(free.shape[0]):
        err = max(err, abs(residual[free[i]]))
    return err / scale


# Rows of the per-assembly lane array ``w`` of the joint Newton, ball b in column b. The loops
# over balls read and write whole rows and have no branches, so LLVM vectorises them (as the
# ``_lane_*`` kernels of tolsim.physics.static); each loop writes at most seven rows, since
# with more LLVM gives up on the run-time checks that the rows do not overlap.
_L_DC = 0  # C_i + d n_i (x, y) of flanks BL, BR, TR, TL, carriage groove at g = 0: 8 rows
_L_H = 8  # half the ball oversize
_L_P = 9  # ball centre (x, y)
_L_G = 11  # carriage-groove translation g = A q (x, y)
_L_DG = 13  # groove translation of the step, A dq (x, y)
_L_KB = 15  # K_b (11, 12, 22)
_L_RB = 18  # F_BL u_BL + F_BR u_BR (x, y)
_L_F01 = 20  # F_BL, F_BR
_L_KT = 22  # K_t (11, 12, 22)
_L_F = 25  # f = F_TR u_TR + F_TL u_TL, the force of the ball on its carriage groove (x, y)
_L_F23 = 27  # F_TR, F_TL
_L_S = 29  # S (11, 12, 22)
_L_W = 32  # M^-1 K_t (11, 12, 21, 22)
_L_D = 36  # ball correction gamma M^-1 r (x, y)
_L_RES = 38  # relative imbalance |r|_inf / max(F_max, floor)
_L_FM = 39  # largest flank force
_L_DB = 40  # dbeta_i of the four flanks (outputs)
_L_ROWS = 44
# The errors of the balls, gathered before the first pass into rows that the passes
# overwrite: e_n (4), e_t (4), rotations (rail, carriage), offsets (rail x, y, carriage x, y).
_L_EN, _L_ET, _L_ROT, _L_OFF = 15, 19, 23, 25


@jit(inline="always")
def _soft_flank(px, py, dcx, dcy, nx, ny, d, h, k):
    """:func:`tolsim.physics.static.flank` without its branch (no force where delta <= 0).

    Returns F u (x, y), the flank stiffness k_i (11, 12, 22) and F, with the operations of
    ``flank`` and :func:`condensed_ball` (the same values where delta > 0).
    """
    vx = px - dcx
    vy = py - dcy
    wx = vx + d * nx
    wy = vy + d * ny
    dist = np.sqrt(wx * wx + wy * wy)
    inv = 1.0 / dist
    ux = wx * inv
    uy = wy * inv
    delta = (vx * vx + vy * vy + 2.0 * d * (nx * vx + ny * vy) + h * (2.0 * d - h)) / (
        dist + d - h)
    dp = max(delta, 0.0)
    sd = np.sqrt(dp)
    f = k * dp * sd
    df = 1.5 * k * sd
    g = f * inv
    a11 = df * ux * ux + g * (1.0 - ux * ux)
    a12 = (df - g) * ux * uy
    a22 = df * uy * uy + g * (1.0 - uy * uy)
    return f * ux, f * uy, a11, a12, a22, f


@jit
def _lane_groove(w, groove, s0, c0, dist, k):
    """Flanks of one groove (0 rail: BL, BR; 1 carriage: TR, TL) of every ball at (P, g).

    Rows _L_KB, _L_RB, _L_F01 (rail) or _L_KT, _L_F, _L_F23 (carriage): the stiffness sum, the
    force sum sum F_i u_i and the two forces.
    """
    i0 = 2 * groove
    sgn = 1.0 if groove == 0 else -1.0
    ax, ay = -sgn * s0, -sgn * c0  # n_i of the first flank (BL or TR, static's docstring)
    bx, by = sgn * s0, -sgn * c0  # and of the second (BR or TL)
    rk = _L_KB if groove == 0 else _L_KT
    rf = _L_RB if groove == 0 else _L_F
    rn = _L_F01 if groove == 0 else _L_F23
    shift = 0.0 if groove == 0 else 1.0  # the carriage groove is translated by g
    for b in range(w.shape[1]):
        px, py, h = w[_L_P, b], w[_L_P + 1, b], w[_L_H, b]
        gx, gy = shift * w[_L_G, b], shift * w[_L_G + 1, b]
        f0x, f0y, p11, p12, p22, f0 = _soft_flank(
            px, py, w[_L_DC + 2 * i0, b] + gx, w[_L_DC + 2 * i0 + 1, b] + gy, ax, ay, dist, h, k)
        f1x, f1y, q11, q12, q22, f1 = _soft_flank(
            px, py, w[_L_DC + 2 * i0 + 2, b] + gx, w[_L_DC + 2 * i0 + 3, b] + gy, bx, by, dist,
            h, k)
        w[rk, b] = p11 + q11
        w[rk + 1, b] = p12 + q12
        w[rk + 2, b] = p22 + q22
        w[rf, b] = f0x + f1x
        w[rf + 1, b] = f0y + f1y
        w[rn, b] = f0
        w[rn + 1, b] = f1


@jit
def _lane_condense(w):
    """S and M^-1 K_t of every ball (rows _L_S, _L_W) by :func:`schur_complement`."""
    for b in range(w.shape[1]):
        s11, s12, s22, r11, r12, r21, r22 = schur_complement(
            w[_L_KB, b], w[_L_KB + 1, b], w[_L_KB + 2, b], w[_L_KT, b], w[_L_KT + 1, b],
            w[_L_KT + 2, b])
        w[_L_S, b] = s11
        w[_L_S + 1, b] = s12
        w[_L_S + 2, b] = s22
        w[_L_W, b] = r11
        w[_L_W + 1, b] = r12
        w[_L_W + 2, b] = r21
        w[_L_W + 3, b] = r22


@jit
def _lane_correct(w, k, ball_floor):
    """The ball's own Newton correction gamma M^-1 r, its relative imbalance and F_max.

    M is regularised as ``flank_newton`` does. gamma = 1.5 for a loose ball (no diagonal pair
    BL-TR or BR-TL carries force: its only equilibrium has no force, so each loaded flank goes
    to delta = 0, where F = K delta^1.5 has a root of order 1.5 and a Newton step only divides
    delta by 3; the 1.5 step lands on delta = 0 to first order), else 1.
    """
    reg = 1.5 * k * 1e-3  # as displacement_one
    for b in range(w.shape[1]):
        m11 = w[_L_KB, b] + w[_L_KT, b]
        m12 = w[_L_KB + 1, b] + w[_L_KT + 1, b]
        m22 = w[_L_KB + 2, b] + w[_L_KT + 2, b]
        rx = w[_L_RB, b] + w[_L_F, b]
        ry = w[_L_RB + 1, b] + w[_L_F + 1, b]
        f0, f1, f2, f3 = w[_L_F01, b], w[_L_F01 + 1, b], w[_L_F23, b], w[_L_F23 + 1, b]
        det = m11 * m22 - m12 * m12
        trace = m11 + m22
        add = reg if (not det > 1e-12 * trace * trace) | (trace == 0.0) else 0.0
        e11, e22 = m11 + add, m22 + add
        loose = not ((min(f0, f2) > 0.0) | (min(f1, f3) > 0.0))
        gamma = (1.5 if loose else 1.0) / (e11 * e22 - m12 * m12)
        fm = max(max(f0, f1), max(f2, f3))
        w[_L_D, b] = gamma * (e22 * rx - m12 * ry)
        w[_L_D + 1, b] = gamma * (e11 * ry - m12 * rx)
        w[_L_RES, b] = max(abs(rx), abs(ry)) / max(fm, ball_floor)
        w[_L_FM, b] = fm


@jit
def _lane_balls(w, s0, c0, dist, k, ball_floor):
    """Every ball (column of w) at its (P, g): the rows _L_KB to _L_FM (:func:`condensed_ball`
    in vectorised passes). The loops run from 0 (with a variable start Numba's negative-index
    wrap-around keeps LLVM from vectorising): pass a column slice for one ball."""
    _lane_groove(w, 0, s0, c0, dist, k)
    _lane_groove(w, 1, s0, c0, dist, k)
    _lane_condense(w)
    _lane_correct(w, k, ball_floor)


@jit
def _lane_angles(w, s0, c0, dist):
    """dbeta_i of every flank of every ball at (P, g) into rows _L_DB, as ``ball_outputs``.

    dbeta_i = atan(t_i . u_i / n_i . u_i) by the series of ``atan_small`` (round-off
    accurate for |tan| <= SMALL_TAN, about 5.7 deg); NaN beyond, for the caller to redo with
    arctan2 (the loop stays branch-free and vectorises).
    """
    for i in range(4):
        sx = -1.0 if (i == 0 or i == 3) else 1.0
        sy = -1.0 if i < 2 else 1.0
        nx, ny = sx * s0, sy * c0
        sxy = sx * sy
        shift = 0.0 if i < 2 else 1.0
        for b in range(w.shape[1]):
            wx = w[_L_P, b] - (w[_L_DC + 2 * i, b] + shift * w[_L_G, b]) + dist * nx
            wy = w[_L_P + 1, b] - (w[_L_DC + 2 * i + 1, b] + shift * w[_L_G + 1, b]) + dist * ny
            tan = sxy * (ny * wx - nx * wy) / (nx * wx + ny * wy)
            w[_L_DB + i, b] = atan_small(tan) if abs(tan) <= SMALL_TAN else np.nan


@jit
def _lane_arc_centres(a, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist, w, work):
    """Rows _L_DC (C_i + d n_i, carriage groove at g = 0) of every ball of assembly a.

    The operations of ``tolsim.physics.static.arc_centres``, vectorised over the balls with
    the sine and cosine of the groove rotations from ``sin_cosm1_small`` (round-off accurate
    up to SMALL_ANGLE = 0.2 rad); a ball with a larger rotation gets ``arc_centres`` itself.
    """
    nball = w.shape[1]
    for b in range(nball):  # gather (inputs have a first axis of m n_balls or 1)
        n = a * nball + b
        ie = n if e_n.shape[0] > 1 else 0
        it = n if e_t.shape[0] > 1 else 0
        for i in range(4):
            w[_L_EN + i, b] = e_n[ie, i]
            w[_L_ET + i, b] = e_t[it, i]
        w[_L_ROT, b] = rot_b[n if rot_b.shape[0] > 1 else 0]
        w[_L_ROT + 1, b] = rot_t[n if rot_t.shape[0] > 1 else 0]
        ib = n if off_b.shape[0] > 1 else 0
        iq = n if off_t.shape[0] > 1 else 0
        w[_L_OFF, b] = off_b[ib, 0]
        w[_L_OFF + 1, b] = off_b[ib, 1]
        w[_L_OFF + 2, b] = off_t[iq, 0]
        w[_L_OFF + 3, b] = off_t[iq, 1]
    for i in range(4):
        groove = i // 2
        sx = -1.0 if (i == 0 or i == 3) else 1.0
        sy = -1.0 if i < 2 else 1.0
        nx, ny = sx * s0, sy * c0  # n_i
        tx, ty = sx * c0, -sy * s0  # t_i = dn_i/dbeta
        for b in range(nball):
            st, cm1 = sin_cosm1_small(w[_L_ROT + groove, b])
            ct = 1.0 + cm1
            en, et = w[_L_EN + i, b], w[_L_ET + i, b]
            x = en * nx - et * tx
            y = en * ny - et * ty
            w[_L_DC + 2 * i, b] = (-dist * (cm1 * nx - st * ny) + ct * x - st * y
                                   + w[_L_OFF + 2 * groove, b])
            w[_L_DC + 2 * i + 1, b] = (-dist * (st * nx + cm1 * ny) + st * x + ct * y
                                       + w[_L_OFF + 2 * groove + 1, b])
    for b in range(nball):
        if not (abs(w[_L_ROT, b]) <= SMALL_ANGLE and abs(w[_L_ROT + 1, b]) <= SMALL_ANGLE):
            arc_centres(a * nball + b, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist,
                        work)
            for i in range(4):
                w[_L_DC + 2 * i, b] = work[i, 2]
                w[_L_DC + 2 * i + 1, b] = work[i, 3]


@jit(inline="always")
def _lane_work(w, b, s0, c0, dist, work):
    """The arc centres of ball b (as ``arc_centres``, carriage groove moved by g) into work."""
    for i in range(4):
        sx = -1.0 if (i == 0 or i == 3) else 1.0
        sy = -1.0 if i < 2 else 1.0
        nx, ny = sx * s0, sy * c0
        work[i, 2] = w[_L_DC + 2 * i, b]
        work[i, 3] = w[_L_DC + 2 * i + 1, b]
        work[i, 0] = work[i, 2] - dist * nx
        work[i, 1] = work[i, 3] - dist * ny
        work[i, 4] = nx
        work[i, 5] = ny
    move_top_groove(work, w[_L_G, b], w[_L_G + 1, b])


@jit
def _lane_local_step(nball, w, dist):
    """Ball-only Newton step P -= gamma M^-1 r (groove held), capped at 0.1 d."""
    cap2 = (0.1 * dist) ** 2
    for b in range(nball):
        dx, dy = w[_L_D, b], w[_L_D + 1, b]
        s2 = dx * dx + dy * dy
        c = np.sqrt(cap2 / s2) if s2 > cap2 else 1.0
        w[_L_P, b] -= c * dx
        w[_L_P + 1, b] -= c * dy


@jit
def _track_assembly(w, frame, zeta, q_ext, residual, reduced, tangent, ball_tol):
    """Carriage residual R, reduced residual and tangent of the joint Newton, track by track.

    With A_b = E_t^T B_b (module docstring; scaled: B_b = [[1, 0, 0, zeta, -eta], [0, 1,
    -zeta, 0, xi]], zeta = z_j / L, xi = x_t / L, eta = y_t / L) and, in the carriage frame,
    T_b = E_t S_b E_t^T and f_c = E_t f: sum_b A_b^T S_b A_b = sum_b B_b^T T_b B_b and
    sum_b A_b^T f_b = sum_b B_b^T f_c,b, so each track needs only the sums of T, zeta T and
    zeta^2 T and of f_c and zeta f_c over its balls (ball b = t n + j). The same K and R as
    ``sum A^T S A`` over ``groove_map`` (to round-off), in a third of the operations.
    ``zeta`` holds z_b / L of every ball (n_tracks n,), so that the balls of each assembly
    may sit at their own z (:func:`solve_carriage_batch` with ``ball_z``).

    Returns the largest flank force [N], sum_b |f_b|^2 [N^2] and whether every ball's relative
    imbalance is within ball_tol.
    """
    n = zeta.shape[0] // frame.shape[0]
    for i in range(5):
        residual[i] = q_ext[i]
        reduced[i] = q_ext[i]
        for j in range(5):
            tangent[i, j] = 0.0
    fmax = force2 = 0.0
    balls_ok = True
    for t in range(frame.shape[0]):
        c, s, xi, eta = frame[t, 0], frame[t, 1], frame[t, 2], frame[t, 3]
        cc, ss, cs = c * c, s * s, c * s
        a11 = a12 = a22 = z11 = z12 = z22 = y11 = y12 = y22 = 0.0  # sums of T, zeta T, zeta^2 T
        fx0 = fy0 = fx1 = fy1 = gx0 = gy0 = gx1 = gy1 = 0.0  # of f_c, zeta f_c (f, reduced)
        for j in range(n):
            b = t * n + j
            z = zeta[b]
            fx, fy = w[_L_F, b], w[_L_F + 1, b]
            rx, ry = w[_L_RB, b] + fx, w[_L_RB + 1, b] + fy
            fmax = max(fmax, w[_L_FM, b])
            force2 += fx * fx + fy * fy
            balls_ok = balls_ok and w[_L_RES, b] <= ball_tol
            # f - K_t M^-1 r, with K_t M^-1 r = (M^-1 K_t)^T r
            gx = fx - (w[_L_W, b] * rx + w[_L_W + 2, b] * ry)
            gy = fy - (w[_L_W + 1, b] * rx + w[_L_W + 3, b] * ry)
            sa, sb, sd = w[_L_S, b], w[_L_S + 1, b], w[_L_S + 2, b]
            t11 = cc * sa - 2.0 * cs * sb + ss * sd
            t12 = cs * (sa - sd) + (cc - ss) * sb
            t22 = ss * sa + 2.0 * cs * sb + cc * sd
            a11 += t11
            a12 += t12
            a22 += t22
            z11 += z * t11
            z12 += z * t12
            z22 += z * t22
            y11 += z * z * t11
            y12 += z * z * t12
            y22 += z * z * t22
            fcx, fcy = c * fx - s * fy, s * fx + c * fy
            gcx, gcy = c * gx - s * gy, s * gx + c * gy
            fx0 += fcx
            fy0 += fcy
            fx1 += z * fcx
            fy1 += z * fcy
            gx0 += gcx
            gy0 += gcy
            gx1 += z * gcx
            gy1 += z * gcy
        residual[0] += fx0
        residual[1] += fy0
        residual[2] -= fy1
        residual[3] += fx1
        residual[4] += xi * fy0 - eta * fx0
        reduced[0] += gx0
        reduced[1] += gy0
        reduced[2] -= gy1
        reduced[3] += gx1
        reduced[4] += xi * gy0 - eta * gx0
        tangent[0, 0] += a11
        tangent[0, 1] += a12
        tangent[1, 1] += a22
        tangent[0, 2] -= z12
        tangent[1, 2] -= z22
        tangent[2, 2] += y22
        tangent[0, 3] += z11
        tangent[1, 3] += z12
        tangent[2, 3] -= y12
        tangent[3, 3] += y11
        tangent[0, 4] += xi * a12 - eta * a11
        tangent[1, 4] += xi * a22 - eta * a12
        tangent[2, 4] += eta * z12 - xi * z22
        tangent[3, 4] += xi * z12 - eta * z11
        tangent[4, 4] += eta * eta * a11 - 2.0 * eta * xi * a12 + xi * xi * a22
    for j in range(5):
        for i in range(j):
            tangent[j, i] = tangent[i, j]
    return fmax, force2, balls_ok


@jit
def _joint_newton(q, free, amap, frame, zeta, w, s0, c0, dist, k, tol, max_iter, ball_tol,
                  ball_max_iter, ball_floor, force_floor, load_norm, singular, cap, limit,
                  resolve, q_ext, residual, tangent, state, work, low, step, reduced):
    """Newton on the balls and the carriage together (the fast path): its steps, or -1.

    Unknowns: every ball centre P_b and q. Linearising the ball balance r_b = sum_i F_i u_i
    = 0 and the carriage balance R = Q + sum_b A_b^T f_b = 0 (:func:`condensed_ball`):
    r_b + M_b dP_b - K_t,b A_b dq = 0 gives dP_b = M_b^-1 K_t,b A_b dq - M_b^-1 r_b and
    df_b = -S_b A_b dq - K_t,b M_b^-1 r_b, so the carriage step solves

        (sum_b A_b^T S_b A_b) dq = R - sum_b A_b^T K_t,b M_b^-1 r_b

    (the tangent of the nested Newton, which has r_b = 0). A step costs one flank pass over
    the balls (:func:`_lane_balls`, vectorised) instead of a Newton solve of every ball.
    While some ball's relative imbalance exceeds ``resolve`` (at the start, _START_STEPS
    times; after a large step, _LOCAL_STEPS times) all balls take a ball-only Newton step
    (:func:`_lane_local_step`); a ball still above it is solved alone by ``flank_newton``.
    Loose balls take the 1.5 correction of :func:`_lane_correct`. Steps are capped as the
    nested Newton's (groove travel _STEP_CAP d, ball travel 0.1 d); no line search. Converged
    when every ball's imbalance is <= ball_tol max(F_max,b, ball_floor) and the carriage's
    <= tol, as the nested Newton. Returns -1 (the caller falls back to the nested Newton) on
    a singular tangent, a ball step beyond 0.1 d, a motion beyond ``limit``, a failed ball
    solve, no carriage force under a load, or max_iter steps.

    On entry w holds the arc centres (rows _L_DC), the oversizes and the start of P; q the
    start of the carriage. On success q, residual[0], tangent[0], state[0] (NaN energy: no
    line search needs it) and w hold the solution.
    """
    nball = w.shape[1]
    reg = 1.5 * k * 1e-3
    it = 0
    while True:
        gmax = 0.0
        for b in range(nball):
            gx = gy = 0.0
            for j in range(5):
                gx += amap[j, b] * q[j]
                gy += amap[5 + j, b] * q[j]
            w[_L_G, b] = gx
            w[_L_G + 1, b] = gy
            gmax = max(gmax, max(abs(gx), abs(gy)))
        if not gmax <= limit:
            return -1
        _lane_balls(w, s0, c0, dist, k, ball_floor)
        # ball-only steps, all balls at once: from the geometric start, and after a step that
        # left some ball far from its balance
        for _ in range(_START_STEPS if it == 0 else _LOCAL_STEPS):
            worst = 0.0
            for b in range(nball):
                worst = max(worst, w[_L_RES, b])
            if worst <= resolve:
                break
            _lane_local_step(nball, w, dist)
            _lane_balls(w, s0, c0, dist, k, ball_floor)
        for b in range(nball):
            if not w[_L_RES, b] <= resolve:  # solve this ball alone (NaN included)
                _lane_work(w, b, s0, c0, dist, work)
                px, py, _, ok, _ = flank_newton(work, 0, 4, dist, w[_L_H, b], k, 0.0, 0.0,
                                                w[_L_P, b], w[_L_P + 1, b], ball_tol,
                                                ball_max_iter, ball_floor, reg, False)
                if not ok:
                    return -1
                w[_L_P, b] = px
                w[_L_P + 1, b] = py
                _lane_balls(w[:, b:b + 1], s0, c0, dist, k, ball_floor)
        fmax, force2, balls_ok = _track_assembly(w, frame, zeta, q_ext, residual[0], reduced,
                                                 tangent[0], ball_tol)
        state[0, 0] = np.nan  # (no energy: no line search)
        state[0, 1] = fmax
        state[0, 2] = force2
        err = _scaled_error(residual[0], free, max(max(load_norm, fmax), force_floor))
        if balls_ok and err <= tol:
            if not force2 > 0.0 and load_norm > 0.0:
                return -1
            return it
        if it >= max_iter:
            return -1
        it += 1
        if not _cholesky(tangent[0], free, low) > singular:
            return -1
        _cholesky_solve(low, free, reduced, step)
        move = 0.0
        for b in range(nball):
            gx = gy = 0.0
            for j in range(5):
                gx += amap[j, b] * step[j]
                gy += amap[5 + j, b] * step[j]
            w[_L_DG, b] = gx
            w[_L_DG + 1, b] = gy
            move = max(move, max(abs(gx), abs(gy)))
        damp = cap / move if move > cap else 1.0
        for j in range(5):
            q[j] += damp * step[j]
        big = 0.0
        for b in range(nball):
            dgx, dgy = w[_L_DG, b], w[_L_DG + 1, b]
            dpx = damp * (w[_L_W, b] * dgx + w[_L_W + 1, b] * dgy - w[_L_D, b])
            dpy = damp * (w[_L_W + 2, b] * dgx + w[_L_W + 3, b] * dgy - w[_L_D + 1, b])
            w[_L_P, b] += dpx
            w[_L_P + 1, b] += dpy
            big = max(big, dpx * dpx + dpy * dpy)
        if not big <= (0.1 * dist) ** 2:
            return -1
    return -1


@jit
def _nested_newton(q, free, groove_map, geometric, base, half, dist, k, tol, max_iter,
                   ball_tol, ball_max_iter, ball_floor, force_floor, load_norm, k_ref, singular,
                   cap, limit, q_ext, pos, grv, resp, ball_ok, work, residual, tangent, state,
                   kreg, low, step, trial):
    """The Newton of :func:`solve_carriage` on q, every ball solved at each evaluation.

    Returns (status, iterations, buffer of the solution, buffer of the last evaluation).
    """
    nball = groove_map.shape[0]
    cur = 0
    last = 0
    it = 0
    if _evaluate_balls(q, False, 0, cur, groove_map, base, half, dist, k, ball_tol,
                       ball_max_iter, ball_floor, limit, q_ext, pos, grv, resp, ball_ok, work,
                       residual, tangent, state) != 0:
        return STATUS_LIFT_OFF, it, cur, last
    status = STATUS_NOT_CONVERGED
    potential = state[cur, 0]
    for j in range(5):
        potential -= q_ext[j] * q[j]
    while True:
        err = _scaled_error(residual[cur], free, max(max(load_norm, state[cur, 1]), force_floor))
        if err <= tol:
            status = STATUS_CONVERGED
            break
        if it >= max_iter:
            break
        it += 1
        if not _cholesky(tangent[cur], free, low) > singular:  # singular: regularise
            if not state[cur, 2] > 0.0 and it > 1:
                return STATUS_LIFT_OFF, it, cur, last
            for i in range(5):
                for j in range(5):
                    kreg[i, j] = tangent[cur, i, j] + k_ref * geometric[i, j]
            if not _cholesky(kreg, free, low) > 0.0:
                return STATUS_LIFT_OFF, it, cur, last
        _cholesky_solve(low, free, residual[cur], step)
        move = 0.0
        for b in range(nball):
            for c in range(2):
                g = 0.0
                for j in range(5):
                    g += groove_map[b, c, j] * step[j]
                move = max(move, abs(g))
        if move > cap:
            for j in range(5):
                step[j] *= cap / move
        slope = 0.0  # d potential / d alpha at 0
        for j in range(5):
            slope -= residual[cur, j] * step[j]
        nxt = 1 - cur
        alpha = 1.0
        found = -1.0  # alpha of the last valid candidate
        last_ok = False
        accepted = False
        pot = potential
        for _ in range(40):
            for j in range(5):
                trial[j] = q[j] + alpha * step[j]
            last = nxt
            last_ok = _evaluate_balls(trial, True, cur, nxt, groove_map, base, half, dist, k,
                                      ball_tol, ball_max_iter, ball_floor, limit, q_ext, pos,
                                      grv, resp, ball_ok, work, residual, tangent, state) == 0
            if last_ok:
                found = alpha
                pot = state[nxt, 0]
                for j in range(5):
                    pot -= q_ext[j] * trial[j]
                scale = max(max(load_norm, state[nxt, 1]), force_floor)
                if (pot <= potential + 1e-4 * alpha * slope
                        or _scaled_error(residual[nxt], free, scale) < (1.0 - 1e-4 * alpha) * err):
                    accepted = True
                    break
            alpha *= 0.5
        if found < 0.0:
            return STATUS_LIFT_OFF, it, cur, last
        if not accepted:  # the last valid candidate (re-evaluated if overwritten since)
            alpha = found
            for j in range(5):
                trial[j] = q[j] + alpha * step[j]
            if not last_ok:
                last = nxt
                _evaluate_balls(trial, True, cur, nxt, groove_map, base, half, dist, k,
                                ball_tol, ball_max_iter, ball_floor, limit, q_ext, pos, grv,
                                resp, ball_ok, work, residual, tangent, state)
            pot = state[nxt, 0]
            for j in range(5):
                pot -= q_ext[j] * trial[j]
        for j in range(5):
            q[j] = trial[j]
        potential = pot
        cur = nxt
        last = cur
    if not state[cur, 2] > 0.0 and load_norm > 0.0:
        return STATUS_LIFT_OFF, it, cur, last
    return status, it, cur, last


@jit(inline="always")
def _unloaded_outputs(loaded, a, out_dbeta, out_force, out_side, out_normal, out_count,
                      out_ball_converged):
    """The outputs of the balls of assembly a outside the loaded zone (``loaded`` False):
    no force, no contact, NaN contact angles and loads, converged (nothing to solve)."""
    for b in range(loaded.shape[0]):
        if not loaded[b]:
            out_count[a, b] = 0
            out_side[a, b] = np.nan
            out_normal[a, b] = np.nan
            out_ball_converged[a, b] = True
            for i in range(4):
                out_dbeta[a, b, i] = np.nan
                out_force[a, b, i] = 0.0


@pjit
def carriage_batch_kernel(groove_maps, amaps, frame, zetas, free, geometrics, geometric_maxs,
                          loaded, load, start, e_n, e_t, rot_b, rot_t, off_b, off_t,
                          oversize_error,
                          oversize, scale, beta0, dist, k, tol, max_iter, ball_tol,
                          ball_max_iter, out_dbeta, out_force, out_side, out_normal, out_count,
                          out_ball_converged, out_displacement, out_stiffness, out_residual,
                          out_iterations, out_status, out_fallback, joint):
    """Equilibrium of many carriage assemblies (see :func:`solve_carriage_batch`).

    Scaled coordinates as in :func:`solve_carriage` (q_s = q / scale, rotations times L).
    Ball inputs have a first axis of m n_balls (assembly a, ball b at row a n_balls + b) or
    1 (the ball's oversize is ``oversize_error`` + ``oversize``, the two of
    :func:`solve_carriage`); ``load`` (m or 1, 5) holds Q [N, N m] and ``start`` (m or 1, 5)
    the scaled start of q.
    ``groove_maps`` (m or 1, n_balls, 2, 5) is the scaled A of each assembly and ``amaps``
    (m or 1, 10, n_balls) the same by rows (row 5 c + j: A[:, c, j]); ``frame`` (n_tracks, 4)
    holds cos phi, sin phi, x / L and y / L of each track and ``zetas`` (m or 1, n_balls)
    z_b / L (:func:`_track_assembly`); ``free`` the indices of the free DOFs, ``geometrics``
    (m or 1, 5, 5) sum_b A_b^T A_b and ``geometric_maxs`` (m or 1,) the largest eigenvalue of
    its free block; ``loaded`` (m or 1, n_balls) marks the balls in the loaded zone. A ball
    that is not loaded has zero rows in A and a radius of R_B - d/2 in the kernel (no flank
    touches it, so it carries and transmits nothing); its outputs are overwritten: no force,
    NaN angles and loads, count 0, converged. Assembly a is solved by the same sequence of
    operations whatever the batch and the thread count (scratch per tile of _ASSEMBLY_TILE
    assemblies, overwritten before use).

    Per assembly: the arc centres of every ball once (only the carriage groove moves with q;
    :func:`_lane_arc_centres`); the reference ball force f_ref and stiffness k_ref of
    :func:`solve_carriage`; the balls start from the mean of their four touching positions
    (as ``displacement_one``) with the carriage groove at A q_start; then, if ``joint``,
    :func:`_joint_newton`, and where it fails (or without ``joint``) :func:`_nested_newton`
    from the start again (``out_fallback``). A tangent whose smallest Cholesky pivot is below
    1e-10 k_ref ``geometric_max`` counts as singular (:func:`solve_carriage` compares its
    smallest eigenvalue with the largest of k_ref sum_b A_b^T A_b: the same zero tangents).
    Outputs as :class:`CarriageBatch` (scaled back: q = q_s scale, K = K_s / scale scale^T).
    """
    nasm = out_status.shape[0]
    nball = groove_maps.shape[1]
    s0, c0 = np.sin(beta0), np.cos(beta0)
    floor = k * FLOOR_LENGTH**1.5
    limit = _LIFT_OFF * dist
    cap = _STEP_CAP * dist
    for tile in prange((nasm + _ASSEMBLY_TILE - 1) // _ASSEMBLY_TILE):
        base = np.empty((nball, 4, 6))
        half = np.empty(nball)
        w = np.empty((_L_ROWS, nball))
        pos = np.empty((2, nball, 2))
        grv = np.empty((2, nball, 2))
        resp = np.empty((2, nball, 4))
        ball_ok = np.empty((2, nball), dtype=np.bool_)
        residual = np.empty((2, 5))
        tangent = np.empty((2, 5, 5))
        state = np.empty((2, 3))
        q = np.empty(5)
        q_ext = np.empty(5)
        step = np.empty(5)
        trial = np.empty(5)
        reduced = np.empty(5)
        kreg = np.empty((5, 5))
        low = np.empty((5, 5))
        work = np.empty((4, 6))
        unit = np.empty((4, 2))
        approach = np.empty((nball, 4))
        for a in range(tile * _ASSEMBLY_TILE, min(nasm, (tile + 1) * _ASSEMBLY_TILE)):
            il = a if load.shape[0] > 1 else 0
            i_s = a if start.shape[0] > 1 else 0
            ig = a if groove_maps.shape[0] > 1 else 0
            iz = a if loaded.shape[0] > 1 else 0
            groove_map, amap, zeta = groove_maps[ig], amaps[ig], zetas[ig]
            geometric, geometric_max = geometrics[ig], geometric_maxs[ig]
            load_norm = 0.0
            for j in range(5):
                q_ext[j] = load[il, j] * scale[j]
                load_norm = max(load_norm, abs(q_ext[j]))
                q[j] = start[i_s, j]
            omax = -np.inf
            nloaded = 0
            for b in range(nball):
                n = a * nball + b
                o = (oversize_error[n if oversize_error.shape[0] > 1 else 0]
                     + oversize[n if oversize.shape[0] > 1 else 0])
                if loaded[iz, b]:
                    half[b] = 0.5 * o
                    omax = max(omax, o)
                    nloaded += 1
                else:  # free: no flank reaches it
                    half[b] = -0.5 * dist
                w[_L_H, b] = half[b]
            _lane_arc_centres(a, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0, dist, w, work)
            for b in range(nball):
                # start: the mean of the four touching positions C_i + (d - h) n_i, as
                # displacement_one, with the carriage flanks moved by g = A q
                px = py = 0.0
                for i in range(4):
                    sx = -1.0 if (i == 0 or i == 3) else 1.0
                    sy = -1.0 if i < 2 else 1.0
                    px += 0.25 * (w[_L_DC + 2 * i, b] - half[b] * (sx * s0))
                    py += 0.25 * (w[_L_DC + 2 * i + 1, b] - half[b] * (sy * c0))
                gx = gy = 0.0
                for j in range(5):
                    gx += amap[j, b] * q[j]
                    gy += amap[5 + j, b] * q[j]
                w[_L_P, b] = px + 0.5 * gx
                w[_L_P + 1, b] = py + 0.5 * gy
            # reference ball force and stiffness, as solve_carriage
            f_ref = max(load_norm / max(nloaded, 1), k * max(0.5 * omax, 0.0) ** 1.5)
            delta_ref = max((f_ref / k) ** (2.0 / 3.0), FLOOR_LENGTH)
            k_ref = 1.5 * k * np.sqrt(delta_ref) * 0.5
            ball_floor = max(f_ref, floor)
            singular = 1e-10 * k_ref * geometric_max
            it = -1
            if joint:
                it = _joint_newton(q, free, amap, frame, zeta, w, s0, c0, dist, k, tol,
                                   _JOINT_MAX_ITER, ball_tol, ball_max_iter, ball_floor, floor,
                                   load_norm, singular, cap, limit, _RESOLVE, q_ext, residual,
                                   tangent, state, work, low, step, reduced)
            out_fallback[a] = joint and it < 0
            if it >= 0:
                status, cur, last = STATUS_CONVERGED, 0, 0
                for b in range(nball):
                    pos[0, b, 0] = w[_L_P, b]
                    pos[0, b, 1] = w[_L_P + 1, b]
                    grv[0, b, 0] = w[_L_G, b]
                    grv[0, b, 1] = w[_L_G + 1, b]
                    ball_ok[0, b] = True
            else:
                for j in range(5):
                    q[j] = start[i_s, j]
                for b in range(nball):
                    arc_centres(a * nball + b, e_n, e_t, rot_b, rot_t, off_b, off_t, s0, c0,
                                dist, base[b])
                status, it, cur, last = _nested_newton(
                    q, free, groove_map, geometric, base, half, dist, k, tol, max_iter,
                    ball_tol, ball_max_iter, ball_floor, floor, load_norm, k_ref, singular, cap,
                    limit, q_ext, pos, grv, resp, ball_ok, work, residual, tangent, state, kreg,
                    low, step, trial)
            out_status[a] = status
            out_iterations[a] = it
            if status == STATUS_LIFT_OFF:
                for b in range(nball):
                    out_ball_converged[a, b] = ball_ok[last, b]
                    out_count[a, b] = 0
                    out_side[a, b] = np.nan
                    out_normal[a, b] = np.nan
                    for i in range(4):
                        out_dbeta[a, b, i] = np.nan
                        out_force[a, b, i] = np.nan
                for i in range(5):
                    out_displacement[a, i] = np.nan
                    out_residual[a, i] = np.nan
                    for j in range(5):
                        out_stiffness[a, i, j] = np.nan
                continue
            if not out_fallback[a] and joint:  # from the lanes of the joint Newton
                _lane_angles(w, s0, c0, dist)
                for b in range(nball):
                    count = 0
                    for i in range(4):
                        f = w[_L_F01 + i, b] if i < 2 else w[_L_F23 + i - 2, b]
                        out_force[a, b, i] = f
                        count += f > 0.0
                        dbeta = w[_L_DB + i, b]
                        if np.isnan(dbeta):  # beyond the series: as ball_outputs
                            _lane_work(w, b, s0, c0, dist, work)
                            ux, uy, _, _, _, _ = flank(w[_L_P, b], w[_L_P + 1, b], work, i,
                                                       dist, half[b], k)
                            nx, ny = work[i, 4], work[i, 5]
                            sxy = 1.0 if (i == 0 or i == 2) else -1.0
                            dbeta = np.arctan2(sxy * (ny * ux - nx * uy), nx * ux + ny * uy)
                        out_dbeta[a, b, i] = dbeta
                    out_count[a, b] = count
                    # (N_x, -N_y) = -(F_TR u_TR + F_TL u_TL), as displacement_one
                    out_side[a, b] = -w[_L_F, b]
                    out_normal[a, b] = w[_L_F + 1, b]
                    out_ball_converged[a, b] = True
                for i in range(5):
                    out_displacement[a, i] = q[i] * scale[i]
                    out_residual[a, i] = residual[0, i] / scale[i]
                    for j in range(5):
                        out_stiffness[a, i, j] = tangent[0, i, j] / (scale[i] * scale[j])
                if nloaded < nball:
                    _unloaded_outputs(loaded[iz], a, out_dbeta, out_force, out_side,
                                      out_normal, out_count, out_ball_converged)
                continue
            dbeta_a = out_dbeta[a]
            force_a = out_force[a]
            for b in range(nball):
                for i in range(4):
                    for c in range(6):
                        work[i, c] = base[b, i, c]
                move_top_groove(work, grv[cur, b, 0], grv[cur, b, 1])
                out_count[a, b] = ball_outputs(b, work, pos[cur, b, 0], pos[cur, b, 1], dist,
                                               half[b], k, dbeta_a, force_a, approach, unit)
                # (N_x, -N_y) = -(F_TR u_TR + F_TL u_TL), as displacement_one
                out_side[a, b] = -(force_a[b, 2] * unit[2, 0] + force_a[b, 3] * unit[3, 0])
                out_normal[a, b] = force_a[b, 2] * unit[2, 1] + force_a[b, 3] * unit[3, 1]
                out_ball_converged[a, b] = ball_ok[cur, b]
            for i in range(5):
                out_displacement[a, i] = q[i] * scale[i]
                out_residual[a, i] = residual[cur, i] / scale[i]
                for j in range(5):
                    out_stiffness[a, i, j] = tangent[cur, i, j] / (scale[i] * scale[j])
            if nloaded < nball:
                _unloaded_outputs(loaded[iz], a, out_dbeta, out_force, out_side, out_normal,
                                  out_count, out_ball_converged)


def end_relief(ball_z, zone_length: float, depth: float, length: float) -> np.ndarray:
    """Recess of the carriage flanks at the ends of the loaded zone (crowning) [m].

    h(z) = depth ((|z| - (L/2 - l)) / l)^2 for |z| > L/2 - l, else 0, with |z| taken at most
    L/2 (module docstring, "end relief"); apply it as ``arc_centre_offset_normal`` of the TR and
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


@dataclass(frozen=True)
class CarriageBatch:
    """Equilibria of m sampled carriage assemblies (:func:`solve_carriage_batch`).

    Ball arrays are over (m, n_tracks, n), contacts BL, BR, TR, TL. An assembly with status
    ``STATUS_LIFT_OFF`` has NaN forces, angles, loads, displacement, stiffness and residual,
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
        ``STATUS_CONVERGED`` (0), ``STATUS_NOT_CONVERGED`` (1: max_iter steps without
        reaching tol; the last iterate is reported) or ``STATUS_LIFT_OFF`` (2: the carriage
        lifted off, its motion left the gothic arch, or a ball solve failed); ``BATCH_STATUS``
        describes each.
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


def _carried(layout, load, q_s_ext):
    """Locked DOFs and the free mask; ValueError for a load along a locked mechanism."""
    locked, null = locked_dofs(layout)
    free = np.array([name not in locked for name in DOFS])
    load_norm = np.abs(q_s_ext).max()
    if null.shape[1] and load_norm > 0:
        along = null.T @ q_s_ext
        if np.abs(along).max() > 1e-9 * load_norm:
            raise ValueError(f"the track layout cannot carry the load ({load.describe()}): "
                             f"it has no stiffness against a motion of {', '.join(locked)}")
    return locked, free


def _ball_positions(layout, ball_z, loaded):
    """``ball_z`` [m] and ``loaded`` of :func:`solve_carriage_batch`, validated and
    broadcast to a common (m, n_tracks, n)."""
    t, n = layout.n_tracks, layout.balls_per_track
    z = layout.ball_z if ball_z is None else np.asarray(ball_z, dtype=float)
    mask = True if loaded is None else np.asarray(loaded)
    if mask is not True and mask.dtype != np.bool_:
        raise ValueError(f"loaded must be an array of bool, got dtype {mask.dtype}")
    if not np.all(np.isfinite(z)):
        raise ValueError("ball_z must be finite")
    try:
        shape = np.broadcast_shapes(np.shape(z), np.shape(mask), (t, n))
    except ValueError:
        shape = ()
    if not 2 <= len(shape) <= 3 or shape[-2:] != (t, n):
        raise ValueError(f"ball_z {np.shape(z)} and loaded {np.shape(mask)} must broadcast to "
                         f"(assemblies, n_tracks, balls_per_track) = (m, {t}, {n})")
    shape = (1,) * (3 - len(shape)) + shape
    return (np.ascontiguousarray(np.broadcast_to(z, shape)),
            np.ascontiguousarray(np.broadcast_to(mask, shape)))


def _ball_inputs(layout, oversize, groove_errors, bearing):
    t, n = layout.n_tracks, layout.balls_per_track
    errors = GrooveErrors() if groove_errors is None else groove_errors
    items = [("groove_displacement", np.zeros((t, n, 2)), 2)]
    items += error_items(errors, bearing)
    items.append(("oversize", 0.0 if oversize is None else oversize, 0))
    arrays, shape = prepare_inputs(items, bearing)
    if shape != (t, n):
        raise ValueError(f"oversize and groove errors must broadcast to the balls (n_tracks, "
                         f"balls_per_track) = {(t, n)}, got {shape}")
    _, e_n, e_t, rot_b, rot_t, off_b, off_t, dd, extra = arrays
    total = np.ascontiguousarray(np.broadcast_to(dd[:, 0] + extra[:, 0], (t * n,)))
    return e_n, e_t, rot_b[:, 0].copy(), rot_t[:, 0].copy(), off_b, off_t, total


def _batch_inputs(layout, oversize, groove_errors, bearing):
    """Ball inputs of m assemblies for :func:`carriage_batch_kernel`, and m.

    Each input's first axis is m n_balls (assembly a, ball b = t n + j at row a n_balls + b)
    or 1 (the same for every ball of every assembly).
    """
    t, n = layout.n_tracks, layout.balls_per_track
    errors = GrooveErrors() if groove_errors is None else groove_errors
    items = error_items(errors, bearing)
    items.append(("oversize", 0.0 if oversize is None else oversize, 0))
    arrays, shape = prepare_inputs(items, bearing)
    try:
        full = np.broadcast_shapes(shape, (t, n))
    except ValueError:
        full = ()
    if not 2 <= len(full) <= 3:
        raise ValueError(f"oversize and groove errors must broadcast to (assemblies, n_tracks, "
                         f"balls_per_track) = (m, {t}, {n}), got ball shape {shape}")
    full = (1,) * (3 - len(full)) + full
    rows = int(np.prod(full))
    flat = []
    for arr in arrays:
        if arr.shape[0] not in (1, rows):  # broadcast over the missing axes of ``shape``
            width = arr.shape[1]
            arr = np.ascontiguousarray(np.broadcast_to(
                arr.reshape(shape + (width,)), full + (width,)).reshape(rows, width))
        flat.append(arr)
    e_n, e_t, rot_b, rot_t, off_b, off_t, dd, extra = flat
    # (columns of (rows, 1) arrays are contiguous views; the kernel adds the two oversizes)
    return (e_n, e_t, rot_b[:, 0], rot_t[:, 0], off_b, off_t, dd[:, 0], extra[:, 0]), full[0]


class _Balls:
    """Evaluates all balls of one assembly at a carriage displacement."""

    def __init__(self, inputs, bearing, nball, tol, max_iter, floor):
        self.inputs = inputs
        self.beta0 = bearing.nominal_contact_angle
        self.dist = bearing.groove_radius - bearing.ball_radius
        self.k = hertz_k(bearing)
        self.tol, self.max_iter, self.nball, self.floor = tol, max_iter, nball, floor

    def __call__(self, groove):
        n = self.nball
        out = dict(dbeta=np.empty((n, 4)), force=np.empty((n, 4)), approach=np.empty((n, 4)),
                   ball=np.empty((n, 2)), load=np.empty((n, 2)),
                   converged=np.empty(n, dtype=np.bool_), iterations=np.empty(n, np.int64),
                   count=np.empty(n, np.int64), residual=np.empty(n),
                   stiffness=np.empty((n, 2, 2)), energy=np.empty(n))
        carriage_balls_kernel(np.ascontiguousarray(groove), *self.inputs, self.beta0, self.dist,
                              self.k, self.tol, self.max_iter, self.floor, *out.values())
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
        Tolerance and step cap of each ball's solve (the imbalance relative to the larger
        of the ball's largest flank force and the reference ball force f_ref; module
        docstring).

    Returns
    -------
    CarriageSolution

    Raises
    ------
    ValueError
        Bad input; a load the layout cannot carry (a component along a locked mechanism);
        a carriage that lifts off.
    """
    check_solver_options(tol, max_iter)
    check_solver_options(ball_tol, ball_max_iter)
    q_ext = load.generalised()
    t, n = layout.n_tracks, layout.balls_per_track
    nball = t * n
    inputs = _ball_inputs(layout, oversize, groove_errors, bearing)
    length = layout.length_scale()
    scale = np.array([1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
    a = layout.groove_map().reshape(nball, 2, 5)
    a_s = a * scale  # groove map in scaled coordinates (rotations times L)
    q_s_ext = q_ext * scale  # moments / L
    locked, free = _carried(layout, load, q_s_ext)
    load_norm = np.abs(q_s_ext).max()
    dist = bearing.groove_radius - bearing.ball_radius
    k = hertz_k(bearing)
    # reference ball force (load share or flank preload): the force floor of the ball
    # tolerance, and with its approach the ball stiffness for the regularised start
    total_o = inputs[-1]
    f_ref = max(load_norm / nball, k * max(0.5 * float(total_o.max()), 0.0) ** 1.5)
    balls = _Balls(inputs, bearing, nball, ball_tol, ball_max_iter,
                   max(f_ref, k * FLOOR_LENGTH**1.5))

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

    delta_ref = max((f_ref / k) ** (2.0 / 3.0), FLOOR_LENGTH)
    k_ref = 1.5 * k * np.sqrt(delta_ref) * 0.5
    geometric = k_ref * np.einsum("bik,bil->kl", a_s, a_s)

    def scaled_norm(out):
        fmax = max(load_norm, float(out["force"].max()), k * FLOOR_LENGTH**1.5)
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
                trial, alpha_trial = cand, alpha
                if (cand["potential"] <= out["potential"] + 1e-4 * alpha * slope
                        or scaled_norm(cand) < (1.0 - 1e-4 * alpha) * r2):
                    break
            alpha *= 0.5
        if trial is None:
            raise lift_off()
        q_s = q_s + alpha_trial * step
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


def solve_carriage_batch(layout: CarriageLayout, load: CarriageLoad, bearing: Bearing = TABLE1,
                         *, oversize=None, groove_errors: GrooveErrors | None = None,
                         nominal_oversize=None, ball_z=None, loaded=None, start=None,
                         tol: float = CARRIAGE_TOLERANCE, max_iter: int = CARRIAGE_MAX_ITER,
                         ball_tol: float = DEFAULT_TOLERANCE,
                         ball_max_iter: int = DEFAULT_MAX_ITER,
                         joint: bool = True) -> CarriageBatch:
    """Equilibria of many sampled carriage assemblies under one load, in parallel.

    Each assembly is solved to the certificate of :func:`solve_carriage` (every ball's and
    the carriage's balance within ``ball_tol`` and ``tol``), by the joint Newton on balls and
    carriage together or, where that does not converge, by the nested Newton of
    :func:`solve_carriage` (module docstring, "Many assemblies at once"), compiled, with the
    assemblies in parallel (:func:`carriage_batch_kernel`). The results agree with
    :func:`solve_carriage` to about 1e-11 of their scale (forces, stiffness, angles) and
    1e-10 in displacement (up to 1e-9 on a badly conditioned carriage; tested to 1e-9 in
    ``tests/test_carriage_batch.py``), except the contact angles of loose balls, whose
    position is not unique. Every
    assembly starts from the solution q0 of the nominal assembly (no groove errors,
    ``nominal_oversize``) by :func:`solve_carriage`, or from q = 0 if that one lifts off.

    An assembly is solved by the same operations whatever batch it is in and whatever the
    number of Numba threads: its result is bit-identical alone or in any batch. An assembly
    that lifts off or fails is reported by ``status``, never raised.

    Parameters
    ----------
    layout : CarriageLayout
        Tracks and balls (the same for all assemblies).
    load : CarriageLoad
        External load at the reference point [N, N m] (the same for all assemblies).
    bearing : Bearing
        Ball, groove and material of every module (default [Lin2018] Table 1).
    oversize : array_like, optional
        Ball diametral oversize o [m] (nominal preload plus deviation), broadcast to (m,
        n_tracks, n) by NumPy's rules; added to ``groove_errors.ball_oversize``. Default 0.
    groove_errors : GrooveErrors, optional
        Errors of each ball's module in its module frame (:mod:`tolsim.physics.static`),
        fields broadcast to (m, n_tracks, n) + their trailing axis. The number of assemblies
        m is the leading axis of the common broadcast shape of ``oversize`` and the error
        fields (1 if they have at most two axes).
    nominal_oversize : array_like, optional
        Oversize [m] of the nominal assembly whose solution starts every Newton, broadcast to
        (n_tracks, n). Default: ``oversize`` if it has at most two axes (the same for all
        assemblies, e.g. the preload class, with the sampled scatter in ``groove_errors``),
        else 0. Not used with ``start``.
    ball_z : array_like, optional
        Axial position z of every ball of every assembly [m], broadcast to (m, n_tracks, n)
        (balls moving through the carriage, :mod:`tolsim.study.pipeline.carriage_track`). Default:
        the layout's nominal z_j (``layout.ball_z``). The layout's ``balls_per_track`` is
        then the number of ball slots per track, not all of them loaded.
    loaded : array_like of bool, optional
        Whether each ball is in the loaded zone, broadcast to (m, n_tracks, n); default all.
        A ball outside carries nothing: its rows of the groove map are zero and no flank
        touches it (in the kernel its radius is R_B - d/2). Its outputs: ``normal_force``
        0, ``contact_count`` 0, ``contact_angle_deviation``, ``side_load`` and
        ``normal_load`` NaN, ``ball_converged`` True. Its errors and oversize are ignored
        but must be finite.
    start : array_like, optional
        Carriage displacement q [m, rad] (``DOFS`` order) that every Newton starts from,
        (5,) or (m, 5), e.g. each assembly's solution of the previous time step. Default:
        the solution of the nominal assembly (:func:`solve_carriage`, layout's nominal z,
        every ball loaded), or q = 0 if it lifts off.
    tol, max_iter, ball_tol, ball_max_iter
        As in :func:`solve_carriage`, for every assembly (``max_iter`` caps the nested
        Newton; the joint one gives up after 12 steps).
    joint : bool
        Try the joint Newton first (default). False solves every assembly by the nested
        Newton alone: the same results to about 1e-11, 3.5 times slower.

    Returns
    -------
    CarriageBatch

    Raises
    ------
    ValueError
        Bad input (shapes, non-finite values, errors out of range, solver options); a load
        the layout cannot carry (a component along a locked mechanism), as
        :func:`solve_carriage`.

    Notes
    -----
    The locked DOFs are those of the layout's nominal balls, whatever ``ball_z`` and
    ``loaded``. Without ``ball_z`` and ``loaded`` the solve is exactly the one of the fixed
    nominal balls (bit-identical); with them, the groove map A, sum_b A_b^T A_b and its
    largest eigenvalue are formed per assembly.
    """
    check_solver_options(tol, max_iter)
    check_solver_options(ball_tol, ball_max_iter)
    q_ext = load.generalised()
    t, n = layout.n_tracks, layout.balls_per_track
    nball = t * n
    inputs, m = _batch_inputs(layout, oversize, groove_errors, bearing)
    length = layout.length_scale()
    scale = np.array([1.0, 1.0, 1.0 / length, 1.0 / length, 1.0 / length])
    locked, free = _carried(layout, load, q_ext * scale)
    free_index = np.flatnonzero(free).astype(np.int64)
    if ball_z is None and loaded is None:  # the fixed nominal balls
        a_s = np.ascontiguousarray(layout.groove_map().reshape(nball, 2, 5) * scale)
        geometric = np.einsum("bik,bil->kl", a_s, a_s)
        geometric_max = float(np.linalg.eigvalsh(geometric[np.ix_(free, free)])[-1])
        amap = np.ascontiguousarray(a_s.transpose(1, 2, 0).reshape(10, nball))
        maps = (a_s[None], amap[None], np.tile(layout.ball_z / length, t)[None],
                geometric[None], np.array([geometric_max]), np.ones((1, nball), np.bool_))
    else:  # balls at their own z, in or out of the loaded zone (per assembly)
        z, mask = _ball_positions(layout, ball_z, loaded)
        if z.shape[0] != m and m != 1 and z.shape[0] != 1:
            raise ValueError(f"ball_z and loaded have {z.shape[0]} assemblies, oversize and "
                             f"groove errors {m}")
        if z.shape[0] > m:  # errors shared by the assemblies: one row of inputs each
            base = 0.0 if oversize is None else np.asarray(oversize, dtype=float)
            inputs, m = _batch_inputs(layout, np.broadcast_to(base, z.shape), groove_errors,
                                      bearing)
        z, mask = np.broadcast_to(z, (m, t, n)), np.broadcast_to(mask, (m, t, n))
        a_s = layout.groove_map_at(z).reshape(z.shape[0], nball, 2, 5) * scale
        a_s = np.ascontiguousarray(np.where(mask.reshape(-1, nball, 1, 1), a_s, 0.0))
        flat = a_s.reshape(-1, 2 * nball, 5)
        geometric = np.matmul(flat.transpose(0, 2, 1), flat)
        geometric_max = np.ascontiguousarray(
            np.linalg.eigvalsh(geometric[:, free][:, :, free])[:, -1])
        amap = np.ascontiguousarray(a_s.transpose(0, 2, 3, 1).reshape(-1, 10, nball))
        maps = (a_s, amap, np.ascontiguousarray(z.reshape(-1, nball) / length), geometric,
                geometric_max, np.ascontiguousarray(mask.reshape(-1, nball)))

    if start is not None:
        start = np.asarray(start, dtype=float)
        if start.shape not in ((5,), (m, 5)) or not np.all(np.isfinite(start)):
            raise ValueError(f"start must hold finite q of shape (5,) or ({m}, 5), got shape "
                             f"{start.shape}")
        start = np.ascontiguousarray(np.atleast_2d(start / scale))
    else:
        if nominal_oversize is None:
            nominal_oversize = oversize if oversize is None or np.ndim(oversize) <= 2 else 0.0
        _ball_inputs(layout, nominal_oversize, None, bearing)  # validate before solving
        try:
            nominal = solve_carriage(layout, load, bearing, oversize=nominal_oversize, tol=tol,
                                     max_iter=max_iter, ball_tol=ball_tol,
                                     ball_max_iter=ball_max_iter)
            start = nominal.displacement / scale if nominal.converged else np.zeros(5)
        except ValueError:  # the nominal assembly lifts off (the input was checked above)
            start = np.zeros(5)
        start = start[None, :]

    shape = (m, t, n)
    dbeta = np.empty((m, nball, 4))
    force = np.empty((m, nball, 4))
    side = np.empty((m, nball))
    normal = np.empty((m, nball))
    count = np.empty((m, nball), dtype=np.int8)
    ball_ok = np.empty((m, nball), dtype=np.bool_)
    displacement = np.empty((m, 5))
    stiffness = np.empty((m, 5, 5))
    residual = np.empty((m, 5))
    iterations = np.empty(m, dtype=np.int32)
    status = np.empty(m, dtype=np.int8)
    fallback = np.empty(m, dtype=np.bool_)
    frame = np.stack([np.cos(layout.track_orientation), np.sin(layout.track_orientation),
                      layout.track_x / length, layout.track_y / length], axis=1)
    groove_maps, amaps, zetas, geometrics, geometric_maxs, loaded_rows = maps
    carriage_batch_kernel(groove_maps, amaps, frame, zetas, free_index, geometrics,
                          geometric_maxs, loaded_rows, q_ext[None, :], start, *inputs, scale,
                          bearing.nominal_contact_angle,
                          bearing.groove_radius - bearing.ball_radius, hertz_k(bearing),
                          float(tol), int(max_iter), float(ball_tol), int(ball_max_iter),
                          dbeta, force, side, normal, count, ball_ok, displacement, stiffness,
                          residual, iterations, status, fallback, bool(joint))
    return CarriageBatch(
        contact_angle_deviation=dbeta.reshape(shape + (4,)),
        normal_force=force.reshape(shape + (4,)),
        side_load=side.reshape(shape),
        normal_load=normal.reshape(shape),
        contact_count=count.reshape(shape),
        ball_converged=ball_ok.reshape(shape),
        displacement=displacement,
        stiffness=stiffness,
        residual=residual,
        converged=status == STATUS_CONVERGED,
        iterations=iterations,
        status=status,
        fallback=fallback,
        locked=locked,
    )


__all__ = [
    "BATCH_STATUS",
    "CARRIAGE_MAX_ITER",
    "CARRIAGE_TOLERANCE",
    "DOFS",
    "STATUS_CONVERGED",
    "STATUS_LIFT_OFF",
    "STATUS_NOT_CONVERGED",
    "CarriageBatch",
    "CarriageLayout",
    "CarriageLoad",
    "CarriageSolution",
    "carriage_balls_kernel",
    "carriage_batch_kernel",
    "condensed_ball",
    "end_relief",
    "locked_dofs",
    "schur_complement",
    "solve_carriage",
    "solve_carriage_batch",
]
