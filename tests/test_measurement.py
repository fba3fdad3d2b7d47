"""Measurement files: the formats and the clear errors of contract.md."""

import numpy as np
import pytest

from negstiff.inference.measurement import MeasurementError, load, parse_column_map

SILVERBOX = "../shared/data/silverbox"


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


@pytest.mark.parametrize("fname", ["SNLS80mV.csv", "SNLS80mV.mat"])
def test_silverbox_loads_with_a_column_map(fname, request):
    path = request.config.rootpath / SILVERBOX / fname
    if not path.exists():
        pytest.skip("shared/ data not beside the repository")
    m = load(path, columns="force=V1,z=V2", fs=610.35)
    assert m.n == 131072 and m.input_name == "force" and m.mass is None


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
