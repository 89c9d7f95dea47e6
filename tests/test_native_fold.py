"""The compiled record loop (``NativeFold``): the same numbers as the step evaluated by CasADi, inputs
read in place (reversed views too), memory carried from sample to sample, results in fresh read-only
memory that no later run writes into, and clear errors."""
import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship.runtime import NativeFold


def _record(n=700, dt=0.5):
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(n) * dt
    tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 30.0))})
    data = cs.measure(tr, m, {"psi": 0.01}, seed=3)
    Y = data.matrix(["psi"])
    Y[::7] = np.nan                                     # missing samples go through the mask
    data = data.with_columns(psi=Y[:, 0])
    return m, cs.discretize(m, dt), data, cs.Gaussian(m.states(), np.diag([1e-3, 1e-5]))


def _accumulator():
    x, u, k = ca.SX.sym("x", 2), ca.SX.sym("u", 2), ca.SX.sym("k")
    return ca.Function("acc_step", [x, u, k], [k * x + u, ca.sumsqr(x)], ["x", "u", "k"], ["x", "norm"],
                       {"allow_duplicate_io_names": True})


@pytest.mark.parametrize("kind", ["EKF", "UKF", "EnKF"])
def test_compiled_loop_equals_the_interpreted_fold(kind):
    """filter and smooth, compiled (one C loop) and interpreted (mapaccum in pieces): same numbers."""
    m, dm, data, prior = _record()
    options = {"members": 20} if kind == "EnKF" else {}
    vm = getattr(cs, kind)(dm, Q=1e-7, R=1e-4, options=options).smooth(data, prior, seed=1)
    cc = getattr(cs, kind)(dm, Q=1e-7, R=1e-4, options={**options, "jit": True}).smooth(data, prior, seed=1)
    for name in ("x", "P", "x_pred", "P_pred", "C", "K", "innovations", "S", "nis", "loglik_terms"):
        np.testing.assert_allclose(getattr(cc, name), getattr(vm, name), rtol=1e-10, atol=1e-13, err_msg=name)


def test_memory_is_carried_and_reversed_inputs_are_read_in_place():
    fold = NativeFold(_accumulator(), ["x"])
    rng = np.random.default_rng(0)
    U = rng.standard_normal((9, 2))
    final, out = fold.run(9, memory={"x": [1.0, -1.0]}, per_sample={"u": U[::-1]}, constants={"k": 0.5})
    x, xs, norms = np.array([1.0, -1.0]), [], []
    for u in U[::-1]:
        norms.append(x @ x)
        x = 0.5 * x + u
        xs.append(x)
    np.testing.assert_allclose(out["x"][:, :, 0], xs, rtol=1e-15)
    np.testing.assert_allclose(out["norm"].ravel(), norms, rtol=1e-15)
    np.testing.assert_allclose(final["x"].ravel(), xs[-1], rtol=1e-15)
    assert not out["x"].flags.writeable


def test_memory_not_kept_still_runs_and_outputs_go_where_asked():
    fold = NativeFold(_accumulator(), ["x"])
    U = np.ones((5, 2))
    final, out = fold.run(5, memory={"x": [0.0, 0.0]}, per_sample={"u": U}, constants={"k": 1.0}, keep=("norm",))
    assert set(out) == {"norm"}
    np.testing.assert_allclose(final["x"].ravel(), [5.0, 5.0])
    np.testing.assert_allclose(out["norm"].ravel(), [0, 2, 8, 18, 32])
    target = np.full((5, 2, 1), np.nan)
    fold.run(5, memory={"x": [0.0, 0.0]}, per_sample={"u": U}, constants={"k": 1.0}, keep=("x",),
             out={"x": target[::-1]})                   # written backwards into the caller's array
    np.testing.assert_allclose(target[:, 0, 0], [5, 4, 3, 2, 1])


def test_results_are_never_written_again():
    """Each run writes its results into memory of its own, read-only once written: a result kept, or
    dropped and a new run started, is never the memory of a later run."""
    fold = NativeFold(_accumulator(), ["x"])
    U = np.ones((6, 2))
    _, first = fold.run(6, memory={"x": [0.0, 0.0]}, per_sample={"u": U}, constants={"k": 1.0})
    kept = first["x"].copy()
    with pytest.raises(ValueError, match="read-only"):
        first["x"][0] = 1.0
    blocks = []
    for k in range(3):
        _, out = fold.run(6, memory={"x": [k + 1.0, 0.0]}, per_sample={"u": U}, constants={"k": 1.0})
        assert not np.shares_memory(out["x"], first["x"])
        assert all(not np.shares_memory(out["norm"], b) for b in blocks)
        blocks.append(out["norm"])
        del out
    np.testing.assert_array_equal(first["x"], kept)
    m, dm, data, prior = _record()
    ekf = cs.EKF(dm, Q=1e-7, R=1e-4, options={"jit": True})
    one = ekf.filter(data, prior)
    P = one.P.copy()
    two = ekf.filter(data, prior)
    np.testing.assert_array_equal(one.P, P)
    assert not np.shares_memory(one.P, two.P)


def test_bad_calls_name_what_is_wrong():
    fold = NativeFold(_accumulator(), ["x"])
    base = {"memory": {"x": [0.0, 0.0]}, "constants": {"k": 1.0}}
    with pytest.raises(ValueError, match="at least one sample"):
        fold.run(0, per_sample={"u": np.ones((0, 2))}, **base)
    with pytest.raises(ValueError, match=r"'u' needs shape \(4, 2\)"):
        fold.run(4, per_sample={"u": np.ones((3, 2))}, **base)
    with pytest.raises(ValueError, match="no slot"):
        fold.run(2, per_sample={"u": np.ones((2, 2)), "w": np.ones((2, 2))}, **base)
    with pytest.raises(ValueError, match="'u' is not given"):
        fold.run(2, per_sample={}, **base)
    with pytest.raises(ValueError, match="writable float64"):
        fold.run(2, per_sample={"u": np.ones((2, 2))}, keep=("x",), out={"x": np.ones((2, 2), dtype=int)}, **base)
    with pytest.raises(ValueError, match="not both an input and an output"):
        NativeFold(_accumulator(), ["norm"])


def test_inputs_in_another_layout_are_copied_into_the_right_one():
    """A matrix input given row-major per sample (or with gaps between the entries) is laid out
    column-major before the loop reads it."""
    M, v = ca.SX.sym("M", 2, 3), ca.SX.sym("v", 3)
    acc = ca.SX.sym("acc", 2)
    step = ca.Function("mv_step", [acc, M, v], [acc + M @ v], ["acc", "M", "v"], ["acc"],
                       {"allow_duplicate_io_names": True})
    fold = NativeFold(step, ["acc"])
    rng = np.random.default_rng(1)
    Ms, vs = rng.standard_normal((4, 2, 3)), rng.standard_normal((4, 6))[:, ::2]   # C order; strided
    final, _ = fold.run(4, memory={"acc": [0.0, 0.0]}, per_sample={"M": Ms, "v": vs})
    np.testing.assert_allclose(final["acc"].ravel(), sum(Ms[k] @ vs[k] for k in range(4)), rtol=1e-14)
