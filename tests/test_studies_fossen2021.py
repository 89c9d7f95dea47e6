"""The fossen2021 study in quick mode."""
import json

import numpy as np

from problems import get_study


def test_fossen2021_quick(tmp_path):
    summary = get_study("fossen2021").run(tmp_path, quick=True)
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
    assert (tmp_path / "report.md").read_text().startswith("# Fossen")
    json.loads((tmp_path / "summary.json").read_text())


def test_fossen2021_real_logs(tmp_path, data_dir):
    from problems.fossen2021 import part_b

    rows, _ = part_b(data_dir / "usv_fuzhou_gnss", quick=True)
    row = rows["zigzag_30_inter_xy.csv"]
    # the log's speed column is in knots: positions move at about 0.514 of it
    assert abs(row["position_speed_over_log_speed"] - 1852 / 3600) < 0.03
    assert row["sog_rmse_vs_log_mps"] < 0.1
    assert row["cog_median_abs_vs_log_after_lag_deg"] < 10.0
    assert np.isfinite(row["Q_w_chi_mle"])
