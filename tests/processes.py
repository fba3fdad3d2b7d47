"""A command's processes as Linux's /proc shows them (the tests that interrupt a running command)."""

from pathlib import Path


def descendants(pid: int) -> list[int]:
    """The processes below ``pid`` (its children's children too), from /proc (none where there is no /proc)."""
    kids = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids += [int(k) for k in (task / "children").read_text().split()]
        except OSError:  # a task that ended while it was read
            pass
    return kids + [g for k in kids for g in descendants(k)]
