"""What an identification returns: one frozen result per record read, with the contract's JSON (``to_json()``) and
back (``from_json``), after ``scipy.integrate.solve_ivp``'s result bunch.

- ``Identification``: a single DOF's (``NSI().fit(rec).result_``, ``SINDy().fit(rec).result_``), the model of the
  restoring force and damping, refined, with its validation, boundedness and warnings;
- ``StructureIdentification``: a structure's with its masses (``element="I-J"`` on a record of N > 1 DOFs), the
  structure with its element in the physical frame and each channel's zero;
- ``StateSpaceIdentification``: a structure read through its sensors without masses (NSI's state-space linear
  part, ``nsi._state_space``).

Every result answers alike: ``method``, ``modal``, ``validation`` (a read-only ``Bunch``: ``validation.rms_percent``),
``refinement`` (None where the model was not refined), ``warnings``, ``settings``, ``summary()`` (one line) and
``to_json()`` / ``from_json``. ``StructureResults`` gives an estimator the structure's learned attributes under
scikit-learn's names.
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


@dataclass(frozen=True, repr=False)
class Identification:
    """An identification's result (``NSI().fit(rec).result_``, ``SINDy().fit(rec).result_``), frozen.

    ``to_json()`` is the contract's identify JSON, the one the command line writes.

    Attributes
    ----------
    method : {"nsi", "sindy"}
        The method.
    model : Model
        The final model (output-error refined where that predicted the held-out tail no worse).
    initial_model : Model
        The method's own estimate (equation error): what method-vs-method checks compare.
    equilibria : Equilibria or None
        The final model's equilibria (None when its restoring force has none usable).
    modal : dict
        ``{"minus", "plus"}`` -> ``{"f_hz", "zeta"}`` of each well's underlying-linear system.
    validation : Bunch
        Free run over the held-out tail (``rms_percent``, ``restarted_rms_percent``, ...).
    refinement : Bunch or None
        The output-error stage's account (None with ``refine=False``).
    bounded : Bunch
        Boundedness of the final model (``ok``, ``over_stroke``, ``globally``, ...).
    stroke_quantiles_m : numpy.ndarray
        Where the identification part of the record went (``update`` compares there).
    identification_samples : int
        The split: samples [0, n) identify, [n, N) are held out.
    mass_source, mass_normalised, input_gain : str, bool, float
        The mass and where it came from.
    record : dict
        How the record was read (time base, sensor, what was derived, units).
    warnings : tuple of str
        Every warning about the record and the result (also issued as ``NegstiffWarning``).
    details, settings : dict
        The method's own keys and its settings.

    Examples
    --------
    >>> from negstiff import Measurement, NSI, Rig
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> res = NSI().fit(Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=1).random(duration=30.0, rms=20.0))).result_
    >>> res.method, res.validation.rms_percent < 5.0
    ('nsi', True)
    >>> {"model", "modal", "validation", "warnings"} <= set(res.to_json())
    True
    """

    method: str
    model: Model
    initial_model: Model
    equilibria: Equilibria | None
    modal: Mapping[str, Mapping[str, float | None]]
    validation: Bunch
    refinement: Bunch | None
    bounded: Bunch
    stroke_quantiles_m: np.ndarray
    identification_samples: int
    mass_source: str
    mass_normalised: bool
    input_gain: float
    record: Mapping[str, Any]
    warnings: tuple[str, ...]
    details: Mapping[str, Any]
    settings: Mapping[str, Any]

    def to_json(self) -> dict[str, Any]:
        """The contract's identify JSON (``negstiff identify`` writes exactly this)."""
        eq = (
            self.equilibria.as_dict() if self.equilibria is not None else {"z_minus": None, "z_0": None, "z_plus": None}
        )
        return {
            "method": self.method,
            "mass_source": self.mass_source,
            "input_gain": self.input_gain,
            "model": self.model.to_dict(),
            "initial_model": self.initial_model.to_dict(),
            "stroke_quantiles_m": np.asarray(self.stroke_quantiles_m).tolist(),
            "refinement": None if self.refinement is None else dict(self.refinement),
            "bounded": dict(self.bounded),
            "warnings": list(self.warnings),
            "mass_normalised": self.mass_normalised,
            "equilibria": eq,
            "modal": {w: dict(m) for w, m in self.modal.items()},
            "validation": {k: v for k, v in self.validation.items() if not isinstance(v, np.ndarray)},
            **dict(self.details),
            "settings": dict(self.settings),
            "record": dict(self.record),
        }

    @classmethod
    def from_json(cls, data) -> Identification:
        """The identification an identify result JSON holds (``to_json()``, its text or a file path). The
        JSON is the contract's: what it does not hold (the validation's per-window arrays) is not rebuilt, so
        ``Identification.from_json(r.to_json()).to_json() == r.to_json()``.
        """
        from negstiff.inference.estimators.persistence import json_source

        d = json_source(data, "identify result JSON")
        d.pop("estimator", None)
        eq = d.pop("equilibria", None) or {}
        known = {"method", "mass_source", "input_gain", "model", "initial_model", "stroke_quantiles_m",
                 "refinement", "bounded", "warnings", "mass_normalised", "modal", "validation", "settings",
                 "record"}  # fmt: skip
        try:
            settings = dict(d.get("settings") or {})
            return cls(
                method=d["method"],
                model=Model.from_dict(d["model"]),
                initial_model=Model.from_dict(d.get("initial_model") or d["model"]),
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

    def summary(self) -> str:
        """One line: k3, the wells' frequencies and the held-out median window's error (with its quartiles)."""
        wells = ", ".join(f"{w} {m['f_hz']:.4g} Hz" for w, m in self.modal.items() if m.get("f_hz"))
        v = self.validation.get("median_window_percent", self.validation.get("rms_percent", math.nan))
        q = self.validation.get("window_percent_quartiles")
        spread = f" (quartiles {q[0]:.3g}-{q[1]:.3g} %)" if q else ""
        return f"k3={self.model.k3:.4g}, wells {wells or 'none'}, held-out median window {v:.3g} %{spread}"

    def __repr__(self) -> str:
        wells = ", ".join(
            f"{w} {m['f_hz']:.4g} Hz / {100 * (m['zeta'] or 0.0):.3g} %" for w, m in self.modal.items() if m.get("f_hz")
        )
        v = self.validation.get("median_window_percent", self.validation.get("rms_percent"))
        return (
            f"Identification({self.method}: k1={self.model.k1:.4g}, k2={self.model.k2:.4g}, k3={self.model.k3:.4g}, "
            f"c={self.model.c:.4g}, c_nl={self.model.c_nl:.4g}; wells {wells or 'none'}; held-out median window "
            f"{'n/a' if v is None else f'{v:.3g} %'}; {len(self.warnings)} warning(s))"
        )


@dataclass(frozen=True, repr=False)
class StateSpaceIdentification:
    """NSI's result on a structure read through its sensors (``NSI(element="I-J").fit(rec)`` on a record of
    N > 1 sensors without masses); ``to_json()`` is the contract's JSON (``linear_part: "state_space"``).

    Attributes
    ----------
    model : StateSpaceStructure
    modal : dict
        ``{"linear": [Mode, ...]}``: the underlying-linear modes the stabilisation diagram holds, shapes over the
        sensors.
    element : dict
        Each basis coefficient about r* (``k2_tilde``, ``k3``, ``c_nl``), its standard error and quality.
    validation : Bunch
        The held-out windows' error of the model and of its linear part alone.
    """

    method: str
    model: StateSpaceStructure
    modal: dict[str, list[Mode]]
    element: dict[str, Any]
    validation: Bunch
    stabilisation: list[dict[str, Any]]
    frf: dict[str, Any]
    warnings: tuple[str, ...]
    settings: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        """The contract's JSON of ``identify`` on a structure read through its sensors."""
        return {
            "method": self.method,
            "linear_part": "state_space",
            "dofs": self.model.n_sensors,
            "element_at": list(self.model.at),
            "order": self.model.order,
            "modal": {w: [m.to_json() for m in ms] for w, ms in self.modal.items()},
            "element": self.element,
            "validation": dict(self.validation),
            "frf": self.frf,
            "stabilisation": self.stabilisation,
            "model": self.model.to_dict(),
            "warnings": list(self.warnings),
            "settings": self.settings,
        }

    @classmethod
    def from_json(cls, data) -> StateSpaceIdentification:
        """The identification a result JSON holds (``to_json()``, its text or a file path)."""
        from negstiff.inference.estimators.persistence import json_source

        d = json_source(data, "state-space identify result JSON")
        try:
            modal = {w: [Mode(float(m["f_hz"]), float(m["zeta"]), tuple(float(x) for x in m["shape"])) for m in ms]
                     for w, ms in d["modal"].items()}  # fmt: skip
            return cls(d["method"], StateSpaceStructure.from_dict(d["model"]), modal, dict(d["element"]),
                       Bunch(d["validation"]), list(d["stabilisation"]), dict(d["frf"]), tuple(d.get("warnings") or ()),
                       dict(d.get("settings") or {}))  # fmt: skip
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"not a state-space identify result JSON: {type(exc).__name__} {exc}") from None

    @property
    def refinement(self) -> None:
        """None: a state-space linear part is not refined by output error (its held-out windows judge it)."""
        return None

    def summary(self) -> str:
        """One line: the sensors, the order, the element's top stiffness coefficient and the modes."""
        top = max((k for k in self.element if k[:1] == "k" and k[1:].isdigit()), key=lambda k: int(k[1:]))
        k3 = self.element[top]
        modes = "; ".join(f"{m.f_hz:.3f} Hz {100 * m.zeta:.2f} %" for m in self.modal["linear"])
        m = self.model
        return f"{m.n_sensors} sensors, order {m.order}, element {top}={k3['value']:.4g} +- {k3['se']:.2g}; {modes}"

    def __repr__(self) -> str:
        v = self.validation
        best = v.get("best_linear_rms_percent")
        against = "" if best is None else f", the best linear model of its order {best:.3g} %"
        return f"StateSpaceIdentification({self.summary()}; held-out {v['rms_percent']:.3g} %{against})"


@dataclass(frozen=True, repr=False)
class StructureIdentification:
    """A structure's identification (``NSI(element="1-2").fit(rec).result_`` on a record of N > 1 DOFs), frozen;
    ``to_json()`` is the contract's ``identify --dofs N`` JSON.

    Attributes
    ----------
    method : {"nsi", "sindy", "discrepancy"}
    structure : Structure
        The identified structure in the physical frame (the element's constant pinned, each channel's zero off).
    modal : dict
        ``{well: [Mode, ...]}``: each well's underlying-linear modes by frequency.
    linear, equilibria : dict
        The underlying-linear K and C at each well and the structure's own; every DOF's static position per well.
    offsets_m : tuple of float
        Each channel's zero found (measured = physical + offset) [m].
    validation : Bunch
        Restarted free runs over the held-out tail (``free_run_error``) and the noise floor.
    warnings : tuple of str
    details, settings : dict
    """

    method: str
    structure: Structure
    modal: dict[str, list[Mode]]
    linear: dict[str, Any]
    equilibria: dict[str, list[float]]
    offsets_m: tuple[float, ...]
    validation: Bunch
    warnings: tuple[str, ...]
    details: dict[str, Any] = field(default_factory=dict)
    settings: dict[str, Any] = field(default_factory=dict)
    refinement: Bunch | None = None
    """The output-error stage's account (``refine.refine_stage``; None with ``refine=False``)."""

    @property
    def model(self) -> Model:
        """The element's law (a ``Model`` of the DOF it moves)."""
        return self.structure.element

    @property
    def initial_model(self) -> Model:
        """The element's law before the output-error refinement (the method's own estimate)."""
        if self.refinement is None:
            return self.model
        return Structure.from_dict(self.refinement["initial_model"]).element

    @property
    def element(self) -> dict[str, float]:
        """The element's k0, k1, k2, k3, c, c_nl."""
        return {k: float(getattr(self.structure.element, k)) for k in ("k0", "k1", "k2", "k3", "c", "c_nl")}

    def to_json(self) -> dict[str, Any]:
        """The contract's ``identify --dofs N`` JSON."""
        return {
            "method": self.method,
            "dofs": self.structure.n_dof,
            "element_at": list(self.structure.place),
            "structure": self.structure.to_dict(),
            "element": {**self.element, "extra": dict(self.structure.element.extra)},
            "modal": {w: [m.to_json() for m in ms] for w, ms in self.modal.items()},
            "linear": self.linear,
            "equilibria": self.equilibria,
            "offsets_m": list(self.offsets_m),
            "validation": dict(self.validation),
            "warnings": list(self.warnings),
            "details": self.details,
            "settings": self.settings,
            "refinement": None if self.refinement is None else dict(self.refinement),
        }

    @classmethod
    def from_json(cls, data) -> StructureIdentification:
        """The identification a structure's identify result JSON holds (``to_json()``, its text or a file path):
        ``StructureIdentification.from_json(r.to_json()).to_json() == r.to_json()`` (the ``element`` key is the
        structure's element, read from ``structure``).
        """
        from negstiff.inference.estimators.persistence import json_source

        d = json_source(data, "structure identify result JSON")
        try:
            structure = Structure.from_dict(d["structure"])
            modal = {w: [Mode(float(m["f_hz"]), float(m["zeta"]), tuple(float(x) for x in m["shape"])) for m in ms]
                     for w, ms in d["modal"].items()}  # fmt: skip
            return cls(
                method=d["method"], structure=structure, modal=modal, linear=dict(d.get("linear") or {}),
                equilibria={w: list(z) for w, z in (d.get("equilibria") or {}).items()},
                offsets_m=tuple(float(x) for x in d["offsets_m"]), validation=Bunch(d.get("validation") or {}),
                warnings=tuple(d.get("warnings") or ()), details=dict(d.get("details") or {}),
                settings=dict(d.get("settings") or {}),
                refinement=None if d.get("refinement") is None else Bunch(d["refinement"]),
            )  # fmt: skip
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"not a structure's identify result JSON: {type(exc).__name__} {exc}") from None

    def summary(self) -> str:
        """One line: the element's k3 and each well's modes."""
        return f"{self.structure.n_dof} DOFs, element k3={self.structure.element.k3:.4g}; {modes_summary(self.modal)}"

    def __repr__(self) -> str:
        v = self.validation.get("rms_percent", math.nan)
        return (f"StructureIdentification({self.method}: {self.summary()}; held-out {v:.3g} %; "
                f"{len(self.warnings)} warning(s))")  # fmt: skip


class StructureResults:
    """What an estimator learned on a record of N > 1 DOFs, under scikit-learn's names (mixed into ``NSI``,
    ``SINDy`` and ``Discrepancy``): ``structure_``, ``element_``, ``linear_``, ``offsets_``.
    """

    result_: Any

    structure_ = property(lambda self: self.result_.structure)
    element_ = property(lambda self: self.result_.element)
    linear_ = property(lambda self: self.result_.linear)
    offsets_ = property(lambda self: self.result_.offsets_m)

    def _restore(self, result: dict[str, Any]) -> None:
        """A structure's result JSON (``"structure"`` and ``"dofs"`` in it) rebuilt as its
        ``StructureIdentification`` (``from_json``); a single DOF's by the estimator's own ``_restore``.
        """
        if result.get("linear_part") == "state_space":
            self.result_ = StateSpaceIdentification.from_json(result)
            return
        if "structure" in result and "dofs" in result:
            self.result_ = StructureIdentification.from_json(result)
            if not isinstance(getattr(type(self), "model_", None), property):  # Discrepancy's own attribute
                self.model_ = self.result_.model
            return
        super()._restore(result)  # type: ignore[misc]

    def _summary(self) -> str:
        r = vars(self).get("result_")  # a single DOF's fit need not have one (Discrepancy's)
        if r is not None:
            return r.summary()
        return super()._summary()  # type: ignore[misc]


def modes_summary(modal: dict[str, list[Mode]]) -> str:
    """One line of each well's modes (frequency, damping ratio)."""
    return "; ".join(
        f"{w}: " + ", ".join(f"{m.f_hz:.3f} Hz {100 * m.zeta:.2f} %" for m in ms) for w, ms in modal.items()
    )
