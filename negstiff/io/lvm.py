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

from .base import SET_ASIDE, check_memory, common_step, equal_lengths, unique_names
from .uff import LAB_PARSE_BYTES_PER_BYTE

SUFFIXES = (".lvm",)


def read(path: Path):
    """Every segment of a LabVIEW measurement file, in order, as one record (lvm_read, no pickle cache)."""
    import lvm_read

    check_memory(path, LAB_PARSE_BYTES_PER_BYTE * path.stat().st_size)
    try:
        d = lvm_read.read(str(path), read_from_pickle=False, dump_file=False)
        segs = [d[k] for k in range(int(d.get("Segments", 1)))]
        parts = [(np.asarray(s["data"], float), _names(s)) for s in segs]
    except Exception as exc:
        raise MeasurementError(f"{path}: unreadable LVM file ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    if not parts:
        raise MeasurementError(f"{path}: no data segment in the LVM file")
    seg, names = segs[0], parts[0][1]
    for data, _ in parts:
        if data.ndim != 2 or data.shape[1] < len(names):
            raise MeasurementError(f"{path}: the LVM data block does not match its {len(names)} channel names")
    data, samples = _joined(path, segs, parts)
    cols: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    units = seg.get("Y_Unit_Label") or []
    dx = seg.get("Delta_X") or []
    has_x = names and names[0] == "X_Value"
    channels: dict[str, tuple[np.ndarray, int, float]] = {}  # name: (column, samples, time step [s])
    names, aside = unique_names(names, [str(j + 1) for j in range(len(names))], "columns")
    meta.update(aside)
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


def _names(seg) -> list[str]:
    """A segment's channel names, less the header's trailing columns that carry no data (``Comment``)."""
    names = [str(n).strip() for n in seg["Channel names"]]
    while names and names[-1] in ("Comment", ""):  # a row's note at most
        names = names[:-1]
    return names


def _joined(path: Path, segs, parts) -> tuple[np.ndarray, list[float]]:
    """The segments' rows one after another, and each channel's samples over them all. LabVIEW starts a new
    segment (a header, then rows) as it goes on logging: the segments of one record hold the same channels
    at the same step, each starting where the one before ended (its ``X0``, where the file has no X column:
    with one, the record's time column says it). A file whose segments differ is refused, naming the first.
    """
    names = parts[0][1]
    step0 = list(segs[0].get("Delta_X") or [])
    for k in range(1, len(segs)):
        other = parts[k][1]
        if other != names:
            raise MeasurementError(
                f"{path}: LVM segment {k + 1} holds the channels {', '.join(other) or 'none'}, segment 1 holds "
                f"{', '.join(names) or 'none'}: one record is one set of channels (export them as separate files)"
            )
        step = list(segs[k].get("Delta_X") or [])
        if len(step) != len(step0) or not np.allclose(step, step0, rtol=1e-9, equal_nan=True):
            raise MeasurementError(
                f"{path}: LVM segment {k + 1} is sampled at another step (Delta_X) than segment 1: one record has "
                "one rate"
            )
    width = len(names)
    samples = [0.0] * len(segs[0].get("Samples") or [])  # per channel (the X column not counted), summed
    for k, seg in enumerate(segs):
        given = list(seg.get("Samples") or [])
        for c in range(len(samples)):
            g = float(given[c]) if c < len(given) else np.nan
            samples[c] += g if np.isfinite(g) else np.nan
        if k and names and names[0] != "X_Value":  # no time column: each segment starts where the last ended
            x0, x0_prev = (seg.get("X0") or [np.nan])[0], (segs[k - 1].get("X0") or [np.nan])[0]
            n_prev = (segs[k - 1].get("Samples") or [parts[k - 1][0].shape[0]])[0]
            dt = step0[0] if step0 else np.nan
            end = x0_prev + n_prev * dt
            if np.isfinite(x0) and np.isfinite(end) and abs(x0 - end) > 0.5 * dt:
                raise MeasurementError(
                    f"{path}: LVM segment {k + 1} starts at {x0:.9g} s, where segment {k} ended at {end:.9g} s: "
                    "a gap (or an overlap) between segments; one record is sampled without one"
                )
    data = np.concatenate([p[0][:, :width] for p in parts], axis=0) if width else parts[0][0]
    return data, samples
