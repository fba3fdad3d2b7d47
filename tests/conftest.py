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


SILVERBOX_TRAIN, SILVERBOX_TEST, SILVERBOX_ARROW = (40650, 105712), (105712, 127400), (0, 40575)


@pytest.fixture(scope="session")
def silverbox(request):
    """The Silverbox record (real data: an electronic Duffing oscillator, force input V1, output V2);
    skips when ../shared is not beside the checkout."""
    from negstiff.inference.measurement import load

    path = request.config.rootpath / "../shared/data/silverbox/SNLS80mV.mat"
    if not path.exists():
        pytest.skip("shared/ data not beside the repository")
    return load(path, columns="force=V1,z=V2", fs=610.35)


@pytest.fixture(scope="session")
def silverbox_fits(silverbox):
    """NSI and SINDy fitted with their defaults (refinement included) on the training part only, once
    per session: several test files check facts about the same fits."""
    from negstiff.inference.nsi import NSI
    from negstiff.inference.sindy import SINDy

    train = silverbox.segment(*SILVERBOX_TRAIN)
    return {"nsi": NSI().fit(train), "sindy": SINDy().fit(train)}


def silverbox_prediction_mv(model, m, part) -> float:
    """Free-run rms error [mV] over ``part`` of the Silverbox record, started from the measured state at
    the part's sample 50, the first one scored (the benchmark's protocol)."""
    from negstiff.inference.derivatives import state_derivatives
    from negstiff.inference.validation import free_run_rms

    seg = m.segment(*part)
    zs, v, _, _ = state_derivatives(seg.z, seg.fs, purpose="state")
    return 1e3 * free_run_rms(model, seg.segment(50, seg.n), x0=(zs[50], v[50]))
