"""The beam scene shared by the rigid-body and cubic-tangent tests (tests/core/test_bodies.py,
test_cubic_tangents.py): a rope from a ground anchor over a sheave at the tip of a beam pivoting about
its centre of mass, under a sheave on a block free in x-z, to a second ground anchor; with what those
tests measure on it (element end coordinates, the exact tangent points, the energy drift)."""
import math

import numpy as np

from reeve_fmu.core.geometry import tangent, wrap_angle
from reeve_fmu.core.solver import Simulator


def beam_scene(rho_inf_step="", rhoA=0.5):
    # beam pivoting about its centre of mass (theta only), sheave at its tip; block free in x-z with a
    # sheave; the rope: ground anchor -> over the tip sheave -> under the block sheave -> ground anchor.
    # The rope starts unstretched (no statics) and its strain swings back to 0 every period: bilateral,
    # so the energy checks see the discretization, not the tension-only law's kink at 0 strain, which a
    # 1 ms step does not resolve (a rope going slack: tests/oracles/test_rope_drop.py)
    return f"""
[scene]
name = "beam_sheave"
model = "planar"
sheave_contact = "rigid"
[solver]
step = 1e-3
rho_inf = 1.0
newton_tol = 1e-10
[initial]
statics = "none"
[[bodies]]
name = "beam"
mass = 100.0
inertia = 200.0
position = [0.0, 0.0, 0.0]
free = ["theta"]
[[bodies]]
name = "block"
mass = 20.0
position = [2.35, 0.0, -3.0]
free = ["x", "z"]
[[sheaves]]
name = "tip"
body = "beam"
center = [2.0, 0.0, 0.0]
radius = 0.2
inertia = 0.05
[[sheaves]]
name = "blk"
body = "block"
center = [0.0, 0.0, 0.0]
radius = 0.15
inertia = 0.02
[[ropes]]
name = "rope"
EA = 1e5
rhoA = {rhoA}
tension_only = false
route = [
  {{ anchor = "ground", at = [-1.0, 0.0, 1.0] }},
  {{ sheave = "tip", wrap = "cw" }},
  {{ sheave = "blk", wrap = "ccw" }},
  {{ anchor = "ground", at = [2.8, 0.0, 1.0] }},
]
"""


def nodes(m, st):
    """Element end coordinates [r1 (x, z), r2 (x, z), s1, s2] from the state after an assembly."""
    K = m.K
    X = np.empty(K.el_idx.shape)
    for ie in range(K.el_idx.shape[0]):
        for a in range(K.el_idx.shape[1]):
            X[ie, a] = st.c[K.el_idx[ie, a]] + st.el_coef[ie, a] @ st.q[K.el_map[ie, a]]
    return X


def beam_tangents(m, sim, st):
    """(tangent points (TA, TB) of the three spans from geometry.tangent at the current poses, the
    two wraps' material lengths) of the beam scene, after an assembly at st."""
    sim.energy(st)                       # an assembly at st.q: c and the maps follow the poses
    q = dict(zip(m.q_names, st.q))
    th = q["beam.theta"]
    tip = np.array([2.0 * math.cos(th), 0.0, 2.0 * math.sin(th)])
    blk = np.array([q["block.x"], 0.0, q["block.z"]])
    a = np.array([0.0, -1.0, 0.0])
    stops = [(np.array([-1.0, 0.0, 1.0]), 0.0, -1.0), (tip, 0.2, -1.0), (blk, 0.15, 1.0),
             (np.array([2.8, 0.0, 1.0]), 0.0, 1.0)]
    T = [tangent(cA, RA, a, sA, cB, RB, a, sB) for (cA, RA, sA), (cB, RB, sB) in zip(stops, stops[1:])]
    wraps = [0.2 * wrap_angle(tip, a, -1.0, T[0][1], T[1][0]), 0.15 * wrap_angle(blk, a, 1.0, T[1][1], T[2][0])]
    return T, wraps


def run_beam(m, h, check=None):
    """Relative energy drift max |E - E0| / max T over 1 s (20 samples); check(sim, st) per sample."""
    sim = Simulator(m, step=h, rho_inf=1.0)
    st = sim.initial_state()
    E0 = sum(sim.energy(st))
    dE, Tmax = 0.0, 0.0
    for k in range(1, 21):
        sim.advance(st, 0.05 * k)
        T, Vg, U = sim.energy(st)
        dE, Tmax = max(dE, abs(T + Vg + U - E0)), max(Tmax, T)
        if check is not None:
            check(sim, st)
    return dE / Tmax, dict(zip(m.q_names, st.q - m.q0))
