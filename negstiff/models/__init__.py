"""The physics of the device: what it is (geometry, equation of motion, extra effects) and how it
moves (simulator, virtual test rig). ``models`` never imports ``inference``.

Names are loaded on first use (PEP 562), so ``negstiff.models.effects`` (the effect registry the CLI's
help lists) comes without the compiled simulator.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "G": ".constants",  # negstiff.constants (the package's physical constants, below every layer)
    "AS_BUILT": "device",
    "NOMINAL": "device",
    "SEED_LIKE_CROSS_WELL_RMS": "device",
    "SEED_LIKE_CUBIC": "device",
    "Device": "device",
    "GeometryError": "device",
    "load_system": "device",
    "Model": "equation",
    "Equilibria": "equation",
    "Rig": "rig",
    "Sensors": "rig",
    "RigRecord": "records",
    "RigError": "records",
    "nfrc": "continuation",
    "ContinuationError": "continuation",
    "SimulationResult": "simulator",
    "simulate": "simulator",
    "simulate_batch": "simulator",
}

__all__ = ["effects", *_EXPORTS]


def __getattr__(name: str):
    if name == "effects":
        return importlib.import_module(".effects", __name__)
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
