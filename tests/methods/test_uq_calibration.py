"""The UQ calibration study runs its records as dask tasks (issue 7): a small LocalCluster here."""

import pytest

from benchmarks.uq_calibration import PARAMS, RANK_DRAWS, report, run, summarise
from negstiff.report.document import Report


def test_the_calibration_study_runs_on_a_local_dask_cluster():
    pytest.importorskip("dask.distributed")
    rows = run(records=2, duration=4.0, max_steps=200, n_ensembles=2, workers=2, scheduler=None)
    assert [r["seed"] for r in rows] == [1000, 1001], "one task per record, results in record order"
    s = summarise(rows)
    assert s["records"] == 2
    for p in PARAMS:
        assert 0.0 <= s["coverage_90"][p] <= 1.0
        assert all(0 <= k <= RANK_DRAWS for k in s["ranks"][p])
    # 200 steps cannot converge: the study lists those records instead of hiding them
    assert s["unconverged_records"] == [1000, 1001]
    rep, results = Report("t"), {}
    report(rep, results, rows, {"duration": 4.0, "ensembles": 2, "where": "LocalCluster, 2 workers"})
    assert results["uq_calibration"]["summary"]["records"] == 2
    assert any(kind == "warn" for kind, _ in rep.blocks)
