"""Batch runs go through folds in pieces (the runtime's one driver, ``run_pieces``; the chunk length is
the one setting ``CASSHIP_FOLD_CHUNK``): the pieces must not change a single number."""
import numpy as np
import pytest

import casship as cs
from casship.runtime import fold_chunk


def _record(n=1100, dt=0.5):
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(n) * dt
    tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 30.0))})
    data = cs.measure(tr, m, {"psi": 0.01}, seed=3)
    return m, cs.discretize(m, dt), data, cs.Gaussian(m.states(), np.diag([1e-3, 1e-5]))


@pytest.mark.parametrize("kind", ["EKF", "UKF", "EnKF"])
def test_pieces_give_the_same_filter_and_smoother_as_one_piece(kind, monkeypatch):
    m, dm, data, prior = _record()
    options = {"members": 20} if kind == "EnKF" else {}
    est = getattr(cs, kind)(dm, Q=1e-7, R=1e-4, options=options)
    assert len(data) > 2 * fold_chunk()                     # two whole pieces and a padded one
    pieces = est.smooth(data, prior, seed=1)
    one = getattr(cs, kind)(dm, Q=1e-7, R=1e-4, options=options)
    monkeypatch.setenv("CASSHIP_FOLD_CHUNK", "2048")        # the whole record in one padded piece
    assert fold_chunk() == 2048
    whole = one.smooth(data, prior, seed=1)
    for name in ("x", "P", "x_pred", "P_pred", "C", "K", "innovations", "S", "nis", "loglik_terms"):
        np.testing.assert_array_equal(getattr(pieces, name), getattr(whole, name), err_msg=name)


def test_batch_equals_online_across_pieces():
    m, dm, data, prior = _record()
    ekf = cs.EKF(dm, Q=1e-7, R=1e-4)
    res = ekf.filter(data, prior)
    run = ekf.online(prior, u=data.matrix(["delta"])[0])
    U, Y = data.matrix(["delta"]), data.matrix(["psi"])
    for k in range(len(data)):
        x = run.update(Y[k], data.t[k] - data.t[k - 1] if k else 0.0, U[max(k - 1, 0)], U[k])
        np.testing.assert_allclose(x, res.x[k], rtol=1e-12, atol=1e-15)


def test_cached_fold_calls_let_go_of_the_result():
    import gc
    import weakref

    m, dm, data, prior = _record()
    ekf = cs.EKF(dm, Q=1e-7, R=1e-4)
    res = ekf.filter(data, prior)
    assert not res.P.flags.writeable                # results are read-only: shared without a copy
    block = weakref.ref(res.P.base if res.P.base is not None else res.P)
    del res
    gc.collect()
    assert block() is None                      # no cached call keeps the result's memory alive
    np.testing.assert_array_equal(ekf.filter(data, prior).x, ekf.filter(data, prior).x)
