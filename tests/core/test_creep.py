"""Rope creep on the rim (sheave_contact = "creep", the default) against exact kinematics.

The rope arrives on a groove at its strain eps_a and rides the rim in adhesion, so the rim speed is the
speed of the *strained* rope: R theta_dot = (1 + eps_a) x material rate. The leaving span's rope then
moves at R theta_dot (1 + eps_l) / (1 + eps_a) (material conservation), and a drum stores
R dtheta / (1 + eps_a) of unstretched rope. The references are these closed forms with eps = T / EA from
hand statics (T = m g; the rope mass is 1e-9 kg/m so its weight changes the strain by < 1e-13), and the
rigid-rim model (sheave_contact = "rigid"), whose material rate is R theta_dot, for the size of the
difference: eps x travel.
"""
from __future__ import annotations

import copy

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

import numpy as np
import pytest

from reeve_fmu.core.kernel import UE_CREEP
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import parse_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.core.solver.inputs import kernel_inputs_at
from reeve_fmu.core.solver.statics import consistent_acceleration, preload_traction
from reeve_fmu.core.system import creep_power
from tests.support import ROOT
from tests.support.checks import check, check_min

ROUNDOFF = "round-off of float64 lengths and speeds, which differs by case and platform"

TEST_SCENES = ROOT / "tests" / "scenes"

G = 9.81
R = 0.3
M_CAR, M_CWT = 1000.0, 1500.0


def one_to_one(mode, EA=1e7, table=None, rhoA=1e-9, J=10.0, slip=False, drive="speed"):
    """1:1 traction elevator, 1D: car | traction sheave (20 m up) | counterweight, speed-driven by a
    speed table (default: 1 m/s from t = 0)."""
    sheave = {"name": "traction", "kind": "traction", "center": [0, 0, 20], "radius": R, "inertia": J}
    if slip:
        sheave.update(slip=True, mu=0.2, creep=1e-3)
    dv = {"kind": "speed", "sheave": "traction", "profile": "table", "table": table or [[0, 1.0], [100, 1.0]]}
    if drive == "none":
        dv = {"kind": "none"}
    return {
        "scene": {"model": "axial-1d", "gravity": [0, 0, -G], "sheave_contact": mode},
        "solver": {"step": 1e-3, "rho_inf": 0.8},
        "bodies": [{"name": "car", "mass": M_CAR, "position": [-R, 0, 0], "free": ["z"]},
                   {"name": "cwt", "mass": M_CWT, "position": [R, 0, 0], "free": ["z"]}],
        "sheaves": [sheave],
        "ropes": [{"name": "rope", "EA": EA, "rhoA": rhoA, "route": [
            {"anchor": "car", "at": [0, 0, 0]}, {"sheave": "traction", "wrap": "cw"},
            {"anchor": "cwt", "at": [0, 0, 0]}]}],
        "drive": dv,
    }


def build(d):
    return build_model(parse_scene(copy.deepcopy(d), "test_creep"))


def start_steady(m, sim, V, eps_in, eps_out, creep):
    """Initial statics, then the steady hoisting velocities at rim speed V (car on the arriving side)."""
    st = sim.initial_state()
    kap = 1.0 + eps_in if creep else 1.0          # material rate = V / kappa
    st.v[m.body_dofs["car"]["z"]] = V * (1 + eps_in) / kap
    st.v[m.body_dofs["cwt"]["z"]] = -V * (1 + eps_out) / kap
    st.v[m.sheave_dof["traction"]] = -V / kap
    if "traction.theta" in m.q_names:
        st.v[m.q_names.index("traction.theta")] = V / R
        preload_traction(m, st, sim.warnings)    # groove friction carries the running tension difference
    consistent_acceleration(m, st)
    return st


@pytest.mark.parametrize("mode,slip", [("creep", False), ("rigid", False), ("creep", True)])
def test_steady_hoisting_rope_speeds_rim_travel_and_torque(mode, slip):
    """Constant rim speed V = 1 m/s, constant tensions m g. Creep: the arriving (car) rope moves at
    R theta_dot and the leaving one at R theta_dot (1 + eps_out)/(1 + eps_in), to round-off; the car
    rises exactly R dtheta; the drive torque is R (T_in - T_out). Rigid rim: the car runs ahead by eps_in R dtheta
    (4.9 mm over 5 m at eps = 9.81e-4) and the torque is off by R (T_in eps_in - T_out eps_out)/2 +
    ... (1.8 N m here): the assumption the creep model replaces. The slipping-sheave model (slip = true,
    groove friction) in adhesion gives the creep kinematics as well."""
    EA, V, T = 1e7, 1.0, 5.0
    ei, eo = M_CAR * G / EA, M_CWT * G / EA
    m = build(one_to_one(mode, EA, slip=slip))
    sim = Simulator(m)
    st = start_steady(m, sim, V, ei, eo, mode == "creep")
    z0 = st.q[m.body_dofs["car"]["z"]]
    res = sim.advance(st, T, out_dt=0.01)
    om, th = res["traction.speed"], res["traction.angle"]
    vc, vw, dz = res["car.velocity"], res["cwt.velocity"], res["car.position"] - z0
    assert abs(R * om[-1] - V) <= 1e-9 * V and abs(R * th[-1] - V * T) <= 1e-9 * V * T  # the rim ran
    if mode == "creep":
        check('arriving rope speed - R theta_dot', vc - R * om, 4e-11 * V, reason=ROUNDOFF)
        check('leaving rope speed + R theta_dot (1 + eps_out)/(1 + eps_in)', vw + R * om * (1 + eo) / (1 + ei), 4e-11 * V,
              reason=ROUNDOFF)
        check('car rise - R dtheta', dz - R * th, 1e-12 * V * T, reason=ROUNDOFF)
        if not slip:
            check('torque - R (T_in - T_out)', res["motor.torque"] - R * (M_CAR - M_CWT) * G, 1.5e-10 * R * M_CAR * G)
    else:
        check('rigid rim: car speed - R theta_dot (1 + eps_in)', vc - R * om * (1 + ei), 4e-11 * V, reason=ROUNDOFF)
        check('rigid rim: car rise - R dtheta (1 + eps_in)', dz - R * th * (1 + ei), 1e-12 * V * T, reason=ROUNDOFF)
        check('rigid rim: run-ahead - eps x travel (4.9 mm)', dz[-1] - R * th[-1] - ei * V * T, 1e-12, reason=ROUNDOFF)
        # the rigid rim takes the strained rope at the rim speed: torque R (T_car (1 + ei/2) -
        # T_cwt (1 + eo/2)): R (M_car - M_cwt) g + R g (M_car ei - M_cwt eo) / 2, the latter -1.804 N m here
        dtau = res["motor.torque"][-1] - R * (M_CAR - M_CWT) * G
        rim = R * G * (M_CAR * ei - M_CWT * eo) / 2
        check('rigid rim: torque offset - R g (M_car eps_in - M_cwt eps_out)/2', dtau - rim, 1.5e-7 * abs(rim))


def drum_hoist(mode, V, EA=1e7):
    """A ground drum (first stop, 30 m stored) paying out (V > 0) or winding (V < 0) a 1000 kg hook."""
    return {
        "scene": {"model": "axial-1d", "gravity": [0, 0, -G], "sheave_contact": mode},
        "bodies": [{"name": "hook", "mass": M_CAR, "position": [R, 0, 0], "free": ["z"]}],
        "sheaves": [{"name": "drum", "kind": "drum", "center": [0, 0, 20], "radius": R, "inertia": 20.0,
                     "stored": 30.0}],
        "ropes": [{"name": "rope", "EA": EA, "rhoA": 1e-9, "route": [
            {"sheave": "drum", "wrap": "cw"}, {"anchor": "hook", "at": [0, 0, 0]}]}],
        "drive": {"kind": "speed", "sheave": "drum", "profile": "table", "table": [[0, V], [100, V]]},
    }


def steady_drum(mode, V, EA):
    """The drum hoist at rest (statics), then moving steadily at rim speed V: (model, simulator,
    state, kappa)."""
    eps = M_CAR * G / EA
    m = build(drum_hoist(mode, V, EA))
    sim = Simulator(m)
    st = sim.initial_state()
    kap = 1.0 + eps if mode == "creep" else 1.0
    st.v[m.sheave_dof["drum"]] = -V / kap
    st.v[m.body_dofs["hook"]["z"]] = -V * (1 + eps) / kap
    consistent_acceleration(m, st)
    return m, sim, st, kap


@pytest.mark.parametrize("mode,V", [("creep", 1.0), ("creep", -1.0), ("rigid", 1.0)])
def test_drum_stored_length_against_angle_and_arriving_strain(mode, V):
    """The rope stored on a drum (its unstretched length, the drum's s coordinate) changes by
    -R dtheta / (1 + eps) paying out and winding at the span strain eps = m g / EA (creep) and by
    -R dtheta with the rigid rim; the hook moves R dtheta with creep."""
    EA, T = 1e7, 3.0
    m, sim, st, kap = steady_drum(mode, V, EA)
    j, jz = m.sheave_dof["drum"], m.body_dofs["hook"]["z"]
    s0, z0 = st.q[j], st.q[jz]
    res = sim.advance(st, T, out_dt=0.01)
    th = res["drum.angle"]
    check('rim travel - V T', R * th[-1] - V * T, 1e-11 * T, reason=ROUNDOFF)
    stored = st.q[j] - s0
    check('stored length + R dtheta / kappa', stored + R * th[-1] / kap, 1e-12 * T, reason=ROUNDOFF)
    if mode == "creep":
        check('hook travel - R dtheta', -(res["hook.position"] - z0) - R * th, 3e-12 * T, reason=ROUNDOFF)


@pytest.mark.parametrize("n", [1, 3])
def test_arriving_strain_of_a_heavy_rope_is_its_strain_at_the_groove(n):
    """kappa = 1 + eps where the rope meets the groove, not the element's mean strain: a heavy rope
    (rhoA = 5 kg/m, 20 m spans) at rest on a 1:1 sheave, kappa = 1 + (eps_car + eps_cwt)/2 with each
    side's strain at the top from hand statics of a hanging rope with an end mass (material length l
    from ell = l + (M g l + rhoA g l^2/2)/EA, tension M g + rhoA g l), with one and three linear
    elements per span (the elements' mean strains are 3.7 % of eps off)."""
    EA, rhoA = 1e7, 5.0

    def top_strain(M, ell):
        a, b = rhoA * G / (2 * EA), 1 + M * G / EA
        l = (-b + np.sqrt(b * b + 4 * a * ell)) / (2 * a)
        return (M * G + rhoA * G * l) / EA
    d = one_to_one("creep", EA=EA, rhoA=rhoA, table=[[0, 0.0], [100, 0.0]])
    d["ropes"][0]["elements_per_span"] = n
    m = build(d)
    sim = Simulator(m)
    st = sim.initial_state()
    kap = kernel_inputs_at(m, st)[UE_CREEP]
    eps = 0.5 * (top_strain(M_CAR, 20 - st.q[m.body_dofs["car"]["z"]])
                 + top_strain(M_CWT, 20 - st.q[m.body_dofs["cwt"]["z"]]))
    check('kappa - 1 - eps at the groove', kap - 1 - eps, 2e-13 * eps, reason=ROUNDOFF)


@pytest.mark.parametrize("mode,V", [("creep", 0.0), ("creep", 1.0), ("creep", -1.0), ("rigid", 0.0)])
def test_drum_torque_is_radius_times_tension(mode, V):
    """Holding, paying out and winding at constant speed and load: the drum torque is R T, T the
    rope's tension where it leaves the drum (moment balance of the drum). With creep the stored rope
    keeps its strain, so its strain energy EA eps^2/2 per unit material pulls on the drum's s like the
    span does; without that term the torque would be R T (1 - eps/2), 1.44 N m low here. The rigid rim
    stores the rope unstrained: R T (1 + eps/2) (the assumption creep replaces; 1.44 N m high)."""
    EA = 1e7
    eps = M_CAR * G / EA
    m, sim, st, _ = steady_drum(mode, V, EA)
    res = sim.advance(st, 2.0, out_dt=0.01)
    RT = R * res["rope.tension_start"]
    expect = RT if mode == "creep" else RT * (1 + eps / 2)
    check('R T - R m g (constant load)', RT[-1] - R * M_CAR * G, 5e-11 * R * M_CAR * G)
    check('drum torque + R T (rigid: R T (1 + eps/2))', res["motor.torque"] + expect, 1e-13 * R * M_CAR * G,
          reason="round-off: 0 to 2.9e-11 N m of R m g = 2.9e3 N m (the stored rope weighs at the drum)")


def test_drum_pays_out_at_the_strain_it_wound_with():
    """Wind 3 m at load A (1000 kg), stop, halve the load at rest (the state carried over to the same
    scene with 500 kg), pay the same 3 m of rim out at load B. The drum returns its wound rope last in
    first out at the strain it was wound with, so the stored length (the drum's s) comes back to its
    start and the hook hangs on the start's span material at eps_B: it stands (eps_A - eps_B) x
    20 m / (1 + eps_A) = 9.8 mm above its start. Measured 2.7e-7 m on both (the record's 5 cm bins mix
    the strains of the acceleration ramps); paying out at the span's current strain (the drum
    before its wound-rope record) was 1.48 mm off, (eps_A - eps_B) x 3 m."""
    table = [[0, 0], [1, -1], [3, -1], [4, 0], [9, 0], [10, 1], [12, 1], [13, 0], [100, 0]]
    sims = []
    for mass in (M_CAR, M_CAR / 2):
        d = drum_hoist("creep", 0.0)
        d["bodies"][0]["mass"] = mass
        d["ropes"][0]["damping"] = 0.05          # settles the load change (zeta ~ 0.5)
        d["drive"]["table"] = table
        sims.append(Simulator(build(d)))
    m = sims[0].model
    j, jz = m.sheave_dof["drum"], m.body_dofs["hook"]["z"]
    st = sims[0].initial_state()
    s0, z0 = st.q[j], st.q[jz]
    sims[0].advance(st, 6.0)
    sims[1].advance(st, 17.0)
    eA, eB = M_CAR * G / 1e7, M_CAR / 2 * G / 1e7
    assert abs(st.v[jz]) < 1e-9 and abs(st.info[10]) < 1e-10     # at rest, the drum back at its angle
    check('stored length back at its start [m]', st.q[j] - s0, 1e-6)
    check('hook height - (eps_A - eps_B) 20 m / (1 + eps_A)', st.q[jz] - z0 - (eA - eB) * 20.0 / (1 + eA), 1e-6)


def test_material_through_the_sheave_over_a_whole_trip():
    """Rope material over a whole trip, rest to rest (1 m/s, 8 m, 0.5 m/s^2 ramps, no damping): the car
    span's material l changes by what crossed the sheave, moved = int R theta_dot / (1 + eps_a(t)) dt
    with eps_a = T_car / EA at the arriving tangent point. The car hangs on the span's stretched length,
    so it rises dz = (1 + eps_1) moved - (eps_1 - eps_0) l_0 (eps_1 = T_car / EA at the end: the car still
    oscillates, undamped; l_0 = L_0 / (1 + eps_0) from the initial span length L_0). The integral is taken here by the trapezoid rule from the outputs (rim speed, tension
    at the sheave), i.e. not from the material coordinates: a wrong arriving side, strain or blend
    shows (the rigid rim's R dtheta (1 + eps_0) is 7.8 mm off). Measured 4.9e-8 m over 8 m (the
    trapezoid rule on the 1 ms output grid against the solver's per-step integration). The rope's total material (spans + wraps
    + stored) is an identity of the elimination p = B q + c (tests/oracles/test_engine_oracles.py checks that
    bookkeeping); this is the physical statement."""
    EA = 1e7
    table = [[0, 0.0], [2, 1.0], [8, 1.0], [10, 0.0], [12, 0.0]]
    m = build(one_to_one("creep", EA, table=table))
    sim = Simulator(m, rho_inf=1.0)
    st = sim.initial_state()
    z0 = st.q[m.body_dofs["car"]["z"]]
    res = sim.advance(st, 12.0, out_dt=1e-3)
    t = np.concatenate([[0.0], res.time])
    om = np.concatenate([[0.0], res["traction.speed"]])
    T = res["traction.tension_in"]
    eps0 = M_CAR * G / EA
    l0 = (20.0 - z0) / (1.0 + eps0)          # the span runs from the car up to the tangent point at z = 20
    ea = np.concatenate([[eps0], T / EA])
    f = R * om / (1.0 + ea)
    moved = float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(t)))
    dz = st.q[m.body_dofs["car"]["z"]] - z0
    assert moved > 7.9
    e1 = T[-1] / EA
    check('car rise - material through the sheave [m]', dz - ((1.0 + e1) * moved - (e1 - eps0) * l0), 2e-7)
    assert abs(dz - (1.0 + eps0) * R * res["traction.angle"][-1]) > 5e-3


def _atwood_driven(mode, tau):
    """The Atwood machine of tests/scenes/atwood.toml with 50 m hanging per side, W1 wrap, a rim
    inertia of 0.02 kg m^2 and a constant drive torque tau on the (traction) pulley."""
    d = tomllib.loads((TEST_SCENES / "atwood.toml").read_text(encoding="utf-8"))
    for b in d["bodies"]:
        b["position"][2] = -50.0
    d["scene"]["sheave_contact"] = mode
    d["sheaves"][0].update(kind="traction", inertia=0.02)
    d["drive"] = {"kind": "torque", "sheave": "pulley", "torque": [[0.0, tau], [100.0, tau]]}
    return d


def test_energy_balance_with_drive_work_and_creep_dissipation():
    """Work of the drive torque = change of kinetic + gravity + strain energy + creep dissipation
    (no damping; generalized-alpha rho_inf = 1, h = 1e-3, the dissipation integrated by the trapezoid
    rule per step). Over 5 s (the rope runs ~7 m over the pulley, tensions differ by up to ~100 N at
    EA = 2e4 N) the balance closes to <= 3e-7 of the largest kinetic energy (second order: h / 2
    divides it by 4): the rim kinematics, its inertia and the creep force are energy-consistent."""
    tau, h, t_end = 3.0, 1e-3, 5.0
    m = build(_atwood_driven("creep", tau))
    sim = Simulator(m, step=h, rho_inf=1.0)
    st = sim.initial_state()
    E0 = sum(sim.energy(st))
    ith = m.output_names.index("motor.angle")
    P0, D, err, Tmax = creep_power(m.KJ, st.arrays(), st.c, st.q, st.v), 0.0, 0.0, 0.0
    for k in range(int(round(t_end / h))):
        sim.advance(st, (k + 1) * h)
        P1 = creep_power(m.KJ, st.arrays(), st.c, st.q, st.v)
        D += 0.5 * h * (P0 + P1)
        P0 = P1
        T, Vg, U = sim.energy(st)
        W = tau * sim.outputs(st)[ith]
        err = max(err, abs(T + Vg + U + D - W - E0))
        Tmax = max(Tmax, T)
    check_min("creep dissipation [J]", D, 0.01)
    check_min("largest kinetic energy [J]", Tmax, 100.0)
    check('energy balance residual', err, 3e-7 * Tmax)


def test_infinitely_stiff_rope_recovers_the_rigid_rim():
    """A trip (1 m/s, 8 m at 0.5 m/s^2 ramps, no damping): the car's end position with creep minus that
    with the rigid rim is -eps x travel (car on the arriving side, eps = m g / EA), within 5 % at
    EA = 1e7 N (the strain differs in the ramps and the car still oscillates) and within 0.5 % at
    EA = 1e10 N, where it is 8 um: the rigid rim is the EA -> inf
    limit of the creep model."""
    table = [[0, 0.0], [2, 1.0], [8, 1.0], [10, 0.0], [12, 0.0]]
    diff = {}
    for EA in (1e7, 1e10):
        z = {}
        for mode in ("creep", "rigid"):
            m = build(one_to_one(mode, EA, table=table))
            sim = Simulator(m)
            st = sim.initial_state()
            z0 = st.q[m.body_dofs["car"]["z"]]
            sim.advance(st, 12.0)
            z[mode] = st.q[m.body_dofs["car"]["z"]] - z0
        diff[EA] = z["creep"] - z["rigid"]
    travel = 8.0
    check('rigid - creep drift / (eps travel) - 1, EA = 1e7', diff[1e7] / (-(M_CAR * G / 1e7) * travel) - 1.0, 0.05)
    check('rigid - creep drift / (eps travel) - 1, EA = 1e10', diff[1e10] / (-(M_CAR * G / 1e10) * travel) - 1.0, 0.005)
    check('rigid - creep drift, EA = 1e10 [m]', diff[1e10], 1e-5)


def test_reversal_is_smooth():
    """The rim decelerates at 1 m/s^2 through zero speed (a reversal at t = 1 s; the arriving side
    changes from the car span to the counterweight span). Tensions and the car's acceleration stay
    continuous: their largest change between 1 ms samples around the reversal is at most that of the
    rigid rim (no regime switch) and creep and rigid tensions differ by O(eps)."""
    table = [[0, 1.0], [2, -1.0], [100, -1.0]]
    out = {}
    for mode in ("creep", "rigid"):
        m = build(one_to_one(mode, 1e7, table=table))
        sim = Simulator(m)
        ei, eo = M_CAR * G / 1e7, M_CWT * G / 1e7
        st = start_steady(m, sim, 1.0, ei, eo, mode == "creep")
        res = sim.advance(st, 1.5, out_dt=1e-3)
        w = (res.time > 0.9) & (res.time < 1.1)
        out[mode] = {n: res[n][w] for n in ("traction.tension_in", "traction.tension_out",
                                             "car.acceleration")}
    for n, y in out["creep"].items():
        jump_c = np.max(np.abs(np.diff(y)))
        jump_r = np.max(np.abs(np.diff(out["rigid"][n])))
        check(f"{n}: largest 1 ms change, creep / rigid rim", jump_c / jump_r, 1.01)
        if "tension" in n:
            check('creep - rigid output', y - out["rigid"][n], 5e-3 * M_CWT * G)


def test_drum_running_empty_is_an_event_naming_the_drum():
    """Paying out 1 m/s from a drum that stores 1 m: the run stops at ~1 s with an error naming the
    drum, the state left at the last good step (stored length still >= 0) and the results so far kept."""
    from reeve_fmu.core.solver import SolverError
    d = drum_hoist("creep", 1.0)
    d["sheaves"][0]["stored"] = 1.0
    m = build(d)
    sim = Simulator(m)
    st = sim.initial_state()
    with pytest.raises(SolverError, match=r"drum 'drum'.*stored length") as err:
        sim.advance(st, 3.0, out_dt=0.01)
    assert 0.9 < st.t < 1.1 and st.q[m.sheave_dof["drum"]] > 0.0
    res = err.value.result            # the outputs up to the last good step are kept
    assert res.time[-1] == st.t and len(res.time) > 0.9 / 0.01


def test_creep_arc_exceeding_the_wrap_is_reported():
    """A no-slip traction sheave whose tension ratio (1.5 statically) exceeds e^(f alpha) (mu = 0.05,
    180 deg, the default undercut groove: f = 1.89 mu, limit 1.35) gets a warning naming it; with
    mu = 0.3 (limit 5.9) none."""
    for mu, warned in ((0.05, True), (0.3, False)):
        d = one_to_one("creep", table=[[0, 0.0], [2, 0.5]])    # a gentle start: no slack
        d["sheaves"][0]["mu"] = mu
        d["scene"]["t_end"] = 0.05
        sim = Simulator(build(d))
        sim.run(0.05, 0.01)
        hits = [w for w in sim.warnings if "'traction'" in w and "creep arc" in w]
        assert bool(hits) == warned
