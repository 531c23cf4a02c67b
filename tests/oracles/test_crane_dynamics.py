"""Axial-torsion coupling in the dynamic engine: the hook block's yaw while hoisting against the
quasi-static closed form of a two-fall reeving and against the torque balance of the 8-fall block
(written in this file), and the torsion forces against the gradient of the torsion energy (exact
tangents, rotation-vector block, twist coordinates)."""
import math
from dataclasses import replace

import numpy as np
import pytest

from reeve_fmu.core.model import build_model, new_state
from reeve_fmu.core.scene import SceneError, load_scene, parse_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.core.system import assemble, energy
from tests.support.checks import check, check_min

SCENE = "scenes/crane_two_fall_hoist.toml"
K_D_AB = 4 * 0.08 * 0.022 / (0.5 * 0.5)     # 4 k d / (a b): sin(psi) = K_D_AB h


def _fall_length(z_cm):
    """h: fall tops at z = 0, the block's sheave axle 0.5 m above its centre of mass (the lower
    tangent points stay at the axle's height to ~1e-4 m while the falls lean by psi b / (2 h))."""
    return -(z_cm + 0.5)


def _yaw_reference(t, h, psi0):
    """The block's yaw as one degree of freedom: I psi'' + c psi' = 2 k d S - S a b sin(psi) / (2 h) with
    S = M g / 2 per fall (the torque factor's moment against the falls' lean), h(t) the fall length
    of the run, block inertia 300 kg m^2 and yaw damping 100 N m s/rad of the scene; at rest it is the
    closed form sin(psi) = 4 k d h / (a b). Integrated by scipy to 1e-10."""
    from scipy.integrate import solve_ivp

    W = 15500.0 * 9.81

    def rhs(s, u):
        H = np.interp(s, t, h)
        return [u[1], (0.08 * 0.022 * W - W * 0.25 * math.sin(u[0]) / (4.0 * H) - 100.0 * u[1]) / 300.0]
    return solve_ivp(rhs, (0.0, t[-1]), [psi0, 0.0], t_eval=t, rtol=1e-10, atol=1e-12, max_step=0.01).y[0]


def test_lowering_follows_the_quasi_static_yaw():
    """Lowering the block 10 m (h = 5.1 -> 15.1 m) in dynamics: the yaw follows the one-degree-of-freedom
    yaw equation of the two-fall block (lag while moving included) from the closed-form equilibrium, and
    the model's static equilibrium along the way is the closed form sin(psi) = 4 k d h / (a b)."""
    m = build_model(load_scene(SCENE))
    sim = Simulator(m)
    res = sim.run()
    h = _fall_length(res["block.position.z"])
    psi = res["block.rotation.z"]
    ref = _yaw_reference(res.time, h, math.asin(K_D_AB * h[0]))
    span = np.ptp(ref)
    check_min("two-fall yaw range of the lowering [rad]", span, 0.29)     # h 5.1 -> 15.1 m
    # the reference's inertia and damping are the model's; measured 4.7e-5 rad (1.6e-4 of the range)
    check('two-fall yaw - one-dof yaw equation', psi - ref, 1.5e-3 * span)
    st0 = sim.initial_state()
    jd = m.sheave_dof["drum"]
    psi_qs, psi_cf = [], []
    for t in (0.0, 20.0, 50.0):
        i = int(np.argmin(np.abs(res.time - t)))
        q = st0.q.copy()
        q[jd] += res["motor.angle"][i] / m.K.mot_gain      # the drum where the run has it
        st = sim.statics.solve(new_state(m, q=q), "rope-length")
        psi_qs.append(st.q[m.body_dofs["block"]["rz"]])
        psi_cf.append(math.asin(K_D_AB * _fall_length(st.q[m.body_dofs["block"]["z"]])))
    # the equilibrium against the closed form (the torsion moment is 2 k d S): measured 5.4e-5, of which
    # 3.7e-5 is the falls' lean the closed form neglects (tests/support/hook_block.py), the rest the rope's weight
    check('static yaw / closed form - 1', np.array(psi_qs) / np.array(psi_cf) - 1.0, 5e-4)
    tilt = np.max(np.abs(res["block.rotation.x"])) + np.max(np.abs(res["block.rotation.y"]))
    check('block tilt while lowering [rad]', tilt, 9e-6)


def test_torsion_forces_are_the_energy_gradient():
    """Costello law (an energy): Q of an assembly at rest = -d(V_gravity + U_strain + U_torsion)/dq
    at a perturbed pose and twist, by central differences of the energy. On the rigid rim: with creep
    the drum's stored rope pulls on its s with EA eps^2/2 (the strain energy it was wound with, a
    matter of its history that energy() of the pose does not hold; tests/core/test_creep.py checks it)."""
    sc = replace(load_scene(SCENE), sheave_contact="rigid")
    rope = sc.ropes[0]
    tor = replace(rope.torsion, law="costello", k0=0.006, GJ0=1000.0)
    m = build_model(replace(sc, ropes=(replace(rope, torsion=tor),)))
    st = Simulator(m).initial_state()
    rng = np.random.default_rng(1)
    q = st.q.copy()
    q[:6] += rng.normal(0.0, [1e-3, 1e-3, 1e-3, 2e-2, 2e-2, 5e-2])
    tw = [i for i, n in enumerate(m.q_names) if n.endswith(".twist")]
    assert len(tw) == 2                                    # tip and hook; drum and dead end clamped
    q[tw] += rng.normal(0.0, 0.1, len(tw))
    nq = m.nq
    Q = np.zeros(nq)
    assemble(m.KJ, st.arrays(), st.c, q, np.zeros(nq), 0.0, np.zeros(2), np.zeros((nq, nq)), Q)

    def V(x):
        _, Vg, U = energy(m.KJ, st.arrays(), st.c, x, np.zeros(nq))
        return Vg + U
    g = np.zeros(nq)
    for j in range(nq):
        dx = 1e-6 * (1.0 + abs(q[j]))
        a, b = q.copy(), q.copy()
        a[j] += dx
        b[j] -= dx
        g[j] = (V(a) - V(b)) / (2.0 * dx)
    scale = np.abs(Q).max()
    check('torsion forces + energy gradient', Q + g, 1e-6 * scale)


def test_costello_needs_a_positive_definite_energy():
    text = open(SCENE).read().replace('law = "torque-factor", diameter = 0.022, k0 = 0.08',
                                      'law = "costello", diameter = 0.022, k0 = 0.08, GJ0 = 50.0')
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib
    with pytest.raises(SceneError, match=r"ropes\[0\].torsion.GJ0\] the costello law needs GJ0 EA"):
        parse_scene(tomllib.loads(text), "crane.toml")   # needs GJ0 > 70.6 N m^2


EIGHT_HOIST = "scenes/crane_8fall_hoist.toml"


def _as_crane(path, **sets):
    """The crane of a dynamic scene: its [crane] section added (block and a height range)."""
    from reeve_fmu.studies.crane import load_crane
    return load_crane(path, {"crane.block": "block", "crane.height_min": 2.0, "crane.height_max": 40.0, **sets})


def _eight_fall_yaw(sc, h):
    """Quasi-static yaw of the 8-fall block at fall length h, from the torque balance about the vertical,
    written from the scene's numbers (independent of the engine and of `reeve-fmu crane`).

    At rest every fall hangs vertically from the tip to the block sheave at the same plan position p_i
    (x = +-R of the block sheave, y its centre). Yawed by psi, the block carries the fall's lower end to
    R(psi) p_i; a fall of tension S pulls it back with the moment S |p_i|^2 sin(psi) / L_i (L_i its
    chord). S is the fall's mean tension, W/n + w h/2 (w = rhoA g): the falls share the block's weight
    W, and their own weight adds half of it on average. The rope torque M is the same in every span at
    rest (the twist passes the sheaves freely), M = k0 d S + G' kappa with G' = GJ0 - EA d^2 k0^2 (the
    Costello law at the span's tension S); between the drum and the dead end, where the twist is
    clamped, the yaw twists each of the n falls by -psi, so with L_r the length of those spans and
    <S> their length-mean tension, M = k0 d <S> - G' n psi / L_r. The drum span (from the drum to the
    lead sheave, rising dz) carries the falls' top tension W/n + w h less w dz/2 on average. The
    balance is n M = sum_i S |p_i|^2 sin(psi) / L_i."""
    from scipy.optimize import brentq

    g, n = 9.81, 8
    sh = {x.name: x for x in sc.sheaves}
    rope, = sc.ropes
    tor = rope.torsion
    W, w = sc.bodies[0].mass * g, rope.rhoA * g
    p2 = [sh[b].radius ** 2 + sh[b].center[1] ** 2 for b in ("B1", "B2", "B3", "B4") for _ in (0, 1)]
    drum, lead = np.array(sh["drum"].center), np.array(sh["lead"].center)
    l0 = math.sqrt(np.sum((lead - drum) ** 2) - (sh["drum"].radius - sh["lead"].radius) ** 2)   # cw, cw
    dz = lead[2] - drum[2]
    S = W / n + w * h / 2
    L_r = l0 + n * h
    S_mean = (l0 * (W / n + w * h - w * dz / 2) + n * h * S) / L_r
    G = tor.GJ0 - rope.EA * tor.diameter ** 2 * tor.k0 ** 2

    def balance(psi):
        M = tor.k0 * tor.diameter * S_mean - G * n * psi / L_r
        return n * M - sum(S * q * math.sin(psi) / math.sqrt(h * h + 2 * q * (1 - math.cos(psi))) for q in p2)
    return brentq(balance, 0.0, 1.0, xtol=1e-15)


def test_eight_fall_slow_hoist_follows_the_quasi_static_yaw():
    """The 8-fall block lowered 20 m (h = 10 -> 30 m) at half the scene's rope speed, Costello
    k0 = 0.006: the dynamic yaw starts on the quasi-static yaw of the torque balance (_eight_fall_yaw),
    stays within 1 % of its range while moving (lag) and settles onto it.

    The rope is 10 x stiffer than the scene's. Nothing in the yaw depends on EA beyond the twist
    stiffness G', which the closed form carries."""
    sc = load_scene(EIGHT_HOIST)
    rope, = sc.ropes
    sc = replace(sc, t_end=180.0, drive=replace(sc.drive, v_max=1.0), ropes=(replace(rope, EA=10.0 * rope.EA),))
    res = Simulator(build_model(sc)).run()
    idx = np.arange(0, len(res.time), 20)
    dyn = res["block.rotation.z"][idx]
    h = -(res["block.position.z"][idx] + 1.0)                 # the block's sheave shaft 1 m above its centre of mass
    ref = np.array([_eight_fall_yaw(sc, x) for x in h])
    span = np.ptp(ref)
    check_min("8-fall yaw range of the lowering [rad]", span, 0.016)      # h 10 -> 30 m
    err = np.abs(dyn - ref) / span
    check('8-fall yaw - closed form, / yaw range (lag while moving)', err.max(), 0.01)
    check('8-fall yaw - closed form at rest, / yaw range', err[0], 7e-5)        # measured 7.0e-6
    check('8-fall yaw - closed form settled, / yaw range', err[-1], 2e-4)       # measured 2.3e-5


def test_cabling_height_by_yaw_continuation_of_the_dynamic_model():
    """The 8-fall hoist with a 6-strand rope (k0 = 0.08): the statics continued in the block yaw from
    the dynamic scene's equilibrium (h = 10 m, rope paid out from the drum) reaches the fold where the
    height sweep of crane_8fall.toml (continuation in h from 5 m, the yaw only near the fold) reports
    cabling."""
    from reeve_fmu.studies.crane import cabling_of_model, load_crane, sweep
    from reeve_fmu.studies.overrides import parse_value
    six = {"rope.torsion": parse_value('{law = "costello", diameter = 0.022, k0 = 0.08, GJ0 = 100.0}')}
    crane = _as_crane(EIGHT_HOIST, **six)
    path = cabling_of_model(crane, crane.sim.initial_state())
    ref = sweep(load_crane("scenes/crane_8fall.toml", {**six, "crane.heights": 60}))
    assert np.all(np.diff(path.height) > 0) and len(path.yaw) > 50
    check('cabling height by yaw continuation - sweep [m]', path.critical_height - ref.critical_height, 1e-6 * ref.critical_height)
    check('cabling yaw by yaw continuation - sweep [rad]', path.critical_yaw - ref.critical_yaw, 2e-6)


def test_two_fall_statics_by_yaw_continuation_against_the_exact_equilibrium():
    """The dynamic two-fall model's statics at prescribed yaws up to 1 rad (h = 7 -> 30 m, rope paid out
    from the drum). With a weightless rope (a millionth of its weight) they are the exact equilibrium
    (tests/support/hook_block.py) to the statics' round-off. With the rope's weight, sin psi = 4 k d h / (a b)
    to 4.3e-5 at 7 m, 6.5e-5 at 30 m: of that, 3.7e-5 to 4.0e-5 is the falls' lean the closed form
    neglects (tests/studies/test_crane.py), the rest the rope's weight. The W1 wraps' rope weight follows
    the wrap angles (bodies.wrap_weight); without it the error grew with h to -0.69 % at h = 20 m."""
    from reeve_fmu.studies.crane import Statics
    from tests.support.hook_block import HookBlock
    err = {}
    for sets in ({}, {"rope.rhoA": 2.4e-6}):
        crane = _as_crane(SCENE, **sets)
        S = Statics(crane, crane.sim.initial_state())
        ref = HookBlock(crane.scene) if sets else None
        q = S.st.q
        for psi in np.arange(0.2, 1.01, 0.1):
            q, _ = S.solve(q, "yaw", psi)
            h = crane.height(q)
            e = math.sin(psi) / (K_D_AB * h) - 1.0 if ref is None else h / ref.equilibrium(psi)[0] - 1.0
            err.setdefault(bool(sets), []).append(e)
    check('sin(psi) at prescribed yaw / closed form - 1', err[False], 4.3e-4)
    check('h at prescribed yaw / exact - 1 (weightless rope)', err[True], 7.5e-8)        # measured 8.0e-9


def test_slow_lowering_cables_where_the_sweep_finds_the_fold():
    """Two falls lowered in dynamics past the critical height (yaw damper, rope speed 0.1 and 0.05 m/s):
    the yaw passes 90 deg and the block spins (cabling) a little below the sweep's fold, later the faster
    the lowering (slow passage through a fold: the delay in h grows as v^(2/3)); extrapolated to v -> 0
    that height is the sweep's critical height."""
    from reeve_fmu.studies.crane import sweep
    sc = load_scene(SCENE)
    h90 = []
    for v in (0.1, 0.05):
        run = replace(sc, t_end=2.0 + 64.0 / v + 10.0, drive=replace(sc.drive, distance=64.0, v_max=v))
        res = Simulator(build_model(run)).run()
        past = np.flatnonzero(np.abs(res["block.rotation.z"]) > math.pi / 2)
        assert len(past)
        check_min("block yaw at the end of the run: spun [rad]", res["block.rotation.z"][-1], 10.0,
                  reason="past the fold the block spins on until the run ends: how far depends on the time left")
        h90.append(_fall_length(res["block.position.z"][past[0]]))
    Hc = sweep(_as_crane(SCENE)).critical_height
    lag = np.array(h90) / Hc - 1
    assert np.all(lag > 0)                                               # the fold is passed late
    check("height at 90 deg / sweep's critical height - 1 (slow passage)", lag, 0.015)
    a, b = 0.1 ** (2 / 3), 0.05 ** (2 / 3)
    h0 = (h90[1] * a - h90[0] * b) / (a - b)                             # h90 = h0 + c v^(2/3)
    check('cabling height extrapolated to v -> 0 - sweep [m]', h0 - Hc, 3e-3 * np.max(np.abs(Hc)))
