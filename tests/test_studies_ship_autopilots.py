"""The ship-autopilots study in quick mode."""
from problems import get_study


def test_ship_autopilots_quick(tmp_path):
    summary = get_study("ship-autopilots").run(tmp_path, quick=True, workers=1)
    assert summary["all_margins_met"]
    assert summary["all_stable"]
    fit = summary["nomoto"]["mariner (zig-zag fit)"]
    lin = summary["nomoto"]["mariner (linearisation)"]
    # the zig-zag fit and the linearisation agree on the rudder effectiveness K/T within 10 %
    assert abs(fit["K_1_s"] / fit["T_s"] / (lin["K_1_s"] / lin["T_s"]) - 1) < 0.1
    rows = summary["closed_loop"]
    assert {r["segment"] for r in rows} >= {"to 20 deg", "back 0 deg", "to 60 deg"}
    assert {r["mode"] for r in rows} == {"heading", "course"}
    assert all(r["max_rudder_deg"] <= 40.0 + 1e-9 for r in rows)
    # the Monte Carlo over noise seeds with the API defaults meets the course-change criteria
    mc = summary["monte_carlo"]["mariner"]
    assert all(v["overshoot_pct_max"] <= 10.0 and v["rate_limited_fraction_max"] < 0.1 for v in mc.values())
    assert (tmp_path / "mariner_course_changes.png").exists()
    assert "GM upper" in (tmp_path / "report.md").read_text()
