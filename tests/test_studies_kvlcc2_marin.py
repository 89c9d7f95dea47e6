"""Study kvlcc2-marin (quick): the fit improves the prediction of the run it did not see, and its
fit.json drives ``casship simulate --params``."""
import json

from casship.cli import main
from problems import get_study


def test_kvlcc2_marin_quick(data_dir, tmp_path, capsys):
    summary = get_study("kvlcc2-marin").run(tmp_path, quick=True, data_dir=data_dir)
    before, after = summary["headline_before"], summary["headline_after"]
    for key in ("psi_rmse_deg", "position_rmse_m", "u_rmse_mps"):
        assert after[key] < before[key], key
    fold = summary["folds"][summary["headline_held_out"]]
    assert summary["headline_held_out"] not in fold["trained_on"]
    assert all(s > 0 for s in fold["std_errors"].values())
    assert (tmp_path / "cross_validation.md").exists() and (tmp_path / "fig_fit_residuals.png").exists()
    held = data_dir / "kvlcc2_marin_free" / "MARIN_FREE_KVLCC2_zz_-20_m.dat"
    capsys.readouterr()
    assert main(["simulate", "--model", "kvlcc2", "--params", str(tmp_path / "fit.json"), "--inputs", str(held), "--json"]) == 0
    replay = json.loads(capsys.readouterr().out)["replay"]
    assert abs(replay["psi_rmse_deg"] - after["psi_rmse_deg"]) < 1e-6
