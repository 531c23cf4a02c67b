"""Build step: spans and wraps of one rope. Every rope node is Eulerian (a tangent point fixed on a
sheave or its body; s is free) or Lagrangian (a rope end; s fixed). Per sheave stop: the coordinate
sigma (s at the in-tangent node), the sheave's inertia and the wrap rope lumped onto sigma and the
body (W1) or W2 wrap elements; per span: the two end nodes (with hitch springs at rope ends), the
interior nodes of a span of several elements and the span's elements."""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from ..geometry import GeometryError
from ..scene import AXES
from .bodies import body_point, world
from .routes import material_guesses, span_tangents, stop_geometry, wrap_table
from .state import Affine, BuildState


@dataclass
class _Rope:
    """One rope while its nodes are built."""
    ir: int
    rope: object
    rhoA: float
    stops: tuple
    geo: list
    spans: list
    wraps: dict
    sig: dict      # stop index -> sigma q index
    nl_spans: list = None   # exact tangents: span indices in bs.nlr

    def s_row(self, kind, k):
        """s of the node at the start of span k (kind 'start') or its end ('end')."""
        stop = k if kind == "start" else k + 1
        st = self.stops[stop]
        if st.sheave is not None:
            j = self.sig[stop]
            lw = self.wraps[stop][0]
            off = lw if (kind == "start" and 0 < stop < len(self.stops) - 1) else 0.0
            return ({j: 1.0}, {}, off)
        if stop == 0:
            return ({}, {}, 0.0)
        return ({}, {self.ir: 1.0}, 0.0)


def add_rope(bs: BuildState, ir: int, rope) -> None:
    """Coordinates, nodes and elements of rope ir (route order)."""
    stops = rope.route
    geo = stop_geometry(stops, bs.sheaves, lambda body, offset: world(bs, body, offset))
    spans = span_tangents(bs.scene.source, rope.name, geo)
    wraps = wrap_table(stops, geo, spans, rope.wrap_model)
    s_at, L_geo = material_guesses(stops, bs.sheaves, spans, wraps)
    bs.par0[ir] = rope.length if rope.length is not None else L_geo
    scale = bs.par0[ir] / L_geo if rope.length is not None else 1.0
    rb = _Rope(ir=ir, rope=rope, rhoA=rope.rhoA * rope.count, stops=stops, geo=geo, spans=spans,
               wraps=wraps, sig={})
    _add_sheave_coordinates(bs, rb, s_at, scale)
    rb.nl_spans = register_spans(bs.nlr, bs.scene, rope, stops, geo) if bs.nlr is not None else None
    span_nodes = []
    rope_wraps = []    # W2: (stop, element indices) per wrap
    for k in range(len(spans)):
        span_nodes.append(_add_span(bs, rb, k, span_nodes, rope_wraps))
    bs.rope_end_taps.append((rope.name, span_nodes[0][2], span_nodes[-1][3]))
    bs.rope_info.append(dict(name=rope.name, spans=span_nodes, wraps=wraps, sig=rb.sig, rhoA=rb.rhoA,
                             first_drum=stops[0].sheave is not None, last_drum=stops[-1].sheave is not None,
                             wrap_elements=rope_wraps))


def _add_sheave_coordinates(bs: BuildState, rb: _Rope, s_at, scale) -> None:
    """sigma per sheave stop, its inertia (sheave, motor, W1 wrap rope), the slipping sheave's
    own angle, drum rope storage and the W1 wrap rope's inertia and weight on the body."""
    scene = bs.scene
    for k, st in enumerate(rb.stops):
        if st.sheave is None:
            continue
        sh = bs.sheaves[st.sheave]
        s_guess = s_at[("end", k - 1)] if k > 0 else s_at[("start", 0)]
        j = bs.new_q(f"{sh.name}.s", "sheave", s_guess * scale)
        rb.sig[k] = j
        bs.sheave_dof[sh.name] = j
        bs.dof_R[j] = sh.radius
        lw, T_in, T_out, theta = rb.wraps[k]
        # W1 lumps the wrap rope's inertia and weight into the sigma and body rows; W2 assembles
        # them from its wrap elements (_add_wrap_elements)
        lump = lw if rb.rope.wrap_model == "W1" else 0.0
        J = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == sh.name else 0.0)
        if sh.slip:
            # the sheave turns on its own (angle coordinate, rad); rope and groove are coupled
            # by friction (contact.traction_force)
            jt = bs.new_q(f"{sh.name}.theta", "angle", 0.0)
            bs.M0_terms.append((jt, jt, J))
            bs.M0_terms.append((j, j, rb.rhoA * lump))
            bs.slip_info.update(sheave=sh, s=j, th=jt, wrap=theta)
        else:
            bs.M0_terms.append((j, j, J / sh.radius ** 2 + rb.rhoA * lump))
        if sh.kind == "drum":
            bs.drums.append((j, rb.rhoA, 1.0 if k == 0 else -1.0))
            _stored_rope_weight(bs, rb, k, j)
        if sh.kind != "idler" and sh.body is not None and J > 0.0:
            _spin_coupling(bs, sh, j, rb.geo[k][3], J)
        if lump > 0 and sh.body is not None:
            chord = T_out - T_in
            for ax, jb in bs.body_dofs[sh.body].items():
                if ax not in AXES:
                    continue   # the wrap's rope turning with the body is neglected
                kk = AXES.index(ax)
                bs.M0_terms.append((jb, jb, rb.rhoA * lump))
                bs.M0_terms.append((jb, j, -rb.rhoA * chord[kk]))
                bs.M0_terms.append((j, jb, -rb.rhoA * chord[kk]))
                bs.F0[jb] = bs.F0.get(jb, 0.0) + rb.rhoA * lump * bs.g[kk]
        bs.wrap_len_total.append((rb.ir, lw))


def _stored_rope_weight(bs: BuildState, rb: _Rope, k, j) -> None:
    """The weight of the rope stored on a drum, at the drum's centre: the spans weigh their rope by its
    position in the scene's frame, so rope paid out from a drum high up would otherwise gain its weight
    from nowhere (a drum 40 m up held its load with 1.5 % too little torque). The stored length is the
    drum's coordinate (s in [0, sigma] at a route's start), so its potential -rhoA sigma g.c is a
    constant force rhoA g.c on sigma: the holding torque no longer depends on where the scene puts z = 0
    (1D, planar and spatial models). Exact while the drum's height does not change with its body's
    motion (a ground drum, a winch on a slewing part or a travelling trolley); a drum that rises or
    falls with its body (a winch on a luffing boom) keeps its stored rope at the scene's height."""
    c = np.asarray(rb.geo[k][0], float)
    sign = 1.0 if k == 0 else -1.0
    bs.F0[j] = bs.F0.get(j, 0.0) + sign * rb.rhoA * float(bs.g @ c)


def _spin_coupling(bs: BuildState, sh, j, sense, J) -> None:
    """A drum or traction sheave on a turning body: its spin relative to the body is
    -sense sigma_dot / R (the rim carries the rope along the route), its absolute spin about its axis
    a adds omega_body . a, so 1/2 J (omega_body . a - sense sigma_dot / R)^2 couples sigma with the
    body's turn (revolute angle, planar theta) by -sense J (k . a) / R, k the turn's axis (a and k turn
    together: constant). On a joint on a moving body omega_body adds the parent's turn: its k . a is
    constant where scene._check_chained_winches lets the sheave on (a prismatic child, a hinge along
    the parent's axis or the sheave's axis along the hinge), so both terms are taken at the scene's
    pose. The sheave's own J (omega . a)^2 is part of the body's inertia."""
    b = bs.bodies[sh.body]
    turns = [b] + ([bs.bodies[b.parent]] if b.parent is not None else [])
    for body in turns:
        dofs = bs.body_dofs[body.name]
        if body.joint == "revolute":
            jr, k = dofs.get("angle"), body.joint_axis
        else:
            jr, k = dofs.get("theta"), (0.0, -1.0, 0.0)
        c = -sense * J * float(np.dot(k, sh.axis)) / sh.radius
        if jr is not None and c != 0.0:
            bs.M0_terms.append((j, jr, c))
            bs.M0_terms.append((jr, j, c))


def _add_span(bs: BuildState, rb: _Rope, k: int, span_nodes, rope_wraps):
    """Nodes and elements of span k; returns (first node, last node, first element, last element)."""
    TA, TB = rb.spans[k]
    e = (TB - TA) / np.linalg.norm(TB - TA)
    ends = [_end_node(bs, rb, kind, k, T, stop, e) for kind, T, stop in (("start", TA, k), ("end", TB, k + 1))]
    stops = rb.stops
    if rb.nl_spans is not None:      # exact tangents: the end nodes (and a W1 wrap's s) follow the poses
        for end, node in enumerate(ends):
            bs.nlr.tangent_rows(node, rb.nl_spans[k], end, bs.comps_nd)
            if "stretch" in bs.nodes[node]:   # cubic: slope = stretch * current span direction
                bs.nlr.slope_rows(node, rb.nl_spans[k], bs.nodes[node]["stretch"], bs.comps_nd)
        if k == 0 and stops[0].sheave is not None:
            _drum_row(bs, rb, ends[0])
        if 0 < k and stops[k].sheave is not None:
            # W1: the wrap holds R x its current angle of rope at the leaving span's strain (linear
            # elements; cubic: unstretched); W0 the change of R x angle since t = 0 (zero rope in the
            # scene's pose): without it a W0 pulley hangs its rope from the axle
            w1 = rb.rope.wrap_model == "W1"
            off = 0.0 if w1 else -rb.geo[k][1] * rb.wraps[k][3]
            strain = None
            if w1 and not bs.cubic:
                strain = (ends[1], rb.rope.EA * rb.rope.count, len(bs.elements))   # span k's first element
            bs.nlr.wrap_row(ends[0], rb.nl_spans[k - 1], rb.nl_spans[k], rb.sig[k], rb.geo[k][1], rb.geo[k][3],
                            rb.geo[k][2], _wrap_weight(bs, rb), rb.wraps[k][0], offset=off, strain=strain)
    if rb.rope.wrap_model == "W2" and k > 0 and stops[k].sheave is not None and rb.wraps[k][0] > 0:
        rope_wraps.append((k, _add_wrap_elements(bs, span_nodes[k - 1][1], ends[0], rb.geo[k], rb.wraps[k],
                                                 bs.sheaves[stops[k].sheave], rb.sig[k],
                                                 rb.rope.wrap_elements, rb.ir, k)))
    n_el = rb.rope.elements_per_span
    chain = [ends[0]] + [_interior_node(bs, rb, k, m, n_el, TA, TB, e, ends) for m in range(1, n_el)]
    chain.append(ends[1])
    first_el = len(bs.elements)
    for m in range(n_el):
        bs.elements.append((chain[m], chain[m + 1], rb.ir, k))
    # tension taps
    if stops[k].sheave is not None:
        bs.tension_taps.setdefault(stops[k].sheave, {})["out"] = (first_el, 0)
    if stops[k + 1].sheave is not None:
        bs.tension_taps.setdefault(stops[k + 1].sheave, {})["in"] = (len(bs.elements) - 1, 1)
    return (chain[0], chain[-1], first_el, len(bs.elements) - 1)


def _drum_row(bs: BuildState, rb: _Rope, node) -> None:
    """Exact tangents, a drum at the route start: the rope wound on it ends at the current tangent
    point, so s there is sigma + R x (the tangent point's angle on the drum since t = 0, in the wrap
    sense): sigma is the drum's angle relative to its body times R and a drum that does not turn keeps
    its rope when the span swings round it. The angle is measured from a reference tangent point fixed
    on the drum (an auxiliary span from a point of the drum's body 2 R off the centre), which makes it
    the wrap row of core/bodies.py (no rope weight: the wound rope's is not modelled)."""
    from ..geometry import tangent, wrap_angle
    sh = bs.sheaves[rb.stops[0].sheave]
    c, R, a, sgn = rb.geo[0]
    T_out = rb.spans[0][0]
    ref = c - 2.0 * (T_out - c)                        # opposite the leaving tangent point
    _, T_ref = tangent(ref, 0.0, None, 1.0, c, R, a, sgn)
    aux = bs.nlr.span((sh.body, ref, 0.0, 1.0, None), (sh.body, c, R, sgn, np.asarray(sh.axis, float)))
    off = -R * wrap_angle(c, a, sgn, T_ref, T_out)
    bs.nlr.wrap_row(node, aux, rb.nl_spans[0], rb.sig[0], R, sgn, a, np.zeros(3), 0.0, offset=off)


def _wrap_weight(bs: BuildState, rb: _Rope):
    """rhoA g of a W0/W1 wrap's rope for bodies.wrap_weight: the weight of the rope a wrap gains or
    loses as its angle changes, at the sheave's centre (without it a slewing crane's payload hung
    3.1 mm off its tangent point, and the cubic rope's payload left the linear one's path by 3 mm in
    a 3 s slew)."""
    return rb.rhoA * np.asarray(bs.g, float)


def register_spans(nlr, scene, rope, stops, geo):
    """Exact tangents: every span of the rope in the registry (core/bodies.py); returns their indices.
    The nonlinear rows are the span end nodes (positions; cubic: slopes; W1: s of the leaving node);
    interior nodes are free coordinates with s interpolated linearly between the end nodes' s at their
    t = 0 offsets (a valid ALE mesh: the material between the nodes follows from their s). W2 wraps
    and hitch springs are not available (scene._check_exact_tangents refuses them)."""
    sheaves = {s.name: s for s in scene.sheaves}
    desc = []
    for st, (c, R, a, sgn) in zip(stops, geo):     # c: the stop's world position at t = 0
        if st.sheave is not None:
            sh = sheaves[st.sheave]
            desc.append((sh.body, c, R, sgn, np.asarray(sh.axis, float)))
        else:
            desc.append((None if st.anchor == "ground" else st.anchor, c, 0.0, 1.0, None))
    return [nlr.span(desc[k], desc[k + 1]) for k in range(len(stops) - 1)]


def _end_node(bs: BuildState, rb: _Rope, kind, k, T, stop, e) -> int:
    """The node at the start or end of span k: a tangent point on a sheave's body or a rope end
    (with its hitch spring deflection, if any); cubic elements add its slope."""
    st = rb.stops[stop]
    rope = rb.rope
    if st.sheave is not None:
        sh = bs.sheaves[st.sheave]
        r = body_point(bs, sh.body, T - world(bs, sh.body, (0, 0, 0)))
    else:
        body = None if st.anchor == "ground" else st.anchor
        r = body_point(bs, body, T - world(bs, body, (0, 0, 0)))
        if st.hitch_stiffness > 0 or st.hitch_damping > 0:
            jh = bs.new_q(f"{rope.name}.hitch{0 if stop == 0 else 1}", "hitch", 0.0)
            # deflection along the span, positive toward the rope (spring extends)
            r.add(jh, e if stop == 0 else -e)
            bs.springs.append((jh, st.hitch_stiffness * rope.count, st.hitch_damping * rope.count))
    node = dict(r=r, e=e, s=rb.s_row(kind, k))
    if bs.cubic:
        if st.sheave is not None and bs.nlr is not None and rope.EI == 0.0:
            # exact tangents, no bending stiffness: the rope leaves the pitch circle in whatever
            # direction its span takes (a pinned string end); holding the slope on the chord would be
            # a moment the rope cannot carry (span sway frequency +14 % with two elements per span)
            node["d"] = bs.free_slope(f"{rope.name}.span{k}.{kind}", e)
        elif st.sheave is not None:
            # leaves/meets the sheave tangentially: slope = stretch * span direction (exact tangents:
            # the current direction, a nonlinear row of core/bodies.py)
            jl = bs.new_q(f"{rope.name}.span{k}.{kind}.stretch", "slope", 1.0)
            node["d"] = Affine(np.zeros(3)).add(jl, e)
            node["stretch"] = jl
        else:
            node["d"] = bs.free_slope(f"{rope.name}.span{k}.{kind}", e)
    bs.nodes.append(node)
    return len(bs.nodes) - 1


def _interior_node(bs: BuildState, rb: _Rope, k, m, n_el, TA, TB, e, ends) -> int:
    """Interior node m of span k (Lagrangian in the span: s interpolated between the end nodes).
    1D: one displacement along the span line; planar/spatial: its position components."""
    nd = bs.nd
    name = rb.rope.name
    xi = m / n_el
    P = TA + xi * (TB - TA)
    r = Affine(P)
    if nd == 1:
        j = bs.new_q(f"{name}.span{k}.node{m}", "interior", 0.0)
        r.r0 = P.copy()
        r.add(j, e)   # displacement along the span line
    else:
        comps = [0, 2] if nd == 2 else [0, 1, 2]
        for kk in comps:
            b = np.zeros(3)
            b[kk] = 1.0
            r.r0[kk] = 0.0
            j = bs.new_q(f"{name}.span{k}.node{m}.{AXES[kk]}", "interior", P[kk])
            r.add(j, b)
    sa, sb = bs.nodes[ends[0]]["s"], bs.nodes[ends[1]]["s"]
    sq = {}
    for d_, w_ in ((sa[0], 1 - xi), (sb[0], xi)):
        for jj, cc in d_.items():
            sq[jj] = sq.get(jj, 0.0) + w_ * cc
    spar = {}
    for d_, w_ in ((sa[1], 1 - xi), (sb[1], xi)):
        for jj, cc in d_.items():
            spar[jj] = spar.get(jj, 0.0) + w_ * cc
    node = dict(r=r, e=e, s=(sq, spar, (1 - xi) * sa[2] + xi * sb[2]))
    if bs.cubic:
        node["d"] = bs.free_slope(f"{name}.span{k}.node{m}", e)
    bs.nodes.append(node)
    return len(bs.nodes) - 1


def _rotate(v, a, ang):
    """v turned by ang about the unit axis a (Rodrigues)."""
    c, s = math.cos(ang), math.sin(ang)
    return v * c + np.cross(a, v) * s + a * (a @ v) * (1.0 - c)


def _add_wrap_elements(bs: BuildState, n_in, n_out, geo, wrap, sh, j_sig, n_w, ir, stop):
    """W2 (docs/theory.md §4.4): n_w cubic elements on the wrap of one sheave, between the tangent points
    of the incoming span (node n_in) and the outgoing span (node n_out). The wrap nodes sit on the
    pitch circle at equal angles, fixed to the sheave's body (Eulerian); their slope is the unit
    tangent of the circle (|d| = 1: the holonomic no-slip model neglects creep, so the wrap rope
    moves at the rim speed and keeps its strain-free length R theta); their material coordinate is
    tied to the sheave, s = sigma + m lw / n_w. The end nodes share position and s with the span
    nodes but not the slope: the span keeps its own stretch (the groove carries the tension
    difference), so the path is tangent-continuous and the wrap adds nothing to the spans' equations.
    Returns the new element indices."""
    nodes = bs.nodes
    c, R, a, sgn = geo
    lw, T_in, T_out, theta = wrap
    a = np.asarray(a, float) / np.linalg.norm(a)
    chain = []
    for m in range(n_w + 1):
        P = c + _rotate(T_in - c, a, sgn * theta * m / n_w)
        t = sgn * np.cross(a, P - c) / R
        if m in (0, n_w) and np.linalg.norm(t - nodes[n_in if m == 0 else n_out]["e"]) > 1e-6:
            raise GeometryError(f"sheave {sh.name!r}: a span does not meet the pitch circle tangentially")
        nodes.append(dict(r=body_point(bs, sh.body, P - world(bs, sh.body, (0, 0, 0))), e=t,
                          s=({j_sig: 1.0}, {}, lw * m / n_w), d=Affine(t)))
        chain.append(len(nodes) - 1)
    new = []
    for m in range(n_w):
        bs.wrap_elements.append((chain[m], chain[m + 1], ir, stop))
        new.append(len(bs.wrap_elements) - 1)
    return new
