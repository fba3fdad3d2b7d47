"""What an identification returns: one frozen result per record read (``Identification``), for a device on its base
and for any structure alike, with the contract's JSON (``to_json()``) and back (``from_json``), after
``scipy.integrate.solve_ivp``'s result bunch.

The identified system is a structure of one or more DOFs carrying the element (``system``; the device on its base
is a structure of one DOF), joined to the ground by its linear part (``linear_part``: none, a physical M, C, K, or a
state-space model read through the sensors without masses). Every result answers alike: ``method``, ``system``
(``structure``), ``model``, ``initial_model``, ``element``, ``dofs``, ``element_at``, ``modal``, ``validation`` (a
read-only ``Bunch``: ``validation.rms_percent``), ``refinement`` (None where the model was not refined),
``warnings``, ``settings``, ``summary()`` (one line) and ``to_json()`` / ``from_json``. ``StructureResults`` gives an
estimator the structure's learned attributes under scikit-learn's names.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from negstiff.errors import InputError
from negstiff.models import Model
from negstiff.models.equation import Equilibria
from negstiff.models.state_space import StateSpaceStructure
from negstiff.models.structure import Mode, Structure


class Bunch(dict):
    """A read-only dict whose keys are also attributes (``validation.rms_percent``), as scipy's result
    objects; it is the JSON object it prints as.
    """

    def __getattr__(self, name: str):
        try:
            return self[name]
        except KeyError:
            raise AttributeError(name) from None

    def _readonly(self, *args, **kwargs):
        raise TypeError(f"{type(self).__name__} is read-only")

    __setitem__ = __delitem__ = __setattr__ = update = pop = popitem = clear = setdefault = _readonly

    def __reduce__(self):
        # rebuilt from a plain dict (pickle's default for a dict subclass sets the items one by one,
        # which a read-only dict refuses)
        return (type(self), (dict(self),))

    def __copy__(self) -> Bunch:
        return type(self)(self)

    def __deepcopy__(self, memo) -> Bunch:
        import copy

        return type(self)(copy.deepcopy(dict(self), memo))

    def __repr__(self) -> str:
        keys = ", ".join(k for k in self if not isinstance(self[k], np.ndarray))
        return f"{type(self).__name__}({keys})"


def _plain(d: Mapping[str, Any] | None) -> Bunch | None:
    return None if d is None else Bunch(d)


LINEAR_PARTS = ("none", "physical", "state_space")
"""What joins an identified element to the ground, an ``Identification``'s ``linear_part``: ``"none"``, the device on
its base (a structure of one DOF, ``Structure.single``); ``"physical"``, a structure's masses, springs and dampers (M,
C, K); ``"state_space"``, a linear model of the order the record shows, read through the sensors without masses
(``StateSpaceStructure``). The contract's JSON of each is its own (``docs/contract.md``)."""


@dataclass(frozen=True, repr=False)
class Identification:
    """An identification's result for any structure (``NSI().fit(rec).result_``, ``SINDy(element="1-2").fit(rec)``'s,
    ``Discrepancy``'s), frozen: the identified system, its modes, how it predicts the held-out record, its warnings.

    The system is a structure of one or more DOFs carrying the element (``system``), joined to the ground by its
    ``linear_part`` (``LINEAR_PARTS``); the fields a linear part does not give stay empty. ``to_json()`` is the
    contract's identify JSON of that linear part, the one the command line writes, and ``from_json`` reads it back.

    Attributes
    ----------
    method : {"nsi", "sindy", "discrepancy"}
        The method.
    system : Structure or StateSpaceStructure
        The identified system (the final one: output-error refined where that predicted the held-out tail no worse).
    modal : dict
        Each well's underlying-linear modes: ``{well: {"f_hz", "zeta"}}`` for the device on its base, ``{well:
        [Mode, ...]}`` by frequency for a structure (``{"linear": [...]}`` for a state-space linear part); empty for
        the discrepancy workflow on the device (it names effects; its JSON gives no modes).
    validation : Bunch
        Free runs over the held-out tail (``rms_percent``, ``restarted_rms_percent``, ...; the discrepancy workflow on
        the device its gap, restarted windows only: ``median_window_percent``, ``workflow_validation``).
    warnings : tuple of str
        Every warning about the record and the result (also issued as ``NegstiffWarning``).
    details, settings : dict
        The method's own keys and its settings.
    refinement : Bunch or None
        The output-error stage's account (None where the model was not refined).
    linear_part : {"none", "physical", "state_space"}
        What joins the element to the ground (``LINEAR_PARTS``).
    initial_system : Structure or None
        The method's own estimate (equation error), what method-vs-method checks compare; None: as the refinement's
        account holds it (``initial_model``).
    equilibria : Equilibria, dict or None
        The device's equilibria (``Equilibria``), or every DOF's static position per well of a structure.
    offsets_m : tuple of float
        Each channel's zero found (measured = physical + offset) [m]; empty where the frame is pinned otherwise.
    linear : dict
        A structure's underlying-linear K and C at each well and its own.
    bounded : Bunch
        Boundedness of the device's final model (``ok``, ``over_stroke``, ``globally``, ...).
    stroke_quantiles_m : numpy.ndarray
        Where the identification part of the record went (``update`` compares there).
    identification_samples : int
        The split: samples [0, n) identify, [n, N) are held out.
    mass_source, mass_normalised, input_gain : str, bool, float
        The device's mass and where it came from.
    record : dict
        How the record was read (time base, sensor, what was derived, units).
    element_estimate, stabilisation, frf : dict, list, dict
        A state-space linear part's element coefficients with their standard errors, its stabilisation diagram and
        its underlying-linear FRF against the measured one.

    Examples
    --------
    >>> from negstiff import Measurement, NSI, Rig
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> res = NSI().fit(Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=1).random(duration=30.0, rms=20.0))).result_
    >>> res.method, res.linear_part, res.dofs, res.validation.rms_percent < 5.0
    ('nsi', 'none', 1, True)
    >>> {"model", "modal", "validation", "warnings"} <= set(res.to_json())
    True
    """

    method: str
    system: Structure | StateSpaceStructure
    modal: Mapping[str, Any]
    validation: Bunch
    warnings: tuple[str, ...]
    details: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    refinement: Bunch | None = None
    linear_part: str = "none"
    initial_system: Structure | None = None
    equilibria: Any = None
    offsets_m: tuple[float, ...] = ()
    linear: Mapping[str, Any] = field(default_factory=dict)
    bounded: Bunch = field(default_factory=Bunch)
    stroke_quantiles_m: np.ndarray = field(default_factory=lambda: np.empty(0))
    identification_samples: int = 0
    mass_source: str = ""
    mass_normalised: bool = False
    input_gain: float = 1.0
    record: Mapping[str, Any] = field(default_factory=dict)
    element_estimate: Mapping[str, Any] = field(default_factory=dict)
    stabilisation: list[dict[str, Any]] = field(default_factory=list)
    frf: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if self.linear_part not in LINEAR_PARTS:
            raise InputError(f"Identification(linear_part={self.linear_part!r}): one of {', '.join(LINEAR_PARTS)}")

    @property
    def structure(self) -> Structure | StateSpaceStructure:
        """The identified system (``system``): for the device on its base a structure of one DOF."""
        return self.system

    @property
    def model(self) -> Any:
        """The contract's ``model``: the element's law (a ``Model``; the device's whole model on its base), or the
        state-space model itself (``StateSpaceStructure``) where the linear part is one.
        """
        return self.system if isinstance(self.system, StateSpaceStructure) else self.system.element

    @property
    def initial_model(self) -> Any:
        """The element's law before the output-error refinement (the method's own estimate)."""
        if self.initial_system is not None:
            return self.initial_system.element
        if self.refinement is None or "initial_model" not in self.refinement:
            return self.model
        return Structure.from_dict(self.refinement["initial_model"]).element

    @property
    def element(self) -> dict[str, Any]:
        """The element's coefficients: k0, k1, k2, k3, c, c_nl of its law (with their standard errors where a
        state-space linear part's extended FRF gives them).
        """
        if self.element_estimate:
            return dict(self.element_estimate)
        law = self.system.element  # type: ignore[union-attr]
        return {k: float(getattr(law, k)) for k in ("k0", "k1", "k2", "k3", "c", "c_nl")}

    @property
    def dofs(self) -> int:
        """The structure's DOFs (its sensors, for a state-space linear part)."""
        s = self.system
        return s.n_sensors if isinstance(s, StateSpaceStructure) else s.n_dof

    @property
    def element_at(self) -> tuple[int, int]:
        """Where the element acts: (I, J), I = 0 the base."""
        s = self.system
        return tuple(s.at) if isinstance(s, StateSpaceStructure) else s.place  # type: ignore[return-value]

    @property
    def layout(self) -> str:
        """Which of the contract's JSON layouts ``to_json()`` writes: the linear part's (``LINEAR_PARTS``), or
        ``"workflow"``: the discrepancy workflow's on the device on its base (its effects, rankings and gaps, the
        command's own JSON; a structure's workflow writes the structure's layout, its account in ``details``).
        """
        return "workflow" if self.method == "discrepancy" and self.linear_part == "none" else self.linear_part

    def to_json(self) -> dict[str, Any]:
        """The contract's JSON of the result's ``layout`` (``negstiff identify`` and ``negstiff discrepancy`` write
        exactly this).
        """
        return _WRITERS[self.layout](self)

    @classmethod
    def from_json(cls, data) -> Identification:
        """The identification an identify result JSON holds (``to_json()``, its text or a file path), its linear part
        read from its keys. The JSON is the contract's: what it does not hold (the validation's per-window arrays)
        is not rebuilt, so ``Identification.from_json(r.to_json()).to_json() == r.to_json()``.
        """
        from negstiff.inference.estimators.persistence import json_source

        d = json_source(data, "identify result JSON")
        if d.get("linear_part") == "state_space":
            return _state_space_from_json(d)
        if "structure" in d and "dofs" in d:
            return _physical_from_json(d)
        if "effects" in d and "gap_after_percent" in d:
            return _workflow_from_json(d)
        return _device_from_json(d)

    def summary(self) -> str:
        """One line: the element's top stiffness coefficient, the modes, the held-out error."""
        return _SUMMARIES[self.layout](self)

    def __repr__(self) -> str:
        v = self.validation.get("median_window_percent", self.validation.get("rms_percent"))
        best = self.validation.get("best_linear_rms_percent")
        against = "" if best is None else f", the best linear model of its order {best:.3g} %"
        return (f"Identification({self.method}, {self.linear_part} linear part: {self.summary()}; held-out "
                f"{'n/a' if v is None else f'{v:.3g} %'}{against}; {len(self.warnings)} warning(s))")  # fmt: skip


def _device_json(r: Identification) -> dict[str, Any]:
    """The device on its base: its model's fields, the equilibria z-, z0, z+, each well's f and zeta."""
    eq = r.equilibria.as_dict() if r.equilibria is not None else {"z_minus": None, "z_0": None, "z_plus": None}
    return {
        "method": r.method,
        "mass_source": r.mass_source,
        "input_gain": r.input_gain,
        "model": r.model.to_dict(),
        "initial_model": r.initial_model.to_dict(),
        "stroke_quantiles_m": np.asarray(r.stroke_quantiles_m).tolist(),
        "refinement": None if r.refinement is None else dict(r.refinement),
        "bounded": dict(r.bounded),
        "warnings": list(r.warnings),
        "mass_normalised": r.mass_normalised,
        "equilibria": eq,
        "modal": {w: dict(m) for w, m in r.modal.items()},
        "validation": {k: v for k, v in r.validation.items() if not isinstance(v, np.ndarray)},
        **dict(r.details),
        "settings": dict(r.settings),
        "record": dict(r.record),
    }


def _physical_json(r: Identification) -> dict[str, Any]:
    """A structure with its masses (``identify --dofs N``): the structure, its element, modes per well, zeros."""
    s = r.system
    assert isinstance(s, Structure)
    return {
        "method": r.method,
        "dofs": s.n_dof,
        "element_at": list(s.place),
        "structure": s.to_dict(),
        "element": {**r.element, "extra": dict(s.element.extra)},
        "modal": {w: [m.to_json() for m in ms] for w, ms in r.modal.items()},
        "linear": dict(r.linear),
        "equilibria": r.equilibria,
        "offsets_m": list(r.offsets_m),
        "validation": dict(r.validation),
        "warnings": list(r.warnings),
        "details": dict(r.details),
        "settings": dict(r.settings),
        "refinement": None if r.refinement is None else dict(r.refinement),
    }


def _state_space_json(r: Identification) -> dict[str, Any]:
    """A structure read through its sensors (``linear_part: "state_space"``)."""
    s = r.system
    assert isinstance(s, StateSpaceStructure)
    return {
        "method": r.method,
        "linear_part": "state_space",
        "dofs": s.n_sensors,
        "element_at": list(s.at),
        "order": s.order,
        "modal": {w: [m.to_json() for m in ms] for w, ms in r.modal.items()},
        "element": dict(r.element_estimate),
        "validation": dict(r.validation),
        "frf": dict(r.frf),
        "stabilisation": list(r.stabilisation),
        "model": s.to_dict(),
        "warnings": list(r.warnings),
        "settings": dict(r.settings),
    }


_WORKFLOW_HEAD = ("effect", "effects", "ranking", "gap_before_percent", "gap_after_percent", "gap_pooled_percent",
                  "gap_median_window_um", "where", "gap_regime_percent", "predictability", "regimes_before",
                  "regimes_after")  # fmt: skip
"""The discrepancy workflow's own keys its JSON writes first (what it named and the gap), as the contract lists
them; its other own keys follow the final model's."""


def _workflow_json(r: Identification) -> dict[str, Any]:
    """The discrepancy workflow on the device (``layout`` ``"workflow"``): what it named and the held-out gap, the
    final model, then the rest of its account (``details``: the baseline, the rankings, the effects' sizes).
    """
    own = dict(r.details)
    head = {k: own.pop(k) for k in _WORKFLOW_HEAD if k in own}
    return {
        **head,
        "model": r.model.to_dict(),
        "initial_model": r.initial_model.to_dict(),
        "refinement": None if r.refinement is None else dict(r.refinement),
        "bounded": dict(r.bounded),
        "warnings": list(r.warnings),
        "record": dict(r.record),
        **own,
        "settings": dict(r.settings),
    }


def workflow_validation(account: Mapping[str, Any]) -> Bunch:
    """The held-out validation of the discrepancy workflow's final model from its account (``details``): its gap,
    restarted free runs over the held-out tail (the median window's and the pooled rms error, % of rms z; the median
    window's in um), the baseline's beside it.
    """
    pooled = account.get("gap_pooled_percent") or {}
    um = account.get("gap_median_window_um") or {}
    return Bunch({"median_window_percent": account.get("gap_after_percent"),
                  "restarted_rms_percent": pooled.get("after"), "median_window_rms_um": um.get("after"),
                  "baseline_median_window_percent": account.get("gap_before_percent")})  # fmt: skip


_WRITERS = {"none": _device_json, "physical": _physical_json, "state_space": _state_space_json,
            "workflow": _workflow_json}  # fmt: skip


def _modes(modal: Mapping[str, Any]) -> dict[str, list[Mode]]:
    return {w: [Mode(float(m["f_hz"]), float(m["zeta"]), tuple(float(x) for x in m["shape"])) for m in ms]
            for w, ms in modal.items()}  # fmt: skip


def _device_from_json(d: dict[str, Any]) -> Identification:
    d = dict(d)
    d.pop("estimator", None)
    eq = d.pop("equilibria", None) or {}
    known = {"method", "mass_source", "input_gain", "model", "initial_model", "stroke_quantiles_m",
             "refinement", "bounded", "warnings", "mass_normalised", "modal", "validation", "settings",
             "record"}  # fmt: skip
    try:
        settings = dict(d.get("settings") or {})
        return Identification(
            method=d["method"],
            system=Structure.single(Model.from_dict(d["model"])),
            initial_system=Structure.single(Model.from_dict(d.get("initial_model") or d["model"])),
            linear_part="none",
            equilibria=None
            if eq.get("z_plus") is None and eq.get("z_minus") is None
            else Equilibria(eq.get("z_minus"), eq.get("z_0"), eq.get("z_plus")),  # type: ignore[arg-type]
            modal={w: dict(m) for w, m in d["modal"].items()},
            validation=Bunch(d.get("validation") or {}),
            refinement=_plain(d.get("refinement")),
            bounded=Bunch(d.get("bounded") or {}),
            stroke_quantiles_m=np.asarray(d.get("stroke_quantiles_m") or [], float),
            identification_samples=int(settings.get("identification_samples", 0)),
            mass_source=d.get("mass_source", ""),
            mass_normalised=bool(d.get("mass_normalised", False)),
            input_gain=float(d.get("input_gain", 1.0)),
            record=dict(d.get("record") or {}),
            warnings=tuple(d.get("warnings") or ()),
            details={k: v for k, v in d.items() if k not in known},
            settings=settings,
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not an identify result JSON: {type(exc).__name__} {exc}") from None


def _workflow_from_json(d: dict[str, Any]) -> Identification:
    """The discrepancy workflow's JSON on the device (``_workflow_json``)."""
    d = dict(d)
    d.pop("estimator", None)
    kept = ("model", "initial_model", "refinement", "bounded", "warnings", "record", "settings")
    details = {k: v for k, v in d.items() if k not in kept}
    try:
        settings = dict(d.get("settings") or {})
        return Identification(
            method="discrepancy", system=Structure.single(Model.from_dict(d["model"])),
            initial_system=Structure.single(Model.from_dict(d.get("initial_model") or d["model"])), linear_part="none",
            modal={}, validation=workflow_validation(details), refinement=_plain(d.get("refinement")),
            bounded=Bunch(d.get("bounded") or {}), warnings=tuple(d.get("warnings") or ()),
            record=dict(d.get("record") or {}), details=details, settings=settings,
            identification_samples=int(settings.get("identification_samples", 0)),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not a discrepancy result JSON: {type(exc).__name__} {exc}") from None


def _physical_from_json(d: dict[str, Any]) -> Identification:
    """A structure's identify result JSON (the ``element`` key is the structure's element, read from ``structure``)."""
    try:
        settings = dict(d.get("settings") or {})
        return Identification(
            method=d["method"], system=Structure.from_dict(d["structure"]), modal=_modes(d["modal"]),
            linear_part="physical", linear=dict(d.get("linear") or {}),
            equilibria={w: list(z) for w, z in (d.get("equilibria") or {}).items()},
            offsets_m=tuple(float(x) for x in d["offsets_m"]), validation=Bunch(d.get("validation") or {}),
            warnings=tuple(d.get("warnings") or ()), details=dict(d.get("details") or {}), settings=settings,
            identification_samples=int(settings.get("identification_samples", 0)),
            refinement=None if d.get("refinement") is None else Bunch(d["refinement"]),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not a structure's identify result JSON: {type(exc).__name__} {exc}") from None


def _state_space_from_json(d: dict[str, Any]) -> Identification:
    try:
        return Identification(
            method=d["method"], system=StateSpaceStructure.from_dict(d["model"]), modal=_modes(d["modal"]),
            linear_part="state_space", element_estimate=dict(d["element"]), validation=Bunch(d["validation"]),
            stabilisation=list(d["stabilisation"]), frf=dict(d["frf"]), warnings=tuple(d.get("warnings") or ()),
            settings=dict(d.get("settings") or {}),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"not a state-space identify result JSON: {type(exc).__name__} {exc}") from None


def _device_summary(r: Identification) -> str:
    """k3, the wells' frequencies and the held-out median window's error (with its quartiles)."""
    wells = ", ".join(f"{w} {m['f_hz']:.4g} Hz" for w, m in r.modal.items() if m.get("f_hz"))
    v = r.validation.get("median_window_percent", r.validation.get("rms_percent", math.nan))
    q = r.validation.get("window_percent_quartiles")
    spread = f" (quartiles {q[0]:.3g}-{q[1]:.3g} %)" if q else ""
    return f"k3={r.model.k3:.4g}, wells {wells or 'none'}, held-out median window {v:.3g} %{spread}"


def _physical_summary(r: Identification) -> str:
    """The element's k3 and each well's modes."""
    return f"{r.dofs} DOFs, element k3={r.model.k3:.4g}; {modes_summary(r.modal)}"


def _state_space_summary(r: Identification) -> str:
    """The sensors, the order, the element's top stiffness coefficient and the modes."""
    top = max((k for k in r.element_estimate if k[:1] == "k" and k[1:].isdigit()), key=lambda k: int(k[1:]))
    k3 = r.element_estimate[top]
    modes = "; ".join(f"{m.f_hz:.3f} Hz {100 * m.zeta:.2f} %" for m in r.modal["linear"])
    s = r.system
    assert isinstance(s, StateSpaceStructure)
    return f"{s.n_sensors} sensors, order {s.order}, element {top}={k3['value']:.4g} +- {k3['se']:.2g}; {modes}"


def _workflow_summary(r: Identification) -> str:
    """The effects named and the held-out gap before and after them."""
    before, after = r.details.get("gap_before_percent"), r.details.get("gap_after_percent")
    gap = "" if before is None or after is None else f"; held-out gap {before:.3g} -> {after:.3g} % (median window)"
    return f"effects: {', '.join(r.details.get('effects') or ['none'])}{gap}"


_SUMMARIES = {"none": _device_summary, "physical": _physical_summary, "state_space": _state_space_summary,
              "workflow": _workflow_summary}  # fmt: skip


class StructureResults:
    """What an estimator learned on a record of N > 1 DOFs, under scikit-learn's names (mixed into ``NSI``,
    ``SINDy`` and ``Discrepancy``): ``structure_``, ``element_``, ``linear_``, ``offsets_``.
    """

    result_: Any

    def _learned(self, name: str) -> Any:
        r = self.result_
        if getattr(r, "linear_part", None) == "none":
            # the device on its base learned its model (``model_``; ``result_.structure`` is it as a structure of one
            # DOF): these attributes name what a structure's fit learned beside its element
            raise AttributeError(f"{type(self).__name__}: a fit of the device on its base has no {name}")
        return getattr(r, name)

    structure_ = property(lambda self: self._learned("structure"))
    element_ = property(lambda self: self._learned("element"))
    linear_ = property(lambda self: self._learned("linear"))
    offsets_ = property(lambda self: self._learned("offsets_m"))

    def _restore(self, result: dict[str, Any]) -> None:
        """A result JSON rebuilt as its ``Identification`` (``from_json``, the linear part read from its keys); a
        single DOF's fit keeps its method's own state too (the estimator's own ``_restore``).
        """
        if "structure" in result and "dofs" in result or result.get("linear_part") == "state_space":
            self.result_ = Identification.from_json(result)
            if not isinstance(getattr(type(self), "model_", None), property):  # Discrepancy's own attribute
                self.model_ = self.result_.model
            return
        if "effects" in result and "gap_after_percent" in result:  # the discrepancy workflow's on the device
            self.result_ = Identification.from_json(result)
        super()._restore(result)  # type: ignore[misc]

    def _summary(self) -> str:
        r = vars(self).get("result_")  # a JSON rebuilt as its estimator need not have one (NSI's, SINDy's)
        if r is not None:
            return r.summary()
        return super()._summary()  # type: ignore[misc]


def modes_summary(modal: Mapping[str, list[Mode]]) -> str:
    """One line of each well's modes (frequency, damping ratio)."""
    return "; ".join(
        f"{w}: " + ", ".join(f"{m.f_hz:.3f} Hz {100 * m.zeta:.2f} %" for m in ms) for w, ms in modal.items()
    )
