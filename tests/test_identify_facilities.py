"""Facility quantities in the ship workflow: a value measured in one facility is that facility's.

A quantity measured per facility before the fit (``identify_ship(facility_values=...)``, e.g. a wake
fitted to one facility's measured thrust) runs each record of that facility at its own value and
every other record, in the fit and in a replay, at the pooled population value with the
between-facility spread in its band; the records' own values reach the output-error problem as
``record_params``.
"""
import dataclasses
import json

import numpy as np
import pytest

import casship as cs
from casship.errors import InputError
from casship.identify.workflow import DIRECTION_SWITCHED, pool_facilities

K_A, T_TRUE = 0.15, 26.0            # facility A's own K (measured before the fit) and the ship's T
PRESET = {"K": 0.1, "T": 20.0}
PRIOR = {"K": 0.05, "T": 10.0}


def _population_by_hand(est=K_A, se=1e-3, prior_mean=PRESET["K"], std=PRIOR["K"]) -> float:
    """Normal-normal posterior mean of the population value: prior N(0.1, 0.05^2), one facility
    estimate with variance spread^2 + se^2 (spread = the stated uncertainty, 0.05)."""
    w0, w1 = 1 / std**2, 1 / (std**2 + se**2)
    return (w0 * prior_mean + w1 * est) / (w0 + w1)


def _runs(ks, seed=0):
    """Zig-zag-like Nomoto runs, run ``i`` of a ship with gain ``ks[i]`` and ``T_TRUE``."""
    t = np.arange(0.0, 400.0, 1.0)
    out = []
    for i, k in enumerate(ks):
        truth = cs.models.nomoto_first_order(K=k, T=T_TRUE)
        amp = np.radians([10.0, -15.0, 20.0, -12.0][i])
        delta = amp * np.sign(np.sin(2 * np.pi * t / (90.0 + 15 * i)) + 1e-9)
        out.append(cs.measure(cs.simulate(truth, truth.states(), t, {"delta": delta}), truth,
                              {"psi": np.radians(0.2)}, seed=seed + i))
    return out


@pytest.fixture(scope="module")
def two_facilities():
    """A's records at A's measured K, B's at the population value the rule gives B."""
    pop = _population_by_hand()
    recs = _runs([K_A, K_A, pop, pop])
    model = cs.models.nomoto_first_order(**PRESET)
    ship = cs.identify_ship(recs, model, facility=["A", "A", "B", "B"], candidates=["T"], prior=PRIOR,
                            facility_values={"K": {"A": (K_A, 1e-3)}}, verdict=None)
    return ship, recs, pop


def test_the_other_facility_runs_at_the_population_value_not_at_the_measured_one(two_facilities):
    ship, _, pop = two_facilities
    assert pop == pytest.approx(0.125, abs=1e-3)          # half-way: one facility against the prior
    assert ship.facility["K"]["population"] == pytest.approx(pop, rel=1e-12)
    assert ship.params("A")["K"] == K_A
    for facility in ("B", "C", None):                    # in the training without a value, absent, a new run
        assert ship.params(facility)["K"] == pytest.approx(pop, rel=1e-12)
        assert ship.params(facility)["K"] != pytest.approx(K_A, rel=0.05)
    # in the fit itself: A's records at A's value, B's at the population value (the problem's base)
    rp = ship.fit.record_params
    assert rp[0]["K"] == K_A and rp[1]["K"] == K_A
    assert rp[2].get("K", ship.fit.params["K"]) == pytest.approx(pop, rel=1e-12)
    # so T is the ship's: recovered from both facilities' runs
    assert ship.fit.estimates["T"] == pytest.approx(T_TRUE, rel=0.02)


def test_applying_the_measured_value_to_every_record_biases_the_ship_quantity():
    """The defect the rule removes: A's K applied as exact to B's records pulls T away from the truth."""
    pop = _population_by_hand()
    recs = _runs([K_A, K_A, pop, pop])
    model = cs.models.nomoto_first_order(**PRESET)
    every = cs.identify_ship(recs, model, facility=["A", "A", "B", "B"], candidates=["T"], prior=PRIOR,
                             propulsion={"K": K_A}, verdict=None)
    assert abs(every.fit.estimates["T"] / T_TRUE - 1) > 0.05


def test_the_band_of_the_other_facility_carries_the_between_facility_spread(two_facilities, tmp_path):
    ship, _, pop = two_facilities
    pool = ship.facility["K"]
    spread = PRIOR["K"]
    var_pop = 1 / (1 / PRIOR["K"] ** 2 + 1 / (spread**2 + 1e-6))
    assert pool["new_facility_std"] == pytest.approx(np.sqrt(var_pop + spread**2), rel=1e-9)
    for facility, std in (("A", 1e-3), ("B", pool["new_facility_std"])):
        unc = ship.uncertainty(facility)
        i = unc.names.index("K")
        assert unc.covariance[i, i] == pytest.approx(std**2, rel=1e-9)
    content = json.loads(ship.to_json(tmp_path / "fit_B.json", "B").read_text())
    assert content["params"]["K"] == pytest.approx(pop, rel=1e-12)
    cov = content["param_covariance"]
    i = cov["names"].index("K")
    assert np.sqrt(cov["matrix"][i][i]) == pytest.approx(pool["new_facility_std"], rel=1e-9)
    assert content["workflow"]["facility_quantities"]["K"]["facilities"] == {"A": {"value": K_A, "std_error": 1e-3}}


def test_facility_values_bad_input():
    model = cs.models.nomoto_first_order(**PRESET)
    recs = _runs([0.1, 0.1])
    with pytest.raises(InputError, match="not a parameter"):
        cs.identify_ship(recs, model, candidates=["T"], prior=PRIOR, facility_values={"w_P0": {"A": (0.3, 0.01)}},
                         verdict=None)
    with pytest.raises(InputError, match="also given in propulsion"):
        cs.identify_ship(recs, model, candidates=["T"], prior=PRIOR, propulsion={"K": 0.1},
                         facility_values={"K": {"A": (0.1, 0.01)}}, verdict=None)


def test_record_params_run_each_record_at_its_own_fixed_values():
    pop = 0.1
    recs = _runs([K_A, pop])
    model = cs.models.nomoto_first_order(**PRESET)
    prob = cs.OutputErrorProblem(model, recs, ["T"], sigma={"psi": np.radians(0.2)}, record_params=[{"K": K_A}, None])
    fit = prob.solve(guess={"T": 20.0}, show=False, verdict=None)
    assert fit.estimates["T"] == pytest.approx(T_TRUE, rel=0.01)
    assert fit.record_params[0] == {"K": K_A} and fit.record_params[1] == {}
    assert fit.params["K"] == pop                        # a new run: the shared fixed value
    # subset alike (cross-validation folds), and the count is checked
    sub = prob.subset([0])
    assert sub.space.record_map(0).fixed["p"][model.index("K", "param")] == K_A
    with pytest.raises(InputError, match="record_params"):
        cs.OutputErrorProblem(model, recs, ["T"], sigma={"psi": 0.01}, record_params=[{"K": K_A}])


def test_wake_change_coefficients_are_direction_switched():
    """``C_2_plus/minus`` switch with the sign of the drift at the propeller: mirrored evidence only."""
    assert {"C_2_plus", "C_2_minus", "gamma_R_plus", "gamma_R_minus"} <= set(DIRECTION_SWITCHED)


def test_pool_with_a_prior_mean():
    pool = pool_facilities({"A": (0.5, 0.0)}, spread=0.1, prior_std=0.1, prior_mean=0.3)
    assert pool["population"] == pytest.approx(0.4)


def test_a_rudder_quantity_is_estimated_per_facility_and_pooled(monkeypatch):
    """A facility's own candidate (``K`` standing for the rudder's ``epsilon``): one copy per facility,
    each facility replayed with its own, a facility the training lacks with the population value."""
    from casship.identify import workflow

    monkeypatch.setattr(workflow, "RUDDER", ("K",))
    k_b = 0.08
    recs = _runs([K_A, K_A, k_b, k_b])
    model = cs.models.nomoto_first_order(**PRESET)
    ship = cs.identify_ship(recs, model, facility=["A", "A", "B", "B"], candidates=["K", "T"], prior=PRIOR,
                            dt=1.0, verdict=None)
    assert {"K@A", "K@B", "T"} <= set(ship.fit.free) and "K" not in ship.fit.free
    assert ship.params("A")["K"] == pytest.approx(K_A, rel=0.03)
    assert ship.params("B")["K"] == pytest.approx(k_b, rel=0.03)
    # the same MAP as the problem built by hand with a copy per facility (the workflow's sigma and prior)
    by_hand = cs.OutputErrorProblem(model, recs, ["K", "T"], sigma=ship.sigma, share={"K": ["A", "A", "B", "B"]},
                                    prior=cs.identify.Prior(PRIOR)).solve(guess={"K@A": 0.15, "K@B": 0.08, "T": 26.0},
                                                                          show=False, verdict=None)
    for name in ("K@A", "K@B", "T"):
        assert ship.fit.estimates[name] == pytest.approx(by_hand.estimates[name], rel=1e-4), name
    pool = ship.facility["K"]
    est = {f: (ship.fit.estimates[f"K@{f}"], workflow._std_error(ship.fit, f"K@{f}")) for f in ("A", "B")}
    assert pool["population"] == pytest.approx(
        pool_facilities(est, spread=PRIOR["K"], prior_std=PRIOR["K"], prior_mean=PRESET["K"])["population"])
    for facility in ("C", None):
        assert ship.params(facility)["K"] == pytest.approx(pool["population"], rel=1e-12)
        unc = ship.uncertainty(facility)
        assert unc.covariance[unc.names.index("K"), unc.names.index("K")] == pytest.approx(pool["new_facility_std"] ** 2)
    # one facility in the training: its own copy, and the other facility gets the population value
    only_a = cs.identify_ship(recs[:2], model, facility=["A", "A"], candidates=["K", "T"], prior=PRIOR, verdict=None)
    assert "K@A" in only_a.fit.free
    assert only_a.params("B")["K"] == pytest.approx(only_a.facility["K"]["population"], rel=1e-12)
    assert abs(only_a.params("B")["K"] - K_A) > 0.01


def test_one_rudder_value_for_two_facilities_fits_neither(monkeypatch):
    """The defect the per-facility copies remove: one value carried across facilities."""
    from casship.identify import workflow

    monkeypatch.setattr(workflow, "RUDDER", ())
    recs = _runs([K_A, K_A, 0.08, 0.08])
    model = cs.models.nomoto_first_order(**PRESET)
    ship = cs.identify_ship(recs, model, facility=["A", "A", "B", "B"], candidates=["K", "T"], prior=PRIOR,
                            dt=1.0, verdict=None)
    assert "K" in ship.fit.free and "K" not in ship.facility
    assert abs(ship.params("A")["K"] / K_A - 1) > 0.2 and abs(ship.params("B")["K"] / 0.08 - 1) > 0.2


def test_with_one_facility_its_copy_is_the_shared_value_through_every_pass(monkeypatch):
    """One facility: ``K@A`` is the same quantity as a shared ``K`` (second choice and refinement start
    from its previous value, channel sigmas taken at it)."""
    from casship.identify import workflow

    recs = _runs([K_A, K_A, K_A])
    model = cs.models.nomoto_first_order(**PRESET)
    fits = {}
    for rudder in ((), ("K",)):
        monkeypatch.setattr(workflow, "RUDDER", rudder)
        fits[rudder] = cs.identify_ship(recs, model, facility="A", candidates=["K", "T"], prior=PRIOR, passes=2,
                                        verdict=None)
    plain, copy = fits[()], fits[("K",)]
    assert copy.sigma == pytest.approx(plain.sigma, rel=1e-9)
    assert copy.fit.estimates["K@A"] == pytest.approx(plain.fit.estimates["K"], rel=1e-6)
    assert copy.fit.estimates["T"] == pytest.approx(plain.fit.estimates["T"], rel=1e-6)
    assert copy.params("A")["K"] == pytest.approx(plain.params("A")["K"], rel=1e-6)


def test_a_fit_file_is_written_for_the_training_facility_when_there_is_one(two_facilities, tmp_path):
    """One way to write a fit: ``to_json`` by default writes the training records' facility when they share
    one (as ``casship identify`` does), the population values when they do not, or what it is told."""
    from casship.identify.shipfit import TRAINING

    ship, recs, pop = two_facilities                  # two facilities: the default is the population values
    assert ship.file_facility() is None and ship.file_facility("A") == "A" and ship.file_facility(None) is None
    content = json.loads(ship.to_json(tmp_path / "two.json").read_text())
    assert content["params"]["K"] == pytest.approx(pop, rel=1e-12)
    only_a = dataclasses.replace(ship, facilities=["A", "A"])
    assert only_a.file_facility(TRAINING) == "A"
    assert json.loads(only_a.to_json(tmp_path / "a.json").read_text())["params"]["K"] == K_A
    assert json.loads(only_a.to_json(tmp_path / "pop.json", None).read_text())["params"]["K"] == pytest.approx(pop)
    assert only_a.to_dict()["params"]["K"] == K_A      # the JSON printed and the file written agree
