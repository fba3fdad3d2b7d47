"""Records as a lab bench hands them over: a swept-sine block whose response drifts at low frequency, a
LabVIEW measurement file as LabVIEW writes it, a harmonic record's report. Each record is written here with
numpy/scipy alone."""

import numpy as np
import pytest
from scipy import signal

from negstiff.cli import main
from negstiff.inference.analysis.frf import frf
from negstiff.inference.record.measurement import from_arrays

FS = 512.0


def _rk4_base_excited(acc_at, fs, n, fn, zeta, k3_per_m=0.0):
    """z'' + 2 zeta wn z' + wn^2 (z + k3_per_m z^3) = -a(t), from rest, by the classical RK4 at the sampling
    step; ``acc_at(t)`` gives the base acceleration [m/s^2] at any time (the stages' half steps included)."""
    wn, h = 2 * np.pi * fn, 1 / fs
    t = np.arange(n) / fs
    a0, ah, a1 = acc_at(t), acc_at(t + h / 2), acc_at(t + h)
    z = np.empty(n)
    x, v = 0.0, 0.0
    for i in range(n):
        z[i] = x

        def f(xx, vv, a):
            return vv, -a - 2 * zeta * wn * vv - wn**2 * (xx + k3_per_m * xx**3)

        k1 = f(x, v, a0[i])
        k2 = f(x + h / 2 * k1[0], v + h / 2 * k1[1], ah[i])
        k3 = f(x + h / 2 * k2[0], v + h / 2 * k2[1], ah[i])
        k4 = f(x + h * k3[0], v + h * k3[1], a1[i])
        x += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        v += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return t, a0, z


@pytest.fixture(scope="module")
def swept_block():
    """A 64 s linear sweep 1-20 Hz of 1 m/s^2 base acceleration at 512 Hz through a linear oscillator at
    9.2 Hz with 3 % damping (a low-level test around one well)."""
    T, fn = 64.0, 9.2

    def acc(t):
        return signal.chirp(t, f0=1.0, t1=T, f1=20.0, method="linear")

    t, a, z = _rk4_base_excited(acc, FS, int(T * FS), fn, 0.03)
    return a, z, fn


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("drift_over_peak", [1.6, 4.8])
def test_a_drift_bump_in_a_swept_response_is_not_the_resonance(swept_block, seed, drift_over_peak):
    # Fact: the response of a swept-sine test with a slow drift (0.1-2 Hz, uncorrelated with the input, its rms
    # 1.6x or 4.8x the response's largest amplitude: a laser on a creeping stand) still resonates at the
    # oscillator's 9.2 Hz. The drift lifts |H1| at low frequency where few Welch segments hold the sweep, with a
    # coherence of 0.5-0.65 (the input explains little of the response there); the resonance's coherence is
    # above 0.9. The dominant peak is the coherent one, within 1 % (the Welch bin is 1/16 Hz, 0.7 % of 9.2 Hz;
    # the SDOF fit lands well inside it), and it says its coherence.
    a, z, fn = swept_block
    rng = np.random.default_rng(seed)
    sos = signal.butter(2, [0.1, 2.0], "bandpass", fs=FS, output="sos")
    drift = signal.sosfiltfilt(sos, rng.standard_normal(z.size))
    drift *= drift_over_peak * np.abs(z).max() / drift.std()
    r = frf(from_arrays(a, z + drift, FS))
    assert r["f_hz"] == pytest.approx(fn, rel=0.01), r["peaks"]
    assert r["coherence"] > 0.9
    assert r["peaks"][0]["f_hz"] == r["f_hz"]  # the dominant peak first, as the contract's f_hz
    passed = [p for p in r["peaks"] if p["f_hz"] < 5.0]
    assert all(p["coherence"] < r["coherence"] for p in passed)


def _labview_file(path, names, data, dt, units, slow=None, comment=None):
    """A LabVIEW Measurement File as LabVIEW's Write To Measurement File writes it: one segment, tab separated,
    one X column, every line of the channel header ending in a separator, the channel names followed by a
    ``Comment`` column that holds a note on the rows that have one (``comment``: the first row's, if any; no row has
    one unless an operator typed it). ``slow``: (name, value, dt, unit) of a channel logged once in the same block
    (``Samples`` 1; its other rows empty)."""
    names, units = list(names), list(units)
    n_rows = len(data)
    samples, steps = [str(n_rows)] * len(names), [f"{dt:.6f}"] * len(names)
    if slow is not None:
        names.append(slow[0])
        units.append(slow[3])
        samples.append("1")
        steps.append(f"{slow[2]:.6f}")
    k = len(names)
    head = ["LabVIEW Measurement\t", "Writer_Version\t2", "Reader_Version\t2", "Separator\tTab",
            "Decimal_Separator\t.", "Multi_Headings\tNo", "X_Columns\tOne", "Time_Pref\tRelative",
            "Operator\tbench", "Date\t2026/11/20", "Time\t14:02:11.5018", "***End_of_Header***\t", "\t"]  # fmt: skip
    seg = [
        "Channels\t" + str(k) + "\t" * k,
        "Samples\t" + "\t".join(samples) + "\t",
        "Date\t" + "\t".join(["2026/11/20"] * k) + "\t",
        "Time\t" + "\t".join(["14:02:11.5018"] * k) + "\t",
        "Y_Unit_Label\t" + "\t".join(units) + "\t",
        "X_Dimension\t" + "\t".join(["Time"] * k) + "\t",
        "X0\t" + "\t".join(["0.0000000000000000E+0"] * k) + "\t",
        "Delta_X\t" + "\t".join(steps) + "\t",
        "***End_of_Header***\t" + "\t" * k,
        "X_Value\t" + "\t".join(names) + "\tComment",
    ]
    rows = []
    for i, row in enumerate(data):
        fields = [f"{i * dt:.6f}", *(f"{v:.6E}" for v in row)]
        if slow is not None:
            fields.append(f"{slow[1]:.6E}" if i == 0 else "")
        if i == 0 and comment:
            fields.append(comment)  # a row's comment, in the Comment column
        rows.append("\t".join(fields))
    path.write_text("\n".join(head + seg + rows) + "\n")
    return path


@pytest.fixture(params=[None, "sweep start"], ids=["no-comment", "a-row-comment"])
def labview_record(tmp_path, request):
    """4 s at 512 Hz: a table accelerometer, a laser on the moving part (relative displacement), a force cell,
    and a temperature logged once (``Samples`` 1, at 1 Hz); with and without a comment on the first row."""
    rng = np.random.default_rng(11)
    t = np.arange(int(4 * FS)) / FS
    acc = 2.0 * np.sin(2 * np.pi * 7.0 * t) + 0.01 * rng.standard_normal(t.size)
    z = 1.5e-3 * np.sin(2 * np.pi * 7.0 * t - 0.4) + 2e-6 * rng.standard_normal(t.size)
    force = 0.3 * np.sin(2 * np.pi * 7.0 * t + 0.2)
    data = np.column_stack([acc, z, force])
    path = _labview_file(tmp_path / "bench.lvm", ["Accel", "Laser", "Force cell"], data, 1 / FS,
                         ["m/s^2", "m", "N"], slow=("Temperature", 21.5, 1.0, "C"), comment=request.param)  # fmt: skip
    return path, data


def test_a_labview_file_as_labview_writes_it_loads_with_its_values(labview_record):
    # Fact: the trailing Comment column of LabVIEW's channel header carries no data, and a channel logged once
    # (Samples 1) is of another rate than the record: neither stops the record from loading. The values are the
    # file's to its printed precision (%.6E: 5e-7 relative, i.e. 5e-7 of each channel's amplitude at most), and
    # the channel set aside is named in the record's info with why.
    from negstiff.inference.record.reading import load

    path, data = labview_record
    rec = load(path, columns="base_acc=Accel,z=Laser")
    assert rec.n == data.shape[0]
    assert rec.fs == pytest.approx(FS, rel=1e-6)
    amp = np.abs(data).max(axis=0)
    assert np.abs(rec.u - data[:, 0]).max() <= 5e-7 * amp[0]
    assert np.abs(rec.z - data[:, 1]).max() <= 5e-7 * amp[1]
    assert "Temperature" in rec.info["set_aside"] and "1 sample" in rec.info["set_aside"]["Temperature"]


def test_a_wanted_channel_of_another_rate_is_refused_in_one_line(labview_record, tmp_path, capsys):
    # Fact: a channel logged once cannot be a column of a 512 Hz record; asking for it is bad input: exit 2 and
    # one line on stderr naming the file, the channel and why, and no output file.
    path, _ = labview_record
    out = tmp_path / "frf.json"
    code = main(["frf", str(path), "--columns", "base_acc=Accel,z=Temperature", "-o", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "Temperature" in err[0] and "bench.lvm" in err[0] and "1 sample" in err[0]
    assert not out.exists()


def _harmonic_in_well_record(path, seconds=4.0, forcing_hz=7.0, amp=1.0):
    """A harmonic shaker test of a symmetric double well (wells at +-10 mm, 9.2 Hz about each, 3 % damping):
    1 m/s^2 at 7 Hz keeps the mass in the upper well. The lab's laser vibrometer gives z_dot alone, so z is
    derived and its constant is unknown. CSV with ``# fs``, no time column."""
    fw, zeta, z_well = 9.2, 0.03, 0.01
    a_lin = (2 * np.pi * fw) ** 2 / 2  # K(z)/m = -a_lin z + b z^3 has wells at +-sqrt(a_lin / b), (2 pi fw)^2 there
    b = a_lin / z_well**2
    c = 2 * zeta * 2 * np.pi * fw
    settle = 4.0  # s: the start's transient decays as exp(-zeta 2 pi fw t), to 1e-3 in 4 s; not recorded
    n = int((settle + seconds) * FS)
    t = np.arange(n) / FS

    def acc(tt):
        return amp * np.sin(2 * np.pi * forcing_hz * tt)

    def rhs(tt, x):
        return [x[1], -acc(tt) - c * x[1] + a_lin * x[0] - b * x[0] ** 3]

    from scipy.integrate import solve_ivp

    sol = solve_ivp(rhs, (0, t[-1]), [z_well, 0.0], t_eval=t, rtol=1e-9, atol=1e-12)
    keep = t >= settle
    rows = np.column_stack([acc(t[keep]), sol.y[1][keep]])
    with open(path, "w") as fh:
        fh.write(f"# fs: {FS:g}\n# mass: 0.2\nbase_acc,z_dot\n")
        np.savetxt(fh, rows, delimiter=",", fmt="%.9g")
    return path


def test_a_harmonic_records_report_says_its_frame_plainly_and_what_else_can_be_done(tmp_path):
    # Fact: a harmonic record gives the characterisation alone; its report says so and names the records and
    # commands for the rest (identification from a broadband record, the map from a campaign). A z derived from a
    # vibrometer in one well has an unknown constant no physics pins: the summary says the frame is not pinned,
    # in a sentence (not "pinned by not pinned").
    from negstiff.report.record import report_records

    rec = _harmonic_in_well_record(tmp_path / "harmonic.csv")
    rep = report_records([rec], forcing_hz=7.0)
    _, summary = rep._composed()
    text = " ".join(summary)
    assert "by not pinned" not in text
    assert "frame (its unknown constant) is not pinned" in text
    assert "broadband" in text and "negstiff map" in text
    out = rep.write(tmp_path / "report")
    md = (out / "index.md").read_text()
    assert "What else the bench can give" in md and "negstiff identify" in md and "negstiff nfrc" in md
