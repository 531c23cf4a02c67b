"""Compile a Scene into an immutable Model (arrays) and create States.

Coordinates (docs/theory.md §4.3, §4.6). Every rope node is either *Eulerian* (a tangent point fixed on a
sheave or its body; its material coordinate s is free) or *Lagrangian* (a rope end; s fixed), so the
ALE mass matrix has no null vector (docs/theory.md §6 item 2). The generalized coordinates q are:

    body translations          one per free axis (absolute coordinate of the body's reference point)
    sigma per sheave/drum      material coordinate s at the sheave's in-tangent node [m]
    hitch deflections          rope-end spring deflection along the span [m] (if hitch_stiffness > 0)
    interior node positions    nd per interior node when a span has several elements

and every element coordinate p (node positions and s) is linear in them: p = B q + c. c holds the
constant parts and the rope lengths (s at the far rope end), which the initial statics may solve for.
Wraps: W0 puts in- and out-node at the same s; W1 gives the wrap a constant material length R*theta
whose rope mass moves with the sheave (its kinetic energy is lumped into the body and sigma rows);
W2 (cubic ropes) represents that wrap by cubic elements on the pitch circle whose constant contributions
are folded into the same rows (_fold_wraps).
Tangent points are computed from the initial geometry and stay fixed in the sheave's body frame
(exact while the span directions keep their initial direction; bodies here only translate).

Sign convention: a sheave angle theta = -(sigma - sigma_0)/R is positive when the rope runs over the
sheave in the route direction (from the route's first stop toward its last). A positive drive torque
drives that way. The elevator scenes start their route at the car side, so positive = car up.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from .geometry import GeometryError, tangent, wrap_angle
from .traction import equivalent_friction
from .profiles import Profile, scurve, speed_table
from .scene import AXES, Scene, SceneError
from .kernel import Kernel, compiled_kernel, new_state_arrays
from .bodies import NonlinearRows, empty_fields, rigid_fields


DRIVE_CODES = {"none": 0, "speed": 1, "torque": 2, "external": 3}
ROTATION_VECTOR = ("rx", "ry", "rz")   # coordinates of a spatial rigid body's rotation vector [rad]
(OUT_Q, OUT_V, OUT_A, OUT_TENSION, OUT_RATIO, OUT_TORQUE, OUT_QREL, OUT_BRAKE, OUT_BUFFER, OUT_SLIP,
 OUT_FRICTION, OUT_CANGLE, OUT_CSPEED, OUT_JOINT) = range(14)
CREEP_VREG = 1e-3   # m/s: material speed over which the arriving side changes at a reversal (tanh blend)
INFO_SIZE = 10  # State.info: [h of jac, steps, iterations, jac builds, status, brake engagement, brake z,
#                element of a vanishing span, traction friction deflection z, cumulative slip], then one sheave angle
#                per creep sheave (sheave_contact = "creep": the angle is integrated, not a function of s)


@dataclass
class State:
    """Everything that evolves: saving/restoring FMU state is copying this (arrays are copied)."""
    t: float
    q: np.ndarray        # generalized coordinates
    v: np.ndarray        # velocities
    a: np.ndarray        # generalized-alpha acceleration-like variable
    qdd: np.ndarray      # accelerations
    c: np.ndarray        # constant part of p = B q + c (holds the rope lengths)
    q_ref: np.ndarray    # q at t0 (angle zero, prescribed-motion offsets)
    u: np.ndarray        # inputs held over the step: [motor torque, brake command (1 = release)]
    jac: np.ndarray      # LU factors of the Newton matrix (reused across steps)
    piv: np.ndarray      # LU pivots
    info: np.ndarray     # see INFO_SIZE: solver counters, status and the brake engagement

    def arrays(self):
        """The arrays bundled for the compiled step (kernel.new_state_arrays), built once per State:
        the bundle references these same buffers, so in-place updates are shared."""
        ref = self.__dict__.get("_arrays")
        if ref is None:
            ref = new_state_arrays(self.c, self.q_ref, self.q, self.v, self.a, self.qdd, self.u,
                                   self.jac, self.piv, self.info)
            self.__dict__["_arrays"] = ref
        return ref

    def copy(self) -> "State":
        return State(self.t, *(getattr(self, f).copy() for f in
                               ("q", "v", "a", "qdd", "c", "q_ref", "u", "jac", "piv", "info")))

    def to_dict(self) -> dict:
        """Builtin-typed snapshot (JSON-safe, bit-exact floats)."""
        d = {"t": float(self.t)}
        for f in ("q", "v", "a", "qdd", "c", "q_ref", "u", "jac", "piv", "info"):
            d[f] = getattr(self, f).tolist()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "State":
        return cls(float(d["t"]), *(np.array(d[f], dtype=np.int64 if f == "piv" else float)
                                    for f in ("q", "v", "a", "qdd", "c", "q_ref", "u", "jac", "piv",
                                              "info")))


@dataclass(frozen=True)
class Model:
    scene: Scene
    nd: int
    K: Kernel
    q_names: tuple
    q_kind: tuple            # 'body' | 'sheave' | 'hitch' | 'interior'
    q0: np.ndarray           # initial guess from the geometry
    B: np.ndarray            # dense p = B q + Bpar par + c0 (statics, checks)
    Bpar: np.ndarray
    c0: np.ndarray
    par0: np.ndarray         # rope lengths (s at the last node) from the geometry / scene
    output_names: tuple
    input_names: tuple
    sheave_dof: dict         # sheave name -> q index
    body_dofs: dict          # body name -> {axis: q index}
    KJ: object               # the same arrays for the compiled kernels (kernel.py)
    ropes: tuple             # per rope: dict(name, s_nodes, wraps, drums) for bookkeeping
    statics_unknowns: tuple  # ('q', i) or ('par', j)
    statics_equations: tuple # q indices
    drive_dof: int
    drive_R: float
    element_span: tuple      # (rope, span index) per element
    info: dict = field(default_factory=dict)

    @property
    def nq(self):
        return self.K.nq

    def output_index(self, name):
        return self.output_names.index(name)


class _Affine:
    """3D point r = r0 + sum_j q_j b_j (b_j in R^3)."""

    def __init__(self, r0):
        self.r0 = np.asarray(r0, float).copy()
        self.terms = {}

    def add(self, j, b):
        self.terms[j] = self.terms.get(j, np.zeros(3)) + np.asarray(b, float)
        return self


def _positions_count_message(scene, n_body, n_rope, locked, q_names, q_kind) -> str:
    """statics = 'positions' solves one rope length per rope and the angle of each driven (held)
    sheave in place of the body coordinates, so the counts must match; a driven drum (reel) fixes its
    rope end and adds no unknown."""
    held = [q_names[j].rsplit(".", 1)[0] for j in sorted(locked) if q_kind[j] == "sheave"]
    sheaves = [n for n in held if sheaves_kind(scene, n + ".s") not in ("drum", "")]
    drums = [n for n in held if sheaves_kind(scene, n + ".s") == "drum"]
    parts = [f"{n_rope} rope length(s)"]
    if sheaves:
        parts.append(f"{len(sheaves)} driven sheave angle(s) ({', '.join(sheaves)})")
    note = (f"; the driven drum(s) {', '.join(drums)} fix their rope end and add none" if drums else "")
    return (f"{scene.source}: [initial.statics] 'positions' keeps every body where the scene puts it and "
            f"solves {' + '.join(parts)} = {n_rope + len(sheaves)} unknowns{note}; the scene has "
            f"{n_body} free body coordinate(s), which must be as many. Use statics = 'rope-length' "
            f"(give ropes.length) or 'none'.")


def build_model(scene: Scene) -> Model:
    """Compile a validated scene."""
    try:
        return _build(scene)
    except GeometryError as exc:
        raise SceneError(f"{scene.source}: geometry: {exc}") from None


def _build(scene: Scene) -> Model:
    if scene.model == "spatial-torsion":
        raise SceneError(f"{scene.source}: [scene.model] 'spatial-torsion' (axial-torsion coupling, hook-block "
                         f"yaw) is solved quasi-statically by `reeve-fmu crane`; the dynamic engine "
                         f"models 'axial-1d', 'planar' and 'spatial'")
    nd = {"axial-1d": 1, "planar": 2, "spatial": 3}[scene.model]
    g = np.asarray(scene.gravity, float)
    bodies = {b.name: b for b in scene.bodies}
    sheaves = {s.name: s for s in scene.sheaves}

    q_names, q_kind, q0 = [], [], []

    def new_q(name, kind, value):
        q_names.append(name), q_kind.append(kind), q0.append(float(value))
        return len(q_names) - 1

    body_dofs = {}
    for b in scene.bodies:
        if scene.model == "planar" and "y" in b.free:
            raise SceneError(f"{scene.source}: [bodies.{b.name}.free] the planar model moves in x-z; "
                             f"'y' cannot be free")
        coords = [c for ax in b.free for c in (ROTATION_VECTOR if ax == "rotation" else (ax,))]
        body_dofs[b.name] = {ax: new_q(f"{b.name}.{ax}", "body",
                                       b.position[AXES.index(ax)] if ax in AXES else 0.0) for ax in coords}
    # exact tangents (rotating bodies): node rows that depend nonlinearly on q (core/bodies.py)
    nlr = NonlinearRows(scene, body_dofs) if scene.tangents == "exact" else None

    def body_point(body, offset):
        """Affine 3D position of a point fixed to a body (or the ground)."""
        if body is None or body == "ground":
            return _Affine(offset)
        b = bodies[body]
        r = _Affine(np.asarray(b.position) + np.asarray(offset))
        for ax, j in body_dofs[body].items():
            if ax == "travel":
                r.add(j, b.joint_axis)
            if ax not in AXES:
                continue    # rotation: the nonlinear rows (NonlinearRows) carry it
            k = AXES.index(ax)
            r.r0[k] -= b.position[k]
            e = np.zeros(3)
            e[k] = 1.0
            r.add(j, e)
        return r

    def world(body, offset):
        if body is None or body == "ground":
            return np.asarray(offset, float)
        return np.asarray(bodies[body].position, float) + np.asarray(offset, float)

    # ------------------------------------------------------------------ nodes, spans, elements
    nodes = []          # dict(r=_Affine, e=unit span dir, s=(dict q->coef, dict par->coef, const))
    elements = []       # (node_a, node_b, rope index, span index)
    wrap_elements = []  # W2: (node_a, node_b, rope index, stop index)
    rope_info = []
    n_par = len(scene.ropes)
    par0 = np.zeros(n_par)
    M0_terms = []       # (i, j, value) in q space
    F0 = {}
    springs = []        # (dof, k, c)
    drums = []          # (dof, rhoA, sign)
    sheave_dof = {}
    tension_taps = {}   # sheave name -> {'in': (element, end), 'out': (element, end)}
    rope_end_taps = []
    wrap_len_total = []
    dof_R = {}
    slip_info = {}

    cubic = bool(scene.ropes) and scene.ropes[0].element == "cubic"
    comps_nd = [0] if nd == 1 else ([0, 2] if nd == 2 else [0, 1, 2])

    def free_slope(prefix, e):
        """Material gradient dr/ds of a node as free coordinates (cubic elements), start: e."""
        d = _Affine(np.zeros(3))
        for kk in comps_nd:
            b = np.zeros(3)
            b[kk] = 1.0
            d.add(new_q(f"{prefix}.d{AXES[kk]}", "slope", e[kk]), b)
        return d

    for ir, rope in enumerate(scene.ropes):
        rhoA = rope.rhoA * rope.count
        stops = rope.route
        # geometry of the stops at t = 0
        geo = []
        for st in stops:
            if st.sheave is not None:
                sh = sheaves[st.sheave]
                geo.append((world(sh.body, sh.center), sh.radius, np.asarray(sh.axis),
                            1.0 if st.wrap == "ccw" else -1.0))
            else:
                geo.append((world(None if st.anchor == "ground" else st.anchor, st.at), 0.0, None, 1.0))
        spans = []
        for k in range(len(stops) - 1):
            (cA, RA, aA, sA), (cB, RB, aB, sB) = geo[k], geo[k + 1]
            TA, TB = tangent(cA, RA, aA, sA, cB, RB, aB, sB)
            if np.linalg.norm(TB - TA) < 1e-6:
                raise SceneError(f"{scene.source}: [ropes.{rope.name}.route] span {k} between "
                                 f"stops {k} and {k + 1} has zero length")
            spans.append((TA, TB))
        # material coordinates along the route (unstretched guess = geometric length)
        s_run = 0.0
        sig = {}   # stop index -> sigma dof
        wraps = {}
        s_cursor = []   # per span: (s row of start node, s row of end node)
        first_drum = stops[0].sheave is not None
        last_drum = stops[-1].sheave is not None
        for k, st in enumerate(stops):
            if st.sheave is None:
                continue
            sh = sheaves[st.sheave]
            c, R, a, sgn = geo[k]
            if 0 < k < len(stops) - 1:
                T_in, T_out = spans[k - 1][1], spans[k][0]
                theta = wrap_angle(c, a, sgn, T_in, T_out)
                lw = R * theta if rope.wrap_model in ("W1", "W2") else 0.0
                wraps[k] = (lw, T_in, T_out, theta)
            else:
                wraps[k] = (0.0, None, None, 0.0)
        # assign s guesses
        s_at = {}
        if first_drum:
            s_run = sheaves[stops[0].sheave].stored
        for k in range(len(stops) - 1):
            if k in wraps and 0 < k:
                s_run += wraps[k][0]
            s_at[("start", k)] = s_run
            s_run += float(np.linalg.norm(spans[k][1] - spans[k][0]))
            s_at[("end", k)] = s_run
        L_geo = s_run + (sheaves[stops[-1].sheave].stored if last_drum else 0.0)
        par0[ir] = rope.length if rope.length is not None else L_geo
        scale = par0[ir] / L_geo if rope.length is not None else 1.0

        for k, st in enumerate(stops):
            if st.sheave is None:
                continue
            sh = sheaves[st.sheave]
            s_guess = s_at[("end", k - 1)] if k > 0 else s_at[("start", 0)]
            j = new_q(f"{sh.name}.s", "sheave", s_guess * scale)
            sig[k] = j
            sheave_dof[sh.name] = j
            dof_R[j] = sh.radius
            lw, T_in, T_out, theta = wraps[k]
            # W1 lumps the wrap rope's inertia and weight into the sigma and body rows; W2 assembles
            # them from its wrap elements (below)
            lump = lw if rope.wrap_model == "W1" else 0.0
            J = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == sh.name else 0.0)
            if sh.slip:
                # the sheave turns on its own (angle coordinate, rad); rope and groove are coupled
                # by friction (system.traction_force)
                jt = new_q(f"{sh.name}.theta", "angle", 0.0)
                M0_terms.append((jt, jt, J))
                M0_terms.append((j, j, rhoA * lump))
                slip_info.update(sheave=sh, s=j, th=jt, wrap=theta)
            else:
                M0_terms.append((j, j, J / sh.radius ** 2 + rhoA * lump))
            if sh.kind == "drum":
                drums.append((j, rhoA, 1.0 if k == 0 else -1.0))
            if lump > 0 and sh.body is not None:
                chord = T_out - T_in
                for ax, jb in body_dofs[sh.body].items():
                    if ax not in AXES:
                        continue   # the wrap's rope turning with the body is neglected
                    kk = AXES.index(ax)
                    M0_terms.append((jb, jb, rhoA * lump))
                    M0_terms.append((jb, j, -rhoA * chord[kk]))
                    M0_terms.append((j, jb, -rhoA * chord[kk]))
                    F0[jb] = F0.get(jb, 0.0) + rhoA * lump * g[kk]
            wrap_len_total.append((ir, lw))

        def s_row(kind, k):
            """s of the node at the start of span k (kind 'start') or its end ('end')."""
            stop = k if kind == "start" else k + 1
            st = stops[stop]
            if st.sheave is not None:
                j = sig[stop]
                lw = wraps[stop][0]
                off = lw if (kind == "start" and 0 < stop < len(stops) - 1) else 0.0
                return ({j: 1.0}, {}, off)
            if stop == 0:
                return ({}, {}, 0.0)
            return ({}, {ir: 1.0}, 0.0)

        span_nodes = []
        rope_wraps = []    # W2: (stop, element indices) per wrap
        nl_spans = _register_spans(nlr, scene, rope, stops, geo) if nlr is not None else None
        for k, (TA, TB) in enumerate(spans):
            e = (TB - TA) / np.linalg.norm(TB - TA)
            ends = []
            for kind, T, stop in (("start", TA, k), ("end", TB, k + 1)):
                st = stops[stop]
                if st.sheave is not None:
                    sh = sheaves[st.sheave]
                    r = body_point(sh.body, T - world(sh.body, (0, 0, 0)))
                else:
                    body = None if st.anchor == "ground" else st.anchor
                    r = body_point(body, T - world(body, (0, 0, 0)))
                    if st.hitch_stiffness > 0 or st.hitch_damping > 0:
                        jh = new_q(f"{rope.name}.hitch{0 if stop == 0 else 1}", "hitch", 0.0)
                        # deflection along the span, positive toward the rope (spring extends)
                        r.add(jh, e if stop == 0 else -e)
                        springs.append((jh, st.hitch_stiffness * rope.count, st.hitch_damping * rope.count))
                node = dict(r=r, e=e, s=s_row(kind, k))
                if cubic:
                    if st.sheave is not None:
                        # leaves/meets the sheave tangentially: slope = stretch * span direction
                        jl = new_q(f"{rope.name}.span{k}.{kind}.stretch", "slope", 1.0)
                        node["d"] = _Affine(np.zeros(3)).add(jl, e)
                    else:
                        node["d"] = free_slope(f"{rope.name}.span{k}.{kind}", e)
                nodes.append(node)
                ends.append(len(nodes) - 1)
                if nl_spans is not None:
                    nlr.tangent_rows(len(nodes) - 1, nl_spans[k], 0 if kind == "start" else 1, comps_nd)
            if nl_spans is not None and 0 < k and rope.wrap_model == "W1" and stops[k].sheave is not None:
                nlr.wrap_row(ends[0], nl_spans[k - 1], nl_spans[k], sig[k], geo[k][1], geo[k][3],
                            geo[k][2])
            if rope.wrap_model == "W2" and k > 0 and stops[k].sheave is not None and wraps[k][0] > 0:
                rope_wraps.append((k, _wrap_elements(
                    nodes, wrap_elements, span_nodes[k - 1][1], ends[0], geo[k], wraps[k],
                    sheaves[stops[k].sheave], sig[k], rope.wrap_elements, ir, k, body_point, world)))
            n_el = rope.elements_per_span
            chain = [ends[0]]
            for m in range(1, n_el):
                xi = m / n_el
                P = TA + xi * (TB - TA)
                r = _Affine(P)
                if nd == 1:
                    j = new_q(f"{rope.name}.span{k}.node{m}", "interior", 0.0)
                    r.r0 = P.copy()
                    r.add(j, e)   # displacement along the span line
                else:
                    comps = [0, 2] if nd == 2 else [0, 1, 2]
                    for kk in comps:
                        b = np.zeros(3)
                        b[kk] = 1.0
                        r.r0[kk] = 0.0
                        j = new_q(f"{rope.name}.span{k}.node{m}.{AXES[kk]}", "interior", P[kk])
                        r.add(j, b)
                sa, sb = nodes[ends[0]]["s"], nodes[ends[1]]["s"]
                sq = {}
                for d_, w_ in ((sa[0], 1 - xi), (sb[0], xi)):
                    for jj, cc in d_.items():
                        sq[jj] = sq.get(jj, 0.0) + w_ * cc
                spar = {}
                for d_, w_ in ((sa[1], 1 - xi), (sb[1], xi)):
                    for jj, cc in d_.items():
                        spar[jj] = spar.get(jj, 0.0) + w_ * cc
                node = dict(r=r, e=e, s=(sq, spar, (1 - xi) * sa[2] + xi * sb[2]))
                if cubic:
                    node["d"] = free_slope(f"{rope.name}.span{k}.node{m}", e)
                nodes.append(node)
                chain.append(len(nodes) - 1)
            chain.append(ends[1])
            first_el = len(elements)
            for m in range(n_el):
                elements.append((chain[m], chain[m + 1], ir, k))
            span_nodes.append((chain[0], chain[-1], first_el, len(elements) - 1))
            # tension taps
            if stops[k].sheave is not None:
                tension_taps.setdefault(stops[k].sheave, {})["out"] = (first_el, 0)
            if stops[k + 1].sheave is not None:
                tension_taps.setdefault(stops[k + 1].sheave, {})["in"] = (len(elements) - 1, 1)
        rope_end_taps.append((rope.name, span_nodes[0][2], span_nodes[-1][3]))
        rope_info.append(dict(name=rope.name, spans=span_nodes, wraps=wraps, sig=sig, rhoA=rhoA,
                              first_drum=first_drum, last_drum=last_drum, wrap_elements=rope_wraps))

    nq = len(q_names)
    # bodies: mass and gravity
    for b in scene.bodies:
        for ax, j in body_dofs[b.name].items():
            if ax in ("theta", "angle"):   # about the centre of mass (theta) or the joint axis (angle)
                M0_terms.append((j, j, b.inertia))
                continue
            if ax in ROTATION_VECTOR:      # M(q) and the quadratic-velocity terms: bodies.rigid_terms
                continue
            if ax == "travel":
                M0_terms.append((j, j, b.mass))
                F0[j] = F0.get(j, 0.0) + b.mass * (g @ np.asarray(b.joint_axis))
                continue
            M0_terms.append((j, j, b.mass))
            F0[j] = F0.get(j, 0.0) + b.mass * g[AXES.index(ax)]
            if b.damping > 0:
                springs.append((j, 0.0, b.damping))

    # ------------------------------------------------------------------ p = B q + Bpar par + c0
    n_nodes = len(nodes)
    n_slope = n_nodes * nd if cubic else 0      # slopes block (cubic elements) after positions
    n_p = n_nodes * (nd + 1) + n_slope
    B = np.zeros((n_p, nq))
    Bpar = np.zeros((n_p, n_par))
    c0 = np.zeros(n_p)
    el_C = np.zeros(len(elements))
    for i, nd_ in enumerate(nodes):
        r, e = nd_["r"], nd_["e"]
        if nd == 1:
            c0[i] = e @ r.r0
            for j, b in r.terms.items():
                B[i, j] += e @ b
        else:
            comps = [0, 2] if nd == 2 else [0, 1, 2]
            for kk, comp in enumerate(comps):
                c0[i * nd + kk] = r.r0[comp]
                for j, b in r.terms.items():
                    B[i * nd + kk, j] += b[comp]
        if cubic:
            dvec = nd_["d"]
            for kk, comp in enumerate([0, 2] if nd == 2 else [0, 1, 2]):
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

    def pidx(node):
        return [node * nd + k for k in range(nd)]

    def didx(node):
        return [n_nodes * nd + node * nd + k for k in range(nd)]

    def sidx(node):
        return n_nodes * nd + n_slope + node

    ne = 4 * nd + 2 if cubic else 2 * nd + 2
    el_idx = np.zeros((len(elements), ne), dtype=np.int64)
    el_g = np.zeros((len(elements), nd))
    for ie, (a, b, ir, k) in enumerate(elements):
        if cubic:   # Westin order [r1, d1, s1, r2, d2, s2]
            el_idx[ie] = pidx(a) + didx(a) + [sidx(a)] + pidx(b) + didx(b) + [sidx(b)]
        else:
            el_idx[ie] = pidx(a) + pidx(b) + [sidx(a), sidx(b)]
        e = nodes[a]["e"]
        if nd == 1:
            el_g[ie, 0] = e @ g
            # potential of a line that does not pass through the origin: g . r_perp
            r0 = nodes[a]["r"].r0
            el_C[ie] = g @ (r0 - e * (e @ r0))
        elif nd == 2:
            el_g[ie] = g[[0, 2]]
        else:
            el_g[ie] = g
    rope_of_el = [scene.ropes[ir] for (_, _, ir, _) in elements]
    # W2 wrap elements carry no axial strain energy: with no slip the groove holds the rope, the wrap
    # material cannot stretch and the tension difference goes into the sheave (docs/numerics.md)

    # fixed-width element -> q maps (every p row of B has at most a few non-zeros): the hot gather
    # and scatter loops then have a constant trip count instead of CSR indirection
    width = max(1, max((int(np.count_nonzero(B[row])) for row in el_idx.ravel()), default=1))
    el_map = np.zeros(el_idx.shape + (width,), np.int64)
    el_coef = np.zeros(el_idx.shape + (width,))
    for ie in range(el_idx.shape[0]):
        for a in range(el_idx.shape[1]):
            nz = np.nonzero(B[el_idx[ie, a]])[0]
            el_map[ie, a, :len(nz)] = nz
            el_coef[ie, a, :len(nz)] = B[el_idx[ie, a], nz]

    nl_fields = empty_fields(len(elements), ne, nq)
    if nlr is not None:
        def row_of(key):
            if key[0] == "pos":
                return key[1] * nd + comps_nd.index(key[2])
            return n_nodes * nd + n_slope + key[1]
        el_map, el_coef, nl_fields = nlr.finalize(nd, row_of, q0, B, c0, el_idx, el_map, el_coef)

    # CSR of B
    ptr, idx, val = [0], [], []
    for row in range(n_p):
        nz = np.nonzero(B[row])[0]
        idx.extend(nz.tolist()), val.extend(B[row, nz].tolist())
        ptr.append(len(idx))

    M0 = np.zeros((nq, nq))
    for i, j, vv in M0_terms:
        M0[i, j] += vv
    F0v = np.zeros(nq)
    for j, vv in F0.items():
        F0v[j] += vv
    wrap_idx = np.zeros((len(wrap_elements), 4 * nd + 2), np.int64)   # W2 wraps: cubic layout
    for iw, (a, b, _, _) in enumerate(wrap_elements):
        wrap_idx[iw] = pidx(a) + didx(a) + [sidx(a)] + pidx(b) + didx(b) + [sidx(b)]
    _fold_wraps(nd, scene, wrap_elements, wrap_idx, B, c0 + Bpar @ par0, q0, g, M0, F0v)

    # ------------------------------------------------------------------ drive
    dv = scene.drive
    drive_kind = DRIVE_CODES[dv.kind]
    mot_dof, mot_R = -1, 1.0
    presc, presc_gain = [], []
    profile = Profile(*(np.zeros(1) for _ in range(5)))
    torque_table = np.zeros((2, 0))
    mot_gain = 1.0
    if dv.kind != "none":
        mot_R = sheaves[dv.sheave].radius
        if slip_info and slip_info["sheave"].name == dv.sheave:
            mot_dof, mot_gain = slip_info["th"], 1.0          # the motor turns the sheave angle
        else:
            mot_dof, mot_gain = sheave_dof[dv.sheave], -1.0 / mot_R   # angle = -(sigma - sigma0)/R
        if dv.kind == "speed":
            # rim travel along the route = roping * profile position
            presc, presc_gain = [mot_dof], [dv.roping / (mot_R * mot_gain)]
            if dv.profile == "s-curve":
                profile = scurve(dv.distance, dv.v_max, dv.a_max, dv.jerk, t_start=dv.t_start)
            else:
                profile = speed_table(dv.table)
        elif dv.kind == "torque":
            torque_table = np.array(dv.torque, float).T.copy()
    joints = _joint_tables(scene, body_dofs, g, springs)
    free = [j for j in range(nq) if j not in presc and j not in joints["jp_dof"]]

    crp = _creep_table(scene, sheave_dof, tension_taps, slip_info)
    crp_index = {name: k for k, name in enumerate(crp["name"])}

    # ------------------------------------------------------------------ outputs
    out_names, ok, oi, oj, osc = [], [], [], [], []

    def out(name, kind, i, j=0, scale=1.0):
        out_names.append(name), ok.append(kind), oi.append(i), oj.append(j), osc.append(scale)
        return len(out_names) - 1

    for b in scene.bodies:
        dofs = body_dofs[b.name]
        if b.joint is not None:
            _joint_outputs(out, b, dofs)
            continue
        for ax, j in dofs.items():
            if ax == "theta":   # rad, counter-clockwise in the x-z drawing
                out(f"{b.name}.angle", OUT_Q, j)
                out(f"{b.name}.angular_velocity", OUT_V, j)
                out(f"{b.name}.angular_acceleration", OUT_A, j)
                continue
            if ax in ROTATION_VECTOR:   # rotation vector from the scene's orientation [rad]
                out(f"{b.name}.rotation.{ax[1]}", OUT_Q, j)
                out(f"{b.name}.rotation_rate.{ax[1]}", OUT_V, j)
                continue
            suffix = "" if (nd == 1 and len(dofs) == 1) else f".{ax}"
            out(f"{b.name}.position{suffix}", OUT_Q, j)
            out(f"{b.name}.velocity{suffix}", OUT_V, j)
            out(f"{b.name}.acceleration{suffix}", OUT_A, j)
    for sh in scene.sheaves:
        if sh.name not in sheave_dof:
            continue
        j = sheave_dof[sh.name]
        if sh.slip:
            jt = slip_info["th"]
            out(f"{sh.name}.angle", OUT_QREL, jt, 0, 1.0)
            out(f"{sh.name}.speed", OUT_V, jt, 0, 1.0)
            out(f"{sh.name}.slip_speed", OUT_SLIP, j, jt, sh.radius)   # rope speed - rim speed
            out(f"{sh.name}.slip", OUT_SLIP, j, jt, -sh.radius)        # cumulative slip [m]
            out(f"{sh.name}.friction", OUT_FRICTION, j, jt, sh.radius)  # force on the rope [N]
        elif sh.name in crp_index:   # the angle is integrated: R dtheta = -(1 + eps_arriving) ds
            out(f"{sh.name}.angle", OUT_CANGLE, crp_index[sh.name])
            out(f"{sh.name}.speed", OUT_CSPEED, crp_index[sh.name])
        else:
            out(f"{sh.name}.angle", OUT_QREL, j, 0, -1.0 / sh.radius)
            out(f"{sh.name}.speed", OUT_V, j, 0, -1.0 / sh.radius)
        taps = tension_taps.get(sh.name, {})
        ti = to = None
        if "in" in taps:
            ti = out(f"{sh.name}.tension_in", OUT_TENSION, taps["in"][0], taps["in"][1])
        if "out" in taps:
            to = out(f"{sh.name}.tension_out", OUT_TENSION, taps["out"][0], taps["out"][1])
        if sh.kind == "traction" and ti is not None and to is not None:
            out(f"{sh.name}.traction_ratio", OUT_RATIO, ti, to)
    for name, e_first, e_last in rope_end_taps:
        out(f"{name}.tension_start", OUT_TENSION, e_first, 0)
        out(f"{name}.tension_end", OUT_TENSION, e_last, 1)
    mot_crp = crp_index.get(dv.sheave, -1) if dv.kind != "none" else -1
    if mot_crp >= 0 and crp["kind"][mot_crp] != 0:
        mot_crp = -1     # a slipping sheave has its own angle coordinate
    if dv.kind != "none" and mot_crp >= 0:
        out("motor.angle", OUT_CANGLE, mot_crp)
        out("motor.speed", OUT_CSPEED, mot_crp)
        out("motor.torque", OUT_TORQUE, mot_dof, 0, 1.0 / mot_gain)
    elif dv.kind != "none":
        out("motor.angle", OUT_QREL, mot_dof, 0, mot_gain)
        out("motor.speed", OUT_V, mot_dof, 0, mot_gain)
        out("motor.torque", OUT_TORQUE, mot_dof, 0, 1.0 / mot_gain)
    for ib, bf in enumerate(scene.buffers):
        out(f"{bf.name}.force", OUT_BUFFER, ib)
    if scene.brake.torque > 0 and dv.kind in ("torque", "external"):
        out("brake.torque", OUT_BRAKE, mot_dof, 0, mot_R)
        out("brake.engaged", OUT_BRAKE, mot_dof, 1, 1.0)

    K = Kernel(
        nd=nd, nq=nq,
        B_ptr=np.array(ptr, np.int64), B_idx=np.array(idx, np.int64), B_val=np.array(val, float),
        el_idx=el_idx, el_map=el_map, el_coef=el_coef, el_rhoA=np.array([r.rhoA * r.count for r in rope_of_el], float),
        el_EA=np.array([r.EA * r.count for r in rope_of_el], float),
        el_nu=np.array([r.damping for r in rope_of_el], float),
        el_tonly=np.array([int(r.tension_only) for r in rope_of_el], np.int64),
        el_g=el_g, el_C=el_C, M0=M0, F0=F0v,
        spr_dof=np.array([s[0] for s in springs], np.int64), spr_k=np.array([s[1] for s in springs], float),
        spr_c=np.array([s[2] for s in springs], float),
        drum_dof=np.array([d[0] for d in drums], np.int64), drum_rhoA=np.array([d[1] for d in drums], float),
        drum_sign=np.array([d[2] for d in drums], float),
        mot_dof=mot_dof, mot_R=float(mot_R), drive_kind=drive_kind, torque_table=torque_table,
        brake_T=float(scene.brake.torque) if dv.kind in ("torque", "external") else 0.0,
        brake_wreg=float(scene.brake.stick_angle),
        brake_tau=float(scene.brake.engage_time),
        free=np.array(free, np.int64), presc=np.array(presc, np.int64),
        presc_gain=np.array(presc_gain, float), profile=profile.arrays,
        out_kind=np.array(ok, np.int64), out_i=np.array(oi, np.int64), out_j=np.array(oj, np.int64),
        out_scale=np.array(osc, float),
        l_min=float(scene.solver.min_span),
        buf_dof=np.array([body_dofs[b.body][b.axis] for b in scene.buffers], np.int64),
        buf_z=np.array([b.position for b in scene.buffers], float),
        buf_sign=np.array([1.0 if b.side == "below" else -1.0 for b in scene.buffers], float),
        buf_k=np.array([b.stiffness for b in scene.buffers], float),
        buf_c=np.array([b.damping for b in scene.buffers], float),
        mot_gain=float(mot_gain),
        trac_s=int(slip_info["s"]) if slip_info else -1,
        trac_th=int(slip_info["th"]) if slip_info else -1,
        trac_R=float(slip_info["sheave"].radius) if slip_info else 1.0,
        trac_efa=(math.exp(equivalent_friction(slip_info["sheave"].mu, slip_info["sheave"].undercut_angle,
                                               slip_info["sheave"].groove_angle, slip_info["sheave"].groove)
                           * slip_info["wrap"]) - 1.0) if slip_info else 0.0,
        trac_zmax=float(slip_info["sheave"].creep) if slip_info else 1.0,
        trac_el_in=int(tension_taps[slip_info["sheave"].name]["in"][0]) if slip_info else -1,
        trac_el_out=int(tension_taps[slip_info["sheave"].name]["out"][0]) if slip_info else -1,
        el_type=1 if cubic else 0,
        el_EI=np.array([r.EI * r.count for r in rope_of_el], float),
        crp_s=np.array(crp["s"], np.int64), crp_el_in=np.array(crp["el_in"], np.int64),
        crp_el_out=np.array(crp["el_out"], np.int64), crp_R=np.array(crp["R"], float),
        crp_J=np.array(crp["J"], float), crp_kind=np.array(crp["kind"], np.int64),
        mot_crp=int(mot_crp), crp_vreg=CREEP_VREG, **nl_fields, **joints,
        **rigid_fields(scene, body_dofs),
    )

    # ------------------------------------------------------------------ statics sets
    locked = set(presc) | set(joints["jp_dof"].tolist())
    if dv.kind in ("torque", "external", "none") and mot_dof >= 0 and dv.kind != "none":
        locked.add(mot_dof)   # held by the brake/drive during the initial statics
    if slip_info:
        locked.add(slip_info["s"])    # held by groove friction (preloaded after the statics)
        locked.add(slip_info["th"])
    eqs = [j for j in range(nq) if j not in locked]
    if scene.statics == "positions":
        body_q = {j for d in body_dofs.values() for j in d.values()}
        unknowns = [("q", j) for j in eqs if j not in body_q]
        unknowns += [("q", j) for j in sorted(locked)
                     if sheaves_kind(scene, q_names[j]) not in ("drum", "") and q_kind[j] == "sheave"]
        unknowns += [("par", i) for i in range(n_par)]
        if len(unknowns) != len(eqs):
            raise SceneError(_positions_count_message(scene, len(body_q), n_par, locked, q_names, q_kind))
    else:
        unknowns = [("q", j) for j in eqs]

    inputs = ("motor.torque", "brake.command") if dv.kind == "external" else ()
    return Model(scene=scene, nd=nd, K=K, KJ=compiled_kernel(K), q_names=tuple(q_names), q_kind=tuple(q_kind),
                 q0=np.array(q0, float), B=B, Bpar=Bpar, c0=c0, par0=par0,
                 output_names=tuple(out_names), input_names=inputs, sheave_dof=sheave_dof,
                 body_dofs=body_dofs, ropes=tuple(rope_info), statics_unknowns=tuple(unknowns),
                 statics_equations=tuple(eqs), drive_dof=mot_dof, drive_R=float(mot_R),
                 element_span=tuple((ir, k) for (_, _, ir, k) in elements),
                 info=dict(n_nodes=n_nodes, n_slope=n_slope, wraps=wrap_len_total, dof_R=dof_R,
                           wrap_el_idx=wrap_idx, creep_sheaves=tuple(crp["name"])))


def _joint_tables(scene, body_dofs, g, springs):
    """Kernel arrays of the joints: S-curve profiles of prescribed joints (jp_*), torque tables
    (jt_*), the gravity moment of revolute bodies A cos(angle) + B sin(angle) (jg_*). Joint damping
    is appended to springs."""
    jp, jt, jg = [], [], []
    for b in scene.bodies:
        if b.joint is None:
            continue
        j = body_dofs[b.name]["angle" if b.joint == "revolute" else "travel"]
        mo = b.motion
        if mo.damping > 0:
            springs.append((j, 0.0, mo.damping))
        if mo.kind == "profile":
            jp.append((j, scurve(mo.distance, mo.v_max, mo.a_max, mo.jerk, t_start=mo.t_start).arrays))
        elif mo.kind == "torque":
            jt.append((j, np.array(mo.torque, float).T))
        if b.joint == "revolute":
            # potential -m g . R(angle) d0 of the centre of mass, d0 from the pivot (Rodrigues)
            a, d0 = np.asarray(b.joint_axis), np.asarray(b.position) - np.asarray(b.pivot)
            A = b.mass * (g @ np.cross(a, d0))
            Bc = b.mass * ((g @ a) * (a @ d0) - g @ d0)
            if abs(A) + abs(Bc) > 0.0:
                jg.append((j, A, Bc))

    def stack(items, rows):
        n = max([t.shape[1] for _, t in items], default=1)
        out = np.zeros((len(items), rows, n))
        for k, (_, t) in enumerate(items):
            out[k, :, :t.shape[1]] = t
            out[k, :, t.shape[1]:] = t[:, -1:]
            out[k, 0, t.shape[1]:] = 1e300     # padding never reached: profile_eval/_interp stay in range
        return out
    return dict(jp_dof=np.array([j for j, _ in jp], np.int64), jp_prof=stack(jp, 5),
                jt_dof=np.array([j for j, _ in jt], np.int64), jt_tab=stack(jt, 2),
                jg_dof=np.array([x[0] for x in jg], np.int64), jg_A=np.array([x[1] for x in jg], float),
                jg_B=np.array([x[2] for x in jg], float))


def _joint_outputs(out, b, dofs):
    """Outputs of a body on a joint: its coordinate, rate, acceleration and the joint torque (force)
    that moves it (the drive's reaction for a prescribed motion)."""
    if b.joint == "revolute":
        j = dofs["angle"]
        out(f"{b.name}.angle", OUT_Q, j)
        out(f"{b.name}.angular_velocity", OUT_V, j)
        out(f"{b.name}.angular_acceleration", OUT_A, j)
        out(f"{b.name}.joint_torque", OUT_JOINT, j)
    else:
        j = dofs["travel"]
        out(f"{b.name}.travel", OUT_Q, j)
        out(f"{b.name}.velocity", OUT_V, j)
        out(f"{b.name}.acceleration", OUT_A, j)
        out(f"{b.name}.joint_force", OUT_JOINT, j)


def _register_spans(nlr, scene, rope, stops, geo):
    """Exact tangents: every span of the rope in the registry (core/bodies.py); returns their indices.
    The nonlinear rows cover one linear element per span with rigid terminations."""
    sheaves = {s.name: s for s in scene.sheaves}
    where = f"{scene.source}: [ropes.{rope.name}]"
    if rope.element != "linear" or rope.wrap_model == "W2" or rope.elements_per_span != 1:
        raise SceneError(f"{where} exact tangent points (rotating bodies, scene.tangents = 'exact') are "
                         f"implemented for linear elements, one per span (elements_per_span = 1), wraps W0/W1")
    desc = []
    for st, (c, R, a, sgn) in zip(stops, geo):     # c: the stop's world position at t = 0
        if st.sheave is not None:
            sh = sheaves[st.sheave]
            desc.append((sh.body, c, R, sgn, np.asarray(sh.axis, float)))
        else:
            if st.hitch_stiffness > 0 or st.hitch_damping > 0:
                raise SceneError(f"{where} route: hitch springs are not available with exact tangent points")
            body = None if st.anchor == "ground" else st.anchor
            desc.append((body, c, 0.0, 1.0, None))
    return [nlr.span(desc[k], desc[k + 1]) for k in range(len(stops) - 1)]


def _creep_table(scene, sheave_dof, tension_taps, slip_info):
    """Sheaves whose rope rides the rim at the arriving strain (sheave_contact = "creep"): sigma dof,
    the elements that meet the sheave (-1 for the missing side of a drum), radius, rim inertia (with
    the motor's) and kind (0: angle integrated from sigma, 1: slipping sheave with its own angle).
    Empty for the rigid rim."""
    t = dict(name=[], s=[], el_in=[], el_out=[], R=[], J=[], kind=[])
    if scene.sheave_contact != "creep":
        return t
    for sh in scene.sheaves:
        if sh.name not in sheave_dof:
            continue
        taps = tension_taps.get(sh.name, {})
        J = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == sh.name else 0.0)
        t["name"].append(sh.name)
        t["s"].append(sheave_dof[sh.name])
        t["el_in"].append(taps["in"][0] if "in" in taps else -1)
        t["el_out"].append(taps["out"][0] if "out" in taps else -1)
        t["R"].append(sh.radius)
        t["J"].append(J)
        t["kind"].append(1 if (slip_info and slip_info["sheave"].name == sh.name) else 0)
    return t


def _fold_wraps(nd, scene, wrap_elements, wrap_idx, B, c, q0, g, M0, F0):
    """Add the W2 wrap elements to the constant q-level terms. With no slip every coordinate of a wrap
    element is fixed to its sheave's body or moves with sigma (positions translate with the body,
    slopes are constant, s1 and s2 shift together, so l and r2 - r1 are constant): its mass matrix
    B_e^T M_e B_e is constant, its quadratic-velocity vector vanishes, its gravity is constant and its
    (bending) strain energy is constant. The element kernel is evaluated once, here, instead of in
    every residual."""
    from .elements.cubic import cubic_element
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


def _rotate(v, a, ang):
    """v turned by ang about the unit axis a (Rodrigues)."""
    c, s = math.cos(ang), math.sin(ang)
    return v * c + np.cross(a, v) * s + a * (a @ v) * (1.0 - c)


def _wrap_elements(nodes, elements, n_in, n_out, geo, wrap, sh, j_sig, n_w, ir, stop,
                   body_point, world):
    """W2 (docs/theory.md §4.4): n_w cubic elements on the wrap of one sheave, between the tangent points
    of the incoming span (node n_in) and the outgoing span (node n_out). The wrap nodes sit on the
    pitch circle at equal angles, fixed to the sheave's body (Eulerian); their slope is the unit
    tangent of the circle (|d| = 1: the holonomic no-slip model neglects creep, so the wrap rope
    moves at the rim speed and keeps its strain-free length R theta); their material coordinate is
    tied to the sheave, s = sigma + m lw / n_w. The end nodes share position and s with the span
    nodes but not the slope: the span keeps its own stretch (the groove carries the tension
    difference), so the path is tangent-continuous and the wrap adds nothing to the spans' equations.
    Returns the new element indices."""
    c, R, a, sgn = geo
    lw, T_in, T_out, theta = wrap
    a = np.asarray(a, float) / np.linalg.norm(a)
    chain = []
    for m in range(n_w + 1):
        P = c + _rotate(T_in - c, a, sgn * theta * m / n_w)
        t = sgn * np.cross(a, P - c) / R
        if m in (0, n_w) and np.linalg.norm(t - nodes[n_in if m == 0 else n_out]["e"]) > 1e-6:
            raise GeometryError(f"sheave {sh.name!r}: a span does not meet the pitch circle tangentially")
        nodes.append(dict(r=body_point(sh.body, P - world(sh.body, (0, 0, 0))), e=t,
                          s=({j_sig: 1.0}, {}, lw * m / n_w), d=_Affine(t)))
        chain.append(len(nodes) - 1)
    new = []
    for m in range(n_w):
        elements.append((chain[m], chain[m + 1], ir, stop))
        new.append(len(elements) - 1)
    return new


def sheaves_kind(scene: Scene, qname: str) -> str:
    name = qname.rsplit(".", 1)[0]
    for s in scene.sheaves:
        if s.name == name:
            return s.kind
    return ""


def new_state(model: Model, q=None, par=None, t=0.0) -> State:
    """A state at rest with the given coordinates (default: the geometric guess)."""
    nq = model.nq
    q = model.q0.copy() if q is None else np.asarray(q, float).copy()
    par = model.par0 if par is None else np.asarray(par, float)
    c = model.c0 + model.Bpar @ par
    nf = len(model.K.free)
    info = np.zeros(INFO_SIZE + model.K.crp_s.shape[0])
    brake = model.scene.brake
    info[5] = 1.0 if (model.K.brake_T > 0 and brake.initially_applied) else 0.0
    u = np.zeros(2)
    u[1] = 0.0 if info[5] > 0 else 1.0
    return State(t=float(t), q=q, v=np.zeros(nq), a=np.zeros(nq), qdd=np.zeros(nq), c=c,
                 q_ref=q.copy(), u=u, jac=np.zeros((nf, nf)), piv=np.zeros(nf, np.int64), info=info)
