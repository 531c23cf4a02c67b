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
