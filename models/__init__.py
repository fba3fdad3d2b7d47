"""The physics of the device: what it is (geometry, equation of motion) and how it moves
(simulator, virtual test rig). ``models`` never imports ``inference``."""

from .constants import G
from .device import AS_BUILT, NOMINAL, Device, GeometryError
from .equation import EFFECTS, Model
from .simulator import SimulationResult, simulate, simulate_batch

__all__ = [
    "AS_BUILT",
    "EFFECTS",
    "G",
    "NOMINAL",
    "Device",
    "GeometryError",
    "Model",
    "SimulationResult",
    "simulate",
    "simulate_batch",
]
