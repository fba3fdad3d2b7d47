"""
Which law: a magnet harvester and a real magneto-mechanical decay
=================================================================

The reference study's cubic is one restoring-force law among others (:doc:`/methods/laws`). Here NSI compares
them on two records and keeps the one that predicts best:

* a synthetic horizontal harvester whose tip magnet faces a fixed magnet (the point-dipole law
  ``K = k0 - k1 z - 3 A z / (d^2 + z^2)^(5/2)``, wells near +-14 mm at 9 Hz), shaken at random across its wells;
* the real free decay of FrID's magneto-mechanical oscillator (Breunung & Balachandran 2024; ``tests/data``),
  its strain gauge read as z.

Each candidate law is estimated on the first part of the record and scored on the next part by runs restarted
from the measured state, in windows as long as the record stays predictable; the table gives each law's median
window error and its pseudo-BMA weight, the figure each law's force over the stroke the record visited. Last, the
damping law: the real decay's damping ratio rises and falls with amplitude, which only a damping law with a
negative z'^3 term follows.
"""

import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from negstiff import NSI, Measurement, Rig, load
from negstiff.models import Model

warnings.simplefilter("ignore")  # each law's own warnings are in its result


def compare(rec, title):
    """NSI with every law compared; the comparison's table and each law's force over the stroke."""
    nsi = NSI(law="auto", refine=False).fit(rec)
    choice = nsi.result_.details["law_choice"]
    print(f"{title}: {choice['chosen']} chosen")
    print(f"{'law':16s} {'held-out median window':>24s} {'weight':>8s}  why not")
    for c in choice["candidates"]:
        err = c["heldout_median_window_percent"]
        print(f"{c['law']:16s} {'-' if err is None else f'{err:.3g} %':>24s} {c['weight']:8.2f}  "
              + "; ".join(c["problems"][:1])[:70])  # fmt: skip
    lo, hi = nsi.result_.stroke_quantiles_m[0], nsi.result_.stroke_quantiles_m[-1]
    z = np.linspace(lo, hi, 300)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for c in choice["candidates"]:
        if c["model"] is None or c["problems"]:
            continue
        m = Model.from_dict(c["model"])
        ax.plot(1e3 * z, m.restoring_force(z) / m.m, lw=2.5 if c["law"] == choice["chosen"] else 1.0,
                label=f"{c['law']} (weight {c['weight']:.2f})")  # fmt: skip
    ax.axhline(0, color="0.6", lw=0.5)
    ax.set(xlabel="z (the record's stroke)", ylabel="K(z) / m", title=title)
    ax.legend(fontsize=8, frameon=False)
    fig.tight_layout()
    return nsi


# %%
# A magnet harvester (synthetic, the truth known)
m, d = 0.05, 0.020
magnet = Model(m=m, k1=-1945.0 * m, k2=0.0, k3=0.0, k0=1.0 * m, c=2 * 0.03 * 2 * np.pi * 9.0 * m,
               extra={"magnet": {"A": 5.62e-6 * m, "d": d}})  # fmt: skip
rec = Measurement.from_rig(Rig(magnet, seed=2).random(duration=60.0, rms=10.0, band=(2.0, 30.0)))
harvester = compare(rec, "magnet harvester")
print("truth's wells [Hz]:", {w: round(magnet.uls(w).f_hz, 3) for w in ("minus", "plus")},
      "NSI's:", {w: round(v["f_hz"], 3) for w, v in harvester.modal_.items() if v["f_hz"]})  # fmt: skip

# %%
# The real magneto-mechanical decay (FrID)
root = Path(__file__).resolve().parent if "__file__" in globals() else Path.cwd()
frid = next(p for p in (root.parent / "tests" / "data", Path("tests") / "data") if p.exists())
decay = load(frid / "frid_magneto_mechanical_decay" / "decay_f_42p05_ampl_2p0_0_12p1-19p1s.lvm",
             columns="force=Sine with Gaussian Noise,z=Strain_0", gravity=0.0)  # fmt: skip
real = compare(decay, "FrID magneto-mechanical decay (strain units)")

# %%
# Which damping: a ratio that rises, then falls
# ---------------------------------------------
# The decay's damping ratio, read from its Hilbert backbone, rises from 0.3 % to 0.7 % with amplitude and falls
# back. The reference study's damping, ``c z' + c_nl z'|z'|``, can only rise; ``polynomial_damping`` adds ``c3 z'^3``,
# which the data give a negative sign. Each model's own free decay, read by the same estimator, against the
# record's:
from negstiff.inference.analysis.backbone import measure_backbone, predict_backbone  # noqa: E402

measured = measure_backbone(decay)
fig, ax = plt.subplots(figsize=(7, 3.6))
a = 1e3 * np.asarray(measured["hilbert"]["amplitude_m"])
ax.plot(100 * np.asarray(measured["hilbert"]["zeta"]), a, "k", lw=2, label="the record (Hilbert)")
for damping in ("quadratic", "polynomial_damping"):
    model = NSI(law="spline", damping=damping).fit(decay).model_
    predicted = predict_backbone(model, decay, measured)["hilbert"]
    print(f"{damping:20s} c {model.c:.3g}, c_nl {model.c_nl:.3g}, c3 {model.extra.get('cubic_damping', 0.0):.4g}")
    ax.plot(100 * np.asarray(predicted["zeta"]), 1e3 * np.asarray(predicted["amplitude_m"]), "--",
            label=f"NSI: spline, {damping.replace('_', ' ')}")  # fmt: skip
ax.set(xlabel="damping ratio [%]", ylabel="amplitude (the gauge's units x 1e3)", ylim=(0, a.max() * 1.05))
ax.legend(fontsize=8, frameon=False)
fig.tight_layout()
