"""Compiling in the background: interpreted until the library is loaded, then compiled, the same
numbers either way (so a fit does not depend on when it switches); a failed compile stays
interpreted and says why."""
import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship import runtime
from casship.identify import MLEProblem
from casship.identify import _engine
from casship.runtime import Compiling, cached_function, compile_in_background


def _function(name="bg_twice"):
    x = ca.SX.sym("x", 3)
    return ca.Function(name, [x], [ca.sin(x) * 2 + x ** 2], ["x"], ["y"])


def test_interpreted_until_compiled_then_the_compiled_function(tmp_path, monkeypatch):
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "cache"))
    fun = _function()
    assert cached_function(fun) is None                      # nothing compiled yet: no wait, no compile
    seen = []
    handle = compile_in_background(fun, on_done=seen.append)
    assert isinstance(handle, Compiling)
    assert handle.function is fun or handle.ready             # interpreted while the compiler works
    compiled = handle.wait(timeout=120)
    assert handle.done and handle.ready and handle.error is None and seen == [handle]
    assert compiled is not fun and compiled.name() == fun.name()
    v = np.array([0.3, -1.2, 2.0])
    np.testing.assert_array_equal(np.array(compiled(v)).ravel(), np.array(fun(v)).ravel())
    # now in the cache: looked up at once by the same process and by the on-disk cache
    assert cached_function(fun) is not None


def test_a_failed_compile_stays_interpreted_with_its_reason(tmp_path, monkeypatch):
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "cache"))
    bad = tmp_path / "badcc"                     # answers --version, refuses to compile
    bad.write_text('#!/bin/sh\n[ "$1" = --version ] && echo "badcc 1.0" && exit 0\necho "badcc: refused" >&2\nexit 1\n')
    bad.chmod(0o755)
    monkeypatch.setenv("CC", str(bad))
    fun = _function("bg_broken")
    handle = compile_in_background(fun)
    assert handle.wait(timeout=60) is fun
    assert handle.done and not handle.ready
    assert "bg_broken" in str(handle.error), handle.error
    assert cached_function(fun) is None


def _records():
    m = cs.models.nomoto_first_order(K=0.08, T=20.0)
    out = []
    for seed in (1, 2):
        rng = np.random.default_rng(seed)
        t = np.arange(200) * 0.5
        tr = cs.simulate(m, m.states(), t, {"delta": np.radians(10.0) * np.sign(np.sin(t / 15.0))},
                         w=np.sqrt(1e-7) * rng.standard_normal((t.size, m.nw)))
        out.append(cs.measure(tr, m, {"psi": 0.01}, seed=rng))
    return m, out


def test_interpreted_and_compiled_likelihoods_agree_to_the_last_bit():
    """The premise of switching mid-fit: with identification's flags both evaluations are identical."""
    m, data = _records()
    ekf = cs.EKF(cs.discretize(m, 0.5), Q=1e-7, R=1e-4)
    prior = cs.Gaussian([0.0, 0.0], [1e-4, 1e-8])
    at = {"K": 0.06, "T": 14.0}
    vm = MLEProblem(ekf, data, free=["K", "T"], x0=prior, jit=False)
    cc = MLEProblem(ekf, data, free=["K", "T"], x0=prior, jit=True)
    assert vm.negloglik(at) == cc.negloglik(at)
    f_vm, g_vm, H_vm, _ = vm.engine.derivatives(vm.space.theta(at))
    f_cc, g_cc, H_cc, _ = cc.engine.derivatives(cc.space.theta(at))
    assert f_vm == f_cc
    np.testing.assert_array_equal(g_vm, g_cc)
    np.testing.assert_array_equal(H_vm, H_cc)


def test_first_fit_on_an_empty_cache_runs_while_compiling_and_equals_the_interpreted_fit(tmp_path, monkeypatch):
    m, data = _records()
    ekf = cs.EKF(cs.discretize(m, 0.5), Q=1e-7, R=1e-4)
    prior = cs.Gaussian([0.0, 0.0], [1e-4, 1e-8])
    guess = {"K": 0.05, "T": 10.0}
    ref = MLEProblem(ekf, data, free=["K", "T"], x0=prior, jit=False).solve(guess=guess)
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "cache"))
    prob = MLEProblem(ekf, data, free=["K", "T"], x0=prior)            # default: compiled through the cache
    fit = prob.solve(guess=guess)
    for name in ("K", "T"):
        assert fit.estimates[name] == ref.estimates[name]
        assert fit.std_errors[name] == ref.std_errors[name]
    handles = [f for f in prob.engine.functions().values() if isinstance(f, Compiling)]
    assert handles, "an empty cache compiles in the background"
    for h in handles:
        h.wait(timeout=300)
        assert h.ready, h.error
    runtime.FUNCTIONS.clear()                                           # as a new process would start
    again = MLEProblem(ekf, data, free=["K", "T"], x0=prior)
    assert again.solve(guess=guess).estimates["K"] == ref.estimates["K"]
    assert again.engine.functions()
    assert not any(isinstance(f, Compiling) for f in again.engine.functions().values())   # loaded from the cache


def test_output_error_interpreted_and_compiled_agree_to_the_last_bit():
    from casship.identify import OutputErrorProblem

    m, data = _records()
    at = {"K": 0.06, "T": 14.0}
    probs = [OutputErrorProblem(m, data, free=["K", "T"], sigma={"psi": 0.01}, jit=jit) for jit in (False, True)]
    (f0, g0, H0, _), (f1, g1, H1, _) = (p.engine.derivatives(p.space.theta(at)) for p in probs)
    assert f0 == f1
    np.testing.assert_array_equal(g0, g1)
    np.testing.assert_array_equal(H0, H1)


def _child_compiles(conn):
    """In a forked child: a compile must not wait for a lock the parent's compiling thread held."""
    from casship.runtime import compile_function

    f = compile_function(_function("bg_in_child"))
    conn.send(float(np.array(f([1.0, 2.0, 3.0]))[0, 0]))
    conn.close()


def test_a_child_forked_during_a_background_compile_can_compile(tmp_path, monkeypatch):
    import multiprocessing as mp

    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "cache"))
    import time

    handle = compile_in_background(_function("bg_parent_slow"))
    time.sleep(0.05)                         # the parent's worker now holds the cache's lock, compiling
    ctx = mp.get_context("fork")
    here, there = ctx.Pipe()
    child = ctx.Process(target=_child_compiles, args=(there,))
    child.start()
    assert here.poll(120), "the forked child hung waiting for the parent's compile lock"
    assert here.recv() == pytest.approx(2 * np.sin(1.0) + 1.0)
    child.join(30)
    assert child.exitcode == 0
    handle.wait(timeout=120)
