"""Elevator data of a scene: rated load, the payload its car mass includes, landings; the car with a given
load; drive sizing from the rated load, speed, roping and sheave.

A scene describes an elevator with an ``[elevator]`` table (docs/studies.md)::

    [elevator]
    rated_load = 1000.0      # kg
    car_load = 1000.0        # kg of payload included in bodies.<car>.mass of this file
    max_load = 1250.0        # kg, structural limit of the car (default 125 % of rated_load)
    landings = [0.0, 39.0]   # m, car positions (default: start position and start + drive.distance)
    car = "car"              # body names (defaults shown)
    counterweight = "counterweight"

Every study takes the payload explicitly (`with_load(scene, load)`): the car body's mass becomes
``mass - car_load + load``. Nothing depends on the scene's name.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
import math

from ..core.scene import Scene, SceneError

G = 9.81

#: speed-loop crossover of the reference drive (R1: Kp = 970 N m s/rad on 28 kg m²): Kp = J * OMEGA_C
OMEGA_C = 970.0 / 28.0
#: speed PI integral time (set by the torque path's lag and dead time, not by the inertia)
TI_SPEED = 0.127
#: design margin of torque and power limits over the largest torque a rated trip needs
SIZING_MARGIN = 1.25


@dataclass(frozen=True)
class ElevatorSpec:
    rated_load: float                 # kg
    car_load: float                   # kg of payload in the scene's car mass
    max_load: float                   # kg, structural limit
    landings: tuple                   # m
    car: str = "car"
    counterweight: str = "counterweight"
    rated_speed: float = 1.0          # m/s car (scene drive.v_max)
    roping: float = 1.0
    sheave_radius: float = 0.1        # m, driven sheave


def elevator_spec(scene: Scene) -> ElevatorSpec:
    """The scene's [elevator] table, validated; SceneError naming the key otherwise."""
    src = scene.source
    el = scene.extra.get("elevator")
    if el is None:
        raise SceneError(f"{src}: no [elevator] table: an elevator study needs rated_load and car_load (kg of "
                         f"payload included in the car body's mass); see docs/studies.md")
    if not isinstance(el, dict):
        raise SceneError(f"{src}: [elevator] must be a table")
    allowed = {"rated_load", "car_load", "max_load", "landings", "car", "counterweight"}
    unknown = sorted(set(el) - allowed)
    if unknown:
        raise SceneError(f"{src}: [elevator] unknown key(s) {', '.join(map(repr, unknown))}; allowed: "
                         f"{', '.join(sorted(allowed))}")

    def num(key, default=None, nonneg=True):
        if key not in el:
            if default is None:
                raise SceneError(f"{src}: [elevator] missing required key '{key}'")
            return default
        v = el[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (nonneg and v < 0):
            raise SceneError(f"{src}: [elevator.{key}] must be a finite number >= 0, got {v!r}")
        return float(v)

    rated = num("rated_load")
    if rated <= 0:
        raise SceneError(f"{src}: [elevator.rated_load] must be > 0, got {rated:g}")
    car_load = num("car_load")
    max_load = num("max_load", SIZING_MARGIN * rated)
    names = {}
    bodies = {b.name: b for b in scene.bodies}
    for key in ("car", "counterweight"):
        v = el.get(key, key)
        if not isinstance(v, str) or v not in bodies:
            raise SceneError(f"{src}: [elevator.{key}] names no body of the scene: {v!r}; bodies: "
                             f"{', '.join(sorted(bodies))}")
        names[key] = v
    car = bodies[names["car"]]
    if not car.mass - car_load > 0:
        raise SceneError(f"{src}: [elevator.car_load] = {car_load:g} kg is not less than the car mass "
                         f"bodies.{car.name}.mass = {car.mass:g} kg")
    z0 = float(car.position[2])
    lands = el.get("landings", [z0, z0 + scene.drive.distance])
    if (not isinstance(lands, list) or len(lands) < 2
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in lands)):
        raise SceneError(f"{src}: [elevator.landings] must be a list of at least two positions (m), got {lands!r}")
    if scene.drive.sheave is None:
        raise SceneError(f"{src}: [drive.sheave] an elevator needs a driven (traction) sheave")
    R = next(s.radius for s in scene.sheaves if s.name == scene.drive.sheave)
    return ElevatorSpec(rated_load=rated, car_load=car_load, max_load=max_load,
                        landings=tuple(float(x) for x in lands), car=names["car"],
                        counterweight=names["counterweight"], rated_speed=float(scene.drive.v_max),
                        roping=float(scene.drive.roping), sheave_radius=float(R))


def check_load(spec: ElevatorSpec, load, what: str = "load") -> float:
    """The load as a float, or ValueError naming it when negative, not finite or above max_load."""
    if isinstance(load, bool) or not isinstance(load, (int, float)) or not math.isfinite(load) or load < 0:
        raise ValueError(f"{what} = {load!r}: the payload must be a finite number of kg >= 0")
    if load > spec.max_load * (1 + 1e-12):
        raise ValueError(f"{what} = {load:g} kg exceeds the structural limit of the car, elevator.max_load = "
                         f"{spec.max_load:g} kg ({100 * spec.max_load / spec.rated_load:.0f} % of the rated "
                         f"load {spec.rated_load:g} kg)")
    return float(load)


def with_load(scene: Scene, load: float) -> Scene:
    """The scene with `load` kg of payload in the car (and elevator.car_load = load)."""
    spec = elevator_spec(scene)
    load = check_load(spec, load)
    bodies = tuple(replace(b, mass=b.mass - spec.car_load + load) if b.name == spec.car else b
                   for b in scene.bodies)
    extra = dict(scene.extra)
    extra["elevator"] = {**scene.extra["elevator"], "car_load": load}
    return replace(scene, bodies=bodies, extra=extra)


def car_at(scene: Scene, z: float) -> Scene:
    """The scene with the car moved to position z and the counterweight moved by the same distance the
    other way (same roping on both sides)."""
    spec = elevator_spec(scene)
    car = next(b for b in scene.bodies if b.name == spec.car)
    d = float(z) - float(car.position[2])

    def moved(b):
        s = {spec.car: d, spec.counterweight: -d}.get(b.name)
        if not s:
            return b
        p = b.position
        return replace(b, position=(p[0], p[1], p[2] + s))
    return replace(scene, bodies=tuple(moved(b) for b in scene.bodies))


def _route_length(scene: Scene, rope) -> float:
    """Polyline length through the route's anchor points and sheave centres (an estimate, m)."""
    bodies = {b.name: b.position for b in scene.bodies}
    sheaves = {s.name: s for s in scene.sheaves}
    pts = []
    for st in rope.route:
        if st.sheave is not None:
            s = sheaves[st.sheave]
            base = bodies[s.body] if s.body else (0.0, 0.0, 0.0)
            pts.append(tuple(b + c for b, c in zip(base, s.center)))
        else:
            base = bodies[st.anchor] if st.anchor != "ground" else (0.0, 0.0, 0.0)
            pts.append(tuple(b + c for b, c in zip(base, st.at)))
    return sum(math.dist(a, b) for a, b in zip(pts, pts[1:]))


def inertia_at_motor(scene: Scene, load: float) -> float:
    """Inertia the machine sees, kg m²: motor + sheaves + car and counterweight at (R/roping)² + all rope
    mass at the rim radius (an upper bound: rope near the hitches moves slower)."""
    spec = elevator_spec(scene)
    R, r = spec.sheave_radius, spec.roping
    m = {b.name: b.mass for b in with_load(scene, load).bodies}
    J = scene.drive.motor_inertia
    J += sum(s.inertia * (R / s.radius) ** 2 for s in scene.sheaves)
    J += (m[spec.car] + m[spec.counterweight]) * (R / r) ** 2
    J += sum(rp.count * rp.rhoA * _route_length(scene, rp) for rp in scene.ropes) * R * R
    return J


def size_drive(scene: Scene, holding_rated: tuple) -> dict:
    """Drive parameters (DriveParams field names) sized for the scene's elevator.

    `holding_rated`: the static motor torque that holds the car with the rated load at the lowest and the
    highest landing (N m; the plant's statics, `plant.holding_torques`). The empty car's holding
    torque follows by linearity, minus rated_load * g * R / roping. The largest torque of a rated trip is
    |holding| + J a_max roping / R over {empty, rated} x {lowest, highest landing}; torque and power
    limits are SIZING_MARGIN times it (and it times the rated motor speed); the speed PI keeps the
    reference drive's crossover OMEGA_C (Kp = J OMEGA_C) and integral time; the feed-forward inertia is
    the inertia at the rated load."""
    spec = elevator_spec(scene)
    R, r = spec.sheave_radius, spec.roping
    dv = scene.drive
    dT = spec.rated_load * G * R / r
    J_rated = inertia_at_motor(scene, spec.rated_load)
    J_empty = inertia_at_motor(scene, 0.0)
    alpha = dv.a_max * r / R
    need = max(max(abs(h) for h in holding_rated) + J_rated * alpha,
               max(abs(h - dT) for h in holding_rated) + J_empty * alpha)
    w_rated = dv.v_max * r / R
    return {"sheave_radius": R, "roping": r, "J_ff": J_rated, "T_max": SIZING_MARGIN * need,
            "P_max": SIZING_MARGIN * need * w_rated, "Kp": J_rated * OMEGA_C, "Ti": TI_SPEED, "Kpos": 2.0,
            "v_max": dv.v_max, "a_max": dv.a_max, "jerk": dv.jerk,
            "brake_static_torque": (0.5 * scene.brake.torque, 0.5 * scene.brake.torque)}
