"""The law records (``law_records.py``) checked as records: the laws are what their docstrings say (wells, frequencies,
damping ratios, shapes), the true motion obeys its law, each run is the kind it claims (chaos, in-well, cross-well),
each sensor chain reads the truth as stated (gains, zeros, drifts, noise) and the frame relation holds. Nothing here
identifies anything: negstiff only reads the files (and gives the rod-frame law to compare with)."""

import math
from dataclasses import replace

import numpy as np
import pytest
from law_records import (
    LDV_NOISE,
    LDV_OFFSET,
    LDV_WANDER,
    WRITERS,
    equilibria,
    magnet_in_well_arrays,
    magnet_law,
    oblique_springs_law,
    rod_frame_law,
    septic_arrays,
    septic_law,
)
from scipy.integrate import cumulative_simpson, simpson


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    """Every writer's record at its defaults, written once."""
    directory = tmp_path_factory.mktemp("law_records")
    return {name: write(directory) for name, write in WRITERS.items()}


def columns(path):
    """The CSV's columns by name, read with plain numpy (the metadata lines skipped)."""
    lines = path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    data = np.loadtxt(lines[k + 1 :], delimiter=",")
    return {name: data[:, i] for i, name in enumerate(lines[k].split(","))}


def hops(z, wells):
    """Well-to-well transitions: z passing from below half the minus well to above half the plus well or back."""
    side = np.where(z < wells["minus"] / 2, -1, np.where(z > wells["plus"] / 2, 1, 0))
    side = side[side != 0]
    return int(np.sum(side[1:] != side[:-1]))


LAWS = {"magnet": magnet_law, "oblique_springs": oblique_springs_law, "septic": septic_law, "rod_frame": rod_frame_law}


@pytest.mark.parametrize("name", LAWS)
def test_each_law_is_the_derivative_of_its_potential(name):
    """K = dU/dz and K' = dK/dz over the law's range, by central differences (their error, h^2 / 6 of the third
    derivative, is below 1e-6 of the force's range at h = 1 um)."""
    law = LAWS[name]()
    z = np.linspace(0.9 * law.search[0], 0.9 * law.search[1], 401)
    h = 1e-6
    force, stiffness = law.force(z), law.stiffness(z)
    scale_f, scale_k = np.ptp(force), np.ptp(stiffness)
    assert np.max(np.abs((law.potential(z + h) - law.potential(z - h)) / (2 * h) - force)) < 1e-6 * scale_f
    assert np.max(np.abs((law.force(z + h) - law.force(z - h)) / (2 * h) - stiffness)) < 1e-6 * scale_k
    assert law.potential(0.0) == pytest.approx(0.0, abs=1e-15)


def test_magnet_law_as_stated():
    """Wells near +-14 mm, a little asymmetric by the tilt, their underlying-linear frequencies about 9.0 Hz, a gap
    d of 15-25 mm, 2-5 % damping; the barrier unstable; the magnetic part is a point-dipole pair's repulsion."""
    law = magnet_law()
    p = law.params
    assert 0.015 <= p["d"] <= 0.025
    eq = equilibria(law)
    assert -0.0155 < eq["minus"] < -0.013 and 0.013 < eq["plus"] < 0.0155
    assert 0.3e-3 < abs(eq["minus"]) - eq["plus"] < 1.0e-3  # the tilt's asymmetry: 0.63 mm
    assert law.stiffness(eq["barrier"]) < 0
    for well in ("minus", "plus"):
        assert abs(law.force(eq[well])) < 1e-9 * np.ptp(law.force(np.linspace(-0.03, 0.03, 61)))
        assert math.sqrt(law.stiffness(eq[well])) / (2 * math.pi) == pytest.approx(9.0, abs=0.1)
    # the magnets' force is the gradient of A / r^3, r the distance between the dipoles (d across, z along)
    z = np.linspace(-0.04, 0.04, 81)
    r = np.hypot(p["d"], z)
    h = 1e-7
    dU = (p["A"] / np.hypot(p["d"], z + h) ** 3 - p["A"] / np.hypot(p["d"], z - h) ** 3) / (2 * h)
    assert np.allclose(law.force(z) - p["k"] * z - p["t0"], dU, rtol=1e-6, atol=1e-9 * p["A"] / p["d"] ** 4)
    assert np.all((law.force(z) - p["k"] * z - p["t0"]) * z <= 0)  # repulsion: it pushes the tip off the centre
    assert np.allclose(r, np.sqrt(p["d"] ** 2 + z**2))


def test_oblique_springs_law_as_stated():
    """One well at 0, 2-4 Hz at small amplitude, stiffening more than tenfold by 25 mm (and K' > 0 everywhere:
    no second well); the force is the springs' own: k_v z plus two springs of free length L0 stretched to
    sqrt(a^2 + z^2), their force along the motion k_o (L - L0) z / L each."""
    law = oblique_springs_law()
    p = law.params
    eq = equilibria(law)
    assert set(eq) == {"plus"} and abs(eq["plus"]) < 1e-12
    assert 2.0 < math.sqrt(law.stiffness(0.0)) / (2 * math.pi) < 4.0
    z = np.linspace(-0.06, 0.06, 1201)
    assert np.all(law.stiffness(z) > 0)
    assert min(law.stiffness(-0.025), law.stiffness(0.025)) > 10 * law.stiffness(0.0)
    length = np.hypot(p["a"], z)
    assert np.allclose(law.force(z), p["k_v"] * z + p["k_o2"] * (length - p["L0"]) * z / length, rtol=1e-12, atol=1e-12)


def test_septic_law_as_stated():
    """A polynomial of order 7 with its top coefficient positive, three real roots (two wells 10-25 mm from the
    origin, 6-15 Hz, and the barrier between), and its monomial coefficients in ``params`` reproduce it."""
    law = septic_law()
    k = [law.params[f"k{j}"] for j in range(8)]
    assert "k8" not in law.params and k[7] > 0
    z = np.linspace(-0.05, 0.05, 201)
    assert np.allclose(np.polynomial.polynomial.polyval(z, k), law.force(z), rtol=1e-12, atol=1e-9)
    roots = np.roots(k[::-1])
    assert np.sum(np.abs(roots.imag) < 1e-12) == 3
    eq = equilibria(law)
    for well in ("minus", "plus"):
        assert 0.010 <= abs(eq[well]) <= 0.025
        assert 6.0 < math.sqrt(law.stiffness(eq[well])) / (2 * math.pi) < 15.0
    assert eq["minus"] < eq["barrier"] < eq["plus"] and law.stiffness(eq["barrier"]) < 0


def test_rod_frame_law_is_the_as_built_device():
    """The re-implemented geometric law equals negstiff's as-built device's restoring force and stiffness (per unit
    mass) within 1e-9 over the stroke the geometry allows, with the same wells and frequencies (11.45 / 9.20 Hz)."""
    from negstiff.models.device import AS_BUILT

    law = rod_frame_law()
    lo, hi = AS_BUILT.stroke_limits()
    z = np.linspace(0.98 * lo, 0.98 * hi, 2001)
    force = AS_BUILT.restoring_force(z) / AS_BUILT.m
    assert np.max(np.abs(law.force(z) - force)) < 1e-9 * np.max(np.abs(force))
    stiffness = AS_BUILT.stiffness(z) / AS_BUILT.m
    assert np.max(np.abs(law.stiffness(z) - stiffness)) < 1e-9 * np.max(np.abs(stiffness))
    eq, theirs = equilibria(law), AS_BUILT.equilibria()
    assert eq["minus"] == pytest.approx(theirs.z_minus, abs=1e-9)
    assert eq["plus"] == pytest.approx(theirs.z_plus, abs=1e-9)
    assert math.sqrt(law.stiffness(eq["minus"])) / (2 * math.pi) == pytest.approx(11.45, abs=0.01)
    assert math.sqrt(law.stiffness(eq["plus"])) / (2 * math.pi) == pytest.approx(9.20, abs=0.01)


def momentum_residual(truth, window_s=0.125, step=1):
    """rms over windows of z'(t1) - z'(t0) + integral of (D(z') + K(z) + b'') / m (Simpson's rule on every
    ``step``-th sample), relative to the rms of z'(t1) - z'(t0): the weak form of the equation of motion."""
    z, v, u = truth.z[::step], truth.z_dot[::step], truth.base_acc[::step]
    fs = truth.fs / step
    w = 2 * int(window_s * fs / 2)
    acc = -(truth.damping(v) + truth.force(z) + u)
    n = (z.size - 1) // w
    change = np.array([v[(i + 1) * w] - v[i * w] for i in range(n)])
    integral = np.array([simpson(acc[i * w : (i + 1) * w + 1], dx=1 / fs) for i in range(n)])
    return float(np.sqrt(np.mean((change - integral) ** 2) / np.mean(change**2)))


@pytest.mark.parametrize("name", WRITERS)
def test_the_true_motion_obeys_its_law(records, name):
    """The true z, z' and b'' satisfy m z'' + D(z') + K(z) = -m b'' with the truth's own force and damping: in weak
    form over 1/8 s windows (measured 2e-7 ... 3e-4 of the velocity's change, the largest at 256 Hz) the residual
    is below 1e-3, where a force 1 % off leaves 1e-2; and it is Simpson's error, not the law's: on every other
    sample it grows (15-16 times where Simpson's h^4 rules, more on the 256 Hz record). Energy balances too: the
    change of z'^2 / 2 + U(z) is the work of the input and the damping within 1e-4 of the input's gross work."""
    truth = records[name].truth
    residual = momentum_residual(truth)
    assert residual < 1e-3, residual
    assert momentum_residual(truth, step=2) > 8 * residual
    assert momentum_residual(replace(truth, force=lambda z: 1.01 * truth.force(z))) > 5e-3
    v = truth.z_dot
    energy = 0.5 * v**2 + truth.potential(truth.z)
    work = cumulative_simpson(-(truth.damping(v) + truth.base_acc) * v, dx=1 / truth.fs, initial=0.0)
    gross = simpson(np.abs(truth.base_acc * v), dx=1 / truth.fs)
    assert np.max(np.abs(energy - energy[0] - work)) < 1e-4 * gross


def test_each_truth_states_its_wells_frequencies_damping_and_stroke(records):
    """The truth's numbers are the law's: K(well) = 0 with K' > 0, f = sqrt(K') / 2 pi, zeta = c / (2 omega) (the
    quadratic damping has no linear part), the stroke the true z's 0.5 / 99.5 % quantiles; the damping ratios
    are the stated ones (magnet 3.0 %, QZS 5.0 %, septic 4.0 / 3.6 %, rod frame 4.9 / 6.1 % as negstiff's rig)."""
    zetas = {"magnet_chaos": (0.029, 0.031), "oblique_springs": (0.049, 0.051), "septic": (0.035, 0.041),
             "rod_frame": (0.048, 0.062)}  # fmt: skip
    zetas["magnet_in_well"] = zetas["magnet_chaos"]
    for name, rec in records.items():
        truth = rec.truth
        for well, z in truth.wells.items():
            assert abs(truth.force(z)) < 1e-9 * max(1.0, np.max(np.abs(truth.force(truth.z)))), name
            omega = 2 * math.pi * truth.f_hz[well]
            assert omega**2 == pytest.approx(truth.stiffness(z), rel=1e-12), name
            assert truth.zeta[well] == pytest.approx(truth.c / (2 * omega), rel=1e-12), name
            assert zetas[name][0] <= truth.zeta[well] <= zetas[name][1], (name, well, truth.zeta[well])
        assert truth.stroke == pytest.approx(tuple(np.quantile(truth.z, [0.005, 0.995])))
        assert truth.damping(np.array([0.1])) == pytest.approx(truth.c * 0.1 + truth.c_nl * 0.01)


def test_the_chaos_record_is_chaotic_and_cross_well(records):
    """8 Hz, 8 m/s^2 from rest in the plus well: the tip hops between the wells hundreds of times (397 measured in
    120 s), stays in each about half the time, peaks near +-27 mm, and its Poincare section (z once per forcing
    period, past the first 20 s) does not repeat (706 of 800 points distinct at 0.01 mm measured; a periodic
    orbit gives a handful)."""
    truth = records["magnet_chaos"].truth
    z = truth.z
    assert z[0] == truth.wells["plus"] and truth.z_dot[0] == 0.0  # the shaker switched on: a transient at the start
    assert hops(z, truth.wells) > 250
    assert 0.35 < np.mean(z > truth.barrier) < 0.65
    assert 0.024 < -z.min() < 0.030 and 0.024 < z.max() < 0.030
    section = z[int(20 * truth.fs) :: int(truth.fs / 8.0)]
    assert len(np.unique(np.round(section / 1e-5))) > 0.8 * section.size


def test_the_in_well_record_stays_in_its_well_and_reaches_its_nonlinear_range(records):
    """The random run never leaves the plus well (8.1 mm its lowest point, the barrier at 0.3 mm) and reaches where
    the stiffness has fallen to under half the well's (0.29 measured), from a start 3 mm off the well."""
    truth = records["magnet_in_well"].truth
    z = truth.z
    assert z[0] == pytest.approx(truth.wells["plus"] + 0.003)
    assert z.min() > truth.barrier + 0.005
    assert truth.stiffness(z.min()) < 0.5 * truth.stiffness(truth.wells["plus"])
    assert hops(z, truth.wells) == 0


def test_the_random_runs_are_what_they_claim(records):
    """The QZS run reaches its hardening (+-21 mm, the stiffness there 12.9 times the well's); the septic and rod-frame
    runs are cross-well (105 and 26 hops measured) over their nonlinear tails."""
    qzs = records["oblique_springs"].truth
    assert min(-qzs.stroke[0], qzs.stroke[1]) > 0.018
    assert min(qzs.stiffness(np.array(qzs.stroke))) > 8 * qzs.stiffness(0.0)
    for name, least in (("septic", 50), ("rod_frame", 10)):
        truth = records[name].truth
        assert hops(truth.z, truth.wells) > least, name
        assert truth.stroke[0] < truth.wells["minus"] and truth.stroke[1] > truth.wells["plus"], name


@pytest.mark.parametrize("name", ["magnet_chaos", "magnet_in_well"])
def test_the_vibrometer_reads_the_absolute_velocity_and_its_integral_drifts(records, name):
    """The vibrometer's volts times its gain are z' + b' with the zero's offset, its wander and its noise: mean and
    rms within the noise's own scatter; integrated, its error drifts by offset x duration (24 mm in 120 s, more than
    half the distance between the wells; 12 mm in 60 s, more than the in-well run's whole stroke) within what the
    wander integrates to. The table's accelerometer reads b'' in g with its noise."""
    rec = records[name]
    truth = rec.truth
    data = columns(rec.path)
    n = truth.z.size
    error = data["ldv"] * truth.gain - truth.z_dot - truth.sensor["base_velocity"]
    assert rec.columns == "base_acc=acc*9.80665,y_dot=ldv*?" and rec.load_kwargs == {"gravity": 0.0}
    assert np.mean(error) == pytest.approx(LDV_OFFSET, abs=5 * LDV_NOISE / math.sqrt(n))
    assert np.std(error) == pytest.approx(math.hypot(LDV_NOISE, LDV_WANDER), rel=0.03)
    drift = np.sum(error) / truth.fs
    duration = n / truth.fs
    assert drift == pytest.approx(LDV_OFFSET * duration, abs=2e-3)
    assert abs(drift) > (
        0.5 * (truth.wells["plus"] - truth.wells["minus"]) if name == "magnet_chaos" else np.ptp(truth.z)
    )
    acc_error = data["acc"] * 9.80665 - truth.base_acc
    assert np.std(acc_error) == pytest.approx(0.002 * 9.80665, rel=0.03)
    assert truth.frame_offset is None and truth.gain == 0.1
    meta = dict(line[2:].split(": ") for line in rec.path.read_text().splitlines()[:6] if line.startswith("# "))
    if name == "magnet_in_well":  # the rest the lab measured statically, to 0.1 mm: what pins an in-well frame
        assert float(meta["z_rest"]) == pytest.approx(truth.wells["plus"], abs=0.05e-3)
    else:  # a cross-well record without gravity is pinned by its wells' symmetry
        assert "z_rest" not in meta and meta["gravity"] == "0"


def test_each_displacement_and_velocity_sensor_reads_the_truth_in_its_frame(records):
    """The septic laser (mm) reads z plus its zero, 3.7 mm (the truth's frame offset), with 20 um noise; the rod-frame
    rig's z = y - base_disp is the true z (frame offset 0) within the laser's noise and the double integral's error
    (6 um measured); the QZS sensor reads z' in mm/s with its zero (20 um/s) and noise, and its file states the
    well's rest (0) that pins the integral's frame."""
    septic = records["septic"]
    error = columns(septic.path)["laser"] * 1e-3 - septic.truth.z
    assert np.mean(error) == pytest.approx(septic.truth.frame_offset, abs=5 * 2e-5 / math.sqrt(error.size))
    assert np.std(error) == pytest.approx(2e-5, rel=0.05)
    rod = records["rod_frame"]
    data = columns(rod.path)
    assert np.allclose(data["z"], data["y"] - data["base_disp"], atol=1e-9)
    error = data["z"] - rod.truth.z
    assert rod.truth.frame_offset == 0.0 and abs(np.mean(error)) < 5e-6
    assert np.std(error) == pytest.approx(math.hypot(30e-6, np.std(rod.truth.sensor["base_disp_error"])), rel=0.05)
    assert np.std(rod.truth.sensor["base_disp_error"]) < 0.3 * 30e-6
    qzs = records["oblique_springs"]
    assert "# z_rest: 0\n" in qzs.path.read_text()[:200] and qzs.truth.wells["plus"] == pytest.approx(0.0, abs=1e-12)
    error = columns(qzs.path)["vrel"] * 1e-3 - qzs.truth.z_dot
    assert np.mean(error) == pytest.approx(qzs.truth.sensor["offset_m_s"], abs=5 * 2e-4 / math.sqrt(error.size))
    assert np.std(error) == pytest.approx(2e-4, rel=0.05)


def test_a_writer_is_deterministic(tmp_path):
    """The same seed and duration write the same file, bit for bit, computed afresh (the per-process cache cleared:
    DOP853's and the compiled RK4's runs alike); another seed another run."""
    for name, arrays in (("septic", septic_arrays), ("magnet_in_well", magnet_in_well_arrays)):
        first = WRITERS[name](tmp_path / "a", seed=3, duration=10.0)
        arrays.cache_clear()
        again = WRITERS[name](tmp_path / "b", seed=3, duration=10.0)
        assert again.path.read_bytes() == first.path.read_bytes(), name
        other = WRITERS[name](tmp_path / "c", seed=4, duration=10.0)
        assert not np.allclose(other.truth.z, first.truth.z), name


@pytest.mark.parametrize("name", ["oblique_springs", "septic", "rod_frame"])
def test_negstiff_reads_the_record(records, name):
    """negstiff's loader reads each record with its column map and keyword arguments, every row."""
    rec = records[name]
    measurement = rec.load()
    assert measurement.n == rec.truth.z.size and measurement.fs == pytest.approx(rec.truth.fs)


@pytest.mark.slow  # the absolute velocity's gain is estimated at load: 4-5 s a record
@pytest.mark.parametrize("name", ["magnet_chaos", "magnet_in_well"])
def test_negstiff_reads_the_vibrometer_records(records, name):
    """The vibrometer records load (y_dot=ldv*?: the gain estimated, 4 s cut at each end)."""
    rec = records[name]
    measurement = rec.load()
    assert measurement.n == pytest.approx(rec.truth.z.size - 8 * rec.truth.fs, abs=0.1 * rec.truth.fs)
