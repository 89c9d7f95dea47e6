"""Messages that say what is wrong: each names the offending item and the reason (issue samples and the
raise sites of the models, readers, manoeuvres and beliefs)."""
from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

import casship as cs
from casship.errors import InputError
from casship.gaussian import as_cov


@pytest.fixture(scope="module")
def runs():
    m = cs.models.nomoto_first_order()
    dm = cs.discretize(m, 0.5)
    prior = cs.Gaussian([0.0, 0.0], [1e-3, 1e-5])
    out = {}
    for est in (cs.EKF(dm, 1e-6, 1e-4), cs.MHE(dm, 1e-6, 1e-4, options={"horizon": 3})):
        run = est.online(prior)
        run.update([0.01], 0.5)
        out[est.name] = run
    return out


@pytest.mark.parametrize("name", ["EKF", "MHE"])
@pytest.mark.parametrize("how, word", [(copy.copy, "copied"), (copy.deepcopy, "copied"), (pickle.dumps, "pickled")])
def test_an_online_run_refuses_to_be_copied_or_pickled_saying_why(runs, name, how, word):
    """Before: pickling said "cannot pickle '_thread.RLock' object"; copy.copy shared the run's buffers."""
    run = runs[name]
    x = run.x
    with pytest.raises(TypeError, match=rf"online {name} run cannot be {word}.*est\.online\(casship\.Gaussian"):
        how(run)
    np.testing.assert_array_equal(run.x, x)             # the run itself is untouched and goes on
    assert run.update([0.012], 0.5).shape == (2,)


def test_a_schedule_speed_without_a_nomoto_model_is_named():
    """Before: ``--schedule 1e-6`` ended in "Nomoto K must be finite"."""
    from casship import autopilot as ap

    ship = cs.models.get_model("kvlcc2")
    with pytest.raises(InputError, match=r"schedule speed 1e-06 m/s: the 'delta' -> 'r' response of 'kvlcc2' has "
                                         r"no finite steady gain"):
        ap.design_autopilot(ship, ship.vessel.U0, schedule=[1e-6, ship.vessel.U0])


def test_a_prior_std_of_an_unknown_parameter_is_named():
    """Before: ``--prior-std bogus=0.1`` said "no mean value"."""
    from casship.design import ParameterBelief

    ship = cs.models.get_model("kvlcc2")
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['bogus'\]: no mean value for them among the \d+ "
                                         r"parameters given \(rho, L_pp, "):
        ParameterBelief.from_std({"bogus": 0.1, "N_r_dash": 0.01}, ship.param_dict())


def test_covariance_messages_name_the_entry():
    with pytest.raises(ValueError, match=r"R: matrix is not symmetric: entry \('psi', 'r'\) is 2, entry \('r', 'psi'\) "
                                         r"is 0"):
        as_cov([[1.0, 2.0], [0.0, 1.0]], 2, "R", names=["psi", "r"])
    with pytest.raises(ValueError, match=r"Q: contains non-finite entries: \(1, 0\) is nan"):
        as_cov([[1.0, 0.0], [np.nan, 1.0]], 2, "Q")
    with pytest.raises(ValueError, match=r"mean contains non-finite entries: entry 1 is inf"):
        cs.Gaussian([0.0, np.inf], 1.0)


def test_zigzag_time_going_backwards_says_when():
    from casship.maneuvers import ZigZag

    ship = cs.models.get_model("kvlcc2")
    zz = ZigZag(ship, np.radians(10.0), np.radians(10.0), t_exec=1.0)
    x = np.asarray(ship.states(u=ship.vessel.U0))
    zz(5.0, x)
    with pytest.raises(ValueError, match=r"time went backwards from 5 s to 2 s"):
        zz(2.0, x)


def test_latitude_in_degrees_is_named():
    from casship.io.geodesy import geodetic_to_ne

    with pytest.raises(ValueError, match=r"latitude 52\.1 \(element 1\) outside \[-pi/2, pi/2\] rad \(degrees given\?\)"):
        geodetic_to_ne(np.array([0.9, 52.1]), np.array([0.1, 0.1]), 0.9, 0.1)
