"""A slewing crane as a co-simulation component (the crane plant FMU's model).

`CranePlant` wraps `Plant` for a scene with a hoist drive (`[drive] sheave`, the reel), a body on a
revolute joint (the slewing jib) and a hoist rope that ends on a free rigid body (the payload):

* inputs: the hoist motor torque (the drive's `motor.torque` convention: positive hoists) and the
  slew input, a torque or a speed of the jib's joint (chosen when the plant is built);
* outputs: the engine's outputs of the scene (payload position and velocity, rotation vector, jib
  angle/speed/joint torque, rope forces `<sheave>.tension_in/out`, ...) without `motor.torque`, plus
  three derived angles (`DERIVED`). The plant starts at rest with the holding torque applied
  (`holding_torque()`), and `motor.angle`/`motor.speed` are positive when hoisting;

  - `payload.swing_radial`, `payload.swing_tangential` [rad]: the direction of the line from the
    suspension point S to the payload's centre of mass, as angles from the downward vertical measured
    in the vertical planes along e_r and e_t (atan2(d.e_r, -d.e_z), atan2(d.e_t, -d.e_z), d = centre
    of mass - S). S is fixed to the jib, at the height of the last sheave's axle, directly above the
    payload's centre of mass in the initial equilibrium (so both angles start at 0); e_r is the
    horizontal direction from the slew axis to S (outwards), e_t = e_z x e_r (the direction S moves
    in a positive slew), e_z up (against gravity). A load slewed at constant speed w hangs outwards
    at tan(swing_radial) = w^2 r / g (r: radius of its centre of mass) and lags (negative
    swing_tangential) while the slew accelerates;
  - `payload.yaw` [rad]: heading of the payload's body x axis in the horizontal plane, relative to
    the scene's orientation, positive about e_z.
"""
from __future__ import annotations

import math

import numpy as np

from ..core.scene import Scene, SceneError, load_scene
from .plant import Plant, with_joint_input

SLEW_INPUTS = ("torque", "speed")
DERIVED = ("payload.swing_radial", "payload.swing_tangential", "payload.yaw")


def crane_parts(scene: Scene) -> dict:
    """Names of the hoist reel, the slewing body, the payload and the last sheave of the hoist rope;
    SceneError naming the key when the scene is not a slewing crane."""
    src = scene.source
    reel = scene.drive.sheave
    if reel is None:
        raise SceneError(f"{src}: [drive.sheave] a crane plant needs the hoist reel as the driven sheave")
    slew = [b for b in scene.bodies if b.joint == "revolute"]
    if not slew:
        raise SceneError(f"{src}: [[bodies]] a crane plant needs a body on a revolute joint "
                         f"(joint = {{ kind = \"revolute\", ... }}): the slewing jib")
    ropes = [r for r in scene.ropes if any(st.sheave == reel for st in r.route)]
    if not ropes:
        raise SceneError(f"{src}: [[ropes]] no rope runs over the hoist reel {reel!r}")
    route = ropes[0].route
    last = route[-1]
    bodies = {b.name: b for b in scene.bodies}
    payload = bodies.get(last.anchor)
    if payload is None or "rotation" not in payload.free and "z" not in payload.free:
        raise SceneError(f"{src}: ropes.route of {ropes[0].name!r} must end at an anchor on a free body "
                         f"(the payload), got {last.anchor!r}")
    tip = [st.sheave for st in route if st.sheave is not None][-1]
    return {"reel": reel, "slew": slew[0].name, "payload": payload.name, "tip": tip,
            "rope": ropes[0].name}


def _rotation(axis, angle) -> np.ndarray:
    """Rotation matrix of `angle` about the unit `axis` (Rodrigues)."""
    a = np.asarray(axis, float)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


class CranePlant:
    """Hoist torque and slew torque or speed in, crane outputs out (module docstring).
    `step(dt, hoist_torque, slew)` advances by dt with both inputs held (the speed input ramps, see
    plant.JointInput) and returns the outputs (`output_names`)."""

    def __init__(self, scene: Scene | str, slew_input: str = "torque", **params):
        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        if slew_input not in SLEW_INPUTS:
            raise ValueError(f"slew input must be one of {SLEW_INPUTS}, got {slew_input!r}")
        self.parts = parts = crane_parts(scene)
        self.slew_input = slew_input
        self.plant = Plant(with_joint_input(scene, parts["slew"], slew_input), **params)
        self.warnings = self.plant.warnings
        # the hoist convention: positive torque and speed hoist (the engine's sign follows the reeving)
        hold = self.plant.holding_torque()
        self.hoist_sign = 1.0 if hold >= 0.0 else -1.0
        self._hold = abs(hold)
        self.plant.start_with_torque(hold)
        names = list(self.plant.output_names)
        self._flip = [names.index(n) for n in ("motor.angle", "motor.speed") if n in names]
        self._keep = [i for i, n in enumerate(names) if n != "motor.torque"]
        self.output_names = tuple(names[i] for i in self._keep) + DERIVED
        self._setup_geometry(self.plant.scene, names)
        self._y = self._outputs(self.plant._y)

    def _setup_geometry(self, scene, names) -> None:
        p = self.parts
        bodies = {b.name: b for b in scene.bodies}
        jib = bodies[p["slew"]]
        g = np.asarray(scene.gravity, float)
        self._ez = -g / np.linalg.norm(g)
        self._axis, self._pivot = np.asarray(jib.joint_axis, float), np.asarray(jib.pivot, float)
        tip = next(s for s in scene.sheaves if s.name == p["tip"])
        centre = np.asarray(tip.center, float) + (np.asarray(jib.position, float) if tip.body == jib.name else 0.0)
        pay = p["payload"]
        self._i_pos = [names.index(f"{pay}.position.{c}") for c in "xyz"]
        self._i_rot = [names.index(f"{pay}.rotation.{c}") for c in "xyz"]
        self._i_ang = names.index(f"{p['slew']}.angle")
        y0 = self.plant._y
        com = y0[self._i_pos]
        ez = self._ez
        # S: above the initial centre of mass at the tip axle's height (relative to the pivot, at angle 0)
        S = com + ez * ((centre - com) @ ez)
        rot0 = _rotation(self._axis, float(y0[self._i_ang]))
        self._S0 = rot0.T @ (S - self._pivot)
        if np.linalg.norm(self._S0 - ez * (self._S0 @ ez)) < 1e-9:
            raise SceneError(f"{scene.source}: the payload hangs on the slew axis of {p['slew']!r}: "
                             f"the radial swing direction is undefined")

    def _outputs(self, y) -> np.ndarray:
        y = y.copy()
        y[self._flip] *= self.hoist_sign
        ez = self._ez
        rot = _rotation(self._axis, float(y[self._i_ang]))
        S = self._pivot + rot @ self._S0
        er = S - self._pivot
        er = er - ez * (er @ ez)
        er /= np.linalg.norm(er)
        et = np.cross(ez, er)
        d = y[self._i_pos] - S
        down = -(d @ ez)
        phi = y[self._i_rot]
        R = _rotation(phi / np.linalg.norm(phi), np.linalg.norm(phi)) if phi.any() else np.eye(3)
        x_body = R[:, 0]
        ex = np.cross(np.array([0.0, 1.0, 0.0]) if abs(ez[1]) < 0.9 else np.array([1.0, 0.0, 0.0]), ez)
        ex /= np.linalg.norm(ex)          # the horizontal reference of the heading (x for z up)
        ey = np.cross(ez, ex)
        derived = (math.atan2(d @ er, down), math.atan2(d @ et, down),
                   math.atan2(x_body @ ey, x_body @ ex))
        return np.concatenate((y[self._keep], derived))

    @property
    def t(self) -> float:
        return self.plant.t

    def step(self, dt: float, hoist_torque: float, slew: float) -> np.ndarray:
        """Advance by dt with the hoist motor torque [N m] (positive hoists) and the slew torque
        [N m] or speed [rad/s] held; returns the outputs. ValueError for bad inputs, SolverError
        if the solver stops (state left at the last good step)."""
        y = self.plant.step(dt, self.hoist_sign * hoist_torque, 0.0, (slew,))
        self._y = self._outputs(y)
        return self._y

    def warm_up(self) -> None:
        self.plant.warm_up()

    def outputs(self) -> dict:
        return dict(zip(self.output_names, self._y.tolist()))

    def output(self, name: str) -> float:
        return float(self._y[self.output_names.index(name)])

    def holding_torque(self) -> float:
        """Hoist motor torque [N m] that holds the payload at rest in the initial state (the plant
        starts with it applied)."""
        return self._hold

    def get_state(self) -> dict:
        return {"plant": self.plant.get_state(), "y": self._y.tolist()}

    def set_state(self, d: dict) -> None:
        self.plant.set_state(d["plant"])
        self._y = np.array(d["y"], float)
