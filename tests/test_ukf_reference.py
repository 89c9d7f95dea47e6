"""The UKF against independent answers at ``alpha != 1``: filterpy's scaled unscented filter on a
nonlinear record, and the unscented transform of a quadratic against its analytic moments."""
import casadi as ca
import numpy as np
import pytest

import casship as cs

DT = 0.2
Q = np.diag([1e-3, 4e-3])
R = np.diag([0.02, 0.05])
M0, P0 = np.array([0.8, -0.3]), np.array([[0.3, 0.05], [0.05, 0.2]])


def pendulum():
    """Discrete-time damped pendulum with a range-like and a product measurement (both nonlinear)."""
    b = cs.ModelBuilder("pendulum-dt", "nonlinear test model", dt=DT)
    x1, x2 = b.state("x1"), b.state("x2")
    b.next(x1=x1 + DT * x2 + b.noise("w1"), x2=x2 - DT * (0.8 * ca.sin(x1) + 0.2 * x2**3) + b.noise("w2"))
    b.output("y1", ca.sqrt(x1**2 + 1.0))
    b.output("y2", x1 * x2)
    return b.build()


def fx(x, dt):
    return np.array([x[0] + DT * x[1], x[1] - DT * (0.8 * np.sin(x[0]) + 0.2 * x[1] ** 3)])


def hx(x):
    return np.array([np.sqrt(x[0] ** 2 + 1.0), x[0] * x[1]])


def record(n=80, seed=2):
    rng = np.random.default_rng(seed)
    x = M0 + np.linalg.cholesky(P0) @ rng.standard_normal(2)
    Y = np.zeros((n, 2))
    for k in range(n):
        Y[k] = hx(x) + np.sqrt(np.diag(R)) * rng.standard_normal(2)
        x = fx(x, DT) + np.sqrt(np.diag(Q)) * rng.standard_normal(2)
    Y[[7, 8, 40]] = np.nan                          # samples with nothing measured: predict only
    return cs.Dataset(np.arange(n) * DT, {"y1": Y[:, 0], "y2": Y[:, 1]}), Y


# (alpha, beta, kappa): a positive central covariance weight (sigma-point Joseph update) and a negative one
@pytest.mark.parametrize("alpha, beta, kappa", [(0.5, 2.0, 1.0), (0.3, 2.0, 0.0), (1.5, 0.0, 0.5)])
def test_ukf_equals_filterpy_at_alpha_not_one(alpha, beta, kappa):
    filterpy = pytest.importorskip("filterpy.kalman", reason="filterpy is not installed: no peer to compare with")
    data, Y = record()
    res = cs.UKF(cs.discretize(pendulum()), Q, R, options={"alpha": alpha, "beta": beta, "kappa": kappa}).filter(
        data, cs.Gaussian(M0, P0))
    points = filterpy.MerweScaledSigmaPoints(2, alpha=alpha, beta=beta, kappa=kappa)
    ukf = filterpy.UnscentedKalmanFilter(dim_x=2, dim_z=2, dt=DT, hx=hx, fx=fx, points=points)
    ukf.x, ukf.P, ukf.Q, ukf.R = M0.copy(), P0.copy(), Q.copy(), R.copy()
    ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)     # the first sample is an update only, as in casship
    for k, y in enumerate(Y):
        if k:
            ukf.predict()
            np.testing.assert_allclose(res.x_pred[k], ukf.x, rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(res.P_pred[k], ukf.P, rtol=1e-9, atol=1e-12)
        if np.all(np.isfinite(y)):
            ukf.update(y)
            assert res.loglik_terms[k] == pytest.approx(ukf.log_likelihood, rel=1e-9), k
        np.testing.assert_allclose(res.x[k], ukf.x, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(res.P[k], ukf.P, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("alpha", [0.3, 0.5, 2.0])
def test_unscented_transform_of_a_quadratic_has_the_analytic_moments(alpha):
    """``y = x + c x^2`` with ``x ~ N(m, P)``: ``E y = m + c (m^2 + P)``,
    ``var y = P (1 + 2 c m)^2 + 2 c^2 P^2``, ``cov(x, y) = P (1 + 2 c m)``. In one dimension the scaled
    transform is exact for them when ``alpha^2 kappa + beta = 2`` (here ``kappa = 0, beta = 2``), at any alpha;
    its covariance weight ``W0c`` then needs its ``1 - alpha^2`` term."""
    c, m, P = 0.3, 0.7, 0.2
    b = cs.ModelBuilder("quadratic-dt", dt=1.0)
    x = b.state("x")
    b.next(x=x + c * x**2 + b.noise("w"))
    b.output("y", x)
    ukf = cs.UKF(cs.discretize(b.build()), Q=0.0, R=1.0, options={"alpha": alpha, "beta": 2.0, "kappa": 0.0})
    res = ukf.filter(cs.Dataset([0.0, 1.0], {"y": [np.nan, np.nan]}), cs.Gaussian([m], [[P]]))
    assert res.x_pred[1, 0] == pytest.approx(m + c * (m**2 + P), rel=1e-13)
    assert res.P_pred[1, 0, 0] == pytest.approx(P * (1 + 2 * c * m) ** 2 + 2 * c**2 * P**2, rel=1e-12)
    assert res.C[1, 0, 0] == pytest.approx(P * (1 + 2 * c * m), rel=1e-12)
