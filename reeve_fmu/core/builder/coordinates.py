"""Build step: coordinates. The nodes' affine functions become p = B q + Bpar par + c0 (p: node
positions, then slopes for cubic elements, then s per node), with every element's rows of p, its
gravity and fixed-width maps element coordinate -> q for the compiled gather/scatter, B in CSR,
and the constant mass matrix M0 and force F0 in q space (W2 wrap elements folded in)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .nonlinear import empty_fields
from .state import BuildState


@dataclass
class Arrays:
    """The coordinate arrays of a model."""
    B: np.ndarray
    Bpar: np.ndarray
    c0: np.ndarray
    n_nodes: int
    n_slope: int
    el_idx: np.ndarray      # element -> rows of p (cubic: Westin order [r1, d1, s1, r2, d2, s2])
    el_g: np.ndarray
    el_C: np.ndarray        # 1D: gravity potential of the span line's offset
    el_map: np.ndarray
    el_coef: np.ndarray
    ptr: list               # CSR of B
    idx: list
    val: list
    M0: np.ndarray
    F0: np.ndarray
    wrap_idx: np.ndarray    # W2 wrap elements -> rows of p
    nl: dict = None         # kernel fields of the nonlinear rows (core/bodies.py)


def node_arrays(bs: BuildState) -> Arrays:
    """All coordinate arrays, after every node and element is in bs."""
    B, Bpar, c0, n_nodes, n_slope = _affine_rows(bs)
    el_idx, el_g, el_C = _element_rows(bs, n_nodes, n_slope)
    el_map, el_coef = _element_maps(B, el_idx)
    nd = bs.nd
    nl = empty_fields()
    if bs.nlr is not None:   # exact tangents: those rows' B (at q0) and maps come from core/bodies.py
        comps = bs.comps_nd

        def row_of(key):
            if key[0] == "pos":
                return key[1] * nd + comps.index(key[2])
            if key[0] == "slope":
                return n_nodes * nd + key[1] * nd + comps.index(key[2])
            return _sidx(nd, n_nodes, n_slope, key[1])
        el_map, el_coef, nl = bs.nlr.finalize(nd, row_of, bs.q0, B, c0, el_idx, el_map, el_coef,
                                              c_full=c0 + Bpar @ bs.par0)
    ptr, idx, val = [0], [], []
    for row in range(B.shape[0]):
        nz = np.nonzero(B[row])[0]
        idx.extend(nz.tolist()), val.extend(B[row, nz].tolist())
        ptr.append(len(idx))
    nq = len(bs.q_names)
    M0 = np.zeros((nq, nq))
    for i, j, vv in bs.M0_terms:
        M0[i, j] += vv
    F0v = np.zeros(nq)
    for j, vv in bs.F0.items():
        F0v[j] += vv
    wrap_idx = np.zeros((len(bs.wrap_elements), 4 * nd + 2), np.int64)   # W2 wraps: cubic layout
    for iw, (a, b, _, _) in enumerate(bs.wrap_elements):
        wrap_idx[iw] = _pidx(nd, a) + _didx(nd, n_nodes, a) + [_sidx(nd, n_nodes, n_slope, a)] \
            + _pidx(nd, b) + _didx(nd, n_nodes, b) + [_sidx(nd, n_nodes, n_slope, b)]
    _fold_wraps(nd, bs.scene, bs.wrap_elements, wrap_idx, B, c0 + Bpar @ bs.par0, bs.q0, bs.g, M0, F0v)
    return Arrays(B=B, Bpar=Bpar, c0=c0, n_nodes=n_nodes, n_slope=n_slope, el_idx=el_idx, el_g=el_g,
                  el_C=el_C, el_map=el_map, el_coef=el_coef, ptr=ptr, idx=idx, val=val, M0=M0, F0=F0v,
                  wrap_idx=wrap_idx, nl=nl)


def _affine_rows(bs: BuildState):
    """B, Bpar, c0 from the nodes' affine positions, slopes and material coordinates. 1D: a node's
    coordinate is its position along its span direction."""
    nd, nodes, cubic = bs.nd, bs.nodes, bs.cubic
    nq, n_par = len(bs.q_names), len(bs.scene.ropes)
    n_nodes = len(nodes)
    n_slope = n_nodes * nd if cubic else 0      # slopes block (cubic elements) after positions
    n_p = n_nodes * (nd + 1) + n_slope
    B = np.zeros((n_p, nq))
    Bpar = np.zeros((n_p, n_par))
    c0 = np.zeros(n_p)
    comps = [0, 2] if nd == 2 else [0, 1, 2]
    for i, nd_ in enumerate(nodes):
        r, e = nd_["r"], nd_["e"]
        if nd == 1:
            c0[i] = e @ r.r0
            for j, b in r.terms.items():
                B[i, j] += e @ b
        else:
            for kk, comp in enumerate(comps):
                c0[i * nd + kk] = r.r0[comp]
                for j, b in r.terms.items():
                    B[i * nd + kk, j] += b[comp]
        if cubic:
            dvec = nd_["d"]
            for kk, comp in enumerate(comps):
                rowd = n_nodes * nd + i * nd + kk
                c0[rowd] = dvec.r0[comp]
                for j, b in dvec.terms.items():
                    B[rowd, j] += b[comp]
        sq, spar, sc = nd_["s"]
        row = n_nodes * nd + n_slope + i
        c0[row] = sc
        for j, cc in sq.items():
            B[row, j] += cc
        for j, cc in spar.items():
            Bpar[row, j] += cc
    return B, Bpar, c0, n_nodes, n_slope


def _pidx(nd, node):
    return [node * nd + k for k in range(nd)]


def _didx(nd, n_nodes, node):
    return [n_nodes * nd + node * nd + k for k in range(nd)]


def _sidx(nd, n_nodes, n_slope, node):
    return n_nodes * nd + n_slope + node


def _element_rows(bs: BuildState, n_nodes, n_slope):
    """Per element: its rows of p, its gravity vector and (1D) the constant of its potential."""
    nd, g, elements = bs.nd, bs.g, bs.elements
    ne = 4 * nd + 2 if bs.cubic else 2 * nd + 2
    el_idx = np.zeros((len(elements), ne), dtype=np.int64)
    el_g = np.zeros((len(elements), nd))
    el_C = np.zeros(len(elements))
    for ie, (a, b, ir, k) in enumerate(elements):
        if bs.cubic:   # Westin order [r1, d1, s1, r2, d2, s2]
            el_idx[ie] = _pidx(nd, a) + _didx(nd, n_nodes, a) + [_sidx(nd, n_nodes, n_slope, a)] \
                + _pidx(nd, b) + _didx(nd, n_nodes, b) + [_sidx(nd, n_nodes, n_slope, b)]
        else:
            el_idx[ie] = _pidx(nd, a) + _pidx(nd, b) + [_sidx(nd, n_nodes, n_slope, a),
                                                         _sidx(nd, n_nodes, n_slope, b)]
        e = bs.nodes[a]["e"]
        if nd == 1:
            el_g[ie, 0] = e @ g
            # potential of a line that does not pass through the origin: g . r_perp
            r0 = bs.nodes[a]["r"].r0
            el_C[ie] = g @ (r0 - e * (e @ r0))
        elif nd == 2:
            el_g[ie] = g[[0, 2]]
        else:
            el_g[ie] = g
    # W2 wrap elements carry no axial strain energy: with no slip the groove holds the rope, the wrap
    # material cannot stretch and the tension difference goes into the sheave (docs/numerics.md)
    return el_idx, el_g, el_C


def _element_maps(B, el_idx):
    """Fixed-width element -> q maps (every p row of B has at most a few non-zeros): the hot gather
    and scatter loops then have a constant trip count instead of CSR indirection."""
    width = max(1, max((int(np.count_nonzero(B[row])) for row in el_idx.ravel()), default=1))
    el_map = np.zeros(el_idx.shape + (width,), np.int64)
    el_coef = np.zeros(el_idx.shape + (width,))
    for ie in range(el_idx.shape[0]):
        for a in range(el_idx.shape[1]):
            nz = np.nonzero(B[el_idx[ie, a]])[0]
            el_map[ie, a, :len(nz)] = nz
            el_coef[ie, a, :len(nz)] = B[el_idx[ie, a], nz]
    return el_map, el_coef


def _fold_wraps(nd, scene, wrap_elements, wrap_idx, B, c, q0, g, M0, F0):
    """Add the W2 wrap elements to the constant q-level terms. With no slip every coordinate of a wrap
    element is fixed to its sheave's body or moves with sigma (positions translate with the body,
    slopes are constant, s1 and s2 shift together, so l and r2 - r1 are constant): its mass matrix
    B_e^T M_e B_e is constant, its quadratic-velocity vector vanishes, its gravity is constant and its
    (bending) strain energy is constant. The element kernel is evaluated once, here, instead of in
    every residual."""
    from ..elements.cubic import cubic_element
    if not wrap_elements:
        return
    p = B @ np.asarray(q0, float) + c
    ge = g[[0, 2]] if nd == 2 else g
    ne = wrap_idx.shape[1]
    Me, Qe = np.zeros((ne, ne)), np.zeros(ne)
    for (_, _, ir, _), idx in zip(wrap_elements, wrap_idx):
        rope = scene.ropes[ir]
        cubic_element(nd, rope.rhoA * rope.count, 0.0, rope.EI * rope.count, 0.0, False, ge,
                      p[idx].copy(), np.zeros(ne), Me, Qe)
        Be = B[idx]
        M0 += Be.T @ Me @ Be
        F0 += Be.T @ Qe
