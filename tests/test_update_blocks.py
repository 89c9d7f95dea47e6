"""The symbolic building blocks of the measurement update: the angle wrap of residuals, the Cholesky
substitutions (reciprocals, not divisions), and the record preparation's gate thresholds, each
against an independent answer."""
from collections import Counter

import casadi as ca
import numpy as np
import pytest
from scipy import stats

import casship as cs
from casship.angles import wrap
from casship.estimators.update import gain_and_terms, spd_solve, wrap_residual


def test_wrap_residual_equals_numpy_wrap_with_derivative_one():
    a = ca.SX.sym("a")
    f = ca.Function("f", [a], [wrap_residual(a), ca.jacobian(wrap_residual(a), a)])
    values = np.concatenate([np.linspace(-20.0, 20.0, 4001), [np.pi, -np.pi, 3 * np.pi, -3 * np.pi, 0.0, 1e-12]])
    out = np.array([np.array(f(v)).ravel() for v in values])
    # (-pi, pi], like casship.angles.wrap, to round-off of 2 pi multiples
    assert np.all(out[:, 0] > -np.pi) and np.all(out[:, 0] <= np.pi)
    np.testing.assert_allclose(out[:, 0], wrap(values), rtol=0, atol=1e-13)
    np.testing.assert_array_equal(out[:, 1], 1.0)
    inside = np.abs(values) < np.pi            # inside the interval the residual is returned exactly
    np.testing.assert_array_equal(out[inside, 0], values[inside])


def _ops(f: ca.Function) -> Counter:
    names = {getattr(ca, n): n[3:] for n in dir(ca) if n.startswith("OP_")}
    return Counter(names.get(f.instruction_id(k)) for k in range(f.n_instructions()))


def test_gain_and_likelihood_terms_against_numpy_with_one_division_per_row():
    rng = np.random.default_rng(4)
    ny, nx = 3, 6
    A = rng.normal(size=(ny, ny))
    S_num = A @ A.T + ny * np.eye(ny)
    B_num, e_num = rng.normal(size=(ny, nx)), rng.normal(size=ny)
    S, B, e, mask = ca.SX.sym("S", ny, ny), ca.SX.sym("B", ny, nx), ca.SX.sym("e", ny), ca.SX.sym("m", ny)
    f = ca.Function("f", [S, B, e, mask], list(gain_and_terms(S, B, e, mask)))
    K, nis, ll = (np.array(v) for v in f(S_num, B_num, e_num, np.ones(ny)))
    np.testing.assert_allclose(K, np.linalg.solve(S_num, B_num).T, rtol=1e-12)
    np.testing.assert_allclose(nis.item(), e_num @ np.linalg.solve(S_num, e_num), rtol=1e-12)
    ref = stats.multivariate_normal(np.zeros(ny), S_num).logpdf(e_num)
    np.testing.assert_allclose(ll.item(), ref, rtol=1e-12)
    # the substitutions multiply by reciprocals of the factor's diagonal: CasADi would turn a * (1 / d)
    # back into a / d (one division per entry) if the reciprocal were not kept apart
    ops = _ops(f)
    assert ops["DIV"] + ops["INV"] <= 2 * ny, ops
    g = ca.Function("g", [S, B], [spd_solve(S, B, exact=True)])
    np.testing.assert_allclose(np.array(g(S_num, B_num)), np.linalg.solve(S_num, B_num), rtol=1e-12)


@pytest.mark.parametrize("gate", [None, 0.99])
def test_prepared_gate_is_the_chi_square_threshold_of_the_measured_count(gate):
    b = cs.ModelBuilder("two_outputs")
    x1, x2 = b.state("x1"), b.state("x2")
    b.ode(x1=x2 + b.noise("w1"), x2=-x1 + b.noise("w2"))
    b.output("y1", x1)
    b.output("y2", x2)
    m = b.build()
    t = np.arange(8) * 0.1
    y1 = np.array([np.nan, 1, np.nan, 2, 3, np.nan, 4, 5.0])
    y2 = np.array([np.nan, np.nan, 1, 2, np.nan, np.nan, 3, 4.0])
    data = cs.Dataset(t, {"y1": y1, "y2": y2})
    ekf = cs.EKF(cs.discretize(m, 0.1), Q=1e-4, R=1e-2, options={"gate": gate})
    arrays = ekf.prepare(data)
    counts = np.isfinite(y1).astype(int) + np.isfinite(y2).astype(int)
    expected = np.where(counts == 0, np.inf, stats.chi2.ppf(gate, np.maximum(counts, 1))) if gate else np.full(8, np.inf)
    np.testing.assert_array_equal(arrays["gate"].ravel(), expected)
    np.testing.assert_array_equal(arrays["mask"].T, np.column_stack([np.isfinite(y1), np.isfinite(y2)]).astype(float))
    np.testing.assert_array_equal(arrays["y"].T, np.nan_to_num(np.column_stack([y1, y2]), nan=0.0))
    res = ekf.filter(data, cs.Gaussian([0.0, 0.0], np.eye(2)))
    np.testing.assert_array_equal(res.n_measured, counts)
    assert np.isnan(res.innovations[~np.isfinite(np.column_stack([y1, y2]))]).all()
    assert not res.innovations.flags.writeable
