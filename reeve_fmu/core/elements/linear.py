"""Linear two-node ALE rope element in 1D, 2D and 3D (docs/theory.md §1.2, §2.2-2.4, §3.1, §3.3).

Local coordinates qe = [r1 (nd), r2 (nd), s1, s2]: node positions and material coordinates. In 1D the
position is the scalar coordinate along the span's fixed line. Everything is derived from the element's
kinetic and potential energy written in xi = (s - s1)/l including the l-dependence (Lagrange form),
so the boundary (momentum/energy flux) terms are kept and energy is conserved across kinks and
zero-length wraps (docs/theory.md §2.3, §6 item 5).

    mass            closed form, exact material mass rhoA*l
    Q_v             dT/dq - dM/dt qdot, material part + boundary part B_e
    gravity         potential form V = -rhoA l g.(r1+r2)/2  (+ rhoA l C for 1D lines off the origin)
    elastic         engineering strain eps = lambda - 1, N = EA eps; tension-only (default) or bilateral
    damping         Kelvin-Voigt N_d = EA nu deps/dt from a Rayleigh function (no boundary terms)
"""
from __future__ import annotations

import math

import numpy as np

from .._jit import njit



SLACK_STRAIN = 1e-6   # widest half-width d of the tension-only law's blend band (strain)
SLACK_FORCE = 1.0     # N: the band's widest force EA d, so a stiff rope under light load is on the linear law


@njit(cache=True, inline="always")
def slack_band(EA):
    """Half-width d of the tension-only law's blend band of a rope of axial stiffness EA: SLACK_STRAIN,
    narrowed to SLACK_FORCE / EA for a stiff rope (without it a rope of EA 1e9 N would sit inside the
    band, softer than EA, under loads up to 1 kN)."""
    if EA * SLACK_STRAIN > SLACK_FORCE:
        return SLACK_FORCE / EA
    return SLACK_STRAIN


@njit(cache=True, inline="always")
def chord(QE, ie, nd):
    """|r_2 - r_1| of linear element ie from its coordinates QE[ie] = [r_1, r_2, s_1, s_2]."""
    dist2 = 0.0
    for k in range(nd):
        dk = QE[ie, nd + k] - QE[ie, k]
        dist2 += dk * dk
    return math.sqrt(dist2)


@njit(cache=True, inline="always")
def smooth_positive(x, d):
    """(p, dp/dx): the positive part of x blended over |x| < d by a C2 polynomial. p = x exactly
    (the same float) for x >= d, 0 for x <= -d, d y^3 (2 - y) with y = (x + d)/(2 d) between; its
    slope 3 y^2 - 2 y^3 runs from 0 to 1 with zero curvature at both ends, and p >= max(x, 0)."""
    if x >= d:
        return x, 1.0
    if x <= -d:
        return 0.0, 0.0
    y = (x + d) / (2.0 * d)
    y2 = y * y
    return d * y2 * y * (2.0 - y), y2 * (3.0 - 2.0 * y)


@njit(cache=True, inline="always")
def axial_law_d(EA, nu, eps, epsdot, tonly):
    """Axial force of a rope section and its derivatives: (N elastic, w energy density, N_d damping
    part, dN/deps, dN_d/deps, dN_d/depsdot).

    Bilateral (tonly false): N = EA eps, w = EA eps^2/2, N_d = EA nu deps/dt.
    Tension-only: N = EA p(eps), p = smooth_positive over d = slack_band(EA) (a bare max(., 0) makes
    Newton cycle between the slack and the taut branch), with its energy w = EA int p deps:
    EA eps^2/2 for eps >= d, EA d^2 (y^4 - 2 y^5/5 - 1/10) in the band, -EA d^2/10 below (C2 in eps).
    The damper acts in proportion to the spring's slope p', and the total force
    f = N + EA nu p' deps/dt is smoothly clipped at 0 (a rope cannot push) over a width
    N EA d / (N + 2 EA d): at most EA d and at most N/2, so a force without damping (f = N) is never
    clipped and the law is conservative with the energy w. Where the rope is taut (eps >= d and
    f >= EA d) it returns the bilateral expressions: a rope that stays taut runs bit for bit as a
    bilateral one."""
    if not tonly:
        return EA * eps, 0.5 * EA * eps * eps, EA * nu * epsdot, EA, 0.0, EA * nu
    d = slack_band(EA)
    dF = EA * d
    if eps >= d and EA * eps + EA * nu * epsdot >= dF:
        return EA * eps, 0.5 * EA * eps * eps, EA * nu * epsdot, EA, 0.0, EA * nu
    p, s = smooth_positive(eps, d)
    N = EA * p
    if eps >= d:
        w = 0.5 * EA * eps * eps
        ds = 0.0
    elif eps > -d:
        y = (eps + d) / (2.0 * d)
        y4 = y * y * y * y
        w = EA * d * d * (y4 - 0.4 * y4 * y - 0.1)
        ds = 3.0 * y * (1.0 - y) / d      # dp'/deps
    else:
        w = -0.1 * EA * d * d
        ds = 0.0
    if not N > 0.0:
        return 0.0, w, 0.0, 0.0, 0.0, 0.0
    c = EA * nu
    f = N + c * epsdot * s
    h = N * dF / (N + 2.0 * dF)                  # the clip's width
    F, g = smooth_positive(f, h)
    gh = (F - f * g) / h                         # dF/dh
    dN = EA * s
    dh = 2.0 * dF * dF / ((N + 2.0 * dF) * (N + 2.0 * dF)) * dN
    return N, w, F - N, dN, g * (dN + c * epsdot * ds) + gh * dh - dN, g * c * s


@njit(cache=True, inline="always")
def axial_law(EA, nu, eps, epsdot, tonly):
    """(N elastic, w energy density, N_d damping part) of axial_law_d."""
    N, w, Nd, dN, dNe, dNed = axial_law_d(EA, nu, eps, epsdot, tonly)
    return N, w, Nd


@njit(cache=True, inline="always")
def linear_element_at(nd, rhoA, EA, nu, tonly, G, C, QE, VE, MEs, QEs, ie):
    """Fill MEs[ie] (ne x ne) and QEs[ie] (ne) for element ie from QE[ie], VE[ie] (indexing, not slicing:
    views cost reference counting in the hot loop); return (N_elastic, N_damping, lambda, w, V).

    G[ie]: gravity in local coordinates (nd); C: g.r_perp for 1D lines (0 otherwise); ne = 2 nd + 2.
    V is the element's potential energy (gravity + strain). Raises nothing: a non-positive material
    length returns lambda = -1 so the caller can stop with a clear event.
    """
    i1 = 2 * nd
    i2 = 2 * nd + 1
    l = QE[ie, i2] - QE[ie, i1]
    if not l > 0.0:
        return 0.0, 0.0, -1.0, 0.0, 0.0
    sd1 = VE[ie, i1]
    sd2 = VE[ie, i2]
    ldot = sd2 - sd1
    dist = chord(QE, ie, nd)
    lam = dist / l
    inv_l = 1.0 / l

    # --- mass matrix (closed form) -----------------------------------------------------------
    m = rhoA * l
    for a in range(2 * nd + 2):
        for b in range(2 * nd + 2):
            MEs[ie, a, b] = 0.0
    dd = lam * lam  # d.d
    for k in range(nd):
        dk = (QE[ie, nd + k] - QE[ie, k]) * inv_l
        MEs[ie, k, k] = m / 3.0
        MEs[ie, nd + k, nd + k] = m / 3.0
        MEs[ie, k, nd + k] = m / 6.0
        MEs[ie, nd + k, k] = m / 6.0
        MEs[ie, k, i1] = -m * dk / 3.0
        MEs[ie, k, i2] = -m * dk / 6.0
        MEs[ie, nd + k, i1] = -m * dk / 6.0
        MEs[ie, nd + k, i2] = -m * dk / 3.0
        MEs[ie, i1, k] = MEs[ie, k, i1]
        MEs[ie, i2, k] = MEs[ie, k, i2]
        MEs[ie, i1, nd + k] = MEs[ie, nd + k, i1]
        MEs[ie, i2, nd + k] = MEs[ie, nd + k, i2]
    MEs[ie, i1, i1] = m * dd / 3.0
    MEs[ie, i2, i2] = m * dd / 3.0
    MEs[ie, i1, i2] = m * dd / 6.0
    MEs[ie, i2, i1] = m * dd / 6.0

    # --- quadratic-velocity vector, Lagrange form -------------------------------------------
    c3 = m / 3.0
    w1 = 2.0 * sd1 + sd2
    w2 = sd1 + 2.0 * sd2
    d_dd = 0.0   # d . d_dot
    d_rA = 0.0   # d . rdot_A
    d_rB = 0.0
    rA2 = 0.0
    rB2 = 0.0
    gm = C       # g . (r1 + r2)/2 (+ C)
    rel = 0.0    # t . (rdot2 - rdot1)
    for k in range(nd):
        dk = (QE[ie, nd + k] - QE[ie, k]) * inv_l
        ddk = (VE[ie, nd + k] - VE[ie, k] - dk * ldot) * inv_l
        rAk = VE[ie, k] - dk * sd1
        rBk = VE[ie, nd + k] - dk * sd2
        d_dd += dk * ddk
        d_rA += dk * rAk
        d_rB += dk * rBk
        rA2 += rAk * rAk
        rB2 += rBk * rBk
        QEs[ie, k] = c3 * ddk * w1 + rhoA * rAk * sd1 + 0.5 * m * G[ie, k]
        QEs[ie, nd + k] = c3 * ddk * w2 - rhoA * rBk * sd2 + 0.5 * m * G[ie, k]
        gm += 0.5 * G[ie, k] * (QE[ie, k] + QE[ie, nd + k])
        if dist > 0.0:
            rel += (QE[ie, nd + k] - QE[ie, k]) / dist * (VE[ie, nd + k] - VE[ie, k])
    QEs[ie, i1] = -c3 * d_dd * w1 + rhoA * (-sd1 * d_rA - 0.5 * rA2) - rhoA * gm
    QEs[ie, i2] = -c3 * d_dd * w2 + rhoA * (sd2 * d_rB + 0.5 * rB2) + rhoA * gm

    # --- axial elastic and Kelvin-Voigt forces ----------------------------------------------
    eps = lam - 1.0
    N, w, Nd = axial_law(EA, nu, eps, rel * inv_l - lam * ldot * inv_l, tonly)
    Ntot = N + Nd
    if dist > 0.0:
        for k in range(nd):
            tk = (QE[ie, nd + k] - QE[ie, k]) / dist
            QEs[ie, k] += Ntot * tk
            QEs[ie, nd + k] -= Ntot * tk
    esh = N * lam - w + Nd * lam   # Eshelby (configurational) force, + damping part
    QEs[ie, i1] -= esh
    QEs[ie, i2] += esh
    V = l * w - m * gm
    return N, Nd, lam, w, V


@njit(cache=True, inline="always")
def linear_element_1d_at(rhoA, EA, nu, tonly, g, C, QE, VE, MEs, QEs, ie):
    """linear_element_at for nd = 1 in scalar form (same formulas, no loops): the 1D model is the
    workhorse of trip simulations, and this path is about twice as fast."""
    x1 = QE[ie, 0]
    x2 = QE[ie, 1]
    l = QE[ie, 3] - QE[ie, 2]
    if not l > 0.0:
        return 0.0, 0.0, -1.0, 0.0, 0.0
    v1 = VE[ie, 0]
    v2 = VE[ie, 1]
    sd1 = VE[ie, 2]
    sd2 = VE[ie, 3]
    inv_l = 1.0 / l
    D = x2 - x1
    dist = abs(D)
    t = 1.0 if D > 0.0 else (-1.0 if D < 0.0 else 0.0)
    d = D * inv_l
    lam = dist * inv_l
    m = rhoA * l
    m3 = m / 3.0
    m6 = m / 6.0
    MEs[ie, 0, 0] = m3
    MEs[ie, 1, 1] = m3
    MEs[ie, 0, 1] = m6
    MEs[ie, 1, 0] = m6
    MEs[ie, 0, 2] = MEs[ie, 2, 0] = -m3 * d
    MEs[ie, 0, 3] = MEs[ie, 3, 0] = -m6 * d
    MEs[ie, 1, 2] = MEs[ie, 2, 1] = -m6 * d
    MEs[ie, 1, 3] = MEs[ie, 3, 1] = -m3 * d
    MEs[ie, 2, 2] = MEs[ie, 3, 3] = m3 * d * d
    MEs[ie, 2, 3] = MEs[ie, 3, 2] = m6 * d * d
    ldot = sd2 - sd1
    dd = (v2 - v1 - d * ldot) * inv_l
    rA = v1 - d * sd1
    rB = v2 - d * sd2
    w1 = 2.0 * sd1 + sd2
    w2 = sd1 + 2.0 * sd2
    gm = C + 0.5 * g * (x1 + x2)
    q0 = m3 * dd * w1 + rhoA * rA * sd1 + 0.5 * m * g
    q1 = m3 * dd * w2 - rhoA * rB * sd2 + 0.5 * m * g
    q2 = -m3 * d * dd * w1 + rhoA * (-sd1 * d * rA - 0.5 * rA * rA) - rhoA * gm
    q3 = -m3 * d * dd * w2 + rhoA * (sd2 * d * rB + 0.5 * rB * rB) + rhoA * gm
    eps = lam - 1.0
    N, w, Nd = axial_law(EA, nu, eps, (t * (v2 - v1) - lam * ldot) * inv_l, tonly)
    Nt = (N + Nd) * t
    esh = N * lam - w + Nd * lam
    QEs[ie, 0] = q0 + Nt
    QEs[ie, 1] = q1 - Nt
    QEs[ie, 2] = q2 - esh
    QEs[ie, 3] = q3 + esh
    return N, Nd, lam, w, l * w - m * gm


@njit(cache=True)
def linear_element(nd, rhoA, EA, nu, tonly, g, C, qe, ve, Me, Qe):
    """One element from plain arrays (tests, tools); see linear_element_at."""
    ne = 2 * nd + 2
    QE = qe.reshape((1, ne)).copy()
    VE = ve.reshape((1, ne)).copy()
    MEs = np.empty((1, ne, ne))
    QEs = np.empty((1, ne))
    res = linear_element_at(nd, rhoA, EA, nu, tonly, g.reshape((1, nd)), C, QE, VE, MEs, QEs, 0)
    Me[:, :] = MEs[0]
    Qe[:] = QEs[0]
    return res


@njit(cache=True)
def end_tension(nd, rhoA, QE, VE, ae, MEs, QEs, ie, end):
    """Rope force at an element end (end = 0: node 1, 1: node 2), from the element's consistent nodal
    force minus inertia and minus the convective momentum flux rhoA rdot s_dot (which the support
    takes, not the rope). Exact static end tensions for a hanging span, see tests."""
    i1 = 2 * nd
    i2 = 2 * nd + 1
    l = QE[ie, i2] - QE[ie, i1]
    dist = chord(QE, ie, nd)
    if dist <= 0.0 or l <= 0.0:
        return 0.0
    ne = 2 * nd + 2
    off = 0 if end == 0 else nd
    sdot = VE[ie, i1] if end == 0 else VE[ie, i2]
    T = 0.0
    for k in range(nd):
        tk = (QE[ie, nd + k] - QE[ie, k]) / dist
        f = QEs[ie, off + k]
        for b in range(ne):
            f -= MEs[ie, off + k, b] * ae[b]
        dk = (QE[ie, nd + k] - QE[ie, k]) / l
        rdot_mat = VE[ie, off + k] - dk * sdot
        if end == 0:
            f -= rhoA * rdot_mat * sdot
            T += tk * f
        else:
            f += rhoA * rdot_mat * sdot
            T -= tk * f
    return T


@njit(cache=True, inline="always")
def reported_tension(nd, EA, tonly, QE, ie, T):
    """The rope force an output reports at an element end, T its end_tension. A stretched span
    (|r2 - r1| > l) reports T, or 0 where T is not positive (the span's weight and inertia share at
    the lower end of a nearly slack span: no rope force). A span that is not stretched is slack: 0
    for a tension-only rope; a bilateral rope pushed into compression reports its axial force
    EA eps < 0, which the model did apply (the verdicts FAIL it)."""
    i1 = 2 * nd
    l = QE[ie, i1 + 1] - QE[ie, i1]
    dist2 = 0.0
    for k in range(nd):
        dk = QE[ie, nd + k] - QE[ie, k]
        dist2 += dk * dk
    if l > 0.0 and dist2 > l * l:            # stretched (no square root on the common path)
        return T if T > 0.0 else 0.0
    if tonly or l <= 0.0:
        return 0.0
    return EA * (math.sqrt(dist2) / l - 1.0)


def element_arrays(nd: int):
    """Work arrays for one element."""
    ne = 2 * nd + 2
    return np.zeros((ne, ne)), np.zeros(ne)
