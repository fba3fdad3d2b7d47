"""
Real data: the Silverbox benchmark
==================================

An electronic Duffing oscillator (Wigren & Schoukens 2013), shipped with negstiff. Train on the
multisine part, predict the held-out multisine test free-run, and compare with the published
models (rms error in mV).
"""

import matplotlib.pyplot as plt

from negstiff import SINDy
from negstiff.datasets import silverbox
from negstiff.experiments.silverbox import PUBLISHED_MV, TEST, TRAIN, prediction_error_mv

rec = silverbox()
sindy = SINDy().fit(rec.segment(*TRAIN))
mv = prediction_error_mv(sindy.model_, rec, TEST)
print(f"SINDy, refined by output error: {mv:.3f} mV on the multisine test")
for name, value in PUBLISHED_MV.items():
    print(f"  published {name}: {value} mV")

# %%
rows = sorted({"negstiff SINDy": mv, **PUBLISHED_MV}.items(), key=lambda kv: kv[1])
fig, ax = plt.subplots(figsize=(6, 2.8))
ax.barh([k for k, _ in rows], [v for _, v in rows], color=["C3" if "negstiff" in k else "C0" for k, _ in rows])
ax.set(xscale="log", xlabel="multisine test rms error [mV]")
fig.tight_layout()
