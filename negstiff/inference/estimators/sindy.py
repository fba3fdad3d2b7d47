"""Equation discovery with SINDy (Brunton, Proctor & Kutz 2016; pysindy 2.1): the restoring force, the
damping and any extra term of the second-order equation of motion, from z and the input only, over
the library of ``weak`` (z'' = theta . Theta(z, z', u), each term a model-file field or a named
``extra`` effect). The input's coefficient is fixed by
physics with an equality constraint (pysindy's ``ConstrainedSR3`` on the sparsity path and in the
ensemble; constrained least squares where a support is refitted): -1 for base acceleration, 1/m for a
force with a known mass; only a force record without a mass learns it (then m = 1/coefficient, as NSI
does from its FRF level).

The weak (integral) form, its library and the regression live in ``weak``; this module is the
workflow: the sparsity path, the selection (``selection``), the ensemble and the final validation.

Sparsity: a path of L0 weights gives a set of candidate supports, each refitted (least squares on
its support, the input's coefficient fixed) on the first part of the identification data and scored
on the following part by its held-out weak residual, in blocks of ``window_s`` seconds: a
cross-validated equation error (``_select`` picks the sparsest support within one standard error, or
a practical margin, of the best). The path also reports each support's free runs restarted from the
measured state over the held-out part, but does not select by them: over cross-well motion they
amplify a 2 % error in the weakly determined k2 (chaos, device-model.md) enough to reward any term
that trims it. The selected support is refitted on all identification data. Ensemble SINDy
(bagging, ``EnsembleOptimizer``) at the selected weight gives each term's inclusion probability and
coefficient spread. The last ``validation_fraction`` of the record is never seen until the final
free-run validation, which is the same as NSI's (contract keys match key for key).
"""

from __future__ import annotations

import math
import re
import warnings
from typing import Any

import numpy as np

from negstiff.errors import InputError
from negstiff.inference.analysis.record_kind import (
    RING_DOWN_KINDS,
    check_decay,
    identification_record,
    record_kind,
    ring_down,
)
from negstiff.inference.estimators.base import ElementPlace, element_of
from negstiff.inference.estimators.identification import (
    WINDOW_S,
    Estimate,
    Identifier,
    check_ring_down_scores,
    structure_result,
)
from negstiff.inference.estimators.parameters import (
    DAMPING_LAW,
    FRACTION,
    RANDOM_STATE,
    RESTORING_LAW,
    Boolean,
    Interval,
    Several,
    seed_of,
)
from negstiff.inference.estimators.results import Identification, StructureResults
from negstiff.inference.record.measurement import Measurement, per_unit_mass_warning
from negstiff.inference.steps.equations import (
    StructureIdentificationError,
    _assemble,
    _block_scores,
    _lstsq,
    _systems,
    physical_frame,
    unknown_zeros,
)
from negstiff.inference.steps.selection import block_rows, block_scores, choose
from negstiff.inference.steps.shape import fit_shape
from negstiff.inference.steps.validation import boundedness, restarted_free_runs
from negstiff.inference.steps.validation import restarted_structure_runs as free_run_error
from negstiff.inference.steps.weak import (
    BASE_FIELDS,
    Bagging,
    Library,
    WeakForm,
    WeakFormError,
    fit_support,
    is_ring_down,
    known_input_gain,
    mass_of,
    terms,
    test_function_half_width,
)
from negstiff.models import effects, laws

MIN_SAMPLES = 4000


DEFAULT_WEIGHTS = tuple(float(w) for w in np.logspace(-9, -1, 33))
"""The sparsity path's L0 weights by default (33, log-spaced from 1e-9 to 0.1)."""


class SINDyError(WeakFormError):
    """The record cannot be identified by SINDy (too short, no excitation, nothing selected)."""


def _selection_rows(rec: Measurement, validation_fraction: float,
                    selection_fraction: float) -> tuple[int, int, int, int]:  # fmt: skip
    """(n_id, n_fit, the test function's half-width h, the rows' stride) of a weak-form fit that scores on the
    selection part [n_fit, n_id): h from the identification part's spectrum (the fit's own, kept with the
    record's segment), one row every max(1, h // 2) samples.
    """
    n_id = int(round(rec.n * (1 - validation_fraction)))
    n_fit = int(round(rec.n * (1 - validation_fraction - selection_fraction)))
    ident = rec.segment(0, n_id)
    half, _ = test_function_half_width(ident.displacement, ident.fs, floor=ident.noise_floor(),
                                       ring_down=is_ring_down(ident))  # fmt: skip
    return n_id, n_fit, half, max(1, half // 2)


def selection_blocks(rec: Measurement, validation_fraction: float, selection_fraction: float,
                     window_s: float) -> tuple[int, float]:  # fmt: skip
    """How many ``window_s`` blocks of weak-form rows the selection part of a single DOF's record holds, and
    about how long a record [s] would give two: the check a weak-form fit (SINDy, the discrepancy workflow)
    makes before any work. The rows are counted as ``WeakForm.system`` makes them: the test function's
    half-width h from the identification part's spectrum (the fit's own, kept with the record's segment), the
    kernel 8 h + 1 samples long, one row every max(1, h // 2) samples of the selection part [n_fit, n_id).
    """
    n_id, n_fit, half, stride = _selection_rows(rec, validation_fraction, selection_fraction)
    rows = block_rows(window_s, rec.fs, stride)
    valid = n_id - n_fit - 8 * half  # the samples where a whole test function fits
    n_rows = 0 if valid <= 0 else -(-valid // stride)
    need = (8 * half + (2 * rows - 1) * stride + 1) / max(selection_fraction, 1e-12)  # samples of the record
    return n_rows // rows, float(need / rec.fs)


def ring_down_window(rec: Measurement, validation_fraction: float, selection_fraction: float,
                     window_s: float) -> float:  # fmt: skip
    """The scoring blocks' and restarted free runs' length [s] of a weak-form fit that scores on the selection
    part [n_fit, n_id) (SINDy, the discrepancy workflow): ``window_s``; on a hammer's or a free decay's record
    (``record_kind``: a ring-down lasts seconds, the lab's records 10 s) shortened to what gives the selection
    part two blocks, but never so short that the selection part holds fewer weak-form rows than the system needs
    (four a column).
    """
    kind = record_kind(rec)
    if kind.kind not in RING_DOWN_KINDS:
        return float(window_s)
    rec = identification_record(rec, kind)  # as the fit reads it (the same weak form's test functions)
    n_id, n_fit, half, stride = _selection_rows(rec, validation_fraction, selection_fraction)
    rows = max(0, -(-(n_id - n_fit - 8 * half) // stride))  # the selection part's weak-form rows
    fits = (rows // 2) * stride / rec.fs  # two blocks of them
    floor = 2 * (len(terms()) + 1) * stride / rec.fs  # WeakForm.system's four rows a column over two blocks
    return float(min(window_s, max(fits, floor)))


class SINDy(StructureResults, Identifier):
    """Weak-form SINDy: which terms of the equation of motion the record asks for, and their sizes, for a single
    DOF or a structure of N DOFs carrying the element between DOFs I-J (``element``; ``identify_sindy``: one
    equation per DOF, the element's terms shared by the DOFs it joins, the same selection rule and ensemble).

    The library holds polynomial stiffness, viscous and quadratic damping, the extra effects and a
    record's measured auxiliary channels (``aux:NAME``); the input's coefficient is fixed by physics
    (``docs/methods/sindy.md``). The selected model is validated on the held-out tail and refined by
    output error.

    Parameters
    ----------
    weights : tuple of float, default 33 weights from 1e-9 to 0.1
        L0 weights of the sparsity path (dimensionless; SR3 threshold sqrt(2 weight)).
    n_models : int, default 50
        Ensemble size (bagging) for the inclusion probabilities.
    subset_fraction : float, default 0.6
        Bag size, a fraction of the test functions.
    validation_fraction : float, default 0.2
        Held-out tail for the final validation (the contract's 0.2).
    selection_fraction : float, default 0.2
        Part of the record (before the tail) that scores the candidate supports.
    window_s : float, default 2
        Length of the restarted free runs and of the residual blocks that score a support [s].
    margin : float, default 0.1
        Relative gain in held-out residual a larger support must bring.
    seed : int, None or numpy.random.Generator, default 0
        Seeds the ensemble's bagging (same seed, same ensemble); None: fresh entropy; a Generator: its next draw
        (scikit-learn's ``random_state``). The integer used is ``seed_`` and the result's ``settings["seed"]``.
    refine : bool or None, default None
        Finish by output-error refinement (kept only if it predicts the held-out tail no worse; a structure's over
        every channel, its channels' zeros with it: ``structure_result``). None: run it.
    element : str or (int, int), optional
        Where the element acts on a record of N > 1 DOFs: ``"I-J"``, it moves DOF J relative to DOF I (0: the
        base). None: the single DOF. Its result is an ``Identification`` for any N.

    law : str or None, default None
        The restoring-force law (``models.laws``: ``"cubic"``, ``"quintic"``, ``"septic"``, ``"magnet"``,
        ``"oblique_springs"``, ``"geometric"``, ``"spline"``) whose columns the method reads, a shaped part's shape
        found on the record (``shape.fit_shape``); ``"auto"``: every law estimated and the one that predicts the
        record best kept (``law_choice``); None: the method's own default (the registry's sparse catalogue), the
        other laws compared where it fails its checks, and said.
    damping : str, default "quadratic"
        The damping law read with ``law`` (``"viscous"``, ``"quadratic"``, ``"cubic_damping"``, ``"friction"``).

    Attributes
    ----------
    result_ : Identification
        Everything ``fit`` learned; ``result()`` is the contract's JSON.
    model_ : Model
        The final model, extra terms in ``model_.extra``.
    selected_ : list of str
        The selected library terms (``"z^3"``, ``"v|v|"``, ``"sgn(v)"``, ...).
    ensemble_ : dict
        Each term's inclusion probability, median and spread over the ensemble.
    path_ : list of dict
        The sparsity path: each candidate support and its held-out score.
    validation_ : Bunch
        The free run over the held-out tail.
    warnings_ : list of str
        Every warning (also issued as ``NegstiffWarning``).
    seed_ : int
        The integer seed the fit used (``seed``, or drawn from None or a Generator).

    Examples
    --------
    >>> from negstiff import Measurement, Rig, SINDy
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rig = Rig(SEED_LIKE_CUBIC, effects={"coulomb_friction": 0.1}, seed=3)
    >>> sindy = SINDy(seed=1).fit(Measurement.from_rig(rig.random(duration=60.0, rms=20.0)))
    >>> "sgn(v)" in sindy.selected_                                # the hidden friction, found
    True
    >>> abs(sindy.model_.extra["coulomb_friction"] - 0.1) < 0.01
    True
    """

    method = "sindy"
    _parameter_constraints = {
        "weights": Several(Interval(float, 0.0, lo_open=True)),
        "n_models": Interval(int, 2, 10000),
        "subset_fraction": Interval(float, 0.0, 1.0, lo_open=True),
        "validation_fraction": FRACTION,
        "selection_fraction": FRACTION,
        "window_s": Interval(float, 0.0, lo_open=True, unit="s"),
        "margin": Interval(float, 0.0),
        "seed": RANDOM_STATE,
        "refine": Boolean(none=True),
        "element": ElementPlace(),
        "law": RESTORING_LAW,
        "damping": DAMPING_LAW,
    }

    def __init__(
        self,
        *,
        weights=DEFAULT_WEIGHTS,
        n_models: int = 50,
        subset_fraction: float = 0.6,
        validation_fraction: float = 0.2,
        selection_fraction: float = 0.2,
        window_s: float = 2.0,
        margin: float = 0.1,
        seed: int | np.random.Generator | None = 0,
        refine: bool | None = None,
        element: str | tuple[int, int] | None = None,
        law: str | None = None,
        damping: str = laws.DEFAULT_DAMPING,
    ):
        self.element = element
        self.refine = refine
        self.law = law
        self.damping = damping
        self.weights = weights
        self.n_models = n_models
        self.subset_fraction = subset_fraction
        self.validation_fraction = validation_fraction
        self.selection_fraction = selection_fraction
        self.window_s = window_s
        self.margin = margin
        self.seed = seed

    # --- the workflow ----------------------------------------------------------------------------
    def _validate(self) -> None:
        if self.validation_fraction + self.selection_fraction >= 1:
            raise SINDyError(
                f"SINDy(validation_fraction={self.validation_fraction}, selection_fraction={self.selection_fraction}): "
                "together they leave nothing to fit"
            )

    @staticmethod
    def _aux(rec: Measurement) -> tuple[str, ...]:
        """The record's measured auxiliary channels (``--aux``): each offered to the library as a term theta
        a(t) (``aux:NAME``), thresholded like the others.
        """
        return tuple(rec.aux)

    def _restore(self, result: dict[str, Any]) -> None:
        """The result JSON's own state (``from_json``), with the terms selected and the ensemble's statistics."""
        super()._restore(result)
        held = result.get("details", {}) if "structure" in result else result  # a structure's keeps them apart
        if "selected_terms" in held:
            self.selected_ = list(held["selected_terms"])
        if "ensemble" in held:
            self.ensemble_ = held["ensemble"]

    def fit(self, data) -> SINDy:
        """Identify from ``data`` (a ``Measurement`` or a file path): a single DOF's record through the shared
        stages (``Identifier.fit``), a structure's (N > 1 DOFs) through ``identify_sindy`` (below).
        """
        rec = self.check(data)
        self.seed_ = seed_of(self.seed)  # None or a Generator: the integer drawn here, recorded in the settings
        at = element_of(self, rec)
        # a hammer's force windowed, a free decay's input zero: the weak form without an input term
        self.record_kind_ = kind = record_kind(rec)
        if at is None:
            return super().fit(identification_record(rec, kind))
        if self.law is not None:
            raise InputError(
                f"{type(self).__name__}(law={self.law!r}): a law is read on a single DOF's record; a "
                "structure's element has its own basis (element=): give no law"
            )
        self.result_ = identify_sindy(self, identification_record(rec, kind), at)
        self.selected_ = list(self.result_.details["selected_terms"])
        self.ensemble_ = self.result_.details["ensemble"]
        return self

    def _check_record(self, rec: Measurement) -> None:
        at = element_of(self, rec)
        rec.require(MIN_SAMPLES, "SINDy")
        if record_kind(rec).kind != "decay":
            rec.require_excitation("SINDy")
        else:
            check_decay(rec, "SINDy")
        rec.require_motion("SINDy")
        rec.require_live_aux("SINDy")
        self._check_response(rec)
        if at is None:
            self.check_length(rec)
        else:
            check_ring_down_scores(self, rec)

    def check_length(self, rec: Measurement) -> None:
        """Refuse a single DOF's record too short for the selection's scoring blocks (two ``window_s`` blocks
        of the selection part at least) with one ``SINDyError``: a cheap check (the record's spectrum, no fit),
        made by ``check`` so a caller refuses before printing any progress. A structure's record is checked by
        its fit (its blocks follow the element's smoothed states).
        """
        window = self.scoring_window(rec)
        kind = record_kind(rec)
        # counted on the record as the fit reads it (a decay named so whose force channel holds noise, a hammer's
        # force windowed), as the discrepancy workflow's check counts it
        read = identification_record(rec, kind) if kind.kind in RING_DOWN_KINDS else rec
        blocks, need_s = selection_blocks(read, self.validation_fraction, self.selection_fraction, window)
        if blocks < 2:
            if kind.kind in RING_DOWN_KINDS:  # a longer record of the same ring-down would not help
                raise SINDyError(
                    f"{rec.source}: SINDy cannot score its candidate models on this ring-down: the part that scores "
                    f"them ({100 * self.selection_fraction:.0f} % of the record, before the held-out tail) holds "
                    f"under two blocks of {window:.3g} s of test functions; a response decayed into its noise there "
                    "widens them (cut the record where it meets the noise, or hit again before it does)"
                )
            raise SINDyError(
                f"{rec.source}: too short for SINDy: {rec.duration:.3g} s, at least about {need_s:.3g} s are "
                f"needed ({100 * self.selection_fraction:.0f} % of the record scores the candidate models in "
                f"{window:.3g} s blocks, two at least)"
            )

    def scoring_window(self, rec: Measurement) -> float:
        """The scoring blocks' and restarted free runs' length [s]: ``window_s``, shortened on a ring-down
        (``ring_down_window``).
        """
        return ring_down_window(rec, self.validation_fraction, self.selection_fraction, self.window_s)

    def _kernels_ahead(self) -> tuple[str, ...]:
        """With the catalogue: the polynomial's kernel, compiled in a helper while the fit compiles the smoothed
        sign's its sgn(v) candidates run first (2-3 s each on a fresh install: side by side, not one after the
        other).
        """
        return ("polynomial",) if self.law is None else ()

    def _estimate(self, rec: Measurement, n_id: int, law: laws.Law | None = None) -> Estimate:
        """SINDy's own estimate: the support selected on held-out residuals, refitted on the
        identification part, with the ensemble's inclusion probabilities (the shared stages follow); its library
        the registry's catalogue, or ``law``'s columns and the damping law's (``Library``).
        """
        n_fit = int(round(rec.n * (1 - self.validation_fraction - self.selection_fraction)))
        ident = rec.segment(0, n_id)
        form = WeakForm.of(ident)
        z0s, v0s, _, _ = ident.states("state")  # where free runs start
        gain = known_input_gain(rec)

        # 1. the sparsity path on the fitting part; 2. each support refitted there and scored by
        # its held-out weak residual over the selection part, in blocks
        lib = self._library(rec, n_fit, n_id, law)
        path = self._path(rec, form, gain, n_fit, n_id, z0s, v0s, lib)
        library = lib.labels()
        fields = lib.fields()
        self.path_ = sorted(path, key=lambda p: (p["n_terms"], p["heldout_residual_percent"]))
        chosen = self._select(self.path_)
        if not np.isfinite(chosen["free_run_percent"]):
            dissipative = {"c", "c_nl", *(e.name for e in effects.REGISTRY if e.dissipative)}
            lossless = not any(fields[t][0] in dissipative for t in chosen["terms"])
            raise SINDyError(
                f"{rec.source}: the selected model ({', '.join(chosen['terms'])}) diverged in the restarted free runs"
                + (
                    "; no damping term was selected, though a device under an input dissipates (is z in one frame "
                    "throughout, without a drift?)"
                    if lossless
                    else ""
                )  # fmt: skip
            )

        # 3. refit the chosen support on all identification data; the ensemble at the same weight
        sys_id = form.system(ident, library=lib)
        phys = fit_support(sys_id, gain, support=chosen["support"])
        bagging = Bagging(self.n_models, self.subset_fraction, self.seed_)
        phys_ens = fit_support(sys_id, gain, chosen["weight"], bagging=bagging)
        mass, mass_source = mass_of(rec, gain, phys[-1])
        model = lib.model(phys, mass)
        self.selected_ = list(chosen["terms"])
        self.weight_ = chosen["weight"]
        self.ensemble_ = {
            term: {
                "inclusion_probability": float(np.mean(phys_ens[:, i] != 0)),
                "median": float(fields[term][1] * mass * np.median(phys_ens[:, i])),
                "sd": float(mass * np.std(phys_ens[:, i])),
                "field": fields[term][0],
            }
            for i, term in enumerate(library)
        }
        # the selection stands in the refinement: unselected terms stay zero, the selected ones are refined; but a
        # law's own fields are all refined (the law's parameters: docs/methods/laws.md), an unselected one from zero:
        # a ring-down's weak form barely sees a damping law's small terms, its free run's envelope does (FrID's
        # decay: c_nl and c3 unselected, c 3x the output-error fit's)
        own = set() if law is None else set(law.fields) | set(laws.get(self.damping, "damping").fields)
        unselected = [fields[t][0] for t in library if t not in self.selected_]
        held = tuple(f for f in unselected if f in BASE_FIELDS and f not in own)
        return Estimate(
            model=model,
            mass_source=mass_source,
            input_gain=float(phys[-1]),
            held=held,
            warnings=tuple(filter(None, [per_unit_mass_warning(rec)])),
            details={
                "selected_terms": self.selected_,
                "ensemble": self.ensemble_,
                "path": [{k: v for k, v in p.items() if k not in ("block_ms", "support")} for p in self.path_],
                **(
                    {}
                    if vars(self).get("record_kind_") is None
                    else {"record_kind": {"kind": self.record_kind_.kind, "how": self.record_kind_.how}}
                ),
            },
            settings={
                "form": f"weak: test functions (1 - (s/T)^2)^4, T = {form.half} samples, every {form.stride}",
                "corner_frequency_hz": form.corner_hz,
                "derivatives": form.derivatives["method"],
                "sgn_noise_scale": form.velocity_noise,
                "library": list(library) + ["u"],
                "law": lib.restoring.name if lib.restoring else "catalogue",
                "damping_law": lib.damping.name if lib.damping else "catalogue",
                **({"shape": self.shape_.to_json()} if lib.by_law else {}),
                "input_coefficient": (
                    "fixed by physics (an equality constraint: pysindy's ConstrainedSR3 on the sparsity path and "
                    "the ensemble, constrained least squares in the support's refit)"
                    if gain is not None
                    else "learned (no mass)"
                ),
                "selection": "sparsest support whose held-out weak residual (samples "
                f"[{n_fit}, {n_id}), blocks of {self.scoring_window(rec):.3g} s) is within max(one standard error, "
                f"{100 * self.margin:g} %) of the best",
                "weight": self.weight_,
                "n_models": self.n_models,
                "subset_fraction": self.subset_fraction,
                "seed": self.seed_,
            },
        )

    def _library(self, rec: Measurement, n_fit: int, n_id: int, law: laws.Law | None) -> Library:
        """The columns the path selects among: the registry's catalogue (``law`` None), or the laws' at the shape
        the record gives their shaped parts (``shape.fit_shape``), with the record's auxiliary channels.
        """
        aux = self._aux(rec)
        if law is None:
            return Library.catalogue(aux)
        fit = fit_shape(rec, law, self.damping, n_fit=n_fit, n_id=n_id, window_s=self.scoring_window(rec), aux=aux)
        self.shape_ = fit
        return Library.of_laws(law, self.damping, fit.shape, aux)

    def _path(self, rec: Measurement, form: WeakForm, gain, n_fit: int, n_id: int, z0s, v0s,
              lib: Library) -> list[dict]:  # fmt: skip
        """The supports of the L0 path on samples [0, n_fit), each refitted there and scored on [n_fit,
        n_id): its held-out weak residual in blocks, its restarted free runs, an escape past the stroke.
        """
        ident = rec.segment(0, n_id)
        sys_fit = form.system(rec, 0, n_fit, library=lib)
        sys_sel = form.system(rec, n_fit, n_id, library=lib, scoring=True)
        W_sel, y_sel = sys_sel.W_physical, sys_sel.y_physical
        window = self.scoring_window(rec)
        rows = block_rows(window, rec.fs, form.stride)
        n_blocks = y_sel.size // rows
        if n_blocks < 2:
            need = 2 * rows / max(1, y_sel.size) * rec.n
            raise SINDyError(
                f"{rec.source}: too short for SINDy: {rec.duration:.3g} s, at least about {need / rec.fs:.3g} s are "
                f"needed ({100 * self.selection_fraction:.0f} % of the record scores the candidate models in "
                f"{window:.3g} s blocks, two at least)"
            )
        library = lib.labels()
        # a ring-down (a decay, a hammer's record) dissipates by what it is: its viscous term is in every support.
        # The equation error cannot weigh it: c z' is 2 zeta of the inertia's size (3 % at 1.5 %), under the
        # selection's margin, so a double well's hammer record selected no damping at all (measured)
        dissipates = record_kind(rec).kind in RING_DOWN_KINDS
        supports: dict[tuple[bool, ...], list[float]] = {}
        for weight in self.weights:
            phys = fit_support(sys_fit, gain, weight)
            on = phys[: len(library)] != 0
            if dissipates:
                on[library.index("v")] = True
            supports.setdefault(tuple(bool(c) for c in on), []).append(weight)
        path = []
        for support, weights in supports.items():
            phys = fit_support(sys_fit, gain, support=support)
            try:
                model = lib.model(phys, mass_of(rec, gain, phys[-1])[0])
                fr = restarted_free_runs(model, ident, n_fit, window, z0s, v0s)
                # a support whose potential opens an escape just past the stroke is never selected
                escape = boundedness(model, ident, free_run=False)["escape_z"]
            except (WeakFormError, ValueError):
                fr, escape = {}, None
            ok = fr.get("restart_diverged", 1) == 0 and escape is None
            block_ms = block_scores((y_sel - W_sel @ phys) ** 2, rows, y_sel.var())
            path.append(
                {
                    "terms": [t for t, on in zip(library, support, strict=False) if on],
                    "n_terms": int(sum(support)),
                    "support": support,
                    # the geometric middle of the weights that give this support
                    "weight": float(np.sqrt(min(weights) * max(weights))),
                    "heldout_residual_percent": float(100 * np.sqrt(block_ms.mean())),
                    "free_run_percent": fr["restarted_rms_percent"] if ok else math.inf,
                    "escape_z": escape,
                    "block_ms": block_ms,
                }
            )
        return path

    def _select(self, path: list[dict]) -> dict:
        """The sparsest candidate whose held-out residual exceeds the best candidate's by less than
        ``max(one standard error of the paired per-block differences, margin x the best)``.

        The standard error is the statistical part (the one-standard-error rule); the margin the
        practical one (``selection``): on a lab record even the true model's weak residual is ~0.1 % of
        the target, and a term must explain more than that floor.

        Only admissible candidates compete: those whose restarted free runs stay bounded and whose
        potential opens no escape just past the stroke (``validation.boundedness``); a term that buys
        equation error at the price of an unbounded model is not selected.
        """
        chosen = choose(path, self.margin, lambda p: np.isfinite(p["free_run_percent"]))
        chosen["selected"] = True
        return chosen


# --- a structure's (N > 1 DOFs): its stacked weak form (``equations``) ----------------------------------------
def identify_sindy(est, rec: Measurement, at: tuple[int, int]) -> Identification:
    """SINDy on a record of N > 1 DOFs (module docstring): the single DOF's sparsity path, one-standard-error
    selection on held-out blocks and bagging ensemble, on the structure's stacked weak form.
    """
    import pysindy as ps

    from negstiff.inference.steps.weak import _seeded_global_rng

    fit, sel, whole, rows, window, form, (n_id, n_fit), _ = _systems(
        est, rec, at, ring_down(rec), ring_down(rec, ("decay",))
    )
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
    ident = rec.segment(0, n_id)
    hits = ring_down(rec, ("impact",))  # a hammer's record: its windows between the pulses
    for support, weights in supports.items():
        theta = _lstsq(Xf, yf, support)
        # admissible as a single DOF's support is (``selection.choose``): a usable element (equilibria in the
        # physical frame), its restarted windows over the selection part all bounded, no escape past the stroke
        try:
            s, b = _assemble(theta, rec.n_dof, at, masses)
            candidate, zeros = physical_frame(s, b, rec.gravity, unknown_zeros(rec))
            candidate.equilibria()
            runs = free_run_error(candidate, ident, n_fit, WINDOW_S, zeros, hits)
            escape = boundedness(candidate, ident, free_run=False, offsets=zeros)["escape_z"]
            usable, diverged = True, int(runs["diverged"])
        except (ValueError, InputError):
            usable, diverged, escape, runs = False, None, None, {}
        path.append({"support": support, "terms": [n for n, on in zip(names, support, strict=True) if on],
                     "n_terms": int(sum(support)), "weight": float(np.sqrt(min(weights) * max(weights))),
                     "block_ms": _block_scores(ys - Xs @ theta, ys, per_sel, rec.n_dof, rows),
                     "usable": usable, "restarted_diverged": diverged, "escape_z": escape,
                     "free_run_percent": runs.get("rms_percent")})  # fmt: skip
    if not path:
        raise StructureIdentificationError(f"{rec.source}: every weight removed every term")
    for p in path:
        p["heldout_residual_percent"] = float(100 * np.sqrt(p["block_ms"].mean()))
    path.sort(key=lambda p: (p["n_terms"], p["heldout_residual_percent"]))
    chosen = choose(path, est.margin, lambda p: p["usable"] and p["restarted_diverged"] == 0 and p["escape_z"] is None)
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
    return structure_result("sindy", rec, structure, offsets, n_id, None, [], {
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
