"""Element and q-level Jacobians of the banded Newton matrix (core/jacobian.py) against central finite
differences: element by element (stiffness and damping parts separately), and the assembled matrix
against one difference per coordinate through the dense assembly, at random states (positions off
equilibrium, so tension-only spans are partly slack), on both sheave contacts."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.scaling import crane, elevator
from reeve_fmu.core.jacobian import _element_res, element_block, element_scratch, newton_matrix_analytic
from reeve_fmu.core.kernel import compiled_kernel
from reeve_fmu.core.model import build_model, new_state
from reeve_fmu.core.scene import Drive, load_scene
from reeve_fmu.core.solver import Simulator
from reeve_fmu.core.solver.inputs import kernel_inputs_at
from reeve_fmu.core.sparse import build_sparse, jac_shape, unpack_dense
from reeve_fmu.core.system import assemble, element_eval, workspace
from tests.support import ROOT
from tests.support.checks import check


def _ropes(sc, **kw):
    return sc.with_overrides(ropes=tuple(r.__class__(**{**r.__dict__, **kw}) for r in sc.ropes))


def _scene(path, **kw):
    return _ropes(load_scene(ROOT / path), **kw)


def _braked():
    """Tension-only ropes, torque-driven traction sheave with the brake engaged."""
    sc = _scene("scenes/hard/slack_hard_stop.toml", elements_per_span=4)
    return sc.with_overrides(drive=Drive(kind="external", sheave="traction", roping=2.0, motor_inertia=2.5))


MODELS = {
    "1d-linear-W1-hitch": lambda: _scene("scenes/elevator_2to1.toml", elements_per_span=4),
    "1d-linear-W0": lambda: _scene("scenes/elevator_2to1.toml", elements_per_span=4, wrap_model="W0"),
    "1d-slack-brake": _braked,
    "1d-traction-slip": lambda: _scene("scenes/hard/traction_en81.toml", elements_per_span=4),
    "1d-drum": lambda: _scene("tests/scenes/drum_hoist.toml", elements_per_span=8),
    "planar-linear-slack": lambda: _scene("scenes/hard/slack_hard_stop.toml", elements_per_span=4).with_overrides(
        model="planar"),
    "planar-cubic-W1": lambda: elevator(3),
    "planar-cubic-W2": lambda: _ropes(elevator(2), wrap_model="W2"),
    "spatial-linear-crane": lambda: crane(2),
    "planar-cubic-bending": lambda: _ropes(elevator(2), EI=50.0),
    "spatial-cubic-crane": lambda: _ropes(crane(1), element="cubic", EI=50.0),
}


def _random_state(m, sim, seed=7):
    """Positions 1 mm off the initial geometry, velocities 0.1 m/s, accelerations 1 m/s^2 (random),
    kernel inputs of that state with the brake engaged and deflected."""
    rng = np.random.default_rng(seed)
    st = new_state(m)
    st.q[:] = st.q + 1e-3 * rng.standard_normal(m.nq)
    st.v[:] = 0.1 * rng.standard_normal(m.nq)
    qdd = rng.standard_normal(m.nq)
    ue = kernel_inputs_at(m, st)
    ue[1], ue[2], ue[4] = 1.0, 3e-5, 2e-5      # brake engaged, brake and groove spring deflected
    return st, qdd, ue


def _model(name, contact):
    sc = dataclasses.replace(MODELS[name](), sheave_contact=contact)
    m = build_model(sc)
    # Kelvin-Voigt damping on every rope (the elevator ropes' 2e-3 s where a scene has none)
    return m, compiled_kernel(m.K._replace(el_nu=np.where(m.K.el_nu > 0.0, m.K.el_nu, 2e-3)))


@pytest.mark.parametrize("name", list(MODELS))
def test_element_jacobians(name):
    """Every element's block d r_e/dq_e (stiffness: elastic, gravity, inertia) and d r_e/dv_e
    (damping, quadratic velocity) against central differences of the element kernel."""
    m, KJ = _model(name, "rigid")
    sim = Simulator(m)
    st, qdd, _ = _random_state(m, sim)
    n_el, ne = m.K.el_idx.shape
    nd = m.K.nd
    QE, VE, MEs, QEs = np.empty((n_el, ne)), np.empty((n_el, ne)), np.empty((n_el, ne, ne)), np.empty((n_el, ne))
    X, XD, MEt, QEt = np.empty((1, ne)), np.empty((1, ne)), np.empty((1, ne, ne)), np.empty((1, ne))
    r0, r1, S, JE = np.empty(ne), np.empty(ne), element_scratch(nd, ne), np.empty((ne, ne))
    worst = (0.0, -1, "")
    for ie in range(n_el):
        element_eval(KJ, st.el_coef, st.c, st.q, st.v, ie, QE, VE, MEs, QEs)
        ae = np.einsum("aw,aw->a", st.el_coef[ie], qdd[m.K.el_map[ie]])
        parts = []
        for gv in (0.0, 1.0):        # stiffness (bq = 1, gv = 0), then stiffness + damping
            element_block(KJ, ie, QE, VE, MEs, QEs, ae, 0.0, 1.0, gv, JE, X, XD, np.zeros((1, nd)), MEt, QEt, r0, r1,
                          S)
            parts.append(JE.copy())
        Kq, Cv = parts[0], parts[1] - parts[0]
        G1 = m.K.el_g[ie:ie + 1].copy()
        Aq, Av = np.empty((ne, ne)), np.empty((ne, ne))

        def central(arr, b, h):
            X[0], XD[0] = QE[ie], VE[ie]
            arr[0, b] += h
            _element_res(KJ, ie, True, X, XD, ae, G1, MEt, QEt, r1)
            arr[0, b] -= 2.0 * h
            _element_res(KJ, ie, True, X, XD, ae, G1, MEt, QEt, r0)
            return (r1 - r0) / (2.0 * h)
        # the reference at two steps (q: Richardson-extrapolated central differences, the tension-only
        # law bends within 1e-6 strain; v: central, exact for the quadratic inertia terms); where they
        # differ (round-off, a slack span's smoothed law) that difference is the reference's uncertainty
        ref = {}
        for k in (1.0, 0.1):
            hq, hv = 1e-7 * k * (1.0 + np.abs(QE[ie])), 1e-5 * k * (1.0 + np.abs(VE[ie]))
            for b in range(ne):
                Aq[:, b] = (4.0 * central(X, b, 0.5 * hq[b]) - central(X, b, hq[b])) / 3.0
                Av[:, b] = central(XD, b, hv[b])
            ref[k] = (Aq.copy(), Av.copy())
        for part, B, A1, A2 in (("q", Kq, ref[1.0][0], ref[0.1][0]), ("v", Cv, ref[1.0][1], ref[0.1][1])):
            err = np.max((np.abs(B - A2) - np.abs(A1 - A2)) / np.max(np.abs(A2)))
            worst = max(worst, (err, ie, part))
    # beyond the references' own difference
    check(f"{name}: (|Newton matrix - differences| - references' difference) / max", worst[0], 1e-6,
          reason="the models differ by 100x: the planar slack span's smoothed tension-only law is the largest")


@pytest.mark.parametrize("contact", ["rigid", "creep"])
@pytest.mark.parametrize("name", list(MODELS))
def test_newton_matrix_equals_differences(name, contact):
    """The assembled banded Newton matrix (h = 1 ms, rho_inf = 1) against one central difference per
    coordinate through the dense assembly: elements, wraps, hitches, brake, groove friction, drums and
    the creep sheaves' strain couplings."""
    m, KJ = _model(name, contact)
    sim = Simulator(m)
    st, qdd, ue = _random_state(m, sim)
    SP = build_sparse(m.K)
    bq, gv = 2.5e-7, 5e-4
    J = np.zeros(jac_shape(SP))
    assert newton_matrix_analytic(KJ, SP, workspace(KJ, st.arrays(), False), st.c, st.q.copy(), st.v.copy(), qdd.copy(), 0.0,
                                  ue, J, np.empty(m.nq), 1.0, bq, gv) == 1
    M, Q = np.empty((m.nq, m.nq)), np.empty(m.nq)

    def r(qq, vv, aa):
        assemble(KJ, st.arrays(), st.c, qq, vv, 0.0, ue, M, Q)
        return (M @ aa - Q)[SP.perm]
    ref = []
    for rel in (1e-7, 1e-9):       # two steps: their difference is the reference's own uncertainty
        A = np.empty((SP.n, SP.n))
        for jb, j in enumerate(SP.perm):
            dx = rel * (1.0 + abs(st.q[j])) / bq
            cols = []
            for s in (1.0, -1.0):
                qq, vv, aa = st.q.copy(), st.v.copy(), qdd.copy()
                qq[j] += s * bq * dx
                vv[j] += s * gv * dx
                aa[j] += s * dx
                cols.append(r(qq, vv, aa))
            A[:, jb] = (cols[0] - cols[1]) / (2.0 * dx)
        ref.append(A)
    A1, A2 = ref
    err = np.max(np.abs(unpack_dense(J, SP) - A2) - np.abs(A1 - A2)) / np.max(np.abs(A2))
    # beyond the references' own difference
    check(f"{name}, {contact}: (|Newton matrix - differences| - references' difference) / max", err, 1e-9,
          reason="the models differ by 1000x, from the spatial crane to the 1-D elevator")
