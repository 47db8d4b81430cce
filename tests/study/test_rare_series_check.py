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
"""

import numpy as np
import pytest
from scipy.special import ndtr

from tolsim.study.analyses import limit_state
from tolsim.study.analyses.rare_events import find_design_point, subset_simulation
from tolsim.study.analyses.rare_events.series_form import component_design_points

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
    # the origin's 2 d + 1 rows once, not once per component
    assert rows == 5 + sum(p.evaluations for p in points)
    assert rows < sum(s.evaluations for s in separate)


def test_component_design_points_report_a_failed_component():
    # the second component fails at the origin: flagged with its reason, the first found
    def components(u):
        return np.column_stack([3.0 - u[:, 0], -1.0 - u[:, 1]])
    points, _, _ = component_design_points(components, 2, 2)
    assert points[0].converged and points[0].beta == pytest.approx(3.0, abs=1e-4)
    assert not points[1].converged and "origin" in points[1].message
