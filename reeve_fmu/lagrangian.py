"""Lagrangian finite-element baseline: the rope as a material mesh sliding over sheaves by contact.

This is how a conventional (non-ALE) multibody code models a reeving system, and it is the yardstick
for the claim that ALE needs far fewer elements (issue 5, docs/fidelity.md §"Lagrangian baseline"):

  * Planar (x-z). The rope is a chain of the same linear two-node elements as the ALE model
    (`elements.linear.linear_element_at`) with every material coordinate fixed (s-dot = 0: the
    Lagrangian limit, method.md §7 item 7): constant consistent mass, axial elastic + Kelvin-Voigt
    force, potential-form gravity. Node positions (x, z) are the unknowns.
  * The mesh is material, so every stretch of rope that touches a sheave at any time of the run must
    be meshed finely: the builder runs the cheap ALE model over the run, takes the material interval
    that passes over each sheave (plus a margin) and meshes it with `element_length`; the rest of the
    rope gets elements of up to `coarse_length`.
  * Rope-sheave interaction by node-to-circle contact (as Exudyn's ObjectContactFrictionCircleCable2D,
    method.md §4.4 "contact-based alternative"): a penalty normal force k_n f(p) + c_n f'(p) p-dot on
    every node that penetrates the pitch circle (p = R - |x - c|, f a C1 quadratic-onset ramp), and a
    regularised Coulomb friction F_t = -mu F_n w / sqrt(w^2 + v_reg^2) against the rim. The slip
    velocity is w = u.(v - v_c)/lambda - R theta-dot: the rate of *unstretched* rope passing a
    point of the rim minus the rim speed, so that stick means s-dot = R theta-dot, the same no-slip
    kinematics as the ALE sheave node (s = s0 + R theta, method.md §4.4, creep neglected). mu is the
    groove's equivalent friction (EN 81-50, `traction.equivalent_friction`). Idler sheaves have their
    own angle (inertia J) driven only by this friction; a speed-driven traction sheave turns with the
    prescribed profile and the friction carries the rope.
  * Bodies translate along their free axes (border unknowns); rope ends are fixed, on hitch springs
    (isotropic, k and c of the scene) or attached to a body.
  * Generalized-alpha (same parameters as the engine) with Newton on the accelerations. The Newton
    matrix M + b K + c C is assembled analytically (element tangent, contact, friction) into a band
    (nodes in rope order, half-bandwidth 3) plus a dense border (bodies, sheave angles) and solved by
    a banded LU and a Schur complement: O(n) per step.
  * Initial state: the ALE statics gives the static configuration of the continuum (straight spans
    with the linear tension of the rope weight, arcs on the sheaves); the mesh is laid out on it and
    polished by Newton statics, the rope held on speed-driven sheaves by tangential springs (static
    friction) and free on idlers.

Outputs carry the engine's names: `<body>.position/.velocity/.acceleration` (no axis suffix for a
body with one free axis), `<sheave>.tension_in/.tension_out` (the rope force in the free span next to
the tangent point: element forces interpolated at `probe` element lengths from the tangent point,
corrected to the tangent point for the rope weight), `<sheave>.angle/.speed`, `traction_ratio`,
`<rope>.tension_start/.tension_end` (consistent end force of the end element minus its inertia, as
the engine), `motor.torque`.
"""
from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass, field
import math
import time

import numpy as np

from ._jit import njit
from .elements.linear import end_tension, linear_element_at
from .profiles import profile_eval, scurve, speed_table
from .scene import AXES, Scene, SceneError
from .solver import Result, SolverError, gen_alpha_params, lu_factor, lu_solve

KB = 3   # half-bandwidth of the node block: two coordinates per node, nearest-neighbour coupling

LK = namedtuple("LK", [
    "nb", "m",
    "node_dof", "node_off", "node_left", "node_right", "node_prev", "node_next", "node_x0",
    "el_a", "el_b", "el_s1", "el_l", "el_rhoA", "el_EA", "el_nu", "el_tonly", "el_g",
    "sh_dof", "sh_off", "sh_R", "sh_mu", "sh_kn", "sh_cn", "sh_w", "sh_kt", "sh_th", "sh_presc",
    "sh_lo", "sh_hi", "sh_J",
    "bd_M", "bd_F", "bd_c",
    "hs_node", "hs_dof", "hs_off", "hs_k", "hs_c",
    "presc_gain", "profile",
    "out_kind", "out_i", "out_j", "out_scale",
    "tap_sh", "tap_off", "tap_dir", "tap_d", "tap_lo", "tap_hi", "tap_rhoA", "tap_last",
    "dof_m", "relax_alpha",
])

(O_Q, O_V, O_A, O_TAP, O_END, O_ANGLE, O_SPEED, O_RATIO, O_TORQUE) = range(9)


# ============================================================================ compiled kernels
@njit(cache=True, inline="always")
def _ramp(p, w):
    """C1 penetration ramp: 0 for p <= 0, p^2/(2w) up to w, then p - w/2. Returns (f, f')."""
    if p <= 0.0:
        return 0.0, 0.0
    if p < w:
        return 0.5 * p * p / w, p / w
    return p - 0.5 * w, 1.0


@njit(cache=True, inline="always")
def _presc(LK, t):
    """Prescribed sheave angle, speed and acceleration."""
    x, xd, xdd = profile_eval(LK.profile, t)
    g = LK.presc_gain
    return g * (x - LK.profile[1, 0]), g * xd, g * xdd


@njit(cache=True, inline="always")
def _sheave_angle(LK, k, q, v, t):
    if LK.sh_presc[k]:
        th, thd, thdd = _presc(LK, t)
        return th, thd
    j = LK.sh_th[k]
    return q[j], v[j]


@njit(cache=True)
def _positions(LK, q, v, qdd, X, V, A):
    nn = LK.node_dof.shape[0]
    for i in range(nn):
        for k in range(2):
            j = LK.node_dof[i, k]
            if j >= 0:
                X[i, k] = q[j] + LK.node_off[i, k]
                V[i, k] = v[j]
                A[i, k] = qdd[j]
            else:
                X[i, k] = LK.node_off[i, k]
                V[i, k] = 0.0
                A[i, k] = 0.0


@njit(cache=True, inline="always")
def _center(LK, k, q, v):
    cx = LK.sh_off[k, 0]
    cz = LK.sh_off[k, 1]
    vx = 0.0
    vz = 0.0
    j = LK.sh_dof[k, 0]
    if j >= 0:
        cx += q[j]
        vx = v[j]
    j = LK.sh_dof[k, 1]
    if j >= 0:
        cz += q[j]
        vz = v[j]
    return cx, cz, vx, vz


@njit(cache=True, inline="always")
def _node_feed(LK, lam, i, R):
    """Unstretched rope per unit arc of the pitch circle at node i: the elements are chords of the
    circle, each of material length l subtending 2 asin(lambda l / 2R), so kappa = sum l / (R sum
    angle). For a smooth rope kappa = 1/lambda; the chord form keeps the material flux over a sheave
    exact for any element length (no chordal feed error of order (l/R)^2/24)."""
    sl = 0.0
    sa = 0.0
    for e in (LK.node_left[i], LK.node_right[i]):
        if e >= 0:
            l = LK.el_l[e]
            x = 0.5 * lam[e] * l / R
            if x > 1.0:
                x = 1.0
            sl += l
            sa += 2.0 * math.asin(x)
    if sa <= 0.0:
        return 1.0
    return sl / (R * sa)


@njit(cache=True, inline="always")
def _route_tangent(LK, X, i, nx, nz):
    """Unit circle tangent at node i pointing along the route (toward the next node)."""
    ux = -nz
    uz = nx
    a = LK.node_prev[i]
    b = LK.node_next[i]
    if a < 0:
        a = i
    if b < 0:
        b = i
    dx = X[b, 0] - X[a, 0]
    dz = X[b, 1] - X[a, 1]
    if ux * dx + uz * dz < 0.0:
        return -ux, -uz
    return ux, uz


@njit(cache=True, inline="always")
def _contact(LK, k, i, X, V, cx, cz, vcx, vcz):
    """Normal contact of node i with sheave k: (active, nx, nz, ux, uz, rho, Fn, dFn/dp, dFn/dp-dot).
    n: outward normal, u: circle tangent along the route, Fn >= 0: normal force on the node,
    Hunt-Crossley form k_n f(p) (1 + d p-dot): the damping force vanishes with the penetration, so
    the force is continuous when a node arrives on the sheave (a damper k-independent of p kicks
    arriving nodes back out, and they chatter on and off the rim from step to step)."""
    dx = X[i, 0] - cx
    dz = X[i, 1] - cz
    R = LK.sh_R[k]
    if abs(dx) > R or abs(dz) > R:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    rho = math.sqrt(dx * dx + dz * dz)
    p = R - rho
    if p <= 0.0 or rho <= 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    nx = dx / rho
    nz = dz / rho
    f, fp = _ramp(p, LK.sh_w[k])
    pdot = -(nx * (V[i, 0] - vcx) + nz * (V[i, 1] - vcz))
    damp = 1.0 + LK.sh_cn[k] * pdot
    if damp <= 0.0:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    ux, uz = _route_tangent(LK, X, i, nx, nz)
    kn = LK.sh_kn[k]
    return True, nx, nz, ux, uz, rho, kn * f * damp, kn * fp * damp, kn * f * LK.sh_cn[k]


@njit(cache=True, inline="always")
def _sat(z, zmax):
    """Elasto-plastic stick spring deflection: linear up to 0.9 zmax, then a C1 tanh saturation at
    zmax (sliding); returns (value, d value/dz, d value/d zmax)."""
    if zmax <= 0.0:
        return 0.0, 0.0, 0.0
    a = 0.9 * zmax
    az = abs(z)
    if az <= a:
        return z, 1.0, 0.0
    th = math.tanh((az - a) / (zmax - a))
    val = a + (zmax - a) * th
    dm = 0.9 + 0.1 * th - (1.0 - th * th) * az / zmax     # d|value| / d zmax
    if z > 0.0:
        return val, 1.0 - th * th, dm
    return -val, 1.0 - th * th, -dm


@njit(cache=True, inline="always")
def _friction(LK, k, i, X, V, cx, cz, vcx, vcz, th, thd, kap, ux, uz, Fn, xo, co, tho, zo, static):
    """Tangential force on node i along u (Ft), the stick deflection z and dz_sat/dz.
    Dynamic: elasto-plastic stick spring z = z_old + (unstretched rope displacement relative to the
    rim since the step start), |k_t z| <= mu Fn. Static: a spring to the
    laid-out position on speed-driven sheaves with the same capacity (static friction), nothing on
    idlers."""
    if static:
        if LK.sh_presc[k]:
            du = ux * (X[i, 0] - LK.node_x0[i, 0]) + uz * (X[i, 1] - LK.node_x0[i, 1])
            return -LK.sh_kt[k] * du, du, 1.0, 0.0
        return 0.0, 0.0, 0.0, 0.0
    R = LK.sh_R[k]
    slip = kap * (ux * ((X[i, 0] - xo[i, 0]) - (cx - co[k, 0]))
                  + uz * ((X[i, 1] - xo[i, 1]) - (cz - co[k, 1]))) - R * (th - tho[k])
    zs, dzs, dzm = _sat(zo[i] + slip, LK.sh_mu[k] * Fn / LK.sh_kt[k])
    return -LK.sh_kt[k] * zs, zs, dzs, dzm


@njit(cache=True)
def residual(LK, q, v, qdd, t, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static,
             xo, co, tho, zo, zn):
    """r = M qdd - Q(q, v, t) over all unknowns (dynamic), or r = -Q(q, 0) + static friction springs
    (static). Fills X, V, A (node kinematics), the element arrays, Nel (axial force incl. damping),
    lam (stretch), torque (friction torque on each sheave, + along the route) and zn (stick deflection
    of every node at this state; 0 off contact). xo, co, tho, zo: node positions, sheave centres and
    angles and stick deflections at the step start."""
    n = r.shape[0]
    for j in range(n):
        r[j] = 0.0
    _positions(LK, q, v, qdd, X, V, A)
    # ---- rope elements (the engine's kernel, material coordinates fixed)
    for ie in range(LK.el_a.shape[0]):
        a = LK.el_a[ie]
        b = LK.el_b[ie]
        for k in range(2):
            QE[ie, k] = X[a, k]
            QE[ie, 2 + k] = X[b, k]
            VE[ie, k] = V[a, k]
            VE[ie, 2 + k] = V[b, k]
        QE[ie, 4] = LK.el_s1[ie]
        QE[ie, 5] = LK.el_s1[ie] + LK.el_l[ie]
        VE[ie, 4] = 0.0
        VE[ie, 5] = 0.0
        res = linear_element_at(2, LK.el_rhoA[ie], LK.el_EA[ie], LK.el_nu[ie], LK.el_tonly[ie] != 0,
                                LK.el_g, 0.0, QE, VE, MEs, QEs, ie)
        Nel[ie] = res[0] + res[1]
        lam[ie] = res[2]
        for al in range(4):
            node = a if al < 2 else b
            j = LK.node_dof[node, al % 2]
            if j < 0:
                continue
            s = -QEs[ie, al]
            if not static:
                for be in range(4):
                    nb_ = a if be < 2 else b
                    s += MEs[ie, al, be] * A[nb_, be % 2]
            r[j] += s
    # ---- bodies and sheave angles (border diagonal)
    for jb in range(LK.m):
        j = LK.nb + jb
        if static:
            r[j] -= LK.bd_F[jb]
        else:
            r[j] += LK.bd_M[jb] * qdd[j] - LK.bd_F[jb] + LK.bd_c[jb] * v[j]
    # ---- hitch springs: node -> anchor point (ground or body)
    for h in range(LK.hs_node.shape[0]):
        i = LK.hs_node[h]
        for k in range(2):
            ja = LK.hs_dof[h, k]
            xa = LK.hs_off[h, k]
            va = 0.0
            if ja >= 0:
                xa += q[ja]
                va = v[ja]
            f = LK.hs_k[h] * (X[i, k] - xa) + LK.hs_c[h] * (V[i, k] - va)
            j = LK.node_dof[i, k]
            if j >= 0:
                r[j] += f
            if ja >= 0:
                r[ja] -= f
    # ---- mass-proportional damping (dynamic relaxation to the initial equilibrium only)
    if LK.relax_alpha > 0.0 and not static:
        for j in range(n):
            r[j] += LK.relax_alpha * LK.dof_m[j] * v[j]
    # ---- contact and friction
    for i in range(zn.shape[0]):
        zn[i] = 0.0
    for k in range(LK.sh_R.shape[0]):
        torque[k] = 0.0
        cx, cz, vcx, vcz = _center(LK, k, q, v)
        th, thd = _sheave_angle(LK, k, q, v, t)
        R = LK.sh_R[k]
        for i in range(LK.sh_lo[k], LK.sh_hi[k]):
            if abs(X[i, 0] - cx) > R or abs(X[i, 1] - cz) > R:
                continue    # cheap test first: a call that receives LK costs ~1 us (tuple refcounts)
            act, nx, nz, ux, uz, rho, Fn, kn, cn = _contact(LK, k, i, X, V, cx, cz, vcx, vcz)
            if not act:
                continue
            kap = _node_feed(LK, lam, i, R)
            Ft, zs, dzs, dzm = _friction(LK, k, i, X, V, cx, cz, vcx, vcz, th, thd, kap, ux, uz, Fn,
                                         xo, co, tho, zo, static)
            zn[i] = zs
            fx = Fn * nx + Ft * ux
            fz = Fn * nz + Ft * uz
            j = LK.node_dof[i, 0]
            if j >= 0:
                r[j] -= fx
            j = LK.node_dof[i, 1]
            if j >= 0:
                r[j] -= fz
            j = LK.sh_dof[k, 0]
            if j >= 0:
                r[j] += fx
            j = LK.sh_dof[k, 1]
            if j >= 0:
                r[j] += fz
            torque[k] -= R * Ft
        if not LK.sh_presc[k]:
            r[LK.sh_th[k]] -= torque[k]


@njit(cache=True, inline="always")
def _add(J, C, D, E, nb, i, j, val):
    if i < 0 or j < 0:
        return
    if i < nb:
        if j < nb:
            d = j - i
            if -KB <= d <= KB:
                J[i, KB + d] += val
        else:
            C[i, j - nb] += val
    else:
        if j < nb:
            D[i - nb, j] += val
        else:
            E[i - nb, j - nb] += val


@njit(cache=True)
def jacobian(LK, q, v, t, cm, bq, gv, X, V, MEs, Nel, lam, J, C, D, E, lock, static,
             xo, co, tho, zo):
    """Newton matrix cm M + bq K + gv Cd (K = -dQ/dq, Cd = -dQ/dv) as band J (nb x 2KB+1) plus
    border C (nb x m), D (m x nb), E (m x m), from the state of the last `residual` call. Locked
    unknowns (statics: idler angles) get identity rows/columns. Neglected: the rotation of u and n
    in the friction force, the change of kappa, the friction capacity's dependence on Fn."""
    nb = LK.nb
    J[:, :] = 0.0
    C[:, :] = 0.0
    D[:, :] = 0.0
    E[:, :] = 0.0
    dof = np.empty(4, np.int64)
    G = np.empty((2, 2))
    for ie in range(LK.el_a.shape[0]):
        a = LK.el_a[ie]
        b = LK.el_b[ie]
        for al in range(4):
            node = a if al < 2 else b
            dj = LK.node_dof[node, al % 2]
            dof[al] = -1 if (dj >= 0 and lock[dj]) else dj
        dx = X[b, 0] - X[a, 0]
        dz = X[b, 1] - X[a, 1]
        dist = math.sqrt(dx * dx + dz * dz)
        tx = dx / dist
        tz = dz / dist
        l = LK.el_l[ie]
        ka = LK.el_EA[ie] / l
        Nt = Nel[ie]
        if LK.el_tonly[ie] != 0 and lam[ie] < 1.0:
            ka *= 1e-6
            if Nt < 0.0:
                Nt = 0.0
        kg = Nt / dist
        cd = LK.el_EA[ie] * LK.el_nu[ie] / l
        tt = ((tx * tx, tx * tz), (tz * tx, tz * tz))
        for p_ in range(2):
            for q_ in range(2):
                idm = 1.0 if p_ == q_ else 0.0
                G[p_, q_] = bq * (ka * tt[p_][q_] + kg * (idm - tt[p_][q_])) + gv * cd * tt[p_][q_]
        for al in range(4):
            if dof[al] < 0:
                continue
            for be in range(4):
                if dof[be] < 0:
                    continue
                sgn = 1.0 if (al < 2) == (be < 2) else -1.0
                val = sgn * G[al % 2, be % 2] + cm * MEs[ie, al, be]
                _add(J, C, D, E, nb, dof[al], dof[be], val)
    m = LK.m
    for jb in range(m):
        j = nb + jb
        if lock[j]:
            continue
        E[jb, jb] += cm * LK.bd_M[jb] + gv * LK.bd_c[jb]
    for h in range(LK.hs_node.shape[0]):
        i = LK.hs_node[h]
        kk = bq * LK.hs_k[h] + gv * LK.hs_c[h]
        for k in range(2):
            jn = LK.node_dof[i, k]
            ja = LK.hs_dof[h, k]
            _add(J, C, D, E, nb, jn, jn, kk)
            _add(J, C, D, E, nb, ja, ja, kk)
            _add(J, C, D, E, nb, jn, ja, -kk)
            _add(J, C, D, E, nb, ja, jn, -kk)
    Knn = np.empty((2, 2))
    Cin = np.empty(2)   # d r_node / d theta (bq) and d theta-dot (gv)
    Cni = np.empty(2)   # d r_theta / d x_node, d v_node
    for k in range(LK.sh_R.shape[0]):
        cx, cz, vcx, vcz = _center(LK, k, q, v)
        th, thd = _sheave_angle(LK, k, q, v, t)
        jt = -1 if LK.sh_presc[k] else LK.sh_th[k]
        if jt >= 0 and lock[jt]:
            jt = -1
        R = LK.sh_R[k]
        kt = LK.sh_kt[k]
        for i in range(LK.sh_lo[k], LK.sh_hi[k]):
            if abs(X[i, 0] - cx) > R or abs(X[i, 1] - cz) > R:
                continue    # cheap test first: a call that receives LK costs ~1 us (tuple refcounts)
            act, nx, nz, ux, uz, rho, Fn, kn, cn = _contact(LK, k, i, X, V, cx, cz, vcx, vcz)
            if not act:
                continue
            kap = _node_feed(LK, lam, i, R)
            Ft, zs, dzs, dzm = _friction(LK, k, i, X, V, cx, cz, vcx, vcz, th, thd, kap, ux, uz, Fn,
                                         xo, co, tho, zo, static)
            nv = (nx, nz)
            uv = (ux, uz)
            ktu = kt * dzs if static else kt * dzs * kap   # static: spring to the layout
            # a saturated (sliding) node: friction = mu Fn follows the normal force
            mk = LK.sh_mu[k] * dzm if Fn > 0.0 else 0.0
            for a_ in range(2):
                for b_ in range(2):
                    idm = 1.0 if a_ == b_ else 0.0
                    kab = (kn * nv[a_] * nv[b_] - Fn / rho * (idm - nv[a_] * nv[b_])
                           + ktu * uv[a_] * uv[b_] - mk * kn * uv[a_] * nv[b_]
                           + Ft / rho * nv[a_] * uv[b_])
                    cab = cn * nv[a_] * nv[b_] + mk * cn * uv[a_] * nv[b_]
                    Knn[a_, b_] = bq * kab + gv * cab
                Cin[a_] = -bq * kt * dzs * R * uv[a_]
                Cni[a_] = (-bq * kt * dzs * R * kap * uv[a_]
                           + R * mk * (bq * kn - gv * cn) * nv[a_])
            dn0 = LK.node_dof[i, 0]
            dn1 = LK.node_dof[i, 1]
            dn0 = dn0 if (dn0 >= 0 and not lock[dn0]) else -1
            dn1 = dn1 if (dn1 >= 0 and not lock[dn1]) else -1
            dnl = (dn0, dn1)
            dc = (LK.sh_dof[k, 0], LK.sh_dof[k, 1])
            for a_ in range(2):
                for b_ in range(2):
                    kab = Knn[a_, b_]
                    _add(J, C, D, E, nb, dnl[a_], dnl[b_], kab)
                    _add(J, C, D, E, nb, dnl[a_], dc[b_], -kab)
                    _add(J, C, D, E, nb, dc[a_], dnl[b_], -kab)
                    _add(J, C, D, E, nb, dc[a_], dc[b_], kab)
            if jt >= 0 and not static:
                _add(J, C, D, E, nb, jt, jt, bq * kt * dzs * R * R)
                for a_ in range(2):
                    _add(J, C, D, E, nb, dnl[a_], jt, Cin[a_])
                    _add(J, C, D, E, nb, dc[a_], jt, -Cin[a_])
                    _add(J, C, D, E, nb, jt, dnl[a_], Cni[a_])
                    _add(J, C, D, E, nb, jt, dc[a_], -Cni[a_])
    if LK.relax_alpha > 0.0 and not static:
        for j in range(nb + m):
            _add(J, C, D, E, nb, j, j, gv * LK.relax_alpha * LK.dof_m[j])
    for j in range(nb):
        if lock[j]:
            J[j, KB] = 1.0
    for jb in range(m):
        if lock[nb + jb]:
            E[jb, jb] = 1.0


@njit(cache=True)
def bb_factor(J, C, D, E, X, S, piv):
    """Factor [[band J, C], [D, E]]: banded LU of J in place (no pivoting: the Newton matrix is
    dominated by its diagonal), X = J^-1 C, S = E - D X factored with pivoting. False if singular."""
    nb = J.shape[0]
    for k in range(nb):
        pv = J[k, KB]
        if pv == 0.0 or not (pv == pv):
            return False
        for i in range(k + 1, min(nb, k + KB + 1)):
            f = J[i, KB + k - i] / pv
            J[i, KB + k - i] = f
            if f != 0.0:
                for j in range(k + 1, min(nb, k + KB + 1)):
                    J[i, KB + j - i] -= f * J[k, KB + j - k]
    m = E.shape[0]
    if m == 0:
        return True
    for c in range(m):
        for i in range(nb):
            X[i, c] = C[i, c]
        _band_solve(J, X[:, c])
    for a in range(m):
        for b in range(m):
            s = E[a, b]
            for i in range(nb):
                s -= D[a, i] * X[i, b]
            S[a, b] = s
    return lu_factor(S, piv)


@njit(cache=True, inline="always")
def _band_solve(J, b):
    nb = J.shape[0]
    for i in range(nb):
        s = b[i]
        for k in range(max(0, i - KB), i):
            s -= J[i, KB + k - i] * b[k]
        b[i] = s
    for i in range(nb - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, min(nb, i + KB + 1)):
            s -= J[i, KB + j - i] * b[j]
        b[i] = s / J[i, KB]


@njit(cache=True)
def bb_solve(J, X, D, S, piv, r):
    """Solve in place with the factors of bb_factor."""
    nb = J.shape[0]
    m = S.shape[0]
    rb = r[:nb]
    _band_solve(J, rb)
    if m == 0:
        return
    z = np.empty(m)
    for a in range(m):
        s = r[nb + a]
        for i in range(nb):
            s -= D[a, i] * rb[i]
        z[a] = s
    lu_solve(S, piv, z)
    for a in range(m):
        r[nb + a] = z[a]
    for i in range(nb):
        s = 0.0
        for a in range(m):
            s += X[i, a] * z[a]
        rb[i] -= s


@njit(cache=True)
def _seg_dist(X, a, b, px, pz):
    dx = X[b, 0] - X[a, 0]
    dz = X[b, 1] - X[a, 1]
    L2 = dx * dx + dz * dz
    xi = ((px - X[a, 0]) * dx + (pz - X[a, 1]) * dz) / L2 if L2 > 0.0 else 0.0
    if xi < 0.0:
        xi = 0.0
    elif xi > 1.0:
        xi = 1.0
    ex = X[a, 0] + xi * dx - px
    ez = X[a, 1] + xi * dz - pz
    return ex * ex + ez * ez, xi


@njit(cache=True)
def outputs(LK, q, v, qdd, t, X, V, A, QE, VE, MEs, QEs, Nel, torque, y):
    """Fill y from the state of the last residual call (see module doc for the definitions)."""
    ae = np.zeros(6)
    for k in range(LK.out_kind.shape[0]):
        kind = LK.out_kind[k]
        i = LK.out_i[k]
        if kind == O_Q:
            y[k] = q[i] * LK.out_scale[k]
        elif kind == O_V:
            y[k] = v[i] * LK.out_scale[k]
        elif kind == O_A:
            y[k] = qdd[i] * LK.out_scale[k]
        elif kind == O_ANGLE:
            th, thd = _sheave_angle(LK, i, q, v, t)
            y[k] = th
        elif kind == O_SPEED:
            th, thd = _sheave_angle(LK, i, q, v, t)
            y[k] = thd
        elif kind == O_END:
            a = LK.el_a[i]
            b = LK.el_b[i]
            ae[0] = A[a, 0]
            ae[1] = A[a, 1]
            ae[2] = A[b, 0]
            ae[3] = A[b, 1]
            y[k] = end_tension(2, LK.el_rhoA[i], QE, VE, ae, MEs, QEs, i, LK.out_j[k])
        elif kind == O_TORQUE:
            if LK.sh_presc[i]:
                th, thd, thdd = _presc(LK, t)
            else:
                thdd = qdd[LK.sh_th[i]]
            y[k] = LK.sh_J[i] * thdd - torque[i]
        elif kind == O_TAP:
            cx, cz, vcx, vcz = _center(LK, LK.tap_sh[i], q, v)
            tx = cx + LK.tap_off[i, 0]
            tz = cz + LK.tap_off[i, 1]
            px = tx + LK.tap_d[i] * LK.tap_dir[i, 0]
            pz = tz + LK.tap_d[i] * LK.tap_dir[i, 1]
            lo = LK.tap_lo[i]
            hi = LK.tap_hi[i]
            e = LK.tap_last[i]
            if e < lo or e >= hi:
                best = 1e300
                for ee in range(lo, hi):
                    d2, xi = _seg_dist(X, LK.el_a[ee], LK.el_b[ee], px, pz)
                    if d2 < best:
                        best = d2
                        e = ee
            else:
                d2, xi = _seg_dist(X, LK.el_a[e], LK.el_b[e], px, pz)
                moved = True
                while moved:
                    moved = False
                    for ee in (e - 1, e + 1):
                        if lo <= ee < hi:
                            d2n, xin = _seg_dist(X, LK.el_a[ee], LK.el_b[ee], px, pz)
                            if d2n < d2:
                                d2 = d2n
                                e = ee
                                moved = True
            LK.tap_last[i] = e
            d2, xi = _seg_dist(X, LK.el_a[e], LK.el_b[e], px, pz)
            T = Nel[e]
            if xi > 0.5 and e + 1 < hi:
                w = xi - 0.5
                T = (1.0 - w) * Nel[e] + w * Nel[e + 1]
            elif xi < 0.5 and e - 1 >= lo:
                w = 0.5 - xi
                T = (1.0 - w) * Nel[e] + w * Nel[e - 1]
            # to the tangent point: dN/ds = -rhoA g.t along the rope
            y[k] = T + LK.tap_rhoA[i] * (LK.el_g[0, 0] * (px - tx) + LK.el_g[0, 1] * (pz - tz))
    for k in range(LK.out_kind.shape[0]):
        if LK.out_kind[k] == O_RATIO:
            a = y[LK.out_i[k]]
            b = y[LK.out_j[k]]
            hi_ = max(a, b)
            lo_ = min(a, b)
            y[k] = hi_ / lo_ if lo_ > 0.0 else math.inf


@njit(cache=True, inline="always")
def _update(n, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma):
    for i in range(n):
        a1 = ((1.0 - af) * qdd[i] + af * qddo[i] - am * ao[i]) / (1.0 - am)
        a[i] = a1
        q[i] = qo[i] + h * vo[i] + h * h * ((0.5 - beta) * ao[i] + beta * a1)
        v[i] = vo[i] + h * ((1.0 - gamma) * ao[i] + gamma * a1)


@njit(cache=True)
def _step_start(LK, q, v, t, X, V, A, xo, co, tho):
    """Node positions, sheave centres and angles at the start of a step (friction reference)."""
    _positions(LK, q, v, v, X, V, A)
    for i in range(X.shape[0]):
        xo[i, 0] = X[i, 0]
        xo[i, 1] = X[i, 1]
    for k in range(LK.sh_R.shape[0]):
        cx, cz, vcx, vcz = _center(LK, k, q, v)
        co[k, 0] = cx
        co[k, 1] = cz
        th, thd = _sheave_angle(LK, k, q, v, t)
        tho[k] = th


@njit(cache=True)
def integrate(LK, q, v, a, qdd, z, t0, h, nsteps, params, ybuf, out_every, info):
    """Generalized-alpha (engine parameters) with Newton on the accelerations; the Newton matrix is
    rebuilt every `jac_every` steps and whenever a step needs more than 3 iterations. A step that
    fails is retried as 4 and 16 substeps. z: stick deflection per node (updated). info = [steps,
    iterations, jacobian builds, residuals, status]. Returns (status, t)."""
    am = params[0]
    af = params[1]
    beta = params[2]
    gamma = params[3]
    tol = params[4]
    maxit = int(params[5])
    jac_every = int(params[6])
    n = q.shape[0]
    nb = LK.nb
    m = LK.m
    nn = LK.node_dof.shape[0]
    ne = LK.el_a.shape[0]
    ns = LK.sh_R.shape[0]
    X = np.empty((nn, 2))
    V = np.empty((nn, 2))
    A = np.empty((nn, 2))
    QE = np.empty((ne, 6))
    VE = np.empty((ne, 6))
    MEs = np.empty((ne, 6, 6))
    QEs = np.empty((ne, 6))
    Nel = np.empty(ne)
    lam = np.ones(ne)
    torque = np.empty(ns)
    xo = np.empty((nn, 2))
    co = np.empty((ns, 2))
    tho = np.empty(ns)
    zo = np.empty(nn)
    zn = np.empty(nn)
    J = np.empty((nb, 2 * KB + 1))
    C = np.empty((nb, m))
    D = np.empty((m, nb))
    E = np.empty((m, m))
    Xs = np.empty((nb, m))
    S = np.empty((m, m))
    piv = np.empty(m, np.int64)
    lock = np.zeros(n, np.bool_)
    r = np.empty(n)
    y = np.empty(LK.out_kind.shape[0])
    qo = np.empty(n)
    vo = np.empty(n)
    ao = np.empty(n)
    qddo = np.empty(n)
    q1 = np.empty(n)
    v1 = np.empty(n)
    a1 = np.empty(n)
    qdd1 = np.empty(n)
    z1 = np.empty(nn)
    t = t0
    row = 0
    have_jac = False
    jac_h = 0.0
    since = 0
    # stretch of every element (the feed factor kappa of the first residual needs it)
    _step_start(LK, q, v, t, X, V, A, xo, co, tho)
    residual(LK, q, v, qdd, t, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, False, xo, co, tho, z, zn)
    for step in range(nsteps):
        q1[:] = q
        v1[:] = v
        a1[:] = a
        qdd1[:] = qdd
        z1[:] = z
        status = 1
        for level in range(3):
            nsub = 1 if level == 0 else 4 ** level
            hs = h / nsub
            if level > 0:
                q[:] = q1
                v[:] = v1
                a[:] = a1
                qdd[:] = qdd1
                z[:] = z1
                have_jac = False
            bq = hs * hs * beta * (1.0 - af) / (1.0 - am)
            gv = hs * gamma * (1.0 - af) / (1.0 - am)
            for sub in range(nsub):
                ts = t + (sub + 1) * hs
                _step_start(LK, q, v, ts - hs, X, V, A, xo, co, tho)
                zo[:] = z
                qo[:] = q
                vo[:] = v
                ao[:] = a
                qddo[:] = qdd
                _update(n, qo, vo, ao, qddo, qdd, q, v, a, hs, am, af, beta, gamma)
                if jac_h != hs or since >= jac_every:
                    have_jac = False
                status = 1
                for it in range(maxit):
                    residual(LK, q, v, qdd, ts, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, False,
                             xo, co, tho, zo, zn)
                    info[3] += 1
                    if not have_jac or it >= 3:
                        jacobian(LK, q, v, ts, 1.0, bq, gv, X, V, MEs, Nel, lam, J, C, D, E, lock, False,
                                 xo, co, tho, zo)
                        info[2] += 1
                        if not bb_factor(J, C, D, E, Xs, S, piv):
                            break
                        have_jac = True
                        jac_h = hs
                        since = 0
                    bb_solve(J, Xs, D, S, piv, r)
                    dmax = 0.0
                    amax = 0.0
                    for i in range(n):
                        qdd[i] -= r[i]
                        if abs(r[i]) > dmax:
                            dmax = abs(r[i])
                        if abs(qdd[i]) > amax:
                            amax = abs(qdd[i])
                    _update(n, qo, vo, ao, qddo, qdd, q, v, a, hs, am, af, beta, gamma)
                    info[1] += 1
                    if not (dmax == dmax) or dmax > 1e300:
                        break
                    if dmax <= tol * (1.0 + amax) or dmax * bq <= 1e-13:
                        status = 0
                        break
                since += 1
                if status != 0:
                    q[:] = qo
                    v[:] = vo
                    a[:] = ao
                    qdd[:] = qddo
                    break
                # stick deflections at the converged state
                residual(LK, q, v, qdd, ts, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, False,
                         xo, co, tho, zo, zn)
                info[3] += 1
                z[:] = zn
            if status == 0:
                break
        if status != 0:
            q[:] = q1
            v[:] = v1
            a[:] = a1
            qdd[:] = qdd1
            z[:] = z1
            info[4] = status
            return status, t
        t = t0 + (step + 1) * h
        info[0] += 1
        if out_every > 0 and (step + 1) % out_every == 0:
            # the residual of the converged state is the last one evaluated
            outputs(LK, q, v, qdd, t, X, V, A, QE, VE, MEs, QEs, Nel, torque, y)
            ybuf[row, 0] = t
            for k in range(y.shape[0]):
                ybuf[row, k + 1] = y[k]
            row += 1
    return 0, t


@njit(cache=True)
def _alloc(LK, n):
    nn = LK.node_dof.shape[0]
    ne = LK.el_a.shape[0]
    ns = LK.sh_R.shape[0]
    return (np.empty((nn, 2)), np.empty((nn, 2)), np.empty((nn, 2)), np.empty((ne, 6)), np.empty((ne, 6)),
            np.empty((ne, 6, 6)), np.empty((ne, 6)), np.empty(ne), np.ones(ne), np.empty(ns),
            np.empty((nn, 2)), np.empty((ns, 2)), np.empty(ns), np.empty(nn))


@njit(cache=True)
def eval_state(LK, q, v, qdd, t, z, static, y, zn_out):
    """Outputs y and the stick deflections zn_out at a state (friction reference = the state
    itself, so z is the stored deflection)."""
    n = q.shape[0]
    X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, xo, co, tho, zn = _alloc(LK, n)
    r = np.empty(n)
    _step_start(LK, q, v, t, X, V, A, xo, co, tho)
    for it in range(2):   # the second pass sees the element stretches (feed factor)
        residual(LK, q, v, qdd, t, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static, xo, co, tho,
                 z, zn)
    outputs(LK, q, v, qdd, t, X, V, A, QE, VE, MEs, QEs, Nel, torque, y)
    zn_out[:] = zn


@njit(cache=True)
def newton_system(LK, q, v, qdd, t, z, cm, bq, gv, static, lock, r):
    """Residual at (q, v, qdd) with the stick deflections z (friction reference = this state), and
    the Newton increment: r is replaced by (cm M + bq K + gv Cd)^-1 r. Returns max |residual| (-1 if
    the matrix is singular). Used by the statics, the consistent initial accelerations, the tests."""
    nn = LK.node_dof.shape[0]
    ns = LK.sh_R.shape[0]
    xo = np.empty((nn, 2))
    co = np.empty((ns, 2))
    tho = np.empty(ns)
    _step_start(LK, q, v, t, np.empty((nn, 2)), np.empty((nn, 2)), np.empty((nn, 2)), xo, co, tho)
    return newton_system_ref(LK, q, v, qdd, t, z, cm, bq, gv, static, lock, r, xo, co, tho)


@njit(cache=True)
def newton_system_ref(LK, q, v, qdd, t, z, cm, bq, gv, static, lock, r, xo, co, tho):
    """newton_system with an explicit friction reference (the step start: xo, co, tho, z)."""
    n = q.shape[0]
    nb = LK.nb
    m = LK.m
    X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, xo_, co_, tho_, zn = _alloc(LK, n)
    for it in range(2):
        residual(LK, q, v, qdd, t, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static, xo, co, tho,
                 z, zn)
    rn = 0.0
    for j in range(n):
        if lock[j]:
            r[j] = 0.0
        rn = max(rn, abs(r[j]))
    J = np.empty((nb, 2 * KB + 1))
    C = np.empty((nb, m))
    D = np.empty((m, nb))
    E = np.empty((m, m))
    Xs = np.empty((nb, m))
    S = np.empty((m, m))
    piv = np.empty(m, np.int64)
    jacobian(LK, q, v, t, cm, bq, gv, X, V, MEs, Nel, lam, J, C, D, E, lock, static, xo, co, tho, z)
    if not bb_factor(J, C, D, E, Xs, S, piv):
        return -1.0
    bb_solve(J, Xs, D, S, piv, r)
    return rn


@njit(cache=True)
def dense_matrices(LK, q, v, t, z, lock, static):
    """Dense M, K and Cd of the Newton matrix at a state (friction reference = the state)."""
    nn = LK.node_dof.shape[0]
    ns = LK.sh_R.shape[0]
    xo = np.empty((nn, 2))
    co = np.empty((ns, 2))
    tho = np.empty(ns)
    _step_start(LK, q, v, t, np.empty((nn, 2)), np.empty((nn, 2)), np.empty((nn, 2)), xo, co, tho)
    return dense_matrices_ref(LK, q, v, t, z, lock, static, xo, co, tho)


@njit(cache=True)
def dense_matrices_ref(LK, q, v, t, z, lock, static, xo, co, tho):
    """Dense M, K and Cd (tests, eigenfrequencies) with an explicit friction reference."""
    n = q.shape[0]
    nb = LK.nb
    m = LK.m
    X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, xo_, co_, tho_, zn = _alloc(LK, n)
    r = np.empty(n)
    qdd = np.zeros(n)
    for it in range(2):
        residual(LK, q, v, qdd, t, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static, xo, co, tho,
                 z, zn)
    out = np.zeros((3, n, n))
    J = np.empty((nb, 2 * KB + 1))
    C = np.empty((nb, m))
    D = np.empty((m, nb))
    E = np.empty((m, m))
    for which in range(3):
        cm = 1.0 if which == 0 else 0.0
        bq = 1.0 if which == 1 else 0.0
        gv = 1.0 if which == 2 else 0.0
        jacobian(LK, q, v, t, cm, bq, gv, X, V, MEs, Nel, lam, J, C, D, E, lock, static, xo, co, tho, z)
        for i in range(nb):
            for d in range(-KB, KB + 1):
                j = i + d
                if 0 <= j < nb:
                    out[which, i, j] = J[i, KB + d]
            for c in range(m):
                out[which, i, nb + c] = C[i, c]
                out[which, nb + c, i] = D[c, i]
        for a in range(m):
            for b in range(m):
                out[which, nb + a, nb + b] = E[a, b]
    return out


@njit(cache=True)
def residual_at(LK, q, v, qdd, t, z, static, xo, co, tho):
    """Residual with an explicit friction reference (tests: finite differences of the Jacobian)."""
    n = q.shape[0]
    X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, xo_, co_, tho_, zn = _alloc(LK, n)
    r = np.empty(n)
    for it in range(2):
        residual(LK, q, v, qdd, t, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static, xo, co, tho,
                 z, zn)
    return r


# ============================================================================ building
@dataclass
class LagrangianState:
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    qdd: np.ndarray
    z: np.ndarray        # stick deflection of every node (elasto-plastic friction state)

    def copy(self):
        return LagrangianState(self.t, self.q.copy(), self.v.copy(), self.a.copy(), self.qdd.copy(),
                               self.z.copy())


@dataclass
class LagrangianModel:
    scene: Scene
    LK: LK
    q_names: tuple
    output_names: tuple
    q_static_guess: np.ndarray
    lock_static: np.ndarray          # unknowns held in the statics (idler angles)
    n_elements: int
    n_fine: int
    element_length: float
    info: dict = field(default_factory=dict)

    @property
    def n_dof(self):
        return len(self.q_names)


def _ale_static_config(scene: Scene, statics: str | None = None):
    """Planar ALE model (one element per span) of the scene and its initial state (scene statics)."""
    from .model import build_model
    from .solver import Simulator
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": 1}) for r in scene.ropes)
    sc = scene.with_overrides(model="planar", ropes=ropes)
    m = build_model(sc)
    sim = Simulator(m)
    st = sim.initial_state(statics=statics)
    return m, sim, st


def _material_ranges(scene: Scene, t_end: float):
    """Material interval [s_min, s_max] (ALE rope coordinate) that touches each sheave during a run to
    t_end, from the 1D ALE model (cheap): {sheave name: (lo, hi)}."""
    from .model import build_model
    from .solver import Simulator
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": 1}) for r in scene.ropes)
    m = build_model(scene.with_overrides(ropes=ropes))
    sim = Simulator(m)
    st = sim.initial_state()
    lo, hi = {}, {}
    wrap = {}
    for rope in m.ropes:
        for k, j in rope["sig"].items():
            name = m.q_names[j].rsplit(".", 1)[0]
            wrap[name] = rope["wraps"][k][0]
    n = max(1, int(math.ceil(t_end / 0.05)))
    for step in range(n + 1):
        if step > 0:
            sim.advance(st, min(t_end, step * t_end / n))
        for name, j in m.sheave_dof.items():
            s = st.q[j]
            lo[name] = min(lo.get(name, s), s)
            hi[name] = max(hi.get(name, s), s + wrap.get(name, 0.0))
    return {k: (lo[k], hi[k]) for k in lo}


def build_lagrangian(scene: Scene, element_length: float = 0.05, coarse_length: float = 1.0,
                     t_end: float | None = None, fine_everywhere: bool = False, penalty: float = 1.0,
                     contact_damping: float = 1.0, stick: float = 1.0, contact_onset: float = 0.5,
                     probe: float = 1.5,
                     margin: float = 0.25, statics: str | None = None) -> LagrangianModel:
    """Lagrangian planar model of a scene (see the module docstring).

    element_length: elements on every stretch of rope that touches a sheave during [0, t_end]
    (default t_end: the scene's); coarse_length: elsewhere. fine_everywhere meshes the whole rope
    finely. penalty: normal contact stiffness in units of EA/element_length (per node);
    contact_damping: normal (Hunt-Crossley) damping as a fraction of the critical damping of a node
    at the static wrap force; stick: tangential (stick) stiffness in units of the normal one;
    contact_onset: width of the C1 onset of the penalty in units of the static penetration of a
    wrap node (wider: smoother arrivals, fewer Newton iterations); probe: distance of the tension
    taps from the tangent point in element lengths; margin [m]: added on both sides of the
    touched material intervals; statics: the scene's [initial] statics mode for the configuration the
    mesh is laid out on (default: the scene's; 'none' = the unloaded geometry)."""
    if scene.model == "spatial":
        raise SceneError(f"{scene.source}: the Lagrangian baseline is planar (x-z); model 'spatial' "
                         "is not supported")
    if scene.drive.kind not in ("none", "speed"):
        raise SceneError(f"{scene.source}: the Lagrangian baseline supports drive kinds 'none' and "
                         f"'speed', not {scene.drive.kind!r}")
    if any(s.kind == "drum" for s in scene.sheaves) or scene.buffers or scene.brake.torque > 0 and \
            scene.drive.kind != "speed":
        raise SceneError(f"{scene.source}: the Lagrangian baseline has no drums, buffers or brakes")
    t_end = scene.t_end if t_end is None else t_end
    ale, ale_sim, ale_st = _ale_static_config(scene, statics)
    mode = statics or scene.statics
    p = ale.B @ ale_st.q + ale_st.c
    nn_ale = ale.info["n_nodes"]
    g3 = np.asarray(scene.gravity, float)
    g2 = g3[[0, 2]]
    sheaves = {s.name: s for s in scene.sheaves}
    bodies = {b.name: b for b in scene.bodies}

    def node_xy(i):
        return np.array([p[2 * i], p[2 * i + 1]])

    def node_s(i):
        return p[2 * nn_ale + i]

    ranges = {} if (fine_everywhere or not scene.sheaves) else _material_ranges(scene, t_end)

    # ---------------------------------------------------------------- border unknowns
    q_names = []
    border = []          # (name, kind, mass, force, damping)
    body_dof = {}
    for b in scene.bodies:
        for ax in b.free:
            if ax == "y":
                raise SceneError(f"{scene.source}: body {b.name!r}: the planar model moves in x-z")
            k3 = AXES.index(ax)
            body_dof[(b.name, ax)] = len(border)
            border.append((f"{b.name}.{ax}", b.mass, b.mass * g3[k3], b.damping))
    sheave_th = {}
    used = [st.sheave for rope in scene.ropes for st in rope.route if st.sheave is not None]
    for name in used:
        sh = sheaves[name]
        if scene.drive.kind == "speed" and scene.drive.sheave == name:
            continue
        J = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == name else 0.0)
        J = max(J, 1e-3 * sh.radius ** 2)   # a massless idler: keep its angle row regular
        sheave_th[name] = len(border)
        border.append((f"{name}.theta", J, 0.0, 0.0))

    # ---------------------------------------------------------------- rope layouts and meshes
    nodes_x = []         # layout positions
    nodes_slot = []      # per node: (kind per axis) -> ('free'|'fixed'|('body', dof)), offsets
    el_list = []         # (a, b, s1, l, rope index)
    rope_node_range = []
    rope_el_range = []
    hitches = []         # (node, anchor body or None, anchor point (2), k, c)
    taps = []            # (sheave, side, tangent point (2, world), dir (2), rope index)
    layouts = []
    sheave_Tw = {}       # mean static tension on each wrap
    for ir, rope in enumerate(scene.ropes):
        info = ale.ropes[ir]
        EA = rope.EA * rope.count
        rhoA = rope.rhoA * rope.count
        stops = rope.route
        # the static path: spans (straight, tension linear in s from the rope weight) and wraps (arcs of
        # the pitch circle, tension linear in the angle from the arriving to the leaving span)
        path = []        # dict(kind, length (spatial), sA0 (ALE s at start), sA_len, ...)
        spans = info["spans"]
        for k, (na, nb_, e0, e1) in enumerate(spans):
            xa, xb = node_xy(na), node_xy(nb_)
            l = node_s(nb_) - node_s(na)
            d = xb - xa
            dist = float(np.linalg.norm(d))
            t_ = d / dist
            N_mid = EA * (dist / l - 1.0)
            # static equilibrium: dN/ds = -rhoA g.t; an unloaded configuration (statics 'none') keeps
            # the span's uniform strain
            dNds = -rhoA * float(g2 @ t_) if mode != "none" else 0.0
            N0, N1 = N_mid - dNds * l / 2, N_mid + dNds * l / 2
            if k > 0:
                sh = sheaves[stops[k].sheave]
                c = _sheave_center(sh, bodies, ale, ale_st)
                prev = path[-1]
                Tin = prev["x0"] + prev["t"] * prev["length"]
                theta = info["wraps"][k][3]
                rin = Tin - c
                tin = prev["t"]
                sense = 1.0 if (rin[0] * tin[1] - rin[1] * tin[0]) > 0 else -1.0
                sA_in = node_s(spans[k - 1][1])
                path.append(dict(kind="wrap", c=c, R=sh.radius, phi0=math.atan2(rin[1], rin[0]),
                                 sense=sense, theta=theta, length=sh.radius * theta, sA0=sA_in,
                                 sA_len=node_s(na) - sA_in, N0=prev["N1"], N1=N0, name=sh.name))
                sheave_Tw[sh.name] = 0.5 * (prev["N1"] + N0)
                taps.append((sh.name, "in", Tin - c, -tin, ir))
                taps.append((sh.name, "out", xa - c, t_, ir))
            path.append(dict(kind="span", x0=xa, t=t_, length=dist, sA0=node_s(na), sA_len=l, N0=N0, N1=N1))
        total = sum(sg["length"] for sg in path)
        starts = np.cumsum([0.0] + [sg["length"] for sg in path])

        def locate(sig):
            k = int(np.searchsorted(starts, sig, side="right") - 1)
            k = min(max(k, 0), len(path) - 1)
            return k, sig - starts[k]

        def point(sig):
            k, u = locate(sig)
            sg = path[k]
            if sg["kind"] == "span":
                return sg["x0"] + sg["t"] * u
            phi = sg["phi0"] + sg["sense"] * u / sg["R"]
            return sg["c"] + sg["R"] * np.array([math.cos(phi), math.sin(phi)])

        def tension(sig):
            k, u = locate(sig)
            sg = path[k]
            f = min(max(u / sg["length"], 0.0), 1.0)
            return sg["N0"] + f * (sg["N1"] - sg["N0"])

        def s_ale(sig):
            k, u = locate(sig)
            sg = path[k]
            return sg["sA0"] + sg["sA_len"] * min(max(u / sg["length"], 0.0), 1.0)

        fine_iv = [] if fine_everywhere else [(ranges[st_.sheave][0] - margin, ranges[st_.sheave][1] + margin)
                                               for st_ in stops if st_.sheave is not None]

        def target(sig):
            if fine_everywhere and any(st_.sheave is not None for st_ in stops):
                return element_length
            a = s_ale(sig)
            b = a + coarse_length
            for lo, hi in fine_iv:
                if b >= lo and a <= hi:
                    return element_length
            return coarse_length

        # march along the path: each element is a chord of length lambda(N) * l (N: static tension at
        # the chord's middle), so the layout is in equilibrium up to the rope weight within an element
        xs = [point(0.0)]
        ls = []
        fine_flags = []
        sig = 0.0
        while True:
            h = target(sig)
            lam_h = 1.0 + tension(min(total, sig + 0.5 * h)) / EA
            rest = total - sig
            end = xs[-1]
            if rest <= 1.5 * lam_h * h and path[-1]["kind"] == "span" and rest <= path[-1]["length"] + 1e-12:
                x_end = point(total)
                lam_e = 1.0 + tension(0.5 * (sig + total)) / EA
                ls.append(float(np.linalg.norm(x_end - end)) / lam_e)
                fine_flags.append(h == element_length)
                xs.append(x_end)
                break
            d = lam_h * h
            lo, hi = sig, sig
            step = 0.25 * d
            while np.linalg.norm(point(min(hi, total)) - end) < d:
                if hi >= total:
                    raise SceneError(f"{scene.source}: Lagrangian layout: rope {rope.name!r} too short for "
                                     f"element length {h:g} m")
                lo, hi = hi, hi + step
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if np.linalg.norm(point(mid) - end) < d:
                    lo = mid
                else:
                    hi = mid
            sig = 0.5 * (lo + hi)
            xs.append(point(sig))
            ls.append(h)
            fine_flags.append(h == element_length)
        if len(ls) > 1 and ls[-1] < 0.5 * ls[-2]:
            # merge a short last element with the one before
            xs.pop(-2)
            lam_e = 1.0 + tension(total) / EA
            ls[-2:] = [float(np.linalg.norm(xs[-1] - xs[-2])) / lam_e]
            fine_flags.pop()
        s_nodes = np.concatenate([[0.0], np.cumsum(ls)])
        n_fine = int(sum(fine_flags))
        L = float(s_nodes[-1])
        n0 = len(nodes_x)
        e_start = len(el_list)
        for x in xs:
            nodes_x.append(np.asarray(x, float))
            nodes_slot.append(None)
        for j in range(len(ls)):
            el_list.append((n0 + j, n0 + j + 1, s_nodes[j], ls[j], ir))
        rope_node_range.append((n0, len(nodes_x)))
        rope_el_range.append((e_start, len(el_list)))
        rope_layout = dict(path=path, L=L, n_fine=n_fine, s_nodes=s_nodes)
        # ends
        for end, st_ in ((0, stops[0]), (1, stops[-1])):
            i = n0 if end == 0 else len(nodes_x) - 1
            if st_.sheave is not None:
                raise SceneError(f"{scene.source}: the Lagrangian baseline needs anchors at both rope ends")
            body = None if st_.anchor == "ground" else st_.anchor
            at = np.asarray(st_.at, float)[[0, 2]]
            if st_.hitch_stiffness > 0 or st_.hitch_damping > 0:
                base = at if body is None else np.asarray(bodies[body].position, float)[[0, 2]] + at
                hitches.append((i, body, base, st_.hitch_stiffness * rope.count,
                                st_.hitch_damping * rope.count))
                nodes_slot[i] = ("free", "free")
            elif body is None:
                nodes_slot[i] = ("fixed", "fixed")
                nodes_x[i] = at.copy()
            else:
                b = bodies[body]
                nodes_slot[i] = tuple(("body", body_dof[(body, ax)]) if ax in b.free else "fixed"
                                      for ax in ("x", "z"))
        rope_layout["EA"] = EA
        rope_layout["rhoA"] = rhoA
        layouts.append(rope_layout)

    # ---------------------------------------------------------------- unknown numbering
    nn = len(nodes_x)
    node_dof = -np.ones((nn, 2), np.int64)
    node_off = np.zeros((nn, 2))
    X0 = np.array(nodes_x, float)
    nb = 0
    banded_names = []
    for i in range(nn):
        slot = nodes_slot[i] or ("free", "free")
        for k in range(2):
            kind = slot[k]
            if kind == "free":
                node_dof[i, k] = nb
                banded_names.append(f"node{i}.{'xz'[k]}")
                nb += 1
    m = len(border)
    for i in range(nn):
        slot = nodes_slot[i] or ("free", "free")
        for k in range(2):
            kind = slot[k]
            if kind == "fixed":
                node_off[i, k] = X0[i, k]
            elif isinstance(kind, tuple):
                jb = kind[1]
                node_dof[i, k] = nb + jb
                bname = border[jb][0].rsplit(".", 1)[0]
                ax = "xz"[k]
                node_off[i, k] = X0[i, k] - ale_st.q[ale.body_dofs[bname][ax]]
    q_names = tuple(banded_names + [b[0] for b in border])
    n = nb + m
    q0 = np.zeros(n)
    for i in range(nn):
        for k in range(2):
            j = node_dof[i, k]
            if 0 <= j < nb:
                q0[j] = X0[i, k]
    for (bname, ax), jb in body_dof.items():
        q0[nb + jb] = ale_st.q[ale.body_dofs[bname][ax]]

    # neighbours
    node_left = -np.ones(nn, np.int64)
    node_right = -np.ones(nn, np.int64)
    node_prev = -np.ones(nn, np.int64)
    node_next = -np.ones(nn, np.int64)
    for ie, (a, b, s1, l, ir) in enumerate(el_list):
        node_right[a] = ie
        node_left[b] = ie
        node_next[a] = b
        node_prev[b] = a

    ne = len(el_list)
    el_a = np.array([e[0] for e in el_list], np.int64)
    el_b = np.array([e[1] for e in el_list], np.int64)
    el_s1 = np.array([e[2] for e in el_list], float)
    el_l = np.array([e[3] for e in el_list], float)
    ropes_of = [scene.ropes[e[4]] for e in el_list]
    el_rhoA = np.array([r.rhoA * r.count for r in ropes_of])
    el_EA = np.array([r.EA * r.count for r in ropes_of])
    el_nu = np.array([r.damping for r in ropes_of])
    el_tonly = np.array([int(r.tension_only) for r in ropes_of], np.int64)
    el_g = np.tile(g2, (ne, 1))

    # ---------------------------------------------------------------- sheaves
    sh_names = [s for s in used]
    ns = len(sh_names)
    sh_dof = -np.ones((ns, 2), np.int64)
    sh_off = np.zeros((ns, 2))
    sh_R = np.zeros(ns)
    sh_mu = np.zeros(ns)
    sh_kn = np.zeros(ns)
    sh_cn = np.zeros(ns)
    sh_w = np.zeros(ns)
    sh_kt = np.zeros(ns)
    sh_th = -np.ones(ns, np.int64)
    sh_presc = np.zeros(ns, np.int64)
    sh_lo = np.zeros(ns, np.int64)
    sh_hi = np.zeros(ns, np.int64)
    sh_J = np.zeros(ns)
    rope_of_sheave = {st.sheave: ir for ir, rope in enumerate(scene.ropes) for st in rope.route
                      if st.sheave is not None}
    for k, name in enumerate(sh_names):
        sh = sheaves[name]
        c = _sheave_center(sh, bodies, ale, ale_st)
        for kk, ax in enumerate(("x", "z")):
            if sh.body is not None and ax in bodies[sh.body].free:
                sh_dof[k, kk] = nb + body_dof[(sh.body, ax)]
                sh_off[k, kk] = c[kk] - ale_st.q[ale.body_dofs[sh.body][ax]]
            else:
                sh_off[k, kk] = c[kk]
        sh_R[k] = sh.radius
        try:
            from .traction import equivalent_friction
            sh_mu[k] = equivalent_friction(sh.mu, sh.undercut_angle, sh.groove_angle, sh.groove)
        except ValueError:
            sh_mu[k] = sh.mu
        ir = rope_of_sheave[name]
        rope = scene.ropes[ir]
        EA = rope.EA * rope.count
        rhoA = rope.rhoA * rope.count
        sh_kn[k] = penalty * EA / element_length
        # onset width of the penalty, in units of the static penetration of a wrap node (C1 contact
        # onset; a sharp kink makes Newton cycle when nodes enter the sheave)
        T_ref = max(sheave_Tw.get(name, 0.0), 1e-4 * EA)
        sh_w[k] = 0.5 * T_ref * element_length / (sh.radius * sh_kn[k])
        sh_kt[k] = stick * sh_kn[k]
        # Hunt-Crossley coefficient: contact_damping x critical for a node at the static wrap force
        sh_cn[k] = contact_damping * 2.0 * math.sqrt(sh_kn[k] * rhoA * element_length) / (
            T_ref * element_length / sh.radius)
        sh_lo[k], sh_hi[k] = rope_node_range[ir]
        if name in sheave_th:
            sh_th[k] = nb + sheave_th[name]
        else:
            sh_presc[k] = 1
        sh_J[k] = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == name else 0.0)

    # free spans: straight between the last node on one sheave and the first node on the next (the
    # marching put them on the continuous tangent; a polygon leaves the sheave at a node, and the
    # straight span from there may cut the circle at the following node, which then joins the wrap):
    # shift the span nodes onto that line, keeping their distances along the span
    centers = [sh_off[k] + np.array([q0[sh_dof[k, kk]] if sh_dof[k, kk] >= 0 else 0.0 for kk in range(2)])
               for k in range(len(sh_names))]
    on_sheave = -np.ones(len(X0), np.int64)
    for k, name in enumerate(sh_names):
        lo, hi = rope_node_range[rope_of_sheave[name]]
        for i in range(lo, hi):
            if float(np.linalg.norm(X0[i] - centers[k])) < sh_R[k] * (1 + 1e-9):
                on_sheave[i] = k

    def on_circle(c, R, P, d, near):
        """Point on the circle (c, R) at distance d from P, the intersection nearer to `near`."""
        D = P - c
        L = float(np.linalg.norm(D))
        x = (L * L + R * R - d * d) / (2.0 * L)
        y = math.sqrt(max(R * R - x * x, 0.0))
        e = D / L
        nrm = np.array([-e[1], e[0]])
        p1, p2 = c + x * e + y * nrm, c + x * e - y * nrm
        return p1 if float(np.linalg.norm(p1 - near)) < float(np.linalg.norm(p2 - near)) else p2

    chord0 = np.array([float(np.linalg.norm(X0[i + 1] - X0[i])) for i in range(len(X0) - 1)] + [0.0])

    def onto_line(a, b):
        """Nodes a..b on the straight line from node a to node b, spaced as the marched chords."""
        A, B = X0[a].copy(), X0[b].copy()
        S = np.concatenate([[0.0], np.cumsum(chord0[a:b])])
        LAB = float(np.linalg.norm(B - A))
        e = (B - A) / LAB
        return [A + e * S[jj] * (LAB / S[-1]) for jj in range(len(S))]

    for ir in range(len(scene.ropes)):
        lo, hi = rope_node_range[ir]
        a = lo
        while a < hi - 1:
            while a + 1 < hi - 1 and on_sheave[a + 1] >= 0:
                a += 1
            b = a + 1
            while b < hi - 1 and on_sheave[b] < 0:
                b += 1
            for _ in range(50):
                if b - a <= 1:
                    break
                pts = onto_line(a, b)
                changed = False
                ka, kb_ = on_sheave[a], on_sheave[b]
                if ka >= 0 and float(np.linalg.norm(pts[1] - centers[ka])) < sh_R[ka]:
                    X0[a + 1] = on_circle(centers[ka], sh_R[ka], X0[a],
                                          float(np.linalg.norm(X0[a + 1] - X0[a])), pts[1])
                    on_sheave[a + 1] = ka
                    a += 1
                    changed = True
                if kb_ >= 0 and b - a > 1 and float(np.linalg.norm(pts[-2] - centers[kb_])) < sh_R[kb_]:
                    X0[b - 1] = on_circle(centers[kb_], sh_R[kb_], X0[b],
                                          float(np.linalg.norm(X0[b] - X0[b - 1])), pts[-2])
                    on_sheave[b - 1] = kb_
                    b -= 1
                    changed = True
                if not changed:
                    for jj, j in enumerate(range(a, b + 1)):
                        X0[j] = pts[jj]
                    break
            a = b
    for i in range(len(X0)):
        for kk in range(2):
            dj = node_dof[i, kk]
            if 0 <= dj < nb:
                q0[dj] = X0[i, kk]

    # wrap nodes: move inside the pitch circle by the static penetration F_n/k_n, with F_n the
    # resultant of the two element tensions at the node's kink (T times the kink angle)
    X_arc = X0.copy()
    for k, name in enumerate(sh_names):
        ir = rope_of_sheave[name]
        Tw = sheave_Tw.get(name, 0.0)
        c = sh_off[k] + np.array([q0[sh_dof[k, kk]] if sh_dof[k, kk] >= 0 else 0.0 for kk in range(2)])
        lo, hi = rope_node_range[ir]
        for i in range(lo + 1, hi - 1):
            d = X_arc[i] - c
            rho = float(np.linalg.norm(d))
            if rho < sh_R[k] * (1 + 1e-9):
                e1 = X_arc[i] - X_arc[i - 1]
                e2 = X_arc[i + 1] - X_arc[i]
                kink = math.atan2(abs(e1[0] * e2[1] - e1[1] * e2[0]), float(e1 @ e2))
                F = max(Tw, 0.0) * kink
                pen = F / sh_kn[k] + 0.5 * sh_w[k] if F / sh_kn[k] > 0.5 * sh_w[k] else \
                    math.sqrt(2.0 * sh_w[k] * F / sh_kn[k])
                X0[i] = c + d / rho * (sh_R[k] - pen)
                for kk in range(2):
                    j = node_dof[i, kk]
                    if 0 <= j < nb:
                        q0[j] = X0[i, kk]

    # the dynamics get the requested onset width (the layout above is made with half the static
    # penetration: a relaxation from a layout with a wide onset fails in its first step)
    sh_w *= contact_onset / 0.5

    # hitch springs
    nh = len(hitches)
    hs_node = np.array([h[0] for h in hitches], np.int64)
    hs_dof = -np.ones((nh, 2), np.int64)
    hs_off = np.zeros((nh, 2))
    for hh, (i, body, base, k_, c_) in enumerate(hitches):
        for kk, ax in enumerate(("x", "z")):
            if body is not None and ax in bodies[body].free:
                hs_dof[hh, kk] = nb + body_dof[(body, ax)]
                hs_off[hh, kk] = base[kk] - ale_st.q[ale.body_dofs[body][ax]]
            else:
                hs_off[hh, kk] = base[kk]
    hs_k = np.array([h[3] for h in hitches], float)
    hs_c = np.array([h[4] for h in hitches], float)

    # drive
    dv = scene.drive
    profile = np.zeros((5, 1))
    presc_gain = 0.0
    if dv.kind == "speed":
        R = sheaves[dv.sheave].radius
        presc_gain = dv.roping / R
        prof = (scurve(dv.distance, dv.v_max, dv.a_max, dv.jerk, t_start=dv.t_start)
                if dv.profile == "s-curve" else speed_table(dv.table))
        profile = np.ascontiguousarray(prof.arrays)

    # ---------------------------------------------------------------- outputs
    names, ok, oi, oj, osc = [], [], [], [], []

    def out(name, kind, i, j=0, scale=1.0):
        names.append(name), ok.append(kind), oi.append(i), oj.append(j), osc.append(scale)
        return len(names) - 1

    for b in scene.bodies:
        for ax in b.free:
            jb = nb + body_dof[(b.name, ax)]
            suffix = "" if len(b.free) == 1 else f".{ax}"
            out(f"{b.name}.position{suffix}", O_Q, jb)
            out(f"{b.name}.velocity{suffix}", O_V, jb)
            out(f"{b.name}.acceleration{suffix}", O_A, jb)
    tap_rows = []
    for k, name in enumerate(sh_names):
        out(f"{name}.angle", O_ANGLE, k)
        out(f"{name}.speed", O_SPEED, k)
        ti = to = None
        for (tname, side, off, dirv, ir) in taps:
            if tname != name:
                continue
            idx = len(tap_rows)
            tap_rows.append((k, off, dirv, ir))
            o = out(f"{name}.tension_{side}", O_TAP, idx)
            if side == "in":
                ti = o
            else:
                to = o
        if sheaves[name].kind == "traction" and ti is not None and to is not None:
            out(f"{name}.traction_ratio", O_RATIO, ti, to)
    for ir, rope in enumerate(scene.ropes):
        e0, e1 = rope_el_range[ir]
        out(f"{rope.name}.tension_start", O_END, e0, 0)
        out(f"{rope.name}.tension_end", O_END, e1 - 1, 1)
    if dv.kind == "speed":
        out("motor.torque", O_TORQUE, sh_names.index(dv.sheave))
    ntap = len(tap_rows)
    tap_sh = np.array([t_[0] for t_ in tap_rows], np.int64)
    tap_off = np.array([t_[1] for t_ in tap_rows], float).reshape(ntap, 2)
    tap_dir = np.array([t_[2] for t_ in tap_rows], float).reshape(ntap, 2)
    tap_d = np.full(ntap, probe * element_length)
    tap_lo = np.array([rope_el_range[t_[3]][0] for t_ in tap_rows], np.int64)
    tap_hi = np.array([rope_el_range[t_[3]][1] for t_ in tap_rows], np.int64)
    tap_rhoA = np.array([scene.ropes[t_[3]].rhoA * scene.ropes[t_[3]].count for t_ in tap_rows], float)

    dof_m = np.zeros(n)      # lumped mass per unknown (relaxation damping)
    for (a_, b_, s1_, l_, ir_) in el_list:
        mh = 0.5 * scene.ropes[ir_].rhoA * scene.ropes[ir_].count * l_
        for node in (a_, b_):
            for kk in range(2):
                j = node_dof[node, kk]
                if 0 <= j < nb:
                    dof_m[j] += mh
    for jb, b_ in enumerate(border):
        dof_m[nb + jb] = b_[1]
    lk = LK(
        nb=nb, m=m, node_dof=node_dof, node_off=node_off, node_left=node_left, node_right=node_right,
        node_prev=node_prev, node_next=node_next, node_x0=X0.copy(),
        el_a=el_a, el_b=el_b, el_s1=el_s1, el_l=el_l, el_rhoA=el_rhoA, el_EA=el_EA, el_nu=el_nu,
        el_tonly=el_tonly, el_g=el_g,
        sh_dof=sh_dof, sh_off=sh_off, sh_R=sh_R, sh_mu=sh_mu, sh_kn=sh_kn, sh_cn=sh_cn, sh_w=sh_w,
        sh_kt=sh_kt, sh_th=sh_th, sh_presc=sh_presc, sh_lo=sh_lo, sh_hi=sh_hi,
        sh_J=sh_J,
        bd_M=np.array([b[1] for b in border], float), bd_F=np.array([b[2] for b in border], float),
        bd_c=np.array([b[3] for b in border], float),
        hs_node=hs_node, hs_dof=hs_dof, hs_off=hs_off, hs_k=hs_k, hs_c=hs_c,
        presc_gain=float(presc_gain), profile=profile,
        out_kind=np.array(ok, np.int64), out_i=np.array(oi, np.int64), out_j=np.array(oj, np.int64),
        out_scale=np.array(osc, float),
        tap_sh=tap_sh, tap_off=tap_off, tap_dir=tap_dir, tap_d=tap_d, tap_lo=tap_lo, tap_hi=tap_hi,
        tap_rhoA=tap_rhoA, tap_last=-np.ones(ntap, np.int64),
        dof_m=dof_m, relax_alpha=0.0,
    )
    lock = np.zeros(n, np.bool_)
    for name, jb in sheave_th.items():
        lock[nb + jb] = True
    n_fine = sum(lay["n_fine"] for lay in layouts)
    return LagrangianModel(scene=scene, LK=lk, q_names=q_names, output_names=tuple(names),
                           q_static_guess=q0, lock_static=lock, n_elements=ne, n_fine=n_fine,
                           element_length=element_length,
                           info=dict(layouts=layouts, ranges=ranges, sheaves=sh_names,
                                     rope_length=[lay["L"] for lay in layouts],
                                     ale_q=ale_st.q.copy(), ale_outputs=dict(zip(
                                         ale.output_names, ale_sim.outputs(ale_st)))))


def _sheave_center(sh, bodies, ale, ale_st):
    """Sheave centre (x, z) in the ALE static configuration."""
    c = np.asarray(sh.center, float).copy()
    if sh.body is not None:
        b = bodies[sh.body]
        pos = np.asarray(b.position, float).copy()
        for ax, j in ale.body_dofs[sh.body].items():
            pos[AXES.index(ax)] = ale_st.q[j]
        c = c + pos
    return c[[0, 2]]


# ============================================================================ simulator
class LagrangianSimulator:
    """Generalized-alpha on the Lagrangian model (same parameters and Newton criterion as the engine)."""

    def __init__(self, model: LagrangianModel, step: float = 1e-3, rho_inf: float | None = None,
                 newton_tol: float = 1e-6, max_iter: int = 12, jac_every: int = 1):
        self.model = model
        self.h = float(step)
        self.rho_inf = model.scene.solver.rho_inf if rho_inf is None else float(rho_inf)
        self.tol = float(newton_tol)
        self.params = np.array([*gen_alpha_params(self.rho_inf), self.tol, max_iter, jac_every], float)
        self.info = np.zeros(5)
        self.method = "gen-alpha"

    # ------------------------------------------------------------------ initial state
    def static_state(self, max_iter: int = 60, relax_time: float = 1.0) -> LagrangianState:
        """Initial equilibrium from the laid-out configuration. Without sheaves: Newton statics. With
        sheaves: dynamic relaxation (robust against the contact kinks, and it leaves the stick state
        z of the traction sheave in a physically reachable distribution): the model itself is run with
        the drive held, numerical damping rho_inf = 0.5 and mass-proportional damping of 2 * 2 pi
        rad/s (critical for a 1 Hz mode) for relax_time, then the velocities are zeroed."""
        m = self.model
        LKm = m.LK
        q = m.q_static_guess.copy()
        n = len(q)
        zero = np.zeros(n)
        z = np.zeros(LKm.node_dof.shape[0])
        if LKm.sh_R.shape[0] > 0:
            prof = LKm.profile
            frozen = np.zeros((5, 1))
            frozen[0, 0] = prof[0, 0]
            frozen[1, 0] = prof[1, 0]
            LKr = LKm._replace(profile=frozen, relax_alpha=4.0 * math.pi)
            st = LagrangianState(0.0, q, np.zeros(n), np.zeros(n), np.zeros(n), z)
            nsteps = max(1, int(round(relax_time / self.h)))
            params = np.array([*gen_alpha_params(0.5), 1e-8, 20, 1], float)
            info = np.zeros(5)
            ybuf = np.empty((1, len(m.output_names) + 1))
            r = np.empty(n)
            newton_system(LKr, st.q, st.v, st.qdd, 0.0, st.z, 1.0, 0.0, 0.0, False, np.zeros(n, np.bool_), r)
            st.qdd[:] = -r
            st.a[:] = st.qdd
            status, t = integrate(LKr, st.q, st.v, st.a, st.qdd, st.z, 0.0, self.h, nsteps, params, ybuf, 0,
                                  info)
            if status != 0:
                raise SolverError(f"Lagrangian statics: the relaxation failed at t = {t:.4f} s")
            vmax = float(np.max(np.abs(st.v)))
            self.relax_info = dict(vmax=vmax, steps=int(info[0]), iterations=int(info[1]))
            return LagrangianState(0.0, st.q, np.zeros(n), np.zeros(n), np.zeros(n), st.z)
        r = np.empty(n)
        lock = m.lock_static
        fscale = max(1.0, float(np.max(np.abs(LKm.bd_F))) if LKm.m else 1.0)
        for it in range(max_iter):
            rn = newton_system(LKm, q, zero, zero, 0.0, z, 0.0, 1.0, 0.0, True, lock, r)
            if rn < 0:
                raise SolverError("Lagrangian statics: singular stiffness matrix")
            q -= r
            if float(np.max(np.abs(r))) < 1e-12 * (1.0 + float(np.max(np.abs(q)))) and rn < 1e-6 * fscale:
                break
        rn = newton_system(LKm, q, zero, zero, 0.0, z, 0.0, 1.0, 0.0, True, lock, r)
        if rn > 1e-4 * fscale:
            raise SolverError(f"Lagrangian statics did not converge (residual {rn:.3g} N)")
        return LagrangianState(0.0, q, np.zeros(n), np.zeros(n), np.zeros(n), z)

    def initial_state(self, statics: str | None = None) -> LagrangianState:
        mode = statics or self.model.scene.statics
        if mode == "none":
            n = len(self.model.q_names)
            st = LagrangianState(0.0, self.model.q_static_guess.copy(), np.zeros(n), np.zeros(n),
                                 np.zeros(n), np.zeros(self.model.LK.node_dof.shape[0]))
        else:
            st = self.static_state()
        self.consistent_acceleration(st)
        return st

    def consistent_acceleration(self, st: LagrangianState):
        m = self.model
        n = len(st.q)
        r = np.empty(n)
        lock = np.zeros(n, np.bool_)
        qdd = np.zeros(n)
        newton_system(m.LK, st.q, st.v, qdd, st.t, st.z, 1.0, 0.0, 0.0, False, lock, r)
        st.qdd[:] = -r
        st.a[:] = st.qdd

    def outputs(self, st: LagrangianState) -> np.ndarray:
        y = np.empty(len(self.model.output_names))
        zn = np.empty_like(st.z)
        eval_state(self.model.LK, st.q, st.v, st.qdd, st.t, st.z, False, y, zn)
        return y

    # ------------------------------------------------------------------ stepping
    def advance(self, st: LagrangianState, t_end: float, out_dt: float | None = None):
        span = t_end - st.t
        if span <= 1e-12:
            return None
        if out_dt is None:
            nsteps = max(1, math.ceil(span / self.h - 1e-9))
            h = span / nsteps
            every, n_out = 0, 0
        else:
            n_out = int(round(span / out_dt))
            every = max(1, math.ceil(out_dt / self.h - 1e-9))
            nsteps = n_out * every
            h = span / nsteps
        ybuf = np.empty((max(n_out, 1), len(self.model.output_names) + 1))
        t0 = st.t
        status, t = integrate(self.model.LK, st.q, st.v, st.a, st.qdd, st.z, t0, h, nsteps, self.params,
                              ybuf, every, self.info)
        if status != 0:
            st.t = t
            raise SolverError(f"Lagrangian model: t = {t:.6f} s: Newton iteration did not converge")
        st.t = t_end
        if out_dt is None:
            return None
        return Result(ybuf[:, 0].copy(), ybuf[:, 1:].copy(), self.model.output_names)

    def run(self, t_end: float | None = None, out_dt: float | None = None,
            state: LagrangianState | None = None, progress=None) -> Result:
        sc = self.model.scene
        t_end = sc.t_end if t_end is None else t_end
        out_dt = sc.output_step if out_dt is None else out_dt
        st = self.initial_state() if state is None else state
        self.model.LK.tap_last[:] = -1
        times, vals = [np.array([st.t])], [self.outputs(st)[None, :]]
        chunk = max(out_dt, round(1.0 / out_dt) * out_dt)
        while st.t < t_end - 1e-12:
            nseg = max(1, int(round((min(t_end, st.t + chunk) - st.t) / out_dt)))
            res = self.advance(st, st.t + nseg * out_dt, out_dt=out_dt)
            times.append(res.time)
            vals.append(res.values)
            if progress is not None:
                progress(st.t)
        self.final_state = st
        return Result(np.concatenate(times), np.vstack(vals), self.model.output_names)
