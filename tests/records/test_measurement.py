"""Measurement files: the formats and the clear errors of contract.md."""

import numpy as np
import pytest
import scipy.io

from negstiff.datasets import silverbox, silverbox_path
from negstiff.errors import MeasurementError
from negstiff.inference.record.reading import load
from negstiff.io.schema import parse_column_map


def _write(tmp_path, text, name="m.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_csv_with_metadata_and_time_column(tmp_path):
    p = _write(tmp_path, "# fs: 100\n# mass: 0.2\n# note: hello\nt,base_acc,z\n0,1,0.01\n0.01,2,0.02\n0.02,3,0.03\n")
    m = load(p)
    assert m.fs == pytest.approx(100) and m.mass == 0.2 and m.meta["note"] == "hello"
    assert np.array_equal(m.u, [1, 2, 3]) and m.input_name == "base_acc"


def test_column_map_with_scale_and_fs(tmp_path):
    p = _write(tmp_path, '"A","B",\n1,2,\n3,4,\n')
    m = load(p, columns="force=A*2,z=B", fs=50.0)
    assert np.array_equal(m.u, [2, 6]) and np.array_equal(m.z, [2, 4]) and m.fs == 50.0
    assert parse_column_map("base_acc=X1*9.81") == {"base_acc": ("X1", 9.81)}


@pytest.mark.parametrize("fmt", ["csv", "mat"])
def test_silverbox_loads_with_a_column_map(fmt, tmp_path):
    # The benchmark's two distributed files: the .mat shipped with the package, and its CSV written here in
    # the benchmark's own layout (a quoted header and a trailing empty column on every line)
    path = silverbox_path()
    if fmt == "csv":
        v = scipy.io.loadmat(path)
        path = tmp_path / "SNLS80mV.csv"
        rows = "".join(f"{a:.17g},{b:.17g},\n" for a, b in zip(v["V1"].ravel(), v["V2"].ravel(), strict=True))
        path.write_text('"V1","V2",\n' + rows)
    m = load(path, columns="force=V1,z=V2", fs=610.35)
    assert m.n == 131072 and m.input_name == "force" and m.mass is None
    shipped = silverbox()
    assert np.array_equal(m.u, shipped.u) and np.array_equal(m.z, shipped.z)


@pytest.mark.parametrize(
    "text, kwargs, message",
    [
        ("t,base_acc\n0,1\n0.1,2\n", {}, "missing column z"),
        ("t,z\n0,1\n0.1,2\n", {}, "no input column"),
        ("t,base_acc,force,z\n0,1,1,1\n0.1,2,2,2\n", {}, "two input columns"),
        ("t,base_acc,z\n0,1,1\n0.1,nan,2\n0.2,1,1\n", {}, "base_acc is NaN or inf at row 2"),
        ("t,base_acc,z\n0,1,1\n0.1,1,inf\n", {}, "z is NaN or inf at row 2"),
        ("t,base_acc,z\n0,1,1\n0.2,1,1\n0.1,1,1\n", {}, "not increasing at row 3"),
        ("t,base_acc,z\n0,1,1\n0.1,1,1\n0.25,1,1\n0.3,1,1\n", {}, "not uniformly sampled at row 3"),
        ("base_acc,z\n1,1\n2,2\n", {}, "no time base"),
        ("t,base_acc,z\n0,1,1\n0.1,x,1\n", {}, "row 2 .* is not numeric"),
        # a signal's empty cell below its first row is a lost sample, not a header value (those are first-row only)
        ("t,base_acc,z\n0,1,1\n0.1,,1\n0.2,1,1\n", {}, "row 2 .* is not numeric"),
        ("# fs: 10\nbase_acc,z,Fs\n1,1,20\n2,2,\n", {}, "fs is 10 in the header's '# fs:' line and 20 in column"),
        ("base_acc,z,Fs [kHz]\n1,1,0.4\n2,2,\n", {}, "column 'Fs' states the rate in 'kHz'"),
        ("t,base_acc,z\n0,1,1\n,1,1\n", {}, "row 2 .* is not numeric"),  # a contract column is never a header value
        ("a,b\n1,2\n", {"columns": "force=a,z=c", "fs": 10.0}, "refers to 'c'"),
        ("a,b\n1,2\n", {"columns": "forse=a,z=b", "fs": 10.0}, "not a measurement column"),
        ("t,base_acc,z\n", {}, "no data rows"),
    ],
)
def test_bad_files_give_one_clear_line(tmp_path, text, kwargs, message):
    p = _write(tmp_path, text)
    with pytest.raises(MeasurementError, match=message) as exc:
        load(p, **kwargs)
    assert str(p) in str(exc.value) or "column map" in str(exc.value)
    assert "\n" not in str(exc.value)


def test_a_benchmarks_csv_with_its_rate_on_the_first_row_is_read_as_written(tmp_path):
    # the F-16 ground vibration test benchmark's CSV layout (nonlinearbenchmark.org, Noel & Schoukens 2017): quoted
    # names, a trailing separator on every line, and its rate in a column "Fs" written on the first data row only
    # (empty below). The rate is read from it as a '# fs:' line would be; "Fs" is not a channel; every sample kept
    rng = np.random.default_rng(0)
    force, z = rng.standard_normal((2, 64))
    rows = [f"{f:.8g},{x:.8g},{'400' if k == 0 else ''}," for k, (f, x) in enumerate(zip(force, z, strict=True))]
    path = _write(tmp_path, '"Force","Displacement","Fs",\n' + "\n".join(rows) + "\n")
    rec = load(path, columns="force=Force,z=Displacement")
    assert rec.fs == 400.0 and rec.n == 64 and rec.input_name == "force"
    assert np.array_equal(rec.u, np.array([float(f"{f:.8g}") for f in force]))
    assert np.array_equal(rec.z, np.array([float(f"{x:.8g}") for x in z]))
    # the same rate said twice, as an integer and as a decimal, is one rate
    text = "# fs: 400\n" + '"Force","Displacement","Fs",\n' + "\n".join(rows).replace(",400,", ",400.0,") + "\n"
    both = _write(tmp_path, text, name="both.csv")
    assert load(both, columns="force=Force,z=Displacement").fs == 400.0


def test_unreadable_files(tmp_path):
    (tmp_path / "bin.csv").write_bytes(b"\x89PNG\x00\xff\xfe")
    (tmp_path / "bad.mat").write_bytes(b"not a mat file at all")
    (tmp_path / "x.xlsx").write_text("")
    for name, msg in (
        ("bin.csv", "unreadable"),
        ("bad.mat", "unreadable"),
        ("x.xlsx", "unknown file type"),
        ("missing.csv", "no such file"),
    ):
        with pytest.raises(MeasurementError, match=msg):
            load(tmp_path / name)


def test_too_few_samples_for_an_analysis(tmp_path):
    m = load(_write(tmp_path, "t,base_acc,z\n0,1,1\n0.1,1,1\n"))
    with pytest.raises(MeasurementError, match="too few samples for NSI: 2"):
        m.require(1000, "NSI")


# --- lab exports: time columns rounded to their printed precision (issue: real 2048 Hz records) -----


def _lab_csv(tmp_path, t_text, n, name="lab.csv"):
    """A lab-style export written with plain numpy: time printed by the lab's format, a response."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal(n)
    z = 0.01 * rng.standard_normal(n)
    lines = ["t,base_acc,z"] + [f"{tt},{uu:.6f},{zz:.8f}" for tt, uu, zz in zip(t_text, u, z, strict=False)]
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


@pytest.mark.parametrize("fmt", ["%.9g", "%.5f", "%.6f"])
def test_time_rounded_as_labs_export_it_is_uniform(tmp_path, fmt):
    # Fact: a 2048 Hz clock printed with 9 significant digits or 5-6 fixed decimals deviates from its
    # grid only by half a printed unit (at 120 s, %.9g keeps 1e-6 s: 0.2 % of the step; 5 decimals
    # 5e-6 s: 1 % of it); the mean step is the clock's.
    fs, n = 2048.0, 2048 * 120
    t = np.arange(n) / fs
    p = _lab_csv(tmp_path, [fmt % x for x in t], n)
    m = load(p)
    assert m.fs == pytest.approx(fs, rel=1e-9)
    # ... plus the fitted grid's own error, ~resolution / sqrt(n) (n = 245760): far below 1e-3 of a unit
    assert m.info["time"]["jitter_s"] <= 0.5 * m.info["time"]["resolution_s"] * (1 + 1e-3)


def test_a_records_time_base_is_the_same_whatever_the_callers_blas_threads(tmp_path):
    # Fact: reading a file is arithmetic, not a function of the process's thread pools. The clock's step is a
    # least-squares slope over every sample (a dot product), and OpenBLAS splits a long one over its threads, adding
    # the parts in another order: a script (two BLAS threads) read 511.99999999997783 Hz where the command (one)
    # read 511.9999999999777, and a structure's k3 then differed by 4.5e-9 between them (measured). The loader now
    # runs its linear algebra on the estimators' fixed thread count: the same bits from either
    from threadpoolctl import threadpool_limits

    fs, n = 512.0, 512 * 30  # the measured case: 30 s at 512 Hz, printed to 10 digits (larger n rounded alike)
    p = _lab_csv(tmp_path, [f"{x:.10g}" for x in np.arange(n) / fs], n)
    with threadpool_limits(limits=1, user_api="blas"):
        one = load(p)
    with threadpool_limits(limits=2, user_api="blas"):
        two = load(p)
    assert one.fs == two.fs and one.info["time"] == two.info["time"]  # the same computation: the same bits


def test_a_real_gap_is_named_at_its_row(tmp_path):
    # Fact: 100 samples missing after row 1001 is a gap, not rounding; the first bad row is 1002.
    fs = 2048.0
    t = np.arange(5000) / fs
    t = np.concatenate([t[:1001], t[1101:]])
    p = _lab_csv(tmp_path, [f"{x:.9g}" for x in t], t.size)
    with pytest.raises(MeasurementError, match=r"not uniformly sampled at row 1002 .*gap"):
        load(p)


def test_a_gap_in_a_coarsely_printed_time_column_is_named_at_its_row(tmp_path):
    # Fact: printed with one decimal at a 0.1 s step, rounding alone moves a step by up to a unit, as
    # much as the step; a step of three steps is still a gap (it was reported as a drifting clock at
    # row 1 when the rounding bound alone decided)
    t = [0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.8, 0.9, 1.0, 1.1]
    p = tmp_path / "coarse.csv"
    p.write_text("t,base_acc,z\n" + "".join(f"{x:g},1,0.02\n" for x in t))
    with pytest.raises(MeasurementError, match=r"not uniformly sampled at row 7 .*gap"):
        load(p)


def test_a_repeated_block_is_named_at_its_row(tmp_path):
    t = np.arange(3000) / 512.0
    t = np.concatenate([t[:2000], t[1900:2000], t[2000:]])  # the export wrote 100 rows twice
    p = _lab_csv(tmp_path, [f"{x:.6f}" for x in t], t.size)
    with pytest.raises(MeasurementError, match="not increasing at row 2001"):
        load(p)


def test_fs_replaces_a_broken_time_column(tmp_path):
    t = np.arange(3000) / 512.0
    t[1500:] += 0.1  # a clock jump the user knows about
    p = _lab_csv(tmp_path, [f"{x:.6f}" for x in t], t.size)
    with pytest.raises(MeasurementError, match="row 1501"):
        load(p)
    m = load(p, fs=512.0)
    assert m.fs == 512.0 and "replaces column t" in m.info["time"]["source"]


def test_an_input_only_record_loads_for_simulation(tmp_path):
    p = _write(tmp_path, "t,base_acc\n0,1\n0.01,2\n0.02,3\n")
    m = load(p, response=False)
    assert m.z is None and m.n == 3
    with pytest.raises(MeasurementError, match="missing column z"):
        load(p)


def _record(n=400, fs=200.0, seed=3):
    """Columns of a record written here: a 5 Hz lightly damped oscillator (scipy's lsim, not the rig)
    under a random base acceleration, as t [s], base_acc [m/s^2], z [m]."""
    from scipy import signal

    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    u = rng.standard_normal(n)
    wn = 2 * np.pi * 5.0
    _, z, _ = signal.lsim(([-1.0], [1.0, 2 * 0.05 * wn, wn**2]), u, t)
    return {"t": t, "base_acc": u, "z": z}


def _rows(cols, fmt="{:.9g}"):
    return [[fmt.format(v) for v in row] for row in zip(*cols.values(), strict=False)]


@pytest.mark.parametrize(
    "dialect",
    ["semicolon, decimal comma", "tab", "blanks", "byte-order mark, CRLF", "Latin-1 header", "comma and blank"],
)
def test_spreadsheet_and_daq_dialects_read_the_same_record(tmp_path, dialect):
    # Lab exports: a spreadsheet where the decimal mark is a comma separates fields by ';', DAQ software
    # writes tabs or blanks, Excel's UTF-8 CSV starts with a byte-order mark and ends lines with CRLF,
    # older Windows tools write Latin-1. Each reads to the same record as the contract's comma file
    # (the values printed to 9 digits: equal to 1e-9).
    cols = _record()
    ref = load(_write(tmp_path, "t,base_acc,z\n" + "".join(",".join(r) + "\n" for r in _rows(cols)), "ref.csv"))
    rows = _rows(cols)
    if dialect == "semicolon, decimal comma":
        text = "t;base_acc;z\n" + "".join(";".join(v.replace(".", ",") for v in r) + "\n" for r in rows)
    elif dialect == "tab":
        text = "t\tbase_acc\tz\n" + "".join("\t".join(r) + "\n" for r in rows)
    elif dialect == "blanks":
        text = "   t   base_acc   z\n" + "".join("  " + "   ".join(r) + "\n" for r in rows)
    elif dialect == "comma and blank":
        text = "t, base_acc, z\n" + "".join(", ".join(r) + "\n" for r in rows)
    else:
        text = "t,base_acc,z\r\n" + "".join(",".join(r) + "\r\n" for r in rows)
    p = tmp_path / "lab.csv"
    if dialect == "byte-order mark, CRLF":
        p.write_bytes(text.encode("utf-8-sig"))
    elif dialect == "Latin-1 header":
        p.write_bytes(("# operator: Müller, sensor µ-range\n" + text).encode("latin-1"))
    else:
        p.write_text(text)
    m = load(p)
    assert m.fs == pytest.approx(ref.fs, rel=1e-9) and m.input_name == "base_acc"
    assert np.allclose(m.u, ref.u, rtol=1e-9, atol=0) and np.allclose(m.z, ref.z, rtol=1e-9, atol=0)


def test_units_in_the_header_are_read_into_si(tmp_path):
    # A DAQ export labels its channels: time in ms, the table's acceleration in g, the laser in mm. Each
    # is converted to SI by its label (g as standard gravity, 9.80665 m/s^2), never read as if in SI; the
    # record says what was converted. The same data in SI is the reference.
    cols = _record()
    si = "t [s],base_acc [m/s^2],z [m]\n" + "".join(",".join(r) + "\n" for r in _rows(cols))
    ref = load(_write(tmp_path, si, "si.csv"))
    lab_cols = {"t": cols["t"] * 1e3, "base_acc": cols["base_acc"] / 9.80665, "z": cols["z"] * 1e3}
    text = "t (ms),base_acc [g],z [mm]\n" + "".join(",".join(r) + "\n" for r in _rows(lab_cols))
    m = load(_write(tmp_path, text, "lab.csv"))
    assert m.fs == pytest.approx(ref.fs, rel=1e-9)
    assert np.allclose(m.u, ref.u, rtol=1e-8, atol=0) and np.allclose(m.z, ref.z, rtol=1e-8, atol=0)
    ch = m.info["channels"]
    assert ch["z"]["to_si"] == pytest.approx(1e-3) and ch["base_acc"]["to_si"] == pytest.approx(9.80665)
    assert "to_si" not in ref.info["channels"]["z"], "SI labels: nothing converted"
    # a mapped channel is the user's to scale: its label only warns when the map does not scale it
    # (a map may name a column by the header's whole text, unit and all: 'time [s]')
    mapped = load(_write(tmp_path, "time [s],acc [g],disp [mm]\n0,1,1\n0.01,2,2\n0.02,3,3\n", "m.csv"),
                  columns="t=time [s],base_acc=acc*9.80665,z=disp")  # fmt: skip
    assert np.allclose(mapped.z, [1, 2, 3]) and np.allclose(mapped.u, 9.80665 * np.array([1, 2, 3]))
    assert mapped.info["warnings"] == [
        "channel disp (z) is labelled 'mm' in the file, not SI (scale it: --columns z=disp*0.001)",
        # and what the unscaled record says by itself, said when it is read
        "z spans 2 m: is the record in mm? negstiff reads SI units (m); scale the column in the map, e.g. "
        "--columns z=COL*0.001",
    ]


@pytest.mark.parametrize(
    "header, message",
    [
        ("t,base_acc,z [m/s]", "column z is labelled 'm/s': a length is expected, in m, cm, mm, um, in"),
        ("t,base_acc,z [V]", "column z is labelled 'V': a sensor's raw output: scale it to SI with its sensitivity"),
        ("t,base_acc [furlong/fortnight],z", "column base_acc is labelled 'furlong/fortnight'"),
    ],
)
def test_a_unit_that_is_not_of_the_columns_dimension_is_refused(tmp_path, header, message):
    p = _write(tmp_path, header + "\n0,1,1\n0.1,2,2\n0.2,3,3\n")
    with pytest.raises(MeasurementError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load(p)


def test_mixed_decimal_marks_are_refused(tmp_path):
    p = _write(tmp_path, "t;base_acc;z\n0,0;1.5;1\n0,1;2;2\n")
    with pytest.raises(MeasurementError, match="mixes decimal points and commas"):
        load(p)


@pytest.mark.parametrize(
    "label, column, factor",
    [
        ("m/s²", "base_acc", 1.0),
        ("m/sec^2", "base_acc", 1.0),
        ("m s^-2", "y_acc", 1.0),
        ("g", "base_acc", 9.80665),
        ("meters", "z", 1.0),
        ("µm", "y", 1e-6),
        ("mm/s", "z_dot", 1e-3),
        ("Newtons", "force", 1.0),
        ("kN", "force", 1e3),
        ("ms", "t", 1e-3),
        ("m/s", "z", None),
        ("N", "base_acc", None),
    ],
)
def test_unit_labels_as_exports_spell_them(label, column, factor):
    from negstiff.io.schema import si_factor

    assert si_factor(label, column) == (None if factor is None else pytest.approx(factor))


def test_a_comma_in_a_header_name_does_not_make_a_tab_file_comma_separated(tmp_path):
    p = _write(tmp_path, "t\tbase_acc\tz\tlaser, raw\n0\t1\t0.5\t7\n0.1\t2\t0.25\t7\n0.2\t3\t0.125\t7\n")
    m = load(p)
    assert np.allclose(m.u, [1, 2, 3]) and m.fs == pytest.approx(10.0)


def test_silverbox_override_and_its_clear_error(tmp_path, monkeypatch):
    # NEGSTIFF_SILVERBOX replaces the shipped copy; naming no file is one clear line, not a silent fallback
    from negstiff import InputError

    copy = tmp_path / "SNLS80mV.mat"
    copy.write_bytes(silverbox_path().read_bytes())
    monkeypatch.setenv("NEGSTIFF_SILVERBOX", str(copy))
    assert silverbox_path() == copy and silverbox().n == 131072
    monkeypatch.setenv("NEGSTIFF_SILVERBOX", str(tmp_path / "missing.mat"))
    with pytest.raises(InputError, match="NEGSTIFF_SILVERBOX=.*is not a file"):
        silverbox()


def test_the_response_checks_coherence_is_scipys():
    # the coherence the response check reads (``derivatives.coherence``, the segments as one matrix) is scipy's
    # with its defaults: a lagged, filtered and noisy copy of a random input, an offset on the response, lengths
    # that leave a partial last segment; rounding alone apart (1e-12: products of unit-scale spectra)
    from scipy import signal

    from negstiff.inference.record.derivatives import coherence

    rng = np.random.default_rng(4)
    for n, fs in ((153_600, 512.0), (40_001, 1000.0), (5000, 100.0)):
        u = rng.standard_normal(n)
        z = 1e-3 * (np.convolve(u, np.hanning(9), "same") + 0.5 * rng.standard_normal(n)) + 0.02
        nper = int(min(n // 16, round(fs)))
        f_ref, c_ref = signal.coherence(u, z, fs=fs, nperseg=nper)
        f, c = coherence(u, z, fs, nper)
        assert np.array_equal(f, f_ref) and c.shape == c_ref.shape
        assert np.max(np.abs(c - c_ref)) < 1e-12
