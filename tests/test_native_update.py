"""The compiled online update (``casship.native_update``): one call into compiled code per sample,
the same numbers, state and errors as the checked Python update it hands everything unusual to."""
from __future__ import annotations

import gc

import numpy as np
import pytest

import casship as cs
from casship.native_update import update_source


MEASURED = ["x", "y", "psi"]
R = [4.0, 4.0, 1e-4]


def _case():
    m = cs.models.mariner()
    t = np.arange(0.0, 120.0, 1.0)
    x0 = m.states(u=7.7, psi=3.1)                           # psi wraps past pi while it turns
    truth = cs.simulate(m, x0, t, {"delta": 0.1 * np.sin(0.05 * t)}, method="rk4")
    data = cs.measure(truth, m, dict(zip(MEASURED, np.sqrt(R))), seed=4)
    prior = cs.Gaussian(x0, np.diag([0.1, 0.1, 1e-4, 25.0, 25.0, 1e-3]))
    return m, cs.discretize(m, 1.0, "rk4"), data, prior


def _runs(outputs=("x", "P")):
    m, dm, data, prior = _case()
    options = {"outputs": outputs}
    Q = np.diag([1e-4, 1e-4, 1e-8])
    checked = cs.EKF(dm, Q, R, measured=MEASURED, options=options).online(prior, u=[0.0])
    compiled = cs.EKF(dm, Q, R, measured=MEASURED, options={**options, "jit": True}).online(prior, u=[0.0])
    if compiled._engine.compiled_update is None:
        pytest.skip("the compiled update needs the Python and NumPy C headers, not installed here")
    return m, data, checked, compiled


def test_the_compiled_update_is_the_runs_update():
    _, _, checked, compiled = _runs()
    assert compiled.update is compiled._engine.compiled_update
    assert type(compiled.update).__name__ == "builtin_function_or_method"
    assert checked._engine.compiled_update is None          # interpreted estimators keep the Python update


def test_every_way_of_calling_gives_the_checked_numbers():
    m, data, checked, compiled = _runs(outputs="all")
    Y = data.matrix(MEASURED)
    Y[5:9, :2] = np.nan                                      # no position for a while
    Y[20, :] = np.nan                                        # nothing measured
    U = 0.1 * np.sin(0.1 * data.t)
    YF = np.asfortranarray(Y)                                # rows are strided views
    calls = []
    for k in range(len(data)):
        dt = 0.0 if k == 0 else 1.0
        u_prev, u = np.array([U[k - 1]]), np.array([U[k]])
        kind = k % 7
        if kind == 0:
            calls.append(((Y[k], dt, u_prev, u), {}))
        elif kind == 1:
            calls.append(((YF[k], dt, u_prev, u), {}))             # strided y
        elif kind == 2:
            calls.append(((Y[k], dt), {}))                          # inputs held
        elif kind == 3:
            calls.append(((list(Y[k]), dt, [U[k - 1]], U[k]), {}))   # a list and a float: checked path
        elif kind == 4:
            calls.append(((Y[k], int(dt), u_prev), {"u": u}))        # int dt, a keyword
        elif kind == 5:
            calls.append(((Y[k].astype(np.float32).astype(np.float64), np.float64(dt), u_prev, None), {}))
        else:
            calls.append(((Y[k].astype(np.float32), dt, u_prev.astype(np.float32), u), {}))
    for k, (args, kwargs) in enumerate(calls):
        x_checked = checked.update(*args, **kwargs)
        x_compiled = compiled.update(*args, **kwargs)
        np.testing.assert_allclose(x_compiled, x_checked, rtol=1e-10, atol=1e-13, err_msg=f"sample {k}")
    np.testing.assert_allclose(compiled.P, checked.P, rtol=1e-10, atol=1e-16)
    for key in ("nis", "ll"):
        assert compiled.info[key] == pytest.approx(checked.info[key], rel=1e-9)
    np.testing.assert_array_equal(np.isnan(compiled.info["e"]), np.isnan(checked.info["e"]))
    assert repr(compiled) == repr(checked) == f"OnlineRun(EKF, samples={len(data)})"


def test_the_returned_mean_is_a_new_array():
    _, data, _, compiled = _runs()
    Y = data.matrix(MEASURED)
    first = compiled.update(Y[0], 0.0)
    second = compiled.update(Y[1], 1.0)
    assert first is not second and not np.shares_memory(first, second)
    assert first.flags.writeable and first.shape == (6,) and first.dtype == np.float64
    first[:] = 99.0                                           # the caller's copy: the run is unaffected
    np.testing.assert_array_equal(compiled.x, second)


def test_the_update_keeps_what_it_works_on_alive():
    m, data, checked, compiled = _runs()
    Y = data.matrix(MEASURED)
    update = compiled.update
    del compiled
    gc.collect()
    np.testing.assert_allclose([update(Y[k], 1.0 * (k > 0)) for k in range(10)],
                               [checked.update(Y[k], 1.0 * (k > 0)) for k in range(10)], rtol=1e-10, atol=1e-12)


def test_update_source_needs_a_c_name():
    assert "casship_update_new_ekf_online" in update_source("ekf_online", 2, 1, 1)
    with pytest.raises(ValueError, match="C identifier"):
        update_source("ekf-online", 2, 1, 1)
