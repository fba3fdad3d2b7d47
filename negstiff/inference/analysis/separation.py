"""Which test tells two effects apart: the discrepancy workflow's runners-up on the first record, each put into the
posterior's mean model at the size its fit gave, run through candidate tests on the virtual rig and read by the
workflow itself; the tests ranked by the information its verdict carries about which effect is present.

The model-discrimination counterpart of ``analysis.design`` (which narrows parameters): it shares the design's
posterior state, candidates and limits (``design.PosteriorState``, ``Candidate``, ``Limits``, ``limit_problems``).
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
import time
import warnings
from typing import Any

import numpy as np

from negstiff.errors import InputError, NegstiffWarning
from negstiff.inference.analysis.design import (
    BAND,
    DEFAULT_MAX_ACC,
    DEFAULT_RANDOM_RMS,
    Candidate,
    _counts,
    _limits,
    _state_of,
    limit_problems,
    record_cost,
)

SEPARATION_LEVELS = (3.0, 4.5, 6.0, 9.0, 14.0, 20.0, 28.0)
"""The random tests' levels [m/s^2 rms] a separation compares (the rig's default test, 14, among them): friction
shows at low levels, where it is a larger part of the damping, cubic damping at high ones."""


def separation(posterior, discrepancy=None, *, hypotheses: dict[str, Any] | None = None,
               duration: float | None = None, max_table_acc: float = DEFAULT_MAX_ACC,
               max_table_disp: float | None = None, stroke: float | None = None, sensor_range: float | None = None,
               levels: tuple[float, ...] = SEPARATION_LEVELS, records: int = 8,
               seed: int = 0) -> dict[str, Any]:  # fmt: skip
    """Which test tells two competing effects apart (the discrepancy's runners-up on the first record).

    Each hypothesis is the posterior's mean model with that effect at that size. For each candidate test (random
    at ``levels``) and each hypothesis, ``records`` records are written by the virtual rig with the posterior's
    noise (the same seeds for every candidate) and read by the workflow itself (``Discrepancy(offer_laws=False)``);
    its verdict (the effect named first, ``none``, another effect, or a refusal) is the test's outcome. The
    criterion is the information the verdict carries about which hypothesis is true, I(H; verdict) in bits with the
    hypotheses equally likely (1 bit: the verdict always tells them apart), the model-discrimination design's
    expected information about the model indicator (Box and Hill 1967, Technometrics 9(1), 57-71; Drovandi, McGree
    and Pettitt 2014, J. Comput. Graph. Stat. 23(1), 3-24), each hypothesis's chance of being named beside it.
    Every check runs before the work: a record of ``duration`` too short for the workflow is refused in a second.

    Parameters
    ----------
    posterior : Posterior, dict, path or PosteriorState
        A fitted coefficient ``Posterior`` of a base-excited record, its ``result()`` or its JSON file (the model
        each hypothesis is added to, and the record's noise).
    discrepancy : dict or path, optional
        The discrepancy workflow's result on the first record (its first round's first two catalogue effects, with
        their sizes, are the hypotheses).
    hypotheses : dict, optional
        ``{effect: size}`` for two effects of the catalogue (``models.effects``), instead of ``discrepancy``.
    duration : float, optional
        The next record's length [s] (default: the posterior's record's).
    max_table_acc, max_table_disp : float
        The table's peak acceleration [m/s^2] and displacement [m] (None: no displacement limit stated); a test
        whose records exceed either, under either hypothesis, is infeasible.
    stroke : float, optional
        The device's travel from its saddle to a stop [m]; a test that reaches it is infeasible.
    sensor_range : float, optional
        The displacement sensor's measuring range [m] (the device's and the table's motion together).
    levels : tuple of float
        The random tests' rms table accelerations [m/s^2] (over the rig's 2-40 Hz band); the default test's 14 is
        always among them.
    records : int
        Records per test and hypothesis (the verdict's frequencies are counted over them). With four, the count
        was a knife-edge on the rig: a 2e-5 change of the posterior's mean flipped one record's verdict and the
        chosen test.
    seed : int
        Seed of the records' excitation and noise (the same for every test: common random numbers).

    Returns
    -------
    dict
        ``{"hypotheses", "criterion", "ranked", "best", "default_test", "warnings", "settings"}``
        (``docs/contract.md``).

    Examples
    --------
    >>> from negstiff import Measurement, Posterior, Rig, separation
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=4).random(duration=24.0, rms=14.0))
    >>> sep = separation(Posterior(seed=0).fit(rec), hypotheses={"coulomb_friction": 0.02, "cubic_damping": 2.0},
    ...                  levels=(3.0,), records=1)
    >>> sorted(sep["hypotheses"]), 0.0 <= sep["best"]["information_bits"] <= 1.0
    (['coulomb_friction', 'cubic_damping'], True)
    """
    from negstiff.inference.estimators.discrepancy import Discrepancy
    from negstiff.inference.record.measurement import Measurement

    state = _state_of(posterior)
    if state.bench != "table":
        raise InputError(f"{state.source or 'the posterior'}: a hammer's or a decay's posterior; a separation compares "
                         "the table's random tests (a base-excited record's posterior)")  # fmt: skip
    hyp = _hypotheses(discrepancy, hypotheses)
    limits = _limits(state, duration, max_table_acc, max_table_disp, stroke, sensor_range)
    _counts(records=records, seed=seed)
    if not levels or any(isinstance(v, bool) or not isinstance(v, numbers.Real) or not (math.isfinite(v) and v > 0)
                         for v in levels):  # fmt: skip
        raise InputError(f"levels {levels!r}: random tests' rms levels must be positive numbers [m/s^2]")
    base = state.model_at(state.mean)
    compared = sorted({float(v) for v in levels} | {DEFAULT_RANDOM_RMS})
    # the workflow's own length check on one record of the quietest test (a fraction of a second, no fit): a record
    # it refuses makes every verdict a refusal and every test worth 0 bits
    lead, lead_size = next(iter(hyp.items()))
    lead_model = dataclasses.replace(base, extra={lead: lead_size})
    quietest = Candidate("random", compared[0])
    first = quietest.run(state.rig(lead_model, seed), limits.duration_s)
    beyond = limit_problems(quietest, record_cost(state, lead_model, [first]), limits)
    if beyond:  # the quietest test already beyond a limit: every louder one too
        raise InputError(f"no random test lies within the limits (the quietest, {quietest.describe()}: {beyond[0]}): "
                         "widen the table's limits or the device's stroke")  # fmt: skip
    try:
        Discrepancy(offer_laws=False).check_length(Measurement.from_rig(first))
    except InputError as exc:
        raise InputError(f"a separation's records of {limits.duration_s:g} s cannot be read by the discrepancy "
                         f"workflow ({str(exc).split(': ', 1)[-1]}): ask for a longer duration") from None  # fmt: skip
    t0 = time.perf_counter()
    rows: list[dict[str, Any]] = []
    for level in compared:
        cand = Candidate("random", level)
        outcomes: dict[str, dict[str, float]] = {}
        costs = []
        for h, size in hyp.items():
            model = dataclasses.replace(base, extra={h: size})
            seen: dict[str, float] = {}
            for r in range(records):
                rec = cand.run(state.rig(model, seed + r), limits.duration_s)
                costs.append(record_cost(state, model, [rec]))
                try:
                    with warnings.catch_warnings():  # what the workflow says of a simulated record is not the user's
                        warnings.simplefilter("ignore", NegstiffWarning)
                        named = Discrepancy(offer_laws=False).fit(Measurement.from_rig(rec)).result()["effects"]
                    verdict = named[0] if named and (named[0] in hyp or named[0] == "none") else "another effect"
                except (InputError, ValueError, ArithmeticError):
                    verdict = "refused"
                seen[verdict] = seen.get(verdict, 0.0) + 1.0 / records
            outcomes[h] = seen
        cost = {k: max(c[k] for c in costs) for k in costs[0] if k != "other_well_share"}
        problems = limit_problems(cand, cost, limits)
        rows.append({"kind": "random", "test": cand.describe(), "rms_m_s2": level, "band_hz": list(BAND),
                     "information_bits": _verdict_information(outcomes), "outcomes": outcomes,
                     "names_right": {h: outcomes[h].get(h, 0.0) for h in hyp},
                     "cost": cost, "feasible": not problems, "problems": problems})  # fmt: skip
    # equally informative tests (to the 0.01 bit: a few records' verdicts are coarse) in favour of the one that names
    # the leading hypothesis (the workflow's first-ranked) when it is true: it tells them apart by naming the likelier
    # effect, not by naming its rival

    def rank(r: dict[str, Any]) -> tuple:
        right = r["names_right"]
        return (
            not r["feasible"],
            -round(float(r["information_bits"]), 2),
            -right[lead],
            -float(np.mean(list(right.values()))),
        )

    rows.sort(key=rank)
    if not rows[0]["feasible"]:
        raise InputError("no random test lies within the limits (the best one: " + rows[0]["problems"][0] + "): "
                         "widen the table's limits or the device's stroke")  # fmt: skip
    default = next(r for r in rows if r["rms_m_s2"] == DEFAULT_RANDOM_RMS)
    notes = _warnings(rows, records)
    for text in notes:
        warnings.warn(text, NegstiffWarning, stacklevel=2)
    return {
        "hypotheses": hyp,
        "criterion": {
            "name": "information the discrepancy workflow's verdict carries about which effect is present [bits]",
            "method": f"each hypothesis (the posterior's mean model with the effect) run through each test on the "
            f"virtual rig, {records} records each, read by Discrepancy(offer_laws=False); I(H; verdict) with the "
            "hypotheses equally likely",
            "references": [
                "Box and Hill 1967, Technometrics 9(1) 57-71",
                "Drovandi, McGree and Pettitt 2014, J. Comput. Graph. Stat. 23(1) 3-24",
            ],
        },  # fmt: skip
        "ranked": rows,
        "best": rows[0],
        "default_test": default,
        "warnings": notes,
        "settings": {
            "duration_s": limits.duration_s,
            "max_table_acc_m_s2": limits.max_table_acc,
            "max_table_disp_m": limits.max_table_disp,
            "stroke_m": limits.stroke,
            "sensor_range_m": limits.sensor_range,
            "levels_m_s2": compared,
            "records": records,
            "seed": seed,
            "seconds": time.perf_counter() - t0,
            "posterior": state.source,
        },  # fmt: skip
    }


def _warnings(rows: list[dict[str, Any]], records: int) -> list[str]:
    """What makes the chosen test's verdict weak: no feasible test tells the effects apart at all, or the workflow
    refused or named another effect in many of the chosen test's records.
    """
    best, out = rows[0], []
    if best["information_bits"] < 0.01:
        out.append("no test among those compared tells the two effects apart: the workflow's verdict is the same "
                   "under either (the first-ranked test is no better than the default)")  # fmt: skip
    other = float(np.mean([o.get("refused", 0.0) + o.get("another effect", 0.0) for o in best["outcomes"].values()]))
    if other >= 0.5:
        out.append(f"in {100 * other:.0f} % of the chosen test's {2 * records} records the workflow refused or named a "
                   "third effect: its verdict there says little about the two compared")  # fmt: skip
    return out


def _hypotheses(discrepancy, hypotheses) -> dict[str, Any]:
    """The two effects a separation compares, with their sizes: given, or the discrepancy result's (its dict or
    file) first two catalogue effects of its first round; one ``InputError`` otherwise.
    """
    from negstiff.models import effects

    if hypotheses is None:
        if discrepancy is None:
            raise InputError("a separation needs the discrepancy's result on the first record or hypotheses "
                             "({effect: size})")  # fmt: skip
        if isinstance(discrepancy, (str, os.PathLike)):
            from negstiff.files import read_json

            discrepancy = read_json(discrepancy, "discrepancy result")
        try:
            ranking = discrepancy["iterations"][0]["ranking"]
        except (KeyError, IndexError, TypeError):
            raise InputError("not a discrepancy result (no iterations[0].ranking)") from None
        hypotheses = {r["effect"]: r["size"] for r in ranking if r.get("size") is not None}
        hypotheses = dict(list(hypotheses.items())[:2])
        if len(hypotheses) < 2:
            raise InputError("the discrepancy result ranks fewer than two catalogue effects with a size (a result "
                             "written before rankings kept sizes: run it again)")  # fmt: skip
    if not isinstance(hypotheses, dict):
        raise InputError(f"hypotheses must be a dict {{effect: size}}, got {type(hypotheses).__name__}")
    known = set(effects.names())
    bad = [h for h in hypotheses if h not in known]
    if bad or len(hypotheses) != 2:
        raise InputError(f"hypotheses {list(hypotheses)}: two of the catalogue's effects ({', '.join(sorted(known))})")
    for h, size in hypotheses.items():
        if isinstance(size, bool) or not isinstance(size, numbers.Real) or not math.isfinite(size):
            raise InputError(f"hypotheses: the size of {h} must be a finite number, got {size!r}")
    return dict(hypotheses)


def _verdict_information(outcomes: dict[str, dict[str, float]]) -> float:
    """I(H; verdict) [bits] with the hypotheses equally likely, from each hypothesis's verdict frequencies."""
    hs = list(outcomes)
    verdicts = {v for o in outcomes.values() for v in o}
    bits = 0.0
    for v in verdicts:
        p_v = float(np.mean([outcomes[h].get(v, 0.0) for h in hs]))
        for h in hs:
            p = outcomes[h].get(v, 0.0)
            if p > 0:
                bits += p / len(hs) * math.log2(p / p_v)
    return bits
