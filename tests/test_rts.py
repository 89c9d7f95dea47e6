"""RTS smoother against an independent textbook implementation, and for the UKF and EKF."""
import numpy as np
import pytest

import casship as cs
from filter_models import linear_record, oscillator

Q, R = 0.05, [0.04, 0.09]


def textbook_rts(x, P, A, B, G, u, Qd):
    """Rauch, Tung & Striebel (1965) with the prediction recomputed from A, B, G."""
    n = x.shape[0]
    xs, Ps = x.copy(), P.copy()
    for k in range(n - 2, -1, -1):
        xp = A @ x[k] + B @ u[k]
        Pp = A @ P[k] @ A.T + G @ Qd @ G.T
        J = P[k] @ A.T @ np.linalg.inv(Pp)
        xs[k] = x[k] + J @ (xs[k + 1] - xp)
        Ps[k] = P[k] + J @ (Ps[k + 1] - Pp) @ J.T
    return xs, Ps


@pytest.fixture(scope="module")
def case():
    m = oscillator()
    dm = cs.discretize(m, 0.1)
    traj, data = linear_record(m, n=400)
    prior = cs.Gaussian([0.0, 0.0], [1.0, 1.0])
    return m, dm, traj, data, prior


def test_rts_equals_textbook(case):
    m, dm, traj, data, prior = case
    res = cs.KF(dm, Q, R).filter(data, prior)
    sm = cs.rts_smooth(res)
    A, B, G = dm.linearize(m.states(), m.inputs())
    xs, Ps = textbook_rts(res.x, res.P, A, B, G, data.matrix(["f"]), np.atleast_2d(Q))
    np.testing.assert_allclose(sm.x, xs, atol=1e-11)
    np.testing.assert_allclose(sm.P, Ps, atol=1e-11)
    assert sm.estimator == "KF+RTS"
    # smoothing reduces the error and every variance
    err = lambda r: np.sqrt(np.mean((r.x - traj.x) ** 2, axis=0))  # noqa: E731
    assert np.all(err(sm) < err(res))
    assert np.all(np.einsum("kii->ki", sm.P) <= np.einsum("kii->ki", res.P) + 1e-15)


def test_rts_ukf_equals_kf_smoother(case):
    m, dm, traj, data, prior = case
    sk = cs.rts_smooth(cs.KF(dm, Q, R).filter(data, prior))
    su = cs.rts_smooth(cs.UKF(dm, Q, R).filter(data, prior))
    np.testing.assert_allclose(su.x, sk.x, atol=1e-11)
    np.testing.assert_allclose(su.P, sk.P, atol=1e-11)


def test_rts_continuous_discrete_ekf(case):
    """Continuous-discrete EKF: C = P Phi' from the integrated sensitivity; the smoother matches the
    textbook one with the exact transition matrix."""
    m, dm, traj, data, prior = case
    ekf = cs.EKF(dm, Q, R, options={"covariance": "continuous", "substeps": 4})
    res = ekf.filter(data, prior)
    sm = cs.rts_smooth(res)
    # rebuild the predictions from the stored ones: textbook with A = Phi from C = P Phi'
    Phi = np.linalg.solve(res.P[0], res.C[1]).T
    for k in range(1, 5):
        np.testing.assert_allclose(res.C[k], res.P[k - 1] @ Phi.T, atol=1e-12)
    xs = res.x.copy()
    for k in range(len(data) - 2, -1, -1):
        J = res.P[k] @ Phi.T @ np.linalg.inv(res.P_pred[k + 1])
        xs[k] = res.x[k] + J @ (xs[k + 1] - res.x_pred[k + 1])
    np.testing.assert_allclose(sm.x, xs, atol=1e-11)


def test_rts_angle_wrap():
    """A heading passing +-pi: the smoothed heading stays continuous on the circle."""
    m = cs.models.nomoto_first_order()
    dm = cs.discretize(m, 0.5)
    t = np.arange(0, 120, 0.5)
    traj = cs.simulate(m, m.states(psi=3.0, r=0.01), t, {"delta": 0.0})
    data = cs.measure(traj, m, {"psi": 0.01}, seed=4)
    res = cs.EKF(dm, 1e-9, 1e-4).filter(data, cs.Gaussian(m.states(psi=3.0, r=0.0), [0.01, 1e-4]))
    sm = cs.rts_smooth(res)
    err = cs.wrap(sm["psi"] - traj["psi"])
    assert np.abs(err).max() < 0.02
    assert np.abs(cs.wrap(np.diff(sm["psi"]))).max() < 0.02


def test_rts_rejects_bad_input(case):
    with pytest.raises(TypeError, match="FilterResult"):
        cs.rts_smooth(case[3])


def test_compiled_backward_pass_equals_interpreted(case):
    m, dm, traj, data, prior = case
    res = cs.KF(dm, Q, R).filter(data.slice(0, 257), prior)      # one fold piece of 256 steps
    try:
        fast = cs.rts_smooth(res, jit=True)
    except RuntimeError as exc:                                   # no C compiler here
        pytest.skip(str(exc))
    ref = cs.rts_smooth(res)
    np.testing.assert_allclose(fast.x, ref.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fast.P, ref.P, rtol=1e-12, atol=1e-13)
