"""FMU entry of the reeving plant (FMI 2.0 co-simulation): `reeve-fmu build` -> fmus/ReevingPlant.fmu.

Input   motor.torque [N.m] (air-gap torque, positive lifts the car) and brake.command (1 = release,
        0 = apply), both held over the communication step.
Outputs the names of `reeve-fmu simulate` for the scene (car.position, traction.tension_in, ...,
        motor.angle, motor.speed, brake.torque, brake.engaged).
Parameters (fixed: the model is built in exitInitializationMode) car.load, rope.EA, rope.damping,
        brake.static_torque, motor.inertia.

The scene and the output declarations come from the FMU's resources (scene.toml, reeve_plant.json,
written by reeve_fmu.fmu.cosim.plant_build_inputs). Any communication step is accepted: the plant
sub-steps internally with the scene's solver step (generalized-alpha, steps <= solver.step).
Plausibility warnings of the scene are logged at initialization (physically impossible values fail
it). A solver failure (an event: vanishing span, no Newton convergence) raises inside step():
ReeveSlave logs it through the FMU logger (the message names the event and its time) and returns
fmi2Discard; the outputs keep the values of the last good step; further steps are refused until the
master restores an FMU state or resets.

Built with `reeve-fmu build --fmi 3` (FMI 3.0): also the arrays sheaves.angle, .speed, .tension_in,
.tension_out over the sheaves' scalars, and, when the host allows early return, steps that end at the
solver step of a brake engagement or release, a slack or snap-taut rope, slip onset, or at the last
solver step before a drum runs empty (_step_to_event).
"""
import json

from reeve_fmu.components.plant import PLANT_PARAMETERS, make_plant
from reeve_fmu.fmu.cosim import PLANT_CONFIG
from reeve_fmu.fmu.slave import DefaultExperiment, Fmi2Status, ReeveSlave


class ReevingPlantSlave(ReeveSlave):
    description = "Reeving system (ALE rope model, reeve_fmu): motor torque in, car/rope/sheave states out"
    might_return_early = True      # FMI 3.0: brake engagement, slack, snap-taut, slip (_step_to_event)

    def define(self):
        with open(self.resource_path(PLANT_CONFIG), encoding="utf-8") as fh:
            cfg = json.load(fh)
        self.config = cfg
        self.modelName = cfg["name"]
        self.description = (f"{type(self).description}; scene {cfg['scene_name']}: "
                            f"{cfg['scene_description']}").rstrip(": ")
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=cfg["stop_time"],
                                                    step_size=1e-3)
        self.add_real("motor.torque", "input", declared_type="Torque", start=0.0,
                      description="air-gap torque of the machine (positive lifts the car), held over "
                                  "the step")
        self.add_real("brake.command", "input", "discrete", unit="1", start=0.0, min=0.0, max=1.0,
                      description="machine brake command: 1 = release (open), 0 = apply (close)")
        for name, (_, unit, desc) in PLANT_PARAMETERS.items():
            self.add_real(name, "parameter", "fixed", unit=unit, start=cfg["parameters"][name],
                          min=1e-9 if name == "rope.EA" else 0.0, description=desc)
        # the engine also reports the torque it applied; it is kept in a local variable so that one
        # dict update per step writes all outputs (the input motor.torque is never overwritten)
        self.add_real("motor.torque_applied", "local", declared_type="Torque",
                      description="motor torque the plant applied during the last step (the input held)")
        self._names = []
        for o in cfg["outputs"]:
            self.add_real(o["name"], "output", unit=o["unit"], declared_type=o["type"],
                          display_unit=o["display"], derivative_of=o["derivative_of"],
                          description=o["description"],
                          dependencies=["motor.torque"] if o["depends"] else ())
            self._names.append(o["name"])
        self.add_output_arrays()      # FMI 3.0: sheaves.angle, .speed, .tension_in, .tension_out
        self.plant = None

    def initialize(self):
        v = self.values
        cfg = self.config
        self.plant = make_plant(self.resource_path(cfg["scene"]), cfg["scene_payload"],
                                {name: v[name] for name in PLANT_PARAMETERS})
        names = self.plant.output_names
        missing = [n for n in self._names if n not in names]
        if missing:
            raise RuntimeError(f"the plant model has no outputs {missing} (resources out of date?)")
        # model output order, with the engine's motor.torque mapped to the local motor.torque_applied
        self._all = [("motor.torque_applied" if n == "motor.torque" else n) for n in names]
        unknown = [n for n in self._all if n not in self.values]
        if unknown:
            raise RuntimeError(f"the plant model has outputs {unknown} this FMU does not declare "
                               f"(resources out of date?)")
        for w in self.plant.warnings:    # plausibility and statics warnings of the scene
            self.log(w, Fmi2Status.warning)
        outs = self.plant.outputs()
        self._write([outs[n] for n in names])
        # per step only what the drive needs is written at once; the other outputs when read
        self._iw, self._ia = names.index("motor.speed"), names.index("motor.angle")
        self._writer = self._write_last          # bound once, not per step
        self.set_eager_outputs(("motor.speed", "motor.angle"))
        self.plant.warm_up()     # JIT load/compile here, not inside the first doStep

    def _write(self, y):
        self.values.update(zip(self._all, y if type(y) is list else y.tolist()))

    def step(self, t, dt):
        v = self.values
        if self.early_return_allowed and not self.plant.joint_inputs:
            return self._step_to_event(t, dt)
        y = self.plant.step(dt, v["motor.torque"], v["brake.command"])   # a new array every step
        v["motor.speed"] = y.item(self._iw)
        v["motor.angle"] = y.item(self._ia)
        self._last = y                   # the snapshot _write_last writes when something reads it
        self.defer_outputs(self._writer)
        return True

    def _step_to_event(self, t, dt):
        """FMI 3.0 with early return allowed: the step ends at the end of the solver step in which the
        brake engages or releases, a rope force reaches or leaves 0 or the rope starts or stops slipping
        (Plant.step_to_event)."""
        v = self.values
        y, t_end, event = self.plant.step_to_event(dt, v["motor.torque"], v["brake.command"])
        if t_end >= t + dt:                  # no event, or at the step's end: a full step
            event = None
        v["motor.speed"] = y.item(self._iw)
        v["motor.angle"] = y.item(self._ia)
        self._last = y
        self.defer_outputs(self._writer)
        if event is None:
            return True
        self.log(f"early return at t = {t_end!r} s (step {t!r} + {dt!r} s): {event}", Fmi2Status.ok)
        return t_end

    def _write_last(self):
        self._write(self._last)

    def get_hidden_state(self):
        return self.plant.get_state()

    def set_hidden_state(self, state):
        self.plant.set_state(state)
