"""The posterior of a structure's nonlinear element (``Posterior(element="I-J")`` on a record of N > 1 DOFs).

Parameters: the element's k1, k2, k3, c, c_nl (the single-DOF names), and as nuisances each channel's zero
(``offset_K``: measured = physical + offset) and the linear structure's springs and dampers (``spring_I-J``,
``damper_I-J``, ``linear_parts``), all started from a deterministic identification's values (``SINDy(element=...)``:
its ``structure_`` and ``offsets_``), and the displacement sensors' noise sigma (one for every DOF: the same kind of
laser); the masses are given. Held at SINDy's, a channel's zero error d moved k2 by 3 k3 d (1-3 um: 4-7 of its sd)
and the linear structure's error put a hammer record's c at 0.465 [0.464, 0.465] for 0.452 (measured).

Likelihood: the identification part of the record (its first 80 %) cut into windows of ``window_s`` (short
against the cross-well motion's divergence), each started where the element follows it best (``refine_starts``:
Gauss-Newton on its 2N start states from the record's band-smoothed state, ``Measurement.channel_states``,
alternating with the parameters' least squares) under the measured input (band-limited between samples), its start
state's directions projected off (profiled out: the state errs, and chaos grows its error within a window);
every DOF's residual Gaussian with sd sigma, curvature-adjusted by the windows' sandwich covariance (the single
DOF's ``likelihood.curvature_adjustment``: what is left beside the sensors' white noise is smooth and correlated
within a window, and the spread of the windows' scores says how much the data really carry). Measured over 12
of the tests' fixture records (0.1 s windows, 40 of them): rms z-score of the truth 0.74 / 1.08 / 0.80 / 0.67 / 0.77
for k1, k2, k3, c, c_nl, 90 % intervals covering 92-100 % (with smoothed starts and the nuisances held: 1.48 / 1.20
/ 1.14 / 1.33 / 1.24, coverage 67-100 %, intervals 1-20x wider, k1 biased by -1.4 sd). The input's sensor noise is
not carried through the structure (the curvature adjustment widens for what it leaves). Flat priors on the
coefficients (c, c_nl >= 0: the element dissipates), on the nuisances and on log sigma. Sampling: the single DOF's
ensembles (``sampling.sample_ensembles``) started around the least-squares point (Gauss-Newton from
SINDy's element) in coordinates scaled by the adjusted covariance; summaries, R-hat and ESS by arviz
(``diagnostics.summarise``).
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import Any

import numpy as np

from negstiff.inference.estimators.posterior.diagnostics import (
    PosteriorResult,
    convergence_warnings,
    noise_names,
    summarise,
)
from negstiff.inference.estimators.posterior.likelihood import (
    curvature_adjustment,
    information_parts,
    input_noise_rms,
)
from negstiff.inference.estimators.posterior.sampling import MOVES, sample_ensembles
from negstiff.inference.estimators.posterior.windows import PosteriorError, between_pulses
from negstiff.inference.record.measurement import Measurement
from negstiff.models.kernel import KINDS
from negstiff.models.simulator import integrate, stage_input
from negstiff.models.structure import Structure

ELEMENT_NAMES = ("k1", "k2", "k3", "c", "c_nl")
SUBSTEPS = 2
IDENTIFICATION_SHARE = 0.8
"""The windows are cut from the record's first 80 % (the identification part of every estimator). Not the whole
record as the single DOF's: over the tests' 12 fixture records the whole record's windows narrowed the intervals
about a k1 whose bias stays (k1's rms z 1.41 -> 1.69, k2 0.86 -> 1.26, coverage 67-83 %; measured 2026-11-30)."""


START_STEPS = 3
"""Gauss-Newton steps on each window's start state before the windows are read (``StructureWindows.refine_starts``)."""

ALTERNATIONS = 4
"""Rounds of the element's least squares and its windows' start states at most (``fit_structure``)."""
ALTERNATION_TOL_SD = 0.05
"""The rounds stop when no coefficient moved by more than this share of its standard error."""

UNFOLLOWED_FACTOR = 100.0
"""A structure's window whose run from SINDy's element misses by more than this many times the median window's is
left out of its posterior. Not the single DOF's 5x (``windows.DROP_FACTOR``): over the tests' 12 cross-well fixture
records the worst window missed by 1.5-33x the median (near the saddle), and leaving those out moved the posterior's
calibration (k1's rms z 1.41 -> 1.63 over them); a window the record's own input does not drive, the first of a chain
driven from rest by a force, missed by 3,000x (measured)."""


def window_starts(rec: Measurement, window_s: float, max_windows: int | None,
                  free: bool = False) -> tuple[np.ndarray, int]:  # fmt: skip
    """The first sample of each window (evenly picked, at most ``max_windows``) over the identification part
    and the samples per window less one; one ``PosteriorError`` when fewer than 4 fit. ``free``: a ring-down's
    record (its input zero between the pulses), only the windows between the pulses (``windows.between_pulses``:
    a pulse of a few samples is not resolved by the simulator's staged input), each a free decay from its state.
    """
    n_id = int(IDENTIFICATION_SHARE * rec.n)
    L = max(8, int(round(window_s * rec.fs)))
    starts = np.arange(0, n_id - L, L)
    if starts.size < 4:
        raise PosteriorError(f"{rec.source}: too short for a structure's posterior: 4 windows of {window_s:g} s "
                             f"needed in its first {100 * IDENTIFICATION_SHARE:g} %")  # fmt: skip
    if free:
        starts = starts[between_pulses(rec, starts[:, None] + np.arange(L + 1)[None, :], window_s)]
    if max_windows is not None:
        starts = starts[np.linspace(0, starts.size - 1, min(max_windows, starts.size)).round().astype(int)]
    return starts, L


def given_start(start, rec: Measurement, at: tuple[int, int], name: str = "Posterior") -> tuple[Structure, np.ndarray,
                                                                                                str]:  # fmt: skip
    """The structure a posterior's search starts from (``Posterior.start`` on a structure's record), each channel's
    zero (measured = physical + offset) and where it came from: an ``Identification`` of the structure (its structure
    and zeros, ``offsets_m``), or a ``Structure`` (its zeros read from the record by the weak form's least squares
    over the structure's whole library, pinned as an identification pins them: ``equations.weak_frame``). One
    ``PosteriorError`` (before any work) for a start that is not this record's structure: another number of DOFs,
    other masses (the posterior holds the record's), the element elsewhere, or a state-space model (no masses).
    """
    from negstiff.inference.estimators.results import Identification
    from negstiff.inference.steps.equations import weak_frame

    source = "given"
    if isinstance(start, Identification):
        if start.linear_part != "physical":
            what = "the device on its base" if start.linear_part == "none" else "a structure read through its sensors"
            raise PosteriorError(f"{name}(start=...): an identification of {what} ({start.linear_part} linear part): a "
                                 "structure's posterior starts from a structure with its masses")  # fmt: skip
        structure, offsets = start.structure, np.asarray(start.offsets_m, float)
        source = f"given: {start.method}'s identification"
    elif isinstance(start, Structure):
        structure, offsets = start, None
    else:
        raise PosteriorError(f"{name}(start=...): a structure's posterior starts from a Structure or a structure's "
                             f"Identification, got a {type(start).__name__}")  # fmt: skip
    assert isinstance(structure, Structure)
    if structure.n_dof != rec.n_dof or tuple(structure.place) != tuple(at):
        raise PosteriorError(f"{name}(start=...): a structure of {structure.n_dof} DOFs with its element at "
                             f"{structure.place[0]}-{structure.place[1]}; the record has {rec.n_dof} DOFs, the element "
                             f"at {at[0]}-{at[1]}")  # fmt: skip
    if not np.allclose(structure.masses, rec.dof_masses, rtol=1e-6, atol=0.0):
        raise PosteriorError(f"{name}(start=...): the start structure's masses {list(structure.masses)} kg are not the "
                             f"record's {list(rec.dof_masses)} kg (the posterior holds the record's)")  # fmt: skip
    if offsets is None:
        zs, v, _ = rec.channel_states(at)
        offsets = weak_frame(rec, at, zs, v, rec.gravity)
        source = "given: a structure, its channels' zeros from the record's weak form"
    if offsets.shape != (rec.n_dof,):
        raise PosteriorError(f"{name}(start=...): {offsets.size} channel zeros for {rec.n_dof} channels")
    return structure, offsets, source


def fit_structure(est, recs: list[Measurement], at: tuple[int, int],
                  seed: int) -> tuple[PosteriorResult, list[str], Any]:  # fmt: skip
    """The element's posterior on ``recs`` (one record, or several of one structure fitted together: the element and
    the linear structure shared, each record its own windows, channels' zeros and sensor noise) for the ``Posterior``
    ``est``: (the result, its warnings, the windows).
    """
    from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS, identification_record, record_kind
    from negstiff.inference.estimators.sindy import SINDy

    rec, R, nd = recs[0], len(recs), recs[0].n_dof
    if est.start is None:
        ident = SINDy(element=at).fit(rec)
        start, first_offsets = ident.structure_, np.asarray(ident.offsets_, float)
        source = f"SINDy(element='{at[0]}-{at[1]}')"
    else:
        start, first_offsets, source = given_start(est.start, rec, at, type(est).__name__)
    # the other records' zeros read by their own weak form about the same structure (``given_start``): sampled as
    # nuisances, corrections of these, as the first's are of its start's
    offsets = [first_offsets, *(given_start(start, r, at, type(est).__name__)[1] for r in recs[1:])]
    kinds = [record_kind(r) for r in recs]
    kind = kinds[0]
    # a hammer's force windowed (zero between its pulses), a decay's input zero: as the fit read it
    read = [
        identification_record(r, rk) if rk.kind in RING_DOWN_KINDS else r for r, rk in zip(recs, kinds, strict=True)
    ]
    sims, datas, n_starts, L = [], [], [], 0
    for r, rk, o in zip(read, kinds, offsets, strict=True):
        one, d, starts, L = record_windows(start, r, o, est.window_s, est.max_windows, rk.kind in RING_DOWN_KINDS)
        one, d, starts = followed_windows(one, d, starts, L, start, r, element_values(start))
        sims.append(one)
        datas.append(d)
        n_starts.append(int(starts.size))
    rec = read[0]
    sim: StructureWindows | JointWindows = sims[0] if R == 1 else JointWindows(sims)
    data = datas[0] if R == 1 else np.concatenate(datas)
    n_obs_r = [d.size - one.W * 2 * nd for d, one in zip(datas, sims, strict=True)]  # the start states profiled out
    n_obs = sum(n_obs_r)
    parts = linear_parts(start)
    theta0 = np.r_[element_values(start), np.zeros(R * nd), [v for _, _, v in parts]]
    p = theta0.size
    sizes = [d.size for d in datas]  # each record's residuals (``JointWindows.residuals`` in the records' order)
    # one record: its residuals as they are; several: each record's whitened by its own sensor noise (a least-squares
    # point of unequal records' noise weighs each by it), the noise read from the previous round's residuals
    weights = None
    theta, cov, sigma, J, r0 = _gauss_newton(sim, data, theta0, n_obs)
    if R > 1:
        weights = _record_weights(r0, sizes, n_obs_r)
        theta, cov, sigma, J, r0 = _gauss_newton(sim, data, theta, n_obs, weights=weights)
    # the element and the windows' start states alternately, each a profile over the other (as the single DOF's MAP
    # point and its windows' states): starts refined for SINDy's element alone hold part of its error (k2's rms z
    # over the 12 fixture records 2.7 with one round, measured)
    for _ in range(ALTERNATIONS - 1):
        sim.refine_starts(theta, data)
        sim.start_sensitivity(theta)
        if weights is not None:
            weights = _record_weights(r0 / weights, sizes, n_obs_r)
        again = _gauss_newton(sim, data, theta, n_obs, weights=weights)
        moved = float(np.max(np.abs(again[0] - theta) / np.sqrt(np.diag(again[1]))))
        theta, cov, sigma, J, r0 = again
        if moved < ALTERNATION_TOL_SD:
            break
    # each record's sensor noise at the point (one record: ``sigma`` itself; several: J and r0 are whitened, sigma ~ 1)
    raw = r0 if weights is None else r0 / weights
    edges = np.cumsum([0, *sizes])
    sigmas = [sigma] if R == 1 else [float(np.sqrt(np.sum(raw[a:b] ** 2) / n)) for a, b, n in
                                     zip(edges[:-1], edges[1:], n_obs_r, strict=True)]  # fmt: skip
    # the single DOF's curvature adjustment by the windows' sandwich covariance (module docstring)
    s_gn = np.sqrt(np.diag(cov))
    A, V_a, inflation = curvature_adjustment(J * s_gn[None, :], r0, sim.W, sigma, adjust=est.adjust)
    tau_res = _correlation_time(raw.reshape(sim.W, nd, -1))
    H, M = information_parts(J, r0, sim.W, sigma)
    scale = np.r_[s_gn * np.sqrt(np.diag(V_a)), [1.0 / math.sqrt(2 * n) for n in n_obs_r]]
    centre = np.r_[theta, [math.log(x) for x in sigmas]]
    # the walkers' start ball inside the dampers' support (c, c_nl >= 0): a ring-down's c_nl at its bound (the
    # double well's decay on a fixture: -2.4e-4 +- 2.6e-4, measured) left 19 % of the ball where the density is
    # positive and no start was found; the start's place is burnt in, the posterior is the same
    centre[3:5] = np.maximum(centre[3:5], 2 * scale[3:5])
    noise = tuple(zip(sizes, n_obs_r, strict=True))
    log_prob = functools.partial(_log_prob, sim, data, theta, s_gn, A, centre, scale, noise)
    d = p + R
    run = sample_ensembles(log_prob, d, n_walkers=est.walkers(d), n_ensembles=est.n_ensembles, seed=seed,
                           tau_multiple=est.tau_multiple, min_steps=est.min_steps, max_steps=est.max_steps,
                           chunk=est.chunk, progress=est.progress,
                           chain_file=est.chains_to(centre, scale, d, seed))  # fmt: skip
    S = min(c.shape[0] for c in run["chains"])
    chains = np.stack([c[-S:] for c in run["chains"]])  # (E, S, walkers, d) scaled
    phys = centre + chains * scale
    phys[..., p:] = np.exp(phys[..., p:])
    point = np.r_[theta, sigmas]
    e = len(ELEMENT_NAMES)
    for k, o in enumerate(offsets):  # each channel's zero itself (measured = physical + offset)
        phys[..., e + k * nd : e + (k + 1) * nd] += o
        point[e + k * nd : e + (k + 1) * nd] += o
    names = (*ELEMENT_NAMES, *zero_names(nd, R), *(n for n, _, _ in parts), *noise_names(R))
    tau = np.array(run["tau"]) * 1.0
    map_point = {n: float(x) for n, x in zip(names, point, strict=True)}
    res = PosteriorResult(names=names, samples=phys, summary={}, tau=tau, warnings=list(run["warnings"]),
                          settings={}, map_point=map_point)  # fmt: skip
    res.summary = summarise(phys, names, tau, est.hdi_prob)
    res.warnings += convergence_warnings(res.summary, est.n_ensembles)
    tau_max = np.nanmax(tau) if np.isfinite(tau).any() else np.nan
    res.thin = max(1, int(np.ceil(tau_max / 2))) if np.isfinite(tau_max) else 1
    zeros_of = [zero_names(nd, R)[k * nd : (k + 1) * nd] for k in range(R)]
    input_rms = [
        0.0 if rk.kind in RING_DOWN_KINDS else input_noise_rms(r)[0] for r, rk in zip(read, kinds, strict=True)
    ]
    res.settings = {
        "model": "coefficients",
        "record_kind": kind.kind,
        "input": rec.input_name,
        "fs": rec.fs,
        "duration_s": rec.duration if R == 1 else [r.duration for r in read],
        "max_windows": est.max_windows,
        "dofs": nd,
        "element_at": list(at),
        "masses": list(rec.dof_masses),
        "window_s": L / rec.fs,
        "windows": int(sum(n_starts)),
        "substeps": SUBSTEPS,
        "curvature_adjustment": est.adjust,
        "variance_inflation": [round(float(x), 3) for x in inflation],
        # the record's model information and windows' score covariance at the MAP point (the sandwich's parts, as the
        # single DOF's posterior keeps them): a design joins a next test's to them as a joint fit would
        "laplace": {
            "parameters": list(names[:-R]),
            "information": H.tolist(),
            "score_covariance": None if M is None else M.tolist(),
        },  # fmt: skip
        "residual_correlation_time": tau_res,
        "input_noise": {
            "rms": None,
            "source": "not carried through a structure (the curvature adjustment widens "
            "for what the input's noise leaves in the residual)",
            # what the input's own spectrum shows of its sensor's noise: a design's simulated records carry it
            "record_rms": input_rms[0] if R == 1 else input_rms,
        },
        "samples_used": int(data.size),
        "walkers": est.walkers(d),
        "ensembles": est.n_ensembles,
        "kept_steps_per_ensemble": int(S),
        "tau_max_steps": float(tau_max) if np.isfinite(tau_max) else None,
        "priors": [
            "k1, k2, k3: flat",
            "c, c_nl: flat on [0, inf): the element dissipates",
            "each channel's zero: flat",
            "the linear structure's springs and dampers: flat",
            "log sigma: flat" if R == 1 else "each record's log sigma: flat",
        ],
        "seed": seed,
        "chain_file": None if est.chain_file is None else str(est.chain_file),
        "resumed_steps": run["resumed_steps"],
        "moves": MOVES,
        "fixed": "the masses; each channel's zero (offset_K) and the linear structure's springs and dampers "
        f"(spring_I-J, damper_I-J) sampled from {'SINDy' if est.start is None else 'the start'}'s as nuisances",
        "start": {"source": source, "structure": start.to_dict()},
        # the first record's (a joint fit's every record's: ``records``)
        "offsets_m": [float(res.summary[n]["mean"]) for n in zeros_of[0]],
        "start_offsets_m": [float(o) for o in offsets[0]],
        "model_mass": float(start.element.m),
    }
    if R > 1:
        res.settings["records"] = [
            {"source": str(r.source), "samples": int(r.n), "duration_s": r.duration, "windows": n_starts[k],
             "offsets_m": [float(res.summary[n]["mean"]) for n in zeros_of[k]],
             "start_offsets_m": [float(o) for o in offsets[k]]}
            for k, r in enumerate(read)
        ]  # fmt: skip
    res.build_idata = functools.partial(_idata, res, data)
    return res, list(res.warnings), sim


def record_windows(
    structure: Structure,
    rec: Measurement,
    offsets: np.ndarray,
    window_s: float,
    max_windows: int | None,
    ring_down: bool,
) -> tuple[StructureWindows, np.ndarray, np.ndarray, int]:
    """The windows a structure's posterior reads ``rec`` through (``window_starts``; a ring-down's between its
    pulses), each started from the record's band-smoothed state (``Measurement.channel_states``): (their simulator
    for ``structure``, the measured windows (W, N, L+1) in the structure's frame (each channel's zero ``offsets``
    taken off: measured = physical + offset), their first samples, the samples per window less one).
    """
    starts, L = window_starts(rec, window_s, max_windows, free=ring_down)
    zs, v, _ = rec.channel_states(structure.place)
    idx = starts[:, None] + np.arange(L + 1)[None, :]
    physical = rec.channels - offsets[:, None]
    data = np.transpose(physical[:, idx], (1, 0, 2))  # (W, N, L+1)
    x0 = np.hstack([(zs[:, starts] - offsets[:, None]).T, v[:, starts].T])
    return StructureWindows(structure, rec, idx, x0), data, starts, L


def followed_windows(
    sim: StructureWindows,
    data: np.ndarray,
    starts: np.ndarray,
    L: int,
    structure: Structure,
    rec: Measurement,
    theta: np.ndarray,
) -> tuple[StructureWindows, np.ndarray, np.ndarray]:
    """``record_windows``' windows, each started where the element ``theta`` follows it best
    (``StructureWindows.refine_starts``), with those it misses by far more than any other left out
    (``UNFOLLOWED_FACTOR`` x the median window's rms residual), their start-state directions set
    (``StructureWindows.start_sensitivity``); one ``PosteriorError`` when over a quarter of them (or all but 3) are.
    On a chain driven from rest by a force, the first window's input at the stage times is read partly from beyond the
    record (the interpolating filter's padding), and its run missed by 3.5 mm rms against 1 um in the others, which
    moved k3 to 2.6 times the truth with no word (measured).
    """
    sim.refine_starts(theta, data)
    sim.start_sensitivity(theta)
    rms = np.sqrt(np.mean(sim.residuals(theta[None], data)[0].reshape(sim.W, -1) ** 2, axis=1))
    bad = ~(rms <= UNFOLLOWED_FACTOR * np.median(rms))
    if not bad.any():
        return sim, data, starts
    if bad.sum() > sim.W // 4 or sim.W - bad.sum() < 4:
        raise PosteriorError(f"{rec.source}: {bad.sum()} of {sim.W} windows are not matched by the element "
                             f"(residual above {UNFOLLOWED_FACTOR:g}x the median window's): the model or the "
                             "record is far off")  # fmt: skip
    kept = starts[~bad]
    sim = StructureWindows(structure, rec, kept[:, None] + np.arange(L + 1)[None, :], sim.x0[~bad])
    sim.start_sensitivity(theta)
    return sim, data[~bad], kept


def zero_names(n_dof: int, n_records: int = 1) -> tuple[str, ...]:
    """The names of the channels' zeros a structure's posterior samples (nuisance parameters): ``offset_K`` for one
    record, ``offset_K_rR`` for record R of a joint fit's (record by record).
    """
    if n_records == 1:
        return tuple(f"offset_{k + 1}" for k in range(n_dof))
    return tuple(f"offset_{k + 1}_r{r + 1}" for r in range(n_records) for k in range(n_dof))


def element_values(structure: Structure) -> np.ndarray:
    """The element's coefficients the posterior samples (``ELEMENT_NAMES``)."""
    return np.array([getattr(structure.element, k) for k in ELEMENT_NAMES], float)


def residuals_and_jacobian(sim: StructureWindows | JointWindows, data: np.ndarray,
                           theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The windows' residuals at the parameters ``theta`` (the element's coefficients, and the nuisances where given:
    ``StructureWindows.simulate``) and their Jacobian (central differences, one batched call): (n_obs,), (n_obs, p).
    """
    p = theta.size
    h = 1e-4 * np.maximum(np.abs(theta), 1e-3)
    res = sim.residuals(np.vstack([theta, theta + np.diag(h), theta - np.diag(h)]), data)
    return res[0], ((res[1 : p + 1] - res[p + 1 : 2 * p + 1]) / (2 * h[:, None])).T


def mean_structure(settings: dict[str, Any], summary: dict[str, dict[str, float]]) -> Structure:
    """The start structure (``settings["start"]``) with the posterior mean's element and linear parts (where the
    posterior sampled them).
    """
    start = Structure.from_dict(settings["start"]["structure"])
    mean = {k: summary[k]["mean"] for k in ELEMENT_NAMES}
    out = start.with_element(start.element.__class__(**{**start.element.to_dict(), **mean}))
    parts = linear_parts(start)
    if parts and all(n in summary for n, _, _ in parts):
        out = with_linear_parts(out, parts, [summary[n]["mean"] for n, _, _ in parts])
    return out


def linear_parts(structure: Structure) -> list[tuple[str, np.ndarray, float]]:
    """The linear structure's springs and dampers, each (its name, its unit matrix, its value): a spring or damper
    to the base on DOF I (``spring_0-I``: e_I e_I^T) and between DOFs I and J (``spring_I-J``: (e_I - e_J)(e_I -
    e_J)^T), the nonzero ones of K and C; K = sum of the springs' value x matrix, C the dampers'.
    """
    out = []
    for label, M in (("spring", np.asarray(structure.K)), ("damper", np.asarray(structure.C))):
        n = M.shape[0]
        for i in range(n):
            ground = float(M[i].sum())  # K_ii + sum of the couplings' -k: the spring to the base
            if ground != 0.0:
                E = np.zeros((n, n))
                E[i, i] = 1.0
                out.append((f"{label}_0-{i + 1}", E, ground))
            for j in range(i + 1, n):
                if M[i, j] != 0.0:
                    E = np.zeros((n, n))
                    E[i, i] = E[j, j] = 1.0
                    E[i, j] = E[j, i] = -1.0
                    out.append((f"{label}_{i + 1}-{j + 1}", E, -float(M[i, j])))
    return out


def with_linear_parts(structure: Structure, parts: list[tuple[str, np.ndarray, float]], values) -> Structure:
    """``structure`` with its springs and dampers (``linear_parts``) at ``values``."""
    from dataclasses import replace

    n = structure.n_dof
    K, C = np.zeros((n, n)), np.zeros((n, n))
    for (name, E, _), v in zip(parts, values, strict=True):
        (K if name.startswith("spring") else C)[...] += float(v) * E
    return replace(structure, stiffness=K, damping=C)


def _log_prob(sim: StructureWindows | JointWindows, data, theta, s_gn, A, centre, scale, noise, xs: np.ndarray):
    """The log posterior at scaled points ``xs`` (one row each): emcee's vectorised callable (a module function
    bound by ``functools.partial``: the fitted estimator pickles). ``noise``: each record's (residuals, degrees of
    freedom), in the residuals' order, its log sigma a column after the ``theta``'s.
    """
    pts = centre[None, :] + xs * scale[None, :]
    out = [(-math.inf, 0.0)] * len(pts)
    ok = (pts[:, 3] >= 0) & (pts[:, 4] >= 0)
    p = theta.size
    if ok.any():
        adjusted = theta + ((pts[ok, :p] - theta) / s_gn) @ A.T * s_gn  # the likelihood's point
        res = sim.residuals(adjusted, data)  # (B, n_obs)
        lp = np.zeros(len(res))
        at = 0
        for k, (size, n) in enumerate(noise):
            log_sigma = pts[ok, p + k]
            lp += -0.5 * np.sum(res[:, at : at + size] ** 2, axis=1) / np.exp(2 * log_sigma) - n * log_sigma
            at += size
        for k, i in enumerate(np.flatnonzero(ok)):
            out[i] = (float(lp[k]) if np.isfinite(lp[k]) else -math.inf, 0.0)
    return out


def _idata(res: PosteriorResult, data: np.ndarray):
    """Arviz data of a structure's run: the posterior (each ensemble a chain, walker-major draws, thinned by half
    the autocorrelation time) and the windows' measured responses; no pointwise log likelihood (None).
    """
    import arviz as az

    E, S, W, d = res.samples.shape
    post = np.moveaxis(res.samples[:, :: res.thin], 2, 1)
    chains = post.reshape(E, -1, d)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = az.from_dict({"posterior": {n: chains[..., i] for i, n in enumerate(res.names)},
                             "observed_data": {"z": data}}, dims={"z": ["window", "dof", "time"]})  # fmt: skip
    tree.attrs.update({k: v for k, v in res.provenance.items() if isinstance(v, (str, int, float))})
    return tree, None


class StructureWindows:
    """The record's windows simulated for many element coefficient sets in one kernel call."""

    def __init__(self, structure: Structure, rec: Measurement, idx: np.ndarray, x0: np.ndarray):
        self.structure, self.dt = structure, rec.dt
        # the input at every Runge-Kutta stage time (band-limited interpolation of the whole record, ``stage_input``):
        # a record's input is band-limited, and over cross-well chaos the linear convention's small error grows
        # (measured on the tests' fixture record, the truth's 0.1 s windows: 31 um rms linear, 0.9 um staged)
        staged = stage_input(rec.u, SUBSTEPS)
        r = 2 * SUBSTEPS
        self.u = np.ascontiguousarray(staged[r * idx[:, 0][:, None] + np.arange(r * (idx.shape[1] - 1) + 1)[None, :]])
        self.x0 = x0
        self.Q: np.ndarray | None = None
        self.W = idx.shape[0]
        self.T = idx.shape[1]
        p, minv, K, C, gain = structure.arrays(rec.input_name, rec.force_dof)
        self.p, self.minv, self.K, self.C, self.gain = p, minv, K, C, gain
        parts = linear_parts(structure)
        # each spring's and damper's unit matrix, (S, N, N), and which are springs: read by every simulation
        self.part_matrices = np.stack([e for _, e, _ in parts]) if parts else np.zeros((0,) + K.shape)
        self.is_spring = np.array([n.startswith("spring") for n, _, _ in parts], dtype=bool)
        from negstiff.models.effects import POLYNOMIAL_ROWS, ROWS

        self.rows = [POLYNOMIAL_ROWS["k1"], POLYNOMIAL_ROWS["k2"], POLYNOMIAL_ROWS["k3"], ROWS["c"], ROWS["c_nl"]]

    def simulate(self, thetas: np.ndarray) -> np.ndarray:
        """(B, W, N, T) responses for B parameter sets: the element's k1, k2, k3, c, c_nl, then optionally its
        channels' zero corrections (N columns, taken off the windows' start states) and the linear structure's springs
        and dampers (``linear_parts``' order; without them the structure's own K and C).
        """
        B, W, nd = thetas.shape[0], self.W, self.structure.n_dof
        nb = B * W
        p = np.repeat(self.p[:, None], nb, axis=1)
        for j, row in enumerate(self.rows):
            p[row] = np.repeat(thetas[:, j], W)
        tile = lambda a: np.ascontiguousarray(np.repeat(a[..., None], nb, axis=-1))  # noqa: E731
        z0 = np.tile(self.x0[:, :nd].T, B)
        if thetas.shape[1] > len(self.rows):  # the physical start: the measured one less each channel's zero
            z0 = z0 - np.repeat(thetas[:, len(self.rows) : len(self.rows) + nd].T, W, axis=1)
        v0 = np.tile(self.x0[:, nd:].T, B)
        K, C = tile(self.K), tile(self.C)
        first = len(self.rows) + nd
        if thetas.shape[1] > first:  # each set's springs and dampers (``linear_parts``)
            lin, E = thetas[:, first:], self.part_matrices
            per = lambda keep: np.ascontiguousarray(  # noqa: E731 - (N, N, B W), each set's matrix W times
                np.repeat(np.einsum("bs,sij->ijb", lin[:, keep], E[keep]), W, axis=2)
            )
            K, C = per(self.is_spring), per(~self.is_spring)
        oz, _, status, _ = integrate(
            KINDS[self.structure.element.kind], np.ascontiguousarray(p), tile(self.minv), K, C,
            tile(self.gain), self.u, np.tile(np.arange(W), B), self.T, self.dt, SUBSTEPS, z0, v0,
            place=self.structure.place, z_limit=1.0, v_limit=100.0, threads=1,
        )  # fmt: skip
        z = np.transpose(oz, (2, 1, 0)).reshape(B, W, nd, self.T)
        z[status.reshape(B, W) != 0] = np.nan
        return z

    def _start_columns(self, theta: np.ndarray) -> np.ndarray:
        """Each window's response to its start state, d z / d x0 (central differences at ``theta``): (W, N T, 2N)."""
        nd = self.structure.n_dof
        x0 = self.x0.copy()
        h = np.r_[np.full(nd, 1e-7), np.full(nd, 1e-5)]
        cols = []
        for k in range(2 * nd):
            self.x0 = x0.copy()
            self.x0[:, k] += h[k]
            up = self.simulate(theta[None])[0]
            self.x0[:, k] -= 2 * h[k]
            down = self.simulate(theta[None])[0]
            cols.append(((up - down) / (2 * h[k])).reshape(self.W, -1))
        self.x0 = x0
        return np.stack(cols, axis=-1)

    def start_sensitivity(self, theta: np.ndarray) -> None:
        """Each window's response to its start state (``_start_columns``) kept as an orthonormal basis ``Q`` (W, N T,
        2N): ``residuals`` projects it out. The windows' start states come from the smoothed record (a fixture's
        velocity off by ~1 %), and over cross-well chaos their error grows into the residual within a window;
        projecting the start-state directions off profiles them out (as the single-DOF posterior does), at the cost
        of 2N degrees of freedom per window.
        """
        self.Q = np.linalg.qr(self._start_columns(theta))[0]

    def refine_starts(self, theta: np.ndarray, data: np.ndarray, steps: int = START_STEPS) -> None:
        """Each window's start state moved to where the element ``theta`` follows the window best (Gauss-Newton on the
        2N states, window by window; a step that does not lower a window's residual is not taken), as the single
        DOF's posterior refines its windows' starts (``Windows.refine_states``). The projection (``start_sensitivity``)
        profiles the states to first order only: near a saddle a smoothed state's error grows beyond it within a
        window, and on a 60 s cross-well record of the fixture (the rig's default random test) windows missed by up to
        33x the median window's, the record's variance inflation on k1 reached 3950 and its intervals 60x the width of
        another record's of the same test; refined, the worst window missed by 1.2x the median (measured).
        """
        base = self.misfit(theta[None], data)[0]
        for _ in range(steps):
            G = self._start_columns(theta)
            gtg = np.einsum("wik,wil->wkl", G, G)
            gtr = np.einsum("wik,wi->wk", G, base)
            ok = np.all(np.isfinite(gtg), axis=(1, 2)) & np.all(np.isfinite(gtr), axis=1)
            step = np.zeros_like(self.x0)
            step[ok] = -_solve_each(gtg[ok], gtr[ok])
            old = self.x0.copy()
            self.x0 = old + step
            moved = self.misfit(theta[None], data)[0]
            worse = ~(np.sum(moved**2, axis=1) < np.sum(base**2, axis=1))
            self.x0[worse] = old[worse]
            # the next step's misfit, each window's at the start it kept (one simulation less per step)
            base = np.where(worse[:, None], base, moved)

    def misfit(self, thetas: np.ndarray, data: np.ndarray) -> np.ndarray:
        """(B, W, N T) simulated less measured, the measured windows taken to each set's frame (less its channels'
        zero corrections, where ``thetas`` has them).
        """
        measured = data[None]
        if thetas.shape[1] > len(self.rows):
            nd = self.structure.n_dof
            measured = measured - thetas[:, None, len(self.rows) : len(self.rows) + nd, None]
        return (self.simulate(thetas) - measured).reshape(thetas.shape[0], self.W, -1)

    def residuals(self, thetas: np.ndarray, data: np.ndarray) -> np.ndarray:
        """(B, n_obs) residuals (simulated - measured) with the start states' directions projected off (when
        ``start_sensitivity`` has run), NaN where a window diverged.
        """
        r = self.misfit(thetas, data)
        if self.Q is not None:
            r = r - np.einsum("wik,bwk->bwi", self.Q, np.einsum("wik,bwi->bwk", self.Q, r))
        return r.reshape(thetas.shape[0], -1)


def _solve_each(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The solutions x[w] of A[w] x[w] = b[w], every w (least squares where A[w] is singular)."""
    try:
        return np.linalg.solve(A, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return np.array([np.linalg.lstsq(a, v, rcond=None)[0] for a, v in zip(A, b, strict=True)])


def _correlation_time(res: np.ndarray) -> float:
    """Integrated autocorrelation time [samples] of residuals (W, N, T) within their windows: 1 + 2 sum rho_k over
    the lags before rho first falls below 0.05 (1 for white noise).
    """
    r = res - res.mean(axis=-1, keepdims=True)
    var = float(np.mean(r**2))
    if not var > 0:
        return 1.0
    tau = 1.0
    for k in range(1, r.shape[-1] // 2):
        rho = float(np.mean(r[..., k:] * r[..., :-k])) / var
        if rho < 0.05:
            break
        tau += 2 * rho
    return tau


def _gauss_newton(sim: StructureWindows | JointWindows, data: np.ndarray, theta: np.ndarray, n_obs: int,
                  iterations: int = 6, weights: np.ndarray | None = None):  # fmt: skip
    """Least squares of the windows' residuals from ``theta`` (central-difference Jacobian, one batched call per
    iteration): the point, its covariance sigma^2 (J^T J)^-1, sigma, the last Jacobian and the point's residuals.
    ``weights``: each residual's (a joint fit's 1 / its record's sigma), the Jacobian and residuals returned weighted.
    """
    theta = theta.astype(float).copy()
    for _ in range(iterations):
        r0, J = _weighted(*residuals_and_jacobian(sim, data, theta), weights)
        if not np.all(np.isfinite(r0)):
            raise PosteriorError("SINDy's element does not survive the record's windows")
        step = np.linalg.lstsq(J, -r0, rcond=None)[0]
        theta = theta + step
        if np.all(np.abs(step) < 1e-6 * np.maximum(np.abs(theta), 1e-9)):
            break
    # the Jacobian at the point itself (the scores pair it with r0)
    r0, J = _weighted(*residuals_and_jacobian(sim, data, theta), weights)
    sigma = float(np.sqrt(np.sum(r0**2) / n_obs))
    cov = sigma**2 * np.linalg.inv(J.T @ J)
    return theta, cov, sigma, J, r0


def _weighted(r: np.ndarray, J: np.ndarray, weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Residuals (n,) and Jacobian (n, p) times each residual's weight (None: as they are)."""
    return (r, J) if weights is None else (r * weights, J * weights[:, None])


def _record_weights(r: np.ndarray, sizes: list[int], n_obs: list[int]) -> np.ndarray:
    """Each residual's weight in a joint fit: 1 / its record's sensor noise, sqrt(sum r^2 / degrees of freedom) over the
    record's residuals (``sizes``, in order; ``n_obs`` their degrees of freedom, the start states profiled out).
    """
    edges = np.cumsum([0, *sizes])
    return np.concatenate([np.full(b - a, math.sqrt(n / np.sum(r[a:b] ** 2)))
                           for a, b, n in zip(edges[:-1], edges[1:], n_obs, strict=True)])  # fmt: skip


class JointWindows:
    """Several records' windows of one structure read as one (a joint posterior: ``fit_structure``): the element's
    coefficients and the linear structure's springs and dampers shared, each record its own channels' zeros. The
    parameters are the element's, every record's zeros (record by record), then the springs and dampers; each
    record's ``StructureWindows`` reads its own, and the residuals follow in the records' order.
    """

    def __init__(self, sims: list[StructureWindows]):
        self.sims = sims
        self.n_dof = sims[0].structure.n_dof
        self.W = sum(s.W for s in sims)
        self.bounds = np.cumsum([0, *(s.W for s in sims)])

    def _thetas(self, thetas: np.ndarray, k: int) -> np.ndarray:
        """Record ``k``'s parameter sets (B, p_k): the element's, its own zeros, the shared springs and dampers."""
        e, nd, R = len(ELEMENT_NAMES), self.n_dof, len(self.sims)
        return np.hstack([thetas[:, :e], thetas[:, e + k * nd : e + (k + 1) * nd], thetas[:, e + R * nd :]])

    def _data(self, data: np.ndarray, k: int) -> np.ndarray:
        return data[self.bounds[k] : self.bounds[k + 1]]

    def residuals(self, thetas: np.ndarray, data: np.ndarray) -> np.ndarray:
        """(B, n_obs) every record's residuals (``StructureWindows.residuals``), record after record."""
        return np.hstack([s.residuals(self._thetas(thetas, k), self._data(data, k)) for k, s in enumerate(self.sims)])

    def misfit(self, thetas: np.ndarray, data: np.ndarray) -> np.ndarray:
        """(B, W, N T) every record's windows' misfits (``StructureWindows.misfit``), record after record."""
        return np.concatenate([s.misfit(self._thetas(thetas, k), self._data(data, k))
                               for k, s in enumerate(self.sims)], axis=1)  # fmt: skip

    def refine_starts(self, theta: np.ndarray, data: np.ndarray) -> None:
        """Each record's windows' start states (``StructureWindows.refine_starts``) at its parameters."""
        for k, s in enumerate(self.sims):
            s.refine_starts(self._thetas(theta[None], k)[0], self._data(data, k))

    def start_sensitivity(self, theta: np.ndarray) -> None:
        """Each record's windows' start-state directions (``StructureWindows.start_sensitivity``)."""
        for k, s in enumerate(self.sims):
            s.start_sensitivity(self._thetas(theta[None], k)[0])
