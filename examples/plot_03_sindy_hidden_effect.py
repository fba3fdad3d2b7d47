"""
SINDy finds a hidden effect
===========================

A record of a cubic double well with 0.1 N of Coulomb friction the model does not have. SINDy's
library holds the friction term sgn(z'); the held-out selection decides whether the data ask for it,
and the ensemble gives each term's inclusion probability.
"""

import matplotlib.pyplot as plt

from negstiff import Measurement, Rig, SINDy
from negstiff.models import SEED_LIKE_CUBIC

rig = Rig(SEED_LIKE_CUBIC, effects={"coulomb_friction": 0.1}, seed=3)
rec = Measurement.from_rig(rig.random(duration=120.0, rms=20.0))
sindy = SINDy(seed=1).fit(rec)
print("selected terms:", sindy.selected_)
print("Coulomb friction found:", sindy.model_.extra.get("coulomb_friction"), "N (hidden: 0.1 N)")

# %%
# Inclusion probabilities over the ensemble
ens = sindy.result()["ensemble"]
fig, ax = plt.subplots(figsize=(6, 2.8))
ax.bar(list(ens), [e["inclusion_probability"] for e in ens.values()])
ax.set(ylabel="inclusion probability", ylim=(0, 1.05))
ax.tick_params(axis="x", rotation=45)
fig.tight_layout()
