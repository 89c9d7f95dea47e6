"""The Tomera (2011) study in quick mode: its claims hold on the regenerated numbers."""
import json

from casship.cli import main


def test_tomera2011_quick(tmp_path):
    assert main(["study", "tomera2011", "--quick", "--out", str(tmp_path)]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    m = s["metrics"]
    for reading in ("A", "B"):
        kf, kb = m[f"discrete KF, reading {reading}"], m[f"Kalman-Bucy, reading {reading}"]
        # the two kinematic filters describe the same continuous noise: similar accuracy
        for c in ("u", "v"):
            assert abs(kf[f"rmse_{c}"] - kb[f"rmse_{c}"]) < 0.2 * kf[f"rmse_{c}"]
    # reading B (swapped G) gives the noisy velocities of the paper's figures, reading A smooth ones
    assert m["Kalman-Bucy, reading B"]["noise_v"] > 10 * m["Kalman-Bucy, reading A"]["noise_v"]
    # the model-based EKF beats every kinematic filter in accuracy and noise on all three velocities
    ekf = m["model-based EKF (MMG, no wind in model)"]
    for label, row in m.items():
        if "EKF" in label:
            continue
        for c in ("u", "v", "r"):
            assert ekf[f"rmse_{c}"] < row[f"rmse_{c}"] and ekf[f"noise_{c}"] < row[f"noise_{c}"]
    for name in s["figures"]:
        assert (tmp_path / name).stat().st_size > 10_000
    assert (tmp_path / "README.md").exists()
