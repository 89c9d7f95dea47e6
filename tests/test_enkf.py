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
    rng = np.random.default_rng(7)
    X = enkf.ensemble(prior, rng)
    Y, U = data.matrix(["y1", "y2"]), data.matrix(["f"])
    for k in range(len(data)):
        X, info = enkf.step(X, U[max(k - 1, 0)], Y[k], 0.0 if k == 0 else 0.1, u=U[k], rng=rng)
        np.testing.assert_allclose(info["x"], a.x[k], atol=1e-12, rtol=1e-12)
        np.testing.assert_allclose(info["P"], a.P[k], atol=1e-12, rtol=1e-12)


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
    enkf = cs.EnKF(dm, Q, R, options={"members": 5})
    with pytest.raises(TypeError, match="rng"):
        enkf.step(np.zeros((2, 5)), [0.0], [0.0, 0.0], 0.1)


def test_online_runner_reproduces_seeded_batch(case):
    m, dm, traj, data, prior = case
    enkf = cs.EnKF(dm, Q, R, options={"members": 25})
    res = enkf.filter(data, prior, seed=11)
    run = enkf.online(prior, seed=11, u=data["f"][:1])
    Y, U = data.matrix(["y1", "y2"]), data.matrix(["f"])
    for k in range(len(data)):
        x = run.update(Y[k], 0.0 if k == 0 else 0.1, u_prev=U[max(k - 1, 0)], u=U[k])
        np.testing.assert_allclose(x, res.x[k], rtol=1e-12, atol=1e-12)
