"""Traction slip (docs/hard-cases.md, "Traction slip"): groove friction with the Euler-Eytelwein limit on a slipping
traction sheave, against the EN 81-50 cases (docs/reference-sets.md §4.2)."""
from dataclasses import replace
from pathlib import Path
import math

import numpy as np
import pytest

from reeve_fmu.studies.analysis import en81_mu, traction_limit
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator

ROOT = Path(__file__).resolve().parents[1]
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


def test_car_loading_125_percent_no_slip():
    """125 % rated load at the bottom landing, mu = 0.1, machine held: the rope only creeps."""
    sc = variant(mu=en81_mu("loading"), masses={"car": 1300 + 1250},
                 positions={"car": (0.0, 0.0, 0.0), "counterweight": (0.32, 0.0, 39.5)},
                 table=[[0.0, 0.0], [5.0, 0.0]])
    res, sim = run(sc, 3.0)
    assert not sim.warnings
    assert np.max(np.abs(res["traction.slip"])) < CREEP
    assert res["traction.traction_ratio"].max() < traction_limit(0.1, 95, 30, 180)


@pytest.mark.parametrize("decel,slips", [(0.3, False), (2.0, True)])
def test_emergency_braking(decel, slips):
    """Empty car going up at rated speed, machine decelerating at decel, mu = 0.1/(1 + v_rope/10):
    within the limit the rope only creeps; beyond it the rope slips, the tension ratio is pinned at
    e^(f alpha) and the car decelerates more slowly than the machine."""
    t_dec = 1.6 / decel
    table = [[0.0, 0.0], [0.5, 0.0], [3.5, 1.6], [6.0, 1.6], [6.0 + t_dec, 0.0], [9.0 + t_dec, 0.0]]
    limit = traction_limit(0.0758, 95, 30, 180)
    res, sim = run(variant(table=table), 9.0 + t_dec)
    slip = np.max(np.abs(res["traction.slip"]))
    ratio = res["traction.traction_ratio"].max()
    if not slips:
        assert slip < CREEP and ratio < limit
    else:
        assert slip > 0.1
        assert abs(ratio / limit - 1) < 0.005
        assert res["car.acceleration"].min() > -decel * 0.8


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
