"""Learning about a device from its records, in four groups by role (each with its own docstring). Names
load on first use (PEP 562); ``negstiff`` itself exports the ones a script needs.

* ``record``: a record as negstiff holds it: ``Measurement``, ``load``, ``from_arrays`` (files through
  ``negstiff.io``), the response sensors (``sensors``), its smoothed states and derivatives
  (``derivatives``);
* ``steps``: what the estimators are made of: the record made physical (``frame.pin_frame``: an unknown
  response scale, a derived z's frame), the weak form, the wells' first guesses, held-out selection,
  free-run validation, output-error refinement, multiple shooting, the plausibility checks;
* ``estimators``: the estimator contract (``base``, ``parameters``), one identification pipeline
  (``identification``), ``NSI`` (with ``subspace``), ``SINDy``, ``Discrepancy`` (with ``hybrid``),
  ``Posterior`` (``posterior/``), ``GAUpdater`` (``updating``);
* ``analysis``: the dynamics of harmonic records: ``characterise`` (with ``periodicity``, ``lyapunov``),
  the bifurcation map of a campaign (``campaign``), ``frf``.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "load": "record.reading",
    "from_arrays": "record.measurement",
    "Measurement": "record.measurement",
    "pin_frame": "steps.frame",
    "NSI": "estimators.nsi",
    "SINDy": "estimators.sindy",
    "Discrepancy": "estimators.discrepancy",
    "Posterior": "estimators.posterior.core",
    "GAUpdater": "estimators.updating",
    "characterise": "analysis.characterise",
    "characterize": "analysis.characterise",
    "frf": "analysis.frf",
    "Estimator": "estimators.base",
    "Identifier": "estimators.identification",
    "Identification": "estimators.identification",
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
