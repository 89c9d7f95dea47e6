"""Kalman-Bucy filter: steady state equals control.lqe; agrees with the discrete KF for small steps.

``Q`` and ``R`` have the one meaning of every estimator (covariances over a sampling interval);
the filter's spectral densities are ``Qc = Q dt`` and ``Rc = R dt``.
"""
import control
import numpy as np
import pytest

import casship as cs
from casship.estimators.rts import rts_smooth
from filter_models import linear_record, oscillator

Qc, R = 0.05, [0.04, 0.09]
Q = Qc / 0.1                    # the covariance over the 0.1 s step whose spectral density is Qc


@pytest.fixture(scope="module")
def case():
    m = oscillator()
    dm = cs.discretize(m, 0.1)
    traj, data = linear_record(m, n=600, q=Qc / 0.1)
    return m, dm, traj, data


def _lqe(m, R):
    z = (m.states(), m.inputs(), m.params(), [0.0])
    A, G = np.array(m.f_jac(*z)[0]), np.array(m.f_jac(*z)[3])
    H = np.array(m.h_jac(*z[:3])[0])
    L, P, _ = control.lqe(A, G, H, np.atleast_2d(Qc), np.diag(R) * 0.1)
    return L, P, H


@pytest.mark.parametrize("integrator", ["auto", "rk4"])
def test_riccati_converges_to_lqe(case, integrator):
    """The default integrator (and plain RK4) has the algebraic Riccati solution as its fixed point."""
    m, dm, traj, data = case
    kb = cs.KalmanBucy(dm, Q, R, options={"integrator": integrator})
    res = kb.filter(data, cs.Gaussian([0.0, 0.0], [0.01, 0.01]))
    L, P, H = _lqe(m, R)
    np.testing.assert_allclose(res.P[-1], P, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(res.K[-1], L, rtol=1e-8)
    L2, P2 = kb.steady_state()
    np.testing.assert_allclose(L2, L, rtol=1e-12)
    np.testing.assert_allclose(P2, P, rtol=1e-12)
    np.testing.assert_allclose(L2, P @ H.T @ np.linalg.inv(np.diag(R) * 0.1), rtol=1e-8)


def test_split_integrator_second_order_and_stable(case):
    """The default splitting survives a vague prior (where RK4 with the same sub-steps diverges)
    and its stationary covariance approaches the ARE solution at second order in the sub-step."""
    m, dm, traj, data = case
    L, P, H = _lqe(m, R)
    prior = cs.Gaussian([0.0, 0.0], [1e4, 1e4])
    errs = []
    for sub in (5, 10, 20):
        res = cs.KalmanBucy(dm, Q, R, options={"substeps": sub, "integrator": "split"}).filter(data.slice(0, 300), prior)
        assert np.all(np.isfinite(res.x))
        errs.append(np.abs(res.P[-1] - P).max() / np.abs(P).max())
    assert errs[2] < 1e-3
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.5)), ratios
    rk4 = cs.KalmanBucy(dm, Q, R, options={"integrator": "rk4", "substeps": 5}).filter(data.slice(0, 20), prior)
    assert not np.all(np.isfinite(rk4.P))
    # the default switches to the splitting where RK4 would diverge, and is exact in the steady state
    auto = cs.KalmanBucy(dm, Q, R, options={"substeps": 5}).filter(data.slice(0, 300), prior)
    assert np.all(np.isfinite(auto.P)) and auto.health().not_pd.size == 0
    np.testing.assert_allclose(auto.P[-1], P, rtol=1e-8, atol=1e-12)


def test_steady_state_filter_uses_lqe_gain(case):
    """With the constant gain the estimate follows dx/dt = A x + B u + L (y - C x) exactly (checked
    against scipy's matrix exponential for a held sample)."""
    import scipy.linalg

    m, dm, traj, data = case
    kb = cs.KalmanBucy(dm, Q, R, options={"steady_state": True, "substeps": 20})
    L, P = kb.steady_state()
    res = kb.filter(data.slice(0, 50), cs.Gaussian([0.3, 0.0], [1.0, 1.0]))
    np.testing.assert_allclose(res.P[-1], P, rtol=1e-12)
    A = np.array(m.f_jac(m.states(), m.inputs(), m.params(), [0.0])[0])
    B = np.array(m.f_jac(m.states(), m.inputs(), m.params(), [0.0])[1])
    H = np.array(m.h_jac(m.states(), m.inputs(), m.params())[0])
    Acl = A - L @ H
    y, u = data.matrix(["y1", "y2"])[1], data["f"][0]
    M = np.zeros((3 + 2, 3 + 2))
    M[:2, :2] = Acl
    M[:2, 2:4] = L
    M[:2, 4:] = B
    E = scipy.linalg.expm(M * 0.1)
    x1 = E[:2, :2] @ res.x[0] + E[:2, 2:4] @ y + E[:2, 4:] @ [u]
    np.testing.assert_allclose(res.x[1], x1, rtol=1e-9, atol=1e-12)


def test_close_to_discrete_kf_for_fast_sampling():
    """At a short step the Kalman-Bucy estimate approaches the discrete KF with Qd = Qc / dt
    held noise (same G Qc G' dt) and the same sampled R."""
    m = oscillator()
    dt = 0.01
    dm = cs.discretize(m, dt, method="euler")
    traj, data = linear_record(m, dt=dt, n=2000, q=Qc / dt, seed=5)
    prior = cs.Gaussian([1.0, 0.0], [0.1, 0.1])
    kb = cs.KalmanBucy(dm, Qc / dt, R, options={"substeps": 2}).filter(data, prior)
    kf = cs.KF(dm, Qc / dt, R).filter(data, prior)          # the same Q and R for both
    # Tomera's derivation: the discrete steady gain over dt tends to the Kalman-Bucy gain
    z = (m.states(), m.inputs(), m.params(), [0.0])
    H = np.array(m.h_jac(*z[:3])[0])
    L = cs.KalmanBucy(dm, Qc / dt, R).steady_state()[0]
    gaps = []
    for h in (0.01, 0.001):
        A, _, G = cs.discretize(m, h, method="euler").linearize(m.states(), m.inputs())
        K, _, _ = control.dlqe(A, G, H, np.atleast_2d(Qc / h), np.diag(R) * 0.01 / h)
        gaps.append(np.abs(K / h - L).max() / np.abs(L).max())
    assert gaps[1] < 0.2 * gaps[0] and gaps[1] < 0.02
    # same accuracy against the truth
    rmse = lambda r: np.sqrt(np.mean((r.x[500:] - traj.x[500:]) ** 2, axis=0))  # noqa: E731
    np.testing.assert_allclose(rmse(kb), rmse(kf), rtol=0.1)


def test_smoothing_refused_and_gate_unavailable(case):
    m, dm, traj, data = case
    kb = cs.KalmanBucy(dm, Q, R)
    prior = cs.Gaussian([0.0, 0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="KalmanBucy has no smoother"):
        kb.smooth(data.slice(0, 20), prior)
    with pytest.raises(ValueError, match="KalmanBucy"):
        rts_smooth(kb.filter(data.slice(0, 20), prior))
    with pytest.raises(ValueError, match="gate"):
        cs.KalmanBucy(dm, Q, R, options={"gate": 0.99})
