"""negstiff: identification, model updating and uncertainty quantification of nonlinear
(bistable, negative-stiffness) oscillators.

The front door: everything a script needs is a name of this package, loaded on first use (PEP 562: the
command line's ``--help`` does not pay for the compiled simulator)::

    from negstiff import load, NSI, SINDy, Posterior

    rec = load("lab.csv", columns="base_acc=ACC,z=DISP", mass=0.2)
    nsi = NSI().fit(rec)
    print(nsi.model_, nsi.modal_)

The parts: ``negstiff.models`` (the physics: device, equation of motion, simulator, virtual rig),
``negstiff.inference`` (learning from data: loading, identification, updating, posteriors),
``negstiff.experiments`` (studies that write ``reports/``), and the ``negstiff`` command line.
"""

from __future__ import annotations

import importlib
from pathlib import Path as _Path

__version__ = "0.1.0"

# In a source checkout the parts are the top-level folders models/, inference/, experiments/ beside
# this one (the project's layout); installed, setuptools puts them inside this package. Let a
# checkout import as the installed package does (e.g. ``python -m pytest`` from the repository).
_here = _Path(__file__).resolve().parent
if not (_here / "models").is_dir() and (_here.parent / "models" / "__init__.py").is_file():
    __path__.append(str(_here.parent))  # noqa: F821 - a package's __path__

_EXPORTS = {
    # records
    "load": "negstiff.inference.record.measurement",
    "from_arrays": "negstiff.inference.record.measurement",
    "Measurement": "negstiff.inference.record.measurement",
    "pin_frame": "negstiff.inference.record.frame",
    "StructureRecord": "negstiff.inference.record.structure",
    "load_structure": "negstiff.inference.record.structure",
    "structure_from_arrays": "negstiff.inference.record.structure",
    # the physics
    "Model": "negstiff.models.equation",
    "Device": "negstiff.models.device",
    "Structure": "negstiff.models.structure",
    "load_system": "negstiff.models.device",
    "simulate": "negstiff.models.simulator",
    "Rig": "negstiff.models.rig",
    "nfrc": "negstiff.models.continuation",
    # learning from data
    "NSI": "negstiff.inference.estimators.nsi",
    "SINDy": "negstiff.inference.estimators.sindy",
    "Discrepancy": "negstiff.inference.estimators.discrepancy",
    "StructureNSI": "negstiff.inference.estimators.structure_id",
    "StructureSINDy": "negstiff.inference.estimators.structure_id",
    "StructureDiscrepancy": "negstiff.inference.estimators.structure_id",
    "StructurePosterior": "negstiff.inference.estimators.structure_posterior",
    "Posterior": "negstiff.inference.estimators.posterior.core",
    "GAUpdater": "negstiff.inference.estimators.updating",
    "characterize": "negstiff.inference.analysis.characterize",
    "frf": "negstiff.inference.analysis.frf",
    "Report": "negstiff.experiments.report",
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
