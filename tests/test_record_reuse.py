"""An estimator run again on the same record reuses its checked arrays, never a stale or writable one.

A :class:`casship.Dataset` is immutable, so :meth:`Estimator.prepare` keeps the arrays of the last
record it checked and the starts it found finite. These tests make sure the reuse cannot leak
from one record to another, nor let a bad start through.
"""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship.estimators import ESTIMATORS
from casship.simulation import ValidityError
from filter_models import oscillator_case

FAST = {"mhe": {"solver": "rti", "horizon": 5}}


def _fields(res):
    return [res.x, res.P, res.innovations, res.loglik_terms, res.n_measured]


@pytest.mark.parametrize("name", sorted(ESTIMATORS))
def test_records_in_turn_give_what_fresh_estimators_give(name):
    _, dm, _, data, prior = oscillator_case(60)
    other = data.with_columns(**{n: np.asarray(data[n]) * 0.5 for n in dm.model.output_names if n in data})
    est = ESTIMATORS[name](dm, 0.05, [0.04, 0.09], options=FAST.get(name, {}))
    runs = [est.filter(d, prior, seed=3) for d in (data, other, data)]
    for d, got in zip((data, other, data), runs):
        fresh = ESTIMATORS[name](dm, 0.05, [0.04, 0.09], options=FAST.get(name, {})).filter(d, prior, seed=3)
        for a, b in zip(_fields(got), _fields(fresh)):
            np.testing.assert_array_equal(a, b)
    assert not np.array_equal(runs[0].x, runs[1].x)


def test_prepared_arrays_are_read_only_and_follow_the_record():
    _, dm, _, data, _ = oscillator_case(20)
    est = cs.KF(dm, 0.05, [0.04, 0.09])
    first = est.prepare(data)
    for k in ("u_prev", "u", "y", "mask", "dt", "gate"):
        assert not first[k].flags.writeable, k
    again = est.prepare(data)
    assert again["y"] is first["y"]                      # the same record: reused
    shifted = cs.Dataset(data.t + 1.0, {n: data[n] for n in data.names})
    assert est.prepare(shifted)["y"] is not first["y"]   # another record: checked again
    with pytest.raises(ValueError, match="not finite at row 3"):
        est.prepare(data.with_columns(**{dm.model.input_names[0]: np.where(np.arange(20) == 3, np.nan, 0.0)})
                    if dm.model.nu else cs.Dataset(data.t, {}))


def test_a_bad_start_is_refused_after_good_ones():
    m = cs.models.kvlcc2()
    dm = cs.discretize(m, 1.0)
    t = np.arange(5.0)
    data = cs.Dataset(t, {**{n: np.full(5, v) for n, v in zip(m.input_names, m.inputs())},
                          **{n: np.zeros(5) for n in m.output_names}})
    ekf = cs.EKF(dm, np.eye(m.nw) * 1e-4, np.eye(len(m.output_names)) * 1e-2)
    moving = np.zeros(m.nx)
    moving[m.state_names.index("u")] = 7.0
    ekf.filter(data, cs.Gaussian(moving, np.ones(m.nx)))
    ekf.filter(data, cs.Gaussian(moving, np.ones(m.nx)))
    with pytest.raises(ValidityError, match="cannot start"):
        ekf.filter(data, cs.Gaussian(np.zeros(m.nx), np.ones(m.nx)))
