"""Replays through shared simulation folds (casship.simulation.folds): compiled and interpreted give the same
numbers, the parameter draws run as one mapped call with the same results and failures as one
simulation each, the sensitivities compiled equal the interpreted ones and central differences, and
the Functions are built once per process per structure."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship import runtime
from casship.simulation import folds
from casship.errors import DivergenceError
from casship.identify import ParameterBelief
from casship.models import kvlcc2
from casship.simulation import sampled_metrics, trajectory_sensitivities
from casship.runtime import CompileError, Compiling, find_compiler
from casship.simulation import IntegrationError, fold_steps
from casship.maneuvers import replay

try:
    find_compiler(None)
    HAVE_CC = True
except CompileError:
    HAVE_CC = False
needs_cc = pytest.mark.skipif(not HAVE_CC, reason="no C compiler: the compiled folds cannot be built")


def _zigzag(seconds=400.0, dt=0.5):
    t = np.arange(0.0, seconds, dt)
    delta = np.radians(20.0) * np.sign(np.sin(t / 40.0) + 1e-9)
    return t, np.column_stack([delta, np.full(t.size, 1.53)])


def _steering(name: str, c: float) -> cs.Model:
    """A first-order steering model with track, a structure of its own for each ``c``."""
    b = cs.ModelBuilder(name)
    b.state("x"), b.state("y")
    psi, r = b.state("psi", angle=True), b.state("r")
    delta = b.input("delta")
    K, T, U = b.param("K", 0.1), b.param("T", 20.0), b.param("U", 5.0)
    b.ode(x=U * ca.cos(psi), y=U * ca.sin(psi), psi=r, r=(K * delta - r) / T + c * r * r + b.noise("w_r"))
    b.output("psi", psi)
    return b.build()


@needs_cc
def test_the_compiled_fold_gives_the_interpreted_states_for_one_and_many_parameter_vectors():
    ship = kvlcc2(asymmetry=True)
    t, U = _zigzag()
    dm = cs.discretize(ship, 0.5)
    x0, n = ship.states(u=7.97), t.size - 1
    W = np.zeros((n, ship.nw))
    P = np.tile(ship.params(), (5, 1))
    P[:, ship.index("N_r_dash", "param")] *= np.linspace(0.9, 1.1, 5)
    ref = [np.vstack([x0, np.asarray(dm.fold(n)(x0, U[:n].T, p, W.T, np.full((1, n), 0.5))).T]) for p in P]
    scale = max(1.0, np.abs(ref).max())
    for jit in (False, True):
        one = fold_steps(dm, x0, U, P[2], W, np.full(n, 0.5), jit=jit)
        many = fold_steps(dm, x0, U, P, W, np.full(n, 0.5), jit=jit)
        assert one.shape == (t.size, ship.nx) and many.shape == (5, t.size, ship.nx)
        assert np.abs(one - ref[2]).max() <= 1e-12 * scale, jit
        assert np.abs(many - np.array(ref)).max() <= 1e-12 * scale, jit


@needs_cc
def test_simulate_many_is_simulate_per_row_and_reports_each_failed_row():
    m = _steering("many_rows", 1.0e-3)
    t = np.arange(0.0, 300.0, 1.0)
    rudder = {"delta": np.radians(10.0) * np.sign(np.sin(t / 30.0) + 1e-9)}
    P = np.array([m.params(K=0.08), m.params(K=0.12), m.params(T=0.05), m.params(T=30.0)])   # rk4 unstable
    for jit in (False, True):
        runs = cs.simulate_many(m, m.states(), t, rudder, P, check_limits=False, jit=jit)
        assert isinstance(runs[2], DivergenceError) and "diverged at t =" in str(runs[2])
        for i in (0, 1, 3):
            ref = cs.simulate(m, m.states(), t, rudder, P[i], check_limits=False)
            for name in ("x", "y", "psi", "r"):
                assert np.abs(runs[i][name] - ref[name]).max() <= 1e-12 * max(1.0, np.abs(ref[name]).max()), name
            assert runs[i].meta["params"] == ref.meta["params"]
    with pytest.raises(ValueError, match=r"params has shape \(4, 2\), expected \(m, 3\)"):
        cs.simulate_many(m, m.states(), t, rudder, P[:, :2])


def test_simulate_many_with_an_integrator_finds_the_row_that_fails():
    b = cs.ModelBuilder("many_blowup")
    x = b.state("x")
    b.ode(x=b.param("a", 1.0) * x**2 + b.input("u"))
    m = b.build()
    t = np.arange(0.0, 3.0, 0.1)
    u = {"u": 0.01 * np.sin(t)}
    runs = cs.simulate_many(m, [1.0], t, u, np.array([[-1.0], [1.0], [-0.5]]), method="cvodes")
    assert isinstance(runs[1], IntegrationError) and runs[1].status.startswith("CV_")
    for i, a in ((0, -1.0), (2, -0.5)):
        ref = cs.simulate(m, [1.0], t, u, [a], method="cvodes")
        np.testing.assert_array_equal(runs[i]["x"], ref["x"])


def test_batched_draws_give_the_intervals_and_failures_of_one_simulation_each():
    m = _steering("many_draws", 1.0e-3)
    t = np.arange(0.0, 300.0, 1.0)
    data = cs.Dataset(t, {"delta": np.radians(10.0) * np.sign(np.sin(t / 30.0) + 1e-9)})
    unc = ParameterBelief.from_values(["K", "T"], [0.1, 1.0], [[1e-4, 0.0], [0.0, 1.0]])   # T near 0: rk4 unstable
    draws = unc.sample(m, m.params(), 40, seed=2)

    def metrics(tr):
        return {"psi_end": float(tr["psi"][-1]), "r_max": float(np.abs(tr["r"]).max())}

    def one(p):
        tr = cs.simulate(m, m.states(), t, data, p, check_limits=False)
        return metrics(tr), tr["psi"]

    def batch(P):
        runs = cs.simulate_many(m, m.states(), t, data, P, check_limits=False, jit=False)
        return [tr if isinstance(tr, Exception) else (metrics(tr), tr["psi"]) for tr in runs]

    a, b = sampled_metrics(one, draws, 0.9), sampled_metrics(batch, draws, 0.9, batch=True)
    assert a["failed"] > 0 and a["failed"] == b["failed"] and a["samples"] == b["samples"] == 40
    assert a["intervals"] == b["intervals"]
    np.testing.assert_array_equal(a["psi_std"], b["psi_std"])
    with pytest.raises(ValueError, match="1 outcome"):
        sampled_metrics(lambda P: batch(P)[:1], draws, batch=True)


@needs_cc
@pytest.mark.parametrize("jit", [False, True])
def test_compiled_sensitivities_equal_the_interpreted_ones(jit):
    ship = kvlcc2(asymmetry=True)
    t, U = _zigzag(300.0, 1.0)
    x0, names, p = ship.states(u=7.97), ["N_r_dash", "Y_v_dash", "delta_0"], ship.params()
    X, S = trajectory_sensitivities(ship, x0, t, U, p, names, jit=jit)
    X0, S0 = trajectory_sensitivities(ship, x0, t, U, p, names, jit=False)
    assert np.abs(X - X0).max() <= 1e-12 * np.abs(X0).max()
    assert np.abs(S - S0).max() <= 1e-12 * np.abs(S0).max()
    assert S.shape == (t.size, ship.nx, 3) and not S[0].any()


@needs_cc
def test_a_replay_with_bands_is_the_same_compiled_or_interpreted():
    m = _steering("replay_jit", 2.0e-3)
    t = np.arange(0.0, 400.0, 0.5)
    truth = cs.simulate(m, m.states(), t, {"delta": np.radians(15.0) * np.sign(np.sin(t / 50.0) + 1e-9)})
    data = cs.Dataset(t, {n: truth[n] for n in ("x", "y", "psi", "r", "delta")})
    unc = ParameterBelief.from_values(["K", "T"], [0.1, 20.0], [[4e-5, 0.0], [0.0, 1.0]])
    a, b = (replay(m, data, uncertainty=unc, samples=12, seed=4, jit=jit) for jit in (False, True))
    for key in ("psi_std", "x_std", "y_std"):
        assert np.abs(a.bands[key] - b.bands[key]).max() <= 1e-12 * np.abs(a.bands[key]).max(), key
    assert a.metric_intervals == b.metric_intervals and a.sampling == b.sampling
    assert np.abs(a.trajectory["psi"] - b.trajectory["psi"]).max() <= 1e-12


def test_replays_of_new_model_objects_build_no_function_again():
    t = np.arange(0.0, 200.0, 1.0)
    data = cs.Dataset(t, {"delta": np.radians(10.0) * np.sign(np.sin(t / 30.0) + 1e-9), "psi": np.zeros(t.size)})
    unc = ParameterBelief.from_values(["K"], [0.1], [[1e-5]])
    replay(_steering("shared_a", 3.0e-3), data, uncertainty=unc, samples=5, jit=False)
    built = folds.COUNTS["built"]
    replay(_steering("shared_b", 3.0e-3), data, uncertainty=unc, samples=5, jit=False)   # a new model object
    assert folds.COUNTS["built"] == built
    replay(_steering("shared_c", 3.5e-3), data, uncertainty=unc, samples=5, jit=False)   # another structure
    assert folds.COUNTS["built"] > built


def test_without_a_compiler_replays_run_interpreted_with_the_same_numbers(tmp_path, monkeypatch, request):
    m = _steering("no_compiler", 4.0e-3)                 # a structure no other test compiles
    t = np.arange(0.0, 200.0, 1.0)
    data = cs.Dataset(t, {"delta": np.radians(10.0) * np.sign(np.sin(t / 30.0) + 1e-9), "psi": np.zeros(t.size)})
    unc = ParameterBelief.from_values(["K"], [0.1], [[1e-5]])
    ref = replay(m, data, uncertainty=unc, samples=6, jit=False)
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "cache"))
    bad = tmp_path / "badcc"                              # answers --version, refuses to compile
    bad.write_text('#!/bin/sh\n[ "$1" = --version ] && echo "badcc 1.0" && exit 0\necho "badcc: refused" >&2\nexit 1\n')
    bad.chmod(0o755)
    monkeypatch.setenv("CC", str(bad))
    saved = list(runtime.BACKGROUND_FAILURES)            # this process's other tests keep compiling
    runtime.BACKGROUND_FAILURES.clear()
    request.addfinalizer(lambda: runtime.BACKGROUND_FAILURES.__setitem__(slice(None), saved))
    with pytest.warns(RuntimeWarning, match="interpreted"):
        res = replay(m, data, uncertainty=unc, samples=6)            # jit=None: compiled in the background
        for handle in [f for f in runtime.FUNCTIONS.values() if isinstance(f, Compiling)]:
            handle.wait(timeout=120)
    np.testing.assert_array_equal(res.trajectory["psi"], ref.trajectory["psi"])
    np.testing.assert_array_equal(res.bands["psi_std"], ref.bands["psi_std"])
    assert res.metric_intervals == ref.metric_intervals
    with pytest.raises(CompileError, match="badcc"):
        replay(m, data, uncertainty=unc, samples=6, jit=True)
