"""What the machine can hold: a piece of work whose arrays would not fit in memory is refused with one
line before anything is allocated (a 1e5 s record at 1 MHz asks for terabytes), instead of failing
inside numpy, or being killed by the operating system with no message.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable

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


# --- threads -------------------------------------------------------------------------------------------
# One level of parallelism at a time: a process's BLAS threads get the cores it may use and nobody else is
# using; inside negstiff's own parallel work (a pool of section processes, the simulator's batch threads)
# BLAS gets one. Measured (docs/speed.md): NSI's second BLAS thread gains nothing alone and costs 6-15x the
# CPU time beside other work (OpenBLAS's threads spin while they wait for a core).


def usable_cores() -> int:
    """The cores this process may run on: its CPU affinity (``os.sched_getaffinity``: a ``taskset``, a
    container's cpuset), else the machine's count; ``$NEGSTIFF_THREADS`` caps it (a machine shared with
    other jobs).
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not on every platform (macOS, Windows)
        cores = os.cpu_count() or 1
    env = os.environ.get("NEGSTIFF_THREADS", "")
    if env.isdigit():
        cores = min(cores, int(env))
    return max(1, cores)


def idle_cores() -> int:
    """The usable cores (``usable_cores``) that other work is not using now: minus the one-minute load
    average (runnable processes, rounded), at least one. Read when a process starts, before it adds to
    the load itself. No thread count that can change a number is taken from it (``FIT_BLAS_THREADS``).
    """
    cores = usable_cores()
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):  # no load average on this platform
        return cores
    return max(1, min(cores, cores - round(load)))


_BUDGET: list[int] = []
"""The thread budget of the running command (``limit_threads``), read by negstiff's own thread pools."""


def thread_budget() -> int:
    """The threads negstiff's own pools (the simulator's batches) may use: the running command's budget
    (``limit_threads``: the usable cores), else the usable cores (``usable_cores``).
    """
    return _BUDGET[-1] if _BUDGET else usable_cores()


def _load_blas() -> None:
    """Load numpy's and scipy's linear algebra: each wheel carries its own OpenBLAS, and threadpoolctl
    limits only the libraries loaded when it is called.
    """
    import numpy.linalg  # noqa: F401
    import scipy.linalg  # noqa: F401


@functools.cache
def _blas_controller():
    """The threadpoolctl controller of numpy's and scipy's BLAS (both loaded first: ``_load_blas``), made once per
    process. ``threadpool_limits`` makes a new controller at every call, which finds the process's thread pools by
    walking its loaded libraries: 1.7 ms a call, and a fit, a record read and each subspace step call it (a 9 Hz
    bifurcation map's 444 records spent 0.8 s in it, measured). The limits set through it are threadpoolctl's own.
    """
    from threadpoolctl import ThreadpoolController

    _load_blas()
    return ThreadpoolController().select(user_api="blas")


def limit_threads(n: int, own: int | None = None):
    """Limit the process's BLAS and OpenMP thread pools to ``n`` threads (threadpoolctl), and numba's where
    its threading layer runs: at once, for the whole process (a worker process's initialiser), or until the
    returned context exits (a command). negstiff's compiled kernels take no numba threads (its simulator
    splits batches over its own threads, ``models.simulator.cores``), so numba's layer is not started for
    nothing; those own threads get ``own`` (default ``n``: ``thread_budget``).
    """
    from threadpoolctl import threadpool_limits

    _load_blas()
    limiter = _Budget(threadpool_limits(limits=max(1, int(n))), max(1, int(n if own is None else own)))
    try:
        import numba
        from numba.np.ufunc import parallel
    except ImportError:  # pragma: no cover - numba is a dependency
        return limiter
    if getattr(parallel, "_is_initialized", True):
        numba.set_num_threads(max(1, min(int(n), getattr(numba.config, "NUMBA_NUM_THREADS", 1))))
    return limiter


class _Budget:
    """threadpoolctl's limits and negstiff's own thread budget (``thread_budget``: the simulator's pools), set
    together and given back together when the context exits.
    """

    def __init__(self, limiter, n: int):
        self.limiter = limiter
        _BUDGET.append(n)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        if _BUDGET:
            _BUDGET.pop()
        self.limiter.restore_original_limits()

    def restore_original_limits(self) -> None:
        """Give the BLAS pools and the budget back (threadpoolctl's name)."""
        self.__exit__(None, None, None)


FIT_BLAS_THREADS = 1
"""The BLAS threads an estimator's ``fit`` runs its linear algebra on, from any entry (a script, the command
line, a dask worker) and on any load: a fixed number, because a sum split over threads is added in another order
(the same record's refined k1 read 381.6666 from Python and 381.6463 from the command, which had set its BLAS
threads from the idle cores). One, because a second buys nothing on the estimators' small products and costs
6-15x the CPU time beside other work (docs/speed.md)."""


def fit_threads():
    """The context an estimator's ``fit`` runs in (``Estimator``): BLAS on ``FIT_BLAS_THREADS``, whatever the
    process's pool; the caller's pool is given back when it exits.
    """
    return _blas_controller().limit(limits=FIT_BLAS_THREADS, user_api="blas")


def on_fit_threads[**P, R](func: Callable[P, R]) -> Callable[P, R]:
    """``func`` run in ``fit_threads``: its linear algebra on ``FIT_BLAS_THREADS`` from any entry. An estimator's
    ``fit`` runs so, and reading a record does too: a record's time base is a least-squares slope (a BLAS dot
    product), and a sum split over two threads is added in another order: a script's ``load`` read the sampling
    rate 511.99999999997783 Hz, the command's (BLAS on one thread) 511.9999999999777, and a structure's NSI k3
    then differed by 4.5e-9 between them (measured).
    """

    @functools.wraps(func)
    def on_fit_threads(*args: P.args, **kwargs: P.kwargs) -> R:
        with fit_threads():
            return func(*args, **kwargs)

    return on_fit_threads


def one_blas_thread():
    """A context in which BLAS runs on one thread (``threadpoolctl.threadpool_limits``): around linear
    algebra too small for a second thread to pay, or inside negstiff's own threads.
    """
    return _blas_controller().limit(limits=1, user_api="blas")


def worker_initializer(threads: int | None = None):
    """A worker process's start, in a pool of them (``concurrent.futures``' ``initializer``): BLAS, OpenMP
    and numba on one thread each (the pool is the parallelism); ``threads``, where given, is what
    negstiff's own threads may use (``$NEGSTIFF_THREADS``, unless the user set it). Returns the limits (a
    caller in its own process gives them back with ``restore_original_limits``).
    """
    if threads is not None:
        os.environ.setdefault("NEGSTIFF_THREADS", str(int(threads)))
    _thread_lock_for_bars()
    return limit_threads(1, own=usable_cores())


def _thread_lock_for_bars() -> None:
    """A worker's progress bars (tqdm) share a thread lock, not tqdm's default multiprocessing lock: that is a
    semaphore the resource tracker reports as leaked when the worker is ended (Ctrl-C on reproduce printed
    "There appear to be 2 leaked semaphore objects"); a worker's bars are its own.
    """
    try:
        from tqdm.std import TqdmDefaultWriteLock
    except ImportError:  # pragma: no cover - tqdm is a dependency
        return
    if not hasattr(TqdmDefaultWriteLock, "mp_lock"):
        TqdmDefaultWriteLock.mp_lock = None
