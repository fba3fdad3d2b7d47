"""Continuation in the reference study's report: section 8, the identified models' continuation set on
the rig's 9 Hz bifurcation map (compute, then render). The figure of ``negstiff nfrc`` is
``negstiff.report.figures.continuation_figure``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from negstiff.report.numbers import fmt
from negstiff.report.sections import draw_branches

from .characterisation import bifurcation_map


# --- the report's section: the identified models' continuation against the rig's bifurcation map -------
@dataclass(frozen=True)
class ContinuationStudy:
    """The rig's 9 Hz stepped map and, for each model and well, its continuation (or why it failed)."""

    rig_map: dict[str, Any]
    continuations: dict[tuple[str, str], dict[str, Any]]
    models: dict[str, Any]
    seconds: dict[str, float]
    posterior_doublings: dict[str, list[float | None]]
    """The first doubling from each well of models drawn from the coefficient posterior (the band)."""
    sweeps: list[dict[str, Any]]
    """Slow swept sines on the rig around z_plus, up and down: where the response jumps, and each model's
    folds at the same amplitude."""


def first_doubling_seen(rig_map: dict[str, Any], well: str) -> float | None:
    """The first amplitude of the rig's up sweep from ``well`` whose response is period 2 (or longer)."""
    from negstiff.inference.analysis.characterise import first_period_2

    return first_period_2([p for p in rig_map["points"] if p["start"] == well and p["direction"] == "up"])


def first_doubling_predicted(result: dict[str, Any]) -> float | None:
    pd = [b["amplitude"] for b in result.get("bifurcations", []) if b["type"] == "period_doubling" and b["period"] == 1]
    return float(min(pd)) if pd else None


def posterior_draws(m, n_draws: int, seed_: int, fast: bool) -> list:
    """Models drawn from the coefficient posterior of the record ``m`` (emcee, the suite's defaults but
    two ensembles, for a dozen draws; in --fast, two short ensembles).
    """
    from negstiff.inference.estimators.posterior import Posterior

    post = Posterior(seed=seed_, n_ensembles=2, max_steps=1500) if fast else Posterior(seed=seed_, n_ensembles=2)
    return post.fit(m).draw_models(n_draws, seed=seed_)


SWEEP_AMPLITUDES = (3.0, 3.5)
"""Table accelerations [m/s^2] of the swept sines around z_plus: the plus well softens, and at these
levels its response folds over (the truth's hysteresis: 0.2 and 0.8 Hz wide) without leaving the well."""
SWEEP_BAND = (5.5, 11.0)


def jump_frequency(rec, f_start: float, f_stop: float, duration: float) -> float:
    """Where a swept sine's response jumps: the largest change of its envelope (the analytic signal's
    modulus, averaged over 0.5 s), at the sweep's instantaneous frequency there.
    """
    from scipy import signal

    z = rec.columns["z"] - np.mean(rec.columns["z"])
    env = np.abs(signal.hilbert(z))
    n = max(1, int(0.5 * rec.fs))
    env = np.convolve(env, np.ones(n) / n, mode="same")
    t = rec.columns["t"] - rec.columns["t"][0]
    inner = (t > 5.0) & (t < t[-1] - 1.0)  # the start's transient and the averaging's edges are not jumps
    k = int(np.argmax(np.where(inner, np.abs(np.gradient(env)), 0.0)))
    return float(f_start + (f_stop - f_start) * t[k] / duration)


def frequency_sweeps(models: dict[str, Any], fast: bool, seed_: int) -> list[dict[str, Any]]:
    """Slow linear swept sines on the rig (the as-built device) around z_plus, up and down, at
    ``SWEEP_AMPLITUDES``; beside each, the models' folds (continuation in frequency) at that amplitude.
    """
    from negstiff.models.continuation import ContinuationError, nfrc
    from negstiff.models.rig import Rig

    duration = 150.0 if fast else 300.0
    out = []
    for amp in SWEEP_AMPLITUDES:
        folds = {}
        for name, system in models.items():
            try:
                r = nfrc(system, freq=SWEEP_BAND, amplitude=amp, well="plus", max_period=1)
                folds[name] = sorted(b["f_hz"] for b in r["bifurcations"] if b["type"] == "fold")
            except (ContinuationError, ValueError):
                folds[name] = []
        stepped = stepped_jumps(amp, fast, seed_)
        for direction, (fa, fb) in (("up", SWEEP_BAND), ("down", SWEEP_BAND[::-1])):
            rec = Rig(seed=seed_ + 7).sine_sweep(fa, fb, amp, duration, start="plus")
            out.append({"amplitude": amp, "direction": direction, "rate_hz_s": (fb - fa) / duration,
                        "rig_jump_hz": jump_frequency(rec, fa, fb, duration), "folds": folds,
                        "stepped_jump_hz": stepped[direction], "step_hz": STEP_HZ[fast]})  # fmt: skip
    return out


STEP_HZ = {False: 0.1, True: 0.25}
"""The rig's stepped sines' frequency step [Hz] (full run, --fast)."""


def stepped_jumps(amplitude: float, fast: bool, seed_: int) -> dict[str, float | None]:
    """Stepped sines on the rig (the as-built device, from z_plus) across ``SWEEP_BAND``, up and down in one
    batched run, as a lab measures a response curve: where each sweep's response amplitude (half the
    measured z's peak-to-peak) jumps (``characterise.jump``).
    """
    from negstiff.inference.analysis.characterise import jump
    from negstiff.models.rig import Rig

    step = STEP_HZ[fast]
    up = list(np.round(np.arange(SWEEP_BAND[0], SWEEP_BAND[1] + step / 2, step), 6))
    sweeps = Rig(seed=seed_ + 8).stepped_sines([up, up[::-1]], amplitude, ["plus", "plus"], 40 if fast else 60, 24)
    out = {}
    for direction, recs in zip(("up", "down"), sweeps, strict=False):
        points = [{"f_hz": r.truth["excitation"]["freq_hz"], "amplitudes": [0.5 * float(np.ptp(r.columns["z"]))]}
                  for r in recs]  # fmt: skip
        out[direction] = jump(points)
    return out


def compute_continuations(fast: bool, seed_: int = 0) -> ContinuationStudy:
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.estimators.sindy import SINDy
    from negstiff.inference.record.measurement import Measurement
    from negstiff.models import AS_BUILT
    from negstiff.models.continuation import ContinuationError, nfrc
    from negstiff.models.rig import Rig

    t0 = time.perf_counter()
    amps = np.round(np.arange(4.0, 26.01, 0.5 if fast else 0.2), 3)
    rig_map = bifurcation_map(Rig(seed=seed_ + 5), 9.0, amps, 40 if fast else 60, 32 if fast else 48)
    t1 = time.perf_counter()
    m = Measurement.from_rig(Rig(AS_BUILT, seed=seed_ + 2).random(duration=60.0 if fast else 300.0))
    models = {"truth (as-built device)": AS_BUILT, "NSI": NSI().fit(m).model_, "SINDy": SINDy().fit(m).model_}
    draws = posterior_draws(m, 6 if fast else 12, seed_, fast)
    t2 = time.perf_counter()
    conts: dict[tuple[str, str], dict[str, Any]] = {}
    for name, system in models.items():
        for well in ("plus", "minus"):
            try:
                conts[(name, well)] = nfrc(system, freq=9.0, amplitude=(2.0, 30.0), well=well, max_period=4)
            except (ContinuationError, ValueError) as exc:
                conts[(name, well)] = {"error": str(exc), "branches": [], "bifurcations": []}
    band: dict[str, list[float | None]] = {"plus": [], "minus": []}
    for draw in draws:
        for well in band:
            try:
                band[well].append(first_doubling_predicted(nfrc(draw, freq=9.0, amplitude=(2.0, 30.0), well=well,
                                                                max_period=1)))  # fmt: skip
            except (ContinuationError, ValueError):
                band[well].append(None)
    sweeps = frequency_sweeps(models, fast, seed_)
    t3 = time.perf_counter()
    seconds = {"rig_map_s": t1 - t0, "identification_s": t2 - t1, "continuation_s": t3 - t2}
    return ContinuationStudy(rig_map, conts, {k: v.to_dict() for k, v in models.items()}, seconds, band, sweeps)


def continuation_section(rep, results: dict[str, Any], fast: bool, seed_: int = 0) -> None:
    """Compute (``compute_continuations``), then render: the table of doublings, the overlay figure."""
    study = compute_continuations(fast, seed_)
    rep.heading("Continuation: does the identified model predict the bifurcation map?")
    rep.text(
        "Each model's periodic responses at 9 Hz are continued in the base-acceleration amplitude from 2 to 30 "
        "m/s^2, from either well (shooting on the simulator, pseudo-arclength through folds, Floquet multipliers; "
        "doubled branches followed to period 4), and set on the rig's stepped 9 Hz map of the as-built device "
        "(the experiment). The models: the truth behind the rig (the exact device geometry), and NSI's and SINDy's "
        "cubics identified from a random cross-well record of the same device (the identification sections' "
        "recipe), and models drawn from the coefficient posterior of the same record (emcee): the range of their "
        "first doublings is the prediction's uncertainty band."
    )
    rows: list[list[Any]] = []
    res: dict[str, Any] = {"seconds": study.seconds, "models": {}}
    for well in ("plus", "minus"):
        seen = first_doubling_seen(study.rig_map, well)
        res.setdefault("rig_first_doubling", {})[well] = seen
        for name in study.models:
            r = study.continuations[(name, well)]
            pred = first_doubling_predicted(r)
            folds = [b["amplitude"] for b in r["bifurcations"] if b["type"] == "fold" and b["period"] == 1]
            res["models"].setdefault(name, {})[well] = {
                "first_doubling": pred,
                "folds": folds,
                "bifurcations": r["bifurcations"],
                "error": r.get("error"),
            }
            diff = None if (pred is None or seen is None) else f"{100 * (pred / seen - 1):+.1f} %"
            rows.append([f"z_{well}", name, pred, seen, diff, ", ".join(fmt(f, 4) for f in folds) or "-"])
        got = [v for v in study.posterior_doublings[well] if v is not None]
        lo, hi = (float(np.min(got)), float(np.max(got))) if got else (None, None)
        res.setdefault("posterior_band", {})[well] = {"draws": study.posterior_doublings[well], "min": lo, "max": hi}
        label = f"posterior draws ({len(got)} of {len(study.posterior_doublings[well])} with a doubling): range"
        rows.append([f"z_{well}", label, f"{fmt(lo, 4)} - {fmt(hi, 4)}" if got else "none", seen, "-", "-"])
    results["continuation"] = res
    rep.table(
        ["well", "model", "first doubling predicted [m/s^2]", "first period 2 on the rig map [m/s^2]", "difference",
         "folds of the period-1 branch [m/s^2]"],
        rows,
    )  # fmt: skip
    rep.text(_reading(res, study.models))
    _render_sweeps(rep, res, study)
    rep.figure(
        "continuation_vs_map",
        _overlay(study),
        "The rig's 9 Hz map (grey: Poincare z of the stepped sweeps up and down) and each model's continued "
        "periodic orbits (their Poincare points; solid stable, dashed unstable), from z_plus (left) and z_minus "
        "(right); orange: the range of the first doubling over the coefficient posterior's draws (drawn at least "
        "0.1 m/s^2 wide).",
    )


def _render_sweeps(rep, res: dict[str, Any], study: ContinuationStudy) -> None:
    """The swept sines' jumps against the folds: sweeping up, the branch the response is on ends at the
    upper fold; sweeping down, at the lower one (hardening or softening alike).
    """
    rows = []
    for s in study.sweeps:
        row = [s["amplitude"], s["direction"], f"{s['rate_hz_s']:+.3f}", s["rig_jump_hz"], s["stepped_jump_hz"]]
        for name in study.models:
            f = s["folds"][name]
            fold = (max(f) if s["direction"] == "up" else min(f)) if f else None
            row.append(fold)
        rows.append(row)
    res["sweeps"] = study.sweeps
    step = study.sweeps[0]["step_hz"] if study.sweeps else None
    rep.table(["amplitude [m/s^2]", "sweep", "rate [Hz/s]", "rig: jump [Hz]", f"rig, {step:g} Hz steps: jump [Hz]"]
              + [f"{n}: fold [Hz]" for n in study.models], rows)  # fmt: skip
    rep.text(
        "Slow linear swept sines on the rig (the as-built device, from z_plus, up and down) against the folds of "
        "each model's frequency response at the same amplitude (the plus well softens: its response curve leans "
        "to lower frequencies). Sweeping up, the branch the response is on ends at the upper fold; sweeping down, "
        "at the lower one; the jump comes a little late (the response needs a few of its time constants to leave "
        "a branch that no longer exists). The jump is read as the largest change of the response's envelope. "
        "Beside them, stepped sines as a lab measures a response curve (`negstiff rig campaign --freqs`, read as "
        "`negstiff map` reads one): the frequency stepped without stopping the table, each step settled, the jump "
        "placed midway between the two steps whose response amplitudes differ most (a step near a fold can knock "
        "the response off its branch early: on a Duffing oscillator 0.25 Hz steps dropped a step before the fold, "
        "tests/methods/test_map.py)."
    )


def _reading(res: dict[str, Any], models: dict[str, Any]) -> str:
    parts, cover = [], []
    truth = "truth (as-built device)"
    for well in ("plus", "minus"):
        seen = res["rig_first_doubling"][well]
        preds = {n: v[well]["first_doubling"] for n, v in res["models"].items()}
        txt = ", ".join(f"{n} {fmt(p, 4) if p is not None else 'none'}" for n, p in preds.items())
        band = res["posterior_band"][well]
        if band["min"] is not None:
            txt += f", the posterior's draws {fmt(band['min'], 4)}-{fmt(band['max'], 4)}"
            t = preds.get(truth)
            if t is not None:
                inside = band["min"] <= t <= band["max"]
                cover.append(f"z_{well}: the draws {'cover' if inside else 'do not cover'} the truth's {fmt(t, 4)}")
        parts.append(f"from z_{well} the rig's map first shows period 2 at {fmt(seen, 4) if seen else 'no amplitude'}"
                     f" m/s^2 (steps of the map), the models predict the first doubling at: {txt}")  # fmt: skip
    extra = {n: sorted((m.get("extra") or {}).keys()) for n, m in models.items() if n != truth}
    terms = "; ".join(f"{n}: {', '.join(e) if e else 'none'}" for n, e in extra.items())
    return (
        "; ".join(parts) + ". The truth's prediction checks the method (it must sit at the map's doubling within "
        "the map's step). The identified models' differences are their model-form error (named extra terms beyond "
        f"the cubic, {terms}): a doubling's amplitude is sensitive to the well's local stiffness, which a cubic "
        "fitted over the whole stroke bends. The posterior's band is the cubic's coefficient uncertainty only ("
        + "; ".join(cover or ["no draws"])
        + "): where it misses the truth, the gap is the model's form, which no coefficient uncertainty covers."
    )


def _overlay(study: ContinuationStudy):
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 4.6), sharey=True)
    colors = dict(zip(study.models, ("k", "C0", "C3"), strict=False))
    for ax, well in zip(axes, ("plus", "minus"), strict=False):
        for p in study.rig_map["points"]:
            if p["start"] == well:
                ax.plot(np.full(len(p["poincare_z"]), p["amplitude"]), 1e3 * np.asarray(p["poincare_z"]), ".",
                        ms=2.0, color="0.45", zorder=3)  # fmt: skip
        for name in study.models:
            draw_branches(ax, study.continuations[(name, well)]["branches"], colors[name], name)
        got = [v for v in study.posterior_doublings[well] if v is not None]
        if got:  # the posterior's band: where its draws put the first doubling (at least 0.1 m/s^2 wide, to be seen)
            lo, hi = min(got), max(got)
            mid, half = (lo + hi) / 2, max(hi - lo, 0.1) / 2
            ax.axvspan(mid - half, mid + half, color="C1", alpha=0.35, lw=0, zorder=1,
                       label=f"posterior draws' first doubling ({fmt(lo, 4)}-{fmt(hi, 4)})")  # fmt: skip
        ax.set(xlabel="base acceleration amplitude [m/s^2]", title=f"from z_{well}", xlim=(2, 30))
        ax.legend(fontsize=8)
    axes[0].set_ylabel("Poincare z (phase 0) [mm]")
    fig.tight_layout()
    return fig
