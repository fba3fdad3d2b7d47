"""Records: ``Measurement`` (one uniformly sampled record in SI units) and ``from_arrays`` (a record made from
arrays in memory, checked as a file is: ``Measurement.from_rig`` makes the virtual rig's through it). A file is
read by ``reading.load``; the checks both share are ``checks``'.

A measurement is one uniformly sampled record with exactly one input column (``base_acc`` [m/s^2]
or ``force`` [N]), the output ``z`` [m], and a time base (``t`` [s], or ``fs`` [Hz] from the
metadata or the caller). A structure of N degrees of freedom is the same record with N response
channels: the file's ``z1 ... zN`` [m] (each DOF's displacement relative to the base) and ``# masses:
m1,...,mN`` [kg], read with every format, column map, unit and check of the single DOF's, per channel; its
``z`` is then (N, T). N = 1 is the single DOF (a file's lone ``z1`` is its ``z``). A channel's zero is a
laser's, arbitrary: the record keeps it as measured and says so (``info["response"]["offsets"]``); the
structure's identification estimates each channel's constant. Foreign files are read through a column
map (``force=V1,z=V2``; an entry may scale, ``base_acc=X1*9.81``). Every problem raises
``MeasurementError`` with one line naming the file, the column or row, and what is wrong. Input files are only read.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from negstiff.constants import G
from negstiff.errors import MeasurementError
from negstiff.inference.record.derivatives import (
    band_limited,
    basis_band_hz,
    coherence,
    noise_floor,
    smooth_and_differentiate,
    state_derivatives,
    velocity_window,
)
from negstiff.io.schema import INPUTS, MASS_RANGE_KG, OPTIONAL, channel_sensor
from negstiff.models.effects import measured_channels
from negstiff.resources import on_fit_threads

from . import channels, sensors
from .checks import (
    aux_channels,
    check_sampling_rate,
    check_values,
    checked_force_dof,
    checked_gravity,
    checked_masses,
    checked_unknown_scale,
    is_constant,
)


@dataclass(frozen=True)
class Measurement:
    """One uniformly sampled record, in SI units (``load`` or ``from_arrays`` make one).

    Attributes
    ----------
    fs : float
        Sampling rate [Hz].
    input_name : {"base_acc", "force"}
        What the input is.
    u : numpy.ndarray
        The input column, (N,).
    z : numpy.ndarray or None
        Relative displacement [m], (T,): measured, or derived from the response sensor (``info``); None
        only for an input-only record read with ``response=False``. A structure of N > 1 DOFs: (N, T),
        each DOF's displacement relative to the base (the file's ``z1 ... zN``).
    z_dot, y, base_disp : numpy.ndarray or None
        Optional columns, (N,).
    mass : float or None
        Moving mass [kg] from the metadata or the caller; None: coefficients per unit mass.
    meta : dict of str
        The file's metadata (``# key: value`` lines), as strings.
    source : str
        Where it came from (for messages).
    t0 : float
        Time of the first sample [s].
    info : dict
        How the record was read: ``time`` (the time base, its jitter) and ``response`` (what was
        measured, how z was derived from it, with its estimated error); results carry it.
    aux : dict of numpy.ndarray
        Measured auxiliary channels kept with ``load(..., aux=...)`` (a harvester's voltage), by name.
    masses : tuple of float or None
        A structure's DOF masses m1 ... mN [kg] (``# masses:``); None for a single DOF (its ``mass``).
    force_dof : int or None
        The DOF a force input acts on (1..N, metadata ``force_dof``); None: the element's.

    Examples
    --------
    >>> from negstiff import Measurement, Rig
    >>> rec = Measurement.from_rig(Rig(seed=1).random(duration=20.0))
    >>> part = rec.segment(0, int(10 * rec.fs))      # the first 10 s, as its own record
    >>> part.duration, part.mass
    (10.0, 0.212)
    """

    fs: float
    input_name: str
    u: np.ndarray
    z: np.ndarray | None
    z_dot: np.ndarray | None = None
    y: np.ndarray | None = None
    base_disp: np.ndarray | None = None
    mass: float | None = None
    meta: dict[str, str] = field(default_factory=dict)
    source: str = "<memory>"
    t0: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    aux: dict[str, np.ndarray] = field(default_factory=dict)
    masses: tuple[float, ...] | None = None
    force_dof: int | None = None
    derived: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)
    """What is computed from this record once and kept with it (its smoothed states, its segments, its
    pinned frame): a record is immutable, so what it gives never changes (``states``, ``segment``)."""

    def __post_init__(self) -> None:
        """The record's invariants, checked however it is made (``Measurement(...)`` directly, ``replace``,
        ``from_arrays``, ``load``): what ``from_arrays`` checks of arrays (the input's name, a sampling rate a
        record has, 1-D columns of one length of at least 2 samples, real, finite and within a shaker-table
        record's SI magnitudes; a mass within ``MASS_RANGE_KG``), each failure one ``MeasurementError``.
        Columns given as sequences become float arrays.
        """
        source = self.source
        if not isinstance(self.input_name, str) or self.input_name not in INPUTS:
            raise MeasurementError(f"{source}: input must be one of {INPUTS}, got {self.input_name!r}")
        object.__setattr__(self, "fs", check_sampling_rate(source, self.fs, "given"))
        cols: dict[str, np.ndarray] = {}
        names = [("u", self.input_name), ("z", "z"), *((k, k) for k in OPTIONAL if k in ("z_dot", "y", "base_disp"))]
        for attr, name in names:
            values = getattr(self, attr)
            if values is None:
                continue
            if np.iscomplexobj(values):
                raise MeasurementError(f"{source}: {name} is complex: a record's samples are real numbers")
            try:
                arr = np.asarray(values, dtype=float)
            except (TypeError, ValueError):
                raise MeasurementError(f"{source}: {name} is not an array of numbers") from None
            if arr is not values:
                object.__setattr__(self, attr, arr)
            if attr == "z" and arr.ndim == 2 and arr.shape[0] > 1:
                cols.update({f"z{k + 1}": row for k, row in enumerate(arr)})
            elif arr.ndim != 1:
                raise MeasurementError(f"{source}: {name} must be a 1-D array (a structure's z: (N, T)), got shape "
                                       f"{arr.shape}")  # fmt: skip
            else:
                cols[name] = arr
        n = cols[self.input_name].size
        for name, arr in cols.items():
            if arr.size != n:
                raise MeasurementError(f"{source}: {name} has {arr.size} samples, {self.input_name} has {n}")
        if n < 2:
            raise MeasurementError(f"{source}: too few samples ({n}) for a record")
        check_values(source, cols)
        if not isinstance(self.aux, Mapping):
            raise MeasurementError(f"{source}: aux must map names to channels ({{'voltage': v}})")
        for name, v in self.aux.items():
            if np.ndim(v) != 1 or np.size(v) != n:
                raise MeasurementError(f"{source}: auxiliary channel {name} has {np.size(v)} samples, the record {n}")
            if not np.all(np.isfinite(v)):
                raise MeasurementError(f"{source}: auxiliary channel {name} is NaN or inf")
        if self.mass is not None:
            m = self.mass
            if (
                isinstance(m, bool)
                or not isinstance(m, (int, float, np.integer, np.floating))
                or not (MASS_RANGE_KG[0] <= m <= MASS_RANGE_KG[1])
            ):
                raise MeasurementError(f"{source}: mass {m!r} kg is not a moving mass "
                                       f"({MASS_RANGE_KG[0]:g} to {MASS_RANGE_KG[1]:g} kg)")  # fmt: skip
        if self.masses is not None:
            object.__setattr__(self, "masses", checked_masses(source, self.masses, self.n_dof))

    @property
    def n(self) -> int:
        """The number of samples."""
        return self.u.size

    def __repr__(self) -> str:
        resp = self.info.get("response", {}).get("measured") or ("z" if self.z is not None else "none")
        mass = f"{self.mass:g} kg" if self.mass is not None else "none (per unit mass)"
        if self.n_dof > 1:
            given = "unknown" if self.masses is None else ", ".join(f"{m:g}" for m in self.masses) + " kg"
            return (f"Measurement({self.source!r}: {self.n} samples at {self.fs:g} Hz ({self.duration:.4g} s), input "
                    f"{self.input_name}, responses of {self.n_dof} DOFs {resp}, masses {given})")  # fmt: skip
        return (
            f"Measurement({self.source!r}: {self.n} samples at {self.fs:g} Hz ({self.duration:.4g} s), input "
            f"{self.input_name}, response {resp}, mass {mass})"
        )

    @property
    def n_dof(self) -> int:
        """The number of response channels (degrees of freedom): 1 for a single DOF's record."""
        return 1 if self.z is None or np.ndim(self.z) == 1 else int(self.z.shape[0])

    @property
    def channels(self) -> np.ndarray:
        """The responses as (N, T) for any N (a single DOF's z as one row; a view, read-only)."""
        return np.atleast_2d(self.displacement)

    @property
    def dof_masses(self) -> tuple[float, ...]:
        """The DOFs' masses [kg]: ``masses``, or a single DOF's ``(mass,)``; one ``MeasurementError`` without."""
        if self.masses is not None:
            return self.masses
        if self.n_dof == 1 and self.mass is not None:
            return (self.mass,)
        through_sensors = (
            "; without them only NSI reads a structure, through its sensors (identify nsi --element I-J --force-dof K: "
            "a state-space model of the order the record shows)"
            if self.n_dof > 1 and self.input_name == "force"
            else ""
        )
        raise MeasurementError(
            f"{self.source}: the masses are not given ('# masses: m1,...,mN' in the header, or --masses)"
            + through_sensors
        )

    @property
    def dt(self) -> float:
        """The sampling interval [s]."""
        return 1.0 / self.fs

    @property
    def t(self) -> np.ndarray:
        """The time of every sample [s]."""
        return self.t0 + np.arange(self.n) / self.fs

    @property
    def duration(self) -> float:
        """The record's length [s]."""
        return self.n / self.fs

    @property
    def displacement(self) -> np.ndarray:
        """The response z [m], (N,), for an analysis that needs one: ``z`` where an input-only record (read
        with ``response=False``) has none, which is one ``MeasurementError`` here.
        """
        if self.z is None:
            raise MeasurementError(f"{self.source}: an input-only record has no response z, which this needs")
        return self.z

    @classmethod
    def from_rig(cls, rec, weighed: bool = True) -> Measurement:
        """A virtual-rig record (``models.rig.RigRecord``) as negstiff reads a lab's: the measured base
        acceleration as input (a hammer's or release's record: the force), the response its sensor measured (z,
        or z_dot, y, y_dot, y_acc, from which z
        is derived as ``load`` derives it), the weighed mass (``weighed``), its source, the wells' rest
        positions its metadata states and a structure's element's place (as a file of it holds them).
        """
        mass = float(rec.meta["mass"]) if weighed and rec.meta.get("mass") is not None else None
        meta = {k: str(v) for k, v in rec.meta.items() if k.endswith("_rest") or k == "element"}
        inp = "force" if "force" in rec.columns else "base_acc"  # a hammer's or release's record: the load cell's
        cols = {k: v for k, v in rec.columns.items() if k not in ("t", inp)}
        z = cols.pop("z", None)
        if z is not None:  # a measured z is the response (the laser's y and the base's, already in it, stay out)
            cols = {}
        sensed = {cs[1] for k in cols if (cs := channel_sensor(k)) is not None}
        if sensed:  # a structure's record: each DOF's z, its masses and the DOF a hammer hit, as its file states them
            if sensed != {"z"}:
                raise MeasurementError(
                    f"{rec.meta['source']}: a structure's record of {', '.join(cols)} is read "
                    "from its file (write it, then load it): each channel's z is derived there"
                )
            z = rec.z  # its z1 ... zN by DOF (``RigRecord.z``)
            cols = {"masses": rec.meta["masses"].split(","), **({"force_dof": int(rec.meta["force_dof"])}
                                                                if "force_dof" in rec.meta else {})}  # fmt: skip
        return from_arrays(rec.columns[inp], z, rec.fs, inp, mass=mass, source=rec.meta["source"], meta=meta,
                           **cols)  # fmt: skip

    def segment(self, start: int | None, stop: int | None) -> Measurement:
        """Samples [start, stop) as a measurement (time base kept); the same object for the same span, so
        what it derives is derived once (``states``).
        """
        start, stop, _ = slice(start, stop).indices(self.n)
        key = ("segment", start, stop)
        seg = self.derived.get(key)
        if seg is None:
            sl = slice(start, stop)
            opt: dict[str, Any] = {k: (None if getattr(self, k) is None else getattr(self, k)[..., sl])
                                   for k in ("z", *OPTIONAL)}  # fmt: skip
            aux = {k: v[sl] for k, v in self.aux.items()}
            seg = self.derived[key] = replace(self, u=self.u[sl], t0=self.t0 + start / self.fs, aux=aux, **opt)
        return seg

    def states(self, purpose: str = "state") -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """Smoothed z, z', z'' of the record and how they were found (``derivatives.state_derivatives``:
        ``"state"``, the least-error velocity every free run starts from; ``"regression"``, the weak form's;
        ``"band"``, NSI's, whose window keeps the response's band flat),
        computed once per record and kept with it (copies are returned: a caller may change its own).
        """
        key = ("states", purpose)
        hit = self.derived.get(key)
        if hit is None:
            floor = None if purpose == "band" else self.noise_floor()  # the band's window reads its own PSD
            hit = self.derived[key] = state_derivatives(self.displacement, self.fs, purpose, floor=floor)
        zs, v, a, info = hit
        return zs.copy(), v.copy(), a.copy(), copy.deepcopy(info)

    def free_run_states(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, T) z and z' of every channel as a free run starts from: ``states("state")``'s least-error velocity,
        channel by channel, each with its own noise floor (one channel's are ``states("state")``'s, shared with it).
        Kept with the record; copies are returned.
        """
        hit = self.derived.get("free_run_states")
        if hit is None:
            z = self.displacement
            pairs = ([self.states("state")[:2]] if z.ndim == 1 else
                     [state_derivatives(zi, self.fs, "state", floor=noise_floor(zi, self.fs))[:2]
                      for zi in z])  # fmt: skip
            hit = self.derived["free_run_states"] = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
        return hit[0].copy(), hit[1].copy()

    def basis_states(self) -> tuple[np.ndarray, np.ndarray]:
        """NSI's band states (``states("band")``) low-passed where the record holds its sensor's noise alone
        (``derivatives.basis_band_hz``, ``band_limited``): the z and z' a nonlinear basis is built from (their noise,
        correlated with the output's, biases the subspace step: errors in variables), computed once per record
        and kept with it (copies are returned).
        """
        hit = self.derived.get("basis_states")
        if hit is None:
            zs, v, _, _ = self.states("band")
            cut = basis_band_hz(self.displacement, self.fs, self.noise_floor())
            hit = self.derived["basis_states"] = (band_limited(zs, self.fs, cut), band_limited(v, self.fs, cut))
        return hit[0].copy(), hit[1].copy()

    def channel_states(self, at: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
        """Band-smoothed displacements and velocities (N, T) of every channel, and the Savitzky-Golay
        (window, order) used: one window for all (a relative motion is a difference of channels, which must be
        smoothed alike), the one the element's relative displacement z_J - z_I allows when ``at`` = (I, J) is
        given (the motion the nonlinear basis reads; a channel that barely moves, like a stiff fixture's, is
        mostly sensor noise and would allow none), else the narrowest any channel allows
        (``derivatives.velocity_window``). A structure's counterpart of ``states("band")``, computed once per
        record and ``at``; copies are returned.
        """
        key = ("channel_states", at)
        hit = self.derived.get(key)
        if hit is None:
            z = self.channels
            if at is not None:
                r = z[at[1] - 1] - (z[at[0] - 1] if at[0] else 0.0)
                w = velocity_window(r, self.fs)
            else:
                w = min(velocity_window(zi, self.fs) for zi in z)
            pairs = [smooth_and_differentiate(zi, self.fs, w) for zi in z]
            hit = self.derived[key] = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]), w)
        zs, v, w = hit
        return zs.copy(), v.copy(), w

    def channel_noise(self) -> np.ndarray:
        """Each channel's white sensor-noise rms [m], (N,) (``derivatives.noise_floor`` per channel), kept."""
        hit = self.derived.get("channel_noise")
        if hit is None:
            hit = self.derived["channel_noise"] = np.sqrt([noise_floor(zi, self.fs)[0] for zi in self.channels])
        return hit.copy()

    def unit_warnings(self) -> list[str]:
        """Unit checks of the record's columns (SI expected): z spanning more than a stroke could, a base
        acceleration over 200 g rms. ``load`` issues them at once; the plausibility check asks again of a
        record made physical (a calibrated response may span more).
        """
        out = []
        scale = self.info.get("scale")
        if self.z is not None and not (scale and scale.get("value") is None):  # a span of unknown units says nothing
            span = float(np.ptp(self.z))
            if span > STROKE_LIMIT_M:
                out.append(
                    f"z spans {span:.3g} m: is the record in mm? negstiff reads SI units (m); scale the column in the "
                    "map, e.g. --columns z=COL*0.001"
                )
        if self.input_name == "base_acc":
            rms = float(np.std(self.u))
            if rms > ACC_LIMIT_M_S2:
                out.append(f"base_acc has rms {rms:.3g} m/s^2 (over 200 g): is it in mm/s^2? negstiff reads m/s^2")
        return out

    def noise_floor(self) -> tuple[float, np.ndarray, np.ndarray]:
        """The displacement's white sensor-noise variance and its signal's PSD, (sigma^2, f, S)
        (``derivatives.noise_floor``), computed once per record and kept with it: the derivative filters,
        the weak form's test functions and the characterisation's tolerances all read it.
        """
        hit = self.derived.get("noise_floor")
        if hit is None:
            hit = self.derived["noise_floor"] = noise_floor(self.displacement, self.fs)
        return hit

    def driving(self, model) -> np.ndarray:
        """The input that drives ``model`` over this record: ``u``, plus the forces of the model's measured
        auxiliary channels (``aux:NAME`` in its ``extra``: theta a(t), on the left-hand side of the equation
        like every effect's force, theta in N per channel unit) moved to the input's side: u + theta a / m
        for a base acceleration (m z'' + ... + theta a = -m u), F - theta a for a force. A model term whose
        channel the record lacks raises ``MeasurementError``.
        """
        terms = measured_channels(getattr(model, "extra", {}))
        if not terms:
            return self.u
        missing = [k for k in terms if k not in self.aux]
        if missing:
            have = ", ".join(self.aux) or "none"
            raise MeasurementError(f"{self.source}: the model has a term in the measured channel {missing[0]!r}, which "
                                   f"this record lacks (its auxiliary channels: {have}; --aux)")  # fmt: skip
        force = sum(theta * self.aux[k] for k, theta in terms.items())
        return self.u + force / model.m if self.input_name == "base_acc" else self.u - force

    def staged(self, model, substeps: int, lo: int = 0, hi: int | None = None) -> np.ndarray:
        """The input that drives ``model`` (``driving``) over samples [lo, hi) at every Runge-Kutta stage time
        (``simulator.stage_input``), interpolated once per record: a fit stages the same input again for each
        candidate, restart and check (NSI 11 times on 5 inputs, SINDy 17 on 6, the discrepancy workflow 25 on 4,
        measured). Kept with the record (``derived``), keyed by the model's measured-channel terms; a copy.
        """
        from negstiff.models.effects import measured_channels
        from negstiff.models.simulator import stage_input

        terms = measured_channels(getattr(model, "extra", {}))
        key = ("staged", int(substeps), int(lo), hi, tuple(sorted(terms.items())), model.m if terms else None)
        hit = self.derived.get(key)
        if hit is None:
            hit = self.derived[key] = stage_input(self.driving(model)[lo:hi], substeps)
        return hit.copy()

    @property
    def rest_positions(self) -> dict[str, float]:
        """The wells' rest positions the metadata states (``z_minus_rest``, ``z_plus_rest`` [m]), by well."""
        out = {}
        for w in ("minus", "plus"):
            try:
                out[w] = float(self.meta[f"z_{w}_rest"])
            except (KeyError, ValueError):
                pass
        return out

    @property
    def gravity(self) -> float:
        """The gravity along the motion [m/s^2]: the metadata's ``gravity`` (0 for a horizontal device, whose
        frame is then pinned by its wells' symmetry or rest positions, never by K(0) = m g), else g.
        """
        return float(self.meta.get("gravity", G))

    def with_gravity(self, gravity: float | None) -> Measurement:
        """The same record with the gravity along its motion given by the caller (overrides the metadata)."""
        if gravity is None:
            return self
        return replace(self, meta={**self.meta, "gravity": repr(checked_gravity(self.source, gravity))})

    def require(self, n_min: int, what: str) -> None:
        """Raise ``MeasurementError`` unless the record has at least ``n_min`` samples for ``what``."""
        if self.n < n_min:
            raise MeasurementError(
                f"{self.source}: too few samples for {what}: {self.n} ({self.duration:.3g} s), need at least {n_min}"
            )

    def with_mass(self, mass: float | None) -> Measurement:
        """The same record with the mass given by the caller (overrides the metadata)."""
        if mass is None:
            return self
        if (
            isinstance(mass, bool)
            or not isinstance(mass, (int, float, np.integer, np.floating))
            or not (MASS_RANGE_KG[0] <= mass <= MASS_RANGE_KG[1])
        ):
            raise MeasurementError(f"{self.source}: mass {mass!r} kg is not a moving mass "
                                   f"({MASS_RANGE_KG[0]:g} to {MASS_RANGE_KG[1]:g} kg)")  # fmt: skip
        return replace(self, mass=float(mass))

    def with_masses(self, masses) -> Measurement:
        """The same record with its DOFs' masses given by the caller (overrides the metadata's ``masses``); a
        single DOF's one mass is its ``mass``.
        """
        if masses is None:
            return self
        masses = checked_masses(self.source, masses, self.n_dof)
        return self.with_mass(masses[0]) if self.n_dof == 1 else replace(self, masses=masses)

    def require_motion(self, what: str) -> None:
        """Raise ``MeasurementError`` when the response does not move (a dead or disconnected sensor):
        ``what`` (an identification, a periodicity analysis) needs motion.
        """
        if self.z is None:
            return
        for k, zk in enumerate(np.atleast_2d(self.z)):
            if is_constant(zk):
                raise MeasurementError(
                    f"{self.source}: the response {self.channel_name(k)} is constant ({zk[0]:.6g} m over {self.n} "
                    f"samples): a dead or disconnected sensor? {what} needs motion"
                )

    def require_excitation(self, what: str) -> None:
        """Raise ``MeasurementError`` when the input does not vary (a dead sensor, or no excitation)."""
        if is_constant(self.u):
            raise MeasurementError(
                f"{self.source}: the input {self.input_name} is constant ({self.u[0]:.6g} over {self.n} samples): a "
                f"dead sensor, or no excitation? {what} needs an input that moves"
            )

    def channel_name(self, k: int) -> str:
        """The name of response channel ``k`` (0-based) as the record's columns write it: ``z``, or ``z1``..``zN``."""
        return "z" if self.z is not None and np.ndim(self.z) == 1 else f"z{k + 1}"

    def require_response(self, what: str) -> None:
        """Raise ``MeasurementError`` when a response channel carries no trace of the input: its coherence with the
        input stays, in every bin below 0.8 of the Nyquist frequency, where two independent signals' reaches by
        chance (the largest of K bins is significant at ``RESPONSE_TRACE_P`` when K (1 - gamma^2)^(n_d - 1) is below
        it, n_d the Welch averages of segments of about a second: Bendat & Piersol 9.2.3): a sensor reading its own
        noise (a vibrometer off its target). A nonlinear response, chaotic too, keeps a linear part of its input
        (a cross-well record's best bin: coherence 0.56 over 31 averages, p = 4e-9; a vibrometer's noise: 0.044 over
        119, p = 0.97); every DOF of a structure the input drives moves with it. Each channel is judged, the first
        without a trace named. A record without an input (a free decay) or a hammer's is not judged here.
        """
        if self.z is None or is_constant(self.u):
            return
        nper = int(min(self.n // 16, round(self.fs)))
        if nper < 64:
            return
        averages = 2 * self.n // nper - 1
        for k, zk in enumerate(self.channels):
            if is_constant(zk):
                continue  # a dead channel is ``require_motion``'s to name
            f, coh = coherence(self.u, zk, self.fs, nper)
            band = (f > 0) & (f < 0.8 * self.fs / 2)
            if not band.any():
                return
            best = float(np.nan_to_num(coh[band]).max())
            p = band.sum() * (1 - best) ** (averages - 1)
            if p > RESPONSE_TRACE_P:
                raise MeasurementError(
                    f"{self.source}: the response {self.channel_name(k)} carries no trace of the input "
                    f"{self.input_name}: its coherence with it reaches {best:.2g} at most over {averages} averages, "
                    f"which independent signals reach by chance (p = {min(p, 1.0):.2g}); is its sensor reading its "
                    f"own noise? {what} needs the response to this input"
                )

    def require_live_aux(self, what: str) -> None:
        """Raise ``MeasurementError`` when a measured auxiliary channel does not vary (a dead sensor): a term in it
        is a constant, which the restoring force's k0 cannot be told from (``what`` offers each as a term).
        """
        for name, a in self.aux.items():
            if is_constant(a):
                raise MeasurementError(
                    f"{self.source}: the auxiliary channel {name!r} is constant ({a[0]:.6g} over {self.n} samples): a "
                    f"dead or disconnected sensor? {what} offers it as a term, which needs a channel that moves"
                )


RESPONSE_TRACE_P = 0.01
"""A response whose best coherence with the input is not significant at this level (over the band's bins) carries
no trace of the input (``Measurement.require_response``)."""


def per_unit_mass_warning(rec: Measurement) -> str | None:
    """The warning an identification of ``rec`` carries when its coefficients are per unit mass (a base-excited
    single DOF's record without a mass: m = 1, ``"mass_normalised": true``), else None. The contract lets the mass
    be omitted, so this warns rather than refuses (a per-unit-mass model still gives the wells, the modes, the
    ratios k3/k1 and a free run); it is said, in the result and through ``warnings``, because every force and
    stiffness in it is one divided by the unknown mass.
    """
    if rec.mass is not None or rec.input_name != "base_acc" or rec.n_dof != 1:
        return None
    return (
        f"{rec.source}: no mass given (--mass, '# mass:' or from_arrays(..., mass=)): the coefficients are per unit "
        "mass (m = 1, mass_normalised): k0-k3, c and c_nl are the device's divided by its moving mass"
    )


@on_fit_threads  # the same numbers from a script and the command (``resources.on_fit_threads``)
def from_arrays(
    u: np.ndarray,
    z: np.ndarray | None,
    fs: float,
    input_name: str = "base_acc",
    *,
    mass: float | None = None,
    unknown_scale: str | None = None,
    gravity: float | None = None,
    decay: bool = False,
    **kw: Any,
) -> Measurement:
    """Build a measurement from arrays, validated like a file.

    The arrays must be 1-D, of one length (at least 2 samples), finite, within a shaker-table record's
    magnitudes in SI units; the sampling rate one a record has; the mass positive. With ``z`` None and a
    response column in ``kw``, z is derived from it as ``load`` does (``sensors.derive``).

    Parameters
    ----------
    u : numpy.ndarray
        The input, (N,): base acceleration [m/s^2] or force [N].
    z : numpy.ndarray or None
        Relative displacement [m], (T,), or a structure's responses (N, T) (each DOF's displacement relative
        to the base; one row is the single DOF's z); None when another response column is given (or for an
        input-only record).
    fs : float
        Sampling rate [Hz].
    input_name : {"base_acc", "force"}, default "base_acc"
        What ``u`` is.
    mass : float, optional
        The moving mass [kg] (a structure's: ``masses``, one per DOF). Without it an identification's
        coefficients are per unit mass (m = 1): its result says so (``"mass_normalised": true``) and warns
        (docs/contract.md); a force-driven record's mass is then estimated from the input's coefficient.
    unknown_scale : str, optional
        A response channel whose sensitivity is unknown (a file's ``*?``).
    gravity : float, optional
        The gravity along the motion [m/s^2] (0 for a horizontal device).
    decay : bool, default False
        The record is a free decay whatever ``u`` holds (``load``'s ``decay``).
    **kw
        Optional columns (``z_dot``, ``y``, ``base_disp``, ...), a structure's ``masses`` (one per DOF) [kg],
        ``force_dof`` (the DOF a force acts on), ``source`` (a name for messages), ``meta`` and
        ``aux`` (a dict of measured auxiliary channels, ``{"voltage": v}``).

    Returns
    -------
    Measurement
        The record, as ``load`` would give it from a file holding the same columns.

    Raises
    ------
    MeasurementError
        Arrays that are not a record (one line: which array and why).

    Examples
    --------
    >>> import numpy as np
    >>> from negstiff import from_arrays
    >>> t = np.arange(2048) / 512.0
    >>> rec = from_arrays(np.sin(2 * np.pi * 9 * t), 1e-3 * np.sin(2 * np.pi * 9 * t), 512.0, mass=0.2)
    >>> rec.duration, rec.mass
    (4.0, 0.2)
    >>> two = from_arrays(np.sin(t), [1e-4 * np.sin(t), 1e-3 * np.sin(t)], 512.0, masses=(1.0, 0.2))
    >>> two.n_dof, two.masses
    (2, (1.0, 0.2))
    """
    if not isinstance(input_name, str) or input_name not in INPUTS:
        raise MeasurementError(f"input must be one of {INPUTS}, got {input_name!r}")
    source = kw.get("source", "<memory>")
    if u is None:
        raise MeasurementError(f"{source}: the input u is None: give the {input_name} samples")
    aux_given = kw.get("aux")
    if aux_given is not None and not isinstance(aux_given, Mapping):
        raise MeasurementError(f"{source}: aux must map names to channels ({{'voltage': v}}), got "
                               f"{type(aux_given).__name__}")  # fmt: skip
    for key in aux_given or {}:
        if not isinstance(key, str) or not key.strip() or key.splitlines() != [key]:
            raise MeasurementError(f"{source}: aux channel names are one line of text, got {key!r}")
    for name, values in (("u", u), ("z", z), *((k, kw.get(k)) for k in OPTIONAL), *dict(aux_given or {}).items()):
        if values is not None and np.iscomplexobj(values):  # np.asarray(float) would drop the imaginary part
            raise MeasurementError(f"{source}: {name} is complex: a record's samples are real numbers")
    kw["mass"] = mass
    masses = kw.pop("masses", None)
    force_dof = kw.pop("force_dof", None)
    responses = None
    if z is not None:
        try:
            zz = np.asarray(z, dtype=float)
        except (TypeError, ValueError):
            raise MeasurementError(f"{source}: z is not an array of numbers") from None
        if zz.ndim == 2 and zz.shape[0] == 1:
            z = zz[0]  # one DOF: its z
        elif zz.ndim == 2:
            if any(kw.get(k) is not None for k in OPTIONAL):
                raise MeasurementError(f"{source}: a structure's record holds its responses z (N, T) alone")
            responses = {f"z{k + 1}": row for k, row in enumerate(zz)}
            z = None
    n_dof = 1 if responses is None else len(responses)
    if masses is not None:
        masses = checked_masses(source, masses, n_dof)
        if n_dof == 1:
            if kw.get("mass") is None:
                kw["mass"] = masses[0]
            masses = None
    if n_dof > 1 and kw.get("mass") is not None:
        raise MeasurementError(f"{source}: a record of {n_dof} DOFs takes its DOFs' masses (masses=), not one mass")
    force_dof = checked_force_dof(source, force_dof, n_dof)
    cols: dict[str, np.ndarray] = {}
    for name, values in ((input_name, u), ("z", z), *(responses or {}).items(),
                         *((k, kw[k]) for k in OPTIONAL if kw.get(k) is not None)):  # fmt: skip
        if values is None:
            continue
        try:
            arr = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            raise MeasurementError(f"{source}: {name} is not an array of numbers") from None
        if arr.ndim != 1:
            raise MeasurementError(f"{source}: {name} must be a 1-D array, got shape {arr.shape}")
        cols[name] = arr
    n = cols[input_name].size
    for name, arr in cols.items():
        if arr.size != n:
            raise MeasurementError(f"{source}: {name} has {arr.size} samples, {input_name} has {n}")
    if n < 2:
        raise MeasurementError(f"{source}: too few samples ({n}) for a record")
    check_values(source, cols)
    fs = check_sampling_rate(source, fs, "given")
    info = dict(kw.pop("info", {}))
    if decay:
        info["decay"] = True
    if z is None and any(k in cols for k in sensors.RESPONSES):
        z, info["response"] = sensors.derive(cols, input_name, fs, source, units_known=unknown_scale is None)
        if info["response"].get("trim_s"):
            what = info["response"]["measured"]
            raise MeasurementError(f"{source}: z from {what} needs the file's route (an integral's ends cut): "
                                   "derive z yourself, or write the record to a file")  # fmt: skip
    mass = kw.get("mass")
    scale_info = checked_unknown_scale(source, unknown_scale, input_name, mass, cols)
    if scale_info:
        info["scale"] = scale_info
    aux = kw.pop("aux", None) or {}
    aux = aux_channels(source, dict(aux), list(aux), n)
    kw = {**kw, **{k: cols[k] for k in OPTIONAL if k in cols}, "aux": aux}
    if responses is not None:
        z, info["response"] = channels.derive_channels(source, cols, dict(enumerate(responses, 1)), input_name, fs)
    rec = Measurement(fs=fs, input_name=input_name, u=cols[input_name], z=None if z is None else np.asarray(z, float),
                      **{**kw, "mass": None, "info": info, "masses": masses, "force_dof": force_dof})  # fmt: skip
    return rec.with_mass(mass).with_gravity(gravity)


STROKE_LIMIT_M = 1.0
"""A shaker-table device's relative displacement stays far below this [m]; beyond it, the record is
not in metres."""


ACC_LIMIT_M_S2 = 2000.0
"""Table accelerations beyond this rms [m/s^2] (200 g) are not in m/s^2."""
