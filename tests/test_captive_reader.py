"""casship.io.read_captive: the record, its conventions, and errors that name the file and column."""
from __future__ import annotations

import numpy as np
import pytest

from casship.errors import InputError
from casship.io import read_captive
from casship.io.captive import HARMONICS

from captive_records import write_tables


def test_reads_tables_and_converts_conventions(tmp_path):
    t = read_captive(write_tables(tmp_path / "c"))
    # run 3 is in static_drift and drift_rudder with the same numbers: kept once
    assert list(t.static.run) == [1, 2, 3, 4, 5]
    assert t.static.kind == ("static_rudder", "static_rudder", "static_drift", "static_drift", "drift_rudder")
    # the tables count the rudder the other way: +10 deg there is -10 deg in casship's sign
    assert t.static.delta[0] == pytest.approx(-np.radians(10))
    assert t.static.delta[4] == pytest.approx(np.radians(10))
    assert t.static.beta[2] == pytest.approx(np.radians(10))
    # pure yaw run 7 repeated in yaw_drift at drift 0: one test; run 8 copied at 12 deg: not measured
    assert list(t.dynamic.run) == [6, 7, 8, 8]
    assert t.dynamic.kind == ("pure_sway", "pure_yaw", "yaw_drift", "yaw_drift")
    assert np.all(np.isfinite(t.dynamic.components["Y"][2]))
    assert np.all(np.isnan(t.dynamic.components["Y"][3]))
    assert any("run 8" in n and "not measured" in n for n in t.notes)
    # the component order: mean, in1, out1, ... from the columns X_mean, X_in, X_out, ...
    assert t.dynamic.components["X"][0, HARMONICS.index("in1")] == pytest.approx(np.linspace(1e-4, 4.2e-3, 42)[1])
    assert t.dynamic.components["Y"][0, 0] == pytest.approx(np.linspace(1e-4, 4.2e-3, 42)[7])
    assert np.isnan(t.dynamic.r_amp[0]) and t.dynamic.vdot_amp[0] == -0.1
    assert "pure_yaw=1" in repr(t)


def test_missing_file_is_named(tmp_path):
    folder = write_tables(tmp_path / "c")
    (folder / "pure_yaw.csv").unlink()
    with pytest.raises(InputError, match="pure_yaw.csv"):
        read_captive(folder)
    with pytest.raises(InputError, match="folder not found"):
        read_captive(tmp_path / "nowhere")


def test_missing_column_is_named(tmp_path):
    folder = write_tables(tmp_path / "c")
    path = folder / "static_drift.csv"
    path.write_text(path.read_text().replace("N_prime", "Nprime", 1))
    with pytest.raises(InputError, match=r"static_drift.csv.*'N_prime'"):
        read_captive(folder)


def test_non_numeric_field_names_file_column_and_row(tmp_path):
    folder = write_tables(tmp_path / "c")
    path = folder / "pure_sway.csv"
    lines = path.read_text().splitlines()
    fields = lines[1].split(",")
    fields[4] = "n/a"                                  # vdot_prime
    lines[1] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=r"pure_sway.csv: column 'vdot_prime', data row 1: not a number"):
        read_captive(folder)


def test_wrong_file_is_refused(tmp_path):
    """A table of another test under a captive name misses that test's columns."""
    folder = write_tables(tmp_path / "c")
    (folder / "pure_yaw.csv").write_text((folder / "pure_sway.csv").read_text())
    with pytest.raises(InputError, match=r"pure_yaw.csv: missing column\(s\) \['r_prime', 'rdot_prime'\]"):
        read_captive(folder)


def test_one_run_with_two_sets_of_numbers_is_refused(tmp_path):
    folder = write_tables(tmp_path / "c")
    path = folder / "drift_rudder.csv"
    path.write_text(path.read_text().replace("3,10,0,1.17,9.9,0.001", "3,10,0,1.17,9.9,0.002"))
    with pytest.raises(InputError, match="run 3"):
        read_captive(folder)


@pytest.mark.data
def test_reads_the_hmri_series(data_dir):
    folder = data_dir / "kvlcc2_hmri_captive"
    if not folder.is_dir():
        pytest.skip(f"{folder} absent")
    t = read_captive(folder)
    assert len(t.static) == 63 and len(t.dynamic) == 26
    counts = {k: len(t.dynamic.select(k)) for k in ("pure_sway", "pure_yaw", "yaw_drift")}
    assert counts == {"pure_sway": 4, "pure_yaw": 6, "yaw_drift": 16}
    # the copy of run 279 at drift 16 deg is not measured
    copy = [i for i in range(len(t.dynamic)) if t.dynamic.run[i] == 279 and np.isclose(t.dynamic.beta[i], np.radians(16))]
    assert len(copy) == 1 and np.all(np.isnan(t.dynamic.components["N"][copy[0]]))
    assert t.open_water["K_T"][0] == pytest.approx(0.3113)
    # rudder sign: casship's positive rudder turns to starboard (positive yaw moment)
    i = int(np.argmax(t.static.delta * (t.static.kind == np.array(["static_rudder"] * len(t.static)))))
    assert t.static.forces["N"][i] > 0


@pytest.mark.data
def test_non_dimensionalisation_from_the_data(data_dir):
    """With forces over 0.5 rho U^2 L^2 (moments L^3) and the rigid-body inertia in the dynamic
    components, the first harmonics give added mass and inertia near the published ones; with the
    inertia taken as subtracted they would be 2-3 times larger."""
    from casship.identify.captive import linear_derivatives

    folder = data_dir / "kvlcc2_hmri_captive"
    if not folder.is_dir():
        pytest.skip(f"{folder} absent")
    L = 6.8279
    lin = linear_derivatives(read_captive(folder), L=L, T=0.448, mass=3123.0, rho=998.5, x_G=0.035 * L, I_z=9516.0)
    assert lin["m_y_dash"] == pytest.approx(0.223, rel=0.1)
    assert lin["J_z_dash"] == pytest.approx(0.011, rel=0.15)
    assert lin["m_y_dash_if_inertia_subtracted"] > 2 * 0.223
    assert lin["Y_v_static_dash"] == pytest.approx(-0.315, rel=0.1)
    assert lin["N_v_static_dash"] == pytest.approx(-0.137, rel=0.1)
    assert lin["N_r_dash"] == pytest.approx(-0.049, rel=0.15)
