"""The innovation gate and the re-acquisition count at their boundaries, as documented: a sample
whose NIS exceeds the chi-square quantile for the channels measured is rejected (a NIS equal to the
threshold passes), and after ``reacquire`` consecutive rejected samples the next measurement is used
(rows measuring nothing leave the count alone)."""
import numpy as np
import pytest
from scipy import stats

import casship as cs
from gaussian_reference import cv_model

Q = np.diag([0.02, 0.03])
R = np.diag([0.25, 0.5])
M0, P0 = np.array([1.0, -0.5]), np.diag([2.0, 1.0])


def prior_memory(est):
    """``x, P``, or for an ensemble members drawn from the prior (fixed seed)."""
    if "X" not in est.memory:
        return {"x": M0, "P": P0}
    members = est.step_function(("x", "P")).size2_in("X")
    return {"X": M0[:, None] + np.linalg.cholesky(P0) @ np.random.default_rng(1).standard_normal((2, members))}


def step_call(est, y, mask, gate):
    step = est.step_function(("x", "P", "nis", "accepted"))
    memory = prior_memory(est)
    args = {**memory, "u_prev": [0.0], "u": [0.0], "y": y, "mask": mask, "dt": 0.0, "p": est.model.params(),
            "Q": Q, "R": R, "gate": gate}
    args.update({name: np.zeros(step.size_in(name)) for name in step.name_in() if name not in args})  # EnKF draws
    return {k: np.asarray(v) for k, v in step.call(args).items()}


@pytest.mark.parametrize("cls", [cs.EKF, cs.UKF, cs.EnKF])
def test_a_nis_equal_to_the_threshold_passes_and_one_above_is_rejected(cls):
    est = cls(cs.discretize(cv_model()), Q, R)
    y, mask = np.array([3.1, 2.0]), np.array([1.0, 1.0])
    nis = step_call(est, y, mask, np.inf)["nis"].item()
    at = step_call(est, y, mask, nis)                          # threshold exactly the NIS: accepted
    above = step_call(est, y, mask, np.nextafter(nis, 0.0))     # the NIS one ulp above the threshold
    assert at["nis"].item() == nis and at["accepted"].item() == 1.0
    assert above["accepted"].item() == 0.0
    assert not np.allclose(at["x"].ravel(), prior_memory(est).get("X", M0[:, None]).mean(axis=1))
    prior_mean = prior_memory(est).get("X", M0[:, None]).mean(axis=1)
    np.testing.assert_allclose(above["x"].ravel(), prior_mean, rtol=1e-14)   # rejected: the prediction stays


def test_gate_threshold_is_the_quantile_for_the_channels_measured():
    """One sample (update only): just below the 1-channel threshold it passes, just above it is rejected;
    a NIS between the 1- and 2-degree-of-freedom quantiles is rejected when one channel is measured
    and accepted when both are."""
    prob = 0.99
    est = cs.EKF(cs.discretize(cv_model()), Q, R, options={"gate": prob})
    s1 = P0[0, 0] + R[0, 0]                                       # variance of the y1 innovation (y1 = x)
    q1, q2 = stats.chi2.ppf(prob, 1), stats.chi2.ppf(prob, 2)
    prior = cs.Gaussian(M0, P0)

    def rejected(y1, y2=np.nan):
        return bool(est.filter(cs.Dataset([0.0], {"a": [0.0], "y1": [y1], "y2": [y2]}), prior).rejected[0])

    assert not rejected(M0[0] + np.sqrt(q1 * s1) * (1 - 1e-9))
    assert rejected(M0[0] + np.sqrt(q1 * s1) * (1 + 1e-9))
    nis_between = 0.5 * (q1 + q2)
    y1 = M0[0] + np.sqrt(nis_between * s1)
    assert rejected(y1)
    # y2 at its expected value given y1: the joint NIS is the same number, now tested against q2
    H = np.array([[1.0, 0.0], [1.0, 2.0]])
    S = H @ P0 @ H.T + R
    e = np.array([y1 - M0[0], S[1, 0] / S[0, 0] * (y1 - M0[0])])
    assert e @ np.linalg.solve(S, e) == pytest.approx(nis_between, rel=1e-12)
    assert not rejected(y1, float(H[1] @ M0 + e[1]))


def test_reacquire_forces_the_update_after_exactly_that_many_rejections():
    """``reacquire=3``: three outliers in a row are rejected, the fourth is used; a row that measures
    nothing inside the streak does not count."""
    est = cs.EKF(cs.discretize(cv_model()), Q, R, options={"gate": 0.999, "reacquire": 3})
    n = 30
    rng = np.random.default_rng(3)
    y1 = M0[0] + 0.3 * rng.standard_normal(n)
    y2 = M0[0] + 2 * M0[1] + 0.3 * rng.standard_normal(n)
    streak = [10, 11, 13, 14, 15]                      # row 12 measures nothing
    y1[streak], y2[streak] = 200.0, 200.0
    y1[12] = y2[12] = np.nan
    data = cs.Dataset(np.arange(n) * 0.5, {"a": np.zeros(n), "y1": y1, "y2": y2})
    res = est.filter(data, cs.Gaussian(M0, P0 / 100))
    assert list(np.flatnonzero(res.rejected[:14])) == [10, 11, 13]       # three rejections, row 12 skipped
    assert not res.rejected[14]                                           # the fourth outlier is forced in
    plain = cs.EKF(cs.discretize(cv_model()), Q, R, options={"gate": 0.999}).filter(data, cs.Gaussian(M0, P0 / 100))
    assert plain.rejected[14]                                             # without reacquire it is rejected
    # a sensor at half the filter's rate (every other row empty) re-acquires after the same count
    half = data.with_columns(y1=np.where(np.arange(n) % 2, np.nan, data["y1"]),
                             y2=np.where(np.arange(n) % 2, np.nan, data["y2"]))
    half = half.with_columns(y1=np.where(np.isin(np.arange(n), [16, 18]), 200.0, half["y1"]),
                             y2=np.where(np.isin(np.arange(n), [16, 18]), 200.0, half["y2"]))
    res = est.filter(half, cs.Gaussian(M0, P0 / 100))
    assert list(np.flatnonzero(res.rejected[:19])) == [10, 14, 16]       # outliers at 10, 14, 16, 18
    assert not res.rejected[18]
