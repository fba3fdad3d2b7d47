"""Record files, in one place: each format's reader and writer in its own module behind one small interface
(``base``), and one schema of columns, dimensions, units and ranges (``schema``).

* ``csv`` (``.csv``, ``.txt``: the contract's file and the lab dialects), ``npz``, ``mat``;
* the lab's own formats through the field's libraries: ``uff`` (Universal File type 58, pyuff), ``tdms``
  (LabVIEW TDMS, npTDMS), ``lvm`` (LabVIEW measurement files, lvm_read; read only).

``read(path)`` returns a file's raw channels and metadata as the file names them; turning them into a
record (the column map, units to SI, the time base, the checks) is ``negstiff.inference.record.reading.load``.
``write(path, columns, fs, meta)`` writes a record's columns in the format of the path's suffix (the virtual
rig's records, ``models.records``). Both refuse with one ``MeasurementError`` line.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import numpy as np

from negstiff.errors import MeasurementError

from . import csv, lvm, mat, npz, tdms, uff

FORMATS: dict[str, ModuleType] = {s: m for m in (csv, npz, mat, uff, tdms, lvm) for s in m.SUFFIXES}
"""Each file suffix's format module."""


def read(path: str | Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """A file's channels (float arrays, by the file's names) and metadata (strings); one
    ``MeasurementError`` line for a missing, unknown or unreadable file.
    """
    path = Path(path)
    if not path.is_file():
        raise MeasurementError(f"{path}: no such file")
    fmt = FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise MeasurementError(f"{path}: unknown file type {path.suffix!r} (use {', '.join(FORMATS)})")
    try:
        return fmt.read(path)
    except MeasurementError:
        raise
    except Exception as exc:  # any parser failure is an unreadable file, said in one line
        raise MeasurementError(f"{path}: unreadable file ({type(exc).__name__}: {exc})".splitlines()[0]) from None


def write(path: str | Path, cols: dict[str, np.ndarray], fs: float, meta: dict, **options) -> None:
    """Write ``cols`` (the time column first, if any) at ``fs`` [Hz] with ``meta`` in the format of ``path``'s
    suffix (``options``: the format's own, e.g. ``time_decimals`` for CSV). The caller writes atomically
    (``negstiff.files.atomic_path``): ``path`` may be a temporary name, so ``suffix`` says the format.
    """
    path = Path(path)
    suffix = options.pop("suffix", path.suffix).lower()
    fmt = FORMATS.get(suffix)
    if fmt is None or not hasattr(fmt, "write"):
        writable = ", ".join(s for s, m in FORMATS.items() if hasattr(m, "write"))
        raise MeasurementError(f"{path}: negstiff writes {writable} records, not {suffix!r}")
    fmt.write(path, cols, fs, meta, **options)
