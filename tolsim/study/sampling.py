"""Reproducible sampling of assemblies in fixed-size blocks.

All randomness comes from one :class:`numpy.random.SeedSequence` with the study's ``seed``:
block k of ``block_size`` assemblies draws from ``SeedSequence(seed, spawn_key=(0, k))`` (the
k-th child of the "assemblies" stream), the spot-check selection from
``SeedSequence(seed, spawn_key=(1,))`` (its near-limit stratum from the hash key of
``spawn_key=(1, 1)``, :class:`SpotCheckPlan`). A block is always drawn whole, in a fixed
order, and then cut to the assemblies it holds, so the draws of an assembly depend only on
(seed, block_size, its index): not on the number of samples, the chunking or the number of
workers.

Within a block the draws are, in this order:

1. the per-assembly factors (``carriage`` sources and ``rail`` sources without a correlation
   length), one standard normal each, from the generator or, with ``sampling = "sobol"`` or
   ``"lhs"``, from a scrambled :mod:`scipy.stats.qmc` design seeded by the block's generator
   (``z = Phi^-1(u)``);
2. the ``ball`` sources, independent standard normals of shape (assemblies, balls);
3. the rail random fields (``rail`` sources with a correlation length): a stationary
   Ornstein-Uhlenbeck process (standard normal, correlation exp(-|ds|/l)), drawn exactly by
   its AR(1) recursion. With ``constant`` propagation it is drawn at the ball centres
   themselves (exact). With ``along_track`` propagation it is drawn on a grid along the rail
   with spacing <= l/16 and interpolated linearly; between grid points this lowers the
   variance by at most (1 - exp(-1/16))/2 = 3 % (1.5 % in standard deviation), at the grid
   points it is exact;
4. the initial gaps, shape (assemblies, balls - 1);
5. only with a ``[carriage]`` and ``along_track`` propagation, the balls that enter the
   carriage's loaded zone during the stroke (:mod:`tolsim.study.pipeline.carriage_track`), E =
   :func:`entering_capacity` per track: their gaps to the ball ahead (from the gap
   distribution), shape (assemblies, tracks * E), then each ``ball`` source in config order,
   the same shape. Drawn after everything else, so the draws 1-4 are those of any other
   study.

With a ``[carriage]`` of T tracks an assembly holds T trains: the per-assembly sources are
drawn once per track (rail and carriage grooves are ground per track), and every draw has T
times the columns, track by track (:func:`draw_widths`); with T = 1 the draws are those of a
single train.

Every distribution maps the standard normal z to its value
(:meth:`tolsim.study.spec.Distribution.from_normal`), so QMC, fields and plain draws share
the transformation; an ``empirical`` distribution (measured values) maps z through u = Phi(z)
and its interpolated empirical quantile function.

Correlated sources (:class:`tolsim.study.spec.Correlation`, a Gaussian copula): the block
holds independent standard normals xi; :func:`error_values` turns those of a correlated group
into z = L xi, L the lower Cholesky factor of the group's correlation matrix, element by
element (no BLAS: the sums run in a fixed order, so the values are bit-identical however the
blocks are chunked). The group shares a scope, so the xi of its sources have one shape; rail
fields of one correlation length share their grid and AR(1) coefficients, and the linear map
commutes with the recursion and the interpolation: the fields are then cross-correlated as
rho_ij exp(-|ds| / l). The sensitivity analysis swaps the independent xi, so the index of a
later source of a group is that of its part independent of the earlier ones (Cholesky
order).
"""

import warnings
from dataclasses import dataclass, field

import numpy as np
from numba import prange
from scipy.special import ndtri
from scipy.stats import qmc

from tolsim._jit import jit, kernel_array, pjit

#: Grid points per correlation length of a rail random field.
FIELD_POINTS_PER_CORRELATION_LENGTH = 16
#: Upper bound on the grid points of one rail field (the spacing grows beyond it).
MAX_FIELD_POINTS = 4096


def block_seed_sequence(seed: int, block: int) -> np.random.SeedSequence:
    """SeedSequence of block ``block``: child ``block`` of the assemblies stream (0)."""
    return np.random.SeedSequence(seed, spawn_key=(0, block))


def block_generator(seed: int, block: int) -> np.random.Generator:
    """The generator of block ``block`` (PCG64)."""
    return np.random.Generator(np.random.PCG64(block_seed_sequence(seed, block)))


def spot_check_generator(seed: int) -> np.random.Generator:
    """The generator that picks the spot-check balls (stream 1)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(1,))))


def n_blocks(samples: int, block_size: int) -> int:
    """Number of blocks holding ``samples`` assemblies."""
    return -(-samples // block_size)


@dataclass
class RailField:
    """A rail random field for a block: standard normal values on a grid [rail position, m].

    ``values`` has shape (assemblies * tracks, points), row a * tracks + t for track t of
    assembly a (a carriage's tracks have a field each); position s_k = origin + k * spacing.
    """

    origin: float
    spacing: float
    values: np.ndarray
    tracks: int = 1

    def at(self, position, parallel=False):
        """Field value at rail positions [-]: the grid's standard normal values, read linearly
        between its points.

        ``position``: shape (assemblies, ...) [m]; with several tracks the positions of each
        assembly track by track, (assemblies, tracks * k) or (assemblies, tracks, k).
        ``parallel``: read the rows on Numba's threads (the same values; not from a thread
        that draws while a parallel kernel may run, :func:`tolsim.study.execution.chunks
        .prefetched`).

        Notes
        -----
        Between two points a fraction w of the spacing h apart the read has variance
        (1 - w)^2 + w^2 + 2 w (1 - w) rho, rho = exp(-h / l), not 1: (1 + rho) / 2 at a cell's
        middle, 0.970 at the 16 points per correlation length l of :func:`field_grid` (the
        load-time warning of a coarser grid names this loss). Dividing the read by its standard
        deviation would make every value standard normal, but a ball's epsilon is integrated
        along its path, and the mean over a cell of that rescaled read has variance 0.990 at
        h = l / 16 (0.875 at h = l), against 0.979 (0.736) for the Ornstein-Uhlenbeck process
        itself, 2 (x - 1 + e^-x) / x^2 with x = h / l; the linear read gives (1 + rho) / 2,
        0.970 (0.684). Either is off by about 1 % at 16 points per correlation length, in
        opposite directions, and the rescaled read errs more on a coarse grid; so the read stays
        linear (session 28; the rescaling was tried and measured: about 1 % in the rail part of
        epsilon's spread along the track).
        """
        if self.tracks > 1:
            pos = np.asarray(position)
            rows = RailField(self.origin, self.spacing, self.values)
            return rows.at(pos.reshape(self.values.shape[0], -1), parallel).reshape(pos.shape)
        pos = np.asarray(position, dtype=np.float64)
        out = np.empty(pos.shape)
        values = np.ascontiguousarray(self.values, dtype=np.float64)
        kernel = _field_at_parallel if parallel else _field_at_kernel
        kernel(values, np.arange(values.shape[0]), float(self.origin), float(self.spacing),
               np.ascontiguousarray(pos).reshape(values.shape[0], -1),
               out.reshape(values.shape[0], -1))
        return out


@jit(inline="always")
def _field_row(values, index, origin, spacing, position, out, r):
    """Row r of :func:`_field_at_kernel`."""
    last = values.shape[1] - 2
    v = values[index[r]]
    for j in range(position.shape[1]):
        x = (position[r, j] - origin) / spacing
        if not np.isfinite(x):
            out[r, j] = np.nan
            continue
        k = 0 if x < 0.0 else (last if x > last else min(int(np.floor(x)), last))
        w = min(max(x - k, 0.0), 1.0)
        out[r, j] = (1.0 - w) * v[k] + w * v[k + 1]


@jit
def _field_at_kernel(values, index, origin, spacing, position, out):
    """Kernel of :meth:`RailField.at`: row r of ``position`` (rows, k) read on row
    ``index[r]`` of the grid ``values``, linear between its points, the end values beyond them
    (NaN at a NaN position)."""
    for r in range(position.shape[0]):
        _field_row(values, index, origin, spacing, position, out, r)


@pjit
def _field_at_parallel(values, index, origin, spacing, position, out):
    """:func:`_field_at_kernel` with its rows on Numba's threads."""
    for r in prange(position.shape[0]):
        _field_row(values, index, origin, spacing, position, out, r)


@dataclass
class Block:
    """The draws of one block (already cut to its ``size`` assemblies).

    Attributes
    ----------
    index, start, size : int
        Block number, index of its first assembly, number of assemblies.
    normals : dict
        source -> independent standard normal variates (correlated groups are combined by
        :func:`error_values`): shape (size, 1) for per-assembly sources,
        (size, balls) for ``ball`` sources and for rail fields at the ball centres
        (``constant`` propagation).
    fields : dict
        source -> :class:`RailField` for rail sources with a correlation length
        (``along_track`` propagation).
    initial_gap : ndarray, shape (size, tracks * (balls - 1))
        Gaps between adjacent balls at t = 0 [m], track by track.
    initial_position : ndarray, shape (size, tracks * balls)
        Ball centres along the rail at t = 0 [m], each train's centroid at 0, ball 0
        trailing, track by track.
    entering_gap : ndarray, shape (size, tracks * E)
        Carriage with ``along_track`` propagation only (else None): the gap [m] of each ball
        that enters the loaded zone during the stroke to the ball ahead of it, in order of
        entry, track by track (E = :func:`entering_capacity`).
    entering : dict
        Likewise: ``ball`` source -> standard normals of the entering balls, (size,
        tracks * E).

    ``tracks`` is 1 without a carriage (:attr:`tolsim.study.spec.StudyConfig.n_tracks`).
    """

    index: int
    start: int
    size: int
    normals: dict
    fields: dict
    initial_gap: np.ndarray
    initial_position: np.ndarray
    entering_gap: np.ndarray | None = None
    entering: dict = field(default_factory=dict)


def per_assembly_sources(config):
    """Tolerances drawn once per assembly (the QMC factors), in config order."""
    return [t for t in config.tolerances
            if t.scope != "ball" and not (t.scope == "rail" and t.correlation_length > 0)]


def _unit_design(kind, rng, n, d):
    """Per-assembly uniform design of shape (n, d) in (0, 1)."""
    if kind == "sobol":
        engine = qmc.Sobol(d, scramble=True, rng=rng)
        with warnings.catch_warnings():  # n need not be a power of two
            warnings.simplefilter("ignore", UserWarning)
            u = engine.random(n)
    elif kind == "lhs":
        u = qmc.LatinHypercube(d, rng=rng).random(n)
    else:
        raise ValueError(f"sampling {kind!r} has no design")
    # keep Phi^-1 finite
    return np.clip(u, 0.5 / 2**53, 1.0 - 0.5 / 2**53)


def nominal_span(config):
    """Half-length [m] covered by the train at t = 0 (fixed, so the field grid is too)."""
    pitch = 2.0 * config.bearing.ball_radius + max(config.train.initial_gap.expected, 0.0)
    return 0.5 * max(config.train.loaded_zone_length, config.train.balls * pitch)


def field_extent(config, initial_span):
    """Rail interval [m] the balls can visit: the train at t = 0 plus the ball travel.

    With a carriage (``along_track``) the balls stay in its loaded zone, which travels the
    whole stroke: a ball entering at the end of the stroke is at L/2 + stroke.
    """
    travel = 0.5 * config.motion.stroke * 1.05 if config.is_along_track else 0
    if travel and config.has_carriage:
        travel = config.motion.stroke
    pad = 2.0 * config.bearing.ball_radius
    return -initial_span - pad, initial_span + travel + pad


def field_grid(config):
    """(origin, spacing, points) of the rail-field grid (``along_track`` propagation)."""
    lo, hi = field_extent(config, nominal_span(config))
    grid = {}
    for t in config.tolerances:
        if t.scope == "rail" and t.correlation_length > 0:
            with np.errstate(over="ignore"):  # (a subnormal length: inf, capped below)
                wanted = np.float64(hi - lo) / t.correlation_length \
                    * FIELD_POINTS_PER_CORRELATION_LENGTH
            points = int(np.ceil(wanted)) + 2 if wanted < MAX_FIELD_POINTS else MAX_FIELD_POINTS
            points = min(max(points, 2), MAX_FIELD_POINTS)
            grid[t.source] = (lo, (hi - lo) / (points - 1), points)
    return grid


@jit
def _ar1_kernel(phi, scale, innovations, out):
    wide = phi.shape[0] > 1
    for r in range(out.shape[0]):
        rp = r if wide else 0
        out[r, 0] = innovations[r, 0]
        for j in range(1, out.shape[1]):
            out[r, j] = phi[rp, j - 1] * out[r, j - 1] + scale[rp, j - 1] * innovations[r, j]


def _ar1(phi, scale, innovations):
    """Rows of the stationary AR(1) recursion x_0 = z_0, x_j = phi_j x_(j-1) + scale_j z_j.

    ``phi``, ``scale``: shape (rows or 1, columns - 1). Compiled: a column-by-column NumPy
    loop streams the whole chunk through the cache once per column.
    """
    out = np.empty_like(innovations)
    _ar1_kernel(phi, scale, kernel_array(innovations), out)
    return out


def block_size_of(config, index: int) -> int:
    """Assemblies in block ``index`` (the last block of a study may be partial)."""
    st = config.study
    size = min(st.block_size, st.samples - index * st.block_size)
    if size <= 0:
        raise ValueError(f"block {index} is beyond samples = {st.samples}")
    return size


def draw_widths(config, grid):
    """Name -> columns of each standard normal draw of a block, in the documented order.

    With a carriage of T tracks every per-assembly source has T columns (one value per
    track, source by source), ball sources and gaps T times a train's, track by track, and
    a rail field one grid (or train) per track.
    """
    tracks, balls = config.n_tracks, config.train.balls
    widths = {"factors": tracks * len(per_assembly_sources(config))}
    widths.update({t.source: tracks * balls for t in config.tolerances if t.scope == "ball"})
    widths["gap"] = tracks * max(balls - 1, 0)
    for source, (_, _, points) in grid.items():
        widths[source] = tracks * (points if config.is_along_track else balls)
    if config.has_carriage and config.is_along_track:
        entering = tracks * entering_capacity(config)
        widths["entering_gap"] = entering
        widths.update({f"entering_{t.source}": entering for t in config.tolerances
                       if t.scope == "ball"})
    return widths


def entering_capacity(config) -> int:
    """Balls drawn per track to enter a carriage's loaded zone during the stroke.

    Relative to the carriage the balls move at (1 - epsilon) v / 2 (:mod:`tolsim.study.
    carriage_track`), so over the stroke s the balls of a track travel (1 - epsilon) s / 2
    and, spaced at least a diameter D apart, at most that over D enter; with |epsilon| <=
    5 %: floor(1.05 s / (2 D)) + 2. With a ``[carriage.circuit]`` of B balls the balls
    that enter are the circuit's own (issue 24): its B - n balls outside the zone at the start
    take these draws (sizes and tolerances) and their gaps, and the B - n + 1 gaps outside the
    zone share the rest of the slack in proportion to the draws
    (:class:`tolsim.study.pipeline.carriage_circuit.CircuitFrame`); at least that many.
    """
    diameter = 2.0 * config.bearing.ball_radius
    open_trains = int(np.floor(1.05 * config.motion.stroke / (2.0 * diameter))) + 2
    circuit = config.circuit
    if circuit is None:
        return open_trains
    return max(open_trains, circuit.balls - config.train.balls + 1)


def _draw(config, index, widths, out, row):
    """Draw block ``index`` into rows row.. of the arrays ``out`` (name -> array)."""
    st = config.study
    size_full = st.block_size
    size = block_size_of(config, index)
    rng = block_generator(st.seed, index)
    for name, width in widths.items():
        dest = out[name][row : row + size]
        if width == 0:  # nothing to draw (the generator does not advance)
            continue
        if name == "factors" and st.sampling != "random":
            dest[:] = ndtri(_unit_design(st.sampling, rng, size_full, width))[:size]
        elif size == size_full:
            rng.standard_normal(out=dest)  # straight into the chunk: no copy
        else:  # a partial last block still draws a whole block
            dest[:] = rng.standard_normal((size_full, width))[:size]
    return size


def sample_block(config, index: int, count: int = 1) -> Block:
    """Draw block ``index`` of a study, or the ``count`` consecutive blocks from it as one.

    Each block draws from its own generator (module docstring); the draws of the blocks are
    then transformed together, so the result for an assembly is the same whether its block
    is drawn alone or with others.

    Parameters
    ----------
    config : tolsim.study.spec.StudyConfig
    index : int
        Block number (0-based) of the first block.
    count : int
        Number of consecutive blocks.

    Returns
    -------
    Block
        ``index`` and ``start`` of the first block, ``size`` of all of them together.
    """
    st = config.study
    grid = field_grid(config)
    widths = draw_widths(config, grid)
    size = sum(block_size_of(config, k) for k in range(index, index + count))
    raw = {name: np.empty((size, width)) for name, width in widths.items()}
    row = 0
    for k in range(index, index + count):
        row += _draw(config, k, widths, raw, row)
    return block_from_draws(config, index, index * st.block_size, raw)


def block_from_draws(config, index: int, start: int, raw: dict) -> Block:
    """The :class:`Block` of drawn independent standard normals ``raw`` (name -> (size,
    width), the columns of :func:`draw_widths`): per-track factors, gaps and ball positions,
    rail fields by their AR(1) recursion, the entering balls. The one transform behind
    :func:`sample_block` and :func:`tolsim.study.analyses.limit_state.block_from_normals`."""
    grid = field_grid(config)
    size = len(raw["gap"])
    tracks, balls = config.n_tracks, config.train.balls
    if tracks == 1:
        draws = {t.source: raw["factors"][:, j : j + 1]
                 for j, t in enumerate(per_assembly_sources(config))}
    else:  # one value per track, the same for the balls of the track
        draws = {t.source: np.repeat(raw["factors"][:, j * tracks : (j + 1) * tracks], balls,
                                     axis=1)
                 for j, t in enumerate(per_assembly_sources(config))}
    draws.update({t.source: raw[t.source] for t in config.tolerances if t.scope == "ball"})
    gaps = np.maximum(config.train.initial_gap.from_normal(raw["gap"]), 0.0)
    pitch = (2.0 * config.bearing.ball_radius + gaps).reshape(size * tracks, balls - 1)
    position = np.concatenate([np.zeros((size * tracks, 1)), np.cumsum(pitch, axis=1)], axis=1)
    position -= position.mean(axis=1, keepdims=True)
    position = position.reshape(size, tracks * balls)
    fields = {}
    for t in config.tolerances:
        if t.source not in grid:
            continue
        innovations = np.ascontiguousarray(raw[t.source])  # no copy when already
        ell = t.correlation_length
        if not config.is_along_track:
            # Exact: the Ornstein-Uhlenbeck process sampled at the ball centres themselves
            # (Markov, so each ball conditions on the one behind it); one field per track.
            along = position.reshape(size * tracks, balls)
            phi = np.exp(-np.diff(along, axis=1) / ell)
            draws[t.source] = _ar1(phi, np.sqrt(1.0 - phi * phi),
                                   innovations.reshape(size * tracks, balls)).reshape(
                size, tracks * balls)
            continue
        origin, spacing, points = grid[t.source]
        phi = np.full((1, points - 1), np.exp(-spacing / ell))
        # one field per track: row a * tracks + t
        values = _ar1(phi, np.sqrt(1.0 - phi * phi), innovations.reshape(size * tracks, points))
        fields[t.source] = RailField(origin, spacing, values, tracks)
    entering_gap, entering = None, {}
    if "entering_gap" in raw:  # a carriage's balls entering its loaded zone (draw 5)
        entering_gap = np.maximum(config.train.initial_gap.from_normal(raw["entering_gap"]),
                                  0.0)
        entering = {t.source: raw[f"entering_{t.source}"] for t in config.tolerances
                    if t.scope == "ball"}
    return Block(index, start, size, draws, fields, gaps, position, entering_gap, entering)


def error_values(config, block: Block, rail_position=None, parallel=False):
    """Error source values per ball in SI, shape (size, balls) each.

    Parameters
    ----------
    config : StudyConfig
    block : Block
    rail_position : ndarray, shape (size, balls), optional
        Ball centres along the rail [m] at which rail fields are read (t = 0 positions by
        default).
    parallel : bool
        Read the rail fields on Numba's threads (:meth:`RailField.at`).

    Returns
    -------
    dict
        source -> ndarray (size, balls) [m or rad].
    """
    pos = block.initial_position if rail_position is None else rail_position
    shape = pos.shape
    z = {}
    for t in config.tolerances:
        if t.source in block.fields:
            z[t.source] = block.fields[t.source].at(pos, parallel)
        else:
            z[t.source] = np.broadcast_to(block.normals[t.source], shape)
    for group in config.correlations:
        _correlate(group, z)
    return {t.source: t.distribution.from_normal(z[t.source]) for t in config.tolerances}


def moving_ball_values(config, block: Block, ball_id, rail_position, rows=None, fixed=None,
                       out=None, sources=None):
    """Error source values of balls moving through a carriage, in SI (``along_track``).

    Each ball keeps its own ``ball`` draws (the initial ball j of a track those of the block,
    the k-th ball to enter the track's loaded zone those of draw 5, module docstring); the
    per-assembly sources are those of its track; a rail field is read at its rail position.

    Parameters
    ----------
    config : StudyConfig
        With a ``[carriage]`` (T tracks of n balls).
    block : Block
    ball_id : ndarray of int, shape (m, T, S)
        The ball in each slot: j < n the initial ball j of the track, n + k the k-th entering
        ball; a negative id gives the values of ball 0 (an empty slot, ignored by the caller).
    rail_position : ndarray, shape (m, T, S)
        Ball centres along the rail [m] (finite).
    rows : array_like of int, optional
        The block's assemblies of the m rows (default all, m = ``block.size``).
    fixed : dict, optional
        :func:`fixed_ball_values` of the block, for a caller that reads the same block at
        every step: those sources are taken from it instead of being transformed again (the
        same values, bit for bit: the transforms are elementwise).
    out : dict, optional
        source -> ndarray (m, T, S) to write the values into (every source of the config;
        views of the GrooveErrors fields,
        :func:`tolsim.study.pipeline.evaluate.groove_error_buffers`).
    sources : iterable of str, optional
        Only these sources (default all), and those correlated with them (a correlation
        group is transformed whole): the same values, for a caller that needs a few.

    Returns
    -------
    dict
        source -> ndarray (m, T, S) [m or rad] (``out`` if given).
    """
    tracks, balls = config.n_tracks, config.train.balls
    rows = np.arange(block.size) if rows is None else np.asarray(rows)
    shape = np.shape(ball_id)
    ids = np.maximum(ball_id, 0)
    fixed = {} if fixed is None else fixed
    wanted = _with_groups(config, sources)
    z = {}
    for t in config.tolerances:
        if t.source in fixed or t.source not in wanted:
            continue
        if t.source in block.fields:
            z[t.source] = _field_at(block.fields[t.source], rows, rail_position)
        elif t.scope == "ball":
            own = block.normals[t.source][rows].reshape(len(rows), tracks, balls)
            new = block.entering[t.source][rows].reshape(len(rows), tracks, -1)
            z[t.source] = np.take_along_axis(np.concatenate([own, new], axis=2), ids, axis=2)
        else:  # one value per track
            per_track = block.normals[t.source][rows].reshape(len(rows), tracks, -1)[:, :, :1]
            z[t.source] = np.broadcast_to(per_track, shape)
    for group in config.correlations:
        if group.sources[0] in wanted:  # (a group is wanted whole or not at all)
            _correlate(group, z)
    given = out is not None
    out = out if given else {}
    for t in config.tolerances:
        if t.source not in wanted:
            continue
        if t.source not in fixed:
            value = t.distribution.from_normal(z[t.source])
            if given:
                out[t.source][...] = value
            else:
                out[t.source] = value
        else:  # by ball id, or the track's one value
            if not given:
                out[t.source] = np.empty(shape)
            _take_balls_kernel(fixed[t.source], rows, ids, t.scope == "ball", out[t.source])
    return out


def _with_groups(config, sources) -> set:
    """The config's sources among ``sources`` (None: all) and every source of a correlation
    group that holds one of them."""
    every = {t.source for t in config.tolerances}
    if sources is None:
        return every
    wanted = set(sources) & every
    for group in config.correlations:
        if wanted & set(group.sources):
            wanted |= set(group.sources)
    return wanted


@pjit
def _take_balls_kernel(values, rows, ids, by_ball, out):
    """``out[a, t, j]`` = ``values[rows[a], t, ids[a, t, j]]`` (``by_ball``) or
    ``values[rows[a], t, 0]`` (as ``np.take_along_axis`` of ``values[rows]``, or its
    broadcast); the rows on Numba's threads."""
    m, tracks, slots = out.shape
    for a in prange(m):
        r = rows[a]
        for t in range(tracks):
            for j in range(slots):
                out[a, t, j] = values[r, t, ids[a, t, j] if by_ball else 0]


def fixed_ball_values(config, block: Block) -> dict:
    """The values of a carriage block's sources that do not change as its balls move, in SI:
    ``ball`` sources (m, T, n + entering balls, by ball id) and per-track ones (m, T, 1); not
    rail fields, nor sources of a correlation group (:func:`moving_ball_values` takes them)."""
    tracks, balls = config.n_tracks, config.train.balls
    correlated = {source for group in config.correlations for source in group.sources}
    size = block.size
    out = {}
    for t in config.tolerances:
        if t.source in block.fields or t.source in correlated:
            continue
        if t.scope == "ball":
            own = block.normals[t.source].reshape(size, tracks, balls)
            new = block.entering[t.source].reshape(size, tracks, -1)
            z = np.concatenate([own, new], axis=2)
        else:
            z = block.normals[t.source].reshape(size, tracks, -1)[:, :, :1]
        out[t.source] = t.distribution.from_normal(z)
    return out


def _field_at(rail_field: RailField, rows, position):
    """``rail_field`` of the block's assemblies ``rows`` at positions (m, T, S) [-]."""
    tracks = rail_field.tracks
    index = (np.asarray(rows)[:, None] * tracks + np.arange(tracks)).reshape(-1)
    pos = np.ascontiguousarray(position, dtype=np.float64)
    out = np.empty(pos.shape)
    _field_at_parallel(np.ascontiguousarray(rail_field.values, dtype=np.float64), index,
                     float(rail_field.origin), float(rail_field.spacing),
                     pos.reshape(len(index), -1), out.reshape(len(index), -1))
    return out


def _correlate(group, z):
    """Replace the independent normals xi of ``group``'s sources in ``z`` by L xi."""
    chol = group.cholesky
    xi = [z[source] for source in group.sources]
    for i, source in enumerate(group.sources):
        total = chol[i, 0] * xi[0]  # elementwise, k = 0, 1, ..., i: a fixed order
        for k in range(1, i + 1):
            total = total + chol[i, k] * xi[k]
        z[source] = total


def choose_spot_checks(config) -> np.ndarray:
    """Sorted global ball indices (assembly * balls + ball): the candidates of the uniform
    stratum of the spot checks (all ``spot_checks`` of them; see :class:`SpotCheckPlan`)."""
    total = config.study.samples * config.balls
    k = min(config.study.spot_checks, total)
    if k == 0:
        return np.empty(0, dtype=np.int64)
    rng = spot_check_generator(config.study.seed)
    return np.sort(rng.choice(total, size=k, replace=False)).astype(np.int64)


# --------------------------------------------------------------------------------------------
# Spot checks stratified towards the spec limit
# --------------------------------------------------------------------------------------------
#: Band of |epsilon| around the spec limit L, as multiples of L, from which the near-limit
#: stratum of the spot checks is drawn.
NEAR_LIMIT_BAND = (0.8, 1.2)
#: Names of the spot-check strata, by their code in ``spot_check_stratum``.
SPOT_CHECK_STRATA = ("uniform", "near_limit")
#: Identity of the selection scheme (part of a run's fingerprint for resuming).
SPOT_CHECK_SCHEME = "spot checks: uniform + near-limit band, splitmix64 priorities, v1"

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1, _MIX2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def spot_check_priority(key: int, ball_index) -> np.ndarray:
    """Seeded pseudo-random priority of global ball indices (uint64).

    SplitMix64's output function (Steele, Lea & Flood, "Fast splittable pseudorandom number
    generators", OOPSLA 2014) at state ``key + (index + 1) * golden``: a fixed function of
    (key, index), so a ball's priority does not depend on which block or chunk it is in.
    """
    x = np.asarray(ball_index, dtype=np.uint64)
    with np.errstate(over="ignore"):  # arithmetic modulo 2^64, as intended
        z = np.uint64(key) + (x + np.uint64(1)) * _GOLDEN
        z = (z ^ (z >> np.uint64(30))) * _MIX1
        z = (z ^ (z >> np.uint64(27))) * _MIX2
    return z ^ (z >> np.uint64(31))


def _smallest(priority, ball_index, k):
    """Positions of the k smallest (priority, ball index) pairs, in that order."""
    order = np.lexsort((ball_index, priority))
    return order[:k]


@dataclass(frozen=True)
class SpotCheckPlan:
    """Which balls a study re-solves with the full model (fixed before the run).

    Two strata. ``uniform``: balls drawn uniformly over all balls before the run
    (:func:`choose_spot_checks`). ``near_limit``: with a spec limit L on |epsilon|, up to
    ``near_limit`` = ``count`` // 2 balls whose study epsilon came from the fast model and
    lies in ``band`` = [0.8 L, 1.2 L] (:data:`NEAR_LIMIT_BAND`), where the ppm and Cpk
    claims are made; a uniform sample of the band: the balls with the smallest
    :func:`spot_check_priority`. Each block keeps its ``near_limit`` smallest, and the k
    smallest of a union are the k smallest of the parts' k smallest, so the choice is the
    same whatever the chunking, workers or resuming (bit-identical). When the band holds
    fewer balls the uniform stratum fills up to ``count`` (its candidates with the smallest
    priorities); without a limit every spot check is uniform, as before.

    Attributes
    ----------
    uniform : ndarray of int64
        Sorted global ball indices, the ``count`` candidates of the uniform stratum.
    count : int
        Spot checks in all.
    near_limit : int
        Most spot checks from the band.
    band : tuple of float
        (low, high) of |epsilon| [-]; NaN without a limit.
    key : int
        Hash key of the priorities (``SeedSequence(seed, spawn_key=(1, 1))``).
    """

    uniform: np.ndarray
    count: int
    near_limit: int
    band: tuple
    key: int


def spot_check_plan(config) -> SpotCheckPlan:
    """The :class:`SpotCheckPlan` of a study."""
    uniform = choose_spot_checks(config)
    limit = config.study.velocity_deviation_limit
    has_limit = bool(limit) and limit > 0
    band = (NEAR_LIMIT_BAND[0] * limit, NEAR_LIMIT_BAND[1] * limit) if has_limit else (
        float("nan"), float("nan"))
    key = int(np.random.SeedSequence(config.study.seed, spawn_key=(1, 1)).generate_state(
        1, np.uint64)[0])
    return SpotCheckPlan(uniform, len(uniform), len(uniform) // 2 if has_limit else 0,
                         band, key)


def near_limit_candidates(plan: SpotCheckPlan, velocity_deviation, fast, start_ball: int,
                          exclude=()):
    """The near-limit candidates among consecutive balls.

    Parameters
    ----------
    plan : SpotCheckPlan
    velocity_deviation : ndarray, shape (n,)
        The study's epsilon of balls ``start_ball`` .. ``start_ball + n - 1`` [-].
    fast : ndarray of bool, shape (n,)
        True where epsilon came from the study's fast model.
    start_ball : int
        Global index of the first ball.
    exclude : array_like of int
        Local positions already spot-checked (the uniform candidates).

    Returns
    -------
    local : ndarray of int64
        Local positions of at most ``plan.near_limit`` balls in the band (smallest
        priorities), sorted.
    in_band : int
        Balls of the fast model in the band (the stratum's population here).
    """
    if plan.near_limit == 0:
        return np.empty(0, np.int64), 0
    a = np.abs(velocity_deviation)
    with np.errstate(invalid="ignore"):
        mask = fast & (a >= plan.band[0]) & (a <= plan.band[1])
    in_band = int(np.count_nonzero(mask))
    mask[np.asarray(exclude, dtype=np.int64)] = False
    local = np.flatnonzero(mask)
    glob = local + start_ball
    keep = _smallest(spot_check_priority(plan.key, glob), glob, plan.near_limit)
    return np.sort(local[keep]).astype(np.int64), in_band


def near_limit_cut(plan: SpotCheckPlan, ball_index, stratum):
    """The largest (priority, ball index) key of a near-limit row that can still be chosen.

    ``ball_index``, ``stratum``: recorded candidates of consecutive blocks (from the first).
    :func:`select_spot_checks` keeps the ``near_limit`` smallest keys of the near-limit
    rows of all blocks; more blocks only add keys, so a row whose key is above the
    ``near_limit``-th smallest of a prefix is never chosen by a run holding that prefix and
    need not be kept. Returns None while the prefix holds no more than ``near_limit`` such
    rows (every one can still be chosen).
    """
    ball_index = np.asarray(ball_index, dtype=np.int64)
    near = ball_index[np.asarray(stratum) == 1]
    if len(near) <= plan.near_limit:
        return None
    priority = spot_check_priority(plan.key, near)
    last = _smallest(priority, near, plan.near_limit)[-1]
    return priority[last], near[last]


def near_limit_kept(plan: SpotCheckPlan, ball_index, stratum, cut) -> np.ndarray:
    """Mask of the rows to keep under :func:`near_limit_cut`'s ``cut``: every uniform
    row, and the near-limit rows whose key is not above it."""
    ball_index = np.asarray(ball_index, dtype=np.int64)
    near = np.asarray(stratum) == 1
    if cut is None:
        return np.ones(len(ball_index), dtype=bool)
    priority = spot_check_priority(plan.key, ball_index)
    above = (priority > cut[0]) | ((priority == cut[0]) & (ball_index > cut[1]))
    return ~(near & above)


def select_spot_checks(plan: SpotCheckPlan, ball_index, stratum) -> np.ndarray:
    """Rows of the recorded candidates that are spot-checked, sorted by ball index.

    ``ball_index``, ``stratum``: of every recorded candidate (all ``count`` uniform ones and
    each block's near-limit ones). Keeps the ``near_limit`` near-limit candidates with the
    smallest priorities and fills up to ``count`` with the uniform candidates of smallest
    priority.
    """
    ball_index = np.asarray(ball_index, dtype=np.int64)
    stratum = np.asarray(stratum)
    priority = spot_check_priority(plan.key, ball_index)
    near = np.flatnonzero(stratum == 1)
    near = near[_smallest(priority[near], ball_index[near], plan.near_limit)]
    uniform = np.flatnonzero(stratum == 0)
    uniform = uniform[_smallest(priority[uniform], ball_index[uniform],
                                plan.count - len(near))]
    rows = np.concatenate([uniform, near])
    return rows[np.argsort(ball_index[rows], kind="stable")]
