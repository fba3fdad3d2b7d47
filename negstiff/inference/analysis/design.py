"""Which test next: the lab's next run designed from what the posterior still does not know.

A lab that has run one test and sampled its posterior asks which test to run now, at what level, frequency and
length, so that what it still does not know is pinned down. For each candidate test the rig can run (a
band-limited random run at a level, a harmonic at an amplitude and frequency, a linear swept sine at an amplitude),
within the limits the user states (duration, peak table acceleration, table stroke, the device's own travel),
draws of the posterior are run through the candidate on the virtual rig (``models.rig.Rig``) with the measurement
noise the record showed (the laser's sigma, the accelerometer's noise), and the information each simulated record
would add is read as the posterior itself reads a record: its multiple-shooting windows (``Windows.cut``, the start
states profiled), the residuals' Jacobian with the start-state directions projected out, and the two parts of the
curvature adjustment (``likelihood.information_parts``): the model's information H and the windows' score
covariance M (what the sensor chain's correlated noise leaves).

The criterion is the Laplace approximation of the expected posterior covariance after the test, the joint fit's
sandwich of the first record's parts and the test's, E_theta[sandwich(H_now + H_test(theta), M_now + M_test(theta))]
over the draws (``_after``; the first record's parts are the posterior's ``settings.laplace``), read relative to the
first record's own sandwich (Bayesian A-optimality in its Laplace form: Chaloner and
Verdinelli 1995, "Bayesian experimental design: a review", Statistical Science 10(3), 273-304; Ryan, Drovandi,
McGree and Pettitt 2016, "A review of modern computational algorithms for Bayesian optimal design", International
Statistical Review 84(1), 128-154), read as the expected shrinkage of the targeted parameters' 90 % intervals: each
interval's width now times sqrt(Var_after / Var_now), the score the geometric mean of width_now / width_after over
the targets. The expected information gain about the targets in the same approximation, 0.5 log(det Sigma_now /
det Sigma_after) [nats], is reported beside it. A grid of candidates is evaluated, and the best ones are searched
further in their continuous settings (level, frequency: bounded scalar and Nelder-Mead searches, the same noise
draws for every candidate so the criterion is a smooth function of the settings).

What it assumes, said in the result: the next record is read by a sensor chain like the rig's (a laser on the
moving part, the table's accelerometer integrated twice) with the noise levels the posterior found; the posterior is
Gaussian with its reported means, standard deviations and correlations (its JSON keeps no draws).
"""

from __future__ import annotations

import functools
import math
import numbers
import os
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from negstiff.errors import InputError, NegstiffWarning
from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS
from negstiff.inference.estimators.posterior.windows import PosteriorError

COEFFICIENTS = ("k1", "k2", "k3", "c", "c_nl")
"""The parameters a design can target (the coefficient posterior's)."""
NAMES = (*COEFFICIENTS, "k0")
"""The parameters the information is computed over (k0, the static offset, a nuisance the records share)."""
DEFAULT_RANDOM_RMS = 14.0
"""The rig's default random test level [m/s^2 rms, 2-40 Hz] (``Rig.random``): the reference each design is
compared with."""
DEFAULT_MAX_ACC = 80.0
"""Default peak table acceleration [m/s^2] (8 g: a small electrodynamic shaker's with a 0.2 kg device)."""
BAND = (2.0, 40.0)
"""The random test's band and the sweep's start and stop [Hz] (the rig's default excitation band)."""
CAMPAIGN_STEPS = 4
"""A stepped campaign's amplitude steps (``level`` / 4, / 2, 3 / 4, ``level``) at one frequency, the duration shared
between their records, as the reference study stepped its harmonic campaign."""
SINUSOIDAL = ("harmonic", "campaign")
"""The kinds set by an amplitude and a frequency (searched over both; drawn over both)."""
RING_DOWN_TESTS = ("hammer", "release")
"""The tests of a device fixed to the ground, read as ring-downs (a hammer's hits, a release from a held position):
the candidates of a hammer's or a free decay's posterior, whose joint fit reads windows of free decay."""
HAMMER_WIDTH_S = 0.004
"""A hammer hit's half-sine duration [s]: a modal hammer's medium tip on a light structure (1-5 ms)."""
HAMMER_MIN_N = 2.0
"""The lightest hit [N] a design plans: the rig's load cell (0.05 N of noise) tells a hit from its floor at 30x it."""
HAMMER_HITS = (2, 4, 8)
"""A hammer test's hit counts on the grid (evenly spread over the record)."""


class CoefficientReading:
    """How a single DOF's coefficient posterior reads a record (``Windows.cut``, the start states profiled, k0 a
    nuisance): the parameters ``NAMES``, the polynomial model, its motion and the information one record carries.
    The design's part for that posterior; ``ElementReading`` is a structure's element posterior's (the posterior's
    two likelihoods, ``posterior.core`` and ``posterior.structure``: the design reads a record as its posterior
    would, through this part, and is otherwise the same for both).
    """

    names: tuple[str, ...] = NAMES
    sensors = "a laser on the moving part"

    def system(self, theta: np.ndarray, mass: float):
        """The polynomial model of the parameters ``theta`` (over ``NAMES``) with the posterior's mass."""
        from negstiff.models import Model

        return Model(m=mass, **{n: float(v) for n, v in zip(NAMES, theta, strict=True)})

    def element(self, system):
        """The law whose equilibria are the wells (the model itself)."""
        return system

    def frequencies(self, system) -> list[float]:
        """The wells' underlying-linear frequencies [Hz]."""
        return [system.uls(w).f_hz for w in ("minus", "plus")]

    def motion(self, rec) -> tuple[np.ndarray, np.ndarray]:
        """A rig record's true motion across the element (z) and every moving part's, (channels, T)."""
        z = np.asarray(rec.true["z"])
        return z, z[None, :]

    def information(self, state: PosteriorState, model, m) -> tuple[np.ndarray, np.ndarray] | None:
        """The model information H and the windows' score covariance M (over ``NAMES``, in the parameters' units) of
        a record ``m`` (a ``Measurement``) of ``model`` as the posterior reads it (``likelihood.information_parts``; a
        hammer's or release's record as a ring-down, its windows the free decays between the pulses), or None where a
        run diverges.
        """
        from negstiff.inference.analysis.record_kind import identification_record, record_kind
        from negstiff.inference.estimators.posterior.likelihood import information_parts
        from negstiff.inference.estimators.posterior.parametrisation import coefficient_parametrisation
        from negstiff.inference.estimators.posterior.windows import Windows

        ring_down = state.bench == "ring-down"
        if ring_down:  # as the posterior reads a hammer's record or a decay (``Posterior.point_estimate``)
            m = identification_record(m, record_kind(m))
        win = Windows.cut(m, state.window_s, state.max_windows, free=ring_down)
        par = coefficient_parametrisation(model)
        th = np.array([getattr(model, n) for n in par.names])
        kind = par.kind
        p0 = par.to_params(th[None])[:, 0]
        win.refine_states(p0, kind)
        win.set_sensitivities(p0, kind)
        x_scale = np.maximum(np.abs(th), 1e-6)
        h = 1e-5 * x_scale

        def projected(point: np.ndarray):
            """The projected residuals at ``point`` and their Jacobian (x coordinates), one batched simulation of
            the point and its finite-difference neighbours; None where a run diverges.
            """
            thetas = np.vstack([point, point + np.diag(h)])
            zsim, div = win.simulate(par.to_params(thetas), kind)
            if div.any():
                return None
            res = win.residuals(zsim).reshape(len(thetas), -1)  # (1 + p, W L)
            return res[0], np.stack([(res[0] - res[1 + i]) / (h[i] / x_scale[i]) for i in range(len(point))], axis=1)

        at = projected(th)
        if at is None:
            return None
        # The sensor's noise alone: the posterior's likelihood also carries the input's noise through each window's
        # response (``Windows.set_input_noise``), which changed the predicted widths by 0.2 % on a 20 s record
        # (measured) and cost three times the rest of the evaluation.
        sigma = math.sqrt(win.mean_square(at[0]))
        # The sandwich read where the posterior reads it, at the record's MAP point (one Gauss-Newton step from the
        # draw): there the parameters have taken up what the sensor chain's systematic error (the integrated
        # accelerometer's) resembles, and the windows' scores are smaller. Read at the draw itself, the inflation was
        # twice the posterior's (10.3 against 4.9 on one 20 s record) and the predicted widths 1.2-1.7x the
        # posterior's.
        step = np.linalg.lstsq(at[1], at[0], rcond=None)[0] * x_scale
        res0, J = projected(th + step) or at
        H_x, M_x = information_parts(J, res0, win.n_windows, sigma)
        per = 1.0 / np.outer(x_scale, x_scale)
        order = np.ix_(*[[par.names.index(n) for n in NAMES]] * 2)
        return (H_x * per)[order], (H_x if M_x is None else M_x * per)[order]


@dataclass(frozen=True)
class ElementReading:
    """How a structure's element posterior reads a record (``posterior.structure``: every channel's windows, each
    started where the element follows it best, its start-state directions projected off; each channel's zero and the
    linear structure's springs and dampers nuisances, the masses given): its parameters (``names``), the structure,
    its motion and the information one record carries (``CoefficientReading``'s counterpart).
    """

    structure: dict[str, Any]
    """The structure the posterior holds fixed but its element's coefficients (``Structure.to_dict``)."""

    @functools.cached_property
    def names(self) -> tuple[str, ...]:
        """The element's coefficients and, nuisances, each channel's zero and the linear structure's springs and
        dampers (the structure's posterior's: ``posterior.structure.zero_names``, ``linear_parts``).
        """
        from negstiff.inference.estimators.posterior.structure import linear_parts, zero_names
        from negstiff.models.structure import Structure

        parts = linear_parts(Structure.from_dict(self.structure))
        return (*COEFFICIENTS, *zero_names(len(self.structure["masses"])), *(n for n, _, _ in parts))

    @property
    def sensors(self) -> str:
        """The sensor chain the next record is read by, in words."""
        return f"a laser on each of the {len(self.structure['masses'])} DOFs"

    def system(self, theta: np.ndarray, mass: float):
        """The structure of the parameters ``theta`` (over ``names``): its element's coefficients and its springs and
        dampers (the channels' zeros do not change it).
        """
        from negstiff.inference.estimators.posterior.structure import linear_parts, with_linear_parts
        from negstiff.models.structure import Structure

        s = Structure.from_dict(self.structure)
        values: dict[str, Any] = {n: float(v) for n, v in zip(COEFFICIENTS, theta, strict=False)}
        parts = linear_parts(s)
        s = s.with_element(replace(s.element, **values))
        return with_linear_parts(s, parts, theta[len(theta) - len(parts) :]) if parts else s

    def element(self, system):
        """The element's law as its wells see it (``Structure.element_law``)."""
        return system.element_law()

    def frequencies(self, system) -> list[float]:
        """Every underlying-linear mode's frequency [Hz] at each well."""
        wells = system.element_equilibria()
        return [m.f_hz for w in ("minus", "plus") if getattr(wells, f"z_{w}") is not None for m in system.modes(w)]

    def motion(self, rec) -> tuple[np.ndarray, np.ndarray]:
        """A rig record's true motion across the element (r = z_J - z_I) and every DOF's, (N, T)."""
        from negstiff.models.structure import relative

        z = np.atleast_2d(np.asarray(rec.true["z"]))
        return relative(z, tuple(self.structure["at"])), z

    def information(self, state: PosteriorState, structure, m) -> tuple[np.ndarray, np.ndarray] | None:
        """H and M (over ``names``: the element's coefficients and its nuisances) of a record ``m`` (a
        ``Measurement``) of ``structure`` as its posterior reads it (``posterior.structure.record_windows``; a
        ring-down's windows between its pulses), at the record's MAP point one Gauss-Newton step from the draw (as
        ``CoefficientReading``'s), or None where a window diverges.
        """
        from negstiff.inference.analysis.record_kind import identification_record, record_kind
        from negstiff.inference.estimators.posterior.likelihood import information_parts
        from negstiff.inference.estimators.posterior.structure import (
            element_values,
            followed_windows,
            linear_parts,
            record_windows,
            residuals_and_jacobian,
        )

        ring_down = state.bench == "ring-down"
        if ring_down:
            m = identification_record(m, record_kind(m))
        sim, data, starts, L = record_windows(structure, m, np.zeros(m.n_dof), state.window_s, state.max_windows,
                                              ring_down)  # fmt: skip
        # the windows the posterior would leave out, left out (one ``PosteriorError`` where it would refuse)
        sim, data, _ = followed_windows(sim, data, starts, L, structure, m, element_values(structure))
        # the zeros the simulated record's own (none), the springs and dampers the structure's
        theta = np.r_[element_values(structure), np.zeros(m.n_dof), [v for _, _, v in linear_parts(structure)]]
        r0, J = residuals_and_jacobian(sim, data, theta)
        if not (np.all(np.isfinite(r0)) and np.all(np.isfinite(J))):
            return None
        r1, J1 = residuals_and_jacobian(sim, data, theta + np.linalg.lstsq(J, -r0, rcond=None)[0])
        if np.all(np.isfinite(r1)) and np.all(np.isfinite(J1)):
            r0, J = r1, J1
        n_obs = data.size - sim.W * 2 * m.n_dof  # the start states profiled out
        sigma = math.sqrt(float(np.sum(r0**2)) / n_obs)
        H, M = information_parts(J, r0, sim.W, sigma)
        return H, (H if M is None else M)


@dataclass(frozen=True)
class Limits:
    """What the lab's rig can do: the record's duration [s], the peak table acceleration [m/s^2] and displacement
    [m] (None: no limit stated; a shaker's tests), the hammer's peak force [N] (a hammer's tests), the device's
    travel [m] (its largest excursion from the saddle before a stop;
    None: no stop), and the displacement sensor's measuring range [m] (the span its reading may cover: the laser on
    the moving part reads the device's motion and the table's together; None: no range stated).
    """

    duration_s: float
    max_table_acc: float = DEFAULT_MAX_ACC
    max_table_disp: float | None = None
    stroke: float | None = None
    sensor_range: float | None = None
    max_force: float | None = None
    """The hammer's peak force [N] (a ring-down posterior's tests; None: no limit stated)."""


@dataclass(frozen=True)
class Candidate:
    """One test the rig can run: ``kind`` random (``level`` the table acceleration's rms over ``BAND``), harmonic
    (``level`` its amplitude at ``freq``), sweep (``level`` the amplitude of a linear sweep over ``BAND``) or campaign
    (``CAMPAIGN_STEPS`` harmonic steps at ``freq`` up to ``level``, one record each, the table not stopped).
    """

    kind: str
    level: float
    freq: float | None = None
    hits: int | None = None
    """A hammer test's hits (``level`` their peak force [N]); a release's ``level`` is its start's offset [m]
    from the plus well the device rests in (positive above it, away from any saddle; negative below it, towards the
    saddle or past it)."""

    def run(self, rig, duration: float):
        """The rig's record of this test, ``duration`` seconds long (a harmonic: whole periods)."""
        if self.kind == "hammer":
            assert self.hits is not None
            return rig.hammer(peak=self.level, hits=self.hits, duration=duration, width=HAMMER_WIDTH_S)
        if self.kind == "release":  # from the plus well (``Equilibria``: above its saddle, where there is one)
            return rig.release(rig.equilibria.z_plus + self.level, duration=duration)
        if self.kind == "random":
            return rig.random(duration=duration, rms=self.level, band=BAND, settle=2.0)
        if self.kind == "sweep":
            # 3 s of settling, the first half the controller's ramp-up: after a 0.5 s ramp a 10 m/s^2 sweep's z
            # was 2.1 mm off (the table's slow motion the lab's 1 Hz integration misses), after 1.5 s 0.29 mm
            return rig.sine_sweep(f_start=BAND[0], f_stop=BAND[1], amplitude=self.level, duration=duration,
                                  settle=3.0)  # fmt: skip
        assert self.freq is not None and self.kind == "harmonic", "a campaign is several records: ``records``"
        periods = int(math.floor(duration * self.freq + 1e-9))  # whole periods within the duration
        return rig.harmonic(freq=self.freq, amplitude=self.level, settle_periods=10, record_periods=max(periods, 1))

    def amplitudes(self) -> list[float]:
        """A campaign's steps [m/s^2]."""
        return [self.level * (k + 1) / CAMPAIGN_STEPS for k in range(CAMPAIGN_STEPS)]

    def records(self, rig, duration: float) -> list:
        """The rig's records of this test: one, or a campaign's one per step (``duration`` shared between them, each
        step's whole periods after ten of settling).
        """
        if self.kind != "campaign":
            return [self.run(rig, duration)]
        assert self.freq is not None
        periods = max(2, int(math.floor(duration * self.freq / CAMPAIGN_STEPS + 1e-9)))
        return rig.sweep(self.freq, self.amplitudes(), settle_periods=10, record_periods=periods)

    def table_disp_bound(self) -> float:
        """The table's peak displacement [m] a sinusoidal test asks for (its lowest frequency's A / w^2)."""
        if self.kind in ("random", *RING_DOWN_TESTS):
            return 0.0  # a random run's is read from its record (``evaluate``); a hammer's or release's table is still
        f = self.freq if self.kind in SINUSOIDAL and self.freq is not None else BAND[0]
        return self.level / (2 * math.pi * f) ** 2

    def describe(self) -> str:
        """One line a lab reads."""
        if self.kind == "hammer":
            return f"{self.hits} hammer hits of {self.level:.3g} N ({1e3 * HAMMER_WIDTH_S:g} ms half-sine)"
        if self.kind == "release":
            where = "above" if self.level > 0 else "below"  # the plus well: above it, away from any saddle
            return f"free decay released {1e3 * abs(self.level):.3g} mm {where} rest"
        if self.kind == "random":
            return f"random {self.level:.3g} m/s^2 rms, {BAND[0]:g}-{BAND[1]:g} Hz"
        if self.kind == "sweep":
            return f"linear sine sweep {BAND[0]:g}-{BAND[1]:g} Hz at {self.level:.3g} m/s^2"
        if self.kind == "campaign":
            return f"stepped campaign {self.freq:.3g} Hz, {CAMPAIGN_STEPS} steps to {self.level:.3g} m/s^2"
        return f"harmonic {self.freq:.3g} Hz at {self.level:.3g} m/s^2"

    def to_json(self) -> dict[str, Any]:
        """The test's settings."""
        out: dict[str, Any] = {"kind": self.kind, "test": self.describe()}
        if self.kind == "hammer":
            out.update(peak_force_n=self.level, hits=self.hits, width_s=HAMMER_WIDTH_S)
        elif self.kind == "release":
            out.update(release_offset_m=self.level)
        elif self.kind == "random":
            out.update(rms_m_s2=self.level, band_hz=list(BAND))
        elif self.kind == "sweep":
            out.update(amplitude_m_s2=self.level, f_start_hz=BAND[0], f_stop_hz=BAND[1])
        else:
            out.update(amplitude_m_s2=self.level, freq_hz=self.freq)
            if self.kind == "campaign":
                out["steps_m_s2"] = self.amplitudes()
        return out


@dataclass
class PosteriorState:
    """What a design needs of a coefficient posterior's JSON: the Gaussian over ``names`` (means, sds,
    correlations), the 90 % widths now, the noise levels, the mass and the windows the posterior read.
    """

    mean: np.ndarray
    cov: np.ndarray
    widths: dict[str, float]
    hdi_prob: float
    sigma: float
    input_noise: float
    mass: float
    fs: float
    window_s: float
    max_windows: int
    duration_s: float
    source: str = ""
    bench: str = "table"
    """Which tests the lab's next run is chosen from: ``"table"`` (a base-excited record's posterior: the shaking
    table's random, harmonic, swept and stepped tests) or ``"ring-down"`` (a hammer's or a free decay's posterior:
    hammer hits and releases, ``RING_DOWN_TESTS``)."""
    information: np.ndarray | None = None
    """The first record's model information H over ``names`` (the posterior's ``settings.laplace``), or None
    (a posterior written before it was kept: the records' adjusted informations are then added instead)."""
    score_covariance: np.ndarray | None = None
    """The first record's windows' score covariance over ``names`` (the sandwich's meat), or None."""
    reading: Any = field(default_factory=lambda: CoefficientReading())
    """How the posterior reads a record (``CoefficientReading``, a structure's ``ElementReading``): its parameters,
    its system and the information a record carries."""

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters the Gaussian is over (``reading.names``)."""
        return tuple(self.reading.names)

    @classmethod
    def from_json(cls, res: dict[str, Any], source: str = "") -> PosteriorState:
        """The state of a posterior result (``Posterior.result()`` or its file); one ``InputError`` for a posterior
        a design cannot read (another model, a law's, a structure's, a record of another kind, an old file).
        """
        if not isinstance(res, dict) or "parameters" not in res or "settings" not in res:
            raise InputError(f"{source or 'the posterior'}: not a posterior result (no parameters and settings)")
        s = res["settings"]
        where = source or "the posterior"
        reading: CoefficientReading | ElementReading = CoefficientReading()
        if "element_at" in s:  # a structure's element posterior (``posterior.structure``): its start structure held
            if not isinstance(s.get("start"), dict) or "structure" not in s["start"]:
                raise InputError(f"{where}: a structure's posterior without its start structure")
            if "records" in s:
                raise InputError(f"{where}: a joint posterior of {len(s['records'])} records of a structure; the "
                                 "design reads one record's element posterior (its channels' zeros are that "
                                 "record's)")  # fmt: skip
            reading = ElementReading(dict(s["start"]["structure"]))
        names = reading.names
        if s.get("model") != "coefficients" or "law" in s:
            what = f"law {s['law']['restoring']}" if "law" in s else f"model {s.get('model')}"
            raise InputError(f"{where}: a posterior of the {what}; the design reads the coefficient posterior "
                             "(k1, k2, k3, c, c_nl)")  # fmt: skip
        kind = s.get("record_kind")
        if kind is None:
            raise InputError(f"{where}: written before posteriors recorded their record's kind: sample it again")
        ring_down = kind in RING_DOWN_KINDS
        if not ring_down and (kind != "base" or s.get("input") != "base_acc"):
            raise InputError(f"{where}: a posterior of a {kind} record ({s.get('input')}); the design plans "
                             "shaker-table tests from a base-excited record's posterior, and hammer hits and "
                             "releases from a hammer's or a free decay's")  # fmt: skip
        params = {**res.get("nuisance_parameters", {}), **res["parameters"]}
        missing = [n for n in names if n not in params]
        if missing:
            raise InputError(f"{where}: no {', '.join(missing)} among its parameters")
        sd = np.array([params[n]["sd"] for n in names], float)
        corr = res.get("correlation") or {}
        C = np.array([[corr.get(a, {}).get(b, 1.0 if a == b else 0.0) for b in names] for a in names], float)
        cov = C * np.outer(sd, sd)
        noise = "sigma" if "sigma" in params else "sigma_1"
        said = s.get("input_noise", {})
        rms = said.get("rms")  # a structure's posterior does not carry it: the record's reading of it (``record_rms``)
        rms = said.get("record_rms", 0.0) if rms is None else rms
        rms = float(rms[0] if isinstance(rms, list) else rms or 0.0)
        dur = s.get("duration_s")
        if ring_down and not float(s.get("fs", 0.0)) * HAMMER_WIDTH_S >= 2:
            raise InputError(f"{where}: a record at {s.get('fs')} Hz: a hammer's {1e3 * HAMMER_WIDTH_S:g} ms hit needs "
                             f"{2 / HAMMER_WIDTH_S:g} Hz at least (two samples of the load cell)")  # fmt: skip
        if ring_down and not (s.get("model_mass") or s.get("mass")):
            raise InputError(f"{where}: a ring-down's posterior without the device's mass (its coefficients per unit "
                             "mass): a hammer's force in N needs it (weigh the device: --mass)")  # fmt: skip
        if not ring_down and not float(s.get("fs", 0.0)) > 2.5 * BAND[1]:
            raise InputError(f"{where}: a record at {s.get('fs')} Hz: the rig's tests reach {BAND[1]:g} Hz, which "
                             f"needs a record above {2.5 * BAND[1]:g} Hz")  # fmt: skip
        out = cls(
            mean=np.array([params[n]["mean"] for n in names], float),
            cov=0.5 * (cov + cov.T),
            widths={n: float(params[n]["hdi_high"] - params[n]["hdi_low"]) for n in COEFFICIENTS},
            hdi_prob=float(res.get("hdi_prob", 0.9)),
            sigma=float(params[noise]["mean"]),
            input_noise=rms,
            mass=float(s.get("model_mass") or s.get("mass") or 1.0),
            fs=float(s["fs"]),
            window_s=float(s["window_s"]),
            max_windows=int(s.get("max_windows") or 240),  # the posterior's cap (a longer test: more windows)
            duration_s=float(dur[0] if isinstance(dur, list) else dur),
            source=source,
            bench="ring-down" if ring_down else "table",
            **_laplace_parts(s.get("laplace"), names),
            reading=reading,
        )
        try:
            eq = out.wells(out.mean)
        except (ValueError, ArithmeticError) as exc:
            raise InputError(f"{where}: its mean model has no usable well ({exc})") from None
        if eq.z_minus is None and not ring_down:
            raise InputError(f"{where}: its mean model has a single well; the design reads a double well's posterior "
                             "(both wells' frequencies place its harmonics)")  # fmt: skip
        return out

    def rig(self, model, seed: int):
        """The virtual rig running ``model`` with the noise the posterior found (the laser's sigma, the
        accelerometer's noise), at the record's rate.
        """
        from negstiff.models.rig import Rig, Sensors

        sensors = Sensors(laser_noise=self.sigma, acc_noise=max(self.input_noise, 1e-9))
        return Rig(model, sensors=sensors, fs=self.fs, seed=seed)

    def rest_scale(self) -> float:
        """The mean model's own length scale of its resting (plus) well [m], on which the ring-down tests' grids
        are laid: the distance to the saddle of a double well; of a single well, the amplitude at which the cubic
        doubles its stiffness, sqrt(k_lin / (3 k3)).
        """
        law = self.reading.element(self.model_at(self.mean))
        eq = law.equilibria()
        if eq.z_0 is not None:
            return abs(eq.z_plus - eq.z_0)
        return math.sqrt(max(law.uls("plus").k1_tilde, 1e-12) / (3 * law.k3))

    def model_at(self, theta: np.ndarray):
        """The system of the parameters ``theta`` (over ``names``): the polynomial model with the posterior's mass,
        or a structure's with the element's coefficients (``reading.system``).
        """
        return self.reading.system(theta, self.mass)

    def wells(self, theta: np.ndarray):
        """The equilibria of the element's motion at the parameters ``theta`` (a single DOF's: its z)."""
        return self.reading.element(self.model_at(theta)).equilibria()

    def draws(self, n: int, seed: int) -> np.ndarray:
        """``n`` draws of the Gaussian posterior, each a usable model (k3, c, c_nl >= 0; two wells for a table's
        tests, a plus well to rest in for a ring-down's); the first is the mean.
        """
        rng = np.random.default_rng(seed)
        names = self.names
        L = np.linalg.cholesky(self.cov + 1e-30 * np.eye(len(names)))
        k3, c, c_nl = (names.index(n) for n in ("k3", "c", "c_nl"))
        out = [self.mean]
        for _ in range(100 * n):
            if len(out) >= n:
                break
            th = self.mean + L @ rng.standard_normal(len(names))
            if th[k3] > 0 and th[c] >= 0 and th[c_nl] >= 0:
                try:
                    eq = self.wells(th)
                    if self.bench != "table" or eq.z_minus is not None:
                        out.append(th)
                except (ValueError, ArithmeticError):
                    continue
        return np.array(out[:n])


@dataclass
class Evaluation:
    """One candidate's predicted outcome: the expected covariance after the test, the targets' widths, the score
    (geometric-mean shrinkage of the targets' intervals), the information gain and what the test costs.
    """

    candidate: Candidate
    cov_after: np.ndarray
    widths_after: dict[str, float]
    score: float
    eig_nats: float
    cost: dict[str, Any]
    problems: list[str] = field(default_factory=list)

    @property
    def feasible(self) -> bool:
        """Within every limit."""
        return not self.problems

    def to_json(self, widths_now: dict[str, float]) -> dict[str, Any]:
        """The candidate's row of the design's result."""
        return {**self.candidate.to_json(), "score": self.score, "eig_nats": self.eig_nats,
                "predicted_width": self.widths_after,
                "shrink": {n: widths_now[n] / w for n, w in self.widths_after.items()},
                "cost": self.cost, "feasible": self.feasible, "problems": self.problems}  # fmt: skip


def _information(state: PosteriorState, candidate: Candidate, limits: Limits, theta: np.ndarray, seed: int):
    """The information (over ``state.names``) the records of ``candidate`` under the parameters ``theta`` would
    carry, as the posterior reads them (module docstring), and what the run costs.
    """
    from negstiff.inference.record.measurement import Measurement

    model = state.model_at(theta)
    recs = candidate.records(state.rig(model, seed), limits.duration_s)
    cost = record_cost(state, model, recs)
    # independent records' information and score covariance add (a campaign's steps: the joint posterior reads each
    # with its own windows, and its sandwich sums both parts over all windows)
    H = M = None
    for rec in recs:
        parts = state.reading.information(state, model, Measurement.from_rig(rec))
        if parts is None:
            return None, cost
        H = parts[0] if H is None else H + parts[0]
        M = parts[1] if M is None else M + parts[1]
    return (H, M), cost


def record_cost(state: PosteriorState, model, recs: list) -> dict[str, float]:
    """What the rig's records ``recs`` of ``model`` cost: their duration, the table's peak acceleration and
    displacement, the device's travel from its saddle, the span the displacement sensor reads, and the share of
    the time spent in the other well.
    """
    eq = state.reading.element(model).equilibria()
    centre = eq.z_0 if eq.z_0 is not None else eq.z_plus
    motions = [state.reading.motion(r) for r in recs]  # the element's motion (a single DOF's z), every DOF's
    z_all = np.concatenate([m[0] for m in motions])
    table = [np.asarray(r.true["base_disp"]) if "base_disp" in r.true else 0.0 for r in recs]  # still: a hammer's
    cost = {"duration_s": float(z_all.size / state.fs)}
    if "base_acc" in recs[0].true:
        cost["peak_table_acc_m_s2"] = max(float(np.max(np.abs(r.true["base_acc"]))) for r in recs)
        cost["peak_table_disp_m"] = max(float(np.max(np.abs(b))) for b in table)
    else:
        # the hits' set peak (the load cell's samples may fall either side of it: 8 % low at 1 kHz, measured)
        cost["peak_force_n"] = max(float(r.truth["excitation"].get("peak_n", 0.0)) for r in recs)
    cost["peak_travel_m"] = float(np.max(np.abs(z_all - centre)))
    # the span a laser on a moving part reads (its motion and the table's), the widest of them
    cost["sensor_span_m"] = max(float(np.max(np.ptp(m[1] + b, axis=-1))) for m, b in zip(motions, table, strict=True))
    # of a single well (a ring-down's draw): no other well to visit
    other = np.sign(z_all - centre) != np.sign(eq.z_plus - centre)
    cost["other_well_share"] = 0.0 if eq.z_0 is None else float(np.mean(other))
    return cost


def limit_problems(candidate: Candidate, cost: dict[str, float], limits: Limits) -> list[str]:
    """The limits a test's records (``cost``, the worst over the draws) exceed, one line each: a random run's peak
    table acceleration and displacement (read from its records; a sinusoidal test's are checked from its settings
    in ``evaluate``), the duration, the sensor's range and the device's stroke.
    """
    problems = []
    if candidate.kind == "hammer" and limits.max_force is not None and candidate.level > limits.max_force:
        problems.append(f"peak force {candidate.level:.3g} N above the hammer's {limits.max_force:g} N")
    if candidate.kind == "random":
        problems += _peak_acc_problems(cost["peak_table_acc_m_s2"], limits)
        if limits.max_table_disp is not None and cost["peak_table_disp_m"] > limits.max_table_disp:
            problems.append(f"table stroke {1e3 * cost['peak_table_disp_m']:.3g} mm above the shaker's "
                            f"{1e3 * limits.max_table_disp:g} mm")  # fmt: skip
    if cost["duration_s"] > limits.duration_s * (1 + 1e-6):
        problems.append(f"its record lasts {cost['duration_s']:.3g} s, beyond the {limits.duration_s:g} s asked")
    if limits.sensor_range is not None and cost["sensor_span_m"] > limits.sensor_range:
        problems.append(f"the displacement sensor would read a {1e3 * cost['sensor_span_m']:.3g} mm span, beyond its "
                        f"{1e3 * limits.sensor_range:g} mm range")  # fmt: skip
    if limits.stroke is not None and cost["peak_travel_m"] > limits.stroke:
        problems.append(f"the device travels {1e3 * cost['peak_travel_m']:.3g} mm from its saddle, beyond its "
                        f"{1e3 * limits.stroke:g} mm stroke (a stop)")  # fmt: skip
    return problems


def _laplace_parts(laplace: Any, names: tuple[str, ...] = NAMES) -> dict[str, np.ndarray]:
    """The first record's model information and score covariance over ``names`` from a posterior's
    ``settings.laplace``; empty where the posterior has none (or another parameter set).
    """
    if not isinstance(laplace, dict) or laplace.get("score_covariance") is None:
        return {}
    kept = list(laplace.get("parameters", []))
    if sorted(kept) != sorted(names):
        return {}
    order = np.ix_(*[[kept.index(n) for n in names]] * 2)
    return {"information": np.asarray(laplace["information"], float)[order],
            "score_covariance": np.asarray(laplace["score_covariance"], float)[order]}  # fmt: skip


def _after(state: PosteriorState, parts: tuple[np.ndarray, np.ndarray], P0inv: np.ndarray) -> np.ndarray:
    """The posterior covariance (over ``state.names``) expected after a test whose records carry ``parts`` (H, M).

    The joint posterior's Laplace covariance is the sandwich of the summed parts, sandwich(H_1 + H, M_1 + M)
    (``likelihood.sandwich``): the joint estimate weights the records by their model information H, not by what
    each really carries. Adding each record's adjusted information instead (the optimal weighting, which the joint
    fit does not do) predicted the joint widths of k1-k3 1.3-1.4x too narrow on the rig's 20 s records, where the
    first record's variance inflation was 3 and a designed harmonic's 13. The result is read relative to the
    first record's own sandwich and applied to the posterior's covariance (its sampled spread), so that only the
    shrinkage is the approximation's. A posterior without its parts (written before they were kept): the
    records' adjusted informations added to the posterior's precision ``P0inv``.
    """
    from negstiff.inference.estimators.posterior.likelihood import sandwich

    def cov(H: np.ndarray, M: np.ndarray) -> np.ndarray:
        # in coordinates where H's diagonal is 1: in the parameters' units H spans ten decades (k3 against k0)
        # and its eigenvalue floor would cut the small ones (the sandwich's V is the same in any coordinates)
        d = 1.0 / np.sqrt(np.diag(H))
        return sandwich(H * np.outer(d, d), M * np.outer(d, d))[1] * np.outer(d, d)

    H, M = parts
    if state.information is None or state.score_covariance is None:
        return np.linalg.pinv(P0inv + np.linalg.pinv(cov(H, M), hermitian=True), hermitian=True)
    now = cov(state.information, state.score_covariance)
    after = cov(state.information + H, state.score_covariance + M)
    scale = np.sqrt(np.diag(state.cov) / np.diag(now))
    return after * np.outer(scale, scale)


def evaluate(state: PosteriorState, candidate: Candidate, limits: Limits, targets: tuple[str, ...],
             draws: np.ndarray, seed: int) -> Evaluation:  # fmt: skip
    """The expected outcome of ``candidate`` over the posterior's ``draws`` (module docstring); the noise of each
    draw's record seeded ``seed + d`` (the same for every candidate: common random numbers).
    """
    from negstiff.models.records import RigError

    problems = []
    if candidate.kind in ("harmonic", "campaign", "sweep") and candidate.level > limits.max_table_acc:
        problems.append(f"amplitude {candidate.level:.3g} m/s^2 above the table's {limits.max_table_acc:g} m/s^2")
    if limits.max_table_disp is not None and candidate.table_disp_bound() > limits.max_table_disp:
        problems.append(f"table stroke {1e3 * candidate.table_disp_bound():.3g} mm above the shaker's "
                        f"{1e3 * limits.max_table_disp:g} mm")  # fmt: skip
    P0inv = np.linalg.pinv(state.cov, hermitian=True)
    covs, costs, eigs = [], [], []
    idx = [state.names.index(n) for n in targets]
    for d, th in enumerate(draws):
        try:
            info, cost = _information(state, candidate, limits, th, seed + d)
        except PosteriorError as exc:  # too short for the posterior's windows (a harmonic's whole periods)
            return Evaluation(candidate, state.cov, dict(state.widths), 1.0, 0.0, {},
                              [*problems, f"its record cannot be read: {exc}"])  # fmt: skip
        except RigError as exc:  # a hit or a release that throws a draw out of every well, or a test the rig refuses
            return Evaluation(candidate, state.cov, dict(state.widths), 1.0, 0.0, {},
                              [*problems, f"the rig cannot run it: {exc}"])  # fmt: skip
        costs.append(cost)
        if info is None:
            problems.append("the model diverges under this test (a draw of the posterior leaves every well)")
            break
        after = _after(state, info, P0inv)
        covs.append(after)
        sub_now, sub_after = state.cov[np.ix_(idx, idx)], after[np.ix_(idx, idx)]
        eigs.append(0.5 * (np.linalg.slogdet(sub_now)[1] - np.linalg.slogdet(sub_after)[1]))
    cost = {k: float(np.max([c[k] for c in costs])) for k in costs[0]}
    cost["other_well_share"] = float(np.mean([c["other_well_share"] for c in costs]))
    # the risk that the test does not do what it is chosen for: in how many draws the record visits both wells
    cost["draws_visiting_both_wells"] = float(np.mean([0.05 < c["other_well_share"] < 0.95 for c in costs]))
    problems += limit_problems(candidate, cost, limits)
    if not covs:
        return Evaluation(candidate, state.cov, dict(state.widths), 1.0, 0.0, cost, problems)
    after = np.mean(covs, axis=0)  # the expected posterior covariance (Laplace) over the draws
    # each target's width after the test, the mean over the draws of each draw's width (the width now scaled by
    # the Laplace sd's shrinkage): the width a run of the test is expected to give. (The width of the mean
    # covariance, dominated by the draws that teach least, was 25-40 % wider than the realised on the rig's
    # 20 s records: docs/methods/design.md.)
    i = [state.names.index(n) for n in targets]
    ratio = np.sqrt(np.maximum(np.array([np.diag(c)[i] for c in covs]), 0.0) / np.diag(state.cov)[i])  # (D, T)
    widths = {n: state.widths[n] * float(np.mean(ratio[:, k])) for k, n in enumerate(targets)}
    cost["width_spread"] = {n: [state.widths[n] * float(np.min(ratio[:, k])), state.widths[n] *
                                float(np.max(ratio[:, k]))] for k, n in enumerate(targets)}  # fmt: skip
    score = math.exp(float(np.mean([math.log(state.widths[n] / widths[n]) for n in targets])))
    return Evaluation(candidate, after, widths, score, float(np.mean(eigs)), cost, problems)


def _peak_acc_problems(peak: float, limits: Limits) -> list[str]:
    """A random test's record whose peak table acceleration [m/s^2] exceeds the table's, said in one line."""
    if peak <= limits.max_table_acc:
        return []
    return [f"peak table acceleration {peak:.3g} m/s^2 above the table's {limits.max_table_acc:g} m/s^2"]


def _harmonic_band(state: PosteriorState) -> tuple[float, float]:
    """The harmonics' frequencies [Hz]: half the lowest underlying-linear frequency of the wells to 2.5 times the
    highest (a structure's: of every mode at each well; within fs / 8).
    """
    f_wells = state.reading.frequencies(state.model_at(state.mean))
    return max(1.0, 0.5 * min(f_wells)), min(state.fs / 8, 2.5 * max(f_wells))


def _hammer_force(state: PosteriorState, amplitude: float) -> float:
    """The peak force [N] of a ``HAMMER_WIDTH_S`` half-sine hit that sets the mean model ringing at about
    ``amplitude`` [m] in its plus well: impulse 2 F w / pi = m v0, v0 = amplitude x the well's angular frequency (a
    structure's: its element's well, the hit on the DOF the element moves, of its mass).
    """
    w = 2 * math.pi * state.reading.element(state.model_at(state.mean)).uls("plus").f_hz
    return amplitude * w * state.mass * math.pi / (2 * HAMMER_WIDTH_S)


def _ring_down_levels(state: PosteriorState, limits: Limits, kind: str) -> tuple[float, float]:
    """The span of a ring-down test's level: a hit ringing at 0.1 to 3 times the rest well's scale
    (``PosteriorState.rest_scale``, within the hammer's force), a release 0.1 to 3 times it away from rest.
    """
    scale = state.rest_scale()
    if kind == "hammer":
        lo, hi = _hammer_force(state, 0.1 * scale), _hammer_force(state, 3.0 * scale)
        if limits.max_force is not None:
            hi = min(hi, limits.max_force)
            lo = min(lo, hi / 4)
        return max(lo, HAMMER_MIN_N), max(hi, HAMMER_MIN_N)
    return 0.1 * scale, 3.0 * scale


def ring_down_reference(state: PosteriorState, limits: Limits) -> Candidate:
    """The reference a ring-down posterior's design is compared with (its record's own test is not in the
    posterior's file): four hits ringing at half the rest well's scale, within the hammer's force.
    """
    force = _hammer_force(state, 0.5 * state.rest_scale())
    if limits.max_force is not None:
        force = min(force, limits.max_force)
    return Candidate("hammer", float(force), hits=4)


def _grid(state: PosteriorState, limits: Limits, n: int) -> list[Candidate]:
    """About ``n`` candidates spread over the kinds and their settings (harmonics around the wells' frequencies;
    a ring-down posterior's: hammer hits over force and count, releases away from and towards the saddle).
    """
    if state.bench == "ring-down":
        n_hit = max(2, (n * 2 // 3) // len(HAMMER_HITS))
        out = [Candidate("hammer", float(f), hits=k) for k in HAMMER_HITS
               for f in np.geomspace(*_ring_down_levels(state, limits, "hammer"), n_hit)]  # fmt: skip
        n_rel = max(2, (n - len(out)) // 2)
        lo, hi = _ring_down_levels(state, limits, "release")
        out += [Candidate("release", float(sign * a)) for sign in (1.0, -1.0) for a in np.geomspace(lo, hi, n_rel)]
        return out
    f_lo, f_hi = _harmonic_band(state)
    n_r = max(2, n // 6)
    n_s = max(2, n // 8)
    n_c = 2 * max(1, n // 16)  # stepped campaigns: two top levels at n_c / 2 frequencies (6 of 50)
    n_h = max(4, n - n_r - n_s - n_c)
    n_f = max(2, int(round(math.sqrt(n_h * 1.2))))
    n_a = max(2, n_h // n_f)
    top = limits.max_table_acc
    out = [Candidate("random", float(x)) for x in np.geomspace(top / 16, top / 3.5, n_r)]
    out += [Candidate("sweep", float(x)) for x in np.geomspace(top / 12, top, n_s)]
    out += [Candidate("harmonic", float(a), float(f)) for f in np.geomspace(f_lo, f_hi, n_f)
            for a in np.geomspace(top / 12, top, n_a)]  # fmt: skip
    # stepped campaigns at the wells' frequencies and between them, to half and to the whole of the table's reach
    freqs = np.geomspace(f_lo, f_hi, n_c // 2) if n_c > 2 else [math.sqrt(f_lo * f_hi)]
    out += [Candidate("campaign", float(a), float(f)) for f in freqs for a in (top / 2, top)]
    return out


def _search(state, limits, targets, draws, seed, start: Evaluation, budget: int, evaluated: list) -> Evaluation:
    """The continuous settings of one candidate searched from its grid point (``budget`` evaluations at most): a
    bounded scalar search of the level, or Nelder-Mead over log frequency and log amplitude for a harmonic.
    """
    from scipy import optimize

    best = [start]
    top = limits.max_table_acc

    def run(c: Candidate) -> float:
        ev = evaluate(state, c, limits, targets, draws, seed)
        evaluated.append(ev)
        if ev.feasible and ev.score > best[0].score:
            best[0] = ev
        return -ev.score if ev.feasible else 0.0

    c0 = start.candidate
    if c0.kind in RING_DOWN_TESTS:  # the level's magnitude (a release keeps its side of the rest well)
        lo, hi = _ring_down_levels(state, limits, c0.kind)
        sign = math.copysign(1.0, c0.level)
        optimize.minimize_scalar(lambda lg: run(replace(c0, level=sign * float(math.exp(lg)))), method="bounded",
                                 bounds=(math.log(lo), math.log(hi)),
                                 options={"maxiter": budget, "xatol": 0.05})  # fmt: skip
    elif c0.kind not in SINUSOIDAL:
        hi = top / 3.5 if c0.kind == "random" else top
        optimize.minimize_scalar(lambda lg: run(replace(c0, level=float(math.exp(lg)))), method="bounded",
                                 bounds=(math.log(top / 40), math.log(hi)),
                                 options={"maxiter": budget, "xatol": 0.05})  # fmt: skip
    else:
        assert c0.freq is not None

        f_lo, f_hi = _harmonic_band(state)

        def f(x):
            freq = float(min(max(math.exp(x[0]), f_lo), f_hi))  # within the grid's band
            return run(replace(c0, level=float(min(math.exp(x[1]), top)), freq=freq))

        optimize.minimize(f, [math.log(c0.freq), math.log(c0.level)], method="Nelder-Mead",
                          options={"maxfev": budget, "initial_simplex": [
                              [math.log(c0.freq), math.log(c0.level)],
                              [math.log(c0.freq) + 0.15, math.log(c0.level)],
                              [math.log(c0.freq), math.log(c0.level) - 0.3]]})  # fmt: skip
    return best[0]


def design(posterior, *, targets=None, duration: float | None = None, max_table_acc: float | None = None,
           max_table_disp: float | None = None, stroke: float | None = None, sensor_range: float | None = None,
           max_force: float | None = None, candidates: int = 50, draws: int = 16, search: int = 12,
           seed: int = 0) -> dict[str, Any]:  # fmt: skip
    """The tests ranked by what they would teach (module docstring).

    Parameters
    ----------
    posterior : Posterior, dict, path or PosteriorState
        A fitted coefficient ``Posterior`` of a base-excited record (the table's tests are ranked), or of a
        hammer's record or a free decay (hammer hits and releases are ranked: ``RING_DOWN_TESTS``); its
        ``result()``, its JSON file, or the state ``prepared`` read from one.
    targets : sequence of str, optional
        The parameters to pin down (among k1, k2, k3, c, c_nl; default all).
    duration : float, optional
        The next record's length [s] (default: the posterior's record's).
    max_table_acc, max_table_disp : float, optional
        The table's peak acceleration [m/s^2] (default 80) and displacement [m] (None: no limit stated); a
        base-excited posterior's only.
    stroke : float, optional
        The device's travel from its saddle to a stop [m]; a test that reaches it is infeasible.
    sensor_range : float, optional
        The displacement sensor's measuring range [m]: a test whose reading (the device's and the table's motion
        together, for the rig's laser on the moving part) spans more is infeasible.
    max_force : float, optional
        The hammer's peak force [N] (a ring-down posterior's only; None: no limit stated).
    candidates : int
        Grid candidates before the continuous search.
    draws : int
        Posterior draws each candidate is simulated under (the first the mean).
    search : int
        Evaluations of the continuous search per searched candidate (the best two of the grid).
    seed : int
        Seed of the draws and of the simulated records' noise (same seed, same design).

    Returns
    -------
    dict
        ``{"targets", "criterion", "now", "ranked", "best", "default_test", "search", "assumptions",
        "settings"}`` (``docs/contract.md``).

    Examples
    --------
    >>> from negstiff import Measurement, Posterior, Rig, design
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=4).random(duration=10.0, rms=14.0))
    >>> plan = design(Posterior(seed=0).fit(rec), targets=("k1", "k3"), candidates=8, draws=2, search=0)
    >>> plan["best"]["score"] >= plan["default_test"]["score"]   # the chosen test teaches at least the default's
    True
    """
    t0 = time.perf_counter()
    state = _state_of(posterior)
    targets = _targets(targets)
    limits = _limits(state, duration, max_table_acc, max_table_disp, stroke, sensor_range, max_force)
    _counts(candidates=candidates, draws=draws, search=search, seed=seed)
    th = state.draws(int(draws), int(seed))
    evaluated = [evaluate(state, c, limits, targets, th, int(seed)) for c in _grid(state, limits, int(candidates))]
    n_grid = len(evaluated)
    feasible = sorted((e for e in evaluated if e.feasible), key=lambda e: -e.score)
    for start in feasible[:2] if search else []:
        _search(state, limits, targets, th, int(seed), start, int(search), evaluated)
    default = (Candidate("random", DEFAULT_RANDOM_RMS) if state.bench == "table"
               else ring_down_reference(state, limits))  # fmt: skip
    reference = evaluate(state, default, limits, targets, th, int(seed))
    evaluated.append(reference)  # a candidate too: the first-ranked test teaches at least what the default does
    unique = {
        (
            e.candidate.kind,
            round(e.candidate.level, 6),
            None if e.candidate.freq is None else round(e.candidate.freq, 6),
            e.candidate.hits,
        ): e
        for e in evaluated
    }  # a setting the search met again: once
    ranked = sorted(unique.values(), key=lambda e: (not e.feasible, -e.score))
    if not ranked[0].feasible:
        what = "the table's limits" if state.bench == "table" else "the hammer's force"
        raise InputError("no candidate test lies within the limits (the best one: " + ranked[0].problems[0] + "): "
                         f"widen {what} or the device's stroke")  # fmt: skip
    rows = [e.to_json(state.widths) for e in ranked]
    risks = _risks(rows[0], limits)
    for text in risks:
        warnings.warn(text, NegstiffWarning, stacklevel=2)
    return {
        "targets": list(targets),
        "warnings": risks,
        "hdi_prob": state.hdi_prob,
        "criterion": {
            "name": f"expected shrinkage of the targets' {100 * state.hdi_prob:g} % intervals (geometric mean of "
            "width now / width after)",
            "method": "Laplace approximation of the expected posterior covariance after the test over the "
            "posterior's draws, each draw's information read from a simulated record as the posterior "
            "reads one (multiple-shooting windows, start states profiled) and joined to the first record's "
            + (
                "as a joint fit joins them (the sandwich of the summed model information and score covariance)"
                if state.information is not None
                else "by adding each record's curvature-adjusted information (the posterior keeps no Laplace parts: "
                "sample it again for the joint fit's sandwich)"
            ),
            "references": [
                "Chaloner and Verdinelli 1995, Statistical Science 10(3) 273-304",
                "Ryan, Drovandi, McGree and Pettitt 2016, International Statistical Review 84(1) 128-154",
            ],
        },  # fmt: skip
        "now": {n: state.widths[n] for n in targets},
        "ranked": rows,
        "best": rows[0],
        "default_test": reference.to_json(state.widths),
        "search": {
            "grid": n_grid,
            "evaluated": len(unique),
            "seconds": time.perf_counter() - t0,
            "draws": int(draws),
        },  # fmt: skip
        "assumptions": [
            (
                f"the next record is read by a sensor chain like the rig's ({state.reading.sensors}, the table's "
                f"accelerometer integrated twice), laser noise {state.sigma:.3g} m and accelerometer noise "
                f"{state.input_noise:.3g} m/s^2 (the posterior's)"
                if state.bench == "table"
                else f"the next record is read by {state.reading.sensors} with the posterior's noise "
                f"({state.sigma:.3g} m), the device at rest in its plus well before the test, the table still; a hit "
                f"is a {1e3 * HAMMER_WIDTH_S:g} ms half-sine; the default test compared with is "
                f"'{default.describe()}' (the first record's own test is not in the posterior's file)"
            ),
            "the posterior is Gaussian with its reported means, sds and correlations",
        ],
        "settings": {
            "duration_s": limits.duration_s,
            "max_table_acc_m_s2": limits.max_table_acc if state.bench == "table" else None,
            "max_table_disp_m": limits.max_table_disp,
            "stroke_m": limits.stroke,
            "sensor_range_m": limits.sensor_range,
            "max_force_n": limits.max_force,
            "bench": state.bench,
            "candidates": candidates,
            "draws": draws,
            "search": search,
            "seed": seed,
            "posterior": state.source,
        },  # fmt: skip
    }


UNSTATED_TABLE_STROKE = 0.0125
"""The table displacement [m, peak] beyond which a design made without a stated table stroke warns: half of a mid-size
electrodynamic shaker's 25 mm (1 inch) peak-to-peak stroke. Long-stroke tables reach 150 mm, small shakers 10 mm:
the user's ``max_table_disp`` decides, and the warning asks for it."""
WIDTH_SPREAD_WARNING = 3.0
"""A chosen test whose predicted width of a target differs by this factor between the posterior's draws (the
widest over the narrowest) is said to depend on where the truth lies within the posterior."""


def _risks(best: dict[str, Any], limits: Limits) -> list[str]:
    """What could make the first-ranked test teach less than the design says, or not run: draws that cross to the
    other well beside draws that do not (the record's regime depends on where the truth lies), a predicted width
    that differs widely between the draws, and a table stroke the user did not bound.
    """
    cost, out = best["cost"], []
    both = cost.get("draws_visiting_both_wells", 0.0)
    if 0.0 < both < 1.0:
        out.append(f"the chosen test ({best['test']}) visits both wells in {100 * both:.0f} % of the posterior's "
                   "draws and stays in one well in the rest: what it teaches depends on where the truth lies (a "
                   "run that stays in the first record's well teaches little new)")  # fmt: skip
    spread = {n: hi / lo for n, (lo, hi) in cost.get("width_spread", {}).items() if lo > 0}
    wide = {n: r for n, r in spread.items() if r > WIDTH_SPREAD_WARNING}
    if wide:
        out.append(f"the chosen test's predicted widths differ between the posterior's draws by up to "
                   f"{max(wide.values()):.3g}x ({', '.join(sorted(wide))}): the expected shrinkage is an average over "
                   "outcomes this far apart")  # fmt: skip
    disp = cost.get("peak_table_disp_m")
    if limits.max_table_disp is None and disp is not None and disp > UNSTATED_TABLE_STROKE:
        out.append(f"the chosen test moves the table {1e3 * disp:.3g} mm (peak) and no table stroke was stated: "
                   "give the shaker's (max_table_disp, --table-stroke) if it has less")  # fmt: skip
    if best["kind"] in RING_DOWN_TESTS and limits.stroke is None:
        out.append(f"the chosen test moves the device {1e3 * cost['peak_travel_m']:.3g} mm from its saddle (or its "
                   "single well's rest) and no stroke was stated: a larger motion teaches more until a stop, so "
                   "give the device's (stroke, --stroke) if it has less")  # fmt: skip
    return out


def prepared(posterior, *, targets=None, duration: float | None = None, max_table_acc: float | None = None,
             max_table_disp: float | None = None, stroke: float | None = None, sensor_range: float | None = None,
             max_force: float | None = None, candidates: int = 50, draws: int = 16, search: int = 12,
             seed: int = 0) -> dict[str, Any]:  # fmt: skip
    """Every check ``design`` makes before its work (the posterior, the targets, the limits, the counts), in a
    fraction of a second: one ``InputError`` for the first bad input. Returns ``design``'s arguments, the
    posterior as read (``design(**prepared(...))`` reads its file once).
    """
    state = _state_of(posterior)
    _limits(state, duration, max_table_acc, max_table_disp, stroke, sensor_range, max_force)
    _counts(candidates=candidates, draws=draws, search=search, seed=seed)
    return {"posterior": state, "targets": _targets(targets), "duration": duration, "max_table_acc": max_table_acc,
            "max_table_disp": max_table_disp, "stroke": stroke, "sensor_range": sensor_range,
            "max_force": max_force, "candidates": candidates, "draws": draws, "search": search,
            "seed": seed}  # fmt: skip


def _counts(**counts) -> None:
    for name, v in counts.items():
        lo = {"candidates": 4, "draws": 1, "search": 0, "seed": 0, "records": 1}[name]
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise InputError(f"{name} must be a whole number >= {lo}, got {v!r}")


def design_figure(result: dict[str, Any]):
    """The criterion over the candidates' settings: the harmonics' score over frequency and amplitude, the random
    runs' and sweeps' over their level, the chosen test and the default random test marked.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in result["ranked"] if r["feasible"]]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10.5, 4.0), constrained_layout=True)
    if any(r["kind"] in RING_DOWN_TESTS for r in result["ranked"]):
        _ring_down_panels(a, b, rows, result)
        return fig
    h = [r for r in rows if r["kind"] in SINUSOIDAL]
    if h:
        norm = matplotlib.colors.LogNorm(min(r["score"] for r in h), max(r["score"] for r in h))
        for kind, mark, name in (("harmonic", "o", "harmonic"), ("campaign", "D", "stepped campaign (its top step)")):
            k = [r for r in h if r["kind"] == kind]
            if k:
                sc = a.scatter([r["freq_hz"] for r in k], [r["amplitude_m_s2"] for r in k], c=[r["score"] for r in k],
                               cmap="viridis", s=36, norm=norm, marker=mark, label=name)  # fmt: skip
        fig.colorbar(sc, ax=a, label="expected shrinkage of the targets' intervals")
    a.set(xscale="log", yscale="log", xlabel="frequency [Hz]", ylabel="amplitude [m/s$^2$]",
          title="harmonic tests and stepped campaigns")  # fmt: skip
    for kind, mark in (("random", "o-"), ("sweep", "s-")):
        r = sorted((x for x in rows if x["kind"] == kind), key=lambda x: x.get("rms_m_s2") or x["amplitude_m_s2"])
        if r:
            b.plot([x.get("rms_m_s2") or x["amplitude_m_s2"] for x in r], [x["score"] for x in r], mark, ms=4,
                   label="random (rms)" if kind == "random" else "linear sweep (amplitude)")  # fmt: skip
    best, ref = result["best"], result["default_test"]
    lvl = best.get("rms_m_s2") or best["amplitude_m_s2"]
    sinusoidal = best["kind"] in SINUSOIDAL
    (a if sinusoidal else b).plot(best["freq_hz"] if sinusoidal else lvl, lvl if sinusoidal else best["score"], "r*",
                                  ms=14, label=f"chosen: {best['test']}")  # fmt: skip
    b.plot(ref["rms_m_s2"], ref["score"], "kx", ms=10, mew=2, label=f"default: {ref['test']}")
    b.set(xscale="log", yscale="log", xlabel="level [m/s$^2$]", ylabel="expected shrinkage",
          title=f"random and swept tests; targets {', '.join(result['targets'])}")  # fmt: skip
    b.legend(fontsize=8)
    _plain_log_ticks(a, b)
    plain = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
    if h:
        sc.colorbar.ax.yaxis.set_major_formatter(plain)
        sc.colorbar.ax.yaxis.set_minor_formatter(plain)
    if h:
        a.legend(fontsize=8)
    return fig


def _ring_down_panels(a, b, rows: list[dict[str, Any]], result: dict[str, Any]) -> None:
    """A ring-down posterior's criterion: the hammer tests' over their peak force (one line per hit count), the
    releases' over their start's distance from rest (away from the saddle and towards it), chosen and default
    marked.
    """
    for k in HAMMER_HITS:
        r = sorted((x for x in rows if x["kind"] == "hammer" and x["hits"] == k), key=lambda x: x["peak_force_n"])
        if r:
            a.plot([x["peak_force_n"] for x in r], [x["score"] for x in r], "o-", ms=4, label=f"{k} hits")
    for sign, name in ((1, "above rest (away from any saddle)"), (-1, "below rest (towards the saddle)")):
        r = sorted((x for x in rows if x["kind"] == "release" and sign * x["release_offset_m"] > 0),
                   key=lambda x: abs(x["release_offset_m"]))  # fmt: skip
        if r:
            b.plot([1e3 * abs(x["release_offset_m"]) for x in r], [x["score"] for x in r], "s-", ms=4, label=name)
    for row, mark, what in ((result["best"], "r*", "chosen"), (result["default_test"], "kx", "reference")):
        ax, x = (a, row["peak_force_n"]) if row["kind"] == "hammer" else (b, 1e3 * abs(row["release_offset_m"]))
        ax.plot(x, row["score"], mark, ms=14 if what == "chosen" else 10, mew=2, label=f"{what}: {row['test']}")
    a.set(xscale="log", yscale="log", xlabel="peak force [N]", ylabel="expected shrinkage",
          title="hammer hits")  # fmt: skip
    b.set(xscale="log", yscale="log", xlabel="release from rest [mm]", ylabel="expected shrinkage",
          title=f"free decays; targets {', '.join(result['targets'])}")  # fmt: skip
    _plain_log_ticks(a, b)
    for ax in (a, b):
        ax.legend(fontsize=8)


def _plain_log_ticks(*axes) -> None:
    """Plain numbers on log axes (4, not 4x10^0) at 1, 2 and 5 per decade, the minor ticks unlabelled."""
    import matplotlib.ticker

    plain = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
    for ax in axes:
        for axis in (ax.xaxis, ax.yaxis):
            axis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
            axis.set_major_formatter(plain)
            axis.set_minor_formatter(matplotlib.ticker.NullFormatter())


def _state_of(posterior) -> PosteriorState:
    if isinstance(posterior, PosteriorState):  # read already (``prepared``)
        return posterior
    if isinstance(posterior, (str, os.PathLike)):
        from negstiff.files import read_json  # one line for a missing, oversized or broken file

        return PosteriorState.from_json(read_json(posterior, "posterior result"), str(posterior))
    if isinstance(posterior, dict):
        return PosteriorState.from_json(posterior)
    if hasattr(posterior, "result") and callable(posterior.result):
        return PosteriorState.from_json(posterior.result(), "the posterior")
    raise InputError(f"design takes a fitted Posterior, its result or its JSON file, got {type(posterior).__name__}")


def _targets(targets) -> tuple[str, ...]:
    if targets is None:
        return COEFFICIENTS
    names = tuple(str(t).strip() for t in (targets.split(",") if isinstance(targets, str) else targets))
    bad = [t for t in names if t not in COEFFICIENTS]
    if bad or not names:
        raise InputError(f"target {', '.join(bad) or '(none)'}: not a parameter of the coefficient posterior "
                         f"(one or more of {', '.join(COEFFICIENTS)})")  # fmt: skip
    return tuple(dict.fromkeys(names))


def _limits(state: PosteriorState, duration, max_acc, max_disp, stroke, sensor_range=None, max_force=None) -> Limits:
    dur = state.duration_s if duration is None else duration
    if state.bench == "ring-down":
        given = [n for n, v in (("max_table_acc", max_acc), ("max_table_disp", max_disp)) if v is not None]
        if given:
            raise InputError(f"{', '.join(given)}: a table's limit; a hammer's or a decay's posterior plans hammer "
                             "hits and releases, the table still (max_force bounds the hammer)")  # fmt: skip
    elif max_force is not None:
        raise InputError("max_force: a hammer's limit; a base-excited record's posterior plans the table's tests "
                         "(max_table_acc, max_table_disp bound them)")  # fmt: skip
    max_acc = DEFAULT_MAX_ACC if max_acc is None else max_acc
    for name, v in (("duration", dur), ("max_table_acc", max_acc), ("max_table_disp", max_disp),
                    ("sensor_range", sensor_range), ("max_force", max_force)):  # fmt: skip
        if v is None and name in ("max_table_disp", "sensor_range", "max_force"):
            continue
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or v <= 0:
            raise InputError(f"{name} must be a positive number, got {v!r}")
    if dur < 4 * state.window_s:
        raise InputError(f"duration {dur:g} s: shorter than 4 of the posterior's {state.window_s:g} s windows")
    if max_force is not None and max_force < HAMMER_MIN_N:
        raise InputError(f"max_force {max_force:g} N: below the lightest hit the load cell tells from its noise "
                         f"({HAMMER_MIN_N:g} N)")  # fmt: skip
    if max_acc <= 3 * state.input_noise:
        raise InputError(f"max_table_acc {max_acc:g} m/s^2: within 3x the accelerometer's noise "
                         f"({state.input_noise:.3g} m/s^2 rms): no test the record could read")  # fmt: skip
    if stroke is not None:
        if isinstance(stroke, bool) or not isinstance(stroke, numbers.Real) or not math.isfinite(stroke):
            raise InputError(f"stroke must be a number [m], got {stroke!r}")
        if stroke <= 3 * state.sigma:
            raise InputError(f"stroke {stroke:g} m: within 3x the laser's noise ({state.sigma:.3g} m): no motion "
                             "the record could read")  # fmt: skip
        eq = state.wells(state.mean)
        centre = eq.z_0 if eq.z_0 is not None else eq.z_plus
        if stroke <= abs(eq.z_plus - centre):
            raise InputError(f"stroke {1e3 * stroke:g} mm: inside the well the device rests in "
                             f"({1e3 * abs(eq.z_plus - centre):.3g} mm from its saddle)")  # fmt: skip
    if sensor_range is not None and sensor_range <= 3 * state.sigma:
        raise InputError(f"sensor_range {sensor_range:g} m: within 3x the laser's noise ({state.sigma:.3g} m): no "
                         "motion the record could read")  # fmt: skip
    return Limits(float(dur), float(max_acc), None if max_disp is None else float(max_disp),
                  None if stroke is None else float(stroke), None if sensor_range is None else float(sensor_range),
                  None if max_force is None else float(max_force))  # fmt: skip
