"""One identification pipeline: what every identification shares, written once.

An identification method (``NSI``, ``SINDy``) supplies only its own estimate of the equation of motion
(``Identifier._estimate``: the method's equation-error model, the mass it used and, where the method has
them, its own modal parameters). Everything after it is this module's, the same for every method:

1. the split: the first ``1 - validation_fraction`` of the record identifies, the tail is held out;
2. the free-run validation over the tail (``validation.validate``: the contract's ``rms_percent`` and
   the restarted 2 s runs chaos cannot fake);
3. the output-error refinement (``refine.refine_stage``), kept only if it predicts the tail at least as
   well (``refine=False`` skips it);
4. the equilibria and each well's modal parameters of the final model (or the method's own, NSI's
   subspace step: reference study Table 1);
5. boundedness beyond the stroke and under 1.2x the input (``validation.boundedness``);
6. every warning a physicist would want: the method's own, boundedness, equilibria, a diverged
   validation, and the record's plausibility (units, mm-vs-m, an input in g, the frame, wells beyond the
   stroke: ``plausibility``). Each goes through Python's ``warnings`` (a ``NegstiffWarning``) and into the
   result, so a script sees what the command line prints.

The result is a frozen ``Identification`` (after ``scipy.integrate.solve_ivp``'s result bunch: named
fields, ``to_json()`` the contract's identify JSON). ``initial_model`` is the method's own estimate (its
equation-error step); ``model`` is the refined one. Refined NSI and SINDy models reach the same output-error
optimum (to 1e-9 on the rig's records), so a consistency check *between methods* compares
``initial_model`` (or ``modal``), not ``model``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Self

import numpy as np

from negstiff.errors import InputError, MeasurementError, issue
from negstiff.errors import NegstiffWarning as _Warning
from negstiff.inference.analysis.record_kind import ring_down, rings_until
from negstiff.inference.estimators.base import Estimator
from negstiff.inference.estimators.prediction import window_errors
from negstiff.inference.estimators.results import Bunch, Identification, _plain
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps import law_choice
from negstiff.inference.steps.equations import StructureIdentificationError, _split
from negstiff.inference.steps.plausibility import classified, judgement, model_warnings
from negstiff.inference.steps.refine import refine_stage, stroke_quantiles
from negstiff.inference.steps.validation import boundedness, predictability, restarted_free_runs, validate
from negstiff.inference.steps.validation import restarted_structure_runs as free_run_error
from negstiff.models import Model, compile_ahead, laws
from negstiff.models.equation import Equilibria
from negstiff.models.simulator import stage_input
from negstiff.models.structure import Mode, Structure, simulate_structures


@dataclass(frozen=True)
class Estimate:
    """What a method estimates by itself, before the shared stages (``Identifier._estimate``)."""

    model: Model
    """The method's equation-error model in the z frame (the contract's model fields)."""
    mass_source: str
    """Where the mass came from (``weak.mass_of``)."""
    input_gain: float
    """The input's coefficient the method learned or fixed (1/m for a force, 1 for base excitation)."""
    modal: dict[str, dict[str, float | None]] | None = None
    """The method's own modal parameters of each well; None: those of the final model's linearisation."""
    held: tuple[str, ...] = ()
    """Base fields the refinement keeps at their value (the terms a sparse method did not select)."""
    details: dict[str, Any] = field(default_factory=dict)
    """The method's own result keys (NSI: ``wells``, ``g_estimate``; SINDy: ``selected_terms``, ...)."""
    settings: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()


def visited_well(rec: Measurement, z: float, models: Sequence[Model] = (),
                 stroke: tuple[float, float] | None = None) -> str:  # fmt: skip
    """The name of the one well a record visited, at ``z`` [m].

    In order: the nearer of the rest positions the metadata states; else the nearer of the two wells of the
    first of ``models`` that has two; else the side of the barrier: the well lies below the region where a
    model's stiffness K'(z) is not positive (the barrier between the wells) for the minus well, above it for the
    plus well, that region sought within one span of ``stroke`` (lo, hi) [m] (where the record went) beyond its
    ends; else ``"plus"``, the contract's name for the well of a single-well system (a stiffness positive
    throughout). A cubic fitted over one well of a bistable device may keep one root only, but it keeps the
    softening towards the barrier (a record in the minus well, 11.41 Hz, was named plus by its one root).
    """
    rest = rec.rest_positions
    if len(rest) == 2:
        return min(rest, key=lambda w: abs(rest[w] - z))
    for model in models:
        try:
            eq = model.equilibria()
        except (ValueError, ArithmeticError):
            continue
        if eq.z_minus is not None and eq.z_plus is not None:
            return "minus" if abs(z - eq.z_minus) < abs(z - eq.z_plus) else "plus"
    lo, hi = stroke if stroke is not None else (z, z)
    lo, hi = min(lo, z), max(hi, z)
    span = hi - lo if hi > lo else max(abs(z), 1e-3)
    grid = np.linspace(lo - span, hi + span, 2001)
    for model in models:
        with np.errstate(all="ignore"):
            soft = grid[np.asarray(model.stiffness(grid), float) <= 0]
        if soft.size:
            return "minus" if soft[np.argmin(np.abs(soft - z))] > z else "plus"
    return "plus"


def equilibria_and_modes(
    model: Model, rec: Measurement, stroke: tuple[float, float], namers: Sequence[Model] = ()
) -> tuple[Equilibria | None, dict[str, dict[str, float | None]], list[str]]:
    """The model's equilibria and each well's underlying-linear frequency and damping ratio (None where the
    model has no such well), with the warnings they call for.

    A model fitted over one well of a record may have roots far outside what the record visited (a quintic's
    extra roots): then the equilibria inside the stroke (widened by half its span) are reported, and a
    warning says the others are an extrapolation. A single well is named by where it lies (``visited_well``:
    by ``model``, then by the other models of ``namers``, the same models that name the method's own well).
    """
    from negstiff.models.equation import find_equilibria

    notes: list[str] = []
    try:
        eq = model.equilibria()
    except ValueError as exc:
        lo, hi = stroke
        pad = 0.5 * (hi - lo)
        try:
            eq = find_equilibria(model.restoring_force, model.stiffness, lo - pad, hi + pad)
        except ValueError:
            return (
                None,
                {w: {"f_hz": None, "zeta": None} for w in ("minus", "plus")},
                [f"the identified restoring force has no usable equilibria: {exc}"],
            )
        notes.append(
            f"the identified restoring force's equilibria beyond the stroke the record visited are an "
            f"extrapolation ({exc}); the wells within it are reported"
        )
    if eq.z_minus is None and visited_well(rec, eq.z_plus, (model, *namers), stroke) == "minus":
        # the one well, named by where it is: as z_minus, z_plus None (against the type's single-well convention)
        eq = Equilibria(eq.z_plus, None, None)  # type: ignore[arg-type]
    modal: dict[str, dict[str, float | None]] = {}
    for well in ("minus", "plus"):
        z = eq.z_minus if well == "minus" else eq.z_plus
        k1t = float(model.stiffness(z)) if z is not None else math.nan
        if z is None or not k1t > 0:
            modal[well] = {"f_hz": None, "zeta": None}
            continue
        modal[well] = {
            "f_hz": math.sqrt(k1t / model.m) / (2 * math.pi),
            "zeta": model.c / (2 * math.sqrt(k1t * model.m)),
        }
    return eq, modal, notes


QUICK_TERMS = ("1", "z", "z^2", "z^3", "v", "v|v|")
"""The quick fit's library: the model file's own polynomial and damping."""


def refuse_one_orbit(rec: Measurement, method: str, at: tuple[int, int] = (0, 1)) -> None:
    """Refuse (``InputError``, one line, before any work) a harmonic record whose element's motion (its relative
    displacement between the points ``at`` it joins: the device's z on its base) is one nearly sinusoidal periodic
    orbit (``periodicity.steady_orbit``): its restoring force's nonlinearity shows only through small harmonics, and
    a fit's coefficients would be numbers the record does not hold.
    """
    from negstiff.inference.analysis.characterise import response_for
    from negstiff.inference.analysis.periodicity import steady_orbit

    orbit = steady_orbit(response_for(rec, at))
    if orbit is not None:
        if at != (0, 1):
            motion = f"whose element's relative motion z{at[1]}" + (f" - z{at[0]}" if at[0] else "")
            orbit = orbit.replace("whose response", motion)
        raise InputError(
            f"{rec.source}: {method} refused before its work: {orbit}: such an orbit shows the restoring force and "
            "damping near one amplitude alone, not their coefficients apart; identify a random or swept record of "
            "the device, or one that drives it across both wells, or characterise this one (negstiff characterise)"
        )


def refuse_softening(rec: Measurement, n_id: int, method: str) -> None:
    """Refuse, in a fraction of a second, a record whose plain weak-form least-squares cubic (``QUICK_TERMS``
    over the identification part) softens (k3 <= 0): no bounded double- or single-well model explains it, and
    a method would find so only after its work (NSI's "k3 must be positive" came after 17 s on a 400 s record
    whose drifting integral had merged the wells). A record too poor for the fit is left to the method.
    """
    from negstiff.inference.steps.weak import WeakFormError, weak_least_squares

    key = ("quick_cubic", n_id)
    if key in rec.derived:  # judged once per record (the check, then the fit)
        return
    try:
        quick = weak_least_squares(rec.segment(0, n_id), QUICK_TERMS)
    except (WeakFormError, np.linalg.LinAlgError, ValueError):
        return
    if quick.k3 > 0:
        rec.derived[key] = True
    else:
        raise InputError(
            f"{rec.source}: {method} refused before its work: the record's quick least-squares cubic softens "
            f"(k3 = {quick.k3:.3g} N/m^3), so no bounded double- or single-well model explains it; is z in m "
            "and in one frame throughout (a drifting integral, a sensor's zero that moved), and is it the "
            "response to this input?"
        )


PREDICTABLE_CAP_S = 2.0
"""The held-out windows sized by the record's predictability are at most as long as the 2 s windows."""


def predictable_validation(model: Model, rec: Measurement, n_id: int) -> dict[str, Any]:
    """The held-out tail [n_id, N) scored by ``model``'s runs restarted from the measured state in windows no
    longer than the record stays predictable (``validation.predictability``, the discrepancy workflow's horizon,
    measured with ``model`` over the identification part; at most ``PREDICTABLE_CAP_S``): on a chaotic record a
    2 s run is beyond what even the true model predicts (79-101 % measured), these windows are not. Returns the
    horizon and the windows' errors (``window_errors``' keys, ``restarted_rms_percent``, ``window_s``).
    """
    z0, v0, _, _ = rec.states("state")
    try:
        horizon = predictability(model, rec, n_id, 2 * PREDICTABLE_CAP_S, z0, v0)
        runs = restarted_free_runs(model, rec, n_id, horizon["window_s"], z0, v0)
    except (MeasurementError, ValueError, ArithmeticError):
        return {}
    if not runs:
        return {}
    ms = runs.pop("window_ms")
    return {"horizon_s": horizon["horizon_s"], "window_s": horizon["window_s"], "limited": horizon["limited"],
            **runs, **window_errors(ms, rec.displacement[n_id:])}  # fmt: skip


def quick_spline_holds(rec: Measurement, n_id: int) -> bool:
    """Whether a quick weak-form least-squares spline (8 intervals over the identification part's stroke, the
    reference study's damping) has a force that grows outward at both ends of the stroke: a bounded law may still
    explain a record whose quick cubic softens (a magnet's force, which turns over beyond its wells).
    """
    from negstiff.inference.steps.shape import stroke
    from negstiff.inference.steps.weak import Library, WeakForm, WeakFormError, fit_support, known_input_gain

    key = ("quick_spline_holds", n_id)
    if key in rec.derived:  # judged once per record (the check, then the fit)
        return rec.derived[key]
    part = rec.segment(0, n_id)
    lo, hi = stroke(part)
    shape = {"spline": {"knots": tuple(np.linspace(lo, hi, 9))}}
    lib = Library.of_laws("spline", laws.DEFAULT_DAMPING, shape)
    try:
        phys = fit_support(WeakForm.of(part).system(part, library=lib), known_input_gain(part))
        model = lib.model(phys, 1.0)
    except (WeakFormError, np.linalg.LinAlgError, ValueError):
        holds = False
    else:
        holds = bool(np.all(model.stiffness(np.array([lo, hi])) > 0))
    rec.derived[key] = holds
    return holds


class Identifier(Estimator):
    """Base of the identifications: ``fit`` runs the method's ``_estimate`` and then the shared stages
    (module docstring). Subclasses declare ``method`` and their parameters; ``validation_fraction``, ``refine``,
    ``law`` and ``damping`` are every identification's.
    """

    method: str = ""
    law: str | None = None
    damping: str = laws.DEFAULT_DAMPING

    def _estimate(self, rec: Measurement, n_id: int, law: laws.Law | None = None) -> Estimate:
        """The method's own estimate over the first ``n_id`` samples, reading ``law`` (None: the method's own
        default: NSI's cubic, SINDy's catalogue) with the damping law ``damping``.
        """
        raise NotImplementedError

    def _held_by_law(self, est: Estimate, law: str) -> Estimate:
        """``est`` with the base fields outside the restoring and the damping law held by the refinement (a law's
        model is refined within its law: the geometric law has no k1 to move).
        """
        free = set(laws.get(law).fields) | set(laws.get(self.damping, "damping").fields)
        outside = tuple(f for f in ("k0", "k1", "k2", "k3", "c", "c_nl") if f not in free and f not in est.held)
        return replace(est, held=(*est.held, *outside))

    def _kernels_ahead(self) -> tuple[str, ...]:
        """The simulator's kernels to compile ahead of this fit on a fresh install (``compile_ahead``), beside
        the one the fit compiles itself at its first simulation: none by default (one kernel, needed at once).
        """
        return ()

    def _estimate_law(self, rec: Measurement, n_id: int) -> tuple[Estimate, dict[str, Any] | None]:
        """The estimate of the law asked for, or of the law the record asks for (``law_choice``): a named law
        as it is; None the method's default, the other laws compared where it fails its checks (and said);
        ``"auto"`` every law compared. Returns the estimate and the comparison's account (None: no comparison).

        A record whose quick least-squares cubic softens is refused in a fraction of a second (``refuse_softening``)
        when the cubic is asked for by name, and by default unless a quick spline's force still grows outward at
        both ends of the stroke (``quick_spline_holds``): then the other laws are compared.
        """
        if self.law not in (None, "auto"):
            if self.law == laws.DEFAULT_RESTORING:
                refuse_softening(rec, n_id, type(self).__name__)
            return self._held_by_law(self._estimate(rec, n_id, laws.get(self.law, "restoring")), self.law), None
        names = laws.names("restoring")
        why, default = None, None
        if self.law is None:
            try:
                refuse_softening(rec, n_id, type(self).__name__)
            except InputError:
                if not quick_spline_holds(rec, n_id):
                    raise
                failed = ["its quick least-squares fit softens (k3 <= 0)"]
            else:
                try:
                    default = self._estimate(rec, n_id, None)
                    failed = law_choice.problems(default.model, rec, n_id)
                except (MeasurementError, ValueError, ArithmeticError) as exc:
                    failed = [" ".join(str(exc).split())]
                if not failed:
                    assert default is not None
                    return default, None
            why = f"the default law ({laws.DEFAULT_RESTORING}) failed its checks: {'; '.join(failed)}"
            names = tuple(n for n in names if n != laws.DEFAULT_RESTORING)
        state = dict(vars(self))  # the default's learned state (its wells, its selection): kept if no law passes
        try:
            choice = law_choice.choose(rec, n_id, names, lambda part, n, name: self._estimate(part, n, laws.get(name)),
                                       lambda est: est.model, why)  # fmt: skip
        except law_choice.NoLawError as exc:
            if default is None:
                raise
            vars(self).clear()
            vars(self).update(state)
            # the default's model, with what is wrong with it: the judgement's warnings follow (shared stages)
            said = f"{why}, and no other law passes its checks ({exc.reasons}): the default's model is kept, not to " \
                   "be believed"  # fmt: skip
            account = {"requested": self.law or "default", "why": why, **exc.windows, "chosen": None,
                       "summary": said, "candidates": [c.to_json() for c in exc.candidates]}  # fmt: skip
            return replace(
                default, warnings=(*default.warnings, said), details={**default.details, "law_choice": account}
            ), account
        best, windows = choice.best, choice.windows
        est = self._held_by_law(choice.estimate, best.law)
        account = {"requested": self.law or "default", "why": why, **windows,
                   "candidates": [c.to_json() for c in choice.candidates]}  # fmt: skip
        account["chosen"] = best.law
        said = (f"{why}; the laws were compared on what they predict" if why else "the laws were compared on what "
                "they predict") + (f" ({windows['windows']} windows of {windows['window_s']:.3g} s restarted over "
                f"the selection part): {best.law} chosen (median window {best.median_percent:.3g} %, weight "
                f"{best.weight:.2f})")  # fmt: skip
        return replace(
            est,
            warnings=(*est.warnings, said) if why else est.warnings,
            details={**est.details, "law_choice": {**account, "summary": said}},
        ), account

    def _check_response(self, rec: Measurement) -> None:
        """The record as the fit reads it checked in the record's check, before any progress line: a forced
        record's every response channel carries a trace of its input (``Measurement.require_response``), its
        element's motion is not one nearly sinusoidal orbit (``refuse_one_orbit``), and the device's quick cubic does
        not soften (``refuse_softening``: the device's own weak form, on its base). A vibrometer reading its own noise
        was refused by NSI's subspace step, after its progress line; a structure's, after its whole fit.
        """
        from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS, identification_record, record_kind
        from negstiff.inference.estimators.base import element_of

        at = element_of(self, rec) or (0, 1)
        kind = record_kind(rec)
        if kind.kind not in RING_DOWN_KINDS:
            rec.require_response(type(self).__name__)
            refuse_one_orbit(rec, type(self).__name__, at)
        if rec.n_dof == 1 and getattr(self, "element", None) is None:
            read = identification_record(rec, kind)
            n_id = int(round(read.n * (1 - self.validation_fraction)))
            # a softening quick cubic refuses here where the cubic is asked for, or where no law could hold the
            # record either (a quick spline's force does not grow outward at the stroke's ends); else the laws are
            # compared (``_estimate_law``). The spline is fitted only where the cubic softens.
            if self.law in (None, laws.DEFAULT_RESTORING):
                try:
                    refuse_softening(read, n_id, type(self).__name__)
                except InputError:
                    if self.law is not None or not quick_spline_holds(read, n_id):
                        raise

    def _final_details(self, rec: Measurement, model: Model, details: dict[str, Any]) -> dict[str, Any]:
        """The method's own result keys that depend on the final model (NSI's ``g_estimate``)."""
        return details

    def _name_own_well(self, est: Estimate, well: str) -> Estimate:
        """``est`` with the one well its own modal parameters give (where they give one) named ``well``: the name
        the final model and the method's own agree on (``visited_well``). A method keeping more under the wells'
        names (NSI's ``wells``) renames them too (``_renamed_well``).
        """
        if est.modal is None:
            return est
        found = [w for w, m in est.modal.items() if m.get("f_hz") is not None]
        if len(found) != 1 or found[0] == well:
            return est
        other = found[0]
        self._renamed_well(other, well)
        details = dict(est.details)
        if isinstance(details.get("wells"), dict) and other in details["wells"]:
            details["wells"] = {well if w == other else w: v for w, v in details["wells"].items()}
        return dataclasses.replace(est, modal={other: est.modal[well], well: est.modal[other]}, details=details)

    def _renamed_well(self, old: str, new: str) -> None:
        """What the method keeps under a well's name, renamed (``_name_own_well``); nothing by default."""

    def fit(self, data) -> Self:
        """Identify from ``data`` (a ``Measurement`` or a file path): the method's estimate, then the
        shared stages (module docstring); the result is ``result_`` (an ``Identification``).
        """
        rec = self.check(data)
        compile_ahead.start(self._kernels_ahead())  # a fresh install's kernels compile beside the fit's first steps
        n_id = int(round(rec.n * (1 - self.validation_fraction)))
        est, comparison = self._estimate_law(rec, n_id)
        stroke = stroke_quantiles(rec.z[:n_id])
        validation = validate(est.model, rec, n_id)
        model, refinement, mass_source = est.model, None, est.mass_source
        if self.refine is not False:  # None: where defined, and a single DOF's record is
            model, validation, refinement = refine_stage(est.model, rec, n_id, validation, held=est.held)
            if refinement["applied"] and refinement.get("free_mass"):
                mass_source += ", refined by simulation error"
        # the held-out headline robust to one well switch: the median restarted window, with the spread
        validation = {**validation, **window_errors(validation.get("window_ms", np.empty(0)), rec.displacement[n_id:]),
                      "predictable": predictable_validation(model, rec, n_id)}  # fmt: skip
        bounded = boundedness(model, rec.segment(0, n_id))
        span = (float(stroke[0]), float(stroke[-1]))
        # one well visited: one name for it, by the final and the method's own model alike (``visited_well``)
        est = self._name_own_well(est, visited_well(rec, float(np.median(rec.z[:n_id])), (model, est.model), span))
        equilibria, modal, eq_warnings = equilibria_and_modes(model, rec, span, (est.model,))
        judged = judgement(model, rec, validation, modal, est.modal, laws_compared=comparison is not None)
        details = dict(self._final_details(rec, model, est.details))
        details["modal_of_model"] = modal  # the final (refined) model's linearisation
        # ``modal`` is the method's own estimate (what method-vs-method checks compare): NSI's subspace pole,
        # else the linearisation of the method's own (equation-error) model, never the refined model's (NSI
        # and SINDy refine to the same output-error optimum, 6 digits alike)
        modal = est.modal if est.modal is not None else equilibria_and_modes(est.model, rec, span, (model,))[1]
        own = [*est.warnings, *([] if bounded["ok"] else [bounded["warning"]]), *eq_warnings, *judged]
        if validation.get("diverged"):
            own.append(validation["warning"])
        lines = classified(rec, model, own)
        issue(lines)
        self.result_ = Identification(
            method=self.method,
            system=Structure.single(model),
            initial_system=Structure.single(est.model),
            linear_part="none",
            equilibria=equilibria,
            modal=modal,
            validation=Bunch(validation),
            refinement=_plain(refinement),
            bounded=Bunch(bounded),
            stroke_quantiles_m=stroke,
            identification_samples=n_id,
            mass_source=mass_source,
            mass_normalised=est.mass_source.startswith("none"),
            input_gain=est.input_gain,
            record=dict(rec.info),
            warnings=tuple(text for _, text in lines),
            details=details,
            settings={**est.settings, "identification_samples": n_id, "input": rec.input_name},
        )
        return self

    # the learned state under scikit-learn's names (``model_``, ``validation_``, ...): the result's fields
    model_ = property(lambda self: self.result_.model)
    initial_model_ = property(lambda self: self.result_.initial_model)
    equilibria_ = property(lambda self: self.result_.equilibria)
    modal_ = property(lambda self: self.result_.modal)
    validation_ = property(lambda self: self.result_.validation)
    refinement_ = property(lambda self: self.result_.refinement)
    bounded_ = property(lambda self: self.result_.bounded)
    stroke_ = property(lambda self: self.result_.stroke_quantiles_m)
    warnings_ = property(lambda self: list(self.result_.warnings))
    settings_ = property(lambda self: self.result_.settings)
    mass_source_ = property(lambda self: self.result_.mass_source)
    mass_normalised_ = property(lambda self: self.result_.mass_normalised)
    input_gain_ = property(lambda self: self.result_.input_gain)

    @property
    def fitted(self) -> bool:
        """Whether ``fit`` has run (the learned attributes exist)."""
        return "result_" in vars(self)

    def result(self) -> dict[str, Any]:
        """The contract's identify JSON (``result_.to_json()``)."""
        return self.result_.to_json()

    def own_estimate(self, data, blocks: int = 3) -> dict[str, Any]:
        """The method's own estimate (``initial_model_``, ``modal_``) with its standard error, by batch means:
        the identification part of the record (``data``: the record this estimator was fitted on) cut into
        ``blocks`` contiguous blocks, the method's own step (``_estimate``, no refinement) run on each; the
        full record's estimate errs by the blocks' scatter over sqrt(blocks) (each block carries 1/blocks of
        its information, the blocks nearly independent: the record's correlation time is far below a
        block). Each block must be long enough for the method.

        Returns
        -------
        dict
            ``{"modal": {WELL: {"f_hz", "f_hz_se", "zeta", "zeta_se"}}, "model": {NAME: value},
            "model_se": {NAME: se}, "blocks": [...], "method": ..., "mass_normalised"}``: the estimate is this fit's
            own (``modal_``, ``initial_model_``), the standard errors the blocks'; ``mass_normalised``: per unit mass.
        """
        rec = self.check(data)
        if not (isinstance(blocks, int) and blocks >= 2):
            raise InputError(f"own_estimate(blocks={blocks!r}): two blocks at least")
        if self.result_.linear_part != "none":
            return self._blocks_of_structure(rec, blocks)
        n_id = int(round(rec.n * (1 - self.validation_fraction)))
        edges = np.linspace(0, n_id, blocks + 1).round().astype(int)
        per_block = []
        for a, b in zip(edges[:-1], edges[1:], strict=True):
            part = rec.segment(int(a), int(b))
            est = self._estimate(part, part.n)
            stroke = stroke_quantiles(part.z)
            modal = est.modal or equilibria_and_modes(est.model, part, (float(stroke[0]), float(stroke[-1])))[1]
            per_block.append({"segment_s": [a / rec.fs, b / rec.fs], "modal": modal, "model": est.model.to_dict()})
        own = self.result_
        out_modal: dict[str, dict[str, float | None]] = {}
        for well, m in own.modal.items():
            row: dict[str, float | None] = {"f_hz": m.get("f_hz"), "zeta": m.get("zeta")}
            for key in ("f_hz", "zeta"):
                row[f"{key}_se"] = _batch_se([blk["modal"].get(well, {}).get(key) for blk in per_block])
            out_modal[well] = row
        names = ("k0", "k1", "k2", "k3", "c", "c_nl")
        model_se = {n: float(np.std([blk["model"][n] for blk in per_block], ddof=1) / math.sqrt(blocks)) for n in names}
        return {"method": self.method, "modal": out_modal, "model": {n: getattr(own.initial_model, n) for n in names},
                "model_se": model_se, "blocks": per_block, "mass_normalised": own.mass_normalised,
                "standard_error": f"batch means over {blocks} blocks of the identification part"}  # fmt: skip

    def _blocks_of_structure(self, rec: Measurement, blocks: int) -> dict[str, Any]:
        """``own_estimate`` of a structure's fit: each block of the identification part identified alone by this
        estimator with its parameters (refinement off: the method's own estimate, as the single DOF's blocks run its
        own step), every mode of every well and every coefficient of the element with the blocks' standard error.
        A block's fit splits off its own held-out tail, so each block's estimate reads 1 - ``validation_fraction``
        of the block; the standard error is the blocks' scatter over sqrt(blocks) all the same (conservative by
        about sqrt(1 / (1 - validation_fraction)), 12 % at the default).
        """
        import warnings

        own = self.result_
        n_id = own.identification_samples or int(round(rec.n * (1 - self.validation_fraction)))
        edges = np.linspace(0, n_id, blocks + 1).round().astype(int)
        params = {**self.get_params(deep=False), "refine": False}
        per_block: list[dict[str, Any]] = []
        for k, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True)):
            part = rec.segment(int(a), int(b))
            try:
                with warnings.catch_warnings():  # a block's notes are its own fit's, not the record's
                    warnings.simplefilter("ignore")
                    res = type(self)(**params).fit(part).result_
            except (InputError, MeasurementError) as exc:
                raise InputError(
                    f"{rec.source}: own_estimate(blocks={blocks}): block {k + 1} ({a / rec.fs:.3g}-{b / rec.fs:.3g} s) "
                    f"is not identified alone ({' '.join(str(exc).split())}); give fewer blocks"
                ) from None
            per_block.append({"segment_s": [a / rec.fs, b / rec.fs], "modal": {w: [m.to_json() for m in ms]
                              for w, ms in res.modal.items()}, "model": _element_values(res)})  # fmt: skip
        out_modal: dict[str, list[dict[str, float | None]]] = {}
        for well, modes in own.modal.items():
            rows = []
            for i, mode in enumerate(modes):
                row: dict[str, float | None] = {"f_hz": mode.f_hz, "zeta": mode.zeta}
                for key in ("f_hz", "zeta"):
                    vals = [blk["modal"][well][i][key] for blk in per_block if len(blk["modal"].get(well, ())) > i]
                    row[f"{key}_se"] = _batch_se(vals)
                rows.append(row)
            out_modal[well] = rows
        values = _element_values(own, initial=True)
        model_se = {n: float(np.std([blk["model"][n] for blk in per_block], ddof=1) / math.sqrt(blocks))
                    for n in values if all(n in blk["model"] for blk in per_block)}  # fmt: skip
        return {"method": self.method, "modal": out_modal, "model": values, "model_se": model_se,
                "blocks": per_block, "mass_normalised": False, "dofs": own.dofs, "element_at": list(own.element_at),
                "standard_error": f"batch means over {blocks} blocks of the identification part, each identified "
                                  "alone without refinement"}  # fmt: skip

    def _restore(self, result: dict[str, Any]) -> None:
        self.result_ = Identification.from_json(result)

    def _summary(self) -> str:
        return self.result_.summary()


def _batch_se(values) -> float | None:
    """The batch-means standard error of the blocks' ``values`` (those given and finite): their scatter over the
    square root of their number; None below two.
    """
    ok = [float(v) for v in values if v is not None and math.isfinite(v)]
    return float(np.std(ok, ddof=1) / math.sqrt(len(ok))) if len(ok) >= 2 else None


def _element_values(result: Identification, initial: bool = False) -> dict[str, float]:
    """The element's coefficients a structure's result gives: its law's k0 ... c_nl (``initial``: before the
    refinement, the method's own), or a state-space linear part's element values.
    """
    if result.element_estimate:
        return {
            n: float(e["value"]) for n, e in result.element_estimate.items() if isinstance(e, dict) and "value" in e
        }
    law = result.initial_model if initial else result.model
    return {n: float(getattr(law, n)) for n in ("k0", "k1", "k2", "k3", "c", "c_nl")}


# --- a structure's shared stages (N > 1 DOFs with their masses) -----------------------------------------------
NOISE_FLOOR_FACTOR = 2.0
"""A model whose held-out free runs miss the record by more than this many times what the channels' sensor noise
alone explains is warned about."""


WINDOW_S = 0.25
"""Held-out free runs' length [s]: two periods of the wells (over cross-well chaos a 1 s run diverges for any
model, the truth too, and then a model that moves less scores better)."""


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
    judge = lambda system, zeros: held_out_runs(system, rec, n_id, zeros, hits, paired=True)  # noqa: E731
    paired = validation if "paired_window_ms" in validation else judge(structure, offsets)
    kept, kept_validation, account = refine_stage(start, rec, n_id, paired, held=("k0",), offsets=offsets, judge=judge)
    if not account["applied"]:
        return structure, offsets, _without_windows(validation), account
    return kept, np.asarray(account["offsets_m"]), _without_windows(kept_validation), account


def held_out_runs(structure: Structure, rec: Measurement, n_id: int, offsets, hits: bool,
                  paired: bool = False) -> dict[str, Any]:  # fmt: skip
    """A structure's held-out windows (``free_run_error`` over [n_id, end) in ``WINDOW_S`` windows; ``hits``: a
    hammer's, between its pulses); ``paired``: with each window's mean square error (``paired_window_ms``, an array
    the refinement's paired comparison reads: ``refine.refine_stage``; ``_without_windows`` takes it off).
    """
    runs = free_run_error(structure, rec, n_id, WINDOW_S, offsets, hits, paired)
    if paired:
        runs["paired_window_ms"] = runs.pop("window_ms")
    return runs


def _without_windows(validation: dict[str, Any]) -> dict[str, Any]:
    """``validation`` without its per-window array (not the result's JSON)."""
    return {k: v for k, v in validation.items() if k != "paired_window_ms"}


def check_ring_down_scores(est, rec: Measurement) -> None:
    """Refuse (``StructureIdentificationError``, one line, before any work) a structure's free decay that rings down
    into its sensors' noise before the part that scores the candidate models (``_split``: from ``n_fit`` on):
    ``record_kind.rings_until``, every channel's rms about its rest within ``RINGING_FACTOR`` of its noise from
    there on. As the single DOF's check (``SINDy.check_length``), which its widening test functions make; the
    structure's blocks were shortened to fit that part instead, and scored noise: the seed-like device on its fixture
    released 6 mm past its well rings for one of its 12 s, and SINDy's k3 came out 28x the truth, the posterior's
    windows all unmatched (measured).
    """
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


def structure_result(method: str, rec: Measurement, structure: Structure, offsets: np.ndarray, n_id: int,
            modal: dict[str, list[Mode]] | None, own_warnings: list[str], details: dict, settings: dict,
            refine: bool = False) -> Identification:  # fmt: skip
    """The shared stages of a structure's identification: the output-error refinement (``refine``: the one
    ``refine.refine_stage``, the element's constant held at the weight its frame pins, kept only if the held-out
    windows are predicted no worse; the modes are then the refined structure's), equilibria, linear matrices, modes,
    held-out free runs against the noise floor, warnings (issued as ``NegstiffWarning`` and kept in the result).
    """
    hits = ring_down(rec, ("impact",))  # a hammer's record: the held-out windows between its pulses
    own_modal = modal  # the method's own modes (NSI's wells'), judged against the final structure's
    validation = held_out_runs(structure, rec, n_id, offsets, hits, paired=refine)  # one run, the refinement's too
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
    return Identification(
        method=method, system=structure, modal=modal, linear=linear, linear_part="physical",
        equilibria={w: z.tolist() for w, z in eq.items()}, offsets_m=tuple(float(x) for x in offsets),
        validation=Bunch(validation), warnings=tuple(lines), details=details,
        settings={**settings, "identification_samples": n_id,
                  "refinement": REFINEMENT_SETTING if refine else "none (refine=False)",
                  "frame": "each channel's zero estimated (a constant force per DOF), the element's constant pinned at "
                           "the weight it carries (m_J g, g the record's gravity)"},
        refinement=None if refinement is None else Bunch(refinement), identification_samples=n_id,
    )  # fmt: skip
