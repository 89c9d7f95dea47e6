"""The online update of the recursive estimators (``StepRun``): one evaluation of the step through
CasADi's buffers per sample, the same numbers compiled and interpreted whatever types the caller
passes, a normal method, runs freed when dropped, and one update at a time across threads."""
from __future__ import annotations

import gc
import sys
import threading
import weakref
from pathlib import Path

import numpy as np
import pytest

import casship as cs
from casship.estimators import OnlineRun

MEASURED = ["x", "y", "psi"]
R = [4.0, 4.0, 1e-4]
Q = np.diag([1e-4, 1e-4, 1e-8])


def _case(n=120):
    m = cs.models.mariner()
    t = np.arange(0.0, float(n), 1.0)
    x0 = m.states(u=7.7, psi=3.1)                           # psi wraps past pi while it turns
    truth = cs.simulate(m, x0, t, {"delta": 0.1 * np.sin(0.05 * t)}, method="rk4")
    data = cs.measure(truth, m, dict(zip(MEASURED, np.sqrt(R))), seed=4)
    prior = cs.Gaussian(x0, np.diag([0.1, 0.1, 1e-4, 25.0, 25.0, 1e-3]))
    return m, cs.discretize(m, 1.0, "rk4"), data, prior


def _estimators(outputs=("x", "P")):
    m, dm, data, prior = _case()
    interpreted = cs.EKF(dm, Q, R, measured=MEASURED, options={"outputs": outputs})
    compiled = cs.EKF(dm, Q, R, measured=MEASURED, options={"outputs": outputs, "jit": True})
    return m, data, prior, interpreted, compiled


def test_update_is_a_normal_method():
    _, _, prior, interpreted, compiled = _estimators()
    for est in (interpreted, compiled):
        run = est.online(prior, u=[0.0])
        assert isinstance(run, OnlineRun) and "update" not in vars(run)
        assert run.update.__func__ is type(run).update


def test_every_way_of_calling_gives_the_same_numbers_compiled_and_interpreted():
    m, data, prior, interpreted, compiled = _estimators(outputs="all")
    checked, fast = interpreted.online(prior, u=[0.0]), compiled.online(prior, u=[0.0])
    Y = data.matrix(MEASURED)
    Y[5:9, :2] = np.nan                                      # no position for a while
    Y[20, :] = np.nan                                        # nothing measured
    U = 0.1 * np.sin(0.1 * data.t)
    YF = np.asfortranarray(Y)                                # rows are strided views
    calls = []
    for k in range(len(data)):
        dt = 0.0 if k == 0 else 1.0
        u_prev, u = np.array([U[k - 1]]), np.array([U[k]])
        kind = k % 8
        if kind == 0:
            calls.append(((Y[k], dt, u_prev, u), {}))
        elif kind == 1:
            calls.append(((YF[k], dt, u_prev, u), {}))             # strided y
        elif kind == 2:
            calls.append(((Y[k], dt), {}))                          # inputs held
        elif kind == 3:
            calls.append(((list(Y[k]), dt, [U[k - 1]], U[k]), {}))   # a list and a scalar
        elif kind == 4:
            calls.append(((Y[k], int(dt), u_prev), {"u": u}))        # int dt, a keyword
        elif kind == 5:
            calls.append(((Y[k].astype(np.float32).astype(np.float64), np.float64(dt), u_prev, None), {}))
        elif kind == 6:
            calls.append(((Y[k].astype(">f8"), dt, u_prev, u), {}))  # another byte order
        else:
            calls.append(((Y[k].astype(np.float32), dt, u_prev.astype(np.float32), u), {}))
    for k, (args, kwargs) in enumerate(calls):
        x_checked = checked.update(*args, **kwargs)
        x_fast = fast.update(*args, **kwargs)
        np.testing.assert_allclose(x_fast, x_checked, rtol=1e-10, atol=1e-13, err_msg=f"sample {k}")
    np.testing.assert_allclose(fast.P, checked.P, rtol=1e-10, atol=1e-16)
    for key in ("nis", "ll"):
        assert fast.info[key] == pytest.approx(checked.info[key], rel=1e-9)
    np.testing.assert_array_equal(np.isnan(fast.info["e"]), np.isnan(checked.info["e"]))
    assert repr(fast) == repr(checked) == f"OnlineRun(EKF, samples={len(data)})"


def test_wrong_shapes_and_values_are_refused_by_name_and_change_nothing():
    _, data, prior, _, compiled = _estimators()
    run = compiled.online(prior, u=[0.0])
    Y = data.matrix(MEASURED)
    run.update(Y[0], 0.0)
    x, P = run.x, run.P
    for bad, match in (((Y[1][:2], 1.0), "y must hold 3 values"), ((Y[1][None, :], 1.0), r"y must hold 3 values.*\(1, 3\)"),
                       ((Y[1], 1.0, [0.0, 0.1]), "u_prev must hold 1 value"), ((Y[1], "1"), "dt must be"),
                       ((Y[1], -1.0), "dt must be >= 0"), ((Y[1], float("nan")), "dt must be >= 0"),
                       ((np.array([np.inf, 0.0, 0.0]), 1.0), r"measurement\(s\) \['x'\] infinite"),
                       ((Y[1], 1.0, [np.nan]), "inputs .*must be finite"), ((["a", 1, 2], 1.0), "y must be 3 numbers")):
        with pytest.raises(ValueError, match=match):
            run.update(*bad)
        np.testing.assert_array_equal(run.x, x)
        np.testing.assert_array_equal(run.P, P)
        assert run.samples == 1


def test_the_returned_mean_is_a_new_array():
    _, data, prior, _, compiled = _estimators()
    run = compiled.online(prior, u=[0.0])
    Y = data.matrix(MEASURED)
    first = run.update(Y[0], 0.0)
    second = run.update(Y[1], 1.0)
    assert first is not second and not np.shares_memory(first, second)
    assert first.flags.writeable and first.shape == (6,) and first.dtype == np.float64
    first[:] = 99.0                                           # the caller's copy: the run is unaffected
    np.testing.assert_array_equal(run.x, second)


def _rss_bytes() -> int | None:
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, ValueError, IndexError):
        return None
    import os

    return pages * os.sysconf("SC_PAGE_SIZE")


def test_dropped_compiled_runs_are_freed():
    """3000 runs of a compiled estimator, created, used and dropped: none stays alive, memory stays flat."""
    _, data, prior, _, compiled = _estimators()
    Y = data.matrix(MEASURED)
    alive, rss = [], []

    def one():
        run = compiled.online(prior, u=[0.0])
        run.update(Y[0], 0.0)
        run.update(Y[1], 1.0)
        alive.append(weakref.ref(run))

    for i in range(3000):
        one()
        if i in (499, 2999):
            gc.collect()
            rss.append(_rss_bytes())
    gc.collect()
    assert sum(r() is not None for r in alive) == 0
    if rss[0] is not None:                       # where the resident size can be read (Linux)
        assert rss[1] - rss[0] < 4e6, f"resident memory grew by {(rss[1] - rss[0]) / 1e6:.1f} MB over 2500 runs"


def test_dropped_runs_are_freed_without_the_cycle_collector():
    _, data, prior, interpreted, compiled = _estimators()
    gc.disable()
    try:
        for est in (interpreted, compiled):
            run = est.online(prior, u=[0.0])
            run.update(data.matrix(MEASURED)[0], 0.0)
            ref = weakref.ref(run)
            del run
            assert ref() is None, est.options.jit              # no reference cycle: freed at once
    finally:
        gc.enable()


@pytest.mark.parametrize("jit", [False, True])
def test_four_threads_on_one_run_give_the_serial_answer(jit):
    """Identical samples from four threads: every update is taken whole, in some order, so the run
    ends where 1000 serial updates end (bit for bit), with every sample counted."""
    _, data, prior, interpreted, compiled = _estimators()
    est = compiled if jit else interpreted
    y, u = data.matrix(MEASURED)[3], np.array([0.05])
    serial = est.online(prior, u=u)
    for _ in range(1000):
        serial.update(y, 1.0, u, u)
    shared = est.online(prior, u=u)
    errors, reads = [], []

    def work():
        try:
            for _ in range(250):
                shared.update(y, 1.0, u, u)
                reads.append(shared.P.shape)
        except Exception as exc:               # noqa: BLE001 - reported below
            errors.append(exc)

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)                  # switch threads as often as possible
    try:
        threads = [threading.Thread(target=work) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)
    assert not errors, errors
    assert shared.samples == 1000 and len(reads) == 1000
    np.testing.assert_array_equal(shared.x, serial.x)
    np.testing.assert_array_equal(shared.P, serial.P)
