"""Damping and the integrators against closed forms: the hanging rope with one element is exactly a
single-degree-of-freedom oscillator (end mass + a third of the rope's mass on the stiffness EA/L,
consistent gravity), so

* Kelvin-Voigt damping N = EA (eps + nu deps/dt) is stiffness-proportional: zeta = nu omega / 2 and the
  release from the unstretched rope is z = z_s (1 - exp(-zeta w t) (cos w_d t + zeta w / w_d sin w_d t));
* generalized-alpha at rho_inf = 0.8 (numerical damping) reproduces its amplification recursion for that
  oscillator, written here from the Chung-Hulbert definition, step by step;
* Radau (scipy, the reference method) reproduces the damped closed form.
"""
import math

import numpy as np
import pytest

from reeve_fmu.core.model import build_model
from reeve_fmu.core.scene import load_scene
from reeve_fmu.core.solver import Simulator
from tests.support import ROOT
from tests.support.checks import check

G = 9.81


def _oscillator(nu):
    sc = load_scene(ROOT / "scenes" / "hanging_rope.toml")
    rp = sc.ropes[0]
    # bilateral: released from its unstretched length the rope's strain swings back to 0, where a
    # tension-only rope would go slack and the oscillator not be linear
    rope = rp.__class__(**{**rp.__dict__, "damping": nu, "tension_only": False})
    sc = sc.with_overrides(statics="none", ropes=(rope,))
    m_end = sc.bodies[0].mass
    L, EA, rhoA = 50.0, rp.EA, rp.rhoA
    M = m_end + rhoA * L / 3                 # consistent mass at the free node
    K = EA / L
    z_s = -(m_end * G + rhoA * G * L / 2) / K   # consistent gravity: the exact static elongation
    return sc, M, K, z_s


def _released(M, K, z_s, nu, t):
    w = math.sqrt(K / M)
    zeta = nu * w / 2
    wd = w * math.sqrt(1 - zeta ** 2)
    return z_s * (1 - np.exp(-zeta * w * t) * (np.cos(wd * t) + zeta * w / wd * np.sin(wd * t)))


def test_kelvin_voigt_damping_ratio_is_nu_omega_over_2():
    nu = 0.01                                           # s: zeta = 0.054
    sc, M, K, z_s = _oscillator(nu)
    res = Simulator(build_model(sc), method="gen-alpha", step=1e-4, rho_inf=1.0, newton_tol=1e-12).run(3.0, 1e-3)
    z = res["mass.position"]
    exact = _released(M, K, z_s, nu, res.time)
    check('z - exact', z - exact, 3e-6 * abs(z_s))
    # the decay itself: successive minima shrink by exp(-2 pi zeta / sqrt(1 - zeta^2))
    w = math.sqrt(K / M)
    zeta = nu * w / 2
    dev = z - z_s
    peaks = [i for i in range(1, len(dev) - 1) if dev[i] > dev[i - 1] and dev[i] >= dev[i + 1]]
    ratio = dev[peaks[1]] / dev[peaks[0]]
    check('ratio - math.exp(-2 * math.pi * zeta / math.sqrt(1 - zeta ** 2))', ratio - math.exp(-2 * math.pi * zeta / math.sqrt(1 - zeta ** 2)), 1e-4 * np.max(np.abs(math.exp(-2 * math.pi * zeta / math.sqrt(1 - zeta ** 2)))))


def _gen_alpha_recursion(w2, h, rho, x0, n):
    """x_k of the Chung-Hulbert generalized-alpha method for x'' + w2 x = 0, x(0) = x0, v(0) = 0,
    a(0) = -w2 x0, from the method's three equations (balance at the alpha points + Newmark updates)."""
    am = (2 * rho - 1) / (rho + 1)
    af = rho / (rho + 1)
    gamma = 0.5 - am + af
    beta = 0.25 * (1 - am + af) ** 2
    # unknowns (x1, v1, a1): rows = balance, Newmark x, Newmark v
    A = np.array([[(1 - af) * w2, 0.0, 1 - am], [1.0, 0.0, -beta * h * h], [0.0, 1.0, -gamma * h]])
    B = np.array([[-af * w2, 0.0, -am], [1.0, h, (0.5 - beta) * h * h], [0.0, 1.0, (1 - gamma) * h]])
    T = np.linalg.solve(A, B)
    y = np.array([x0, 0.0, -w2 * x0])
    out = [x0]
    for _ in range(n):
        y = T @ y
        out.append(y[0])
    return np.array(out), T


def test_generalized_alpha_at_rho_inf_0_8_follows_its_recursion():
    """Undamped oscillator, 6 steps per period (omega h = 1.05): the engine's positions equal the
    recursion to round-off, and the amplitude falls by the recursion's spectral radius per step
    (0.99938: 17 % over 300 steps; the exact solution keeps its amplitude)."""
    sc, M, K, z_s = _oscillator(0.0)
    w2 = K / M
    h = 2 * math.pi / math.sqrt(w2) / 6
    n = 300
    res = Simulator(build_model(sc), method="gen-alpha", step=h, rho_inf=0.8, newton_tol=1e-13).run(n * h, h)
    x_ref, T = _gen_alpha_recursion(w2, h, 0.8, -z_s, n)
    x = res["mass.position"] - z_s
    assert len(x) == n + 1
    check('x - x_ref', x - x_ref, 5e-12 * abs(z_s))
    radius = max(abs(np.linalg.eigvals(T)))
    check('radius - 0.999383', radius - 0.999383, 1e-6)  # numerical damping at rho_inf < 1
    check('x[-6:]', x[-6:], 0.85 * abs(z_s))
    # and at large omega h the radius tends to rho_inf (the method's definition)
    _, T_inf = _gen_alpha_recursion(1.0, 1e6, 0.8, 1.0, 0)
    check('max(abs(np.linalg.eigvals(T_inf))) - 0.8', max(abs(np.linalg.eigvals(T_inf))) - 0.8, 1e-4)


def test_radau_reproduces_the_damped_release():
    nu = 0.01
    sc, M, K, z_s = _oscillator(nu)
    res = Simulator(build_model(sc), method="radau").run(1.5, 1e-3)
    exact = _released(M, K, z_s, nu, res.time)
    check('res["mass.position"] - exact', res["mass.position"] - exact, 2.5e-8 * abs(z_s))
