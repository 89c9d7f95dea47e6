"""Study kvlcc2-marin (quick: seven runs, the 20/20 zig-zag held out) and its tutorial.

The quick study runs the whole workflow (propulsion from the measured thrust, smoothing, free set
from the Fisher information, MAP refinement) without the held-out run, writes the fold's fit file
and scores the held-out run by replaying that file; the file replays from the command line to the
same numbers.
"""
import json
import re
from pathlib import Path

import numpy as np
import pytest

from casship.cli import main
from casship.models import get_model
from casship.maneuvers import replay
from casship.io import read_marin
from problems import get_study

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.fixture(scope="module")
def quick(data_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("kvlcc2_marin")
    return out, get_study("kvlcc2-marin").run(out, quick=True, data_dir=data_dir)


def test_held_out_run_is_predicted_better_than_by_the_published_constants(quick):
    out, summary = quick
    (row,) = summary["leave_one_run_out"]
    assert row["run"] == "MARIN zz_-20"
    assert "MARIN zz_-20" not in summary["folds"]["run:MARIN zz_-20"]["train"]
    assert row["psi_rmse_deg_fit"] < row["psi_rmse_deg_published"]
    assert row["position_rmse_m_fit"] < row["position_rmse_m_published"]
    # the first overshoot closer to the measured one (the second is not: 22.7 against the published 21.8,
    # measured 16.0, with the free set of the run-level rule)
    k = "overshoot_1_deg"
    assert abs(row[f"{k}_fit"] - row[f"{k}_measured"]) < abs(row[f"{k}_published"] - row[f"{k}_measured"]), k
    # propulsion: the propeller fitted to HSVA's measured thrust lowers the thrust error of every run,
    # and of all runs together to about half
    thrust = summary["propulsion"]["thrust"]
    for name, p in thrust.items():
        assert p["thrust RMS error, fitted propeller [%]"] < p["thrust RMS error, published propeller [%]"], name
    fitted, published = ([p[f"thrust RMS error, {k} propeller [%]"] for p in thrust.values()] for k in ("fitted", "published"))
    assert np.mean(fitted) < 0.6 * np.mean(published)
    # every parameter that moved has a standard error
    for name, m in summary["moved"].items():
        if not name.startswith("k_"):          # the thrust coefficients are the open-water curve's
            assert np.isfinite(m["std_error"]) and m["std_error"] > 0, name
    # the free set is chosen twice (at the preset, then at that refinement's estimate); the file carries the second
    fold = summary["folds"]["run:MARIN zz_-20"]
    assert fold["free_at_preset"] and fold["free"]
    # the files' free quantities: the chosen set (the rudder's own quantities one copy per facility,
    # name@MARIN / name@HSVA), then the joined captive facility's own ones (name@HMRI)
    # (the joint fit's files: the chosen ones, or kept beside the captive-only file the nested choice shipped)
    ship_free = [n for n in json.loads((out / fold["joint_file"]).read_text())["free"] if not n.endswith("@HMRI")]
    assert sorted(ship_free) == sorted(fold["free"])
    assert sorted(n for n in json.loads(Path(summary["joint_fit_json"]).read_text())["free"]
                  if not n.endswith("@HMRI")) == sorted(summary["free"])
    # facilities as facilities: HSVA's measured wake is HSVA's; the MARIN run is replayed with the pooled
    # population value (the spread in its band), never with HSVA's value as exact
    held_file = json.loads((out / fold["joint_file"]).read_text())
    pool = held_file["workflow"]["facility_quantities"]["w_P0"]
    assert set(pool["facilities"]) == {"HSVA"} and held_file["workflow"]["replayed_as_facility"] == "MARIN"
    assert held_file["params"]["w_P0"] == pytest.approx(pool["population"], rel=1e-12)
    assert abs(held_file["params"]["w_P0"] - pool["facilities"]["HSVA"]["value"]) > 0.01
    cov = held_file["param_covariance"]
    i = cov["names"].index("w_P0")
    assert np.sqrt(cov["matrix"][i][i]) == pytest.approx(pool["new_facility_std"], rel=1e-9)
    for name in ("epsilon", "kappa", "f_alpha"):     # no rudder quantity is one value carried across facilities
        assert name not in fold["free"], name
    for name in ("report.md", "fit.json", "fit_without_MARIN_zz_-20.json", "cross_validation.csv", "summary.json",
                 "fig_heldout_MARIN_zz_-20.png"):
        assert (out / name).exists(), name


def test_fold_file_replays_to_the_numbers_in_the_report(quick, data_dir, capsys):
    out, summary = quick
    (row,) = summary["leave_one_run_out"]
    held = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_-20_m.dat"
    capsys.readouterr()
    assert main(["simulate", "--model", "kvlcc2", "--params", str(out / row["fit_file"]), "--inputs", str(held),
                 "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    assert cli["replay"]["psi_rmse_deg"] == pytest.approx(row["psi_rmse_deg_fit"], rel=1e-9)
    assert cli["replay"]["position_rmse_m"] == pytest.approx(row["position_rmse_m_fit"], rel=1e-9)
    for k in ("overshoot_1_deg", "overshoot_2_deg"):
        assert cli["metrics"][k] == pytest.approx(row[f"{k}_fit"], rel=1e-9)
        assert cli["metric_intervals"][k] == pytest.approx([row[f"{k}_fit_lo"], row[f"{k}_fit_hi"]], rel=1e-9)
    assert cli["bands"]["psi_coverage"] == pytest.approx(row["psi_band_coverage"], rel=1e-12)
    report = (out / "report.md").read_text()
    assert f"{row['psi_rmse_deg_published']:.3g} -> {row['psi_rmse_deg_fit']:.3g}" in report


def test_fit_file_replays_the_fitted_variant_from_the_command_line(quick, data_dir, capsys):
    out, summary = quick
    fit = json.loads((out / "fit.json").read_text())
    assert fit["model"] == "kvlcc2" and fit["model_options"] == {"asymmetry": True, "smooth": True}
    cov = fit["param_covariance"]
    assert cov["names"] and all(fit["params"][n] == v for n, v in zip(cov["names"], cov["values"]))
    held = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_-20_m.dat"
    capsys.readouterr()
    assert main(["simulate", "--model", "kvlcc2", "--params", str(out / "fit.json"), "--inputs", str(held), "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)["replay"]
    model = get_model("kvlcc2", **fit["model_options"])
    direct = replay(model, read_marin(held), model.params(fit["params"]))
    assert cli["psi_rmse_deg"] == pytest.approx(direct.errors["psi_rmse_deg"], rel=1e-9)


def test_tutorial_runs_and_predicts_the_held_out_zigzag(data_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("CASSHIP_DATA", str(data_dir))
    ns: dict = {}
    for block in re.findall(r"```python\n(.*?)```", (DOCS / "tutorial-kvlcc2-marin.md").read_text(), re.S):
        exec(compile(block, "tutorial-kvlcc2-marin.md", "exec"), ns)
    # the tutorial's claim: 10.5 -> about 7 deg (only the chosen free set moves; no asymmetry from two runs
    # without a mirror pair)
    assert ns["after"].errors["psi_rmse_deg"] < 0.7 * ns["before"].errors["psi_rmse_deg"]
    assert set(ns["idf"].confounded) == {"delta_0", "N_0_dash"}
    assert (tmp_path / "kvlcc2_marin_heldout_bands.png").exists()
    assert 0.012 < ns["R_0"] < 0.017
    assert (tmp_path / "kvlcc2_marin_heldout.png").exists()
    assert np.isfinite(list(ns["fit"].estimates.values())).all()
    # the workflow in one call: every choice has its reason; the held-out zig-zag better than published
    assert all(c["reason"] for c in ns["one_call"].choices)
    assert ns["by_workflow"].errors["psi_rmse_deg"] < ns["before"].errors["psi_rmse_deg"]


def test_runs_are_split_by_the_side_of_their_first_rudder():
    import casship as cs
    from problems.kvlcc2_marin.data import Run, first_rudder_side

    t = np.arange(0.0, 100.0, 1.0)

    def run(first_sign):
        delta = np.where(t < 10, np.radians(0.5), first_sign * np.radians(20.0) * np.sign(np.sin(t / 15.0) + 1e-9))
        return Run("test", "X", cs.Dataset(t, {"delta": delta}), "zigzag")

    assert first_rudder_side(run(+1)) == "+"
    assert first_rudder_side(run(-1)) == "-"
    with pytest.raises(ValueError, match="does not move"):
        first_rudder_side(Run("flat", "X", cs.Dataset(t, {"delta": np.zeros_like(t)}), "zigzag"))
    # a 5/1 zig-zag from a 0.3 deg approach: the first swing (+5 deg) is less than 5 deg from the approach
    delta = np.radians(np.where(t < 10, 0.3, np.where(t < 40, 5.0, -5.0)))
    assert first_rudder_side(Run("5/1", "X", cs.Dataset(t, {"delta": delta}), "zigzag")) == "+"


def test_rudder_lift_term_is_a_candidate_only_of_the_variant_that_has_it():
    from casship.models import kvlcc2
    from problems.kvlcc2_marin import workflow

    plain = kvlcc2(asymmetry=True, smooth=True)
    lift = kvlcc2(asymmetry=True, smooth=True, rudder_lift="cubic")
    assert "c_alpha3" not in workflow.candidates(plain)
    assert workflow.candidates(lift) == [*workflow.CANDIDATES, "c_alpha3"]
    assert workflow.prior_std(lift, ["c_alpha3"]) == {"c_alpha3": 0.5}     # absolute: its published value is 0
    assert workflow.MODEL_OPTIONS.get("rudder_lift", "sine") == "sine"      # lost its cross-validation: off


def test_work_of_one_run_is_done_once_per_process_and_again_for_other_content():
    """Fit records and published replays are kept per run; a run whose columns differ in one bit (the
    HSVA runs with smoothed speeds carry their old names) is another run."""
    import casship as cs
    from problems.kvlcc2_marin.data import Run, per_run

    t = np.arange(5.0)
    run = Run("HSVA X", "HSVA", cs.Dataset(t, {"u": np.ones(5), "delta": np.zeros(5)}), "zigzag")
    made = []
    make = lambda: made.append(1) or len(made)          # noqa: E731
    assert per_run(("test",), run, make) == 1 and per_run(("test",), run, make) == 1
    copy = Run("HSVA X", "HSVA", cs.Dataset(t.copy(), {"u": np.ones(5), "delta": np.zeros(5)}), "zigzag")
    assert per_run(("test",), copy, make) == 1                  # the same content: found again
    assert per_run(("other",), run, make) == 2                  # another kind of work
    u = np.ones(5)
    u[3] = np.nextafter(1.0, 2.0)
    changed = Run("HSVA X", "HSVA", cs.Dataset(t, {"u": u, "delta": np.zeros(5)}), "zigzag")
    assert per_run(("test",), changed, make) == 3


def test_summary_holds_every_fold_family_the_circle_the_coverage_and_the_variants(quick):
    out, summary = quick
    for key in ("loro", "loro_regime", "lodo", "lofo"):
        fam = summary[key]
        assert set(fam) == {"published_mean_deg", "fit_mean_deg", "better", "of"}, key
        assert isinstance(fam["published_mean_deg"], float) and isinstance(fam["fit_mean_deg"], float)
        assert isinstance(fam["better"], int) and isinstance(fam["of"], int) and 0 <= fam["better"] <= fam["of"]
    (row,) = summary["leave_one_run_out"]
    assert summary["loro"]["of"] == 1
    assert summary["loro"]["fit_mean_deg"] == pytest.approx(row["psi_rmse_deg_fit"])
    assert {"advance_pct", "tactical_diameter_pct"} <= set(summary["circle_left_out"])
    assert isinstance(summary["predictive_coverage"], float)
    assert isinstance(summary["variants_tried"], int) and summary["variants_tried"] >= 1
    on_disk = json.loads((out / "summary.json").read_text())
    assert on_disk["variants_tried"] == summary["variants_tried"]
    report = (out / "report.md").read_text()
    assert "Headline: every fold family" in report and "Turning circle left out" in report
    # the joint fit's file records every choice of the workflow with its reason
    fit = json.loads(Path(summary["joint_fit_json"]).read_text())
    assert fit["workflow"]["choices"] and all(c["reason"] for c in fit["workflow"]["choices"])


def test_the_nested_choice_never_sees_the_runs_its_fold_holds_out(quick):
    from problems.kvlcc2_marin.choice import RULE

    out, summary = quick
    nested = summary["nested_choice"]
    assert nested["rule"] == RULE and nested["all_runs"] in ("captive-only", "joint")
    fold = summary["folds"]["run:MARIN zz_-20"]
    chosen = json.loads((out / fold["file"]).read_text())["nested_choice"]
    assert chosen["choice"] == nested["folds"]["run:MARIN zz_-20"]["choice"]
    inner = {n for g in chosen["groups"] for n in g}
    assert "MARIN zz_-20" not in chosen["per_run"] and "MARIN zz_-20" not in inner
    assert inner == set(chosen["per_run"]) == set(fold["train"])
    # the choice follows the rule on its own scores
    s = chosen["scores"]
    assert chosen["choice"] == ("joint" if s["joint"] < s["captive-only"] else "captive-only")
    assert s["captive-only"] == pytest.approx(np.mean([v["captive-only"] for v in chosen["per_run"].values()]))
    # the file a user replays is the chosen candidate's
    assert summary["fit_json_candidate"] == nested["all_runs"]


def test_the_thrust_wake_is_the_facility_s_and_the_open_water_curve_the_ship_s():
    import casship as cs
    from casship.errors import InputError
    from problems.kvlcc2_marin.data import Run
    from problems.kvlcc2_marin.propulsion import PropulsionFit
    from problems.kvlcc2_marin.workflow import propulsion_split

    t = np.arange(3.0)
    runs = [Run(f"{f} {i}", f, cs.Dataset(t, {"thrust": np.ones(3)}), "zigzag") for i, f in enumerate(("HSVA", "MARIN"))]
    prop = PropulsionFit({"k_0": 0.26, "k_1": -0.19, "k_2": -0.13, "w_P0": 0.49}, {"w_P0": 0.004}, ["w_P0"], [],
                         0.0, {}, {}, 1.0, ["HSVA 0"])
    ship, own = propulsion_split(prop, runs)
    assert ship == {"k_0": 0.26, "k_1": -0.19, "k_2": -0.13}
    assert own == {"w_P0": {"HSVA": (0.49, 0.004)}}
    empty = PropulsionFit({}, {}, [], [], float("nan"), {}, {}, float("nan"), [])
    assert propulsion_split(empty, runs) == ({}, {})
    both = PropulsionFit({"w_P0": 0.49}, {"w_P0": 0.004}, ["w_P0"], [], 0.0, {}, {}, 1.0, ["HSVA 0", "MARIN 1"])
    with pytest.raises(InputError, match="several facilities"):
        propulsion_split(both, runs)


def test_predictive_coverage_says_how_much_of_it_is_informative():
    import casship as cs
    from problems.kvlcc2_marin.calibration import predictive_coverage
    from problems.kvlcc2_marin.data import Run

    t = np.arange(0.0, 100.0, 1.0)
    s = np.radians(np.where(t < 50.0, 10.0, 60.0)) / 1.959963984540054      # 10 deg, then 60 deg half-width
    data = cs.Dataset(t, {"psi": np.radians(15.0) * np.ones_like(t)})          # 15 deg off the replay throughout
    run = Run("MARIN A", "MARIN", data, "zigzag")
    ev = {"row": {"run": "MARIN A"}, "fit": cs.Dataset(t, {"psi": np.zeros_like(t)}), "bands": {"psi_std": s}}
    results = [{"kind": "run", "label": "MARIN A", "held": ["MARIN A"], "evaluations": [ev]}]
    narrow = predictive_coverage([run], results, {"MARIN B": 0.0})
    assert narrow["mean"] == 0.5 and narrow["informative_share"] == 1.0 and narrow["inside_and_informative"] == 0.5
    ev["bands"] = {"psi_std": 2.0 * s}                                         # 20 deg, then 120 deg
    wide = predictive_coverage([run], results, {"MARIN B": 0.0})
    assert wide["mean"] == 1.0 and wide["informative_share"] == 0.5 and wide["inside_and_informative"] == 0.5
