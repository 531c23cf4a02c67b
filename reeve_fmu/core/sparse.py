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
  * `bordered_factor` / `bordered_solve`  the few coordinates coupled to whole spans (sheave
                       material coordinates) form a border; the rest is banded: band LU with partial
                       pivoting (LAPACK gbtrf layout in rows) and a dense Schur complement for the
                       border, O(n kl (kl + ku) + n nb^2).

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
    "n", "nb", "kl", "ku",    # free coordinates, border coordinates (the last nb), lower and upper
                              # half-bandwidth of the ordered non-border block
    "perm",                   # position -> q index (free coordinates only)
    "bpos",                   # q index -> border number (-1: not a border coordinate)
    "col_el_ptr", "col_el",   # per column: the elements that depend on it
    "qb_ptr", "qb_rows",      # per column: the border rows it reaches through q-level terms
    "col_ptr", "col_rows",    # CSC of the structural pattern in band positions
    "grp_ptr", "grp_cols",    # column groups (colours): columns in one group share no row
    "m0_ptr", "m0_idx", "m0_val",   # M0 (q-level constant mass) as CSR in q space
])


# --------------------------------------------------------------------------------- structure
def _element_q(K, ie):
    """q indices element ie depends on."""
    m = K.el_map[ie][K.el_coef[ie] != 0.0]
    return np.unique(m)


def newton_pattern(K, elements=True):
    """Structural non-zeros of d(M qdd - Q)/d(q, v, qdd) in q-space as a boolean scipy CSR matrix;
    elements=False: only the q-level terms (diagonal, M0, groove friction)."""
    import scipy.sparse as sp
    nq = K.nq
    rows, cols = [np.arange(nq)], [np.arange(nq)]
    for ie in range(K.el_map.shape[0] if elements else 0):
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
    for k in range(K.crp_s.shape[0]):
        # creep sheave: kappa (rim inertia, the drive's gain) and the creep force follow the end
        # strains of the spans at the sheave
        qs = np.unique(np.concatenate([_element_q(K, e) for e in (K.crp_el_in[k], K.crp_el_out[k]) if e >= 0]
                                      + [np.array([K.crp_s[k]])]))
        for r in [K.crp_s[k]] + ([K.mot_dof] if k == K.mot_crp and K.mot_dof >= 0 else []):
            rows.append(np.full(len(qs), r))
            cols.append(qs)
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    P = sp.csr_matrix((np.ones(len(r), bool), (r, c)), shape=(nq, nq))
    P.sum_duplicates()
    return P


DENSE_GROUPS_MIN = 16   # free coordinates from which a model with nonlinear rows colours its columns


def dense_groups(K) -> np.ndarray:
    """Column groups for the dense Newton matrix of a model with nonlinear rows (kernel field nl_grp,
    layout there): the matrix is differenced with the rows held (solver.newton.build_jacobian), so a column
    reaches the rows of the elements whose maps list it (a nonlinear entry lists all its columns,
    whatever their current coefficient), the constant mass M0 and a rigid body's rotation block; the
    other q-level terms are diagonal. Models with torsion spans, groove friction or creep sheaves
    (couplings outside that list), or fewer than DENSE_GROUPS_MIN free coordinates: column by column."""
    import scipy.sparse as sp
    free = np.asarray(K.free, np.int64)
    nf = len(free)
    if not (K.nl_on & 1) or K.nl_on & 4 or K.trac_s >= 0 or len(K.crp_s) or nf < DENSE_GROUPS_MIN:
        return np.zeros(1, np.int64)
    rows, cols = [np.arange(K.nq)], [np.arange(K.nq)]
    for ie in range(K.el_map.shape[0]):
        qs = []
        for a in range(K.el_map.shape[1]):
            r = K.nl_ent[ie, a] if K.nl_ent.shape[0] else -1
            w = K.nl_rw[r] != -1 if r >= 0 else K.el_coef[ie, a] != 0.0
            qs.append(K.el_map[ie, a, :len(w)][w])
        qs = np.unique(np.concatenate(qs))
        rows.append(np.repeat(qs, len(qs)))
        cols.append(np.tile(qs, len(qs)))
    i0, j0 = np.nonzero(K.M0)
    rows.append(i0), cols.append(j0)
    for b in list(np.asarray(K.rb_q)) + list(np.asarray(K.ch_q)):
        qs = np.asarray(b)[np.asarray(b) >= 0]
        rows.append(np.repeat(qs, len(qs))), cols.append(np.tile(qs, len(qs)))
    P = sp.csr_matrix((np.ones(sum(len(r) for r in rows), bool), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(K.nq, K.nq))[free][:, free].tocsc()
    P.sort_indices()
    ptr, idx = P.indptr.astype(np.int64), P.indices.astype(np.int64)
    gptr, gcols = colour_columns(ptr, idx, nf, nf)
    return np.concatenate([[len(gptr) - 1], gptr, gcols, ptr, idx]).astype(np.int64)


def colour_columns(csc_ptr, csc_rows, nrows, n):
    """Greedy column colouring: columns of one colour share no row (distance-2 colouring of the
    column-intersection graph). Columns are taken in order, which for a banded matrix gives at most
    kl + ku + 1 colours. Returns (group pointers, columns grouped)."""
    # rows -> columns (CSR of the same pattern)
    row_cols = [[] for _ in range(nrows)]
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


BORDER_DEGREE = 3.0   # a coordinate coupled to more than this many times the median is a border one
BORDER_MAX = 64       # at most this many border coordinates (their Schur complement is dense)


def build_sparse(K) -> SparseNewton:
    """Ordering, bandwidth, pattern and column groups of the free block. A sheave's material
    coordinate sigma enters every element of its spans (interior nodes interpolate s between the span
    ends), so its row and column are full over those spans: such coordinates (degree above
    BORDER_DEGREE x the median) go last as a border; the rest is ordered by reverse Cuthill-McKee
    into a band whose width does not grow with the elements per span."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import reverse_cuthill_mckee
    free = np.asarray(K.free, np.int64)
    P = newton_pattern(K)[free][:, free].tocsr()
    n = len(free)
    sym = (P + P.T).tocsr()
    deg = np.diff(sym.indptr)
    border = np.zeros(0, np.int64)
    if n:
        cand = np.nonzero(deg > BORDER_DEGREE * np.median(deg))[0]
        border = cand[np.argsort(-deg[cand], kind="stable")][:BORDER_MAX]
        border = np.sort(border)
    inner = np.setdiff1d(np.arange(n), border)
    S = sym[inner][:, inner].tocsr()
    rcm = np.asarray(reverse_cuthill_mckee(S, symmetric_mode=True), np.int64) if len(inner) else inner
    order = np.concatenate([inner[rcm], border]).astype(np.int64)
    n1 = len(inner)
    Pb = P[order][:, order].tocoo()
    a = (Pb.row < n1) & (Pb.col < n1)
    kl = int(max(0, np.max(Pb.row[a] - Pb.col[a]))) if a.any() else 0
    ku = int(max(0, np.max(Pb.col[a] - Pb.row[a]))) if a.any() else 0
    C = sp.csc_matrix((np.ones(Pb.nnz, bool), (Pb.row, Pb.col)), shape=(n, n))
    C.sort_indices()
    col_ptr = C.indptr.astype(np.int64)
    col_rows = C.indices.astype(np.int64)
    perm = free[order].copy()
    nb = len(border)
    # border rows are differenced element by element (residual_sparse records each element's share),
    # so they do not force the columns of a whole span into separate groups. Columns conflict when
    # they share a non-border row, an element, or a border row through a q-level term.
    pos = np.full(K.nq, -1, np.int64)
    pos[perm] = np.arange(n)
    n_el = K.el_map.shape[0]
    er, ec = [], []
    for ie in range(n_el):
        cs = pos[_element_q(K, ie)]
        cs = cs[cs >= 0]
        er.append(np.full(len(cs), ie))
        ec.append(cs)
    er = np.concatenate(er) if er else np.zeros(0, np.int64)
    ec = np.concatenate(ec) if ec else np.zeros(0, np.int64)
    E = sp.csc_matrix((np.ones(len(er), bool), (er, ec)), shape=(n_el, n))
    E.sort_indices()
    Pq = newton_pattern(K, elements=False)[perm][:, perm].tocoo()
    qb = Pq.row >= n1
    Qb = sp.csc_matrix((np.ones(int(qb.sum()), bool), (Pq.row[qb] - n1, Pq.col[qb])), shape=(nb, n))
    Qb.sort_indices()
    inner_rows = Pb.row < n1
    X = sp.vstack([sp.csc_matrix((np.ones(int(inner_rows.sum()), bool), (Pb.row[inner_rows], Pb.col[inner_rows])),
                                 shape=(n1, n)), Qb, E]).tocsc()
    X.sort_indices()
    grp_ptr, grp_cols = colour_columns(X.indptr.astype(np.int64), X.indices.astype(np.int64), X.shape[0], n)
    bpos = np.full(K.nq, -1, np.int64)
    bpos[perm[n1:]] = np.arange(nb)
    M0 = sp.csr_matrix(np.asarray(K.M0))
    M0.sort_indices()
    return SparseNewton(n=n, nb=int(nb), kl=kl, ku=ku, perm=perm, bpos=bpos,
                        col_el_ptr=E.indptr.astype(np.int64), col_el=E.indices.astype(np.int64),
                        qb_ptr=Qb.indptr.astype(np.int64), qb_rows=Qb.indices.astype(np.int64),
                        col_ptr=col_ptr, col_rows=col_rows, grp_ptr=grp_ptr, grp_cols=grp_cols,
                        m0_ptr=M0.indptr.astype(np.int64), m0_idx=M0.indices.astype(np.int64),
                        m0_val=M0.data.astype(float))


def jac_shape(SP):
    """Shape of the State.jac array that holds the factors (see bordered_factor)."""
    wb = 3 * SP.kl + SP.ku + 1
    return (max(SP.n, 1), max(wb + 2 * SP.nb, 1))


def unpack_dense(J, SP):
    """The ordered matrix held in J (layout of bordered_factor, before factorisation) as a dense array."""
    n, nb, kl, ku = SP.n, SP.nb, SP.kl, SP.ku
    n1, wb = n - nb, 3 * kl + ku + 1
    A = np.zeros((n, n))
    rows = np.arange(n1)
    for d in range(-kl, ku + 1):
        ok = (rows + d >= 0) & (rows + d < n1)
        A[rows[ok], rows[ok] + d] = J[rows[ok], d + kl]
    A[:n1, n1:] = J[:n1, wb:wb + nb]
    A[n1:, :n1] = J[:n1, wb + nb:wb + 2 * nb].T
    A[n1:, n1:] = J[n1:, :nb]
    return A


def unpack_sparse(J, SP):
    """unpack_dense as a scipy CSR matrix (structural zeros of the band dropped)."""
    import scipy.sparse as sp
    n, nb, kl, ku = SP.n, SP.nb, SP.kl, SP.ku
    n1, wb = n - nb, 3 * kl + ku + 1
    rows = np.arange(n1)
    R, C, V = [], [], []
    for d in range(-kl, ku + 1):
        ok = (rows + d >= 0) & (rows + d < n1)
        R.append(rows[ok])
        C.append(rows[ok] + d)
        V.append(J[rows[ok], d + kl])
    if nb:
        bi = np.arange(nb)
        R += [np.repeat(rows, nb), np.tile(n1 + bi, n1), np.repeat(n1 + bi, nb)]
        C += [np.tile(n1 + bi, n1), np.repeat(rows, nb), np.tile(n1 + bi, nb)]
        V += [J[:n1, wb:wb + nb].ravel(), J[:n1, wb + nb:wb + 2 * nb].ravel(), J[n1:n, :nb].ravel()]
    A = sp.csr_matrix((np.concatenate(V), (np.concatenate(R), np.concatenate(C))), shape=(n, n))
    A.eliminate_zeros()
    return A


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


@njit(cache=True, inline="always")
def _at(ib, jb, n1, kl, wb, nb):
    """(row, column) of J that holds entry (ib, jb) of the ordered Newton matrix (bordered_factor)."""
    if ib < n1:
        if jb < n1:
            return ib, jb - ib + kl
        return ib, wb + jb - n1
    if jb < n1:
        return jb, wb + nb + ib - n1
    return ib, jb - n1


@njit(cache=True)
def bordered_factor(J, piv, n, nb, kl, ku):
    """Factorise the ordered Newton matrix [[A, B], [C, D]] (A: the first n1 = n - nb rows, banded;
    B, C, D: the nb border rows and columns) held in J as
        J[:n1, :wb]          band LU of A (band_factor), wb = 3 kl + ku + 1
        J[:n1, wb:wb+nb]     B, overwritten by Z = A^-1 B
        J[:n1, wb+nb:]       C transposed
        J[n1:, :nb]          D, overwritten by the LU of the Schur complement S = D - C Z.
    Pivots: piv[:n1] band, piv[n1:] Schur. Cost O(n kl (kl + ku) + n nb^2). False if singular."""
    n1 = n - nb
    wb = 3 * kl + ku + 1
    if not band_factor(J, piv, n1, kl, ku):
        return False
    if nb == 0:
        return True
    tmp = np.empty(n1)
    for m in range(nb):
        for i in range(n1):
            tmp[i] = J[i, wb + m]
        band_solve(J, piv, n1, kl, ku, tmp)
        for i in range(n1):
            J[i, wb + m] = tmp[i]
    # S = D - C Z, row by row of J (contiguous memory; see docs/performance.md "Cost per doubling")
    for i in range(n1):
        for p in range(nb):
            cip = J[i, wb + nb + p]
            if cip != 0.0:
                for m in range(nb):
                    J[n1 + p, m] -= cip * J[i, wb + m]
    # dense LU with partial pivoting of S in place
    for k in range(nb):
        p = k
        big = abs(J[n1 + k, k])
        for i in range(k + 1, nb):
            if abs(J[n1 + i, k]) > big:
                big = abs(J[n1 + i, k])
                p = i
        piv[n1 + k] = p
        if big == 0.0:
            return False
        if p != k:
            for j in range(nb):
                tmp2 = J[n1 + k, j]
                J[n1 + k, j] = J[n1 + p, j]
                J[n1 + p, j] = tmp2
        inv = 1.0 / J[n1 + k, k]
        for i in range(k + 1, nb):
            J[n1 + i, k] *= inv
            f = J[n1 + i, k]
            if f != 0.0:
                for j in range(k + 1, nb):
                    J[n1 + i, j] -= f * J[n1 + k, j]
    return True


@njit(cache=True, inline="always")
def bordered_solve(J, piv, n, nb, kl, ku, b):
    """Solve with the factors of bordered_factor; b (length n, ordered) is overwritten."""
    n1 = n - nb
    wb = 3 * kl + ku + 1
    band_solve(J, piv, n1, kl, ku, b)          # y = A^-1 b1
    if nb == 0:
        return
    for i in range(n1):                        # b2 - C y, row by row of J
        yi = b[i]
        if yi != 0.0:
            for p in range(nb):
                b[n1 + p] -= J[i, wb + nb + p] * yi
    for k in range(nb):                        # x2 = S^-1 (b2 - C y)
        p = piv[n1 + k]
        if p != k:
            tmp = b[n1 + k]
            b[n1 + k] = b[n1 + p]
            b[n1 + p] = tmp
    for i in range(nb):
        s = b[n1 + i]
        for j in range(i):
            s -= J[n1 + i, j] * b[n1 + j]
        b[n1 + i] = s
    for i in range(nb - 1, -1, -1):
        s = b[n1 + i]
        for j in range(i + 1, nb):
            s -= J[n1 + i, j] * b[n1 + j]
        b[n1 + i] = s / J[n1 + i, i]
    for i in range(n1):                        # x1 = y - Z x2
        s = b[i]
        for m in range(nb):
            s -= J[i, wb + m] * b[n1 + m]
        b[i] = s


# --------------------------------------------------------------------------------- residual
@njit(cache=True, inline="always")
def residual_sparse(K, SP, W, c, q, v, qdd, t, u, R):
    """R = M qdd - Q over all nq rows, element by element (no dense M); see residual_tracked."""
    return residual_tracked(K, SP, W, c, q, v, qdd, t, u, R, SP.m0_val[:0].reshape((0, 0)), False)


@njit(cache=True, inline="always")
def residual_tracked(K, SP, W, c, q, v, qdd, t, u, R, Eb, track):
    """R = M qdd - Q over all nq rows, element by element (no dense M). Leaves the element arrays in
    W as assemble_ws does and W.Q = -R (so outputs_ws reads drive reactions from it; W.M has no
    columns on this path). With track, Eb[element, border number] receives each element's share of
    the border rows. Returns -1 - element for a vanishing span, else 0."""
    nq = K.nq
    ne = K.el_idx.shape[1]
    Q = W.Q
    QE = W.QE
    MEs = W.MEs
    QEs = W.QEs
    Md = W.Md
    el_map = K.el_map
    el_coef = W.el_coef
    nw = el_map.shape[2]
    F0 = K.F0
    for i in range(nq):
        Q[i] = F0[i]
        R[i] = 0.0
    status = 0
    ae = np.empty(ne)
    bpos = SP.bpos
    if track:
        for ie in range(Eb.shape[0]):
            for p in range(Eb.shape[1]):
                Eb[ie, p] = 0.0
    for ie in range(el_map.shape[0]):
        st, ok = element_eval(K, el_coef, c, q, v, ie, W.QE, W.VE, MEs, QEs)
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
                    ia = el_map[ie, a, wa]
                    R[ia] += ba * fa
                    if track and bpos[ia] >= 0:
                        Eb[ie, bpos[ia]] += ba * fa
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
    """newton_matrix_sparse, factorised (bordered_factor). Returns -1 - element (vanishing span),
    0 (singular) or 1."""
    st = newton_matrix_sparse(K, SP, W, c, q, v, qdd, t1, ue, J, R, R0, dxs, 1.0, bq, gv, 1e-10)
    if st < 0:
        return st
    return 1 if bordered_factor(J, piv, SP.n, SP.nb, SP.kl, SP.ku) else 0


@njit(cache=True, inline="always")
def newton_matrix_sparse(K, SP, W, c, q, v, qdd, t1, ue, J, R, R0, dxs, ba, bq, gv, rel):
    """d r / dx over the free coordinates by coloured differences into J (layout of bordered_factor),
    with qdd += ba dx, q += bq dx, v += gv dx and dx = rel (1 + |q|) / bq: the Newton matrix is
    (1, bq, gv) from the Newmark relations (rel 1e-10: the velocity change must stay inside stiff
    bands), the static stiffness -dQ/dq is (0, 1, 0). Returns -1 - element (vanishing span) or 1."""
    n = SP.n
    nb = SP.nb
    n1 = n - nb
    kl = SP.kl
    wb = 3 * kl + SP.ku + 1
    perm = SP.perm
    n_el = K.el_map.shape[0]
    Eb0 = np.empty((n_el, nb))
    Eb = np.empty((n_el, nb))
    owner = np.empty(nb, np.int64)
    st = residual_tracked(K, SP, W, c, q, v, qdd, t1, ue, R0, Eb0, True)
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
            dx = rel * (1.0 + abs(q[j])) / bq
            dxs[jb] = dx
            qdd[j] += ba * dx
            q[j] += bq * dx
            v[j] += gv * dx
        residual_tracked(K, SP, W, c, q, v, qdd, t1, ue, R, Eb, True)
        for p in range(nb):
            owner[p] = -1
        for kk in range(g0, g1):
            jb = SP.grp_cols[kk]
            j = perm[jb]
            dx = dxs[jb]
            qdd[j] -= ba * dx
            q[j] -= bq * dx
            v[j] -= gv * dx
            for m in range(SP.col_ptr[jb], SP.col_ptr[jb + 1]):
                ib = SP.col_rows[m]
                if ib < n1:
                    i = perm[ib]
                    J[ib, jb - ib + kl if jb < n1 else wb + jb - n1] = (R[i] - R0[i]) / dx
            # border rows: this column's elements' shares (no other column of the group touches them)
            for m in range(SP.col_el_ptr[jb], SP.col_el_ptr[jb + 1]):
                ie = SP.col_el[m]
                for p in range(nb):
                    d = Eb[ie, p] - Eb0[ie, p]
                    if d != 0.0:
                        r_, c_ = _at(n1 + p, jb, n1, kl, wb, nb)
                        J[r_, c_] += d / dx
                        R[perm[n1 + p]] -= d      # what is left is the q-level part
            for m in range(SP.qb_ptr[jb], SP.qb_ptr[jb + 1]):
                owner[SP.qb_rows[m]] = jb
        # border rows: the q-level part belongs to the one column of the group that reaches the row
        for p in range(nb):
            jb = owner[p]
            if jb >= 0:
                i = perm[n1 + p]
                r_, c_ = _at(n1 + p, jb, n1, kl, wb, nb)
                J[r_, c_] += (R[i] - R0[i]) / dxs[jb]
    return 1


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
