"""The report's fixture section: what a single-DOF identification of the moving mass gets wrong when the shaker
fixture is not rigid, and the 2-DOF identification that mends it (issue "Beyond one degree of freedom").

The virtual rig (``models.rig``) carries the seed-like cubic device on a 1 kg fixture sprung
to the table at 25 Hz, 2 % (the reference study's device on a fixture that is not rigid); one 300 s random
cross-well record, measured as the reference study measures (a laser per DOF, the table's accelerometer double
integrated). The single-DOF route is what a user without the fixture's laser does: z = z2 (the moving mass
relative to the table) and NSI / SINDy as for any record. The 2-DOF route reads both lasers and names the
element (``--dofs 2 --element 1-2``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from negstiff.inference.estimators.nsi import NSI
from negstiff.inference.estimators.sindy import SINDy
from negstiff.inference.record.measurement import from_arrays
from negstiff.inference.steps.validation import restarted_structure_runs as free_run_error
from negstiff.models.device import SEED_LIKE_CUBIC
from negstiff.models.rig import Rig
from negstiff.models.structure import Structure
from negstiff.report.numbers import fmt

COEFS = ("k1", "k2", "k3", "c", "c_nl")
WINDOW_S = 0.25
"""Held-out free runs are restarted every 0.25 s (two periods of the wells): over cross-well chaos a longer run
diverges for any model, the truth too, and then a model that moves less scores better (measured: 1 s windows put
both single-DOF models below the truth's own error)."""
FIXTURE = {"fixture_mass": 1.0, "fixture_hz": 25.0, "fixture_zeta": 0.02}


@dataclass
class FixtureStudy:
    """Everything the section shows: the truth, the record, the four identifications and their times."""

    rig: Rig
    structure: Structure
    record: Any
    single: dict[str, Any]
    double: dict[str, Any]
    floor: dict[str, Any]
    seconds: dict[str, float]


def compute_fixture(fast: bool, seed: int) -> FixtureStudy:
    """The record and the four identifications (single-DOF NSI and SINDy on z2; the structure's NSI and SINDy)."""
    rig = Rig.device_on_fixture(SEED_LIKE_CUBIC, seed=seed + 31, **FIXTURE)
    structure = rig.system
    assert isinstance(structure, Structure)  # the rig carries the structure ``device_on_fixture`` built
    rec = rig.random(duration=120.0 if fast else 300.0, rms=14.0)
    u = rec.columns["base_acc"]
    srec = from_arrays(u, rec.z, rec.fs, masses=structure.masses, source="fixture record")
    one = from_arrays(u, rec.z[1], rec.fs, mass=structure.masses[1], source="fixture record, z2 alone")
    seconds: dict[str, float] = {}
    single, double = {}, {}
    for name, est in (("NSI", NSI()), ("SINDy", SINDy(seed=seed))):
        t0 = time.perf_counter()
        single[name] = est.fit(one)
        seconds[f"single {name}"] = time.perf_counter() - t0
    for name, sest in (("NSI", NSI(element="1-2")), ("SINDy", SINDy(element="1-2", seed=seed))):
        t0 = time.perf_counter()
        double[name] = sest.fit(srec)
        seconds[f"2-DOF {name}"] = time.perf_counter() - t0
    floor = free_run_error(structure, srec, int(0.8 * srec.n))
    return FixtureStudy(rig, structure, rec, single, double, floor, seconds)


def fixture_section(rep, results: dict[str, Any], fast: bool, seed: int = 0) -> None:
    """Compute (``compute_fixture``), then render: the coefficient table, the wells' modes, the held-out runs."""
    study = compute_fixture(fast, seed)
    truth, s = SEED_LIKE_CUBIC, study.structure
    rep.heading("A fixture that is not rigid: single-DOF against 2-DOF identification")
    duration = study.record.truth["excitation"]["duration_s"]
    rep.text(
        f"The device (the seed-like cubic, {fmt(truth.m, 3)} kg) stands on a {fmt(FIXTURE['fixture_mass'], 2)} kg "
        f"shaker fixture sprung to the table at {fmt(FIXTURE['fixture_hz'], 3)} Hz, "
        f"{fmt(100 * FIXTURE['fixture_zeta'], 2)} % (the virtual rig: a laser on each mass, the table's "
        f"accelerometer double-integrated as in the reference study; {fmt(duration, 3)} s "
        "of random cross-well motion at 14 m/s^2 rms). A single-DOF identification of the moving mass alone takes "
        "z = z2 - b and the table's acceleration as the device's input, though the device's base is the fixture, "
        "which moves. The 2-DOF identification reads both lasers and the element's place "
        "(`identify --dofs 2 --element 1-2`)."
    )
    rows: list[list[Any]] = []
    res: dict[str, Any] = {"truth": {k: getattr(truth, k) for k in COEFS}, "seconds": study.seconds}
    for k in COEFS:
        row: list[Any] = [k, getattr(truth, k)]
        for route, fits in (("single", study.single), ("2-DOF", study.double)):
            for name, est in fits.items():
                value = getattr(est.model_, k) if route == "single" else est.element_[k]
                if value == 0.0:
                    row.append("not selected")
                else:
                    row.append(f"{fmt(value, 4)} ({100 * (value / getattr(truth, k) - 1):+.1f} %)")
                res.setdefault(f"{route} {name}", {})[k] = value
        rows.append(row)
    rep.table(["coefficient", "truth", "single-DOF NSI", "single-DOF SINDy", "2-DOF NSI", "2-DOF SINDy"], rows)
    rep.text(
        "Each well's underlying-linear modes: the single-DOF routes have one frequency per well (their damping is not "
        "a mode's), the 2-DOF routes both modes with their damping ratios."
    )
    mrows: list[list[Any]] = []
    for well in ("minus", "plus"):
        true_modes = s.modes(well)
        single_f = {n: e.modal_[well]["f_hz"] for n, e in study.single.items()}
        for i, m in enumerate(true_modes):
            what = "device" if i == 0 else "fixture"
            mrows.append([
                f"z_{well}, {what} mode", f"{fmt(m.f_hz, 4)} Hz, {fmt(100 * m.zeta, 3)} %",
                *(f"{fmt(single_f[n], 4)} Hz" if i == 0 and single_f[n] is not None else "-" for n in study.single),
                *(f"{fmt(e.modal_[well][i].f_hz, 4)} Hz, {fmt(100 * e.modal_[well][i].zeta, 3)} %"
                  for e in study.double.values()),
            ])  # fmt: skip
            res.setdefault("modes", {}).setdefault(well, []).append(
                {"truth": m.to_json(), **{f"2-DOF {n}": e.modal_[well][i].to_json() for n, e in study.double.items()}}
            )
        res.setdefault("single_modal", {})[well] = {n: e.modal_[well] for n, e in study.single.items()}
    rep.table(["well, mode", "truth", "single-DOF NSI", "single-DOF SINDy", "2-DOF NSI", "2-DOF SINDy"], mrows)
    # one yardstick for all: z2's error over the held-out last 20 %, free runs of 1 s restarted from the measured
    # state (a single-DOF model as the structure of one DOF on the record of z2 alone)
    start = int(0.8 * study.record.z.shape[1])
    u = study.record.columns["base_acc"]
    alone = from_arrays(u, study.record.z[1:2], study.record.fs, masses=(s.masses[1],), source="z2 alone")
    both = from_arrays(u, study.record.z, study.record.fs, masses=s.masses, source="both")
    held = {f"single-DOF {n}": free_run_error(Structure.single(e.model_), alone, start, WINDOW_S)["rms_percent"]
            for n, e in study.single.items()}  # fmt: skip
    held |= {f"2-DOF {n}": free_run_error(e.structure_, both, start, WINDOW_S)["per_dof_percent"][1]
             for n, e in study.double.items()}  # fmt: skip
    res["held_out_z2_rms_percent"] = held
    res["truth_floor_z2_rms_percent"] = free_run_error(s, both, start, WINDOW_S)["per_dof_percent"][1]
    single_worst = max(abs(res[f"single {n}"][k] / getattr(truth, k) - 1) for n in study.single for k in COEFS)
    double_worst = {n: max(abs(res[f"2-DOF {n}"][k] / getattr(truth, k) - 1) for k in COEFS) for n in study.double}
    rep.text(
        "What the single-DOF route gets wrong: it reads the coupled system's lowest mode as the well's own frequency "
        "and lumps the fixture's motion into the device's force, so the restoring force's asymmetry and the damping "
        f"law come out wrong (its worst coefficient is off by {fmt(100 * single_worst, 3)} %). The 2-DOF route "
        "recovers every element coefficient (worst: "
        + ", ".join(f"{n} {fmt(100 * v, 2)} %" for n, v in double_worst.items())
        + ") and both modes of each well. The moving mass's held-out response (the last 20 %, free runs of "
        f"{fmt(WINDOW_S, 2)} s restarted from the measured state, error in % of its rms): "
        + ", ".join(f"{k} {fmt(v, 3)} %" for k, v in held.items())
        + f"; the true structure itself: {fmt(res['truth_floor_z2_rms_percent'], 3)} % (noise and chaos)."
    )
    nsi_ratio = held["2-DOF NSI"] / res["truth_floor_z2_rms_percent"]
    if nsi_ratio > 2:
        rep.warning(
            f"The 2-DOF NSI predicts the held-out record {fmt(nsi_ratio, 2)}x worse than the truth: on this rig record "
            "(30 um lasers, heavy damping, the base double-integrated) its plus well's frequency and damping law are "
            "off by percents, where the 2-DOF SINDy's weak form is not. On the tests' record (1 um sensors, light "
            "damping) both meet the 1 % / 5 % bounds."
        )
    _figure(rep, res, truth)
    results["fixture"] = res


def _figure(rep, res: dict[str, Any], truth) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    routes = [k for k in res if k.startswith(("single ", "2-DOF "))]
    fig, ax = plt.subplots(figsize=(8, 3.6))
    width = 0.8 / len(routes)
    for i, r in enumerate(routes):
        err = [max(abs(100 * (res[r][k] / getattr(truth, k) - 1)), 1e-3) for k in COEFS]
        ax.bar(np.arange(len(COEFS)) + (i - (len(routes) - 1) / 2) * width, err, width, label=r)
    ax.set_yscale("log")
    ax.set_xticks(np.arange(len(COEFS)), COEFS)
    ax.set_ylabel("|error| [%]")
    ax.axhline(5.0, color="k", lw=0.8, ls="--")
    ax.legend(fontsize=8, ncol=2)
    ax.set_title("Device on a 25 Hz fixture: coefficient errors")
    fig.tight_layout()
    caption = ("Each identification's coefficient errors (log scale; dashed: 5 %): the single-DOF routes read the "
               "moving mass alone, the 2-DOF routes both DOFs.")  # fmt: skip
    rep.figure("fixture_errors", fig, caption)
    plt.close(fig)
