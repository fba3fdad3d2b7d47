"""A record of a structure of N degrees of freedom: the input and every DOF's response.

The contract's multi-DOF record: the input column (``base_acc`` [m/s^2] or ``force`` [N]) and responses
``z1 ... zN`` [m] (each DOF's displacement relative to the base, from the rest position of the linear springs
loaded by the weights), with ``# masses: m1,...,mN`` [kg] in the header. A record keeps the states it
derives (its band-smoothed displacements and velocities) so that the estimators do not derive them twice.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError
from negstiff.inference.record.derivatives import smooth_and_differentiate, velocity_window
from negstiff.inference.record.measurement import check_sampling_rate, check_values, time_base
from negstiff.models.structure import relative

INPUTS = ("base_acc", "force")


@dataclass(frozen=True)
class StructureRecord:
    """Input ``u`` (T,) and responses ``z`` (N, T) of a structure of N DOFs sampled at ``fs`` [Hz].

    Parameters
    ----------
    fs : float
        Sampling rate [Hz].
    input_name : {"base_acc", "force"}
        What ``u`` is.
    u : (T,) array
        The input.
    z : (N, T) array
        Each DOF's displacement relative to the base [m].
    masses : tuple of float
        The DOFs' masses [kg] (the record's ``# masses:``); NSI and SINDy need them to turn the identified
        dynamics into stiffness and damping.
    source : str, default "<memory>"
        Where the record came from (named in every message).
    force_dof : int, optional
        The DOF a force input acts on (1..N); default the element's.
    meta : dict, optional
        The file's ``# key: value`` lines.

    Examples
    --------
    >>> import numpy as np
    >>> from negstiff import StructureRecord
    >>> t = np.arange(0, 10, 1 / 512)
    >>> rec = StructureRecord(512.0, "base_acc", np.sin(t), np.vstack([1e-4 * np.sin(t), 1e-3 * np.sin(t)]), (1.0, 0.2))
    >>> rec.n_dof, rec.n, rec.masses
    (2, 5120, (1.0, 0.2))
    """

    fs: float
    input_name: str
    u: np.ndarray
    z: np.ndarray
    masses: tuple[float, ...]
    source: str = "<memory>"
    force_dof: int | None = None
    meta: dict[str, str] = field(default_factory=dict)
    derived: dict[Any, Any] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        fs = check_sampling_rate(self.source, self.fs, "fs")
        object.__setattr__(self, "fs", fs)
        if self.input_name not in INPUTS:
            raise InputError(f"{self.source}: the input must be one of {', '.join(INPUTS)}, got {self.input_name!r}")
        u = np.asarray(self.u, dtype=float)
        z = np.atleast_2d(np.asarray(self.z, dtype=float))
        if u.ndim != 1 or z.ndim != 2 or z.shape[1] != u.size:
            raise InputError(
                f"{self.source}: responses must be (N, T) with T = the input's {u.size} samples, got {z.shape}"
            )
        check_values(self.source, {self.input_name: u})
        for i, zi in enumerate(z):  # each response against the displacement's limits, named by its DOF
            check_values(f"{self.source} (z{i + 1})", {"z": zi})
        masses = tuple(float(m) for m in self.masses)
        if len(masses) != z.shape[0] or not all(math.isfinite(m) and m > 0 for m in masses):
            raise InputError(
                f"{self.source}: masses must be {z.shape[0]} positive numbers (one per DOF, '# masses: m1,...'), "
                f"got {list(masses)}"
            )
        for name, a in (("u", u), ("z", z)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "masses", masses)

    @property
    def n(self) -> int:
        """Number of samples."""
        return self.u.size

    @property
    def n_dof(self) -> int:
        """Number of degrees of freedom."""
        return self.z.shape[0]

    @property
    def dt(self) -> float:
        """Sampling interval [s]."""
        return 1.0 / self.fs

    @property
    def t(self) -> np.ndarray:
        """Sample times [s] from 0."""
        return np.arange(self.n) * self.dt

    def segment(self, start: int | None, stop: int | None) -> StructureRecord:
        """Samples ``start:stop`` as a record of their own (kept: asked again, the same object)."""
        key = ("segment", start, stop)
        if key not in self.derived:
            sl = slice(start, stop)
            self.derived[key] = replace(self, u=self.u[sl], z=self.z[:, sl])
        return self.derived[key]

    def states(self, at: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
        """Band-smoothed displacements and velocities (N, T) of every DOF, with one Savitzky-Golay window for all
        (relative motions are differences of DOFs, which must be smoothed alike): the window the element's relative
        displacement z_J - z_I allows when ``at`` = (I, J) is given (the motion the nonlinear basis reads; a DOF
        that barely moves, like a stiff fixture's, is mostly sensor noise and would allow none), else the narrowest
        any DOF allows (``derivatives.velocity_window``). Computed once per record and ``at``; copies returned.
        """
        key = ("states", at)
        if key not in self.derived:
            if at is not None:
                w = velocity_window(relative(self.z, at), self.fs)
            else:
                w = min(velocity_window(zi, self.fs) for zi in self.z)
            pairs = [smooth_and_differentiate(zi, self.fs, w) for zi in self.z]
            self.derived[key] = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]), w)
        zs, v, w = self.derived[key]
        return zs.copy(), v.copy(), w

    def require(self, n_min: int, what: str) -> None:
        """One ``InputError`` when the record is shorter than ``n_min`` samples."""
        if self.n < n_min:
            raise InputError(f"{self.source}: {what} needs at least {n_min} samples, the record has {self.n}")


def structure_from_arrays(u, z, fs: float, masses, input_name: str = "base_acc", force_dof: int | None = None,
                          source: str = "<memory>") -> StructureRecord:  # fmt: skip
    """A multi-DOF record from arrays, with every check a file gets, before any work.

    Parameters
    ----------
    u : (T,) array
        The input: base acceleration [m/s^2] or force [N].
    z : (N, T) array
        Each DOF's displacement relative to the base [m].
    fs : float
        Sampling rate [Hz].
    masses : sequence of float
        The DOFs' masses [kg].
    input_name : {"base_acc", "force"}, default "base_acc"
        What ``u`` is.
    force_dof : int, optional
        The DOF a force acts on (default: the element's).
    source : str, default "<memory>"
        The name messages give the record.

    Returns
    -------
    StructureRecord
        The record.

    Examples
    --------
    >>> import numpy as np
    >>> from negstiff import structure_from_arrays
    >>> t = np.arange(0, 10, 1 / 512)
    >>> rec = structure_from_arrays(np.sin(t), [1e-4 * np.sin(t), 1e-3 * np.sin(t)], 512, masses=(1.0, 0.2))
    >>> rec.n_dof
    2
    """
    return StructureRecord(float(fs), input_name, np.asarray(u, float), np.asarray(z, float), tuple(masses), source,
                           force_dof)  # fmt: skip


_RESPONSE = re.compile(r"^z(\d+)$")


def load_structure(path: str | Path, fs: float | None = None, masses=None) -> StructureRecord:
    """Read a structure's CSV record, the contract's multi-DOF file.

    ``# key: value`` header lines (``fs``, ``masses``), a header row, then the numbers: ``t`` (optional with
    ``# fs:``), the input column (``base_acc`` or ``force``) and the responses ``z1`` to ``zN``.

    Parameters
    ----------
    path : str or pathlib.Path
        The CSV file.
    fs : float, optional
        Sampling rate [Hz], in place of the file's ``t`` column or ``# fs:``.
    masses : sequence of float, optional
        The DOFs' masses [kg], in place of the file's ``# masses:``.

    Returns
    -------
    StructureRecord
        The record; one ``InputError`` naming the file and the problem otherwise.

    Examples
    --------
    >>> from negstiff import load_structure
    >>> from negstiff.models.structure_rig import StructureRig
    >>> path = StructureRig.device_on_fixture(seed=1).random(duration=5.0).write("fixture.csv")
    >>> rec = load_structure(path)
    >>> rec.n_dof, rec.masses
    (2, (1.0, 0.212))
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: no such file")
    meta: dict[str, str] = {}
    header: list[str] | None = None
    with p.open() as fh:
        for line in fh:
            s = line.strip()
            if s.startswith("#"):
                if ":" in s:
                    k, v = s[1:].split(":", 1)
                    meta[k.strip().lower()] = v.strip()
                continue
            if s:
                header = [h.strip() for h in s.split(",")]
                break
    if header is None:
        raise InputError(f"{p}: no header row (columns t, base_acc or force, z1 ... zN)")
    try:
        data = np.loadtxt(p, delimiter=",", comments="#", skiprows=1 + sum(1 for _ in _header_lines(p)), ndmin=2)
    except ValueError as exc:
        raise InputError(f"{p}: unreadable numbers ({str(exc).splitlines()[0]})") from None
    if data.shape[1] != len(header):
        raise InputError(f"{p}: {len(header)} column names but {data.shape[1]} columns of numbers")
    cols = dict(zip(header, data.T, strict=True))
    inputs = [c for c in INPUTS if c in cols]
    if len(inputs) != 1:
        raise InputError(f"{p}: needs exactly one input column (base_acc or force), has {inputs or 'none'}")
    dofs = sorted((int(m.group(1)), name) for name in cols if (m := _RESPONSE.match(name)))
    if not dofs or [d for d, _ in dofs] != list(range(1, len(dofs) + 1)):
        raise InputError(f"{p}: responses must be z1 ... zN, consecutive; found {[n for _, n in dofs] or 'none'}")
    rate = _rate(p, cols.get("t"), meta.get("fs"), fs)
    mass = masses if masses is not None else meta.get("masses")
    if mass is None:
        raise InputError(f"{p}: the masses are not given ('# masses: m1,...,mN' in the header, or --masses)")
    if isinstance(mass, str):
        try:
            mass = [float(x) for x in mass.split(",")]
        except ValueError:
            raise InputError(f"{p}: '# masses:' must be numbers separated by commas, got {mass!r}") from None
    force_dof = int(meta["force_dof"]) if "force_dof" in meta else None
    return StructureRecord(rate, inputs[0], cols[inputs[0]], np.array([cols[n] for _, n in dofs]), tuple(mass), str(p),
                           force_dof, meta)  # fmt: skip


def _header_lines(p: Path):
    with p.open() as fh:
        for line in fh:
            if line.strip().startswith("#"):
                yield line
            else:
                return


def _rate(p: Path, t, meta_fs, fs) -> float:
    if fs is not None:
        return check_sampling_rate(p, fs, "--fs")
    if t is not None and t.size > 1:
        step = time_base(t, None, p)[0]  # the single-DOF reader's clock check: uniform within 1 % of a step
        return check_sampling_rate(p, 1.0 / step, "the t column")
    if meta_fs is not None:
        try:
            return check_sampling_rate(p, float(meta_fs), "'# fs:'")
        except ValueError:
            raise InputError(f"{p}: '# fs:' is not a number: {meta_fs!r}") from None
    raise InputError(f"{p}: no sampling rate (a t column, '# fs:' or --fs)")
