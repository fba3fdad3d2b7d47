"""
NSI on a vibrometer record
==========================

Many labs measure the moving part's velocity with a laser Doppler vibrometer instead of its
displacement. negstiff integrates z_dot to z, pins the unknown constant by physics and says how
(``record.response``). The record here is written as such a lab's CSV, accelerations in g.
"""

import tempfile
from pathlib import Path

from negstiff import NSI, Rig, load
from negstiff.models.rig import Sensors

folder = Path(tempfile.mkdtemp())
rig = Rig(seed=2, sensors=Sensors(response="velocity"))
path = rig.random(duration=120.0).write(folder / "ldv.csv")
print(path.read_text().splitlines()[:6])

# %%
# Load it with a column map (the names as the file has them), identify, compare with the truth.
rec = load(path)
print(rec.info["response"]["derived"])
nsi = NSI().fit(rec)
truth = rig.system.equilibria()
print(
    f"wells: {1e3 * nsi.result_.equilibria.z_minus:.2f} / {1e3 * nsi.result_.equilibria.z_plus:.2f} mm "
    f"(truth {1e3 * truth.z_minus:.2f} / {1e3 * truth.z_plus:.2f} mm)"
)
print(nsi.result_.warnings or "no warnings")
