"""``casship autopilot`` on the command line."""
import json

import pytest

from casship.cli import main


def test_autopilot_json_reports_margins_and_metrics(capsys, tmp_path):
    code = main(["autopilot", "shi-taylor", "--speed", "8", "--wn", "0.05", "--scenario", "course-20",
                 "--t-end", "400", "--json", "--plot", str(tmp_path), "--current", "0.5", "90"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == "shi-taylor"
    assert set(out["margins"]) >= {"gain_margin_db", "phase_margin_deg", "closed_loop_stable"}
    assert out["margins"]["closed_loop_stable"]
    assert len(out["metrics"]) == 2
    first = out["metrics"][0]
    assert first["target_deg"] == pytest.approx(20.0)
    assert abs(first["steady_state_error_deg"]) < 1.0
    assert out["inputs"]["n"] > 0
    assert (tmp_path / "shi-taylor_course-20.png").exists() and (tmp_path / "shi-taylor_loop.png").exists()


def test_autopilot_text_output_and_errors(capsys):
    assert main(["autopilot", "shi-taylor", "--speed", "8", "--wn", "0.05", "--t-end", "100"]) == 0
    text = capsys.readouterr().out
    assert "margins" in text and "Nomoto" in text
    assert main(["autopilot", "no-such-ship", "--speed", "8"]) == 2
    assert "no-such-ship" in capsys.readouterr().err
    assert main(["autopilot", "shi-taylor", "--speed", "8", "--wn", "0.05", "--scenario", "zigzag"]) == 2
    assert "zigzag" in capsys.readouterr().err
