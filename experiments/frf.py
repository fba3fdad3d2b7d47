"""The figure of ``negstiff frf``: |H1| and |H2| over the band with each fitted peak, and the coherence."""

from __future__ import annotations

from typing import Any

import numpy as np


def figure(res: dict[str, Any], curves: dict[str, np.ndarray], input_name: str, title: str):
    """The FRF figure of an ``frf`` result and its spectra (``_curves``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    f = curves["f"]
    sel = (f >= res["band"][0]) & (f <= res["band"][1])
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1])
    a1.semilogy(f[sel], np.abs(curves["H1"][sel]), label="H1")
    a1.semilogy(f[sel], np.abs(curves["H2"][sel]), "--", label="H2")
    for p in res["peaks"]:
        a1.axvline(p["f_hz"], color="0.6", lw=0.8)
        a1.annotate(f"{p['f_hz']:.3f} Hz, zeta {100 * p['zeta']:.2f} %", (p["f_hz"], np.abs(curves["H1"][sel]).max()),
                    fontsize=8, ha="left", va="top")  # fmt: skip
    a1.set(ylabel=f"|z / {input_name}|", title=title)
    a1.legend()
    a2.plot(f[sel], curves["coherence"][sel])
    a2.set(xlabel="frequency [Hz]", ylabel="coherence", ylim=(0, 1.05))
    fig.tight_layout()
    return fig
