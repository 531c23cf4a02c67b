"""Rotating rigid bodies and exact tangent points (core/bodies.py) against closed forms.

* a 1.0 x 0.8 m box (2500 kg) hanging 15 m below a ground anchor by a rope fixed to the centre of its
  top face: the two pendulum modes (rope swing, block rocking) of the linearised model against the
  double pendulum rope + rigid block, and the axial mode against beta tan beta = rho A L / M;
* a rope over a sheave on a rotating beam and under a sheave on a translating block: tangent points
  equal to geometry.tangent of the current poses, rope material conserved, energy balanced.
"""
import math

import numpy as np
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.rigid import rigid_terms, rigid_terms_fd
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from reeve_fmu.core.solver import Simulator
from tests.support.beams import (beam_scene as _beam_scene, beam_tangents as _beam_tangents, nodes as _nodes,
                                 run_beam as _run_beam)
from tests.support.linearise import linearised
from tests.support.checks import SECOND_ORDER, check, check_min

ROUNDOFF = "round-off, which differs by platform"

G = 9.81
M_BOX, A_BOX, H_BOX = 2500.0, 1.0, 0.8            # kg, m (width in x), m (height in z)
I_BOX = M_BOX * (A_BOX ** 2 + H_BOX ** 2) / 12.0  # kg m^2 about y through the centre of mass
L_ROPE, EA, RHOA = 15.0, 30e6, 1.1


def _box_scene(extra_body="", model="planar"):
    return f"""
[scene]
name = "box_pendulum"
model = "{model}"
sheave_contact = "rigid"
[initial]
statics = "rope-length"
[[bodies]]
name = "box"
mass = {M_BOX}
inertia = {I_BOX}
position = [0.0, 0.0, {-L_ROPE - H_BOX / 2}]
free = ["x", "z", "theta"]
{extra_body}
[[ropes]]
name = "hoist"
EA = {EA}
rhoA = {RHOA}
length = {L_ROPE}
route = [
  {{ anchor = "ground", at = [0.0, 0.0, 0.0] }},
  {{ anchor = "box", at = [0.0, 0.0, {H_BOX / 2}] }},
]
"""


def _linearised(sim, st):
    """(M, K) on the free coordinates at rest: K = -dQ/dq by central differences."""
    return linearised(sim, st)


def _double_pendulum(l, d, m_rope):
    """omega^2 of rope (a uniform rod of mass m_rope and length l, pivoted at the top: one linear
    element per span) + rigid block (anchor d above the centre of mass), small swings."""
    Mm = np.array([[(M_BOX + m_rope / 3) * l * l, M_BOX * l * d], [M_BOX * l * d, M_BOX * d * d + I_BOX]])
    Kk = np.array([[(M_BOX + m_rope / 2) * G * l, 0.0], [0.0, M_BOX * G * d]])
    return np.sort(np.linalg.eigvals(np.linalg.solve(Mm, Kk)).real)


def test_box_pendulum_modes_against_the_double_pendulum_and_beta_tan_beta():
    m = build_model(loads_scene(_box_scene(), "box_pendulum.toml"))
    sim = Simulator(m)
    st = sim.initial_state()
    y = dict(zip(m.output_names, sim.outputs(st)))
    check('rope end tension - M g', y["hoist.tension_end"] - M_BOX * G, 2e-12 * M_BOX * G, reason=ROUNDOFF)
    check('box angle at rest', y["box.angle"], 1e-15, reason=ROUNDOFF)
    Mf, Kf = _linearised(sim, st)
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(Mf, Kf)).real)
    l = -(y["box.position.z"] + H_BOX / 2)                        # stretched span length
    exact = _double_pendulum(l, H_BOX / 2, RHOA * L_ROPE)
    err = np.abs(np.sqrt(w2[:2] / exact) - 1.0)
    check('swing and rocking frequencies / double pendulum - 1', err, 4e-7,
          reason="the two modes' errors differ 30x (1.3e-9, 4.1e-8): one bound for both")
    point = _double_pendulum(l, H_BOX / 2, 0.0)                   # massless rope: the engineering formula
    check('against the massless-rope formula (the rope mass)', np.sqrt(w2[:2] / point) - 1.0, 5e-3)
    # axial mode: beta tan beta = rho A L / M, omega = beta c / L
    ratio = RHOA * L_ROPE / M_BOX
    beta = math.sqrt(ratio)
    for _ in range(50):
        beta -= (beta * math.tan(beta) - ratio) / (math.tan(beta) + beta / math.cos(beta) ** 2)
    w_axial = beta * math.sqrt(EA / RHOA) / L_ROPE
    check('axial frequency / closed form - 1', math.sqrt(w2[2]) / w_axial - 1.0, 4.5e-6)


def _check_geometry(m, sim, st):
    """Tangent points against geometry.tangent at the current poses; material conservation."""
    T, wraps = _beam_tangents(m, sim, st)
    X = _nodes(m, st)
    for k, (TA, TB) in enumerate(T):
        check('node coordinates - tangent points', X[k, :4] - np.r_[TA[[0, 2]], TB[[0, 2]]], 1e-14, reason=ROUNDOFF)
    # a W1 wrap holds R x angle of rope at its leaving span's strain: R angle (s2 - s1) / |r2 - r1|
    held = [w * (X[k, 5] - X[k, 4]) / np.linalg.norm(X[k, 2:4] - X[k, :2]) for w, k in zip(wraps, (1, 2))]
    return sum(X[k, 5] - X[k, 4] for k in range(3)) + sum(held)


def test_rope_over_sheaves_on_a_rotating_and_a_translating_body():
    """Tangent points exact, rope material conserved to round-off, energy drift second order in h
    (a wrong Jacobian or a missing convective term would leave a drift that does not shrink)."""
    m = build_model(loads_scene(_beam_scene(), "beam_sheave.toml"))
    sim0 = Simulator(m)
    L0 = _check_geometry(m, sim0, sim0.initial_state())
    check('rope material at the start', L0 - m.par0[0], 1e-14 * L0, reason=ROUNDOFF)

    def geometry_holds(sim, st):
        check('rope material conserved', _check_geometry(m, sim, st) - L0, 1e-14 * L0, reason=ROUNDOFF)

    d1, moved = _run_beam(m, 1e-3, geometry_holds)
    d2, _ = _run_beam(m, 5e-4)
    # both bodies move and the rope runs over both sheaves, so the drift test exercises all of it
    check_min("beam rotation [rad]", -moved["beam.theta"], 0.4)
    check_min("block descent [m]", -moved["block.z"], 0.3)
    check_min("rope run over the tip sheave [m]", moved["tip.s"], 0.15)
    check_min("rope run over the block sheave [m]", -moved["blk.s"], 0.25)
    check('relative energy drift at h = 1 ms', d1, 1e-6)
    check("drift ratio h / (h/2) - 4 (second order)", d1 / d2 - 4, 0.5, reason=SECOND_ORDER)


@pytest.mark.parametrize("body, model, key", [
    ('inertia = 0.0', "planar", "inertia"),
    ('', "spatial", "free"),
])
def test_rotating_body_errors_name_the_key(body, model, key):
    text = _box_scene(model=model).replace(f"inertia = {I_BOX}", body)
    with pytest.raises(SceneError, match=rf"bodies\[0\]\.{key}"):
        loads_scene(text, "bad.toml")


def _slew_scene(motion='kind = "free"', rhoA=1e-6, method="gen-alpha"):
    # jib slewing about the vertical axis through the tower top; a point payload hangs 15 m below the
    # jib tip, displaced 1 m sideways so that it swings across the jib
    return f"""
[scene]
name = "slew"
model = "spatial"
sheave_contact = "rigid"
[solver]
method = "{method}"
step = 1e-3
rho_inf = 1.0
newton_tol = 1e-12
rtol = 1e-11
atol = 1e-12
[initial]
statics = "none"
[[bodies]]
name = "jib"
mass = 5000.0
inertia = 2.0e5
position = [6.0, 0.0, 20.0]
joint = {{ kind = "revolute", axis = [0.0, 0.0, 1.0], pivot = [0.0, 0.0, 20.0] }}
motion = {{ {motion} }}
[[bodies]]
name = "payload"
mass = 2500.0
position = [12.0, 1.0, 5.0]
free = ["x", "y", "z"]
[[ropes]]
name = "hoist"
EA = 30e6
rhoA = {rhoA}
tension_only = false     # started unstretched, its strain swings back to 0 (the slack law's kink)
route = [
  {{ anchor = "jib", at = [6.0, 0.0, 0.0] }},
  {{ anchor = "payload", at = [0.0, 0.0, 0.0] }},
]
"""


def test_free_slew_conserves_angular_momentum_about_its_axis():
    m = build_model(loads_scene(_slew_scene(), "slew.toml"))
    sim = Simulator(m)
    res = sim.run(t_end=3.0, out_dt=0.05)
    y = {n: res.values[:, i] for i, n in enumerate(res.names)}
    Lj = 2.0e5 * y["jib.angular_velocity"]
    Lp = 2500.0 * (y["payload.position.x"] * y["payload.velocity.y"]
                   - y["payload.position.y"] * y["payload.velocity.x"])
    assert np.max(np.abs(y["jib.angle"])) > 0.05                    # the swing turns the jib (0.107 rad)
    check('angular momentum: jib + payload', Lj + Lp, 3e-8 * np.max(np.abs(Lj)))


def test_prescribed_slew_follows_its_profile_and_the_joint_torque_balances_energy():
    motion = 'kind = "profile", distance = 0.5, v_max = 0.2, a_max = 0.2, jerk = 0.4'
    m = build_model(loads_scene(_slew_scene(motion, rhoA=1.1), "slew.toml"))
    sim = Simulator(m)
    st = sim.initial_state()
    E = [sum(sim.energy(st))]
    res = sim.run(t_end=5.0, out_dt=0.01, state=st)
    y = {n: res.values[:, i] for i, n in enumerate(res.names)}
    check('jib angle at the end of its profile', y["jib.angle"][-1] - 0.5, 1e-15, reason=ROUNDOFF)
    E.append(sum(sim.energy(sim.final_state)))
    P = y["jib.joint_torque"] * y["jib.angular_velocity"]
    work = float(np.sum(0.5 * (P[1:] + P[:-1]) * np.diff(res.time)))
    check('E[1] - E[0] - work', E[1] - E[0] - work, 3e-6 * abs(work))


def test_spatial_box_swings_in_both_planes_like_the_planar_box():
    Ixy = I_BOX                                   # 1.0 x 1.0 x 0.8 m: Ixx = Iyy = M (1 + 0.64) / 12
    Izz = M_BOX * 2.0 / 12.0
    text = (_box_scene(model="spatial").replace(f"inertia = {I_BOX}", f"inertia = [{Ixy}, {Ixy}, {Izz}]")
            .replace('free = ["x", "z", "theta"]', 'free = ["x", "y", "z", "rotation"]'))
    m = build_model(loads_scene(text, "box_spatial.toml"))
    sim = Simulator(m)
    st = sim.initial_state()
    y = dict(zip(m.output_names, sim.outputs(st)))
    Mf, Kf = _linearised(sim, st)
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(Mf, Kf)).real)
    check('yaw eigenvalue (a single rope holds no torque)', w2[0], 1e-12 * w2[1], reason=ROUNDOFF)
    l = -(y["box.position.z"] + H_BOX / 2)
    exact = _double_pendulum(l, H_BOX / 2, RHOA * L_ROPE)
    err = np.abs(np.sqrt(w2[1:5] / np.repeat(exact, 2)) - 1.0)
    check('swing and rocking in both planes / double pendulum - 1', err, 1e-6,
          reason="the modes' errors differ 30x (3.2e-9, 1.1e-7): one bound for all")


@pytest.mark.parametrize("inertia, match", [
    ("[100.0, 100.0, -1.0]", "positive definite"),
    ("[100.0, 10.0, 200.0]", "I1 \\+ I2 >= I3"),
    ("[[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]", "symmetric"),
])
def test_non_physical_inertia_tensor_is_an_error_naming_the_key(inertia, match):
    text = (_box_scene(model="spatial").replace(f"inertia = {I_BOX}", f"inertia = {inertia}")
            .replace('free = ["x", "z", "theta"]', 'free = ["x", "y", "z", "rotation"]'))
    with pytest.raises(SceneError, match=rf"bodies\[0\]\.inertia\] .*{match}"):
        loads_scene(text, "bad.toml")


def test_sheave_inside_another_is_an_error_naming_the_key():
    text = _box_scene() + """
[[sheaves]]
name = "big"
center = [0.0, 0.0, 1.0]
radius = 0.5
[[sheaves]]
name = "small"
center = [0.1, 0.0, 1.0]
radius = 0.2
"""
    with pytest.raises(SceneError, match=r"sheaves\[1\]\.center\] sheave 'small' overlaps sheave 'big'"):
        loads_scene(text, "bad.toml")


def test_luffing_boom_swings_like_a_compound_double_pendulum():
    """A boom on a horizontal revolute joint (centre of mass d below the pivot: its weight gives the
    restoring moment) with a point load on a rope from its tip: the linearised modes against the
    compound pendulum + point pendulum in series."""
    m_b, d, L1, I_b, m_p, l = 100.0, 2.0, 4.0, 450.0, 20.0, 1.5
    text = f"""
[scene]
name = "luff"
model = "planar"
sheave_contact = "rigid"
[initial]
statics = "rope-length"
[[bodies]]
name = "boom"
mass = {m_b}
inertia = {I_b}
position = [0.0, 0.0, {-d}]
joint = {{ kind = "revolute", axis = [0.0, -1.0, 0.0], pivot = [0.0, 0.0, 0.0] }}
[[bodies]]
name = "load"
mass = {m_p}
position = [0.0, 0.0, {-L1 - l}]
free = ["x", "z"]
[[ropes]]
name = "rope"
EA = 1e7                       # stiffer: round-off of the tension (EA x 1e-16) spoils K's differences
rhoA = 1e-6
length = {l}
route = [
  {{ anchor = "boom", at = [0.0, 0.0, {d - L1}] }},
  {{ anchor = "load", at = [0.0, 0.0, 0.0] }},
]
"""
    m = build_model(loads_scene(text, "luff.toml"))
    sim = Simulator(m)
    st = sim.initial_state()
    Mf, Kf = _linearised(sim, st)
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(Mf, Kf)).real)
    l = -L1 - dict(zip(m.output_names, sim.outputs(st)))["load.position.z"]     # stretched rope
    Mm = np.array([[I_b + m_p * L1 ** 2, m_p * L1 * l], [m_p * L1 * l, m_p * l * l]])
    Kk = np.array([[(m_b * d + m_p * L1) * G, 0.0], [0.0, m_p * G * l]])
    exact = np.sort(np.linalg.eigvals(np.linalg.solve(Mm, Kk)).real)
    err = np.abs(np.sqrt(w2[:2] / exact) - 1.0)
    check('boom and load frequencies / closed form - 1 (tension round-off in K)', err, 3e-5)


def _random_poses(m, rng, amp):
    q = m.q0.copy()
    for j in m.K.nl_cols:
        q[j] += amp * rng.standard_normal()
    return q


def test_closed_form_row_jacobian_matches_central_differences_at_random_poses():
    """bodies.rows_jacobian (twists, implicit differentiation of the tangency conditions, wrap
    angles) against bodies.rows_jacobian_fd: 3D tangents between turned sheaves (slewing crane),
    planar sheaves on a rotating and a translating body (beam), anchors on a revolute joint (slew)."""
    from reeve_fmu.core import bodies as B
    rng = np.random.default_rng(1)
    scenes = [build_model(load_scene("scenes/slewing_crane.toml")),
              build_model(loads_scene(_beam_scene(), "beam.toml")),
              build_model(loads_scene(_slew_scene(), "slew.toml")),
              build_model(load_scene("scenes/tower_crane.toml")),            # a trolley on the slewing jib
              build_model(load_scene("scenes/luffing_crane_slewing.toml")),  # a boom on the superstructure
              build_model(loads_scene(GANTRY, "gantry.toml"))]              # an arm on a travelling gantry
    for m in scenes:
        K = m.K
        G_ = B.geometry(K)
        nr, nc = K.nl_rk.shape[0], K.nl_cols.shape[0]
        assert nr > 0 and nc > 0
        for _ in range(4):
            q = _random_poses(m, rng, 0.3)
            J = [np.zeros((nr, nc)), np.zeros((nr, nc))]
            for fun, Jk in zip((B.rows_jacobian, B.rows_jacobian_fd), J):
                fun(q, G_, K.nl_cols, K.nl_colbody, np.zeros(nr), np.zeros(nr), np.zeros(nr), np.zeros(len(q)), Jk)
            check('J[0] - J[1]', J[0] - J[1], 1e-8 * np.max(np.abs(J[1])))


def test_closed_form_rigid_terms_match_the_lagrangian_by_differences():
    """rigid.rigid_terms (Euler equations projected by T(phi)^T) against rigid_terms_fd (Lagrange
    equations with M_r(phi) differentiated numerically), near phi = 0 (series branch) and beyond."""
    m = build_model(load_scene("scenes/slewing_crane.toml"))
    rng = np.random.default_rng(2)
    for amp in (1e-3, 0.3, 2.0):
        q, v = m.q0.copy(), np.zeros(m.nq)
        for j in m.K.rb_q.ravel():
            q[j], v[j] = amp * rng.standard_normal(), rng.standard_normal()
        out = [(np.zeros((m.nq, m.nq)), np.zeros(m.nq)) for _ in range(2)]
        rigid_terms(m.KJ, q, v, *out[0])
        rigid_terms_fd(m.KJ, q, v, *out[1])
        check('rigid mass matrix: closed form - differences', out[0][0] - out[1][0], 2e-14 * np.max(np.abs(out[1][0])),
              reason="round-off, which differs by pose")
        check('rigid quadratic-velocity terms: closed form - differences', out[0][1] - out[1][1],
              5e-9 * np.max(np.abs(out[1][1])), reason="the differences' truncation error, which differs by pose")


def test_closed_form_row_acceleration_matches_the_second_difference():
    """bodies.rows_accel ((dB/dt) v: centripetal terms of turning bodies, touching points sliding on
    turning sheaves, wrap angles) against bodies.rows_accel_fd at random poses and velocities."""
    from reeve_fmu.core import bodies as B
    rng = np.random.default_rng(3)
    for m in (build_model(load_scene("scenes/slewing_crane.toml")), build_model(loads_scene(_beam_scene(), "beam.toml")),
              build_model(load_scene("scenes/tower_crane.toml")), build_model(load_scene("scenes/luffing_crane_slewing.toml")),
              build_model(loads_scene(GANTRY, "gantry.toml"))):
        K = m.K
        G_ = B.geometry(K)
        nr = K.nl_rk.shape[0]
        for _ in range(4):
            q, v = _random_poses(m, rng, 0.3), np.zeros(m.nq)
            v[K.nl_cols] = rng.standard_normal(len(K.nl_cols))
            f0, acc, ref = np.zeros(nr), np.zeros(nr), np.zeros(nr)
            B.rows_eval(q, *G_, -1, f0)
            B.rows_accel_fd(q, v, G_, K.nl_cols, f0, np.zeros(nr), np.zeros(nr), np.zeros(m.nq), ref)
            B.rows_accel(q, v, G_, acc)
            # round-off of the second difference itself (s rows of ~100 m divided by NL_EPS^2)
            check('row acceleration: closed form - second difference', acc - ref, 3e-6 * np.max(np.abs(ref)),
                  reason="round-off of the second difference, which differs by row and pose")


# an arm turning on a gantry that travels (a revolute joint on a prismatic one), a rope over its tip
GANTRY = """
[scene]
model = "spatial"
sheave_contact = "rigid"
[initial]
statics = "none"
[[bodies]]
name = "gantry"
mass = 2000.0
position = [0.0, 0.0, 5.0]
joint = { kind = "prismatic", axis = [1.0, 0.0, 0.0] }
[[bodies]]
name = "arm"
mass = 500.0
inertia = [[50.0, 0.0, 30.0], [0.0, 400.0, 0.0], [30.0, 0.0, 380.0]]
position = [2.0, 0.0, 5.0]
joint = { kind = "revolute", parent = "gantry", axis = [0.0, -1.0, 0.0], pivot = [0.0, 0.0, 5.0] }
[[bodies]]
name = "weight"
mass = 100.0
position = [4.3, 0.0, 0.0]
free = ["x", "y", "z"]
[[sheaves]]
name = "tip"
body = "arm"
center = [2.0, 0.0, 0.0]
radius = 0.3
[[ropes]]
name = "rope"
EA = 1e6
rhoA = 0.5
route = [{ anchor = "ground", at = [-5.0, 0.0, 5.3] }, { sheave = "tip", wrap = "cw" }, { anchor = "weight", at = [0.0, 0.0, 0.0] }]
"""


def _rodrigues(axis, ang):
    a = np.asarray(axis, float)
    K = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(ang) * K + (1.0 - np.cos(ang)) * (K @ K)


def _chain_lagrangian(sc, child, qp, qc, vp, vc, h=1e-30):
    """(M, Q) of a body on a joint on a moving body from its Lagrangian written here: the pose
    (R, x_c) composed from the two joints as rotation matrices, T = m |x_c'|^2 / 2 + w.R J R^T w / 2
    with x_c' and the angular velocity (R' R^T) by complex steps along (vp, vc) (exact); M by
    polarization in the rates, Q = dT/dq - (d/dt dT/dv at zero accelerations) - dV/dq by central
    differences."""
    bodies = {b.name: b for b in sc.bodies}
    c = bodies[child]
    p = bodies[c.parent]
    g = np.array([0.0, 0.0, -9.81])

    def pose(q):
        def joint(b, u):
            if b.joint == "revolute":
                R = _rodrigues(b.joint_axis, u)
                return R, np.asarray(b.pivot) - R @ np.asarray(b.pivot)
            return np.eye(3), u * np.asarray(b.joint_axis)
        Rp, tp = joint(p, q[0])
        Rc, tc = joint(c, q[1])
        return Rp @ Rc, Rp @ (Rc @ np.asarray(c.position) + tc) + tp

    def T(q, v):
        Rq, xq = pose(q + 1j * h * v)
        R = Rq.real
        xd = xq.imag / h
        W = Rq.imag / h @ R.T
        w = np.array([W[2, 1], W[0, 2], W[1, 0]])
        return 0.5 * c.mass * xd @ xd + 0.5 * w @ R @ np.asarray(c.inertia) @ R.T @ w

    q, v = np.array([qp, qc]), np.array([vp, vc])
    E = np.eye(2)
    M = np.array([[T(q, E[i] + E[j]) - T(q, E[i]) - T(q, E[j]) for j in range(2)] for i in range(2)])   # polarization
    H = 1e-4
    Q = np.zeros(2)
    for i in range(2):
        dTdq = (T(q + H * E[i], v) - T(q - H * E[i], v)) / (2 * H)
        # d/dt (M v)_i at zero accelerations = sum_k dM_ik/dq . v
        dMv = sum((np.array([(T(q + H * v, E[i] + E[j]) - T(q + H * v, E[i]) - T(q + H * v, E[j]))
                             - (T(q - H * v, E[i] + E[j]) - T(q - H * v, E[i]) - T(q - H * v, E[j]))
                             for j in range(2)]) / (2 * H)) * v)
        dV = -c.mass * g @ (pose(q + H * E[i])[1] - pose(q - H * E[i])[1]) / (2 * H)
        Q[i] = dTdq - dMv - dV
    return M, Q


@pytest.mark.parametrize("path, child", [("scenes/tower_crane.toml", "trolley"),
                                         ("scenes/luffing_crane_slewing.toml", "boom"), ("gantry", "arm")])
def test_chain_terms_match_the_lagrangian_of_the_composed_pose(path, child):
    """rigid.chain_terms (Newton-Euler projected on the parent's and the own joint coordinate) against
    the Lagrange equations of the child's kinetic and gravity energy written here from its composed pose
    (rotation matrices, differences): a trolley sliding on a slewing jib (Coriolis and centrifugal
    forces) and a boom with a full inertia tensor luffing on a slewing superstructure (gyroscopic
    terms) and an arm with a full inertia tensor turning on a travelling gantry, at random poses and
    rates."""
    from reeve_fmu.core.rigid import chain_terms
    sc = loads_scene(GANTRY, "gantry.toml") if path == "gantry" else load_scene(path)
    m = build_model(sc)
    ip, ic = m.K.ch_q[0]
    rng = np.random.default_rng(5)
    for _ in range(3):
        qp, qc, vp, vc = rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3), rng.normal(), rng.normal()
        q, v = m.q0.copy(), np.zeros(m.nq)
        q[ip], q[ic], v[ip], v[ic] = qp, qc, vp, vc
        M, Q = np.zeros((m.nq, m.nq)), np.zeros(m.nq)
        chain_terms(m.KJ, q, v, M, Q)
        Mr, Qr = _chain_lagrangian(sc, child, qp, qc, vp, vc)
        idx = [ip, ic]
        # measured 2e-16 to 4e-16 of max |M|, 3e-11 to 4e-9 of max |Q| (the differences in q)
        check("chain mass matrix - Lagrangian's", M[np.ix_(idx, idx)] - Mr, 3e-15 * np.max(np.abs(Mr)), reason=ROUNDOFF)
        check("chain forces - Lagrangian's", Q[idx] - Qr, 2e-8 * np.max(np.abs(Qr)),
              reason="the differences' truncation error, which differs by pose")
