"""The closed loop's readings of a loop estimator, one per kind, on numbers."""
import numpy as np

from casship.autopilot.loop_variants import READINGS, CourseReading, HeadingReading


def _ix(names):
    return lambda n: names.index(n)


def test_course_reading_measures_gnss_and_reports_the_estimate():
    rd = READINGS["course"]
    assert isinstance(rd, CourseReading) and rd.measured == ("x_n", "y_n")
    y, extra = rd.online_input((10.0, 20.0), 0.3, 0.01, np.array([1, 1]), 0.05)
    assert list(y) == [10.0, 20.0] and extra == {}
    y, _ = rd.online_input((10.0, 20.0), 0.3, 0.01, np.array([0, 1]), 0.05)
    assert np.isnan(y).all()                          # no fix: not measured
    names = ["x_n", "y_n", "chi", "omega_chi", "U"]
    xh = np.array([1.0, 2.0, 0.5, 0.01, 7.0])
    assert rd.read(xh, _ix(names), (9.0, 9.0), 3.0) == (0.5, 0.01, 1.0, 2.0, 7.0)
    assert rd.bias(xh, _ix(names), names, 0.0) == 0.0
    mean = np.zeros(5)
    rd.place(mean, _ix(names), 4.0, 5.0, 0.2, 0.03, 0.6)
    assert list(mean) == [4.0, 5.0, 0.6, 0.0, 0.0]


def test_heading_reading_is_driven_by_the_rudder_and_takes_position_from_the_fix():
    rd = READINGS["heading"]
    assert isinstance(rd, HeadingReading) and rd.measured == ("psi_m", "r_m")
    y, extra = rd.online_input((10.0, 20.0), 0.3, 0.01, np.array([1, 0]), 0.05)
    assert np.isnan(y[0]) and y[1] == 0.01 and list(extra["u_prev"]) == [0.05]
    names = ["psi", "r", "b"]
    xh = np.array([0.4, 0.02, -0.01])
    assert rd.read(xh, _ix(names), (9.0, 8.0), 3.0) == (0.4, 0.02, 9.0, 8.0, 3.0)
    assert rd.bias(xh, _ix(names), names, 0.0) == -0.01
    assert rd.bias(xh[:2], _ix(names[:2]), names[:2], 0.0) == 0.0
    mean = np.zeros(3)
    rd.place(mean, _ix(names), 4.0, 5.0, 0.2, 0.03, 0.6)
    assert list(mean) == [0.2, 0.03, 0.0]
