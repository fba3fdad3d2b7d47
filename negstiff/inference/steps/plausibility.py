"""Loud warnings for results a physicist would not believe: a record in mm, an input in g (or a wrong
mass or force sensitivity), a z frame far from the rods-horizontal position (or physics that never
carry the weight: wrong units), wells beyond the stroke the record visited.

These never fail a command (the numbers may be right for an unusual device); they go into the
result's ``warnings`` and onto stderr, each saying what looks wrong and what to check.
"""

from __future__ import annotations

import numpy as np

from negstiff.errors import (
    BoundednessWarning,
    ConvergenceWarning,
    ExtrapolationWarning,
    FrameWarning,
    NegstiffWarning,
    RecordWarning,
)
from negstiff.inference.steps.frame import frame_offset
from negstiff.inference.steps.validation import element_motion
from negstiff.inference.steps.weak import input_coefficient
from negstiff.models.structure import as_structure, relative

FRAME_WARN_M = 2e-3
"""A measured z whose zero sits this far [m] from where the record's physics carries the weight is
warned about. The gravity estimate of the frame errs by ~0.2 mm on the exact device's records
(model form, measured); a cubic's own k0 is no guide (NSI's cubic on as-built records puts m g at
z = -3.6 mm, k0/m = 1.4-1.8 m/s^2: the exact K is not a cubic)."""


def frame_warnings(rec) -> list[str]:
    """Is a measured z in the rods-horizontal frame? Where the record's own physics carries the weight
    (``frame.frame_offset`` by gravity, rest positions ignored) says how far its zero is from it; for a
    device without gravity along its motion (``rec.gravity`` 0), the midpoint between its wells.
    """
    constant_known = rec.info.get("response", {}).get("z_constant_known", True)
    if rec.z is None or (rec.input_name != "base_acc" and rec.gravity != 0) or not constant_known:
        return []
    fo = frame_offset(rec, spread=False, use_rest=False)  # the parts' spread only for a warning's text (0.3 s on 300 s)
    if fo["offset_m"] is not None and abs(fo["offset_m"]) > FRAME_WARN_M:
        fo = frame_offset(rec, use_rest=False)
    if fo["offset_m"] is None and (fo.get("one_well") or rec.gravity == 0):
        return []  # an in-well record (or a horizontal one without two wells) cannot say where its zero is
    if fo["offset_m"] is None:
        return [
            f"the record's physics never carry the weight ({fo['method']}): are base_acc in m/s^2 and z in m, "
            "and is the input the table's acceleration? (a horizontal device: '# gravity: 0' or --gravity 0)"
        ]
    c, se = fo["offset_m"], fo.get("offset_se_m") or 0.0
    if abs(c) > FRAME_WARN_M:  # the parts' spread (se) is said, not used: short parts may visit one well only
        if rec.gravity == 0:
            return [
                f"z's zero seems {-1e3 * c:.3g} mm off the midpoint between the record's wells (+-{1e3 * se:.2g} mm; "
                "gravity 0 along the motion, so a symmetric device's origin is that midpoint): a displacement "
                f"sensor's offset? Shifting z by {1e3 * c:.3g} mm would put it there"
            ]
        return [
            f"z's zero seems {-1e3 * c:.3g} mm off the rods-horizontal position (+-{1e3 * se:.2g} mm): the record's "
            f"physics carry the weight at z = {-1e3 * c:.3g} mm, not at z = 0 (a displacement sensor's offset?). "
            f"The model is in the record's frame; shifting z by {1e3 * c:.3g} mm would put it in the physical one"
        ]
    return []


INPUT_GAIN_RANGE = (0.7, 1.4)
"""The input's coefficient the record's own dynamics learn, over the one physics fixes, stays in this
range on sound records (0.985-1.000 measured on rig records, cross-well and low-level); a base
acceleration in g gives 9.8."""


def input_warnings(rec) -> list[str]:
    """Units and mass: the input's weight in the record's own dynamics against the physics' (-1 for a
    base acceleration in m/s^2, 1/m for a force in N; ``weak.input_coefficient``).
    """
    if rec.z is None or (rec.input_name == "force" and rec.mass is None):
        return []
    try:
        c = input_coefficient(rec)
    except Exception:  # a record too poor for the fit: nothing to say about its units
        return []
    ratio = -c if rec.input_name == "base_acc" else c * rec.mass
    lo, hi = INPUT_GAIN_RANGE
    if lo < ratio < hi:
        return []
    if rec.input_name == "base_acc":
        hint = " (about 9.81: is base_acc in g? map it with --columns base_acc=COL*9.81)" if 7 < ratio < 13 else ""
        return [
            f"the record's own dynamics weigh base_acc {ratio:.3g} times what physics says (z'' = ... - base_acc)"
            f"{hint}; check the accelerometer's units and sensitivity"
        ]
    return [
        f"the record's own dynamics say the moving mass is {1 / c:.4g} kg, not the {rec.mass:g} kg given "
        "(or the force is not in N): check the mass and the force sensor's sensitivity"
    ]


def model_warnings(model, rec, offsets=None) -> list[str]:
    """Wells of an identified model beyond the stroke the record visited are extrapolations (a structure's: its
    element's wells beyond the relative motion the record's channels show, ``validation.element_motion``).
    """
    out: list[str] = []
    if rec.z is None:
        return out
    law, z = element_motion(model, rec, offsets)
    lo, hi = float(z.min()), float(z.max())
    span = hi - lo
    try:
        eq = law.equilibria()
    except ValueError:
        return out
    for name in ("z_minus", "z_plus"):
        z = getattr(eq, name)
        if z is not None and not (lo - 0.5 * span <= z <= hi + 0.5 * span):
            out.append(
                f"the model's well {name} = {z:.4g} m lies beyond the stroke the record visited "
                f"[{lo:.4g}, {hi:.4g}] m: an extrapolation"
            )
    return out


POWER_SIGMAS = 5.0
"""The record dissipates when the input's mean power exceeds this many batch-means standard errors."""

MODAL_CONTRADICTION = 0.10
"""A method's own modal frequency further than this (relative) from its model's linearisation sqrt(K'(z*)/m)
contradicts the model."""

HELD_OUT_LIMIT_PERCENT = 100.0
"""A held-out free run erring by more than the record's own rms predicts worse than zero."""

NOISE_TAIL_PERCENT = 50.0
"""A held-out part whose channels' sensor noise alone reaches this share of their rms there (``noise_floor_percent``,
a structure's runs give it) is read mostly as noise: its held-out error judges nothing, whatever it is. A free decay's
tail rung into its noise (78.7 % noise) was missed by the fit and by the truth alike (90.80 and 90.85 %), under the
100 % that said so before its windows started from least-error states (measured)."""


def input_power(rec) -> tuple[float, float]:
    """The input's mean power per unit mass over the record [W/kg] and its batch-means standard error (20
    batches): -<u z'> for a base acceleration, <F z'> / m for a force (1/kg unknown: per newton); a structure's
    over its DOFs, -<u sum m_i z_i'> / M or <F z_k'> / M (M their total mass, k the DOF the force acts on). Over a
    long record the kinetic and potential energies average out, so this is what the device dissipates. The channels'
    velocities are ``Measurement.free_run_states``'.
    """
    v = rec.free_run_states()[1]
    if rec.input_name == "base_acc":
        masses = np.asarray(rec.masses if rec.masses is not None else [rec.mass or 1.0], float)
        weights = masses / masses.sum()  # a single DOF's 1.0
        p = -rec.u * (weights @ v)
    else:
        k = (rec.force_dof or v.shape[0]) - 1
        p = rec.u * v[k] / (sum(rec.masses) if rec.masses is not None else (rec.mass or 1.0))
    nb = 20
    if p.size < 10 * nb:
        return float(p.mean()), float("inf")
    means = np.array([b.mean() for b in np.array_split(p, nb)])
    return float(p.mean()), float(means.std(ddof=1) / np.sqrt(nb))


def dissipated_power(system, rec, offsets=None) -> float:
    """The mean power [W/kg] ``system``'s damping draws from the record's motion (its channels, their velocities
    ``free_run_states``; a structure's: its element's damping force on the relative motion and its dampers, over its
    total mass, the channels less their zeros ``offsets``).
    """
    structure = as_structure(system)
    v = rec.free_run_states()[1]
    zs = rec.channels - (np.zeros(structure.n_dof) if offsets is None else np.asarray(offsets, float))[:, None]
    el, at = structure.element, structure.place
    r, vr = relative(zs, at), relative(v, at)
    damping = (el.total_force(r, vr) - el.restoring_force(r)) * vr + np.einsum("it,ij,jt->t", v, structure.C, v)
    return float(np.mean(damping)) / float(sum(structure.masses))


def _modes(modal: dict | None, well: str) -> list[float | None]:
    """A well's modal frequencies, a single DOF's ``{"f_hz"}`` or a structure's list of ``Mode``, by frequency."""
    entry = (modal or {}).get(well)
    if isinstance(entry, list):
        return [m.f_hz for m in entry]
    return [(entry or {}).get("f_hz")]


def judgement(
    model, rec, validation: dict, modal: dict | None, own_modal: dict | None, laws_compared: bool = True,
    offsets=None,
) -> list[str]:  # fmt: skip
    """What a physicist checks before believing an identified model, each a warning: negative viscous
    damping (a structure's: its element's, or a damper matrix that feeds energy in); a model that dissipates
    nothing (or gains energy) over a record whose input does work on it (the energy balance <D(z') z'> = input
    power, ``input_power`` and ``dissipated_power``); a held-out free run erring by more than the record's rms
    (``HELD_OUT_LIMIT_PERCENT``); a method's own modal values that contradict its model's linearisation
    (``MODAL_CONTRADICTION``; a structure's mode by mode), where the laws were not compared (``laws_compared``
    False) with the comparison named as what to try. A structure (``offsets``: its channels' zeros) is judged as
    a single DOF is, the single DOF being the structure of one DOF on the base.
    """
    out: list[str] = []
    causes = (
        "(the record's frame or drift, or a model order too low?)"
        if laws_compared
        else "(the record's frame or drift, a model order too low, or a restoring law that is not the record's? "
        "law='auto', --law auto, compares the laws on what they predict)"
    )
    structure = as_structure(model)
    if structure.element.c < 0:
        out.append(
            f"negative viscous damping c = {structure.element.c:.3g} N s/m: the model feeds energy into small motion, "
            "which no passive device does (the record's drift, a wrong frame or a missing effect bent the fit?)"
        )
    lowest = float(np.linalg.eigvalsh(np.asarray(structure.C, float)).min())
    if lowest < -1e-12 * max(1.0, float(np.abs(structure.C).max())):
        out.append(
            f"the linear structure's damping matrix has the eigenvalue {lowest:.3g} N s/m: its dampers feed energy "
            "into a motion, which no passive structure does (a wrong mass or frame, or a missing effect, bent the fit?)"
        )
    if rec.z is not None and rec.n >= 200:
        try:
            p, se = input_power(rec)
            dissipated = dissipated_power(structure, rec, offsets)
        except Exception:  # a record or model the check cannot evaluate: nothing to say
            p, se, dissipated = 0.0, float("inf"), 0.0
        if p > POWER_SIGMAS * se and dissipated <= 0:
            what = "no damping" if dissipated == 0 else f"damping that gains {-dissipated:.3g} W/kg"
            out.append(
                f"the model has {what}, but the record dissipates: the input's mean power is {p:.3g} W/kg "
                f"(+- {se:.2g}); an energy balance the model cannot meet"
            )
    # the restarted runs where there are any: one long free run of a chaotic record errs by ~140 % for the truth
    key = "restarted_rms_percent" if validation.get("restarted_rms_percent") is not None else "rms_percent"
    worst = validation.get(key)
    floor = validation.get("floor_percent")  # what a right model misses on a record like this (its own noise)
    noise = validation.get("noise_floor_percent")  # the channels' sensor noise alone there (a structure's runs)
    noise_tail = noise is not None and noise >= NOISE_TAIL_PERCENT
    if worst is not None and np.isfinite(worst) and (worst > HELD_OUT_LIMIT_PERCENT or noise_tail):
        what = "restarted free runs err" if key.startswith("restarted") else "free run errs"
        if noise_tail or floor is not None and floor >= HELD_OUT_LIMIT_PERCENT:  # a right model misses it as badly:
            # the held-out part is the sensors' noise and judges nothing (beyond the floor: ``structure_result``'s own)
            right = (f"a right model misses a record like this by {floor:.3g} % (its own run under the channels' "
                     "noise)" if floor is not None else f"the sensors' noise alone is {noise:.3g} % of it")  # fmt: skip
            out.append(
                f"the held-out part is at the sensors' noise: the model's held-out {what} by {worst:.3g} % of the "
                f"record's rms there, and {right}: the held-out error cannot judge the model; hold out a part that "
                "rings above the noise (cut the record where it meets it)"
            )
        else:
            out.append(
                f"the model's held-out {what} by {worst:.3g} % of the record's rms: worse than predicting zero, "
                "so it explains nothing of the held-out part"
            )
    if own_modal is not None and modal is not None:
        for well in ("minus", "plus"):
            for f_own, f_lin in zip(_modes(own_modal, well), _modes(modal, well), strict=False):
                if f_own and f_lin and abs(f_own / f_lin - 1) > MODAL_CONTRADICTION:
                    out.append(
                        f"the {well} well's modal frequency {f_own:.3g} Hz contradicts the model's own linearisation "
                        f"sqrt(K'(z*)/m) = {f_lin:.3g} Hz: the subspace step and the restoring force disagree " + causes
                    )
                elif f_own and not f_lin:
                    out.append(
                        f"the {well} well has a modal frequency by the method ({f_own:.3g} Hz) but none by the model's "
                        "own linearisation (the model has no stable equilibrium there): the subspace step and the "
                        "restoring force disagree"
                    )
                elif f_lin and not f_own:
                    out.append(
                        f"the {well} well has a modal frequency by the model's linearisation ({f_lin:.3g} Hz) but "
                        "none by the method: the subspace step and the restoring force disagree"
                    )
    return out


def classified(rec, model=None, own: list[str] | tuple[str, ...] = ()) -> list[tuple[type, str]]:
    """Every warning about a result (``own``: the method's, boundedness, convergence) and about its record
    (its derivation, its units, its frame) and model (wells beyond the stroke), each with its
    ``NegstiffWarning`` category, without repeats: what the result holds and Python's ``warnings`` issue.
    """

    def kind(text: str) -> type:
        if "not bounded" in text:
            return BoundednessWarning
        if "diverged" in text or "converge" in text or "R-hat" in text or " ESS " in text:
            return ConvergenceWarning
        return NegstiffWarning

    resp = rec.info.get("response", {}) if rec is not None else {}
    lines = [(kind(t), t) for t in own]
    lines += [
        (RecordWarning, t) for t in [*rec.info.get("warnings", []), *resp.get("warnings", []), *rec.unit_warnings()]
    ]
    if model is not None:
        lines += [(RecordWarning, t) for t in input_warnings(rec)]
        lines += [(FrameWarning, t) for t in frame_warnings(rec)]
        lines += [(ExtrapolationWarning, t) for t in model_warnings(model, rec)]
    seen, out = set(), []
    for cat, text in lines:
        if text not in seen:
            seen.add(text)
            out.append((cat, text))
    return out
