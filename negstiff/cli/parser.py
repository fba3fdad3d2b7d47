"""The argument parser: one function per command, each adding its subparser (``build_parser``)."""

from __future__ import annotations

import argparse

from negstiff.io.schema import GRAVITY_RANGE, MAGNITUDE_LIMITS, SAMPLING_RATE_RANGE_HZ
from negstiff.models import effects

from . import commands as c
from .common import POSITIVE, SEED, Parser, acceleration_option, declared, default, mass_option, number

POST = "estimators.posterior.core.Posterior"
NO_REFINE_HELP = (
    "skip the output-error refinement (the last stage: the model's simulation error minimised over the "
    "identification part; kept only if it predicts the held-out part at least as well)"
)

EPILOG_RIG = """examples:
  negstiff rig random -o rec.csv --seed 1            300 s cross-well random record of the as-built device
  negstiff rig random --model m.json -o rec.csv      ... of a polynomial model instead (coefficients known exactly)
  negstiff rig random --effect coulomb_friction=0.05 -o rec.csv   with a hidden extra effect
  negstiff rig harmonic --freq 9 --amplitude 15 -o h.csv          steady-state harmonic response
  negstiff rig campaign --amplitudes 4:30:0.5 --start both --direction both -o campaign/
  negstiff rig campaign --freqs 5:11:0.1 --amplitude 3 --direction both -o nfrc_test/   stepped sine
  negstiff rig hammer --peak 20 --hits 4 --duration 10 -o hit.csv  an impact hammer's test, the table still
  negstiff rig release --z0 0.03 --duration 10 -o decay.csv        a free decay from 30 mm
  negstiff rig hammer --model fixture.json --dof 1 -o hit.csv      a structure hit on its DOF 1
Every record is written with <name>.truth.json beside it (the truth behind the record)."""


def _structure_options(p: argparse.ArgumentParser, element_help: str) -> None:
    """A structure's options of a fitting command: --dofs (a check of the file), --element, --masses."""
    p.add_argument(
        "--dofs",
        type=number(int, 1, 50),
        help="degrees of freedom the record must measure (a check of the file: its responses z1 ... zN and "
        "'# masses: m1,...,mN' give N; N > 1 needs --element)",
    )
    p.add_argument("--element", help=element_help + " (default: the record's '# element: I-J')")
    p.add_argument("--masses", help="the DOFs' masses m1,...,mN [kg] (default: the record's '# masses:')")
    p.add_argument("--force-dof", type=number(int, 1, 50), help=FORCE_DOF_HELP)


FORCE_DOF_HELP = ("a structure's DOF (sensor) the measured force acts on, 1..N (default: the record's '# force_dof:'; "
                  "NSI without masses sizes the element through it)")  # fmt: skip


def _rig(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    rig = sub.add_parser(
        "rig",
        parents=[common],
        help="virtual test rig: records as the reference study's laboratory measures them",
        description="Virtual shaking table with the as-built device (exact geometry), a model or a structure of N "
        "DOFs on it. Records: t, base_acc (accelerometer), y (laser), base_disp (double-integrated), "
        "z = y - base_disp; a structure's: t, base_acc and each DOF's z1 ... zN (or zK_dot, yK, yK_acc by --sensor), "
        "its masses and element in the header.",
        epilog=EPILOG_RIG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    rig.add_argument("mode", choices=["random", "harmonic", "sweep", "campaign", "hammer", "release"])
    rig.add_argument(
        "-o", "--out", required=True, help="record file (.csv, .npz, .uff/.unv, .tdms); for campaign, a folder"
    )
    rig.add_argument(
        "--model",
        help="drive a model JSON (polynomial truth), a device JSON or a structure JSON (masses, element, "
        "at, stiffness, damping; or a structure's identify result) instead of the as-built device",
    )
    rig.add_argument(
        "--effect",
        action="append",
        metavar="NAME=VALUE",
        help=f"hidden extra effect ({', '.join(e.help() for e in effects.REGISTRY)}); repeatable",
    )
    rig.add_argument("--fs", type=number(float, 1.0, 1e6), default=512.0, help="sampling rate [Hz] (default 512)")
    rig.add_argument("--noise-free", action="store_true", help="perfect sensors (no noise, no bias)")
    g = rig.add_argument_group("lab variants (records as other labs write them)")
    g.add_argument(
        "--sensor",
        default="displacement",
        choices=["displacement", "velocity", "absolute", "accelerometer"],
        help="response sensor: displacement (the reference study's laser and double-integrated base: y, base_disp, z), "
        "velocity (a vibrometer relative to the base: z_dot), absolute (the laser's y only), accelerometer "
        "(on the moving part: y_acc)",
    )
    g.add_argument(
        "--response-offset",
        type=number(float),
        default=0.0,
        help="DC offset of the response sensor in its units (m, m/s or m/s^2; default 0)",
    )
    g.add_argument("--time-decimals", type=number(int, 0, 12), help="print the time column with N fixed decimals (CSV)")
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
    g.add_argument("--duration", type=number(float, 1.0, 1e5), default=None,
                   help="record length [s] (default 300; a hammer's or release's: 10)")  # fmt: skip
    g.add_argument(
        "--rms",
        type=acceleration_option(),
        default=14.0,
        help="table acceleration rms [m/s^2] (default 14: cross-well)",
    )
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
        "--amplitude",
        type=acceleration_option(lo_open=False),
        default=5.0,
        help="table acceleration amplitude [m/s^2] (harmonic)",
    )
    g.add_argument(
        "--amplitudes", default="4:30:0.5", help="campaign amplitudes start:stop:step or a list (default 4:30:0.5)"
    )
    g.add_argument(
        "--freqs",
        help="a stepped-sine campaign in frequency instead, at --amplitude: start:stop:step or a list [Hz] "
        "(each step --settle-periods and --periods of its own period)",
    )
    g.add_argument("--start", default="plus", choices=["plus", "minus", "both"], help="starting well (default plus)")
    g.add_argument("--direction", default="up", choices=["up", "down", "both"], help="campaign sweep direction")
    g.add_argument(
        "--settle-periods",
        type=number(int, 0, 10**6),
        default=100,
        help="forcing periods discarded per step (default 100)",
    )
    g.add_argument(
        "--periods", type=number(int, 1, 10**6), default=100, help="forcing periods recorded per step (default 100)"
    )
    g = rig.add_argument_group("hammer and release (the table still; --duration, --start too)")
    g.add_argument("--peak", type=POSITIVE, default=20.0, help="a hit's peak force [N] (default 20)")
    g.add_argument("--hits", type=number(int, 1, 10**4), default=4, help="hits, evenly spread (default 4)")
    g.add_argument("--width", type=POSITIVE, default=0.004, help="a hit's duration [s] (a half-sine; default 0.004)")
    g.add_argument("--dof", type=number(int, 1, 50), help="a structure's DOF the hammer hits (default: the element's)")
    g.add_argument(
        "--z0", type=number(float), help="release: where the moving part is held [m] (a structure's element)"
    )
    rig.set_defaults(func=c.cmd_rig)


def _simulate(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
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
    sim.add_argument("--z0", type=number(float), help="initial z [m]")
    sim.add_argument("--v0", type=number(float), help="initial z_dot [m/s]")
    sim.add_argument(
        "--aux",
        help="measured auxiliary channels of INPUT (default: those the model's aux:NAME terms name), by the file's "
        "column names",
    )
    sim.add_argument(
        "--substeps",
        type=number(int, 1, 64),
        help="RK4 steps per sample interval (default: 2, more where the model is fast for the sampling rate)",
    )
    sim.add_argument(
        "--interpolation",
        choices=("band-limited", "linear"),
        default="band-limited",
        help="the input between samples: band-limited (a record through an anti-aliasing filter; default) "
        "or linear (a piecewise-linear drive)",
    )
    sim.set_defaults(func=c.cmd_simulate)


DECAY_HELP = (
    "the record is a free decay whatever its input column holds (a force channel left connected that "
    "reads only its noise); a constant input is one without saying so"
)


def _law_options(p: argparse.ArgumentParser) -> None:
    """--law and --damping: the restoring and the damping law (``models.laws``) a fit reads."""
    from negstiff.models import laws

    p.add_argument(
        "--law",
        choices=[*laws.names("restoring"), "auto"],
        help="the restoring-force law: " + "; ".join(f"{law.name}: {law.title}" for law in laws.LAWS
                                                     if law.kind == "restoring")
        + "; auto: every law fitted and the one that predicts the record best kept (the comparison in the result's "
        "law_choice). Default: the method's own (NSI the cubic, SINDy its sparse catalogue), the other laws "
        "compared where it fails its checks",
    )  # fmt: skip
    p.add_argument(
        "--damping",
        choices=list(laws.names("damping")),
        default=laws.DEFAULT_DAMPING,
        help="the damping law with --law: " + "; ".join(f"{law.name}: {law.title}" for law in laws.LAWS
                                                         if law.kind == "damping")
        + f" (default {laws.DEFAULT_DAMPING})",
    )  # fmt: skip


def _discrepancy_law_options(p: argparse.ArgumentParser) -> None:
    """The discrepancy workflow's --law, --damping and --no-laws (``Discrepancy(law=, damping=, offer_laws=)``)."""
    from negstiff.models import laws

    p.add_argument(
        "--law",
        choices=[*laws.names("restoring"), "auto"],
        help="the baseline's restoring-force law (its columns at the record's shape): "
        + "; ".join(f"{law.name}: {law.title}" for law in laws.LAWS if law.kind == "restoring")
        + "; auto: the law the record asks for, chosen as identify chooses it (the comparison in the result's "
        "baseline_law.choice). Default: --baseline's terms",
    )  # fmt: skip
    p.add_argument(
        "--damping",
        choices=list(laws.names("damping")),
        help="the baseline's damping law: " + "; ".join(f"{law.name}: {law.title}" for law in laws.LAWS
                                                         if law.kind == "damping")
        + f" (default: --baseline's own without --law, {laws.DEFAULT_DAMPING} with it)",
    )  # fmt: skip
    p.add_argument(
        "--no-laws",
        action="store_true",
        help="offer no restoring law as a candidate (by default, where the baseline's restoring force is a law, the "
        "cubic's or --law's, every other law is offered beside the catalogue's effects, named law:NAME: it replaces "
        "the restoring force rather than adding a term; --baseline linear is built up by the catalogue's terms)",
    )


def _identify(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    idf = sub.add_parser(
        "identify",
        parents=[common, data_opts],
        help="identify K and D (and modal parameters) from a record",
        description="nsi: nonlinear subspace identification around both stable wells (reference study section 4): "
        "modal "
        "parameters of each underlying-linear system, the z-frame cubic restoring force and damping. sindy: weak-form "
        "sparse regression over 1, z..z^5, z', z'|z'|, z'^3, sgn(z') with the input's coefficient fixed by physics, "
        "terms selected by held-out residual, ensemble inclusion probabilities. Both: equilibria, modal parameters "
        "and a free-run validation over the held-out last 20 %.",
    )
    idf.add_argument("method", choices=["nsi", "sindy"], help="identification method")
    idf.add_argument(
        "--no-refine",
        action="store_true",
        help=NO_REFINE_HELP,
    )
    idf.add_argument("data", help="measurement file")
    idf.add_argument("-o", "--out", required=True, help="result JSON")
    idf.add_argument("--decay", action="store_true", help=DECAY_HELP)
    idf.add_argument(
        "--mass", type=mass_option(), help="moving mass [kg] (default: the file's metadata; else per unit mass)"
    )
    idf.add_argument(
        "--aux",
        help="measured auxiliary channels, by the file's column names (e.g. voltage): SINDy offers each as a term "
        "theta a(t), named aux:NAME (NSI does not use them, and says so)",
    )
    idf.add_argument(
        "--order",
        type=declared("estimators.nsi.NSI", "order", what=" (the state dimension: 2 per mode)"),
        default=default("estimators.nsi.NSI", "order"),
        help=f"NSI model order (default {default('estimators.nsi.NSI', 'order')}: one mode)",
    )
    idf.add_argument(
        "--block-rows",
        type=declared("estimators.nsi.NSI", "block_rows"),
        default=default("estimators.nsi.NSI", "block_rows"),
        help=f"NSI: block rows of the Hankel matrices (default {default('estimators.nsi.NSI', 'block_rows')})",
    )
    idf.add_argument(
        "--ensemble",
        type=declared("estimators.sindy.SINDy", "n_models"),
        default=default("estimators.sindy.SINDy", "n_models"),
        help=f"SINDy: bagged models of the ensemble (default {default('estimators.sindy.SINDy', 'n_models')})",
    )
    _law_options(idf)
    idf.add_argument(
        "--frf",
        action="append",
        metavar="R.json",
        help="an frf result of a low-level test around a well: its peak beside the identified well frequency "
        "(repeatable, one per well); a structure's: each of its modes beside the identified mode nearest it",
    )
    _structure_options(idf, "where the nonlinear element acts, I-J: it moves DOF J relative to DOF I (0: the base), "
                       "e.g. 1-2 for a device on a fixture")  # fmt: skip
    idf.set_defaults(func=c.cmd_identify)


def _frf(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    frq = sub.add_parser(
        "frf",
        parents=[common, data_opts],
        help="H1/H2 frequency response with coherence, modal fit of the peaks",
        description="Frequency response of a (low-level) record from its input to z: H1 and H2 with the coherence "
        "(Welch, Hann, 50 % overlap), every resonance peak fitted by a single-degree-of-freedom receptance "
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
        type=number(float, 0.5, 1e4),
        help="Welch segment [s] (default 16 s, longer where a lightly damped peak needs finer bins)",
    )
    frq.add_argument(
        "--dofs",
        type=number(int, 1, 50),
        help="degrees of freedom the record must measure (a check of the file; a structure's record, z1 ... zN, "
        "gives the FRF to every DOF, modes merged)",
    )
    frq.set_defaults(func=c.cmd_frf)


def _backbone(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    bb = sub.add_parser(
        "backbone",
        parents=[common, data_opts],
        help="backbone curves (frequency and damping against amplitude) of a free decay, measured and predicted",
        description="The free decay after the record's input falls silent (a release, a hammer's last hit, a shaker "
        "switched off; an input at its floor throughout is a decay from the start): its instantaneous frequency and "
        "damping ratio against amplitude by the Hilbert transform of the band-passed response, with the "
        "peak-to-peak cycles as a cross-check; with --model, the model's free decay from the record's state "
        "measured alike. Writes OUT.json and OUT.png.",
    )
    bb.add_argument("data", help="measurement file (a force or base_acc column, silent after the release)")
    bb.add_argument("--model", help="model file (JSON): its predicted backbone beside the measured one")
    bb.add_argument("--mass", type=mass_option(), help="moving mass [kg] (default: the file's '# mass:')")
    bb.add_argument("--dof", type=number(int, 1, 50), help="a structure's channel whose backbone is measured, "
                    "1..N (default: the one whose decay moves most)")  # fmt: skip
    bb.add_argument("--band", help="the band-pass F1:F2 [Hz] (default: around the mode that dominates the channel; "
                    "another mode's band reads that mode's backbone)")  # fmt: skip
    bb.add_argument("-o", "--out", required=True, help="result JSON (the figure beside it, .png)")
    bb.add_argument("--decay", action="store_true", help=DECAY_HELP)
    bb.set_defaults(func=c.cmd_backbone)


def _nfrc(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    nf = sub.add_parser(
        "nfrc",
        parents=[common],
        help="continue a model's periodic response in amplitude or frequency, with stability and bifurcations",
        description="Periodic orbits of MODEL under b'' = A sin(2 pi f t) (or a force A sin(2 pi f t)), continued "
        "in A at a fixed f (--freq F --amplitude A1:A2: the reference study's bifurcation-map axis) or in f at a "
        "fixed A "
        "(--freq F1:F2 --amplitude A: a nonlinear frequency response curve), by shooting and pseudo-arclength "
        "through folds; Floquet multipliers give the stability, folds, period doublings (whose doubled branches "
        "are followed) and Neimark-Sacker points. Writes R.json and R.png.",
    )
    nf.add_argument("model", help="model JSON (polynomial, named effects) or device JSON, or an identify result")
    nf.add_argument("--freq", required=True, help="forcing frequency F [Hz], or a range F1:F2")
    nf.add_argument("--amplitude", required=True, help="forcing amplitude A [m/s^2, or N], or a range A1:A2")
    nf.add_argument("--well", choices=["plus", "minus"], default="plus", help="well the continuation starts in")
    nf.add_argument("--input", choices=["base_acc", "force"], default="base_acc", help="what A is (default base_acc)")
    nf.add_argument("--max-period", type=number(int, 1, 64), default=4, help="follow doublings up to this period")
    nf.add_argument("-o", "--out", required=True, help="result JSON (the figure beside it, .png)")
    nf.set_defaults(func=c.cmd_nfrc)


def _posterior(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    pst = sub.add_parser(
        "posterior",
        parents=[common, data_opts],
        help="Bayesian posterior (emcee) of the coefficients or the device parameters",
        description="emcee posterior with a multiple-shooting output-error likelihood (short windows simulated "
        "from measured states, start states profiled out, sensor noise sigma sampled). coefficients: k1, k2, k3, c, "
        "c_nl, sigma (mass fixed: --mass, the file's metadata, or per unit mass). device: E, alpha, m, c, c_nl, "
        "sigma with the exact geometric restoring force; --mass-prior weighed (N(m, 2 %)) or free (shows the E-m "
        "ridge). R-hat across independent ensembles, bulk/tail ESS, autocorrelation times; a run that does not "
        "converge is reported with a warning in the result.",
    )
    pst.add_argument(
        "data",
        nargs="+",
        help="measurement file; several: records of one device fitted together "
        "(the device's parameters shared, each record its own sensor noise sigma_1, sigma_2, ...)",
    )
    pst.add_argument("--decay", action="store_true", help=DECAY_HELP)
    pst.add_argument("-o", "--out", required=True, help="result JSON")
    pst.add_argument("--mass", type=mass_option(), help="moving mass [kg] (default: the file's metadata)")
    pst.add_argument("--model", choices=["coefficients", "device"], default=default(POST, "model"))
    pst.add_argument(
        "--mass-prior",
        choices=["weighed", "free"],
        default=default(POST, "mass_prior"),
        help="device model: mass prior",
    )
    pst.add_argument("--idata", help="save the arviz data (posterior, sample stats, log likelihood) as NetCDF")
    pst.add_argument(
        "--chain-file",
        metavar="F.h5",
        help="save each ensemble's emcee chain to this HDF5 file as it runs (a long run that stops keeps its steps)",
    )
    pst.add_argument(
        "--resume",
        action="store_true",
        help="continue the chains saved in --chain-file by a run of the same record, settings and --seed",
    )
    pst.add_argument(
        "--start",
        help="coefficients: an identify result (its refined model) or a model file the MAP search starts from "
        "(default: weak-form least squares of the record, refined by simulation error); on a structure's record a "
        "structure's identify result (its structure and channel zeros) or structure file (default: SINDy's)",
    )
    pst.add_argument(
        "--no-refine",
        action="store_true",
        help="coefficients without --start: start the MAP search from the weak-form estimate itself, not its "
        "output-error refinement",
    )
    pst.add_argument("--duration", type=POSITIVE, help="use only the first DURATION seconds of the record")
    pst.add_argument(
        "--window",
        type=declared(POST, "window_s"),
        default=default(POST, "window_s"),
        help=f"multiple-shooting window [s] (default {default(POST, 'window_s')})",
    )
    pst.add_argument(
        "--max-windows",
        type=declared(POST, "max_windows"),
        default=default(POST, "max_windows"),
        help=f"windows used at most, spread over the record (default {default(POST, 'max_windows')})",
    )
    pst.add_argument(
        "--walkers",
        type=declared(POST, "n_walkers", what=" (emcee: twice the 7 dimensions of the device model, at least)"),
        default=default(POST, "n_walkers"),
        help=f"walkers per ensemble (default {default(POST, 'n_walkers')})",
    )
    pst.add_argument(
        "--ensembles",
        type=declared(POST, "n_ensembles"),
        default=default(POST, "n_ensembles"),
        help=f"independent ensembles (default {default(POST, 'n_ensembles')})",
    )
    pst.add_argument(
        "--max-steps",
        type=declared(POST, "max_steps"),
        default=default(POST, "max_steps"),
        help=f"step cap per ensemble (default {default(POST, 'max_steps')})",
    )
    pst.add_argument(
        "--hdi-prob",
        type=declared(POST, "hdi_prob"),
        default=default(POST, "hdi_prob"),
        help=f"credible-interval probability (default {default(POST, 'hdi_prob')})",
    )
    pst.add_argument(
        "--no-adjust",
        action="store_true",
        help="no curvature adjustment: the i.i.d. Gaussian likelihood as it stands (narrower, overconfident "
        "intervals when the input is measured with noise)",
    )
    pst.add_argument(
        "--input-noise",
        # the declared range, capped where no record's input reaches (its noise beyond is no measurement)
        type=number(float, declared(POST, "input_noise").lo, MAGNITUDE_LIMITS["force"], what=" (m/s^2 or N)"),
        default=default(POST, "input_noise"),
        help="the input sensor's white noise rms [m/s^2, or N for a force] (default: read from the input's spectral "
        "floor above the excitation's band; 0: the input taken as exact)",
    )
    from negstiff.models import laws

    pst.add_argument(
        "--law",
        choices=list(laws.names("restoring")),
        help="sample a restoring-force law's parameters (every base field it frees and every parameter of its parts: "
        "a magnet's A and d, a spline's coefficients over the record's knots, the rod frame's k_f, D0, L, alpha), "
        "about its deterministic fit; the result adds the force's credible band over the stroke (force_band): "
        + "; ".join(f"{law.name}: {law.title}" for law in laws.LAWS if law.kind == "restoring")
        + ". Default: the coefficient or device model (--model)",
    )  # fmt: skip
    pst.add_argument(
        "--damping",
        choices=list(laws.names("damping")),
        help="the damping law sampled with --law (default quadratic; without --law: the cubic with this damping): "
        + "; ".join(f"{law.name}: {law.title}" for law in laws.LAWS if law.kind == "damping"),
    )  # fmt: skip
    _structure_options(pst, "a structure's record: where the nonlinear element acts, I-J (it moves DOF J relative "
                       "to DOF I, 0: the base); its coefficients are sampled, each channel's zero and the linear "
                       "structure's springs and dampers with them (nuisances, from SINDy's)")  # fmt: skip
    pst.set_defaults(func=c.cmd_posterior)


def _discrepancy(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    dsc = sub.add_parser(
        "discrepancy",
        parents=[common, data_opts],
        help="find where model and data disagree, name the missing effect, add it, refit",
        description="Fits the baseline (cubic K, viscous c and c_nl; a linear K; or a law, --law), locates its "
        "equation error over the state and the regimes, scores a catalogue of effects "
        f"({', '.join(e.name for e in effects.REGISTRY if e.catalogued)}, none) and the other restoring laws "
        "(law:NAME, each in place of the restoring force) by held-out weak residual, adds the winner, refits "
        "everything, repeats until none wins, and measures the held-out gap (restarted free runs) before and after.",
    )
    dsc.add_argument("data", help="measurement file")
    dsc.add_argument("-o", "--out", required=True, help="result JSON")
    dsc.add_argument("--mass", type=mass_option(), help="moving mass [kg] (default: the file's metadata)")
    dsc.add_argument(
        "--aux",
        help="measured auxiliary channels, by the file's column names (e.g. voltage): each a candidate term theta "
        "a(t) beside the catalogue's effects, named aux:NAME",
    )
    dsc.add_argument("--baseline", choices=["cubic", "linear"], default="cubic",
                     help="starting model without --law: the seed's (cubic K, c and c_nl) or a linear one")  # fmt: skip
    _discrepancy_law_options(dsc)
    dsc.add_argument("--decay", action="store_true", help=DECAY_HELP)
    dsc.add_argument(
        "--max-effects",
        type=declared("estimators.discrepancy.Discrepancy", "max_effects"),
        default=default("estimators.discrepancy.Discrepancy", "max_effects"),
        help=f"effects added at most (default {default('estimators.discrepancy.Discrepancy', 'max_effects')})",
    )
    dsc.add_argument(
        "--no-refine",
        action="store_true",
        help=NO_REFINE_HELP,
    )
    dsc.add_argument(
        "--unnamed",
        action="store_true",
        help="also fit a non-parametric force g(z, z', u) to what no catalogue effect names (output error, the "
        "final model held) and report its size, the held-out gap with it, and how far it would move the physical "
        "coefficients (result key 'unnamed'; a structure's: on its element's relative motion, in 'details')",
    )
    _structure_options(dsc, "a structure's record: where the nonlinear element acts, I-J (it moves DOF J relative "
                       "to DOF I, 0: the base); the effects are offered to its law, round after round")  # fmt: skip
    dsc.set_defaults(func=c.cmd_discrepancy)


def _characterise(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    chz = sub.add_parser(
        "characterise",
        aliases=["characterize"],  # the contract's first spelling, kept: a script that ran keeps running
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
    chz.add_argument("--element", help="a structure's element I-J: its relative displacement is analysed (default: "
                     "the file's '# element:')")  # fmt: skip
    chz.add_argument("--dof", type=number(int, 1, 50), help="a structure's channel zK analysed instead")
    chz.add_argument(
        "--wells",
        help="z_minus,z_plus (or z_minus,z_0,z_plus) [m]; default: the file's rest positions, "
        "else estimated from the data",
    )
    chz.add_argument("-o", "--out", required=True, help="result JSON")
    chz.set_defaults(func=c.cmd_characterise)


def _map(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    mp = sub.add_parser(
        "map",
        parents=[common, data_opts],
        help="the bifurcation map of a stepped harmonic campaign (reference study Figure 4), with continuations "
        "over it",
        description="Every record of a stepped harmonic campaign (files in the order given, or a folder: its "
        "index.json, as `negstiff rig campaign` writes it, else its measurement files by name) analysed for its "
        "period, regime and Poincare z (phase 0), against the forcing amplitude measured from its input (a "
        "campaign at one frequency: the reference study's map) or against its frequency (a stepped sine: each record's "
        "frequency from the index, its metadata's forcing_hz or --forcing-hz). Each sweep's sequence and first "
        "period 2, or where a stepped sine jumps; `negstiff nfrc` results along the same axis drawn over the map, "
        "their first doubling or folds beside the map's. Writes R.json and R.png.",
    )
    mp.add_argument("data", nargs="+", help="measurement files of the campaign, or its folder")
    mp.add_argument(
        "--forcing-hz", type=POSITIVE, help="forcing frequency [Hz] (default: the index's or each record's metadata)"
    )
    mp.add_argument(
        "--wells",
        help="z_minus,z_plus (or z_minus,z_0,z_plus) [m] for the regime; default: the records' rest positions",
    )
    mp.add_argument("--nfrc", action="append", help="a `negstiff nfrc` result to draw over the map (repeatable)")
    mp.add_argument("-o", "--out", required=True, help="result JSON (the figure beside it, .png)")
    mp.set_defaults(func=c.cmd_map)


def _design(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    dsg = sub.add_parser(
        "design",
        parents=[common],
        help="the test to run next: candidate tests ranked by how much they would narrow the posterior",
        description="Rank the tests the rig can run next (random at a level, a harmonic at an amplitude and "
        "frequency, a linear sine sweep at an amplitude), within the limits given, by the expected shrinkage of the "
        "targeted parameters' 90 % intervals: the posterior's draws run through each candidate on the virtual rig "
        "with the record's noise, each simulated record read as the posterior reads one (Laplace approximation of "
        "the expected posterior covariance). The grid's best candidates are searched further in their level and "
        "frequency. POSTERIOR is a coefficient posterior of a base-excited record (negstiff posterior ... -o); of a "
        "hammer's record or a free decay, hammer hits (peak force, hit count) and releases from a held position "
        "are ranked instead.",
    )
    dsg.add_argument("posterior", help="posterior result JSON")
    dsg.add_argument("-o", "--out", required=True, help="design result JSON (a figure of the criterion beside it)")
    dsg.add_argument("--target", help="the parameters to pin down, comma-separated among k1,k2,k3,c,c_nl "
                     "(default: all)")  # fmt: skip
    dsg.add_argument("--duration", type=POSITIVE, help="the next record's length [s] (default: the posterior's "
                     "record's)")  # fmt: skip
    dsg.add_argument("--max-acc", type=POSITIVE, help="the table's peak acceleration [m/s^2] (default 80; a "
                     "base-excited record's posterior)")  # fmt: skip
    dsg.add_argument("--max-force", type=POSITIVE, help="the hammer's peak force [N] (a hammer's or a decay's "
                     "posterior; default: no limit)")  # fmt: skip
    dsg.add_argument("--table-stroke", type=POSITIVE, help="the table's peak displacement [m] (default: no limit)")
    dsg.add_argument("--stroke", type=POSITIVE, help="the device's travel from its saddle to a stop [m]: a test that "
                     "reaches it is infeasible (default: no stop)")  # fmt: skip
    dsg.add_argument("--sensor-range", type=POSITIVE, help="the displacement sensor's measuring range [m]: a test "
                     "whose reading (the device's and the table's motion) spans more is infeasible (default: no "
                     "range)")  # fmt: skip
    dsg.add_argument("--candidates", type=number(int, 4), help="grid candidates (default 50)")
    dsg.add_argument("--draws", type=number(int, 1), help="posterior draws per candidate (default 16)")
    dsg.add_argument("--separate", metavar="DISCREPANCY.json", help="instead, the test that tells apart the two "
                     "effects the discrepancy workflow ranked first on the first record (its result JSON): random "
                     "tests ranked by the information the workflow's verdict carries about which is "
                     "present")  # fmt: skip
    dsg.set_defaults(func=c.cmd_design)


def _update(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    upd = sub.add_parser(
        "update",
        parents=[common],
        help="GA model updating of the device's E, frame angle and mass",
        description="Update the physical device (E, alpha, m, from the nominal design) with a genetic algorithm so "
        "that its well frequencies and equilibria match TARGETS (reference study section 4.1, Eq. 9). TARGETS is an "
        "'identify' result or a JSON with f_minus, f_plus [Hz], z_minus, z_plus [m]. The features depend on E "
        "and m only through E/m: with the mass free the result is one point of a ridge; --fix-mass pins E.",
    )
    upd.add_argument("targets", help="identify result JSON or targets JSON")
    upd.add_argument("-o", "--out", required=True, help="result JSON")
    upd.add_argument(
        "--fix-mass",
        type=declared("estimators.updating.GAUpdater", "fixed_mass"),
        help="weighed moving mass [kg]: update E and alpha only",
    )
    ga = "estimators.updating.GAUpdater"
    upd.add_argument(
        "--generations",
        type=declared(ga, "generations"),
        default=default(ga, "generations"),
        help=f"GA generations (default {default(ga, 'generations')})",
    )
    upd.add_argument(
        "--pop-size",
        type=declared(ga, "pop_size"),
        default=default(ga, "pop_size"),
        help=f"GA population (default {default(ga, 'pop_size')})",
    )
    upd.set_defaults(func=c.cmd_update)


def _report(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    rp = sub.add_parser(
        "report",
        parents=[common, data_opts],
        help="the study on your own record: every analysis that fits it, as one report",
        description="A report of a record (or of a stepped campaign: several files, or a folder): what the record "
        "is decides what is run. A broadband record: NSI around each well it visited, SINDy, the coefficient "
        "posterior, the discrepancy workflow and the FRF (a structure's record, z1 ... zN, with its element's place: "
        "each read as the estimators read it); a harmonic record (its input one spectral line, or "
        "--forcing-hz): the characterisation; a campaign: the bifurcation map, with --nfrc results over it. The "
        "report opens with a summary and a table of contents, the record (sensor, derivation, frame, warnings), one "
        "table of every coefficient with each method's estimate beside the posterior's mean and credible interval "
        "(and a forest plot), and the held-out prediction errors against the record's noise floor. An analysis "
        "that cannot be made is shown in its place with the reason. Writes FOLDER/index.html, index.md, results.json.",
    )
    rp.add_argument("data", nargs="+", help="measurement file, or a campaign's files or folder")
    rp.add_argument("-o", "--out", required=True, help="report folder (index.html, index.md, results.json, figures)")
    rp.add_argument("--decay", action="store_true", help=DECAY_HELP + " (a single record)")
    rp.add_argument("--mass", type=mass_option(), help="moving mass [kg] (default: the file's metadata)")
    rp.add_argument("--element", help="a structure's record (z1 ... zN): where the nonlinear element acts, I-J (it "
                    "moves DOF J relative to DOF I, 0: the base; default: the file's '# element:')")  # fmt: skip
    rp.add_argument("--masses", help="a structure's DOF masses m1,...,mN [kg] (default: the file's '# masses:')")
    rp.add_argument("--force-dof", type=number(int, 1, 50), help=FORCE_DOF_HELP)
    rp.add_argument(
        "--aux",
        help="measured auxiliary channels of the record, by the file's column names (e.g. voltage): SINDy and the "
        "discrepancy workflow offer each as a term theta a(t), named aux:NAME",
    )
    rp.add_argument("--forcing-hz", type=POSITIVE, help="forcing frequency [Hz] of a harmonic record or campaign")
    rp.add_argument("--wells", help="z_minus,z_plus [m] for the regime of a harmonic record (default: the metadata's)")
    rp.add_argument("--nfrc", action="append", help="a `negstiff nfrc` result to draw over a campaign's map")
    rp.add_argument("--only", help="the analyses to run, comma-separated (nsi, sindy, posterior, design, discrepancy, "
                    "frf, characterise, map; design runs the posterior it reads)")  # fmt: skip
    _law_options(rp)
    rp.add_argument("--duration", type=POSITIVE, help="posterior: use only the first DURATION seconds of the record")
    rp.add_argument("--max-steps", type=declared(POST, "max_steps"), help="posterior: step cap per ensemble")
    rp.add_argument("--ensembles", type=declared(POST, "n_ensembles"), help="posterior: independent ensembles")
    rp.add_argument(
        "--max-effects",
        type=declared("estimators.discrepancy.Discrepancy", "max_effects"),
        help="discrepancy: effects added at most",
    )
    rp.set_defaults(func=c.cmd_report)


def _reproduce(sub, common: argparse.ArgumentParser, data_opts: argparse.ArgumentParser) -> None:
    rep = sub.add_parser(
        "reproduce",
        parents=[common],
        help="the whole study, end to end, as one report",
        description="Run the reference study (Anastasio et al., EURODYN 2020) on the virtual rig and write "
        "index.md, index.html and results.json, showing progress per section.",
    )
    rep.add_argument(
        "-o",
        "--out",
        default="reports/latest",
        help="report folder (default reports/latest, not tracked by git; the committed reference report is "
        "reports/paper, rewritten only when asked: -o reports/paper)",
    )
    rep.add_argument("--fast", action="store_true", help="a quick reduced run (minutes)")
    rep.add_argument(
        "--workers",
        type=number(int, 1, 256),
        default=None,
        help="processes computing the report's sections at once (default: the machine's cores, at most one per "
        "section and per 2 GB of memory)",
    )
    rep.set_defaults(func=c.cmd_reproduce)


class _Listed(Exception):
    """Raised by ``_ListingOnly.add_parser``: the command is listed, its options are not built."""


class _ListingOnly:
    """The subparsers' stand-in for a command that is not run: ``add_parser`` registers the command (its name
    and one-line help, for ``negstiff --help`` and argparse's choice) and stops its builder there, before its
    options' declared ranges import the estimators they name.
    """

    def __init__(self, sub):
        self.sub = sub

    def add_parser(self, name, **kw):
        self.sub.add_parser(name, help=kw.get("help"), aliases=kw.get("aliases", ()), add_help=False)
        raise _Listed


COMMANDS = ("rig", "simulate", "identify", "frf", "backbone", "nfrc", "posterior", "design", "discrepancy",
            "characterise", "map", "update", "report", "reproduce")  # fmt: skip
"""Every command, in the order ``negstiff --help`` lists them."""


ALIASES = {"characterize": "characterise"}
"""Other spellings of a command's name that run it (the contract's first spellings; negstiff spells British)."""


def command_of(argv) -> str | None:
    """The command ``argv`` runs (its first word that is a command's name or an alias of one), or None."""
    return next((ALIASES.get(a, a) for a in argv if a in COMMANDS or a in ALIASES), None)


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser. ``only``: build the options of that command alone (the others listed by
    name and help), so a command pays for the imports its own options need and ``negstiff --help`` for none;
    "" builds no command's options; None (default) builds every command's (the tests introspect them).
    """
    common = Parser(add_help=False)
    common.add_argument(
        "--seed", type=SEED, default=0, help="random seed of every random draw (same random seed, same numbers)"
    )
    common.add_argument("--quiet", action="store_true", help="no progress on stderr")

    p = Parser(
        prog="negstiff",
        description="Identify, update and quantify the uncertainty of nonlinear (bistable, negative-stiffness) "
        "oscillators from shaker-table records. Units are SI; see 'negstiff COMMAND --help'.",
    )
    from negstiff import __version__

    p.add_argument("--version", action="version", version=f"negstiff {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    # options of every command that reads a measurement file
    data_opts = Parser(add_help=False)
    data_opts.add_argument(
        "--columns",
        help="column map for foreign files, e.g. force=V1,z=V2 (a map entry may scale: X*9.81; a "
        "response of unknown sensitivity: z_dot=LDV*?, its scale estimated from the record's dynamics)",
    )
    data_opts.add_argument(
        "--fs",
        type=number(float, *SAMPLING_RATE_RANGE_HZ, what=" Hz"),
        help="sampling rate [Hz]; replaces the file's time column (for files without t, or a broken one)",
    )
    data_opts.add_argument(
        "--gravity",
        type=number(float, *GRAVITY_RANGE, what=" m/s^2"),
        help="gravity along the device's motion [m/s^2] (default: the file's '# gravity:', else 9.81); 0 for a "
        "horizontal device (a harvester): its frame is then pinned by its wells' symmetry or rest positions",
    )

    builders = {"rig": _rig, "simulate": _simulate, "identify": _identify, "frf": _frf, "backbone": _backbone,
                "nfrc": _nfrc, "posterior": _posterior, "design": _design, "discrepancy": _discrepancy,
                "characterise": _characterise,
                "map": _map, "update": _update, "report": _report, "reproduce": _reproduce}  # fmt: skip
    extra = [name for name in builders if name not in COMMANDS]
    assert not extra, f"commands missing from COMMANDS: {extra}"
    for name in COMMANDS:
        try:
            builders[name](sub if only is None or only == name else _ListingOnly(sub), common, data_opts)
        except _Listed:
            pass
    return p
