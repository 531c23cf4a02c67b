"""Cubic elements (and several elements per span) with exact tangent points, against exact results:

* a rope over a sheave on a rotating beam and under a sheave on a translating block (two cubic
  elements per span): span end nodes at geometry.tangent of the current poses, end slopes along the
  current span (EI > 0), rope material conserved, energy drift second order in the step;
* the slewing crane (scenes/slewing_crane.toml) with two cubic elements per span: the jib span's
  transverse sway against the taut string f = (1 / 2L) sqrt(T / rho A'), rho A' = rho A s / L the mass
  per stretched length, and the payload's slew-and-hoist motion against the linear-element crane;
* three linear elements per span on the same beam: energy drift second order.
"""
import math

import numpy as np
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import SceneError, load_scene, loads_scene
from reeve_fmu.core.solver import Simulator
from tests.support.beams import (beam_scene as _beam_scene, beam_tangents as _beam_tangents, nodes as _nodes,
                                 run_beam as _run_beam)
from tests.support.linearise import linearised
from tests.support.checks import SECOND_ORDER, check, check_min


def _cubic(text, n=2, extra=""):
    return text.replace("[[ropes]]", f'[[ropes]]\nelement = "cubic"\nelements_per_span = {n}\n{extra}', 1)


def _beam_geometry(m, sim, st):
    """(largest end-node distance from geometry.tangent, largest sine between an end slope at a
    sheave and the span direction, rope material) at st; element layout [r1, d1, s1, r2, d2, s2]."""
    T, wraps = _beam_tangents(m, sim, st)
    X = _nodes(m, st)
    dist, sine = 0.0, 0.0
    for k, (TA, TB) in enumerate(T):
        first, last = X[2 * k], X[2 * k + 1]
        dist = max(dist, np.max(np.abs(first[0:2] - TA[[0, 2]])), np.max(np.abs(last[5:7] - TB[[0, 2]])))
        u = (TB - TA)[[0, 2]] / np.linalg.norm(TB - TA)
        for d, at_sheave in ((first[2:4], k > 0), (last[7:9], k < 2)):
            if at_sheave:
                sine = max(sine, abs(d[0] * u[1] - d[1] * u[0]) / np.linalg.norm(d))
    # a cubic rope's W1 wrap holds R x angle of rope (unstretched)
    return dist, sine, sum(X[2 * k + 1, 9] - X[2 * k, 4] for k in range(3)) + sum(wraps)


def test_cubic_rope_over_sheaves_on_a_rotating_and_a_translating_body():
    """Two cubic elements per span, EI > 0 (end slopes = stretch x current span direction): tangent
    points and slope directions exact, material conserved, energy drift second order in h, and the
    closed-form slope rows' Jacobian and convective acceleration equal to their differences."""
    from reeve_fmu.core import bodies as B
    m = build_model(loads_scene(_cubic(_beam_scene(), extra="EI = 0.5"), "beam_cubic.toml"))
    assert np.count_nonzero(m.K.nl_rk[:, 0] == B.ROW_SLOPE) == 8    # 4 sheave ends x (x, z)
    sim0 = Simulator(m)
    dist, sine, L0 = _beam_geometry(m, sim0, sim0.initial_state())
    assert dist < 1e-14 and sine < 1e-14 and abs(L0 - m.par0[0]) < 1e-14 * L0

    def geometry_holds(sim, st):
        dist, sine, L = _beam_geometry(m, sim, st)
        check("tangent points: distance and slope sine", [dist, sine], 1e-13, reason="round-off of the 3D tangent Newton")
        check('rope material conserved', L - L0, 1e-15 * L0, reason="round-off of the rope length")

    d1, moved = _run_beam(m, 1e-3, geometry_holds)
    d2, _ = _run_beam(m, 5e-4)
    check_min("beam rotation [rad]", -moved["beam.theta"], 0.4)      # the beam swings, the rope runs
    check_min("rope run over the tip sheave [m]", moved["tip.s"], 0.15)
    check('d1', d1, 2e-5)
    check("drift ratio h / (h/2) - 4 (second order)", d1 / d2 - 4, 0.5, reason=SECOND_ORDER)
    K = m.K
    G_ = B.geometry(K)
    nr, nc = K.nl_rk.shape[0], K.nl_cols.shape[0]
    rng = np.random.default_rng(4)
    q, v = m.q0.copy(), np.zeros(m.nq)
    q[K.nl_cols] += 0.3 * rng.standard_normal(nc)
    v[K.nl_cols] = rng.standard_normal(nc)
    lam = K.nl_rf[K.nl_rk[:, 0] == B.ROW_SLOPE, 0].astype(int)
    q[lam] += 0.01 * rng.standard_normal(len(lam))
    v[lam] = 0.1 * rng.standard_normal(len(lam))
    J = [np.zeros((nr, nc)), np.zeros((nr, nc))]
    for fun, Jk in zip((B.rows_jacobian, B.rows_jacobian_fd), J):
        fun(q, G_, K.nl_cols, K.nl_colbody, np.zeros(nr), np.zeros(nr), np.zeros(nr), np.zeros(m.nq), Jk)
    check('J[0] - J[1]', J[0] - J[1], 1e-8 * np.max(np.abs(J[1])))
    f0, acc, ref = np.zeros(nr), np.zeros(nr), np.zeros(nr)
    B.rows_eval(q, *G_, -1, f0)
    B.rows_accel_fd(q, v, G_, K.nl_cols, f0, np.zeros(nr), np.zeros(nr), np.zeros(m.nq), ref)
    B.rows_accel(q, v, G_, acc)
    check('slope-row acceleration: closed form - differences', acc - ref, 9e-7 * np.max(np.abs(ref)))


@pytest.fixture(scope="module")
def cubic_crane():
    m = build_model(loads_scene(_cubic(open("scenes/slewing_crane.toml").read()), "slewing_crane_cubic.toml"))
    sim = Simulator(m)
    return m, sim, sim.initial_state()


def test_cubic_crane_jib_span_sways_like_a_taut_string(cubic_crane):
    """EI = 0: the span ends are pinned (free end slopes), so the first sway mode across the jib
    plane is the taut string's, f = (1 / 2L) sqrt(T / rho A'), L the stretched chord between the
    tangent points, s its material length, rho A' = rho A s / L."""
    m, sim, st = cubic_crane
    Mf, Kf = linearised(sim, st)
    w2, V = np.linalg.eig(np.linalg.solve(Mf, Kf))
    names = [m.q_names[j] for j in m.K.free]
    across = [k for k, nm in enumerate(names) if nm.startswith("hoist.span1.node") and nm.endswith(".y")]
    share = np.sum(np.abs(V[across]) ** 2, axis=0) / np.sum(np.abs(V) ** 2, axis=0)
    f_fe = math.sqrt(w2[int(np.argmax(share))].real) / (2 * math.pi)
    X = _nodes(m, st)
    first, last = X[2], X[3]                 # span 1 (tower top -> tip): elements 2 and 3
    L = np.linalg.norm(last[7:10] - first[0:3])
    s = last[13] - first[6]
    y = dict(zip(m.output_names, sim.outputs(st)))
    T = y["tip.tension_in"]
    f_string = math.sqrt(T / (1.1 * s / L)) / (2 * L)
    check('f_fe / f_string - 1.0', f_fe / f_string - 1.0, 1e-3)


def test_cubic_and_linear_crane_payload_agree(cubic_crane):
    """Slew and hoist start (3 s): the payload follows the same path with cubic and linear elements
    (the spans' own sway and sag, and the W1 wraps: a linear rope's hold their rope at the leaving
    span's strain, a cubic rope's unstretched, which moves the payload by eps R/2-sized offsets and
    their swing: measured 9.96e-3 of the travel)."""
    m, sim, st = cubic_crane
    lin = build_model(load_scene("scenes/slewing_crane.toml"))
    paths = []
    for mm, ss in ((m, sim), (lin, Simulator(lin))):
        res = ss.run(t_end=3.0, out_dt=0.05, state=ss.initial_state())
        paths.append(np.array([res[f"payload.position.{c}"] for c in "xyz"]))
    moved = np.max(np.abs(paths[1] - paths[1][:, :1]))
    diff = np.max(np.abs(paths[0] - paths[1]))
    check_min("payload travel [m] (the slew swings the payload)", moved, 0.05)
    check('diff', diff, 1.5e-2 * moved)


def test_w2_wraps_with_exact_tangents_are_an_error_naming_the_key():
    text = _cubic(_beam_scene(), extra='wrap_model = "W2"')
    with pytest.raises(SceneError, match=r"^beam_w2.toml: \[ropes\[0\]\.wrap_model\] 'W2' cannot hold its cubic wrap "
                                         r"elements with exact tangent points"):
        loads_scene(text, "beam_w2.toml")


def test_cubic_rope_without_bending_stiffness_has_free_end_slopes_and_balances_energy():
    """EI = 0: the end slopes at the sheaves are free coordinates (no slope rows); tangent points
    exact, material conserved, energy drift second order in h."""
    from reeve_fmu.core import bodies as B
    m = build_model(loads_scene(_cubic(_beam_scene()), "beam_cubic_ei0.toml"))
    assert not np.any(m.K.nl_rk[:, 0] == B.ROW_SLOPE)
    sim0 = Simulator(m)
    L0 = _beam_geometry(m, sim0, sim0.initial_state())[2]

    def geometry_holds(sim, st):
        dist, _, L = _beam_geometry(m, sim, st)
        assert dist < 1e-13 and abs(L - L0) < 1e-13 * L0

    d1, moved = _run_beam(m, 1e-3, geometry_holds)
    d2, _ = _run_beam(m, 5e-4)
    check_min("beam rotation [rad]", -moved["beam.theta"], 0.4)
    check('d1', d1, 2e-5)
    check("drift ratio h / (h/2) - 4 (second order)", d1 / d2 - 4, 0.5, reason=SECOND_ORDER)


def test_linear_elements_several_per_span_with_exact_tangents_balance_energy():
    """Three linear elements per span on the rotating / translating beam: interior nodes free, their
    s interpolated between the span ends; energy drift second order in h."""
    m = build_model(loads_scene(_beam_scene().replace("[[ropes]]", "[[ropes]]\nelements_per_span = 3", 1), "b3.toml"))
    d1, moved = _run_beam(m, 1e-3)
    d2, _ = _run_beam(m, 5e-4)
    check_min("beam rotation [rad]", -moved["beam.theta"], 0.4)      # the beam swings, the rope runs
    check_min("rope run over the tip sheave [m]", moved["tip.s"], 0.15)
    check('d1', d1, 5e-6)
    check("drift ratio h / (h/2) - 4 (second order)", d1 / d2 - 4, 0.5, reason=SECOND_ORDER)


def test_coloured_newton_matrix_equals_the_column_by_column_one(cubic_crane):
    """The dense Newton matrix of a model with nonlinear rows, differenced with the columns of a
    group (sparse.dense_groups) perturbed together, is the column-by-column one to the bit: a
    column's entries come from rows no other column of its group reaches."""
    from reeve_fmu.core.kernel import compiled_kernel
    from reeve_fmu.core.solver.newton import build_jacobian
    from reeve_fmu.core.system import workspace
    m, sim, st = cubic_crane
    nf = len(m.K.free)
    assert 0 < m.K.nl_grp[0] < nf                    # 32 groups for 44 columns
    rng = np.random.default_rng(5)
    v, qdd = 0.01 * rng.standard_normal(m.nq), 0.1 * rng.standard_normal(m.nq)
    u = sim.kernel_inputs(st)
    jacs = []
    for K in (m.K, m.K._replace(nl_grp=np.zeros(1, np.int64))):
        KJ = compiled_kernel(K)
        jac = np.zeros((nf, nf))
        build_jacobian(KJ, workspace(KJ, st.arrays()), st.c.copy(), st.q.copy(), v.copy(), qdd.copy(), 0.0, u, jac,
                       np.zeros(nf, np.int64), np.zeros(nf), np.zeros(nf), 1e-5, 1e-3)
        jacs.append(jac)
    assert np.array_equal(jacs[0], jacs[1])
