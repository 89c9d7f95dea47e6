"""Cross-validation helper: leave-one-run-out and leave-one-group-out replays against the published values."""
import json

import numpy as np
import pytest

import casship as cs
from casship.identify import OutputErrorProblem, cross_validate

DT = 1.0


def _runs(bias_by_group):
    truth = cs.models.nomoto_first_order(K=0.1, T=20.0)
    runs = []
    for i, (group, bias) in enumerate(bias_by_group):
        rng = np.random.default_rng(i)
        t = np.arange(0, 300.0, DT)
        delta = (0.1 + 0.05 * i) * np.sign(np.sin(2 * np.pi * t / (100 + 15 * i)))
        tr = cs.simulate(truth, truth.states(), t, {"delta": delta + bias})
        d = cs.measure(tr, truth, {"psi": 0.005}, seed=rng).with_columns(delta=delta)
        d.meta.update(name=f"run {i} ({group})", facility=group)
        runs.append(d)
    return runs


def test_leave_one_run_out_and_leave_one_group_out(tmp_path):
    published = cs.models.nomoto_first_order()              # Mariner K, T: far from the truth
    runs = _runs([("A", 0.01), ("A", 0.01), ("B", -0.01), ("B", -0.01)])
    prob = OutputErrorProblem(published, runs, free=["K", "T", "bias[delta]"], sigma={"psi": 0.005},
                              share={"bias[delta]": "facility"}, estimate_x0=["psi"])
    cv = cross_validate(prob)
    assert len(cv.folds) == 4 and [len(f["train"]) for f in cv.folds] == [3, 3, 3, 3]
    assert sorted(cv.improved) == sorted(d.meta["name"] for d in runs)
    for row in cv.rows:
        # the held-out run's facility bias is estimated in its fold: the replay is close to the measurement
        assert row["fit"]["psi_rmse_deg"] < 0.2 * row["reference"]["psi_rmse_deg"]
    assert "4 of 4" in cv.summary()
    # leave one facility out: the held-out facility's bias is unknown to the fold (replayed with 0)
    by_facility = cross_validate(prob, by="facility")
    assert [f["label"] for f in by_facility.folds] == ["A", "B"]
    for f in by_facility.folds:
        assert not any(n.startswith("bias[delta]@" + f["label"]) for n in f["fit"].free)
    worse = {r["record"]: r["fit"]["psi_rmse_deg"] for r in by_facility.rows}
    better = {r["record"]: r["fit"]["psi_rmse_deg"] for r in cv.rows}
    assert all(worse[k] > better[k] for k in better)
    paths = cv.plot(tmp_path / "cv")
    assert len(paths) == 4 and all(p.stat().st_size > 10_000 for p in paths)
    saved = json.loads(cv.to_json(tmp_path / "cv.json").read_text())
    assert len(saved["rows"]) == 4 and saved["folds"][0]["estimates"]["K"] == pytest.approx(
        cv.folds[0]["fit"].estimates["K"])
    with pytest.raises(ValueError, match="meta"):
        cross_validate(prob, by="basin")
