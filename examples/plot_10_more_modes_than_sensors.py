"""
More modes than sensors: a joint in a structure read by three sensors
=====================================================================

A ground vibration test rarely has a sensor on every mass. Here a chain of five masses on the ground (five modes,
7.7 to 41 Hz) is driven by a shaker's measured random force at mass 1, and a joint between masses 4 and 5 hardens
as a cubic spring. Three sensors read it: the drive point and either side of the joint, 1 % noise each. No masses
are given.

NSI then reads the structure through a state-space linear part whose order the record shows (the stabilisation
diagram), and sizes the joint in newtons through the measured drive point (:doc:`/methods/structures`). The
figures: the stabilisation diagram with the chain's own modes, and the identified underlying-linear FRF against
the chain's.
"""

import warnings

import matplotlib.pyplot as plt
import numpy as np
from scipy import linalg, signal

from negstiff import NSI, Model, Structure, from_arrays

warnings.simplefilter("ignore")  # the joint's weakly determined terms are said in the result's warnings

FS = 1000.0
masses, springs = [2.0, 1.5, 1.2, 1.0, 0.8], [4e4, 3e4, 2.5e4, 2e4, 1.5e4]
joint = Model(m=0.8, k0=0.0, k1=0.0, k2=0.0, k3=2e9, c=0.0, c_nl=0.0)  # a cubic spring, no linear part of its own
chain = Structure.chain(masses, springs, [2e-4 * k for k in springs], joint, (4, 5))  # dampers beside the springs

rng = np.random.default_rng(3)
sos = signal.butter(4, [2, 150], btype="band", fs=FS, output="sos")
force = signal.sosfilt(sos, rng.standard_normal(int(40 * FS)))
force *= 20.0 / force.std()
z = chain.simulate(force, 1 / FS, z0=0.0, input_kind="force", force_dof=1).z[0]
sensed = z[[0, 3, 4]]
sensed = sensed + 0.01 * sensed.std(axis=1, keepdims=True) * rng.standard_normal(sensed.shape)

rec = from_arrays(force, sensed, FS, input_name="force", force_dof=1, source="chain")
result = NSI(element="2-3").fit(rec).result_

# %%
# The chain's own modes (the joint's linear part is zero) beside the identified ones, and the joint's k3
minv = np.diag(1 / np.asarray(masses))
lam = linalg.eigvals(np.block([[np.zeros((5, 5)), np.eye(5)], [-minv @ chain.K, -minv @ chain.C]]))
lam = sorted(lam[lam.imag > 0], key=abs)
lam = np.array(lam)
truth, truth_zeta = np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)
print(f"linear part of order {result.model.order} from the stabilisation diagram, for 3 sensors")
for m, f, zt, se in zip(result.modal["linear"], truth, truth_zeta, result.settings["modes_se"], strict=True):
    print(f"  {m.f_hz:7.3f} Hz (+- {se['f_hz']:.3f}, truth {f:7.3f})   zeta {100 * m.zeta:.2f} % "
          f"(+- {100 * se['zeta']:.2f}, truth {100 * zt:.2f})")  # fmt: skip
k3 = result.element["k3"]
print(f"joint k3 = {k3['value']:.4g} +- {k3['se']:.2g} N/m^3 (truth 2e9)")
v = result.validation
print(f"held-out free runs: {v['rms_percent']:.2g} % of the sensors' rms; the linear part alone "
      f"{v['linear_rms_percent']:.3g} %")  # fmt: skip

# %%
# Left, the stabilisation diagram: each order's poles, the stable ones filled. Below order 10 the poles wander
# between the chain's modes (grey lines); from 10 on each mode stands still (the last orders have no next ones
# to be called stable against). Right, the identified underlying-linear FRF from the force to each sensor [m/N]
# against the chain's own (thick).
fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
for row in result.stabilisation:
    f = [p["f_hz"] for p in row["poles"]]
    stable = [p["stable"] for p in row["poles"]]
    ax.scatter(f, [row["order"]] * len(f), s=14, c=["C0" if s else "none" for s in stable], edgecolors="C0")
for f in truth:
    ax.axvline(f, color="0.7", lw=0.8, zorder=0)
ax.axhline(result.model.order, color="C3", lw=0.8, ls="--")
ax.set(xlabel="frequency [Hz]", ylabel="model order", xlim=(0, 60), title="stabilisation diagram (chosen: dashed)")

freqs = np.asarray(result.frf["f_hz"])
H = np.asarray(result.frf["real"]) + 1j * np.asarray(result.frf["imag"])
om = 2 * np.pi * freqs
H_true = np.array([np.linalg.solve(chain.K - w**2 * np.diag(masses) + 1j * w * chain.C, np.eye(5)[0])[[0, 3, 4]]
                   for w in om]).T  # fmt: skip
for k, name in enumerate(["drive point (mass 1)", "mass 4", "mass 5"]):
    bx.semilogy(freqs, np.abs(H_true[k]), color=f"C{k}", lw=2.5, alpha=0.35)
    bx.semilogy(freqs, np.abs(H[k]), color=f"C{k}", lw=1, label=name)
bx.set(xlabel="frequency [Hz]", ylabel="|H| [m/N]", title="underlying-linear FRF (thick: the chain's)")
bx.legend(fontsize=8)
fig.tight_layout()
plt.show()
