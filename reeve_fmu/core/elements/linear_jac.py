"""Closed-form Jacobian of the linear ALE element's inertia terms (elements/linear.py).

With D = r2 - r1, l = s2 - s1, p = D / l the mass matrix is M = rhoA [l/3, l/6 on the node blocks;
-D/3, -D/6 node-s; |D|^2/(3l), |D|^2/(6l) s-s], so (M a) is explicit in (D, l), and the
quadratic-velocity vector depends on q only through p:

    Q_1  = rhoA [(V - p ldot) w1/3 + (v1 - p sd1) sd1]
    Q_2  = rhoA [(V - p ldot) w2/3 - (v2 - p sd2) sd2]
    Q_s1 = rhoA [-p.(V - p ldot) w1/3 - sd1 p.(v1 - p sd1) - |v1 - p sd1|^2 / 2]
    Q_s2 = rhoA [-p.(V - p ldot) w2/3 + sd2 p.(v2 - p sd2) + |v2 - p sd2|^2 / 2]

(V = v2 - v1, ldot = sd2 - sd1, w1 = 2 sd1 + sd2, w2 = sd1 + 2 sd2; gravity is in jacobian.linear_stiffness).
`linear_inertia` adds bq (d(M a)/dq - dQ_v/dq) + gv (-dQ_v/dv) to the element block.
"""
from __future__ import annotations

from .._jit import njit


@njit(cache=True, inline="always")
def linear_inertia(nd, rhoA, QE, VE, ie, ae, bq, gv, JE):
    """Adds the inertia terms' Newton-matrix block (module doc) of element ie to JE (ne x ne)."""
    i1 = 2 * nd
    i2 = i1 + 1
    l = QE[ie, i2] - QE[ie, i1]
    sd1 = VE[ie, i1]
    sd2 = VE[ie, i2]
    ld = sd2 - sd1
    w1 = 2.0 * sd1 + sd2
    w2 = sd1 + 2.0 * sd2
    al1 = ae[i1] / 3.0 + ae[i2] / 6.0
    al2 = ae[i1] / 6.0 + ae[i2] / 3.0
    pp = 0.0
    g = 0.0
    for k in range(nd):
        p = (QE[ie, nd + k] - QE[ie, k]) / l
        pp += p * p
        g += p * (VE[ie, nd + k] - VE[ie, k] - p * ld)
    bm = bq * rhoA
    ca = -ld * w1 / 3.0 - sd1 * sd1      # dQ_1k / dp_k / rhoA
    cb = -ld * w2 / 3.0 + sd2 * sd2      # dQ_2k / dp_k / rhoA
    s1p = 0.0                            # sum_j dQ_s / dp_j p_j (the l column)
    s2p = 0.0
    for k in range(nd):
        n2 = nd + k
        p = (QE[ie, n2] - QE[ie, k]) / l
        V = VE[ie, n2] - VE[ie, k]
        rA = VE[ie, k] - p * sd1
        rB = VE[ie, n2] - p * sd2
        A1 = ae[k] / 3.0 + ae[n2] / 6.0
        A2 = ae[k] / 6.0 + ae[n2] / 3.0
        # d(M a)/dq: node rows through m = rhoA l and D, s rows through D and |D|^2 / l
        JE[k, i2] += bm * A1
        JE[k, i1] -= bm * A1
        JE[n2, i2] += bm * A2
        JE[n2, i1] -= bm * A2
        JE[k, n2] -= bm * al1
        JE[k, k] += bm * al1
        JE[n2, n2] -= bm * al2
        JE[n2, k] += bm * al2
        c1 = bm * (-A1 + 2.0 * p * al1)
        c2 = bm * (-A2 + 2.0 * p * al2)
        JE[i1, n2] += c1
        JE[i1, k] -= c1
        JE[i2, n2] += c2
        JE[i2, k] -= c2
        # -dQ_v/dq = -(dQ_v/dp)(dp/dq), dp/dr2 = I/l = -dp/dr1, dp/dl = -p/l
        JE[k, n2] -= bm * ca / l
        JE[k, k] += bm * ca / l
        JE[k, i2] += bm * ca * p / l
        JE[k, i1] -= bm * ca * p / l
        JE[n2, n2] -= bm * cb / l
        JE[n2, k] += bm * cb / l
        JE[n2, i2] += bm * cb * p / l
        JE[n2, i1] -= bm * cb * p / l
        e1 = -(V - 2.0 * p * ld) * w1 / 3.0 + sd1 * sd1 * p
        e2 = -(V - 2.0 * p * ld) * w2 / 3.0 - sd2 * sd2 * p
        JE[i1, n2] -= bm * e1 / l
        JE[i1, k] += bm * e1 / l
        JE[i2, n2] -= bm * e2 / l
        JE[i2, k] += bm * e2 / l
        s1p += e1 * p
        s2p += e2 * p
        # gv (-dQ_v/dv)
        gm = gv * rhoA
        JE[k, k] -= gm * (sd1 - w1 / 3.0)
        JE[k, n2] -= gm * w1 / 3.0
        JE[k, i1] -= gm * (p * w1 / 3.0 + 2.0 * (V - p * ld) / 3.0 + rA - p * sd1)
        JE[k, i2] -= gm * (-p * w1 / 3.0 + (V - p * ld) / 3.0)
        JE[n2, k] += gm * w2 / 3.0
        JE[n2, n2] -= gm * (w2 / 3.0 - sd2)
        JE[n2, i1] -= gm * (p * w2 / 3.0 + (V - p * ld) / 3.0)
        JE[n2, i2] -= gm * (-p * w2 / 3.0 + 2.0 * (V - p * ld) / 3.0 - rB + p * sd2)
        JE[i1, k] -= gm * (p * w1 / 3.0 - sd1 * p - rA)
        JE[i1, n2] += gm * p * w1 / 3.0
        JE[i2, k] -= gm * p * w2 / 3.0
        JE[i2, n2] -= gm * (-p * w2 / 3.0 + sd2 * p + rB)
    # l columns of d(M a)_s / dq: -rhoA |D|^2 / l^2 (alpha) = -rhoA pp alpha
    JE[i1, i2] -= bm * pp * al1
    JE[i1, i1] += bm * pp * al1
    JE[i2, i2] -= bm * pp * al2
    JE[i2, i1] += bm * pp * al2
    JE[i1, i2] += bm * s1p / l
    JE[i1, i1] -= bm * s1p / l
    JE[i2, i2] += bm * s2p / l
    JE[i2, i1] -= bm * s2p / l
    gm = gv * rhoA
    JE[i1, i1] -= gm * (-pp * w1 / 3.0 - 2.0 * g / 3.0 + sd1 * pp)
    JE[i1, i2] -= gm * (pp * w1 / 3.0 - g / 3.0)
    JE[i2, i1] -= gm * (-pp * w2 / 3.0 - g / 3.0)
    JE[i2, i2] -= gm * (pp * w2 / 3.0 - 2.0 * g / 3.0 - sd2 * pp)
