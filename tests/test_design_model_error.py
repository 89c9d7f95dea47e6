"""Trial design with model error: the compiled information fold against the identification's own
information and a dense whitening, the model-error floor against a Monte Carlo, the closed check's rule,
and the command line's floor, per-hour ranking and size caps."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy.stats import chi2

from casship.design import Approach, ParameterBelief, design_trials, get_target, standard_trials, trial_information
from casship.design.infofold import InformationFold, discrepancy_gains
from casship.design.targets import _to_heading
from casship.errors import InputError
from casship.models import kvlcc2

NAMES = ["N_r_dash", "N_v_dash", "Y_v_dash", "N_vvr_dash"]
NOISE = {"psi": np.radians(0.2), "r": np.radians(0.02), "u": 0.02}


@pytest.fixture(scope="module")
def ship():
    m = kvlcc2()
    return m, Approach(m, m.params(), dt=4.0)


def test_information_fold_equals_the_output_error_problems_information(ship):
    from casship.identify import OutputErrorProblem

    m, ap = ship
    trial = standard_trials(ap, zigzag=(20.0,), turning=(), pullout=(), spiral=False, sides=(1,))[0]
    info = trial_information(ap, trial, NAMES, NOISE, jit=False)
    prob = OutputErrorProblem(m, [trial.record(ap)], free=NAMES, measured=list(NOISE), sigma=NOISE, params=ap.p,
                              x0=[ap.x0], jit=False)
    ref = prob.information()
    assert np.max(np.abs(info - ref)) <= 1e-10 * np.max(np.abs(ref))


def test_heading_discrepancy_information_equals_a_dense_whitening(ship):
    """With a heading random walk the fold's information is J' (s^2 I + q min(t_i, t_j))^-1 J on the heading
    channel (plus the white channels), computed here with dense matrices from the exact sensitivities."""
    m, ap = ship
    trial = standard_trials(ap, zigzag=(10.0,), turning=(), pullout=(), spiral=False, sides=(-1,))[0]
    q = np.radians(np.radians(0.05))
    info = trial_information(ap, trial, NAMES, NOISE, discrepancy=q, jit=False)
    n = trial.rudder.size
    U = ap.inputs(trial.rudder)
    import casadi as ca

    _, dX = ap.fold(NAMES, n).sensitivities(lambda tau: ca.MX(ca.DM(U)))
    ref = np.zeros((len(NAMES), len(NAMES)))
    for c in ("r", "u"):
        J = dX[1:, m.index(c), :] / NOISE[c]
        ref += J.T @ J
    J = dX[1:, m.index("psi"), :]
    t = np.arange(1, n + 1) * ap.dt
    S = NOISE["psi"] ** 2 * np.eye(n) + q * np.minimum.outer(t, t)
    ref += J.T @ np.linalg.solve(S, J)
    assert np.max(np.abs(info - ref)) <= 1e-8 * np.max(np.abs(ref))
    white = trial_information(ap, trial, NAMES, NOISE, jit=False)
    assert np.trace(info) < np.trace(white)        # the random walk takes information away, never adds


def test_discrepancy_gains_without_a_walk_are_the_white_weights():
    gain, inv_sd = discrepancy_gains(5, 1.0, 0.1, 0.0)
    assert np.all(gain == 0) and np.allclose(inv_sd, 10.0)
    gain, inv_sd = discrepancy_gains(3, 2.0, 1.0, 0.5)
    # by hand: P = 1, s = 2, K = 1/2, P = 1/2; P = 3/2, s = 5/2, K = 3/5, P = 3/5; P = 8/5, s = 13/5, K = 8/13
    assert np.allclose(gain, [0.5, 0.6, 8 / 13]) and np.allclose(inv_sd, 1 / np.sqrt([2, 2.5, 2.6]))


def test_model_error_floor_matches_a_monte_carlo_of_heading_random_walks():
    """The floor of the tactical diameter (first order in the heading error) against 3000 random walks
    carried through the same kinematics and the same crossing rule."""
    m = kvlcc2()
    ap = Approach(m, m.params(), dt=2.0)
    q = np.radians(0.3) ** 2 / 100
    target = get_target("tactical_diameter")
    floor = target.evaluate(ap, ["N_r_dash"]).floor(q)
    level = np.radians(180.0)
    X, _, *_ = _to_heading(ap, ["N_r_dash"], target.rudder(ap), level, 1, "td", extra=40)
    ix, iy, ip = m.index("x"), m.index("y"), m.index("psi")
    dx, dy = np.diff(X[:, ix]), np.diff(X[:, iy])
    rng = np.random.default_rng(3)
    values = []
    for _ in range(3000):
        e = np.concatenate([[0.0], np.cumsum(rng.standard_normal(len(dx)) * np.sqrt(q * ap.dt))])
        c, s = np.cos(e[:-1]), np.sin(e[:-1])
        y = np.concatenate([[0.0], np.cumsum(dy * c + dx * s)])
        h = X[:, ip] + e
        k = np.flatnonzero(h >= level)[0]
        values.append(y[k - 1] + (level - h[k - 1]) / (h[k] - h[k - 1]) * (y[k] - y[k - 1]))
    sd = np.std(values)
    assert floor == pytest.approx(sd, rel=0.06)        # 3000 draws: sampling error of an SD about 1.3 %
    assert target.evaluate(ap, ["N_r_dash"]).floor(0.0) == 0.0
    with pytest.raises(InputError, match="discrepancy"):
        target.evaluate(ap, ["N_r_dash"]).floor(-1.0)


def test_no_trial_is_predicted_below_the_model_error_floor(ship):
    m, ap = ship
    belief = ParameterBelief.from_std({"N_r_dash": 0.01, "N_v_dash": 0.03}, m.param_dict())
    q = np.radians(np.radians(0.1))
    res = design_trials(m, belief, NOISE, "tactical_diameter", dt=4.0, discrepancy=q,
                        candidates=standard_trials(ap, spiral=False))
    assert res.model_floor > 0
    assert all(r["sd_after"] >= res.model_floor for r in res.rows)
    assert all(r["sd_after"] == pytest.approx(np.hypot(r["sd_after_parameters"], res.model_floor)) for r in res.rows)
    hourly = res.per_hour
    assert [r["trial"] for r in hourly] == [r["trial"] for r in sorted(
        hourly, key=lambda r: -(res.row(r["trial"])["sd_before"] ** 2 - r["sd_after"] ** 2) / r["hours"])]
    d = res.to_dict()
    assert d["model_floor"] == res.model_floor and d["per_hour"] == hourly


def test_closed_check_rule_by_hand():
    from problems.trial_design import closed_check_verdict

    v = closed_check_verdict(1.15, 1.0, 5.0, 60)     # bound sqrt(83.30 / 60) = 1.178
    assert v["upper_bound"] == pytest.approx(np.sqrt(chi2.ppf(0.975, 60) / 60))
    assert v["passed"] and v["not_over_confident"] and v["trial_helps"]
    assert not closed_check_verdict(1.2, 1.0, 5.0, 60)["passed"]        # 1.2 > 1.178: over-confident
    assert not closed_check_verdict(1.0, 1.0, 0.9, 60)["passed"]        # worse than the prior alone


def test_coloured_noise_has_its_variance_and_correlation_time():
    from problems.trial_design import coloured_noise

    e = coloured_noise(200_000, 1.0, 2.0, 10.0, np.random.default_rng(0))
    assert np.std(e) == pytest.approx(2.0, rel=0.03)
    assert np.corrcoef(e[:-10], e[10:])[0, 1] == pytest.approx(np.exp(-1.0), abs=0.02)


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "casship", *args], capture_output=True, text=True, cwd=cwd, timeout=600)


def test_design_trial_reports_the_floor_and_the_per_hour_ranking(tmp_path):
    res = _cli("design-trial", "--model", "kvlcc2", "--prior-std", "N_r_dash=0.01,N_v_dash=0.03",
               "--sigma", "psi=0.0035,r=0.0002,u=0.02", "--no-free", "--no-spiral", "--dt", "4",
               "--discrepancy-deg2-s", "0.1", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["model_floor"] > 0 and out["discrepancy_deg2_per_s"] == pytest.approx(0.1)
    assert all(r["sd_after"] >= out["model_floor"] for r in out["ranking"])
    assert {r["trial"] for r in out["per_hour"]} <= {r["trial"] for r in out["ranking"]} and out["per_hour"]


def test_design_trial_refuses_a_free_trial_beyond_its_size(tmp_path):
    res = _cli("design-trial", "--model", "kvlcc2", "--prior-std", "N_r_dash=0.01", "--sigma", "psi=0.0035",
               "--duration", "1e9", cwd=tmp_path)
    assert res.returncode == 2 and "design steps" in res.stderr and "Traceback" not in res.stderr
