"""Vessel values, validity limits and model identity (registry key == model name)."""
import pickle

import numpy as np
import pytest

import casship as cs
from casship.models import add_wind, get_model, kvlcc2, model_names


def test_vessel_checks_its_fields():
    with pytest.raises(ValueError, match="L_pp"):
        cs.Vessel("ship", L_pp=-1.0)
    with pytest.raises(ValueError, match="rudders"):
        cs.Vessel("ship", L_pp=10.0, rudders=("not a name",))
    with pytest.raises(ValueError, match="propeller_range"):
        cs.Vessel("ship", L_pp=10.0, propeller_range=(2.0, 1.0))
    with pytest.raises(ValueError, match="U0"):
        cs.Vessel("ship", L_pp=10.0, U0=float("nan"))


def test_every_registered_model_is_named_by_its_key_and_its_vessel_names_real_inputs():
    for key in model_names():
        model = get_model(key)
        assert model.name == key
        if model.vessel is not None:
            for name in (*model.vessel.rudders, *model.vessel.propellers):
                assert name in model.input_names, (key, name)


def test_a_vessel_naming_a_missing_input_is_refused_at_build():
    b = cs.ModelBuilder("boat")
    r = b.state("r")
    delta = b.input("delta")
    b.ode(r=-r + delta)
    b.vessel = cs.Vessel("boat", L_pp=5.0, rudders=("rudder",))
    with pytest.raises(ValueError, match="rudder"):
        b.build()


def test_limits_are_declared_from_the_vessel():
    ship = kvlcc2()
    lim = ship.limits["delta"]
    assert (lim.lower, lim.upper) == pytest.approx((-np.radians(35), np.radians(35)))
    assert ship.limits["n"].lower == 0.0 and ship.limits["n"].upper == pytest.approx(2 * ship.vessel.n0)
    assert ship.limits["u"].upper == pytest.approx(2 * ship.vessel.U0)
    assert lim.describe(angle=True) == "[-35, 35] deg (rudder stop)"
    assert lim.contains([0.1, 1.0]).tolist() == [True, False]
    b = ship.builder()
    with pytest.raises(ValueError, match="not a declared state or input"):
        b.limit("K_not_there", 0, 1)
    with pytest.raises(ValueError, match="lower < upper"):
        b.limit("delta", 1.0, -1.0)


def test_vessel_and_limits_survive_extension_and_pickling():
    windy = add_wind(kvlcc2())
    assert windy.vessel == kvlcc2().vessel and "delta" in windy.limits
    back = pickle.loads(pickle.dumps(windy))
    assert back.vessel == windy.vessel and dict(back.limits) == dict(windy.limits)


def test_models_with_non_identifier_names_discretize_with_cvodes():
    windy = add_wind(kvlcc2())            # name "kvlcc2+wind"
    assert windy.c_name == "kvlcc2_wind"
    dm = cs.discretize(windy, 1.0, method="cvodes")
    x0 = windy.states(u=windy.vessel.U0)
    u = windy.inputs(n=windy.vessel.n0)
    assert np.all(np.isfinite(dm.step(x0, u)))
