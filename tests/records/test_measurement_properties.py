"""Property: whatever file a user hands the loader, it returns a Measurement or raises one
MeasurementError line; never another exception (hypothesis generates the files)."""

import io

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.io import savemat

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.record.reading import load
from negstiff.io.schema import KNOWN

NAMES = st.sampled_from([*KNOWN, "V1", "V2", "time", "", "meta", "fs", "mass"])
CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
    st.integers(-10, 10**6).map(str),
    st.sampled_from(["", "nan", "x", "1e400", "-", "1,2", '"3"', "0.000488281", "1e-3"]),
)
SETTINGS = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _outcome(path, **kw):
    try:
        m = load(path, **kw)
    except MeasurementError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(path) in msg or msg.startswith("column map"), msg
        return None
    assert isinstance(m, Measurement) and m.fs > 0 and np.all(np.isfinite(m.u))
    assert m.z is None or (m.z.shape == m.u.shape and np.all(np.isfinite(m.z)))
    return m


@SETTINGS
@given(
    meta=st.lists(st.tuples(st.sampled_from(["fs", "mass", "units", "x"]), CELLS), max_size=3),
    header=st.lists(NAMES, min_size=1, max_size=5),
    rows=st.lists(st.lists(CELLS, min_size=0, max_size=6), max_size=12),
    fs=st.one_of(st.none(), st.floats(-10, 1e4)),
    columns=st.one_of(st.none(), st.sampled_from(["force=V1,z=V2", "base_acc=V1*9.81,z_dot=V2", "z=V9", "bad"])),
)
def test_any_csv_gives_a_measurement_or_one_clear_line(tmp_path, meta, header, rows, fs, columns):
    text = "".join(f"# {k}: {v}\n" for k, v in meta) + ",".join(header) + "\n"
    text += "".join(",".join(r) + "\n" for r in rows)
    p = tmp_path / "h.csv"
    p.write_text(text)
    _outcome(p, fs=fs, columns=columns)


ARRAYS = st.lists(
    st.tuples(NAMES.filter(bool), st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=20)),
    max_size=5,
)


@SETTINGS
@given(arrays=ARRAYS, fs=st.one_of(st.none(), st.floats(0.1, 1e4)), as_mat=st.booleans(), single=st.booleans())
def test_any_npz_or_mat_gives_a_measurement_or_one_clear_line(tmp_path, arrays, fs, as_mat, single):
    data = {k: np.array(v, np.float32 if single else float) for k, v in arrays if k not in ("meta",)}
    if as_mat:
        p = tmp_path / "h.mat"
        buf = io.BytesIO()
        savemat(buf, {k: v for k, v in data.items() if k.isidentifier()})
        p.write_bytes(buf.getvalue())
    else:
        p = tmp_path / "h.npz"
        with open(p, "wb") as fh:
            np.savez(fh, **data)
    _outcome(p, fs=fs)


@pytest.mark.parametrize("blob", [b"", b"\x00\x01\x02", b"PK\x03\x04garbage", b"MATLAB 5.0 MAT-file garbage"])
@pytest.mark.parametrize("suffix", [".csv", ".npz", ".mat"])
def test_garbage_bytes_are_an_unreadable_file(tmp_path, blob, suffix):
    p = tmp_path / f"g{suffix}"
    p.write_bytes(blob)
    with pytest.raises(MeasurementError):
        load(p)


@SETTINGS
@given(
    response=st.sampled_from(["z", "z_dot", "y", "y_dot", "y_acc"]),
    extra=st.lists(st.sampled_from(["base_disp", "z_dot", "y"]), max_size=2, unique=True),
    n=st.integers(0, 40),
    step=st.floats(1e-4, 1.0),
    jitter=st.floats(0, 0.6),
    values=st.floats(-1e3, 1e3),
    decimals=st.integers(0, 9),
)
def test_nearly_valid_records_load_or_are_refused_cleanly(tmp_path, response, extra, n, step, jitter, values, decimals):
    rng = np.random.default_rng(n)
    t = np.arange(n) * step + jitter * step * rng.uniform(-1, 1, n)
    names = ["t", "base_acc", response, *[e for e in extra if e != response]]
    data = np.column_stack([t] + [values * rng.standard_normal(n) for _ in names[1:]]) if n else np.zeros((0, 4))
    p = tmp_path / "v.csv"
    p.write_text(",".join(names) + "\n" + "".join(",".join(f"{x:.{decimals}f}" for x in row) + "\n" for row in data))
    _outcome(p)


TIME_TOKENS = st.lists(
    st.one_of(
        st.floats(-1e7, 1e7, allow_nan=False).flatmap(
            lambda v: st.sampled_from(["%.0f", "%.3f", "%.9f", "%.6g", "%.12g", "%g", "%+.4f"]).map(lambda f: f % v)
        ),
        st.sampled_from(["0", "-0", ".5", "+.5", "5.", "00.100", "nan", "1e-3", '"0.5"', " 2.5", "0.000488281"]),
    ),
    min_size=1,
    max_size=30,
)


@settings(max_examples=300, deadline=None)
@given(tokens=TIME_TOKENS)
def test_the_bytes_route_reads_the_printed_digits_as_the_token_loop_does(tokens):
    """The time column's printed precision (decimals D, significant digits S) read on the tokens' bytes
    as one array is the per-token parse's, for every column it accepts (plain decimals); others go to
    the loop."""
    from negstiff.io.csv import _plain_decimal_digits, _printed_digits

    fast = _plain_decimal_digits(tokens)
    if fast is not None:
        assert fast == _printed_digits(tokens)
    plain = all(set(t) <= set("0123456789.+-") for t in tokens)
    assert (fast is not None) == plain
