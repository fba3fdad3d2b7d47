"""The discrepancy workflow's candidates: the catalogue of effects and the laws offered beside it, a candidate's
terms, its size in a model (set, drawn, removed), and the rule that names a measured channel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, override

import numpy as np

from negstiff.errors import InputError, MeasurementError
from negstiff.inference.estimators.parameters import Constraint, Options, Several
from negstiff.inference.steps.weak import BASE_FIELDS, term_fields
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
