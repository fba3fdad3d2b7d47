"""The virtual shaking table with a structure on it: the single-DOF rig's measurement chain, one laser per DOF.

The table's true motion, the accelerometer on the table (noise, DC bias), the delta-sigma front end
(linear-phase FIR anti-aliasing, decimation) and the lab's double integration of the table's acceleration are
those of ``models.rig`` (``Sensors``); each DOF carries a laser measuring its absolute displacement y_i = z_i + b
(white noise ``Sensors.laser_noise``), and z_i = y_i - b_est as the reference study derives it. Two campaigns
name the structures the issue asks for: the device on a flexible fixture, and the device carrying a payload.

Every random draw comes from ``numpy.random.SeedSequence(seed)`` (the excitation and the sensors: independent
streams); the same seed gives the same record.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import signal

from negstiff.files import atomic_path

from .device import SEED_LIKE_CUBIC
from .equation import Model
from .records import RigError
from .rig import Sensors
from .simulator import antialias_fir
from .structure import Structure, simulate_structures
from .table import integrate_twice, table_motion


@dataclass(frozen=True)
class StructureRigRecord:
    """A structure's record: ``columns`` (t, base_acc, z1 ... zN), ``meta`` (fs, masses, ...), ``truth`` (the
    structure, sensors, excitation, seed) and the true responses ``true`` (z (N, T), base_acc).
    """

    fs: float
    columns: dict[str, np.ndarray]
    meta: dict[str, str]
    truth: dict[str, Any]
    true: dict[str, np.ndarray] = field(repr=False)

    @property
    def z(self) -> np.ndarray:
        """The measured responses (N, T)."""
        n = sum(1 for k in self.columns if k.startswith("z"))
        return np.array([self.columns[f"z{i + 1}"] for i in range(n)])

    def write(self, path: str | Path) -> Path:
        """The contract's multi-DOF CSV (``# masses:`` and ``# fs:`` in the header), written atomically."""
        path = Path(path)
        head = "".join(f"# {k}: {v}\n" for k, v in self.meta.items()) + ",".join(self.columns) + "\n"
        rows = np.column_stack(list(self.columns.values()))
        with atomic_path(path) as tmp:
            with open(tmp, "w") as fh:
                fh.write(head)
                np.savetxt(fh, rows, delimiter=",", fmt="%.10g")
        return path


class StructureRig:
    """The virtual shaking table carrying a ``Structure`` (module docstring).

    Parameters
    ----------
    structure : Structure
        The truth.
    sensors : Sensors, optional
        The measurement chain (the single-DOF rig's; ``response`` must be ``"displacement"``: a laser per DOF).
    fs : float, default 512
        Output rate [Hz].
    oversample : int, default 4
        Simulation and acquisition rate = ``oversample * fs``.
    seed : int, default 0
        Root of every random draw.

    Examples
    --------
    >>> from negstiff.models.structure_rig import StructureRig
    >>> rig = StructureRig.device_on_fixture(seed=1)
    >>> rec = rig.random(duration=10.0, rms=14.0)
    >>> sorted(rec.columns), rec.meta["masses"]
    (['base_acc', 't', 'z1', 'z2'], '1,0.212')
    """

    def __init__(self, structure: Structure, *, sensors: Sensors | None = None, fs: float = 512.0,
                 oversample: int = 4, seed: int = 0):  # fmt: skip
        sensors = Sensors() if sensors is None else sensors
        if sensors.response != "displacement":
            raise RigError("a structure's rig measures every DOF with a laser (Sensors(response='displacement'))")
        if not (fs > 0 and math.isfinite(fs)) or int(oversample) < 1:
            raise RigError(f"sampling rate must be positive and oversample >= 1, got {fs}, {oversample}")
        self.structure, self.sensors, self.fs, self.oversample, self.seed = (
            structure, sensors, float(fs), int(oversample), int(seed))  # fmt: skip

    @classmethod
    def device_on_fixture(cls, device: Model = SEED_LIKE_CUBIC, *, fixture_mass: float = 1.0,
                          fixture_hz: float = 25.0, fixture_zeta: float = 0.02, **kw) -> StructureRig:  # fmt: skip
        """The device on a shaker fixture that is not rigid (DOF 1, sprung to the table; the device's mass DOF 2)."""
        s = Structure.on_fixture(device, fixture_mass=fixture_mass, fixture_hz=fixture_hz, fixture_zeta=fixture_zeta)
        return cls(s, **kw)

    @classmethod
    def device_with_payload(cls, device: Model = SEED_LIKE_CUBIC, *, payload_mass: float = 0.1,
                            payload_hz: float = 30.0, payload_zeta: float = 0.01, **kw) -> StructureRig:  # fmt: skip
        """The device (DOF 1, the element on the table) carrying a payload on a spring and damper (DOF 2):
        ``payload_hz`` and ``payload_zeta`` of the payload alone on its spring.
        """
        k = payload_mass * (2 * math.pi * payload_hz) ** 2
        c = 2 * payload_zeta * math.sqrt(k * payload_mass)
        s = Structure.chain((device.m, payload_mass), (0.0, k), (0.0, c), device, (0, 1))
        return cls(s, **kw)

    def random(self, duration: float = 300.0, rms: float = 14.0, band: tuple[float, float] = (2.0, 40.0),
               settle: float = 5.0, start: str = "plus") -> StructureRigRecord:  # fmt: skip
        """Band-limited Gaussian random table acceleration (``rms`` m/s^2 over ``band`` Hz), from rest in a well."""
        if not (duration > 0 and rms >= 0 and 0 <= band[0] < band[1] and settle >= 0):
            raise RigError(f"random excitation: duration {duration}, rms {rms}, band {band}, settle {settle}")
        s, q = self.sensors, self.oversample
        fsim = self.fs * q
        n = int(round((duration + settle + 4.0) * self.fs)) * q
        exc, sens = (np.random.default_rng(x) for x in np.random.SeedSequence(self.seed).spawn(2))
        spec = np.fft.rfft(exc.standard_normal(n))
        f = np.fft.rfftfreq(n, 1 / fsim)
        spec[(f < band[0]) | (f > band[1])] = 0.0
        acc = np.fft.irfft(spec, n)
        acc *= rms / acc.std()
        b_true, acc_true = table_motion(acc, fsim, s.table_min_hz)
        eq = self.structure.equilibria()
        if start not in eq:
            raise RigError(f"starting well must be one of {sorted(eq)}, got {start!r}")
        x0 = np.r_[eq[start], np.zeros(self.structure.n_dof)]
        sim = simulate_structures(self.structure, acc_true, 1 / fsim, x0)
        if sim.diverged.any():
            raise RigError(f"the structure did not survive the excitation: {sim.describe_failures()}")
        chans = {"base_acc": acc_true + s.acc_bias + s.acc_noise * math.sqrt(q) * sens.standard_normal(n)}
        for i in range(self.structure.n_dof):
            chans[f"y{i + 1}"] = sim.z[0, i] + b_true + s.laser_noise * math.sqrt(q) * sens.standard_normal(n)
        true = {"base_acc": acc_true, **{f"z{i + 1}": sim.z[0, i] for i in range(self.structure.n_dof)}}
        if q > 1:
            fir = antialias_fir(q)
            chans = {k: signal.resample_poly(v, 1, q, window=fir) for k, v in chans.items()}
            true = {k: signal.resample_poly(v, 1, q, window=fir) for k, v in true.items()}
        b_est = integrate_twice(chans["base_acc"], self.fs, s.highpass_hz, s.integration)
        k0 = int(round(settle * self.fs))
        sl = slice(k0, k0 + int(round(duration * self.fs)))
        cols = {"t": np.arange(sl.stop - sl.start) / self.fs, "base_acc": chans["base_acc"][sl]}
        for i in range(self.structure.n_dof):
            cols[f"z{i + 1}"] = chans[f"y{i + 1}"][sl] - b_est[sl]
        meta = {
            "fs": f"{self.fs:g}",
            "masses": ",".join(f"{m:g}" for m in self.structure.masses),
            "element": "-".join(map(str, self.structure.place)),
            "units": "SI (s, m/s^2, m)",
            "source": f"negstiff virtual structure rig (random, seed {self.seed})",
        }
        truth = {
            "structure": self.structure.to_dict(),
            "sensors": asdict(s),
            "fs": self.fs,
            "oversample": q,
            "seed": self.seed,
            "excitation": {
                "type": "random",
                "duration_s": duration,
                "rms_m_s2": rms,
                "band_hz": list(band),
                "settle_s": settle,
                "start_well": start,
            },  # fmt: skip
        }
        return StructureRigRecord(self.fs, cols, meta, truth, {k: v[sl] for k, v in true.items()})
