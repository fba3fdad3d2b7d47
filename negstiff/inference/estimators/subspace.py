"""Generic LTI subspace identification (PO-MOESP) for the NSI estimator.

Van Overschee & De Moor (1996), "Subspace Identification for Linear Systems"; Verhaegen (1994),
"Identification of the deterministic part of MIMO state space models given in innovations form from
input-output data" (PO-MOESP). Notation of ``docs/algorithms.md`` A.2:

1. Block Hankel matrices of i block rows for the inputs (m channels) and outputs (l channels):
   U_p, U_f, Y_p, Y_f; W_p = [U_p; Y_p].
2. LQ factor of H = [U_f; W_p; Y_f] / sqrt(j). Fast route: L is the Cholesky factor of the Gram matrix
   H H^T (H = L Q with orthonormal Q gives H H^T = L L^T), and the Gram matrix of a block Hankel
   matrix is a matrix of lagged correlations: its first block row costs 2i products of the channels
   with their lags, every other block follows from the one up-left of it by adding the sample that
   enters and removing the one that leaves (Van Overschee & De Moor 1996, sec. 6.1, and Cho, Xu &
   Kailath 1994 use the same structure). O(N (m+l)^2 i) work instead of the QR's O(N (2i(m+l))^2),
   and no Hankel matrix at all. The Gram matrix squares H's condition: where a row's residual variance
   after the rows before it falls below ``GRAM_MIN_RATIO`` of its own (Cholesky would then lose more
   than ~1e-5 of it to rounding), or Cholesky fails, the Gram matrix with a ridge at its own rounding
   level (``GRAM_RIDGE``: a noise-free record, whose band-limited channels leave H numerically rank
   deficient) is factored instead; only where that fails too does the factor come from the QR route: the
   R of an economy QR of H^T, accumulated over column chunks of H (memory O(chunk * rows), never the big
   projections; Gandino & Marchesiello 2010 use the same idea). No numpy/scipy routine or maintained
   subspace package exploits the Hankel structure (nfoursid and SIPPY build the Hankel matrix and QR
   it whole; see reports/benchmarks.md), hence this code.
3. PO-MOESP: SVD of L32, the block of L that couples Y_f to the past after U_f is removed;
   extended observability Gamma = U_1 S_1^(1/2).
4. A, C from the shift invariance of Gamma; (x0, B, D) by linear least squares on the output equation
   y_k = C A^k x0 + sum_t C A^(k-1-t) B u_t + D u_k (A.2.6b).
5. Continuous time (A.3): A_c = logm(A)/dt, B_c = (A - I)^-1 A_c B (inverse zero-order hold).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, signal

from negstiff.resources import one_blas_thread


@dataclass(frozen=True)
class StateSpace:
    """A continuous-time state-space model x' = A x + B u, y = C x + D u."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    singular_values: np.ndarray
    Ad: np.ndarray | None = None
    Bd: np.ndarray | None = None
    dt: float | None = None
    lq_route: str | None = None
    """The route of the LQ factor (one of ``LQ_ROUTES``), where the model came from ``identify``."""

    def frf_discrete(self, freqs_hz: np.ndarray) -> np.ndarray:
        """H(e^(i omega dt)) of the identified discrete-time model, shape (F, l, m). For band-limited
        (non-ZOH) inputs this, not the inverse-ZOH continuous model, carries the right FRF level
        below Nyquist (algorithms.md A.3 measured up to 9 % level error the other way).
        """
        if self.Ad is None or self.Bd is None or self.dt is None:
            raise ValueError("a continuous-time state space has no discrete FRF (Ad, Bd, dt unset)")
        Ad, Bd = self.Ad, self.Bd
        n = Ad.shape[0]
        q = np.exp(2j * np.pi * np.asarray(freqs_hz) * self.dt)
        out = np.empty((q.size, self.C.shape[0], Bd.shape[1]), dtype=np.complex128)
        for k, qk in enumerate(q):
            out[k] = self.D + self.C @ np.linalg.solve(qk * np.eye(n) - Ad, Bd)
        return out

    def frf(self, freqs_hz: np.ndarray) -> np.ndarray:
        """H(omega) = D + C (i omega I - A)^-1 B, shape (F, l, m)."""
        n = self.A.shape[0]
        s = 2j * np.pi * np.asarray(freqs_hz)
        out = np.empty((s.size, self.C.shape[0], self.B.shape[1]), complex)
        for k, sk in enumerate(s):
            out[k] = self.D + self.C @ np.linalg.solve(sk * np.eye(n) - self.A, self.B)
        return out

    def poles(self) -> np.ndarray:
        """The discrete-time poles (eigenvalues of A)."""
        return np.linalg.eigvals(self.A)


def hankel_block(x: np.ndarray, start: int, rows: int, cols: int) -> np.ndarray:
    """Rows ``start .. start+rows-1`` of the block Hankel matrix of x (N, ch): shape (rows*ch, cols)."""
    n_ch = x.shape[1]
    out = np.empty((rows * n_ch, cols))
    for r in range(rows):
        out[r * n_ch : (r + 1) * n_ch] = x[start + r : start + r + cols].T
    return out


GRAM_MIN_RATIO = 1e-11
"""The covariance route's Cholesky factor is used while every row keeps at least this fraction of its
variance after the rows before it (rounding then perturbs L by at most ~eps / ratio ~ 2e-5 of the row;
on a 300 s rig record the smallest ratio was 1.4e-10 and L agreed with the QR route's to 1.5e-7)."""


def hankel_gram(u: np.ndarray, y: np.ndarray, i: int, chunk: int = 4096) -> np.ndarray:
    """H H^T / j of H = [U_f; U_p; Y_p; Y_f] from the channels' lagged products, without forming H."""
    z = np.hstack([u, y])
    n, c = z.shape
    j, depth = n - 2 * i + 1, 2 * i
    # the first block row, blocks (0, d) = the channels against their lag-d copies, for every lag at once:
    # one (c x chunk) @ (chunk x c 2i) product per chunk of samples (2i thin products of c x j @ j x c
    # took 1.7x as long: BLAS is slow on 5 x 5 outputs)
    lagged = np.lib.stride_tricks.sliding_window_view(z, depth, axis=0)  # (j, c, 2i): [t, b, d] = z[t + d, b]
    first_row = np.zeros((c, c * depth))
    for t0 in range(0, j, chunk):
        t1 = min(j, t0 + chunk)
        first_row += z[t0:t1].T @ lagged[t0:t1].reshape(t1 - t0, c * depth)
    first_row = first_row.reshape(c, c, depth)
    g = np.empty((depth, c, depth, c))
    for d in range(depth):
        first = first_row[:, :, d]  # block (0, d)
        t = np.arange(depth - 1 - d)
        # block (o, o + d) = block (o - 1, o - 1 + d) + the products of the sample entering the window
        # minus those of the sample leaving it
        step = np.einsum("ta,tb->tab", z[t + j], z[t + d + j]) - np.einsum("ta,tb->tab", z[t], z[t + d])
        blocks = np.concatenate([first[None], first[None] + np.cumsum(step, axis=0)])
        for o in range(depth - d):
            g[o, :, o + d, :] = blocks[o]
            g[o + d, :, o, :] = blocks[o].T
    m, l_out = u.shape[1], y.shape[1]
    rows = [(o, ch) for o in range(i, depth) for ch in range(m)]  # U_f
    rows += [(o, ch) for o in range(i) for ch in range(m)]  # U_p
    rows += [(o, m + ch) for o in range(i) for ch in range(l_out)]  # Y_p
    rows += [(o, m + ch) for o in range(i, depth) for ch in range(l_out)]  # Y_f
    idx = np.array([o * c + ch for o, ch in rows])
    return g.reshape(depth * c, depth * c)[np.ix_(idx, idx)] / j


GRAM_RIDGE = 1.0
"""The ridge route factors G + ``GRAM_RIDGE`` * n * eps * diag(G) (n: G's rows): each row's variance raised by
n eps of itself, the size of the perturbation Cholesky's own rounding already puts on it (its backward error
is bounded by about (n + 1) eps |L| |L^T|, whose diagonal is diag(G): Higham 2002, Theorem 10.3). In
expectation it is the Gram matrix of H plus independent white noise of variance n eps in each standardised
channel (~7e-14 for 300 rows: a noise floor of 3e-7 of the channel's rms, a 24-bit converter's
quantisation, below any real sensor's), with which PO-MOESP stays consistent. What it cannot see is what the
double-precision Gram matrix had lost anyway: the parts of H whose singular values lie below ~sqrt(n eps) of
the largest, which a noise-free record's band-limited channels have by the hundred (a DOP853 record at
512 Hz, excitation to 40 Hz: 167 of G's 300 eigenvalues below 1e-12 of the largest; Cholesky fails).
Measured on such records (NSI's wells against the QR route's): frequencies within 1e-8 relative on 300 s,
8e-7 on 60 s; damping within 1e-7 and 6e-5 (the truth is 4e-5 and 4e-4 away). NSI's own inputs take this
route on noisy records too: its basis is low-passed above the response's band, so the input rows are rank
deficient whatever the sensor's noise (the Gram matrix's smallest eigenvalue 1e-17 of its largest on a rig
record). There the two routes settle the unspanned directions differently (L32's singular values differ by
up to 5e-3, benchmarks' peers section), and NSI's estimates by less than their noise: on two 120 s rig
records, k2 within 0.2 % of the QR route's, k1, k3, c within 0.04 %, the wells' frequencies within 1e-4."""


LQ_ROUTES = ("gram", "gram_ridge", "qr")
"""The routes of the LQ factor: the Gram matrix's Cholesky factor, the same with ``GRAM_RIDGE``, the chunked QR."""


def gram_factor(g: np.ndarray) -> tuple[np.ndarray, str] | None:
    """The Cholesky factor of the Hankel Gram matrix ``g`` and its route: ``"gram"`` where every row keeps
    ``GRAM_MIN_RATIO`` of its variance after the rows before it, else ``"gram_ridge"`` (``GRAM_RIDGE``), or
    None where even that fails (the QR route's case).
    """
    try:
        L = linalg.cholesky(g, lower=True, check_finite=False)
        if np.min(np.diag(L) ** 2 / np.diag(g)) >= GRAM_MIN_RATIO:
            return L, "gram"
    except linalg.LinAlgError:
        pass
    ridged = g + np.diag(GRAM_RIDGE * g.shape[0] * np.finfo(float).eps * np.diag(g))
    try:
        return linalg.cholesky(ridged, lower=True, check_finite=False), "gram_ridge"
    except linalg.LinAlgError:
        return None


def covariance_factor(u: np.ndarray, y: np.ndarray, i: int) -> np.ndarray | None:
    """The covariance route's L (the Cholesky factor of ``hankel_gram``, with ``GRAM_RIDGE`` where the plain
    factor is refused: ``gram_factor``), or None where even the ridge's Cholesky fails.
    """
    out = gram_factor(hankel_gram(u, y, i))
    return None if out is None else out[0]


def lq_factor(u: np.ndarray, y: np.ndarray, i: int, chunk: int = 8192, route: str = "auto") -> np.ndarray:
    """Lower-triangular L of the LQ factorisation of H = [U_f; U_p; Y_p; Y_f] / sqrt(j), up to the
    signs of its columns (which no later step depends on).

    ``route="auto"``: the Cholesky factor of the Hankel Gram matrix (``hankel_gram``; ``gram_factor``: with
    ``GRAM_RIDGE`` where it is ill-conditioned), else the chunked QR; ``"qr"``: the chunked QR always. The QR
    processes the rows of H^T in chunks, updating R by QR of [R; chunk]: memory O(chunk * 2i(m+l)),
    independent of the record length squared.
    """
    return lq_factor_route(u, y, i, chunk, route)[0]


def lq_factor_route(
    u: np.ndarray, y: np.ndarray, i: int, chunk: int = 8192, route: str = "auto"
) -> tuple[np.ndarray, str]:
    """``lq_factor``'s L and the route it took (one of ``LQ_ROUTES``)."""
    n = u.shape[0]
    j = n - 2 * i + 1
    if j < 2 * i * (u.shape[1] + y.shape[1]):
        raise ValueError(f"record too short for {i} block rows: {n} samples")
    if route not in ("auto", "qr"):
        raise ValueError(f"unknown LQ route {route!r}: 'auto' or 'qr'")
    if route == "auto":
        out = gram_factor(hankel_gram(u, y, i))
        if out is not None:
            return out
    r = None
    for c0 in range(0, j, chunk):
        cols = min(chunk, j - c0)
        blocks = [
            hankel_block(u[c0:], i, i, cols),
            hankel_block(u[c0:], 0, i, cols),
            hankel_block(y[c0:], 0, i, cols),
            hankel_block(y[c0:], i, i, cols),
        ]
        ht = np.vstack(blocks).T
        stacked = ht if r is None else np.vstack([r, ht])
        r = linalg.qr(stacked, mode="r", overwrite_a=True, check_finite=False)[0]
        r = r[: stacked.shape[1]]
    assert r is not None  # j > 0: at least one chunk
    return r.T / np.sqrt(j), "qr"


def po_moesp(
    u: np.ndarray, y: np.ndarray, i: int, order: int, route: str = "auto"
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete A, C and the singular values from PO-MOESP with ``i`` block rows (``route``: the LQ's,
    ``lq_factor``).
    """
    return _po_moesp(u, y, i, order, route)[:3]


def _po_moesp(
    u: np.ndarray, y: np.ndarray, i: int, order: int, route: str = "auto"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """``po_moesp`` and the route its LQ factor took."""
    uu, s, taken = _observability(u, y, i, route)
    if order > s.size:
        raise ValueError(f"order {order} exceeds the {s.size} available singular values")
    A, C = _state_matrices(uu, s, order, y.shape[1])
    return A, C, s, taken


def _observability(u: np.ndarray, y: np.ndarray, i: int, route: str = "auto") -> tuple[np.ndarray, np.ndarray, str]:
    """The left singular vectors and singular values of PO-MOESP's projected block (the extended observability
    matrix's column space, every order's), and the route of its LQ factor.
    """
    m, l_out = u.shape[1], y.shape[1]
    L, taken = lq_factor_route(u, y, i, route=route)
    a, b = i * m, i * m + i * (m + l_out)
    uu, s, _ = np.linalg.svd(L[b:, a:b], full_matrices=False)
    return uu, s, taken


def _state_matrices(uu: np.ndarray, s: np.ndarray, order: int, l_out: int) -> tuple[np.ndarray, np.ndarray]:
    """Discrete A and C of ``order`` states from ``_observability``'s singular vectors and values."""
    gamma = uu[:, :order] * np.sqrt(s[:order])
    C = gamma[:l_out]
    A = np.linalg.lstsq(gamma[:-l_out], gamma[l_out:], rcond=None)[0]
    return A, C


def poles_by_order(u: np.ndarray, y: np.ndarray, dt: float, i: int, orders) -> dict[int, np.ndarray]:
    """The continuous-time poles (rad/s, Im > 0 kept with the real ones) of the PO-MOESP model at each order of
    ``orders``, from one LQ factor and one SVD with ``i`` block rows: a stabilisation diagram's columns at the
    cost of one fit (the A of each order is a least squares on the same extended observability matrix). No B or D
    is estimated, so an order whose model has an unstable spurious pole still gives its poles.
    """
    uu, s, _ = _observability(u, y, i)
    out = {}
    for order in orders:
        if order > s.size:
            break
        mu = np.linalg.eigvals(_state_matrices(uu, s, order, y.shape[1])[0]).astype(complex)
        with np.errstate(divide="ignore"):
            lam = np.log(mu) / dt
        out[int(order)] = lam[np.isfinite(lam) & (lam.imag >= 0)]
    return out


def estimate_bd(
    A: np.ndarray, C: np.ndarray, u: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x0, B, D) by linear least squares on the output equation (algorithms.md A.2.6b)."""
    n, m, l_out = A.shape[0], u.shape[1], y.shape[1]
    N = u.shape[0]
    cols = []
    # x0 regressors: C A^k e_s, vectorised through A = V diag(mu) V^-1 (A has distinct eigenvalues
    # for an identified system; a Python loop over N samples took seconds)
    mu, V = np.linalg.eig(A)
    if np.any(np.abs(mu) >= 1.0):
        raise ValueError("the identified discrete-time system is unstable (|eigenvalue| >= 1)")
    # (N, n): mu^k as exp(k log mu), 4x faster than complex **; the complex log takes real negative mu
    with np.errstate(divide="ignore", invalid="ignore"):
        powers = np.exp(np.arange(N)[:, None] * np.log(mu.astype(complex))[None, :])
    powers[0] = 1.0  # mu^0, also for mu = 0 (0 * log 0 is nan)
    cv, vi = C @ V, np.linalg.inv(V)
    resp = np.stack([(powers * cv[o]) @ vi for o in range(l_out)], axis=1).real  # (N, l, n); einsum took 5x
    cols += [resp[:, :, s] for s in range(n)]
    # B regressors: response to input channel q through state s (B = e_s e_q^T), zero initial state,
    # filtered as transfer functions (lfilter runs in C; dlsim loops in Python)
    for q in range(m):
        for s in range(n):
            Bq = np.zeros((n, 1))
            Bq[s] = 1.0
            yy = np.empty((N, l_out))
            for o in range(l_out):
                num, den = signal.ss2tf(A, Bq, C[o : o + 1], np.zeros((1, 1)))
                yy[:, o] = signal.lfilter(num[0], den, u[:, q])
            cols.append(yy)
    # D regressors
    for q in range(m):
        for o in range(l_out):
            d = np.zeros((N, l_out))
            d[:, o] = u[:, q]
            cols.append(d)
    Phi = np.stack([c.reshape(-1) for c in cols], axis=1)
    theta = np.linalg.lstsq(Phi, y.reshape(-1), rcond=None)[0]
    x0 = theta[:n]
    B = theta[n : n + n * m].reshape(m, n).T
    D = theta[n + n * m :].reshape(m, l_out).T
    return x0, B, D


def to_continuous(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Inverse zero-order hold: A_c = logm(A)/dt, B_c = (A - I)^-1 A_c B."""
    Ac = linalg.logm(A).real / dt
    Bc = np.linalg.solve(A - np.eye(A.shape[0]), Ac @ B)
    return Ac, Bc


def identify(u: np.ndarray, y: np.ndarray, dt: float, order: int, block_rows: int, route: str = "auto") -> StateSpace:
    """Continuous-time state space from input (N, m) and output (N, l) samples (``route``: the LQ's,
    ``lq_factor``; the one taken is ``StateSpace.lq_route``).

    Runs on one BLAS thread (``negstiff.resources.one_blas_thread``): its products are too small for a
    second one to pay (NSI on a 300 s record at 512 Hz: the same wall time on an idle machine, and 6-15x the
    CPU time beside other work; ``docs/speed.md``).
    """
    with one_blas_thread():
        A, C, s, taken = _po_moesp(u, y, block_rows, order, route)
        _, B, D = estimate_bd(A, C, u, y)
        Ac, Bc = to_continuous(A, B, dt)
    return StateSpace(Ac, Bc, C, D, s, A, B, dt, taken)
