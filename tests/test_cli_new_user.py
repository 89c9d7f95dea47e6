"""The command line as a new user meets it: the registered ships, plausible mistakes on the measured records,
and errors that name the offending option, record or channel (no raw message, no option the command lacks)."""
from __future__ import annotations

import numpy as np
import pytest

from casship.cli import main

from cli_checks import one_line_error


# -- autopilot -------------------------------------------------------------------------------------------------
def test_autopilot_designs_for_the_model_scale_ship_it_lists(capsys):
    """Before: the trim started the propeller at 1 rps (no stated rate n0 for the model) and ended on the
    reversed root, n = -8.8 1/s: every autopilot command on kvlcc2-l7 stopped with a validity error."""
    assert main(["autopilot", "--model", "kvlcc2-l7", "--show-defaults", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "speed = 1.18 m/s" in out


def test_a_validity_error_does_not_offer_an_option_the_command_lacks(capsys):
    """Before: '... pass check_limits=False (command line: --allow-out-of-range)', an option autopilot refuses."""
    err = one_line_error(capsys, ["autopilot", "--model", "kvlcc2", "--speed", "100", "--quiet"],
                         "state 'u' = 100 m/s", "validity ranges")
    assert "--allow-out-of-range" not in err and "check_limits" not in err


def test_an_unknown_scenario_names_the_option_and_every_kind(capsys):
    """Before: "unknown scenario 'turn-20'; use course-A, step-A (A in degrees) or rot-R (R in deg/min)", after
    the design, without the option and without track."""
    one_line_error(capsys, ["autopilot", "--model", "kvlcc2", "--scenario", "turn-20", "--quiet"],
                   "--scenario turn-20: unknown scenario", "course-A", "step-A", "rot-R", "or track")


# -- design-trial ------------------------------------------------------------------------------------------------
DESIGN = ["design-trial", "--model", "kvlcc2", "--prior-std", "N_r_dash=0.01", "--sigma", "psi=0.003", "--no-free",
          "--quiet"]


def test_design_trial_rudder_angle_beyond_the_stop_names_the_option(capsys):
    """Before: "input 'delta' = 80 deg is outside its valid range ... (command line: --allow-out-of-range)"."""
    err = one_line_error(capsys, [*DESIGN, "--turning", "80"], "--turning", "80", "rudder stop 35 deg")
    assert "--allow-out-of-range" not in err


@pytest.mark.parametrize("option", ["--speed", "--dt", "--duration", "--knot", "--corridor", "--rudder-rate-deg-s"])
def test_design_trial_a_non_positive_value_names_the_option(option, capsys):
    """Before: 'approach speed must be a positive number [m/s], got -3.0' (the API's keyword, not the option)."""
    one_line_error(capsys, [*DESIGN, option, "-3"], f"argument {option}: must be a positive number")


def test_design_trial_prior_std_for_a_parameter_the_fit_estimated_names_the_option(tmp_path, capsys):
    """Before: "extra_std given for ['N_r_dash'], which the fit estimated" (the API's keyword, not --prior-std)."""
    rec = _kvlcc2_record(tmp_path / "run.csv", 1.53)
    fit = tmp_path / "fit.json"
    main(["identify", str(rec), "--model", "kvlcc2", "--free", "N_r_dash", "--measured", "psi,r", "--R",
          "psi=1e-6,r=1e-8", "--max-iter", "2", "--no-loo", "--out", str(fit), "--quiet"])
    capsys.readouterr()
    assert fit.exists()
    one_line_error(capsys, ["design-trial", "--model", "kvlcc2", "--params", str(fit), "--prior-std", "N_r_dash=0.01",
                            "--no-free", "--quiet"], "--prior-std: ['N_r_dash'] estimated by the fit")


# -- identify: the records checked against the model's validity ranges, as filter and simulate do ---------------
def _kvlcc2_record(path, n: float):
    """A short straight run of kvlcc2 columns with propeller rate ``n`` [1/s], as a CSV."""
    import numpy as np

    import casship as cs

    t = np.arange(0.0, 20.0, 0.5)
    cols = {"u": np.full(t.size, 7.97), "v": np.zeros(t.size), "r": np.zeros(t.size), "x": 7.97 * t,
            "y": np.zeros(t.size), "psi": np.zeros(t.size), "delta": np.zeros(t.size), "n": np.full(t.size, n)}
    return cs.Dataset(t, cols).to_csv(path)


def test_identify_refuses_a_record_outside_the_models_ranges_naming_it(tmp_path, capsys):
    """Before: the fit ran (a model-scale propeller rate on the full-scale ship) and ended in nonsense."""
    rec = _kvlcc2_record(tmp_path / "model_scale.csv", 10.23)
    err = one_line_error(capsys, ["identify", str(rec), "--model", "kvlcc2", "--free", "N_r_dash", "--out",
                                  str(tmp_path / "fit.json"), "--quiet"],
                         "record model_scale.csv", "input 'n' = 10.23 1/s", "--allow-out-of-range")
    assert not (tmp_path / "fit.json").exists(), err


@pytest.mark.data
def test_identify_refuses_records_of_the_other_scale(data_dir, tmp_path, capsys):
    """Before: the HSVA model-scale zig-zag was fitted on the 320 m ship (exit 3, R[u] = 1e18)."""
    hsva = data_dir / "kvlcc2_hsva_free" / "HSVA_CPMC_KVLCC2_Z_10_05.dat"
    marin = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_10_m.dat"
    out = str(tmp_path / "fit.json")
    one_line_error(capsys, ["identify", str(hsva), "--model", "kvlcc2", "--free", "N_r_dash", "--out", out, "--quiet"],
                   "record HSVA_CPMC_KVLCC2_Z_10_05.dat", "input 'n'", "of model 'kvlcc2'")
    one_line_error(capsys, ["identify", str(marin), "--model", "kvlcc2-l7", "--out", out, "--quiet"],
                   "record MARIN_FREE_KVLCC2_zz_10_m.dat", "state 'u' = 7.98 m/s", "of model 'kvlcc2-l7'")


# -- the record options on a trial file ----------------------------------------------------------------------------
@pytest.mark.data
@pytest.mark.parametrize("command", [["identify", "--model", "kvlcc2", "--free", "N_r_dash"], ["filter", "--model", "kvlcc2"],
                                     ["simulate", "--model", "kvlcc2", "--inputs"]])
def test_record_options_on_a_trial_file_say_they_read_csv(command, data_dir, capsys):
    """Before: "...zz_10_m.dat: no time column 't'; columns: ['MARIN(Maritime Research Institute Netherlands)']"
    (the .dat file read as a CSV whose header is its title line)."""
    rec = str(data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_10_m.dat")
    argv = [*command, rec, "--columns", "psi=heading:deg", "--quiet"]
    err = one_line_error(capsys, argv, "--columns: record options read CSV files", "is a marin record",
                         "u, v, r, x, y, psi, delta, n")
    assert "no time column" not in err


# -- a channel whose noise the record does not show ------------------------------------------------------------------
@pytest.fixture
def steady_x(tmp_path):
    """A kvlcc2 straight run whose x column advances by exactly 4 m a sample (second differences all zero), the
    other outputs with noise."""
    import numpy as np

    import casship as cs

    rng = np.random.default_rng(0)
    t = np.arange(0.0, 40.0, 0.5)
    noisy = {name: level + scale * rng.standard_normal(t.size)
             for name, level, scale in (("u", 8.0, 0.01), ("v", 0.0, 0.01), ("r", 0.0, 1e-5), ("y", 0.0, 0.1),
                                        ("psi", 0.0, 1e-3))}
    cols = {**noisy, "x": 8.0 * t, "delta": np.zeros(t.size), "n": np.full(t.size, 1.53)}
    return cs.Dataset(t, cols).to_csv(tmp_path / "steady_x.csv")


@pytest.mark.parametrize("command, option", [
    (["filter", "--model", "kvlcc2"], "--R x=VARIANCE (or --R-std x=STD)"),
    (["identify", "--model", "kvlcc2", "--free", "N_r_dash", "--out", "fit.json"], "--R x=VARIANCE"),
    (["identify", "--model", "kvlcc2", "--free", "N_r_dash", "--out", "fit.json", "--objective", "oe"], "--sigma x=STD"),
])
def test_a_channel_without_visible_noise_is_named_with_the_option_that_gives_it(command, option, steady_x, capsys):
    """Before: "the noise of 'x' cannot be estimated from the record (a constant channel); give its variance" (x is
    not constant; no option, no record named), and for output error "... give its standard deviation"."""
    err = one_line_error(capsys, [*command, str(steady_x), "--quiet"], "'x'", option, "leave 'x' out of --measured")
    if "oe" not in command:
        assert "steady_x.csv" in err and "second differences are zero" in err and "constant" not in err


def test_identify_decimation_that_leaves_one_row_names_the_option_and_the_record(tmp_path, capsys):
    """Before: 'decimate: k = 100000 leaves 1 row(s) of 40' (neither the option nor the record)."""
    rec = _kvlcc2_record(tmp_path / "short.csv", 1.53)
    one_line_error(capsys, ["identify", str(rec), "--model", "kvlcc2", "--free", "N_r_dash", "--decimate", "100000",
                            "--quiet"], "--decimate 100000: record short.csv has 40 rows", "--decimate 39 at most")


# -- filter: the starting variances ------------------------------------------------------------------------------
def test_filter_p0_for_some_states_keeps_the_default_for_the_others(tmp_path, capsys):
    """Before: '--P0: no value for [...]' although the help says 'default 1, R for measured states'."""
    rec = _kvlcc2_record(tmp_path / "run.csv", 1.53)
    argv = ["filter", str(rec), "--model", "kvlcc2", "--R", "1e-4", "--measured", "x,y,psi", "--json", "--quiet"]
    assert main([*argv, "--P0", "u=0.01,r=1e-6"]) == 0
    import json

    prior = json.loads(capsys.readouterr().out)["prior"]
    assert prior["u"].split("+-")[1].split()[0] == "0.1" and prior["r"].split("+-")[1].split()[0] == "0.001"
    assert prior["v"].split("+-")[1].split()[0] == "1" and prior["psi"].split("+-")[1].split()[0] == "0.01"
    one_line_error(capsys, [*argv, "--P0", "u=-1"], "--P0: a variance must be non-negative", "'u': -1.0")


# -- identify: a fit that diverges says so in casship's words ------------------------------------------------------
@pytest.mark.data
def test_a_diverging_noise_fit_on_the_usv_logs_prints_no_raw_numpy_message(data_dir, tmp_path, capsys):
    """Before: 'casship identify: warning: overflow encountered in multiply' (numpy's, from the chain rule of a
    log-variance beyond float range) and a relative standard error printed with 90 digits. The fit stalls either
    way (the two logs with Q and R free do not determine it): that is reported, exit code 3."""
    folder = data_dir / "usv_fuzhou_gnss"
    argv = ["identify", str(folder / "turnningdata_xy.csv"), str(folder / "zigzag_30_inter_xy.csv"), "--preset",
            "usv-gnss", "--model", "sog-cog-latlon", "--free", "alpha1,alpha2", "--estimate-noise", "Q,R", "--out",
            str(tmp_path / "usv.json"), "--quiet"]
    assert main(argv) == 3
    out, err = capsys.readouterr()
    assert "overflow encountered" not in err and "encountered in" not in err, err
    assert "verdict stalled" in err
    table = [line for line in out.splitlines() if line.strip().startswith(("alpha", "Q[", "R["))]
    assert len(table) == 6 and max(len(line) for line in table) < 80, table


@pytest.mark.data
def test_captive_given_a_file_of_the_folder_points_to_the_folder(data_dir, capsys):
    """Before: '.../pure_yaw.csv: captive-test folder not found' (the file exists)."""
    test = data_dir / "kvlcc2_hmri_captive" / "pure_yaw.csv"
    one_line_error(capsys, ["identify", "--captive", str(test), "--rig", "hmri-t530", "--model", "kvlcc2", "--quiet"],
                   "pure_yaw.csv: a file; the captive tests are read from their folder", "kvlcc2_hmri_captive)")


@pytest.mark.data
def test_a_diverging_filter_names_the_starting_variances(data_dir, capsys):
    """Before: '... the filter diverged; check the starting state (--x0), R, Q and the record', silent on --P0,
    whose default variance 1 for the unmeasured yaw rate (1 rad/s standard deviation) makes the ensemble diverge."""
    rec = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_10_m.dat"
    one_line_error(capsys, ["filter", str(rec), "--model", "kvlcc2", "--estimator", "enkf", "--measured", "x,y,psi",
                            "--quiet"], "the filter diverged", "--P0: 1 for a state not measured")


@pytest.mark.parametrize("option, value, text", [
    ("--weights", "q=1", "--weights: unknown name(s) ['q']"),
    ("--weights", "psi=-1", "--weights: a standard deviation must be positive, got {'psi': -1.0}"),
    ("--prior-std", "N_q=0.1", "--prior-std: unknown name(s) ['N_q']"),
])
def test_the_ship_workflow_refuses_a_name_it_would_pass_over(option, value, text, tmp_path, capsys):
    """Before: 'casship identify REC --model kvlcc2 --weights q=1' (or --prior-std N_q=0.1) ran the whole workflow
    with the unknown name ignored; a negative weight stopped after the inverse-dynamics start with 'sigma values
    must be positive: ['psi']'."""
    rec = _kvlcc2_record(tmp_path / "run.csv", 1.53)
    one_line_error(capsys, ["identify", str(rec), "--model", "kvlcc2", option, value, "--quiet"], text)
    assert not (tmp_path / "fit.json").exists()


@pytest.mark.parametrize("free", [["--free", "N_r_dash"], []])
def test_identify_names_the_record_whose_input_is_not_finite(free, tmp_path, capsys):
    """Before: "input 'delta' is not finite at row 5 (t = 2.5 s)" with two records, not saying which."""
    import pandas as pd

    good = _kvlcc2_record(tmp_path / "good.csv", 1.53)
    frame = pd.read_csv(good)
    frame.loc[5, "delta"] = float("nan")
    frame.to_csv(tmp_path / "gap.csv", index=False)
    one_line_error(capsys, ["identify", str(good), str(tmp_path / "gap.csv"), "--model", "kvlcc2", *free, "--quiet"],
                   "record gap.csv: input 'delta' is not finite at row 5 (t = 2.5 s)")


def test_identify_names_the_record_that_lacks_a_column(tmp_path, capsys):
    """Before: "data has no column(s) ['n'] needed by EKF on 'kvlcc2'" (or 'record 1 lacks ...', counted from 0)
    with two records, and for a --measured output "unknown column 'psi' ... with --R psi=VARIANCE"."""
    import pandas as pd

    good = _kvlcc2_record(tmp_path / "good.csv", 1.53)
    frame = pd.read_csv(good)
    frame.drop(columns=["n"]).to_csv(tmp_path / "no_n.csv", index=False)
    frame.drop(columns=["psi"]).to_csv(tmp_path / "no_psi.csv", index=False)
    for free in (["--free", "N_r_dash"], []):
        one_line_error(capsys, ["identify", str(good), str(tmp_path / "no_n.csv"), "--model", "kvlcc2", *free,
                                "--quiet"], "record no_n.csv: no column(s) ['n'], the input(s) of 'kvlcc2'")
        err = one_line_error(capsys, ["identify", str(good), str(tmp_path / "no_psi.csv"), "--model", "kvlcc2", *free,
                                      "--measured", "u,psi", "--quiet"],
                             "record no_psi.csv: no column(s) ['psi'], the --measured output(s)")
        assert "VARIANCE" not in err


def test_filter_measured_names_an_output_the_model_lacks(tmp_path, capsys):
    """Before: "the data have no column(s) ['q'] needed by model 'kvlcc2'" (q is no output of the model)."""
    rec = _kvlcc2_record(tmp_path / "run.csv", 1.53)
    one_line_error(capsys, ["filter", str(rec), "--model", "kvlcc2", "--measured", "u,q", "--quiet"],
                   "--measured: ['q'] not output(s) of model 'kvlcc2'", "'psi'")


@pytest.mark.parametrize("estimator, option", [("mhe", "horizon=abc"), ("enkf", "members=abc"), ("ukf", "alpha=abc"),
                                               ("ekf", "substeps=abc"), ("ekf", "gate=0.99,reacquire=abc"),
                                               ("mhe", "tol=abc")])
def test_filter_an_option_that_is_not_a_number_is_named(estimator, option, tmp_path, capsys):
    """Before: 'internal error (a bug in casship): ValueError: could not convert string to float: 'abc''."""
    rec = _kvlcc2_record(tmp_path / "run.csv", 1.53)
    name = option.rsplit(",", 1)[-1].split("=")[0]
    one_line_error(capsys, ["filter", str(rec), "--model", "kvlcc2", "--R", "1e-4", "--estimator", estimator,
                            "--options", option, "--quiet"], f"option '{name}' is a number, got 'abc'")


def test_the_ship_workflow_names_the_record_it_cannot_use(tmp_path, capsys):
    """Before: a record whose psi column holds no value stopped the workflow with 'Gaussian: mean contains
    non-finite entries: entry 2 is nan'; a straight run beside a manoeuvre with "rudder column 'delta' never moves
    by more than 1.0 deg" (which record?); and an output-error record of one row had a noise remedy appended."""
    import pandas as pd

    good = _kvlcc2_record(tmp_path / "straight.csv", 1.53)
    frame = pd.read_csv(good)
    frame.assign(psi=float("nan")).to_csv(tmp_path / "no_heading.csv", index=False)
    frame.iloc[:1].to_csv(tmp_path / "one_row.csv", index=False)
    one_line_error(capsys, ["identify", str(tmp_path / "no_heading.csv"), "--model", "kvlcc2", "--quiet"],
                   "record no_heading.csv: column(s) ['psi'] hold no finite value")
    one_line_error(capsys, ["identify", str(good), "--model", "kvlcc2", "--quiet"],
                   "record straight.csv: rudder column 'delta' never moves")
    err = one_line_error(capsys, ["identify", str(tmp_path / "one_row.csv"), "--model", "kvlcc2", "--free", "N_r_dash",
                                  "--objective", "oe", "--quiet"], "'one_row.csv' has 1 row(s)")
    assert "--sigma" not in err


def test_identify_replay_table_shows_whole_record_names(tmp_path, capsys):
    """Before: names cut to their last 24 characters ('_FREE_KVLCC2_zz_10_m.dat'), where trial files differ at
    their start."""
    rec = _kvlcc2_record(tmp_path / "MARIN_FREE_KVLCC2_straight_run.csv", 1.53)
    main(["identify", str(rec), "--model", "kvlcc2", "--free", "N_r_dash", "--measured", "psi,r", "--R",
          "psi=1e-6,r=1e-8", "--max-iter", "2", "--no-loo", "--out", str(tmp_path / "fit.json"), "--quiet"])
    out = capsys.readouterr().out
    assert " MARIN_FREE_KVLCC2_straight_run.csv " in out.replace("\n", " "), out


@pytest.mark.data
def test_output_error_says_which_states_start_at_zero(data_dir, tmp_path, capsys):
    """Before: the output-error fit of the USV log on sog-cog started U, chi, omega_chi at 0 without a word (a
    track that stays put: 0 iterations, 'converged', exit 0); now a warning names them and --estimate-x0."""
    log = data_dir / "usv_fuzhou_gnss" / "zigzag_30_inter_xy.csv"
    argv = ["identify", str(log), "--preset", "usv-gnss", "--model", "sog-cog", "--free", "alpha1", "--objective",
            "oe", "--out", str(tmp_path / "fit.json"), "--quiet"]
    main(argv)
    err = capsys.readouterr().err
    assert err.count("warning: output error starts state(s) ['U', 'chi', 'omega_chi'] at 0") == 1, err
    assert "(zigzag_30_inter_xy.csv); --estimate-x0 U,chi,omega_chi estimates their start" in err
    main([*argv, "--estimate-x0", "U,chi,omega_chi", "--overwrite"])
    assert "starts state(s)" not in capsys.readouterr().err


def test_autopilot_wind_on_a_ship_without_wind_geometry_names_the_option(capsys):
    """Before: "add_wind: no value for wind geometry [...] (model 'otter+current' has no vessel wind geometry; pass
    geometry=...)": a keyword the command line cannot pass, no --wind."""
    err = one_line_error(capsys, ["autopilot", "--model", "otter", "--current", "0.5", "90", "--wind", "5", "0",
                                  "--quiet"], "--wind: model 'otter' carries no wind geometry",
                         "casship.models.add_wind(model, geometry=...)")
    assert "otter+current" not in err


def test_the_mhe_on_a_lat_lon_log_equals_the_one_in_metres(data_dir, tmp_path):
    """Before: IPOPT stopped at row 1 ('Maximum_Iterations_Exceeded') on the latitude/longitude model, and
    the real-time iteration with an internal error ('evaluation of mhe_gn_step_20 failed (status 1)').
    Now both run, and give the estimates of the same log in metres (as the EKFs do: the flat-earth and
    the WGS-84 forms differ by about 3e-6 rad of course)."""
    import pandas as pd

    log = str(data_dir / "usv_fuzhou_gnss" / "zigzag_30_inter_xy.csv")
    base = ["filter", log, "--preset", "usv-gnss", "--estimator", "mhe", "--quiet"]
    for solver in ("ipopt", "rti"):
        out = {}
        for model in ("sog-cog-latlon", "sog-cog"):
            path = tmp_path / f"{model}_{solver}.csv"
            assert main([*base, "--model", model, "--options", f"solver={solver}", "--out", str(path)]) == 0
            out[model] = pd.read_csv(path)
        a, b = out["sog-cog-latlon"], out["sog-cog"]
        assert np.abs(np.angle(np.exp(1j * (a["chi"] - b["chi"])))).max() < 1e-5, solver
        assert np.abs(a["U"] - b["U"]).max() < 1e-6, solver


def test_filter_takes_the_variances_of_some_channels_and_fills_the_others_as_identify_does(tmp_path, capsys):
    """Before: '--R: no value for [...]' / '--Q: no value for [...]' for a partial list, while identify took one."""
    import json

    import numpy as np

    import casship as cs

    t = np.arange(0.0, 20.0, 0.5)
    noise = np.random.default_rng(3).standard_normal((3, t.size))
    cols = {"u": np.full(t.size, 7.97), "v": np.zeros(t.size), "r": np.zeros(t.size), "x": 7.97 * t + 2 * noise[0],
            "y": 2 * noise[1], "psi": 0.003 * noise[2], "delta": np.zeros(t.size), "n": np.full(t.size, 1.53)}
    rec = cs.Dataset(t, cols).to_csv(tmp_path / "run.csv")
    argv = ["filter", str(rec), "--model", "kvlcc2", "--measured", "x,y,psi", "--json", "--quiet"]
    assert main([*argv, "--R", "x=4,y=4", "--Q", "w_r=1e-9"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["R"].startswith("given (--R) for ['x', 'y'], estimated from the record: psi std")
    assert out["Q"] == "given (--Q) for ['w_r']; w_u 1e-08 (default), w_v 1e-08 (default)"
    assert main([*argv, "--R", "4"]) == 0                                  # a scalar is every channel's, as before
    assert json.loads(capsys.readouterr().out)["R"] == "given (--R)"
    one_line_error(capsys, [*argv, "--R-std", "x=-2"], "--R-std: a standard deviation must be positive")
