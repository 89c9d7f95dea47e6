"""Port/starboard asymmetry only from mirrored evidence (casship.identify.asymmetry).

A simulated KVLCC2 with a known rudder neutral angle: trained on runs that turn first to one side
only, the neutral angle of its facility is flagged confounded with the turning dynamics and not
proposed; with the mirror images of the runs in training it is recovered.
"""
import numpy as np
import pytest

import casship as cs
from casship.identify import Prior
from casship.identify.asymmetry import confounded_asymmetry, mirror_pairs, turn_side

from asymmetry_records import SIGMA, both_directions

TRUTH = {"delta_0": np.radians(1.5)}


@pytest.fixture(scope="module")
def runs():
    return both_directions(TRUTH)


def _problem(ship, records):
    return cs.OutputErrorProblem(ship, records, ["delta_0", "N_r_dash"], measured=["psi", "r"],
                                 sigma=SIGMA,
                                 share={"delta_0": "facility"}, scale={"delta_0": np.radians(1.0)},
                                 prior=Prior({"delta_0": np.radians(1.0), "N_r_dash": 0.01}))


def test_turn_side_uses_half_the_largest_deflection():
    t = np.arange(0.0, 100.0, 1.0)
    delta = np.radians(np.where(t < 10, 0.3, np.where(t < 40, 5.0, -5.0)))   # a 5 deg first swing
    assert turn_side(cs.Dataset(t, {"delta": delta})) == "+"
    assert turn_side(cs.Dataset(t, {"delta": -delta})) == "-"
    with pytest.raises(ValueError, match="does not move"):
        turn_side(cs.Dataset(t, {"delta": np.zeros_like(t)}))


def test_mirror_pairs_need_the_same_manoeuvre_in_both_directions(runs):
    _, starboard, port = runs
    assert mirror_pairs(starboard) == []
    assert sorted(mirror_pairs(starboard + port)) == [(0, 2), (1, 3)]
    # a pair split over two groups (e.g. facilities) is no evidence within either
    assert mirror_pairs(starboard + port, within=["A", "A", "B", "B"]) == []
    why = confounded_asymmetry(starboard, ["delta_0@A"], {"delta_0": ["A", "A"]})
    assert "confounded with the turning dynamics" in why["delta_0@A"]


def test_one_direction_only_is_flagged_confounded_and_not_proposed(runs):
    ship, starboard, _ = runs
    idf = _problem(ship, starboard).identifiability(at={"delta_0@A": 0.0, "N_r_dash": ship.param_dict()["N_r_dash"]})
    assert list(idf.confounded) == ["delta_0@A"]
    assert "delta_0@A" not in idf.propose()
    assert "N_r_dash" in idf.propose()
    assert "confounded: delta_0@A" in idf.summary()


def test_both_directions_recover_the_neutral_angle(runs):
    ship, starboard, port = runs
    prob = _problem(ship, starboard + port)
    idf = prob.identifiability()
    assert idf.confounded == {}
    assert "delta_0@A" in idf.propose()
    fit = prob.solve(show=False)
    est, se = fit.estimates["delta_0@A"], fit.std_errors["delta_0@A"]
    assert abs(est - TRUTH["delta_0"]) < max(4 * se, np.radians(0.05))
    assert abs(np.degrees(est) - 1.5) < 0.1
