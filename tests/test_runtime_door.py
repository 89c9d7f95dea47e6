"""One door for compiling: outside ``casship/runtime/`` nothing compiles, keeps a Function table of its own,
or runs a chunk-and-pad driver of its own; ``jit`` means one thing wherever it is accepted."""
from __future__ import annotations

import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship.errors import InputError
from casship.runtime import JitPolicy, fold_chunk, pieces

ROOT = Path(__file__).resolve().parents[1]
RUNTIME = ROOT / "casship" / "runtime"

#: What only the runtime may do: compile (or look compiled code up), keep a table of shared Functions,
#: build a compiled record loop, run a fold in pieces; and the fold chunk constants of before.
DOOR = re.compile(r"\b(compile_function|compile_in_background|cached_function|NativeFold|BoundedTable|"
                  r"FOLD_CHUNK|CHUNK)\s*[(=]|ca\.external\(|casadi\.external\(|\.generate\(|"
                  r"CodeGenerator\(")


def _sources():
    for top in ("casship", "problems", "examples"):
        for path in sorted((ROOT / top).rglob("*.py")):
            if RUNTIME not in path.parents:
                yield path


def test_nothing_outside_the_runtime_compiles_or_keeps_a_function_table():
    hits = [f"{p.relative_to(ROOT)}:{i}: {line.strip()}" for p in _sources()
            for i, line in enumerate(p.read_text().splitlines(), 1)
            if DOOR.search(line) and not line.lstrip().startswith("#")]
    assert not hits, hits


def test_the_door_check_sees_a_planted_compile(tmp_path):
    planted = "from casship.runtime import compile_function\nf = compile_function(step)\ntable = BoundedTable(8)\n"
    assert len([line for line in planted.splitlines() if DOOR.search(line)]) == 2


def test_compiling_module_is_gone():
    assert not (ROOT / "casship" / "compiling.py").exists()
    texts = [p for top in ("casship", "docs", "tests", "benchmarks", "examples", "problems") for p in (ROOT / top).rglob("*")
             if p.suffix in (".py", ".md") and p != Path(__file__)]
    mentions = [str(p.relative_to(ROOT)) for p in texts if re.search(r"casship\.compiling\b|compiling\.py", p.read_text())]
    assert not mentions, mentions


@pytest.mark.parametrize("given, policy", [(False, JitPolicy.OFF), (True, JitPolicy.NOW), (None, JitPolicy.BACKGROUND),
                                           ("off", JitPolicy.OFF), ("NOW", JitPolicy.NOW),
                                           (JitPolicy.BACKGROUND, JitPolicy.BACKGROUND)])
def test_jit_means_one_policy_everywhere(given, policy):
    assert JitPolicy.of(given) is policy
    assert bool(policy) is (policy is not JitPolicy.OFF)
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    ekf = cs.EKF(cs.discretize(m, 0.5), Q=1e-7, R=1e-4, options={"jit": given})
    assert ekf.options.jit is policy
    t = np.arange(0, 40.0, 0.5)
    data = cs.measure(cs.simulate(m, m.states(), t, {"delta": 0.1}), m, {"psi": 0.01}, seed=1)
    prob = cs.OutputErrorProblem(m, data, free=["K"], sigma={"psi": 0.01}, jit=given)
    assert prob.engine.jit is policy


@pytest.mark.parametrize("bad", ["sometimes", 1, 0.5, "fast"])
def test_an_unknown_jit_is_refused_naming_it(bad):
    with pytest.raises(InputError, match=repr(bad)):
        JitPolicy.of(bad)
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    with pytest.raises(ValueError, match="jit"):
        cs.EKF(cs.discretize(m, 0.5), Q=1e-7, R=1e-4, options={"jit": bad})


def test_one_chunk_setting(monkeypatch):
    assert fold_chunk() == 256
    monkeypatch.setenv("CASSHIP_FOLD_CHUNK", "64")
    assert fold_chunk() == 64
    assert pieces(130) == [(0, 64, 64), (64, 128, 64), (128, 130, 64)]
    assert pieces(130, shrink=True)[-1] == (128, 130, 2)
    monkeypatch.setenv("CASSHIP_FOLD_CHUNK", "0")
    with pytest.raises(InputError, match="CASSHIP_FOLD_CHUNK"):
        fold_chunk()


def test_the_chunk_length_does_not_change_a_number(monkeypatch):
    """A filter, a simulation fold with sensitivities and an identification cost through the one driver,
    at two chunk lengths: the same numbers to the last bit (padding never reaches a result)."""
    from casship.simulation import trajectory_sensitivities
    from casship.simulation import fold_steps

    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, 0.5)
    t = np.arange(0, 150.0, 0.5)
    U = {"delta": 0.15 * np.sign(np.sin(t / 20.0))}
    data = cs.measure(cs.simulate(m, m.states(), t, U), m, {"psi": 0.01}, seed=2)
    prior = cs.Gaussian(m.states(), np.diag([1e-3, 1e-5]))
    Um = data.matrix(["delta"])

    def run():
        res = cs.EKF(dm, Q=1e-7, R=1e-4).smooth(data, prior)
        X = fold_steps(dm, m.states(), Um[:-1], np.vstack([m.params(), 1.1 * m.params()]),
                       np.zeros((len(t) - 1, m.nw)), np.diff(t))
        _, S = trajectory_sensitivities(m, m.states(), t, Um, m.params(), ["K", "T"])
        prob = cs.OutputErrorProblem(m, data, free=["K", "T"], sigma={"psi": 0.01}, jit=False)
        return res.x, res.P, X, S, prob.cost({"K": 0.09, "T": 18.0}), prob.gradient({"K": 0.09, "T": 18.0})

    monkeypatch.setenv("CASSHIP_FOLD_CHUNK", "64")
    small = run()
    monkeypatch.setenv("CASSHIP_FOLD_CHUNK", "1024")
    whole = run()
    for a, b in zip(small[:4], whole[:4]):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(small[4], whole[4], rtol=1e-13)      # sums over pieces: last-bit order only
    np.testing.assert_allclose(small[5], whole[5], rtol=1e-11)


def test_an_integrator_step_is_never_compiled():
    """CasADi generates no C for an adaptive integrator: the simulation folds stay interpreted under any jit."""
    from casship.simulation import simulation_fold

    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, 0.5, method="cvodes")
    fold = simulation_fold(dm, 4, jit=True)
    assert fold.class_name() != "External"
    assert isinstance(fold, ca.Function)
