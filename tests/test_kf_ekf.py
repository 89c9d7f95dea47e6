"""KF and EKF: analytic answers (dlqe, Van Loan), a plain-numpy reference EKF, online = batch."""
import control
import numpy as np
import pytest

import casship as cs
from filter_models import oscillator_case

Q, R = 0.05, [0.04, 0.09]


@pytest.fixture(scope="module")
def linear_case():
    return oscillator_case(500)


def test_kf_equals_ekf_and_dlqe(linear_case):
    m, dm, traj, data, prior = linear_case
    kf = cs.KF(dm, Q, R).filter(data, prior)
    ekf = cs.EKF(dm, Q, R).filter(data, prior)
    np.testing.assert_allclose(kf.x, ekf.x, atol=1e-14)
    np.testing.assert_allclose(kf.P, ekf.P, atol=1e-14)
    A, _, G = dm.linearize(m.states(), m.inputs())
    H = np.array(m.h_jac(m.states(), m.inputs(), m.params())[0])
    L, P, _ = control.dlqe(A, G, H, np.atleast_2d(Q), np.diag(R))
    np.testing.assert_allclose(kf.P_pred[-1], P, rtol=1e-10)
    K = kf.P_pred[-1] @ H.T @ np.linalg.inv(kf.S[-1])          # filter gain; dlqe gives the predictor gain A K
    np.testing.assert_allclose(A @ K, L, rtol=1e-9)
    np.testing.assert_allclose(kf.K[-1], K, rtol=1e-9)           # the result carries the gain applied
    L2, P2 = cs.KF(dm, Q, R).steady_state()                     # python-control on the exact linearisation
    np.testing.assert_allclose(L2, L, rtol=1e-12)
    np.testing.assert_allclose(P2, P, rtol=1e-12)


def test_continuous_discrete_covariance_equals_van_loan(linear_case):
    m, dm, traj, data, prior = linear_case
    ekf = cs.EKF(dm, Q, R, options={"covariance": "continuous", "substeps": 16})
    res = ekf.filter(data.slice(0, 5), prior)
    A = np.array(m.f_jac(m.states(), m.inputs(), m.params(), [0.0])[0])
    G = np.array(m.f_jac(m.states(), m.inputs(), m.params(), [0.0])[3])
    Ad, Qd = cs.van_loan(A, G, np.atleast_2d(Q) * 0.1, 0.1)       # the spectral density of Q is Q dt
    for k in range(1, 5):
        np.testing.assert_allclose(res.P_pred[k], Ad @ res.P[k - 1] @ Ad.T + Qd, rtol=1e-9, atol=1e-13)


def test_kf_refuses_nonlinear_model():
    with pytest.raises(ValueError, match="not linear"):
        cs.KF(cs.discretize(cs.models.sog_cog(), 0.1), Q=[1e-3, 1e-4], R=1.0)


def _sog_with_range():
    """SOG/COG model with a nonlinear range output and a course (angle) output."""
    import casadi as ca

    m = cs.models.sog_cog()
    return m.with_outputs({"rng": lambda b: ca.sqrt(b.sym("x_n") ** 2 + b.sym("y_n") ** 2 + 1.0),
                           "chi_m": lambda b: b.sym("chi")}, name="sog_range")


def numpy_reference_ekf(Y, dt, alpha1, alpha2, Qd, Rm, x0, P0):
    """Textbook EKF with hand-written Euler Jacobians, Joseph update, wrapped course residual."""
    x, P = x0.copy(), P0.copy()
    out = []
    for k in range(Y.shape[0]):
        h = 0.0 if k == 0 else dt
        xn, yn, U, chi, om = x
        x = x + h * np.array([U * np.cos(chi), U * np.sin(chi), -alpha1 * U, om, -alpha2 * om])
        A = np.eye(5)
        A[0, 2], A[0, 3] = h * np.cos(chi), -h * U * np.sin(chi)
        A[1, 2], A[1, 3] = h * np.sin(chi), h * U * np.cos(chi)
        A[2, 2], A[3, 4], A[4, 4] = 1 - h * alpha1, h, 1 - h * alpha2
        G = np.zeros((5, 2))
        G[2, 0], G[4, 1] = h, h
        P = A @ P @ A.T + G @ Qd @ G.T
        ok = np.isfinite(Y[k])
        if ok.any():
            rho = np.sqrt(x[0] ** 2 + x[1] ** 2 + 1.0)
            H = np.array([[x[0] / rho, x[1] / rho, 0, 0, 0], [0, 0, 0, 1, 0]])[ok]
            e = (Y[k] - np.array([rho, x[3]]))[ok]
            if ok[1]:
                e[-1] = np.arctan2(np.sin(e[-1]), np.cos(e[-1]))
            Rk = Rm[np.ix_(ok, ok)]
            S = H @ P @ H.T + Rk
            K = P @ H.T @ np.linalg.inv(S)
            x = x + K @ e
            IKH = np.eye(5) - K @ H
            P = IKH @ P @ IKH.T + K @ Rk @ K.T
        out.append((x.copy(), P.copy()))
    return out


def test_ekf_equals_numpy_reference_on_nonlinear_model():
    m = _sog_with_range()
    dt = 0.1
    dm = cs.discretize(m, dt, method="euler")
    t = np.arange(300) * dt
    traj = cs.simulate(m, m.states(x_n=20.0, y_n=-5.0, U=3.0, chi=3.0, omega_chi=0.05), t, method="euler")
    data = cs.measure(traj, m, {"rng": 0.5, "chi_m": 0.05}, rates={"rng": 2.0}, seed=11)
    Qd, Rm = np.diag([1e-2, 1e-3]), np.diag([0.25, 0.0025])
    x0 = m.states(x_n=18.0, y_n=-3.0, U=2.0, chi=-3.1, omega_chi=0.0)
    P0 = np.diag([9.0, 9.0, 1.0, 0.1, 0.01])
    res = cs.EKF(dm, Qd, Rm).filter(data, cs.Gaussian(x0, P0))
    ref = numpy_reference_ekf(data.matrix(["rng", "chi_m"]), dt, 0.01, 0.1, Qd, Rm, x0, P0)
    for k, (x, P) in enumerate(ref):
        np.testing.assert_allclose(res.x[k], x, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(res.P[k], P, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("cls", [cs.EKF, cs.UKF])
def test_online_equals_batch(cls):
    m = _sog_with_range()
    dm = cs.discretize(m, 0.1, method="rk4")
    t = np.arange(150) * 0.1
    traj = cs.simulate(m, m.states(x_n=20.0, U=3.0, chi=3.0, omega_chi=0.05), t)
    data = cs.measure(traj, m, {"rng": 0.5, "chi_m": 0.05}, rates={"rng": 2.0}, seed=2)
    data = data.with_columns(chi_m=data["chi_m"] + np.where(np.arange(150) == 60, 0.5, 0.0))   # an outlier
    est = cls(dm, [1e-2, 1e-3], [0.25, 0.0025], options={"gate": 0.999, "outputs": "all"})
    prior = cs.Gaussian(m.states(x_n=18.0, U=2.0, chi=3.1), [9.0, 9.0, 1.0, 0.1, 0.01])
    res = est.filter(data, prior)
    assert 0 < res.rejected.sum() < len(data)                   # the gate acts on this record
    run = est.online(prior)
    Y = data.matrix(["rng", "chi_m"])
    for k in range(len(data)):
        x = run.update(Y[k], 0.0 if k == 0 else 0.1)
        np.testing.assert_allclose(x, res.x[k], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(run.P, res.P[k], rtol=1e-12, atol=1e-12)
        assert run.info["rejected"] == res.rejected[k]
        assert run.info["nis"] == pytest.approx(res.nis[k], rel=1e-12, abs=1e-12)
        np.testing.assert_allclose(run.info["K"], res.K[k], rtol=1e-12, atol=1e-12)


def test_persistence_kf():
    m = cs.persistence_model(["u", "psi"])
    dm = cs.discretize(m, 0.1)
    rng = np.random.default_rng(0)
    t = np.arange(200) * 0.1
    data = cs.Dataset(t, {"u": 2.0 + 0.1 * rng.standard_normal(t.size),
                          "psi": cs.wrap(np.pi + 0.05 * rng.standard_normal(t.size))})
    res = cs.KF(dm, 1e-6, [0.01, 0.0025]).filter(data, cs.Gaussian([0.0, 3.0], [10.0, 1.0]))
    assert res["u"][-1] == pytest.approx(2.0, abs=0.05)
    assert abs(cs.wrap(res["psi"][-1] - np.pi)) < 0.02


def test_online_runner_and_jit_equal_batch():
    """``online()`` keeps the memory in the step's buffers; ``jit`` compiles the step and folds to C:
    both give the batch numbers."""
    m = _sog_with_range()
    dm = cs.discretize(m, 0.1, method="euler")
    t = np.arange(700) * 0.1          # > one fold piece of 512 samples plus a padded remainder
    traj = cs.simulate(m, m.states(x_n=20.0, U=3.0, chi=3.0, omega_chi=0.05), t, method="euler")
    data = cs.measure(traj, m, {"rng": 0.5, "chi_m": 0.05}, rates={"rng": 2.0}, seed=2)
    prior = cs.Gaussian(m.states(x_n=18.0, U=2.0, chi=3.1), [9.0, 9.0, 1.0, 0.1, 0.01])
    ekf = cs.EKF(dm, [1e-2, 1e-3], [0.25, 0.0025], options={"outputs": ("x", "P", "nis")})
    res = ekf.filter(data, prior)
    run = ekf.online(prior)
    Y = data.matrix(["rng", "chi_m"])
    X = np.array([run.update(Y[k], 0.0 if k == 0 else 0.1) for k in range(len(data))])
    np.testing.assert_allclose(X, res.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(run.P, res.P[-1], rtol=1e-12, atol=1e-12)
    assert run.info["nis"] == pytest.approx(res.nis[-1], rel=1e-12)
    with pytest.raises(KeyError, match="'ll' is not among the diagnostics"):
        run.info["ll"]                            # lean: only what the options asked for is computed
    fast = cs.EKF(dm, [1e-2, 1e-3], [0.25, 0.0025], options={"jit": True})
    res_jit = fast.filter(data, prior)
    np.testing.assert_allclose(res_jit.x, res.x, rtol=1e-11, atol=1e-11)
    np.testing.assert_allclose(res_jit.P, res.P, rtol=1e-11, atol=1e-11)
    run_jit = fast.online(prior)
    X_jit = np.array([run_jit.update(Y[k], 0.0 if k == 0 else 0.1) for k in range(len(data))])
    np.testing.assert_allclose(X_jit, res.x, rtol=1e-11, atol=1e-11)
