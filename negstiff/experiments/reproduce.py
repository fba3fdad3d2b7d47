"""``negstiff reproduce``: the reference study's study end to end on the virtual rig, as one report.

Sections grow as the suite's capabilities land; each states what it measured and where it differs
from the reference study. Every number in the report is taken from the ``results`` dict that is also written
as ``results.json``.
"""

from __future__ import annotations

import os
import signal as posix_signal
import sys
import threading
import time
import warnings
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from scipy import signal
from tqdm import tqdm

from negstiff import __version__
from negstiff.files import check_folder
from negstiff.models import AS_BUILT, simulate
from negstiff.models.reference import reference_solution
from negstiff.models.rig import Rig
from negstiff.models.warm_kernels import warm
from negstiff.report.document import Report
from negstiff.report.numbers import fmt
from negstiff.resources import worker_initializer

from .calibration import device_section
from .characterisation import characterisation_section
from .continuation import continuation_section
from .discrepancy import discrepancy_section
from .findings import conclusion, summary_lines
from .fixture import fixture_section
from .nsi import nsi_section
from .posterior import posterior_section
from .silverbox import silverbox_section
from .sindy import sindy_section
from .updating import updating_section

CACHE_ENV = "NEGSTIFF_CACHE"
"""Environment variable naming the section cache folder (default ~/.cache/negstiff; "off" disables it)."""


def _cache_dir() -> Path | None:
    v = os.environ.get(CACHE_ENV)
    if v and v.lower() == "off":
        return None
    return Path(v) if v else Path.home() / ".cache" / "negstiff"


def _source_hash() -> str:
    """Hash of the package's source (every module of ``negstiff``): a code change invalidates the cache."""
    import hashlib

    import negstiff

    folder = Path(negstiff.__file__).resolve().parent
    h = hashlib.sha256()
    for f in sorted(folder.rglob("*.py")):  # subpackages too (inference/estimators/posterior)
        h.update(str(f.relative_to(folder)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def _cache_path(name: str, fast: bool, seed: int, source: str) -> Path | None:
    """Where section ``name``'s payload is cached, keyed by its inputs and ``source`` (``_source_hash``)."""
    import hashlib

    cdir = _cache_dir()
    key = hashlib.sha256(f"{name}|{fast}|{seed}|{__version__}|{source}".encode()).hexdigest()[:24]
    return None if cdir is None else cdir / f"{name}-{key}.pkl"


def _cached(path: Path | None):
    """A section's stored (blocks, figures, results), or None (no cache, none stored, a broken entry)."""
    import pickle

    if path is None or not path.is_file():
        return None
    try:
        return pickle.loads(path.read_bytes())
    except Exception:  # noqa: BLE001 - a stale or broken cache entry is recomputed
        return None


def _store(path: Path | None, payload, say) -> None:
    import pickle

    from negstiff.files import atomic_path

    if path is None:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            tmp.write_bytes(pickle.dumps(payload))
    except OSError as exc:
        say(f"could not write the cache {path} ({exc})")


def compute_section(name: str, fast: bool, seed: int):
    """One section of ``SECTION_TABLE`` computed and rendered on its own: (blocks, figures, results),
    each result stamped with the section's time. Picklable in and out: a worker process runs it.
    """
    fn = _TABLE[name][1]
    sub = Report("")
    res: dict[str, Any] = {}
    t0 = time.perf_counter()
    fn(sub, res, fast, seed)
    for v in res.values():
        if isinstance(v, dict):
            v.setdefault("section_elapsed_s", time.perf_counter() - t0)
    return sub.blocks, sub.figures, res


def _merge(rep: Report, results: dict[str, Any], payload) -> None:
    blocks, figures, res = payload
    rep.blocks += blocks
    rep.figures.update(figures)
    results.update(res)


KERNELS = ("polynomial", "device", "polynomial_sign", "hybrid", "benettin", "structure")
"""The compiled kernels a full run uses, in the order the sections first need them."""

ALL_KERNELS = (*KERNELS, "table", "generic", "device_sign")
"""Every kernel ``warm_kernel`` compiles: the models' (``models.warm_kernels.KERNELS``) and the hybrid model's."""


def warm_kernel(name: str) -> None:
    """Compile one of ``ALL_KERNELS`` (or load it from numba's cache) with a tiny call. A fresh install's
    first run queues these before the sections: each kernel is compiled once, the two workers each
    taking some, instead of by every section process that reaches it first (~6 s a kernel alone; the
    fresh run took 31 s longer than a cached one, measured).
    """
    if name != "hybrid":
        warm(name)
        return
    from negstiff.inference.estimators.hybrid import Basis, simulate_hybrid
    from negstiff.models import SEED_LIKE_CUBIC

    basis = Basis.over(np.linspace(-1, 1, 9), np.linspace(-1, 1, 9), np.linspace(-1, 1, 9), 2, 2, 2)
    simulate_hybrid(SEED_LIKE_CUBIC, basis, np.zeros(basis.size), np.zeros((1, 9)), 1e-3, np.zeros((1, 2)), 2,
                    "base_acc", 1.0, 100.0)  # fmt: skip


WORKER_MEMORY_BYTES = 2 * 1024**3
"""What one section process may hold at its peak (measured up to ~1.6 GB: the posterior section)."""


def default_workers() -> int:
    """Processes for the sections by default: the machine's cores, but no more than the sections (with the
    rig's) nor than its memory holds at ``WORKER_MEMORY_BYTES`` each.
    """
    cores = os.cpu_count() or 1
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):  # not on every platform
        memory = cores * WORKER_MEMORY_BYTES
    return max(1, min(cores, len(_TABLE), memory // WORKER_MEMORY_BYTES))


def _share_cores(threads: int):
    """A section process's initialiser: BLAS, OpenMP and numba on one thread each, the processes being the
    parallelism (``resources.worker_initializer``; a user's measurement on 2 cores: two section processes
    with two BLAS threads each took 196 s wall and 360 s of CPU, with one each 160 s and 280 s); negstiff's
    own threads (simulator batches, posterior ensembles) get ``threads``, unless the user set
    ``NEGSTIFF_THREADS``. A section's warnings are in its results, not on the command's stderr (as the command's
    own: ``cli.main``; a ConvergenceWarning printed beside Ctrl-C's one line). Returns the limits
    (``worker_initializer``).
    """
    warnings.simplefilter("ignore")
    return worker_initializer(threads)


def _no_bar(name: str | None = None) -> None:
    """``run_sections``' default ``tick``: no progress bar."""


def run_sections(names, fast: bool, seed: int, workers: int, say, tick=_no_bar) -> dict[str, Any]:
    """The sections ``names``, replayed from the cache when their inputs (the section, --fast, the seed
    and the package's source) are unchanged (each stored as pickled blocks, figures and results, written
    atomically), else computed on ``workers`` processes at once, the longest first (``SECTION_TABLE``'s
    measured cost); returns name -> (blocks, figures, results). The
    sections are independent (each seeds its own draws), so the numbers are those of a serial run.
    ``tick(name)`` is called as each section is done (``tick(None)`` about every second while they run:
    the progress bar's clock).
    """
    out: dict[str, Any] = {}
    source = _source_hash()  # read and hashed once, not per section
    paths = {n: _cache_path(n, fast, seed, source) for n in names}
    for n in names:
        payload = _cached(paths[n])
        if payload is not None:
            say(f"{n}: from the cache ({paths[n]})")
            out[n] = payload
            tick(n)
    todo = [n for n in names if n not in out]
    if workers <= 1 or len(todo) <= 1:
        for n in todo:  # in the report's order
            say(_TABLE[n][0])
            out[n] = compute_section(n, fast, seed)
            _store(paths[n], out[n], say)
            tick(n)
        return out
    todo.sort(key=lambda n: -_TABLE[n][2])
    return _run_pool(todo, out, paths, fast, seed, workers, say, tick)


def _run_pool(todo, out, paths, fast: bool, seed: int, workers: int, say, tick) -> dict[str, Any]:
    """``run_sections``' parallel part: the kernels' warm-up, then the sections, on ``workers`` processes.
    Each process's own threads (posterior ensembles, simulator batches) get the cores divided among the
    processes, but at least two: on 2 cores each may use both (capping them at one per process,
    ``NEGSTIFF_THREADS=1``, did not shorten the run: 236 s against 187-224 s, on a machine whose speed
    drifted by 1.7x over the evening), while on many cores the processes' threads do not multiply.
    """
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from multiprocessing import get_context

    threads = max(2, (os.cpu_count() or 1) // workers)
    # Ctrl-C reaches the whole process group: the section processes ignore it and this process answers for
    # them (``_stop_workers``: they are ended before its one line, with no traceback of theirs and nothing
    # left running). They ignore it from their first instruction: started while this process ignores SIGINT,
    # which a spawned Python keeps (a handler set in the initialiser would come after a second of imports)
    answer = threading.current_thread() is threading.main_thread()
    previous = posix_signal.getsignal(posix_signal.SIGINT) if answer else None
    # spawn, not fork: the parent's numba and BLAS thread pools do not survive a fork
    pool = ProcessPoolExecutor(
        max_workers=workers, mp_context=get_context("spawn"), initializer=_share_cores, initargs=(threads,)
    )
    try:
        if answer:  # a Ctrl-C in the milliseconds the processes take to start is lost (press it again)
            posix_signal.signal(posix_signal.SIGINT, posix_signal.SIG_IGN)
        for k in KERNELS:  # first in the queue: compiled once each (loaded, once numba has cached them)
            pool.submit(warm_kernel, k)  # the first submissions start the processes, every one of them
        futures = {pool.submit(compute_section, n, fast, seed): n for n in todo}
        if answer and previous is not posix_signal.SIG_IGN:  # Ctrl-C: KeyboardInterrupt, caught below
            posix_signal.signal(posix_signal.SIGINT, posix_signal.default_int_handler)
        say(f"{len(todo)} sections on {workers} processes: {', '.join(todo)}")
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, timeout=1.0, return_when=FIRST_COMPLETED)
            tick(None)
            for fut in finished:
                n = futures[fut]
                out[n] = fut.result()  # a section's failure: those finished are cached (a rerun replays them)
                _store(paths[n], out[n], say)
                say(f"{_TABLE[n][0]}: done")
                tick(n)
    except BaseException:  # Ctrl-C, or a section failed: the sections still running are stopped, not waited for
        if answer:  # a second Ctrl-C does not cut the teardown short
            posix_signal.signal(posix_signal.SIGINT, posix_signal.SIG_IGN)
        _stop_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if answer:
            posix_signal.signal(posix_signal.SIGINT, previous)
    return out


def _stop_workers(pool) -> None:
    """End ``pool``'s processes now (SIGTERM: no traceback of theirs) and wait for them, so that the pool's
    queues are released (the resource tracker then has no semaphore to report). ``concurrent.futures``
    gives no public way before Python 3.14 (``terminate_workers``); its process table is used until then.
    """
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
        return
    processes = list((getattr(pool, "_processes", None) or {}).values())
    for p in processes:
        p.terminate()
    for p in processes:
        p.join(timeout=30)


def simulator_accuracy(duration: float = 10.0, fs: float = 512.0, amplitude: float = 3.0) -> dict[str, Any]:
    """Max |dz| of the simulator against scipy's DOP853 (rtol 1e-10) on an in-well 9 Hz response,
    both driven by the same linearly interpolated input.
    """
    dt = 1 / fs
    t = np.arange(0, duration, dt)
    u = amplitude * np.sin(2 * np.pi * 9.0 * t)
    zp = AS_BUILT.equilibria().z_plus
    ours = simulate(AS_BUILT, u, dt, z0=zp).z[0]

    ref = reference_solution(AS_BUILT, u, dt, zp)
    return {
        "max_abs_dz_m": float(np.max(np.abs(ours - ref))),
        "response_peak_to_peak_m": float(np.ptp(ref)),
        "duration_s": duration,
        "reference": "scipy DOP853 rtol 1e-10, per sample interval",
    }


def rig_section(rep: Report, results: dict[str, Any], fast: bool, seed: int) -> None:
    duration = 60.0 if fast else 300.0
    rec = Rig(seed=seed).random(duration=duration)
    z, zt = rec.columns["z"], rec.true["z"]
    eq = AS_BUILT.equilibria()
    crossings = int(np.count_nonzero(np.diff(np.sign(zt - eq.z_0))))
    n = z.size
    k0 = int(0.8 * n)
    # the true model's own free-run error over the held-out tail: the floor any identified model faces
    sim = simulate(AS_BUILT, rec.columns["base_acc"][k0:], 1 / rec.fs, z0=zt[k0], v0=rec.true["z_dot"][k0])
    floor = 100 * np.sqrt(np.mean((sim.z[0] - z[k0:]) ** 2)) / np.sqrt(np.mean(z[k0:] ** 2))
    r = {
        "duration_s": duration,
        "rms_m_s2": rec.truth["excitation"]["rms_m_s2"],
        "crossings": crossings,
        "crossings_per_min": crossings / duration * 60,
        "z_error_std_m": float(np.std(z - zt)),
        "base_disp_error_std_m": float(np.std(rec.columns["base_disp"] - rec.true["base_disp"])),
        "true_model_floor_rms_percent": float(floor),
        "sensors": rec.truth["sensors"],
    }
    results["rig"] = r
    rep.heading("2. The virtual test rig")
    rep.text(
        f"A {duration:g} s band-limited random record (2-40 Hz, {fmt(r['rms_m_s2'])} m/s^2 rms) of the as-built "
        f"device, measured as the paper's lab did: laser for y, accelerometer for the table, base displacement by "
        f"double integration (high-passed), z = y - b. The device crossed between the wells {crossings} times "
        f"({fmt(r['crossings_per_min'], 3)} per minute). The measured z differs from the true z by "
        f"{fmt(r['z_error_std_m'] * 1e6, 3)} um rms, mostly the low-frequency error of the integrated base "
        f"displacement ({fmt(r['base_disp_error_std_m'] * 1e6, 3)} um rms) on top of the laser noise."
    )
    rep.text(
        f"Floor: the TRUE model, fed the measured input and started from the true state, reproduces the last 20 % "
        f"of the record with rms error {fmt(floor, 3)} % of rms(z). No identified model can be expected to beat "
        "this on the same record; every validation figure in this report should be read against it."
    )
    t = rec.columns["t"]
    fig, ax = plt.subplots(2, 1, figsize=(10, 5), sharex=True)
    ax[0].plot(t, rec.columns["base_acc"], lw=0.4)
    ax[0].set(ylabel="base_acc [m/s^2]")
    ax[1].plot(t, z * 1e3, lw=0.4, label="measured z")
    for zz, lab in ((eq.z_minus, "z_minus"), (eq.z_0, "z_0"), (eq.z_plus, "z_plus")):
        ax[1].axhline(zz * 1e3, color="0.5", lw=0.8, ls="--")
        ax[1].text(t[-1], zz * 1e3, " " + lab, va="center", fontsize=8)
    ax[1].set(xlabel="t [s]", ylabel="z [mm]")
    rep.figure(
        "rig_random",
        fig,
        "A random cross-well rig record: table acceleration and relative displacement, "
        "with the equilibria of the as-built device.",
    )
    f, pz = signal.welch(z, rec.fs, nperseg=4096)
    _, pe = signal.welch(z - zt, rec.fs, nperseg=4096)
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.semilogy(f, pz, label="measured z")
    ax.semilogy(f, pe, label="measured z - true z (sensor chain error)")
    ax.set(xlabel="f [Hz]", ylabel="PSD [m^2/Hz]", xlim=(0, 100))
    ax.legend(fontsize=8)
    rep.figure("rig_psd", fig, "Power spectral density of the measured z and of its error against the truth.")


def simulator_section(rep: Report, results: dict[str, Any]) -> None:
    acc = simulator_accuracy()
    results["simulator"] = acc
    rep.heading("3. Simulator accuracy")
    rep.text(
        f"Against scipy's adaptive DOP853 (rtol 1e-10, restarted at every sample so the input's kinks cost "
        f"nothing) on a {acc['duration_s']:g} s in-well 9 Hz response of the "
        f"as-built device (peak-to-peak {fmt(acc['response_peak_to_peak_m'] * 1e3, 3)} mm), the numba RK4 "
        f"simulator at its default settings (2 substeps per sample) differs by at most "
        f"{fmt(acc['max_abs_dz_m'])} m (target: below 1e-7 m). Speed is measured in reports/benchmarks.md."
    )


SECTION_TABLE = {
    "nsi": ("NSI around both wells", nsi_section, 26),
    "updating": ("GA model updating", updating_section, 50),
    "characterisation": ("dynamics characterisation", characterisation_section, 21),
    "sindy": ("SINDy equation discovery", sindy_section, 12),
    "posterior": ("Bayesian posteriors (emcee)", posterior_section, 79),
    "discrepancy": ("discrepancy workflow", discrepancy_section, 32),
    "silverbox": ("Silverbox benchmark (real data)", silverbox_section, 54),
    "continuation": ("continuation against the bifurcation map", continuation_section, 58),
    "fixture": ("a fixture that is not rigid (2 DOF)", fixture_section, 25),
}
"""name -> (title, section function, seconds it took in a full run: the order the workers take them)."""

SECTIONS = tuple(SECTION_TABLE)


def base_section(rep: Report, results: dict[str, Any], fast: bool, seed: int = 0) -> None:
    """The parts every run has after the device's: the virtual rig's record and the simulator's accuracy
    (computed beside the sections: run first and alone they kept one core idle for 8 s).
    """
    rig_section(rep, results, fast, seed)
    simulator_section(rep, results)


_TABLE = {"rig": ("virtual rig record and simulator accuracy", base_section, 3), **SECTION_TABLE}


def reproduce(
    out: Path, fast: bool = False, seed: int = 0, progress: bool = True, sections=None, workers: int | None = None
) -> Path:
    """Run the study and write the report folder ``out`` (atomically). ``sections``: run only these of
    ``SECTIONS`` (the device, rig and simulator parts always run; the report says which were left out).
    ``workers``: processes computing sections at once (default: the machine's cores).
    """
    check_folder(out, "report folder")  # a folder holding a user's file: refused before the study, not after
    workers = default_workers() if workers is None else max(1, int(workers))
    if sections is not None and not set(sections) <= set(SECTIONS):
        raise ValueError(f"unknown sections {sorted(set(sections) - set(SECTIONS))}; known: {SECTIONS}")
    t_start = time.perf_counter()
    names = ["rig"] + [n for n in SECTIONS if sections is None or n in sections]
    # one bar over the sections (tqdm: its messages printed above it), its clock refreshed while they run
    bar = tqdm(total=len(names), desc="reproduce", unit="section", disable=not progress, file=sys.stderr)

    def say(msg: str) -> None:
        if progress:
            bar.write(f"[reproduce {time.perf_counter() - t_start:6.1f} s] {msg}", file=sys.stderr)

    def tick(name: str | None) -> None:
        if name is None:
            bar.refresh()
        else:
            bar.set_postfix_str(name, refresh=False)
            bar.update(1)

    rep = Report("negstiff: nonlinear dynamics of a negative-stiffness oscillator, reproduced on a virtual rig")
    results: dict[str, Any] = {"negstiff_version": __version__, "fast": fast, "seed": seed}
    rep.text(
        "This report reruns the study of Anastasio, Fasana, Garibaldi and Marchesiello (EURODYN 2020), the "
        "reference study, on a virtual shaking table whose truth is known, and sets the reference study's numbers "
        "beside ours and the truth's. " + ("This is a reduced (--fast) run." if fast else "")
    )
    say("device and calibration")
    device_section(rep, results)
    try:
        computed = run_sections(names, fast, seed, workers, say, tick)
    finally:
        bar.close()
    for _name, payload in sorted(computed.items(), key=lambda kv: names.index(kv[0])):
        _merge(rep, results, payload)
    if sections is not None:
        results["sections_left_out"] = [n for n in SECTIONS if n not in sections]
        rep.warning(f"A partial run: sections left out: {', '.join(results['sections_left_out']) or 'none'}.")
    for line in summary_lines(results):
        rep.summary(line)
    closing = conclusion(results)
    if closing:
        rep.heading("Conclusion", 2)
        for para in closing:
            rep.text(para)
    elapsed = time.perf_counter() - t_start
    results["elapsed_s"] = elapsed
    rep.text(f"Run time: {elapsed:.1f} s ({'fast' if fast else 'full'} run, random seed {seed}).")
    say(f"writing {out}")
    rep.write(out, results)
    say("done")
    return out
