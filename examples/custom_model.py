"""Write your own model once: declare it, compose a force term, simulate, filter, export to C.

A 3-DOF linear manoeuvring model in body velocities with earth-fixed kinematics, written with
``ModelBuilder``; a constant wind force is added through the generalised-force port ``tau``
without rewriting the model; a heading autopilot closes the loop during the simulation; GNSS
positions at 1 Hz and a gyro at 10 Hz are filtered by an EKF whose step is exported as C.

Run: ``python examples/custom_model.py``
"""
import tempfile

import casadi as ca
import numpy as np

import casship as cs
from casship.estimators import export_estimator

# -- 1. the model: named states, inputs, parameters with nominal values, noise, outputs -------------
b = cs.ModelBuilder("linear3dof", "linear surge-sway-yaw model with NED kinematics (example)")
u, v, r = b.state("u", unit="m/s"), b.state("v", unit="m/s"), b.state("r", unit="rad/s")
x, y, psi = b.state("x", unit="m"), b.state("y", unit="m"), b.state("psi", unit="rad", angle=True)
delta, thrust = b.input("delta", unit="rad"), b.input("thrust", unit="N")
m, Iz = b.param("m", 5.0e4, unit="kg"), b.param("Iz", 2.0e6, unit="kg m^2")
Xu, Yv, Nr = b.param("Xu", 2.0e3), b.param("Yv", 3.0e4), b.param("Nr", 4.0e6)
Yd, Nd = b.param("Ydelta", 2.0e4), b.param("Ndelta", -2.5e5)
tau = b.port("tau", 3)                                  # external forces: zero until a term feeds it
b.ode(u=(thrust - Xu * u + tau[0]) / m,
      v=(-Yv * v + Yd * delta + tau[1]) / m + b.noise("w_v"),
      r=(-Nr * r + Nd * delta + tau[2]) / Iz + b.noise("w_r"))
b.ode(**dict(zip(("x", "y", "psi"), cs.frames.body_to_ned(u, v, r, psi))))
b.output("x", x)
b.output("y", y)
b.output("psi", psi)
calm = b.build()


# -- 2. compose: a constant wind force, as a term fed into the port -----------------------------------
def wind(builder):
    builder.feed("tau", ca.vertcat(builder.param("X_wind", -500.0), builder.param("Y_wind", 1500.0), 0.0))


ship = calm.extend(wind, name="linear3dof+wind")
print(ship)

# -- 3. simulate with a heading autopilot in the loop ------------------------------------------------
psi_ref = np.radians(30.0)


def autopilot(t, state):
    e = cs.wrap(psi_ref - state[ship.index("psi")])
    return [np.clip(-(2.0 * e - 40.0 * state[ship.index("r")]), -0.6, 0.6), 6.0e3]


t = np.arange(0.0, 300.0, 0.1)
truth = cs.simulate(ship, ship.states(u=3.0), t, autopilot)
print(f"heading after 300 s: {np.degrees(truth['psi'][-1]):.2f} deg (reference 30 deg)")

# -- 4. measure (GNSS 1 Hz, gyro 10 Hz) and filter --------------------------------------------------
std = {"x": 2.0, "y": 2.0, "psi": np.radians(0.5)}
data = cs.measure(truth, ship, std, rates={"x": 1.0, "y": 1.0}, seed=7)
ekf = cs.EKF(cs.discretize(ship, 0.1), Q=np.diag([1e-6, 1e-9]), R={k: s**2 for k, s in std.items()})
prior = cs.Gaussian(ship.states(u=2.5), np.diag([1.0, 0.1, 1e-4, 25.0, 25.0, 0.01]))
result = ekf.filter(data, prior)
pos_err = np.hypot(result["x"] - truth["x"], result["y"] - truth["y"])
print(f"position error: GNSS {std['x'] * np.sqrt(2):.2f} m (rms), EKF {np.sqrt(np.mean(pos_err[100:] ** 2)):.2f} m")

# -- 5. exact Jacobians and the same EKF step as standalone C ----------------------------------------
A = np.array(ship.f_jac(truth.x[-1], truth.u[-1], ship.params(), np.zeros(ship.nw))[0])
print("A[psi-row] =", np.round(A[ship.index("psi")], 6))
with tempfile.TemporaryDirectory() as folder:
    files = export_estimator(ekf, folder, "ship_ekf")
    print(f"C export: {files.source.name} ({files.source.stat().st_size // 1024} kB), {files.header.name}, "
          f"{files.data_header.name}; inputs {[n for n, _ in files.inputs]}")
