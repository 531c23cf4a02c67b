"""FMU entry of the crane plant (FMI 2.0 co-simulation): `reeve-fmu build --scene <crane scene>` ->
CranePlant.fmu.

Inputs  motor.torque [N.m] or hoist.speed [rad/s] (hoist motor on the reel, positive hoists; the fixed
        parameter hoist.input selects: 0 torque, 1 speed) and per axis (a body on a joint: slew, luff,
        travel; reeve_fmu.components.craneplant.crane_axes) <axis>.torque [N.m] (force [N] for a
        prismatic joint) or <axis>.speed [rad/s, m/s] (the fixed parameter <axis>.input selects: 0
        torque/force, 1 speed; the other input is ignored), all held over the communication step
        (a speed as a linear ramp from its previous value).
Outputs the engine's outputs of the scene (payload position/velocity, jib angle/speed/joint torque,
        rope forces <sheave>.tension_in/out, ...) plus payload.swing_radial, payload.swing_tangential
        and payload.yaw (reeve_fmu.components.craneplant, docs/crane.md).

The scene and the output declarations come from the FMU's resources (scene.toml, reeve_crane.json,
written by reeve_fmu.fmu.crane.crane_config). A solver failure is logged through the FMU logger and the
step returns fmi2Discard; further steps are refused until the master restores a state or resets.
"""
import json

from reeve_fmu.fmu.crane import CRANE_CONFIG, HOIST_INPUTS, SLEW_MODES, axis_input_names, crane_inputs
from reeve_fmu.fmu.slave import DefaultExperiment, Fmi2Status, ReeveSlave


class CranePlantSlave(ReeveSlave):
    description = "Slewing crane (ALE rope model, reeve_fmu): hoist and slew inputs, payload sway out"

    def define(self):
        with open(self.resource_path(CRANE_CONFIG), encoding="utf-8") as fh:
            cfg = json.load(fh)
        self.config = cfg
        self.modelName = cfg["name"]
        names = [a["name"] for a in cfg["parts"]["axes"]]
        what = type(self).description if names == ["slew"] else \
            f"Crane (ALE rope model, reeve_fmu): hoist and {' and '.join(names)} inputs, payload sway out"
        self.description = f"{what}; scene {cfg['scene_name']}: {cfg['scene_description']}"
        self.default_experiment = DefaultExperiment(start_time=0.0, stop_time=cfg["stop_time"], step_size=5e-3)
        self._axes = cfg["parts"]["axes"]
        inputs = crane_inputs(self._axes)
        for name, (typ, desc) in inputs.items():
            start = cfg["holding_torque"] if name == "motor.torque" else 0.0
            self.add_real(name, "input", declared_type=typ, start=start, description=desc)
        self.add_integer("hoist.input", "parameter", "fixed", start=0, min=0, max=1,
                         description=f"hoist input: 0 = {HOIST_INPUTS[0]}, 1 = {HOIST_INPUTS[1]}")
        for a in self._axes:
            n, (first, second) = a["name"], axis_input_names(a)
            self.add_integer(f"{n}.input", "parameter", "fixed", start=a.get("start_input", 0), min=0, max=1,
                             description=f"{n} input: 0 = {first}, 1 = {second}")
        self.add_real("hoist.holding_torque", "calculatedParameter", "fixed", declared_type="Torque",
                      getter=lambda: cfg["holding_torque"],
                      description="hoist motor torque that holds the payload at rest in the initial state")
        self._names = []
        for o in cfg["outputs"]:
            self.add_real(o["name"], "output", unit=o["unit"], declared_type=o["type"],
                          description=o["description"],
                          dependencies=list(inputs) if o["depends"] else ())
            self._names.append(o["name"])
        self.add_output_arrays()      # FMI 3.0: payload.position, .rotation, ... (x, y, z); sheaves.*
        self.crane = None

    def initialize(self):
        from reeve_fmu.components.craneplant import CranePlant

        modes = {a["name"]: SLEW_MODES[int(self.values[f"{a['name']}.input"])] for a in self._axes}
        self._cmd = [axis_input_names(a)[SLEW_MODES.index(modes[a["name"]])] for a in self._axes]
        self._hoist = HOIST_INPUTS[int(self.values["hoist.input"])]
        self.crane = CranePlant(self.resource_path(self.config["scene"]), modes, SLEW_MODES[int(self.values["hoist.input"])])
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
        self._write(self.crane.step(dt, v[self._hoist], [v[c] for c in self._cmd]))
        return True

    def get_hidden_state(self):
        return self.crane.get_state()

    def set_hidden_state(self, state):
        self.crane.set_state(state)
