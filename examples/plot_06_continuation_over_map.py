"""
Continuation over a measured bifurcation map
============================================

A stepped harmonic test at 9 Hz (the reference study's Figure 4 axis): the table's amplitude rises
step by step, each step's Poincare points drawn against it. The model's periodic orbits, continued
in amplitude with their Floquet stability, predict where the first period doubling appears.
"""

import matplotlib.pyplot as plt
import numpy as np

from negstiff import Measurement, Rig, characterise, nfrc
from negstiff.models import SEED_LIKE_CUBIC

amplitudes = np.arange(4.0, 16.0, 1.0)
steps = Rig(SEED_LIKE_CUBIC, seed=6).sweep(9.0, amplitudes, start="plus", record_periods=40)
fig, ax = plt.subplots(figsize=(7, 3.5))
for a, step in zip(amplitudes, steps, strict=False):
    c = characterise(Measurement.from_rig(step), forcing_hz=9.0, lle=False, poincare=True)
    ax.plot(np.full(len(c["poincare_z"]), a), 1e3 * np.asarray(c["poincare_z"]), "k.", ms=2)
    print(f"{a:5.1f} m/s^2: period {c['period']}, {c['regime']}")

# %%
# The truth's periodic orbits from the plus well, continued in amplitude
curve = nfrc(SEED_LIKE_CUBIC, freq=9.0, amplitude=(4.0, 16.0), well="plus", max_period=2)
first = [b for b in curve["bifurcations"] if b["type"] == "period_doubling"]
for b in first[:1]:
    print(f"continuation: first period doubling at {b['amplitude']:.2f} m/s^2")
    ax.axvline(b["amplitude"], color="C3", ls="--", label=f"first period doubling {b['amplitude']:.2f} m/s^2")
ax.set(xlabel="table acceleration amplitude [m/s^2]", ylabel="Poincare z [mm]")
ax.legend(loc="lower left", fontsize=8)
fig.tight_layout()
