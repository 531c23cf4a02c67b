"""Rotational inertia of the spatial rigid bodies ('rotation' in free; compiled): the mass matrix of
the rotation vector and its quadratic-velocity force, in closed form (rigid_terms) and by central
differences of the Lagrangian (rigid_terms_fd, the tests' reference)."""
from __future__ import annotations

import math

import numpy as np

from ._jit import njit
from .bodies import rot_coefs


RB_H = 1e-6   # rad: central-difference step of the rotational mass matrix M(phi)


@njit(cache=True, inline="always")
def _rot_maps(p0, p1, p2, a, b, s1, T, R):
    """T = I + a P + b P^2 (the map phi_dot -> world angular velocity) and R = I + s1 P + a P^2 (the
    orientation, Rodrigues) of the rotation vector phi, P = phi^, P^2 = phi phi^T - th2 I; a, b, s1
    are (1 - cos)/th^2, (th - sin)/th^3, sin/th."""
    th2 = p0 * p0 + p1 * p1 + p2 * p2
    P = ((0.0, -p2, p1), (p2, 0.0, -p0), (-p1, p0, 0.0))
    ph = (p0, p1, p2)
    for i in range(3):
        for k in range(3):
            p2ik = ph[i] * ph[k] - (th2 if i == k else 0.0)
            e = 1.0 if i == k else 0.0
            T[i, k] = e + a * P[i][k] + b * p2ik
            R[i, k] = e + s1 * P[i][k] + a * p2ik


@njit(cache=True, inline="always")
def _congruence(X, J, out):
    """out = X^T J X (3 x 3), summed in a fixed order."""
    for i in range(3):
        for k in range(3):
            acc = 0.0
            for r in range(3):
                for c in range(3):
                    acc += X[r, i] * J[r, c] * X[c, k]
            out[i, k] = acc


@njit(cache=True, inline="always")
def _rot_mass(p0, p1, p2, J, out):
    """out = T^T R J R^T T: the mass matrix of the rotation vector phi, with R = exp(phi^) (the
    orientation from the scene's) and T(phi) the map phi_dot -> world angular velocity. Written out
    with scalars and fixed-size loops (no temporaries: it runs 7 times per residual and body)."""
    th2 = p0 * p0 + p1 * p1 + p2 * p2
    th = math.sqrt(th2)
    if th < 1e-4:   # series of (1 - cos)/th^2, (th - sin)/th^3 and sin/th
        a = 0.5 - th2 / 24.0
        b = 1.0 / 6.0 - th2 / 120.0
        s1 = 1.0 - th2 / 6.0
    else:
        a = (1.0 - math.cos(th)) / th2
        b = (th - math.sin(th)) / (th2 * th)
        s1 = math.sin(th) / th
    T = np.empty((3, 3))
    R = np.empty((3, 3))
    _rot_maps(p0, p1, p2, a, b, s1, T, R)
    # W = R^T T (body angular velocity map); out = W^T J W
    W = np.empty((3, 3))
    for i in range(3):
        for k in range(3):
            W[i, k] = R[0, i] * T[0, k] + R[1, i] * T[1, k] + R[2, i] * T[2, k]
    _congruence(W, J, out)


@njit(cache=True)
def rigid_terms_fd(K, q, v, M, Q):
    """rigid_terms from the Lagrangian by central differences of M_r (step RB_H; the tests'
    reference): M[phi, phi] += M_r(phi) and the quadratic-velocity force
    -M_r' phi_dot + d/dphi (phi_dot^T M_r phi_dot / 2)."""
    Mr = np.empty((3, 3))
    Mp = np.empty((3, 3))
    Mm = np.empty((3, 3))
    p = np.empty(3)
    w = np.empty(3)
    dMw = np.empty(3)
    for k in range(K.rb_q.shape[0]):
        for a in range(3):
            p[a] = q[K.rb_q[k, a]]
            w[a] = v[K.rb_q[k, a]]
            dMw[a] = 0.0
        J = K.rb_J[k]
        _rot_mass(p[0], p[1], p[2], J, Mr)
        for a in range(3):
            for b in range(3):
                M[K.rb_q[k, a], K.rb_q[k, b]] += Mr[a, b]
        if w[0] == 0.0 and w[1] == 0.0 and w[2] == 0.0:
            continue
        # dM_r/dt w = sum_c (dM_r/dphi_c) w_c w, and d/dphi_c of w^T M_r w / 2
        for c in range(3):
            p[c] += RB_H
            _rot_mass(p[0], p[1], p[2], J, Mp)
            p[c] -= 2.0 * RB_H
            _rot_mass(p[0], p[1], p[2], J, Mm)
            p[c] += RB_H
            dT = 0.0
            for a in range(3):
                for b in range(3):
                    dM = (Mp[a, b] - Mm[a, b]) / (2.0 * RB_H)
                    dMw[a] += dM * w[c] * w[b]
                    dT += 0.5 * w[a] * dM * w[b]
            Q[K.rb_q[k, c]] += dT
        for a in range(3):
            Q[K.rb_q[k, a]] -= dMw[a]


@njit(cache=True)
def rigid_terms(K, q, v, M, Q):
    """Rotational inertia of the spatial rigid bodies in closed form. With the world angular velocity
    w = T phi_dot and the world inertia J_w = R J R^T, the Euler equations
    J_w (T phi_ddot + dT/dt phi_dot) + w x J_w w = torque, projected by T^T (virtual work), give
    M[phi, phi] += T^T J_w T and Q[phi] -= T^T (J_w dT/dt phi_dot + w x J_w w), where
    dT/dt phi_dot = (phi . phi_dot) (ca phi x phi_dot + cb phi x (phi x phi_dot)) + b phi_dot x (phi x phi_dot)."""
    T = np.empty((3, 3))
    R = np.empty((3, 3))
    Jw = np.empty((3, 3))
    g = np.empty(3)
    for k in range(K.rb_q.shape[0]):
        i0, i1, i2 = K.rb_q[k, 0], K.rb_q[k, 1], K.rb_q[k, 2]
        p0, p1, p2 = q[i0], q[i1], q[i2]
        a, b, s1, ca, cb = rot_coefs(p0, p1, p2)
        _rot_maps(p0, p1, p2, a, b, s1, T, R)
        J = K.rb_J[k]
        _congruence(R.T, J, Jw)       # J_w = R J R^T
        d0, d1, d2 = v[i0], v[i1], v[i2]
        w0 = T[0, 0] * d0 + T[0, 1] * d1 + T[0, 2] * d2
        w1 = T[1, 0] * d0 + T[1, 1] * d1 + T[1, 2] * d2
        w2 = T[2, 0] * d0 + T[2, 1] * d1 + T[2, 2] * d2
        x0, x1, x2 = p1 * d2 - p2 * d1, p2 * d0 - p0 * d2, p0 * d1 - p1 * d0       # phi x phi_dot
        y0, y1, y2 = p1 * x2 - p2 * x1, p2 * x0 - p0 * x2, p0 * x1 - p1 * x0       # phi x (phi x phi_dot)
        z0, z1, z2 = d1 * x2 - d2 * x1, d2 * x0 - d0 * x2, d0 * x1 - d1 * x0       # phi_dot x (phi x phi_dot)
        pd = p0 * d0 + p1 * d1 + p2 * d2
        t0 = pd * (ca * x0 + cb * y0) + b * z0
        t1 = pd * (ca * x1 + cb * y1) + b * z1
        t2 = pd * (ca * x2 + cb * y2) + b * z2
        h0 = Jw[0, 0] * w0 + Jw[0, 1] * w1 + Jw[0, 2] * w2
        h1 = Jw[1, 0] * w0 + Jw[1, 1] * w1 + Jw[1, 2] * w2
        h2 = Jw[2, 0] * w0 + Jw[2, 1] * w1 + Jw[2, 2] * w2
        g[0] = Jw[0, 0] * t0 + Jw[0, 1] * t1 + Jw[0, 2] * t2 + w1 * h2 - w2 * h1
        g[1] = Jw[1, 0] * t0 + Jw[1, 1] * t1 + Jw[1, 2] * t2 + w2 * h0 - w0 * h2
        g[2] = Jw[2, 0] * t0 + Jw[2, 1] * t1 + Jw[2, 2] * t2 + w0 * h1 - w1 * h0
        for m in range(3):
            Q[K.rb_q[k, m]] -= T[0, m] * g[0] + T[1, m] * g[1] + T[2, m] * g[2]
            for n in range(3):
                acc = 0.0
                for i in range(3):
                    for r in range(3):
                        acc += T[i, m] * Jw[i, r] * T[r, n]
                M[K.rb_q[k, m], K.rb_q[k, n]] += acc


# Columns of Kernel.ch_f, one row per body on a joint on a moving body (builder/bodies.chain_fields):
# parent's kind (0 revolute, 1 prismatic), axis, pivot; own kind, axis, pivot (scene's pose); centre of
# mass at the scene's pose; mass; gravity; inertia tensor about the centre of mass (scene axes, 9)
CH_PK, CH_PA, CH_PP, CH_CK, CH_CA, CH_CP, CH_X0, CH_M, CH_G, CH_J = 0, 1, 4, 7, 8, 11, 14, 17, 18, 21
CH_SIZE = 30


@njit(cache=True, inline="always")
def _turn(a0, a1, a2, c, s, v0, v1, v2):
    """v turned by the angle (cos c, sin s) about the unit axis a (Rodrigues)."""
    d = (a0 * v0 + a1 * v1 + a2 * v2) * (1.0 - c)
    return (v0 * c + (a1 * v2 - a2 * v1) * s + a0 * d, v1 * c + (a2 * v0 - a0 * v2) * s + a1 * d,
            v2 * c + (a0 * v1 - a1 * v0) * s + a2 * d)


@njit(cache=True, inline="always")
def _cr(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, inline="always")
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, inline="always")
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, inline="always")
def _axpy(s, a, b):
    """s a + b."""
    return (s * a[0] + b[0], s * a[1] + b[1], s * a[2] + b[2])


@njit(cache=True, inline="always")
def _about(a, c, s, p, x):
    """x turned by (cos c, sin s) about the axis a through p."""
    r = _turn(a[0], a[1], a[2], c, s, x[0] - p[0], x[1] - p[1], x[2] - p[2])
    return (p[0] + r[0], p[1] + r[1], p[2] + r[2])


@njit(cache=True, inline="always")
def _vec(f, i):
    return (f[i], f[i + 1], f[i + 2])


@njit(cache=True, inline="always")
def _jw(J, rot, u):
    """R J R^T u for R = R_parent R_own, rot = (parent axis, cos, sin, own axis, cos, sin); J row-major."""
    pa0, pa1, pa2, cp, sp, ca0, ca1, ca2, cc, sc = rot
    b = _turn(pa0, pa1, pa2, cp, -sp, u[0], u[1], u[2])
    b = _turn(ca0, ca1, ca2, cc, -sc, b[0], b[1], b[2])
    jb = (J[0] * b[0] + J[1] * b[1] + J[2] * b[2], J[3] * b[0] + J[4] * b[1] + J[5] * b[2],
          J[6] * b[0] + J[7] * b[1] + J[8] * b[2])
    r = _turn(ca0, ca1, ca2, cc, sc, jb[0], jb[1], jb[2])
    return _turn(pa0, pa1, pa2, cp, sp, r[0], r[1], r[2])


@njit(cache=True)
def chain_terms(K, q, v, M, Q):
    """Mass, weight and velocity terms of the bodies on a joint on a moving body (a trolley on a slewing
    jib, a boom luffing on a slewing superstructure), by projecting Newton-Euler on the two joint
    coordinates (parent's p, own c). With J_i the velocity of the centre of mass and W_i the angular
    velocity per unit rate of coordinate i, M[i, j] += m J_i.J_j + W_i.J_w W_j and
    Q[i] += m g.J_i - m J_i.a_q - W_i.(J_w al_q + w x J_w w): a_q = w_p x (w_p x r_p) + 2 w_p x u_rel +
    w_r x (w_r x r_c) the centre's acceleration at zero coordinate accelerations (centripetal, Coriolis),
    al_q = w_p x w_r; J_w = R J R^T the world inertia tensor. Scalars and tuples only (no arrays: it
    runs in every residual)."""
    zero = (0.0, 0.0, 0.0)
    for k in range(K.ch_q.shape[0]):
        f = K.ch_f[k]
        ip, ic = K.ch_q[k, 0], K.ch_q[k, 1]
        pa, pp, ca, cp = _vec(f, CH_PA), _vec(f, CH_PP), _vec(f, CH_CA), _vec(f, CH_CP)
        m = f[CH_M]
        rev_p, rev_c = f[CH_PK] == 0.0, f[CH_CK] == 0.0
        # own joint in the parent's frame at the scene's pose, then the parent's motion
        cc, sc, cpa, spa = 1.0, 0.0, 1.0, 0.0
        y = _vec(f, CH_X0)
        if rev_c:
            cc, sc = math.cos(q[ic]), math.sin(q[ic])
            y = _about(ca, cc, sc, cp, y)
        else:
            y = _axpy(q[ic], ca, y)
        if rev_p:
            cpa, spa = math.cos(q[ip]), math.sin(q[ip])
            x, xp = _about(pa, cpa, spa, pp, y), _about(pa, cpa, spa, pp, cp)
        else:
            x, xp = _axpy(q[ip], pa, y), _axpy(q[ip], pa, cp)
        aw = _turn(pa[0], pa[1], pa[2], cpa, spa, ca[0], ca[1], ca[2])       # own axis, world
        Jp, Wp = (_cr(pa, _sub(x, pp)), pa) if rev_p else (pa, zero)
        Jc, Wc = (_cr(aw, _sub(x, xp)), aw) if rev_c else (aw, zero)
        vp, vc = v[ip], v[ic]
        wp = (Wp[0] * vp, Wp[1] * vp, Wp[2] * vp)
        wr = (Wc[0] * vc, Wc[1] * vc, Wc[2] * vc)
        w = (wp[0] + wr[0], wp[1] + wr[1], wp[2] + wr[2])
        cor = _cr(wp, (Jc[0] * vc, Jc[1] * vc, Jc[2] * vc))
        aq = _axpy(2.0, cor, _cr(wr, _cr(wr, _sub(x, xp))))
        if rev_p:
            cen = _cr(wp, _cr(wp, _sub(x, pp)))
            aq = (aq[0] + cen[0], aq[1] + cen[1], aq[2] + cen[2])
        alq = _cr(wp, wr)
        # world inertia tensor J_w = R J R^T, R = R_parent R_own (_jw applies it to a vector)
        Jm = f[CH_J:CH_J + 9]
        rot = (pa[0], pa[1], pa[2], cpa, spa, ca[0], ca[1], ca[2], cc, sc)
        h = _jw(Jm, rot, w)
        e = _axpy(1.0, _jw(Jm, rot, alq), _cr(w, h))
        JWp, JWc = _jw(Jm, rot, Wp), _jw(Jm, rot, Wc)
        g = _vec(f, CH_G)
        Q[ip] += m * _dot(g, Jp) - m * _dot(Jp, aq) - _dot(Wp, e)
        Q[ic] += m * _dot(g, Jc) - m * _dot(Jc, aq) - _dot(Wc, e)
        M[ip, ip] += m * _dot(Jp, Jp) + _dot(Wp, JWp)
        M[ic, ic] += m * _dot(Jc, Jc) + _dot(Wc, JWc)
        mpc = m * _dot(Jp, Jc) + _dot(Wp, JWc)
        M[ip, ic] += mpc
        M[ic, ip] += mpc


@njit(cache=True)
def chain_potential(K, q):
    """Gravity potential -m g.x of the bodies on a joint on a moving body (their centres of mass x)."""
    V = 0.0
    for k in range(K.ch_q.shape[0]):
        f = K.ch_f[k]
        ip, ic = K.ch_q[k, 0], K.ch_q[k, 1]
        pa, pp, ca, cp = f[CH_PA:CH_PA + 3], f[CH_PP:CH_PP + 3], f[CH_CA:CH_CA + 3], f[CH_CP:CH_CP + 3]
        x0, x1, x2 = f[CH_X0], f[CH_X0 + 1], f[CH_X0 + 2]
        if f[CH_CK] == 0.0:
            r0, r1, r2 = _turn(ca[0], ca[1], ca[2], math.cos(q[ic]), math.sin(q[ic]), x0 - cp[0], x1 - cp[1],
                               x2 - cp[2])
            x0, x1, x2 = cp[0] + r0, cp[1] + r1, cp[2] + r2
        else:
            x0, x1, x2 = x0 + q[ic] * ca[0], x1 + q[ic] * ca[1], x2 + q[ic] * ca[2]
        if f[CH_PK] == 0.0:
            r0, r1, r2 = _turn(pa[0], pa[1], pa[2], math.cos(q[ip]), math.sin(q[ip]), x0 - pp[0], x1 - pp[1],
                               x2 - pp[2])
            x0, x1, x2 = pp[0] + r0, pp[1] + r1, pp[2] + r2
        else:
            x0, x1, x2 = x0 + q[ip] * pa[0], x1 + q[ip] * pa[1], x2 + q[ip] * pa[2]
        V -= f[CH_M] * (f[CH_G] * x0 + f[CH_G + 1] * x1 + f[CH_G + 2] * x2)
    return V
