"""LabVIEW measurement files (``.lvm``) through **lvm_read** (SDyPy, MIT), called without its pickle cache
(by default it writes a ``.pkl`` beside the input and trusts one found there: negstiff never writes beside
an input); channels by the header's names, the time step from ``Delta_X``. Read only: lvm_read writes
nothing, and labs export LVM from LabVIEW itself.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from negstiff.errors import MeasurementError

from .base import check_memory, common_step, equal_lengths
from .uff import LAB_PARSE_BYTES_PER_BYTE

SUFFIXES = (".lvm",)


def read(path: Path):
    """The first segment of a LabVIEW measurement file (lvm_read, no pickle cache)."""
    import lvm_read

    check_memory(path, LAB_PARSE_BYTES_PER_BYTE * path.stat().st_size)
    try:
        d = lvm_read.read(str(path), read_from_pickle=False, dump_file=False)
        seg = d[0]
        data = np.asarray(seg["data"], float)
        names = [str(n).strip() for n in seg["Channel names"]]
    except Exception as exc:
        raise MeasurementError(f"{path}: unreadable LVM file ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    if data.ndim != 2 or data.shape[1] < len(names):
        raise MeasurementError(f"{path}: the LVM data block does not match its {len(names)} channel names")
    cols: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    units = seg.get("Y_Unit_Label") or []
    dx = seg.get("Delta_X") or []
    steps: dict[str, float] = {}
    has_x = names and names[0] == "X_Value"
    for j, name in enumerate(names):
        if name in ("Comment", ""):
            continue
        if name == "X_Value":
            cols["t"] = data[:, j]
            continue
        cols[name] = data[:, j]
        k = j - 1 if has_x else j  # the per-channel header fields do not count the X column
        if 0 <= k < len(units) and str(units[k]).strip():
            meta[f"unit:{name}"] = str(units[k]).strip()
        if 0 <= k < len(dx):
            steps[name] = float(dx[k]) if np.isfinite(dx[k]) else 0.0
    equal_lengths(path, cols)
    step = common_step(path, steps)
    if step and "t" not in cols:
        meta["fs"] = repr(1.0 / step)
    return cols, meta
