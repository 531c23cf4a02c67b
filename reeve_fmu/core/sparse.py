"""Sparse (banded) Newton matrix for large models: structure, ordering, coloured differences, banded LU.

A rope is a chain: every residual row depends only on the coordinates of the elements that touch it
(plus a few q-level couplings: lumped wrap inertia, the groove-friction rows). Once the free
coordinates are ordered along the route (reverse Cuthill-McKee on the structural pattern, computed
once at build) the Newton matrix M + gamma' C + beta' K is banded with half-bandwidths kl, ku that do
not grow with the number of elements per span. Here:

  * `newton_pattern`   the structural non-zeros in q-space, from the element maps and the q-level terms;
  * `SparseNewton`     the ordering, bandwidth, column groups and pattern for the compiled step
                       (`build_sparse`);
  * `residual_sparse`  M qdd - Q without forming the dense M (O(elements));
  * `jacobian_sparse`  coloured finite differences: one residual per group of columns that share no
                       row, so a Jacobian costs (number of groups) residuals, independent of the size;
  * `band_factor` / `band_solve`  LU with partial pivoting inside the band (LAPACK gbtrf layout in
                       rows), O(n kl (kl + ku)).

The structure is checked numerically once (`pattern_leaks`): a residual row outside the pattern that
changes when a group is perturbed means a coupling the pattern does not know, and the simulator then
keeps the dense path.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np

from ._jit import njit
from .system import element_eval, q_terms

# Arrays of the banded Newton path (built once per model by build_sparse; read-only in the step).
SparseNewton = namedtuple("SparseNewton", [
    "n", "kl", "ku",          # free coordinates, lower and upper half-bandwidth of the ordered matrix
    "perm",                   # band position -> q index (free coordinates only)
    "col_ptr", "col_rows",    # CSC of the structural pattern in band positions
    "grp_ptr", "grp_cols",    # column groups (colours): columns in one group share no row
    "m0_ptr", "m0_idx", "m0_val",   # M0 (q-level constant mass) as CSR in q space
])


# --------------------------------------------------------------------------------- structure
def _element_q(K, ie):
    """q indices element ie depends on."""
    m = K.el_map[ie][K.el_coef[ie] != 0.0]
    return np.unique(m)


def newton_pattern(K):
    """Structural non-zeros of d(M qdd - Q)/d(q, v, qdd) in q-space as a boolean scipy CSR matrix."""
    import scipy.sparse as sp
    nq = K.nq
    rows, cols = [np.arange(nq)], [np.arange(nq)]
    for ie in range(K.el_map.shape[0]):
        qs = _element_q(K, ie)
        rows.append(np.repeat(qs, len(qs)))
        cols.append(np.tile(qs, len(qs)))
    i0, j0 = np.nonzero(K.M0)
    rows.append(i0)
    cols.append(j0)
    if K.trac_s >= 0:
        # groove friction: its capacity follows the end tensions of the two spans at the sheave
        qs = np.unique(np.concatenate([_element_q(K, K.trac_el_in), _element_q(K, K.trac_el_out),
                                       [K.trac_s, K.trac_th]]))
        for r in (K.trac_s, K.trac_th):
            rows.append(np.full(len(qs), r))
            cols.append(qs)
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    P = sp.csr_matrix((np.ones(len(r), bool), (r, c)), shape=(nq, nq))
    P.sum_duplicates()
    return P


def _colour(csc_ptr, csc_rows, n):
    """Greedy column colouring: columns of one colour share no row (distance-2 colouring of the
    column-intersection graph). Columns are taken in band order, which for a banded matrix gives at
    most kl + ku + 1 colours."""
    # rows -> columns (CSR of the same pattern)
    row_cols = [[] for _ in range(n)]
    for j in range(n):
        for i in csc_rows[csc_ptr[j]:csc_ptr[j + 1]]:
            row_cols[i].append(j)
    colour = np.full(n, -1, np.int64)
    for j in range(n):
        used = set()
        for i in csc_rows[csc_ptr[j]:csc_ptr[j + 1]]:
            for k in row_cols[i]:
                if colour[k] >= 0:
                    used.add(colour[k])
        c = 0
        while c in used:
            c += 1
        colour[j] = c
    ng = int(colour.max()) + 1 if n else 0
    order = np.argsort(colour, kind="stable")
    ptr = np.searchsorted(colour[order], np.arange(ng + 1)).astype(np.int64)
    return ptr, order.astype(np.int64)


def build_sparse(K) -> SparseNewton:
    """Ordering (reverse Cuthill-McKee), bandwidth, pattern and column groups of the free block."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import reverse_cuthill_mckee
    free = np.asarray(K.free, np.int64)
    P = newton_pattern(K)[free][:, free].tocsr()
    n = len(free)
    sym = (P + P.T).tocsr()
    order = np.asarray(reverse_cuthill_mckee(sym, symmetric_mode=True), np.int64) if n else free[:0]
    Pb = P[order][:, order].tocoo()
    kl = int(max(0, np.max(Pb.row - Pb.col))) if Pb.nnz else 0
    ku = int(max(0, np.max(Pb.col - Pb.row))) if Pb.nnz else 0
    C = sp.csc_matrix((np.ones(Pb.nnz, bool), (Pb.row, Pb.col)), shape=(n, n))
    C.sort_indices()
    col_ptr = C.indptr.astype(np.int64)
    col_rows = C.indices.astype(np.int64)
    grp_ptr, grp_cols = _colour(col_ptr, col_rows, n)
    M0 = sp.csr_matrix(np.asarray(K.M0))
    M0.sort_indices()
    return SparseNewton(n=n, kl=kl, ku=ku, perm=free[order].copy(), col_ptr=col_ptr, col_rows=col_rows,
                        grp_ptr=grp_ptr, grp_cols=grp_cols, m0_ptr=M0.indptr.astype(np.int64),
                        m0_idx=M0.indices.astype(np.int64), m0_val=M0.data.astype(float))


def jac_shape(SP):
    """Shape of the State.jac array that holds the band LU: U rows (2 kl + ku + 1) and L (kl)."""
    return (max(SP.n, 1), 3 * SP.kl + SP.ku + 1)


# --------------------------------------------------------------------------------- banded LU
@njit(cache=True)
def band_factor(J, piv, n, kl, ku):
    """In-place LU with partial pivoting of the banded matrix stored by rows in J:
    A[i, j] = J[i, j - i + kl] for j in [i - kl, i + kl + ku] (the extra kl columns take the fill of
    row exchanges); the multipliers of step k go to J[k, w + m - 1], m = 1..kl, w = 2 kl + ku + 1.
    Returns False for an exactly singular matrix."""
    w = 2 * kl + ku + 1
    for k in range(n):
        imax = min(n - 1, k + kl)
        jmax = min(n - 1, k + kl + ku)
        p = k
        big = abs(J[k, kl])
        for i in range(k + 1, imax + 1):
            a = abs(J[i, k - i + kl])
            if a > big:
                big = a
                p = i
        piv[k] = p
        if big == 0.0:
            return False
        if p != k:
            for j in range(k, jmax + 1):
                tmp = J[k, j - k + kl]
                J[k, j - k + kl] = J[p, j - p + kl]
                J[p, j - p + kl] = tmp
        inv = 1.0 / J[k, kl]
        for i in range(k + 1, imax + 1):
            f = J[i, k - i + kl] * inv
            J[k, w + i - k - 1] = f
            J[i, k - i + kl] = 0.0
            if f != 0.0:
                for j in range(k + 1, jmax + 1):
                    J[i, j - i + kl] -= f * J[k, j - k + kl]
    return True


@njit(cache=True, inline="always")
def band_solve(J, piv, n, kl, ku, b):
    """Solve with the factors of band_factor, b overwritten by the solution."""
    w = 2 * kl + ku + 1
    for k in range(n):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
        bk = b[k]
        if bk != 0.0:
            for i in range(k + 1, min(n - 1, k + kl) + 1):
                b[i] -= J[k, w + i - k - 1] * bk
    for i in range(n - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, min(n - 1, i + kl + ku) + 1):
            s -= J[i, j - i + kl] * b[j]
        b[i] = s / J[i, kl]


# --------------------------------------------------------------------------------- residual
@njit(cache=True, inline="always")
def residual_sparse(K, SP, W, c, q, v, qdd, t, u, R):
    """R = M qdd - Q over all nq rows, element by element (no dense M). Leaves the element arrays in
    W as assemble_ws does and W.Q = -R (so outputs_ws reads drive reactions from it; W.M has no
    columns on this path). Returns -1 - element for a vanishing span, else 0."""
    nq = K.nq
    ne = K.el_idx.shape[1]
    Q = W.Q
    QE = W.QE
    MEs = W.MEs
    QEs = W.QEs
    Md = W.Md
    el_map = K.el_map
    el_coef = K.el_coef
    nw = el_map.shape[2]
    F0 = K.F0
    for i in range(nq):
        Q[i] = F0[i]
        R[i] = 0.0
    status = 0
    ae = np.empty(ne)
    for ie in range(el_map.shape[0]):
        st, ok = element_eval(K, c, q, v, ie, W.QE, W.VE, MEs, QEs)
        if st < 0:
            status = st
        if not ok:
            continue
        for a in range(ne):
            x = 0.0
            for wa in range(nw):
                x += el_coef[ie, a, wa] * qdd[el_map[ie, a, wa]]
            ae[a] = x
        for a in range(ne):
            fa = -QEs[ie, a]
            for b in range(ne):
                fa += MEs[ie, a, b] * ae[b]
            for wa in range(nw):
                ba = el_coef[ie, a, wa]
                if ba != 0.0:
                    R[el_map[ie, a, wa]] += ba * fa
    q_terms(K, W, q, v, t, u)
    for i in range(nq):
        s = R[i] - Q[i] + Md[i] * qdd[i]
        for k in range(SP.m0_ptr[i], SP.m0_ptr[i + 1]):
            s += SP.m0_val[k] * qdd[SP.m0_idx[k]]
        R[i] = s
        Q[i] = -s
    return status


# --------------------------------------------------------------------------------- Newton matrix
@njit(cache=True)
def jacobian_sparse(K, SP, W, c, q, v, qdd, t1, ue, J, piv, R, R0, dxs, bq, gv):
    """Newton matrix d r / d qdd_free by coloured differences (q and v follow through the Newmark
    relations q += bq dx, v += gv dx), assembled in band order into J and factorised.
    Returns -1 - element (vanishing span), 0 (singular) or 1."""
    n = SP.n
    kl = SP.kl
    perm = SP.perm
    st = residual_sparse(K, SP, W, c, q, v, qdd, t1, ue, R0)
    if st < 0:
        return st
    for i in range(J.shape[0]):
        for k in range(J.shape[1]):
            J[i, k] = 0.0
    for g in range(SP.grp_ptr.shape[0] - 1):
        g0 = SP.grp_ptr[g]
        g1 = SP.grp_ptr[g + 1]
        for kk in range(g0, g1):
            jb = SP.grp_cols[kk]
            j = perm[jb]
            dx = 1e-10 * (1.0 + abs(q[j])) / bq   # as the dense path: inside stiff velocity bands
            dxs[jb] = dx
            qdd[j] += dx
            q[j] += bq * dx
            v[j] += gv * dx
        residual_sparse(K, SP, W, c, q, v, qdd, t1, ue, R)
        for kk in range(g0, g1):
            jb = SP.grp_cols[kk]
            j = perm[jb]
            dx = dxs[jb]
            qdd[j] -= dx
            q[j] -= bq * dx
            v[j] -= gv * dx
            for m in range(SP.col_ptr[jb], SP.col_ptr[jb + 1]):
                ib = SP.col_rows[m]
                i = perm[ib]
                J[ib, jb - ib + kl] = (R[i] - R0[i]) / dx
    return 1 if band_factor(J, piv, n, kl, SP.ku) else 0


@njit(cache=True)
def pattern_leaks(K, SP, W, c, q, v, qdd, t, ue, bq, gv):
    """Number of (group, row) pairs where perturbing a column group changes a free residual row that
    none of the group's columns is structurally coupled to: a coupling `newton_pattern` misses. The
    rows are compared bit for bit (an untouched row is evaluated from identical numbers)."""
    nq = K.nq
    n = SP.n
    perm = SP.perm
    R0 = np.empty(nq)
    R = np.empty(nq)
    covered = np.zeros(n, np.int64)
    residual_sparse(K, SP, W, c, q, v, qdd, t, ue, R0)
    leaks = 0
    for g in range(SP.grp_ptr.shape[0] - 1):
        g0 = SP.grp_ptr[g]
        g1 = SP.grp_ptr[g + 1]
        for kk in range(g0, g1):
            jb = SP.grp_cols[kk]
            for m in range(SP.col_ptr[jb], SP.col_ptr[jb + 1]):
                covered[SP.col_rows[m]] = g + 1
        qs = q.copy()
        vs = v.copy()
        ds = qdd.copy()
        for kk in range(g0, g1):
            j = perm[SP.grp_cols[kk]]
            dx = 1e-6 * (1.0 + abs(q[j])) / bq
            qdd[j] += dx
            q[j] += bq * dx
            v[j] += gv * dx
        residual_sparse(K, SP, W, c, q, v, qdd, t, ue, R)
        q[:] = qs
        v[:] = vs
        qdd[:] = ds
        for ib in range(n):
            i = perm[ib]
            if covered[ib] != g + 1 and R[i] != R0[i]:
                leaks += 1
    return leaks
