"""A virtual-rig record and its files: the measured columns, metadata and truth (``RigRecord``), written
as CSV or NPZ, or as a lab's front end writes it (Universal File type 58, TDMS: ``write_lab_format``)."""

from __future__ import annotations

import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError
from negstiff.files import atomic_path, write_text

from .constants import G


class RigError(InputError):
    """The rig cannot produce the requested record (bad settings, or the device left its stroke)."""


@dataclass
class RigRecord:
    """One measured record: columns at ``fs``, metadata lines, and the truth behind it.

    ``columns`` holds ``t, base_acc`` and the response sensor's columns (``Sensors.response``; the
    seed's laser: ``y, base_disp, z``), by the contract's names. ``true`` holds the
    noise-free ``z``, ``z_dot``, ``base_acc`` and ``base_disp`` at the same samples (never written
    to the measurement file: a lab does not have them; tests and reports use them as the truth).
    """

    fs: float
    columns: dict[str, np.ndarray]
    meta: dict[str, Any]
    truth: dict[str, Any]
    true: dict[str, np.ndarray] = field(repr=False, default_factory=dict)

    def export_columns(self, acc_unit: str = "m/s^2") -> dict[str, np.ndarray]:
        """The columns as written: accelerations in g are named ``<name>_g`` (a lab's export; map
        them back with ``--columns base_acc=base_acc_g*9.81``)."""
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
        the same seed gives the same bytes whatever the file is called."""
        path = Path(path)
        truth_path = path.with_name(path.stem + ".truth.json")
        meta = dict(self.meta)
        cols = self.export_columns(acc_unit)
        if acc_unit == "g":
            meta["units"] = "s, g (accelerations), m, m/s"
        if path.suffix.lower() == ".npz":
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as fh:
                    np.savez(fh, fs=self.fs, **cols, meta=json.dumps(meta))
        elif path.suffix.lower() in (".uff", ".unv", ".tdms"):
            with atomic_path(path) as tmp:
                write_lab_format(tmp, path.suffix.lower(), cols, self.fs, meta, acc_unit)
        elif path.suffix.lower() == ".csv":
            buf = io.StringIO()
            for k, v in meta.items():
                buf.write(f"# {k}: {v}\n")
            data = np.column_stack(list(cols.values()))
            fmt = ["%.10g"] * len(cols)
            if time_decimals is not None:
                if not 0 <= time_decimals <= 12:
                    raise RigError(f"time decimals must be 0..12, got {time_decimals}")
                fmt[0] = f"%.{int(time_decimals)}f"
            np.savetxt(buf, data, delimiter=",", fmt=fmt, header=",".join(cols), comments="")
            write_text(path, buf.getvalue())
        else:
            raise RigError(f"{path}: the rig writes .csv, .npz, .uff (.unv) or .tdms records")
        write_text(truth_path, json.dumps(self.truth, indent=2) + "\n")
        return path


UNITS = {"t": "s", "base_acc": "m/s^2", "y_acc": "m/s^2", "y": "m", "base_disp": "m", "z": "m", "z_dot": "m/s"}
"""SI unit of each record column (a ``_g`` suffix: the acceleration in g)."""


def write_lab_format(path: Path, kind: str, cols: dict[str, np.ndarray], fs: float, meta: dict, acc_unit: str):
    """A record as a lab's front end writes it, through the field's libraries: a Universal File of
    type-58 time responses, one per channel (pyuff; ASCII, as pyuff's binary 58b of this version did not
    read back its own output), or a TDMS file with one group of waveform channels and the record's
    metadata as file properties (npTDMS). The time column is not a channel: the time step is."""

    def unit(name: str) -> str:
        return "g" if name.endswith("_g") else UNITS.get(name, "")

    chans = {k: v for k, v in cols.items() if k != "t"}
    if kind == ".tdms":
        from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

        with TdmsWriter(str(path)) as w:
            objs = [RootObject(properties={k: str(v) for k, v in meta.items()}), GroupObject("negstiff")]
            objs += [
                ChannelObject("negstiff", k, np.asarray(v, float), properties={"wf_increment": 1.0 / fs,
                              "wf_start_offset": 0.0, "unit_string": unit(k)})
                for k, v in chans.items()
            ]  # fmt: skip
            w.write_segment(objs)
        return
    import pyuff

    x = np.arange(next(iter(chans.values())).size) / fs
    uff = pyuff.UFF(str(path))
    for i, (k, v) in enumerate(chans.items()):
        zero = {
            f"{a}_{b}": 0
            for a in ("orddenom", "z_axis")
            for b in ("spec_data_type", "len_unit_exp", "force_unit_exp", "temp_unit_exp")
        }
        ds = pyuff.prepare_58(
            binary=0, id1=k, id2=str(meta.get("source", "")), func_type=1, rsp_node=i + 1, rsp_dir=3, ref_node=0,
            ref_dir=0, data=np.asarray(v, float), x=x, ord_data_type=4, num_pts=x.size, abscissa_spacing=1,
            abscissa_min=0.0, abscissa_inc=1.0 / fs, abscissa_spec_data_type=17, abscissa_len_unit_exp=0,
            abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0, abscissa_axis_units_lab="s",
            ordinate_spec_data_type=0, ordinate_len_unit_exp=0, ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0,
            ordinate_axis_units_lab=unit(k), orddenom_axis_units_lab="", z_axis_axis_units_lab="", z_axis_value=0.0,
            **zero,
        )  # fmt: skip
        uff.write_sets(ds, mode="overwrite" if i == 0 else "add")
