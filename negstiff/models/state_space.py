"""A structure read through its sensors: a linear part of any order and one nonlinear element between two sensors.

A lab's structure has more modes in its band than the lab has sensors (a wing's seven modes, two accelerometers
beside a joint), and its masses are not known. Its underlying-linear part is then not physical M, C, K over the
sensors (``models.structure``) but a state-space model of the order the record shows (the stabilisation diagram's),
x_{k+1} = A x_k + B w_k, y_k = C x_k + y_mean, whose outputs are the sensors' displacements and whose inputs w are
the measured force and the element's basis functions of the relative motion r = y_J - y_I (I = 0: the ground) as
feedback forces (its laws' basis, ``laws.FeedbackBasis``; the cubic's [f, -(r - r*)^2, -(r - r*)^3, -r'|r'|]),
each less the mean it had in the identification
(Marchesiello & Garibaldi 2008; the extended input of Noel & Kerschen 2013's FNSI, here in the time domain). The
model is the identified discrete-time one, in the record's own sampling, so a free run replays exactly what was
fitted; its continuous-time state matrix gives the modes and r' (r' = l.C A_c x: a displacement output has no
feedthrough of a force, C B = 0).

Where the sensors are accelerometers the outputs are their accelerations, y_k = C x_k + D w_k + y_mean (an
acceleration answers a force at once: the feedthrough D): what they measured, not its double integral, whose slow
error no model of the structure holds. The displacement and the velocity are then read from the same state,
C A_c^-2 x and C A_c^-1 x (a structure's accelerance is s^2 times its compliance), r's constant being r* (no
acceleration holds it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import linalg

from negstiff.models import laws
from negstiff.models.structure import Mode, coupling, modes_of_state_matrix


def element_basis(restoring: str = laws.DEFAULT_RESTORING, damping: str = laws.DEFAULT_DAMPING) -> laws.FeedbackBasis:
    """The element's basis about a reference for a restoring and a damping law (``laws.FeedbackBasis``; the cubic
    with quadratic damping: x^2, x^3, r'|r'|). A shaped law's shape is fitted on a single DOF's record only: one
    ``InputError`` here.
    """
    from negstiff.errors import InputError

    law, damp = laws.get(restoring, "restoring"), laws.get(damping, "damping")
    if law.shaped() or damp.shaped():
        raise InputError(
            f"law {law.name!r}: a shaped law's shape is fitted on a single DOF's record; a structure's element reads "
            "the laws linear in their parameters (polynomials, the damping laws)"
        )
    return laws.FeedbackBasis(law, damp, {})


def feedback_inputs(
    basis: laws.FeedbackBasis, r: np.ndarray | float, vr: np.ndarray | float, r_ref: float
) -> np.ndarray:
    """The element's basis functions of (r, r') about ``r_ref`` as feedback inputs, (T, J): their negatives."""
    r, vr = np.atleast_1d(np.asarray(r, float)), np.atleast_1d(np.asarray(vr, float))
    return -np.column_stack([basis.displacement(r - r_ref, r_ref), basis.velocity(vr)])


@dataclass(frozen=True, eq=False)
class StateSpaceStructure:
    """The identified model of a structure read through its sensors (module docstring), as
    ``NSI(element="I-J").fit(rec).result_.model`` gives it on a record without masses.

    Attributes
    ----------
    A, B, C : ndarray
        The discrete-time linear part: ``x[k+1] = A x[k] + B w[k]``, ``y[k] = C x[k] + output_mean``,
        ``w = [f, -g_1, ..., -g_J] - input_mean``, g the element's basis about r* (``element_basis``; the cubic's
        ``x^2, x^3, r' abs(r')``, x = r - r*), B in SI units per input.
    dt : float
        The sampling interval [s].
    at : tuple of int
        The element's place (I, J) over the sensors (I = 0: the ground): r = y_J - y_I.
    r_ref : float
        The reference r* [m] the basis is expanded about.
    input_mean, output_mean : ndarray
        The inputs' and the sensors' means in the identification.
    restoring, damping : str
        The element's laws (``models.laws``), whose basis the inputs hold.
    output : {"displacement", "acceleration"}
        What the outputs are: the sensors' displacements [m] or their accelerations [m/s^2] (accelerometers').
    D : ndarray or None
        The feedthrough (sensors, inputs) of acceleration outputs: ``y[k] = C x[k] + D w[k] + output_mean``; None
        for displacements (no feedthrough).
    cut_hz : float or None
        The band [Hz] a record is read within (every input and output low-passed there before its decimation to
        ``dt``, and the element's motion): how ``predict`` reads another record; None where not kept.

    Examples
    --------
    One mass on a spring (10 Hz, 2 % damping, 1 kg) read by one sensor, its element on the ground and zero:

    >>> import numpy as np
    >>> from scipy import signal
    >>> from negstiff import StateSpaceStructure
    >>> w, zeta, dt = 2 * np.pi * 10.0, 0.02, 1e-3
    >>> Ac = np.array([[0.0, 1.0], [-w**2, -2 * zeta * w]])
    >>> Bc = np.array([[0.0, 0, 0, 0], [1.0, 0, 0, 0]])
    >>> A, B, C, _, _ = signal.cont2discrete((Ac, Bc, np.array([[1.0, 0.0]]), np.zeros((1, 4))), dt)
    >>> model = StateSpaceStructure(A, B, C, dt, (0, 1), 0.0, np.zeros(4), np.zeros(1))
    >>> [(round(m.f_hz, 3), round(m.zeta, 4)) for m in model.modes()]
    [(10.0, 0.02)]
    >>> round(float(abs(model.frf(np.array([0.1]))[0, 0])) * w**2, 3)  # the static compliance 1/k
    1.0
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    dt: float
    at: tuple[int, int]
    r_ref: float
    input_mean: np.ndarray
    output_mean: np.ndarray
    restoring: str = laws.DEFAULT_RESTORING
    damping: str = laws.DEFAULT_DAMPING
    output: str = "displacement"
    D: np.ndarray | None = None
    cut_hz: float | None = None

    @property
    def basis(self) -> laws.FeedbackBasis:
        """The element's basis (``element_basis`` of its laws)."""
        return element_basis(self.restoring, self.damping)

    @property
    def order(self) -> int:
        """The linear part's order (states)."""
        return int(self.A.shape[0])

    @property
    def n_sensors(self) -> int:
        """The sensors (outputs)."""
        return int(self.C.shape[0])

    def continuous_state_matrix(self) -> np.ndarray:
        """A_c = logm(A) / dt."""
        return linalg.logm(self.A).real / self.dt

    def motion_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows reading the sensors' displacements and velocities from the state, (sensors, states) each:
        C and C A_c for displacement outputs, C A_c^-2 and C A_c^-1 for accelerations (module docstring).
        """
        Ac = self.continuous_state_matrix()
        if self.output == "acceleration":
            return self.C @ np.linalg.inv(Ac @ Ac), self.C @ np.linalg.inv(Ac)
        return self.C, self.C @ Ac

    def modes(self) -> list[Mode]:
        """The underlying-linear modes (every underdamped pole pair), their shapes over the sensors."""
        return modes_of_state_matrix(self.continuous_state_matrix(), self.motion_rows()[0])

    def _feedthrough(self) -> np.ndarray:
        return np.zeros((self.n_sensors, self.B.shape[1])) if self.D is None else self.D

    def extended_frf(self, freqs_hz: np.ndarray) -> np.ndarray:
        """The identified discrete-time model's FRF from every input (the force, then the element's feedback
        inputs) to each sensor's output (``output``), (F, sensors, inputs): its level is right below Nyquist for a
        band-limited force (``subspace``).
        """
        q = np.exp(2j * np.pi * np.asarray(freqs_hz, float) * self.dt)
        eye = np.eye(self.order)
        D = self._feedthrough()
        return np.array([self.C @ np.linalg.solve(qk * eye - self.A, self.B) + D for qk in q])

    def frf(self, freqs_hz: np.ndarray) -> np.ndarray:
        """The underlying-linear FRF [m/N] from the force to each sensor, (F, sensors) (``extended_frf``'s first
        input; an accelerance over -(2 pi f)^2).
        """
        freqs_hz = np.asarray(freqs_hz, float)
        H = self.extended_frf(freqs_hz)[:, :, 0]
        return -H / (2 * np.pi * freqs_hz[:, None]) ** 2 if self.output == "acceleration" else H

    def _inputs(self, basis: laws.FeedbackBasis, u: float, r: float, vr: float, element: bool) -> np.ndarray:
        w = np.concatenate([[u], feedback_inputs(basis, r, vr, self.r_ref)[0]]) - self.input_mean
        if not element:
            w[1:] = 0.0
        return w

    def initial_state(self, u: np.ndarray, y: np.ndarray, r: np.ndarray, vr: np.ndarray,
                      element: bool = True) -> np.ndarray:  # fmt: skip
        """The state at the end of a measured stretch (force ``u``, sensors ``y`` (sensors, L), the element's
        smoothed r and r'), by least squares of the outputs on the state at its start through the model driven
        by the measured inputs (the element's basis the measured one: no free run inside the stretch).
        """
        n, L = self.order, u.size
        w = np.column_stack([u, feedback_inputs(self.basis, r, vr, self.r_ref)]) - self.input_mean
        if not element:
            w[:, 1:] = 0.0
        forced = w @ self._feedthrough().T
        free = np.zeros((L, self.n_sensors, n))
        xf = np.zeros(n)
        P = np.eye(n)
        for k in range(L):
            forced[k] += self.C @ xf
            free[k] = self.C @ P
            xf = self.A @ xf + self.B @ w[k]
            P = self.A @ P
        rhs = (y.T - self.output_mean - forced).reshape(-1)
        x0 = np.linalg.lstsq(free.reshape(-1, n), rhs, rcond=None)[0]
        return P @ x0 + xf  # the state after the stretch: A^L x0 plus the forced part

    def run(self, u: np.ndarray, x0: np.ndarray, element: bool = True) -> tuple[np.ndarray, bool]:
        """A free run from state ``x0`` under the force ``u``: the sensors' outputs (sensors, T) and whether it
        diverged (the element's relative motion beyond 100x its reference's scale; the rest NaN).
        ``element=False``: the underlying-linear part alone.
        """
        basis = self.basis
        lvec = coupling(self.n_sensors, self.at)
        rows, vel = self.motion_rows()
        lc, lcv = lvec @ rows, lvec @ vel
        r_off = self.r_ref if self.output == "acceleration" else float(lvec @ self.output_mean)
        D = self._feedthrough()
        out = np.full((self.n_sensors, u.size), np.nan)
        x = np.asarray(x0, float).copy()
        bound = 100.0 * max(abs(self.r_ref), float(np.max(np.abs(rows @ x))) if x.any() else 0.0, 1e-3)
        for k in range(u.size):
            r = float(lc @ x) + r_off
            if not math.isfinite(r) or abs(r) > bound:
                return out, True
            w = self._inputs(basis, float(u[k]), r, float(lcv @ x), element)
            out[:, k] = self.C @ x + D @ w + self.output_mean
            x = self.A @ x + self.B @ w
        return out, False

    def to_dict(self) -> dict[str, Any]:
        """The model in JSON terms (lists), read back by ``from_dict``."""
        return {"A": self.A.tolist(), "B": self.B.tolist(), "C": self.C.tolist(), "dt": self.dt,
                "element_at": list(self.at), "r_ref_m": self.r_ref, "inputs": ["force", *self.basis.names()],
                "restoring": self.restoring, "damping": self.damping,
                "input_mean": self.input_mean.tolist(), "output_mean": self.output_mean.tolist(),
                "output": self.output, "D": None if self.D is None else self.D.tolist(),
                "cut_hz": self.cut_hz}  # fmt: skip

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> StateSpaceStructure:
        """The model ``to_dict`` wrote."""
        return cls(np.asarray(d["A"], float), np.asarray(d["B"], float), np.asarray(d["C"], float), float(d["dt"]),
                   (int(d["element_at"][0]), int(d["element_at"][1])), float(d["r_ref_m"]),
                   np.asarray(d["input_mean"], float), np.asarray(d["output_mean"], float),
                   str(d.get("restoring", laws.DEFAULT_RESTORING)),
                   str(d.get("damping", laws.DEFAULT_DAMPING)), str(d.get("output", "displacement")),
                   None if d.get("D") is None else np.asarray(d["D"], float),
                   None if d.get("cut_hz") is None else float(d["cut_hz"]))  # fmt: skip
