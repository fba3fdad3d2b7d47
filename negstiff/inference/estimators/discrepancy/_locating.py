"""Locate: where a model's weak residual lives, by regime (the wells, the barrier, near zero velocity, large stroke)
and over the state plane, and the same in words.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.equations import _Weak
from negstiff.models.structure import Structure, relative

from ._baseline import Baselines
from ._candidates import share_text


class Locating(Baselines):
    """Where the equation error sits (a layer of ``Discrepancy``)."""

    def locate(self, rec: Measurement, model_terms: tuple[str, ...], stop: float | None,
               aux: tuple[str, ...] = (), law: str | None = None) -> dict[str, Any]:  # fmt: skip
        """Where the current model's weak residual lives: by regime and over the state plane."""
        W, y = self._design(rec, 0, self.n_id_, stop, aux, law)
        coef = self._fit(W, y, model_terms, stop is not None, len(aux), law)
        r = y - W @ coef
        form = self._form
        centres = np.clip(np.arange(r.size) * form.stride + form.centre(rec.dt), 0, self.n_id_ - 1)
        z, v = self._zs[centres], self._v[centres]
        try:
            model = self._model(coef, rec, stop, aux, law)
            eq = model.equilibria()
            wells = (eq.z_minus, eq.z_0, eq.z_plus)
        except ValueError:
            wells = (None, None, None)
        regimes = regime_shares(z, v, r, wells, self._zs, self._v)
        worst = max(regimes.items(), key=lambda kv: kv[1]["ratio"]) if regimes else None
        return {"regimes": regimes, "worst": worst[0] if worst else None, "z": z, "v": v, "r": r, "wells": wells}

    def where_text(self) -> str:
        """Where the baseline's equation error concentrates, in words (the result's ``where``)."""
        return where_words(self.locate_before_["regimes"])


def regime_shares(z: np.ndarray, v: np.ndarray, r: np.ndarray, wells, z_all: np.ndarray,
                  v_all: np.ndarray) -> dict[str, dict[str, float]]:  # fmt: skip
    """Each regime's share of the squared residual ``r`` against its share of the record (``ratio``: > 1 where the
    error concentrates), the residual's rows at the states (``z``, ``v``) of their test functions' centres: near zero
    velocity (a tenth of the rms ``v_all``), at large stroke (beyond the 90th percentile of |z - median| over
    ``z_all``), and with the wells (``wells``: z_minus, z_0, z_plus, or Nones) crossing the barrier and in each
    well. A single DOF's z; a structure's element's relative displacement.
    """
    regimes = {}
    v_rms = float(np.sqrt(np.mean(v_all**2)))
    stroke = np.percentile(np.abs(z_all - np.median(z_all)), 90)
    masks = {
        "near zero velocity": np.abs(v) < 0.1 * v_rms,
        "large stroke": np.abs(z - np.median(z_all)) > stroke,
    }
    if wells[1] is not None:
        zm, z0, zp = wells
        masks["crossing the barrier"] = np.abs(z - z0) < 0.25 * (zp - zm) / 2
        masks["in the minus well"] = (z < z0) & ~masks["crossing the barrier"]
        masks["in the plus well"] = (z >= z0) & ~masks["crossing the barrier"]
    total = float(np.sum(r**2))
    for name, m in masks.items():
        if m.any():
            share_r = float(np.sum(r[m] ** 2) / total)
            share_t = float(np.mean(m))
            regimes[name] = {"residual_share": share_r, "time_share": share_t, "ratio": share_r / share_t}
    return regimes


def where_words(regimes: dict[str, dict[str, float]]) -> str:
    """Where a baseline's equation error concentrates (``regime_shares``), in words."""
    if not regimes:
        return "no regime could be told apart"
    parts = sorted(regimes.items(), key=lambda kv: -kv[1]["ratio"])
    worst, w = parts[0]
    if w["ratio"] < 1.5:
        return (
            "the baseline's equation error is spread evenly: no regime carries more than 1.5x its share of the "
            f"record (largest: {worst}, {w['ratio']:.1f}x)"
        )

    def where(regime: str) -> str:  # "concentrated at large stroke", "... crossing the barrier"
        return f"at {regime}" if regime == "large stroke" else regime

    txt = (
        f"the baseline's equation error is concentrated {where(worst)} "
        f"({share_text(w['residual_share'])} % of the squared "
        f"residual in {share_text(w['time_share'])} % of the record, {w['ratio']:.1f}x its share)"
    )
    if len(parts) > 1:
        n2, w2 = parts[1]
        txt += f"; next {where(n2)} ({w2['ratio']:.1f}x)"
    return txt


# --- a structure's: on the element's relative motion ---------------------------------------------------------------
def locate(residual: np.ndarray, y: np.ndarray, per_dof: int, form: _Weak, states, at: tuple[int, int],
           structure: Structure, offsets: np.ndarray) -> dict[str, dict[str, float]]:  # fmt: skip
    """Where a structure's weak residual (``weak_system``'s rows over the identification part) lives, by the regimes
    of the element's relative motion (the single DOF's ``regime_shares`` on the element's relative displacement and
    velocity at each test function's centre, in the physical frame of ``structure`` and its channels' ``offsets``,
    its wells the element's): each test function's squared residual of every DOF, divided by that DOF's target's
    variance and averaged over the DOFs (``_block_scores``' measure).
    """
    zs, v = states
    n_dof = zs.shape[0]
    r2 = (residual.reshape(n_dof, per_dof) ** 2 / y.reshape(n_dof, per_dof).var(axis=1, keepdims=True)).mean(axis=0)
    centres = np.clip(np.arange(per_dof) * form.stride + form.phi.size // 2, 0, zs.shape[1] - 1)
    o = np.asarray(offsets, float)
    r_all = relative(zs - o[:, None], at)
    rv_all = relative(v, at)
    wells: tuple[float | None, ...] = (None, None, None)
    try:
        eq = structure.element_equilibria()
        wells = (eq.z_minus, eq.z_0, eq.z_plus)
    except ValueError:
        pass
    return regime_shares(r_all[centres], rv_all[centres], np.sqrt(r2), wells, r_all, rv_all)
