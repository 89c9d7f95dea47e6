"""Simulation of models and generation of noisy measurements."""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from ..runtime import BufferedCall
from ..angles import wrap
from ..data import Dataset, check_time
from ..errors import DivergenceError, InputError, SolverError
from .folds import IntegrationError, fold_steps, padded, solver_status
from ..trajectory import Trajectory
from ..discretize import discretize
from ..model import Model
from .validity import ValidityError, check_inputs, check_states, check_step, warn_states

__all__ = ["simulate", "simulate_many", "measure", "input_matrix", "fold_steps", "IntegrationError"]


def input_matrix(model: Model, t: np.ndarray, inputs, x0=None) -> np.ndarray | None:
    """Inputs as an (N, nu) array from an array, a mapping name -> array/constant or a Dataset.

    Returns ``None`` for a callable (evaluated during the simulation).

    Parameters
    ----------
    model : Model
        The model.
    t : numpy.ndarray
        Time grid [s].
    inputs : array, mapping, Dataset or callable
        See :func:`simulate`.
    x0 : array_like, optional
        Unused (kept for callers).

    Returns
    -------
    numpy.ndarray or None
    """
    n = t.size
    if callable(inputs) and not isinstance(inputs, Dataset):
        return None
    if inputs is None:
        if model.nu:
            raise InputError(f"model {model.name!r} needs inputs {list(model.input_names)}")
        return np.zeros((n, 0))
    if isinstance(inputs, Dataset):
        missing = [k for k in model.input_names if k not in inputs]
        if missing:
            raise InputError(f"data has no column for input(s) {missing} of model {model.name!r}")
        U = inputs.matrix(model.input_names, finite=True, what="input")
        tol = 1e-9 * max(1.0, float(np.abs(t).max()))
        if len(inputs) == n and np.allclose(inputs.t, t, rtol=0.0, atol=tol):
            U_out = U
        else:
            # another grid: hold each recorded value until the next record (zero-order hold)
            if t[0] < inputs.t[0] - tol or t[-1] > inputs.t[-1] + tol:
                raise InputError(f"input data cover t = [{inputs.t[0]:g}, {inputs.t[-1]:g}] s, the simulation "
                                 f"needs [{t[0]:g}, {t[-1]:g}] s")
            rows = np.clip(np.searchsorted(inputs.t, t + tol, side="right") - 1, 0, len(inputs) - 1)
            U_out = U[rows]
        check_radians(model, U_out)
        return U_out
    if isinstance(inputs, Mapping):
        unknown = set(inputs) - set(model.input_names)
        if unknown:
            raise InputError(f"unknown input name(s) {sorted(unknown)}; model inputs: {list(model.input_names)}")
        missing = [k for k in model.input_names if k not in inputs]
        if missing:
            raise InputError(f"no value given for input(s) {missing}")
        cols = []
        for name in model.input_names:
            _refuse_masked(inputs[name], f"input {name!r}", t)
            v = np.broadcast_to(np.asarray(inputs[name], dtype=float), (n,)) if np.ndim(inputs[name]) == 0 \
                else np.asarray(inputs[name], dtype=float)
            if v.shape != (n,):
                raise InputError(f"input {name!r} has shape {v.shape}, expected ({n},)")
            cols.append(v)
        U = np.column_stack(cols) if cols else np.zeros((n, 0))
    else:
        _refuse_masked(inputs, "inputs", t)
        U = np.asarray(inputs, dtype=float)
        if U.ndim == 1 and model.nu == 1:
            U = U[:, None]
        if U.shape != (n, model.nu):
            raise InputError(f"inputs have shape {U.shape}, expected ({n}, {model.nu}) for {list(model.input_names)}")
    bad = np.argwhere(~np.isfinite(U))
    if bad.size:
        row, col = bad[0]
        raise InputError(f"input {model.input_names[col]!r} is not finite at row {row} (t = {t[row]:g} s)")
    check_radians(model, U)
    return U


def _refuse_masked(values, what: str, t) -> None:
    """An input needs a value at every row: a masked entry is refused (its hidden value would be used)."""
    mask = np.ma.getmaskarray(values) if np.ma.isMaskedArray(values) else None
    if mask is not None and mask.any():
        row = int(np.flatnonzero(mask.reshape(mask.shape[0], -1).any(axis=1))[0]) if mask.ndim else 0
        raise InputError(f"{what} is masked at row {row} (t = {t[row]:g} s); an input needs a value at every row")


def check_radians(model: Model, U: np.ndarray) -> None:
    """Reject inputs declared in radians whose magnitude exceeds 2 pi (degrees given by mistake)."""
    for j, var in enumerate(model.input_vars):
        if var.unit == "rad" and U.shape[0] and np.abs(U[:, j]).max() > 2 * np.pi:
            raise InputError(f"input {var.name!r} reaches {np.abs(U[:, j]).max():.4g} rad: angles are in "
                             "radians (degrees given?)")


def _chunk(steps: int) -> int:
    """Map length for ``steps`` steps: a power of two up to the runtime's chunk (few cached sizes)."""
    from ..runtime import fold_chunk

    return min(fold_chunk(), 1 << max(0, int(steps - 1).bit_length()))


def eval_outputs(model: Model, X: np.ndarray, U: np.ndarray, p) -> np.ndarray:
    """Outputs ``h(x, u, p)`` of every row of ``X`` (N, nx) and ``U`` (N, nu) as an (N, ny) array."""
    n = X.shape[0]
    if model.ny == 0:
        return np.zeros((n, 0))
    direct = model.derived(("output_selection",), lambda: _output_selection(model))
    if direct is not None:                      # every output is a state or an input: no evaluation
        return np.column_stack([(X if kind == "x" else U)[:, j] for kind, j in direct])
    size = _chunk(n)
    hmap = model.derived(("h_map", size), lambda: model.h.map(size))
    total = -(-n // size) * size
    Xc, Uc = padded(X.T, total), padded(U.T, total)
    Y = np.hstack([np.asarray(hmap(Xc[:, k:k + size], Uc[:, k:k + size], p)) for k in range(0, total, size)])
    return Y[:, :n].T.reshape(n, model.ny)


def simulate(model: Model, x0, t, inputs=None, p=None, *, method: str | None = None, max_step: float | None = None,
             w=None, options: dict | None = None, check_limits: bool = True, jit: bool | None = False) -> Trajectory:
    """Simulate ``model`` from ``x0`` on the time grid ``t``.

    Parameters
    ----------
    model : Model
    x0 : array_like (nx,) or mapping state name -> value
    t : array_like (N,)
        Strictly increasing time grid [s]; the result is sampled on it.
    inputs : array (N, nu), mapping name -> array or constant, Dataset, or callable
        Inputs held constant over each interval (zero-order hold). A Dataset may have its own
        time stamps covering ``t``: each grid point then takes the latest recorded value. A callable
        ``inputs(t, x) -> u`` is evaluated at every grid point (closed loop).
    p : array_like or mapping, optional
        Parameters (nominal by default).
    method : {"rk4", "euler", "cvodes"}
        Integration method per interval (see :func:`casship.discretize`; default ``"rk4"``). With
        ``"cvodes"`` and inputs (and noise) constant over the record, one adaptive integration with
        outputs on the grid replaces the restart at every sample. A discrete-time model
        (``ModelBuilder(name, dt=...)``) takes no method: it steps ``x[k+1] = F(x, u, p, w)`` on a
        grid of its own ``dt``.
    max_step : float, optional
        Largest explicit sub-step [s]; by default one sub-step per interval.
    w : array (N, nw), optional
        Process-noise realisation held over each interval (zero by default).
    options : dict, optional
        Integrator options for ``method="cvodes"`` (e.g. ``{"abstol": 1e-12, "reltol": 1e-12}``).
    check_limits : bool
        Check the initial state and the inputs against the model's declared ranges (``model.limits``)
        and a fixed step (``euler``, ``rk4``) against its stability limit at the start (see
        :mod:`casship.simulation.validity`); both raise :class:`~casship.simulation.validity.ValidityError`. A state
        leaving its range during the run gives a :class:`~casship.simulation.validity.ValidityWarning`.
        ``False`` is the explicit opt-in for a deliberate out-of-range study.
    jit : bool or None
        How the fold over the record runs (see :mod:`casship.simulation.folds`): interpreted (``False``, the
        default: a one-off simulation does not pay for a compile), compiled (``True``), or compiled
        from the cache, else in the background while it runs interpreted (``None``: for repeated
        simulations of one model, as replays make). The same numbers either way.

    Returns
    -------
    Trajectory

    Raises
    ------
    ValueError
        Bad time grid (not increasing, NaN), shapes, unknown input names, non-finite inputs.
    casship.simulation.validity.ValidityError
        An input or the initial state outside the model's ranges, or a step beyond the stability
        limit (e.g. a long time gap with ``rk4``), unless ``check_limits=False``.
    IntegrationError
        The adaptive integrator failed (its status is given).

    Examples
    --------
    >>> import numpy as np
    >>> from casship.models import nomoto_first_order
    >>> m = nomoto_first_order()
    >>> tr = simulate(m, m.states(), np.arange(0, 10, 0.1), {"delta": 0.1})
    >>> round(float(tr["r"][-1]), 4) > 0
    True
    """
    t, x0, p, dt, dmodel, method, substeps, W, U = _setup(model, x0, t, inputs, p, method, max_step, w, options)
    if check_limits:
        check_states(model, x0, "initial state")
        if U is not None:
            check_inputs(model, U, t)
            _check_steps(model, dt, substeps, x0, U[0], p, method)
    if U is not None and method == "cvodes" and t.size > 2 and _constant_rows(U) and _constant_rows(W):
        X = _adaptive_on_grid(model, x0, t, U[0], p, W[0], options)
    elif U is not None:
        X = _steps(dmodel, x0, U, p, W, dt, t, jit)
    else:
        first = (lambda u: _check_steps(model, dt, substeps, x0, u, p, method)) if check_limits else None
        X, U = _closed_loop(model, dmodel, x0, t, inputs, p, W, dt, first)
        if check_limits:
            check_inputs(model, U, t)
    return _trajectory(model, t, X, U, p, method, check_limits)


def simulate_many(model: Model, x0, t, inputs, params, *, method: str | None = None, max_step: float | None = None,
                  w=None, check_limits: bool = True, jit: bool | None = None) -> list:
    """Simulate ``model`` once per parameter vector, all of them in one mapped call of the fold per chunk.

    What :func:`simulate` gives for each row of ``params`` (the same numbers), for many parameter
    vectors at once (e.g. draws from a fit's covariance): the record's inputs, noise and steps are
    shared, and the step fold is mapped over the parameter vectors (``Function.map``), so the
    simulations cost one call per chunk of the record instead of one simulation each.

    Parameters
    ----------
    model : Model
    x0 : array_like (nx,) or mapping state name -> value
        Initial state, the same for every simulation.
    t : array_like (N,)
        Strictly increasing time grid [s].
    inputs : array (N, nu), mapping name -> array or constant, or Dataset
        As for :func:`simulate` (a callable runs one closed loop per parameter vector).
    params : array_like (m, np)
        One parameter vector per row.
    method, max_step, w
        As for :func:`simulate`.
    check_limits : bool
        As for :func:`simulate`: the initial state and the inputs are checked once (raising), the
        fixed step's stability limit per parameter vector (its simulation then fails with the
        :class:`~casship.simulation.validity.ValidityError`).
    jit : bool or None
        The fold interpreted (``False``), compiled (``True``), or compiled from the cache, else in the
        background while it runs interpreted (``None``); the same numbers either way (see
        :mod:`casship.simulation.folds`).

    Returns
    -------
    list
        Per row of ``params``: its :class:`~casship.trajectory.Trajectory`, or the exception its
        simulation failed with (:class:`~casship.simulation.validity.ValidityError`,
        :class:`~casship.errors.DivergenceError`, :class:`IntegrationError`), as :func:`simulate`
        would raise it for that row.

    Examples
    --------
    >>> import numpy as np
    >>> from casship.models import nomoto_first_order
    >>> m = nomoto_first_order()
    >>> P = np.array([m.params(K=k) for k in (0.05, 0.1)])
    >>> runs = simulate_many(m, m.states(), np.arange(0, 10, 0.1), {"delta": 0.1}, P, jit=False)
    >>> [round(float(tr["r"][-1]), 5) for tr in runs] == [round(float(simulate(m, m.states(), np.arange(0, 10, 0.1),
    ...     {"delta": 0.1}, p)["r"][-1]), 5) for p in P]
    True
    """
    P = np.atleast_2d(np.asarray(params, dtype=float))
    if P.ndim != 2 or P.shape[1] != model.np:
        raise InputError(f"params has shape {np.shape(params)}, expected (m, {model.np}) for model {model.name!r}")
    asked = method
    t, x0, _, dt, dmodel, method, substeps, W, U = _setup(model, x0, t, inputs, None, method, max_step, w, None)
    if check_limits:
        check_states(model, x0, "initial state")
        if U is not None:
            check_inputs(model, U, t)
    if U is None or (method == "cvodes" and t.size > 2 and _constant_rows(U) and _constant_rows(W)):
        # a closed loop, or one adaptive integration over the record: one simulation per parameter vector
        return [_attempt(lambda p=p: simulate(model, x0, t, inputs, p, method=asked, max_step=max_step, w=w,
                                               check_limits=check_limits)) for p in P]
    out: list = [None] * len(P)
    rows = []
    for i, p in enumerate(P):
        failed = _attempt(lambda p=p: _check_steps(model, dt, substeps, x0, U[0], p, method)) if check_limits else None
        if failed is not None:
            out[i] = failed
        else:
            rows.append(i)
    try:
        states = list(_steps(dmodel, x0, U, P[rows], W, dt, t, jit)) if rows else []
    except IntegrationError:            # which simulation failed: each alone
        states = [_attempt(lambda p=P[i]: _steps(dmodel, x0, U, p, W, dt, t, jit)) for i in rows]
    for i, X in zip(rows, states):
        out[i] = X if isinstance(X, Exception) else _attempt(lambda X=X, p=P[i]: _trajectory(model, t, X, U, p, method,
                                                                                                 check_limits))
    return out


def _attempt(run):
    """``run()``, or the error of a simulation that failed (a bad step, divergence, a solver failure)."""
    try:
        return run()
    except (ValidityError, SolverError) as exc:
        return exc


def _setup(model: Model, x0, t, inputs, p, method, max_step, w, options):
    """The checked time grid, initial state, parameters, steps, discretisation, noise and inputs."""
    t = check_time(t, "t")
    x0 = model.states(**x0) if isinstance(x0, Mapping) else np.asarray(x0, dtype=float).reshape(-1)
    if x0.shape != (model.nx,):
        raise InputError(f"x0 has {x0.size} entries, model {model.name!r} has {model.nx} states")
    if not np.all(np.isfinite(x0)):
        raise InputError("x0 contains non-finite entries")
    p = model.params(p) if p is not None else model.params()
    dt = np.diff(t)
    if max_step is not None and not (np.isfinite(max_step) and max_step > 0):
        raise InputError(f"max_step must be a positive finite number, got {max_step}")
    if model.dt is not None:
        if method is not None or max_step is not None or options:
            raise InputError(f"model {model.name!r} is discrete-time: it steps x[k+1] = F(x, u, p, w) itself "
                             "(no method, max_step or integrator options)")
        dmodel = model.derived(("discretize", "discrete"), lambda: discretize(model))
        dmodel.check_steps(dt, t)
        method, substeps = "discrete", 1      # it steps itself: no integrator stability limit to check
    else:
        method = "rk4" if method is None else method
        substeps = 1 if max_step is None else max(1, int(np.ceil(dt.max(initial=0.0) / max_step)))
        key = ("discretize", method, substeps, tuple(sorted((options or {}).items())))
        dmodel = model.derived(key, lambda: discretize(model, float(dt[0]) if dt.size else 1.0, method=method,
                                                      substeps=substeps, options=options))
    W = _noise_matrix(model, t, w)
    U = input_matrix(model, t, inputs)
    return t, x0, p, dt, dmodel, method, substeps, W, U


def _steps(dmodel, x0, U, p, W, dt, t, jit):
    """The fold over the record (:func:`fold_steps`), a failure located in time."""
    try:
        return fold_steps(dmodel, x0, U, p, W, dt, jit=jit)
    except IntegrationError as exc:
        raise IntegrationError(f"{exc} (from t = {t[exc.step]:g} s)", exc.status, exc.step) from exc


def _trajectory(model: Model, t, X, U, p, method: str, check_limits: bool) -> Trajectory:
    """The simulated states as a :class:`Trajectory` with inputs and outputs (divergence refused)."""
    if not np.all(np.isfinite(X)):
        row = int(np.argwhere(~np.isfinite(X))[0, 0])
        raise DivergenceError(f"simulation of {model.name!r} diverged at t = {t[row]:g} s (a step too long for its "
                              "dynamics, or inputs far outside its range?)")
    if check_limits:
        warn_states(model, X, t)
    Y = eval_outputs(model, X, U, p)
    cols = {n: X[:, i] for i, n in enumerate(model.state_names)}
    cols.update({n: U[:, i] for i, n in enumerate(model.input_names)})
    cols.update({n: Y[:, i] for i, n in enumerate(model.output_names) if n not in cols})
    units = {v.name: v.unit for v in (*model.state_vars, *model.input_vars, *model.output_vars)}
    return Trajectory(t, cols, model_name=model.name, state_names=model.state_names,
                      input_names=model.input_names, output_names=model.output_names, units=units,
                      meta={"model": model.name, "method": method, "params": model.param_dict(p)})


def _check_steps(model: Model, dt: np.ndarray, substeps: int, x0, u0, p, method: str) -> None:
    """The longest fixed (sub-)step against the stability limit at the start (see :func:`check_step`)."""
    if dt.size == 0 or method not in ("euler", "rk4"):
        return
    k = int(np.argmax(dt))
    h = float(dt[k]) / substeps
    where = f" (interval {k}, {dt[k]:.4g} s long" + (f" in {substeps} sub-steps)" if substeps > 1 else ")")
    check_step(model, h, x0, u0, p, method, where=where)


def _output_selection(model: Model):
    """``[("x" | "u", index), ...]`` if every output is a state or an input symbol, else None."""
    import casadi as ca

    found = []
    for i in range(model.ny):
        yi = model.y[i]
        hit = next((("x", j) for j in range(model.nx) if ca.is_equal(yi, model.x[j])), None) or \
            next((("u", j) for j in range(model.nu) if ca.is_equal(yi, model.u[j])), None)
        if hit is None:
            return None
        found.append(hit)
    return found


def _constant_rows(A: np.ndarray) -> bool:
    return bool(A.shape[1] == 0 or np.all(A == A[:1]))


def _adaptive_on_grid(model: Model, x0, t, u, p, w, options) -> np.ndarray:
    """Inputs constant over the whole record: one CVODES integration with outputs on the grid
    (no restart at every sample, which only piecewise-constant inputs need)."""
    import casadi as ca

    x = ca.MX.sym("x", model.nx)
    theta = ca.MX.sym("theta", model.nu + model.np + model.nw)
    us, ps, ws = theta[:model.nu], theta[model.nu:model.nu + model.np], theta[model.nu + model.np:]
    opts = {"abstol": 1e-10, "reltol": 1e-10}
    opts.update(options or {})
    integ = ca.integrator(f"{model.c_name}_cvodes_grid", "cvodes", {"x": x, "p": theta, "ode": model.f(x, us, ps, ws)},
                          float(t[0]), [float(v) for v in t[1:]], opts)
    try:
        xf = integ(x0=x0, p=np.concatenate([u, p, w]))["xf"]
    except RuntimeError as exc:
        status = solver_status(exc)
        raise IntegrationError(f"integration of {model.name!r} (cvodes) failed between t = {t[0]:g} and "
                               f"{t[-1]:g} s: solver status {status}", status, 0) from exc
    return np.vstack([x0[None, :], np.asarray(xf).T])


def _noise_matrix(model: Model, t: np.ndarray, w) -> np.ndarray:
    if w is None:
        return np.zeros((t.size, model.nw))
    W = np.asarray(w, dtype=float)
    if W.ndim == 1 and model.nw == 1:
        W = W[:, None]
    if W.shape != (t.size, model.nw):
        raise InputError(f"w has shape {W.shape}, expected ({t.size}, {model.nw}) for noise channels "
                         f"{list(model.noise_names)}")
    if not np.all(np.isfinite(W)):
        row, col = np.argwhere(~np.isfinite(W))[0]
        raise InputError(f"process noise {model.noise_names[col]!r} is not finite at row {row}")
    return W


def _closed_loop(model, dmodel, x0, t, controller: Callable, p, W, dt, first=None):
    step = BufferedCall(dmodel.F)
    slot = dict(zip(dmodel.F.name_in(), step.args))          # input slots by name
    x_next = dict(zip(dmodel.F.name_out(), step.res))["xf"]
    slot["p"][:] = p
    X = np.empty((t.size, model.nx))
    U = np.empty((t.size, model.nu))
    X[0] = x0
    for k in range(t.size):
        u = np.asarray(controller(t[k], X[k]), dtype=float).reshape(-1)
        if u.shape != (model.nu,) or not np.all(np.isfinite(u)):
            raise InputError(f"input function returned {u!r} at t = {t[k]:g} s; expected {model.nu} finite values "
                             f"for {list(model.input_names)}")
        U[k] = u
        if k == 0:
            check_radians(model, U[:1])
            if first is not None:
                first(u)
        if k + 1 < t.size:
            slot["x"][:], slot["u"][:], slot["w"][:], slot["dt"][:] = X[k], u, W[k], dt[k]
            step()
            X[k + 1] = x_next
    return X, U


def measure(traj: Dataset, model: Model, std: Mapping[str, float], *, rates: Mapping[str, float] | None = None,
            seed=None, keep: tuple[str, ...] = ()) -> Dataset:
    """Noisy measurements of a simulated trajectory.

    Parameters
    ----------
    traj : Trajectory
        Simulated record holding the model's outputs and inputs.
    model : Model
        Its output names select the columns; angle outputs are wrapped to (-pi, pi].
    std : mapping output name -> standard deviation
        Outputs not named here are not measured.
    rates : mapping output name -> rate [Hz], optional
        Channels sampled slower than the record; other rows are NaN (not measured).
    seed : int or numpy.random.Generator
    keep : tuple of str
        Extra columns of ``traj`` to copy (e.g. true states for later comparison, prefixed ``true_``).

    Returns
    -------
    Dataset
        Inputs of the model, the measured outputs (NaN where not sampled) and ``true_*`` columns.
    """
    rng = np.random.default_rng(seed)
    unknown = set(std) - set(model.output_names)
    if unknown:
        raise InputError(f"unknown output name(s) {sorted(unknown)}; outputs: {list(model.output_names)}")
    rates = dict(rates or {})
    unknown = set(rates) - set(std)
    if unknown:
        raise InputError(f"rates given for unmeasured output(s) {sorted(unknown)}")
    t = traj.t
    cols = {n: traj[n] for n in model.input_names}
    for name in model.output_names:
        if name not in std:
            continue
        sigma = float(std[name])
        if not np.isfinite(sigma) or sigma < 0:
            raise InputError(f"standard deviation of {name!r} must be finite and >= 0, got {sigma}")
        y = traj[name] + sigma * rng.standard_normal(t.size)
        if model.angle_outputs[model.index(name, "output")]:
            y = wrap(y)
        if name in rates:
            try:
                y = np.where(sample_mask(t, rates[name]), y, np.nan)
            except ValueError as exc:
                raise InputError(f"rate of {name!r}: {exc}") from None
        cols[name] = y
    for name in keep:
        cols[f"true_{name}"] = traj[name]
    return Dataset(t, cols, traj.units, {"measured_from": traj.meta.get("model", ""), "std": dict(std)})


def sample_mask(t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Rows of the grid ``t`` at which a sensor of ``rate_hz`` delivers.

    The sensor samples at ``t[0] + k / rate_hz``; each sample lands on the first grid row at or after
    its time (rows coincide when the rate divides the grid rate, e.g. 5 Hz in 50 Hz: every 10th
    row). A rate at or above the grid rate samples every row. The first row is always sampled.
    """
    rate_hz = float(rate_hz)
    if not np.isfinite(rate_hz) or rate_hz <= 0:
        raise InputError(f"sample rate must be a positive finite number [Hz], got {rate_hz}")
    t = np.asarray(t, dtype=float)
    tick = np.floor((t - t[0]) * rate_hz + 1e-6)
    return np.concatenate([[True], np.diff(tick) > 0])
