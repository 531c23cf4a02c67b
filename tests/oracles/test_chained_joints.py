"""Joints on moving bodies (`joint.parent`: a trolley on a slewing jib) against the mechanics of a mass
on a turning rail, written here: the rail's holding force m w^2 r on a locked trolley (plus the rope's
pull along the rail in the tower crane), the slewing torque (I_jib + m r^2) alpha (plus the moment of
the rope's fall), a free trolley sliding out as r'' = w^2 r (r0 cosh(w t) at constant w), and scene
errors of the chains."""
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from reeve_fmu.core.geometry import tangent, wrap_angle
from reeve_fmu.core.model import build_model
from reeve_fmu.core.profiles import scurve
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene, parse_scene
from reeve_fmu.core.solver import Simulator
from tests.support.checks import check, check_min

I_JIB, M_T, R0, W, F_T = 4.0e6, 400.0, 10.0, 0.2, -100.0

RAIL = f"""
[scene]
model = "spatial"
sheave_contact = "rigid"
[solver]
step = 5e-3
rho_inf = 1.0
[initial]
statics = "none"
[[bodies]]
name = "jib"
mass = 16000.0
inertia = {I_JIB}
position = [4.0, 0.0, 40.0]
joint = {{ kind = "revolute", axis = [0.0, 0.0, 1.0], pivot = [0.0, 0.0, 40.0] }}
motion = {{ kind = "profile", distance = 50.0, v_max = {W}, a_max = 0.5, jerk = 5.0, t_start = 0.5 }}
[[bodies]]
name = "trolley"
mass = {M_T}
position = [{R0}, 0.0, 39.6]
joint = {{ kind = "prismatic", parent = "jib", axis = [1.0, 0.0, 0.0] }}
motion = {{trolley}}
[[bodies]]
name = "weight"
mass = 10.0
position = [0.0, 5.0, 0.0]
free = ["z"]
[[ropes]]
name = "hanger"
EA = 1e5
rhoA = 0.1
route = [{{ anchor = "ground", at = [0.0, 5.0, 2.0] }}, {{ anchor = "weight", at = [0.0, 0.0, 0.0] }}]
"""

JIB_PROFILE = scurve(50.0, W, 0.5, 5.0, t_start=0.5)
T_RAMP = 0.5 + 0.5 / 5.0 + W / 0.5          # the slew reaches W here (jerk phases 0.1 s, W / a_max 0.4 s)


def _rail(trolley):
    motion = {"profile": '{ kind = "profile", t_start = 1000.0 }', "free": '{ kind = "free" }',
              "force": f'{{ kind = "torque", torque = [[0.0, {F_T}], [100.0, {F_T}]] }}'}[trolley]
    return loads_scene(RAIL.replace("{trolley}", motion), "rail.toml")


def test_locked_trolley_on_the_slewing_jib_holding_force_and_slewing_torque():
    """Trolley locked on the rail 10 m out (its profile not started) while the jib spins up to
    w = 0.2 rad/s: the rail holds it with -m w^2 r (the joint force along the rail, inward), and the slew
    needs (I_jib + m r^2) alpha. A jib that ignored the trolley would need I_jib alpha only (1 % less)."""
    res = Simulator(build_model(_rail("profile"))).run(6.0, 0.01)
    w, al = res["jib.angular_velocity"], res["jib.angular_acceleration"]
    check_min("slew speed reached [rad/s]", w[-1], 0.19)
    assert np.all(res["trolley.travel"] == 0.0)
    # measured 5.7e-14 N of the 160 N holding force (round-off)
    check("trolley.joint_force + m w^2 r [N]", res["trolley.joint_force"] + M_T * w ** 2 * R0, 5e-13)
    check_min("holding force at full speed [N]", -res["trolley.joint_force"][-1], 150.0)
    ramp = np.abs(al) > 0.0
    check_min("ramp samples", np.count_nonzero(ramp), 30)
    # measured 2.7e-13 N m of the 2.0e6 N m slewing torque (round-off)
    check("jib.joint_torque - (I_jib + m r^2) alpha [N m]", res["jib.joint_torque"] - (I_JIB + M_T * R0 ** 2) * al,
          2e-12)


@pytest.mark.parametrize("motion, force, travel", [("free", 0.0, 15.0), ("force", F_T, 3.0)])
def test_free_trolley_slides_out_as_cosh_on_the_slewing_jib(motion, force, travel):
    """A free trolley (no rope) on a frictionless radial rail of a jib slewing at the prescribed speed,
    without a force or pulled inwards by a constant travel force F (its force table, motion.kind =
    "torque"): r'' = w(t)^2 r + F / m (the rail takes the Coriolis force). During the spin-up the radial
    equation is integrated here (scipy, rtol 1e-12); from T_RAMP on w is constant and
    r = -F / (m w^2) + (r1 + F / (m w^2)) cosh(w (t - t1)) + (v1 / w) sinh(w (t - t1)): without the force
    r0 cosh(w t) after a step start, 10 m -> 27 m in 8 s."""
    res = Simulator(build_model(_rail(motion))).run(9.0, 0.01)
    a = force / M_T
    sol = solve_ivp(lambda t, y: (y[1], JIB_PROFILE(t)[1] ** 2 * y[0] + a), (0.0, T_RAMP), (R0, 0.0), rtol=1e-12,
                    atol=1e-14, dense_output=True)
    r1, v1 = sol.y[:, -1]
    t = res.time
    rp = -a / W ** 2                         # the particular solution at constant w
    rr = np.where(t < T_RAMP, sol.sol(np.minimum(t, T_RAMP))[0],
                  rp + (r1 - rp) * np.cosh(W * (t - T_RAMP)) + v1 / W * np.sinh(W * (t - T_RAMP)))
    r = R0 + res["trolley.travel"]
    check_min("travel [m]", r[-1] - R0, travel)
    # measured 7.8e-6 m (free, 17 m of travel) and 5.0e-6 m (force, 3.5 m): the generalized-alpha step's
    # O(h^2) error on the exponential growth
    check("trolley radius - r'' = w^2 r + F / m [m]", r - rr, 5e-5)
    # measured 5.7e-14 N (free) and 1.4e-14 N (force) (round-off)
    check("joint force - the force table [N]", res["trolley.joint_force"] - force, 2.5e-13,
          reason="round-off, which differs by platform and case")


def _rot(axis, ang):
    """Rotation matrix of ang about the unit axis (Rodrigues)."""
    a = np.asarray(axis, float)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + math.sin(ang) * K + (1.0 - math.cos(ang)) * (K @ K)


def _anchor(y, at):
    """World position of the payload's rope anchor from the outputs (centre of mass, rotation vector)."""
    c = np.array([y["payload.position.x"], y["payload.position.y"], y["payload.position.z"]])
    phi = np.array([y["payload.rotation.x"], y["payload.rotation.y"], y["payload.rotation.z"]])
    th = float(np.linalg.norm(phi))
    return c + (np.eye(3) if th == 0.0 else _rot(phi / th, th)) @ np.asarray(at, float)


def test_tower_crane_slew_loads_rail_and_slewing_drive_with_the_rope():
    """scenes/tower_crane.toml with a weightless rope 1000 x stiffer (the inextensible limit), trolley
    locked 20 m out, hoist held: the jib slews 0.6 rad and the box swings. For a frictionless rope of
    tension S the rope's generalized force on a coordinate is -S dP/dq, P the rope path winch -> trolley
    sheave -> box (geometry.tangent, wrap_angle; differenced here with the box held). At every output
    the travel drive's force balances m w^2 r and the rope (joint_force = S dP/du - m w^2 r), and the
    slewing torque is (I_jib + m r^2) alpha + S dP/dtheta. A fall leaving the sheave's plane (the swing)
    makes dP/du differ from the pull of the two spans along the rail (S (e_lead + e_fall)): the path's
    wrap is not stationary in the tangent point then (about 6 N here)."""
    sc = load_scene("scenes/tower_crane.toml")
    bodies = {b.name: b for b in sc.bodies}
    sc = replace(sc, ropes=(replace(sc.ropes[0], rhoA=1e-6, damping=0.0, EA=1000.0 * sc.ropes[0].EA),),
                 drive=replace(sc.drive, t_start=1e3),
                 bodies=tuple(replace(b, motion=replace(b.motion, t_start=1e3)) if b.name == "trolley" else b
                              for b in sc.bodies))
    res = Simulator(build_model(sc)).run(14.0, 0.05)
    jib, tr = bodies["jib"], bodies["trolley"]
    sh = {s.name: s for s in sc.sheaves}
    w, t = sh["winch"], sh["trolley_sheave"]
    p = np.asarray(jib.pivot)
    at = sc.ropes[0].route[2].at
    r = float(np.linalg.norm((np.asarray(tr.position) - p)[:2]))

    def path(th, u, anc):
        Rj = _rot(jib.joint_axis, th)
        cw = p + Rj @ (np.asarray(jib.position) + np.asarray(w.center) - p)
        ct = p + Rj @ (np.asarray(tr.position) + u * np.asarray(tr.joint_axis) - p)
        aw, a = Rj @ np.asarray(w.axis), Rj @ np.asarray(t.axis)
        Tw, Ti = tangent(cw, w.radius, aw, -1.0, ct, t.radius, a, -1.0)
        To, _ = tangent(ct, t.radius, a, -1.0, anc, 0.0, None, 1.0)
        on_drum = w.radius * wrap_angle(cw, aw, -1.0, cw + w.radius * (Rj @ np.array([-1.0, 0.0, 0.0])), Tw)
        return (on_drum + np.linalg.norm(Ti - Tw) + t.radius * wrap_angle(ct, a, -1.0, Ti, To)
                + np.linalg.norm(anc - To))

    h = 1e-6
    rail, slew = [], []
    for k in range(len(res.time)):
        y = {n: res[n][k] for n in res.names}
        th, anc = y["jib.angle"], _anchor(y, at)
        S = 0.5 * (y["trolley_sheave.tension_in"] + y["trolley_sheave.tension_out"])
        dPu = (path(th, h, anc) - path(th, -h, anc)) / (2 * h)
        dPth = (path(th + h, 0.0, anc) - path(th - h, 0.0, anc)) / (2 * h)
        rail.append(y["trolley.joint_force"] + M_T * y["jib.angular_velocity"] ** 2 * r - S * dPu)
        slew.append(y["jib.joint_torque"] - (I_JIB + M_T * r ** 2) * y["jib.angular_acceleration"] - S * dPth)
    check_min("slew [rad]", res["jib.angle"][-1], 0.59)
    check_min("box swing across the jib [m]", np.max(np.abs(res["payload.position.y"] - 20.35 * np.sin(res["jib.angle"]))), 1.0)
    check_min("rope's pull along the rail [N]", np.max(np.abs(res["trolley.joint_force"])), 2.5e4)
    check_min("slewing torque [N m]", np.max(np.abs(res["jib.joint_torque"])), 1e5)
    # measured 2.1e-3 N of the 32 kN pull and 5.3e-4 N m of the 2.5e5 N m slewing torque (round-off: the
    # run's last bits move with any change of the float operations, 6.0e-4 N and 1.7e-3 N m before the
    # tension-only law's band narrowed to 1 N, which put this 1000 x stiff rope on its bilateral branch)
    check("rail force: joint_force + m w^2 r - S dP/du [N]", np.array(rail), 1.2e-2)
    check("slewing torque: tau - (I_jib + m r^2) alpha - S dP/dtheta [N m]", np.array(slew), 1.6e-2,
          reason="round-off of a 14 s spatial run: 5.3e-4 to 1.7e-3 N m as the float operations change")


CHAIN = """
[scene]
model = "spatial"
[[bodies]]
name = "jib"
mass = 1000.0
inertia = 1e5
position = [2.0, 0.0, 10.0]
joint = {{ kind = "revolute", axis = [0.0, 0.0, 1.0], pivot = [0.0, 0.0, 10.0] }}
[[bodies]]
name = "trolley"
mass = 100.0
position = [5.0, 0.0, 9.8]
{trolley}
[[bodies]]
name = "hook"
mass = 50.0
position = [5.0, 0.0, 2.0]
{hook}
[[sheaves]]
name = "winch"
kind = "drum"
body = "{winch_body}"
center = [-4.0, 0.0, 0.5]
radius = 0.2
stored = 10.0
[[sheaves]]
name = "pulley"
body = "trolley"
center = [0.0, 0.0, 0.0]
radius = 0.2
[[ropes]]
name = "hoist"
EA = 1e6
rhoA = 0.5
route = [{{ sheave = "winch", wrap = "cw" }}, {{ sheave = "pulley", wrap = "cw" }}, {{ anchor = "hook", at = [0.0, 0.0, 0.0] }}]
"""
TROLLEY = 'joint = { kind = "prismatic", parent = "jib", axis = [1.0, 0.0, 0.0], range = [-3.0, 4.0] }'
FREE = 'free = ["x", "y", "z"]'


@pytest.mark.parametrize("trolley, hook, winch_body, key, words", [
    (TROLLEY.replace('"jib"', '"boom"'), FREE, "jib", "bodies[1].joint.parent", "unknown body 'boom'"),
    (TROLLEY, 'joint = { kind = "prismatic", parent = "trolley", axis = [0.0, 0.0, 1.0] }', "jib",
     "bodies[2].joint.parent", "chains are two deep at most"),
    (TROLLEY.replace('"jib"', '"trolley"'), FREE, "jib", "bodies[1].joint.parent", "its own parent"),
    (TROLLEY.replace('"jib"', '"hook"'), FREE, "jib", "bodies[1].joint.parent", "has no joint"),
    (TROLLEY + '\nmotion = { kind = "profile", distance = 5.0 }', FREE, "jib", "bodies[1].motion.distance",
     "run off its rail"),
    (TROLLEY + '\ninertia = "heavy"', FREE, "jib", "bodies[1].inertia", "must be [Ixx, Iyy, Izz]"),
    (TROLLEY + '\ninertia = 50.0', FREE, "jib", "bodies[1].inertia", "must be [Ixx, Iyy, Izz]"),
    (TROLLEY.replace('"prismatic"', '"revolute"').replace("range = [-3.0, 4.0]", "pivot = [5.0, 0.0, 9.8]"), FREE,
     "jib", "bodies[1].inertia", "positive moment of inertia about its axis"),
    (TROLLEY, FREE, "hook2", "sheaves[0].body", "unknown body"),
])
def test_bad_chains_name_the_key(trolley, hook, winch_body, key, words):
    """Joint chains a scene refuses with the key and the reason: an unknown parent, a parent on a joint on
    another body (depth 3 or a cycle), a body its own parent, a parent without a joint, a trolley profile
    past its rail's end (a winch on a body on a moving body: tests/oracles/test_trolley_hoist.py)."""
    import tomllib
    text = CHAIN.format(trolley=trolley, hook=hook, winch_body=winch_body)
    with pytest.raises(SceneError) as exc:
        parse_scene(tomllib.loads(text), "chain.toml")
    assert f"[{key}]" in str(exc.value) and words in str(exc.value), str(exc.value)


def test_winch_on_a_body_without_motion_is_refused():
    import tomllib
    text = CHAIN.format(trolley=TROLLEY, hook=FREE, winch_body="post").replace(
        '[[sheaves]]', '[[bodies]]\nname = "post"\nmass = 1.0\nfree = []\n[[sheaves]]', 1)
    with pytest.raises(SceneError) as exc:
        parse_scene(tomllib.loads(text), "chain.toml")
    assert "[sheaves[0].body]" in str(exc.value) and "no joint and no free coordinate" in str(exc.value)


def test_torsion_rope_over_a_joint_on_a_moving_body_is_refused():
    import tomllib
    text = CHAIN.format(trolley=TROLLEY, hook=FREE, winch_body="jib").replace(
        'rhoA = 0.5', 'rhoA = 0.5\ntorsion = { law = "torque-factor", diameter = 0.02, k0 = 0.05 }')
    with pytest.raises(SceneError) as exc:
        build_model(parse_scene(tomllib.loads(text), "chain.toml"))
    assert "[ropes[0].torsion]" in str(exc.value) and "trolley" in str(exc.value), str(exc.value)


I_S = 2.0e5
J_BOOM = np.array([[450250.0, 0.0, -259374.60843343937], [0.0, 600000.0, 0.0], [-259374.60843343937, 0.0, 150750.0]])
M_B, C_B, P_B = 8000.0, np.array([7.5, 0.0, 15.990381]), np.array([0.0, 0.0, 3.0])
BOOM = f"""
[scene]
model = "spatial"
sheave_contact = "rigid"
[solver]
step = 5e-3
rho_inf = 1.0
[initial]
statics = "none"
[[bodies]]
name = "superstructure"
mass = 20000.0
inertia = {I_S}
position = [-1.5, 0.0, 2.0]
joint = {{ kind = "revolute", axis = [0.0, 0.0, 1.0], pivot = [0.0, 0.0, 0.0] }}
motion = {{ kind = "profile", distance = 50.0, v_max = 0.1, a_max = 0.1, jerk = 0.5, t_start = 0.5 }}
[[bodies]]
name = "boom"
mass = {M_B}
inertia = {J_BOOM.tolist()}
position = {C_B.tolist()}
joint = {{ kind = "revolute", parent = "superstructure", axis = [0.0, -1.0, 0.0], pivot = {P_B.tolist()} }}
motion = {{ kind = "profile", distance = -0.1, t_start = 1000.0 }}
[[bodies]]
name = "weight"
mass = 10.0
position = [0.0, 5.0, 0.0]
free = ["z"]
[[ropes]]
name = "hanger"
EA = 1e5
rhoA = 0.1
route = [{{ anchor = "ground", at = [0.0, 5.0, 2.0] }}, {{ anchor = "weight", at = [0.0, 0.0, 0.0] }}]
"""


def test_boom_on_the_slewing_superstructure_luffing_and_slewing_torques():
    """A 30 m boom (8 t, full inertia tensor J about its centre of mass) locked 60 deg up on a
    superstructure spun up to w = 0.1 rad/s. The slewing torque is (I_s + I_boom,z) alpha, I_boom,z =
    J_zz + m (c_x^2 + c_y^2) its moment about the slew axis. The luffing torque at constant w balances
    gravity and the centrifugal forces w^2 r_h dm about the luff axis a through the pivot p:
    tau = -a.[m (c - p) x g + w^2 (m (c - p) x c_h + int d x d_h dm)], d = r - c, d_h its horizontal
    part, int d_i d_j dm = S = tr(J)/2 I - J (the second moments from the inertia tensor)."""
    res = Simulator(build_model(loads_scene(BOOM, "boom.toml"))).run(4.0, 0.01)
    w, al = res["superstructure.angular_velocity"], res["superstructure.angular_acceleration"]
    a, g = np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, -9.81])
    Ph = np.diag([1.0, 1.0, 0.0])
    S = 0.5 * np.trace(J_BOOM) * np.eye(3) - J_BOOM
    second = np.array([sum(np.cross(np.eye(3)[i], np.eye(3)[j])[k] * (S @ Ph)[i, j] for i in range(3) for j in range(3))
                       for k in range(3)])
    cen = M_B * np.cross(C_B - P_B, Ph @ C_B) + second
    tau = -(a @ (M_B * np.cross(C_B - P_B, g)) + w ** 2 * (a @ cen))
    I_bz = J_BOOM[2, 2] + M_B * (C_B[0] ** 2 + C_B[1] ** 2)
    check_min("slew speed reached [rad/s]", w[-1], 0.099)
    check_min("centrifugal part of the luffing torque [N m]", w[-1] ** 2 * abs(a @ cen), 1e4)
    # measured 2.3e-10 N m of the 6.0e5 N m luffing torque (1.0e4 of it centrifugal), 1.5e-11 N m of the
    # 8.0e4 N m slewing torque
    check("boom.joint_torque - (gravity + centrifugal moment) [N m]", (res["boom.joint_torque"] - tau)[w == w[-1]], 2e-9)
    check("superstructure.joint_torque - (I_s + I_boom,z) alpha [N m]",
          res["superstructure.joint_torque"] - (I_S + I_bz) * al, 1e-10)
