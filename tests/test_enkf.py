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
