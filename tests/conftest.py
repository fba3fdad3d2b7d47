"""Shared fixtures: small rig records (seconds, not minutes) reused across tests."""

import numpy as np
import pytest

from negstiff.experiments import silverbox as silverbox_study
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


# the benchmark's split and protocol, from the one Silverbox module (experiments/silverbox.py)
SILVERBOX_TRAIN, SILVERBOX_TEST, SILVERBOX_ARROW = silverbox_study.TRAIN, silverbox_study.TEST, silverbox_study.ARROW


@pytest.fixture(scope="session")
def silverbox():
    """The Silverbox record (real data: an electronic Duffing oscillator, force input V1, output V2),
    shipped with the package."""
    return silverbox_study.load_silverbox()


@pytest.fixture(scope="session")
def silverbox_fits(silverbox):
    """NSI and SINDy fitted with their defaults (refinement included) on the training part only, once
    per session: several test files check facts about the same fits."""
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.estimators.sindy import SINDy

    train = silverbox.segment(*SILVERBOX_TRAIN)
    return {"nsi": NSI().fit(train), "sindy": SINDy().fit(train)}


def silverbox_prediction_mv(model, m, part) -> float:
    """Free-run rms error [mV] over ``part`` of the Silverbox record (the benchmark's protocol:
    ``experiments.silverbox.prediction_error_mv``)."""
    return silverbox_study.prediction_error_mv(model, m, part)
