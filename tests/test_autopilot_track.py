"""Track control: wheel-over points from the turn radius, turns along arcs, the rate-of-turn mode,
lookahead sized by the ship."""
import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap
from casship.autopilot.guidance import LOSGuidance, Waypoints, track_deviation


@pytest.fixture(scope="module")
def kvlcc2():
    return ap.design_autopilot(cs.models.get_model("kvlcc2"))


def test_wheel_over_and_turn_geometry():
    wp = Waypoints([0.0, 100.0, 100.0, 0.0], [0.0, 0.0, 100.0, 100.0])
    g = LOSGuidance(wp, 20.0, 20.0, turn_radius=30.0)
    np.testing.assert_allclose(g.wheel_over(), [30.0, 30.0])                  # R tan(90 deg / 2)
    g60 = LOSGuidance(Waypoints([0.0, 100.0, 200.0], [0.0, 0.0, 100 * np.sqrt(3.0)]), 20.0, 20.0, turn_radius=30.0)
    np.testing.assert_allclose(g60.wheel_over(), [30.0 * np.tan(np.radians(30.0))])
    els = g.elements()
    assert [e["kind"] for e in els] == ["line", "arc", "line", "arc", "line"]
    assert els[1]["side"] == 1.0 and els[3]["side"] == 1.0                    # two starboard turns
    np.testing.assert_allclose(els[1]["centre"], [70.0, 30.0])
    track = wp.track(30.0, spacing=0.5)
    # the arc keeps the turn radius from its centre and passes R (sqrt 2 - 1) inside the corner
    near = np.hypot(track[:, 0] - 70.0, track[:, 1] - 30.0)
    on_arc = (track[:, 0] > 70.0) & (track[:, 1] < 30.0)
    np.testing.assert_allclose(near[on_arc], 30.0, atol=1e-9)
    assert np.min(np.hypot(track[:, 0] - 100.0, track[:, 1])) == pytest.approx(30.0 * (np.sqrt(2.0) - 1.0), abs=0.3)
    with pytest.raises(ValueError, match="too short"):
        LOSGuidance(Waypoints([0.0, 20.0, 20.0], [0.0, 0.0, 20.0]), 20.0, 20.0, turn_radius=30.0)
    with pytest.raises(ValueError, match="170 deg"):
        LOSGuidance(Waypoints([0.0, 100.0, 0.0], [0.0, 0.0, 1.0]), 20.0, 20.0, turn_radius=5.0)


def test_guidance_on_a_turn_commands_the_tangent_with_the_lead():
    wp = Waypoints([0.0, 100.0, 100.0], [0.0, 0.0, 100.0])
    g = LOSGuidance(wp, 20.0, 20.0, turn_radius=30.0, lead=5.0)
    f = g.function(0.1)
    # on the arc (element 1), at 45 deg round it, on the radius: course 45 deg plus the lead 5 U/R
    c = np.array([70.0, 30.0])
    p = c + 30.0 * np.array([np.cos(-np.pi / 4), np.sin(-np.pi / 4)])
    out = f.call({"memory": [1.0, 0.0], "north": p[0], "east": p[1], "U": 3.0, "angle": 0.0})
    assert float(out["cross_track"]) == pytest.approx(0.0, abs=1e-12)
    assert float(out["chi_ref"]) == pytest.approx(np.pi / 4 + 5.0 * 3.0 / 30.0)
    assert float(out["segment"]) == 1.0
    # at the wheel-over point of the first leg the turn begins
    w = f.call({"memory": [0.0, 0.0], "north": 70.5, "east": 0.0, "U": 3.0, "angle": 0.0})
    assert float(np.ravel(np.asarray(w["memory_next"]))[0]) == 1.0
    w = f.call({"memory": [0.0, 0.0], "north": 69.5, "east": 0.0, "U": 3.0, "angle": 0.0})
    assert float(np.ravel(np.asarray(w["memory_next"]))[0]) == 0.0


def test_wheel_over_keeps_the_ship_on_the_turning_track(kvlcc2):
    """KVLCC2, heading autopilot, two 90 deg turns: turning at the wheel-over points along arcs of
    the design's turn radius keeps the ship within a ship length of the turning track, less than
    half the largest deviation when the legs change at the circle of acceptance."""
    d = kvlcc2
    L, U = d.plant.model.vessel.L_pp, d.settings.speed
    D = LOSGuidance.for_design(Waypoints([0.0, 1.0], [0.0, 0.0]), d).lookahead
    assert D == pytest.approx(max(2 * L, 3 * U / d.settings.wn_ref))      # three ship lengths for the KVLCC2
    assert 2 * L <= D <= 5 * L
    wp = Waypoints([0.0, 12 * D, 12 * D, 24 * D], [0.0, 0.0, 12 * D, 12 * D])
    track = LOSGuidance.for_design(wp, d)
    worst = {}
    for wheel_over in (True, False):
        g = LOSGuidance.for_design(wp, d, wheel_over=wheel_over)
        data = d.closed_loop_system(guidance=g).run(0.0, 40 * D / U, seed=1)
        assert data["segment"][-1] == 2
        worst[wheel_over] = np.max(track_deviation(data, track))
    assert worst[True] < L
    assert worst[True] < 0.5 * worst[False]


def test_rate_of_turn_mode(kvlcc2):
    """rot-R: the course command moves at R deg/min; the ship turns at that rate."""
    d = kvlcc2
    rate = 0.5 * np.degrees(d.settings.r_max) * 60.0             # deg/min, half the preset rate
    res = d.simulate(f"rot-{rate:.4g}", warn=False)
    t, r = res.data.t, res.data["r"]
    steady = (t > 0.25 * t[-1]) & (t < 0.5 * t[-1])
    assert np.mean(r[steady]) == pytest.approx(np.radians(rate / 60.0), rel=0.02)
    assert np.max(np.abs(r)) <= 1.1 * d.settings.r_max
