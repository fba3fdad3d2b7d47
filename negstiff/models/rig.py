"""Virtual test rig: the reference study's shaking-table campaign on a device whose truth is known.

What the laboratory of the reference study (section 3) measures, and how this rig reproduces it:

* the table moves the frame's base by b(t); the true table motion is band-limited (no content
  below ``Sensors.table_min_hz``), and its acceleration b'' is what drives the device;
* the device (the as-built ``Device`` with its exact geometric K(z), or a polynomial ``Model`` when
  the coefficients must exist exactly), or a ``Structure`` of N DOFs carrying the device as its element (on a
  fixture, under a payload: ``Rig.device_on_fixture``, ``Rig.device_with_payload``), is simulated at
  ``oversample`` times the output rate, with the suite's one input convention (linear interpolation between the
  fine samples);
* an accelerometer measures b'' (white noise, a small DC bias); a laser vibrometer measures the
  absolute displacement y = z + b (white noise), one per DOF on a structure (each DOF its own sensor, of the
  kind ``Sensors.response`` names);
* a delta-sigma acquisition front end low-passes every channel with the same linear-phase FIR
  anti-aliasing filter (delay compensated) and decimates to ``fs``;
* as in the reference study, the base displacement is not measured: it is the double integral of the measured
  acceleration, band-limited below ``Sensors.highpass_hz`` so that bias and noise do not make it run
  away; it is imperfect at low frequency and at the record's ends, and z = y - b_est inherits that;
* settling time is discarded; the mass is weighed on a scale (``weigh_resolution``).

Everything random draws from ``numpy.random.SeedSequence(seed)``, split into independent streams
for the excitation and for each sensor: the same seed gives the same record, bit for bit.
Every record carries its truth (system, effects, sensors, excitation, seed), written beside it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy import fft as sp_fft
from scipy import signal

from negstiff.errors import InputError

from . import effects as effect_registry
from .device import AS_BUILT, SEED_LIKE_CUBIC, Device
from .equation import Model
from .records import RigError, RigRecord
from .simulator import antialias_fir, simulate_batch
from .structure import Structure, simulate_structures
from .table import integrate_twice, table_motion

TAIL_S = 4.0
"""Seconds acquired after the last record and discarded, as the settling time is before it: the
double integration's end effects stay out of the records."""
RAMP_DOWN_S = 3.0
"""A sine test's ramp-down to rest [s], within the discarded tail (``_ended``)."""
RAMP_UP_S = 2.0
"""A sine test's ramp-up from rest [s] where its first settling time allows (``_ramp_up``)."""


def _ramp_up(period_s: float, settle_s: float, fsim: float) -> int:
    """Samples of a sine test's first ramp-up from rest: ``RAMP_UP_S``, within half the first settling time, and
    two periods at least. A two-period ramp set the table moving slowly where the lab's integral (high-passed at
    1 Hz) cannot see: a 10 s record of a 9 Hz, 10 m/s^2 harmonic after ten settling periods read z 0.078 mm off,
    2.7 times the laser's noise (measured).
    """
    return int(round(max(2 * period_s, min(RAMP_UP_S, 0.5 * settle_s)) * fsim))


@dataclass(frozen=True)
class Sensors:
    """The measurement chain's imperfections (SI units; noise as rms at the output rate)."""

    laser_noise: float = 30e-6
    """Laser vibrometer displacement noise [m rms] (about 1 % of an in-well response)."""
    acc_noise: float = 0.005
    """Accelerometer noise [m/s^2 rms], sensor, cabling and acquisition together: about 10x the
    broadband floor of a lab ICP accelerometer (~5e-4 m/s^2), conservative. It matters through the
    double integration: at 0.03 m/s^2 the integrated base displacement erred by 28 um rms and
    biased the soft well's NSI frequency by 3.5 %."""
    acc_bias: float = 0.02
    """Accelerometer DC bias [m/s^2]; double integration turns it into drift of b_est."""
    highpass_hz: float = 1.0
    """Low-frequency limit of the double integration [Hz], set (as a careful lab does) below the
    excitation band (2-40 Hz): accelerometer noise integrated twice grows as 1/f^4."""
    integration: str = "fft"
    """How the lab double-integrates the acceleration: ``"fft"`` (exact 1/(i w)^2 above
    ``highpass_hz``, cosine taper down to half of it, nothing below) or ``"time"`` (trapezoidal
    integration twice, each followed by a zero-phase 4th-order Butterworth high-pass at
    ``highpass_hz``). Measured on a 300 s cross-well record: the time-domain route removes ~0.8 % of
    the table motion at the 2 Hz band edge, an error correlated with the input (corr 0.73 with the
    true b) that biased the soft well's NSI frequency by ~3 %; see the report."""
    table_min_hz: float = 0.5
    """The table's true motion has no content below this frequency [Hz]."""
    response: str = "displacement"
    """The response sensor, as labs have them: ``"displacement"`` (the reference study's laser on y, the base
    double-integrated, z = y - b: columns y, base_disp, z), ``"velocity"`` (a laser Doppler
    vibrometer on the moving part, relative to the base: z_dot), ``"absolute"`` (the laser's y alone:
    the user derives the base), ``"accelerometer"`` (an accelerometer on the moving part: y_acc)."""
    velocity_noise: float = 1e-4
    """Vibrometer velocity noise [m/s rms] (~0.05 % of a cross-well response's velocity)."""
    response_offset: float = 0.0
    """DC offset of the response sensor, in its units (a laser zero away from the rods-horizontal
    position [m], a vibrometer's offset [m/s], an accelerometer's bias [m/s^2])."""
    force_noise: float = 0.05
    """The impact hammer's load cell noise [N rms] (``Rig.hammer``): a modal hammer's, about 0.1 % of a light
    hit's peak."""

    @classmethod
    def noiseless(cls) -> Sensors:
        """Perfect sensors (no noise, no bias): for checks that need the exact response."""
        return cls(laser_noise=0.0, acc_noise=0.0, acc_bias=0.0, velocity_noise=0.0, force_noise=0.0)


def system_from_dict(d: dict[str, Any]) -> Device | Model | Structure:
    """Rebuild the truth's system (``{"kind": "device"|"polynomial"|"structure", "parameters": {...}}``)."""
    if d["kind"] == "structure":
        return Structure.from_dict(d["parameters"])
    return Device.from_dict(d["parameters"]) if d["kind"] == "device" else Model.from_dict(d["parameters"])


def response_column(sensor: str, dof: int, n_dof: int) -> str:
    """The contract's column of a response ``sensor`` (``z``, ``z_dot``, ``y``, ``y_acc``) of DOF ``dof`` (1..N):
    a single DOF's own name, a structure's with its DOF's number (``z2``, ``y1_acc``).
    """
    if n_dof == 1:
        return sensor
    head, _, tail = sensor.partition("_")
    return f"{head}{dof}" + (f"_{tail}" if tail else "")


def _smooth_steps(levels: Sequence[float], step_samples, ramp_samples, start: float = 0.0) -> np.ndarray:
    """Piecewise-constant profile, level i held for ``step_samples`` (one count, or one per level), each
    change (from ``start`` into the first level, then between levels) a raised-cosine transition of
    ``ramp_samples`` (one count, or one per level) at the start of its level.
    """
    lv = np.asarray(levels, float)
    steps = np.broadcast_to(np.asarray(step_samples, int), lv.shape)
    ramps = np.broadcast_to(np.asarray(ramp_samples, int), lv.shape)
    env = np.repeat(lv, steps)
    prev = np.concatenate([[start], lv[:-1]])
    for a0, a1, s, r in zip(prev, lv, np.concatenate([[0], np.cumsum(steps)[:-1]]), ramps, strict=False):
        ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(r) / r)
        env[s : s + r] = a0 + (a1 - a0) * ramp
    return env


def _ended(env: np.ndarray, n_total: int, ramp_samples: int) -> np.ndarray:
    """``env`` held at its last level up to ``n_total`` samples, then brought to zero by a raised cosine over its
    last ``ramp_samples``, as a shaker controller ends a sine test (its ramp-down). The table's motion is the FFT's
    periodic integral of the drive (``table.table_motion``): a drive that stopped at full amplitude and wrapped to
    its silent start carried a slow table motion below the lab's integration high-pass, so the lab's z (laser minus
    the table accelerometer's double integral) was off by millimetres (a 9 Hz harmonic at 10 m/s^2: 0.68 mm rms,
    23 times the laser's noise; a 2-40 Hz sweep at 10 m/s^2: 4.7 mm; measured).
    """
    out = np.pad(env, (0, n_total - env.size), mode="edge")
    r = min(ramp_samples, n_total - env.size)
    out[n_total - r :] *= 0.5 + 0.5 * np.cos(np.pi * np.arange(r) / r)
    return out


BYTES_PER_SAMPLE = 200
"""Memory the rig holds per simulated sample of one run (its excitation, table motion, states and sensor
channels at the simulation rate, and their FFTs): measured 200 on a 300 s random record, 72 on a campaign."""


def _element(system: Device | Model | Structure) -> Device | Model:
    """The system's nonlinear part: a single DOF's law, a structure's element."""
    return system.element if isinstance(system, Structure) else system


def _with_effects(system: Device | Model | Structure, effects: Mapping[str, Any]) -> Device | Model | Structure:
    """``system`` with the extra ``effects`` added to its nonlinear part (``_element``)."""
    if isinstance(system, Structure):
        el = system.element
        return system.with_element(Model.from_dict({**el.to_dict(), "extra": {**dict(el.extra), **effects}}))
    if isinstance(system, Model):
        return type(system).from_dict({**system.to_dict(), "extra": {**dict(system.extra), **effects}})
    return system.with_(extra={**dict(system.extra), **effects})


def _real(x) -> bool:
    """A real number (not a flag, not text)."""
    return not isinstance(x, bool) and isinstance(x, (int, float, np.integer, np.floating))


class Rig:
    """The virtual shaking table with a device on it: records measured as a lab measures them.

    Parameters
    ----------
    system : Device, Model or Structure, default AS_BUILT
        The truth: a ``Device`` (the as-built device, exact geometry), a polynomial ``Model``, or a ``Structure`` of
        N DOFs (its element a polynomial ``Model``): every excitation drives any of them, and each DOF of a
        structure carries its own response sensor (columns ``z1 ... zN``, or ``zK_dot``, ``yK``, ``yK_acc``).
    effects : dict, optional
        Hidden extra effects added to the truth (``models.effects`` names and values; a structure's: its
        element's).
    sensors : Sensors, optional
        The measurement chain: noise, bias, integration, the response sensor (``models.rig.Sensors``).
    fs : float, default 512
        Output sampling rate [Hz] (the reference study's).
    oversample : int, default 4
        Simulation and acquisition rate = ``oversample * fs``.
    seed : int, default 0
        Root of every random draw (same seed, same record).
    weigh_resolution : float or None, default 1e-4
        Resolution of the scale that weighs the moving mass [kg] (None: not weighed).

    Examples
    --------
    >>> from negstiff import Rig
    >>> rec = Rig(seed=1).random(duration=30.0, rms=14.0)      # cross-well random motion
    >>> sorted(rec.columns)
    ['base_acc', 'base_disp', 't', 'y', 'z']
    >>> h = Rig(seed=1).harmonic(freq=9.0, amplitude=5.0)         # a steady-state 9 Hz response
    >>> rec.truth["system"]["kind"]
    'device'
    >>> fixture = Rig.device_on_fixture(seed=1).random(duration=10.0)     # the device on a sprung fixture
    >>> sorted(fixture.columns), fixture.meta["masses"]
    (['base_acc', 't', 'z1', 'z2'], '1,0.212')
    """

    def __init__(
        self,
        system: Device | Model | Structure = AS_BUILT,
        *,
        effects: dict[str, Any] | None = None,
        sensors: Sensors = Sensors(),
        fs: float = 512.0,
        oversample: int = 4,
        seed: int = 0,
        weigh_resolution: float | None = 1e-4,
    ):
        if effects is not None and not isinstance(effects, Mapping):
            raise RigError(f"effects must map effect names to values ({{'coulomb_friction': 0.1}}), got {effects!r}")
        if effects:
            try:  # the registry names a wrong effect or value; a program gets the rig's error for it
                system = _with_effects(system, effects)
            except (TypeError, ValueError, KeyError) as exc:
                raise RigError(f"effects {effects!r}: {' '.join(str(exc).split())}") from None
        for name, value in _element(system).extra.items():
            effect = effect_registry.get(name)
            if effect.dissipative and value < 0:
                raise RigError(f"effect {name} = {value:g} {effect.units}: a {name.replace('_', ' ')} dissipates "
                               "energy, its value is >= 0 on a physical device")  # fmt: skip
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise RigError(f"seed must be a whole number >= 0 (numpy's SeedSequence), got {seed!r}")
        if not (_real(fs) and fs > 0 and math.isfinite(fs)):
            raise RigError(f"sampling rate must be positive, got {fs!r}")
        if isinstance(oversample, bool) or not isinstance(oversample, (int, np.integer)) or oversample < 1:
            raise RigError(f"oversample must be a whole number >= 1, got {oversample!r}")
        if weigh_resolution is not None and not (
            _real(weigh_resolution) and 0 < weigh_resolution and math.isfinite(weigh_resolution)
        ):
            raise RigError(f"weigh_resolution must be None or a positive mass [kg], got {weigh_resolution!r}")
        self.system = system
        self.sensors = sensors
        self.fs = float(fs)
        self.oversample = int(oversample)
        self.seed = int(seed)
        self.weigh_resolution = weigh_resolution
        self.equilibria = system.element_equilibria() if isinstance(system, Structure) else system.equilibria()
        """The equilibria of the element's relative displacement (a single DOF's z)."""

    @classmethod
    def device_on_fixture(cls, device: Model = SEED_LIKE_CUBIC, *, fixture_mass: float = 1.0,
                          fixture_hz: float = 25.0, fixture_zeta: float = 0.02, **kw) -> Rig:  # fmt: skip
        """The device on a shaker fixture that is not rigid (DOF 1, sprung to the table; the device's mass DOF 2):
        ``fixture_hz`` and ``fixture_zeta`` of the fixture alone on its spring. ``kw``: the rig's parameters.
        """
        s = Structure.on_fixture(device, fixture_mass=fixture_mass, fixture_hz=fixture_hz, fixture_zeta=fixture_zeta)
        return cls(s, **kw)

    @classmethod
    def device_with_payload(cls, device: Model = SEED_LIKE_CUBIC, *, payload_mass: float = 0.1,
                            payload_hz: float = 30.0, payload_zeta: float = 0.01, **kw) -> Rig:  # fmt: skip
        """The device (DOF 1, the element on the table) carrying a payload on a spring and damper (DOF 2):
        ``payload_hz`` and ``payload_zeta`` of the payload alone on its spring. ``kw``: the rig's parameters.
        """
        k = payload_mass * (2 * math.pi * payload_hz) ** 2
        c = 2 * payload_zeta * math.sqrt(k * payload_mass)
        s = Structure.chain((device.m, payload_mass), (0.0, k), (0.0, c), device, (0, 1))
        return cls(s, **kw)

    @property
    def n_dof(self) -> int:
        """The DOFs on the table (1: a single DOF)."""
        return self.system.n_dof if isinstance(self.system, Structure) else 1

    def _positions(self, r: float) -> np.ndarray:
        """Every DOF's static position [m] with the element's relative displacement at ``r`` (the single DOF's z)."""
        return self.system.static_positions(r) if isinstance(self.system, Structure) else np.array([float(r)])

    def _batch(self, inputs: np.ndarray, dt: float, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The system under each row of ``inputs`` (base accelerations) from the states ``x0`` (B, 2N), in one
        batch: z and z' of shape (B, N, T), a ``RigError`` if a run left the stroke.
        """
        rows = np.arange(len(inputs))
        if isinstance(self.system, Structure):
            sim = simulate_structures(self.system, inputs, dt, x0, input_index=rows, store_velocity=True)
        else:
            params = np.repeat(self.system.kernel_params()[:, None], len(inputs), axis=1)
            sim = simulate_batch(params, self.system.kind, inputs, dt, x0, input_index=rows, store_velocity=True)
        if sim.diverged.any():
            raise RigError(
                f"the device did not survive the excitation: {sim.describe_failures()}; lower the excitation level"
            )
        assert sim.z_dot is not None  # stored above
        return sim.z.reshape(len(inputs), self.n_dof, -1), sim.z_dot.reshape(len(inputs), self.n_dof, -1)

    def __repr__(self) -> str:
        system = "the as-built device" if self.system == AS_BUILT else repr(self.system)
        return (
            f"Rig({system}, fs={self.fs:g} Hz, oversample={self.oversample}, seed={self.seed}, "
            f"sensor={self.sensors.response})"
        )

    # --- excitations -------------------------------------------------------------------------
    def random(
        self,
        duration: float = 300.0,
        rms: float = 14.0,
        band: tuple[float, float] = (2.0, 40.0),
        settle: float = 5.0,
        start: str = "plus",
    ) -> RigRecord:
        """Band-limited Gaussian random base excitation (flat spectrum over ``band`` [Hz]).

        ``rms`` [m/s^2] of the table acceleration; the first ``settle`` seconds are discarded.
        Starts at rest in the ``start`` well. The default level drives the as-built device across
        the wells a few times a minute while the true model's free run stays predictable (about 5 %
        over 12 s); above about 17 m/s^2 the crossings become chaotic and no model, not even the
        truth, can follow a long free run (see the calibration report).
        """
        self.check_random(duration, rms, band, settle, start)
        fsim = self.fs * self.oversample
        # a fast FFT length (the extra samples lengthen the discarded tail): the table motion and the
        # integration are FFTs of the whole acquisition, slow for lengths with large prime factors
        n = sp_fft.next_fast_len(int(round((duration + settle + TAIL_S) * self.fs)) * self.oversample, real=True)
        n -= n % self.oversample
        while n < int(round((duration + settle + TAIL_S) * self.fs)) * self.oversample:
            n = sp_fft.next_fast_len(n + self.oversample, real=True)
            n -= n % self.oversample
        exc_rng, sens_rng = self._streams()
        spec = sp_fft.rfft(exc_rng.standard_normal(n))
        f = np.fft.rfftfreq(n, 1 / fsim)
        spec[(f < band[0]) | (f > band[1])] = 0.0
        acc = sp_fft.irfft(spec, n)
        acc *= rms / acc.std()
        excitation = {
            "type": "random",
            "duration_s": duration,
            "rms_m_s2": rms,
            "band_hz": list(band),
            "settle_s": settle,
        }
        return self._run([acc], [start], [settle], [duration], excitation, sens_rng)[0]

    def check_random(self, duration=300.0, rms=14.0, band=(2.0, 40.0), settle=5.0, start="plus") -> None:
        """Everything ``random`` refuses (``RigError``, one line), before any work: the settings, the memory."""
        if not (duration > 0 and rms > 0 and 0 < band[0] < band[1] < self.fs / 2 and settle >= 0):
            raise RigError(
                f"random excitation needs duration > 0, rms > 0 and 0 < band < fs/2; got {duration}, {rms}, {band}"
            )
        self._check_start([start])
        self._require_memory([(duration + settle + TAIL_S) * self.fs * self.oversample], "a random record")

    def hammer(
        self,
        peak: float = 20.0,
        hits: int = 4,
        duration: float = 10.0,
        width: float = 0.004,
        start: str = "plus",
        dof: int | None = None,
    ) -> RigRecord:
        """The device hit by an impact hammer with the table held still: ``hits`` half-sine pulses of ``peak`` [N]
        lasting ``width`` [s], evenly spread (the first at 5 % of the record, each next after an equal share of the
        rest), from rest in the ``start`` well; on a structure, DOF ``dof`` is hit (default: the DOF the element
        moves; the record's ``force_dof``).

        The laser reads z (no base motion), the hammer's load cell the force (``Sensors.force_noise``). The device
        is simulated at the rig's ``oversample`` times ``fs``, or finer so that a pulse spans 16 samples, the force
        sampled on that grid (a pulse of a few output samples is not resolved by the band-limited input), and read
        at ``fs``. Columns ``t, force, z`` (a structure's: ``z1 ... zN``).
        """
        self.check_hammer(peak, hits, duration, width, start, dof)
        n = int(round(duration * self.fs))
        q = self._hammer_oversample(width)
        t_fine = np.arange(n * q) / (self.fs * q)
        times = [0.05 * duration + k * 0.95 * duration / hits for k in range(hits)]
        force = np.zeros(t_fine.size)
        for h in times:
            inside = (t_fine >= h) & (t_fine <= h + width)
            force[inside] += peak * np.sin(np.pi * (t_fine[inside] - h) / width)
        excitation = {"type": "hammer", "duration_s": duration, "peak_n": peak, "hits": hits, "width_s": width,
                      "hit_times_s": times}  # fmt: skip
        if self.n_dof > 1:
            excitation["force_dof"] = self._hit_dof(dof)
        return self._force_record(force, q, self._well(start), excitation)

    def release(self, z0: float, duration: float = 10.0) -> RigRecord:
        """A free decay: the moving part held at ``z0`` [m] and released from rest at t = 0, the table still (a
        structure's element held at the relative displacement ``z0``, every DOF where the structure rests under that
        hold). The laser reads z; the record's force column is zero (no input: a free decay, read as one). Columns
        ``t, force, z`` (a structure's: ``z1 ... zN``).
        """
        self.check_release(z0, duration)
        n = int(round(duration * self.fs))
        excitation = {"type": "release", "duration_s": duration, "z0_m": float(z0)}
        return self._force_record(np.zeros(n * self.oversample), self.oversample, float(z0), excitation)

    def check_release(self, z0: float, duration: float = 10.0) -> None:
        """Everything ``release`` refuses (``RigError``, one line), before any work."""
        if not (_real(z0) and math.isfinite(z0)):
            raise RigError(f"release position must be a finite number [m], got {z0!r}")
        if not (_real(duration) and duration > 0 and math.isfinite(duration)):
            raise RigError(f"a release needs a positive duration, got {duration!r}")
        self._check_laser()
        self._require_memory([duration * self.fs * self.oversample], "a release record")

    def check_hammer(self, peak=20.0, hits=4, duration=10.0, width=0.004, start="plus", dof=None) -> None:
        """Everything ``hammer`` refuses (``RigError``, one line), before any work."""
        self._check_laser()
        self._hit_dof(dof)
        if isinstance(hits, bool) or not isinstance(hits, (int, np.integer)) or hits < 1:
            raise RigError(f"hits must be a whole number >= 1, got {hits!r}")
        if not all(_real(v) and v > 0 and math.isfinite(v) for v in (peak, duration, width)):
            raise RigError(f"a hammer test needs peak > 0 [N], duration > 0 and width > 0 [s]; got {peak!r}, "
                           f"{duration!r}, {width!r}")  # fmt: skip
        if width * self.fs < 2:
            raise RigError(f"a {1e3 * width:g} ms hit spans {width * self.fs:.2g} samples at {self.fs:g} Hz: the load "
                           f"cell's record would miss it (at least 2 samples: {2 / width:g} Hz)")  # fmt: skip
        if width * hits >= 0.5 * duration:
            raise RigError(f"{hits} pulses of {width:g} s fill half of the {duration:g} s record or more: no ring-down "
                           "between them")  # fmt: skip
        self._check_start([start])
        self._well(start)
        self._require_memory([duration * self.fs * self._hammer_oversample(width)], "a hammer record")

    def _check_laser(self) -> None:
        """A hammer or release test is read by the laser on the moving part: a ``RigError`` for another sensor."""
        if self.sensors.response not in ("displacement", "absolute"):
            raise RigError(f"a hammer or release test is read by the laser on the moving part (response "
                           f"'displacement' or 'absolute'), not {self.sensors.response!r}")  # fmt: skip

    def _hit_dof(self, dof: int | None) -> int:
        """The DOF a hammer hits (1..N; default: the DOF the element moves), a ``RigError`` for any other."""
        if dof is None:
            return self.system.place[1] if isinstance(self.system, Structure) else 1
        if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or not 1 <= dof <= self.n_dof:
            raise RigError(f"the hammer hits a DOF 1..{self.n_dof}, got {dof!r}")
        return int(dof)

    def _hammer_oversample(self, width: float) -> int:
        """The simulation's samples per output sample for a hit of ``width`` [s]: the rig's ``oversample``, or
        more so that a pulse spans 16 of them.
        """
        return max(self.oversample, math.ceil(16 / (width * self.fs)))

    def _well(self, start: str) -> float:
        """The rest position [m] of the ``start`` well (``Equilibria.well``), a ``RigError`` where there is none."""
        try:
            return float(self.equilibria.well(start))
        except ValueError:
            raise RigError(f"the device has no {start} well to rest in") from None

    def _force_record(self, force: np.ndarray, q: int, z0: float, excitation: dict[str, Any]) -> RigRecord:
        """The record of the device driven by ``force`` [N] (on the grid ``q`` times ``fs``) from rest at ``z0``,
        the table still: z read by the laser at ``fs`` (every ``q``-th sample; the force is not band-limited, so no
        acquisition filter is modelled), the force by the hammer's load cell.
        """
        from .simulator import simulate

        self._check_laser()
        res = simulate(self.system, force, 1.0 / (self.fs * q), z0=z0, v0=0.0, input_kind="force",
                       force_dof=excitation.get("force_dof"))  # fmt: skip
        if res.diverged[0]:
            raise RigError(f"the device left every well under the {excitation['type']} test "
                           f"({res.describe_failures()})")  # fmt: skip
        assert res.z_dot is not None  # ``simulate`` stores the velocity
        n = self.n_dof
        z, z_dot, f = res.z[0].reshape(n, -1)[:, ::q], res.z_dot[0].reshape(n, -1)[:, ::q], force[::q]
        _, sens_rng = self._streams()
        s = self.sensors
        # each laser's noise first (DOF by DOF), the load cell's after
        lasers = [z[k] + s.response_offset + s.laser_noise * sens_rng.standard_normal(f.size) for k in range(n)]
        cell = s.force_noise * sens_rng.standard_normal(f.size) if excitation["type"] == "hammer" else 0.0
        cols = {"t": np.arange(f.size) / self.fs, "force": f + cell,
                **{response_column("z", k + 1, n): lasers[k] for k in range(n)}}  # fmt: skip
        true = {"z": z[0] if n == 1 else z, "z_dot": z_dot[0] if n == 1 else z_dot, "force": f}
        return self._record(cols, true, excitation)

    def sine_sweep(
        self,
        f_start: float = 2.0,
        f_stop: float = 40.0,
        amplitude: float = 1.0,
        duration: float = 120.0,
        mode: str = "linear",
        settle: float = 5.0,
        start: str = "plus",
    ) -> RigRecord:
        """A swept sine of the table acceleration, ``amplitude`` [m/s^2] from ``f_start`` to ``f_stop``
        [Hz] over ``duration`` s (``mode`` linear or logarithmic), by pyExSi's ``sine_sweep`` (SDyPy,
        MIT); the settling time holds the start frequency, and the table motion is band-limited as
        every excitation of the rig. A low-level sweep around one well is the lab's FRF test.

        The random excitation stays the rig's own (an FFT of seeded white noise, band-limited exactly):
        pyExSi's ``random_gaussian`` draws random phases under a prescribed PSD, a different signal
        for the same seed, and every reference record and report of the suite is built on the rig's
        draws; the two are the same process (a flat-spectrum band-limited Gaussian).
        """
        from pyExSi import sine_sweep

        self.check_sine_sweep(f_start, f_stop, amplitude, duration, mode, settle, start)
        fsim = self.fs * self.oversample
        n_settle, n_sweep = int(round(settle * fsim)), int(round(duration * fsim))
        n = sp_fft.next_fast_len(n_settle + n_sweep + int(round(TAIL_S * fsim)), real=True)
        t = np.arange(n) / fsim
        acc = np.empty(n)
        acc[:n_settle] = np.sin(2 * np.pi * f_start * t[:n_settle])
        phi0 = 2 * np.pi * f_start * t[n_settle] if n_settle else 0.0
        # the rate that reaches f_stop at the end of the record (Hz/s, or octaves/min for pyExSi's log mode);
        # the discarded tail sweeps on a little beyond it
        rate = (f_stop - f_start) / duration if mode == "linear" else math.log2(f_stop / f_start) / (duration / 60)
        acc[n_settle:] = sine_sweep(
            t[n_settle:] - t[n_settle], phi=phi0, freq_start=f_start, sweep_rate=rate, mode=mode
        )
        # the controller's ramp-up over the first half of the settling time and its ramp-down in the discarded
        # tail (``_ended``): the drive's ends meet at rest, so the table's motion has no slow part the lab's
        # integration misses
        acc[: n_settle + n_sweep] *= _smooth_steps([1.0], n_settle + n_sweep, n_settle // 2)
        acc *= amplitude * _ended(np.ones(n_settle + n_sweep), n, int(round(RAMP_DOWN_S * fsim)))
        excitation = {
            "type": "sine_sweep",
            "f_start_hz": f_start,
            "f_stop_hz": f_stop,
            "amplitude_m_s2": amplitude,
            "duration_s": duration,
            "mode": mode,
            "settle_s": settle,
            "generator": "pyExSi.sine_sweep",
        }
        _, sens_rng = self._streams()
        return self._run([acc], [start], [settle], [duration], excitation, sens_rng)[0]

    def check_sine_sweep(self, f_start=2.0, f_stop=40.0, amplitude=1.0, duration=120.0, mode="linear", settle=5.0,
                         start="plus") -> None:  # fmt: skip
        """Everything ``sine_sweep`` refuses (``RigError``, one line), before any work."""
        if not (0 < f_start < self.fs / 2 and 0 < f_stop < self.fs / 2) or amplitude < 0 or duration <= 0:
            raise RigError("a sine sweep needs 0 < f_start, f_stop < fs/2, amplitude >= 0 and duration > 0")
        if mode not in ("linear", "logarithmic"):
            raise RigError(f"sweep mode must be 'linear' or 'logarithmic', got {mode!r}")
        self._check_start([start])
        self._require_memory([(duration + settle + TAIL_S) * self.fs * self.oversample], "a sine sweep")

    def harmonic(
        self,
        freq: float = 9.0,
        amplitude: float = 5.0,
        start: str = "plus",
        settle_periods: int = 100,
        record_periods: int = 100,
    ) -> RigRecord:
        """Steady-state response to b'' = A sin(2 pi f t) [m/s^2], starting at rest in ``start`` well."""
        return self.sweep(freq, [amplitude], start, settle_periods, record_periods)[0]

    def sweep(
        self,
        freq: float,
        amplitudes: Sequence[float],
        start: str = "plus",
        settle_periods: int = 100,
        record_periods: int = 100,
    ) -> list[RigRecord]:
        """Step the harmonic amplitude through ``amplitudes`` without stopping the table, as a lab
        does (up or down by their order); one record per step, its settling time discarded. The first step ramps
        up from rest (``_ramp_up``), each next one over two periods, and the test ramps down to rest in the
        discarded tail (``_ended``).
        """
        return self.sweeps(freq, [amplitudes], [start], settle_periods, record_periods)[0]

    def sweeps(
        self,
        freq: float,
        amplitude_lists: Sequence[Sequence[float]],
        starts: Sequence[str],
        settle_periods: int = 100,
        record_periods: int = 100,
    ) -> list[list[RigRecord]]:
        """Several stepped sweeps (each from its own starting well) in one batched simulation."""
        self.check_sweeps(freq, amplitude_lists, starts, settle_periods, record_periods)
        fsim = self.fs * self.oversample
        period = 1.0 / freq
        step_s = (settle_periods + record_periods) * period
        step_n = int(round(step_s * self.fs)) * self.oversample
        ramp_n = int(round(2 * period * fsim))
        exc_rng, sens_rng = self._streams()
        phase = exc_rng.uniform(0, 2 * np.pi)
        accs, settles, durations = [], [], []
        first_ramp = _ramp_up(period, settle_periods * period, fsim)
        for amps in amplitude_lists:
            env = _smooth_steps(amps, step_n, [first_ramp] + [ramp_n] * (len(amps) - 1))
            n_fast = sp_fft.next_fast_len(env.size + int(TAIL_S * fsim), real=True)  # see random()
            env = _ended(env, n_fast, int(round(RAMP_DOWN_S * fsim)))
            t = np.arange(env.size) / fsim
            accs.append(env * np.sin(2 * np.pi * freq * t + phase))
            settles.append([i * step_n / fsim + settle_periods * period for i in range(len(amps))])
            durations.append(record_periods * period)
        excitation = {
            "type": "harmonic",
            "freq_hz": freq,
            "settle_periods": settle_periods,
            "record_periods": record_periods,
            "phase_rad": phase,
        }
        return self._run(
            accs,
            list(starts),
            settles,
            durations,
            excitation,
            sens_rng,
            steps=[[{"amplitude_m_s2": float(a), "step": j} for j, a in enumerate(amps)] for amps in amplitude_lists],
        )

    def check_sweeps(self, freq, amplitude_lists, starts, settle_periods=100, record_periods=100) -> None:
        """Everything ``sweeps`` (and ``harmonic``, ``sweep``) refuses (``RigError``, one line), before any work."""
        if not (0 < freq < self.fs / 4):
            raise RigError(f"forcing frequency must lie in (0, fs/4) = (0, {self.fs / 4:g}) Hz, got {freq}")
        if len(amplitude_lists) != len(starts) or not all(len(a) for a in amplitude_lists):
            raise RigError("each sweep needs a starting well and at least one amplitude")
        if settle_periods < 1 or record_periods < 2:
            raise RigError("need at least 1 settling and 2 recorded periods per step")
        for amps in amplitude_lists:
            if any(not (a >= 0 and math.isfinite(a)) for a in amps):
                raise RigError(f"harmonic amplitudes must be finite and >= 0, got {list(amps)}")
        self._check_start(starts)
        fsim, step_s = self.fs * self.oversample, (settle_periods + record_periods) / freq
        self._require_memory([len(a) * step_s * fsim + TAIL_S * fsim for a in amplitude_lists], "the campaign")

    def stepped_sines(
        self,
        freq_lists: Sequence[Sequence[float]],
        amplitude: float,
        starts: Sequence[str],
        settle_periods: int = 100,
        record_periods: int = 100,
    ) -> list[list[RigRecord]]:
        """Stepped-sine tests, as a lab measures a nonlinear frequency response: the table's acceleration
        ``amplitude`` [m/s^2] x sin(phase), its frequency stepped through each list without stopping the
        table (the phase continuous, each new frequency reached by a raised-cosine ramp over two periods of
        the slower one); one record per step, ``record_periods`` of its own period after ``settle_periods``;
        all sweeps in one batched simulation. The test ramps up from rest (``_ramp_up``) and down to rest in the
        discarded tail (``_ended``), as a controller runs it.
        """
        self.check_stepped_sines(freq_lists, amplitude, starts, settle_periods, record_periods)
        fsim = self.fs * self.oversample
        exc_rng, sens_rng = self._streams()
        phase0 = exc_rng.uniform(0, 2 * np.pi)
        accs, settles, durations = [], [], []
        for freqs in freq_lists:
            lengths = [int(round((settle_periods + record_periods) / f * self.fs)) * self.oversample for f in freqs]
            edges = np.concatenate([[0], np.cumsum(lengths)])
            ramps = [int(round(2 / min(f0, f1) * fsim)) for f0, f1 in zip([freqs[0], *freqs[:-1]], freqs, strict=False)]
            f_inst = _smooth_steps(freqs, lengths, ramps, start=freqs[0])
            env = _smooth_steps([amplitude], f_inst.size, _ramp_up(1 / freqs[0], settle_periods / freqs[0], fsim))
            n_fast = sp_fft.next_fast_len(f_inst.size + int(TAIL_S * fsim), real=True)  # see random()
            f_inst = np.pad(f_inst, (0, n_fast - f_inst.size), mode="edge")
            env = _ended(env, n_fast, int(round(RAMP_DOWN_S * fsim)))
            accs.append(env * np.sin(phase0 + 2 * np.pi * np.cumsum(f_inst) / fsim))
            settles.append([edges[k] / fsim + settle_periods / f for k, f in enumerate(freqs)])
            durations.append([record_periods / f for f in freqs])
        excitation = {
            "type": "harmonic",
            "campaign": "stepped sine",
            "settle_periods": settle_periods,
            "record_periods": record_periods,
            "phase_rad": phase0,
        }
        steps = [[{"freq_hz": float(f), "amplitude_m_s2": float(amplitude), "step": j} for j, f in enumerate(fl)]
                 for fl in freq_lists]  # fmt: skip
        return self._run(accs, list(starts), settles, durations, excitation, sens_rng, steps=steps)

    def check_stepped_sines(self, freq_lists, amplitude, starts, settle_periods=100, record_periods=100) -> None:
        """Everything ``stepped_sines`` refuses (``RigError``, one line), before any work."""
        if len(freq_lists) != len(starts) or not all(len(f) for f in freq_lists):
            raise RigError("each sweep needs a starting well and at least one frequency")
        if any(not (0 < f < self.fs / 4) for fl in freq_lists for f in fl):
            raise RigError(f"forcing frequencies must lie in (0, fs/4) = (0, {self.fs / 4:g}) Hz")
        if not (amplitude >= 0 and math.isfinite(amplitude)):
            raise RigError(f"the amplitude must be finite and >= 0, got {amplitude}")
        if settle_periods < 2 or record_periods < 2:
            raise RigError("need at least 2 settling and 2 recorded periods per step")
        self._check_start(starts)
        fsim = self.fs * self.oversample
        self._require_memory(
            [sum((settle_periods + record_periods) / f for f in fl) * fsim + TAIL_S * fsim for fl in freq_lists],
            "the stepped-sine campaign",
        )

    # --- the measurement chain ---------------------------------------------------------------
    @staticmethod
    def _check_start(starts) -> None:
        for st in starts:
            if st not in ("plus", "minus"):
                raise RigError(f"starting well must be 'plus' or 'minus', got {st!r}")

    def _require_memory(self, samples: Sequence[float], what: str) -> None:
        """Refuse (``RigError``, one line) before allocating a batch of simulations of ``samples`` samples
        each at the simulation rate that the machine cannot hold (``BYTES_PER_SAMPLE`` each).
        """
        from negstiff.resources import require_memory

        total = BYTES_PER_SAMPLE * self.n_dof * len(samples) * max(samples)  # a structure's: every DOF's channels
        try:
            require_memory(total, f"{what} ({max(samples) / (self.fs * self.oversample):.4g} s x {len(samples)} "
                                  f"at {self.fs * self.oversample:g} Hz)")  # fmt: skip
        except InputError as exc:
            raise RigError(str(exc)) from None

    def _streams(self) -> tuple[np.random.Generator, np.random.Generator]:
        exc, sens = np.random.SeedSequence(self.seed).spawn(2)
        return np.random.default_rng(exc), np.random.default_rng(sens)

    def _run(self, accs, starts, settles, durations, excitation, sens_rng, steps=None):
        """Simulate every excitation in one batch, then measure and cut the records: sweep i's j-th record
        starts at ``settles[i][j]`` and lasts ``durations[i]`` (or ``durations[i][j]``) seconds; ``steps[i][j]``
        is added to its excitation (a campaign's per-step values: amplitude, frequency, step).
        """
        fsim = self.fs * self.oversample
        s = self.sensors
        n = max(a.size for a in accs)
        motions = [table_motion(np.pad(a, (0, n - a.size)), fsim, s.table_min_hz) for a in accs]
        self._check_start(starts)
        nd = self.n_dof
        x0 = np.array([np.r_[self._positions(self._well(st)), np.zeros(nd)] for st in starts])
        z, z_dot = self._batch(np.array([m[1] for m in motions]), 1 / fsim, x0)
        q = self.oversample
        out = []
        for i, ((b_true, acc_true), st) in enumerate(zip(motions, starts, strict=False)):
            acc_meas = acc_true + s.acc_bias + s.acc_noise * math.sqrt(q) * sens_rng.standard_normal(n)
            chans = {"base_acc": acc_meas}
            for k in range(nd):  # each DOF's laser (a single DOF's: y), drawn after the table's accelerometer
                y_meas = z[i, k] + b_true + s.laser_noise * math.sqrt(q) * sens_rng.standard_normal(n)
                if s.response in ("displacement", "absolute"):
                    y_meas = y_meas + s.response_offset  # the laser's zero away from the rods-horizontal position
                chans[response_column("y", k + 1, nd)] = y_meas
            for k in range(nd):
                chans |= self._response_channels(z_dot[i, k], acc_true, fsim, sens_rng, k + 1)
            chans |= {f"z_true{k}": z[i, k] for k in range(nd)} | {f"z_dot_true{k}": z_dot[i, k] for k in range(nd)}
            chans |= {"acc_true": acc_true, "b_true": b_true}
            if q > 1:  # delta-sigma front end: linear-phase FIR anti-aliasing, delay compensated
                b = antialias_fir(q)
                chans = {k: signal.resample_poly(v, 1, q, window=b) for k, v in chans.items()}
            b_est = integrate_twice(chans["base_acc"], self.fs, s.highpass_hz, s.integration)
            sweep_out = []
            lasts = np.broadcast_to(np.atleast_1d(durations[i]), np.atleast_1d(settles[i]).shape)
            for j, (t0, last) in enumerate(zip(np.atleast_1d(settles[i]), lasts, strict=False)):
                k0 = int(round(t0 * self.fs))
                k1 = k0 + int(round(last * self.fs))
                sl = slice(k0, k1)
                cols = {"t": np.arange(k1 - k0) / self.fs, "base_acc": chans["base_acc"][sl]}
                for k in range(1, nd + 1):
                    y = chans[response_column("y", k, nd)][sl]
                    if s.response == "displacement":
                        # the reference study's columns: a single DOF's laser, the integrated base and their z; a
                        # structure's record holds one response per DOF (``load``'s rule), each DOF's z
                        cols |= {"y": y, "base_disp": b_est[sl]} if nd == 1 else {}
                        cols[response_column("z", k, nd)] = y - b_est[sl]
                    elif s.response == "absolute":
                        cols[response_column("y", k, nd)] = y
                    else:
                        name = response_column("z_dot" if s.response == "velocity" else "y_acc", k, nd)
                        cols[name] = chans[name][sl]
                zt = np.array([chans[f"z_true{k}"][sl] for k in range(nd)])
                vt = np.array([chans[f"z_dot_true{k}"][sl] for k in range(nd)])
                true = {
                    "z": zt[0] if nd == 1 else zt,
                    "z_dot": vt[0] if nd == 1 else vt,
                    "base_acc": chans["acc_true"][sl],
                    "base_disp": chans["b_true"][sl],
                }
                exc = dict(excitation, start_well=st, record_start_s=k0 / self.fs, **(steps[i][j] if steps else {}))
                sweep_out.append(self._record(cols, true, exc))
            out.append(sweep_out)
        return out if steps is not None else [r[0] for r in out]

    def _response_channels(self, z_dot, acc_true, fsim, rng, dof: int = 1) -> dict[str, np.ndarray]:
        """DOF ``dof``'s vibrometer (relative velocity) or accelerometer, at the fine rate (drawn after the
        reference study's sensors, so a displacement record is the same bit for bit).
        """
        s, q = self.sensors, self.oversample
        if s.response == "velocity":
            noise = s.velocity_noise * math.sqrt(q) * rng.standard_normal(z_dot.size)
            return {response_column("z_dot", dof, self.n_dof): z_dot + s.response_offset + noise}
        if s.response == "accelerometer":
            z_ddot = np.gradient(z_dot, 1 / fsim, edge_order=2)
            noise = s.acc_noise * math.sqrt(q) * rng.standard_normal(z_dot.size)
            return {response_column("y_acc", dof, self.n_dof): z_ddot + acc_true + s.response_offset + noise}
        if s.response not in ("displacement", "absolute"):
            raise RigError(
                f"response sensor must be displacement, velocity, absolute or accelerometer, got {s.response!r}"
            )
        return {}

    def _record(self, cols, true, excitation) -> RigRecord:
        meta = {
            "fs": f"{self.fs:g}",
            "units": "SI (s, m/s^2, m)",
            "source": f"negstiff virtual rig ({excitation['type']}, seed {self.seed})",
        }
        eq = self.equilibria
        if isinstance(self.system, Structure):  # the contract's multi-DOF header: each DOF's mass, the element's place
            meta["masses"] = ",".join(f"{m:g}" for m in self.system.masses)
            meta["element"] = "-".join(map(str, self.system.place))
            # the element's relative displacement at rest in each well, as the lasers read it before the test (the
            # single DOF's z rests, for what reads the element's relative motion: ``characterise.response_for``)
            for name in ("z_minus", "z_plus"):
                if getattr(eq, name) is not None:
                    meta[f"element_{name.removeprefix('z_')}_rest"] = f"{round(getattr(eq, name), 5):.5f}"
            if "force_dof" in excitation:
                meta["force_dof"] = str(excitation["force_dof"])
        else:
            # the rest positions, measured with the laser before the test (0.01 mm resolution)
            for name in ("z_minus", "z_plus"):
                if getattr(eq, name) is not None:
                    meta[f"{name}_rest"] = f"{round(getattr(eq, name), 5):.5f}"
            if self.weigh_resolution:
                meta["mass"] = f"{round(self.system.m / self.weigh_resolution) * self.weigh_resolution:.6g}"
        if excitation["type"] == "harmonic":
            meta["forcing_hz"] = f"{excitation['freq_hz']:g}"
            meta["amplitude_m_s2"] = f"{excitation['amplitude_m_s2']:g}"
        kind = "structure" if isinstance(self.system, Structure) else self.system.kind
        truth = {
            "system": {"kind": kind, "parameters": self.system.to_dict()},
            "effects": effect_registry.plain(_element(self.system).extra),
            "equilibria": eq.as_dict(),
            "sensors": asdict(self.sensors),
            "fs": self.fs,
            "oversample": self.oversample,
            "seed": self.seed,
            "excitation": excitation,
        }
        if isinstance(self.system, Device) and eq.z_minus is not None:  # a double well's features
            truth["features"] = self.system.features()
        if isinstance(self.system, Structure):
            truth["structure"] = self.system.to_dict()
            truth["rest_positions_m"] = {w: list(map(float, z)) for w, z in self.system.equilibria().items()}
        return RigRecord(self.fs, cols, meta, truth, true)
