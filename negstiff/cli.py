"""The ``negstiff`` command line: a thin shell over ``negstiff.models``, ``negstiff.inference`` and
``negstiff.experiments`` (``shared/docs/contract.md`` is its specification).

Exit codes: 0 success, 2 bad input (one line on stderr, no output written).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import sys
import threading
import warnings
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from negstiff.models import effects

EPILOG_RIG = """examples:
  negstiff rig random -o rec.csv --seed 1            300 s cross-well random record of the as-built device
  negstiff rig random --model m.json -o rec.csv      ... of a polynomial model instead (coefficients known exactly)
  negstiff rig random --effect coulomb_friction=0.05 -o rec.csv   with a hidden extra effect
  negstiff rig harmonic --freq 9 --amplitude 15 -o h.csv          steady-state harmonic response
  negstiff rig campaign --amplitudes 4:30:0.5 --start both --direction both -o campaign/
Every record is written with <name>.truth.json beside it (the truth behind the record)."""


class InputError(Exception):
    """Bad input found by the CLI itself (exit 2)."""


class _Parser(argparse.ArgumentParser):
    """argparse with the contract's error form: one line naming the option, exit 2 (no usage dump)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _number(kind, lo=None, hi=None, lo_open=False, what=""):
    """An argparse type: a number of ``kind`` in [lo, hi] (open at lo with ``lo_open``)."""

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if kind is float and not np.isfinite(v):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if lo is not None and (v < lo or (lo_open and v == lo)):
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {'>' if lo_open else '>='} {lo:g}{what}")
        if hi is not None and v > hi:
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be <= {hi:g}{what}")
        return v

    parse.__name__ = kind.__name__
    return parse


POSITIVE = _number(float, 0.0, lo_open=True)
POSITIVE_INT = _number(int, 1)
SEED = _number(int, 0, 2**32 - 1)


def _bad_input_types() -> tuple[type[BaseException], ...]:
    from negstiff.inference.measurement import MeasurementError
    from negstiff.inference.updating import UpdatingError
    from negstiff.models.rig import RigError

    return (InputError, MeasurementError, RigError, UpdatingError, ValueError, FileNotFoundError, json.JSONDecodeError)


def _progress(args) -> bool:
    return not getattr(args, "quiet", False)


def _parse_effects(items: Sequence[str] | None) -> dict[str, Any]:
    """``NAME=VALUE`` (a stop: ``NAME=k:2e4,z:0.035``) into an extra-effects mapping."""
    out: dict[str, Any] = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(f"--effect {item!r}: expected NAME=VALUE (e.g. coulomb_friction=0.05)")
        name, value = item.split("=", 1)
        try:
            if ":" in value:
                out[name] = {k: float(v) for k, v in (kv.split(":", 1) for kv in value.split(","))}
            else:
                out[name] = float(value)
        except ValueError:
            raise InputError(f"--effect {item!r}: the value is not a number (or k:N/m,z:m for a stop)") from None
    return out


def _parse_amplitudes(text: str) -> list[float]:
    """``4:30:0.5`` (start:stop:step, stop included) or ``5,10,15``."""
    try:
        if ":" in text:
            a, b, s = (float(x) for x in text.split(":"))
            if s <= 0 or b < a:
                raise ValueError
            return list(np.round(np.arange(a, b + s / 2, s), 10))
        return [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"--amplitudes {text!r}: use start:stop:step (e.g. 4:30:0.5) or a list 5,10,15") from None


def load_system(path: str | Path):
    """A model JSON (polynomial, contract fields) or a device JSON (geometry fields E, alpha_deg, ...)."""
    from negstiff.files import read_json
    from negstiff.models import Device, Model

    path = Path(path)
    try:
        d = read_json(path)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    if isinstance(d, dict) and isinstance(d.get("model"), dict):  # an identify result holds a model
        d = d["model"]
    if not isinstance(d, dict):
        raise InputError(f"{path}: a model file is a JSON object")
    try:
        return Device.from_dict(d) if "E" in d else Model.from_dict(d)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: {exc}") from None


def _make_rig(args):
    from negstiff.models.device import AS_BUILT
    from negstiff.models.rig import Rig, Sensors

    system = load_system(args.model) if args.model else AS_BUILT
    sensors = Sensors.noiseless() if args.noise_free else Sensors()
    sensors = dataclasses.replace(sensors, response=args.sensor, response_offset=args.response_offset)
    return Rig(system, effects=_parse_effects(args.effect), sensors=sensors, fs=args.fs, seed=args.seed)


def cmd_rig(args) -> int:
    rig = _make_rig(args)
    out = _out_path(args) if args.mode != "campaign" else Path(args.out)
    if args.mode == "random":
        rec = rig.random(
            duration=args.duration,
            rms=args.rms,
            band=tuple(args.band),
            start="plus" if args.start == "both" else args.start,
        )
        rec.write(out, **_export(args))
        _say(args, f"wrote {out} ({rec.columns['t'].size} samples at {rig.fs:g} Hz) and its truth")
    elif args.mode == "sweep":
        rec = rig.sine_sweep(args.f_start, args.f_stop, args.amplitude, args.duration, args.sweep_mode,
                             start="plus" if args.start == "both" else args.start)  # fmt: skip
        rec.write(out, **_export(args))
        _say(
            args,
            f"wrote {out} (sine sweep {args.f_start:g}-{args.f_stop:g} Hz, {args.amplitude:g} m/s^2) and its truth",
        )
    elif args.mode == "harmonic":
        rec = rig.harmonic(args.freq, args.amplitude, args.start, args.settle_periods, args.periods)
        rec.write(out, **_export(args))
        _say(args, f"wrote {out} ({args.periods} periods at {args.freq:g} Hz, {args.amplitude:g} m/s^2) and its truth")
    else:
        write_campaign(rig, args)
    return 0


def _export(args) -> dict[str, Any]:
    """How the rig's file is written (a lab's export: time decimals, accelerations in g)."""
    return {"time_decimals": args.time_decimals, "acc_unit": args.acc_unit}


def _out_path(args) -> Path:
    """The record's path; ``--format`` sets (or checks) its suffix."""
    out = Path(args.out)
    if args.format and out.suffix.lower().lstrip(".") != args.format:
        if out.suffix and not (args.format == "uff" and out.suffix.lower() == ".unv"):
            raise InputError(f"--format {args.format}: the output {out} has another suffix ({out.suffix})")
        out = out.with_suffix(f".{args.format}")
    return out


def write_campaign(rig, args) -> None:
    """Stepped sweeps up and/or down from either well, one batched run, written as one folder."""
    from negstiff.files import atomic_dir

    amps = _parse_amplitudes(args.amplitudes)
    starts = ["plus", "minus"] if args.start == "both" else [args.start]
    dirs = ["up", "down"] if args.direction == "both" else [args.direction]
    plans = [(s, d) for s in starts for d in dirs]
    lists = [amps if d == "up" else amps[::-1] for _, d in plans]
    _say(args, f"campaign: {len(plans)} sweep(s) x {len(amps)} amplitudes at {args.freq:g} Hz, one batched run")
    sweeps = rig.sweeps(args.freq, lists, [s for s, _ in plans], args.settle_periods, args.periods)
    index = []
    with atomic_dir(args.out) as tmp:
        for (start, direction), recs in zip(plans, sweeps):
            for rec in recs:
                amp = rec.truth["excitation"]["amplitude_m_s2"]
                name = f"{start}_{direction}_{rec.truth['excitation']['step']:03d}_{amp:g}.{args.format or 'csv'}"
                rec.write(tmp / name, **_export(args))
                index.append(
                    {
                        "file": name,
                        "start_well": start,
                        "direction": direction,
                        "amplitude_m_s2": amp,
                        "forcing_hz": args.freq,
                    }
                )
        (tmp / "index.json").write_text(json.dumps({"records": index}, indent=1) + "\n")
    _say(args, f"wrote {len(index)} records to {args.out}/ (index.json lists them)")


def cmd_simulate(args) -> int:
    from negstiff.files import atomic_path
    from negstiff.inference.derivatives import state_derivatives
    from negstiff.inference.measurement import load
    from negstiff.inference.validation import divergence_limits, simulate_record, start_state
    from negstiff.models import simulate
    from negstiff.models.simulator import DEFAULT_V_LIMIT, DEFAULT_Z_LIMIT

    system = load_system(args.model)
    rec = load(args.input, columns=args.columns, fs=args.fs, response=False)
    rec.require(2, "a simulation")
    # the record's own start: the state whose free run matches its first periods (validation.start_state)
    z0, v0 = (None, 0.0)
    if rec.z is not None and (args.z0 is None or args.v0 is None):
        z0, v0 = start_state(system, rec)
    # a record with a response bounds the run by ten times its own stroke and speed (a benchmark in
    # volts exceeds the shaker defaults' 100 m/s); an input-only record by the shaker defaults
    limits = {"z_limit": DEFAULT_Z_LIMIT, "v_limit": DEFAULT_V_LIMIT}
    if rec.z is not None:
        limits = divergence_limits(rec.z, state_derivatives(rec.z, rec.fs, purpose="state")[1])
    if args.z0 is not None:
        z0 = args.z0
    if args.v0 is not None:
        v0 = args.v0
    if z0 is None:
        z0 = system.equilibria().z_plus
    if args.interpolation == "linear":
        res = simulate(system, rec.u, rec.dt, z0=z0, v0=v0, input_kind=rec.input_name, substeps=args.substeps or 2,
                       **limits)  # fmt: skip
    else:
        res = simulate_record(system, rec, (z0, v0), substeps=args.substeps, **limits)
    if res.diverged[0]:
        raise InputError(f"simulation of {args.model} under {args.input} failed: {res.describe_failures()}")
    data = np.column_stack([rec.t, rec.u, res.z[0], res.z_dot[0]])
    with atomic_path(args.out) as tmp:
        np.savetxt(tmp, data, delimiter=",", fmt="%.10g", header=f"t,{rec.input_name},z,z_dot", comments="")
    _say(args, f"wrote {args.out} ({rec.n} samples)")
    return 0


def write_json(path: str | Path, data: dict) -> None:
    """Write a result JSON atomically (NaN and inf become null: JSON has no such numbers)."""
    from negstiff.files import write_text

    write_text(path, json.dumps(_finite(data), indent=2) + "\n")


def _finite(o):
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if np.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return _finite(o.tolist())
    return o


def cmd_identify(args) -> int:
    from negstiff.inference.measurement import load

    rec = load(args.data, columns=args.columns, fs=args.fs, mass=args.mass)
    frfs = read_frf_results(args.frf)
    _say(args, f"identify {args.method}: {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}")
    if args.method == "nsi":
        from negstiff.inference.nsi import NSI

        est = NSI(order=args.order, block_rows=args.block_rows, refine=not args.no_refine).fit(rec)
    else:
        from negstiff.inference.sindy import SINDy

        est = SINDy(n_models=args.ensemble, seed=args.seed, refine=not args.no_refine).fit(rec)
    result = _with_record(est.result(), rec, est.model_)
    if args.frf:
        result["frf_comparison"] = frf_comparison(result, frfs)
        for c in result["frf_comparison"]:
            _say(args, f"{c['well']} well: identified {c['identified_f_hz']:.4f} Hz, FRF {c['frf_f_hz']:.4f} Hz "
                       f"({c['difference_percent']:+.2f} %)")  # fmt: skip
    _say_refinement(args, result.get("refinement"))
    v = result["validation"]
    if v.get("diverged"):
        _say(args, f"WARNING: {v['warning']}")
    _warn(args, result["warnings"])
    if args.method == "sindy":
        _say(args, f"selected terms: {', '.join(result['selected_terms'])}")
    write_json(args.out, result)
    wells = ", ".join(
        f"{w}: {m['f_hz']:.3f} Hz, zeta {100 * m['zeta']:.1f} %"
        for w, m in result["modal"].items()
        if m["f_hz"] is not None
    )
    _say(args, f"wrote {args.out} ({wells}; validation {v['rms_percent']:.2f} % rms)")
    return 0


def _say_refinement(args, info: dict | None) -> None:
    """One line on the output-error refinement: held-out free-run error before and after, kept or not."""
    if not info:
        return
    h = info.get("heldout")
    if h is None:
        _say(args, f"refinement: {info['reason']}")
        return
    a, b = h["initial"].get("restarted_rms_percent"), h["refined"].get("restarted_rms_percent")
    fmt = lambda x: "diverged" if x is None or not np.isfinite(x) else f"{x:.3g} %"  # noqa: E731
    _say(args, f"refinement by simulation error ({info['seconds']:.1f} s): held-out restarted free runs "
               f"{fmt(a)} -> {fmt(b)} rms, {info['reason'].split(':')[0]}")  # fmt: skip


def cmd_posterior(args) -> int:
    from negstiff.inference.measurement import load
    from negstiff.inference.posterior import Posterior
    from negstiff.models import Model

    start = None
    if args.start is not None:
        start = load_system(args.start)
        if args.model != "coefficients" or not isinstance(start, Model):
            raise InputError(
                f"--start {args.start}: a polynomial model, for the coefficient posterior (--model coefficients)"
            )
    rec = load(args.data, columns=args.columns, fs=args.fs, mass=args.mass)
    if args.duration is not None:
        rec = rec.segment(0, min(rec.n, int(round(args.duration * rec.fs))))
    _say(args, f"posterior ({args.model}): {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}")
    post = Posterior(
        model=args.model,
        mass_prior=args.mass_prior,
        window_s=args.window,
        max_windows=args.max_windows,
        n_walkers=args.walkers,
        n_ensembles=args.ensembles,
        max_steps=args.max_steps,
        hdi_prob=args.hdi_prob,
        adjust=not args.no_adjust,
        seed=args.seed,
        progress=_progress(args),
        start=start,
        refine_start=not args.no_refine,
    )
    res = post.fit(rec).result_
    result = _with_record(post.result(), rec)
    if args.idata:
        from negstiff.files import atomic_path

        with atomic_path(args.idata) as tmp:
            res.idata.to_netcdf(tmp, engine="h5netcdf")
    write_json(args.out, result)
    _warn(args, result["warnings"])
    line = ", ".join(f"{n} {s['mean']:.4g} +- {s['sd']:.2g}" for n, s in result["parameters"].items())
    _say(args, f"wrote {args.out}: {line}")
    return 0


def cmd_discrepancy(args) -> int:
    from negstiff.inference.discrepancy import CUBIC_BASELINE, LINEAR_BASELINE, Discrepancy
    from negstiff.inference.measurement import load

    rec = load(args.data, columns=args.columns, fs=args.fs, mass=args.mass)
    _say(args, f"discrepancy: {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}, baseline {args.baseline}")
    base = CUBIC_BASELINE if args.baseline == "cubic" else LINEAR_BASELINE
    d = Discrepancy(baseline=base, max_effects=args.max_effects, refine=not args.no_refine, unnamed=args.unnamed)
    d.fit(rec)
    result = _with_record(d.result(), rec, d.model_)
    _say_refinement(args, result.get("refinement"))
    write_json(args.out, result)
    _warn(args, result["warnings"])
    _say(args, f"where: {result['where']}")
    un = result.get("unnamed")
    if un:
        g = un["gap"]
        _say(args, f"unnamed: a non-parametric term of {un['term_percent_of_restoring_force']:.3g} % of the "
                   f"restoring force; held-out gap {g.get('physics_median_window_percent', float('nan')):.3g} % -> "
                   f"{g.get('hybrid_median_window_percent', float('nan')):.3g} % with it")  # fmt: skip
    _say(
        args,
        f"wrote {args.out}: named {', '.join(result['effects'])}; held-out gap (restarted free runs) "
        f"{result['gap_before_percent']:.3g} % -> {result['gap_after_percent']:.3g} %",
    )
    return 0


def cmd_characterize(args) -> int:
    from negstiff.inference.characterize import characterize
    from negstiff.inference.measurement import load
    from negstiff.inference.nsi import well_guesses

    rec = load(args.data, columns=args.columns, fs=args.fs)
    if args.signal != "z":
        col = getattr(rec, args.signal, None)
        if col is None:
            raise InputError(f"{args.data}: no column {args.signal!r} to analyse (choose z, y, z_dot or base_disp)")
        rec = dataclasses.replace(rec, z=col)
    if args.wells:
        try:
            wells = tuple(float(x) for x in args.wells.split(","))
            if len(wells) not in (2, 3) or not all(np.isfinite(wells)) or list(wells) != sorted(wells):
                raise ValueError
        except ValueError:
            raise InputError(f"--wells {args.wells!r}: give z_minus,z_plus or z_minus,z_0,z_plus in m") from None
    elif "z_minus_rest" in rec.meta and "z_plus_rest" in rec.meta:
        wells = (float(rec.meta["z_minus_rest"]), float(rec.meta["z_plus_rest"]))
    else:
        try:
            wells = well_guesses(rec)
        except ValueError:
            wells = None
    if not args.forcing_hz < rec.fs / 2:
        raise InputError(
            f"--forcing-hz {args.forcing_hz:g}: above the Nyquist frequency of {args.data} ({rec.fs / 2:g} Hz)"
        )
    _say(args, f"characterize: {rec.n} samples at {rec.fs:g} Hz, forcing {args.forcing_hz:g} Hz")
    r = characterize(rec, args.forcing_hz, wells)
    r.pop("poincare_z")
    r["wells_used"] = wells
    r = _with_record(r, rec)
    write_json(args.out, r)
    _warn(args, r["warnings"])
    lle = r["lle"]
    lle_txt = "not determinable" if lle["value"] is None else f"{lle['value']:.2f} +- {lle['sd']:.2g} 1/s (Wolf)"
    _say(
        args,
        f"wrote {args.out}: period {r['period']}, {r['regime']}, LLE {lle_txt}, "
        f"{'chaotic' if r['chaotic'] else 'not chaotic'}",
    )
    for what, why in r["reasons"].items():
        _say(args, f"{what}: {why}")
    return 0


def _band(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(x) for x in text.split(":"))
        if not (0 <= lo < hi and np.isfinite(hi)):
            raise ValueError
    except ValueError:
        raise InputError(f"--band {text!r}: give F1:F2 in Hz with 0 <= F1 < F2 (e.g. 2:40)") from None
    return lo, hi


def _frf_well(rec) -> str | None:
    """The well a low-level record sits in: the rest position (metadata) nearest its mean z."""
    rest = {}
    for w in ("minus", "plus"):
        try:
            rest[w] = float(rec.meta[f"z_{w}_rest"])
        except (KeyError, ValueError):
            pass
    if not rest or rec.z is None:
        return None
    return min(rest, key=lambda w: abs(rest[w] - float(np.mean(rec.z))))


def cmd_frf(args) -> int:
    from negstiff.files import atomic_path
    from negstiff.inference.frf import frf
    from negstiff.inference.measurement import load

    band = _band(args.band)
    rec = load(args.data, columns=args.columns, fs=args.fs)
    if band is not None and band[1] > rec.fs / 2:
        raise InputError(f"--band {args.band}: beyond the Nyquist frequency of {args.data} ({rec.fs / 2:g} Hz)")
    _say(args, f"frf: {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}")
    res = frf(rec, band=band, segment_s=args.segment)
    curves = res.pop("_curves")
    res["well"] = _frf_well(rec)
    res = _with_record(res, rec)
    if res["reason"]:
        res["warnings"].append(res["reason"])
    figure = Path(args.out).with_suffix(".png")
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
    a1.set(ylabel=f"|z / {rec.input_name}|", title=f"FRF of {Path(args.data).name}")
    a1.legend()
    a2.plot(f[sel], curves["coherence"][sel])
    a2.set(xlabel="frequency [Hz]", ylabel="coherence", ylim=(0, 1.05))
    fig.tight_layout()
    res["figure"] = figure.name
    with atomic_path(figure) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    write_json(args.out, res)
    _warn(args, res["warnings"])
    top = "no peak" if res["f_hz"] is None else f"{res['f_hz']:.4f} Hz, zeta {100 * res['zeta']:.2f} %"
    _say(args, f"wrote {args.out} and {figure.name}: dominant peak {top}; {len(res['peaks'])} peak(s)")
    return 0


def read_frf_results(paths: Sequence[str] | None) -> list[tuple[str, float, str | None]]:
    """(path, peak frequency [Hz], well) of each ``--frf`` result, checked before any work."""
    from negstiff.files import read_json

    out = []
    for p in paths or []:
        try:
            r = read_json(p)
            f_frf, well = r["f_hz"], r.get("well")
        except (ValueError, KeyError, TypeError, AttributeError):
            raise InputError(f"--frf {p}: not an frf result (needs f_hz)") from None
        if not isinstance(f_frf, (int, float)) or isinstance(f_frf, bool):
            raise InputError(f"--frf {p}: the FRF found no peak to compare with (f_hz is {f_frf!r})")
        out.append((p, float(f_frf), well))
    return out


def frf_comparison(result: dict, frfs: list[tuple[str, float, str | None]]) -> list[dict]:
    """Each well's identified underlying-linear frequency beside a low-level FRF's (``--frf``)."""
    out = []
    for p, f_frf, well in frfs:
        modal = {w: m["f_hz"] for w, m in result["modal"].items() if m.get("f_hz")}
        if well not in modal:  # no rest positions in the FRF's record: the nearest well frequency
            well = min(modal, key=lambda w: abs(modal[w] - f_frf)) if modal else None
        f_id = modal.get(well)
        out.append(
            {
                "frf": str(p),
                "well": well,
                "frf_f_hz": f_frf,
                "identified_f_hz": f_id,
                "difference_percent": None if f_id is None else 100 * (f_id / f_frf - 1),
            }
        )
    return out


def cmd_update(args) -> int:
    from tqdm import tqdm

    from negstiff.inference.updating import GAUpdater, load_targets

    targets = load_targets(args.targets)
    bar = tqdm(total=args.generations, desc="GA", unit="gen", disable=not _progress(args), file=sys.stderr)

    def progress(gen: int, best: float) -> None:
        bar.update(1)
        bar.set_postfix(best=f"{best:.3f} %")

    ga = GAUpdater(pop_size=args.pop_size, generations=args.generations, fixed_mass=args.fix_mass, seed=args.seed)
    ga.fit(targets, progress=progress)
    bar.close()
    write_json(args.out, ga.result())
    d = ga.device_
    _say(
        args,
        f"wrote {args.out}: E = {d.E / 1e9:.2f} GPa, alpha = {d.alpha_deg:.2f} deg, m = {d.m * 1e3:.1f} g, "
        f"fitness {ga.fitness_:.3f} % (seed Eq. 9)"
        + (f", restoring-force mismatch {ga.objective_:.3f} % (minimised)" if ga.stroke_ is not None else ""),
    )
    return 0


def cmd_reproduce(args) -> int:
    from negstiff.experiments.reproduce import reproduce

    reproduce(Path(args.out), fast=args.fast, seed=args.seed, progress=_progress(args))
    return 0


def _say(args, text: str) -> None:
    if _progress(args):
        print(text, file=sys.stderr)


def _warn(args, warnings: Sequence[str]) -> None:
    """Warnings are loud: on stderr even with --quiet (and in the result)."""
    for w in warnings:
        print(f"negstiff {args.command}: WARNING: {w}", file=sys.stderr)


def _with_record(result: dict, rec, model=None) -> dict:
    """A result with how its record was read (time base, response sensor, derived z) and every
    warning about the record and the model (``inference.plausibility``)."""
    from negstiff.inference.plausibility import collect

    return {**result, "record": rec.info, "warnings": collect(rec, result, model)}


INPUT_ARGS = ("data", "model", "input", "targets", "frf", "start")
OUTPUT_ARGS = ("out", "idata")


def check_paths(args) -> None:
    """Before any work: no output may be an input, and every output's folder must be writable."""
    import os
    import tempfile

    inputs = {}
    for name in INPUT_ARGS:
        v = getattr(args, name, None)
        for item in v if isinstance(v, list) else [v] if v else []:
            inputs[Path(item).resolve()] = item
    for name in OUTPUT_ARGS:
        v = getattr(args, name, None)
        if not v:
            continue
        out = Path(v).resolve()
        targets = [out]
        if args.command == "rig" and out.suffix:
            targets.append(out.with_name(out.stem + ".truth.json"))
        if args.command == "frf":
            targets.append(out.with_suffix(".png"))
        for t in targets:
            if t in inputs:
                raise InputError(
                    f"--{name.replace('_', '-')} {v}: would overwrite the input {inputs[t]}; choose another path"
                )
        folder_out = args.command == "reproduce" or (args.command == "rig" and args.mode == "campaign")
        if out.is_dir() and not folder_out:
            raise InputError(f"--{name} {v}: is a folder; give a file path")
        parent = out if folder_out else out.parent
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        try:  # the one sure test of a folder's writability: write in it
            if not parent.is_dir():
                raise OSError
            fd, probe = tempfile.mkstemp(prefix=".negstiff-probe.", dir=parent)
            os.close(fd)
            os.unlink(probe)
        except OSError:
            raise InputError(f"--{name} {v}: cannot write there ({parent} is not a writable folder)") from None


def build_parser() -> argparse.ArgumentParser:
    common = _Parser(add_help=False)
    common.add_argument("--seed", type=SEED, default=0, help="seed of every random draw (same seed, same numbers)")
    common.add_argument("--quiet", action="store_true", help="no progress on stderr")

    p = _Parser(
        prog="negstiff",
        description="Identify, update and quantify the uncertainty of nonlinear (bistable, negative-stiffness) "
        "oscillators from shaker-table records. Units are SI; see 'negstiff COMMAND --help'.",
    )
    from negstiff import __version__

    p.add_argument("--version", action="version", version=f"negstiff {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    rig = sub.add_parser(
        "rig",
        parents=[common],
        help="virtual test rig: records as the seed's laboratory measures them",
        description="Virtual shaking table with the as-built device (exact geometry) or a model on it. "
        "Records: t, base_acc (accelerometer), y (laser), base_disp (double-integrated), "
        "z = y - base_disp.",
        epilog=EPILOG_RIG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    rig.add_argument("mode", choices=["random", "harmonic", "sweep", "campaign"])
    rig.add_argument(
        "-o", "--out", required=True, help="record file (.csv, .npz, .uff/.unv, .tdms); for campaign, a folder"
    )
    rig.add_argument(
        "--model", help="drive a model JSON (polynomial truth) or device JSON instead of the as-built device"
    )
    rig.add_argument(
        "--effect",
        action="append",
        metavar="NAME=VALUE",
        help=f"hidden extra effect ({', '.join(e.help() for e in effects.REGISTRY)}); repeatable",
    )
    rig.add_argument("--fs", type=_number(float, 1.0, 1e6), default=512.0, help="sampling rate [Hz] (default 512)")
    rig.add_argument("--noise-free", action="store_true", help="perfect sensors (no noise, no bias)")
    g = rig.add_argument_group("lab variants (records as other labs write them)")
    g.add_argument(
        "--sensor",
        default="displacement",
        choices=["displacement", "velocity", "absolute", "accelerometer"],
        help="response sensor: displacement (the seed's laser and double-integrated base: y, base_disp, z), "
        "velocity (a vibrometer relative to the base: z_dot), absolute (the laser's y only), accelerometer "
        "(on the moving part: y_acc)",
    )
    g.add_argument(
        "--response-offset",
        type=_number(float),
        default=0.0,
        help="DC offset of the response sensor in its units (m, m/s or m/s^2; default 0)",
    )
    g.add_argument(
        "--time-decimals", type=_number(int, 0, 12), help="print the time column with N fixed decimals (CSV)"
    )
    g.add_argument(
        "--format",
        choices=["csv", "npz", "uff", "tdms"],
        help="file format (default: from the --out suffix; campaign records: csv); uff: Universal File type 58, "
        "tdms: LabVIEW TDMS",
    )
    g.add_argument(
        "--acc-unit",
        default="m/s^2",
        choices=["m/s^2", "g"],
        help="write accelerations in g, as base_acc_g / y_acc_g (read back with --columns base_acc=base_acc_g*9.81)",
    )
    g = rig.add_argument_group("random")
    g.add_argument("--duration", type=_number(float, 1.0, 1e5), default=300.0, help="record length [s] (default 300)")
    g.add_argument("--rms", type=POSITIVE, default=14.0, help="table acceleration rms [m/s^2] (default 14: cross-well)")
    g.add_argument(
        "--band",
        type=POSITIVE,
        nargs=2,
        default=[2.0, 40.0],
        metavar=("LO", "HI"),
        help="excitation band [Hz] (default 2 40)",
    )
    g = rig.add_argument_group("sweep (a swept sine by pyExSi: --amplitude, --duration, --start too)")
    g.add_argument("--f-start", type=POSITIVE, default=2.0, help="start frequency [Hz] (default 2)")
    g.add_argument("--f-stop", type=POSITIVE, default=40.0, help="stop frequency [Hz] (default 40)")
    g.add_argument("--sweep-mode", choices=["linear", "logarithmic"], default="linear", help="sweep law")
    g = rig.add_argument_group("harmonic and campaign")
    g.add_argument("--freq", type=POSITIVE, default=9.0, help="forcing frequency [Hz] (default 9)")
    g.add_argument(
        "--amplitude", type=_number(float, 0.0), default=5.0, help="table acceleration amplitude [m/s^2] (harmonic)"
    )
    g.add_argument(
        "--amplitudes", default="4:30:0.5", help="campaign amplitudes start:stop:step or a list (default 4:30:0.5)"
    )
    g.add_argument("--start", default="plus", choices=["plus", "minus", "both"], help="starting well (default plus)")
    g.add_argument("--direction", default="up", choices=["up", "down", "both"], help="campaign sweep direction")
    g.add_argument(
        "--settle-periods",
        type=_number(int, 0, 10**6),
        default=100,
        help="forcing periods discarded per step (default 100)",
    )
    g.add_argument(
        "--periods", type=_number(int, 1, 10**6), default=100, help="forcing periods recorded per step (default 100)"
    )
    rig.set_defaults(func=cmd_rig)

    # options of every command that reads a measurement file
    data_opts = _Parser(add_help=False)
    data_opts.add_argument(
        "--columns", help="column map for foreign files, e.g. force=V1,z=V2 (a map entry may scale: X*9.81)"
    )
    data_opts.add_argument(
        "--fs",
        type=POSITIVE,
        help="sampling rate [Hz]; replaces the file's time column (for files without t, or a broken one)",
    )

    sim = sub.add_parser(
        "simulate",
        parents=[common, data_opts],
        help="integrate a model under a record's input",
        description="Integrate MODEL.json (contract model file, or a device JSON) under INPUT's input "
        "column. Initial state: from INPUT's first z samples if present, else rest at z_plus.",
    )
    sim.add_argument("model", help="model JSON")
    sim.add_argument("input", help="measurement file whose input column drives the model")
    sim.add_argument("-o", "--out", required=True, help="output CSV: t,<input>,z,z_dot")
    sim.add_argument("--z0", type=_number(float), help="initial z [m]")
    sim.add_argument("--v0", type=_number(float), help="initial z_dot [m/s]")
    sim.add_argument(
        "--substeps",
        type=_number(int, 1, 64),
        help="RK4 steps per sample interval (default: 2, more where the model is fast for the sampling rate)",
    )
    sim.add_argument(
        "--interpolation",
        choices=("band-limited", "linear"),
        default="band-limited",
        help="the input between samples: band-limited (a record through an anti-aliasing filter; default) "
        "or linear (a piecewise-linear drive)",
    )
    sim.set_defaults(func=cmd_simulate)

    idf = sub.add_parser(
        "identify",
        parents=[common, data_opts],
        help="identify K and D (and modal parameters) from a record",
        description="nsi: nonlinear subspace identification around both stable wells (seed section 4): modal "
        "parameters of each underlying-linear system, the z-frame cubic restoring force and damping. sindy: weak-form "
        "sparse regression over 1, z..z^5, z', z'|z'|, z'^3, sgn(z') with the input's coefficient fixed by physics, "
        "terms selected by held-out residual, ensemble inclusion probabilities. Both: equilibria, modal parameters "
        "and a free-run validation over the held-out last 20 %%.",
    )
    idf.add_argument("method", choices=["nsi", "sindy"], help="identification method")
    idf.add_argument(
        "--no-refine",
        action="store_true",
        help="skip the output-error refinement (the last stage: the model's simulation error minimised over the "
        "identification part; kept only if it predicts the held-out part at least as well)",
    )
    idf.add_argument("data", help="measurement file")
    idf.add_argument("-o", "--out", required=True, help="result JSON")
    idf.add_argument(
        "--mass", type=POSITIVE, help="moving mass [kg] (default: the file's metadata; else per unit mass)"
    )
    idf.add_argument(
        "--order",
        type=_number(int, 2, 20, what=" (the state dimension: 2 per mode)"),
        default=2,
        help="NSI model order (default 2: one mode)",
    )
    idf.add_argument(
        "--block-rows",
        type=_number(int, 2, 500),
        default=30,
        help="NSI: block rows of the Hankel matrices (default 30)",
    )
    idf.add_argument(
        "--ensemble", type=_number(int, 2, 10000), default=50, help="SINDy: bagged models of the ensemble (default 50)"
    )
    idf.add_argument(
        "--frf",
        action="append",
        metavar="R.json",
        help="an frf result of a low-level test around a well: its peak beside the identified well frequency "
        "(repeatable, one per well)",
    )
    idf.set_defaults(func=cmd_identify)

    frq = sub.add_parser(
        "frf",
        parents=[common, data_opts],
        help="H1/H2 frequency response with coherence, modal fit of the peaks",
        description="Frequency response of a (low-level) record from its input to z: H1 and H2 with the coherence "
        "(Welch, Hann, 50 %% overlap), every resonance peak fitted by a single-degree-of-freedom receptance "
        "(frequency, damping ratio). Around one well at low level, the peak is that well's underlying-linear "
        "frequency: compare it with 'identify ... --frf R.json'. Writes R.json and R.png.",
    )
    frq.add_argument("data", help="measurement file")
    frq.add_argument("-o", "--out", required=True, help="result JSON (the figure beside it, .png)")
    frq.add_argument(
        "--band", help="frequency band F1:F2 [Hz] (default: where the input's spectrum is within 20 dB of its peak)"
    )
    frq.add_argument(
        "--segment",
        type=_number(float, 0.5, 1e4),
        help="Welch segment [s] (default 16 s, longer where a lightly damped peak needs finer bins)",
    )
    frq.set_defaults(func=cmd_frf)

    pst = sub.add_parser(
        "posterior",
        parents=[common, data_opts],
        help="Bayesian posterior (emcee) of the coefficients or the device parameters",
        description="emcee posterior with a multiple-shooting output-error likelihood (short windows simulated "
        "from measured states, start states profiled out, sensor noise sigma sampled). coefficients: k1, k2, k3, c, "
        "c_nl, sigma (mass fixed: --mass, the file's metadata, or per unit mass). device: E, alpha, m, c, c_nl, "
        "sigma with the exact geometric restoring force; --mass-prior weighed (N(m, 2 %%)) or free (shows the E-m "
        "ridge). R-hat across independent ensembles, bulk/tail ESS, autocorrelation times; a run that does not "
        "converge is reported with a warning in the result.",
    )
    pst.add_argument("data", help="measurement file")
    pst.add_argument("-o", "--out", required=True, help="result JSON")
    pst.add_argument("--mass", type=POSITIVE, help="moving mass [kg] (default: the file's metadata)")
    pst.add_argument("--model", choices=["coefficients", "device"], default="coefficients")
    pst.add_argument("--mass-prior", choices=["weighed", "free"], default="weighed", help="device model: mass prior")
    pst.add_argument("--idata", help="save the arviz data (posterior, sample stats, log likelihood) as NetCDF")
    pst.add_argument(
        "--start",
        help="coefficients: an identify result (its refined model) or a model file the MAP search starts from "
        "(default: weak-form least squares of the record, refined by simulation error)",
    )
    pst.add_argument(
        "--no-refine",
        action="store_true",
        help="coefficients without --start: start the MAP search from the weak-form estimate itself, not its "
        "output-error refinement",
    )
    pst.add_argument("--duration", type=POSITIVE, help="use only the first DURATION seconds of the record")
    pst.add_argument("--window", type=POSITIVE, default=0.125, help="multiple-shooting window [s] (default 0.125)")
    pst.add_argument(
        "--max-windows",
        type=_number(int, 4, 10**6),
        default=240,
        help="windows used at most, spread over the record (default 240)",
    )
    pst.add_argument(
        "--walkers",
        type=_number(int, 16, 10**5, what=" (emcee: twice the 7 dimensions of the device model, at least)"),
        default=32,
        help="walkers per ensemble (default 32)",
    )
    pst.add_argument("--ensembles", type=_number(int, 1, 1000), default=4, help="independent ensembles (default 4)")
    pst.add_argument(
        "--max-steps", type=_number(int, 1, 10**7), default=6000, help="step cap per ensemble (default 6000)"
    )
    pst.add_argument(
        "--hdi-prob",
        type=_number(float, 0.0, 0.999, lo_open=True),
        default=0.9,
        help="credible-interval probability (default 0.9)",
    )
    pst.add_argument(
        "--no-adjust",
        action="store_true",
        help="no curvature adjustment: the i.i.d. Gaussian likelihood as it stands (narrower, overconfident "
        "intervals when the input is measured with noise)",
    )
    pst.set_defaults(func=cmd_posterior)

    dsc = sub.add_parser(
        "discrepancy",
        parents=[common, data_opts],
        help="find where model and data disagree, name the missing effect, add it, refit",
        description="Fits the baseline (cubic K, viscous c; or linear K), locates its equation error over the state "
        f"and the regimes, scores a catalogue of effects ({', '.join(effects.names())}, none) by held-out "
        "weak residual, adds the winner, refits everything, repeats until none wins, and measures the held-out gap "
        "(restarted free runs) before and after.",
    )
    dsc.add_argument("data", help="measurement file")
    dsc.add_argument("-o", "--out", required=True, help="result JSON")
    dsc.add_argument("--mass", type=POSITIVE, help="moving mass [kg] (default: the file's metadata)")
    dsc.add_argument("--baseline", choices=["cubic", "linear"], default="cubic", help="starting model")
    dsc.add_argument("--max-effects", type=_number(int, 0, 20), default=3, help="effects added at most (default 3)")
    dsc.add_argument(
        "--no-refine",
        action="store_true",
        help="skip the output-error refinement (the last stage: the model's simulation error minimised over the "
        "identification part; kept only if it predicts the held-out part at least as well)",
    )
    dsc.add_argument(
        "--unnamed",
        action="store_true",
        help="also fit a non-parametric force g(z, z', u) to what no catalogue effect names (output error, the "
        "final model held) and report its size, the held-out gap with it, and how far it would move the physical "
        "coefficients (result key 'unnamed')",
    )
    dsc.set_defaults(func=cmd_discrepancy)

    chz = sub.add_parser(
        "characterize",
        parents=[common, data_opts],
        help="periodicity, regime, Lyapunov exponent of a harmonic-forced record",
        description="Periodicity analysis of a steady-state record forced at --forcing-hz (phase-synchronous Poincare "
        "samples from the measured input's phase), the regime (in-well around either well, or cross-well), the "
        "amplitude of each branch and the largest Lyapunov exponent (Wolf 1985, embedding from the data; "
        "Rosenstein beside it).",
    )
    chz.add_argument("data", help="measurement file")
    chz.add_argument("--forcing-hz", type=POSITIVE, required=True, help="forcing frequency [Hz]")
    chz.add_argument("--signal", default="z", choices=["z", "y", "z_dot", "base_disp"], help="column to analyse")
    chz.add_argument(
        "--wells",
        help="z_minus,z_plus (or z_minus,z_0,z_plus) [m]; default: the file's rest positions, "
        "else estimated from the data",
    )
    chz.add_argument("-o", "--out", required=True, help="result JSON")
    chz.set_defaults(func=cmd_characterize)

    upd = sub.add_parser(
        "update",
        parents=[common],
        help="GA model updating of the device's E, frame angle and mass",
        description="Update the physical device (E, alpha, m, from the nominal design) with a genetic algorithm so "
        "that its well frequencies and equilibria match TARGETS (seed section 4.1, Eq. 9). TARGETS is an "
        "'identify' result or a JSON with f_minus, f_plus [Hz], z_minus, z_plus [m]. The features depend on E "
        "and m only through E/m: with the mass free the result is one point of a ridge; --fix-mass pins E.",
    )
    upd.add_argument("targets", help="identify result JSON or targets JSON")
    upd.add_argument("-o", "--out", required=True, help="result JSON")
    upd.add_argument("--fix-mass", type=POSITIVE, help="weighed moving mass [kg]: update E and alpha only")
    upd.add_argument("--generations", type=_number(int, 1, 10**5), default=120, help="GA generations (default 120)")
    upd.add_argument("--pop-size", type=_number(int, 4, 10**5), default=60, help="GA population (default 60)")
    upd.set_defaults(func=cmd_update)

    rep = sub.add_parser(
        "reproduce",
        parents=[common],
        help="the whole study, end to end, as one report",
        description="Run the seed paper's study on the virtual rig and write index.md, index.html and results.json.",
    )
    rep.add_argument("-o", "--out", default="reports/paper", help="report folder (default reports/paper)")
    rep.add_argument("--fast", action="store_true", help="a quick reduced run (minutes)")
    rep.set_defaults(func=cmd_reproduce)
    return p


def _interrupt_handler(command: str):
    """Ctrl-C: one line, the outputs being written removed, exit 130 at once. (Raising
    KeyboardInterrupt is not enough: emcee prints the traceback of any exception inside a
    log-probability call before passing it on.)"""

    def handler(signum, frame):
        from negstiff.files import remove_pending

        remove_pending()
        sys.stderr.write(f"negstiff {command}: interrupted (nothing written)\n")
        sys.stderr.flush()
        os._exit(130)

    return handler


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except KeyboardInterrupt:
        print("negstiff: interrupted", file=sys.stderr)
        return 130
    if threading.current_thread() is threading.main_thread() and argv is None:  # the installed command
        signal.signal(signal.SIGINT, _interrupt_handler(args.command))
    try:
        check_paths(args)
        with warnings.catch_warnings():
            # the libraries' notices (arviz's dimension names, numpy's empty slices) are not the user's
            # business; negstiff's own warnings are in the result and on stderr (``_warn``)
            warnings.simplefilter("ignore")
            return args.func(args)
    except _bad_input_types() as exc:
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"negstiff {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"negstiff {args.command}: interrupted (nothing written)", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 141


if __name__ == "__main__":
    sys.exit(main())
