"""Reference values of the manoeuvre and step-response metrics, the IMO limits, the predictive band's
z-value and the integral-LOS integration: hand-built signals whose answers are exact, and the
published limits of IMO MSC.137(76) (Standards for Ship Manoeuvrability, 5.3.3)."""
from __future__ import annotations

import numpy as np
import pytest

from casship import Dataset
from casship.autopilot.guidance import LOSGuidance, Waypoints
from casship.autopilot.performance import step_metrics
from casship.maneuvers import imo_check, zigzag_metrics
from casship.simulation import band_z


# -- IMO MSC.137(76) 5.3.3: the 10/10 zig-zag limits at the edges of their L/V bands --------------------------
def _limits(L_over_V: float) -> tuple[float, float]:
    rows = imo_check(100.0 * L_over_V, 100.0, zz10={"overshoot_1_deg": 0.0, "overshoot_2_deg": 0.0})
    table = {r["criterion"].split(" (")[0]: r["limit"] for r in rows}
    return table["10/10 first overshoot"], table["10/10 second overshoot"]


@pytest.mark.parametrize("L_over_V, first, second", [
    (5.0, 10.0, 25.0),                   # L/V < 10 s: 10 deg and 25 deg
    (9.75, 10.0, 25.0),
    (10.0, 10.0, 25.0),                  # 10 <= L/V < 30 s: 5 + L/2V and 17.5 + 0.75 L/V (continuous at 10 s)
    (12.0, 11.0, 26.5),
    (20.0, 15.0, 32.5),
    (29.0, 19.5, 39.25),
    (30.0, 20.0, 40.0),                  # L/V >= 30 s: 20 deg and 40 deg
    (40.0, 20.0, 40.0),
])
def test_imo_zigzag_10_limits_at_the_band_edges(L_over_V, first, second):
    assert _limits(L_over_V) == (first, second)


def test_imo_second_overshoot_of_the_kvlcc2_is_judged_against_40_deg():
    L, V = 320.0, 7.97                     # KVLCC2 at its approach speed: L/V = 40.2 s
    rows = imo_check(L, V, zz10={"overshoot_1_deg": 19.0, "overshoot_2_deg": 37.0})
    second = [r for r in rows if r["criterion"].startswith("10/10 second")][0]
    assert second["limit"] == 40.0 and second["pass"]


def test_imo_limit_itself_passes_and_just_above_fails():
    at = imo_check(2000.0, 100.0, zz10={"overshoot_1_deg": 15.0, "overshoot_2_deg": 32.5},
                   zz20={"overshoot_1_deg": 25.0})
    assert all(r["pass"] for r in at)
    above = imo_check(2000.0, 100.0, zz10={"overshoot_1_deg": 15.0 + 1e-9, "overshoot_2_deg": 32.5 + 1e-9},
                      zz20={"overshoot_1_deg": 25.0 + 1e-9})
    assert not any(r["pass"] for r in above)


def test_imo_turning_and_initial_turning_limits():
    L = 200.0
    rows = imo_check(L, 5.0, turning={"advance_m": 4.5 * L, "tactical_diameter_m": 5.0 * L + 1e-6},
                     zz10={"initial_turning_distance_m": 2.5 * L})
    table = {r["criterion"].split(" (")[0]: r for r in rows}
    assert table["advance / L"]["limit"] == 4.5 and table["advance / L"]["pass"]
    assert table["tactical diameter / L"]["limit"] == 5.0 and not table["tactical diameter / L"]["pass"]
    assert table["initial turning distance / L"]["limit"] == 2.5 and table["initial turning distance / L"]["pass"]


# -- the zig-zag metrics on a hand-built heading --------------------------------------------------------------
def _zigzag_record():
    """Heading [deg] piecewise linear at 1 deg/s: 0 -> 16 (t = 16) -> -18 (t = 50) -> 19 (t = 87) -> 0 (t = 106),
    sampled every 0.5 s; execute at t = 0."""
    t = np.arange(0.0, 106.5, 0.5)
    psi_deg = np.interp(t, [0.0, 16.0, 50.0, 87.0, 106.0], [0.0, 16.0, -18.0, 19.0, 0.0])
    return Dataset(t, {"psi": np.radians(psi_deg), "x": 2.0 * t, "y": 0.0 * t})


def test_zigzag_overshoots_times_and_period_on_a_hand_built_heading():
    m = zigzag_metrics(_zigzag_record(), 10.0, t_exec=0.0, L=10.0)
    assert m["first_side"] == 1
    # overshoots: 16 - 10, 18 - 10, 19 - 10 deg at the peaks t = 16, 50, 87 s
    assert m["overshoot_1_deg"] == pytest.approx(6.0, abs=1e-9)
    assert m["overshoot_2_deg"] == pytest.approx(8.0, abs=1e-9)
    assert m["overshoot_3_deg"] == pytest.approx(9.0, abs=1e-9)
    assert (m["overshoot_1_time_s"], m["overshoot_2_time_s"], m["overshoot_3_time_s"]) == (16.0, 50.0, 87.0)
    # reversals (the heading reaching +10, -10, +10 deg) at t = 10, 42, 78 s
    assert m["initial_turning_time_s"] == pytest.approx(10.0, abs=1e-9)
    assert m["period_s"] == pytest.approx(68.0, abs=1e-9)
    assert m["initial_turning_distance_m"] == pytest.approx(20.0, abs=1e-9)
    assert m["initial_turning_distance_L"] == pytest.approx(2.0, abs=1e-9)


def test_zigzag_first_to_port_mirrors():
    d = _zigzag_record()
    m = zigzag_metrics(d.with_columns(psi=-d["psi"]), 10.0, t_exec=0.0)
    assert m["first_side"] == -1
    assert (m["overshoot_1_deg"], m["overshoot_2_deg"]) == pytest.approx((6.0, 8.0), abs=1e-9)


# -- step-response metrics at the settling band's edges -------------------------------------------------------
def test_step_metrics_overshoot_and_settling_at_the_band_edge():
    t = np.arange(8.0)
    # change 1 rad, band 25 %: |error| = 0.25 is inside (the band is closed), 0.5 outside
    y = np.array([0.0, 0.5, 1.25, 0.75, 1.0, 1.0, 1.0, 1.0])
    m = step_metrics(t, y, 1.0, band=0.25)
    assert m["overshoot_pct"] == 25.0
    assert m["overshoot_deg"] == pytest.approx(np.degrees(0.25), rel=1e-15)
    assert m["settling_time_s"] == 2.0          # last sample outside: index 1
    assert m["rise_time_s"] == 1.0              # 10 % at t = 1 (0.5), 90 % at t = 2 (1.25)
    # just outside the band at index 3: settles one sample later
    y2 = y.copy()
    y2[3] = 0.75 - 1e-9
    assert step_metrics(t, y2, 1.0, band=0.25)["settling_time_s"] == 4.0
    # the larger of the relative and the absolute band counts
    assert step_metrics(t, y2, 1.0, band=0.25, abs_band=0.3)["settling_time_s"] == 2.0


def test_step_metrics_unsettled_when_the_last_sample_is_outside():
    t = np.arange(5.0)
    y = np.array([0.0, 1.0, 1.0, 1.0, 1.5])
    m = step_metrics(t, y, 1.0, band=0.25)
    assert np.isnan(m["settling_time_s"]) and m["overshoot_pct"] == 50.0
    assert step_metrics(t, np.array([0.0, 0.75, 1.0, 1.0, 1.0]), 1.0, band=0.25)["settling_time_s"] == 1.0
    assert step_metrics(t, np.array([0.0, 0.5, 0.75, 1.0, 1.0]), 1.0, band=0.25)["overshoot_pct"] == 0.0


def test_step_metrics_of_a_negative_change():
    t = np.arange(6.0)
    y = -np.array([0.0, 0.5, 1.25, 0.75, 1.0, 1.0])
    m = step_metrics(t, y, -1.0, band=0.25)
    assert m["overshoot_pct"] == 25.0 and m["settling_time_s"] == 2.0


# -- the predictive band's z-value --------------------------------------------------------------------------
def test_band_z_is_the_two_sided_normal_quantile():
    # Phi(1.959963984540054) = 0.975 (two-sided 95 %); 1.6448536269514722 for 90 %; 2.5758293035489 for 99 %
    assert band_z(0.95) == pytest.approx(1.959963984540054, abs=1e-12)
    assert band_z(0.90) == pytest.approx(1.6448536269514722, abs=1e-12)
    assert band_z(0.99) == pytest.approx(2.5758293035489004, abs=1e-12)
    assert band_z(0.6826894921370859) == pytest.approx(1.0, abs=1e-12)


def test_replay_band_halfwidth_is_z_times_std():
    from casship.maneuvers import ReplayResult
    from casship.trajectory import Trajectory

    std = np.radians(np.array([0.0, 0.5, 1.0, 2.0]))
    tr = Trajectory(np.arange(4.0), {"psi": np.zeros(4)}, model_name="m", state_names=("psi",), input_names=(),
                    output_names=())
    res = ReplayResult(tr, {}, bands={"level": 0.95, "z": band_z(0.95), "psi_std": std,
                                     "cross_track_std": np.array([0.0, 1.0, 2.0, 3.0])})
    s = res.band_summary()
    assert s["psi_halfwidth_max_deg"] == pytest.approx(1.959963984540054 * 2.0, rel=1e-12)
    assert s["cross_track_halfwidth_end_m"] == pytest.approx(1.959963984540054 * 3.0, rel=1e-12)


def test_prediction_bands_carry_the_z_of_their_level():
    from casship.models import nomoto_first_order
    from casship.simulation import prediction_bands

    m = nomoto_first_order(K=0.1, T=20.0)
    X = np.zeros((3, m.nx))
    S = np.zeros((3, m.nx, 1))
    S[:, list(m.state_names).index("psi"), 0] = [0.0, 1.0, 2.0]
    b = prediction_bands(m, X, S, np.array([[0.25]]), 0.95)
    assert b["z"] == pytest.approx(1.959963984540054, abs=1e-12)
    np.testing.assert_allclose(b["psi_std"], [0.0, 0.5, 1.0], rtol=1e-14)


# -- integral LOS: one step of the guidance law against the formula ------------------------------------------
@pytest.mark.parametrize("turn_radius", [None, 50.0])
def test_ilos_step_integrates_at_the_published_rate(turn_radius):
    """Borhaug, Pavlov & Pettersen (2008): chi_d = pi_k - atan((y_e + kappa y_int) / Delta),
    y_int' = Delta y_e / (Delta^2 + (y_e + kappa y_int)^2); one forward-Euler step of dt."""
    wp = Waypoints([0.0, 1000.0, 1000.0], [0.0, 0.0, 1000.0])
    Delta, kappa, dt = 100.0, 2.0, 0.5
    g = LOSGuidance(wp, Delta, 10.0, kappa, turn_radius=turn_radius)
    f = g.function(dt)
    north, east, y_int = 200.0, 30.0, 4.0               # on the first leg (path angle 0): y_e = east
    out = f.call({"memory": [0.0, y_int], "north": north, "east": east, "U": 5.0, "angle": 0.0})
    y_e = 30.0
    s = y_e + kappa * y_int                               # 38
    assert float(out["cross_track"]) == pytest.approx(y_e, abs=1e-12)
    assert float(out["chi_ref"]) == pytest.approx(-np.arctan(s / Delta), abs=1e-14)
    expected = y_int + dt * Delta * y_e / (Delta**2 + s**2)     # 4 + 0.5 * 3000 / 11444
    assert float(np.asarray(out["memory_next"]).ravel()[1]) == pytest.approx(expected, abs=1e-14)
    assert float(np.asarray(out["memory_next"]).ravel()[0]) == 0.0
    assert float(out["y_int"]) == y_int


def test_los_without_integral_keeps_the_integral_at_zero():
    wp = Waypoints([0.0, 1000.0], [0.0, 0.0])
    f = LOSGuidance(wp, 100.0, 10.0).function(1.0)
    out = f.call({"memory": [0.0, 0.0], "north": 10.0, "east": -100.0, "U": 5.0, "angle": 0.0})
    assert float(np.asarray(out["memory_next"]).ravel()[1]) == 0.0
    assert float(out["chi_ref"]) == pytest.approx(np.pi / 4, abs=1e-14)     # atan(100 / 100) back to the track
