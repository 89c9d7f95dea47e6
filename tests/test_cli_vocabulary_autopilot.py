"""``casship autopilot`` says what ran: the controller in header, JSON and figure title; the designs a
gain schedule interpolates (speeds and gains, in the output and the figure); the track scenario
with its waypoints and intended track."""
import json

import numpy as np
import pytest
from matplotlib.image import imread

from casship import autopilot as ap
from casship.cli import main
from casship.models import get_model


def test_an_mpc_run_is_headed_mpc(capsys):
    assert main(["autopilot", "--model", "otter", "--controller", "mpc", "--duration", "40"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].startswith("controller: mpc (HPIPM, period"), lines[1]
    assert not lines[1].startswith("pid") and lines[2].startswith("pid-pole-placement-fossen design")
    assert main(["autopilot", "--model", "otter", "--duration", "40", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["controller"] == "pid-pole-placement-fossen"


def test_schedule_reports_the_point_designs(capsys, tmp_path):
    assert main(["autopilot", "--model", "otter", "--speed", "1.0", "--schedule", "0.8", "1.4", "2.0",
                 "--duration", "60", "--json", "--plot", str(tmp_path / "fig")]) == 0
    out = json.loads(capsys.readouterr().out)
    rows = out["schedule"]
    assert [r["speed_m_s"] for r in rows] == pytest.approx([0.8, 1.4, 2.0])
    assert out["controller"] == "pid-pole-placement-fossen gain schedule (3 speeds)"
    # each row is the point design at its speed (the same numbers as designing there alone)
    for r in rows:
        point = ap.design_autopilot(get_model("otter"), r["speed_m_s"])
        assert r["Kp"] == pytest.approx(point.gains.Kp, rel=1e-9)
        assert r["Kd_s"] == pytest.approx(point.gains.Kd, rel=1e-9)
        assert r["Ki_1_s"] == pytest.approx(point.gains.Ki, rel=1e-9)
    assert imread(tmp_path / "fig" / "otter_loop.png").shape[0] > 100
    assert main(["autopilot", "--model", "otter", "--speed", "1.0", "--schedule", "0.8", "1.4", "2.0",
                 "--duration", "60"]) == 0
    text = capsys.readouterr().out
    assert "gain schedule: 3 point designs" in text
    assert sum(1 for line in text.splitlines() if line.split()[:1] in (["0.8"], ["1.4"], ["2"])) == 3


def test_track_scenario_follows_the_waypoints(capsys, tmp_path):
    assert main(["autopilot", "--model", "otter", "--scenario", "track", "--waypoints", "0,0", "150,0", "150,150",
                 "--json", "--plot", str(tmp_path / "fig")]) == 0
    out = json.loads(capsys.readouterr().out)
    tr = out["track"]
    assert tr["waypoints_north_m"] == [0.0, 150.0, 150.0] and tr["waypoints_east_m"] == [0.0, 0.0, 150.0]
    assert tr["legs"] == 2 and tr["legs_reached"] == 2
    assert tr["track_deviation_max_m"] < 0.1 * 150.0       # within a tenth of a leg of the turning track
    assert (tmp_path / "fig" / "otter_track.png").is_file()
    assert main(["autopilot", "--model", "otter", "--scenario", "track", "--waypoints", "0,0", "x"]) == 2
    assert "--waypoints: 'x' is not a North,East pair" in capsys.readouterr().err
    assert main(["autopilot", "--model", "otter", "--waypoints", "0,0", "1,1"]) == 2
    assert "only the track scenario" in capsys.readouterr().err
