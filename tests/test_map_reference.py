"""The MAP cost (data cost plus the Gaussian prior's ``0.5 sum ((theta - mean) / std)^2``) against a
hand computation, and the MAP estimate of every solver route against the closed form: with a linear
model whose outputs are affine in the free quantities the cost is quadratic, so its minimiser solves
the normal equations written here in NumPy."""
import numpy as np
import pytest

import casship as cs
from casship.identify import MLEProblem, OutputErrorProblem, Prior
from gaussian_reference import DT, cv_matrices, cv_model, loglik, output_moments

Q = np.array([[0.02, 0.005], [0.005, 0.03]])
R = np.diag([0.25, 0.5])
X0 = cs.Gaussian([1.0, -0.5], [[2.0, 0.3], [0.3, 1.0]])
PRIOR = Prior(std={"g": 0.05, "bias[y1]": 0.1}, mean={"g": 1.1, "bias[y1]": 0.3})
PREC, PMEAN = np.array([1 / 0.05**2, 1 / 0.1**2]), np.array([1.1, 0.3])


def record(n=50, seed=4, gain=1.0, bias=0.2, noise=True):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    a = np.sign(np.sin(2 * np.pi * t / 8.0))
    A, B, H = cv_matrices(gain)
    x = X0.mean.copy()
    Y = np.zeros((n, 2))
    for k in range(n):
        Y[k] = H @ x + [bias, 0.0] + (np.sqrt(np.diag(R)) * rng.standard_normal(2) if noise else 0.0)
        x = A @ x + B * a[k] + (np.linalg.cholesky(Q) @ rng.standard_normal(2) if noise else 0.0)
    Y[5::7, 1] = np.nan
    return cs.Dataset(t, {"a": a, "y1": Y[:, 0], "y2": Y[:, 1]}), a, Y


def normal_equations(mean_of, Y, cov, prec, pmean):
    """Minimiser of ``0.5 (y - m(theta))' C^-1 (y - m(theta)) + 0.5 sum prec (theta - pmean)^2`` for an
    affine ``m`` (observed entries of ``Y`` only)."""
    k = len(pmean)
    m0 = mean_of(np.zeros(k))
    D = np.column_stack([mean_of(np.eye(k)[i]) - m0 for i in range(k)])
    ok = np.isfinite(Y.reshape(-1))
    Ci = np.linalg.inv(cov[np.ix_(ok, ok)])
    lhs = D[ok].T @ Ci @ D[ok] + np.diag(prec)
    rhs = D[ok].T @ Ci @ (Y.reshape(-1)[ok] - m0[ok]) + prec * pmean
    return np.linalg.solve(lhs, rhs), np.sqrt(np.diag(np.linalg.inv(lhs)))


# -- the filter likelihood (MLEProblem) ------------------------------------------------------------------
def mle_moments(theta, u):
    g, b = theta
    A, B, H = cv_matrices(g)
    return output_moments(A, B, H, Q, R, X0.mean, X0.cov, u, bias=np.array([b, 0.0]))


def test_mle_map_cost_and_estimate_of_both_routes_equal_the_hand_computation():
    data, u, Y = record()
    prob = MLEProblem(cs.KF(cs.discretize(cv_model()), Q, R), data, free=["g", "bias[y1]"], x0=X0, prior=PRIOR)
    at = np.array([0.93, 0.12])
    hand = -loglik(Y, *mle_moments(at, u)) + 0.5 * np.sum(PREC * (at - PMEAN) ** 2)
    assert prob.cost(dict(zip(prob.free, at))) == pytest.approx(hand, rel=1e-11)
    cov = mle_moments(at, u)[1]                       # the covariance does not depend on g or the bias
    best, post_std = normal_equations(lambda th: mle_moments(th, u)[0], Y, cov, PREC, PMEAN)
    for hessian in ("fisher", "exact"):
        fit = prob.solve(guess={"g": 0.9, "bias[y1]": 0.0}, hessian=hessian, show=False)
        est = np.array([fit.estimates[n] for n in prob.free])
        assert np.all(np.abs(est - best) < 1e-4 * post_std), (hessian, (est - best) / post_std)
        # the standard errors are the posterior ones: data information plus the prior's precision, from
        # the expected (Fisher) or the observed (exact Hessian) information alike: the cost is quadratic
        np.testing.assert_allclose([fit.std_errors[n] for n in prob.free], post_std, rtol=1e-6)
        observed = prob.solve(guess={"g": 0.9, "bias[y1]": 0.0}, hessian=hessian, information="hessian", show=False)
        np.testing.assert_allclose([observed.std_errors[n] for n in prob.free], post_std, rtol=1e-6)


# -- output error (OutputErrorProblem) -------------------------------------------------------------------
SIGMA = {"y1": 0.5, "y2": 0.7}


def oe_outputs(theta, u, n):
    """Noise-free outputs for ``theta = (g, bias[y1], x0, v0)``, stacked like ``Y``."""
    g, b, x0, v0 = theta
    A, B, H = cv_matrices(g)
    x, out = np.array([x0, v0]), []
    for k in range(n):
        out.append(H @ x + [b, 0.0])
        x = A @ x + B * u[k]
    return np.concatenate(out)


def test_output_error_map_cost_and_estimate_of_both_routes_equal_the_hand_computation():
    data, u, Y = record(noise=False)
    rng = np.random.default_rng(9)
    Y = Y + rng.standard_normal(Y.shape) * [SIGMA["y1"], SIGMA["y2"]]
    data = data.with_columns(y1=Y[:, 0], y2=Y[:, 1])
    n = len(data)
    W = np.tile([1 / SIGMA["y1"], 1 / SIGMA["y2"]], n)
    prec, pmean = np.concatenate([PREC, [0.0, 0.0]]), np.concatenate([PMEAN, [0.0, 0.0]])
    kw = dict(free=["g", "bias[y1]"], sigma=SIGMA, estimate_x0=["x", "v"], prior=PRIOR, segment=12)
    prob = OutputErrorProblem(cs.discretize(cv_model()), data, **kw)
    assert prob.free[:2] == ["g", "bias[y1]"] and len(prob.free) == 4
    at = np.array([0.93, 0.12, 0.8, -0.3])
    r = (Y.reshape(-1) - oe_outputs(at, u, n)) * W
    hand = 0.5 * np.nansum(r**2) + 0.5 * np.sum(prec * (at - pmean) ** 2)
    assert prob.cost(dict(zip(prob.free, at))) == pytest.approx(hand, rel=1e-11)
    best, post_std = normal_equations(lambda th: oe_outputs(th, u, n), Y, np.diag(1 / W**2), prec, pmean)
    guess = dict(zip(prob.free, [0.9, 0.0, 1.0, -0.5]))
    for shooting, opts in (("single", {"tol": 1e-12}), ("multiple", {})):
        fit = OutputErrorProblem(cs.discretize(cv_model()), data, shooting=shooting, **kw).solve(guess=guess,
                                                                                                 show=False, **opts)
        est = np.array([fit.estimates[k] for k in prob.free])
        assert np.all(np.abs(est - best) < 1e-4 * post_std), (shooting, (est - best) / post_std)
