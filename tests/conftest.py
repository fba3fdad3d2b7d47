"""Shared fixtures: small rig records (seconds, not minutes) reused across tests."""

import numpy as np
import pytest

from negstiff.models import AS_BUILT, Model
from negstiff.models.rig import Rig


@pytest.fixture(scope="session")
def cubic_model() -> Model:
    """A polynomial double-well model close to the as-built device (least-squares cubic)."""
    return AS_BUILT.lsq_cubic()


@pytest.fixture(scope="session")
def short_random_record():
    """A 30 s cross-well-level random record of the as-built device."""
    return Rig(seed=3).random(duration=30.0)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
