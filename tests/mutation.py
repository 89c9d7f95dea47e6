"""Mutation check: plant small, realistic bugs one at a time and see whether the tests notice.

Each mutant in :data:`MUTANTS` names a file, an exact piece of its text, the replacement and the
tests that should fail. For each one the script writes the mutated file, runs those tests (pytest
stops at the first failure), and restores the file, always (also on Ctrl-C or a terminating
signal). A mutant is *killed* when a test fails, *survives* when all pass; a survivor is either a
gap in the tests or an equivalent mutant (a change that cannot alter any result), which the table
then says with the reason (``equivalent=``).

This file is not collected by pytest and is not part of the default test run. Run it from the
repository root::

    python tests/mutation.py                    # every mutant (a while: about half a minute each)
    python tests/mutation.py -k likelihood      # the mutants whose name or file contains a word
    python tests/mutation.py -k IMO,HAC         # ... any of several words
    python tests/mutation.py --list             # the table of mutants, nothing run
    python tests/mutation.py --out mutation.md  # also write the result table (Markdown)
    python tests/mutation.py -k reacquire --all-failures   # every test that fails, not only the first

Python byte code of the mutated files goes to a temporary folder (``PYTHONPYCACHEPREFIX``), so no
stale ``.pyc`` of a mutant can outlive it; compiled CasADi code is cached under a key of the
Function's serialised form, so a mutant never loads the original's library or the reverse.
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Mutant:
    """One planted bug: ``original`` (exactly once in ``path``) becomes ``replacement``."""

    name: str
    path: str
    original: str
    replacement: str
    tests: tuple
    equivalent: str = ""


M = Mutant
UPD, UKF, EKF = "casship/estimators/update.py", "casship/estimators/ukf.py", "casship/estimators/ekf.py"
LIK, ENG = "casship/identify/_likelihood.py", "casship/identify/_engine.py"
MLE, OE, PROB = "casship/identify/mle.py", "casship/identify/output_error.py", "casship/identify/problem.py"
DISC, RTS, ANG = "casship/discretize.py", "casship/estimators/rts.py", "casship/angles.py"
MET, MMG = "casship/maneuvers/metrics.py", "casship/models/mmg.py"
T_LIK, T_UKF = "tests/test_likelihood_reference.py", "tests/test_ukf_reference.py"
T_FISH, T_GRAD = "tests/test_fisher_reference.py", "tests/test_gradient_reference.py"
RIG, VERD = "casship/identify/rig.py", "casship/identify/verdict.py"
CHOOSE, T_RIG = "casship/identify/captive_choice.py", "tests/test_captive_rig.py"
T_MAP, T_GATE, T_MMG = "tests/test_map_reference.py", "tests/test_gate_reference.py", "tests/test_mmg_reference.py"
PERF, PRED, GUID = "casship/autopilot/performance.py", "casship/simulation/bands.py", "casship/autopilot/guidance.py"
UNC, ASYM, CV = "casship/identify/uncertainty.py", "casship/identify/asymmetry.py", "casship/identify/crossval.py"
ARR, RUN = "casship/estimators/mhe/arrival.py", "casship/estimators/mhe/runner.py"
SCH, PLANTS, MPC = "casship/autopilot/schedule.py", "casship/autopilot/plants.py", "casship/autopilot/mpc.py"
T_RMET, T_RID = "tests/test_reference_metrics.py", "tests/test_reference_identify.py"
T_RMHE, T_RAP = "tests/test_reference_mhe_arrival.py", "tests/test_reference_autopilot.py"
T_MPCI, T_MHES = "tests/test_autopilot_mpc_integral.py", "tests/test_mhe_scaling.py"
MHEP = "casship/estimators/mhe/problem.py"
T_GUID = "tests/test_autopilot_guidance.py"
CF, T_CF = "casship/identify/captive_forces.py", "tests/test_captive_forces.py"
MARIN, T_CHOICE = "problems/kvlcc2_marin/__init__.py", "tests/test_marin_choice.py"
WAVE, T_WAVE = "casship/autopilot/wave_limit.py", "tests/test_autopilot_waves_unstable.py"
T_MMG_ALL = "tests/test_mmg.py"

MUTANTS = [
    # -- the statistics of the filters and the fits -------------------------------------------------------------
    M("likelihood: log(pi) for log(2 pi)", UPD, "ca.sum1(mask) * np.log(2 * np.pi)", "ca.sum1(mask) * np.log(np.pi)",
      (T_LIK,)),
    M("likelihood: constant over all channels", UPD, "ca.sum1(mask) * np.log(2 * np.pi)",
      "mask.numel() * np.log(2 * np.pi)", (T_LIK,)),
    M("likelihood: log det without its factor 2", UPD, "logdet = 2 * ca.sum1(", "logdet = ca.sum1(", (T_LIK,)),
    M("likelihood: unmeasured channels not neutralised in S", UPD, "Dm @ (HPH + R) @ Dm + ca.diag(1 - mask)",
      "(HPH + R) + ca.diag(1 - mask)", (T_LIK,)),
    M("UKF: W0c without 1 - alpha^2", UKF, "wc[0] += 1 - alpha**2 + beta", "wc[0] += beta", (T_UKF,)),
    M("UKF: predicted covariance with the mean weights", UKF, "Pp = outer_sum(dXf, wc)", "Pp = outer_sum(dXf, wm)",
      (T_UKF,)),
    M("UKF: sigma points spread by c, not sqrt(c)", UKF, "L = np.sqrt(c) * psd_sqrt(cov)", "L = c * psd_sqrt(cov)",
      (T_UKF,)),
    M("Fisher: covariance term without 0.5", LIK, "0.5 * (A.T @ B)", "(A.T @ B)", (T_FISH,)),
    M("Fisher: mean term without S^-1", LIK, "de.T @ Si @ de", "de.T @ de", (T_FISH,)),
    M("gradient: output-bias sign, adjoint (MLE)", LIK, 'g -= E["y"].T @ sums["y"]', 'g += E["y"].T @ sums["y"]',
      (T_GRAD,)),
    M("gradient: output-bias sign, sensitivities (MLE)", LIK, '"y": -E["y"]', '"y": E["y"]', (T_GRAD,)),
    M("gradient: output-bias sign, adjoint (output error)", ENG, '- E["y"].T @ sums["y"]', '+ E["y"].T @ sums["y"]',
      (T_GRAD,)),
    M("gradient: output-bias sign, sensitivities (output error)", ENG, '"y": -rm.E["y"]', '"y": rm.E["y"]',
      (T_GRAD,)),
    M("MAP: prior without 0.5, IPOPT route (MLE)", MLE, "f = self._graph(theta) + 0.5 * ca.sum1(",
      "f = self._graph(theta) + ca.sum1(", (T_MAP, T_GRAD)),
    M("MAP: prior without 0.5, IPOPT route (output error)", OE, "cost += 0.5 * ca.sum1(ca.DM(self._prec)",
      "cost += ca.sum1(ca.DM(self._prec)", (T_MAP, T_GRAD)),
    M("MAP: prior without 0.5, trust-region route", PROB, "return 0.5 * float(np.sum(self._prec * d * d))",
      "return float(np.sum(self._prec * d * d))", (T_MAP, T_GRAD)),
    M("MAP: observed information's prior without 0.5", MLE, "f = self._graph(ts) + 0.5 * ca.sum1(",
      "f = self._graph(ts) + ca.sum1(", (T_MAP, "tests/test_identify.py")),
    M("output error: record steps unchecked for a discrete-time model", OE, "model.check_steps(np.diff(d.t), d.t)",
      "pass", ("tests/test_output_error_discrete.py",)),
    M("gate: nis < gate instead of <=", UPD, "acc = nis <= gate", "acc = nis < gate", (T_GATE,)),
    M("gate: nis < gate instead of <= (UKF)", UKF, 'acc = nis <= s["gate"]', 'acc = nis < s["gate"]', (T_GATE,)),
    M("reacquire: one rejection too many", EKF, "force = (count >= reacquire)", "force = (count > reacquire)",
      (T_GATE, "tests/test_reacquire.py")),
    M("reacquire: empty rows reset the count", EKF,
      "ca.if_else(measured > 0, ca.if_else(out[\"accepted\"], 0, count + 1), count)",
      "ca.if_else(out[\"accepted\"], 0, ca.if_else(measured > 0, count + 1, count))", (T_GATE,)),
    # -- estimator updates ------------------------------------------------------------------------------------
    M("Joseph form: I + K H", UPD, "ca.DM.eye(Pp.shape[0]) - Ka @ Hm", "ca.DM.eye(Pp.shape[0]) + Ka @ Hm",
      ("tests/test_kf_ekf.py",)),
    M("Joseph form: K R K' dropped", UPD, "P = sandwich(IKH, Pp) + sandwich(Ka, Dm @ R @ Dm)",
      "P = sandwich(IKH, Pp)", ("tests/test_kf_ekf.py",)),
    M("EKF: cross-covariance transpose dropped", EKF, "C = P @ A.T", "C = P @ A", ("tests/test_rts.py",)),
    M("EKF: process noise subtracted", EKF, 'sandwich(A, P, C.T) + sandwich(G, s["Q"])',
      'sandwich(A, P, C.T) - sandwich(G, s["Q"])', ("tests/test_kf_ekf.py",)),
    # -- discretisation -------------------------------------------------------------------------------------
    M("RK4: weight of k3 halved", DISC, "(p + 2 * q + 2 * r + s)", "(p + 2 * q + r + s)",
      ("tests/test_discretize.py",)),
    M("RK4: k2 evaluated a full step ahead", DISC, "k2 = rhs(*(a + h / 2 * k for a, k in zip(z, k1)))",
      "k2 = rhs(*(a + h * k for a, k in zip(z, k1)))", ("tests/test_discretize.py",)),
    M("Van Loan: sign of A", DISC, "M[:n, :n] = -A", "M[:n, :n] = A",
      ("tests/test_discretize.py", "tests/test_kf_ekf.py")),
    M("Euler: half step", DISC, "return x + h * f(x, u, p, w)", "return x + 0.5 * h * f(x, u, p, w)",
      ("tests/test_discretize.py",)),
    # -- smoother -------------------------------------------------------------------------------------------
    M("RTS: correction subtracted", RTS, "[x + J @ d, Ps, J]", "[x - J @ d, Ps, J]", ("tests/test_rts.py",)),
    M("RTS: gain transpose dropped", RTS, "J = spd_solve(Pp1, C.T, exact=True).T",
      "J = spd_solve(Pp1, C, exact=True).T",
      ("tests/test_rts.py",)),
    M("RTS: covariance correction sign", RTS, "Ps1[i, j] - Pp1[i, j]", "Ps1[i, j] + Pp1[i, j]", ("tests/test_rts.py",)),
    # -- angle helpers --------------------------------------------------------------------------------------
    M("wrap: -pi kept (interval closed)", ANG, "np.where(out <= -np.pi, out + 2.0 * np.pi, out)",
      "np.where(out < -np.pi, out + 2.0 * np.pi, out)", ("tests/test_properties.py", "tests/test_frames_kinematic.py")),
    M("wrap_sym: sine and cosine swapped", ANG, "ca.atan2(ca.sin(angle), ca.cos(angle))",
      "ca.atan2(ca.cos(angle), ca.sin(angle))", ("tests/test_properties.py", "tests/test_kf_ekf.py")),
    M("wrap_fast: floor offset", UKF, "ca.floor((angle + np.pi) / (2 * np.pi))",
      "ca.floor((angle - np.pi) / (2 * np.pi))",
      ("tests/test_ukf.py", "tests/test_enkf.py")),
    # -- manoeuvre metrics ----------------------------------------------------------------------------------
    M("turning: lateral axis sign", MET, "lateral = -(x - x0) * np.sin(psi0)", "lateral = (x - x0) * np.sin(psi0)",
      ("tests/test_maneuvers.py",)),
    M("zig-zag: overshoot measured from the wrong side", MET, "np.degrees(seg[j] - heading)",
      "np.degrees(seg[j] + heading)", ("tests/test_maneuvers.py",)),
    M("zig-zag: period from the wrong reversal", MET, "reversals[2][0] - reversals[0][0]",
      "reversals[1][0] - reversals[0][0]", ("tests/test_maneuvers.py",)),
    # -- MMG hull, propeller, rudder ------------------------------------------------------------------------
    M("MMG: sign of Y'_vrr", MMG, '+ P["Y_vrr_dash"] * v * rL**2', '- P["Y_vrr_dash"] * v * rL**2', (T_MMG,)),
    M("MMG: X'_vvvv scaled by U, not U^2", MMG, 'P["X_vvvv_dash"] * v**4 / U**2', 'P["X_vvvv_dash"] * v**4 / U',
      (T_MMG,)),
    M("MMG: N_H scaled by L, not L^2", MMG, "N_H = 0.5 * rho * L**2 * d", "N_H = 0.5 * rho * L * d", (T_MMG,)),
    M("MMG: sign of a_H x_H in N_R", MMG, '-(x_R + P["a_H"] * x_H)', '-(x_R - P["a_H"] * x_H)', (T_MMG,)),
    M("MMG: wake C_2 switch reversed", MMG, 'ca.if_else(beta_P > 0, P["C_2_plus"]',
      'ca.if_else(beta_P < 0, P["C_2_plus"]',
      (T_MMG,)),
    M("MMG: flow-straightening switch reversed", MMG, 'ca.if_else(beta_R < 0, P["gamma_R_minus"]',
      'ca.if_else(beta_R > 0, P["gamma_R_minus"]', (T_MMG,)),
    # -- IMO limits and step-response metrics (published and hand-built references) -------------------------
    M("IMO: second overshoot limit = first-overshoot limit + 15 deg", MET,
      "return 5.0 + 0.5 * L_over_V, 17.5 + 0.75 * L_over_V", "return 5.0 + 0.5 * L_over_V, 20.0 + 0.5 * L_over_V",
      (T_RMET,)),
    M("IMO: 35 deg second overshoot for L/V >= 30 s", MET, "return 20.0, 40.0", "return 20.0, 35.0", (T_RMET,)),
    M("IMO: 10/10 limits of L/V < 10 s", MET, "return 10.0, 25.0", "return 10.0, 20.0", (T_RMET,)),
    M("step: the settling band's edge counts as outside", PERF, "outside = np.flatnonzero(np.abs(err) > tol)",
      "outside = np.flatnonzero(np.abs(err) >= tol)", (T_RMET,)),
    M("step: settled at the last sample outside", PERF, "float(t[outside[-1] + 1] - t[0])",
      "float(t[outside[-1]] - t[0])", (T_RMET,)),
    M("step: overshoot counted from 90 %", PERF, "over = max(0.0, float(np.max(frac) - 1.0))",
      "over = max(0.0, float(np.max(frac) - 0.9))", (T_RMET,)),
    # -- predictive band and integral LOS ---------------------------------------------------------------------
    M("band: one-sided quantile (z 1.645 for 95 %)", PRED, "stats.norm.ppf(0.5 + 0.5 * float(level))",
      "stats.norm.ppf(float(level))", (T_RMET,)),
    M("ILOS: integral rate without Delta", GUID,
      "step = dt * Delta * y_e / (Delta**2 + (y_e + kappa * y_int) ** 2)",
      "step = dt * y_e / (Delta**2 + (y_e + kappa * y_int) ** 2)", (T_RMET,)),
    M("ILOS: integral rate halved", GUID,
      "step = dt * Delta * y_e / (Delta**2 + (y_e + kappa * y_int) ** 2)",
      "step = 0.5 * dt * Delta * y_e / (Delta**2 + (y_e + kappa * y_int) ** 2)", (T_RMET,)),
    M("ILOS: integrates outside its linear region", GUID,
      "ca.fabs(y_e) <= self.integrate_within * Delta", "ca.fabs(y_e) <= 1e9 * Delta", (T_GUID,)),
    # -- robust (HAC) covariance ------------------------------------------------------------------------------
    M("HAC: Bartlett weight 1 - l/L", UNC, "w = 1.0 - lag / (L + 1.0)", "w = 1.0 - lag / L", (T_RID,)),
    M("HAC: one side of the lagged covariance", UNC, "G += w * (C + C.T)", "G += w * C", (T_RID,)),
    M("HAC: Andrews constant of the quadratic-spectral kernel", UNC, "np.ceil(1.1447 * (alpha * n) ** (1 / 3))",
      "np.ceil(1.3221 * (alpha * n) ** (1 / 3))", (T_RID,)),
    M("HAC: bandwidth capped at half the record", UNC, "return int(min(n // 4,", "return int(min(n // 2,", (T_RID,)),
    # -- mirror pairs: when an asymmetry is estimable --------------------------------------------------------
    M("asymmetry: rudder tolerance exclusive", ASYM, 'abs(a["rudder_deg"] - b["rudder_deg"]) > ANGLE_TOL_DEG',
      'abs(a["rudder_deg"] - b["rudder_deg"]) >= ANGLE_TOL_DEG', (T_RID,)),
    M("asymmetry: switch heading not compared", ASYM,
      'return a["kind"] != "zigzag" or abs(a["heading_deg"] - b["heading_deg"]) <= ANGLE_TOL_DEG', "return True",
      (T_RID,)),
    M("asymmetry: 'other' records pair", ASYM, 'if a["kind"] != b["kind"] or a["kind"] == "other" or',
      'if a["kind"] != b["kind"] or', (T_RID,)),
    M("asymmetry: pairs across facilities", ASYM,
      'if sig[i]["side"] != sig[j]["side"] and _same(sig[i], sig[j]) and same(i, j)}',
      'if sig[i]["side"] != sig[j]["side"] and _same(sig[i], sig[j])}', (T_RID,)),
    M("asymmetry: records without a copy join every group", ASYM, "if lab is not None and str(lab) == label",
      "if lab is None or str(lab) == label", (T_RID,)),
    M("asymmetry: a group's pair may reach outside it", ASYM,
      "if not any(i in members and j in members for i, j in pairs)",
      "if not any(i in members or j in members for i, j in pairs)", (T_RID,)),
    # -- cross-validation's replay of a held-out record -------------------------------------------------------
    M("cross-validation: output bias added to the record", CV, "cols[ch] = data[ch] - b",
      "cols[ch] = data[ch] + b", (T_RID,)),
    M("cross-validation: input bias subtracted", CV, "cols[ch] = data[ch] + b", "cols[ch] = data[ch] - b", (T_RID,)),
    M("cross-validation: the first record's group copy for every record", CV, "label = labels[name][r]",
      "label = labels[name][0]", (T_RID,)),
    # -- MHE fixed arrival cost -------------------------------------------------------------------------------
    M("MHE arrival: previous estimate one window early", ARR, 'if kind == "fixed" and k > N:',
      'if kind == "fixed" and k >= N:', (T_RMHE,)),
    M("MHE arrival: previous estimate one window late", ARR, 'if kind == "fixed" and k > N:',
      'if kind == "fixed" and k > N + 1:', (T_RMHE,)),
    M("MHE arrival: the previous window's first state", RUN, "self.z[win.ix[1]], self.P0)",
      "self.z[win.ix[0]], self.P0)", (T_RMHE,)),
    # -- gain schedule and MPC preview ------------------------------------------------------------------------
    M("schedule: Kd and Ki swapped in the law handed out", SCH, 'PIDGains(P["Kp"], P["Kd"], P["Ki"], P["m"]',
      'PIDGains(P["Kp"], P["Ki"], P["Kd"], P["m"]', (T_RAP,)),
    M("schedule: m_hf handed out as m", SCH, 'm_hf=P["m_hf"]', 'm_hf=P["m"]', (T_RAP,)),
    M("schedule: interpolation over the whole range", PLANTS, "w = (x - xs[i]) / (xs[i + 1] - xs[i])",
      "w = (x - xs[i]) / (xs[-1] - xs[0])", (T_RAP,)),
    M("schedule: the slowest design's numbers at the top speed", SCH,
      "piecewise_linear(speed, self.speeds, [t[k] for t in tables])",
      "piecewise_linear(speed, self.speeds, [t[k] for t in tables[:-1]] + [tables[0][k]])", (T_RAP,)),
    M("MPC preview: one period late", MPC, "M = Ad @ M\n            out.append(M[:rows])",
      "out.append(M[:rows])\n            M = Ad @ M", (T_RAP,)),
    M("MPC preview: from the reference state before the sample's step", MPC,
      'z = np.array([float(wrap(mem["xr"][0] - ref)), mem["xr"][1], mem["xr"][2]])',
      'z = np.array([float(wrap(memory["xr"][0] - ref)), memory["xr"][1], memory["xr"][2]])', (T_RAP,)),
    M("MPC preview: the reference model's acceleration dropped", MPC,
      'mem["xr"][1], mem["xr"][2]])', 'mem["xr"][1], 0.0])', (T_RAP,)),
    M("MPC integral: the plan's integral does not integrate", MPC, "Ac[m, 0] = 1.0", "Ac[m, 0] = 0.0", (T_MPCI,)),
    M("MPC integral: its preview one period late", MPC, "acc = acc + Phi @ M\n            M = Ad @ M",
      "M = Ad @ M\n            acc = acc + Phi @ M", (T_MPCI,)),
    M("MPC integral: no anti-windup", MPC, "out = ca.if_else(hold, integral, integral + dt * e)",
      "out = ca.if_else(hold, integral + dt * e, integral + dt * e)", (T_MPCI,)),
    M("MHE scaling: the solvers see the window unscaled", MHEP,
      "dx = ca.if_else(c > 0, ca.fmax(ca.fmin(1.0 / ca.sqrt(ca.fmax(c, 1e-300)), 1.0), 1e-12), 1.0)",
      "dx = ca.if_else(c > 0, 1.0, 1.0)", (T_MHES,)),
    M("MHE scaling: the Gauss-Newton step's KKT system not equilibrated", MHEP,
      'sol = s_ * ca.solve(ca.mtimes(Sd, ca.mtimes(K, Sd)), s_ * rhs, "qr")', 'sol = ca.solve(K, rhs, "qr")',
      (T_MHES,)),
    M("MHE scaling: the arrival's whitening tested on the covariance, not the correlations", ARR,
      "sd = np.where(np.isfinite(d) & (d > 0), np.sqrt(np.abs(d)), top)", "sd = np.ones_like(d)", (T_MHES,)),
    M("MHE scaling: a small process noise dropped as round-off", MHEP, "        keep = d > 0\n",
      "        keep = d > 1e-12 * max(1.0, d.max())\n", (T_MHES,)),
    # -- captive forces, the rudder lever, the fold families, the heading-error floor ---------------------------
    M("captive Jacobian: the scale's derivative in rho dropped", CF,
      "J = J - ca.mtimes(y / rho, ca.DM(e_rho)) - ca.mtimes(self._powers * y / L, ca.DM(e_L))",
      "J = J - ca.mtimes(self._powers * y / L, ca.DM(e_L))", (T_CF,)),
    M("captive Jacobian: the scale's power of L taken as 1", CF, "ca.mtimes(self._powers * y / L, ca.DM(e_L))",
      "ca.mtimes(y / L, ca.DM(e_L))", (T_CF,)),
    M("rudder lever: the advance ratio without the wake", MMG, "x_H + P[\"x_HJ_dash\"] * L * u_P * n * D",
      "x_H + P[\"x_HJ_dash\"] * L * u * n * D", (T_MMG_ALL,)),
    M("fold families: the group families always run", MARIN, "            if kind not in families:\n                continue\n",
      "", (T_CHOICE,)),
    M("heading floor: the yaw rate's error for the heading's", WAVE, 'np.sqrt(P[m["ipsi"], m["ipsi"]])',
      'np.sqrt(P[m["ir"], m["ir"]])', (T_WAVE,)),
    # -- captive rigs, what carries to another ship, the out-of-sample verdict ------------------------------------
    M("rig: R'_0 without the draught", RIG, 'U0**2 * p["L_pp"] * p["d"])', 'U0**2 * p["L_pp"])', (T_RIG,)),
    M("rig: the model-based covariance carried for the robust one", RIG, 'belief = fit.uncertainty("robust")',
      'belief = fit.uncertainty("model")', (T_RIG,)),
    M("rig: the open-water curve fitted linear", RIG, "np.vstack([np.ones_like(J), J, J**2]).T",
      "np.vstack([np.ones_like(J), J, 0 * J]).T", (T_RIG,)),
    M("verdict out of sample: the start's replay for the fit's", VERD,
      "f_res = _replay(model, data, values, {}, method, uncertainty=uncertainty)",
      "f_res = _replay(model, data, start_p, {}, method, uncertainty=uncertainty)", (T_RIG,)),
    M("classical derivatives: the yaw inertia about the centre of gravity for midship's", RIG,
      'I_z=mass * ((p["k_zz"] * L) ** 2 + p["x_G"] ** 2))', 'I_z=mass * (p["k_zz"] * L) ** 2)', (T_RIG,)),
    M("captive choice: a held-out record without a facility at the population values", CHOOSE,
      "ship.params(facility_of(d))", 'ship.params(d.meta.get("facility"))', (T_RIG,)),
    M("captive choice: the worse candidate wins", CHOOSE, 'scores["joint"] < scores["captive-only"] else',
      'scores["joint"] > scores["captive-only"] else', (T_RIG,)),
    M("rig: a new facility's quantity without the between-facility spread", RIG,
      'prior_std=prior[n])["new_facility_std"]', 'prior_std=prior[n])["population_std"]', (T_RIG,)),
    M("covariance check: relative to the largest eigenvalue again (units mixed)", "casship/gaussian.py",
      "m[np.ix_(keep, keep)] * np.outer(scale, scale)", "m[np.ix_(keep, keep)] / np.abs(m).max()",
      ("tests/test_data.py",)),
    M("replay: the uninformative band never flagged", "casship/maneuvers/replay.py",
      "wide = halfwidth > UNINFORMATIVE_DEG", "wide = halfwidth > 360.0 * UNINFORMATIVE_DEG",
      ("tests/test_verdict_bands.py",)),
]


class _Restore:
    """Write a mutant and put the original text back on exit, whatever ends the run."""

    def __init__(self, path: Path, text: str, mutated: str):
        self.path, self.text, self.mutated = path, text, mutated

    def __enter__(self):
        self.path.write_text(self.mutated)
        return self

    def __exit__(self, *exc):
        self.path.write_text(self.text)
        return False


def _terminate(signum, frame):            # SIGTERM / SIGHUP: unwind through the restores like Ctrl-C
    raise KeyboardInterrupt(f"signal {signum}")


def _failed_tests(output: str) -> list[str]:
    return re.findall(r"^(?:FAILED|ERROR) (\S+)", output, re.M)


def run_tests(tests, timeout: float, first: bool = True) -> tuple[int, str, float]:
    """Run ``tests`` with pytest (by default stopping at the first failure); ``(exit code, output, seconds)``."""
    with tempfile.TemporaryDirectory(prefix="casship-mutation-pyc-") as pyc:
        env = {**os.environ, "PYTHONPYCACHEPREFIX": pyc, "PYTHONDONTWRITEBYTECODE": "1"}
        cmd = [sys.executable, "-m", "pytest", *(["-x"] if first else []), "-q", "-rfE", "-p", "no:cacheprovider",
               "-W", "ignore", *tests]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
            return proc.returncode, proc.stdout + proc.stderr, time.perf_counter() - t0
        except subprocess.TimeoutExpired as exc:
            out = (exc.stdout or b"").decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
            return -1, out, time.perf_counter() - t0


def check_table(mutants) -> list[str]:
    """Problems with the table: an original text missing or ambiguous in its file, an unknown test."""
    problems = []
    for mu in mutants:
        text = (ROOT / mu.path).read_text()
        count = text.count(mu.original)
        if count != 1:
            problems.append(f"{mu.name}: {mu.original!r} occurs {count} times in {mu.path} (must be once)")
        problems += [f"{mu.name}: no test file {t}" for t in mu.tests if not (ROOT / t.split("::")[0]).exists()]
    return problems


def markdown(rows) -> str:
    lines = ["| # | mutant | file | result | killed by / reason |", "|---|---|---|---|---|"]
    for i, (mu, result, detail, secs) in enumerate(rows, 1):
        lines.append(f"| {i} | {mu.name} | `{mu.path}` | {result} | {detail} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-k", dest="keyword", help="only mutants whose name or file contains this (case-insensitive; "
                                               "several words separated by commas: any of them)")
    ap.add_argument("--list", action="store_true", help="print the table of mutants and stop")
    ap.add_argument("--out", help="also write the result table (Markdown) to this file")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per mutant before it counts as killed")
    ap.add_argument("--no-baseline", action="store_true", help="skip running the tests once unmutated first")
    ap.add_argument("--all-failures", action="store_true",
                    help="run each mutant's tests to the end and list every test that fails (slower)")
    args = ap.parse_args(argv)
    words = [w.strip().lower() for w in (args.keyword or "").split(",") if w.strip()]
    chosen = [mu for mu in MUTANTS if not words or any(w in (mu.name + " " + mu.path).lower() for w in words)]
    problems = check_table(chosen)
    if problems:
        print("the mutation table is out of step with the code:\n  " + "\n  ".join(problems), file=sys.stderr)
        return 2
    if args.list:
        for i, mu in enumerate(chosen, 1):
            print(f"{i:3d}  {mu.name}  [{mu.path}]  -> {', '.join(mu.tests)}")
        return 0
    signal.signal(signal.SIGTERM, _terminate)
    if hasattr(signal, "SIGHUP"):
        signal.signal(signal.SIGHUP, _terminate)
    if not args.no_baseline:
        tests = sorted({t for mu in chosen for t in mu.tests})
        code, out, secs = run_tests(tests, args.timeout)
        if code != 0:
            print(f"the tests fail without any mutant ({secs:.0f} s): fix them first\n{out[-3000:]}", file=sys.stderr)
            return 2
        print(f"baseline: {len(tests)} test files pass ({secs:.0f} s)", flush=True)
    rows = []
    try:
        for i, mu in enumerate(chosen, 1):
            path = ROOT / mu.path
            text = path.read_text()
            with _Restore(path, text, text.replace(mu.original, mu.replacement, 1)):
                code, out, secs = run_tests(mu.tests, args.timeout, first=not args.all_failures)
            if code == 1:
                result, detail = "killed", ", ".join(f"`{t}`" for t in _failed_tests(out))
            elif code == -1:
                result, detail = "killed (timeout)", f"no result in {args.timeout:.0f} s"
            elif code == 0:
                result = "equivalent" if mu.equivalent else "SURVIVED"
                detail = mu.equivalent or "no test failed: a gap"
            else:
                result, detail = f"error (pytest exit {code})", out.strip().splitlines()[-1] if out.strip() else ""
            rows.append((mu, result, detail, secs))
            print(f"[{i}/{len(chosen)}] {result:10s} {mu.name} ({secs:.0f} s) {detail}", flush=True)
    except KeyboardInterrupt:
        print("interrupted: every mutated file has been restored", file=sys.stderr)
        return 130
    table = markdown(rows)
    print("\n" + table)
    if args.out:
        Path(args.out).write_text(table + "\n")
    survivors = [r for r in rows if r[1] in ("SURVIVED",) or r[1].startswith("error")]
    return 1 if survivors else 0


if __name__ == "__main__":
    sys.exit(main())
