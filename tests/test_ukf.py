"""UKF: equality with the KF on linear models, unscented-transform exactness, online = batch."""
import numpy as np
import pytest

import casship as cs
from filter_models import linear_record, oscillator

Q, R = 0.05, [0.04, 0.09]


@pytest.fixture(scope="module")
def linear_case():
    m = oscillator()
    dm = cs.discretize(m, 0.1)
    traj, data = linear_record(m)
    return m, dm, traj, data, cs.Gaussian([0.0, 0.0], [1.0, 1.0])


@pytest.mark.parametrize("opts", [{}, {"alpha": 0.5, "beta": 2.0, "kappa": 1.0}, {"kappa": 0.5}])
def test_ukf_equals_kf_on_linear_model(linear_case, opts):
    m, dm, traj, data, prior = linear_case
    kf = cs.KF(dm, Q, R).filter(data, prior)
    ukf = cs.UKF(dm, Q, R, options=opts).filter(data, prior)
    np.testing.assert_allclose(ukf.x, kf.x, atol=1e-12)
    np.testing.assert_allclose(ukf.P, kf.P, atol=1e-12)
    np.testing.assert_allclose(ukf.C, kf.C, atol=1e-12)
    np.testing.assert_allclose(ukf.loglik, kf.loglik, rtol=1e-12)


def test_ukf_missing_channels_equal_kf(linear_case):
    m, dm, traj, data, prior = linear_case
    y1 = np.where(np.arange(len(data)) % 3 == 0, data["y1"], np.nan)
    data2 = data.with_columns(y1=y1)
    kf = cs.KF(dm, Q, R).filter(data2, prior)
    ukf = cs.UKF(dm, Q, R).filter(data2, prior)
    np.testing.assert_allclose(ukf.x, kf.x, atol=1e-12)
    assert np.isnan(ukf.innovations[1, 0]) and np.isfinite(ukf.innovations[1, 1])


def test_seed_weights():
    c, wm, wc = cs.estimators.ukf.sigma_weights(6, 1.0, 0.0, 3.0)
    assert c == 9.0 and wm[0] == pytest.approx(3 / 9) and wm[1] == pytest.approx(1 / 18)
    assert wm.sum() == pytest.approx(1.0) and np.array_equal(wm, wc)
    with pytest.raises(ValueError, match="n \\+ lambda"):
        cs.estimators.ukf.sigma_weights(2, 1.0, 0.0, -3.0)


def test_unscented_transform_exact_for_quadratic():
    """Euler step of x' = x^2: E[x + dt x^2] = m + dt (m^2 + P) exactly, var adds dt^2 (4 m^2 P + 2 P^2)."""
    b = cs.ModelBuilder("quad")
    x = b.state("x")
    b.ode(x=x**2 + b.noise("w"))
    b.output("y", x)
    m = b.build()
    dt, mean, var = 0.1, 0.7, 0.2
    ukf = cs.UKF(cs.discretize(m, dt, method="euler"), Q=0.0, R=1.0, options={"kappa": 2.0})
    data = cs.Dataset([0.0, dt], {"y": [np.nan, np.nan]})
    res = ukf.filter(data, cs.Gaussian([mean], [[var]]))
    assert res.x_pred[1, 0] == pytest.approx(mean + dt * (mean**2 + var), abs=1e-14)
    # kappa = 2 (n + kappa = 3) matches the Gaussian fourth moment, so the variance is exact too
    exact_var = var * (1 + 2 * dt * mean) ** 2 + dt**2 * 2 * var**2
    assert res.P_pred[1, 0, 0] == pytest.approx(exact_var, rel=1e-12)


def test_unknown_option_named(linear_case):
    _, dm, *_ = linear_case
    with pytest.raises(ValueError, match="lamda"):
        cs.UKF(dm, Q, R, options={"lamda": 1.0})


def test_ukf_online_equals_batch():
    m = cs.models.sog_cog()
    dm = cs.discretize(m, 0.1, method="euler")
    t = np.arange(200) * 0.1
    traj = cs.simulate(m, m.states(U=2.0, chi=3.0, omega_chi=0.02), t)
    data = cs.measure(traj, m, {"x_n": 1.0, "y_n": 1.0}, rates={"x_n": 2.0, "y_n": 2.0}, seed=3)
    ukf = cs.UKF(dm, Q=[1e-3, 1e-4], R=1.0)
    prior = cs.Gaussian(m.states(x_n=0.0, y_n=0.0, U=1.5, chi=2.9), [4.0, 4.0, 1.0, 0.1, 1e-3])
    res = ukf.filter(data, prior)
    run = ukf.online(prior)
    Y = data.matrix(["x_n", "y_n"])
    for k in range(len(data)):
        x = run.update(Y[k], 0.0 if k == 0 else 0.1)
        np.testing.assert_allclose(x, res.x[k], atol=1e-12, rtol=1e-12)
        np.testing.assert_allclose(run.P, res.P[k], atol=1e-12, rtol=1e-12)
    assert np.sqrt(np.mean((res["U"][100:] - 2.0) ** 2)) < 0.3
