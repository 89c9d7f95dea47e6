"""One vocabulary across the command line: every option of every command is listed here with its one
meaning; angles carry their unit in the name; renamed options still work, with a warning."""
import argparse
import re

import numpy as np
import pytest

from casship.cli import build_parser, main
from casship.cli._vocabulary import RENAMED

ALL = ("autopilot", "bench", "cache", "demo", "design-trial", "filter", "identify", "simulate", "study")

#: option -> (its one meaning, the commands that have it). A new option, or an option added to one
#: more command, is added here deliberately: a name already listed must keep its meaning.
MEANINGS = {
    "--help": ("show the help and exit", ALL),
    "--debug": ("show the Python traceback of an error", ALL),
    "--quiet": ("no progress on standard error", ALL),
    "--overwrite": ("replace existing output files or folders", tuple(c for c in ALL if c != "cache")),
    "--model": ("registered model name", ("autopilot", "design-trial", "filter", "identify", "simulate")),
    "--params": ("JSON file with the ship's parameters (a fit file)", ("autopilot", "design-trial", "filter",
                                                                       "identify", "simulate", "study")),
    "--json": ("print the result as JSON on standard output", ("autopilot", "design-trial", "filter", "identify",
                                                               "simulate")),
    "--json-file": ("write the result as JSON to this file", ("bench",)),
    "--plot": ("save the figure(s) there (autopilot: a new folder for its two)", ("autopilot", "design-trial", "filter",
                                                                                "identify", "simulate")),
    "--csv": ("write the command's series as CSV to this file", ("design-trial", "simulate")),
    "--out": ("where the command's result goes (a file, or a new folder)", ("demo", "filter", "identify", "study")),
    "--list": ("list what the command can use and exit", ("filter", "simulate", "study")),
    "--quick": ("a short, fast variant", ("bench", "demo", "study")),
    "--seed": ("seed of the random numbers", ("autopilot", "filter", "simulate")),
    "--speed": ("approach (design) speed [m/s]", ("autopilot", "design-trial", "simulate")),
    "--dt": ("time step [s]", ("autopilot", "design-trial", "filter", "simulate")),
    "--duration": ("simulated or trial time [s]", ("autopilot", "design-trial", "simulate")),
    "--discrepancy-deg2-s": ("heading model discrepancy q [deg^2/s] of a trial design", ("design-trial",)),
    "--max-iter": ("iteration limit of the optimiser", ("design-trial", "identify")),
    "--measured": ("measured outputs to use", ("filter", "identify")),
    "--sigma": ("noise standard deviation per output name=value", ("design-trial", "identify")),
    "--prior-std": ("prior standard deviations name=std of parameters", ("design-trial", "identify")),
    "--weights": ("channel standard deviations name=value of the ship workflow's cost", ("identify",)),
    "--Q": ("process-noise variances", ("filter", "identify")),
    "--R": ("measurement variances", ("filter", "identify")),
    "--integrator": ("how the model's equations are integrated in time", ("filter", "simulate")),
    "--allow-out-of-range": ("run outside the model's validity ranges", ("filter", "identify", "simulate")),
    # autopilot
    "--scenario": ("closed-loop scenario", ("autopilot",)), "--waypoints": ("track waypoints [m]", ("autopilot",)),
    "--design": ("design method of the law (pid, lqr)", ("autopilot",)),
    "--mode": ("controlled angle (heading, course)", ("autopilot",)),
    "--rate-source": ("rate fed to the law (estimator, gyro)", ("autopilot",)),
    "--wn": ("natural frequency [rad/s]", ("autopilot",)), "--zeta": ("damping ratio", ("autopilot",)),
    "--integral": ("integral action rule", ("autopilot",)),
    "--wn-ref": ("reference model natural frequency [rad/s]", ("autopilot",)),
    "--zeta-ref": ("reference model damping", ("autopilot",)),
    "--r-max-deg-s": ("preset rate of turn [deg/s]", ("autopilot",)),
    "--feedforward": ("feed-forward kind", ("autopilot",)),
    "--steer-max-deg": ("rudder limit [deg]", ("autopilot",)),
    "--steer-max-N-m": ("yaw-moment limit [N m]", ("autopilot",)),
    "--steer-rate-max-deg-s": ("rudder rate limit [deg/s]", ("autopilot",)),
    "--steer-rate-max-N-m-s": ("yaw-moment rate limit [N m/s]", ("autopilot",)),
    "--actuator-T": ("steering servo time constant [s]", ("autopilot",)),
    "--filter-T": ("command low-pass time constant [s]", ("autopilot",)),
    "--delay": ("sensor delay [s]", ("autopilot",)), "--gnss-rate": ("GNSS rate [Hz]", ("autopilot",)),
    "--gnss-std": ("GNSS position noise [m]", ("autopilot",)),
    "--compass-rate": ("compass rate [Hz]", ("autopilot",)),
    "--compass-std-deg": ("compass noise [deg]", ("autopilot",)),
    "--gyro-std-deg-s": ("gyro noise [deg/s]", ("autopilot",)),
    "--ekf-alpha": ("course EKF time constants", ("autopilot",)), "--ekf-q": ("course EKF noise", ("autopilot",)),
    "--observer-q": ("heading observer noise", ("autopilot",)),
    "--segment": ("length of one course change [s]", ("autopilot",)),
    "--controller": ("law or MPC", ("autopilot",)), "--mpc-tuning": ("the MPC's weights", ("autopilot",)),
    "--mpc-offset": ("the MPC's offset-free action", ("autopilot",)), "--schedule": ("gain-schedule speeds [m/s]", ("autopilot",)),
    "--current": ("current speed and direction [m/s, deg]", ("autopilot",)),
    "--wind": ("wind speed and direction [m/s, deg]", ("autopilot",)),
    "--show-defaults": ("print the settings and exit", ("autopilot",)),
    "--allow-unmet": ("exit 0 with performance checks not met", ("autopilot",)),
    "--wave-w0": ("wave encounter frequency of the design's sea [rad/s]", ("autopilot",)),
    "--wave-std-deg": ("wave yaw standard deviation of the design's sea [deg]", ("autopilot",)),
    "--wave-filter": ("wave filter in the heading observer (off, on)", ("autopilot",)),
    # bench, cache, study
    "--only": ("topics to run", ("bench",)), "--markdown": ("results page to update", ("bench",)),
    "--dir": ("the cache folder", ("cache",)), "--data": ("measured-data folder", ("study",)),
    "--workers": ("local worker processes", ("study",)), "--scheduler": ("Dask scheduler address", ("study",)),
    # design-trial
    "--covariance": ("which covariance of the fit file", ("design-trial",)),
    "--target": ("the prediction to resolve", ("design-trial",)),
    "--criterion": ("classical design criterion", ("design-trial",)),
    "--turning": ("turning-circle rudder angles [deg]", ("design-trial",)),
    "--zigzag": ("zig-zag angles [deg]", ("design-trial",)), "--pullout": ("pull-out rudder angles [deg]", ("design-trial",)),
    "--no-spiral": ("leave the spiral out", ("design-trial",)), "--no-free": ("standard trials only", ("design-trial",)),
    "--rudder-max-deg": ("free trial rudder limit [deg]", ("design-trial",)),
    "--rudder-rate-deg-s": ("free trial rudder rate limit [deg/s]", ("design-trial",)),
    "--corridor": ("free trial corridor half width [m]", ("design-trial",)),
    "--speed-min": ("free trial speed floor [m/s]", ("design-trial",)),
    "--knot": ("free trial knot spacing [s]", ("design-trial",)),
    # filter
    "--estimator": ("estimator name", ("filter",)), "--smooth": ("smooth instead of filter", ("filter",)),
    # the record options: one vocabulary for every command that reads records
    "--preset": ("log format preset", ("filter", "identify", "simulate")),
    "--columns": ("CSV columns and units", ("filter", "identify", "simulate")),
    "--time": ("time column and unit", ("filter", "identify", "simulate")),
    "--latlon": ("geodetic columns", ("filter", "identify", "simulate")),
    "--accept-worse": ("exit 0 although the fit's verdict is worse than its start or stalled", ("identify",)),
    "--no-loo": ("judge the fit on its records only (no left-one-out refits)", ("identify",)),
    "--R-std": ("measurement standard deviations", ("filter",)), "--x0": ("initial state", ("filter",)),
    "--P0": ("initial variances", ("filter",)), "--rate": ("filter rate [Hz]", ("filter",)),
    "--options": ("estimator options", ("filter",)),
    # identify
    "--free": ("quantities to estimate", ("identify",)), "--objective": ("what the fit minimises (mle, oe)", ("identify",)),
    "--share": ("shared quantities", ("identify",)), "--group": ("group labels of records", ("identify",)),
    "--prior-weight": ("weight of the prior", ("identify",)), "--bounds": ("parameter bounds", ("identify",)),
    "--captive": ("folder of captive (PMM) tests", ("identify",)),
    "--rig": ("the rig of the captive tests (a known name or a JSON file)", ("identify",)),
    "--estimate-noise": ("noise variances to estimate", ("identify",)), "--guess": ("starting values", ("identify",)),
    "--estimate-x0": ("initial states to estimate", ("identify",)), "--decimate": ("keep every k-th sample", ("identify",)),
    "--shooting": ("output-error shooting", ("identify",)),
    "--identifiability": ("print the identifiability analysis", ("identify",)),
    # simulate
    "--maneuver": ("manoeuvre", ("simulate",)), "--rudder-deg": ("rudder angle [deg]", ("simulate",)),
    "--heading-deg": ("zig-zag switch heading [deg]", ("simulate",)), "--first": ("first rudder side", ("simulate",)),
    "--rps": ("propeller rate [1/s]", ("simulate",)), "--hold": ("hold time [s]", ("simulate",)),
    "--inputs": ("record whose inputs are replayed", ("simulate",)),
    "--samples": ("parameter draws for the intervals", ("simulate",)),
    "--level": ("coverage of bands and intervals", ("simulate",)), "--no-bands": ("ignore the covariance", ("simulate",)),
}

#: angle units a help text may state in brackets, and what the option's name or metavar must then carry
ANGLE_UNITS = {"deg": "deg", "deg/s": "deg-s", "rad": "rad", "rad/s": "rad-s"}
#: natural frequencies are angular frequencies in rad/s (every control text writes wn so); not angles
FREQUENCIES = {"--wn", "--wn-ref", "--wave-w0"}


def _options():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for command, cp in sub.choices.items():
        for action in cp._actions:
            if action.help == argparse.SUPPRESS:       # deprecated aliases
                continue
            for option in action.option_strings:
                if option.startswith("--"):
                    yield command, option, action


def test_every_option_has_one_listed_meaning():
    seen = {}
    for command, option, _ in _options():
        seen.setdefault(option, set()).add(command)
    unlisted = sorted(set(seen) - set(MEANINGS))
    assert not unlisted, f"options without a listed meaning: {unlisted}"
    moved = {o: sorted(c) for o, c in seen.items() if c != set(MEANINGS[o][1])}
    assert not moved, f"options in other commands than listed (same name, same meaning?): {moved}"
    gone = sorted(set(MEANINGS) - set(seen))
    assert not gone, f"listed options no command has: {gone}"


def test_no_renamed_option_is_visible_under_its_old_name():
    """An old name is a hidden alias in the commands that renamed it (it may keep its one meaning elsewhere:
    ``--json`` prints JSON, ``--rate`` is the filter's rate in Hz)."""
    visible = {(command, option) for command, option, _ in _options()}
    left = [(c, old) for old, (_, commands) in RENAMED.items() for c in commands if (c, old) in visible]
    assert not left, left


def test_angles_carry_their_unit_in_the_name():
    bad = []
    for command, option, action in _options():
        units = re.findall(r"\[([^\]]+)\]", action.help or "")
        if not units or option in FREQUENCIES:
            continue
        unit = units[0].split(" or ")[0].strip()
        if unit not in ANGLE_UNITS:
            continue
        metavar = " ".join(np.ravel([action.metavar or ""]).astype(str)).lower().replace("_", "-")
        if ANGLE_UNITS[unit] not in option.lower() and unit.split("/")[0] not in metavar:
            bad.append(f"{command} {option} [{unit}]")
    assert not bad, f"angle options without their unit in the name or metavar: {bad}"


def test_the_naming_rule_catches_a_bare_angle():
    """The check above is not empty: a help in [deg] on a bare name is what it reports."""
    action = argparse.ArgumentParser().add_argument("--steer", help="[deg] limit")
    unit = re.findall(r"\[([^\]]+)\]", action.help)[0]
    assert unit in ANGLE_UNITS and ANGLE_UNITS[unit] not in "--steer"


@pytest.mark.parametrize("command, old, new, value, expected", [
    ("autopilot", ["--method", "lqr"], ["--design", "lqr"], "method", "lqr"),
    ("autopilot", ["--rate", "gyro"], ["--rate-source", "gyro"], "rate", "gyro"),
    ("autopilot", ["--t-end", "60"], ["--duration", "60"], "t_end", 60.0),
    ("simulate", ["--method", "euler"], ["--integrator", "euler"], "method", "euler"),
    ("filter", ["--method", "rk4"], ["--integrator", "rk4"], "method", "rk4"),
    ("identify", ["--method", "oe"], ["--objective", "oe"], "method", "oe"),
    ("identify", ["--prior", "K=0.1"], ["--prior-std", "K=0.1"], "prior", "K=0.1"),
    ("design-trial", ["--rudder-rate-deg", "2.5"], ["--rudder-rate-deg-s", "2.5"], "rudder_rate_deg", 2.5),
    ("bench", ["--json", "b.json"], ["--json-file", "b.json"], "json", "b.json"),
])
def test_an_old_name_warns_and_gives_the_same_value(capsys, command, old, new, value, expected):
    parser = build_parser(command)
    required = {"identify": ["run.csv", "--model", "nomoto1", "--free", "K"], "design-trial": ["--model", "kvlcc2"],
                "filter": ["run.csv"]}.get(command, [])
    args_new = parser.parse_args([command, *required, *new])
    assert capsys.readouterr().err == ""
    args_old = parser.parse_args([command, *required, *old])
    err = capsys.readouterr().err
    assert f"casship {command}: warning: {old[0]} is deprecated" in err and new[0] in err, err
    assert getattr(args_old, value) == getattr(args_new, value) == expected


def test_steering_limits_in_degrees_or_newton_metres(capsys):
    from casship.cli.cmd_autopilot import settings_from_args

    parser = build_parser("autopilot")
    deg = settings_from_args(parser.parse_args(["autopilot", "--steer-max-deg", "20", "--steer-rate-max-deg-s", "3"]))
    assert deg["steer_max"] == pytest.approx(np.radians(20.0)) and deg["steer_rate_max"] == pytest.approx(np.radians(3.0))
    old = settings_from_args(parser.parse_args(["autopilot", "--steer-max", str(np.radians(20.0))]))   # radians
    assert "deprecated" in capsys.readouterr().err
    assert old["steer_max"] == pytest.approx(deg["steer_max"])
    moment = settings_from_args(parser.parse_args(["autopilot", "--steer-max-N-m", "40"]))
    assert moment["steer_max"] == 40.0
    assert main(["autopilot", "--model", "otter", "--steer-max-deg", "20"]) == 2
    assert "'otter' steers by a yaw moment (tau_N), not a rudder; give --steer-max-N-m" in capsys.readouterr().err
    assert main(["autopilot", "--model", "kvlcc2", "--steer-max-N-m", "20"]) == 2
    assert "give --steer-max-deg" in capsys.readouterr().err
    assert main(["autopilot", "--model", "kvlcc2", "--steer-max-deg", "20", "--steer-max", "0.3"]) == 2
    assert "set the same limit" in capsys.readouterr().err
