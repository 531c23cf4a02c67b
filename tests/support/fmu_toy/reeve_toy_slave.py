"""Toy FMU entry for the machinery tests: sheave + elastic rope + hanging cabin.

Not a plant model, just enough dynamics to exercise ReeveSlave: numpy state, a hidden integrator,
inputs with and without direct feed-through, tunable/fixed parameters, an Integer output, and a
fault-injection input. Positive phi lifts the cabin; x is the cabin position (up positive).

    rope elongation   e = r*phi - x,   tension F = max(0, k*e + c*(r*w - v))
    sheave            J*dw/dt = tau_eff - F*r,    tau_eff lags motor.tau with time constant T
    cabin             m*dv/dt = F - m*g
Hidden (not a registered variable): the numpy state vector y = [phi, w, x, v, tau_eff] and the
tension impulse integral, which feeds the output rope.meanTension.
"""
import numpy as np

from reeve_fmu.fmu.slave import DefaultExperiment, Fmi2Status, ReeveSlave

G = 9.81


class ReeveToySlave(ReeveSlave):
    description = "reeve_fmu machinery test toy: sheave, spring rope, cabin"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=2.0, step_size=1e-3)

    def define(self):
        self.add_real("motor.tau", "input", unit="N.m", start=0.0, declared_type="Torque",
                      description="air-gap torque")
        self.add_boolean("test.raiseInStep", "input", start=False,
                         description="fault injection: step() raises while true")
        self.add_real("cabin.mass", "parameter", "fixed", "kg", start=500.0, min=1.0)
        self.add_real("sheave.J", "parameter", "fixed", "kg.m2", start=10.0, min=1e-6)
        self.add_real("sheave.radius", "parameter", "fixed", "m", start=0.3, min=1e-3)
        self.add_real("rope.k", "parameter", "fixed", "N/m", start=2.0e5, min=0.0)
        self.add_real("rope.c", "parameter", "tunable", "N.s/m", start=2.0e3, min=0.0)
        self.add_real("motor.T", "parameter", "fixed", "s", start=0.01, min=1e-6)
        self.add_integer("solver.substeps", "parameter", "fixed", start=10, min=1, max=1000)
        self.add_real("sheave.phi", "output", unit="rad", display_unit="deg")
        self.add_real("sheave.w", "output", unit="rad/s", display_unit="rpm", derivative_of="sheave.phi")
        self.add_real("cabin.position", "output", declared_type="Position", display_unit="mm")
        self.add_real("cabin.velocity", "output", declared_type="Velocity", derivative_of="cabin.position")
        self.add_real("cabin.acceleration", "output", declared_type="Acceleration",
                      derivative_of="cabin.velocity")
        self.add_real("rope.tension", "output", declared_type="Force")
        self.add_real("rope.meanTension", "output", unit="N", description="impulse / elapsed time")
        self.add_real("motor.power", "output", unit="W", dependencies=["motor.tau"],
                      description="motor.tau * sheave.w (direct feed-through)",
                      getter=lambda: self.values["motor.tau"] * self.values["sheave.w"])
        self.add_integer("steps", "output")

    # -- model -------------------------------------------------------------------------------
    def initialize(self):
        v = self.values
        self.m, self.J, self.r = v["cabin.mass"], v["sheave.J"], v["sheave.radius"]
        self.k, self.T = v["rope.k"], v["motor.T"]
        self.n_sub = int(v["solver.substeps"])
        x0 = -self.m * G / self.k                       # static equilibrium, phi = 0
        self.y = np.array([0.0, 0.0, x0, 0.0, self.m * G * self.r])
        self.impulse = 0.0
        self.elapsed = 0.0
        self._outputs(v["rope.c"])

    def _tension(self, y, c):
        return max(0.0, self.k * (self.r * y[0] - y[2]) + c * (self.r * y[1] - y[3]))

    def _rhs(self, y, tau, c):
        F = self._tension(y, c)
        return np.array([y[1], (y[4] - F * self.r) / self.J, y[3], F / self.m - G,
                         (tau - y[4]) / self.T])

    def step(self, t, dt):
        v = self.values
        if v["test.raiseInStep"]:
            raise ZeroDivisionError(f"toy failure injected at t={t} (100% intended, %s %d %n stay literal)")
        tau, c = v["motor.tau"], v["rope.c"]
        h = dt / self.n_sub
        y = self.y
        for _ in range(self.n_sub):
            k1 = self._rhs(y, tau, c)
            k2 = self._rhs(y + 0.5 * h * k1, tau, c)
            k3 = self._rhs(y + 0.5 * h * k2, tau, c)
            k4 = self._rhs(y + h * k3, tau, c)
            y = y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
            self.impulse += h * self._tension(y, c)
        if not np.all(np.isfinite(y)):
            self.log(f"state became non-finite at t={t}", Fmi2Status.error)
            return False
        self.y = y
        self.elapsed += dt
        v["steps"] += 1
        self._outputs(c)
        return True

    def _outputs(self, c):
        y, v = self.y, self.values
        v["sheave.phi"], v["sheave.w"] = float(y[0]), float(y[1])
        v["cabin.position"], v["cabin.velocity"] = float(y[2]), float(y[3])
        F = self._tension(y, c)
        v["rope.tension"] = F
        v["cabin.acceleration"] = F / self.m - G
        v["rope.meanTension"] = self.impulse / self.elapsed if self.elapsed > 0 else F

    # -- hidden state --------------------------------------------------------------------------
    def get_hidden_state(self):
        return {"y": self.y.tolist(), "impulse": self.impulse, "elapsed": self.elapsed}

    def set_hidden_state(self, s):
        self.y = np.array(s["y"], dtype=float)
        self.impulse = s["impulse"]
        self.elapsed = s["elapsed"]
