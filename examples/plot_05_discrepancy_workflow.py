"""
The discrepancy workflow
========================

Where does a cubic model miss the data, what is missing, and how much of the gap does adding it
close? The record hides an end stop (a stiff contact beyond -38 mm) from the cubic model.
"""

from negstiff import Discrepancy, Measurement, Rig
from negstiff.models import SEED_LIKE_CUBIC

rig = Rig(SEED_LIKE_CUBIC, effects={"end_stop": {"k": 3000.0, "z": -0.038}}, seed=5)
rec = Measurement.from_rig(rig.random(duration=120.0, rms=20.0))
disc = Discrepancy().fit(rec)

# %%
# Where the baseline's equation error sits, what was named (with its refined size), and the held-out gap
# before and after: the truth is k = 3000 N/m beyond z = -38 mm, and the cubic rig's own c_nl = 0.5
r = disc.result()
print("where:", r["where"])
print("named:", r["effects"], "sizes:", r["effect_size"])
print(f"held-out gap: {r['gap_before_percent']:.3g} % -> {r['gap_after_percent']:.3g} %")
