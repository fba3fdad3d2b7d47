"""The contract every negstiff estimator keeps (NSI, SINDy, Discrepancy, Posterior, GAUpdater), after
scikit-learn's (``sklearn/base.py``, its developer guide's "rolling your own estimator"):

* ``__init__`` stores its parameters as given, under their own names, and does nothing else;
* ``fit(data)`` validates the parameters first (``_validate``), learns, and returns ``self``;
* what was learned lives in attributes ending in ``_``;
* ``result()`` is the learned state as the contract's JSON (``to_json`` its alias).

Written here rather than inheriting scikit-learn's ``BaseEstimator``: the estimators take records and
targets, not (X, y) arrays, and scikit-learn would be a dependency for two small methods.
"""

from __future__ import annotations

import inspect
from typing import Any


class Estimator:
    """Base of the estimators (module docstring)."""

    def get_params(self) -> dict[str, Any]:
        """The constructor's parameters and their current values."""
        names = [p for p in inspect.signature(type(self).__init__).parameters if p != "self"]
        return {n: getattr(self, n) for n in names}

    def _validate(self) -> None:
        """Check the parameters (called first by ``fit``); raise the estimator's domain error."""

    def result(self) -> dict[str, Any]:
        raise NotImplementedError

    def to_json(self) -> dict[str, Any]:
        return self.result()

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items() if not hasattr(v, "__array__"))
        return f"{type(self).__name__}({args})"
