"""Impact (hammer) tests read as the field reads them: hits found in a force channel with a DC offset, force and
exponential windows, H1 averaged over hits, the exponential window's added damping taken off each mode.

The records are written here with scipy's DOP853 (``impact_records``): a hardening Duffing and the seed-like
asymmetric double well, hit at a level that keeps them linear (the frequency moves by under 0.03 % at the
0.3 mm the hits reach: the averaging method's backbone of each), so the FRF's mode is the underlying-linear one.
"""

import json
import warnings

import numpy as np
import pytest
from impact_records import DOUBLE_WELL, DUFFING, MASS, hammer_record

from negstiff.inference.analysis.frf import frf
from negstiff.inference.analysis.impact import correct_exponential
from negstiff.inference.record.impacts import find_impacts
from negstiff.inference.record.measurement import from_arrays

FS = 2048.0
HITS = [0.5, 3.5, 6.5, 9.5]
"""Four hits 3 s apart: a 1.5-2 % mode at 10-12 Hz rings down to 3-9 % of its peak in that time, so the response
needs the exponential window (leakage otherwise), whose added damping (about 1 %) the fit must take off."""

FORCE_OFFSET_N, FORCE_NOISE_N = 0.5, 0.01
"""The hammer channel's DC offset (a charge amplifier's, a third of the hit's peak) and its noise."""


def _lab(force, response, rng, noise):
    return force + FORCE_OFFSET_N + FORCE_NOISE_N * rng.standard_normal(force.size), \
        response + noise * rng.standard_normal(response.size)  # fmt: skip


def _quiet_frf(rec, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return frf(rec, **kw)


def test_duffing_hammer_with_offset_gives_the_linear_mode_and_its_damping():
    # the hardening Duffing hit four times at 0.3 mm (a laser displacement, 1 um noise): its underlying-linear
    # 12 Hz, 1.5 % mode; the noise (SNR 300 on the response, 180 on the force's peak) and 4 averages leave the
    # frequency within 0.05 % and the damping within 2 %; the bounds are 1 % and 10 %
    rng = np.random.default_rng(11)
    _, f, z, _ = hammer_record(DUFFING, 0.0, FS, HITS, 1.8, 0.004, 12.0)
    fm, zm = _lab(f, z, rng, 1e-6)
    r = _quiet_frf(from_arrays(fm, zm, FS, input_name="force", mass=MASS))
    truth = DUFFING.uls("plus")
    assert r["impacts"]["hits"] == 4
    assert np.allclose(r["impacts"]["offset_n"], FORCE_OFFSET_N, atol=5 * FORCE_NOISE_N)
    assert r["impacts"]["exponential_tau_s"] is not None  # the ring-downs were cut: the window was needed
    assert abs(r["f_hz"] / truth.f_hz - 1) < 0.01
    assert abs(r["zeta"] / truth.zeta - 1) < 0.10
    # without the correction the window's damping (1/tau over w_n) would be reported: far beyond 10 %
    windowed = r["peaks"][0]["windowed"]["zeta"]
    assert windowed / truth.zeta - 1 > 0.3


def test_double_well_hammer_measured_by_velocity_gives_the_well_mode():
    # the double well at rest in its +20 mm well, hit three times, a laser vibrometer (velocity, 1e-4 m/s noise:
    # SNR 190); the force channel keeps a 2 N offset (six times the noise floor's size, above the hit's peak
    # share of nothing: the offset is the largest line of the raw force's spectrum): the well's 10.31 Hz, 1.9 %
    rng = np.random.default_rng(12)
    well = DOUBLE_WELL.equilibria().z_plus
    _, f, _, v = hammer_record(DOUBLE_WELL, well, FS, HITS[:3], 1.5, 0.004, 9.0)
    fm = f + 2.0 + FORCE_NOISE_N * rng.standard_normal(f.size)
    vm = v + 1e-4 * rng.standard_normal(v.size)
    rec = from_arrays(fm, None, FS, input_name="force", mass=MASS, z_dot=vm)
    r = _quiet_frf(rec)
    truth = DOUBLE_WELL.uls("plus")
    assert r["impacts"]["hits"] == 3 and r["impacts"]["response"] == "z_dot"
    assert abs(r["f_hz"] / truth.f_hz - 1) < 0.01
    assert abs(r["zeta"] / truth.zeta - 1) < 0.10
    assert r["coherence"] > 0.99  # three hits of one linear mode: coherent at the peak


def test_single_hit_and_its_offset():
    # one hit in a record whose force channel keeps its offset: still the mode (the lab's beam: 'frf' reported a
    # band of 0.2:0.8 Hz or "0.3 Hz, zeta 100 %" from the offset's line); the coherence of one hit says nothing
    rng = np.random.default_rng(13)
    _, f, z, _ = hammer_record(DUFFING, 0.0, FS, [0.4], 1.8, 0.004, 4.0)
    fm, zm = _lab(f, z, rng, 1e-6)
    r = _quiet_frf(from_arrays(fm, zm, FS, input_name="force", mass=MASS))
    truth = DUFFING.uls("plus")
    assert r["impacts"]["hits"] == 1 and "by construction" in r["impacts"]["coherence"]
    assert abs(r["f_hz"] / truth.f_hz - 1) < 0.01
    assert abs(r["zeta"] / truth.zeta - 1) < 0.10
    assert all(0.001 < p["zeta"] < 0.5 for p in r["peaks"])  # no fit at a damping bound is reported as a mode


def test_a_random_force_is_not_taken_for_impacts():
    # a shaker's random force: its peaks stand 3-5 deviations above its median, not 30: a stationary record
    rng = np.random.default_rng(14)
    assert find_impacts(0.3 + rng.standard_normal(20000), FS) is None
    assert find_impacts(np.sin(np.arange(20000) / 50), FS) is None


def test_exponential_window_correction_is_the_pole_shift():
    # the window exp(-t/tau) moves the pole by -1/tau: a 10 Hz, 1 % mode seen through tau = 1 s has decay rate
    # 0.628 + 1 = 1.628 1/s at the same damped frequency; the correction gives back 10 Hz and 1 %
    wn, zeta, tau = 2 * np.pi * 10.0, 0.01, 1.0
    wd = wn * np.sqrt(1 - zeta**2)
    sigma_w = zeta * wn + 1 / tau
    wn_w = np.hypot(sigma_w, wd)
    f, z = correct_exponential(wn_w / (2 * np.pi), sigma_w / wn_w, tau)
    assert f == pytest.approx(10.0, rel=1e-12) and z == pytest.approx(0.01, rel=1e-10)


def test_cli_frf_reads_an_impact_file_and_says_so(tmp_path, capsys):
    # the lab's file: a hammer channel with its offset and a laser vibrometer, mapped by --columns; the command
    # says it treated the record as impacts (hits, windows) and finds the 12 Hz mode
    from negstiff.cli import main

    rng = np.random.default_rng(15)
    t, f, _, v = hammer_record(DUFFING, 0.0, FS, HITS[:2], 1.8, 0.004, 6.0)
    fm = f + FORCE_OFFSET_N + FORCE_NOISE_N * rng.standard_normal(f.size)
    vm = v + 1e-4 * rng.standard_normal(v.size)
    data = tmp_path / "beam.csv"
    np.savetxt(data, np.column_stack([t, fm, vm]), delimiter=",", header="t,F,V", comments="")
    out = tmp_path / "frf.json"
    assert main(["frf", str(data), "--columns", "t=t,force=F,z_dot=V", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "impact test: 2 hit(s)" in err and "exponential" in err
    r = json.loads(out.read_text())
    assert abs(r["f_hz"] / DUFFING.uls("plus").f_hz - 1) < 0.01 and r["impacts"]["hits"] == 2
    assert (tmp_path / "frf.png").exists()
