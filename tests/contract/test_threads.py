"""Threads: one level of parallelism at a time (``negstiff.resources``). A command runs BLAS on one thread, as
every estimator's fit does from any entry (the numbers do not move with the load); negstiff's own threads get the
cores the process may use; inside negstiff's own parallel work (the subspace step, reproduce's section processes)
BLAS gets one thread.
"""

import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

import numpy as np
from scipy import signal
from threadpoolctl import threadpool_info, threadpool_limits

import negstiff.cli as cli
from negstiff import resources
from negstiff.cli import commands
from negstiff.inference.estimators import subspace


def _blas_threads(info=None) -> set[int]:
    return {lib["num_threads"] for lib in (info or threadpool_info()) if lib["user_api"] == "blas"}


def test_usable_cores_are_the_affinity_capped_by_negstiff_threads(monkeypatch):
    # a process pinned to one core (taskset, a container's cpuset) may use one, whatever the machine has;
    # NEGSTIFF_THREADS caps the rest
    monkeypatch.delenv("NEGSTIFF_THREADS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3}, raising=False)
    assert resources.usable_cores() == 1
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    assert resources.usable_cores() == 4
    monkeypatch.setenv("NEGSTIFF_THREADS", "2")
    assert resources.usable_cores() == 2


def test_idle_cores_leave_the_busy_ones_to_other_work(monkeypatch):
    # four usable cores: a load of 3.2 runnable processes leaves one, an idle machine all four, an
    # overloaded one still one (the process runs anyway)
    monkeypatch.delenv("NEGSTIFF_THREADS", raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    for load, idle in ((3.2, 1), (0.3, 4), (1.6, 2), (9.0, 1)):
        monkeypatch.setattr(os, "getloadavg", lambda load=load: (load, load, load))
        assert resources.idle_cores() == idle, load


def test_limit_threads_sets_numpys_and_scipys_blas_and_gives_them_back():
    # both wheels' BLAS libraries are limited (scipy's loaded first if it was not), and the context restores
    # what the process had
    before = _blas_threads()
    with resources.limit_threads(1):
        assert _blas_threads() == {1}
    assert _blas_threads() == before


def test_numbas_threads_follow_the_limit_once_its_threading_layer_runs():
    # negstiff's kernels take no numba threads, so a limit does not start numba's threading layer; once it
    # runs (a user's parallel kernel), its thread count follows the limit
    import numba

    n0 = numba.get_num_threads()  # starts the layer
    try:
        resources.limit_threads(1).restore_original_limits()
        assert numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(n0)


def test_the_subspace_step_runs_on_one_blas_thread(monkeypatch):
    # NSI's linear algebra is too small for a second BLAS thread to pay (docs/speed.md): identify limits
    # BLAS to one thread around it, whatever the process has
    seen = []
    estimate_bd = subspace.estimate_bd

    def spy(*args):
        seen.append(_blas_threads())
        return estimate_bd(*args)

    monkeypatch.setattr(subspace, "estimate_bd", spy)
    rng = np.random.default_rng(2)
    u = rng.standard_normal((3000, 2))
    # a lightly damped 50 Hz mode at 1 kHz driven by the first input, with a sensor noise floor
    num, den, _ = signal.cont2discrete(([1.0], [1.0, 2 * 0.05 * 314.0, 314.0**2]), 1e-3)
    y = signal.lfilter(num.ravel(), den, u[:, 0])
    y = (y.ravel() / y.std() + 1e-3 * rng.standard_normal(3000))[:, None]
    with threadpool_limits(limits=2):
        ss = subspace.identify(u, y, 1e-3, 2, 5)
    assert seen == [{1}]
    assert ss.lq_route == "gram", "a noise floor: the plain Cholesky factor"


def test_a_command_runs_blas_on_one_thread_on_any_load_and_gives_the_caller_its_threads_back(monkeypatch, tmp_path):
    # main() limits BLAS to one thread for the command's run only (an in-process caller keeps its own), on an idle
    # machine too: a thread count taken from the load average moved the numbers (resources.FIT_BLAS_THREADS)
    seen = []

    def fake_frf(args):
        seen.append(_blas_threads())
        return 0

    monkeypatch.setattr(os, "getloadavg", lambda: (0.0, 0.0, 0.0))
    monkeypatch.setattr(commands, "cmd_frf", fake_frf)
    data = tmp_path / "rec.csv"
    t = np.arange(2048) / 512.0
    np.savetxt(
        data, np.column_stack([t, np.sin(t), 1e-3 * np.sin(t)]), delimiter=",", header="t,base_acc,z", comments=""
    )
    before = _blas_threads()
    assert cli.main(["frf", str(data), "-o", str(tmp_path / "frf.json"), "--quiet"]) == 0
    assert seen == [{1}]
    assert _blas_threads() == before


def test_reproduces_section_processes_run_blas_on_one_thread():
    # the section processes are the parallelism: in each, every BLAS library (numpy's and scipy's) runs on
    # one thread, and negstiff's own threads get the share reproduce gives them unless the user set one
    from negstiff.experiments import reproduce

    with ProcessPoolExecutor(
        1, mp_context=get_context("spawn"), initializer=reproduce._share_cores, initargs=(2,)
    ) as pool:
        info = pool.submit(threadpool_info).result()
        threads = pool.submit(os.getenv, "NEGSTIFF_THREADS").result()
    assert _blas_threads(info) == {1}
    assert threads == os.environ.get("NEGSTIFF_THREADS", "2")


def test_the_simulators_threads_follow_the_commands_budget(monkeypatch):
    """A command's simulator batches run on the budget it sets (the cores the process may use, never a count
    read from the load): one level of parallelism, sized once; a limit set by a caller is the budget within it."""
    from negstiff.models.simulator import cores

    monkeypatch.delenv("NEGSTIFF_THREADS", raising=False)
    monkeypatch.setattr(resources, "_BUDGET", [])  # a process without a budget (a pytest-xdist worker has one)
    assert cores() == resources.usable_cores()
    with resources.limit_threads(1):
        assert cores() == 1
    assert cores() == resources.usable_cores()
    # a section process of reproduce: BLAS on one thread, its own threads on what NEGSTIFF_THREADS gives it
    monkeypatch.setenv("NEGSTIFF_THREADS", "2")
    limits = resources.worker_initializer(2)
    try:
        assert cores() == min(2, resources.usable_cores())
    finally:
        limits.restore_original_limits()
