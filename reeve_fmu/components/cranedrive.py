"""A two-axis crane drive: hoist and slew speed loops with jerk-limited references.

Each axis follows an S-curve of its position (hoist: payload travel in m, positive up; slew: jib
angle in rad) with a PI speed controller, an inertia feed-forward J * alpha_ref and a torque limit.
The hoist adds the holding torque as pre-torque (its integrator starts there), so the payload does
not sag when the loop closes. The controllers sample the measured speeds at the start of each
communication step and hold their torques over it (no direct feed-through). `slew.speed` is the slew
reference speed at the end of the step, for a plant driven by a slew speed input.

`PARAMETERS` are the crane drive FMU's parameters; `crane_drive_defaults(scene, holding_torque)` sizes
them from a crane scene.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from ..core.profiles import scurve

#: parameter -> (unit, description); the crane drive FMU's parameters (all fixed)
PARAMETERS = {
    "hoist.distance": ("m", "hoist travel of the payload (positive up)"),
    "hoist.v_max": ("m/s", "hoist speed limit of the reference"),
    "hoist.a_max": ("m/s2", "hoist acceleration limit of the reference"),
    "hoist.jerk": ("m/s3", "hoist jerk of the reference"),
    "hoist.t_start": ("s", "start time of the hoist reference"),
    "hoist.radius": ("m", "reel radius: rope speed = radius * motor speed"),
    "hoist.inertia": ("kg.m2", "inertia the hoist feed-forward assumes (motor side)"),
    "hoist.holding_torque": ("N.m", "pre-torque that holds the payload at rest"),
    "hoist.kp": ("N.m.s/rad", "hoist speed-loop proportional gain"),
    "hoist.ki": ("N.m/rad", "hoist speed-loop integral gain"),
    "hoist.torque_max": ("N.m", "hoist torque limit (both directions)"),
    "slew.distance": ("rad", "slew angle of the reference"),
    "slew.v_max": ("rad/s", "slew speed limit of the reference"),
    "slew.a_max": ("rad/s2", "slew acceleration limit of the reference"),
    "slew.jerk": ("rad/s3", "slew jerk of the reference"),
    "slew.t_start": ("s", "start time of the slew reference"),
    "slew.inertia": ("kg.m2", "inertia the slew feed-forward assumes"),
    "slew.kp": ("N.m.s/rad", "slew speed-loop proportional gain"),
    "slew.ki": ("N.m/rad", "slew speed-loop integral gain"),
    "slew.torque_max": ("N.m", "slew torque limit (both directions)"),
    "hoist.lower": ("m", "lowering of the payload after the hoist travel (pick and place; 0: none)"),
    "hoist.t_lower": ("s", "start time of the lowering (same speed, acceleration and jerk limits)"),
}


@dataclass
class CraneDriveParams:
    """Defaults: scenes/slewing_crane.toml (reel 0.3 m, 2500 kg payload, 12 m jib of 2.88e5 kg m^2);
    speed-loop crossovers about 5 rad/s (hoist, below the 16 rad/s axial rope mode) and 2 rad/s (slew)."""
    hoist_distance: float = 3.0
    hoist_v_max: float = 0.5
    hoist_a_max: float = 0.3
    hoist_jerk: float = 0.5
    hoist_t_start: float = 2.0
    hoist_radius: float = 0.3
    hoist_inertia: float = 245.0       # reel 20 + payload 2500 * 0.3^2
    hoist_holding_torque: float = 0.0
    hoist_kp: float = 1250.0
    hoist_ki: float = 1500.0
    hoist_torque_max: float = 2.0e4
    slew_distance: float = 0.6
    slew_v_max: float = 0.1
    slew_a_max: float = 0.05
    slew_jerk: float = 0.05
    slew_t_start: float = 1.0
    slew_inertia: float = 2.88e5
    slew_kp: float = 6.0e5
    slew_ki: float = 3.0e5
    slew_torque_max: float = 2.0e5
    hoist_lower: float = 0.0
    hoist_t_lower: float = 0.0

    @classmethod
    def from_values(cls, values: dict) -> "CraneDriveParams":
        """From FMU parameter names ("hoist.kp": ...); unknown names raise ValueError naming them."""
        kw = {}
        for name, v in values.items():
            if name not in PARAMETERS:
                raise ValueError(f"unknown crane drive parameter {name!r}; known: {sorted(PARAMETERS)}")
            v = float(v)
            if not math.isfinite(v):
                raise ValueError(f"crane drive parameter {name} must be finite, got {v}")
            kw[name.replace(".", "_")] = v
        return cls(**kw)

    def values(self) -> dict:
        return {k.replace("_", ".", 1): v for k, v in asdict(self).items()}


class _Moves:
    """The sum of S-curve moves (distance, t_start) with the same limits: position, speed, acceleration."""

    def __init__(self, moves, v_max, a_max, jerk):
        self.profs = [scurve(d, v_max, a_max, jerk, t_start=t0) for d, t0 in moves]

    def __call__(self, t):
        if len(self.profs) == 1:
            return self.profs[0](t)
        return tuple(sum(c) for c in zip(*(p(t) for p in self.profs)))


class _Axis:
    """One speed loop: reference profile of the axis position (unit per motor radian: `ratio`)."""

    def __init__(self, moves, v_max, a_max, jerk, ratio, inertia, kp, ki, tmax, pre):
        self.prof = _Moves(moves, v_max, a_max, jerk)
        self.ratio, self.J, self.kp, self.ki, self.tmax = ratio, inertia, kp, ki, tmax
        self.integral = pre          # integrator state, N m
        self.torque = pre

    def tick(self, t, dt, speed):
        _, v, a = self.prof(t)
        w_ref, alpha = v / self.ratio, a / self.ratio
        e = w_ref - speed
        raw = self.integral + self.kp * e + self.J * alpha
        tq = min(max(raw, -self.tmax), self.tmax)
        if tq == raw:               # anti-windup: integrate only while not limited
            self.integral += self.ki * e * dt
        self.torque = tq
        return tq


class CraneDrive:
    """`step(t, dt, hoist_speed, slew_speed)` -> (hoist torque, slew torque, slew speed reference)."""

    def __init__(self, params: CraneDriveParams | None = None):
        P = self.params = params or CraneDriveParams()
        if not P.hoist_radius > 0.0:
            raise ValueError(f"hoist.radius must be > 0, got {P.hoist_radius}")
        hoist = [(P.hoist_distance, P.hoist_t_start)] + ([(-P.hoist_lower, P.hoist_t_lower)] if P.hoist_lower else [])
        self.hoist = _Axis(hoist, P.hoist_v_max, P.hoist_a_max, P.hoist_jerk, P.hoist_radius, P.hoist_inertia, P.hoist_kp, P.hoist_ki, P.hoist_torque_max,
                           P.hoist_holding_torque)
        self.slew = _Axis([(P.slew_distance, P.slew_t_start)], P.slew_v_max, P.slew_a_max, P.slew_jerk, 1.0, P.slew_inertia, P.slew_kp, P.slew_ki, P.slew_torque_max, 0.0)
        self.slew_speed_ref = 0.0

    def step(self, t: float, dt: float, hoist_speed: float, slew_speed: float):
        th = self.hoist.tick(t, dt, hoist_speed)
        ts = self.slew.tick(t, dt, slew_speed)
        self.slew_speed_ref = float(self.slew.prof(t + dt)[1])
        return th, ts, self.slew_speed_ref

    def references(self, t: float) -> dict:
        xh, vh, _ = self.hoist.prof(t)
        xs, vs, _ = self.slew.prof(t)
        return {"hoist.position_ref": float(xh), "hoist.velocity_ref": float(vh),
                "slew.angle_ref": float(xs), "slew.speed_ref": float(vs)}

    def get_state(self) -> dict:
        return {"hi": self.hoist.integral, "ht": self.hoist.torque, "si": self.slew.integral,
                "st": self.slew.torque, "sr": self.slew_speed_ref}

    def set_state(self, d: dict) -> None:
        self.hoist.integral, self.hoist.torque = d["hi"], d["ht"]
        self.slew.integral, self.slew.torque = d["si"], d["st"]
        self.slew_speed_ref = d["sr"]


def crane_drive_defaults(scene, holding_torque: float) -> dict:
    """Crane drive parameters sized from the scene: reel radius, inertias, holding torque (the hoist's
    torque limit at least 1.5 times it), and the
    scene's hoist and first axis's profiles as the references (the drive's slew loop drives the
    scene's first axis, craneplant.crane_axes: a slew, a luff or a trolley's travel; for a prismatic
    axis its inertia is the body's mass)."""
    from .craneplant import crane_parts   # here, not at the top: the crane drive FMU loads no plant

    p = crane_parts(scene)
    v = CraneDriveParams().values()
    reel = next(s for s in scene.sheaves if s.name == p["reel"])
    bodies = {b.name: b for b in scene.bodies}
    jib, pay = bodies[p["axes"][0]["body"]], bodies[p["payload"]]
    v["hoist.radius"] = reel.radius
    v["hoist.inertia"] = reel.inertia + scene.drive.motor_inertia + pay.mass * reel.radius ** 2
    v["hoist.holding_torque"] = float(holding_torque)
    # a hoist motor that can hold the load and accelerate it: at least 1.5 x the holding torque
    v["hoist.torque_max"] = max(v["hoist.torque_max"], 1.5 * abs(float(holding_torque)))
    v["slew.inertia"] = jib.inertia if jib.joint == "revolute" else jib.mass
    dv = scene.drive
    if dv.kind == "speed" and dv.profile == "s-curve":     # the scene's hoist: rope hauled in = up
        v.update({"hoist.distance": -dv.distance, "hoist.v_max": dv.v_max, "hoist.a_max": dv.a_max,
                  "hoist.jerk": dv.jerk, "hoist.t_start": dv.t_start})
    mo = jib.motion
    if mo is not None and mo.kind == "profile":
        v.update({"slew.distance": mo.distance, "slew.v_max": mo.v_max, "slew.a_max": mo.a_max,
                  "slew.jerk": mo.jerk, "slew.t_start": mo.t_start})
    return v
