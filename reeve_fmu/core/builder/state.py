"""Shared state of the model builder: the coordinates, nodes, elements and constant terms that the
build steps collect (one BuildState per build), and the affine point type of the nodes."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..scene import AXES, Scene


class Affine:
    """3D point r = r0 + sum_j q_j b_j (b_j in R^3)."""

    def __init__(self, r0):
        self.r0 = np.asarray(r0, float).copy()
        self.terms = {}

    def add(self, j, b):
        self.terms[j] = self.terms.get(j, np.zeros(3)) + np.asarray(b, float)
        return self


@dataclass
class BuildState:
    """What the steps share. Every element coordinate (node position, slope, s) is an affine
    function of q and of the rope lengths par; nodes keep that function until coordinates.py turns
    them into the rows of B."""
    scene: Scene
    nd: int                     # 1 (axial-1d), 2 (planar x-z), 3 (spatial)
    g: np.ndarray               # gravity [3]
    bodies: dict                # name -> Body
    sheaves: dict               # name -> Sheave
    cubic: bool                 # cubic ALE-ANCF elements (slopes are coordinates)
    comps_nd: list              # world components of a node position (x / x, z / x, y, z)
    par0: np.ndarray            # rope lengths (s at the far rope end) from the geometry / scene
    # generalized coordinates
    q_names: list = field(default_factory=list)
    q_kind: list = field(default_factory=list)   # body | sheave | angle | hitch | interior | slope
    q0: list = field(default_factory=list)
    body_dofs: dict = field(default_factory=dict)   # body -> {axis: q index}
    sheave_dof: dict = field(default_factory=dict)  # sheave -> q index of its sigma
    dof_R: dict = field(default_factory=dict)       # sigma q index -> sheave radius
    # rope nodes and elements
    nodes: list = field(default_factory=list)       # dict(r=Affine, e=unit span dir, s=(q coefs, par coefs, const)[, d=Affine])
    elements: list = field(default_factory=list)    # (node_a, node_b, rope index, span index)
    wrap_elements: list = field(default_factory=list)   # W2: (node_a, node_b, rope index, stop index)
    rope_info: list = field(default_factory=list)   # per rope: bookkeeping dict (Model.ropes)
    wrap_len_total: list = field(default_factory=list)  # (rope index, wrap material length)
    tension_taps: dict = field(default_factory=dict)    # sheave -> {'in'|'out': (element, end)}
    rope_end_taps: list = field(default_factory=list)   # (rope, first element, last element)
    slip_info: dict = field(default_factory=dict)       # the slipping traction sheave: sheave, s, th, wrap
    # constant q-level terms
    M0_terms: list = field(default_factory=list)    # (i, j, value)
    F0: dict = field(default_factory=dict)          # q index -> force
    springs: list = field(default_factory=list)     # (dof, k, c)
    drums: list = field(default_factory=list)       # (dof, rhoA, sign)
    # exact tangents: the nonlinear rows (builder/nonlinear.NonlinearRows), None when tangents are frozen
    nlr: object = None
    torsion: list = field(default_factory=list)     # torsion spans (builder/torsion.py)

    def new_q(self, name, kind, value) -> int:
        """Append a generalized coordinate; returns its index."""
        self.q_names.append(name), self.q_kind.append(kind), self.q0.append(float(value))
        return len(self.q_names) - 1

    def free_slope(self, prefix, e) -> Affine:
        """Material gradient dr/ds of a node as free coordinates (cubic elements), start: e."""
        d = Affine(np.zeros(3))
        for kk in self.comps_nd:
            b = np.zeros(3)
            b[kk] = 1.0
            d.add(self.new_q(f"{prefix}.d{AXES[kk]}", "slope", e[kk]), b)
        return d


def start(scene: Scene) -> BuildState:
    """An empty build of a scene."""
    nd = {"axial-1d": 1, "planar": 2, "spatial": 3}[scene.model]
    cubic = bool(scene.ropes) and scene.ropes[0].element == "cubic"
    comps_nd = [0] if nd == 1 else ([0, 2] if nd == 2 else [0, 1, 2])
    return BuildState(scene=scene, nd=nd, g=np.asarray(scene.gravity, float),
                      bodies={b.name: b for b in scene.bodies}, sheaves={s.name: s for s in scene.sheaves},
                      cubic=cubic, comps_nd=comps_nd, par0=np.zeros(len(scene.ropes)))
