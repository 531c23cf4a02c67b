"""Rotating rigid bodies and exact tangent points from the current poses (compiled part).

The 1D and translating models map coordinates to rope-node coordinates by a constant affine map
p = B q + c. A body that rotates, or a sheave whose span direction turns, makes some rows of p
nonlinear: p_r = f_r(q). This module evaluates those rows in every residual:

* body poses (x, y, z, theta): theta turns the body counter-clockwise in the x-z drawing (x right,
  z up), i.e. about -y, the default sheave axis; the body's position is its centre of mass;
* points fixed to a body at an offset in body axes (sheave centres, rope anchors);
* the common tangent of the two stops of each span (closed form for coplanar circles, the same formula
  as geometry.tangent), so tangent points slide on the pitch circles as the span turns;
* W1 wraps: the material coordinate of the leaving node is sigma + R * wrap angle(q), so the rope
  stored on a wrap follows the current wrap angle and the rope length is conserved exactly;
* cubic elements: the slope dr/ds of a span's end node at a sheave is lambda * e(q), lambda the
  node's stretch coordinate and e(q) = (TB - TA) / |TB - TA| the current span direction, so the rope
  leaves the pitch circle tangentially at the current tangent point (the slope's direction is
  eliminated by the geometry; only its length, the stretch, stays a coordinate).

For each nonlinear row the Jacobian row B_r(q) (rows_jacobian) and the convective acceleration
(dB/dt qdot)_r (rows_accel) are recomputed in closed form: rigid body motions, the tangency conditions
differentiated once and twice, wrap angles. rows_jacobian_fd / rows_accel_fd do the same by central
differences (steps NL_H, NL_EPS): the tests' reference. The rows are registered at build time
(builder/nonlinear.py); the rotational inertia of spatial bodies is core/rigid.py.
`nl_update` writes them into the kernel's element maps (el_coef) and into c (so that the unchanged
gather gives x = f(q) and its velocity B(q) qdot); `nl_convect` subtracts M_e (dB/dt qdot) from an
element's force vector. Models without nonlinear rows never call either (kernel.nl_on = 0).
"""
from __future__ import annotations

import math

import numpy as np

from ._jit import njit
from .elements.linear import axial_law

NL_H = 1e-4      # m or rad: Jacobian step; truncation ~ h^2/6 |f'''| ~ 2e-9 m, round-off ~ 1e-16 |f| / h
NL_EPS = 5e-4    # step of the second difference along qdot (normalised by its largest component)
ROW_TANGENT, ROW_WRAP, ROW_SLOPE = 0, 1, 2
# nl_rf columns of a W1 wrap row after (R, sense, s offset, centre, rhoA g, lumped rope): the leaving
# span's far s = c[RF_ROW] (+ q[RF_J2] if RF_J2 >= 0), the rope's EA (> 0: the wrap holds its rope at
# that span's strain, _strain_wrap) and that span's first element (whose axial law the wrap's rope follows)
RF_J2, RF_ROW, RF_EA, RF_EL = 8, 9, 10, 11
RF_WIDTH = 12
# SW columns (Work.nl_SW, per row): the far s's constant part, the leaving span's chord D, the wrap's
# arc A, the material s2 - sigma shared by the wrap and that span
SW_C, SW_D, SW_A, SW_DL = 0, 1, 2, 3
SW_WIDTH = 4


@njit(cache=True, inline="always")
def _basis_from(a0, a1, a2, h0, h1, h2):
    """u = the helper h projected on the plane normal to the unit axis a, v = a x u."""
    d = h0 * a0 + h1 * a1 + h2 * a2
    u0, u1, u2 = h0 - a0 * d, h1 - a1 * d, h2 - a2 * d
    n = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    u0, u1, u2 = u0 / n, u1 / n, u2 / n
    return u0, u1, u2, a1 * u2 - a2 * u1, a2 * u0 - a0 * u2, a0 * u1 - a1 * u0


@njit(cache=True, inline="always")
def _basis(a0, a1, a2):
    """Two unit vectors u, v with (u, v, a) right-handed (as geometry._basis)."""
    if abs(a0) < 0.9:
        return _basis_from(a0, a1, a2, 1.0, 0.0, 0.0)
    return _basis_from(a0, a1, a2, 0.0, 0.0, 1.0)


@njit(cache=True, inline="always")
def _basis_z(a0, a1, a2):
    """u, v with (u, v, a) right-handed, u from the vertical unless the axis is within 26 deg of it:
    continuous while an axis turns about the vertical (a hook block's yaw), so the contact angles
    tangent_spatial keeps as its warm start stay on the tangent they follow."""
    if abs(a2) < 0.9:
        return _basis_from(a0, a1, a2, 0.0, 0.0, 1.0)
    return _basis_from(a0, a1, a2, 1.0, 0.0, 0.0)


@njit(cache=True)
def tangent_planar(P, iA, iB, RA, sA, RB, sB, a, out):
    """Touching points of the span from stop A (point P[iA], radius RA, sense sA) to stop B, for
    coplanar circles with the reference axis a: out[0:3] = TA, out[3:6] = TB (geometry._planar)."""
    u0, u1, u2, v0, v1, v2 = _basis(a[0], a[1], a[2])
    D0, D1, D2 = P[iB, 0] - P[iA, 0], P[iB, 1] - P[iA, 1], P[iB, 2] - P[iA, 2]
    Du = D0 * u0 + D1 * u1 + D2 * u2
    Dv = D0 * v0 + D1 * v1 + D2 * v2
    L = math.sqrt(Du * Du + Dv * Dv)
    rho = sB * RB - sA * RA
    x = rho / L
    if x > 1.0:
        x = 1.0
    elif x < -1.0:
        x = -1.0
    th = math.atan2(Dv, Du) - math.asin(x)
    ct, st = math.cos(th), math.sin(th)
    t0, t1, t2 = ct * u0 + st * v0, ct * u1 + st * v1, ct * u2 + st * v2
    n0, n1, n2 = a[1] * t2 - a[2] * t1, a[2] * t0 - a[0] * t2, a[0] * t1 - a[1] * t0
    out[0] = P[iA, 0] - sA * RA * n0
    out[1] = P[iA, 1] - sA * RA * n1
    out[2] = P[iA, 2] - sA * RA * n2
    out[3] = P[iB, 0] - sB * RB * n0
    out[4] = P[iB, 1] - sB * RB * n1
    out[5] = P[iB, 2] - sB * RB * n2


@njit(cache=True, inline="always")
def _wrap_angle(c, a, sg, T_in, T_out):
    """Angle in [0, 2 pi) swept from T_in to T_out about c in the sense sg * a (geometry.wrap_angle)."""
    u0, u1, u2, v0, v1, v2 = _basis(sg * a[0], sg * a[1], sg * a[2])
    p0, p1, p2 = T_in[0] - c[0], T_in[1] - c[1], T_in[2] - c[2]
    q0, q1, q2 = T_out[0] - c[0], T_out[1] - c[1], T_out[2] - c[2]
    ang = (math.atan2(q0 * v0 + q1 * v1 + q2 * v2, q0 * u0 + q1 * u1 + q2 * u2)
           - math.atan2(p0 * v0 + p1 * v1 + p2 * v2, p0 * u0 + p1 * u1 + p2 * u2))
    two_pi = 2.0 * math.pi
    return ang - two_pi * math.floor(ang / two_pi)


@njit(cache=True, inline="always")
def _rotate(R, b, v0, v1, v2):
    """v turned by body b's rotation R[b] = (axis, cos, sin) (Rodrigues)."""
    a0, a1, a2, c, s = R[b, 0], R[b, 1], R[b, 2], R[b, 3], R[b, 4]
    d = (a0 * v0 + a1 * v1 + a2 * v2) * (1.0 - c)
    return (v0 * c + (a1 * v2 - a2 * v1) * s + a0 * d, v1 * c + (a2 * v0 - a0 * v2) * s + a1 * d,
            v2 * c + (a0 * v1 - a1 * v0) * s + a2 * d)


@njit(cache=True, inline="always")
def _on(bq, bk, i_body, b):
    """True if a point of body i_body moves with body b: it is b, or a body on a joint on b (kind 3)."""
    return i_body == b or (i_body >= 0 and bk[i_body] == 3 and bq[i_body, 7] == b)


@njit(cache=True, inline="always")
def _axis_w(bq, bk, BR, b, v0, v1, v2):
    """A vector fixed to body b (axes at its scene pose) in world axes: turned by the body's rotation,
    and a body on a joint on a moving body (kind 3) by its parent's too (a prismatic parent: none)."""
    if b < 0 or bk[b] == 1:
        return v0, v1, v2
    v0, v1, v2 = _rotate(BR, b, v0, v1, v2)
    if bk[b] == 3 and bk[bq[b, 7]] != 1:
        v0, v1, v2 = _rotate(BR, bq[b, 7], v0, v1, v2)
    return v0, v1, v2


@njit(cache=True, inline="always")
def _chain_point(q, bq, b0, bk, bax, BR, b, p0, p1, p2):
    """World position of the point at offset p from the reference point of a kind-3 body b (scene
    pose): its own joint (revolute about bax[b] through b0[b], or sliding along it), then its parent's
    (revolute about its axis through its pivot, or sliding)."""
    y0, y1, y2 = _rotate(BR, b, p0, p1, p2)
    y0, y1, y2 = y0 + b0[b, 0], y1 + b0[b, 1], y2 + b0[b, 2]
    if bq[b, 0] >= 0:
        u = q[bq[b, 0]]
        y0, y1, y2 = y0 + u * bax[b, 0], y1 + u * bax[b, 1], y2 + u * bax[b, 2]
    p = bq[b, 7]
    if bk[p] == 1:
        u = q[bq[p, 0]]
        return y0 + u * bax[p, 0], y1 + u * bax[p, 1], y2 + u * bax[p, 2]
    r0, r1, r2 = _rotate(BR, p, y0 - b0[p, 0], y1 - b0[p, 1], y2 - b0[p, 2])
    return b0[p, 0] + r0, b0[p, 1] + r1, b0[p, 2] + r2


@njit(cache=True, inline="always")
def rot_coefs(p0, p1, p2):
    """Coefficients of the rotation vector phi (angle th = |phi|): R = I + s1 P + a P^2 (Rodrigues),
    T = I + a P + b P^2 (phi_dot -> world angular velocity), with P = phi^, and ca = a'(th) / th,
    cb = b'(th) / th (for dT/dt). Series below th = 1e-2 (truncation < 1e-12 relative)."""
    th2 = p0 * p0 + p1 * p1 + p2 * p2
    if th2 < 1e-4:
        a = 0.5 - th2 / 24.0 + th2 * th2 / 720.0
        b = 1.0 / 6.0 - th2 / 120.0 + th2 * th2 / 5040.0
        s1 = 1.0 - th2 / 6.0 + th2 * th2 / 120.0
        ca = -1.0 / 12.0 + th2 / 180.0 - th2 * th2 / 6720.0
        cb = -1.0 / 60.0 + th2 / 1260.0 - th2 * th2 / 60480.0
    else:
        th = math.sqrt(th2)
        sn, cs = math.sin(th), math.cos(th)
        a = (1.0 - cs) / th2
        b = (th - sn) / (th2 * th)
        s1 = sn / th
        ca = (th * sn - 2.0 * (1.0 - cs)) / (th2 * th2)
        cb = ((1.0 - cs) * th - 3.0 * (th - sn)) / (th2 * th2 * th)
    return a, b, s1, ca, cb


@njit(cache=True)
def tangent_spatial(P, iA, iB, RA, sA, RB, sB, aA, aB, ang, out):
    """Touching points of a span between circles with any axes (world aA, aB; a point has R = 0):
    D = TB - TA perpendicular to both radii (geometry.tangent), Newton on the contact angles ang[0:2]
    (warm start from the last call; NaN: from the coplanar formula). Coplanar circles: closed form."""
    ref = aA if RA > 0.0 else aB
    D0, D1, D2 = P[iB, 0] - P[iA, 0], P[iB, 1] - P[iA, 1], P[iB, 2] - P[iA, 2]
    scale = 1.0 + abs(D0) + abs(D1) + abs(D2)
    par = (RA == 0.0 or RB == 0.0 or abs(abs(aA[0] * aB[0] + aA[1] * aB[1] + aA[2] * aB[2]) - 1.0) < 1e-12)
    if (RA == 0.0 and RB == 0.0) or (par and abs(D0 * ref[0] + D1 * ref[1] + D2 * ref[2]) < 1e-12 * scale):
        tangent_planar(P, iA, iB, RA, sA, RB, sB, ref, out)
        return
    uA0, uA1, uA2, vA0, vA1, vA2 = _basis_z(aA[0], aA[1], aA[2])
    uB0, uB1, uB2, vB0, vB1, vB2 = _basis_z(aB[0], aB[1], aB[2])
    if not (ang[0] == ang[0]):
        tangent_planar(P, iA, iB, RA, sA, RB, sB, ref, out)
        x0, x1, x2 = out[0] - P[iA, 0], out[1] - P[iA, 1], out[2] - P[iA, 2]
        ang[0] = math.atan2(x0 * vA0 + x1 * vA1 + x2 * vA2, x0 * uA0 + x1 * uA1 + x2 * uA2)
        x0, x1, x2 = out[3] - P[iB, 0], out[4] - P[iB, 1], out[5] - P[iB, 2]
        ang[1] = math.atan2(x0 * vB0 + x1 * vB1 + x2 * vB2, x0 * uB0 + x1 * uB1 + x2 * uB2)
    for it in range(40):
        cA, sA_ = math.cos(ang[0]), math.sin(ang[0])
        cB, sB_ = math.cos(ang[1]), math.sin(ang[1])
        nA0, nA1, nA2 = cA * uA0 + sA_ * vA0, cA * uA1 + sA_ * vA1, cA * uA2 + sA_ * vA2
        tA0, tA1, tA2 = -sA_ * uA0 + cA * vA0, -sA_ * uA1 + cA * vA1, -sA_ * uA2 + cA * vA2
        nB0, nB1, nB2 = cB * uB0 + sB_ * vB0, cB * uB1 + sB_ * vB1, cB * uB2 + sB_ * vB2
        tB0, tB1, tB2 = -sB_ * uB0 + cB * vB0, -sB_ * uB1 + cB * vB1, -sB_ * uB2 + cB * vB2
        d0 = P[iB, 0] + RB * nB0 - P[iA, 0] - RA * nA0
        d1 = P[iB, 1] + RB * nB1 - P[iA, 1] - RA * nA1
        d2 = P[iB, 2] + RB * nB2 - P[iA, 2] - RA * nA2
        rA = d0 * nA0 + d1 * nA1 + d2 * nA2
        rB = d0 * nB0 + d1 * nB1 + d2 * nB2
        jAA = d0 * tA0 + d1 * tA1 + d2 * tA2
        jAB = RB * (tB0 * nA0 + tB1 * nA1 + tB2 * nA2)
        jBA = -RA * (tA0 * nB0 + tA1 * nB1 + tA2 * nB2)
        jBB = d0 * tB0 + d1 * tB1 + d2 * tB2
        if RA == 0.0:
            dA, dB = 0.0, rB / jBB
        elif RB == 0.0:
            dA, dB = rA / jAA, 0.0
        else:
            det = jAA * jBB - jAB * jBA
            dA = (rA * jBB - jAB * rB) / det
            dB = (jAA * rB - jBA * rA) / det
        ang[0] -= dA
        ang[1] -= dB
        if abs(dA) + abs(dB) < 1e-12:   # the step just taken leaves an error ~ its square
            break
    cA, sA_ = math.cos(ang[0]), math.sin(ang[0])
    cB, sB_ = math.cos(ang[1]), math.sin(ang[1])
    out[0] = P[iA, 0] + RA * (cA * uA0 + sA_ * vA0)
    out[1] = P[iA, 1] + RA * (cA * uA1 + sA_ * vA1)
    out[2] = P[iA, 2] + RA * (cA * uA2 + sA_ * vA2)
    out[3] = P[iB, 0] + RB * (cB * uB0 + sB_ * vB0)
    out[4] = P[iB, 1] + RB * (cB * uB1 + sB_ * vB1)
    out[5] = P[iB, 2] + RB * (cB * uB2 + sB_ * vB2)


@njit(cache=True, inline="always")
def _span_dir(TW, k, comp):
    """Component comp of the unit direction of span k, (TB - TA) / |TB - TA|."""
    d0, d1, d2 = TW[k, 3] - TW[k, 0], TW[k, 4] - TW[k, 1], TW[k, 5] - TW[k, 2]
    return (TW[k, 3 + comp] - TW[k, comp]) / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)


@njit(cache=True, inline="always")
def extra_coef(rk, rf, TW, SW, r, k):
    """The B entry of a row's own coordinate (k = -2 in nl_rw): 1 for a W1 wrap's sigma (D / (D + A)
    when the wrap holds its rope at the leaving span's strain, and A / (D + A) for that span's far s,
    k = -3: _strain_wrap), the span direction's component for a slope row's stretch."""
    if rk[r, 0] == ROW_SLOPE:
        return _span_dir(TW, rk[r, 1], rk[r, 3])
    if rf[r, RF_EA] > 0.0:
        S = SW[r, SW_D] + SW[r, SW_A]
        return SW[r, SW_D] / S if k == -2 else SW[r, SW_A] / S
    return 1.0


@njit(cache=True, inline="always")
def _strain_wrap(q, rf, TW, SW, r, k_out, sig, A):
    """s of the node leaving a W1 wrap that holds its rope at the leaving span's strain: the wrap
    (arc A = R x angle) and that span (chord D, from the node to the far node's s2) share the material
    s2 - sigma in proportion to their lengths, s = (sigma D + A s2) / (D + A), i.e. R x angle / (1 + eps)
    of rope on the wrap. Keeps D, A and s2 - sigma in SW[r]."""
    j2 = int(rf[r, RF_J2])
    s2 = SW[r, SW_C] + (q[j2] if j2 >= 0 else 0.0)
    d0, d1, d2 = TW[k_out, 3] - TW[k_out, 0], TW[k_out, 4] - TW[k_out, 1], TW[k_out, 5] - TW[k_out, 2]
    D = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    SW[r, SW_D], SW[r, SW_A], SW[r, SW_DL] = D, A, s2 - sig
    return (sig * D + A * s2) / (D + A)


@njit(cache=True, inline="always")
def _slope_rate(TW, k, comp, lam, dT):
    """lam * d e_comp for the tangent-point changes dT of span k: lam (dD - e (e . dD))_comp / L,
    D = TB - TA, L = |D|."""
    L = 0.0
    ed = 0.0
    for m in range(3):
        L += (TW[k, 3 + m] - TW[k, m]) ** 2
    L = math.sqrt(L)
    for m in range(3):
        ed += (TW[k, 3 + m] - TW[k, m]) / L * (dT[3 + m] - dT[m])
    e = (TW[k, 3 + comp] - TW[k, comp]) / L
    return lam * (dT[3 + comp] - dT[comp] - e * ed) / L


@njit(cache=True)
def rows_eval(q, bq, b0, bk, bax, pb, po, sp, sg, sa, rk, rf, P, TW, BR, ANG, AX, SW, only, f):
    """The nonlinear rows f at q.
    Body b: bq[b] = q indices of (x, y, z, angle, rotation vector) (-1: fixed at b0[b]); bk[b] = 0: reference point
    (x, y, z) turned by the angle about the unit axis bax[b] (planar theta: -y; revolute joint: its
    axis, the reference point its pivot); bk[b] = 1: prismatic joint, reference b0[b] + q[bq[b, 0]] bax[b];
    bk[b] = 2: spatial rigid body, (x, y, z) turned by the rotation vector bq[b, 4:7]; bk[b] = 3: a body
    on a joint on the moving body bq[b, 7] (_chain_point: revolute angle bq[b, 3] about bax[b] through
    b0[b], or prismatic travel bq[b, 0] along bax[b], in the parent's axes at the scene's pose).
    Point i sits on body pb[i] (-1: ground) at offset po[i] from the reference point (axes at angle 0);
    span k runs from point sp[k, 0] to sp[k, 1] with sg[k] = (RA, sA, RB, sB) and the sheave axes
    sa[k, 0:3], sa[k, 3:6] in their bodies' axes; row r: rk[r] = (ROW_TANGENT, span, end, world
    component) or (ROW_WRAP, span in, span out, sigma index) with rf[r] = (R, sense relative to the
    span-in end-B axis, s offset, centre point) or (ROW_SLOPE, span, end, world component) with
    rf[r, 0] = the stretch coordinate's index (f = q[stretch] * span direction); a W1 wrap at its leaving
    span's strain (rf[r, RF_EA] > 0) reads that span's far s = SW[r, SW_C] (+ q[rf[r, RF_J2]]).
    P, TW, BR (body rotations), ANG (contact angles), AX (two axes), SW (the strain wraps' D, A, s2 -
    sigma) are scratch. only >= 0: recompute only the points and spans on body `only` (the others
    keep their values in P and TW: a Jacobian column of that body's coordinate)."""
    for b in range(bq.shape[0]):
        if bk[b] == 2:   # rotation vector phi: axis phi / |phi|, angle |phi|
            p0, p1, p2 = q[bq[b, 4]], q[bq[b, 5]], q[bq[b, 6]]
            th = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
            if th > 0.0:
                BR[b, 0], BR[b, 1], BR[b, 2] = p0 / th, p1 / th, p2 / th
            else:
                BR[b, 0], BR[b, 1], BR[b, 2] = 0.0, 0.0, 1.0
        else:
            th = q[bq[b, 3]] if bq[b, 3] >= 0 else (0.0 if bk[b] == 3 else b0[b, 3])
            BR[b, 0], BR[b, 1], BR[b, 2] = bax[b, 0], bax[b, 1], bax[b, 2]
        BR[b, 3], BR[b, 4] = math.cos(th), math.sin(th)
    for i in range(pb.shape[0]):
        b = pb[i]
        if only >= 0 and not _on(bq, bk, b, only):
            continue
        if b < 0:
            for k in range(3):
                P[i, k] = po[i, k]
            continue
        if bk[b] == 3:
            P[i, 0], P[i, 1], P[i, 2] = _chain_point(q, bq, b0, bk, bax, BR, b, po[i, 0], po[i, 1], po[i, 2])
            continue
        if bk[b] == 1:
            u = q[bq[b, 0]]
            for k in range(3):
                P[i, k] = b0[b, k] + u * bax[b, k] + po[i, k]
            continue
        x = q[bq[b, 0]] if bq[b, 0] >= 0 else b0[b, 0]
        y = q[bq[b, 1]] if bq[b, 1] >= 0 else b0[b, 1]
        z = q[bq[b, 2]] if bq[b, 2] >= 0 else b0[b, 2]
        r0, r1, r2 = _rotate(BR, b, po[i, 0], po[i, 1], po[i, 2])
        P[i, 0] = x + r0
        P[i, 1] = y + r1
        P[i, 2] = z + r2
    aA = AX[0]
    aB = AX[1]
    for k in range(sp.shape[0]):
        if only >= 0 and not _on(bq, bk, pb[sp[k, 0]], only) and not _on(bq, bk, pb[sp[k, 1]], only):
            continue
        for e in range(2):
            v0, v1, v2 = _axis_w(bq, bk, BR, pb[sp[k, e]], sa[k, 3 * e], sa[k, 3 * e + 1], sa[k, 3 * e + 2])
            w = aA if e == 0 else aB
            w[0], w[1], w[2] = v0, v1, v2
        tangent_spatial(P, sp[k, 0], sp[k, 1], sg[k, 0], sg[k, 1], sg[k, 2], sg[k, 3], aA, aB, ANG[k], TW[k])
    for r in range(rk.shape[0]):
        if rk[r, 0] == ROW_TANGENT:
            f[r] = TW[rk[r, 1], 3 * rk[r, 2] + rk[r, 3]]
        elif rk[r, 0] == ROW_SLOPE:
            f[r] = q[int(rf[r, 0])] * _span_dir(TW, rk[r, 1], rk[r, 3])
        else:
            k_in, k_out = rk[r, 1], rk[r, 2]
            ip = int(rf[r, 3])
            v0, v1, v2 = _axis_w(bq, bk, BR, pb[ip], sa[k_in, 3], sa[k_in, 4], sa[k_in, 5])
            aB[0], aB[1], aB[2] = v0, v1, v2
            ang = _wrap_angle(P[ip], aB, rf[r, 1], TW[k_in, 3:6], TW[k_out, 0:3])
            if rf[r, RF_EA] > 0.0:
                f[r] = _strain_wrap(q, rf, TW, SW, r, k_out, q[rk[r, 3]], rf[r, 0] * ang)
            else:
                f[r] = q[rk[r, 3]] + rf[r, 2] + rf[r, 0] * ang


@njit(cache=True)
def rows_jacobian_fd(q, G, cols, colbody, f0, fp, fm, qs, J):
    """rows_jacobian by central differences (step NL_H; the tests' reference). G = the
    geometry arrays of rows_eval (a tuple); a column re-evaluates only the spans on its body
    colbody[k] and then restores the points and tangents of q."""
    P, TW = G[11], G[12]
    rows_eval(q, *G, -1, f0)
    P0 = P.copy()
    TW0 = TW.copy()
    for i in range(q.shape[0]):
        qs[i] = q[i]
    for k in range(cols.shape[0]):
        j = cols[k]
        qs[j] = q[j] + NL_H
        rows_eval(qs, *G, colbody[k], fp)
        qs[j] = q[j] - NL_H
        rows_eval(qs, *G, colbody[k], fm)
        qs[j] = q[j]
        P[:, :] = P0
        TW[:, :] = TW0
        for r in range(f0.shape[0]):
            J[r, k] = (fp[r] - fm[r]) / (2.0 * NL_H)


@njit(cache=True, inline="always")
def _twist(q, bq, b0, bk, bax, BR, b, j):
    """The motion of body b per unit change of its coordinate q[j]: (v, omega, O) with every point P of
    the body moving by v + omega x (P - O) and every axis a turning by omega x a."""
    v0 = v1 = v2 = w0 = w1 = w2 = 0.0
    if bk[b] == 1:                      # prismatic: slides along its axis
        return bax[b, 0], bax[b, 1], bax[b, 2], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    if bk[b] == 3:                      # own joint of a body on a moving body: its axis in world axes
        a0, a1, a2 = bax[b, 0], bax[b, 1], bax[b, 2]
        if bk[bq[b, 7]] != 1:
            a0, a1, a2 = _rotate(BR, bq[b, 7], a0, a1, a2)
        if bq[b, 0] == j:
            return a0, a1, a2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        O0, O1, O2 = _chain_point(q, bq, b0, bk, bax, BR, b, 0.0, 0.0, 0.0)
        return 0.0, 0.0, 0.0, a0, a1, a2, O0, O1, O2
    O0 = q[bq[b, 0]] if bq[b, 0] >= 0 else b0[b, 0]
    O1 = q[bq[b, 1]] if bq[b, 1] >= 0 else b0[b, 1]
    O2 = q[bq[b, 2]] if bq[b, 2] >= 0 else b0[b, 2]
    if bq[b, 0] == j:
        v0 = 1.0
    elif bq[b, 1] == j:
        v1 = 1.0
    elif bq[b, 2] == j:
        v2 = 1.0
    elif bq[b, 3] == j:                 # planar theta / revolute angle: about the body's axis
        w0, w1, w2 = bax[b, 0], bax[b, 1], bax[b, 2]
    else:                               # rotation vector: omega = T(phi)[:, c]
        c = 0 if bq[b, 4] == j else (1 if bq[b, 5] == j else 2)
        p0, p1, p2 = q[bq[b, 4]], q[bq[b, 5]], q[bq[b, 6]]
        a, bb, s1, ca, cb = rot_coefs(p0, p1, p2)
        ph = (p0, p1, p2)
        P = ((0.0, -p2, p1), (p2, 0.0, -p0), (-p1, p0, 0.0))
        th2 = p0 * p0 + p1 * p1 + p2 * p2
        w0 = (1.0 if c == 0 else 0.0) + a * P[0][c] + bb * (ph[0] * ph[c] - (th2 if c == 0 else 0.0))
        w1 = (1.0 if c == 1 else 0.0) + a * P[1][c] + bb * (ph[1] * ph[c] - (th2 if c == 1 else 0.0))
        w2 = (1.0 if c == 2 else 0.0) + a * P[2][c] + bb * (ph[2] * ph[c] - (th2 if c == 2 else 0.0))
    return v0, v1, v2, w0, w1, w2, O0, O1, O2


@njit(cache=True, inline="always")
def _moved(P, i, on, v0, v1, v2, w0, w1, w2, O0, O1, O2):
    """dP[i] under the twist (zero when the point is not on the moving body)."""
    if not on:
        return 0.0, 0.0, 0.0
    r0, r1, r2 = P[i, 0] - O0, P[i, 1] - O1, P[i, 2] - O2
    return v0 + w1 * r2 - w2 * r1, v1 + w2 * r0 - w0 * r2, v2 + w0 * r1 - w1 * r0


@njit(cache=True, inline="always")
def _solve2(RA, RB, jAA, jAB, jBA, jBB, gA, gB):
    """The contact-angle changes from the 2 x 2 tangency system (a point stop, R = 0, has none)."""
    if RA > 0.0 and RB > 0.0:
        det = jAA * jBB - jAB * jBA
        return (gA * jBB - jAB * gB) / det, (jAA * gB - jBA * gA) / det
    if RA > 0.0:
        return gA / jAA, 0.0
    if RB > 0.0:
        return 0.0, gB / jBB
    return 0.0, 0.0


@njit(cache=True)
def _tangent_rate(P, iA, iB, RA, RB, aA, aB, onA, onB, tw, T, dT):
    """dT = d(TA, TB) of a span whose stops move by the twist tw (stops on the moving body: onA,
    onB), by implicit differentiation of the tangency conditions (TB - TA) . n = 0 at both touching
    points (n: unit radius, t = a x n); the same 2 x 2 matrix as tangent_spatial's Newton step."""
    v0, v1, v2, w0, w1, w2, O0, O1, O2 = tw[0], tw[1], tw[2], tw[3], tw[4], tw[5], tw[6], tw[7], tw[8]
    dA0, dA1, dA2 = _moved(P, iA, onA, v0, v1, v2, w0, w1, w2, O0, O1, O2)
    dB0, dB1, dB2 = _moved(P, iB, onB, v0, v1, v2, w0, w1, w2, O0, O1, O2)
    d0, d1, d2 = T[3] - T[0], T[4] - T[1], T[5] - T[2]
    # radius directions, their turn with the body (omega x n), tangents t = a x n
    nA0 = nA1 = nA2 = tA0 = tA1 = tA2 = rA0 = rA1 = rA2 = 0.0
    nB0 = nB1 = nB2 = tB0 = tB1 = tB2 = rB0 = rB1 = rB2 = 0.0
    if RA > 0.0:
        nA0, nA1, nA2 = (T[0] - P[iA, 0]) / RA, (T[1] - P[iA, 1]) / RA, (T[2] - P[iA, 2]) / RA
        tA0, tA1, tA2 = aA[1] * nA2 - aA[2] * nA1, aA[2] * nA0 - aA[0] * nA2, aA[0] * nA1 - aA[1] * nA0
        if onA:
            rA0, rA1, rA2 = w1 * nA2 - w2 * nA1, w2 * nA0 - w0 * nA2, w0 * nA1 - w1 * nA0
    if RB > 0.0:
        nB0, nB1, nB2 = (T[3] - P[iB, 0]) / RB, (T[4] - P[iB, 1]) / RB, (T[5] - P[iB, 2]) / RB
        tB0, tB1, tB2 = aB[1] * nB2 - aB[2] * nB1, aB[2] * nB0 - aB[0] * nB2, aB[0] * nB1 - aB[1] * nB0
        if onB:
            rB0, rB1, rB2 = w1 * nB2 - w2 * nB1, w2 * nB0 - w0 * nB2, w0 * nB1 - w1 * nB0
    # d(TB - TA) without the contact-angle changes
    e0 = dB0 + RB * rB0 - dA0 - RA * rA0
    e1 = dB1 + RB * rB1 - dA1 - RA * rA1
    e2 = dB2 + RB * rB2 - dA2 - RA * rA2
    gA = -(e0 * nA0 + e1 * nA1 + e2 * nA2 + d0 * rA0 + d1 * rA1 + d2 * rA2)
    gB = -(e0 * nB0 + e1 * nB1 + e2 * nB2 + d0 * rB0 + d1 * rB1 + d2 * rB2)
    jAA = d0 * tA0 + d1 * tA1 + d2 * tA2
    jAB = RB * (tB0 * nA0 + tB1 * nA1 + tB2 * nA2)
    jBA = -RA * (tA0 * nB0 + tA1 * nB1 + tA2 * nB2)
    jBB = d0 * tB0 + d1 * tB1 + d2 * tB2
    xA, xB = _solve2(RA, RB, jAA, jAB, jBA, jBB, gA, gB)
    dT[0] = dA0 + RA * (rA0 + tA0 * xA)
    dT[1] = dA1 + RA * (rA1 + tA1 * xA)
    dT[2] = dA2 + RA * (rA2 + tA2 * xA)
    dT[3] = dB0 + RB * (rB0 + tB0 * xB)
    dT[4] = dB1 + RB * (rB1 + tB1 * xB)
    dT[5] = dB2 + RB * (rB2 + tB2 * xB)


@njit(cache=True, inline="always")
def _world_axis(sa, k, e, bq, bk, BR, b):
    return _axis_w(bq, bk, BR, b, sa[k, 3 * e], sa[k, 3 * e + 1], sa[k, 3 * e + 2])


@njit(cache=True)
def rows_jacobian(q, G, cols, colbody, f0, fp, fm, qs, J):
    """f0 = f(q) and J[:, k] = d f / d q[cols[k]] in closed form: each body coordinate moves its body
    rigidly (_twist); tangent points follow by implicit differentiation of the tangency conditions
    (_tangent_rate); a W1 wrap's s by R d(wrap angle), with d(angle of x about n) = (n x x) . dx / |x|^2.
    (rows_jacobian_fd: the same by central differences.)"""
    bq, b0, bk, bax, pb, po, sp, sg, sa, rk, rf, P, TW, BR, ANG, AX, SW = G
    rows_eval(q, *G, -1, f0)
    nr = rk.shape[0]
    nsp = sp.shape[0]
    dTW = np.zeros((nsp, 6))
    tw = np.empty(9)
    aA = np.empty(3)
    aB = np.empty(3)
    for k in range(cols.shape[0]):
        b = colbody[k]
        tw[:] = _twist(q, bq, b0, bk, bax, BR, b, cols[k])
        for s in range(nsp):
            iA, iB = sp[s, 0], sp[s, 1]
            onA, onB = _on(bq, bk, pb[iA], b), _on(bq, bk, pb[iB], b)
            if not (onA or onB):
                for m in range(6):
                    dTW[s, m] = 0.0
                continue
            aA[0], aA[1], aA[2] = _world_axis(sa, s, 0, bq, bk, BR, pb[iA])
            aB[0], aB[1], aB[2] = _world_axis(sa, s, 1, bq, bk, BR, pb[iB])
            _tangent_rate(P, iA, iB, sg[s, 0], sg[s, 2], aA, aB, onA, onB, tw, TW[s], dTW[s])
        for r in range(rk.shape[0]):
            if rk[r, 0] == ROW_TANGENT:
                J[r, k] = dTW[rk[r, 1], 3 * rk[r, 2] + rk[r, 3]]
                continue
            if rk[r, 0] == ROW_SLOPE:
                J[r, k] = _slope_rate(TW, rk[r, 1], rk[r, 3], q[int(rf[r, 0])], dTW[rk[r, 1]])
                continue
            k_in, k_out = rk[r, 1], rk[r, 2]
            ip = int(rf[r, 3])
            n0, n1, n2 = _world_axis(sa, k_in, 1, bq, bk, BR, pb[ip])
            sgn = rf[r, 1]
            n0, n1, n2 = sgn * n0, sgn * n1, sgn * n2
            c0, c1, c2 = _moved(P, ip, _on(bq, bk, pb[ip], b), tw[0], tw[1], tw[2], tw[3], tw[4], tw[5], tw[6], tw[7], tw[8])
            x0, x1, x2 = TW[k_out, 0] - P[ip, 0], TW[k_out, 1] - P[ip, 1], TW[k_out, 2] - P[ip, 2]
            g = ((n1 * x2 - n2 * x1) * (dTW[k_out, 0] - c0) + (n2 * x0 - n0 * x2) * (dTW[k_out, 1] - c1)
                 + (n0 * x1 - n1 * x0) * (dTW[k_out, 2] - c2)) / (x0 * x0 + x1 * x1 + x2 * x2)
            x0, x1, x2 = TW[k_in, 3] - P[ip, 0], TW[k_in, 4] - P[ip, 1], TW[k_in, 5] - P[ip, 2]
            g -= ((n1 * x2 - n2 * x1) * (dTW[k_in, 3] - c0) + (n2 * x0 - n0 * x2) * (dTW[k_in, 4] - c1)
                  + (n0 * x1 - n1 * x0) * (dTW[k_in, 5] - c2)) / (x0 * x0 + x1 * x1 + x2 * x2)
            J[r, k] = rf[r, 0] * g
            if rf[r, RF_EA] > 0.0:      # s = (sigma D + A s2) / (D + A): _strain_wrap
                D, A, dl = SW[r, SW_D], SW[r, SW_A], SW[r, SW_DL]
                dD = 0.0
                for m in range(3):
                    dD += (TW[k_out, 3 + m] - TW[k_out, m]) / D * (dTW[k_out, 3 + m] - dTW[k_out, m])
                if J.shape[0] >= 4 * nr:    # dA/dq, dD/dq, rhoA g.dm/dq (span middle m): wrap_weight
                    J[nr + r, k] = J[r, k]
                    J[2 * nr + r, k] = dD
                    J[3 * nr + r, k] = 0.5 * (rf[r, 4] * (dTW[k_out, 0] + dTW[k_out, 3])
                                              + rf[r, 5] * (dTW[k_out, 1] + dTW[k_out, 4])
                                              + rf[r, 6] * (dTW[k_out, 2] + dTW[k_out, 5]))
                J[r, k] = dl * (D * J[r, k] - A * dD) / ((D + A) * (D + A))


@njit(cache=True, inline="always")
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _body_motion(q, v, bq, b0, bk, bax, BR, b, out):
    """Rigid motion of body b at velocities v: out = (reference point O, its velocity, omega, the
    part of d omega / dt that is not from accelerations, O's acceleration at zero coordinate
    accelerations); a point P moves with velocity u_O + omega x (P - O) and, at zero coordinate
    accelerations, acceleration a_O + domega x (P - O) + omega x (omega x (P - O))."""
    for m in range(15):
        out[m] = 0.0
    if b < 0:
        return
    if bk[b] == 3:
        _chain_motion(q, v, bq, b0, bk, bax, BR, b, out)
        return
    if bk[b] == 1:
        for m in range(3):
            out[3 + m] = bax[b, m] * v[bq[b, 0]]
        return
    for m in range(3):
        j = bq[b, m]
        out[m] = q[j] if j >= 0 else b0[b, m]
        out[3 + m] = v[j] if j >= 0 else 0.0
    if bk[b] == 0:
        w = v[bq[b, 3]] if bq[b, 3] >= 0 else 0.0
        for m in range(3):
            out[6 + m] = bax[b, m] * w
        return
    i0, i1, i2 = bq[b, 4], bq[b, 5], bq[b, 6]
    p0, p1, p2 = q[i0], q[i1], q[i2]
    d0, d1, d2 = v[i0], v[i1], v[i2]
    a, bb, s1, ca, cb = rot_coefs(p0, p1, p2)
    x0, x1, x2 = _cross(p0, p1, p2, d0, d1, d2)               # phi x phi_dot
    y0, y1, y2 = _cross(p0, p1, p2, x0, x1, x2)
    z0, z1, z2 = _cross(d0, d1, d2, x0, x1, x2)
    out[6], out[7], out[8] = d0 + a * x0 + bb * y0, d1 + a * x1 + bb * y1, d2 + a * x2 + bb * y2   # T phi_dot
    pd = p0 * d0 + p1 * d1 + p2 * d2
    out[9] = pd * (ca * x0 + cb * y0) + bb * z0                                                 # dT/dt phi_dot
    out[10] = pd * (ca * x1 + cb * y1) + bb * z1
    out[11] = pd * (ca * x2 + cb * y2) + bb * z2


@njit(cache=True)
def _chain_motion(q, v, bq, b0, bk, bax, BR, b, out):
    """_body_motion of a kind-3 body (on a joint on the moving body p = bq[b, 7]): O its reference point
    (its joint's pivot, or the slider's point), omega = w_p + w_r (parent's, own), domega = w_p x w_r;
    u_O = w_p x (O - pivot_p) (or p's slide) + the own slide a u', a_O = w_p x (w_p x (O - pivot_p))
    + 2 w_p x a u' (Coriolis). BR: the body rotations of rows_eval at q."""
    p = bq[b, 7]
    O0, O1, O2 = _chain_point(q, bq, b0, bk, bax, BR, b, 0.0, 0.0, 0.0)
    a0, a1, a2 = bax[b, 0], bax[b, 1], bax[b, 2]
    wp0 = wp1 = wp2 = 0.0
    if bk[p] == 1:
        up = v[bq[p, 0]]
        u0, u1, u2 = bax[p, 0] * up, bax[p, 1] * up, bax[p, 2] * up
        c0 = c1 = c2 = 0.0
    else:
        a0, a1, a2 = _rotate(BR, p, a0, a1, a2)
        wp = v[bq[p, 3]]
        wp0, wp1, wp2 = bax[p, 0] * wp, bax[p, 1] * wp, bax[p, 2] * wp
        u0, u1, u2 = _cross(wp0, wp1, wp2, O0 - b0[p, 0], O1 - b0[p, 1], O2 - b0[p, 2])
        c0, c1, c2 = _cross(wp0, wp1, wp2, u0, u1, u2)
    out[0], out[1], out[2] = O0, O1, O2
    if bq[b, 0] >= 0:       # own slide: u_rel = a u'
        ur = v[bq[b, 0]]
        s0, s1, s2 = _cross(wp0, wp1, wp2, a0 * ur, a1 * ur, a2 * ur)
        u0, u1, u2 = u0 + a0 * ur, u1 + a1 * ur, u2 + a2 * ur
        c0, c1, c2 = c0 + 2.0 * s0, c1 + 2.0 * s1, c2 + 2.0 * s2
        wr0 = wr1 = wr2 = 0.0
    else:
        wr = v[bq[b, 3]]
        wr0, wr1, wr2 = a0 * wr, a1 * wr, a2 * wr
    out[3], out[4], out[5] = u0, u1, u2
    out[6], out[7], out[8] = wp0 + wr0, wp1 + wr1, wp2 + wr2
    out[9], out[10], out[11] = _cross(wp0, wp1, wp2, wr0, wr1, wr2)
    out[12], out[13], out[14] = c0, c1, c2


@njit(cache=True, inline="always")
def _point_motion(P, i, mo):
    """(velocity, convective acceleration) of point P[i] on a body with motion mo (_body_motion)."""
    r0, r1, r2 = P[i, 0] - mo[0], P[i, 1] - mo[1], P[i, 2] - mo[2]
    c0, c1, c2 = _cross(mo[6], mo[7], mo[8], r0, r1, r2)
    e0, e1, e2 = _cross(mo[6], mo[7], mo[8], c0, c1, c2)
    f0, f1, f2 = _cross(mo[9], mo[10], mo[11], r0, r1, r2)
    return mo[3] + c0, mo[4] + c1, mo[5] + c2, e0 + f0 + mo[12], e1 + f1 + mo[13], e2 + f2 + mo[14]


@njit(cache=True)
def _tangent_accel(P, iA, iB, RA, RB, aA, aB, mA, mB, T, VT, AT, S):
    """Velocities VT and convective accelerations AT (zero coordinate accelerations) of the touching
    points T of a span whose stops move with mA, mB (_body_motion): the tangency conditions
    (TB - TA) . n = 0 differentiated once and twice (same 2 x 2 matrix as _tangent_rate). S: scratch
    (5, 2, 3), the caller's (no allocation per span)."""
    uA0, uA1, uA2, gA0, gA1, gA2 = _point_motion(P, iA, mA)
    uB0, uB1, uB2, gB0, gB1, gB2 = _point_motion(P, iB, mB)
    d0, d1, d2 = T[3] - T[0], T[4] - T[1], T[5] - T[2]
    S[:, :, :] = 0.0
    n = S[0]
    t = S[1]
    wn = S[2]      # omega x n
    for e in range(2):
        R = RA if e == 0 else RB
        if R > 0.0:
            ip = iA if e == 0 else iB
            ax = aA if e == 0 else aB
            mo = mA if e == 0 else mB
            for m in range(3):
                n[e, m] = (T[3 * e + m] - P[ip, m]) / R
            t[e, 0], t[e, 1], t[e, 2] = _cross(ax[0], ax[1], ax[2], n[e, 0], n[e, 1], n[e, 2])
            wn[e, 0], wn[e, 1], wn[e, 2] = _cross(mo[6], mo[7], mo[8], n[e, 0], n[e, 1], n[e, 2])
    jAA = d0 * t[0, 0] + d1 * t[0, 1] + d2 * t[0, 2]
    jAB = RB * (t[1, 0] * n[0, 0] + t[1, 1] * n[0, 1] + t[1, 2] * n[0, 2])
    jBA = -RA * (t[0, 0] * n[1, 0] + t[0, 1] * n[1, 1] + t[0, 2] * n[1, 2])
    jBB = d0 * t[1, 0] + d1 * t[1, 1] + d2 * t[1, 2]
    # first order: n_dot = omega x n + t alpha_dot
    e0 = uB0 + RB * wn[1, 0] - uA0 - RA * wn[0, 0]
    e1 = uB1 + RB * wn[1, 1] - uA1 - RA * wn[0, 1]
    e2 = uB2 + RB * wn[1, 2] - uA2 - RA * wn[0, 2]
    gA = -(e0 * n[0, 0] + e1 * n[0, 1] + e2 * n[0, 2] + d0 * wn[0, 0] + d1 * wn[0, 1] + d2 * wn[0, 2])
    gB = -(e0 * n[1, 0] + e1 * n[1, 1] + e2 * n[1, 2] + d0 * wn[1, 0] + d1 * wn[1, 1] + d2 * wn[1, 2])
    xA, xB = _solve2(RA, RB, jAA, jAB, jBA, jBB, gA, gB)
    nd = S[3]
    for m in range(3):
        nd[0, m] = wn[0, m] + t[0, m] * xA
        nd[1, m] = wn[1, m] + t[1, m] * xB
    VT[0], VT[1], VT[2] = uA0 + RA * nd[0, 0], uA1 + RA * nd[0, 1], uA2 + RA * nd[0, 2]
    VT[3], VT[4], VT[5] = uB0 + RB * nd[1, 0], uB1 + RB * nd[1, 1], uB2 + RB * nd[1, 2]
    # second order at zero alpha_ddot: n_ddot0 = domega x n + omega x n_dot + t_dot alpha_dot,
    # t_dot = (omega x a) x n + a x n_dot
    nn = S[4]
    for e in range(2):
        R = RA if e == 0 else RB
        if R == 0.0:
            continue
        ax = aA if e == 0 else aB
        mo = mA if e == 0 else mB
        al = xA if e == 0 else xB
        h0, h1, h2 = _cross(mo[9], mo[10], mo[11], n[e, 0], n[e, 1], n[e, 2])
        k0, k1, k2 = _cross(mo[6], mo[7], mo[8], nd[e, 0], nd[e, 1], nd[e, 2])
        w0, w1, w2 = _cross(mo[6], mo[7], mo[8], ax[0], ax[1], ax[2])
        s0, s1, s2 = _cross(w0, w1, w2, n[e, 0], n[e, 1], n[e, 2])
        r0, r1, r2 = _cross(ax[0], ax[1], ax[2], nd[e, 0], nd[e, 1], nd[e, 2])
        nn[e, 0] = h0 + k0 + (s0 + r0) * al
        nn[e, 1] = h1 + k1 + (s1 + r1) * al
        nn[e, 2] = h2 + k2 + (s2 + r2) * al
    dd0, dd1, dd2 = VT[3] - VT[0], VT[4] - VT[1], VT[5] - VT[2]
    f0 = gB0 + RB * nn[1, 0] - gA0 - RA * nn[0, 0]
    f1 = gB1 + RB * nn[1, 1] - gA1 - RA * nn[0, 1]
    f2 = gB2 + RB * nn[1, 2] - gA2 - RA * nn[0, 2]
    hA = -(f0 * n[0, 0] + f1 * n[0, 1] + f2 * n[0, 2] + 2.0 * (dd0 * nd[0, 0] + dd1 * nd[0, 1] + dd2 * nd[0, 2])
           + d0 * nn[0, 0] + d1 * nn[0, 1] + d2 * nn[0, 2])
    hB = -(f0 * n[1, 0] + f1 * n[1, 1] + f2 * n[1, 2] + 2.0 * (dd0 * nd[1, 0] + dd1 * nd[1, 1] + dd2 * nd[1, 2])
           + d0 * nn[1, 0] + d1 * nn[1, 1] + d2 * nn[1, 2])
    yA, yB = _solve2(RA, RB, jAA, jAB, jBA, jBB, hA, hB)
    AT[0], AT[1], AT[2] = gA0 + RA * (nn[0, 0] + t[0, 0] * yA), gA1 + RA * (nn[0, 1] + t[0, 1] * yA), gA2 + RA * (nn[0, 2] + t[0, 2] * yA)
    AT[3], AT[4], AT[5] = gB0 + RB * (nn[1, 0] + t[1, 0] * yB), gB1 + RB * (nn[1, 1] + t[1, 1] * yB), gB2 + RB * (nn[1, 2] + t[1, 2] * yB)


@njit(cache=True)
def _slope_accel(T, VT, AT, comp, lam, dlam):
    """Convective acceleration of a slope row lam * e, e = D / L, D = TB - TA: 2 lam' e' + lam e''
    at zero coordinate accelerations, with e' = (D' - e L') / L, L' = e . D' and
    e'' = (D'' - e (e . D'') - e (e' . D') - 2 e' L') / L (D'': the touching points' convective part)."""
    L = math.sqrt((T[3] - T[0]) ** 2 + (T[4] - T[1]) ** 2 + (T[5] - T[2]) ** 2)
    e = np.empty(3)
    dD = np.empty(3)
    aD = np.empty(3)
    for m in range(3):
        e[m] = (T[3 + m] - T[m]) / L
        dD[m] = VT[3 + m] - VT[m]
        aD[m] = AT[3 + m] - AT[m]
    Ld = e[0] * dD[0] + e[1] * dD[1] + e[2] * dD[2]
    ea = e[0] * aD[0] + e[1] * aD[1] + e[2] * aD[2]
    ed = (dD[comp] - e[comp] * Ld) / L
    edD = 0.0
    for m in range(3):
        edD += (dD[m] - e[m] * Ld) / L * dD[m]
    edd = (aD[comp] - e[comp] * ea - e[comp] * edD - 2.0 * ed * Ld) / L
    return 2.0 * dlam * ed + lam * edd


@njit(cache=True)
def rows_accel(q, v, G, acc):
    """acc = (dB/dt) v of the rows (their acceleration at zero coordinate accelerations), in closed
    form at the poses of the last rows_eval: body motions (_body_motion), touching points by
    differentiating the tangency conditions twice (_tangent_accel), a W1 wrap's s by R times the
    second derivative of the wrap angle in the sheave's frame.
    (rows_accel_fd: the same by a second difference along v.)"""
    bq, b0, bk, bax, pb, po, sp, sg, sa, rk, rf, P, TW, BR, ANG, AX, SW = G
    nb = bq.shape[0]
    mo = np.empty((nb, 15))
    for b in range(nb):
        _body_motion(q, v, bq, b0, bk, bax, BR, b, mo[b])
    zero = np.zeros(15)
    nsp = sp.shape[0]
    VT = np.empty((nsp, 6))
    AT = np.empty((nsp, 6))
    aA = np.empty(3)
    aB = np.empty(3)
    S = np.empty((5, 2, 3))
    for s in range(nsp):
        iA, iB = sp[s, 0], sp[s, 1]
        aA[0], aA[1], aA[2] = _world_axis(sa, s, 0, bq, bk, BR, pb[iA])
        aB[0], aB[1], aB[2] = _world_axis(sa, s, 1, bq, bk, BR, pb[iB])
        _tangent_accel(P, iA, iB, sg[s, 0], sg[s, 2], aA, aB, mo[pb[iA]] if pb[iA] >= 0 else zero,
                       mo[pb[iB]] if pb[iB] >= 0 else zero, TW[s], VT[s], AT[s], S)
    for r in range(rk.shape[0]):
        if rk[r, 0] == ROW_TANGENT:
            acc[r] = AT[rk[r, 1], 3 * rk[r, 2] + rk[r, 3]]
            continue
        if rk[r, 0] == ROW_SLOPE:
            j = int(rf[r, 0])
            acc[r] = _slope_accel(TW[rk[r, 1]], VT[rk[r, 1]], AT[rk[r, 1]], rk[r, 3], q[j], v[j])
            continue
        k_in, k_out = rk[r, 1], rk[r, 2]
        ip = int(rf[r, 3])
        m = mo[pb[ip]] if pb[ip] >= 0 else zero
        n0, n1, n2 = _world_axis(sa, k_in, 1, bq, bk, BR, pb[ip])
        sgn = rf[r, 1]
        n0, n1, n2 = sgn * n0, sgn * n1, sgn * n2
        uc0, uc1, uc2, ac0, ac1, ac2 = _point_motion(P, ip, m)
        tot = 0.0
        rate = 0.0
        for e in range(2):
            k, o = (k_out, 0) if e == 0 else (k_in, 3)
            x0, x1, x2 = TW[k, o] - P[ip, 0], TW[k, o + 1] - P[ip, 1], TW[k, o + 2] - P[ip, 2]
            # velocity and acceleration relative to the sheave's frame (omega = m[6:9])
            w0, w1, w2 = _cross(m[6], m[7], m[8], x0, x1, x2)
            y0, y1, y2 = VT[k, o] - uc0 - w0, VT[k, o + 1] - uc1 - w1, VT[k, o + 2] - uc2 - w2
            ux0, ux1, ux2 = VT[k, o] - uc0, VT[k, o + 1] - uc1, VT[k, o + 2] - uc2
            c0, c1, c2 = _cross(m[9], m[10], m[11], x0, x1, x2)
            d0, d1, d2 = _cross(m[6], m[7], m[8], ux0, ux1, ux2)
            h0, h1, h2 = _cross(m[6], m[7], m[8], w0, w1, w2)
            z0 = AT[k, o] - ac0 - c0 - 2.0 * d0 + h0
            z1 = AT[k, o + 1] - ac1 - c1 - 2.0 * d1 + h1
            z2 = AT[k, o + 2] - ac2 - c2 - 2.0 * d2 + h2
            nx0, nx1, nx2 = _cross(n0, n1, n2, x0, x1, x2)
            xx = x0 * x0 + x1 * x1 + x2 * x2
            th = ((nx0 * z0 + nx1 * z1 + nx2 * z2) / xx
                  - 2.0 * (nx0 * y0 + nx1 * y1 + nx2 * y2) * (x0 * y0 + x1 * y1 + x2 * y2) / (xx * xx))
            tot += th if e == 0 else -th
            rt = (nx0 * y0 + nx1 * y1 + nx2 * y2) / xx
            rate += rt if e == 0 else -rt
        acc[r] = rf[r, 0] * tot
        if rf[r, RF_EA] > 0.0:
            acc[r] = _strain_wrap_accel(v, rf, SW, r, TW[k_out], VT[k_out], AT[k_out], rk[r, 3],
                                        rf[r, 0] * rate, rf[r, 0] * tot)


@njit(cache=True)
def _strain_wrap_accel(v, rf, SW, r, T, VT, AT, jsig, Ad, Add):
    """Convective acceleration of s = s2 - (s2 - sigma) phi, phi = D / (D + A) (_strain_wrap):
    -2 (s2 - sigma)' phi' - (s2 - sigma) phi'' at zero coordinate accelerations, with
    phi' = (D' A - D A') / (D + A)^2, phi'' = (D'' A - D A'') / (D + A)^2 - 2 (D' A - D A') (D' + A') / (D + A)^3;
    A' = Ad, A'' = Add (the wrap arc's rate and convective acceleration), D'' = e . (the touching
    points' convective accelerations) + (|D'|^2 - (e . D')^2) / D."""
    D, A, dl = SW[r, SW_D], SW[r, SW_A], SW[r, SW_DL]
    Dd = 0.0
    dd2 = 0.0
    ea = 0.0
    for m in range(3):
        e = (T[3 + m] - T[m]) / D
        dv = VT[3 + m] - VT[m]
        Dd += e * dv
        dd2 += dv * dv
        ea += e * (AT[3 + m] - AT[m])
    Ddd = ea + (dd2 - Dd * Dd) / D
    S = D + A
    j2 = int(rf[r, RF_J2])
    dld = (v[j2] if j2 >= 0 else 0.0) - v[jsig]
    ph1 = (Dd * A - D * Ad) / (S * S)
    ph2 = (Ddd * A - D * Add) / (S * S) - 2.0 * (Dd * A - D * Ad) * (Dd + Ad) / (S * S * S)
    return -2.0 * dld * ph1 - dl * ph2


@njit(cache=True)
def rows_accel_fd(q, v, G, cols, f0, fp, fm, qs, acc):
    """rows_accel by the second central difference of the rows along the body velocities (step
    NL_EPS; the tests' reference); f0 = f(q)."""
    rk, rf = G[9], G[10]
    sel = np.zeros(q.shape[0], np.bool_)    # body coordinates and the slope rows' stretches
    for k in range(cols.shape[0]):
        sel[cols[k]] = True
    for r in range(rk.shape[0]):
        if rk[r, 0] == ROW_SLOPE:
            sel[int(rf[r, 0])] = True
        elif rk[r, 0] == ROW_WRAP and rf[r, RF_EA] > 0.0:    # sigma and s2 of a strain wrap
            sel[rk[r, 3]] = True
            if rf[r, RF_J2] >= 0.0:
                sel[int(rf[r, RF_J2])] = True
    nrm = 0.0
    for j in range(q.shape[0]):
        if sel[j] and abs(v[j]) > nrm:
            nrm = abs(v[j])
    if nrm == 0.0:
        acc[:] = 0.0
        return
    for i in range(q.shape[0]):
        qs[i] = q[i] + (NL_EPS * v[i] / nrm if sel[i] else 0.0)
    rows_eval(qs, *G, -1, fp)
    for i in range(q.shape[0]):
        qs[i] = q[i] - (NL_EPS * v[i] / nrm if sel[i] else 0.0)
    rows_eval(qs, *G, -1, fm)
    sc = nrm * nrm / (NL_EPS * NL_EPS)
    for r in range(f0.shape[0]):
        acc[r] = (fp[r] - 2.0 * f0[r] + fm[r]) * sc
    rows_eval(q, *G, -1, fp)     # the points, tangents and contact angles of q again


@njit(cache=True)
def nl_update(K, W, c, q, v):
    """Nonlinear rows at (q, v): element maps W.el_coef <- B(q), c <- f(q) - B(q) q, W.nl_acc <- dB/dt v
    for every element coordinate that is a nonlinear row (W: the rows' scratch and the State's maps
    and contact angles, kernel.WORK_FIELDS)."""
    f0, fp, fm, J = W.nl_f0, W.nl_fp, W.nl_fm, W.nl_J
    qs = W.nl_qs
    G = (K.nl_bq, K.nl_b0, K.nl_bk, K.nl_bax, K.nl_pb, K.nl_po, K.nl_sp, K.nl_sg, K.nl_sa, K.nl_rk, K.nl_rf,
         W.nl_P, W.nl_TW, W.nl_BR, W.nl_ang, W.nl_AX, W.nl_SW)
    strain_far_s(K.nl_rk, K.nl_rf, c, W.nl_SW)
    rows_jacobian(q, G, K.nl_cols, K.nl_colbody, f0, fp, fm, qs, J)
    for i in range(q.shape[0]):     # q of this update (wrap_weight linearises the rows about it)
        qs[i] = q[i]
    acc = W.nl_racc
    at_rest = True
    for j in range(v.shape[0]):
        if v[j] != 0.0:
            at_rest = False
            break
    if at_rest:           # statics: no convective accelerations
        acc[:] = 0.0
    else:
        rows_accel(q, v, G, acc)
    el_idx, el_map, el_coef, ent, rw = K.el_idx, K.el_map, W.el_coef, K.nl_ent, K.nl_rw
    for ie in range(ent.shape[0]):
        for a in range(ent.shape[1]):
            r = ent[ie, a]
            if r < 0:
                continue
            x = f0[r]
            for w in range(el_map.shape[2]):
                k = rw[r, w]
                b = 0.0 if k == -1 else (extra_coef(K.nl_rk, K.nl_rf, W.nl_TW, W.nl_SW, r, k) if k < -1
                                         else J[r, k])
                el_coef[ie, a, w] = b
                x -= b * q[el_map[ie, a, w]]
            c[el_idx[ie, a]] = x
            W.nl_acc[ie, a] = acc[r]


@njit(cache=True)
def strain_far_s(rk, rf, c, SW):
    """SW[r, SW_C] <- the constant part of a strain wrap's far s (c of its node's row: the rope's length
    at a rope end)."""
    for r in range(rk.shape[0]):
        if rf[r, RF_EA] > 0.0:
            SW[r, SW_C] = c[int(rf[r, RF_ROW])]


@njit(cache=True)
def wrap_weight(K, W, Q, q, energy):
    """The weight of the rope a W1 wrap gains or loses as its angle changes: V = -(l_w(q) - lw) rhoA g.c
    per wrap (l_w = s_out - sigma, c the sheave centre, lw the lumped part). Without it the span
    elements' gravity potential, which counts material leaving a span at the span's mid-height, makes a
    spurious force rhoA g.(span mid - c) R d(wrap angle)/dq. Q -= dV/dq = rhoA g.c d l_w/dq (the rope
    moved) + rhoA (l_w - lw) g.dc/dq (the centre moving under the unlumped rope).
    A wrap at its leaving span's strain (l_w = A / lambda, A = R x angle) adds its rope's strain energy
    (_wrap_strain) and counts its stretch deficit l_w - A at the leaving span's middle m instead of at
    c, V = -rhoA g.((l_w - lw) c + (l_w - A)(m - c)): the material that moves between the wrap and the
    span as the span's chord D changes then weighs where the span's element counts it, so a payload
    hanging from a one-element span carries M g at its end (at c: a force rhoA g.(m - c) A/(D + A)
    per unit chord, 1.2e-4 of M g on the slewing crane). energy: return V instead (after nl_update
    on W)."""
    rk, rf, P, J, cols, f0, pb, TW, SW = K.nl_rk, K.nl_rf, W.nl_P, W.nl_J, K.nl_cols, W.nl_f0, K.nl_pb, W.nl_TW, W.nl_SW
    nr = rk.shape[0]
    V = 0.0
    for r in range(nr):
        if rk[r, 0] != ROW_WRAP:
            continue
        ip = int(rf[r, 3])
        gc = rf[r, 4] * P[ip, 0] + rf[r, 5] * P[ip, 1] + rf[r, 6] * P[ip, 2]
        sig = q[rk[r, 3]]
        f = f0[r]
        strain = rf[r, RF_EA] > 0.0
        gm = gc      # the weight's coefficient of d l_w
        dmat = 0.0   # s2 - sigma
        D, A = SW[r, SW_D], SW[r, SW_A]
        if strain:
            # q as it is now: f0, D, A are those of the last update, which the Newton matrix's
            # differences keep (W.frz); sigma, s2 and, to first order (rows_jacobian), D and A follow q
            j2 = int(rf[r, RF_J2])
            s2 = SW[r, SW_C] + (q[j2] if j2 >= 0 else 0.0)
            dA = 0.0
            dD = 0.0
            for k in range(cols.shape[0]):
                dx = q[cols[k]] - W.nl_qs[cols[k]]
                dA += J[nr + r, k] * dx
                dD += J[2 * nr + r, k] * dx
            A += dA
            D += dD
            f = (sig * D + A * s2) / (D + A)
            dmat = s2 - sig
            V += _wrap_strain(K, W, Q, r, D, A, dmat, energy)
            ko = rk[r, 2]
            gm = 0.5 * (rf[r, 4] * (TW[ko, 0] + TW[ko, 3]) + rf[r, 5] * (TW[ko, 1] + TW[ko, 4])
                        + rf[r, 6] * (TW[ko, 2] + TW[ko, 5]))
        dl = f - sig - rf[r, 7]
        lx = f - sig - A if strain else 0.0     # l_w - A
        if energy:
            V -= dl * gc + lx * (gm - gc)
            continue
        if strain:     # l_w = s - sigma also moves with sigma and s2
            Q[rk[r, 3]] += gm * (D / (D + A) - 1.0)
            if rf[r, RF_J2] >= 0.0:
                Q[int(rf[r, RF_J2])] += gm * A / (D + A)
        for k in range(cols.shape[0]):
            Q[cols[k]] += gm * J[r, k]
            if strain:
                Q[cols[k]] += lx * J[3 * nr + r, k] - (gm - gc) * J[nr + r, k]
            b = K.nl_colbody[k]
            if _on(K.nl_bq, K.nl_bk, pb[ip], b):
                v0, v1, v2, w0, w1, w2, O0, O1, O2 = _twist(q, K.nl_bq, K.nl_b0, K.nl_bk, K.nl_bax, W.nl_BR, b,
                                                            cols[k])
                c0, c1, c2 = _moved(P, ip, True, v0, v1, v2, w0, w1, w2, O0, O1, O2)
                Q[cols[k]] += (dl - lx) * (rf[r, 4] * c0 + rf[r, 5] * c1 + rf[r, 6] * c2)
    return V


@njit(cache=True)
def _wrap_strain(K, W, Q, r, D, A, dl, energy):
    """Strain energy of the rope on a wrap that holds it at its leaving span's strain (_strain_wrap):
    U = l_w w(lambda), l_w = A Delta / S, lambda = S / Delta (S = D + A, Delta = s2 - sigma: the wrap
    and the span are one stretch of rope; w the elements' axial law). Q -= dU/dq through A and D
    (their q-derivatives kept by rows_jacobian below the rows' Jacobian), sigma and s2 (D, A, dl =
    s2 - sigma: wrap_weight's, at q). energy: return U (Q untouched), else 0."""
    rk, rf, J, cols = K.nl_rk, K.nl_rf, W.nl_J, K.nl_cols
    nr = rk.shape[0]
    S = D + A
    lam = S / dl
    el = int(rf[r, RF_EL])     # the element's law (a statics may swap tension-only for bilateral)
    N, w, _ = axial_law(K.el_EA[el], 0.0, lam - 1.0, 0.0, K.el_tonly[el] != 0)
    if energy:
        return A * dl / S * w
    UA = dl * D * w / (S * S) + A * N / S
    UD = -A * dl * w / (S * S) + A * N / S
    Ud = A * (w - N * lam) / S
    for k in range(cols.shape[0]):
        Q[cols[k]] -= UA * J[nr + r, k] + UD * J[2 * nr + r, k]
    Q[rk[r, 3]] += Ud
    if rf[r, RF_J2] >= 0.0:
        Q[int(rf[r, RF_J2])] -= Ud
    return 0.0


@njit(cache=True, inline="always")
def nl_convect(W, MEs, QEs, ie):
    """QEs[ie] -= MEs[ie] (dB/dt qdot) for element ie: the part of the nodes' acceleration that is
    not B qddot (centripetal terms of rotating bodies, turning tangent points)."""
    acc = W.nl_acc
    ne = QEs.shape[1]
    for a in range(ne):
        s = 0.0
        for b in range(ne):
            s += MEs[ie, a, b] * acc[ie, b]
        QEs[ie, a] -= s


# The kernel fields of the geometry rows_eval reads (the first 11 of its tuple G); the last six are
# scratch and warm start: points, span tangents, body rotations, contact angles, axes, strain wraps
# (geometry()).
GEOMETRY_FIELDS = ("nl_bq", "nl_b0", "nl_bk", "nl_bax", "nl_pb", "nl_po", "nl_sp", "nl_sg", "nl_sa", "nl_rk",
                   "nl_rf")


def geometry(K, ang=None, c=None):
    """rows_eval's tuple G for kernel fields K (a Kernel or any object with them) with fresh scratch;
    ang: the contact angles' warm start (default: K.nl_ang0's copy; NaN: from the coplanar formula);
    c: the model's c (the strain wraps' far s at rope ends; default: zero)."""
    nsp = K.nl_sp.shape[0]
    SW = np.zeros((K.nl_rk.shape[0], SW_WIDTH))
    if c is not None:
        strain_far_s(K.nl_rk, K.nl_rf, np.asarray(c, float), SW)
    return tuple(getattr(K, f) for f in GEOMETRY_FIELDS) + (
        np.zeros((K.nl_pb.shape[0], 3)), np.zeros((nsp, 6)), np.zeros((K.nl_bq.shape[0], 5)),
        K.nl_ang0.copy() if ang is None else ang, np.zeros((2, 3)), SW)
