"""A model's forces in a captive test: the prescribed motion, the force on the rig, its harmonics.

In a captive test the rig prescribes the motion ``(u, v, r)`` and its rates and measures the force
the model needs. For any symbolic ship model with states ``u, v, r`` and the generalised-force
port ``tau`` (every ship model in :mod:`casship.models` has one), the model's accelerations are
affine in ``tau``: ``a = a0(x, u, p) + B(x, u, p) tau``. The rig force that makes the model follow
the prescribed rates ``a`` is ``tau_rig = B^-1 (a - a0)``, and the force the gauges read is its
reaction ``F = -tau_rig``: the hydrodynamic force *including* the rigid-body inertia and
centripetal terms of the model, ``F = F_hydro - M_RB a - C_RB(nu)``. (That is what the HMRI tables
hold: see ``docs/data.md``, "Captive tests".) :func:`captive_forces` builds it as a CasADi Function,
so its Jacobian in the parameters is exact.

:func:`pmm_motion` writes the prescribed motion of a static or PMM test at ``n`` equally spaced
phases of one period; :func:`harmonics` projects samples onto the mean and the in-phase
(``sin k omega t``) and out-of-phase (``cos k omega t``) components; :class:`CaptivePredictor`
puts them together: the model's prediction of every measured component of a
:class:`~casship.io.captive.CaptiveTests` record, with its exact Jacobian.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

from ..errors import InputError
from ..io.captive import CHANNELS, FORCE_SCALES, HARMONICS

__all__ = ["captive_forces", "pmm_motion", "harmonics", "harmonic_matrix", "CaptivePredictor", "Observation",
           "N_PHASES"]

#: Samples per period for the harmonic projection (exact for trigonometric polynomials of degree < 32).
N_PHASES = 64


def _declared(model):
    d = model.builder().declarations()
    for name in ("u", "v", "r"):
        if name not in model.state_names:
            raise InputError(f"captive forces: model {model.name!r} has no state {name!r} (needs u, v, r)")
    if "tau" not in d.ports or d.ports["tau"].numel() != 3:
        raise InputError(f"captive forces: model {model.name!r} has no generalised-force port 'tau' of size 3")
    return d


def captive_forces(model, channels: Sequence[str] = ("X", "Y", "N")) -> ca.Function:
    """The force a captive rig measures on ``model`` at a prescribed motion, as a CasADi Function.

    Parameters
    ----------
    model : Model
        A ship model with states ``u, v, r`` and the port ``tau`` (size 3, body-axis force at the
        model's reference point, e.g. midship for the MMG models).
    channels : sequence of str
        ``X, Y, N`` (the force on the rig, rigid-body inertia included) and, for the MMG standard
        models (:func:`casship.models.mmg.mmg_standard`), ``T`` (propeller thrust) and ``RX``,
        ``RY`` (rudder force on the stock), see :func:`casship.models.mmg.mmg_force_parts`.

    Returns
    -------
    casadi.Function
        ``captive_forces(x, xdot3, u, p) -> F`` with ``x`` the model's state (``u, v, r`` set to the
        prescribed motion; the others as they are, e.g. a rudder state), ``xdot3`` the prescribed
        ``(du, dv, dr)``, ``u`` the model's inputs and ``p`` its parameters; ``F`` the channels in
        newtons (moments in N m), in the order given.

    Examples
    --------
    >>> from casship.models import kvlcc2_l7
    >>> from casship.identify.captive_forces import captive_forces
    >>> ship = kvlcc2_l7()
    >>> F = captive_forces(ship)
    >>> x = ship.states(u=1.18)
    >>> float(F(x, [0, 0, 0], ship.inputs(n=10.0), ship.params())[1])   # no drift, no rudder: no side force
    0.0
    """
    d = _declared(model)
    bad = [c for c in channels if c not in CHANNELS]
    if bad:
        raise InputError(f"captive forces: unknown channel(s) {bad}; known: {list(CHANNELS)}")
    sym = d.symbols
    x, u, p, w = model.x, model.u, model.p, model.w
    tau = d.ports["tau"]
    others = [k for k in d.ports if k != "tau"]
    rates = ca.vertcat(*[d.rates[n] for n in ("u", "v", "r")])
    # resolve the other ports and the terms fed to tau (wind, ...), keep tau's own symbol as the rig
    subs_from = [d.ports[k] for k in others]
    subs_to = [sum(d.port_terms[k], ca.SX.zeros(d.ports[k].shape)) for k in others]
    tau_rig = ca.SX.sym("tau_rig", 3)
    fed = sum(d.port_terms["tau"], ca.SX.zeros(3))
    rates = ca.substitute([rates], subs_from + [tau], subs_to + [fed + tau_rig])[0]
    rates = ca.substitute(rates, w, ca.DM.zeros(w.shape))
    B = ca.jacobian(rates, tau_rig)
    a0 = ca.substitute(rates, tau_rig, ca.DM.zeros(3))
    acc = ca.SX.sym("xdot3", 3)
    rig = ca.solve(B, acc - a0)
    out = []
    parts = None
    for c in channels:
        if c in ("X", "Y", "N"):
            out.append(-rig[("X", "Y", "N").index(c)])
            continue
        if parts is None:
            parts = _mmg_parts(model, sym)
        out.append(parts[c])
    expr = ca.vertcat(*out)
    return ca.Function("captive_forces", [x, acc, u, p], [expr], ["x", "xdot3", "u", "p"], ["F"])


def _mmg_parts(model, sym) -> dict:
    from ..models.mmg import MMG_PARAMS, SMOOTH_WIDTH, mmg_force_parts

    missing = [k for k in MMG_PARAMS if k not in sym]
    delta = sym.get("delta")
    if missing or delta is None or "n" not in sym:
        raise InputError(f"captive forces: channels T, RX, RY need an MMG standard model (delta, n and the MMG "
                         f"parameters); model {model.name!r} lacks {missing or ['delta/n']}")
    opts = dict(model.meta.get("options", {}))
    P = {k: sym[k] for k in model.param_names}
    return mmg_force_parts(P, sym["u"], sym["v"], sym["r"], delta, sym["n"],
                           SMOOTH_WIDTH if opts.get("smooth") else None, opts.get("rudder_inflow", "published"))


def _sparse(rows, cols, values, n_rows: int, n_cols: int):
    """A ``scipy.sparse`` matrix from triplets (CasADi takes it as a sparse DM)."""
    from scipy.sparse import csc_matrix

    return csc_matrix((values, (rows, cols)), shape=(n_rows, n_cols))


def pmm_motion(kind: str, U: float, *, beta: float = 0.0, omega: float | None = None, vdot_amp: float | None = None,
               r_amp: float | None = None, L: float, n: int = N_PHASES) -> dict:
    """The body-axis motion of a static or PMM test at ``n`` equally spaced phases of one period.

    The carriage runs at ``U`` [m/s]; phases ``theta = omega t = 2 pi j / n``.

    * ``static``: ``u = U cos(beta)``, ``v = -U sin(beta)``, no rotation (one sample).
    * ``pure_sway``: lateral position ``y = y_max sin(omega t)``: ``u = U``, ``v = y_max omega
      cos(omega t)``, ``r = 0``, with ``y_max = -vdot_amp U^2 / (omega^2 L)``.
    * ``pure_yaw`` and ``yaw_drift``: the midship follows the path of angle ``phi = psi_max
      sin(omega t)`` at the carriage speed along ``x`` (speed on the path ``U / cos(phi)``), the
      heading is ``beta + phi`` (the drift ``beta`` held to the path): ``u = U cos(beta) / cos(phi)``,
      ``v = -U sin(beta) / cos(phi)``, ``r = psi_max omega cos(omega t)``, with
      ``psi_max = r_amp U / (omega L)``. Pure yaw is ``beta = 0`` (no sway velocity at midship).

    Parameters
    ----------
    kind : str
        ``static``, ``pure_sway``, ``pure_yaw`` or ``yaw_drift``.
    U : float
        Carriage speed [m/s].
    beta : float
        Drift angle [rad] (``atan(-v/u)``).
    omega : float, optional
        PMM circular frequency [rad/s] (dynamic tests).
    vdot_amp, r_amp : float, optional
        Non-dimensional amplitudes: ``vdot' = vdot L / U^2`` coefficient of ``sin(omega t)``
        (pure sway), ``r' = r L / U`` coefficient of ``cos(omega t)`` (yaw tests).
    L : float
        Model length [m].
    n : int
        Phases per period.

    Returns
    -------
    dict
        ``theta, u, v, r, du, dv, dr`` arrays (SI units, ``theta`` in rad).
    """
    if kind == "static":
        one = np.ones(1)
        z = np.zeros(1)
        return {"theta": z, "u": U * np.cos(beta) * one, "v": -U * np.sin(beta) * one, "r": z, "du": z, "dv": z,
                "dr": z}
    if omega is None or not omega > 0:
        raise InputError(f"pmm_motion: {kind} needs a positive omega, got {omega}")
    th = 2 * np.pi * np.arange(n) / n
    s, c = np.sin(th), np.cos(th)
    if kind == "pure_sway":
        if vdot_amp is None:
            raise InputError("pmm_motion: pure_sway needs vdot_amp")
        y_max = -vdot_amp * U**2 / (omega**2 * L)
        z = np.zeros(n)
        return {"theta": th, "u": U + z, "v": y_max * omega * c, "r": z, "du": z, "dv": -y_max * omega**2 * s,
                "dr": z}
    if kind in ("pure_yaw", "yaw_drift"):
        if r_amp is None:
            raise InputError(f"pmm_motion: {kind} needs r_amp")
        psi_max = r_amp * U / (omega * L)
        phi = psi_max * s
        dphi = psi_max * omega * c
        Up = U / np.cos(phi)
        dUp = U * np.sin(phi) / np.cos(phi) ** 2 * dphi
        return {"theta": th, "u": Up * np.cos(beta), "v": -Up * np.sin(beta), "r": dphi,
                "du": dUp * np.cos(beta), "dv": -dUp * np.sin(beta), "dr": -psi_max * omega**2 * s}
    raise InputError(f"pmm_motion: kind must be static, pure_sway, pure_yaw or yaw_drift, got {kind!r}")


def harmonic_matrix(n: int = N_PHASES, n_harm: int = 3) -> np.ndarray:
    """The linear map from ``n`` equally spaced samples of one period to the harmonic components.

    Rows: mean, then ``in_k`` (``sin k theta``) and ``out_k`` (``cos k theta``) for ``k = 1..n_harm``
    (the order of :data:`casship.io.captive.HARMONICS`). Exact for trigonometric polynomials of
    degree below ``n / 2``.

    Parameters
    ----------
    n : int
        Samples per period.
    n_harm : int
        Highest harmonic.

    Returns
    -------
    (1 + 2 n_harm, n) array
    """
    if n <= 2 * n_harm:
        raise InputError(f"harmonic_matrix: {n} samples cannot resolve {n_harm} harmonics (need more than {2 * n_harm})")
    th = 2 * np.pi * np.arange(n) / n
    rows = [np.full(n, 1.0 / n)]
    for k in range(1, n_harm + 1):
        rows += [2.0 / n * np.sin(k * th), 2.0 / n * np.cos(k * th)]
    return np.array(rows)


def harmonics(samples, n_harm: int = 3) -> np.ndarray:
    """Mean and in-/out-of-phase components of samples over one period (see :func:`harmonic_matrix`).

    Parameters
    ----------
    samples : (n,) or (n, m) array
        Values at ``theta = 2 pi j / n``, ``j = 0..n-1``.
    n_harm : int
        Highest harmonic.

    Returns
    -------
    (1 + 2 n_harm,) or (1 + 2 n_harm, m) array
        ``mean, in1, out1, in2, out2, ...``.

    Examples
    --------
    >>> import numpy as np
    >>> th = 2 * np.pi * np.arange(16) / 16
    >>> np.round(harmonics(1 + 2 * np.sin(th) - 3 * np.cos(2 * th), 2), 12)
    array([ 1.,  2.,  0.,  0., -3.])
    """
    samples = np.asarray(samples, dtype=float)
    return harmonic_matrix(samples.shape[0], n_harm) @ samples


@dataclass(frozen=True)
class Observation:
    """One measured scalar of a captive record.

    Parameters
    ----------
    test : str
        ``"static"`` or ``"dynamic"``.
    index : int
        Point or test index in the record.
    channel : str
        Force channel (``X, Y, N, RX, RY, T``).
    component : str
        ``"value"`` for a static point, else one of :data:`~casship.io.captive.HARMONICS`.
    value : float
        The measured value.
    kind : str
        The test kind (``static_drift``, ``pure_yaw``...).
    """

    test: str          # "static" or "dynamic"
    index: int         # point / test index in the record
    channel: str       # X, Y, N, RX, RY, T
    component: str     # "value" for a static point, else one of HARMONICS
    value: float
    kind: str          # the test kind (static_drift, pure_yaw, ...)


class CaptivePredictor:
    """The model's prediction of a captive record's measured components, with its exact Jacobian.

    Parameters
    ----------
    model : Model
        A ship model as for :func:`captive_forces` (its parameters ``L_pp`` and ``rho`` give the
        non-dimensionalisation, see ``length`` and ``density``).
    tests : CaptiveTests
        The record (:func:`casship.io.read_captive`).
    channels : sequence of str
        Channels to predict.
    components : sequence of str
        Dynamic-test components to use (default: all but the means; see ``docs/identification.md``).
    static_kinds, dynamic_kinds : sequence of str, optional
        Test kinds to use (default: all).
    length, density : str
        Names of the model's length and water-density parameters.
    rudder, propeller : str
        Names of the model's rudder (input or state) and propeller-rate input.
    n_phases : int
        Samples per PMM period.
    params : array_like or mapping, optional
        Parameter values whose length sets the PMM motion's amplitudes (default: the model's).

    Attributes
    ----------
    observations : list of Observation
        The measured scalars used (NaN ones left out), in the order of :meth:`predict`.
    """

    def __init__(self, model, tests, channels: Sequence[str] = ("X", "Y", "N"),
                 components: Sequence[str] = HARMONICS[1:], *, static_kinds: Sequence[str] | None = None,
                 dynamic_kinds: Sequence[str] | None = None, length: str = "L_pp", density: str = "rho",
                 rudder: str = "delta", propeller: str = "n", n_phases: int = N_PHASES, params=None):
        self.model, self.tests = model, tests
        base = model.params(params) if params is not None else model.params()
        self.length = float(base[model.index(length, "param")])
        self.channels = tuple(channels)
        bad = [c for c in components if c not in HARMONICS]
        if bad:
            raise InputError(f"captive predictor: unknown component(s) {bad}; known: {list(HARMONICS)}")
        self.components = tuple(components)
        self._F = captive_forces(model, self.channels)
        for name in (length, density):
            model.index(name, "param")
        self._iL, self._irho = model.index(length, "param"), model.index(density, "param")
        st, dy = tests.static, tests.dynamic
        sk = tuple(static_kinds) if static_kinds is not None else None
        dk = tuple(dynamic_kinds) if dynamic_kinds is not None else None
        # every sample the model is evaluated at (a static point, or one phase of a PMM period), and
        # every observation as a weighted sum of one channel over samples, divided by 1/2 rho U^2 L^k
        X, A, U = [], [], []
        obs: list[Observation] = []
        rows, cols, weights, chan, speeds, powers = [], [], [], [], [], []

        def observe(observation, channel, samples, w, speed):
            rows.extend([len(obs)] * len(samples))
            cols.extend(samples)
            weights.extend(np.broadcast_to(w, (len(samples),)))
            chan.append(self.channels.index(channel))
            speeds.append(speed)
            powers.append(FORCE_SCALES[channel])
            obs.append(observation)

        s_idx = [i for i in range(len(st)) if sk is None or st.kind[i] in sk]
        for i in s_idx:                               # static points: one sample each
            m = pmm_motion("static", st.speed[i], beta=st.beta[i], L=1.0)
            X.append(self._state(m, 0, st.delta[i], rudder))
            A.append([0.0, 0.0, 0.0])
            U.append(self._inputs(st.delta[i], st.rps[i], rudder, propeller))
        for c in self.channels:                       # observations by channel, then point
            for k, i in enumerate(s_idx):
                meas = st.forces[c][i]
                if np.isfinite(meas):
                    observe(Observation("static", i, c, "value", float(meas), st.kind[i]), c, [k], 1.0, st.speed[i])
        Hm = harmonic_matrix(n_phases, 3)
        for i in (i for i in range(len(dy)) if dk is None or dy.kind[i] in dk):
            m = self.motion(i, L_value=None, n=n_phases)
            first = len(X)
            for k in range(n_phases):
                X.append(self._state(m, k, 0.0, rudder))
                A.append([m["du"][k], m["dv"][k], m["dr"][k]])
                U.append(self._inputs(0.0, dy.rps[i], rudder, propeller))
            samples = list(range(first, first + n_phases))
            for c in self.channels:
                for h in self.components:
                    meas = dy.components[c][i, HARMONICS.index(h)]
                    if np.isfinite(meas):
                        observe(Observation("dynamic", i, c, h, float(meas), dy.kind[i]), c, samples,
                                Hm[HARMONICS.index(h)], dy.speed[i])
        if not obs:
            raise InputError("captive predictor: no measured component selected")
        self.observations = obs
        self.measured = np.array([o.value for o in obs])
        self._samples = (np.array(X).T, np.array(A).T, np.array(U).T)
        n_obs, n_s = len(obs), len(X)
        chan_of_row = np.array(chan)[np.array(rows)]
        # one sparse weight matrix per channel: observation rows, sample columns
        self._weights = [ca.DM(_sparse(np.array(rows)[chan_of_row == j], np.array(cols)[chan_of_row == j],
                                       np.array(weights)[chan_of_row == j], n_obs, n_s))
                         for j in range(len(self.channels))]
        self._half_U2 = 0.5 * np.array(speeds) ** 2
        self._powers = np.array(powers, dtype=float)
        p = ca.MX.sym("p", model.np)
        self._value = ca.Function("captive_value", [p], [self._scaled(p, self._F)[0]], ["p"], ["y"])
        self._function = None                    # value and Jacobian: built at the first :meth:`jacobian`

    def _scaled(self, p, point, jac: bool = False):
        """``y`` (and ``dy/dp``) of every observation from ``point`` mapped over the samples."""
        x, xdot3, u = self._samples
        n_s = x.shape[1]
        out = point.map(n_s)(x=x, xdot3=xdot3, u=u, p=ca.repmat(p, 1, n_s))
        F = out["F"]
        raw = sum(ca.mtimes(W, F[j, :].T) for j, W in enumerate(self._weights))
        L, rho = p[self._iL], p[self._irho]
        scale = rho * self._half_U2 * L ** self._powers
        y = raw / scale
        if not jac:
            return y, None
        npar = p.numel()
        raw_J = sum(ca.mtimes(W, ca.reshape(out["dF_dp"][j, :], npar, n_s).T) for j, W in enumerate(self._weights))
        # d(raw / scale)/dp: the scale depends on rho and L only
        J = raw_J / ca.repmat(scale, 1, npar)
        e_rho, e_L = np.zeros((1, npar)), np.zeros((1, npar))
        e_rho[0, self._irho], e_L[0, self._iL] = 1.0, 1.0
        J = J - ca.mtimes(y / rho, ca.DM(e_rho)) - ca.mtimes(self._powers * y / L, ca.DM(e_L))
        return y, J

    @property
    def function(self) -> ca.Function:
        """``p -> (y, J)``: the predictions and their exact Jacobian in the parameters.

        Built once, at first use: the force Function and its Jacobian in the parameters at one
        sample (scalar operations), mapped over every sample and projected onto the observations by
        sparse weight matrices, so the graph stays a handful of matrix operations (building it takes
        milliseconds; differentiating the expanded prediction as a whole took seconds).
        """
        if self._function is None:
            names = list(self._F.name_in())                      # x, xdot3, u, p
            sym = {n: ca.SX.sym(n, self._F.sparsity_in(n)) for n in names}
            F = self._F(**sym)["F"]
            point = ca.Function("captive_point", [sym[n] for n in names], [F, ca.jacobian(F, sym["p"])], names,
                                ["F", "dF_dp"])
            p = ca.MX.sym("p", self.model.np)
            y, J = self._scaled(p, point, jac=True)
            self._function = ca.Function("captive_predict", [p], [y, J], ["p"], ["y", "J"])
        return self._function

    # the model length is only known from p at evaluation; the motion needs it numerically
    def motion(self, i: int, L_value: float | None = None, n: int = N_PHASES) -> dict:
        """The prescribed motion of dynamic test ``i`` (see :func:`pmm_motion`).

        Parameters
        ----------
        i : int
            Dynamic test index.
        L_value : float, optional
            Model length [m] (default: :attr:`length`).
        n : int
            Phases per period.

        Returns
        -------
        dict
        """
        dy = self.tests.dynamic
        L = L_value if L_value is not None else self.length
        kind = dy.kind[i]
        if kind == "pure_sway":
            omega = 2 * np.pi * dy.freq_hz[i]
            return pmm_motion(kind, dy.speed[i], omega=omega, vdot_amp=dy.vdot_amp[i], L=L, n=n)
        # the yaw tables give r' and rdot' to 3-4 digits but the frequency to 2: take omega from their ratio
        omega = -dy.rdot_amp[i] * dy.speed[i] / (dy.r_amp[i] * L)
        return pmm_motion(kind, dy.speed[i], beta=dy.beta[i], omega=omega, r_amp=dy.r_amp[i], L=L, n=n)

    def _state(self, m, k, delta, rudder):
        vals = {"u": m["u"][k], "v": m["v"][k], "r": m["r"][k]}
        if rudder in self.model.state_names:
            vals[rudder] = delta
        return self.model.states(**vals)

    def _inputs(self, delta, rps, rudder, propeller):
        vals = {propeller: rps}
        if rudder in self.model.input_names:
            vals[rudder] = delta
        return self.model.inputs(**vals)

    def predict(self, p) -> np.ndarray:
        """The predicted components (ordered like :attr:`observations`).

        Parameters
        ----------
        p : array_like
            The model's parameter vector.

        Returns
        -------
        array
        """
        return np.asarray(self._value(p)).ravel()

    def jacobian(self, p) -> tuple[np.ndarray, np.ndarray]:
        """``(prediction, d prediction / d p)`` (exact).

        Parameters
        ----------
        p : array_like
            The model's parameter vector.

        Returns
        -------
        (array, 2-d array)
        """
        y, J = self.function(p)
        return np.asarray(y).ravel(), np.asarray(J)
