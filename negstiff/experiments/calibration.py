"""Calibration of the rig's device against the reference study's headline figures, and the device section of
the report (reference study Figure 2): exact K(z), U(z) against the Taylor and least-squares cubics.
"""

from __future__ import annotations

from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from negstiff.models.device import AS_BUILT, NOMINAL, Device
from negstiff.report.document import Report

from . import seed


def calibration(device: Device = AS_BUILT) -> dict[str, Any]:
    """How close the device's features come to the reference study's targets (percent errors)."""
    f = device.features()
    uls = {w: device.uls(w) for w in ("minus", "plus")}
    targets = {"f_minus": seed.TABLE1["minus"]["f_hz"], "f_plus": seed.TABLE1["plus"]["f_hz"], "z_plus": seed.Z_PLUS}
    err = {k: 100 * (f[k] - v) / v for k, v in targets.items()}
    return {
        "features": f,
        "targets": targets,
        "error_percent": err,
        "zeta": {w: uls[w].zeta for w in uls},
        "seed_zeta": {w: seed.TABLE1[w]["zeta"] for w in uls},
        "stroke_m": list(device.stroke_limits()),
        "E_over_m": device.E / device.m,
    }


def device_section(rep: Report, results: dict[str, Any]) -> None:
    """Seed Figure 2 and the calibration table."""
    cal = calibration(AS_BUILT)
    nom = NOMINAL.features()
    tay, lsq = AS_BUILT.taylor_cubic(), AS_BUILT.lsq_cubic()
    results["device"] = {
        "nominal": NOMINAL.to_dict(),
        "as_built": AS_BUILT.to_dict(),
        "calibration": cal,
        "nominal_features": nom,
        "taylor_cubic": tay.to_dict(),
        "lsq_cubic": lsq.to_dict(),
        "taylor_cubic_equilibria": tay.equilibria().as_dict(),
        "lsq_cubic_equilibria": lsq.equilibria().as_dict(),
    }
    rep.heading("1. The device and its potential (reference study Figure 2)")
    rep.text(
        "The rig's device is the physically-based model of device-model.md: two rods hinged on the moving "
        "mass and on the tips of two pre-compressed leaf-spring arms. Its exact restoring force K(z) is "
        "geometric; the reference study's cubic (Eq. 2) is its Taylor expansion at z = 0. The fixed geometry "
        f"(L = {AS_BUILT.L * 1e3:g} mm, l = {AS_BUILT.l * 1e3:g} mm, b = {AS_BUILT.b * 1e3:g} mm, "
        f"h = {AS_BUILT.h * 1e3:g} mm, D0 = {AS_BUILT.D0 * 1e3:g} mm) was calibrated once so that the as-built "
        "device reproduces the paper's Table 1 frequencies and z_plus; the nominal design is what the drawings say."
    )
    rows = []
    for k, label, unit, scale in (
        ("f_minus", "f at z_minus", "Hz", 1),
        ("f_plus", "f at z_plus", "Hz", 1),
        ("z_minus", "z_minus", "mm", 1e3),
        ("z_plus", "z_plus", "mm", 1e3),
    ):
        tgt = cal["targets"].get(k)
        rows.append(
            [
                f"{label} [{unit}]",
                nom[k] * scale,
                cal["features"][k] * scale,
                "-" if tgt is None else tgt * scale,
                "-" if tgt is None else f"{cal['error_percent'][k]:+.2f} %",
            ]
        )
    rows.append(["zeta at z_minus [%]", "-", 100 * cal["zeta"]["minus"], 100 * cal["seed_zeta"]["minus"], "see text"])
    rows.append(["zeta at z_plus [%]", "-", 100 * cal["zeta"]["plus"], 100 * cal["seed_zeta"]["plus"], "see text"])
    rep.table(["feature", "nominal design", "as-built (rig truth)", "seed", "as-built vs seed"], rows)
    rep.text(
        "The damping ratios are lower than the paper's on purpose. At 9 Hz the as-built device shows the paper's "
        "period-doubling cascade near 12-15 m/s^2 only with well damping of about 5-6 %; at the paper's 11 % / 20 % "
        "the cascade moves to about 21 m/s^2 (viscous plus positive quadratic damping cannot give both). The "
        "rig keeps the dynamics and reports the gap; a polynomial truth with the paper's damping is available "
        "for identification studies (`negstiff rig --model`)."
    )
    z = np.linspace(-0.045, 0.040, 400)
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
    for sys_, lab, st in (
        (AS_BUILT, "exact geometry (as-built)", "k-"),
        (tay, "Taylor cubic at z = 0", "C1--"),
        (lsq, "least-squares cubic, +-30 mm", "C2:"),
    ):
        ax[0].plot(z * 1e3, sys_.restoring_force(z), st, label=lab)
        ax[1].plot(z * 1e3, sys_.potential(z) * 1e3, st, label=lab)
    eq = AS_BUILT.equilibria()
    zs = np.array([eq.z_minus, eq.z_0, eq.z_plus])
    ax[0].plot(zs * 1e3, AS_BUILT.restoring_force(zs), "o", color="C1")
    ax[1].plot(zs * 1e3, AS_BUILT.potential(zs) * 1e3, "o", color="C1", label="equilibria")
    ax[0].set(xlabel="z [mm]", ylabel="K(z) [N]", title="restoring force")
    ax[1].set(xlabel="z [mm]", ylabel="U(z) [mJ]", title="potential")
    ax[0].axhline(0, color="0.7", lw=0.8)
    ax[1].legend(fontsize=8)
    rep.figure(
        "fig2_potential",
        fig,
        "Figure 2 (seed): restoring force and potential of the as-built device, exact "
        "geometry against its Taylor cubic and a least-squares cubic; orange dots: equilibria.",
    )
    rep.table(
        ["cubic", "k1 [N/m]", "k2 [N/m^2]", "k3 [N/m^3]", "z_minus [mm]", "z_plus [mm]"],
        [
            [name, m.k1, m.k2, m.k3, 1e3 * (m.equilibria().z_minus or np.nan), 1e3 * m.equilibria().z_plus]
            for name, m in (("Taylor at z = 0", tay), ("least squares over +-30 mm", lsq))
        ],
    )
    rep.text(
        "Model-form gap: no cubic matches the exact K(z) over the whole stroke. The Taylor cubic is exact near "
        "z = 0 and misplaces the wells; the least-squares cubic trades accuracy near z = 0 for the wells. "
        "Identification on as-built records therefore cannot recover 'true' k1-k3: they do not exist. "
        "Coefficient accuracy is judged on records of a polynomial truth instead."
    )
