"""The MHE's Gauss-Newton step by the Riccati recursion equals the sparse KKT solve, multipliers included;
the compiled real-time iteration equals the interpreted one; the warm start makes IPOPT's work small."""
import numpy as np
import pytest

import casship as cs


def _ship(nv_full=True, huber=None, R=None):
    model = cs.models.shi_taylor({"c1": 0.001}).with_outputs(["x", "y", "psi"])
    dm = cs.discretize(model, 0.1, "euler")
    Q = np.diag([2e-3, 2e-3, 2e-6]) if nv_full else np.diag([2e-3, 0.0, 2e-6])   # singular Q: fewer v
    R = np.diag([1.0, 1.0, 3e-4]) if R is None else R
    return model, dm, Q, R, huber


def _random_window(mhe, N, rng, missing=False):
    win = mhe.window(N)
    m = mhe.model
    nx, nu, ny = m.nx, m.nu, mhe.ny
    z = np.zeros(win.nz)
    X = np.array([6.0, 0.1, 0.01, 10.0, 5.0, 0.3]) + 0.1 * rng.standard_normal((N + 1, nx))
    z[win.ix] = X
    z[win.iv] = 0.3 * rng.standard_normal(win.iv.shape)
    A = rng.standard_normal((nx, nx))
    W = np.linalg.cholesky(np.linalg.inv(A @ A.T + nx * np.eye(nx))).T
    Y = X[:, 3:] + 0.5 * rng.standard_normal((N + 1, ny))
    M = np.ones((N + 1, ny))
    if missing:
        M[rng.random((N + 1, ny)) < 0.3] = 0.0
        Y[M == 0] = 0.0
    U = np.column_stack([0.2 * np.sign(rng.standard_normal(N + 1)), np.full(N + 1, 1.5)])
    par = np.concatenate([X[0] + 0.05 * rng.standard_normal(nx), W.ravel(order="F"), U.ravel(), U[:N].ravel(),
                          Y.ravel(), M.ravel(), np.full(N, 0.1), m.params()])
    return win, z, par


def _steps(win, z, par, multipliers):
    out = {}
    for method in ("riccati", "kkt"):
        call = win.make_gn(multipliers, method)
        call["z"], call["p"] = z, par
        call()
        out[method] = {k: call.out(k).ravel().copy() for k in call.names_out}
    return out


@pytest.mark.parametrize("case", ["plain", "missing rows", "singular Q", "huber", "correlated R"])
@pytest.mark.parametrize("N", [1, 4, 12])
def test_riccati_step_equals_kkt_solve(case, N):
    R = np.array([[1.0, 0.3, 0.0], [0.3, 1.0, 0.0], [0.0, 0.0, 3e-4]]) if case == "correlated R" else None
    model, dm, Q, R, _ = _ship(nv_full=case != "singular Q", R=R)
    opts = {"horizon": N, "solver": "rti", **({"huber": 1.0} if case == "huber" else {})}
    mhe = cs.MHE(dm, Q, R, options=opts)
    rng = np.random.default_rng(N)
    win, z, par = _random_window(mhe, N, rng, missing=case == "missing rows")
    out = _steps(win, z, par, multipliers=True)
    dz_ref = out["kkt"]["z_next"] - z
    np.testing.assert_allclose(out["riccati"]["z_next"] - z, dz_ref, rtol=1e-8, atol=1e-10 * np.abs(dz_ref).max())
    lam_ref = out["kkt"]["lam_g"]
    np.testing.assert_allclose(out["riccati"]["lam_g"], lam_ref, rtol=1e-7, atol=1e-9 * np.abs(lam_ref).max())
    assert np.abs(dz_ref).max() > 1e-3                       # a real step, not a fixed point


def test_multiplier_free_step_is_the_same_step():
    model, dm, Q, R, _ = _ship()
    mhe = cs.MHE(dm, Q, R, options={"horizon": 6, "solver": "rti"})
    win, z, par = _random_window(mhe, 6, np.random.default_rng(1))
    a, b = _steps(win, z, par, False), _steps(win, z, par, True)
    np.testing.assert_array_equal(a["riccati"]["z_next"], b["riccati"]["z_next"])
    assert set(a["riccati"]) == {"z_next"}


def _record(duration=20.0, seed=0):
    from benchmarks.bench_mhe import problem

    return problem(duration, seed)


def test_compiled_rti_equals_interpreted_rti():
    """jit: the Riccati step compiled to C; without: the KKT solve interpreted. Same estimates."""
    model, dm, data, prior, Q, R = _record()
    fast = cs.MHE(dm, Q, R, options={"horizon": 15, "solver": "rti", "jit": True}).filter(data, prior)
    slow = cs.MHE(dm, Q, R, options={"horizon": 15, "solver": "rti"}).filter(data, prior)
    np.testing.assert_allclose(fast.x, slow.x, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(fast.P, slow.P, rtol=1e-9, atol=1e-12)


def test_ipopt_warm_start_converges_to_the_same_windows():
    """IPOPT from the Gauss-Newton warm start reaches the same optimum as the SQP solver iterated to
    convergence, and within two iterations per window on this record (``max_iter = 2``: more would
    raise ``MHEFailed``)."""
    model, dm, data, prior, Q, R = _record(10.0)
    res = cs.MHE(dm, Q, R, options={"horizon": 10, "solver": "ipopt", "max_iter": 2}).filter(data, prior)
    sqp = cs.MHE(dm, Q, R, options={"horizon": 10, "solver": "sqp"}).filter(data, prior)
    np.testing.assert_allclose(res.x, sqp.x, rtol=1e-6, atol=1e-6)
    with pytest.raises(cs.estimators.MHEFailed, match="Maximum_Iterations_Exceeded"):
        cs.MHE(dm, Q, R, options={"horizon": 10, "solver": "ipopt", "max_iter": 0, "huber": 0.5}).filter(data, prior)
