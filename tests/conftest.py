import os

import numpy as np
import pytest
from hypothesis import settings

# Deterministic property tests: CI must not flake, and a failure must reproduce.
settings.register_profile("tolsim", derandomize=True, deadline=None, max_examples=60)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "tolsim"))


@pytest.fixture
def rng():
    return np.random.default_rng(20181109)
