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
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, override

import numpy as np

from negstiff.errors import InputError, MeasurementError, NotFittedError, issue
from negstiff.inference.estimators.base import Estimator
from negstiff.inference.estimators.parameters import (
    FRACTION,
    RESTORING_LAW,
    Boolean,
    Constraint,
    Interval,
    LawName,
    Options,
    Several,
)
from negstiff.inference.estimators.structure_id import ElementPlace, StructureResults, element_of
from negstiff.inference.estimators.structure_id import discrepancy as structure_discrepancy
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps import law_choice
from negstiff.inference.steps.plausibility import classified
from negstiff.inference.steps.refine import parameter_names, parameter_scales, refine_stage, values_of, with_values
from negstiff.inference.steps.selection import block_rows, block_scores, compare, indistinguishable
from negstiff.inference.steps.shape import ShapeFit, fit_shape
from negstiff.inference.steps.validation import (
    RestartWindows,
    boundedness,
    parting_sample,
    predictability,
    restart_windows,
    restarted_free_runs,
    simulate_windows,
    validate,
)
from negstiff.inference.steps.weak import (
    BASE_FIELDS,
    Library,
    WeakForm,
    aux_terms,
    fit_support,
    known_input_gain,
    mass_of,
    model_from,
    term_fields,
    test_function,
)
from negstiff.inference.steps.weak import terms as library_terms
from negstiff.models import Model, effects, laws

CUBIC_BASELINE = ("1", "z", "z^2", "z^3", "v", "v|v|")
"""The seed's own model form: cubic K, viscous c and quadratic c_nl (the contract's damping law)."""
LINEAR_BASELINE = ("1", "z", "v")
MEASURED_SE = 2.0
"""A measured channel's term (``aux:NAME``) is named when its held-out weak residual falls by more than this many
standard errors (no practical margin: a channel of noise alone is named by chance in about 2 % of rounds)."""
LOCAL_DRAWS = 4
"""Draws of the start states' noise per window when the predictable span of the windows where an effect acts is
measured (``Discrepancy._episode_windows``)."""
LAW_PREFIX = "law:"
"""A candidate that replaces the restoring force by a law of ``models.laws`` (rather than adding a term to it) is
named ``law:NAME`` (``law:geometric``), beside the catalogue's effects and the measured channels' ``aux:NAME``."""
STOP_MIN_SAMPLES = 10
"""An end stop's onset is sought only where at least this many samples of the fitting part lie beyond it (a stop
sized from fewer would fit the noise of a few extreme samples)."""


def catalogue() -> dict[str, tuple[str, ...]]:
    """Candidate effects (the registry's, in its order) and the library terms each adds; an effect with a
    positional law (the one-sided stop) adds none: its column is made at a searched position.
    """
    return {e.name: (() if e.law.label is None else (e.law.label,)) for e in effects.REGISTRY if e.catalogued}


def _positional() -> effects.Effect | None:
    """The catalogue's effect with a positional law (at most one: the kernel has one stop row)."""
    return next((e for e in effects.REGISTRY if e.catalogued and e.law.label is None), None)


def law_of(name: str) -> str | None:
    """The law a candidate's name ``law:NAME`` offers, None for an effect's (or a channel's) name."""
    return name[len(LAW_PREFIX) :] if name.startswith(LAW_PREFIX) else None


def _stop() -> tuple[str, effects.OneSidedStop]:
    """The positional effect's name and law, where a candidate has a stop onset (so the registry has one)."""
    e = _positional()
    assert e is not None and isinstance(e.law, effects.OneSidedStop)
    return e.name, e.law


def share_text(share: float) -> str:
    """A share (0..1) in per cent with the digits it needs: two significant ones below 10 % (94, 2.3, 0.35,
    0.0041), never a small share rounded to "0".
    """
    pct = 100 * share
    if not pct > 0:
        return "0"
    digits = max(0, 1 - math.floor(math.log10(pct)))
    return f"{pct:.{digits}f}"


def _scores(c: Candidate) -> np.ndarray:
    """A scored candidate's per-block held-out scores."""
    assert c.block_ms is not None  # set by ``_score``
    return c.block_ms


@dataclass
class Candidate:
    """A catalogue entry: an effect, its library terms, and an end stop's onset when it has one; ``law`` the
    restoring law whose columns beyond the catalogue's the terms may name (None: the catalogue's alone).
    """

    effect: str
    terms: tuple[str, ...]
    stop: float | None = None
    aux: tuple[str, ...] = ()  # measured auxiliary channels whose terms the model carries (``aux:NAME``)
    law: str | None = None
    heldout_percent: float = math.inf
    block_ms: np.ndarray | None = None
    coefficients: np.ndarray | None = None
    notes: dict[str, Any] = field(default_factory=dict)


def _stop_of(model: Model, default: float | None) -> float | None:
    """The onset of the model's positional effect (refined by output error), else ``default``."""
    pos = _positional()
    value = model.extra.get(pos.name) if pos is not None else None
    return float(value["z"]) if value is not None else default


def _size_of(model: Model, effect: str) -> Any:
    """An effect's value in ``model`` (a base field's term read from its field), None where it is absent."""
    e = effects.get(effect)
    val = model.to_dict()[e.folds_into] if e.folds_into else model.extra.get(effect)
    return dict(val) if hasattr(val, "keys") else val


def _with_size(model: Model, effect: str, size: Any) -> Model:
    """``model`` with ``effect``'s value set to ``size`` (a base field's term in its field)."""
    e = effects.get(effect)
    fields = model.to_dict()
    if e.folds_into:
        return Model(**{**fields, e.folds_into: size})
    return Model(**{**fields, "extra": {**dict(model.extra), effect: size}})


def _admissible_sizes(model: Model, effect: str, keys: list, draw, theta: np.ndarray, cov: np.ndarray,
                      draws: int) -> list[Any]:  # fmt: skip
    """``draws`` sizes of ``effect`` drawn from the Gaussian N(``theta``, ``cov``) (``draw``: a Generator's
    ``multivariate_normal``) that its law admits, as ``_with_size`` takes them: a draw it refuses (a stop's k below
    0, where a wide interval reaches: a hammer's four contacts, measured) is drawn again, the Gaussian truncated to
    the admissible sizes. A law that refuses none draws as one call of ``draw`` would.
    """
    sizes: list[Any] = []
    for _ in range(100):
        for th in draw(theta, cov, size=draws, method="eigh"):
            size = {k: float(t) for k, t in zip(keys, th, strict=True)} if keys[0] is not None else float(th[0])
            try:
                _with_size(model, effect, size)
            except InputError:
                continue
            sizes.append(size)
            if len(sizes) == draws:
                return sizes
    return sizes


def _without(model: Model, effect: str) -> Model:
    """``model`` without ``effect`` (a base field's term set to zero), the rest held."""
    e = effects.get(effect)
    fields = model.to_dict()
    if e.folds_into:
        return Model(**{**fields, e.folds_into: 0.0})
    return Model(**{**fields, "extra": {k: v for k, v in dict(model.extra).items() if k != effect}})


def _passes_measured(gain) -> bool:
    """A measured channel's naming rule: its held-out weak residual falls by more than ``MEASURED_SE`` standard
    errors (``MEASURED_SE``).
    """
    return bool(gain.gain > MEASURED_SE * gain.se)


def _loo_compare(ms_with: np.ndarray, ms_without: np.ndarray, residual_rows, length: int,
                 rng: np.random.Generator) -> dict[str, Any]:  # fmt: skip
    """``arviz.compare`` (PSIS-LOO) of two models by windows: ``ms_*`` each window's mean-square run error per draw
    (draws, windows). Each window's log density is Gaussian with ``n_eff`` independent samples (``length`` over the
    errors' integrated autocorrelation time, from ``residual_rows``) and a noise variance drawn per draw from its
    scaled inverse chi-square posterior (so that each model's draws differ, as LOO needs).
    """
    import arviz as az

    # the integrated autocorrelation time (samples), summed to the first negative lag: a window of ``length``
    # correlated samples carries length / tau independent ones (numpy's correlate: arviz's autocorrelation works
    # on chains, not on these residual windows)
    taus = []
    for row in residual_rows:
        if not np.all(np.isfinite(row)) or not np.any(row):
            continue
        x = row - row.mean()
        ac = np.correlate(x, x, "full")[x.size - 1 :] / np.dot(x, x)
        neg = np.flatnonzero(ac < 0)
        taus.append(1 + 2 * np.sum(ac[1 : neg[0] if neg.size else ac.size]))
    tau = float(np.median(taus)) if taus else float(length)
    n_eff = max(1.0, length / max(tau, 1.0))
    draws, windows = ms_with.shape

    def loglik(ms: np.ndarray) -> np.ndarray:
        nu = n_eff * ms.shape[1]
        s2 = np.mean(ms, axis=1)  # each draw's pooled variance
        sig2 = nu * s2 / rng.chisquare(nu, size=s2.size)
        return -0.5 * n_eff * (np.log(2 * np.pi * sig2)[:, None] + ms / sig2[:, None])

    data = {name: az.from_dict({"posterior": {"draw_index": np.arange(draws, dtype=float)[None, :]},
                                "log_likelihood": {"windows": loglik(ms)[None]}})
            for name, ms in (("with", ms_with), ("without", ms_without))}  # fmt: skip
    # arviz's own warnings (PSIS's Pareto k over 0.7 for a window that dominates; the stacking weights' overflow
    # when the two models' densities lie far apart) said in the result, not printed to the user's terminal mid-run
    with warnings.catch_warnings(record=True) as said, np.errstate(all="ignore"):
        warnings.simplefilter("always")
        try:
            table = az.compare(data, round_to="none")
        except ValueError as err:  # arviz cannot score these windows
            return {"windows": int(windows), "error": str(err)}
    pareto = any("Pareto" in str(w.message) for w in said) or bool("warning" in table and np.any(table["warning"]))
    weight = float(table.loc["with", "weight"])
    diff = float(table.loc["with", "elpd"] - table.loc["without", "elpd"])
    dse = float(max(table.loc["with", "dse"], table.loc["without", "dse"]))
    return {
        "elpd_with": float(table.loc["with", "elpd"]),
        "elpd_without": float(table.loc["without", "elpd"]),
        "elpd_diff": diff,  # with minus without: > 0 favours naming it
        "dse": dse,
        "weight_with": weight if math.isfinite(weight) else None,  # the stacking weights overflow far apart
        "prefers": "with" if diff > 0 else "without",
        "beyond_two_se": bool(abs(diff) > 2 * dse),
        "windows": int(windows),
        "effective_samples_per_window": n_eff,
        "pareto_k_high": pareto,  # PSIS-LOO's own check: a window its importance sampling cannot stand in for
    }


def _displacement_labels() -> tuple[str, ...]:
    """The catalogue's terms of z alone (the restoring force's: 1, z, z^2, ...)."""
    return tuple(t.label for t in effects.library_terms() if t.law.displacement_only)


def _damping_of(velocity: tuple[str, ...]) -> str | None:
    """The damping law whose columns are the terms ``velocity`` (``("v", "v|v|")``: ``quadratic``), else None."""
    return next((n for n in laws.names("damping")
                 if tuple(c.label for c in laws.get(n).column_list()) == tuple(velocity)), None)  # fmt: skip


def law_parameters(model: Model, name: str) -> dict[str, float]:
    """The restoring law ``name``'s parameters in ``model``, flat: its base fields (``k0``, ``k1``, ...) and its
    parts' (a scalar part by its name, a shaped part's ``PART.FIELD``: ``rod_frame.L``, ``spline.c3``).
    """
    law = laws.get(name)
    out = {f: float(getattr(model, f)) for f in law.fields}
    for part in law.parts:
        value = model.extra.get(part)
        if value is None:
            continue
        if effects.get(part).scalar:
            out[part] = float(value)
        else:
            out |= {f"{part}.{k}": float(v) for k, v in effects.get(part).law.parameters(value).items()}  # type: ignore[union-attr]
    return out


def _held(terms) -> tuple[str, ...]:
    """Base fields whose library term the model does not carry: refinement holds them at zero."""
    fields = term_fields()
    return tuple(f for t, (f, _) in fields.items() if t not in terms and f in BASE_FIELDS)


@dataclass(frozen=True)
class LibraryTerms(Constraint):
    """A non-empty sequence of the library's terms (``weak.terms``: the registry's, when checked)."""

    @override
    def accepts(self, value) -> bool:
        return Several(Options(library_terms())).accepts(value)

    @override
    def describe(self) -> str:
        return f"a non-empty sequence of library terms ({', '.join(library_terms())})"


_READ = {
    "base": "as recorded",
    "force": "as recorded",
    "impact": "the force windowed (each hit's offset off, zero between its pulses); the weak-form rows and restarted "
    "windows that would hold a pulse not read (each window restarted after it); blocks and windows shortened to "
    "the ring-down (settings.window_s); no output-error refinement unless refine=True",
    "decay": "a free decay from the record's own initial state, its input not used; blocks and windows shortened to "
    "the ring-down (settings.window_s)",
}
"""How the workflow reads each record kind (``record_kind``; the result's ``record_kind.read``)."""


class DiscrepancyError(MeasurementError):
    """The record cannot support the workflow (too short, no excitation)."""


class Discrepancy(StructureResults, Estimator):
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
        Refine each model by output error (an effect is kept only if it then predicts better). None: where it is
        defined, a single DOF's record other than a hammer's (its windows would cross the pulses); ``refine=True``
        on a structure's record is one ``InputError``.
    unnamed : bool, default False
        Add a non-parametric force for what no catalogue effect names (the hybrid model; a single DOF's).
    element : str or (int, int), optional
        Where the element acts on a record of N > 1 DOFs: ``"I-J"`` (``structure_id.discrepancy``: the element's
        base law with the linear structure as the baseline, one round of the catalogue, the same paired block
        rule). None: the single DOF.

    Attributes
    ----------
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

    # --- the weak-form system with an optional end stop column -----------------------------------
    def _systems(self, rec: Measurement) -> None:
        n_id = int(round(rec.n * (1 - self.validation_fraction)))
        n_fit = int(round(rec.n * (1 - self.validation_fraction - self.selection_fraction)))
        ident = rec.segment(0, n_id)
        self._form = WeakForm.of(ident)
        self._zs, self._v = self._form.zs, self._form.v
        # the measured states the gap's free runs start from, whole record (before and after share them)
        self._z0, self._v0, _, _ = rec.states("state")
        self._gain = known_input_gain(rec)
        self.n_id_, self.n_fit_ = n_id, n_fit
        self._library_systems: dict[tuple[int, int], tuple[Measurement, np.ndarray, np.ndarray]] = {}
        self._aux_columns: dict[tuple[int, int, str], tuple[Measurement, np.ndarray]] = {}
        self._law_columns: dict[tuple[int, int, str], tuple[Measurement, np.ndarray]] = {}
        self._shapes: dict[str, ShapeFit | str] = {}  # each law's shape on the record, or why it has none

    # --- the laws' columns beside the catalogue's ----------------------------------------------------
    def _damping_law(self) -> str:
        """The damping law the laws' shapes are fitted with: ``damping``, else the one whose columns are the
        baseline's velocity terms (the reference study's ``quadratic`` where none is).
        """
        if self.damping is not None:
            return self.damping
        return _damping_of(tuple(t for t in self.baseline if t not in _displacement_labels())) or laws.DEFAULT_DAMPING

    def _shape(self, rec: Measurement, law: str) -> ShapeFit:
        """``law``'s shape on the record (``shape.fit_shape`` on the fitting part, a spline's knots scored on the
        selection part), found once; ``DiscrepancyError`` saying why where it has none.
        """
        hit = self._shapes.get(law)
        if hit is None:
            try:
                hit = fit_shape(rec, law, self._damping_law(), n_fit=self.n_fit_, n_id=self.n_id_,
                                window_s=self.window_s)  # fmt: skip
            except (MeasurementError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                hit = " ".join(str(exc).split()) or type(exc).__name__
            self._shapes[law] = hit
        if isinstance(hit, str):
            raise DiscrepancyError(f"{rec.source}: the {law} law has no shape on this record: {hit}")
        return hit

    def _law_extra(self, law: str | None) -> tuple[str, ...]:
        """The columns of ``law`` (at its shape) that the catalogue has not (a shaped part's, z^6, z^7), in the
        law's order; none without a law.
        """
        if law is None:
            return ()
        lw = laws.get(law)
        known = set(library_terms())
        labels = [c.label for c in lw.column_list(self._shapes_of(law))]
        return tuple(t for t in labels if t not in known)

    def _shapes_of(self, law: str) -> dict[str, Any]:
        """The shape fields of ``law``'s shaped parts (empty for a law without: no fit needed)."""
        if not laws.get(law).shaped():
            return {}
        hit = self._shapes.get(law)
        assert isinstance(hit, ShapeFit), f"the {law} law's shape is sought first (_shape)"
        return hit.shape

    def _law_terms(self, law: str) -> tuple[str, ...]:
        """The restoring force's columns of ``law`` (labels, at its shape)."""
        return tuple(c.label for c in laws.get(law).column_list(self._shapes_of(law)))

    def _restoring_terms(self, terms, law: str | None) -> tuple[str, ...]:
        """The restoring force's share of ``terms``: the displacement-only catalogue terms and ``law``'s own."""
        own = set(_displacement_labels()) | set(self._law_extra(law))
        return tuple(t for t in terms if t in own)

    def _n_parameters(self, terms, law: str | None) -> int:
        """The restoring force's parameters: its columns' coefficients and its shaped parts' searched shape fields
        (a spline's knots are set by the stroke: none).
        """
        shape = 0 if law is None else sum(len(p.shape_bounds((-1.0, 1.0))) for p in laws.get(law).shaped().values())
        return len(self._restoring_terms(terms, law)) + shape

    def _design(self, rec: Measurement, lo: int, hi: int, stop: float | None, aux: tuple[str, ...] = (),
                law: str | None = None):  # fmt: skip
        """Weak system over samples [lo, hi): the library's columns, the input's, a column per measured
        auxiliary channel in ``aux`` (its projection, like the input's), ``law``'s columns the catalogue has not
        (``_law_extra``, at its shape) and an end-stop column last. The library's part is projected once per span
        and record (a fit asks for the same two spans ~75 times, one per candidate stop and effect: 16 of a
        discrepancy study's 36 s went to projecting them again), a law's once per span too.
        """
        hit = self._library_systems.get((lo, hi))
        if hit is None or hit[0] is not rec:
            sysd = self._form.system(rec, lo, hi)
            read = self._between_pulses(rec, lo, hi, sysd.y_physical.size)
            hit = (rec, sysd.W_physical * read[:, None], sysd.y_physical * read)
            for a in hit[1:]:
                a.setflags(write=False)
            self._library_systems[(lo, hi)] = hit
        W, y = hit[1], hit[2]
        for name in aux:  # projected once per span like the library (the stop's column moves; these do not)
            cached = self._aux_columns.get((lo, hi, name))
            if cached is None or cached[0] is not rec:
                Wa = self._form.project(np.asarray(rec.aux[name][lo:hi], float)[:, None], rec.dt)[:, 0]
                cached = self._aux_columns[(lo, hi, name)] = (rec, Wa)
            W = np.column_stack([W, cached[1][: W.shape[0]]])
        extra = self._law_extra(law)
        if extra:
            assert law is not None
            cached = self._law_columns.get((lo, hi, law))
            if cached is None or cached[0] is not rec:
                lw = laws.get(law)
                at = [i for i, c in enumerate(lw.column_list(self._shapes_of(law))) if c.label in extra]
                with np.errstate(invalid="ignore", over="ignore"):
                    cols = lw.columns(self._zs[lo:hi], self._v[lo:hi], self._shapes_of(law),
                                      self._form.velocity_noise)[:, at]  # fmt: skip
                cached = self._law_columns[(lo, hi, law)] = (rec, self._form.project(cols, rec.dt))
            W = np.column_stack([W, cached[1][: W.shape[0]]])
        if stop is not None:
            z = self._zs[lo:hi]
            col = _stop()[1].column(z, stop)
            Ws = self._form.project(col[:, None], rec.dt)[:, 0]
            W = np.column_stack([W, Ws[: W.shape[0]]])
        if aux or extra or stop is not None:  # a row the library's part does not read (``_between_pulses``) reads none
            W = W * self._between_pulses(rec, lo, hi, y.size)[:, None]
        return W, y

    def _between_pulses(self, rec: Measurement, lo: int, hi: int, rows: int) -> np.ndarray:
        """Which of the ``rows`` weak-form rows of samples [lo, hi) the fits read (1.0) and which they do not (0.0):
        on a hammer's record (``record_kind``) a row whose test function holds a sample of a pulse is not read (the
        hits set the ring-downs' states, the rows after them read the ring-downs, as its restarted windows start
        after the pulses: ``_after_pulses``); on any other record every row. A pulse of a few samples is not
        resolved by its samples (a 40 N, 4 ms half-sine at 1 kHz integrates 5 % short, its phase decides), and the
        rows across it made the fit trade the missing impulse for damping: on the seed-like double well hit four
        times, c 0.561 and c_nl -0.303 against 0.5 and 0, the held-out gap 3.9 % against the true model's 0.32 %;
        with them not read, c 0.5006, c_nl -0.003, the gap 0.36 % (1 um of noise, measured).
        """
        kind = vars(self).get("record_kind_")
        if kind is None or kind.kind != "impact":
            return np.ones(rows)
        support = test_function(self._form.half, rec.dt)[0].size
        busy = np.concatenate([[0], np.cumsum(np.asarray(rec.u)[lo:hi] != 0)])
        first = np.minimum(np.arange(rows) * self._form.stride, hi - lo)
        last = np.minimum(first + support, hi - lo)
        return ((busy[last] - busy[first]) == 0).astype(float)

    def _fit(self, W: np.ndarray, y: np.ndarray, terms: tuple[str, ...], stop: bool, n_aux: int = 0,
             law: str | None = None) -> np.ndarray:  # fmt: skip
        """Least squares on ``terms`` (+ the auxiliary channels' and the stop's columns), the input's
        coefficient fixed by physics; ``law``: the restoring law whose own columns (``_design``) ``terms`` may name.
        """
        lib = library_terms()
        n_lib = len(lib)
        extra = self._law_extra(law)
        aux_cols = list(range(n_lib + 1, n_lib + 1 + n_aux))  # after the input's; the law's next, the stop's last
        index = {t: i for i, t in enumerate(lib)} | {t: n_lib + 1 + n_aux + j for j, t in enumerate(extra)}
        cols = [index[t] for t in terms] + aux_cols + ([W.shape[1] - 1] if stop else [])
        target = y.copy()
        if self._gain is not None:
            target = target - self._gain * W[:, n_lib]
        else:
            cols = cols + [n_lib]
        A = W[:, cols]
        scale = np.sqrt(np.mean(A**2, axis=0))  # rms, not std: the constant's column has none
        scale[scale == 0] = 1.0
        coef = np.linalg.lstsq(A / scale, target, rcond=None)[0] / scale
        full = np.zeros(n_lib + 1 + n_aux + len(extra) + int(stop))
        full[cols] = coef
        if self._gain is not None:
            full[n_lib] = self._gain
        return full

    def _model(self, coef: np.ndarray, rec: Measurement, stop: float | None, aux: tuple[str, ...] = (),
               law: str | None = None) -> Model:  # fmt: skip
        n_lib = len(library_terms())
        # weak.model_from's order: the library's terms, the channels' (here after the input's column), the input
        phys = np.concatenate([coef[:n_lib], coef[n_lib + 1 : n_lib + 1 + len(aux)], coef[n_lib : n_lib + 1]])
        mass = mass_of(rec, self._gain, phys[-1])[0]
        model = model_from(phys, mass, aux)
        labels = self._law_extra(law)
        if labels:  # the law's own parts (a shaped part's value from its shape and coefficients, z^6, z^7)
            assert law is not None
            lw, shape = laws.get(law), self._shapes_of(law)
            cols = lw.column_list(shape)
            at = n_lib + 1 + len(aux)
            own = dict(zip(labels, coef[at : at + len(labels)], strict=True))
            _, parts = lw.values([own.get(c.label, 0.0) for c in cols], mass, shape)
            targets = {c.target for c in cols if c.label in own}
            own_parts = {k: v for k, v in parts.items() if k in targets}
            model = Model(**{**model.to_dict(), "extra": {**dict(model.extra), **own_parts}})
        if stop is not None:
            k = -mass * float(coef[-1])
            if k > 0:
                extra = {**dict(model.extra), _stop()[0]: {"k": k, "z": stop}}
                model = Model(**{**model.to_dict(), "extra": extra})
        return model

    def _size_of(self, rec: Measurement, cand: Candidate) -> dict[str, Any]:
        """A ranked effect's size as its fit on the scoring part has it (``{"size": ...}``; the model's entry for
        it), for a catalogue effect that scored; nothing for the baseline, a law or a channel. What a test
        design takes as each hypothesis (``analysis.separation``).
        """
        if (cand.effect == "none" or cand.coefficients is None or not math.isfinite(cand.heldout_percent)
                or law_of(cand.effect) is not None or cand.effect.startswith(effects.AUX_PREFIX)):  # fmt: skip
            return {}
        try:
            size = self._model(cand.coefficients, rec, cand.stop, cand.aux, cand.law).extra.get(cand.effect)
        except (ValueError, ArithmeticError):
            return {}
        if size is None:
            return {}
        # a stop's {"k", "z"} is the model's read-only mapping: a plain dict of floats, as JSON and pickle take it
        return {"size": {k: float(v) for k, v in size.items()} if hasattr(size, "items") else float(size)}

    def _score(self, rec: Measurement, cand: Candidate) -> Candidate:
        W, y = self._design(rec, 0, self.n_fit_, cand.stop, cand.aux, cand.law)
        coef = self._fit(W, y, cand.terms, cand.stop is not None, len(cand.aux), cand.law)
        Ws, ys = self._design(rec, self.n_fit_, self.n_id_, cand.stop, cand.aux, cand.law)
        r2 = (ys - Ws @ coef) ** 2
        rows = block_rows(self.window_s_, rec.fs, self._form.stride)
        nb = r2.size // rows
        if nb < 2:
            need = 2 * rows / max(1, r2.size) * rec.n  # samples of record that give two blocks
            raise DiscrepancyError(
                f"{rec.source}: too short for the discrepancy workflow: {rec.duration:.3g} s, at least about "
                f"{need / rec.fs:.3g} s are needed (the part from {100 * self.n_fit_ / rec.n:.0f} to "
                f"{100 * self.n_id_ / rec.n:.0f} % of the record scores each effect in {self.window_s_:g} s blocks, "
                "two at least)"
            )
        cand.block_ms = block_scores(r2, rows, ys.var())
        cand.heldout_percent = float(100 * np.sqrt(cand.block_ms.mean()))
        cand.coefficients = coef
        if law_of(cand.effect) is not None:
            # a law that fails the identifications' checks is never named (``law_choice.problems``: no stable well,
            # a well outside the stroke, an escape just past it, damping that feeds energy in), whatever it scores
            try:
                failed = law_choice.problems(self._model(coef, rec, cand.stop, cand.aux, cand.law), rec, self.n_id_)
            except (ValueError, ArithmeticError) as exc:
                failed = [" ".join(str(exc).split())]
            if failed:
                cand.notes["problems"] = failed
                cand.heldout_percent = math.inf
        elif cand.effect != "none":
            # the catalogue never names an effect whose fit opens an escape just past the stroke
            try:
                model = self._model(coef, rec, cand.stop, cand.aux, cand.law)
                escape = boundedness(model, rec.segment(0, self.n_id_), free_run=False)
                escape = escape["escape_z"]
            except ValueError:
                escape = None
            if escape is not None:
                cand.notes["escape_z"] = escape
                cand.heldout_percent = math.inf
        return cand

    def _law_candidate(self, rec: Measurement, name: str, terms: tuple[str, ...], stop: float | None,
                       aux: tuple[str, ...], law: str | None) -> Candidate:  # fmt: skip
        """The candidate that replaces the restoring force of ``terms`` (``law``'s, or the catalogue's terms of z
        alone) by the law ``name`` at its shape, the rest (the damping, a stop, the channels) held; scored as an
        effect is (``_score``). A law with no shape on the record is not a candidate, and says why.
        """
        cand = Candidate(f"{LAW_PREFIX}{name}", (), stop, aux, name)
        try:
            shape = self._shape(rec, name)
        except DiscrepancyError as exc:
            cand.notes["problems"] = [str(exc)]
            return cand
        rest = tuple(t for t in terms if t not in self._restoring_terms(terms, law))
        cand.terms = self._law_terms(name) + rest
        if shape.shape:
            cand.notes["shape"] = shape.to_json()["shape"]
        return self._score(rec, cand)

    def _fit_stop(self, rec: Measurement, terms: tuple[str, ...], aux: tuple[str, ...] = (), upto: int | None = None,
                  keep: np.ndarray | None = None, law: str | None = None) -> float:  # fmt: skip
        """The end stop's position (a nonlinear parameter) by least squares on the fitting part (or the weak rows
        ``keep`` of [0, ``upto``)): a grid over the outer 0.05-10 % of the stroke on either side (an onset with at
        least ``STOP_MIN_SAMPLES`` samples beyond it), refined by a bounded scalar search between the best grid
        point's neighbours. The grid reaches 0.05 %: a stop hit in 0.2 % of a record (the plus well's bumper on a
        record that lives in the minus well) lies beyond the 0.5 % point, and a search that starts there never
        reaches it (measured: onset 24.3 mm and k 340-640 N/m for a 3000 N/m stop at 28 mm, then not named).
        """
        from scipy import optimize

        upto = self.n_fit_ if upto is None else upto

        def ss(zs: float) -> float:
            W, y = self._design(rec, 0, upto, zs, aux, law)
            if keep is not None:
                W, y = W[keep], y[keep]
            coef = self._fit(W, y, terms, True, len(aux), law)
            return float(np.sum((y - W @ coef) ** 2)) if coef[-1] < 0 else math.inf  # a stop pushes back

        z = self._zs[:upto]
        qs = tuple(q for q in (0.05, 0.1, 0.2, 0.5, 1, 2, 3, 5, 7, 10) if q / 100 * z.size >= STOP_MIN_SAMPLES)
        grid = [float(np.percentile(z, q)) for q in qs] + [float(np.percentile(z, 100 - q)) for q in qs]
        vals = [ss(g) for g in grid]
        i = int(np.argmin(vals))
        side = grid[: len(qs)] if i < len(qs) else grid[len(qs) :]
        j = side.index(grid[i])
        lo, hi = sorted((side[max(j - 1, 0)], side[min(j + 1, len(side) - 1)]))
        if hi > lo:
            # a position where the stop would pull (inf) makes the bounded search's parabola inf - inf: its
            # golden-section step takes over, as intended; numpy's notice of the NaN is not the user's business
            with np.errstate(invalid="ignore"):
                r = optimize.minimize_scalar(ss, bounds=(lo, hi), method="bounded", options={"xatol": 1e-5})
            if r.fun < vals[i]:
                return float(r.x)
        return grid[i]

    # --- locate ------------------------------------------------------------------------------------
    def locate(self, rec: Measurement, model_terms: tuple[str, ...], stop: float | None,
               aux: tuple[str, ...] = (), law: str | None = None) -> dict[str, Any]:  # fmt: skip
        """Where the current model's weak residual lives: by regime and over the state plane."""
        W, y = self._design(rec, 0, self.n_id_, stop, aux, law)
        coef = self._fit(W, y, model_terms, stop is not None, len(aux), law)
        r = y - W @ coef
        form = self._form
        centres = np.clip(np.arange(r.size) * form.stride + form.centre(rec.dt), 0, self.n_id_ - 1)
        z, v = self._zs[centres], self._v[centres]
        try:
            model = self._model(coef, rec, stop, aux, law)
            eq = model.equilibria()
            wells = (eq.z_minus, eq.z_0, eq.z_plus)
        except ValueError:
            wells = (None, None, None)
        regimes = {}
        v_rms = float(np.sqrt(np.mean(self._v**2)))
        stroke = np.percentile(np.abs(self._zs - np.median(self._zs)), 90)
        masks = {
            "near zero velocity": np.abs(v) < 0.1 * v_rms,
            "large stroke": np.abs(z - np.median(self._zs)) > stroke,
        }
        if wells[1] is not None:
            zm, z0, zp = wells
            masks["crossing the barrier"] = np.abs(z - z0) < 0.25 * (zp - zm) / 2
            masks["in the minus well"] = (z < z0) & ~masks["crossing the barrier"]
            masks["in the plus well"] = (z >= z0) & ~masks["crossing the barrier"]
        total = float(np.sum(r**2))
        for name, m in masks.items():
            if m.any():
                share_r = float(np.sum(r[m] ** 2) / total)
                share_t = float(np.mean(m))
                regimes[name] = {"residual_share": share_r, "time_share": share_t, "ratio": share_r / share_t}
        worst = max(regimes.items(), key=lambda kv: kv[1]["ratio"]) if regimes else None
        return {"regimes": regimes, "worst": worst[0] if worst else None, "z": z, "v": v, "r": r, "wells": wells}

    # --- the workflow ------------------------------------------------------------------------------
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
            if self.unnamed:
                raise DiscrepancyError("Discrepancy(unnamed=True): the non-parametric force is a single DOF's (a "
                                       f"record of {rec.n_dof} DOFs)")  # fmt: skip
        from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS, check_decay, record_kind
        from negstiff.inference.estimators.identification import refuse_one_orbit

        kind = record_kind(rec).kind
        if kind in RING_DOWN_KINDS and at is not None:
            # a structure's ring-down is read raw by ``structure_id.discrepancy`` (its windows across the hits, no
            # ring-down blocks: a clean 2-DOF hammer record's held-out gap 12 %, measured): refused as before
            what = "a hammer's record" if kind == "impact" else "a free decay"
            raise DiscrepancyError(f"{rec.source}: {what} of {rec.n_dof} DOFs: the discrepancy workflow reads a single "
                                   "DOF's ring-down, not a structure's yet; NSI and SINDy identify this record "
                                   "(element=)")  # fmt: skip
        rec.require(4000, "the discrepancy workflow")
        if kind != "decay":  # a free decay has no input: its response must ring down instead
            rec.require_excitation("the discrepancy workflow")
            if at is None:
                refuse_one_orbit(rec, "the discrepancy workflow")
        else:
            check_decay(rec, "the discrepancy workflow")
        rec.require_motion("the discrepancy workflow")
        rec.require_live_aux("the discrepancy workflow")
        if at is None:
            self.check_length(rec)

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
        rec = self.check(rec)
        at = element_of(self, rec)
        if at is not None:
            self.result_ = structure_discrepancy(self, rec, at)
            self.model_ = self.result_.model
            return self
        # a ring-down, read as NSI and SINDy read it (``record_kind``): a hammer's force windowed (each hit's offset
        # off, zero between its pulses), a free decay's input zero (a decay from the record's own initial state);
        # its blocks and restarted windows shortened as SINDy's (``sindy.ring_down_window``: a ring-down lasts
        # seconds), every window of the workflow alike for the fit's duration (the parameter is given back after)
        from negstiff.inference.analysis.record_kind import identification_record, record_kind
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

    def _baseline(self, rec: Measurement) -> tuple[tuple[str, ...], str | None]:
        """The baseline's terms and its restoring law (``law``, ``damping``; module docstring, 1), and its account
        in ``baseline_law_``. None: ``baseline``'s terms, their velocity terms replaced by ``damping``'s columns where
        it is given; the law is then the cubic where they are its terms (the reference study's, the default) and
        none otherwise (``LINEAR_BASELINE``). A law: its columns at the record's shape (``_shape``). ``"auto"``: the
        law the record asks for, chosen as the identifications choose it (``law_choice.choose``).
        """
        damping = self._damping_law()
        damping_terms = tuple(c.label for c in laws.get(damping).column_list())
        choice = None
        velocity = damping_terms
        if self.law is None:
            restoring = tuple(t for t in self.baseline if t in _displacement_labels())
            velocity = tuple(t for t in self.baseline if t not in restoring)
            terms = restoring + (velocity if self.damping is None else damping_terms)
            cubic = self._law_terms(laws.DEFAULT_RESTORING)
            law = laws.DEFAULT_RESTORING if restoring == cubic else None
        else:
            law = self.law
            if law == "auto":
                choice = self._choose_law(rec)
                law = choice.best.law
            self._shape(rec, law)
            terms = self._law_terms(law) + damping_terms
        self.baseline_law_ = {
            "requested": self.law,
            "restoring": law,
            "damping": damping if self.law is not None or self.damping is not None else _damping_of(velocity),
            "terms": list(terms),
            "shape": None if law is None or not laws.get(law).shaped() else self._shapes[law].to_json(),  # type: ignore[union-attr]
            "choice": None if choice is None else self._choice_json(choice),
        }
        return terms, law

    def _law_estimate(self, rec: Measurement, part: Measurement, n: int, name: str) -> Model:
        """``law_choice.choose``'s estimate of the law ``name`` over the first ``n`` samples of ``part``: on the
        identification part itself the workflow's own fit (the law's columns at the record's shape, ``_shape``,
        and the damping law's, by weak least squares over [0, n_id)); on the comparison's fitting part the same
        fit of that part alone (its shape found there, on its first ``1 - selection / (1 - validation)``).
        """
        damping = self._damping_law()
        if part is rec and n == self.n_id_:
            self._shape(rec, name)
            terms = self._law_terms(name) + tuple(c.label for c in laws.get(damping).column_list())
            return self._refit_model(rec, terms, None, (), name)
        share = 1 - self.selection_fraction / (1 - self.validation_fraction)
        fit = fit_shape(part, name, damping, n_fit=int(round(share * n)), n_id=n, window_s=self.window_s)
        lib = Library.of_laws(name, damping, fit.shape)
        gain = known_input_gain(part)
        phys = fit_support(WeakForm.of(part).system(part, 0, n, library=lib), gain)
        return lib.model(phys, mass_of(part, gain, phys[-1])[0])

    def _choose_law(self, rec: Measurement) -> law_choice.Choice:
        """The restoring law the record asks for (``law="auto"``), by the identifications' comparison
        (``law_choice.choose``) with this workflow's estimate of each (``_law_estimate``).
        """
        try:
            return law_choice.choose(rec, self.n_id_, laws.names("restoring"),
                                     lambda part, n, name: self._law_estimate(rec, part, n, name),
                                     lambda m: m)  # fmt: skip
        except InputError as exc:
            raise DiscrepancyError(str(exc)) from None

    @staticmethod
    def _choice_json(choice: law_choice.Choice) -> dict[str, Any]:
        """The comparison that chose the baseline's law, as the identifications' ``law_choice``."""
        best = choice.best
        return {**choice.windows, "chosen": best.law, "candidates": [c.to_json() for c in choice.candidates],
                "summary": f"the laws were compared on what they predict ({choice.windows.get('windows')} windows of "
                           f"{choice.windows.get('window_s', math.nan):.3g} s restarted over the selection part): "
                           f"{best.law} chosen (median window {best.median_percent:.3g} %, weight "
                           f"{best.weight:.2f})"}  # fmt: skip

    def _extra_parameters(self, c: Candidate, terms: tuple[str, ...], law: str | None) -> int:
        """The parameters a candidate adds to the current model: an effect's values (an end stop's two), a
        channel's theta, a law's restoring parameters beyond the current restoring force's (``_n_parameters``:
        the geometric law's k0, k_f, k_f D0, L and alpha against the cubic's k0..k3 adds one; a magnet's none).
        """
        if c.effect == "none":
            return 0
        if law_of(c.effect) is not None:
            return self._n_parameters(c.terms, c.law) - self._n_parameters(terms, law)
        if c.effect.startswith(effects.AUX_PREFIX):
            return 1  # theta alone
        return effects.get(c.effect).n_values

    def _first(self, ranking: list[Candidate], best: Candidate, iteration: dict[str, Any] | None,
               terms: tuple[str, ...], law: str | None, gain) -> dict[str, Any]:  # fmt: skip
        """Why the candidate ranked first (the least held-out weak residual) was named or not, in words: the
        result's ``iterations[].first``.
        """
        first = ranking[0]
        out: dict[str, Any] = {"effect": first.effect, "score": first.heldout_percent,
                               "named": bool(iteration is not None and iteration.get("kept")
                                             and best is first)}  # fmt: skip
        none = next(c for c in ranking if c.effect == "none")
        if first.effect == "none":
            out["why"] = "no candidate's held-out weak residual fell below the baseline's"
            return out
        if best is not first:
            n_first, n_best = (self._extra_parameters(c, terms, law) for c in (first, best))
            out["why"] = (f"{best.effect} scores within max(one standard error, {100 * self.margin:g} %) of it "
                          f"({best.heldout_percent:.3g} % against {first.heldout_percent:.3g} %) with fewer parameters "
                          f"({n_best} against {n_first}): the simpler of the two was the candidate")  # fmt: skip
            if iteration is None:
                out["why"] += (f", and its gain over the baseline ({100 * gain.gain / _scores(none).mean():.3g} %) was "
                               f"not beyond max(one standard error, {100 * self.margin:g} %)")  # fmt: skip
            elif not iteration.get("kept"):
                out["why"] += f"; {iteration['verdict']}"
            return out
        if iteration is None:
            out["why"] = (f"its gain over the baseline ({100 * gain.gain / _scores(none).mean():.3g} % of its held-out "
                          f"weak residual, one standard error {100 * gain.se / _scores(none).mean():.3g} %) is not "
                          f"beyond max(one standard error, {100 * self.margin:g} %)")  # fmt: skip
        elif not iteration.get("kept"):
            out["why"] = iteration["verdict"]
        return out

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

    def _helps(self, rec: Measurement, before: dict[str, Any], after: dict[str, Any], effect: str,
               model_before: Model, model_after: Model, spec_before: Candidate | None = None,
               best: Candidate | None = None) -> tuple[bool, str, dict[str, Any]]:  # fmt: skip
        """Whether the effect is kept, and why.

        Judged on the held-out tail twice, the same restarted free runs before and after (paired), each
        comparison by the windows' log mean-square errors (log: a window whose run parts near the barrier,
        chaos, carries an error 100x the others' and would decide a plain mean alone; a
        window whose run diverges counts as an error the size of the signal):

        * **pooled**: every ``window_s`` window of the tail;
        * **where it acts** (``_regime``): windows starting just before each episode where the effect's force
          is large, scored on their own, beside the tail's windows where it never acts (the rest).

        * **where it acts, cross-validated** (``_regime_folds``), when the tail holds fewer than three such
          windows (an effect the tail barely reaches): the windows where it acts anywhere in the record, in
          blocks, each predicted by fits made without its block's data.

        Kept when the model with it predicts the windows where it acts better by more than one standard error
        of their paired differences and does not predict the rest of the tail worse beyond theirs; with fewer
        than three such windows in the tail, the cross-validated windows decide, and with fewer than three of
        those too, the pooled rule. An effect the equation error named that does not help the prediction is
        said, and left out.
        """
        pooled = self._paired(rec, before.get("window_ms"), after.get("window_ms"))
        regime = self._regime(rec, before, after, effect, model_before, model_after)
        evidence: dict[str, Any] = {"pooled": pooled, "regime": regime,
                                    "bayesian": self._held_out_opinion(rec, model_before, model_after)}  # fmt: skip
        change = "{:.3g} % (one standard error: {:.3g} to {:.3g} %, geometric mean)"
        judged, where = regime, "held-out windows"
        if regime.get("windows", 0) < 3 and spec_before is not None and best is not None:
            evidence["folds"] = self._regime_folds(rec, effect, spec_before, best, model_after, model_before)
            self._folds_evidence[effect] = evidence["folds"]
            if evidence["folds"].get("windows", 0) >= 3 and evidence["folds"].get("acting") is not None:
                judged = {**evidence["folds"], "rest": regime.get("rest")}
                where = f"windows of the record (in {len(judged['folds'])} blocks, each predicted by fits without it)"
        # a measured channel's term the equation error named (beyond twice its standard error) is kept unless it
        # predicts worse beyond its uncertainty: the catalogue's rule (better beyond it) dropped a piezo's coupling
        # whose windows' error fell 30 % within a wide one (measured)
        measured = effect.startswith(effects.AUX_PREFIX)

        def not_worse(c: dict[str, Any] | None) -> bool:
            return c is not None and not (c["gain_percent"] < 0 and c["significant"])

        if judged.get("windows", 0) >= 3 and judged.get("acting") is not None:
            acts, rest = judged["acting"], judged.get("rest")
            worse = rest is not None and rest["gain_percent"] < 0 and rest["significant"]
            what = (f"the {judged['windows']} {where} where it acts: rms error fell "
                    + change.format(acts["gain_percent"], *acts["gain_interval_percent"]))  # fmt: skip
            if acts["significant"] and acts["gain_percent"] > 0 and not worse:
                return True, f"{effect}: kept: {what}; the rest not worse", evidence
            if measured and not_worse(acts) and not worse:
                return True, f"{effect}: kept: a measured channel, not worse: {what}; the rest not worse", evidence
            why = "the rest predicted worse" if worse else "not a fall beyond its uncertainty"
            return False, f"{effect}: named by the equation error but not kept: {what}: {why}", evidence
        if pooled is None:
            return False, f"{effect}: not kept: the held-out tail has too few windows to tell if it helps", evidence
        txt = change.format(pooled["gain_percent"], *pooled["gain_interval_percent"])
        if pooled["significant"] and pooled["gain_percent"] > 0:
            return True, f"{effect}: kept: the held-out windows' rms error fell {txt}", evidence
        if measured and not_worse(pooled):
            return True, (f"{effect}: kept: a measured channel the equation error names, not predicting the held-out "
                          f"windows worse: their rms error fell {txt}"), evidence  # fmt: skip
        return False, (f"{effect}: named by the equation error but not kept: with it the held-out windows' rms error "
                       f"fell {txt}, not beyond its uncertainty"), evidence  # fmt: skip

    def _paired(self, rec: Measurement, a, b, worst: float | None = None) -> dict[str, Any] | None:
        """Paired comparison of two models' per-window mean-square errors (the same windows) by their logs:
        the rms error's fall in % (geometric mean), its standard error, whether it exceeds one standard error.
        """
        if a is None or b is None or len(a) != len(b) or len(a) < 2:
            return None
        if worst is None:  # a diverged run counts as an error the size of the signal (the tail's, by default)
            worst = float(np.mean(rec.displacement[self.n_id_ :] ** 2))
        a, b = (np.log(np.maximum(np.where(np.isfinite(x), x, worst), 1e-300)) for x in (a, b))
        gain = compare(a, b, 0.0, a)
        return {
            "windows": int(len(a)),
            "gain_percent": float(100 * (1 - math.exp(-gain.gain / 2))),  # the windows' rms error, geometric mean
            "gain_interval_percent": [float(100 * (1 - math.exp(-(gain.gain + k * gain.se) / 2))) for k in (-1, 1)],
            "significant": bool(gain.significant),
        }

    def _effect_force(self, model: Model, effect: str, z: np.ndarray, v: np.ndarray) -> np.ndarray | None:
        """The named effect's force [N] in ``model`` at the states (z, v); None for a measured channel's term and
        for a law (it replaces the restoring force at every state: it acts wherever the motion goes).
        """
        if law_of(effect) is not None:
            return None
        e = effects.get(effect)
        if isinstance(e.law, effects.MeasuredChannel):
            return None
        value = model.to_dict()[e.folds_into] if e.folds_into else model.extra.get(effect)
        if value is None:
            return None
        return np.asarray(e.law.force(value, z, v), float)

    def _regime(self, rec: Measurement, before: dict[str, Any], after: dict[str, Any], effect: str,
                model_before: Model, model_after: Model) -> dict[str, Any]:  # fmt: skip
        """The held-out windows where ``effect`` acts, scored on their own: free runs restarted a quarter window
        before each episode of the tail where the effect's force (the model's with it, at the measured states)
        exceeds a quarter of its rms over the samples where it acts at all, no longer than the motion there stays
        predictable by either model (``_episode_windows``: ``window_s / 2`` at most); and the tail's ``window_s``
        windows that hold no such sample (the rest). Gaps in % of the windows' rms z, before and after, and the
        paired comparisons.
        """
        z, v = self._z0, self._v0
        force = self._effect_force(model_after, effect, z[self.n_id_ :], v[self.n_id_ :])
        if force is None:
            return {"windows": 0, "reason": "a law replaces the restoring force at every state: judged on every "
                    "held-out window" if law_of(effect) is not None else "a measured channel's term acts wherever "
                    "the channel does"}  # fmt: skip
        if not np.any(np.abs(force) > 0):
            return {"windows": 0, "reason": "the effect does not act in the held-out tail"}
        acting, windows, horizon = self._episode_windows(rec, force, self.n_id_, (model_before, model_after))
        out: dict[str, Any] = {"window_s": windows.length / rec.fs, "windows": len(windows),
                               "record_window_s": horizon["record_s"],
                               "acting_share_of_tail": float(np.mean(acting))}  # fmt: skip
        if len(windows) < 2:
            return out
        ms_b, ms_a = (self._runs_at(m, rec, windows) for m in (model_before, model_after))
        meas = windows.measured(rec.displacement)
        ref = float(np.sqrt(np.mean(meas**2)))
        worst = float(np.mean(meas**2))
        # the median window's rms error, % of those windows' rms z (the headline gap's measure: one run that
        # parts near the barrier, chaos, cannot decide it)
        out["gap_before_percent"], out["gap_after_percent"] = (
            float(100 * np.sqrt(np.median(np.where(np.isfinite(m), m, worst))) / ref) for m in (ms_b, ms_a)
        )
        out["acting"] = self._paired(rec, ms_b, ms_a)
        a, b = before.get("window_ms"), after.get("window_ms")
        if a is not None and b is not None:
            # the tail's windows (``restarted_free_runs``' own) that hold no sample where it acts
            tail = self._tail_windows(rec)
            clear = ~tail.measured(np.concatenate([np.zeros(self.n_id_, bool), acting])).any(axis=1)
            if clear.sum() >= 2:
                out["rest"] = self._paired(rec, np.asarray(a)[clear], np.asarray(b)[clear])
        return out

    def _predictability(self, rec: Measurement, model: Model) -> dict[str, Any]:
        """How long ``model``'s runs restarted from the record's states stay predictable (``validation.predictability``
        over the identification part, at most ``window_s / 2`` of the fit's own window, ``window_s_``).
        """
        return predictability(model, rec, self.n_id_, self.window_s_, self._z0, self._v0)

    def _parting_sample(self, rec: Measurement, model: Model, windows: RestartWindows, draws: int,
                        min_pairs: int) -> int | None:  # fmt: skip
        """``validation.parting_sample`` of ``model``'s runs over ``windows`` (the identification part's amplitude)."""
        return parting_sample(model, rec, windows, self._z0, self._v0, self.n_id_, draws, min_pairs)

    def _window_length(self, rec: Measurement) -> int:
        """Samples of the regime's and the interval's windows: the record's predictability horizon
        (``predictability_``), at most ``window_s / 2``.
        """
        return max(8, int(round(self.predictability_["window_s"] * rec.fs)))

    def _episode_windows(self, rec: Measurement, force: np.ndarray, lo: int,
                         models: tuple[Model, ...]) -> tuple[np.ndarray, RestartWindows, dict[str, Any]]:  # fmt: skip
        """``_episodes``' windows no longer than the motion there stays predictable by the models compared on them:
        each model's runs from the windows' start states and from those states moved by draws of their noise
        (``LOCAL_DRAWS`` per window, seeded), the first time their rms separation, pooled over windows and draws,
        exceeds ``PREDICTABILITY_FRACTION`` of the identification part's amplitude (``motion_amplitude``); the
        shorter of the models' (and of the record's span, ``_window_length``). Measured before any run is compared
        with the record, the same for every model. Where an effect acts the motion can be far less predictable than
        the record's average (an end stop's bounce next to the barrier: 0.17 s against 0.9 s, measured), which the
        baseline, without the effect, does not show. Returns (acting mask, the windows, ``{"horizon_s", "record_s"}``).
        """
        acting, windows = self._episodes(rec, force, lo)
        length = windows.length
        info = {"record_s": length / rec.fs, "horizon_s": length / rec.fs}
        if len(windows) < 1:
            return acting, windows, info
        for model in models:
            parted = self._parting_sample(rec, model, windows, draws=LOCAL_DRAWS, min_pairs=1)
            if parted is not None:
                length = min(length, max(8, parted))
        if length < windows.length:
            acting, windows = self._episodes(rec, force, lo, length)
            info["horizon_s"] = length / rec.fs
        return acting, windows, info

    def _episodes(self, rec: Measurement, force: np.ndarray, lo: int,
                  length: int | None = None) -> tuple[np.ndarray, RestartWindows]:  # fmt: skip
        """Where a force acts (above a quarter of its rms over the samples where it acts at all) and windows of
        ``length`` samples (by default the record's predictable span, ``_window_length``: ``window_s / 2`` at
        most) restarted a quarter window before each episode (no two overlapping); ``force`` is given from sample
        ``lo`` on. Returns (acting mask from ``lo`` on, the windows).
        """
        nz = np.abs(force) > 0
        acting = np.abs(force) > 0.25 * np.sqrt(np.mean(force[nz] ** 2)) if nz.any() else nz
        length = self._window_length(rec) if length is None else length
        lead = length // 4
        starts: list[int] = []
        edges = np.flatnonzero(np.diff(np.concatenate([[0], acting.astype(np.int8)])) == 1)  # episodes' first samples
        for e in edges:
            s0 = lo + max(0, int(e) - lead)
            if s0 + length <= rec.n and (not starts or s0 >= starts[-1] + length):
                starts.append(s0)
        return acting, self._after_pulses(rec, RestartWindows.at(starts, length))

    def _regime_folds(self, rec: Measurement, effect: str, before: Candidate, best: Candidate,
                      model_after: Model, model_before: Model | None = None,
                      folds: int = 5) -> dict[str, Any]:  # fmt: skip
        """The windows where ``effect`` acts anywhere in the record, judged by blocked cross-validation: the
        episodes where its force (``model_after``'s, at the measured states) is large, their restarted windows
        split into ``folds`` contiguous blocks in time; for each block the model without the effect (``before``'s
        terms) and with it (``best``'s, an end stop's onset searched again) are fitted by weak least squares on
        the identification part without the block's data (the weak rows whose test function touches one of its
        windows or any sample between them where the effect acts) and run from the block's windows. Every
        window is thus predicted by fits that never saw it: the honest judgement where the held-out tail barely
        reaches the effect. Returns the windows, the gaps before and after (the median window's rms error, % of
        those windows' rms z), the paired comparison ``acting`` and each fold's fitted size.
        """
        force = self._effect_force(model_after, effect, self._z0, self._v0)
        if force is None or not np.any(np.abs(force) > 0):
            return {"windows": 0}
        compared = (model_after,) if model_before is None else (model_before, model_after)
        acting, windows, horizon = self._episode_windows(rec, force, 0, compared)
        length = windows.length
        out: dict[str, Any] = {"windows": len(windows), "window_s": length / rec.fs,
                               "record_window_s": horizon["record_s"],
                               "acting_share_of_record": float(np.mean(acting))}  # fmt: skip
        if len(windows) < 3:
            return out
        form = self._form
        n_rows = self._design(rec, 0, self.n_id_, None, before.aux, before.law)[0].shape[0]
        support = test_function(form.half, rec.dt)[0].size
        row_lo = np.arange(n_rows) * form.stride  # row k's test function spans [row_lo, row_lo + support)
        groups = np.array_split(windows.starts, min(folds, len(windows)))
        ms_b, ms_a, sizes = [], [], []
        pos = _positional()
        for idx in groups:
            block = RestartWindows.at(idx, length)
            mask = np.zeros(rec.n, bool)  # the block's samples: its windows and its contacts between them
            mask[block.index] = True
            span = slice(int(idx[0]), int(idx[-1]) + length)
            mask[span] |= acting[span]
            cum = np.concatenate([[0], np.cumsum(mask[: self.n_id_])])
            hi = np.minimum(row_lo + support, self.n_id_)
            keep = (cum[hi] - cum[np.minimum(row_lo, self.n_id_)]) == 0
            models = []
            for cand in (before, best):
                stop = cand.stop
                if pos is not None and cand.effect == pos.name:
                    stop = self._fit_stop(rec, cand.terms, cand.aux, upto=self.n_id_, keep=keep, law=cand.law)
                W, y = self._design(rec, 0, self.n_id_, stop, cand.aux, cand.law)
                coef = self._fit(W[keep], y[keep], cand.terms, stop is not None, len(cand.aux), cand.law)
                models.append(self._model(coef, rec, stop, cand.aux, cand.law))
            ms_b.append(self._runs_at(models[0], rec, block))
            ms_a.append(self._runs_at(models[1], rec, block))
            folds_size = _size_of(models[1], effect)
            sizes.append({"from_s": float(idx[0] / rec.fs), "to_s": float((idx[-1] + length) / rec.fs),
                          "windows": int(len(idx)), "size": folds_size})  # fmt: skip
        b, a = np.concatenate(ms_b), np.concatenate(ms_a)
        meas = windows.measured(rec.displacement)
        ref = float(np.sqrt(np.mean(meas**2)))
        worst = float(np.mean(meas**2))
        out["gap_before_percent"], out["gap_after_percent"] = (
            float(100 * np.sqrt(np.median(np.where(np.isfinite(m), m, worst))) / ref) for m in (b, a)
        )
        out["acting"] = self._paired(rec, b, a, worst)
        out["folds"] = sizes
        return out

    def _runs_at(self, model: Model, rec: Measurement, windows: RestartWindows) -> np.ndarray:
        """Mean-square error of free runs over ``windows``, each restarted from the measured state at its start
        (nan: diverged).
        """
        return np.mean(self._residuals_at(model, rec, windows) ** 2, axis=1)

    def _residuals_at(self, model: Model, rec: Measurement, windows: RestartWindows) -> np.ndarray:
        """Free runs' errors over ``windows`` (run minus measured z, one row per window; nan rows: diverged):
        ``validation.simulate_windows`` from the states the gap's runs start from.
        """
        res = simulate_windows(model, rec, windows, self._z0, self._v0)
        meas = windows.measured(rec.displacement)
        out = np.full(meas.shape, np.nan)
        ok = ~res.diverged
        out[ok] = res.z[ok] - meas[ok]
        return out

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

    def _parsimonious(self, ranking: list[Candidate], terms: tuple[str, ...] = CUBIC_BASELINE,
                      law: str | None = laws.DEFAULT_RESTORING) -> Candidate:  # fmt: skip
        """Among the effects within max(1 SE, margin) of the best held-out residual, the one with the
        fewest parameters (``_extra_parameters``: the end stop has two, its stiffness and its position; a law
        what it adds to the current restoring force, ``terms`` of ``law``), then the lowest residual: a
        two-parameter stop that beats z^5 by 4 % on the as-built device is not evidence of a stop (measured).
        """
        top = ranking[0]
        ok = []
        for c in ranking:
            if c.effect == "none" or not np.isfinite(c.heldout_percent):
                continue
            if indistinguishable(_scores(c), _scores(top), self.margin):
                ok.append(c)
        if not ok:
            return top
        return min(ok, key=lambda c: (self._extra_parameters(c, terms, law), c.heldout_percent))

    def _refit_model(self, rec: Measurement, terms, stop, aux: tuple[str, ...] = (), law: str | None = None) -> Model:
        W, y = self._design(rec, 0, self.n_id_, stop, aux, law)
        return self._model(self._fit(W, y, terms, stop is not None, len(aux), law), rec, stop, aux, law)

    def _gap(self, rec: Measurement, model: Model) -> dict[str, Any]:
        """Restarted free runs over the held-out tail (and their residual PSD)."""
        fr = self._tail_runs(model, rec)
        out = {k: v for k, v in fr.items() if not isinstance(v, np.ndarray)}
        ms = fr.get("window_ms")
        out["window_ms"] = ms  # per window, for the paired comparison (``_helps``); not in the result JSON
        if ms is not None:
            ok = np.isfinite(ms)
            # the median window: a single window that diverges near the barrier (chaos) cannot dominate
            out["median_window_rms_um"] = float(1e6 * np.sqrt(np.median(ms[ok]))) if ok.any() else math.inf
            tail = rec.displacement[self.n_id_ :]
            out["median_window_percent"] = (
                float(100 * np.sqrt(np.median(ms[ok])) / np.sqrt(np.mean(tail**2))) if ok.any() else math.inf
            )
        return out

    # --- a hammer's record: windows restarted after its pulses -------------------------------------------
    def _after_pulses(self, rec: Measurement, windows: RestartWindows) -> RestartWindows:
        """On a hammer's record (its force windowed: zero between the pulses, ``record_kind``), each window that
        holds a pulse restarted after it (the hit sets its start state), once the start state's smoothing window
        (``derivatives.derivative_window``, the free runs' states) is clear of it; those that then run past the
        record's end are left out; on any other record ``windows`` as they are. A pulse lasts a few samples (4 ms
        at 1 kHz: four), which the sampled force does not resolve for the simulator: the true model's run through
        a hit missed its record by 0.9-2 mm; restarted on the pulse's last sample by 100-200 um (the smoothing
        window across the hit), half a smoothing window after it by 1-160 um, the velocity's noise (the seed-like
        double well hit by 40 N, 1 um of noise; measured), as the posterior found (``Windows.free_windows``).
        """
        kind = vars(self).get("record_kind_")
        if kind is None or kind.kind != "impact" or not len(windows):
            return windows
        from negstiff.inference.record.derivatives import derivative_window

        cached = vars(self).get("_state_window")
        if cached is None or cached[0] is not rec:  # the states' own window (``Measurement.states("state")``)
            width = derivative_window(rec.displacement, rec.fs, "state", floor=rec.noise_floor())[0]
            cached = self._state_window = (rec, width)
        clear = cached[1] // 2 + 1
        busy = np.asarray(rec.u) != 0
        starts = []
        for s in windows.starts.tolist():
            for _ in range(4):  # a window moved past one pulse into the next is moved again
                held = np.flatnonzero(busy[max(0, s - clear + 1) : s + windows.length])
                if not held.size:
                    break
                s = max(0, s - clear + 1) + int(held[-1]) + clear
            if s + windows.length <= rec.n and not busy[max(0, s - clear + 1) : s + windows.length].any():
                starts.append(s)
        return RestartWindows.at(starts, windows.length)

    def _tail_windows(self, rec: Measurement) -> RestartWindows:
        """The held-out tail's gap windows: ``window_s`` windows from the split (``restart_windows``), on a hammer's
        record restarted after its pulses (``_after_pulses``).
        """
        return self._after_pulses(rec, restart_windows(rec.n, rec.fs, self.window_s_, start=self.n_id_))

    def _tail_runs(self, model: Model, rec: Measurement) -> dict[str, Any]:
        """The held-out tail's restarted free runs (``validation.restarted_free_runs``' keys) over ``_tail_windows``:
        ``restarted_free_runs`` itself where they are its windows (any record but a hammer's).
        """
        if vars(self).get("record_kind_") is None or self.record_kind_.kind != "impact":
            return restarted_free_runs(model, rec, self.n_id_, self.window_s_, self._z0, self._v0)
        windows = self._tail_windows(rec)
        if not len(windows):
            return {}
        err = self._residuals_at(model, rec, windows)
        meas = windows.measured(rec.displacement)
        ok = np.isfinite(err).all(axis=1)
        window_ms = np.where(ok, np.mean(np.where(ok[:, None], err, 0.0) ** 2, axis=1), np.nan)
        out: dict[str, Any] = {"restart_window_s": windows.length / rec.fs, "restart_windows": len(windows),
                               "restart_diverged": int((~ok).sum()), "window_ms": window_ms,
                               "restarted_after_pulses": True}  # fmt: skip
        out["restarted_rms_percent"] = (float(100 * np.sqrt(np.mean(err[ok] ** 2)) / np.sqrt(np.mean(meas[ok] ** 2)))
                                        if ok.any() else math.inf)  # fmt: skip
        return out

    def effect_size(self) -> dict[str, Any]:
        """The named effects' values in the model file's units (an effect that is a base field's term, such as
        ``quadratic_damping``, is read from its field: c_nl); a law's, its parameters in the final model (its base
        fields and its parts', ``PART.FIELD``; None where a later round replaced it).
        """
        out: dict[str, Any] = {}
        folds = {e.name: e.folds_into for e in effects.REGISTRY if e.folds_into}
        fields = self.model_.to_dict()
        for e in self.effects_:
            name = law_of(e)
            if name is not None:
                out[e] = law_parameters(self.model_, name) if name == self.law_ else None
                continue
            val = fields[folds[e]] if e in folds else self.model_.extra.get(e)
            out[e] = dict(val) if isinstance(val, dict) or hasattr(val, "keys") else val
        return out

    def _interval_windows(self, rec: Measurement, effect: str) -> tuple[RestartWindows, str]:
        """The windows an effect's interval is judged on, over the whole record as a posterior's data: runs of the
        record's predictable span (``_window_length``: ``window_s / 2`` at most) restarted one after the other,
        and one more before each episode where the effect acts (``_episodes``' windows, of the same length).
        """
        every = restart_windows(rec.n, rec.fs, self._window_length(rec) / rec.fs, min_step=8)
        starts = set(every.starts.tolist())
        force = self._effect_force(self.model_, effect, self._z0, self._v0)
        extra = 0
        if force is not None and np.any(np.abs(force) > 0):
            acting, episodes = self._episodes(rec, force, 0)
            if acting.mean() < 0.5:
                extra = len(set(episodes.starts.tolist()) - starts)
                starts |= set(episodes.starts.tolist())
        windows = self._after_pulses(rec, RestartWindows.at(sorted(starts), every.length))
        return windows, f"the record's windows, {extra} of them restarted where it acts"

    def effect_interval(self, data, prob: float = 0.9) -> dict[str, Any]:
        """Each named effect's size with its interval (probability ``prob``) on ``data`` (a ``Measurement`` or a path:
        the record this estimator was fitted on), read as the fit read it (``record_kind_``: a hammer's force
        windowed, a free decay's input zero; its windows ``window_s_`` long): ``_effect_interval``.
        """
        if not self.fitted:
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet (effect_interval reads its fit): call "
                                 "fit first")  # fmt: skip
        from negstiff.inference.analysis.record_kind import identification_record

        rec = self.check(data)
        kind = vars(self).get("record_kind_")
        return self._effect_interval(rec if kind is None else identification_record(rec, kind), prob)

    def _effect_interval(self, rec: Measurement, prob: float = 0.9) -> dict[str, Any]:
        """Each named effect's size with its interval (probability ``prob``), by a Laplace approximation of the
        output error over the record's restarted windows (``_interval_windows``: runs of the record's predictable
        span, ``predictability_``, one after the other, and one more before each episode where the effect acts),
        every refined parameter free (``refine.parameter_names``). A run longer than the span would pass chaos's
        amplification in its linearisation off as information (an end stop's onset over 1 s windows: 25.943-25.982
        mm for a 26 mm truth, three windows of 88 holding 56 % of the true model's squared error; over 0.594 s
        windows 25.749-26.176 mm, measured).
        The posterior under a flat prior is taken Gaussian, its covariance the Gauss-Newton inverse Hessian made
        robust over windows (a sandwich with each window one cluster: the samples of a run are correlated, so the
        windows, not the samples, are the independent units); the effect's marginal is kept, widened by the
        distance between the reported value and these windows' mode (one Gauss-Newton step), and centred on the
        reported value. ``Posterior`` does not sample ``extra`` effects, hence this approximation. Also fills
        ``bayesian_`` (``_bayesian_opinion``) for each effect with an interval.
        """
        from scipy import stats

        zq = float(stats.norm.ppf(0.5 + prob / 2))
        out: dict[str, Any] = {}
        self.bayesian_: dict[str, Any] = {}
        for e in self.effects_:
            if law_of(e) is not None:
                out[e] = {"value": self.effect_size()[e], "interval": None, "prob": prob,
                          "method": "not available for a law: it replaces the restoring force, whose parameters "
                          "this approximation of an effect's size does not sample"}  # fmt: skip
                continue
            value = _size_of(self.model_, e)
            keys = sorted(value) if isinstance(value, dict) else [None]
            if value is None or effects.get(e).law.label is None and not isinstance(value, dict):
                out[e] = {"value": value, "interval": None, "prob": prob, "method": "not available for this effect"}
                continue
            windows, where = self._interval_windows(rec, e)
            length = windows.length
            names = parameter_names(self.model_, False, held=_held(self.terms_))
            mine = [f"{e}.{k}" if k is not None else e for k in keys]
            if len(windows) < 3 or not set(mine) <= set(names):
                out[e] = {"value": value, "interval": None, "prob": prob, "method": "not available for this effect"}
                continue
            theta = values_of(self.model_, names)
            scales = parameter_scales(self.model_, names, float(np.std(self._z0)), float(np.std(self._v0)))
            steps = 1e-3 * np.maximum(np.abs(theta), np.abs(scales))

            def residuals(th: np.ndarray, names=names, windows=windows) -> np.ndarray:
                return self._residuals_at(with_values(self.model_, names, th), rec, windows)

            r0 = residuals(theta)
            J = np.stack([(residuals(theta + np.eye(theta.size)[j] * steps[j]) - r0) / steps[j]
                          for j in range(theta.size)], axis=-1)  # fmt: skip  # (windows, samples, parameters)
            ok = np.isfinite(r0).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
            r0, J = r0[ok], J[ok]
            n_w, p = r0.shape[0], theta.size
            if n_w <= p + 1:
                out[e] = {"value": value, "interval": None, "prob": prob, "method": "too few windows ran"}
                continue
            H = np.einsum("wsi,wsj->ij", J, J)
            g = np.einsum("wsi,ws->wi", J, r0)  # each window's score
            # inverted in the parameters' own scales: in SI units H spans 17 decades (k0 in N against a stop's onset
            # in m and its k in N/m), and pinv's cut-off then drops its least determined direction, the stop's k
            # traded against its onset and the cubic: the interval came out 100x too narrow (measured: k's standard
            # error 0.40 N/m against 49 N/m with the scales, H's condition number 2.8e16 against 7.7e6)
            Hi = scales[:, None] * np.linalg.pinv(scales[:, None] * H * scales[None, :]) * scales[None, :]
            cov_all = Hi @ (g.T @ g) @ Hi * n_w / (n_w - p)
            at = [names.index(n) for n in mine]
            cov = cov_all[np.ix_(at, at)]
            # the mode on these windows by one Gauss-Newton step from the final model (refined on the identification
            # part alone): where the two differ by more than the noise's scatter, the estimate carries an error the
            # noise does not explain (restart states, the form's misfit), so that difference joins the standard
            # error in quadrature and the interval stays centred on the reported value (measured: the mode alone
            # moved friction 1.6 % away from the truth on one record and the stop's k 0.06 % towards it on another)
            mode = (theta - Hi @ g.sum(axis=0))[at]
            theta = theta[at]
            se = np.sqrt(np.maximum(np.diag(cov), 0.0) + (mode - theta) ** 2)
            cov = cov + np.diag((mode - theta) ** 2)
            method = (f"Laplace approximation of the output error over {n_w} restarted windows "
                      f"({length / rec.fs:g} s; {where}), every parameter free, window-robust covariance, the "
                      "difference between the reported value and these windows' mode added in quadrature; "
                      "Posterior does not sample extra effects")  # fmt: skip
            model_value = [float(value[k]) if k is not None else float(value) for k in keys]
            parts = {(k if k is not None else "value"): {"value": m_, "windows_mode": float(t),
                                                         "standard_error": float(s_),
                                                         "interval": [float(m_ - zq * s_), float(m_ + zq * s_)]}
                     for k, t, m_, s_ in zip(keys, mode, model_value, se, strict=True)}  # fmt: skip
            if keys[0] is None:
                out[e] = {**parts["value"], "prob": prob, "method": method}
            else:
                out[e] = {**parts, "prob": prob, "method": method}
            ran = RestartWindows.at(windows.starts[ok], length)
            self.bayesian_[e] = self._bayesian_opinion(rec, e, ran, theta, cov, keys, where)
        return out

    def _bayesian_opinion(self, rec: Measurement, effect: str, windows: RestartWindows, theta: np.ndarray,
                          cov: np.ndarray, keys: list, where: str, draws: int = 64) -> dict[str, Any]:  # fmt: skip
        """A Bayesian second opinion on naming ``effect``: the windows' predictive densities of the final model
        with it (its size drawn from the Laplace approximation) and without it (the rest held), compared by
        ``arviz.compare`` (PSIS-LOO over the windows). Each window's log density is Gaussian in its run's error
        with ``n_eff`` independent samples (the window's length over the errors' integrated autocorrelation
        time) and a noise variance drawn from its scaled inverse chi-square posterior (so that each model's
        draws differ, as LOO needs).
        """
        rng = np.random.default_rng(0)
        length = windows.length
        worst = float(np.mean(windows.measured(rec.displacement) ** 2))

        def window_ms(model: Model) -> tuple[np.ndarray, np.ndarray]:
            r = self._residuals_at(model, rec, windows)
            ms = np.nanmean(r**2, axis=1)
            return np.where(np.isfinite(ms), ms, worst), r

        with_ms = []
        for size in _admissible_sizes(self.model_, effect, keys, rng.multivariate_normal, theta, cov, draws):
            with_ms.append(window_ms(_with_size(self.model_, effect, size))[0])
        ms_with = np.stack(with_ms)  # (draws, windows)
        ms_without, r_without = window_ms(_without(self.model_, effect))
        out = _loo_compare(ms_with, np.repeat(ms_without[None, :], len(ms_with), axis=0),
                           [*self._residuals_at(self.model_, rec, windows), *r_without], length, rng)  # fmt: skip
        out["method"] = (
            f"arviz.compare (PSIS-LOO) over {where} ({length / rec.fs:g} s restarted runs), {draws} "
            "draws of the effect's size from its Laplace approximation and of the noise variance"
        )
        return out

    def _held_out_opinion(self, rec: Measurement, model_before: Model, model_after: Model,
                          draws: int = 64) -> dict[str, Any]:  # fmt: skip
        """A round's Bayesian second opinion: the held-out tail's ``window_s`` restarted runs' predictive
        densities with the effect (``model_after``) and without it (``model_before``), compared by
        ``arviz.compare`` (PSIS-LOO over the windows; the noise variance drawn, the models' parameters held).
        """
        windows = self._tail_windows(rec)  # the tail's gap windows
        if len(windows) < 2:
            return {"windows": len(windows), "error": "too few held-out windows"}
        rb, ra = (self._residuals_at(m, rec, windows) for m in (model_before, model_after))
        worst = float(np.mean(rec.displacement[self.n_id_ :] ** 2))
        ms_b, ms_a = (np.where(np.isfinite(m), m, worst) for m in (np.mean(rb**2, axis=1), np.mean(ra**2, axis=1)))
        rng = np.random.default_rng(0)
        out = _loo_compare(np.repeat(ms_a[None], draws, 0), np.repeat(ms_b[None], draws, 0), [*ra, *rb],
                           windows.length, rng)  # fmt: skip
        out["method"] = (f"arviz.compare (PSIS-LOO) over the held-out tail's {len(windows)} restarted "
                         f"{self.window_s_:g} s runs, {draws} draws of the noise variance")  # fmt: skip
        return out

    def where_text(self) -> str:
        """Where the baseline's equation error concentrates, in words (the result's ``where``)."""
        loc = self.locate_before_
        if not loc["regimes"]:
            return "no regime could be told apart"
        parts = sorted(loc["regimes"].items(), key=lambda kv: -kv[1]["ratio"])
        worst, w = parts[0]
        if w["ratio"] < 1.5:
            return (
                "the baseline's equation error is spread evenly: no regime carries more than 1.5x its share of the "
                f"record (largest: {worst}, {w['ratio']:.1f}x)"
            )

        def where(regime: str) -> str:  # "concentrated at large stroke", "... crossing the barrier"
            return f"at {regime}" if regime == "large stroke" else regime

        txt = (
            f"the baseline's equation error is concentrated {where(worst)} "
            f"({share_text(w['residual_share'])} % of the squared "
            f"residual in {share_text(w['time_share'])} % of the record, {w['ratio']:.1f}x its share)"
        )
        if len(parts) > 1:
            n2, w2 = parts[1]
            txt += f"; next {where(n2)} ({w2['ratio']:.1f}x)"
        return txt

    @override
    def result(self) -> dict[str, Any]:
        if "result_" in vars(self):  # a structure's (N > 1 DOFs)
            return self.result_.to_json()
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
            "model": self.model_.to_dict(),
            "initial_model": self.initial_model_.to_dict(),
            "refinement": self.refinement_,
            "bounded": self.bounded_,
            "warnings": list(self.warnings_),
            "record": self.record_,
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
            "settings": {
                "identification_samples": self.n_id_,
                "window_s": self.window_s_,  # ``window_s``, shortened on a ring-down (``sindy.ring_down_window``)
                "baseline_terms": list(self.baseline),
                "score": "held-out weak residual (rms, % of the target) over samples "
                f"[{self.n_fit_}, {self.n_id_}); named only above max(1 SE, {100 * self.margin:g} %)",
                "gap": f"restarted {self.window_s_:g} s free runs over the held-out tail [{self.n_id_}, end): "
                "the median window's rms error, % of rms(z) (pooled over all windows in gap_pooled_percent; one "
                "window that diverges near the barrier, chaos, can dominate the pool)",
            },
        }
