"""The closed loop as one compiled system: ship + sensors + estimator + autopilot + steering gear.

:class:`ClosedLoop` composes, on CasADi expressions, one sample of

1. the sensors on the true ship state (GNSS positions, compass, rate gyro; noise from per-sample
   standard-normal draws, availability from per-sample masks; optional first-order wave yaw),
2. the estimator's step Function (the SOG/COG EKF in course mode, the heading observer in heading
   mode), addressed by slot names,
3. optional guidance (LOS/ILOS through waypoints) giving the course command,
4. the control law (:class:`~casship.autopilot.law.Autopilot`), and
5. the steering gear (:class:`~casship.autopilot.law.Actuator`: saturation, servo, rate limit)
   driving one RK4 step of the nonlinear ship,

into one ``casadi.Function`` :attr:`ClosedLoop.step` with named slots, run over a whole record by
``mapaccum`` (:meth:`ClosedLoop.run`) and exported to C like the estimator steps
(:meth:`ClosedLoop.export_c`). :meth:`ClosedLoop.run_stepwise` runs the same parts one by one
from Python (the estimator through its online runner): the reference the compiled loop is tested
against.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..angles import wrap
from ..data import Dataset, check_rows
from ..errors import DivergenceError, InputError
from .components import DRAWS, MASKS, Layout, Sensors
from .estimation import WaveYaw
from .law import Actuator, Autopilot
from .loop_variants import READINGS, feedback_source
from .plants import SteeringPlant

__all__ = ["ClosedLoop"]

#: What a diverged run says about why.
_WHY = " (the loop period too long for the ship, or a load far beyond its range: check dt, wind and current)"


class ClosedLoop:
    """Ship, sensors, estimator, autopilot and steering gear composed into one CasADi step.

    Parameters
    ----------
    plant : SteeringPlant
        The nonlinear ship (truth) with its other inputs (propeller, wind, current) bound.
    autopilot : Autopilot
        The control law (reference model, gains, command limit).
    actuator : Actuator
        Steering gear (limits, servo time constant, rate limit).
    dt : float
        Loop period [s] (sensors, estimator, autopilot and ship step run at this rate).
    mode : {"course", "heading"}
        Controlled angle: course over ground or heading.
    rate : {"estimator", "gyro"}
        Rate fed to the autopilot: the estimator's (course rate or yaw rate) or the rate gyro's.
    estimator : LoopEstimator, TrueState, RawMeasurement, "truth" or "raw"
        The feedback source (:class:`~casship.autopilot.loop_variants.LoopFeedback`): an estimator;
        :class:`~casship.autopilot.loop_variants.TrueState` (shorthand ``"truth"``) feeds the true
        angle and rate (no sensors); :class:`~casship.autopilot.loop_variants.RawMeasurement`
        (shorthand ``"raw"``, heading mode) feeds the last compass reading and the gyro.
    sensors : Sensors
    wave : WaveYaw, optional
        First-order wave yaw added to the measured heading and yaw rate.
    guidance : object, optional
        Path guidance (:class:`casship.autopilot.guidance.LOSGuidance`) giving the course command
        from the position (the estimator's in course mode, the last GNSS fix in heading mode, the
        true one with ``estimator="truth"``).

    Attributes
    ----------
    estimator : LoopFeedback
        The feedback source (a shorthand string resolved).
    reading : CourseReading or HeadingReading
        How the controlled angle of ``mode`` is read (:data:`~casship.autopilot.loop_variants.READINGS`).

    Notes
    -----
    The law is any object with ``MEMORY``, ``memory0(chi0)``, ``symbolic_step(memory, ref, chi, r,
    dt, speed, steer=, bias=)`` and ``function`` (:class:`~casship.autopilot.law.Autopilot`, its
    gain schedule, :class:`~casship.autopilot.slot.LinearController`); a law whose step is an
    MX Function with a solver call (``mx_law = True``: the MPC of
    :meth:`~casship.autopilot.mpc.MPCAutopilot.law`) is composed at the Function level: the
    sensing part, the law's call and the acting part form the loop's step.
    """

    def __init__(self, plant: SteeringPlant, autopilot: Autopilot, actuator: Actuator, *, dt: float,
                 mode: str = "course", rate: str = "gyro", estimator="truth", sensors: Sensors | None = None,
                 wave: WaveYaw | None = None, guidance=None):
        if mode not in READINGS:
            raise InputError(f"mode must be 'course' or 'heading', got {mode!r}")
        if rate not in ("estimator", "gyro"):
            raise InputError(f"rate must be 'estimator' or 'gyro', got {rate!r}")
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be positive, got {dt}")
        estimator = feedback_source(estimator)
        estimator.check_mode(mode, guided=guidance is not None)
        self.plant, self.autopilot, self.actuator = plant, autopilot, actuator
        self.dt, self.mode, self.rate, self.reading = float(dt), mode, rate, READINGS[mode]
        self.estimator, self.sensors, self.wave, self.guidance = estimator, sensors or Sensors(), wave, guidance
        m = plant.model
        blocks = [("x", m.nx), ("steer", 1), ("steer_prev", 1), *estimator.blocks(),
                  ("autopilot", len(autopilot.MEMORY)), ("compass_hold", 1), ("gnss_hold", 2), ("chi_prev", 1)]
        if wave is not None:
            blocks.append(("wave", 2))
        if guidance is not None:
            blocks.append(("guidance", guidance.memory_size))
        self.layout = Layout(blocks)
        self._step = None
        self._log_names = None

    # -- composition ----------------------------------------------------------------------------
    @property
    def signals(self) -> tuple[str, ...]:
        """Names of the logged signals (the rows of the step's ``log`` output)."""
        if self._log_names is None:
            self._build()
        return self._log_names

    @property
    def step(self) -> ca.Function:
        """``loop(s, ref, draws, mask, dt_est, p) -> (s_next, log)``: one sample of the closed loop.

        ``s`` is the loop state (:meth:`state0`), ``ref`` the course command [rad], ``draws`` the
        standard-normal draws named in :data:`DRAWS`, ``mask`` the sensor availability (GNSS,
        compass), ``dt_est`` the estimator's time since its previous sample (0 on the first), ``p``
        the ship's parameters; ``log`` holds :attr:`signals`.
        """
        if self._step is None:
            self._build()
        return self._step

    def _measurements(self, parts, draws, mask, x, motion, wave_out):
        m, pl, sen = self.plant.model, self.plant, self.sensors
        psi_w, r_w = wave_out
        north, east = x[m.index(pl.north)], x[m.index(pl.east)]
        psi, r = x[m.index(pl.heading)], x[m.index(pl.yaw_rate)]
        gnss = ca.vertcat(north + sen.gnss_std * draws[0], east + sen.gnss_std * draws[1])
        compass = psi + psi_w + sen.compass_std * draws[2]
        compass = ca.atan2(ca.sin(compass), ca.cos(compass))
        gyro = r + r_w + sen.gyro_std * draws[3]
        return {"gnss": gnss, "compass": compass, "gyro": gyro, "north": north, "east": east, "psi": psi, "r": r}

    def _build(self):
        m = self.plant.model
        s = ca.SX.sym("s", self.layout.size)
        ref, draws, mask = ca.SX.sym("ref"), ca.SX.sym("draws", len(DRAWS)), ca.SX.sym("mask", len(MASKS))
        dt_est, p = ca.SX.sym("dt_est"), ca.SX.sym("p", m.np)
        parts = self.layout.split(s)
        x, steer = parts["x"], parts["steer"]
        motion = self.plant.symbolic_motion(x, steer, p)
        if self.wave is not None:
            wave_next, psi_w, r_w = self.wave.symbolic_step(parts["wave"], draws[4], self.dt)
        else:
            psi_w = r_w = ca.SX(0)
        meas = self._measurements(parts, draws, mask, x, motion, (psi_w, r_w))
        est = self.estimator.symbolic(self, parts, meas, mask, dt_est, motion, parts["steer_prev"])
        log = {}
        command = ref
        nxt = {}
        if self.guidance is not None:
            g = self.guidance.symbolic_step(parts["guidance"], est["north"], est["east"], est["U"], est["angle"],
                                            self.dt)
            command = g["chi_ref"]
            nxt["guidance"] = g["memory"]
            log.update({k: g[k] for k in self.guidance.LOG})
        composed = getattr(self.autopilot, "mx_law", False)
        n_mem = len(self.autopilot.MEMORY)
        law_in = ca.vertcat(parts["autopilot"], command, est["angle"], est["rate"], est["U"], steer, est["bias"])
        if composed:          # the law's outputs enter as symbols; its MX call is composed below
            law_out = ca.SX.sym("law_out", n_mem + 5)
            law = dict(zip(("steer", "chi_d", "r_d", "a_d", "e"), ca.vertsplit(law_out[n_mem:])))
            law["memory"] = law_out[:n_mem]
        else:
            law = self.autopilot.symbolic_step(parts["autopilot"], command, est["angle"], est["rate"], self.dt,
                                               est["U"], steer=steer, bias=est["bias"])
        act = self.actuator.symbolic_step(steer, law["steer"], self.dt)
        steer_avg = 0.5 * (steer + act["steer"])          # the servo ramps over the sample
        x_next = self.plant.symbolic_step(x, steer_avg, p, self.dt)
        nxt.update({"x": x_next, "steer": act["steer"], "steer_prev": steer_avg, "autopilot": law["memory"],
                    "compass_hold": est["compass_hold"], "gnss_hold": est["gnss_hold"], "chi_prev": motion[0]})
        nxt.update({f"est_{n}": v for n, v in est["memory"].items()})
        if self.wave is not None:
            nxt["wave"] = wave_next
        nan = ca.SX(np.nan)
        log.update({
            "north": meas["north"], "east": meas["east"], "psi": meas["psi"], "r": meas["r"], "U": motion[1],
            "chi": motion[0], "chi_hat": est["angle"], "omega_hat": est["rate"], "U_hat": est["U"],
            "chi_std": est["angle_std"], "steer": steer, "steer_cmd": law["steer"], "chi_d": law["chi_d"],
            "r_d": law["r_d"], "a_d": law["a_d"], "ref": command, "e": law["e"], "rate_limited": act["rate_limited"],
            "gnss_north": ca.if_else(mask[0] > 0, meas["gnss"][0], nan),
            "gnss_east": ca.if_else(mask[0] > 0, meas["gnss"][1], nan),
            "compass": ca.if_else(mask[1] > 0, meas["compass"], nan), "gyro": meas["gyro"], "psi_wave": psi_w,
        })
        self._log_names = tuple(log)
        names_in, names_out = ["s", "ref", "draws", "mask", "dt_est", "p"], ["s_next", "log"]
        outputs = [self.layout.join(nxt), ca.vertcat(*log.values())]
        if not composed:
            self._step = ca.Function("closed_loop", [s, ref, draws, mask, dt_est, p], outputs, names_in, names_out)
            return
        sensing = ca.Function("loop_sensing", [s, ref, draws, mask, dt_est, p], [law_in])
        acting = ca.Function("loop_acting", [s, ref, draws, mask, dt_est, p, law_out], outputs)
        args = [ca.MX.sym(n, *sx.shape) for n, sx in zip(names_in, (s, ref, draws, mask, dt_est, p))]
        li = ca.vertsplit(sensing(*args), [0, n_mem, n_mem + 1, n_mem + 2, n_mem + 3, n_mem + 4, n_mem + 5,
                                           n_mem + 6])
        lo = self.autopilot.function(li[0], li[1], li[2], li[3], self.dt, li[4], li[5], li[6])
        self._step = ca.Function("closed_loop", args, acting(*args, ca.vertcat(*lo)), names_in, names_out)

    # -- running -----------------------------------------------------------------------------------
    def state0(self, x0=None, chi0: float | None = None) -> np.ndarray:
        """Initial loop state: ship at ``x0`` (the plant's trim point by default), steering at rest,
        estimator at its prior, reference model at the initial course.

        Parameters
        ----------
        x0 : array, optional
            Ship state.
        chi0 : float, optional
            Initial course (or heading) of the reference model (default: the ship's).

        Returns
        -------
        ndarray
            The flat loop state (blocks in :attr:`layout`).
        """
        pl, m = self.plant, self.plant.model
        x0 = np.asarray(x0 if x0 is not None else (pl.x0 if pl.x0 is not None else m.states()), float)
        if chi0 is None:
            chi0 = self.initial_angle(x0)
        parts = {"x": x0, "steer": 0.0, "steer_prev": 0.0, "autopilot": self.autopilot.memory0(chi0),
                 "compass_hold": x0[m.index(pl.heading)], "gnss_hold": x0[[m.index(pl.north), m.index(pl.east)]],
                 "chi_prev": chi0}
        parts.update(self.estimator.memory0(lambda: self._prior(x0)))
        if self.wave is not None:
            parts["wave"] = np.zeros(2)
        if self.guidance is not None:
            parts["guidance"] = self.guidance.memory0()
        return self.layout.pack(parts)

    def _prior(self, x0):
        """The estimator's prior at the start state ``x0``."""
        pl, m = self.plant, self.plant.model
        return self.estimator.prior_at(x0[m.index(pl.north)], x0[m.index(pl.east)], x0[m.index(pl.heading)],
                                       x0[m.index(pl.yaw_rate)], self._course_over_ground(x0))

    def _course_over_ground(self, x0) -> float:
        pl = self.plant
        chi = ca.Function("chi0", [], [pl.symbolic_motion(ca.DM(x0), 0.0, ca.DM(pl.pvec))[0]])
        return float(chi()["o0"])

    def initial_angle(self, x0) -> float:
        """Course over ground (course mode) or heading at ``x0``.

        Parameters
        ----------
        x0 : array
            Ship state.
        """
        pl, m = self.plant, self.plant.model
        return self.reading.start_angle(x0[m.index(pl.heading)], lambda: self._course_over_ground(x0))

    def schedule(self, n: int) -> np.ndarray:
        """Sensor availability masks ``(2, n)``: GNSS and compass readings at their rates.

        Parameters
        ----------
        n : int
            Samples.
        """
        every = lambda rate: max(1, int(round(1.0 / (rate * self.dt))))  # noqa: E731
        k = np.arange(n)
        return np.vstack([(k % every(self.sensors.gnss_rate)) == 0,
                          (k % every(self.sensors.compass_rate)) == 0]).astype(float)

    def draws(self, n: int, seed) -> np.ndarray:
        """Standard-normal draws ``(len(DRAWS), n)`` from ``seed`` (the same for both runners).

        Parameters
        ----------
        n : int
            Samples.
        seed : int or Generator
        """
        return np.random.default_rng(seed).standard_normal((len(DRAWS), n))

    def _inputs(self, command, t_end, seed):
        n = check_rows(round(t_end / self.dt) + 1, f"closed loop: {t_end:g} s at steps of {self.dt:g} s")
        t = np.arange(n) * self.dt
        if callable(command):
            refs = np.array([float(command(tk)) for tk in t])
        else:
            refs = np.broadcast_to(np.asarray(command, float), t.shape).copy()
        if not np.all(np.isfinite(refs)):
            raise InputError("the course command must be finite")
        dt_est = np.full(n, self.dt)
        dt_est[0] = 0.0
        return t, refs, self.draws(n, seed), self.schedule(n), dt_est

    def run(self, command, t_end: float, *, seed=0, x0=None, chunk: int = 2048) -> Dataset:
        """Run the compiled loop (``mapaccum`` of :attr:`step`) for ``t_end`` seconds.

        Parameters
        ----------
        command : callable or array
            Course command [rad]: a function of time, or values on the loop grid.
        t_end : float
            Duration [s].
        seed : int or Generator
            Sensor-noise draws.
        x0 : array, optional
            Ship start state (default: the plant's trim point).
        chunk : int
            Samples per ``mapaccum`` piece.

        Returns
        -------
        Dataset
            The logged :attr:`signals` (``meta`` holds the estimator prior).
        """
        t, refs, draws, masks, dt_est = self._inputs(command, t_end, seed)
        s = self.state0(x0)
        p = self.plant.pvec
        logs, start, n = [], 0, t.size
        folds = {}
        while start < n:
            size = min(chunk, n - start)
            if size not in folds:
                folds[size] = self.step.mapaccum(size)
            sl = slice(start, start + size)
            out = folds[size].call({"s": s, "ref": refs[None, sl], "draws": draws[:, sl], "mask": masks[:, sl],
                                    "dt_est": dt_est[None, sl], "p": p})
            S = np.asarray(out["s_next"])
            logs.append(np.asarray(out["log"]))
            s = S[:, -1]
            if not np.all(np.isfinite(s)):
                bad = start + int(np.argmax(~np.all(np.isfinite(S), axis=0)))
                raise DivergenceError(f"closed loop of {self.plant.model.name!r} diverged at t = {t[bad]:g} s{_WHY}")
            start += size
        return self._dataset(t, np.hstack(logs), x0)

    def run_stepwise(self, command, t_end: float, *, seed=0, x0=None) -> Dataset:
        """The same run, one part at a time from Python: the reference for :meth:`run`.

        Sensors are evaluated in numpy, the estimator runs through its online runner
        (``est.online(prior).update(y, dt, u_prev=...)``), the law, the steering gear and the ship
        through their own CasADi Functions (the law through its ``function``, an MPC's QP included).
        here instead of the law.

        Parameters
        ----------
        command : callable or array
        t_end : float
        seed : int or Generator
        x0 : array, optional
            As :meth:`run`.

        Returns
        -------
        Dataset
        """
        t, refs, draws, masks, dt_est = self._inputs(command, t_end, seed)
        pl, m, sen = self.plant, self.plant.model, self.sensors
        s0 = self.layout.split(self.state0(x0))
        x, steer, steer_prev = s0["x"].copy(), 0.0, 0.0
        law_mem, hold, chi_prev = s0["autopilot"].copy(), float(s0["compass_hold"][0]), float(s0["chi_prev"][0])
        fix = s0["gnss_hold"].copy()
        wave_x = np.zeros(2)
        plant_f = pl.step_function()
        law_f = self.autopilot.function
        st, cmd, h = ca.SX.sym("steer"), ca.SX.sym("command"), ca.SX.sym("dt")
        a = self.actuator.symbolic_step(st, cmd, h)
        act_f = ca.Function("actuator", [st, cmd, h], [a["steer"], a["rate_limited"]], ["steer", "command", "dt"],
                            ["steer_next", "rate_limited"])
        x_start = np.asarray(x0 if x0 is not None else (pl.x0 if pl.x0 is not None else m.states()), float)
        feed = self.estimator.stepwise(self, lambda: self._prior(x_start))
        guid_mem = self.guidance.memory0() if self.guidance is not None else None
        guid_f = self.guidance.function(self.dt) if self.guidance is not None else None
        if self.wave is not None:
            Ad, Bd = self.wave.discrete(self.dt)
        rows = []
        ix, iy, ipsi, ir = (m.index(k) for k in (pl.north, pl.east, pl.heading, pl.yaw_rate))
        for k in range(t.size):
            mot = plant_f.call({"x": x, "steer": steer, "p": pl.pvec, "dt": self.dt})
            chi, U = float(mot["chi"]), float(mot["U"])
            psi_w = r_w = 0.0
            if self.wave is not None:
                psi_w, r_w = wave_x[0], wave_x[1]
                wave_x = Ad @ wave_x + Bd[:, 0] * draws[4, k]
            gn, ge = x[ix] + sen.gnss_std * draws[0, k], x[iy] + sen.gnss_std * draws[1, k]
            compass = float(wrap(x[ipsi] + psi_w + sen.compass_std * draws[2, k]))
            gyro = x[ir] + r_w + sen.gyro_std * draws[3, k]
            if masks[0, k]:
                fix = np.array([gn, ge])
            fed = feed({"gnss": (gn, ge), "compass": compass, "gyro": gyro, "north": x[ix], "east": x[iy],
                        "psi": x[ipsi], "r": x[ir], "mask": masks[:, k], "dt_est": dt_est[k], "fix": fix, "chi": chi,
                        "chi_prev": chi_prev, "U": U, "steer_prev": steer_prev, "compass_hold": hold})
            angle, rate, north, east, U_hat = fed["angle"], fed["rate"], fed["north"], fed["east"], fed["U"]
            std, bias, hold = fed["angle_std"], fed["bias"], fed["compass_hold"]
            log = {}
            command = refs[k]
            if guid_f is not None:
                g = guid_f.call({"memory": guid_mem, "north": north, "east": east, "U": U_hat, "angle": angle})
                guid_mem = np.asarray(g["memory_next"]).ravel()
                command = float(g["chi_ref"])
                log.update({key: float(g[key]) for key in self.guidance.LOG})
            lo = law_f.call({"memory": law_mem, "ref": command, "chi": angle, "r": rate, "dt": self.dt,
                             "speed": U_hat, "steering": steer, "bias": bias})
            law_mem = np.asarray(lo["memory_next"]).ravel()
            ao = act_f.call({"steer": steer, "command": float(lo["steer"]), "dt": self.dt})
            steer_next = float(ao["steer_next"])
            steer_avg = 0.5 * (steer + steer_next)
            log.update({"north": x[ix], "east": x[iy], "psi": x[ipsi], "r": x[ir], "U": U, "chi": chi,
                        "chi_hat": angle, "omega_hat": rate, "U_hat": U_hat, "chi_std": std, "steer": steer,
                        "steer_cmd": float(lo["steer"]), "chi_d": float(lo["chi_d"]), "r_d": float(lo["r_d"]),
                        "a_d": float(lo.get("a_d", np.nan)),
                        "ref": command, "e": float(lo["e"]), "rate_limited": float(ao["rate_limited"]),
                        "gnss_north": gn if masks[0, k] else np.nan, "gnss_east": ge if masks[0, k] else np.nan,
                        "compass": compass if masks[1, k] else np.nan, "gyro": gyro, "psi_wave": psi_w})
            rows.append([log[name] for name in self.signals])
            x = np.asarray(plant_f.call({"x": x, "steer": steer_avg, "p": pl.pvec, "dt": self.dt})["x_next"]).ravel()
            steer, steer_prev, chi_prev = steer_next, steer_avg, chi
            if not np.all(np.isfinite(x)):
                raise DivergenceError(f"closed loop of {m.name!r} diverged at t = {t[k]:g} s{_WHY}")
        return self._dataset(t, np.array(rows).T, x_start)

    def _dataset(self, t, log, x0) -> Dataset:
        meta = {"mode": self.mode, "model": self.plant.model.name, "dt": self.dt, "rate": self.rate}
        pl = self.plant
        x0 = np.asarray(x0 if x0 is not None else (pl.x0 if pl.x0 is not None else pl.model.states()), float)
        meta.update(self.estimator.meta(lambda: self._prior(x0)))
        cols = dict(zip(self.signals, log))
        cols["omega_chi"] = np.gradient(np.unwrap(cols["chi"]), t)      # true course rate
        return Dataset(t, cols, meta=meta)

    # -- code generation ----------------------------------------------------------------------------
    def export_c(self, directory, name: str = "closed_loop_step"):
        """Write the loop step as C (:func:`casship.runtime.generate_c`).

        Parameters
        ----------
        directory : path
        name : str
            C function name.

        Returns
        -------
        CFiles
        """
        from ..runtime import generate_c

        title = (f"{name}: closed loop of '{self.plant.model.name}' ({self.mode} autopilot, dt = {self.dt:g} s); "
                 f"log rows: {', '.join(self.signals)}")
        return generate_c(self.step, directory, name, title=title)
