"""Exact tangents over skewed sheaves (the 8-fall crane reeving): the generalized forces of the spans
and W1 wraps (their rope at the leaving span's strain) are minus the gradient of the rope's elastic
energy, with the rope path (tangent points and wrap angles) computed independently here from the scene
data and the block pose."""
from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from reeve_fmu.core.geometry import tangent, wrap_angle
from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.core.system import assemble, gather


def _stops(sc, m, q):
    """(centre, radius, axis, sense, sigma index) per route stop at the block pose in q."""
    bd = m.body_dofs["block"]
    body = sc.bodies[0]
    pos = q[[bd["x"], bd["y"], bd["z"]]]
    rot = Rotation.from_rotvec(q[[bd["rx"], bd["ry"], bd["rz"]]]).as_matrix()
    sheaves = {s.name: s for s in sc.sheaves}
    out = []
    for st in sc.ropes[0].route:
        if st.sheave is None:
            out.append((np.asarray(st.at, float), 0.0, None, 1.0, None))
            continue
        sh = sheaves[st.sheave]
        c, a = np.asarray(sh.center, float), np.asarray(sh.axis, float)
        if sh.body == body.name:
            c, a = pos + rot @ c, rot @ a
        out.append((c, sh.radius, a, 1.0 if st.wrap == "ccw" else -1.0, m.sheave_dof[sh.name]))
    return out


def _path(sc, m, q):
    """Span end points and wrap angles of the rope at q."""
    stops = _stops(sc, m, q)
    spans = [tangent(A[0], A[1], A[2], A[3], B[0], B[1], B[2], B[3]) for A, B in zip(stops, stops[1:])]
    wraps = [0.0] + [wrap_angle(stops[k][0], stops[k][2], stops[k][3], spans[k - 1][1], spans[k][0])
                     for k in range(1, len(stops) - 1)]
    return stops, spans, wraps


def test_wrap_and_tangent_forces_are_the_elastic_energy_gradient():
    sc = load_scene("scenes/crane_8fall_hoist.toml")
    sc = replace(sc, gravity=(0.0, 0.0, 0.0), statics="none", sheave_contact="rigid",   # creep: stored-rope strain on the drum s
                 ropes=(replace(sc.ropes[0], torsion=None, damping=0.0, tension_only=False),))   # U: bilateral
    m = build_model(sc)
    st = Simulator(m).initial_state()
    nq, EA = m.nq, sc.ropes[0].EA
    # material constants of the span ends: s = sigma + const (the drum, the span ends), read once at
    # the start pose from the model's element data; a W1 wrap's leaving s follows from U's law below
    ne = m.K.el_idx.shape[1]
    nel = m.K.el_idx.shape[0]
    QE, VE = np.empty((nel, ne)), np.empty((nel, ne))
    for ie in range(nel):
        gather(m.KJ, st.el_coef, st.c, st.q, np.zeros(nq), ie, QE, VE)
    nd = 3
    stops, _, wraps = _path(sc, m, st.q)
    nsp = len(stops) - 1
    assert nel == nsp
    const = []
    for k in range(nsp):
        sA = QE[k, 2 * nd] - (st.q[stops[k][4]] + stops[k][1] * wraps[k] if stops[k][4] is not None else 0.0)
        jb = stops[k + 1][4]
        sB = QE[k, 2 * nd + 1] - (st.q[jb] if jb is not None else 0.0)
        const.append((sA, sB))

    def U(q):
        stops, spans, wraps = _path(sc, m, q)
        u = 0.0
        for k, (TA, TB) in enumerate(spans):
            jA, jB = stops[k][4], stops[k + 1][4]
            sB = const[k][1] + (q[jB] if jB is not None else 0.0)
            D = np.linalg.norm(TB - TA)
            if k > 0 and jA is not None:
                # a W1 wrap and its leaving span: one stretch of rope, material sB - sigma over the
                # length R * wrap angle + chord
                L = sB - q[jA]
                u += 0.5 * EA * (stops[k][1] * wraps[k] + D - L) ** 2 / L
                continue
            L = sB - (const[k][0] + (q[jA] if jA is not None else 0.0))
            u += 0.5 * EA * (D - L) ** 2 / L
        return u

    rng = np.random.default_rng(3)
    bd = m.body_dofs["block"]
    pose = [bd[a] for a in ("x", "y", "z", "rx", "ry", "rz")]
    sig = [s[4] for s in stops if s[4] is not None]
    for trial in range(3):
        q = st.q.copy()
        q[pose] += rng.normal(0.0, [0.05, 0.05, 0.05, 0.02, 0.02, 0.2])
        q[sig] += rng.normal(0.0, 0.02, len(sig))
        Q = np.zeros(nq)
        assemble(m.KJ, st.arrays(), st.c, q, np.zeros(nq), 0.0, np.zeros(2), np.zeros((nq, nq)), Q)
        g = np.zeros(nq)
        for j in pose + sig:
            dx = 1e-6
            a, b = q.copy(), q.copy()
            a[j] += dx
            b[j] -= dx
            g[j] = (U(a) - U(b)) / (2.0 * dx)
        idx = pose + sig
        err = np.abs(Q[idx] + g[idx])
        print(trial, err.max() / np.abs(Q[idx]).max(), Q[pose], -g[pose])
        assert err.max() < 1e-6 * np.abs(Q[idx]).max()
