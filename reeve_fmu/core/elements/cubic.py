"""Cubic ALE-ANCF rope element (Hong & Ren type) in 2D and 3D (docs/theory.md §1.3, §2, §3.1, §3.3).

Local coordinates (Westin order) qe = [r1 (nd), d1 (nd), s1, r2 (nd), d2 (nd), s2], ne = 4 nd + 2:
node positions r, material gradients d = dr/ds (|d| = 1 + eps at the node), material coordinates s.
With xi = (s - s1)/l, l = s2 - s1 (material length),

    r(xi) = h1 r1 + l h2 d1 + h3 r2 + l h4 d2,
    h1 = 1 - 3xi^2 + 2xi^3,  h2 = xi - 2xi^2 + xi^3,  h3 = 3xi^2 - 2xi^3,  h4 = -xi^2 + xi^3.

Everything follows from the element's energies written in xi, including their dependence on l
(Lagrange form; the boundary/flux terms are then automatic, docs/theory.md §2.3, §6 item 5):

    T = 1/2 rhoA l int_0^1 |rdot|^2 dxi,  rdot = N(xi, q) qdot  (material velocity, docs/theory.md §2.1)
        N = [h1 I, l h2 I, -(1-xi) r_s - P, h3 I, l h4 I, -xi r_s + P],  P = dr/dl = h2 d1 + h4 d2
    mass         M = rhoA l int N^T N dxi in closed form (docs/theory.md §2.2; `cubic_mass_gauss` is the
                 4-point Gauss check, exact for the degree-6 integrand)
    Q_v          dT/dq - (dM/dt) qdot, by 4-point Gauss (exact): with the fixed-xi rates
                 dT/dq_i = 1/2 rhoA (dl/dq_i) int |rdot|^2 + rhoA l int rdot.(dN/dq_i qdot),
                 dM/dt qdot = (ldot/l) M qdot + rhoA l int (Ndot^T rdot + N^T Ndot qdot)
    gravity      potential form V_g = -rhoA g.[l (r1 + r2)/2 + l^2 (d1 - d2)/12] (docs/theory.md §2.4)
    elastic      U = l int w dxi, w = 1/2 EA eps^2 + 1/2 EI kappa^2 (5-point Gauss, the forces are
                 the exact gradient of that quadrature), with
                   eps = |r_s| - 1 (engineering strain, tension N = EA eps), and the material
                   curvature (rotation of the tangent per unstretched length)
                   kappa = |r_s x r_s s| / |r_s|^2,  kappa^2 = (|a|^2 |b|^2 - (a.b)^2)/|a|^4,
                   a = r_s, b = r_ss (the same formula in 2D and 3D, smooth at kappa = 0);
                 s rows: dU/ds2 = -dU/ds1 = dU/dl at fixed xi (docs/theory.md §3.1)
    damping      Kelvin-Voigt on the axial strain, Rayleigh function D = 1/2 l int EA nu epsdot^2 dxi
                 with the material strain rate epsdot = t.(d r_s/dt|_xi - w r_ss),
                 w = (1-xi) s1dot + xi s2dot; Q_d = -dD/dqdot (no boundary terms, docs/theory.md §3.3)
    tension-only (the default): the axial force and energy of linear.axial_law at each Gauss point
                 (N = EA eps where taut, 0 where slack, a C2 blend over |eps| < SLACK_STRAIN)

With s1dot = s2dot = 0 and s fixed the element is the standard gradient-deficient ANCF cable: the
e-e block of M is the classical cable matrix, Q_v has zero e-rows (tests/core/test_cubic.py).

Assembly (same convention as linear.py): `cubic_element_at(nd, rhoA, EA, EI, nu, tonly, G, QE, VE,
MEs, QEs, ie)` fills MEs[ie] (ne x ne) and QEs[ie] (ne) = Q_v + Q_g + Q_el + Q_d from QE[ie],
VE[ie] and returns (N1, N2, V): the axial forces EA(|d_i| - 1) at the two nodes and the element's
potential energy (gravity + strain). Neighbouring elements share [r, d, s] at a node (C1 in s).
"""
from __future__ import annotations

import math

import numpy as np

from .._jit import njit
from .linear import axial_law

# Gauss-Legendre on [0, 1]
_G4 = np.polynomial.legendre.leggauss(4)
GX4 = 0.5 * (_G4[0] + 1.0)
GW4 = 0.5 * _G4[1]
_G5 = np.polynomial.legendre.leggauss(5)
GX5 = 0.5 * (_G5[0] + 1.0)
GW5 = 0.5 * _G5[1]


def layout(nd: int):
    """Offsets in qe: (r1, d1, s1, r2, d2, s2) and ne."""
    return 0, nd, 2 * nd, 2 * nd + 1, 3 * nd + 1, 4 * nd + 1, 4 * nd + 2


@njit(cache=True)
def _shape(xi):
    x2 = xi * xi
    x3 = x2 * xi
    return (1.0 - 3.0 * x2 + 2.0 * x3, xi - 2.0 * x2 + x3, 3.0 * x2 - 2.0 * x3, -x2 + x3,
            -6.0 * xi + 6.0 * x2, 1.0 - 4.0 * xi + 3.0 * x2, 6.0 * xi - 6.0 * x2, -2.0 * xi + 3.0 * x2,
            -6.0 + 12.0 * xi, -4.0 + 6.0 * xi, 6.0 - 12.0 * xi, -2.0 + 6.0 * xi)


@njit(cache=True)
def cubic_mass(nd, rhoA, qe, Me):
    """Closed-form mass matrix (docs/theory.md §2.2) into Me (ne x ne)."""
    s1 = 2 * nd
    o2 = 2 * nd + 1
    s2 = 4 * nd + 1
    ne = 4 * nd + 2
    l = qe[s2] - qe[s1]
    m = rhoA * l
    for a in range(ne):
        for b in range(ne):
            Me[a, b] = 0.0
    c = np.empty((4, 4))
    c[0, 0] = 13.0 / 35.0
    c[0, 1] = 11.0 * l / 210.0
    c[0, 2] = 9.0 / 70.0
    c[0, 3] = -13.0 * l / 420.0
    c[1, 1] = l * l / 105.0
    c[1, 2] = 13.0 * l / 420.0
    c[1, 3] = -l * l / 140.0
    c[2, 2] = 13.0 / 35.0
    c[2, 3] = -11.0 * l / 210.0
    c[3, 3] = l * l / 105.0
    off = (0, nd, o2, o2 + nd)     # r1, d1, r2, d2
    for i in range(4):
        for j in range(i, 4):
            v = m * c[i, j]
            for k in range(nd):
                Me[off[i] + k, off[j] + k] = v
                Me[off[j] + k, off[i] + k] = v
    DD = 0.0
    AD = 0.0
    BD = 0.0
    AA = 0.0
    AB = 0.0
    BB = 0.0
    for k in range(nd):
        D = qe[o2 + k] - qe[k]
        A = l * qe[nd + k]
        B = l * qe[o2 + nd + k]
        DD += D * D
        AD += A * D
        BD += B * D
        AA += A * A
        AB += A * B
        BB += B * B
        v = (
            rhoA * (-11.0 * D / 35.0 - 17.0 * A / 105.0 + 11.0 * B / 105.0),   # r1, s1
            rhoA * (-13.0 * D / 70.0 + 13.0 * A / 210.0 - B / 210.0),          # r1, s2
            rhoA * l * (-12.0 * D - 3.0 * A + 4.0 * B) / 210.0,                 # d1, s1
            rhoA * l * (-18.0 * D + 6.0 * A - B) / 420.0,                       # d1, s2
            rhoA * (-13.0 * D / 70.0 - A / 210.0 + 13.0 * B / 210.0),          # r2, s1
            rhoA * (-11.0 * D / 35.0 + 11.0 * A / 105.0 - 17.0 * B / 105.0),   # r2, s2
            rhoA * l * (18.0 * D + A - 6.0 * B) / 420.0,                        # d2, s1
            rhoA * l * (12.0 * D - 4.0 * A + 3.0 * B) / 210.0,                  # d2, s2
        )
        rows = (k, k, nd + k, nd + k, o2 + k, o2 + k, o2 + nd + k, o2 + nd + k)
        for j in range(8):
            col = s1 if j % 2 == 0 else s2
            Me[rows[j], col] = v[j]
            Me[col, rows[j]] = v[j]
    Me[s1, s1] = rhoA * (36.0 * DD + 18.0 * AD - 24.0 * BD + 11.0 * AA - 6.0 * AB + 4.0 * BB) / (105.0 * l)
    Me[s1, s2] = rhoA * (54.0 * DD - 15.0 * AD - 15.0 * BD - AA + 5.0 * AB - BB) / (210.0 * l)
    Me[s2, s1] = Me[s1, s2]
    Me[s2, s2] = rhoA * (36.0 * DD - 24.0 * AD + 18.0 * BD + 4.0 * AA - 6.0 * AB + 11.0 * BB) / (105.0 * l)


@njit(cache=True)
def _N(nd, qe, xi, Nm):
    """Velocity map N (nd x ne) at xi: rdot = N qdot."""
    s1 = 2 * nd
    o2 = 2 * nd + 1
    s2 = 4 * nd + 1
    l = qe[s2] - qe[s1]
    h1, h2, h3, h4, p1, p2, p3, p4, _a, _b, _c, _d = _shape(xi)
    for k in range(nd):
        for j in range(4 * nd + 2):
            Nm[k, j] = 0.0
        rs = (p1 * qe[k] + p3 * qe[o2 + k]) / l + p2 * qe[nd + k] + p4 * qe[o2 + nd + k]
        P = h2 * qe[nd + k] + h4 * qe[o2 + nd + k]
        Nm[k, k] = h1
        Nm[k, nd + k] = l * h2
        Nm[k, o2 + k] = h3
        Nm[k, o2 + nd + k] = l * h4
        Nm[k, s1] = -(1.0 - xi) * rs - P
        Nm[k, s2] = -xi * rs + P


@njit(cache=True)
def cubic_mass_gauss(nd, rhoA, qe, Me):
    """M = rhoA l int_0^1 N^T N dxi by 4-point Gauss (exact): the check of the closed form."""
    ne = 4 * nd + 2
    l = qe[4 * nd + 1] - qe[2 * nd]
    Nm = np.empty((nd, ne))
    for a in range(ne):
        for b in range(ne):
            Me[a, b] = 0.0
    for g in range(4):
        _N(nd, qe, GX4[g], Nm)
        f = rhoA * l * GW4[g]
        for a in range(ne):
            for b in range(ne):
                acc = 0.0
                for k in range(nd):
                    acc += Nm[k, a] * Nm[k, b]
                Me[a, b] += f * acc


@njit(cache=True)
def cubic_kinetic(nd, rhoA, qe, ve):
    """T = 1/2 rhoA l int |rdot|^2 dxi (4-point Gauss, exact)."""
    ne = 4 * nd + 2
    l = qe[4 * nd + 1] - qe[2 * nd]
    Nm = np.empty((nd, ne))
    T = 0.0
    for g in range(4):
        _N(nd, qe, GX4[g], Nm)
        v2 = 0.0
        for k in range(nd):
            rd = 0.0
            for j in range(ne):
                rd += Nm[k, j] * ve[j]
            v2 += rd * rd
        T += 0.5 * rhoA * l * GW4[g] * v2
    return T


@njit(cache=True)
def cubic_qv(nd, rhoA, qe, ve, Me, Q):
    """Quadratic-velocity vector Q_v = dT/dq - (dM/dt) qdot (Lagrange form) into Q (overwrites);
    Me must hold the mass matrix at qe (its product with qdot gives the ldot/l term)."""
    s1 = 2 * nd
    o2 = 2 * nd + 1
    s2 = 4 * nd + 1
    ne = 4 * nd + 2
    l = qe[s2] - qe[s1]
    sd1 = ve[s1]
    sd2 = ve[s2]
    ld = sd2 - sd1
    for j in range(ne):
        Q[j] = 0.0
    W = np.empty((10, nd))   # rs, P, c1, c2, rdot, rsdot, Pdot, c1dot, c2dot, gamma
    for g in range(4):
        xi = GX4[g]
        f = rhoA * l * GW4[g]
        h1, h2, h3, h4, p1, p2, p3, p4, _a, _b, _c, _d = _shape(xi)
        w = (1.0 - xi) * sd1 + xi * sd2
        rd2 = 0.0
        for k in range(nd):
            r1, d1, r2, d2 = qe[k], qe[nd + k], qe[o2 + k], qe[o2 + nd + k]
            v1, e1, v2, e2 = ve[k], ve[nd + k], ve[o2 + k], ve[o2 + nd + k]
            rs = (p1 * r1 + p3 * r2) / l + p2 * d1 + p4 * d2
            P = h2 * d1 + h4 * d2
            c1 = -(1.0 - xi) * rs - P
            c2 = -xi * rs + P
            rdot = h1 * v1 + l * h2 * e1 + h3 * v2 + l * h4 * e2 + c1 * sd1 + c2 * sd2
            rsd = (p1 * v1 + p3 * v2) / l + p2 * e1 + p4 * e2 - ld * (p1 * r1 + p3 * r2) / (l * l)
            Pd = h2 * e1 + h4 * e2
            c1d = -(1.0 - xi) * rsd - Pd
            c2d = -xi * rsd + Pd
            gam = ld * Pd + c1d * sd1 + c2d * sd2
            W[0, k] = rs
            W[1, k] = P
            W[2, k] = c1
            W[3, k] = c2
            W[4, k] = rdot
            W[5, k] = rsd
            W[6, k] = Pd
            W[7, k] = c1d
            W[8, k] = c2d
            W[9, k] = gam
            rd2 += rdot * rdot
        # node rows: rdot.g_i - (Ndot^T rdot)_i - (N^T gamma)_i
        for k in range(nd):
            rdot = W[4, k]
            gam = W[9, k]
            Q[k] += f * (-w * p1 / l * rdot - h1 * gam)
            Q[nd + k] += f * ((-w * p2 + h2 * ld) * rdot - ld * h2 * rdot - l * h2 * gam)
            Q[o2 + k] += f * (-w * p3 / l * rdot - h3 * gam)
            Q[o2 + nd + k] += f * ((-w * p4 + h4 * ld) * rdot - ld * h4 * rdot - l * h4 * gam)
        # s rows: g_s2 = Pdot + w (h1' r1 + h3' r2)/l^2 = -g_s1
        gs = 0.0
        n1 = 0.0
        n2 = 0.0
        for k in range(nd):
            gk = W[6, k] + w * (p1 * qe[k] + p3 * qe[o2 + k]) / (l * l)
            gs += W[4, k] * gk
            n1 += W[7, k] * W[4, k] + W[2, k] * W[9, k]
            n2 += W[8, k] * W[4, k] + W[3, k] * W[9, k]
        Q[s1] += f * (-gs - n1) - 0.5 * rhoA * GW4[g] * rd2
        Q[s2] += f * (gs - n2) + 0.5 * rhoA * GW4[g] * rd2
    # - (ldot/l) M qdot
    if ld != 0.0:
        for a in range(ne):
            acc = 0.0
            for b in range(ne):
                acc += Me[a, b] * ve[b]
            Q[a] -= ld / l * acc


@njit(cache=True)
def cubic_gravity(nd, rhoA, g, qe, Q):
    """Adds the potential-form gravity force to Q; returns V_g."""
    s1 = 2 * nd
    o2 = 2 * nd + 1
    s2 = 4 * nd + 1
    l = qe[s2] - qe[s1]
    V = 0.0
    Qs = 0.0
    for k in range(nd):
        r1, d1, r2, d2 = qe[k], qe[nd + k], qe[o2 + k], qe[o2 + nd + k]
        Q[k] += rhoA * l * g[k] / 2.0
        Q[nd + k] += rhoA * l * l * g[k] / 12.0
        Q[o2 + k] += rhoA * l * g[k] / 2.0
        Q[o2 + nd + k] -= rhoA * l * l * g[k] / 12.0
        Qs += rhoA * g[k] * (0.5 * (r1 + r2) + l * (d1 - d2) / 6.0)
        V -= rhoA * g[k] * (0.5 * l * (r1 + r2) + l * l * (d1 - d2) / 12.0)
    Q[s1] -= Qs
    Q[s2] += Qs
    return V


@njit(cache=True)
def cubic_elastic(nd, EA, EI, nu, tonly, qe, ve, Q):
    """Adds Q_el = -dU/dq and the Kelvin-Voigt force Q_d to Q; returns (U, N1, N2)."""
    s1 = 2 * nd
    o2 = 2 * nd + 1
    s2 = 4 * nd + 1
    l = qe[s2] - qe[s1]
    sd1 = ve[s1]
    sd2 = ve[s2]
    ld = sd2 - sd1
    a = np.empty(nd)
    b = np.empty(nd)
    al = np.empty(nd)    # da/dl
    bl = np.empty(nd)    # db/dl
    ga = np.empty(nd)    # dw/da
    gb = np.empty(nd)    # dw/db
    U = 0.0
    dUdl = 0.0
    for g in range(5):
        xi = GX5[g]
        W = GW5[g]
        h1, h2, h3, h4, p1, p2, p3, p4, q1, q2, q3, q4 = _shape(xi)
        w = (1.0 - xi) * sd1 + xi * sd2
        A = 0.0
        B = 0.0
        C = 0.0
        tbd = 0.0   # t.(rsdot_xi - w b) * lambda  (accumulate a.(...))
        for k in range(nd):
            r1, d1, r2, d2 = qe[k], qe[nd + k], qe[o2 + k], qe[o2 + nd + k]
            a[k] = (p1 * r1 + p3 * r2) / l + p2 * d1 + p4 * d2
            b[k] = (q1 * r1 + q3 * r2) / (l * l) + (q2 * d1 + q4 * d2) / l
            al[k] = -(p1 * r1 + p3 * r2) / (l * l)
            bl[k] = -2.0 * (q1 * r1 + q3 * r2) / (l * l * l) - (q2 * d1 + q4 * d2) / (l * l)
            A += a[k] * a[k]
            B += b[k] * b[k]
            C += a[k] * b[k]
            v1, e1, v2, e2 = ve[k], ve[nd + k], ve[o2 + k], ve[o2 + nd + k]
            rsd = (p1 * v1 + p3 * v2) / l + p2 * e1 + p4 * e2 + ld * al[k]
            tbd += a[k] * (rsd - w * b[k])
        lam = math.sqrt(A)
        eps = lam - 1.0
        epsd = tbd / lam
        N, wv, Nd = axial_law(EA, nu, eps, epsd, tonly)
        K = A * B - C * C
        if K < 0.0:
            K = 0.0
        wv += 0.5 * EI * K / (A * A)
        Ab = 0.0   # dw/da . da/dl + dw/db . db/dl
        for k in range(nd):
            ga[k] = N * a[k] / lam + EI * ((a[k] * B - C * b[k]) / (A * A) - 2.0 * K * a[k] / (A * A * A))
            gb[k] = EI * (b[k] * A - C * a[k]) / (A * A)
            Ab += ga[k] * al[k] + gb[k] * bl[k]
        U += l * W * wv
        dUdl += W * (wv + l * Ab)
        f = l * W
        for k in range(nd):
            # elastic: -dU/de ; damping: -l W Nd t . d(eps)/de = -l W Nd (a/lam) . da/de
            tk = a[k] / lam
            Q[k] -= f * (ga[k] * p1 / l + gb[k] * q1 / (l * l) + Nd * tk * p1 / l)
            Q[nd + k] -= f * (ga[k] * p2 + gb[k] * q2 / l + Nd * tk * p2)
            Q[o2 + k] -= f * (ga[k] * p3 / l + gb[k] * q3 / (l * l) + Nd * tk * p3 / l)
            Q[o2 + nd + k] -= f * (ga[k] * p4 + gb[k] * q4 / l + Nd * tk * p4)
        # damping s rows: d(eps)/ds1|_s = -t.da/dl - (1-xi) t.b, d(eps)/ds2|_s = t.da/dl - xi t.b
        tal = 0.0
        tb = 0.0
        for k in range(nd):
            tal += a[k] * al[k] / lam
            tb += a[k] * b[k] / lam
        Q[s1] -= f * Nd * (-tal - (1.0 - xi) * tb)
        Q[s2] -= f * Nd * (tal - xi * tb)
    Q[s1] += dUdl
    Q[s2] -= dUdl
    n1 = 0.0
    n2 = 0.0
    for k in range(nd):
        n1 += qe[nd + k] * qe[nd + k]
        n2 += qe[o2 + nd + k] * qe[o2 + nd + k]
    N1 = EA * (math.sqrt(n1) - 1.0)
    N2 = EA * (math.sqrt(n2) - 1.0)
    if tonly:
        N1 = max(N1, 0.0)
        N2 = max(N2, 0.0)
    return U, N1, N2


@njit(cache=True)
def cubic_element_at(nd, rhoA, EA, EI, nu, tonly, G, QE, VE, MEs, QEs, ie):
    """Fill MEs[ie] and QEs[ie] (= Q_v + Q_g + Q_el + Q_d) for element ie from QE[ie], VE[ie];
    G[ie] is the gravity vector (nd). Returns (N1, N2, V): nodal axial forces and the potential
    energy (gravity + strain). A non-positive material length returns N1 = N2 = 0, V = nan (the
    caller stops with an event)."""
    qe = QE[ie]
    ve = VE[ie]
    Me = MEs[ie]
    Q = QEs[ie]
    if not QE[ie, 4 * nd + 1] - QE[ie, 2 * nd] > 0.0:
        return 0.0, 0.0, math.nan
    cubic_mass(nd, rhoA, qe, Me)
    cubic_qv(nd, rhoA, qe, ve, Me, Q)
    Vg = cubic_gravity(nd, rhoA, G[ie], qe, Q)
    U, N1, N2 = cubic_elastic(nd, EA, EI, nu, tonly, qe, ve, Q)
    return N1, N2, U + Vg


@njit(cache=True)
def cubic_element(nd, rhoA, EA, EI, nu, tonly, g, qe, ve, Me, Qe):
    """One element from plain arrays (tests, tools); see cubic_element_at."""
    ne = 4 * nd + 2
    QE = qe.reshape((1, ne)).copy()
    VE = ve.reshape((1, ne)).copy()
    MEs = np.empty((1, ne, ne))
    QEs = np.empty((1, ne))
    res = cubic_element_at(nd, rhoA, EA, EI, nu, tonly, g.reshape((1, nd)), QE, VE, MEs, QEs, 0)
    Me[:, :] = MEs[0]
    Qe[:] = QEs[0]
    return res


def element_arrays(nd: int):
    """Work arrays for one element."""
    ne = 4 * nd + 2
    return np.zeros((ne, ne)), np.zeros(ne)
