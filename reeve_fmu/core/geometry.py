"""Rope-sheave tangent points (docs/theory.md §4.2).

A route stop is a circle (centre c, radius R, unit axis a, wrap sense sigma = +1 for a positive
rotation about a) or a point (R = 0). The rope leaves stop A and arrives at stop B along the common
tangent whose direction agrees with both wrap senses.

Coplanar case (parallel axes, every planar scene): closed form. With travel direction t and left
normal n = a x t the touching point is T = c - sigma R n, and n.(c_B - c_A) = sigma_B R_B - sigma_A R_A
fixes the direction uniquely: theta = psi - asin((rho_B - rho_A)/L). General 3D: Newton on the two
contact angles from that planar start (the segment is perpendicular to both radii, Exudyn's
algorithm), then the sense is checked.
"""
from __future__ import annotations

import math

import numpy as np


class GeometryError(ValueError):
    pass


def _basis(a):
    a = np.asarray(a, float)
    h = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = h - a * (h @ a)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def _planar(cA, RA, sA, cB, RB, sB, a):
    u, v = _basis(a)
    D = cB - cA
    Du, Dv = D @ u, D @ v
    L = math.hypot(Du, Dv)
    rho = sB * RB - sA * RA
    if L <= abs(rho) + 1e-12:
        raise GeometryError(f"no common tangent: circles overlap (centre distance {L:.4g} m, "
                            f"radius term {abs(rho):.4g} m)")
    theta = math.atan2(Dv, Du) - math.asin(rho / L)
    t = math.cos(theta) * u + math.sin(theta) * v
    n = np.cross(a, t)
    return cA - sA * RA * n, cB - sB * RB * n


def tangent(cA, RA, aA, sA, cB, RB, aB, sB):
    """Touching points (TA, TB) of the span leaving circle/point A and arriving at circle/point B."""
    cA, cB = np.asarray(cA, float), np.asarray(cB, float)
    aA = np.asarray(aA, float) if RA > 0 else None
    aB = np.asarray(aB, float) if RB > 0 else None
    ref = aA if aA is not None else aB
    if ref is None:
        if np.linalg.norm(cB - cA) < 1e-12:
            raise GeometryError("span of zero length between two points")
        return cA.copy(), cB.copy()
    coplanar = ((aA is None or aB is None or abs(abs(aA @ aB) - 1) < 1e-12)
                and abs((cB - cA) @ ref) < 1e-12)
    TA, TB = _planar(cA, RA, sA, cB, RB, sB, ref)
    if coplanar:
        return TA, TB
    # 3D: unknown contact angles, equations (TB - TA).rhoA = 0, (TB - TA).rhoB = 0
    circles = [(cA, RA, aA, TA), (cB, RB, aB, TB)]
    phis, frames = [], []
    for c, R, a, T in circles:
        if R > 0:
            u, v = _basis(a)
            d = T - c
            phis.append(math.atan2(d @ v, d @ u))
            frames.append((u, v))
        else:
            frames.append(None)

    def points(x):
        out, k = [], 0
        for (c, R, a, _), fr in zip(circles, frames):
            if fr is None:
                out.append(c)
            else:
                u, v = fr
                out.append(c + R * (math.cos(x[k]) * u + math.sin(x[k]) * v))
                k += 1
        return out

    def resid(x):
        PA, PB = points(x)
        D = PB - PA
        r = []
        for (c, R, a, _), P in zip(circles, (PA, PB)):
            if R > 0:
                r.append(D @ (P - c) / R)
        return np.array(r)

    x = np.array(phis, float)
    # residuals are lengths (D . radius_unit): tolerance relative to the scene's coordinate scale,
    # an absolute 1e-13 m is below round-off ~100 m from the origin
    tol = 1e-13 * max(1.0, float(np.max(np.abs(cA))), float(np.max(np.abs(cB))), float(np.linalg.norm(cB - cA)))
    for _ in range(50):
        r = resid(x)
        if np.max(np.abs(r)) < tol:
            break
        J = np.empty((len(x), len(x)))
        for j in range(len(x)):
            dx = np.zeros_like(x)
            dx[j] = 1e-7
            J[:, j] = (resid(x + dx) - resid(x - dx)) / 2e-7
        x = x - np.linalg.solve(J, r)
    else:
        raise GeometryError("3D tangent iteration did not converge")
    TA, TB = points(x)
    D = TB - TA
    for (c, R, a, _), P, s in ((circles[0], TA, sA), (circles[1], TB, sB)):
        if R > 0 and D @ (s * np.cross(a, P - c)) <= 0:
            raise GeometryError("3D tangent converged to a span with the wrong wrap sense")
    return TA, TB


def wrap_angle(c, a, sigma, T_in, T_out):
    """Angle [0, 2 pi) swept by the rope from T_in to T_out around centre c in the sense sigma*a."""
    a = sigma * np.asarray(a, float)
    u, v = _basis(a)
    p, q = T_in - c, T_out - c
    ang = math.atan2(q @ v, q @ u) - math.atan2(p @ v, p @ u)
    return ang % (2.0 * math.pi)
