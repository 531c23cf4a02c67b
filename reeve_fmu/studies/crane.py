"""Crane hoist statics: hook-block rotation and cabling against the hoisting height (docs/crane.md).

The crane is an ordinary scene of the dynamic engine (core/model.py): a hook block with `rotation`
among its free axes, a rope with a `torsion` table, exact tangents. This module adds what is
crane-specific, on the statics of that model:

* `sweep`: equilibria over a range of fall lengths h (the [crane] section). At each h the drum's rope
  coordinate is free and h(q) = h replaces its equation; continuation from the previous solution
  (secant predictor, chord Newton corrector with the closed-form Jacobian of the model's forces at
  rest, core/solver/statics_jac.py, step control on the predicted yaw). Cabling is the fold of the path: the height
  continuation creeps up to it with shrinking steps and hands over to
* `cabling_of_model`: continuation in the block yaw (prescribed; the drum free), which passes the fold;
  the critical height is the vertex of the parabola h(yaw) through the highest point and its neighbours.
* the `reeve-fmu crane` command: rotation.csv, rotation.png, summary.json.
"""
from __future__ import annotations

from dataclasses import dataclass
import json
import math
from pathlib import Path
import sys
import time

import numpy as np

from ..core.bodies import rot_coefs
from ..core.builder.bodies import world
from ..core.builder.routes import span_tangents, stop_geometry
from ..core.builder.state import start
from ..core.geometry import GeometryError
from ..core.model import build_model
from ..core.scene import Scene, SceneError, _Reader, load_scene
from ..core.solver import Simulator, SolverError
from ..core.solver.lu import lu_factor, lu_solve
from ..core.solver.statics_jac import static_jacobian, supported
from ..core._jit import njit
from ..core.solver.inputs import kernel_inputs_at
from ..core.system import outputs, static_forces, workspace


class CraneError(ValueError):
    """The crane statics cannot start (no equilibrium in the scene's own configuration)."""


SWEEP_KEYS = {"block", "rope", "height_min", "height_max", "heights", "yaw_step", "tolerance", "fold_tol"}
# keys of the former quasi-static engine's [crane] section and where they live now
MOVED_KEYS = {
    **{k: f"the rope's torsion table: [[ropes]] torsion = {{ law, diameter, k0, k1, GJ0 }} (here: {k})"
       for k in ("law", "diameter", "k0", "k1", "GJ0")},
    "payload": "the hook block's mass: add the payload to [[bodies]] mass",
    "cg": "the hook block's [[bodies]] position, which is its centre of mass (its sheaves' centres are "
          "relative to it)",
    "pose": "the hook block's free axes: free = [\"x\", \"y\", \"z\", \"rotation\"]",
    "rope_weight": "the rope's rhoA (its weight is always included)",
}


@dataclass(frozen=True)
class SweepSpec:
    block: str                 # hook-block body (free axes include "rotation")
    rope: str                  # hoist rope: drum first, dead end last
    height_min: float          # m, fall length h
    height_max: float          # m
    heights: int = 200
    yaw_step: float = 0.05     # rad, largest predicted yaw change per continuation step
    tolerance: float = 1e-9    # Newton tolerance: force residual over the largest scene force
    fold_tol: float = 1e-6     # smallest height step, relative to the range: then the fold is sought in yaw


def parse_sweep(scene: Scene) -> SweepSpec:
    """Validate the scene's [crane] section and the crane parts of the scene (errors name the file and key)."""
    r = _Reader(scene.source)
    if "crane" not in scene.extra:
        r.fail("crane", "missing section: a crane scene needs a [crane] table (see docs/crane.md)")
    c = scene.extra["crane"]
    if not isinstance(c, dict):
        r.fail("crane", "must be a table")
    for k in c:
        if k in MOVED_KEYS:
            r.fail(f"crane.{k}", f"no longer a [crane] key: it is {MOVED_KEYS[k]} (docs/crane.md)")
    c = r.table(c, "crane", SWEEP_KEYS)
    if scene.model != "spatial":
        r.fail("scene.model", f"the crane statics is three-dimensional: use 'spatial', got {scene.model!r}")
    bodies = {b.name: b for b in scene.bodies}
    block = r.string(c, "crane", "block", required=True)
    if block not in bodies:
        r.fail("crane.block", f"unknown body {block!r}; bodies: {', '.join(sorted(bodies)) or 'none'}")
    if "rotation" not in bodies[block].free:
        r.fail(f"bodies.{block}.free", f"the hook block turns: its free axes must include 'rotation', got "
                                       f"{list(bodies[block].free)}")
    ropes = [rp.name for rp in scene.ropes]
    if "rope" in c:
        rope = r.string(c, "crane", "rope")
        if rope not in ropes:
            r.fail("crane.rope", f"unknown rope {rope!r}; ropes: {', '.join(ropes)}")
    elif len(ropes) == 1:
        rope = ropes[0]
    else:
        r.fail("crane", f"missing required key 'rope' (the scene has {len(ropes)} ropes)")
    spec = SweepSpec(
        block=block, rope=rope,
        height_min=r.number(c, "crane", "height_min", positive=True, required=True),
        height_max=r.number(c, "crane", "height_max", positive=True, required=True),
        heights=r.integer(c, "crane", "heights", 200, minimum=2),
        yaw_step=r.number(c, "crane", "yaw_step", 0.05, positive=True),
        tolerance=r.number(c, "crane", "tolerance", 1e-9, positive=True),
        fold_tol=r.number(c, "crane", "fold_tol", 1e-6, positive=True),
    )
    if spec.height_max <= spec.height_min:
        r.fail("crane.height_max", f"must be > height_min = {spec.height_min:g}, got {spec.height_max:g}")
    return spec


# ------------------------------------------------------------------------------------- the crane
@dataclass
class Crane:
    """A crane scene compiled: the dynamic model, its simulator and the crane's parts in it."""
    scene: Scene
    spec: SweepSpec
    sim: Simulator
    drum: str                 # the hoist rope's first stop
    falls: tuple              # span indices with one end on the block, route order
    span_names: tuple         # fall1 ... fallN, lead, lead2 ... per span
    tension_outputs: tuple    # per span: the model outputs with its tension at its start and its end
    ends: list                # per fall: (top, bottom) = ((body or None, offset/point), ...)
    weight: float             # N, the block's weight
    S_eff: float              # m, effective fall spacing 2 sqrt(sum p_b.p_t / n)
    H_est: float              # m, torque-factor estimate of the critical height (nan if k0 = 0)

    @property
    def model(self):
        return self.sim.model

    def height(self, q) -> float:
        """Fall length h: mean over the falls of the top's height above the bottom's (sheave centres,
        or the dead end's point; block points turn with the block's rotation vector)."""
        bd = self.model.body_dofs[self.spec.block]
        p = np.array([q[bd[a]] for a in ("x", "y", "z")])
        Rm = _rotation_matrix(np.array([q[bd[a]] for a in ("rx", "ry", "rz")]))
        z = lambda e: e[1][2] if e[0] is None else p[2] + Rm[2] @ e[1]
        return float(np.mean([z(top) - z(bot) for top, bot in self.ends]))


def _height_arrays(crane: Crane):
    """_height's arrays for Crane.height: the block's (x, y, z, rx, ry, rz) indices, the weights +-1/n
    and offsets of the fall ends on the block, and the ground ends' constant part."""
    bd = crane.model.body_dofs[crane.spec.block]
    n = len(crane.ends)
    hw, hE, hc = [], [], 0.0
    for top, bot in crane.ends:
        for e, w in ((top, 1.0 / n), (bot, -1.0 / n)):
            if e[0] is None:
                hc += w * float(e[1][2])
            else:
                hw.append(w)
                hE.append(np.asarray(e[1], float))
    return (np.array([bd[a] for a in ("x", "y", "z", "rx", "ry", "rz")], np.int64), np.array(hw, float),
            np.array(hE, float).reshape(-1, 3), hc)


def _rotation_matrix(v):
    th = float(np.linalg.norm(v))
    if th < 1e-300:
        return np.eye(3)
    k = v / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K


def _rotation_row_z(v0, v1, v2):
    """The last row of _rotation_matrix((v0, v1, v2)) (Rodrigues: I + sin K + (1 - cos) K^2)."""
    th = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if th < 1e-300:
        return 0.0, 0.0, 1.0
    k0, k1, k2 = v0 / th, v1 / th, v2 / th
    sn, cm = math.sin(th), 1.0 - math.cos(th)
    return -sn * k1 + cm * k2 * k0, sn * k0 + cm * k2 * k1, 1.0 - cm * (k0 * k0 + k1 * k1)


def _route_parts(scene, spec, r):
    """Route geometry of the hoist rope in the scene's configuration: falls, span names, fall ends
    (block points as offsets from the block's position) and the falls' (top, bottom) tangent points."""
    rope = next(rp for rp in scene.ropes if rp.name == spec.rope)
    rpath = f"ropes[{[rp.name for rp in scene.ropes].index(rope.name)}]"
    sheaves = {s.name: s for s in scene.sheaves}
    stops = rope.route
    if stops[0].sheave is None or sheaves[stops[0].sheave].kind != "drum":
        r.fail(f"{rpath}.route[0]", "a crane rope must start at a drum (kind = 'drum'): the hoist winds the rope there")
    if stops[-1].sheave is not None:
        r.fail(f"{rpath}.route[{len(stops) - 1}]", "a crane rope must end at an anchor (the dead end)")
    if rope.torsion is None:
        r.fail(f"{rpath}.torsion", "missing: the crane's rope needs its torsion table "
                                   "{ law, diameter, k0, k1, GJ0 } (docs/scenes.md)")
    bs = start(scene)
    geo = stop_geometry(stops, bs.sheaves, lambda body, offset: world(bs, body, offset))
    try:
        T = span_tangents(scene.source, rope.name, geo)
    except GeometryError as exc:
        raise SceneError(f"{scene.source}: [{rpath}.route] geometry: {exc}") from None
    p0 = np.asarray(next(b for b in scene.bodies if b.name == spec.block).position, float)
    on = [(sheaves[st.sheave].body if st.sheave is not None else st.anchor) == spec.block for st in stops]
    point = [(spec.block, g[0] - p0) if o else (None, g[0]) for g, o in zip(geo, on)]
    falls, ends, touch, names, lead = [], [], [], [], 0
    for k in range(len(stops) - 1):
        if on[k] != on[k + 1]:      # a fall: its top is the end off the block
            falls.append(k)
            ends.append((point[k], point[k + 1]) if on[k + 1] else (point[k + 1], point[k]))
            touch.append(T[k] if on[k + 1] else T[k][::-1])
            names.append(f"fall{len(falls)}")
        else:
            lead += 1
            names.append("lead" if lead == 1 else f"lead{lead}")
    if not falls:
        r.fail(f"{rpath}.route", f"no fall: no span between the boom tip and the hook block {spec.block!r}")
    tension = tuple((f"{stops[k].sheave}.tension_out",
                     f"{stops[k + 1].sheave}.tension_in" if stops[k + 1].sheave is not None else f"{rope.name}.tension_end")
                    for k in range(len(stops) - 1))
    return rope, falls, ends, names, tension, touch, p0


def _critical_height_estimate(touch, p0, torsion):
    """Effective spacing and the torque-factor estimate of the critical height (docs/crane.md):
    sum over falls of the moment (W/n)(p_b(psi) x p_t)_z / h = -(W/(n h)) (P sin psi - Q cos psi)."""
    P = Q = 0.0
    for top, bottom in touch:
        pt, pb = top[:2] - p0[:2], bottom[:2] - p0[:2]
        P += pt @ pb
        Q += pb[0] * pt[1] - pb[1] * pt[0]
    n = len(touch)
    S_eff = 2.0 * math.sqrt(max(P, 0.0) / n)
    k0, d = torsion.k0, torsion.diameter
    H_est = math.hypot(P, Q) / (n * abs(k0) * d) if k0 != 0 and d > 0 else math.nan
    return S_eff, H_est


def build_crane(scene: Scene) -> Crane:
    """The dynamic model of a crane scene and the crane's parts in it."""
    spec = parse_sweep(scene)
    r = _Reader(scene.source)
    rope, falls, ends, names, tension, touch, p0 = _route_parts(scene, spec, r)
    sim = Simulator(build_model(scene))
    block = next(b for b in scene.bodies if b.name == spec.block)
    S_eff, H_est = _critical_height_estimate(touch, p0, rope.torsion)
    return Crane(scene=scene, spec=spec, sim=sim, drum=rope.route[0].sheave, falls=tuple(falls),
                 span_names=tuple(names), tension_outputs=tension, ends=ends,
                 weight=block.mass * float(np.linalg.norm(scene.gravity)), S_eff=S_eff, H_est=H_est)


def load_crane(path, sets: dict | None = None) -> Crane:
    """Scene file -> Crane; `sets` are --set style scene keys (`crane.heights`, `ropes.hoist.torsion`, ...)."""
    if sets:
        from .overrides import scene_with
        return build_crane(scene_with(path, sets)[0])
    return build_crane(load_scene(path))


# ------------------------------------------------------------------------------------- statics
@njit(cache=True)
def _height(q, hd, hw, hE, hc):
    """Crane.height in compiled form: hc + sum_i hw[i] z(block point i), z = the block's z + the z row
    of its rotation (rotation vector q[hd[3:6]], Rodrigues) applied to the offset hE[i]."""
    p0, p1, p2 = q[hd[3]], q[hd[4]], q[hd[5]]
    th = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    k0 = k1 = k2 = 0.0
    sn, cm = 0.0, 0.0
    if th >= 1e-300:
        k0, k1, k2 = p0 / th, p1 / th, p2 / th
        sn, cm = math.sin(th), 1.0 - math.cos(th)
    h = hc
    for i in range(hw.shape[0]):
        e0, e1, e2 = hE[i, 0], hE[i, 1], hE[i, 2]
        ke = k0 * e0 + k1 * e1 + k2 * e2
        h += hw[i] * (q[hd[2]] + e2 + sn * (k0 * e1 - k1 * e0) + cm * (k2 * ke - e2))
    return h


@njit(cache=True)
def _residual(K, W, c, q, zero, u, eqs, fscale, hgeo, value, r):
    """Statics.residual into r (hgeo: _height's arrays; r one longer than eqs: the height row).
    Returns its largest magnitude (inf if not finite), -1 if a span vanishes."""
    if static_forces(K, W, c, q, zero, 0.0, u) < 0:
        return -1.0
    Q = W.Q
    for i in range(eqs.shape[0]):
        r[i] = Q[eqs[i]] / fscale
    if r.shape[0] > eqs.shape[0]:
        hd, hw, hE, hc = hgeo
        r[eqs.shape[0]] = _height(q, hd, hw, hE, hc) - value
    err = 0.0
    for i in range(r.shape[0]):
        a = abs(r[i])
        if not a <= 1e300:
            return math.inf
        err = max(err, a)
    return err


@njit(cache=True)
def _height_grad(q, hd, hw, hE, g):
    """g[k] = d _height / d q[hd[2 + k]] (k = 0: the block's z, 1-3: its rotation vector): the z row of
    omega_c x (R e_i), omega_c = T(phi) e_c the rotation per unit phi_c."""
    p0, p1, p2 = q[hd[3]], q[hd[4]], q[hd[5]]
    a, b, s1, _, _ = rot_coefs(p0, p1, p2)
    th2 = p0 * p0 + p1 * p1 + p2 * p2
    g[0] = 0.0
    for i in range(hw.shape[0]):
        g[0] += hw[i]
    for c in range(3):
        e = np.zeros(3)
        e[c] = 1.0
        x0, x1, x2 = p1 * e[2] - p2 * e[1], p2 * e[0] - p0 * e[2], p0 * e[1] - p1 * e[0]     # phi x e_c
        y0, y1 = p1 * x2 - p2 * x1, p2 * x0 - p0 * x2                                          # phi x (phi x e_c)
        w0, w1 = e[0] + a * x0 + b * y0, e[1] + a * x1 + b * y1
        s = 0.0
        for i in range(hw.shape[0]):
            e0, e1, e2 = hE[i, 0], hE[i, 1], hE[i, 2]
            pe = p0 * e0 + p1 * e1 + p2 * e2
            # R e = e + s1 phi x e + a phi x (phi x e), phi x (phi x e) = phi (phi.e) - th2 e
            r0 = e0 + s1 * (p1 * e2 - p2 * e1) + a * (p0 * pe - th2 * e0)
            r1 = e1 + s1 * (p2 * e0 - p0 * e2) + a * (p1 * pe - th2 * e1)
            s += hw[i] * (w0 * r1 - w1 * r0)
        g[1 + c] = s


@njit(cache=True)
def _closed_jacobian(K, W, c, q, zero, u, eqs, fscale, hgeo, unk, Jq, J):
    """Statics.residual's Jacobian over the unknowns into J from the closed-form static Jacobian
    (core/solver/statics_jac.py) and _height_grad; False if a span vanishes."""
    if static_jacobian(K, W, c, q, zero, u, Jq) < 0:
        return False
    pos = np.full(q.shape[0], -1, np.int64)
    for k in range(unk.shape[0]):
        pos[unk[k]] = k
    for i in range(eqs.shape[0]):
        for k in range(unk.shape[0]):
            J[i, k] = Jq[eqs[i], unk[k]] / fscale
    if J.shape[0] > eqs.shape[0]:
        hd, hw, hE, hc = hgeo
        g = np.empty(4)
        _height_grad(q, hd, hw, hE, g)
        n = eqs.shape[0]
        for k in range(unk.shape[0]):
            J[n, k] = 0.0
        for k in range(4):
            if pos[hd[2 + k]] >= 0:
                J[n, pos[hd[2 + k]]] = g[k]
    return True


@njit(cache=True)
def _fd_jacobian(K, W, c, q, zero, u, eqs, fscale, hgeo, value, unk, r0, rp, J):
    """Forward differences of _residual over the unknowns into J (models whose static forces
    statics_jac does not cover); False if a span vanishes."""
    for k in range(unk.shape[0]):
        j = unk[k]
        qj = q[j]
        q[j] = qj + 1e-7 * (1.0 + abs(qj))
        dq = q[j] - qj
        ok = _residual(K, W, c, q, zero, u, eqs, fscale, hgeo, value, rp) >= 0.0
        q[j] = qj
        if not ok:
            return False
        for i in range(r0.shape[0]):
            J[i, k] = (rp[i] - r0[i]) / dq
    return True


class Statics:
    """Static equilibria of the crane's dynamic model with the drum's rope coordinate free and one
    constraint in its place: a prescribed fall length h, or a prescribed block yaw (its rotation
    vector's z component). Newton with the closed-form Jacobian of the forces at rest where
    statics_jac covers the model, else forward differences (compiled: _residual, _closed_jacobian,
    _fd_jacobian)."""

    def __init__(self, crane: Crane, st):
        m = crane.model
        self.crane, self.st = crane, st
        self.u = crane.sim.kernel_inputs(st)
        self.jd = m.sheave_dof[crane.drum]
        self.jyaw = m.body_dofs[crane.spec.block]["rz"]
        self.eqs = np.array(m.statics_equations, np.int64)
        self.fscale = max(1.0, float(np.max(np.abs(m.K.F0))))
        self.W = workspace(m.KJ, st.arrays())
        self.zero = np.zeros(m.nq)
        self.hgeo = _height_arrays(crane)
        self.stats = [0, 0]          # Newton iterations, Jacobians
        # the closed-form Jacobian where it covers the model's static forces, else differences
        self.Jq = np.empty((m.nq, m.nq)) if supported(m.K) else None

    def unknowns(self, mode):
        free = set(self.eqs) | {self.jd}
        return np.array(sorted(free - {self.jyaw} if mode == "yaw" else free), np.int64)

    def residual(self, q, mode, value):
        """Scaled forces of the statics equations, then the constraint (height row, m) for mode 'height';
        None if a span vanishes."""
        return self._residual(q, mode, value)[0]

    def _residual(self, q, mode, value):
        """(residual or None, its largest magnitude: inf if not finite)."""
        r = np.empty(len(self.eqs) + (mode == "height"))
        err = _residual(self.crane.model.KJ, self.W, self.st.c, q, self.zero, self.u, self.eqs, self.fscale,
                        self.hgeo, float(value), r)
        return (r, err) if err >= 0.0 else (None, math.inf)

    def jacobian(self, q, unk, mode, value, r0=None):
        r0 = self.residual(q, mode, value) if r0 is None else r0
        if r0 is None:
            return None
        J = np.empty((len(r0), len(unk)))
        if self.Jq is not None:
            if not _closed_jacobian(self.crane.model.KJ, self.W, self.st.c, q.copy(), self.zero, self.u, self.eqs,
                                    self.fscale, self.hgeo, unk, self.Jq, J):
                return None
        elif not _fd_jacobian(self.crane.model.KJ, self.W, self.st.c, q.copy(), self.zero, self.u, self.eqs,
                              self.fscale, self.hgeo, float(value), unk, r0, np.empty(len(r0)), J):
            return None
        self.stats[1] += 1
        return J

    def solve(self, q, mode, value, J=None, maxit=25, max_dyaw=0.5, keep=0, F=None):
        """Newton from q (q[jyaw] = value first in mode 'yaw'); J: a Jacobian to start from (chord
        Newton, refreshed when the residual falls by less than 4x). Returns (q, J at q) or (None, None);
        the tangent solver's warm start is restored on failure or when it jumped (_branch_jump).
        keep: a given J that converged within `keep` iterations is returned as the Jacobian at q (the
        continuation's next predictor); else a fresh one is computed there. F: J's factors if known."""
        ang = self.st.nl_ang.copy()
        unk = self.unknowns(mode)
        q = q.copy()
        if mode == "yaw":
            q[self.jyaw] = value
        tol = self.crane.spec.tolerance
        err_prev, fresh = np.inf, False
        given = J is not None
        F = (_factor(J) if F is None else F) if given else None
        if given and F is None:
            J = None
        for it in range(maxit):
            r, err = self._residual(q, mode, value)
            if not err < math.inf:
                break
            if err < tol:
                if _branch_jump(ang, self.st.nl_ang):
                    break
                if given and it <= keep:
                    return q, J
                return q, self.jacobian(q, unk, mode, value, r)
            if J is None or (it > 0 and err > 0.25 * err_prev and not fresh):
                J, fresh = self.jacobian(q, unk, mode, value, r), True
                if J is None:
                    break
                given = False
                F = _factor(J)
                if F is None:
                    break
            else:
                fresh = False
            err_prev = err
            dx = _lu_apply(F, -r)
            if not np.all(np.isfinite(dx)) or (mode == "height" and abs(dx[np.searchsorted(unk, self.jyaw)]) > max_dyaw):
                break
            q[unk] += dx
            self.stats[0] += 1
        self.st.nl_ang[:] = ang
        return None, None


def _factor(J):
    """LU factors (core/solver/lu.py) of J, or None if J is singular or not finite."""
    LU, piv = J.copy(), np.empty(len(J), np.int64)
    if not lu_factor(LU, piv) or not np.all(np.isfinite(np.diag(LU))):
        return None
    return LU, piv


def _lu_apply(F, b):
    """J^-1 b from J's factors."""
    x = np.array(b, float)
    lu_solve(F[0], F[1], x)
    return x


def _lu_sign(F) -> int:
    """The sign of det J from its LU factors (_factor); 0 if singular."""
    if F is None:
        return 0
    LU, piv = F
    d = np.diag(LU)
    swaps = int(np.count_nonzero(piv != np.arange(len(piv))))
    return (-1) ** (swaps + int(np.count_nonzero(d < 0.0)))


def _branch_jump(before, after, limit=0.5) -> bool:
    """A contact angle of the exact tangents moved by more than `limit` rad (modulo 2 pi) in one solve:
    its warm-started Newton (core/bodies.tangent_spatial) left the tangent it followed for another
    one, an equilibrium of a different rope path. A continuation step moves them by far less."""
    ok = np.isfinite(before) & np.isfinite(after)
    d = np.remainder(after[ok] - before[ok] + math.pi, 2 * math.pi) - math.pi
    return bool(np.any(np.abs(d) > limit))


@dataclass
class YawPath:
    """Equilibria of the crane along the block yaw."""
    yaw: np.ndarray            # rad, prescribed block yaw per accepted point
    height: np.ndarray         # m, fall length
    critical_height: float     # m, the fold of height(yaw): parabola through the highest point and its neighbours
    critical_yaw: float        # rad
    q: np.ndarray              # coordinates at the highest point


def _parabola_vertex(points):
    """Vertex (h, psi) of the parabola h(psi) through three points (psi, h); the middle point if the
    fit is not a maximum near it."""
    (p1, h1), (p2, h2), (p3, h3) = points
    a, b, c = np.linalg.solve([[p1 * p1, p1, 1.0], [p2 * p2, p2, 1.0], [p3 * p3, p3, 1.0]], [h1, h2, h3])
    if a >= 0:
        return h2, p2
    pv = -b / (2 * a)
    if abs(pv - p2) > abs(p3 - p1):
        return h2, p2
    return c - b * b / (4 * a), pv


def cabling_of_model(crane: Crane, st, q=None, dpsi: float = 0.02, d: float = 0.02) -> YawPath:
    """Continuation of the crane's statics in the block yaw from q (default st.q) in steps dpsi (rope
    paid out from the drum as needed): the height rises with the yaw up to the fold (cabling) and falls
    beyond it. The march stops after two falling steps (one alone may be a jump of the tangent points,
    not the fold) or when Newton fails (step cut by 3 down to dpsi / 100); the fold is the vertex of
    the parabola through the highest point and the points +-d around it."""
    S = Statics(crane, st)
    q = st.q.copy() if q is None else q.copy()
    hist = [(q[S.jyaw], crane.height(q), q)]
    step, falling = dpsi, 0
    while falling < 2 and step > dpsi / 100 and hist[-1][0] < math.pi:
        qn, _ = S.solve(hist[-1][2], "yaw", hist[-1][0] + step)
        if qn is None:
            step /= 3.0
            continue
        h = crane.height(qn)
        falling = falling + 1 if h < hist[-1][1] else 0
        hist.append((qn[S.jyaw], h, qn))
    k = max(range(len(hist)), key=lambda i: hist[i][1])
    psi, h, q = hist[k]
    side = [S.solve(q, "yaw", psi + e)[0] for e in (-d, d)]
    ch, cy = h, psi
    if all(x is not None for x in side):
        ch, cy = _parabola_vertex([(psi - d, crane.height(side[0])), (psi, h), (psi + d, crane.height(side[1]))])
    P = np.array([(p_, h_) for p_, h_, _ in hist[:k + 1]])
    return YawPath(yaw=P[:, 0], height=P[:, 1], critical_height=float(ch), critical_yaw=float(cy), q=q)


# --------------------------------------------------------------------------------------- sweep
@dataclass
class SweepResult:
    columns: dict
    critical_height: float | None
    critical_yaw: float | None
    seconds: float               # the sweep, after the first equilibrium
    first_solve_seconds: float   # model build and first equilibrium (incl. loading the compiled kernels)
    path: np.ndarray             # accepted continuation points (h, yaw), then the yaw path up to the fold
    steps: int
    rejected: int
    newton_iterations: int
    jacobians: int
    crane: Crane


# a continuation step whose chord Newton converged within this many iterations keeps its Jacobian for
# the next predictor (the path's Jacobian changes little per step; a fresh one costs an assembly per
# unknown)
KEEP_ITERATIONS = 4


class _Continuation:
    """Natural continuation of the statics in the fall length h."""

    def __init__(self, S: Statics, q, h, J):
        self.S, self.q, self.h, self.J = S, q, h, J
        self.F = _factor(J)          # J's LU factors (kept with it)
        self.unk = S.unknowns("height")
        self.iyaw = int(np.searchsorted(self.unk, S.jyaw))
        self.steps = self.rejected = 0
        self.history = [(h, q[S.jyaw])]
        self.prev = None             # (h, q) of the previous accepted point: the secant predictor

    def continue_to(self, h_target, dh_min, yaw_step):
        """From the current point to h_target; False at a fold (no equilibrium beyond self.h within
        dh_min, or the Jacobian's determinant changes sign: a jump onto the unstable branch)."""
        F = self.F
        sign0 = _lu_sign(F)
        e = np.zeros(len(self.unk))
        e[-1] = 1.0
        while abs(h_target - self.h) > 1e-12 * max(1.0, abs(h_target)):
            v = _lu_apply(F, e)          # dx/dh: the height row is h(q) - h
            dh = h_target - self.h
            if abs(v[self.iyaw] * dh) > yaw_step:
                dh = math.copysign(yaw_step / abs(v[self.iyaw]), dh)
            while True:
                if abs(dh) < dh_min:
                    return False
                qp = self.q.copy()
                if self.prev is not None and abs(dh) <= 2.0 * abs(self.h - self.prev[0]):
                    qp += (self.q - self.prev[1]) * (dh / (self.h - self.prev[0]))   # secant: second order
                else:
                    qp[self.unk] += dh * v
                qn, Jn = self.S.solve(qp, "height", self.h + dh, J=self.J, maxit=12, keep=KEEP_ITERATIONS, F=F)
                ok = qn is not None and abs(qn[self.S.jyaw] - self.q[self.S.jyaw]) <= 4.0 * yaw_step
                Fn = (F if Jn is self.J else _factor(Jn)) if ok else None
                if ok and _lu_sign(Fn) != sign0:     # a kept J: check a fresh one
                    Jn = self.S.jacobian(qn, self.unk, "height", self.h + dh)
                    Fn = _factor(Jn) if Jn is not None else None
                    ok = Fn is not None and _lu_sign(Fn) == sign0
                if ok:
                    self.prev = (self.h, self.q)
                    self.q, self.h, self.J, self.F = qn, self.h + dh, Jn, Fn
                    F = Fn
                    self.steps += 1
                    self.history.append((self.h, qn[self.S.jyaw]))
                    break
                self.rejected += 1
                dh *= 0.5
        return True


def _columns(crane: Crane, n: int) -> dict:
    cols = {"height": np.full(n, np.nan)}
    for nm in ("block.yaw", "block.x", "block.y", "block.z", "block.pitch", "block.roll"):
        cols[nm] = np.full(n, np.nan)
    for i in range(len(crane.falls)):
        cols[f"fall{i + 1}.tension"] = np.full(n, np.nan)
    for k, nm in enumerate(crane.span_names):
        if k not in crane.falls:
            cols[f"{nm}.tension"] = np.full(n, np.nan)
    for nm in ("rope.torque", "rope.twist", "drum.s"):
        cols[nm] = np.full(n, np.nan)
    return cols


class _Recorder:
    """Rows of the sweep's columns at equilibria: the output indices looked up once, the outputs
    evaluated on one scratch copy of the State."""

    def __init__(self, crane: Crane, st):
        m = crane.model
        self.crane, self.st = crane, st.copy()
        ix = {n: k for k, n in enumerate(m.output_names)}
        self.tension = [(f"{nm}.tension", ix[a], ix[b]) for nm, (a, b) in zip(crane.span_names, crane.tension_outputs)]
        rope = crane.spec.rope
        self.torque = [ix[f"{rope}.span{k}.torque"] for k in crane.falls]
        self.twist = [ix[f"{rope}.span{k}.twist"] for k in crane.falls] if "twist" in m.q_kind else None
        self.bd = m.body_dofs[crane.spec.block]
        self.jd = m.sheave_dof[crane.drum]
        # the kernel inputs at the sweep's state (the recorded outputs are element forces and torsion
        # torques: they do not read them), the scratch State's arrays, the outputs
        self.u = kernel_inputs_at(m, self.st)
        self.arrays = self.st.arrays()
        self.y = np.empty(len(m.output_names))

    def record(self, q, cols, i):
        """Row i of the sweep's columns at the equilibrium q."""
        st = self.st
        st.q[:] = q
        y = self.y
        outputs(self.crane.model.KJ, self.arrays, st.c, st.q, st.v, st.qdd, st.q_ref, st.t, self.u, y)
        bd = self.bd
        r20, r21, r22 = _rotation_row_z(q[bd["rx"]], q[bd["ry"]], q[bd["rz"]])
        cols["block.yaw"][i] = q[bd["rz"]]
        cols["block.pitch"][i] = math.asin(max(-1.0, min(1.0, -r20)))
        cols["block.roll"][i] = math.atan2(r21, r22)
        cols["block.x"][i], cols["block.y"][i], cols["block.z"][i] = q[bd["x"]], q[bd["y"]], q[bd["z"]]
        for nm, a, b in self.tension:
            cols[nm][i] = 0.5 * (y[a] + y[b])     # mid-span: the element's EA eps
        cols["rope.torque"][i] = sum(y[k] for k in self.torque) / len(self.torque)
        # no twist state: NaN
        cols["rope.twist"][i] = sum(y[k] for k in self.twist) / len(self.twist) if self.twist else math.nan
        cols["drum.s"][i] = q[self.jd]


def sweep(crane: Crane, heights=None) -> SweepResult:
    """Equilibria over the heights (default: the scene's linspace(height_min, height_max, heights));
    NaN rows beyond the critical height."""
    spec = crane.spec
    heights = np.linspace(spec.height_min, spec.height_max, spec.heights) if heights is None else np.asarray(heights, float)
    t0 = time.perf_counter()
    try:
        st = crane.sim.initial_state()
    except SolverError as exc:
        raise CraneError(f"{exc}{_no_yaw_stiffness(crane)}") from None
    S = Statics(crane, st)
    h0 = crane.height(st.q)
    q, J = S.solve(st.q, "height", h0)
    if q is None or np.linalg.cond(J) > 1e14:    # singular: some coordinate (the yaw) is undetermined
        raise CraneError(f"{crane.scene.source}: no unique equilibrium found in the scene's configuration "
                         f"(height {h0:.3f} m){_no_yaw_stiffness(crane) or _yaw_keys(crane)}")
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    dh_min = spec.fold_tol * float(np.ptp(heights) or 1.0)
    cont = _Continuation(S, q, h0, J)
    rec = _Recorder(crane, st)
    cols = _columns(crane, len(heights))
    cols["height"][:] = heights
    crit = crit_yaw = None
    path = []
    for i, h in enumerate(heights):
        if not cont.continue_to(h, dh_min, spec.yaw_step):
            fold = cabling_of_model(crane, st, cont.q)
            crit, crit_yaw = fold.critical_height, fold.critical_yaw
            path = list(zip(fold.height[1:], fold.yaw[1:]))
            break
        if i == 0:
            cont.history = [(cont.h, cont.q[S.jyaw])]
        rec.record(cont.q, cols, i)
    return SweepResult(columns=cols, critical_height=crit, critical_yaw=crit_yaw,
                       seconds=time.perf_counter() - t0, first_solve_seconds=t_first,
                       path=np.array(cont.history + path), steps=cont.steps, rejected=cont.rejected,
                       newton_iterations=S.stats[0], jacobians=S.stats[1], crane=crane)


def _no_yaw_stiffness(crane: Crane) -> str:
    """Why the statics can fail before it starts: nothing resists the block's yaw. Falls spaced apart
    turn the block back (the block rises as it turns); a rope with torsional stiffness does too. One
    fall (or falls through one point) with the torque-factor law and GJ0 = k1 = 0 has neither."""
    tor = next(rp for rp in crane.scene.ropes if rp.name == crane.spec.rope).torsion
    if tor.law != "torque-factor" or tor.GJ0 > 0 or tor.k1 != 0 or (len(crane.falls) > 1 and crane.S_eff > 1e-9):
        return ""
    return (f": the hook block's yaw has no stiffness — {len(crane.falls)} fall(s) at one point and the "
            f"rope's torsion law = 'torque-factor' with GJ0 = {tor.GJ0:g}, k1 = {tor.k1:g} give no torsional "
            f"stiffness, so nothing turns the block back (k0 = {tor.k0:g}: "
            + ("the yaw is undetermined" if tor.k0 == 0 else "the rope torque turns it freely")
            + "). Give the rope torsional stiffness (torsion GJ0 > 0, or law = 'costello' or 'feyrer') "
              "or reeve two or more falls")


def _yaw_keys(crane: Crane) -> str:
    """The keys a singular block equilibrium depends on, when `_no_yaw_stiffness` has no better reason."""
    i = next(k for k, rp in enumerate(crane.scene.ropes) if rp.name == crane.spec.rope)
    tor = crane.scene.ropes[i].torsion
    b = next(k for k, bd in enumerate(crane.scene.bodies) if bd.name == crane.spec.block)
    return (f": the hook block's yaw is not determined by the rope torque (ropes[{i}].torsion: law = "
            f"{tor.law!r}, diameter = {tor.diameter:g} m, k0 = {tor.k0:g}, GJ0 = {tor.GJ0:g} N·m²) and the "
            f"falls at this position (bodies[{b}].position); check these values (the diameter in m)")


# ---------------------------------------------------------------------------------------- front end
def _torsion(crane: Crane):
    return next(rp for rp in crane.scene.ropes if rp.name == crane.spec.rope).torsion


def summary(res: SweepResult) -> dict:
    m = res.crane
    s = _torsion(m)
    h = res.columns["height"]
    return {
        "scene": m.scene.name, "source": m.scene.source, "law": s.law, "k0": s.k0, "k1": s.k1, "GJ0": s.GJ0,
        "diameter": s.diameter, "falls": len(m.falls), "hook_load_N": m.weight,
        "height_min": float(h[0]), "height_max": float(h[-1]), "heights": int(len(h)),
        "critical_height": res.critical_height, "critical_yaw": res.critical_yaw,
        "effective_spacing": m.S_eff, "critical_height_estimate": None if math.isnan(m.H_est) else m.H_est,
        "max_yaw": float(np.nanmax(np.abs(res.columns["block.yaw"]))) if np.isfinite(res.columns["block.yaw"]).any() else None,
        "sweep_seconds": res.seconds, "first_solve_seconds": res.first_solve_seconds, "steps": res.steps, "rejected_steps": res.rejected,
        "newton_iterations": res.newton_iterations, "jacobians": res.jacobians, "unknowns": m.model.nq,
    }


def plot_rotation(path, res: SweepResult):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = res.columns
    m = res.crane
    tor = _torsion(m)
    h = c["height"]
    fig, axes = plt.subplots(3, 1, figsize=(8, 8.5), sharex=True)
    ax = axes[0]
    ax.plot(res.path[:, 0], np.degrees(res.path[:, 1]), lw=1.5, label="statics of the model (continuation path)")
    if not math.isnan(m.H_est):
        ok = h < m.H_est
        ax.plot(h[ok], np.degrees(np.arcsin(np.clip(h[ok] / m.H_est, -1, 1))) * np.sign(tor.k0), "k--", lw=0.8,
                label=f"sin ψ = h / H_est  (torque factor, H_est = {m.H_est:.4g} m)")
    if res.critical_height is not None:
        for a in axes:
            a.axvline(res.critical_height, color="r", lw=0.8)
        ax.annotate(f"cabling at {res.critical_height:.2f} m", (res.critical_height, 0), color="r",
                    rotation=90, va="bottom", ha="right", fontsize=8)
    ax.set_ylabel("block yaw ψ [deg]")
    ax.legend(fontsize=7)
    ax.set_title(f"{m.scene.name}: {len(m.falls)} falls, {tor.law}, k0 = {tor.k0:g}, d = {tor.diameter * 1e3:g} mm")
    for nm in c:
        if nm.endswith(".tension"):
            axes[1].plot(h, np.asarray(c[nm]) / 1e3, lw=0.8, label=nm)
    axes[1].set_ylabel("tension [kN]")
    axes[1].legend(fontsize=6, ncol=3)
    axes[2].plot(h, c["rope.torque"], lw=1.2)
    axes[2].set_ylabel("rope torque [N·m]")
    axes[2].set_xlabel("hoist height h [m]")
    for a in axes:
        a.grid(True, alpha=0.3)
        a.set_xlim(h[0], h[-1])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def write_rotation_csv(path, cols: dict):
    names = list(cols)
    data = np.column_stack([np.asarray(cols[n], float) for n in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g", encoding="utf-8")
    return Path(path)


def cli_crane(args) -> int:
    scene_sets = {}
    if getattr(args, "set", None):
        from .overrides import OverrideError, parse_sets, split

        scene_sets, drive_sets, load = split(parse_sets(args.set))
        if drive_sets or load is not None:
            raise OverrideError("--set: a crane study takes scene keys only (bodies.block.mass, rope.EA, ...)")
    crane = load_crane(args.scene, scene_sets)
    from ..core.plausibility import check_or_raise
    warnings = check_or_raise(crane.scene)
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    spec = crane.spec
    heights = None
    if args.heights is not None:
        if args.heights < 2:
            raise ValueError("--heights must be >= 2")
        heights = np.linspace(spec.height_min, spec.height_max, args.heights)
    res = sweep(crane, heights)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_rotation_csv(out / "rotation.csv", res.columns)
    plot_rotation(out / "rotation.png", res)
    summ = summary(res)
    summ["warnings"] = warnings
    (out / "summary.json").write_text(json.dumps(summ, indent=2) + "\n", encoding="utf-8")
    ch = res.critical_height
    yaw = res.columns["block.yaw"]
    last = np.flatnonzero(np.isfinite(yaw))
    msg = (f"{crane.scene.name}: {len(res.columns['height'])} heights in {res.seconds:.3f} s "
           f"({res.steps} steps, {res.newton_iterations} Newton iterations); ")
    if ch is None:
        msg += f"yaw {np.degrees(yaw[last[-1]]):.2f} deg at {res.columns['height'][last[-1]]:.1f} m, no cabling in range"
    else:
        msg += f"cabling: equilibrium lost at h = {ch:.3f} m (yaw {np.degrees(res.critical_yaw):.1f} deg)"
    print(msg + f" -> {out}/rotation.csv, rotation.png, summary.json")
    return 0




#: motor outputs whose sign follows the hoist convention
MOTOR_OUTPUTS = ("motor.torque", "motor.speed", "motor.angle")


def hoist_convention(scene: Scene, cols: dict) -> str:
    """Give a crane scene's motor outputs the crane FMUs' sign (positive torque, speed and angle hoist):
    the engine's sign follows the reeving, so the columns are negated when the torque that holds the
    load at t = 0 is negative. Elevator scenes keep the engine's (their routes make positive raise the
    car). Returns the convention applied, for the run's summary."""
    from ..fmu.crane import is_crane_scene

    if not (is_crane_scene(scene) or "crane" in scene.extra) or "motor.torque" not in cols:
        return "engine: motor.* positive counter-clockwise about the driven sheave's axis"
    if float(np.asarray(cols["motor.torque"])[0]) < 0.0:
        for n in MOTOR_OUTPUTS:
            if n in cols:
                cols[n] = -np.asarray(cols[n])
    return "hoist: motor.torque, motor.speed, motor.angle positive when hoisting (as the crane FMUs)"


def crane_angles(scene: Scene, cols: dict) -> list:
    """Add to a `simulate` record of a slewing crane (a body on a revolute joint with a hoist) the crane
    plant FMU's derived angles, `payload.swing_radial`, `payload.swing_tangential`, `payload.yaw` [rad]
    (components.craneplant: the same expressions, from the same outputs); returns the names added."""
    from ..components.craneplant import DERIVED, CranePlant
    from ..fmu.crane import is_crane_scene

    if not is_crane_scene(scene):
        return []
    cp = CranePlant(scene, "speed")
    names = cp.plant.output_names
    if any(n not in cols for n in names):
        return []
    rows = np.column_stack([np.asarray(cols[n], float) for n in names])
    out = np.array([cp._outputs(y)[-len(DERIVED):] for y in rows])
    for k, n in enumerate(DERIVED):
        cols[n] = out[:, k]
    return list(DERIVED)


def plot_crane_angles(path, scene: Scene, time_, cols: dict):
    """crane.png of a `simulate` run: the joint angles of the scene's revolute bodies (the jib), the
    payload's swing angles and the yaw of the payload or the hook block [deg]; None when the record has
    none of them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    joints = [f"{b.name}.angle" for b in scene.bodies if b.joint == "revolute" and f"{b.name}.angle" in cols]
    swing = [n for n in ("payload.swing_radial", "payload.swing_tangential") if n in cols]
    # yaw: the slewing payload's heading, else the z component of each rotating body's rotation vector
    # (the yaw while the tilt is small, as `reeve-fmu crane` reports block.yaw)
    yaw = ["payload.yaw"] if "payload.yaw" in cols else [
        f"{b.name}.rotation.z" for b in scene.bodies if "rotation" in b.free and f"{b.name}.rotation.z" in cols]
    panels = [(lab, ns) for lab, ns in (("joint angle [deg]", joints), ("payload swing [deg]", swing),
                                        ("yaw [deg]", yaw)) if ns]
    if not panels:
        return None
    fig, ax = plt.subplots(len(panels), 1, figsize=(10, 2.6 * len(panels)), sharex=True, squeeze=False)
    for a, (lab, ns) in zip(ax[:, 0], panels):
        for n in ns:
            a.plot(time_, np.degrees(np.asarray(cols[n], float)), lw=0.9, label=n)
        a.set_ylabel(lab)
        a.grid(alpha=0.3)
        a.legend(loc="best", fontsize=8)
    ax[-1, 0].set_xlabel("time [s]")
    ax[0, 0].set_title(f"{scene.name}: crane angles")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
