"""The kvlcc2-marin study's asymmetry rule on a simulated ship (no measured data needed).

A KVLCC2 with a known propeller-induced yaw moment ``N_P = N'_0 L T`` (it scales with the thrust):
with zig-zags that turn first to both sides the prior-ratio selection rule
(:meth:`casship.identify.Identifiability.propose` with ``max_ratio``, the rig's neutral angle waiting
for the ship's thrust terms) chooses the thrust term over a rudder
neutral angle of the facility, which explains nearly the same port/starboard difference, and the
refinement recovers its value; trained on one direction only, both are flagged confounded with
the turning dynamics and neither is chosen.
"""
import numpy as np
import pytest

import casship as cs
from casship.identify import Prior

from asymmetry_records import SIGMA, both_directions

TRUTH = {"N_0_dash": 0.02}
PRIOR = {"N_0_dash": 0.025, "delta_0": np.radians(1.0), "N_r_dash": 0.01}


@pytest.fixture(scope="module")
def runs():
    return both_directions(TRUTH)


def _problem(ship, records, free=("N_0_dash", "delta_0", "N_r_dash")):
    return cs.OutputErrorProblem(ship, records, list(free), measured=["psi", "r"], sigma=SIGMA,
                                 share={"delta_0": "facility"} if "delta_0" in free else None,
                                 scale={k: v for k, v in (("N_0_dash", 0.025), ("delta_0", np.radians(1.0)))
                                        if k in free},
                                 prior=Prior({k: v for k, v in PRIOR.items() if k in free}))


def _choose(ship, records):
    prob = _problem(ship, records)
    idf = prob.identifiability(at={"N_0_dash": 0.0, "delta_0@A": 0.0, "N_r_dash": ship.param_dict()["N_r_dash"]})
    return idf, *select_free(idf, after={"delta_0@A": ["N_0_dash"]})


def select_free(idf, after):
    return idf.propose(max_ratio=0.5, max_count=15, after=after, candidates=idf.names, keep=[], explain=True)


def test_both_directions_choose_and_recover_the_thrust_dependent_term(runs):
    ship, starboard, port = runs
    idf, chosen, rows = _choose(ship, starboard + port)
    assert idf.confounded == {}
    assert "N_0_dash" in chosen and "delta_0@A" not in chosen
    fit = _problem(ship, starboard + port, free=chosen).solve(show=False)
    est, se = fit.estimates["N_0_dash"], fit.std_errors["N_0_dash"]
    assert abs(est - TRUTH["N_0_dash"]) < max(4 * se, 1e-3)
    assert abs(est / TRUTH["N_0_dash"] - 1) < 0.1


def test_without_the_waiting_rule_the_neutral_angle_could_take_its_place(runs):
    """The two terms explain nearly the same difference: the rule decides which one goes in."""
    ship, starboard, port = runs
    idf, *_ = _choose(ship, starboard + port)
    i, j = idf.names.index("N_0_dash"), idf.names.index("delta_0@A")
    F = np.asarray(idf.information)
    assert abs(F[i, j]) / np.sqrt(F[i, i] * F[j, j]) > 0.95
    chosen, _ = select_free(idf, after={"N_0_dash": ["delta_0@A"]})
    assert "delta_0@A" in chosen and "N_0_dash" not in chosen


def test_one_direction_only_is_flagged_confounded_and_not_chosen(runs):
    ship, starboard, _ = runs
    idf, chosen, rows = _choose(ship, starboard)
    assert set(idf.confounded) == {"N_0_dash", "delta_0@A"}
    assert chosen == ["N_r_dash"]
    assert {r["quantity"] for r in rows if r.get("confounded")} == {"N_0_dash", "delta_0@A"}


def test_after_names_must_be_candidates(runs):
    ship, starboard, port = runs
    idf, *_ = _choose(ship, starboard + port)
    with pytest.raises(ValueError, match="bias"):
        select_free(idf, after={"bias[delta]": ["N_0_dash"]})


def test_band_check_discrepancy_from_the_other_folds_reaches_the_nominal_coverage():
    """Held-out heading errors that grow like a random walk (variance ``q t``) with a parameter band
    far too narrow: the parameter-only band covers little, the band with the discrepancy term
    estimated from the other runs only covers about 95 %."""
    from problems.kvlcc2_marin.calibration import band_check
    from problems.kvlcc2_marin.data import Run

    rng = np.random.default_rng(4)
    q = np.radians(0.3) ** 2            # rad^2/s
    t = np.arange(0.0, 600.0, 1.0)
    runs, results = [], []
    for i in range(12):
        e = np.cumsum(np.sqrt(q) * rng.standard_normal(t.size))        # variance q t
        psi = np.radians(10.0) * np.sin(t / 50.0)
        data = cs.Dataset(t, {"psi": psi})
        runs.append(Run(f"run {i}", "X", data, "zigzag"))
        row = {"run": f"run {i}", "kind": "zigzag"}
        for k, meas in (("overshoot_1_deg", 10.0), ("overshoot_2_deg", 12.0)):
            err = 2.0 * rng.standard_normal()
            row.update({f"{k}_measured": meas, f"{k}_fit": meas + err, f"{k}_fit_lo": meas + err - 0.1,
                        f"{k}_fit_hi": meas + err + 0.1})
        if i == 0:                        # a replay that never reaches its second overshoot
            row.update({f"overshoot_2_deg_{k}": np.nan for k in ("fit", "fit_lo", "fit_hi")})
        ev = {"row": row, "fit": cs.Dataset(t, {"psi": psi + e}), "bands": {"psi_std": np.full(t.size, 1e-4)}}
        results.append({"kind": "run", "evaluations": [ev]})
    circle = {"run": "circle", "kind": "turning", "advance_m_measured": 1000.0, "advance_m_fit": 990.0,
              "advance_m_fit_lo": 980.0, "advance_m_fit_hi": 1000.0}
    runs.append(Run("circle", "X", cs.Dataset(t, {"psi": 0.01 * t}), "turning"))
    results.append({"kind": "run", "evaluations": [{"row": {**circle, **{f"{k}_{s}": np.nan for k in
                    ("transfer_m", "tactical_diameter_m") for s in ("measured", "fit", "fit_lo", "fit_hi")}},
                    "fit": cs.Dataset(t, {"psi": 0.01 * t + np.cumsum(np.sqrt(q) * rng.standard_normal(t.size))}),
                    "bands": {"psi_std": np.full(t.size, 1e-4)}}]})
    out = band_check(runs, results)
    assert out["runs"]["circle"]["advance_m in interval, parameter"] is True
    assert out["runs"]["run 0"]["overshoot_2_deg in interval, with discrepancy"] is False
    assert out["runs"]["circle"]["advance_m in interval, with discrepancy"] is None     # no other circle
    sm = out["summary"]
    assert sm["psi coverage, parameter band (mean)"] < 0.2
    assert 0.88 < sm["psi coverage, with discrepancy (mean)"] < 0.99
    assert out["q_all_folds_deg2_per_s"] == pytest.approx(0.09, rel=0.3)
    assert sm["indices in interval, parameter"] < 0.2
    assert 0.8 < sm["indices in interval, with discrepancy"] <= 1.0
