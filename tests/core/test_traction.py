"""Traction slip (docs/hard-cases.md, "Traction slip"): groove friction with the Euler-Eytelwein limit on a slipping
traction sheave, against the EN 81-50 cases (docs/reference-sets.md §4.2)."""
from dataclasses import replace
import math

import numpy as np
import pytest

from reeve_fmu.studies.analysis import en81_mu, traction_limit
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
from tests.support import ROOT
from tests.support.checks import check

BASE = load_scene(ROOT / "scenes" / "hard" / "traction_en81.toml")
CREEP = 1e-3


def variant(mu=None, masses=None, positions=None, table=None, buffers=None):
    sc = BASE
    if mu is not None:
        sc = replace(sc, sheaves=tuple(replace(s, mu=mu) if s.name == "traction" else s for s in sc.sheaves))
    if masses or positions:
        sc = replace(sc, bodies=tuple(
            replace(b, mass=(masses or {}).get(b.name, b.mass),
                    position=(positions or {}).get(b.name, b.position)) for b in sc.bodies))
    if table is not None:
        sc = replace(sc, drive=replace(sc.drive, table=tuple(map(tuple, table))))
    if buffers is not None:
        sc = replace(sc, buffers=buffers)
    return sc


def run(sc, t_end):
    sim = Simulator(build_model(sc))
    st = sim.initial_state()
    return sim.run(t_end, 1e-3, state=st), sim


def test_check_vector_and_model_limit():
    """e^(f alpha) of docs/reference-sets.md §4.2 exactly, and the model's capacity uses the same limit with the
    geometric wrap angle (180 deg)."""
    v_rope = 3.2
    assert round(traction_limit(en81_mu("loading"), 95, 30, 180), 4) == 1.8582
    assert round(traction_limit(en81_mu("emergency", v_rope), 95, 30, 180), 4) == 1.5990
    assert round(traction_limit(en81_mu("stalled"), 95, 30, 180), 4) == 3.4528
    m = build_model(BASE)
    assert abs(1 + m.K.trac_efa - traction_limit(0.0758, 95, 30, 180)) < 1e-12


def hanging_side(mass, span):
    """Hand statics of one side of the 2:1 roping at the traction sheave: the sheave on the body carries
    the body and the rope on its half wrap on two falls of equal tension (frictionless, tangent points
    at one height), plus the weight of the vertical span up to the traction sheave. Six ropes; the
    weight per metre of stretched rope is rhoA g/(1 + T/EA), so up the span dT/dz = rhoA g/(1 + T/EA),
    i.e. T + T^2/(2 EA) grows by rhoA g z."""
    g, rhoA, EA, r = 9.81, 6 * 0.26, 6 * 2.9e6, 0.16
    T = mass * g / 2
    for _ in range(20):                  # the stretch depends on the tension: a fixed point
        T = (mass * g + rhoA * g / (1 + T / EA) * math.pi * r) / 2
    c = T + T * T / (2 * EA) + rhoA * g * span
    return EA * (math.sqrt(1 + 2 * c / EA) - 1)


def test_car_loading_125_percent_no_slip():
    """125 % rated load at the bottom landing, mu = 0.1, machine held: the rope does not slip and the
    tension ratio is the hand statics (car sheave 40 m below the traction sheave, counterweight sheave
    3 m), below the limit e^(f alpha) = 1.858."""
    sc = variant(mu=en81_mu("loading"), masses={"car": 1300 + 1250},
                 positions={"car": (0.0, 0.0, 0.0), "counterweight": (0.32, 0.0, 39.5)},
                 table=[[0.0, 0.0], [5.0, 0.0]])
    res, sim = run(sc, 3.0)
    assert not sim.warnings
    check("traction slip at rest [m]", res["traction.slip"], 1e-12,
          reason="no slip: what is left is the round-off of the friction deflection (platform-dependent)")
    ratio = res["traction.traction_ratio"]
    hand = hanging_side(2550.0, 40.0) / hanging_side(1750.0, 3.0)      # 1.5200
    check("tension ratio / hand statics - 1", ratio / hand - 1, 9e-8)
    assert hand < traction_limit(0.1, 95, 30, 180)


def slipping_deceleration(z_car, z_cw, v, e):
    """Car acceleration (up) of the base scene while the rope slips with T_cw = e T_car at the traction
    sheave, for a rigid rope: the spans to the traction sheave run at 2v (anchor spans stand still),
    each sheave rolls (J/r^2 plus its half wrap rho_A pi r of rope), the wrap on a body's sheave takes
    rope in at 0 and hands it on at 2v (momentum flux rho_A v^2 per fall). Momentum balances:
      T_car = T_b + w L2 + 2 rho_A L2 a,   2 T_b = (m_car + rho_A pi r)(g + a) + (J/r^2 + rho_A pi r) a + 2 rho_A v^2
      T_cw  = T_c + w L3 - 2 rho_A L3 a,   2 T_c = (m_cw + rho_A pi r)(g - a) - (J/r^2 + rho_A pi r) a + 2 rho_A v^2
    with w = rho_A g; T_cw = e T_car is linear in a."""
    g, rhoA, r, J, m_car, m_cw = 9.81, 6 * 0.26, 0.16, 0.15, 1300.0, 1750.0
    L2, L3 = 42.5 - (z_car + 2.5), 42.5 - z_cw
    wrap, roll = rhoA * math.pi * r, J / r ** 2 + rhoA * math.pi * r
    c0 = (m_car + wrap) * g / 2 + rhoA * v * v + rhoA * g * L2
    c1 = (m_car + wrap) / 2 + roll / 2 + 2 * rhoA * L2
    w0 = (m_cw + wrap) * g / 2 + rhoA * v * v + rhoA * g * L3
    w1 = -(m_cw + wrap) / 2 - roll / 2 - 2 * rhoA * L3
    return (w0 - e * c0) / (e * c1 - w1)


@pytest.mark.parametrize("decel,slips", [(0.3, False), (2.0, True)])
def test_emergency_braking(decel, slips):
    """Empty car going up at rated speed, machine decelerating at decel, mu = 0.1/(1 + v_rope/10):
    within the limit the rope only creeps; beyond it the rope slips, the tension ratio is pinned at
    e^(f alpha) and the car decelerates as the rigid-rope momentum balance with that ratio gives
    (slipping_deceleration), more slowly than the machine."""
    t_dec = 1.6 / decel
    table = [[0.0, 0.0], [0.5, 0.0], [3.5, 1.6], [6.0, 1.6], [6.0 + t_dec, 0.0], [9.0 + t_dec, 0.0]]
    limit = traction_limit(0.0758, 95, 30, 180)
    res, sim = run(variant(table=table), 9.0 + t_dec)
    slip = np.max(np.abs(res["traction.slip"]))
    ratio = res["traction.traction_ratio"].max()
    if not slips:
        assert slip < CREEP and ratio < limit       # creep only (< 1 mm), the ratio below e^(f alpha)
    else:
        assert slip > 0.1                           # gross slip (2.4 m)
        check("pinned ratio / e^(f alpha) - 1 (the creep law's overshoot)", ratio / limit - 1, 0.005)
        # the ratio is pinned from 6.05 to 8.24 s; the rope's axial ringing (+-0.23 m/s^2) averages out
        # over the window
        t = res.time
        w = (t > 6.1) & (t < 8.2)
        a_hand = slipping_deceleration(res["car.position"][w], res["counterweight.position"][w],
                                       res["car.velocity"][w], limit)
        check("mean deceleration while slipping / rigid-rope balance - 1",
              np.mean(res["car.acceleration"][w]) / np.mean(a_hand) - 1, 5e-3)
        assert np.mean(a_hand) > -0.5 * decel


def test_car_stalled_counterweight_on_buffer_rope_slips():
    """Counterweight on its buffer, empty car near the top, machine turning 'up' with mu = 0.2: the
    rope slips and the car is not lifted."""
    from reeve_fmu.core.scene import Buffer
    W_cw = 1750 * 9.81
    k_buf = 1.0e6
    z_cw = 1.5
    buf = Buffer(name="cw_buffer", body="counterweight", position=z_cw + 0.95 * W_cw / k_buf,
                 stiffness=k_buf, damping=2.0e4)
    sc = variant(mu=en81_mu("stalled"), positions={"car": (0.0, 0.0, 37.0), "counterweight": (0.32, 0.0, z_cw)},
                 table=[[0.0, 0.0], [0.5, 0.0], [1.5, 0.5], [4.0, 0.5]], buffers=(buf,))
    res, sim = run(sc, 4.0)
    assert any("slips" in w for w in sim.warnings)
    z0 = res["car.position"][0]
    assert res["car.position"].max() < z0 + 1e-3          # not lifted
    rim = res["traction.angle"][-1] * 0.16 / 2.0           # car travel the machine asked for
    assert rim > 0.5
    assert abs(res["traction.slip"][-1]) > rim             # the rope slipped at least that much
