"""Nothing silently wrong, nothing lost: every case below once gave a wrong result, lost a file, or
crashed (the docstrings say what happened before); now each gets a clear error or the right answer."""
from __future__ import annotations

import io
import json
import subprocess
import sys

import numpy as np
import pytest

import casship as cs
from casship.cli import is_user_error, main
from casship.errors import CasshipError, InputError, SolverError
from casship.outdir import output_file, output_folder

from cli_checks import one_line_error as _error


def _nomoto_record(n=120):
    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, n * 0.5, 0.5)
    tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 10))})
    return m, cs.measure(tr, m, {"psi": 0.01}, seed=2)


# -- inputs ignored or misread ----------------------------------------------------------------------------------
def test_masked_measurements_are_not_measured_and_masked_inputs_refused():
    """Before: the mask of a masked array passed to update was ignored (the hidden value was used)."""
    m, data = _nomoto_record()
    ekf = cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4)
    prior = cs.Gaussian(m.states(), np.diag([1e-2, 1e-4]))
    a, b = ekf.online(prior, u=[0.1]), ekf.online(prior, u=[0.1])
    a.update(np.ma.array([5.0], mask=[True]), 0.5)
    b.update(np.array([np.nan]), 0.5)
    np.testing.assert_array_equal(a.x, b.x)
    with pytest.raises(ValueError, match=r"u is masked for \['delta'\]"):
        a.update([0.1], 0.5, u=np.ma.array([0.1], mask=[True]))
    masked = cs.Dataset(data.t, {"delta": data["delta"], "psi": np.ma.array(data["psi"], mask=data.t > 30)})
    assert np.isnan(masked["psi"][data.t > 30]).all() and np.isfinite(masked["psi"][data.t <= 30]).all()
    with pytest.raises(ValueError, match="masked time stamp at row 1"):
        cs.Dataset(np.ma.array([0.0, 1.0], mask=[False, True]), {"psi": [0.0, 0.1]})


def test_repeated_names_and_columns_are_refused(tmp_path):
    """Before: a CSV with two psi columns used the first; measured=["psi", "psi"] used each sample twice."""
    path = tmp_path / "dup.csv"
    path.write_text("t,psi,delta,psi\n0,0.1,0,0.2\n1,0.2,0,0.3\n")
    with pytest.raises(ValueError, match=r"column\(s\) \['psi'\] appear more than once in the header"):
        cs.io.read_record(path)
    m = cs.models.nomoto_first_order()
    with pytest.raises(ValueError, match=r"measured output\(s\) \['psi'\] given more than once"):
        cs.EKF(cs.discretize(m, 0.5), Q=1e-8, R=[1e-4, 1e-4], measured=["psi", "psi"])


def test_parameters_outside_their_physical_range_are_refused(tmp_path, capsys):
    """Before: N_r_dash = nan gave all-NaN estimates; nabla = -1 gave a 1339 m turning circle."""
    ship = cs.models.get_model("kvlcc2")
    with pytest.raises(InputError, match="parameter 'N_r_dash' = nan of model 'kvlcc2' is not finite"):
        ship.params({"N_r_dash": np.nan})
    with pytest.raises(InputError, match=r"parameter 'nabla' = -1 m\^3 of model 'kvlcc2' is outside its valid range"):
        ship.params(nabla=-1.0)
    fit = tmp_path / "bad.json"
    fit.write_text(json.dumps({"model": "kvlcc2", "params": {"nabla": -1}}))
    _error(capsys, ["simulate", "--model", "kvlcc2", "--params", str(fit)], "parameter 'nabla' = -1 m^3")


def test_options_that_do_nothing_are_refused(tmp_path, capsys):
    """Before: filter --dt 1e6 and --method rk4 --dt 300 had no effect and were echoed in the summary;
    a one-row replay reported RMSE 0."""
    m, data = _nomoto_record()
    path = tmp_path / "run.csv"
    data.to_csv(path)
    _error(capsys, ["filter", str(path), "--model", "nomoto1", "--dt", "1e6"], "--dt would have no effect")
    _error(capsys, ["filter", str(path), "--model", "nomoto1", "--method", "rk4", "--dt", "300"],
           "--dt would have no effect")
    _error(capsys, ["filter", str(path), "--model", "nomoto1", "--options", "gate=abc"], "option 'gate' is a number")
    _error(capsys, ["filter", str(path), "--model", "nomoto1", "--options", "max_gap=inf"],
           "option 'max_gap' is a positive time")           # an infinite limit would check no gap
    one = tmp_path / "one.csv"
    data.slice(0, 1).to_csv(one)
    _error(capsys, ["simulate", "--model", "nomoto1", "--inputs", str(one)], "the record has 1 row(s)")
    _error(capsys, ["simulate", "--model", "nomoto1", "--inputs", str(path), "--rudder-deg", "10"],
           "--rudder-deg would have no effect")


# -- files lost -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv", [["filter", "RUN", "--model", "nomoto1", "--out", "X.png", "--plot", "X.png"],
                                  ["simulate", "--model", "nomoto1", "--csv", "X.png", "--plot", "X.png"]])
def test_two_outputs_on_one_path_are_refused(tmp_path, capsys, argv):
    """Before: the CSV was written and then replaced by the PNG."""
    m, data = _nomoto_record()
    data.to_csv(tmp_path / "run.csv")
    argv = [a.replace("RUN", str(tmp_path / "run.csv")).replace("X.png", str(tmp_path / "x.png")) for a in argv]
    _error(capsys, argv, "name the same path")
    assert not (tmp_path / "x.png").exists()


def test_a_file_that_appears_while_a_run_writes_is_never_replaced(tmp_path):
    """Before: a fit file written while identify --out fit.json ran was overwritten."""
    target = tmp_path / "fit.json"
    with pytest.raises(FileExistsError, match="it changed while casship was running"):
        with output_file(target) as tmp:
            tmp.write_text("casship's result")
            target.write_text("someone else's file")
    assert target.read_text() == "someone else's file"
    kept = [p for p in tmp_path.iterdir() if p.name.startswith(".fit.partial")]
    assert len(kept) == 1 and kept[0].read_text() == "casship's result"       # the result is not lost either


def test_a_file_created_in_a_report_folder_while_it_runs_is_kept(tmp_path):
    """Before: a file created in the demo's report folder while it ran was deleted with the folder."""
    with output_folder(tmp_path / "report") as folder:
        (folder / "a.md").write_text("old")
    with pytest.raises(FileExistsError, match="it changed while casship was running"):
        with output_folder(tmp_path / "report", overwrite=True) as folder:
            (folder / "a.md").write_text("new")
            (tmp_path / "report" / "notes.txt").write_text("the user's notes")
    assert (tmp_path / "report" / "notes.txt").read_text() == "the user's notes"


# -- crashes ----------------------------------------------------------------------------------------------------
def test_size_caps_before_memory_runs_out(capsys):
    """Before: Dataset.resample(1e7) on a 200 s record exhausted memory; simulate --duration 1e9 ended in a
    traceback."""
    d = cs.Dataset(np.arange(0.0, 200.0, 1.0), {"psi": np.zeros(200)})
    with pytest.raises(InputError, match=r"resample: 199 s at 1e\+07 Hz would make 1.99e\+09 rows"):
        d.resample(1e7)
    _error(capsys, ["simulate", "--model", "kvlcc2", "--duration", "1e9"], "would make", "rows")


# -- errors: casship's own, or a bug ------------------------------------------------------------------------------
def test_only_casships_own_errors_are_one_line_user_errors(monkeypatch, capsys):
    """Before: TypeError, KeyError and RuntimeError were reported as one-line user errors, hiding bugs."""
    assert issubclass(InputError, ValueError) and issubclass(SolverError, RuntimeError)
    assert issubclass(cs.simulation.ValidityError, CasshipError)
    assert is_user_error(InputError("x")) and is_user_error(FileNotFoundError("x"))
    for exc in (TypeError("x"), KeyError("x"), RuntimeError("x"), ZeroDivisionError()):
        assert not is_user_error(exc)
    try:
        np.zeros(2).reshape(3)             # a ValueError from inside NumPy is a bug, not the user's
    except ValueError as exc:
        assert not is_user_error(exc)
    from casship.cli import cmd_cache

    def broken(args):
        return {}["missing"]

    monkeypatch.setattr(cmd_cache, "run", broken)
    assert main(["cache", "info"]) == 1
    err = capsys.readouterr().err
    assert "casship cache: internal error (a bug in casship): KeyError: 'missing'" in err and "--debug" in err
    with pytest.raises(KeyError):
        main(["cache", "info", "--debug"])


def test_help_and_argument_errors_do_not_load_numpy_or_casadi():
    """Before: every command took 3-5 s before it did anything, --help included (imports)."""
    code = ("import sys\nfrom casship.cli import main\n"
            "for argv in (['--help'], ['filter', '--help'], ['simulate', '--bogus']):\n"
            "    try:\n        main(argv)\n    except SystemExit:\n        pass\n"
            "print(sorted(m for m in ('numpy', 'casadi', 'scipy', 'matplotlib', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_progress_is_shown_while_one_long_call_runs(monkeypatch):
    """Before: the first identify was silent for about 30 s while it compiled."""
    from casship.progress import activity

    monkeypatch.setenv("CASSHIP_PROGRESS", "1")
    stream = io.StringIO()
    with activity("casship: compiling f to C", stream=stream, every=0.01):
        pass
    assert "casship: compiling f to C" in stream.getvalue()
    monkeypatch.setenv("CASSHIP_PROGRESS", "0")
    quiet = io.StringIO()
    with activity("x", stream=quiet):
        pass
    assert quiet.getvalue() == ""


def test_one_json_writer_keeps_non_finite_values_apart():
    from casship.io.jsonfile import dumps

    assert json.loads(dumps({"a": np.float64(np.nan), "b": [np.inf, -np.inf], "c": np.int64(3)})) == \
        {"a": "nan", "b": ["inf", "-inf"], "c": 3}
    with pytest.raises(TypeError, match="cannot write a object as JSON"):
        dumps({"x": object()})


def test_building_an_mpc_prints_no_banner(capfd):
    """Before: building an MPC printed the qpOASES licence banner on standard output."""
    from casship import autopilot as ap
    from casship.autopilot.mpc import MPCAutopilot

    MPCAutopilot(ap.Nomoto(K=0.185, T=107.3), period=5.0, horizon=10, steer_max=0.6, rate_max=0.04, r_max=0.02)
    assert "qpOASES" not in capfd.readouterr().out


def test_a_stable_ship_loop_gives_no_badly_conditioned_warning():
    """Before: every KVLCC2 autopilot printed scipy's "Badly conditioned filter coefficients" beside
    "closed loop stable: True" (the stability came from a transfer function)."""
    import warnings

    from casship import autopilot as ap

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        design = ap.design_autopilot(cs.models.get_model("kvlcc2"))
    assert design.margins["closed_loop_stable"] is True


def test_identify_and_simulate_options_without_effect_are_refused(tmp_path, capsys):
    m, data = _nomoto_record()
    path = tmp_path / "run.csv"
    data.to_csv(path)
    base = ["identify", str(path), "--model", "nomoto1", "--free", "K", "--out", str(tmp_path / "fit.json")]
    _error(capsys, base + ["--method", "oe", "--R", "psi=1e-4"], "--R would have no effect")
    _error(capsys, base + ["--sigma", "psi=0.01"], "--sigma would have no effect")
    _error(capsys, base + ["--prior-weight", "2"], "--prior-weight would have no effect")
    _error(capsys, base + ["--free", "K,K"], "['K'] given more than once")
    _error(capsys, ["simulate", "--model", "kvlcc2", "--hold", "100"], "--hold would have no effect")
    _error(capsys, ["simulate", "--model", "kvlcc2", "--seed", "3"], "--seed would have no effect")


@pytest.mark.parametrize("argv, text", [
    (["simulate", "--model", "kvlcc2", "--maneuver", "random", "--seed", "-1"], "a seed is a whole number >= 0"),
    (["study", "kvlcc2-maneuvers", "--workers", "-3"], "must be a whole number >= 1, got -3"),
    (["identify", "x.csv", "--model", "nomoto1", "--free", "K", "--max-iter", "0"], "must be a whole number >= 1"),
])
def test_counts_and_seeds_are_checked_at_the_door(capsys, argv, text):
    """Before: a negative seed ended in NumPy's "expected non-negative integer" (a bug report); --workers -3
    was accepted."""
    _error(capsys, argv, text)
