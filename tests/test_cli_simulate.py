"""``casship simulate``: the documented command forms, JSON keys, CSV/plot output and replay."""
import json

import numpy as np
import pytest

from casship import Dataset
from casship.cli import main


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_turning_json_form(capsys):
    out = _json(capsys, ["simulate", "--model", "kvlcc2", "--maneuver", "turning", "--rudder-deg", "35", "--speed", "7.97",
                         "--duration", "800", "--json"])
    assert out["L_pp_m"] == 320.0
    m = out["metrics"]
    for key in ("advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m", "time_to_90_s"):
        assert np.isfinite(m[key]), key
    assert 2.5 * 320 < m["advance_m"] < 4.5 * 320
    assert 1.5 < out["rps"] < 2.1     # solved for equilibrium at 7.97 m/s


def test_zigzag_port_first_and_rps(capsys, tmp_path):
    csv, png = tmp_path / "zz.csv", tmp_path / "zz.png"
    out = _json(capsys, ["simulate", "--model", "kvlcc2-l7", "--maneuver", "zigzag", "--rudder-deg", "20", "--first", "port",
                         "--rps", "11.0", "--speed", "1.18", "--json", "--csv", str(csv), "--plot", str(png)])
    assert out["rps"] == 11.0 and out["L_pp_m"] == 7.0
    assert out["metrics"]["first_side"] == -1 and out["first_side"] == "port"
    assert out["metrics"]["overshoot_1_pct"] == pytest.approx(100 * out["metrics"]["overshoot_1_deg"] / 20)
    assert out["metrics"]["overshoot_1_deg"] > 0 and out["metrics"]["overshoot_2_deg"] > 0
    data = Dataset.from_csv(csv)
    assert {"u", "v", "r", "x", "y", "psi", "delta", "n"} <= set(data.names)
    assert png.stat().st_size > 1000


def test_params_and_replay_of_a_csv_record(capsys, tmp_path):
    # a record simulated with R_0_dash = 0.03 and replayed with that value is reproduced exactly
    from casship.maneuvers import run_maneuver
    from casship.models import kvlcc2

    ship = kvlcc2()
    p = ship.params(R_0_dash=0.03)
    res = run_maneuver(ship, "zigzag", rudder_deg=10, p=p, duration=400, dt=0.5)
    path = tmp_path / "rec.csv"
    res.trajectory.to_csv(path)
    (tmp_path / "fit.json").write_text(json.dumps({"params": {"R_0_dash": 0.03}}))
    out = _json(capsys, ["simulate", "--model", "kvlcc2", "--params", str(tmp_path / "fit.json"), "--inputs", str(path), "--json"])
    assert out["replay"]["psi_rmse_deg"] < 1e-8
    assert out["replay"]["position_rmse_m"] < 1e-6
    assert out["replay"]["u_rmse_mps"] < 1e-9
    assert out["metrics"]["overshoot_1_deg"] == pytest.approx(res.metrics["overshoot_1_deg"], abs=1e-6)
    # with the nominal parameters the replay differs
    out = _json(capsys, ["simulate", "--model", "kvlcc2", "--inputs", str(path), "--json"])
    assert out["replay"]["u_rmse_mps"] > 1e-3


def test_bad_params_file_names_the_problem(tmp_path, capsys):
    (tmp_path / "bad.json").write_text(json.dumps({"params": {"no_such": 1.0}}))
    assert main(["simulate", "--model", "kvlcc2", "--params", str(tmp_path / "bad.json")]) == 2
    assert "no_such" in capsys.readouterr().err


def test_list_models(capsys):
    assert main(["simulate", "--list"]) == 0
    text = capsys.readouterr().out
    assert "kvlcc2" in text and "kvlcc2-l7" in text


def test_replay_marin(capsys, data_dir):
    f = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_10_m.dat"
    if not f.is_file():
        pytest.skip(f"{f} is absent")
    out = _json(capsys, ["simulate", "--model", "kvlcc2", "--inputs", str(f), "--json"])
    assert set(out["replay"]) == {"psi_rmse_deg", "position_rmse_m", "u_rmse_mps"}
    assert out["measured_metrics"]["overshoot_1_deg"] == pytest.approx(9.33, abs=0.05)
    assert 0 < out["replay"]["psi_rmse_deg"] < 30


def test_zigzag_side_is_never_guessed(capsys):
    """Before: the side was sign(rudder) x sign(heading), so -20/-20 ran starboard first, and no output
    said which side went first."""
    base = ["simulate", "--model", "kvlcc2-l7", "--maneuver", "zigzag", "--duration", "60"]
    out = _json(capsys, base + ["--rudder-deg", "-20", "--heading-deg", "-20", "--json"])
    assert out["first_side"] == "port" and out["metrics"]["first_side"] == -1
    assert main(base + ["--rudder-deg", "20"]) == 0
    assert "first rudder to starboard" in capsys.readouterr().out
    assert _json(capsys, base + ["--rudder-deg", "20", "--heading-deg", "-20", "--json"])["first_side"] == "port"
    assert main(base + ["--rudder-deg", "-20", "--first", "starboard"]) == 2
    assert "rudder_deg is negative (port first)" in capsys.readouterr().err
    assert main(["simulate", "--model", "kvlcc2", "--first", "port"]) == 2
    assert "--first would have no effect: not used by a turning manoeuvre" in capsys.readouterr().err
