"""The mhe-wind study: quick mode (files, complete table, tuning from its grids); full mode marked slow."""
from __future__ import annotations

import json

import numpy as np
import pytest

from problems import get_study
from problems.mhe_wind import D_GRID, FILTERS, Q_GRID, STATES


def test_mhe_wind_quick(tmp_path):
    study = get_study("mhe-wind")
    summary = study.run(tmp_path, quick=True, workers=1)
    for name in ("rmse.md", "rmse.png", "disturbance.png", "summary.json", "report.md"):
        assert (tmp_path / name).is_file(), name
    assert json.loads((tmp_path / "summary.json").read_text())["study"] == "mhe-wind"
    assert summary["tuning"]["q_ekf"] in Q_GRID and summary["tuning"]["q_dist"] in D_GRID
    for f in FILTERS:
        for w in ("0", "1.64"):
            row = summary["rmse"][f"{w}/{f}"]
            assert set(row) == set(STATES)
            # every filter tracks the measured states better than the measurement noise (0.05)
            assert all(np.isfinite(v) and 0 < v < 0.05 for v in row.values()), (f, w, row)
    table = (tmp_path / "rmse.md").read_text()
    assert table.count(", MHE |") == 2                       # one row per wind speed
    report = (tmp_path / "report.md").read_text()
    assert report.splitlines()[0].endswith("(quick run)") and "## Departures from the paper" in report
    assert set(summary["rmse_fujiwara2005"]) == {f"1.64/{f}" for f in FILTERS}


@pytest.mark.slow
def test_mhe_wind_full_mhe_beats_ekf_and_ukf(tmp_path):
    """Full study (5 noise seeds, 200 s): at the strongest wind the disturbance-estimating MHE has a
    lower RMSE than the tuned EKF and UKF in every state."""
    summary = get_study("mhe-wind").run(tmp_path, quick=False, workers=1)
    assert all(summary["mhe_beats_ekf_and_ukf_at_strongest_wind"].values()), summary["rmse"]
