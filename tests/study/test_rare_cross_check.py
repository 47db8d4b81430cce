"""``[study] estimator = "rare"`` (issue 23): subset simulation and importance sampling on each
event, combined only when they agree, and numbers that their estimator does not back kept in
the study and the file with their status and message.

Where the numbers come from:

* **configs/rare_contact.toml** at small settings (1000 plain trains, 500 samples per level,
  1000 importance samples): P(contact) = 1.175e-3 by 3e6 plain trains
  (tests/study/test_rare_study.py). Both estimators are ``ok`` there and agree; the combined
  number is their inverse-variance mean (:func:`tolsim.study.analyses.rare_events.api.
  combine`, the rule of ``tolsim.rare_events.estimate(method="rare")``), so it lies between
  them, with a smaller standard error than either, and costs the sum of their evaluations.
* **A constructed disagreement**: subset simulation's number multiplied by 100 (monkeypatched)
  lies far outside importance sampling's interval: status ``estimators_disagree``, both
  numbers kept.
* **A constructed diagnostic failure**: importance sampling's result relabelled
  ``diagnostic_failed``: the ``importance`` study keeps its number (no fallback) with the
  status and the message.
"""

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from tolsim.io.config import ConfigError, parse_config, with_study_settings
from tolsim.io.netcdf import read_result, result_to_dataset, write_result
from tolsim.io.schema.rare_events import STATUS_FLAGS, status_flag
from tolsim.study.analyses import limit_state
from tolsim.study.analyses.rare_events import (
    STATUS_DIAGNOSTIC_FAILED,
    STATUS_ESTIMATORS_DISAGREE,
    STATUS_OK,
    series_importance_sampling,
    subset_simulation,
)
from tolsim.study.analyses.rare_events.api import agree, estimator_seeds
from tolsim.study.execution.runner import run_study

ROOT = Path(__file__).resolve().parents[2]
RARE = ROOT / "configs" / "rare_contact.toml"
#: P(contact) of rare_contact.toml: plain Monte Carlo over 3e6 trains.
RARE_CONTACT_REFERENCE = 1.175e-3


def with_estimator(lines):
    """rare_contact.toml's text with its ``estimator = "subset"`` line replaced."""
    return re.sub(r'^estimator = "subset"', lines, RARE.read_text(), flags=re.M)


def rare_config(estimator="rare", **settings):
    """rare_contact.toml with the estimator given and small settings."""
    config = parse_config(with_estimator(f'estimator = "{estimator}"'), str(RARE))
    settings = {"samples": 1000, "samples_per_level": 500, "sampling": "random", **settings}
    if estimator in ("importance", "rare"):  # the reader refuses it for subset
        settings.setdefault("importance_samples", 1000)
    return with_study_settings(config, **settings)


def times_100(*args, **kwargs):
    """Subset simulation with its number (and interval) 100 times too high."""
    r = subset_simulation(*args, **kwargs)
    return dataclasses.replace(r, probability=100 * r.probability,
                               standard_error=100 * r.standard_error,
                               ci_lower=100 * r.ci_lower, ci_upper=100 * r.ci_upper)


def flagged_importance(*args, **kwargs):
    """Importance sampling whose (unchanged) number a diagnostic flags."""
    r, design = series_importance_sampling(*args, **kwargs)
    return dataclasses.replace(r, status=STATUS_DIAGNOSTIC_FAILED,
                               message="constructed: a diagnostic failed"), design


@pytest.fixture(scope="module")
def rare():
    return run_study(rare_config())


@pytest.fixture(scope="module")
def disagreeing():
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(limit_state, "subset_simulation", times_100)
        return run_study(rare_config())


def test_the_estimators_agree_and_are_combined(rare):
    estimate = rare.rare_events["contact"]
    r, sub, imp = estimate.result, estimate.parts["subset"], estimate.parts["importance"]
    assert (sub.estimator, imp.estimator, r.estimator) == ("subset", "importance", "rare")
    assert sub.ok and imp.ok and agree(sub, imp)
    assert r.status == STATUS_OK and r.message == ""
    assert min(sub.probability, imp.probability) <= r.probability <= max(
        sub.probability, imp.probability)
    assert r.standard_error < min(sub.standard_error, imp.standard_error)
    assert r.evaluations == sub.evaluations + imp.evaluations
    assert r.ci_lower < RARE_CONTACT_REFERENCE < r.ci_upper
    # no unresolved row: the bounds and their interval are the combined estimate's
    assert r.unresolved == 0
    assert (r.bound_lower, r.bound_upper) == (r.probability, r.probability)
    assert (r.bounds_ci_lower, r.bounds_ci_upper) == (r.ci_lower, r.ci_upper)
    # each part is the number that estimator gives alone from its own child of the event's
    # seed (issue 23: independent streams), subset simulation at half samples_per_level
    config = rare.config
    g = limit_state.LimitState(config, "contact")
    sub_seed, imp_seed = estimator_seeds(limit_state.event_seed(config, "contact"))
    alone = {"subset": subset_simulation(g, g.dimension, sub_seed, samples_per_level=250,
                                         p0=config.study.p0),
             "importance": series_importance_sampling(g, imp_seed, samples=1000)[0]}
    for name, part in estimate.parts.items():
        assert alone[name].probability == part.probability
        assert alone[name].evaluations == part.evaluations
    same_seed = subset_simulation(g, g.dimension, limit_state.event_seed(config, "contact"),
                                  samples_per_level=250, p0=config.study.p0)
    assert same_seed.probability != sub.probability
    # the diagnostics of both are carried by the combined result
    assert r.effective_sample_size == imp.effective_sample_size and r.ancestors == sub.ancestors
    assert estimate.design_point is not None
    assert rare.rare_events["velocity_deviation_exceedance"].result.estimator == "rare"


def test_the_file_carries_status_diagnostics_and_both_numbers(rare, tmp_path):
    path = tmp_path / "rare.nc"
    write_result(rare, path, history="test")
    ds = read_result(path)
    estimate = rare.rare_events["contact"]
    r = estimate.result
    assert ds.attrs["estimator"] == "rare"
    assert ds.contact_probability.attrs["estimator"] == "rare"
    assert float(ds.contact_probability) == r.probability
    status = ds.contact_probability_status
    assert int(status) == status_flag(STATUS_OK) and status.attrs["units"] == "1"
    assert status.attrs["flag_meanings"].split() == list(STATUS_FLAGS.values())
    assert list(status.attrs["flag_values"]) == list(STATUS_FLAGS)
    assert float(ds.contact_probability_effective_sample_size) == r.effective_sample_size
    assert float(ds.contact_probability_largest_weight_share) == r.largest_weight_share
    assert float(ds.contact_probability_form_ratio) == r.form_ratio
    assert int(ds.contact_probability_ancestors) == r.ancestors
    assert float(ds.contact_probability_level_independent_coefficient_of_variation) == \
        r.level_independent_cv
    for name, part in estimate.parts.items():
        var = f"contact_probability_{name}"
        assert float(ds[var]) == part.probability and ds[var].attrs["units"] == "1"
        assert ds[var].attrs["estimator"] == name
        assert float(ds[f"{var}_ci_upper"]) == part.ci_upper
        assert int(ds[f"{var}_evaluations"]) == part.evaluations
        assert int(ds[f"{var}_status"]) == status_flag(part.status)
    for name in ds.data_vars:
        if name.startswith("contact_probability_"):
            assert ds[name].attrs.get("long_name"), name


def test_a_subset_file_carries_its_diagnostics(tmp_path):
    # a single estimator: its own diagnostics only
    result = run_study(rare_config("subset"))
    ds = result_to_dataset(result, history="t")
    r = result.rare_events["contact"].result
    assert int(ds.contact_probability_ancestors) == r.ancestors > 0
    assert "contact_probability_effective_sample_size" not in ds
    assert "contact_probability_subset" not in ds
    assert int(ds.contact_probability_status) == status_flag(r.status)


def test_a_disagreement_keeps_both_numbers(disagreeing, tmp_path):
    estimate = disagreeing.rare_events["contact"]
    r, sub, imp = estimate.result, estimate.parts["subset"], estimate.parts["importance"]
    assert sub.ok and imp.ok and not agree(sub, imp)
    assert r.status == STATUS_ESTIMATORS_DISAGREE and not r.ok
    assert np.isfinite(r.probability)
    assert f"{sub.probability:.3g}" in r.message and f"{imp.probability:.3g}" in r.message
    path = tmp_path / "disagree.nc"
    write_result(disagreeing, path, history="test")
    ds = read_result(path)
    assert int(ds.contact_probability_status) == status_flag(STATUS_ESTIMATORS_DISAGREE)
    assert ds.contact_probability.attrs["estimator_status"] == STATUS_ESTIMATORS_DISAGREE
    assert ds.contact_probability.attrs["estimator_message"] == r.message
    assert float(ds.contact_probability) == r.probability
    assert float(ds.contact_probability_subset) == sub.probability
    assert float(ds.contact_probability_importance) == imp.probability


def test_a_flagged_number_is_kept_with_its_status(monkeypatch):
    from tolsim.cli.run import summary

    monkeypatch.setattr(limit_state, "series_importance_sampling", flagged_importance)
    result = run_study(rare_config("importance"))
    estimate = result.rare_events["contact"]
    r = estimate.result
    assert r.estimator == "importance" and r.status == STATUS_DIAGNOSTIC_FAILED
    assert np.isfinite(r.probability) and estimate.note == ""  # no fallback
    ds = result_to_dataset(result, history="t")
    assert float(ds.contact_probability) == r.probability
    assert int(ds.contact_probability_status) == status_flag(STATUS_DIAGNOSTIC_FAILED)
    assert ds.contact_probability.attrs["estimator_message"] == r.message
    lines = summary(ds, "x.nc", 1.0).splitlines()
    at = next(i for i, x in enumerate(lines) if x.startswith("P(contact"))
    assert f" = {r.probability:.3g} by importance sampling" in lines[at]
    assert lines[at + 1] == f"  NOT OK (diagnostic_failed): {r.message}"


def test_rare_settings_in_the_config():
    config = parse_config(with_estimator('estimator = "rare"\nimportance_samples = 500'),
                          "r.toml")
    assert config.study.estimator == "rare" and config.study.importance_samples == 500
    with pytest.raises(ConfigError, match="importance_samples has no effect with estimator "
                                          "= 'subset'"):
        parse_config(with_estimator('estimator = "subset"\nimportance_samples = 500'), "r.toml")


def test_rare_falls_back_to_subset_where_importance_is_not_attempted():
    text = (ROOT / "configs" / "friction_yaw.toml").read_text()
    config = parse_config(text, "friction_yaw.toml")
    config = with_study_settings(config, samples=64, estimator="rare", samples_per_level=100,
                                 importance_samples=200, sampling="random")
    estimate = limit_state.estimate_event(config, "friction_exceedance")
    assert estimate.result.estimator == "subset"
    # no design point: two subset simulation runs check each other (issue 23)
    assert tuple(estimate.parts) == limit_state.REPLICATE_PARTS
    assert estimate.mode_check == limit_state.MODE_CHECK_REPLICATES
    assert estimate.note.startswith("importance sampling not attempted")
