"""ALE torsion field of a straight rope span and the axial-torsion coupling laws (docs/theory.md §1.5, §3.2).

Kinematics (§1.5). Every rope node i carries a torsion angle phi_i, measured from a reference frame
attached to the node's support: a unit vector v_i fixed to the support body (a sheave's or drum's axis
a, or a body-fixed vector at a rope end), projected on the plane normal to the span tangent t. The
method writes the sheave frame as n = a x t; that is the projection of a turned by -90 deg about t,
a constant offset that cancels in every difference below (and the twist-free reference absorbs it).
A straight span from node A to node B transports a frame without twist, so the frames' relative
rotation about t is

    Delta_AB = atan2(Y, X),  Y = t.(v_A x v_B),  X = v_A.v_B - (v_A.t)(v_B.t)

and the twist per unstretched length is uniform in the span:

    kappa_t = (phi_B + Delta_AB - phi_A) / l,       l = s_B - s_A  (material length).

atan2 jumps by 2 pi; `transport_angle` returns the branch nearest to a given previous value so a
continuation follows Delta through any number of turns.

Constitutive laws (§3.2), per rope: EA [N], diameter d [m], k0, k1 [-], GJ0 [N m^2]. Tension
S = dw/deps and rope torque M = dw/dkappa for the energy laws:

    LAW_COSTELLO   w = 1/2 EA eps^2 + k0 d EA eps kappa + 1/2 GJ0 kappa^2
                   S = EA eps + k0 d EA kappa,   M = k0 d EA eps + GJ0 kappa
                   (linear, reciprocal coupling C = k0 d EA; positive definite iff GJ0 EA > C^2)
    LAW_FEYRER     w = 1/2 EA eps^2 + EA d eps (k0 kappa + 1/2 k1 d kappa^2) + 1/2 GJ0 kappa^2
                   S = EA eps + EA d (k0 kappa + 1/2 k1 d kappa^2)
                   M = EA eps d (k0 + k1 d kappa) + GJ0 kappa   (= S d k(kappa) + ..., k = k0 + k1 d kappa)
                   (k1 = 0 is COSTELLO)
    LAW_TORQUE_FACTOR  (not an energy; the engineering check of docs/reference-sets.md §5.3)
                   S = EA eps,   M = d S (k0 + k1 d kappa) + GJ0 kappa

The span's internal virtual work is  delta W = S delta|D| + M delta(phi_B + Delta - phi_A) + E delta l
(D = r_B - r_A), with the configurational (Eshelby) force E = dU/dl at fixed D and twist angle:
E = w - S lambda - M kappa for the energy laws (lambda = 1 + eps), so that the generalized forces are
exactly -grad(l w). For the torque-factor law E = 1/2 EA eps^2 - S lambda (the axial part only), so a
frictionless sheave's s-equation stays the plain tension balance S_a = S_b.
"""
from __future__ import annotations

import math

import numpy as np

from .._jit import njit

LAW_TORQUE_FACTOR = 0
LAW_COSTELLO = 1
LAW_FEYRER = 2
LAWS = {"torque-factor": LAW_TORQUE_FACTOR, "costello": LAW_COSTELLO, "feyrer": LAW_FEYRER}


@njit(cache=True, inline="always")
def coupling_law(law, EA, d, k0, k1, GJ0, eps, kap):
    """(w, S, M, E) for strain eps and twist kap (rad/m); E is the configurational force dU/dl at
    fixed chord and twist angle (see the module docstring). w is the energy density [J/m] (for the
    torque-factor law its axial + GJ0 part, which is not a potential of M)."""
    lam = 1.0 + eps
    if law == LAW_TORQUE_FACTOR:
        S = EA * eps
        M = d * S * (k0 + k1 * d * kap) + GJ0 * kap
        wa = 0.5 * EA * eps * eps
        return wa + 0.5 * GJ0 * kap * kap, S, M, wa - S * lam
    c = k0 * kap
    c2 = 0.5 * k1 * d * kap * kap
    if law == LAW_COSTELLO:
        c2 = 0.0
    w = 0.5 * EA * eps * eps + EA * d * eps * (c + c2) + 0.5 * GJ0 * kap * kap
    S = EA * eps + EA * d * (c + c2)
    kk = k1 if law == LAW_FEYRER else 0.0
    M = EA * eps * d * (k0 + kk * d * kap) + GJ0 * kap
    return w, S, M, w - S * lam - M * kap


@njit(cache=True, inline="always")
def transport_angle(t0, t1, t2, a0, a1, a2, b0, b1, b2, ref):
    """Delta = rotation about unit t from the projection of v_A = a to that of v_B = b, on the
    2-pi branch nearest to ref."""
    # Y = t.(a x b), X = a.b - (a.t)(b.t)
    cx = a1 * b2 - a2 * b1
    cy = a2 * b0 - a0 * b2
    cz = a0 * b1 - a1 * b0
    Y = t0 * cx + t1 * cy + t2 * cz
    at = a0 * t0 + a1 * t1 + a2 * t2
    bt = b0 * t0 + b1 * t1 + b2 * t2
    X = a0 * b0 + a1 * b1 + a2 * b2 - at * bt
    D = math.atan2(Y, X)
    return D + 2.0 * math.pi * math.floor((ref - D) / (2.0 * math.pi) + 0.5)


@njit(cache=True)
def transport_angle_grad(t, a, b, ref, gt, ga, gb):
    """Delta (as transport_angle) and its gradients with respect to t, v_A = a, v_B = b treated as
    independent vectors (gt, ga, gb filled). Chain dt/dD = (I - t t^T)/|D| for a chord D."""
    cx = a[1] * b[2] - a[2] * b[1]
    cy = a[2] * b[0] - a[0] * b[2]
    cz = a[0] * b[1] - a[1] * b[0]
    Y = t[0] * cx + t[1] * cy + t[2] * cz
    at = a[0] * t[0] + a[1] * t[1] + a[2] * t[2]
    bt = b[0] * t[0] + b[1] * t[1] + b[2] * t[2]
    X = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] - at * bt
    D = math.atan2(Y, X)
    D += 2.0 * math.pi * math.floor((ref - D) / (2.0 * math.pi) + 0.5)
    q = 1.0 / (X * X + Y * Y)
    fx = -Y * q   # dDelta/dX
    fy = X * q    # dDelta/dY
    # dY/dt = a x b;  dX/dt = -(a.t) b - (b.t) a
    gt[0] = fy * cx + fx * (-at * b[0] - bt * a[0])
    gt[1] = fy * cy + fx * (-at * b[1] - bt * a[1])
    gt[2] = fy * cz + fx * (-at * b[2] - bt * a[2])
    # dY/da = b x t;  dX/da = b - (b.t) t
    ga[0] = fy * (b[1] * t[2] - b[2] * t[1]) + fx * (b[0] - bt * t[0])
    ga[1] = fy * (b[2] * t[0] - b[0] * t[2]) + fx * (b[1] - bt * t[1])
    ga[2] = fy * (b[0] * t[1] - b[1] * t[0]) + fx * (b[2] - bt * t[2])
    # dY/db = t x a;  dX/db = a - (a.t) t
    gb[0] = fy * (t[1] * a[2] - t[2] * a[1]) + fx * (a[0] - at * t[0])
    gb[1] = fy * (t[2] * a[0] - t[0] * a[2]) + fx * (a[1] - at * t[1])
    gb[2] = fy * (t[0] * a[1] - t[1] * a[0]) + fx * (a[2] - at * t[2])
    return D


@njit(cache=True, inline="always")
def twist(phiA, phiB, delta, l):
    """Uniform twist per unstretched length of a span: (phi_B + Delta - phi_A)/l [rad/m]."""
    return (phiB + delta - phiA) / l


@njit(cache=True)
def torsion_span(law, EA, rhoA, d, k0, k1, GJ0, g, rA, rB, sA, sB, phiA, phiB, vA, vB, dref, grad, wk):
    """Potential-energy gradient of one straight span: a linear ALE element (docs/theory.md §1.2, statics:
    elastic + potential-form gravity) with the torsion field of §1.5.

    grad (16) is filled with dU/d[rA(3), rB(3), sA, sB, phiA, phiB, vA(3), vB(3)] (for the
    torque-factor law: minus the generalized internal + gravity forces, the same expressions).
    Returns (S, M, eps, kappa, Delta, V) with V = l w - rhoA l g.(rA + rB)/2. A non-positive
    material length or chord returns eps = nan. wk: work array of at least 12 floats (no allocation
    in the caller's Newton loop).
    """
    l = sB - sA
    D0 = rB[0] - rA[0]
    D1 = rB[1] - rA[1]
    D2 = rB[2] - rA[2]
    dist = math.sqrt(D0 * D0 + D1 * D1 + D2 * D2)
    if not (l > 0.0 and dist > 0.0):
        for k in range(16):
            grad[k] = 0.0
        return 0.0, 0.0, math.nan, 0.0, 0.0, 0.0
    t = wk[0:3]
    gt = wk[3:6]
    ga = wk[6:9]
    gb = wk[9:12]
    t[0] = D0 / dist
    t[1] = D1 / dist
    t[2] = D2 / dist
    delta = transport_angle_grad(t, vA, vB, dref, gt, ga, gb)
    lam = dist / l
    eps = lam - 1.0
    kap = (phiB + delta - phiA) / l
    w, S, M, E = coupling_law(law, EA, d, k0, k1, GJ0, eps, kap)
    # dDelta/dD = (I - t t^T) gt / dist
    tg = t[0] * gt[0] + t[1] * gt[1] + t[2] * gt[2]
    gmid = 0.0
    for k in range(3):
        dU = S * t[k] + M * (gt[k] - tg * t[k]) / dist
        grav = -0.5 * rhoA * l * g[k]
        grad[k] = -dU + grav
        grad[3 + k] = dU + grav
        grad[10 + k] = M * ga[k]
        grad[13 + k] = M * gb[k]
        gmid += g[k] * 0.5 * (rA[k] + rB[k])
    dUdl = E - rhoA * gmid
    grad[6] = -dUdl
    grad[7] = dUdl
    grad[8] = -M
    grad[9] = M
    return S, M, eps, kap, delta, l * w - rhoA * l * gmid


# ------------------------------------------------------------------ the torsion field in dynamics
# The dynamic engine's linear element already carries the axial part (tension EA eps, gravity, the
# Kelvin-Voigt damping, the ALE inertia). A torsion rope adds, per span, the difference between its
# coupling law and that axial part: the same generalized forces as torsion_span with the axial law
# subtracted, so nothing is counted twice.

@njit(cache=True)
def torsion_extra(law, EA, d, k0, k1, GJ0, rA, rB, sA, sB, phiA, phiB, vA, vB, dref, grad, wk):
    """grad (16) = dU_t/d[rA(3), rB(3), sA, sB, phiA, phiB, vA(3), vB(3)] of the torsion part
    U_t = l (w - EA eps^2 / 2) of one span (for the torque-factor law: minus its generalized forces).
    Returns (M, kappa, Delta); a span of non-positive length or chord returns zeros (the element
    reports it)."""
    l = sB - sA
    D0, D1, D2 = rB[0] - rA[0], rB[1] - rA[1], rB[2] - rA[2]
    dist = math.sqrt(D0 * D0 + D1 * D1 + D2 * D2)
    if not (l > 0.0 and dist > 0.0):
        for k in range(16):
            grad[k] = 0.0
        return 0.0, 0.0, dref
    t = wk[0:3]
    gt = wk[3:6]
    ga = wk[6:9]
    gb = wk[9:12]
    t[0], t[1], t[2] = D0 / dist, D1 / dist, D2 / dist
    delta = transport_angle_grad(t, vA, vB, dref, gt, ga, gb)
    eps = dist / l - 1.0
    kap = (phiB + delta - phiA) / l
    w, S, M, E = coupling_law(law, EA, d, k0, k1, GJ0, eps, kap)
    S0 = EA * eps
    dS = S - S0
    dE = E - (0.5 * EA * eps * eps - S0 * (1.0 + eps))
    tg = t[0] * gt[0] + t[1] * gt[1] + t[2] * gt[2]
    for k in range(3):
        dU = dS * t[k] + M * (gt[k] - tg * t[k]) / dist
        grad[k] = -dU
        grad[3 + k] = dU
        grad[10 + k] = M * ga[k]
        grad[13 + k] = M * gb[k]
    grad[6] = -dE
    grad[7] = dE
    grad[8] = -M
    grad[9] = M
    return M, kap, delta


@njit(cache=True, inline="always")
def _frame(K, W, k, e, out):
    """Frame vector of end e of torsion span k in world axes: the body-axis vector turned by its
    body's current rotation (bodies.nl_update has set W.nl_BR)."""
    v0, v1, v2 = K.tq_v0[k, 3 * e], K.tq_v0[k, 3 * e + 1], K.tq_v0[k, 3 * e + 2]
    b = K.tq_vb[k, e]
    if b >= 0 and K.nl_bk[b] != 1:
        R = W.nl_BR
        a0, a1, a2, c, s = R[b, 0], R[b, 1], R[b, 2], R[b, 3], R[b, 4]
        dd = (a0 * v0 + a1 * v1 + a2 * v2) * (1.0 - c)
        v0, v1, v2 = (v0 * c + (a1 * v2 - a2 * v1) * s + a0 * dd, v1 * c + (a2 * v0 - a0 * v2) * s + a1 * dd,
                      v2 * c + (a0 * v1 - a1 * v0) * s + a2 * dd)
    out[0], out[1], out[2] = v0, v1, v2


@njit(cache=True, inline="always")
def _frame_force(K, q, b, v, g, Q):
    """Generalized force of dU = g . dv on the rotation coordinates of body b, with dv = dtheta x v:
    dU = dtheta . (v x g); a rotation vector phi has dtheta = T(phi) dphi, an angle about a fixed
    axis dtheta = axis d(angle)."""
    m0 = v[1] * g[2] - v[2] * g[1]
    m1 = v[2] * g[0] - v[0] * g[2]
    m2 = v[0] * g[1] - v[1] * g[0]
    bq = K.nl_bq
    if K.nl_bk[b] == 2:
        p0, p1, p2 = q[bq[b, 4]], q[bq[b, 5]], q[bq[b, 6]]
        th2 = p0 * p0 + p1 * p1 + p2 * p2
        if th2 < 1e-8:
            a = 0.5 - th2 / 24.0
            bb = 1.0 / 6.0 - th2 / 120.0
        else:
            th = math.sqrt(th2)
            a = (1.0 - math.cos(th)) / th2
            bb = (th - math.sin(th)) / (th2 * th)
        # T = I + a phi^ + bb (phi phi^T - th2 I);  dU/dphi = T^T m
        pm = p0 * m0 + p1 * m1 + p2 * m2
        c0 = p1 * m2 - p2 * m1        # phi x m;  (phi^)^T m = -phi x m
        c1 = p2 * m0 - p0 * m2
        c2 = p0 * m1 - p1 * m0
        f = 1.0 - bb * th2
        Q[bq[b, 4]] -= f * m0 - a * c0 + bb * p0 * pm
        Q[bq[b, 5]] -= f * m1 - a * c1 + bb * p1 * pm
        Q[bq[b, 6]] -= f * m2 - a * c2 + bb * p2 * pm
    elif K.nl_bk[b] == 0 and bq[b, 3] >= 0:
        Q[bq[b, 3]] -= K.nl_bax[b, 0] * m0 + K.nl_bax[b, 1] * m1 + K.nl_bax[b, 2] * m2


@njit(cache=True, inline="always")
def _span_ends(K, W, q, k, vA, vB):
    """Torsion span k's end frames (vA, vB) and twist coordinates: (jA, jB) (-1: fixed) and their
    angles."""
    _frame(K, W, k, 0, vA)
    _frame(K, W, k, 1, vB)
    jA, jB = K.tq_phi[k, 0], K.tq_phi[k, 1]
    phiA = q[jA] if jA >= 0 else K.tq_phic[k, 0]
    phiB = q[jB] if jB >= 0 else K.tq_phic[k, 1]
    return jA, jB, phiA, phiB


@njit(cache=True)
def torsion_terms(K, W, QE, q, Q):
    """Add the torsion part of every torsion span (torsion_extra) to Q: its node and material
    coordinate forces through the element's map (like the element's own forces), the torques on
    the twist coordinates and the moments on the bodies that carry the frames. Call after the
    element loop (QE holds the element coordinates) and bodies.nl_update (W.nl_BR). Keeps the
    transport-angle branch in W.tq_dref (the State's) and (M, kappa) in W.tq_out."""
    wk = np.empty(12)
    g = np.empty(16)
    vA = np.empty(3)
    vB = np.empty(3)
    el_map, el_coef = K.el_map, W.el_coef
    nw = el_map.shape[2]
    for k in range(K.tq_el.shape[0]):
        ie = K.tq_el[k]
        jA, jB, phiA, phiB = _span_ends(K, W, q, k, vA, vB)
        p = K.tq_p[k]
        M, kap, delta = torsion_extra(int(p[0]), p[1], p[2], p[3], p[4], p[5], QE[ie, 0:3], QE[ie, 3:6],
                                      QE[ie, 6], QE[ie, 7], phiA, phiB, vA, vB, W.tq_dref[k], g, wk)
        W.tq_dref[k] = delta
        W.tq_out[k, 0] = M
        W.tq_out[k, 1] = kap
        for a in range(8):
            for w in range(nw):
                ba = el_coef[ie, a, w]
                if ba != 0.0:
                    Q[el_map[ie, a, w]] -= ba * g[a]
        if jA >= 0:
            Q[jA] -= g[8]
        if jB >= 0:
            Q[jB] -= g[9]
        for e in range(2):
            b = K.tq_vb[k, e]
            if b >= 0:
                _frame_force(K, q, b, vA if e == 0 else vB, g[10 + 3 * e:13 + 3 * e], Q)


@njit(cache=True)
def torsion_energy(K, W, QE, q):
    """Torsion part of the strain energy, sum of l (w - EA eps^2 / 2) over the torsion spans (the
    energy laws; the torque-factor law has none: its GJ0 kappa^2 / 2 part only). QE: the element
    coordinates at q, W.nl_BR the rotations at q (after an assembly on W at q)."""
    vA = np.empty(3)
    vB = np.empty(3)
    U = 0.0
    for k in range(K.tq_el.shape[0]):
        ie = K.tq_el[k]
        jA, jB, phiA, phiB = _span_ends(K, W, q, k, vA, vB)
        p = K.tq_p[k]
        l = QE[ie, 7] - QE[ie, 6]
        D0, D1, D2 = QE[ie, 3] - QE[ie, 0], QE[ie, 4] - QE[ie, 1], QE[ie, 5] - QE[ie, 2]
        dist = math.sqrt(D0 * D0 + D1 * D1 + D2 * D2)
        delta = transport_angle(D0 / dist, D1 / dist, D2 / dist, vA[0], vA[1], vA[2], vB[0], vB[1], vB[2],
                                W.tq_dref[k])
        eps = dist / l - 1.0
        w = coupling_law(int(p[0]), p[1], p[2], p[3], p[4], p[5], eps, (phiB + delta - phiA) / l)[0]
        U += l * (w - 0.5 * p[1] * eps * eps)
    return U
