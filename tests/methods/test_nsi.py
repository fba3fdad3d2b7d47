"""Nonlinear subspace identification (algorithms.md A.9; issue 4's acceptance)."""

import numpy as np
import pytest
from records import SILVERBOX_TEST, assert_result_answers_alike, silverbox_prediction_mv
from scipy import linalg, signal

from negstiff.errors import MeasurementError
from negstiff.inference.estimators import subspace
from negstiff.inference.estimators.nsi import NSI
from negstiff.inference.record.derivatives import smooth_and_differentiate
from negstiff.inference.record.measurement import from_arrays
from negstiff.inference.steps.wells import well_guesses
from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC, Model, simulate
from negstiff.models.rig import Rig, Sensors


def _a9_record():
    """algorithms.md A.9: z'' + 2 zeta wn z' + wn^2 z + a2 z^2 + a3 z^3 = u, fn = 10 Hz, zeta = 0.02,
    a2 = 2e5, a3 = 1e8, u Gaussian low-passed at 60 Hz, 20 m/s^2 rms, fs = 1 kHz, N = 60 000."""
    wn = 2 * np.pi * 10.0
    truth = Model(m=1.0, k1=-(wn**2), k2=2e5, k3=1e8, c=2 * 0.02 * wn, k0=0.0)
    u = signal.sosfiltfilt(
        signal.butter(8, 60, fs=1000.0, output="sos"), np.random.default_rng(0).standard_normal(60000)
    )
    u *= 20 / u.std()
    z = simulate(truth, u, 1e-3, z0=0.0, v0=0.0, input_kind="force", substeps=10).z[0]
    return truth, from_arrays(u, z, 1000.0, input_name="force", mass=1.0, source="A.9")


@pytest.mark.parametrize(
    "block_rows", [(30,), pytest.param((10, 20, 30), marks=pytest.mark.slow)], ids=["recipe", "block_row_stability"]
)  # the default suite checks the recipe's accuracy at its default block rows; -m slow, the stability across 10-30
def test_a9_recipe_noise_free_recovery_quality_and_block_row_stability(block_rows):
    truth, rec = _a9_record()
    fits = {i: NSI(block_rows=i).fit(rec).wells_["plus"] for i in block_rows}
    for _rows, w in fits.items():
        c = w.coefficients
        # noise-free: only the integrator (h = 0.1 ms) and the basis smoothing err, far below 1e-3
        assert w.f_hz == pytest.approx(10.0, rel=1e-3)
        assert w.zeta == pytest.approx(0.02, rel=1e-3)
        assert c["k2_tilde"] == pytest.approx(2e5, rel=1e-3)
        assert c["k3"] == pytest.approx(1e8, rel=1e-3)
        # the extended FRF ratios are real and frequency-independent in theory
        assert w.quality["x2"] < 1e-2 and w.quality["x3"] < 1e-2
    k3 = np.array([w.coefficients["k3"] for w in fits.values()])
    assert np.ptp(k3) / k3.mean() < 1e-3, "coefficients stable across block rows 10-30"


def test_chunked_lq_equals_the_direct_factorisation():
    rng = np.random.default_rng(1)
    u, y = rng.standard_normal((3000, 2)), rng.standard_normal((3000, 1))
    i = 6
    L = subspace.lq_factor(u, y, i, chunk=500, route="qr")
    j = 3000 - 2 * i + 1
    blocks = [
        subspace.hankel_block(u, i, i, j),
        subspace.hankel_block(u, 0, i, j),
        subspace.hankel_block(y, 0, i, j),
        subspace.hankel_block(y, i, i, j),
    ]
    H = np.vstack(blocks) / np.sqrt(j)
    R = linalg.qr(H.T, mode="r")[0][: H.shape[0]]
    # L is unique up to the signs of its columns
    assert np.allclose(np.abs(L), np.abs(R.T), atol=1e-10)


def test_covariance_route_gives_the_qr_factor_of_an_oversampled_record():
    # The Gram route's L must be the QR route's (up to column signs) to the rounding its conditioning
    # allows: eps / (smallest residual variance ratio). Channels: band-limited noise at 25x its band
    # edge and its lightly damped response (the conditioning of a device record at 512 Hz), each with
    # a sensor noise floor (without one the plain Cholesky factor is refused, GRAM_MIN_RATIO: next tests).
    rng = np.random.default_rng(3)
    n, fs = 20000, 512.0
    b, a = signal.butter(4, 20.0, fs=fs)
    u = signal.lfilter(b, a, rng.standard_normal((n, 2)), axis=0)
    u = u / u.std(axis=0) + 1e-2 * rng.standard_normal((n, 2))  # the sensors' noise floor
    wn, zeta = 2 * np.pi * 8.0, 0.05
    sys_d = signal.cont2discrete(([1.0], [1.0, 2 * zeta * wn, wn**2]), 1 / fs)
    y = signal.lfilter(sys_d[0].ravel(), sys_d[1], u[:, 0])[:, None]
    y = y / y.std() + 1e-3 * rng.standard_normal((n, 1))
    i = 20
    g = subspace.hankel_gram(u, y, i)
    L_qr = subspace.lq_factor(u, y, i, route="qr")
    L = subspace.lq_factor(u, y, i)
    assert np.allclose(L_qr @ L_qr.T, g, rtol=0, atol=1e-12 * np.abs(g).max()), "the Gram matrix is H H^T / j"
    ratio = float(np.min(np.diag(L) ** 2 / np.diag(g)))
    assert ratio >= subspace.GRAM_MIN_RATIO, "this record takes the covariance route"
    bound = 100 * np.finfo(float).eps / ratio
    assert np.abs(np.abs(L) - np.abs(L_qr)).max() <= bound * np.abs(L_qr).max()


def test_a_singular_gram_matrix_takes_the_ridge_route_and_keeps_po_moesps_projection():
    # two identical input channels: the Gram matrix is singular and Cholesky fails; the ridge route factors
    # it. L L^T is the Gram matrix to the ridge's size, and the singular values of L32 (all that PO-MOESP
    # reads) are those of the projections themselves: Y_f and the past W_p with the row space of U_f
    # removed, then Y_f's part in the rest of W_p's row space, each from an SVD. (The QR route's are not:
    # past its zero pivot the direction it takes is rounding's choice, outside U_f's row space)
    rng = np.random.default_rng(4)
    x = rng.standard_normal((4000, 1))
    u, y = np.hstack([x, x]), rng.standard_normal((4000, 1))
    i = 5
    g = subspace.hankel_gram(u, y, i)
    with pytest.raises(linalg.LinAlgError):
        linalg.cholesky(g, lower=True)
    L, route = subspace.lq_factor_route(u, y, i)
    assert route == "gram_ridge"
    ridge = g.shape[0] * np.finfo(float).eps * np.abs(g).max()
    assert np.allclose(L @ L.T, g, rtol=0, atol=10 * ridge)

    j = u.shape[0] - 2 * i + 1
    u_f = subspace.hankel_block(u, i, i, j)
    w_p = np.vstack([subspace.hankel_block(u, 0, i, j), subspace.hankel_block(y, 0, i, j)])
    y_f = subspace.hankel_block(y, i, i, j)

    def row_basis(a):
        _, s, vt = np.linalg.svd(a, full_matrices=False)
        return vt[s > 1e-10 * s[0]]

    def without(a, basis):
        return a - (a @ basis.T) @ basis

    q_f = row_basis(u_f)
    expected = np.linalg.svd(without(y_f, q_f) @ row_basis(without(w_p, q_f)).T / np.sqrt(j), compute_uv=False)
    a, b = 2 * i, 2 * i + 3 * i  # L32: the Y_f rows against the past (U_p, Y_p) columns
    got = np.linalg.svd(L[b:, a:b], compute_uv=False)
    assert np.allclose(got, expected, rtol=0, atol=10 * np.sqrt(ridge))
    with pytest.raises(ValueError, match="unknown LQ route"):
        subspace.lq_factor(u, y, 5, route="fast")


def test_output_equation_recovers_x0_b_d_of_a_system_with_a_negative_and_a_zero_pole():
    """estimate_bd's regressors (C A^k for x0, the state responses for B, the inputs for D) fit an exact
    discrete system's output to rounding, including eigenvalues -0.6 (mu^k alternates) and 0 (mu^0 = 1):
    x0, B and D come back to the linear solve's rounding."""
    rng = np.random.default_rng(11)
    A = np.diag([0.95, -0.6, 0.0]) + np.triu(0.05 * rng.standard_normal((3, 3)), 1)
    B, C, D = rng.standard_normal((3, 2)), rng.standard_normal((1, 3)), rng.standard_normal((1, 2))
    x0 = rng.standard_normal(3)
    u = rng.standard_normal((3000, 2))
    x, y = x0.copy(), np.empty((3000, 1))
    for k in range(3000):
        y[k] = C @ x + D @ u[k]
        x = A @ x + B @ u[k]
    x0_e, B_e, D_e = subspace.estimate_bd(A, C, u, y)
    for est, true in ((x0_e, x0), (B_e, B), (D_e, D)):
        assert np.allclose(est, true, rtol=1e-9, atol=1e-9)


@pytest.fixture(scope="module")
def dop853_double_well():
    """A noise-free record as a library user writes one: m z'' + c z' - k1 z + k3 z^3 = -m b'' integrated by
    scipy's DOP853 (rtol 1e-8), b'' band-limited random (3-40 Hz, 6 m/s^2 rms, a cubic spline through
    its samples), sampled at 512 Hz. Wells at +-20 mm, 10 Hz (K'(z*) = 2 k1), 5 % damping.
    """
    from scipy.integrate import solve_ivp
    from scipy.interpolate import CubicSpline

    duration, fs, seed = 60.0, 512.0, 0
    m, z_star, f_well = 0.2, 0.02, 10.0
    k1 = m * (2 * np.pi * f_well) ** 2 / 2
    k3, c = k1 / z_star**2, 2 * 0.05 * np.sqrt(2 * k1 * m)
    n = int(duration * fs)
    t = np.arange(n) / fs
    b = signal.sosfiltfilt(
        signal.butter(4, [3.0, 40.0], btype="band", fs=fs, output="sos"), np.random.default_rng(seed).standard_normal(n)
    )
    b *= 6.0 / b.std()
    coef = CubicSpline(t, b).c

    def rhs(time, state):
        k = min(int(time * fs), n - 2)  # the spline's piece, evaluated by hand (CubicSpline's call costs 5x)
        h, p = time - k / fs, coef[:, k]
        acc = ((p[0] * h + p[1]) * h + p[2]) * h + p[3]
        return [state[1], (-c * state[1] + k1 * state[0] - k3 * state[0] ** 3) / m - acc]

    sol = solve_ivp(rhs, (0.0, t[-1]), [z_star, 0.0], method="DOP853", t_eval=t, rtol=1e-8, atol=1e-12)
    return from_arrays(b, sol.y[0], fs, mass=m, gravity=0.0, source="dop853"), f_well


def test_a_noise_free_dop853_record_takes_the_fast_route_and_finds_both_wells(dop853_double_well, monkeypatch):
    # a noise-free record's band-limited channels leave the Hankel Gram matrix singular to rounding
    # (Cholesky fails): NSI takes the ridge route (subspace.GRAM_RIDGE), not the chunked QR (8x the CPU
    # time). Both wells' frequencies are the truth's linearisation sqrt(K'(z*)/m) within 1 % (measured
    # 4e-5: the smoothing's), and the QR route's within 2e-6 (measured 8e-7: what the Gram matrix cannot
    # resolve, below sqrt(n eps) of the largest singular value)
    rec, f_well = dop853_double_well
    est = NSI(refine=False).fit(rec)
    assert set(est.wells_) == {"minus", "plus"}
    for name, well in est.result()["wells"].items():
        assert well["lq_routes"] and set(well["lq_routes"]) == {"gram_ridge"}, name
        assert well["f_hz"] == pytest.approx(f_well, rel=0.01), name
    monkeypatch.setattr(subspace, "gram_factor", lambda g: None)  # every pass through the chunked QR
    qr = NSI(refine=False).fit(rec)
    for name, well in est.wells_.items():
        assert qr.wells_[name].lq_routes == ("qr",) * len(well.lq_routes)
        assert well.f_hz == pytest.approx(qr.wells_[name].f_hz, rel=2e-6), name


def test_the_progress_bar_counts_every_pass_of_a_well(dop853_double_well):
    # identify nsi's bar is advanced by all of a well's passes, whether the well converged early or not:
    # one pass, two (the default) or five
    rec, _ = dop853_double_well
    zs, v, _, _ = rec.states("band")
    _, z_plus = well_guesses(rec)

    class Ticks:
        n = 0

        def update(self, k=1):
            self.n += k

    for passes in (1, 2, 5):
        ticks = Ticks()
        NSI(passes=passes).fit_well(rec, zs, v, z_plus, ticks)
        assert ticks.n == passes


@pytest.fixture(scope="module")
def seed_like_noise_free():
    rec = Rig(SEED_LIKE_CUBIC, sensors=Sensors.noiseless(), seed=1).random(duration=300, rms=SEED_LIKE_CROSS_WELL_RMS)
    return from_arrays(rec.columns["base_acc"], rec.columns["z"], 512.0, mass=SEED_LIKE_CUBIC.m, source="rig")


def test_shifted_double_well_noise_free(seed_like_noise_free):
    # both references are found from the data; noise-free sensors (the double integration of the
    # base acceleration remains): k1-k3 within 0.5 %, both well frequencies within 0.1 %
    est = NSI().fit(seed_like_noise_free)
    assert set(est.wells_) == {"minus", "plus"}
    for k in ("k1", "k2", "k3"):
        assert getattr(est.model_, k) == pytest.approx(getattr(SEED_LIKE_CUBIC, k), rel=5e-3), k
    for well, w in est.wells_.items():
        uls = SEED_LIKE_CUBIC.uls(well)
        assert w.f_hz == pytest.approx(uls.f_hz, rel=1e-3), well
        assert w.z_ref == pytest.approx(uls.z_ref, abs=5e-5), well


def test_cross_well_record_at_default_noise_meets_the_seed():
    # 300 s cross-well random record, polynomial truth, the rig's default sensors
    truth = SEED_LIKE_CUBIC
    rec = Rig(truth, seed=2).random(duration=300, rms=SEED_LIKE_CROSS_WELL_RMS)
    est = NSI().fit(load_record(rec))
    for well, w in est.wells_.items():
        uls = truth.uls(well)
        assert w.f_hz == pytest.approx(uls.f_hz, rel=0.01), well
        assert w.zeta == pytest.approx(uls.zeta, rel=0.15), well
    assert est.model_.k3 == pytest.approx(truth.k3, rel=0.03)
    assert est.model_.k1 == pytest.approx(truth.k1, rel=0.05)
    assert est.model_.k2 == pytest.approx(truth.k2, rel=0.05)
    assert est.validation_["rms_percent"] <= 8.0, "the seed's Table 2 level"
    assert est.result()["input_gain"] == pytest.approx(1.0, rel=0.02), "base excitation: unit input gain"


def load_record(rec):
    return from_arrays(rec.columns["base_acc"], rec.columns["z"], rec.fs, mass=float(rec.meta["mass"]), source="rig")


def test_a_record_without_excitation_gets_a_clear_error():
    z = 0.02 + 1e-5 * np.random.default_rng(0).standard_normal(20000)
    with pytest.raises(MeasurementError, match="quiet.csv: the input base_acc is constant"):
        NSI().fit(from_arrays(np.zeros(20000), z, 512.0, source="quiet.csv"))
    with pytest.raises(MeasurementError, match="too few samples for NSI"):
        NSI().fit(from_arrays(np.ones(500), np.ones(500), 512.0, source="short.csv"))


def test_smoothing_does_not_bend_the_response():
    # a 60 Hz sine sampled at 610 Hz (the Silverbox's band): the fitted window keeps its amplitude
    t = np.arange(20000) / 610.35
    z = 0.1 * np.sin(2 * np.pi * 60 * t)
    zs, v = smooth_and_differentiate(z, 610.35)
    assert np.ptp(zs[100:-100]) == pytest.approx(np.ptp(z[100:-100]), rel=2e-3)
    assert np.max(np.abs(v[100:-100])) == pytest.approx(0.1 * 2 * np.pi * 60, rel=5e-3)


def test_silverbox_nsi_finds_the_hardening_and_predicts_the_test(silverbox, silverbox_fits):
    # real data: the Silverbox is a hardening Duffing oscillator; NSI with its defaults (trained on
    # 40650-105712 only) predicts the multisine test free-run within the 0.85 mV (0.24 mV
    # measured; the published polynomial NARX reaches 0.64 mV)
    est = silverbox_fits["nsi"]
    assert est.model_.k3 > 0 and est.initial_model_.k3 > 0, "Silverbox is a hardening Duffing oscillator"
    assert silverbox_prediction_mv(est.model_, silverbox, SILVERBOX_TEST) <= 0.85
    assert est.bounded_["ok"]
    assert_result_answers_alike(est)  # as a structure's result does
