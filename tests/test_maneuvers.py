"""Manoeuvre generators and metrics: known answers on synthetic circles and sinusoids."""
import numpy as np
import pytest

from casship import Dataset, simulate
from casship.maneuvers import (imo_check, imo_table, propeller_rate_for_speed, random_rudder_inputs,
                               run_maneuver, spiral_inputs, turning_inputs, turning_metrics, zigzag_metrics)
from casship.models import kvlcc2


def _circle_record(R=500.0, U=4.0, psi0=0.3, direction=1, t_exec=20.0, turns=2.5):
    """Straight run to t_exec, then a perfect circle of radius R at speed U (heading tangent)."""
    t = np.arange(0.0, t_exec + turns * 2 * np.pi * R / U, 0.05)
    r = direction * U / R
    s = np.clip(t - t_exec, 0, None)
    psi = psi0 + r * s
    straight = np.minimum(t, t_exec) * U
    # position: straight along psi0, then arc (in the initial-heading frame)
    along = straight + R * np.sin(r * s * direction) * (t > t_exec)
    lateral = direction * R * (1 - np.cos(r * s)) * (t > t_exec)
    x = along * np.cos(psi0) - lateral * np.sin(psi0)
    y = along * np.sin(psi0) + lateral * np.cos(psi0)
    delta = np.where(t >= t_exec, direction * 0.6, 0.0)
    return Dataset(t, {"x": x, "y": y, "psi": psi, "delta": delta, "u": np.full_like(t, U), "v": 0 * t})


@pytest.mark.parametrize("direction", [1, -1])
def test_turning_metrics_on_a_circle(direction):
    R, t_exec = 500.0, 20.0
    m = turning_metrics(_circle_record(R=R, direction=direction, t_exec=t_exec), L=100.0)
    assert m["turn_direction"] == direction
    assert m["advance_m"] == pytest.approx(R, rel=1e-4)
    assert m["transfer_m"] == pytest.approx(R, rel=1e-4)
    assert m["tactical_diameter_m"] == pytest.approx(2 * R, rel=1e-4)
    assert m["steady_diameter_m"] == pytest.approx(2 * R, rel=1e-6)
    assert m["steady_speed_mps"] == pytest.approx(4.0)
    assert m["time_to_90_s"] == pytest.approx(np.pi / 2 * R / 4.0, rel=1e-4)
    assert m["time_to_180_s"] == pytest.approx(np.pi * R / 4.0, rel=1e-4)
    assert m["advance_L"] == pytest.approx(5.0, rel=1e-4)
    assert abs(m["t_exec_s"] - t_exec) < 0.06


def _sine_record(A_deg=15.0, period=200.0, t_exec=10.0, sign=1.0):
    t = np.arange(0.0, 700.0, 0.02)
    w = 2 * np.pi / period
    psi = 0.2 + sign * np.radians(A_deg) * np.sin(w * np.clip(t - t_exec, 0, None))
    return Dataset(t, {"psi": psi, "x": 5.0 * t, "y": 0 * t}), w


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_zigzag_metrics_on_a_sinusoid(sign):
    A, P, t_exec, sw = 15.0, 200.0, 10.0, 10.0
    data, w = _sine_record(A, P, t_exec, sign)
    m = zigzag_metrics(data, sw, t_exec=t_exec, L=50.0)
    assert m["first_side"] == int(sign)
    assert m["overshoot_1_deg"] == pytest.approx(A - sw, abs=1e-5)
    assert m["overshoot_2_deg"] == pytest.approx(A - sw, abs=1e-5)
    assert m["overshoot_1_time_s"] == pytest.approx(P / 4, abs=0.02)
    assert m["overshoot_2_time_s"] == pytest.approx(3 * P / 4, abs=0.02)
    t_switch = np.arcsin(sw / A) / w
    assert m["initial_turning_time_s"] == pytest.approx(t_switch, abs=1e-3)
    assert m["period_s"] == pytest.approx(P, abs=1e-3)
    assert m["initial_turning_distance_m"] == pytest.approx(5.0 * t_switch, abs=0.11)


def test_imo_limits():
    rows = imo_check(320.0, 8.0, turning={"advance_m": 4.4 * 320, "tactical_diameter_m": 5.1 * 320},
                     zz10={"overshoot_1_deg": 19.0, "overshoot_2_deg": 41.0, "initial_turning_distance_m": 600.0},
                     zz20={"overshoot_1_deg": 12.0})
    table = {r["criterion"].split(" (")[0]: r for r in rows}
    assert table["advance / L"]["pass"] and not table["tactical diameter / L"]["pass"]
    assert table["10/10 first overshoot"]["limit"] == 20.0 and table["10/10 first overshoot"]["pass"]
    assert table["10/10 second overshoot"]["limit"] == 40.0 and not table["10/10 second overshoot"]["pass"]
    assert table["20/20 first overshoot"]["pass"]
    # L/V between 10 and 30 s: 5 + 0.5 L/V
    mid = imo_check(100.0, 5.0, zz10={"overshoot_1_deg": 14.0})
    assert mid[0]["limit"] == pytest.approx(15.0)
    assert "FAIL" in imo_table(rows)


def test_propeller_rate_gives_equilibrium():
    ship = kvlcc2()
    n = propeller_rate_for_speed(ship, 7.97)
    f = np.asarray(ship.f(ship.states(u=7.97), ship.inputs(n=n), ship.params(), np.zeros(3))).ravel()
    assert abs(f[0]) < 1e-9
    assert 1.5 < n < 2.1
    with pytest.raises(ValueError, match="speed"):
        propeller_rate_for_speed(ship, -1.0)


def test_zigzag_controller_switches_on_heading():
    ship = kvlcc2()
    res = run_maneuver(ship, "zigzag", rudder_deg=20, first="port", duration=500, dt=0.5)
    tr = res.trajectory
    assert res.metrics["first_side"] == -1
    # the rudder starts to port (negative) and is reversed when the heading change reaches -20 deg
    k = np.searchsorted(tr.t, 60.0)
    assert tr["delta"][k] == pytest.approx(-np.radians(20))
    rate = np.abs(np.diff(tr["delta"])) / 0.5
    assert rate.max() <= np.radians(2.32) + 1e-12
    assert res.metrics["overshoot_1_deg"] > 0


def test_turning_inputs_ramp_and_generators():
    ship = kvlcc2()
    t = np.arange(0, 40, 0.5)
    u = turning_inputs(ship, t, np.radians(35), 1.7, t_exec=5.0)
    assert u["delta"][t < 5].max() == 0 and u["delta"][-1] == pytest.approx(np.radians(35))
    assert np.diff(u["delta"]).max() <= np.radians(2.32) * 0.5 + 1e-12
    s = spiral_inputs(ship, np.arange(0, 30, 1.0), np.radians([10, -10, 0]), 1.7, hold=10.0, rate=None)
    assert s["delta"][5] == pytest.approx(np.radians(10)) and s["delta"][15] == pytest.approx(np.radians(-10))
    a = random_rudder_inputs(ship, t, 1.7, hold=5.0, seed=4)
    b = random_rudder_inputs(ship, t, 1.7, hold=5.0, seed=4)
    np.testing.assert_array_equal(a["delta"], b["delta"])
    assert np.abs(a["delta"]).max() <= np.radians(35)
    with pytest.raises(ValueError, match="unknown input"):
        turning_inputs(ship, t, 0.1, 1.7, wind=3.0)


def test_run_turning_mirrors_metric_sign_convention():
    ship = kvlcc2()
    res = run_maneuver(ship, "turning", rudder_deg=-35, duration=400, dt=0.5)
    assert res.metrics["turn_direction"] == -1
    assert res.metrics["advance_m"] > 0 and res.metrics["transfer_m"] > 0


def test_models_page_example_runs(tmp_path, monkeypatch):
    import re
    from pathlib import Path

    monkeypatch.chdir(tmp_path)
    page = Path(__file__).resolve().parents[1] / "docs" / "models.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), re.S)
    assert blocks
    for block in blocks:
        exec(compile(block, str(page), "exec"), {})


def test_reverse_spiral_holds_the_yaw_rate_target():
    from casship.maneuvers import ReverseSpiral
    from casship.models import mariner

    ship = mariner({"Y0": 0.0, "Y0u": 0.0, "Y0uu": 0.0, "N0": 0.0, "N0u": 0.0, "N0uu": 0.0})
    target = [np.radians(0.3), -np.radians(0.3)]
    ctrl = ReverseSpiral(ship, target, hold=400.0, gain=20.0)
    t = np.arange(0.0, 800.0, 0.5)
    tr = simulate(ship, ship.states(u=7.7175), t, ctrl)
    for k, r_t in enumerate(target):
        seg = (t > k * 400 + 300) & (t < (k + 1) * 400)
        assert np.mean(tr["r"][seg]) == pytest.approx(r_t, rel=0.05)
        assert np.sign(np.mean(tr["delta"][seg])) == np.sign(r_t)


def test_pullout_of_a_stable_ship_returns_to_straight():
    from casship.models import mariner

    ship = mariner({"Y0": 0.0, "Y0u": 0.0, "Y0uu": 0.0, "N0": 0.0, "N0u": 0.0, "N0uu": 0.0})
    res = run_maneuver(ship, "pullout", rudder_deg=20, hold=200.0, duration=900.0, dt=0.5)
    assert abs(res.metrics["yaw_rate_at_release_deg_s"]) > 0.3
    assert abs(res.metrics["residual_yaw_rate_deg_s"]) < 0.01
