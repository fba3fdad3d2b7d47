"""Structures of N degrees of freedom carrying one nonlinear element (the device).

Each DOF's displacement z_i is relative to the base, measured from the rest position of the linear
springs loaded by the weights. The element acts on the relative motion r = z_J - z_I of DOF J and the DOF I
it is attached to (I = 0: the base):

    M z'' + C z' + K z + l F(r, r') = -M 1 b''  (base excitation)   or   = e_k f  (a force at DOF k)
    l = e_J - e_I,   F(r, r') = K_e(r) + D(r') + extra(r, r')

F is the single-DOF model's force law (``Model``: K_e(r) = k3 r^3 + k2 r^2 - k1 r + k0, its damping and
extra effects), k0 included: the element's force, its constant too, acts on J and with the opposite sign on
I (Newton's third law). (Physically the weight of J is not transmitted to I like that; the difference
is a constant force on I, which a linear spring path from I to the base turns into a shift of the rest
position the displacements are measured from.) K and C are the linear structure without the element.

The single-DOF ``Model`` is the case N = 1 (J = 1 on the base, K = C = 0): ``Structure.single(model)``
simulates through the same compiled kernel with the same numbers to the last bit (tested), and every
quantity here (equilibria, underlying-linear modes) reduces to the model's.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np

from negstiff.errors import InputError

from . import effects
from .equation import Equilibria, Model
from .kernel import KINDS
from .simulator import (
    DEFAULT_SUBSTEPS,
    DEFAULT_V_LIMIT,
    DEFAULT_Z_LIMIT,
    SimulationResult,
    checked_input,
    input_gain,
    integrate,
    stage_input,
)


@dataclass(frozen=True)
class Mode:
    """One mode of an underlying-linear system: frequency [Hz] (|lambda| / 2 pi), damping ratio, shape."""

    f_hz: float
    zeta: float
    shape: tuple[float, ...]
    """Displacement shape over the DOFs, its largest component 1 (real part, the phase of that component
    removed)."""

    def to_json(self) -> dict[str, Any]:
        """The result JSON's mode: f_hz, zeta, shape."""
        return {"f_hz": self.f_hz, "zeta": self.zeta, "shape": list(self.shape)}


def modes_of(mass: np.ndarray, K: np.ndarray, C: np.ndarray) -> list[Mode]:
    """The modes of M x'' + C x' + K x = 0, sorted by frequency (the eigenvalues of the first-order form)."""
    n = len(mass)
    minv = 1.0 / np.asarray(mass, float)
    A = np.zeros((2 * n, 2 * n))
    A[:n, n:] = np.eye(n)
    A[n:, :n] = -minv[:, None] * K
    A[n:, n:] = -minv[:, None] * C
    return modes_of_state_matrix(A, np.hstack([np.eye(n), np.zeros((n, n))]))


def modes_of_state_matrix(A: np.ndarray, C_out: np.ndarray) -> list[Mode]:
    """Modes of a continuous state matrix seen through displacement outputs ``C_out``: every pole pair with
    Im > 0 (underdamped), by frequency; overdamped real poles are not modes and are left out.
    """
    lam, psi = np.linalg.eig(A)
    out = []
    for r in np.flatnonzero(lam.imag > 0):
        shape = C_out @ psi[:, r]
        k = int(np.argmax(np.abs(shape)))
        shape = (shape / shape[k]).real
        out.append(
            Mode(float(abs(lam[r]) / (2 * math.pi)), float(-lam[r].real / abs(lam[r])), tuple(map(float, shape)))
        )
    return sorted(out, key=lambda m: m.f_hz)


def coupling(n: int, at: tuple[int, int]) -> np.ndarray:
    """Coupling vector l = e_J - e_I of an element at (I, J) among ``n`` DOFs (I = 0: the base): where its
    force acts, + on J and - on I.
    """
    lvec = np.zeros(n)
    lvec[at[1] - 1] = 1.0
    if at[0]:
        lvec[at[0] - 1] = -1.0
    return lvec


def relative(x: np.ndarray, at: tuple[int, int]) -> np.ndarray:
    """The element's relative motion x_J - x_I (x_J on the base) of per-DOF rows ``x`` (DOFs on axis -2 or 0)."""
    i, j = at
    x = np.asarray(x)
    rows = (lambda k: x[..., k - 1, :]) if x.ndim > 2 else (lambda k: x[k - 1])
    return rows(j) - rows(i) if i else rows(j).copy()


def assemble(pairs, values, n: int) -> np.ndarray:
    """The symmetric matrix of springs (or dampers) ``values`` joining DOF pairs (d, e) (e = 0: to the base)."""
    K = np.zeros((n, n))
    for (d, e), k in zip(pairs, values, strict=True):
        K[d - 1, d - 1] += k
        if e:
            K[e - 1, e - 1] += k
            K[d - 1, e - 1] -= k
            K[e - 1, d - 1] -= k
    return K


MAX_DOFS = 1000
"""The most DOFs a structure may have: its matrices are dense (N x N), its simulation loops over them."""


def _matrix(name: str, value, n: int) -> np.ndarray:
    a = np.zeros((n, n)) if value is None else np.array(value, dtype=float)
    if a.shape != (n, n):
        raise InputError(f"structure {name} must be {n} x {n} (one row per DOF), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"structure {name} contains NaN or inf")
    if not np.allclose(a, a.T, rtol=1e-12, atol=1e-12 * max(1.0, float(np.abs(a).max(initial=0.0)))):
        raise InputError(f"structure {name} must be symmetric (springs and dampers act both ways)")
    return a


@dataclass(frozen=True, eq=False)
class Structure:
    """N degrees of freedom: masses, a linear structure (stiffness and damping matrices, the element
    excluded) and one nonlinear element between DOF ``at[0]`` (0: the base) and DOF ``at[1]``.

    Parameters
    ----------
    masses : sequence of float
        The DOFs' masses [kg], m_1 ... m_N.
    element : Model
        The element's force law on the relative motion (a single-DOF ``Model``; its ``m`` must be the mass
        of the DOF it moves, which sets its default k0 = m g).
    stiffness, damping : (N, N) array, optional
        The linear structure without the element [N/m, N s/m], symmetric; default none.
    at : (int, int), default (0, N)
        (I, J): the element moves DOF J relative to DOF I (0: the base). DOFs count from 1.

    Examples
    --------
    >>> from negstiff import Model
    >>> from negstiff.models.structure import Structure
    >>> device = Model(m=0.2, k1=435.0, k2=1000.0, k3=6.7e5, c=0.6, c_nl=0.4)
    >>> s = Structure.on_fixture(device, fixture_mass=1.0, fixture_hz=25.0, fixture_zeta=0.02)
    >>> [round(m.f_hz, 1) for m in s.modes("plus")]
    [8.5, 25.3]
    """

    masses: tuple[float, ...]
    element: Model
    stiffness: np.ndarray | None = None
    damping: np.ndarray | None = None
    at: tuple[int, int] | None = None

    def __post_init__(self):
        given = self.masses
        if isinstance(given, (str, bytes)) or not np.iterable(given):  # a number alone: one DOF
            given = [given]
        if len(given) > MAX_DOFS:  # before any N x N matrix (100,000 DOFs asked for 74.5 GiB)
            raise InputError(f"a structure of {len(given)} DOFs: negstiff's structures are lumped models of at "
                             f"most {MAX_DOFS} DOFs")  # fmt: skip
        try:  # each mass a number as given (a JSON true is not 1 kg)
            masses = tuple(effects.finite(f"m{i + 1}", m) for i, m in enumerate(given))
        except ValueError as exc:  # not a number: negstiff's error, the registry's words
            raise InputError(str(exc)) from None
        if not masses or min(masses) <= 0:
            raise InputError(f"structure masses must be positive, got {list(masses)}")
        n = len(masses)
        object.__setattr__(self, "masses", masses)
        if not isinstance(self.element, Model):
            raise InputError("the element's force law must be a Model (polynomial) in a structure")
        if self.at is not None and (isinstance(self.at, (str, bytes)) or not np.iterable(self.at) or any(
                isinstance(a, bool) or not isinstance(a, (int, np.integer)) for a in self.at)):  # fmt: skip
            raise InputError(f"element I-J must be two DOF numbers (integers, 0: the base), got {self.at!r}")
        at = (0, n) if self.at is None else tuple(int(a) for a in self.at)
        if len(at) != 2 or not (0 <= at[0] <= n and 1 <= at[1] <= n and at[0] != at[1]):
            raise InputError(f"element I-J must name DOF J in 1..{n} and I in 0..{n} (0: the base), I != J; got {at}")
        object.__setattr__(self, "at", at)
        object.__setattr__(self, "stiffness", _matrix("stiffness", self.stiffness, n))
        object.__setattr__(self, "damping", _matrix("damping", self.damping, n))
        mj = masses[at[1] - 1]
        if not math.isclose(self.element.m, mj, rel_tol=1e-12):
            raise InputError(f"the element's mass {self.element.m:g} kg is not m{at[1]} = {mj:g} kg, the DOF it moves")

    # --- construction -------------------------------------------------------------------------------
    @classmethod
    def single(cls, model: Model) -> Structure:
        """The single-DOF model as a structure of one DOF (the element on the base)."""
        return cls((model.m,), model)

    @classmethod
    def unchecked(cls, masses: tuple[float, ...], element: Model, K: np.ndarray, C: np.ndarray,
                  at: tuple[int, int]) -> Structure:  # fmt: skip
        """A structure from parts the package made itself and checked once (a refinement's parameter points, each
        a checked structure with other values), without ``__post_init__``'s checks of a user's input: building one
        per point cost a single DOF's refinement 10 % of its time (measured).
        """
        new = object.__new__(cls)
        for name, value in (("masses", tuple(masses)), ("element", element), ("stiffness", K), ("damping", C),
                            ("at", tuple(at))):  # fmt: skip
            object.__setattr__(new, name, value)
        return new

    @classmethod
    def on_fixture(cls, element: Model, *, fixture_mass: float, fixture_hz: float, fixture_zeta: float) -> Structure:
        """The element's mass on a fixture (DOF 1) sprung to the base: fixture frequency and damping ratio
        of the fixture alone (its mass on its spring), the element between the fixture and DOF 2.
        """
        k = fixture_mass * (2 * math.pi * fixture_hz) ** 2
        c = 2 * fixture_zeta * math.sqrt(k * fixture_mass)
        return cls(
            (fixture_mass, element.m),
            element,
            np.array([[k, 0.0], [0.0, 0.0]]),
            np.array([[c, 0.0], [0.0, 0.0]]),
            (1, 2),
        )

    @classmethod
    def chain(cls, masses: Sequence[float], springs: Sequence[float], dampers: Sequence[float], element: Model,
              at: tuple[int, int]) -> Structure:  # fmt: skip
        """A chain: spring/damper i joins DOF i to DOF i - 1 (DOF 0 the base); zero for none."""
        n = len(masses)
        if len(springs) != n or len(dampers) != n:
            raise InputError(f"a chain of {n} DOFs needs {n} springs and {n} dampers (0 for none)")
        pairs = [(i + 1, i) for i in range(n)]  # spring i + 1 joins DOF i + 1 to DOF i (0: the base)
        K, C = assemble(pairs, springs, n), assemble(pairs, dampers, n)
        return cls(tuple(masses), element, K, C, at)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Structure):
            return NotImplemented
        return (self.masses, self.element, self.at) == (other.masses, other.element, other.at) and all(
            np.array_equal(a, b) for a, b in ((self.K, other.K), (self.C, other.C))
        )

    __hash__ = None  # type: ignore[assignment]

    @property
    def n_dof(self) -> int:
        """Number of degrees of freedom."""
        return len(self.masses)

    @property
    def place(self) -> tuple[int, int]:
        """(I, J): the element moves DOF J relative to DOF I (0: the base)."""
        return cast(tuple[int, int], self.at)

    @property
    def K(self) -> np.ndarray:
        """The linear structure's stiffness matrix [N/m] (the element excluded)."""
        return cast(np.ndarray, self.stiffness)

    @property
    def C(self) -> np.ndarray:
        """The linear structure's damping matrix [N s/m] (the element excluded)."""
        return cast(np.ndarray, self.damping)

    @property
    def coupling(self) -> np.ndarray:
        """L = e_J - e_I: where the element's force acts (+ on J, - on I)."""
        return coupling(self.n_dof, self.place)

    def with_element(self, element: Model) -> Structure:
        """The same structure with another element (a fitted one)."""
        return replace(self, element=element)

    # --- statics and linearisation ----------------------------------------------------------------
    def _static(self, r: float) -> np.ndarray:
        """The linear structure's static solution with relative displacement r held across the element: every
        DOF's position and, last, the force lambda the element must carry (K z + l lambda = 0, l . z = r).
        """
        n, lvec = self.n_dof, self.coupling
        a = np.zeros((n + 1, n + 1))
        a[:n, :n] = self.K
        a[:n, n] = lvec
        a[n, :n] = lvec
        return np.linalg.lstsq(a, np.r_[np.zeros(n), r], rcond=None)[0]

    def _series_stiffness(self) -> float:
        """kappa: the linear structure's stiffness seen across the element (the static force lambda(r) = kappa r
        with which it resists a relative displacement r), 0 when DOF J hangs on the element alone.
        """
        return float(self._static(1.0)[-1])

    def static_positions(self, r: float) -> np.ndarray:
        """The DOFs' static positions with relative displacement r across the element."""
        return self._static(r)[:-1]

    def element_law(self) -> Model:
        """The element's law as the relative displacement r across it sees the structure at rest: F(r) - kappa r
        (``_series_stiffness``; a spring k in parallel with the element has kappa = -k): the cubic's -k1 r becomes
        -(k1 + kappa) r. The element itself for N = 1.
        """
        return replace(self.element, k1=self.element.k1 + self._series_stiffness())

    def element_equilibria(self) -> Equilibria:
        """Equilibria of the relative displacement r across the element (``element_law``'s), the element's own
        equilibria for N = 1.
        """
        return self.element_law().equilibria()

    def equilibria(self) -> dict[str, np.ndarray]:
        """Static positions of every DOF [m] at each stable equilibrium (``"minus"``, ``"plus"``)."""
        eq = self.element_equilibria()
        return {w: self.static_positions(eq.well(w)) for w in ("minus", "plus") if getattr(eq, f"z_{w}") is not None}

    def linear(self, well: str) -> tuple[np.ndarray, np.ndarray]:
        """Stiffness and damping matrices of the underlying-linear system at a well (the element
        linearised: its K_e'(r*) and c across I-J).
        """
        r = self.element_equilibria().well(well)
        lvec = self.coupling
        ll = np.outer(lvec, lvec)
        return self.K + float(self.element.stiffness(r)) * ll, self.C + self.element.c * ll

    def modes(self, well: str) -> list[Mode]:
        """The underlying-linear system's modes at a well, by frequency."""
        K, C = self.linear(well)
        return modes_of(np.asarray(self.masses), K, C)

    # --- serialisation --------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The structure as JSON fields (masses, element, at, stiffness, damping)."""
        return {
            "masses": list(self.masses),
            "element": self.element.to_dict(),
            "at": list(self.place),
            "stiffness": np.asarray(self.stiffness).tolist(),
            "damping": np.asarray(self.damping).tolist(),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Structure:
        """Build from ``to_dict``'s fields; one ``InputError`` when they do not make a structure."""
        unknown = set(d) - {"masses", "element", "at", "stiffness", "damping"}
        if unknown:
            raise InputError(f"structure has unknown fields {', '.join(sorted(unknown))}")
        try:
            element = Model.from_dict(d["element"])
            at = d.get("at") or (0, 1)
            at = at if isinstance(at, str) else tuple(at)  # a text is refused as written, not read digit by digit
            return cls(d["masses"], element, d.get("stiffness"), d.get("damping"), at)  # type: ignore[arg-type]
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"structure: {exc}") from None

    # --- simulation ---------------------------------------------------------------------------------
    def simulate(self, u: np.ndarray, dt: float, *, z0: float | None = None, input_kind: str = "base_acc",
                 force_dof: int | None = None, substeps: int = DEFAULT_SUBSTEPS, z_limit: float = DEFAULT_Z_LIMIT,
                 v_limit: float = DEFAULT_V_LIMIT) -> SimulationResult:  # fmt: skip
        """The structure under a sampled input (band-limited between samples, ``stage_input``), from rest with the
        element's relative displacement at ``z0`` (default: the plus well's); ``z``, ``z_dot`` of shape (1, N, T).
        """
        r0 = self.element_equilibria().z_plus if z0 is None else float(z0)
        x0 = np.r_[self.static_positions(r0), np.zeros(self.n_dof)]
        return simulate_structures(self, stage_input(u, substeps), dt, x0, input_kind=input_kind, force_dof=force_dof,
                                   substeps=substeps, store_velocity=True, z_limit=z_limit, v_limit=v_limit,
                                   staged=True)  # fmt: skip

    def arrays(self, input_kind: str = "base_acc", force_dof: int | None = None):
        """The kernel's arrays of this structure: element parameters (P,), inverse masses (N,), K, C, input
        gain (N,).
        """
        mass = np.asarray(self.masses)
        if input_kind == "base_acc":
            gain = input_gain("base_acc", mass)
        else:
            k = self.place[1] if force_dof is None else int(force_dof)
            if not 1 <= k <= self.n_dof:
                raise InputError(f"the force acts on a DOF 1..{self.n_dof}, got {k}")
            gain = np.zeros(self.n_dof)
            gain[k - 1] = input_gain("force", mass[k - 1 : k])[0]
        return self.element.kernel_params(), 1.0 / mass, self.K, self.C, gain


def as_structure(system) -> Structure:
    """A ``Structure`` as itself, a single-DOF ``Model`` as the structure of one DOF on the base
    (``Structure.single``): what reads any N reads a single DOF's model through this.
    """
    return system if isinstance(system, Structure) else Structure.single(system)


def simulate_structures(
    structures: Structure | Sequence[Structure],
    u: np.ndarray,
    dt: float,
    x0: np.ndarray,
    *,
    input_kind: str = "base_acc",
    force_dof: int | None = None,
    input_index: np.ndarray | None = None,
    structure_index: np.ndarray | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
    store_velocity: bool = False,
    z_limit: float = DEFAULT_Z_LIMIT,
    v_limit: float = DEFAULT_V_LIMIT,
    threads: int | None = None,
    staged: bool = False,
    hook: tuple | None = None,
) -> SimulationResult:
    """Integrate B structures (one, repeated for every start state, or one per member; same N and element
    DOFs) from states ``x0`` (B, 2N) = [z_1..z_N, z_1'..z_N'] under the input rows ``u`` (the conventions of
    ``simulate_batch``: linear interpolation between samples, or the input at the stage times).
    ``structure_index`` (B,): member b runs ``structures[structure_index[b]]`` (a refinement's parameter points
    over its windows: each structure's arrays made once). ``hook``: the extra force on the element
    (``kernel.extra_term``'s arguments: a hybrid term of the element's relative motion and the input; with a
    staged input, whose stage values it reads), shared by the batch.
    """
    if hook is not None and not staged:
        raise InputError("the extra force hook reads the input at the stage times: give it staged (staged=True)")
    x0 = np.atleast_2d(np.asarray(x0, dtype=np.float64))
    unique: list[Structure] = [structures] if isinstance(structures, Structure) else list(structures)
    if structure_index is not None:
        member = np.asarray(structure_index, dtype=np.intp)
    elif isinstance(structures, Structure):
        member = np.zeros(x0.shape[0], dtype=np.intp)
    else:
        member = np.arange(len(unique), dtype=np.intp)
    nb = member.size
    nd = unique[0].n_dof
    if any(s.n_dof != nd or s.at != unique[0].at for s in unique):
        raise InputError("a batch of structures must share the number of DOFs and the element's place")
    if member.size and not (0 <= member.min() and member.max() < len(unique)):
        raise InputError(f"structure_index must name structures 0..{len(unique) - 1}")
    x0 = np.broadcast_to(x0, (nb, 2 * nd))
    if not np.all(np.isfinite(x0)):
        raise InputError("initial state contains NaN or inf")
    parts = [s.arrays(input_kind, force_dof) for s in unique]
    p = np.ascontiguousarray(np.stack([q[0] for q in parts], axis=1)[:, member])
    minv = np.ascontiguousarray(np.stack([q[1] for q in parts], axis=1)[:, member])
    lk = np.ascontiguousarray(np.stack([q[2] for q in parts], axis=2)[:, :, member])
    lc = np.ascontiguousarray(np.stack([q[3] for q in parts], axis=2)[:, :, member])
    gain = np.ascontiguousarray(np.stack([q[4] for q in parts], axis=1)[:, member])
    u2, uidx, n = checked_input(u, dt, substeps, input_index, nb, staged)
    oz, ov, status, fail = integrate(
        KINDS[unique[0].element.kind], p, minv, lk, lc, gain, u2, uidx, n, dt, substeps, x0[:, :nd].T, x0[:, nd:].T,
        place=unique[0].place, store_velocity=store_velocity, z_limit=z_limit, v_limit=v_limit, threads=threads,
        hook=hook,
    )  # fmt: skip
    return SimulationResult(
        np.transpose(oz, (2, 1, 0)),
        None if ov is None else np.transpose(ov, (2, 1, 0)),
        status,
        np.where(fail >= 0, fail * dt, np.nan),
        dt,
    )
