"""
A ground vibration test read by accelerometers, judged on another test
======================================================================

The lab's usual sensors are accelerometers, and a model is judged on a test it was not fitted to. The five-mass
chain of the previous example (a cubic joint between masses 4 and 5, no masses given) is read here by three
accelerometers (0.1 % noise) at the drive point and either side of the joint, through a file, as a lab's record is.
The file names the sensor the shaker's force acts at (``# force_dof: 1``): the joint is sized through that driving
point, which NSI does not guess (a record without it is refused).

NSI's outputs are then the accelerations themselves (with a feedthrough: an acceleration answers a force at once),
not their double integrals, and the record is decimated to its band (:doc:`/methods/structures`). The fitted model
then predicts a second test of the same structure, another random force, by restarted free runs
(``predict``): the benchmarks' way of judging a model. The figures: the measured FRFs with the model's, and one
predicted window of the second test.
"""

import tempfile
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from scipy import signal

from negstiff import NSI, Model, Structure, load
from negstiff.inference.analysis.frf import frf
from negstiff.io import write

warnings.simplefilter("ignore")  # the joint's weakly determined terms are said in the result's warnings

FS = 1000.0
masses, springs = [2.0, 1.5, 1.2, 1.0, 0.8], [4e4, 3e4, 2.5e4, 2e4, 1.5e4]
joint = Model(m=0.8, k0=0.0, k1=0.0, k2=0.0, k3=2e9, c=0.0, c_nl=0.0)
chain = Structure.chain(masses, springs, [2e-4 * k for k in springs], joint, (4, 5))
folder = Path(tempfile.mkdtemp())


def shaker_test(seed: int, path: Path) -> Path:
    """40 s of a random force (2-150 Hz, 20 N rms) at mass 1, three accelerometers written to ``path``: each mass's
    acceleration from its equation of motion, M a = f e_1 - K z - C z' - the joint's force."""
    rng = np.random.default_rng(seed)
    force = signal.sosfilt(signal.butter(4, [2, 150], btype="band", fs=FS, output="sos"),
                           rng.standard_normal(int(40 * FS)))  # fmt: skip
    force *= 20.0 / force.std()
    run = chain.simulate(force, 1 / FS, z0=0.0, input_kind="force", force_dof=1)
    z, v = run.z[0], run.z_dot[0]
    g = joint.k3 * (z[4] - z[3]) ** 3  # the cubic joint, on mass 5 and, opposite, on mass 4
    f_all = -(chain.K @ z) - (chain.C @ v)
    f_all[0] += force
    f_all[4] -= g
    f_all[3] += g
    acc = (f_all / np.asarray(masses)[:, None])[[0, 3, 4]]
    acc = acc + 1e-3 * acc.std(axis=1, keepdims=True) * rng.standard_normal(acc.shape)
    columns = {"t": np.arange(force.size) / FS, "force": force, **{f"y{k + 1}_acc": acc[k] for k in range(3)}}
    write(path, columns, FS, {"force_dof": "1", "element": "2-3"})
    return path


first = load(shaker_test(3, folder / "test1.csv"))
second = load(shaker_test(7, folder / "test2.csv"))
nsi = NSI().fit(first)  # the element's place from the file's '# element: 2-3'
result = nsi.result_
print(f"outputs: {result.settings['sampling']}; order {result.model.order}")
print("modes [Hz]:", ", ".join(f"{m.f_hz:.2f}" for m in result.modal["linear"]))
k3 = result.element["k3"]
print(f"joint k3 = {k3['value']:.4g} +- {k3['se']:.2g} N/m^3 (truth 2e9); the sensor read as the driving point: "
      f"{result.settings['driving_point_like']}")  # fmt: skip
v = result.validation
print(f"its own held-out tail: {v['rms_percent']:.2g} % of the accelerations' rms, the best linear model of its "
      f"order {v['best_linear_rms_percent']:.3g} %")  # fmt: skip
prediction = nsi.predict(second, window_s=0.25)
errors = prediction.errors
print(f"the second test, predicted: median window {prediction.score_percent:.2g} % ({errors['windows_scored']} windows,"
      f" {errors['windows_diverged']} diverged)")  # fmt: skip

# %%
# Left, each sensor's measured FRF (H1, the force to its double integral) with the model's underlying-linear FRF
# dashed over it: the two agree where the joint does not move (the first two modes), and differ at the modes that
# move it (28-36 Hz): the measured H1 holds the joint's equivalent stiffness at this level, the model's FRF is the
# structure with the joint's cubic taken out (its law is the model's feedback). Right, the second test's
# acceleration at mass 5 over its median window and the model's free run from the state it read off the window
# before.
curves = frf(first)["_curves"]
fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
for k, c in enumerate(curves):
    sel = (c["f"] > 2) & (c["f"] < 50)
    ax.semilogy(c["f"][sel], np.abs(c["H1"][sel]), color=f"C{k}", label=f"sensor {k + 1}")
    ax.semilogy(c["f"][sel], np.abs(result.model.frf(c["f"][sel])[:, k]), "--", color=f"C{k}", lw=1)
ax.set(xlabel="frequency [Hz]", ylabel="|H| [m/N]", title="measured H1 (solid), the model's FRF (dashed)")
ax.legend(fontsize=8)
w = int(np.argsort(np.nanmean((prediction.z - prediction.measured) ** 2, axis=(1, 2)))[len(prediction.z) // 2])
bx.plot(prediction.t[w], prediction.measured[w, 2], label="measured", lw=2, alpha=0.5)
bx.plot(prediction.t[w], prediction.z[w, 2], "--", label="NSI's model, free run")
bx.set(xlabel="time [s]", ylabel="acceleration of mass 5 [m/s^2]", title="the second test: its median window")
bx.legend(fontsize=8)
fig.tight_layout()
plt.show()
