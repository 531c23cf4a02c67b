"""The crane plant and crane drive FMUs: configuration, build, and an fmpy master for the pair.

* `build_crane_fmus(dest, scene)`: the crane plant FMU of a crane scene (fmus/reeve_crane_slave.py,
  model reeve_fmu.components.craneplant.CranePlant), named by `crane_plant_name` (`CranePlant.fmu` for the
  reference scene scenes/slewing_crane.toml, `Plant_<scene name>.fmu` for any other), and
  `CraneDrive.fmu` (fmus/reeve_cranedrive_slave.py, reeve_fmu.components.cranedrive.CraneDrive);
  `reeve-fmu build --scene <crane scene>` calls it.
* `cosimulate_crane(plant_fmu, drive_fmu, ...)`: a hoist-and-axis cycle (slew, luff or trolley
  travel), Gauss-Seidel (the drive steps first with the plant's speeds at t, then the plant holding
  the drive's new torques).

This module imports only numpy (plus reeve_fmu) at import time: it is vendored into the FMUs.
"""
from __future__ import annotations

import json
import math
import tempfile
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from ..core.results import TimeSeries

CRANE_NAME = "CranePlant"
CRANE_DRIVE_NAME = "CraneDrive"
CRANE_REFERENCE_SCENE = "slewing_crane.toml"   # the scene CRANE_NAME stands for
CRANE_CONFIG = "reeve_crane.json"    # resource of the crane plant FMU (crane_config)
CRANE_SCENE = "scene.toml"
SLEW_MODES = ("torque", "speed")     # the crane plant's Integer parameter slew.input: 0, 1

HOIST_INPUT = ("motor.torque", "Torque", "hoist motor air-gap torque on the reel (positive hoists; used when "
                                         "hoist.input = 0), held over the step")
HOIST_SPEED = ("hoist.speed", "AngularVelocity", "hoist motor speed (positive hoists; used when hoist.input = 1); "
                                                 "the drum's rate ramps linearly to it over the step")
HOIST_INPUTS = (HOIST_INPUT[0], HOIST_SPEED[0])   # in the order of hoist.input's values (0 torque, 1 speed)


def crane_inputs(axes: Sequence[Mapping]) -> dict:
    """The crane plant's inputs, name -> (declared type, description): the hoist motor torque and
    speed, then per axis (craneplant.crane_axes) its torque (force for a prismatic joint) and its
    speed; the Integer parameters hoist.input and <axis>.input choose which one the plant uses."""
    out = {HOIST_INPUT[0]: HOIST_INPUT[1:], HOIST_SPEED[0]: HOIST_SPEED[1:]}
    for a in axes:
        n, b = a["name"], a["body"]
        rev = a["joint"] == "revolute"
        out[f"{n}.{'torque' if rev else 'force'}"] = (
            "Torque" if rev else "Force",
            f"{n} drive {'torque' if rev else 'force'} on the {b}'s joint (used when {n}.input = 0), held over the step")
        out[f"{n}.speed"] = ("AngularVelocity" if rev else "Velocity",
                             f"{n} speed of the {b}'s joint (used when {n}.input = 1); the joint "
                             f"rate ramps linearly to it over the step")
    return out


def axis_input_names(axis: Mapping) -> tuple:
    """The two inputs of an axis in the order of its <axis>.input values (0: torque/force, 1: speed)."""
    n = axis["name"]
    return (f"{n}.{'torque' if axis['joint'] == 'revolute' else 'force'}", f"{n}.speed")


def is_crane_scene(scene) -> bool:
    """A scene the crane plant FMU can be built from (a body on a joint and a hoist drive)."""
    return scene.drive.sheave is not None and any(b.joint is not None for b in scene.bodies)


def crane_output_specs(names: Sequence[str], sheaves: Sequence[str], parts: Mapping[str, str]) -> list:
    """FMI declaration of each crane output (unit or declaredType, description, feed-through).
    Accelerations, rope forces at sheaves and the joint torque react to an input change within an
    arbitrarily short step (declared as depending on all inputs); positions, velocities and angles
    integrate them (no dependency)."""
    derived = {
        "payload.swing_radial": "swing angle of the payload outwards from the slew axis (docs/crane.md)",
        "payload.swing_tangential": "swing angle of the payload in the direction of positive slew (docs/crane.md)",
        "payload.yaw": "heading of the payload's body x axis about the vertical, from the scene's orientation",
    }
    out = []
    for n in names:
        obj, _, q = n.partition(".")
        spec = {"name": n, "unit": None, "type": None, "description": n, "depends": False}
        if n in derived:
            spec.update(type="Angle", description=derived[n])
        elif q.startswith("position."):
            spec.update(type="Position", description=f"{obj} centre of mass, {q[-1]} (z up)")
        elif q.startswith("velocity."):
            spec.update(type="Velocity", description=f"{obj} velocity of the centre of mass, {q[-1]}")
        elif q.startswith("acceleration."):
            spec.update(type="Acceleration", depends=True, description=f"{obj} acceleration, {q[-1]}")
        elif q.startswith("rotation_rate."):
            spec.update(unit="rad/s", description=f"{obj} rate of the rotation vector, {q[-1]}")
        elif q.startswith("rotation."):
            spec.update(type="Angle", description=f"{obj} rotation vector from the scene's orientation, {q[-1]}")
        elif q == "angle":
            spec.update(type="Angle", description=f"{obj} angle" + (" (slew, about the joint axis)" if obj == parts.get("slew") else ""))
        elif q in ("angular_velocity", "speed"):
            spec.update(type="AngularVelocity", description=f"{obj} angular speed")
        elif q == "angular_acceleration":
            spec.update(type="AngularAcceleration", depends=True, description=f"{obj} angular acceleration")
        elif q == "joint_torque":
            spec.update(type="Torque", depends=True, description=f"torque the slew drive applies to {obj}'s joint")
        elif q == "joint_force":
            spec.update(type="Force", depends=True, description=f"force the travel drive applies to {obj}'s joint")
        elif q == "velocity":
            spec.update(type="Velocity", description=f"{obj} speed along its joint axis")
        elif q == "acceleration":
            spec.update(type="Acceleration", depends=True, description=f"{obj} acceleration along its joint axis")
        elif q == "travel":
            spec.update(type="Position", description=f"{obj} travel along its joint axis")
        elif q in ("tension_in", "tension_out"):
            side = "entry" if q == "tension_in" else "exit"
            spec.update(type="Force", depends=obj in sheaves, description=f"rope force at the {side} tangent point of {obj}")
        elif q in ("tension_start", "tension_end"):
            spec.update(type="Force", description=f"rope force at the {q[8:]} of rope {obj}")
        elif n == "hoist.torque":
            spec.update(type="Torque", depends=True,
                        description="hoist motor torque: the torque input, or the torque the speed input needs "
                                    "(positive hoists)")
        elif n in ("motor.angle", "motor.speed"):
            spec.update(type="Angle" if q == "angle" else "AngularVelocity",
                        description=f"hoist motor {q} (positive hoists)")
        else:
            spec.update(unit="1")
        out.append(spec)
    return out


def crane_config(scene_path, name: str = CRANE_NAME) -> dict:
    """The JSON configuration the crane plant FMU carries (resources/reeve_crane.json)."""
    from ..components.craneplant import CranePlant
    from ..core.solver import SolverError
    from .cosim import checked_scene, fmu_config

    scene = checked_scene(scene_path)
    cp = CranePlant(scene, "speed")     # (joints held in the initial statics; the outputs do not depend on it)
    for a in cp.parts["axes"]:
        # <axis>.input starts at 0 (torque/force) where the initial statics holds the joint without
        # one (a slewing jib), else at 1 (speed): a trolley or a boom the rope or gravity pulls on
        try:
            CranePlant(scene, {x["name"]: "torque" if x is a else "speed" for x in cp.parts["axes"]})
            a["start_input"] = 0
        except SolverError:
            a["start_input"] = 1
    return fmu_config("reeve_fmu.crane_fmu/1", name, scene, CRANE_SCENE, parts=cp.parts, holding_torque=cp.holding_torque(),
                      stop_time=float(scene.t_end),
                      outputs=crane_output_specs(cp.output_names, [s.name for s in scene.sheaves], cp.parts))


def _entry(kind: str) -> Path:
    from .cosim import repo_root

    p = repo_root() / "fmus" / f"reeve_{kind}_slave.py"
    if not p.is_file():
        raise FileNotFoundError(f"FMU entry script {p} not found: building FMUs needs a source checkout")
    return p


def crane_plant_name(scene_path, scene=None, name: Optional[str] = None) -> str:
    """The crane plant FMU's model name, the rule of the elevator plant (demo.plant_fmu_name): `name`
    when given (explicit), CranePlant for the reference scene file scenes/slewing_crane.toml as it is,
    Plant_<scene name> for any other scene."""
    from ..core.scene import default_scene, load_scene
    from .cosim import _slug

    if name:
        return name
    if Path(scene_path).resolve() == Path(default_scene(CRANE_REFERENCE_SCENE)).resolve():
        return CRANE_NAME
    return "Plant_" + _slug((scene if scene is not None else load_scene(scene_path)).name)


def build_crane_fmus(dest, scene, *, name: Optional[str] = None, standalone: bool = False,
                     fmi_version: int = 2) -> tuple[Path, Path, dict]:
    """Build the crane plant FMU of `scene` (a path; model name `crane_plant_name`, or `name`) and
    CraneDrive.fmu into dest; returns their paths and the drive parameters sized for the scene (start
    values for CraneDrive.fmu)."""
    from ..components.cranedrive import crane_drive_defaults
    from ..core.scene import load_scene
    from .build import NUMBA, NUMPY, start_builds, start_fmu_build
    from .cosim import _slug

    scene_path = Path(scene)
    name = crane_plant_name(scene_path, name=name)
    if not name.isidentifier() or name == CRANE_DRIVE_NAME:
        raise ValueError(f"crane plant FMU model name {name!r} must be an identifier other than {CRANE_DRIVE_NAME!r}")
    cfg = crane_config(scene_path, name)
    res = {CRANE_SCENE: scene_path.read_bytes(), CRANE_CONFIG: (json.dumps(cfg, indent=1) + "\n").encode()}
    dest = Path(dest)

    def start_plant():
        with tempfile.TemporaryDirectory(prefix="reeve_crane_entry_") as work:
            entry = _entry("crane")
            if name != CRANE_NAME:
                # a unique entry module per model: two FMUs sharing one run each other's code in a process
                copy = Path(work) / f"reeve_crane_{_slug(name)}_slave.py"
                copy.write_bytes(entry.read_bytes())
                entry = copy
            return start_fmu_build(entry, dest, resources=res, standalone=standalone, fmi_version=fmi_version)

    def start_drive():
        return start_fmu_build(_entry("cranedrive"), dest, requirements=(NUMPY, NUMBA), standalone=standalone,
                               fmi_version=fmi_version)

    plant, drive = start_builds([start_plant, start_drive]).finish()     # side by side
    return plant, drive, crane_drive_defaults(load_scene(scene_path), cfg["holding_torque"])


def pendulum_length(scene) -> float:
    """Height of the last sheave's axle above the payload's centre of mass in the scene as written [m]
    (the payload's pendulum length, to the sheave's axle)."""
    from ..components.craneplant import crane_parts
    from ..core.scene import load_scene

    scene = load_scene(scene) if not hasattr(scene, "sheaves") else scene
    p = crane_parts(scene)
    bodies = {b.name: b for b in scene.bodies}
    tip = next(s for s in scene.sheaves if s.name == p["tip"])
    z = float(tip.center[2]) + (float(bodies[tip.body].position[2]) if tip.body in bodies else 0.0)
    return z - float(bodies[p["payload"]].position[2])


def pick_and_place(drive_values: Mapping[str, float], *, lift: Optional[float] = None,
                   move: Optional[float] = None, length: Optional[float] = None, t_start: float = 1.0,
                   settle: float = 15.0) -> tuple[dict, float]:
    """CraneDrive start values for a pick-and-place cycle from the drive's values sized for a scene
    (`<plant>.drive.json`, crane_drive_defaults): hoist `lift` m up (default: the scene's hoist
    travel), then move the first axis by `move` (rad or m; default: the scene's), then lower the same
    `lift`, each S-curve starting when the one before has ended; `settle` s after the lowering. Returns
    (values, end time).

    `length` (the pendulum length at the start, pendulum_length(scene)) shapes the axis move against
    residual sway: with the hoisted length L = length - lift and T = 2 pi sqrt(L / g), the axis
    accelerates and decelerates over T each (speed v = move / (1.5 T), acceleration v / T, jerk ramps
    of T / 10). An acceleration pulse of that shape has no spectral content at 2 pi / T, so a linear
    pendulum (the load seen from its suspension point) is at rest again after each ramp."""
    from ..core.profiles import scurve_phases

    v = dict(drive_values)
    lift = abs(v["hoist.distance"]) if lift is None else float(lift)
    move = v["slew.distance"] if move is None else float(move)
    if length is not None:
        T = 2.0 * math.pi * math.sqrt((length - lift) / 9.81)
        vm = abs(move) / (1.5 * T)
        v.update({"slew.v_max": vm, "slew.a_max": vm / T, "slew.jerk": vm / T / (0.1 * T)})

    def duration(axis, d):
        return sum(scurve_phases(d, v[f"{axis}.v_max"], v[f"{axis}.a_max"], v[f"{axis}.jerk"])[0])
    t_move = t_start + duration("hoist", lift)
    t_lower = t_move + duration("slew", move)
    v.update({"hoist.distance": lift, "hoist.t_start": t_start, "slew.distance": move, "slew.t_start": t_move,
              "hoist.lower": lift, "hoist.t_lower": t_lower})
    return v, t_lower + duration("hoist", lift) + settle


def plant_axes(handle) -> list:
    """The axes (craneplant.crane_axes) of an opened crane plant FMU, from its resources."""
    with open(Path(handle.unzip_dir) / "resources" / CRANE_CONFIG, encoding="utf-8") as fh:
        return json.load(fh)["parts"]["axes"]


AXIS_ALIASES = ("axis.position", "axis.speed", "axis.effort")   # record names for the driven axis's signals


def _axis_signals(axis: Mapping) -> tuple:
    """Position, speed and drive-effort outputs of an axis's joint."""
    b = axis["body"]
    if axis["joint"] == "revolute":
        return f"{b}.angle", f"{b}.angular_velocity", f"{b}.joint_torque"
    return f"{b}.travel", f"{b}.velocity", f"{b}.joint_force"


def cosimulate_crane(plant_fmu, drive_fmu, *, step: float = 5e-3, t_end: float = 30.0, slew_input: str = "speed",
                     drive_values: Optional[Mapping[str, float]] = None, axis: Optional[str] = None,
                     record: Optional[Sequence[str]] = None) -> TimeSeries:
    """Co-simulate a crane plant FMU with CraneDrive.fmu (Gauss-Seidel, communication step `step`, points
    k * step): the drive reads motor.speed and the speed of the plant's axis `axis` (default: its first,
    e.g. slew or travel), the plant takes motor.torque and that axis's torque (force) or speed
    (slew_input) from the drive's slew loop; any other axis of the plant is held at speed 0. The result
    holds the drive's two commands and `record` after every step (from t = step on; default: payload
    swing, yaw and height, the axis's position, speed and drive effort, motor.speed and the tension
    leaving the last sheave; `axis.position`, `axis.speed`, `axis.effort` name the driven axis's
    angle or travel, its speed and its joint torque or force). Raises ValueError naming an axis the plant lacks, CosimError with both
    FMUs' logs if a step fails."""
    from .master import FmuUnit, run
    from .runner import SlaveHandle

    if slew_input not in SLEW_MODES:
        raise ValueError(f"slew_input must be one of {SLEW_MODES}, got {slew_input!r}")
    n = int(math.floor(t_end / step + 1e-9))
    handles = []
    try:
        plant = SlaveHandle.open(plant_fmu, "crane")
        handles.append(plant)
        axes = plant_axes(plant)
        names = [a["name"] for a in axes]
        if axis is not None and axis not in names:
            raise ValueError(f"{Path(plant_fmu).name} has no axis {axis!r} (no inputs {axis}.speed/.torque); "
                             f"its axes: {names}")
        ax = axes[names.index(axis)] if axis is not None else axes[0]
        drive = SlaveHandle.open(drive_fmu, "crane_drive")
        handles.append(drive)
        modes = {f"{a['name']}.input": 1 for a in axes}
        modes[f"{ax['name']}.input"] = SLEW_MODES.index(slew_input)
        plant.setup(0.0, t_end, start_values=modes)
        drive.setup(0.0, t_end, start_values=dict(drive_values or {}))
        _, speed, effort = _axis_signals(ax)
        cmd = "slew.speed" if slew_input == "speed" else "slew.torque"
        target = axis_input_names(ax)[SLEW_MODES.index(slew_input)]
        connections = (("plant.motor.speed", "drive.motor.speed"), (f"plant.{speed}", "drive.slew.angular_velocity"),
                       ("drive.motor.torque", "plant.motor.torque"), (f"drive.{cmd}", f"plant.{target}"))
        if record is None:
            config = Path(plant.unzip_dir) / "resources" / CRANE_CONFIG
            tip = json.loads(config.read_text(encoding="utf-8"))["parts"]["tip"]
            record = ("payload.swing_radial", "payload.swing_tangential", "payload.yaw", "payload.position.z",
                      *_axis_signals(ax), "motor.speed", f"{tip}.tension_out")
        alias = dict(zip(AXIS_ALIASES, _axis_signals(ax)))
        plant_rec = [alias.get(x, x) for x in record]
        recorded = {"drive": ["motor.torque", cmd], "plant": plant_rec}
        r = run([FmuUnit("drive", drive), FmuUnit("plant", plant)], connections, n=n, step=step, grid="multiply",
                record=recorded)
    finally:
        for h in reversed(handles):
            h.close()
    if r.failure is not None:
        raise r.failure
    cols = r.columns(recorded)
    for a, x in zip(record, plant_rec):
        cols[a] = cols[x]
    return TimeSeries(np.arange(n) * step + step, {k: v[1:] for k, v in cols.items()})


def place_position(plant_fmu, distance: float, axis: Optional[str] = None) -> tuple[np.ndarray, np.ndarray]:
    """The payload's centre of mass at rest in the plant FMU's initial state, and the place position of
    a pick and place that moves `axis` (default: the first) by `distance` (rad: turned about the joint
    axis through its pivot; m: moved along the rail): horizontally, the start moved as the suspension
    point moves (the load comes to rest below it); its height, the pick height. That height is exact
    for a slew, which leaves the rope path as it was; a luff or a trolley's travel changes the rope
    path (tower_crane_trolley.toml lifts the load by the lead's lengthening), so only the horizontal
    place holds for them. Opens the FMU once (in this process)."""
    from .runner import SlaveHandle

    with SlaveHandle.open(plant_fmu, "probe") as h:
        with open(Path(h.unzip_dir) / "resources" / CRANE_CONFIG, encoding="utf-8") as fh:
            parts = json.load(fh)["parts"]
        axes = parts["axes"]
        h.setup(0.0, start_values={f"{a['name']}.input": 1 for a in axes})
        start = np.array(h.get_many([f"payload.position.{c}" for c in "xyz"]))
    ax = axes[0] if axis is None else next(a for a in axes if a["name"] == axis)
    k = np.asarray(ax["axis"], float) / np.linalg.norm(ax["axis"])
    S0 = np.asarray(parts["suspension"], float)
    if ax["joint"] == "prismatic":
        S1 = S0 + distance * k
    else:
        from ..components.craneplant import _rotation

        p = np.asarray(ax["pivot"], float)
        S1 = p + _rotation(k, distance) @ (S0 - p)
    move = S1 - S0
    up = start - S0
    up /= np.linalg.norm(up)                 # the vertical (the load hangs below S)
    return start, start + move - up * (move @ up)


def speed_cycle(scene, *, lift: Optional[float] = None, moves: Optional[Mapping[str, float]] = None,
                length: Optional[float] = None, t_start: float = 1.0, settle: float = 15.0) -> tuple[dict, float]:
    """A pick and place by the crane plant's speed inputs alone (hoist.input = 1, every <axis>.input =
    1): hoist `lift` m up (default: the scene's hoist travel), then move every axis at once by `moves`
    (axis name -> rad or m; default: each axis's body motion distance in the scene), then lower `lift`,
    each from the end of the one before, `settle` s after. The moves are shaped against residual sway as
    in pick_and_place, for the hoisted pendulum length (`length`: pendulum_length(scene)). Returns
    ({input name: its speed as a function of time, hoist.speed in motor rad/s}, end time)."""
    from ..components.craneplant import crane_parts
    from ..core.profiles import scurve, scurve_phases
    from ..core.scene import load_scene

    scene = load_scene(scene) if not hasattr(scene, "sheaves") else scene
    dv = scene.drive
    R = next(s.radius for s in scene.sheaves if s.name == dv.sheave) / dv.roping
    lift = abs(dv.distance) if lift is None else float(lift)
    bodies = {b.name: b for b in scene.bodies}
    axes = crane_parts(scene)["axes"]
    moves = {a["name"]: bodies[a["body"]].motion.distance for a in axes} if moves is None else dict(moves)
    T = 2.0 * math.pi * math.sqrt(max(length - lift, 1.0) / 9.81) if length is not None else None

    def move(d, t0, v_max, a_max, jerk):
        if T is not None:
            v_max = abs(d) / (1.5 * T)
            a_max, jerk = v_max / T, v_max / T / (0.1 * T)
        p = scurve(d, v_max, a_max, jerk, t_start=t0)
        return p, t0 + sum(scurve_phases(d, v_max, a_max, jerk)[0])

    up, t1 = scurve(lift, dv.v_max, dv.a_max, dv.jerk, t_start=t_start), t_start + sum(
        scurve_phases(lift, dv.v_max, dv.a_max, dv.jerk)[0])
    prof, t2 = {}, t1
    for a in axes:
        mo = bodies[a["body"]].motion
        prof[f"{a['name']}.speed"], te = move(moves.get(a["name"], 0.0), t1, mo.v_max, mo.a_max, mo.jerk)
        t2 = max(t2, te)
    down = scurve(-lift, dv.v_max, dv.a_max, dv.jerk, t_start=t2)
    t3 = t2 + sum(scurve_phases(lift, dv.v_max, dv.a_max, dv.jerk)[0])
    speeds = {k: (lambda t, p=p: p(t)[1]) for k, p in prof.items()}
    # the hoist: up, then down (rope speed / R: the motor speed, positive hoists)
    speeds["hoist.speed"] = lambda t: (up(t)[1] + down(t)[1]) / R
    return speeds, t3 + settle


def cosimulate_speeds(plant_fmu, speeds: Mapping, *, step: float = 5e-3, t_end: float = 30.0,
                      record: Sequence[str] = ("payload.swing_radial", "payload.swing_tangential")) -> TimeSeries:
    """Drive a crane plant FMU by its speed inputs alone (hoist.input = 1 and every <axis>.input = 1):
    `speeds` maps an input name (hoist.speed, <axis>.speed) to a function of time; each step
    (communication step `step`) sets every speed to its value at the step's end (the plant ramps to it)
    and records `record` and the inputs after it. An input the plant lacks is a ValueError naming it and
    the plant's inputs."""
    from .runner import SlaveHandle

    n = int(math.floor(t_end / step + 1e-9))
    with SlaveHandle.open(plant_fmu, "crane") as h:
        axes = plant_axes(h)
        known = ["hoist.speed"] + [f"{a['name']}.speed" for a in axes]
        bad = sorted(set(speeds) - set(known))
        if bad:
            raise ValueError(f"{Path(plant_fmu).name} has no input {bad[0]!r}; its speed inputs: {known}")
        h.setup(0.0, t_end, start_values={"hoist.input": 1, **{f"{a['name']}.input": 1 for a in axes}})
        rows = []
        for k in range(n):
            t = k * step
            h.set_many({name: float(f(t + step)) for name, f in speeds.items()})
            status = h.do_step(t, step)
            if status != 0:
                log = "; ".join(m.message for m in h.messages)
                raise RuntimeError(f"{Path(plant_fmu).name}: doStep at t = {t:g} s returned {status}: {log}")
            rows.append(h.get_many(list(record) + list(speeds)))
    cols = np.array(rows, float).T if rows else np.zeros((len(record) + len(speeds), 0))
    return TimeSeries(np.arange(n) * step + step, dict(zip(list(record) + list(speeds), cols)))
