"""Datasets and trajectories: CSV and pandas round trips, derived records, errors."""
import numpy as np
import pandas as pd
import pytest

import casship as cs
from casship.data import check_time
from casship.gaussian import as_cov
from casship.models import nomoto_first_order


def record():
    t = np.array([0.0, 0.1, 0.25, 0.4, 1.0])
    return cs.Dataset(t, {"delta": [0.1, 0.2, -0.3, 1e-17, 2.5], "psi": [0.3, np.nan, -3.1, np.pi, np.nan]},
                      units={"delta": "rad", "psi": "rad"}, meta={"vessel": "test"})


def assert_same(a, b):
    np.testing.assert_array_equal(a.t, b.t)
    assert a.names == b.names
    for n in a.names:
        np.testing.assert_array_equal(a[n], b[n])          # NaN in the same places, values bit-exact


def test_csv_round_trip_is_exact(tmp_path):
    data = record()
    back = cs.Dataset.from_csv(data.to_csv(tmp_path / "rec.csv"))
    assert_same(data, back)
    assert back.meta["source"].endswith("rec.csv")


def test_pandas_round_trip_keeps_units():
    data = record()
    frame = data.to_pandas()
    assert list(frame.columns) == ["t", "delta", "psi"] and frame.attrs["units"]["psi"] == "rad"
    back = cs.Dataset.from_pandas(frame)
    assert_same(data, back)
    assert back.units == data.units


def test_from_csv_time_column_rename_and_scale(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("time,heading,rudder\n0.0,10.0,1.0\n0.5,20.0,2.0\n")
    data = cs.Dataset.from_csv(path, rename={"heading": "psi"}, scale={"psi": np.pi / 180})
    np.testing.assert_array_equal(data.t, [0.0, 0.5])
    np.testing.assert_allclose(data["psi"], np.radians([10.0, 20.0]), rtol=1e-15)
    assert data.names == ("psi", "rudder")


@pytest.mark.parametrize("text, kwargs, match", [
    ("a,b\n1,2\n", {}, "no 't' or 'time' column"),
    ("t,a\n0,1\n", {"rename": {"b": "c"}}, r"cannot rename unknown column\(s\) \['b'\]"),
    ("t,a\n0,x\n1,y\n", {}, r"non-numeric column\(s\) \['a'\]"),
    ("t,a\n0,1\n0,2\n", {}, "must increase strictly; row 1"),
    ("t,a\n0,1\n,2\n", {}, "non-finite time stamp at row 1"),
    ("t,a\n0,1\n", {"time": "clock"}, "no time column 'clock'"),
])
def test_from_csv_errors(tmp_path, text, kwargs, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        cs.Dataset.from_csv(path, **kwargs)


@pytest.mark.parametrize("make, match", [
    (lambda: cs.Dataset([0, 1], {"a": [1, 2, 3]}), "column 'a' has 3 rows, time has 2"),
    (lambda: cs.Dataset([0, 1], {"t": [1, 2]}), "column name 't' is reserved"),
    (lambda: cs.Dataset([0, 1], {"": [1, 2]}), "must be a non-empty string"),
    (lambda: cs.Dataset([1, 0], {"a": [1, 2]}), "must increase strictly"),
    (lambda: record()["speed"], "unknown column 'speed'"),
    (lambda: record().matrix(["delta", "psi"], finite=True, what="input"), r"input 'psi' is not finite at row 1"),
    (lambda: record().between(5.0, 6.0), "no samples between"),
])
def test_dataset_errors(make, match):
    with pytest.raises(ValueError, match=match):
        make()


def test_derived_records_and_read_only_columns():
    data = record()
    assert len(data) == 5 and "psi" in data and "x" not in data
    np.testing.assert_array_equal(data["t"], data.t)
    np.testing.assert_allclose(data.dt, np.diff(data.t))
    with pytest.raises(ValueError):
        data["psi"][0] = 1.0
    more = data.with_columns(r=np.zeros(5))
    assert more.names == ("delta", "psi", "r") and data.names == ("delta", "psi")
    assert data.select(["psi"]).names == ("psi",)
    part = data.between(0.1, 0.4)
    np.testing.assert_array_equal(part.t, [0.1, 0.25, 0.4])
    assert data.slice(1, 3).meta == data.meta


def test_trajectory_round_trips_keep_the_names(tmp_path):
    m = nomoto_first_order()
    traj = cs.simulate(m, m.states(r=0.01), np.arange(0.0, 5.0, 0.5), {"delta": 0.1})
    frame = traj.to_pandas()
    back = cs.Trajectory.from_pandas(frame)
    assert isinstance(back, cs.Trajectory) and back.model_name == "nomoto1"
    assert back.state_names == ("psi", "r") and back.input_names == ("delta",) and back.output_names == ("psi",)
    np.testing.assert_array_equal(back.x, traj.x)
    from_csv = cs.Trajectory.from_csv(traj.to_csv(tmp_path / "traj.csv"), model=m)
    np.testing.assert_array_equal(from_csv.x, traj.x)
    np.testing.assert_array_equal(from_csv.u, traj.u)
    part = traj.slice(2, 5)
    assert isinstance(part, cs.Trajectory) and part.x.shape == (3, 2)
    with pytest.raises(ValueError, match="needs model="):
        cs.Trajectory.from_csv(tmp_path / "traj.csv")
    with pytest.raises(ValueError, match="carries no state names"):
        cs.Trajectory.from_pandas(pd.DataFrame({"t": [0.0, 1.0], "psi": [0.0, 0.1]}))
    with pytest.raises(ValueError, match=r"no column\(s\) \['delta'\]"):
        cs.Trajectory.from_dataset(traj.select(["psi", "r"]), m)


def test_check_time_and_covariances():
    np.testing.assert_array_equal(check_time([0, 1, 2.5]), [0.0, 1.0, 2.5])
    np.testing.assert_array_equal(as_cov(2.0, 2, "Q"), 2.0 * np.eye(2))
    np.testing.assert_array_equal(as_cov([1.0, 3.0], 2, "Q"), np.diag([1.0, 3.0]))
    np.testing.assert_array_equal(as_cov({"b": 3.0, "a": 1.0}, 2, "Q", ["a", "b"]), np.diag([1.0, 3.0]))
    for value, match in (([[1.0, 2.0], [0.0, 1.0]], "not symmetric"), ([-1.0, 1.0], "not positive semi-definite"),
                         ([1.0, np.nan], "non-finite"), ([1.0, 2.0, 3.0], "expected 2 variances"),
                         ({"a": 1.0}, r"no variance given for channel\(s\) \['b'\]"),
                         ({"a": 1.0, "b": 1.0, "c": 1.0}, r"unknown channel name\(s\) \['c'\]")):
        with pytest.raises(ValueError, match=match):
            as_cov(value, 2, "Q", ["a", "b"])
    with pytest.raises(ValueError, match="not symmetric"):           # small scales (rad^2 of lat/lon) too
        as_cov([[1e-14, 5e-15], [0.0, 1e-14]], 2, "R")
    np.testing.assert_array_equal(as_cov([[1e-14, 0.0], [0.0, 2e-14]], 2, "R"), np.diag([1e-14, 2e-14]))
    with pytest.raises(ValueError, match="R: must be positive definite"):
        as_cov([1.0, 0.0], 2, "R", allow_zero=False)


def test_covariance_check_is_unit_free_and_names_the_channel():
    # a smooth yaw-rate record (1e-12 rad^2/s^2) beside a position in metres (6 m^2) is definite
    mixed = as_cov({"r": 1.1e-12, "x": 6.3}, 2, "R", ["r", "x"], allow_zero=False)
    np.testing.assert_array_equal(mixed, np.diag([1.1e-12, 6.3]))
    with pytest.raises(ValueError, match="R: must be positive definite \\(the variance of 'x' is 0\\)"):
        as_cov({"r": 1.0, "x": 0.0}, 2, "R", ["r", "x"], allow_zero=False)
    with pytest.raises(ValueError, match="Q: not positive semi-definite \\(the variance of 'b' is -1"):
        as_cov([1.0, -1.0], 2, "Q", ["a", "b"])
    with pytest.raises(ValueError, match="'a' has variance 0 but covaries with 'b'"):
        as_cov([[0.0, 1e-3], [1e-3, 1.0]], 2, "Q", ["a", "b"])
    with pytest.raises(ValueError, match="exactly correlated"):     # rank one in any units
        as_cov([[1e-12, 2.5e-6], [2.5e-6, 6.25]], 2, "R", allow_zero=False)
    assert np.linalg.matrix_rank(as_cov([[1e-12, 2.5e-6], [2.5e-6, 6.25]], 2, "Q")) == 1   # semi-definite: allowed


def test_gaussian_sampling_is_seeded():
    g = cs.Gaussian([1.0, -1.0], [[2.0, 0.5], [0.5, 1.0]])
    np.testing.assert_array_equal(g.sample(5, seed=3), g.sample(5, seed=3))
    s = g.sample(20000, seed=1)
    np.testing.assert_allclose(np.cov(s.T), g.cov, atol=0.06)
    np.testing.assert_allclose(g.std, np.sqrt([2.0, 1.0]))
    with pytest.raises(ValueError, match="mean contains non-finite"):
        cs.Gaussian([np.nan], 1.0)


# -- decimate and resample -----------------------------------------------------------------------------
def test_decimate_keeps_every_kth_row_and_the_type():
    m = cs.models.nomoto_first_order()
    tr = cs.simulate(m, m.states(), np.arange(0.0, 10.0, 0.5), {"delta": 0.1})
    d = tr.decimate(4)
    assert isinstance(d, cs.Trajectory) and d.state_names == tr.state_names
    np.testing.assert_array_equal(d.t, [0.0, 2.0, 4.0, 6.0, 8.0])
    np.testing.assert_array_equal(d["r"], tr["r"][::4])
    assert d.decimate(2).meta["decimated"] == 8
    assert tr.decimate(1) is tr
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="decimate: k must be an integer >= 1"):
            tr.decimate(bad)
    with pytest.raises(ValueError, match="leaves 1 row"):
        tr.decimate(100)


def test_resample_inserts_unmeasured_rows_and_holds_inputs():
    d = cs.Dataset([0.0, 1.0, 2.5], {"delta": [0.1, 0.2, 0.3], "psi": [0.0, 0.5, 1.0]})
    r = d.resample(2.0, hold=["delta"])
    np.testing.assert_array_equal(r.t, [0.0, 0.5, 1.0, 1.5, 2.0, 2.5])
    np.testing.assert_array_equal(r["delta"], [0.1, 0.1, 0.2, 0.2, 0.2, 0.3])
    np.testing.assert_array_equal(np.isnan(r["psi"]), [False, True, False, True, True, False])
    np.testing.assert_array_equal(r["psi"][~np.isnan(r["psi"])], d["psi"])       # every sample kept


def test_resample_refuses_what_would_drop_samples_or_is_not_a_rate():
    d = cs.Dataset(np.arange(0.0, 10.0, 0.1), {"psi": np.zeros(100)})
    with pytest.raises(ValueError, match=r"rate 2 Hz is below the record's rate 10 Hz .* use decimate"):
        d.resample(2.0)
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="rate must be a positive finite number"):
            d.resample(bad)
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['delta'\] in hold"):
        d.resample(20.0, hold=["delta"])
