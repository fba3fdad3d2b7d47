"""The contract every negstiff estimator keeps (NSI, SINDy, Discrepancy, Posterior, GAUpdater), after
scikit-learn's (``sklearn/base.py``, its developer guide's "rolling your own estimator"):

* ``__init__`` stores its parameters as given, under their own names, and does nothing else;
* ``fit(data)`` first runs ``check(data)`` (the parameters, ``_validate``, and the record, ``_check_record``:
  everything that can refuse the input, before any work or progress output), learns, and returns ``self``;
* what was learned lives in attributes ending in ``_``;
* ``result()`` is the learned state as the contract's JSON (``to_json`` its alias).

Written here rather than inheriting scikit-learn's ``BaseEstimator``: the estimators take records and
targets, not (X, y) arrays, and scikit-learn would be a dependency for two small methods.
"""

from __future__ import annotations

import inspect
from os import PathLike
from typing import Any


class Estimator:
    """Base of the estimators (module docstring)."""

    def get_params(self) -> dict[str, Any]:
        """The constructor's parameters and their current values."""
        names = [p for p in inspect.signature(type(self).__init__).parameters if p != "self"]
        return {n: getattr(self, n) for n in names}

    def _validate(self) -> None:
        """Check the parameters (called first by ``fit``); raise the estimator's domain error."""

    def _check_record(self, rec) -> None:
        """Check that ``rec`` can be used (length, excitation, motion); raise a ``MeasurementError``."""

    def check(self, data):
        """Everything ``fit`` checks before it starts (the parameters and the record), so a caller can
        refuse bad input before printing any progress; returns the record ``fit`` would use.

        ``data`` is a ``Measurement`` or a path to a measurement file (read with ``load``); arrays go
        through ``from_arrays(u, z, fs)`` first."""
        from negstiff.errors import InputError

        from .measurement import Measurement, load

        self._validate()
        if isinstance(data, (str, PathLike)):
            data = load(data)
        if not isinstance(data, Measurement):
            raise InputError(
                f"{type(self).__name__}.fit takes a Measurement or a file path, got {type(data).__name__} "
                "(arrays: negstiff.from_arrays(u, z, fs))"
            )
        self._check_record(data)
        return data

    def result(self) -> dict[str, Any]:
        raise NotImplementedError

    def to_json(self) -> dict[str, Any]:
        return self.result()

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items() if not hasattr(v, "__array__"))
        return f"{type(self).__name__}({args})"
