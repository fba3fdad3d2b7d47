"""Identification of a structure of N degrees of freedom carrying one nonlinear element (``models.structure``).

**NSI** as the method was made for (Marchesiello & Garibaldi 2008): the element's basis functions of the relative
motion r = z_J - z_I about a reference r* (x^2, x^3, r'|r'|, x = r - r*) are feedback inputs of the underlying-
linear system (ULS), M x'' + C x' + K x = M 1 u - l sum_j mu_j g_j (l = e_J - e_I), identified with every DOF's
displacement as an output by the package's LTI subspace step (``subspace``, PO-MOESP, state order 2N). Then,
around each well:

- the ULS's modes: the identified state matrix's poles (frequency |lambda| / 2 pi, damping ratio) and shapes (the
  output matrix times the eigenvectors);
- its physical matrices: the identified (A, C) turned into physical coordinates by T = [C; C A] (the state
  [x; x'] of a model whose outputs are all N displacements), whose lower blocks are -M^-1 K and -M^-1 C: with
  the record's masses, K and C of the ULS;
- the element's coefficients mu_j from the extended FRF H_e = H [M 1, l mu_1, ...]: Z(w) H_e with
  Z = K - w^2 M + i w C (the identified ULS's dynamic stiffness) is [M 1, l mu_1, ...]; its input column, whose
  value M 1 physics fixes, scales out the level error of the discrete-to-continuous step (as the single-DOF NSI
  reads ratios to the input column), and mu_j(w) = l . (Z H_e,j) / |l|^2 averaged (Re) over the modes' band, with
  |Im/Re| as the quality index;
- the element's linear part is the ULS's I-J coupling (a spring in parallel with the element cannot be told
  from it: it is counted as the element's); the structure's own K, C are the ULS's without it; the element's
  constant follows from the time-averaged equations of motion (every channel is zero-mean in the subspace step),
  and the reference moves to the identified structure's equilibrium (``Structure.element_equilibria``) for the
  next pass (the reference shift per element).

**SINDy** with one equation per DOF in the weak form (``weak.test_function``, as the single-DOF SINDy): the
element's terms are shared between the two DOFs it connects with opposite signs (Newton's third law, built into
the regression as one shared coefficient per term rather than left for the data to find), the linear
structure's springs and dampers are columns of the DOFs they join, the input's coefficient is fixed by the known
masses. Sparsity: pysindy's STLSQ on the stacked, column-scaled system over a path of thresholds, each support
scored by its weak residual on the identification data's last quarter; the sparsest within 1 % of the best is
kept and refitted.

Both report the same keys (``modal``, ``element``, ``linear``, ``equilibria``, ``validation``).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from negstiff.errors import InputError, NegstiffWarning
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.weak import test_function, test_function_half_width, weak_project
from negstiff.models import Model
from negstiff.models.structure import (
    Mode,
    Structure,
    assemble,
    coupling,
    modes_of,
    modes_of_state_matrix,
    relative,
    simulate_structures,
)

from . import subspace

ELEMENT_TERMS = ("1", "r", "r^2", "r^3", "v", "v|v|")
"""The element's library: F(r, r') = k0 - k1 r + k2 r^2 + k3 r^3 + c r' + c_nl r'|r'| (the single-DOF names)."""


THRESHOLDS = tuple(float(t) for t in np.logspace(-4, -1, 13))
"""SINDy's STLSQ thresholds by default, relative to the target's spread."""


ASYMMETRY_WARNING = 0.05
"""NSI warns when the identified stiffness matrix's asymmetry exceeds this share of its largest entry: the
record's masses scale the identified M^-1 K back to K, and wrong masses leave it lopsided."""


class StructureIdentificationError(InputError):
    """The record cannot be identified as a structure with one element (too short, wrong element, no modes)."""


def parse_element(text: str | tuple[int, int], n_dof: int) -> tuple[int, int]:
    """``"I-J"`` (J the DOF the element moves, I the one it is attached to, 0 the base) as (I, J), checked."""
    if isinstance(text, str):
        try:
            i, j = (int(x) for x in text.split("-"))
        except ValueError:
            raise InputError(f"--element must be I-J (e.g. 1-2; 0 is the base), got {text!r}") from None
    else:
        i, j = (int(x) for x in text)
    if not (0 <= i <= n_dof and 1 <= j <= n_dof and i != j):
        raise InputError(f"--element {i}-{j}: J must be a DOF 1..{n_dof}, I one of 0..{n_dof} (0: the base), I != J")
    return i, j


def _asymmetry(K: np.ndarray) -> float:
    """The largest |K_ij - K_ji| relative to the larger of the pair, over the coupled pairs (0 when symmetric)."""
    big = np.maximum(np.abs(K), np.abs(K.T))
    coupled = big > 1e-6 * big.max()
    return float(np.max(np.abs(K - K.T)[coupled] / big[coupled], initial=0.0))


def feedback_channels(lin: np.ndarray, x: np.ndarray, vr: np.ndarray) -> np.ndarray:
    """NSI's extended input about a reference: the excitation and the element's basis as feedback forces,
    [u, -x^2, -x^3, -r'|r'|] (x = r - r*), one column each.
    """
    return np.column_stack([lin, -(x**2), -(x**3), -vr * np.abs(vr)])


def _element_model(coef: dict[str, float], mass: float) -> Model:
    return Model(m=mass, k0=coef["1"], k1=-coef["r"], k2=coef["r^2"], k3=coef["r^3"], c=coef["v"], c_nl=coef["v|v|"])


def _springs(n: int, at: tuple[int, int]) -> list[tuple[int, int]]:
    """The linear structure's candidate springs/dampers (d, e): e = 0 to the base, else between DOFs d < e;
    the element's own pair is left out (its linear part is the element's).
    """
    pairs = [(d, 0) for d in range(1, n + 1)] + [(d, e) for d in range(1, n + 1) for e in range(d + 1, n + 1)]
    own = (at[1], 0) if at[0] == 0 else (min(at), max(at))
    return [p for p in pairs if p != own]


def equation_columns(z: np.ndarray, v: np.ndarray, at: tuple[int, int]) -> tuple[np.ndarray, list[str]]:
    """The stacked equation-of-motion columns, (N, T, P): for DOF d, the force each parameter puts on it per unit
    parameter, with the sign of the left-hand side moved right (M z'' - M 1 u = -sum theta_p col_p). Parameters:
    the linear structure's springs then dampers (``_springs``), then the element's terms (``ELEMENT_TERMS``),
    shared by DOFs J (+) and I (-).
    """
    n, t = z.shape
    pairs = _springs(n, at)
    r, vr = relative(z, at), relative(v, at)
    g = [np.ones(t), r, r**2, r**3, vr, vr * np.abs(vr)]
    lvec = coupling(n, at)
    cols = np.zeros((n, t, 2 * len(pairs) + len(g)))
    for p, (d, e) in enumerate(pairs):
        for off, x in ((0, z), (len(pairs), v)):
            cols[d - 1, :, off + p] += x[d - 1] - (x[e - 1] if e else 0.0)
            if e:
                cols[e - 1, :, off + p] += x[e - 1] - x[d - 1]
    for q, gq in enumerate(g):
        for d in range(n):
            if lvec[d]:
                cols[d, :, 2 * len(pairs) + q] = lvec[d] * gq
    names = [f"k{d}{e}" for d, e in pairs] + [f"c{d}{e}" for d, e in pairs] + [f"element {t_}" for t_ in ELEMENT_TERMS]
    return cols, names


def _assemble(theta: np.ndarray, n: int, at: tuple[int, int], masses, extra: dict[str, float] | None = None
              ) -> Structure:  # fmt: skip
    pairs = _springs(n, at)
    k, c, e = theta[: len(pairs)], theta[len(pairs) : 2 * len(pairs)], theta[2 * len(pairs) :]
    element = _element_model(dict(zip(ELEMENT_TERMS, e, strict=True)), masses[at[1] - 1])
    if extra:
        element = Model(**{**element.to_dict(), "extra": extra})
    return Structure(tuple(masses), element, assemble(pairs, k, n), assemble(pairs, c, n), at)


@dataclass(frozen=True)
class WellFit:
    """NSI around one well: the reference r*, the ULS's modes and matrices, the element's shifted coefficients."""

    r_ref: float
    modes: list[Mode]
    K: np.ndarray
    C: np.ndarray
    coefficients: dict[str, float]
    quality: dict[str, float]
    band_hz: tuple[float, float]
    singular_values: list[float]
    structure: Structure


def free_run_error(structure: Structure, rec: Measurement, start: int, window_s: float = 0.25) -> dict[str, Any]:
    """Free runs of ``structure`` over the record from sample ``start`` on, restarted every ``window_s`` from the
    record's band-smoothed states: rms error over every DOF in % of the responses' rms, and per DOF. The truth's
    own value on the same record is the floor noise and chaos leave any model. 0.25 s (two periods of the wells)
    by default: over cross-well chaos a 1 s run diverges for any model, the truth too (60 % rms on the tests'
    fixture record), and then a model that moves less scores better.
    """
    zs, v, _ = rec.channel_states(structure.place)
    L = max(8, int(round(window_s * rec.fs)))
    starts = np.arange(start, rec.n - L, L)
    if not starts.size:
        raise StructureIdentificationError(f"{rec.source}: the held-out part is shorter than one {window_s} s window")
    idx = starts[:, None] + np.arange(L + 1)[None, :]
    u = rec.u[idx]
    x0 = np.hstack([zs[:, starts].T, v[:, starts].T])
    res = simulate_structures(structure, u, rec.dt, x0, input_kind=rec.input_name, force_dof=rec.force_dof,
                              input_index=np.arange(starts.size))  # fmt: skip
    meas = np.transpose(rec.channels[:, idx], (1, 0, 2))  # (W, N, L+1)
    err = res.z - meas
    ok = ~res.diverged
    centred = rec.channels[:, start:] - rec.channels[:, start:].mean(axis=1, keepdims=True)
    scale = np.sqrt(np.mean(centred**2, axis=1))
    if not ok.any():
        return {"rms_percent": math.inf, "per_dof_percent": [math.inf] * rec.n_dof, "windows": int(starts.size),
                "diverged": int(starts.size)}  # fmt: skip
    per = np.sqrt(np.mean(err[ok] ** 2, axis=(0, 2))) / scale
    total = float(np.sqrt(np.mean((err[ok] / scale[None, :, None]) ** 2)))
    return {"rms_percent": 100 * total, "per_dof_percent": (100 * per).tolist(), "windows": int(starts.size),
            "diverged": int((~ok).sum()), "window_s": window_s}  # fmt: skip


class _StructureIdentifier:
    """What NSI and SINDy share: the record's checks, the held-out tail, the result's keys."""

    method = ""

    def __init__(self, *, element: str | tuple[int, int] | None = None, validation_fraction: float = 0.2):
        self.element = element
        self.validation_fraction = validation_fraction

    def _prepare(self, rec: Measurement) -> tuple[Measurement, tuple[int, int], int]:
        if not isinstance(rec, Measurement):
            raise InputError(
                "a structure's identification needs a Measurement (load, from_arrays)"
            )
        if not 0.0 < self.validation_fraction < 0.9:
            raise InputError(f"validation_fraction must be in (0, 0.9), got {self.validation_fraction}")
        if self.element is None and rec.n_dof > 1:
            raise InputError(f"{rec.source}: a record of {rec.n_dof} DOFs needs the element's place (element='I-J')")
        at = parse_element(self.element if self.element is not None else (0, 1), rec.n_dof)  # one DOF: on the base
        n_id = int(round((1 - self.validation_fraction) * rec.n))
        rec.require(4000, f"{type(self).__name__}")
        return rec, at, n_id

    def _finish(self, rec: Measurement, structure: Structure, n_id: int, modal: dict, extra: dict) -> None:
        self.structure_ = structure
        self.element_ = {k: getattr(structure.element, k) for k in ("k0", "k1", "k2", "k3", "c", "c_nl")}
        self.modal_ = modal
        self.warnings_: list[str] = list(extra.pop("warnings", []))
        try:
            eq = structure.equilibria()
        except ValueError as exc:
            raise StructureIdentificationError(f"{rec.source}: the identified element is not usable ({exc})") from None
        self.equilibria_ = {w: z.tolist() for w, z in eq.items()}
        self.linear_ = {w: {"K": structure.linear(w)[0].tolist(), "C": structure.linear(w)[1].tolist()} for w in eq}
        self.linear_["structure"] = {"K": np.asarray(structure.stiffness).tolist(),
                                     "C": np.asarray(structure.damping).tolist()}  # fmt: skip
        self.validation_ = free_run_error(structure, rec, n_id)
        for w in self.warnings_:
            warnings.warn(w, NegstiffWarning, stacklevel=3)
        self.details_ = extra

    def result(self) -> dict[str, Any]:
        """The contract's result JSON of a structure's identification."""
        return {
            "method": self.method,
            "dofs": self.structure_.n_dof,
            "element_at": list(self.structure_.place),
            "structure": self.structure_.to_dict(),
            "element": {**self.element_, "extra": dict(self.structure_.element.extra)},
            "modal": {w: [m.to_json() for m in ms] for w, ms in self.modal_.items()},
            "linear": self.linear_,
            "equilibria": self.equilibria_,
            "validation": self.validation_,
            "warnings": self.warnings_,
            "details": self.details_,
        }


class StructureNSI(_StructureIdentifier):
    """Nonlinear subspace identification of a structure of N DOFs with one element (module docstring).

    Parameters
    ----------
    element : "I-J" or (I, J)
        The element moves DOF J relative to DOF I (0: the base).
    block_rows : int, default 40
        Block rows of the Hankel matrices.
    band : (float, float), default (0.6, 1.6)
        The coefficients' averaging band, as fractions of the lowest and highest mode's frequency.
    passes : int, default 3
        Identification passes per well at most (each at the equilibrium the previous one identified).
    validation_fraction : float, default 0.2
        The held-out tail.

    Attributes
    ----------
    structure_ : Structure
        The identified structure (element coefficients averaged over the wells, the linear structure too).
    modal_ : dict
        ``{well: [Mode, ...]}``: each well's ULS modes by frequency, as identified.
    element_ : dict
        The element's k0, k1, k2, k3, c, c_nl (the single-DOF names).
    wells_ : dict
        Each well's ``WellFit``.
    validation_ : dict
        Restarted free runs over the held-out tail (``free_run_error``).
    equilibria_ : dict
        Every DOF's static position at each well.
    linear_ : dict
        The underlying-linear system's K and C at each well, and the structure's own.
    warnings_ : list of str
        What NSI did not believe (also issued as ``NegstiffWarning``).

    Examples
    --------
    >>> from negstiff import StructureNSI, load
    >>> from negstiff.models.structure_rig import StructureRig
    >>> rig = StructureRig.device_on_fixture(seed=1)          # the device on a 1 kg, 25 Hz fixture
    >>> rec = load(rig.random(duration=120.0, rms=14.0).write("fixture.csv"))
    >>> nsi = StructureNSI(element="1-2").fit(rec)
    >>> [round(m.f_hz, 1) for m in nsi.modal_["minus"]]       # the device's mode, the fixture's
    [11.3, 25.7]
    """

    method = "nsi"

    def __init__(self, *, element=None, block_rows: int = 40, band: tuple[float, float] = (0.6, 1.6), passes: int = 3,
                 validation_fraction: float = 0.2):  # fmt: skip
        super().__init__(element=element, validation_fraction=validation_fraction)
        self.block_rows = block_rows
        self.band = band
        self.passes = passes

    def fit(self, rec: Measurement) -> StructureNSI:
        """Identify the structure from ``rec`` (a ``Measurement``); returns self."""
        rec, at, n_id = self._prepare(rec)
        ident = rec.segment(0, n_id)
        zs, v, window = ident.channel_states(at)
        first = StructureSINDy._least_squares(ident, at, zs, v)  # equation error: the wells' first guesses
        try:
            guesses = first.element_equilibria()
        except ValueError as exc:
            raise StructureIdentificationError(
                f"{rec.source}: no stable equilibrium of the element found ({exc})"
            ) from None
        wells = {}
        for name in ("minus", "plus"):
            r0 = getattr(guesses, f"z_{name}")
            if r0 is not None:
                wells[name] = self.fit_well(ident, zs, v, at, r0, first)
        self.wells_ = wells
        mass = rec.dof_masses[at[1] - 1]
        coef = {k: float(np.mean([w.structure.element.to_dict()[k] for w in wells.values()]))
                for k in ("k0", "k1", "k2", "k3", "c", "c_nl")}  # fmt: skip
        Ks = np.mean([np.asarray(w.structure.stiffness) for w in wells.values()], axis=0)
        Cs = np.mean([np.asarray(w.structure.damping) for w in wells.values()], axis=0)
        structure = Structure(rec.dof_masses, Model(m=mass, **coef), 0.5 * (Ks + Ks.T), 0.5 * (Cs + Cs.T), at)
        lopsided = {w: f.coefficients["stiffness_asymmetry"] for w, f in wells.items()}
        stops = [f"{rec.source}: NSI around the {w} well: {f.coefficients['refinement_stopped']}"
                 for w, f in wells.items() if f.coefficients["refinement_stopped"]]  # fmt: skip
        warned = [
            f"{rec.source}: the identified stiffness matrix of the {w} well is not symmetric ({100 * a:.0f} % of a "
            "coupling): a linear structure's is (reciprocity); are the masses right?"
            for w, a in lopsided.items() if a > ASYMMETRY_WARNING
        ]  # fmt: skip
        self._finish(rec, structure, n_id, {w: f.modes for w, f in wells.items()}, {
            "warnings": warned + stops,
            "wells": {w: {"r_ref": f.r_ref, "coefficients": f.coefficients, "quality_im_over_re": f.quality,
                          "band_hz": list(f.band_hz), "singular_values": f.singular_values,
                          "K_uls": f.K.tolist(), "C_uls": f.C.tolist()} for w, f in wells.items()},
            "settings": {"block_rows": self.block_rows, "order": 2 * rec.n_dof, "band_fraction": list(self.band),
                         "passes": self.passes, "velocity": f"Savitzky-Golay (window, order) = {window}",
                         "identification_samples": n_id},
        })  # fmt: skip
        return self

    def stabilization(self, rec: Measurement, orders=(4, 6, 8, 10), block_rows=(20, 30, 40, 60)) -> list[dict]:
        """Stabilisation diagram (Marchesiello, Fasana & Garibaldi 2016) around each well ``fit`` found: for every
        (order, block rows), the identified poles (f_hz, zeta) with the feedback channels of that well's reference,
        each marked ``stable`` when a pole of the next lower order lies within 1 % in frequency and 5 % in damping.
        Physical modes stay put as the order grows; spurious ones wander. Run after ``fit``.
        """
        n_id = self.details_["settings"]["identification_samples"]
        at = self.structure_.place
        ident = rec.segment(0, n_id)
        zs, v, _ = ident.channel_states(at)
        r, vr = relative(zs, at), relative(v, at)
        lin = -ident.u if ident.input_name == "base_acc" else ident.u
        y = (zs - zs.mean(axis=1, keepdims=True)).T
        y = y / y.std(axis=0)
        rows: list[dict] = []
        for name, well in self.wells_.items():
            x = r - well.r_ref
            chans = feedback_channels(lin, x, vr)
            w = (chans - chans.mean(axis=0)) / chans.std(axis=0)
            for i in block_rows:
                previous: list[tuple[float, float]] = []
                for n in orders:
                    try:
                        ss = subspace.identify(w, y, ident.dt, n, i)
                    except (ValueError, np.linalg.LinAlgError) as exc:
                        rows.append({"well": name, "order": n, "block_rows": i, "error": str(exc)})
                        continue
                    lam = np.linalg.eigvals(ss.A)
                    poles = sorted((float(abs(q) / (2 * math.pi)), float(-q.real / abs(q))) for q in lam if q.imag > 0)
                    rows.append({"well": name, "order": n, "block_rows": i, "poles": [
                        {"f_hz": f, "zeta": z, "stable": any(abs(f / pf - 1) < 0.01 and abs(z - pz) < 0.05 * abs(pz)
                                                             for pf, pz in previous)} for f, z in poles]})  # fmt: skip
                    previous = poles
        return rows

    def fit_well(self, rec: Measurement, zs: np.ndarray, v: np.ndarray, at: tuple[int, int], r_ref: float,
                 start: Structure) -> WellFit:  # fmt: skip
        """The ULS and the element's coefficients about ``r_ref``, moved to the identified equilibrium each pass."""
        n = rec.n_dof
        mass = np.asarray(rec.dof_masses)
        lvec = coupling(n, at)
        r, vr = relative(zs, at), relative(v, at)
        lin = -rec.u if rec.input_name == "base_acc" else rec.u
        if rec.input_name == "base_acc":
            influence = mass.copy()  # M 1
        else:
            influence = np.zeros(n)
            influence[(rec.force_dof or at[1]) - 1] = 1.0
        structure = start
        stopped, shift = "", 0.0
        for k_pass in range(self.passes):
            x = r - r_ref
            chans = feedback_channels(lin, x, vr)
            means, scale = chans.mean(axis=0), chans.std(axis=0)
            if np.any(scale == 0):
                raise StructureIdentificationError(f"{rec.source}: the input or a basis function is constant")
            w = (chans - means) / scale
            y = (zs - zs.mean(axis=1, keepdims=True)).T
            ys = y.std(axis=0)
            try:
                ss = subspace.identify(w, y / ys, rec.dt, 2 * n, self.block_rows)
            except (ValueError, np.linalg.LinAlgError) as exc:
                if k_pass == 0:
                    raise StructureIdentificationError(f"{rec.source}: subspace step failed ({exc})") from None
                # a later pass's reference failed: the previous pass stands, and the result says so
                stopped = f"the pass at r = {1e3 * r_ref:.3f} mm failed ({exc}); the previous pass's fit is kept"
                r_ref = r_ref - shift
                break
            Cp = ys[:, None] * ss.C
            T = np.vstack([Cp, Cp @ ss.A])
            Ap = T @ ss.A @ np.linalg.inv(T)
            K = -mass[:, None] * Ap[n:, :n]
            C = -mass[:, None] * Ap[n:, n:]
            asymmetry = _asymmetry(K)  # 0 for the right masses (reciprocity)
            K, C = 0.5 * (K + K.T), 0.5 * (C + C.T)
            modes = modes_of_state_matrix(ss.A, Cp)
            if len(modes) < n:
                raise StructureIdentificationError(
                    f"{rec.source}: {len(modes)} underdamped modes identified around r = {1e3 * r_ref:.2f} mm, "
                    f"expected {n}"
                )
            f_lo, f_hi = min(m.f_hz for m in modes), max(m.f_hz for m in modes)
            band = (self.band[0] * f_lo, min(self.band[1] * f_hi, 0.45 * rec.fs))
            freqs = np.linspace(band[0], band[1], 128)
            he = ss.frf_discrete(freqs) * (ys[None, :, None] / scale[None, None, :])  # (F, N, 4) physical units
            om = 2 * np.pi * freqs
            Z = K[None] - om[:, None, None] ** 2 * np.diag(mass)[None] + 1j * om[:, None, None] * C[None]
            forces = np.einsum("fij,fjq->fiq", Z, he)  # [M 1, l mu_1, ...] up to the level error
            level = (influence @ influence) / (forces[:, :, 0] @ influence)  # 1 where the level is right
            mu = (np.einsum("i,fiq->fq", lvec, forces[:, :, 1:]) / (lvec @ lvec)) * level[:, None]
            coef = mu.real.mean(axis=0)
            quality = np.abs(mu.imag).mean(axis=0) / np.maximum(np.abs(coef), 1e-300)
            k1t = float(-K[at[0] - 1, at[1] - 1]) if at[0] else float(K[at[1] - 1].sum())
            ct = float(-C[at[0] - 1, at[1] - 1]) if at[0] else float(C[at[1] - 1].sum())
            ll = np.outer(lvec, lvec)
            Ks, Cs = K - k1t * ll, C - ct * ll
            # the element's constant F(r_ref) from the time-averaged equations of motion (least squares over DOFs)
            acc_mean = (v[:, -1] - v[:, 0]) / (v.shape[1] * rec.dt)
            g_mean = np.array([np.mean(x**2), np.mean(x**3), np.mean(vr * np.abs(vr))])
            rhs = (influence * lin.mean() - mass * acc_mean - Cs @ v.mean(axis=1) - Ks @ zs.mean(axis=1)
                   - lvec * (k1t * x.mean() + ct * vr.mean() + coef @ g_mean))  # fmt: skip
            # each DOF's averaged equation weighted by the inverse size of its forces: a stiff fixture's balances
            # tens of newtons of spring force, and its small relative error would swamp the element's constant
            # (measured on the rig's fixture record: the device's damping -7.8 % unweighted, -4.2 % weighted)
            wts = 1.0 / (np.abs(Ks).sum(axis=1) * zs.std(axis=1) + mass * np.abs(lin).std() + 1e-300)
            f0 = float((wts * lvec) @ rhs / ((wts * lvec) @ lvec))
            # F(r) about r_ref -> z frame: k3 r^3 + k2 r^2 - k1 r + k0
            poly = np.polynomial.Polynomial([f0, k1t, coef[0], coef[1]])
            shifted = poly(np.polynomial.Polynomial([-r_ref, 1.0]))
            c0, c1, c2, c3 = (list(shifted.coef) + [0.0] * 4)[:4]
            element = Model(m=float(mass[at[1] - 1]), k0=float(c0), k1=-float(c1), k2=float(c2), k3=float(c3), c=ct,
                            c_nl=float(coef[2]))  # fmt: skip
            structure = Structure(rec.dof_masses, element, Ks, Cs, at)
            try:
                eq = structure.element_equilibria()
            except ValueError as exc:
                raise StructureIdentificationError(
                    f"{rec.source}: the identified element has no usable equilibria near r = "
                    f"{1e3 * r_ref:.2f} mm ({exc})"
                ) from None
            new = min((z for z in (eq.z_minus, eq.z_plus) if z is not None), key=lambda z: abs(z - r_ref))
            shift, r_ref = new - r_ref, new
            if abs(shift) < 1e-3 * r.std():
                break
        coefficients = {
            "k1_tilde": float(element.stiffness(r_ref)),
            "k2_tilde": float(element.k2 + 3 * element.k3 * r_ref),
            "k3": element.k3,
            "c": ct,
            "c_nl": element.c_nl,
            "constant_last_pass": f0,
            "shift_last_pass": shift,
            "stiffness_asymmetry": asymmetry,
            "refinement_stopped": stopped,
        }
        quality_of = dict(zip(("x2", "x3", "vabsv"), quality.tolist(), strict=True))
        singular = list(ss.singular_values[:12])
        return WellFit(r_ref, modes, K, C, coefficients, quality_of, band, singular, structure)


class StructureSINDy(_StructureIdentifier):
    """SINDy of a structure of N DOFs in the weak form, one equation per DOF, the element's terms shared by the
    DOFs it joins (Newton's third law; module docstring).

    Parameters
    ----------
    element : "I-J" or (I, J)
        The element moves DOF J relative to DOF I (0: the base).
    thresholds : sequence of float
        STLSQ thresholds on the column-scaled coefficients (the sparsity path).
    validation_fraction : float, default 0.2
        The held-out tail.

    Attributes
    ----------
    structure_ : Structure
        The identified structure.
    element_ : dict
        The element's k0, k1, k2, k3, c, c_nl.
    modal_ : dict
        ``{well: [Mode, ...]}`` of the identified structure.
    validation_ : dict
        Restarted free runs over the held-out tail (``free_run_error``).
    details_ : dict
        Every term's coefficient, the selected terms and the sparsity path.

    Examples
    --------
    >>> from negstiff import StructureSINDy, load
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> from negstiff.models.structure_rig import StructureRig
    >>> rec = load(StructureRig.device_on_fixture(seed=1).random(duration=120.0).write("fixture.csv"))
    >>> sindy = StructureSINDy(element="1-2").fit(rec)
    >>> abs(sindy.element_["k3"] / SEED_LIKE_CUBIC.k3 - 1) < 0.02   # the device's cubic stiffness
    True
    """

    method = "sindy"

    def __init__(self, *, element=None, thresholds=THRESHOLDS,
                 validation_fraction: float = 0.2):  # fmt: skip
        super().__init__(element=element, validation_fraction=validation_fraction)
        self.thresholds = thresholds

    @staticmethod
    def _least_squares(rec: Measurement, at, zs, v) -> Structure:
        """Plain equation-error least squares on the pointwise equations (smoothed accelerations): a start."""
        a = np.gradient(v, rec.dt, axis=1)
        cols, _ = equation_columns(zs, v, at)
        y, X = _targets(rec, a, cols, at)
        theta = np.linalg.lstsq(X, y, rcond=None)[0]
        return _assemble(theta, rec.n_dof, at, rec.dof_masses)

    def weak_system(self, rec: Measurement, at, zs, v, extra=()) -> tuple[np.ndarray, np.ndarray, list[str], int]:
        """The stacked weak-form system (rows: DOF x test function; acceleration units) and its names; ``extra``:
        (name, g) pairs of further element terms g(t) (acting on J and, opposite, on I), appended as columns.
        """
        half, _ = test_function_half_width(zs[at[1] - 1], rec.fs)
        phi, d2phi = test_function(half, rec.dt)
        stride = max(1, half)
        cols, names = equation_columns(zs, v, at)
        if extra:
            lvec = coupling(rec.n_dof, at)
            more = np.stack([lvec[:, None] * g[None, :] for _, g in extra], axis=-1)  # (N, T, E)
            cols = np.concatenate([cols, more], axis=-1)
            names = names + [f"element {name}" for name, _ in extra]
        lin = -rec.u if rec.input_name == "base_acc" else rec.u
        mass = np.asarray(rec.dof_masses)
        ys, Xs = [], []
        for d in range(rec.n_dof):
            gain = 1.0 if rec.input_name == "base_acc" else float((rec.force_dof or at[1]) - 1 == d)
            target = weak_project(rec.channels[d][:, None], d2phi, stride, rec.dt)[:, 0] * mass[d]
            target -= (
                gain
                * weak_project(lin[:, None], phi, stride, rec.dt)[:, 0]
                * (mass[d] if rec.input_name == "base_acc" else 1.0)
            )
            ys.append(target / mass[d])
            Xs.append(-weak_project(cols[d], phi, stride, rec.dt) / mass[d])
        return np.concatenate(ys), np.vstack(Xs), names, ys[0].size

    def fit(self, rec: Measurement) -> StructureSINDy:
        """Identify the structure from ``rec`` (a ``Measurement``); returns self."""
        import pysindy as ps

        rec, at, n_id = self._prepare(rec)
        ident = rec.segment(0, n_id)
        zs, v, window = ident.channel_states(at)
        y, X, names, per_dof = self.weak_system(ident, at, zs, v)
        scale = X.std(axis=0)
        scale[scale == 0] = 1.0
        Xn = X / scale
        n_rows = per_dof
        fit_rows = np.concatenate([np.arange(d * n_rows, d * n_rows + int(0.75 * n_rows)) for d in range(rec.n_dof)])
        test_rows = np.setdiff1d(np.arange(y.size), fit_rows)
        path = []
        for thr in self.thresholds:
            opt = ps.STLSQ(threshold=thr * np.abs(y).std(), alpha=0.0, max_iter=50)
            opt.fit(Xn[fit_rows], y[fit_rows])
            support = np.abs(opt.coef_[0]) > 0
            if not support.any():
                continue
            coef = np.zeros(X.shape[1])
            coef[support] = np.linalg.lstsq(Xn[fit_rows][:, support], y[fit_rows], rcond=None)[0]
            score = float(np.sqrt(np.mean((Xn[test_rows] @ coef - y[test_rows]) ** 2)))
            path.append({"threshold": thr, "support": support, "score": score})
        if not path:
            raise StructureIdentificationError(f"{rec.source}: every threshold removed every term")
        best = min(p["score"] for p in path)
        chosen = min((p for p in path if p["score"] <= 1.01 * best), key=lambda p: (p["support"].sum(), p["score"]))
        support = chosen["support"]
        theta = np.zeros(X.shape[1])
        theta[support] = np.linalg.lstsq(Xn[:, support], y, rcond=None)[0] / scale[support]
        structure = _assemble(theta, rec.n_dof, at, rec.dof_masses)
        try:
            modal = {w: structure.modes(w) for w in structure.equilibria()}
        except ValueError as exc:
            raise StructureIdentificationError(f"{rec.source}: the identified element is not usable ({exc})") from None
        self._finish(rec, structure, n_id, modal, {
            "terms": {nm: float(t) for nm, t in zip(names, theta, strict=True)},
            "selected": [nm for nm, s in zip(names, support, strict=True) if s],
            "path": [{"threshold": p["threshold"], "terms": int(p["support"].sum()), "held_out_weak_rms": p["score"]}
                     for p in path],
            "settings": {"velocity": f"Savitzky-Golay (window, order) = {window}", "identification_samples": n_id,
                         "newtons_third_law": "the element's terms are one coefficient each, acting on J and, "
                                              "opposite, on I"},
        })  # fmt: skip
        return self


class StructureDiscrepancy(_StructureIdentifier):
    """What a structure's element model misses, named, added and measured (the discrepancy workflow for N DOFs).

    The baseline is the element's base law (``ELEMENT_TERMS``) fitted with the linear structure by the weak-form
    least squares of ``StructureSINDy``. Each registered effect with a column of its own (``models.effects``:
    Coulomb friction, cubic damping, quartic and quintic stiffness) is added in turn as a term of the element
    (shared by the DOFs it joins) and the system refitted. The effect whose equation error is least on test
    functions it was not fitted on (the identification part's last quarter) is named, and kept when its model's
    held-out prediction (free runs of ``window_s`` restarted from the measured state over the last
    ``validation_fraction``, ``free_run_error``) shrinks the baseline's error by at least ``min_gain`` of it;
    otherwise nothing is named and the baseline stands.

    Parameters
    ----------
    element : "I-J" or (I, J)
        The element's place.
    window_s : float, default 0.25
        Held-out free runs' length [s] (short against cross-well chaos).
    min_gain : float, default 0.1
        The share of the baseline's held-out error an effect must remove to be named.
    validation_fraction : float, default 0.2
        The held-out tail.

    Attributes
    ----------
    named_ : str or None
        The effect named (a registry name), or None.
    gap_ : dict
        Held-out error [% rms] of the baseline and of the model with the named effect.
    candidates_ : dict
        Every effect tried: its fitted value and held-out error.
    structure_ : Structure
        The final structure (with the named effect, or the baseline).

    Examples
    --------
    >>> from negstiff import StructureDiscrepancy, load
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> from negstiff.models.structure_rig import StructureRig
    >>> device = SEED_LIKE_CUBIC.__class__(**{**SEED_LIKE_CUBIC.to_dict(), "extra": {"coulomb_friction": 0.3}})
    >>> rig = StructureRig.device_on_fixture(device, seed=1)   # the element has friction its model lacks
    >>> rec = load(rig.random(duration=120.0).write("fixture.csv"))
    >>> StructureDiscrepancy(element="1-2").fit(rec).named_
    'coulomb_friction'
    """

    method = "discrepancy"

    def __init__(self, *, element=None, window_s: float = 0.25, min_gain: float = 0.1,
                 validation_fraction: float = 0.2):  # fmt: skip
        super().__init__(element=element, validation_fraction=validation_fraction)
        self.window_s, self.min_gain = window_s, min_gain

    def fit(self, rec: Measurement) -> StructureDiscrepancy:
        """Fit the baseline and every candidate effect on ``rec``, name the one that predicts best; returns self."""
        from negstiff.models import effects

        rec, at, n_id = self._prepare(rec)
        ident = rec.segment(0, n_id)
        zs, v, _ = ident.channel_states(at)
        r, vr = relative(zs, at), relative(v, at)
        # the smoothed sign's velocity scale: the relative velocity's noise, read as its rough part (first differences
        # of a white-noise-dominated tail), never below 1e-4 of its spread
        v_noise = max(float(np.std(np.diff(vr)) / math.sqrt(2)), 1e-4 * float(vr.std()))
        sindy = StructureSINDy(element=at)
        y, X, _, per_dof = sindy.weak_system(ident, at, zs, v)
        # the equation error of each candidate on test functions it was not fitted on (the last quarter of every
        # DOF's rows) names the effect; the held-out free runs decide whether it is kept
        fit_rows = np.concatenate([np.arange(d * per_dof, d * per_dof + int(0.75 * per_dof)) for d in range(rec.n_dof)])
        test_rows = np.setdiff1d(np.arange(y.size), fit_rows)

        def weak_score(X_: np.ndarray, y_: np.ndarray) -> float:
            th = np.linalg.lstsq(X_[fit_rows], y_[fit_rows], rcond=None)[0]
            return float(np.sqrt(np.mean((X_[test_rows] @ th - y_[test_rows]) ** 2)))

        theta0 = np.linalg.lstsq(X, y, rcond=None)[0]
        base = _assemble(theta0, rec.n_dof, at, rec.dof_masses)
        e0 = free_run_error(base, rec, n_id, self.window_s)["rms_percent"]
        w0 = weak_score(X, y)
        terms = [t for t in effects.library_terms() if t.field not in ("k0", "k1", "k2", "k3", "c", "c_nl")]
        candidates: dict[str, dict[str, float]] = {}
        fitted: dict[str, Structure] = {}
        for t in terms:
            g = t.law.column(r, vr, v_noise)
            y2, X2, _, _ = sindy.weak_system(ident, at, zs, v, extra=[(t.field, g)])
            theta = np.linalg.lstsq(X2, y2, rcond=None)[0]
            value = float(theta[-1])
            entry = {"value": value, "held_out_weak_rms": weak_score(X2, y2), "held_out_rms_percent": math.inf}
            candidates[t.field] = entry
            if effects.get(t.field).dissipative and value < 0:
                entry["held_out_weak_rms"] = math.inf  # it would feed energy in: unphysical, not a candidate
                continue
            try:
                s = _assemble(theta[:-1], rec.n_dof, at, rec.dof_masses, {t.field: value})
                entry["held_out_rms_percent"] = free_run_error(s, rec, n_id, self.window_s)["rms_percent"]
                fitted[t.field] = s
            except (ValueError, InputError):
                pass
        best = min(candidates, key=lambda k: candidates[k]["held_out_weak_rms"])
        e_best = candidates[best]["held_out_rms_percent"]
        self.named_ = best if e_best <= (1 - self.min_gain) * e0 else None
        self.candidates_ = candidates
        self.gap_ = {"baseline_rms_percent": e0, "with_named_rms_percent": e_best if self.named_ else e0,
                     "baseline_weak_rms": w0}  # fmt: skip
        structure = fitted[best] if self.named_ else base
        modal = {w: structure.modes(w) for w in structure.equilibria()}
        self._finish(rec, structure, n_id, modal, {
            "named": self.named_, "gap": self.gap_, "candidates": candidates, "window_s": self.window_s,
            "min_gain": self.min_gain, "velocity_noise_for_sign": v_noise,
        })  # fmt: skip
        return self


def _targets(rec: Measurement, a: np.ndarray, cols: np.ndarray, at: tuple[int, int]
             ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Pointwise stacked targets z_d'' - (input) and columns, per unit mass (a force acts on ``force_dof``, by
    default the DOF the element moves, as everywhere else).
    """
    lin = -rec.u if rec.input_name == "base_acc" else rec.u
    mass = np.asarray(rec.dof_masses)
    ys, Xs = [], []
    for d in range(rec.n_dof):
        if rec.input_name == "base_acc":
            inp = lin
        else:
            inp = lin / mass[d] if (rec.force_dof or at[1]) - 1 == d else 0.0 * lin
        ys.append(a[d] - inp)
        Xs.append(-cols[d] / mass[d])
    return np.concatenate(ys), np.vstack(Xs)


def modes_summary(modal: dict[str, list[Mode]]) -> str:
    """One line of each well's modes (frequency, damping ratio)."""
    return "; ".join(
        f"{w}: " + ", ".join(f"{m.f_hz:.3f} Hz {100 * m.zeta:.2f} %" for m in ms) for w, ms in modal.items()
    )


__all__ = ["StructureNSI", "StructureSINDy", "free_run_error", "parse_element", "modes_of", "modes_summary"]
