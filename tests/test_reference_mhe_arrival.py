"""The MHE's fixed arrival cost against hand-built window problems.

On a linear model the window problem is a linear least-squares problem, written out here with numpy:
over the rows ``k-N .. k`` (rows before the record: no step, nothing measured) the unknowns are the
first state and the whitened process noise, the cost
``|W (x_s - xbar)|^2 + sum |v_j|^2 + sum mask_j (y_j - psi_j)^2 / R``. With ``arrival="fixed"`` the prior
``(xbar, W' W = P0^-1)`` is the prior of the record as long as the window still holds its first row
(``k <= N``), and from then on the previous window's estimate of this window's first row, with ``P0``.
"""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs

Q, R, DT = 1e-6, 1e-4, 0.5


def linear_maps(dm, p, dt):
    """``A, B, G`` of ``x+ = A x + B u + G w`` (the discretised linear model, read off column by column)."""
    nx = dm.model.nx if hasattr(dm, "model") else 2
    F = lambda x, u, w: np.asarray(dm.F(x, [u], p, [w], dt)).ravel()  # noqa: E731
    zero = np.zeros(nx)
    c = F(zero, 0.0, 0.0)
    A = np.column_stack([F(e, 0.0, 0.0) - c for e in np.eye(nx)])
    return A, F(zero, 1.0, 0.0) - c, F(zero, 0.0, 1.0) - c


def window_estimate(dm, p, data, k, N, xbar, P0):
    """The states of rows ``k-N .. k`` minimising the window cost (numpy least squares)."""
    nx = 2
    W = np.linalg.inv(np.linalg.cholesky(P0))
    rows = list(range(k - N, k + 1))
    U, Y = data["delta"], data["psi"]
    # x_j = Phi_j x0 + sum_i Gam_{j,i} v_i + c_j
    Phi, Gam, c = [np.eye(nx)], [np.zeros((nx, N))], [np.zeros(nx)]
    for j in range(N):
        row = rows[j + 1]
        if row <= 0:                                       # before the record, and the first row: no step
            A, B, G, u = np.eye(nx), np.zeros(nx), np.zeros(nx), 0.0
        else:
            A, B, G = linear_maps(dm, p, DT)
            u = U[row - 1]                                 # the input held over the interval
        Phi.append(A @ Phi[-1])
        g = A @ Gam[-1]
        g[:, j] += G * np.sqrt(Q)
        Gam.append(g)
        c.append(A @ c[-1] + B * u)
    M, b = [], []
    M.append(np.hstack([W, np.zeros((nx, N))]))
    b.append(W @ xbar)
    M.append(np.hstack([np.zeros((N, nx)), np.eye(N)]))
    b.append(np.zeros(N))
    for j, row in enumerate(rows):
        if row < 0 or not np.isfinite(Y[row]):
            continue
        M.append(np.hstack([Phi[j][:1], Gam[j][:1]]) / np.sqrt(R))
        b.append(np.array([Y[row] - c[j][0]]) / np.sqrt(R))
    z = np.linalg.lstsq(np.vstack(M), np.concatenate(b), rcond=None)[0]
    return [Phi[j] @ z[:nx] + Gam[j] @ z[nx:] + c[j] for j in range(N + 1)]


def fixed_arrival_by_hand(dm, p, data, prior, N, switch_after=None):
    """The estimates of a fixed-arrival MHE, window by window (``switch_after``: the last window whose
    prior is the record's prior; ``N`` by the rule)."""
    switch_after = N if switch_after is None else switch_after
    out, previous = [], None
    for k in range(len(data)):
        xbar = prior.mean if k <= switch_after else previous[1]
        states = window_estimate(dm, p, data, k, N, xbar, prior.cov)
        out.append(states[-1])
        previous = states
    return np.array(out)


@pytest.fixture(scope="module")
def case():
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, DT, "rk4")
    t = np.arange(0.0, 12.0, DT)
    rng = np.random.default_rng(4)
    delta = 0.1 * np.sign(np.sin(2 * np.pi * t / 6.0) + 0.3)
    tr = cs.simulate(m, m.states(), t, {"delta": delta}, w=rng.standard_normal((t.size, 1)) * np.sqrt(Q))
    data = cs.measure(tr, m, {"psi": np.sqrt(R)}, seed=rng, keep=("psi",))
    y = data["psi"].copy()
    y[6] = np.nan                                          # one row measures nothing
    data = data.with_columns(psi=y)
    prior = cs.Gaussian([0.004, -0.001], [1e-4, 1e-6])
    return m, dm, data, prior


@pytest.mark.parametrize("N", [1, 3])
def test_fixed_arrival_is_the_previous_windows_estimate_after_the_first_row_leaves(case, N):
    m, dm, data, prior = case
    p = m.params()
    res = cs.MHE(dm, Q, R, options={"horizon": N, "arrival": "fixed", "solver": "rti"}).filter(data, prior)
    ref = fixed_arrival_by_hand(dm, p, data, prior, N)
    np.testing.assert_allclose(res.x, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # the rule is visible in the numbers: the previous window's estimate entering one window early
    # (or late), or the previous window's first state instead of its second, gives other estimates
    for other in (fixed_arrival_by_hand(dm, p, data, prior, N, switch_after=N - 1),
                  fixed_arrival_by_hand(dm, p, data, prior, N, switch_after=N + 1)):
        assert np.abs(other - ref).max() > 1e-5 * np.abs(ref).max()


def test_first_windows_use_the_record_prior(case):
    """Before the window has moved past the first row, every window's prior is the record's prior: the first
    estimate is the prior updated with the first measurement alone (a Kalman update)."""
    m, dm, data, prior = case
    res = cs.MHE(dm, Q, R, options={"horizon": 3, "arrival": "fixed", "solver": "rti"}).filter(data, prior)
    P0, H = prior.cov, np.array([[1.0, 0.0]])
    K = P0 @ H.T / (H @ P0 @ H.T + R)
    x0 = prior.mean + (K * (data["psi"][0] - prior.mean[0])).ravel()
    np.testing.assert_allclose(res.x[0], x0, rtol=1e-10, atol=1e-14)
