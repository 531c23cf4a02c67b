"""Closed-form stiffness and damping Jacobian of the cubic ALE-ANCF element (elements/cubic.py).

The element's strain energy is U = l sum_g W_g w(a_g, b_g) with a = r_s, b = r_ss at the Gauss point,

    a = sum_j alpha_j(l) x_j,  b = sum_j beta_j(l) x_j,   x_j in (r1, d1, r2, d2),
    alpha = (h1'/l, h2', h3'/l, h4'),  beta = (h1''/l^2, h2''/l, h3''/l^2, h4''/l),  l = s2 - s1,

and w = 1/2 EA (|a| - 1)^2 + 1/2 EI (|a|^2 |b|^2 - (a.b)^2) / |a|^4. Its Hessian is taken in the
coordinates y = (x, l), where z = (a, b) is linear in x and the l-dependence sits in alpha(l), beta(l):

    d2U/dy2 = sum_g W_g [ l Z^T H_w Z + l E + e_l (g.Z) + (g.Z) e_l ],   Z = dz/dy,

H_w, g the Hessian and gradient of w in z, E the second derivative of z (non-zero only in the
x-l and l-l entries); then d/ds2 = d/dl = -d/ds1. The Kelvin-Voigt force is -l W EA nu epsdot G with
epsdot = G(q).v exactly linear in v, so its v-Jacobian is the rank-one l W EA nu G G^T; its q-Jacobian
follows from dG/dy, written out below. Gravity is linear in q except through l (closed form).
The inertia terms (mass matrix times acceleration, quadratic-velocity vector) are not here: their
Jacobian is taken by element-local differences (core/jacobian.py).
"""
from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from .cubic import GW5, GX5, _shape
from .linear import axial_law_d


@njit(cache=True, inline="always")
def gravity_jac(nd, rhoA, g, qe, bq, JE):
    """Adds bq (-dQ_g/dq) of cubic.cubic_gravity to JE."""
    s1 = 2 * nd
    o2 = 2 * nd + 1
    s2 = 4 * nd + 1
    l = qe[s2] - qe[s1]
    dQsdl = 0.0
    for k in range(nd):
        c = bq * rhoA * g[k]
        dQsdl += c * (qe[nd + k] - qe[o2 + nd + k]) / 6.0
        # node rows: dQ/dl (l = s2 - s1)
        for row, dl in ((k, 0.5 * c), (nd + k, c * l / 6.0), (o2 + k, 0.5 * c), (o2 + nd + k, -c * l / 6.0)):
            JE[row, s2] -= dl
            JE[row, s1] += dl
        # s rows: Q_s2 = +Qs, Q_s1 = -Qs
        for col, dq in ((k, 0.5 * c), (o2 + k, 0.5 * c), (nd + k, c * l / 6.0), (o2 + nd + k, -c * l / 6.0)):
            JE[s2, col] -= dq
            JE[s1, col] += dq
    JE[s2, s2] -= dQsdl
    JE[s2, s1] += dQsdl
    JE[s1, s2] += dQsdl
    JE[s1, s1] -= dQsdl


@njit(cache=True, inline="always")
def _w_hessian(nd, dN, EI, a, b, A, B, C, lam, N, Hz, gz):
    """Gradient gz (2 nd) and Hessian Hz (2 nd x 2 nd) of w(a, b) (module doc) in z = (a, b); N and
    dN the axial force and its slope dN/deps (linear.axial_law_d)."""
    for i in range(2 * nd):
        gz[i] = 0.0
        for j in range(2 * nd):
            Hz[i, j] = 0.0
    if N != 0.0 or dN != 0.0:
        for k in range(nd):
            tk = a[k] / lam
            gz[k] += N * tk
            for m in range(nd):
                tm = a[m] / lam
                Hz[k, m] += (dN - N / lam) * tk * tm + (N / lam if k == m else 0.0)
    if EI != 0.0:
        K = A * B - C * C
        A2 = A * A
        A3 = A2 * A
        fA = 0.5 * EI * (B / A2 - 2.0 * K / A3)
        fB = 0.5 * EI / A
        fC = -EI * C / A2
        fAA = 0.5 * EI * (-4.0 * B / A3 + 6.0 * K / (A2 * A2))
        fAB = -0.5 * EI / A2
        fAC = 2.0 * EI * C / A3
        fCC = -EI / A2
        for k in range(nd):
            gz[k] += 2.0 * fA * a[k] + fC * b[k]
            gz[nd + k] += 2.0 * fB * b[k] + fC * a[k]
            for m in range(nd):
                dkm = 1.0 if k == m else 0.0
                Hz[k, m] += (4.0 * fAA * a[k] * a[m] + 2.0 * fAC * (a[k] * b[m] + b[k] * a[m])
                             + fCC * b[k] * b[m] + 2.0 * fA * dkm)
                hab = 4.0 * fAB * a[k] * b[m] + 2.0 * fAC * a[k] * a[m] + fCC * b[k] * a[m] + fC * dkm
                Hz[k, nd + m] += hab
                Hz[nd + m, k] += hab
                Hz[nd + k, nd + m] += fCC * a[k] * a[m] + 2.0 * fB * dkm


@njit(cache=True)
def cubic_stiffness(nd, EA, EI, nu, tonly, qe, ve, bq, gv, JE, Z, Hz, Hy, Dy, V):
    """Adds bq (-dQ/dq) + gv (-dQ/dv) of the cubic element's elastic, Kelvin-Voigt and (separately,
    not gravity: gravity_jac) forces to JE (ne x ne). Scratch: Z (2 nd, ne), Hz (2 nd, 2 nd), Hy, Dy
    (ne, ne), V (9, ne). y-indexing (module doc): column/row s2 of Z, Hy, Dy stands for l, s1 is unused."""
    s1 = 2 * nd
    o2 = 2 * nd + 1
    s2 = 4 * nd + 1
    ne = 4 * nd + 2
    l = qe[s2] - qe[s1]
    off = (0, nd, o2, o2 + nd)
    a, b, al, bl = V[0], V[1], V[2], V[3]
    all_, bll, gz, G = V[4], V[5], V[6], V[7]
    for i in range(ne):
        for j in range(ne):
            Hy[i, j] = 0.0
            Dy[i, j] = 0.0
    for i in range(2 * nd):
        for j in range(ne):
            Z[i, j] = 0.0
    damp = nu != 0.0 and EA != 0.0
    for gp in range(5):
        xi = GX5[gp]
        W = GW5[gp]
        h1, h2, h3, h4, p1, p2, p3, p4, q1, q2, q3, q4 = _shape(xi)
        il = 1.0 / l
        alp = (p1 * il, p2, p3 * il, p4)
        bet = (q1 * il * il, q2 * il, q3 * il * il, q4 * il)
        alp1 = (-p1 * il * il, 0.0, -p3 * il * il, 0.0)
        bet1 = (-2.0 * q1 * il ** 3, -q2 * il * il, -2.0 * q3 * il ** 3, -q4 * il * il)
        alp2 = (2.0 * p1 * il ** 3, 0.0, 2.0 * p3 * il ** 3, 0.0)
        bet2 = (6.0 * q1 * il ** 4, 2.0 * q2 * il ** 3, 6.0 * q3 * il ** 4, 2.0 * q4 * il ** 3)
        A = 0.0
        B = 0.0
        C = 0.0
        for k in range(nd):
            a[k] = b[k] = al[k] = bl[k] = all_[k] = bll[k] = 0.0
            for j in range(4):
                x = qe[off[j] + k]
                a[k] += alp[j] * x
                b[k] += bet[j] * x
                al[k] += alp1[j] * x
                bl[k] += bet1[j] * x
                all_[k] += alp2[j] * x
                bll[k] += bet2[j] * x
                Z[k, off[j] + k] = alp[j]
                Z[nd + k, off[j] + k] = bet[j]
            Z[k, s2] = al[k]
            Z[nd + k, s2] = bl[k]
            A += a[k] * a[k]
            B += b[k] * b[k]
            C += a[k] * b[k]
        lam = math.sqrt(A)
        eps = lam - 1.0
        ed = _strain_rate(nd, s1, s2, off, xi, ve, alp, a, b, al, lam, G) if damp else 0.0
        N, w, Nd, dN, dNe, dNed = axial_law_d(EA, nu, eps, ed, tonly)
        _w_hessian(nd, dN, EI, a, b, A, B, C, lam, N, Hz, gz)
        _add_elastic(nd, ne, s2, off, l, W, alp1, bet1, Z, Hz, Hy, gz, all_, bll)
        if damp and (Nd != 0.0 or dNe != 0.0 or dNed != 0.0):
            _add_damping(nd, ne, s1, s2, off, l, xi, W * dNed, W * Nd, W * dNe, ve, alp, bet, alp1, a, b,
                         al, bl, all_, lam, G, V[8], Dy, JE, gv)
    for i in range(ne):
        yi, si = (s2, -1.0) if i == s1 else (i, 1.0)
        for j in range(ne):
            yj, sj = (s2, -1.0) if j == s1 else (j, 1.0)
            JE[i, j] += bq * (si * sj * Hy[yi, yj] + sj * Dy[i, yj])


@njit(cache=True, inline="always")
def _add_elastic(nd, ne, s2, off, l, W, alp1, bet1, Z, Hz, Hy, gz, all_, bll):
    """Hy += W [l Z^T Hz Z + l E + e_l (g.Z) + (g.Z) e_l] (module doc)."""
    for i in range(ne):
        for j in range(i, ne):
            acc = 0.0
            for m in range(2 * nd):
                zm = Z[m, i]
                if zm == 0.0:
                    continue
                for n in range(2 * nd):
                    acc += zm * Hz[m, n] * Z[n, j]
            Hy[i, j] += W * l * acc
            if j != i:
                Hy[j, i] += W * l * acc
    gl = 0.0
    for m in range(2 * nd):
        gl += gz[m] * Z[m, s2]
    for i in range(ne):     # (g.Z) e_l + e_l (g.Z): g.Z_i in row/column l
        if i == s2:
            continue
        gZ = 0.0
        for m in range(2 * nd):
            gZ += gz[m] * Z[m, i]
        Hy[i, s2] += W * gZ
        Hy[s2, i] += W * gZ
    Hy[s2, s2] += 2.0 * W * gl
    for k in range(nd):     # E: d2 z / dx dl and d2 z / dl2
        for j in range(4):
            e = W * l * (gz[k] * alp1[j] + gz[nd + k] * bet1[j])
            Hy[off[j] + k, s2] += e
            Hy[s2, off[j] + k] += e
        Hy[s2, s2] += W * l * (gz[k] * all_[k] + gz[nd + k] * bll[k])


@njit(cache=True, inline="always")
def _strain_rate(nd, s1, s2, off, xi, ve, alp, a, b, al, lam, G):
    """The material strain rate epsdot = G.v at the Gauss point; fills G (module doc)."""
    ne = G.shape[0]
    for i in range(ne):
        G[i] = 0.0
    for k in range(nd):
        tk = a[k] / lam
        for j in range(4):
            G[off[j] + k] = alp[j] * tk
    u1 = 0.0        # t.u for u = -al - (1-xi) b (s1) and al - xi b (s2)
    u2 = 0.0
    for k in range(nd):
        tk = a[k] / lam
        u1 += tk * (-al[k] - (1.0 - xi) * b[k])
        u2 += tk * (al[k] - xi * b[k])
    G[s1] = u1
    G[s2] = u2
    ed = 0.0
    for i in range(ne):
        ed += G[i] * ve[i]
    return ed


@njit(cache=True, inline="always")
def _add_damping(nd, ne, s1, s2, off, l, xi, c, fN, ce, ve, alp, bet, alp1, a, b, al, bl, all_, lam, G, dE,
                 Dy, JE, gv):
    """Kelvin-Voigt force -Q_d = l W N_d G (G from _strain_rate, epsdot = G.v): adds gv l c G G^T to JE
    (v part) and the q part to Dy (y-indexed columns). c = W dN_d/depsdot, fN = W N_d,
    ce = W dN_d/deps (linear.axial_law_d; bilateral: c = W EA nu, fN = c epsdot, ce = 0)."""
    for i in range(ne):
        for j in range(ne):
            JE[i, j] += gv * l * c * G[i] * G[j]
    if ce != 0.0:     # N_d through the strain: l ce G (deps/dy), deps/dy = t.da/dy
        tal = 0.0
        for k in range(nd):
            tal += a[k] * al[k] / lam
        for arow in range(ne):
            ga = G[arow]
            if ga == 0.0:
                continue
            for k in range(nd):
                for j in range(4):
                    Dy[arow, off[j] + k] += l * ce * ga * alp[j] * a[k] / lam
            Dy[arow, s2] += l * ce * ga * tal
    # dG/dy contracted with v (dE) and times epsdot (epsd DG): rows of DG built one at a time
    # P = I - t t^T; dt/dx_{i,m} = alpha_i P[:, m] / lam, dt/dl = P al / lam
    tal = 0.0
    for k in range(nd):
        tal += a[k] * al[k] / lam
    # v . dG/dy (dE, length ne in y-indexing) and the term epsd dG_a/dy_c go into Dy
    for i in range(ne):
        dE[i] = 0.0
    for arow in range(ne):
        _dg_row(nd, s1, s2, off, arow, xi, alp, alp1, bet, a, b, al, bl, all_, lam, tal, fN * l, ve[arow],
                Dy, dE)
    for arow in range(ne):
        ga = G[arow]
        if ga == 0.0:
            continue
        for yc in range(ne):
            Dy[arow, yc] += c * l * dE[yc] * ga
        Dy[arow, s2] += fN * ga


@njit(cache=True, inline="always")
def _dg_row(nd, s1, s2, off, arow, xi, alp, alp1, bet, a, b, al, bl, all_, lam, tal, f, va, Dy, dE):
    """Row arow of dG/dy: adds f dG_arow/dy to Dy[arow] and va dG_arow/dy to dE."""
    if arow == s1 or arow == s2:
        cu = -(1.0 - xi) if arow == s1 else -xi      # u = sa al + cu b
        sa = -1.0 if arow == s1 else 1.0
        tu = 0.0
        alu = 0.0      # (P al).u / lam = (al.u - tal t.u) / lam
        for k in range(nd):
            uk = sa * al[k] + cu * b[k]
            tu += a[k] / lam * uk
            alu += al[k] * uk
        dl = (alu - tal * tu) / lam
        for k in range(nd):
            dl += a[k] / lam * (sa * all_[k] + cu * bl[k])
        Dy[arow, s2] += f * dl
        dE[s2] += va * dl
        for m in range(nd):
            tm = a[m] / lam
            Pu = (sa * al[m] + cu * b[m] - tm * tu) / lam
            for i in range(4):
                d = alp[i] * Pu + tm * (sa * alp1[i] + cu * bet[i])
                Dy[arow, off[i] + m] += f * d
                dE[off[i] + m] += va * d
        return
    j = 0
    for jj in range(4):
        if arow >= off[jj] and arow < off[jj] + nd:
            j = jj
    k = arow - off[j]
    tk = a[k] / lam
    Pal = (al[k] - tk * tal) / lam
    dl = alp1[j] * tk + alp[j] * Pal
    Dy[arow, s2] += f * dl
    dE[s2] += va * dl
    for m in range(nd):
        Pkm = ((1.0 if k == m else 0.0) - tk * a[m] / lam) / lam
        for i in range(4):
            d = alp[j] * alp[i] * Pkm
            Dy[arow, off[i] + m] += f * d
            dE[off[i] + m] += va * d
