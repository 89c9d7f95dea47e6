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
    from dask import distributed           # the test extra brings dask[distributed]: this path is tested, not skipped

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        remote = run_cases(_case, CASES[:2], scheduler=cluster.scheduler_address)
    _assert_same(run_cases(_case, CASES[:2], workers=1), remote)


def test_a_studys_cases_on_a_two_worker_dask_cluster_give_the_serial_numbers():
    """The autopilot-waves study's quick cases (the Otter with and without its wave filter), as its
    ``run(scheduler=...)`` hands them to :func:`run_cases`."""
    from dask import distributed

    from casship_studies.autopilot_waves import run_case

    cases = [{"ship": "otter", "filter": f, "changes": [20], "seeds": [2]} for f in (False, True)]
    serial = run_cases(run_case, cases, workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        with distributed.Client(cluster.scheduler_address) as client:
            assert len(client.scheduler_info()["workers"]) == 2
        remote = run_cases(run_case, cases, scheduler=cluster.scheduler_address)
    assert [r["filter"] for r in remote] == [False, True]
    for a, b in zip(serial, remote):
        for key in ("psi", "steer", "psd"):
            assert np.array_equal(a[key], b[key]), key             # bit-identical
        assert [r["keeping"] for r in a["runs"]] == [r["keeping"] for r in b["runs"]]
    assert not np.array_equal(serial[0]["steer"], serial[1]["steer"])     # the filter changes the run


_RUNNING = {"now": 0, "most": 0}


def _sleepy_case(case: int) -> int:
    """Counts how many cases of this process run at once (threaded Dask workers share the module)."""
    import time

    _RUNNING["now"] += 1
    _RUNNING["most"] = max(_RUNNING["most"], _RUNNING["now"])
    time.sleep(0.2)
    _RUNNING["now"] -= 1
    return case


def test_dask_workers_in_one_process_run_cases_one_at_a_time():
    """CasADi is not thread-safe: two threaded workers of one process must not run cases together."""
    from dask import distributed

    _RUNNING.update(now=0, most=0)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster:
        assert run_cases(_sleepy_case, list(range(6)), scheduler=cluster.scheduler_address) == list(range(6))
    assert _RUNNING["most"] == 1


def test_unpicklable_case_function_fails_loudly():
    with pytest.raises(Exception):
        run_cases(lambda c: c, [1, 2], workers=2)


# -- a synthetic multi-record identification study: folds in parallel give the serial numbers ------------
def _records():
    model = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 240.0, 1.0)
    runs = []
    for i, amp in enumerate((0.1, -0.15, 0.2, -0.12)):
        truth = cs.simulate(model, model.states(), t, {"delta": amp * np.sign(np.sin(t / (20.0 + 5 * i)))})
        runs.append(cs.measure(truth, model, {"psi": 0.01}, seed=10 + i))
    return model, runs


def _fit(model, records, free=("K", "T")):
    """One fold of the study: a MAP output-error fit (the case function, module level)."""
    prob = cs.OutputErrorProblem(model, records, free=list(free), sigma={"psi": 0.01}, estimate_x0=["r"],
                                 prior={n: {"K": 0.05, "T": 10.0}[n] for n in free})
    fit = prob.solve(guess={n: {"K": 0.05, "T": 10.0}[n] for n in free}, show=False)
    return {"estimates": fit.estimates, "std": fit.std_errors, "robust": fit.std_errors_robust, "cost": fit.cost,
            "information": prob.information(fit.estimates)}


def _study_cases():
    from casship.parallel import call

    model, runs = _records()
    cases = [(_fit, (model, runs))]                                              # the fit on all records
    cases += [(_fit, (model, [r for j, r in enumerate(runs) if j != i])) for i in range(len(runs))]  # leave one out
    cases += [(_fit, (model, runs[:2], ("K",)))]                                # another structure
    return call, cases


def test_parallel_folds_give_exactly_the_serial_numbers():
    call, cases = _study_cases()
    serial = run_cases(call, cases, workers=1)
    pooled = run_cases(call, cases, workers=2, label="folds")
    assert len(serial) == len(pooled) == len(cases)
    for a, b in zip(serial, pooled):
        assert a["estimates"] == b["estimates"]                                # bit-identical
        assert a["std"] == b["std"] and a["robust"] == b["robust"] and a["cost"] == b["cost"]
        assert np.array_equal(a["information"], b["information"])
    # the folds see different records, so they differ (the comparison above is not vacuous)
    assert serial[1]["estimates"]["K"] != serial[2]["estimates"]["K"]
    assert abs(serial[0]["estimates"]["K"] - 0.1) < 4 * serial[0]["std"]["K"]


def test_call_runs_a_function_with_its_arguments():
    from casship.parallel import call

    assert run_cases(call, [(divmod, (7, 2)), (round, (2.567,), {"ndigits": 1})], workers=2) == [(3, 1), 2.6]


def _blas_counts(case) -> dict:
    """BLAS threads seen inside a case, and inside ``blas_threads(None)`` there."""
    from threadpoolctl import threadpool_info

    from casship.parallel import blas_threads

    inner = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    with blas_threads(None):
        restored = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    return {"case": case, "inner": inner, "restored": restored}


@pytest.mark.parametrize("workers", [1, 2])
def test_cases_run_with_the_blas_threads_asked_for_and_give_them_back(workers):
    from threadpoolctl import threadpool_info

    before = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    if not before:
        pytest.skip("no BLAS library that threadpoolctl controls")
    out = run_cases(_blas_counts, [0, 1], workers=workers, blas_threads=1)
    assert [o["case"] for o in out] == [0, 1]
    for o in out:
        assert o["inner"] == [1] * len(before)            # every BLAS library held to one thread
        assert o["restored"] == before                    # the count the process started with
    assert [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"] == before
    # the numbers of a case do not change with the limit here (no BLAS product in it that threads)
    _assert_same(run_cases(_case, CASES, workers=workers, blas_threads=1), [_case(c) for c in CASES])
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="blas_threads"):
            run_cases(_case, CASES, workers=1, blas_threads=bad)
