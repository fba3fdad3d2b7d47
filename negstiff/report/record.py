"""The study negstiff runs on its rig, run on a lab's own record (``negstiff report``).

What the record is decides what is run: a broadband record (random, sine sweep, multisine) gets NSI around
each well it visited, SINDy, the coefficient posterior, the discrepancy workflow and the FRF; a harmonic
record (its input one spectral line, or ``forcing_hz`` given) gets the characterisation; a hammer's record
(``analysis.record_kind``) the FRF, NSI, SINDy and the posterior; a free decay NSI, SINDy and the backbone
(measured and the identified model's); several records or
a folder (a stepped campaign) get the bifurcation map, with continuations drawn over it. ``only`` chooses
among them. A structure's record (N DOFs) takes the same plan, each analysis reading it as its estimator reads
it (the element's place from ``element`` or the file's ``# element:``). Every input is read and checked before any
work (one ``InputError``); each analysis that then cannot be made is shown in its place with the reason, and the
rest of the report is still written.

The report opens with the summary and a table of contents, then the record (sensor, derivation, frame,
warnings), one table of every coefficient with each method's estimate beside the posterior's mean and
credible interval (and its forest plot), the held-out prediction errors against the record's noise floor,
and a section per analysis (``negstiff.report.sections``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError
from negstiff.inference.analysis.periodicity import harmonic_frequency

from .document import Report

BROADBAND = ("nsi", "sindy", "posterior", "design", "discrepancy", "frf")
HARMONIC = ("characterise",)
CAMPAIGN = ("map",)
IMPACT = ("frf", "nsi", "sindy", "interval", "posterior", "design", "discrepancy")
"""A hammer's record: its FRF (hits, offsets, windows), the identifications with the force windowed, NSI's
estimate's interval by batch means over blocks of the record (a hit or so each), the coefficient posterior (its
windows between the hits), the hammer hits and releases to run next, and the discrepancy workflow (its windows after
the hits)."""
DECAY = ("nsi", "sindy", "posterior", "design", "discrepancy", "backbone")
"""A free decay: the identifications (their decay forms), the coefficient posterior, the hammer hits and releases to
run next, the discrepancy workflow, then the backbone measured and the identified model's, with the posterior's
credible band."""
SECTIONS = (*BROADBAND, *HARMONIC, *CAMPAIGN, "backbone", "interval")
"""Every analysis a report may hold (``only`` chooses among them)."""

SECTION_ALIASES = {"characterize": "characterise"}
"""An analysis's other spellings ``only`` takes: the command's alias (``negstiff characterize``) names its section."""


def _only(only: Sequence[str] | str | None, kind: tuple[str, ...]) -> tuple[str, ...]:
    if not only:
        return kind
    names = tuple(SECTION_ALIASES.get(x.strip(), x.strip())
                  for x in (only.split(",") if isinstance(only, str) else only) if x.strip())  # fmt: skip
    bad = [n for n in names if n not in SECTIONS]
    if bad:
        raise InputError(f"--only {','.join(names)}: unknown analysis {bad[0]!r} (choose among {', '.join(SECTIONS)})")
    chosen = tuple(n for n in names if n in kind)
    if "design" in chosen and "posterior" not in chosen:  # the design reads the posterior: sampled first
        chosen = tuple(x for n in chosen for x in (("posterior", n) if n == "design" else (n,)))
    if not chosen:
        raise InputError(f"--only {','.join(names)}: none of these fits this record (it takes {', '.join(kind)})")
    return chosen


def report_records(
    data: Sequence[str | Path],
    columns: str | None = None,
    fs: float | None = None,
    mass: float | None = None,
    forcing_hz: float | None = None,
    wells: tuple[float, ...] | None = None,
    nfrc: Sequence[str] | None = None,
    only: Sequence[str] | str | None = None,
    seed: int = 0,
    options: dict[str, dict[str, Any]] | None = None,
    progress: Callable[[str], None] | None = None,
    gravity: float | None = None,
    aux: Sequence[str] | str | None = None,
    decay: bool = False,
    element: str | None = None,
    masses: Sequence[float] | None = None,
    force_dof: int | None = None,
) -> Report:
    """The report of ``data`` (one record, or a campaign's records or folder): every input read and checked
    first (one ``InputError``), then each analysis that fits it; ``options`` per analysis (``{"posterior":
    {"max_steps": 2000}, ...}``: the estimators' parameters); ``progress`` hears of each analysis. Returns the
    ``Report`` (``write(folder)`` writes it). ``gravity`` [m/s^2] along the motion overrides the records'
    metadata (0 for a horizontal device); ``aux`` names measured auxiliary channels of a single record (SINDy
    and the discrepancy workflow offer each as a term); ``decay``: a single record is a free decay whatever its
    input column holds (``load``'s). A structure's record (N DOFs, ``z1 ... zN``) is reported as a single DOF's is,
    each analysis reading it as its estimator does: ``element`` its place (``"I-J"``; default: the file's
    ``# element:``), ``masses`` its DOFs' (default: the file's ``# masses:``), ``force_dof`` the DOF its force acts
    on (default: the file's ``# force_dof:``); an analysis that reads a single DOF's record only is shown with its
    reason.
    """
    say = progress or (lambda text: None)
    options = {k: dict(v) for k, v in (options or {}).items()}
    paths = [Path(d) for d in data]
    if len(paths) > 1 or paths[0].is_dir():
        if aux or decay:
            option = (
                "--aux: a campaign's report (characterisation, map) uses no auxiliary channel"
                if aux
                else "--decay: a campaign's records are forced (characterisation, map)"
            )
            raise InputError(f"{option}; give one record")
        return _campaign_report(data, columns, fs, forcing_hz, wells, nfrc, _only(only, CAMPAIGN), say, gravity)
    from negstiff.inference.record.reading import load
    from negstiff.inference.steps.frame import pin_frame

    if nfrc:
        raise InputError("--nfrc: a single record's report draws no NFRC (a campaign's bifurcation map overlays "
                         "them); give a campaign's records or folder")  # fmt: skip
    rec = load(paths[0], columns=columns, fs=fs, mass=mass, gravity=gravity, aux=aux, decay=decay, force_dof=force_dof)
    if masses is not None:
        rec = rec.with_masses(masses)
    if rec.n_dof > 1 and element is None and "element" not in rec.meta:  # before any work: a structure's needs it
        raise InputError(f"{rec.source}: a record of {rec.n_dof} DOFs (z1 ... z{rec.n_dof}): give the element's "
                         "place (--element I-J, or '# element: I-J' in the file's header)")  # fmt: skip
    if element is not None:  # given here; else the estimators read the file's own (``element_of``), as its masses
        options = {**options, **{n: {**options.get(n, {}), "element": element}
                                 for n in ("nsi", "sindy", "posterior", "discrepancy")}}  # fmt: skip
        if rec.n_dof > 1:  # and the analyses that read the element's relative motion (the characterisation)
            text = element if isinstance(element, str) else f"{element[0]}-{element[1]}"
            rec = dataclasses.replace(rec, meta={**rec.meta, "element": text})
    if forcing_hz is not None:
        check_forcing(rec, forcing_hz)
    from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS, check_decay, record_kind

    what = record_kind(rec)
    if what.kind == "decay":
        check_decay(rec, "the report")  # a dead input on a record at rest: nothing to report, said before any work
    f_h = None if what.kind in RING_DOWN_KINDS and forcing_hz is None else forcing_hz or harmonic_frequency(rec)
    if f_h is not None and forcing_hz is None and f_h < 2 / rec.duration:
        f_h = None  # a 'line' under two cycles in the record is its drift or its offset, no forcing
    kind = {"impact": IMPACT, "decay": DECAY}.get(what.kind, HARMONIC if f_h else BROADBAND)
    chosen = _only(only, kind)
    runs = _plan(rec, chosen, f_h, wells, seed, options)  # every estimator built and its parameters checked
    refused = _preflight(rec, runs)  # every section's own check of the record, before any progress line
    rep = Report(f"negstiff report: {Path(rec.source).name}")  # the path once, in the record's table
    try:
        rec = pin_frame(rec)  # the record as the analyses see it (a derived z in the physical frame)
    except InputError:
        pass
    rep.add(rec)
    if what.kind in RING_DOWN_KINDS:
        rep.add_text(f"Read as {'a hammer' if what.kind == 'impact' else 'a free decay'}'s record: {what.how}.")
    failed: list[str] = []
    made: dict[str, Any] = {}
    for name, title, run, _ in runs:
        start = time.perf_counter()
        say(f"report: {title} ...")
        try:
            if name in refused:  # its check refused the record already (``_preflight``): not run again
                raise refused[name]
            result = run(rec)
        except InputError as exc:
            rep.add_failure(title, " ".join(str(exc).split()))
            say(f"report: {title}: not made ({exc})")
            failed.append(f"{title}: {' '.join(str(exc).split())}")
            continue
        except Exception as exc:  # noqa: BLE001 - a section's failure is shown in its place, the rest written
            rep.add_failure(title, f"{type(exc).__name__}: {' '.join(str(exc).split())} (a fault of negstiff's: "
                                   "please report it)")  # fmt: skip
            say(f"report: {title}: FAILED ({type(exc).__name__}: {exc})")
            failed.append(f"{title}: {type(exc).__name__}: {' '.join(str(exc).split())}")
            continue
        rep.add(result)
        made[name] = result
        if name == "frf" and _crosses_wells(rec, made):
            rep.warning("The record crosses between the wells: its FRF is not an underlying-linear system's (the "
                        "FRF of a low-level record around one well is; NSI gives each well's here).")  # fmt: skip
        say(f"report: {title} done ({time.perf_counter() - start:.1f} s)")
    if runs and len(failed) == len(runs):  # a report of nothing but "not made" is no result
        more = f" (and {len(failed) - 1} more: {', '.join(t for t, _, _, _ in runs[1:])})" if len(failed) > 1 else ""
        raise InputError(f"{rec.source}: no section of the report could be made: {failed[0]}{more}")
    if kind == HARMONIC and f_h:
        rep.add(harmonic_next_steps(f_h))
    return rep


def check_forcing(rec, forcing_hz: float, option: str = "--forcing-hz") -> None:
    """Refuse (``InputError``) a forcing frequency [Hz] above the record's usable band (``USABLE_BAND_FRACTION``
    of its sampling rate: its anti-aliasing filter's roll-off, where no forcing phase can be read), before any
    analysis.

    Parameters
    ----------
    rec : Measurement
        The record.
    forcing_hz : float
        The stated forcing frequency [Hz].
    option : str
        How the user gave it, for the message.
    """
    from negstiff.io.schema import USABLE_BAND_FRACTION

    top = USABLE_BAND_FRACTION * rec.fs
    if not 0 < forcing_hz <= top:
        raise InputError(
            f"{option} {forcing_hz:g}: {rec.fs / forcing_hz:.2g} samples a forcing period at {rec.fs:g} Hz; "
            f"{rec.source} resolves a forcing up to {top:g} Hz ({USABLE_BAND_FRACTION:g} fs, below its "
            "anti-aliasing filter's roll-off)"
        )


def harmonic_next_steps(forcing_hz: float):
    """The section a harmonic record's report ends with: what such a record cannot give, what record can, and
    the command that runs it (a report of a harmonic record runs the characterisation alone).
    """
    from .sections import Section

    sec = Section("next", "", "What else the bench can give")
    rows = [
        ["K(z), D(zdot), each well's frequency and damping", "a broadband record: random or swept-sine base "
         "excitation that explores the stroke", "negstiff report REC (NSI, SINDy, posterior, discrepancy, FRF); "
         "negstiff identify nsi|sindy REC"],
        ["each well's underlying-linear FRF", "a low-level random or swept record around one well",
         "negstiff frf REC"],
        ["the bifurcation map (period doubling, jumps, chaos)", f"a campaign: harmonic records stepped in amplitude "
         f"at {forcing_hz:.4g} Hz (or in frequency)", "negstiff map REC1 REC2 ... (or FOLDER); negstiff report on "
         "the same files"],
        ["the periodic response's stability and bifurcations", "an identified model (from a broadband record)",
         f"negstiff nfrc MODEL.json --freq {forcing_hz:.4g} --amplitude A1:A2"],
    ]  # fmt: skip
    sec.text(f"A harmonic record (one forcing line at {forcing_hz:.4g} Hz) shows what the device does at that "
             "frequency and level: its period, regime and Lyapunov exponent (the characterisation above). "
             "Identification and the rest need other records:")  # fmt: skip
    sec.table(["to get", "record needed", "command"], rows)
    sec.summary.append(
        "A harmonic record gives the characterisation only: identification (NSI, SINDy, the posterior, the "
        "discrepancy workflow) and the FRF need a broadband (random or swept) record, 'negstiff report REC' on it "
        "runs them; a campaign of harmonic records stepped in amplitude gives the bifurcation map ('negstiff map')."
    )
    sec.json = {"forcing_hz": forcing_hz, "next": [{"to_get": a, "record": b, "command": c} for a, b, c in rows]}
    return sec


def _crosses_wells(rec, made: dict[str, Any] | None = None) -> bool:
    """Whether the record visits both wells (``periodicity.classify_regime`` against its metadata's rest
    positions, else the wells of a cubic fitted to it); a structure's: whether the element's relative motion (in
    the frame an identification found) visits both of the identified element's wells (False before any).
    """
    from negstiff.inference.analysis.periodicity import classify_regime
    from negstiff.inference.steps.wells import well_guesses

    if rec.n_dof > 1:
        for est in (made or {}).values():
            result = getattr(est, "result_", None)
            structure = getattr(result, "structure", None)
            if structure is None or getattr(result, "linear_part", "physical") != "physical":
                continue
            eq = structure.element_equilibria()
            r = structure.coupling @ (np.asarray(rec.z) - np.asarray(est.result_.offsets_m)[:, None])
            return eq.z_minus is not None and classify_regime(r, (eq.z_minus, eq.z_plus)) == "cross-well"
        return False
    rest = rec.rest_positions
    try:
        wells = (rest["minus"], rest["plus"]) if len(rest) == 2 else well_guesses(rec)
    except (InputError, ValueError):
        return False
    return None not in wells and classify_regime(rec.z, wells) == "cross-well"


class _OptionRefused(InputError):
    """An option the user gave that the one analysis it is for refuses (``_preflight`` raises it at once)."""


Run = tuple[str, str, Callable[[Any], Any], Callable[[Any], None] | None]
"""A report's section: (name, title, run(record), check(record) or None: what the run checks before its work)."""

DEPENDS = {"interval": ("nsi", "sindy"), "design": ("posterior",)}
"""Sections made from another's fit: not made where every one they read was refused."""
TITLES = {"nsi": "NSI's identification", "sindy": "SINDy's identification", "posterior": "the coefficient posterior"}
"""How a refused section names the sections it is made from."""


def _preflight(rec, runs: list[Run]) -> dict[str, InputError]:
    """Each section's own check of the record (``Run``), before any progress line: an option refused by the one
    analysis it is for is one ``InputError`` at once (``--duration 0.01``: the posterior's part of the record too
    short); a record that every section refuses is one ``InputError`` naming the first refusal and the rest (a
    3-row file printed a "not made" line per section first). Returns the sections refused (made as "not made").
    """
    refused: dict[str, InputError] = {}
    for name, _, _, check in runs:
        if check is None:
            continue
        try:
            check(rec)
        except _OptionRefused:
            raise
        except InputError as exc:
            refused[name] = exc
    for name, needs in DEPENDS.items():
        if any(n == name for n, *_ in runs) and all(n in refused or n not in [r[0] for r in runs] for n in needs):
            made_from = " or ".join(TITLES.get(n, n) for n in needs)
            refused[name] = InputError(f"{rec.source}: it is made from {made_from}, which was not made")
    if runs and len(refused) == len(runs):
        first = runs[0]
        msg = " ".join(str(refused[first[0]]).split())
        more = f" (and {len(runs) - 1} more: {', '.join(n for n, _, _, _ in runs[1:])})" if len(runs) > 1 else ""
        raise InputError(f"{rec.source}: no section of the report could be made: {first[1]}: {msg}{more}")
    return refused


def _plan(rec, chosen, forcing_hz, wells, seed, options) -> list[Run]:
    """Each chosen analysis as (name, title, run(record), check(record)), its estimator's parameters checked now."""
    from negstiff.inference.analysis.characterise import characterise, check_harmonic
    from negstiff.inference.analysis.frf import check_frf
    from negstiff.inference.estimators.discrepancy import Discrepancy
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.inference.estimators.posterior.core import Posterior
    from negstiff.inference.estimators.sindy import SINDy

    runs: list[Run] = []
    fitted: dict[str, Any] = {}  # the identifications' fits, for the backbone's predicted curve
    for name in chosen:
        opts = options.get(name, {})
        if name in ("nsi", "sindy", "posterior", "discrepancy"):
            cls = {"nsi": NSI, "sindy": SINDy, "posterior": Posterior, "discrepancy": Discrepancy}[name]
            if name in ("sindy", "posterior"):
                opts.setdefault("seed", seed)
            duration = opts.pop("duration", None)
            # the posterior samples a named law: asked for the law the record asks for (--law auto), it samples the
            # one the identification chose (``_chosen_law``)
            auto = name == "posterior" and opts.get("law") == "auto"
            if auto:
                opts = {**opts, "law": None}
            est = cls(**opts)
            est._validate_params()
            est._validate()
            titles = {"nsi": "NSI around each well", "sindy": "SINDy", "posterior": "the coefficient posterior",
                      "discrepancy": "the discrepancy workflow"}  # fmt: skip

            def part(r, duration=duration):
                if duration is None or not duration * r.fs < r.n:  # the whole record (1e308 s: no overflow)
                    return r
                return r.segment(0, int(round(duration * r.fs)))

            def run(r, est=est, part=part, name=name, auto=auto):
                if auto:
                    est.set_params(law=_chosen_law(part(r), fitted, est.damping))
                fitted[name] = est.fit(part(r))
                return fitted[name]

            def check(r, est=est, part=part, duration=duration):
                est.check(r)
                if duration is not None:  # the option's part of a record the analysis takes whole
                    try:
                        est.check(part(r))
                    except InputError as exc:
                        raise _OptionRefused(f"--duration {duration:g}: {' '.join(str(exc).split())}") from None

            runs.append((name, titles[name], run, check))
        elif name == "frf":
            runs.append((name, "the frequency response",
                         lambda r: _frf_beside_models(r, fitted, options.get("frf", {})), check_frf))  # fmt: skip
        elif name == "interval":
            runs.append((name, "the identification's interval", lambda r: _interval(r, fitted), None))
        elif name == "backbone":
            runs.append((name, "the backbone", lambda r: _backbone(r, fitted), None))
        elif name == "design":
            runs.append((name, "what to test next", lambda r: _design(r, fitted, seed), _check_design))
        elif name == "characterise":
            runs.append((name, "the characterisation", lambda r: characterise(r, forcing_hz, wells or "auto"),
                         lambda r: check_harmonic(r, forcing_hz)))  # fmt: skip
    return runs


def _frf_beside_models(rec, fitted: dict[str, Any], options: dict[str, Any]) -> dict[str, Any]:
    """The record's FRFs (``frf``), with the underlying-linear FRF of NSI's state-space model where it was identified
    (a structure read through its sensors): ``_model_frf``, each DOF's at its own frequencies within the model's band
    and Nyquist, drawn over the measured H1 (the model against the data, the lab's first look).
    """
    from negstiff.inference.analysis.frf import frf

    res = frf(rec, **options)
    model = getattr(fitted.get("nsi"), "model_", None)  # a fit in ``fitted`` has one
    if model is None or not hasattr(model, "initial_state") or "_curves" not in res:
        return res
    top = 0.45 / model.dt
    per_dof = []
    for k, c in enumerate(res["_curves"]):
        f = np.asarray(c["f"])
        keep = (f > 0) & (f < top)
        per_dof.append({"f": f[keep], "H": model.frf(f[keep])[:, k]})
    return {**res, "_model_frf": {"label": "NSI's state-space model", "curves": per_dof}}


def _chosen_law(rec, fitted: dict[str, Any], damping: str) -> str:
    """The restoring law the record asks for (``law="auto"``): the one the first identification made chose (NSI's,
    else SINDy's), else NSI's choice made now (every law compared on what it predicts: ``law_choice``).
    """
    from negstiff.inference.estimators.nsi import NSI
    from negstiff.models import laws

    for name in ("nsi", "sindy"):
        law = fitted[name].result_.settings.get("law") if name in fitted else None
        if law in laws.names("restoring"):  # (SINDy's own catalogue is no law)
            return str(law)
    return str(NSI(law="auto", damping=damping, refine=False).fit(rec).result_.settings["law"])


def _interval(rec, fitted: dict[str, Any]) -> dict[str, Any]:
    """The first identification's own estimate with its batch-means standard error (``own_estimate``) over
    three blocks of the record as the identification read it (a hammer's force windowed); a structure's: its element's
    coefficients and every mode of every well, each block identified alone.
    """
    from negstiff.inference.analysis.record_kind import identification_record, record_kind

    for name in ("nsi", "sindy"):
        if name in fitted:
            return fitted[name].own_estimate(identification_record(rec, record_kind(rec)), blocks=3)
    raise InputError(f"{rec.source}: no identification was made, so it has no interval")


REPORT_DESIGN = {"candidates": 16, "draws": 4, "search": 4}
"""The report's test design: a smaller search than ``negstiff design``'s (a tenth of its evaluations: seconds, not a
minute); ``negstiff design`` on the report's posterior searches further."""


def _check_design(rec) -> None:
    from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS, record_kind

    if rec.input_name != "base_acc" and record_kind(rec).kind not in RING_DOWN_KINDS:
        raise InputError(f"{rec.source}: a shaker's force record: the design plans shaker-table tests from a "
                         "base-excited record's posterior, hammer hits and releases from a hammer's or a "
                         "decay's")  # fmt: skip


def _design(rec, fitted: dict[str, Any], seed: int) -> dict[str, Any]:
    """The test to run next (``analysis.design``) from the report's coefficient posterior."""
    from negstiff.inference.analysis.design import design

    post = fitted.get("posterior")
    if post is None:
        raise InputError(f"{rec.source}: no posterior was sampled, so no test can be designed from it")
    return design(post, seed=seed, **REPORT_DESIGN)


BACKBONE_DRAWS = 24
"""Posterior draws whose predicted backbones make the report's credible band."""


def _backbone(rec, fitted: dict[str, Any]) -> dict[str, Any]:
    """The decay's backbone, measured and predicted by the first identification that was made (NSI's, else
    SINDy's, else the posterior mean's), with the credible band of ``BACKBONE_DRAWS`` posterior draws where the
    posterior was sampled.
    """
    from negstiff.inference.analysis.backbone import backbone

    post = fitted.get("posterior")
    draws = post.draw_models(min(BACKBONE_DRAWS, post.result_.samples[..., 0].size)) if post is not None else None
    own = getattr(post, "structure_", None) if post is not None else None
    if draws and own is not None:  # a structure's element draws in the structure the posterior sampled them with
        draws = [own.with_element(d) for d in draws]
    for name, label in (("nsi", "NSI"), ("sindy", "SINDy"), ("posterior", "the posterior mean")):
        if name in fitted:
            # a structure's fit: the identified structure (its element in ``model_``) decays from the record's state
            # less each channel's zero the identification found (``offsets_``)
            model = getattr(fitted[name], "structure_", None) or fitted[name].model_
            offsets = getattr(fitted[name], "offsets_", None) if hasattr(model, "n_dof") else None
            return {**backbone(_last_well(rec, model, offsets), model=model, draws=draws, offsets=offsets),
                    "model_name": f"{label}'s model"}  # fmt: skip
    return backbone(rec)


def _last_well(rec, model, offsets=None):
    """The record from its last crossing of the model's barrier z_0 on (a double well's decay that crossed between
    the wells rings down in the last one; a backbone is a well's), or the record where it never crosses.
    Measured: the seed-like double well released 12 mm beyond its plus well crosses once and rings down in the
    minus well; over the whole record the Hilbert backbone read 2.27 Hz, from the crossing on 11.238 Hz (the well's
    11.240 Hz). A structure's: its element's relative motion, each channel less its zero (``offsets``).
    """
    from negstiff.models.structure import as_structure

    structure = as_structure(model)
    try:
        z0 = structure.element_equilibria().z_0
    except ValueError:
        return rec
    if z0 is None:
        return rec
    o = np.zeros(rec.n_dof) if offsets is None else np.asarray(offsets, float)  # each channel's zero
    side = np.sign(structure.coupling @ (np.asarray(rec.channels) - o[:, None]) - z0)  # the element's relative motion
    crossed = np.flatnonzero(side != side[-1])
    return rec if crossed.size == 0 else rec.segment(int(crossed[-1]) + 1, rec.n)


def _campaign_report(data, columns, fs, forcing_hz, wells, nfrc, chosen, say, gravity=None) -> Report:
    from negstiff.inference.analysis.campaign import Campaign

    campaign = Campaign.read(data, columns, fs, forcing_hz, wells, nfrc, gravity=gravity)
    rep = Report(f"negstiff report: a campaign of {len(campaign.records)} records")
    say(f"report: the bifurcation map of {len(campaign.records)} records ...")
    rep.add(campaign.records[0], label="first record")
    try:
        res = campaign.map(progress=say)
    except InputError as exc:
        return rep.add_failure("the bifurcation map", str(exc))
    from .sections import map_section

    rep.add(map_section(res, campaign.overlays))
    return rep
