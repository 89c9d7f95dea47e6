"""The path-following, wave-filter and MPC studies in quick mode (Otter)."""
from problems import get_study


def test_path_following_quick(tmp_path):
    s = get_study("path-following").run(tmp_path, quick=True, workers=1)
    leg1 = {r["controller"]: r for r in s["table"] if r["leg"].startswith("leg 1")}
    # across the current: plain LOS on a heading autopilot keeps an offset, ILOS and course control do not
    assert leg1["heading, LOS"]["mean_over_lookahead"] > 0.03
    assert abs(leg1["heading, ILOS"]["mean_over_lookahead"]) < 0.3 * leg1["heading, LOS"]["mean_over_lookahead"]
    assert abs(leg1["course, LOS"]["mean_over_lookahead"]) < 0.3 * leg1["heading, LOS"]["mean_over_lookahead"]
    text = (tmp_path / "report.md").read_text()
    assert "(quick run)" in text and "Departures from the paper" in text
    assert (tmp_path / "otter_path_following.png").exists()


def test_autopilot_waves_quick(tmp_path):
    s = get_study("autopilot-waves").run(tmp_path, quick=True, workers=1)
    rows = {r["wave_filter"]: r for r in s["table"]}
    # the wave filter takes the wave band out of the steering: less rudder, less rudder rate
    assert rows[True]["steer_rms"] < 0.5 * rows[False]["steer_rms"]
    assert rows[True]["steer_rate_rms"] < 0.5 * rows[False]["steer_rate_rms"]
    assert (tmp_path / "otter_waves.png").exists()


def test_autopilot_mpc_quick(tmp_path):
    s = get_study("autopilot-mpc").run(tmp_path, quick=True, workers=1)
    rows = {r["controller"]: r for r in s["table"] if r["scenario"] == "course-20" and r["reading"] == "casship"}
    assert set(rows) == {"PID", "LQR", "MPC"}
    for r in rows.values():
        assert max(r["overshoot_pct"]) <= 10.0
    assert (tmp_path / "otter_mpc_pid_lqr.png").exists()
