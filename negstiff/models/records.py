"""A virtual-rig record and its files: the measured columns, metadata and truth (``RigRecord``), written
as CSV or NPZ, or as a lab's front end writes it (Universal File type 58, TDMS), through ``negstiff.io``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from negstiff import io as record_io
from negstiff.constants import G
from negstiff.errors import InputError
from negstiff.files import atomic_path, write_text

WRITTEN = (".csv", ".npz", ".uff", ".unv", ".tdms")
"""The formats a rig record is written in (``negstiff.io``; the lab's own: Universal File, TDMS)."""


class RigError(InputError):
    """The rig cannot produce the requested record (bad settings, or the device left its stroke)."""


def check_written(path: str | Path) -> None:
    """Refuse (``RigError``, one line) a record path whose suffix the rig does not write (``WRITTEN``): checked
    before a record is simulated, not after.

    Parameters
    ----------
    path : str or Path
        Where the record would be written.
    """
    path = Path(path)
    if path.suffix.lower() not in WRITTEN:
        raise RigError(f"{path}: the rig writes {', '.join(WRITTEN)} records (not {path.suffix or 'no suffix'})")


@dataclass
class RigRecord:
    """One measured record: columns at ``fs``, metadata lines, and the truth behind it.

    ``columns`` holds ``t, base_acc`` and the response sensor's columns (``Sensors.response``; the
    reference study's laser: ``y, base_disp, z``), by the contract's names. ``true`` holds the
    noise-free ``z``, ``z_dot``, ``base_acc`` and ``base_disp`` at the same samples (never written
    to the measurement file: a lab does not have them; tests and reports use them as the truth).
    """

    fs: float
    columns: dict[str, np.ndarray]
    meta: dict[str, Any]
    truth: dict[str, Any]
    true: dict[str, np.ndarray] = field(repr=False, default_factory=dict)

    @property
    def z(self) -> np.ndarray:
        """The measured displacements z (N, T): a structure's ``z1 ... zN`` by DOF, a single DOF's ``z`` as one
        row (a ``RigError`` for a record whose sensor measured no z: derive it with ``Measurement.from_rig``).
        """
        from negstiff.io.schema import channel_sensor

        rows = {cs: v for k, v in self.columns.items() if (cs := channel_sensor(k)) is not None}
        if "z" in self.columns:
            return np.atleast_2d(self.columns["z"])
        if rows and all(sensor == "z" for _, sensor in rows):
            return np.array([rows[key] for key in sorted(rows)])
        raise RigError(
            f"{self.meta.get('source', 'the record')}: no measured z (its response is "
            f"{', '.join(k for k in self.columns if k not in ('t', 'base_acc', 'force'))})"
        )

    def export_columns(self, acc_unit: str = "m/s^2") -> dict[str, np.ndarray]:
        """The columns as written: accelerations in g are named ``<name>_g`` (a lab's export; map
        them back with ``--columns base_acc=base_acc_g*9.81``).
        """
        if acc_unit == "m/s^2":
            return dict(self.columns)
        if acc_unit != "g":
            raise RigError(f"acceleration unit must be 'm/s^2' or 'g', got {acc_unit!r}")
        return {
            (f"{k}_g" if k in ("base_acc", "y_acc") else k): (v / G if k in ("base_acc", "y_acc") else v)
            for k, v in self.columns.items()
        }

    def write(self, path: str | Path, time_decimals: int | None = None, acc_unit: str = "m/s^2") -> Path:
        """Write the record (CSV, or NPZ by suffix) and ``<stem>.truth.json`` beside it, atomically.

        ``time_decimals`` prints the CSV's time column with that many fixed decimals (a lab export);
        ``acc_unit="g"`` writes accelerations in g. The record itself does not name its truth file, so
        the same seed gives the same bytes whatever the file is called.
        """
        path = Path(path)
        truth_path = path.with_name(path.stem + ".truth.json")
        meta = dict(self.meta)
        cols = self.export_columns(acc_unit)
        if acc_unit == "g":
            meta["units"] = "s, g (accelerations), m, m/s"
        suffix = path.suffix.lower()
        check_written(path)
        options = {}
        if suffix == ".csv" and time_decimals is not None:
            if not 0 <= time_decimals <= 12:
                raise RigError(f"time decimals must be 0..12, got {time_decimals}")
            options["time_decimals"] = time_decimals
        with atomic_path(path) as tmp:
            record_io.write(tmp, cols, self.fs, meta, suffix=suffix, **options)
        write_text(truth_path, json.dumps(self.truth, indent=2) + "\n")
        return path
