"""Benchmarks of the hot paths, each against a named baseline in the same run.

    python -m benchmarks.benchmarks [-o reports/benchmarks.md] [--quick] [--only simulator,nsi,...]

Simulator (issue 2): one 300 s record at 512 Hz and a batch of 256 such records (parameters +-2 %),
against ``scipy.integrate.solve_ivp`` (RK45, rtol 1e-8, atol 1e-10, Python right-hand side with the
same linearly interpolated input) and against a plain compiled C RK4 loop (gcc -O3, 4 and 2 substeps
per sample), the practical limit. Accuracy of each is measured against a reference (our RK4 at 32
substeps per sample, which agrees with DOP853 at rtol 1e-12 to ~1e-9) on an in-well record, where
trajectories can be compared pointwise (cross-well records are chaotic, so their pointwise error says
nothing about the integrator). Timings are medians of repeats, after a warm-up (numba compiled).

Then NSI, the map, the posterior, continuation and refinement, each against its baseline; the peers and
the scaling with the record's length (``peers.py``; ``scaling.png``).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.files import write_text
from negstiff.models import AS_BUILT, simulate, simulate_batch
from negstiff.models.effects import DEVICE_ROWS, POLYNOMIAL_ROWS
from negstiff.models.rig import Rig
from negstiff.models.structure import Structure, simulate_structures

from .baselines import build_c_rk4, median_time, solve_ivp_run
from .peers import peak, peers_section, scaling, scaling_section
from .peers import section as _section
from .waits import profile_section, waits_section


def simulator_benchmark(quick: bool = False) -> tuple[list[list[str]], dict]:
    dt = 1 / 512.0
    duration = 60.0 if quick else 300.0
    model = AS_BUILT.lsq_cubic()  # same polynomial law for every method
    cross = Rig(model, seed=11).random(duration=duration)  # the default cross-well random record
    inwell = Rig(model, seed=12).random(duration=duration, rms=4.0)
    u_cross, u_in = cross.columns["base_acc"], inwell.columns["base_acc"]
    zp = model.equilibria().z_plus
    rows, res = [], {}
    c_rk4 = build_c_rk4()

    # accuracy on the in-well record against RK4 with 32 substeps
    ref = simulate(model, u_in, dt, z0=zp, substeps=32).z[0]
    scale = np.sqrt(np.mean((ref - ref.mean()) ** 2))

    def rel_err(z):
        return float(np.sqrt(np.mean((z - ref) ** 2)) / scale)

    simulate(model, u_cross[:100], dt, z0=zp)  # warm-up: compile
    t_ours, _ = median_time(lambda: simulate(model, u_cross, dt, z0=zp), 5)
    err_ours = rel_err(simulate(model, u_in, dt, z0=zp).z[0])
    t_dev, _ = median_time(lambda: simulate(AS_BUILT, u_cross, dt), 5)
    # a law outside the kernel's fixed rows: the device's own geometry as the geometric law's table (the same force)
    law = AS_BUILT.law_model()
    simulate(law, u_cross[:100], dt)  # warm-up: compile the table's kernel
    t_law, _ = median_time(lambda: simulate(law, u_cross, dt), 5)
    law_err = float(np.sqrt(np.mean((simulate(law, u_in, dt).z[0] - simulate(AS_BUILT, u_in, dt).z[0]) ** 2)))
    t_ivp, _ = median_time(lambda: solve_ivp_run(model, u_cross, dt, zp, 0.0), 1)
    err_ivp = rel_err(solve_ivp_run(model, u_in, dt, zp, 0.0))
    res["single"] = {
        "numba_s": t_ours,
        "numba_device_s": t_dev,
        "solve_ivp_s": t_ivp,
        "numba_rel_err": err_ours,
        "solve_ivp_rel_err": err_ivp,
        "speedup_vs_solve_ivp": t_ivp / t_ours,
        "numba_table_law_s": t_law,
        "table_law_vs_polynomial": t_law / t_ours,
        "table_law_rms_m_vs_compiled_geometry": law_err,
    }
    rows.append(
        [
            f"one {duration:g} s record, polynomial K",
            "negstiff (numba RK4, 2 substeps)",
            f"{t_ours * 1e3:.1f} ms",
            f"{t_ivp / t_ours:.0f}x",
            f"{err_ours:.1e}",
        ]
    )
    rows.append(
        [
            f"one {duration:g} s record, exact geometric K",
            "negstiff (numba RK4, 2 substeps)",
            f"{t_dev * 1e3:.1f} ms",
            f"{t_ivp / t_dev:.0f}x",
            "-",
        ]
    )
    rows.append(
        [
            f"one {duration:g} s record, exact geometric K as a law (table, any law's path)",
            "negstiff (numba RK4, 2 substeps)",
            f"{t_law * 1e3:.1f} ms",
            f"{t_ivp / t_law:.0f}x",
            f"{t_law / t_ours:.2f}x the polynomial's time; {law_err:.1e} m from the compiled geometry",
        ]
    )
    rows.append(
        [
            f"one {duration:g} s record, polynomial K",
            "solve_ivp RK45 rtol 1e-8 (baseline)",
            f"{t_ivp:.1f} s",
            "1x",
            f"{err_ivp:.1e}",
        ]
    )
    if c_rk4 is not None:
        for nsub in (4, 2):
            c_rk4(model, u_cross[:100], dt, nsub, zp, 0.0)
            t_c, _ = median_time(lambda: c_rk4(model, u_cross, dt, nsub, zp, 0.0), 5)
            err_c = rel_err(c_rk4(model, u_in, dt, nsub, zp, 0.0))
            res[f"c_rk4_{nsub}"] = {"s": t_c, "rel_err": err_c}
            rows.append(
                [
                    f"one {duration:g} s record, polynomial K",
                    f"plain C RK4 loop, gcc -O3, {nsub} substeps",
                    f"{t_c * 1e3:.1f} ms",
                    f"{t_ivp / t_c:.0f}x",
                    f"{err_c:.1e}",
                ]
            )

    batch_rows, res["batch"] = _batch_benchmark(model, u_cross, dt, zp, t_ivp, quick)
    return rows + batch_rows, res


def _batch_benchmark(model, u_cross: np.ndarray, dt: float, zp: float, t_ivp: float, quick: bool):
    """A batch of records with +-2 % parameters, polynomial and exact K, per record against solve_ivp."""
    rows = []
    nb = 64 if quick else 256
    rng = np.random.default_rng(0)
    P = np.repeat(model.kernel_params()[:, None], nb, axis=1)
    k123 = [POLYNOMIAL_ROWS[k] for k in ("k1", "k2", "k3")]
    P[k123] *= 1 + 0.02 * rng.uniform(-1, 1, (3, nb))
    Pd = np.repeat(AS_BUILT.kernel_params()[:, None], nb, axis=1)
    Pd[DEVICE_ROWS["k_f"]] *= 1 + 0.02 * rng.uniform(-1, 1, nb)
    x0 = np.array([zp, 0.0])
    simulate_batch(P[:, :4], "polynomial", u_cross[:100], dt, x0)
    t_b, _ = median_time(lambda: simulate_batch(P, "polynomial", u_cross, dt, x0), 5)
    t_bd, _ = median_time(
        lambda: simulate_batch(Pd, "device", u_cross, dt, np.array([AS_BUILT.equilibria().z_plus, 0])), 5
    )
    # the same law on a 25 Hz, 2 % fixture of 1 kg (2 DOF): the Runge-Kutta loop's stage-wise path, against the
    # single DOF's fused one above
    fixture = Structure.on_fixture(model, fixture_mass=1.0, fixture_hz=25.0, fixture_zeta=0.02)
    xs = np.r_[fixture.static_positions(fixture.element_equilibria().z_plus), 0.0, 0.0]
    group = [fixture.with_element(replace(model, k1=model.k1 * (1 + 0.02 * e))) for e in rng.uniform(-1, 1, nb)]
    simulate_structures(group[:4], u_cross[:100], dt, xs)
    t_s, _ = median_time(lambda: simulate_structures(group, u_cross, dt, xs), 5)
    # the geometric law's table, +-2 % k_f per member (each member its own table)
    law = AS_BUILT.law_model()
    frames = [replace(law, extra={"rod_frame": {**law.extra["rod_frame"], "k_f": law.extra["rod_frame"]["k_f"] * f}})
              for f in 1 + 0.02 * rng.uniform(-1, 1, nb)]  # fmt: skip
    Pl = np.column_stack([m.kernel_params() for m in frames])
    xl = np.array([AS_BUILT.equilibria().z_plus, 0])
    simulate_batch(Pl[:, :4], "polynomial", u_cross[:100], dt, xl)
    t_bl, _ = median_time(lambda: simulate_batch(Pl, "polynomial", u_cross, dt, xl), 5)
    res = {
        "members": nb,
        "table_law_s": t_bl,
        "table_law_vs_polynomial": t_bl / t_b,
        "structure_2dof_s": t_s,
        "polynomial_s": t_b,
        "device_s": t_bd,
        "per_record_s": t_b / nb,
        "speedup_per_record_vs_solve_ivp": t_ivp / (t_b / nb),
        "threads": os.cpu_count(),
    }
    rows.append(
        [
            f"batch of {nb} records (+-2 % parameters), polynomial K",
            f"negstiff batch, {os.cpu_count()} threads",
            f"{t_b:.2f} s ({t_b / nb * 1e3:.2f} ms/record)",
            f"{t_ivp / (t_b / nb):.0f}x per record",
            "same kernel",
        ]
    )
    rows.append(
        [
            f"batch of {nb} records (+-2 % k1), polynomial K on a 25 Hz fixture (2 DOF)",
            f"negstiff batch, {os.cpu_count()} threads",
            f"{t_s:.2f} s ({t_s / nb * 1e3:.2f} ms/record)",
            f"{t_ivp / (t_s / nb):.0f}x per record",
            f"{t_s / t_b:.1f}x the 1-DOF batch",
        ]
    )
    rows.append(
        [
            f"batch of {nb} records (+-2 % k_f), exact geometric K as a law (a table per member)",
            f"negstiff batch, {os.cpu_count()} threads",
            f"{t_bl:.2f} s ({t_bl / nb * 1e3:.2f} ms/record)",
            f"{t_ivp / (t_bl / nb):.0f}x per record",
            f"{t_bl / t_b:.1f}x the polynomial batch (a table look-up does not vectorise over members)",
        ]
    )
    rows.append(
        [
            f"batch of {nb} records (+-2 % parameters), exact K",
            f"negstiff batch, {os.cpu_count()} threads",
            f"{t_bd:.2f} s ({t_bd / nb * 1e3:.2f} ms/record)",
            f"{t_ivp / (t_bd / nb):.0f}x per record",
            "-",
        ]
    )
    return rows, res


def nsi_benchmark(quick: bool = False) -> tuple[list[list[str]], dict]:
    """NSI on a 300 s record at 512 Hz: total time and peak memory; the LQ step against the direct QR
    of the whole Hankel stack (the baseline whose memory is N x 2i(m+l) at once).
    """
    from scipy import linalg

    from negstiff.inference.estimators import subspace
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.record.measurement import from_arrays
    from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC

    duration = 60.0 if quick else 300.0
    rec = Rig(SEED_LIKE_CUBIC, seed=21).random(duration=duration, rms=SEED_LIKE_CROSS_WELL_RMS)
    m = from_arrays(rec.columns["base_acc"], rec.columns["z"], 512.0, mass=SEED_LIKE_CUBIC.m)

    t_nsi, pk_nsi, _ = peak(lambda: NSI().fit(m))
    rng = np.random.default_rng(0)
    n = int(0.8 * m.n)
    u, y = rng.standard_normal((n, 4)), rng.standard_normal((n, 1))
    i = 30
    t_lq, pk_lq, _ = peak(lambda: subspace.lq_factor(u, y, i))
    t_qr, pk_qr, _ = peak(lambda: subspace.lq_factor(u, y, i, route="qr"))

    def direct():
        j = n - 2 * i + 1
        blocks = [
            subspace.hankel_block(u, i, i, j),
            subspace.hankel_block(u, 0, i, j),
            subspace.hankel_block(y, 0, i, j),
            subspace.hankel_block(y, i, i, j),
        ]
        return linalg.qr(np.vstack(blocks).T, mode="r")[0]

    t_dir, pk_dir, _ = peak(direct)
    res = {
        "nsi_s": t_nsi,
        "nsi_peak_mb": pk_nsi / 1e6,
        "lq_s": t_lq,
        "lq_peak_mb": pk_lq / 1e6,
        "qr_route_s": t_qr,
        "direct_qr_s": t_dir,
        "direct_qr_peak_mb": pk_dir / 1e6,
        "record_s": duration,
    }
    rows = [
        [
            f"NSI, both wells, {duration:g} s record",
            "negstiff NSI (order 2, 30 block rows)",
            f"{t_nsi:.1f} s",
            f"{pk_nsi / 1e6:.0f} MB",
            "-",
        ],
        [
            f"LQ of the Hankel stack ({n} samples, i = 30, 5 channels)",
            "negstiff: covariance route (Gram matrix from lagged products, Cholesky)",
            f"{t_lq:.2f} s",
            f"{pk_lq / 1e6:.0f} MB",
            f"{pk_dir / pk_lq:.1f}x less memory, {t_dir / t_lq:.2f}x the speed",
        ],
        [
            "same",
            "negstiff: chunked QR (the fallback for ill-conditioned stacks)",
            f"{t_qr:.2f} s",
            f"{pk_qr / 1e6:.0f} MB",
            f"{pk_dir / pk_qr:.1f}x less memory, {t_dir / t_qr:.2f}x the speed",
        ],
        ["same", "direct QR of the whole stack (baseline)", f"{t_dir:.2f} s", f"{pk_dir / 1e6:.0f} MB", "1x"],
    ]
    return rows, res


def bifurcation_benchmark(quick: bool = False) -> tuple[list[list[str]], dict]:
    """The 9 Hz bifurcation map's simulations: all sweeps in one batched rig run against the same
    records simulated one by one (each step started afresh from its well, the same simulated time).
    """
    n_amp = 25 if quick else 100
    amps = list(np.linspace(4.0, 26.0, n_amp))
    rig = Rig(seed=31)
    settle, record = 60, 64
    plans = [(s, d) for s in ("plus", "minus") for d in ("up", "down")]
    lists = [amps if d == "up" else amps[::-1] for _, d in plans]
    rig.sweeps(9.0, [amps[:2]], ["plus"], 5, 5)  # warm-up
    t_batch, _ = median_time(lambda: rig.sweeps(9.0, lists, [s for s, _ in plans], settle, record), 1)

    def one_by_one():
        for s_, _ in plans:
            for a in amps:
                rig.harmonic(9.0, a, s_, settle, record)

    t_one, _ = median_time(one_by_one, 1)
    n_rec = len(plans) * n_amp
    res = {"records": n_rec, "batched_s": t_batch, "one_by_one_s": t_one, "speedup": t_one / t_batch}
    rows = [
        [
            f"bifurcation map: {n_amp} amplitudes x 2 wells x 2 directions ({n_rec} records, {settle}+{record} "
            "periods each)",
            "negstiff: all sweeps in one batched rig run",
            f"{t_batch:.1f} s",
            f"{t_one / t_batch:.1f}x",
        ],
        ["same records", "one rig run per record (baseline)", f"{t_one:.1f} s", "1x"],
    ]
    return rows, res


def posterior_benchmark(quick: bool = False) -> tuple[list[list[str]], dict]:
    """Effective samples per second: emcee with the batched (vectorised) likelihood against the same
    sampler calling the same likelihood walker by walker (emcee's default, vectorize=False). With the
    same seed both give the same chain (checked), so the ESS is the same and the ratio is the time's.
    """
    import emcee

    from negstiff.inference.estimators.posterior import LogPosterior, Posterior
    from negstiff.inference.estimators.posterior.sampling import laplace_independence_move
    from negstiff.inference.record.measurement import from_arrays
    from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
    from negstiff.models.rig import Rig

    duration, steps = (5.0, 60) if quick else (10.0, 300)
    r = Rig(SEED_LIKE_CUBIC, seed=3).random(duration=duration, rms=SEED_LIKE_CROSS_WELL_RMS)
    rec = from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source="bench")
    post = Posterior(n_ensembles=1, max_steps=steps, min_steps=steps, chunk=steps, seed=0)
    post.fit(rec)  # builds the whitened log posterior (MAP, Laplace) and runs the batched sampler once
    lp: LogPosterior = post.logpost_
    nd, nw = lp.q0.size, post.n_walkers
    p0 = np.random.RandomState(0).standard_normal((nw, nd))
    moves = [(laplace_independence_move(nd), 0.5), (emcee.moves.DEMove(), 0.5)]  # the posterior's own (MOVES)

    def run(vectorize: bool):
        fn = lp if vectorize else (lambda y: lp(np.atleast_2d(y))[0])
        s = emcee.EnsembleSampler(nw, nd, fn, vectorize=vectorize, moves=moves)
        s.random_state = np.random.RandomState(1).get_state()
        t0 = time.perf_counter()
        s.run_mcmc(p0, steps, progress=False)
        return time.perf_counter() - t0, s

    t_batch, sb = run(True)
    t_loop, sl = run(False)
    same = bool(np.allclose(sb.get_chain(), sl.get_chain()))

    # the plainest baseline: one simulator call per walker and per window (no batch at all)
    win = lp.win
    orig = win.simulate

    def one_by_one(params, kind, x0=None):
        zs, div = [], []
        for p in range(params.shape[1]):
            for w in range(win.n_windows):
                res_ = simulate_batch(
                    params[:, p],
                    kind,
                    win.u[w],
                    win.dt,
                    (win.x0 if x0 is None else x0)[w],
                    input_kind=win.input_kind,
                    substeps=win.substeps,
                    threads=1,
                )
                zs.append(res_.z[0])
                div.append(res_.diverged[0])
        P = params.shape[1]
        return np.array(zs).reshape(P, win.n_windows, -1), np.array(div).reshape(P, -1).any(axis=1)

    win.simulate = one_by_one  # type: ignore[method-assign]
    try:
        t_plain, sp = run(False)
    finally:
        win.simulate = orig  # type: ignore[method-assign]
    same = same and bool(np.allclose(sb.get_chain(), sp.get_chain()))
    tau = float(np.max(sb.get_autocorr_time(tol=0, quiet=True)))
    ess = nw * steps / max(tau, 1.0)
    rows = [
        [
            f"{duration:g} s record, {nw} walkers, {steps} steps",
            "a simulator call per walker and per window",
            f"{t_plain:.2f} s",
            f"{ess / t_plain:.1f}",
            f"{t_plain / t_loop:.2f}x",
        ],
        [
            "",
            "per-walker loop (vectorize=False; the walker's windows batched)",
            f"{t_loop:.2f} s",
            f"{ess / t_loop:.1f}",
            "1.0x",
        ],
        [
            "",
            "batched: all walkers x windows in one simulator call",
            f"{t_batch:.2f} s",
            f"{ess / t_batch:.1f}",
            f"{t_loop / t_batch:.1f}x",
        ],
    ]
    return rows, {"t_plain": t_plain, "t_loop": t_loop, "t_batch": t_batch, "tau": tau, "ess": ess, "same_chain": same}


def refinement_benchmark(quick: bool = False) -> tuple[list[list[str]], dict]:
    """Output-error refinement (issue 15) as ``identify`` runs it (``refine.refine_stage``: the widening
    window stages, the held-out validation, the boundedness check) on a 300 s rig record and on the
    Silverbox's training part; and the first window stage with each of ``refine.SOLVERS``: negstiff's
    Levenberg-Marquardt with the start states eliminated, scipy's ``least_squares`` given the Jacobian's
    sparsity (a window's start state moves only that window), and with a dense finite-difference
    Jacobian (two batched runs per parameter and per start state: what ``least_squares`` does unless told
    the sparsity); each with its evaluations and its end error over the best of the three.
    """
    from negstiff.datasets import silverbox
    from negstiff.experiments.silverbox import TRAIN
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.record.measurement import from_arrays
    from negstiff.inference.steps.refine import SOLVERS, refine, refine_stage
    from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
    from negstiff.models.rig import Rig

    duration = 60.0 if quick else 300.0
    r = Rig(SEED_LIKE_CUBIC, seed=4).random(duration=duration, rms=SEED_LIKE_CROSS_WELL_RMS)
    rec = from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source="bench")
    cases = [
        (f"{duration:g} s rig record ({rec.n:,} samples at {rec.fs:g} Hz), NSI start", rec),
        ("Silverbox training part (65,062 samples at 610 Hz), NSI start", silverbox().segment(*TRAIN)),
    ]
    rows, res = [], {}
    for label, m in cases:
        est = NSI(refine=False).fit(m)
        n_id = est.settings_["identification_samples"]
        t0 = time.perf_counter()
        _, _, info = refine_stage(est.model_, m, n_id, est.validation_)
        t_stage = time.perf_counter() - t0
        ident = m.segment(0, n_id)
        runs = {}
        for solver in SOLVERS:
            t, ref = median_time(lambda: refine(est.model_, ident, windows_s=(0.05,), solver=solver), 1)
            runs[solver] = (t, ref.stages[0]["rms_end_m"], ref.stages[0]["evaluations"])
        best = min(v[1] for v in runs.values())
        key = "silverbox" if "Silverbox" in label else "rig"
        first = {k: {"s": t, "rms_end_m": e, "evaluations": n} for k, (t, e, n) in runs.items()}
        res[key] = {"refine_stage_s": t_stage, "stages": len(info.get("stages", [])), "first_stage": first}
        rows.append([label, "refinement as identify runs it (all stages, validation, boundedness)",
                     f"{t_stage:.2f} s", "-", "-"])  # fmt: skip
        t_base = runs["scipy-dense"][0]
        for solver, what in (
            ("schur", "Levenberg-Marquardt, start states eliminated (negstiff)"),
            ("scipy", "scipy least_squares (trf) given the Jacobian's sparsity"),
            ("scipy-dense", "scipy least_squares (trf), dense Jacobian (baseline)"),
        ):
            t, e, n = runs[solver]
            rows.append([("same, first stage (0.05 s windows)" if solver == "schur" else ""), what, f"{t:.2f} s",
                         f"{t_base / t:.0f}x", f"{n}, {100 * (e / best - 1):+.4f} %"])  # fmt: skip
    return rows, res


def hybrid_benchmark(quick: bool = False) -> tuple[list[list[str]], dict]:
    """The hybrid model's free runs (``inference.hybrid``: the physics plus a net of Gaussian bumps inside the
    Runge-Kutta loop), as its output-error fit runs them: the Silverbox training part's 1 s windows from their
    measured states, the refined SINDy physics with the default 7 x 5 + 5 bumps at random weights of the fitted
    term's size; negstiff's batched kernel against ``scipy.integrate.solve_ivp`` (RK45, rtol 1e-8) of the same
    equation with the bumps in numpy (``Basis.evaluate``), window by window, which is what a user would write;
    the rms difference of the two over the windows; and the whole fit (``fit_hybrid``) on the training part.
    """
    from scipy.integrate import solve_ivp

    from negstiff.datasets import silverbox
    from negstiff.experiments.silverbox import TRAIN
    from negstiff.inference.estimators.hybrid import Basis, fit_hybrid, simulate_hybrid
    from negstiff.inference.estimators.sindy import SINDy
    from negstiff.models.simulator import stage_input

    train = silverbox().segment(*TRAIN)
    physics = SINDy().fit(train).model_
    zs, vs, _, _ = train.states("state")
    basis = Basis.over(zs, vs, train.u)
    theta = np.random.default_rng(0).normal(0.0, 2e-3, basis.size)  # the fitted term's weights are ~1e-3 N
    length = int(round(train.fs))
    n_win = 8 if quick else 60
    starts = np.linspace(0, train.n - length - 1, n_win).round().astype(int)
    u = np.stack([stage_input(train.u[a : a + length + 1], 2) for a in starts])
    x0 = np.stack([zs[starts], vs[starts]], axis=1)

    def ours():
        return simulate_hybrid(physics, basis, theta, u, train.dt, x0, 2, train.input_name, 1.0, 100.0)[0]

    t_ours, z_ours = median_time(ours, 5)
    m = physics.m  # a force record: z'' = (u - forces) / m

    # the input between samples band-limited (``stage_input``) at 8 substeps a sample: the kernel reads it at its
    # stages, solve_ivp interpolates it linearly at dt / 16
    u8 = np.stack([stage_input(train.u[a : a + length + 1], 8) for a in starts])

    def ivp_window(k: int) -> np.ndarray:
        t = np.arange(length + 1) * train.dt
        t_staged = np.linspace(0.0, t[-1], u8.shape[1])

        def rhs(tt, x):
            uk = float(np.interp(tt, t_staged, u8[k]))
            g = float(basis.evaluate(theta, x[0], x[1], uk))
            return [x[1], (uk - float(physics.total_force(x[0], x[1])) - g) / m]

        return solve_ivp(rhs, (0.0, t[-1]), x0[k], t_eval=t, rtol=1e-8, atol=1e-12).y[0]

    n_ivp = 2 if quick else 4
    t_ivp, z_ivp = median_time(lambda: np.stack([ivp_window(k) for k in range(n_ivp)], axis=1), 1)
    per_ours, per_ivp = t_ours / n_win, t_ivp / n_ivp

    def rel(z):
        return float(np.sqrt(np.mean((z - z_ivp) ** 2)) / np.sqrt(np.mean(z_ivp**2)))

    diff = rel(z_ours[:, :n_ivp])
    # the same windows at 8 substeps a sample: how much of the difference is the Runge-Kutta step's
    diff8 = rel(simulate_hybrid(physics, basis, theta, u8[:n_ivp], train.dt, x0[:n_ivp], 8, train.input_name, 1.0,
                                100.0)[0])  # fmt: skip
    t_fit, _ = median_time(lambda: fit_hybrid(physics, train), 1)
    rows = [
        [f"{n_win} windows of 1 s ({length} samples at {train.fs:g} Hz)", "negstiff batched kernel, 2 substeps",
         f"{1e3 * per_ours:.2f} ms a window", f"{per_ivp / per_ours:.0f}x", f"{diff:.1e} of rms z from RK45"],
        ["same, a few windows", "negstiff, 8 substeps", "-", "-", f"{diff8:.1e} of rms z from RK45"],
        ["same, a few windows", "solve_ivp RK45 rtol 1e-8, bumps in numpy (baseline)",
         f"{1e3 * per_ivp:.0f} ms a window", "1x", "-"],
        ["the whole fit on the training part", "fit_hybrid (term, then physics and term)", f"{t_fit:.1f} s", "-", "-"],
    ]  # fmt: skip
    return rows, {"per_window_s": per_ours, "ivp_per_window_s": per_ivp, "rel_rms_diff": diff,
                  "rel_rms_diff_8_substeps": diff8, "fit_s": t_fit, "windows": n_win}  # fmt: skip


def continuation_benchmark(quick: bool = False) -> tuple[list[list[str]], dict]:
    """A 9 Hz continuation from 2 to 30 m/s^2 (issue 16) against the brute-force route a user would take
    instead: a stepped sweep in 0.1 m/s^2 steps with the state carried over (150 settling and 16 recorded
    periods a step, one simulator call each), which finds only the stable orbits.
    """
    from negstiff.models import SEED_LIKE_CUBIC
    from negstiff.models.continuation import nfrc

    rows: list[list[Any]] = []
    res: dict[str, Any] = {}
    for name, system in (("seed-like cubic", SEED_LIKE_CUBIC), ("as-built device (exact geometry)", AS_BUILT)):
        for well in ("plus", "minus"):
            nfrc(system, freq=9.0, amplitude=(2.0, 4.0), well=well)  # warm-up: compile
            t, r = median_time(lambda: nfrc(system, freq=9.0, amplitude=(2.0, 30.0), well=well), 1 if quick else 3)
            n_pts = sum(len(b["points"]) for b in r["branches"])
            res[f"{name}, {well}"] = {"s": t, "points": n_pts, "branches": len(r["branches"])}
            rows.append([f"9 Hz, 2-30 m/s^2, {name}, from z_{well}", "negstiff nfrc (shooting + arclength)",
                         f"{t:.2f} s", f"{n_pts} orbits on {len(r['branches'])} branches"])  # fmt: skip
    z0, v0, n = SEED_LIKE_CUBIC.equilibria().z_plus, 0.0, 128
    amps = np.round(np.arange(2.0, 30.0, 0.1), 2)
    t0 = time.perf_counter()
    for a in amps:
        dt = 1 / (9.0 * n)
        tt = np.arange(n * 166 + 1) * dt
        sim = simulate(SEED_LIKE_CUBIC, a * np.sin(2 * np.pi * 9.0 * tt), dt, z0=z0, v0=v0)
        z0, v0 = sim.z[0][-1], sim.z_dot[0][-1]
    t_bf = time.perf_counter() - t0
    res["brute_force_s"] = t_bf
    rows.append(["9 Hz, 2-30 m/s^2, seed-like cubic, from z_plus", "stepped sweep, 0.1 m/s^2 steps (baseline)",
                 f"{t_bf:.2f} s", f"{amps.size} steps, stable orbits only"])  # fmt: skip
    return rows, res


def _header(quick: bool) -> list[str]:
    """The report's head: the machine and how it was written."""
    return [
        "# negstiff benchmarks",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, numpy {np.__version__}. Written by `python -m benchmarks.benchmarks`"
        f"{' --quick' if quick else ''}, each section as soon as it is measured (its figures also in "
        "`benchmarks.json`; `--only NAME` reruns one section in place); every ratio is against the baseline "
        "measured in the same section's run.",
    ]


def _simulator_section(quick: bool) -> tuple[list[str], dict]:
    """The simulator section (issue 2) and its figures."""
    print("simulator benchmark (solve_ivp takes a while)...", file=sys.stderr)
    rows, res = simulator_benchmark(quick)
    s = res["single"]
    lines = [
        "## Simulator (issue 2)",
        "",
        "Record: the rig's default cross-well random excitation (300 s at 512 Hz, 153,600 samples) driving the "
        "least-squares cubic of the as-built device. Accuracy: rms error of z relative to rms(z), on an in-well "
        "record of the same length, against RK4 at 32 substeps per sample.",
        "",
        "| case | method | wall time | speed-up vs solve_ivp | accuracy (rel. rms) |",
        "|---|---|---|---|---|",
    ]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    b = res["batch"]
    lines += [
        "",
        f"Targets (issue 2): at least 1000x faster than solve_ivp for one record (measured "
        f"{s['speedup_vs_solve_ivp']:.0f}x), 2500x per record in the batch (measured "
        f"{b['speedup_per_record_vs_solve_ivp']:.0f}x), at equal or better accuracy (measured "
        f"{s['numba_rel_err']:.1e} against solve_ivp's {s['solve_ivp_rel_err']:.1e}).",
    ]
    law_single, law_batch = s["table_law_vs_polynomial"], b["table_law_vs_polynomial"]
    lines += [
        f"A law outside the kernel's rows (issue 55: within 2x the cubic's time) takes {law_single:.2f}x the "
        f"polynomial's time for one record ({'met' if law_single <= 2 else 'not met'}) and {law_batch:.1f}x in the "
        f"batch ({'met' if law_batch <= 2 else 'not met'}). One record: the look-up (a floor, an index, four "
        "loads, a cubic) adds to each Runge-Kutta stage's chain of dependent operations. The batch: the "
        "polynomial's batch runs four members per vector instruction, while a table look-up loads from an address "
        "each member computes, a gather LLVM does not emit for this machine, so a batch of tables runs member by "
        "member at about one record's speed."
    ]
    if "c_rk4_2" in res:
        ratio = s["numba_s"] / res["c_rk4_2"]["s"]
        lines += [
            f"The single-record path takes {ratio:.2f}x the time of the plain C loop at the same 2 substeps "
            "(the C loop has no batch, no divergence checks and no velocity output); the batch path "
            f"amortises to {b['per_record_s'] * 1e3:.2f} ms per record, "
            f"{res['c_rk4_2']['s'] / b['per_record_s']:.1f}x faster than one C loop per record."
        ]
    return lines, res


def _posterior_section(quick: bool) -> tuple[list[str], dict]:
    """Posterior sampling (issue 7): batched likelihood against the per-walker loop."""
    print("posterior benchmark...", file=sys.stderr)
    prows, pres = posterior_benchmark(quick)
    lines = _section(
        "Posterior sampling (issue 7)",
        (
            "Effective samples per second of emcee (the posterior's own moves, whitened coordinates) on the "
            "coefficient posterior: "
            "the batched likelihood (every walker and every multiple-shooting window in one simulator call) against "
            "the same likelihood called walker by walker. Same seed, same chain "
            f"({'verified' if pres['same_chain'] else 'NOT identical'}), so the ESS ({pres['ess']:.0f} from "
            f"tau = {pres['tau']:.1f} steps) is shared and the ratio is the time's. Target: at least 10x."
        ),
        ["case", "method", "wall time", "ESS per second", "vs the per-walker loop"],
        prows,
    )
    ratio = pres["t_loop"] / pres["t_batch"]
    lines += [
        "",
        f"Against the per-walker loop the batched likelihood is {ratio:.1f}x faster: "
        + ("the 10x target is met." if ratio >= 10 else "**the 10x target is not met.** ")
        + (
            ""
            if ratio >= 10
            else "A walker's own multiple-shooting windows already make a batch of "
            "dozens of trajectories in one compiled call; batching the walkers as well saves the per-call Python "
            "and numpy work (parameters, projection, sums), no more: the arithmetic is the same. (A step's batch is "
            "too small for a second thread to pay for its hand-off.) Against one simulator call per trajectory "
            "(walker x window) "
            f"the batch is {pres['t_plain'] / pres['t_batch']:.1f}x faster."
        ),
    ]
    return lines, pres


def _nsi_section(quick: bool) -> tuple[list[str], dict]:
    print("NSI benchmark...", file=sys.stderr)
    rows, res = nsi_benchmark(quick)
    lines = _section(
        "NSI (issue 4)",
        (
            "Peak memory is what Python allocates (tracemalloc) during the call. Neither negstiff route holds the "
            "whole block-Hankel stack: the covariance route never forms it, the chunked QR's memory is set by the "
            "chunk, not by the record length."
        ),
        ["case", "method", "wall time", "peak memory", "vs baseline"],
        rows,
    )
    return lines, res


def _bifurcation_section(quick: bool) -> tuple[list[str], dict]:
    print("bifurcation-map benchmark...", file=sys.stderr)
    rows, res = bifurcation_benchmark(quick)
    lines = _section(
        "Bifurcation map (issue 3)",
        (
            "Wall time of producing the records (simulation, sensor chain, anti-aliasing, integration), before "
            "the periodicity analysis."
        ),
        ["case", "method", "wall time", "vs baseline"],
        rows,
    )
    return lines, res


def _continuation_section(quick: bool) -> tuple[list[str], dict]:
    print("continuation benchmark...", file=sys.stderr)
    rows, res = continuation_benchmark(quick)
    lines = _section(
        "Continuation (issue 16)",
        (
            "`negstiff nfrc` at 9 Hz from 2 to 30 m/s^2 (doubled branches followed to period 4), against the "
            "stepped sweep a user would simulate instead. Target: under 30 s on 2 cores."
        ),
        ["case", "method", "wall time", "what it gives"],
        rows,
    )
    slowest = max(v["s"] for k, v in res.items() if k != "brute_force_s")
    lines += ["", f"The slowest continuation took {slowest:.1f} s: the 30 s target is "
              + ("met." if slowest < 30 else "**not met**.")]  # fmt: skip
    return lines, res


def _refinement_section(quick: bool) -> tuple[list[str], dict]:
    print("refinement benchmark...", file=sys.stderr)
    rows, res = refinement_benchmark(quick)
    lines = _section(
        "Output-error refinement (issue 15)",
        (
            "The stage `identify nsi|sindy` and `discrepancy` end with, timed on its own from the equation-error "
            "estimate; and its first window stage with three least-squares solvers (evaluations: residual "
            "evaluations, Jacobians not counted; end error: the fit's rms error over the best of the three). "
            "Target: under 10 s for a 300 s record on 2 cores."
        ),
        ["case", "method", "wall time", "vs baseline", "evaluations, end error"],
        rows,
    )
    t300 = res["rig"]["refine_stage_s"]
    lines += [
        "",
        f"On the {'60' if quick else '300'} s record the refinement takes {t300:.1f} s: the 10 s target is "
        + ("met." if t300 < 10 else "**not met**.")
        + " "
        + " ".join(
            f"{k}: scipy's sparse solver took {v['first_stage']['scipy']['evaluations']} evaluations and ended "
            f"{100 * (v['first_stage']['scipy']['rms_end_m'] / v['first_stage']['schur']['rms_end_m'] - 1):+.4f} % "
            f"from negstiff's end error, reached in {v['first_stage']['schur']['evaluations']}."
            for k, v in res.items()
        ),
    ]
    return lines, res


def _hybrid_section(quick: bool) -> tuple[list[str], dict]:
    print("hybrid benchmark...", file=sys.stderr)
    rows, res = hybrid_benchmark(quick)
    lines = _section(
        "Hybrid free runs",
        (
            "The hybrid model's output-error fit simulates physics plus its bumps tens of thousands of times. Its "
            "term is evaluated inside the kernel's Runge-Kutta loop, each grid's bumps from two exponentials by the "
            "ratio of neighbouring bumps (``kernel._bumps``), and a kernel without the sign, monomial and table "
            "code the hybrid's polynomial physics does not use. Before that change the same fit took 33.7 s on "
            "this machine (34.3 s in `reproduce`'s run of 2026-11-30). Accuracy: the rms difference from RK45 on "
            "the same input (band-limited between samples, read at 8 substeps), over rms z: the fit's 2 substeps "
            "a sample leave RK4's step error at the Silverbox's resonance (omega h about 0.35), which 8 substeps "
            "shrink."
        ),
        ["case", "method", "wall time", "vs baseline", "accuracy"],
        rows,
    )
    return lines, res


def _design_section(quick: bool) -> tuple[list[str], dict]:
    """Test design, checked against the rig (``design_check``): 2 seeds with ``quick``."""
    from .design_check import design_check, design_section

    print("design check...", file=sys.stderr)
    res = design_check((1, 2) if quick else (1, 2, 3, 4, 5))
    return design_section(res), res


def _separation_section(quick: bool) -> tuple[list[str], dict]:
    """Telling two effects apart, checked against the rig (``separation_check``): 2 seeds with ``quick``."""
    from .design_check import separation_check, separation_section

    print("separation check...", file=sys.stderr)
    res = separation_check((1, 2) if quick else (1, 2, 3, 4, 5))
    return separation_section(res), res


def _ring_down_design_section(quick: bool) -> tuple[list[str], dict]:
    """Hammer hits and releases, checked against the rig (``ring_down_check``): 2 seeds with ``quick``."""
    from .design_check import ring_down_check, ring_down_section

    print("ring-down design check...", file=sys.stderr)
    res = ring_down_check((1, 2) if quick else (1, 2, 3, 4, 5))
    return ring_down_section(res), res


SECTIONS: dict[str, Any] = {
    "waits": lambda quick, out: waits_section(quick),
    "profile": lambda quick, out: profile_section(quick),
    "simulator": lambda quick, out: _simulator_section(quick),
    "nsi": lambda quick, out: _nsi_section(quick),
    "bifurcation": lambda quick, out: _bifurcation_section(quick),
    "posterior": lambda quick, out: _posterior_section(quick),
    "continuation": lambda quick, out: _continuation_section(quick),
    "refinement": lambda quick, out: _refinement_section(quick),
    "hybrid": lambda quick, out: _hybrid_section(quick),
    "design": lambda quick, out: _design_section(quick),
    "separation": lambda quick, out: _separation_section(quick),
    "ring-down-design": lambda quick, out: _ring_down_design_section(quick),
    "peers": lambda quick, out: (peers_section(quick), None),
    "scaling": lambda quick, out: (
        scaling_section(
            res := scaling((10.0, 30.0, 100.0) if quick else (30.0, 300.0, 3000.0)),
            Path(out).with_name("scaling.png"),
        ),
        res,
    ),
}
"""The sections in the order they are measured (the waits first, on the machine at rest): name -> (quick, the
Markdown's path) -> (its Markdown lines, its figures for the JSON, or None where only the text holds them)."""


def _blocks(lines: list[str]) -> tuple[list[str], list[tuple[str, list[str]]]]:
    """A Markdown text as its head (before the first ``## ``) and its ``## `` blocks, in order."""
    head: list[str] = []
    blocks: list[tuple[str, list[str]]] = []
    for line in lines:
        if line.startswith("## "):
            blocks.append((line, [line]))
        elif blocks:
            blocks[-1][1].append(line)
        else:
            head.append(line)
    return head, blocks


def _key(heading: str) -> str:
    """A block's name, its heading without the issue it came from ("## Waits (issue 18)" -> "Waits")."""
    return heading[3:].split(" (issue")[0].strip()


BLOCKS = ("Simulator", "Waits", "NSI", "Bifurcation map", "Posterior sampling", "Continuation",
          "Output-error refinement", "Hybrid free runs", "Test design", "Peers", "Scaling")  # fmt: skip
"""The blocks' names (their starts: the peers write four blocks) in the Markdown's order."""


def _rank(heading: str) -> int:
    """A block's place in the Markdown: its name's in ``BLOCKS`` (a block of no known name last)."""
    key = _key(heading)
    return next((i for i, start in enumerate(BLOCKS) if key.startswith(start)), len(BLOCKS))


def write_section(out: str, name: str, lines: list[str], quick: bool) -> None:
    """Put one section's blocks into the Markdown at ``out`` in place of the same blocks (every other block kept),
    a new one where ``BLOCKS`` puts it, its date after each heading; written at once, atomically.
    """
    path = Path(out)
    blocks = _blocks(path.read_text().splitlines() if path.exists() else [])[1]
    head = _header(quick)  # this run's machine and way
    stamp = f"*Measured {time.strftime('%Y-%m-%d')}{' (--quick)' if quick else ''}, section `{name}`.*"
    for heading, block in _blocks(lines)[1]:
        block = _trim([heading, "", stamp, *block[1:]])
        keys = [_key(h) for h, _ in blocks]
        if _key(heading) in keys:
            blocks[keys.index(_key(heading))] = (heading, block)
        else:  # before the first block of a later section (a full run measures the waits first)
            at = next((k for k, (h, _) in enumerate(blocks) if _rank(h) > _rank(heading)), len(blocks))
            blocks.insert(at, (heading, block))
    text = [*_trim(head)] + [line for _, block in blocks for line in block]
    write_text(out, "\n".join(text).rstrip("\n") + "\n")


def _trim(block: list[str]) -> list[str]:
    """A block with one blank line after it."""
    while block and not block[-1].strip():
        block = block[:-1]
    return [*block, ""]


def write_figures(out: str, name: str, res, quick: bool) -> None:
    """One section's figures into ``benchmarks.json`` beside the Markdown (the others kept)."""
    import json

    path = Path(out).with_suffix(".json")
    data = json.loads(path.read_text()) if path.exists() else {}
    data[name] = {"measured": time.strftime("%Y-%m-%d"), "quick": quick, "figures": res}
    text = json.dumps(data, indent=1, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))
    write_text(str(path), text + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-o", "--out", default="reports/benchmarks.md")
    ap.add_argument("--quick", action="store_true", help="60 s records and a batch of 64 (a smoke run)")
    ap.add_argument("--only", default="", help=f"comma-separated sections to rerun in place: {', '.join(SECTIONS)}")
    a = ap.parse_args(argv)
    only = [n.strip() for n in a.only.split(",") if n.strip()] or list(SECTIONS)
    unknown = [n for n in only if n not in SECTIONS]
    if unknown:
        ap.error(f"unknown section {', '.join(unknown)}: one of {', '.join(SECTIONS)}")
    # no section's old text is dropped before its new one is measured: a run that stops keeps the earlier figures
    for name in (n for n in SECTIONS if n in only):
        lines, res = SECTIONS[name](a.quick, a.out)
        write_section(a.out, name, lines, a.quick)  # at once: a later section's failure loses nothing measured
        if res is not None:
            write_figures(a.out, name, res, a.quick)
        print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
