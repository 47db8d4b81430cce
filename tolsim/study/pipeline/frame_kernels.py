"""Compiled passes of the free balls' steps (:class:`tolsim.study.pipeline.propagation.FreeBalls`
and :class:`tolsim.study.pipeline.propagation.FirstContact`): the motion, the gaps, the first
contact.

Each kernel does in one pass, element by element, what a chain of NumPy calls did: the same
operations in the same order, so the results are bit-identical to those calls.
"""

import numpy as np

from tolsim._jit import jit
from tolsim.study.pipeline.ball_kernels import nan_to_num_one


@jit
def free_motion_kernel(position, w, h, v, out):
    """``out`` = position + h (1 + nan_to_num(w)) / 2 v, as ``position + h * (1.0 +
    np.nan_to_num(w)) * 0.5 * v`` (flat arrays; positions [m], epsilon [-], h [s], v [m/s])."""
    for i in range(position.shape[0]):
        out[i] = position[i] + h * (1.0 + nan_to_num_one(w[i])) * 0.5 * v


@jit
def gaps_kernel(position, diameter, out):
    """The gaps of (m, balls) ball centres [m]: ``np.diff(position, axis=1) - diameter`` into
    ``out`` (m, balls - 1)."""
    for r in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[r, j] = (position[r, j + 1] - position[r, j]) - diameter


@jit
def first_contact_kernel(gap_old, gap_new, ball_ok, t, dt, time, pair):
    """The first contacts of a step (:meth:`tolsim.study.pipeline.propagation.FirstContact
    .observe`), in place.

    ``gap_old``, ``gap_new`` (m, balls - 1) [m] at the start and end of the step (t, dt [s]);
    ``ball_ok`` (m, balls). For each row without a contact yet (``time`` inf), the pairs that
    close (gap_new <= 0 < gap_old - gap_new, both balls ok) at
    t + dt gap_old / (gap_old - gap_new) (t at a gap already closed); the earliest, the first
    pair on ties, into ``time`` and ``pair``. A NaN time makes the row's step find nothing
    (as ``np.argmin``, which returns it).
    """
    for r in range(gap_old.shape[0]):
        if np.isfinite(time[r]):
            continue
        best = np.inf
        first = 0
        for j in range(gap_old.shape[1]):
            old = gap_old[r, j]
            new = gap_new[r, j]
            if not (new <= 0.0 and old > new and ball_ok[r, j] and ball_ok[r, j + 1]):
                continue
            tc = t + (0.0 if old <= 0.0 else old / (old - new)) * dt
            if tc != tc:
                best = np.nan
                break
            if tc < best:
                best = tc
                first = j
        if np.isfinite(best):
            time[r] = best
            pair[r] = first
