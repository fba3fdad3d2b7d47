"""
A report over a campaign of records
===================================

An experiment script that runs its own campaign (here three random records of the virtual rig at
increasing table acceleration, standing in for a lab's), identifies each with NSI and SINDy, samples one
coefficient posterior, and writes one report: the summary first, one table of every coefficient with
each method's estimate beside the posterior's interval (and its forest plot), how each coefficient moves
with the amplitude, and a section per result.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from negstiff import NSI, Measurement, Posterior, Report, Rig, SINDy

rep = Report("How the identified model moves with the excitation level")
k3 = {}
for rms in (8.0, 11.0, 14.0):
    record = Measurement.from_rig(Rig(seed=7).random(duration=60.0, rms=rms))
    label = f"{rms:g} m/s^2 rms"
    sindy = SINDy(seed=1).fit(record)
    rep.add(sindy, label=label).add(NSI().fit(record), label=label)
    k3[rms] = sindy.model_.k3

# %%
# One posterior, on the first 20 s of the last record: the interval the estimates are read against
rep.add(Posterior(seed=1).fit(record.segment(0, int(20 * record.fs))), label="14 m/s^2 rms")

fig, ax = plt.subplots(figsize=(5, 3))
ax.plot(list(k3), list(k3.values()), "o-")
ax.set(xlabel="table acceleration rms [m/s^2]", ylabel="k3 [N/m^3]")
rep.add_figure(
    fig,
    "SINDy's k3 at each level: the as-built device is not a cubic, so the cubic's best fit moves "
    "with how far the record reaches.",
    heading="k3 against the excitation level",
)
out = rep.write(Path(tempfile.mkdtemp()) / "report_over_amplitudes")  # your own folder in a real script
print(f"wrote {out / 'index.html'}")
print("\n".join(rep.results()["summary"]))
