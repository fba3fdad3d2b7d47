"""NSI on a structure of N DOFs with its masses known: the physical linear part M, C, K (Marchesiello & Garibaldi
2008), the method as it was made.

The element's basis functions of the relative motion r = z_J - z_I about a reference r* (x^2, x^3, r'|r'|,
x = r - r*) are feedback inputs of the underlying-linear system (ULS), M x'' + C x' + K x = M 1 u - l sum_j mu_j g_j
(l = e_J - e_I), identified with every DOF's displacement as an output by the package's LTI subspace step
(``subspace``, PO-MOESP, state order ``order`` x N). Then, around each well: the ULS's modes (the identified state
matrix's poles and shapes); its physical matrices (the identified (A, C) turned into physical coordinates by
T = [C; C A], whose lower blocks are -M^-1 K and -M^-1 C); the element's coefficients mu_j from the extended FRF
H_e = H [M 1, l mu_1, ...]: Z(w) H_e = [M 1, l mu_1, ...] with Z = K - w^2 M + i w C, its input column scaling
out the level error of the discrete-to-continuous step, mu_j(w) = l . (Z H_e,j) / |l|^2 averaged (Re) over the
modes' band, |Im/Re| the quality index. The element's linear part is the ULS's I-J coupling; the constant forces
follow from the time-averaged equations of motion, and the reference moves to the identified structure's
equilibrium for the next pass. The frame is pinned once by the weak form's least squares (``equations.weak_frame``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from negstiff.errors import InputError
from negstiff.inference.analysis.record_kind import ring_down
from negstiff.inference.estimators import subspace
from negstiff.inference.estimators.identification import structure_result
from negstiff.inference.estimators.results import Identification
from negstiff.inference.record.derivatives import band_limited, basis_band_hz
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.equations import (
    StructureIdentificationError,
    _in_frame,
    _least_squares_start,
    physical_frame,
    unknown_zeros,
    weak_frame,
)
from negstiff.models import Model
from negstiff.models.structure import Mode, Structure, coupling, modes_of_state_matrix, relative

ASYMMETRY_WARNING = 0.05
"""NSI warns when the identified stiffness matrix's asymmetry exceeds this share of its largest entry: the
record's masses scale the identified M^-1 K back to K, and wrong masses leave it lopsided."""


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


def identify_nsi(est, rec: Measurement, at: tuple[int, int]) -> Identification:
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
    modal = {w: f.modes for w, f in wells.items()}
    return structure_result("nsi", rec, structure, offsets, n_id, modal, warned + stops, {
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
