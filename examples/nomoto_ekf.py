"""Heading and yaw rate of a ship from a noisy gyro compass: Nomoto model + EKF.

Simulates a 20/20 zig-zag-like rudder sequence on the first-order Nomoto model (Mariner values),
measures the heading at 1 Hz with 0.5 deg noise inside a 10 Hz record (other rows NaN = not
measured), and estimates heading and yaw rate with an extended Kalman filter.

Run: ``python examples/nomoto_ekf.py``
"""
import numpy as np

import casship as cs

model = cs.models.nomoto_first_order()                # states psi, r; input delta; output psi
dt = 0.1
t = np.arange(0.0, 600.0, dt)
delta = np.radians(20.0) * np.sign(np.sin(2 * np.pi * t / 200.0) + 1e-9)

truth = cs.simulate(model, model.states(), t, {"delta": delta})
sigma = np.radians(0.5)
data = cs.measure(truth, model, {"psi": sigma}, rates={"psi": 1.0}, seed=1)

ekf = cs.EKF(cs.discretize(model, dt, method="rk4"), Q=1e-9, R=sigma**2)
prior = cs.Gaussian(model.states(), np.diag([np.radians(5.0) ** 2, 1e-4]))
result = ekf.filter(data, prior)

measured = np.isfinite(data["psi"])
err_psi = cs.wrap(result["psi"] - truth["psi"])
err_r = result["r"] - truth["r"]
print(f"samples: {len(t)}, heading measured at {measured.sum()} of them (1 Hz)")
print(f"heading RMSE: measurement {np.degrees(np.std(cs.wrap(data['psi'][measured] - truth['psi'][measured]))):.3f} deg, "
      f"EKF {np.degrees(np.sqrt(np.mean(err_psi[100:] ** 2))):.3f} deg")
print(f"yaw-rate RMSE (not measured): EKF {np.degrees(np.sqrt(np.mean(err_r[100:] ** 2))):.4f} deg/s")
print(f"average NIS {result.nis[measured].mean():.2f} (expected 1 for a consistent filter); "
      f"health ok: {result.health(window=100).ok}")
