"""SINDy study: equation discovery on the virtual rig (polynomial truth, a hidden friction force, the
as-built device's exact geometry), beside NSI on the same records (the Silverbox: ``silverbox.py``).

    python -m negstiff.experiments.sindy [-o reports/sindy] [--fast]
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
from scipy import signal

from negstiff.inference.estimators.nsi import NSI
from negstiff.inference.estimators.sindy import SINDy
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.weak import term_fields
from negstiff.models import AS_BUILT, SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC, Model
from negstiff.models.rig import Rig
from negstiff.report.document import Report, run_study
from negstiff.report.numbers import fmt

from .nsi import law_rows, pct, true_floor

HIDDEN_FRICTION_N = 0.1
"""Coulomb friction hidden in the rig for the ensemble check [N] (5 % of the device's weight)."""


def _coefficient_rows(est: SINDy, truth: Model | None, nsi: NSI | None) -> list[list[Any]]:
    rows = []
    for term, (field, _) in term_fields().items():
        base = field in ("k0", "k1", "k2", "k3", "c", "c_nl")
        val = getattr(est.model_, field) if base else est.model_.extra.get(field, 0.0)
        tru = None if truth is None else (getattr(truth, field) if base else truth.extra.get(field, 0.0))
        nv = getattr(nsi.model_, field) if (nsi is not None and base) else None
        ens = est.ensemble_[term]
        rows.append(
            [
                term,
                field,
                "yes" if term in est.selected_ else "no",
                ens["inclusion_probability"],
                val,
                "" if tru is None else tru,
                "" if (tru in (None, 0.0) or val == 0.0) else pct(val, tru),
                ens["sd"],
                "" if nv is None else nv,
            ]
        )
    return rows


COEF_HEADER = ["term", "field", "selected", "inclusion prob.", "SINDy", "truth", "error", "ensemble sd", "NSI"]


@dataclass(frozen=True)
class SindyRun:
    """What one part of the study measured: SINDy's fit of one rig record (``est``, wall time ``elapsed``),
    the truth behind the record, and what the part compares it with: NSI on the same record, the effect
    the rig hid, the true model's own held-out free-run floor.
    """

    truth: Model
    measurement: Measurement
    est: SINDy
    elapsed: float
    duration: float
    nsi: NSI | None = None
    hidden: dict[str, float] | None = None
    floor: float | None = None
    by_law: SINDy | None = None
    """SINDy with every law compared on the same record (``law="auto"``; the as-built part)."""

    def result(self) -> dict[str, Any]:
        """The part's entry of results.json."""
        r = self.est.result()
        r["elapsed_s"] = self.elapsed
        if self.nsi is not None:
            r["truth"] = self.truth.to_dict()
            r["nsi_model"] = self.nsi.model_.to_dict()
            r["errors_percent"] = {
                k: 100 * (getattr(self.est.model_, k) / getattr(self.truth, k) - 1)
                for k in ("k0", "k1", "k2", "k3", "c", "c_nl")
            }
        if self.hidden is not None:
            r["hidden"] = dict(self.hidden)
        if self.floor is not None:
            r["truth_features"] = self.truth.features()
            r["truth_floor_rms_percent"] = self.floor
        if self.by_law is not None:
            r["by_law"] = self.by_law.result()
        return r


def compute_polynomial(duration: float, seed_: int) -> SindyRun:
    """SINDy and NSI on one cross-well record of the polynomial truth (default sensor noise)."""
    truth = SEED_LIKE_CUBIC
    rec = Rig(truth, seed=seed_).random(duration=duration, rms=SEED_LIKE_CROSS_WELL_RMS)
    m = Measurement.from_rig(rec)
    t0 = time.perf_counter()
    est = SINDy(seed=seed_).fit(m)
    elapsed = time.perf_counter() - t0
    return SindyRun(truth, m, est, elapsed, duration, nsi=NSI().fit(m))


def polynomial_part(rep: Report, res: dict[str, Any], duration: float, seed_: int) -> None:
    """Compute (``compute_polynomial``), then render: the selected terms, the coefficient table, the
    selection path, the forces and the held-out validation.
    """
    run = compute_polynomial(duration, seed_)
    res["polynomial_truth"] = run.result()
    truth, est, nsi, m, elapsed = run.truth, run.est, run.nsi, run.measurement, run.elapsed
    rep.heading("The discovered equation (polynomial truth, default sensor noise)", 3)
    exact = est.selected_ == ["1", "z", "z^2", "z^3", "v", "v|v|"]
    rep.text(
        f"The same {duration:g} s cross-well record as the NSI section (random seed {seed_}). SINDy saw z and the base "
        f"acceleration only, and took {elapsed:.1f} s ({est.settings_['form']}; derivatives for the "
        f"library: {est.settings_['derivatives']}). Selected terms: **{', '.join(est.selected_)}**"
        + (" - exactly the truth's." if exact else " - NOT the truth's terms (1, z, z^2, z^3, v, v|v|).")
        + " The input's coefficient is fixed at -1 (base excitation) by the constrained optimiser; mass "
        f"{fmt(est.model_.m, 4)} kg (weighed)."
    )
    if not exact:
        rep.warning("SINDy did not select exactly the truth's terms on this record.")
    rep.table(COEF_HEADER, _coefficient_rows(est, truth, nsi))
    rep.text(
        "Inclusion probabilities are the share of 50 bagged SR3 fits (pysindy EnsembleOptimizer, 60 % of the test "
        "functions each, at the selected sparsity weight) that keep a term; the ensemble sd is their coefficient "
        "spread. The truth's k2 sits ~2 % above every estimate on rig records, noise or not: the acquisition chain's "
        "anti-aliasing filter removes the response's harmonics above ~200 Hz, whose products feed the even part of "
        "the restoring force (measured on a clean simulation decimated with and without the filter)."
    )
    rep.heading("Selection path", 4)
    rep.table(
        ["terms", "held-out weak residual [%]", "restarted free runs [%]", "selected"],
        [
            [", ".join(p["terms"]), p["heldout_residual_percent"], p["free_run_percent"], p.get("selected", "")]
            for p in est.path_
        ],
    )
    rep.text(
        "Each support of the L0 path is refitted on the first 60 % of the record and scored on the next 20 %; the "
        "sparsest within one standard error (or 10 %) of the best held-out residual wins. The restarted 2 s free "
        "runs are shown, not used: over cross-well motion they amplify small coefficient errors (chaos)."
    )
    assert nsi is not None  # the polynomial truth's run has NSI beside it
    _force_figure(rep, truth, est, nsi, m)
    _validation_figure(rep, est, nsi)


def _force_figure(rep: Report, truth: Model, est: SINDy, nsi: NSI, m) -> None:
    eq = truth.equilibria()
    z = np.linspace(eq.z_minus - 0.012, eq.z_plus + 0.012, 300)
    v = np.linspace(-1.5, 1.5, 300)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].plot(1e3 * z, truth.restoring_force(z), "k-", lw=2, label="truth")
    ax[0].plot(1e3 * z, est.model_.restoring_force(z), "r--", label="SINDy")
    ax[0].plot(1e3 * z, nsi.model_.restoring_force(z), "C0:", label="NSI")
    ax[0].set(xlabel="z [mm]", ylabel="K(z) [N]", title="restoring force")
    ax[1].plot(v, truth.damping_force(v), "k-", lw=2, label="truth")
    ax[1].plot(v, est.model_.damping_force(v) + _extra_damping(est.model_, v), "r--", label="SINDy")
    ax[1].plot(v, nsi.model_.damping_force(v), "C0:", label="NSI")
    ax[1].set(xlabel="z' [m/s]", ylabel="D(z') [N]", title="damping force")
    for a in ax:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    rep.figure("sindy_forces", fig, "Restoring and damping forces: truth, SINDy and NSI from the same record.")


def _extra_damping(model: Model, v: np.ndarray) -> np.ndarray:
    from negstiff.models import effects

    return effects.force(model.extra, np.zeros_like(v), v) - effects.stiffness_force(model.extra, np.zeros_like(v))


def _validation_figure(rep: Report, est: SINDy, nsi: NSI) -> None:
    v, vn = est.validation_, nsi.validation_
    if "z_sim" not in v:
        rep.warning("The SINDy model's held-out free run diverged; no validation figure.")
        return
    t = v["t"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
    sl = slice(0, min(t.size, int(4 * 512)))
    ax[0].plot(t[sl], 1e3 * v["z_meas"][sl], "k-", lw=1.5, label="measured")
    ax[0].plot(t[sl], 1e3 * v["z_sim"][sl], "r--", lw=1, label="SINDy free run")
    ax[0].set(xlabel="t [s]", ylabel="z [mm]", title="held-out segment (first 4 s)")
    fs = 1 / (t[1] - t[0])
    for y, style, lab in ((v["z_meas"], "k-", "measured"), (v["z_meas"] - v["z_sim"], "r-", "SINDy residual")):
        f, p = signal.welch(y - y.mean(), fs, nperseg=2048)
        ax[1].semilogy(f, p, style, lw=1, label=lab)
    if "z_sim" in vn:
        f, p = signal.welch(vn["z_meas"] - vn["z_sim"], fs, nperseg=2048)
        ax[1].semilogy(f, p, "C0:", lw=1, label="NSI residual")
    ax[1].set(xlabel="f [Hz]", ylabel="PSD [m^2/Hz]", xlim=(0, 80), title="residual PSD")
    for a in ax:
        a.legend(fontsize=8)
    rep.figure(
        "sindy_validation",
        fig,
        f"Free-run validation over the held-out last 20 %: SINDy {fmt(v['rms_percent'], 3)} % rms "
        f"(NSI {fmt(vn['rms_percent'], 3)} %); restarted 2 s runs {fmt(v.get('restarted_rms_percent'), 3)} %.",
    )


def compute_friction(duration: float, seed_: int) -> SindyRun:
    """SINDy on a record whose rig hides Coulomb friction (SINDy is not told)."""
    truth = SEED_LIKE_CUBIC
    hidden = {"coulomb_friction": HIDDEN_FRICTION_N}
    rec = Rig(truth, effects=hidden, seed=seed_).random(duration=duration, rms=SEED_LIKE_CROSS_WELL_RMS)
    m = Measurement.from_rig(rec)
    t0 = time.perf_counter()
    est = SINDy(seed=seed_).fit(m)
    return SindyRun(truth, m, est, time.perf_counter() - t0, duration, hidden=hidden)


def friction_part(rep: Report, res: dict[str, Any], duration: float, seed_: int) -> None:
    """Compute (``compute_friction``), then render: what was selected, the inclusion probabilities."""
    run = compute_friction(duration, seed_)
    res["hidden_friction"] = run.result()
    truth, est = run.truth, run.est
    ens: dict[str, dict[str, Any]] = est.ensemble_
    spurious = {t: e["inclusion_probability"] for t, e in ens.items() if t in ("z^4", "z^5", "v^3")}
    found = est.model_.extra.get("coulomb_friction", 0.0)
    rep.heading(f"A hidden effect: {HIDDEN_FRICTION_N:g} N of Coulomb friction", 3)
    ok = ens["sgn(v)"]["inclusion_probability"] > 0.9 and max(spurious.values()) < 0.5
    rep.text(
        f"The rig hid {HIDDEN_FRICTION_N:g} N of Coulomb friction (5 % of the device's weight) in a {duration:g} s "
        f"record; SINDy was not told. Selected: **{', '.join(est.selected_)}**; sgn(v) in "
        f"{fmt(100 * ens['sgn(v)']['inclusion_probability'], 3)} % of the bagged models, the friction force "
        f"{fmt(found, 3)} N ({pct(found, HIDDEN_FRICTION_N)} against the hidden {HIDDEN_FRICTION_N:g} N); terms the "
        f"truth lacks: {', '.join(f'{t} {fmt(p, 2)}' for t, p in spurious.items())}. "
        "The library's sgn(v) is erf(v / (sqrt(2) s_n)), the expected sign of the true velocity given the estimated "
        "one (s_n its predicted noise): with a plain sign, or with a finite-difference z'' that smears the force's "
        "jump, 30-40 % of the friction went unexplained (measured while building this)."
    )
    if not ok:
        rep.warning("The ensemble did not single out the hidden friction cleanly on this record.")
    rep.table(
        COEF_HEADER,
        _coefficient_rows(est, dataclasses.replace(truth, extra={"coulomb_friction": HIDDEN_FRICTION_N}), None),
    )


def compute_as_built(duration: float, seed_: int) -> SindyRun:
    """SINDy on a record of the as-built device (no polynomial truth), and the exact model's own floor.
    The wall time is not reported for this part (``elapsed`` 0).
    """
    rec = Rig(AS_BUILT, seed=seed_).random(duration=duration)
    m = Measurement.from_rig(rec)
    est = SINDy(seed=seed_).fit(m)
    floor = true_floor(AS_BUILT, m, est.settings_["identification_samples"])
    return SindyRun(AS_BUILT, m, est, 0.0, duration, floor=floor, by_law=SINDy(seed=seed_, law="auto").fit(m))


def as_built_part(rep: Report, res: dict[str, Any], duration: float, seed_: int) -> None:
    """Compute (``compute_as_built``), then render: the wells' frequencies, the force against the best cubic."""
    run = compute_as_built(duration, seed_)
    res["as_built"] = run.result()
    est, floor = run.est, run.floor
    rep.heading("The as-built device (exact geometric restoring force)", 3)
    rows = []
    for w in ("minus", "plus"):
        uls = AS_BUILT.uls(w)
        rows.append([f"z_{w}", est.modal_[w]["f_hz"], uls.f_hz, pct(est.modal_[w]["f_hz"], uls.f_hz)])
    higher = [t for t in est.selected_ if t in ("z^4", "z^5")]
    rep.text(
        f"No polynomial truth exists here. SINDy selects **{', '.join(est.selected_)}**"
        + (
            f": the higher-order stiffness terms {', '.join(higher)} are how it reports the cubic's model-form gap."
            if higher
            else "."
        )
        + f" Held-out free run: {fmt(est.validation_['rms_percent'], 3)} % (restarted 2 s runs "
        f"{fmt(est.validation_.get('restarted_rms_percent'), 3)} %), against the exact model's own floor of "
        f"{fmt(floor, 3)} % on the same record (one long cross-well free run diverges even for the truth)."
    )
    rep.table(["well", "f SINDy [Hz]", "f exact K'(z*) [Hz]", "error"], rows)
    eq = AS_BUILT.equilibria()
    z = np.linspace(eq.z_minus - 0.012, eq.z_plus + 0.012, 300)
    fig, ax = plt.subplots(figsize=(6, 3.6))
    ax.plot(1e3 * z, AS_BUILT.restoring_force(z), "k-", lw=2, label="exact geometry (truth)")
    ax.plot(1e3 * z, est.model_.restoring_force(z), "r--", label="SINDy")
    ax.plot(1e3 * z, AS_BUILT.lsq_cubic().restoring_force(z), "C2:", label="least-squares cubic of the truth")
    if run.by_law is not None:
        ax.plot(1e3 * z, run.by_law.model_.restoring_force(z), "C1-.",
                label=f"SINDy, {run.by_law.settings_['law']} law (chosen)")  # fmt: skip
    ax.set(xlabel="z [mm]", ylabel="K [N]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    rep.figure("sindy_as_built", fig, "As-built device: exact restoring force, SINDy's polynomial, the best cubic, "
               "and SINDy with the law the record asks for.")  # fmt: skip
    if run.by_law is not None:
        law_rows(rep, run.by_law, "SINDy")


def sindy_section(rep: Report, results: dict[str, Any], fast: bool, seed_: int = 0) -> None:
    """The SINDy section; numbers go into ``results["sindy"]``."""
    res: dict[str, Any] = {}
    results["sindy"] = res
    duration = 60.0 if fast else 300.0
    rep.heading("SINDy: equation discovery from the records")
    polynomial_part(rep, res, duration, seed_ + 1)
    if not fast:
        friction_part(rep, res, duration, seed_ + 4)
        as_built_part(rep, res, duration, seed_ + 2)


def main(argv=None) -> int:
    return run_study(
        sindy_section,
        "negstiff: equation discovery with SINDy",
        "reports/sindy",
        __doc__,
        argv,
    )


if __name__ == "__main__":
    sys.exit(main())
