"""Keeping fitted estimators and their results: the JSON form and the run's provenance.

Two forms, as scikit-learn and pysindy keep theirs:

* **pickle** (``pickle``, ``joblib``, dask's transport): the whole fitted object, every array and the
  arviz data of a posterior included; what a dask worker returns and a pytest cache stores. A pickle is
  for the same negstiff version (as scikit-learn's: no promise across versions) and, like any pickle,
  only from a trusted source.
* **JSON** (``to_json()`` -> ``from_json(...)``): the contract's result JSON (``docs/contract.md``), plus
  ``"estimator": {"class", "params"}`` so that ``from_json`` rebuilds the configured estimator.
  ``to_json()`` returns the JSON *object* (a dict), as every ``to_json`` of negstiff does (models,
  results, continuation branches): a result is written with ``files``/the command line, read back with
  ``json``, compared key by key in tests; a string would be parsed again by every one of them.
  ``from_json`` takes that dict, its text, or the path of a file holding it. The JSON is the portable,
  lossy form: it holds what the contract's result holds (a posterior's summary, not its draws; the
  draws are its NetCDF, ``PosteriorResult.to_netcdf``).

A rebuilt estimator answers ``result()`` with the JSON it was rebuilt from and has the learned
attributes the JSON carries (``model_``, ``initial_model_``, ...); an ``Identification`` is rebuilt
field by field.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import platform
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError


def json_source(data: Any, what: str = "result JSON") -> dict[str, Any]:
    """The JSON object ``data`` is: a mapping as it is, a JSON text parsed, or a path read
    (``files.read_json``); one ``InputError`` otherwise.
    """
    if isinstance(data, Mapping):
        return dict(data)
    if isinstance(data, str) and data.lstrip().startswith("{"):
        try:
            out = json.loads(data)
        except json.JSONDecodeError as exc:
            raise InputError(f"the {what} is not valid JSON ({exc.msg} at line {exc.lineno})") from None
    elif isinstance(data, (str, os.PathLike)):
        from negstiff.files import read_json

        out = read_json(Path(data), what)
    else:
        raise InputError(f"a {what} is a dict, its JSON text or a file path, not {type(data).__name__}")
    if not isinstance(out, dict):
        raise InputError(f"the {what} is a JSON object, not {type(out).__name__}")
    return out


def _class_path(obj: Any) -> str:
    return f"{type(obj).__module__}.{type(obj).__qualname__}"


def encode_param(value: Any) -> Any:
    """An estimator parameter as JSON: numbers, strings, None, sequences as they are; a ``Model`` or a ``Structure``
    as its model-file fields; an ``Identification`` as its result JSON; a frozen dataclass (``Device``, ``Bounds``) as
    ``{"__class__", "fields"}``; a ``numpy.random.Generator`` (not reproducible from JSON) as None.
    """
    from negstiff.models import Model
    from negstiff.models.structure import Structure

    if isinstance(value, Model | Structure):
        return {"__class__": _class_path(value), "model": value.to_dict()}
    if dataclasses.is_dataclass(value) and callable(getattr(type(value), "from_json", None)):
        # a result with its contract JSON (an ``Identification``: ``results`` imports this module, so not by name)
        return {"__class__": _class_path(value), "json": getattr(value, "to_json")()}  # noqa: B009
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        fields = {f.name: encode_param(getattr(value, f.name)) for f in dataclasses.fields(value) if f.init}
        return {"__class__": _class_path(value), "fields": fields}
    if isinstance(value, np.random.Generator):
        return None
    if isinstance(value, (list, tuple)):
        return [encode_param(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): encode_param(v) for k, v in value.items()}
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, os.PathLike):  # a file path (Posterior's chain_file)
        return os.fspath(value)
    return value


def decode_param(value: Any) -> Any:
    """The inverse of ``encode_param`` (JSON lists come back as tuples, as the constructors' defaults)."""
    if isinstance(value, list):
        return tuple(decode_param(v) for v in value)
    if isinstance(value, Mapping):
        if "__class__" in value:
            module, _, name = str(value["__class__"]).rpartition(".")
            if not module.startswith("negstiff."):
                raise InputError(f"an estimator parameter of class {value['__class__']!r} is not negstiff's")
            cls = getattr(importlib.import_module(module), name)
            if "model" in value:
                return cls.from_dict(value["model"])
            if "json" in value:
                return cls.from_json(value["json"])
            return cls(**{k: decode_param(v) for k, v in value["fields"].items()})
        return {k: decode_param(v) for k, v in value.items()}
    return value


def provenance(source: str | None = None, settings: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Where a saved result came from: the record's ``source``, the run's ``settings`` (as JSON text) and
    the software that made it (negstiff, numpy, Python versions).
    """
    import negstiff

    out: dict[str, Any] = {
        "negstiff_version": negstiff.__version__,
        "numpy_version": np.__version__,
        "python_version": platform.python_version(),
    }
    if source is not None:
        out["record_source"] = str(source)
    if settings is not None:
        out["settings_json"] = json.dumps(encode_param(dict(settings)), default=str)
    return out
