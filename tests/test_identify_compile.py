"""Build once, run many: problems of one structure share their Functions; a Function not yet in the
compile cache is compiled in the background while the problem evaluates it interpreted, with the
same numbers before and after the switch."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship import runtime
from casship.identify import _engine
from casship.runtime import CompileError, Compiling, cache_info, find_compiler


def _model(name: str, c: float) -> cs.Model:
    """A first-order steering model with a small quadratic damping ``c``: a structure (equations)
    of its own for each ``c`` (the name does not count: equal equations share their Functions)."""
    b = cs.ModelBuilder(name)
    psi, r = b.state("psi", angle=True), b.state("r")
    delta = b.input("delta")
    K, T = b.param("K", 0.1), b.param("T", 20.0)
    b.ode(psi=r, r=(K * delta - r) / T + c * r * r + b.noise("w_r"))
    b.output("psi", psi)
    return b.build()


def _records(model, n=3, seconds=150.0):
    t = np.arange(0.0, seconds, 1.0)
    out = []
    for i in range(n):
        delta = (0.1 + 0.05 * i) * np.sign(np.sin(t / (15.0 + 4 * i)))
        truth = cs.simulate(model, model.states(), t, {"delta": delta})
        out.append(cs.measure(truth, model, {"psi": 0.01}, seed=30 + i))
    return out


def test_problems_of_one_structure_share_their_functions():
    model = _model("share_test", 1.1e-3)
    recs = _records(model)
    a = cs.OutputErrorProblem(model, recs, free=["K", "T"], sigma={"psi": 0.01}, jit=False)
    a.information(), a.cost()
    built = _engine.COUNTS["built"]
    # other records (a cross-validation fold), another free set of the same size, a new model object
    b = cs.OutputErrorProblem(_model("renamed", 1.1e-3), recs[1:], free=["K", "T"], sigma={"psi": 0.02}, jit=False)
    assert b.engine.signature() == a.engine.signature()
    info = b.information()
    b.cost()
    assert _engine.COUNTS["built"] == built                        # nothing built again
    # the shared Functions give what a problem of its own gives: the information by central differences
    k = np.array([0.1, 20.0])
    h = 1e-5 * k
    res = lambda v: np.concatenate(b.residuals(dict(zip(["K", "T"], v)))).ravel()  # noqa: E731
    J = np.column_stack([(res(k + h[i] * np.eye(2)[i]) - res(k - h[i] * np.eye(2)[i])) / (2 * h[i]) for i in range(2)])
    assert np.allclose(info, J.T @ J, rtol=1e-5)
    # a different structure (one free value: another sensitivity fold; another model) builds its own
    b.replace(free=["K"]).information()
    assert _engine.COUNTS["built"] == built + 1
    other = cs.OutputErrorProblem(_model("share_test", 1.2e-3), recs, free=["K", "T"], sigma={"psi": 0.01}, jit=False)
    assert other.engine.signature() != a.engine.signature()


def test_background_compile_gives_the_interpreted_numbers(tmp_path, monkeypatch):
    try:
        find_compiler()
    except CompileError as exc:
        pytest.skip(f"no C compiler: {exc}")
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "cache"))
    model = _model("background_test", 1.3e-3)
    recs = _records(model)
    ref = cs.OutputErrorProblem(model, recs, free=["K", "T"], sigma={"psi": 0.01}, jit=False)
    prob = ref.replace(jit=None)
    sens = prob.engine._sens_fold(2, ("p",))                         # the interpreted fold while compiling
    pending = [f for f in runtime.FUNCTIONS.values() if isinstance(f, Compiling)
               and f.interpreted.name().startswith("oe_sens2")]
    assert pending
    background = pending[-1]
    assert sens is background.interpreted or background.ready
    values = {"K": 0.09, "T": 18.0}
    first = prob.information(values), prob.cost(values), prob.gradient(values)
    compiled = background.wait(timeout=300)
    assert compiled is not background.interpreted                    # the compile finished ...
    assert prob.engine._sens_fold(2, ("p",)) is compiled              # ... and took over
    assert cache_info().entries >= 1                       # kept for the next process
    after = prob.information(values), prob.cost(values), prob.gradient(values)
    plain = ref.information(values), ref.cost(values), ref.gradient(values)
    for x, y, z in zip(first, after, plain):
        assert np.array_equal(x, z) and np.array_equal(y, z)           # bit for bit
    fit_a = prob.solve(guess={"K": 0.05, "T": 10.0}, show=False)
    fit_b = ref.solve(guess={"K": 0.05, "T": 10.0}, show=False)
    assert fit_a.estimates == fit_b.estimates


def test_an_evaluation_repeated_at_the_same_point_is_answered_from_the_last_one(monkeypatch):
    """A solve checks, starts and ends at points just evaluated: the engine evaluates each point once
    in a row, returns what a fresh evaluation returns, and evaluates again at any other point."""
    model = _model("repeat_test", 1.1e-3)
    prob = cs.OutputErrorProblem(model, _records(model, n=2), free=["K", "T"], sigma={"psi": 0.01}, jit=False)
    evaluated = {"cost": 0, "derivatives": 0}
    for kind in evaluated:
        real = getattr(type(prob.engine), f"_{kind}")

        def counted(self, theta, _real=real, _kind=kind):
            evaluated[_kind] += 1
            return _real(self, theta)
        monkeypatch.setattr(type(prob.engine), f"_{kind}", counted)
    theta = np.array([0.1, 20.0])
    first = prob.engine.derivatives(theta)
    again = prob.engine.derivatives(theta.copy())
    assert evaluated["derivatives"] == 1 and again[0] == first[0] and np.array_equal(again[2], first[2])
    fresh = cs.OutputErrorProblem(model, _records(model, n=2), free=["K", "T"], sigma={"psi": 0.01}, jit=False)
    assert np.array_equal(fresh.engine.derivatives(theta)[2], first[2])      # a problem of its own
    assert evaluated["derivatives"] == 2
    prob.engine.derivatives(theta * (1 + 1e-12))              # another point, however near: evaluated
    assert evaluated["derivatives"] == 3
    c = prob.cost({"K": 0.1, "T": 20.0})
    assert prob.cost({"K": 0.1, "T": 20.0}) == c and evaluated["cost"] == 1
    prob.cost({"K": 0.11, "T": 20.0})
    assert evaluated["cost"] == 2
    assert prob.solve(show=False).status == "converged"


def test_problems_on_one_model_share_its_discretisation():
    model = _model("disc_test", 1.1e-3)
    recs = _records(model, n=2)
    a = cs.OutputErrorProblem(model, recs, free=["K"], sigma={"psi": 0.01}, jit=False)
    b = cs.OutputErrorProblem(model, recs[1:], free=["K", "T"], sigma={"psi": 0.02}, jit=False)
    assert a.dmodel is b.dmodel and a.dmodel.dt == 1.0
    # another method is another discretisation
    c = cs.OutputErrorProblem(model, recs, free=["K"], sigma={"psi": 0.01}, method="euler", jit=False)
    assert c.dmodel is not a.dmodel and c.dmodel.method == "euler"
