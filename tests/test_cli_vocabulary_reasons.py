"""Where a number is missing, the output says why: a manoeuvre metric on one side only, a failed
parameter draw."""
import numpy as np

from casship.simulation import sampled_metrics
from casship.maneuvers.replay import _metric_notes, why_absent


def test_why_a_metric_is_absent():
    assert why_absent("overshoot_2_deg") == "the record ends before the heading turns back after the 2nd overshoot"
    assert "three rudder reversals" in why_absent("period_s")
    assert "180 deg" in why_absent("tactical_diameter_m")
    assert why_absent("something_else") == "not reached in this record"


def test_notes_name_the_side_and_the_reason():
    replayed = {"overshoot_1_deg": 6.9, "period_s": 431.0, "first_side": 1, "overshoot_1_time_s": 50.0}
    measured = {"overshoot_1_deg": 9.3, "overshoot_2_deg": 15.2}
    notes = _metric_notes(replayed, measured, {"replayed": None, "measured": None})
    assert notes == {"period_s": "measured: " + why_absent("period_s"),
                     "overshoot_2_deg": "replayed: " + why_absent("overshoot_2_deg")}
    # when no metric could be taken at all, the metric function's own reason is given
    notes = _metric_notes(replayed, {}, {"measured": "the heading never changes by 10 deg after the execute"})
    assert notes["period_s"] == "measured: the heading never changes by 10 deg after the execute"


def test_failed_draws_say_why():
    def run(p):
        if p[0] < 0:
            raise FloatingPointError("the simulation diverged at t = 12 s")
        return {"a": float(p[0])}, None

    draws = np.array([[1.0], [-1.0], [2.0], [-2.0], [3.0]])
    s = sampled_metrics(run, draws, 0.9)
    assert s["failed"] == 2 and s["failures"] == {"the simulation diverged at t = 12 s": 2}
