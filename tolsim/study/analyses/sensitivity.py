"""What drives the risk: variance-based (Sobol') sensitivity indices with confidence intervals.

For an output Y = f(X_1, ..., X_d) of independent factors (a factor may be a *group* of
inputs, e.g. the per-ball values of one tolerance source in an assembly), the first-order
index S_i = Var(E[Y | X_i]) / Var(Y) is the share of the variance of Y that X_i explains on
its own, and the total-effect index S_Ti = E[Var(Y | X_~i)] / Var(Y) its share including all
interactions ([Saltelli2010]). For an additive model S_i = S_Ti; sum_i S_i <= 1 always.

Estimator (the pick-and-freeze design of [Saltelli2010], Table 2, with the estimators that
:func:`scipy.stats.sobol_indices` uses by default): two independent base samples A and B of n
rows, and for each factor i the matrix AB_i = A with the columns of factor i taken from B;
n (d + 2) evaluations of f. With f centred on its mean,

    V_i  = mean(f(B) (f(AB_i) - f(A)))            (Saltelli 2010, first order)
    V_Ti = mean((f(A) - f(AB_i))^2) / 2           (Jansen 1999, total effect)
    S_i = V_i / V,  S_Ti = V_Ti / V,  V = variance of f over A and B.

This is scipy's method, written here in NumPy because tolsim needs three things scipy's
function does not give: factor *groups* (a per-ball source is one factor of an assembly),
several outputs of different shape (epsilon per ball, the contact indicator per assembly),
and pooled outputs: an output of shape (n, m) is treated as m exchangeable replicates (e.g.
the m balls of a train) whose numerators and variances are pooled, i.e. the indices are the
variance-weighted average over the m columns of the per-column indices. Evaluations that are
not finite (invalid balls) are left out of every sum, and counted. ``tests/test_sensitivity``
compares with :func:`scipy.stats.sobol_indices` on a case both can do.

Confidence intervals: a nonparametric bootstrap over the n rows of (A, B, AB_i) (percentile
interval, ``n_resamples`` replicates, vectorised as a multinomial weight matrix), the same kind
of interval as ``scipy.stats.sobol_indices(...).bootstrap()``.

Indices that cannot be estimated: an output without variance (up to rounding, relative
:data:`ZERO_VARIANCE`) has none. A nearly constant output (the contact indicator when contact
is nearly certain or nearly impossible) has a variance, but only from the few rows where it
differs from its most common value; a bootstrap resample that misses those rows has no variance
and its indices are undefined (0/0 or x/0). When more resamples than the interval's tail share
((1 - confidence_level) / 2) are undefined, the percentile interval has no defined end and the
point estimate is the noise of a handful of rows (a total index of 1.67 over 3 varying rows in
2 048 on rare_contact.toml with gaps U(0, 1 um)): the indices are NaN, with the reason in
``reasons``. With fewer undefined resamples they are left out of the percentiles. (A resample
misses k given rows of n with probability (1 - k/n)^n ~ e^-k, so at 95 % about 3 or fewer
varying rows make an output not estimable.) An output with a defined variance in every
resample, the usual case, is not affected.

Cost: n (d + 2) evaluations. With tolsim's pipeline at millions of balls per second, n = 4096
assemblies of 10 balls and d = 8 factors is 0.4 M balls: a second or two, so the cheaper
one-at-a-time or regression estimators are not needed; their answers are also wrong for the
contact indicator, which is strongly non-linear in the factors.

References
----------
.. [Saltelli2010] A. Saltelli, P. Annoni, I. Azzini, F. Campolongo, M. Ratto, S. Tarantola,
   "Variance based sensitivity analysis of model output. Design and estimator for the total
   sensitivity index", Comput. Phys. Commun. 181 (2010) 259-270.
.. [Jansen1999] M. J. W. Jansen, "Analysis of variance designs for model output", Comput.
   Phys. Commun. 117 (1999) 35-43.
"""

from dataclasses import dataclass, replace

import numpy as np
from scipy.special import ndtri

from tolsim.study.pipeline.block import evaluate_block, has_contact
from tolsim.study.sampling import sample_block

#: Output name of the velocity deviation in :func:`study_sensitivity`.
VELOCITY_DEVIATION = "velocity_deviation"
#: Output name of the per-assembly contact indicator in :func:`study_sensitivity`.
CONTACT = "contact"
#: Output name of the per-assembly friction increase (a study with ``[contact]``).
FRICTION_INCREASE = "friction_increase"
#: Factor name of the initial gaps between balls in :func:`study_sensitivity`.
INITIAL_GAP = "initial_gap"
#: A variance at most this share of the mean square of the centred values is zero: what is
#: left of an output that does not vary after rounding (module docstring) [-].
ZERO_VARIANCE = 1e-12


@dataclass(frozen=True)
class SensitivityResult:
    """Sobol' indices of k outputs with respect to d factors.

    Attributes
    ----------
    factors : tuple of str, length d
    outputs : tuple of str, length k
    first_order, total : ndarray, shape (k, d)
        S_i and S_Ti [-] (NaN for an output whose indices are not estimable: ``reasons``).
    first_order_ci, total_ci : ndarray, shape (k, d, 2)
        Lower and upper ends of the bootstrap percentile interval [-].
    variance : ndarray, shape (k,)
        Var(Y) pooled over the replicate columns [output units squared].
    mean : ndarray, shape (k,)
        Mean of Y over A and B [output units].
    used : ndarray of int, shape (k,)
        Finite evaluations used per output (rows x replicate columns).
    excluded : ndarray of int, shape (k,)
        Row-column pairs left out because some evaluation was not finite.
    n : int
        Rows of each base sample.
    evaluations : int
        Rows evaluated, n (d + 2).
    confidence_level : float
    n_resamples : int
    method : str
    reasons : tuple of str, length k
        Why an output's indices are not estimable (module docstring), '' when they are.
    """

    factors: tuple
    outputs: tuple
    first_order: np.ndarray
    total: np.ndarray
    first_order_ci: np.ndarray
    total_ci: np.ndarray
    variance: np.ndarray
    mean: np.ndarray
    used: np.ndarray
    excluded: np.ndarray
    n: int
    evaluations: int
    confidence_level: float
    n_resamples: int
    method: str = "Saltelli 2010 first order, Jansen 1999 total, bootstrap percentile CI"
    reasons: tuple = ()

    def output_index(self, output) -> int:
        """Position of ``output`` (a name or an int) in :attr:`outputs`."""
        if isinstance(output, (int, np.integer)):
            return int(output)
        try:
            return self.outputs.index(output)
        except ValueError:
            raise ValueError(f"unknown output {output!r}; have {self.outputs}") from None

    def ranking(self, output=0):
        """Factors sorted by decreasing total-effect index for one output.

        Returns
        -------
        list of (factor, first_order, total, total_ci_lower, total_ci_upper)
        """
        k = self.output_index(output)
        order = np.argsort(-np.nan_to_num(self.total[k], nan=-np.inf), kind="stable")
        return [(self.factors[i], float(self.first_order[k, i]), float(self.total[k, i]),
                 float(self.total_ci[k, i, 0]), float(self.total_ci[k, i, 1])) for i in order]


# --------------------------------------------------------------------------------------------
# Sampling the base matrices
# --------------------------------------------------------------------------------------------
def _marginal_sampler(dists):
    """Sampler of independent columns from objects with ``ppf`` or ``from_normal``."""
    dists = list(dists)
    for j, d in enumerate(dists):
        if not (hasattr(d, "ppf") or hasattr(d, "from_normal")):
            raise ValueError(f"dists[{j}] = {d!r} has neither ppf nor from_normal")

    def sample(rng, n):
        u = rng.random((n, len(dists)))
        u = np.clip(u, 0.5 / 2**53, 1.0 - 0.5 / 2**53)
        cols = [d.ppf(u[:, j]) if hasattr(d, "ppf") else d.from_normal(ndtri(u[:, j]))
                for j, d in enumerate(dists)]
        return np.stack([np.asarray(c, dtype=float) for c in cols], axis=1)

    return sample


def _as_outputs(values, n):
    """func's return value -> dict name -> float array (n, m)."""
    if not isinstance(values, dict):
        values = {"output": values}
    out = {}
    for name, v in values.items():
        v = np.asarray(v, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if v.ndim != 2 or v.shape[0] != n:
            raise ValueError(f"output {name!r} has shape {v.shape}; expected ({n},) or "
                             f"({n}, m)")
        out[str(name)] = v
    return out


# --------------------------------------------------------------------------------------------
# Estimators
# --------------------------------------------------------------------------------------------
def indices_from_evaluations(f_a, f_b, f_ab, rng, *, confidence_level=0.95,
                             n_resamples=1000):
    """Sobol' indices of one (pooled) output from the pick-and-freeze evaluations.

    Parameters
    ----------
    f_a, f_b : array_like, shape (n,) or (n, m)
        f(A), f(B); m replicate columns are pooled.
    f_ab : array_like, shape (d, n) or (d, n, m)
        f(AB_i) for each factor i.
    rng : numpy.random.Generator
        For the bootstrap.
    confidence_level : float
        Of the percentile interval, in (0, 1).
    n_resamples : int
        Bootstrap replicates (0: no interval, NaN ends).

    Returns
    -------
    dict
        ``first_order``, ``total`` (d,), ``first_order_ci``, ``total_ci`` (d, 2),
        ``variance``, ``mean``, ``used``, ``excluded``, and ``reason``: why the indices are
        not estimable (all NaN then; module docstring), '' when they are.
    """
    f_a = np.asarray(f_a, dtype=float)
    f_b = np.asarray(f_b, dtype=float)
    f_ab = np.asarray(f_ab, dtype=float)
    if f_a.ndim == 1:
        f_a, f_b, f_ab = f_a[:, None], f_b[:, None], f_ab[..., None]
    n, m = f_a.shape
    d = f_ab.shape[0]
    if f_b.shape != (n, m) or f_ab.shape != (d, n, m):
        raise ValueError(f"f_a {f_a.shape}, f_b {f_b.shape} and f_ab {f_ab.shape} do not match")
    if not 0.0 < confidence_level < 1.0:
        raise ValueError(f"confidence_level = {confidence_level!r} must be in (0, 1)")
    if not (isinstance(n_resamples, (int, np.integer)) and n_resamples >= 0):
        raise ValueError(f"n_resamples = {n_resamples!r} must be a non-negative integer")

    mask = np.isfinite(f_a) & np.isfinite(f_b) & np.all(np.isfinite(f_ab), axis=0)
    w = mask.astype(float)
    count_col = w.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.where(count_col > 0,
                      np.where(mask, f_a + f_b, 0.0).sum(axis=0) / (2 * count_col), 0.0)
    a = np.where(mask, f_a - mu, 0.0)
    b = np.where(mask, f_b - mu, 0.0)
    ab = np.where(mask, f_ab - mu, 0.0)

    # Per-row sums (over the pooled columns) that every estimate is a ratio of.
    row_first = np.einsum("nm,dnm->nd", b, ab - a)            # sum_j f_B (f_ABi - f_A)
    row_total = 0.5 * np.einsum("dnm->nd", (a - ab) ** 2)     # sum_j (f_A - f_ABi)^2 / 2
    col_sum = 0.5 * (a + b)                                   # (n, m)
    col_sq = 0.5 * (a * a + b * b)

    def estimate(weights):
        # weights: (r, n) row multiplicities -> indices (r, d) each
        cnt = weights @ w                                      # (r, m)
        s1 = weights @ col_sum
        s2 = weights @ col_sq
        total_cnt = cnt.sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            var = (s2 - np.where(cnt > 0, s1 * s1 / cnt, 0.0)).sum(axis=1) / total_cnt
            first = (weights @ row_first) / total_cnt[:, None] / var[:, None]
            total = (weights @ row_total) / total_cnt[:, None] / var[:, None]
            # no variance, up to rounding: the indices are undefined (module docstring)
            defined = var > ZERO_VARIANCE * s2.sum(axis=1) / total_cnt
        return first, total, var, defined

    first, total, var, defined = estimate(np.ones((1, n)))
    first, total, var = first[0], total[0], float(var[0])
    nan2 = np.full((d, 2), np.nan)
    first_ci, total_ci = nan2.copy(), nan2.copy()
    used = int(mask.sum())
    reason = ("" if defined[0] else "the output does not vary: indices not estimable" if used
              else "no finite evaluation: indices not estimable")
    if not reason and n_resamples > 0:
        alpha = 1.0 - confidence_level
        f_boot, t_boot, ok = [], [], []
        chunk = max(1, int(2**22 // max(n, 1)))
        for start in range(0, n_resamples, chunk):
            r = min(chunk, n_resamples - start)
            weights = rng.multinomial(n, np.full(n, 1.0 / n), size=r).astype(float)
            fb, tb, _, db = estimate(weights)
            f_boot.append(fb)
            t_boot.append(tb)
            ok.append(db)
        ok = np.concatenate(ok)
        undefined = int(n_resamples - ok.sum())
        if undefined > alpha / 2 * n_resamples:  # an end of the interval is undefined
            reason = (f"the output varies in only {_varying(f_a, f_b, mask):,} of "
                      f"{2 * used:,} {'rows' if m == 1 else 'values'}: indices not estimable "
                      f"({undefined:,} of {n_resamples:,} bootstrap resamples have no "
                      "variance)")
        else:  # the few undefined resamples are left out of the percentiles
            f_boot = np.concatenate(f_boot)[ok]
            t_boot = np.concatenate(t_boot)[ok]
            levels = [100 * alpha / 2, 100 * (1 - alpha / 2)]
            with np.errstate(invalid="ignore"):
                first_ci = np.nanpercentile(f_boot, levels, axis=0).T
                total_ci = np.nanpercentile(t_boot, levels, axis=0).T
    if reason:
        first = np.full(d, np.nan)
        total = np.full(d, np.nan)
    mean = float(np.where(mask, f_a + f_b, 0.0).sum() / (2 * used)) if used else np.nan
    return {"first_order": first, "total": total, "first_order_ci": first_ci,
            "total_ci": total_ci, "variance": var if used else np.nan, "mean": mean,
            "used": used, "excluded": int(mask.size - used), "reason": reason}


def _varying(f_a, f_b, mask) -> int:
    """Rows of A and B (pooled columns: row-column values) where the output differs from
    its most common value in the column, for the reason of an output that is not
    estimable."""
    count = 0
    for j in range(f_a.shape[1]):
        values = np.concatenate([f_a[mask[:, j], j], f_b[mask[:, j], j]])
        if values.size:
            _, counts = np.unique(values, return_counts=True)
            count += int(values.size - counts.max())
    return count


def _assemble(factors, per_output, n, confidence_level, n_resamples):
    outputs = tuple(per_output)
    stack = lambda key: np.array([per_output[o][key] for o in outputs])  # noqa: E731
    return SensitivityResult(
        factors=tuple(factors), outputs=outputs,
        first_order=stack("first_order"), total=stack("total"),
        first_order_ci=stack("first_order_ci"), total_ci=stack("total_ci"),
        variance=stack("variance"), mean=stack("mean"),
        used=stack("used").astype(np.int64), excluded=stack("excluded").astype(np.int64),
        n=int(n), evaluations=int(n * (len(factors) + 2)),
        confidence_level=float(confidence_level), n_resamples=int(n_resamples),
        reasons=tuple(per_output[o]["reason"] for o in outputs))


def sobol_sensitivity(func, sampler, n, rng, *, factors=None, groups=None,
                      confidence_level=0.95, n_resamples=1000) -> SensitivityResult:
    """Variance-based sensitivity indices of ``func`` with bootstrap confidence intervals.

    Parameters
    ----------
    func : callable
        ``func(x) -> y`` with ``x`` of shape (rows, D), the factor values in their own units;
        ``y`` an array of shape (rows,) or (rows, m) (m replicates, pooled), or a dict
        name -> such arrays for several outputs. Non-finite values are left out.
        Called once, on the n (d + 2) stacked rows of A, B and every AB_i.
    sampler : sequence or callable
        Either D independent marginals, each with a ``ppf`` method (frozen
        :mod:`scipy.stats` distributions) or a ``from_normal`` method
        (:class:`tolsim.study.spec.Distribution`); or ``sampler(rng, n) -> ndarray (n, D)``
        drawing n independent rows (columns of one group may depend on each other, groups
        must be independent).
    n : int
        Rows of each base sample (>= 2). The cost is n (d + 2) evaluations.
    rng : numpy.random.Generator
        Source of every random number (base samples, then the bootstrap).
    factors : sequence of str, optional
        Names of the d factors (default ``x0, x1, ...``).
    groups : sequence of sequences of int, optional
        The columns of each factor (default: one column per factor).
    confidence_level : float
        Of the bootstrap percentile intervals.
    n_resamples : int
        Bootstrap replicates.

    Returns
    -------
    SensitivityResult
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng = {rng!r} must be a numpy.random.Generator")
    if not (isinstance(n, (int, np.integer)) and n >= 2):
        raise ValueError(f"n = {n!r} must be an integer >= 2")
    sample = sampler if callable(sampler) else _marginal_sampler(sampler)
    a = np.asarray(sample(rng, n), dtype=float)
    b = np.asarray(sample(rng, n), dtype=float)
    if a.ndim != 2 or a.shape[0] != n or b.shape != a.shape:
        raise ValueError(f"sampler returned shape {a.shape}; expected ({n}, D)")
    width = a.shape[1]
    if groups is None:
        groups = [[j] for j in range(width)]
    groups = [np.atleast_1d(np.asarray(g, dtype=int)) for g in groups]
    used_cols = np.concatenate(groups) if groups else np.empty(0, int)
    if (len(used_cols) != len(set(used_cols.tolist())) or np.any(used_cols < 0)
            or np.any(used_cols >= width)):
        raise ValueError(f"groups = {groups!r} must be disjoint column sets of 0..{width - 1}")
    d = len(groups)
    if factors is None:
        factors = [f"x{i}" for i in range(d)]
    factors = [str(f) for f in factors]
    if len(factors) != d:
        raise ValueError(f"factors has {len(factors)} names for {d} factors")
    stacked = [a, b]
    for cols in groups:
        ab = a.copy()
        ab[:, cols] = b[:, cols]
        stacked.append(ab)
    y = _as_outputs(func(np.concatenate(stacked)), n * (d + 2))
    per_output = {}
    for name, v in y.items():
        parts = v.reshape(d + 2, n, v.shape[1])
        per_output[name] = indices_from_evaluations(
            parts[0], parts[1], parts[2:], rng, confidence_level=confidence_level,
            n_resamples=n_resamples)
    return _assemble(factors, per_output, n, confidence_level, n_resamples)


# --------------------------------------------------------------------------------------------
# A tolsim study
# --------------------------------------------------------------------------------------------
def study_factors(config) -> tuple:
    """The factors of a study: every random tolerance source, and the gaps if random.

    Each factor is a group: a ``ball`` source is one value per ball, a rail field its values
    along the rail, a ``carriage`` or ``rail`` source one value per assembly.
    """
    names = [t.source for t in config.tolerances if t.distribution.is_random]
    if config.train.balls > 1 and config.train.initial_gap.is_random:
        names.append(INITIAL_GAP)
    return tuple(names)


def _mix(block_a, block_b, factor):
    """Block A with factor ``factor`` taken from block B (the AB_i of the design)."""
    if factor == INITIAL_GAP:  # with the gaps of the balls entering a carriage, if any
        return replace(block_a, initial_gap=block_b.initial_gap,
                       initial_position=block_b.initial_position,
                       entering_gap=block_b.entering_gap)
    normals, fields = dict(block_a.normals), dict(block_a.fields)
    entering = dict(block_a.entering)
    if factor in fields:
        fields[factor] = block_b.fields[factor]
    else:
        normals[factor] = block_b.normals[factor]
    if factor in entering:  # a ball source: the entering balls' values go with it
        entering[factor] = block_b.entering[factor]
    return replace(block_a, normals=normals, fields=fields, entering=entering)


def _evaluate_block(config, block):
    """epsilon per ball (size, balls) (NaN unresolved) and contact indicator (size,) (NaN
    when the train has an unresolved ball and no certain contact); with ``[contact]`` also
    the friction increase (size,) [N] of the worst track (NaN when unresolved,
    :mod:`tolsim.study.pipeline.track_friction`)."""
    outcome = evaluate_block(config, block)
    # a reported contact is certain even in a train with an unresolved ball; no contact is
    # known only when every ball was resolved (NaN otherwise)
    hit = np.isfinite(outcome.time)
    contact = np.where(hit, 1.0, np.where(outcome.resolved, 0.0, np.nan))
    if outcome.friction is not None:  # after contact (issue 13): the friction increase
        return outcome.state.velocity_deviation, contact, outcome.friction.increase_max
    return outcome.state.velocity_deviation, contact


def study_sensitivity(config, samples: int = 2048, *, confidence_level=0.95,
                      n_resamples=1000) -> SensitivityResult:
    """Sobol' indices of epsilon and of the contact indicator for a tolsim study.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
        The study; its seed, sampling, models and propagation are used.
    samples : int
        Assemblies per base sample; the cost is samples (d + 2) assemblies for d factors.
    confidence_level, n_resamples
        Of the bootstrap intervals.

    Returns
    -------
    SensitivityResult
        Outputs ``velocity_deviation`` (epsilon of a ball at a fixed train position, pooled
        over the positions: the share of the within-position variance, so the deterministic
        load variation along the train is not counted as a tolerance effect) and ``contact``
        (1 if a pair of the train touches within the horizon); with ``[contact]`` also
        ``friction_increase`` (the worst track's friction increase per assembly [N],
        :mod:`tolsim.study.pipeline.track_friction`; unresolved assemblies left out). Factors as
        :func:`study_factors`; no factors gives an empty result (d = 0). With
        ``along_track`` propagation epsilon is taken at the start of the stroke (the balls'
        initial rail positions) while the contact indicator follows the whole stroke.

    Notes
    -----
    Randomness: A and B are blocks 0 and 1 (of ``samples`` assemblies) of the stream
    ``SeedSequence(seed, spawn_key=(2,))``, the bootstrap uses ``spawn_key=(3,)``, so the
    indices are reproducible and independent of the study's own draws.
    """
    if not (isinstance(samples, (int, np.integer)) and samples >= 2):
        raise ValueError(f"samples = {samples!r} must be an integer >= 2")
    seed = int(np.random.SeedSequence(config.study.seed, spawn_key=(2,)).generate_state(1)[0])
    sub = replace(config, study=replace(config.study, samples=2 * int(samples),
                                        block_size=int(samples), seed=seed))
    factors = study_factors(config)
    block_a, block_b = sample_block(sub, 0), sample_block(sub, 1)
    blocks = [block_a, block_b] + [_mix(block_a, block_b, f) for f in factors]
    evaluated = [_evaluate_block(sub, blk) for blk in blocks]
    boot = np.random.Generator(np.random.PCG64(
        np.random.SeedSequence(config.study.seed, spawn_key=(3,))))
    per_output = {}
    names = (VELOCITY_DEVIATION, CONTACT) + ((FRICTION_INCREASE,) if has_contact(config) else ())
    for k, name in enumerate(names):
        ys = [e[k] for e in evaluated]
        per_output[name] = indices_from_evaluations(
            ys[0], ys[1], np.stack(ys[2:]) if factors else np.empty((0,) + ys[0].shape), boot,
            confidence_level=confidence_level, n_resamples=n_resamples)
    return _assemble(factors, per_output, samples, confidence_level, n_resamples)
