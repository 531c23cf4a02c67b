"""Newton matrix of the banded path from element Jacobians (closed form where practical).

For r = M(q) qdd - Q(q, v) the generalized-alpha Newton matrix is

    dr/dqdd = ba M + bq (d(M qdd)/dq - dQ/dq) + gv (-dQ/dv)

(ba = 1 and bq, gv from the Newmark relations). It is assembled element by element, B_e^T J_e B_e,
straight into the banded layout of core/sparse.py:

  * mass matrix: exact (the element kernel's M_e, the q-level M0 and diagonal mass);
  * linear element, axial force (elastic, Kelvin-Voigt damping, smoothed tension-only law, with the
    material-length dependence through l = s2 - s1 and the Eshelby force on the s rows) and gravity:
    closed form (`linear_stiffness`);
  * linear element, inertia terms (d(M_e a_e)/dq_e and the quadratic-velocity vector): closed form
    (elements/linear_jac.py);
  * cubic element: axial and bending stiffness (with the ALE dependence on l = s2 - s1), Kelvin-Voigt
    damping and gravity in closed form (elements/cubic_jac.py); inertia terms by element-local central
    differences of its mass matrix and quadratic-velocity vector (2 ne calls per element; exact in v,
    where these terms are quadratic, second order in q on the element's scale): their q-derivative
    in closed form would differentiate the 4-point Gauss sums of N^T N-dot products a second time;
  * q-level terms: hitch springs and dampers, buffers, stored drum rope, brake and the groove friction's
    spring law in closed form (`qlevel_closed`); what couples a q-level row to element strains (a creep
    sheave's kappa and creep force, the groove friction's capacity from the end tensions) by central
    differences over the coordinates of those few elements (`qlevel_coupled`).
"""
from __future__ import annotations

import math

import numpy as np

from ._jit import njit
from .contact import creep_kappa, creep_terms, creep_wound, static_end_tension
from .elements.cubic import cubic_element_at, cubic_mass, cubic_qv
from .elements.cubic_jac import cubic_stiffness, gravity_jac
from .elements.linear import axial_law_d, chord, linear_element_at
from .elements.linear_jac import linear_inertia
from .kernel import UE_BRAKE_E, UE_BRAKE_Z, UE_CREEP, UE_MOTOR_Q, UE_TRAC_S, UE_TRAC_TH, UE_TRAC_Z
from .sparse import bordered_factor, residual_sparse
from .system import element_eval, q_terms

FD_STEP = 1e-7     # coordinate step of the element-local differences, x (1 + |q|)
QL_STEP = 1e-9     # and of the q-level ones (the friction laws saturate within ~1e-5 m)


@njit(cache=True, inline="always")
def linear_stiffness(nd, rhoA, EA, nu, tonly, G, QE, VE, ie, bq, gv, JE, S):
    """Adds bq (-dQ/dq) + gv (-dQ/dv) of the linear element's gravity and axial force to JE (ne x ne,
    element coordinates [r1, r2, s1, s2]). S: scratch (5, ne). Closed form of the kernel's
    N t (node rows) and Eshelby force N lambda - w + N_d lambda (s rows), lambda = |r2 - r1| / l."""
    i1 = 2 * nd
    i2 = i1 + 1
    ne = i2 + 1
    l = QE[ie, i2] - QE[ie, i1]
    for k in range(nd):          # gravity: m g / 2 on the nodes, rhoA g.(r1 + r2)/2 on the s rows
        gk = 0.5 * rhoA * G[ie, k] * bq
        for a in (k, nd + k):
            JE[a, i1] += gk
            JE[a, i2] -= gk
            JE[i1, a] += gk
            JE[i2, a] -= gk
    dist = chord(QE, ie, nd)
    if dist <= 0.0:
        return
    ldot = VE[ie, i2] - VE[ie, i1]
    lam = dist / l
    t = S[4]
    rel = 0.0
    for k in range(nd):
        t[k] = (QE[ie, nd + k] - QE[ie, k]) / dist
        rel += t[k] * (VE[ie, nd + k] - VE[ie, k])
    A = rel - lam * ldot                      # l x strain rate
    N, w, Nd, dN, dNe, dNed = axial_law_d(EA, nu, lam - 1.0, A / l, tonly)
    Nt = N + Nd
    eq = S[0]      # d eps / d x (= d epsdot / d xdot)
    edq = S[1]     # d epsdot / d x
    dNq = S[2]     # d(N + N_d) / d x
    dNv = S[3]     # d(N + N_d) / d xdot
    for k in range(nd):
        eq[k] = -t[k] / l
        eq[nd + k] = t[k] / l
        e2 = ((VE[ie, nd + k] - VE[ie, k] - t[k] * rel) / dist - ldot * t[k] / l) / l
        edq[k] = -e2
        edq[nd + k] = e2
    eq[i1] = lam / l
    eq[i2] = -lam / l
    edq[i1] = (A - ldot * lam) / (l * l)
    edq[i2] = -edq[i1]
    for b in range(ne):
        dNq[b] = (dN + dNe) * eq[b] + dNed * edq[b]
        dNv[b] = dNed * eq[b]
    for b in range(ne):
        for k in range(nd):
            dt = 0.0                           # d t_k / d x_b
            if b < nd:
                dt = -((1.0 if b == k else 0.0) - t[k] * t[b]) / dist
            elif b < 2 * nd:
                dt = ((1.0 if b - nd == k else 0.0) - t[k] * t[b - nd]) / dist
            val = bq * (t[k] * dNq[b] + Nt * dt) + gv * t[k] * dNv[b]
            JE[k, b] -= val
            JE[nd + k, b] += val
        desh = bq * (dNq[b] * lam + Nd * eq[b]) + gv * dNv[b] * lam
        JE[i1, b] += desh
        JE[i2, b] -= desh


@njit(cache=True, inline="always")
def _element_res(K, ie, full, X, XD, ae, G1, MEt, QEt, out):
    """out = M_e a_e - Q_e of element ie at X[0], XD[0]; full = False: inertia only (mass matrix and
    quadratic-velocity vector: stiffness, damping and gravity off; G1 then holds zeros)."""
    nd = K.nd
    if K.el_type == 1:
        if full:
            cubic_element_at(nd, K.el_rhoA[ie], K.el_EA[ie], K.el_EI[ie], K.el_nu[ie], K.el_tonly[ie] != 0,
                             G1, X, XD, MEt, QEt, 0)
        else:
            cubic_mass(nd, K.el_rhoA[ie], X[0], MEt[0])
            cubic_qv(nd, K.el_rhoA[ie], X[0], XD[0], MEt[0], QEt[0])
    elif full:
        linear_element_at(nd, K.el_rhoA[ie], K.el_EA[ie], K.el_nu[ie], K.el_tonly[ie] != 0, G1, K.el_C[ie],
                          X, XD, MEt, QEt, 0)
    else:
        linear_element_at(nd, K.el_rhoA[ie], 0.0, 0.0, False, G1, 0.0, X, XD, MEt, QEt, 0)
    ne = X.shape[1]
    for a in range(ne):
        s = -QEt[0, a]
        for b in range(ne):
            s += MEt[0, a, b] * ae[b]
        out[a] = s


def element_scratch(nd, ne):
    """Scratch S of element_block."""
    return np.empty((9 + 4 * nd + 2 * ne, ne))


@njit(cache=True)
def element_block(K, ie, QE, VE, MEs, QEs, ae, ba, bq, gv, JE, X, XD, G1, MEt, QEt, r0, r1, S):
    """The element's Newton block J_e = ba M_e + bq d r_e/dq_e + gv d r_e/dv_e (ne x ne) into JE,
    r_e = M_e a_e - Q_e; element arrays QE, VE, MEs, QEs as the residual left them (module doc)."""
    nd = K.nd
    ne = QE.shape[1]
    cubic = K.el_type == 1
    for a in range(ne):
        for b in range(ne):
            JE[a, b] = ba * MEs[ie, a, b]
        X[0, a] = QE[ie, a]
        XD[0, a] = VE[ie, a]
    for k in range(nd):
        G1[0, k] = 0.0
    if cubic:
        gravity_jac(nd, K.el_rhoA[ie], K.el_g[ie], X[0], bq, JE)
        n2 = 2 * nd
        cubic_stiffness(nd, K.el_EA[ie], K.el_EI[ie], K.el_nu[ie], K.el_tonly[ie] != 0, X[0], XD[0], bq, gv, JE,
                        S[9:9 + n2], S[9 + n2:9 + 2 * n2, :n2], S[9 + 2 * n2:9 + 2 * n2 + ne],
                        S[9 + 2 * n2 + ne:9 + 2 * n2 + 2 * ne], S[:9])
    else:
        linear_stiffness(nd, K.el_rhoA[ie], K.el_EA[ie], K.el_nu[ie], K.el_tonly[ie] != 0, K.el_g, QE, VE, ie,
                         bq, gv, JE, S)
        linear_inertia(nd, K.el_rhoA[ie], QE, VE, ie, ae, bq, gv, JE)
        return
    # cubic inertia, central differences: exact for the quadratic-velocity terms (quadratic in v),
    # second order in q
    for b in range(ne):
        hq = FD_STEP * (1.0 + abs(QE[ie, b]))
        dx = hq / bq
        X[0, b] = QE[ie, b] + hq
        XD[0, b] = VE[ie, b] + gv * dx
        _element_res(K, ie, False, X, XD, ae, G1, MEt, QEt, r1)
        X[0, b] = QE[ie, b] - hq
        XD[0, b] = VE[ie, b] - gv * dx
        _element_res(K, ie, False, X, XD, ae, G1, MEt, QEt, r0)
        for a in range(ne):
            JE[a, b] += (r1[a] - r0[a]) / (2.0 * dx)
        X[0, b] = QE[ie, b]
        XD[0, b] = VE[ie, b]


@njit(cache=True, inline="always")
def _add(J, ib, jb, val, n1, kl, ku, wb, nb):
    """J[ib, jb] += val in the layout of sparse.bordered_factor (entries outside the band are dropped:
    the structural pattern contains every coupling assembled here)."""
    if ib < n1:
        if jb < n1:
            d = jb - ib
            if d <= ku and d >= -kl:
                J[ib, d + kl] += val
        else:
            J[ib, wb + jb - n1] += val
    elif jb < n1:
        J[jb, wb + nb + ib - n1] += val
    else:
        J[ib, jb - n1] += val


@njit(cache=True, inline="always")
def _elastoplastic_d(z, zmax):
    """d/dz of contact._elastoplastic."""
    a = 0.9 * zmax
    az = abs(z)
    if az <= a:
        return 1.0
    th = math.tanh((az - a) / (zmax - a))
    return 1.0 - th * th


@njit(cache=True)
def elements_pass(K, SP, W, qdd, pos, J, ba, bq, gv):
    """Every element's Newton block, assembled B_e^T J_e B_e into J."""
    ne = K.el_idx.shape[1]
    nd = K.nd
    nw = K.el_map.shape[2]
    n1 = SP.n - SP.nb
    wb = 3 * SP.kl + SP.ku + 1
    JE = np.empty((ne, ne))
    X = np.empty((1, ne))
    XD = np.empty((1, ne))
    G1 = np.zeros((1, nd))
    MEt = np.empty((1, ne, ne))
    QEt = np.empty((1, ne))
    r0 = np.empty(ne)
    r1 = np.empty(ne)
    ae = np.empty(ne)
    S = np.empty((9 + 4 * nd + 2 * ne, ne))
    el_map = K.el_map
    el_coef = W.el_coef
    for ie in range(el_map.shape[0]):
        for a in range(ne):
            x = 0.0
            for w in range(nw):
                x += el_coef[ie, a, w] * qdd[el_map[ie, a, w]]
            ae[a] = x
        element_block(K, ie, W.QE, W.VE, W.MEs, W.QEs, ae, ba, bq, gv, JE, X, XD, G1, MEt, QEt, r0, r1, S)
        for a in range(ne):
            for wa in range(nw):
                ca = el_coef[ie, a, wa]
                if ca == 0.0:
                    continue
                ib = pos[el_map[ie, a, wa]]
                if ib < 0:
                    continue
                for b in range(ne):
                    val = ca * JE[a, b]
                    if val == 0.0:
                        continue
                    for wc in range(nw):
                        cb = el_coef[ie, b, wc]
                        if cb == 0.0:
                            continue
                        jb = pos[el_map[ie, b, wc]]
                        if jb >= 0:
                            _add(J, ib, jb, cb * val, n1, SP.kl, SP.ku, wb, SP.nb)


@njit(cache=True)
def coupled_columns(K):
    """(mark over q, elements): coordinates and elements through which q-level rows depend on element
    strains (creep sheaves, the groove friction's capacity)."""
    els = []
    for k in range(K.crp_s.shape[0]):
        if K.crp_el_in[k] >= 0:
            els.append(K.crp_el_in[k])
        if K.crp_el_out[k] >= 0:
            els.append(K.crp_el_out[k])
    if K.trac_s >= 0:
        els.append(K.trac_el_in)
        els.append(K.trac_el_out)
    mark = np.zeros(K.nq, np.bool_)
    out = np.empty(len(els), np.int64)
    for m in range(len(els)):
        ie = els[m]
        out[m] = ie
        for a in range(K.el_map.shape[1]):
            for w in range(K.el_map.shape[2]):
                if K.el_coef[ie, a, w] != 0.0:
                    mark[K.el_map[ie, a, w]] = True
    return mark, out


@njit(cache=True)
def qlevel_closed(K, SP, W, q, v, qdd, u, pos, mark, J, ba, bq, gv):
    """q-level mass (ba (M0 + diagonal)) and the closed-form derivatives of the q-level forces with
    respect to their own coordinates, for coordinates outside `mark` (those are differenced)."""
    n1 = SP.n - SP.nb
    kl, ku, nb = SP.kl, SP.ku, SP.nb
    wb = 3 * kl + ku + 1
    for i in range(K.nq):
        ib = pos[i]
        if ib < 0:
            continue
        _add(J, ib, ib, ba * W.Md[i], n1, kl, ku, wb, nb)
        for m in range(SP.m0_ptr[i], SP.m0_ptr[i + 1]):
            jb = pos[SP.m0_idx[m]]
            if jb >= 0:
                _add(J, ib, jb, ba * SP.m0_val[m], n1, kl, ku, wb, nb)
    for k in range(K.spr_dof.shape[0]):
        j = K.spr_dof[k]
        if pos[j] >= 0 and not mark[j]:
            _add(J, pos[j], pos[j], bq * K.spr_k[k] + gv * K.spr_c[k], n1, kl, ku, wb, nb)
    for k in range(K.buf_dof.shape[0]):
        j = K.buf_dof[k]
        sg = K.buf_sign[k]
        d = sg * (K.buf_z[k] - q[j])
        if pos[j] >= 0 and not mark[j] and d > 0.0 and K.buf_k[k] * d - sg * K.buf_c[k] * v[j] > 0.0:
            _add(J, pos[j], pos[j], bq * K.buf_k[k] + gv * K.buf_c[k], n1, kl, ku, wb, nb)
    for k in range(K.drum_dof.shape[0]):
        j = K.drum_dof[k]
        if pos[j] >= 0 and not mark[j]:
            _add(J, pos[j], pos[j], K.drum_rhoA[k] * (bq * qdd[j] + gv * v[j]), n1, kl, ku, wb, nb)
    for k in range(K.jg_dof.shape[0]):      # gravity moment A cos x + B sin x of a revolute body
        j = K.jg_dof[k]
        if pos[j] >= 0 and not mark[j]:
            dQ = -K.jg_A[k] * math.sin(q[j]) + K.jg_B[k] * math.cos(q[j])
            _add(J, pos[j], pos[j], -bq * dQ, n1, kl, ku, wb, nb)
    j = K.mot_dof
    if K.brake_T > 0.0 and j >= 0 and pos[j] >= 0 and not mark[j]:
        gain = K.mot_gain
        if K.mot_crp >= 0 and K.crp_kind[K.mot_crp] == 0 and u.shape[0] > UE_CREEP:
            gain *= creep_terms(K, W.QE, W.VE, v, K.mot_crp, creep_wound(u, K.mot_crp))[0]
        kz = K.mot_gain * creep_kappa(K, u, K.mot_crp)          # dz/dq
        z = u[UE_BRAKE_Z] + kz * (q[j] - u[UE_MOTOR_Q])
        kb = u[UE_BRAKE_E] * K.brake_T / K.brake_wreg * _elastoplastic_d(z, K.brake_wreg)
        _add(J, pos[j], pos[j], bq * kb * kz * gain, n1, kl, ku, wb, nb)
    if K.trac_s >= 0:
        kap = 1.0
        for k in range(K.crp_s.shape[0]):
            if K.crp_kind[k] == 1:
                kap = creep_kappa(K, u, k)
        T_in = static_end_tension(K, W.QE, W.QEs, K.trac_el_in, 1)
        T_out = static_end_tension(K, W.QE, W.QEs, K.trac_el_out, 0)
        T_slack = max(min(T_in, T_out), 0.0)
        z = u[UE_TRAC_Z] - kap * (q[K.trac_s] - u[UE_TRAC_S]) - K.trac_R * (q[K.trac_th] - u[UE_TRAC_TH])
        kf = T_slack * K.trac_efa / K.trac_zmax * _elastoplastic_d(z, K.trac_zmax)   # -df/dz
        s, th = K.trac_s, K.trac_th
        R = K.trac_R
        # R_s += f kappa, R_th += f R with df/dq_s = kf kappa, df/dq_th = kf R
        for col, dz in ((s, kap), (th, R)):
            if pos[col] >= 0 and not mark[col]:
                if pos[s] >= 0:
                    _add(J, pos[s], pos[col], bq * kap * kf * dz, n1, kl, ku, wb, nb)
                if pos[th] >= 0:
                    _add(J, pos[th], pos[col], bq * R * kf * dz, n1, kl, ku, wb, nb)


@njit(cache=True, inline="always")
def _qlevel_values(K, W, q, v, qdd, t, u, rows, out):
    """out[m] = (q-level forces - diagonal mass x qdd) at rows[m] (element arrays as in W)."""
    for m in range(rows.shape[0]):
        W.Q[rows[m]] = 0.0
    q_terms(K, W, q, v, t, u)
    for m in range(rows.shape[0]):
        out[m] = W.Q[rows[m]] - W.Md[rows[m]] * qdd[rows[m]]


@njit(cache=True, inline="always")
def _refresh(K, c, q, v, W, els, j):
    """Re-evaluate the elements in els that depend on coordinate j."""
    for m in range(els.shape[0]):
        ie = els[m]
        hit = False
        for a in range(K.el_map.shape[1]):
            for w in range(K.el_map.shape[2]):
                if W.el_coef[ie, a, w] != 0.0 and K.el_map[ie, a, w] == j:
                    hit = True
        if hit:
            element_eval(K, W.el_coef, c, q, v, ie, W.QE, W.VE, W.MEs, W.QEs)


@njit(cache=True)
def qlevel_coupled(K, SP, W, c, q, v, qdd, t, u, pos, mark, els, J, bq, gv):
    """Central differences of the q-level forces over the marked coordinates (q and v move together as
    in the Newton step; the diagonal mass's qdd part is exact in qlevel_closed)."""
    n1 = SP.n - SP.nb
    kl, ku, nb = SP.kl, SP.ku, SP.nb
    wb = 3 * kl + ku + 1
    seen = np.zeros(K.nq, np.bool_)
    rl = []
    for arr in (K.crp_s, K.spr_dof, K.buf_dof, K.drum_dof, K.jg_dof):
        for i in arr:
            if not seen[i]:
                seen[i] = True
                rl.append(i)
    for i in (K.mot_dof, K.trac_s, K.trac_th):
        if i >= 0 and not seen[i]:
            seen[i] = True
            rl.append(i)
    rows = np.empty(len(rl), np.int64)
    for m in range(len(rl)):
        rows[m] = rl[m]
    rp = np.empty(len(rl))
    rm = np.empty(len(rl))
    for j in range(K.nq):
        if not mark[j] or pos[j] < 0:
            continue
        hq = QL_STEP * (1.0 + abs(q[j]))
        dx = hq / bq
        q0, v0 = q[j], v[j]
        q[j] = q0 + hq
        v[j] = v0 + gv * dx
        _refresh(K, c, q, v, W, els, j)
        _qlevel_values(K, W, q, v, qdd, t, u, rows, rp)
        q[j] = q0 - hq
        v[j] = v0 - gv * dx
        _refresh(K, c, q, v, W, els, j)
        _qlevel_values(K, W, q, v, qdd, t, u, rows, rm)
        q[j] = q0
        v[j] = v0
        _refresh(K, c, q, v, W, els, j)
        for m in range(rows.shape[0]):
            ib = pos[rows[m]]
            d = rp[m] - rm[m]
            if ib >= 0 and d != 0.0:
                _add(J, ib, pos[j], -d / (2.0 * dx), n1, kl, ku, wb, nb)


@njit(cache=True)
def newton_matrix_analytic(K, SP, W, c, q, v, qdd, t, u, J, R0, ba, bq, gv):
    """The Newton matrix ba M + bq dr/dq + gv dr/dv into J (layout of sparse.bordered_factor) from
    element and q-level Jacobians (module doc). Returns -1 - element (vanishing span) or 1."""
    st = residual_sparse(K, SP, W, c, q, v, qdd, t, u, R0)
    if st < 0:
        return st
    for i in range(J.shape[0]):
        for k in range(J.shape[1]):
            J[i, k] = 0.0
    pos = np.full(K.nq, -1, np.int64)
    for b in range(SP.n):
        pos[SP.perm[b]] = b
    elements_pass(K, SP, W, qdd, pos, J, ba, bq, gv)
    mark, els = coupled_columns(K)
    qlevel_closed(K, SP, W, q, v, qdd, u, pos, mark, J, ba, bq, gv)
    if els.shape[0]:
        qlevel_coupled(K, SP, W, c, q, v, qdd, t, u, pos, mark, els, J, bq, gv)
    return 1


@njit(cache=True)
def jacobian_analytic(K, SP, W, c, q, v, qdd, t, u, J, piv, R0, bq, gv):
    """newton_matrix_analytic (ba = 1), factorised (sparse.bordered_factor). Returns -1 - element
    (vanishing span), 0 (singular) or 1."""
    st = newton_matrix_analytic(K, SP, W, c, q, v, qdd, t, u, J, R0, 1.0, bq, gv)
    if st < 0:
        return st
    return 1 if bordered_factor(J, piv, SP.n, SP.nb, SP.kl, SP.ku) else 0
