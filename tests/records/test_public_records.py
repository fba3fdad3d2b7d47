"""Real public records that negstiff may not ship: read from the user's own copy, run on request.

BistableX (J. P. Norenberg, P. S. Varoto, S. da Silva, A. Cunha Jr, "Asymmetry-enhanced performance in
bistable energy harvesters: an experimental study", 2025; https://github.com/americocunhajr/BistableX) holds
the measured records of a horizontal bistable piezo-magneto-elastic harvester on a shaker: base acceleration
[g] and a laser vibrometer's velocity [V, gain not stated] at 2048 Hz. Its licence (CC BY-NC-ND 4.0) forbids
redistributing it under negstiff's MIT licence, so the data is not in this repository: clone BistableX and
point ``NEGSTIFF_BISTABLEX`` at the clone, then ``python -m pytest -m slow tests/records/test_public_records.py``.
"""

import os
from pathlib import Path

import numpy as np
import pytest

from negstiff.errors import InputError

ROOT = os.environ.get("NEGSTIFF_BISTABLEX")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not ROOT, reason="NEGSTIFF_BISTABLEX (a clone of BistableX) not set: not shippable"),
]


def _chaos_record(tmp_path: Path) -> Path:
    """The asymmetric chaotic run as one CSV: blocks DPsv00001-00099 (4 s each, contiguous: each block's
    first velocity sample continues the last one's), 396 s at 2048 Hz, written as the lab's columns (the waits
    benchmark's reader, which times its refusals)."""
    from benchmarks.waits import harvester_record

    return harvester_record(Path(ROOT), tmp_path / "bistablex_chaos_asymmetric.csv")


def test_the_harvesters_chaotic_run_keeps_its_wells_and_its_forcing(tmp_path):
    # Facts of the run (its authors' Poincare maps): forced at 6.5 Hz (a user who states 9.1 Hz, the
    # folder's other frequency, is told so before any work), chaotic and cross-well. The velocity's
    # integral drifts by some 45 mm over 396 s; with the drift separated, z's histogram has two modes
    # (the wells) and the regime is cross-well (it read "in-well-minus" before).
    from negstiff.inference.analysis.characterise import characterise
    from negstiff.inference.record.reading import load

    path = _chaos_record(tmp_path)
    rec = load(path, columns="base_acc=ACC*9.80665,z_dot=VEL*?", gravity=0.0)
    with pytest.raises(InputError, match="dominant line is at 6.5 Hz"):
        characterise(rec, 9.1)
    c = characterise(rec, 6.5)
    assert c["regime"] == "cross-well" and c["period"] is None and c["chaotic"]
    assert rec.info["response"]["drift"]["modes_after"] == 2


SWEEPS = Path("DataExperimental") / "base_rotation_phi=0" / "swept_sine"


def _frf_misfit(f, h, absolute):
    """Gain [V per m/s], and the rms relative misfit, of the vibrometer's FRF to the base acceleration [V/g] by
    one well's linear oscillator: H = G g0 (-i / w) T, T = 1 + p r^2 / (1 - r^2 + 2 i zeta r) for a vibrometer on
    the ground (the point's absolute velocity), T = p r^2 / (...) for one moving with the base (relative)."""
    from scipy.optimize import least_squares

    w = 2 * np.pi * f

    def residual(x):
        gain, p, fn, zeta = x
        r = f / fn
        rel = p * r**2 / (1 - r**2 + 2j * zeta * r)
        e = (gain * 9.80665 * (-1j / w) * ((1 + rel) if absolute else rel)) / h - 1
        return np.r_[e.real, e.imag]

    fits = [least_squares(residual, [10.0, p0, fn0, 0.02], bounds=([0, -5, 3, 1e-4], [1e3, 5, 15, 0.5]))
            for fn0 in (7.0, 8.0, 9.0, 9.5) for p0 in (0.5, -0.5)]  # fmt: skip
    best = min(fits, key=lambda r: r.cost)
    return best.x[0], float(np.sqrt(2 * best.cost / f.size))


def test_the_vibrometer_reads_the_absolute_velocity(tmp_path):
    # The lab's swept-sine FRFs (velocity channel over base acceleration, 4.5-30 Hz where the coherence is above
    # 0.9) are those of a point's absolute velocity: an antiresonance above each well's resonance, and a level
    # falling as 1/w away from them (the base's own velocity), at one gain in every sweep (a vibrometer on the
    # ground; measured 20.3-21.3 V per m/s, misfit 12-19 %). Read as a relative velocity they misfit by 56-87 %.
    # The chaotic run's own dynamics, read as an absolute velocity of unknown gain (y_dot=VEL*?), give that gain
    # within 15 % (measured 18.7 against the FRFs' 20.7: a small-amplitude linear fit against a cross-well
    # equation error), and the base's motion left out of z (two wells, cross-well)
    from scipy.io import loadmat

    from negstiff.inference.record.reading import load

    sweeps = sorted((Path(ROOT) / SWEEPS).glob("*/*_eq_point.mat"))
    if not sweeps:
        pytest.skip(f"{SWEEPS} is not in the clone")
    gains = []
    for path in sweeps:
        d = loadmat(path)
        f, h, coh = d["H1_3"][:, 0].real, d["H1_3"][:, 1], d["C1_3"][:, 1]
        keep = (f > 4.5) & (f < 30) & (coh > 0.9)
        g_abs, misfit_abs = _frf_misfit(f[keep], h[keep], absolute=True)
        _, misfit_rel = _frf_misfit(f[keep], h[keep], absolute=False)
        assert misfit_abs < 0.25 < 0.5 < misfit_rel, (path.name, misfit_abs, misfit_rel)
        gains.append(g_abs)
    frf_gain = float(np.median(gains))
    assert np.ptp(gains) < 0.1 * frf_gain
    rec = load(_chaos_record(tmp_path), columns="base_acc=ACC*9.80665,y_dot=VEL*?", gravity=0.0)
    assert 1.0 / rec.info["response"]["gain"]["gain"] == pytest.approx(frf_gain, rel=0.15)
    assert rec.info["response"]["drift"]["modes_after"] == 2


@pytest.mark.xfail(
    strict=True,
    reason="open (measured on the absolute-velocity route, y_dot=VEL*?): NSI refuses (its subspace step's "
    "discrete-time system is unstable; its basis is a cubic, and the record's restoring force is not: a "
    "cubic explains 94 % of z'' by equation error, a quintic 98.7 %); SINDy selects viscous damping (c > "
    "0) and a quintic that turns over beyond the visited stroke (k5 < 0), whose restarted runs diverge. "
    "With z^6 and z^7 offered (registered effects) SINDy's model is bounded, c > 0, wells 7.43 and 8.17 "
    "Hz, but its held-out 2 s restarted runs err by 121 % (0.25 s: 39 %). 2 s is beyond this chaotic "
    "run's horizon: that model, run on a record of its own under the run's base acceleration (cross-well,"
    " 237 hops a minute), errs by 79-101 % over 2 s windows (z noise 0.01-0.1 mm), 1.3-6.3 % over 0.25 s."
    " The same study on a DOP853 record of a cubic harvester passes "
    "(tests/records/test_absolute_velocity_records.py). Measured 2026-11-29 with the laws (the default falls back"
    " to them): SINDy chooses the spline, wells 7.61 / 8.31 Hz, predictable windows 70 %. NSI (measured "
    "again 2026-11-29, 75d473b) answers in 68 s: the cubic's subspace step is unstable, and of the laws "
    "only the septic passes its checks (c 4.0 > 0; wells by its linearisation 7.07 / 7.85 Hz, the "
    "subspace step's poles at its references 3.83 / 5.12 Hz, the passes still moving 3-5 mm), its "
    "predictable (0.49 s) windows' median 95 %, 2 s windows 124 %. The 9.2 Hz target is the "
    "symmetric configuration's: the lab's FRFs of its asymmetric ones (one magnet rotated: vr or vl = 30)"
    " put one well at 9.15-9.58 Hz and the other at 6.93-7.50 Hz, and which one this run is the data do "
    "not say. On the symmetric chaotic run (chaos_symmetric, blocks 1-99, the FRFs' configuration: 9.19 /"
    " 9.15 Hz) SINDy's wells are 8.24 / 8.16 Hz (-10.3 / -10.8 %), its predictable windows' median 44 %; "
    "NSI refuses alike. The symmetric in-well runs at 6.5 Hz (0.13 g), read at the FRFs' gain and "
    "participation, ring as 7.2-7.3 Hz wells with 3.5-5 % damping: the device softens and dissipates with"
    " amplitude far beyond a smooth double well's (a Duffing well softens < 1 % at that amplitude), so a "
    "memoryless law fitted to chaos does not reach the 5 mV sweeps' 9.2 Hz",
)
@pytest.mark.parametrize("method", ["nsi", "sindy"])
def test_the_harvesters_chaotic_run_is_identified(tmp_path, method):
    # What a user of this record expects: a model with positive damping whose wells are two (cross-well)
    # and which predicts held-out windows better than zero does. The vibrometer stands on the ground: its
    # velocity is absolute (test_the_vibrometer_reads_the_absolute_velocity)
    from negstiff import NSI, SINDy
    from negstiff.inference.record.reading import load

    rec = load(_chaos_record(tmp_path), columns="base_acc=ACC*9.80665,y_dot=VEL*?", gravity=0.0)
    est = (NSI() if method == "nsi" else SINDy()).fit(rec)
    assert est.model_.c > 0
    assert est.result_.validation["restarted_rms_percent"] < 50
