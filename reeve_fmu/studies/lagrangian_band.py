"""The Lagrangian baseline's Newton matrix solve (compiled): the node block is banded (half-bandwidth
KB), the bodies' and sheaves' coordinates border it; banded LU of the block, dense LU of the Schur
complement of the border (core/solver/lu.py)."""
from __future__ import annotations

import numpy as np

from ..core._jit import njit
from ..core.solver.lu import lu_factor, lu_solve

KB = 3   # half-bandwidth of the node block: two coordinates per node, nearest-neighbour coupling


@njit(cache=True)
def bb_factor(J, C, D, E, X, S, piv):
    """Factor [[band J, C], [D, E]]: banded LU of J in place (no pivoting: the Newton matrix is
    dominated by its diagonal), X = J^-1 C, S = E - D X factored with pivoting. False if singular."""
    nb = J.shape[0]
    for k in range(nb):
        pv = J[k, KB]
        if pv == 0.0 or not (pv == pv):
            return False
        for i in range(k + 1, min(nb, k + KB + 1)):
            f = J[i, KB + k - i] / pv
            J[i, KB + k - i] = f
            if f != 0.0:
                for j in range(k + 1, min(nb, k + KB + 1)):
                    J[i, KB + j - i] -= f * J[k, KB + j - k]
    m = E.shape[0]
    if m == 0:
        return True
    for c in range(m):
        for i in range(nb):
            X[i, c] = C[i, c]
        _band_solve(J, X[:, c])
    for a in range(m):
        for b in range(m):
            s = E[a, b]
            for i in range(nb):
                s -= D[a, i] * X[i, b]
            S[a, b] = s
    return lu_factor(S, piv)


@njit(cache=True, inline="always")
def _band_solve(J, b):
    nb = J.shape[0]
    for i in range(nb):
        s = b[i]
        for k in range(max(0, i - KB), i):
            s -= J[i, KB + k - i] * b[k]
        b[i] = s
    for i in range(nb - 1, -1, -1):
        s = b[i]
        for j in range(i + 1, min(nb, i + KB + 1)):
            s -= J[i, KB + j - i] * b[j]
        b[i] = s / J[i, KB]


@njit(cache=True)
def bb_solve(J, X, D, S, piv, r):
    """Solve in place with the factors of bb_factor."""
    nb = J.shape[0]
    m = S.shape[0]
    rb = r[:nb]
    _band_solve(J, rb)
    if m == 0:
        return
    z = np.empty(m)
    for a in range(m):
        s = r[nb + a]
        for i in range(nb):
            s -= D[a, i] * rb[i]
        z[a] = s
    lu_solve(S, piv, z)
    for a in range(m):
        r[nb + a] = z[a]
    for i in range(nb):
        s = 0.0
        for a in range(m):
            s += X[i, a] * z[a]
        rb[i] -= s
