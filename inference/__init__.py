"""Learning about a device from its records: reading them, identifying, updating, quantifying the
uncertainty, and characterising the dynamics. Names load on first use (PEP 562); ``negstiff`` itself
exports the ones a script needs.

* records: ``load``, ``from_arrays``, ``Measurement`` (``measurement``; files through ``negstiff.io``), the
  response sensors (``sensors``), the frame of a derived z (``frame``: ``pin_frame``)
* identification: ``NSI``, ``SINDy`` (one pipeline, ``Identifier`` -> ``Identification``), ``Discrepancy``
* uncertainty: ``Posterior``; model updating: ``GAUpdater``
* analysis: ``characterize``, ``frf``
* the estimator contract: ``Estimator`` (``estimator``), parameter constraints (``parameters``)
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "load": "measurement",
    "from_arrays": "measurement",
    "Measurement": "measurement",
    "pin_frame": "frame",
    "NSI": "nsi",
    "SINDy": "sindy",
    "Discrepancy": "discrepancy",
    "Posterior": "posterior.core",
    "GAUpdater": "updating",
    "characterize": "characterize",
    "frf": "frf",
    "Estimator": "estimator",
    "Identifier": "identification",
    "Identification": "identification",
}

__all__ = list(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
