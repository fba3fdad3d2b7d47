"""The lab's formats (UFF 58, TDMS, LVM): a record loads to the same Measurement as its CSV, files built
by the libraries themselves (and an LVM written as LabVIEW writes it) are read, and bad files are
refused in one line naming the file and the channel or record."""

import json

import numpy as np
import pytest

from negstiff.cli import main
from negstiff.errors import MeasurementError
from negstiff.inference.record.reading import load
from negstiff.models.device import SEED_LIKE_CUBIC
from negstiff.models.rig import Rig

FS = 512.0


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    d = tmp_path_factory.mktemp("formats")
    rec = Rig(SEED_LIKE_CUBIC, seed=4).random(duration=30, rms=20)
    for suffix in ("csv", "uff", "tdms"):
        rec.write(d / f"r.{suffix}")
    return rec, d


def _uff58(name, data, fs, unit="", func_type=1):
    """A type-58 dataset as pyuff prepares it (ASCII)."""
    import pyuff

    x = np.arange(np.size(data)) / fs
    zero = {f"{a}_{b}": 0 for a in ("orddenom", "z_axis") for b in ("spec_data_type", "len_unit_exp",
                                                                       "force_unit_exp", "temp_unit_exp")}  # fmt: skip
    return pyuff.prepare_58(
        binary=0, id1=name, func_type=func_type, rsp_node=1, rsp_dir=3, ref_node=0, ref_dir=0,
        data=np.asarray(data, float), x=x, ord_data_type=4, num_pts=x.size, abscissa_spacing=1, abscissa_min=0.0,
        abscissa_inc=1 / fs, abscissa_spec_data_type=17, abscissa_len_unit_exp=0, abscissa_force_unit_exp=0,
        abscissa_temp_unit_exp=0, abscissa_axis_units_lab="s", ordinate_spec_data_type=0, ordinate_len_unit_exp=0,
        ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0, ordinate_axis_units_lab=unit, orddenom_axis_units_lab="",
        z_axis_axis_units_lab="", z_axis_value=0.0, **zero,
    )  # fmt: skip


def _write_uff(path, sets):
    import pyuff

    u = pyuff.UFF(str(path))
    for i, s in enumerate(sets):
        u.write_sets(s, mode="overwrite" if i == 0 else "add")
    return path


def _write_lvm(path, names, data, dt, units):
    """A LabVIEW measurement file as LabVIEW's Write To Measurement File writes it (one segment, tab
    separated, one X column), written with plain Python: lvm_read cannot write."""
    n = len(names)
    head = ["LabVIEW Measurement\t", "Writer_Version\t2", "Reader_Version\t2", "Separator\tTab",
            "Decimal_Separator\t.", "Multi_Headings\tNo", "X_Columns\tOne", "Time_Pref\tRelative",
            "Operator\tlab", "Date\t2026/11/22", "Time\t10:00:00", "***End_of_Header***\t", ""]  # fmt: skip
    seg = [
        "Channels\t" + "\t".join([str(n)] * n),
        "Samples\t" + "\t".join([str(len(data))] * n),
        "Date\t" + "\t".join(["2026/11/22"] * n),
        "Time\t" + "\t".join(["10:00:00"] * n),
        "Y_Unit_Label\t" + "\t".join(units),
        "X_Dimension\t" + "\t".join(["Time"] * n),
        "X0\t" + "\t".join(["0.0000000000000000E+0"] * n),
        "Delta_X\t" + "\t".join([f"{dt:.16E}"] * n),
        "***End_of_Header***\t",
        "X_Value\t" + "\t".join(names) + "\tComment",
    ]
    rows = [f"{i * dt:.6f}\t" + "\t".join(f"{v:.9E}" for v in row) for i, row in enumerate(data)]
    path.write_text("\n".join(head + seg + rows) + "\n")
    return path


def test_uff_and_tdms_records_load_to_the_csv_measurement(record):
    # Fact: the same record in three formats is one measurement; the CSV prints 10 significant digits,
    # UFF and TDMS keep more, so the signals agree to the CSV's rounding (5e-10 relative)
    rec, d = record
    csv = load(d / "r.csv")
    for suffix in ("uff", "tdms"):
        m = load(d / f"r.{suffix}", mass=csv.mass)
        assert m.fs == pytest.approx(csv.fs, rel=1e-9) and m.fs == pytest.approx(FS, rel=1e-12)
        assert m.n == csv.n and m.input_name == csv.input_name
        for a, b in ((m.u, csv.u), (m.z, csv.z)):
            assert np.allclose(a, b, rtol=6e-10, atol=1e-15 + 6e-10 * np.abs(b).max())
        assert m.info["channels"]["base_acc"]["unit"] == "m/s^2" and m.info["channels"]["z"]["unit"] == "m"
    assert load(d / "r.tdms").mass == csv.mass, "the TDMS file keeps the record's metadata as properties"
    # LVM: the same record as LabVIEW writes it (9 significant digits: the format's precision)
    names = [k for k in rec.columns if k != "t"]
    lvm = _write_lvm(
        d / "r.lvm", names, np.column_stack([rec.columns[k] for k in names]), 1 / FS, ["m/s^2", "m", "m", "m"]
    )
    m = load(lvm, mass=csv.mass)
    assert m.fs == pytest.approx(csv.fs, rel=1e-6) and m.n == csv.n
    assert np.allclose(m.u, csv.u, rtol=1e-8, atol=1e-8 * np.abs(csv.u).max())
    assert np.allclose(m.z, csv.z, rtol=1e-8, atol=1e-8 * np.abs(csv.z).max())


def test_files_built_by_the_libraries_themselves_are_read(tmp_path):
    # pyuff's and npTDMS's own writers, a LabVIEW-style LVM, foreign channel names, a column map
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    rng = np.random.default_rng(1)
    acc, disp = rng.standard_normal(2048), 1e-3 * rng.standard_normal(2048)
    uff = _write_uff(
        tmp_path / "lab.uff", [_uff58("Table acc +Z", acc, 1024.0, "m/s^2"), _uff58("Laser", disp, 1024.0, "m")]
    )
    m = load(uff, columns="base_acc=Table acc +Z,z=Laser")
    assert m.fs == 1024.0 and np.allclose(m.u, acc, rtol=1e-9) and np.allclose(m.z, disp, rtol=1e-9)
    tdms = tmp_path / "lab.tdms"
    with TdmsWriter(str(tdms)) as w:
        step = 1 / 1024.0
        w.write_segment(
            [
                RootObject(),
                GroupObject("Untitled"),
                ChannelObject("Untitled", "AI0", acc / 9.81, properties={"wf_increment": step, "unit_string": "g"}),
                ChannelObject("Untitled", "AI1", disp, properties={"wf_increment": step, "unit_string": "m"}),
            ]
        )
    m = load(tdms, columns="base_acc=AI0*9.81,z=AI1")
    assert m.fs == pytest.approx(1024.0) and np.allclose(m.u, acc) and m.info["channels"]["AI0"]["unit"] == "g"
    unscaled = load(tdms, columns="base_acc=AI0,z=AI1")
    assert any("labelled 'g'" in w for w in unscaled.info["warnings"]), "a channel in g mapped without a scale"
    lvm = _write_lvm(tmp_path / "lab.lvm", ["Accel", "Disp"], np.column_stack([acc, disp]), 1 / 1024.0, ["m/s^2", "m"])
    m = load(lvm, columns="base_acc=Accel,z=Disp")
    assert (
        m.fs == pytest.approx(1024.0, rel=1e-6)
        and np.allclose(m.u, acc, rtol=1e-8)
        and np.allclose(m.z, disp, rtol=1e-8)
    )
    assert not list(tmp_path.glob("*.pkl")), "lvm_read's pickle cache must not be written beside an input"


@pytest.mark.parametrize(
    "kind, message",
    [
        ("uff_missing_channel", r"refers to 'Laser'.*\(columns: Table acc"),
        ("uff_not_time", r"record 2 \(H1\) holds a frequency response function .*not a time series"),
        ("uff_rates", r"channels acc and disp have different sampling rates"),
        ("uff_lengths", r"channels acc and disp have different lengths"),
        ("uff_garbage", r"unreadable Universal File|no UFF 58"),
        ("tdms_garbage", r"unreadable TDMS file"),
        ("tdms_lengths", r"channels a and b have different lengths"),
        ("lvm_garbage", r"unreadable LVM file"),
    ],
)
def test_bad_lab_files_give_one_line_naming_the_channel_or_record(tmp_path, kind, message):
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    x = np.sin(np.arange(256) / 5)
    cols = None
    if kind == "uff_missing_channel":
        p = _write_uff(tmp_path / "a.uff", [_uff58("Table acc", x, 512.0), _uff58("Disp", x, 512.0)])
        cols = "base_acc=Table acc,z=Laser"
    elif kind == "uff_not_time":
        p = _write_uff(tmp_path / "a.uff", [_uff58("acc", x, 512.0), _uff58("H1", x, 512.0, func_type=4)])
    elif kind == "uff_rates":
        p = _write_uff(tmp_path / "a.uff", [_uff58("acc", x, 512.0), _uff58("disp", x, 1024.0)])
    elif kind == "uff_lengths":
        p = _write_uff(tmp_path / "a.uff", [_uff58("acc", x, 512.0), _uff58("disp", x[:100], 512.0)])
    elif kind.endswith("garbage"):
        p = tmp_path / ("a." + kind.split("_")[0])
        p.write_text("this is not a measurement\n1 2 3\n")
    elif kind == "tdms_lengths":
        p = tmp_path / "a.tdms"
        with TdmsWriter(str(p)) as w:
            w.write_segment(
                [RootObject(), GroupObject("g"), ChannelObject("g", "a", x), ChannelObject("g", "b", x[:10])]
            )
    with pytest.raises(MeasurementError, match=message) as exc:
        load(p, columns=cols, fs=None if "uff" in kind else 512.0)
    assert "\n" not in str(exc.value) and str(p) in str(exc.value)


# UFF in the default suite; TDMS and LVM with -m slow (after load() the three share one road; each
# reader's own round trips run by default above)
@pytest.mark.parametrize(
    "suffix", ["uff", pytest.param("tdms", marks=pytest.mark.slow), pytest.param("lvm", marks=pytest.mark.slow)]
)
def test_contract_commands_run_on_lab_formats(record, suffix, tmp_path):
    # every reading command on the record as a UFF and as a TDMS file (a CLI run, as a user would)
    rec, d = record
    path = d / f"r.{suffix}"
    if suffix == "lvm":
        names = [k for k in rec.columns if k != "t"]
        data = np.column_stack([rec.columns[k] for k in names])
        path = _write_lvm(tmp_path / "r.lvm", names, data, 1 / FS, ["m/s^2", "m", "m", "m"])
    model = tmp_path / "m.json"
    model.write_text(json.dumps(SEED_LIKE_CUBIC.to_dict()))
    mass = ["--mass", "0.2"] if suffix in ("uff", "lvm") else []
    # --no-refine: what is tested is the format's road into each command (refinement: test_refine.py)
    runs = {
        "simulate": ["simulate", str(model), str(path), "-o", str(tmp_path / "s.csv")],
        "nsi": ["identify", "nsi", str(path), "-o", str(tmp_path / "n.json"), *mass, "--no-refine"],
        "sindy": ["identify", "sindy", str(path), "-o", str(tmp_path / "y.json"), *mass, "--no-refine"],
        "posterior": [
            "posterior",
            str(path),
            "-o",
            str(tmp_path / "p.json"),
            "--duration",
            "3",
            "--ensembles",
            "2",
            "--walkers",
            "16",
            "--max-steps",
            "200",
            *mass,
        ],  # fmt: skip
        "discrepancy": [
            "discrepancy",
            str(path),
            "-o",
            str(tmp_path / "d.json"),
            "--max-effects",
            "1",
            *mass,
            "--no-refine",
        ],
    }
    runs["frf"] = ["frf", str(path), "-o", str(tmp_path / "f.json")]
    harmonic = Rig(SEED_LIKE_CUBIC, seed=5).harmonic(9.0, 5.0, "plus", 20, 120)
    if suffix == "lvm":
        names = [k for k in harmonic.columns if k != "t"]
        h = _write_lvm(tmp_path / "h.lvm", names, np.column_stack([harmonic.columns[k] for k in names]), 1 / FS,
                       ["m/s^2", "m", "m", "m"])  # fmt: skip
    else:
        h = harmonic.write(tmp_path / f"h.{suffix}")
    runs["characterise"] = ["characterise", str(h), "--forcing-hz", "9", "-o", str(tmp_path / "c.json")]
    for name, argv in runs.items():
        assert main([*argv, "--quiet"]) == 0, name
    assert json.loads((tmp_path / "c.json").read_text())["period"] == 1
    r = json.loads((tmp_path / "n.json").read_text())
    for well in ("minus", "plus"):
        assert r["modal"][well]["f_hz"] == pytest.approx(SEED_LIKE_CUBIC.uls(well).f_hz, rel=0.02)
    assert r["record"]["channels"]["z"]["unit"] == "m"
