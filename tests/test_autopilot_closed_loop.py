"""The closed loop as one compiled system: equal to the step-by-step reference, exported to C, Monte Carlo."""
import shutil
import subprocess
import warnings

import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap
from casship.autopilot.montecarlo import monte_carlo
from casship.runtime import compile_c, read_harness_output, write_harness

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed: C export not compiled")


@pytest.fixture(scope="module")
def otter():
    return ap.design_autopilot(cs.models.get_model("otter"))


@pytest.fixture(scope="module")
def kvlcc2():
    return ap.design_autopilot(cs.models.get_model("kvlcc2"))


def _same(a, b):
    """Largest difference over all columns (NaN where both are NaN)."""
    worst = 0.0
    for name in a.names:
        x, y = a[name], b[name]
        assert np.array_equal(np.isnan(x), np.isnan(y)), name
        ok = ~np.isnan(x)
        worst = max(worst, float(np.max(np.abs(x[ok] - y[ok]), initial=0.0)))
    return worst


@pytest.mark.parametrize("options", [dict(mode="heading"), dict(mode="course"), dict(mode="course", rate="gyro"),
                                     dict(mode="heading", estimator="raw"), dict(estimator="truth"),
                                     dict(mode="heading", wave=ap.WaveYaw(1.0, np.radians(2.0)), wave_filter=True)],
                         ids=["heading-observer", "course-ekf", "course-ekf-gyro", "heading-raw", "truth",
                              "heading-wave-filter"])
def test_compiled_loop_equals_step_by_step_reference(otter, options):
    loop = otter.closed_loop_system(**options)
    cmd, t_end, _ = ap.course_scenario("course-20", 12.0)
    fold = loop.run(cmd, t_end, seed=5)
    ref = loop.run_stepwise(cmd, t_end, seed=5)
    assert len(fold) == len(ref) == 601
    assert _same(fold, ref) < 1e-12
    assert np.ptp(fold["psi"]) > np.radians(10)          # the ship did turn


def test_compiled_loop_is_one_function_with_named_slots(kvlcc2):
    loop = kvlcc2.closed_loop_system()
    step = loop.step
    assert step.name_in() == ["s", "ref", "draws", "mask", "dt_est", "p"]
    assert step.name_out() == ["s_next", "log"]
    assert step.size_out("log")[0] == len(loop.signals)
    assert {"psi", "steer", "steer_cmd", "rate_limited", "chi_hat"} <= set(loop.signals)


@needs_gcc
def test_closed_loop_exported_to_c_equals_python(otter, tmp_path):
    loop = otter.closed_loop_system(mode="course")
    files = loop.export_c(tmp_path, "otter_loop")
    exe = compile_c([write_harness(files), files.source], tmp_path / "harness")
    n = 40
    draws = loop.draws(n, 3)
    masks = loop.schedule(n)
    s = loop.state0()
    sets, py = [], []
    for k in range(n):
        args = {"s": s, "ref": np.radians(20.0), "draws": draws[:, k], "mask": masks[:, k],
                "dt_est": 0.0 if k == 0 else loop.dt, "p": loop.plant.pvec}
        sets.append(np.concatenate([np.ravel(np.asarray(args[name], float)) for name in loop.step.name_in()]))
        out = loop.step.call(args)
        py.append(np.ravel(np.asarray(out["log"])))
        s = np.ravel(np.asarray(out["s_next"]))
    text = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in sets)
    proc = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
    c_sets = read_harness_output(proc.stdout, files)
    log_index = [name for name, _ in files.outputs].index("log")
    c_log = np.array([np.ravel(c[log_index]) for c in c_sets])
    py = np.array(py)
    ok = ~np.isnan(py)
    assert np.array_equal(np.isnan(c_log), ~ok)
    np.testing.assert_allclose(c_log[ok], py[ok], rtol=1e-12, atol=1e-12)


def test_rate_limit_warning_names_the_fraction():
    """A loop fed the raw gyro with a fast bandwidth chases the sensor noise: the steering gear runs at
    its rate limit most of the time, and the run says so."""
    d = ap.design_autopilot(cs.models.get_model("kvlcc2"), rate="gyro", wn=0.05, wn_ref=0.05, gyro_std=np.radians(0.05))
    with pytest.warns(ap.RateLimitWarning, match=r"rate limit .* \d+\.\d % of the time"):
        res = d.simulate(t_end=400.0)
    assert res.performance["rate_limited_fraction"] > 0.1
    check = [c for c in res.performance["checks"] if c["check"] == "steering-gear rate limit active"][0]
    assert not check["ok"] and not res.performance["all_ok"]


def test_monte_carlo_over_seeds_and_speeds_parallel_equals_serial():
    kw = dict(seeds=[0, 1], speeds=[1.6, 2.0], t_end=20.0)
    serial = monte_carlo("otter", workers=1, **kw)
    parallel = monte_carlo("otter", workers=2, **kw)
    assert serial["summary"] == parallel["summary"]
    assert len(serial["runs"]) == 4
    assert set(serial["summary"]) == {"1.6", "2"}
    # different noise seeds give different runs
    a, b = (r["metrics"][0]["iae_deg_s"] for r in serial["runs"][:2])
    assert a != b


def test_loop_input_errors(otter):
    with pytest.raises(ValueError, match="mode"):
        otter.closed_loop_system(mode="track")
    with pytest.raises(ValueError, match="raw"):
        otter.closed_loop_system(mode="course", estimator="raw")
    loop = otter.closed_loop_system()
    with pytest.raises(ValueError, match="finite"):
        loop.run(np.full(11, np.nan), 0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert len(loop.run(0.0, 0.2)) == 11
