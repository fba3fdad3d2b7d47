"""Real public records shipped with the tests: a measured free decay of a hardening oscillator (issue "Hammer and
decay tests").

FrID (T. Breunung, B. Balachandran, "Frequency response based identification of nonlinear oscillators", J. Sound
Vib. 2024, 118651; https://github.com/tbreunung/FrID, MIT License) holds the strain-gauge record of a cantilever
beam stiffened by magnets (a hardening single-DOF oscillator) ringing down after a shaker driving it at 42.05 Hz
is switched off, and the authors' SINDy model fitted to that decay (a MATLAB figure). Both are in
``tests/data/frid_magneto_mechanical_decay`` (the record cut to the authors' decay window, 12.1-19.1 s; its
README says what was cut and why the reference is the SINDy fit).

Acceptance (the issue): the identified linear frequency within 1 % of the published value, the backbone within 2 %.
The published value is the authors' identification of this record: their SINDy model's free decay, read cycle by
cycle here with plain numpy (period between upward zero crossings, half peak-to-peak amplitude). The tolerances
are the acceptance's; what each estimate reached is in the comments.

No hammer (impact) record whose licence allows shipping it and whose natural frequency is published was found;
the issue's impact half is open.
"""

import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat

from negstiff import NSI, SINDy
from negstiff.inference.analysis.backbone import backbone, on_amplitudes
from negstiff.inference.record.measurement import load

FRID = Path(__file__).parent / "data" / "frid_magneto_mechanical_decay"
RECORD = FRID / "decay_f_42p05_ampl_2p0_0_12p1-19p1s.lvm"
COLUMNS = "force=Sine with Gaussian Noise,z=Strain_0"
"""The generator's output as the input (0 throughout the cut: a free decay), the beam's strain gauge as z (in the
gauge's units, ~2e-4 at the start: the frequencies do not depend on the scale)."""

SMALL_CYCLES = 5
"""The reference's linear frequency: the mean over its last (smallest) five cycles, 4.7e-6 to 5.4e-6 strain, where
its frequency has stopped falling (36.818-36.822 Hz)."""


def _cycles(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each cycle between two upward zero crossings (linear interpolation): its half peak-to-peak amplitude and
    its frequency 1 / period."""
    s = np.sign(x)
    i = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))
    tc = t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])
    amp = np.array([np.ptp(x[a + 1 : b + 1]) / 2 for a, b in zip(i[:-1], i[1:], strict=True)])
    return amp, 1.0 / np.diff(tc)


@cache
def _published() -> dict[str, np.ndarray]:
    """The authors' SINDy model's free decay (the figure's line 'SinDy'), cycle by cycle."""
    fig = loadmat(FRID / "SinDy_decay_fit.fig", squeeze_me=True, struct_as_record=False)["hgS_070000"]
    axes = next(c for c in np.atleast_1d(fig.children) if c.type == "axes")
    line = next(c.properties for c in np.atleast_1d(axes.children)
                if "line" in c.type and c.properties.DisplayName == "SinDy")  # fmt: skip
    amp, f = _cycles(np.asarray(line.XData, float), np.asarray(line.YData, float))
    return {"amplitude_m": amp, "f_hz": f}


@cache
def _record():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load(RECORD, columns=COLUMNS, gravity=0.0)


@cache
def _measured() -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return backbone(_record())


def test_the_lvm_record_is_read_as_a_free_decay_from_its_first_sample():
    # the file as LabVIEW wrote it (twelve channels, three of them 1 Hz and empty between their samples), the
    # generator's output at 0 throughout: a decay from 12.100 s, the authors' own start
    rec = _record()
    assert rec.fs == pytest.approx(1000.0) and rec.n == 7000 and rec.t0 == pytest.approx(12.1)
    assert np.all(np.asarray(rec.u) == 0.0)
    assert _measured()["decay"]["start_s"] == pytest.approx(12.1, abs=1e-9)


def test_the_linear_frequency_of_the_decay_is_the_published_one():
    # the published model's smallest cycles: 36.820 Hz; the Hilbert backbone's smallest fifth of amplitudes
    # (1.3e-5 to 1.9e-5): 36.888 Hz, +0.18 %
    f_published = float(np.mean(_published()["f_hz"][-SMALL_CYCLES:]))
    assert _measured()["linear"]["f_hz"] == pytest.approx(f_published, rel=0.01)


@pytest.mark.parametrize("estimator", ["hilbert", "peaks"])
def test_the_backbone_of_the_decay_is_the_published_one(estimator):
    # hardening from 36.8 Hz to 41.3 Hz over the decay; at each of 12 amplitudes (geometric, over the range both
    # curves cover) the measured frequency within 2 % of the published model's. Measured (Hilbert): +0.04 % at
    # 1.7e-5 to +1.63 % at 1.6e-4; the peaks +0.18 % to +1.48 % where they reach. The authors' own filtered decay
    # read cycle by cycle is 1.7 % above their model at 1.6e-4: the fit's error, not the estimators'.
    pub, meas = _published(), _measured()
    lo = max(pub["amplitude_m"].min(), meas["amplitude_range_m"][0])
    hi = min(pub["amplitude_m"].max(), meas["amplitude_range_m"][1])
    grid = np.geomspace(lo, hi, 12)
    f_pub = on_amplitudes(pub, grid)
    f_meas = on_amplitudes(meas["measured"][estimator], grid)
    covered = np.isfinite(f_meas)
    assert covered.sum() >= (12 if estimator == "hilbert" else 8), covered
    assert hi / lo > 10  # the comparison spans the decay, not its tail
    np.testing.assert_allclose(f_meas[covered], f_pub[covered], rtol=0.02)
    assert f_meas[covered][-1] > 1.08 * f_meas[covered][0]  # the hardening is read, not a flat line


@pytest.mark.parametrize("method", [NSI, SINDy], ids=["nsi", "sindy"])
def test_nsi_and_sindy_identify_the_decays_linear_frequency(method):
    # each on the decay (no input, per unit mass): its well's linearised frequency. Measured: NSI 36.838 Hz
    # (+0.05 %), SINDy 36.649 Hz (-0.46 %), both models with quadratic and cubic stiffness; a second or two each
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = method().fit(_record())
    assert est.result_.details["record_kind"]["kind"] == "decay"
    f_published = float(np.mean(_published()["f_hz"][-SMALL_CYCLES:]))
    found = [m["f_hz"] for m in est.modal_.values() if m["f_hz"] is not None]
    assert found and min(abs(f / f_published - 1) for f in found) < 0.01, found
