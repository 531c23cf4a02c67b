"""One generalized-alpha step by Newton's method on the free accelerations (docs/theory.md §4.7):
the residual M qdd - Q of the free rows, the Newton matrix (dense: finite differences, banded:
element Jacobians or coloured differences, core/jacobian.py and core/sparse.py), modified Newton
with the matrix kept across steps and full-Newton retries."""
from __future__ import annotations

import numpy as np

from .._jit import gated, njit
from ..jacobian import jacobian_analytic
from ..kernel import CREEP, IN_ITERS, IN_JACS, IN_JAC_H, IN_WHERE, NL_ROWS
from ..sparse import bordered_solve, jacobian_sparse, residual_sparse
from ..system import assemble_ws, set_prescribed, set_prescribed_creep
from .genalpha import REFRESH_AFTER, converged, newmark_factors, newmark_update, newton_correct
from .lu import lu_factor, lu_solve

# From this many free coordinates on the Newton matrix is banded (core/sparse.py); below, the dense
# path is as fast or faster (benchmarks/dense_cutoff.py, docs/performance.md).
SPARSE_MIN_FREE = 16


@njit(cache=True)
def _residual(K, W, c, q, v, qdd, t, u, r):
    st = assemble_ws(K, W, c, q, v, t, u)
    M = W.M
    Q = W.Q
    nq = K.nq
    for fi in range(K.free.shape[0]):
        i = K.free[fi]
        s = -Q[i]
        for j in range(nq):
            s += M[i, j] * qdd[j]
        r[fi] = s
    return st


@njit(cache=True)
def _coloured_columns(K, W, c, q, v, qdd, t1, ue, jac, r, r0, bq, gv):
    """build_jacobian's differences with the columns of one group (sparse.dense_groups: they reach
    disjoint rows) perturbed together: the same entries from far fewer residuals."""
    g = K.nl_grp
    nf = K.free.shape[0]
    ng = g[0]
    o_c = 2 + ng             # free columns by group
    o_p = o_c + nf           # reach pointers
    o_r = o_p + nf + 1       # reached rows
    dxs = np.empty(nf)
    for i in range(nf):
        for k in range(nf):
            jac[i, k] = 0.0
    for gi in range(ng):
        for kk in range(g[1 + gi], g[2 + gi]):
            fj = g[o_c + kk]
            j = K.free[fj]
            dx = 1e-10 * (1.0 + abs(q[j])) / bq
            dxs[fj] = dx
            qdd[j] += dx
            q[j] += bq * dx
            v[j] += gv * dx
        _residual(K, W, c, q, v, qdd, t1, ue, r)
        for kk in range(g[1 + gi], g[2 + gi]):
            fj = g[o_c + kk]
            j = K.free[fj]
            dx = dxs[fj]
            qdd[j] -= dx
            q[j] -= bq * dx
            v[j] -= gv * dx
            for m in range(g[o_p + fj], g[o_p + fj + 1]):
                fi = g[o_r + m]
                jac[fi, fj] = (r[fi] - r0[fi]) / dx


_coloured = gated(NL_ROWS, _coloured_columns)   # column groups exist only with nonlinear rows
# the creep sheaves' part of a step (the call sites test for creep sheaves at run time)
_set_prescribed_creep = gated(CREEP, set_prescribed_creep)


@njit(cache=True)
def build_jacobian(K, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, bq, gv):
    """Finite-difference Newton matrix d r / d qdd_free at the current iterate (q and v follow
    through the Newmark relations; column groups K.nl_grp: _coloured_columns). Returns -1
    (vanishing span), 0 (singular) or 1."""
    nf = K.free.shape[0]
    st = _residual(K, W, c, q, v, qdd, t1, ue, r0)
    if st < 0:
        return st
    # the nonlinear rows (core/bodies.py) keep B(q), c and dB/dt qdot of the unperturbed iterate:
    # p = B q + c is then their exact linearisation; what is left out (tension x curvature of the
    # tangent-point map, ~1e-5 of the mass and axial terms) slows the modified Newton contraction
    # at most, it does not change the solution
    W.frz[0] = 1
    if K.nl_grp[0] > 0:
        _coloured(K, K, W, c, q, v, qdd, t1, ue, jac, r, r0, bq, gv)
        W.frz[0] = 0
        return 1 if lu_factor(jac, piv) else 0
    for fj in range(nf):
        j = K.free[fj]
        dq = 1e-10 * (1.0 + abs(q[j]))   # small: the velocity change must stay inside stiff bands
        dx = dq / bq
        qdd[j] += dx
        q[j] += bq * dx
        v[j] += gv * dx
        _residual(K, W, c, q, v, qdd, t1, ue, r)
        for fi in range(nf):
            jac[fi, fj] = (r[fi] - r0[fi]) / dx
        qdd[j] -= dx
        q[j] -= bq * dx
        v[j] -= gv * dx
    W.frz[0] = 0
    return 1 if lu_factor(jac, piv) else 0


@njit(cache=True)
def _matrix(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, rb, bq, gv, analytic):
    """The factorised Newton matrix: dense by finite differences (SP None: build_jacobian) or banded,
    from element Jacobians (core/jacobian.py) or coloured differences (core/sparse.py). Returns -1
    (vanishing span), 0 (singular) or 1."""
    if SP is None:
        return build_jacobian(K, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, bq, gv)
    if analytic:
        return jacobian_analytic(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, r0, bq, gv)
    return jacobian_sparse(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, rb, bq, gv)


@njit(cache=True)
def _correction(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, r, rb):
    """The Newton correction of the free accelerations into rb, in the order of newton_step's `order`
    (dense: rb is r, the free rows; banded: SP.perm). Returns the residual's status (< 0: a vanishing
    span)."""
    if SP is None:
        st = _residual(K, W, c, q, v, qdd, t1, ue, r)
        if st < 0:
            return st
        lu_solve(jac, piv, r)
        return st
    st = residual_sparse(K, SP, W, c, q, v, qdd, t1, ue, r)
    if st < 0:
        return st
    for b in range(SP.n):
        rb[b] = r[SP.perm[b]]
    bordered_solve(jac, piv, SP.n, SP.nb, SP.kl, SP.ku, rb)
    return st


@njit(cache=True)
def newton_step(K, SP, W, c, q_ref, q, v, a, qdd, qo, vo, ao, qddo, t1, h, ue, jac, piv, info, r, r0, rb,
                am, af, beta, gamma, tol, maxit, analytic):
    """One generalized-alpha step from (qo, vo, ao, qddo) to t1 = t0 + h, with the dense Newton matrix
    (SP None: r, r0 and rb = r have the free rows) or the banded one SP (core/sparse.py: r, r0 have nq
    rows, rb SP.n). Modified Newton with the kept matrix first; retries are full Newton from the last
    iterate (crosses regime changes: brake stick -> slip, slack -> taut), the last one from the
    predictor. Returns 0 (converged), 1 (no convergence), 2 (vanishing span; info[7] = element)."""
    if SP is None:
        order = K.free
        n = K.free.shape[0]
    else:
        order = SP.perm
        n = SP.n
    bq, gv = newmark_factors(h, am, af, beta, gamma)
    # (q, v, a, qdd) == (qo, vo, ao, qddo) on entry
    if K.mot_crp >= 0:
        _set_prescribed_creep(K, K, W.jp_prof, ue, t1 - h, t1, q, v, qdd)
    else:
        set_prescribed(K, W.jp_prof, q_ref, t1, q, v, qdd)
    for k in range(K.presc.shape[0]):
        a[K.presc[k]] = qdd[K.presc[k]]
    for attempt in range(4):
        if attempt == 0 or attempt == 3:
            for fi in range(K.free.shape[0]):   # predictor: constant acceleration
                qdd[K.free[fi]] = qddo[K.free[fi]]
            newmark_update(K.free, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma)
        if info[IN_JAC_H] != h or attempt > 0:
            ok = _matrix(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, rb, bq, gv, analytic)
            info[IN_JACS] += 1
            if ok < 0:
                info[IN_WHERE] = -ok - 1
                return 2
            if ok == 0:
                info[IN_JAC_H] = 0.0
                continue
            info[IN_JAC_H] = h
        dprev = 1e300
        for it in range(maxit):
            if attempt > 0 and it > 0:
                ok = _matrix(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, r, r0, rb, bq, gv, analytic)
                info[IN_JACS] += 1
                if ok <= 0:
                    info[IN_JAC_H] = 0.0
                    break
            st = _correction(K, SP, W, c, q, v, qdd, t1, ue, jac, piv, r, rb)
            if st < 0:
                info[IN_WHERE] = -st - 1
                return 2
            dmax, amax, qmax = newton_correct(order, n, rb, qdd, q)
            newmark_update(K.free, qo, vo, ao, qddo, qdd, q, v, a, h, am, af, beta, gamma)
            info[IN_ITERS] += 1
            if not (dmax == dmax) or dmax > 1e300:
                break
            # converged: relative acceleration change below tol, or the position change it
            # causes is at round-off level (the residual has a floor ~ EA * 1e-16)
            if converged(dmax, dprev, amax, qmax, bq, tol, it == maxit - 1):
                if it >= REFRESH_AFTER:
                    info[IN_JAC_H] = 0.0  # slow contraction: refresh the Newton matrix next step
                return 0
            dprev = dmax
    return 1
