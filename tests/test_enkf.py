"""EnKF: seeded reproducibility, online = batch, convergence to the KF with many members."""
import numpy as np
import pytest

import casship as cs
from filter_models import oscillator_case

Q, R = 0.05, [0.04, 0.09]


@pytest.fixture(scope="module")
def case():
    return oscillator_case(120)


def test_seeded_and_online_equals_batch(case):
    m, dm, traj, data, prior = case
    enkf = cs.EnKF(dm, Q, R, options={"members": 30})
    a = enkf.filter(data, prior, seed=7)
    b = enkf.filter(data, prior, seed=7)
    c = enkf.filter(data, prior, seed=8)
    np.testing.assert_array_equal(a.x, b.x)
    assert np.abs(a.x - c.x).max() > 1e-6
    # the step Function by its named slots, with the draws in the order filter() takes them
    rng = np.random.default_rng(7)
    X = enkf.ensemble(prior, rng)
    Y, U = data.matrix(["y1", "y2"]), data.matrix(["f"])
    step = enkf.step
    assert step.name_in()[0] == "X" and step.name_out()[:3] == ["X", "x", "P"]
    for k in range(len(data)):
        z = rng.standard_normal(3 * 30)
        ok = np.isfinite(Y[k])
        out = step(X=X, u_prev=U[max(k - 1, 0)], u=U[k], y=np.where(ok, Y[k], 0.0), mask=ok, dt=0.1 if k else 0.0,
                   p=m.params(), Q=enkf.Q, R=enkf.R, gate=np.inf, z_w=z[:30].reshape(1, 30),
                   z_v=z[30:].reshape(30, 2).T)
        X = np.array(out["X"])
        np.testing.assert_allclose(np.array(out["x"]).ravel(), a.x[k], atol=1e-12, rtol=1e-12)
        np.testing.assert_allclose(np.array(out["P"]), a.P[k], atol=1e-12, rtol=1e-12)


def test_large_ensemble_approaches_kf(case):
    """With many members the ensemble mean approaches the KF mean (Monte Carlo error ~ 1/sqrt(N))."""
    m, dm, traj, data, prior = case
    kf = cs.KF(dm, Q, R).filter(data, prior)
    errs = []
    for N in (20, 500):
        res = cs.EnKF(dm, Q, R, options={"members": N}).filter(data.slice(0, 60), prior, seed=1)
        errs.append(np.abs(res.x - kf.x[:60]).mean())
    kf_std = kf.std[:60].mean()
    assert errs[1] < 0.25 * kf_std
    assert errs[1] < errs[0]


def test_chi_square_consistency_of_ensemble(case):
    """NEES of the EnKF (N = 100) over time is consistent with its own covariance."""
    m, dm, traj, data, prior = case
    res = cs.EnKF(dm, Q, R).filter(data, prior, seed=3)
    nees = res.nees(traj.x)[10:]
    assert 1.0 < nees.mean() < 3.2   # 2 states; sampling error of N = 100 inflates NEES slightly


def test_enkf_angle_heading_across_pi():
    m = cs.models.nomoto_first_order()
    dm = cs.discretize(m, 0.5)
    t = np.arange(0, 60, 0.5)
    traj = cs.simulate(m, m.states(psi=3.05, r=0.01), t, {"delta": 0.0})
    data = cs.measure(traj, m, {"psi": 0.01}, seed=4)
    res = cs.EnKF(dm, 1e-8, 1e-4, options={"members": 50}).filter(
        data, cs.Gaussian(m.states(psi=-3.1, r=0.0), [0.01, 1e-4]), seed=2)
    err = cs.wrap(res["psi"] - traj["psi"])
    assert np.abs(err).max() < 0.1
    assert res.std[:, 0].max() < 0.15


def test_bad_options(case):
    _, dm, *_ = case
    with pytest.raises(ValueError, match="members"):
        cs.EnKF(dm, Q, R, options={"members": 1})
    with pytest.raises(ValueError, match="members"):
        cs.EnKF(dm, Q, R, options={"members": 2.5})
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['member'\]"):
        cs.EnKF(dm, Q, R, options={"member": 5})


def test_online_runner_reproduces_seeded_batch(case):
    m, dm, traj, data, prior = case
    enkf = cs.EnKF(dm, Q, R, options={"members": 25})
    res = enkf.filter(data, prior, seed=11)
    run = enkf.online(prior, seed=11, u=data["f"][:1])
    Y, U = data.matrix(["y1", "y2"]), data.matrix(["f"])
    for k in range(len(data)):
        x = run.update(Y[k], 0.0 if k == 0 else 0.1, u_prev=U[max(k - 1, 0)], u=U[k])
        np.testing.assert_allclose(x, res.x[k], rtol=1e-12, atol=1e-12)


def test_one_pass_moments_equal_the_two_pass_sample_moments():
    """Means (angles on the circle) and sample covariances from the member sums of ``_moments``
    equal NumPy's two-pass ones, also for an angle row whose members straddle +-pi."""
    import casadi as ca

    from casship.estimators.enkf import _moments

    rng = np.random.default_rng(7)
    N = 40
    A = rng.normal([[5.0], [-2.0], [np.pi - 0.05]], [[1.0], [0.3], [0.1]], size=(3, N))
    A[2] = cs.wrap(A[2])                                     # some near +pi, some near -pi
    B = rng.normal(size=(2, N)) + 0.5 * A[:2]
    XA, XB = ca.MX.sym("A", 3, N), ca.MX.sym("B", 2, N)
    means, covs = _moments("test_moments", {"a": XA, "b": XB}, {"a": [False, False, True], "b": [False, False]},
                           [("a", "b"), ("a", "a")], N)
    f = ca.Function("f", [XA, XB], [means["a"], means["b"], covs["a", "b"], covs["a", "a"]])
    mean_a, mean_b, cov_ab, cov_aa = (np.array(v) for v in f(A, B))
    da = A - A[:, :1]
    da[2] = cs.wrap(da[2])
    expect_a = A[:, 0] + da.mean(axis=1)
    np.testing.assert_allclose(mean_a.ravel(), expect_a, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(mean_b.ravel(), B.mean(axis=1), rtol=1e-12, atol=1e-12)
    dev_a = da - da.mean(axis=1, keepdims=True)
    dev_b = B - B.mean(axis=1, keepdims=True)
    np.testing.assert_allclose(cov_aa, dev_a @ dev_a.T / (N - 1), rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(cov_ab, dev_a @ dev_b.T / (N - 1), rtol=1e-11, atol=1e-13)
    assert np.array_equal(cov_aa, cov_aa.T)
    assert abs(cs.wrap(mean_a[2, 0] - np.pi)) < 0.1           # the circular mean, not ~0
