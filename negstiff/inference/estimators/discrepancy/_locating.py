"""Locate: where a model's weak residual lives, by regime (the wells, the barrier, near zero velocity, large stroke)
and over the state plane, and the same in words.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from negstiff.inference.record.measurement import Measurement

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
        regimes = {}
        v_rms = float(np.sqrt(np.mean(self._v**2)))
        stroke = np.percentile(np.abs(self._zs - np.median(self._zs)), 90)
        masks = {
            "near zero velocity": np.abs(v) < 0.1 * v_rms,
            "large stroke": np.abs(z - np.median(self._zs)) > stroke,
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
        worst = max(regimes.items(), key=lambda kv: kv[1]["ratio"]) if regimes else None
        return {"regimes": regimes, "worst": worst[0] if worst else None, "z": z, "v": v, "r": r, "wells": wells}

    def where_text(self) -> str:
        """Where the baseline's equation error concentrates, in words (the result's ``where``)."""
        loc = self.locate_before_
        if not loc["regimes"]:
            return "no regime could be told apart"
        parts = sorted(loc["regimes"].items(), key=lambda kv: -kv[1]["ratio"])
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
