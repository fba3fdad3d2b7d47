"""LabVIEW measurement files (``.lvm``) through **lvm_read** (SDyPy, MIT), called without its pickle cache
(by default it writes a ``.pkl`` beside the input and trusts one found there: negstiff never writes beside
an input); channels by the header's names, the time step from ``Delta_X``. Read only: lvm_read writes
nothing, and labs export LVM from LabVIEW itself.

As LabVIEW writes them: the channel header's last column ``Comment`` carries no data (only a row's note, where
one was written), and a file may hold channels of other rates beside the record's (a temperature logged once:
``Samples`` 1). The record is the channels of the most samples at their common ``Delta_X``; each other channel is
set aside, its reason under ``SET_ASIDE + name`` in the metadata (``load`` refuses it, one line, if asked for).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from negstiff.errors import MeasurementError

from .base import SET_ASIDE, check_memory, common_step, equal_lengths
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
    while names and names[-1] in ("Comment", ""):  # header columns that carry no data (a row's note at most)
        names = names[:-1]
    if data.ndim != 2 or data.shape[1] < len(names):
        raise MeasurementError(f"{path}: the LVM data block does not match its {len(names)} channel names")
    cols: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    units = seg.get("Y_Unit_Label") or []
    dx = seg.get("Delta_X") or []
    samples = seg.get("Samples") or []
    has_x = names and names[0] == "X_Value"
    channels: dict[str, tuple[np.ndarray, int, float]] = {}  # name: (column, samples, time step [s])
    for j, name in enumerate(names):
        if name in ("Comment", ""):
            continue
        if name == "X_Value":
            cols["t"] = data[:, j]
            continue
        k = j - 1 if has_x else j  # the per-channel header fields do not count the X column
        if 0 <= k < len(units) and str(units[k]).strip():
            meta[f"unit:{name}"] = str(units[k]).strip()
        step = float(dx[k]) if 0 <= k < len(dx) and np.isfinite(dx[k]) else 0.0
        given = samples[k] if 0 <= k < len(samples) else np.nan
        count = int(given) if np.isfinite(given) else int(np.argmin(np.r_[np.isfinite(data[:, j]), False]))
        channels[name] = (data[:, j], count, step)
    if channels:
        n = max(c for _, c, _ in channels.values())
        rates = [st for _, c, st in channels.values() if c == n and st > 0]
        step = max(set(rates), key=rates.count) if rates else 0.0  # the record's: its channels' most common step
        for name, (col, count, st) in channels.items():
            if count == n and (st <= 0 or step <= 0 or abs(st / step - 1) <= 1e-6):
                cols[name] = col
                continue
            at = f" at {1 / st:.6g} Hz" if st > 0 else ""
            meta[SET_ASIDE + name] = (
                f"holds {count} sample{'s' if count != 1 else ''}{at} beside the record's {n}"
                + (f" at {1 / step:.6g} Hz" if step > 0 else "")
                + ": a channel of another rate (LabVIEW wrote it in the same block), not a column of this record"
            )
    equal_lengths(path, cols)
    shared = common_step(path, {k: v[2] for k, v in channels.items() if k in cols})
    if shared and "t" not in cols:
        meta["fs"] = repr(1.0 / shared)
    return cols, meta
