"""Build step: outputs. Every output is a row (kind, i, j, scale) that the compiled step evaluates
from the state: `car.position`, `<sheave>.tension_in`, `motor.torque`, ..."""
from __future__ import annotations

from dataclasses import dataclass, field

from .elimination import Drive
from .state import BuildState

(OUT_Q, OUT_V, OUT_A, OUT_TENSION, OUT_RATIO, OUT_TORQUE, OUT_QREL, OUT_BRAKE, OUT_BUFFER, OUT_SLIP,
 OUT_FRICTION, OUT_CANGLE, OUT_CSPEED, OUT_JOINT, OUT_TORSION) = range(15)


@dataclass
class Outputs:
    """The output table: names and per output (kind, i, j, scale)."""
    names: list = field(default_factory=list)
    kind: list = field(default_factory=list)
    i: list = field(default_factory=list)
    j: list = field(default_factory=list)
    scale: list = field(default_factory=list)

    def add(self, name, kind, i, j=0, scale=1.0) -> int:
        self.names.append(name), self.kind.append(kind), self.i.append(i), self.j.append(j)
        self.scale.append(scale)
        return len(self.names) - 1


def output_table(bs: BuildState, d: Drive, crp_index: dict, mot_crp: int) -> Outputs:
    """Bodies, sheaves, rope ends, motor, buffers, brake, in that order."""
    o = Outputs()
    scene = bs.scene
    for b in scene.bodies:
        dofs = bs.body_dofs[b.name]
        if b.joint is not None:
            _joint_outputs(o.add, b, dofs)
            continue
        for ax, j in dofs.items():
            if ax == "theta":   # rad, counter-clockwise in the x-z drawing
                o.add(f"{b.name}.angle", OUT_Q, j)
                o.add(f"{b.name}.angular_velocity", OUT_V, j)
                o.add(f"{b.name}.angular_acceleration", OUT_A, j)
                continue
            if ax in ("rx", "ry", "rz"):   # rotation vector from the scene's orientation [rad]
                o.add(f"{b.name}.rotation.{ax[1]}", OUT_Q, j)
                o.add(f"{b.name}.rotation_rate.{ax[1]}", OUT_V, j)
                continue
            suffix = "" if (bs.nd == 1 and len(dofs) == 1) else f".{ax}"
            o.add(f"{b.name}.position{suffix}", OUT_Q, j)
            o.add(f"{b.name}.velocity{suffix}", OUT_V, j)
            o.add(f"{b.name}.acceleration{suffix}", OUT_A, j)
    for sh in scene.sheaves:
        if sh.name in bs.sheave_dof:
            _sheave_outputs(o, bs, sh, crp_index)
    for name, e_first, e_last in bs.rope_end_taps:
        o.add(f"{name}.tension_start", OUT_TENSION, e_first, 0)
        o.add(f"{name}.tension_end", OUT_TENSION, e_last, 1)
    for k, sp in enumerate(bs.torsion):   # torsion spans (builder/torsion.py)
        o.add(f"{sp['rope']}.span{sp['span']}.torque", OUT_TORSION, k, 0)
        o.add(f"{sp['rope']}.span{sp['span']}.twist", OUT_TORSION, k, 1)
    for j, (name, kind) in enumerate(zip(bs.q_names, bs.q_kind)):
        if kind == "twist":
            o.add(name, OUT_Q, j)
    dv = scene.drive
    if dv.kind != "none" and mot_crp >= 0:
        o.add("motor.angle", OUT_CANGLE, mot_crp)
        o.add("motor.speed", OUT_CSPEED, mot_crp)
        o.add("motor.torque", OUT_TORQUE, d.dof, 0, 1.0 / d.gain)
    elif dv.kind != "none":
        o.add("motor.angle", OUT_QREL, d.dof, 0, d.gain)
        o.add("motor.speed", OUT_V, d.dof, 0, d.gain)
        o.add("motor.torque", OUT_TORQUE, d.dof, 0, 1.0 / d.gain)
    for ib, bf in enumerate(scene.buffers):
        o.add(f"{bf.name}.force", OUT_BUFFER, ib)
    if scene.brake.torque > 0 and dv.kind in ("torque", "external"):
        o.add("brake.torque", OUT_BRAKE, d.dof, 0, d.R)
        o.add("brake.engaged", OUT_BRAKE, d.dof, 1, 1.0)
    return o


def _sheave_outputs(o: Outputs, bs: BuildState, sh, crp_index) -> None:
    """Angle and speed of a sheave (slip, creep or rigid rim), its tensions and traction ratio."""
    j = bs.sheave_dof[sh.name]
    if sh.slip:
        jt = bs.slip_info["th"]
        o.add(f"{sh.name}.angle", OUT_QREL, jt, 0, 1.0)
        o.add(f"{sh.name}.speed", OUT_V, jt, 0, 1.0)
        o.add(f"{sh.name}.slip_speed", OUT_SLIP, j, jt, sh.radius)   # rope speed - rim speed
        o.add(f"{sh.name}.slip", OUT_SLIP, j, jt, -sh.radius)        # cumulative slip [m]
        o.add(f"{sh.name}.friction", OUT_FRICTION, j, jt, sh.radius)  # force on the rope [N]
    elif sh.name in crp_index:   # the angle is integrated: R dtheta = -(1 + eps_arriving) ds
        o.add(f"{sh.name}.angle", OUT_CANGLE, crp_index[sh.name])
        o.add(f"{sh.name}.speed", OUT_CSPEED, crp_index[sh.name])
    else:
        o.add(f"{sh.name}.angle", OUT_QREL, j, 0, -1.0 / sh.radius)
        o.add(f"{sh.name}.speed", OUT_V, j, 0, -1.0 / sh.radius)
    taps = bs.tension_taps.get(sh.name, {})
    ti = to = None
    if "in" in taps:
        ti = o.add(f"{sh.name}.tension_in", OUT_TENSION, taps["in"][0], taps["in"][1])
    if "out" in taps:
        to = o.add(f"{sh.name}.tension_out", OUT_TENSION, taps["out"][0], taps["out"][1])
    if sh.kind == "traction" and ti is not None and to is not None:
        o.add(f"{sh.name}.traction_ratio", OUT_RATIO, ti, to)


def _joint_outputs(out, b, dofs):
    """Outputs of a body on a joint: its coordinate, rate, acceleration and the joint torque (force)
    that moves it (the drive's reaction for a prescribed motion)."""
    if b.joint == "revolute":
        j = dofs["angle"]
        out(f"{b.name}.angle", OUT_Q, j)
        out(f"{b.name}.angular_velocity", OUT_V, j)
        out(f"{b.name}.angular_acceleration", OUT_A, j)
        out(f"{b.name}.joint_torque", OUT_JOINT, j)
    else:
        j = dofs["travel"]
        out(f"{b.name}.travel", OUT_Q, j)
        out(f"{b.name}.velocity", OUT_V, j)
        out(f"{b.name}.acceleration", OUT_A, j)
        out(f"{b.name}.joint_force", OUT_JOINT, j)
