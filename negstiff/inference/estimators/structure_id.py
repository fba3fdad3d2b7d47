"""NSI, SINDy and the discrepancy workflow on a record of N > 1 degrees of freedom: the N-DOF branch of the one
estimator per method (``NSI``, ``SINDy``, ``Discrepancy`` with ``element="I-J"``), for a structure carrying one
nonlinear element (``models.structure``). The estimators call these functions when ``rec.n_dof > 1``; a record of
one DOF takes the single-DOF algorithms unchanged.

**Each channel's zero.** A laser's zero is arbitrary: each response channel carries an unknown constant o_d. The
equations of motion in the measured coordinates then hold a constant force b_d on every DOF (the linear springs'
K o and the element's constant, which cannot be told apart from the record), estimated with the other
parameters, as the single DOF's constant term is. The physical frame (each DOF's displacement from the rest
position of the linear springs loaded by the weights, the contract's) is then pinned by the physics
(``physical_frame``): no constant force but the element's, whose constant is the weight it carries,
K_e(0) = m_J g (g: the record's ``gravity``, 0 for a horizontal device), as the single DOF's frame is pinned by
K(0) = m g. The offsets found are in the result (``offsets_m``), and every free run is compared with the record
in the record's own frame.

**NSI** as the method was made for (Marchesiello & Garibaldi 2008): the element's basis functions of the relative
motion r = z_J - z_I about a reference r* (x^2, x^3, r'|r'|, x = r - r*) are feedback inputs of the underlying-
linear system (ULS), M x'' + C x' + K x = M 1 u - l sum_j mu_j g_j (l = e_J - e_I), identified with every DOF's
displacement as an output by the package's LTI subspace step (``subspace``, PO-MOESP, state order
``order`` x N). Then, around each well: the ULS's modes (the identified state matrix's poles and shapes); its
physical matrices (the identified (A, C) turned into physical coordinates by T = [C; C A], whose lower blocks are
-M^-1 K and -M^-1 C); the element's coefficients mu_j from the extended FRF H_e = H [M 1, l mu_1, ...]:
Z(w) H_e = [M 1, l mu_1, ...] with Z = K - w^2 M + i w C, its input column scaling out the level error of the
discrete-to-continuous step, mu_j(w) = l . (Z H_e,j) / |l|^2 averaged (Re) over the modes' band, |Im/Re| the
quality index. The element's linear part is the ULS's I-J coupling; the constant forces follow from the
time-averaged equations of motion, and the reference moves to the identified structure's equilibrium for the next
pass.

**SINDy** with one equation per DOF in the weak form (``weak.test_function``, as the single-DOF SINDy): the
element's terms are shared between the two DOFs it connects with opposite signs (Newton's third law, one shared
coefficient per term), the linear structure's springs and dampers are columns of the DOFs they join, each DOF has
its constant force, the input's coefficient is fixed by the masses. Sparsity and selection are the single DOF's
rules: a path of L0 weights (pysindy's STLSQ at the threshold sqrt(2 weight) on the column-scaled system), each
support refitted on the first part of the identification data and scored on the next by its weak residual in
blocks of ``window_s``; the sparsest support within max(one standard error of the paired block differences,
``margin``) of the best (``selection.indistinguishable``), refitted on all identification data; pysindy's
bagging ensemble at the selected weight gives each term's inclusion probability.

**Discrepancy**: the element's base law with the linear structure is the baseline; each registered effect with a
column of its own is added as a term of the element and scored like SINDy's supports, on held-out blocks. An
effect is named when it lowers the held-out weak residual by more than max(one standard error of the paired block
differences, ``margin``) (``selection.compare``, the single DOF's rule); among those, the largest gain.

**Refinement** (``refine``, as a single DOF's): the method's structure refined by output error, the one
``refine.refine_stage``: every channel's error over the identification part's restarted windows, the element's
coefficients, the linear structure's nonzero entries and each channel's zero moved together, the element's constant
held at the weight its frame pins (``weight_pinned``), kept only if it predicts the held-out windows no worse. On
the tests' fixture record it took NSI's and SINDy's elements from k2 +0.67 / +0.47 % to -0.03 / -0.09 % of the
truth and NSI's plus-well device mode from +0.25 % to +0.002 % (measured).

Every result reports the same keys (``modal``, ``element``, ``linear``, ``equilibria``, ``offsets_m``,
``validation``, ``refinement``); validation is ``free_run_error``: free runs over the held-out tail restarted every
0.25 s from the record's smoothed states, and a model that misses them by more than twice what the channels' sensor
noise alone explains is warned about.
"""

from __future__ import annotations

import dataclasses
import math
import re
import warnings
from dataclasses import dataclass, field
from typing import Any, override

import numpy as np
from scipy import optimize

from negstiff.errors import InputError, issue
from negstiff.errors import NegstiffWarning as _Warning
from negstiff.inference.estimators.parameters import Constraint
from negstiff.inference.estimators.state_space_id import StateSpaceIdentification
from negstiff.inference.record.derivatives import band_limited, basis_band_hz
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.plausibility import judgement, model_warnings
from negstiff.inference.steps.refine import refine_stage
from negstiff.inference.steps.selection import block_rows, block_scores, compare, indistinguishable
from negstiff.inference.steps.validation import restarted_structure_runs as free_run_error
from negstiff.inference.steps.weak import test_function, test_function_half_width, weak_project
from negstiff.models import Model
from negstiff.models.simulator import stage_input
from negstiff.models.structure import (
    Mode,
    Structure,
    assemble,
    coupling,
    modes_of_state_matrix,
    relative,
    simulate_structures,
)

from . import subspace

ELEMENT_TERMS = ("r", "r^2", "r^3", "v", "v|v|")
"""The element's regressed library: F(r, r') = k0 - k1 r + k2 r^2 + k3 r^3 + c r' + c_nl r'|r'| (the single-DOF
names); its constant k0 is not regressed (each DOF's constant force holds it) but pinned (``physical_frame``)."""

_FIELDS = {"r": ("k1", -1.0), "r^2": ("k2", 1.0), "r^3": ("k3", 1.0), "v": ("c", 1.0), "v|v|": ("c_nl", 1.0)}

ASYMMETRY_WARNING = 0.05
"""NSI warns when the identified stiffness matrix's asymmetry exceeds this share of its largest entry: the
record's masses scale the identified M^-1 K back to K, and wrong masses leave it lopsided."""

NOISE_FLOOR_FACTOR = 2.0
"""A model whose held-out free runs miss the record by more than this many times what the channels' sensor noise
alone explains is warned about."""

WINDOW_S = 0.25
"""Held-out free runs' length [s]: two periods of the wells (over cross-well chaos a 1 s run diverges for any
model, the truth too, and then a model that moves less scores better)."""


class StructureIdentificationError(InputError):
    """The record cannot be identified as a structure with one element (too short, wrong element, no modes)."""


_PLACE = re.compile(r"^\s*(\d+)\s*-\s*(\d+)\s*$")


@dataclass(frozen=True)
class ElementPlace(Constraint):
    """Where the nonlinear element acts: None (the single DOF, on the base), ``"I-J"`` or a pair (I, J) of
    integers, J >= 1 the DOF it moves, I >= 0 the one it is attached to (0: the base), I != J.
    """

    @override
    def accepts(self, value) -> bool:
        if value is None:
            return True
        if isinstance(value, str):
            m = _PLACE.match(value)
            if not m:
                return False
            i, j = int(m.group(1)), int(m.group(2))
        elif (
            isinstance(value, (tuple, list))
            and len(value) == 2
            and all(isinstance(x, (int, np.integer)) and not isinstance(x, bool) for x in value)
        ):
            i, j = (int(x) for x in value)
        else:
            return False
        return i >= 0 and j >= 1 and i != j

    @override
    def describe(self) -> str:
        return "None (the single DOF) or I-J: the DOF J >= 1 the element moves and the DOF I >= 0 it is attached to "
        "(0: the base), I != J"


def parse_element(text: str | tuple[int, int], n_dof: int) -> tuple[int, int]:
    """``"I-J"`` (J the DOF the element moves, I the one it is attached to, 0 the base) as (I, J), checked."""
    if isinstance(text, str):
        m = _PLACE.match(text)
        if not m:
            raise InputError(f"element must be I-J (e.g. 1-2; 0 is the base), got {text!r}")
        i, j = int(m.group(1)), int(m.group(2))
    else:
        i, j = (int(x) for x in text)
    if not (0 <= i <= n_dof and 1 <= j <= n_dof and i != j):
        raise InputError(f"element {i}-{j}: J must be a DOF 1..{n_dof}, I one of 0..{n_dof} (0: the base), I != J")
    return i, j


def element_of(est, rec: Measurement) -> tuple[int, int] | None:
    """The element's place on ``rec`` for estimator ``est`` (its ``element``, else the record's ``# element:`` as
    its ``masses`` come from ``# masses:``): None for a record of one DOF (the single-DOF algorithms; its element
    can only be on the base), else (I, J), checked, with the record's masses. One ``InputError`` before any work
    otherwise.
    """
    name = type(est).__name__
    given = est.element if est.element is not None else (rec.meta or {}).get("element")
    said = f"{name}(element={given!r})" if est.element is not None else f"{rec.source}: '# element: {given}'"
    if rec.n_dof == 1:
        if given is not None and parse_element(given, 1) != (0, 1):
            raise InputError(f"{said}: a record of one DOF has its element on the base (0-1)")
        return None
    if given is None:
        raise InputError(f"{rec.source}: a record of {rec.n_dof} DOFs needs the element's place "
                         f"({name}(element='I-J'), --element I-J, or '# element: I-J' in its header)")  # fmt: skip
    try:
        at = parse_element(given, rec.n_dof)
    except InputError as exc:
        raise InputError(f"{said}: {exc}" if est.element is None else str(exc)) from None
    if rec.masses is None and not getattr(est, "reads_sensors_without_masses", False):
        # NSI reads such a record through a state-space linear part (``state_space_id``); the weak form's equations
        # per DOF need each DOF's mass
        rec.dof_masses  # noqa: B018 - one MeasurementError without them, before any work
    if rec.masses is None and getattr(est, "refine", None) is True:
        # the state-space linear part (``state_space_id``) is judged on held-out windows, not refined: output error
        # over a state-space model's A, B, C, D is a prediction-error method of its own, not written yet
        raise InputError(f"{name}(refine=True): a structure read through its sensors without masses (a state-space "
                         "linear part) is not refined by output error; give the masses ('# masses:', --masses) to "
                         "refine its physical model, or leave refine unset")  # fmt: skip
    return at


# --- the result -------------------------------------------------------------------------------------------------
class Bunch(dict):
    """A read-only dict whose keys are also attributes (``validation.rms_percent``)."""

    def __getattr__(self, name: str):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None


@dataclass(frozen=True, repr=False)
class StructureIdentification:
    """A structure's identification (``NSI(element="1-2").fit(rec).result_`` on a record of N > 1 DOFs), frozen;
    ``to_json()`` is the contract's ``identify --dofs N`` JSON.

    Attributes
    ----------
    method : {"nsi", "sindy", "discrepancy"}
    structure : Structure
        The identified structure in the physical frame (the element's constant pinned, each channel's zero off).
    modal : dict
        ``{well: [Mode, ...]}``: each well's underlying-linear modes by frequency.
    linear, equilibria : dict
        The underlying-linear K and C at each well and the structure's own; every DOF's static position per well.
    offsets_m : tuple of float
        Each channel's zero found (measured = physical + offset) [m].
    validation : Bunch
        Restarted free runs over the held-out tail (``free_run_error``) and the noise floor.
    warnings : tuple of str
    details, settings : dict
    """

    method: str
    structure: Structure
    modal: dict[str, list[Mode]]
    linear: dict[str, Any]
    equilibria: dict[str, list[float]]
    offsets_m: tuple[float, ...]
    validation: Bunch
    warnings: tuple[str, ...]
    details: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    refinement: Bunch | None = None
    """The output-error stage's account (``refine.refine_stage``; None with ``refine=False``)."""

    @property
    def model(self) -> Model:
        """The element's law (a ``Model`` of the DOF it moves)."""
        return self.structure.element

    @property
    def initial_model(self) -> Model:
        """The element's law before the output-error refinement (the method's own estimate)."""
        if self.refinement is None:
            return self.model
        return Structure.from_dict(self.refinement["initial_model"]).element

    @property
    def element(self) -> dict[str, float]:
        """The element's k0, k1, k2, k3, c, c_nl."""
        return {k: float(getattr(self.structure.element, k)) for k in ("k0", "k1", "k2", "k3", "c", "c_nl")}

    def to_json(self) -> dict[str, Any]:
        """The contract's ``identify --dofs N`` JSON."""
        return {
            "method": self.method,
            "dofs": self.structure.n_dof,
            "element_at": list(self.structure.place),
            "structure": self.structure.to_dict(),
            "element": {**self.element, "extra": dict(self.structure.element.extra)},
            "modal": {w: [m.to_json() for m in ms] for w, ms in self.modal.items()},
            "linear": self.linear,
            "equilibria": self.equilibria,
            "offsets_m": list(self.offsets_m),
            "validation": dict(self.validation),
            "warnings": list(self.warnings),
            "details": self.details,
            "settings": self.settings,
            "refinement": None if self.refinement is None else dict(self.refinement),
        }

    @classmethod
    def from_json(cls, data) -> StructureIdentification:
        """The identification a structure's identify result JSON holds (``to_json()``, its text or a file path):
        ``StructureIdentification.from_json(r.to_json()).to_json() == r.to_json()`` (the ``element`` key is the
        structure's element, read from ``structure``).
        """
        from negstiff.inference.estimators.persistence import json_source

        d = json_source(data, "structure identify result JSON")
        try:
            structure = Structure.from_dict(d["structure"])
            modal = {w: [Mode(float(m["f_hz"]), float(m["zeta"]), tuple(float(x) for x in m["shape"])) for m in ms]
                     for w, ms in d["modal"].items()}  # fmt: skip
            return cls(
                method=d["method"], structure=structure, modal=modal, linear=dict(d.get("linear") or {}),
                equilibria={w: list(z) for w, z in (d.get("equilibria") or {}).items()},
                offsets_m=tuple(float(x) for x in d["offsets_m"]), validation=Bunch(d.get("validation") or {}),
                warnings=tuple(d.get("warnings") or ()), details=dict(d.get("details") or {}),
                settings=dict(d.get("settings") or {}),
                refinement=None if d.get("refinement") is None else Bunch(d["refinement"]),
            )  # fmt: skip
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"not a structure's identify result JSON: {type(exc).__name__} {exc}") from None

    def summary(self) -> str:
        """One line: the element's k3 and each well's modes."""
        return f"{self.structure.n_dof} DOFs, element k3={self.structure.element.k3:.4g}; {modes_summary(self.modal)}"

    def __repr__(self) -> str:
        v = self.validation.get("rms_percent", math.nan)
        return (f"StructureIdentification({self.method}: {self.summary()}; held-out {v:.3g} %; "
                f"{len(self.warnings)} warning(s))")  # fmt: skip


class StructureResults:
    """What an estimator learned on a record of N > 1 DOFs, under scikit-learn's names (mixed into ``NSI``,
    ``SINDy`` and ``Discrepancy``): ``structure_``, ``element_``, ``linear_``, ``offsets_``.
    """

    result_: Any

    structure_ = property(lambda self: self.result_.structure)
    element_ = property(lambda self: self.result_.element)
    linear_ = property(lambda self: self.result_.linear)
    offsets_ = property(lambda self: self.result_.offsets_m)

    def _restore(self, result: dict[str, Any]) -> None:
        """A structure's result JSON (``"structure"`` and ``"dofs"`` in it) rebuilt as its
        ``StructureIdentification`` (``from_json``); a single DOF's by the estimator's own ``_restore``.
        """
        if result.get("linear_part") == "state_space":
            self.result_ = StateSpaceIdentification.from_json(result)
            return
        if "structure" in result and "dofs" in result:
            self.result_ = StructureIdentification.from_json(result)
            if not isinstance(getattr(type(self), "model_", None), property):  # Discrepancy's own attribute
                self.model_ = self.result_.model
            return
        super()._restore(result)  # type: ignore[misc]

    def _summary(self) -> str:
        r = vars(self).get("result_")  # a single DOF's fit need not have one (Discrepancy's)
        if isinstance(r, (StructureIdentification, StateSpaceIdentification)):
            return r.summary()
        return super()._summary()  # type: ignore[misc]


# --- the equations of motion in the measured frame ---------------------------------------------------------------
def _springs(n: int, at: tuple[int, int]) -> list[tuple[int, int]]:
    """The linear structure's candidate springs/dampers (d, e): e = 0 to the base, else between DOFs d < e;
    the element's own pair is left out (its linear part is the element's).
    """
    pairs = [(d, 0) for d in range(1, n + 1)] + [(d, e) for d in range(1, n + 1) for e in range(d + 1, n + 1)]
    own = (at[1], 0) if at[0] == 0 else (min(at), max(at))
    return [p for p in pairs if p != own]


def equation_columns(z: np.ndarray, v: np.ndarray, at: tuple[int, int]) -> tuple[np.ndarray, list[str]]:
    """The stacked equation-of-motion columns, (N, T, P): for DOF d, the force each parameter puts on it per unit
    parameter (M z'' - M 1 u = -sum theta_p col_p). Parameters: the linear structure's springs then dampers
    (``_springs``), the element's terms (``ELEMENT_TERMS``, shared by DOFs J (+) and I (-)), then each DOF's
    constant force (each channel's zero and the element's constant).
    """
    n, t = z.shape
    pairs = _springs(n, at)
    r, vr = relative(z, at), relative(v, at)
    g = [r, r**2, r**3, vr, vr * np.abs(vr)]
    lvec = coupling(n, at)
    cols = np.zeros((n, t, 2 * len(pairs) + len(g) + n))
    for p, (d, e) in enumerate(pairs):
        for off, x in ((0, z), (len(pairs), v)):
            cols[d - 1, :, off + p] += x[d - 1] - (x[e - 1] if e else 0.0)
            if e:
                cols[e - 1, :, off + p] += x[e - 1] - x[d - 1]
    for q, gq in enumerate(g):
        for d in range(n):
            if lvec[d]:
                cols[d, :, 2 * len(pairs) + q] = lvec[d] * gq
    for d in range(n):
        cols[d, :, 2 * len(pairs) + len(g) + d] = 1.0
    names = ([f"k{d}{e}" for d, e in pairs] + [f"c{d}{e}" for d, e in pairs]
             + [f"element {t_}" for t_ in ELEMENT_TERMS] + [f"constant on z{d + 1}" for d in range(n)])  # fmt: skip
    return cols, names


def _assemble(theta: np.ndarray, n: int, at: tuple[int, int], masses, extra: dict[str, Any] | None = None
              ) -> tuple[Structure, np.ndarray]:  # fmt: skip
    """The structure in the measured frame (its element's constant 0) and each DOF's constant force b."""
    pairs = _springs(n, at)
    np_ = len(pairs)
    k, c = theta[:np_], theta[np_ : 2 * np_]
    e = dict(zip(ELEMENT_TERMS, theta[2 * np_ : 2 * np_ + len(ELEMENT_TERMS)], strict=True))
    b = np.asarray(theta[2 * np_ + len(ELEMENT_TERMS) : 2 * np_ + len(ELEMENT_TERMS) + n], float)
    fields = {f: sign * float(e[t]) for t, (f, sign) in _FIELDS.items()}
    element = Model(m=float(masses[at[1] - 1]), k0=0.0, extra=extra or {}, **fields)
    return Structure(tuple(masses), element, assemble(pairs, k, n), assemble(pairs, c, n), at), b


def unknown_zeros(rec: Measurement) -> bool:
    """Whether a record's channels have no zero of their own (derived from a velocity or an acceleration: an
    integral's constant is arbitrary), so that the frame must be chosen by the physics alone (``physical_frame``'s
    ``between_wells``); a laser's zero, however arbitrary, is a few tenths of a millimetre off at most.
    """
    return any(a.get("derived") for a in (rec.info.get("response") or {}).get("channels", ()))


def physical_frame(structure: Structure, b: np.ndarray, gravity: float,
                   between_wells: bool = False) -> tuple[Structure, np.ndarray]:  # fmt: skip
    """The structure identified in the record's frame (each DOF's constant force ``b``, its element's polynomial
    in the measured relative coordinate) in the physical frame, and each channel's zero o (measured = physical +
    o): the o for which Ks o + l G(l.o) + b = l k0 (no constant force but the element's, whose constant is the
    weight it carries, k0 = m_J g), the element's polynomial re-expanded about l.o (reference study Eq. 7). A
    bistable element allows three such frames, its polynomial re-expanded about either well or the barrier, each
    describing the same motion: the one nearest the channels' zeros (a laser's), or with ``between_wells`` (channels
    with no zero of their own, ``unknown_zeros``) the middle one, the barrier's (``_barrier_frame``; the frame of
    negstiff's device models: r = 0 on the negative-stiffness branch). One
    ``StructureIdentificationError`` when no such frame exists.
    """
    el = structure.element
    lvec = structure.coupling
    K = np.asarray(structure.stiffness, float)
    b = np.asarray(b, float) + lvec * el.k0  # the element's own constant is one more constant force
    k0 = el.m * gravity
    P = np.polynomial.Polynomial([0.0, -el.k1, el.k2, el.k3])
    start = np.zeros(structure.n_dof)
    if between_wells:
        start = _barrier_frame(K, lvec, P, b, k0, start)

    def residual(o):
        return K @ o + lvec * P(lvec @ o) + b - lvec * k0

    def jacobian(o):
        return K + np.outer(lvec, lvec) * P.deriv()(lvec @ o)

    o, info, ok, msg = optimize.fsolve(residual, start, fprime=jacobian, full_output=True, xtol=1e-12)
    scale = float(np.abs(b).max() + abs(k0) + 1e-12)
    # the residual decides, not fsolve's flag: on a horizontal Duffing's decay (constant forces of 0.2 mN, no weight)
    # it flagged "not making good progress" at a residual of 3e-20 N, a frame found at its first steps
    del ok
    if np.abs(residual(o)).max() > 1e-6 * scale:
        raise StructureIdentificationError(
            f"no physical frame for the identified structure: its constant forces {b.tolist()} N are not the element's "
            f"weight {k0:.4g} N on linear springs ({msg})"
        )
    s = float(lvec @ o)
    shifted = P(np.polynomial.Polynomial([s, 1.0]))
    c0, c1, c2, c3 = (list(shifted.coef) + [0.0] * 4)[:4]
    del c0  # G(s): taken by the frame (K o + l G(s) + b = l k0)
    element = Model(**{**el.to_dict(), "k0": float(k0), "k1": -float(c1), "k2": float(c2), "k3": float(c3)})
    return structure.with_element(element), o


def _barrier_frame(K: np.ndarray, lvec: np.ndarray, P, b: np.ndarray, k0: float, fallback: np.ndarray) -> np.ndarray:
    """The middle of a bistable element's three frames (the barrier's; ``physical_frame``): with the element's
    force lambda = P(s) at s = l.o, K o + l lambda = l k0 - b and l.o = s are linear in (o, lambda) (the bordered
    system ``Structure._static`` solves, invertible whenever the structure with the element held is grounded, a
    DOF carried by the element alone included), so lambda(s) = lambda0 + lambda1 s and the frames are the real
    roots of P(s) = lambda(s), a cubic. ``fallback`` where the system is singular or the cubic has no real root.
    """
    n = K.shape[0]
    A = np.zeros((n + 1, n + 1))
    A[:n, :n], A[:n, n], A[n, :n] = K, lvec, lvec
    e = np.zeros(n + 1)
    e[n] = 1.0
    try:
        x0 = np.linalg.solve(A, np.concatenate([lvec * k0 - b, [0.0]]))
        x1 = np.linalg.solve(A, e)
    except np.linalg.LinAlgError:
        return fallback
    roots = (P - np.polynomial.Polynomial([x0[n], x1[n]])).roots()
    real = sorted(float(r.real) for r in roots if abs(r.imag) <= 1e-9 * max(1.0, abs(r.real)))
    if not real:
        return fallback
    return x0[:n] + real[len(real) // 2] * x1[:n]


def held_out_floor(structure: Structure, rec: Measurement, start: int, offsets, draws: int = 5,
                   between_pulses: bool = False) -> float | None:  # fmt: skip
    """What a right model misses on the held-out windows of a record like ``rec`` (the floor noise, smoothing and
    chaos leave any model; % of rms z, ``free_run_error``'s measure): ``structure`` run once over the held-out
    input from the record's state, each channel given its zero and white noise of the channel's sensor-noise rms
    (``Measurement.channel_noise``), and its own restarted windows measured on that record; the median over
    ``draws`` noise draws (seeds 0, 1, ...: over cross-well chaos one draw's floor varies by 2x, measured on the
    tests' fixture record). None when the run escapes (no floor to compare with). ``between_pulses``: a
    hammer's record, its windows between the pulses (``free_run_error``'s).
    """
    o = np.asarray(offsets, float)
    zs, v, _ = rec.channel_states(structure.place)
    x0 = np.concatenate([zs[:, start] - o, v[:, start]])[None, :]
    # the input between samples band-limited (``stage_input``), as a lab's record's is: the restarted runs' linear
    # convention then errs on it as on the record (the floor holds that error too)
    res = simulate_structures(structure, stage_input(rec.u[start:])[None], rec.dt, x0, input_kind=rec.input_name,
                              force_dof=rec.force_dof, staged=True)  # fmt: skip
    if bool(np.any(res.diverged)):
        return None
    out = []
    for seed in range(draws):
        rng = np.random.default_rng(seed)
        z = res.z[0] + o[:, None] + rec.channel_noise()[:, None] * rng.standard_normal(res.z[0].shape)
        own = Measurement(rec.fs, rec.input_name, rec.u[start:], z, masses=rec.dof_masses, force_dof=rec.force_dof,
                          source=f"{rec.source} (the model's own)")  # fmt: skip
        out.append(free_run_error(structure, own, 0, WINDOW_S, o, between_pulses)["rms_percent"])
    floor = float(np.median(out))
    return floor if math.isfinite(floor) else None


REFINEMENT_SETTING = "output error over every channel, the element's constant held (refine.refine_stage)"
"""The settings' account of a structure's refinement."""


def weight_pinned(structure: Structure, gravity: float) -> Structure:
    """``structure`` with its element's constant at the weight it carries, m_J g (the physical frame's convention,
    ``physical_frame``), which the output-error refinement holds while it moves the channels' zeros: held anywhere
    else, the frame follows it (NSI's element constant 0.5 % off, 0.01 N, held, moved a zero by 24 um and the
    seed-like element's k2 by +4.8 % to an output-error optimum as good as the truth's; measured).
    """
    element = structure.element
    return structure.with_element(Model(**{**element.to_dict(), "k0": element.m * gravity}))


def refined(structure: Structure, offsets: np.ndarray, rec: Measurement, n_id: int, validation: dict[str, Any],
            hits: bool) -> tuple[Structure, np.ndarray, dict[str, Any], dict[str, Any]]:  # fmt: skip
    """A structure's output-error refinement (``refine.refine_stage``), judged on the held-out windows as it was
    (``free_run_error``; ``hits``: a hammer's record, its windows between the pulses), its element's constant held at
    the weight its frame pins (``weight_pinned``) while the channels' zeros move: the structure, zeros and
    validation to keep (the given ones where the refinement was not), and the stage's account.
    """
    start = weight_pinned(structure, rec.gravity)
    kept, kept_validation, account = refine_stage(
        start, rec, n_id, validation, held=("k0",), offsets=offsets,
        judge=lambda system, zeros: free_run_error(system, rec, n_id, WINDOW_S, zeros, hits),
    )  # fmt: skip
    if not account["applied"]:
        return structure, offsets, validation, account
    return kept, np.asarray(account["offsets_m"]), kept_validation, account


def _finish(method: str, rec: Measurement, structure: Structure, offsets: np.ndarray, n_id: int,
            modal: dict[str, list[Mode]] | None, own_warnings: list[str], details: dict, settings: dict,
            refine: bool = False) -> StructureIdentification:  # fmt: skip
    """The shared stages of a structure's identification: the output-error refinement (``refine``: the one
    ``refine.refine_stage``, the element's constant held at the weight its frame pins, kept only if the held-out
    windows are predicted no worse; the modes are then the refined structure's), equilibria, linear matrices, modes,
    held-out free runs against the noise floor, warnings (issued as ``NegstiffWarning`` and kept in the result).
    """
    hits = ring_down(rec, ("impact",))  # a hammer's record: the held-out windows between its pulses
    own_modal = modal  # the method's own modes (NSI's wells'), judged against the final structure's
    validation = free_run_error(structure, rec, n_id, WINDOW_S, offsets, hits)
    refinement = None
    if refine:
        structure, offsets, validation, refinement = refined(structure, offsets, rec, n_id, validation, hits)
        if refinement["applied"]:
            modal = None  # the refined structure's own
    try:
        eq = structure.equilibria()
        if modal is None:
            modal = {w: structure.modes(w) for w in eq}
    except ValueError as exc:
        raise StructureIdentificationError(f"{rec.source}: the identified element is not usable ({exc})") from None
    linear: dict[str, Any] = {w: {"K": structure.linear(w)[0].tolist(), "C": structure.linear(w)[1].tolist()}
                              for w in eq}  # fmt: skip
    linear["structure"] = {"K": np.asarray(structure.stiffness).tolist(), "C": np.asarray(structure.damping).tolist()}
    validation["floor_percent"] = held_out_floor(structure, rec, n_id, offsets, between_pulses=hits)
    # judged as a single DOF's model is (``plausibility``): damping that feeds energy in, the energy balance, a
    # held-out error beyond the record's rms, the method's own modes against the structure's, wells beyond the stroke
    lines = [*own_warnings, *judgement(structure, rec, validation, modal, own_modal, offsets=offsets),
             *model_warnings(structure, rec, offsets)]  # fmt: skip
    floor = validation["floor_percent"]
    if floor is not None and not validation["rms_percent"] <= NOISE_FLOOR_FACTOR * floor:
        lines.append(
            f"{rec.source}: the identified structure misses its own record's held-out windows by "
            f"{validation['rms_percent']:.3g} % of rms z, more than {NOISE_FLOOR_FACTOR:g}x the {floor:.3g} % it "
            "misses on a record of its own with the channels' sensor noise (the floor of a right model)"
        )
    issue([(_Warning, w) for w in lines])
    return StructureIdentification(
        method=method, structure=structure, modal=modal, linear=linear,
        equilibria={w: z.tolist() for w, z in eq.items()}, offsets_m=tuple(float(x) for x in offsets),
        validation=Bunch(validation), warnings=tuple(lines), details=details,
        settings={**settings, "identification_samples": n_id,
                  "refinement": REFINEMENT_SETTING if refine else "none (refine=False)",
                  "frame": "each channel's zero estimated (a constant force per DOF), the element's constant pinned at "
                           "the weight it carries (m_J g, g the record's gravity)"},
        refinement=None if refinement is None else Bunch(refinement),
    )  # fmt: skip


# --- the weak form ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Weak:
    """The test functions of a structure's weak form: half width and stride in samples, and phi, phi''."""

    half: int
    stride: int
    phi: np.ndarray
    d2phi: np.ndarray

    @classmethod
    def of(cls, zs_element: np.ndarray, fs: float, ring_down: bool = False) -> _Weak:
        half, _ = test_function_half_width(zs_element, fs, ring_down=ring_down)  # a ring-down's corner: its lines
        phi, d2phi = test_function(half, 1.0 / fs)
        return cls(half, max(1, half), phi, d2phi)


def weak_system(rec: Measurement, at: tuple[int, int], zs: np.ndarray, v: np.ndarray, form: _Weak,
                extra=()) -> tuple[np.ndarray, np.ndarray, list[str], int]:  # fmt: skip
    """The stacked weak-form system over ``rec`` (rows: DOF x test function, acceleration units), its names and
    rows per DOF; ``extra``: (name, g) pairs of further element terms g(t) (on J and, opposite, on I).
    """
    cols, names = equation_columns(zs, v, at)
    if extra:
        lvec = coupling(rec.n_dof, at)
        more = np.stack([lvec[:, None] * g[None, :] for _, g in extra], axis=-1)  # (N, T, E)
        cols = np.concatenate([cols, more], axis=-1)
        names = names + [f"element {name}" for name, _ in extra]
    lin = -rec.u if rec.input_name == "base_acc" else rec.u
    mass = np.asarray(rec.dof_masses)
    z = rec.channels
    ys, Xs = [], []
    for d in range(rec.n_dof):
        gain = 1.0 if rec.input_name == "base_acc" else float((rec.force_dof or at[1]) - 1 == d) / mass[d]
        target = weak_project(z[d][:, None], form.d2phi, form.stride, rec.dt)[:, 0]
        target -= gain * weak_project(lin[:, None], form.phi, form.stride, rec.dt)[:, 0]
        ys.append(target)
        Xs.append(-weak_project(cols[d], form.phi, form.stride, rec.dt) / mass[d])
    return np.concatenate(ys), np.vstack(Xs), names, ys[0].size


def _block_scores(residual: np.ndarray, y: np.ndarray, per_dof: int, n_dof: int, rows: int) -> np.ndarray:
    """Held-out weak residual per block of ``rows`` test functions, each DOF's squared residual divided by its
    target's variance and averaged over the DOFs (the same blocks for every candidate: paired comparisons).
    """
    r2 = (residual.reshape(n_dof, per_dof) ** 2) / y.reshape(n_dof, per_dof).var(axis=1, keepdims=True)
    return block_scores(r2.mean(axis=0), rows, 1.0)


def _split(est, rec: Measurement) -> tuple[int, int]:
    n_id = int(round(rec.n * (1 - est.validation_fraction)))
    n_fit = int(round(rec.n * (1 - est.validation_fraction - getattr(est, "selection_fraction", 0.2))))
    return n_id, n_fit


def ring_down(rec: Measurement, kinds: tuple[str, ...] | None = None) -> bool:
    """Whether ``rec`` is a hammer's record or a free decay (``record_kind``; ``kinds``: of those): a response that
    rings down.
    """
    from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS, record_kind

    return record_kind(rec).kind in (RING_DOWN_KINDS if kinds is None else kinds)


def check_ring_down_scores(est, rec: Measurement) -> None:
    """Refuse (``StructureIdentificationError``, one line, before any work) a structure's free decay that rings down
    into its sensors' noise before the part that scores the candidate models (``_split``: from ``n_fit`` on):
    ``record_kind.rings_until``, every channel's rms about its rest within ``RINGING_FACTOR`` of its noise from
    there on. As the single DOF's check (``SINDy.check_length``), which its widening test functions make; the
    structure's blocks were shortened to fit that part instead, and scored noise: the seed-like device on its fixture
    released 6 mm past its well rings for one of its 12 s, and SINDy's k3 came out 28x the truth, the posterior's
    windows all unmatched (measured).
    """
    from negstiff.inference.analysis.record_kind import rings_until

    if not ring_down(rec, ("decay",)):
        return
    _, n_fit = _split(est, rec)
    end = rings_until(rec)
    if end <= n_fit:
        raise StructureIdentificationError(
            f"{rec.source}: a free decay that rings down into its sensors' noise by {end / rec.fs:.3g} "
            f"s, before the part of it that judges {type(est).__name__}'s models ({n_fit / rec.fs:.3g} s on): cut "
            "the record where it meets the noise, or release it again before it does"
        )


def _systems(est, rec: Measurement, at, extra_of=None):
    """The weak systems of the fitting part [0, n_fit) and the selection part [n_fit, n_id) of ``rec`` (the
    identification part's smoothed states), with the blocks' rows; ``extra_of(zs, v)`` gives extra element terms.
    """
    n_id, n_fit = _split(est, rec)
    ident = rec.segment(0, n_id)
    zs, v, smoother = ident.channel_states(at)
    # a free decay's corner by its lines (``weak.RING_DOWN_RULE``: at 1 um the floor's rule selected a double well
    # 20 % off); a hammer's record keeps the floor's rule: its pulses put broadband response above the floor, which
    # the lines' wider test functions smear (measured: the Duffing's damping -18 % with the lines' corner, -7.5 %)
    form = _Weak.of(relative(zs, at), rec.fs, ring_down(rec, ("decay",)))
    extra = extra_of(zs, v) if extra_of else ()
    fit = weak_system(ident.segment(0, n_fit), at, zs[:, :n_fit], v[:, :n_fit], form,
                      [(nm, g[:n_fit]) for nm, g in extra])  # fmt: skip
    sel = weak_system(ident.segment(n_fit, n_id), at, zs[:, n_fit:], v[:, n_fit:], form,
                      [(nm, g[n_fit:]) for nm, g in extra])  # fmt: skip
    whole = weak_system(ident, at, zs, v, form, extra)
    window = float(est.window_s)
    if ring_down(rec):  # a ring-down lasts seconds: the blocks shortened to give the selection part two
        window = min(window, (sel[3] // 2) * form.stride / rec.fs)
    rows = block_rows(window, rec.fs, form.stride)
    if sel[3] // rows < 2:
        raise StructureIdentificationError(
            f"{rec.source}: too short for {type(est).__name__} on {rec.n_dof} DOFs: the selection part "
            f"[{n_fit}, {n_id}) holds fewer than two {window:g} s blocks"
        )
    return fit, sel, whole, rows, smoother, form, (n_id, n_fit), (zs, v)


def _lstsq(X: np.ndarray, y: np.ndarray, support=None) -> np.ndarray:
    """Least squares on the column-scaled system (rms scaling), the columns outside ``support`` at zero."""
    keep = np.ones(X.shape[1], bool) if support is None else np.asarray(support, bool)
    scale = np.sqrt(np.mean(X[:, keep] ** 2, axis=0))
    scale[scale == 0] = 1.0
    theta = np.zeros(X.shape[1])
    theta[keep] = np.linalg.lstsq(X[:, keep] / scale, y, rcond=None)[0] / scale
    return theta


# --- SINDy -------------------------------------------------------------------------------------------------------
def identify_sindy(est, rec: Measurement, at: tuple[int, int]) -> StructureIdentification:
    """SINDy on a record of N > 1 DOFs (module docstring): the single DOF's sparsity path, one-standard-error
    selection on held-out blocks and bagging ensemble, on the structure's stacked weak form.
    """
    import pysindy as ps

    from negstiff.inference.steps.weak import _seeded_global_rng

    fit, sel, whole, rows, window, form, (n_id, _), _ = _systems(est, rec, at)
    (yf, Xf, names, _), (ys, Xs, _, per_sel) = fit[:4], sel[:4]
    masses = rec.dof_masses
    colscale = np.sqrt(np.mean(Xf**2, axis=0))
    colscale[colscale == 0] = 1.0
    ystd = float(yf.std()) or 1.0
    supports: dict[tuple[bool, ...], list[float]] = {}
    # a ring-down (a hammer's record, a free decay) dissipates by what it is: every damper of the structure and the
    # element's viscous term in every support, as the single DOF's (the equation error cannot weigh them: c r' is
    # 2 zeta of the inertia's size, under the selection's margin; measured: a 2-DOF hammer record selected none)
    dampers = np.array([bool(re.fullmatch(r"c\d+", n)) or n == "element v" for n in names]) if ring_down(rec) else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for weight in est.weights:
            opt = ps.STLSQ(threshold=math.sqrt(2 * weight), alpha=0.0, max_iter=50)
            opt.fit(Xf / colscale, yf / ystd)
            on = np.abs(opt.coef_[0]) > 0
            if dampers is not None:
                on |= dampers
            support = tuple(bool(c) for c in on)
            if any(support):
                supports.setdefault(support, []).append(weight)
    path: list[dict[str, Any]] = []
    for support, weights in supports.items():
        theta = _lstsq(Xf, yf, support)
        try:
            s, b = _assemble(theta, rec.n_dof, at, masses)
            physical_frame(s, b, rec.gravity, unknown_zeros(rec))[0].equilibria()
            usable = True
        except (ValueError, InputError):
            usable = False
        path.append({"support": support, "terms": [n for n, on in zip(names, support, strict=True) if on],
                     "n_terms": int(sum(support)), "weight": float(np.sqrt(min(weights) * max(weights))),
                     "block_ms": _block_scores(ys - Xs @ theta, ys, per_sel, rec.n_dof, rows),
                     "usable": usable})  # fmt: skip
    if not path:
        raise StructureIdentificationError(f"{rec.source}: every weight removed every term")
    for p in path:
        p["heldout_residual_percent"] = float(100 * np.sqrt(p["block_ms"].mean()))
    path.sort(key=lambda p: (p["n_terms"], p["heldout_residual_percent"]))
    admissible = [p for p in path if p["usable"]] or path
    best = min(admissible, key=lambda p: p["heldout_residual_percent"])
    chosen = next(p for p in admissible if indistinguishable(p["block_ms"], best["block_ms"], est.margin))
    y, X = whole[0], whole[1]
    theta = _lstsq(X, y, chosen["support"])
    scale_all = np.sqrt(np.mean(X**2, axis=0))
    scale_all[scale_all == 0] = 1.0
    with warnings.catch_warnings(), _seeded_global_rng(est.seed_):
        warnings.simplefilter("ignore")
        ens = ps.EnsembleOptimizer(
            ps.STLSQ(threshold=math.sqrt(2 * chosen["weight"]), alpha=0.0, max_iter=50),
            bagging=True,
            n_models=est.n_models,
            n_subset=int(est.subset_fraction * y.size),
        )
        ens.fit(X / scale_all, (y / (float(y.std()) or 1.0))[:, None])
    coefs = np.array(ens.coef_list)[:, 0, :] * (float(y.std()) or 1.0) / scale_all
    ensemble = {n: {"inclusion_probability": float(np.mean(coefs[:, i] != 0)), "median": float(np.median(coefs[:, i])),
                    "sd": float(np.std(coefs[:, i]))} for i, n in enumerate(names)}  # fmt: skip
    s_m, b = _assemble(theta, rec.n_dof, at, masses)
    structure, offsets = physical_frame(s_m, b, rec.gravity, unknown_zeros(rec))
    return _finish("sindy", rec, structure, offsets, n_id, None, [], {
        "terms": {nm: float(t) for nm, t in zip(names, theta, strict=True)},
        "selected_terms": chosen["terms"],
        "ensemble": ensemble,
        "path": [{k: v for k, v in p.items() if k not in ("block_ms", "support")} for p in path],
    }, {
        "velocity": f"Savitzky-Golay (window, order) = {window}",
        "form": f"weak: test functions (1 - (s/T)^2)^4, T = {form.half} samples, every {form.stride}",
        "selection": f"sparsest support whose held-out weak residual (blocks of {est.window_s:g} s) is within "
                     f"max(one standard error, {100 * est.margin:g} %) of the best",
        "weight": chosen["weight"], "n_models": est.n_models, "seed": est.seed_,
        "newtons_third_law": "the element's terms are one coefficient each, acting on J and, opposite, on I",
    }, refine=est.refine is not False)  # fmt: skip


# --- NSI ---------------------------------------------------------------------------------------------------------
def feedback_channels(lin: np.ndarray, x: np.ndarray, vr: np.ndarray) -> np.ndarray:
    """NSI's extended input about a reference: the excitation and the element's basis as feedback forces,
    [u, -x^2, -x^3, -r'|r'|] (x = r - r*), one column each.
    """
    return np.column_stack([lin, -(x**2), -(x**3), -vr * np.abs(vr)])


COUPLING_FLOOR = 0.01
"""A pair of DOFs is coupled (its reciprocity judged, ``_asymmetry``) when its stiffness is at least this share of
the geometric mean of the two DOFs' own: a chain's DOFs 1 and 3, uncoupled, come out of the fit a few N/m apart
(noise, 1.5e-4 of their own stiffness), and judged as a coupling they read 112 % asymmetric on an identification
within 0.1 % of the truth (measured)."""


def _asymmetry(K: np.ndarray) -> float:
    """The largest |K_ij - K_ji| relative to the larger of the pair, over the coupled pairs (``COUPLING_FLOOR``;
    0 when symmetric).
    """
    big = np.maximum(np.abs(K), np.abs(K.T))
    own = np.sqrt(np.abs(np.outer(np.diag(K), np.diag(K))))
    coupled = big > COUPLING_FLOOR * own
    return float(np.max(np.abs(K - K.T)[coupled] / big[coupled], initial=0.0))


@dataclass(frozen=True)
class WellFit:
    """NSI around one well: the reference r* (measured frame), the ULS's modes and matrices, the element's shifted
    coefficients, the structure in the physical frame and each channel's zero.
    """

    r_ref: float
    modes: list[Mode]
    K: np.ndarray
    C: np.ndarray
    coefficients: dict[str, Any]
    quality: dict[str, float]
    band_hz: tuple[float, float]
    singular_values: list[float]
    structure: Structure
    offsets: np.ndarray


def _least_squares_start(rec: Measurement, at, zs, v, gravity: float) -> tuple[Structure, np.ndarray]:
    """Plain equation-error least squares on the pointwise equations (smoothed accelerations): the wells' first
    guesses, in the physical frame, with each channel's zero.
    """
    a = np.gradient(v, rec.dt, axis=1)
    cols, _ = equation_columns(zs, v, at)
    lin = -rec.u if rec.input_name == "base_acc" else rec.u
    mass = np.asarray(rec.dof_masses)
    ys, Xs = [], []
    for d in range(rec.n_dof):
        gain = 1.0 if rec.input_name == "base_acc" else float((rec.force_dof or at[1]) - 1 == d) / mass[d]
        ys.append(a[d] - gain * lin)
        Xs.append(-cols[d] / mass[d])
    theta = _lstsq(np.vstack(Xs), np.concatenate(ys))
    s, b = _assemble(theta, rec.n_dof, at, rec.dof_masses)
    return physical_frame(s, b, gravity, unknown_zeros(rec))


def weak_frame(rec: Measurement, at: tuple[int, int], zs: np.ndarray, v: np.ndarray, gravity: float) -> np.ndarray:
    """Each channel's zero (measured = physical + o) from the weak form's least squares over the whole library of
    the structure's equation (no selection): the record's frame, pinned as ``physical_frame`` pins it.
    """
    form = _Weak.of(relative(zs, at), rec.fs)
    y, X, _, _ = weak_system(rec, at, zs, v, form, [])
    s, b = _assemble(_lstsq(X, y), rec.n_dof, at, rec.dof_masses)
    return physical_frame(s, b, gravity, unknown_zeros(rec))[1]


def _in_frame(structure: Structure, offsets: np.ndarray, frame: np.ndarray) -> tuple[Structure, np.ndarray]:
    """``structure`` (physical in the frame of ``offsets``) expressed in the frame of ``frame``: the element's
    relative coordinate moves by d = l.(frame - offsets), its polynomial re-expanded about it (k0 included).
    """
    el = structure.element
    d = float(structure.coupling @ (np.asarray(frame) - np.asarray(offsets)))
    k0 = float(el.to_dict()["k0"])  # None in a model means m g: the dict holds the value
    P = np.polynomial.Polynomial([k0, -el.k1, el.k2, el.k3])(np.polynomial.Polynomial([d, 1.0]))
    c0, c1, c2, c3 = (list(P.coef) + [0.0] * 4)[:4]
    element = Model(**{**el.to_dict(), "k0": float(c0), "k1": -float(c1), "k2": float(c2), "k3": float(c3)})
    return structure.with_element(element), np.asarray(frame, float)


def identify_nsi(est, rec: Measurement, at: tuple[int, int]) -> StructureIdentification:
    """NSI on a record of N > 1 DOFs (module docstring): each well's ULS and element, averaged."""
    n_id = int(round(rec.n * (1 - est.validation_fraction)))
    ident = rec.segment(0, n_id)
    zs, v, window = ident.channel_states(at)
    first, o0 = _least_squares_start(ident, at, zs, v, rec.gravity)
    s0 = float(coupling(rec.n_dof, at) @ o0)
    try:
        guesses = first.element_equilibria()
    except ValueError as exc:
        raise StructureIdentificationError(
            f"{rec.source}: no stable equilibrium of the element found ({exc})"
        ) from None
    wells = {}
    r = relative(zs, at)
    for name in ("minus", "plus"):
        r0 = getattr(guesses, f"z_{name}")
        # a ring-down stays in the wells it visits: one it never reaches has no data about it to fit around
        if r0 is not None and not (ring_down(rec) and not r.min() <= r0 + s0 <= r.max()):
            wells[name] = nsi_well(est, ident, zs, v, at, r0 + s0, rec.gravity)
    if not wells:
        raise StructureIdentificationError(
            f"{rec.source}: the record's relative motion [{1e3 * r.min():.3g}, {1e3 * r.max():.3g}] mm reaches "
            "none of the element's wells"
        )
    est.wells_ = wells
    masses = rec.dof_masses
    coef = {k: float(np.mean([w.structure.element.to_dict()[k] for w in wells.values()]))
            for k in ("k0", "k1", "k2", "k3", "c", "c_nl")}  # fmt: skip
    Ks = np.mean([np.asarray(w.structure.stiffness) for w in wells.values()], axis=0)
    Cs = np.mean([np.asarray(w.structure.damping) for w in wells.values()], axis=0)
    offsets = np.mean([w.offsets for w in wells.values()], axis=0)
    structure = Structure(masses, Model(m=masses[at[1] - 1], **coef), 0.5 * (Ks + Ks.T), 0.5 * (Cs + Cs.T), at)
    # the frame is the record's, pinned once by the weak form's least squares (as the single DOF's frame is a step
    # before any estimator): each well's constant forces come from time averages of a model fitted about that
    # well, whose error far from it moves the frame (the rig's fixture record: the plus well's zeros 0.51 mm off,
    # k2 +48 %; the weak form's within 5 um). The element's polynomial is re-expanded in that frame
    structure, offsets = _in_frame(structure, offsets, weak_frame(ident, at, zs, v, rec.gravity))
    lopsided = {w: f.coefficients["stiffness_asymmetry"] for w, f in wells.items()}
    stops = [f"{rec.source}: NSI around the {w} well: {f.coefficients['refinement_stopped']}"
             for w, f in wells.items() if f.coefficients["refinement_stopped"]]  # fmt: skip
    warned = [
        f"{rec.source}: the identified stiffness matrix of the {w} well is not symmetric ({100 * a:.0f} % of a "
        "coupling): a linear structure's is (reciprocity); are the masses right?"
        for w, a in lopsided.items() if a > ASYMMETRY_WARNING
    ]  # fmt: skip
    return _finish("nsi", rec, structure, offsets, n_id, {w: f.modes for w, f in wells.items()}, warned + stops, {
        "wells": {w: {"r_ref": f.r_ref, "coefficients": f.coefficients, "quality_im_over_re": f.quality,
                      "band_hz": list(f.band_hz), "singular_values": f.singular_values, "K_uls": f.K.tolist(),
                      "C_uls": f.C.tolist(), "offsets_m": f.offsets.tolist()} for w, f in wells.items()},
    }, {"block_rows": est.block_rows, "order": est.order * rec.n_dof, "band_fraction": list(est.band),
        "passes": est.passes, "velocity": f"Savitzky-Golay (window, order) = {window}"},
        refine=est.refine is not False)  # fmt: skip


def nsi_well(est, rec: Measurement, zs: np.ndarray, v: np.ndarray, at: tuple[int, int], r_ref: float,
             gravity: float) -> WellFit:  # fmt: skip
    """The ULS and the element's coefficients about ``r_ref`` (the measured frame), moved to the identified
    equilibrium each pass; each DOF's constant force from the time-averaged equations, the frame pinned.
    """
    n = rec.n_dof
    mass = np.asarray(rec.dof_masses)
    lvec = coupling(n, at)
    r, vr = relative(zs, at), relative(v, at)
    if ring_down(rec):
        # a ring-down's basis from the relative motion without the sensor noise's band (``derivatives.BASIS_SNR``:
        # errors in variables, strongest where the decay's tail reaches the noise: a lightly damped Duffing's k3
        # -8.9 % at 1 um, +0.8 % low-passed). Not a stationary record's: on the rig's fixture record (random base
        # excitation, 1 um) a low-pass at 0.8 of the Nyquist frequency moved the plus well's mode from +0.25 % to
        # +1.9 % and k2 from +0.7 % to +2.9 % (noise-free it moved nothing): the structure's outputs are the raw
        # channels, and their noise and the smoothed basis's balance there (measured, not yet understood)
        cut = basis_band_hz(relative(rec.channels, at), rec.fs)
        r, vr = band_limited(r, rec.fs, cut), band_limited(vr, rec.fs, cut)
    lin = -rec.u if rec.input_name == "base_acc" else rec.u
    # a free decay (its input written zero: ``record_kind.identification_record``): the decay form (Anastasio &
    # Marchesiello 2019), the feedback channels alone drive the ULS from its initial state; no input column to
    # scale the level by, the masses given scale it (the discrete-time FRF's level, as the single DOF's decay form)
    decay = not np.any(lin)
    # a hammer's pulse (a 4 ms half-sine is four samples at 1 kHz) is not resolved by the sampled input: its column's
    # FRF level came out 0.95 (the sampled pulse's impulse 5 % low), which the level correction below carried into
    # the coefficients (the double well on a fixture: k3 -5.0 % noise-free, -4.4 % at 1 um). The masses given scale
    # the level there, as the decay form's (noise-free k3 +0.01 % with a clean force, +0.5 % with the lab's; -2.6 %
    # at 1 um)
    level_of_input = not (decay or ring_down(rec, ("impact",)))
    if rec.input_name == "base_acc":
        influence = mass.copy()  # M 1
    else:
        influence = np.zeros(n)
        influence[(rec.force_dof or at[1]) - 1] = 1.0
    stopped, shift = "", 0.0
    fitted = None
    for k_pass in range(est.passes):
        x = r - r_ref
        chans = feedback_channels(lin, x, vr)[:, 1:] if decay else feedback_channels(lin, x, vr)
        means, scale = chans.mean(axis=0), chans.std(axis=0)
        if np.any(scale == 0):
            raise StructureIdentificationError(f"{rec.source}: the input or a basis function is constant")
        w = (chans - means) / scale
        # the outputs are the measured channels, not the smoothed states: a smoother on the outputs and not on the
        # input is a filter inside the identified FRF, which bends a heavily damped pole (the seed-like device on a
        # fixture, zeta 15 %: its mode -1.3 % and k2 +11 % from the smoothed outputs, +0.25 % and -4 % from the
        # measured ones); the subspace step's instruments take the sensor noise. The basis functions keep the
        # smoothed states (their noise would enter as an error in the inputs: k2 +60 % measured)
        zm = rec.channels
        y = (zm - zm.mean(axis=1, keepdims=True)).T
        ys = y.std(axis=0)
        try:
            ss = subspace.identify(w, y / ys, rec.dt, est.order * n, est.block_rows)
        except (ValueError, np.linalg.LinAlgError) as exc:
            if k_pass == 0:
                raise StructureIdentificationError(f"{rec.source}: subspace step failed ({exc})") from None
            stopped = f"the pass at r = {1e3 * r_ref:.3f} mm failed ({exc}); the previous pass's fit is kept"
            break
        Cp = ys[:, None] * ss.C
        T = np.vstack([Cp, Cp @ ss.A])[: 2 * n]
        Ap = T @ ss.A @ np.linalg.pinv(T)
        K = -mass[:, None] * Ap[n:, :n]
        C = -mass[:, None] * Ap[n:, n:]
        asymmetry = _asymmetry(K)  # 0 for the right masses (reciprocity)
        K, C = 0.5 * (K + K.T), 0.5 * (C + C.T)
        modes = modes_of_state_matrix(ss.A, Cp)
        if len(modes) < n:
            raise StructureIdentificationError(
                f"{rec.source}: {len(modes)} underdamped modes identified around r = {1e3 * r_ref:.2f} mm, expected {n}"
            )
        modes = sorted(modes, key=lambda m: -abs(np.asarray(m.shape)).sum())[:n] if len(modes) > n else modes
        modes = sorted(modes, key=lambda m: m.f_hz)
        f_lo, f_hi = min(m.f_hz for m in modes), max(m.f_hz for m in modes)
        band = (est.band[0] * f_lo, min(est.band[1] * f_hi, 0.45 * rec.fs))
        freqs = np.linspace(band[0], band[1], 128)
        he = ss.frf_discrete(freqs) * (ys[None, :, None] / scale[None, None, :])  # (F, N, 4) physical units
        om = 2 * np.pi * freqs
        Z = K[None] - om[:, None, None] ** 2 * np.diag(mass)[None] + 1j * om[:, None, None] * C[None]
        forces = np.einsum("fij,fjq->fiq", Z, he)  # [M 1, l mu_1, ...] up to the level error
        if decay:
            mu = np.einsum("i,fiq->fq", lvec, forces) / (lvec @ lvec)
        else:
            level = (influence @ influence) / (forces[:, :, 0] @ influence) if level_of_input else np.ones(freqs.size)
            mu = (np.einsum("i,fiq->fq", lvec, forces[:, :, 1:]) / (lvec @ lvec)) * level[:, None]
        coef = mu.real.mean(axis=0)
        quality = np.abs(mu.imag).mean(axis=0) / np.maximum(np.abs(coef), 1e-300)
        k1t = float(-K[at[0] - 1, at[1] - 1]) if at[0] else float(K[at[1] - 1].sum())
        ct = float(-C[at[0] - 1, at[1] - 1]) if at[0] else float(C[at[1] - 1].sum())
        ll = np.outer(lvec, lvec)
        Ks, Cs = K - k1t * ll, C - ct * ll
        # each DOF's constant force from the time-averaged equations of motion (the element's F(r_ref) and each
        # channel's zero are not told apart by the record: the frame pins them)
        acc_mean = (v[:, -1] - v[:, 0]) / (v.shape[1] * rec.dt)
        g_mean = np.array([np.mean(x**2), np.mean(x**3), np.mean(vr * np.abs(vr))])
        b = (influence * lin.mean() - mass * acc_mean - Cs @ v.mean(axis=1) - Ks @ zs.mean(axis=1)
             - lvec * (k1t * x.mean() + ct * vr.mean() + coef @ g_mean))  # fmt: skip
        # G(r) about r_ref -> the measured frame: k3 r^3 + k2 r^2 - k1 r + k0, G(r_ref) = 0
        shifted = np.polynomial.Polynomial([0.0, k1t, coef[0], coef[1]])(np.polynomial.Polynomial([-r_ref, 1.0]))
        c0, c1, c2, c3 = (list(shifted.coef) + [0.0] * 4)[:4]
        element = Model(m=float(mass[at[1] - 1]), k0=float(c0), k1=-float(c1), k2=float(c2), k3=float(c3), c=ct,
                        c_nl=float(coef[2]))  # fmt: skip
        try:
            structure, offsets = physical_frame(
                Structure(rec.dof_masses, element, Ks, Cs, at), b, gravity, unknown_zeros(rec)
            )
            eq = structure.element_equilibria()
        except (ValueError, InputError) as exc:
            raise StructureIdentificationError(
                f"{rec.source}: the identified element has no usable equilibria near r = {1e3 * r_ref:.2f} mm ({exc})"
            ) from None
        s = float(lvec @ offsets)
        fitted = (r_ref, modes, K, C, k1t, coef, ct, quality, band, ss, structure, offsets, asymmetry, b)
        new = min((z + s for z in (eq.z_minus, eq.z_plus) if z is not None), key=lambda z: abs(z - r_ref))
        shift, r_ref = new - r_ref, new
        if abs(shift) < 1e-3 * r.std():
            break
    assert fitted is not None
    r_used, modes, K, C, k1t, coef, ct, quality, band, ss, structure, offsets, asymmetry, b = fitted
    coefficients = {
        "k1_tilde": k1t,
        "k2_tilde": float(coef[0]),
        "k3": float(coef[1]),
        "c": ct,
        "c_nl": float(coef[2]),
        "constant_forces_last_pass": b.tolist(),
        "shift_last_pass": shift,
        "stiffness_asymmetry": asymmetry,
        "refinement_stopped": stopped,
    }
    quality_of = dict(zip(("x2", "x3", "vabsv"), quality.tolist(), strict=True))
    return WellFit(r_used, modes, K, C, coefficients, quality_of, band, list(ss.singular_values[:12]), structure,
                   offsets)  # fmt: skip


def stabilisation(est, rec: Measurement, orders=(4, 6, 8, 10), block_rows=(20, 30, 40, 60)) -> list[dict]:
    """Stabilisation diagram (Marchesiello, Fasana & Garibaldi 2016) around each well a structure's NSI found: for
    every (order, block rows), the identified poles (f_hz, zeta) with the feedback channels of that well's
    reference, each marked ``stable`` when a pole of the next lower order lies within 1 % in frequency and 5 % in
    damping. Physical modes stay put as the order grows; spurious ones wander. Run after ``fit``. Each (well, block
    rows) takes every order's poles from one LQ factor (``subspace.poles_by_order``): an order whose model has an
    unstable spurious pole still shows its poles.
    """
    n_id = est.result_.settings["identification_samples"]
    at = est.result_.structure.place
    ident = rec.segment(0, n_id)
    zs, v, _ = ident.channel_states(at)
    r, vr = relative(zs, at), relative(v, at)
    lin = -ident.u if ident.input_name == "base_acc" else ident.u
    y = (zs - zs.mean(axis=1, keepdims=True)).T
    y = y / y.std(axis=0)
    rows: list[dict] = []
    for name, well in est.wells_.items():
        chans = feedback_channels(lin, r - well.r_ref, vr)
        w = (chans - chans.mean(axis=0)) / chans.std(axis=0)
        for i in block_rows:
            previous: list[tuple[float, float]] = []
            try:  # every order's poles from one LQ factor (as the state-space route's diagram)
                by_order = subspace.poles_by_order(w, y, ident.dt, i, orders)
            except (ValueError, np.linalg.LinAlgError) as exc:
                rows += [{"well": name, "order": n, "block_rows": i, "error": str(exc)} for n in orders]
                continue
            for n in orders:
                if n not in by_order:
                    rows.append({"well": name, "order": n, "block_rows": i,
                                 "error": f"order {n} exceeds the {i} block rows' rank"})  # fmt: skip
                    continue
                poles = sorted((float(abs(q) / (2 * math.pi)), float(-q.real / abs(q))) for q in by_order[n]
                               if q.imag > 0)  # fmt: skip
                rows.append({"well": name, "order": n, "block_rows": i, "poles": [
                    {"f_hz": f, "zeta": z, "stable": any(abs(f / pf - 1) < 0.01 and abs(z - pz) < 0.05 * abs(pz)
                                                         for pf, pz in previous)} for f, z in poles]})  # fmt: skip
                previous = poles
    return rows


# --- the discrepancy workflow ------------------------------------------------------------------------------------
def discrepancy(est, rec: Measurement, at: tuple[int, int]) -> StructureIdentification:
    """The discrepancy workflow on a record of N > 1 DOFs (module docstring): the element's base law with the
    linear structure, each registered effect added in turn, named by the paired block rule; the named one joins the
    base and the rest are offered again, until none is named (at most ``max_effects`` rounds: ``iterations``).
    """
    from negstiff.inference.estimators.discrepancy._locating import where_words
    from negstiff.models import effects

    ident_states: dict[str, Any] = {}

    def v_noise_of(vr: np.ndarray) -> float:
        # the smoothed sign's velocity scale: the relative velocity's noise, read as its rough part (first differences
        # of a white-noise-dominated tail), never below 1e-4 of its spread
        return max(float(np.std(np.diff(vr)) / math.sqrt(2)), 1e-4 * float(vr.std()))

    terms = [t for t in effects.library_terms() if t.field not in ("k0", "k1", "k2", "k3", "c", "c_nl")]

    def extras(zs, v):
        r, vr = relative(zs, at), relative(v, at)
        ident_states["v_noise"] = v_noise_of(vr)
        return [(t.field, t.law.column(r, vr, ident_states["v_noise"])) for t in terms]

    fit, sel, whole, rows, window, form, (n_id, _), states = _systems(est, rec, at, extras)
    (yf, Xf_all, names_all, _), (ys, Xs_all, _, per_sel) = fit[:4], sel[:4]
    n_base = len(names_all) - len(terms)
    masses = rec.dof_masses

    def scored(cols: list[int]) -> tuple[np.ndarray, np.ndarray]:
        theta = _lstsq(Xf_all[:, cols], yf)
        return theta, _block_scores(ys - Xs_all[:, cols] @ theta, ys, per_sel, rec.n_dof, rows)

    fields = [t.field for t in terms]
    base_cols = list(range(n_base))
    named_all: list[str] = []
    iterations: list[dict[str, Any]] = []
    # as the single DOF's workflow: each round adds the effect that lowers the held-out score most, beyond the margin
    # rule, to the base the next round scores against; until no effect passes (at most ``max_effects``)
    for _ in range(est.max_effects):
        _, base_blocks = scored(base_cols)
        ranking: list[dict[str, Any]] = [{"effect": "none", "score": float(100 * np.sqrt(base_blocks.mean()))}]
        named, best_gain = None, 0.0
        candidates: dict[str, dict[str, float]] = {}
        for k, t in enumerate(terms):
            if t.field in named_all:
                continue
            theta, blocks = scored(base_cols + [n_base + k])
            value = float(theta[-1])
            cmp = compare(base_blocks, blocks, est.margin, base_blocks)
            physical = not (effects.get(t.field).dissipative and value < 0)  # a feed of energy is no candidate
            candidates[t.field] = {"value": value, "score": float(100 * np.sqrt(blocks.mean())), "gain": cmp.gain,
                                   "se": cmp.se, "physical": physical}  # fmt: skip
            ranking.append({"effect": t.field, "score": candidates[t.field]["score"]})
            if physical and cmp.significant and cmp.gain > best_gain:
                named, best_gain = t.field, cmp.gain
        ranking.sort(key=lambda e: e["score"])
        iterations.append({"named": named or "none", "ranking": ranking, "candidates": candidates})
        if named is None:
            break
        named_all.append(named)
        base_cols.append(n_base + fields.index(named))
    if not iterations:  # max_effects = 0: the base law's own score, nothing offered
        score = float(100 * np.sqrt(scored(base_cols)[1].mean()))
        iterations.append({"named": "none", "ranking": [{"effect": "none", "score": score}], "candidates": {}})
    first = iterations[0]
    y, X = whole[0], whole[1]
    theta_base = _lstsq(X[:, :n_base], y)
    base_s, base_b = _assemble(theta_base, rec.n_dof, at, masses)
    baseline, base_offsets = physical_frame(base_s, base_b, rec.gravity, unknown_zeros(rec))
    located = {"before": locate(y - X[:, :n_base] @ theta_base, y, whole[3], form, states, at, baseline, base_offsets)}
    if not named_all:
        structure, offsets = baseline, base_offsets
        located["after"] = located["before"]
    else:
        theta = _lstsq(X[:, base_cols], y)
        extra = {name: float(theta[n_base + i]) for i, name in enumerate(named_all)}
        s, b = _assemble(theta[:n_base], rec.n_dof, at, masses, extra)
        structure, offsets = physical_frame(s, b, rec.gravity, unknown_zeros(rec))
        located["after"] = locate(y - X[:, base_cols] @ theta, y, whole[3], form, states, at, structure, offsets)
    hits = ring_down(rec, ("impact",))  # a hammer's record: the windows between its pulses
    # refined as the single DOF's workflow refines (a hammer's record only when asked): the baseline here, the
    # final structure by ``_finish``, so the gap before and after the effects is measured on refined models alike
    refine = est.refine is True or (est.refine is None and not hits)
    gap_before = free_run_error(baseline, rec, n_id, WINDOW_S, base_offsets, hits)
    if refine:
        baseline, base_offsets, gap_before, account = refined(baseline, base_offsets, rec, n_id, gap_before, hits)
        if not named_all:  # the baseline is the result, refined once
            structure, offsets = baseline, base_offsets
    est.effects_ = named_all or ["none"]
    est.baseline_structure_ = baseline
    out = _finish("discrepancy", rec, structure, offsets, n_id, None, [], {
        "effect": first["named"], "effects": named_all or ["none"], "ranking": first["ranking"],
        "candidates": first["candidates"], "iterations": iterations,
        "gap_before_percent": gap_before["rms_percent"],
        "where": where_words(located["before"]), "regimes_before": located["before"],
        "regimes_after": located["after"],
        "velocity_noise_for_sign": ident_states.get("v_noise"),
    }, {"velocity": f"Savitzky-Golay (window, order) = {window}",
        "score": f"held-out weak residual in blocks of {est.window_s:g} s; named only above max(1 SE, "
                 f"{100 * est.margin:g} %)"}, refine=refine and bool(named_all))  # fmt: skip
    if refine and not named_all:
        out = dataclasses.replace(out, refinement=Bunch(account),
                                  settings={**out.settings, "refinement": REFINEMENT_SETTING})  # fmt: skip
    gap_after = {k: v for k, v in out.validation.items() if k != "floor_percent"}
    out.details["gap_after_percent"] = gap_after["rms_percent"]
    out.details["effect_interval"] = effect_intervals(out, named_all)
    out.details["bayesian"] = bayesian_opinions(out, rec, n_id, named_all, hits)
    est.gap_before_, est.gap_after_ = gap_before, gap_after
    return out


def locate(residual: np.ndarray, y: np.ndarray, per_dof: int, form: _Weak, states, at: tuple[int, int],
           structure: Structure, offsets: np.ndarray) -> dict[str, dict[str, float]]:  # fmt: skip
    """Where a structure's weak residual (``weak_system``'s rows over the identification part) lives, by the regimes
    of the element's relative motion (the single DOF's ``regime_shares`` on the element's relative displacement and
    velocity at each test function's centre, in the physical frame of ``structure`` and its channels' ``offsets``,
    its wells the element's): each test function's squared residual of every DOF, divided by that DOF's target's
    variance and averaged over the DOFs (``_block_scores``' measure).
    """
    from negstiff.inference.estimators.discrepancy._locating import regime_shares

    zs, v = states
    n_dof = zs.shape[0]
    r2 = (residual.reshape(n_dof, per_dof) ** 2 / y.reshape(n_dof, per_dof).var(axis=1, keepdims=True)).mean(axis=0)
    centres = np.clip(np.arange(per_dof) * form.stride + form.phi.size // 2, 0, zs.shape[1] - 1)
    o = np.asarray(offsets, float)
    r_all = relative(zs - o[:, None], at)
    rv_all = relative(v, at)
    wells: tuple[float | None, ...] = (None, None, None)
    try:
        eq = structure.element_equilibria()
        wells = (eq.z_minus, eq.z_0, eq.z_plus)
    except ValueError:
        pass
    return regime_shares(r_all[centres], rv_all[centres], np.sqrt(r2), wells, r_all, rv_all)


def effect_intervals(result: StructureIdentification, named: list[str], prob: float = 0.9) -> dict[str, Any]:
    """Each named effect's value with its interval (probability ``prob``): the refinement's window-robust standard
    error of the effect's coefficient (``refine._standard_errors``, the structure's other parameters and the
    channels' zeros free), a Gaussian interval about the refined value; None without a kept refinement (the weak
    form's value stands alone). Conditional on the model's form, as the single DOF's Laplace interval is.
    """
    from scipy import stats

    zq = float(stats.norm.ppf(0.5 + prob / 2))
    account: dict[str, Any] = dict(result.refinement or {})
    se_all = account.get("standard_errors") or {}
    out: dict[str, Any] = {}
    for e in named:
        value = result.structure.element.extra.get(e)
        se = se_all.get(e)
        if not account.get("applied") or se is None or not isinstance(value, (int, float)) or not math.isfinite(se):
            out[e] = {"value": value, "interval": None, "prob": prob,
                      "method": "not available: no refinement kept, or the effect is not one coefficient"}  # fmt: skip
            continue
        out[e] = {"value": float(value), "standard_error": float(se),
                  "interval": [float(value - zq * se), float(value + zq * se)], "prob": prob,
                  "method": "the output-error refinement's window-robust standard error (its last stage's restarted "
                            "windows, every parameter and the channels' zeros free), a Gaussian interval"}  # fmt: skip
    return out


def bayesian_opinions(result: StructureIdentification, rec: Measurement, n_id: int, named: list[str],
                      between_pulses: bool = False, draws: int = 64) -> dict[str, Any]:  # fmt: skip
    """A Bayesian second opinion on each named effect, beside the paired rule that named it (the single DOF's
    ``_loo_compare``): the held-out tail's restarted windows (``free_run_error``'s) predicted by the final structure
    with the effect (its size drawn ``draws`` times from the refinement's standard error where one was kept, else at
    its value) and without it (the rest held), compared by ``arviz.compare`` (PSIS-LOO over the windows). A window's
    mean-square error is every DOF's divided by that channel's held-out variance (the validation's measure); a
    diverged run's is the measured motion's own.
    """
    from negstiff.inference.estimators.discrepancy._candidates import _admissible_sizes, _with_size, _without
    from negstiff.inference.estimators.discrepancy._opinions import _loo_compare
    from negstiff.inference.steps.validation import channel_scales, structure_window_errors, structure_windows

    if not named:
        return {}
    structure, offsets = result.structure, np.asarray(result.offsets_m, float)
    windows, zs, v = structure_windows(rec, structure.place, n_id, WINDOW_S, between_pulses)
    scale = channel_scales(rec, n_id)[None, None, :, None]
    worst = float(np.mean((windows.measured(rec.channels) / scale[0]) ** 2))
    account: dict[str, Any] = dict(result.refinement or {})
    se_all = (account.get("standard_errors") or {}) if account.get("applied") else {}
    element = structure.element
    out: dict[str, Any] = {}
    for e in named:
        rng = np.random.default_rng(0)
        raw = element.extra.get(e)
        if not isinstance(raw, (int, float)):  # an effect of several values (none in a structure's catalogue yet)
            out[e] = {"error": "not one coefficient: no opinion drawn"}
            continue
        value, se = float(raw), float(se_all.get(e) or math.nan)
        drawn = math.isfinite(se) and se > 0
        sizes = (_admissible_sizes(element, e, [None], rng.multivariate_normal, np.array([value]),
                                   np.array([[se**2]]), draws) if drawn else [])  # fmt: skip
        systems = [structure.with_element(_with_size(element, e, size)) for size in sizes]
        systems += [structure, structure.with_element(_without(element, e))]  # at its value; without it
        err, diverged = structure_window_errors(systems, rec, windows, zs, v, offsets)
        norm = err / scale
        ms = np.where(diverged, worst, np.mean(norm**2, axis=(2, 3)))
        rows = [r for k in (-2, -1) for r in norm[k].reshape(-1, norm.shape[-1])]
        ms_with = ms[:-2] if drawn else np.repeat(ms[-2:-1], draws, axis=0)  # at its value: its one run, each draw's
        opinion = _loo_compare(ms_with, np.repeat(ms[-1][None], draws, axis=0), rows, windows.length, rng)
        opinion["method"] = (
            f"arviz.compare (PSIS-LOO) over the held-out tail's {windows.starts.size} restarted {WINDOW_S:g} s runs of "
            f"every DOF, {draws} draws of the noise variance"
            + (" and of the effect's size from the refinement's standard error" if drawn else
               " (the effect at its value: no refinement's standard error was kept)")
        )  # fmt: skip
        out[e] = opinion
    return out


def modes_summary(modal: dict[str, list[Mode]]) -> str:
    """One line of each well's modes (frequency, damping ratio)."""
    return "; ".join(
        f"{w}: " + ", ".join(f"{m.f_hz:.3f} Hz {100 * m.zeta:.2f} %" for m in ms) for w, ms in modal.items()
    )
