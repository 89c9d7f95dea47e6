"""Study ``kvlcc2-maneuvers`` in quick mode (with and without the MARIN data)."""
import json

import numpy as np
import pytest

import problems
from problems import kvlcc2_maneuvers as study


def test_quick_study_with_data(tmp_path, data_dir):
    if not (data_dir / "kvlcc2_marin_free").is_dir():
        pytest.skip("MARIN data absent")
    summary = problems.get_study("kvlcc2-maneuvers").run(tmp_path, quick=True, data_dir=data_dir)
    assert summary["data"] is True
    for name in ("turning_35", "zigzag_10", "zigzag_20"):
        assert (tmp_path / f"fig_{name}.png").stat().st_size > 10_000
        run = summary["runs"][name]
        assert set(run["metrics"]) == {"measured", "simulated", "replayed"}
        assert set(run["replay_errors"]) == {"psi_rmse_deg", "position_rmse_m", "u_rmse_mps"}
    turn = summary["runs"]["turning_35"]["metrics"]
    # the measured turning circle is the MARIN run read by the same metric functions
    assert turn["measured"]["advance_L"] == pytest.approx(3.09, abs=0.05)
    assert turn["measured"]["tactical_diameter_L"] == pytest.approx(3.33, abs=0.05)
    # the model predicts the turning circle within 15 % (advance, transfer, tactical diameter)
    for key in ("advance_m", "transfer_m", "tactical_diameter_m"):
        assert turn["simulated"][key] == pytest.approx(turn["measured"][key], rel=0.15), key
    zz10 = summary["runs"]["zigzag_10"]
    assert zz10["first_side"] == -1 and zz10["metrics"]["measured"]["overshoot_1_deg"] == pytest.approx(9.33, abs=0.1)
    assert summary["runs"]["zigzag_20"]["first_side"] == 1
    report = (tmp_path / "report.md").read_text()
    assert "IMO MSC.137(76)" in report and "Differences" in report and "## Departures from the paper" in report
    deps = {d["topic"]: d["effect"] for d in summary["departures"]}
    assert "advance/L" in deps["propeller rate"] and "->" in deps["rudder rate"]
    assert json.dumps(summary, default=float)


def test_quick_study_without_data(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    summary = study.run(tmp_path / "out", quick=True, data_dir=tmp_path / "empty")
    assert "skipped the comparison with the MARIN free-running runs" in capsys.readouterr().err
    assert summary["data"] is False
    assert "absent" in (tmp_path / "out" / "report.md").read_text()
    m = summary["runs"]["turning_35"]["metrics"]["simulated"]
    assert np.isfinite(m["tactical_diameter_m"]) and "measured" not in summary["runs"]["turning_35"]["metrics"]
