"""Quasi-static crane hoist with axial-torsion coupling: hook-block rotation and cabling (docs/theory.md §5.3).

Model. The scene's rope runs drum -> lead line(s) -> boom-tip sheaves -> n falls between tip sheaves
and hook-block sheaves (any axes) -> dead end on the tip or on the block. Every straight span is one
linear ALE element with the torsion field of docs/theory.md §1.5 (`elements.torsion.torsion_span`): node
positions at the rope-sheave tangent points, material coordinates s at the sheave nodes (W0 wraps:
in- and out-node share s), a torsion angle phi per sheave node (phi_in = phi_out: the groove
transports twist), phi fixed at the drum and the dead end (clamped rope ends). The hook block is rigid
with the unknown position and yaw psi (pose = "yaw") or the full pose (yaw, pitch, roll; pose = "full")
and carries the hook load W at its centre of gravity. Sheaves are frictionless and massless.

Tangent points are exact (docs/theory.md §4.2): every evaluation of the equations places them on the
current common tangents of the route circles (Newton on the contact angles, warm-started), so
tangent points slide around the sheaves as the block moves and turns. The forces on the block are
the rope forces at those points (for a frictionless sheave that is exact: the rope path is stationary
in the contact angles). The twist-free reference state (kappa_t = 0 in every span) is the scene's
initial configuration.

Equations, for a prescribed hoist height h:
    dPi/d(pose) = 0, dPi/ds_j = 0 (sheave nodes: tension balance), dPi/dphi_j = 0 (torque balance),
    h(x) - h = 0,
Pi = sum over spans of [l w(eps, kappa_t) - rhoA l g.(r_A + r_B)/2] - W g.r_cg. The unknowns are the
pose, s at the drum (the drum coordinate follows from h: it replaces the block's vertical equation)
and at the sheave nodes, and phi at the sheave nodes. h is the mean vertical extent of the falls
(top tangent point minus bottom tangent point). The Jacobian is by central differences of the
compiled residual (21 unknowns for 8 falls).

Continuation over h: tangent predictor dx/dh = J^-1 e_h, chord-Newton corrector (Jacobian refreshed
when the contraction is poor), step control (the predicted yaw change per step is limited; a failed
corrector halves the step). Cabling is the fold (limit point) of the equilibrium path: past it no
equilibrium exists with the block turned less than about 90 deg. The continuation approaches it with
shrinking steps; when the step falls below `fold_tol` x the height range the fold is located, the
critical height is refined by a parabola h(psi) through the last accepted points, and the remaining
heights are reported as NaN. A change of sign of det J between accepted points (a jump over a fold)
is refused the same way.
"""
from __future__ import annotations

from dataclasses import dataclass
import json
import math
from pathlib import Path
import sys
import time

import numpy as np

from ..core._jit import njit
from ..core.elements.torsion import LAWS, torsion_span
from ..core.builder.bodies import world
from ..core.builder.routes import span_tangents, stop_geometry
from ..core.builder.state import start
from ..core.geometry import GeometryError, _basis
from ..core.scene import Scene, SceneError, _Reader, load_scene, parse_scene
from ..core.system import assemble


class CraneError(ValueError):
    """The crane statics cannot start (no equilibrium in the scene's own configuration)."""

CRANE_KEYS = {"block", "rope", "diameter", "law", "k0", "k1", "GJ0", "payload", "cg", "pose",
              "height_min", "height_max", "heights", "rope_weight", "yaw_step", "tolerance", "fold_tol"}


# ------------------------------------------------------------------------------------------ schema
@dataclass(frozen=True)
class CraneSpec:
    block: str                 # hook-block body
    rope: str                  # hoist rope
    diameter: float            # m, nominal rope diameter d
    law: str                   # torque-factor | costello | feyrer
    k0: float                  # -, torque factor at zero twist (sign = lay direction)
    k1: float = 0.0            # -, twist dependence of the torque factor k = k0 + k1 d kappa_t
    GJ0: float = 0.0           # N m^2, torsional stiffness
    payload: float = 0.0       # kg, hook load added to the block body's mass
    cg: tuple = (0.0, 0.0, 0.0)  # m, centre of gravity relative to the block reference point (block frame)
    pose: str = "yaw"          # yaw: x, y, z, yaw | full: x, y, z, yaw, pitch, roll
    height_min: float = 0.0    # m
    height_max: float = 0.0    # m
    heights: int = 200         # number of heights of the sweep
    rope_weight: bool = True   # include the rope's own weight
    yaw_step: float = 0.05     # rad, largest predicted yaw change per continuation step
    tolerance: float = 1e-10   # Newton tolerance on the scaled residual
    fold_tol: float = 1e-6     # smallest height step, relative to the range: the fold is located to it


def parse_crane(scene: Scene) -> CraneSpec:
    """Validate the scene's [crane] section (errors name the file and the key)."""
    r = _Reader(scene.source)
    if "crane" not in scene.extra:
        r.fail("crane", "missing section: a crane scene needs a [crane] table (see docs/crane.md)")
    c = r.table(scene.extra["crane"], "crane", CRANE_KEYS)
    if scene.model not in ("spatial-torsion", "spatial"):
        r.fail("scene.model", f"the crane statics is three-dimensional: use 'spatial-torsion', got {scene.model!r}")
    bodies = {b.name for b in scene.bodies}
    block = r.string(c, "crane", "block", required=True)
    if block not in bodies:
        r.fail("crane.block", f"unknown body {block!r}; bodies: {', '.join(sorted(bodies)) or 'none'}")
    ropes = [rp.name for rp in scene.ropes]
    if "rope" in c:
        rope = r.string(c, "crane", "rope")
        if rope not in ropes:
            r.fail("crane.rope", f"unknown rope {rope!r}; ropes: {', '.join(ropes)}")
    elif len(ropes) == 1:
        rope = ropes[0]
    else:
        r.fail("crane", f"missing required key 'rope' (the scene has {len(ropes)} ropes)")
    spec = CraneSpec(
        block=block, rope=rope,
        diameter=r.number(c, "crane", "diameter", positive=True, required=True),
        law=r.string(c, "crane", "law", "costello", tuple(LAWS)),
        k0=r.number(c, "crane", "k0", required=True),
        k1=r.number(c, "crane", "k1", 0.0),
        GJ0=r.number(c, "crane", "GJ0", 0.0, nonneg=True),
        payload=r.number(c, "crane", "payload", 0.0, nonneg=True),
        cg=r.vector(c, "crane", "cg", default=(0.0, 0.0, 0.0)),
        pose=r.string(c, "crane", "pose", "yaw", ("yaw", "full")),
        height_min=r.number(c, "crane", "height_min", positive=True, required=True),
        height_max=r.number(c, "crane", "height_max", positive=True, required=True),
        heights=r.integer(c, "crane", "heights", 200, minimum=2),
        rope_weight=r.boolean(c, "crane", "rope_weight", True),
        yaw_step=r.number(c, "crane", "yaw_step", 0.05, positive=True),
        tolerance=r.number(c, "crane", "tolerance", 1e-10, positive=True),
        fold_tol=r.number(c, "crane", "fold_tol", 1e-6, positive=True),
    )
    if spec.height_max <= spec.height_min:
        r.fail("crane.height_max", f"must be > height_min = {spec.height_min:g}, got {spec.height_max:g}")
    if spec.pose == "full" and spec.cg[2] >= 0.0:
        r.fail("crane.cg", "pose = 'full' needs the centre of gravity below the block reference point "
                           f"(cg[2] < 0; the block hangs like a pendulum), got {list(spec.cg)}")
    return spec


# --------------------------------------------------------------------------------- compiled kernels
@njit(cache=True)
def _rotation(x, npose, Rm, dR):
    """Rm = Rz(yaw) Ry(pitch) Rx(roll) and dR[j] = dRm/d(angle j) (j: yaw, pitch, roll)."""
    ps = x[3]
    th = x[4] if npose == 6 else 0.0
    ph = x[5] if npose == 6 else 0.0
    cz, sz = math.cos(ps), math.sin(ps)
    cy, sy = math.cos(th), math.sin(th)
    cx, sx = math.cos(ph), math.sin(ph)
    Rm[0, 0] = cz * cy
    Rm[0, 1] = cz * sy * sx - sz * cx
    Rm[0, 2] = cz * sy * cx + sz * sx
    Rm[1, 0] = sz * cy
    Rm[1, 1] = sz * sy * sx + cz * cx
    Rm[1, 2] = sz * sy * cx - cz * sx
    Rm[2, 0] = -sy
    Rm[2, 1] = cy * sx
    Rm[2, 2] = cy * cx
    # d/d yaw = e_z x Rm
    for m in range(3):
        dR[0, 0, m] = -Rm[1, m]
        dR[0, 1, m] = Rm[0, m]
        dR[0, 2, m] = 0.0
    dR[1, 0, 0] = -cz * sy
    dR[1, 0, 1] = cz * cy * sx
    dR[1, 0, 2] = cz * cy * cx
    dR[1, 1, 0] = -sz * sy
    dR[1, 1, 1] = sz * cy * sx
    dR[1, 1, 2] = sz * cy * cx
    dR[1, 2, 0] = -cy
    dR[1, 2, 1] = -sy * sx
    dR[1, 2, 2] = -sy * cx
    dR[2, 0, 0] = 0.0
    dR[2, 0, 1] = cz * sy * cx + sz * sx
    dR[2, 0, 2] = -cz * sy * sx + sz * cx
    dR[2, 1, 0] = 0.0
    dR[2, 1, 1] = sz * sy * cx - cz * sx
    dR[2, 1, 2] = -sz * sy * sx - cz * cx
    dR[2, 2, 0] = 0.0
    dR[2, 2, 1] = cy * cx
    dR[2, 2, 2] = -cy * sx


@njit(cache=True)
def _lu_solve(A, b, x):
    """x = A^-1 b by Gaussian elimination with partial pivoting (A, b overwritten); False if
    singular. (Hand-written: numba's np.linalg.solve costs ~10 s of compile time.)"""
    n = b.shape[0]
    for k in range(n):
        p = k
        amax = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > amax:
                amax = abs(A[i, k])
                p = i
        if not amax > 0.0:
            return False
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
            b[k], b[p] = b[p], b[k]
        piv = A[k, k]
        for i in range(k + 1, n):
            f = A[i, k] / piv
            if f != 0.0:
                for j in range(k + 1, n):
                    A[i, j] -= f * A[k, j]
                b[i] -= f * b[k]
    for i in range(n - 1, -1, -1):
        acc = b[i]
        for j in range(i + 1, n):
            acc -= A[i, j] * x[j]
        x[i] = acc / A[i, i]
    return True


@njit(cache=True)
def _contact(cA, uA, wA, RA, cB, uB, wB, RB, a0, b0):
    """Contact angles of the common tangent from circle A to circle B (radius 0: a point), Newton
    from (a0, b0): (P_B - P_A).rho_X = 0 for each circle (docs/theory.md §4.2)."""
    aA = a0
    aB = b0
    extra = 0
    for _ in range(40):
        caA, saA = math.cos(aA), math.sin(aA)
        caB, saB = math.cos(aB), math.sin(aB)
        fA = 0.0
        fB = 0.0
        jAA = 0.0
        jAB = 0.0
        jBA = 0.0
        jBB = 0.0
        for k in range(3):
            rA = caA * uA[k] + saA * wA[k]
            rB = caB * uB[k] + saB * wB[k]
            pA = -saA * uA[k] + caA * wA[k]
            pB = -saB * uB[k] + caB * wB[k]
            Dk = cB[k] + RB * rB - cA[k] - RA * rA
            fA += Dk * rA
            fB += Dk * rB
            jAA += Dk * pA
            jBB += Dk * pB
            jAB += RB * pB * rA
            jBA += -RA * pA * rB
        dA = 0.0
        dB = 0.0
        if RA > 0.0 and RB > 0.0:
            det = jAA * jBB - jAB * jBA
            dA = -(jBB * fA - jAB * fB) / det
            dB = -(-jBA * fA + jAA * fB) / det
        elif RA > 0.0:
            dA = -fA / jAA
        elif RB > 0.0:
            dB = -fB / jBB
        aA += dA
        aB += dB
        if abs(dA) + abs(dB) < 1e-13:
            extra += 1
            if extra > 1:
                break
    return aA, aB


@njit(cache=True)
def _evaluate(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, R, spo, wk):
    """Residual R(x; h) and per-span outputs spo[k] = [S, M, eps, kappa, Delta, l, angA, angB, hk];
    returns (mean fall height, total potential Pi). With ip[6] = 0 the contact angles stay at sp_f
    (tangent points fixed in their body frames): R is then exactly grad Pi for the energy laws (tests).

    ip = [law, npose, nst, nsp, drum index in x, rope weight flag, exact tangents flag]
    fp = [EA, rhoA, d, k0, k1, GJ0, mass, gx, gy, gz, cgx, cgy, cgz]
    st_i[k] = [body (0 ground, 1 block), x index of s (-1: fixed), x index of phi (-1: fixed)]
    st_f[k] = [c(3), u(3), w(3), R, v(3), s fixed, phi fixed]  (block stops in the block frame)
    sp_i[k] = 1: fall with its top at the span start, -1: top at the end, 0: not a fall
    sp_f[k] = [contact angle at start, at end, Delta reference]
    """
    law = ip[0]
    npose = ip[1]
    nsp = ip[3]
    drum = ip[4]
    EA, rhoA, d, k0, k1, GJ0, mass = fp[0], fp[1], fp[2], fp[3], fp[4], fp[5], fp[6]
    if ip[5] == 0:
        rhoA = 0.0
    g = fp[7:10]
    Rm = np.empty((3, 3))
    dR = np.empty((3, 3, 3))
    _rotation(x, npose, Rm, dR)
    nang = npose - 3
    for i in range(R.shape[0]):
        R[i] = 0.0
    grad = np.empty(16)
    cw = np.empty((2, 3))   # world centre
    uw = np.empty((2, 3))
    ww = np.empty((2, 3))
    vw = np.empty((2, 3))
    rw = np.empty((2, 3))   # world contact point
    rb = np.empty((2, 3))   # contact point in the block frame
    vb = np.empty((2, 3))
    Rad = np.empty(2)
    sv = np.empty(2)
    pv = np.empty(2)
    hsum = 0.0
    nfall = 0
    Pi = 0.0
    for k in range(nsp):
        for e in range(2):
            st = k + e
            Rad[e] = st_f[st, 9]
            for q in range(3):
                vb[e, q] = st_f[st, 10 + q]
            if st_i[st, 0] == 1:
                for q in range(3):
                    c = x[q]
                    u = 0.0
                    w = 0.0
                    v = 0.0
                    for m in range(3):
                        c += Rm[q, m] * st_f[st, m]
                        u += Rm[q, m] * st_f[st, 3 + m]
                        w += Rm[q, m] * st_f[st, 6 + m]
                        v += Rm[q, m] * st_f[st, 10 + m]
                    cw[e, q] = c
                    uw[e, q] = u
                    ww[e, q] = w
                    vw[e, q] = v
            else:
                for q in range(3):
                    cw[e, q] = st_f[st, q]
                    uw[e, q] = st_f[st, 3 + q]
                    ww[e, q] = st_f[st, 6 + q]
                    vw[e, q] = st_f[st, 10 + q]
        if ip[6] == 0 or (st_i[k, 0] == 0 and st_i[k + 1, 0] == 0):
            aA, aB = sp_f[k, 0], sp_f[k, 1]     # frozen contacts, or both ends on the ground
        else:
            aA, aB = _contact(cw[0], uw[0], ww[0], Rad[0], cw[1], uw[1], ww[1], Rad[1], sp_f[k, 0], sp_f[k, 1])
        ang = (aA, aB)
        for e in range(2):
            st = k + e
            ca, sa = math.cos(ang[e]), math.sin(ang[e])
            for q in range(3):
                rw[e, q] = cw[e, q] + Rad[e] * (ca * uw[e, q] + sa * ww[e, q])
                rb[e, q] = st_f[st, q] + Rad[e] * (ca * st_f[st, 3 + q] + sa * st_f[st, 6 + q])
        for e in range(2):
            st = k + e
            js = st_i[st, 1]
            jp = st_i[st, 2]
            sv[e] = x[js] if js >= 0 else st_f[st, 13]
            pv[e] = x[jp] if jp >= 0 else st_f[st, 14]
        S, M, eps, kap, delta, V = torsion_span(law, EA, rhoA, d, k0, k1, GJ0, g, rw[0], rw[1], sv[0], sv[1],
                                                pv[0], pv[1], vw[0], vw[1], sp_f[k, 2], grad, wk)
        Pi += V
        hk = 0.0
        if sp_i[k] != 0:
            hk = rw[0, 2] - rw[1, 2] if sp_i[k] == 1 else rw[1, 2] - rw[0, 2]
            hsum += hk
            nfall += 1
        spo[k, 0] = S
        spo[k, 1] = M
        spo[k, 2] = eps
        spo[k, 3] = kap
        spo[k, 4] = delta
        spo[k, 5] = sv[1] - sv[0]
        spo[k, 6] = aA
        spo[k, 7] = aB
        spo[k, 8] = hk
        for e in range(2):
            st = k + e
            if st_i[st, 0] == 1:
                o = 3 * e
                for q in range(3):
                    R[q] += grad[o + q]
                for j in range(nang):
                    acc = 0.0
                    for q in range(3):
                        dr = 0.0
                        dv = 0.0
                        for m in range(3):
                            dr += dR[j, q, m] * rb[e, m]
                            dv += dR[j, q, m] * vb[e, m]
                        acc += grad[o + q] * dr + grad[10 + o + q] * dv
                    R[3 + j] += acc
            js = st_i[st, 1]
            if js >= 0:
                R[js] += grad[6 + e]
            jp = st_i[st, 2]
            if jp >= 0:
                R[jp] += grad[8 + e]
    # hook load: V = -m g.(p + Rm cg)
    for q in range(3):
        R[q] -= mass * g[q]
        cgw = x[q]
        for m in range(3):
            cgw += Rm[q, m] * fp[10 + m]
        Pi -= mass * g[q] * cgw
    for j in range(nang):
        acc = 0.0
        for q in range(3):
            dc = 0.0
            for m in range(3):
                dc += dR[j, q, m] * fp[10 + m]
            acc += g[q] * dc
        R[3 + j] -= mass * acc
    hmean = hsum / nfall
    R[drum] = hmean - ht
    return hmean, Pi


@njit(cache=True)
def _jacobian(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, J, spo, wk, step):
    """Forward differences (n + 1 residuals; central ones gained nothing measurable in Newton)."""
    n = x.shape[0]
    R0 = np.empty(n)
    Rp = np.empty(n)
    _evaluate(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, R0, spo, wk)
    for j in range(n):
        xj = x[j]
        x[j] = xj + step
        _evaluate(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, Rp, spo, wk)
        x[j] = xj
        for i in range(n):
            J[i, j] = (Rp[i] - R0[i]) / step


@njit(cache=True)
def _newton(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, J, have_jac, rscale, tol, maxit, max_dyaw, spo, wk, stats):
    """Chord Newton: J (given when have_jac) is refreshed when the scaled residual falls by less
    than a factor 4. Returns 0 converged, 1 no convergence, 2 non-finite, 3 yaw step too large.
    stats += [iterations, jacobian evaluations]."""
    n = x.shape[0]
    R = np.empty(n)
    A = np.empty((n, n))
    rhs = np.empty(n)
    dx = np.empty(n)
    fresh = False
    if not have_jac:
        _jacobian(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, J, spo, wk, 1e-6)
        stats[1] += 1
        fresh = True
    err_prev = np.inf
    for it in range(maxit):
        _evaluate(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, R, spo, wk)
        err = 0.0
        for i in range(n):
            e = abs(R[i]) / rscale[i]
            if not e < np.inf:
                return 2
            if e > err:
                err = e
        if err < tol:
            return 0
        if it > 0 and err > 0.25 * err_prev and not fresh:
            _jacobian(x, ht, ip, fp, st_i, st_f, sp_i, sp_f, J, spo, wk, 1e-6)
            stats[1] += 1
            fresh = True
        else:
            fresh = False
        err_prev = err
        for i in range(n):
            rhs[i] = -R[i]
            for j in range(n):
                A[i, j] = J[i, j]
        if not _lu_solve(A, rhs, dx):
            return 2
        stats[0] += 1
        for i in range(n):
            if not abs(dx[i]) < np.inf:
                return 2
        if abs(dx[3]) > max_dyaw:
            return 3
        for i in range(n):
            x[i] += dx[i]
    return 1


# ------------------------------------------------------------------------------------------- model
@dataclass
class CraneModel:
    scene: Scene
    spec: CraneSpec
    npose: int
    nx: int
    drum_idx: int
    ip: np.ndarray
    fp: np.ndarray
    st_i: np.ndarray
    st_f: np.ndarray
    sp_i: np.ndarray
    sp_f: np.ndarray          # mutable: contact angles and Delta references of the current state
    rscale: np.ndarray
    falls: tuple              # span indices of the falls, route order
    span_names: tuple
    h_ref: float              # height of the scene's configuration (twist-free reference)
    p_ref: np.ndarray         # block position in the scene
    s_ref: np.ndarray         # s per stop in the reference (unstretched = geometric)
    phi_ref: np.ndarray       # phi per stop in the twist-free reference
    weight: float             # N, hook load incl. the block
    S_eff: float              # m, effective fall spacing 2 sqrt(sum p_b.p_t / n)
    H_est: float              # m, torque-factor estimate of the critical height (nan if k0 = 0)
    torsion: bool = True      # phi unknowns present (False: torque-factor law with GJ0 = k1 = 0)

    def x_names(self):
        names = ["block.x", "block.y", "block.z", "block.yaw"] + (["block.pitch", "block.roll"] if self.npose == 6 else [])
        stops = self.scene_route()
        extra = {}
        for k, st in enumerate(stops):
            js, jp = self.st_i[k, 1], self.st_i[k, 2]
            label = st.sheave or "dead_end"
            if js >= 0:
                extra[js] = f"{label}.s"
            if jp >= 0:
                extra[jp] = f"{label}.phi"
        return names + [extra[i] for i in range(self.npose, self.nx)]

    def scene_route(self):
        return next(r for r in self.scene.ropes if r.name == self.spec.rope).route


def _route_geometry(scene: Scene, stops, spec: CraneSpec, r, rpath) -> list:
    """Per route stop (world centre, radius, axis, wrap sense, on the block) from the model
    builder's supports step; a sheave or dead end off the ground and off the hook block fails with
    the key's path."""
    bs = start(scene)
    on_block = []
    for k, st in enumerate(stops):
        if st.sheave is not None:
            sh = bs.sheaves[st.sheave]
            if sh.body not in (None, spec.block):
                r.fail(f"sheaves.{sh.name}.body", f"the crane model moves only the hook block {spec.block!r}; "
                                                  f"sheave on body {sh.body!r}")
            on_block.append(sh.body == spec.block)
        else:
            if st.anchor not in ("ground", spec.block):
                r.fail(f"{rpath}.route[{k}].anchor", f"the dead end must be on the ground (boom tip) or on "
                                                     f"the hook block {spec.block!r}, got {st.anchor!r}")
            on_block.append(st.anchor == spec.block)
    geo = stop_geometry(stops, bs.sheaves, lambda body, offset: world(bs, body, offset))
    return [(c, R, None if a is None else np.asarray(a, float), sg, on)
            for (c, R, a, sg), on in zip(geo, on_block)]


def _critical_height_estimate(T, falls, sp_i, p0, spec: CraneSpec):
    """Effective spacing and the torque-factor estimate of the critical height
    (docs/reference-sets.md §5.3): sum over falls of the moment (W/n)(p_b(psi) x p_t)_z / h
    = -(W/(n h)) (P sin psi - Q cos psi)."""
    nf = len(falls)
    P = Q = 0.0
    for k in falls:
        top, bot = (T[k][0], T[k][1]) if sp_i[k] == 1 else (T[k][1], T[k][0])
        pt, pb = top[:2] - p0[:2], bot[:2] - p0[:2]
        P += pt @ pb
        Q += pb[0] * pt[1] - pb[1] * pt[0]
    S_eff = 2.0 * math.sqrt(max(P, 0.0) / nf)
    H_est = math.hypot(P, Q) / (nf * abs(spec.k0) * spec.diameter) if spec.k0 != 0 else math.nan
    return S_eff, H_est


def _span_names(sp_i, falls) -> list:
    """fall1 ... fallN for the falls (route order), lead, lead2, ... for the other spans."""
    names = []
    lead = 0
    for k in range(len(sp_i)):
        if sp_i[k] != 0:
            names.append(f"fall{falls.index(k) + 1}")
        else:
            lead += 1
            names.append("lead" if lead == 1 else f"lead{lead}")
    return names


def build_crane(scene: Scene, spec: CraneSpec | None = None) -> CraneModel:
    """Compile the crane statics from a validated scene and its [crane] section."""
    spec = parse_crane(scene) if spec is None else spec
    r = _Reader(scene.source)
    rope = next(rp for rp in scene.ropes if rp.name == spec.rope)
    rpath = f"ropes[{[rp.name for rp in scene.ropes].index(rope.name)}]"
    sheaves = {s.name: s for s in scene.sheaves}
    bodies = {b.name: b for b in scene.bodies}
    stops = rope.route
    if stops[0].sheave is None or sheaves[stops[0].sheave].kind != "drum":
        r.fail(f"{rpath}.route[0]", "a crane rope must start at a drum (kind = 'drum'): the hoist "
                                    "winds the rope there")
    if stops[-1].sheave is not None:
        r.fail(f"{rpath}.route[{len(stops) - 1}]", "a crane rope must end at an anchor (the dead end)")
    block = bodies[spec.block]
    p0 = np.asarray(block.position, float)

    geo = _route_geometry(scene, stops, spec, r, rpath)
    nst = len(stops)
    nsp = nst - 1
    try:
        T = span_tangents(scene.source, rope.name, [g[:4] for g in geo])
    except GeometryError as exc:
        raise SceneError(f"{scene.source}: [{rpath}.route] geometry: {exc}") from None

    # stops: frames, contact bases, frame vectors
    st_f = np.zeros((nst, 15))
    st_i = np.full((nst, 3), -1, dtype=np.int64)
    angles = np.zeros((nsp, 2))
    for k, (c, R, a, sig, on) in enumerate(geo):
        st_i[k, 0] = 1 if on else 0
        cb = c - p0 if on else c
        st_f[k, 0:3] = cb
        st_f[k, 9] = R
        if R > 0:
            u, w = _basis(a)
            st_f[k, 3:6] = u
            st_f[k, 6:9] = w
            st_f[k, 10:13] = a
            for j, end in ((k - 1, 1), (k, 0)):   # span ending here (end 1), span starting here (end 0)
                if 0 <= j < nsp:
                    d = T[j][end] - c
                    angles[j, end] = math.atan2(d @ w, d @ u)
        else:
            j = k - 1 if k == nst - 1 else k
            t = T[j][1] - T[j][0]
            t /= np.linalg.norm(t)
            axes = np.eye(3)
            st_f[k, 10:13] = axes[int(np.argmin(np.abs(axes @ t)))]
    # spans: falls, reference twist-free state
    sp_i = np.zeros(nsp, dtype=np.int64)
    falls = []
    for k in range(nsp):
        onA, onB = geo[k][4], geo[k + 1][4]
        if onA != onB:
            sp_i[k] = 1 if onB else -1   # top at the start when the end is on the block
            falls.append(k)
    if not falls:
        r.fail(f"{rpath}.route", f"no fall: no span between the boom tip and the hook block {spec.block!r}")
    sp_f = np.zeros((nsp, 3))
    sp_f[:, 0:2] = angles
    s_ref = np.zeros(nst)
    phi_ref = np.zeros(nst)
    from ..core.elements.torsion import transport_angle
    for k in range(nsp):
        D = T[k][1] - T[k][0]
        L = float(np.linalg.norm(D))
        t = D / L
        a, b = st_f[k, 10:13], st_f[k + 1, 10:13]
        dl = transport_angle(t[0], t[1], t[2], a[0], a[1], a[2], b[0], b[1], b[2], 0.0)
        sp_f[k, 2] = dl
        s_ref[k + 1] = s_ref[k] + L
        phi_ref[k + 1] = phi_ref[k] - dl
    h_ref = float(np.mean([(T[k][0][2] - T[k][1][2]) * sp_i[k] for k in falls]))
    if h_ref <= 0:
        r.fail(f"bodies.{spec.block}.position", f"the hook block must hang below the boom tip (mean fall height {h_ref:.3g} m)")

    # unknowns: pose, s at the drum and the sheave nodes, phi at the sheave nodes
    law = LAWS[spec.law]
    torsion = not (law == LAWS["torque-factor"] and spec.GJ0 == 0.0 and spec.k1 == 0.0)
    npose = 6 if spec.pose == "full" else 4
    n = npose
    for k in range(nst - 1):
        st_i[k, 1] = n
        n += 1
    st_f[nst - 1, 13] = s_ref[-1]
    for k in range(1, nst - 1):
        if torsion:
            st_i[k, 2] = n
            n += 1
    st_f[:, 14] = phi_ref
    drum_idx = int(st_i[0, 1])

    g = np.asarray(scene.gravity, float)
    mass = block.mass + spec.payload
    weight = mass * float(np.linalg.norm(g))
    rhoA = rope.rhoA * rope.count
    EA = rope.EA * rope.count
    nf = len(falls)
    ip = np.array([law, npose, nst, nsp, drum_idx, 1 if spec.rope_weight else 0, 1], dtype=np.int64)
    fp = np.array([EA, rhoA, spec.diameter, spec.k0, spec.k1, spec.GJ0, mass, *g, *spec.cg], float)
    Sref = weight / nf
    rscale = np.empty(n)
    rscale[0:3] = weight
    rscale[3:npose] = weight * 1.0
    for k in range(nst):
        if st_i[k, 1] >= 0:
            rscale[st_i[k, 1]] = Sref
        if st_i[k, 2] >= 0:
            rscale[st_i[k, 2]] = Sref * spec.diameter
    rscale[drum_idx] = 1.0
    S_eff, H_est = _critical_height_estimate(T, falls, sp_i, p0, spec)
    names = _span_names(sp_i, falls)
    return CraneModel(scene=scene, spec=spec, npose=npose, nx=n, drum_idx=drum_idx, ip=ip, fp=fp,
                      st_i=st_i, st_f=st_f, sp_i=sp_i, sp_f=sp_f, rscale=rscale, falls=tuple(falls),
                      span_names=tuple(names), h_ref=h_ref, p_ref=p0, s_ref=s_ref, phi_ref=phi_ref,
                      weight=weight, S_eff=S_eff, H_est=H_est, torsion=torsion)


# -------------------------------------------------------------------------------------------- solve
class CraneSolver:
    """Equilibrium at a height and continuation in the height, on one CraneModel (its state: x, the
    contact angles and the Delta references in model.sp_f)."""

    def __init__(self, model: CraneModel):
        self.m = model
        self.x = np.zeros(model.nx)
        self.h = math.nan
        self.J = np.zeros((model.nx, model.nx))
        self.have_jac = False
        self.spo = np.zeros((len(model.sp_i), 9))
        self.wk = np.zeros(12)
        self.stats = np.zeros(2, dtype=np.int64)   # Newton iterations, Jacobians
        self.steps = 0
        self.rejected = 0
        self.maxit = 25
        self.history = []          # accepted (h, yaw) of the continuation

    # -- helpers
    def _call_newton(self, x, h, have_jac):
        """Newton on a copy of the Jacobian: self.J stays the one at self.x (for the tangent)."""
        m = self.m
        J = self.J.copy()
        return _newton(x, h, m.ip, m.fp, m.st_i, m.st_f, m.sp_i, m.sp_f, J, have_jac, m.rscale,
                       m.spec.tolerance, self.maxit, 0.5, self.spo, self.wk, self.stats)

    def residual(self, x=None, h=None):
        m = self.m
        x = self.x if x is None else x
        R = np.empty(m.nx)
        _evaluate(x, self.h if h is None else h, m.ip, m.fp, m.st_i, m.st_f, m.sp_i, m.sp_f, R, self.spo, self.wk)
        return R

    def potential(self, x=None):
        """Total potential Pi at x (rope strain + rope and hook-load weight; for the torque-factor
        law the axial part only)."""
        m = self.m
        R = np.empty(m.nx)
        return _evaluate(self.x if x is None else x, 0.0, m.ip, m.fp, m.st_i, m.st_f, m.sp_i, m.sp_f, R,
                         self.spo, self.wk)[1]

    def jacobian(self):
        m = self.m
        _jacobian(self.x, self.h, m.ip, m.fp, m.st_i, m.st_f, m.sp_i, m.sp_f, self.J, self.spo, self.wk, 1e-6)
        self.stats[1] += 1
        self.have_jac = True
        return self.J

    def _commit(self):
        """Accepted state: store the exact contact angles and the Delta branch; Jacobian at x."""
        self.residual()
        self.m.sp_f[:, 0] = self.spo[:, 6]
        self.m.sp_f[:, 1] = self.spo[:, 7]
        self.m.sp_f[:, 2] = self.spo[:, 4]
        self.jacobian()

    def guess(self, h):
        """Block moved vertically from the scene position to height h, unturned; spans stretched by
        the mean fall tension; phi of the twist-free reference."""
        m = self.m
        x = np.zeros(m.nx)
        x[0:3] = m.p_ref
        x[2] -= h - m.h_ref
        eps0 = m.weight / len(m.falls) / m.fp[0]
        # geometric span lengths at that pose
        R = np.empty(m.nx)
        xs = x.copy()
        for k in range(m.st_f.shape[0]):
            if m.st_i[k, 1] >= 0:
                xs[m.st_i[k, 1]] = m.s_ref[k]
            if m.st_i[k, 2] >= 0:
                xs[m.st_i[k, 2]] = m.phi_ref[k]
        _evaluate(xs, h, m.ip, m.fp, m.st_i, m.st_f, m.sp_i, m.sp_f, R, self.spo, self.wk)
        chords = (1.0 + self.spo[:, 2]) * self.spo[:, 5]
        s = m.s_ref[-1]
        for k in range(len(chords) - 1, -1, -1):
            s -= chords[k] / (1.0 + eps0)
            if m.st_i[k, 1] >= 0:
                xs[m.st_i[k, 1]] = s
        return xs

    def solve(self, h, x0=None):
        """Equilibrium at height h from x0 (default: guess(h)); True on success."""
        x = self.guess(h) if x0 is None else x0.copy()
        st = self._call_newton(x, h, False)
        if st != 0:
            return False
        self.x, self.h = x, h
        self._commit()
        return True

    def tangent(self):
        """dx/dh at the current state (J at x)."""
        e = np.zeros(self.m.nx)
        e[self.m.drum_idx] = 1.0
        return np.linalg.solve(self.J, e)

    def continue_to(self, h_target, dh_min):
        """Natural continuation from the current state to h_target. Returns True when reached,
        False at a fold (no equilibrium beyond self.h within dh_min)."""
        yaw_step = self.m.spec.yaw_step
        sign0 = np.linalg.slogdet(self.J)[0]
        while abs(h_target - self.h) > 1e-12 * max(1.0, abs(h_target)):
            v = self.tangent()
            dh = h_target - self.h
            if abs(v[3] * dh) > yaw_step:
                dh = math.copysign(yaw_step / abs(v[3]), dh)
            while True:
                if abs(dh) < dh_min:
                    return False
                x = self.x + dh * v
                st = self._call_newton(x, self.h + dh, True)
                if st == 0 and abs(x[3] - self.x[3]) <= 4.0 * yaw_step:
                    # the Newton matrix at the new point must keep its sign (no jump over a fold)
                    xo, ho, Jo = self.x, self.h, self.J.copy()
                    self.x, self.h = x, self.h + dh
                    self._commit()
                    sign = np.linalg.slogdet(self.J)[0]
                    if sign == sign0 or sign == 0:
                        self.steps += 1
                        self.history.append((self.h, self.x[3]))
                        break
                    self.x, self.h, self.J = xo, ho, Jo
                    self.residual()
                    self.m.sp_f[:, 0] = self.spo[:, 6]
                    self.m.sp_f[:, 1] = self.spo[:, 7]
                    self.m.sp_f[:, 2] = self.spo[:, 4]
                self.rejected += 1
                dh *= 0.5
        return True

    def outputs(self):
        """Per-span [S, M, eps, kappa, Delta, l, angA, angB, h] at the current state."""
        self.residual()
        return self.spo.copy()


@dataclass
class SweepResult:
    columns: dict
    critical_height: float | None
    critical_yaw: float | None
    seconds: float               # the sweep, after the first equilibrium
    first_solve_seconds: float   # first equilibrium in the scene's configuration (incl. JIT compile/load)
    path: np.ndarray             # accepted continuation points (h, yaw), including the substeps
    steps: int
    rejected: int
    newton_iterations: int
    jacobians: int
    model: CraneModel


def _refine_fold(history):
    """Critical height from the last accepted points (h, psi) near the fold: vertex of the parabola
    h(psi) through the last three; the last height if the fit is not a maximum beyond it."""
    h_last, psi_last = history[-1]
    if len(history) < 3:
        return h_last, psi_last
    (h1, p1), (h2, p2), (h3, p3) = history[-3:]
    if len({p1, p2, p3}) < 3:
        return h_last, psi_last
    A = np.array([[p1 * p1, p1, 1.0], [p2 * p2, p2, 1.0], [p3 * p3, p3, 1.0]])
    a, b, c = np.linalg.solve(A, [h1, h2, h3])
    if a >= 0:
        return h_last, psi_last
    pv = -b / (2 * a)
    hv = c - b * b / (4 * a)
    if hv < h_last or hv > h_last + 0.01 * abs(h_last) or abs(pv - psi_last) > 0.2:
        return h_last, psi_last
    return hv, pv


def _no_yaw_stiffness(model: CraneModel) -> str:
    """Why the statics can fail before it starts: nothing resists the block's yaw. Falls spaced
    apart turn the block back (the block rises as it turns); a rope with torsional stiffness does
    too. One fall (or falls through one point) with the torque-factor law and GJ0 = k1 = 0 has
    neither: with k0 = 0 the yaw is undetermined, with k0 != 0 the rope torque turns the block freely."""
    if model.torsion or (len(model.falls) > 1 and model.S_eff > 1e-9):
        return ""
    spec = model.spec
    return (f": the hook block's yaw has no stiffness — {len(model.falls)} fall(s) at one point and "
            f"[crane] law = {spec.law!r} with GJ0 = {spec.GJ0:g}, k1 = {spec.k1:g} give no torsional "
            f"stiffness, so nothing turns the block back (k0 = {spec.k0:g}: "
            + ("the yaw is undetermined" if spec.k0 == 0 else "the rope torque turns it freely")
            + "). Give the rope torsional stiffness ([crane] GJ0 > 0, or law = 'costello' or 'feyrer') "
              "or reeve two or more falls")


def sweep(model: CraneModel, heights=None) -> SweepResult:
    """Equilibria over the heights (default: the scene's linspace(height_min, height_max, heights));
    NaN rows beyond the critical height."""
    spec = model.spec
    if heights is None:
        heights = np.linspace(spec.height_min, spec.height_max, spec.heights)
    heights = np.asarray(heights, float)
    t0 = time.perf_counter()
    sol = CraneSolver(model)
    if not sol.solve(model.h_ref):
        raise CraneError(f"{model.scene.source}: no equilibrium found in the scene's configuration "
                         f"(height {model.h_ref:.3f} m){_no_yaw_stiffness(model)}")
    t_first = time.perf_counter() - t0   # includes the JIT compile (or cache load) of the kernels
    t0 = time.perf_counter()
    dh_min = spec.fold_tol * float(np.ptp(heights) or 1.0)
    nf = len(model.falls)
    nsp = len(model.sp_i)
    cols = {"height": heights.copy(), "block.yaw": np.full(len(heights), np.nan)}
    for nm in ("block.x", "block.y", "block.z") + (("block.pitch", "block.roll") if model.npose == 6 else ()):
        cols[nm] = np.full(len(heights), np.nan)
    for i in range(nf):
        cols[f"fall{i + 1}.tension"] = np.full(len(heights), np.nan)
    for k in range(nsp):
        if model.sp_i[k] == 0:
            cols[f"{model.span_names[k]}.tension"] = np.full(len(heights), np.nan)
    for nm in ("rope.torque", "rope.twist", "drum.s"):
        cols[nm] = np.full(len(heights), np.nan)
    crit = None
    crit_yaw = None
    sol.history = [(sol.h, sol.x[3])]
    ok = sol.continue_to(heights[0], dh_min)
    if ok:
        sol.history = [(sol.h, sol.x[3])]
    path = sol.history
    for i, h in enumerate(heights):
        if ok and i > 0:
            ok = sol.continue_to(h, dh_min)
        if not ok:
            crit, crit_yaw = _refine_fold(sol.history)
            break
        x = sol.x
        spo = sol.outputs()
        cols["block.yaw"][i] = x[3]
        cols["block.x"][i], cols["block.y"][i], cols["block.z"][i] = x[0], x[1], x[2]
        if model.npose == 6:
            cols["block.pitch"][i], cols["block.roll"][i] = x[4], x[5]
        for j, k in enumerate(model.falls):
            cols[f"fall{j + 1}.tension"][i] = spo[k, 0]
        for k in range(nsp):
            if model.sp_i[k] == 0:
                cols[f"{model.span_names[k]}.tension"][i] = spo[k, 0]
        fk = list(model.falls)
        cols["rope.torque"][i] = float(np.mean(spo[fk, 1]))
        cols["rope.twist"][i] = float(np.mean(spo[fk, 3])) if model.torsion else math.nan
        cols["drum.s"][i] = x[model.drum_idx]
    seconds = time.perf_counter() - t0
    return SweepResult(columns=cols, critical_height=None if crit is None else float(crit),
                       critical_yaw=None if crit_yaw is None else float(crit_yaw), seconds=seconds,
                       first_solve_seconds=t_first, path=np.array(path),
                       steps=sol.steps, rejected=sol.rejected, newton_iterations=int(sol.stats[0]),
                       jacobians=int(sol.stats[1]), model=model)


# ---------------------------------------------------------------------------------------- front end
def load_crane(path, overrides: dict | None = None) -> CraneModel:
    """Scene file -> CraneModel; overrides update keys of the [crane] section (tests, studies)."""
    if overrides:
        try:
            import tomllib
        except ModuleNotFoundError:  # Python 3.10
            import tomli as tomllib
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
        data.setdefault("crane", {}).update(overrides)
        return build_crane(parse_scene(data, str(path)))
    return build_crane(load_scene(path))


def summary(res: SweepResult) -> dict:
    m = res.model
    s = m.spec
    h = res.columns["height"]
    return {
        "scene": m.scene.name, "source": m.scene.source, "law": s.law, "k0": s.k0, "k1": s.k1, "GJ0": s.GJ0,
        "diameter": s.diameter, "falls": len(m.falls), "hook_load_N": m.weight,
        "height_min": float(h[0]), "height_max": float(h[-1]), "heights": int(len(h)),
        "critical_height": res.critical_height, "critical_yaw": res.critical_yaw,
        "effective_spacing": m.S_eff, "critical_height_estimate": None if math.isnan(m.H_est) else m.H_est,
        "max_yaw": float(np.nanmax(np.abs(res.columns["block.yaw"]))) if np.isfinite(res.columns["block.yaw"]).any() else None,
        "sweep_seconds": res.seconds, "first_solve_seconds": res.first_solve_seconds, "steps": res.steps, "rejected_steps": res.rejected,
        "newton_iterations": res.newton_iterations, "jacobians": res.jacobians, "unknowns": m.nx,
    }


def plot_rotation(path, res: SweepResult):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    c = res.columns
    m = res.model
    h = c["height"]
    fig, axes = plt.subplots(3, 1, figsize=(8, 8.5), sharex=True)
    ax = axes[0]
    ax.plot(res.path[:, 0], np.degrees(res.path[:, 1]), lw=1.5, label="ALE statics (continuation path)")
    if not math.isnan(m.H_est):
        ok = h < m.H_est
        ax.plot(h[ok], np.degrees(np.arcsin(np.clip(h[ok] / m.H_est, -1, 1))) * np.sign(m.spec.k0), "k--", lw=0.8,
                label=f"sin ψ = h / H_est  (torque factor, H_est = {m.H_est:.4g} m)")
    if res.critical_height is not None:
        for a in axes:
            a.axvline(res.critical_height, color="r", lw=0.8)
        ax.annotate(f"cabling at {res.critical_height:.2f} m", (res.critical_height, 0), color="r",
                    rotation=90, va="bottom", ha="right", fontsize=8)
    ax.set_ylabel("block yaw ψ [deg]")
    ax.legend(fontsize=7)
    ax.set_title(f"{m.scene.name}: {len(m.falls)} falls, {m.spec.law}, k0 = {m.spec.k0:g}, d = {m.spec.diameter * 1e3:g} mm")
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
    if getattr(args, "set", None):
        from .overrides import OverrideError, parse_sets, scene_with, split

        scene_sets, drive_sets, load = split(parse_sets(args.set))
        if drive_sets or load is not None:
            raise OverrideError("--set: a crane study takes scene keys only (crane.payload, rope.EA, ...)")
        model = build_crane(scene_with(args.scene, scene_sets)[0])
    else:
        model = load_crane(args.scene)
    from ..core.plausibility import check_or_raise
    warnings = check_or_raise(model.scene)
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    spec = model.spec
    heights = None
    if args.heights is not None:
        if args.heights < 2:
            raise ValueError("--heights must be >= 2")
        heights = np.linspace(spec.height_min, spec.height_max, args.heights)
    res = sweep(model, heights)
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
    msg = (f"{model.scene.name}: {len(res.columns['height'])} heights in {res.seconds:.3f} s "
           f"({res.steps} steps, {res.newton_iterations} Newton iterations); ")
    if ch is None:
        msg += f"yaw {np.degrees(yaw[last[-1]]):.2f} deg at {res.columns['height'][last[-1]]:.1f} m, no cabling in range"
    else:
        msg += f"cabling: equilibrium lost at h = {ch:.3f} m (yaw {np.degrees(res.critical_yaw):.1f} deg)"
    print(msg + f" -> {out}/rotation.csv, rotation.png, summary.json")
    return 0


# ------------------------------------------------------------- cabling of the dynamic model
@dataclass
class YawPath:
    """Equilibria of a dynamic model (core.model, rotation-vector hook block) along its yaw."""
    yaw: np.ndarray            # rad, prescribed block yaw per accepted point
    height: np.ndarray         # m, block sheaves below the fixed sheaves they hang from
    critical_height: float     # m, the fold of height(yaw): parabola through the last three points
    critical_yaw: float        # rad
    q: np.ndarray              # coordinates at the last accepted point


def yaw_equilibrium(sim, st, q, jyaw: int, jfree: int, psi: float, tol: float = 1e-9):
    """Statics of the dynamic model with the block yaw q[jyaw] = psi prescribed and the rope coordinate
    q[jfree] (the drum's) free instead: the yaw is the continuation parameter, which passes the fold
    of height(yaw) where a sweep in height cannot. Newton with a forward-difference Jacobian from q;
    returns the coordinates, or None when Newton does not converge (the caller halves its step)."""
    m = sim.model
    nq = m.nq
    eqs = np.array(m.statics_equations)
    unk = np.array(sorted((set(range(nq)) - {jyaw}) & set(m.statics_equations) | {jfree}))
    M, Q, zero = np.empty((nq, nq)), np.empty(nq), np.zeros(nq)
    u = sim.kernel_inputs(st)
    ang = m.K.nl_ANG.copy()           # the tangent solver's warm start (its branch) at the start
    q = q.copy()
    q[jyaw] = psi
    fscale = max(1.0, float(np.max(np.abs(m.K.F0))))

    def resid(x):
        qq = q.copy()
        qq[unk] = x
        if assemble(m.KJ, st.c, qq, zero, 0.0, u, M, Q) < 0:
            return None
        return Q[eqs].copy()
    x = q[unk].copy()
    J = np.empty((len(eqs), len(unk)))
    for _ in range(30):
        r = resid(x)
        if r is None or not np.all(np.isfinite(r)):
            break
        if np.max(np.abs(r)) < tol * fscale:
            q[unk] = x
            return q
        for k in range(len(unk)):
            xp = x.copy()
            xp[k] += 1e-7 * (1.0 + abs(x[k]))
            rp = resid(xp)
            J[:, k] = (rp - r) / (xp[k] - x[k]) if rp is not None else np.nan
        try:
            x = x - np.linalg.solve(J, r)
            if not np.all(np.isfinite(x)):
                break
        except np.linalg.LinAlgError:
            break
    m.K.nl_ANG[:] = ang
    return None


def block_height(model, q, block: str) -> float:
    """Mean height of the fixed sheaves above the block's sheaves (their centres, the block's pose in
    q): the fall length of a crane whose falls hang from the boom tip."""
    from scipy.spatial.transform import Rotation
    bd = model.body_dofs[block]
    body = next(b for b in model.scene.bodies if b.name == block)
    pos = np.array([q[bd[a]] for a in ("x", "y", "z")])
    rot = Rotation.from_rotvec([q[bd[a]] for a in ("rx", "ry", "rz")]).as_matrix()
    on = [s for s in model.scene.sheaves if s.body == body.name]
    fixed = [s for s in model.scene.sheaves if s.body is None and s.kind != "drum"]
    z_block = np.mean([(pos + rot @ np.asarray(s.center, float))[2] for s in on])
    return float(np.mean([s.center[2] for s in fixed]) - z_block)


def cabling_of_model(sim, st, block: str, drum: str, dpsi: float = 0.02, d: float = 0.02) -> YawPath:
    """Continuation of the dynamic model's statics in the block yaw from its equilibrium st (rope paid
    out from the drum as needed) in steps dpsi: the height rises with the yaw up to the fold (cabling)
    and falls beyond it. The march stops after two falling steps (one alone may be a jump of the
    tangent points, not the fold) or when Newton fails (step cut by 3 down to dpsi / 100); the fold is
    the vertex of the parabola through the highest point and the points +-d around it."""
    m = sim.model
    jyaw, jd = m.body_dofs[block]["rz"], m.sheave_dof[drum]
    q = st.q.copy()
    hist = [(q[jyaw], block_height(m, q, block), q)]
    step, falling = dpsi, 0
    while falling < 2 and step > dpsi / 100 and hist[-1][0] < math.pi:
        qn = yaw_equilibrium(sim, st, hist[-1][2], jyaw, jd, hist[-1][0] + step)
        if qn is None:
            step /= 3.0
            continue
        h = block_height(m, qn, block)
        falling = falling + 1 if h < hist[-1][1] else 0
        hist.append((qn[jyaw], h, qn))
    k = max(range(len(hist)), key=lambda i: hist[i][1])
    psi, h, q = hist[k]
    side = [yaw_equilibrium(sim, st, q, jyaw, jd, psi + e) for e in (-d, d)]
    if all(x is not None for x in side):
        around = [(block_height(m, side[0], block), psi - d), (h, psi), (block_height(m, side[1], block), psi + d)]
        ch, cy = _refine_fold(around)
    else:
        ch, cy = h, psi
    P = np.array([(p_, h_) for p_, h_, _ in hist[:k + 1]])
    return YawPath(yaw=P[:, 0], height=P[:, 1], critical_height=float(ch), critical_yaw=float(cy), q=q)
