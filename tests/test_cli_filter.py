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
    """The real USV logs: SOG from positions agrees with the log's own speed column (in knots)."""
    for name in ("zigzag_30_inter_xy.csv", "turnningdata_xy.csv"):
        out = tmp_path / f"{model}-{name}"
        assert main(["filter", str(data_dir / "usv_fuzhou_gnss" / name), "--preset", "usv-gnss", "--model", model,
                     "--estimator", "ekf", "--smooth", "--out", str(out), "--plot", str(out.with_suffix(".png")),
                     "--json"]) == 0
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
