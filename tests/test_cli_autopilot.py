"""``casship autopilot`` on the command line: the same design as the Python API, defaults in --help."""
import json
from pathlib import Path

import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap
from casship.cli import main


def test_autopilot_json_reports_margins_metrics_and_performance(capsys, tmp_path):
    code = main(["autopilot", "--model", "shi-taylor", "--scenario", "course-20", "--t-end", "600", "--json", "--plot",
                 str(tmp_path), "--current", "0.5", "90"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["model"] == "shi-taylor"
    assert set(out["margins"]) >= {"gain_margin_db", "upper_gain_margin_db", "lower_gain_margin_db",
                                   "phase_margin_deg", "closed_loop_stable"}
    assert out["margins"]["closed_loop_stable"]
    assert len(out["metrics"]) == 2
    first = out["metrics"][0]
    assert first["target_deg"] == pytest.approx(20.0)
    assert abs(first["steady_state_error_deg"]) < 1.0
    assert out["inputs"]["n"] > 0
    assert 0.0 <= out["performance"]["rate_limited_fraction"] < 1.0
    assert (tmp_path / "shi-taylor_course-20.png").exists() and (tmp_path / "shi-taylor_loop.png").exists()


def test_autopilot_json_course_changes_schedule_and_mpc(capsys):
    """The JSON carries per change the overshoot in % with degrees beside it, the settling time,
    the rate-limited fraction and the steering travel; --schedule designs over speeds; --controller
    mpc runs the MPC in the compiled loop."""
    code = main(["autopilot", "--model", "otter", "--speed", "1.0", "--schedule", "--scenario", "course-90", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["schedule_speeds_m_s"] == pytest.approx([0.8, 1.1, 1.4, 1.7, 2.0])
    assert out["settings"]["speed"] == pytest.approx(1.0)
    for c in out["course_changes"]:
        assert set(c) >= {"change_deg", "overshoot_pct", "overshoot_deg", "settling_time_s", "rate_limited_fraction",
                          "steer_travel_N_m"}
        assert c["overshoot_deg"] == pytest.approx(c["overshoot_pct"] / 100 * abs(c["change_deg"]))
        assert c["overshoot_pct"] <= 10.0 and c["settling_time_s"] is not None
    assert out["steer_travel_N_m_per_hour"] > 0
    code = main(["autopilot", "--model", "otter", "--controller", "mpc", "--scenario", "course-20", "--duration", "60",
                 "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["controller"] == "mpc" and out["mpc"]["solver"] == "hpipm" and out["mpc"]["horizon"] == 60
    assert out["mpc"]["tuning"] == "limits"
    assert all(c["overshoot_pct"] <= 10.0 for c in out["course_changes"])
    # the bandwidth weights and the integral offset are the API's (same runs as mpc_for_design(d, tuning=...,
    # offset=...)); without --controller mpc they are refused
    for option, value, key in (("--mpc-tuning", "bandwidth", "tuning"), ("--mpc-offset", "integral", "offset")):
        code = main(["autopilot", "--model", "otter", "--controller", "mpc", option, value, "--scenario", "course-20",
                     "--duration", "60", "--json"])
        assert code == 0
        other = json.loads(capsys.readouterr().out)
        assert other["mpc"][key] == value and other["course_changes"] != out["course_changes"]
        assert main(["autopilot", "--model", "otter", option, value]) == 2
        assert f"{option} would have no effect" in capsys.readouterr().err


@pytest.mark.parametrize("name, args, api", [
    ("kvlcc2", [], {}),
    ("otter", ["--mode", "course", "--gnss-std", "0.1", "--compass-std-deg", "1.0"],
     {"mode": "course", "gnss_std": 0.1, "compass_std": np.radians(1.0)}),
])
def test_cli_and_api_give_the_same_design(capsys, name, args, api):
    assert main(["autopilot", "--model", name, "--show-defaults", "--json", *args]) == 0
    cli = json.loads(capsys.readouterr().out)["settings"]
    d = ap.design_autopilot(cs.models.get_model(name), **api)
    for key, value in d.settings.as_dict().items():
        got = cli[key]["value"]
        if isinstance(value, (float, int)) and not isinstance(value, bool):
            assert got == pytest.approx(value, rel=1e-12), key
        elif isinstance(value, list):
            assert got == pytest.approx(value, rel=1e-12), key
        else:
            assert got == value, key
        assert cli[key]["source"] == d.settings.sources[key], key


def test_help_shows_the_rules(capsys):
    with pytest.raises(SystemExit):
        main(["autopilot", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for rule in ("vessel.U0", "vessel.rudder_max", "U/L", "control.dlqe", "--r-max-deg-s"):
        assert rule in text


def test_autopilot_text_output_and_errors(capsys):
    assert main(["autopilot", "--model", "shi-taylor", "--t-end", "200", "--wn", "0.05", "--allow-unmet"]) == 0
    text = capsys.readouterr().out
    assert "margins (python-control)" in text and "Nomoto" in text and "rate limit active" in text
    assert main(["autopilot", "--model", "no-such-ship"]) == 2
    assert "no-such-ship" in capsys.readouterr().err
    assert main(["autopilot", "--model", "shi-taylor", "--scenario", "zigzag"]) == 2
    assert "zigzag" in capsys.readouterr().err


def test_autopilot_refuses_settings_that_mean_nothing(capsys):
    """Before: course-720 wrapped to no turn and passed its checks; a negative delay and a current of
    1e6 m/s were accepted."""
    for argv, text in ((["--scenario", "course-720"], "must be non-zero and within +-180 deg"),
                       (["--delay", "-1"], "autopilot setting delay = -1.0 [s] must be finite and >= 0"),
                       (["--current", "1e6", "0"], "--current: speed 1e+06 m/s towards 0 deg must be finite, >= 0")):
        assert main(["autopilot", "--model", "kvlcc2"] + argv) == 2
        err = capsys.readouterr().err
        assert text in err and "Traceback" not in err, err


def test_autopilot_plot_folder_follows_the_overwrite_rule(tmp_path, capsys):
    """Before: --plot DIR overwrote the user's files and had no --overwrite."""
    folder = tmp_path / "plots"
    folder.mkdir()
    (folder / "mine.txt").write_text("the user's file")
    assert main(["autopilot", "--model", "shi-taylor", "--t-end", "300", "--plot", str(folder)]) == 2
    assert "pass --overwrite" in capsys.readouterr().err and (folder / "mine.txt").exists()
    fresh = tmp_path / "fresh"
    assert main(["autopilot", "--model", "shi-taylor", "--t-end", "300", "--plot", str(fresh), "--json",
                 "--allow-unmet"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert all(Path(p).is_file() for p in out["plots"])
    for m in out["metrics"]:       # overshoot in % with its degrees beside it
        assert "overshoot_pct" in m and "overshoot_deg" in m


def test_unmet_checks_are_said_and_exit_3(capsys):
    """Before: a run whose checks failed exited 0 with nothing on standard error."""
    from casship.cli.cmd_autopilot import EXIT_UNMET

    assert EXIT_UNMET == 3
    assert main(["autopilot", "--model", "shi-taylor", "--duration", "30", "--json"]) == 3
    cap = capsys.readouterr()
    out = json.loads(cap.out)                                  # the results are still written
    assert not out["performance"]["all_ok"]
    assert "performance check(s) not met: settled, change 1" in cap.err and "exit code 3" in cap.err
    assert main(["autopilot", "--model", "shi-taylor", "--duration", "30", "--allow-unmet"]) == 0
    cap = capsys.readouterr()
    assert "NOT MET" in cap.out and "accepted (--allow-unmet)" in cap.err


def test_autopilot_refuses_a_steering_gear_that_cannot_turn_the_ship_and_mpc_in_course_mode(capsys):
    """Before: --steer-rate-max 1e-9 ran 61 000 s of simulated time without turning; the MPC in
    course mode overshot 67-90 % and exited 0."""
    assert main(["autopilot", "--model", "kvlcc2", "--controller", "mpc", "--steer-rate-max-deg-s", "1e-9"]) == 2
    err = capsys.readouterr().err
    assert "steer_rate_max = 1.74533e-11 rad/s" in err and "more than 10 L/U" in err
    assert main(["autopilot", "--model", "otter", "--controller", "mpc", "--mode", "course"]) == 2
    assert "the MPC is for heading control" in capsys.readouterr().err


def test_schedule_is_shown_in_the_text_output(capsys):
    """Above the approach speed the default schedule reaches the design speed (the Otter at 2.5 m/s)."""
    assert main(["autopilot", "--model", "otter", "--speed", "2.5", "--schedule", "--duration", "40", "--allow-unmet"]) == 0
    text = capsys.readouterr().out
    assert "gain schedule: 7 point designs" in text
    for speed in ("0.8", "2.3", "2.5"):
        assert f"\n{speed:>10} " in text
