"""The contract every negstiff estimator keeps (NSI, SINDy, Discrepancy, Posterior, GAUpdater), after
scikit-learn's (``sklearn/base.py``, its developer guide's "rolling your own estimator"), enforced here.

* ``__init__(self, *, ...)`` takes keywords only, stores them as given under their own names, and does
  nothing else; ``get_params(deep=True)`` and ``set_params(**params)`` read and change them, so
  ``sklearn.base.clone`` copies an estimator;
* every parameter is declared with its constraint beside the class (``_parameter_constraints``,
  ``inference.parameters``); ``fit`` first runs ``check(data)``: every parameter against its declaration
  and the estimator's own cross-checks (``_validate``), then the record (``_check_record``): everything
  that can refuse the input, one ``InputError``, before any work or progress output;
* ``fit(data)`` takes a ``Measurement`` or a path to a measurement file (arrays go through
  ``from_arrays`` first), learns, and returns ``self``;
* what was learned lives in attributes ending in ``_``; asking one before ``fit`` raises
  ``NotFittedError``;
* a fitted model (``model_``) predicts a record by restarted free runs (``predict``), scores it
  (``score``: the median window's error), simulates any input (``simulate``) and prints its equation
  (``equations``, ``print``), as pysindy's (``prediction``);
* ``result()`` is the learned state as the contract's JSON; ``to_json()`` is it with the estimator's class
  and parameters (``"estimator"``), and ``from_json`` rebuilds a fitted estimator from it
  (``persistence``); a fitted estimator pickles (``pickle``, ``joblib``) with everything it learned.

Written here rather than inheriting scikit-learn's ``BaseEstimator``: the estimators take records and
targets, not (X, y) arrays, and scikit-learn would be a dependency for a few small methods.
"""

from __future__ import annotations

import copy
import functools
import inspect
import re
import weakref
from dataclasses import dataclass
from os import PathLike
from typing import Any, ClassVar, Self, override

import numpy as np

from negstiff.errors import InputError, NotFittedError
from negstiff.inference.estimators.parameters import Constraint
from negstiff.inference.estimators.persistence import decode_param, encode_param, json_source
from negstiff.inference.estimators.prediction import ModelPredictions
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.record.reading import load
from negstiff.inference.steps.frame import pin_frame

_CHECKED: weakref.WeakValueDictionary[tuple[int, str, str], Measurement] = weakref.WeakValueDictionary()
"""The records whose checks passed, by (the record's id, the estimator's class, its parameters): a record's checks
are a function of those three (``_check_record`` sets nothing), and ``fit`` checks what its caller checked already
(the command line's ``check``, a subclass's ``fit`` before the shared one's); some checks simulate (NSI's on a 300 s
record: 0.13 s, three times per ``identify nsi``). Held weakly: an entry leaves with its record, so an id is never
read for another record."""


class Estimator(ModelPredictions):
    """Base of the estimators (module docstring); a fitted ``model_`` predicts, scores, simulates and prints
    its equation (``prediction.ModelPredictions``).
    """

    _parameter_constraints: ClassVar[dict[str, Constraint]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "result" in cls.__dict__:  # an estimator rebuilt from its JSON answers with that JSON
            cls.result = _answering_stored(cls.__dict__["result"])  # type: ignore[method-assign]
        if "fit" in cls.__dict__:  # the same numbers from any entry and on any load (``resources.fit_threads``)
            setattr(cls, "fit", _on_fit_threads(cls.__dict__["fit"]))  # noqa: B010 (mypy: no fit on the base)

    @classmethod
    def _param_names(cls) -> list[str]:
        return [p for p in inspect.signature(cls.__init__).parameters if p != "self"]

    def get_params(self, deep: bool = True) -> dict[str, Any]:
        """The constructor's parameters and their current values (``deep``: with those of nested
        estimators as ``name__parameter``, as scikit-learn's).
        """
        out: dict[str, Any] = {}
        for name in self._param_names():
            value = getattr(self, name)
            if deep and isinstance(value, Estimator):
                out |= {f"{name}__{k}": v for k, v in value.get_params().items()}
            out[name] = value
        return out

    def set_params(self, **params: Any) -> Estimator:
        """Set parameters (``name=value``, or ``name__parameter`` of a nested estimator); returns ``self``.
        Values are checked by ``fit``, as the constructor's.
        """
        names = self._param_names()
        for key, value in params.items():
            name, _, sub = key.partition("__")
            if name not in names:
                raise InputError(
                    f"{type(self).__name__} has no parameter {name!r} (its parameters: {', '.join(names)})"
                )
            if sub:
                getattr(self, name).set_params(**{sub: value})
            else:
                setattr(self, name, value)
        return self

    def _validate_params(self) -> None:
        """Every parameter against its declared constraint: one ``InputError`` naming it and the range."""
        for name in self._param_names():
            constraint = self._parameter_constraints.get(name)
            if constraint is None:  # a developer's omission, found by the test of the declarations
                raise TypeError(f"{type(self).__name__}.{name} has no declared constraint")
            constraint.check(type(self).__name__, name, getattr(self, name))

    def _validate(self) -> None:
        """The estimator's own checks across parameters (after each is checked alone)."""

    def _check_record(self, rec) -> None:
        """Check that ``rec`` can be used (length, excitation, motion); raise a ``MeasurementError``."""

    def check(self, data):
        """Everything ``fit`` checks before it starts (the parameters and the record), so a caller can
        refuse bad input before printing any progress; returns the record ``fit`` would use.

        ``data`` is a ``Measurement`` or a path to a measurement file (read with ``load``); arrays go
        through ``from_arrays(u, z, fs)`` first. A z derived from another sensor is pinned to the physical
        frame here (``frame.pin_frame``), the step that needs it.
        """
        self._validate_params()
        self._validate()
        if isinstance(data, (str, PathLike)):
            data = load(data)
        if not isinstance(data, Measurement):
            raise InputError(
                f"{type(self).__name__}.fit takes a Measurement or a file path, got {type(data).__name__} "
                "(arrays: negstiff.from_arrays(u, z, fs))"
            )
        data = pin_frame(data)  # a derived z in the physical frame (said in the record's info)
        key = (id(data), type(self).__qualname__, repr(self.get_params(deep=False)))
        if _CHECKED.get(key) is not data:
            self._check_record(data)
            _CHECKED[key] = data
        return data

    def __getattr__(self, name: str):
        # reached only when ``name`` is not set: a learned attribute before ``fit``
        if name.endswith("_") and not name.startswith("__"):
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet ({name} is learned by fit): call fit first"
            )
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def fitted(self) -> bool:
        """Whether ``fit`` has run."""
        return "model_" in vars(self) or "result_" in vars(self) or "device_" in vars(self)

    def result(self) -> dict[str, Any]:
        """The fitted result as the command line writes it (JSON-ready)."""
        raise NotImplementedError

    def to_json(self) -> dict[str, Any]:
        """The result JSON (``result()``, the contract's) with ``"estimator": {"class", "params"}``: the JSON
        object (a dict, as every ``to_json`` of negstiff) that ``from_json`` rebuilds the fitted estimator from.
        """
        params = {k: encode_param(v) for k, v in self.get_params(deep=False).items()}
        return {**self.result(), "estimator": {"class": type(self).__name__, "params": params}}

    @classmethod
    def from_json(cls, data) -> Self:
        """A fitted estimator rebuilt from its ``to_json()`` (a dict, its JSON text or a file path): configured
        with the parameters the JSON names (the defaults where it names none: a result JSON the command line
        wrote), its ``result()`` the JSON's, its learned attributes those the JSON carries (``persistence``).
        """
        d = json_source(data, f"{cls.__name__} JSON")
        spec = d.pop("estimator", None) or {}
        if spec.get("class", cls.__name__) != cls.__name__:
            raise InputError(f"the JSON is a {spec['class']}'s, not a {cls.__name__}'s")
        names = set(cls._param_names())
        est = cls(**{k: decode_param(v) for k, v in (spec.get("params") or {}).items() if k in names})
        est._restore(d)
        return est

    def _restore(self, result: dict[str, Any]) -> None:
        """Set the learned state from a result JSON (``from_json``). By default the JSON is kept as the
        result, with the models it holds as ``model_``, ``initial_model_``, ``baseline_model_`` and its
        warnings as ``warnings_``; an estimator that can rebuild more overrides this.
        """
        from negstiff.models import Model

        self.__dict__["_stored_result"] = copy.deepcopy(result)
        for key in ("model", "initial_model", "baseline_model"):
            if isinstance(result.get(key), dict):
                setattr(self, f"{key}_", Model.from_dict(result[key]))
        self.warnings_ = list(result.get("warnings", []))

    def _summary(self) -> str:
        """The headline of a fitted estimator (a line), for ``repr``."""
        return ""

    def __repr__(self) -> str:
        defaults = {n: p.default for n, p in inspect.signature(type(self).__init__).parameters.items() if n != "self"}
        shown = []
        for name, value in self.get_params(deep=False).items():
            d = defaults.get(name, inspect.Parameter.empty)
            try:
                same = value is d or bool(value == d)
            except (TypeError, ValueError):  # arrays
                same = False
            if not same:
                text = repr(value)
                shown.append(f"{name}={text if len(text) <= 40 else text[:37] + '...'}")
        head = f"{type(self).__name__}({', '.join(shown)})"
        if not self.fitted:
            return f"{head}  [not fitted]"
        summary = self._summary()
        return f"{head}  [fitted{': ' + summary if summary else ''}]"


def _on_fit_threads(fit):
    """``fit`` with its linear algebra on ``resources.FIT_BLAS_THREADS`` BLAS threads, whatever the caller's pool."""
    from negstiff.resources import on_fit_threads

    return on_fit_threads(fit)


def _answering_stored(result):
    """``result`` answering with the JSON an estimator was rebuilt from (``Estimator._restore``), if any."""

    @functools.wraps(result)
    def answer(self) -> dict[str, Any]:
        stored = self.__dict__.get("_stored_result")
        return copy.deepcopy(stored) if stored is not None else result(self)

    return answer


# --- where a structure's element acts (the estimators' ``element``) ----------------------------------------------
_PLACE = re.compile(r"^\s*(\d+)\s*-\s*(\d+)\s*$")


@dataclass(frozen=True)
class ElementPlace(Constraint):
    """Where the nonlinear element acts: None (the single DOF, on the base), ``"I-J"`` or a pair (I, J) of
    integers, J >= 1 the DOF it moves, I >= 0 the one it is attached to (0: the base), I != J.
    """

    @override
    def accepts(self, value) -> bool:
        if value is None:
            return True
        if isinstance(value, str):
            m = _PLACE.match(value)
            if not m:
                return False
            i, j = int(m.group(1)), int(m.group(2))
        elif (
            isinstance(value, (tuple, list))
            and len(value) == 2
            and all(isinstance(x, (int, np.integer)) and not isinstance(x, bool) for x in value)
        ):
            i, j = (int(x) for x in value)
        else:
            return False
        return i >= 0 and j >= 1 and i != j

    @override
    def describe(self) -> str:
        return "None (the single DOF) or I-J: the DOF J >= 1 the element moves and the DOF I >= 0 it is attached to "
        "(0: the base), I != J"


def parse_element(text: str | tuple[int, int], n_dof: int) -> tuple[int, int]:
    """``"I-J"`` (J the DOF the element moves, I the one it is attached to, 0 the base) as (I, J), checked."""
    if isinstance(text, str):
        m = _PLACE.match(text)
        if not m:
            raise InputError(f"element must be I-J (e.g. 1-2; 0 is the base), got {text!r}")
        i, j = int(m.group(1)), int(m.group(2))
    else:
        i, j = (int(x) for x in text)
    if not (0 <= i <= n_dof and 1 <= j <= n_dof and i != j):
        raise InputError(f"element {i}-{j}: J must be a DOF 1..{n_dof}, I one of 0..{n_dof} (0: the base), I != J")
    return i, j


def element_of(est, rec: Measurement) -> tuple[int, int] | None:
    """The element's place on ``rec`` for estimator ``est`` (its ``element``, else the record's ``# element:`` as
    its ``masses`` come from ``# masses:``): None for a record of one DOF (the single-DOF algorithms; its element
    can only be on the base), else (I, J), checked, with the record's masses. One ``InputError`` before any work
    otherwise.
    """
    name = type(est).__name__
    given = est.element if est.element is not None else (rec.meta or {}).get("element")
    said = f"{name}(element={given!r})" if est.element is not None else f"{rec.source}: '# element: {given}'"
    if rec.n_dof == 1:
        if given is not None and parse_element(given, 1) != (0, 1):
            raise InputError(f"{said}: a record of one DOF has its element on the base (0-1)")
        return None
    if given is None:
        raise InputError(f"{rec.source}: a record of {rec.n_dof} DOFs needs the element's place "
                         f"({name}(element='I-J'), --element I-J, or '# element: I-J' in its header)")  # fmt: skip
    try:
        at = parse_element(given, rec.n_dof)
    except InputError as exc:
        raise InputError(f"{said}: {exc}" if est.element is None else str(exc)) from None
    if rec.masses is None and not getattr(est, "reads_sensors_without_masses", False):
        # NSI reads such a record through a state-space linear part (``nsi._state_space``); the weak form's equations
        # per DOF need each DOF's mass
        rec.dof_masses  # noqa: B018 - one MeasurementError without them, before any work
    if rec.masses is None and getattr(est, "refine", None) is True:
        # the state-space linear part (``nsi._state_space``) is judged on held-out windows, not refined: output error
        # over a state-space model's A, B, C, D is a prediction-error method of its own, not written yet
        raise InputError(f"{name}(refine=True): a structure read through its sensors without masses (a state-space "
                         "linear part) is not refined by output error; give the masses ('# masses:', --masses) to "
                         "refine its physical model, or leave refine unset")  # fmt: skip
    return at
