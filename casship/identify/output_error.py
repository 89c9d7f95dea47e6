"""Output-error identification: weighted least squares of simulated against measured outputs.

The deterministic model is simulated with each record's measured inputs from its initial state
(single shooting), or over segments whose initial states are extra unknowns tied together by
continuity constraints (multiple shooting, solved by IPOPT; more robust for unstable or long
records). The cost is ``0.5 sum ((y - yhat) / sigma)^2`` over the measured samples of all records,
plus the prior's; derivatives are exact.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..angles import unwrap, wrap_sym
from .spec import OutputErrorOptions
from ..discretize import DiscreteModel, discretize
from ..model import Model
from ._engine import OutputErrorEngine
from ._solver import SolverReport
from .problem import IdentificationProblem
from .records import as_records, check_gaps, noise_std
from .result import FitResult
from ..errors import InputError, InputTypeError

__all__ = ["OutputErrorProblem"]


def _record_weights(weights, records) -> np.ndarray:
    if weights is None:
        return np.ones(len(records))
    w = np.asarray(weights, dtype=float).ravel()
    if w.size != len(records):
        raise InputError(f"record_weights: {w.size} weight(s) for {len(records)} record(s)")
    bad = [i for i, v in enumerate(w) if not (np.isfinite(v) and v > 0)]
    if bad:
        raise InputError(f"record_weights must be positive and finite; record(s) {bad} have {w[bad].tolist()}")
    return w


class OutputErrorProblem(IdentificationProblem):
    """Output-error (simulation-error) identification over one or many records.

    Parameters
    ----------
    model : Model or DiscreteModel
        A continuous model is discretised with ``method`` at the records' median sampling period
        (each step uses the record's own time stamps).
    datasets : Dataset or sequence of Dataset
        Records with the model's inputs (finite) and measured outputs (NaN = not measured).
    free : sequence of str
        Free model parameters and biases (``"bias[n]"``: an offset added to a measured input;
        ``"bias[psi]"``: an offset of a measured output's sensor).
    measured : sequence of str, optional
        Outputs compared (default: every output that is a column of every record).
    sigma : mapping output -> standard deviation, or "estimate", optional
        Measurement noise of each output (the weights are ``1 / sigma``). Default ``"estimate"``:
        from the records themselves (:func:`~casship.identify.noise_std`, a high-pass); a mapping
        may give some channels and leave the others estimated. Standard errors are scaled by the
        root mean square weighted residual, so they stay right when ``sigma`` is only right up to a
        factor; each channel's share of the cost is reported.
    params : array or mapping, optional
        Values of the fixed parameters (nominal by default).
    x0 : mapping or sequence of (array or mapping), optional
        Initial state of each record; by default states named like a column start at its first
        value (NaN there is an error naming the record), the others at 0.
    estimate_x0 : sequence of str
        States whose initial values are estimated per record (``<state>@<record>``).
    share : mapping name -> "record" | "all" | grouping | labels, optional
        Which free quantities are per record or per group (see
        :func:`~casship.identify.share_labels`), e.g. ``{"bias[n]": "record", "N_0": "facility"}``.
    groups : mapping grouping -> labels, optional
        Group labels per record (else taken from each record's ``meta``).
    record_weights : sequence of float, optional
        One positive factor per record multiplying its squared residuals in the cost (default 1):
        e.g. ``1 / N_r`` so that every record counts the same however long it is. The weights are
        a design choice of the cost, stated with the fit (``fit.noise["record_weights"]``).
    prior : Prior or mapping name -> std, optional
        Gaussian prior (MAP), centred on the published values by default.
    shooting : {"single", "multiple"}
    segment : int
        Samples per shooting segment (multiple shooting).
    method : str
        Discretisation of a continuous model (``"rk4"``, ``"euler"``, ``"cvodes"``).
    bounds, scale : mapping name -> (lower, upper) / magnitude, optional
        For any free quantity (a declared name applies to all its copies); the model's parameter
        bounds apply too.
    record_params : sequence of (mapping name -> value, or None), optional
        One entry per record: fixed parameter values of that record over ``params`` (e.g. a
        facility's own measured wake; the free quantities are unaffected). A new run is at ``params``.
    jit : bool or None
        Compile the cost and its derivatives to C (``None``: when a compiler works; code not in the
        cache yet is compiled in the background while the fit runs interpreted, with the same numbers).

    Examples
    --------
    >>> import numpy as np, casship as cs
    >>> m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    >>> t = np.arange(0, 300, 1.0)
    >>> runs = [cs.measure(cs.simulate(m, m.states(), t, {"delta": a * np.sign(np.sin(t / 25))}), m,
    ...                    {"psi": 0.01}, seed=i) for i, a in enumerate((0.1, -0.15))]
    >>> prob = cs.OutputErrorProblem(m, runs, free=["K", "T"], sigma={"psi": 0.01}, estimate_x0=["psi"])
    >>> fit = prob.solve(guess={"K": 0.05, "T": 10.0}, show=False)
    >>> abs(fit.estimates["K"] - 0.1) < 4 * fit.std_errors["K"]
    True
    """

    method = "output-error"

    OPTIONS = OutputErrorOptions

    def __init__(self, model, datasets, free: Sequence[str] = (), *, measured: Sequence[str] | None = None,
                 sigma: Mapping[str, float] | str | None = "estimate", params=None, x0=None,
                 estimate_x0: Sequence[str] = (), share: Mapping | None = None, groups: Mapping | None = None,
                 record_weights: Sequence[float] | None = None, prior=None, shooting: str = "single",
                 segment: int = 50, method: str = "rk4", bounds=None, scale=None, jit: bool | None = None,
                 record_params: Sequence[Mapping | None] | None = None):
        kwargs = dict(model=model, datasets=datasets, free=free, measured=measured, sigma=sigma, params=params, x0=x0,
                      estimate_x0=estimate_x0, share=share, groups=groups, record_weights=record_weights, prior=prior,
                      shooting=shooting, segment=segment, method=method, bounds=bounds, scale=scale, jit=jit,
                      record_params=record_params)
        records = as_records(datasets)
        self.record_weights = _record_weights(record_weights, records)
        if isinstance(model, Model):          # a discrete-time model has its own step
            cont = model                       # kept with the model: every problem on it shares the steps
            dt = None if cont.dt is not None else float(np.median(np.diff(records[0].t)))
            model = cont.derived(("discretize", method, dt), lambda: discretize(cont) if dt is None
                                 else discretize(cont, dt, method=method))
        if not isinstance(model, DiscreteModel):
            raise InputTypeError(f"OutputErrorProblem needs a Model or DiscreteModel, got {type(model).__name__}")
        for d in records:                      # a discrete-time model steps its own dt, nothing else
            model.check_steps(np.diff(d.t), d.t)
        if shooting not in ("single", "multiple"):
            raise InputError(f"shooting must be 'single' or 'multiple', got {shooting!r}")
        self.dmodel = model
        m = model.model
        if measured is None:
            measured = [n for n in m.output_names if all(n in d for d in records)]
            if not measured:
                raise InputError(f"no output of {m.name!r} {list(m.output_names)} is a column of every record")
        self.meas_index = m.indices(measured, "output")
        self.angle_meas = m.angle_outputs[self.meas_index]
        self.sigma = self._sigma(records, list(measured), sigma)
        self.shooting, self.segment = shooting, int(segment)
        if self.segment < 2:
            raise InputError(f"segment must be >= 2 samples, got {segment}")
        self._setup(m, records, free, kwargs=kwargs, share=share, groups=groups, prior=prior, params=params, x0=x0,
                    estimate_x0=estimate_x0, bounds=bounds, scale=scale, measured=measured, record_params=record_params)
        check_gaps(self.dmodel, self.records, self.x0, self.space.base, self.labels)
        self._arrays = [self._arrays_of(d) for d in self.records]
        if shooting == "multiple" and np.any(self.record_weights != 1.0):
            raise InputError("record_weights are supported with single shooting only")
        self.engine = OutputErrorEngine(self.dmodel, self.space, self._arrays, self.meas_index, 1.0 / self.sigma, jit,
                                        record_scale=np.sqrt(self.record_weights))
        self._check_data_amount()

    def _sigma(self, records, measured, sigma) -> np.ndarray:
        m = self.dmodel.model
        given = {} if sigma is None or isinstance(sigma, str) else dict(sigma)
        if isinstance(sigma, str) and sigma != "estimate":
            raise InputError(f"sigma must be a mapping output -> std or 'estimate', got {sigma!r}")
        unknown = set(given) - set(measured)
        if unknown:
            raise InputError(f"sigma given for {sorted(unknown)}, not among measured {list(measured)}")
        bad = [n for n, v in given.items() if not (np.isfinite(float(v)) and float(v) > 0)]
        if bad:
            raise InputError(f"sigma values must be positive: {bad}")
        rest = [n for n in measured if n not in given]
        angles = [n for n in rest if m.angle_outputs[m.index(n, "output")]]
        est = noise_std(records, rest, angles) if rest else {}
        self.sigma_estimated = est
        return np.array([float(given.get(n, est.get(n))) for n in measured])

    def _arrays_of(self, d) -> dict:
        m = self.model
        missing = [n for n in (*m.input_names, *self.measured) if n not in d]
        if missing:
            raise InputError(f"data has no column(s) {missing}; columns: {list(d.names)}")
        U = d.matrix(m.input_names, finite=True, what="input")
        Y = d.matrix(self.measured)
        mask = np.isfinite(Y)
        return {"U": U.T, "Y": np.nan_to_num(Y).T, "mask": mask.T.astype(float),
                "dt": np.concatenate([np.diff(d.t), [0.0]])[None, :]}

    # -- problem hooks -----------------------------------------------------------------------------
    def _n_obs(self) -> int:
        return int(sum(a["mask"].sum() for a in self._arrays))

    def _residual_scale(self, f_data: float, n_obs: int) -> float:
        return 2 * f_data / max(n_obs - len(self.space), 1)

    def _loglik(self, f_data, s2, n_obs) -> float:
        # record r's residuals have the standard deviation sigma / sqrt(weight_r)
        log_sig = 0.0
        for a, w in zip(self._arrays, self.record_weights):
            n_per = a["mask"].sum(axis=1)
            log_sig += float(np.sum(n_per * np.log(np.sqrt(s2) * self.sigma / np.sqrt(w))))
        return float(-0.5 * n_obs * (1 + np.log(2 * np.pi)) - log_sig)

    def _noise_report(self, theta) -> dict:
        s2 = self._residual_scale(self.engine.cost(theta)[0], self._n_obs())
        out = {"sigma": dict(zip(self.measured, self.sigma.tolist())),
               "sigma_estimated": dict(self.sigma_estimated), "weight_scale": float(np.sqrt(s2))}
        if np.any(self.record_weights != 1.0):
            out["record_weights"] = dict(zip(self.labels, self.record_weights.tolist()))
        return out

    def _first_nonfinite(self, r, theta) -> str:
        res = self.engine.residuals(r, theta)
        rows = np.flatnonzero(~np.all(np.isfinite(res), axis=1))
        return f" (simulation not finite from t = {self.records[r].t[rows[0]]:g} s)" if rows.size else ""

    def residuals(self, values=None) -> list[np.ndarray]:
        """Weighted residuals ``(y - yhat) / sigma`` (N, n_measured) of each record (single shooting).

        Parameters
        ----------
        values : mapping name -> value, optional
            Free values (missing names keep their start).

        Returns
        -------
        list of arrays
        """
        theta = self.space.theta(values)
        return [self.engine.residuals(r, theta) for r in range(len(self.records))]

    # -- multiple shooting -------------------------------------------------------------------------
    def solve(self, guess: Mapping[str, float] | None = None, *, max_iter: int = 100, tol: float = 1e-8,
              show: bool | None = None, options: Mapping | None = None, verdict: str | None = "replay") -> FitResult:
        """Minimise the weighted output error (plus the prior's cost).

        Single shooting uses bounded Gauss-Newton trust-region steps on the exact residual Jacobian
        (see :meth:`IdentificationProblem.solve`); multiple shooting uses IPOPT with the exact
        Hessian of the Lagrangian. Either way a fit that stops early returns its iterate with the
        status and a warning.

        Parameters
        ----------
        guess : mapping, optional
            Starting values of the free quantities.
        max_iter : int
            Iteration limit.
        tol : float
            Convergence threshold (single shooting; see the base class).
        show : bool, optional
            ``False`` hides the progress bar.
        options : mapping, optional
            IPOPT options (multiple shooting).
        verdict : {"replay", "loo", None}
            Replay the fit on its records against the starting model (``"replay"``), also left-one-out
            (``"loo"``: one refit per record), or not (None); see :meth:`judge`.

        Returns
        -------
        FitResult
        """
        if self.shooting == "single":
            fit = super().solve(guess, max_iter=max_iter, tol=tol, show=show)
        else:
            fit = self._solve_multiple(guess, max_iter, options)
        return self._verdict(fit, verdict, guess)

    def _solve_multiple(self, guess, max_iter, options) -> FitResult:
        from ._ipopt import ipopt_solve

        m, sp = self.model, self.space
        theta0 = sp.theta(guess)
        sp.check_bounds(theta0)
        self._check_finite(theta0)
        z = ca.MX.sym("z", len(sp))
        theta = ca.vertcat(*[ca.exp(z[i]) if e.log else z[i] * e.scale for i, e in enumerate(sp.entries)])
        s_syms, s0, g, cost = [], [], [], 0
        for r, (arr, d) in enumerate(zip(self._arrays, self.records)):
            rm = sp.record_map(r)
            loc = theta[[int(c) for c in rm.cols]] if rm.k else ca.MX(0, 1)
            blk = {key: ca.DM(rm.fixed[key]) + (ca.mtimes(ca.DM(rm.E[key]), loc) if rm.k else 0) for key in rm.fixed}
            n = arr["U"].shape[1]
            U = arr["U"] + ca.repmat(blk["u"], 1, n)
            starts = list(range(0, n - 1, self.segment))
            traj = self._guess_states(r, d, sp.record_map(r).values(theta0))
            x_start = blk["x0"]
            for j, a in enumerate(starts):
                b = n if j + 1 == len(starts) else starts[j + 1] + 1
                X = self._simulate_sym(x_start, blk["p"], U[:, a:b], arr["dt"][:, a:b - 1])
                last = j + 1 == len(starts)
                use = slice(a, b if last else b - 1)
                cost += 0.5 * ca.sumsqr(self._residuals_sym(X[:, : use.stop - use.start], blk, U[:, use], arr, use))
                if not last:
                    s = ca.MX.sym(f"s{r}_{j + 1}", m.nx)
                    s_syms.append(s)
                    s0.append(traj[b - 1])
                    g.append(X[:, -1] - s)
                    x_start = s
        d_ = theta - self._mu
        cost += 0.5 * ca.sum1(ca.DM(self._prec) * d_ * d_)
        lbz, ubz = sp.z_bounds()
        w = ca.vertcat(z, *s_syms)
        w0 = np.concatenate([sp.to_z(theta0), *s0]) if s0 else sp.to_z(theta0)
        pad = np.full(len(s0) * m.nx, np.inf)
        gg = ca.vertcat(*g) if g else ca.MX(0, 1)
        opts = {"max_iter": max_iter, **dict(options or {})}
        w_opt, st, seconds = ipopt_solve(cost, w, w0, np.concatenate([lbz, -pad]), np.concatenate([ubz, pad]), g=gg,
                                         lbg=np.zeros(gg.shape[0]), ubg=np.zeros(gg.shape[0]), options=opts,
                                         name="output_error_ms")
        zo = w_opt[: len(sp)]
        th = sp.natural(zo)
        f, gr, H, det = self.engine.derivatives(th)
        status = st.get("return_status", "unknown")
        ok = status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
        rep = SolverReport(zo, f + self._prior_terms(th)[0], gr, H, "converged" if ok else status,
                           f"IPOPT: {status}", int(st.get("iter_count", 0)), seconds, float("nan"))
        fit = self._result(rep, {"f": f, "H": H, "det": det}, self._shares(self.engine.derivatives(theta0)[3]))
        fit.method, fit.status = "output-error-multiple", status
        return fit

    def _simulate_sym(self, x0, p, U, dt):
        steps = U.shape[1] - 1
        if steps == 0:
            return x0
        X = self.dmodel.F.mapaccum(steps)(x0, U[:, :steps], p, np.zeros((self.model.nw, 1)), dt)
        return ca.horzcat(x0, X)

    def _residuals_sym(self, X, blk, U, arr, rows: slice):
        m = self.model
        n = rows.stop - rows.start
        Yh = m.h.map(n)(X, U, blk["p"])
        Yh = ca.vertcat(*[Yh[i, :] for i in self.meas_index])
        E = arr["Y"][:, rows] - ca.repmat(blk["y"], 1, n) - Yh
        if self.angle_meas.any():
            E = ca.vertcat(*[wrap_sym(E[j, :]) if a else E[j, :] for j, a in enumerate(self.angle_meas)])
        return (arr["mask"][:, rows] * E) / self.sigma[:, None]

    def _guess_states(self, r, d, vals) -> np.ndarray:
        """Segment start guesses: measured states where a column holds them, else a simulation."""
        from ..simulation import fold_steps

        m, arr = self.model, self._arrays[r]
        U = (arr["U"] + vals["u"][:, None]).T
        X = fold_steps(self.dmodel, vals["x0"], U, vals["p"], np.zeros((U.shape[0], m.nw)), arr["dt"][0, :-1])
        for i, s in enumerate(m.state_names):
            if s in d:
                col = d[s].astype(float)
                if m.angle_states[i]:
                    col = unwrap(col)
                ok = np.isfinite(col)
                if ok.sum() >= 2:
                    X[:, i] = np.interp(d.t, d.t[ok], col[ok])
        return X

    def __repr__(self) -> str:
        return (f"OutputErrorProblem({self.model.name!r}, {len(self.records)} record(s), free={self.free}, "
                f"shooting={self.shooting!r})")
