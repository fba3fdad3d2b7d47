"""The command line's figures: ``negstiff frf`` (|H1| and |H2| over the band with each fitted peak, and the
coherence) and ``negstiff nfrc`` (the response's extent along each branch, stable solid, unstable dashed,
bifurcations marked), ``negstiff backbone`` (frequency and damping against amplitude).
"""

from __future__ import annotations

from typing import Any

import numpy as np


def frf_figure(res: dict[str, Any], curves: dict[str, np.ndarray], input_name: str, title: str):
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


def frf_figure_dofs(res: dict[str, Any], curves: list[dict[str, np.ndarray]], input_name: str, title: str,
                    model: dict[str, Any] | None = None):  # fmt: skip
    """The FRF figure of a structure's record: |H1| from the input to every DOF, the coherence below, the merged
    modes marked; ``model`` (``{"label", "curves": [{"f", "H"}, ...]}``): a model's FRF at each DOF, dashed.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    lo, hi = res["dofs"][0]["band"]  # the input's band: outside it the ratio is noise over noise
    for i, c in enumerate(curves):
        f = c["f"]
        sel = (f >= lo) & (f <= hi)
        a1.semilogy(f[sel], np.abs(c["H1"][sel]), label=f"z{i + 1}", color=f"C{i}")
        a2.plot(f[sel], c["coherence"][sel], label=f"z{i + 1}", color=f"C{i}")
        if model is not None:
            m = model["curves"][i]
            inside = (m["f"] >= lo) & (m["f"] <= hi)
            a1.semilogy(m["f"][inside], np.abs(m["H"][inside]), "--", color=f"C{i}", lw=1.0,
                        label=model["label"] if i == 0 else None)  # fmt: skip
    for m in res["modes"]:
        a1.axvline(m["f_hz"], color="0.6", lw=0.8)
    a1.set_ylabel(f"|H1| [m per {'m/s^2' if input_name == 'base_acc' else 'N'}]")
    a1.legend(fontsize=8)
    a1.set_title(title)
    a2.set_ylabel("coherence")
    a2.set_xlabel("frequency [Hz]")
    a2.set_ylim(0, 1.05)
    fig.tight_layout()
    return fig


def state_space_figure(j: dict[str, Any], title: str):
    """A structure read through its sensors (``identify nsi`` without masses, its JSON ``j``): the stabilisation
    diagram (each order's poles, the stable ones filled, the chosen order dashed, the modes read grey) and the
    model's underlying-linear FRF from the force to each sensor [m/N].
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    for row in j["stabilisation"]:
        f = [p["f_hz"] for p in row["poles"]]
        filled = ["C0" if p["stable"] else "none" for p in row["poles"]]
        ax.scatter(f, [row["order"]] * len(f), s=12, c=filled, edgecolors="C0", linewidths=0.7)
    modes = [m["f_hz"] for m in j["modal"]["linear"]]
    for f in modes:
        ax.axvline(f, color="0.75", lw=0.8, zorder=0)
    ax.axhline(j["order"], color="C3", lw=0.8, ls="--")
    top = max([p["f_hz"] for row in j["stabilisation"] for p in row["poles"]] + modes + [1.0])
    ax.set(xlabel="frequency [Hz]", ylabel="model order", xlim=(0, 1.05 * top),
           title=f"stabilisation diagram (order {j['order']} chosen: dashed)")  # fmt: skip
    frf = j["frf"]
    freqs = np.asarray(frf["f_hz"])
    for k, (re, im) in enumerate(zip(frf["real"], frf["imag"], strict=True)):
        bx.semilogy(freqs, np.abs(np.asarray(re) + 1j * np.asarray(im)), label=f"sensor {k + 1}")
    for m in modes:
        bx.axvline(m, color="0.75", lw=0.8, zorder=0)
    bx.set(xlabel="frequency [Hz]", ylabel="|H| [m/N]", title=f"underlying-linear FRF ({frf['input']})")
    bx.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def backbone_figure(res: dict[str, Any], title: str):
    """The backbone figure of a ``backbone`` result: frequency and damping ratio against amplitude [mm], the
    measured Hilbert curve, its peak-to-peak cross-check, the model's prediction, its forced responses (half the
    peak-to-peak against the forcing frequency, grey) and the draws' band where given.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.5), sharey=True)
    curves = [("measured (Hilbert)", res["measured"]["hilbert"], "C0", "-"),
              ("measured (peaks)", res["measured"]["peaks"], "C0", ":")]  # fmt: skip
    if res.get("predicted"):
        curves.append(("model (Hilbert)", res["predicted"]["hilbert"], "C3", "--"))
    for label, c, color, ls in curves:
        a = 1e3 * np.asarray(c["amplitude_m"])
        a1.plot(c["f_hz"], a, ls, color=color, label=label)
        a2.plot(100 * np.asarray(c["zeta"]), a, ls, color=color, label=label)
    for k, c in enumerate((res.get("forced") or {}).get("curves", [])):
        a = 1e3 * np.asarray(c["amplitude_m"])
        stable = np.asarray(c["stable"], bool)
        for mask, ls in ((stable, "-"), (~stable, "--")):
            edge = mask | np.r_[mask[1:], False] | np.r_[False, mask[:-1]]  # runs joined to their neighbours
            a1.plot(c["f_hz"], np.where(edge, a, np.nan), ls, color="0.45", lw=0.9,
                    label="model's forced response (dashed: unstable)" if (k == 0 and ls == "-") else None)  # fmt: skip
        unit = (res.get("forced") or {}).get("force_unit", "N")
        a1.annotate(f"{c['force_n']:.2g} {unit}", (c["peak"]["f_hz"], 1e3 * c["peak"]["amplitude_m"]), fontsize=7,
                    color="0.35", xytext=(3, 2), textcoords="offset points")  # fmt: skip
    band = res.get("credible")
    if band:
        a = 1e3 * np.asarray(band["amplitude_m"])
        a1.fill_betweenx(a, band["f_hz_low"], band["f_hz_high"], color="C3", alpha=0.2,
                         label=f"posterior draws, {100 * band['prob']:.0f} % band ({band['draws']})")  # fmt: skip
        a2.fill_betweenx(a, 100 * np.asarray(band["zeta_low"]), 100 * np.asarray(band["zeta_high"]), color="C3",
                         alpha=0.2)  # fmt: skip
    a1.set(xlabel="frequency [Hz]", ylabel="amplitude [mm]", title=title)
    a2.set(xlabel="damping ratio [%]")
    handles, labels = a1.get_legend_handles_labels()
    rows = -(-len(labels) // 3)
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=8, frameon=False)  # below: the curves' peaks
    fig.tight_layout(rect=(0, 0.045 * rows, 1, 1))  # fill both upper corners (softening and hardening)
    return fig


MARKERS = {"fold": ("o", "C3"), "period_doubling": ("s", "C2"), "neimark_sacker": ("^", "C4")}


def continuation_figure(result: dict[str, Any], title: str = ""):
    """Max z and min z along every branch against the continuation parameter [mm]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    par = result["settings"]["parameter"]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for k, br in enumerate(result["branches"]):
        pts = br["points"]
        lam = np.array([p[par] for p in pts])
        stable = np.array([p["stable"] for p in pts])
        color = f"C{k % 10}" if br["period"] == 1 else f"C{(k + 4) % 10}"
        for key in ("max_z", "min_z"):
            z = 1e3 * np.array([p[key] for p in pts])
            for mask, ls in ((stable, "-"), (~stable, "--")):
                # join a run to its neighbours so that stable and unstable parts meet
                edge = mask | np.concatenate([mask[1:], [False]]) | np.concatenate([[False], mask[:-1]])
                zz = np.where(edge, z, np.nan)
                ax.plot(lam, zz, ls, color=color, lw=1.2,
                        label=f"period {br['period']}" if (key == "max_z" and ls == "-") else None)  # fmt: skip
    for b in result["bifurcations"]:
        m, c = MARKERS[b["type"]]
        ax.axvline(b[par], color=c, lw=0.6, ls=":")
        ax.plot([], [], m, color=c, label=b["type"].replace("_", " "))
        ax.plot(b[par], 1.0, m, color=c, clip_on=False, transform=ax.get_xaxis_transform())
    unit = "Hz" if par == "f_hz" else ("m/s^2" if result["settings"]["input"] == "base_acc" else "N")
    title = title or f"continuation ({result['settings']['well']} well): solid stable, dashed unstable"
    ax.set(xlabel=f"{'frequency' if par == 'f_hz' else 'amplitude'} [{unit}]", ylabel="max z, min z [mm]", title=title)
    handles, labels = ax.get_legend_handles_labels()
    seen = dict(zip(labels, handles, strict=False))
    ax.legend(seen.values(), seen.keys(), fontsize=8)
    fig.tight_layout()
    return fig


def force_figure(models: dict[str, Any], stroke: tuple[float, float], title: str = "",
                 band: dict[str, Any] | None = None):  # fmt: skip
    """The restoring force K(z) [N] of each model (``{label: Model}``) over the measured stroke [m] (its wells
    marked); with a posterior's credible band (``band``: a posterior's ``force_band``, ``{"z_m", "low_n",
    "high_n", "median_n"}``) shaded, and below it each model's force minus the band's median with the band about
    zero (a band a fraction of a percent of the force wide is seen there).
    """
    import matplotlib.pyplot as plt

    rows = 2 if band else 1
    fig, axes = plt.subplots(rows, 1, figsize=(8, 4.2 if rows == 1 else 6.4), sharex=True, squeeze=False,
                             height_ratios=[3, 2][:rows])  # fmt: skip
    ax = axes[0, 0]
    z = np.linspace(stroke[0], stroke[1], 401)
    if band:
        zb = np.asarray(band["z_m"])
        ax.fill_between(1e3 * zb, band["low_n"], band["high_n"], color="0.8", label=band.get("label", "posterior band"))
        med = np.asarray(band["median_n"])
        axes[1, 0].fill_between(1e3 * zb, np.asarray(band["low_n"]) - med, np.asarray(band["high_n"]) - med,
                                color="0.8")  # fmt: skip
        axes[1, 0].axhline(0.0, color="0.5", lw=0.6)
        axes[1, 0].set_ylabel("K(z) - posterior median [N]")
    for label, model in models.items():
        (line,) = ax.plot(1e3 * z, model.restoring_force(z), lw=1.5, label=label)
        if band:
            axes[1, 0].plot(1e3 * zb, model.restoring_force(zb) - med, lw=1.2, color=line.get_color())
        try:
            eq = model.equilibria()
        except ValueError:
            continue
        wells = [w for w in (eq.z_minus, eq.z_plus) if w is not None and stroke[0] <= w <= stroke[1]]
        ax.plot(1e3 * np.array(wells), np.zeros(len(wells)), "o", color=line.get_color(), ms=5)
    ax.axhline(0.0, color="0.5", lw=0.6)
    axes[-1, 0].set_xlabel("z [mm] (the record's stroke)")
    ax.set_ylabel("restoring force K(z) [N]" + (" per unit mass" if all(m.m == 1.0 for m in models.values()) else ""))
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=8, frameon=False)
    fig.tight_layout()
    return fig
