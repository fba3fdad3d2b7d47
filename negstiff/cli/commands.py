"""The commands: each reads its inputs, calls ``negstiff.models``, ``negstiff.inference`` or
``negstiff.report`` and ``negstiff.experiments``, and writes its output atomically (``docs/contract.md``).
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from .common import (
    InputError,
    export_options,
    out_path,
    parse_amplitudes,
    parse_band,
    parse_effects,
    parse_span,
    say,
    say_refinement,
    wants_progress,
    warn,
    write_json,
)


def make_rig(args):
    from negstiff.models.device import AS_BUILT, load_system
    from negstiff.models.records import RigError
    from negstiff.models.rig import Rig, Sensors

    system = load_system(args.model) if args.model else AS_BUILT
    sensors = Sensors.noiseless() if args.noise_free else Sensors()
    sensors = dataclasses.replace(sensors, response=args.sensor, response_offset=args.response_offset)
    try:
        return Rig(system, effects=parse_effects(args.effect), sensors=sensors, fs=args.fs, seed=args.seed)
    except RigError:
        raise
    except ValueError as exc:  # an unknown effect or a bad value: the user's --effect
        raise InputError(f"--effect: {exc}") from None


def cmd_rig(args) -> int:
    from negstiff.models.records import check_written

    rig = make_rig(args)
    if args.mode == "campaign":
        write_campaign(rig, args)
        return 0
    out = out_path(args)
    start = "plus" if args.start == "both" else args.start
    duration = args.duration if args.duration is not None else (10.0 if args.mode in ("hammer", "release") else 300.0)
    # each mode: (its check before any work, the run, its settings, the progress line, what the record holds)
    plans = {
        "hammer": (rig.check_hammer, rig.hammer,
                   {"peak": args.peak, "hits": args.hits, "duration": duration, "width": args.width, "start": start,
                    "dof": args.dof},
                   f"{args.hits} hit(s) of {args.peak:g} N over {duration:g} s",
                   lambda rec: f"{args.hits} hit(s) of {args.peak:g} N, {duration:g} s"),
        "release": (lambda **kw: _check_release(rig, **kw), rig.release, {"z0": args.z0, "duration": duration},
                    f"from z = {1e3 * (args.z0 or 0.0):g} mm over {duration:g} s",
                    lambda rec: f"a free decay from {1e3 * args.z0:g} mm, {duration:g} s"),
        "random": (rig.check_random, rig.random,
                   {"duration": duration, "rms": args.rms, "band": tuple(args.band), "start": start},
                   f"{duration:g} s at {rig.fs:g} Hz, {args.rms:g} m/s^2 rms",
                   lambda rec: f"{rec.columns['t'].size} samples at {rig.fs:g} Hz"),
        "sweep": (rig.check_sine_sweep, rig.sine_sweep,
                  {"f_start": args.f_start, "f_stop": args.f_stop, "amplitude": args.amplitude, "duration": duration,
                   "mode": args.sweep_mode, "start": start},
                  f"{args.f_start:g}-{args.f_stop:g} Hz over {duration:g} s",
                  lambda rec: f"sine sweep {args.f_start:g}-{args.f_stop:g} Hz, {args.amplitude:g} m/s^2"),
        "harmonic": (lambda **kw: rig.check_sweeps(kw["freq"], [[kw["amplitude"]]], [kw["start"]],
                                                   kw["settle_periods"], kw["record_periods"]), rig.harmonic,
                     {"freq": args.freq, "amplitude": args.amplitude, "start": args.start,
                      "settle_periods": args.settle_periods, "record_periods": args.periods},
                     f"{args.freq:g} Hz, {args.amplitude:g} m/s^2",
                     lambda rec: f"{args.periods} periods at {args.freq:g} Hz, {args.amplitude:g} m/s^2"),
    }  # fmt: skip
    check, run, kw, said, what_of = plans[args.mode]
    check(**kw)
    check_written(out)  # the suffix, before the simulation
    say(args, f"rig {args.mode}: {said}")
    rec = run(**kw)
    what = what_of(rec)
    rec.write(out, **export_options(args))
    say(args, f"wrote {out} ({what}) and its truth")
    return 0


def _check_release(rig, z0: float | None, duration: float) -> None:
    """Everything ``rig release`` refuses, before any work: no position to let go from (``--z0``), and the rig's."""
    if z0 is None:
        raise InputError("rig release: give --z0, where the moving part is held before it is let go [m]")
    rig.check_release(z0, duration)


def write_campaign(rig, args) -> None:
    """Stepped sweeps up and/or down from either well, one batched run, written as one folder."""
    from negstiff.files import atomic_dir

    in_freq = args.freqs is not None  # a stepped sine in frequency at --amplitude, else in amplitude at --freq
    values = parse_amplitudes(args.freqs, "--freqs") if in_freq else parse_amplitudes(args.amplitudes)
    starts = ["plus", "minus"] if args.start == "both" else [args.start]
    dirs = ["up", "down"] if args.direction == "both" else [args.direction]
    plans = [(s, d) for s in starts for d in dirs]
    lists = [values if d == "up" else values[::-1] for _, d in plans]
    what = f"frequencies at {args.amplitude:g} m/s^2" if in_freq else f"amplitudes at {args.freq:g} Hz"
    wells = [s for s, _ in plans]
    if in_freq:
        rig.check_stepped_sines(lists, args.amplitude, wells, args.settle_periods, args.periods)
    else:
        rig.check_sweeps(args.freq, lists, wells, args.settle_periods, args.periods)
    say(args, f"campaign: {len(plans)} sweep(s) x {len(values)} {what}, one batched run")
    if in_freq:
        sweeps = rig.stepped_sines(lists, args.amplitude, wells, args.settle_periods, args.periods)
    else:
        sweeps = rig.sweeps(args.freq, lists, wells, args.settle_periods, args.periods)
    index = []
    with atomic_dir(args.out) as tmp:
        for (start, direction), recs in zip(plans, sweeps, strict=False):
            for rec in recs:
                exc = rec.truth["excitation"]
                amp, f = exc["amplitude_m_s2"], exc.get("freq_hz", args.freq)
                value = f"{f:g}Hz" if in_freq else f"{amp:g}"
                name = f"{start}_{direction}_{exc['step']:03d}_{value}.{args.format or 'csv'}"
                rec.write(tmp / name, **export_options(args))
                index.append(
                    {"file": name, "start_well": start, "direction": direction, "amplitude_m_s2": amp, "forcing_hz": f}
                )
        (tmp / "index.json").write_text(json.dumps({"records": index}, indent=1) + "\n")
    say(args, f"wrote {len(index)} records to {args.out}/ (index.json lists them)")


def cmd_simulate(args) -> int:
    from negstiff.files import atomic_path
    from negstiff.inference.record.reading import load
    from negstiff.inference.steps.validation import simulate_measured
    from negstiff.models.device import load_system
    from negstiff.models.effects import measured_channels
    from negstiff.models.equation import check_dissipation

    system = load_system(args.model)
    if hasattr(system, "n_dof"):  # a structure of N DOFs: its responses z1 ... zN and velocities
        return _simulate_structure(args, system)
    check_dissipation(getattr(system, "extra", {}), str(args.model))
    # the measured channels the model's aux:NAME terms need are read with the input, unless --aux names others
    needed = list(measured_channels(getattr(system, "extra", {})))
    rec = load(args.input, columns=args.columns, fs=args.fs, response=False, gravity=args.gravity,
               aux=args.aux if args.aux is not None else needed)  # fmt: skip
    rec.require(2, "a simulation")
    res = simulate_measured(system, rec, args.z0, args.v0, args.interpolation, args.substeps)
    if res.diverged[0]:  # the refusal is the one line: the progress line follows a run that did not diverge
        raise InputError(f"simulation of {args.model} under {args.input} failed: {res.describe_failures()}")
    say(args, f"simulate: {rec.n} samples at {rec.fs:g} Hz under {rec.input_name}")
    assert res.z_dot is not None  # simulate_measured stores the velocity
    data = np.column_stack([rec.t, rec.u, res.z[0], res.z_dot[0]])
    with atomic_path(args.out) as tmp:
        np.savetxt(tmp, data, delimiter=",", fmt="%.10g", header=f"t,{rec.input_name},z,z_dot", comments="")
    say(args, f"wrote {args.out} ({rec.n} samples)")
    return 0


def _simulate_structure(args, structure) -> int:
    """``simulate STRUCTURE.json``: the structure under the record's input, every DOF's z and z_dot written."""
    from negstiff.files import atomic_path
    from negstiff.inference.record.reading import load
    from negstiff.inference.steps.validation import check_structure_run

    for option, given in (("--v0", args.v0), ("--aux", args.aux)):
        if given:
            raise InputError(f"{option} is for a single-DOF model (a structure starts from rest; --z0 names its well)")
    if args.interpolation == "linear":
        raise InputError("a structure's input is band-limited between samples: --interpolation linear is not offered")
    rec = load(args.input, columns=args.columns, fs=args.fs, response=False, gravity=args.gravity)
    rec.require(2, "a simulation")
    try:
        check_structure_run(structure, args.z0)
    except InputError as exc:
        raise InputError(f"{args.model}: {exc}") from None
    n = structure.n_dof
    say(args, f"simulate: {n} DOFs, {rec.n} samples at {rec.fs:g} Hz under {rec.input_name}")
    res = structure.simulate(rec.u, rec.dt, z0=args.z0, input_kind=rec.input_name, substeps=args.substeps or 2)
    if res.diverged[0]:
        raise InputError(f"simulation of {args.model} under {args.input} failed: {res.describe_failures()}")
    data = np.column_stack([rec.t, rec.u, *res.z[0], *res.z_dot[0]])
    head = ",".join(["t", rec.input_name, *(f"z{i + 1}" for i in range(n)), *(f"z{i + 1}_dot" for i in range(n))])
    with atomic_path(args.out) as tmp:
        np.savetxt(tmp, data, delimiter=",", fmt="%.10g", header=head, comments="")
    say(args, f"wrote {args.out} ({rec.n} samples, {n} DOFs)")
    return 0


def refinement(args) -> bool | None:
    """The estimators' ``refine`` from ``--no-refine``: False, else None (the estimator's default)."""
    return False if args.no_refine else None


def cmd_identify(args) -> int:
    from negstiff.inference.analysis.frf import read_frf_results
    from negstiff.inference.record.reading import load

    masses = parse_amplitudes(args.masses, "--masses") if args.masses else None
    rec = load(args.data, columns=args.columns, fs=args.fs, mass=args.mass, gravity=args.gravity, aux=args.aux,
               masses=masses, decay=args.decay, force_dof=args.force_dof)  # fmt: skip
    check_dofs(args, rec)
    frfs = read_frf_results(args.frf)
    for path, _, _, n_dofs in frfs:  # before any work: a structure's FRFs do not read a single DOF's wells
        if rec.n_dof == 1 and n_dofs > 1:
            raise InputError(f"--frf {path}: a structure's FRFs ({n_dofs} DOFs) beside a single DOF's record")
    if args.method == "nsi":
        from negstiff.inference.estimators.nsi import NSI

        est: NSI | SINDy = NSI(
            order=args.order, block_rows=args.block_rows, refine=refinement(args), progress=wants_progress(args),
            element=args.element, law=args.law, damping=args.damping,
        )  # fmt: skip
    else:
        from negstiff.inference.estimators.sindy import SINDy

        est = SINDy(n_models=args.ensemble, seed=args.seed, refine=refinement(args), element=args.element,
                    law=args.law, damping=args.damping)  # fmt: skip
    rec = est.check(rec)  # every refusal before the progress line
    if rec.n_dof > 1:
        return _identify_structure(args, est, rec, frfs)
    say(args, f"identify {args.method}: {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}")
    est.fit(rec)
    result = est.result()
    kind = result.get("record_kind") or {}
    if kind.get("kind") in ("impact", "decay"):
        say(args, f"read as {'a hammer' if kind['kind'] == 'impact' else 'a free decay'}'s record: {kind['how']}")
    if args.frf:
        compared(args, result, frfs)
    say_refinement(args, result.get("refinement"))
    v = result["validation"]
    warn(args, result["warnings"])
    if args.method == "sindy":
        say(args, f"selected terms: {', '.join(result['selected_terms'])}")
    write_json(args.out, result)
    wells = ", ".join(
        f"{w}: {m['f_hz']:.3f} Hz, zeta {100 * m['zeta']:.1f} %"
        for w, m in result["modal"].items()
        if m["f_hz"] is not None
    )
    say(args, f"wrote {args.out} ({wells}; validation {v['rms_percent']:.2f} % rms)")
    return 0


def check_dofs(args, rec, path=None) -> None:
    """``--dofs N``: a check of the file ``path`` (default ``args.data``): its responses z1 ... zN give N."""
    if args.dofs is not None and rec.n_dof != args.dofs:
        have = "z" if rec.n_dof == 1 else f"z1 ... z{rec.n_dof}"
        raise InputError(f"{path or args.data}: --dofs {args.dofs}, but the record has responses {have}")


def compared(args, result: dict, frfs) -> None:
    """``--frf``: each FRF peak beside the identified underlying-linear frequency nearest it, in the result and said."""
    from negstiff.inference.analysis.frf import compare_with_frf

    result["frf_comparison"] = compare_with_frf(result["modal"], frfs)
    for c in result["frf_comparison"]:
        if c["identified_f_hz"] is None:
            say(args, f"FRF {c['frf_f_hz']:.4f} Hz: no identified frequency to compare with")
            continue
        mode = f" mode {c['mode']}" if "mode" in c else ""
        say(args, f"{c['well']} well{mode}: identified {c['identified_f_hz']:.4f} Hz, FRF {c['frf_f_hz']:.4f} Hz "
                  f"({c['difference_percent']:+.2f} %)")  # fmt: skip


def _identify_structure(args, est, rec, frfs) -> int:
    """``identify`` on a structure's record (N > 1 DOFs, ``--element I-J``): the same estimator, its result."""
    from negstiff.inference.estimators.base import element_of
    from negstiff.inference.estimators.results import modes_summary

    at = element_of(est, rec)  # the estimator's own reading (--element, else the file's '# element:')
    assert at is not None  # a structure's record (N > 1): its place, or element_of refused it
    say(args, f"identify {args.method}: {rec.n_dof} DOFs, element {at[0]}-{at[1]}, {rec.n} samples at {rec.fs:g} Hz")
    est.fit(rec)
    result = est.result()
    if args.frf:
        compared(args, result, frfs)
    say_refinement(args, result.get("refinement"))
    warn(args, result["warnings"])
    write_json(args.out, result)
    v = result["validation"]
    said = est.result_.summary() if result.get("linear_part") == "state_space" else modes_summary(est.modal_)
    best = v.get("best_linear_rms_percent")  # a state-space model's: the best linear model of its order, judged alike
    against = "" if best is None else f", the best linear model of its order {best:.1f} %"
    say(args, f"wrote {args.out} ({said}; validation {v['rms_percent']:.1f} % rms{against})")
    return 0


def cmd_posterior(args) -> int:
    from negstiff.inference.estimators.base import element_of
    from negstiff.inference.estimators.posterior import Posterior
    from negstiff.inference.record.reading import load
    from negstiff.models import Model
    from negstiff.models.device import load_system

    start: Any = None
    if args.start is not None:
        from negstiff.files import read_json
        from negstiff.inference.estimators.results import Identification
        from negstiff.models.structure import Structure

        held = read_json(args.start, "start model")
        if isinstance(held, dict) and "structure" in held and "dofs" in held:
            start = Identification.from_json(held)  # a structure's identify result: its channels' zeros kept
        else:
            start = load_system(args.start)
        if args.model != "coefficients" or not isinstance(start, Model | Structure | Identification):
            raise InputError(f"--start {args.start}: a polynomial model, a structure or an identify result, for the "
                             "coefficient posterior (--model coefficients)")  # fmt: skip
    masses = parse_amplitudes(args.masses, "--masses") if args.masses else None
    recs = []
    for path in args.data:  # several: records of one device, fitted together
        rec = load(path, columns=args.columns, fs=args.fs, mass=args.mass, gravity=args.gravity, masses=masses,
                   decay=args.decay, force_dof=args.force_dof)  # fmt: skip
        check_dofs(args, rec, path)  # N from the file; --dofs a check
        if args.duration is not None:
            rec = rec.segment(0, rec.n if not args.duration * rec.fs < rec.n else int(round(args.duration * rec.fs)))
        recs.append(rec)
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
        input_noise=args.input_noise,
        seed=args.seed,
        progress=wants_progress(args),
        start=start,
        refine_start=not args.no_refine,
        element=args.element,
        chain_file=args.chain_file,
        resume=args.resume,
        law=args.law,
        damping=args.damping,
    )
    checked = post.check(recs if len(recs) > 1 else recs[0])  # every refusal before the progress line and bar
    rec = checked[0] if isinstance(checked, list) else checked
    at = element_of(post, rec)  # the estimator's own reading (--element, else the file's '# element:')
    where = f", {rec.n_dof} DOFs, element {at[0]}-{at[1]}" if at is not None else ""
    pair = post.law_pair()
    what = args.model if pair is None else f"laws {pair[0].name} and {pair[1].name}"
    n = sum(r.n for r in checked) if isinstance(checked, list) else rec.n
    joint = f" of {len(checked)} records" if isinstance(checked, list) else ""
    say(args, f"posterior ({what}{where}): {n} samples{joint} at {rec.fs:g} Hz, input {rec.input_name}")
    res = post.fit(checked).result_
    result = post.result()
    if args.idata:
        from negstiff.files import atomic_path

        with atomic_path(args.idata) as tmp:
            res.idata.to_netcdf(tmp, engine="h5netcdf")
    write_json(args.out, result)
    warn(args, result["warnings"])
    line = ", ".join(f"{n} {s['mean']:.4g} +- {s['sd']:.2g}" for n, s in result["parameters"].items())
    say(args, f"wrote {args.out}: {line}")
    return 0


def cmd_discrepancy(args) -> int:
    from negstiff.inference.estimators.discrepancy import CUBIC_BASELINE, LINEAR_BASELINE, Discrepancy
    from negstiff.inference.record.reading import load

    masses = parse_amplitudes(args.masses, "--masses") if args.masses else None
    rec = load(args.data, columns=args.columns, fs=args.fs, mass=args.mass, gravity=args.gravity, aux=args.aux,
               masses=masses, decay=args.decay, force_dof=args.force_dof)  # fmt: skip
    check_dofs(args, rec)
    base = CUBIC_BASELINE if args.baseline == "cubic" else LINEAR_BASELINE
    d = Discrepancy(baseline=base, max_effects=args.max_effects, refine=refinement(args), unnamed=args.unnamed,
                    law=args.law, damping=args.damping, offer_laws=False if args.no_laws else None,
                    element=args.element)  # fmt: skip
    rec = d.check(rec)  # every refusal before the progress line
    what = f"law {args.law}" if args.law else f"baseline {args.baseline}"
    say(args, f"discrepancy: {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}, {what}"
              + (f", damping {args.damping}" if args.damping else ""))  # fmt: skip
    d.fit(rec)
    result = d.result()
    kind = result.get("record_kind") or {}
    if kind.get("kind") in ("impact", "decay"):
        say(args, f"read as {'a hammer' if kind['kind'] == 'impact' else 'a free decay'}'s record: {kind['how']}")
    say_refinement(args, result.get("refinement"))
    write_json(args.out, result)
    warn(args, result["warnings"])
    acc = result["details"] if "dofs" in result else result  # a structure's workflow account is its details
    say(args, f"where: {acc['where']}")
    un = acc.get("unnamed")
    if un and "gap" not in un:  # not fitted (a hammer's record): why
        say(args, f"unnamed: {un['reason']}")
    elif un:
        g = un["gap"]
        say(args, f"unnamed: a non-parametric term of {un['term_percent_of_restoring_force']:.3g} % of the "
                   f"restoring force; held-out gap {g.get('physics_median_window_percent', float('nan')):.3g} % -> "
                   f"{g.get('hybrid_median_window_percent', float('nan')):.3g} % with it")  # fmt: skip
    for i, it in enumerate(acc.get("iterations", [])):
        first = it.get("first") or {}
        if first.get("why") and first.get("effect") != "none":
            say(args, f"round {i + 1}: {first['effect']} ranked first, not named: {first['why']}")
    for effect, iv in acc.get("effect_interval", {}).items():
        if effect.startswith("law:"):
            size = iv.get("value") or {}
            say(args, f"{effect}: the restoring force is the {effect[4:]} law's ("
                      + ", ".join(f"{k} {v:.4g}" for k, v in size.items()) + ")")  # fmt: skip
            continue
        parts = [(k, v) for k, v in iv.items() if isinstance(v, dict) and v.get("interval")] or (
            [("", iv)] if iv.get("interval") else [])  # fmt: skip
        sizes = ", ".join(f"{k + ' ' if k else ''}{v['value']:.4g} [{v['interval'][0]:.4g}, {v['interval'][1]:.4g}]"
                          for k, v in parts)  # fmt: skip
        b = acc.get("bayesian", {}).get(effect, {})
        opinion = (f"; LOO over {b['windows']} windows prefers the model {b['prefers']} it (elpd difference "
                   f"{b['elpd_diff']:.3g} +- {b['dse']:.3g}"
                   + ("; PSIS's Pareto k is high for some: LOO is rough there" if b.get("pareto_k_high") else "")
                   + ")" if "prefers" in b else "")  # fmt: skip
        say(args, f"{effect}: {sizes or 'no interval'} ({100 * iv['prob']:g} % interval){opinion}")
    say(
        args,
        f"wrote {args.out}: named {', '.join(acc['effects'])}; held-out gap (restarted free runs) "
        f"{acc['gap_before_percent']:.3g} % -> {acc['gap_after_percent']:.3g} %",
    )
    return 0


def parse_wells(text: str | None) -> tuple[float, ...] | None:
    """``--wells z_minus,z_plus`` (or z_minus,z_0,z_plus) [m], increasing; None when not given."""
    if not text:
        return None
    try:
        wells = tuple(float(x) for x in text.split(","))
        if len(wells) not in (2, 3) or not all(np.isfinite(wells)) or any(np.diff(wells) <= 0):
            raise ValueError
    except ValueError:
        raise InputError(f"--wells {text!r}: give z_minus,z_plus or z_minus,z_0,z_plus in m, increasing") from None
    return wells


def cmd_characterise(args) -> int:
    from negstiff.inference.analysis.characterise import characterise, check_harmonic, response_for
    from negstiff.inference.record.reading import load
    from negstiff.report.record import check_forcing

    given = parse_wells(args.wells)  # the options before any work
    if args.element is not None and args.dof is not None:
        raise InputError("--element and --dof each name the one response analysed: give one")
    rec = load(args.data, columns=args.columns, fs=args.fs, gravity=args.gravity)
    if rec.n_dof > 1 or args.element is not None or args.dof is not None:
        if args.signal != "z":
            raise InputError(f"--signal {args.signal} reads a single DOF's columns; a structure's response is named "
                             "by --element I-J or --dof K")  # fmt: skip
        rec = response_for(rec, args.element, args.dof)
    if args.signal != "z":
        col = getattr(rec, args.signal, None)
        if col is None:
            raise InputError(f"{args.data}: no column {args.signal!r} to analyse (choose z, y, z_dot or base_disp)")
        rec = dataclasses.replace(rec, z=col)
    check_forcing(rec, args.forcing_hz)  # within the record's usable band (2 samples a period are not)
    check_harmonic(rec, args.forcing_hz)
    say(args, f"characterise: {rec.n} samples at {rec.fs:g} Hz, forcing {args.forcing_hz:g} Hz")
    r = characterise(rec, args.forcing_hz, given if given is not None else "auto")
    write_json(args.out, r)
    warn(args, r["warnings"])
    lle = r["lle"]
    lle_txt = "not determinable" if lle["value"] is None else f"{lle['value']:.2f} +- {lle['sd']:.2g} 1/s (Wolf)"
    if lle.get("rosenstein") is not None:
        lle_txt += f", {lle['rosenstein']:.2f} 1/s (Rosenstein)"
    say(
        args,
        f"wrote {args.out}: period {r['period']}, {r['regime']}, LLE {lle_txt}, "
        f"{'chaotic' if r['chaotic'] else 'not chaotic'}",
    )
    for what, why in r["reasons"].items():
        say(args, f"{what}: {why}")
    return 0


def cmd_frf(args) -> int:
    from negstiff.inference.analysis.frf import check_frf, frf
    from negstiff.inference.record.reading import load
    from negstiff.report.figures import frf_figure

    band = parse_band(args.band)
    rec = load(args.data, columns=args.columns, fs=args.fs, gravity=args.gravity)
    check_dofs(args, rec)
    if rec.n_dof > 1:
        return _frf_structure(args, band, rec)
    if band is not None and band[1] > rec.fs / 2:
        raise InputError(f"--band {args.band}: beyond the Nyquist frequency of {args.data} ({rec.fs / 2:g} Hz)")
    check_frf(rec, band)
    say(args, f"frf: {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}")
    res = frf(rec, band=band, segment_s=args.segment)
    if res.get("impacts"):
        imp = res["impacts"]
        say(
            args,
            f"frf: treated as an impact test: {imp['hits']} hit(s) found in the force channel (offset "
            f"{imp['offset_n'][0]:.3g} N removed), blocks of {imp['block_s']:.3g} s; {imp['windows']}",
        )
    curves = res.pop("_curves")
    fig = frf_figure(res, curves, rec.input_name, f"FRF of {Path(args.data).name}")
    res["figure"] = write_figure(fig, args.out)
    write_json(args.out, res)
    warn(args, res["warnings"])
    top = "no peak" if res["f_hz"] is None else (f"{res['f_hz']:.4f} Hz, zeta {100 * res['zeta']:.2f} %, "
                                                 f"coherence {res['coherence']:.2f}")  # fmt: skip
    say(args, f"wrote {args.out} and {res['figure']}: dominant peak {top}; {len(res['peaks'])} peak(s)")
    return 0


def _frf_structure(args, band, rec) -> int:
    """``frf DATA`` on a structure's record (N > 1 DOFs): every DOF's FRF from the input, the modes merged."""
    from negstiff.inference.analysis.frf import check_frf, frf_structure
    from negstiff.report.figures import frf_figure_dofs as figure_dofs

    if band is not None and band[1] > rec.fs / 2:
        raise InputError(f"--band {args.band}: beyond the Nyquist frequency of {args.data} ({rec.fs / 2:g} Hz)")
    check_frf(rec, band)  # every DOF's: before the progress line
    say(args, f"frf: {rec.n_dof} DOFs, {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}")
    res = frf_structure(rec, band=band, segment_s=args.segment)
    curves = res.pop("_curves")
    res["figure"] = write_figure(figure_dofs(res, curves, rec.input_name, f"FRFs of {Path(args.data).name}"), args.out)
    write_json(args.out, res)
    warn(args, res["warnings"])
    modes = ", ".join(f"{m['f_hz']:.3f} Hz ({100 * m['zeta']:.2f} %, z{'/z'.join(map(str, m['seen_on']))})"
                      for m in res["modes"]) or "no peak"  # fmt: skip
    say(args, f"wrote {args.out} and {res['figure']}: {modes}")
    return 0


def cmd_backbone(args) -> int:
    from negstiff.inference.analysis.backbone import backbone
    from negstiff.inference.record.reading import load
    from negstiff.models import Model
    from negstiff.models.device import load_system
    from negstiff.models.structure import Structure
    from negstiff.report.figures import backbone_figure

    model = load_system(args.model) if args.model else None
    if model is not None and not isinstance(model, (Model, Structure)):
        raise InputError(f"--model {args.model}: a backbone's prediction needs a model file (coefficients) or a "
                         "structure file, not a device file")  # fmt: skip
    band = parse_band(args.band)
    if band is not None and band[0] <= 0:
        raise InputError(f"--band {args.band}: a backbone's band-pass starts above 0 Hz")
    rec = load(args.data, columns=args.columns, fs=args.fs, gravity=args.gravity, mass=args.mass, decay=args.decay)
    dof = args.dof
    if dof is not None and dof > rec.n_dof:
        raise InputError(f"--dof {dof}: one of the record's DOFs, 1..{rec.n_dof}")
    if band is not None and band[1] >= rec.fs / 2:
        raise InputError(f"--band {args.band}: beyond the Nyquist frequency of {args.data} ({rec.fs / 2:g} Hz)")
    n_model = model.n_dof if isinstance(model, Structure) else 1
    if model is not None and n_model != rec.n_dof:
        raise InputError(f"--model {args.model}: a model of {n_model} DOF(s) for a record of {rec.n_dof}")
    offsets = None  # a structure's identify result: each channel's zero it found (measured = physical + offset)
    if isinstance(model, Structure):
        found = json.loads(Path(args.model).read_text()).get("offsets_m")
        offsets = [float(o) for o in found] if isinstance(found, list) and len(found) == rec.n_dof else None
    say(args, f"backbone: {rec.n} samples at {rec.fs:g} Hz, input {rec.input_name}")
    res = backbone(rec, model=model, dof=dof, band=band, offsets=offsets)
    res["figure"] = write_figure(backbone_figure(res, f"Backbone of {Path(args.data).name}"), args.out)
    write_json(args.out, res)
    warn(args, res["warnings"])
    lo, hi = res["amplitude_range_m"]
    lin = res["linear"]
    pred = res.get("predicted")
    say(
        args,
        f"wrote {args.out} and {res['figure']}: decay from {res['decay']['start_s']:.4g} s"
        + (f", DOF {res['dof']} in {res['band_hz'][0]:.3g}-{res['band_hz'][1]:.3g} Hz" if rec.n_dof > 1 else "")
        + ", amplitudes "
        f"{1e3 * hi:.3g} to {1e3 * lo:.3g} mm, small-amplitude {lin['f_hz']:.4f} Hz, zeta "
        f"{100 * lin['zeta']:.2f} %"
        + (
            ""
            if pred is None or pred["difference_percent"] is None
            else f"; the model's backbone within {pred['difference_percent']:.2f} %"
        ),
    )
    return 0


def cmd_nfrc(args) -> int:
    from negstiff.models.continuation import check_nfrc, nfrc
    from negstiff.models.device import load_system
    from negstiff.report.figures import continuation_figure as figure

    system = load_system(args.model)
    freq, amplitude = parse_span(args.freq, "--freq"), parse_span(args.amplitude, "--amplitude")
    if isinstance(freq, tuple) == isinstance(amplitude, tuple):
        raise InputError("give a range (F1:F2 or A1:A2) for exactly one of --freq and --amplitude")
    settings = {"freq": freq, "amplitude": amplitude, "well": args.well, "input_kind": args.input,
                "max_period": args.max_period}  # fmt: skip
    check_nfrc(system, **settings)
    say(args, f"nfrc: continuation in {'amplitude' if isinstance(amplitude, tuple) else 'frequency'} from the "
              f"{args.well} well")  # fmt: skip
    res = nfrc(system, **settings)
    res["figure"] = write_figure(figure(res), args.out)
    write_json(args.out, res)
    kinds = ", ".join(f"{b['type']} at {b['amplitude']:.4g} / {b['f_hz']:.4g} Hz (period {b['period']})"
                      for b in res["bifurcations"]) or "none"  # fmt: skip
    say(args, f"wrote {args.out} and {res['figure']}: {len(res['branches'])} branch(es); bifurcations: {kinds}")
    return 0


def cmd_map(args) -> int:
    from negstiff.inference.analysis.campaign import Campaign
    from negstiff.report.sections import map_figure

    given = parse_wells(args.wells)  # the options, and every input read and checked, before any analysis
    campaign = Campaign.read(args.data, args.columns, args.fs, args.forcing_hz, given, args.nfrc, gravity=args.gravity)
    n, f0 = len(campaign.records), campaign.freqs[0]
    say(args, f"map: {n} record(s), " + ("stepped in frequency" if campaign.axis == "f_hz" else f"at {f0:g} Hz"))
    res = campaign.map(progress=lambda line: say(args, line))
    unit = "m/s^2" if res["input"] == "base_acc" else "N"
    res["figure"] = write_figure(map_figure(res["points"], campaign.overlays, unit, campaign.axis), args.out)
    write_json(args.out, res)
    warn(args, res["warnings"])
    say(
        args,
        f"wrote {args.out} and {res['figure']}: "
        + "; ".join(
            f"{k}: " + ", ".join(f"{n} {v}" for n, v in s.items() if n != "sequence") for k, s in res["sweeps"].items()
        ),
    )
    return 0


def write_figure(fig, out: str) -> str:
    """A command's figure beside its result (``out`` with .png), atomically; returns the figure's name."""
    import matplotlib.pyplot as plt

    from negstiff.files import atomic_path

    png = Path(out).with_suffix(".png")
    with atomic_path(png) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return png.name


def cmd_design(args) -> int:
    from negstiff.inference.analysis.design import DEFAULT_MAX_ACC, design, design_figure, prepared
    from negstiff.inference.analysis.separation import separation

    if args.separate is not None:
        given = [o for o, v in (("--target", args.target), ("--candidates", args.candidates),
                                ("--draws", args.draws), ("--max-force", args.max_force)) if v is not None]  # fmt: skip
        if given:
            raise InputError(f"{', '.join(given)}: a design's option; a separation (--separate) ranks random tests by "
                             "what the discrepancy workflow's verdict tells, and does not read it")  # fmt: skip
        say(args, f"design: which random test tells apart the effects {args.separate} ranked first")
        result = separation(
            args.posterior,
            args.separate,
            duration=args.duration,
            max_table_acc=DEFAULT_MAX_ACC if args.max_acc is None else args.max_acc,
            max_table_disp=args.table_stroke,
            stroke=args.stroke,
            sensor_range=args.sensor_range,
            seed=args.seed,
        )  # fmt: skip  (every refusal before the work)
        write_json(args.out, result)
        warn(args, result["warnings"])
        best = result["best"]
        say(args, f"wrote {args.out}: {best['test']} tells them apart with {best['information_bits']:.2f} bits "
                  f"(the default random test: {result['default_test']['information_bits']:.2f})")  # fmt: skip
        return 0
    args.candidates = 50 if args.candidates is None else args.candidates
    args.draws = 16 if args.draws is None else args.draws
    run = prepared(
        args.posterior,
        targets=args.target,
        duration=args.duration,
        max_table_acc=args.max_acc,
        max_table_disp=args.table_stroke,
        stroke=args.stroke,
        sensor_range=args.sensor_range,
        max_force=args.max_force,
        candidates=args.candidates,
        draws=args.draws,
        seed=args.seed,
    )  # fmt: skip  (every refusal before the work)
    say(args, f"design: {args.candidates} candidate tests x {args.draws} posterior draws, targets "
              f"{', '.join(run['targets'])}")  # fmt: skip
    result = design(**run)  # the posterior as ``prepared`` read it
    result["figure"] = write_figure(design_figure(result), args.out)
    write_json(args.out, result)
    warn(args, result["warnings"])
    best = result["best"]
    ref = result["default_test"]
    say(args, f"wrote {args.out}: next test {best['test']}, targets' intervals {best['score']:.3g}x narrower "
              f"(the default test, {ref['test']}: {ref['score']:.3g}x)")  # fmt: skip
    return 0


def cmd_update(args) -> int:
    from tqdm import tqdm

    from negstiff.inference.estimators.updating import GAUpdater, load_targets

    targets = load_targets(args.targets)
    ga = GAUpdater(pop_size=args.pop_size, generations=args.generations, fixed_mass=args.fix_mass, seed=args.seed)
    ga.check(targets)  # every refusal before the progress bar
    say(args, f"update: GA of {args.generations} generations x {args.pop_size}")
    bar = tqdm(total=args.generations, desc="GA", unit="gen", disable=not wants_progress(args), file=sys.stderr)

    def progress(gen: int, best: float) -> None:
        bar.update(1)
        bar.set_postfix(best=f"{best:.3f} %")

    ga.fit(targets, progress=progress)
    bar.close()
    result = ga.result()
    write_json(args.out, result)
    warn(args, result["warnings"])
    d = ga.device_
    say(
        args,
        f"wrote {args.out}: E = {d.E / 1e9:.2f} GPa, alpha = {d.alpha_deg:.2f} deg, m = {d.m * 1e3:.1f} g, "
        f"fitness {ga.fitness_:.3f} % (reference study Eq. 9)"
        + (f", restoring-force mismatch {ga.objective_:.3f} % (minimised)" if ga.stroke_ is not None else ""),
    )
    return 0


def law_readers() -> tuple[str, ...]:
    """The report's analyses whose estimator takes ``law`` and ``damping``."""
    import inspect

    from negstiff.inference.estimators.discrepancy import Discrepancy
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.estimators.posterior.core import Posterior
    from negstiff.inference.estimators.sindy import SINDy

    classes = {"nsi": NSI, "sindy": SINDy, "posterior": Posterior, "discrepancy": Discrepancy}
    return tuple(n for n, c in classes.items() if {"law", "damping"} <= set(inspect.signature(c).parameters))


def cmd_report(args) -> int:
    from negstiff.report.record import report_records

    options: dict[str, dict] = {"posterior": {}, "discrepancy": {}}
    if args.duration is not None:
        options["posterior"]["duration"] = args.duration
    if args.max_steps is not None:
        options["posterior"]["max_steps"] = args.max_steps
    if args.ensembles is not None:
        options["posterior"]["n_ensembles"] = args.ensembles
    from negstiff.models import laws

    if args.law is not None or args.damping != laws.DEFAULT_DAMPING:
        # every analysis that reads a law (the identifications; the others as they come to read one)
        for name in law_readers():
            options.setdefault(name, {}).update(law=args.law, damping=args.damping)
    if args.max_effects is not None:
        options["discrepancy"]["max_effects"] = args.max_effects
    masses = parse_amplitudes(args.masses, "--masses") if args.masses else None
    rep = report_records(args.data, args.columns, args.fs, args.mass, args.forcing_hz, parse_wells(args.wells),
                         args.nfrc, args.only, args.seed, options, progress=lambda line: say(args, line),
                         gravity=args.gravity, aux=args.aux, decay=args.decay, element=args.element,
                         masses=masses, force_dof=args.force_dof)  # fmt: skip
    rep.write(args.out)
    for w in rep.results()["summary"]:
        say(args, f"  {w}")
    say(args, f"wrote {args.out}/index.html (and index.md, results.json)")
    return 0


def cmd_reproduce(args) -> int:
    from negstiff.experiments.reproduce import reproduce

    reproduce(Path(args.out), fast=args.fast, seed=args.seed, progress=wants_progress(args), workers=args.workers)
    return 0
