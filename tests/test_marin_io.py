"""Reader of the MARIN free-running KVLCC2 records (skips when the data folder is absent)."""
import numpy as np
import pytest

from casship.io.marin import marin_runs, read_marin


@pytest.fixture(scope="module")
def runs(data_dir):
    folder = data_dir / "kvlcc2_marin_free"
    if not folder.is_dir():
        pytest.skip(f"{folder} is absent")
    return marin_runs(folder)


def test_three_runs_found(runs):
    assert set(runs) == {"tc_-35", "zz_10", "zz_-20"}


def test_turning_run_units_time_and_signs(runs):
    d = read_marin(runs["tc_-35"])
    assert len(d) == 15753
    # rebuilt time: uniform step close to 0.02 s * sqrt(45.7) and within one print quantum
    assert np.ptp(np.diff(d.t)) < 1e-9
    assert d.meta["dt"] == pytest.approx(0.02 * np.sqrt(45.7), rel=2e-3)
    assert d.meta["time_residual_quanta"] < 1.0
    # rpm -> rps (about 1.53) and the approach speed in body axes
    assert d["n"][0] == pytest.approx(91.4 / 60)
    assert d["u"][0] == pytest.approx(8.01, abs=0.01)
    # the file's -35 deg rudder, flipped, is +35 deg and turns the ship to starboard
    i = np.searchsorted(d.t, 300.0)
    assert np.degrees(d["delta"][i]) == pytest.approx(35.1, abs=0.2)
    assert d["psi"][i] > np.radians(90) and d["r"][i] > 0
    # body velocities agree with differenced positions in the steady turn
    k = slice(i - 150, i + 151)      # +-20 s: positions are printed to about +-5 m
    xd = np.polyfit(d.t[k] - d.t[i], d["x"][k], 2)[1]
    yd = np.polyfit(d.t[k] - d.t[i], d["y"][k], 2)[1]
    psi = d["psi"][i]
    assert xd * np.cos(psi) + yd * np.sin(psi) == pytest.approx(d["u"][i], abs=0.1)
    # sway from positions is ~0.17 m/s more negative: the files do not say at which point the
    # positions and velocities are taken (0.17 m/s = r * 21 m), so only the sign and size agree
    assert -xd * np.sin(psi) + yd * np.cos(psi) == pytest.approx(d["v"][i], abs=0.25)
    assert d["v"][i] < 0         # outward drift at midship when turning to starboard


def test_rudder_flip_is_explicit(runs):
    a = read_marin(runs["zz_10"])
    b = read_marin(runs["zz_10"], flip_rudder=False)
    np.testing.assert_array_equal(a["delta"], -b["delta"])
    assert a.meta["rudder_sign_flipped"] and not b.meta["rudder_sign_flipped"]


def test_bad_file_raises(tmp_path):
    f = tmp_path / "bad.dat"
    f.write_text("title\ntitle\n\n1 2 3\n")
    with pytest.raises(ValueError, match="fields"):
        read_marin(f)
    with pytest.raises(FileNotFoundError):
        read_marin(tmp_path / "missing.dat")


def test_trial_table_names_the_bad_line_and_value(tmp_path):
    from pathlib import Path

    from casship.io.table import read_numeric_rows

    path = Path("trial.dat")
    title = ["title", "units"]
    good = ["0 1 2", "1 1 2", "2 1 2"]
    assert read_numeric_rows(path, title + good, 2, ["time", "a", "b"]).shape == (3, 3)
    with pytest.raises(ValueError, match=r"line 4 has 2 fields, expected 3 \(time a \?\)"):
        read_numeric_rows(path, title + ["0 1 2", "1 1"], 2, ["time", "a", None])
    with pytest.raises(ValueError, match=r"line 3 is not numeric: '0 x 2'"):
        read_numeric_rows(path, title + ["0 x 2"], 2, ["time", "a", "b"])
    with pytest.raises(ValueError, match=r"2 data row\(s\); a record needs at least 3"):
        read_numeric_rows(path, title + good[:2], 2, ["time", "a", "b"])
    with pytest.raises(ValueError, match=r"non-finite value in column 1 \(a\) at data row 2"):
        read_numeric_rows(path, title + good[:2] + ["2 nan 2"], 2, ["time", "a", "b"])
