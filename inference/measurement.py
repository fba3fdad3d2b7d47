"""Measurement files of the contract (``shared/docs/contract.md``): CSV, NPZ and MAT.

A measurement is one uniformly sampled record with exactly one input column (``base_acc`` [m/s^2]
or ``force`` [N]), the output ``z`` [m], and a time base (``t`` [s], or ``fs`` [Hz] from the
metadata or the caller). Foreign files are read through a column map (``force=V1,z=V2``; an entry
may scale, ``base_acc=X1*9.81``). Every problem raises ``MeasurementError`` with one line naming the
file, the column or row, and what is wrong. Input files are only read.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError, RecordWarning

from .plausibility import issue, record_warnings

INPUTS = ("base_acc", "force")
OPTIONAL = ("z_dot", "y", "base_disp")
RESPONSE_ONLY = ("y_dot", "y_acc")
"""Response columns a record may hold instead of z (``sensors.RESPONSES``): z is derived from them."""
KNOWN = ("t", *INPUTS, "z", *OPTIONAL, *RESPONSE_ONLY)

TIME_JITTER_FRACTION = 0.01
"""A time column's samples may sit this fraction of a step off a uniform grid (or by their printed
precision, whichever is larger) and still be uniform: lab exports round time."""


class MeasurementError(InputError):
    """Bad measurement input; the message is one line naming the file and the problem."""


@dataclass(frozen=True)
class Measurement:
    """One uniformly sampled record (SI units).

    Attributes
    ----------
    fs : sampling rate [Hz]
    input_name : ``"base_acc"`` or ``"force"``
    u : the input column, (N,)
    z : relative displacement [m], (N,) (measured, or derived from the response sensor: ``info``;
        None only for an input-only record read with ``response=False``)
    z_dot, y, base_disp : optional columns, (N,) or None
    mass : moving mass [kg] from the metadata or the caller, or None (mass-normalised)
    meta : the file's metadata (``# key: value`` lines) as strings
    source : where it came from (for messages)
    t0 : time of the first sample [s]
    info : how the record was read: ``time`` (the time base, its jitter) and ``response`` (what was
        measured, and how z was derived from it, with its estimated error); results carry it
    """

    fs: float
    input_name: str
    u: np.ndarray
    z: np.ndarray | None
    z_dot: np.ndarray | None = None
    y: np.ndarray | None = None
    base_disp: np.ndarray | None = None
    mass: float | None = None
    meta: dict[str, str] = field(default_factory=dict)
    source: str = "<memory>"
    t0: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.u.size

    def __repr__(self) -> str:
        resp = self.info.get("response", {}).get("measured") or ("z" if self.z is not None else "none")
        mass = f"{self.mass:g} kg" if self.mass is not None else "none (per unit mass)"
        return (
            f"Measurement({self.source!r}: {self.n} samples at {self.fs:g} Hz ({self.duration:.4g} s), input "
            f"{self.input_name}, response {resp}, mass {mass})"
        )

    @property
    def dt(self) -> float:
        return 1.0 / self.fs

    @property
    def t(self) -> np.ndarray:
        return self.t0 + np.arange(self.n) / self.fs

    @property
    def duration(self) -> float:
        return self.n / self.fs

    @classmethod
    def from_rig(cls, rec, weighed: bool = True) -> "Measurement":
        """A virtual-rig record (``models.rig.RigRecord``) as negstiff reads a lab's: the measured base
        acceleration as input, the measured z as response, the weighed mass (``weighed``) and its source."""
        mass = float(rec.meta["mass"]) if weighed and rec.meta.get("mass") is not None else None
        return from_arrays(rec.columns["base_acc"], rec.columns["z"], rec.fs, mass=mass, source=rec.meta["source"])

    def segment(self, start: int, stop: int) -> "Measurement":
        """Samples [start, stop) as a new measurement (time base kept)."""
        sl = slice(start, stop)
        opt = {k: (None if getattr(self, k) is None else getattr(self, k)[sl]) for k in ("z", *OPTIONAL)}
        return replace(self, u=self.u[sl], t0=self.t0 + start / self.fs, **opt)

    @property
    def rest_positions(self) -> dict[str, float]:
        """The wells' rest positions the metadata states (``z_minus_rest``, ``z_plus_rest`` [m]), by well."""
        out = {}
        for w in ("minus", "plus"):
            try:
                out[w] = float(self.meta[f"z_{w}_rest"])
            except (KeyError, ValueError):
                pass
        return out

    def require(self, n_min: int, what: str) -> None:
        """Raise ``MeasurementError`` unless the record has at least ``n_min`` samples for ``what``."""
        if self.n < n_min:
            raise MeasurementError(
                f"{self.source}: too few samples for {what}: {self.n} ({self.duration:.3g} s), need at least {n_min}"
            )

    def with_mass(self, mass: float | None) -> "Measurement":
        """The same record with the mass given by the caller (overrides the metadata)."""
        if mass is None:
            return self
        if (
            isinstance(mass, bool)
            or not isinstance(mass, (int, float, np.integer, np.floating))
            or not (MASS_RANGE_KG[0] <= mass <= MASS_RANGE_KG[1])
        ):
            raise MeasurementError(f"{self.source}: mass {mass!r} kg is not a moving mass "
                                   f"({MASS_RANGE_KG[0]:g} to {MASS_RANGE_KG[1]:g} kg)")  # fmt: skip
        return replace(self, mass=float(mass))

    def require_motion(self, what: str) -> None:
        """Raise ``MeasurementError`` when the response does not move (a dead or disconnected sensor):
        ``what`` (an identification, a periodicity analysis) needs motion."""
        if self.z is not None and _constant(self.z):
            raise MeasurementError(
                f"{self.source}: the response z is constant ({self.z[0]:.6g} m over {self.n} samples): a dead or "
                f"disconnected sensor? {what} needs motion"
            )

    def require_excitation(self, what: str) -> None:
        """Raise ``MeasurementError`` when the input does not vary (a dead sensor, or no excitation)."""
        if _constant(self.u):
            raise MeasurementError(
                f"{self.source}: the input {self.input_name} is constant ({self.u[0]:.6g} over {self.n} samples): a "
                f"dead sensor, or no excitation? {what} needs an input that moves"
            )


MASS_RANGE_KG = (1e-9, 1e9)
"""Moving masses [kg] a record may state: a microgram MEMS proof mass to a building's storey."""


def _constant(x: np.ndarray) -> bool:
    """No variation beyond the values' own floating-point resolution."""
    span = float(np.ptp(x))
    return span <= 64 * np.finfo(float).eps * float(np.max(np.abs(x))) or span < 1e-15


_MAP_ENTRY = re.compile(r"^\s*(\w+)\s*=\s*([^*]+?)\s*(?:\*\s*([-+0-9.eE]+))?\s*$")


def parse_column_map(text: str | None) -> dict[str, tuple[str, float]]:
    """Parse ``name=SOURCE[*scale],...`` into ``{name: (SOURCE, scale)}``."""
    if not text:
        return {}
    out: dict[str, tuple[str, float]] = {}
    for entry in text.split(","):
        m = _MAP_ENTRY.match(entry)
        if not m:
            raise MeasurementError(f"column map entry {entry!r} is not of the form name=COLUMN or name=COLUMN*scale")
        name, src, scale = m.group(1), m.group(2).strip().strip('"'), m.group(3)
        if name not in KNOWN:
            raise MeasurementError(f"column map names {name!r}, which is not a measurement column ({', '.join(KNOWN)})")
        try:
            factor = 1.0 if scale is None else float(scale)
        except ValueError:
            raise MeasurementError(f"column map entry {entry!r}: scale {scale!r} is not a number") from None
        if name in out:
            raise MeasurementError(
                f"column map names {name!r} twice ({out[name][0]!r} and {src!r}): which one is meant?"
            )
        out[name] = (src, factor)
    return out


_UNIT_IN_NAME = re.compile(r"^(?P<name>.*?)\s*(?:\[(?P<square>[^\]]*)\]|\((?P<round>[^)]*)\))\s*$")
"""A header entry with its unit: ``z [mm]`` or ``z (mm)``."""


READ_CHUNK_BYTES = 16 * 2**20
"""A text file is read in chunks of this size, each checked before the next is read."""

TEXT_PARSE_BYTES_PER_BYTE = 8
"""Memory [bytes] the parser holds per byte of a CSV file (its text, its lines and their values; 4.5
measured on a 10 MB rig record): a file whose parse would not fit in memory is refused before it is read."""


def _text(path: Path) -> str:
    """A text file's content: UTF-8 (a byte-order mark, as spreadsheets write, dropped), else Latin-1
    (older Windows exports write 'µm' so). Read in chunks with a bounded budget: a file with NUL bytes
    is not text, and is refused at the first chunk that holds one (not after reading a gigabyte)."""
    from negstiff.resources import require_memory

    chunks, offset = [], 0
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            while chunk := fh.read(READ_CHUNK_BYTES):
                nul = chunk.find(b"\0")
                if nul >= 0:
                    raise MeasurementError(
                        f"{path}: unreadable file (a NUL byte at byte {offset + nul}: not text; a CSV is expected)"
                    )
                if not offset:  # a text head: is the whole file's parse within the memory?
                    try:
                        require_memory(size * TEXT_PARSE_BYTES_PER_BYTE, f"reading {path} ({size / 2**20:.4g} MiB)")
                    except InputError as exc:
                        raise MeasurementError(f"{exc}; split the file, or save it as NPZ") from None
                chunks.append(chunk)
                offset += len(chunk)
    except OSError as exc:
        raise MeasurementError(f"{path}: cannot read ({exc.strerror or exc})") from None
    raw = b"".join(chunks)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _dialect(path: Path, header: str, first_row: str) -> tuple[str | None, bool]:
    """(field separator, decimal comma) of a CSV from its header and first data row: ',' (the contract),
    ';' (spreadsheets where the decimal mark is a comma, which then appears in the numbers), a tab, or
    blanks (None). Written here rather than with ``csv.Sniffer``, which guesses from character counts and
    takes a digit or the decimal point for the separator of a numeric file."""
    # the separator is in both lines (a header's names may hold commas, a decimal-comma row holds commas)
    sep = next((d for d in (",", ";", "\t") if d in header and d in first_row), None)
    decimal_comma = sep != "," and "," in first_row
    if decimal_comma and "." in first_row:
        raise MeasurementError(
            f"{path}: the first data row mixes decimal points and commas: {first_row[:60]!r} (one decimal mark, please)"
        )
    return sep, decimal_comma


def _read_csv(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    lines = _text(path).splitlines()
    meta: dict[str, str] = {}
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        if ":" in lines[i]:
            k, v = lines[i][1:].split(":", 1)
            meta[k.strip()] = v.strip()
        i += 1
    if i >= len(lines):
        raise MeasurementError(f"{path}: no header line (and no data)")
    header_line = i + 1
    body = lines[i + 1 :]
    while body and not body[-1].strip():
        body.pop()
    if not body:
        raise MeasurementError(f"{path}: no data rows after the header")
    sep, decimal_comma = _dialect(path, lines[i], body[0])
    if decimal_comma:
        body = [line.replace(",", ".") for line in body]
    names = []
    for c in lines[i].split(sep):
        c = c.strip().strip('"').strip()
        m = _UNIT_IN_NAME.match(c)
        if m and m.group("name"):  # a unit in the header: the column's name without it, its unit in the metadata
            c = m.group("name").strip().strip('"').strip()
            meta[f"unit:{c}"] = (m.group("square") if m.group("square") is not None else m.group("round")).strip()
        if c and c in names:
            raise MeasurementError(
                f"{path}: the header names column {c!r} twice (columns {names.index(c) + 1} and {len(names) + 1}): "
                "which one is meant? rename one, or map the one to use with --columns"
            )
        names.append(c)
    use = [j for j, c in enumerate(names) if c]  # trailing separators make unnamed empty columns
    try:
        data = np.loadtxt(body, delimiter=sep, usecols=use, ndmin=2, dtype=float)
    except ValueError:
        for r, line in enumerate(body):
            parts = line.split(sep)
            try:
                [float(parts[j]) for j in use]
            except (ValueError, IndexError):
                raise MeasurementError(
                    f"{path}: row {r + 1} (line {header_line + r + 1}) is not numeric in every column: {line[:60]!r}"
                ) from None
        raise MeasurementError(f"{path}: rows are not all numeric") from None
    cols = {names[j]: data[:, k] for k, j in enumerate(use)}
    if "t" in names:  # the printed precision of each time value (lab exports round time)
        j = names.index("t")
        tokens = [line.partition(sep)[0] for line in body] if j == 0 and sep else [line.split(sep)[j] for line in body]
        cols[RESOLUTION] = printed_resolution(tokens, cols["t"])
    return cols, meta


RESOLUTION = "\0t_resolution"
"""Key under which a reader returns the resolution [s] of each value of the time column."""


def printed_resolution(tokens: list[str], values: np.ndarray) -> np.ndarray:
    """The resolution of each printed value of a column, from the column's format as the tokens show it.

    A fixed-decimals export ('%.5f') has one resolution, 10^-D; a significant-digits export ('%.9g')
    has 10^(e - S + 1) for a value of magnitude 10^e. Trailing zeros are dropped by many writers, so
    D and S are the largest seen in the column, and each value's resolution is the coarser of the two.
    """
    digits = _plain_decimal_digits(tokens)
    decimals, sig = digits if digits is not None else _printed_digits(tokens)
    with np.errstate(divide="ignore"):
        mag = np.floor(np.log10(np.abs(values)))
    mag[~np.isfinite(mag)] = -np.inf
    return np.maximum(10.0 ** (-decimals), 10.0 ** (mag - sig + 1))


def _printed_digits(tokens: list[str]) -> tuple[int, int]:
    """(D, S) of ``printed_resolution``: the most decimals (less the exponent) and significant digits."""
    decimals, sig = 0, 1
    for tok in tokens:
        mant, _, exp = tok.strip().strip('"').lower().partition("e")
        mant = mant.lstrip("+-")
        whole, _, frac = mant.partition(".")
        try:
            e = int(exp) if exp else 0
        except ValueError:
            continue
        decimals = max(decimals, len(frac) - e)
        sig = max(sig, len((whole + frac).lstrip("0")) or 1)
    return decimals, sig


_PLAIN = np.zeros(256, dtype=bool)
_PLAIN[np.frombuffer(b"0123456789.+-\0", dtype=np.uint8)] = True


def _plain_decimal_digits(tokens: list[str]) -> tuple[int, int] | None:
    """``_printed_digits`` of a column of plain decimals (digits, sign and point only: what lab exports
    write) on the tokens' bytes as one array, or None for any other column. The per-token loop took 0.13
    s on a 300 s record at 512 Hz, half of reading the file; this takes 0.04 s."""
    text = "".join(tokens)
    if not tokens or not text.isascii():
        return None
    b = np.array(tokens, dtype=bytes)  # NUL-padded to the longest token
    m = b.view(np.uint8).reshape(b.size, b.itemsize)
    if not _PLAIN[m].all():
        return None
    length = np.count_nonzero(m, axis=1)
    is_dot = m == ord(".")
    has_dot = is_dot.any(axis=1)
    dot = np.argmax(is_dot, axis=1)
    nonzero = (m >= ord("1")) & (m <= ord("9"))
    first = np.argmax(nonzero, axis=1)
    decimals = int(np.max(np.where(has_dot, length - dot - 1, 0)))
    # significant digits: from the first nonzero digit to the end, less a point among them
    digits = np.where(nonzero.any(axis=1), length - first - (has_dot & (dot > first)), 0)
    return decimals, max(1, int(np.max(digits)))


def _require_memory(path: Path, nbytes: float) -> None:
    from negstiff.resources import require_memory

    try:
        require_memory(nbytes, f"reading {path}")
    except InputError as exc:
        raise MeasurementError(str(exc)) from None


def _read_npz(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    import zipfile

    try:  # the arrays' size as stored (compressed or not), before any is read
        with zipfile.ZipFile(path) as z:
            _require_memory(path, 3 * sum(i.file_size for i in z.infolist()))
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
    return _with_binary_resolution(cols, arrays), meta


def _with_binary_resolution(cols: dict[str, np.ndarray], stored: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A time column stored in single (or half) precision is as uniform as its float spacing allows."""
    if "t" in cols and stored["t"].dtype.kind == "f" and stored["t"].dtype.itemsize < 8:
        cols[RESOLUTION] = np.spacing(np.abs(stored["t"].ravel())).astype(float)
    return cols


def _read_mat(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    from scipy.io import loadmat

    _require_memory(path, 8 * path.stat().st_size)  # MAT v5 compresses its arrays (zlib): a few times the file
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
    return _with_binary_resolution(cols, raw), meta


def _lab_reader(suffix: str):
    """The lab formats' readers (``formats.py``) are imported only when such a file is read."""

    def read(path: Path):
        from negstiff.inference import formats

        return formats.READERS[suffix](path)

    return read


READERS = {
    ".csv": _read_csv,
    ".txt": _read_csv,
    ".npz": _read_npz,
    ".mat": _read_mat,
    **{s: _lab_reader(s) for s in (".uff", ".unv", ".tdms", ".lvm")},
}


def load(
    path: str | Path,
    columns: str | dict | None = None,
    fs: float | None = None,
    mass: float | None = None,
    response: bool = True,
) -> Measurement:
    """Read a measurement file.

    Parameters
    ----------
    path : a .csv, .npz, .mat, .uff/.unv, .tdms or .lvm file
    columns : column map (``"force=V1,z=V2"`` or its parsed dict) for foreign files
    fs : sampling rate [Hz]; replaces the time column when given (the column then only sets t0)
    mass : moving mass [kg] (overrides the metadata's ``mass``)
    response : False for an input-only record (``negstiff simulate``): no response column needed

    The response is z, or z derived from z_dot, y (with the base's motion), y_dot or y_acc
    (``sensors.derive``), its frame pinned by physics where its constant is unknown
    (``sensors.pin_frame``); what was done is in ``info["response"]``.
    """
    from negstiff.inference import sensors

    path = Path(path)
    raw, meta = _read(path)
    resolution = raw.pop(RESOLUTION, None)
    cmap = parse_column_map(columns) if isinstance(columns, (str, type(None))) else dict(columns)
    cmap = {name: (_header_name(src, raw), scale) for name, (src, scale) in cmap.items()}
    from negstiff.inference.units import in_si

    cols, channel_info = in_si(path, _mapped_columns(path, raw, cmap), meta, cmap)
    if any(name == "t" and (src != "t" or scale != 1.0) for name, (src, scale) in cmap.items()):
        resolution = None  # the printed precision was read for a column named t only
    if resolution is not None:  # a time column in ms: its printed precision in s too
        resolution = resolution * channel_info.get("channels", {}).get("t", {}).get("to_si", 1.0)
    input_name, n = _checked_input(path, raw, cols)
    fs, t0, time_info = _time_base(path, cols, meta, fs, resolution)
    if mass is None and "mass" in meta:
        try:
            mass = float(meta["mass"])
        except ValueError:
            raise MeasurementError(f"{path}: metadata mass = {meta['mass']!r} is not a number") from None
    z, resp = None, {"measured": None}
    if response or any(k in cols for k in sensors.RESPONSES):
        z, resp = sensors.derive(cols, input_name, fs, str(path))
        k = int(round(resp.get("trim_s", 0.0) * fs))
        if k:
            if n <= 4 * k:
                raise MeasurementError(
                    f"{path}: too few samples ({n}) to derive z from {resp['measured']}: the integral of an "
                    f"accelerometer loses {resp['trim_s']:g} s at each end"
                )
            cols = {c: v[k:-k] for c, v in cols.items()}
            z, t0 = z[k:-k], t0 + k / fs
            resp["derived"] += f"; {resp['trim_s']:g} s cut at each end (the integral's end effects)"
    rec = Measurement(
        fs=fs,
        input_name=input_name,
        u=cols[input_name],
        z=z,
        z_dot=cols.get("z_dot"),
        y=cols.get("y"),
        base_disp=cols.get("base_disp"),
        meta=meta,
        source=str(path),
        t0=t0,
        info={"time": time_info, "response": resp, **channel_info},
    )
    rec = sensors.pin_frame(rec.with_mass(mass))
    return _warned(rec)


def _warned(rec: Measurement) -> Measurement:
    """The record with what looks wrong in it alone (units: mm read as m, an acceleration in mm/s^2; the
    sensor's derivation) in ``info["warnings"]``, each issued as a ``RecordWarning`` at once: a user learns
    it when loading, whatever comes next (``plausibility.record_warnings``)."""
    new = [w for w in record_warnings(rec) if w not in rec.info.get("warnings", [])]
    lines = [*rec.info.get("warnings", []), *rec.info.get("response", {}).get("warnings", []), *new]
    issue([(RecordWarning, w) for w in lines])
    return replace(rec, info={**rec.info, "warnings": [*rec.info.get("warnings", []), *new]}) if new else rec


def _read(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The file's columns and metadata by its reader; any parser failure is one line."""
    if not path.is_file():
        raise MeasurementError(f"{path}: no such file")
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise MeasurementError(f"{path}: unknown file type {path.suffix!r} (use {', '.join(READERS)})")
    try:
        return reader(path)
    except MeasurementError:
        raise
    except Exception as exc:  # any parser failure is an unreadable file, said in one line
        raise MeasurementError(f"{path}: unreadable file ({type(exc).__name__}: {exc})".splitlines()[0]) from None


def _header_name(src: str, raw: dict[str, np.ndarray]) -> str:
    """A column map's source as the file's column name: the header's whole text ('Time [s]') names the
    column its unit was split from ('Time')."""
    m = _UNIT_IN_NAME.match(src)
    return m.group("name").strip() if src not in raw and m and m.group("name").strip() in raw else src


def _mapped_columns(path: Path, raw: dict[str, np.ndarray], cmap: dict) -> dict[str, np.ndarray]:
    """The contract's columns: mapped (and scaled) from the file's, plus unmapped contract names."""
    if not cmap:
        return {k: v for k, v in raw.items() if k in KNOWN}
    cols: dict[str, np.ndarray] = {}
    for name, (src, scale) in cmap.items():
        if src not in raw:
            raise MeasurementError(
                f"{path}: column map refers to {src!r}, which is not in the file (columns: {', '.join(raw) or 'none'})"
            )
        cols[name] = raw[src] * scale
    for name in KNOWN:  # unmapped contract columns present in the file still count
        if name in raw and name not in cols and all(src != name for src, _ in cmap.values()):
            cols[name] = raw[name]
    return cols


def _checked_input(path: Path, raw: dict, cols: dict[str, np.ndarray]) -> tuple[str, int]:
    """The one input column's name and the record's length; equal lengths, finite values."""
    inputs = [k for k in INPUTS if k in cols]
    if len(inputs) != 1:
        what = "no input column" if not inputs else "two input columns"
        raise MeasurementError(
            f"{path}: {what}; exactly one of base_acc, force is needed "
            f"(columns: {', '.join(raw) or 'none'}; map foreign names with --columns)"
        )
    n = cols[inputs[0]].size
    if n < 2:
        raise MeasurementError(f"{path}: too few samples ({n}) for a record")
    for k, v in cols.items():
        if v.size != n:
            raise MeasurementError(f"{path}: column {k} has {v.size} samples, {inputs[0]} has {n}")
    check_values(path, cols)
    return inputs[0], n


def check_values(source, cols: dict[str, np.ndarray]) -> None:
    """Every value finite and, for a contract column, within the magnitude no shaker-table record in SI
    exceeds (``units.MAGNITUDE_LIMITS``); one ``MeasurementError`` naming the column, the row and the unit."""
    from negstiff.inference.units import DIMENSIONS, MAGNITUDE_LIMITS, UNITS

    for k, v in cols.items():
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise MeasurementError(f"{source}: column {k} is NaN or inf at row {bad[0] + 1}")
        dim = DIMENSIONS.get(k)
        if dim is None or not v.size:
            continue
        limit = MAGNITUDE_LIMITS[dim]
        big = np.flatnonzero(np.abs(v) > limit)
        if big.size:
            unit = next(iter(UNITS[dim]))
            raise MeasurementError(
                f"{source}: column {k} is {v[big[0]]:.3g} {unit} at row {big[0] + 1}, beyond any shaker-table record "
                f"(|{k}| <= {limit:g} {unit}): is it in SI units? scale it with --columns {k}=COL*FACTOR"
            )


def check_sampling_rate(source, fs: float, where: str) -> float:
    """A sampling rate [Hz] within ``units.SAMPLING_RATE_RANGE_HZ``, or one ``MeasurementError`` naming
    where it came from."""
    from negstiff.inference.units import SAMPLING_RATE_RANGE_HZ

    lo, hi = SAMPLING_RATE_RANGE_HZ
    if isinstance(fs, bool) or not isinstance(fs, (int, float, np.integer, np.floating)) or not lo <= fs <= hi:
        raise MeasurementError(f"{source}: sampling rate {fs!r} Hz ({where}) is not a rate a record has "
                               f"({lo:g} to {hi:g} Hz)")  # fmt: skip
    return float(fs)


def _time_base(path: Path, cols: dict, meta: dict, fs: float | None, resolution) -> tuple[float, float, dict]:
    """(fs [Hz], t0 [s], how it was found): the caller's fs (replacing any column t), else column t
    (``time_base``: uniform within its printed precision), else the metadata's fs."""
    if fs is not None:
        fs = check_sampling_rate(path, fs, "given by the caller")
        source = f"fs = {fs:g} Hz given by the caller" + (" (replaces column t)" if "t" in cols else "")
        return float(fs), float(cols["t"][0]) if "t" in cols else 0.0, {"source": source}
    fs_meta = meta.get("fs")
    if fs_meta is not None:
        try:
            fs = float(fs_meta)
        except ValueError:
            raise MeasurementError(f"{path}: metadata fs = {fs_meta!r} is not a number") from None
        fs = check_sampling_rate(path, fs, "the metadata's fs")
    if "t" in cols:
        dt, jitter, res = time_base(cols["t"], resolution, path)
        check_sampling_rate(path, 1.0 / dt if dt > 0 else math.inf, "from column t")
        if fs is not None and abs(fs * dt - 1) > TIME_JITTER_FRACTION:
            raise MeasurementError(
                f"{path}: fs = {fs:g} Hz disagrees with column t (1/dt = {1 / dt:.6g} Hz); "
                "--fs replaces the time column"
            )
        return (
            1.0 / dt,
            float(cols["t"][0]),
            {"source": "column t (mean step)", "jitter_s": jitter, "resolution_s": res},
        )
    if fs is None:
        raise MeasurementError(f"{path}: no time base: give a column t, '# fs: ...' metadata or --fs")
    return fs, 0.0, {"source": "metadata fs"}


def time_base(t: np.ndarray, resolution: np.ndarray | None, path) -> tuple[float, float, float]:
    """The step of a time column that is uniform within its printed precision (or 1 % of a step).

    Returns (mean step [s], largest deviation from the uniform grid [s], coarsest printed
    resolution [s]). A step that is not positive, or a gap, dropout or repeated block, raises
    ``MeasurementError`` naming the first bad row (1-based data row).
    """
    n = t.size
    d = np.diff(t)
    if np.any(d <= 0):
        r = int(np.flatnonzero(d <= 0)[0]) + 2
        raise MeasurementError(
            f"{path}: column t is not increasing at row {r} (t = {t[r - 1]:.9g} s after {t[r - 2]:.9g} s)"
        )
    res = np.zeros(n) if resolution is None else np.asarray(resolution, float)
    res = res + 4 * np.spacing(np.abs(t))  # the column's own floating-point resolution
    # the typical step: the median of the printed steps, itself off by up to one printed unit
    k = int(np.argsort(d)[d.size // 2])
    step = float(d[k])
    # a step may deviate by the rounding of its two ends (half a printed unit each) plus the median's own
    # rounding, or by 1 % of a step from each end's grid position
    tol_d = np.maximum(0.5 * (res[1:] + res[:-1]) + res[k : k + 2].max(), 2 * TIME_JITTER_FRACTION * step)
    # a step half a typical step off is a gap or a repeat whatever the printing: rounding explains it only
    # where the column is printed too coarsely to show its own sampling (then --fs is the way)
    tol_d = np.minimum(tol_d, 0.5 * step)
    bad = np.flatnonzero(np.abs(d - step) > tol_d * (1 + 1e-9))
    if bad.size:
        r = int(bad[0]) + 2
        raise MeasurementError(
            f"{path}: column t is not uniformly sampled at row {r} (step {d[r - 2]:.6g} s, typical {step:.6g} s: "
            "a gap, dropout or repeated block; only rounding of the printed time is tolerated)"
        )
    i = np.arange(n) - (n - 1) / 2  # the clock's step: least squares over every sample (rounding averages out)
    dt = float(i @ (t - t.mean()) / (i @ i))
    dev = np.abs(t - (t.mean() + dt * i))
    # half a printed unit (or 1 % of a step), plus the fitted grid's own error (~ resolution / sqrt(n))
    tol = np.maximum(0.5 * res, TIME_JITTER_FRACTION * dt) + 1e-3 * res.max() + 1e-12 * dt
    slow = np.flatnonzero(dev > tol)
    if slow.size:
        r = int(slow[0]) + 1
        raise MeasurementError(
            f"{path}: column t is not uniformly sampled at row {r} (t = {t[r - 1]:.9g} s, {dev[r - 1]:.3g} s off "
            f"the uniform grid of step {dt:.6g} s; the clock drifts)"
        )
    return float(dt), float(dev.max()), float(res.max())


def from_arrays(u: np.ndarray, z: np.ndarray | None, fs: float, input_name: str = "base_acc", **kw: Any) -> Measurement:
    """Build a measurement in memory, validated like a file: 1-D arrays of one length (at least 2
    samples), finite values within a shaker-table record's magnitudes in SI units, a sampling rate a
    record has, a positive mass. Optional columns (``z_dot``, ``y``, ``base_disp``) go in ``kw``."""
    if input_name not in INPUTS:
        raise MeasurementError(f"input must be one of {INPUTS}, got {input_name!r}")
    source = kw.get("source", "<memory>")
    cols: dict[str, np.ndarray] = {}
    for name, values in ((input_name, u), ("z", z), *((k, kw[k]) for k in OPTIONAL if kw.get(k) is not None)):
        if values is None:
            continue
        try:
            arr = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            raise MeasurementError(f"{source}: {name} is not an array of numbers") from None
        if arr.ndim != 1:
            raise MeasurementError(f"{source}: {name} must be a 1-D array, got shape {arr.shape}")
        cols[name] = arr
    n = cols[input_name].size
    for name, arr in cols.items():
        if arr.size != n:
            raise MeasurementError(f"{source}: {name} has {arr.size} samples, {input_name} has {n}")
    if n < 2:
        raise MeasurementError(f"{source}: too few samples ({n}) for a record")
    check_values(source, cols)
    fs = check_sampling_rate(source, fs, "given")
    kw = {**kw, **{k: cols[k] for k in OPTIONAL if k in cols}}
    rec = Measurement(fs=fs, input_name=input_name, u=cols[input_name], z=cols.get("z"), **{**kw, "mass": None})
    return rec.with_mass(kw.get("mass"))
