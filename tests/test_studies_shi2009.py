"""Study shi2009 (quick): raw positions/heading -> smoothing -> augmented-EKF and ML identification ->
manoeuvres of the identified models against the truth, for the Taylor truth and the KVLCC2 MMG truth;
the paper's convergence claim checked by a stated criterion."""
import json

import numpy as np
import pytest

from problems import get_study
from problems.shi2009.figures import panel_limits
from problems.shi2009.pipeline import Reading, convergence_step, with_inputs


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("shi2009")
    return out, get_study("shi2009").run(out, quick=True)


def test_shi2009_quick_taylor_truth(quick):
    tmp_path, s = quick
    # the smoother recovers body velocities from 1 m position noise at T = 2 s
    for info in s["smoothing"]:
        assert info["rmse"]["u"] < 0.05 and info["rmse"]["v"] < 0.05
        assert np.degrees(info["rmse"]["r"]) < 0.02
        # its own variance (the R used, no truth needed) is of the size of its actual error
        assert 0.3 < info["smoother_var"]["u"] ** 0.5 / info["rmse"]["u"] < 3.0
    # the yaw equation is identified (the paper's model over-parameterises surge)
    truth = s["truth_params"]
    for method in ("aekf_params", "mle_params"):
        for name in ("c1", "c2", "c3"):
            assert abs(s[method][name] - truth[name]) < 0.1 * abs(truth[name]), (method, name)
    # Table 2: advance, transfer and tactical diameter within 10 % of the target ship
    for key, row in s["table2"].items():
        assert abs(row["aekf_error_pct"]) < 10 and abs(row["mle_error_pct"]) < 10, key
    for key in ("overshoot_1_deg", "overshoot_2_deg"):
        assert abs(s["zigzag"][key]["mle"] - s["zigzag"][key]["truth"]) < 2.0
    fit = json.loads((tmp_path / "fit_mle.json").read_text())
    assert fit["model"] == "shi-taylor" and len(fit["params"]) == 16
    for name in ("table2.md", "parameters.md", "fig_turning.png", "fig_zigzag.png", "fig_convergence.png",
                 "fig_rate_of_turn.png", "fig_convergence_mmg.png", "fig_turning_mmg.png", "fit_mle_mmg.json"):
        assert (tmp_path / name).exists(), name


def test_convergence_claim_and_readings_are_reported(quick):
    tmp_path, s = quick
    claim = s["claim"]
    assert claim["steps"] == 500 and 0 <= claim["settled_by_200"] <= 16
    assert set(s["convergence"]) == set(s["truth_params"])
    for row in s["convergence"].values():
        assert row["settled"] is None or 1 <= row["settled"] <= 500
    assert set(s["readings"]) == {"input held over the step", "P(0) of u, v, r = R", "R from the smoothed-vs-true error"}
    report = (tmp_path / "report.md").read_text()
    assert report.splitlines()[0].endswith("(quick run)")
    assert "## Departures from the paper" in report
    rows = [*s["convergence"].values(), *s["mmg"]["convergence"].values()]
    verdict = "holds here" if all(r["settled"] is not None and r["settled"] <= 200 for r in rows) else "does not hold for every parameter here"
    assert f"after 200 recursive steps\" (Figs. 4-6 show a1, b2, c1), {verdict}" in report
    assert "| advance | 790 | 805 | +1.90 |" in report                     # the paper's Table 2 beside ours
    assert "docs/identification.md" in report
    topics = {d["topic"] for d in s["departures"]}
    assert {"input over a step", "initial covariance P(0)", "target ship"} <= topics


def test_mmg_truth_is_reported(quick):
    _, s = quick
    mmg = s["mmg"]
    assert mmg["u0"] == pytest.approx(7.974, abs=0.01)
    for key, row in mmg["table2"].items():
        assert np.isfinite(row["truth"]) and row["truth"] > 0, key
    assert set(mmg["claim"]) == {"steps", "settled_by_200", "settled_in_last_tenth"}
    # the best Taylor model (least squares on six MMG manoeuvres) against the MMG truth: reported
    assert set(mmg["least_squares_taylor_error_pct"]) == {"advance_m", "transfer_m", "tactical_diameter_m"}
    assert all(np.isfinite(v) for v in mmg["least_squares_taylor_error_pct"].values())


def test_convergence_step_criterion():
    traj = [0.0, 5.0, 9.5, 10.2, 12.0, 9.8, 10.0]
    assert convergence_step(traj, 10.0) == 6          # within 10 % from the 6th update on
    assert convergence_step(traj, 10.0, within=0.25) == 3
    assert convergence_step([1.0, 2.0, 3.0], 1.0) is None
    assert convergence_step([1.0, 1.0], 1.0) == 1


def test_panel_limits_show_the_end_value_and_the_reference():
    traj = np.concatenate([np.linspace(-50.0, 50.0, 100), np.full(100, 0.002)])
    lo, hi = panel_limits(traj, -1e-4)
    assert lo < -1e-4 < 0.002 < hi and hi - lo < 1.0


def test_input_averaging_reading():
    import casship as cs

    rec = cs.Dataset(np.arange(3.0), {"delta": np.array([0.0, 1.0, 3.0]), "n": np.ones(3)})
    assert np.allclose(with_inputs(rec, "average")["delta"], [0.5, 2.0, 3.0])
    assert with_inputs(rec, "hold") is rec
    with pytest.raises(ValueError, match="inputs"):
        Reading(inputs="linear")
