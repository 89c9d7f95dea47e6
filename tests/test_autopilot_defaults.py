"""Defaults that work: derived from the ship, one set for the API and the CLI, checked in closed loop."""
import dataclasses
import warnings

import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap


@pytest.mark.parametrize("name", ["kvlcc2", "otter"])
def test_api_defaults_meet_the_course_change_criteria(name):
    """design_autopilot + simulate with nothing but the ship: both course changes of the standard
    scenario overshoot at most 10 %, end without steady error, and the steering gear is at its rate
    limit less than 10 % of the time (the performance report's own checks)."""
    d = ap.design_autopilot(cs.models.get_model(name))
    with warnings.catch_warnings():
        warnings.simplefilter("error", ap.RateLimitWarning)
        res = d.simulate()
    assert len(res.metrics) == 2
    for m in res.metrics:
        assert abs(m["change_deg"]) == pytest.approx(20.0, abs=0.5)
        assert m["overshoot_pct"] <= 10.0
        assert abs(m["steady_state_error_deg"]) <= 0.5
    assert res.performance["rate_limited_fraction"] < 0.10
    assert res.performance["all_ok"]
    assert d.margins["closed_loop_stable"]


@pytest.mark.parametrize("name", ["otter", "kvlcc2"])
@pytest.mark.parametrize("mode", ["heading", "course"])
def test_api_defaults_meet_the_criteria_on_large_course_changes(name, mode):
    """20, 60 and 90 deg and back, heading and course mode, API defaults: every change overshoots at
    most 10 % and settles (2 % of the change or 1 deg) without steady error, the steering gear is at
    its rate limit less than 10 % of the time, and the rate of turn stays within 10 % of the preset
    rate (IMO A.342(IX) 3.2): every check of the performance report."""
    d = ap.design_autopilot(cs.models.get_model(name), mode=mode)
    assert d.settings.r_max <= d.settings.turn_rate_top
    for change in (20, 60, 90):
        with warnings.catch_warnings():
            warnings.simplefilter("error", ap.RateLimitWarning)
            res = d.simulate(f"course-{change}")
        for m in res.metrics:
            assert abs(m["change_deg"]) == pytest.approx(change, abs=0.5)
            assert m["overshoot_pct"] <= 10.0 and np.isfinite(m["settling_time_s"])
        assert res.performance["all_ok"], [c for c in res.performance["checks"] if c["ok"] is False]


def test_settings_record_where_each_value_came_from():
    d = ap.design_autopilot(cs.models.get_model("kvlcc2"), wn=0.02, gnss_std=1.0)
    s = d.settings
    assert s.sources["wn"] == "given" and s.sources["gnss_std"] == "given"
    assert s.wn == 0.02 and d.gains.Kp == pytest.approx(d.nomoto.m * 0.02**2)
    assert s.steer_max == pytest.approx(np.radians(35.0)) and s.sources["steer_max"] == ap.RULES["steer_max"][1]
    assert s.steer_rate_max == pytest.approx(np.radians(2.32))
    assert s.speed == pytest.approx(cs.models.get_model("kvlcc2").vessel.U0)
    # every setting has a rule (shown by --help and the docs)
    names = {f.name for f in dataclasses.fields(ap.AutopilotSettings)} - {"sources", "steering"}
    assert names == set(ap.RULES)


def test_unknown_setting_is_named():
    with pytest.raises(ValueError, match=r"unknown autopilot setting\(s\) \['wm'\]"):
        ap.design_autopilot(cs.models.get_model("kvlcc2"), wm=0.02)
    with pytest.raises(ValueError, match="method"):
        ap.design_autopilot(cs.models.get_model("kvlcc2"), method="h-infinity")


def test_estimator_tuning_meets_the_steering_noise_budget():
    """The course-rate process noise is the largest that keeps the sensor noise on the steering
    command within the budget (steady-state Kalman filter from control.dlqe); noisier GNSS gives a
    slower filter for the same gains."""
    from casship.autopilot.estimation import tune_course_q

    kw = dict(speed=7.7, alpha=(0.01, 0.05), q_U=1e-3, q_chi_max=1e-3, dt=0.1, gnss_every=2, Kp=1.3, Kd=30.0,
              budget=np.radians(1.0))
    q, sigma = tune_course_q(gnss_std=0.5, **kw)
    assert sigma <= kw["budget"]
    _, sigma_up = tune_course_q(gnss_std=0.5, **{**kw, "q_chi_max": q * 10 ** 0.25 * (1 + 1e-12), "budget": np.inf})
    assert sigma_up > kw["budget"]
    q_noisy, _ = tune_course_q(gnss_std=2.0, **kw)
    assert q_noisy < q


def test_two_propeller_craft_steers_by_yaw_moment_within_the_propeller_limits():
    otter = cs.models.get_model("otter")
    d = ap.design_autopilot(otter)
    assert d.plant.steer == "tau_N"
    limit = ap.twin_propeller_yaw_limit(otter, d.plant.inputs["tau_X"])
    assert d.settings.steer_max == pytest.approx(limit)
    assert d.settings.actuator_T == pytest.approx(0.1)
