"""Linear ALE rope element (docs/theory.md §1.2, §2.2-2.4, §3.1, §3.3) against its defining energies.

The element returns M(q), the generalized force Q(q, qdot) and the potential V(q). Each term must
follow from the scalar functions it is derived from, which are written out independently here:

    T = 1/2 qdot^T M qdot,  M = rhoA l int_0^1 N^T N dxi    (N = [(1-xi)I, xi I, -(1-xi)d, -xi d])
    Q_v = dT/dq - (dM/dt) qdot                              (Lagrange form, §2.3)
    V = 1/2 EA (lambda - 1)^2 l - rhoA l (g.(r1 + r2)/2 + C),  Q_el + Q_g = -dV/dq
    D = 1/2 l EA nu epsdot^2,  Q_d = -dD/dqdot               (Kelvin-Voigt, §3.3)

and derivatives are taken by central finite differences of those functions at random states in
nd = 1, 2, 3. Both the general kernel and the scalar 1-D kernel used by the assembly (if present)
are checked.
"""
from __future__ import annotations

import numpy as np
import pytest

from reeve_fmu.core.elements import linear as lin
from reeve_fmu.core.elements.linear import linear_element
from tests.support.checks import check

SPREAD = "the cases' errors differ by more than 10x: one bound for all"
ROUNDOFF = "round-off, which differs by platform"
EXACT = "exact here; round-off in general"


def _kernel_1d(nd, rhoA, EA, nu, tonly, g, C, qe, ve, Me, Qe):
    """The scalar 1-D kernel through the same interface as linear_element."""
    assert nd == 1
    QE, VE = qe.reshape(1, 4).copy(), ve.reshape(1, 4).copy()
    MEs, QEs = np.zeros((1, 4, 4)), np.zeros((1, 4))
    res = lin.linear_element_1d_at(rhoA, EA, nu, tonly, float(g[0]), C, QE, VE, MEs, QEs, 0)
    Me[:, :] = MEs[0]
    Qe[:] = QEs[0]
    return res


KERNELS = [(nd, "general", linear_element) for nd in (1, 2, 3)]
if hasattr(lin, "linear_element_1d_at"):
    KERNELS.append((1, "scalar-1d", _kernel_1d))
IDS = [f"nd{nd}-{name}" for nd, name, _ in KERNELS]


def element(fn, nd, qe, ve, rhoA=0.0, EA=0.0, nu=0.0, g=None, C=0.0, tonly=False):
    ne = 2 * nd + 2
    Me, Qe = np.zeros((ne, ne)), np.zeros(ne)
    g = np.zeros(nd) if g is None else np.asarray(g, float)
    res = fn(nd, rhoA, EA, nu, tonly, g, C, np.asarray(qe, float), np.asarray(ve, float), Me, Qe)
    return Me, Qe, res


def random_state(rng, nd, lam_range=(0.9, 1.1)):
    """Random element coordinates with material length l in [0.5, 2], stretch in lam_range, and
    random velocities of the nodes and of s1, s2."""
    l = rng.uniform(0.5, 2.0)
    s1 = rng.uniform(-3.0, 3.0)
    r1 = rng.normal(size=nd)
    t = rng.normal(size=nd)
    t /= np.linalg.norm(t)
    r2 = r1 + rng.uniform(*lam_range) * l * t
    qe = np.concatenate([r1, r2, [s1, s1 + l]])
    ve = rng.normal(size=2 * nd + 2)
    return qe, ve


def central_grad(f, x, h):
    g = np.zeros_like(x)
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = h
        g[i] = (f(x + e) - f(x - e)) / (2 * h)
    return g


N_STATES = 6


@pytest.mark.parametrize("nd,name,fn", KERNELS, ids=IDS)
def test_mass_matrix_is_the_integral_of_NtN(nd, name, fn):
    """M = rhoA l int_0^1 N^T N dxi, by 3-point Gauss quadrature (exact for the quadratic integrand),
    to 3e-15 relative (round-off); symmetric."""
    rng = np.random.default_rng(100 + nd)
    rhoA = 0.8
    xg, wg = np.polynomial.legendre.leggauss(3)
    xi, wi = (xg + 1) / 2, wg / 2
    I = np.eye(nd)
    for _ in range(N_STATES):
        qe, ve = random_state(rng, nd)
        Me, _, _ = element(fn, nd, qe, ve, rhoA=rhoA)
        l = qe[-1] - qe[-2]
        d = (qe[nd:2 * nd] - qe[:nd]) / l
        Mref = np.zeros_like(Me)
        for x, w in zip(xi, wi):
            N = np.hstack([(1 - x) * I, x * I, -(1 - x) * d[:, None], -x * d[:, None]])
            Mref += w * rhoA * l * N.T @ N
        check('Me - Mref', Me - Mref, 3e-15 * np.max(np.abs(Mref)), reason=ROUNDOFF)  # round-off
        assert np.array_equal(Me, Me.T)


@pytest.mark.parametrize("nd,name,fn", KERNELS, ids=IDS)
def test_mass_matrix_null_vector(nd, name, fn):
    """§2.2: M [d; d; 1; 1] = 0 (sliding along the chord while s follows moves no material), 4e-15 of |M|."""
    rng = np.random.default_rng(200 + nd)
    for _ in range(N_STATES):
        qe, ve = random_state(rng, nd)
        Me, _, _ = element(fn, nd, qe, ve, rhoA=1.3)
        d = (qe[nd:2 * nd] - qe[:nd]) / (qe[-1] - qe[-2])
        z = np.concatenate([d, d, [1.0, 1.0]])
        check('Me @ z', Me @ z, 4e-15 * np.max(np.abs(Me)), reason=ROUNDOFF)  # round-off


@pytest.mark.parametrize("nd,name,fn", KERNELS, ids=IDS)
def test_quadratic_velocity_vector_is_lagrange_form(nd, name, fn):
    """Q_v = dT/dq - (dM/dt) qdot with T = 1/2 qdot^T M(q) qdot (no gravity, no stiffness, so the
    element's Q is Q_v alone); derivatives by central differences of M (h = 1e-6): 3e-9 relative to
    the largest entry."""
    rng = np.random.default_rng(300 + nd)
    rhoA = 0.9
    for _ in range(N_STATES):
        qe, ve = random_state(rng, nd)
        _, Qv, _ = element(fn, nd, qe, ve, rhoA=rhoA)

        def M_of(q):
            return element(fn, nd, q, ve, rhoA=rhoA)[0]

        dTdq = central_grad(lambda q: 0.5 * ve @ M_of(q) @ ve, qe, 1e-6)
        h = 1e-6
        Mdot_v = (M_of(qe + h * ve) - M_of(qe - h * ve)) @ ve / (2 * h)
        ref = dTdq - Mdot_v
        # central differences, h = 1e-6: round-off ~1e-16/h
        check('Qv - ref', Qv - ref, 6.8e-10 * np.max(np.abs(ref)), reason=SPREAD)


@pytest.mark.parametrize("nd,name,fn", KERNELS, ids=IDS)
def test_elastic_and_gravity_forces_are_minus_dV(nd, name, fn):
    """At rest (qdot = 0) Q = Q_el + Q_g = -dV/dq, where V is the element's returned potential, and
    V itself equals 1/2 EA eps^2 l - rhoA l (g.(r1+r2)/2 + C) (C: g.r_perp of a 1-D line off the
    origin). Stretched and compressed states; 2e-9 relative (h = 1e-6)."""
    rng = np.random.default_rng(400 + nd)
    rhoA, EA = 0.6, 2.0e4
    for k in range(N_STATES):
        qe, _ = random_state(rng, nd, lam_range=(0.97, 1.03))
        zero = np.zeros_like(qe)
        g = rng.normal(size=nd) * 9.81
        C = rng.normal() * 5.0 if nd == 1 else 0.0
        _, Q, res = element(fn, nd, qe, zero, rhoA=rhoA, EA=EA, g=g, C=C)
        l = qe[-1] - qe[-2]
        lam = np.linalg.norm(qe[nd:2 * nd] - qe[:nd]) / l
        V_ref = 0.5 * EA * (lam - 1) ** 2 * l - rhoA * l * (g @ (qe[:nd] + qe[nd:2 * nd]) / 2 + C)
        check('res[4] - V_ref', res[4] - V_ref, 1.7e-15 * (abs(V_ref) + EA * l * 1e-4), reason=ROUNDOFF)  # round-off
        check('res[0] - EA * (lam - 1)', res[0] - EA * (lam - 1), 1e-15 * EA, reason=EXACT)  # round-off
        dV = central_grad(lambda q: element(fn, nd, q, zero, rhoA=rhoA, EA=EA, g=g, C=C)[2][4], qe, 1e-6)
        check('Q + dV', Q + dV, 1.3e-09 * np.max(np.abs(dV)), reason=SPREAD)  # central differences


@pytest.mark.parametrize("nd,name,fn", KERNELS, ids=IDS)
def test_tension_only_has_no_force_in_compression(nd, name, fn):
    """tension_only and lambda < 1 - d (d = linear.slack_band(EA)): no axial force (elastic or damping)
    at all, and the slack energy density -EA d^2/10 (linear.axial_law_d), whose only trace is the
    configurational force EA d^2/10 on the material coordinates (rhoA = 0: no inertia, no gravity)."""
    EA = 1e5
    d = lin.slack_band(EA)
    rng = np.random.default_rng(500 + nd)
    for _ in range(N_STATES):
        qe, ve = random_state(rng, nd, lam_range=(0.8, 0.99))
        _, Q, res = element(fn, nd, qe, ve, EA=EA, nu=1e-2, tonly=True)
        assert res[0] == 0.0 and res[1] == 0.0, res
        check('res[3] + EA d^2/10', res[3] + 0.1 * EA * d * d, 1e-16 * EA * d * d, reason=EXACT)
        esh = np.zeros(2 * nd + 2)
        esh[-2:] = (-0.1 * EA * d * d, 0.1 * EA * d * d)
        check('Q - configurational force', Q - esh, 1e-16 * EA * d * d, reason=EXACT)


@pytest.mark.parametrize("nd,name,fn", KERNELS, ids=IDS)
def test_tension_only_taut_is_the_bilateral_law_bit_for_bit(nd, name, fn):
    """A stretched span (eps >= d = linear.slack_band(EA)) whose total force is not clipped: the tension-only element
    returns the bilateral element's M, Q and results to the bit (a rope that stays taut runs as a
    bilateral one); with damping and without."""
    rng = np.random.default_rng(700 + nd)
    taken = 0
    for k in range(N_STATES):
        qe, ve = random_state(rng, nd, lam_range=(1.0 + 2e-6, 1.05))
        nu = 0.0 if k % 2 else 1e-3
        g = rng.normal(size=nd)
        a = element(fn, nd, qe, ve, rhoA=0.7, EA=3e6, nu=nu, g=g, tonly=True)
        b = element(fn, nd, qe, ve, rhoA=0.7, EA=3e6, nu=nu, g=g, tonly=False)
        if b[2][0] + b[2][1] < 3e6 * lin.slack_band(3e6):
            continue    # damping clipped (a fast-retracting span): not the linear law
        taken += 1
        assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and a[2] == b[2], (a, b)
    assert taken >= N_STATES // 2


def test_tension_only_law_is_conservative_and_smooth():
    """linear.axial_law_d across the band |eps| < d: N = dw/deps and its returned derivatives against
    central differences, N and dN/deps continuous at +-d (N = EA eps, slope EA above; 0, 0 below),
    the total force never negative and without damping exactly N (the clip never acts on N alone),
    and bit for bit the bilateral law wherever taut."""
    from reeve_fmu.core.elements.linear import axial_law_d, slack_band
    EA, nu = 2.9e6, 1e-2
    d = slack_band(EA)
    h, hd = 1e-3 * d, 1e-5 * d
    for eps in np.linspace(-1.5 * d, 1.5 * d, 60):     # not on +-d, where the second derivative jumps
        N, w, _, dN, _, _ = axial_law_d(EA, 0.0, eps, 0.0, True)
        wp, wm = axial_law_d(EA, 0.0, eps + h, 0.0, True)[1], axial_law_d(EA, 0.0, eps - h, 0.0, True)[1]
        check('dw/deps - N', (wp - wm) / (2 * h) - N, 2e-7 * EA * d, reason=SPREAD)
        Np, Nm = axial_law_d(EA, 0.0, eps + h, 0.0, True)[0], axial_law_d(EA, 0.0, eps - h, 0.0, True)[0]
        check('dN/deps - slope', (Np - Nm) / (2 * h) - dN, 1e-6 * EA, reason=SPREAD)
        assert N >= max(EA * eps, 0.0) and 0.0 <= dN <= EA
        for ed in (-1e-2, -1e-4, -1e-6, 1e-6, 1e-4, 1e-2):
            N, _, Nd, _, dNe, dNed = axial_law_d(EA, nu, eps, ed, True)
            assert N + Nd >= 0.0, (eps, ed, N, Nd)
            he = 1e-4 * abs(ed)
            Ndp, Ndm = axial_law_d(EA, nu, eps, ed + he, True)[2], axial_law_d(EA, nu, eps, ed - he, True)[2]
            check('dN_d/depsdot - returned', (Ndp - Ndm) / (2 * he) - dNed, 1e-7 * EA * nu, reason=SPREAD)
            # N_d turns by up to EA nu epsdot over the band: a finer step (the error is O(h^2))
            Ndp, Ndm = axial_law_d(EA, nu, eps + hd, ed, True)[2], axial_law_d(EA, nu, eps - hd, ed, True)[2]
            check('dN_d/deps - returned', (Ndp - Ndm) / (2 * hd) - dNe, 1.5e-8 * EA, reason=SPREAD)
        assert axial_law_d(EA, nu, eps, 0.0, True)[2] == 0.0
    # C1 at the band's ends, from 1e-9 d inside: N = EA d (1 - 1e-9) and EA d 2 (5e-10)^3 there, the slope
    # 3 EA (5e-10)^2 = 2.2e-12 off EA and 0 (at the upper end below the round-off of EA)
    for e, N_end, bound, slope, sbound in ((d, EA * d, 6e-9, EA, 1e-11), (-d, 0.0, 1.5e-27, 0.0, 5e-12)):
        N, _, _, dN, _, _ = axial_law_d(EA, 0.0, e * (1 - 1e-9), 0.0, True)
        check('N at the band end', N - N_end, bound)
        check('slope at the band end', dN - slope, sbound, reason="2.2e-12 at the lower end; at the upper end below EA's round-off")
    # taut: the bilateral expressions themselves
    rng = np.random.default_rng(3)
    for eps in np.r_[d, rng.uniform(d, 1e-2, 50)]:
        for ed in (0.0, 1e-3, -1e-3):
            if EA * eps + EA * nu * ed >= EA * d:
                assert axial_law_d(EA, nu, eps, ed, True) == axial_law_d(EA, nu, eps, ed, False), (eps, ed)


@pytest.mark.parametrize("nd,name,fn", KERNELS, ids=IDS)
def test_damping_force_from_rayleigh_function(nd, name, fn):
    """Q_d = -dD/dqdot with D = 1/2 l EA nu epsdot^2, epsdot = d/dt (|r2 - r1|/(s2 - s1)) along qdot
    (central differences in time and in qdot; D is quadratic in qdot). Q_d is the element's
    Q(qdot) - Q(0) with rhoA = 0 (no inertia, no gravity). 3e-9 relative; the returned damping
    tension equals EA nu epsdot; pure axial flow (nodes fixed, s1dot = s2dot) is not damped."""
    rng = np.random.default_rng(600 + nd)
    EA, nu = 3.0e4, 5e-3
    for _ in range(N_STATES):
        qe, ve = random_state(rng, nd)
        l = qe[-1] - qe[-2]

        def eps(q):
            return np.linalg.norm(q[nd:2 * nd] - q[:nd]) / (q[-1] - q[-2]) - 1.0

        def epsdot(v, h=1e-6):
            return (eps(qe + h * v) - eps(qe - h * v)) / (2 * h)

        def D(v):
            return 0.5 * l * EA * nu * epsdot(v) ** 2

        _, Q1, res = element(fn, nd, qe, ve, EA=EA, nu=nu)
        _, Q0, _ = element(fn, nd, qe, np.zeros_like(ve), EA=EA, nu=nu)
        ref = -central_grad(D, ve, 1e-3)
        check('(Q1 - Q0) - ref', (Q1 - Q0) - ref, 7.3e-07 * np.max(np.abs(ref)), reason=SPREAD)
        check('res[1] - EA * nu * epsdot(ve)', res[1] - EA * nu * epsdot(ve), 4.9e-10 * abs(EA * nu * epsdot(ve)), reason=SPREAD)
        flow = np.concatenate([np.zeros(2 * nd), [1.7, 1.7]])
        _, Qf, resf = element(fn, nd, qe, flow, EA=EA, nu=nu)
        check('resf[1]', resf[1], 1e-12 * EA * nu, reason=EXACT)
        check('Qf - Q0', Qf - Q0, 1e-12 * EA, reason=EXACT)


STIFF = """
[scene]
model = "axial-1d"
t_end = 0.5
output_step = 0.01
[solver]
step = 1e-3
[[bodies]]
name = "mass"
mass = 0.5
[[ropes]]
name = "rope"
EA = 1e9
rhoA = 0.001
length = 10.0
route = [ { anchor = "ground", at = [0, 0, 10] }, { anchor = "mass", at = [0, 0, 0] } ]
[initial]
statics = "rope-length"
"""


def test_stiff_lightly_loaded_rope_is_on_the_linear_law():
    """A tension-only rope of EA 1e9 N, 10 m, holding 0.5 kg (F = 4.9 N at the mass, strain 5e-9): its
    blend band is 1 N / EA (linear.slack_band), so the rope is on the linear law N = EA eps. The static
    elongation is (F + w L/2) L / EA (w = rhoA g; exact for one linear element, whose gravity goes half
    to each node) and the mass stays there in dynamics. With the band at 1e-6 of strain for every rope
    the law gave 62 N at zero strain and the mass flew up 0.18 m in the 0.5 s."""
    from reeve_fmu.core.model import build_model
    from reeve_fmu.core.scene import loads_scene
    from reeve_fmu.core.solver import Simulator
    assert lin.slack_band(1e9) == 1e-9 and lin.slack_band(1e6) == lin.SLACK_STRAIN
    g, L, EA = 9.81, 10.0, 1e9
    F = 0.5 * g + 0.001 * L * g / 2
    res = Simulator(build_model(loads_scene(STIFF, "stiff.toml"))).run()
    z = res["mass.position"]
    # measured 3.0e-16 m (the round-off of a strain taken from 10 m coordinates is ~1e-15 m)
    check("static elongation + z - F L / EA [m]", z[0] + F * L / EA, 3e-15)
    check("mass drift in dynamics [m]", z - z[0], 2.5e-14)                   # measured 2.7e-15 m
    # the tension at the mass (EA eps less the half element's weight) against the mass's weight over the
    # run: measured 1.9e-7, a chord 1e-15 m off (the drift above) in a strain of 5e-9
    check("rope tension at the mass / (m g) - 1", res["rope.tension_end"] / (0.5 * g) - 1, 1e-6)
