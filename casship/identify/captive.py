"""Identification from captive (PMM) model tests: the classical route, and a term for a joint fit.

:class:`CaptiveProblem` fits a ship model's parameters to the measured force components of a
:class:`~casship.io.captive.CaptiveTests` record by weighted least squares, i.e. maximum likelihood
with Gaussian noise of one standard deviation per *group* (static points or dynamic components,
per force channel). The noise rule is fixed in advance: unless given, each group's variance is
estimated with the coefficients (concentrated likelihood: fit, set ``sigma_g^2 = RSS_g / n_g *
n / (n - k)``, refit, until the sigmas settle), so that no channel's units decide the fit.

A captive rig belongs to a *facility*: its model, propeller and rudder are not the free-running
ship's. Parameters listed in ``facility_params`` (particulars, propeller, rudder, neutral angle)
are named ``name@facility`` (``w_P0@HMRI``), the hull coefficients keep their names; joined with a
free-running problem (:class:`~casship.identify.cost_term.JointProblem`), the hull is shared and
each facility keeps its own quantities.

:func:`linear_derivatives` gives the classical linear derivatives from the first harmonics of pure
sway and pure yaw (and the static drift slope), a cross-check on published values.
"""
from __future__ import annotations

import time
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError
from ..io.captive import HARMONICS
from ._solver import trust_region
from .captive_forces import CaptivePredictor, pmm_motion  # noqa: F401  (pmm_motion re-exported for users)
from .cost_term import CostTerm, fit_result
from .prior import Prior

__all__ = ["CaptiveProblem", "FACILITY_PARAMS", "linear_derivatives", "noise_groups"]

#: MMG parameters that belong to a test facility (its model, propeller, rudder), not to the hull form.
FACILITY_PARAMS = ("rho", "L_pp", "B", "d", "nabla", "x_G", "k_zz", "D_p", "t_P", "w_P0", "x_P_dash",
                   "k_0", "k_1", "k_2", "A_R", "H_R", "epsilon", "kappa", "f_alpha", "x_R_dash",
                   "delta_0", "Y_0_dash", "N_0_dash", "c_alpha3", "T_rud", "rudder_rate_max")


def noise_groups(observations) -> list[str]:
    """The noise group of each observation: ``static:X``, ``dynamic:N``... (test family and channel).

    Parameters
    ----------
    observations : sequence of Observation
        From :attr:`~casship.identify.captive_forces.CaptivePredictor.observations`.

    Returns
    -------
    list of str
    """
    return [f"{o.test}:{o.channel}" for o in observations]


class CaptiveProblem:
    """Weighted least squares (Gaussian ML) of a model's parameters on captive-test force components.

    Parameters
    ----------
    model : Model
        A ship model with states ``u, v, r`` and the port ``tau`` (see
        :func:`~casship.identify.captive_forces.captive_forces`), built with the captive model's
        particulars (length, draught, mass, propeller, rudder).
    tests : CaptiveTests
        The record (:func:`casship.io.read_captive`).
    free : sequence of str
        Model parameters to estimate (plain names).
    prior : Prior or mapping name -> std, optional
        Gaussian prior (means: the model's values unless ``Prior.mean`` gives them); names plain or
        joint (``w_P0@HMRI``).
    facility : str
        Name of the facility: the suffix of its own quantities' joint names.
    facility_params : sequence of str
        Parameters that belong to the facility (default :data:`FACILITY_PARAMS`).
    params : mapping or array, optional
        Parameter values to start from (default: the model's).
    channels : sequence of str
        Force channels to fit (``X, Y, N``; ``RY``, ``RX``, ``T`` for MMG models).
    components : sequence of str
        Dynamic-test components to fit. The default leaves out the means: the HMRI tables give
        dynamic means near zero at any drift (``Y'`` 0.00017-0.00019 at 16 deg against 0.0075 in the
        static test), i.e. referenced to the running condition, not absolute forces.
    sigma : mapping group -> float, optional
        Noise standard deviation per group (:func:`noise_groups`); groups not given are estimated
        (see the module docstring).
    static_kinds, dynamic_kinds : sequence of str, optional
        Test kinds to use (default: all).

    Examples
    --------
    >>> pb = CaptiveProblem(ship, tests, free=["Y_v_dash", "N_v_dash"])    # doctest: +SKIP
    >>> fit = pb.solve()                                                  # doctest: +SKIP
    >>> term = pb.cost_term(fit)          # for a JointProblem            # doctest: +SKIP
    """

    method = "captive"

    def __init__(self, model, tests, free: Sequence[str], *, prior=None, facility: str = "captive",
                 facility_params: Sequence[str] = FACILITY_PARAMS, params=None,
                 channels: Sequence[str] = ("X", "Y", "N"), components: Sequence[str] = HARMONICS[1:],
                 sigma: Mapping[str, float] | None = None, static_kinds=None, dynamic_kinds=None):
        self.model, self.tests, self.facility = model, tests, str(facility)
        free = list(free)
        if not free:
            raise InputError("CaptiveProblem: give the parameters to estimate (free=[...])")
        model.indices(free, "param")
        if len(set(free)) != len(free):
            raise InputError(f"CaptiveProblem: free names repeat: {free}")
        self.plain = free
        self.facility_params = tuple(facility_params)
        self.free = [self.joint_name(n) for n in free]
        self.base = model.params(params) if params is not None else model.params()
        self._idx = np.array(model.indices(free, "param"), dtype=int)
        self.predictor = CaptivePredictor(model, tests, channels, components, static_kinds=static_kinds,
                                          dynamic_kinds=dynamic_kinds, params=self.base)
        obs = self.predictor.observations
        self.groups = noise_groups(obs)
        self.group_names = sorted(set(self.groups))
        self._gidx = np.array([self.group_names.index(g) for g in self.groups])
        given = dict(sigma or {})
        unknown = set(given) - set(self.group_names)
        if unknown:
            raise InputError(f"CaptiveProblem: sigma given for unknown group(s) {sorted(unknown)}; groups: "
                             f"{self.group_names}")
        self.sigma_given = given
        self.lower = np.array([model.param_lower[i] for i in self._idx])
        self.upper = np.array([model.param_upper[i] for i in self._idx])
        self._mu, self._prec, self._prior_desc = self._prior(prior)
        if len(obs) <= len(free):
            raise InputError(f"CaptiveProblem: {len(obs)} measured values for {len(free)} free parameters")

    def joint_name(self, name: str) -> str:
        """The name of a model parameter in a joint problem (``name@facility`` for facility quantities).

        Parameters
        ----------
        name : str
            A model parameter.

        Returns
        -------
        str
        """
        return f"{name}@{self.facility}" if name in self.facility_params else name

    def _prior(self, prior):
        if prior is None:
            prior = Prior()
        elif isinstance(prior, Mapping):
            prior = Prior(std=prior)
        elif not isinstance(prior, Prior):
            raise InputError(f"CaptiveProblem: prior must be a Prior or a mapping name -> std, got {type(prior).__name__}")
        names = set(self.free) | set(self.plain)
        unknown = (set(prior.std) | set(prior.mean)) - names
        if unknown:
            raise InputError(f"CaptiveProblem: prior given for {sorted(unknown)}, which are not free; free: {self.free}")
        nominal = self.model.params()
        mu, prec, desc = np.zeros(len(self.free)), np.zeros(len(self.free)), {}
        for j, (jn, pn) in enumerate(zip(self.free, self.plain)):
            mu[j] = prior.mean.get(jn, prior.mean.get(pn, nominal[self._idx[j]]))
            s = prior.std.get(jn, prior.std.get(pn))
            if s is not None:
                prec[j] = prior.weight / s**2
                desc[jn] = {"mean": float(mu[j]), "std": float(s)}
        return mu, prec, ({"weight": prior.weight, "quantities": desc} if desc else {})

    # -- evaluation -----------------------------------------------------------------------------
    def params(self, theta) -> np.ndarray:
        """The model's parameter vector with the free values ``theta``.

        Parameters
        ----------
        theta : array_like
            Free values ordered like :attr:`free`.

        Returns
        -------
        array
        """
        p = self.base.copy()
        p[self._idx] = np.asarray(theta, dtype=float)
        return p

    def theta(self, values: Mapping[str, float] | None = None) -> np.ndarray:
        """Free values from a mapping.

        Parameters
        ----------
        values : mapping name -> value, optional
            Joint or plain names; missing ones keep the starting values.

        Returns
        -------
        array
        """
        values = dict(values or {})
        known = set(self.free) | set(self.plain)
        unknown = set(values) - known
        if unknown:
            raise InputError(f"CaptiveProblem: {sorted(unknown)} are not free; free: {self.free}")
        return np.array([values.get(j, values.get(p, self.base[i])) for j, p, i in zip(self.free, self.plain, self._idx)],
                        dtype=float)

    def prediction(self, theta=None) -> np.ndarray:
        """The model's components, ordered like ``predictor.observations``.

        Parameters
        ----------
        theta : array_like, optional
            Free values (default: the start).

        Returns
        -------
        array
        """
        return self.predictor.predict(self.params(self.theta() if theta is None else theta))

    def raw_residuals(self, theta) -> tuple[np.ndarray, np.ndarray]:
        """``(prediction - measured, d/d theta)`` (not whitened).

        Parameters
        ----------
        theta : array_like
            Free values ordered like :attr:`free`.

        Returns
        -------
        (array, 2-d array)
        """
        y, J = self.predictor.jacobian(self.params(theta))
        return y - self.predictor.measured, J[:, self._idx]

    def _sigma_vector(self, sigma: Mapping[str, float]) -> np.ndarray:
        missing = [g for g in self.group_names if g not in sigma]
        if missing:
            raise InputError(f"CaptiveProblem: no noise level for group(s) {missing}")
        s = np.array([float(sigma[g]) for g in self.group_names])
        if not np.all(np.isfinite(s) & (s > 0)):
            raise InputError(f"CaptiveProblem: noise levels must be positive: {dict(zip(self.group_names, s))}")
        return s[self._gidx]

    def _estimate_sigma(self, res, k) -> dict:
        n = len(res)
        out = {}
        for gi, g in enumerate(self.group_names):
            if g in self.sigma_given:
                out[g] = self.sigma_given[g]
                continue
            rg = res[self._gidx == gi]
            out[g] = float(np.sqrt(np.sum(rg**2) / len(rg) * n / max(n - k, 1)))
        return out

    def _fit(self, theta0, sigma, max_iter, tol, show):
        s = self._sigma_vector(sigma)

        def derivs(th):
            r, J = self.raw_residuals(th)
            r, J = r / s, J / s[:, None]
            d = th - self._mu
            return (0.5 * float(r @ r) + 0.5 * float(np.sum(self._prec * d * d)), J.T @ r + self._prec * d,
                    J.T @ J + np.diag(self._prec))

        def cost(th):
            r = (self.predictor.predict(self.params(th)) - self.predictor.measured) / s
            d = th - self._mu
            return 0.5 * float(r @ r) + 0.5 * float(np.sum(self._prec * d * d))

        return trust_region(derivs, cost, theta0, self.lower, self.upper, tol=tol, max_iter=max_iter,
                            label="captive fit", show=show)

    def solve(self, guess: Mapping[str, float] | None = None, *, max_iter: int = 100, tol: float = 1e-8,
              noise_passes: int = 5, show: bool | None = None):
        """Fit the free parameters (and, unless given, the noise level of each group).

        Parameters
        ----------
        guess : mapping name -> value, optional
            Starting values (default: the model's).
        max_iter, tol : int, float
            As for :meth:`casship.identify.IdentificationProblem.solve`.
        noise_passes : int
            Most fits of the alternation coefficients / noise levels (stops when the levels change
            by less than 1 %).
        show : bool, optional
            Progress bar.

        Returns
        -------
        FitResult
            ``free`` in joint names; ``noise["sigma"]`` the noise level of each group (given or
            estimated), ``noise["rms"]`` the RMS residual of each group; ``std_errors_robust`` the
            heteroscedasticity-consistent (sandwich) errors, each value's squared residual in place
            of its group's noise level.
        """
        t0 = time.perf_counter()
        theta = self.theta(guess)
        res = self.raw_residuals(theta)[0]
        # first pass: each group weighted by the RMS of its measured values (only to start)
        meas = self.predictor.measured
        sigma = {g: self.sigma_given.get(g, float(np.sqrt(np.mean(meas[self._gidx == i] ** 2))) or 1.0)
                 for i, g in enumerate(self.group_names)}
        rep = None
        for _ in range(max(int(noise_passes), 1)):
            rep = self._fit(theta, sigma, max_iter, tol, show)
            theta = rep.z
            res = self.raw_residuals(theta)[0]
            new = self._estimate_sigma(res, len(self.free))
            settled = all(abs(new[g] / sigma[g] - 1) < 0.01 for g in sigma)
            sigma = new
            if settled:
                break
        rep = self._fit(theta, sigma, max_iter, tol, show)      # the estimate at the final noise levels
        theta = rep.z
        s = self._sigma_vector(sigma)
        r, J = self.raw_residuals(theta)
        rw, Jw = r / s, J / s[:, None]
        info = Jw.T @ Jw + np.diag(self._prec)
        # robust (sandwich) covariance: the values' own squared residuals instead of their noise levels
        cov_inv = np.linalg.pinv(info)
        scores = Jw * rw[:, None]
        robust = cov_inv @ (scores.T @ scores) @ cov_inv
        n = len(r)
        loglik = float(-0.5 * rw @ rw - np.sum(np.log(s)) - 0.5 * n * np.log(2 * np.pi))
        rms = {g: float(np.sqrt(np.mean(r[self._gidx == i] ** 2))) for i, g in enumerate(self.group_names)}
        counts = {g: int(np.sum(self._gidx == i)) for i, g in enumerate(self.group_names)}
        return fit_result(model_name=self.model.name, params=self.model.param_dict(self.params(theta)), names=self.free,
                          theta=theta, info=info, cost=rep.f, n_obs=n, loglik=loglik, method=self.method,
                          status=rep.status, message=rep.message, iterations=rep.iterations,
                          seconds=time.perf_counter() - t0, lower=self.lower, upper=self.upper,
                          noise={"sigma": sigma, "rms": rms, "n": counts,
                                 "rule": "per group (static/dynamic x channel), estimated by concentrated ML"
                                 if not self.sigma_given else "given"},
                          records=[f"captive:{self.facility}"], prior=self._prior_desc, model=self.model,
                          robust=robust)

    def cost_term(self, fit=None, *, sigma: Mapping[str, float] | None = None, prior: bool = True) -> CostTerm:
        """This record as a :class:`~casship.identify.cost_term.CostTerm` for a joint problem.

        Parameters
        ----------
        fit : FitResult, optional
            A captive fit whose noise levels (``noise["sigma"]``) weight the residuals, and whose
            estimates are the starting values of the facility's own quantities.
        sigma : mapping group -> float, optional
            Noise levels (instead of ``fit``'s; every group needs one).
        prior : bool
            Carry this problem's prior on the facility's own quantities (shared quantities take the
            joined problem's prior).

        Returns
        -------
        CostTerm
            Over the joint names :attr:`free`.
        """
        if sigma is None:
            if fit is None:
                sigma = dict(self.sigma_given)
            else:
                sigma = dict(fit.noise.get("sigma", {}))
        s = self._sigma_vector(sigma)
        start = self.theta({n: fit.estimates[n] for n in self.free if n in fit.estimates} if fit is not None else None)

        def residual(theta):
            r, J = self.raw_residuals(theta)
            return r / s, J / s[:, None]

        def value(theta):
            return (self.predictor.predict(self.params(theta)) - self.predictor.measured) / s

        pstd = {}
        if prior and self._prior_desc:
            pstd = {n: q["std"] for n, q in self._prior_desc["quantities"].items()
                    if n.endswith(f"@{self.facility}")}
        return CostTerm(label=f"captive:{self.facility}", names=tuple(self.free), start=start, lower=self.lower.copy(),
                        upper=self.upper.copy(), residual=residual, n_obs=len(s), prior_std=pstd, value=value)

    def plot(self, fit, ax=None, path=None):
        """Measured against modelled force components: one panel per test kind and channel.

        Grey crosses: the model's own values (where the fit started); blue circles: ``fit``. The
        plot contract of :mod:`casship.plotting`.

        Parameters
        ----------
        fit : FitResult
            A fit of this problem (:meth:`solve`).
        ax : array of Axes, optional
            ``kinds x channels`` axes to draw into.
        path : str or Path, optional
            Where to write the figure.
        """
        from matplotlib.ticker import MaxNLocator

        from ..plotting import finish, panels, split_args

        ax, path = split_args(ax, path)
        obs = self.predictor.observations
        kinds = list(dict.fromkeys(o.kind for o in obs))
        chans = [c for c in self.predictor.channels if any(o.channel == c for o in obs)]
        fig, axes = panels(ax, len(kinds), len(chans), figsize=(3.0 * len(chans), 2.8 * len(kinds)),
                           what="the captive force plot")
        start = self.predictor.predict(self.base)
        pred = self.prediction(np.array([fit.estimates[n] for n in self.free]))
        meas = self.predictor.measured
        for i, kind in enumerate(kinds):
            for j, c in enumerate(chans):
                a = axes[i, j]
                idx = [q for q, o in enumerate(obs) if o.kind == kind and o.channel == c]
                if not idx:
                    a.set_axis_off()
                    continue
                m = meas[idx]
                a.plot(m, start[idx], "x", color="tab:gray", ms=4, label="start (the model's values)")
                a.plot(m, pred[idx], "o", color="tab:blue", ms=3, mfc="none", label="fit")
                lo, hi = float(np.min(m)), float(np.max(m))
                a.plot([lo, hi], [lo, hi], "k-", lw=0.6)
                a.set_title(f"{kind}: {c}'", fontsize=9)
                a.tick_params(labelsize=7)
                a.xaxis.set_major_locator(MaxNLocator(4))           # non-dimensional values: long tick labels
                a.yaxis.set_major_locator(MaxNLocator(5))
                if i == len(kinds) - 1:
                    a.set_xlabel("measured", fontsize=8)
                if j == 0:
                    a.set_ylabel("model", fontsize=8)
        axes[0, 0].legend(fontsize=7)
        return finish(fig, ax, path)

    def __repr__(self) -> str:
        return (f"CaptiveProblem({self.model.name!r}, facility={self.facility!r}, {len(self.predictor.observations)} "
                f"values, free={self.free})")


def linear_derivatives(tests, *, L: float, T: float, mass: float | None = None, rho: float = 1000.0,
                       x_G: float = 0.0, I_z: float | None = None) -> dict:
    """Classical linear derivatives from the first harmonics of pure sway and pure yaw, and the static drift slope.

    Each is the least-squares slope through the origin of a first-harmonic component against its
    motion amplitude over the test's amplitudes (with a cubic term, so the slope is the linear
    derivative): pure sway ``Y_out1 = Y'_v v'`` and ``Y_in1 = -(m' + m'_y) vdot'`` (``v' = -vdot' U /
    (omega L)`` the sway-velocity amplitude), likewise ``N``; pure yaw ``Y_out1 = (Y'_r - m' - m'_x) r'``,
    ``N_in1 = -(I'_z + J'_z) rdot'``, ``N_out1 = (N'_r - x'_G m') r'``. The forces include the
    rigid-body inertia (see :func:`~casship.identify.captive_forces.captive_forces`).

    Parameters
    ----------
    tests : CaptiveTests
    L, T : float
        Model length and draught [m] (to convert to the MMG's ``0.5 rho L^2 d`` scale).
    mass : float, optional
        Model mass [kg] (to separate the added mass from the rigid-body mass).
    rho : float
        Water density [kg/m^3].
    x_G : float
        Centre of gravity forward of midship [m].
    I_z : float, optional
        Model yaw inertia about midship [kg m^2] (to separate the added yaw inertia).

    Returns
    -------
    dict
        Name -> value on the tables' scale (``..._table``) and on the MMG scale (``0.5 rho L d U^2``
        forces, ``0.5 rho L^2 d U^2`` moments), e.g. ``Y_v_dash``, ``N_v_dash``, ``Y_r_dash``,
        ``N_r_dash``, ``m_y_dash``, ``J_z_dash`` (added mass/inertia when ``mass`` is given).
    """
    dy, st = tests.dynamic, tests.static
    k = L / T
    out = {}

    def slope(x, y):
        A = np.vstack([x, x**3]).T
        return float(np.linalg.lstsq(A, y, rcond=None)[0][0])

    c = {n: tests.dynamic.components[n] for n in ("Y", "N")}
    col = {h: HARMONICS.index(h) for h in HARMONICS}
    sw = dy.select("pure_sway")
    if len(sw) >= 2:
        omega = 2 * np.pi * dy.freq_hz[sw]
        vdot = dy.vdot_amp[sw]
        v_amp = -vdot * dy.speed[sw] / (omega * L)
        out["Y_v_table"] = slope(v_amp, c["Y"][sw, col["out1"]])
        out["N_v_table"] = slope(v_amp, c["N"][sw, col["out1"]])
        out["m_plus_m_y_table"] = -slope(vdot, c["Y"][sw, col["in1"]])
        out["N_vdot_table"] = slope(vdot, c["N"][sw, col["in1"]])
    yw = dy.select("pure_yaw")
    if len(yw) >= 2:
        r, rdot = dy.r_amp[yw], dy.rdot_amp[yw]
        out["Y_r_minus_m_table"] = slope(r, c["Y"][yw, col["out1"]])
        out["N_r_table"] = slope(r, c["N"][yw, col["out1"]])
        out["I_plus_J_z_table"] = -slope(rdot, c["N"][yw, col["in1"]])
        out["Y_rdot_table"] = slope(rdot, c["Y"][yw, col["in1"]])
    sd = [i for i in range(len(st)) if st.kind[i] in ("static_drift", "static_rudder") and st.delta[i] == 0
          and np.isclose(st.speed[i], np.max(st.speed)) and abs(st.beta[i]) <= np.radians(12.1)]
    if len(sd) >= 3:
        v = -np.sin(st.beta[sd])
        out["Y_v_static_table"] = slope(v, st.forces["Y"][sd])
        out["N_v_static_table"] = slope(v, st.forces["N"][sd])
    # to the MMG scale: forces / (0.5 rho L d U^2) = table * L / d; moments / (0.5 rho L^2 d U^2) likewise
    for name in ("Y_v", "N_v", "N_r", "Y_v_static", "N_v_static"):
        if f"{name}_table" in out:
            out[f"{name}_dash"] = out[f"{name}_table"] * k
    if mass is not None:
        m_dash = mass / (0.5 * rho * L**2 * T)            # MMG scale
        if "m_plus_m_y_table" in out:
            out["m_dash"] = m_dash
            out["m_y_dash"] = out["m_plus_m_y_table"] * k - m_dash
            out["m_y_dash_if_inertia_subtracted"] = out["m_plus_m_y_table"] * k
        if "Y_r_minus_m_table" in out:
            out["Y_r_minus_m_x_dash"] = out["Y_r_minus_m_table"] * k + m_dash
        if "N_r_table" in out:
            out["N_r_dash"] = out["N_r_table"] * k + m_dash * x_G / L
    if I_z is not None and "I_plus_J_z_table" in out:
        out["J_z_dash"] = out["I_plus_J_z_table"] * k - I_z / (0.5 * rho * L**4 * T)
        out["J_z_dash_if_inertia_subtracted"] = out["I_plus_J_z_table"] * k
    return out
