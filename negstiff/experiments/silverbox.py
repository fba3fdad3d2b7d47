"""The Silverbox benchmark (Wigren & Schoukens 2013): every identification method on real data, judged
by what it predicts.

An electronic circuit realising a forced Duffing oscillator (force input V1, displacement output V2,
610.35 Hz). The standard split: train on samples 40650-105712 (multisines), test on the multisine
segment 105712-127400 and on the "arrow" (0-40575, filtered Gaussian noise of growing amplitude whose
last third exceeds the training amplitude: extrapolation); the first 50 test samples initialise the
state and are not scored. Each model is simulated free-run on the test input from the measured state.

Computed first (``compute``, a ``SilverboxStudy``), rendered second (``render``).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from negstiff.datasets import (  # the benchmark's split and protocol
    ARROW,
    ARROW_NO_EXTRAPOLATION,
    OUTPUT_ERROR_DUFFING_MV,
    PUBLISHED_BY_TEST_SET_MV,
    PUBLISHED_MV,
    SKIP,
    TEST,
    TRAIN,
    prediction_error_mv,
    silverbox,
)
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.validation import simulate_record
from negstiff.models import Model
from negstiff.report.document import Report, run_study
from negstiff.report.numbers import fmt


@dataclass
class MethodRow:
    """One method on the benchmark: its equation-error model, the refined one, their errors [mV]."""

    method: str
    initial: dict[str, Any]
    refined: dict[str, Any]
    refinement_kept: bool
    seconds: float
    detail: dict[str, Any] = field(default_factory=dict)


@dataclass
class SilverboxStudy:
    rows: list[MethodRow]
    record: dict[str, Any]
    hybrid: dict[str, Any] | None = None


def _scores(model: Model, m: Measurement) -> dict[str, Any]:
    return {
        "test_mv": prediction_error_mv(model, m, TEST),
        "arrow_mv": prediction_error_mv(model, m, ARROW),
        "arrow_no_extrapolation_mv": prediction_error_mv(model, m, ARROW_NO_EXTRAPOLATION),
        "model": model.to_dict(),
    }


def compute(m: Measurement, fast: bool = False) -> SilverboxStudy:
    """Fit every method on the training part with its defaults (refinement included) and score the
    equation-error and refined models on the three test parts (``fast``: without the discrepancy
    workflow's linear start and NSI).
    """
    from negstiff.inference.estimators.discrepancy import LINEAR_BASELINE, Discrepancy
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.estimators.sindy import SINDy

    train = m.segment(*TRAIN)
    rows = []
    fits = {
        "NSI": lambda: NSI().fit(train),
        "SINDy": lambda: SINDy().fit(train),
        "discrepancy (cubic baseline, default)": lambda: Discrepancy().fit(train),
        "discrepancy from a linear start": lambda: Discrepancy(baseline=LINEAR_BASELINE).fit(train),
    }
    if fast:  # the two slowest rows (the report's figure and text use SINDy and the default discrepancy)
        fits.pop("discrepancy from a linear start")
        fits.pop("NSI")
    for name, fit in fits.items():
        t0 = time.perf_counter()
        est = fit()
        seconds = time.perf_counter() - t0
        initial = _scores(est.initial_model_, m)
        initial["test_mv_linear_input"] = prediction_error_mv(est.initial_model_, m, TEST, linear=True)
        refined = _scores(est.model_, m)
        info = est.refinement_ or {}
        detail: dict[str, Any] = {"refinement": {k: v for k, v in info.items() if k not in ("initial_model",)}}
        if hasattr(est, "effects_"):
            detail["effects"] = est.effects_ or ["none"]
            detail["gap_percent"] = [est.gap_before_.get("median_window_percent"),
                                     est.gap_after_.get("median_window_percent")]  # fmt: skip
        if hasattr(est, "selected_"):
            detail["selected_terms"] = est.selected_
        rows.append(MethodRow(name, initial, refined, bool(info.get("applied")), seconds, detail))
    record = {"fs_hz": m.fs, "samples": m.n, "train": TRAIN, "test": TEST, "arrow": ARROW}
    # the hybrid takes a minute and a half: the full run only
    return SilverboxStudy(rows, record, None if fast else hybrid_part(m, rows))


def hybrid_error_mv(h, m: Measurement, part: tuple[int, int]) -> float:
    """``prediction_error_mv`` for a hybrid model (inf if it diverges)."""
    seg = m.segment(*part)
    zs, v, _, _ = seg.states("state")
    scored = seg.segment(SKIP, seg.n)
    z = h.free_run(scored, (zs[SKIP], v[SKIP]))
    return float(1e3 * np.sqrt(np.mean((z - scored.z) ** 2))) if np.all(np.isfinite(z)) else float("inf")


def hybrid_part(m: Measurement, rows: list[MethodRow]) -> dict[str, Any]:
    """The refined SINDy model plus a non-parametric discrepancy force (``inference.hybrid``), fitted on
    the training part with the physics held, then refitted jointly; its errors on the three test parts.
    """
    from negstiff.inference.estimators.hybrid import fit_hybrid

    row = next(r for r in rows if r.method == "SINDy")
    physics = Model.from_dict(row.refined["model"])
    t0 = time.perf_counter()
    train = m.segment(*TRAIN)
    h = fit_hybrid(physics, train)
    seconds = time.perf_counter() - t0
    zs, vs, _, _ = train.states("state")
    term = h.term(zs, vs, train.u)
    restoring = physics.restoring_force(zs)
    held = h.held()
    return {
        "physics": "SINDy, refined",
        "test_mv": hybrid_error_mv(h, m, TEST),
        "arrow_mv": hybrid_error_mv(h, m, ARROW),
        "arrow_no_extrapolation_mv": hybrid_error_mv(h, m, ARROW_NO_EXTRAPOLATION),
        "held_fit": {  # the physics as given, the term alone fitted (its coefficients are the physics')
            "test_mv": hybrid_error_mv(held, m, TEST),
            "arrow_mv": hybrid_error_mv(held, m, ARROW),
            "arrow_no_extrapolation_mv": hybrid_error_mv(held, m, ARROW_NO_EXTRAPOLATION),
            "term_rms_N": float(np.sqrt(np.mean(held.term(zs, vs, train.u) ** 2))),
        },
        "physics_test_mv": row.refined["test_mv"],
        "physics_arrow_mv": row.refined["arrow_mv"],
        "physics_arrow_no_extrapolation_mv": row.refined["arrow_no_extrapolation_mv"],
        "term_rms_N": float(np.sqrt(np.mean(term**2))),
        "physical_force_rms_N": float(np.sqrt(np.mean(restoring**2))),
        "seconds": seconds,
        **h.to_json(),
    }


def _figure(study: SilverboxStudy, m: Measurement):
    import matplotlib.pyplot as plt
    from scipy import signal

    row = next(r for r in study.rows if r.method == "SINDy")
    model = Model.from_dict(row.refined["model"])
    seg = m.segment(*ARROW)
    zs, v, _, _ = seg.states("state")
    sim = simulate_record(model, seg.segment(SKIP, seg.n), (zs[SKIP], v[SKIP]))
    err = 1e3 * (sim.z[0] - seg.displacement[SKIP:])
    t = seg.t[SKIP:]
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
    ax[0].plot(t, 1e3 * seg.displacement[SKIP:], color="0.75", lw=0.5, label="measured output")
    ax[0].plot(t, 10 * err, color="C3", lw=0.5, label="prediction error x10")
    ax[0].axvspan(t[ARROW_NO_EXTRAPOLATION[1] - SKIP], t[-1], color="C1", alpha=0.12, label="beyond training amplitude")
    ax[0].set(xlabel="t [s]", ylabel="[mV]", title="Arrow: refined SINDy model, free run")
    ax[0].legend(fontsize=7, loc="upper left")
    test = m.segment(*TEST)
    zt, vt, _, _ = test.states("state")
    for r, c in ((row, "C0"),):
        for which, ls in (("initial", "--"), ("refined", "-")):
            mm = Model.from_dict(getattr(r, which)["model"])
            s = simulate_record(mm, test.segment(SKIP, test.n), (zt[SKIP], vt[SKIP]))
            f, p = signal.welch(1e3 * (s.z[0] - test.displacement[SKIP:]), test.fs, nperseg=2048)
            ax[1].semilogy(f, p, ls, color=c, lw=0.8, label=f"{r.method} {which} model: error")
    f, p = signal.welch(1e3 * test.displacement[SKIP:], test.fs, nperseg=2048)
    ax[1].semilogy(f, p, color="0.6", lw=0.8, label="measured output")
    ax[1].set(xlabel="f [Hz]", ylabel="PSD [mV^2/Hz]", title="Multisine test: error spectrum")
    ax[1].legend(fontsize=7)
    fig.tight_layout()
    return fig


def _span(values) -> str:
    """'a-b' of a few numbers at 3 digits, or one number when they agree at that precision."""
    v = list(values)
    lo, hi = fmt(min(v), 3), fmt(max(v), 3)
    return lo if lo == hi else f"{lo}-{hi}"


def render(rep: Report, study: SilverboxStudy, m: Measurement) -> dict[str, Any]:
    """Tables, a figure and the text; returns the results entry."""
    rep.heading("Real data: the Silverbox benchmark", 2)
    rep.text(
        "Every method trained on samples 40650-105712 only, with its defaults (output-error refinement included), "
        "then simulated free-run on the test inputs from the measured state; the first 50 samples of each test part "
        "are not scored. Multisine test: 105712-127400. Arrow: 0-40575 (its last third exceeds the training "
        "amplitude); arrow without extrapolation: 100-32100. The column 'linear input' is the same equation-error "
        "model simulated with the input drawn straight between samples, the suite's convention before band-limited "
        "stage inputs."
    )
    rep.table(
        ["method", "equation-error model: test [mV], linear input", "test [mV]", "refined: test [mV]",
         "arrow [mV]", "arrow without extrapolation [mV]", "refinement kept", "fit time [s]"],
        [[r.method, r.initial["test_mv_linear_input"], r.initial["test_mv"], r.refined["test_mv"],
          r.refined["arrow_mv"], r.refined["arrow_no_extrapolation_mv"], r.refinement_kept, r.seconds]
         for r in study.rows],
    )  # fmt: skip
    rep.table(
        ["published model (multisine test)", "rms error [mV]"],
        [[k, v] for k, v in PUBLISHED_MV.items()] + [["output-error Duffing ODE, linear input (issue anchor)",
                                                      OUTPUT_ERROR_DUFFING_MV]],
    )  # fmt: skip
    best = min(study.rows, key=lambda r: r.refined["test_mv"])
    rep.table(
        ["model, every test set", "multisine test [mV]", "arrow [mV]", "arrow without extrapolation [mV]"],
        [[k, *("-" if v is None else v for v in vals)] for k, vals in PUBLISHED_BY_TEST_SET_MV.items()]
        + [[f"negstiff: {best.method} (this run)", best.refined["test_mv"], best.refined["arrow_mv"],
            best.refined["arrow_no_extrapolation_mv"]]],
    )  # fmt: skip
    lin = [r.initial["test_mv_linear_input"] for r in study.rows]
    bl = [r.initial["test_mv"] for r in study.rows]
    disc = next(r for r in study.rows if r.method.startswith("discrepancy (cubic"))
    rep.text(
        f"What decided the prediction was not the identification but the input between samples. The record passed "
        f"an anti-aliasing filter, so its input is band-limited; drawn straight between samples, its 60-200 Hz "
        f"band (0.1-0.33 of the 610 Hz rate) loses up to 31 % of its amplitude (sinc^2), and the equation-error "
        f"models predicted with {_span(lin)} mV error. With the input interpolated "
        f"band-limited at every Runge-Kutta stage and the step refined to omega h <= 0.25, the same models predict "
        f"with {_span(bl)} mV, and the output-error refinement brings every method to "
        f"{_span(r.refined['test_mv'] for r in study.rows)} mV (best: {best.method}), below the best published "
        f"model quoted ({fmt(PUBLISHED_MV['GP-NARX'], 2)} mV). The arrow's extrapolating last third is predicted too "
        f"(full arrow {fmt(best.refined['arrow_mv'], 3)} mV, without its extrapolating part "
        f"{fmt(best.refined['arrow_no_extrapolation_mv'], 3)} mV; the data's README quotes SUBNET at "
        f"{fmt(PUBLISHED_BY_TEST_SET_MV['SUBNET neural state-space'][1], 2)} mV on the full arrow: a physical model "
        "extrapolates where a black box has seen nothing). The discrepancy workflow named "
        f"**{', '.join(disc.detail.get('effects', ['none']))}** beyond the cubic Duffing form."
    )
    rep.figure(
        "silverbox_prediction",
        _figure(study, m),
        "Left: the refined SINDy model's free-run prediction error (x10) on the arrow; shaded, the part beyond the "
        "training amplitude. Right: spectrum of the multisine-test prediction error before (dashed) and after "
        "refinement, against the output's.",
    )
    if study.hybrid is not None:
        _render_hybrid(rep, study.hybrid, m)
    return {
        "hybrid": study.hybrid,
        "record": study.record,
        "methods": {
            r.method: {
                "initial": r.initial,
                "refined": r.refined,
                "refinement_kept": r.refinement_kept,
                "seconds": r.seconds,
                **r.detail,
            }
            for r in study.rows
        },  # fmt: skip
        "published_mv": PUBLISHED_MV,
        "published_by_test_set_mv": {
            k: dict(zip(("test", "arrow", "arrow_no_extrapolation"), v, strict=True))
            for k, v in PUBLISHED_BY_TEST_SET_MV.items()
        },
    }


def _render_hybrid(rep: Report, h: dict[str, Any], m: Measurement) -> None:
    import matplotlib.pyplot as plt

    from negstiff.inference.estimators.hybrid import Basis

    rep.heading("What Duffing still misses: a non-parametric discrepancy term", 3)
    rep.text(
        "Beyond the catalogue: the refined SINDy model plus a smooth force g(z, z', u) (Gaussian bumps on a grid "
        "over the states and inputs the training part visits, kept orthogonal to every force the physics can make, "
        "so the term carries only what the physics cannot), fitted by simulation error on 1 s windows with a ridge "
        "penalty, first with the physics held (its coefficients stay the physics' own estimate), then together "
        "with the physics (the joint hybrid). Their errors on the same test parts, the size of the term, and how "
        "far the joint fit moved each physical coefficient in units of its standard error (from the fit's "
        "Jacobian, start states marginalised, inflated by the residual's correlation time)."
    )
    held = h.get("held_fit", {})
    rep.table(
        ["model", "test [mV]", "arrow [mV]", "arrow without extrapolation [mV]", "fit time [s]"],
        [["refined SINDy (physics)", h["physics_test_mv"], h["physics_arrow_mv"],
          h["physics_arrow_no_extrapolation_mv"], "-"],
         ["physics held + term", held.get("test_mv"), held.get("arrow_mv"), held.get("arrow_no_extrapolation_mv"),
          "(first stage)"],
         ["physics + term, fitted jointly", h["test_mv"], h["arrow_mv"], h["arrow_no_extrapolation_mv"],
          h["seconds"]]],
    )  # fmt: skip
    rows = [[n, c["held"], c["joint"], c["se"], c["shift_in_se"]] for n, c in h["joint"]["coefficients"].items()]
    rep.table(["coefficient", "physics (held)", "joint refit", "standard error", "shift / standard error"], rows)
    gain = (h["physics_test_mv"] - h["test_mv"]) / h["physics_test_mv"] if h["physics_test_mv"] else float("nan")
    worst = max((abs(r[4]) for r in rows if r[4] is not None), default=float("nan"))
    rep.text(
        f"The term carries {fmt(h['term_rms_N'], 2)} (rms over the training states) against a restoring force of "
        f"{fmt(h['physical_force_rms_N'], 2)}, in the circuit's units: "
        f"{fmt(100 * h['term_rms_N'] / h['physical_force_rms_N'], 2)} %. It changes the multisine-test error from "
        f"{fmt(h['physics_test_mv'], 3)} to {fmt(h['test_mv'], 3)} mV ({fmt(100 * gain, 2)} %); the joint "
        f"fit moved the physical coefficients by up to {fmt(worst, 2)} standard errors"
        + (" (within their uncertainty). " if worst <= 3 else
           ": beyond their uncertainty, so on this record the term and the physics are not fully separable, or "
           "the physics-only fit had bent its coefficients to cover what the term now carries. ")
        + (f"With the physics held the term brings the test to {fmt(held['test_mv'], 3)} mV and the full arrow to "
           f"{fmt(held['arrow_mv'], 3)} mV (physics {fmt(h['physics_arrow_mv'], 3)}, joint {fmt(h['arrow_mv'], 3)})"
           + (": beyond the training range the bumps vanish and both hybrids are their physics there, so the "
              "arrow's larger amplitudes judge the cubic, and the joint fit's changed cubic predicts them worse. "
              if held["arrow_mv"] < h["arrow_mv"] else ". ")
           if held.get("test_mv") is not None else "")
        + ("What remains unnamed is small against what the physics explains: a physical effect hiding in it would "
           "have to be smaller still." if abs(gain) < 0.2 else
           "The term explains a visible part of the error: its shape below says where to look for a physical "
           "effect.")
    )  # fmt: skip
    basis = Basis.from_json(h["basis"])
    theta = np.array(h["weights_N"])
    train = m.segment(*TRAIN)
    zs, vs, _, _ = train.states("state")
    zg = np.linspace(basis.zc[0], basis.zc[-1], 80)
    vg = np.linspace(basis.vc[0], basis.vc[-1], 80)
    Z, V = np.meshgrid(zg, vg)
    G = basis.evaluate(theta, Z, V)
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    lim = float(np.abs(G).max()) or 1.0
    cs = ax[0].contourf(1e3 * Z, V, G, 21, cmap="RdBu_r", vmin=-lim, vmax=lim)
    fig.colorbar(cs, ax=ax[0], label="g(z, z') [force units]")
    ax[0].plot(1e3 * zs[::40], vs[::40], ",", color="0.2", alpha=0.3)
    ax[0].set(xlabel="z [mV]", ylabel="z' [V/s]", title="Discrepancy force over the visited states")
    if basis.uc.size:
        ug = np.linspace(basis.uc[0], basis.uc[-1], 200)
        ax[1].plot(1e3 * ug, basis.input_part(theta, ug))
        ax[1].set(xlabel="input u [mV]", ylabel="g's input part [force units]", title="Discrepancy force's input part")
    fig.tight_layout()
    rep.figure(
        "silverbox_discrepancy_term",
        fig,
        "Left: the non-parametric discrepancy force g(z, z') over the states the training part visits (dots); "
        "right: its part that depends on the input alone.",
    )


def silverbox_section(rep: Report, results: dict[str, Any], fast: bool, seed_: int = 0) -> None:
    """The Silverbox section of the report (deterministic: no seed; ``fast`` drops the linear start and NSI)."""
    m = silverbox()
    results["silverbox"] = render(rep, compute(m, fast), m)


def main(argv=None) -> int:
    return run_study(silverbox_section, "negstiff: the Silverbox benchmark", "reports/silverbox", __doc__, argv)


if __name__ == "__main__":
    sys.exit(main())
