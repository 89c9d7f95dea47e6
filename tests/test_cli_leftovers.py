"""The last silently wrong and unclear cases of the command line a probe found (each docstring says
what happened before, and what happens now)."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship.cli import main

from cli_checks import one_line_error as _error


def _nomoto_record(tmp_path, columns=("delta", "psi")):
    """A simulated Nomoto zig-zag-like record (0.5 s steps) holding ``columns`` of the replay."""
    model = cs.models.get_model("nomoto1")
    t = np.arange(0.0, 100.0, 0.5)
    delta = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 60.0) + 1e-9)
    tr = cs.simulate(model, model.states(), t, {"delta": delta})
    path = tmp_path / "nomoto.csv"
    cs.Dataset(t, {n: np.array(tr[n]) for n in columns}).to_csv(path)
    return path


# -- empty values ------------------------------------------------------------------------------------------
def test_an_empty_measured_list_is_refused_by_identify(tmp_path, capsys):
    """Before: ``identify --measured ""`` fitted to every output of the records, as if the option were
    left out. Now it is refused, naming the option."""
    path = str(_nomoto_record(tmp_path))
    _error(capsys, ["identify", path, "--model", "nomoto1", "--free", "K", "--measured", "",
                    "--out", str(tmp_path / "fit.json")], "--measured: an empty value names nothing")
    assert not (tmp_path / "fit.json").exists()


@pytest.mark.parametrize("argv, option", [
    (["simulate", "--model", "nomoto1", "--inputs", ""], "--inputs"),         # was: a turning circle
    (["simulate", "--model", "kvlcc2", "--params", ""], "--params"),          # was: the nominal parameters
    (["identify", "run.csv", "--model", "nomoto1", "--free", "K", "--R", ""], "--R"),   # was: R estimated
    (["identify", "", "--model", "nomoto1", "--free", "K"], "data"),
])
def test_an_empty_value_is_not_taken_for_a_left_out_option(capsys, argv, option):
    """Before: an empty value of an option whose default means "left out" chose that default silently
    (``simulate --inputs ""`` ran a turning circle instead of a replay). Now it is a usage error."""
    _error(capsys, argv, f"{option}: an empty value names nothing")


def test_an_empty_value_still_means_none_where_the_default_is_a_list(capsys):
    """An option whose default is a non-empty list keeps ``""`` as "none" (``design-trial --pullout ""``)."""
    from casship.cli import build_parser

    args = build_parser("design-trial").parse_args(["design-trial", "--model", "kvlcc2", "--pullout", ""])
    assert args.pullout == ""


# -- files the options name ---------------------------------------------------------------------------------
@pytest.mark.parametrize("argv", [
    ["simulate", "--model", "kvlcc2", "--params", "{missing}"],
    ["identify", "{record}", "--model", "nomoto1", "--free", "K", "--params", "{missing}"],
    ["autopilot", "--model", "kvlcc2", "--params", "{missing}"],
    ["design-trial", "--model", "kvlcc2", "--params", "{missing}"],
])
def test_a_missing_params_file_names_the_option_and_the_path(tmp_path, capsys, argv):
    """Before: "[Errno 2] No such file or directory: 'nosuch.json'" (no option named). Now the option
    and the path are named, before any work."""
    missing = tmp_path / "nosuch.json"
    argv = [a.format(missing=missing, record=_nomoto_record(tmp_path)) for a in argv]
    _error(capsys, argv, f"--params {missing}: no such file")


def test_a_folder_given_as_params_file_is_named(tmp_path, capsys):
    _error(capsys, ["simulate", "--model", "kvlcc2", "--params", str(tmp_path)], f"--params {tmp_path}: is a folder")


def test_a_missing_inputs_record_names_the_option(tmp_path, capsys):
    _error(capsys, ["simulate", "--model", "nomoto1", "--inputs", str(tmp_path / "run.csv")],
           f"--inputs {tmp_path / 'run.csv'}: no such file")


# -- version -----------------------------------------------------------------------------------------------
def test_version_is_the_installed_metadata(capsys):
    """Before: ``casship --version`` said 0.1.0, written in two places. Now one place (pyproject.toml),
    read from the installed metadata."""
    from importlib.metadata import version

    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code in (0, None)
    assert capsys.readouterr().out.strip() == f"casship {version('casship')}"
    assert cs.__version__ == version("casship")


def test_version_in_a_source_checkout_that_is_not_installed(monkeypatch):
    """Without installed metadata the version is the one in the checkout's pyproject.toml."""
    tomllib = pytest.importorskip("tomllib")
    import importlib.metadata
    from pathlib import Path

    def not_installed(name):
        raise importlib.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(importlib.metadata, "version", not_installed)
    pyproject = Path(cs.__file__).resolve().parents[1] / "pyproject.toml"
    if not pyproject.is_file():
        pytest.skip("casship is not run from a source checkout")
    assert cs._version() == tomllib.loads(pyproject.read_text())["project"]["version"]


# -- casship bench ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("only, text", [
    (["nosuch"], "--only: unknown benchmark(s) ['nosuch']; known: ["),
    (["ek"], "--only: unknown benchmark(s) ['ek']"),                   # no prefix matching (ekf, ...)
    (["simulate", "bench_simulate"], "--only: benchmark(s) ['simulate'] named more than once"),
])
def test_bench_only_names_whole_known_topics(capsys, only, text):
    """Before: ``casship bench --only nosuch`` ended with the usage and error of ``python -m benchmarks``
    (another program's name) by a SystemExit out of ``main``. Now the option, the name and the known
    topics are named, and the known ones are the topics as typed (``simulate``, not ``bench_simulate``)."""
    err = _error(capsys, ["bench", "--only", *only], text)
    assert "'simulate'" in err and "python -m benchmarks" not in err


# -- the whiteness warning ------------------------------------------------------------------------------------
@pytest.mark.parametrize("ratio, reading, span", [
    ([0.996, 1.004], "hold nonetheless", "are 1 times the model-based"),      # was: "do not hold ... 1-1 times"
    ([1.8, 1.84], "are optimistic", "are 1.8 times the model-based"),          # was: "1.8-1.8 times"
    ([1.8, 1.9, np.nan], "are optimistic", "are 1.8-1.9 times the model-based"),
    ([0.5, 0.71], "are conservative", "are 0.5-0.71 times the model-based"),
    ([0.78, 1.9], "do not hold as they are", "are 0.78-1.9 times the model-based"),
    ([np.nan], "do not hold as they are", "are unlike the model-based"),
])
def test_the_whiteness_warning_prints_one_number_for_a_degenerate_range(ratio, reading, span):
    """Before: "the robust ones ... are 1-1 times the model-based ones", and "do not hold as they are"
    for ratios that all print as 1. Now one number, and words that agree with it."""
    from casship.identify.problem import whiteness_warning

    text = whiteness_warning(["psi"], ratio)
    assert text.startswith("residuals of ['psi'] are not white (Ljung-Box): the model-based standard errors ")
    assert reading in text and span in text


def _coloured_nomoto_record():
    """A Nomoto record whose heading carries a 37 s oscillation the model cannot follow (coloured residuals)."""
    model = cs.models.get_model("nomoto1")
    t = np.arange(0.0, 300.0, 0.5)
    delta = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 60.0) + 1e-9)
    tr = cs.simulate(model, model.states(), t, {"delta": delta}, model.params(K=0.1, T=20.0))
    noise = 1e-3 * np.random.default_rng(1).standard_normal(t.size)
    return model, cs.Dataset(t, {"delta": delta,
                                 "psi": np.array(tr["psi"]) + 0.02 * np.sin(2 * np.pi * t / 37.0) + noise})


def test_one_fit_issues_its_whiteness_warning_once(tmp_path):
    """One fit with coloured residuals (a 37 s heading oscillation the Nomoto model cannot follow):
    one IdentificationWarning, whose text is the fit's own warning, read from its standard errors.
    Before: shown at a line inside casship (``fit = super().solve(...)`` of mle.py) instead of the
    caller's; with ``print(fit.summary())`` the text appears a second time, as the summary's report."""
    import warnings

    from casship.identify import IdentificationWarning, MLEProblem
    from casship.identify.problem import whiteness_warning

    model, data = _coloured_nomoto_record()
    ekf = cs.EKF(cs.discretize(model, 0.5), 1e-6, {"psi": 1e-4}, measured=["psi"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = MLEProblem(ekf, [data], ["K", "T"]).solve(show=False)
    white = [w for w in caught if issubclass(w.category, IdentificationWarning) and "not white" in str(w.message)]
    assert len(white) == 1 and not fit.whiteness["psi"]["white"]
    assert white[0].filename == __file__        # the caller's line (was: casship/identify/mle.py)
    ratio = [fit.std_errors_robust[n] / fit.std_errors[n] for n in ("K", "T")]
    assert str(white[0].message) == f"mle-ekf: {whiteness_warning(['psi'], ratio)}"
    assert fit.warnings == [whiteness_warning(["psi"], ratio)]


# -- a replay with a model that has fewer states than the record ----------------------------------------------
def _ship_record(tmp_path):
    """A simulated KVLCC2 zig-zag record (1 s steps, 200 s) with columns delta, n, x, y, psi."""
    ship = cs.models.get_model("kvlcc2")
    t = np.arange(0.0, 200.0)
    delta = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 200.0) + 1e-9)
    tr = cs.simulate(ship, ship.states(u=ship.vessel.U0), t, {"delta": delta, "n": np.full(t.size, 1.7785)})
    data = cs.measure(tr, ship, {"x": 1.0, "y": 1.0, "psi": 1e-3}, seed=3)
    path = tmp_path / "ship.csv"
    data.to_csv(path)
    return path, data


def test_a_heading_model_replays_a_ship_record(tmp_path, capsys):
    """Before: ``simulate --model nomoto1 --inputs RUN`` stopped with "unknown column 'x'": the replay
    compared the record's track with the replayed model's, which a Nomoto model does not have. Now it
    replays from the record's heading (yaw rate at zero: no column), says so, and names the columns
    it does not compare; the heading error is the one of an independent simulation."""
    import json

    path, data = _ship_record(tmp_path)
    assert {"x", "y", "psi", "delta"} <= set(data.names) and "r" not in data.names
    assert main(["simulate", "--model", "nomoto1", "--inputs", str(path), "--json",
                 "--plot", str(tmp_path / "replay.png")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["start"] == {"psi": "record", "r": "zero"} and out["not_compared"] == ["x", "y"]
    assert set(out["replay"]) == {"psi_rmse_deg"} and (tmp_path / "replay.png").stat().st_size > 0
    model = cs.models.get_model("nomoto1")
    tr = cs.simulate(model, model.states(psi=data["psi"][0]), data.t, {"delta": data["delta"]})
    e = cs.wrap(np.array(tr["psi"]) - data["psi"])
    assert out["replay"]["psi_rmse_deg"] == pytest.approx(np.degrees(np.sqrt(np.mean(e ** 2))), rel=1e-9)
    assert main(["simulate", "--model", "nomoto1", "--inputs", str(path)]) == 0
    text = capsys.readouterr().out
    assert "initial psi from the record's first row" in text and "initial r at zero (no column)" in text
    assert "not compared (the model has no such state or output): x, y" in text and "L_pp = None" not in text


def test_a_replay_given_its_start_says_so():
    model = cs.models.get_model("nomoto1")
    t = np.arange(0.0, 20.0, 0.5)
    data = cs.Dataset(t, {"delta": np.full(t.size, 0.1), "psi": np.zeros(t.size), "x": t})
    from casship.maneuvers import replay

    res = replay(model, data, x0=model.states(r=0.01))
    assert res.start == {"psi": "x0", "r": "x0"} and res.not_compared == ["x"]
    assert "initial psi, r given" in res.summary()


@pytest.mark.parametrize("how", ["mle-exact", "oe-single", "oe-multiple"])
def test_the_whiteness_warning_points_at_the_callers_line(how):
    """Every solver path issues the fit's warning once, at the line that called ``solve``."""
    import warnings

    from casship.identify import IdentificationWarning, MLEProblem, OutputErrorProblem

    model, data = _coloured_nomoto_record()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if how == "mle-exact":
            ekf = cs.EKF(cs.discretize(model, 0.5), 1e-6, {"psi": 1e-4}, measured=["psi"])
            MLEProblem(ekf, [data], ["K", "T"]).solve(show=False, hessian="exact")
        else:
            OutputErrorProblem(model, [data], ["K", "T"], shooting=how[3:]).solve(show=False)
    white = [w for w in caught if issubclass(w.category, IdentificationWarning) and "not white" in str(w.message)]
    assert len(white) == 1 and white[0].filename == __file__
