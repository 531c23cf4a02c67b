"""Build step: torsion. A rope with a `torsion` table carries a twist angle phi per sheave stop
(shared by the stop's in- and out-node: the groove transports twist), clamped (fixed) at a drum and
at an anchored rope end. Each span gets a reference frame vector at both ends, fixed to the
support: the sheave's or drum's axis, or at an anchor the body (or world) axis most perpendicular to
the span. The scene's configuration is twist-free: phi along the route starts at 0 and drops by
each span's transport angle. The twist coordinates carry the rope's rotary inertia rho I_p, lumped
half a span to each end (the scene's span lengths). Kernel fields: torsion_fields."""
from __future__ import annotations

import numpy as np

from ..elements.torsion import LAWS
from ..scene import SceneError
from .bodies import world
from .routes import span_tangents, stop_geometry
from .state import BuildState


def transport_angle_np(t, a, b) -> float:
    """Delta = rotation about the unit span direction t from the projection of a to that of b."""
    Y = t @ np.cross(a, b)
    X = a @ b - (a @ t) * (b @ t)
    return float(np.arctan2(Y, X))


def _end_frame(bs: BuildState, stop, t):
    """(body name or None, frame vector in body axes) of a route stop for a span of direction t."""
    if stop.sheave is not None:
        sh = bs.sheaves[stop.sheave]
        a = np.asarray(sh.axis, float)
        return sh.body, a / np.linalg.norm(a)
    body = None if stop.anchor == "ground" else stop.anchor
    e = np.eye(3)[int(np.argmin(np.abs(t)))]    # the axis most perpendicular to the span
    return body, e


def add_torsion(bs: BuildState) -> None:
    """Twist coordinates and the span table of every torsion rope (after add_rope: its elements)."""
    bs.torsion = []
    chained = {b.name for b in bs.scene.bodies if b.parent is not None}
    for ir, rope in enumerate(bs.scene.ropes):
        on = sorted({bs.sheaves[st.sheave].body if st.sheave is not None else st.anchor
                     for st in rope.route} & chained)
        if rope.torsion is not None and on:
            raise SceneError(f"{bs.scene.source}: [ropes[{ir}].torsion] a rope with torsion over a body on a joint "
                             f"on a moving body ({', '.join(on)}) is not available")
        if rope.torsion is None:
            continue
        _add_rope_torsion(bs, ir, rope)


def _add_rope_torsion(bs: BuildState, ir, rope) -> None:
    tor = rope.torsion
    where = f"{bs.scene.source}: [ropes.{rope.name}.torsion]"
    if bs.nlr is None:
        raise SceneError(f"{where} needs exact tangent points (scene.tangents = 'exact' or a rotating body)")
    stops = rope.route
    geo = stop_geometry(stops, bs.sheaves, lambda body, offset: world(bs, body, offset))
    spans = span_tangents(bs.scene.source, rope.name, geo)
    info = bs.rope_info[ir]
    law = LAWS[tor.law]
    # the torque-factor law without GJ0 and k1 does not depend on the twist: no twist coordinates
    twist_free = law == LAWS["torque-factor"] and tor.GJ0 == 0.0 and tor.k1 == 0.0
    rhoIp = tor.rotary_inertia or rope.rhoA * tor.diameter ** 2 / 8.0
    phi = 0.0
    prev_j = -1
    for k, (TA, TB) in enumerate(spans):
        t = (TB - TA) / np.linalg.norm(TB - TA)
        (bA, vA), (bB, vB) = _end_frame(bs, stops[k], t), _end_frame(bs, stops[k + 1], t)
        delta = transport_angle_np(t, vA, vB)
        phiB = phi - delta
        last = k + 1 == len(spans)
        jB = -1
        if not (twist_free or last or stops[k + 1].sheave is None):
            jB = bs.new_q(f"{stops[k + 1].sheave}.twist", "twist", phiB)
        elif twist_free:
            phiB = 0.0
        length = float(np.linalg.norm(TB - TA))
        for j in (prev_j, jB):
            if j >= 0:
                bs.M0_terms.append((j, j, 0.5 * rhoIp * length))
        ie = info["spans"][k][2]
        bs.torsion.append(dict(el=ie, phi=(prev_j, jB), phic=(0.0 if twist_free else phi, phiB),
                               bodies=(bA, bB), v0=np.r_[vA, vB], dref=delta,
                               p=(float(law), rope.EA * rope.count, tor.diameter, tor.k0, tor.k1, tor.GJ0),
                               rope=rope.name, span=k))
        phi, prev_j = phiB, jB


def torsion_fields(bs: BuildState) -> dict:
    """Kernel fields of the torsion spans (tq_*); nl body indices from the nonlinear rows."""
    tq = getattr(bs, "torsion", None) or []
    n = len(tq)

    def body_index(name):
        if name is None or name == "ground":
            return -1
        return bs.nlr.bodies.get(name, -1)
    return dict(tq_el=np.array([s["el"] for s in tq], np.int64),
                tq_phi=np.array([s["phi"] for s in tq], np.int64).reshape(n, 2),
                tq_phic=np.array([s["phic"] for s in tq], float).reshape(n, 2),
                tq_vb=np.array([[body_index(b) for b in s["bodies"]] for s in tq], np.int64).reshape(n, 2),
                tq_v0=np.array([s["v0"] for s in tq], float).reshape(n, 6),
                tq_p=np.array([s["p"] for s in tq], float).reshape(n, 6),
                tq_dref=np.array([s["dref"] for s in tq], float))
