"""
A posterior beside the deterministic estimates
==============================================

emcee samples the coefficients' posterior from 20 s of a record; arviz diagnoses it. The credible
intervals sit beside NSI's and SINDy's point estimates and the truth.
"""

import matplotlib.pyplot as plt

from negstiff import NSI, Measurement, Posterior, Rig, SINDy
from negstiff.models import SEED_LIKE_CUBIC

rig = Rig(SEED_LIKE_CUBIC, seed=4)
rec = Measurement.from_rig(rig.random(duration=60.0, rms=20.0))
nsi, sindy = NSI().fit(rec), SINDy(seed=1).fit(rec)
post = Posterior(seed=1).fit(rec.segment(0, int(20 * rec.fs)))
params = post.result()["parameters"]
print("converged:", post.result()["converged"], post.result()["warnings"] or "")

# %%
# Each coefficient: the posterior's 90 % interval, the two methods, the truth
fig, axes = plt.subplots(1, 3, figsize=(9, 2.6))
for ax, k in zip(axes, ("k1", "k3", "c"), strict=False):
    p = params[k]
    ax.errorbar(
        [0],
        [p["mean"]],
        yerr=[[p["mean"] - p["hdi_low"]], [p["hdi_high"] - p["mean"]]],
        fmt="o",
        label="posterior 90 %",
    )
    ax.plot([1], [getattr(nsi.model_, k)], "s", label="NSI")
    ax.plot([2], [getattr(sindy.model_, k)], "^", label="SINDy")
    ax.axhline(getattr(SEED_LIKE_CUBIC, k), color="k", lw=0.8, label="truth")
    ax.set(title=k, xticks=[])
axes[0].legend(fontsize=7)
fig.tight_layout()

# %%
# arviz reads the same draws: each independent ensemble is one chain
import arviz as az  # noqa: E402

print(az.summary(post.result_.idata))
