"""Files in and out, so that nothing the user gives is lost: outputs are written atomically (complete on
disk or absent, never half-written), checked before any work (``check_outputs``: never onto an input,
never onto each other, never onto something that is not a regular file, always a name the file system
takes), and inputs are read with a bounded budget (``read_bytes``, ``read_json``).

A group of outputs (a record and its truth, a result and its figure) is one ``transaction``: every file
is staged beside its place and all are moved into place at the end, or none.

A folder output (a report, a campaign) is replaced as a whole, so it is written only where nothing of the
user's is lost (``check_folder``): a new or empty folder, or one holding only what negstiff wrote there
before, as its manifest (``MANIFEST``: every file's path, size and SHA-256, written with the folder) lists
it, unchanged.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path

from negstiff.errors import InputError, OutputError

_PENDING: set[Path] = set()
"""Temporary files and folders being written now (``remove_pending`` deletes them on an interrupt)."""

_STAGED: list[tuple[int, Path, Path, bool]] = []
"""(process, temporary, final path, is a folder) of the open transaction's outputs, moved into place at its end."""

_TRANSACTION: list[int] = []
"""The process ids that hold an open transaction (a spawned or forked worker never defers)."""

TEMP_NAME_CHARS = 64
"""At most this many characters of an output's name go into its temporary name (``.NAME.xxxx.part``):
a legal 255-character name must not make an illegal temporary one."""

MANIFEST = ".negstiff-manifest.json"
"""The file a folder output holds beside what negstiff wrote there: ``{"written_by", "files": {PATH: {"bytes",
"sha256"}}}`` (paths relative to the folder, with ``/``). A later write replaces the folder only when every
file in it is listed here, unchanged (``check_folder``)."""

OUTPUT_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EIO, errno.ENAMETOOLONG,
                 errno.EACCES, errno.EPERM, errno.EISDIR, errno.ENOTDIR, errno.EXDEV}  # fmt: skip
"""What a file system says when an output cannot be written: turned into one ``OutputError`` line."""


@contextlib.contextmanager
def _signals_held():
    """Ctrl-C and a kill (SIGINT, SIGTERM) held back while a temporary output is made and registered as pending:
    delivered between the two, the command's handler (``remove_pending``) did not know the temporary yet and
    left it behind (seen once in CI: a campaign's folder, its kill sent the moment the folder appeared). Held at
    the operating system (``signal.pthread_sigmask``, POSIX; elsewhere a no-op) and delivered on release.
    """
    import signal
    import threading

    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        yield
        return
    held = {signal.SIGINT, signal.SIGTERM}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


def remove_pending() -> None:
    """Delete every temporary output still being written (an interrupted command leaves nothing)."""
    for p in list(_PENDING):
        with contextlib.suppress(OSError):
            shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
        _PENDING.discard(p)
    _STAGED.clear()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _temp_prefix(path: Path) -> str:
    return f".{path.name[:TEMP_NAME_CHARS]}."


def _in_transaction() -> bool:
    return bool(_TRANSACTION) and _TRANSACTION[-1] == os.getpid()


@contextlib.contextmanager
def _output_errors(path: Path):
    """An operating system's refusal to write ``path`` as one ``OutputError`` line."""
    try:
        yield
    except OSError as exc:
        if exc.errno in OUTPUT_ERRNOS:
            raise OutputError(f"cannot write {path}: {exc.strerror or exc} (nothing written)") from None
        raise


@contextlib.contextmanager
def transaction():
    """Every output written inside (``atomic_path``, ``atomic_dir``, ``write_text``) is staged and moved
    into place when the block ends without an exception; on an exception (or ``remove_pending``, on a
    signal) every staged output is deleted and no final path is touched.
    """
    _TRANSACTION.append(os.getpid())
    start = len(_STAGED)
    try:
        yield
    except BaseException:
        for _, tmp, _, is_dir in _STAGED[start:]:
            with contextlib.suppress(OSError):
                shutil.rmtree(tmp) if is_dir else tmp.unlink()
            _PENDING.discard(tmp)
        del _STAGED[start:]
        raise
    finally:
        _TRANSACTION.pop()
    staged = _STAGED[start:]
    del _STAGED[start:]
    try:
        for _, _, path, is_dir in staged:  # a folder that now holds a user's file: nothing is moved
            if is_dir:
                check_folder(path)
        for _, tmp, path, is_dir in staged:
            with _output_errors(path):
                _move_into_place(tmp, path, is_dir, checked=True)
    finally:
        for _, tmp, _, is_dir in staged:
            if tmp.exists():
                with contextlib.suppress(OSError):
                    shutil.rmtree(tmp) if is_dir else tmp.unlink()
            _PENDING.discard(tmp)


def _move_into_place(tmp: Path, path: Path, is_dir: bool, checked: bool = False) -> None:
    """Rename ``tmp`` to ``path``; a folder gets its manifest first and replaces an existing one only when
    ``check_folder`` allows it (looked at again here, unless ``checked`` just now).
    """
    if not is_dir:
        os.replace(tmp, path)
        return
    _write_manifest(tmp)
    if not checked:
        check_folder(path)
    if path.exists():
        old = tmp.with_name(f"{tmp.name}.old")  # unique beside it, as the temporary folder's name is
        os.replace(path, old)
        os.replace(tmp, path)
        with contextlib.suppress(OSError):
            old.unlink() if old.is_symlink() else shutil.rmtree(old)
    else:
        os.replace(tmp, path)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path beside ``path``; on success it replaces ``path`` in one rename (at the end
    of the open ``transaction``, if any). On an exception the temporary file is removed and ``path`` is
    left untouched; a file system's refusal (full disk, ...) is an ``OutputError``.
    """
    path = Path(path)
    with _output_errors(path), _signals_held():  # made and registered as pending before a signal's handler runs
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(prefix=_temp_prefix(path), suffix=".part", dir=path.parent)
        os.close(fd)
        tmp = Path(tmp_name)
        _PENDING.add(tmp)
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual permissions
    try:
        with _output_errors(path):
            yield tmp
            if _in_transaction():
                _STAGED.append((os.getpid(), tmp, path, False))
                return
            os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    finally:
        if not _in_transaction():
            _PENDING.discard(tmp)


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike):
    """Yield a temporary folder beside ``path``; on success it replaces ``path`` as a whole, with its
    manifest (``MANIFEST``). An existing ``path`` that ``check_folder`` refuses (a user's file in it, a file
    where the folder is wanted) is an ``OutputError`` and is left as it was; the caller checks it before
    its work (``check_folder``, ``check_outputs``), this is the last look.
    """
    path = Path(path)
    with _output_errors(path), _signals_held():  # made and registered as pending before a signal's handler runs
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=_temp_prefix(path), suffix=".part", dir=path.parent))
        _PENDING.add(tmp)
    os.chmod(tmp, 0o777 & ~_umask())
    try:
        with _output_errors(path):
            yield tmp
            if _in_transaction():
                _STAGED.append((os.getpid(), tmp, path, True))
                return
            _move_into_place(tmp, path, True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        if not _in_transaction():
            _PENDING.discard(tmp)


# --- inputs ------------------------------------------------------------------------------------------
JSON_MAX_BYTES = 64 * 2**20
"""A model, targets or result JSON larger than this is not one negstiff wrote or a person typed."""

JSON_MAX_DEPTH = 32
"""Nesting deeper than this is not a negstiff JSON (the deepest negstiff writes is 6)."""


def read_json(path: str | os.PathLike, what: str = "JSON"):
    """Parse a JSON file; an ``InputError`` with one line naming the file when it is missing, too
    large, not JSON, or nested deeper than ``JSON_MAX_DEPTH`` (no parser recursion reaches Python's
    limit).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    text = read_bytes(path, JSON_MAX_BYTES, what).decode("utf-8", errors="replace")
    depth = _max_depth(text)
    if depth > JSON_MAX_DEPTH:
        raise InputError(f"{path}: nested {depth} levels deep (a negstiff {what} has a few); not read")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:  # pragma: no cover - the depth check comes first
        raise InputError(f"{path}: nested too deeply to read") from None


def _max_depth(text: str) -> int:
    """The deepest bracket nesting of a JSON text, strings skipped (a linear scan, no recursion)."""
    depth = best = 0
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "[{":
            depth += 1
            best = max(best, depth)
        elif ch in "]}":
            depth -= 1
    return best


def read_bytes(path: str | os.PathLike, max_bytes: int, what: str = "file") -> bytes:
    """A file's bytes, refused with one line before reading when it is larger than ``max_bytes``."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise InputError(
                f"{path}: {size / 2**20:.4g} MiB, larger than a {what} can be ({max_bytes / 2**20:.4g} MiB); not read"
            )
        return path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None


# --- outputs, checked before any work ----------------------------------------------------------------
def name_max(folder: Path) -> int:
    """The longest file name (bytes) the file system holding ``folder`` takes (255 where it does not say)."""
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def _existing_parent(path: Path) -> Path:
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    return parent


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_outputs(
    outputs: Mapping[str, str | os.PathLike],
    inputs: Iterable[str | os.PathLike] = (),
    folders: Mapping[str, str] | None = None,
) -> dict[str, Path]:
    """Check, before any work, that every output can be written and loses nothing.

    Parameters
    ----------
    outputs : {label: path} of every file (and folder) a piece of work will write, side files
        included (a record's truth, a result's figure); labels name them in messages (``--out``).
    inputs : every file the work reads (files inside a folder input included).
    folders : {label: marker} of the outputs that are folders, replaced as a whole: an existing one only
        where ``check_folder`` allows it (the marker, the file that names negstiff's folders of versions
        before the manifest, is kept for callers; ``check_folder`` knows them all).

    Returns the outputs as absolute paths. Raises ``OutputError`` (one line) when a path is empty, is an
    input (however spelled: relative, absolute, through a symlink, a hard link, or inside a folder
    output), is another output, exists and is not a regular file (a folder, a device, a pipe), has a
    name the file system does not take, or lies in a folder that cannot be written.
    """
    folders = dict(folders or {})
    ins = [(Path(p), Path(p).resolve()) for p in inputs if str(p)]
    out: dict[str, Path] = {}
    for label, given in outputs.items():
        if not str(given).strip():
            raise OutputError(f"{label} '': an empty path; give a file name")
        path = Path(given)
        longest = name_max(_existing_parent(Path(os.path.abspath(path))))
        if len(path.name.encode()) > longest:
            raise OutputError(f"{label} {given}: the file name is longer than the file system takes "
                              f"({len(path.name.encode())} bytes, at most {longest})")  # fmt: skip
        try:
            real = path.resolve()
        except OSError as exc:
            raise OutputError(f"{label} {given}: not a path this system takes ({exc.strerror or exc})") from None
        for shown, r in ins:
            if r == real or _same_file(r, real):
                raise OutputError(f"{label} {given}: would overwrite the input {shown}; choose another path")
        for other, p in out.items():
            if p == real:
                raise OutputError(f"{label} {given} is also {other}: give them different paths")
        if label in folders:
            check_folder(given, label, [shown for shown, _ in ins])
        elif real.exists() or path.is_symlink():
            if real.is_dir():
                raise OutputError(f"{label} {given}: is a folder; give a file path")
            if real.exists() and not real.is_file():
                raise OutputError(f"{label} {given}: exists and is not a regular file (a device or a pipe?)")
        _check_writable(label, given, _existing_parent(real))
        out[label] = real
    return out


def check_folder(path: str | os.PathLike, label: str = "folder", inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """Check, before any work, that the folder output ``path`` may be replaced as a whole, losing nothing.

    It may when it does not exist, is empty, or holds only what negstiff wrote there: every file listed in
    its manifest (``MANIFEST``) with the same size and SHA-256. A folder written before the manifest
    (negstiff 0.1.0: no manifest) may when it holds only the files negstiff wrote into such a folder: a
    report's ``results.json``, ``index.md``, ``index.html`` and the figures ``index.md`` shows; a
    campaign's ``index.json``, the records it lists and their truth files.

    Parameters
    ----------
    path : the folder.
    label : how messages name it (``--out``).
    inputs : files the work reads: a folder holding one is refused.

    Returns the folder's absolute path. Raises ``OutputError`` (one line, naming the first file that would
    be lost) when the path exists and is not a folder, holds an input, or holds anything else (a user's
    file, a file changed since negstiff wrote it, a link).
    """
    given = str(path)
    if not given.strip():
        raise OutputError(f"{label} '': an empty path; give a folder")
    path = Path(path)
    try:
        real = path.resolve()
    except OSError as exc:
        raise OutputError(f"{label} {given}: not a path this system takes ({exc.strerror or exc})") from None
    for shown in inputs:
        r = Path(shown).resolve()
        if r == real or _same_file(r, real):
            raise OutputError(f"{label} {given}: is the input {shown}; choose another folder")
        if real in r.parents:
            raise OutputError(f"{label} {given}: the folder holds the input {shown}, and would be replaced")
    if path.is_symlink() and not real.exists():
        raise OutputError(f"{label} {given}: a link to nothing ({real}); give a folder")
    if not real.exists():
        return real
    if not real.is_dir():
        raise OutputError(f"{label} {given}: exists and is not a folder; give a new or empty folder")
    lost = _not_negstiffs(real)
    if lost:
        raise OutputError(f"{label} {given}: the folder holds {lost}; it would be replaced as a whole: move it "
                          "or give a new or empty folder")  # fmt: skip
    return real


def _not_negstiffs(folder: Path) -> str | None:
    """What in ``folder`` negstiff did not write there (said for a message), or None: nothing would be lost."""
    files: dict[str, Path] = {}
    subfolders: list[str] = []
    unreadable: list[OSError] = []
    for here, dirs, names in os.walk(folder, onerror=unreadable.append):
        base = Path(here)
        for name in [*dirs, *names]:
            p = base / name
            rel = p.relative_to(folder).as_posix()
            if p.is_symlink():
                return f"{rel}, a link negstiff did not make"
            if name in names:
                if not p.is_file():
                    return f"{rel}, which is not a regular file"
                files[rel] = p
            else:
                subfolders.append(rel)
    if unreadable:
        return f"{unreadable[0].filename or folder}, a folder negstiff cannot read"
    if not files and not subfolders:
        return None
    known: dict[str, tuple[int, str] | None] | None
    if MANIFEST in files:
        known = _read_manifest(folder / MANIFEST)
        if known is None:
            return f"{MANIFEST}, which is not a manifest negstiff wrote"
    else:
        known = {rel: None for rel in _written_before_the_manifest(folder)}
    for rel in subfolders:  # a folder of negstiff's holds a file it wrote
        if not any(k.startswith(rel + "/") for k in known):
            return f"{rel}/, a folder negstiff did not make there"
    for rel, p in sorted(files.items()):
        if rel == MANIFEST:
            continue
        if rel not in known:
            return f"{rel}, which negstiff did not write there"
        entry = known[rel]
        if entry is not None:  # listed in the manifest: as negstiff wrote it
            size, digest = entry
            try:
                if p.stat().st_size != size or _sha256(p) != digest:
                    return f"{rel}, changed since negstiff wrote it"
            except OSError:
                return f"{rel}, which negstiff cannot read"
    return None


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _write_manifest(folder: Path) -> None:
    """List every file in ``folder`` (the finished temporary folder) in its ``MANIFEST``."""
    from negstiff import __version__

    files = {}
    for here, _, names in os.walk(folder):
        for name in names:
            p = Path(here) / name
            rel = p.relative_to(folder).as_posix()
            if rel != MANIFEST:
                files[rel] = {"bytes": p.stat().st_size, "sha256": _sha256(p)}
    doc = {"written_by": f"negstiff {__version__}", "files": dict(sorted(files.items()))}
    (folder / MANIFEST).write_text(json.dumps(doc, indent=1) + "\n")


def _read_manifest(path: Path) -> dict[str, tuple[int, str] | None] | None:
    """{path: (bytes, sha256)} of a manifest, or None when it is not one."""
    try:
        files = read_json(path, "manifest")["files"]
        return {str(k): (int(v["bytes"]), str(v["sha256"])) for k, v in files.items()}
    except (InputError, KeyError, TypeError, ValueError, AttributeError):
        return None


REPORT_FIGURE = re.compile(r"\]\(([^()\s/\\]+\.png)\)")
"""A figure's link in a report's index.md (``![caption](name.png)``)."""


def _written_before_the_manifest(folder: Path) -> set[str]:
    """The files negstiff wrote into a report or campaign folder before it wrote a manifest there (its
    marker file present: ``results.json``, ``index.json``); empty when neither is there.
    """
    known: set[str] = set()
    if (folder / "results.json").is_file():  # a report: its figures are the PNGs index.md shows
        known |= {"results.json", "index.md", "index.html"}
        md = folder / "index.md"
        if md.is_file():
            with contextlib.suppress(InputError):
                text = read_bytes(md, JSON_MAX_BYTES, "report").decode("utf-8", errors="replace")
                known |= set(REPORT_FIGURE.findall(text))
    if (folder / "index.json").is_file():  # a campaign: the records its index lists, each with its truth
        try:
            names = [r["file"] for r in read_json(folder / "index.json", "campaign index")["records"]]
        except (InputError, KeyError, TypeError):
            names = []
        known.add("index.json")
        for name in names:
            if isinstance(name, str) and name and "/" not in name and "\\" not in name:
                known |= {name, Path(name).stem + ".truth.json"}
    return known


def _check_writable(label: str, given, parent: Path) -> None:
    """An output's folder (where its temporary file, or a folder output's temporary folder, is made)."""
    try:  # the one sure test of a folder's writability: write in it
        if not parent.is_dir():
            raise OSError
        fd, probe = tempfile.mkstemp(prefix=".negstiff-probe.", dir=parent)
        os.close(fd)
        os.unlink(probe)
    except OSError:
        raise OutputError(f"{label} {given}: cannot write there ({parent} is not a writable folder)") from None
