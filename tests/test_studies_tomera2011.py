"""The Tomera (2011) study in quick mode: its claims hold on the regenerated numbers, on the Blue Lady
stand-in, and the readings the paper leaves open are run and reported."""
import json

import numpy as np
import pytest

from casship.cli import main
from problems.tomera2011 import BLUE_LADY, blue_lady_standin


def test_blue_lady_standin_has_the_papers_particulars():
    ship = blue_lady_standin()
    v = ship.vessel
    assert (v.L_pp, v.B, v.mass) == (13.75, 2.38, 22934.0)
    p = ship.param_dict()
    assert p["rho"] * p["nabla"] == pytest.approx(BLUE_LADY["mass"], rel=1e-12)
    assert p["L_pp"] == 13.75 and p["B"] == 2.38
    # Froude-scaled from the 7 m model: the propeller diameter in proportion to the length
    assert p["D_p"] / p["L_pp"] == pytest.approx(0.216 / 7.0, rel=1e-12)
    assert "stand-in" in v.name


def test_tomera2011_quick(tmp_path):
    assert main(["study", "tomera2011", "--quick", "--out", str(tmp_path / "t")]) == 0
    out = tmp_path / "t"
    s = json.loads((out / "summary.json").read_text())
    assert s["quick"] is True
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
    # R read as the spectral density instead of the sampled variance: the Kalman-Bucy velocity gain
    # changes by sqrt(10) (gain ~ sqrt(q / Rc) for a double integrator)
    ratio = s["headline"]["KB velocity gain on x [1/s^2]"] / \
        s["other_readings"]["R as spectral density"]["KB velocity gain on x [1/s^2]"]
    assert ratio == pytest.approx(np.sqrt(10.0), rel=1e-6)
    for name in s["figures"]:
        assert (out / name).stat().st_size > 10_000
    report = (out / "report.md").read_text()
    assert report.splitlines()[0].endswith("(quick run)")
    assert "## Departures from the paper" in report and "cannot be reproduced" in report
    assert {d["topic"] for d in s["departures"]} >= {"ship", "lake trials (Figs. 7-9)", "R (Eq. 61-62, 35)",
                                                       "G and Q (Eq. 61-62)"}
