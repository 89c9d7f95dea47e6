"""A newcomer's and an adversary's probe of the library: each case below once gave a silently wrong
result, a crash or an unclear error (the docstrings say what happened before, and what happens now)."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship.cli import main

from cli_checks import one_line_error as _error


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
    _error(capsys, [*base, "--measured", ""], "--measured: an empty value names nothing")
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


# -- casship design-trial ---------------------------------------------------------------------------------------
DESIGN = ["design-trial", "--model", "kvlcc2", "--sigma", "psi=0.0035", "--dt", "4", "--zigzag", "20", "--pullout", "",
          "--no-spiral"]


def test_design_trial_refuses_what_it_misread_or_crashed_on(tmp_path, capsys):
    """Before: ``--prior-std N_r_dash=0.01,N_r_dash=0.02`` used the second value (its own pair parser);
    no candidate at all crashed with an IndexError (exit 1); ``--max-iter 0`` ran and wrote a sequence
    "Maximum_Iterations_Exceeded, 0 iterations"; ``--csv`` with ``--no-free`` was ignored, so was one
    path for ``--csv`` and ``--plot``."""
    base = [*DESIGN, "--prior-std", "N_r_dash=0.01"]
    _error(capsys, [*DESIGN, "--prior-std", "N_r_dash=0.01,N_r_dash=0.02", "--no-free"],
           "--prior-std: 'N_r_dash' given more than once")
    _error(capsys, [*base, "--no-free", "--turning", "", "--zigzag", ""], "no candidate trials and no free trial")
    _error(capsys, [*base, "--max-iter", "0"], "--max-iter: must be a whole number >= 1, got 0")
    _error(capsys, [*base, "--no-free", "--csv", str(tmp_path / "a.csv")], "--csv would have no effect: --no-free")
    same = str(tmp_path / "b.png")
    _error(capsys, [*base, "--csv", same, "--plot", same], "--csv and --plot name the same path")
    assert not list(tmp_path.iterdir())


def test_design_trial_writes_no_file_unasked_and_reads_a_likelihood_fit(tmp_path, capsys, monkeypatch):
    """Before: every run wrote ``free_trial.csv`` into the working folder, so the second run there
    failed ("file exists"); a fit file of ``casship identify`` (maximum likelihood: its noise is
    ``R``) was refused as holding no output noise, so the documented ``--params fit.json`` failed on
    the getting-started fit. Now the CSV is written with ``--csv`` only, and a likelihood fit's R
    gives the noise of one sample (sqrt of its diagonal)."""
    from casship.design import fit_noise
    from casship.identify import FitResult

    monkeypatch.chdir(tmp_path)
    run = [*DESIGN, "--prior-std", "N_r_dash=0.01", "--duration", "200", "--max-iter", "3"]
    for _ in range(2):
        assert main(run) == 0
        assert "--csv FILE writes its rudder sequence" in capsys.readouterr().out
    assert not list(tmp_path.iterdir())
    fit = FitResult.from_dict({"model": "kvlcc2", "params": {}, "free": [], "estimates": {}, "std_errors": {},
                               "noise": {"R": {"psi": 4e-6, "r": 1e-10}}})
    assert fit_noise(fit) == pytest.approx({"psi": 2e-3, "r": 1e-5})


def test_solver_failures_of_the_free_trial_are_one_line_errors():
    """Before: ``--corridor 1`` ended after a minute as "internal error (a bug in casship):
    FreeTrialError" (a bare RuntimeError). Now it is casship's SolverError: one line, exit code 2."""
    from casship.cli import is_user_error
    from casship.design import FreeTrialError
    from casship.errors import SolverError

    assert issubclass(FreeTrialError, SolverError) and is_user_error(FreeTrialError("IPOPT failed"))


def test_help_shows_no_default_for_a_flag(capsys):
    """Before: ``--no-spiral  leave the spiral out (default: True)`` read as if the spiral were left
    out by default."""
    with pytest.raises(SystemExit):
        main(["design-trial", "--help"])
    out = capsys.readouterr().out
    assert "--no-spiral           leave the spiral out\n" in out and "(default: True)" not in out


# -- divergence, sizes and settings of the closed loop and the simulator ----------------------------------------
def test_a_diverging_run_is_a_one_line_error(capsys):
    """Before: ``casship simulate --dt 100 --allow-out-of-range`` and ``casship autopilot --dt 1000``
    (or ``--wind 1e6 0``) ended as "internal error (a bug in casship): FloatingPointError". Now the
    divergence is casship's DivergenceError (a SolverError, still a FloatingPointError), one line
    naming the time and what to check."""
    from casship.errors import DivergenceError, SolverError

    assert issubclass(DivergenceError, SolverError) and issubclass(DivergenceError, FloatingPointError)
    _error(capsys, ["simulate", "--model", "kvlcc2", "--dt", "100", "--allow-out-of-range"],
           "simulation of 'kvlcc2' diverged at t = 400 s")
    _error(capsys, ["autopilot", "--model", "kvlcc2", "--wind", "1e6", "0"],
           "closed loop of 'kvlcc2+wind' diverged at t = 0.2 s", "check dt, wind and current")


@pytest.mark.parametrize("option", [["--t-end", "1e9"], ["--segment", "1e9"], ["--dt", "1e-6"]])
def test_a_closed_loop_too_long_for_memory_is_refused(capsys, option):
    """Before: MemoryError ("Unable to allocate 37.3 GiB"), reported as an internal error."""
    _error(capsys, ["autopilot", "--model", "kvlcc2", *option], "closed loop: ", "casship.data.MAX_ROWS")


def test_autopilot_settings_beyond_the_ship(capsys):
    """Before: ``--steer-max 100`` (rad: 5730 deg) ran with the rudder allowed far past its stop;
    ``--scenario rot-1e6`` ran a turn the reference model silently held to r_max (25.7 deg/min)."""
    _error(capsys, ["autopilot", "--model", "kvlcc2", "--steer-max", "100"],
           "steer_max = 100 rad (5730 deg) is beyond the valid range [-35, 35] deg (rudder stop) of 'delta'")
    _error(capsys, ["autopilot", "--model", "kvlcc2", "--scenario", "rot-1e6"],
           "the rate of turn 1e+06 deg/min is above the preset rate of turn r_max = 25.7 deg/min")


@pytest.mark.parametrize("argv, text", [
    (["simulate", "--model", "nomoto1"], "--model nomoto1: has no vessel"),
    (["simulate", "--model", "otter"], "--model otter: steers with its propellers ['n1', 'n2'], not a rudder"),
    (["design-trial", "--model", "sog-cog", "--prior-std", "K=0.1", "--sigma", "chi=0.1"], "--model sog-cog: has no vessel"),
    (["autopilot", "--model", "nomoto2"], "--model nomoto2: has no vessel"),
])
def test_a_model_the_command_cannot_run_names_those_it_can(capsys, argv, text):
    """Before: "model 'nomoto1' has no vessel ...; build it with ModelBuilder.vessel = casship.Vessel(...)"
    (simulate, design-trial) and "give steer" (autopilot): advice a command-line user cannot follow,
    for models that ``casship simulate --list`` lists. Now the error names the registered ships."""
    err = _error(capsys, argv, text, "registered: ['kvlcc2', 'kvlcc2-l7', 'mariner', 'mmg-twin-lowspeed'")
    assert ("'otter'" in err) == (argv[0] == "autopilot")      # a twin-propeller craft has an autopilot


# -- manoeuvres -------------------------------------------------------------------------------------------------
def test_manoeuvres_whose_hold_outlasts_the_record(capsys):
    """Before: ``--maneuver random --hold 1e9`` ran one constant rudder angle (9.6 deg) for the whole
    run and called it random; ``--maneuver pullout --hold 1e9`` never released the rudder and printed
    no metric, exit 0."""
    _error(capsys, ["simulate", "--model", "kvlcc2", "--maneuver", "random", "--hold", "1e9"],
           "hold 1e+09 s is not shorter than the record")
    _error(capsys, ["simulate", "--model", "kvlcc2", "--maneuver", "pullout", "--hold", "1e9"],
           "pull-out: the rudder would return at t = 1e+09 s, not before the end of the record")


def test_pullout_metrics_are_printed_as_text(capsys):
    """Before: the text output of a pull-out printed the approach and no metric (the JSON had two)."""
    assert main(["simulate", "--model", "kvlcc2-l7", "--maneuver", "pullout", "--dt", "0.05"]) == 0
    out = capsys.readouterr().out
    assert "yaw_rate_at_release_deg_s" in out and "residual_yaw_rate_deg_s" in out


def test_masked_inputs_are_refused_by_simulate():
    """Before: a masked rudder entry was simulated with the value hidden under the mask."""
    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, 10.0, 0.5)
    delta = np.ma.array(np.full(t.size, 0.1), mask=t == 1.5)
    with pytest.raises(ValueError, match=r"input 'delta' is masked at row 3 \(t = 1.5 s\)"):
        cs.simulate(m, m.states(), t, {"delta": delta})
    unmasked = cs.simulate(m, m.states(), t, {"delta": np.ma.array(np.full(t.size, 0.1))})
    np.testing.assert_array_equal(unmasked["r"], cs.simulate(m, m.states(), t, {"delta": 0.1})["r"])


# -- estimators: sizes and shapes -----------------------------------------------------------------------------------
def _nomoto_result():
    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, 20.0, 0.5)
    data = cs.measure(cs.simulate(m, m.states(), t, {"delta": 0.1}), m, {"psi": 0.01}, seed=1)
    ekf = cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4)
    return m, data, ekf, ekf.filter(data, cs.Gaussian(m.states(), [1e-2, 1e-4]))


def test_prediction_and_nees_check_their_sizes():
    """Before: ``ekf.predict(result, 1e9)`` allocated until the kernel killed the process (24 GB);
    ``result.nees`` of a wrong shape raised numpy's "operands could not be broadcast"."""
    from casship.errors import InputError

    m, data, ekf, res = _nomoto_result()
    with pytest.raises(InputError, match=r"EKF prediction: 1e\+09 s at steps of 0.5 s would make 2e\+09 rows"):
        ekf.predict(res, 1e9)
    with pytest.raises(InputError, match="the number of rows is not a number"):
        ekf.predict(res, float("nan"))
    assert ekf.predict(res, 5.0).t[-1] == pytest.approx(res.t[-1] + 5.0)
    with pytest.raises(ValueError, match=r"nees: x_true has shape \(3, 2\), the estimates \(40, 2\)"):
        res.nees(np.zeros((3, 2)))


def test_an_ensemble_too_large_for_memory_is_refused(monkeypatch):
    """Before: ``--estimator enkf --options members=10000000`` ran for two minutes and was killed by
    the kernel (out of memory)."""
    from casship.errors import InputError
    from casship.estimators import base

    m, data, _, _ = _nomoto_result()
    dm = cs.discretize(m, 0.5, "rk4")
    with pytest.raises(ValueError, match=r"option 'members' = 10000000 is more than 100000"):
        cs.EnKF(dm, Q=1e-8, R=1e-4, options={"members": 10_000_000})
    enkf = cs.EnKF(dm, Q=1e-8, R=1e-4, options={"members": 50})
    monkeypatch.setattr(base, "MAX_DRAWS", 1000)         # 40 steps x 100 draws
    with pytest.raises(InputError, match=r"EnKF: 40 steps x 100 random draws per step would need"):
        enkf.filter(data, cs.Gaussian(m.states(), [1e-2, 1e-4]), seed=1)


# -- records --------------------------------------------------------------------------------------------------------
def test_a_truncated_csv_row_is_refused(tmp_path):
    """Before: a row with fewer fields than the header was filled with NaN by pandas: a truncated
    heading read as "not measured", silently. An empty field (``a,,c``) still means not measured."""
    bad = tmp_path / "bad.csv"
    bad.write_text("t,psi,delta\n0,0.1,0\n1,0.2\n2,0.3,0\n")
    with pytest.raises(ValueError, match="bad.csv: line 3 has 2 field.s., the header 3: a truncated row"):
        cs.Dataset.from_csv(bad)
    good = tmp_path / "good.csv"
    good.write_text("t,psi,delta\n0,0.1,0\n1,,0\n2,0.3,0\n")
    assert np.isnan(cs.Dataset.from_csv(good)["psi"][1])


def test_too_few_samples_for_a_noise_estimate_say_so():
    """Before: "the noise of 'x' cannot be estimated from the record (a constant channel)" for a
    two-row record whose x was not constant."""
    m = cs.models.nomoto_first_order()
    data = cs.Dataset([0.0, 1.0], {"psi": [0.0, 0.5], "delta": [0.1, 0.1]})
    with pytest.raises(ValueError, match=r"noise of 'psi' .* \(only 2 measured sample\(s\), too few\)"):
        cs.noise_from_data(m, data, ["psi"])


def test_a_closed_pipe_is_not_an_error():
    """Before: ``casship cache info | head -1`` ended with "casship cache: error: [Errno 32] Broken pipe"."""
    import subprocess
    import sys

    code = ("import sys; from casship.cli import main; sys.stdout.close = lambda: None\n"
            "class Closed:\n"
            "    def write(self, s): raise BrokenPipeError(32, 'Broken pipe')\n"
            "    def flush(self): pass\n"
            "    def fileno(self): return sys.__stdout__.fileno()\n"
            "sys.stdout = Closed(); sys.exit(main(['cache', 'info']))")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 141 and "error" not in run.stderr, run.stderr


def test_filter_plot_shows_rates_in_degrees_and_is_not_flattened_by_the_prior(tmp_path, monkeypatch):
    """Before: the yaw rate was drawn in rad/s beside a heading in degrees, and the +-2 std band of a
    vague prior (+-2 rad/s on the first row) set the vertical range: the estimate of r looked like a
    flat zero line. Now rates are in deg/s and the range follows the estimate after the first rows."""
    from matplotlib.figure import Figure

    m, data, _, _ = _nomoto_result()
    ekf = cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4)
    res = ekf.filter(data, cs.Gaussian(m.states(), [1.0, 1.0]))
    figures = []
    monkeypatch.setattr(Figure, "savefig", lambda fig, *a, **k: figures.append(fig))
    res.plot(tmp_path / "r.png", measured={"psi": data["psi"]})
    ax_psi, ax_r = figures[0].axes
    assert ax_r.get_ylabel() == "r [deg/s]" and ax_psi.get_ylabel() == "psi [deg]"
    r_deg = np.degrees(res["r"])
    lo, hi = ax_r.get_ylim()
    assert lo <= r_deg[5:].min() and hi >= r_deg[5:].max()
    assert hi - lo < 0.1 * 4 * np.degrees(res.std[0, 1])      # far narrower than the prior's band
    assert "measured" in [t.get_text() for t in ax_psi.get_legend().get_texts()]


# -- outputs ----------------------------------------------------------------------------------------------------
def _unwritable_folder(tmp_path):
    """A folder nothing can be written into: read-only for a normal user; /proc for root (which
    permission bits do not stop)."""
    import os
    from pathlib import Path

    if hasattr(os, "geteuid") and os.geteuid() == 0:
        if not Path("/proc").is_dir():
            pytest.skip("running as root without /proc: no folder root cannot write into")
        return Path("/proc")
    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o500)
    return folder


def test_an_unwritable_output_folder_is_named_before_any_work(tmp_path, capsys):
    """Before: ``casship filter ... --out /proc/x.csv`` ran the filter and then failed with
    "[Errno 2] No such file or directory: '/proc/.x.partial-22137.csv'", naming a temporary file
    the user never gave (the same for demo --out and autopilot --plot). Now the option and the
    folder are named at the start."""
    from casship.outdir import check_output_file, check_output_folder

    folder = _unwritable_folder(tmp_path)
    with pytest.raises(PermissionError, match=f"--out {folder}/x.csv: cannot write into the folder {folder}"):
        check_output_file(folder / "x.csv")
    with pytest.raises(PermissionError, match=f"--plot {folder}/ap: cannot write into the folder {folder}"):
        check_output_folder(folder / "ap", what="--plot")
    _error(capsys, ["demo", "--quick", "--out", str(folder / "demo")], "cannot write into the folder")
    assert not [p for p in tmp_path.rglob(".casship-probe-*")]


def test_a_plot_is_written_in_the_format_its_name_says(tmp_path, capsys):
    """Before: ``--plot est.pdf`` wrote PNG data under the .pdf name (filter, simulate), and
    ``design-trial --plot o.xyz`` ended, after the work, as "internal error: ValueError: Format 'xyz'
    is not supported". Now .png, .pdf and .svg are written as such and any other name is refused first."""
    pdf = tmp_path / "turn.pdf"
    assert main(["simulate", "--model", "kvlcc2-l7", "--dt", "0.2", "--plot", str(pdf)]) == 0
    assert pdf.read_bytes()[:5] == b"%PDF-"
    capsys.readouterr()
    _error(capsys, ["simulate", "--model", "kvlcc2-l7", "--plot", str(tmp_path / "turn.xyz")],
           "a figure is written as .png, .pdf, .svg")
    _error(capsys, [*DESIGN, "--prior-std", "N_r_dash=0.01", "--no-free", "--plot", str(tmp_path / "o.xyz")],
           "--plot", "a figure is written as")
    m, data, ekf, res = _nomoto_result()
    assert res.plot(tmp_path / "est.svg").read_text().lstrip().startswith("<?xml")


def test_a_pandas_frame_indexed_by_time_and_a_file_that_is_no_result():
    """Before: ``Dataset.from_pandas(frame.set_index("t"))`` said "no time column 't'" (the index was
    never looked at); a frame with two ``psi`` columns failed further on without naming them."""
    import pandas as pd

    frame = pd.DataFrame({"t": [0.0, 1.0, 2.0], "psi": [0.1, 0.2, 0.3]})
    np.testing.assert_array_equal(cs.Dataset.from_pandas(frame.set_index("t"))["psi"], frame["psi"])
    with pytest.raises(ValueError, match=r"column\(s\) \['psi'\] appear more than once in the frame"):
        cs.Dataset.from_pandas(pd.DataFrame(np.ones((2, 3)), columns=["t", "psi", "psi"]))
    with pytest.raises(ValueError, match="no time column 'time' .nor an index of that name."):
        cs.Dataset.from_pandas(frame, time="time")


def test_loading_a_file_that_is_no_saved_result(tmp_path):
    """Before: ``FilterResult.load("run.csv")`` said "This file contains pickled (object) data..."."""
    path = tmp_path / "run.csv"
    path.write_text("t,psi\n0,1\n")
    with pytest.raises(ValueError, match=r"run.csv: not a saved FilterResult \(not a numpy .npz file\)"):
        cs.FilterResult.load(path)
