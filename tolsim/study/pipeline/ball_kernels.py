"""Compiled glue of the ball evaluations (:mod:`tolsim.study.pipeline.evaluate`,
:mod:`tolsim.study.pipeline.carriage_track`): contact counts, outcomes, loaded-ball gathers.

Each kernel does in one pass, element by element, what a chain of NumPy calls did: the same
comparisons and the same values, so the results are bit-identical to those calls.
"""

import numpy as np

from tolsim._jit import jit


@jit
def contact_counts_kernel(force, limit, out_count, out_clipped):
    """Loaded contacts of n balls with round-off contacts settled, and the forces clipped at 0.

    ``force`` (n, 4) [N]. ``out_count`` (n,) int8: the loaded contacts (F > 0), -1 for a ball
    with a contact in tension (F < 0), 0 for a loaded ball whose forces are all at or below
    ``limit`` [N] (it carries round-off only); ``out_clipped`` (n, 4): max(F, 0) as
    ``np.maximum`` (NaN stays NaN), 0 at a settled ball. Returns the number of settled balls.
    (:func:`tolsim.study.pipeline.evaluate.loaded_contacts` then
    :func:`tolsim.study.pipeline.evaluate.settle_round_off_contacts`.)
    """
    settled = 0
    for b in range(force.shape[0]):
        count = 0
        tension = False
        small = True
        for i in range(4):
            f = force[b, i]
            count += f > 0.0
            tension |= f < 0.0
            small &= f <= limit
        if tension:
            count = -1
        if count > 0 and small:
            settled += 1
            out_count[b] = 0
            for i in range(4):
                out_clipped[b, i] = 0.0
            continue
        out_count[b] = count
        for i in range(4):
            f = force[b, i]
            out_clipped[b, i] = f if (f > 0.0 or f != f) else 0.0  # as np.maximum(f, 0.0)
    return settled


@jit
def ball_outcomes_kernel(eps, valid, converged, four_point, count, fast, model_fast,
                         model_unresolved, regime_a, regime_unresolved, regime_unloaded,
                         out_model, out_regime, out_lost, out_redo):
    """The outcome of n balls after the fast velocity model, before the full-model re-solves.

    In place: ``valid`` &= converged & four_point & finite epsilon (if ``fast``), ``eps`` NaN
    where not valid. Writes ``out_model``, ``out_regime`` (unloaded: converged with no loaded
    contact), ``out_lost`` (converged with one loaded contact or one in tension) and the
    indices of the balls to re-solve with the full model (converged, not valid, two or more
    loaded contacts) into ``out_redo``; returns their number. As
    :func:`tolsim.study.pipeline.evaluate.ball_velocities` did with NumPy.
    """
    redo = 0
    for b in range(eps.shape[0]):
        ok = valid[b]
        if fast:
            ok = ok and converged[b] and four_point[b] and np.isfinite(eps[b])
            valid[b] = ok
        c = count[b]
        out_model[b] = model_fast if ok else model_unresolved
        out_regime[b] = regime_a if ok else regime_unresolved
        if converged[b] and c == 0:
            out_regime[b] = regime_unloaded
        if converged[b] and not ok and c >= 2:
            out_redo[redo] = b
            redo += 1
        out_lost[b] = converged[b] and (c == 1 or c < 0)
        if not ok:
            eps[b] = np.nan
    return redo


@jit
def gather_loaded_kernel(loaded, dbeta, force, ball_converged, solved, out_dbeta, out_force,
                         out_converged, out_four_point):
    """The loaded balls of slot arrays, in C order (as ``x[loaded]``).

    ``loaded`` (m, T, S); ``dbeta``, ``force`` (m, T, S, 4); ``ball_converged`` (m, T, S);
    ``solved`` (m,). Writes per loaded ball: dbeta, the force with non-finite values set to 0,
    converged (the ball's and its assembly's) and four-point (every force > 0).
    """
    m, tracks, slots = loaded.shape
    k = 0
    for a in range(m):
        for t in range(tracks):
            for j in range(slots):
                if not loaded[a, t, j]:
                    continue
                four = True
                for i in range(4):
                    out_dbeta[k, i] = dbeta[a, t, j, i]
                    f = force[a, t, j, i]
                    f = f if np.isfinite(f) else 0.0
                    out_force[k, i] = f
                    four &= f > 0.0
                out_converged[k] = ball_converged[a, t, j] and solved[a]
                out_four_point[k] = four
                k += 1


@jit
def scatter_loaded_kernel(loaded, values, fill, out):
    """``out`` (m, T, S) = ``fill`` with ``values`` at the loaded slots, in C order (as
    ``out[loaded] = values``)."""
    m, tracks, slots = loaded.shape
    k = 0
    for a in range(m):
        for t in range(tracks):
            for j in range(slots):
                if loaded[a, t, j]:
                    out[a, t, j] = values[k]
                    k += 1
                else:
                    out[a, t, j] = fill


@jit
def _nan_to_num_kernel(values, out):
    big = np.finfo(np.float64).max
    for i in range(values.size):
        v = values[i]
        if np.isnan(v):
            v = 0.0
        elif v == np.inf:
            v = big
        elif v == -np.inf:
            v = -big
        out[i] = v


def nan_to_num(x):
    """``np.nan_to_num(x)`` (NaN -> 0, +-inf -> +-the largest double) of a float64 array, in
    one compiled pass where it is C-contiguous."""
    if not (isinstance(x, np.ndarray) and x.dtype == np.float64 and x.flags.c_contiguous):
        return np.nan_to_num(x)
    out = np.empty_like(x)
    _nan_to_num_kernel(x.reshape(-1), out.reshape(-1))
    return out
