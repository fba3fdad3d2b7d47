"""What the machine can hold: a piece of work whose arrays would not fit in memory is refused with one
line before anything is allocated (a 1e5 s record at 1 MHz asks for terabytes), instead of failing
inside numpy, or being killed by the operating system with no message.
"""

from __future__ import annotations

import os

from negstiff.errors import InputError

MEMORY_SHARE = 0.75
"""A single piece of work may plan on at most this share of the memory available when it starts."""


def available_memory() -> int:
    """Bytes of memory available now: the kernel's MemAvailable (Linux), else the physical memory, else 8 GiB."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (OSError, ValueError, AttributeError):
        return 8 * 2**30


def require_memory(nbytes: float, what: str) -> None:
    """Raise ``InputError`` (one line, naming ``what`` and both sizes) unless ``nbytes`` fits in
    ``MEMORY_SHARE`` of the available memory.
    """
    budget = MEMORY_SHARE * available_memory()
    if not nbytes <= budget:
        raise InputError(
            f"{what} would need about {_size(nbytes)} of memory; this machine has {_size(budget / MEMORY_SHARE)} "
            "available: ask for less"
        )


def _size(nbytes: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes / 2**10:.3g} KiB"
