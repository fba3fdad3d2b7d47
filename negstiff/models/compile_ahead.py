"""The simulator's kernels compiled ahead of the fit that needs them, in helper processes.

numba compiles a kernel (``kernel._integrate`` at one set of its flags) on its first call and keeps it in its
on-disk cache (``cache=True``). On a fresh install the first ``identify sindy`` compiled two kernels (the
one with a smoothed sign its sgn(v) candidates run first, then the polynomial's), one after the other, 2-3 s each,
while the fit waited: +4.7 s over a later run, measured. ``start`` hands each kernel a fit will need later, and the
cache does not hold, to a helper process (``python -m negstiff.models.warm_kernels KIND``) as the fit begins,
while the fit compiles the one it needs first as usual: the two compile side by side, and the first call of a kernel
whose helper is still at work waits for it (``wait_for``), then loads it from the cache. Measured on a 300 s rig
record, 2 cores: the first ``identify sindy`` +2.5 s over a later run (+3.1-3.4 s with both kernels in helpers:
three processes on two cores while the fit prepares).

Why helper processes: numba compiles under one lock per process, so a thread cannot compile beside the fit; its
ahead-of-time compiler (``numba.pycc``) is deprecated and writes an extension module, not the cache the
dispatcher reads. Nothing here changes a number: a kernel loaded from the cache is the one compiled in the process.
A helper that fails or is slow costs nothing but the wait (``WAIT_S``): the fit then compiles the kernel itself.
``NEGSTIFF_COMPILE_AHEAD=off`` turns helpers off; so does a machine of one core, or numba's JIT disabled.
"""

from __future__ import annotations

import os
import subprocess
import sys

from .kernel import _integrate

KINDS: dict[str, tuple[int | None, ...]] = {"polynomial": (None, None, None, None, None, 1, None)}
"""The kernels a fit may hand to a helper, by ``warm_kernels`` name: ``_integrate``'s seven leading flags
(``kernel.kernel_flags``). The polynomial's: one DOF on the base, its fused step, no smoothed sign."""
WAIT_S = 60.0
"""How long the first call of a kernel waits for its helper before compiling the kernel itself [s]."""

HELPER = "negstiff.models.warm_kernels"
"""The helper's module (run as ``python -m HELPER KIND``: ``warm_kernels.warm``)."""

_PENDING: dict[tuple[int | None, ...], subprocess.Popen] = {}


def _enabled() -> bool:
    from numba.core import config

    from negstiff.resources import thread_budget

    return (os.environ.get("NEGSTIFF_COMPILE_AHEAD", "").lower() != "off" and not getattr(config, "DISABLE_JIT", False)
            and thread_budget() > 1)  # fmt: skip


def cached() -> set[tuple[int | None, ...]]:
    """The flags of every kernel numba's cache holds for this machine and this source (its index; empty when the
    cache is empty, stale or unreadable). Reads numba's private index (``FunctionCache._cache_file``): the
    dispatcher has no public way to ask without compiling.
    """
    try:
        index = _integrate._cache._cache_file._load_index()
        return {tuple(None if str(t) == "none" else 1 for t in key[0][:7]) for key in index}
    except Exception:  # noqa: BLE001 - any failure only means: do not rely on the cache
        return set()


def start(kinds) -> None:
    """Start a helper for each kernel in ``kinds`` (names in ``KINDS``) the cache does not hold and no helper is
    compiling; returns at once.
    """
    wanted = [KINDS[k] for k in kinds if KINDS[k] not in _PENDING]
    if not wanted or not _enabled():
        return
    have = cached()
    for kind, flags in KINDS.items():
        if flags in wanted and flags not in have:
            try:
                _PENDING[flags] = subprocess.Popen(
                    [sys.executable, "-m", HELPER, kind], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                    stderr=subprocess.DEVNULL, env=os.environ.copy(),
                )  # fmt: skip
            except OSError:  # no process to spare: the fit compiles the kernel itself
                pass


def wait_for(flags: tuple[int | None, ...]) -> None:
    """Before the first call of the kernel ``flags`` in this process: wait for its helper, if one is compiling it
    (at most ``WAIT_S``).
    """
    proc = _PENDING.pop(tuple(flags), None)
    if proc is not None:
        try:
            proc.wait(timeout=WAIT_S)
        except subprocess.TimeoutExpired:
            pass
