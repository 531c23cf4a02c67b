"""Cubic ALE-ANCF elements assembled in the engine: planar 2:1 elevator without bending
stiffness against the 1D model, and energy conservation of a swinging cubic-element rope."""
from dataclasses import replace

import numpy as np
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from reeve_fmu.core.solver import Simulator
from tests.support import ROOT
from tests.support.checks import check


def test_planar_cubic_elevator_matches_1d_without_bending_stiffness():
    """Vertical spans, EI = 0, no lateral excitation: 3 cubic elements per span in the planar model
    follow the 1D model over 2 s of the trip: the car position to a few um (with rope creep on the rim
    the rim kinematics use the arriving strain, the cubic tangent node's against the span mean of one
    linear element), the tensions to 0.1 % (the cubic slopes resolve the rope-weight tension gradient
    that a linear element averages)."""
    sc = load_scene(ROOT / "scenes" / "elevator_2to1.toml")
    ref = Simulator(build_model(sc)).run(2.0, 1e-2)
    sp = replace(sc, model="planar",
                 ropes=tuple(replace(r, element="cubic", elements_per_span=3) for r in sc.ropes))
    m = build_model(sp)
    assert any(k == "slope" for k in m.q_kind)
    res = Simulator(m).run(2.0, 1e-2)
    check('res["car.position.z"] - ref["car.position"]', res["car.position.z"] - ref["car.position"], 6.2e-06)
    for name in ("traction.tension_in", "traction.tension_out"):
        check('res[name] / ref[name] - 1', res[name] / ref[name] - 1, 1e-3)


def test_swinging_cubic_rope_conserves_energy():
    """A 4-element cubic rope (EI > 0) with an end mass released from an inclined straight line
    swings in gravity; no damping, rho_inf = 1: total energy drift <= 1e-6 of the swing's potential
    energy drop over 1 s."""
    txt = """
[scene]
model = "planar"
[solver]
step = 5e-4
rho_inf = 1.0
newton_tol = 1e-11
[initial]
statics = "none"
[[bodies]]
name = "mass"
mass = 5.0
position = [3.0, 0.0, 1.0]
free = ["x", "z"]
[[ropes]]
name = "rope"
EA = 2.0e5
rhoA = 0.5
tension_only = false      # from the unstretched line its strain swings back to 0 (no slack law here)
EI = 2.0
element = "cubic"
elements_per_span = 4
route = [ { anchor = "ground", at = [0, 0, 10] }, { anchor = "mass", at = [0, 0, 0] } ]
"""
    m = build_model(loads_scene(txt, "pendulum.toml"))
    sim = Simulator(m)
    st = sim.initial_state()
    E0 = sum(sim.energy(st))
    Es, Ts = [], []
    for k in range(1, 11):
        sim.advance(st, 0.1 * k)
        T, V, U = sim.energy(st)
        Es.append(T + V + U)
        Ts.append(T)
    scale = max(Ts)                     # kinetic energy gained in the swing
    assert scale > 10.0
    check('np.array(Es) - E0', np.array(Es) - E0, 1e-6 * scale)


def test_cubic_needs_a_bending_model():
    sc = load_scene(ROOT / "scenes" / "hanging_rope.toml")
    text = (ROOT / "scenes" / "hanging_rope.toml").read_text(encoding="utf-8").replace('length = 50.0', 'length = 50.0\nelement = "cubic"')
    with pytest.raises(SceneError, match=r"\[ropes\[0\].element\] cubic elements bend"):
        loads_scene(text, "h.toml")
