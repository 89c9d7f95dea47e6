"""LOS and integral LOS guidance: convergence to a straight path, crab compensation, waypoints."""
import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap
from casship.autopilot.guidance import LOSGuidance, Waypoints, cross_track_metrics
from casship.models.wind import add_current


@pytest.fixture(scope="module")
def otter():
    return ap.design_autopilot(add_current(cs.models.get_model("otter")))


def test_waypoint_geometry_and_errors():
    wp = Waypoints([0.0, 100.0, 100.0], [0.0, 0.0, 50.0])
    np.testing.assert_allclose(wp.angles, [0.0, np.pi / 2])
    np.testing.assert_allclose(wp.lengths, [100.0, 50.0])
    s, y = wp.errors(30.0, 4.0, 0)
    assert (s, y) == pytest.approx((30.0, 4.0))             # right of a northbound path: positive
    s, y = wp.errors(103.0, 20.0, 1)
    assert (s, y) == pytest.approx((20.0, -3.0))            # eastbound: North of it is left
    with pytest.raises(ValueError, match="repeats"):
        Waypoints([0.0, 0.0], [1.0, 1.0])
    with pytest.raises(ValueError, match="at least two"):
        Waypoints([0.0], [0.0])


def test_los_law_and_switching_on_the_function():
    wp = Waypoints([0.0, 100.0, 100.0], [0.0, 0.0, 100.0])
    los = LOSGuidance(wp, lookahead=20.0, acceptance=10.0)
    f = los.function(0.1)
    out = f.call({"memory": [0.0, 0.0], "north": 10.0, "east": -20.0, "U": 2.0, "angle": 0.0})
    assert float(out["chi_ref"]) == pytest.approx(np.arctan(20.0 / 20.0))      # steer back towards the path
    assert float(out["cross_track"]) == pytest.approx(-20.0)
    assert float(np.ravel(np.asarray(out["memory_next"]))[0]) == 0.0
    inside = f.call({"memory": [0.0, 0.0], "north": 95.0, "east": 3.0, "U": 2.0, "angle": 0.0})
    assert float(np.ravel(np.asarray(inside["memory_next"]))[0]) == 1.0        # circle of acceptance: next leg
    last = f.call({"memory": [1.0, 0.0], "north": 100.0, "east": 99.0, "U": 2.0, "angle": 0.0})
    assert float(np.ravel(np.asarray(last["memory_next"]))[0]) == 1.0          # the last leg is kept


def test_los_converges_to_a_straight_path_from_an_offset(otter):
    """Otter, heading autopilot, calm water: starting one lookahead to the left of a straight path,
    LOS brings the cross-track error down to the sensor-noise level and keeps it there."""
    d = otter
    wp = Waypoints([0.0, 400.0], [0.0, 0.0])
    los = LOSGuidance.for_design(wp, d)
    loop = d.closed_loop_system(guidance=los)
    x0 = loop.plant.x0.copy()
    x0[loop.plant.model.index("y")] = -los.lookahead
    data = loop.run(0.0, 150.0, x0=x0, seed=1)
    _, y = wp.errors(data["north"], data["east"], 0)          # true cross-track error (guidance sees GNSS fixes)
    assert y[0] == pytest.approx(-los.lookahead)
    late = data.t >= 100.0
    assert np.sqrt(np.mean(y[late] ** 2)) < 0.05 * los.lookahead
    assert abs(np.mean(y[late])) < 0.02 * los.lookahead
    assert cross_track_metrics(data, start=100.0)["cross_track_rms_m"] < 0.1 * los.lookahead
    # the error decays: each 25 s window has a smaller peak than the one before until the noise floor
    peaks = [np.max(np.abs(y[(data.t >= a) & (data.t < a + 25.0)])) for a in (0.0, 25.0, 50.0)]
    assert peaks[0] > peaks[1] > peaks[2]


def test_integral_los_removes_the_offset_a_current_leaves(otter):
    d = otter
    wp = Waypoints([0.0, 1000.0], [0.0, 0.0])
    env = {"current_speed": 0.2, "current_dir": np.radians(90.0)}
    means = {}
    for integral in (False, True):
        loop = d.closed_loop_system(environment=env, guidance=LOSGuidance.for_design(wp, d, integral=integral))
        data = loop.run(0.0, 250.0, seed=2)
        means[integral] = cross_track_metrics(data, start=150.0)["cross_track_mean_m"]
    Delta = LOSGuidance.for_design(wp, d).lookahead
    assert means[False] > 0.03 * Delta                     # pushed to the right (East) of a northbound path
    assert abs(means[True]) < 0.2 * means[False]


def test_guided_loop_compiled_equals_stepwise(otter):
    wp = Waypoints([0.0, 60.0, 60.0], [0.0, 0.0, 60.0])
    loop = otter.closed_loop_system(guidance=LOSGuidance.for_design(wp, otter, integral=True),
                                    environment={"current_speed": 0.2, "current_dir": 1.0})
    a, b = loop.run(0.0, 40.0, seed=3), loop.run_stepwise(0.0, 40.0, seed=3)
    for name in ("cross_track", "segment", "y_int", "psi", "steer"):
        np.testing.assert_allclose(a[name], b[name], atol=1e-12, rtol=0)


def _los_step(g, memory, north, east):
    out = g.function(0.1).call({"memory": memory, "north": north, "east": east, "U": 1.0, "angle": 0.0})
    return np.asarray(out["memory_next"]).ravel()


@pytest.mark.parametrize("turn_deg", [90.0, 60.0])
def test_ilos_integral_at_a_waypoint_by_rule(turn_deg):
    """At the switch to the next leg the integral is kept (MSS), reset, or projected by the cosine of
    the course change (hand-computed: 0 for 90 deg, half for 60 deg)."""
    a = np.radians(turn_deg)
    wp = Waypoints([0.0, 100.0, 100.0 + 100.0 * np.cos(a)], [0.0, 0.0, 100.0 * np.sin(a)])
    y_int = 3.0
    at = [100.5, 0.0]                                         # past the first waypoint: the leg changes
    for rule, expect in (("keep", y_int), ("reset", 0.0), ("project", np.cos(a) * y_int)):
        g = LOSGuidance(wp, 20.0, 5.0, 0.5, at_switch=rule, integrate_within=None)
        mem = _los_step(g, np.array([0.0, y_int]), *at)
        assert mem[0] == 1.0
        assert mem[1] == pytest.approx(expect, abs=1e-12)
    with pytest.raises(ValueError, match="at_switch"):
        LOSGuidance(wp, 20.0, 5.0, 0.5, at_switch="hold")


def test_ilos_integrates_only_near_the_path():
    """Conditional integration: within half a lookahead the Borhaug et al. increment
    dt Delta y_e / (Delta^2 + (y_e + kappa y_int)^2); beyond it, none."""
    wp = Waypoints([0.0, 1000.0], [0.0, 0.0])
    g = LOSGuidance(wp, 20.0, 5.0, 0.5)                       # the default: within 0.5 Delta
    assert (g.at_switch, g.integrate_within) == ("project", 0.5)
    near = _los_step(g, np.array([0.0, 1.0]), 50.0, 8.0)[1]
    assert near == pytest.approx(1.0 + 0.1 * 20.0 * 8.0 / (20.0**2 + (8.0 + 0.5) ** 2), rel=1e-12)
    assert _los_step(g, np.array([0.0, 1.0]), 50.0, 10.5)[1] == 1.0
    mss = LOSGuidance(wp, 20.0, 5.0, 0.5, at_switch="keep", integrate_within=None)
    assert _los_step(mss, np.array([0.0, 1.0]), 50.0, 10.5)[1] > 1.0
