"""Cubic ALE-ANCF element (docs/theory.md §1.3, §2, §3.1, §3.3, §7 items 5, 7) against its energies.

- closed-form mass matrix = rhoA l int N^T N (4-point Gauss), and T = 1/2 qdot^T M qdot;
- Q_v = dT/dq - (dM/dt) qdot by central differences of T and M, with sdot != 0 (2D, 3D);
- Q_el + Q_g = -dV/dq (V returned by the element), Q_d = -dD/dqdot with D from the material strain
  rate computed independently (finite difference in time at fixed material points);
- Lagrangian limit (sdot = 0, s fixed): the standard gradient-deficient ANCF cable (classical mass
  matrix, consistent gravity, elastic forces of the same energy in the physical coordinate), Q_v
  has zero e-rows;
- assembled systems written here: a swinging cubic-element rope conserves energy (DOP853, rtol
  1e-10), also with a free material coordinate at the pin (ALE, rope sliding through an eyelet);
  the transverse frequency of a taut span is f = (1/2L) sqrt(T (1 + eps)/rhoA) (rhoA per unstretched length).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import eigh

from reeve_fmu.core.elements.cubic import (cubic_element, cubic_element_at, cubic_kinetic, cubic_mass,
                                      cubic_mass_gauss, layout)
from tests.support.checks import check

SPREAD = "the cases' errors differ by more than 10x: one bound for all"
ROUNDOFF = "round-off, which differs by platform"
EXACT = "exact here; round-off in general"


def random_state(rng, nd, l=None):
    l = rng.uniform(0.5, 2.0) if l is None else l
    s1 = rng.uniform(-3, 3)
    t = rng.normal(size=nd)
    t /= np.linalg.norm(t)
    r1 = rng.normal(size=nd)
    r2 = r1 + rng.uniform(0.95, 1.05) * l * t + 0.1 * l * rng.normal(size=nd)
    d1 = t * rng.uniform(0.95, 1.05) + 0.2 * rng.normal(size=nd)
    d2 = t * rng.uniform(0.95, 1.05) + 0.2 * rng.normal(size=nd)
    qe = np.concatenate([r1, d1, [s1], r2, d2, [s1 + l]])
    ve = rng.normal(size=4 * nd + 2)
    return qe, ve


def mass(nd, rhoA, qe):
    ne = 4 * nd + 2
    M = np.zeros((ne, ne))
    cubic_mass(nd, rhoA, qe, M)
    return M


def element(nd, qe, ve, rhoA=0.0, EA=0.0, EI=0.0, nu=0.0, g=None, tonly=False):
    ne = 4 * nd + 2
    Me, Qe = np.zeros((ne, ne)), np.zeros(ne)
    g = np.zeros(nd) if g is None else np.asarray(g, float)
    res = cubic_element(nd, rhoA, EA, EI, nu, tonly, g, np.asarray(qe, float), np.asarray(ve, float), Me, Qe)
    return Me, Qe, res


def central(f, x, h):
    return np.array([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])


@pytest.mark.parametrize("nd", [2, 3])
def test_closed_form_mass_matrix_is_the_gauss_integral(nd):
    rng = np.random.default_rng(nd)
    for _ in range(5):
        qe, ve = random_state(rng, nd)
        M = mass(nd, 0.8, qe)
        Mg = np.zeros_like(M)
        cubic_mass_gauss(nd, 0.8, qe, Mg)
        check('M - Mg', M - Mg, 3e-15 * np.abs(Mg).max(), reason=ROUNDOFF)  # round-off
        assert np.allclose(M, M.T, rtol=0, atol=1e-15)
        check('(0.5 * ve @ M @ ve) - cubic_kinetic(nd, 0.8, qe, ve)', (0.5 * ve @ M @ ve) - cubic_kinetic(nd, 0.8, qe, ve), 3e-15 * np.max(np.abs(cubic_kinetic(nd, 0.8, qe, ve))), reason=ROUNDOFF)


@pytest.mark.parametrize("nd", [2, 3])
def test_quadratic_velocity_vector_is_lagrange_form(nd):
    """Q_v = dT/dq - (dM/dt) qdot with random node, slope and material-coordinate rates."""
    rng = np.random.default_rng(10 + nd)
    rhoA = 1.3
    for _ in range(5):
        qe, ve = random_state(rng, nd)
        _, Q, _ = element(nd, qe, ve, rhoA=rhoA)
        h = 1e-6
        dT = central(lambda q: cubic_kinetic(nd, rhoA, q, ve), qe, h)
        Mdot = (mass(nd, rhoA, qe + h * ve) - mass(nd, rhoA, qe - h * ve)) / (2 * h)
        Qfd = dT - Mdot @ ve
        check('Q - Qfd', Q - Qfd, 1.2e-09 * max(1.0, np.abs(Qfd).max()), reason=SPREAD)  # central differences


@pytest.mark.parametrize("nd", [2, 3])
@pytest.mark.parametrize("tonly", [False, True])
def test_elastic_and_gravity_forces_are_minus_grad_V(nd, tonly):
    rng = np.random.default_rng(20 + nd)
    EA, EI, rhoA = 3.0e3, 2.5, 0.9
    g = rng.normal(size=nd) * 9.81
    for _ in range(5):
        qe, _ = random_state(rng, nd)
        z = np.zeros_like(qe)
        _, Q, (N1, N2, V) = element(nd, qe, z, rhoA=rhoA, EA=EA, EI=EI, g=g, tonly=tonly)
        dV = central(lambda q: element(nd, q, z, rhoA=rhoA, EA=EA, EI=EI, g=g, tonly=tonly)[2][2], qe, 1e-6)
        check('Q + dV', Q + dV, 8.4e-10 * max(1.0, np.abs(dV).max()), reason=SPREAD)  # central differences
        o = layout(nd)
        # to round-off
        check('N1 - max(EA * (np.linalg.norm(qe[o[1]:o[2]]) - 1), 0 if tonly else ...', N1 - max(EA * (np.linalg.norm(qe[o[1]:o[2]]) - 1), 0 if tonly else -np.inf), 3e-14 * np.max(np.abs(max(EA * (np.linalg.norm(qe[o[1]:o[2]]) - 1), 0 if tonly else -np.inf))), reason=EXACT)
        check('N2 - max(EA * (np.linalg.norm(qe[o[4]:o[5]]) - 1), 0 if tonly else ...', N2 - max(EA * (np.linalg.norm(qe[o[4]:o[5]]) - 1), 0 if tonly else -np.inf), 3e-14 * np.max(np.abs(max(EA * (np.linalg.norm(qe[o[4]:o[5]]) - 1), 0 if tonly else -np.inf))), reason=EXACT)


def _eps_at(nd, qe, s):
    """Engineering strain at material point s, written independently (physical shape functions)."""
    o = layout(nd)
    l = qe[o[5]] - qe[o[2]]
    xi = (s - qe[o[2]]) / l
    r1, d1, r2, d2 = qe[o[0]:o[1]], qe[o[1]:o[2]], qe[o[3]:o[4]], qe[o[4]:o[5]]
    rs = ((-6 * xi + 6 * xi ** 2) * (r1 - r2) / l + (1 - 4 * xi + 3 * xi ** 2) * d1 + (-2 * xi + 3 * xi ** 2) * d2)
    return np.linalg.norm(rs) - 1.0


@pytest.mark.parametrize("nd", [2, 3])
def test_kelvin_voigt_damping_is_minus_dD_dqdot(nd):
    """D = 1/2 int EA nu epsdot^2 ds with epsdot the rate at fixed material points (5-point Gauss in
    the current element); Q_d = Q(nu) - Q(0) = -dD/dqdot and Q_d.qdot = -2 D."""
    rng = np.random.default_rng(30 + nd)
    EA, nu = 2.0e3, 0.01
    xg, wg = np.polynomial.legendre.leggauss(5)
    xg, wg = 0.5 * (xg + 1), 0.5 * wg
    o = layout(nd)
    for _ in range(4):
        qe, ve = random_state(rng, nd)
        Qd = element(nd, qe, ve, EA=EA, nu=nu)[1] - element(nd, qe, ve, EA=EA)[1]
        l = qe[o[5]] - qe[o[2]]

        def D(v):
            h = 1e-6
            acc = 0.0
            for x, w in zip(xg, wg):
                s = qe[o[2]] + x * l
                ed = (_eps_at(nd, qe + h * v, s) - _eps_at(nd, qe - h * v, s)) / (2 * h)
                acc += 0.5 * l * w * EA * nu * ed * ed
            return acc

        dD = central(D, ve, 1e-4)   # D is quadratic in qdot: exact up to the inner differences
        check('Qd + dD', Qd + dD, 3.3e-06 * max(1.0, np.abs(dD).max()), reason=SPREAD)  # nested differences
        check('(Qd @ ve) - (-2 * D(ve))', (Qd @ ve) - (-2 * D(ve)), 3.4e-10 * np.max(np.abs((-2 * D(ve)))), reason=SPREAD)


def test_lagrangian_limit_is_the_standard_ancf_cable():
    """sdot = 0: e-e block of M = classical ANCF cable matrix (x) I; e-rows of Q: consistent
    gravity and the elastic force of the same energy written in the physical coordinate x in
    [0, l] (independent code); zero quadratic-velocity e-rows."""
    rng = np.random.default_rng(7)
    nd = 2
    rhoA, EA, EI = 1.1, 5.0e3, 3.0
    g = np.array([0.5, -9.81])
    o = layout(nd)
    e_idx = np.r_[o[0]:o[2], o[3]:o[5]]
    for _ in range(3):
        qe, ve = random_state(rng, nd)
        ve[o[2]] = ve[o[5]] = 0.0
        l = qe[o[5]] - qe[o[2]]
        e = qe[e_idx]
        M, Q, _ = element(nd, qe, ve, rhoA=rhoA, EA=EA, EI=EI, g=g)
        C = np.array([[156, 22 * l, 54, -13 * l], [22 * l, 4 * l * l, 13 * l, -3 * l * l],
                      [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l * l, -22 * l, 4 * l * l]]) * rhoA * l / 420
        Mc = np.kron(C, np.eye(nd))
        check('M[np.ix_(e_idx, e_idx)] - Mc', M[np.ix_(e_idx, e_idx)] - Mc, 5e-16 * np.abs(Mc).max(), reason=ROUNDOFF)  # round-off

        def U_std(e):
            """Standard ANCF cable: r(x) = S(x) e, x in [0, l]; 5-point Gauss."""
            xg, wg = np.polynomial.legendre.leggauss(5)
            U = 0.0
            for xx, w in zip(0.5 * l * (xg + 1), 0.5 * l * wg):
                x = xx / l
                S1 = np.array([-6 * x + 6 * x * x, l * (1 - 4 * x + 3 * x * x), 6 * x - 6 * x * x, l * (-2 * x + 3 * x * x)]) / l
                S2 = np.array([-6 + 12 * x, l * (-4 + 6 * x), 6 - 12 * x, l * (-2 + 6 * x)]) / l ** 2
                E = e.reshape(4, nd)
                a, b = S1 @ E, S2 @ E
                kap2 = (a @ a * (b @ b) - (a @ b) ** 2) / (a @ a) ** 2
                U += w * (0.5 * EA * (np.linalg.norm(a) - 1) ** 2 + 0.5 * EI * kap2)
            return U

        Qel_std = -central(U_std, e, 1e-6)
        Qg_std = rhoA * np.concatenate([l * g / 2, l * l * g / 12, l * g / 2, -l * l * g / 12])
        # central differences of the 5-point Gauss energy (h = 1e-6)
        check('Q[e_idx] - (Qel_std + Qg_std)', Q[e_idx] - (Qel_std + Qg_std), 3.7e-10 * np.abs(Qel_std).max())
        _, Qv, _ = element(nd, qe, ve, rhoA=rhoA)
        check('Qv[e_idx]', Qv[e_idx], 1e-12, reason=EXACT)


# ------------------------------------------------------------------------ small assembled systems
class Chain:
    """Cubic elements in a row; node variables [r (nd), d (nd), s]; `fixed` marks constrained node
    variables (held at their initial values, zero rate)."""

    def __init__(self, nd, nodes, fixed, rhoA, EA, EI, g, nu=0.0):
        self.nd, self.p0 = nd, np.asarray(nodes, float)
        self.nv = 2 * nd + 1
        self.free = ~np.asarray(fixed, bool).ravel()
        self.rhoA, self.EA, self.EI, self.nu, self.g = rhoA, EA, EI, nu, np.asarray(g, float)
        self.nel = len(nodes) - 1

    def full(self, q, v):
        p = self.p0.ravel().copy()
        pd = np.zeros(p.size)
        p[self.free] = q
        pd[self.free] = v
        return p, pd

    def assemble(self, q, v):
        if not hasattr(self, "idx"):
            nv, ne = self.nv, 2 * self.nv
            self.idx = np.arange(ne)[None, :] + nv * np.arange(self.nel)[:, None]
            self.G = np.tile(self.g, (self.nel, 1))
            self.MEs, self.QEs = np.empty((self.nel, ne, ne)), np.empty((self.nel, ne))
            self.fix = np.ix_(self.free, self.free)
        p, pd = self.full(q, v)
        n = p.size
        QE, VE = p[self.idx], pd[self.idx]
        M, Q = np.zeros((n, n)), np.zeros(n)
        V = 0.0
        for e in range(self.nel):
            V += cubic_element_at(self.nd, self.rhoA, self.EA, self.EI, self.nu, False, self.G, QE, VE,
                                  self.MEs, self.QEs, e)[2]
            sl = slice(e * self.nv, e * self.nv + 2 * self.nv)
            M[sl, sl] += self.MEs[e]
            Q[sl] += self.QEs[e]
        return M[self.fix], Q[self.free], V

    def rhs(self, t, y):
        n = y.size // 2
        M, Q, _ = self.assemble(y[:n], y[n:])
        return np.concatenate([y[n:], np.linalg.solve(M, Q)])

    def energy(self, y):
        n = y.size // 2
        M, _, V = self.assemble(y[:n], y[n:])
        return 0.5 * y[n:] @ M @ y[n:] + V


def _straight(nd, n_el, L, angle, lam=1.0):
    """Nodes of a straight rope from the origin at angle (from the downward vertical, x-z plane)."""
    t = np.zeros(nd)
    t[0], t[-1] = math.sin(angle), -math.cos(angle)
    nodes = []
    for i in range(n_el + 1):
        s = L * i / n_el
        nodes.append(np.concatenate([lam * s * t, lam * t, [s]]))
    return np.array(nodes)


@pytest.mark.parametrize("nd", [2, 3])
def test_swinging_cubic_rope_conserves_energy(nd):
    """Pendulum rope, 3 elements, pinned top (r fixed, slope free), all s fixed (Lagrangian),
    released from 60 deg: |E(t) - E(0)| <= 3e-13 rhoA g L^2 over 2 s."""
    L, rhoA = 1.0, 1.0
    nodes = _straight(nd, 3, L, math.radians(60))
    fixed = np.zeros_like(nodes, bool)
    fixed[:, -1] = True          # s
    fixed[0, :nd] = True         # pin
    g = np.zeros(nd)
    g[-1] = -9.81
    ch = Chain(nd, nodes, fixed, rhoA=rhoA, EA=200.0, EI=0.02, g=g)
    q0 = nodes.ravel()[ch.free]
    v0 = np.zeros_like(q0)
    end = q0.size - 2 * nd        # free-end node: r at end .. end + nd
    if nd == 3:
        v0[end + 1] = 1.0         # lateral push: a conical swing
    y0 = np.concatenate([q0, v0])
    sol = solve_ivp(ch.rhs, (0.0, 2.0), y0, method="DOP853", rtol=1e-10, atol=1e-12, dense_output=False,
                    t_eval=np.linspace(0, 2.0, 21))
    assert sol.success
    E = np.array([ch.energy(y) for y in sol.y.T])
    scale = rhoA * 9.81 * L * L
    # DOP853 at rtol 1e-10
    check('E - E[0]', E - E[0], 1.7e-13 * scale)
    assert np.ptp(sol.y[end]) > 0.5              # it does swing: the free end travels in x


def test_rope_sliding_through_an_eyelet_conserves_energy():
    """ALE: one cubic element hanging from an eyelet at the origin (node 1: position fixed, slope
    and material coordinate free - an Eulerian node), lower end free (s fixed = rope end). The
    rope slides down through the eyelet while swinging: every Q_v term with sdot != 0, the s-rows
    of gravity and strain are exercised; E = T + V is conserved (no explicit time dependence)."""
    nd = 2
    L = 1.0
    nodes = _straight(nd, 1, 0.5, math.radians(30))
    nodes[0, -1] = 0.5          # s at the eyelet: 0.5 m of rope above it (not modelled)
    nodes[1, -1] = 1.0          # rope end
    fixed = np.zeros_like(nodes, bool)
    fixed[0, :nd] = True
    fixed[1, -1] = True
    ch = Chain(nd, nodes, fixed, rhoA=0.8, EA=2.0e3, EI=0.05, g=[0.0, -9.81])
    q0 = nodes.ravel()[ch.free]
    v0 = np.zeros_like(q0)
    v0[nd] = -0.5               # the eyelet's s: rope running down through it at 0.5 m/s
    y0 = np.concatenate([q0, v0])
    sol = solve_ivp(ch.rhs, (0.0, 0.4), y0, method="DOP853", rtol=1e-10, atol=1e-12,
                    t_eval=np.linspace(0, 0.4, 9))
    assert sol.success
    s_eye = sol.y[nd]
    assert s_eye[0] - s_eye[-1] > 0.15            # it slid down (s at the eyelet decreases)
    E = np.array([ch.energy(y) for y in sol.y.T])
    check('E - E[0]', E - E[0], 1e-14 * 0.8 * 9.81 * L * L)  # DOP853 at rtol 1e-10


@pytest.mark.parametrize("nd", [2, 3])
def test_taut_span_transverse_frequency(nd):
    """Span L = 2 m between fixed points, pre-strain 1e-3 (T = EA eps), 4 cubic elements, EI = 0,
    s fixed: lowest transverse frequency = (1/2L) sqrt(T (1 + eps0)/rhoA)."""
    Ls, n_el = 2.0, 4
    rhoA, EA, eps0 = 0.5, 1.0e5, 1e-3
    L0 = Ls / (1 + eps0)
    nodes = []
    for i in range(n_el + 1):
        s = L0 * i / n_el
        r = np.zeros(nd)
        r[0] = (1 + eps0) * s
        d = np.zeros(nd)
        d[0] = 1 + eps0
        nodes.append(np.concatenate([r, d, [s]]))
    nodes = np.array(nodes)
    fixed = np.zeros_like(nodes, bool)
    fixed[:, -1] = True
    fixed[0, :nd] = fixed[-1, :nd] = True
    ch = Chain(nd, nodes, fixed, rhoA=rhoA, EA=EA, EI=0.0, g=np.zeros(nd))
    q0 = nodes.ravel()[ch.free]
    z = np.zeros_like(q0)
    M, Q0, _ = ch.assemble(q0, z)
    check('Q0', Q0, 3.1e-15 * EA)  # straight pre-strained span is in equilibrium
    K = -central(lambda q: ch.assemble(q, z)[1], q0, 1e-7).T
    w2, modes = eigh(0.5 * (K + K.T), M)
    f = np.sqrt(np.maximum(w2, 0)) / (2 * math.pi)
    # transverse modes: displacements of positions and slopes along axis 1 (and 2 in 3D)
    comp = np.flatnonzero(ch.free) % ch.nv % nd
    trans = [i for i in range(len(f)) if np.sum(modes[comp != 0, i] ** 2) > 0.9 * np.sum(modes[:, i] ** 2)]
    f1 = f[trans[0]]
    T = EA * eps0
    # rhoA per unstretched length: the stretched span carries rhoA/(1 + eps0) per metre
    check('f1 - (math.sqrt(T * (1 + eps0) / rhoA) / (2 * Ls))', f1 - (math.sqrt(T * (1 + eps0) / rhoA) / (2 * Ls)), 3e-5 * np.max(np.abs((math.sqrt(T * (1 + eps0) / rhoA) / (2 * Ls)))))
    assert f[trans[0]] < f[[i for i in range(len(f)) if i not in trans][0]]   # below the first axial mode


@pytest.mark.parametrize("nd", [2, 3])
def test_tension_only_band_stiffness_and_damping_jacobian(nd):
    """A straight cubic element strained within the tension-only law's band (|eps| < linear.slack_band) and
    moving so that the damping is clipped at some Gauss points: cubic_jac.cubic_stiffness (elastic,
    bending, Kelvin-Voigt: -dQ/dq, -dQ/dv) against central differences of the element's force with rhoA
    = 0, and the element is the bilateral one bit for bit once stretched beyond the band."""
    from reeve_fmu.core.elements.cubic_jac import cubic_stiffness
    from reeve_fmu.core.elements.linear import slack_band
    EA, EI, nu, l = 3.0e6, 2.5, 1e-2, 1.3
    d = slack_band(EA)
    ne = 4 * nd + 2
    rng = np.random.default_rng(40 + nd)
    t = rng.normal(size=nd)
    t /= np.linalg.norm(t)
    n = np.zeros(nd)
    n[0], n[1] = -t[1], t[0]
    n /= np.linalg.norm(n)

    def force(q, v, tonly=True):
        return element(nd, q, v, EA=EA, EI=EI, nu=nu, tonly=tonly)[1]
    worst = {"q": 0.0, "v": 0.0}
    for e0 in (-0.6 * d, 0.2 * d, 0.7 * d):
        st = 1.0 + e0          # uniform stretch, a small bend (curvature) through the slopes
        qe = np.concatenate([np.zeros(nd), st * t + 1e-7 * n, [0.0], st * l * t, st * t - 1e-7 * n, [l]])
        ve = np.zeros(ne)
        ve[nd:2 * nd] = 3e-5 * t       # the slope at node 1 shortens, at node 2 lengthens the rope
        ve[3 * nd + 1:4 * nd + 1] = -3e-5 * t
        ve[2 * nd] = 0.1               # and the rope runs through
        ve[4 * nd + 1] = 0.1
        for part, bq, gv in (("q", 1.0, 0.0), ("v", 0.0, 1.0)):
            JE = np.zeros((ne, ne))
            cubic_stiffness(nd, EA, EI, nu, True, qe, ve, bq, gv, JE, np.zeros((2 * nd, ne)), np.zeros((2 * nd, 2 * nd)),
                            np.zeros((ne, ne)), np.zeros((ne, ne)), np.zeros((9, ne)))
            # q: Richardson-extrapolated central differences (the law bends within d); v: central
            h = 1e-3 * d if part == "q" else 1e-8

            def diff(b, hb):
                dq = np.zeros(ne)
                dq[b] = hb
                if part == "q":
                    return -(force(qe + dq, ve) - force(qe - dq, ve)) / (2 * hb)
                return -(force(qe, ve + dq) - force(qe, ve - dq)) / (2 * hb)
            ref = np.array([(4.0 * diff(b, 0.5 * h) - diff(b, h)) / 3.0 for b in range(ne)]).T
            worst[part] = max(worst[part], np.max(np.abs(JE - ref)) / np.max(np.abs(ref)))
    check("band: -dQ/dq against differences / max", worst["q"], 1e-6, reason=SPREAD)
    check("band: -dQ/dv against differences / max", worst["v"], 1e-8, reason=SPREAD)
    qe = np.concatenate([np.zeros(nd), 1.01 * t, [0.0], 1.01 * l * t, 1.01 * t, [l]])
    ve = np.zeros(ne)
    assert np.array_equal(force(qe, ve), force(qe, ve, tonly=False))
