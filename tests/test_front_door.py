"""Bad input at the front door: the command line and the Python API name the offending item.

Every user error of the command line ends with exit code 2 and one line ``casship CMD: error: ...``
(no traceback; ``--debug`` shows it). The Python API raises ``ValueError``/``TypeError`` (or warns)
naming the item and, for validity ranges, the range and the way to opt in.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import casship as cs
from casship.cli import build_parser, main
from casship.simulation import ValidityError


def _fails(capsys, argv, *expected):
    """Run the CLI; exit code 2, one error line holding every expected text, no traceback."""
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    errors = [line for line in err.splitlines() if ": error: " in line]
    assert len(errors) == 1, err
    for text in expected:
        assert text in errors[0], (text, errors[0])
    return errors[0]


SIM = ["simulate", "--model", "kvlcc2", "--duration", "60"]


# -- simulate: validity ranges, steps, speeds -----------------------------------------------------------
@pytest.mark.parametrize("extra, expected", [
    (["--rudder-deg", "200"], ["input 'delta' = 200 deg", "[-35, 35] deg (rudder stop)", "--allow-out-of-range"]),
    (["--dt", "1000", "--duration", "5000"], ["time step 1000 s", "rk4 stability limit", "kvlcc2"]),
    (["--speed", "100"], ["state 'u' = 100 m/s", "[0, 15.95] m/s"]),
    (["--rps", "-2"], ["input 'n' = -2 1/s", "[0, 3.06] 1/s"]),
    (["--dt", "0"], ["dt must be positive, got 0 s"]),
    (["--dt", "-0.5"], ["dt must be positive, got -0.5 s"]),
    (["--duration", "-10"], ["duration must be positive, got -10 s"]),
    (["--speed", "-5"], ["speed must be positive, got -5 m/s"]),
    (["--speed", "0"], ["speed must be positive, got 0 m/s"]),
    (["--rudder-deg", "nan"], ["rudder_deg must be finite"]),
    (["--maneuver", "spin"], ["invalid choice: 'spin'"]),
])
def test_simulate_bad_values(capsys, extra, expected):
    _fails(capsys, SIM + extra, *expected)


def test_simulate_explicit_out_of_range_study(capsys):
    assert main(SIM + ["--rudder-deg", "40", "--allow-out-of-range", "--json"]) == 0
    assert '"rudder_deg": 40.0' in capsys.readouterr().out


def test_model_argument_is_one_way_everywhere(capsys):
    _fails(capsys, ["simulate", "kvlcc2"], "unrecognized arguments: kvlcc2")
    _fails(capsys, ["autopilot", "kvlcc2"], "unrecognized arguments: kvlcc2")
    _fails(capsys, ["simulate", "--model", "kvlcc3"], "unknown model 'kvlcc3'", "known models")
    _fails(capsys, ["simulate"], "the following arguments are required: --model")


def test_debug_shows_the_traceback():
    with pytest.raises(ValueError, match="dt must be positive"):
        main(SIM + ["--dt", "0", "--debug"])


def test_warnings_print_as_one_line(capsys):
    assert main(["simulate", "--model", "kvlcc2", "--rudder-deg", "0.61", "--duration", "300", "--json"]) == 0
    err = capsys.readouterr().err
    assert "casship simulate: warning: rudder_deg=0.61 is below 1 deg" in err
    assert "Traceback" not in err and "warnings.warn" not in err


# -- filter ----------------------------------------------------------------------------------------------
@pytest.fixture
def nomoto_record(tmp_path):
    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, 60.0, 0.5)
    tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 10))})
    data = cs.measure(tr, m, {"psi": 0.01}, seed=2)
    path = tmp_path / "run.csv"
    data.to_csv(path)
    return path, data


def test_filter_reports_every_missing_option_at_once(capsys, nomoto_record):
    _fails(capsys, ["filter"], "the following arguments are required: DATA, --model")


def test_filter_takes_what_is_not_given_from_the_record_and_says_so(capsys, nomoto_record):
    """Before: R and Q were required; now R is estimated from the record, Q takes a stated default and
    the start comes from the first samples, each named in the output."""
    import json

    path, _ = nomoto_record
    assert main(["filter", str(path), "--model", "nomoto1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["R"].startswith("estimated from the record: psi std 0.01")      # measured with std 0.01
    assert summary["Q"].startswith("default 1e-08 per channel ['w_r'] (not tuned")
    assert "first sample of column 'psi'" in summary["prior"]["psi"]
    assert "rate of column 'psi'" in summary["prior"]["r"]
    assert 0.2 < summary["nis_per_measurement"] < 5


def test_filter_list_works_alone(capsys):
    assert main(["filter", "--list"]) == 0
    out = capsys.readouterr().out
    assert "ekf" in out and "preset usv-gnss" in out


@pytest.mark.parametrize("extra, expected", [
    (["--dt", "0"], ["argument --dt: must be a positive number, got 0"]),
    (["--dt", "-1"], ["argument --dt: must be a positive number, got -1"]),
    (["--rate", "0.5"], ["--rate: resample: rate 0.5 Hz is below the record's rate 2 Hz"]),
    (["--estimator", "ekff"], ["unknown estimator 'ekff'"]),
    (["--R=-1e-4"], ["not positive semi-definite"]),
    (["--R", "phi=1e-4"], ["--R: unknown name(s) ['phi']"]),
    (["--x0", "bogus=1"], ["--x0: unknown name(s) ['bogus']"]),
    (["--options", "gait=0.9"], ["unknown option(s) ['gait']"]),
    (["--measured", "heading"], ["--measured: ['heading'] not output(s) of model 'nomoto1'"]),
])
def test_filter_bad_values(capsys, nomoto_record, extra, expected):
    path, _ = nomoto_record
    base = ["filter", str(path), "--model", "nomoto1", "--R", "1e-4", "--Q", "1e-8"]
    argv = base + extra
    if extra[0].startswith("--R"):            # the option replaces the base value
        argv = ["filter", str(path), "--model", "nomoto1", "--Q", "1e-8"] + extra
    _fails(capsys, argv, *expected)


def test_filter_rate_above_the_data_rate_inserts_prediction_rows(capsys, nomoto_record):
    path, data = nomoto_record
    assert main(["filter", str(path), "--model", "nomoto1", "--R", "1e-4", "--Q", "1e-8", "--rate", "4",
                 "--json"]) == 0
    out = capsys.readouterr().out
    assert f'"rows": {2 * len(data) - 1}' in out and f'"updates": {len(data)}' in out


def test_filter_reads_nmea_logs(tmp_path, capsys):
    lines = []
    for k in range(20):
        hh, mm, ss = 12, 0, k
        body = f"GPRMC,{hh:02d}{mm:02d}{ss:02d}.00,A,6325.{8000 + 10 * k:04d},N,01023.5000,E,5.0,0.0,010120,,"
        lines.append(f"${body}*{_checksum(body)}")
    path = tmp_path / "track.nmea"
    path.write_text("\n".join(lines) + "\n")
    assert main(["filter", str(path), "--model", "sog-cog", "--R", "x_n=4,y_n=4", "--Q", "w_U=1e-3,w_chi=1e-4",
                 "--json"]) == 0
    out = capsys.readouterr().out
    assert '"rows": 20' in out


def _checksum(body: str) -> str:
    value = 0
    for ch in body:
        value ^= ord(ch)
    return f"{value:02X}"


@pytest.mark.data
def test_filter_reads_marin_records(data_dir, capsys):
    path = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_10_m.dat"
    assert main(["filter", str(path), "--model", "kvlcc2", "--measured", "x,y,psi", "--R", "4",
                 "--Q", "1e-6", "--json"]) == 0
    assert '"rows": 3844' in capsys.readouterr().out


def test_filter_files_that_are_not_there_or_empty(tmp_path, capsys):
    _fails(capsys, ["filter", str(tmp_path / "none.csv"), "--model", "nomoto1", "--R", "1", "--Q", "1"],
           "none.csv: no such file")
    (tmp_path / "empty.csv").write_text("")
    _fails(capsys, ["filter", str(tmp_path / "empty.csv"), "--model", "nomoto1", "--R", "1", "--Q", "1"],
           "empty.csv: empty file")


def test_result_files_are_not_overwritten(capsys, nomoto_record, tmp_path):
    path, _ = nomoto_record
    out = tmp_path / "est.csv"
    out.write_text("previous results")
    base = ["filter", str(path), "--model", "nomoto1", "--R", "1e-4", "--Q", "1e-8", "--out", str(out)]
    _fails(capsys, base, "--out", "est.csv: file exists; pass --overwrite")
    assert out.read_text() == "previous results"
    assert main(base + ["--overwrite"]) == 0
    assert out.read_text().startswith("t,")


# -- help ----------------------------------------------------------------------------------------------
def test_every_command_has_help_with_defaults():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(sub.choices) >= {"demo", "study", "simulate", "filter", "identify", "autopilot", "bench"}
    for name, command in sub.choices.items():
        text = command.format_help()
        assert command.description, name
        for action in command._actions:
            if action.help == "==SUPPRESS==" or not action.option_strings and action.dest == "help":
                continue
            assert action.help, f"{name} {action.option_strings or action.dest} has no help"
            if action.default not in (None, False, "==SUPPRESS==") and action.option_strings and \
                    "%(default)" not in (action.help or ""):
                assert "(default:" in " ".join(command.format_help().split()), name
    simulate = " ".join(sub.choices["simulate"].format_help().split())
    assert "rudder angle [deg]; positive turns to starboard; negative zig-zag = port first (default: 35.0)" \
        in simulate


# -- Python API ----------------------------------------------------------------------------------------
def test_rudder_in_radians_where_degrees_are_expected_warns():
    from casship.maneuvers import run_maneuver

    ship = cs.models.get_model("kvlcc2")
    with pytest.warns(UserWarning) as record:
        res = run_maneuver(ship, "turning", rudder_deg=np.radians(35), duration=600)
    text = " ".join(str(w.message) for w in record)
    assert "rudder_deg=0.610865 is below 1 deg" in text
    assert "the heading changed by only" in text
    assert "advance_m" not in res.metrics


def test_run_maneuver_checks_each_setting():
    from casship.maneuvers import run_maneuver

    ship = cs.models.get_model("kvlcc2")
    with pytest.raises(ValidityError, match=r"input 'delta' = 200 deg .* \[-35, 35\] deg"):
        run_maneuver(ship, rudder_deg=200)
    with pytest.raises(ValidityError, match=r"time step 1000 s"):
        run_maneuver(ship, dt=1000.0, duration=5000.0)
    with pytest.raises(ValueError, match="dt = 50 s must be shorter than the duration 10 s"):
        run_maneuver(ship, dt=50.0, duration=10.0)
    with pytest.raises(ValueError, match="hold must be positive"):
        run_maneuver(ship, "pullout", hold=-1.0)
    with pytest.raises(ValueError, match="rudder_deg must be non-zero"):
        run_maneuver(ship, "zigzag", rudder_deg=0.0)
    with pytest.raises(TypeError, match="rudder_deg must be a number, got None"):
        run_maneuver(ship, rudder_deg=None)
    with pytest.raises(ValueError, match="unknown manoeuvre 'spin'"):
        run_maneuver(ship, "spin")


def test_propeller_rate_and_trim_refuse_speeds_outside_the_model():
    from casship.maneuvers import propeller_rate_for_speed

    ship = cs.models.get_model("kvlcc2")
    with pytest.raises(ValidityError, match=r"speed: state 'u' = 100 m/s is outside its valid range \[0, 15.95\]"):
        propeller_rate_for_speed(ship, 100.0)
    n = propeller_rate_for_speed(ship, ship.vessel.U0)
    xdot = ship.f(ship.states(u=ship.vessel.U0), ship.inputs(n=n), ship.params(), np.zeros(ship.nw))
    assert abs(float(xdot[ship.index("u")])) < 1e-10


def test_design_autopilot_at_zero_speed():
    from casship import autopilot as ap

    with pytest.raises(ValueError, match="speed must be positive, got 0"):
        ap.design_autopilot(cs.models.get_model("kvlcc2"), speed=0.0)


def test_symbolic_nan_is_rejected_at_build():
    b = cs.ModelBuilder("bad")
    psi, r = b.state("psi"), b.state("r")
    b.ode(psi=r, r=math.cos(psi) - r)
    with pytest.raises(ValueError, match="the equation of state 'r' contains the constant nan"):
        b.build()


def test_readers_name_the_source(tmp_path):
    from casship.io import read_nmea, read_record

    with pytest.raises(ValueError, match="read_nmea: the source is an empty string"):
        read_nmea("")
    with pytest.raises(IsADirectoryError, match="is a folder"):
        read_nmea(tmp_path)
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(ValueError, match=r"empty.csv: empty file"):
        cs.Dataset.from_csv(tmp_path / "empty.csv")
    (tmp_path / "header.csv").write_text("t,psi\n")
    with pytest.raises(ValueError, match=r"header.csv: no data rows below the header \['t', 'psi'\]"):
        read_record(tmp_path / "header.csv")
    with pytest.raises(FileNotFoundError, match="record .*missing.dat: no such file"):
        read_record(tmp_path / "missing.dat")


def test_time_stamps_nan_duplicate_and_gaps():
    with pytest.raises(ValueError, match=r"non-finite time stamp at row 1"):
        cs.Dataset([0.0, np.nan, 2.0], {"psi": [0.0, 0.1, 0.2]})
    with pytest.raises(ValueError, match=r"row 2 \(1.0\) is not after row 1 \(1.0\)"):
        cs.Dataset([0.0, 1.0, 1.0], {"psi": [0.0, 0.1, 0.2]})
    m = cs.models.nomoto_first_order()
    t = np.concatenate([np.arange(0.0, 50.0, 0.5), 1e4 + np.arange(0.0, 50.0, 0.5)])
    with pytest.raises(ValidityError, match="exceeds the rk4 stability limit"):
        cs.simulate(m, m.states(), t, {"delta": 0.1})


def _gap_record():
    m = cs.models.nomoto_first_order()
    t = np.concatenate([np.arange(0.0, 100.0, 0.5), 1e4 + np.arange(0.0, 100.0, 0.5)])
    truth = cs.simulate(m, m.states(), t, {"delta": 0.1}, method="cvodes")
    return m, truth, cs.measure(truth, m, {"psi": 0.01}, seed=3)


def test_estimator_facing_a_long_gap_raises_or_bridges():
    m, truth, data = _gap_record()
    prior = cs.Gaussian(m.states(), np.diag([1e-2, 1e-4]))
    ekf = cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4)
    with pytest.raises(ValueError, match=r"EKF: time gap of 9900 s between t = 99.5 and 10000 s \(rows 199 and 200\) "
                                         r"is longer than .* s, the longest interval the rk4 prediction bridges"):
        ekf.filter(data, prior)
    bridged = cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4, options={"on_gap": "bridge"})
    with pytest.warns(UserWarning, match=r"1 time gap\(s\) longer than .* bridged by \d+ prediction-only row"):
        res = bridged.filter(data, prior)
    assert np.all(np.isfinite(res.x)) and len(res.t) > len(data)
    # the yaw rate after the gap is the steady K delta, not 1e29
    assert res["r"][-1] == pytest.approx(truth["r"][-1], abs=1e-3)
    # a stated limit
    capped = cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4, options={"max_gap": 5.0})
    with pytest.raises(ValueError, match="longer than 5 s"):
        capped.filter(data, prior)
    with pytest.raises(ValueError, match="option 'max_gap' is a positive time"):
        cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4, options={"max_gap": -1.0})
    with pytest.raises(ValueError, match="option 'on_gap' is 'raise' or 'bridge'"):
        cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4, options={"on_gap": "ignore"})


def _started_gap_run(m, data, **options):
    """An online EKF on the gap record (held rudder 0.1), after its first update."""
    prior = cs.Gaussian(m.states(), np.diag([1e-2, 1e-4]))
    run = cs.EKF(cs.discretize(m, 0.5, "rk4"), Q=1e-8, R=1e-4, options=options).online(prior, u=[0.1])
    run.update(data["psi"][:1], 0.0)
    return run


@pytest.mark.parametrize("jit", [False, True], ids=["interpreted", "compiled"])
def test_online_update_refuses_bad_dt_and_long_gaps(jit):
    m, truth, data = _gap_record()
    run = _started_gap_run(m, data, jit=jit)
    for bad in (np.nan, -1.0, np.inf):
        with pytest.raises(ValueError, match="dt must be >= 0 and finite"):
            run.update(data["psi"][1:2], bad)
    with pytest.raises(ValueError, match="time gap of 1e\\+04 s before update 2"):
        run.update(data["psi"][1:2], 1e4)
    bridged = _started_gap_run(m, data, on_gap="bridge", jit=jit)
    with pytest.warns(UserWarning, match="bridged by"):
        x = bridged.update(data["psi"][-1:], 1e4)
    assert np.all(np.isfinite(x))
    assert abs(x[1] - truth["r"][-1]) < 3 * np.sqrt(bridged.P[1, 1])


@pytest.mark.parametrize("jit", [False, True], ids=["interpreted", "compiled"])
def test_a_refused_online_update_changes_nothing(jit):
    m, truth, data = _gap_record()
    run = _started_gap_run(m, data, jit=jit)
    x, P = run.x, run.P
    refused = [((np.array([np.inf]), 0.5), "measurement\\(s\\) \\['psi'\\] infinite"),
               ((np.array([0.1]), 0.5, None, [np.nan]), "inputs \\['delta'\\] must be finite"),
               ((np.array([0.1]), 0.5, None, [0.1, 0.2]), "u must hold 1 value for \\['delta'\\], got shape \\(2,\\)"),
               (("abc", 0.5), "y must be 1 number for \\['psi'\\]"),
               ((np.array([0.1, 0.2]), 0.5), "y must hold 1 value for \\['psi'\\]")]
    for args, message in refused:
        with pytest.raises(ValueError, match=message):
            run.update(*args)
        np.testing.assert_array_equal(run.x, x)
        np.testing.assert_array_equal(run.P, P)
    # the input held since the last accepted update is still the default (not the refused NaN)
    reference = _started_gap_run(m, data)
    np.testing.assert_array_equal(run.update(data["psi"][1:2], 0.5), reference.update(data["psi"][1:2], 0.5))


def test_wrong_shapes_are_named():
    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, 1.0, 0.1)
    with pytest.raises(ValueError, match="x0 has 3 entries, model 'nomoto1' has 2 states"):
        cs.simulate(m, [0.0, 0.0, 0.0], t, {"delta": 0.0})
    with pytest.raises(ValueError, match=r"input 'delta' has shape \(4,\), expected \(10,\)"):
        cs.simulate(m, m.states(), t, {"delta": np.zeros(4)})
    with pytest.raises(ValueError, match=r"column 'psi' has 2 rows, time has 3"):
        cs.Dataset([0.0, 1.0, 2.0], {"psi": [0.0, 1.0]})
    with pytest.raises(ValueError, match=r"Gaussian covariance: expected shape \(2, 2\), got \(3, 3\)"):
        cs.Gaussian([0.0, 0.0], np.eye(3))


def test_non_positive_definite_covariances_are_refused():
    m = cs.models.nomoto_first_order()
    with pytest.raises(ValueError, match="Gaussian covariance: not positive semi-definite"):
        cs.Gaussian([0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="not symmetric"):
        cs.Gaussian([0.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="R.*not positive semi-definite"):
        cs.EKF(cs.discretize(m, 0.1), Q=1e-8, R=-1e-4)


def test_unknown_names_are_named():
    m = cs.models.nomoto_first_order()
    with pytest.raises(ValueError, match="unknown state name 'yaw'"):
        m.states(yaw=1.0)
    with pytest.raises(ValueError, match=r"unknown input name\(s\) \['rudder'\]"):
        cs.simulate(m, m.states(), np.arange(0.0, 1.0, 0.1), {"rudder": 0.1})
    with pytest.raises(ValueError, match="unknown parameter name 'KK'"):
        m.params(KK=1.0)
    with pytest.raises(ValueError, match="trim: unknown free variable 'rudder'"):
        cs.trim(m, free=["rudder"], zero=["r"])
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['gait'\]"):
        cs.EKF(cs.discretize(m, 0.1), Q=1e-8, R=1e-4, options={"gait": 0.9})
    with pytest.raises(ValueError, match="unknown model 'kvlcc3'"):
        cs.models.get_model("kvlcc3")


def test_linearize_without_inputs():
    b = cs.ModelBuilder("free")
    x = b.state("x")
    b.ode(x=-x)
    b.output("x", x)
    with pytest.raises(ValueError, match="model 'free' has no inputs"):
        cs.linearize(b.build())


def test_results_read_short(tmp_path):
    from casship.maneuvers import run_maneuver
    from casship.maneuvers import replay

    m = cs.models.shi_taylor()
    tr = cs.trim(m, x={"u": 8.0}, u={"n": 1.0}, free=["n"], zero=["u"])
    assert "\n" not in repr(tr) and len(repr(tr)) < 80
    ship = cs.models.get_model("kvlcc2")
    record = run_maneuver(ship, "zigzag", rudder_deg=10, duration=400, dt=1.0).trajectory
    res = replay(ship, record, ship.params(R_0_dash=0.03))
    assert "\n" not in repr(res) and repr(res).startswith("ReplayResult('kvlcc2', zigzag, N=")
    text = res.summary()
    assert "psi_rmse_deg" in text and "overshoot_1_deg" in text and "replayed" in text
    fig = res.plot()
    labels = [(ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes]
    assert all("[" in x and "[" in y for x, y in labels), labels
    assert res.plot(tmp_path / "replay.png").stat().st_size > 10_000


def test_identify_refuses_to_overwrite_a_fit(capsys, nomoto_record, tmp_path):
    path, _ = nomoto_record
    out = tmp_path / "fit.json"
    out.write_text("{}")
    _fails(capsys, ["identify", str(path), "--model", "nomoto1", "--free", "K", "--out", str(out)],
           "--out", "fit.json: file exists; pass --overwrite")
    assert out.read_text() == "{}"


def test_health_reads_short():
    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, 50.0, 0.5)
    data = cs.measure(cs.simulate(m, m.states(), t, {"delta": 0.1}), m, {"psi": 0.01}, seed=1)
    health = cs.EKF(cs.discretize(m, 0.5), Q=1e-8, R=1e-4).filter(data, cs.Gaussian(m.states(), 1e-2)).health()
    text = repr(health)
    assert "\n" not in text and "array(" not in text and len(text) < 120
    assert text.startswith("Health(ok: 0 of 2 NIS window(s) of 50 flagged")
