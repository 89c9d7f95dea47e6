"""The loop's feedback source: the same numbers as the 0.4 string branches, bit for bit."""
import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap

# Fingerprints of a 4 s "course-20" run of the Otter's default design (seed 5), recorded from the
# 0.4 code (feedback chosen by the strings "truth" / "raw" / "ekf"): final heading, sums of the fed
# angle and rate, sum of the steering command. The compiled fold and the step-by-step reference
# differ in the last bits (they round differently), so each has its own record.
RECORDED_0_4 = {
    ("course", "truth", "run"): (0.10552774718663051, 7.2222443024860645, 4.687864800555281, -212.07182639301732),
    ("course", "truth", "run_stepwise"): (0.10552774718663056, 7.222244302486087, 4.687864800555297,
                                          -212.0718263930228),
    ("heading", "truth", "run"): (0.08939539454129021, 7.1826519910591085, 4.477631178072127, -152.99722485375716),
    ("heading", "truth", "run_stepwise"): (0.08939539454129021, 7.1826519910591085, 4.477631178072127,
                                           -152.99722485375716),
    ("heading", "raw", "run"): (0.08971217286881424, 7.029873990770244, 4.49851823666009, -151.91853978381252),
    ("heading", "raw", "run_stepwise"): (0.08971217286881425, 7.0298739907702394, 4.498518236660091,
                                         -151.91853978381278),
    ("course", "ekf", "run"): (0.1048569350270582, 15.657662009418194, 3.0027228707029496, -155.75754694670422),
    ("course", "ekf", "run_stepwise"): (0.1048569350270582, 15.657662009418194, 3.0027228707029496,
                                        -155.75754694670422),
    ("heading", "ekf", "run"): (0.08913737753431693, 7.259044586201894, 4.469760816752084, -154.2055206632929),
    ("heading", "ekf", "run_stepwise"): (0.08913737753431694, 7.259044586201897, 4.469760816752083,
                                         -154.20552066329302),
}


@pytest.fixture(scope="module")
def otter():
    return ap.design_autopilot(cs.models.get_model("otter"))


def _fingerprint(data):
    return (float(data["psi"][-1]), float(np.sum(data["chi_hat"])), float(np.sum(data["omega_hat"])),
            float(np.sum(data["steer_cmd"])))


@pytest.mark.parametrize("key", sorted(RECORDED_0_4), ids=lambda k: "-".join(k))
def test_feedback_gives_the_recorded_0_4_numbers(otter, key):
    mode, estimator, runner = key
    loop = otter.closed_loop_system(mode=mode, estimator=estimator)
    cmd, t_end, _ = ap.course_scenario("course-20", 4.0)
    data = getattr(loop, runner)(cmd, t_end, seed=5)
    assert len(data) == 201
    # exact on the machine that recorded them (the refactor changes no operation); 1e-9 leaves room for
    # another libm or BLAS in the design, far below what a changed branch moves
    assert _fingerprint(data) == pytest.approx(RECORDED_0_4[key], rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("mode, shorthand, cls", [("course", "truth", ap.TrueState), ("heading", "truth", ap.TrueState),
                                                  ("heading", "raw", ap.RawMeasurement)])
@pytest.mark.parametrize("runner", ["run", "run_stepwise"])
def test_shorthand_string_and_class_give_equal_arrays(otter, mode, shorthand, cls, runner):
    by_name = otter.closed_loop_system(mode=mode, estimator=shorthand)
    by_class = otter.closed_loop_system(mode=mode, estimator=cls())
    assert by_name.estimator == cls() and type(by_class.estimator) is cls      # resolved once, at construction
    cmd, t_end, _ = ap.course_scenario("course-20", 4.0)
    a, b = getattr(by_name, runner)(cmd, t_end, seed=5), getattr(by_class, runner)(cmd, t_end, seed=5)
    assert a.names == b.names
    for name in a.names:
        assert np.array_equal(a[name], b[name], equal_nan=True), name
    assert _fingerprint(b) == pytest.approx(RECORDED_0_4[(mode, shorthand, runner)], rel=1e-9, abs=1e-12)


def test_feedback_sources_are_exported_values():
    assert {"TrueState", "RawMeasurement", "LoopFeedback"} <= set(ap.__all__)
    assert ap.TrueState() == ap.TrueState() and hash(ap.RawMeasurement()) == hash(ap.RawMeasurement())
    assert ap.RawMeasurement().modes == ("heading",) and ap.TrueState().modes == ("course", "heading")
    with pytest.raises(AttributeError):
        ap.TrueState().modes = ("course",)                                       # frozen


def test_unknown_or_unsupported_feedback_is_named(otter):
    with pytest.raises(cs.errors.InputError, match="'kalman'") as err:
        otter.closed_loop_system(mode="heading", estimator="kalman")
    assert "'kalman'" in str(err.value) and "'raw'" in str(err.value) and "'truth'" in str(err.value)
    with pytest.raises(cs.errors.InputError, match="'course'") as err:
        otter.closed_loop_system(mode="course", estimator=ap.RawMeasurement())
    assert "RawMeasurement" in str(err.value)
    with pytest.raises(cs.errors.InputTypeError, match="int"):
        otter.closed_loop_system(mode="heading", estimator=3)
    heading_est = otter.estimator("heading")
    with pytest.raises(cs.errors.InputError, match="heading estimator cannot feed a course autopilot"):
        otter.closed_loop_system(mode="course", estimator=heading_est)


def test_true_state_reads_course_or_heading_by_hand():
    """Course: the backward difference across +-pi (the yaw rate on the first sample); heading: psi and r."""
    from casship.autopilot.loop_variants import READINGS

    meas = {"psi": 0.3, "r": 0.02}
    course, heading = READINGS["course"], READINGS["heading"]
    angle, rate = course.true_numeric(meas, -3.1, 3.1, 0.5, 0.5)
    assert angle == -3.1 and rate == pytest.approx((2 * np.pi - 6.2) / 0.5, rel=1e-12)
    assert course.true_numeric(meas, -3.1, 3.1, 0.0, 0.5) == (-3.1, 0.02)         # first sample
    assert heading.true_numeric(meas, -3.1, 3.1, 0.5, 0.5) == (0.3, 0.02)
    assert heading.start_angle(3 * np.pi / 2, lambda: pytest.fail("course not needed")) == pytest.approx(-np.pi / 2)
    assert course.start_angle(0.3, lambda: 0.25) == 0.25
