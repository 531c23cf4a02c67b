"""What the bench steps: the plant FMU through fmpy (default) or the same `Plant` in this process.

Both adapters have one interface: `output_names`, `outputs()` (current values, an indexable sequence in
`output_names` order), `step(dt, torque, brake) -> outputs`, `close()`. A failed step raises PlantError.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np


class PlantError(RuntimeError):
    """The plant could not complete a step (solver failure, FMU error status)."""


class InProcessPlant:
    """reeve_fmu.components.plant.Plant in this process (fast tests, no FMU)."""

    kind = "in-process"

    def __init__(self, plant=None, *, scene=None, params: dict | None = None):
        if plant is None:
            plant = make_default_plant(scene, params)
        self.plant = plant
        self.output_names = tuple(plant.output_names)
        od = plant.outputs()
        self._y = np.array([od[n] for n in self.output_names], float)
        self.t = float(plant.t)

    def outputs(self):
        return self._y

    def step(self, dt: float, torque: float, brake: float):
        from ..core.solver import SolverError

        try:
            self._y = self.plant.step(dt, torque, brake)
        except (SolverError, ValueError) as exc:
            raise PlantError(f"plant step at t = {self.t:.6f} s failed: {exc}") from exc
        self.t += dt
        return self._y

    def warm_up(self, dt: float) -> None:
        """One step and back (loads or compiles the numba step path before the clock starts)."""
        s = self.plant.get_state()
        try:
            self.plant.step(dt, 0.0, 0.0)
        finally:
            self.plant.set_state(s)

    def close(self):
        pass

    def describe(self) -> dict:
        return {"kind": self.kind, "scene": getattr(self.plant.scene, "name", None)}


class FmuPlant:
    """The plant FMU (docs/cosim.md, 'pythonfmu and fmpy' item 7: fmpy FMU2Slave, one setReal/doStep/getReal per step).

    Inputs are found by name: `motor.torque` and `brake.command` (the plant FMU of `reeve-fmu build`).
    `motor.torque` is an input of that FMU, not an output; the adapter appends it to the outputs (the
    torque held over the last step) so that results have the same columns as the in-process plant."""

    kind = "fmu"

    def __init__(self, fmu_path, *, start_values: dict | None = None, instance_name: str = "plant",
                 torque_input: str = "motor.torque", brake_input: str = "brake.command"):
        from fmpy.fmi2 import fmi2Real, fmi2ValueReference

        from ..fmu.runner import SlaveHandle

        self.path = Path(fmu_path)
        self.h = SlaveHandle.open(self.path, instance_name)
        try:
            vars_ = self.h.variables
            for name in (torque_input, brake_input):
                if name not in vars_ or vars_[name].causality != "input":
                    raise PlantError(f"{self.path.name}: no input variable {name!r}")
            self.h.setup(0.0, start_values=dict(start_values or {}))
            errs = self.h.errors()
            if errs:
                raise PlantError(f"{self.path.name}: initialization failed\n{self.h.log_text()}")
            outs = [v.name for v in self.h.md.modelVariables if v.causality == "output" and v.type == "Real"]
            self.output_names = tuple(outs) + ((torque_input,) if torque_input not in outs else ())
            self._n = len(outs)
            self._vr_out = (fmi2ValueReference * self._n)(*[self.h.vr(n) for n in outs])
            self._buf = (fmi2Real * self._n)()
            self._vr_in = (fmi2ValueReference * 2)(self.h.vr(torque_input), self.h.vr(brake_input))
            self._in = (fmi2Real * 2)()
            f = self.h.fmu
            self._c = f.component
            self._get, self._set, self._dostep = f.dll.fmi2GetReal, f.dll.fmi2SetReal, f.dll.fmi2DoStep
            self._view = np.ctypeslib.as_array(self._buf)
            self._y = np.zeros(len(self.output_names))
            self._read(0.0)
            self.t = 0.0
        except BaseException:
            self.h.close()
            raise

    def _read(self, torque):
        s = self._get(self._c, self._vr_out, self._n, self._buf)
        if s > 1:
            raise PlantError(f"{self.path.name}: getReal returned status {s}\n{self.h.log_text()}")
        self._y[:self._n] = self._view
        if len(self._y) > self._n:
            self._y[self._n] = torque

    def outputs(self):
        return self._y

    def step(self, dt: float, torque: float, brake: float):
        if not (math.isfinite(torque) and math.isfinite(brake)):
            raise PlantError(f"non-finite plant input (torque {torque!r}, brake {brake!r})")
        self._in[0] = torque
        self._in[1] = brake
        s = self._set(self._c, self._vr_in, 2, self._in)
        if s <= 1:
            s = self._dostep(self._c, self.t, dt, 1)
        if s > 1:
            raise PlantError(f"{self.path.name}: doStep at t = {self.t:.6f} s returned fmi2 status {s}\n"
                             f"{self.h.log_text()[-4000:]}")
        self.t += dt
        self._read(torque)
        return self._y

    def warm_up(self, dt: float) -> None:
        """One doStep and back through get/setFMUstate (the FMU compiles/loads its step path)."""
        f = self.h.fmu
        try:
            state = f.getFMUstate()
        except Exception:
            return                              # FMU without state support: no warm-up
        try:
            self._in[0] = 0.0
            self._in[1] = 0.0
            self._set(self._c, self._vr_in, 2, self._in)
            self._dostep(self._c, self.t, dt, 1)
        finally:
            f.setFMUstate(state)
            f.freeFMUstate(state)
        self._read(0.0)

    def close(self):
        self.h.close()

    def describe(self) -> dict:
        return {"kind": self.kind, "fmu": str(self.path), "model": self.h.md.modelName}


def make_default_plant(scene=None, params: dict | None = None):
    """The in-process twin of the plant FMU: reeve_fmu.components.plant.make_plant (car.load = rated load) of the
    2:1 elevator scene. `params` are plant FMU parameter names ({"car.load": ..., "rope.EA": ...})."""
    from ..components.plant import make_plant
    from ..core.scene import default_scene

    scene = scene if scene is not None else default_scene("elevator_2to1.toml")
    return make_plant(scene, params=params or None)


def default_plant_fmu(dest=None, *, build: bool = True, log=None) -> Path:
    """The demo's plant FMU (reeve_fmu.fmu.cosim.fmu_dir(): $REEVE_FMU_FMUS or fmus/ of the checkout) /
    ReevingPlant.fmu, built, or rebuilt when stale, with reeve_fmu.fmu.cosim.build_plant_fmu."""
    from ..fmu.cosim import PLANT_NAME, build_plant_fmu

    if dest is None:
        from ..fmu.cosim import fmu_dir

        dest = fmu_dir()
    path = Path(dest) / f"{PLANT_NAME}.fmu"
    if build:
        path, built = build_plant_fmu(dest, force=False)
        if built and log is not None:
            log(f"built {path}")
    elif not path.is_file():
        raise FileNotFoundError(f"{path} not found: run `reeve-fmu build`")
    return path
