"""A slewing crane as a co-simulation component (the crane plant FMU's model).

`CranePlant` wraps `Plant` for a scene with a hoist drive (`[drive] sheave`, the reel), bodies on
joints (slewing jib, luffing boom, trolley) and a hoist rope that ends on a free rigid body (the payload):

* inputs: the hoist motor torque (the drive's `motor.torque` convention: positive hoists) or, with
  hoist="speed", the hoist motor speed (the drum ramps to it over each step), and, per body on a joint
  (also one on a joint on a moving body: a trolley on the slewing jib), one *axis* input, a torque
  (force) or a speed of that joint (chosen per axis when the plant is built). The axes are named by
  role (`crane_axes`): `slew` (revolute about the vertical), `luff` (revolute about a horizontal
  axis), `travel` (prismatic); a second joint of the same role is named after its body;
* outputs: the engine's outputs of the scene (payload position and velocity, rotation vector, jib
  angle/speed/joint torque, rope forces `<sheave>.tension_in/out`, ...) with `motor.torque` named
  `hoist.torque` (the torque input, or the torque the speed input needs), plus three derived angles
  (`DERIVED`). The plant starts at rest with the holding torque applied (`holding_torque()`), and
  `motor.angle`/`motor.speed`/`hoist.torque` are positive when hoisting;

  - `payload.swing_radial`, `payload.swing_tangential` [rad]: the direction of the line from the
    suspension point S to the payload's centre of mass, as angles from the downward vertical measured
    in the vertical planes along e_r and e_t (atan2(d.e_r, -d.e_z), atan2(d.e_t, -d.e_z), d = centre
    of mass - S). S is fixed to the *frame* body (the last sheave's body when it is on a joint, else
    the first body on a joint), at the height of the last sheave's axle, directly above the payload's
    centre of mass in the initial equilibrium (so both angles start at 0); e_r is the horizontal
    direction from a revolute frame's joint axis to S (outwards; for a prismatic frame the horizontal
    direction of its rail), e_t = e_z x e_r (the direction S moves in a positive slew), e_z up
    (against gravity); a frame on a joint on a moving body carries S through both joints, e_r
    pointing away from its parent's axis. A load slewed at constant speed w hangs outwards
    at tan(swing_radial) = w^2 r / g (r: radius of its centre of mass) and lags (negative
    swing_tangential) while the slew accelerates;
  - `payload.yaw` [rad]: heading of the payload's body x axis in the horizontal plane, relative to
    the scene's orientation, positive about e_z.
"""
from __future__ import annotations

import math

import numpy as np

from ..core.scene import Scene, SceneError, load_scene
from ..core.solver import SolverError
from .plant import Plant, with_hoist_speed, with_joint_input

SLEW_INPUTS = ("torque", "speed")      # the modes of an axis input (its Integer parameter <axis>.input: 0, 1)
DERIVED = ("payload.swing_radial", "payload.swing_tangential", "payload.yaw")


def crane_axes(scene: Scene) -> list:
    """The joint inputs of a crane scene, one per body on a joint in scene order: dicts with `name`
    (the role: "slew" for a revolute joint about the vertical, "luff" for a revolute joint about a
    horizontal axis, "travel" for a prismatic joint; the body's name when the role is taken),
    `body`, `joint` ("revolute" or "prismatic"), `axis`, `pivot`, `range` (the joint's range or None)."""
    g = np.asarray(scene.gravity, float)
    ez = -g / np.linalg.norm(g)
    axes, taken = [], set()
    for b in scene.bodies:
        if b.joint is None:
            continue
        if b.joint == "prismatic":
            role = "travel"
        else:
            a = np.asarray(b.joint_axis, float)
            role = "slew" if abs(a @ ez) > (1.0 - 1e-9) * np.linalg.norm(a) else "luff"
        name = b.name if role in taken else role
        taken.add(name)
        axes.append({"name": name, "body": b.name, "joint": b.joint, "axis": [float(x) for x in b.joint_axis],
                     "pivot": [float(x) for x in b.pivot],
                     "range": None if b.joint_range is None else [float(x) for x in b.joint_range]})
    return axes


def crane_parts(scene: Scene) -> dict:
    """Names of the hoist reel, the axes (`crane_axes`), the frame body that carries the suspension
    point, the payload and the last sheave of the hoist rope (plus `slew`: the slewing body, when
    there is one; CranePlant adds `suspension`, the suspension point at t = 0); SceneError naming the
    key when the scene is not a crane."""
    src = scene.source
    reel = scene.drive.sheave
    if reel is None:
        raise SceneError(f"{src}: [drive.sheave] a crane plant needs the hoist reel as the driven sheave")
    axes = crane_axes(scene)
    if not axes:
        raise SceneError(f"{src}: [[bodies]] a crane plant needs a body on a joint "
                         f"(joint = {{ kind = \"revolute\" | \"prismatic\", ... }}): the jib, boom or trolley")
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
    tip_body = next(s.body for s in scene.sheaves if s.name == tip)
    jointed = [a["body"] for a in axes]
    frame = tip_body if tip_body in jointed else jointed[0]
    parts = {"reel": reel, "axes": axes, "frame": frame, "payload": payload.name, "tip": tip,
             "rope": ropes[0].name}
    slew = [a["body"] for a in axes if a["name"] == "slew"]
    if slew:
        parts["slew"] = slew[0]
    return parts


def _rotation(axis, angle) -> np.ndarray:
    """Rotation matrix of `angle` about the unit `axis` (Rodrigues)."""
    a = np.asarray(axis, float)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def _modes(axes, inputs) -> dict:
    """{axis name: "torque" | "speed"} from one mode for all axes or a mapping per axis name."""
    names = [a["name"] for a in axes]
    if isinstance(inputs, str):
        inputs = {n: inputs for n in names}
    unknown = sorted(set(inputs) - set(names))
    if unknown:
        raise ValueError(f"crane plant: no axis {unknown[0]!r} in this scene; its axes: {names}")
    modes = {n: inputs.get(n, "torque") for n in names}
    for n, m in modes.items():
        if m not in SLEW_INPUTS:
            raise ValueError(f"{n}.input must be one of {SLEW_INPUTS}, got {m!r}")
    return modes


class CranePlant:
    """Hoist torque and one torque (force) or speed per axis in, crane outputs out (module
    docstring). `step(dt, hoist_torque, axes)` advances by dt with the inputs held (a speed input
    ramps, see plant.JointInput) and returns the outputs (`output_names`); `axes` is one value per
    axis in `input_names` order (a single number for a one-axis crane)."""

    def __init__(self, scene: Scene | str, inputs="torque", hoist="torque", **params):
        if not isinstance(scene, Scene):
            scene = load_scene(scene)
        self.parts = parts = crane_parts(scene)
        self.axes = parts["axes"]
        self.modes = _modes(self.axes, inputs)
        if hoist not in SLEW_INPUTS:
            raise ValueError(f"hoist.input must be one of {SLEW_INPUTS}, got {hoist!r}")
        self.hoist_mode = hoist
        self.slew_input = self.modes[self.axes[0]["name"]]
        sc = with_hoist_speed(scene) if hoist == "speed" else scene
        for a in self.axes:
            sc = with_joint_input(sc, a["body"], self.modes[a["name"]])
        try:
            self.plant = Plant(sc, **params)
        except SolverError as e:
            free = [f"{a['name']}.input = 0 leaves the joint of {a['body']!r} free" for a in self.axes
                    if self.modes[a["name"]] == "torque"]
            if not free:
                raise
            # a torque (force) input starts at 0: nothing holds a joint the rope pulls on
            raise SolverError(f"{e}; {', '.join(free)} in the initial statics (no torque or force holds "
                              f"it against the rope): use the speed input (<axis>.input = 1)") from e
        # the plant's joint inputs follow the scene's body order, like crane_axes
        assert self.plant.joint_inputs == tuple(f"{a['body']}.{self.modes[a['name']]}" for a in self.axes)
        self.input_names = tuple(f"{a['name']}.{self._unit_word(a)}" for a in self.axes)
        self._ranges = [(i, a) for i, a in enumerate(self.axes)
                        if a["range"] is not None and self.modes[a["name"]] == "speed"]
        self._jq = [self.plant.model.q_names.index(f"{a['body']}.{'angle' if a['joint'] == 'revolute' else 'travel'}")
                    for a in self.axes]
        self.warnings = self.plant.warnings
        # the hoist convention: positive torque and speed hoist (the engine's sign follows the reeving)
        hold = self.plant.holding_torque()
        self.hoist_sign = 1.0 if hold >= 0.0 else -1.0
        self._hold = abs(hold)
        self.plant.start_with_torque(hold)
        self._gain = float(self.plant.model.K.mot_gain)    # motor angle per unit of the drum's coordinate
        names = list(self.plant.output_names)
        self._flip = [names.index(n) for n in ("motor.angle", "motor.speed", "motor.torque") if n in names]
        # the motor torque is an input name: its output (the torque input, or the torque the hoist
        # speed input needs) is hoist.torque
        self.output_names = tuple("hoist.torque" if n == "motor.torque" else n for n in names) + DERIVED
        self._setup_geometry(self.plant.scene, names)
        self._y = self._outputs(self.plant._y)

    def _unit_word(self, a) -> str:
        m = self.modes[a["name"]]
        return "force" if m == "torque" and a["joint"] == "prismatic" else m

    def _setup_geometry(self, scene, names) -> None:
        p = self.parts
        bodies = {b.name: b for b in scene.bodies}
        frame = bodies[p["frame"]]
        g = np.asarray(scene.gravity, float)
        self._ez = ez = -g / np.linalg.norm(g)
        tip = next(s for s in scene.sheaves if s.name == p["tip"])
        centre = np.asarray(tip.center, float) + (np.asarray(frame.position, float) if tip.body == frame.name else 0.0)
        pay = p["payload"]
        self._i_pos = [names.index(f"{pay}.position.{c}") for c in "xyz"]
        self._i_rot = [names.index(f"{pay}.rotation.{c}") for c in "xyz"]
        y0 = self.plant._y
        com = y0[self._i_pos]
        # S: above the initial centre of mass at the tip axle's height
        S = com + ez * ((centre - com) @ ez)
        p["suspension"] = S.tolist()      # at t = 0 (the FMU's configuration carries it: place_position)
        self._chain = None
        if frame.parent is not None:      # the frame on a joint on a moving body (a trolley on the jib)
            self._setup_chain(scene, frame, bodies[frame.parent], names, S)
            return
        self._prismatic = frame.joint == "prismatic"
        self._axis, self._pivot = np.asarray(frame.joint_axis, float), np.asarray(frame.pivot, float)
        self._i_ang = names.index(f"{frame.name}.{'travel' if self._prismatic else 'angle'}")
        if self._prismatic:
            self._S0 = S - self._axis * float(y0[self._i_ang])
            er = self._axis - ez * (self._axis @ ez)
            if np.linalg.norm(er) < 1e-9:
                raise SceneError(f"{scene.source}: the rail of {frame.name!r} is vertical: "
                                 f"the radial swing direction is undefined")
            self._er = er / np.linalg.norm(er)
            return
        rot0 = _rotation(self._axis, float(y0[self._i_ang]))
        self._S0 = rot0.T @ (S - self._pivot)
        if np.linalg.norm(self._S0 - ez * (self._S0 @ ez)) < 1e-9:
            raise SceneError(f"{scene.source}: the payload hangs on the joint axis of {frame.name!r}: "
                             f"the radial swing direction is undefined")

    def _setup_chain(self, scene, frame, parent, names, S) -> None:
        """Suspension point and outward direction of a frame body on a joint on a moving body: S fixed
        to the frame (its scene-pose position S_ref), turned or moved by the frame's joint and then by its
        parent's; outwards is away from the parent's axis (a revolute parent), else along its rail."""
        def joint(b):
            return (b.joint == "prismatic", np.asarray(b.joint_axis, float), np.asarray(b.pivot, float),
                    names.index(f"{b.name}.{'travel' if b.joint == 'prismatic' else 'angle'}"))
        self._chain = (joint(frame), joint(parent))
        y0 = self.plant._y
        x = S
        for prism, a, piv, i in reversed(self._chain):     # undo the parent's motion, then the frame's
            x = x - a * float(y0[i]) if prism else piv + _rotation(a, -float(y0[i])) @ (x - piv)
        self._S0 = x

    def _chain_frame(self, y):
        ez = self._ez
        S = self._S0
        for prism, a, piv, i in self._chain:               # the frame's joint, then the parent's
            S = S + a * float(y[i]) if prism else piv + _rotation(a, float(y[i])) @ (S - piv)
        prism, a, piv, i = self._chain[1]
        er = self._chain[0][1] if prism else S - piv
        er = er - ez * (er @ ez)
        return S, er / np.linalg.norm(er)

    def _frame(self, q):
        """Suspension point S and the horizontal outward direction e_r at frame coordinate q."""
        ez = self._ez
        if self._prismatic:
            return self._S0 + self._axis * q, self._er
        S = self._pivot + _rotation(self._axis, q) @ self._S0
        er = S - self._pivot
        er = er - ez * (er @ ez)
        return S, er / np.linalg.norm(er)

    def _outputs(self, y) -> np.ndarray:
        y = y.copy()
        y[self._flip] *= self.hoist_sign
        ez = self._ez
        S, er = self._chain_frame(y) if self._chain is not None else self._frame(float(y[self._i_ang]))
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
        return np.concatenate((y, derived))

    @property
    def t(self) -> float:
        return self.plant.t

    def step(self, dt: float, hoist_torque: float, axes) -> np.ndarray:
        """Advance by dt with the hoist input (motor torque [N m], or with hoist="speed" the motor speed
        [rad/s] the drum ramps to over the step; positive hoists) and the axis inputs (torque [N m] /
        force [N] or speed [rad/s, m/s], `input_names` order) held; returns the outputs. ValueError
        naming the input for a bad value (not finite, or a speed that would take a joint with a range
        past its end within the step), SolverError if the solver stops (state left at the last good
        step)."""
        vals = (axes,) if np.ndim(axes) == 0 else tuple(axes)
        st = self.plant.state
        for i, a in self._ranges:
            v = float(vals[i])
            x = st.q[self._jq[i]] + 0.5 * (st.v[self._jq[i]] + v) * dt
            lo, hi = a["range"]
            if not lo <= x <= hi:
                raise ValueError(f"{self.input_names[i]} = {v!r} would take {a['body']}'s joint to {x:.6g}, "
                                 f"outside its range [{lo:g}, {hi:g}] (joint.range of the scene)")
        if self.hoist_mode == "speed":
            w = float(hoist_torque)
            if not math.isfinite(w):
                raise ValueError(f"hoist.speed must be finite, got {w}")
            y = self.plant.step(dt, 0.0, 0.0, vals, hoist_speed=self.hoist_sign * w / self._gain)
        else:
            y = self.plant.step(dt, self.hoist_sign * hoist_torque, 0.0, vals)
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
