"""A newcomer's and an adversary's probe of the library: each case below once gave a silently wrong
result, a crash or an unclear error (the docstrings say what happened before, and what happens now)."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship.cli import main


def _error(capsys, argv, *texts):
    """The command ends with exit code 2 and one error line holding every one of ``texts``."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len([x for x in err.splitlines() if ": error: " in x]) == 1, err
    for text in texts:
        assert text in err, (text, err)
    return err


def _kvlcc2_record(tmp_path, n=120, **change):
    """A simulated KVLCC2 zig-zag record as CSV (1 s steps); ``change`` maps column -> (row, value)."""
    ship = cs.models.get_model("kvlcc2")
    t = np.arange(0.0, float(n))
    u0 = ship.vessel.U0
    delta = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 200.0) + 1e-9)
    n_prop = np.full(t.size, 1.7785)
    tr = cs.simulate(ship, ship.states(u=u0), t, {"delta": delta, "n": n_prop})
    data = cs.measure(tr, ship, {"x": 1.0, "y": 1.0, "psi": 1e-3}, seed=3)
    cols = {name: np.array(data[name]) for name in data.names}
    for name, (row, value) in change.items():
        cols[name][row] = value
    path = tmp_path / "run.csv"
    cs.Dataset(data.t, cols).to_csv(path)
    return path


# -- angles --------------------------------------------------------------------------------------------------
def test_wrap_keeps_an_infinite_angle_infinite():
    """Before: wrap(inf) was NaN with numpy's 'invalid value encountered in remainder', so an infinite
    heading in a record became "not measured" on the command line. Now it stays infinite, silently."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = cs.wrap(np.array([np.inf, -np.inf, np.nan, 3 * np.pi / 2]))
    assert out[0] == np.inf and out[1] == -np.inf and np.isnan(out[2])
    assert out[3] == pytest.approx(-np.pi / 2)


# -- casship filter ----------------------------------------------------------------------------------------------
def test_filter_refuses_an_infinite_heading(tmp_path, capsys):
    """Before: exit 0, the infinite heading of row 10 dropped as if not measured (and a numpy warning)."""
    path = _kvlcc2_record(tmp_path, psi=(10, np.inf))
    _error(capsys, ["filter", str(path), "--model", "kvlcc2", "--measured", "x,y,psi"],
           "measurement 'psi' is infinite at row 10")


def test_filter_option_values_that_were_misread(tmp_path, capsys):
    """Before: ``--measured ""`` measured every output in the file; ``--R-std x=-1`` was squared into a
    variance of 1; ``--x0 u=-5`` started a KVLCC2 astern, outside its range [0, 15.95] m/s."""
    path = str(_kvlcc2_record(tmp_path))
    base = ["filter", path, "--model", "kvlcc2"]
    _error(capsys, [*base, "--measured", ""], "--measured: no output named")
    _error(capsys, [*base, "--measured", "x,y,psi", "--R-std", "x=-1,y=1,psi=1"],
           "--R-std: a standard deviation must be positive, got {'x': -1.0}")
    _error(capsys, [*base, "--measured", "x,y,psi", "--x0", "u=-5"],
           "starting state (--x0 or the record) 'u' = -5 m/s is outside its valid range", "--allow-out-of-range")


def test_filter_bridges_a_gap_when_asked(tmp_path, capsys):
    """Before: a 62 s gap in a 1 s record was refused by the command's own step check (the Euler limit
    at the start), with or without ``--options on_gap=bridge``: the documented bridging was out of
    reach. Now the gap is the estimator's (checked at the state where it happens): refused by
    default, naming on_gap, and bridged with prediction-only rows when asked."""
    path = _kvlcc2_record(tmp_path, n=200)
    data = cs.io.read_record(path)
    keep = (data.t < 50) | (data.t > 110)
    cs.Dataset(data.t[keep], {n: data[n][keep] for n in data.names}).to_csv(tmp_path / "gap.csv")
    base = ["filter", str(tmp_path / "gap.csv"), "--model", "kvlcc2", "--measured", "x,y,psi", "--json"]
    _error(capsys, base, "time gap of 62 s between t = 49 and 111 s", "on_gap")
    assert main([*base, "--options", "on_gap=bridge"]) == 0
    out = capsys.readouterr()
    assert "bridged by 4 prediction-only row(s)" in out.err and '"loglik"' in out.out
