"""Discrepancy workflow: find where the model and the data disagree, name the missing effect, add it,
refit, and show the gap shrink (Kaheman et al. 2019 and Ebers et al. 2024, ecosystem.md 6: the known
physics fixed, the mismatch sought as a sparse term from a physical catalogue).

1. **Locate.** The baseline (the seed's model: cubic K, viscous c, quadratic c_nl; linear K for a start from
   nothing; or a restoring and a damping law of ``models.laws`` at the record's shape, ``law=``, ``damping=``, the
   law the record asks for with ``law="auto"``, chosen by the identifications' one comparison, ``law_choice.choose``)
   is fitted by weak-form least squares (``weak.weak_least_squares``: the input's coefficient fixed by
   physics). Its weak residual, the equation error each test function sees, is mapped over the state (z, z'),
   split by regime (in either well, crossing, near zero velocity, at large stroke), and its share in each regime
   is compared with the regime's share of the record; restarted short free runs give the gap in time and as a
   PSD. A long free run is never used: cross-well motion diverges even for the true model (device-model.md).
2. **Name.** Each catalogue effect (``catalogue()``: every effect of ``models.effects``) is added to the
   baseline in turn, refitted on the first part of the data and scored on the held-out part by its weak residual
   (an equation error that chaos cannot fake). ``none`` is the baseline itself. An effect is named only if it
   lowers the held-out residual by more than max(one standard error of the paired per-block differences,
   ``margin``) (the one-standard-error rule plus a practical margin, as in ``sindy``): otherwise the answer is
   ``none``. Among effects that close to the best, the one with fewer parameters wins. Every other restoring law
   is a candidate too (``law:NAME``, where the baseline's restoring force is a law): its columns at its shape
   (``shape.fit_shape``, variable projection) replace the restoring force's rather than add a term, scored alike,
   counting the parameters it adds to the current restoring force, and never named where it fails the
   identifications' checks (``law_choice.problems``): "the force is not a cubic" can be what is named (the rig's
   as-built device: the geometric law, where the catalogue alone named z^5, z^4 and a stop it does not have).
3. **Add and refit.** The winner enters the model (its ``extra``; an effect whose term is a base field's, such
   as ``z'|z'|`` or z^3, lands in that field, c_nl or k3, and only there: one home per term), every parameter is
   refitted on all identification data, and the gap is measured again on the held-out tail: restarted free runs
   (the median window's rms error: a window whose run diverges near the barrier, chaos, would dominate a pooled
   rms), residual PSD, maps.
4. **Iterate** until ``none`` wins (at most ``max_effects``). An effect the held-out tail barely reaches is
   judged where it acts anywhere in the record by blocked cross-validation (``_regime_folds``).
5. **Size and second opinion.** Each named effect's interval by a Laplace approximation of the output error over
   the record's restarted windows (``effect_interval``; ``Posterior`` samples no ``extra`` effect), and
   ``arviz.compare``'s LOO over those windows with and without it (``_bayesian_opinion``) beside the rule above.

A hammer's record and a free decay (``record_kind``) are read as NSI and SINDy read them (the force windowed, a
decay without an input; blocks and windows shortened to the ring-down by SINDy's rule); on a hammer's record the
weak-form rows and restarted windows that would hold a pulse, which its few samples do not resolve, are not read:
the hits set the states, the ring-downs after them are what is scored (docs/methods/discrepancy.md).

The workflow (``Discrepancy``, here) is built of layers by role, each a private module and the base of the next:
``_weak`` (the weak-form systems and fits), ``_baseline`` (step 1's laws), ``_locating`` (1), ``_scoring`` (2),
``_runs`` (the restarted free runs and their windows), ``_opinions`` (5's second opinion), ``_judging`` (3: whether
an effect is kept), ``_intervals`` (5's sizes); ``_candidates`` holds the catalogue and a candidate's sizes, and
``hybrid`` the non-parametric force (``unnamed=True``).
"""

from __future__ import annotations

import math
from typing import Any, override

import numpy as np

from negstiff.errors import InputError, issue
from negstiff.inference.estimators.base import ElementPlace, element_of
from negstiff.inference.estimators.parameters import FRACTION, RESTORING_LAW, Boolean, Interval, LawName
from negstiff.inference.estimators.results import (
    Bunch,
    Identification,
    StructureResults,
    _plain,
    workflow_validation,
)
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.plausibility import classified
from negstiff.inference.steps.refine import refine_stage
from negstiff.inference.steps.selection import compare
from negstiff.inference.steps.validation import boundedness, validate
from negstiff.inference.steps.weak import aux_terms
from negstiff.models import effects, laws
from negstiff.models.structure import Structure

from ._candidates import (
    _READ,
    CUBIC_BASELINE,
    LINEAR_BASELINE,
    Candidate,
    DiscrepancyError,
    LibraryTerms,
    _held,
    _passes_measured,
    _scores,
    _stop_of,
    catalogue,
    law_of,
    law_parameters,
    share_text,
)
from ._intervals import Intervals
from ._rounds import structure_rounds

__all__ = [
    "CUBIC_BASELINE",
    "LINEAR_BASELINE",
    "Candidate",
    "Discrepancy",
    "DiscrepancyError",
    "catalogue",
    "law_of",
    "law_parameters",
    "share_text",
]


class Discrepancy(StructureResults, Intervals):
    """The discrepancy workflow: locate where a model and the data disagree, name the missing effect,
    add it, refit, and show the gap shrink (``docs/methods/discrepancy.md``).

    Parameters
    ----------
    baseline : tuple of str, default ("1", "z", "z^2", "z^3", "v", "v|v|")
        Library terms of the starting model where no ``law`` is given: the seed's model (cubic K, viscous c,
        quadratic c_nl). An effect whose law is a base field's term (``quadratic_damping`` is c_nl's ``z'|z'|``) is
        never a candidate beside that field, and when named from a smaller baseline it lands in its field: one home
        per term.
    law : str, optional
        The baseline's restoring law (``models.laws``: ``cubic``, ``quintic``, ``septic``, ``magnet``,
        ``oblique_springs``, ``geometric``, ``spline``): its columns at the shape the record gives its shaped parts
        (``shape.fit_shape``, variable projection on the weak form). ``"auto"``: the law the record asks for, chosen
        as the identifications choose it (``law_choice.choose``: each law judged, then compared on restarted windows
        at the record's predictability horizon). None: ``baseline``'s terms.
    damping : str, optional
        The baseline's damping law (``viscous``, ``quadratic``, ``cubic_damping``, ``friction``): its columns
        replace ``baseline``'s velocity terms. None: ``baseline``'s own with no ``law`` (the reference study's
        quadratic damping by default), the reference study's ``quadratic`` with one.
    offer_laws : bool, optional
        Offer every other restoring law as a candidate beside the catalogue's effects (``law:NAME``: it replaces
        the restoring force rather than adding a term to it), scored by the same held-out rules, so that "the force
        is not a cubic" can be what is named. None (default): where the baseline's restoring force is a law (the
        cubic of the seed's model, or ``law``'s), not where it is none (``LINEAR_BASELINE``: a start from nothing,
        which the catalogue's terms build up one at a time; a law would add several at once, the Silverbox's z^2
        and z^3 as the cubic law before its cubic stiffness).
    validation_fraction : float, default 0.2
        Held-out tail on which the gap is measured before and after.
    selection_fraction : float, default 0.2
        The part before the tail on which candidate effects are scored.
    margin : float, default 0.1
        Relative gain in held-out residual an effect must bring to be named.
    max_effects : int, default 3
        Effects added at most (iterations).
    window_s : float, default 2
        Restarted free runs and residual blocks [s]; on a hammer's record or a free decay shortened to what gives
        the scoring part two blocks (``sindy.ring_down_window``: ``window_s_``).
    refine : bool or None, default None
        Refine each model by output error (an effect is kept only if it then predicts better). None: on any record
        but a hammer's (its windows would cross the pulses); a structure's baseline and final structure are
        refined alike, so its gap before and after the effects compares refined models.
    unnamed : bool, default False
        Add a non-parametric force for what no catalogue effect names (the hybrid model; a structure's on its
        element's relative motion, held and jointly with the structure: ``_rounds.unnamed_term``).
    element : str or (int, int), optional
        Where the element acts on a record of N > 1 DOFs: ``"I-J"`` (``_rounds.structure_rounds``: the element's
        base law with the linear structure as the baseline, the catalogue offered round after round up to
        ``max_effects``, the same paired block rule). None: the record's ``# element:``, else the single DOF.

    Attributes
    ----------
    result_ : Identification
        The result, as every identification's (``estimators.results``): the final model as a structure of one DOF
        (``result_.model`` is ``model_``), its held-out gap as its ``validation``, the workflow's own account
        (below) in its ``details``; ``to_json()`` is the ``discrepancy`` command's JSON (``layout`` "workflow"). On a
        structure's record the structure's (``_rounds.structure_rounds``).
    model_ : Model
        The final model, named effects in ``model_.extra``.
    baseline_model_ : Model
        The baseline's fit.
    effects_ : list of str
        The effects named and kept, in order (``["none"]`` when nothing was missing); a law that replaced the
        restoring force is ``law:NAME``.
    law_ : str or None
        The final model's restoring law (None: a baseline's terms that are no law's, ``LINEAR_BASELINE``).
    baseline_law_ : dict
        The baseline's laws: ``restoring``, ``damping``, what was ``requested``, the ``shape`` and, with
        ``law="auto"``, the comparison that chose it (``choice``).
    laws_offered_ : list of str
        The restoring laws offered as candidates.
    gap_before_, gap_after_ : dict
        The held-out gap of the baseline and of the final model (restarted free runs).
    gap_regime_ : dict
        Per named effect, the gap over the held-out windows where it acts (``_regime``): ``before`` (the
        baseline), ``after`` (the final model): the median window's rms error in % of those windows' rms z;
        ``windows``, ``window_s``.
    predictability_ : dict
        The record's predictability horizon (``_predictability``: the baseline's runs restarted from states that
        differ by their noise part by 10 % of rms z), measured before any effect is scored; ``window_s`` there is
        the length of the regime's and the interval's windows (the horizon, at most ``window_s / 2``).
    locate_before_, locate_after_ : dict
        Where the equation error sits, by regime, before and after.
    iterations_ : list of dict
        Each round's ranking of the catalogue and what it named.
    effect_interval_ : dict
        Per named effect, its size with its 90 % interval (``effect_interval``: a Laplace approximation).
    bayesian_ : dict
        Per named effect, ``arviz.compare``'s LOO over the record's windows with and without it.
    warnings_ : list of str
        Every warning (also issued as ``NegstiffWarning``).
    record_kind_ : RecordKind
        What kind of test the record is (``record_kind``): a hammer's record is read with its force windowed, its
        weak-form rows and restarted windows clear of the pulses (``_between_pulses``, ``_after_pulses``); a free
        decay from its own initial state, without an input.
    window_s_ : float
        The blocks' and restarted windows' length used [s] (``window_s``, shortened on a ring-down).

    Examples
    --------
    >>> from negstiff import Discrepancy, Measurement, Rig
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rig = Rig(SEED_LIKE_CUBIC, effects={"end_stop": {"k": 3000.0, "z": -0.038}}, seed=5)
    >>> disc = Discrepancy().fit(Measurement.from_rig(rig.random(duration=120.0, rms=20.0)))
    >>> "end_stop" in disc.effects_
    True
    >>> disc.gap_after_["median_window_percent"] < disc.gap_before_["median_window_percent"]
    True
    """

    _parameter_constraints = {
        "baseline": LibraryTerms(),
        "validation_fraction": FRACTION,
        "selection_fraction": FRACTION,
        "margin": Interval(float, 0.0),
        "max_effects": Interval(int, 0, 20),
        "window_s": Interval(float, 0.0, lo_open=True, unit="s"),
        "refine": Boolean(none=True),
        "unnamed": Boolean(),
        "element": ElementPlace(),
        "law": RESTORING_LAW,
        "damping": LawName("damping", (None,)),
        "offer_laws": Boolean(none=True),
    }

    def __init__(
        self,
        *,
        baseline: tuple[str, ...] = CUBIC_BASELINE,
        validation_fraction: float = 0.2,
        selection_fraction: float = 0.2,
        margin: float = 0.1,
        max_effects: int = 3,
        window_s: float = 2.0,
        refine: bool | None = None,
        unnamed: bool = False,
        element: str | tuple[int, int] | None = None,
        law: str | None = None,
        damping: str | None = None,
        offer_laws: bool | None = None,
    ):
        self.law = law
        self.damping = damping
        self.offer_laws = offer_laws
        self.element = element
        self.refine = refine
        self.unnamed = unnamed
        self.baseline = baseline
        self.validation_fraction = validation_fraction
        self.selection_fraction = selection_fraction
        self.margin = margin
        self.max_effects = max_effects
        self.window_s = window_s

    def _validate(self) -> None:
        if self.law is not None and tuple(self.baseline) != CUBIC_BASELINE:
            raise InputError(f"Discrepancy(law={self.law!r}, baseline={self.baseline!r}): a law's baseline is its "
                             "columns (with the damping law's): give a law or baseline terms, not both")  # fmt: skip
        if self.validation_fraction + self.selection_fraction >= 1:
            raise DiscrepancyError(
                f"Discrepancy(validation_fraction={self.validation_fraction}, selection_fraction="
                f"{self.selection_fraction}): together they leave nothing to fit"
            )

    def _check_record(self, rec: Measurement) -> None:
        at = element_of(self, rec)  # None: a single DOF's record
        if at is not None:
            if tuple(self.baseline) != CUBIC_BASELINE:
                raise DiscrepancyError(f"Discrepancy(baseline={self.baseline!r}): a structure's baseline is its "
                                       "element's cubic law with the linear structure (leave baseline at its "
                                       "default)")  # fmt: skip
            if self.law is not None or self.damping is not None:
                raise DiscrepancyError(f"Discrepancy(law={self.law!r}, damping={self.damping!r}): a structure's "
                                       "baseline is its element's cubic law with the linear structure (give no "
                                       "law)")  # fmt: skip
        from negstiff.inference.analysis.record_kind import check_decay, record_kind
        from negstiff.inference.estimators.identification import check_ring_down_scores, refuse_one_orbit

        kind = record_kind(rec).kind
        rec.require(4000, "the discrepancy workflow")
        if kind != "decay":  # a free decay has no input: its response must ring down instead
            rec.require_excitation("the discrepancy workflow")
            refuse_one_orbit(rec, "the discrepancy workflow", at or (0, 1))
        else:
            check_decay(rec, "the discrepancy workflow")
        rec.require_motion("the discrepancy workflow")
        rec.require_live_aux("the discrepancy workflow")
        if at is None:
            self.check_length(rec)
        else:
            check_ring_down_scores(self, rec)

    def check_length(self, rec: Measurement) -> None:
        """Refuse a single DOF's record too short to score an effect (two ``window_s`` blocks of the part
        [n_fit, n_id)) with one ``DiscrepancyError``, before any work (``sindy.selection_blocks``: the record's
        spectrum, no fit); a structure's record is checked by its fit.
        """
        from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS, identification_record, record_kind
        from negstiff.inference.estimators.sindy import ring_down_window, selection_blocks

        kind = record_kind(rec)
        window = ring_down_window(rec, self.validation_fraction, self.selection_fraction, self.window_s)
        # counted on the record as the fit reads it: a decay named so (--decay) whose force channel holds noise has
        # a ring-down's test functions there, wider than its noisy input's (it passed, and the fit then refused)
        read = identification_record(rec, kind)
        blocks, need_s = selection_blocks(read, self.validation_fraction, self.selection_fraction, window)
        if blocks < 2 and kind.kind in RING_DOWN_KINDS:  # a longer record would not help
            raise DiscrepancyError(
                f"{rec.source}: the discrepancy workflow cannot score its candidate effects on this ring-down: the "
                f"part that scores them ({100 * self.selection_fraction:.0f} % of the record, before the held-out "
                f"tail) holds under two blocks of {window:.3g} s of test functions; a response decayed into its "
                "noise there widens them (cut the record where it meets the noise, or hit again before it does)"
            )
        if blocks < 2:
            lo, hi = 1 - self.validation_fraction - self.selection_fraction, 1 - self.validation_fraction
            raise DiscrepancyError(
                f"{rec.source}: too short for the discrepancy workflow: {rec.duration:.3g} s, at least about "
                f"{need_s:.3g} s are needed (the part from {100 * lo:.0f} to {100 * hi:.0f} % of the record scores "
                f"each effect in {self.window_s:g} s blocks, two at least)"
            )

    def fit(self, rec: Measurement) -> Discrepancy:
        """Locate, name, add and refit on ``rec`` (a ``Measurement`` or a path); returns ``self``."""
        from negstiff.inference.analysis.record_kind import identification_record, record_kind

        rec = self.check(rec)
        at = element_of(self, rec)
        if at is not None:
            # a structure's ring-down read as NSI and SINDy read it (``record_kind``): a hammer's force windowed, a
            # decay's input zero; its blocks shortened to the ring-down and its held-out windows between the pulses
            self.result_ = structure_rounds(self, identification_record(rec, record_kind(rec)), at)
            self.model_ = self.result_.model
            return self
        # a ring-down, read as NSI and SINDy read it (``record_kind``): a hammer's force windowed (each hit's offset
        # off, zero between its pulses), a free decay's input zero (a decay from the record's own initial state);
        # its blocks and restarted windows shortened as SINDy's (``sindy.ring_down_window``: a ring-down lasts
        # seconds), every window of the workflow alike for the fit's duration (the parameter is given back after)
        from negstiff.inference.estimators.sindy import ring_down_window

        self.record_kind_ = kind = record_kind(rec)
        self.window_s_ = ring_down_window(rec, self.validation_fraction, self.selection_fraction, self.window_s)
        # a hammer's record is not refined by output error unless asked (refine=True): the refinement's windows and
        # its held-out free run cross the pulses its samples do not resolve (``_after_pulses``): on the double well
        # with a stop it moved the stop's k from 3004 to 2956 N/m (the truth 3000) and was kept by 0.2 % of a
        # held-out error the tail's hit decided (measured)
        unrefined = kind.kind == "impact" and self.refine is None
        # nor given the non-parametric force (``unnamed``): fitted by output error and judged on windows that cross
        # the pulses, it closed the gap the pulses make (4.4 -> 1.2 % on the double well with its stop found, whose
        # own gap was 0.38 %: measured)
        no_hybrid = kind.kind == "impact" and self.unnamed
        # what this fit runs with, kept apart from the parameters (which the fit leaves as given: it swapped them while
        # it ran, so a method called after it on a ring-down read the record raw, in the parameter's windows)
        self._refine_run = False if unrefined else self.refine
        self._unnamed_run = self.unnamed and not no_hybrid
        self._fit_one(identification_record(rec, kind))
        if unrefined:
            self.refinement_ = {"applied": False, "reason": "not run on a hammer's record (refine=True runs it): its "
                                "windows and held-out free run would cross the pulses, which a few samples do not "
                                "resolve"}  # fmt: skip
        if no_hybrid:
            why = ("not fitted on a hammer's record: the non-parametric force is fitted and judged by output error on "
                   "windows that would cross the pulses")  # fmt: skip
            self.unnamed_: dict[str, Any] | None = {"reason": why}
        self.result_ = self._workflow_result()
        return self

    def _fit_one(self, rec: Measurement) -> Discrepancy:
        """The workflow on a single DOF's record as it is read (``fit``: a ring-down's input windowed)."""
        self._systems(rec)
        terms, law = self._baseline(rec)
        stop: float | None = None
        added: list[dict[str, Any]] = []
        self.iterations_ = []
        self._folds_evidence: dict[str, dict[str, Any]] = {}
        try:
            base_model = self._refit_model(rec, terms, stop, (), law)
        except ValueError as exc:  # a law's parts refuse their fitted values (a rod frame's spring k_f below 0)
            raise DiscrepancyError(f"{rec.source}: the baseline law ({law}) does not fit this record: "
                                   f"{' '.join(str(exc).split())}") from None  # fmt: skip
        self.baseline_model_ = base_model
        self.baseline_refinement_ = None
        if self._refine_run is not False:  # the gap a user sees: the best the baseline form predicts, not its weak fit
            val = validate(base_model, rec, self.n_id_)
            base_model, _, self.baseline_refinement_ = refine_stage(base_model, rec, self.n_id_, val, held=_held(terms))
        self.gap_before_ = self._gap(rec, base_model)
        # the regime's and the interval's windows last no longer than the record stays predictable: measured once,
        # from the record and the baseline, before any effect is scored, the same for the baseline and every effect
        self.predictability_ = self._predictability(rec, base_model)
        self.locate_before_ = self.locate(rec, terms, stop, (), law)
        current = {"model": base_model, "initial": self.baseline_model_, "refinement": self.baseline_refinement_,
                   "gap": self.gap_before_}  # fmt: skip
        aux: tuple[str, ...] = ()
        offer = law is not None if self.offer_laws is None else self.offer_laws
        self.laws_offered_ = [n for n in laws.names("restoring") if n != law] if offer else []
        for _ in range(self.max_effects):
            none = self._score(rec, Candidate("none", terms, stop, aux, law))
            cands = [none]
            for effect, extra_terms in catalogue().items():
                if not extra_terms:  # the positional effect: one at most
                    if stop is None:
                        cands.append(self._score(rec, Candidate(effect, terms, self._fit_stop(rec, terms, aux, law=law),
                                                                aux, law)))  # fmt: skip
                    continue
                if set(extra_terms) <= set(terms):
                    continue
                cands.append(self._score(rec, Candidate(effect, terms + extra_terms, stop, aux, law)))
            for channel in rec.aux:  # each measured auxiliary channel: a term theta a(t), like an effect
                if channel not in aux:
                    cands.append(self._score(rec, Candidate(aux_terms([channel])[0], terms, stop, (*aux, channel),
                                                            law)))  # fmt: skip
            for name in self.laws_offered_:  # each other restoring law, in place of the restoring force
                if name != law:
                    cands.append(self._law_candidate(rec, name, terms, stop, aux, law))
            ranking = sorted(cands, key=lambda c: c.heldout_percent)
            best = self._parsimonious(ranking, terms, law)
            # a measured channel's term (aux:NAME) is no guess from a catalogue: no practical margin (the lab's
            # consistency floor a catalogue's term can buy back), twice the standard error instead of once; and it
            # is weighed first: a channel that passes its own rule is named before any guessed effect or law (a law
            # in place of the cubic bought a weak coupling's record 30 % of its weak residual, then predicted no
            # better and ended the round with the coupling unnamed: measured)
            passing = [c for c in ranking if c.effect.startswith(effects.AUX_PREFIX)
                       and _passes_measured(compare(_scores(none), _scores(c), 0.0, _scores(none)))]  # fmt: skip
            first_channel = passing[0] if passing else None
            best = first_channel or best
            measured = best.effect.startswith(effects.AUX_PREFIX)
            gain = compare(_scores(none), _scores(best), 0.0 if measured else self.margin, _scores(none))
            named = best.effect != "none" and (_passes_measured(gain) if measured else gain.significant)
            iteration = {
                "ranking": [
                    {
                        "effect": c.effect,
                        **c.notes,  # an inf (a run that diverged) is JSON's None, as written
                        "score": c.heldout_percent if math.isfinite(c.heldout_percent) else None,
                        **self._size_of(rec, c),
                    }
                    for c in ranking
                ],  # fmt: skip
                "named": best.effect if named else "none",
                "gain_percent": float(100 * gain.gain / _scores(none).mean()),
                "standard_error_percent": float(100 * gain.se / _scores(none).mean()),
            }
            self.iterations_.append(iteration)
            if not named:
                iteration["first"] = self._first(ranking, best, None, terms, law, gain)
                break
            trial = self._trial(rec, best)
            iteration["kept"], iteration["verdict"], iteration["evidence"] = self._helps(
                rec,
                current["gap"],
                trial["gap"],
                best.effect,
                current["model"],
                trial["model"],
                Candidate("before", terms, stop, aux, law),
                best,
            )
            iteration["gap_percent"] = {"before": current["gap"].get("median_window_percent"),
                                        "after": trial["gap"].get("median_window_percent")}  # fmt: skip
            iteration["first"] = self._first(ranking, best, iteration, terms, law, gain)
            if not iteration["kept"]:
                iteration["named"] = "none"
                break
            current = trial
            terms, aux, law = best.terms, best.aux, best.law
            stop = _stop_of(trial["model"], best.stop)  # the next effects are sought beside the refined stop
            added.append({"effect": best.effect, "stop": stop})
        self.effects_ = [a["effect"] for a in added]
        self.terms_ = terms
        self.law_ = law
        self.stop_ = stop
        self.model_, self.initial_model_, self.refinement_ = current["model"], current["initial"], current["refinement"]
        self.gap_after_ = current["gap"]  # the same measure as the gap before: restarted runs, same windows
        self.aux_ = aux
        # each named effect's regime: the held-out windows where it acts, the baseline against the final model
        self.gap_regime_ = {}
        for e in self.effects_:
            reg = self._regime(rec, self.gap_before_, self.gap_after_, e, base_model, self.model_)
            judged = "held-out tail"
            if reg.get("windows", 0) < 3 and self._folds_evidence.get(e, {}).get("acting") is not None:
                # the tail barely reaches it: the cross-validated windows' gap (fits that never saw them)
                reg, judged = self._folds_evidence[e], "cross-validated blocks of the record"
            self.gap_regime_[e] = {"before": reg.get("gap_before_percent"), "after": reg.get("gap_after_percent"),
                                   "windows": reg.get("windows", 0), "window_s": reg.get("window_s"),
                                   "record_window_s": reg.get("record_window_s"), "judged_on": judged}  # fmt: skip
        self.locate_after_ = self.locate(rec, terms, stop, aux, law)
        self.effect_interval_ = self._effect_interval(rec)
        self.bounded_ = boundedness(self.model_, rec.segment(0, self.n_id_))
        self.unnamed_ = self._unnamed(rec) if self._unnamed_run else None
        lines = classified(rec, self.model_, [] if self.bounded_["ok"] else [self.bounded_["warning"]])
        issue(lines)
        self.warnings_ = [text for _, text in lines]
        self.record_ = dict(rec.info)
        return self

    def _trial(self, rec: Measurement, best: Candidate) -> dict[str, Any]:
        """The model with ``best`` added: every parameter refitted on the identification part by weak least
        squares, then (``refine``) by output error, every effect's own values included (an end stop's
        stiffness and onset: ``refine.parameter_names``); its held-out gap.
        """
        initial = self._refit_model(rec, best.terms, best.stop, best.aux, best.law)
        model, refinement = initial, None
        if self._refine_run is not False:
            val = validate(initial, rec, self.n_id_)
            model, _, refinement = refine_stage(initial, rec, self.n_id_, val, held=_held(best.terms))
        return {"model": model, "initial": initial, "refinement": refinement, "gap": self._gap(rec, model)}

    def _unnamed(self, rec: Measurement) -> dict[str, Any]:
        """What no catalogue effect names: a non-parametric force g(z, z', u) fitted by output error on the
        identification part with the final model held (``hybrid.fit_hybrid``), its size, the held-out gap
        with and without it (the same restarted windows), and how far the joint refit moved each physical
        coefficient in its standard errors.
        """
        from negstiff.inference.estimators.hybrid import fit_hybrid

        ident = rec.segment(0, self.n_id_)
        h = fit_hybrid(self.model_, ident)
        zs, vs, _, _ = ident.states("state")
        term = h.term(zs, vs, ident.driving(self.model_))
        force = self.model_.restoring_force(zs)
        return {
            "term_rms": float(np.sqrt(np.mean(term**2))),
            "term_percent_of_restoring_force": float(100 * np.sqrt(np.mean(term**2) / np.mean(force**2))),
            "gap": h.restarted_gap(rec, self.n_id_, self.window_s_, self._z0, self._v0),
            **h.to_json(),
        }

    @override
    def result(self) -> dict[str, Any]:
        """The contract's discrepancy JSON (``result_.to_json()``: a structure's layout on a structure's record)."""
        return self.result_.to_json()

    def _workflow_result(self) -> Identification:
        """The workflow's result on the device on its base: its final model as a structure of one DOF, its held-out
        gap as the validation (``workflow_validation``), its own account (what it named, the rankings, the gaps, the
        sizes) in ``details``; ``to_json()`` writes the contract's discrepancy JSON.
        """
        account = self._account()
        return Identification(
            method="discrepancy", system=Structure.single(self.model_),
            initial_system=Structure.single(self.initial_model_), linear_part="none", modal={},
            validation=workflow_validation(account), refinement=_plain(self.refinement_),
            bounded=Bunch(self.bounded_), warnings=tuple(self.warnings_),
            record=dict(self.record_), details=account, settings=self._settings(),
            identification_samples=self.n_id_,
        )  # fmt: skip

    def _account(self) -> dict[str, Any]:
        """The workflow's own keys of its JSON (``_workflow_result``' details), in the contract's order."""
        last = self.iterations_[0] if self.iterations_ else {"ranking": []}  # max_effects = 0: the baseline only
        before = self.gap_before_.get("median_window_percent", math.inf)
        after = self.gap_after_.get("median_window_percent", math.inf)
        return {
            "effect": self.effects_[0] if self.effects_ else "none",
            "effects": self.effects_ or ["none"],
            "ranking": last["ranking"],
            "gap_before_percent": before,
            "gap_after_percent": after,
            "gap_pooled_percent": {
                "before": self.gap_before_.get("restarted_rms_percent"),
                "after": self.gap_after_.get("restarted_rms_percent"),
            },
            "gap_median_window_um": {
                "before": self.gap_before_.get("median_window_rms_um"),
                "after": self.gap_after_.get("median_window_rms_um"),
            },
            "where": self.where_text(),
            "gap_regime_percent": self.gap_regime_,
            "predictability": dict(self.predictability_),
            "regimes_before": self.locate_before_["regimes"],
            "regimes_after": self.locate_after_["regimes"],
            "baseline_model": self.baseline_model_.to_dict(),
            "baseline_law": self.baseline_law_,
            "laws_offered": list(self.laws_offered_),
            "law": self.law_,
            "effect_size": self.effect_size(),
            "effect_interval": self.effect_interval_,
            "bayesian": self.bayesian_,
            "aux_per_unit_mass": {
                e: v / self.model_.m for e, v in self.model_.extra.items() if e.startswith(effects.AUX_PREFIX)
            },  # fmt: skip
            **({"unnamed": self.unnamed_} if getattr(self, "unnamed_", None) else {}),
            "iterations": self.iterations_,
            "record_kind": {
                "kind": self.record_kind_.kind,
                "how": self.record_kind_.how,
                "read": _READ[self.record_kind_.kind],
            },  # fmt: skip
        }

    def _settings(self) -> dict[str, Any]:
        """The workflow's settings as its JSON writes them."""
        return {
            "identification_samples": self.n_id_,
            "window_s": self.window_s_,  # ``window_s``, shortened on a ring-down (``sindy.ring_down_window``)
            "baseline_terms": list(self.baseline),
            "score": "held-out weak residual (rms, % of the target) over samples "
            f"[{self.n_fit_}, {self.n_id_}); named only above max(1 SE, {100 * self.margin:g} %)",
            "gap": f"restarted {self.window_s_:g} s free runs over the held-out tail [{self.n_id_}, end): "
            "the median window's rms error, % of rms(z) (pooled over all windows in gap_pooled_percent; one "
            "window that diverges near the barrier, chaos, can dominate the pool)",
        }
