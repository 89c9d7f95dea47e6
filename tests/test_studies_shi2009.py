"""Study shi2009 (quick): raw positions/heading -> smoothing -> augmented-EKF and ML identification ->
manoeuvres of the identified models close to the target ship's."""
import json

import numpy as np

from problems import get_study


def test_shi2009_quick(tmp_path):
    s = get_study("shi2009").run(tmp_path, quick=True)
    # the smoother recovers body velocities from 1 m position noise at T = 2 s
    for info in s["smoothing"]:
        assert info["rmse"]["u"] < 0.05 and info["rmse"]["v"] < 0.05
        assert np.degrees(info["rmse"]["r"]) < 0.02
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
                 "fig_rate_of_turn.png"):
        assert (tmp_path / name).exists(), name
