"""Build step: the registry of nonlinear rows. While the routes are laid out (builder/spans.py) every
span of an exact-tangent model is registered here; `finalize` turns the rows that touch a moving body
into the kernel fields the compiled core/bodies.py evaluates in every residual."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from ..bodies import (RF_EA, RF_J2, RF_ROW, RF_EL, RF_WIDTH, ROW_SLOPE, ROW_TANGENT, ROW_WRAP, extra_coef,
                      geometry, rows_jacobian)


def body_frame(b):
    """(kind, axis, reference point at t = 0, coordinate -> slot) of a scene body for rows_eval:
    planar theta turns about -y through the centre of mass; a revolute joint turns about its axis
    through its pivot; a prismatic joint (kind 1) slides along its axis; a joint on a moving body is kind
    3 (bodies._chain_point; its parent in slot 7 of nl_bq)."""
    joint = getattr(b, "joint", None)
    if joint is not None and getattr(b, "parent", None) is not None:
        rev = joint == "revolute"
        return (3, np.asarray(b.joint_axis, float), np.asarray(b.pivot if rev else b.position, float),
                {"angle": 3} if rev else {"travel": 0})
    if joint == "revolute":
        return 0, np.asarray(b.joint_axis, float), np.asarray(b.pivot, float), {"angle": 3}
    if joint == "prismatic":
        return 1, np.asarray(b.joint_axis, float), np.asarray(b.position, float), {"travel": 0}
    slots = {"x": 0, "y": 1, "z": 2, "theta": 3, "rx": 4, "ry": 5, "rz": 6}
    return 2 if "rotation" in b.free else 0, np.array([0.0, -1.0, 0.0]), np.asarray(b.position, float), slots


def empty_fields() -> dict:
    """Kernel fields of a model without nonlinear rows (nl_on = 0; nothing is evaluated)."""
    i2, f2 = np.zeros((0, 4), np.int64), np.zeros((0, 4))
    return dict(nl_on=0, nl_bq=np.zeros((0, 7), np.int64), nl_b0=f2, nl_bk=np.zeros(0, np.int64), nl_bax=np.zeros((0, 3)),
                nl_ang0=np.zeros((0, 2)), nl_pb=np.zeros(0, np.int64), nl_po=np.zeros((0, 3)),
                nl_sp=np.zeros((0, 2), np.int64), nl_sg=f2.copy(), nl_sa=np.zeros((0, 6)), nl_rk=i2.copy(),
                nl_rf=np.zeros((0, RF_WIDTH)), nl_cols=np.zeros(0, np.int64), nl_colbody=np.zeros(0, np.int64),
                nl_rw=np.zeros((0, 1), np.int64), nl_ent=np.zeros((0, 0), np.int64), nl_grp=np.zeros(1, np.int64))


class NonlinearRows:
    """Build-time registry of the nonlinear rows of a model (model.build_model fills it while it lays out
    the routes, then `finalize` turns it into kernel fields). Every span of an exact-tangent model is
    registered; rows become nonlinear when a span touches a moving body."""

    def __init__(self, scene, body_dofs):
        self.scene = scene
        self.body_dofs = body_dofs
        self.frames = {b.name: body_frame(b) for b in scene.bodies}
        self.bodies = {}        # body name -> index
        self.points = []        # (body index or -1, offset from the body's reference point)
        self.spans = []         # (point A, point B, RA, sA, RB, sB, sheave axes A and B in body axes)
        self.moving = []        # per span: True if a stop is on a body with a free coordinate
        self.rows = {}          # ("pos" | "slope", node, world comp) | ("s", node) -> row spec

    def _body(self, name):
        if name is None or name == "ground":
            return -1
        parent = getattr(next(b for b in self.scene.bodies if b.name == name), "parent", None)
        if parent is not None:
            self._body(parent)          # a joint on a moving body: its parent is a kernel body too
        if name not in self.bodies:
            self.bodies[name] = len(self.bodies)
        return self.bodies[name]

    def point(self, body, world):
        """A point fixed to body (None: ground) at its t = 0 world position."""
        ib = self._body(body)
        ref = self.frames[body][2] if ib >= 0 else np.zeros(3)
        self.points.append((ib, np.asarray(world, float) - ref))
        return len(self.points) - 1

    def span(self, stopA, stopB):
        """stop = (body name or None, world point at t = 0, radius, sense, axis in body axes or None);
        returns the span index."""
        (bA, wA, RA, sA, aA), (bB, wB, RB, sB, aB) = stopA, stopB
        dflt = np.array([0.0, -1.0, 0.0])
        aA = dflt if aA is None else np.asarray(aA, float)
        aB = dflt if aB is None else np.asarray(aB, float)
        moving = any(b is not None and b != "ground" and self.body_dofs.get(b) for b in (bA, bB))
        self.spans.append((self.point(bA, wA), self.point(bB, wB), RA, sA, RB, sB, np.r_[aA, aB]))
        self.moving.append(moving)
        return len(self.spans) - 1

    def tangent_rows(self, node, span, end, comps):
        if self.moving[span]:
            for comp in comps:
                self.rows[("pos", node, comp)] = (ROW_TANGENT, span, end, comp, 0.0, 0.0, 0.0, 0, None)

    def slope_rows(self, node, span, j_stretch, comps):
        """Cubic elements: the slope of a span's end node at a sheave, stretch * current span direction."""
        if self.moving[span]:
            for comp in comps:
                self.rows[("slope", node, comp)] = (ROW_SLOPE, span, 0, comp, float(j_stretch), 0.0, 0.0, 0.0,
                                                    j_stretch)

    def wrap_row(self, node, span_in, span_out, j_sigma, R, sense, axis, rhoA_g=(0.0, 0.0, 0.0), lw=0.0,
                 offset=0.0, strain=None):
        """s of the node leaving a wrap: sigma + offset + R * current wrap angle (about the sheave's
        axis, which is the incoming span's end-B axis). rhoA_g: the rope's weight per length (vector),
        lw: the wrap's rope whose weight the builder lumped (wrap_weight adds the rest). A W0 wrap is
        the same row with offset = -R * (its angle at t = 0): no rope on it in the scene's pose, the
        change of its arc since. strain = (the leaving span's far node, EA, its first element): W1, the
        wrap holds R x angle / (1 + eps) of rope, eps the leaving span's strain (core/bodies._strain_wrap)."""
        if self.moving[span_in] or self.moving[span_out]:
            centre = self.spans[span_in][1]
            self.rows[("s", node)] = (ROW_WRAP, span_in, span_out, j_sigma, R, sense, float(offset), centre,
                                      j_sigma, tuple(rhoA_g), lw, strain)

    @staticmethod
    def _strain_cols(spec, row_of, B):
        """nl_rf[RF_J2:] of a row: a strain wrap's far node's s as its p row, whose B row is one
        coordinate with coefficient 1 (RF_J2) or none (a rope end); EA, the span's first element. Other
        rows: -1, -1, 0, 0."""
        if len(spec) < 12 or spec[11] is None:
            return [-1.0, -1.0, 0.0, 0.0]
        node, EA, el = spec[11]
        row = row_of(("s", node))
        nz = np.nonzero(B[row])[0]
        if len(nz) > 1 or (len(nz) == 1 and B[row, nz[0]] != 1.0) or EA <= 0.0:
            raise ValueError("a W1 wrap's leaving span must end at a node whose s is one coordinate or a "
                             "constant, with EA > 0")
        return [float(nz[0]) if len(nz) else -1.0, float(row), float(EA), float(el)]

    def _cols(self):
        """q indices of every registered body coordinate and the body tables of rows_eval."""
        nb = len(self.bodies)
        bq, b0 = -np.ones((nb, 8), np.int64), np.zeros((nb, 4))
        bk, bax = np.zeros(nb, np.int64), np.zeros((nb, 3))
        parents = {b.name: getattr(b, "parent", None) for b in self.scene.bodies}
        for name, ib in self.bodies.items():
            kind, axis, ref, slots = self.frames[name]
            bk[ib], bax[ib], b0[ib, :3] = kind, axis, ref
            for ax, j in self.body_dofs[name].items():
                bq[ib, slots[ax]] = j
            if parents[name] is not None:
                bq[ib, 7] = self.bodies[parents[name]]
        cols = sorted({int(j) for j in bq[:, :7].ravel() if j >= 0})
        return bq, b0, bk, bax, cols

    def finalize(self, nd, row_of, q0, B, c0, el_idx, el_map, el_coef, c_full=None):
        """Kernel fields; B and c0 rows of the nonlinear rows set from the Jacobian at q0; el_map and
        el_coef widened so that every nonlinear entry lists its columns. row_of(key) -> p row; c_full:
        c at the scene's parameters (default c0)."""
        bq, b0, bk, bax, cols = self._cols()
        keys = list(self.rows)
        specs = [self.rows[k] for k in keys]
        nr = len(keys)
        rk = np.array([[s[0], s[1], s[2], s[3]] for s in specs], np.int64).reshape(nr, 4)
        rf = np.array([[s[4], s[5], s[6], s[7]] + (list(s[9]) + [s[10]] if len(s) > 9 else [0.0] * 4)
                       + self._strain_cols(s, row_of, B) for s in specs], float).reshape(nr, RF_WIDTH)
        col_k = {j: k for k, j in enumerate(cols)}
        colbody = np.array([next(ib for ib in range(len(bq)) if j in bq[ib, :7]) for j in cols], np.int64)
        body_cols = {ib: [col_k[int(j)] for j in bq[ib, :7] if j >= 0] for ib in range(len(self.bodies))}
        for ib in range(len(self.bodies)):
            if bk[ib] == 3:             # a body on a moving body moves with its parent's coordinate too
                body_cols[ib] = body_cols[ib] + body_cols[int(bq[ib, 7])]

        def span_cols(k):
            out = []
            for ip in self.spans[k][:2]:
                out += body_cols.get(self.points[ip][0], [])
            return out

        deps = []
        for r, s in enumerate(specs):
            d = span_cols(s[1]) + (span_cols(s[2]) if s[0] == ROW_WRAP else [])
            d = sorted(set(d))
            deps.append(d + ([-2] if s[0] in (ROW_WRAP, ROW_SLOPE) else []) + ([-3] if rf[r, RF_J2] >= 0 else []))
        W = max([el_map.shape[2]] + [len(d) for d in deps])
        rw = -np.ones((nr, W), np.int64)
        for r, d in enumerate(deps):
            rw[r, :len(d)] = d
        new_map = np.zeros(el_map.shape[:2] + (W,), np.int64)
        new_coef = np.zeros(el_coef.shape[:2] + (W,))
        new_map[:, :, :el_map.shape[2]] = el_map
        new_coef[:, :, :el_coef.shape[2]] = el_coef
        prow = {row_of(k): r for r, k in enumerate(keys)}
        ent = -np.ones(el_idx.shape, np.int64)
        for ie in range(el_idx.shape[0]):
            for a in range(el_idx.shape[1]):
                r = prow.get(int(el_idx[ie, a]))
                if r is None:
                    continue
                ent[ie, a] = r
                for w in range(W):
                    k = rw[r, w]
                    new_map[ie, a, w] = (cols[k] if k >= 0 else specs[r][8] if k == -2
                                         else int(rf[r, RF_J2]) if k == -3 else 0)
                    new_coef[ie, a, w] = 0.0
        pb = np.array([p[0] for p in self.points], np.int64)
        po = np.array([p[1] for p in self.points], float).reshape(-1, 3)
        sp = np.array([s[:2] for s in self.spans], np.int64).reshape(-1, 2)
        sg = np.array([s[2:6] for s in self.spans], float).reshape(-1, 4)
        sa = np.array([s[6] for s in self.spans], float).reshape(-1, 6)
        f = dict(nl_on=1 if nr else 0, nl_bq=bq, nl_b0=b0, nl_bk=bk, nl_bax=bax, nl_ang0=np.full((len(sp), 2), np.nan),
                 nl_pb=pb, nl_po=po, nl_sp=sp, nl_sg=sg, nl_sa=sa, nl_rk=rk, nl_rf=rf,
                 nl_cols=np.array(cols, np.int64), nl_colbody=colbody, nl_rw=rw, nl_ent=ent, nl_grp=np.zeros(1, np.int64))
        if nr:
            q0 = np.asarray(q0, float)
            K = SimpleNamespace(**f)
            # the contact angles at q0 stay in nl_ang0: a State's warm start
            G = geometry(K, f["nl_ang0"], c0 if c_full is None else c_full)
            J = np.zeros((nr, len(cols)))
            f0 = np.zeros(nr)
            rows_jacobian(q0, G, f["nl_cols"], colbody, f0, np.zeros(nr), np.zeros(nr), np.zeros(len(q0)), J)
            for key, r in zip(keys, range(nr)):
                row = row_of(key)
                B[row, :] = 0.0
                for k, j in enumerate(cols):
                    B[row, j] = J[r, k]
                if specs[r][0] in (ROW_WRAP, ROW_SLOPE):   # G[-5], G[-1]: span tangents, strain wraps
                    B[row, specs[r][8]] = extra_coef(rk, rf, G[-5], G[-1], r, -2)
                if rf[r, RF_J2] >= 0:
                    B[row, int(rf[r, RF_J2])] = extra_coef(rk, rf, G[-5], G[-1], r, -3)
                c0[row] = f0[r] - B[row] @ q0
        return new_map, new_coef, f
