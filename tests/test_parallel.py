"""Parallel study cases: a process pool (and a Dask cluster, when installed) give the serial results."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship.parallel import run_cases


def _case(case: dict) -> dict:
    """A small Monte Carlo case: simulate, measure with the case's own seed, filter, score."""
    model = cs.models.nomoto_first_order()
    t = np.arange(0.0, 60.0, 0.5)
    truth = cs.simulate(model, model.states(), t, {"delta": np.radians(case["rudder_deg"])})
    data = cs.measure(truth, model, {"psi": np.radians(0.5)}, seed=case["seed"])
    ekf = cs.EKF(cs.discretize(model, 0.5), Q=1e-8, R=np.radians(0.5) ** 2)
    res = ekf.filter(data, cs.Gaussian(model.states(), np.diag([1e-2, 1e-4])))
    return {"seed": case["seed"], "rmse_r": float(np.sqrt(np.mean((res["r"] - truth["r"]) ** 2))),
            "noise": np.asarray(data["psi"] - truth["psi"])}


CASES = [{"seed": s, "rudder_deg": d} for s in (1, 2, 3) for d in (5.0, -10.0)]


def _assert_same(a: list, b: list) -> None:
    assert len(a) == len(b)
    for ra, rb in zip(a, b):
        assert ra["seed"] == rb["seed"]
        assert ra["rmse_r"] == rb["rmse_r"]                 # bit-identical, not just close
        assert np.array_equal(ra["noise"], rb["noise"])


def test_process_pool_equals_serial():
    serial = run_cases(_case, CASES, workers=1)
    pooled = run_cases(_case, CASES, workers=2)
    _assert_same(serial, pooled)
    # different seeds do give different noise (the comparison above is not vacuous)
    assert not np.array_equal(serial[0]["noise"], serial[2]["noise"])
    assert [r["seed"] for r in pooled] == [c["seed"] for c in CASES]   # order of the cases is kept


def test_dask_scheduler_equals_serial():
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        remote = run_cases(_case, CASES[:2], scheduler=cluster.scheduler_address)
    _assert_same(run_cases(_case, CASES[:2], workers=1), remote)


def test_unpicklable_case_function_fails_loudly():
    with pytest.raises(Exception):
        run_cases(lambda c: c, [1, 2], workers=2)
