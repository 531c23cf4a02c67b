"""The Lagrangian baseline's build steps (lagrangian.build_lagrangian runs them in order): the ALE
static configuration the mesh is laid out on, the touched material intervals, the static path and
marched mesh of every rope, the numbering of the unknowns, the element, sheave, hitch, drive and
output arrays of the kernel (lagrangian_kernels.LK)."""
from __future__ import annotations

import math

import numpy as np

from .lagrangian_kernels import LK, O_A, O_ANGLE, O_END, O_Q, O_RATIO, O_SPEED, O_TAP, O_TORQUE, O_V
from ..core.profiles import scurve, speed_table
from ..core.scene import AXES, Scene, SceneError


def _ale_static_config(scene: Scene, statics: str | None = None):
    """Planar ALE model (one element per span) of the scene and its initial state (scene statics)."""
    from ..core.model import build_model
    from ..core.solver import Simulator
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": 1}) for r in scene.ropes)
    sc = scene.with_overrides(model="planar", ropes=ropes)
    m = build_model(sc)
    sim = Simulator(m)
    st = sim.initial_state(statics=statics)
    return m, sim, st


def _material_ranges(scene: Scene, t_end: float):
    """Material interval [s_min, s_max] (ALE rope coordinate) that touches each sheave during a run to
    t_end, from the 1D ALE model (cheap): {sheave name: (lo, hi)}."""
    from ..core.model import build_model
    from ..core.solver import Simulator
    ropes = tuple(r.__class__(**{**r.__dict__, "elements_per_span": 1}) for r in scene.ropes)
    m = build_model(scene.with_overrides(ropes=ropes))
    sim = Simulator(m)
    st = sim.initial_state()
    lo, hi = {}, {}
    wrap = {}
    for rope in m.ropes:
        for k, j in rope["sig"].items():
            name = m.q_names[j].rsplit(".", 1)[0]
            wrap[name] = rope["wraps"][k][0]
    n = max(1, int(math.ceil(t_end / 0.05)))
    for step in range(n + 1):
        if step > 0:
            sim.advance(st, min(t_end, step * t_end / n))
        for name, j in m.sheave_dof.items():
            s = st.q[j]
            lo[name] = min(lo.get(name, s), s)
            hi[name] = max(hi.get(name, s), s + wrap.get(name, 0.0))
    return {k: (lo[k], hi[k]) for k in lo}


def check_supported(scene: Scene):
    """The scene features the Lagrangian baseline cannot model raise a SceneError naming the file."""
    if scene.model == "spatial":
        raise SceneError(f"{scene.source}: the Lagrangian baseline is planar (x-z); model 'spatial' "
                         "is not supported")
    if scene.drive.kind not in ("none", "speed"):
        raise SceneError(f"{scene.source}: the Lagrangian baseline supports drive kinds 'none' and "
                         f"'speed', not {scene.drive.kind!r}")
    if any(s.kind == "drum" for s in scene.sheaves) or scene.buffers or scene.brake.torque > 0 and \
            scene.drive.kind != "speed":
        raise SceneError(f"{scene.source}: the Lagrangian baseline has no drums, buffers or brakes")


class _StaticPath:
    """The static path of one rope in the ALE static configuration: spans (straight, tension linear
    in s from the rope weight) and wraps (arcs of the pitch circle, tension linear in the angle from
    the arriving to the leaving span), as a list of dicts; positions along it by spatial arc length
    sigma from the rope's start."""

    def __init__(self, path):
        self.path = path
        self.total = sum(sg["length"] for sg in path)
        self.starts = np.cumsum([0.0] + [sg["length"] for sg in path])

    def locate(self, sig):
        k = int(np.searchsorted(self.starts, sig, side="right") - 1)
        k = min(max(k, 0), len(self.path) - 1)
        return k, sig - self.starts[k]

    def point(self, sig):
        k, u = self.locate(sig)
        sg = self.path[k]
        if sg["kind"] == "span":
            return sg["x0"] + sg["t"] * u
        phi = sg["phi0"] + sg["sense"] * u / sg["R"]
        return sg["c"] + sg["R"] * np.array([math.cos(phi), math.sin(phi)])

    def tension(self, sig):
        k, u = self.locate(sig)
        sg = self.path[k]
        f = min(max(u / sg["length"], 0.0), 1.0)
        return sg["N0"] + f * (sg["N1"] - sg["N0"])

    def s_ale(self, sig):
        k, u = self.locate(sig)
        sg = self.path[k]
        return sg["sA0"] + sg["sA_len"] * min(max(u / sg["length"], 0.0), 1.0)


def _on_circle(c, R, P, d, near):
    """Point on the circle (c, R) at distance d from P, the intersection nearer to `near`."""
    D = P - c
    L = float(np.linalg.norm(D))
    x = (L * L + R * R - d * d) / (2.0 * L)
    y = math.sqrt(max(R * R - x * x, 0.0))
    e = D / L
    nrm = np.array([-e[1], e[0]])
    p1, p2 = c + x * e + y * nrm, c + x * e - y * nrm
    return p1 if float(np.linalg.norm(p1 - near)) < float(np.linalg.norm(p2 - near)) else p2


class LagrangianBuilder:
    """State shared by the steps of `build_lagrangian`; each method is one step and documents what
    it adds."""

    def __init__(self, scene, element_length, coarse_length, fine_everywhere, penalty, contact_damping,
                 stick, probe, margin, statics):
        self.scene = scene
        self.element_length = element_length
        self.coarse_length = coarse_length
        self.fine_everywhere = fine_everywhere
        self.penalty = penalty
        self.contact_damping = contact_damping
        self.stick = stick
        self.probe = probe
        self.margin = margin
        self.statics = statics
        self.g2 = np.asarray(scene.gravity, float)[[0, 2]]
        self.sheaves = {s.name: s for s in scene.sheaves}
        self.bodies = {b.name: b for b in scene.bodies}
        # the mesh, filled rope by rope in layout_rope
        self.nodes_x = []         # layout positions
        self.nodes_slot = []      # per node and axis: 'free' | 'fixed' | ('body', border index)
        self.el_list = []         # (a, b, s1, l, rope index)
        self.rope_node_range = []
        self.rope_el_range = []
        self.hitches = []         # (node, anchor body or None, anchor point (2), k, c)
        self.taps = []            # (sheave, side, tangent point (2, world), dir (2), rope index)
        self.layouts = []
        self.sheave_Tw = {}       # mean static tension on each wrap

    # ------------------------------------------------------------------------ ALE configuration
    def static_configuration(self, t_end):
        """The planar ALE model in its static state (the mesh is laid out on it) and the material
        intervals that touch each sheave during [0, t_end] (they get the fine mesh)."""
        scene = self.scene
        self.ale, self.ale_sim, self.ale_st = _ale_static_config(scene, self.statics)
        self.mode = self.statics or scene.statics
        self.p = self.ale.B @ self.ale_st.q + self.ale_st.c
        self.nn_ale = self.ale.info["n_nodes"]
        self.ranges = {} if (self.fine_everywhere or not scene.sheaves) else _material_ranges(scene, t_end)

    def node_xy(self, i):
        return np.array([self.p[2 * i], self.p[2 * i + 1]])

    def node_s(self, i):
        return self.p[2 * self.nn_ale + i]

    # ------------------------------------------------------------------------ border unknowns
    def border_unknowns(self):
        """The dense border of the Newton matrix: body translations and the angles of the sheaves
        that are not speed-driven, each as (name, mass, force, damping)."""
        scene, sheaves = self.scene, self.sheaves
        g3 = np.asarray(scene.gravity, float)
        border = []          # (name, kind, mass, force, damping)
        body_dof = {}
        for b in scene.bodies:
            for ax in b.free:
                if ax == "y":
                    raise SceneError(f"{scene.source}: body {b.name!r}: the planar model moves in x-z")
                k3 = AXES.index(ax)
                body_dof[(b.name, ax)] = len(border)
                border.append((f"{b.name}.{ax}", b.mass, b.mass * g3[k3], b.damping))
        sheave_th = {}
        used = [st.sheave for rope in scene.ropes for st in rope.route if st.sheave is not None]
        for name in used:
            sh = sheaves[name]
            if scene.drive.kind == "speed" and scene.drive.sheave == name:
                continue
            J = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == name else 0.0)
            J = max(J, 1e-3 * sh.radius ** 2)   # a massless idler: keep its angle row regular
            sheave_th[name] = len(border)
            border.append((f"{name}.theta", J, 0.0, 0.0))
        self.border, self.body_dof, self.sheave_th, self.used = border, body_dof, sheave_th, used

    # ------------------------------------------------------------------------ rope layouts and meshes
    def layout_rope(self, ir, rope):
        """Mesh one rope: its static path, the elements marched along it, its ends."""
        EA = rope.EA * rope.count
        rhoA = rope.rhoA * rope.count
        path = self._static_path(ir, rope, EA, rhoA)
        xs, ls, fine_flags = self._march(rope, path, EA)
        # the material lengths above come from chords and a tension estimate: scale them to the
        # continuum's rope length exactly (relative change ~1e-8)
        ls = list(np.asarray(ls) * ((path.path[-1]["sA0"] + path.path[-1]["sA_len"] - path.path[0]["sA0"])
                                    / sum(ls)))
        s_nodes = np.concatenate([[0.0], np.cumsum(ls)])
        n_fine = int(sum(fine_flags))
        L = float(s_nodes[-1])
        n0 = len(self.nodes_x)
        e_start = len(self.el_list)
        for x in xs:
            self.nodes_x.append(np.asarray(x, float))
            self.nodes_slot.append(None)
        for j in range(len(ls)):
            self.el_list.append((n0 + j, n0 + j + 1, s_nodes[j], ls[j], ir))
        self.rope_node_range.append((n0, len(self.nodes_x)))
        self.rope_el_range.append((e_start, len(self.el_list)))
        rope_layout = dict(path=path.path, L=L, n_fine=n_fine, s_nodes=s_nodes)
        self._rope_ends(rope, n0)
        rope_layout["EA"] = EA
        rope_layout["rhoA"] = rhoA
        self.layouts.append(rope_layout)

    def _static_path(self, ir, rope, EA, rhoA) -> _StaticPath:
        """Spans and wraps of the rope in the ALE static configuration (see `_StaticPath`); records
        the tension taps at the tangent points and the mean static tension on each wrap."""
        info = self.ale.ropes[ir]
        stops = rope.route
        node_xy, node_s = self.node_xy, self.node_s
        path = []        # dict(kind, length (spatial), sA0 (ALE s at start), sA_len, ...)
        spans = info["spans"]
        for k, (na, nb_, e0, e1) in enumerate(spans):
            xa, xb = node_xy(na), node_xy(nb_)
            l = node_s(nb_) - node_s(na)
            d = xb - xa
            dist = float(np.linalg.norm(d))
            t_ = d / dist
            N_mid = EA * (dist / l - 1.0)
            # static equilibrium: dN/ds = -rhoA g.t; an unloaded configuration (statics 'none') keeps
            # the span's uniform strain
            dNds = -rhoA * float(self.g2 @ t_) if self.mode != "none" else 0.0
            N0, N1 = N_mid - dNds * l / 2, N_mid + dNds * l / 2
            if k > 0:
                sh = self.sheaves[stops[k].sheave]
                c = _sheave_center(sh, self.bodies, self.ale, self.ale_st)
                prev = path[-1]
                Tin = prev["x0"] + prev["t"] * prev["length"]
                theta = info["wraps"][k][3]
                rin = Tin - c
                tin = prev["t"]
                sense = 1.0 if (rin[0] * tin[1] - rin[1] * tin[0]) > 0 else -1.0
                sA_in = node_s(spans[k - 1][1])
                path.append(dict(kind="wrap", c=c, R=sh.radius, phi0=math.atan2(rin[1], rin[0]),
                                 sense=sense, theta=theta, length=sh.radius * theta, sA0=sA_in,
                                 sA_len=node_s(na) - sA_in, N0=prev["N1"], N1=N0, name=sh.name))
                self.sheave_Tw[sh.name] = 0.5 * (prev["N1"] + N0)
                self.taps.append((sh.name, "in", Tin - c, -tin, ir))
                self.taps.append((sh.name, "out", xa - c, t_, ir))
            path.append(dict(kind="span", x0=xa, t=t_, length=dist, sA0=node_s(na), sA_len=l, N0=N0, N1=N1))
        return _StaticPath(path)

    def _march(self, rope, sp: _StaticPath, EA):
        """March along the path: each element is a chord of length lambda(N) * l (N: static tension at
        the chord's middle), so the layout is in equilibrium up to the rope weight within an element.
        Returns the node positions, the elements' material lengths and which elements are fine."""
        scene, element_length, coarse_length = self.scene, self.element_length, self.coarse_length
        fine_everywhere, ranges, margin = self.fine_everywhere, self.ranges, self.margin
        stops = rope.route
        path, total, point, tension = sp.path, sp.total, sp.point, sp.tension
        fine_iv = [] if fine_everywhere else [(ranges[st_.sheave][0] - margin, ranges[st_.sheave][1] + margin)
                                               for st_ in stops if st_.sheave is not None]

        def target(sig):
            if fine_everywhere and any(st_.sheave is not None for st_ in stops):
                return element_length
            a = sp.s_ale(sig)
            b = a + coarse_length
            for lo, hi in fine_iv:
                if b >= lo and a <= hi:
                    return element_length
            return coarse_length

        xs = [point(0.0)]
        ls = []
        fine_flags = []
        sig = 0.0
        while True:
            h = target(sig)
            lam_h = 1.0 + tension(min(total, sig + 0.5 * h)) / EA
            rest = total - sig
            end = xs[-1]
            if rest <= 1.5 * lam_h * h and path[-1]["kind"] == "span" and rest <= path[-1]["length"] + 1e-12:
                x_end = point(total)
                lam_e = 1.0 + tension(0.5 * (sig + total)) / EA
                ls.append(float(np.linalg.norm(x_end - end)) / lam_e)
                fine_flags.append(h == element_length)
                xs.append(x_end)
                break
            d = lam_h * h
            lo, hi = sig, sig
            step = 0.25 * d
            while np.linalg.norm(point(min(hi, total)) - end) < d:
                if hi >= total:
                    raise SceneError(f"{scene.source}: Lagrangian layout: rope {rope.name!r} too short for "
                                     f"element length {h:g} m")
                lo, hi = hi, hi + step
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if np.linalg.norm(point(mid) - end) < d:
                    lo = mid
                else:
                    hi = mid
            sig = 0.5 * (lo + hi)
            xs.append(point(sig))
            ls.append(h)
            fine_flags.append(h == element_length)
        if len(ls) > 1 and ls[-1] < 0.5 * ls[-2]:
            # merge a short last element with the one before
            xs.pop(-2)
            lam_e = 1.0 + tension(total) / EA
            ls[-2:] = [float(np.linalg.norm(xs[-1] - xs[-2])) / lam_e]
            fine_flags.pop()
        return xs, ls, fine_flags

    def _rope_ends(self, rope, n0):
        """Rope ends: fixed, on a hitch spring (free node, spring to the anchor) or on a body."""
        scene, nodes_slot, nodes_x = self.scene, self.nodes_slot, self.nodes_x
        stops = rope.route
        for end, st_ in ((0, stops[0]), (1, stops[-1])):
            i = n0 if end == 0 else len(nodes_x) - 1
            if st_.sheave is not None:
                raise SceneError(f"{scene.source}: the Lagrangian baseline needs anchors at both rope ends")
            body = None if st_.anchor == "ground" else st_.anchor
            at = np.asarray(st_.at, float)[[0, 2]]
            if st_.hitch_stiffness > 0 or st_.hitch_damping > 0:
                base = at if body is None else np.asarray(self.bodies[body].position, float)[[0, 2]] + at
                self.hitches.append((i, body, base, st_.hitch_stiffness * rope.count,
                                     st_.hitch_damping * rope.count))
                nodes_slot[i] = ("free", "free")
            elif body is None:
                nodes_slot[i] = ("fixed", "fixed")
                nodes_x[i] = at.copy()
            else:
                b = self.bodies[body]
                nodes_slot[i] = tuple(("body", self.body_dof[(body, ax)]) if ax in b.free else "fixed"
                                      for ax in ("x", "z"))

    # ------------------------------------------------------------------------ unknown numbering
    def number_unknowns(self):
        """Banded unknowns (free node coordinates, in rope order) first, then the border; node
        coordinates on a body or fixed get an offset instead. Sets the initial guess q0."""
        ale, ale_st, border, body_dof = self.ale, self.ale_st, self.border, self.body_dof
        nodes_slot = self.nodes_slot
        nn = len(self.nodes_x)
        node_dof = -np.ones((nn, 2), np.int64)
        node_off = np.zeros((nn, 2))
        X0 = np.array(self.nodes_x, float)
        nb = 0
        banded_names = []
        for i in range(nn):
            slot = nodes_slot[i] or ("free", "free")
            for k in range(2):
                kind = slot[k]
                if kind == "free":
                    node_dof[i, k] = nb
                    banded_names.append(f"node{i}.{'xz'[k]}")
                    nb += 1
        m = len(border)
        for i in range(nn):
            slot = nodes_slot[i] or ("free", "free")
            for k in range(2):
                kind = slot[k]
                if kind == "fixed":
                    node_off[i, k] = X0[i, k]
                elif isinstance(kind, tuple):
                    jb = kind[1]
                    node_dof[i, k] = nb + jb
                    bname = border[jb][0].rsplit(".", 1)[0]
                    ax = "xz"[k]
                    node_off[i, k] = X0[i, k] - ale_st.q[ale.body_dofs[bname][ax]]
        q_names = tuple(banded_names + [b[0] for b in border])
        n = nb + m
        q0 = np.zeros(n)
        for i in range(nn):
            for k in range(2):
                j = node_dof[i, k]
                if 0 <= j < nb:
                    q0[j] = X0[i, k]
        for (bname, ax), jb in body_dof.items():
            q0[nb + jb] = ale_st.q[ale.body_dofs[bname][ax]]
        self.nn, self.node_dof, self.node_off, self.X0 = nn, node_dof, node_off, X0
        self.nb, self.m, self.n, self.q_names, self.q0 = nb, m, n, q_names, q0

    def element_arrays(self):
        """Node neighbours and the per-element arrays of the kernel."""
        nn, el_list, scene = self.nn, self.el_list, self.scene
        node_left = -np.ones(nn, np.int64)
        node_right = -np.ones(nn, np.int64)
        node_prev = -np.ones(nn, np.int64)
        node_next = -np.ones(nn, np.int64)
        for ie, (a, b, s1, l, ir) in enumerate(el_list):
            node_right[a] = ie
            node_left[b] = ie
            node_next[a] = b
            node_prev[b] = a
        ne = len(el_list)
        ropes_of = [scene.ropes[e[4]] for e in el_list]
        self.ne = ne
        self.nodes = dict(node_left=node_left, node_right=node_right, node_prev=node_prev,
                          node_next=node_next)
        self.elements = dict(
            el_a=np.array([e[0] for e in el_list], np.int64),
            el_b=np.array([e[1] for e in el_list], np.int64),
            el_s1=np.array([e[2] for e in el_list], float),
            el_l=np.array([e[3] for e in el_list], float),
            el_rhoA=np.array([r.rhoA * r.count for r in ropes_of]),
            el_EA=np.array([r.EA * r.count for r in ropes_of]),
            el_nu=np.array([r.damping for r in ropes_of]),
            el_tonly=np.array([int(r.tension_only) for r in ropes_of], np.int64),
            el_g=np.tile(self.g2, (ne, 1)))

    # ------------------------------------------------------------------------ sheaves
    def sheave_arrays(self):
        """Per used sheave: centre (dof or fixed), radius, groove friction, contact stiffness,
        onset width and damping, stick stiffness, angle unknown or prescribed, rope node range."""
        scene, sheaves, bodies = self.scene, self.sheaves, self.bodies
        ale, ale_st, nb, body_dof = self.ale, self.ale_st, self.nb, self.body_dof
        element_length, penalty = self.element_length, self.penalty
        sh_names = [s for s in self.used]
        ns = len(sh_names)
        sh_dof = -np.ones((ns, 2), np.int64)
        sh_off = np.zeros((ns, 2))
        sh_R = np.zeros(ns)
        sh_mu = np.zeros(ns)
        sh_kn = np.zeros(ns)
        sh_cn = np.zeros(ns)
        sh_w = np.zeros(ns)
        sh_kt = np.zeros(ns)
        sh_th = -np.ones(ns, np.int64)
        sh_presc = np.zeros(ns, np.int64)
        sh_lo = np.zeros(ns, np.int64)
        sh_hi = np.zeros(ns, np.int64)
        sh_J = np.zeros(ns)
        rope_of_sheave = {st.sheave: ir for ir, rope in enumerate(scene.ropes) for st in rope.route
                          if st.sheave is not None}
        for k, name in enumerate(sh_names):
            sh = sheaves[name]
            c = _sheave_center(sh, bodies, ale, ale_st)
            for kk, ax in enumerate(("x", "z")):
                if sh.body is not None and ax in bodies[sh.body].free:
                    sh_dof[k, kk] = nb + body_dof[(sh.body, ax)]
                    sh_off[k, kk] = c[kk] - ale_st.q[ale.body_dofs[sh.body][ax]]
                else:
                    sh_off[k, kk] = c[kk]
            sh_R[k] = sh.radius
            try:
                from ..core.traction import equivalent_friction
                sh_mu[k] = equivalent_friction(sh.mu, sh.undercut_angle, sh.groove_angle, sh.groove)
            except ValueError:
                sh_mu[k] = sh.mu
            ir = rope_of_sheave[name]
            rope = scene.ropes[ir]
            EA = rope.EA * rope.count
            rhoA = rope.rhoA * rope.count
            sh_kn[k] = penalty * EA / element_length
            # onset width of the penalty, in units of the static penetration of a wrap node (C1 contact
            # onset; a sharp kink makes Newton cycle when nodes enter the sheave)
            T_ref = max(self.sheave_Tw.get(name, 0.0), 1e-4 * EA)
            sh_w[k] = 0.5 * T_ref * element_length / (sh.radius * sh_kn[k])
            sh_kt[k] = self.stick * sh_kn[k]
            # Hunt-Crossley coefficient: contact_damping x critical for a node at the static wrap force
            sh_cn[k] = self.contact_damping * 2.0 * math.sqrt(sh_kn[k] * rhoA * element_length) / (
                T_ref * element_length / sh.radius)
            sh_lo[k], sh_hi[k] = self.rope_node_range[ir]
            if name in self.sheave_th:
                sh_th[k] = nb + self.sheave_th[name]
            else:
                sh_presc[k] = 1
            sh_J[k] = sh.inertia + (scene.drive.motor_inertia if scene.drive.sheave == name else 0.0)
        self.sh_names, self.rope_of_sheave = sh_names, rope_of_sheave
        self.sh_dof, self.sh_off, self.sh_R, self.sh_kn, self.sh_w = sh_dof, sh_off, sh_R, sh_kn, sh_w
        self.sheave_rest = dict(sh_mu=sh_mu, sh_cn=sh_cn, sh_kt=sh_kt, sh_th=sh_th, sh_presc=sh_presc,
                                sh_lo=sh_lo, sh_hi=sh_hi, sh_J=sh_J)

    def straighten_free_spans(self):
        """Free spans: straight between the last node on one sheave and the first node on the next
        (the marching put them on the continuous tangent; a polygon leaves the sheave at a node, and
        the straight span from there may cut the circle at the following node, which then joins the
        wrap): shift the span nodes onto that line, keeping their distances along the span."""
        X0, q0, nb, node_dof = self.X0, self.q0, self.nb, self.node_dof
        sh_dof, sh_off, sh_R = self.sh_dof, self.sh_off, self.sh_R
        rope_node_range = self.rope_node_range
        centers = [sh_off[k] + np.array([q0[sh_dof[k, kk]] if sh_dof[k, kk] >= 0 else 0.0 for kk in range(2)])
                   for k in range(len(self.sh_names))]
        on_sheave = -np.ones(len(X0), np.int64)
        for k, name in enumerate(self.sh_names):
            lo, hi = rope_node_range[self.rope_of_sheave[name]]
            for i in range(lo, hi):
                if float(np.linalg.norm(X0[i] - centers[k])) < sh_R[k] * (1 + 1e-9):
                    on_sheave[i] = k

        chord0 = np.array([float(np.linalg.norm(X0[i + 1] - X0[i])) for i in range(len(X0) - 1)] + [0.0])

        def onto_line(a, b):
            """Nodes a..b on the straight line from node a to node b, spaced as the marched chords."""
            A, B = X0[a].copy(), X0[b].copy()
            S = np.concatenate([[0.0], np.cumsum(chord0[a:b])])
            LAB = float(np.linalg.norm(B - A))
            e = (B - A) / LAB
            return [A + e * S[jj] * (LAB / S[-1]) for jj in range(len(S))]

        for ir in range(len(self.scene.ropes)):
            lo, hi = rope_node_range[ir]
            a = lo
            while a < hi - 1:
                while a + 1 < hi - 1 and on_sheave[a + 1] >= 0:
                    a += 1
                b = a + 1
                while b < hi - 1 and on_sheave[b] < 0:
                    b += 1
                for _ in range(50):
                    if b - a <= 1:
                        break
                    pts = onto_line(a, b)
                    changed = False
                    ka, kb_ = on_sheave[a], on_sheave[b]
                    if ka >= 0 and float(np.linalg.norm(pts[1] - centers[ka])) < sh_R[ka]:
                        X0[a + 1] = _on_circle(centers[ka], sh_R[ka], X0[a],
                                               float(np.linalg.norm(X0[a + 1] - X0[a])), pts[1])
                        on_sheave[a + 1] = ka
                        a += 1
                        changed = True
                    if kb_ >= 0 and b - a > 1 and float(np.linalg.norm(pts[-2] - centers[kb_])) < sh_R[kb_]:
                        X0[b - 1] = _on_circle(centers[kb_], sh_R[kb_], X0[b],
                                               float(np.linalg.norm(X0[b] - X0[b - 1])), pts[-2])
                        on_sheave[b - 1] = kb_
                        b -= 1
                        changed = True
                    if not changed:
                        for jj, j in enumerate(range(a, b + 1)):
                            X0[j] = pts[jj]
                        break
                a = b
        for i in range(len(X0)):
            for kk in range(2):
                dj = node_dof[i, kk]
                if 0 <= dj < nb:
                    q0[dj] = X0[i, kk]

    def seat_wrap_nodes(self):
        """Wrap nodes: move inside the pitch circle by the static penetration F_n/k_n, with F_n the
        resultant of the two element tensions at the node's kink (T times the kink angle)."""
        X0, q0, nb, node_dof = self.X0, self.q0, self.nb, self.node_dof
        sh_dof, sh_off, sh_R, sh_kn, sh_w = self.sh_dof, self.sh_off, self.sh_R, self.sh_kn, self.sh_w
        X_arc = X0.copy()
        for k, name in enumerate(self.sh_names):
            ir = self.rope_of_sheave[name]
            Tw = self.sheave_Tw.get(name, 0.0)
            c = sh_off[k] + np.array([q0[sh_dof[k, kk]] if sh_dof[k, kk] >= 0 else 0.0 for kk in range(2)])
            lo, hi = self.rope_node_range[ir]
            for i in range(lo + 1, hi - 1):
                d = X_arc[i] - c
                rho = float(np.linalg.norm(d))
                if rho < sh_R[k] * (1 + 1e-9):
                    e1 = X_arc[i] - X_arc[i - 1]
                    e2 = X_arc[i + 1] - X_arc[i]
                    kink = math.atan2(abs(e1[0] * e2[1] - e1[1] * e2[0]), float(e1 @ e2))
                    F = max(Tw, 0.0) * kink
                    pen = F / sh_kn[k] + 0.5 * sh_w[k] if F / sh_kn[k] > 0.5 * sh_w[k] else \
                        math.sqrt(2.0 * sh_w[k] * F / sh_kn[k])
                    X0[i] = c + d / rho * (sh_R[k] - pen)
                    for kk in range(2):
                        j = node_dof[i, kk]
                        if 0 <= j < nb:
                            q0[j] = X0[i, kk]

    # ------------------------------------------------------------------------ hitches, drive, outputs
    def hitch_arrays(self):
        """Hitch springs: node, anchor (body dof or fixed point), k, c."""
        hitches, bodies, nb = self.hitches, self.bodies, self.nb
        nh = len(hitches)
        hs_node = np.array([h[0] for h in hitches], np.int64)
        hs_dof = -np.ones((nh, 2), np.int64)
        hs_off = np.zeros((nh, 2))
        for hh, (i, body, base, k_, c_) in enumerate(hitches):
            for kk, ax in enumerate(("x", "z")):
                if body is not None and ax in bodies[body].free:
                    hs_dof[hh, kk] = nb + self.body_dof[(body, ax)]
                    hs_off[hh, kk] = base[kk] - self.ale_st.q[self.ale.body_dofs[body][ax]]
                else:
                    hs_off[hh, kk] = base[kk]
        self.hitch = dict(hs_node=hs_node, hs_dof=hs_dof, hs_off=hs_off,
                          hs_k=np.array([h[3] for h in hitches], float),
                          hs_c=np.array([h[4] for h in hitches], float))

    def drive_profile(self):
        """Speed drive: the profile arrays and the gain from car speed to sheave rate."""
        dv = self.scene.drive
        profile = np.zeros((5, 1))
        presc_gain = 0.0
        if dv.kind == "speed":
            R = self.sheaves[dv.sheave].radius
            presc_gain = dv.roping / R
            prof = (scurve(dv.distance, dv.v_max, dv.a_max, dv.jerk, t_start=dv.t_start)
                    if dv.profile == "s-curve" else speed_table(dv.table))
            profile = np.ascontiguousarray(prof.arrays)
        self.profile, self.presc_gain = profile, presc_gain

    def outputs(self):
        """Output table (the engine's names) and the tension taps next to the tangent points."""
        scene, sheaves, nb, body_dof, sh_names = self.scene, self.sheaves, self.nb, self.body_dof, self.sh_names
        names, ok, oi, oj, osc = [], [], [], [], []

        def out(name, kind, i, j=0, scale=1.0):
            names.append(name), ok.append(kind), oi.append(i), oj.append(j), osc.append(scale)
            return len(names) - 1

        for b in scene.bodies:
            for ax in b.free:
                jb = nb + body_dof[(b.name, ax)]
                suffix = "" if len(b.free) == 1 else f".{ax}"
                out(f"{b.name}.position{suffix}", O_Q, jb)
                out(f"{b.name}.velocity{suffix}", O_V, jb)
                out(f"{b.name}.acceleration{suffix}", O_A, jb)
        tap_rows = []
        for k, name in enumerate(sh_names):
            out(f"{name}.angle", O_ANGLE, k)
            out(f"{name}.speed", O_SPEED, k)
            ti = to = None
            for (tname, side, off, dirv, ir) in self.taps:
                if tname != name:
                    continue
                idx = len(tap_rows)
                tap_rows.append((k, off, dirv, ir))
                o = out(f"{name}.tension_{side}", O_TAP, idx)
                if side == "in":
                    ti = o
                else:
                    to = o
            if sheaves[name].kind == "traction" and ti is not None and to is not None:
                out(f"{name}.traction_ratio", O_RATIO, ti, to)
        for ir, rope in enumerate(scene.ropes):
            e0, e1 = self.rope_el_range[ir]
            out(f"{rope.name}.tension_start", O_END, e0, 0)
            out(f"{rope.name}.tension_end", O_END, e1 - 1, 1)
        if scene.drive.kind == "speed":
            out("motor.torque", O_TORQUE, sh_names.index(scene.drive.sheave))
        ntap = len(tap_rows)
        rope_el_range = self.rope_el_range
        self.output_names = tuple(names)
        self.out = dict(out_kind=np.array(ok, np.int64), out_i=np.array(oi, np.int64),
                        out_j=np.array(oj, np.int64), out_scale=np.array(osc, float))
        self.tap = dict(
            tap_sh=np.array([t_[0] for t_ in tap_rows], np.int64),
            tap_off=np.array([t_[1] for t_ in tap_rows], float).reshape(ntap, 2),
            tap_dir=np.array([t_[2] for t_ in tap_rows], float).reshape(ntap, 2),
            tap_d=np.full(ntap, self.probe * self.element_length),
            tap_lo=np.array([rope_el_range[t_[3]][0] for t_ in tap_rows], np.int64),
            tap_hi=np.array([rope_el_range[t_[3]][1] for t_ in tap_rows], np.int64),
            tap_rhoA=np.array([scene.ropes[t_[3]].rhoA * scene.ropes[t_[3]].count for t_ in tap_rows], float),
            tap_last=-np.ones(ntap, np.int64))

    # ------------------------------------------------------------------------ the model
    def model(self) -> dict:
        """The kernel's parameter record (with the lumped mass per unknown for the relaxation) and
        the rest of the model: lagrangian.LagrangianModel's fields."""
        scene, nb, n, border, node_dof = self.scene, self.nb, self.n, self.border, self.node_dof
        dof_m = np.zeros(n)      # lumped mass per unknown (relaxation damping)
        for (a_, b_, s1_, l_, ir_) in self.el_list:
            mh = 0.5 * scene.ropes[ir_].rhoA * scene.ropes[ir_].count * l_
            for node in (a_, b_):
                for kk in range(2):
                    j = node_dof[node, kk]
                    if 0 <= j < nb:
                        dof_m[j] += mh
        for jb, b_ in enumerate(border):
            dof_m[nb + jb] = b_[1]
        lk = LK(
            nb=nb, m=self.m, node_dof=node_dof, node_off=self.node_off, **self.nodes, node_x0=self.X0.copy(),
            **self.elements,
            sh_dof=self.sh_dof, sh_off=self.sh_off, sh_R=self.sh_R, sh_kn=self.sh_kn, sh_w=self.sh_w,
            **self.sheave_rest,
            bd_M=np.array([b[1] for b in border], float), bd_F=np.array([b[2] for b in border], float),
            bd_c=np.array([b[3] for b in border], float),
            **self.hitch,
            presc_gain=float(self.presc_gain), profile=self.profile,
            **self.out, **self.tap,
            dof_m=dof_m, relax_alpha=0.0,
        )
        lock = np.zeros(n, np.bool_)
        for name, jb in self.sheave_th.items():
            lock[nb + jb] = True
        layouts, ale, ale_st = self.layouts, self.ale, self.ale_st
        n_fine = sum(lay["n_fine"] for lay in layouts)
        return dict(scene=scene, LK=lk, q_names=self.q_names, output_names=self.output_names,
                    q_static_guess=self.q0, lock_static=lock, n_elements=self.ne, n_fine=n_fine,
                    element_length=self.element_length,
                    info=dict(layouts=layouts, ranges=self.ranges, sheaves=self.sh_names,
                              rope_length=[lay["L"] for lay in layouts],
                              ale_q=ale_st.q.copy(), ale_outputs=dict(zip(
                                  ale.output_names, self.ale_sim.outputs(ale_st)))))


def _sheave_center(sh, bodies, ale, ale_st):
    """Sheave centre (x, z) in the ALE static configuration."""
    c = np.asarray(sh.center, float).copy()
    if sh.body is not None:
        b = bodies[sh.body]
        pos = np.asarray(b.position, float).copy()
        for ax, j in ale.body_dofs[sh.body].items():
            pos[AXES.index(ax)] = ale_st.q[j]
        c = c + pos
    return c[[0, 2]]
