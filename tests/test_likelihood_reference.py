"""The filters' Gaussian log-likelihood against independent answers: the joint density of the
measured outputs written directly from the model (channels missing, several sampling rates) and
pykalman's ``loglikelihood`` on the same record."""
import numpy as np
import pytest

import casship as cs
from gaussian_reference import DT, cv_matrices, cv_model, loglik, loglik_terms, output_moments

Q = np.array([[0.02, 0.005], [0.005, 0.03]])
R = np.diag([0.25, 0.5])
PRIOR = cs.Gaussian([1.0, -0.5], [[2.0, 0.3], [0.3, 1.0]])


def multirate_record(n=36, seed=5):
    """``y1`` at every sample except a few, ``y2`` at a third of the rate, some rows with nothing."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    u = np.sin(0.4 * t)
    Y = 1.0 + 3.0 * rng.standard_normal((n, 2))
    Y[np.arange(n) % 3 != 0, 1] = np.nan          # y2 at one third of the filter's rate
    Y[[4, 5, 11, 22], 0] = np.nan                 # y1 dropped: rows 4, 11, 22 measure nothing
    return cs.Dataset(t, {"a": u, "y1": Y[:, 0], "y2": Y[:, 1]}), u, Y


def reference(u, Y, gain=1.0):
    A, B, H = cv_matrices(gain)
    return output_moments(A, B, H, Q, R, PRIOR.mean, PRIOR.cov, u)


@pytest.mark.parametrize("cls", [cs.KF, cs.EKF, cs.UKF])
def test_loglik_equals_the_joint_density_with_missing_channels_and_rates(cls):
    data, u, Y = multirate_record()
    mean, cov = reference(u, Y)
    res = cls(cs.discretize(cv_model()), Q, R).filter(data, PRIOR)
    assert res.loglik == pytest.approx(loglik(Y, mean, cov), rel=1e-11)
    # every sample's term is the conditional density log p(y_k | y_0..k-1); rows measuring nothing add 0
    terms = loglik_terms(Y, mean, cov)
    np.testing.assert_allclose(res.loglik_terms, terms, rtol=1e-9, atol=1e-10)
    assert np.all(res.loglik_terms[[4, 11, 22]] == 0.0)


def test_identification_likelihood_equals_the_joint_density_of_all_records():
    records = [multirate_record(36, 5), multirate_record(30, 6)]
    gain = 0.8
    prob = cs.MLEProblem(cs.KF(cs.discretize(cv_model()), Q, R), [d for d, _, _ in records], free=["g"], x0=PRIOR)
    expected = sum(loglik(Y, *reference(u, Y, gain)) for _, u, Y in records)
    assert prob.negloglik({"g": gain}) == pytest.approx(-expected, rel=1e-11)


def test_loglik_equals_pykalman():
    pykalman = pytest.importorskip("pykalman", reason="pykalman is not installed: no peer to compare with")
    rng = np.random.default_rng(8)
    n = 60
    t = np.arange(n) * DT
    u = np.cos(0.3 * t)
    Y = 2.0 * rng.standard_normal((n, 2))
    Y[1::2] = np.nan                               # both sensors at half the filter's rate
    Y[[10, 30, 31, 32]] = np.nan                   # and a dropout (pykalman masks whole rows only)
    data = cs.Dataset(t, {"a": u, "y1": Y[:, 0], "y2": Y[:, 1]})
    A, B, H = cv_matrices()
    kf = pykalman.KalmanFilter(transition_matrices=A, observation_matrices=H, transition_covariance=Q,
                               observation_covariance=R, transition_offsets=np.outer(u, B),
                               initial_state_mean=PRIOR.mean, initial_state_covariance=PRIOR.cov)
    masked = np.ma.masked_invalid(Y)
    res = cs.KF(cs.discretize(cv_model()), Q, R).filter(data, PRIOR)
    assert res.loglik == pytest.approx(kf.loglikelihood(masked), rel=1e-11)
    means, _ = kf.filter(masked)
    np.testing.assert_allclose(res.x, means, rtol=1e-10, atol=1e-10)
