r"""The standard-normal space of a study and its limit states, for the rare-event estimators.

:mod:`tolsim.study.analyses.rare_events` estimates P(g(U) <= 0) for U ~ N(0, I_d) and a limit state
g
on arrays of shape (n, d). This module gives a study's d, the map from U to the study's
:class:`~tolsim.study.sampling.Block` and the limit state g of each event the study defines
(issue 15), and runs the estimator the config names for each event
(:func:`estimate_events`, called by :func:`tolsim.study.execution.runner.run_study` after its plain
Monte Carlo run). The theory is in the Notes of :func:`block_from_normals` (the standard-normal
space), :func:`event_values` (the limit states), :func:`estimate_event` (the estimators),
:func:`event_seed` (the seeds) and :func:`design_point_summary` (the design point in physical
units).

References
----------
.. [Lin2018] B. Lin, C. E. Okwudire, M. Duan, J. S. Wou, "Ball-to-ball contact in linear ball
   bearings", IMECE2018-88033.
.. [Melchers1989] R. E. Melchers, "Importance sampling in structural systems", Structural
   Safety 6 (1989) 3-10, doi:10.1016/0167-4730(89)90003-9.
"""

import time
from dataclasses import dataclass, field

import numpy as np

from tolsim.study.analyses.rare_events import (
    ESTIMATOR_TITLES,
    MIN_CHAINS,
    SeriesDesignPoints,
    series_importance_sampling,
    subset_simulation,
)
from tolsim.study.analyses.rare_events.api import (
    combine,
    estimator_seeds,
    form_cross_check,
    replicated_subset,
)
from tolsim.study.analyses.rare_events.importance import series_design_points
from tolsim.study.analyses.sensitivity import study_factors
from tolsim.study.pipeline.block import (
    evaluate_block,
    has_carriage,
    has_contact,
    is_along_track,
)
from tolsim.study.pipeline.propagation import StepObserver, integrate_along_track
from tolsim.study.pipeline.track_friction import evaluate_friction
from tolsim.study.sampling import (
    Block,
    block_from_draws,
    draw_widths,
    error_values,
    field_grid,
    per_assembly_sources,
)
from tolsim.study.spec import ESTIMATORS, SOURCES

#: First spawn-key entry of the rare-event streams under the study's seed (Notes of
#: :func:`event_seed`).
RARE_EVENT_SPAWN_KEY = 4
#: Second entry, per event: fixed, so adding an event never changes another's draws.
EVENT_KEYS = {"contact": 0, "velocity_deviation_exceedance": 1, "friction_exceedance": 2}
#: The events, in the order they are estimated and reported.
EVENTS = tuple(EVENT_KEYS)
#: The probability variables of each event in the result file (prefix of ``_ci_lower`` ...).
EVENT_PROBABILITY = {"contact": "contact_probability",
                     "velocity_deviation_exceedance": "velocity_deviation_exceedance_probability",
                     "friction_exceedance": "friction_exceedance_probability"}
#: How the summary names an event's probability.
EVENT_TITLES = {"contact": "P(contact)", "velocity_deviation_exceedance": "P(an assembly has "
                "|epsilon| > limit)", "friction_exceedance": "P(friction increase > limit)"}
#: Units of each event's g.
EVENT_UNITS = {"contact": "m", "velocity_deviation_exceedance": "1", "friction_exceedance": "1"}
#: :attr:`EventEstimate.mode_check`: subset simulation unchecked for a lost failure mode,
#: checked against FORM design points, or checked by two independent replicates.
MODE_CHECK_NONE = "none"
MODE_CHECK_DESIGN_POINTS = "design_points"
MODE_CHECK_REPLICATES = "replicates"
#: :attr:`EventEstimate.parts` keys of the two replicates.
REPLICATE_PARTS = ("replicate_1", "replicate_2")
#: Name of the gap factor (as :data:`tolsim.study.analyses.sensitivity.INITIAL_GAP`).
INITIAL_GAP = "initial_gap"


# ---------------------------------------------------------------------------------------------
# the standard-normal space
# ---------------------------------------------------------------------------------------------

def column_layout(config) -> dict:
    """Draw name -> slice of its columns in a row of U, in the documented order.

    Names as :func:`tolsim.study.sampling.sample_block` draws them: ``factors``, each ball
    source, ``gap``, each rail field, and with a carriage and ``along_track`` propagation
    ``entering_gap`` and ``entering_<source>``.
    """
    out, start = {}, 0
    for name, width in draw_widths(config, field_grid(config)).items():
        out[name] = slice(start, start + width)
        start += width
    return out


def dimension(config) -> int:
    """d: the independent standard normals of one assembly."""
    layout = column_layout(config)
    return max((s.stop for s in layout.values()), default=0)


def block_from_normals(config, normals, index: int = 0, start: int = 0) -> Block:
    """The :class:`~tolsim.study.sampling.Block` of the assemblies whose standard normals are
    the rows of ``normals`` (the inverse of the draw layout, Notes).

    The transformation is that of :func:`tolsim.study.sampling.sample_block`
    (:func:`tolsim.study.sampling.block_from_draws`), on the rows given instead of a block's
    draws.

    Parameters
    ----------
    config : StudyConfig
    normals : ndarray, shape (m, d)
        One row per assembly [-].
    index, start : int
        Recorded in the Block (block number, first assembly); no effect on the values.

    Returns
    -------
    Block
        Of ``m`` assemblies.

    Notes
    -----
    **The standard-normal space.**
    One assembly is one row u of d independent standard normals: exactly the draws of one
    assembly in a random block (:mod:`tolsim.study.sampling`), in the same order, so that
    :func:`block_from_normals` is the inverse of the draw layout. The columns, in order
    (:func:`column_layout`; T tracks, n balls per track, all track by track):

    1. ``factors``: T per per-assembly source (``carriage`` sources and ``rail`` sources without
       a correlation length, in config order), source by source, track by track within a source;
    2. each ``ball`` source, in config order: T n (one per ball);
    3. ``gap``: T (n - 1), the initial gaps;
    4. each rail random field (a ``rail`` source with a correlation length), in config order: its
       AR(1) innovations, T n (``constant`` propagation: the field at the ball centres) or T times
       the grid points (``along_track``);
    5. a carriage with ``along_track`` propagation only: ``entering_gap`` and
       ``entering_<source>`` of each ball source, T E each.

    A column belongs to a source even when its distribution is fixed (the draws are made all the
    same; g does not depend on it). The marginal maps, correlations (Cholesky of the
    independent xi, :func:`tolsim.study.sampling.error_values`) and the AR(1) recursion of the
    fields are those of :func:`tolsim.study.sampling.sample_block`, applied row by row, so a row
    of U drawn the sampler's way gives the sampler's assembly bit for bit
    (``tests/study/test_rare_study.py``). With ``sampling = "sobol"`` or ``"lhs"`` the plain run's
    per-assembly factors come from a quasi-random design; the rare-event estimators draw every
    column as an independent standard normal (the same distribution).
    """
    u = np.asarray(normals, dtype=np.float64)
    d = dimension(config)
    if u.ndim != 2 or u.shape[1] != d:
        raise ValueError(f"normals of shape {u.shape}: expected (rows, {d})")
    layout = column_layout(config)
    raw = {name: u[:, sl] for name, sl in layout.items()}
    return block_from_draws(config, index, start, raw)


# ---------------------------------------------------------------------------------------------
# events and limit states
# ---------------------------------------------------------------------------------------------

def study_events(config) -> tuple:
    """The events a study defines, in :data:`EVENTS` order (Notes of :func:`event_values`)."""
    out = []
    if config.train.balls > 1:
        out.append("contact")
    if config.study.velocity_deviation_limit > 0:
        out.append("velocity_deviation_exceedance")
    if has_contact(config) and config.contact.friction_increase_limit > 0:
        out.append("friction_exceedance")
    return tuple(out)


def check_supported(config) -> None:
    """Raise ValueError (one line) when a study cannot use a rare-event estimator."""
    estimator = config.study.estimator
    if estimator == "monte_carlo":
        return
    if has_carriage(config) and is_along_track(config):
        raise ValueError(f"estimator = {estimator!r} is not available for a carriage with "
                         "along_track propagation (balls enter and leave its loaded zone); "
                         "use propagation = 'constant' or estimator = 'monte_carlo'")
    if not study_events(config):
        raise ValueError(f"estimator = {estimator!r}: the study defines no event to estimate "
                         "(one ball per track, no velocity_deviation_limit, no friction limit)")


def is_smooth(config, event) -> bool:
    """Whether FORM may be tried on the event's limit state (Notes of :func:`event_values`)."""
    return event in ("contact", "velocity_deviation_exceedance") and \
        not is_along_track(config)


def outside_model_range(config, values) -> np.ndarray:
    """Assemblies (rows) with an error value beyond what the static model accepts.

    The static model takes rotations within +/-pi/8 and lengths within a quarter of the
    ball-groove centre distance (:func:`tolsim.physics.static.error_items`; the config
    checks that the distributions stay inside,
    :func:`tolsim.io.config.sections._check_range`). The estimators' points can lie further
    out (a FORM step, a far tail): such an assembly is unresolved (g NaN), not an error.
    """
    bearing = config.bearing
    limits = {"angle": np.pi / 8, "length": 0.25 * (bearing.groove_radius - bearing.ball_radius)}
    bad = np.zeros(next(iter(values.values())).shape[0], dtype=bool)
    for source, x in values.items():
        bad |= ~np.all(np.abs(x) <= limits[SOURCES[source][0]], axis=1)
    return bad


def _balls(config, block):
    """BallState of a block's assemblies at the start of the stroke (as ``run_chunk``), with
    the assemblies :func:`outside_model_range` evaluated at the nominal errors and then
    marked unresolved (epsilon NaN, not valid)."""
    values = error_values(config, block)
    bad = outside_model_range(config, values) if values else np.zeros(block.size, bool)
    if bad.any():
        values = {k: np.where(bad[:, None], 0.0, v) for k, v in values.items()}
    state = evaluate_block(config, block, values, propagate=False).state
    if bad.any():
        state.velocity_deviation[bad] = np.nan
        state.valid[bad] = False
    return state


def _row_min(x):
    """Smallest value per row ignoring NaN, +inf for an empty or all-NaN row."""
    if x.shape[1] == 0:
        return np.full(x.shape[0], np.inf)
    return np.min(np.where(np.isnan(x), np.inf, x), axis=1)


def contact_margins(config, block, state) -> np.ndarray:
    """Contact margin of every adjacent pair, (size, tracks * (balls - 1)) [m], track by track.

    g_j = g0_j - (eps_j - eps_{j+1}) v T / 2 (``constant`` propagation; NaN where a ball of
    the pair is unresolved); a pair touches within the horizon iff g_j <= 0, as
    :func:`tolsim.study.pipeline.propagation.first_contact_tracks` decides (Notes of
    :func:`event_values`).
    """
    tracks, balls = config.n_tracks, config.train.balls
    m = block.size
    eps = state.velocity_deviation.reshape(m * tracks, balls)
    half_speed = 0.5 * config.motion.groove_velocity
    rate = (eps[:, :-1] - eps[:, 1:]) * half_speed       # as constant_contact_kernel
    gap = block.initial_gap.reshape(m * tracks, balls - 1)
    margin = gap - rate * config.motion.duration
    # the kernel needs a closing rate > 0: a gap of 0 that does not close is no contact
    margin = np.where((margin == 0) & ~(rate > 0), np.finfo(float).tiny, margin)
    return margin.reshape(m, tracks * (balls - 1))


def exceedance_margins(config, state) -> np.ndarray:
    """|epsilon| limit margins L - eps_b and L + eps_b of every ball, (size, 2 balls) [-]:
    ball by ball, the upper then the lower side; NaN for an unresolved ball."""
    limit = config.study.velocity_deviation_limit
    eps = state.velocity_deviation
    return np.stack([limit - eps, limit + eps], axis=2).reshape(eps.shape[0], -1)


def component_names(config, event) -> tuple:
    """Names of the components of a series event (:func:`component_values` columns)."""
    tracks, balls = config.n_tracks, config.train.balls
    where = (lambda t: f"track {t} ") if tracks > 1 else (lambda t: "")
    if event == "contact":
        return tuple(f"{where(t)}pair {j}" for t in range(tracks) for j in range(balls - 1))
    if event == "velocity_deviation_exceedance":
        return tuple(f"{where(t)}ball {b} epsilon {side}" for t in range(tracks)
                     for b in range(balls) for side in ("> +L", "< -L"))
    raise ValueError(f"event {event!r} has no components")


def component_values(config, block, event) -> np.ndarray:
    """The components of a series event, (size, k): the event is their union, its g their
    minimum (:func:`series`). ``contact`` (``constant`` propagation): the pairs
    (:func:`contact_margins`); ``velocity_deviation_exceedance``: each ball beyond +L or
    below -L (:func:`exceedance_margins`)."""
    state = _balls(config, block)
    if event == "contact":
        return contact_margins(config, block, state)
    if event == "velocity_deviation_exceedance":
        return exceedance_margins(config, state)
    raise ValueError(f"event {event!r} has no components")


def series(components) -> np.ndarray:
    """g of the union of components (size, k): their minimum where it fails (<= 0) or where
    every component is known, NaN otherwise (a certain failure counts even with an
    unresolved component, as the plain run counts a certain contact)."""
    g = _row_min(components)
    known = ~np.isnan(components).any(axis=1) | (g <= 0)
    return np.where(known, g, np.nan)


class SmallestGap(StepObserver):
    """The smallest gap of a resolved pair at the end of each step [m] (``smallest``), and
    whether the contact event occurred (``hit``), as :class:`~tolsim.study.pipeline.
    propagation.FirstContact` decides it."""

    def begin(self, block, position):
        self.hit = np.zeros(block.size, dtype=bool)
        self.smallest = np.full(block.size, np.inf)

    def observe(self, step):
        gap_old, gap_new, ball_ok = step.gap_old, step.gap_new, step.ball_ok
        pair_ok = ball_ok[:, :-1] & ball_ok[:, 1:]
        self.hit |= np.any((gap_new <= 0.0) & (gap_old > gap_new) & pair_ok, axis=1)
        self.smallest = np.minimum(self.smallest,
                                   _row_min(np.where(pair_ok, gap_new, np.inf)))


def contact_margin_along_track(config, block, state):
    """(g [m], hit, resolved) of the contact event with ``along_track`` propagation.

    The midpoint integration of :func:`tolsim.study.pipeline.propagation.first_contact_along_track`
    (:func:`~tolsim.study.pipeline.propagation.integrate_along_track`, the same arithmetic),
    recording the smallest gap of a resolved pair at the end of each step and its contact
    decision (Notes of :func:`event_values`).
    """
    margin = SmallestGap()
    ball_ok, _ = integrate_along_track(config, block, state, [margin])
    hit, smallest = margin.hit, margin.smallest
    # a gap at exactly 0 that never closed further is no contact (as the plain run)
    g = np.where(~hit & (smallest <= 0), np.finfo(float).tiny, smallest)
    resolved = state.valid.all(axis=1) & ball_ok.all(axis=1)
    return g, hit, resolved


def event_values(config, block, events=None) -> dict:
    """g of each event (Notes) for the assemblies of ``block``.

    Parameters
    ----------
    config : StudyConfig
    block : Block
    events : sequence of str, optional
        Default :func:`study_events`.

    Returns
    -------
    dict
        event -> ndarray (size,): g, failure where g <= 0, NaN unresolved.

    Notes
    -----
    **Limit states (failure where g <= 0; NaN: unresolved).**
    Each is computed on the block built from U through the study's own evaluation path
    (:func:`tolsim.study.sampling.error_values`,
    :func:`tolsim.study.pipeline.evaluate.evaluate_balls` or
    :func:`tolsim.study.pipeline.carriage.evaluate_carriage`, the propagation, the friction of the
    trains), row by row: the value of a row does not depend on the other rows of the call (no
    BLAS product mixes rows), so the estimators' results do not depend on the batch size.

    ``contact`` (every study with at least two balls per track) [m]
        ``constant`` propagation: the smallest margin over the adjacent pairs of every track,
        g = min_j (g0_j - c_j(T)), c_j(T) = (eps_j - eps_{j+1}) v T / 2 the closure of pair j at
        the horizon T ([Lin2018] Sec. 3.2; :mod:`tolsim.study.pipeline.propagation`, mode a). g <= 0
        iff a pair touches within the horizon, as :func:`~tolsim.study.pipeline.propagation.
        first_contact_tracks` decides (a gap of exactly 0 that does not close, where the kernel
        needs a closing rate > 0, is given the smallest positive g). The event is a *series
        system*: the union of its pairs' events, each with a smooth margin g_j (the components,
        :func:`component_values`); g is smooth except where two pairs tie for the minimum.

        ``along_track`` (single trains): the smallest gap of a resolved pair at the end of any
        integration step, g = min_{k, j} g_j(t_k), from the midpoint integration of
        :func:`~tolsim.study.pipeline.propagation.first_contact_along_track` (the same arithmetic);
        g <= 0
        iff that function reports a contact (a gap that reaches exactly 0 without closing
        further is given the smallest positive g). It is continuous but not smooth (the minimum
        over a time grid): importance sampling is not attempted (FORM needs a smooth limit state)
        and subset simulation is used, with one line saying so. (A contact *time* would not do:
        without contact within the horizon there is none, and g would be flat.) With a
        ``[carriage]`` and ``along_track`` the rare-event estimators are not available (balls
        enter and leave the loaded zone; :func:`check_supported`).

        Unresolved: a train with a contact of resolved balls has g <= 0 (certain, as the plain
        run counts it); otherwise a train with an unresolved ball (at any evaluation) gives NaN.
    ``velocity_deviation_exceedance`` (a ``velocity_deviation_limit``, L) [-]
        g = L - max_b |eps_b| over the balls of the assembly: the probability that an
        **assembly** has a ball beyond the limit (the plain run's ppm are per ball; its count
        of such assemblies, ``Accumulator.n_exceedance``, is the plain estimate of this event,
        kept when the estimator does not reach it). With ``along_track`` the balls' epsilon at
        the start of the stroke (as the plain run's epsilon statistics). An unresolved ball
        gives NaN unless a resolved ball of the assembly exceeds (an unloaded ball too, having
        no epsilon, where the plain count takes it as within the limit, as the plain
        P(contact) takes it as answered). A series system of 2 T n components, L - eps_b and
        L + eps_b (each ball, either side).
    ``friction_exceedance`` (``[contact]`` with a ``friction_increase_limit``, L) [-]
        The increase of the worst track's friction force needs a contact: without one it is 0,
        and g = (L - increase) / L would be flat (1) over most of the space, which stops subset
        simulation. So, dimensionless::

            g = (L - increase_max) / L            with a contact in the assembly (g <= 1),
            g = 1 + g_contact / (v T / 2)         without one (g > 1),

        g_contact the contact margin above [m] and v T / 2 the travel over which it is
        measured (g_contact / (v T / 2) is the margin in epsilon-difference units). g <= 0 iff the
        increase reaches L (:mod:`tolsim.study.pipeline.track_friction`; the plain run counts > L, a
        tie of
        measure zero). g jumps at the contact boundary (the contact forces start at K delta-eps),
        so importance sampling is not attempted; subset simulation is used, as for along_track.
        An unresolved or sliding assembly whose increase certainly exceeds L (as the plain run's
        count) gets g = 0, any other unresolved one NaN.

    An assembly whose error values lie beyond the range the static model accepts (a point far out
    in U, which the sampler never draws: the config keeps every distribution inside,
    :func:`outside_model_range`) is unresolved, NaN, instead of stopping the estimator.
    """
    events = study_events(config) if events is None else tuple(events)
    state = _balls(config, block)
    out = {}
    touched = margin = None
    if "contact" in events or "friction_exceedance" in events:
        if is_along_track(config):
            margin, _, resolved = contact_margin_along_track(config, block, state)
        else:
            margin = _row_min(contact_margins(config, block, state))
            resolved = state.valid.all(axis=1)
        touched = margin <= 0
        out["contact"] = np.where(touched | resolved, margin, np.nan)
    if "velocity_deviation_exceedance" in events:
        out["velocity_deviation_exceedance"] = series(exceedance_margins(config, state))
    if "friction_exceedance" in events:
        limit = config.contact.friction_increase_limit
        figures = evaluate_friction(config, block.initial_gap, state, block=block)
        scale = 0.5 * config.motion.groove_velocity * config.motion.duration
        g = np.where(touched, (limit - figures.increase_max) / limit, 1.0 + margin / scale)
        out["friction_exceedance"] = np.where(
            figures.resolved, g, np.where(figures.exceeds, 0.0, np.nan))
    return {event: out[event] for event in events}


class LimitState:
    """g(U) of one event of a study: a callable on (rows, d) arrays (Notes of
    :func:`event_values`).

    Attributes
    ----------
    config : StudyConfig
    event : str
        A name of :data:`EVENTS`.
    dimension : int
        d.
    smooth : bool
        Whether FORM may be tried (:func:`is_smooth`); then the event is a union of smooth
        components (:meth:`components`, :attr:`component_names`).
    units : str
        Of g.
    """

    def __init__(self, config, event):
        if event not in EVENTS:
            raise ValueError(f"event {event!r} is not one of {', '.join(EVENTS)}")
        if event not in study_events(config):
            raise ValueError(f"the study does not define the event {event!r}")
        self.config = config
        self.event = event
        self.dimension = dimension(config)
        self.smooth = is_smooth(config, event)
        self.units = EVENT_UNITS[event]
        self.component_names = component_names(config, event) if self.smooth else ()

    def _block(self, u):
        u = np.asarray(u, dtype=np.float64)
        return block_from_normals(self.config, u)

    def __call__(self, u):
        """g (rows,) [:attr:`units`]; failure where g <= 0, NaN unresolved."""
        if np.shape(u)[0] == 0:
            return np.empty(0)
        if self.smooth:  # the same numbers, without evaluating the other events
            return series(self.components(u))
        return event_values(self.config, self._block(u), (self.event,))[self.event]

    def components(self, u):
        """The components' g (rows, k) of a smooth event (:func:`component_values`)."""
        if not self.smooth:
            raise ValueError(f"the {self.event} limit state has no smooth components")
        if np.shape(u)[0] == 0:
            return np.empty((0, len(self.component_names)))
        return component_values(self.config, self._block(u), self.event)

    def component(self, k):
        """g of component k alone: a limit state for :func:`~tolsim.study.analyses.rare_events.
        find_design_point`."""
        return lambda u: self.components(u)[:, k]


# ---------------------------------------------------------------------------------------------
# running the estimators
# ---------------------------------------------------------------------------------------------

def event_seed(config, event) -> np.random.SeedSequence:
    """The SeedSequence of an event's estimator (Notes).

    Notes
    -----
    **Seeds.**
    The estimator of event e draws from ``SeedSequence(seed, spawn_key=(4, EVENT_KEYS[e]))``
    (:data:`RARE_EVENT_SPAWN_KEY`; the plain run uses (0, k) and (1, ...), the sensitivity
    analysis (2,) and (3,)), so the events' estimates are independent of each other and of the
    plain run, and reproducible. :mod:`tolsim.study.analyses.rare_events` adds its own stream key
    below.
    """
    return np.random.SeedSequence(config.study.seed,
                                  spawn_key=(RARE_EVENT_SPAWN_KEY, EVENT_KEYS[event]))


@dataclass(frozen=True, eq=False)
class DesignPointSummary:
    """The design point of importance sampling in the study's factors (Notes of
    :func:`design_point_summary`).

    Attributes
    ----------
    factors : tuple of str
        :func:`tolsim.study.analyses.sensitivity.study_factors`.
    kinds : tuple of str
        ``length`` [m] or ``angle`` [rad] per factor.
    value : ndarray (k,)
        The factor's value at u* [m or rad].
    standard_normal : ndarray (k,)
        u* of the column reported [-].
    element : ndarray of int (k,)
        The ball (track * n + ball), pair (track * (n - 1) + pair) or track of the value.
    importance_factor : ndarray (k,)
        Sum of alpha^2 over the factor's columns [-].
    component : str
        The component of the series event whose design point this is (``pair 3``).
    element_kinds : tuple of str
        What ``element`` counts per factor: ``ball``, ``pair`` or ``track``.
    """

    factors: tuple
    kinds: tuple
    value: np.ndarray
    standard_normal: np.ndarray
    element: np.ndarray
    importance_factor: np.ndarray
    component: str = ""
    element_kinds: tuple = ()

    def top(self, count=3) -> list:
        """(factor, value, kind, element, importance factor) of the ``count`` largest
        importance factors, largest first."""
        order = np.argsort(-self.importance_factor, kind="stable")[:count]
        return [(self.factors[i], float(self.value[i]), self.kinds[i], int(self.element[i]),
                 float(self.importance_factor[i])) for i in order]

    def describe(self, count=3, tracks=1) -> str:
        """The ``count`` largest contributors in words: ``arc_centre_offset_tangential_BL
        +0.575 um at ball 1 (57 %)`` (lengths in um, angles in deg)."""
        parts = []
        for i in np.argsort(-self.importance_factor, kind="stable")[:count]:
            value = self.value[i]
            text = (f"{1e6 * value:+.3g} um" if self.kinds[i] == "length"
                    else f"{np.degrees(value):+.3g} deg")
            where = self.element_kinds[i] if i < len(self.element_kinds) else ""
            if where and (where != "track" or tracks > 1):
                text += f" at {where} {int(self.element[i])}"
            parts.append(f"{self.factors[i]} {text} ({100 * self.importance_factor[i]:.0f} %)")
        return ", ".join(parts)


def _factor_columns(config) -> dict:
    """factor -> list of (column, element, what) over the columns of U (Notes of
    :func:`block_from_normals`);
    ``what``: ``assembly`` (per-assembly source, element = track), ``ball`` or ``gap``."""
    layout = column_layout(config)
    tracks = config.n_tracks
    out = {}
    for j, t in enumerate(per_assembly_sources(config)):
        first = layout["factors"].start + j * tracks
        out[t.source] = [(first + k, k, "assembly") for k in range(tracks)]
    for name, sl in layout.items():
        if name == "factors":
            continue
        factor = INITIAL_GAP if name in ("gap", "entering_gap") else name.removeprefix(
            "entering_")
        what = "gap" if factor == INITIAL_GAP else "ball"
        entering = name.startswith("entering_")
        out.setdefault(factor, []).extend(
            (c, -1 if entering else c - sl.start, what) for c in range(sl.start, sl.stop))
    return out


def design_point_summary(config, point, component="") -> DesignPointSummary:
    """Map a design point u* (d,) to the study's factors (Notes).

    Notes
    -----
    **The design point in physical units.**
    Importance sampling reports u* in the standard space. :func:`design_point_summary` maps it
    to the study's factors (:func:`tolsim.study.analyses.sensitivity.study_factors`: every random
    source,
    and the gaps): a source of one value per assembly gives its value at u*; a source with one
    value per ball (``ball`` sources, rail fields), per track or per gap gives the value of the
    element (ball, track or pair) whose column has the largest |u*| (u* is zero, to the
    solver's tolerance, in the columns that do not matter; its largest entries are the elements
    that fail), with that element's index. The importance factor of a factor is the sum of
    alpha_k^2 over its columns (of the independent xi for correlated sources, Cholesky order, as
    in the sensitivity analysis).
    """
    u = np.asarray(point, dtype=float)
    block = block_from_normals(config, u[None])
    values = error_values(config, block)
    columns = _factor_columns(config)
    alpha2 = (u / np.linalg.norm(u)) ** 2 if np.any(u) else np.zeros_like(u)
    balls = config.train.balls
    names = study_factors(config)
    value, normal, element, share, kinds, where = [], [], [], [], [], []
    for factor in names:
        cols = [c for c in columns[factor] if c[1] >= 0]
        index = np.array([c[0] for c in cols])
        best = cols[int(np.argmax(np.abs(u[index])))]
        column, at, what = best
        if what == "gap":
            value.append(float(block.initial_gap[0, at]))
            kinds.append("length")
        else:
            ball = at * balls if what == "assembly" else at
            value.append(float(values[factor][0, ball]))
            kinds.append(SOURCES[factor][0])
        normal.append(float(u[column]))
        element.append(at)
        where.append({"gap": "pair", "assembly": "track"}.get(what, "ball"))
        share.append(float(np.sum(alpha2[[c[0] for c in columns[factor]]])))
    return DesignPointSummary(tuple(names), tuple(kinds), np.array(value, dtype=float),
                              np.array(normal, dtype=float), np.array(element, dtype=np.int64),
                              np.array(share, dtype=float), component, tuple(where))


@dataclass(frozen=True, eq=False)
class EventEstimate:
    """What a rare-event estimator gave for one event of a study.

    Attributes
    ----------
    event : str
    requested : str
        The config's estimator.
    result : tolsim.study.analyses.rare_events.RareEventResult
        The estimate reported (flagged, without a number, when no estimator could back one).
    note : str
        One line when another estimator than the requested one gave ``result`` (importance
        sampling falling back to subset simulation), else "".
    design_point : DesignPointSummary or None
        Importance sampling's design point (of its most probable component) in the study's
        factors, when it gave a number (``importance``, ``rare``).
    components : SeriesDesignPoints or None
        Importance sampling: every component's design point and beta.
    seconds : float
        Wall time [s].
    parts : dict
        ``rare`` on a smooth event: ``subset`` and ``importance`` -> each estimator's
        RareEventResult, which ``result`` combines or sets side by side; on an event that is
        not smooth (:data:`REPLICATE_PARTS`) ``replicate_1`` and ``replicate_2`` -> the two
        subset simulation runs; empty otherwise.
    mode_check : str
        How subset simulation's number was checked for a lost failure mode:
        ``"design_points"`` against FORM design points
        (:func:`~tolsim.study.analyses.rare_events.subset.lost_modes`), ``"replicates"`` by
        the agreement of two independent runs (a limit state that is not smooth,
        :func:`~tolsim.study.analyses.rare_events.api.replicated_subset`: a mode one run
        finds and the other misses, not one both miss), ``"none"`` (unchecked: no design
        point found), "" when no subset simulation gave or checked the number.
    """

    event: str
    requested: str
    result: object
    note: str = ""
    design_point: DesignPointSummary | None = None
    components: SeriesDesignPoints | None = None
    seconds: float = 0.0
    parts: dict = field(default_factory=dict)
    mode_check: str = ""

    def describe(self) -> str:
        """One line: the event, the estimator and its number (or why there is none)."""
        line = f"{EVENT_TITLES[self.event]} by {self.result.describe()}"
        if self.note:
            line += f" [{self.note}]"
        if self.mode_check == MODE_CHECK_NONE:
            line += " [no FORM design points: unchecked for a lost failure mode]"
        elif self.mode_check == MODE_CHECK_REPLICATES:
            line += " [checked for a lost failure mode by two independent runs]"
        return line


def estimate_event(config, event, *, batch_size=None) -> EventEstimate:
    """Run the config's estimator on one event (Notes).

    ``importance`` tries FORM on a smooth limit state and falls back to subset simulation
    (same settings) when the limit state is not smooth or importance sampling gives no
    number, saying why in ``note``; a number flagged by a diagnostic is kept, not ok.
    ``rare`` runs both and combines them (:func:`~tolsim.study.analyses.rare_events.api.
    combine`); the two results are in :attr:`EventEstimate.parts`.

    Notes
    -----
    **Estimators.**
    ``subset``: :func:`~tolsim.study.analyses.rare_events.subset_simulation` on g, for every event.
    On a smooth series event FORM on its components comes first (:func:`checked_subset`), so
    that a failure mode the chains lost flags the number (``diagnostic_failed``) instead of
    leaving a wrong ``ok``. On the others (``along_track``, friction; with every estimator)
    there is no design point: subset simulation runs twice instead, from the two children of
    :func:`~tolsim.study.analyses.rare_events.api.estimator_seeds`, each at the configured
    samples per level (twice the cost of one run: at half size each run loses a mode more
    often, and on RPRepo's RP110 two half-size runs were no better than one full run), and
    :func:`~tolsim.study.analyses.rare_events.api.replicated_subset` gives their
    mean when both are ``ok`` and agree, else ``estimators_disagree`` with both numbers (the
    report's verdict undecided); :attr:`EventEstimate.mode_check` ``"replicates"``. This
    catches a failure mode that one run finds and the other misses; a mode that both miss
    (with a per-run miss probability q, about q^2 of the time; q grows as the runs shrink)
    gives two agreeing, wrong numbers and stays ``ok``. ``rare`` and the
    fallback of ``importance`` pass importance sampling's design points to subset simulation
    (no extra cost).
    ``importance``: on a smooth series event (``contact`` with ``constant`` propagation,
    ``velocity_deviation_exceedance``), FORM on *every component* and importance sampling from
    the mixture of the shifted normals around their design points
    (:func:`tolsim.study.analyses.rare_events.series_importance_sampling`). Around the one design
    point that FORM finds on g itself, the samples miss the other pairs' failure domains: on
    ``configs/rare_contact.toml`` that gave P(contact) = 1.8e-4 (95 % interval 1.6e-4 to 2.0e-4)
    for a true 1.18e-3, the pairs of the train having betas of 3.44 to 3.58. On the other events
    (``along_track``, friction) it is not attempted, and where FORM fails on a component, or no
    sample fails, subset simulation runs instead: each time :attr:`EventEstimate.note` says so
    in one line. An importance-sampling number that a diagnostic flags (``diagnostic_failed``)
    is kept, with its status and message (no fallback: the number is there to inspect).
    ``rare``: both, cross-checked by :func:`tolsim.study.analyses.rare_events.api.combine` (the
    rule of ``tolsim.rare_events.estimate(method="rare")``): their inverse-variance combination
    when both are ``ok`` and agree (:func:`~tolsim.study.analyses.rare_events.api.agree`),
    importance sampling's number when subset simulation lost a failure mode that explains the
    gap (:func:`~tolsim.study.analyses.rare_events.api.lost_mode_explains`), else
    both numbers (:attr:`EventEstimate.parts`) and status ``estimators_disagree`` (or the flag
    of the one that failed). They draw from independent streams, the two children that
    :func:`~tolsim.study.analyses.rare_events.api.estimator_seeds` spawns from the event's
    seed. Importance sampling runs at its configured size, subset simulation at half its own
    (:func:`rare_size`: the combined number is mostly importance sampling's, subset
    simulation cross-checks it), so that ``rare`` costs about what ``importance`` alone
    costs plus half a subset simulation (on ``configs/rare_contact.toml`` FORM on the
    components, 2 471 evaluations for the nine pairs, :mod:`~tolsim.study.analyses.
    rare_events.series_form`). Where importance
    sampling is not attempted (not smooth), the two replicates of ``subset`` stand in for it,
    with a note; where it gives no number,
    ``combine`` keeps subset simulation's with importance sampling's flag (not ``ok``).
    """
    st = config.study
    started = time.perf_counter()
    g = LimitState(config, event)
    seed = event_seed(config, event)

    # "rare": each estimator from its own spawned child of the event's seed, subset
    # simulation at half size when both run
    rare = st.estimator == "rare"
    sub_seed, imp_seed = estimator_seeds(seed) if rare else (seed, seed)

    def subset(per_level=st.samples_per_level, search=None):
        return subset_simulation(g, g.dimension, sub_seed, samples_per_level=per_level,
                                 p0=st.p0, max_levels=st.max_levels, batch_size=batch_size,
                                 design_points=None if search is None else
                                 search.design_points)

    note, design, components, parts = "", None, None, {}
    mode_check = MODE_CHECK_NONE
    if st.estimator in ("subset", "importance", "rare") and not g.smooth:
        # no design point: two independent full-size runs check each other
        result, runs = replicated_subset(
            g, g.dimension, seed, samples_per_level=st.samples_per_level,
            p0=st.p0, max_levels=st.max_levels, batch_size=batch_size)
        parts, mode_check = dict(zip(REPLICATE_PARTS, runs, strict=True)), MODE_CHECK_REPLICATES
        if st.estimator != "subset":
            why = ("along_track propagation gives a limit state that is not smooth (the "
                   "smallest gap over the time steps)" if is_along_track(config) else
                   "the friction limit state jumps where the balls start to touch")
            note = (f"importance sampling not attempted: {why}; subset simulation used (two "
                    "independent runs)")
    elif st.estimator == "subset":
        result, mode_check = checked_subset(g, sub_seed, samples_per_level=st.samples_per_level,
                                            p0=st.p0, max_levels=st.max_levels,
                                            batch_size=batch_size)
    elif st.estimator in ("importance", "rare"):
        search = series_design_points(g, batch_size=batch_size)
        result, components = series_importance_sampling(
            g, imp_seed, samples=st.importance_samples, batch_size=batch_size, design=search)
        mode_check = ""
        if np.isfinite(result.probability):
            design = design_point_summary(config, result.design_point,
                                          components.names[components.most_probable])
        checked = MODE_CHECK_DESIGN_POINTS if search.point_set.points else MODE_CHECK_NONE
        if st.estimator == "rare":
            parts = {"subset": subset(rare_size(st.samples_per_level, st.p0), search),
                     "importance": result}
            result = combine(parts["subset"], result)
            mode_check = checked
        elif design is None:
            note = f"{result.message}; subset simulation used instead"
            result, components = subset(search=search), None
            mode_check = checked
    else:
        raise ValueError(f"estimator = {st.estimator!r}: choose one of "
                         f"{', '.join(ESTIMATORS[1:])} (monte_carlo is the plain run)")
    return EventEstimate(event, st.estimator, result, note, design, components,
                         time.perf_counter() - started, parts, mode_check)


def checked_subset(limit_state, seed, *, batch_size=None, **options):
    """Subset simulation on a smooth series event, checked for a lost failure mode.

    FORM on every component first (:func:`~tolsim.study.analyses.rare_events.importance.
    series_design_points`), then :func:`~tolsim.study.analyses.rare_events.subset_simulation`
    with the accepted design points (its lost-mode check, :func:`~tolsim.study.analyses.
    rare_events.subset.lost_modes`: ``diagnostic_failed``) and the FORM cross-check of their
    total (:func:`~tolsim.study.analyses.rare_events.api.form_cross_check`:
    ``estimators_disagree``), as ``tolsim.rare_events.estimate(method="subset")`` does; the
    searches' evaluations are added to the result's.

    Parameters
    ----------
    limit_state : object
        A smooth series event: ``dimension``, ``component_names``, ``components(u)`` and
        ``__call__(u)`` (e.g. :class:`LimitState`).
    seed : numpy.random.SeedSequence
        Subset simulation's (FORM draws nothing).
    batch_size : int, optional
    **options
        Of :func:`~tolsim.study.analyses.rare_events.subset_simulation`.

    Returns
    -------
    (RareEventResult, mode check)
        The mode check ``"design_points"``, or ``"none"`` when FORM accepted no design point
        (then the number is unchecked for a lost mode).
    """
    search = series_design_points(limit_state, batch_size=batch_size)
    found = search.point_set
    result = subset_simulation(limit_state, limit_state.dimension, seed, batch_size=batch_size,
                               design_points=found.points, **options)
    return (form_cross_check(result, found),
            MODE_CHECK_DESIGN_POINTS if found.points else MODE_CHECK_NONE)


def rare_size(samples_per_level, p0):
    """Subset simulation's samples per level in ``estimator = "rare"``: half the configured
    number when that still gives a whole number of at least
    :data:`~tolsim.study.analyses.rare_events.MIN_CHAINS` chains that divides it, else the
    configured number."""
    half = samples_per_level // 2
    chains = round(half * p0)
    if chains >= MIN_CHAINS and abs(half * p0 - chains) <= 1e-9 * half and half % chains == 0:
        return half
    return samples_per_level


def estimate_events(config, *, batch_size=None, notify=None) -> dict:
    """:func:`estimate_event` for every event of the study (:func:`study_events`).

    Returns
    -------
    dict
        event -> EventEstimate, in :data:`EVENTS` order.
    """
    check_supported(config)
    out = {}
    for event in study_events(config):
        if notify is not None:
            notify(f"{ESTIMATOR_TITLES.get(config.study.estimator, config.study.estimator)} "
                   f"of {EVENT_TITLES[event]}")
        out[event] = estimate_event(config, event, batch_size=batch_size)
    return out
