"""Which test next, checked against reality: the designed test run on the rig and fitted jointly with the first
record, against the rig's default random test of the same duration; and the design's time against solving each
draw through each candidate with scipy's ``solve_ivp``.

    python -m benchmarks.benchmarks --only design

On 20 s rig records of the polynomial truth under the rig's default random test (5 seeds): the first record's
posterior, ``design`` over the five coefficients (its defaults: 50 grid candidates, 8 draws), the first-ranked test
and the default test each run on the rig (seed 100 + s) and fitted jointly with the first record. The shrinkage of a
test is the geometric mean over the coefficients of the 90 % width before / after.
"""

from __future__ import annotations

import sys
import time

import numpy as np

SEEDS = (1, 2, 3, 4, 5)
DURATION = 20.0


def design_check(seeds=SEEDS, duration: float = DURATION) -> dict:
    """The realised check (module docstring): per seed the chosen test, its predicted and realised widths, the
    default test's realised widths, and the design's time.
    """
    from negstiff.inference.analysis.design import DEFAULT_RANDOM_RMS, Candidate, design
    from negstiff.inference.estimators.posterior import Posterior
    from negstiff.inference.record.measurement import Measurement
    from negstiff.models import SEED_LIKE_CUBIC
    from negstiff.models.rig import Rig

    rows = []
    for seed in seeds:
        first = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=seed).random(duration=duration, rms=DEFAULT_RANDOM_RMS))
        post = Posterior(seed=0).fit(first).result()
        t0 = time.perf_counter()
        plan = design(post, seed=0)
        t_design = time.perf_counter() - t0
        best = plan["best"]
        chosen = Candidate(best["kind"], best.get("rms_m_s2") or best["amplitude_m_s2"], best.get("freq_hz"))
        row = {"seed": seed, "design_s": t_design, "evaluated": plan["search"]["evaluated"], "test": best["test"],
               "draws": plan["search"]["draws"],
               "now": plan["now"], "predicted": best["predicted_width"],
               "predicted_default": plan["default_test"]["predicted_width"]}  # fmt: skip
        for name, test in (("designed", chosen), ("default", Candidate("random", DEFAULT_RANDOM_RMS))):
            nexts = [Measurement.from_rig(r) for r in test.records(Rig(SEED_LIKE_CUBIC, seed=100 + seed), duration)]
            joint = Posterior(seed=0).fit([first, *nexts]).result()["parameters"]
            row[name] = {k: joint[k]["hdi_high"] - joint[k]["hdi_low"] for k in plan["now"]}
            row[name + "_truth_inside"] = int(sum(joint[k]["hdi_low"] <= getattr(SEED_LIKE_CUBIC, k)
                                                  <= joint[k]["hdi_high"] for k in plan["now"]))  # fmt: skip
        row["shrink_designed"] = _shrink(row["now"], row["designed"])
        row["shrink_default"] = _shrink(row["now"], row["default"])
        rows.append(row)
        print(f"design check: seed {seed}, {row['test']}: {row['shrink_designed']:.3g}x against "
              f"{row['shrink_default']:.3g}x", file=sys.stderr)  # fmt: skip
    return {"rows": rows, "solve_ivp": _solve_ivp_equivalent(rows)}


def separation_check(seeds=SEEDS, friction: float = 0.02, duration: float = 24.0) -> dict:
    """Which test tells two effects apart, checked against reality: on rig records of the polynomial truth with a
    hidden Coulomb friction (``friction`` N) under the default random test, the posterior and the discrepancy
    workflow on the first record, ``separation`` between its first two ranked effects, then the chosen test and the
    default test each run on the rig (seed 100 + s) and read by the workflow: what each names.
    """
    import dataclasses

    from negstiff import Discrepancy
    from negstiff.inference.analysis.design import DEFAULT_RANDOM_RMS, Candidate
    from negstiff.inference.analysis.separation import separation
    from negstiff.inference.estimators.posterior import Posterior
    from negstiff.inference.record.measurement import Measurement
    from negstiff.models import SEED_LIKE_CUBIC
    from negstiff.models.rig import Rig

    truth = dataclasses.replace(SEED_LIKE_CUBIC, extra={"coulomb_friction": friction})
    rows = []
    for seed in seeds:
        first = Measurement.from_rig(Candidate("random", DEFAULT_RANDOM_RMS).run(Rig(truth, seed=seed), duration))
        post = Posterior(seed=0).fit(first).result()
        disc = Discrepancy(offer_laws=False).fit(first).result()
        t0 = time.perf_counter()
        sep = separation(post, disc, seed=0)
        row = {"seed": seed, "first_named": disc["effects"], "ranking": disc["iterations"][0]["ranking"][:2],
               "hypotheses": sep["hypotheses"], "test": sep["best"]["test"],
               "bits": sep["best"]["information_bits"], "default_bits": sep["default_test"]["information_bits"],
               "separation_s": time.perf_counter() - t0}  # fmt: skip
        for name, level in (("designed", sep["best"]["rms_m_s2"]), ("default", DEFAULT_RANDOM_RMS)):
            nxt = Measurement.from_rig(Candidate("random", level).run(Rig(truth, seed=100 + seed), duration))
            row[name] = Discrepancy(offer_laws=False).fit(nxt).result()["effects"]
        rows.append(row)
        print(f"separation check: seed {seed}, {row['test']}: named {row['designed']} against the default's "
              f"{row['default']}", file=sys.stderr)  # fmt: skip
    return {"rows": rows, "friction_n": friction, "duration_s": duration}


HAMMER_FIRST_N = 20.0
"""The first record's hits [N] in the ring-down check (4 of them, 4 ms: the double well rings about 4 mm in its
plus well, a quarter of the way to its saddle)."""


def ring_down_check(seeds=SEEDS, duration: float = 10.0) -> dict:
    """Which hammer test or release next, checked against reality: on the virtual rig (1 kHz, its default laser),
    the lightly damped double well of the tests' hammer records (``tests/impact_records.DOUBLE_WELL``, 1.9 %
    damping) hit four times at ``HAMMER_FIRST_N``; its posterior, ``design`` with its defaults, and the chosen test
    and the reference test each run on the rig (seed 100 + s) and fitted jointly with the first record.
    """
    from negstiff import Model
    from negstiff.inference.analysis.design import Candidate, design
    from negstiff.inference.estimators.posterior import Posterior
    from negstiff.inference.record.measurement import Measurement
    from negstiff.models.rig import Rig

    # the tests' double well (``tests/impact_records.py``), written out: the benchmarks do not import the tests
    p = np.poly((-0.015, 0.004, 0.020)) * 1.5e6
    truth = Model(m=0.2, k1=-p[2], k2=p[1], k3=1.5e6, c=0.5, k0=p[3])
    rows = []
    for seed in seeds:
        rig = Rig(truth, seed=seed, fs=1000.0)
        first = Measurement.from_rig(rig.hammer(peak=HAMMER_FIRST_N, hits=4, duration=duration))
        post = Posterior(seed=0).fit(first).result()
        t0 = time.perf_counter()
        plan = design(post, seed=seed)
        t_design = time.perf_counter() - t0
        row = {"seed": seed, "design_s": t_design, "now": plan["now"]}
        for name, r in (("designed", plan["best"]), ("default", plan["default_test"])):
            test = Candidate(r["kind"], r.get("peak_force_n", r.get("release_offset_m")), hits=r.get("hits"))
            nxt = Measurement.from_rig(test.run(Rig(truth, seed=100 + seed, fs=1000.0), duration))
            joint = Posterior(seed=0).fit([first, nxt]).result()["parameters"]
            row[name + "_test"] = r["test"]
            row[name + "_predicted"] = r["predicted_width"]
            row[name + "_both_wells"] = r["cost"]["draws_visiting_both_wells"]
            row[name] = {k: joint[k]["hdi_high"] - joint[k]["hdi_low"] for k in plan["now"]}
            row[name + "_truth_inside"] = int(sum(joint[k]["hdi_low"] <= getattr(truth, k) <= joint[k]["hdi_high"]
                                                  for k in plan["now"]))  # fmt: skip
        row["shrink_designed"] = _shrink(row["now"], row["designed"])
        row["shrink_default"] = _shrink(row["now"], row["default"])
        rows.append(row)
        print(f"ring-down design check: seed {seed}, {row['designed_test']}: {row['shrink_designed']:.3g}x against "
              f"{row['shrink_default']:.3g}x", file=sys.stderr)  # fmt: skip
    return {"rows": rows, "first_hits_n": HAMMER_FIRST_N, "duration_s": duration}


def ring_down_section(res: dict) -> list[str]:
    """The report section of ``ring_down_check``."""
    from .peers import section

    rows = res["rows"]
    table = []
    for r in rows:
        cells = [str(r["seed"]), r["designed_test"], f"{r['design_s']:.0f} s"]
        for name in ("designed", "default"):
            ratio = [r[name][k] / r[name + "_predicted"][k] for k in r["now"]]
            cells.append(f"{r['shrink_' + name]:.3g}x, {min(ratio):.2f}-{max(ratio):.2f}")
        cells += [f"{r['default_both_wells']:.2f}", f"{r['designed_truth_inside']} / {r['default_truth_inside']}"]
        table.append(cells)
    per_param = {
        k: float(np.median([r["designed"][k] / r["designed_predicted"][k] for r in rows])) for k in rows[0]["now"]
    }
    intro = (
        f"The first record: {res['duration_s']:g} s of four {res['first_hits_n']:g} N hammer hits (4 ms) on the "
        "virtual rig at 1 kHz, the device the lightly damped double well of the tests' hammer records (wells at "
        "-15 / +20 mm, 1.9 % damping), at rest in its plus well. `design` with its defaults ranks hammer tests "
        "(peak force, 2-8 hits) and releases; the chosen test and the reference test (four hits ringing at half "
        "the distance to the saddle) each run on the rig (another seed) and fitted jointly with the first record. "
        "Shrinkage: the geometric mean over the five coefficients of the 90 % width before / after; realised / "
        "predicted: per coefficient, the range over the five."
    )
    lines = section("Test design: hammer hits and releases", intro,
                    ["seed", "chosen test", "design time", "chosen: shrinkage, realised / predicted",
                     "reference: shrinkage, realised / predicted", "reference: draws visiting both wells",
                     "truth inside (chosen / reference)"], table)  # fmt: skip
    lines += ["", "Median realised / predicted of the chosen test per coefficient: "
              + ", ".join(f"{k} {v:.2f}" for k, v in per_param.items())
              + ". A test that throws some of the posterior's draws across the saddle and not others has a two-valued "
              "outcome: the prediction is its average, and the realised width lies on one side of it."]  # fmt: skip
    return lines


def _shrink(now: dict, after: dict) -> float:
    return float(np.exp(np.mean([np.log(now[k] / after[k]) for k in now])))


def _solve_ivp_equivalent(rows) -> dict:
    """What the design's simulations would cost with ``solve_ivp`` (RK45, rtol 1e-8): one 20 s record of the truth
    under a random input timed, times the trajectories one design integrates at least (evaluations x draws x the 7
    columns of the Jacobian's finite differences, the windows' start-state refinement left out).
    """
    from scipy.integrate import solve_ivp

    from negstiff.models import SEED_LIKE_CUBIC
    from negstiff.models.rig import Rig

    rec = Rig(SEED_LIKE_CUBIC, seed=1).random(duration=DURATION, rms=8.0)
    t = rec.columns["t"] - rec.columns["t"][0]
    u = rec.true["base_acc"]
    m = SEED_LIKE_CUBIC

    def rhs(s, x):
        return [x[1], -np.interp(s, t, u) - (m.restoring_force(x[0]) + m.damping_force(x[1])) / m.m]

    t0 = time.perf_counter()
    solve_ivp(rhs, (0, t[-1]), [rec.true["z"][0], 0.0], t_eval=t, rtol=1e-8, atol=1e-12)
    one = time.perf_counter() - t0
    evaluated = float(np.median([r["evaluated"] for r in rows]))
    n = evaluated * float(np.median([r["draws"] for r in rows])) * 7
    design_s = float(np.median([r["design_s"] for r in rows]))
    return {"one_record_s": one, "trajectories": n, "estimated_s": one * n, "design_s": design_s,
            "ratio": one * n / design_s}  # fmt: skip


def design_section(res: dict) -> list[str]:
    """The report section."""
    from .peers import section

    rows = res["rows"]
    table = []
    for r in rows:
        realised = [r["designed"][k] / r["predicted"][k] for k in r["now"]]
        table.append([str(r["seed"]), r["test"], f"{r['design_s']:.1f} s", f"{r['shrink_designed']:.3g}x",
                      f"{r['shrink_default']:.3g}x", f"{r['shrink_designed'] / r['shrink_default']:.3g}",
                      f"{min(realised):.2f}-{max(realised):.2f}",
                      f"{r['designed_truth_inside']} / {r['default_truth_inside']}"])  # fmt: skip
    ratios = [r["shrink_designed"] / r["shrink_default"] for r in rows]
    per_param = {k: float(np.median([r["designed"][k] / r["predicted"][k] for r in rows])) for k in rows[0]["now"]}
    s = res["solve_ivp"]
    intro = (
        "The first record: 20 s of the rig's default random test (14 m/s^2 rms) on the polynomial truth, which "
        "settles into one well. `design` over the five coefficients with its defaults; the first-ranked test and the "
        "rig's default random test each run on the rig (another seed) and fitted jointly with the first record. "
        "Shrinkage: the geometric mean over k1, k2, k3, c, c_nl of the 90 % width before / after. Realised / "
        "predicted: the designed test's joint widths over the design's prediction. Truth inside: of the five "
        "coefficients, inside the joint 90 % intervals (designed / default)."
    )
    lines = section("Test design", intro, ["seed", "chosen test", "design time", "shrinkage (designed)",
                                           "shrinkage (default)", "ratio", "realised / predicted",
                                           "truth inside"], table)  # fmt: skip
    med = float(np.median(ratios))
    lines += [
        "",
        f"Median ratio {med:.3g} (the acceptance: at least 1.5, "
        + ("met" if med >= 1.5 else "**not met**")
        + "). Median realised / predicted per coefficient: "
        + ", ".join(f"{k} {v:.2f}" for k, v in per_param.items())
        + " (within 30 %: "
        + ("met" if all(abs(v - 1) <= 0.3 for v in per_param.values()) else "**not met**")
        + f"). One design took {s['design_s']:.0f} s (median); its simulations through solve_ivp (RK45, rtol 1e-8: "
        f"{s['one_record_s']:.2f} s for one 20 s record, times {s['trajectories']:.0f} trajectories at least) would "
        f"take about {s['estimated_s'] / 60:.0f} min, {s['ratio']:.0f}x longer.",
    ]
    return lines


def separation_section(res: dict) -> list[str]:
    """The report section of ``separation_check``."""
    from .peers import section

    rows = res["rows"]
    table = []
    for r in rows:
        (a, sa), (b, sb) = list(r["hypotheses"].items())
        scores = " / ".join(f"{x['score']:.3g}" for x in r["ranking"])
        table.append([str(r["seed"]), ", ".join(r["first_named"]), f"{a} {sa:.3g}, {b} {sb:.3g} ({scores} %)",
                      r["test"], f"{r['bits']:.2f} / {r['default_bits']:.2f}", f"{r['separation_s']:.0f} s",
                      ", ".join(r["designed"]), ", ".join(r["default"])])  # fmt: skip
    designed = sum(r["designed"] == ["coulomb_friction"] for r in rows)
    default = sum(r["default"] == ["coulomb_friction"] for r in rows)
    intro = (
        f"The first record: {res['duration_s']:g} s of the rig's default random test on the polynomial truth with a "
        f"hidden {res['friction_n']:g} N Coulomb friction; its posterior and `Discrepancy(offer_laws=False)`, whose "
        "first two ranked effects (with the sizes their fits gave) are the hypotheses. `separation` runs each "
        "hypothesis through random tests at 3-28 m/s^2 rms on the rig (8 records each) and ranks them by the "
        "information the workflow's verdict carries about which is present; the chosen test and the default one "
        "are then run on the rig (another seed) and read by the workflow."
    )
    lines = section("Test design: telling two effects apart", intro,
                    ["seed", "first record named", "hypotheses (held-out scores)", "chosen test",
                     "bits (chosen / default)", "time", "named (chosen test)", "named (default test)"],
                    table)  # fmt: skip
    lines += ["", f"The chosen test named the friction in {designed} of {len(rows)} seeds, the default test in "
              f"{default} (the acceptance: at least 4 of 5, and the default fewer: "
              + ("met" if designed >= 4 and default < designed else "**not met**") + ")."]  # fmt: skip
    return lines
