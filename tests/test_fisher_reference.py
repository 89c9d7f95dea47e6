"""The Fisher information of the identification likelihood (``MLEProblem.information``) against
independent answers: the textbook information of white-noise variances, the expected Hessian of the
joint Gaussian density of the outputs, and the Monte Carlo covariance of maximum-likelihood
estimates over many seeded records."""
import numpy as np
import pytest
from scipy import stats

import casship as cs
from gaussian_reference import gaussian_fisher

G_TRUE, P0 = 0.5, 0.5


def drifting_level():
    """Local level driven by ``g * a``: ``x[k+1] = x[k] + g a[k] + w``, ``y = x + v`` (discrete time)."""
    b = cs.ModelBuilder("level", "local level with a driven drift", dt=1.0)
    x, a = b.state("x"), b.input("a")
    g = b.param("g", G_TRUE)
    b.next(x=x + g * a + b.noise("w"))
    b.output("y", x)
    b.output("y2", 2.0 * x)
    return b.build()


def design(n):
    t = np.arange(n) * 1.0
    return t, np.sign(np.sin(2 * np.pi * t / 20.0))


def joint(n, q, r):
    """Mean, covariance and their derivatives (``g``, ``q``, ``r``) of the outputs ``y[0..n-1]``."""
    t, a = design(n)
    D = np.minimum.outer(np.arange(n), np.arange(n)).astype(float)     # noise steps shared by y_j and y_k
    dmean = np.concatenate([[0.0], np.cumsum(a[:-1])])
    cov = P0 + q * D + r * np.eye(n)
    return G_TRUE * dmean, cov, [dmean, np.zeros(n), np.zeros(n)], [np.zeros((n, n)), D, np.eye(n)]


def test_information_of_white_noise_variances_and_a_mean_parameter_is_textbook():
    """A state known exactly (no prior or process noise): innovations are white with ``S = R``, so
    the information is ``n_j / (2 R_j^2)`` for each variance and ``sum (d mu_k)^2 / R`` for ``g``."""
    n = 40
    t, a = design(n)
    rng = np.random.default_rng(0)
    R = np.diag([0.3, 0.8])
    y1, y2 = rng.standard_normal(n), rng.standard_normal(n)
    y2[::4] = np.nan                                   # the second sensor misses a quarter of the samples
    data = cs.Dataset(t, {"a": a, "y": y1, "y2": y2})
    kf = cs.KF(cs.discretize(drifting_level()), Q=0.0, R=R)
    prob = cs.MLEProblem(kf, data, free=["g"], noise={"R": True}, x0=cs.Gaussian([0.0], [[0.0]]))
    info = prob.information({"g": G_TRUE, "R[y]": R[0, 0], "R[y2]": R[1, 1]})
    dmu = np.concatenate([[0.0], np.cumsum(a[:-1])])
    measured2 = np.isfinite(y2)
    expected = np.diag([np.sum(dmu**2) / R[0, 0] + np.sum((2 * dmu[measured2]) ** 2) / R[1, 1],
                        n / (2 * R[0, 0] ** 2), measured2.sum() / (2 * R[1, 1] ** 2)])
    np.testing.assert_allclose(info, expected, rtol=1e-10, atol=1e-9)


def _sample(mean, cov, rng, count):
    L = np.linalg.cholesky(cov)
    return [mean + L @ rng.standard_normal(len(mean)) for _ in range(count)]


def test_information_is_the_expected_hessian_of_the_joint_density():
    """Averaged over records drawn from the model's joint Gaussian, the information of the innovations
    equals the analytic Fisher information ``dm' C^-1 dm + 0.5 tr(C^-1 dC C^-1 dC)`` (Cavanaugh &
    Shumway 1996); the bound is six Monte Carlo standard errors of the mean (from 40 groups)."""
    n, q, r, groups, per_group = 30, 0.3, 1.0, 40, 25
    mean, cov, dm, dc = joint(n, q, r)
    exact = gaussian_fisher(dm, dc, cov)
    t, a = design(n)
    kf = cs.KF(cs.discretize(drifting_level()), q, r, measured=["y"])
    at = {"g": G_TRUE, "Q[w]": q, "R[y]": r}
    rng = np.random.default_rng(7)
    infos = []
    for _ in range(groups):
        records = [cs.Dataset(t, {"a": a, "y": y}) for y in _sample(mean, cov, rng, per_group)]
        prob = cs.MLEProblem(kf, records, free=["g"], noise={"Q": True, "R": True}, x0=cs.Gaussian([0.0], [P0]))
        infos.append(prob.information(at) / per_group)
    infos = np.array(infos)
    avg, se = infos.mean(axis=0), infos.std(axis=0, ddof=1) / np.sqrt(groups)
    assert np.all(np.abs(avg - exact) <= 6 * se + 1e-9 * np.abs(exact).max()), (avg, exact, se)


# (q, r, noise variances free): both variances free; and a nearly known state whose measurement variance
# acts on the likelihood through S alone (the covariance term of the information dominates)
@pytest.mark.parametrize("q, r, noise", [(0.5, 0.5, ("Q", "R")), (0.02, 1.0, ("R",))], ids=["Q-and-R", "R-only"])
def test_inverse_information_is_the_monte_carlo_covariance_of_the_estimates(q, r, noise):
    """Over 200 seeded records the sample variances of the ML estimates match the inverse of the
    information at the truth: ``(M - 1) s^2 / sigma^2`` inside the 0.1 %-99.9 % chi-square interval."""
    n, runs = 150, 200
    mean, cov, _, _ = joint(n, q, r)
    t, a = design(n)
    kf = cs.KF(cs.discretize(drifting_level()), q, r, measured=["y"])
    truth = {"g": G_TRUE, **({"Q[w]": q} if "Q" in noise else {}), "R[y]": r}
    prior = cs.Gaussian([0.0], [P0])
    rng = np.random.default_rng(11)
    estimates, info = [], 0.0
    for y in _sample(mean, cov, rng, runs):
        prob = cs.MLEProblem(kf, cs.Dataset(t, {"a": a, "y": y}), free=["g"], noise={k: True for k in noise},
                             x0=prior)
        fit = prob.solve(guess=truth, show=False)
        assert fit.status == "converged"
        estimates.append([fit.estimates[k] for k in truth])
        info = info + prob.information(truth) / runs
    variance = np.diag(np.linalg.inv(info))
    ratio = np.var(estimates, axis=0, ddof=1) / variance
    lo, hi = stats.chi2.ppf([0.001, 0.999], runs - 1) / (runs - 1)
    assert np.all((lo < ratio) & (ratio < hi)), dict(zip(truth, ratio))
