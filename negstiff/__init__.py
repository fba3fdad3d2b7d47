"""negstiff: identification, model updating and uncertainty quantification of nonlinear
(bistable, negative-stiffness) oscillators.

The front door: everything a script needs is a name of this package, loaded on first use (PEP 562: the
command line's ``--help`` does not pay for the compiled simulator)::

    from negstiff import load, NSI, SINDy, Posterior

    rec = load("lab.csv", columns="base_acc=ACC,z=DISP", mass=0.2)
    nsi = NSI().fit(rec)
    print(nsi.model_, nsi.modal_)

The parts, each a folder of this package: ``negstiff.io`` (the lab's file formats), ``negstiff.models``
(the physics: device, equation of motion, simulator, virtual rig), ``negstiff.inference`` (learning from
data: records, identification, updating, posteriors), ``negstiff.report`` (reports from results, the
``negstiff report`` engine), ``negstiff.cli`` (the command line) and ``negstiff.experiments`` (the reference
study reproduced, which only the command line's ``reproduce`` imports). The developers' benchmarks are
outside the package (``benchmarks/`` of the repository).
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"


_EXPORTS = {
    # records
    "load": "negstiff.inference.record.reading",
    "from_arrays": "negstiff.inference.record.measurement",
    "Measurement": "negstiff.inference.record.measurement",
    "pin_frame": "negstiff.inference.steps.frame",
    # the physics
    "Model": "negstiff.models.equation",
    "Device": "negstiff.models.device",
    "Structure": "negstiff.models.structure",
    "StateSpaceStructure": "negstiff.models.state_space",  # a structure read through its sensors, masses unknown
    "load_system": "negstiff.models.device",
    "simulate": "negstiff.models.simulator",
    "Rig": "negstiff.models.rig",
    "nfrc": "negstiff.models.continuation",
    # learning from data
    "NSI": "negstiff.inference.estimators.nsi",
    "SINDy": "negstiff.inference.estimators.sindy",
    "Discrepancy": "negstiff.inference.estimators.discrepancy",
    "Posterior": "negstiff.inference.estimators.posterior.core",
    "GAUpdater": "negstiff.inference.estimators.updating",
    "fit_many": "negstiff.inference.estimators.many",  # every estimator on many records, serially or on dask
    "characterise": "negstiff.inference.analysis.characterise",
    "characterize": "negstiff.inference.analysis.characterise",  # the first spelling, kept: ``characterise``
    "frf": "negstiff.inference.analysis.frf",
    "backbone": "negstiff.inference.analysis.backbone",  # a decay's backbones, measured and a model's
    "design": "negstiff.inference.analysis.design",  # the test to run next, from a posterior
    "separation": "negstiff.inference.analysis.separation",  # the test that tells two effects apart
    "Report": "negstiff.report.document",
    "Identification": "negstiff.inference.estimators.identification",
    # errors and warnings
    "InputError": "negstiff.errors",
    "OutputError": "negstiff.errors",
    "NegstiffWarning": "negstiff.errors",
    "NotFittedError": "negstiff.errors",
    "MeasurementError": "negstiff.errors",
}

__all__ = [*_EXPORTS, "__version__"]


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(_EXPORTS[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
