"""The Jacobian dQ/dq of the static forces (system.static_forces, v = 0) of a model with nonlinear rows,
assembled in closed form (compiled):

    dQ/dq = sum_e B_e^T (dQ_e/dp_e) B_e + sum_r lambda_r d2f_r/dq2 + d(wrap weight)/dq + d(torsion)/dq + q-level

* element stiffness dQ_e/dp_e: the Newton matrix's element blocks (core/jacobian.element_block at rest);
* geometric term: lambda_r = the element and torsion forces on nonlinear row r (the entries of B^T
  they multiply), d2f_r/dq2 over the body coordinates from the rows' second derivatives along a
  direction u (bodies.rows_accel: u^T H_r u at zero coordinate accelerations), polarised,
  H_ij = (a(e_i + e_j) - a(e_i) - a(e_j)) / 2; a W1 strain wrap's s = s2 - (s2 - sigma) D / (D + A)
  adds the mixed sigma / s2 x body terms;
* the W1 wraps' weight and strain energy (bodies.wrap_weight): V = V(sigma, s2, A, D, g.c, g.m) per
  wrap, chained with the gradients and second derivatives of A (wrap arc), D (leaving chord), c (centre)
  and m (leaving span's middle), the latter from the same polarised second derivatives;
* torsion (elements/torsion.torsion_terms): the span's local gradient over its 16 inputs (element
  coordinates, twist angles, frame vectors), chained with B, the frames' turn omega x v and their second
  derivative domega x v + omega x (omega x v);
* q level: hitch springs, gravity moments of revolute bodies, the creep sheaves' forces on sigma (at
  rest the drums' stored-rope strain force, a function of the leaving span's groove strain); other
  q-level laws: `supported` is False.

What is differenced, by central differences on a law's own few inputs (no residual is evaluated): the
torsion span's energy gradient (16 inputs, TORSION_STEP), the wrap's V gradient (6 inputs, WRAP_STEP)
and a creep sheave's force over its elements' coordinates (the groove strain law, CREEP_STEP). Everything that involves the poses is closed form.
"""
from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from ..bodies import (RF_EA, RF_EL, RF_J2, ROW_SLOPE, ROW_TANGENT, ROW_WRAP, SW_A, SW_C, SW_D, _body_motion,
                      _moved, _on, _point_motion, _twist, rows_accel)
from ..contact import sheave_terms
from ..elements.linear import axial_law
from ..elements.torsion import _frame, torsion_extra
from ..jacobian import element_block
from ..kernel import CR_WOUND, UE_CREEP, UE_STRIDE
from ..system import static_forces

TORSION_STEP = 1e-6    # x (1 + |x|): the torsion span's local differences
WRAP_STEP = 1e-6       # x (1 + |x|): the wrap potential's local differences
CREEP_STEP = 1e-7      # x (1 + |x|): a creep sheave's force over its elements' coordinates


def supported(K) -> bool:
    """True if static_jacobian covers every term of K's static forces (else: differences)."""
    rk = K.nl_rk
    if (K.nl_on & 1) == 0 or np.any(rk[:, 0] == ROW_SLOPE) or K.trac_s >= 0:
        return False
    if K.crp_s.shape[0] and K.mot_dof >= 0 and K.drive_kind >= 2:   # a torque times the creep kappa
        return False
    if K.buf_dof.shape[0] or (K.brake_T > 0.0 and K.mot_dof >= 0):
        return False
    for k in range(K.tq_el.shape[0]):     # torsion frames on a body on a joint: not covered
        for e in range(2):
            b = K.tq_vb[k, e]
            if b >= 0 and K.nl_bk[b] == 3:
                return False
    return True


@njit(cache=True)
def _second(K, W, q, u, mo, acc, out):
    """Second derivatives along u (zero coordinate accelerations) at the last update: out[0:nr] the rows
    (rows_accel), out[nr:2nr] g.c'' of each wrap's centre, out[2nr + 6k + 3e + m] the frame vector of
    torsion span k's end e."""
    G = (K.nl_bq, K.nl_b0, K.nl_bk, K.nl_bax, K.nl_pb, K.nl_po, K.nl_sp, K.nl_sg, K.nl_sa, K.nl_rk, K.nl_rf,
         W.nl_P, W.nl_TW, W.nl_BR, W.nl_ang, W.nl_AX, W.nl_SW)
    nr = K.nl_rk.shape[0]
    rows_accel(q, u, G, acc)
    for r in range(nr):
        out[r] = acc[r]
    for b in range(K.nl_bq.shape[0]):
        _body_motion(q, u, K.nl_bq, K.nl_b0, K.nl_bk, K.nl_bax, W.nl_BR, b, mo[b])
    rf = K.nl_rf
    for r in range(nr):
        out[nr + r] = 0.0
        if K.nl_rk[r, 0] != ROW_WRAP:
            continue
        ip = int(rf[r, 3])
        if K.nl_pb[ip] >= 0:
            a = _point_motion(W.nl_P, ip, mo[K.nl_pb[ip]])
            out[nr + r] = rf[r, 4] * a[3] + rf[r, 5] * a[4] + rf[r, 6] * a[5]
    v = np.empty(3)
    for k in range(K.tq_el.shape[0]):
        for e in range(2):
            o = 2 * nr + 6 * k + 3 * e
            out[o] = out[o + 1] = out[o + 2] = 0.0
            b = K.tq_vb[k, e]
            if b < 0 or K.nl_bk[b] == 1:
                continue
            _frame(K, W, k, e, v)
            m = mo[b]
            w0, w1, w2 = _cross(m[6], m[7], m[8], v[0], v[1], v[2])
            a0, a1, a2 = _cross(m[6], m[7], m[8], w0, w1, w2)
            d0, d1, d2 = _cross(m[9], m[10], m[11], v[0], v[1], v[2])
            out[o], out[o + 1], out[o + 2] = a0 + d0, a1 + d1, a2 + d2


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def second_derivatives(K, W, q):
    """H[:, i, j]: the second derivatives of _second's quantities over the body coordinates nl_cols
    (i, j), polarised from directional ones."""
    nr = K.nl_rk.shape[0]
    cols = K.nl_cols
    nc = cols.shape[0]
    nout = 2 * nr + 6 * K.tq_el.shape[0]
    H = np.zeros((nout, nc, nc))
    d = np.empty((nc, nout))
    out = np.empty(nout)
    acc = np.empty(nr)
    mo = np.empty((K.nl_bq.shape[0], 15))
    u = np.zeros(q.shape[0])
    for i in range(nc):
        u[cols[i]] = 1.0
        _second(K, W, q, u, mo, acc, d[i])
        u[cols[i]] = 0.0
        for m in range(nout):
            H[m, i, i] = d[i, m]
    for i in range(nc):
        for j in range(i + 1, nc):
            u[cols[i]] = 1.0
            u[cols[j]] = 1.0
            _second(K, W, q, u, mo, acc, out)
            u[cols[i]] = 0.0
            u[cols[j]] = 0.0
            for m in range(nout):
                h = 0.5 * (out[m] - d[i, m] - d[j, m])
                H[m, i, j] = h
                H[m, j, i] = h
    return H


@njit(cache=True)
def _elements(K, W, Jq, lam):
    """Jq += sum_e B_e^T dQ_e/dp_e B_e; lam[r] += the element forces on row r."""
    ne = K.el_idx.shape[1]
    nd = K.nd
    nw = K.el_map.shape[2]
    JE = np.empty((ne, ne))
    X = np.empty((1, ne))
    XD = np.empty((1, ne))
    G1 = np.zeros((1, nd))
    MEt = np.empty((1, ne, ne))
    QEt = np.empty((1, ne))
    r0 = np.empty(ne)
    r1 = np.empty(ne)
    ae = np.zeros(ne)
    S = np.empty((9 + 4 * nd + 2 * ne, ne))    # element_scratch
    el_map, el_coef = K.el_map, W.el_coef
    for ie in range(el_map.shape[0]):
        # at rest: JE = -dQ_e/dp_e (ba = 0, bq = 1, gv = 0, zero element accelerations)
        element_block(K, ie, W.QE, W.VE, W.MEs, W.QEs, ae, 0.0, 1.0, 0.0, JE, X, XD, G1, MEt, QEt, r0, r1, S)
        for a in range(ne):
            r = K.nl_ent[ie, a]
            if r >= 0:
                lam[r] += W.QEs[ie, a]
            for wa in range(nw):
                ca = el_coef[ie, a, wa]
                if ca == 0.0:
                    continue
                ia = el_map[ie, a, wa]
                for b in range(ne):
                    val = ca * JE[a, b]
                    if val == 0.0:
                        continue
                    for wb in range(nw):
                        Jq[ia, el_map[ie, b, wb]] -= el_coef[ie, b, wb] * val


@njit(cache=True, inline="always")
def _frame_rate(K, W, q, b, j, v):
    """d v / d q[j] = omega_j x v for a frame vector v on body b (kinds 0 and 2; zero otherwise)."""
    if b < 0 or (K.nl_bk[b] != 0 and K.nl_bk[b] != 2):
        return 0.0, 0.0, 0.0
    bq = K.nl_bq
    if K.nl_bk[b] == 0:
        if bq[b, 3] != j:
            return 0.0, 0.0, 0.0
    elif bq[b, 4] != j and bq[b, 5] != j and bq[b, 6] != j:
        return 0.0, 0.0, 0.0
    tw = _twist(q, bq, K.nl_b0, K.nl_bk, K.nl_bax, W.nl_BR, b, j)
    return _cross(tw[3], tw[4], tw[5], v[0], v[1], v[2])


@njit(cache=True)
def _torsion_span(K, W, q, k, Jq, lam, H, x, g, gp, gm, wk, Hl, Jx, HJ, idx):
    """Torsion span k: Jq -= Jx^T Hl Jx + the frames' second derivatives g_v . v''; lam gets its forces
    on the element coordinates (their second derivatives are the rows')."""
    ie = K.tq_el[k]
    p = K.tq_p[k]
    law = int(p[0])
    jA, jB = K.tq_phi[k, 0], K.tq_phi[k, 1]
    for a in range(8):
        x[a] = W.QE[ie, a]
    x[8] = q[jA] if jA >= 0 else K.tq_phic[k, 0]
    x[9] = q[jB] if jB >= 0 else K.tq_phic[k, 1]
    _frame(K, W, k, 0, x[10:13])
    _frame(K, W, k, 1, x[13:16])
    dref = W.tq_dref[k]
    torsion_extra(law, p[1], p[2], p[3], p[4], p[5], x[0:3], x[3:6], x[6], x[7], x[8], x[9], x[10:13], x[13:16],
                  dref, g, wk)
    # Jx: d(local inputs)/dq on the columns idx[:n]
    n = 0
    nq = q.shape[0]
    Jx[:, :] = 0.0
    slot = np.full(nq, -1, np.int64)
    el_map, el_coef = K.el_map, W.el_coef
    for a in range(8):
        r = K.nl_ent[ie, a]
        if r >= 0:
            lam[r] -= g[a]
        for w in range(el_map.shape[2]):
            c = el_coef[ie, a, w]
            if c != 0.0:
                j = el_map[ie, a, w]
                if slot[j] < 0:
                    slot[j] = n
                    idx[n] = j
                    n += 1
                Jx[a, slot[j]] += c
    for e in range(2):
        j = jA if e == 0 else jB
        if j >= 0:
            if slot[j] < 0:
                slot[j] = n
                idx[n] = j
                n += 1
            Jx[8 + e, slot[j]] += 1.0
        b = K.tq_vb[k, e]
        for i in range(K.nl_cols.shape[0]):
            j = K.nl_cols[i]
            d0, d1, d2 = _frame_rate(K, W, q, b, j, x[10 + 3 * e:13 + 3 * e])
            if d0 == 0.0 and d1 == 0.0 and d2 == 0.0:
                continue
            if slot[j] < 0:
                slot[j] = n
                idx[n] = j
                n += 1
            Jx[10 + 3 * e, slot[j]] += d0
            Jx[11 + 3 * e, slot[j]] += d1
            Jx[12 + 3 * e, slot[j]] += d2
    for b in range(16):     # Hl[:, b] by central differences, for the inputs that move with q
        active = False
        for i in range(n):
            if Jx[b, i] != 0.0:
                active = True
        if not active:
            for a in range(16):
                Hl[a, b] = 0.0
            continue
        h = TORSION_STEP * (1.0 + abs(x[b]))
        xb = x[b]
        x[b] = xb + h
        torsion_extra(law, p[1], p[2], p[3], p[4], p[5], x[0:3], x[3:6], x[6], x[7], x[8], x[9], x[10:13],
                      x[13:16], dref, gp, wk)
        x[b] = xb - h
        torsion_extra(law, p[1], p[2], p[3], p[4], p[5], x[0:3], x[3:6], x[6], x[7], x[8], x[9], x[10:13],
                      x[13:16], dref, gm, wk)
        x[b] = xb
        for a in range(16):
            Hl[a, b] = (gp[a] - gm[a]) / (2.0 * h)
    for a in range(16):     # HJ = Hl Jx, then Jx^T HJ
        for jj in range(n):
            t = 0.0
            for b in range(16):
                t += Hl[a, b] * Jx[b, jj]
            HJ[a, jj] = t
    for i in range(n):
        for jj in range(n):
            s = 0.0
            for a in range(16):
                s += Jx[a, i] * HJ[a, jj]
            Jq[idx[i], idx[jj]] -= s
    nr = K.nl_rk.shape[0]
    for e in range(2):       # g_v . v'' on the frame body's coordinates
        o = 2 * nr + 6 * k + 3 * e
        for i in range(K.nl_cols.shape[0]):
            for jj in range(K.nl_cols.shape[0]):
                s = (g[10 + 3 * e] * H[o, i, jj] + g[11 + 3 * e] * H[o + 1, i, jj]
                     + g[12 + 3 * e] * H[o + 2, i, jj])
                if s != 0.0:
                    Jq[K.nl_cols[i], K.nl_cols[jj]] -= s


@njit(cache=True)
def _torsion(K, W, q, Jq, lam, H):
    x = np.empty(16)
    g = np.empty(16)
    gp = np.empty(16)
    gm = np.empty(16)
    wk = np.empty(12)
    Hl = np.empty((16, 16))
    nmax = 8 * K.el_map.shape[2] + 2 + K.nl_cols.shape[0]
    Jx = np.empty((16, nmax))
    HJ = np.empty((16, nmax))
    idx = np.empty(nmax, np.int64)
    for k in range(K.tq_el.shape[0]):
        _torsion_span(K, W, q, k, Jq, lam, H, x, g, gp, gm, wk, Hl, Jx, HJ, idx)


@njit(cache=True, inline="always")
def _wrap_grad(strain, EA, tonly, lw, off, x, gv):
    """dV/dx of a wrap's potential over x = (sigma, s2, A, D, g.c, g.m) (bodies.wrap_weight): with
    F = (s2 - sigma) A / (D + A) (its rope's material length) V = F (w(lambda) - g.m) + lw g.c
    + A (g.m - g.c), lambda = (D + A) / (s2 - sigma); without strain V = -(off + A - lw) g.c."""
    sig, s2, A, D, gc, gm = x[0], x[1], x[2], x[3], x[4], x[5]
    if not strain:
        gv[0] = gv[1] = gv[3] = gv[5] = 0.0
        gv[2] = -gc
        gv[4] = -(off + A - lw)
        return
    S = D + A
    dl = s2 - sig
    N, w, _ = axial_law(EA, 0.0, S / dl - 1.0, 0.0, tonly)
    gv[0] = -A / S * (w - gm) + A * N / dl
    gv[1] = -gv[0]
    gv[2] = dl * D / (S * S) * (w - gm) + A * N / S + gm - gc
    gv[3] = -dl * A / (S * S) * (w - gm) + A * N / S
    gv[4] = lw - A
    gv[5] = A - dl * A / S


@njit(cache=True)
def _wrap_row(K, W, q, r, Jq, H, lam, trow, x, gv, gp, gm, Vh, Gm, Hb, idx):
    """Jq -= d2V/dq2 of wrap row r (V_ab grad a grad b^T + V_a d2a/dq2), and the strain wrap's mixed
    geometric terms of its element forces lam[r]."""
    rk, rf, J, SW, TW, P = K.nl_rk, K.nl_rf, W.nl_J, W.nl_SW, W.nl_TW, W.nl_P
    cols = K.nl_cols
    nc = cols.shape[0]
    nr = rk.shape[0]
    ip = int(rf[r, 3])
    jsig = rk[r, 3]
    j2 = int(rf[r, RF_J2])
    ko = rk[r, 2]
    strain = rf[r, RF_EA] > 0.0
    el = int(rf[r, RF_EL])
    x[0] = q[jsig]
    gc = rf[r, 4] * P[ip, 0] + rf[r, 5] * P[ip, 1] + rf[r, 6] * P[ip, 2]
    x[4] = gc
    x[1] = x[3] = 0.0
    x[5] = gc
    Gm[:, :] = 0.0       # gradients of x over idx = cols, sigma, s2
    Hb[:, :, :] = 0.0    # second derivatives of A, D, g.c, g.m over the columns
    nidx = nc
    for i in range(nc):
        idx[i] = cols[i]
    idx[nc] = jsig
    Gm[0, nc] = 1.0
    nidx = nc + 1
    if strain and j2 >= 0:
        idx[nidx] = j2
        Gm[1, nidx] = 1.0
        nidx += 1
    for i in range(nc):          # g.c: the centre moves with its body
        b = K.nl_colbody[i]
        if K.nl_pb[ip] >= 0 and _on(K.nl_bq, K.nl_bk, K.nl_pb[ip], b):
            tw = _twist(q, K.nl_bq, K.nl_b0, K.nl_bk, K.nl_bax, W.nl_BR, b, cols[i])
            c0, c1, c2 = _moved(P, ip, True, tw[0], tw[1], tw[2], tw[3], tw[4], tw[5], tw[6], tw[7], tw[8])
            Gm[4, i] = rf[r, 4] * c0 + rf[r, 5] * c1 + rf[r, 6] * c2
        for jj in range(nc):
            Hb[2, i, jj] = H[nr + r, i, jj]
    if strain:
        A, D = SW[r, SW_A], SW[r, SW_D]
        x[1] = SW[r, SW_C] + (q[j2] if j2 >= 0 else 0.0)
        x[2], x[3] = A, D
        x[5] = 0.5 * (rf[r, 4] * (TW[ko, 0] + TW[ko, 3]) + rf[r, 5] * (TW[ko, 1] + TW[ko, 4])
                      + rf[r, 6] * (TW[ko, 2] + TW[ko, 5]))
        S = D + A
        dl = x[1] - x[0]
        for i in range(nc):
            Gm[2, i] = J[nr + r, i]
            Gm[3, i] = J[2 * nr + r, i]
            Gm[5, i] = J[3 * nr + r, i]
        _chord_second(TW, J, H, trow, ko, D, rf[r, 4:7], Hb)
        # A'' from the row's f'' = -dl phi'', phi = D / S
        for i in range(nc):
            for jj in range(nc):
                sD = (Gm[3, i] * (Gm[3, jj] + Gm[2, jj]) + (Gm[3, i] + Gm[2, i]) * Gm[3, jj])
                ss = (Gm[3, i] + Gm[2, i]) * (Gm[3, jj] + Gm[2, jj])
                Hb[0, i, jj] = (A * Hb[1, i, jj] - sD + 2.0 * D * ss / S + S * S * H[r, i, jj] / dl) / D
        # the element forces through s = s2 - dl phi: d2s / dsigma dq_b = phi_b, d2s / ds2 dq_b = -phi_b
        for i in range(nc):
            ph = (A * Gm[3, i] - D * Gm[2, i]) / (S * S)
            Jq[cols[i], jsig] += lam[r] * ph
            Jq[jsig, cols[i]] += lam[r] * ph
            if j2 >= 0:
                Jq[cols[i], j2] -= lam[r] * ph
                Jq[j2, cols[i]] -= lam[r] * ph
    else:
        x[2] = W.nl_f0[r] - x[0] - rf[r, 2]
        for i in range(nc):
            Gm[2, i] = J[r, i]
            for jj in range(nc):
                Hb[0, i, jj] = H[r, i, jj]
    EA = K.el_EA[el] if strain else 0.0
    tonly = K.el_tonly[el] != 0 if strain else False
    _wrap_grad(strain, EA, tonly, rf[r, 7], rf[r, 2], x, gv)
    for b in range(6):       # V_ab by central differences of the closed-form gradient
        h = WRAP_STEP * (1.0 + abs(x[b]))
        xb = x[b]
        x[b] = xb + h
        _wrap_grad(strain, EA, tonly, rf[r, 7], rf[r, 2], x, gp)
        x[b] = xb - h
        _wrap_grad(strain, EA, tonly, rf[r, 7], rf[r, 2], x, gm)
        x[b] = xb
        for a in range(6):
            Vh[a, b] = (gp[a] - gm[a]) / (2.0 * h)
    for i in range(nidx):
        for jj in range(nidx):
            s = 0.0
            for a in range(6):
                if Gm[a, i] == 0.0:
                    continue
                for b in range(6):
                    s += Vh[a, b] * Gm[a, i] * Gm[b, jj]
            if i < nc and jj < nc:
                s += gv[2] * Hb[0, i, jj] + gv[3] * Hb[1, i, jj] + gv[4] * Hb[2, i, jj] + gv[5] * Hb[3, i, jj]
            Jq[idx[i], idx[jj]] -= s


@njit(cache=True)
def _chord_second(TW, J, H, trow, k, D, g, Hb):
    """Hb[1] = d2D/dq2 and Hb[3] = g.d2m/dq2 of span k (chord D = |TB - TA|, middle m) from its tangent
    rows trow[k] (gradients J, second derivatives H)."""
    nc = Hb.shape[1]
    e = np.empty(3)
    for m in range(3):
        e[m] = (TW[k, 3 + m] - TW[k, m]) / D
    for i in range(nc):
        for jj in range(nc):
            h = 0.0
            hm = 0.0
            dd = 0.0
            de_i = 0.0
            de_j = 0.0
            for m in range(3):
                ra, rb = trow[k, m], trow[k, 3 + m]
                hA = H[ra, i, jj] if ra >= 0 else 0.0
                hB = H[rb, i, jj] if rb >= 0 else 0.0
                h += e[m] * (hB - hA)
                hm += 0.5 * g[m] * (hA + hB)
                di = (J[rb, i] if rb >= 0 else 0.0) - (J[ra, i] if ra >= 0 else 0.0)
                dj = (J[rb, jj] if rb >= 0 else 0.0) - (J[ra, jj] if ra >= 0 else 0.0)
                dd += di * dj
                de_i += e[m] * di
                de_j += e[m] * dj
            Hb[1, i, jj] = h + (dd - de_i * de_j) / D
            Hb[3, i, jj] = hm


@njit(cache=True)
def _wraps(K, W, q, Jq, H, lam):
    nr = K.nl_rk.shape[0]
    nsp = K.nl_sp.shape[0]
    nc = K.nl_cols.shape[0]
    trow = np.full((nsp, 6), -1, np.int64)
    for r in range(nr):
        if K.nl_rk[r, 0] == ROW_TANGENT:
            trow[K.nl_rk[r, 1], 3 * K.nl_rk[r, 2] + K.nl_rk[r, 3]] = r
    x = np.empty(6)
    gv = np.empty(6)
    gp = np.empty(6)
    gm = np.empty(6)
    Vh = np.empty((6, 6))
    Gm = np.empty((6, nc + 2))
    Hb = np.empty((4, nc, nc))
    idx = np.empty(nc + 2, np.int64)
    for r in range(nr):
        if K.nl_rk[r, 0] == ROW_WRAP:
            _wrap_row(K, W, q, r, Jq, H, lam, trow, x, gv, gp, gm, Vh, Gm, Hb, idx)


@njit(cache=True)
def _creep(K, W, u, Jq):
    """Jq[sigma_k] += d(creep force of sheave k)/dq through its elements' coordinates (system.creep_forces
    at rest: the force on sigma; kappa enters no other static force, `supported`)."""
    T = K.crp_tab
    ne = K.el_idx.shape[1]
    zero = np.zeros(K.nq)
    QE = W.QE
    for k in range(T.shape[0]):
        j = K.crp_s[k]
        kw = u[UE_CREEP + UE_STRIDE * k + CR_WOUND] if u.shape[0] > UE_CREEP else 0.0
        for m in range(2):
            ie = K.crp_el_in[k] if m == 0 else K.crp_el_out[k]
            if ie < 0:
                continue
            for a in range(ne):
                x = QE[ie, a]
                h = CREEP_STEP * (1.0 + abs(x))
                QE[ie, a] = x + h
                fp = sheave_terms(K, T, QE, W.VE, zero, k, kw, K.crp_vreg, K.nd, K.el_type == 1)[2]
                QE[ie, a] = x - h
                fm = sheave_terms(K, T, QE, W.VE, zero, k, kw, K.crp_vreg, K.nd, K.el_type == 1)[2]
                QE[ie, a] = x
                d = (fp - fm) / (2.0 * h)
                if d == 0.0:
                    continue
                for w in range(K.el_map.shape[2]):
                    Jq[j, K.el_map[ie, a, w]] += d * W.el_coef[ie, a, w]


@njit(cache=True)
def static_jacobian(K, W, c, q, zero, u, Jq):
    """Jq (nq x nq) = dQ/dq of static_forces at q (module doc); W: a workspace whose frozen-row flag is
    0. Returns static_forces' status (< 0: a vanishing span; Jq is then not filled)."""
    st = static_forces(K, W, c, q, zero, 0.0, u)
    if st < 0:
        return st
    Jq[:, :] = 0.0
    nr = K.nl_rk.shape[0]
    lam = np.zeros(nr)
    _elements(K, W, Jq, lam)
    H = second_derivatives(K, W, q)
    if K.nl_on & 4:
        _torsion(K, W, q, Jq, lam, H)
    cols = K.nl_cols
    for r in range(nr):          # geometric term of the element (and torsion) forces
        if lam[r] == 0.0:
            continue
        for i in range(cols.shape[0]):
            for j in range(cols.shape[0]):
                Jq[cols[i], cols[j]] += lam[r] * H[r, i, j]
    _wraps(K, W, q, Jq, H, lam)
    if K.crp_s.shape[0]:
        _creep(K, W, u, Jq)
    for k in range(K.spr_dof.shape[0]):
        j = K.spr_dof[k]
        Jq[j, j] -= K.spr_k[k]
    if K.nl_on & 2:
        for k in range(K.jg_dof.shape[0]):
            j = K.jg_dof[k]
            Jq[j, j] += -K.jg_A[k] * math.sin(q[j]) + K.jg_B[k] * math.cos(q[j])
    return st
