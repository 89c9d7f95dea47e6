"""``casship filter`` on synthetic CSV files and on the real USV GNSS logs."""
import json

import numpy as np
import pandas as pd
import pytest

import casship as cs
from casship.cli import main
from casship.estimators import EKF, ESTIMATORS


@pytest.fixture(scope="module")
def nomoto_csv(tmp_path_factory):
    """A Nomoto record written with degrees, as a user's CSV would be."""
    m = cs.models.nomoto_first_order()
    t = np.arange(0, 200, 0.5)
    delta = np.deg2rad(10) * np.sign(np.sin(2 * np.pi * t / 100))
    traj = cs.simulate(m, m.states(psi=3.0), t, {"delta": delta})
    rng = np.random.default_rng(0)
    heading = np.rad2deg(cs.wrap(traj["psi"] + 0.005 * rng.standard_normal(t.size))) % 360
    path = tmp_path_factory.mktemp("cli") / "trial.csv"
    pd.DataFrame({"time": t, "heading": heading, "rudder": np.rad2deg(delta), "r_true": traj["r"]}).to_csv(path, index=False)
    return path, traj


@pytest.mark.parametrize("estimator", ["ekf", "ukf", "enkf"])
def test_filter_synthetic_csv(nomoto_csv, tmp_path, estimator, capsys):
    path, traj = nomoto_csv
    out, png = tmp_path / "est.csv", tmp_path / "est.png"
    args = ["filter", str(path), "--model", "nomoto1", "--estimator", estimator, "--time", "time:s",
            "--columns", "psi=heading:deg,delta=rudder:deg", "--R-std", "psi=0.005", "--Q", "1e-9",
            "--P0", "psi=1e-4,r=1e-4", "--out", str(out), "--plot", str(png), "--json"]
    if estimator == "enkf":
        args += ["--options", "members=40"]
    if estimator != "enkf":
        args += ["--smooth"]
    assert main(args) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["updates"] == traj.t.size
    est = cs.Dataset.from_csv(out)
    assert set(est.names) == {"psi", "r", "psi_std", "r_std"}
    assert np.sqrt(np.mean((est["r"][40:] - traj["r"][40:]) ** 2)) < 5e-4
    assert png.stat().st_size > 10_000


def test_filter_rate_inserts_prediction_rows(nomoto_csv, tmp_path, capsys):
    path, traj = nomoto_csv
    out = tmp_path / "fast.csv"
    assert main(["filter", str(path), "--model", "nomoto1", "--time", "time:s", "--columns",
                 "psi=heading:deg,delta=rudder:deg", "--R", "2.5e-5", "--Q", "1e-9", "--rate", "10",
                 "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["rows"] == 5 * (traj.t.size - 1) + 1 and summary["updates"] == traj.t.size
    assert summary["dt_s"] == pytest.approx(0.1)


def test_errors_name_the_item(nomoto_csv, capsys):
    path, _ = nomoto_csv
    base = ["filter", str(path), "--model", "nomoto1", "--time", "time:s", "--columns", "psi=heading:deg,delta=rudder:deg",
            "--R", "1e-4", "--Q", "1e-9"]
    assert main(base + ["--estimator", "ekff"]) == 2
    assert "ekff" in capsys.readouterr().err
    assert main(base + ["--x0", "phi=1"]) == 2
    assert "phi" in capsys.readouterr().err
    assert main(["filter", str(path), "--model", "nomoto1", "--R", "1e-4", "--Q", "1e-9"]) == 2
    err = capsys.readouterr().err
    assert "['psi']" in err and "heading" in err


def test_estimators_registry_is_extensible(nomoto_csv, monkeypatch, capsys):
    class Mine(EKF):
        name = "Mine"

    monkeypatch.setitem(ESTIMATORS, "mine", Mine)
    path, _ = nomoto_csv
    assert main(["filter", str(path), "--model", "nomoto1", "--estimator", "mine", "--time", "time:s",
                 "--columns", "psi=heading:deg,delta=rudder:deg", "--R", "2.5e-5", "--Q", "1e-9", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["estimator"] == "Mine"


@pytest.mark.data
@pytest.mark.parametrize("model", ["sog-cog", "sog-cog-latlon"])
def test_usv_gnss_logs(data_dir, tmp_path, model, capsys):
    """The real USV logs: SOG from positions agrees with the log's own speed column (in knots).

    The process noise is the user's choice (here the values that give an NIS per measurement near 1 on
    the zig-zag log); the preset only describes the log's columns and units."""
    for name in ("zigzag_30_inter_xy.csv", "turnningdata_xy.csv"):
        out = tmp_path / f"{model}-{name}"
        assert main(["filter", str(data_dir / "usv_fuzhou_gnss" / name), "--preset", "usv-gnss", "--model", model,
                     "--estimator", "ekf", "--smooth", "--Q", "w_U=0.004,w_chi=0.001", "--out", str(out),
                     "--plot", str(out.with_suffix(".png")), "--json"]) == 0
        summary = json.loads(capsys.readouterr().out)
        assert summary["rmse_U_vs_log_speed"] < 0.1
        assert summary["rejected"] == 0
        est = cs.Dataset.from_csv(out)
        assert np.all(est["U"] > 0) and np.all(np.isfinite(est["chi_std"]))


@pytest.mark.data
def test_usv_latlon_and_north_east_agree(data_dir, capsys):
    path = str(data_dir / "usv_fuzhou_gnss" / "zigzag_30_inter_xy.csv")
    finals = {}
    for model in ("sog-cog", "sog-cog-latlon"):
        assert main(["filter", path, "--preset", "usv-gnss", "--model", model, "--json"]) == 0
        finals[model] = json.loads(capsys.readouterr().out)
    assert finals["sog-cog"]["final_U"] == pytest.approx(finals["sog-cog-latlon"]["final_U"], abs=1e-3)
    assert finals["sog-cog"]["final_chi"] == pytest.approx(finals["sog-cog-latlon"]["final_chi"], abs=1e-3)


@pytest.mark.data
def test_first_real_data_filter_runs_with_no_other_option(data_dir, capsys):
    """Before: "variance of 'u' at row 0 is nan" (unmeasured states started at 0, where the MMG model is
    singular); now the start, R and Q come from the record or stated defaults, each named."""
    run = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_10_m.dat"
    assert main(["filter", str(run), "--model", "kvlcc2", "--measured", "x,y,psi", "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert np.isfinite(summary["loglik"]) and np.isfinite(summary["final_U"] if "final_U" in summary else 0.0)
    assert summary["prior"]["u"].startswith("7.9") and "column 'u'" in summary["prior"]["u"]
    assert summary["R"].startswith("estimated from the record") and summary["Q"].startswith("default 1e-08")
    assert "NIS per measurement" in captured.err          # the untuned default is not silently trusted


@pytest.mark.data
def test_real_data_filter_from_positions_only_and_a_start_at_rest(data_dir, tmp_path, capsys):
    """Without u, v, r columns the speed comes from the track; a start at rest is refused, naming --x0.
    Before: the heading-only run printed "loglik: NaN" with exit code 0."""
    raw = cs.io.read_record(data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_10_m.dat")
    path = tmp_path / "track.csv"
    raw.select(["x", "y", "psi", "delta", "n"]).with_columns(psi=cs.wrap(raw["psi"])).to_csv(path)
    out = tmp_path / "est.csv"
    assert main(["filter", str(path), "--model", "kvlcc2", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert "speed over ground of the track x, y" in summary["prior"]["u"] and summary["prior"]["v"].endswith(
        "(0 (default))")
    est = cs.Dataset.from_csv(out)
    assert np.all(np.isfinite(est["u"])) and abs(est["u"][0] - raw["u"][0]) < 0.1
    assert main(["filter", str(path), "--model", "kvlcc2", "--measured", "psi", "--x0", "u=0,v=0"]) == 2
    err = capsys.readouterr().err
    assert "model 'kvlcc2' cannot start at the starting state (u = 0, v = 0," in err
    assert "give the starting value: --x0 u=..., v=..." in err and "Traceback" not in err
