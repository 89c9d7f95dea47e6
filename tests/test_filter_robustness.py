"""Consistency (NEES/NIS in chi-square bounds) on the SOG/COG model, GNSS dropout, outlier gating and
multi-rate GNSS, for the EKF and the UKF (the heading across +-180 deg is checked for every estimator
in test_estimator_contract.py)."""
import numpy as np
import pytest
from scipy import stats

import casship as cs

FILTERS = [cs.EKF, cs.UKF]


def _sog_case(n=300, dt=0.1, seed=0, q=(1e-2, 1e-3), r=1.0, rates=None, x0=None):
    m = cs.models.sog_cog()
    rng = np.random.default_rng(seed)
    prior = cs.Gaussian(m.states(x_n=0.0, y_n=0.0, U=3.0, chi=0.5, omega_chi=0.0), [4.0, 4.0, 0.25, 0.01, 1e-4])
    x_true0 = prior.sample(1, rng)[0] if x0 is None else x0
    t = np.arange(n) * dt
    w = rng.standard_normal((n, 2)) * np.sqrt(q)
    traj = cs.simulate(m, x_true0, t, w=w, method="euler")
    std = {"x_n": np.sqrt(r), "y_n": np.sqrt(r)}
    data = cs.measure(traj, m, std, rates=rates, seed=rng)
    return m, cs.discretize(m, dt, method="euler"), traj, data, prior, np.diag(q), r


@pytest.mark.parametrize("cls", FILTERS)
def test_nees_nis_in_chi_square_bounds(cls):
    """Monte Carlo over M runs with the truth drawn from the prior and matched noise: the average
    NEES (5 states) and NIS (2 outputs) lie inside their 95 % chi-square bounds (Bar-Shalom et al.
    2001, Sec. 5.4), both overall and at 90 % of the time steps."""
    M, n = 24, 200
    nees, nis = [], []
    est = None
    for run in range(M):
        m, dm, traj, data, prior, Q, R = _sog_case(n=n, seed=100 + run)
        est = est or cls(dm, Q, R)
        res = est.filter(data, prior)
        nees.append(res.nees(traj.x))
        nis.append(res.nis)
    nees, nis = np.array(nees).mean(axis=0), np.array(nis).mean(axis=0)
    for values, dof in ((nees, 5), (nis, 2)):
        lo, hi = stats.chi2.ppf([0.025, 0.975], M * dof) / M
        assert lo < values.mean() < hi, (values.mean(), lo, hi)
        inside = np.mean((values > lo) & (values < hi))
        assert inside > 0.90, inside


@pytest.mark.parametrize("cls", FILTERS)
def test_gnss_dropout_covariance_grows_and_recovers(cls):
    m, dm, traj, data, prior, Q, R = _sog_case(n=1500, seed=3)
    gap = (data.t >= 60.0) & (data.t < 90.0)
    data = data.with_columns(x_n=np.where(gap, np.nan, data["x_n"]), y_n=np.where(gap, np.nan, data["y_n"]))
    res = cls(dm, Q, R).filter(data, prior)
    var = res.P[:, 0, 0] + res.P[:, 1, 1]
    inside = np.flatnonzero(gap)
    assert np.all(np.diff(var[inside]) > 0)                  # grows all through the dropout
    assert var[inside[-1]] > 20 * var[inside[0] - 1]
    err = np.hypot(res["x_n"] - traj["x_n"], res["y_n"] - traj["y_n"])
    sigma = np.sqrt(var)
    assert np.all(err[inside] < 4 * sigma[inside])            # the error stays inside the grown spread
    after = (data.t > 100.0) & (data.t < 150.0)
    before = (data.t > 20.0) & (data.t < 60.0)
    assert err[after].mean() < 1.5 * err[before].mean()      # recovered
    assert var[after].mean() < 1.5 * var[before].mean()


@pytest.mark.parametrize("cls", FILTERS)
def test_outlier_rejected_by_gate(cls):
    m, dm, traj, data, prior, Q, R = _sog_case(n=400, seed=4)
    k = 250
    bad = data["x_n"].copy()
    bad[k] += 10.0 * np.sqrt(R)
    dirty = data.with_columns(x_n=bad)
    gated = cls(dm, Q, R, options={"gate": 0.999})
    res = gated.filter(dirty, prior)
    assert res.rejected[k]
    assert res.rejected.sum() <= 3                       # otherwise only chance rejections (p = 0.001)
    clean = gated.filter(data, prior)
    np.testing.assert_array_equal(res.x[k], res.x_pred[k])     # no update at the outlier
    np.testing.assert_allclose(res.x[k - 1], clean.x[k - 1], rtol=1e-12)
    ungated = cls(dm, Q, R).filter(dirty, prior)
    assert not ungated.rejected.any()
    assert abs(ungated["x_n"][k] - traj["x_n"][k]) > 3 * abs(res["x_n"][k] - traj["x_n"][k])


@pytest.mark.parametrize("cls", FILTERS)
def test_multirate_gnss_5hz_into_50hz(cls):
    """Fossen & Fossen (2021): the filter runs at 50 Hz, GNSS arrives at 5 Hz (NaN rows between)."""
    m, dm, traj, data, prior, Q, R = _sog_case(n=3000, dt=0.02, seed=6, q=(1e-2 / 5, 1e-3 / 5),
                                              rates={"x_n": 5.0, "y_n": 5.0})
    assert np.isnan(data["x_n"]).sum() == pytest.approx(0.9 * len(data), abs=2)
    res = cls(dm, Q, R).filter(data, prior)
    assert np.array_equal(res.n_measured > 0, np.isfinite(data["x_n"]))
    var = res.P[:, 0, 0]
    fix = np.flatnonzero(np.isfinite(data["x_n"]))
    for a, b in zip(fix[100:110], fix[101:111]):             # sawtooth: grows between fixes, drops at a fix
        assert np.all(np.diff(var[a:b]) > 0) and var[b] < var[b - 1]
    late = data.t > 20.0
    assert np.sqrt(np.mean((res["U"][late] - traj["U"][late]) ** 2)) < 0.15
    assert np.sqrt(np.mean(cs.wrap(res["chi"][late] - traj["chi"][late]) ** 2)) < 0.1
