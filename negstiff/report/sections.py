"""A report's sections, one per kind of result: functions of the library's results, shared by the command
``negstiff report`` (``negstiff.report.record``) and by a script's own ``Report``.

* a record (``Measurement``): its time base, sensor, what was derived, its frame and anchor, its warnings;
* an identification (``NSI``, ``SINDy`` or their ``Identification``): the model, each well's modal
  parameters, the held-out validation, the refinement, the warnings;
* a posterior (``Posterior``): each parameter's mean, sd and credible interval with its diagnostics;
* the discrepancy workflow (``Discrepancy``): what it named, its size, where the baseline erred, the gap;
* an FRF, a characterisation, a bifurcation map, a decay's backbone (the ``frf``, ``characterise``,
  ``Campaign.map`` and ``backbone`` dicts).

Each returns a ``Section``: its blocks, its figures, and what the report's summary and its coefficient
table take from it (each method's estimates beside the posterior's interval).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .numbers import fmt, fmt_interval

COEFFICIENTS = ("k1", "k2", "k3", "c", "c_nl")
"""The coefficients every report's table holds (the contract's model fields)."""

UNITS = {"k1": "N/m", "k2": "N/m^2", "k3": "N/m^3", "c": "N s/m", "c_nl": "N s^2/m^2"}
"""The coefficients' units (SI)."""


def coefficient_units(per_kg: bool = False) -> dict[str, str]:
    """Each coefficient's unit (the base fields' and every scalar part's of the effect registry): SI, or per
    kilogram of moving mass for a model identified without a mass (m = 1).
    """
    from negstiff.models import effects

    units = {**{e.name: e.units for e in effects.REGISTRY if e.scalar and e.units}, **UNITS}
    return {k: f"{u} per kg" if per_kg else u for k, u in units.items()}


class Blocks:
    """The blocks a report is written in (paragraphs, warnings, tables, figures), added to ``blocks`` and
    ``figures``: one way of writing them for a ``Section`` and a whole ``Report``.
    """

    blocks: list[tuple[str, Any]]
    figures: dict[str, bytes]

    def text(self, text: str) -> None:
        """A paragraph."""
        self.blocks.append(("p", text))

    def warning(self, text: str) -> None:
        """A paragraph set apart as a warning."""
        self.blocks.append(("warn", text))

    def table(self, header: list[str], rows: list[list[Any]]) -> None:
        """A table of ``header`` and ``rows`` (numbers at their significant figures)."""
        self.blocks.append(("table", (header, [[fmt(c) for c in r] for r in rows])))

    def figure(self, name: str, fig, caption: str) -> None:
        """A matplotlib figure saved as PNG under ``name``, with its caption."""
        import matplotlib.pyplot as plt

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        self.figures[f"{name}.png"] = buf.getvalue()
        self.blocks.append(("fig", (f"{name}.png", caption)))


@dataclass
class Section(Blocks):
    """What one result gives a report."""

    kind: str
    label: str
    title: str
    blocks: list[tuple[str, Any]] = field(default_factory=list)
    figures: dict[str, bytes] = field(default_factory=dict)
    estimates: dict[str, dict[str, float]] = field(default_factory=dict)
    """column -> {coefficient: value} (each method's estimates, for the coefficient table)."""
    interval: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    """coefficient -> (mean, low, high) of a posterior."""
    heldout: dict[str, float | None] = field(default_factory=dict)
    """what -> held-out prediction error [% of rms z]."""
    summary: list[str] = field(default_factory=list)
    json: dict[str, Any] = field(default_factory=dict)
    models: dict[str, Any] = field(default_factory=dict)
    """column -> the method's final ``Model`` (the report's force figure draws each over the stroke)."""
    band: dict[str, Any] | None = None
    """A law's posterior: its force band over the stroke (``Posterior``'s ``force_band``)."""
    stroke: tuple[float, float] | None = None
    """The stroke the record visited [m] (the identification part's 0.5 and 99.5 % quantiles)."""


def effective(model) -> dict[str, float]:
    """k1-k3, c, c_nl of a model (a ``Model`` or its dict) with each named effect that is one of those terms
    folded back in (a discrepancy's ``quadratic_damping`` is c_nl's term: the simulator adds the two), and each
    shaped part's parameters (a magnet's ``magnet.A``, ``magnet.d``: ``models.shaped``), named as the refinement
    and the posterior name them.
    """
    from negstiff.models import effects
    from negstiff.models.shaped import ShapedLaw

    d = model if isinstance(model, dict) else model.to_dict()
    out = {k: float(d[k]) for k in COEFFICIENTS}
    extra = d.get("extra") or {}
    out |= {k: v for k, v in _part_parameters(extra).items() if not compared_by_force(k.partition(".")[0])}
    for name, value in extra.items():
        if isinstance(effects.get(name).law, ShapedLaw):
            continue  # its parameters above
        field = effects.get(name).folds_into
        if field in out and not isinstance(value, dict):
            out[field] += float(value)
        elif not isinstance(value, dict) and not name.startswith(effects.AUX_PREFIX):
            out[name] = float(value)  # a law's scalar part of its own (polynomial damping's z'^3 term)
    return out


def _part_parameters(extra: Mapping[str, Any]) -> dict[str, float]:
    """Every shaped part's parameters among a model's ``extra`` effects (``PART.NAME``), a spline's coefficients
    among them.
    """
    from negstiff.models import effects
    from negstiff.models.shaped import ShapedLaw

    out: dict[str, float] = {}
    for name, value in extra.items():
        law = effects.get(name).law
        if isinstance(law, ShapedLaw):
            out |= {f"{name}.{p}": v for p, v in law.parameters(value).items()}
    return out


def compared_by_force(name: str) -> bool:
    """Whether a part's parameters are compared between methods by its force rather than one by one (its law's
    ``ShapedLaw.parameters_compared`` false: a spline's coefficients weigh basis functions on knots each method
    chooses from its own data; its force over the stroke is compared, in the posterior's band).
    """
    from negstiff.models import effects

    return name in effects.names() and not getattr(effects.get(name).law, "parameters_compared", True)


def coefficient_keys(estimates: dict[str, dict[str, float]], intervals: dict[str, dict[str, tuple]]) -> list[str]:
    """The coefficients a report's table holds: the contract's five, and every other any estimate or interval has
    (a law's parts' parameters), in the order first met; a base coefficient every estimate holds at zero and no
    interval has (the cubic's k3 beside a magnet's law) is left out where other rows remain.
    """
    keys = list(COEFFICIENTS)
    sources: list[dict[str, Any]] = [*estimates.values(), *intervals.values()]
    for d in sources:
        keys += [k for k in d if k not in keys]
    extra = [k for k in keys if k not in COEFFICIENTS]
    if not extra:
        return keys
    held = [
        k
        for k in COEFFICIENTS
        if any(est.get(k) for est in estimates.values()) or any(k in iv for iv in intervals.values())
    ]
    return held + extra


def _slug(text: str) -> str:
    return "".join(ch if ch.isalnum() else "_" for ch in text.lower()).strip("_")[:40]


def _with_label(name: str, label: str) -> str:
    return f"{name} ({label})" if label else name


def _frame_words(resp: dict) -> str:
    """The frame of a derived z in plain words, for the record's summary line ('' when z was measured)."""
    method = resp.get("frame")
    if not method:
        return ""
    if resp.get("frame_offset_m") is None:
        why = method.removeprefix("not pinned:").strip()
        return f"; z's frame (its unknown constant) is not pinned ({why}): positions in z are up to that constant"
    return f"; z's frame pinned by {method}"


def _accelerometer_floor(rec) -> tuple[float, list[float]] | None:
    """Where NSI reads a structure through its accelerometers (no masses, every sensor an accelerometer: its outputs
    the accelerations), each accelerometer's white noise (as the loader measured it) in % of its acceleration's rms,
    and their pooled value (as the held-out errors are pooled); else None.
    """
    from negstiff.inference.estimators.nsi._state_space import output_kind, sensor_channels, sensor_outputs

    if rec.n_dof < 2 or rec.masses is not None or output_kind(rec) != "acceleration":
        return None
    chans = sensor_channels(rec)
    noise = [float(chans[k].get("acceleration_noise_m_s2") or np.nan) for k in range(1, rec.n_dof + 1)]
    if not np.all(np.isfinite(noise)):
        return None
    acc = sensor_outputs(rec, "acceleration")
    per = [100 * n / float(np.std(acc[:, k])) for k, n in enumerate(noise)]
    return float(np.sqrt(np.mean(np.square(per)))), per


def record_section(rec, label: str = "") -> Section:
    """The record as negstiff read it: time base, sensor, derivation, frame and its anchor, warnings."""
    info = rec.info
    resp = info.get("response", {})
    # the file's name in the heading (a lab's path ran off the page there and in the title), its path in the table
    sec = Section("record", label, _with_label(f"The record: {Path(rec.source).name}", label))
    noise_pct, per_dof = None, []
    if rec.z is not None and rec.z.size > 64:
        # each channel's white-noise floor (``channel_noise``, kept with the record) in % of its rms; a structure's
        # pooled as its held-out errors are (over its DOFs)
        per_dof = [100 * float(n) / float(np.sqrt(np.mean(z**2))) for n, z in zip(rec.channel_noise(), rec.channels,
                                                                                      strict=True)]  # fmt: skip
        noise_pct = float(np.sqrt(np.mean(np.square(per_dof))))
    masses = rec.masses
    if masses is not None:  # a structure's: each DOF's mass
        mass_row = ["masses [kg]", ", ".join(f"{m:g}" for m in masses)]
    elif rec.n_dof > 1:
        mass_row = ["masses [kg]", "not given: NSI reads the structure through its sensors (a state-space part)"]
    else:
        mass_row = ["mass [kg]", rec.mass if rec.mass is not None else "not given: coefficients per unit mass"]
    rows = [
        ["file", rec.source],
        ["samples", rec.n],
        ["sampling rate [Hz]", rec.fs],
        ["duration [s]", rec.duration],
        ["input", rec.input_name],
        ["time base", info.get("time", {}).get("source", "")],
        ["response measured", resp.get("measured") or "z"],
        ["how z was derived", resp.get("derived") or "measured"],
        ["frame", resp.get("frame", "as measured" if resp.get("z_constant_known", True) else "not pinned")],
        ["frame offset [mm]", "none" if resp.get("frame_offset_m") is None else 1e3 * resp["frame_offset_m"]],
        mass_row,
        ["sensor-noise floor [% of rms z]", noise_pct if len(per_dof) < 2 else
         f"{fmt(noise_pct, 3)} (by DOF: {', '.join(fmt(x, 3) for x in per_dof)})"],
    ]  # fmt: skip
    if rec.n_dof > 1:
        rows.insert(4, ["degrees of freedom", rec.n_dof])
    acc_floor = _accelerometer_floor(rec)
    if acc_floor is not None:  # NSI's outputs are the accelerations: their floor beside its errors
        rows.append(["accelerometers' noise floor [% of rms acceleration]",
                     f"{fmt(acc_floor[0], 3)} (by sensor: {', '.join(fmt(x, 3) for x in acc_floor[1])})"])  # fmt: skip
    sec.table(["", "value"], rows)
    said = list(dict.fromkeys([*info.get("warnings", []), *resp.get("warnings", [])]))  # each once: a structure's
    for w in said:  # sensors of one kind say the same
        sec.warning(w)
    sec.heldout["the record's sensor-noise floor"] = noise_pct
    if acc_floor is not None:
        sec.heldout["the accelerometers' noise floor [% of rms acceleration]"] = acc_floor[0]
    sec.summary.append(
        f"Record {Path(rec.source).name}: {rec.duration:.4g} s at {rec.fs:g} Hz, input {rec.input_name}, response "
        f"{resp.get('measured') or 'z'}" + (f" ({resp['derived']})" if resp.get("derived") else "")
        + _frame_words(resp)
        + f"; {len(said)} warning(s) about it."
    )  # fmt: skip
    sec.json = {"source": rec.source, "n": rec.n, "fs": rec.fs, "info": info, "noise_floor_percent": noise_pct,
                "mass": rec.mass, **({"dofs": rec.n_dof, "masses": None if masses is None else list(masses),
                                      "noise_floor_percent_by_dof": per_dof} if rec.n_dof > 1 else {})}  # fmt: skip
    return sec


def structure_section(est, label: str = "") -> Section:
    """A structure's identification (``NSI``/``SINDy`` fitted on a record of N DOFs, or its result): each well's
    modes, the element's law and each channel's zero; read through the sensors (no masses: a state-space linear
    part), the modes in band and the element's coefficients with their standard errors.
    """
    r = getattr(est, "result_", est)
    name = {"nsi": "NSI", "sindy": "SINDy", "discrepancy": "the discrepancy workflow"}.get(r.method, r.method)
    col = _with_label(name if r.method != "discrepancy" else "discrepancy", label)
    j = r.to_json()
    i, k = j["element_at"]
    place = f"element {i}-{k}: between DOF {i} and DOF {k}" if i else f"element 0-{k}: between the base and DOF {k}"
    sec = Section("identification", label, _with_label(f"{name}: the structure ({j['dofs']} DOFs, {place})", label))
    rows = [[w, n + 1, m.f_hz, 100 * m.zeta, ", ".join(fmt(x, 3) for x in m.shape)]
            for w, ms in r.modal.items() for n, m in enumerate(ms)]  # fmt: skip
    v = j["validation"]
    if j.get("linear_part") == "state_space":
        settings = j.get("settings") or {}
        accelerations = settings.get("outputs") == "acceleration"
        sec.text(f"No masses: the linear part is a state-space model of order {j['order']} (its stabilisation "
                 "diagram's), every mode in the force's band; the element's coefficients through the measured "
                 "driving point (reciprocity), each with its standard error. Its outputs: "
                 + (str(settings["sampling"]) if settings.get("sampling") else "the sensors' displacements")
                 + (" (the held-out errors are of their rms, not of z's)" if accelerations else "") + ".")  # fmt: skip
        from .figures import state_space_figure

        sec.figure(f"state_space_{_slug(label or col)}", state_space_figure(j, f"{col}: the linear part"),
                   "Left, the stabilisation diagram: each order's poles (filled where the next orders hold them), "
                   "the modes read (grey) and the order chosen (dashed). Right, the model's underlying-linear FRF "
                   "from the measured force to each sensor.")  # fmt: skip
        sec.table(["", "mode", "f [Hz]", "zeta [%]", "shape (by sensor)"], rows)
        choice = settings.get("law_choice")
        if choice:  # law="auto": the laws compared on the selection part
            sec.text(f"The element's law, {choice['chosen']}, chosen by {choice['criterion']} ({choice['selection']}):")
            sec.table(["law", "selection median window [%]", "selection rms [%]", "why not"],
                      [[c["law"], c.get("median_window_percent"), c.get("rms_percent"), "; ".join(c["problems"][:1])]
                       for c in choice["candidates"]])  # fmt: skip
        coefs = [[c, e["value"], e.get("se")] for c, e in j["element"].items() if isinstance(e, dict) and "value" in e]
        sec.table(["coefficient", "value", "standard error"], coefs)
        coefficients = {c: value for c, value, _ in coefs}
        held = v.get("rms_percent")
        best = v.get("best_linear_rms_percent")
        sec.text(f"Held-out windows: the model misses them by {fmt(held, 3)} % of their rms, its linear part "
                 f"alone by {fmt(v.get('linear_rms_percent'), 3)} %"
                 + ("." if best is None else f", the best linear model of its order (the force its only input, "
                    f"the element's equivalent stiffness and damping taken in) by {fmt(best, 3)} %."))  # fmt: skip
        of = " [% of rms acceleration]" if accelerations else ""
        top = max((c for c in coefficients if c[:1] == "k" and c[1:].isdigit()), key=lambda c: int(c[1:]), default=None)
        said = "" if top is None else f"{top} = {fmt(coefficients[top])} +- {fmt(j['element'][top].get('se'), 2)}"
    else:
        el = r.structure.element
        sec.estimates[col] = effective(el)
        sec.text("Each well's underlying-linear modes (the element linearised at the well; shapes by DOF, the "
                 "largest 1):")  # fmt: skip
        sec.table(["well", "mode", "f [Hz]", "zeta [%]", "shape (by DOF)"], rows)
        units = coefficient_units()
        r_is = f"z{k}" + (f" - z{i}" if i else "")
        sec.text(
            f"The element's law, its force across {i}-{k} as the relative motion r = {r_is} and r' drive it "
            "(F = k3 r^3 + k2 r^2 - k1 r + k0 + c r' + c_nl r'|r'|):"
        )
        sec.table([f"{c} [{units[c]}]" for c in COEFFICIENTS], [[getattr(el, c) for c in COEFFICIENTS]])
        sec.text(
            "The linear structure (the element's part excluded), stiffness K [N/m] and damping C [N s/m] by DOF: "
            + "; ".join(f"K row {n + 1}: {', '.join(fmt(x, 4) for x in row)}" for n, row in enumerate(r.structure.K))
            + ". " + "; ".join(f"C row {n + 1}: {', '.join(fmt(x, 3) for x in row)}"
                               for n, row in enumerate(r.structure.C))
            + ". Each channel's zero found (measured = physical + offset): "
            + ", ".join(f"z{n + 1} {fmt(1e3 * o, 3)} mm" for n, o in enumerate(j["offsets_m"])) + "."
        )  # fmt: skip
        held = v.get("rms_percent")
        sec.text(f"Held-out validation (the last part of the record, not used to identify): free runs of "
                 f"{fmt(v.get('window_s'), 2)} s restarted at the measured states miss it by {fmt(held, 3)} % of "
                 f"rms z over every DOF (by DOF: {', '.join(fmt(x, 3) for x in v.get('per_dof_percent', []))} %); "
                 f"a right model misses a record like this by about {fmt(v.get('floor_percent'), 3)} % (the fitted "
                 "structure run on its own record with the channels' noise: what noise, smoothing and chaos leave "
                 "any model).")  # fmt: skip
        said = f"k3 = {fmt(el.k3)} N/m^3"
        of, best = "", None
    sec.heldout[col + of] = held
    if best is not None:  # after the model in the report's held-out table: the baseline it must beat
        sec.heldout[f"the best linear model of {col}'s order{of}"] = best
    for w in r.warnings:
        sec.warning(w)
    modes = "; ".join(f"{w}: " + ", ".join(f"{m.f_hz:.4g} Hz ({100 * m.zeta:.3g} %)" for m in ms)
                      for w, ms in r.modal.items())  # fmt: skip
    sec.summary.append(f"{col}'s structure: element {said}; modes {modes}; held-out error {fmt(held, 3)} %"
                       + (" of the accelerations' rms." if of else "."))  # fmt: skip
    sec.json = j
    return sec


def identification_section(est, label: str = "") -> Section:
    """An identification (``NSI``/``SINDy`` fitted, or its ``Identification``)."""
    r = getattr(est, "result_", est)
    name = {"nsi": "NSI", "sindy": "SINDy"}.get(r.method, r.method)
    col = _with_label(name, label)
    sec = Section("identification", label, _with_label(f"{name}: identification", label))
    refined = bool(r.refinement and r.refinement.get("applied"))
    sec.estimates[col] = effective(r.model)
    sec.models[col] = r.model
    q = np.asarray(r.stroke_quantiles_m, float)
    sec.stroke = (float(q[0]), float(q[-1])) if q.size >= 2 else None
    if refined:
        sec.estimates[_with_label(f"{name}, its own estimate", label)] = effective(r.initial_model)
    final = r.details.get("modal_of_model") or {}

    def _pct(m):
        return None if m.get("zeta") is None else 100 * m["zeta"]

    rows = [[w, m.get("f_hz"), _pct(m), final.get(w, {}).get("f_hz"), _pct(final.get(w, {}))]
            for w, m in r.modal.items()]  # fmt: skip
    sec.text(
        "Each well's underlying-linear system, by the method's own step ("
        + ("NSI: its subspace step" if r.method == "nsi" else "its equation-error model linearised")
        + "; reference study Table 1) and by the final model linearised:"
    )
    sec.table(["well", "own f [Hz]", "own zeta [%]", "final f [Hz]", "final zeta [%]"], rows)
    per_kg = bool(r.mass_normalised)  # no mass given: every coefficient the device's over its moving mass
    units = coefficient_units(per_kg)
    mass_col = [] if per_kg else ["m [kg]"]
    own = effective(r.initial_model)
    keys = coefficient_keys({"final": effective(r.model), **({"own": own} if refined else {})}, {})
    cols = [k for k in keys if k in UNITS]  # the base coefficients; a law's parts' parameters in their own table
    sec.table(
        ["model", *[f"{k} [{units[k]}]" for k in cols], *mass_col],
        [["final" + (" (output-error refined)" if refined else ""), *[getattr(r.model, k) for k in cols],
          *([] if per_kg else [r.model.m])]]
        + ([["own estimate (equation error)", *[getattr(r.initial_model, k) for k in cols],
             *([] if per_kg else [r.initial_model.m])]] if refined else []),
    )  # fmt: skip
    if per_kg:
        sec.text("No mass was given: the coefficients are per kilogram of moving mass (the device's divided by it).")
    v = r.validation
    # a quiet tail (a decay's) scores no restarted window: the one free run's error then
    held_keys = ("restarted_rms_percent", "median_window_percent", "rms_percent")
    held = next((v[k] for k in held_keys if v.get(k) is not None), None)
    sec.heldout[col] = held
    t0, t1 = v.get("segment", [None, None])
    sec.text(
        f"Held-out validation over {fmt(t0, 4)}-{fmt(t1, 4)} s (not used to identify): restarted 2 s free runs miss "
        f"it by {fmt(held, 3)} % of rms z, one free run over the whole tail by {fmt(v.get('rms_percent'), 3)} %. "
        + (f"Refinement: {r.refinement.get('reason')}." if r.refinement else "No output-error refinement.")
        + f" Mass: {r.mass_source}."
    )  # fmt: skip
    mean, std = v.get("residual_mean"), v.get("residual_std")
    if held is not None and held == v.get("rms_percent") and mean is not None and std:
        offset = mean**2 / (mean**2 + std**2)
        if offset > 0.25:  # a ring-down's quiet tail: its rest, not its motion, can hold most of the error
            sec.text(
                f"{fmt(100 * offset, 2)} % of that free run's squared error is a constant offset "
                f"({fmt(mean, 2)} in z's units): the model's rest against the record's, not its motion."
            )
    if r.method == "sindy" and "selected_terms" in r.details:
        sec.text(f"Selected terms: {', '.join(r.details['selected_terms'])}.")
    _law_blocks(sec, r, name)
    for w in r.warnings:
        sec.warning(w)
    # the summary's wells are the final model's (the one written, refined where it was); the method's own estimate
    # beside them where it differs by more than 5 %: on an in-well sweep SINDy's own put a 8.25 Hz well at 4.8 Hz
    # and its refined model at 8.26 Hz (measured), and the summary said 4.8
    said = final if any(m.get("f_hz") for m in final.values()) else r.modal
    wells = ", ".join(f"{w} {mm['f_hz']:.4g} Hz (zeta {100 * mm['zeta']:.3g} %)" for w, mm in said.items()
                      if mm.get("f_hz"))  # fmt: skip
    apart = [f"{w} {m['f_hz']:.4g} Hz" for w, m in r.modal.items() if m.get("f_hz") and said.get(w, {}).get("f_hz")
             and abs(m["f_hz"] / said[w]["f_hz"] - 1) > 0.05]  # fmt: skip
    own_said = f" (its own step's estimate: {', '.join(apart)})" if apart and said is final else ""
    sec.summary.append(f"{col}'s model has its wells at {wells or 'none'}{own_said}; held-out error {fmt(held, 3)} % "
                       "of rms z.")  # fmt: skip
    sec.json = r.to_json()
    return sec


def _law_blocks(sec: Section, r, name: str) -> None:
    """The law the identification read (its formula and its parts' values), the comparison of laws where one was
    made, and the held-out tail in windows of the record's predictability (the report draws every method's force
    over the stroke once, ``Report``).
    """
    from negstiff.models import laws

    law_name = r.settings.get("law")
    law = laws.get(law_name) if law_name in laws.names() else None
    if law is not None:
        damping = r.settings.get("damping_law")
        sec.text(f"Restoring-force law: {law.name}, {law.title} ({law.reference})"
                 + (f"; damping law: {damping}." if damping and damping != "catalogue" else "."))  # fmt: skip
        final, own = _part_parameters(r.model.extra), _part_parameters(r.initial_model.extra)
        rows = [[k, final[k], own.get(k)] for k in final if "." in k]  # one fit's: a spline's knots are its own
        parts = set(law.parts) | (set(laws.get(damping).parts) if damping in laws.names("damping") else set())
        rows += [
            [k, float(v), r.initial_model.extra.get(k)]
            for k, v in r.model.extra.items()
            if k in parts and not isinstance(v, Mapping)
        ]  # the laws' monomials (z^4 ... z^7, the damping's z'^3)
        if rows:
            sec.table(["the law's part", "final (SI)", "own estimate (SI)"], rows)
        if r.settings.get("shape"):
            sec.text(f"Its shape, from the record: {r.settings['shape'].get('method', '')}.")
    choice = r.details.get("law_choice")
    if choice:
        sec.text(f"Laws compared: {choice.get('summary', '')}.")
        sec.table(["law", "held-out median window [%]", "weight", "why not"],
                  [[c["law"], c["heldout_median_window_percent"], c["weight"], "; ".join(c["problems"][:1])]
                   for c in choice["candidates"]])  # fmt: skip
    pred = r.validation.get("predictable") or {}
    if pred.get("median_window_percent") is not None:
        sooner = " sooner" if pred.get("limited") else ""
        sec.text(f"In windows as long as the record stays predictable ({fmt(pred['window_s'], 3)} s: runs restarted "
                 f"from states that differ by their noise part by 10 % of rms z{sooner}), the held-out median window "
                 f"errs by {fmt(pred['median_window_percent'], 3)} %.")  # fmt: skip


def posterior_section(post, label: str = "") -> Section:
    """A fitted ``Posterior``: the summary table with diagnostics, the credible intervals."""
    from negstiff.models import effects

    res = post.result()
    pct = 100 * res["hdi_prob"]
    sec = Section("posterior", label, _with_label("Posterior (emcee)", label))
    rows = []
    for n, s in res["parameters"].items():
        rows.append([n, s["mean"], s["sd"], s["hdi_low"], s["hdi_high"], s["r_hat"], s["ess_bulk"]])
        part = n.partition(".")[0]
        if n in COEFFICIENTS or ("." in n and not compared_by_force(part)) or n in effects.names():
            # a base coefficient, a law's part's parameter (PART.NAME) or a scalar part (the z'^3 term's)
            sec.interval[n] = (s["mean"], s["hdi_low"], s["hdi_high"])
    sec.table(["parameter", "mean", "sd", f"{pct:g} % low", f"{pct:g} % high", "R-hat", "ESS bulk"], rows)
    st = res["settings"]
    sec.text(
        f"{st['ensembles']} independent ensembles of {st['walkers']} walkers, {st['kept_steps_per_ensemble']} kept "
        f"steps each; {st['windows']} windows of {st['window_s']:g} s; "
        + ("converged." if res["converged"] else "NOT converged: see the warnings.")
    )  # fmt: skip
    for w in res["warnings"]:
        sec.warning(w)
    if res.get("force_band"):
        sec.band = {**res["force_band"], "label": f"posterior {100 * res['force_band']['prob']:g} % band"}
        sec.stroke = (float(sec.band["z_m"][0]), float(sec.band["z_m"][-1]))
    if "k3" in sec.interval:
        mean, lo, hi = sec.interval["k3"]
        per_kg = st.get("mass") is None and not st.get("masses") and st.get("model") == "coefficients"
        unit = coefficient_units(per_kg)["k3"]
        sec.summary.append(
            f"The posterior puts k3 at {fmt(mean)} {unit} ({pct:g} % interval {' to '.join(fmt_interval(lo, hi))})"
            + ("." if res["converged"] else "; its chains did not converge (warnings).")
        )
    sec.json = res
    return sec


def interval_section(own: dict[str, Any], label: str = "", prob: float = 0.95) -> Section:
    """A method's own estimate with its batch-means interval (``Identifier.own_estimate``): each block of the
    identification part (a hammer's record: about one hit each) identified alone; the interval is Student's t
    over the blocks (``blocks - 1`` degrees of freedom) times the standard error they give.
    """
    from scipy import stats

    name = {"nsi": "NSI", "sindy": "SINDy"}.get(own["method"], own["method"])
    blocks = len(own["blocks"])
    t = float(stats.t.ppf(0.5 + prob / 2, blocks - 1))
    sec = Section("interval", label, _with_label(f"{name}: its estimate's interval ({blocks} blocks)", label))
    rows = []
    for well, ms in own["modal"].items():
        modes = ms if isinstance(ms, list) else [ms]  # a structure's: every mode of the well
        for i, m in enumerate(modes):
            if m.get("f_hz") is None:
                continue
            where = f"{well}, mode {i + 1}" if isinstance(ms, list) else well
            for key, unit, scale in (("f_hz", "Hz", 1.0), ("zeta", "%", 100.0)):
                se = m.get(f"{key}_se")
                half = None if se is None else t * se * scale
                rows.append([f"{key} ({where}) [{unit}]", scale * m[key], half])
    others = [k for k in own["model"] if k not in (*COEFFICIENTS, "k0")]  # a state-space element's (k2_tilde, ...)
    for key in [k for k in COEFFICIENTS if k in own["model"]] + others:
        mean, se = own["model"].get(key), own["model_se"].get(key)
        rows.append([key, mean, None if se is None else t * se])
    sec.table(["quantity", "estimate", f"+- ({100 * prob:g} %)"], rows)
    element = f" (a structure's: its element's, at {'-'.join(map(str, own['element_at']))})" if "dofs" in own else ""
    sec.text(f"The identification part cut into {blocks} blocks, each identified alone by {name}'s own "
             f"step{element} (no refinement); {100 * prob:g} % interval: Student's t ({blocks - 1} degrees of "
             "freedom) times the blocks' standard error (their scatter over sqrt(blocks)). The estimate is the whole "
             "record's.")  # fmt: skip
    # not the coefficient table's ``interval`` (a posterior's credible interval): a batch-means interval of its own
    mean, se = own["model"].get("k3"), own["model_se"].get("k3")
    if mean is not None and se is not None:
        unit = coefficient_units(bool(own.get("mass_normalised")))["k3"]
        sec.summary.append(f"{name}'s k3 = {fmt(mean)} {unit} ({100 * prob:g} % interval over {blocks} blocks: "
                           f"{' to '.join(fmt_interval(mean - t * se, mean + t * se))}).")  # fmt: skip
    sec.json = dict(own)
    return sec


def discrepancy_section(d, label: str = "") -> Section:
    """A fitted ``Discrepancy``: what it named, its size, where the baseline erred, the gap before and after."""
    res = d.result()
    if "dofs" in res:  # a structure's: its final model is a structure (``structure_section``), its account details
        return _structure_discrepancy_section(d, res, label)
    sec = Section("discrepancy", label, _with_label("Discrepancy: where model and data disagree", label))
    col = _with_label("discrepancy", label)
    sec.estimates[col] = effective(res["model"])
    named = [e for e in res["effects"] if e != "none"]
    sec.text(f"Where: {res['where']}.")
    sec.table(["effect", "held-out weak residual score [%]"], [[r["effect"], r["score"]] for r in res["ranking"]])
    sizes = ", ".join(
        f"{e} = " + (", ".join(f"{k} {fmt(x)}" for k, x in v.items()) if isinstance(v, dict) else fmt(v))
        for e, v in res["effect_size"].items()
    )
    sec.text(
        ("Named: " + ", ".join(named) + f" ({sizes})." if named else "No catalogue effect passed its margin.")
        + f" Held-out gap (restarted free runs, median window): {fmt(res['gap_before_percent'], 3)} % before, "
        f"{fmt(res['gap_after_percent'], 3)} % after."
    )  # fmt: skip
    sec.heldout[col] = res["gap_after_percent"]
    _verdicts(sec, res.get("iterations") or [])
    _unnamed(sec, res.get("unnamed"))
    for w in res["warnings"]:
        sec.warning(w)
    sec.summary.append(
        (f"The discrepancy workflow names {', '.join(named)} ({sizes})" if named else
         "The discrepancy workflow names no missing effect")
        + f"; held-out gap {fmt(res['gap_before_percent'], 3)} % -> {fmt(res['gap_after_percent'], 3)} %."
    )  # fmt: skip
    sec.json = res
    return sec


def _structure_discrepancy_section(d, res: dict[str, Any], label: str) -> Section:
    """A structure's discrepancy workflow: each registered effect scored on the held-out weak residual beside the
    element's base law, the one named (if any) and the held-out gap before and after, then its final structure.
    """
    det = res["details"]
    effects = [e for e in det.get("effects", [det["effect"]]) if e != "none"]
    title = _with_label("Discrepancy: where the structure's model and data disagree", label)
    sec = Section("discrepancy", label, title)
    if det.get("where"):  # on the element's relative motion
        sec.text(f"Where (the element's relative motion): {det['where']}.")
    sec.table(["effect", "held-out weak residual score [%] (first round)"],
              [[r["effect"], r["score"]] for r in det["ranking"][:6]])  # fmt: skip
    extra = res["structure"]["element"].get("extra") or {}
    size = "" if not effects else " (" + ", ".join(f"{e} = {fmt(extra.get(e))}" for e in effects) + ")"
    named = ", ".join(effects) or None
    sec.text((f"Named: {named}{size}." if named else "No registered effect passed its margin.")
             + f" Held-out gap (restarted free runs): {fmt(det['gap_before_percent'], 3)} % before, "
             f"{fmt(det['gap_after_percent'], 3)} % after.")  # fmt: skip
    _verdicts(sec, det.get("iterations") or [])
    _unnamed(sec, det.get("unnamed"))
    sec.text("The final structure:")
    final = structure_section(d, label)
    sec.blocks += final.blocks
    sec.estimates, sec.heldout = final.estimates, final.heldout
    sec.summary = [
        (
            f"The discrepancy workflow names {named}{size}"
            if named
            else "The discrepancy workflow names no missing effect of the structure's element"
        )
        + f"; held-out gap {fmt(det['gap_before_percent'], 3)} % -> {fmt(det['gap_after_percent'], 3)} %."
    ]
    sec.json = res
    return sec


def _verdicts(sec: Section, iterations: list[dict[str, Any]]) -> None:
    """Each round's verdict on the effect the equation error named (kept or left out, and on which windows: where
    it acts, its cross-validated blocks, or the whole held-out tail), a table, where any round judged one.
    """
    rows = [[k + 1, it["verdict"]] for k, it in enumerate(iterations) if it.get("verdict")]
    if rows:
        sec.table(["round", "verdict: the prediction without and with the named effect"], rows)


def _unnamed(sec: Section, un: dict[str, Any] | None) -> None:
    """What no effect names (``Discrepancy(unnamed=True)``): the non-parametric term's size and the held-out windows
    without and with it (the joint fit; a structure's with the term held too), or why it was not fitted.
    """
    if not un:
        return
    if "gap" not in un:
        sec.text(f"Unnamed term: not fitted ({un.get('reason', 'no reason given')}).")
        return
    g = un["gap"]
    without, with_it = (fmt(g.get(f"{k}_median_window_percent"), 3) for k in ("physics", "hybrid"))
    held = g.get("held_median_window_percent")
    sec.text(
        f"Unnamed term (what no effect names, a non-parametric force fitted jointly with the physics): "
        f"{fmt(un['term_percent_of_restoring_force'], 2)} % of the restoring force; held-out median window "
        f"{without} % without it, {with_it} % with it"
        + (f" ({fmt(held, 3)} % with the physics held)" if held is not None else "")
        + "."
    )


def frf_section(res: dict[str, Any], label: str = "", title: str = "") -> Section:
    """An ``frf`` result (its spectra ``_curves`` drawn where it holds them)."""
    if "dofs" in res:  # a structure's: every DOF's FRF, the modes merged
        return _frf_dofs_section(res, label, title)
    sec = Section("frf", label, _with_label("Frequency response (H1, H2, coherence)", label))
    curves = res.get("_curves")
    if curves is not None:
        from .figures import frf_figure as figure

        input_name = "base_acc" if "base_acc" in res.get("response_per_input", "") else "force"
        fig = figure(res, curves, input_name, title or "FRF")
        sec.figure(f"frf_{_slug(label or 'record')}", fig, "H1 and H2 with each fitted peak; coherence below.")
    sec.table(["peak", "f [Hz]", "zeta [%]", "coherence"],
              [[i + 1, p["f_hz"], 100 * p["zeta"], p.get("coherence")]
               for i, p in enumerate(res["peaks"])])  # fmt: skip
    for w in res.get("warnings", []):
        sec.warning(w)
    top = "no peak" if res["f_hz"] is None else f"{res['f_hz']:.4g} Hz, zeta {100 * res['zeta']:.3g} %"
    sec.summary.append(f"The FRF's dominant peak: {top} ({len(res['peaks'])} peak(s) in {res['band'][0]:.3g}-"
                       f"{res['band'][1]:.3g} Hz).")  # fmt: skip
    sec.json = {k: v for k, v in res.items() if k != "_curves"}
    return sec


def _frf_dofs_section(res: dict[str, Any], label: str, title: str) -> Section:
    """A structure's ``frf`` result: every DOF's |H1| and coherence, the merged modes and the DOFs that show each."""
    sec = Section("frf", label, _with_label("Frequency response of every DOF (H1, coherence)", label))
    curves = res.get("_curves")
    if curves is not None:
        from .figures import frf_figure_dofs

        input_name = "base_acc" if "base_acc" in res["dofs"][0].get("response_per_input", "") else "force"
        model = res.get("_model_frf")
        fig = frf_figure_dofs(res, curves, input_name, title or "FRFs", model)
        sec.figure(f"frf_{_slug(label or 'record')}", fig, "|H1| from the input to each DOF, the modes found marked; "
                   "coherence below" + (f"; dashed, {model['label']}'s underlying-linear FRF at each DOF"
                                        if model else "") + ".")  # fmt: skip
    sec.table(["mode", "f [Hz]", "zeta [%]", "seen on"],
              [[i + 1, m["f_hz"], 100 * m["zeta"], ", ".join(f"z{d}" for d in m["seen_on"])]
               for i, m in enumerate(res["modes"])])  # fmt: skip
    for w in res.get("warnings", []):
        sec.warning(w)
    said = ", ".join(f"{m['f_hz']:.4g} Hz ({100 * m['zeta']:.3g} %)" for m in res["modes"]) or "no peak"
    sec.summary.append(f"The FRFs show {len(res['modes'])} mode(s): {said}.")
    sec.json = {k: v for k, v in res.items() if not k.startswith("_")}
    return sec


def backbone_section(res: dict[str, Any], label: str = "", model_name: str = "") -> Section:
    """A ``backbone`` result (``negstiff.inference.analysis.backbone``): the measured curves and, where the
    result holds it, the identified model's (``model_name`` says which identification's).
    """
    from .figures import backbone_figure

    sec = Section("backbone", label, _with_label("Backbone of the free decay (frequency and damping against "
                                                 "amplitude)", label))  # fmt: skip
    sec.figure(f"backbone_{_slug(label or 'record')}", backbone_figure(res, "backbone"),
               "Frequency and damping ratio against amplitude: measured (Hilbert, peaks)"
               + (f" and {model_name or 'the model'}'s free decay from the record's state" if res.get("predicted")
                  else "")
               + ("; grey, the model's forced response at three force levels" if (res.get("forced") or {}).get("curves")
                  else ""))  # fmt: skip
    lo, hi = res["amplitude_range_m"]
    lin = res["linear"]
    d = res["decay"]
    sec.text(f"The decay from {fmt(d.get('start_s'), 4)} s ({d.get('found', '')}); amplitudes {fmt(1e3 * lo, 3)} to "
             f"{fmt(1e3 * hi, 3)} mm. At its smallest amplitudes: {fmt(lin['f_hz'], 5)} Hz, zeta "
             f"{fmt(100 * lin['zeta'], 3)} %. {res.get('estimator', '')}.")  # fmt: skip
    modes = res.get("modes_hz") or []
    if len(modes) > 1:  # a structure's decay: which of its modes this backbone is
        sec.text(f"The decay rings at {', '.join(fmt(f, 4) for f in modes)} Hz (its channels' periodogram peaks); this "
                 f"is the backbone of the mode DOF {res['dof']}'s channel shows most, band-passed between its "
                 "neighbours.")  # fmt: skip
    hil = res["measured"]["hilbert"]
    a = np.asarray(hil["amplitude_m"])
    rows = []
    if a.size:
        for q in (0.1, 0.5, 0.9):
            k = int(np.argmin(np.abs(a - np.quantile(a, q))))
            rows.append([1e3 * a[k], hil["f_hz"][k], 100 * hil["zeta"][k]])
    sec.table(["amplitude [mm]", "f [Hz] (Hilbert)", "zeta [%]"], rows)
    pred = res.get("predicted")
    if pred:
        diff = fmt(pred.get("difference_percent"), 3)
        sec.text(f"{model_name or 'The model'}'s backbone differs from the measured one by {diff} % at most over the "
                 "measured range (frequency, Hilbert).")  # fmt: skip
        forced = (res.get("forced") or {}).get("curves", [])
        if forced:
            off = max(abs(c["peak_off_backbone_percent"] or 0.0) for c in forced)
            sec.text(f"Grey: the forced response {model_name or 'the model'} predicts under a harmonic force of "
                     + ", ".join(f"{fmt(c['force_n'], 2)}" for c in forced)
                     + f" {res['forced'].get('force_unit', 'N')} about its "
                     f"{res['forced']['well']} well (continuation, dashed where unstable); each peak lies within "
                     f"{'0.01' if off < 0.01 else fmt(off, 2)} % of the model's own backbone (light damping puts it "
                     "zeta^2 below).")  # fmt: skip
    for w in res.get("warnings", []):
        sec.warning(w)
    on = f" (DOF {res['dof']}, the mode it shows most)" if len(modes) > 1 else ""
    sec.summary.append(
        f"The decay's backbone{on}: {fmt(lin['f_hz'], 5)} Hz at small amplitude, over {fmt(1e3 * lo, 3)}-"
        f"{fmt(1e3 * hi, 3)} mm"
        + (f"; {model_name or 'the model'}'s within {fmt(pred.get('difference_percent'), 3)} %." if pred else ".")
    )
    sec.json = dict(res)
    return sec


def characterisation_section(res: dict[str, Any], label: str = "") -> Section:
    """A ``characterise`` result: period, regime, amplitudes, Lyapunov exponent, and why not where not."""
    sec = Section("characterisation", label, _with_label("Characterisation of the harmonic response", label))
    lle = res.get("lle") or {}
    forcing = res.get("forcing") or {}
    sec.table(["", "value"], [
        ["period (forcing cycles)", res["period"]], ["regime", res["regime"]], ["chaotic", res["chaotic"]],
        ["forcing, stated [Hz]", forcing.get("stated_hz")], ["forcing, measured on the input [Hz]",
                                                              forcing.get("measured_hz")],
        ["largest Lyapunov exponent, Wolf [1/s]", lle.get("value")], ["its sd [1/s]", lle.get("sd")],
        ["... Rosenstein [1/s]", lle.get("rosenstein")],
    ])  # fmt: skip
    if res.get("residuals"):
        sec.table(["period tested", "residual", "tolerance"],
                  [[p, r, res["tolerances"][p]] for p, r in res["residuals"].items()])  # fmt: skip
    for what, why in res.get("reasons", {}).items():
        sec.text(f"{what}: {why}")
    for w in res.get("warnings", []):
        sec.warning(w)
    sec.summary.append(
        f"The harmonic response is {'period ' + str(res['period']) if res['period'] else 'not periodic'}, "
        f"{res['regime']}, {'chaotic' if res['chaotic'] else 'not chaotic'}."
    )
    sec.json = res
    return sec


def map_section(res: dict[str, Any], overlays=(), label: str = "") -> Section:
    """A bifurcation map (``Campaign.map``) with the continuations drawn over it."""
    sec = Section("map", label, _with_label("Bifurcation map of the campaign", label))
    unit = "m/s^2" if res["input"] == "base_acc" else "N"
    sec.figure(f"map_{_slug(label or 'campaign')}", map_figure(res["points"], list(overlays), unit, res["axis"]),
               "Each record's Poincare z against its measured forcing; continuations over it.")  # fmt: skip
    rows = [[k] + [v for n, v in s.items() if n != "sequence"] for k, s in res["sweeps"].items()]
    key = "first period 2" if res["axis"] == "amplitude" else "jump [Hz]"
    sec.table(["sweep", key], rows)
    for c in res["continuations"]:
        sec.text(f"Continuation {c['label']} ({c['well']} well): " + ", ".join(
            f"{k} {v}" for k, v in c.items() if k not in ("label", "well")))  # fmt: skip
    for w in res["warnings"]:
        sec.warning(w)
    sec.summary.append("The map's sweeps: " + "; ".join(f"{r[0]}: {key} {fmt(r[1]) if len(r) > 1 else 'none'}"
                                                        for r in rows) + ".")  # fmt: skip
    sec.json = res
    return sec


def coefficient_blocks(estimates: dict[str, dict[str, float]], intervals: dict[str, dict[str, tuple]],
                       per_kg: bool = False, element: bool = False):  # fmt: skip
    """The report's coefficient table (each method's estimate of k1-k3, c, c_nl beside each posterior's mean
    and interval) and its forest plot; and the summary's lines on whether the estimates lie inside. ``per_kg``: the
    record states no mass, the coefficients are per kilogram of moving mass; ``element``: a structure's, the
    coefficients its element's, on the relative motion r across it.
    """
    import matplotlib.pyplot as plt

    header = ["coefficient", *estimates]
    for lab in intervals:
        name = "posterior" if lab == "posterior" else f"posterior ({lab})"
        header += [f"{name} mean", "interval low", "interval high"]
    rows = []
    keys = coefficient_keys(estimates, intervals)
    units = coefficient_units(per_kg)
    for k in keys:
        row: list[Any] = [f"{k} [{units[k]}]" if k in units else k, *[est.get(k) for est in estimates.values()]]
        for iv in intervals.values():
            row += list(iv.get(k, (None, None, None)))
        rows.append(row)
    blocks: list[tuple[str, Any]] = [
        ("h", (2, "Coefficients: every method beside the posterior")),
        ("p", ("Each method's estimate of the structure's element, its force on the relative motion r across it "
               "(F = k3 r^3 + k2 r^2 - k1 r + k0 + c r' + c_nl r'|r'|)" if element else
               "Each method's estimate of the z-frame coefficients (K = k3 z^3 + k2 z^2 - k1 z + k0, D = c z' + "
               "c_nl z'|z'|; a law's parts by their parameters, PART.NAME)")
              + ", beside the posterior's mean and credible interval; the forest plot below draws the same."
              + (" No mass was given: they are per kilogram of moving mass." if per_kg else "")),
        ("table", (header, [[fmt(c) for c in r] for r in rows])),
    ]  # fmt: skip
    rows_n = len(estimates) + len(intervals)
    fig, axes = plt.subplots(1, len(keys), figsize=(3.2 * len(keys), 1.2 + 0.5 * rows_n), sharey=True,
                             squeeze=False)  # fmt: skip
    labels = [*estimates, *(f"posterior {lab}" if lab != "posterior" else "posterior" for lab in intervals)]
    for ax, k in zip(axes[0], keys, strict=False):
        for j, est in enumerate(estimates.values()):
            if est.get(k) is not None:
                ax.plot(est[k], j, "o", color=f"C{j % 10}")
        for i, iv in enumerate(intervals.values()):
            if k in iv:
                mean, lo, hi = iv[k]
                y = len(estimates) + i
                ax.plot([lo, hi], [y, y], "-", color="k", lw=2)
                ax.plot(mean, y, "s", color="k")
                ax.axvspan(lo, hi, color="0.85", zorder=0)
        ax.set_title(k)
        ax.ticklabel_format(axis="x", style="sci", scilimits=(-3, 4))
    axes[0, 0].set_yticks(range(len(labels)), labels)
    axes[0, 0].invert_yaxis()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    blocks.append(("fig", ("coefficients_forest.png", "Forest plot: each method's estimate (dots) and the posterior's "
                           "mean and credible interval (black, shaded).")))  # fmt: skip
    lines = []
    for lab, iv in intervals.items():
        parts = []
        mine = {c: e for c, e in estimates.items() if lab == "posterior" or c.endswith(f"({lab})")}
        for col, est in (mine or estimates).items():
            inside = [k for k in keys if k in iv and est.get(k) is not None and iv[k][1] <= est[k] <= iv[k][2]]
            n = sum(1 for k in keys if k in iv and est.get(k) is not None)
            parts.append(f"{col} {len(inside)} of {n}" + (f" ({', '.join(inside)})" if inside else ""))
        which = "" if lab == "posterior" else f" ({lab})"
        if parts:  # no method's estimate beside the posterior (a report of the posterior alone): nothing to say
            lines.append(f"Estimates inside the posterior's credible intervals{which}: {'; '.join(parts)}.")
    return blocks, {"coefficients_forest.png": buf.getvalue()}, lines


def draw_branches(ax, branches: list[dict[str, Any]], color, label: str | None = None, x: str = "amplitude") -> None:
    """A continuation's branches on a bifurcation map's axes: each orbit's Poincare z [mm] against its
    amplitude (or ``x``), solid where stable, dashed where not; ``label`` on the first period-1 branch's line.
    """
    for br in branches:
        a = np.array([q[x] for q in br["points"]])
        stable = np.array([q["stable"] for q in br["points"]])
        pz = np.array([q["poincare_z"] for q in br["points"]]) * 1e3
        for k in range(pz.shape[1]):
            for mask, ls in ((stable, "-"), (~stable, "--")):
                ax.plot(a, np.where(mask, pz[:, k], np.nan), ls, color=color, lw=0.9, alpha=0.8,
                        label=label if (k == 0 and ls == "-" and br["period"] == 1) else None)  # fmt: skip


def map_figure(points: list[dict[str, Any]], overlays: Sequence[dict[str, Any]] = (), unit: str = "m/s^2",
               axis: str = "amplitude"):  # fmt: skip
    """The bifurcation map (reference study Figure 4): each record's Poincare z against its forcing amplitude (or its
    frequency, ``axis="f_hz"``: a stepped sine), a panel per starting well (``start``: plus, minus; one panel
    where it is unknown), blue sweeping up, red down, black in the records' order; grey behind a cross-well
    or non-periodic record. Each ``overlays`` entry, a ``negstiff nfrc`` result along the same axis, is drawn
    over its well's panel (``draw_branches``).
    """
    import matplotlib.pyplot as plt

    starts = sorted({p.get("start") for p in points}, key=lambda s: ["plus", "minus", None].index(s))
    fig, axes = plt.subplots(1, len(starts), figsize=(6 * len(starts), 4), sharey=True, squeeze=False)
    xs = np.unique([p[axis] for p in points])
    half = 0.5 * float(np.median(np.diff(xs))) if xs.size > 1 else 0.05 * max(abs(float(xs[0])), 1e-12)
    for ax, start in zip(axes[0], starts, strict=False):
        for p in (q for q in points if q.get("start") == start):
            col = {"up": "C0", "down": "C3"}.get(p.get("direction") or "", "k")
            if p["regime"] == "cross-well" or p["period"] is None:
                ax.axvspan(p[axis] - half, p[axis] + half, color="0.9", zorder=0)
            z = 1e3 * np.asarray(p["poincare_z"])
            ax.plot(np.full(z.size, p[axis]), z, ".", ms=1.5, color=col)
        for k, r in enumerate(overlays):
            if start is None or r["settings"]["well"] == start:
                draw_branches(ax, r["branches"], f"C{(k + 2) % 10}", r.get("label", f"continuation {k + 1}"), axis)
        title = "in the records' order" if start is None else f"starting from z_{start} (blue up, red down)"
        xlabel = "forcing frequency [Hz]" if axis == "f_hz" else f"forcing amplitude [{unit}]"
        ax.set(xlabel=xlabel, title=title)
        if overlays:
            ax.legend(fontsize=8)
    axes[0][0].set_ylabel("Poincare z (phase 0) [mm]")
    fig.tight_layout()
    return fig


def design_section(res: dict[str, Any], label: str = "") -> Section:
    """A ``design`` result: the tests ranked by what they would teach, their predicted widths beside today's, the
    criterion over level and frequency, and what the best costs.
    """
    from negstiff.inference.analysis.design import design_figure

    sec = Section("design", label, _with_label("What to test next", label))
    targets = res["targets"]
    best, ref = res["best"], res["default_test"]
    pct = 100 * res.get("hdi_prob", 0.9)
    table = res["settings"].get("bench", "table") == "table"
    reference = "the rig's default random test" if table else f"the reference test ({ref['test']})"
    what = "" if table else ": hammer hits and releases from a held position, the table still"
    sec.text(f"The tests the {'rig' if table else 'lab'} could run next ({res['settings']['duration_s']:.3g} s "
             f"each{what}), ranked by how much they "
             f"would narrow the {pct:g} % intervals of {', '.join(targets)}: the posterior's draws run through each on "
             "the virtual rig with this record's noise, each simulated record read as the posterior reads one "
             f"({res['search']['evaluated']} tests evaluated, {res['search']['draws']} draws each). Shrinkage: the "
             "geometric mean over the targets of the width now / the predicted width. The first-ranked test, run "
             "and fitted with this record (`negstiff posterior THIS.csv NEXT.csv`), should give the widths in its "
             "row.")  # fmt: skip
    rows = [["now", "", *[res["now"][n] for n in targets], "", "", ""]]
    shown = [r for r in res["ranked"] if r["feasible"]][:5]
    if ref not in shown:
        shown.append(ref)
    for r in shown:
        name = r["test"] + ((" (the rig's default)" if table else " (the reference)") if r["test"] == ref["test"]
                            else "")  # fmt: skip
        # a test whose record could not be read has no cost (its row says why in ``problems``): blank cells
        keys = ((("peak_table_acc_m_s2", 1.0), ("peak_table_disp_m", 1e3)) if table
                else (("peak_force_n", 1.0), ("peak_travel_m", 1e3)))  # fmt: skip
        cost = [r["cost"][k] * f if k in r["cost"] else "" for k, f in keys]
        rows.append([name, r["score"], *[r["predicted_width"][n] for n in targets], *cost,
                     r["cost"].get("draws_visiting_both_wells", "")])  # fmt: skip
    heads = (["peak table acc [m/s^2]", "table stroke [mm]"] if table
             else ["peak force [N]", "travel from the saddle [mm]"])  # fmt: skip
    sec.table(["test", "shrinkage", *[f"{n} {pct:g} % width" for n in targets], *heads,
               "draws visiting both wells"], rows)  # fmt: skip
    sec.figure(f"design_{_slug(label or 'record')}", design_figure(res),
               "The criterion over the candidates' settings: harmonics over frequency and amplitude (left), random "
               "and swept tests over their level (right); the star is the chosen test, the cross the rig's default "
               "random test." if table else "The criterion over the candidates' settings: hammer tests over their "
               "peak force, one line per hit count (left), releases over their start's distance from rest (right); "
               "the star is the chosen test, the cross the reference test.")  # fmt: skip
    infeasible = [r for r in res["ranked"] if not r["feasible"]]
    if infeasible:
        sec.text(f"{len(infeasible)} candidate(s) lay outside the limits (the first: {infeasible[0]['test']}: "
                 f"{infeasible[0]['problems'][0]}).")  # fmt: skip
    for a in res.get("assumptions", []):
        sec.text(f"Assumed: {a}.")
    for w in res.get("warnings", []):
        sec.warning(w)
    sec.summary.append(f"What to test next: {best['test']}, predicted to narrow the intervals of {', '.join(targets)} "
                       f"{best['score']:.3g}x ({reference}: {ref['score']:.3g}x).")  # fmt: skip
    sec.json = res
    return sec


def section_for(result, label: str = "") -> Section:
    """The section of any result a report takes (by its kind)."""
    from negstiff.inference.estimators.discrepancy import Discrepancy
    from negstiff.inference.estimators.identification import Identification, Identifier
    from negstiff.inference.estimators.posterior.core import Posterior
    from negstiff.inference.record.measurement import Measurement

    if isinstance(result, Section):
        return result
    if isinstance(result, Measurement):
        return record_section(result, label)
    if isinstance(result, Discrepancy):
        return discrepancy_section(result, label)
    if getattr(getattr(result, "result_", result), "linear_part", "none") != "none":
        return structure_section(result, label)
    if isinstance(result, (Identifier, Identification)):
        return identification_section(result, label)
    if isinstance(result, Posterior):
        return posterior_section(result, label)
    if isinstance(result, dict) and "standard_error" in result and "blocks" in result:
        return interval_section(result, label)
    if isinstance(result, dict) and "measured" in result and "decay" in result:
        return backbone_section(result, label, result.get("model_name", ""))
    if isinstance(result, dict) and ("peaks" in result or ("modes" in result and "dofs" in result)):
        return frf_section(result, label)
    if isinstance(result, dict) and "regime" in result and "period" in result:
        return characterisation_section(result, label)
    if isinstance(result, dict) and "sweeps" in result:
        return map_section(result, (), label)
    if isinstance(result, dict) and "ranked" in result and "criterion" in result:
        return design_section(result, label)
    raise TypeError(f"a report takes records, fitted estimators and analysis results, not {type(result).__name__}")
