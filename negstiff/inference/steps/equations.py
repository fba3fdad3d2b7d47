"""A structure's equations of motion in the measured frame, for every method that regresses them: each DOF's
equation with the element's terms shared between the two DOFs it joins (Newton's third law, one coefficient per
term), the linear structure's springs and dampers as columns of the DOFs they join, a constant force per DOF; the
equations pointwise (NSI's first guess) and in the weak form (SINDy, the discrepancy workflow, the frame);
their least squares; and the physical frame they pin.

**Each channel's zero.** A laser's zero is arbitrary: each response channel carries an unknown constant o_d. The
equations of motion in the measured coordinates then hold a constant force b_d on every DOF (the linear springs'
K o and the element's constant, which cannot be told apart from the record), estimated with the other
parameters, as the single DOF's constant term is. The physical frame (each DOF's displacement from the rest
position of the linear springs loaded by the weights, the contract's) is then pinned by the physics
(``physical_frame``): no constant force but the element's, whose constant is the weight it carries,
K_e(0) = m_J g (g: the record's ``gravity``, 0 for a horizontal device), as the single DOF's frame is pinned by
K(0) = m g. The offsets found are in the result (``offsets_m``), and every free run is compared with the record
in the record's own frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import optimize

from negstiff.errors import InputError
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.selection import block_rows, block_scores
from negstiff.inference.steps.weak import test_function, test_function_half_width, weak_project
from negstiff.models import Model
from negstiff.models.structure import Structure, assemble, coupling, relative


class StructureIdentificationError(InputError):
    """The record cannot be identified as a structure with one element (too short, wrong element, no modes)."""


ELEMENT_TERMS = ("r", "r^2", "r^3", "v", "v|v|")
"""The element's regressed library: F(r, r') = k0 - k1 r + k2 r^2 + k3 r^3 + c r' + c_nl r'|r'| (the single-DOF
names); its constant k0 is not regressed (each DOF's constant force holds it) but pinned (``physical_frame``)."""


_FIELDS = {"r": ("k1", -1.0), "r^2": ("k2", 1.0), "r^3": ("k3", 1.0), "v": ("c", 1.0), "v|v|": ("c_nl", 1.0)}


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


def _systems(est, rec: Measurement, at, rings_down: bool, decay: bool, extra_of=None):
    """The weak systems of the fitting part [0, n_fit) and the selection part [n_fit, n_id) of ``rec`` (the
    identification part's smoothed states), with the blocks' rows; ``extra_of(zs, v)`` gives extra element terms.
    ``rings_down``: a hammer's record or a free decay (``record_kind.ring_down``); ``decay``: a free decay.
    """
    n_id, n_fit = _split(est, rec)
    ident = rec.segment(0, n_id)
    zs, v, smoother = ident.channel_states(at)
    # a free decay's corner by its lines (``weak.RING_DOWN_RULE``: at 1 um the floor's rule selected a double well
    # 20 % off); a hammer's record keeps the floor's rule: its pulses put broadband response above the floor, which
    # the lines' wider test functions smear (measured: the Duffing's damping -18 % with the lines' corner, -7.5 %)
    form = _Weak.of(relative(zs, at), rec.fs, decay)
    extra = extra_of(zs, v) if extra_of else ()
    fit = weak_system(ident.segment(0, n_fit), at, zs[:, :n_fit], v[:, :n_fit], form,
                      [(nm, g[:n_fit]) for nm, g in extra])  # fmt: skip
    sel = weak_system(ident.segment(n_fit, n_id), at, zs[:, n_fit:], v[:, n_fit:], form,
                      [(nm, g[n_fit:]) for nm, g in extra])  # fmt: skip
    whole = weak_system(ident, at, zs, v, form, extra)
    window = float(est.window_s)
    if rings_down:  # a ring-down lasts seconds: the blocks shortened to give the selection part two
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
