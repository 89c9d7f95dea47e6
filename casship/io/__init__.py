"""Data import: NMEA 0183 logs, CSV files/pandas frames with units, MARIN and HSVA free-running
records, captive (PMM) model tests, WGS-84 local frames; :func:`read_record` reads any of them by format."""
from .csv import UNITS, from_frame, read_csv
from .datadir import DATA_ENV, data_dir
from .geodesy import geodetic_to_ne, ne_to_geodetic
from .nmea import NMEAError, read_nmea
from .marin import marin_runs, read_marin
from .hsva import hsva_runs, read_hsva
from .record import RECORD_FORMATS, read_record, record_format
from .captive import CaptiveTests, read_captive

__all__ = ["read_nmea", "NMEAError", "read_csv", "from_frame", "UNITS", "geodetic_to_ne", "ne_to_geodetic", "read_marin", "marin_runs",
           "data_dir", "DATA_ENV", "read_hsva", "hsva_runs", "read_record", "record_format", "RECORD_FORMATS",
           "read_captive", "CaptiveTests"]
