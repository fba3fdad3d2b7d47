"""What every format module of ``negstiff.io`` shares (after emcee's ``backends/``: one small interface,
one module per format).

A format module holds its file type's reader and, where a lab writes it, its writer:

* ``SUFFIXES``: the file name endings it reads;
* ``read(path) -> (columns, metadata)``: every channel as a float array under the name the file gives it,
  and the metadata as strings (``fs`` from the file's time step; ``unit:<channel>`` and
  ``sensitivity:<channel>`` where the file holds them); the printed precision of a time column under
  ``RESOLUTION``. A file it cannot read whole is one ``MeasurementError`` line;
* ``write(path, columns, fs, meta)`` (optional): the columns (SI, or ``<name>_g`` in g) as that format holds
  them, to ``path`` (the caller writes atomically).

Nothing here converts units or checks what a record is: ``negstiff.inference.record.reading.load`` does, by the
schema (``negstiff.io.schema``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from negstiff.errors import InputError, MeasurementError
from negstiff.resources import require_memory

RESOLUTION = "\0t_resolution"
"""Key under which a reader returns the resolution [s] of each value of the time column."""

SET_ASIDE = "set_aside:"
"""Metadata key prefix of a channel a reader set aside (``SET_ASIDE + name``: why, e.g. another rate than the
record's); ``load`` refuses such a channel by name, in one line, when it is asked for."""


def check_memory(path: Path, nbytes: float) -> None:
    """Refuse a file whose parse would take ``nbytes`` the machine cannot hold, before its reader starts."""
    try:
        require_memory(nbytes, f"reading {path}")
    except InputError as exc:
        raise MeasurementError(f"{exc}; split the file, or save it as NPZ") from None


def with_binary_resolution(cols: dict[str, np.ndarray], stored) -> dict[str, np.ndarray]:
    """A time column stored in single (or half) precision is as uniform as its float spacing allows."""
    if "t" in cols and stored["t"].dtype.kind == "f" and stored["t"].dtype.itemsize < 8:
        cols[RESOLUTION] = np.spacing(np.abs(stored["t"].ravel())).astype(float)
    return cols


def common_step(path: Path, steps: dict[str, float]) -> float | None:
    """The one sampling step all channels share (relative 1e-6), or a MeasurementError naming two."""
    named = {k: v for k, v in steps.items() if v and np.isfinite(v) and v > 0}
    if not named:
        return None
    ref_name, ref = next(iter(named.items()))
    for k, v in named.items():
        if abs(v / ref - 1) > 1e-6:
            raise MeasurementError(
                f"{path}: channels {ref_name} and {k} have different sampling rates ({1 / ref:.6g} Hz, {1 / v:.6g} Hz)"
            )
    return ref


def equal_lengths(path: Path, cols: dict[str, np.ndarray]) -> None:
    """Refuse (``MeasurementError``) channels of unequal lengths, naming the first that differs."""
    if not cols:
        raise MeasurementError(f"{path}: no channels in the file")
    ref_name, ref = next(iter(cols.items()))
    for k, v in cols.items():
        if v.size != ref.size:
            raise MeasurementError(
                f"{path}: channels {ref_name} and {k} have different lengths ({ref.size}, {v.size} samples)"
            )


def unique_names(names: list[str], places: list[str], what: str) -> tuple[list[str], dict[str, str]]:
    """The channels' names made unique, and what that sets aside: a name that ``what`` (e.g. "datasets")
    gives to more than one channel becomes ``NAME#PLACE`` for each of them (``places``: where each channel
    is, e.g. its record number), and the bare name is set aside (``SET_ASIDE``), so that asking for it
    (``load``'s columns, a column map, ``--aux``) is one line that says which channels hold it and how to
    map one; a file whose duplicates are never asked for reads as before.
    """
    seen: dict[str, list[int]] = {}
    for j, name in enumerate(names):
        seen.setdefault(name, []).append(j)
    out, meta = list(names), {}
    for name, js in seen.items():
        if len(js) < 2 or not name:
            continue
        for j in js:
            out[j] = f"{name}#{places[j]}"
        spelled = ", ".join(out[j] for j in js)
        meta[SET_ASIDE + name] = (
            f"is the name of {len(js)} {what} ({', '.join(places[j] for j in js)}): which one is meant? map one of "
            f"{spelled} (e.g. --columns {name}={out[js[0]]})"
        )
    return out, meta
