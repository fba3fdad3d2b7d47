"""CSV (and ``.txt``) records: the contract's file, and the dialects spreadsheets and DAQs write (fields
separated by ``;`` with decimal commas, tabs or blanks; a UTF-8 byte-order mark; Latin-1 text; units in the
header, ``z [mm]``). Read in chunks with a bounded memory budget; the time column's printed precision is
kept (lab exports round time).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from negstiff.errors import MeasurementError

from .base import RESOLUTION, check_memory
from .schema import CHANNEL_SENSOR, KNOWN, UNIT_IN_NAME

SUFFIXES = (".csv", ".txt")

READ_CHUNK_BYTES = 16 * 2**20
"""A text file is read in chunks of this size, each checked before the next is read."""

TEXT_PARSE_BYTES_PER_BYTE = 8
"""Memory [bytes] the parser holds per byte of a CSV file (its text, its lines and their values; 4.5
measured on a 10 MB rig record): a file whose parse would not fit in memory is refused before it is read."""


def _text(path: Path) -> str:
    """A text file's content: UTF-8 (a byte-order mark, as spreadsheets write, dropped), else Latin-1
    (older Windows exports write 'µm' so). Read in chunks with a bounded budget: a file with NUL bytes
    is not text, and is refused at the first chunk that holds one (not after reading a gigabyte).
    """
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
                    check_memory(path, size * TEXT_PARSE_BYTES_PER_BYTE)
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
    takes a digit or the decimal point for the separator of a numeric file.
    """
    # the separator is in both lines (a header's names may hold commas, a decimal-comma row holds commas)
    sep = next((d for d in (",", ";", "\t") if d in header and d in first_row), None)
    decimal_comma = sep != "," and "," in first_row
    if decimal_comma and "." in first_row:
        raise MeasurementError(
            f"{path}: the first data row mixes decimal points and commas: {first_row[:60]!r} (one decimal mark, please)"
        )
    return sep, decimal_comma


def read(path: Path) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The columns and ``# key: value`` metadata of a CSV file in any of the lab dialects."""
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
    names: list[str] = []
    for c in lines[i].split(sep):
        c = c.strip().strip('"').strip()
        m = UNIT_IN_NAME.match(c)
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
    if "t" not in names:
        _check_no_line_skipped(path, body, header_line)
    try:
        data = np.loadtxt(body, delimiter=sep, usecols=use, ndmin=2, dtype=float)
    except ValueError:
        # a value written on the first data row only (the F-16 benchmark's "Fs" column, 400 on its first row and
        # empty below): metadata, as a '# key: value' line is (an "fs" column the sampling rate); a contract column
        # (t, z, force, ... ) never is, and every other column must be numeric on every row (an empty cell in a
        # signal is a lost sample: refused, named)
        signals = {j for j in use if names[j] in KNOWN or CHANNEL_SENSOR.match(names[j])}
        header_values = {j: v for j, v in _first_row_only(body, sep, use).items() if j not in signals}
        for j, value in header_values.items():
            _header_value(path, meta, names[j], value)
        use = [j for j in use if j not in header_values]
        data = _numeric(path, body, sep, use, header_line)
    cols = {names[j]: data[:, k] for k, j in enumerate(use)}
    if "t" in names:  # the printed precision of each time value (lab exports round time)
        j = names.index("t")
        tokens = [line.partition(sep)[0] for line in body] if j == 0 and sep else [line.split(sep)[j] for line in body]
        cols[RESOLUTION] = printed_resolution(tokens, cols["t"])
    return cols, meta


def _first_row_only(body: list[str], sep: str | None, use: list[int]) -> dict[int, str]:
    """The columns of ``use`` holding a value on the first data row and nothing on any other (an empty quoted
    cell counts as nothing): {column: its value}.
    """
    if len(body) < 2:
        return {}
    rows = [[c.strip().strip('"').strip() for c in line.split(sep)] for line in body]
    first = rows[0]
    return {j: first[j] for j in use if j < len(first) and first[j] and all(j >= len(r) or not r[j] for r in rows[1:])}


def _header_value(path: Path, meta: dict[str, str], name: str, value: str) -> None:
    """A column's first-row value into ``meta`` under its name (a rate column, any case of "fs", as "fs", in Hz:
    another unit in its header is refused); one ``MeasurementError`` where the header's lines say otherwise.
    """
    key = "fs" if name.lower() == "fs" else name
    unit = meta.get(f"unit:{name}")
    if key == "fs" and unit is not None and unit.lower() != "hz":
        raise MeasurementError(f"{path}: column {name!r} states the rate in {unit!r}: give it in Hz (or --fs)")
    said = next((meta[k] for k in meta if k.lower() == key.lower()), None)
    if said is not None and not _same_number(said, value):
        raise MeasurementError(
            f"{path}: {key} is {said} in the header's '# {key}:' line and {value} in column {name!r}'s first row: "
            "which is it?"
        )
    meta[key] = value


def _same_number(a: str, b: str) -> bool:
    """Whether two metadata values are the same: as numbers where both read as numbers, else as text."""
    try:
        return float(a) == float(b)
    except ValueError:
        return a.strip() == b.strip()


def _numeric(path: Path, body: list[str], sep: str | None, use: list[int], header_line: int) -> np.ndarray:
    """The ``use`` columns of the data rows as floats, or one ``MeasurementError`` naming the first row that is not
    numeric in every one of them.
    """
    try:
        return np.loadtxt(body, delimiter=sep, usecols=use, ndmin=2, dtype=float)
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


def _check_no_line_skipped(path: Path, body: list[str], header_line: int) -> None:
    """A record without a time column (its rate from ``# fs:``) has one sample per data line: a comment or a
    blank line among them (which the parser would skip) may stand where a sample was, and a dropped sample
    is undetectable afterwards (the rest of the record would shift by one step). Refused, naming the line.
    """
    for r, line in enumerate(body):
        text = line.strip()
        if not text or text.startswith("#"):
            what = "a comment" if text else "a blank line"
            raise MeasurementError(
                f"{path}: line {header_line + r + 1} is {what} inside the data: with no t column (the rate from "
                "# fs:) a sample there would be lost without trace; remove the line, or give the t column"
            )


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
    s on a 300 s record at 512 Hz, half of reading the file; this takes 0.04 s.
    """
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


def write(path: Path, cols: dict[str, np.ndarray], fs: float, meta: dict, time_decimals: int | None = None) -> None:
    """The record as the contract's CSV: ``# key: value`` metadata lines, a header, comma-separated rows
    (``%.10g``; the time column with ``time_decimals`` fixed decimals, as a lab's export rounds it).
    """
    buf = io.StringIO()
    for k, v in meta.items():
        buf.write(f"# {k}: {v}\n")
    data = np.column_stack(list(cols.values()))
    fmt = ["%.10g"] * len(cols)
    if time_decimals is not None:
        if not 0 <= time_decimals <= 12:
            raise MeasurementError(f"time decimals must be 0..12, got {time_decimals}")
        fmt[0] = f"%.{int(time_decimals)}f"
    np.savetxt(buf, data, delimiter=",", fmt=fmt, header=",".join(cols), comments="")
    path.write_text(buf.getvalue())
