"""A real aircraft ground vibration test, run on request: the F-16 benchmark (J. P. Noel and M. Schoukens, "F-16
aircraft benchmark based on ground vibration test data", 2017 Workshop on Nonlinear System Identification
Benchmarks; https://www.nonlinearbenchmark.org, data at https://data.4tu.nl/articles/_/12954911). A shaker's force
under the right wing, accelerometers at the shaker (1), on the wing beside the wing-to-payload joint (2) and on the
payload beside it (3), 400 Hz; the joint's clearance and friction are the nonlinearity. The file is not in this
repository (its terms are the benchmark's): point ``NEGSTIFF_F16`` at ``F16Data_FullMSine_Level1.csv`` (the full
multisine, 2-15 Hz, 12.4 N rms, 9 periods of 8192 samples) as published, then ``python -m pytest -m slow
tests/records/test_public_gvt_record.py``.
"""

import os
import warnings

import pytest

from negstiff import NSI, load
from negstiff.inference.analysis.frf import frf
from negstiff.inference.estimators.nsi._state_space import StateSpaceIdentificationError

PATH = os.environ.get("NEGSTIFF_F16")
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(not PATH, reason="NEGSTIFF_F16 (the F-16 benchmark's full multisine CSV) not set"),
]
COLUMNS = "force=Force,y1_acc=Acceleration1,y2_acc=Acceleration2,y3_acc=Acceleration3"


@pytest.fixture(scope="module")
def record():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load(PATH, columns=COLUMNS)  # the rate from the file's own "Fs" column (first row only)


def test_the_file_is_read_as_published_and_every_accelerometer_alike(record):
    # 400 Hz from its "Fs" column; the three accelerometers' double integrals each read as a structure's (above
    # 1 Hz): the wing's had been read as a cross-well device's, its wander's histogram having two modes (its
    # oscillation about them 0.19 of their spread, a cross-well motion's 0.48-1.02)
    assert record.fs == 400.0 and record.input_name == "force" and record.n_dof == 3
    for c in record.info["response"]["channels"]:
        assert c["derived"].endswith("above 1 Hz"), c


def test_the_frf_finds_the_modes_in_the_band(record):
    # the driving point's and the joint's FRFs: six peaks between 3 and 10 Hz (measured 3.47, 3.97, 5.19, 6.60,
    # 7.32 and 9.17 Hz, damped 0.6-1.7 %)
    peaks = sorted(m["f_hz"] for m in frf(record).get("modes", []))
    assert len([f for f in peaks if 3.0 < f < 10.0]) >= 6, peaks


@pytest.mark.xfail(
    strict=True,
    raises=StateSpaceIdentificationError,
    reason="open: NSI's state-space step refuses this record ('no state-space model from order 16 up: the identified "
    "discrete-time system is unstable'): on the accelerometers' double integrals its stabilisation diagram holds 2 of "
    "the FRF's 6 modes (3.46, 7.23 Hz) and every order from 18 to 40 has a pole outside the unit circle, most below "
    "2.5 Hz where the force has no power (the integrals' slow error; high-passing every channel at 1-1.5 Hz or "
    "decimating does not help). A prototype outside the package (measured 2026-11-30): the accelerations themselves "
    "as the outputs (a feedthrough term D), inputs and outputs band-passed alike to the force's 2-16 Hz and decimated "
    "to 50 Hz: the diagram holds 7 modes (3.48, 3.95, 5.18, 6.62, 7.33, 9.18, 12.34 Hz, the FRF's within 1 %), every "
    "order from 18 to 24 stable; the cubic basis's coefficients poorly determined (|Im/Re| 0.6-2.7) and the held-out "
    "tail predicted no better than by the best linear model of the order (5.9 % against 5.5-6.6 %): at 12 N rms the "
    "joint is nearly linear. Next: that route in the package, and the benchmark's higher levels",
)
def test_nsi_reads_the_joint_between_the_wing_and_the_payload(record):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = NSI(element="2-3").fit(record).result_
    assert r.validation["rms_percent"] < r.validation["best_linear_rms_percent"]
