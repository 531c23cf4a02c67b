"""Compiled kernels of the Lagrangian baseline (lagrangian.py): residual, analytic Newton matrix
(band + border; its LU: lagrangian_band.py), outputs and the generalized-alpha loop. Kept apart
from the builder so that editing the builder does not invalidate the numba cache."""
from __future__ import annotations

from collections import namedtuple
import math

import numpy as np

from ..core._jit import njit
from ..core.elements.linear import end_tension, linear_element_at
from ..core.profiles import profile_eval
from ..core.solver.genalpha import method_params, newmark_factors, newmark_update, newton_correct, step_buffers
from .lagrangian_band import KB, bb_factor, bb_solve

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


@njit(cache=True, inline="always")
def _node_contact(LK, k, i, X, V, cx, cz, vcx, vcz, R, th, thd, lam, xo, co, tho, zo, static):
    """Contact of node i with sheave k (_contact) and, in contact, its feed factor and groove friction
    (_friction): (act, nx, nz, ux, uz, rho, Fn, kn, cn, kap, Ft, zs, dzs, dzm)."""
    act, nx, nz, ux, uz, rho, Fn, kn, cn = _contact(LK, k, i, X, V, cx, cz, vcx, vcz)
    if not act:
        return act, nx, nz, ux, uz, rho, Fn, kn, cn, 1.0, 0.0, 0.0, 0.0, 0.0
    kap = _node_feed(LK, lam, i, R)
    Ft, zs, dzs, dzm = _friction(LK, k, i, X, V, cx, cz, vcx, vcz, th, thd, kap, ux, uz, Fn,
                                 xo, co, tho, zo, static)
    return act, nx, nz, ux, uz, rho, Fn, kn, cn, kap, Ft, zs, dzs, dzm


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
                continue    # cheap test first: a call that receives LK pays the tuple's refcounts
            act, nx, nz, ux, uz, rho, Fn, kn, cn, kap, Ft, zs, dzs, dzm = _node_contact(
                LK, k, i, X, V, cx, cz, vcx, vcz, R, th, thd, lam, xo, co, tho, zo, static)
            if not act:
                continue
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
                continue    # cheap test first: a call that receives LK pays the tuple's refcounts
            act, nx, nz, ux, uz, rho, Fn, kn, cn, kap, Ft, zs, dzs, dzm = _node_contact(
                LK, k, i, X, V, cx, cz, vcx, vcz, R, th, thd, lam, xo, co, tho, zo, static)
            if not act:
                continue
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
    am, af, beta, gamma, tol, maxit = method_params(params)
    jac_every = int(params[6])
    n = q.shape[0]
    every = np.arange(n)     # the coordinates the Newmark relations update: all of them
    # static = False typed bool, not Literal[False]: residual and jacobian then share the
    # specialization eval_state and newton_system compile (a literal would compile both again)
    static = n < 0
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
    qo, vo, ao, qddo, q1, v1, a1, qdd1 = step_buffers(n)
    z1 = np.empty(nn)
    t = t0
    row = 0
    have_jac = False
    jac_h = 0.0
    since = 0
    # stretch of every element (the feed factor kappa of the first residual needs it)
    _step_start(LK, q, v, t, X, V, A, xo, co, tho)
    residual(LK, q, v, qdd, t, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static, xo, co, tho, z, zn)
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
            bq, gv = newmark_factors(hs, am, af, beta, gamma)
            for sub in range(nsub):
                ts = t + (sub + 1) * hs
                _step_start(LK, q, v, ts - hs, X, V, A, xo, co, tho)
                zo[:] = z
                qo[:] = q
                vo[:] = v
                ao[:] = a
                qddo[:] = qdd
                newmark_update(every, qo, vo, ao, qddo, qdd, q, v, a, hs, am, af, beta, gamma)
                if jac_h != hs or since >= jac_every:
                    have_jac = False
                status = 1
                for it in range(maxit):
                    residual(LK, q, v, qdd, ts, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static,
                             xo, co, tho, zo, zn)
                    info[3] += 1
                    if not have_jac or it >= 3:
                        jacobian(LK, q, v, ts, 1.0, bq, gv, X, V, MEs, Nel, lam, J, C, D, E, lock, static,
                                 xo, co, tho, zo)
                        info[2] += 1
                        if not bb_factor(J, C, D, E, Xs, S, piv):
                            break
                        have_jac = True
                        jac_h = hs
                        since = 0
                    bb_solve(J, Xs, D, S, piv, r)
                    dmax, amax, _ = newton_correct(every, n, r, qdd, q)
                    newmark_update(every, qo, vo, ao, qddo, qdd, q, v, a, hs, am, af, beta, gamma)
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
                residual(LK, q, v, qdd, ts, r, X, V, A, QE, VE, MEs, QEs, Nel, lam, torque, static,
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
