"""NMEA 0183 reader, WGS-84 local frame, CSV with units; a real GNSS log round trip through NMEA."""
from __future__ import annotations

from datetime import datetime, timedelta, timezone

import numpy as np
import pynmea2
import pytest

import casship as cs
from casship.frames import latlon_to_ne
from casship.io import NMEAError, geodetic_to_ne, ne_to_geodetic, read_csv, read_nmea
from casship.io.nmea import KNOT


# -- a test helper that writes NMEA sentences ----------------------------------------------------------
def _dm(value_deg: float, kind: str) -> tuple[str, str]:
    hemi = ("N" if value_deg >= 0 else "S") if kind == "lat" else ("E" if value_deg >= 0 else "W")
    a = abs(value_deg)
    deg = int(a)
    minutes = (a - deg) * 60.0
    if round(minutes, 6) >= 60.0:
        deg, minutes = deg + 1, 0.0
    return (f"{deg:02d}" if kind == "lat" else f"{deg:03d}") + f"{minutes:09.6f}", hemi


def nmea_log(t, lat_deg, lon_deg, *, start: datetime, sog_kn=None, cog_deg=None, heading_deg=None) -> str:
    """GGA + RMC (+ HDT) sentences, one epoch per time stamp, with checksums (via pynmea2)."""
    lines = []
    for k, tk in enumerate(t):
        stamp = start + timedelta(seconds=float(tk))
        hms = stamp.strftime("%H%M%S") + f".{int(round(stamp.microsecond / 1e4)):02d}"
        lat, lat_h = _dm(lat_deg[k], "lat")
        lon, lon_h = _dm(lon_deg[k], "lon")
        lines.append(str(pynmea2.GGA("GP", "GGA", (hms, lat, lat_h, lon, lon_h, "1", "09", "0.8", "3.0", "M",
                                                   "0.0", "M", "", ""))))
        sog = "" if sog_kn is None else f"{sog_kn[k]:.3f}"
        cog = "" if cog_deg is None else f"{cog_deg[k] % 360.0:.2f}"
        lines.append(str(pynmea2.RMC("GP", "RMC", (hms, "A", lat, lat_h, lon, lon_h, sog, cog,
                                                   stamp.strftime("%d%m%y"), "", "", "A"))))
        if heading_deg is not None:
            lines.append(str(pynmea2.HDT("HE", "HDT", (f"{heading_deg[k] % 360.0:.2f}", "T"))))
    return "\n".join(lines) + "\n"


GOOD = ("$GPGGA,235959.50,6325.8000,N,01023.5000,E,1,08,0.9,5.0,M,0.0,M,,*53\n"
        "$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K*48\n"
        "$HEHDT,274.07,T*19\n"
        "$GPGGA,000000.00,6325.8010,N,01023.5010,E,1,08,0.9,5.0,M,0.0,M,,*57\n"
        "$HCHDG,101.1,,,7.1,W*3C\n")


def test_sentences_columns_units_and_midnight_rollover():
    data = read_nmea(GOOD)
    assert np.allclose(data.t, [0.0, 0.5])
    assert data.meta["start_time_of_day_s"] == pytest.approx(86399.5)
    assert data["lat"][0] == pytest.approx(np.radians(63 + 25.8 / 60))
    assert data["lon"][0] == pytest.approx(np.radians(10 + 23.5 / 60))
    assert data["sog"][0] == pytest.approx(5.5 * 1852 / 3600)
    assert data["cog"][0] == pytest.approx(np.radians(54.7))
    assert data["psi"][0] == pytest.approx(cs.wrap(np.radians(274.07)))
    # HDG with variation 7.1 W: true = magnetic - 7.1 deg
    assert data["psi"][1] == pytest.approx(np.radians(101.1 - 7.1))
    assert np.isnan(data["sog"][1])
    assert data["x_n"][0] == 0.0 and data["y_n"][0] == 0.0
    assert data["x_n"][1] == pytest.approx(0.001 / 60 * np.pi / 180 * 6.36e6, rel=0.01)
    assert data.units["sog"] == "m/s" and data.units["psi"] == "rad"


def test_southern_western_hemispheres_and_no_fix():
    log = ("$GPGGA,120000,3351.000,S,07040.000,W,1,05,1.0,10.0,M,,M,,*62\n"
           "$GPGGA,120001,,,,,0,00,,,M,,M,,*64\n")
    data = read_nmea(log)
    assert data["lat"][0] == pytest.approx(-np.radians(33 + 51 / 60))
    assert data["lon"][0] == pytest.approx(-np.radians(70 + 40 / 60))
    assert np.isnan(data["lat"][1]) and np.isnan(data["x_n"][1])   # no fix = not measured
    assert data["fix_quality"].tolist() == [1.0, 0.0]


@pytest.mark.parametrize("line, reason", [
    ("$GPGGA,235959.50,6325.8000,N,01023.5000,E,1,08,0.9,5.0,M,0.0,M,,*5C", "checksum"),
    ("$GPGGA,23595x.50,6325.8000,N,01023.5000,E,1,08,0.9,5.0,M,0.0,M,,", "time stamp"),
    ("$GPGGA,235959.50,6325.8000,Q,01023.5000,E,1,08,0.9,5.0,M,0.0,M,,", "hemisphere"),
    ("$GPGGA,235959.50,6375.8000,N,01023.5000,E,1,08,0.9,5.0,M,0.0,M,,", "minutes"),
    ("$GPRMC,235959.50,A,6325.8000,N,01023.5000,E,abc,054.7,230394,,,A", "speed over ground"),
    ("GPGGA,235959.50,6325.8000,N", "does not start"),
    ("$HEHDT,27x.07,T", "heading"),
])
def test_malformed_line_raises_with_line_number(line, reason):
    log = GOOD.splitlines()
    log.insert(2, line)
    with pytest.raises(NMEAError, match=reason) as info:
        read_nmea("\n".join(log))
    assert info.value.line_number == 3
    assert "line 3" in str(info.value)


def test_skip_bad_reports_skipped_lines():
    log = GOOD.splitlines()
    log.insert(1, "$GPGGA,235959.50,6325.8000,N,01023.5000,E,1,08,0.9,5.0,M,0.0,M,,*5C")
    log.insert(4, "not nmea at all")
    with pytest.warns(UserWarning, match="skipped 2 malformed line"):
        data = read_nmea("\n".join(log), skip_bad=True)
    assert [k for k, _ in data.meta["nmea"]["skipped"]] == [2, 5]
    assert len(data) == 2          # the good lines are all there


def test_time_going_back_is_an_error_and_unsupported_sentences_are_counted():
    log = GOOD + "$GPGGA,000000.00,6325.8010,N,01023.5010,E,1,08,0.9,5.0,M,0.0,M,,*57\n"
    data = read_nmea(log)         # repeated time stamp: same epoch, value superseded and counted
    assert len(data) == 2 and data.meta["nmea"]["superseded"]["lat"] == 1
    for stamp in ("235958.00", "235959.00"):         # back across midnight, back within the day
        back = GOOD.splitlines() + [f"$GPGGA,{stamp},6325.8010,N,01023.5010,E,1,08,0.9,5.0,M,0.0,M,,"]
        with pytest.raises(NMEAError, match="goes back") as info:
            read_nmea(back)
        assert info.value.line_number == 6
    within = ["$GPGGA,120001,3351.000,S,07040.000,W,1,05,1.0,10.0,M,,M,,",
              "$GPGGA,120000,3351.000,S,07040.000,W,1,05,1.0,10.0,M,,M,,"]
    with pytest.raises(NMEAError, match="goes back from 43201.000 s"):
        read_nmea(within)
    data = read_nmea(GOOD + "$GPGSA,A,3,04,05,,09,12,,,24,,,,,2.5,1.3,2.1*39\n")
    assert data.meta["nmea"]["ignored"] == {"GSA": 1}
    with pytest.raises(NMEAError, match="no checksum"):
        read_nmea(["$HEHDT,274.07,T"], require_checksum=True)
    with pytest.raises(ValueError, match="no time-stamped"):
        read_nmea(["$HEHDT,274.07,T*19"])


def test_geodesy_against_independent_formula():
    lat0, lon0 = np.radians(26.0666), np.radians(119.162)
    errors = []
    for span in (0.01, 0.001):                      # about 1 km and 100 m from the origin
        lat = lat0 + np.radians(np.linspace(-span, span, 7))
        lon = lon0 + np.radians(np.linspace(span, -span, 7))
        n, e = geodetic_to_ne(lat, lon, lat0, lon0)
        n2, e2 = latlon_to_ne(lat, lon, lat0, lon0)  # first-order WGS-84 radii, independent code
        errors.append(max(np.max(np.abs(n - n2)), np.max(np.abs(e - e2))))
    # the flat-earth formula is exact to first order: its error shrinks with the square of the distance
    assert errors[1] < 2e-3
    assert 80 < errors[0] / errors[1] < 120
    lat_b, lon_b = ne_to_geodetic(n, e, lat0, lon0)
    assert np.max(np.abs(lat_b - lat)) < 1e-9 and np.max(np.abs(lon_b - lon)) < 1e-9
    with pytest.raises(ValueError, match="degrees given"):
        geodetic_to_ne(np.array([45.0]), np.array([10.0]), 0.0, 0.0)


def test_read_csv_units_names_and_errors(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("time_ms,heading,speed,rev,lat,lon\n0,350,10,60,60.0,10.0\n500,10,12,90,60.001,10.0\n")
    data = read_csv(path, {"psi": "heading:deg", "U": "speed:kn", "n": "rev:rpm", "lat": "lat:deg",
                           "lon": "lon:deg"}, time="time_ms:ms", wrap=["psi"], latlon=("lat", "lon"))
    assert np.allclose(data.t, [0.0, 0.5])
    assert np.allclose(data["psi"], np.radians([-10.0, 10.0]))
    assert np.allclose(data["U"], np.array([10.0, 12.0]) * 1852 / 3600)
    assert np.allclose(data["n"], [1.0, 1.5])
    assert data["x_n"][1] == pytest.approx(111.41, abs=0.05) and data.units["n"] == "1/s"
    with pytest.raises(ValueError, match="unknown unit 'furlong'"):
        read_csv(path, {"U": "speed:furlong"}, time="time_ms:ms")
    with pytest.raises(ValueError, match="unknown source column 'spd'"):
        read_csv(path, {"U": "spd:kn"}, time="time_ms:ms")
    with pytest.raises(ValueError, match="no time column 't'"):
        read_csv(path, {"U": "speed:kn"})
    with pytest.raises(ValueError, match="not an angle"):
        read_csv(path, {"U": "speed:kn"}, time="time_ms:ms", wrap=["U"])


def test_usv_gnss_log_round_trip_through_nmea_and_sog_cog_ekf(data_dir, tmp_path):
    """The real USV GNSS log written out as NMEA, read back, filtered to SOG/COG by the 5-state EKF.

    The log's ``speed`` column is consistent with knots (its values are 1.9 times the speed the
    positions show, and 1 kn = 0.514 m/s), so it is written into the knots field of RMC as is.
    """
    src = read_csv(data_dir / "usv_fuzhou_gnss" / "zigzag_30_inter_xy.csv",
                   {"lat": "lat:deg", "lon": "lon:deg", "speed_kn": "speed", "heading": "heading"},
                   time="time:s")
    start = datetime(2021, 6, 10, 23, 58, 30, tzinfo=timezone.utc)       # crosses midnight
    path = tmp_path / "usv.nmea"
    path.write_text(nmea_log(src.t, np.degrees(src["lat"]), np.degrees(src["lon"]), start=start,
                             sog_kn=src["speed_kn"], heading_deg=src["heading"]))
    data = read_nmea(path)
    assert len(data) == len(src)
    assert np.max(np.abs(data.t - src.t)) < 0.006                      # 1/100 s time stamps
    assert datetime.fromisoformat(data.meta["start_utc"]) == start
    assert np.max(np.abs(data["lat"] - src["lat"])) < np.radians(1e-6 / 60 * 1.01)
    n_ref, e_ref = geodetic_to_ne(src["lat"], src["lon"], src["lat"][0], src["lon"][0])
    assert np.max(np.hypot(data["x_n"] - n_ref, data["y_n"] - e_ref)) < 0.01
    assert np.allclose(data["sog"], src["speed_kn"] * KNOT, atol=0.001 * KNOT)
    assert np.allclose(cs.wrap(data["psi"] - np.radians(src["heading"])), 0.0, atol=np.radians(0.006))

    model = cs.models.sog_cog()
    ekf = cs.EKF(cs.discretize(model, 0.5, "euler"), Q=np.diag([0.01, 0.01]), R=np.diag([0.1**2, 0.1**2]),
                 measured=["x_n", "y_n"])
    prior = cs.Gaussian(model.states(x_n=data["x_n"][0], y_n=data["y_n"][0], U=1.0),
                        np.diag([1.0, 1.0, 1.0, np.pi**2, 0.01]))
    res = ekf.filter(data.select(["x_n", "y_n"]), prior)
    settled = data.t > 20.0
    err_u = res["U"][settled] - data["sog"][settled]
    assert np.sqrt(np.mean(err_u**2)) < 0.1            # SOG from positions vs the logged speed
    assert abs(np.mean(err_u)) < 0.03
    # COG against the course of the positions over +-2 s (an independent, model-free estimate)
    k = np.arange(4, len(data) - 4)
    chi_fd = np.arctan2(data["y_n"][k + 4] - data["y_n"][k - 4], data["x_n"][k + 4] - data["x_n"][k - 4])
    ok = data.t[k] > 20.0
    err_chi = cs.wrap(res["chi"][k][ok] - chi_fd[ok])
    assert np.degrees(np.sqrt(np.mean(err_chi**2))) < 10.0
    assert res.health().ok


def test_hdg_without_variation_is_magnetic_and_vtg_in_km_per_h():
    log = ("$GPGGA,120000,3351.000,S,07040.000,W,1,05,1.0,10.0,M,,M,,*62\n"
           "$HCHDG,98.5,2.0,E,,*1F\n"                      # deviation 2 E, no variation
           "$GPVTG,10.0,T,,M,,N,18.52,K,A*1C\n"            # speed only in km/h
           "$GPGGA,120001,3351.000,S,07040.000,W,1,05,1.0,10.0,M,,M,,*63\n"
           "$GPVTG,,T,,M,,N,,K,N*2C\n")                    # mode N: not valid, not used
    data = read_nmea(log)
    assert "psi" not in data.names
    assert data["psi_mag"][0] == pytest.approx(np.radians(100.5))
    assert data["sog"][0] == pytest.approx(18.52 / 3.6)
    assert data["cog"][0] == pytest.approx(np.radians(10.0))
    assert np.isnan(data["sog"][1]) and np.isnan(data["psi_mag"][1])


def test_data_import_guide_runs_as_written(tmp_path, monkeypatch):
    """The Python blocks of docs/data.md, run in order (they write their own small files)."""
    import re
    from pathlib import Path

    page = Path(__file__).resolve().parents[1] / "docs" / "data.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), re.S)
    assert len(blocks) >= 3
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for block in blocks:
        if block.startswith("# needs the measured data") and not _have_data():
            continue          # the blocks that read ../shared/data run where it is
        exec(compile(block, str(page), "exec"), namespace)
    # the guide's EKF recovers the boat's 2 m/s and its final course (0.3 deg/s for 119 s)
    result = namespace["result"]
    assert abs(result["U"][-1] - 2.0) < 0.1
    assert abs(np.degrees(result["chi"][-1]) - 0.3 * 119) < 2.0


def test_ais_and_proprietary_sentences_are_checked_and_counted_not_used():
    ais = "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C"
    log = GOOD + ais + "\n$PGRME,15.0,M,45.0,M,25.0,M*1C\n"
    data = read_nmea(log)
    assert data.meta["nmea"]["ignored"] == {"VDM": 1, "GRME": 1}
    with pytest.raises(NMEAError, match="checksum") as info:
        read_nmea(GOOD + ais.replace("*5C", "*5D") + "\n")
    assert info.value.line_number == 6


def test_sources_path_text_single_sentence_stream_and_lines(tmp_path):
    import io

    path = tmp_path / "log.nmea"
    path.write_text(GOOD)
    ref = read_nmea(path)
    for source in (str(path), GOOD, io.StringIO(GOOD), GOOD.splitlines()):
        data = read_nmea(source)
        assert np.array_equal(data.t, ref.t) and np.allclose(data["lat"], ref["lat"])
    one = read_nmea(GOOD.splitlines()[0])                 # a single sentence is text, not a file name
    assert len(one) == 1
    with pytest.raises(FileNotFoundError):
        read_nmea(tmp_path / "missing.nmea")


def _have_data() -> bool:
    """Whether the measured data are here (the docs' blocks marked "# needs the measured data" need them)."""
    from casship.io import data_dir

    try:
        return data_dir() is not None
    except FileNotFoundError:
        return False
