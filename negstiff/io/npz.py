"""NumPy ``.npz`` records: one array per column by the contract's names, ``fs`` as a scalar, ``meta`` a
JSON object of the metadata; nothing pickled is read.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import MeasurementError

from .base import check_memory, with_binary_resolution

SUFFIXES = (".npz",)


def read(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The arrays (as columns) and metadata of an ``.npz`` file."""
    import zipfile

    try:  # the arrays' size as stored (compressed or not), before any is read
        with zipfile.ZipFile(path) as z:
            check_memory(path, 3 * sum(i.file_size for i in z.infolist()))
    except zipfile.BadZipFile:
        pass  # np.load says what is wrong
    with np.load(path, allow_pickle=False) as f:
        arrays = {k: np.asarray(f[k]) for k in f.files}
    meta: dict[str, str] = {}
    if "meta" in arrays:
        try:
            meta = {k: str(v) for k, v in json.loads(str(arrays.pop("meta"))).items()}
        except (ValueError, AttributeError):
            raise MeasurementError(f"{path}: the 'meta' entry is not a JSON object") from None
    if "fs" in arrays and arrays["fs"].size == 1:
        meta.setdefault("fs", str(float(arrays.pop("fs"))))
    cols = {k: v.ravel().astype(float) for k, v in arrays.items() if v.ndim >= 1 and v.size > 1}
    return with_binary_resolution(cols, arrays), meta


def write(path: Path, cols: dict[str, np.ndarray], fs: float, meta: dict) -> None:
    """The columns as arrays, ``fs`` and the metadata (JSON) beside them."""
    with open(path, "wb") as fh:
        arrays: dict[str, Any] = {"fs": fs, **cols, "meta": json.dumps(meta)}
        np.savez(fh, **arrays)
