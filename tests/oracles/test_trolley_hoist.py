"""A winch on a joint on a moving body: the tower crane whose trolley carries its own hoist drum
(scenes/tower_crane_trolley_hoist.toml; the trolley on a prismatic joint on the slewing jib, the load
hanging from the drum), against the mechanics written here: the rope the drum winds = the change of the
rope path while the jib slews and the trolley travels (rigid limit); the drum's holding torque R x the
rope's tension (= the load's weight) and a traction sheave's R x its tension difference; the trolley's
rail force m w^2 r plus the rope's pull along the rail and the slewing torque (I_jib + m r^2 + J_zz)
alpha plus the rope's moment during a prescribed slew; the energy of a free swing with the drum held;
the angular momentum of a jib whose trolley's drum (axis along the slew axis) is spun by its motor; and
the scenes refused with the key."""
import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from reeve_fmu.core.geometry import tangent, wrap_angle
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene, parse_scene
from reeve_fmu.core.solver import Simulator
from tests.support.checks import check, check_min

SCENE = "scenes/tower_crane_trolley_hoist.toml"
G = 9.81
AT = np.array([0.0, 0.0, 0.5])      # the rope's anchor on the box, from its centre of mass


def _rot(axis, ang):
    """Rotation matrix of ang about the unit axis (Rodrigues)."""
    a = np.asarray(axis, float)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(ang) * K + (1.0 - math.cos(ang)) * (K @ K)


def _scene(EA_factor=1000.0, jib=None, trolley=None, **rope):
    """The shipped scene with a weightless rope (forces at the drum; EA_factor x stiffer), the drum
    held (its hoist not started), the box a point mass (its rope anchor AT above its centre), the
    jib's and trolley's motions replaced if given."""
    sc = load_scene(SCENE)
    r = replace(sc.ropes[0], rhoA=1e-6, damping=0.0, EA=EA_factor * sc.ropes[0].EA, **rope)
    motions = {"jib": jib, "trolley": trolley}
    bodies = tuple(replace(b, free=("x", "y", "z"), inertia=0.0) if b.name == "payload" else
                   b if motions.get(b.name) is None else replace(b, motion=motions[b.name]) for b in sc.bodies)
    return replace(sc, ropes=(r,), bodies=bodies, drive=replace(sc.drive, t_start=1e3))


def _anchor(y):
    return np.array([y["payload.position.x"], y["payload.position.y"], y["payload.position.z"]]) + AT


def _held(b):
    """A joint's profile that never starts: the joint is locked."""
    return replace(b.motion, t_start=1e3)


def test_holding_torque_is_the_rope_tension_times_the_radius():
    """At rest (initial statics) the drum on the trolley holds the load: the rope's tension at the drum
    is the load's weight (a weightless rope), the drive torque R x that tension, and the rail takes no
    force (the fall hangs plumb)."""
    sc = _scene()
    m = build_model(sc)
    sim = Simulator(m)
    y = dict(zip(m.output_names, sim.outputs(sim.initial_state())))
    W = 3000.0 * G
    R = sc.sheaves[0].radius
    S = y["drum.tension_out"]
    # measured 1.0e-8: the rope's own weight (1e-6 kg/m)
    check("drum tension / load weight - 1", S / W - 1.0, 1e-7)
    # measured 3.5e-7 = eps / 2: the drum counts its rope coordinate as unstretched material
    check("drive torque / (R x tension) - 1", -y["motor.torque"] / (R * S) - 1.0, 3.5e-6)
    check_min("holding torque [N m]", -y["motor.torque"], 1.0e4)
    # measured 1.5e-12 N
    check("trolley.joint_force [N]", y["trolley.joint_force"], 1.5e-11,
          reason="round-off: 7.4e-13 to 1.7e-12 N as the scene's numbers change")


def test_holding_torque_with_the_rope_weight_forty_metres_up():
    """The shipped rope (1.2 kg/m) on the drum 40 m up: the drive holds R x the tension at the drum
    (the load and the hanging rope's weight) with the same eps/2 as a weightless rope. The stored rope
    weighs at the drum; without its weight the torque came out 1.5 % low (the paid-out rope gained
    its weight from z = 0)."""
    sc = load_scene(SCENE)
    sc = replace(sc, drive=replace(sc.drive, t_start=1e3))
    m = build_model(sc)
    sim = Simulator(m)
    y = dict(zip(m.output_names, sim.outputs(sim.initial_state())))
    R, S = sc.sheaves[0].radius, y["drum.tension_out"]
    check_min("hanging rope's weight in the drum tension [N]", S - 3000.0 * G, 300.0)   # measured 353 N
    eps = S / (sc.ropes[0].EA * sc.ropes[0].count)
    # measured 1.2e-8 (the rope's strain varies along the span: eps/2 is that of the drum end)
    check("drive torque / (R x tension) - 1 - eps/2", -y["motor.torque"] / (R * S) - 1.0 - eps / 2, 1.1e-7)


def _path(sc, th, u, anc):
    """The rope from a trolley-fixed point on the drum to the load's anchor: the wound-off arc and the
    span, for the jib at angle th and the trolley travel u (geometry.tangent, wrap_angle)."""
    jib, tr, dr = sc.bodies[0], sc.bodies[1], sc.sheaves[0]
    p = np.asarray(jib.pivot)
    Rj = _rot(jib.joint_axis, th)
    c = p + Rj @ (np.asarray(tr.position) + u * np.asarray(tr.joint_axis) + np.asarray(dr.center) - p)
    a = Rj @ np.asarray(dr.axis)
    T, _ = tangent(c, dr.radius, a, -1.0, anc, 0.0, None, 1.0)
    ref = c + dr.radius * (Rj @ np.array([-1.0, 0.0, 0.0]))
    return dr.radius * wrap_angle(c, a, -1.0, ref, T) + float(np.linalg.norm(anc - T))


def test_slew_loads_rail_and_slewing_drive_with_trolley_drum_and_rope():
    """The jib slews 0.6 rad with the trolley locked 20 m out and the drum held; the load swings. A
    frictionless rope of tension S acts on a coordinate q with -S dP/dq, P the rope path (_path,
    differenced with the load held). At every output the rail holds the trolley (900 kg with its drum)
    against m w^2 r and the rope: joint_force = S dP/du - m w^2 r; the slewing drive gives
    (I_jib + m r^2 + J_zz) alpha + S dP/dtheta (the drum held: its spin does not load the slew)."""
    sc0 = load_scene(SCENE)
    jib, tr = sc0.bodies[0], sc0.bodies[1]
    sc = _scene(trolley=_held(tr))
    res = Simulator(build_model(sc)).run(14.0, 0.05)
    r = float(np.linalg.norm((np.asarray(tr.position) - np.asarray(jib.pivot))[:2]))
    I_jib, m, Jzz = jib.inertia, tr.mass, tr.inertia[2][2]
    h = 1e-6
    rail, slew = [], []
    for k in range(len(res.time)):
        y = {n: res[n][k] for n in res.names}
        th = y["jib.angle"]
        anc = _anchor(y)
        S = y["drum.tension_out"]
        dPu = (_path(sc, th, h, anc) - _path(sc, th, -h, anc)) / (2 * h)
        dPth = (_path(sc, th + h, 0.0, anc) - _path(sc, th - h, 0.0, anc)) / (2 * h)
        rail.append(y["trolley.joint_force"] + m * y["jib.angular_velocity"] ** 2 * r - S * dPu)
        slew.append(y["jib.joint_torque"] - (I_jib + m * r ** 2 + Jzz) * y["jib.angular_acceleration"] - S * dPth)
    check_min("slew [rad]", res["jib.angle"][-1], 0.59)
    swing = res["payload.position.y"] - 20.35 * np.sin(res["jib.angle"])
    check_min("load swing across the jib [m]", np.max(np.abs(swing)), 1.0)
    check_min("rail force [N]", np.max(np.abs(res["trolley.joint_force"])), 500.0)
    check_min("slewing torque [N m]", np.max(np.abs(res["jib.joint_torque"])), 1e5)
    # measured 2.1e-4 N of the 2.4 kN rail force and 4.2e-4 N m of the 2.7e5 N m slewing torque (round-off
    # of a 14 s spatial run; the load swings 6.2 m across the jib)
    check("rail force: joint_force + m w^2 r - S dP/du [N]", np.array(rail), 2.1e-3,
          reason="round-off of a 14 s spatial run, which moves with the float operations (2.1e-4 to 2.2e-4 N)")
    check("slewing torque: tau - (I_jib + m r^2 + J_zz) alpha - S dP/dtheta [N m]", np.array(slew), 3.5e-3)


def test_drum_on_the_travelling_trolley_winds_the_rope_path():
    """The shipped motion (slew 0.6 rad, travel 10 m, hoist 5 m), rope 1000 x stiffer (the rigid limit):
    the rope the drum winds (R x its angle relative to the trolley) equals the change of the rope path
    from a trolley-fixed point on the drum to the load (_path at the jib's angle and the trolley's
    travel): the wound rope ends at the current tangent point of a drum that slews and travels; the
    travel itself winds nothing."""
    sc = replace(_scene(), drive=load_scene(SCENE).drive)
    res = Simulator(build_model(sc)).run(18.0, 0.05)
    P = np.array([_path(sc, res["jib.angle"][k], res["trolley.travel"][k], _anchor({n: res[n][k] for n in res.names}))
                  for k in range(len(res.time))])
    wound = sc.sheaves[0].radius * (res["drum.angle"] - res["drum.angle"][0])   # sigma - sigma0 = -R angle
    check_min("jib slew [rad]", res["jib.angle"][-1], 0.59)
    check_min("trolley travel [m]", res["trolley.travel"][-1], 9.9)
    check_min("rope wound [m]", -(P[-1] - P[0]), 4.9)
    # measured 4.3e-6 m over 5.0 m wound, the 0.6 rad slew and 10 m of travel (the stiff rope's strain changes)
    check("path change + rope wound [m]", (P - P[0]) - wound, 4e-5)


def test_free_swing_with_the_drum_held_conserves_energy():
    """The jib free on its bearing, pushed by 1e5 N m for 2 s, then left alone; the trolley free on its
    rail (it slides out as the jib turns); the drum held by its drive; the load swings. From the end of
    the push the energy is constant: 1/2 I_jib w^2 + 1/2 m (u_dot^2 + r^2 w^2) + 1/2 J_zz w^2 (trolley)
    + 1/2 M v^2 + M g z (load) + S^2 L0 / (2 EA) (the rope's strain energy: S the span's tension, L0 its
    unstretched length). The rope starts at the load's weight (no statics)."""
    sc0 = load_scene(SCENE)
    jib, tr = sc0.bodies[0], sc0.bodies[1]
    push = replace(jib.motion, kind="torque", torque=((0.0, 1e5), (2.0, 1e5), (2.01, 0.0), (30.0, 0.0)))
    free = replace(tr.motion, kind="free")
    EA = sc0.ropes[0].EA
    sc = _scene(1.0, jib=push, trolley=free, length=60.0 + 30.0 / (1.0 + 3000.0 * G / EA))
    sc = replace(sc, statics="none", solver=replace(sc.solver, rho_inf=1.0))   # no numerical damping
    res = Simulator(build_model(sc)).run(12.0, 0.01)
    w, u, ud = res["jib.angular_velocity"], res["trolley.travel"], res["trolley.velocity"]
    r = 20.0 + u
    v2 = sum(res[f"payload.velocity.{c}"] ** 2 for c in "xyz")
    S = res["drum.tension_out"]
    dr = sc.sheaves[0]
    L = []
    for k in range(len(res.time)):
        y = {n: res[n][k] for n in res.names}
        Rj = _rot(jib.joint_axis, y["jib.angle"])
        p = np.asarray(jib.pivot)
        c = p + Rj @ (np.asarray(tr.position) + y["trolley.travel"] * np.asarray(tr.joint_axis) - p)
        anc = _anchor(y)
        T, _ = tangent(c, dr.radius, Rj @ np.asarray(dr.axis), -1.0, anc, 0.0, None, 1.0)
        L.append(float(np.linalg.norm(anc - T)))
    L0 = np.array(L) / (1.0 + S / EA)
    E = (0.5 * jib.inertia * w ** 2 + 0.5 * tr.mass * (ud ** 2 + r ** 2 * w ** 2) + 0.5 * tr.inertia[2][2] * w ** 2
         + 0.5 * 3000.0 * v2 + 3000.0 * G * res["payload.position.z"] + S ** 2 * L0 / (2.0 * EA))
    after = res.time >= 2.05
    check_min("slew speed after the push [rad/s]", w[after][0], 0.04)
    check_min("trolley slid out [m]", u[-1], 0.5)
    check_min("load's speed [m/s]", np.max(np.sqrt(v2)), 0.5)
    E1 = E[after]
    # measured 4.4e-3 J of about 7 kJ kinetic energy (the generalized-alpha step's error on the 3.4 Hz
    # axial mode and the swing)
    check("energy change after the push [J]", E1 - E1[0], 0.04)


def _traction_trolley():
    """scenes/tower_crane.toml with the hoist's traction sheave on the trolley: the rope runs from an
    anchor on the counter-jib over the trolley's sheave (a traction sheave, J = 5 kg m^2, driven) down to
    the box; weightless, 1000 x stiffer; the length puts the lead at about the box's weight."""
    text = Path("scenes/tower_crane.toml").read_text(encoding="utf-8")
    a, b = text.index('[[sheaves]]\nname = "winch"'), text.index('[[sheaves]]\nname = "trolley_sheave"')
    text = text[:a] + text[b:]
    for old, new in (('name = "trolley_sheave"\nbody = "trolley"', 'name = "trolley_sheave"\nkind = "traction"\n'
                                                                    'body = "trolley"\ninertia = 5.0'),
                     ('{ sheave = "winch", wrap = "cw" }', '{ anchor = "jib", at = [-14.0, 0.0, 0.85] }'),
                     ('length = 210.55277883', 'length = 60.56323'), ('sheave = "winch"', 'sheave = "trolley_sheave"'),
                     ('EA = 40e6', 'EA = 40e9'), ('rhoA = 1.2', 'rhoA = 1e-6')):
        assert old in text, old
        text = text.replace(old, new)
    return loads_scene(text, "traction_trolley.toml")


def test_traction_sheave_on_the_trolley_holds_the_tension_difference():
    """A traction sheave on the trolley (a joint on the slewing jib) at rest: its drive torque is
    R x (the tension difference of its two spans), the fall carries the box's weight."""
    m = build_model(_traction_trolley())
    sim = Simulator(m)
    y = dict(zip(m.output_names, sim.outputs(sim.initial_state())))
    d = y["trolley_sheave.tension_in"] - y["trolley_sheave.tension_out"]
    check_min("tension difference [N]", abs(d), 100.0)
    # measured 9.6e-9 (the rope's own weight, 1e-6 kg/m)
    check("fall tension / box weight - 1", y["trolley_sheave.tension_out"] / (3000.0 * G) - 1.0, 9e-8)
    # measured 7.4e-7 of the 105 N m torque (the wrap counts its rope unstretched)
    check("drive torque / (R x tension difference) - 1", y["motor.torque"] / (0.35 * d) - 1.0, 7.4e-6)


SPIN = """
[scene]
model = "spatial"
sheave_contact = "rigid"
gravity = [0.0, 0.0, 0.0]
[solver]
step = 1e-3
rho_inf = 1.0
[initial]
statics = "none"
[[bodies]]
name = "jib"
mass = 100.0
inertia = 100.0
position = [0.5, 0.0, 0.0]
joint = { kind = "revolute", axis = [0.0, 0.0, 1.0], pivot = [0.0, 0.0, 0.0] }
motion = { kind = "free" }
[[bodies]]
name = "trolley"
mass = 10.0
inertia = [1.0, 1.0, 1.5]
position = [2.0, 0.0, 0.0]
joint = { kind = "prismatic", parent = "jib", axis = [1.0, 0.0, 0.0] }
motion = { kind = "free" }
[[sheaves]]
name = "drum"
kind = "drum"
body = "trolley"
center = [0.0, 0.0, 0.0]
radius = 0.1
axis = [0.0, 0.0, 1.0]
inertia = 1.0
stored = 5.0
[[ropes]]
name = "rope"
EA = 1e3
rhoA = 1e-4
route = [{ sheave = "drum", wrap = "cw" }, { anchor = "trolley", at = [1.0, 0.0, 0.0] }]
[drive]
kind = "torque"
sheave = "drum"
torque = [[0.0, 0.5], [10.0, 0.5]]
"""


def test_trolley_drum_spin_turns_the_jib():
    """A drum (J = 1 kg m^2) on the trolley with its axis along the slew axis; the jib turns freely (no
    gravity) and the trolley slides freely on its rail; the drum's motor winds a rope anchored on the
    trolley. Every force is internal, so the angular momentum about the slew axis
    (I_jib + m r^2 + J_zz) w + J (the drum's spin relative to the trolley) stays 0 (the drum's
    J w^2 / 2 is part of the trolley's J_zz): the jib turns back as the drum spins up. Without the
    coupling of the drum's spin with the parent's (jib's) turn the jib would not turn."""
    res = Simulator(build_model(loads_scene(SPIN, "spin.toml"))).run(2.0, 0.01)
    spin = -res["drum.speed"]                   # relative to the trolley, about +z (cw wrap)
    r = 2.0 + res["trolley.travel"]
    Lz = (100.0 + 10.0 * r ** 2 + 1.5) * res["jib.angular_velocity"] + 1.0 * spin
    check_min("drum spin relative to the trolley [rad/s]", np.max(np.abs(spin)), 0.5)
    check_min("jib's counter-turn [rad/s]", np.max(np.abs(res["jib.angular_velocity"])), 1e-3)
    # measured 3.4e-6 of J x the largest spin (the rope's own momentum, 1e-4 kg/m)
    check("angular momentum / (J spin)", Lz / np.max(np.abs(spin)), 3.4e-5)


BOOM = """
[scene]
model = "spatial"
[initial]
statics = "none"
[[bodies]]
name = "superstructure"
mass = 20000.0
inertia = 2e5
position = [-1.5, 0.0, 2.0]
joint = {{ kind = "revolute", axis = [0.0, 0.0, 1.0], pivot = [0.0, 0.0, 0.0] }}
[[bodies]]
name = "boom"
mass = 8000.0
inertia = [1e4, 6e5, 6e5]
position = [7.5, 0.0, 3.0]
joint = {{ kind = "revolute", parent = "superstructure", axis = [0.0, -1.0, 0.0], pivot = [0.0, 0.0, 3.0] }}
[[bodies]]
name = "hook"
mass = 500.0
position = [2.6, 0.0, -5.0]
free = ["x", "y", "z"]
[[sheaves]]
name = "winch"
kind = "{kind}"
body = "boom"
center = [-5.5, 0.0, 0.0]
radius = 0.3
axis = {axis}
inertia = {J}
[[ropes]]
name = "hoist"
EA = 1e7
rhoA = 1.0
route = [{route}{{ sheave = "winch", wrap = "cw" }}, {{ anchor = "hook", at = [0.0, 0.0, 0.0] }}]
[drive]
kind = "speed"
sheave = "winch"
distance = -1.0
motor_inertia = {Jm}
"""


@pytest.mark.parametrize("kind, axis, J, Jm", [
    ("drum", [0.0, 0.0, 1.0], 5.0, 0.0),             # the spin's coupling with the slew changes with the luff
    ("traction", [1.0, 0.0, 0.0], 5.0, 0.0),
    ("drum", [0.0, 0.0, 1.0], 0.0, 2.0),             # the motor's inertia alone
])
def test_winch_off_the_hinge_axis_on_a_luffing_boom_is_refused(kind, axis, J, Jm):
    """A drum or traction sheave on a boom luffing on a slewing superstructure: its spin couples with the
    slew by J (k_slew . a) / R, which changes with the luff unless the sheave's axis lies along the
    luffing hinge (or J = 0, sheave and motor): refused naming [sheaves[0].axis] and the remedies."""
    route = '{ anchor = "ground", at = [-5.0, 0.0, 3.0] }, ' if kind == "traction" else ""   # a traction sheave between
    with pytest.raises(SceneError) as exc:
        parse_scene(tomllib.loads(BOOM.format(kind=kind, axis=axis, J=J, Jm=Jm, route=route)), "boom.toml")
    msg = str(exc.value)
    assert msg.startswith("boom.toml: [sheaves[0].axis]") and "'boom'" in msg and "'superstructure'" in msg, msg
    assert f"inertia {J + Jm:g} kg m^2" in msg and "give it an axis along [0.0, -1.0, 0.0]" in msg, msg


@pytest.mark.parametrize("axis, J, Jm", [([0.0, 1.0, 0.0], 5.0, 2.0), ([0.0, 0.0, 1.0], 0.0, 0.0)])
def test_winch_on_the_hinge_axis_or_without_inertia_on_a_luffing_boom_builds(axis, J, Jm):
    """The same drum along the luffing hinge (its coupling with the slew is constant: k_slew . a = 0 at
    every luff) or without inertia (no coupling) is a model: it builds, with sigma coupled to the luff
    by -sense J (k_luff . a) / R = J_total (-(-1) (-1) / 0.3) in the mass matrix, and nothing to the slew."""
    sc = parse_scene(tomllib.loads(BOOM.format(kind="drum", axis=axis, J=J, Jm=Jm, route="")), "boom.toml")
    m = build_model(sc)
    names = list(m.q_names)
    js, jl, jz = names.index("winch.s"), names.index("boom.angle"), names.index("superstructure.angle")
    M0 = np.asarray(m.K.M0)
    assert M0[js, jz] == 0.0
    assert M0[js, jl] == pytest.approx(-(J + Jm) / 0.3, rel=1e-15)
