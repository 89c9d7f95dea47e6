"""Reader of the HSVA free-running KVLCC2 zig-zags: a small synthetic file (always runs) and the
shared records (skip when the data folder is absent)."""
import numpy as np
import pytest

from casship.io import hsva_runs, read_hsva
from casship.maneuvers import classify_maneuver

TITLE = [" HSVA, experimental data CPMC", " KVLCC2", " Z10\u00b0/10\u00b0 starting to port", " Time series of motions"]


def _write(path, rows, title=TITLE):
    text = "\n".join(title) + "\n" + "\n".join(" ".join(f"{v:.9f}" for v in row) for row in rows) + "\n"
    path.write_bytes(text.encode("cp1252"))
    return path


def _synthetic_rows(n=40, dt=0.05):
    """A model turning to port at a constant rate with the file's conventions (rudder + = to port)."""
    t = np.arange(n) * dt
    r_deg = -1.5                                        # deg/s, turning to port
    psi_deg = r_deg * t
    U = 1.18
    psi = np.radians(psi_deg)
    x = 2.0 + np.cumsum(U * np.cos(psi)) * dt
    y = np.cumsum(U * np.sin(psi)) * dt
    rows = np.column_stack([t, x, y, psi_deg, np.full(n, U), np.full(n, 0.3), np.full(n, r_deg),
                            np.full(n, -0.2), np.full(n, 10.0), np.full(n, 10.23), np.full(n, 42.0),
                            np.full(n, 1.03)])
    return rows


def test_synthetic_units_signs_and_left_out_channels(tmp_path):
    rows = _synthetic_rows()
    d = read_hsva(_write(tmp_path / "HSVA_CPMC_KVLCC2_Z_10_10_P.dat", rows))
    assert set(d.names) == {"u", "r", "x", "y", "psi", "delta", "n", "thrust", "torque"}
    assert "v" not in d and "phi" not in d                       # columns 5 and 7 are not established
    assert set(d.meta["left_out"]) == {"column 5", "column 7"}
    np.testing.assert_allclose(d.t, rows[:, 0])
    np.testing.assert_allclose(d["psi"], np.radians(rows[:, 3]))
    np.testing.assert_allclose(d["r"], np.radians(-1.5))
    # file rudder +10 deg (steering to port) is -10 deg in the MMG convention, and turns the heading down
    np.testing.assert_allclose(d["delta"], np.radians(-10.0))
    assert d.meta["rudder_sign_flipped"] and d.meta["facility"] == "HSVA"
    assert d.meta["L_pp"] == 7.0 and not d.meta["full_scale"]
    assert d.meta["maneuver"] == {"kind": "zigzag", "rudder_deg": 10.0, "heading_deg": 10.0, "first": "port"}
    kept = read_hsva(tmp_path / "HSVA_CPMC_KVLCC2_Z_10_10_P.dat", flip_rudder=False)
    np.testing.assert_array_equal(kept["delta"], -d["delta"])
    assert not kept.meta["rudder_sign_flipped"]


def test_synthetic_froude_scaling(tmp_path):
    rows = _synthetic_rows()
    path = _write(tmp_path / "z.dat", rows)
    m = read_hsva(path)
    f = read_hsva(path, full_scale=True)
    k = np.sqrt(45.7)
    np.testing.assert_allclose(f.t, m.t * k)
    np.testing.assert_allclose(f["u"], m["u"] * k)
    np.testing.assert_allclose(f["x"], m["x"] * 45.7)
    np.testing.assert_allclose(f["r"], m["r"] / k)
    np.testing.assert_allclose(f["n"], m["n"] / k)
    np.testing.assert_allclose(f["psi"], m["psi"])
    np.testing.assert_allclose(f["delta"], m["delta"])
    np.testing.assert_allclose(f["thrust"], m["thrust"] * 45.7**3 * 1.025)
    np.testing.assert_allclose(f["torque"], m["torque"] * 45.7**4 * 1.025)
    assert f.meta["L_pp"] == pytest.approx(320.0, rel=1e-3) and f.meta["full_scale"]
    # the Froude number is kept: u / sqrt(g L)
    assert f["u"][0] / np.sqrt(f.meta["L_pp"]) == pytest.approx(m["u"][0] / np.sqrt(m.meta["L_pp"]))
    # a dimensionless turning rate r L / U is kept too
    assert f["r"][0] * f.meta["L_pp"] / f["u"][0] == pytest.approx(m["r"][0] * 7.0 / m["u"][0])


def test_synthetic_bad_files(tmp_path):
    rows = _synthetic_rows(5)
    bad = rows.copy()
    bad[2, 4] = np.nan
    with pytest.raises(ValueError, match="column 4"):
        read_hsva(_write(tmp_path / "nan.dat", bad))
    with pytest.raises(ValueError, match="fields"):
        read_hsva(_write(tmp_path / "short.dat", rows[:, :11]))
    back = rows.copy()
    back[3, 0] = back[1, 0]
    with pytest.raises(ValueError, match="increase"):
        read_hsva(_write(tmp_path / "time.dat", back))
    with pytest.raises(FileNotFoundError):
        read_hsva(tmp_path / "missing.dat")
    with pytest.raises(ValueError, match="scale"):
        read_hsva(_write(tmp_path / "ok.dat", rows), full_scale=True, scale=-1.0)


# -- the shared records -------------------------------------------------------------------------
@pytest.fixture(scope="module")
def runs(data_dir):
    folder = data_dir / "kvlcc2_hsva_free"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    return hsva_runs(folder)


def test_thirteen_runs(runs):
    assert len(runs) == 13
    assert {"Z_05_01", "Z_10_10_P", "Z_10_10_S", "Z_35_05"} <= set(runs)


@pytest.mark.parametrize("name, first", [("Z_10_10_P", -1), ("Z_10_10_S", 1), ("Z_20_10_P", -1), ("Z_35_05", 1)])
def test_first_turn_direction_in_mmg_sign(runs, name, first):
    """After the flip, the first rudder has the sign of the first heading change (MMG convention)."""
    d = read_hsva(runs[name], full_scale=True)
    assert d.meta["maneuver"]["first"] == ("port" if first < 0 else "starboard")
    big = np.flatnonzero(np.abs(d["delta"]) > np.radians(3))[0]
    assert np.sign(d["delta"][big]) == first
    k = np.searchsorted(d.t, d.t[big] + 60.0)
    assert np.sign(d["psi"][k] - d["psi"][0]) == first


def test_record_checks_against_itself(runs):
    """Yaw rate = d(psi)/dt, heading = course on the straight approach, Froude-scaled approach
    speed 15.5 kn and rate 1.51 rps (full scale), classified as the titled zig-zag."""
    d = read_hsva(runs["Z_20_10_S"], full_scale=True)
    dpsi = np.gradient(np.unwrap(d["psi"]), d.t)
    assert np.corrcoef(dpsi, d["r"])[0, 1] > 0.99
    assert np.polyfit(d["r"], dpsi, 1)[0] == pytest.approx(1.0, abs=0.03)
    assert d["u"][0] == pytest.approx(15.5 * 1852 / 3600, abs=0.05)
    assert d["n"][0] == pytest.approx(10.2295 / np.sqrt(45.7), rel=1e-4)
    kind, opts = classify_maneuver(d)
    assert kind == "zigzag" and opts["heading_deg"] == pytest.approx(10.0)
    # surge from differenced positions (projected on the heading): equal on the straight approach,
    # up to about 4 % higher than the u column on average over the larger zig-zags (documented)
    xd, yd = np.gradient(d["x"], d.t), np.gradient(d["y"], d.t)
    u_pos = xd * np.cos(d["psi"]) + yd * np.sin(d["psi"])
    approach = d.t < 20.0
    np.testing.assert_allclose(u_pos[approach], d["u"][approach], rtol=0.005)
    assert 0.0 < np.mean(u_pos / d["u"] - 1) < 0.04
