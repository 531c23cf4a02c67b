"""The reeving plant as a torque-driven co-simulation component.

`Plant` turns a scene into the model the plant FMU, the monolithic reference run and the CAN bridge
all step: the scene's drive becomes an external motor-torque input on the driven sheave, the brake
command is a second input, and everything else is the core engine (Model/State/Simulator). Its state is
exactly the engine State, so saving and restoring it (FMU get/set/serialize) is copying arrays.

`PLANT_PARAMETERS` are the plant FMU's parameters; `make_plant(scene, params=...)` builds the Plant
for their values (the FMU, the monolithic reference and the HIL bench call it), and
`holding_torques` gives the pre-torque that holds a given load at each landing.
"""
from __future__ import annotations

from dataclasses import replace
import math
from typing import Mapping, Optional, Sequence

import numpy as np

from ..core.kernel import IN_STATUS, IN_TRAC_Z, UE_TORQUE, U_TORQUE
from ..core.model import State, build_model
from ..core.plausibility import check_or_raise
from ..core.scene import Body, Rope, Scene, SceneError, load_scene
from ..core.solver import SolverError, Simulator
from ..core.solver.inputs import kernel_inputs_at
from ..core.solver.statics import consistent_acceleration
from ..core.system import assemble
from .elevator import car_at, check_load, elevator_spec, with_load


def plant_scene(scene: Scene, *, car_load: float = 0.0, rope_EA: float | None = None,
                rope_damping: float | None = None, brake_torque: float | None = None,
                motor_inertia: float | None = None, car_body: str = "car") -> Scene:
    """The scene with an external motor-torque drive (or the hoist speed input, drive.kind
    "speed-input": with_hoist_speed) and the given parameter overrides."""
    if scene.drive.sheave is None:
        raise SceneError(f"{scene.source}: [drive.sheave] a plant needs a driven sheave")
    for name, value in (("car.load", car_load), ("rope.EA", rope_EA), ("rope.damping", rope_damping),
                        ("brake.torque", brake_torque), ("motor.inertia", motor_inertia)):
        if value is not None and (not math.isfinite(value) or value < 0):
            raise ValueError(f"parameter {name} must be a finite number >= 0, got {value}")
    if rope_EA is not None and rope_EA <= 0:
        raise ValueError(f"parameter rope.EA must be > 0, got {rope_EA}")
    bodies = list(scene.bodies)
    if car_load:
        idx = [i for i, b in enumerate(bodies) if b.name == car_body]
        if not idx:
            raise SceneError(f"{scene.source}: no body named {car_body!r} to carry car.load")
        b = bodies[idx[0]]
        bodies[idx[0]] = replace(b, mass=b.mass + car_load)
    ropes = [replace(r, EA=r.EA if rope_EA is None else rope_EA,
                     damping=r.damping if rope_damping is None else rope_damping) for r in scene.ropes]
    drive = replace(scene.drive, kind="speed-input" if scene.drive.kind == "speed-input" else "external",
                    motor_inertia=scene.drive.motor_inertia if motor_inertia is None else motor_inertia)
    brake = scene.brake if brake_torque is None else replace(scene.brake, torque=brake_torque)
    return replace(scene, bodies=tuple(bodies), ropes=tuple(ropes), drive=drive, brake=brake)


def with_joint_input(scene: Scene, body: str, kind: str) -> Scene:
    """The scene with the joint of `body` driven by a Plant input: kind "speed" (the joint rate
    follows the input) or "torque" (the input acts on the joint's inertia; the joint's damping is
    kept)."""
    if kind not in ("speed", "torque"):
        raise ValueError(f"joint input kind must be 'speed' or 'torque', got {kind!r}")
    bodies = list(scene.bodies)
    idx = [i for i, b in enumerate(bodies) if b.name == body and b.joint is not None]
    if not idx:
        raise SceneError(f"{scene.source}: no body named {body!r} on a joint (bodies.joint) to drive")
    b = bodies[idx[0]]
    bodies[idx[0]] = replace(b, motion=replace(b.motion, kind=f"{kind}-input"))
    return replace(scene, bodies=tuple(bodies))


def with_hoist_speed(scene: Scene) -> Scene:
    """The scene with its driven sheave (the hoist drum) following a Plant speed input: the drum's rope
    coordinate is held like a speed-input joint (Plant.step's hoist_speed ramps it over each step)."""
    if scene.drive.sheave is None:
        raise SceneError(f"{scene.source}: [drive.sheave] a hoist speed input needs a driven sheave")
    return replace(scene, drive=replace(scene.drive, kind="speed-input"))


class JointInput:
    """One joint driven by a Plant input. speed: each step writes a one-segment profile into the
    State's prescribed-joint table (the rate ramps linearly from its value at the step start to
    the input at the step end: continuous rate, bounded acceleration, the angle its exact
    integral); torque: the joint's torque table in the State becomes the constant input. A body=None
    input is the hoist speed input (with_hoist_speed): coordinate j, the drum's rope coordinate."""

    def __init__(self, model, body, j=None):
        if body is None:
            self.body, self.kind, self.j = "hoist", "speed", j
        else:
            self.body, self.kind = body.name, body.motion.kind.split("-")[0]
            self.j = model.q_names.index(f"{body.name}.{'angle' if body.joint == 'revolute' else 'travel'}")
        K = model.K
        self.k = list(K.jp_dof if self.kind == "speed" else K.jt_dof).index(self.j)

    def row(self, st: State) -> np.ndarray:
        """The joint's table in st (a view: writing it sets the input)."""
        return (st.jp_prof if self.kind == "speed" else st.jt_tab)[self.k]

    def set(self, st: State, dt: float, value: float) -> None:
        r = self.row(st)
        if self.kind == "torque":
            r[1, :] = value
            return
        x0, v0, t0 = st.q[self.j], st.v[self.j], st.t
        r[:, 0] = (t0, x0, v0, (value - v0) / dt, 0.0)
        r[:, 1] = (t0 + dt, x0 + 0.5 * (v0 + value) * dt, value, 0.0, 0.0)
        r[0, 2:] = 1e300


class Plant:
    """Torque in, outputs out. `step(dt, torque, brake_command)` advances by dt with the inputs
    held; outputs are the engine's output names (`car.position`, `traction.tension_in`, ...).
    Joints whose motion is `speed-input` or `torque-input` (`with_joint_input`) are listed in
    `joint_inputs` ("<body>.speed" or "<body>.torque"); `step(..., joints=[...])` gives their values
    in that order (rad/s or m/s; N m or N)."""

    def __init__(self, scene: Scene | str, **params):
        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        self.scene = plant_scene(scene, **params)
        # physically wrong values (after the parameter overrides) raise here; unusual ones are kept
        # for the FMU log
        self.warnings: list[str] = check_or_raise(self.scene)
        self.model = build_model(self.scene)
        self.sim = Simulator(self.model)
        self.output_names = self.model.output_names
        self._joints = [JointInput(self.model, b) for b in self.scene.bodies
                        if b.joint is not None and b.motion.kind.endswith("-input")]
        self.joint_inputs = tuple(f"{ji.body}.{ji.kind}" for ji in self._joints)
        self._hoist = (JointInput(self.model, None, self.model.drive_dof)
                       if self.scene.drive.kind == "speed-input" else None)
        self.state: State = self.sim.initial_state()
        self._event_index = None      # step_to_event's output indices, found on first use
        self.warnings += self.sim.warnings
        self._y = self.sim.outputs(self.state)

    @property
    def t(self) -> float:
        return self.state.t

    def step(self, dt: float, torque: float, brake_command: float, joints=None, hoist_speed=None) -> np.ndarray:
        """Advance by dt (> 0) with motor torque [N m] and brake command (1 = release, 0 = apply)
        held, and the joint inputs `joints` (see the class); with the hoist speed input
        (with_hoist_speed) `hoist_speed` is the drum's rope-coordinate rate at the step's end [m/s]
        (the torque is then ignored). Returns the outputs. Raises ValueError for bad inputs,
        SolverError if the solver stops (the state is then left at the last good step)."""
        torque, brake_command = float(torque), float(brake_command)
        if not (dt > 0.0 and dt - dt == 0.0 and torque - torque == 0.0 and brake_command - brake_command == 0.0):
            # (x - x == 0.0 is False exactly for NaN and +-inf: one test per step for all inputs)
            if not (dt > 0.0 and math.isfinite(dt)):
                raise ValueError(f"communication step must be a finite number > 0, got {dt}")
            if not math.isfinite(torque):
                raise ValueError(f"motor.torque must be finite, got {torque}")
            raise ValueError(f"brake.command must be finite, got {brake_command}")
        st = self.state
        if joints is not None:
            self._set_joints(st, dt, joints)
        if self._hoist is not None:
            x = float(hoist_speed if hoist_speed is not None else st.v[self._hoist.j])
            if not math.isfinite(x):
                raise ValueError(f"hoist.speed must be finite, got {x}")
            self._hoist.set(st, dt, x)
        self._y = self.sim.step(st, st.t + dt, torque, brake_command).copy()
        return self._y

    def step_to_event(self, dt: float, torque: float, brake_command: float) -> tuple:
        """As step() (no joint inputs), ending early at the end of the first solver step in which an event
        happens: the brake engages or releases (brake.engaged, a first-order lag after the command,
        crosses 1/2: it has no sharper instant), a rope force reaches 0 (slack) or leaves 0 (snap-taut),
        the rope starts or stops slipping on a slipping traction sheave (its groove-friction deflection
        leaves or re-enters the sticking band, |z| <= 0.9 creep: contact._elastoplastic). A drum that runs
        empty stops the solver (SolverError): the step ends at the last solver step before it (the event
        "the solver stops: ..."), and the next step raises the SolverError (no solver step made).
        Returns (outputs, time reached, the event or None). The step is made as by step(); only when
        the watched signs differ at its end is it made again from its start in solver steps to find the
        first one (an event undone within the same step is not seen). Without an event, or when the
        step is one solver step, the result is step()'s bit for bit."""
        if self._joints:
            raise ValueError("step_to_event: this plant has joint inputs; use step()")
        start, y_start = self.state.copy(), self._y
        before = self._indicators(y_start)
        stop = None
        try:
            self.step(dt, torque, brake_command)
        except SolverError as exc:
            stop = self._stopped(start.t, exc)
        after = self._indicators(self._y)
        if after == before:
            return self._y, self.state.t, stop
        n = max(1, math.ceil(dt / self.sim.h - 1e-9))
        if n == 1:                          # one solver step: the event is at its end (no redo)
            return self._y, self.state.t, self._event(before, after)
        self.state, self._y = start, y_start
        t0 = start.t
        for k in range(1, n + 1):
            tk = t0 + dt if k == n else t0 + k * (dt / n)
            try:
                self.step(tk - self.state.t, torque, brake_command)
            except SolverError as exc:
                return self._y, self.state.t, self._stopped(t0, exc)
            self.state.t = tk
            now = self._indicators(self._y)
            if now != before:
                return self._y, tk, self._event(before, now)
        return self._y, self.state.t, None      # an event undone within the step

    def _stopped(self, t0: float, exc: SolverError) -> str:
        """After a SolverError in step_to_event: when a drum ran empty after t0, the outputs at the last
        good solver step (where the state was left) and the event; otherwise the error again."""
        st = self.state
        if int(st.info[IN_STATUS]) != 4 or not st.t > t0:
            raise exc
        self._y = self.sim.outputs(st).copy()
        return f"the solver stops: {exc}"

    def _indicators(self, y) -> tuple:
        """(brake at least half engaged, every rope force > 0, the traction sheave slipping): what
        step_to_event watches. Slipping: the groove-friction deflection the step ended with (the state's
        info) beyond the sticking band 0.9 creep (contact._elastoplastic: linear below, sliding above)."""
        idx = self._event_index
        if idx is None:
            names = self.output_names
            forces = [i for i, n in enumerate(names) if ".tension" in n]
            slip = any(s.slip for s in self.scene.sheaves)
            idx = self._event_index = (names.index("brake.engaged") if "brake.engaged" in names else -1, forces,
                                       0.9 * self.model.K.trac_zmax if slip else -1.0)
        brake, forces, band = idx
        return (brake >= 0 and float(y[brake]) >= 0.5, tuple(float(y[i]) > 0.0 for i in forces),
                band >= 0.0 and abs(float(self.state.info[IN_TRAC_Z])) > band)

    def _event(self, before, now) -> str:
        if before[0] != now[0]:
            return "the brake engages" if now[0] else "the brake releases"
        if before[2] != now[2]:
            sheave = next(s.name for s in self.scene.sheaves if s.slip)
            return f"{sheave} starts to slip" if now[2] else f"{sheave} stops slipping"
        names = [n for n in self.output_names if ".tension" in n]
        changed = [(n, b) for n, a, b in zip(names, before[1], now[1]) if a != b]
        return "; ".join(f"{n} {'snap-taut' if taut else 'slack'}" for n, taut in changed)

    def _set_joints(self, st: State, dt: float, joints) -> None:
        if len(joints) != len(self._joints):
            raise ValueError(f"{len(joints)} joint input(s) given, the plant has {list(self.joint_inputs)}")
        for ji, x, name in zip(self._joints, joints, self.joint_inputs):
            x = float(x)
            if not math.isfinite(x):
                raise ValueError(f"{name} must be finite, got {x}")
            ji.set(st, dt, x)

    def holding_torque(self) -> float:
        """Motor torque [N m] that balances the driven coordinate in the current state (at rest:
        the torque that holds the load)."""
        m, st = self.model, self.state
        ue = kernel_inputs_at(m, st)
        ue[UE_TORQUE] = 0.0
        M, Q = np.empty((m.nq, m.nq)), np.empty(m.nq)
        assemble(m.KJ, st.arrays(), st.c, st.q, st.v, st.t, ue, M, Q)
        return float(-Q[m.K.mot_dof] / m.K.mot_gain)

    def start_with_torque(self, torque: float) -> None:
        """Before the first step: the motor torque acts from t0 on (accelerations and outputs made
        consistent with it), e.g. the holding torque, so that a held load starts at rest."""
        st = self.state
        st.u[U_TORQUE] = float(torque)
        consistent_acceleration(self.model, st)
        self._y = self.sim.outputs(st).copy()

    def warm_up(self) -> None:
        """Load (or compile) the step kernels now with a throw-away step on a copy of the state, so that
        an FMU's first doStep costs what every other one costs (a cold numba cache takes ~40 s here).
        A failure is left to the real step to report."""
        st = self.state.copy()
        try:
            self.sim.step(st, st.t + 1e-4, 0.0, 0.0)
        except Exception:  # noqa: BLE001 - the first real step raises it again, with context
            pass

    def outputs(self) -> dict:
        return dict(zip(self.output_names, self._y.tolist()))

    def output(self, name: str) -> float:
        return float(self._y[self.output_names.index(name)])

    def energy(self):
        return self.sim.energy(self.state)

    # FMU state: builtin types, bit-exact
    def get_state(self) -> dict:
        return {"state": self.state.to_dict(), "y": self._y.tolist()}   # the joint inputs are in the State

    def set_state(self, d: dict):
        self.state = State.from_dict(d["state"])
        self._y = np.array(d["y"], float)


# ---------------------------------------------------------------------------------------------------
# The plant FMU's parameters and the factory the FMU (fmus/reeve_plant_slave.py), the monolithic
# reference and the HIL bench share, so they build the same Plant from the same values.

#: plant FMU parameter -> (Plant keyword, unit, description); all fixed (they change the model)
PLANT_PARAMETERS = {
    "car.load": ("car_load", "kg", "payload in the car (on top of the empty car); default: the rated load of [elevator]"),
    "rope.EA": ("rope_EA", "N", "axial stiffness per rope; a value different from the default sets "
                                "every rope of the scene"),
    "rope.damping": ("rope_damping", "s", "Kelvin-Voigt time constant of the ropes (every rope)"),
    # (not "brake.torque": that is the output of the torque the brake transmits)
    "brake.static_torque": ("brake_torque", "N.m", "total static torque (capacity) of the machine brake"),
    "motor.inertia": ("motor_inertia", "kg.m2", "rotor + traction sheave + brake discs"),
}


def _scene(scene):
    return scene if isinstance(scene, Scene) else load_scene(scene)


def scene_load(scene) -> float:
    """Payload (kg) the scene's car mass includes: [elevator].car_load; 0 for a scene without [elevator]
    (taken as written). `scene`: a Scene or a scene file path."""
    scene = _scene(scene)
    return elevator_spec(scene).car_load if "elevator" in scene.extra else 0.0


def empty_car_scene(scene):
    """The scene with its declared payload ([elevator].car_load) taken out of the car body's mass."""
    scene = _scene(scene)
    return with_load(scene, 0.0) if "elevator" in scene.extra else scene


def plant_defaults(scene) -> dict:
    """Default values of the plant FMU parameters for `scene` (FMU name -> value); car.load: the rated
    load of [elevator] (0 without)."""
    scene = _scene(scene)
    return {
        "car.load": elevator_spec(scene).rated_load if "elevator" in scene.extra else 0.0,
        "rope.EA": float(scene.ropes[0].EA),
        "rope.damping": float(scene.ropes[0].damping),
        "brake.static_torque": float(scene.brake.torque),
        "motor.inertia": float(scene.drive.motor_inertia),
    }


def make_plant(scene, declared_load: float | None = None, params: Optional[Mapping[str, float]] = None):
    """The `Plant` of the plant FMU: `scene` (Scene or path) and FMU parameter values
    {"car.load": kg, "rope.EA": N, ...} (PLANT_PARAMETERS; missing ones take `plant_defaults`).

    `declared_load` is only a consistency check for FMUs built by older versions: when given it must
    equal the scene's [elevator].car_load. Parameters equal to their default leave the scene untouched
    (a scene with ropes of different EA keeps them unless rope.EA is changed)."""
    scene = _scene(scene)
    decl = scene_load(scene)
    if declared_load is not None and abs(float(declared_load) - decl) > 1e-9:
        raise ValueError(f"{scene.source}: the FMU configuration says the car mass includes {declared_load} kg "
                         f"of payload, the scene's [elevator].car_load says {decl} kg")
    params = dict(params or {})
    unknown = set(params) - set(PLANT_PARAMETERS)
    if unknown:
        raise ValueError(f"unknown plant parameters {sorted(unknown)}; known: {sorted(PLANT_PARAMETERS)}")
    defaults = plant_defaults(scene)
    load = float(params.get("car.load", defaults["car.load"]))
    if "elevator" in scene.extra:
        check_load(elevator_spec(scene), load, "car.load")
    kw = {"car_load": load}
    for name, (key, _, _) in PLANT_PARAMETERS.items():
        if name == "car.load":
            continue
        v = params.get(name)
        if v is not None and float(v) != defaults[name]:
            kw[key] = float(v)
    return Plant(empty_car_scene(scene), **kw)


def holding_torques(scene, landings: Sequence[float], load: float,
                    params: Optional[Mapping[str, float]] = None) -> list[float]:
    """Static motor torque (N m) that holds the car with `load` kg of payload at each landing (m): the
    plant's `brake.torque` at rest with the car moved to the landing (the counterweight moved by the same
    distance the other way). This is what a load-weighing device gives the drive as pre-torque.
    `params`: other plant FMU parameters (rope.EA, ...); a car.load in them must equal `load`."""
    scene = _scene(scene)
    params = dict(params or {})
    if "car.load" in params and float(params["car.load"]) != float(load):
        raise ValueError(f"holding_torques: load = {load} kg but params['car.load'] = {params['car.load']} kg")
    params["car.load"] = float(load)
    return [make_plant(car_at(scene, float(x)), None, params).output("brake.torque") for x in landings]
