"""Hard cases (docs/hard-cases.md): slack and snap, vanishing span, buffer impact, emergency stop,
extreme parameters, each against an exact result where one exists (Newton's law in free flight, the
spring-damper impact, the wave solution of the snap load). Each must run or stop with a clear event -
never NaN or an unexplained failure."""
from dataclasses import replace
import math

import numpy as np
import pytest

from reeve_fmu.core.elements.linear import axial_law
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from reeve_fmu.core.solver import SolverError, Simulator
from reeve_fmu.studies.fidelity import configure, parse_accuracy, select
from reeve_fmu.studies.snapload import Hoist, converged_peak, lumped_chain, single_mode_peak
from tests.support import ROOT
from tests.support.checks import check

HARD = ROOT / "scenes" / "hard"


def run(scene, t_end=None, dt=1e-3):
    m = build_model(scene)
    sim = Simulator(m)
    return m, sim.run(scene.t_end if t_end is None else t_end, dt)


def finite_except_ratios(res):
    cols = [i for i, n in enumerate(res.names) if not n.endswith("traction_ratio")]
    return bool(np.all(np.isfinite(res.values[:, cols])))


def test_slack_rope_snaps_taut_without_solver_failure():
    """Empty car going up, traction sheave stopped in 0.1 s: the car flies on, its ropes go slack and
    snap taut again. A slack rope carries nothing and reports 0 N. The car is not in exact free fall here: in the 1D model a slack span stays straight between
    its ends, so its ~100 kg of rope moves with the 1300 kg car (exact free fall of a body on a slack rope:
    test_free_fall_onto_a_buffer_against_the_closed_form)."""
    m, res = run(load_scene(HARD / "slack_hard_stop.toml"))
    assert finite_except_ratios(res)
    T = res["car_sheave.tension_in"]
    t = res.time
    T_out = res["car_sheave.tension_out"]
    slack = (np.maximum(T, T_out) <= 0.0) & (t > 8.1)       # both falls at the car
    assert slack.sum() * 1e-3 > 0.5                          # 1.30 s of slack after the stop
    # the first snap: the car falls back onto its ropes at v_r (read at the first taut sample before the
    # peak: a slack span reports 0 N, not its weight and inertia share). A spring-mass catch from zero
    # tension, 1/2 k d^2 = M_e g d + 1/2 M_e v_r^2, with the car-side rope (two falls and the wrap, 6 ropes)
    # in series with the 6 hitch springs, T = k d / 2 (2:1): the massless rope (M_e = M) gives 24.62 kN;
    # the model's peak is 24.21 kN, -1.6 %: the one-mode catch leaves out the rope's Kelvin-Voigt damping
    # and its slack mass, which the falls take up along their length, not at the car's speed
    k_peak = int(np.argmax(np.where(t > 8.1, T, 0.0)))
    j = int(np.flatnonzero(slack[:k_peak])[-1]) + 1
    v_r = -res["car.velocity"][j]
    fall = 42.5 - (res["car.position"][j] + 2.5)             # hitch and traction sheave at 42.5 m
    L_rope = 2.0 * fall + math.pi * 0.16
    c = 2.0 / (L_rope / (6 * 2.9e6) + 1.0 / (6 * 60e3))      # T per m of car drop
    k = 2.0 * c

    def catch(M_e):
        return c * (M_e * 9.81 + math.sqrt((M_e * 9.81) ** 2 + k * M_e * v_r ** 2)) / k
    assert 1.1 < v_r < 1.3, v_r                                   # 1.180 m/s
    check("snap peak / massless one-mode catch - 1", T[k_peak] / catch(1300.0) - 1.0, 0.06,
          reason="an approximate model (above): the measured -1.6 % is its error, not the engine's")
    a = res["car.acceleration"][slack]
    check("car acceleration + g while slack [m/s^2] (rope mass, above)", a + 9.81, 1.5)


def test_vanishing_span_stops_with_a_clear_event():
    sc = load_scene(HARD / "vanishing_span.toml")
    m = build_model(sc)
    sim = Simulator(m)
    with pytest.raises(SolverError) as exc:
        sim.run(sc.t_end, 1e-3)
    msg = str(exc.value)
    assert "rope 'hoist' span 0 (ground anchor -> car_sheave)" in msg
    assert "solver.min_span = 0.02 m" in msg
    t_event = float(msg.split("t = ")[1].split(" s")[0])
    assert 26.0 < t_event < sc.t_end


def test_buffer_impact_at_115_percent_speed():
    """Full R1 car on a Kelvin-Voigt pit buffer at 1.84 m/s: the peak buffer force is c v_hit at the
    contact instant (c^2 > k M: the force only falls after contact); the car comes to rest on it."""
    m, res = run(load_scene(HARD / "buffer_impact.toml"))
    assert finite_except_ratios(res)
    F = res["car_buffer.force"]
    z = res["car.position"]
    v = res["car.velocity"]
    i = np.argmax(z < -0.2)                                  # first sample in contact
    v_hit = abs(np.interp(-0.2, [z[i], z[i - 1]], [v[i], v[i - 1]]))
    check("v_hit / 1.84 - 1 (115 % of 1.6 m/s)", v_hit / 1.84 - 1, 0.01)
    check("peak buffer force / (c v_hit) - 1", F.max() / (3.0e4 * v_hit) - 1, 5e-4)
    check("final speed on the buffer [m/s]", v[-1], 0.02,
          reason="a rest criterion, not an error: the rigid rim ends at 0.017 m/s, the creep contact lower")


BUFFER_DROP = """
[scene]
name = "buffer_drop"
model = "axial-1d"
t_end = 0.9
output_step = 1e-3
[solver]
step = 1e-4
rho_inf = 1.0
newton_tol = 1e-9
[initial]
statics = "none"
[[bodies]]
name = "car"
mass = 1000.0
position = [0.0, 0.0, 1.0]
free = ["z"]
[[ropes]]
name = "rope"          # slack throughout (12 m of rope over 9-10 m): only there to hold a body
EA = 1.0e6
rhoA = 1e-4
tension_only = true
length = 12.0
route = [ { anchor = "ground", at = [0.0, 0.0, 10.0] }, { anchor = "car", at = [0.0, 0.0, 0.0] } ]
[[buffers]]
name = "buffer"
body = "car"
position = 0.0
stiffness = 2.0e5
damping = 1.5e4
"""


def test_free_fall_onto_a_buffer_against_the_closed_form():
    """A 1000 kg body falls 1 m from rest onto a linear spring-damper buffer (k = 200 kN/m,
    c = 15 kN s/m, zeta = 0.53). Free flight: z = 1 - g t^2/2, a = -g (the slack rope carries nothing:
    its strain is below -SLACK_STRAIN throughout). Contact at v0 = sqrt(2 g): x'' + 2 zeta w x' + w^2 x = g,
    x(0) = 0, x'(0) = v0, so x = g/w^2 + exp(-zeta w t) (A cos w_d t + B sin w_d t). The buffer force
    F = k x + c x' is c v0 at contact but still rising there (dF/dt = k v0 + c (g - c v0/M) > 0 here):
    its peak is where k x' + c x'' = 0, 3.1 ms after contact and 8.5e-4 above c v0."""
    sc = loads_scene(BUFFER_DROP, "buffer_drop.toml")
    m, res = run(sc)
    g, M, k, c = 9.81, 1000.0, 2.0e5, 1.5e4
    t, z, a, F = res.time, res["car.position"], res["car.acceleration"], res["buffer.force"]
    assert np.all(res["rope.tension_end"] == 0.0)            # slack throughout: it reports 0 N
    free = z > 0.0
    # R: the tension-only law's force at the span's strain (the rope is 12 m over 10 - z): none
    R = np.array([sum(axial_law(1.0e6, 0.0, (10.0 - x) / 12.0 - 1.0, 0.0, True)[::2]) for x in z])
    assert np.all(R == 0.0)
    # measured 2.0e-6: what is left is the rope's own weight and inertia share (1.2 g of rope)
    check("free flight: a + g - R/M [m/s^2]", a[free] + g - R[free] / M, 1.5e-5)
    # measured 2.0e-7 m (the rope's weight and inertia share, as above, and the step)
    check("free flight: z against 1 - g t^2/2 [m]", z[free] - (1.0 - 0.5 * g * t[free] ** 2), 1.5e-6)
    t_hit, v0 = math.sqrt(2.0 / g), math.sqrt(2.0 * g)
    w = math.sqrt(k / M)
    zeta = c / (2.0 * math.sqrt(k * M))
    wd = w * math.sqrt(1.0 - zeta ** 2)
    A = -g / w ** 2
    B = (v0 + zeta * w * A) / wd

    def x(s):
        return g / w ** 2 + np.exp(-zeta * w * s) * (A * np.cos(wd * s) + B * np.sin(wd * s))
    s = np.linspace(0.0, 0.5, 500001)
    stroke = x(s).max()
    check("stroke / closed form - 1", -z.min() / stroke - 1, 1e-3)
    on = (t > t_hit) & (t < t_hit + 0.3)
    check("buffer compression against x(t) [m]", -z[on] - x(t[on] - t_hit), 5e-4)
    # x' = exp(-zeta w s) (C cos + D sin), x'' likewise: k x' + c x'' = 0 at tan(w_d s) = -P/Q
    sig = zeta * w
    C, D = -sig * A + wd * B, -sig * B - wd * A
    P, Q = k * C + c * (wd * D - sig * C), k * D - c * (sig * D + wd * C)
    s_pk = (math.atan2(-P, Q) / wd) % (math.pi / wd)
    F_pk = k * x(s_pk) + c * math.exp(-sig * s_pk) * (C * math.cos(wd * s_pk) + D * math.sin(wd * s_pk))
    assert 2e-3 < s_pk < 4e-3 and F_pk / (c * v0) - 1.0 == pytest.approx(8.5e-4, abs=1e-5)
    # contact inside a step of 1e-4 s (the same error as the stroke's); c v0 is 1.0e-3 off
    check("peak buffer force / closed-form peak - 1", F.max() / F_pk - 1, 5e-4)
    assert abs(t[np.argmax(F)] - (t_hit + s_pk)) <= 0.5e-3 + 1e-4   # outputs every 1 ms


def _estop_hoist(res, t_stop=1.0):
    """The wave-solution input at the stop: material length and speed from the run."""
    i = np.searchsorted(res.time, t_stop)
    L = 50.0 - res["mass.position"][i]                       # stretched: drum tangent point at z = 50
    L0 = L / (1.0 + (1000.0 * 9.81 + 0.5 * 9.81 * L / 2.0) / 2.0e7)   # mean static strain
    return Hoist(mass=1000.0, EA=2.0e7, rhoA=0.5, length=L0, speed=-res["mass.velocity"][i], t_stop=5e-3)


def test_snap_load_wave_solution_against_a_lumped_chain():
    """The d'Alembert solution (reeve_fmu/studies/snapload.py) is converged on its grid and a lumped
    wave chain of the same rope converges to it from 200 to 400 segments."""
    h = Hoist(mass=1000.0, EA=2.0e7, rhoA=0.5, length=50.56, speed=1.0, t_stop=5e-3)
    peak, t_peak, err = converged_peak(h, 0.15, 1024)
    check("wave solution: grid error / peak", err / peak, 1e-4)
    assert t_peak == pytest.approx(0.0770, abs=5e-4)         # first swing, before any slack (0.18 s)
    errs = []
    for n in (200, 400):
        t, T, T_min = lumped_chain(h, 0.15, n)
        errs.append(T.max() / peak - 1)
        assert T_min.min() > 0.0                             # the rope stays taut over the first swing
    check("lumped chain (200 segments) / wave peak - 1", errs[0], 2e-3)
    assert abs(errs[1]) < abs(errs[0])                       # converges with the segments
    massless, corrected = single_mode_peak(h)
    assert peak / massless - 1 > 0.06                        # the one-mode formula is 6.7 % low


def test_emergency_stop_peak_tension_against_the_wave_solution():
    """Drum stops within 5 ms while lowering 1000 kg at 1 m/s on 50.6 m of rope: the peak rope force at
    the mass in the first swing (before the rope could go slack) against the exact wave solution.
    The fidelity selection asked for rope.tension_end at 1 % rejects 8/16/32 elements per span and
    falls back to its 64-element reference, the mesh the shipped scene uses; that peak is within 1 %."""
    sc = load_scene(HARD / "emergency_stop.toml")
    assert sc.ropes[0].elements_per_span == 64
    t_win = 1.15                                             # the stop at 1.0 s and its first swing
    acc = parse_accuracy({"outputs": ["rope.tension_end"], "tol": 0.01, "elements": [8, 16, 32],
                          "steps": [1e-4], "probe": t_win, "full_check": False}, sc.source)
    rep = select(sc, acc, t_end=t_win, out_dt=1e-4)
    cfg = rep.chosen.config
    assert cfg.elements == 64 and cfg.step <= 1e-4
    res = Simulator(build_model(configure(sc, cfg)), method="gen-alpha", step=cfg.step).run(t_win, 1e-4)
    h = _estop_hoist(res)
    peak, _, _ = converged_peak(h, t_win - 1.0, 1024)
    after = res.time > 1.0
    got = res["rope.tension_end"][after].max()
    check("emergency stop: peak (64 elements) / wave solution - 1", got / peak - 1, 0.01,
          reason="the 1 % the fidelity selection was asked for; the scene's mesh is what it picks")
    # the shipped one-element mesh is the one-mode model: 6.7 % low
    one = Simulator(build_model(configure(sc, replace(cfg, elements=1, step=1e-4)))).run(t_win, 1e-4)
    assert one["rope.tension_end"][after].max() / peak - 1 < -0.05


@pytest.mark.parametrize("case", ["EA x100", "500 m rope", "very light car", "rope heavier than car"])
def test_extreme_parameters_run(case):
    """Documented outcome: every case runs its 3 s with finite outputs, and its initial statics is the
    hand statics: a 2:1 car sheave carries (M g + rhoA pi R g)/2 per side (the half wrap of rope on it),
    a hanging rope m g at the mass and m g + rhoA g L at the top."""
    if case == "500 m rope":
        sc = load_scene(ROOT / "scenes" / "hanging_rope.toml")
        sc = replace(sc, ropes=(replace(sc.ropes[0], length=500.0),))
    else:
        sc = load_scene(ROOT / "scenes" / "elevator_2to1.toml")
        if case == "EA x100":
            sc = replace(sc, ropes=tuple(replace(r, EA=r.EA * 100) for r in sc.ropes))
        elif case == "very light car":
            sc = replace(sc, bodies=tuple(replace(b, mass=20.0) if b.name == "car" else b for b in sc.bodies))
        else:   # 60 kg car under 2 x 6 ropes of 0.26 kg/m over ~40 m (~125 kg of rope)
            sc = replace(sc, bodies=tuple(replace(b, mass=60.0) if b.name == "car" else b for b in sc.bodies))
    m, res = run(sc, t_end=3.0)
    assert res.time[-1] == pytest.approx(3.0)
    assert finite_except_ratios(res)
    g = 9.81
    rp = sc.ropes[0]
    rhoA = rp.rhoA * rp.count
    mass = {b.name: b.mass for b in sc.bodies}
    if case == "500 m rope":
        body = next(iter(mass))
        check("500 m rope: tension at the mass / m g - 1", res["rope.tension_end"][0] / (mass[body] * g) - 1,
              1e-12, reason="round-off of the static Newton (EA strain differences), platform-dependent")
        check("500 m rope: top tension / (m g + rhoA g L) - 1",
              res["rope.tension_start"][0] / (mass[body] * g + rhoA * g * 500.0) - 1, 1e-12,
              reason="round-off of the static Newton (EA strain differences), platform-dependent")
    else:
        R = next(sh.radius for sh in sc.sheaves if sh.name == "car_sheave")
        expect = (mass["car"] * g + rhoA * math.pi * R * g) / 2
        # the static Newton's floor grows as the car's weight shrinks against EA x strain differences
        bound = {"EA x100": 1.4e-11, "very light car": 1e-8, "rope heavier than car": 5e-9}[case]
        for side in ("tension_in", "tension_out"):
            check(f"{case}: car_sheave.{side} / hand statics - 1", res[f"car_sheave.{side}"][0] / expect - 1, bound)
