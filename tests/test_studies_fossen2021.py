"""The fossen2021 study: the paper's course command (back to 0 deg at t = 20 s in both modes), the quick
run, and the real-data part on the substitute vessel's logs."""
import json

import numpy as np
import pytest

from problems import fossen2021, get_study


@pytest.mark.parametrize("quick", [True, False])
def test_course_command_returns_to_zero_at_20_s_in_both_modes(quick):
    command, t_end, steps = fossen2021.course_command(quick)
    assert steps == [0.0, 20.0]
    assert t_end > 20.0
    assert command(19.99) == pytest.approx(np.radians(20.0)) and command(20.0) == 0.0
    assert command(24.99) == 0.0          # the old full run (t_end = 50 s) switched back at t_end / 2 = 25 s


def test_fossen2021_quick(tmp_path):
    summary = get_study("fossen2021").run(tmp_path, quick=True, data_dir=None)
    assert summary["command_back_s"] == pytest.approx(20.0)
    # the EKF run online inside the loop equals the batch filter on the same record
    assert summary["online_vs_batch_max_chi_diff_rad"] < 1e-9
    est = summary["estimation"]
    for row in est.values():
        assert row["U_rmse_mps"] < 0.1 and row["chi_rmse_deg"] < 5.0
    first, second = summary["closed_loop"]
    assert first["target_deg"] == 20.0 and second["target_deg"] == 0.0
    assert abs(first["steady_state_error_deg"]) < 1.5 and abs(second["steady_state_error_deg"]) < 1.5
    assert summary["margins"]["closed_loop_stable"]
    for name in ("fig4_north_east.png", "fig5_propellers.png", "fig6_sog_cog_rate.png"):
        assert (tmp_path / name).exists()
    report = (tmp_path / "report.md").read_text()
    assert report.splitlines()[0] == ("# Fossen & Fossen (2021): SOG/COG/course-rate EKF and Otter course "
                                      "autopilot (quick run)")
    assert "## Departures from the paper" in report
    topics = [d["topic"] for d in summary["departures"]]
    assert {"GNSS rate", "GNSS position noise", "speed of the simulated course change"} <= set(topics)
    json.loads((tmp_path / "summary.json").read_text())


def test_fossen2021_real_logs(tmp_path, data_dir):
    rows, _ = fossen2021.part_b(data_dir / "usv_fuzhou_gnss", quick=True)
    row = rows["zigzag_30_inter_xy.csv"]
    # the log's speed column is in knots: positions move at about 0.514 of it
    assert abs(row["position_speed_over_log_speed"] - 1852 / 3600) < 0.03
    assert row["sog_rmse_vs_log_mps"] < 0.1
    assert row["cog_median_abs_vs_log_after_lag_deg"] < 10.0
    assert np.isfinite(row["Q_w_chi_mle"])
    # a substitute vessel in the slow-speed regime: every logged speed is below the paper's 1 m/s
    assert 0.4 < row["log_sog_p5_mps"] < row["log_sog_p95_mps"] < 1.0
