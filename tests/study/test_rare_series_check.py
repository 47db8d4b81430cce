"""A study's subset simulation checked for a lost failure mode (issue 23), and FORM on the
components of a series event (tolsim.study.analyses.rare_events.series_form).

Where the numbers come from:

* **Two modes, one lost.** RP110 of RPRepo (Rozsas & Slobbe; ``benchmarks/reliability_problems.py``)
  written as a study's series event of two components, g1 = 0.85 - 0.1 x1 (x1 <= 3.5) else
  4 - x1 and g2 = 2.3 - x2 (x2 <= 2) else 0.5 - 0.1 x2: the event fails iff x1 >= 4 or
  x2 >= 5, P = 1 - Phi(4) Phi(5) = 3.20e-5 exactly. The mode x1 >= 4 holds 99 % of P but is
  150 times rarer than x2 >= 5 at the first thresholds, so subset simulation often returns the
  other mode's ~3e-7 with status ``ok`` (seeds 0 and 4-9 of the ten below: measured). That is
  what a study with ``estimator = "subset"`` returned before; with the check every such run
  is ``diagnostic_failed``.
* **Separate searches.** :func:`component_design_points` must find the same design points as
  :func:`find_design_point` on each component alone (betas to 1e-4: the looser SLSQP
  tolerance, 1e-5 in beta, plus margin), evaluating the origin's rows once.
* **Sparse components.** A series event in d = 16 whose components each depend on 3 columns,
  g_j = b_j - a_j . u (linear: beta_j = b_j / |a_j| exactly, Hasofer & Lind 1974) and a
  paraboloid b - u_k + kappa / 2 u_m^2 (A = 1 + beta kappa, Breitung 1984, as
  ``test_second_order_gives_sorm``): the design points to 1e-6 with fewer rows than full
  stencils. A column that the probe does not show must be caught at the end point
  (``verified_stencil``), the checks then on the full stencil.
* **configs/rare_contact.toml**: the nine pairs' design points as the full-stencil search
  finds them (its points, 5 793 rows, to 1e-4; betas to 1e-5), for at most 2 800 rows, the cost
  of the subset simulation they check (issue 23: the check within 2x of subset alone).
"""

from pathlib import Path

import numpy as np
import pytest
from scipy.special import ndtr

from tolsim.io.config import load_config
from tolsim.study.analyses import limit_state
from tolsim.study.analyses.rare_events import find_design_point, subset_simulation
from tolsim.study.analyses.rare_events.form import verified_stencil
from tolsim.study.analyses.rare_events.series_form import (
    SERIES_FTOL,
    component_design_points,
)

#: P of the two-mode series event (module docstring), exact.
TRUTH = float(1.0 - ndtr(4.0) * ndtr(5.0))


class TwoModes:
    """RP110 as a study's smooth series event (module docstring)."""

    dimension = 2
    component_names = ("x1 >= 4", "x2 >= 5")
    smooth = True

    def components(self, u):
        x1, x2 = u[:, 0], u[:, 1]
        return np.column_stack([np.where(x1 <= 3.5, 0.85 - 0.1 * x1, 4.0 - x1),
                                np.where(x2 <= 2.0, 2.3 - x2, 0.5 - 0.1 * x2)])

    def __call__(self, u):
        return limit_state.series(self.components(u))


def wrong(result):
    """``ok`` with a 95 % interval that misses the truth by more than a factor of 3."""
    return result.ok and (result.ci_upper < TRUTH / 3.0 or result.ci_lower > 3.0 * TRUTH)


def test_a_lost_mode_is_flagged_not_ok():
    g = TwoModes()
    unchecked, checked = [], []
    for s in range(10):
        seed = np.random.SeedSequence(s)
        # the study's subset before the check: no design points
        unchecked.append(subset_simulation(g, 2, seed, samples_per_level=1000))
        result, mode_check = limit_state.checked_subset(g, seed, samples_per_level=1000,
                                                        p0=0.1, max_levels=20)
        assert mode_check == limit_state.MODE_CHECK_DESIGN_POINTS
        checked.append(result)
    lost = [s for s, r in enumerate(unchecked) if wrong(r)]
    assert len(lost) >= 3, lost                  # the case the check is for does occur
    assert not [s for s, r in enumerate(checked) if wrong(r)]
    for s in lost:
        assert checked[s].status == "diagnostic_failed"
        assert "lost a failure mode" in checked[s].message
        # the same chains: the number is kept, FORM's rows are added to the cost
        assert checked[s].probability == unchecked[s].probability
        assert checked[s].evaluations > unchecked[s].evaluations
    # a run that kept both modes stays ok
    assert any(r.ok for r in checked)


def test_component_design_points_as_separate_searches():
    g = TwoModes()
    points, rows, nans = component_design_points(g.components, 2, 2)
    separate = [find_design_point(lambda u, k=k: g.components(u)[:, k], 2) for k in range(2)]
    assert nans == 0
    assert [p.converged for p in points] == [True, True]
    assert [p.beta for p in points] == pytest.approx([s.beta for s in separate], abs=1e-4)
    assert [p.beta for p in points] == pytest.approx([4.0, 5.0], abs=1e-4)
    # the origin's 2 d + 1 rows and the probe's d + 1 once, not once per component
    assert rows == 5 + 3 + sum(p.evaluations for p in points)
    assert rows < sum(s.evaluations for s in separate)


def test_component_design_points_report_a_failed_component():
    # the second component fails at the origin: flagged with its reason, the first found
    def components(u):
        return np.column_stack([3.0 - u[:, 0], -1.0 - u[:, 1]])
    points, _, _ = component_design_points(components, 2, 2)
    assert points[0].converged and points[0].beta == pytest.approx(3.0, abs=1e-4)
    assert not points[1].converged and "origin" in points[1].message


#: Sparse components in d = 16 (module docstring): (b_j, a_j over its 3 columns, columns).
SPARSE_DIMENSION = 16
SPARSE = [(3.0, [1.0, 0.5, -0.2], [0, 1, 2]), (3.5, [0.3, -1.0, 0.4], [3, 4, 5]),
          (4.0, [0.6, 0.6, 0.6], [6, 7, 8])]
BETA_P, KAPPA = 3.2, 0.2


def sparse_components(u):
    out = [b - u[:, c] @ np.array(a) for b, a, c in SPARSE]
    out.append(BETA_P - u[:, 9] + 0.5 * KAPPA * u[:, 10] ** 2)      # the paraboloid
    return np.column_stack(out)


def test_component_design_points_along_the_columns_each_depends_on():
    points, rows, nans = component_design_points(sparse_components, SPARSE_DIMENSION, 4)
    assert nans == 0 and all(p.converged for p in points)
    exact = [b / np.linalg.norm(a) for b, a, _ in SPARSE] + [BETA_P]
    assert [p.beta for p in points] == pytest.approx(exact, abs=1e-6)
    for (b, a, c), p in zip(SPARSE, points[:3], strict=True):
        a = np.array(a)
        assert_point = np.zeros(SPARSE_DIMENSION)
        assert_point[c] = b * a / (a @ a)                  # u* = beta alpha, on the plane
        assert np.abs(p.point - assert_point).max() < 1e-6
    # the diagonal of A (d - 1 > 12): the paraboloid's 1 + beta kappa along u_10 (Breitung),
    # 1 along the other tangent axes, which are not evaluated
    assert points[3].curvature_eigenvalues == pytest.approx(
        [1.0] * (SPARSE_DIMENSION - 2) + [1.0 + BETA_P * KAPPA], abs=1e-4)
    # the same points by full stencils cost more (each search its own origin rows here)
    full = [find_design_point(lambda u, k=k: sparse_components(u)[:, k], SPARSE_DIMENSION,
                              ftol=SERIES_FTOL) for k in range(4)]
    assert [p.beta for p in points] == pytest.approx([f.beta for f in full], abs=1e-6)
    assert rows < 0.6 * sum(f.evaluations for f in full)


def test_a_column_the_probe_missed_is_caught_at_the_end_point():
    # g depends on u_2 only beyond u_0 = 1 (not at the origin, not at the probe): at the end
    # point (3, 0, 0) it does, and the stencil must be the full one
    def g(u):
        return 3.0 - u[:, 0] - 0.5 * np.maximum(u[:, 0] - 1.0, 0.0) * u[:, 2]
    calls = [0]

    def values(rows):
        calls[0] += rows.shape[0]
        return g(rows)

    point = np.array([3.0, 0.0, 0.0])
    stencil, columns = verified_stencil(values, point, 1e-4, np.array([0, 1]))
    assert columns is None
    full = g(np.concatenate([point[None], point + 1e-4 * np.eye(3), point - 1e-4 * np.eye(3)]))
    assert np.array_equal(stencil, full)
    # where the structure holds, the two rows of the check and no more
    calls[0] = 0
    stencil, columns = verified_stencil(values, np.array([3.0, 0.0, 0.0]), 1e-4,
                                        np.array([0, 2]))
    assert columns is not None and calls[0] == 1 + 2 * 2 + 2
    assert np.array_equal(stencil, full)


def test_rare_contact_pairs_cost_less_than_the_chains_they_check():
    config = load_config(Path(__file__).resolve().parents[2] / "configs" / "rare_contact.toml")
    g = limit_state.LimitState(config, "contact")
    points, rows, nans = component_design_points(g.components, g.dimension, 9)
    assert nans == 0 and all(p.converged for p in points)
    assert rows <= 2800                   # measured 2 471 (5 793 with full stencils)
    full = [find_design_point(g.component(k), g.dimension, ftol=SERIES_FTOL)
            for k in range(9)]
    assert [p.beta for p in points] == pytest.approx([f.beta for f in full], abs=1e-5)
    assert max(np.abs(p.point - f.point).max() for p, f in zip(points, full, strict=True)) \
        < 1e-4
