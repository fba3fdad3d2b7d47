"""MATLAB ``.mat`` records (v4 to v7, through scipy.io; v7.3 is HDF5 and refused with the way out): one
vector per column, scalars as metadata.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from negstiff.errors import MeasurementError

from .base import check_memory, with_binary_resolution

SUFFIXES = (".mat",)


def read(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The variables (as columns) and metadata of a MATLAB v5 file."""
    from scipy.io import loadmat

    check_memory(path, 8 * path.stat().st_size)  # MAT v5 compresses its arrays (zlib): a few times the file
    try:
        raw = loadmat(path)
    except NotImplementedError:
        raise MeasurementError(f"{path}: MATLAB v7.3 (HDF5) files are not supported; save with -v7") from None
    meta: dict[str, str] = {}
    cols: dict[str, np.ndarray] = {}
    for k, v in raw.items():
        if k.startswith("__") or not isinstance(v, np.ndarray) or v.dtype.kind not in "fiu":
            continue
        if v.size == 1:
            meta[k] = str(float(v.ravel()[0]))
        elif min(v.shape) == 1:
            cols[k] = v.ravel().astype(float)
    return with_binary_resolution(cols, raw), meta


def write(path: Path, cols: dict[str, np.ndarray], fs: float, meta: dict) -> None:
    """The columns as vectors and ``fs`` as a scalar (MATLAB v5, scipy.io.savemat); numeric metadata as
    scalars (a .mat file holds no strings the reader keeps).
    """
    from scipy.io import savemat

    scalars = {}
    for k, v in meta.items():
        try:
            scalars[k] = float(v)
        except (TypeError, ValueError):
            continue
    with open(path, "wb") as fh:
        savemat(fh, {**scalars, **{k: np.asarray(v, float) for k, v in cols.items()}, "fs": float(fs)})
