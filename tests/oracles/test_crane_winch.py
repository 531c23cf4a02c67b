"""Winches on moving bodies (scenes/tower_crane.toml, luffing_crane.toml, tower_crane_trolley.toml)
against results computed here: the rope a drum on the slewing jib pays out is the change of the rope
path from the drum to the box (rigid limit, the path from the poses with geometry.tangent); the
luffing boom's joint torque at rest from the free body of boom, winch and rope (and from the forces on
the boom alone, the winch's drive torque acting between drum and boom); the trolley's travel force
against the rope's horizontal pull."""
import math
from dataclasses import replace

import numpy as np
import pytest

from reeve_fmu.core.geometry import tangent, wrap_angle
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, load_scene, parse_scene
from reeve_fmu.core.solver import Simulator
from tests.support.checks import check, check_min

G = np.array([0.0, 0.0, -9.81])


def _rot(axis, ang):
    """Rotation matrix of ang about the unit axis (Rodrigues)."""
    a = np.asarray(axis, float)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(ang) * K + (1.0 - math.cos(ang)) * (K @ K)


def _rotvec(phi):
    th = float(np.linalg.norm(phi))
    return np.eye(3) if th == 0.0 else _rot(phi / th, th)


def _scene(path, EA_factor=1.0, rhoA=None, **drive):
    sc = load_scene(path)
    rope = sc.ropes[0]
    rope = replace(rope, EA=EA_factor * rope.EA, rhoA=rope.rhoA if rhoA is None else rhoA)
    return replace(sc, ropes=(rope,), drive=replace(sc.drive, **drive))


def _anchor(y, at):
    """World position of the payload's rope anchor from the outputs (centre of mass, rotation vector)."""
    c = np.array([y["payload.position.x"], y["payload.position.y"], y["payload.position.z"]])
    phi = np.array([y["payload.rotation.x"], y["payload.rotation.y"], y["payload.rotation.z"]])
    return c + _rotvec(phi) @ np.asarray(at, float)


def test_winch_on_the_slewing_jib_pays_out_the_rope_path():
    """Tower crane, rope 1000 x stiffer (the rigid limit): the jib slews 0.6 rad while the trolley
    travels 10 m out along it (a joint on the jib) and the winch on its counter-jib hoists 5 m. The rope
    the winch winds (R x its angle relative to the jib) equals the change of the rope path drum ->
    trolley sheave -> box, computed from the jib angle, the trolley's travel and the box's pose; a winch
    that did not turn with the jib would see the slew in its span (about 10 m of path to the trolley
    turned by 0.6 rad)."""
    sc = _scene("scenes/tower_crane.toml", 1000.0)
    m = build_model(sc)
    res = Simulator(m).run(15.0, 0.05)
    jib, tr = sc.bodies[0], sc.bodies[1]
    sh = {s.name: s for s in sc.sheaves}
    w, t = sh["winch"], sh["trolley_sheave"]
    stops = sc.ropes[0].route
    p, c0 = np.asarray(jib.pivot), np.asarray(jib.position)

    def path(k):
        y = {n: res[n][k] for n in res.names}
        Rj = _rot(jib.joint_axis, y["jib.angle"])
        cw = p + Rj @ (c0 + np.asarray(w.center) - p)
        ct = p + Rj @ (np.asarray(tr.position) + y["trolley.travel"] * np.asarray(tr.joint_axis) - p)
        aw, at = Rj @ np.asarray(w.axis), Rj @ np.asarray(t.axis)
        anc = _anchor(y, stops[2].at)
        Tw, Ti = tangent(cw, w.radius, aw, -1.0, ct, t.radius, at, -1.0)
        To, _ = tangent(ct, t.radius, at, -1.0, anc, 0.0, None, 1.0)
        wrap = t.radius * wrap_angle(ct, at, -1.0, Ti, To)
        # the lead's departure from the drum moves round it as the trolley travels: from a jib-fixed point
        on_drum = w.radius * wrap_angle(cw, aw, -1.0, cw + w.radius * (Rj @ np.array([-1.0, 0.0, 0.0])), Tw)
        return on_drum + np.linalg.norm(Ti - Tw) + wrap + np.linalg.norm(anc - To)

    P = np.array([path(k) for k in range(len(res.time))])
    wound = w.radius * (res["winch.angle"] - res["winch.angle"][0])   # sigma - sigma0 = -R angle
    check_min("jib slew [rad]", res["jib.angle"][-1], 0.5)
    check_min("trolley travel [m]", res["trolley.travel"][-1], 9.0)
    check_min("rope wound [m]", -(P[-1] - P[0]), 4.5)
    # measured 7.7e-6 m over 5.0 m wound, the 0.6 rad slew and 9 m of travel (the stiff rope's strain changes)
    check("path change + rope paid out [m]", (P - P[0]) - wound, 2e-5)


def _luffing_statics(EA_factor):
    sc = _scene("scenes/luffing_crane.toml", EA_factor, rhoA=1e-6)    # weightless rope: forces at the sheaves
    m = build_model(sc)
    sim = Simulator(m)
    st = sim.initial_state()
    y = dict(zip(m.output_names, sim.outputs(st)))
    boom = sc.bodies[0]
    sh = {s.name: s for s in sc.sheaves}
    p, c0 = np.asarray(boom.pivot), np.asarray(boom.position)
    Rb = _rot(boom.joint_axis, y["boom.angle"])
    cd, ch = (p + Rb @ (c0 + np.asarray(sh[n].center) - p) for n in ("winch", "head"))
    a = Rb @ np.asarray(sh["head"].axis)
    Td, Thi = tangent(cd, sh["winch"].radius, a, -1.0, ch, sh["head"].radius, a, -1.0)
    Tho, _ = tangent(ch, sh["head"].radius, a, -1.0, _anchor(y, sc.ropes[0].route[2].at), 0.0, None, 1.0)
    e1 = (Thi - Td) / np.linalg.norm(Thi - Td)
    e2 = _anchor(y, sc.ropes[0].route[2].at) - Tho
    e2 /= np.linalg.norm(e2)
    return sc, y, dict(p=p, cg=p + Rb @ (c0 - p), cd=cd, Td=Td, Thi=Thi, Tho=Tho, e1=e1, e2=e2, a=a)


def test_luffing_boom_joint_torque_carries_the_winch_torque():
    """Luffing crane at rest, winch on the boom base: the luffing cylinder's torque (`boom.joint_torque`)
    against (a) the free body of boom, winch and the rope up to the head sheave: boom weight and the
    fall's pull at the head's tangent point; (b) the forces on the boom alone: the rope at both tangent
    points of the head sheave, the winch's bearing load (the rope's pull moved to the drum axle) and
    the reaction of the winch's drive torque (`motor.torque`) on its mounting, 22 kN m here. The scene's
    rope 1000 x stiffer: the wraps count their rope unstretched, an error eps R S / 2 in the torques."""
    sc, y, g = _luffing_statics(1000.0)
    boom = sc.bodies[0]
    k = np.asarray(boom.joint_axis)
    S_fall, S_lead = y["head.tension_out"], y["head.tension_in"]
    weight = np.cross(g["cg"] - g["p"], boom.mass * G)
    free_body = -k @ (weight + np.cross(g["Tho"] - g["p"], S_fall * g["e2"]))
    on_boom = (weight + np.cross(g["Thi"] - g["p"], -S_lead * g["e1"]) + np.cross(g["Tho"] - g["p"], S_fall * g["e2"])
               + np.cross(g["cd"] - g["p"], y["winch.tension_out"] * g["e1"]))
    tau_d = -y["motor.torque"]            # the drive's torque on the drum about its axis (engine sign)
    boom_alone = -k @ on_boom + tau_d * float(k @ g["a"])    # its reaction -tau_d a acts on the boom
    tau = y["boom.joint_torque"]
    R = sc.sheaves[0].radius
    # measured 3.8e-7 = eps / 2: the drum's rope coordinate is unstretched material
    check("drive torque / (R x lead tension) - 1", tau_d / (R * y["winch.tension_out"]) - 1.0, 4e-6)
    # measured 4.6e-10 (free body) and 5.0e-9 (boom alone) of the 1.35 MN m joint torque
    check("joint torque - free body, relative", (tau - free_body) / tau, 4.5e-9)
    check("joint torque - forces on the boom and the drive torque's reaction, relative", (tau - boom_alone) / tau, 4.5e-8)


def test_trolley_travel_force_against_the_rope_pull():
    """Tower crane with the trolley on its rail (scenes/tower_crane_trolley.toml) at rest: the travel
    drive's force (`trolley.joint_force`, along the rail) balances the horizontal pull of the rope on
    the trolley sheave: the lead toward the winch and the fall toward the box, at their tangent points.
    Then travelling out at constant speed, hoist held, the same balance with the rope's pull at that
    instant. The rope is weightless here: one element per span
    puts a span's weight at its ends and the rope the fall gives up to the wrap at mid-fall height."""
    sc = _scene("scenes/tower_crane_trolley.toml", rhoA=1e-6, t_start=1e3)   # weightless rope, no hoisting
    m = build_model(sc)
    res = Simulator(m).run(12.0, 0.05)
    tr = sc.bodies[0]
    sh = {s.name: s for s in sc.sheaves}
    at = sc.ropes[0].route[2].at

    def pull(k):
        y = {n: res[n][k] for n in res.names}
        ct = np.asarray(tr.position) + y["trolley.travel"] * np.asarray(tr.joint_axis)
        cw, a = np.asarray(sh["winch"].center), np.asarray(sh["trolley_sheave"].axis)
        Tw, Ti = tangent(cw, sh["winch"].radius, a, -1.0, ct, sh["trolley_sheave"].radius, a, -1.0)
        anc = _anchor(y, at)
        To, _ = tangent(ct, sh["trolley_sheave"].radius, a, -1.0, anc, 0.0, None, 1.0)
        F = (y["trolley_sheave.tension_in"] * (Tw - Ti) / np.linalg.norm(Tw - Ti)
             + y["trolley_sheave.tension_out"] * (anc - To) / np.linalg.norm(anc - To))
        return y["trolley.joint_force"], float(np.asarray(tr.joint_axis) @ F)

    f0, pull0 = pull(0)
    check_min("rope's pull toward the winch at rest [N]", -pull0, 2.5e4)
    # measured 1.3e-7 of the 29.4 kN pull (the trolley sheave's W1 wrap holds its rope at the fall's strain)
    check("travel force + rope pull at rest, relative", (f0 + pull0) / pull0, 1.2e-6)
    k = int(np.argmin(np.abs(res.time - 6.0)))          # cruising at 0.8 m/s (from 1 s, 2.7 s ramp)
    assert res["trolley.acceleration"][k] == 0.0
    f, pl = pull(k)
    # measured 3.5e-8 of the pull
    check("travel force + rope pull while cruising, relative", (f + pl) / pl, 3e-7)


SPIN = """
[scene]
model = "planar"
sheave_contact = "rigid"
gravity = [0.0, 0.0, 0.0]
[solver]
step = 1e-3
rho_inf = 1.0
[initial]
statics = "none"
[[bodies]]
name = "beam"
mass = 100.0
inertia = 10.0
position = [0.0, 0.0, 0.0]
free = ["theta"]
[[sheaves]]
name = "drum"
kind = "drum"
body = "beam"
center = [0.0, 0.0, 0.0]
radius = 0.1
inertia = 1.0
stored = 5.0
[[ropes]]
name = "rope"
EA = 1e3
rhoA = 1e-4
route = [{ sheave = "drum", wrap = "cw" }, { anchor = "beam", at = [1.0, 0.0, 0.1] }]
[drive]
kind = "torque"
sheave = "drum"
torque = [[0.0, 0.5], [10.0, 0.5]]
"""


def test_winch_spin_turns_its_body():
    """A beam turning freely about its centre of mass (no gravity) carries a drum (J = 1 kg m^2, axis
    along the beam's) whose motor winds a soft rope anchored on the same beam: every force is internal,
    so the angular momentum I_beam theta_dot + J (drum spin relative to the beam) stays 0 (the drum's
    J (theta_dot)^2 / 2 is part of I_beam): the beam turns back as the drum spins up. Without the spin
    coupling of drum and body the beam would not turn."""
    import tomllib
    m = build_model(parse_scene(tomllib.loads(SPIN), "spin.toml"))
    res = Simulator(m).run(2.0, 0.01)
    spin = -res["drum.speed"]                  # relative to the beam, about the drum's axis (cw wrap)
    # measured 1.11 rad/s: the motor pays the rope out slack and spins up its drum nearly freely
    check_min("drum spin relative to the beam [rad/s]", np.max(np.abs(spin)), 0.5)
    # measured 3.0e-6 of J x the largest spin (the rope's own momentum, 1e-4 kg/m)
    check("angular momentum / (J spin)", (10.0 * res["beam.angular_velocity"] + 1.0 * spin) / np.max(np.abs(spin)),
          2.9e-5)


WINCH = """
[scene]
model = "spatial"
[initial]
statics = "none"
[[bodies]]
name = "frame"
mass = 100.0
position = [0.0, 0.0, 0.0]
{frame}
[[bodies]]
name = "box"
mass = 100.0
position = [0.3, 0.0, -5.0]
[[sheaves]]
name = "drum"
kind = "drum"
body = "frame"
center = [0.0, 0.0, 0.0]
radius = 0.3
[[ropes]]
name = "rope"
EA = 1e6
rhoA = 1.0
route = [{{ sheave = "drum", wrap = "ccw" }}, {{ anchor = "box", at = [0.0, 0.0, 0.0] }}]
"""


@pytest.mark.parametrize("frame, key, words", [
    ("free = []", "sheaves[0].body", "no joint and no free coordinate"),
    ('free = ["x", "y", "z", "rotation"]\ninertia = [1.0, 1.0, 1.0]', "sheaves[0].body", "spatial rigid body"),
    ('joint = { kind = "prismatic", axis = [1.0, 0.0, 0.0], range = [-2.0, 5.0] }\n'
     'motion = { kind = "profile", distance = 6.0 }', "bodies[0].motion.distance", "run off its rail"),
    ('joint = { kind = "prismatic", axis = [1.0, 0.0, 0.0], range = [1.0, 5.0] }', "bodies[0].joint.range",
     "min <= 0 <= max"),
])
def test_bad_winch_mountings_name_the_key(frame, key, words):
    import tomllib
    with pytest.raises(SceneError) as exc:
        parse_scene(tomllib.loads(WINCH.format(frame=frame)), "winch.toml")
    assert f"[{key}]" in str(exc.value) and words in str(exc.value), str(exc.value)


def test_trolley_pushed_off_its_rail_stops_the_run_naming_the_key():
    """The trolley of tower_crane_trolley.toml under a constant travel force instead of its profile
    (statics off: the force does not balance the rope's pull): it runs along its rail to the rail's
    inner end (range -15 m) and past it. The run stops at the first sample outside, naming the body and
    [bodies[0].joint.range], and keeps the samples up to it (no profile to check when the scene loads)."""
    from reeve_fmu.core.scene import loads_scene
    from reeve_fmu.core.solver import SolverError
    text = open("scenes/tower_crane_trolley.toml", encoding="utf-8").read()
    old = 'motion = { kind = "profile", distance = 10.0, v_max = 0.8, a_max = 0.3, jerk = 0.5, t_start = 1.0 }'
    assert old in text
    text = text.replace('statics = "rope-length"', 'statics = "none"').replace(
        old, 'motion = { kind = "torque", torque = [[0.0, 6000.0], [30.0, 6000.0]] }')
    sim = Simulator(build_model(loads_scene(text, "trolley.toml")))
    with pytest.raises(SolverError) as exc:
        sim.run(12.0, 0.05)
    msg = str(exc.value)
    assert ("body 'trolley' ran off its rail: travel" in msg and "outside [bodies[0].joint.range] = [-15, 20] m" in msg
            and "its motion 'torque'" in msg), msg
    x = exc.value.result["trolley.travel"]
    assert x[-1] < -15.0 <= x[-2] and exc.value.time == exc.value.result.time[-1] > 0.0
