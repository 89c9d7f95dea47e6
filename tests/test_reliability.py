"""Reliability under faults and bad input: consistency, dropouts, outlier bursts, a frozen sensor,
time-stamp jitter, a wrong hemisphere sign, long runs, and clear errors for bad input.

Complements ``test_filter_robustness.py`` (EKF/UKF consistency, 30 s dropout, a single outlier,
multi-rate GNSS, heading across +-180 deg).
"""
import numpy as np
import pytest
from scipy import stats

import casship as cs
from casship.frames import wgs84_radii
from casship.models import sog_cog, sog_cog_latlon, tomera_kinematic

Q_SOG = np.diag([1e-2, 1e-3])
R_GNSS = 1.0
LAT0, LON0 = np.radians(63.43), np.radians(10.39)


def sog_record(n, dt=0.1, seed=0, rate=None, t=None):
    """Truth with held process noise drawn from Q and GNSS positions (1 m std), and the prior."""
    m = sog_cog()
    rng = np.random.default_rng(seed)
    prior = cs.Gaussian(m.states(U=3.0, chi=0.5), [4.0, 4.0, 0.25, 0.01, 1e-4])
    t = np.arange(n) * dt if t is None else t
    w = rng.standard_normal((t.size, 2)) @ np.sqrt(Q_SOG)
    truth = cs.simulate(m, prior.sample(1, rng)[0], t, w=w, method="euler")
    rates = {"x_n": rate, "y_n": rate} if rate else None
    data = cs.measure(truth, m, {"x_n": 1.0, "y_n": 1.0}, rates=rates, seed=rng)
    return m, truth, data, prior


def ekf(dt=0.1, gate=None, cls=None):
    return (cls or cs.EKF)(cs.discretize(sog_cog(), dt, method="euler"), Q_SOG, R_GNSS, options={"gate": gate})


def position_error(res, truth):
    return np.hypot(res["x_n"] - truth["x_n"], res["y_n"] - truth["y_n"])


def chi2_band(runs, dof, p=0.95):
    return stats.chi2.ppf([(1 - p) / 2, (1 + p) / 2], runs * dof) / runs


# -- consistency -----------------------------------------------------------------------------------

def test_kf_nees_nis_inside_chi_square_bounds():
    """Linear model (Tomera's double integrators), matched noise: Monte Carlo NEES and NIS."""
    m = tomera_kinematic()
    dm = cs.discretize(m, 0.5, method="rk4")
    Q = np.diag([0.5, 0.5, 0.5, 0.5, 0.2, 0.2]) ** 2
    R = {"x": 4.0, "y": 4.0, "psi": np.radians(1.0) ** 2}
    kf = cs.KF(dm, Q, R)
    prior = cs.Gaussian(m.states(vx=3.0, vy=1.0), [25.0, 1.0, 25.0, 1.0, 0.01, 1e-4])
    runs, n = 30, 150
    t = np.arange(n) * 0.5
    nees, nis = [], []
    for run in range(runs):
        rng = np.random.default_rng(1000 + run)
        w = rng.standard_normal((n, m.nw)) @ np.sqrt(Q)
        truth = cs.simulate(m, prior.sample(1, rng)[0], t, w=w)
        data = cs.measure(truth, m, {k: np.sqrt(v) for k, v in R.items()}, seed=rng)
        res = kf.filter(data, prior)
        nees.append(res.nees(truth.x))
        nis.append(res.nis)
    for values, dof in ((np.mean(nees, axis=0), m.nx), (np.mean(nis, axis=0), 3)):
        lo, hi = chi2_band(runs, dof)
        assert lo < values.mean() < hi
        assert np.mean((values > lo) & (values < hi)) > 0.9


def test_time_stamp_jitter_is_handled_by_the_actual_dt():
    """Irregular sampling (0.1 s +- 40 ms): the filter steps with each row's own dt and stays
    consistent (Monte Carlo NEES inside the 95 % chi-square band)."""
    runs, n = 20, 250
    base = ekf()
    nees = []
    for run in range(runs):
        rng = np.random.default_rng(50 + run)
        t = np.arange(n) * 0.1 + rng.uniform(-0.04, 0.04, n)
        m, truth, data, prior = sog_record(n, seed=500 + run, t=t)
        nees.append(base.filter(data, prior).nees(truth.x))
    lo, hi = chi2_band(runs, 5)
    assert lo < np.mean(nees) < hi


# -- faults ----------------------------------------------------------------------------------------

def test_five_minute_gnss_dropout_grows_covariance_and_recovers():
    m, truth, data, prior = sog_record(6000, seed=8, rate=1.0)
    gap = (data.t >= 150.0) & (data.t < 450.0)                 # 5 min without position
    data = data.with_columns(x_n=np.where(gap, np.nan, data["x_n"]), y_n=np.where(gap, np.nan, data["y_n"]))
    res = ekf().filter(data, prior)
    assert not res.n_measured[gap].any()
    sigma = np.sqrt(res.P[:, 0, 0] + res.P[:, 1, 1])
    inside = np.flatnonzero(gap)
    assert np.all(np.diff(sigma[inside]) > 0)
    assert sigma[inside[-1]] > 50.0 * sigma[inside[0] - 1]      # hundreds of metres after 5 min
    err = position_error(res, truth)
    assert np.all(err[inside] < 4 * sigma[inside])              # honest about its uncertainty
    before, after = (data.t > 60) & (data.t < 150), (data.t > 500) & (data.t < 590)
    assert err[after].mean() < 1.5 * err[before].mean()
    assert sigma[after].mean() < 1.5 * sigma[before].mean()


def test_burst_of_ten_sigma_outliers_is_rejected_and_reported():
    m, truth, data, prior = sog_record(1200, seed=9)
    burst = np.arange(600, 640)                                 # 4 s of 10-sigma errors
    rng = np.random.default_rng(1)
    x = data["x_n"].copy()
    x[burst] += 10.0 * rng.choice([-1.0, 1.0], burst.size)
    dirty = data.with_columns(x_n=x)
    res = ekf(gate=0.999).filter(dirty, prior)
    assert res.rejected[burst].all()                            # every corrupted sample reported
    assert res.rejected.sum() - burst.size <= 4                 # only chance rejections elsewhere
    clean = ekf(gate=0.999).filter(data, prior)
    err, err_clean = position_error(res, truth), position_error(clean, truth)
    assert err[burst].max() < 2.5 * err_clean[burst].max() + 0.5
    np.testing.assert_allclose(res.x[-1], clean.x[-1], atol=0.5)
    ungated = ekf().filter(dirty, prior)
    assert ungated.health(window=50).flagged[600 // 50]         # without the gate the monitor flags the burst


def frozen_case():
    m, truth, data, prior = sog_record(2400, seed=10)
    frozen = (data.t >= 100.0) & (data.t < 160.0)               # the receiver repeats its last fix
    k0 = np.flatnonzero(frozen)[0] - 1
    stuck = data.with_columns(x_n=np.where(frozen, data["x_n"][k0], data["x_n"]),
                              y_n=np.where(frozen, data["y_n"][k0], data["y_n"]))
    return truth, stuck, prior, frozen


def test_frozen_sensor_is_flagged_and_the_filter_recovers():
    """A frozen fix looks like a ship that stopped: its innovations become far too small, which the
    NIS monitor flags (and can raise on); once the receiver delivers again the filter recovers."""
    truth, stuck, prior, frozen = frozen_case()
    res = ekf().filter(stuck, prior)
    health = res.health(window=50)
    frozen_windows = np.flatnonzero(frozen[::50][: health.flagged.size])
    assert health.flagged[frozen_windows[2:]].all()              # a few seconds after it froze
    assert health.flagged[: frozen_windows[0]].sum() <= 1
    with pytest.raises(RuntimeError, match="filter health check failed"):
        health.raise_if_diverged()
    after = stuck.t > 190.0
    assert position_error(res, truth)[after].max() < 1.5
    assert ekf(gate=0.999).filter(stuck, prior).health(window=50).flagged[frozen_windows[2:]].all()


def test_gated_filter_that_loses_track_is_not_silent():
    """After the frozen stretch a gated filter without re-acquisition rejects the correct fixes
    (``options={"reacquire": N}`` fixes that, see test_reacquire.py); the monitor flags every such
    window instead of reporting a clean NIS."""
    truth, stuck, prior, frozen = frozen_case()
    res = ekf(gate=0.999).filter(stuck, prior)
    health = res.health(window=50)
    locked = np.flatnonzero(res.rejected & (stuck.t > 165.0))
    assert locked.size > 100                                     # the lock-out this test is about
    windows = np.unique(locked // 50)
    assert health.flagged[windows].all() and (health.rejected[windows] >= 3).all()
    m, truth2, data2, prior2 = sog_record(2400, seed=10)
    assert ekf(gate=0.999).filter(data2, prior2).health(window=50).ok   # no false alarm on clean data


def test_wrong_hemisphere_sign_is_rejected():
    """A receiver reports the latitude with the wrong sign for a minute: every such fix is rejected,
    the estimate stays on the track, and the correct fixes afterwards are accepted."""
    m = sog_cog_latlon()
    dm = cs.discretize(m, 1.0, method="rk4")
    r_n, r_m = wgs84_radii(LAT0)
    sig = 2.0                                                    # metres
    R = {"lat": (sig / r_m) ** 2, "lon": (sig / (r_n * np.cos(LAT0))) ** 2}
    Q = np.diag([1e-4, 1e-6])
    t = np.arange(0.0, 600.0, 1.0)
    rng = np.random.default_rng(3)
    truth = cs.simulate(m, m.states(lat=LAT0, lon=LON0, U=4.0, chi=0.3), t,
                        w=rng.standard_normal((t.size, 2)) @ np.sqrt(Q))
    data = cs.measure(truth, m, {k: np.sqrt(v) for k, v in R.items()}, seed=rng)
    wrong = (t >= 300.0) & (t < 360.0)
    data = data.with_columns(lat=np.where(wrong, -data["lat"], data["lat"]))
    prior = cs.Gaussian(m.states(lat=LAT0, lon=LON0, U=4.0, chi=0.3),
                        [R["lat"] * 25, R["lon"] * 25, 0.25, 1e-2, 1e-5])
    res = cs.EKF(dm, Q, R, options={"gate": 0.9999}).filter(data, prior)
    assert res.rejected[wrong].all()
    assert res.rejected[~wrong].sum() <= 2
    north_err = (res["lat"] - truth["lat"]) * r_m
    east_err = (res["lon"] - truth["lon"]) * r_n * np.cos(LAT0)
    assert np.hypot(north_err, east_err)[t > 20].max() < 10.0


# -- long runs -------------------------------------------------------------------------------------

def long_run(n):
    m, truth, data, prior = sog_record(n, seed=11, rate=1.0)
    return m, data, prior, ekf().filter(data, prior)


def check_covariances(P):
    np.testing.assert_array_equal(P, P.transpose(0, 2, 1))     # exactly symmetric
    assert np.linalg.eigvalsh(P).min() > 0                      # positive definite throughout


def test_covariance_symmetric_positive_definite_over_1e5_steps():
    *_, res = long_run(100_000)
    check_covariances(res.P)
    check_covariances(res.P_pred)
    assert np.isfinite(res.x).all()
    assert res.health(window=500).ok


def online_matches_batch(n):
    m, data, prior, res = long_run(n)
    run = ekf().online(prior)
    y = data.matrix(["x_n", "y_n"])
    dt = np.concatenate([[0.0], np.diff(data.t)])
    for k in range(n):
        x = run.update(y[k], dt[k])
    return res, x, run.P


def test_online_steps_do_not_drift_over_1e5_steps():
    res, x, P = online_matches_batch(100_000)
    np.testing.assert_allclose(x, res.x[-1], rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(P, res.P[-1], rtol=1e-9, atol=1e-12)


# -- bad input -------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def nomoto_case():
    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, 20.0, 0.1)
    truth = cs.simulate(m, m.states(), t, {"delta": 0.1})
    data = cs.measure(truth, m, {"psi": 0.01}, seed=0)
    return m, cs.discretize(m, 0.1), data, cs.Gaussian(m.states(), [1e-2, 1e-4])


@pytest.mark.parametrize("cls", [cs.EKF, cs.UKF])
def test_bad_estimator_input_is_named(nomoto_case, cls):
    m, dm, data, prior = nomoto_case
    est = cls(dm, 1e-8, 1e-4)
    delta = data["delta"].copy()
    delta[7] = np.nan
    with pytest.raises(ValueError, match=r"input 'delta' is not finite at row 7"):
        est.filter(data.with_columns(delta=delta), prior)
    with pytest.raises(ValueError, match=r"data has no column\(s\) \['delta'\]"):
        est.filter(data.select(["psi"]), prior)
    with pytest.raises(ValueError, match="angle measurement 'psi' reaches .*degrees given"):
        est.filter(data.with_columns(psi=np.degrees(data["psi"]) + 400.0), prior)
    with pytest.raises(ValueError, match="measurement 'psi' is infinite at row 3"):
        est.filter(data.with_columns(psi=np.where(np.arange(len(data)) == 3, np.inf, data["psi"])), prior)
    with pytest.raises(ValueError, match="prior has 3 entries"):
        est.filter(data, cs.Gaussian(np.zeros(3), 1.0))
    with pytest.raises(ValueError, match="prior mean of angle state 'psi' is 45: .*degrees given"):
        est.filter(data, cs.Gaussian([45.0, 0.0], [1e-2, 1e-4]))
    with pytest.raises(TypeError, match="prior must be a casship.Gaussian"):
        est.filter(data, (np.zeros(2), np.eye(2)))


@pytest.mark.parametrize("kwargs, error, match", [
    ({"Q": -1e-8}, ValueError, "Q: not positive semi-definite"),
    ({"R": [[1e-4, 2e-4], [2e-4, 1e-4]]}, ValueError, r"R: expected shape \(1, 1\)"),
    ({"R": 0.0}, ValueError, "R: must be positive definite"),
    ({"R": np.nan}, ValueError, "R: contains non-finite"),
    ({"measured": ["heading"]}, ValueError, r"unknown measured output\(s\) \['heading'\]"),
    ({"options": {"gates": 0.99}}, ValueError, r"unknown option\(s\) \['gates'\]"),
    ({"options": {"gate": 1.5}}, ValueError, "option 'gate' is a probability"),
])
def test_bad_estimator_settings_are_named(nomoto_case, kwargs, error, match):
    m, dm, data, prior = nomoto_case
    args = {"Q": 1e-8, "R": 1e-4, **kwargs}
    with pytest.raises(error, match=match):
        cs.EKF(dm, args.pop("Q"), args.pop("R"), **args)


def test_non_pd_prior_and_bad_time_stamps(nomoto_case):
    with pytest.raises(ValueError, match="Gaussian covariance: not positive semi-definite"):
        cs.Gaussian([0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="must increase strictly; row 2"):
        cs.Dataset([0.0, 0.1, 0.05], {"psi": [0.0, 0.0, 0.0]})
    with pytest.raises(ValueError, match="non-finite time stamp at row 1"):
        cs.Dataset([0.0, np.nan], {"psi": [0.0, 0.0]})
    with pytest.raises(ValueError, match="column 'psi' has 2 rows, time has 3"):
        cs.Dataset([0.0, 0.1, 0.2], {"psi": [0.0, 0.0]})
    with pytest.raises(TypeError, match="needs a DiscreteModel"):
        cs.EKF(nomoto_case[0], 1e-8, 1e-4)
