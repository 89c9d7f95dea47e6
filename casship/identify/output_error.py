"""Output-error identification: weighted least squares of simulated against measured outputs.

The deterministic model is simulated with the measured inputs from each record's initial state
(single shooting), or over segments whose initial states are extra unknowns tied together by
continuity constraints (multiple shooting, more robust for unstable or long records). The cost is
``0.5 sum ((y - yhat) / sigma)^2`` over the measured samples; derivatives are exact.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..angles import unwrap, wrap, wrap_sym
from ..data import Dataset
from ..discretize import DiscreteModel, discretize
from ..model import Model
from ._space import ParamSpace, ipopt_solve
from .mle import _as_records
from .result import FitResult, finish

__all__ = ["OutputErrorProblem"]


class OutputErrorProblem:
    """Output-error (simulation-error) least squares for deterministic models.

    Parameters
    ----------
    model : Model or DiscreteModel
        A continuous model is discretised with ``method`` at the records' sampling period.
    datasets : Dataset or sequence of Dataset
    free : sequence of str
        Free model parameters.
    measured : sequence of str, optional
        Outputs compared (default: all outputs present as columns in the first record).
    sigma : mapping output -> standard deviation, optional
        Weights (default 1). Standard errors are scaled by the root mean square weighted residual,
        so they stay right when ``sigma`` is only known up to a factor.
    params : array or mapping, optional
        Values of the fixed parameters.
    x0 : mapping or sequence of (array or mapping), optional
        Initial state of each record; by default states named like a column start at its first value,
        the others at 0 (a mapping overrides named states for all records).
    estimate_x0 : sequence of str
        States whose initial values are estimated per record (``<state>@<k>``).
    shooting : {"single", "multiple"}
        Multiple shooting splits each record into segments of ``segment`` samples.
    segment : int
        Samples per shooting segment.
    method : str
        Discretisation method for a continuous model (``"rk4"``, ``"euler"``, ``"cvodes"``).
    bounds, scale : mapping, optional
    """

    method = "output-error"

    def __init__(self, model, datasets, free: Sequence[str] = (), *, measured: Sequence[str] | None = None,
                 sigma: Mapping[str, float] | None = None, params=None, x0=None, estimate_x0: Sequence[str] = (),
                 shooting: str = "single", segment: int = 50, method: str = "rk4", bounds=None, scale=None):
        self.records = _as_records(datasets)
        if isinstance(model, Model):
            model = discretize(model, float(np.median(np.diff(self.records[0].t))), method=method)
        if not isinstance(model, DiscreteModel):
            raise TypeError(f"OutputErrorProblem needs a Model or DiscreteModel, got {type(model).__name__}")
        if shooting not in ("single", "multiple"):
            raise ValueError(f"shooting must be 'single' or 'multiple', got {shooting!r}")
        self.dmodel, self.model = model, model.model
        m = self.model
        if measured is None:
            measured = [n for n in m.output_names if n in self.records[0]]
            if not measured:
                raise ValueError(f"no output of {m.name!r} {list(m.output_names)} is a column of the data")
        self.measured = tuple(measured)
        self.meas_index = m.indices(self.measured, "output")
        self.angle_meas = m.angle_outputs[self.meas_index]
        sigma = dict(sigma or {})
        unknown = set(sigma) - set(self.measured)
        if unknown:
            raise ValueError(f"sigma given for {sorted(unknown)}, not among measured {list(self.measured)}")
        self.sigma = np.array([float(sigma.get(n, 1.0)) for n in self.measured])
        if not np.all(self.sigma > 0):
            raise ValueError("sigma values must be positive")
        self.shooting, self.segment = shooting, int(segment)
        if self.segment < 2:
            raise ValueError(f"segment must be >= 2 samples, got {segment}")
        self.x0 = self._initial_states(x0)
        estimate_x0 = list(estimate_x0)
        m.indices(estimate_x0, "state")
        x0_entries = [(f"{s}@{k}", k, m.index(s), self.x0[k][m.index(s)])
                      for k in range(len(self.records)) for s in estimate_x0]
        base = m.params(params) if params is not None else m.params()
        self.space = ParamSpace(m, free, base, bounds=bounds, scale=scale, x0_entries=x0_entries)
        if not len(self.space):
            raise ValueError("nothing to estimate: give free parameters or estimate_x0")
        self._prepare()

    # -- set-up ------------------------------------------------------------------------------------
    def _initial_states(self, x0) -> list[np.ndarray]:
        m, recs = self.model, self.records
        if x0 is None or isinstance(x0, Mapping):
            out = []
            for d in recs:
                v = np.array([d[s][0] if s in d and np.isfinite(d[s][0]) else 0.0 for s in m.state_names])
                if isinstance(x0, Mapping):
                    idx = m.indices(x0, "state")
                    v[idx] = m.states(**x0)[idx]
                out.append(v)
            return out
        x0 = list(x0)
        if len(x0) != len(recs):
            raise ValueError(f"x0: {len(x0)} initial states for {len(recs)} records")
        out = []
        for v in x0:
            v = m.states(**v) if isinstance(v, Mapping) else np.asarray(v, dtype=float).reshape(-1)
            if v.shape != (m.nx,):
                raise ValueError(f"x0 entry has {v.size} values, model has {m.nx} states")
            out.append(v)
        return out

    def _prepare(self) -> None:
        m = self.model
        self._arrays = []
        for d in self.records:
            missing = [n for n in (*m.input_names, *self.measured) if n not in d]
            if missing:
                raise ValueError(f"data has no column(s) {missing}; columns: {list(d.names)}")
            U = d.matrix(m.input_names, finite=True, what="input")
            Y = d.matrix(self.measured)
            mask = np.isfinite(Y)
            self._arrays.append(dict(U=U, Y=np.nan_to_num(Y), mask=mask.astype(float), dt=np.diff(d.t)))

    def _simulate_sym(self, x0, p, arr, rows: slice):
        """States at the rows of a slice, simulated from ``x0`` at its first row."""
        dm, m = self.dmodel, self.model
        start, stop = rows.start, rows.stop
        steps = stop - start - 1
        if steps == 0:
            return x0
        X = dm.F.mapaccum(steps)(x0, arr["U"][start:stop - 1].T, p, np.zeros((m.nw, 1)),
                                 arr["dt"][start:stop - 1][None, :])
        return ca.horzcat(x0, X)

    def _residuals_sym(self, X, p, arr, rows: slice):
        m = self.model
        n = rows.stop - rows.start
        Yh = m.h.map(n)(X, arr["U"][rows].T, p)
        Yh = ca.vertcat(*[Yh[i, :] for i in self.meas_index])
        E = arr["Y"][rows].T - Yh
        if self.angle_meas.any():
            E = ca.vertcat(*[wrap_sym(E[j, :]) if a else E[j, :] for j, a in enumerate(self.angle_meas)])
        return (arr["mask"][rows].T * E) / self.sigma[:, None]

    def _x0_sym(self, nat, r):
        items = [ca.MX(float(v)) for v in self.x0[r]]
        for e, v in zip(self.space.entries, nat):
            if e.kind == "x0" and e.record == r:
                items[e.index] = v
        return ca.vertcat(*items)

    def _single(self, nat):
        p = self.space.param_vector(nat)
        res = []
        for r, arr in enumerate(self._arrays):
            rows = slice(0, arr["U"].shape[0])
            X = self._simulate_sym(self._x0_sym(nat, r), p, arr, rows)
            res.append(self._residuals_sym(X, p, arr, rows))
        return res

    # -- evaluation --------------------------------------------------------------------------------
    @property
    def free(self) -> list[str]:
        return list(self.space.names)

    def residuals(self, values=None) -> list[np.ndarray]:
        """Weighted residuals (N, n_measured) of each record at the free values (single shooting)."""
        theta = ca.MX.sym("theta", len(self.space))
        f = ca.Function("oe_res", [theta], self._single([theta[i] for i in range(len(self.space))]))
        vals = {**self.space.default_guess, **dict(values or {})}
        out = f(np.array([vals[n] for n in self.space.names]))
        out = [out] if len(self.records) == 1 else out
        return [np.asarray(o).T for o in out]

    def cost(self, values=None) -> float:
        """Half the weighted sum of squared output errors."""
        return 0.5 * float(sum(np.sum(r**2) for r in self.residuals(values)))

    # -- solve -------------------------------------------------------------------------------------
    def solve(self, guess: Mapping[str, float] | None = None, *, hessian: str | None = None,
              options: Mapping | None = None) -> FitResult:
        """Minimise the weighted output error with IPOPT.

        Parameters
        ----------
        guess : mapping, optional
            Starting values of the free quantities.
        hessian : {"gauss-newton", "exact", "limited-memory"}, optional
            Curvature IPOPT uses: ``J'J`` of the residuals (single shooting; the default there), the
            exact Hessian of the Lagrangian (the default for multiple shooting) or L-BFGS.
        options : mapping, optional
            IPOPT options.
        """
        sp, m = self.space, self.model
        hessian = hessian or ("gauss-newton" if self.shooting == "single" else "exact")
        if hessian not in ("gauss-newton", "exact", "limited-memory"):
            raise ValueError(f"unknown hessian {hessian!r}; use 'gauss-newton', 'exact' or 'limited-memory'")
        if hessian == "gauss-newton" and self.shooting == "multiple":
            raise ValueError("hessian='gauss-newton' is for single shooting; use 'exact' with multiple shooting")
        z = ca.MX.sym("z", len(sp))
        nat = sp.natural(z)
        z0 = sp.guess_z(guess)
        lbz, ubz = sp.z_bounds()
        if self.shooting == "single":
            res = ca.vertcat(*[ca.vec(r) for r in self._single(nat)])
            f = 0.5 * ca.sumsqr(res)
            hess_f = None
            if hessian == "gauss-newton":
                J = ca.jtimes(res, z, ca.MX.eye(len(sp)))
                hess_f = J.T @ J
            z_opt, st, seconds = ipopt_solve(f, z, z0, lbz, ubz, hessian="custom" if hess_f is not None else hessian,
                                             hess_f=hess_f, options=options, name="output_error")
        else:
            z_opt, st, seconds = self._solve_multiple(z, nat, z0, lbz, ubz, hessian, options)
        # information (Gauss-Newton) from the single-shooting residuals at the optimum
        r_all = ca.vertcat(*[ca.vec(r) for r in self._single(nat)])
        jac = ca.Function("oe_jac", [z], [r_all, ca.jtimes(r_all, z, ca.MX.eye(len(sp)))])
        r_opt, J = (np.asarray(a) for a in jac(z_opt))
        cost = 0.5 * float(np.sum(r_opt**2))
        n_obs = int(sum(a["mask"].sum() for a in self._arrays))
        k = len(sp)
        s2 = 2 * cost / max(n_obs - k, 1)
        info = J.T @ J / s2
        values = sp.natural_numeric(z_opt)
        p = sp.param_vector(values)
        residuals = [r / np.sqrt(s2) for r in self.residuals(dict(zip(sp.names, values)))]
        predictions = []
        x0_out = []
        for rec, d, r in zip(range(len(self.records)), self.records, residuals):
            y = d.matrix(self.measured)
            yhat = y - r * np.sqrt(s2) * self.sigma
            yhat[:, self.angle_meas] = wrap(yhat[:, self.angle_meas])
            predictions.append({"t": d.t, "label": d.meta.get("name", d.meta.get("source", f"record {rec}")),
                                "kind": "simulated", "measured": {n: y[:, j] for j, n in enumerate(self.measured)},
                                "predicted": {n: yhat[:, j] for j, n in enumerate(self.measured)}})
            x0 = self.x0[rec].copy()
            for e, v in zip(sp.entries, values):
                if e.kind == "x0" and e.record == rec:
                    x0[e.index] = v
            x0_out.append(dict(zip(m.state_names, x0.tolist())))
        sig = np.sqrt(s2) * self.sigma
        n_per = np.array([sum(a["mask"][:, j].sum() for a in self._arrays) for j in range(len(self.measured))])
        loglik = -0.5 * n_obs * (1 + np.log(2 * np.pi)) - float(np.sum(n_per * np.log(sig)))
        noise = {"sigma": dict(zip(self.measured, sig.tolist())), "weight_scale": float(np.sqrt(s2))}
        return finish(model=m.name, params=m.param_dict(p), names=sp.names, values=values, info=info,
                      jac_nat=sp.jac_natural(z_opt), scale=sp.scales(), cost=cost, loglik=loglik, n_obs=n_obs,
                      residuals=residuals, output_names=self.measured,
                      method=f"output-error-{self.shooting}", status=st.get("return_status", ""),
                      iterations=st.get("iter_count", 0), solve_time_s=seconds, noise=noise, x0=x0_out,
                      predictions=predictions)

    def _solve_multiple(self, z, nat, z0, lbz, ubz, hessian, options):
        """Multiple shooting: segment start states are unknowns, continuity is a constraint."""
        m, sp = self.model, self.space
        p = sp.param_vector(nat)
        s_syms, s0, g, cost = [], [], [], 0
        p0 = sp.param_vector(sp.natural_numeric(z0))
        for r, (arr, d) in enumerate(zip(self._arrays, self.records)):
            n = arr["U"].shape[0]
            starts = list(range(0, n - 1, self.segment))
            guess_traj = self._initial_guess_states(r, d, p0)
            x_start = self._x0_sym(nat, r)
            for j, a in enumerate(starts):
                b = min(a + self.segment, n - 1) + 1 if j + 1 == len(starts) else starts[j + 1] + 1
                rows = slice(a, b)
                X = self._simulate_sym(x_start, p, arr, rows)
                last = j + 1 == len(starts)
                use = slice(a, b if last else b - 1)
                cost += 0.5 * ca.sumsqr(self._residuals_sym(X[:, : use.stop - use.start], p, arr, use))
                if not last:
                    s = ca.MX.sym(f"s{r}_{j + 1}", m.nx)
                    s_syms.append(s)
                    s0.append(guess_traj[b - 1])
                    g.append(X[:, -1] - s)
                    x_start = s
        w = ca.vertcat(z, *s_syms)
        w0 = np.concatenate([z0, *s0]) if s0 else z0
        lbw = np.concatenate([lbz, np.full(len(s0) * m.nx, -np.inf)])
        ubw = np.concatenate([ubz, np.full(len(s0) * m.nx, np.inf)])
        gg = ca.vertcat(*g) if g else ca.MX(0, 1)
        ng = gg.shape[0]
        w_opt, st, seconds = ipopt_solve(cost, w, w0, lbw, ubw, g=gg, lbg=np.zeros(ng), ubg=np.zeros(ng),
                                         hessian=hessian, options=options, name="output_error_ms")
        return w_opt[: len(sp)], st, seconds

    def _initial_guess_states(self, r, d: Dataset, p) -> np.ndarray:
        """Segment start guesses: measured states where a column holds them, else a simulation."""
        m = self.model
        arr = self._arrays[r]
        from ..simulate import fold_steps

        X = fold_steps(self.dmodel, self.x0[r], arr["U"], p, np.zeros((arr["U"].shape[0], m.nw)), arr["dt"])
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
