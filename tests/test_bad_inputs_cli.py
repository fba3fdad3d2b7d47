"""The third bad-input probe (issue "Nothing lost, round three"), kept as tests: Ctrl-C from the first
millisecond, lab formats checked against their own headers, the wrong acceptances, the refusals made
before the work, and the library's errors that are negstiff's. Each case is refused cleanly (exit 2, one
line on stderr, no traceback, nothing written, every input byte-identical; in Python one ``InputError``)
or, where the input is legal, read to a sound result."""

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from negstiff.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _snapshot(d: Path) -> dict:
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*"))
            if p.is_file() and not p.is_symlink()}  # fmt: skip


def refused(folder: Path, capsys, argv, outputs=()) -> str:
    """Exit 2, one line naming an error, no traceback, no output written, every file of ``folder``
    unchanged."""
    before = _snapshot(folder)
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's errors
        rc = exc.code
    err = capsys.readouterr().err
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert rc == 2, f"exit {rc} for {argv}: {err}"
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in err, err
    for o in outputs:
        assert not os.path.exists(o), f"{o} was written"
    assert _snapshot(folder) == before, "an input was modified"
    return lines[0]


# --- Ctrl-C: one line and exit 130 from the first millisecond ----------------------------------------------
def _mapped(pid: int, name: str) -> bool:
    """Whether process ``pid`` has loaded a shared object whose path holds ``name`` (Linux's /proc)."""
    try:
        return name in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def _commands():
    yield [sys.executable, "-m", "negstiff"]
    script = shutil.which("negstiff", path=os.path.dirname(sys.executable))
    if script:  # the console entry (negstiff.cli:run), as installed
        yield [script]


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs Linux's /proc to see the imports")
@pytest.mark.parametrize("command", list(_commands()), ids=lambda c: "console" if len(c) == 1 else "module")
def test_ctrl_c_during_the_imports_is_one_line_and_exit_130(command, tmp_path):
    # the probe: Ctrl-C while numpy imports (the first second of every command) printed a traceback of
    # 10-29 lines. numpy's compiled core appearing in the process's memory map is the moment the heavy
    # imports are under way; the interrupt then must end the command with one line and exit 130
    out = tmp_path / "r.json"
    p = subprocess.Popen([*command, "frf", str(tmp_path / "rec.csv"), "-o", str(out)], stderr=subprocess.PIPE,
                         stdout=subprocess.DEVNULL, text=True, cwd=tmp_path)  # fmt: skip
    deadline = time.monotonic() + 60
    while not _mapped(p.pid, "_multiarray_umath") and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.0005)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err and "Traceback" not in err, err
    assert not out.exists()


def _descendants(pid: int) -> list[int]:
    """The processes below ``pid`` (its children's children too), from /proc."""
    kids = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids += [int(k) for k in (task / "children").read_text().split()]
        except OSError:
            pass
    return kids + [g for k in kids for g in _descendants(k)]


def _running_in_group(pgid: int) -> list[int]:
    """The processes of process group ``pgid`` that are alive (not zombies waiting to be reaped)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] not in "ZX":
            alive.append(int(stat.parent.name))
    return alive


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux's /proc to see the workers")
def test_ctrl_c_on_reproduce_is_one_line_and_the_workers_go_quietly(tmp_path):
    # the probe: Ctrl-C on reproduce printed the parent's one line, then each spawned worker's
    # KeyboardInterrupt traceback and the resource tracker's "5 leaked semaphore objects" (76-130 lines).
    # A terminal's Ctrl-C reaches the whole process group: it is sent so here, a second after the
    # section processes started (while they import and begin their sections)
    out = tmp_path / "report"
    env = dict(os.environ, NEGSTIFF_CACHE="off")
    p = subprocess.Popen([sys.executable, "-m", "negstiff", "reproduce", "--fast", "--quiet", "-o", str(out)],
                         stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=tmp_path, env=env,
                         start_new_session=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while len(_descendants(p.pid)) < 3 and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the resource tracker and two section processes
    assert p.poll() is None, p.communicate()[1]
    time.sleep(1.5)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=90)  # stderr closes once every process holding it (workers, tracker) ended
    assert p.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err, err
    assert "Traceback" not in err and "leaked" not in err, err
    assert not out.exists()
    time.sleep(0.5)
    assert not _running_in_group(p.pid), "a process of the command is still running"
