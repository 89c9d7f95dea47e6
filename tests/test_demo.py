"""The quick end-to-end demonstration (``casship demo --quick``) and what its report must show."""
from __future__ import annotations

import json

import numpy as np

from casship.cli import main


def test_demo_quick_writes_report_and_recovers_the_ship(tmp_path, capsys):
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    assert "report written" in capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    report = (tmp_path / "report.md").read_text()
    assert report.splitlines()[0].startswith("# casship demo (quick run)")
    assert "The trials are simulated, not measured" in report      # before: the report did not say so
    # rudder rate next to rudder angle, for the records and the closed loop; never above the ship's limit
    assert "| max rudder angle [deg] | max rudder rate [deg/s] |" in report
    for motion in summary["rudder"].values():
        assert 0 < motion["max_rudder_rate_deg_s"] <= summary["rudder_rate_limit_deg_s"] * (1 + 1e-9)
    # a second run into the same folder is refused before any work, naming the way out
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "folder exists and is not empty; pass --overwrite" in err and "Traceback" not in err
    for fig in summary["figures"]:
        assert (tmp_path / fig).stat().st_size > 10_000
        assert f"]({fig})" in report
    # the unmeasured sway speed is reconstructed, and smoothing (which sees the future) does better
    rmse = summary["rmse"]
    for state in ("u", "v"):
        assert rmse["EKF+RTS"][state] < rmse["EKF"][state]
    assert all(summary["filter_health_ok"].values())
    # the maximum-likelihood fit converges and its standard errors cover the truth (fixed seed)
    fit = summary["fit"]
    assert fit["status"] == "converged"
    for row in fit["params"].values():
        assert abs(row["z"]) < 4.0
        assert abs(row["estimate"] - row["true"]) < abs(row["guess"] - row["true"]) / 10
    # the fitted model predicts manoeuvres it never saw far better than the initial guess
    for rows in summary["validation"].values():
        assert rows["fitted"]["position_rms_m"] < rows["initial guess"]["position_rms_m"] / 5
    # the autopilot designed on the fitted model holds the true ship on the commanded heading
    for step in summary["autopilot"]["closed_loop"]:
        assert abs(step["steady_state_error_deg"]) < 1.0
        assert step["overshoot_deg"] < 0.25 * abs(step["change_deg"])
    assert summary["autopilot"]["design"]["margins"]["closed_loop_stable"]
    assert np.isfinite(summary["seconds"])


def test_demo_out_is_a_file(tmp_path, capsys):
    target = tmp_path / "report.txt"
    target.write_text("mine")
    assert main(["demo", "--out", str(target)]) == 2
    err = capsys.readouterr().err
    assert err.strip().endswith("is a file, not a folder; choose a folder name") and "Traceback" not in err
    assert target.read_text() == "mine"
