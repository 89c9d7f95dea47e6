"""Captive rigs: the facility's model from its particulars and tests, the rule's free set, what carries to
another ship, the out-of-sample verdict, and the ``casship identify --captive`` door."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from casship.cli import main
from casship.data import Dataset
from casship.errors import InputError
from casship.identify.captive_choice import choose_with_captive, inner_groups
from casship.identify.rig import (CAPTIVE_HULL, CAPTIVE_OWN, RIGS, Rig, captive_free_set, carried,
                                  classical_derivatives, read_rig, write_carried)
from casship.identify.verdict import judge_unseen
from casship.models import kvlcc2, nomoto_first_order
from casship.simulation import simulate

from captive_records import design, synthetic

PARTICULARS = {"L_pp": 7.0, "B": 1.27, "d": 0.46, "nabla": 3.27, "x_G": 0.25, "rho": 1000.0, "k_zz": 0.25,
               "D_p": 0.216, "A_R": 0.0539, "H_R": 0.345}
K_T = (0.29, -0.27, -0.16)         # K_T = k0 + k1 J + k2 J^2 of the synthetic open-water curve
TRUE = {"Y_v_dash": -0.34, "N_v_dash": -0.13, "N_r_dash": -0.055, "m_y_dash": 0.25, "t_R": 0.45,
        "gamma_R_plus": 0.6, "delta_0": 0.01}
NOISE = {f"{t}:{c}": s for t in ("static", "dynamic") for c, s in zip(("X", "Y", "N", "RY", "T"),
                                                                      (2e-4, 3e-4, 1e-4, 1e-4, 1e-4))}


def rig_tests(rig: Rig, seed: int = 3):
    """Synthetic tests of a known ship on ``rig``: with an exactly quadratic open-water curve and a resistance test."""
    J = np.linspace(0.0, 0.7, 8)
    base = replace(design(U=1.18, rps=10.0, L=PARTICULARS["L_pp"]), source="synthetic",
                   open_water={"J": J, "K_T": K_T[0] + K_T[1] * J + K_T[2] * J**2, "K_Q": 0.03 + 0 * J},
                   resistance={"speed": np.array([1.0, 1.1, 1.3]), "resistance": np.array([20.0, 24.0, 33.0])})
    model = rig.model(base)
    truth = synthetic(model, model.params(TRUE), base, channels=("X", "Y", "N", "RY", "T"), noise=NOISE, seed=seed)
    return replace(truth, open_water=base.open_water, resistance=base.resistance), model


@pytest.fixture(scope="module")
def rig():
    return Rig("TANK", PARTICULARS, nominal_speed=1.18, source="made up")


def test_the_rig_model_carries_its_particulars_propeller_curve_and_resistance(rig):
    tests, model = rig_tests(rig)
    p = model.param_dict()
    for name, value in PARTICULARS.items():
        assert p[name] == value
    np.testing.assert_allclose([p["k_0"], p["k_1"], p["k_2"]], K_T, atol=1e-12)     # the quadratic fitted exactly
    R = np.interp(1.18, [1.0, 1.1, 1.3], [20.0, 24.0, 33.0])
    assert p["R_0_dash"] == pytest.approx(R / (0.5 * 1000.0 * 1.18**2 * 7.0 * 0.46), rel=1e-12)
    assert {"delta_0", "Y_0_dash"} <= set(model.param_names)            # the neutral angle of the captive variant


def test_the_rule_recovers_a_known_ship_and_carries_only_the_hull(rig):
    tests, _ = rig_tests(rig)
    pb = rig.problem(tests)
    assert pb.plain == captive_free_set(pb.model)
    assert set(CAPTIVE_HULL) <= set(pb.plain) and set(CAPTIVE_OWN) <= set(pb.plain)
    fit = pb.solve(show=False)
    for name, value in TRUE.items():
        joint = pb.joint_name(name)
        assert abs(fit.estimates[joint] - value) < 4 * fit.std_errors[joint], name
    ship = kvlcc2()
    values, belief = carried(fit, ship)
    assert not any("@" in n for n in values) and "delta_0" not in values      # facility quantities stay with the rig
    k = len(values)
    assert list(belief.names)[:k] == list(values) and belief.kind == "robust"
    robust = fit.uncertainty("robust")
    i = [robust.names.index(n) for n in values]
    np.testing.assert_array_equal(belief.cov[:k, :k], robust.cov[np.ix_(i, i)])
    # the facility quantities no captive test pins on the ship: at its preset, independent, with the
    # population value of a new facility: prior and between-facility spread both the stated uncertainty
    rest = list(belief.names)[k:]
    preset = ship.param_dict()
    assert set(rest) == {"epsilon", "kappa", "f_alpha", "t_P", "w_P0"}           # kvlcc2: no neutral angle term
    np.testing.assert_array_equal(belief.cov[:k, k:], 0.0)
    for j, n in enumerate(rest):
        assert belief.values[k + j] == preset[n]
        assert np.sqrt(belief.cov[k + j, k + j]) == pytest.approx(np.sqrt(2.0) * 0.2 * preset[n], rel=1e-12), n
    with_ports = carried(fit, kvlcc2(asymmetry=True, smooth=True))[1]
    sd = dict(zip(with_ports.names, np.sqrt(np.diag(with_ports.cov))))
    assert sd["delta_0"] == pytest.approx(np.radians(np.sqrt(2.0)), rel=1e-12)     # 1 deg prior, 1 deg spread
    assert sd["N_0_dash"] == pytest.approx(0.025, rel=1e-12)                        # a port/starboard term: its prior
    path = write_carried("carried.json", ship, values, belief)
    obj = json.loads(path.read_text())
    assert obj["candidate"] == "captive-only" and obj["estimates"] == values and obj["free"] == list(values)
    assert obj["param_covariance"]["names"] == list(belief.names)


def test_rig_files_and_their_errors(rig, tmp_path):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(rig.to_dict()))
    assert read_rig(path) == rig
    hmri = read_rig("hmri-t530")
    assert hmri.facility == "HMRI" and set(RIGS) == {"hmri-t530"}
    # k_zz from the yaw inertia about midship (README): m k^2 L^2 + m x_G^2 = 9516 kg m^2
    p = hmri.particulars
    assert 3123.0 * (p["k_zz"] * p["L_pp"]) ** 2 + 3123.0 * p["x_G"] ** 2 == pytest.approx(9516.0, rel=1e-12)
    cases = {"nosuch": "neither a known rig", '{"facility": "A"}': "missing 'nominal_speed_mps'",
             '{"facility": "A", "nominal_speed_mps": 1, "particulars": {"L_pp": "7"}}': "['L_pp'] are not numbers",
             '{"facility": "A", "nominal_speed_mps": 1, "particulars": {"L_pp": 7}, "speed": 2}': "unknown entries",
             '{"facility": "A@B", "nominal_speed_mps": 1, "particulars": {"L_pp": 7}}': "without '@'",
             '[1, 2]': "expected a JSON object", '{': "not JSON"}
    for text, message in cases.items():
        src = text
        if text != "nosuch":
            src = tmp_path / "bad.json"
            src.write_text(text)
        with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
            read_rig(src)
    tests, _ = rig_tests(rig)
    with pytest.raises(InputError, match="outside the resistance test"):
        Rig("TANK", PARTICULARS, nominal_speed=2.0).values(tests)
    with pytest.raises(InputError, match="lacks"):
        rig.values(replace(tests, open_water=None))
    with pytest.raises(InputError, match="rig TANK: .*'hull_colour'"):
        Rig("TANK", {**PARTICULARS, "hull_colour": 1.0}, nominal_speed=1.18).model(tests)
    with pytest.raises(InputError, match="cannot be a captive rig's model"):
        rig.model(tests, "nomoto1")


def _nomoto_record(K, T, seed=0):
    m = nomoto_first_order()
    t = np.arange(0.0, 300.0, 1.0)
    delta = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 120.0))
    tr = simulate(m, np.zeros(2), t, {"delta": delta}, p=m.params({"K": K, "T": T}))
    psi = tr["psi"] + np.radians(0.2) * np.random.default_rng(seed).standard_normal(len(t))
    return Dataset(t, {"delta": delta, "r": tr["r"], "psi": psi}, meta={"name": f"zz{seed}"})


def test_judging_values_on_records_they_did_not_see():
    m = nomoto_first_order()
    K, T = 0.8 * m.param_dict()["K"], 1.3 * m.param_dict()["T"]
    records = [_nomoto_record(K, T, seed) for seed in (1, 2)]
    verdict, q = judge_unseen(m, records, {"K": K, "T": T})
    assert verdict["verdict"] == "better" and verdict["out_of_sample"]
    assert all(r["psi_rmse_deg_fit"] < r["psi_rmse_deg_start"] for r in verdict["records"])
    assert 0.0 <= q["psi_variance_growth_deg2_per_s"] < 1e-3 and "out of sample" in q["method"]
    same, _ = judge_unseen(m, records, {})
    assert same["verdict"] == "no better"


def test_inner_groups_deal_names_in_order():
    assert inner_groups(["c", "a", "b", "d"]) == [["a", "d"], ["b"], ["c"]]
    assert inner_groups(["x"]) == [["x"]]


# -- the command, on the measured folders --------------------------------------------------------------------

def _folders(data_dir):
    captive = data_dir / "kvlcc2_hmri_captive"
    marin = data_dir / "kvlcc2_marin_free"
    if not captive.is_dir() or not marin.is_dir():
        pytest.skip("the HMRI captive tests or the MARIN runs are absent from the data folder")
    return captive, marin / "MARIN_FREE_KVLCC2"


@pytest.mark.data
def test_identify_captive_alone_writes_the_carried_hull(data_dir, capsys):
    from casship.io import read_captive

    captive, _ = _folders(data_dir)
    assert main(["identify", "--captive", str(captive), "--rig", "hmri-t530", "--model", "kvlcc2",
                 "--out", "cap.json", "--plot", "forces.png"]) == 0
    text = capsys.readouterr().out
    assert "carried to 'kvlcc2'" in text and "no model-discrepancy term" in text
    obj = json.loads(open("cap.json").read())
    problem = read_rig("hmri-t530").problem(read_captive(captive), "kvlcc2")
    fit = problem.solve(show=False)
    # the classical cross-check on the rig's mass and yaw inertia: the added mass and inertia of docs/data.md
    classical = classical_derivatives(problem)
    assert classical["m_y_dash"] == pytest.approx(0.209, abs=5e-4) and classical["J_z_dash"] == pytest.approx(0.0114, abs=5e-5)
    values, _ = carried(fit, kvlcc2())
    assert obj["estimates"] == pytest.approx(values, rel=1e-9) and "verdict" not in obj
    assert open("forces.png", "rb").read(4) == b"\x89PNG"


@pytest.mark.data
def test_identify_with_captive_tests_chooses_by_the_rule_and_judges_out_of_sample(data_dir, capsys):
    captive, marin = _folders(data_dir)
    code = main(["identify", f"{marin}_zz_10_m.dat", "--model", "kvlcc2", "--captive", str(captive), "--rig",
                 "hmri-t530", "--out", "fit.json"])
    obj = json.loads(open("fit.json").read())
    assert obj["captive_choice"]["choice"] == "captive-only" and obj["captive_choice"]["groups"] == []
    assert obj["verdict"]["out_of_sample"] and obj["model_discrepancy"]["psi_variance_growth_deg2_per_s"] >= 0
    assert code == (3 if obj["verdict"]["verdict"] in ("worse", "stalled") else 0)
    assert "[captive] captive-only" in capsys.readouterr().out
    assert main(["simulate", "--model", "kvlcc2", "--params", "fit.json", "--inputs", f"{marin}_zz_-20_m.dat",
                 "--samples", "0"]) == 0


@pytest.mark.data
def test_the_choice_scores_both_candidates_with_an_inner_split(data_dir):
    from casship.io import read_captive, read_marin

    captive, marin = _folders(data_dir)
    records = [read_marin(f"{marin}_{n}_m.dat") for n in ("tc_-35", "zz_10")]
    pb = read_rig("hmri-t530").problem(read_captive(captive), "kvlcc2")
    choice = choose_with_captive(records, kvlcc2(), pb, pb.solve(show=False))
    assert len(choice.groups) == 2 and all(np.isfinite(v) for v in choice.scores.values())
    assert choice.choice == min(choice.scores, key=choice.scores.get)


def test_the_command_refuses_what_it_cannot_do(capsys):
    assert main(["identify", "--model", "kvlcc2"]) == 2
    assert "--captive DIR --rig RIG" in capsys.readouterr().err
    assert main(["identify", "--model", "kvlcc2", "--captive", "somewhere"]) == 2
    assert "name the rig" in capsys.readouterr().err
    for args, message in ((["x.csv", "--model", "kvlcc2", "--rig", "hmri-t530"], "--rig would have no effect"),
                          (["--model", "kvlcc2", "--captive", "d", "--rig", "hmri-t530", "--free", "K"],
                           "--free would have no effect")):
        assert main(["identify", *args]) == 2
        assert message in capsys.readouterr().err


def test_identify_with_captive_tests_alone_and_the_joint_branch(rig, monkeypatch):
    """Without records the carried captive-only model; with records and the joint fit chosen, the ship workflow with
    the captive term (the choice forced here: on these synthetic records either candidate could win)."""
    import casship as cs
    from casship.identify import captive_choice
    from casship.identify.captive_choice import CaptiveChoice, identify_with_captive

    tests, _ = rig_tests(rig)
    pb = rig.problem(tests)
    fit = pb.solve(show=False)
    alone = identify_with_captive([], "kvlcc2", pb, fit)
    assert alone.ship is None and alone.verdict is None and not alone.worse
    assert alone.values == carried(fit, kvlcc2())[0]
    assert "the captive tests alone" in alone.summary() and "classical linear derivatives" in alone.summary()
    assert alone.classical == classical_derivatives(pb) and "N_v_dash" in alone.classical
    obj = json.loads(alone.to_json("alone.json").read_text())
    assert obj["captive_choice"]["choice"] == "captive-only" and "verdict" not in obj

    ship = cs.models.get_model("kvlcc2")
    tr = cs.maneuvers.run_maneuver(ship, "zigzag", rudder_deg=10, duration=500, dt=2.0).trajectory
    rng = np.random.default_rng(5)
    noise = {"u": 0.02, "v": 0.02, "r": 1e-4, "x": 2.0, "y": 2.0, "psi": np.radians(0.2)}
    cols = {n: tr[n] + noise.get(n, 0.0) * rng.standard_normal(len(tr)) for n in ("delta", "n", *noise)}
    rec = cs.Dataset(tr.t, cols, meta={"name": "zz"})
    forced = CaptiveChoice("joint", {"captive-only": 2.0, "joint": 1.0}, {"zz": {"captive-only": 2.0, "joint": 1.0}},
                           [["zz"]])
    monkeypatch.setattr(captive_choice, "choose_with_captive", lambda *a, **k: forced)
    joint = identify_with_captive([rec], ship, pb, fit, workflow={"verdict": "replay"})
    assert joint.ship is not None and joint.values == {}
    assert "captive:TANK" in joint.ship.fit.records
    assert joint.verdict_block is joint.ship.fit.verdict
    obj = json.loads(joint.to_json("joint.json").read_text())
    assert obj["captive_choice"]["choice"] == "joint" and obj["verdict"]["verdict"] in ("better", "no better", "worse")


def test_the_inner_folds_replay_a_record_with_its_own_facility(rig, monkeypatch):
    """A record that names no facility is of the workflow's one default facility, in training and when held out."""
    import casship as cs
    from casship.identify import captive_choice, workflow
    from casship.identify.records import DEFAULT_FACILITY, facility_of

    tests, _ = rig_tests(rig)
    pb = rig.problem(tests)
    fit = pb.solve(show=False)
    ship = cs.models.get_model("kvlcc2")
    tr = cs.maneuvers.run_maneuver(ship, "zigzag", rudder_deg=10, duration=300, dt=2.0).trajectory
    records = [cs.Dataset(tr.t, {n: tr[n] for n in ("delta", "n", "u", "v", "r", "x", "y", "psi")}, meta={"name": k})
               for k in ("a", "b")]
    asked = []

    class Fake:
        def params(self, facility=None):
            asked.append(facility)
            return ship.param_dict()

    monkeypatch.setattr(workflow, "identify_ship", lambda *a, **k: Fake())
    choice = captive_choice.choose_with_captive(records, ship, pb, fit)
    assert asked == [DEFAULT_FACILITY] * 2 and len(choice.groups) == 2
    assert facility_of(cs.Dataset(tr.t, {"psi": tr["psi"]}, meta={"facility": "HSVA"})) == "HSVA"
