"""Shared fixtures: small rig records (seconds, not minutes) reused across tests.

The tests are grouped by what they check: ``contract/`` (the estimator contract, persistence, the package's
structure, the docs), ``models/`` (the physics: equation, device, laws, simulator, rig, continuation),
``records/`` (records as labs write them, read and checked), ``methods/`` (each identification, posterior and
workflow on records negstiff did not make, single DOFs and structures), ``cli/`` (the command line, its refusals
and outputs, the reports). The records they share are written by the helper modules here (``records``,
``impact_records``, ``law_records``) with plain numpy and scipy; ``data/`` holds the real public records.
"""

import os

import numpy as np
import pytest

from negstiff import datasets
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


@pytest.fixture(scope="session")
def silverbox():
    """The Silverbox record (real data: an electronic Duffing oscillator, force input V1, output V2),
    shipped with the package."""
    return datasets.silverbox()


@pytest.fixture(scope="session")
def silverbox_fits(silverbox):
    """NSI and SINDy fitted with their defaults (refinement included) on the training part only, once
    per session: several test files check facts about the same fits."""
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.estimators.sindy import SINDy

    train = silverbox.segment(*silverbox_study.TRAIN)
    return {"nsi": NSI().fit(train), "sindy": SINDy().fit(train)}


UNIT_TIER = {
    "test_equation.py",
    "test_device.py",
    "test_measurement.py",
    "test_measurement_properties.py",
    "test_structure.py",
    "test_simulator.py",
    "test_shooting.py",
    "test_rig.py",
    "test_estimator.py",
    "test_formats.py",
    "test_bad_inputs_commands.py",
}
"""The fast unit tier (about 40 s on 2 cores): the physics' building blocks, records and their errors, the
estimators' contract, the command line's refusals. ``pytest -m unit`` runs it alone; a full run runs it
first, so a broken building block shows before the studies that use it."""


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.path.name in UNIT_TIER:
            item.add_marker(pytest.mark.unit)
    items.sort(key=lambda item: item.path.name not in UNIT_TIER)  # stable: the unit tier first, in its order


def pytest_configure(config):
    """Under pytest-xdist the worker processes are the parallelism, as reproduce's section processes are
    (``resources.worker_initializer``): BLAS on one thread in each, and negstiff's own threads on the worker's
    share of the cores, not every worker on every core."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    if workers > 1 and hasattr(config, "workerinput"):
        from negstiff.resources import usable_cores, worker_initializer

        worker_initializer(threads=max(1, usable_cores() // workers))
        # each worker compiles its share of the kernels first (or loads them from numba's cache), in place of
        # each compiling every kernel its first tests need, the two at times the same one (on an empty cache the
        # suite took 423 s against 448 s, measured)
        from negstiff.experiments.reproduce import ALL_KERNELS, warm_kernel

        index = int(config.workerinput["workerid"].removeprefix("gw"))
        for name in ALL_KERNELS[index::workers]:
            warm_kernel(name)
