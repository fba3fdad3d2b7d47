"""The physics of the device: what it is (geometry, equation of motion) and how it moves
(simulator, virtual test rig). ``models`` never imports ``inference``."""

from .constants import G
from .device import AS_BUILT, NOMINAL, SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC, Device, GeometryError
from .equation import EFFECTS, Model
from .simulator import SimulationResult, simulate, simulate_batch

__all__ = [
    "AS_BUILT",
    "EFFECTS",
    "G",
    "NOMINAL",
    "SEED_LIKE_CROSS_WELL_RMS",
    "SEED_LIKE_CUBIC",
    "Device",
    "GeometryError",
    "Model",
    "SimulationResult",
    "simulate",
    "simulate_batch",
]
