"""FMU entry of the crane plant (FMI 2.0 co-simulation): `reeve-fmu build --scene <crane scene>` ->
CranePlant.fmu.

Inputs  motor.torque [N.m] (hoist motor on the reel, positive hoists), slew.torque [N.m] or slew.speed
        [rad/s] of the jib's joint (the fixed parameter slew.input selects: 0 torque, 1 speed; the
        other input is ignored), all held over the communication step (the speed as a linear ramp
        from its previous value).
Outputs the engine's outputs of the scene (payload position/velocity, jib angle/speed/joint torque,
        rope forces <sheave>.tension_in/out, ...) plus payload.swing_radial, payload.swing_tangential
        and payload.yaw (reeve_fmu.components.craneplant, docs/crane.md).

The scene and the output declarations come from the FMU's resources (scene.toml, reeve_crane.json,
written by reeve_fmu.fmu.crane.crane_config). A solver failure is logged through the FMU logger and the
step returns fmi2Discard; further steps are refused until the master restores a state or resets.
"""
import json

from reeve_fmu.fmu.crane import CRANE_CONFIG, CRANE_INPUTS, SLEW_MODES
from reeve_fmu.fmu.slave import DefaultExperiment, Fmi2Status, ReeveSlave


class CranePlantSlave(ReeveSlave):
    description = "Slewing crane (ALE rope model, reeve_fmu): hoist and slew inputs, payload sway out"

    def define(self):
        with open(self.resource_path(CRANE_CONFIG), encoding="utf-8") as fh:
            cfg = json.load(fh)
        self.config = cfg
        self.modelName = cfg["name"]
        self.description = f"{type(self).description}; scene {cfg['scene_name']}: {cfg['scene_description']}"
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=cfg["stop_time"], step_size=5e-3)
        for name, (typ, desc) in CRANE_INPUTS.items():
            start = cfg["holding_torque"] if name == "motor.torque" else 0.0
            self.add_real(name, "input", declared_type=typ, start=start, description=desc)
        self.add_integer("slew.input", "parameter", "fixed", start=0, min=0, max=1,
                         description="slew input: 0 = slew.torque, 1 = slew.speed")
        self.add_real("hoist.holding_torque", "calculatedParameter", "fixed", declared_type="Torque",
                      getter=lambda: cfg["holding_torque"],
                      description="hoist motor torque that holds the payload at rest in the initial state")
        self._names = []
        for o in cfg["outputs"]:
            self.add_real(o["name"], "output", unit=o["unit"], declared_type=o["type"],
                          description=o["description"],
                          dependencies=list(CRANE_INPUTS) if o["depends"] else ())
            self._names.append(o["name"])
        self.add_output_arrays()      # FMI 3.0: payload.position, .rotation, ... (x, y, z); sheaves.*
        self.crane = None

    def initialize(self):
        from reeve_fmu.components.craneplant import CranePlant

        mode = SLEW_MODES[int(self.values["slew.input"])]
        self._cmd = f"slew.{mode}"
        self.crane = CranePlant(self.resource_path(self.config["scene"]), mode)
        if list(self.crane.output_names) != self._names:
            raise RuntimeError("the crane model's outputs differ from the declared ones (resources out of date?)")
        for w in self.crane.warnings:
            self.log(w, Fmi2Status.warning)
        self._write(self.crane._y)
        self.crane.warm_up()

    def _write(self, y):
        self.values.update(zip(self._names, y.tolist()))

    def step(self, t, dt):
        v = self.values
        self._write(self.crane.step(dt, v["motor.torque"], v[self._cmd]))
        return True

    def get_hidden_state(self):
        return self.crane.get_state()

    def set_hidden_state(self, state):
        self.crane.set_state(state)
