"""Trial design on KVLCC2: exact target gradients, the free sequence within every limit, asymmetry wants
both directions, the optimiser's information equals the fit's, the command line."""
import copy
import csv
import json

import numpy as np
import pytest

from casship.cli import main
from casship.design import (Approach, FirstOvershoot, ParameterBelief, TrialLimits, Turning, design_trials,
                            optimise_free_trial, standard_trials)
from casship.maneuvers import run_maneuver
from casship.models import kvlcc2
from casship.simulation import simulate

NAMES = ("N_r_dash", "Y_v_dash", "N_v_dash", "delta_0", "N_0_dash")
NOISE = {"psi": np.radians(0.2), "r": np.radians(0.01), "u": 0.02}


@pytest.fixture(scope="module")
def ship():
    m = kvlcc2(asymmetry=True, smooth=True)
    pd = m.param_dict()
    std = {n: 0.2 * abs(pd[n]) for n in NAMES[:3]}
    std.update(delta_0=np.radians(1.0), N_0_dash=0.01)
    return m, Approach(m, m.params(), dt=2.0), ParameterBelief.from_std(std, pd)


def _at(ap, names, theta):
    """The approach with other parameter values and the same propeller rate (as the gradient holds it)."""
    other = copy.copy(ap)
    other.p = ap.p.copy()
    other.p[ap.model.indices(names, "param")] = theta
    return other


@pytest.mark.parametrize("target", [Turning("tactical_diameter", 1), Turning("advance", -1),
                                    FirstOvershoot(20.0, 20.0, 1)], ids=lambda t: t.name)
def test_target_gradient_equals_central_differences(ship, target):
    m, ap, _ = ship
    tv = target.evaluate(ap, NAMES)
    theta = ap.p[m.indices(NAMES, "param")]
    for j in range(len(NAMES)):
        h = 1e-4 * max(abs(theta[j]), 1e-2)
        e = np.zeros(len(NAMES))
        e[j] = h
        up = target.evaluate(_at(ap, NAMES, theta + e), NAMES).value
        down = target.evaluate(_at(ap, NAMES, theta - e), NAMES).value
        fd = (up - down) / (2 * h)
        assert tv.gradient[j] == pytest.approx(fd, rel=2e-4, abs=1e-6 * np.abs(tv.gradient).max()), NAMES[j]


def test_target_values_agree_with_the_manoeuvre_metrics(ship):
    m, _, _ = ship
    ap = Approach(m, m.params(), dt=1.0)
    turn = run_maneuver(m, "turning", rudder_deg=35.0, t_exec=0.0).metrics
    assert Turning("tactical_diameter", 1).evaluate(ap, NAMES).value == pytest.approx(turn["tactical_diameter_m"],
                                                                                       rel=2e-3)
    assert Turning("advance", 1).evaluate(ap, NAMES).value == pytest.approx(turn["advance_m"], rel=2e-3)
    zz = run_maneuver(m, "zigzag", rudder_deg=20.0, t_exec=0.0).metrics
    first = FirstOvershoot(20.0, 20.0, 1).evaluate(ap, NAMES).value
    assert np.degrees(first) == pytest.approx(zz["overshoot_1_deg"], rel=0.02)


def test_free_sequence_respects_every_limit(ship):
    m, ap, belief = ship
    lim = TrialLimits(duration=300.0, rudder_max=np.radians(25.0), rudder_rate=np.radians(1.5), corridor=60.0,
                      speed_min=7.6, knot=10.0)
    trial, rep = optimise_free_trial(ap, belief, NOISE, lim, criterion="D", max_iter=40)
    assert trial.duration == pytest.approx(300.0)
    assert np.abs(trial.rudder).max() <= np.radians(25.0) * (1 + 1e-6)
    rate = np.abs(np.diff(np.concatenate([[0.0], trial.rudder]))) / trial.dt
    assert rate.max() <= np.radians(1.5) * (1 + 1e-6)
    # an independent simulation of the sequence as a tank would run it
    U = ap.inputs(np.append(trial.rudder, trial.rudder[-1]))
    tr = simulate(m, ap.x0, trial.t, U.T, ap.p, method="rk4")
    assert np.abs(tr["y"]).max() <= 60.0 * (1 + 1e-4)
    assert np.hypot(tr["u"], tr["v"]).min() >= 7.6 * (1 - 1e-4)
    # the limits bind: without them the optimiser goes further
    assert np.abs(tr["y"]).max() > 0.9 * 60.0 or np.hypot(tr["u"], tr["v"]).min() < 7.6 * 1.01
    assert rep["objective"] < rep["objective_start"]


def test_impossible_limits_are_refused_naming_the_limit(ship):
    m, ap, belief = ship
    cases = [(TrialLimits(300.0, speed_min=9.0), "speed_min"), (TrialLimits(300.0, rudder_max=np.radians(40)), "stop"),
             (TrialLimits(15.0), "two rudder knots"), (TrialLimits(300.0, knot=3.0), "whole number"),
             (TrialLimits(300.0, corridor=-5.0), "corridor"), (TrialLimits(np.inf), "duration")]
    for lim, match in cases:
        with pytest.raises(ValueError, match=match):
            optimise_free_trial(ap, belief, NOISE, lim, criterion="A")


def test_asymmetry_target_prefers_trials_in_both_directions(ship):
    m, _, belief = ship
    ap = Approach(m, m.params(), dt=4.0)
    turns = standard_trials(ap, turning=(35.0,), zigzag=(), pullout=(), spiral=False, durations={"turning": 15.0})
    duration = turns[0].duration
    res = design_trials(m, belief, NOISE, "port_starboard_difference", dt=4.0, candidates=turns,
                        limits=TrialLimits(duration), max_iter=40)
    free = res.row("free")
    assert res.trials["free"].sides() == {1, -1}
    assert free["sd_after"] < min(res.row(t.name)["sd_after"] for t in turns)
    assert res.best.name == "free"
    # the optimiser's information (symbolic sensitivities) is the fit likelihood's
    assert np.exp(res.free["objective"]) == pytest.approx(free["sd_after"] ** 2, rel=1e-6)
    # a one-sided target wants the trial on its side
    one = design_trials(m, belief, NOISE, "tactical_diameter", dt=4.0, candidates=turns)
    assert one.rows[0]["trial"] == "turning 35 starboard"


def test_cli_ranks_trials_and_writes_a_runnable_csv(tmp_path, capsys):
    common = ["design-trial", "--model", "kvlcc2", "--prior-std", "N_r_dash=0.01,N_v_dash=0.03",
              "--sigma", "psi=0.0035,r=0.0002", "--dt", "4", "--zigzag", "20", "--pullout", "", "--no-spiral"]
    assert main(common + ["--no-free", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["ranking"]) == 4 and out["target"]["name"] == "tactical_diameter_starboard_35"
    sd = [r["sd_after"] for r in out["ranking"]]
    assert sd == sorted(sd) and all(s < r["sd_before"] for s, r in zip(sd, out["ranking"]))
    path = tmp_path / "next.csv"
    assert main(common + ["--duration", "200", "--max-iter", "5", "--csv", str(path)]) == 0
    text = capsys.readouterr().out
    assert "free" in text and str(path) in text
    rows = list(csv.reader(path.open()))
    assert rows[0] == ["t_s", "rudder_deg", "n"] and len(rows) == 1 + 50
    assert all(abs(float(r[1])) <= 35.0 for r in rows[1:])
    assert main(common + ["--duration", "200", "--csv", str(path)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(common + ["--speed-min", "9", "--csv", str(tmp_path / "x.csv")]) == 2
    assert "speed_min" in capsys.readouterr().err
    assert main(["design-trial", "--model", "kvlcc2", "--prior-std", "N_r_dash=0.01", "--no-free"]) == 2
    assert "--sigma" in capsys.readouterr().err


def test_cli_target_names_are_the_library_targets():
    from casship.cli.cmd_design_trial import TARGET_NAMES
    from casship.design import TARGETS

    assert set(TARGET_NAMES) == set(TARGETS)
