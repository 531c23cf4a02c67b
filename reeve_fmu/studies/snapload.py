"""Snap load of a hoist rope: the exact wave solution of an elastic rope with an end mass whose top end
stops (docs/hard-cases.md, emergency stop), and an independent lumped wave chain to check it.

Rope of material length L (axial stiffness EA, mass per length rhoA) hanging from a drum, carrying a mass
m at its lower end, everything moving down at V. The top end then follows a prescribed velocity history
(the stop). Gravity is carried by the static state; for a linear rope law the dynamic part is exactly
the wave equation rhoA u_tt = EA u_ss in the material coordinate s (down from the drum), with
superposition. d'Alembert: the velocity change is v = F(t - s/c) + G(t + s/c), the dynamic tension
N = -Z (F - G), c = sqrt(EA/rhoA), Z = sqrt(EA rhoA).

* top (s = 0):   F(t) = v0(t) - G(t)                          (prescribed velocity change v0)
* mass (s = L):  with the incident wave a(t) = F(t - tau) and the reflected b(t) = G(t + tau),
                 tau = L/c, the mass velocity is w = a + b and m w' = Z (a - b) = Z (2a - w).

So one round trip 2 tau maps the incident history onto the next: a delay-differential recursion. Here
it is evaluated on a grid of N steps per round trip; the first-order mass equation is integrated exactly
for an incident wave linear between grid points, so the result converges as N^-2 (`converged_peak`
checks it by doubling N). No mesh, no rope modes, no damping: an independent reference for any
discretisation of the same rope.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np


@dataclass(frozen=True)
class Hoist:
    mass: float        # kg, end mass
    EA: float          # N, axial stiffness
    rhoA: float        # kg/m, mass per unstretched length
    length: float      # m, material (unstretched) length of the hanging rope at the stop
    speed: float       # m/s, lowering speed before the stop
    t_stop: float = 0.0  # s, the top end decelerates linearly to rest over t_stop (0: instantly)
    g: float = 9.81

    @property
    def c(self) -> float:
        return math.sqrt(self.EA / self.rhoA)

    @property
    def Z(self) -> float:
        return math.sqrt(self.EA * self.rhoA)

    @property
    def tau(self) -> float:
        return self.length / self.c


def _v0(h: Hoist, t):
    """Velocity change of the top end (down positive): 0 before the stop, -V once stopped."""
    if h.t_stop <= 0.0:
        return np.where(t >= 0.0, -h.speed, 0.0)
    return -h.speed * np.clip(t / h.t_stop, 0.0, 1.0)


def wave_solution(h: Hoist, t_end: float, n_per_trip: int = 4096):
    """Tension at the mass and mass velocity change after a stop at t = 0.

    Returns (t, T_mass, w): time [s] from the start of the stop, total rope force at the mass [N]
    (m g + dynamic), velocity change of the mass [m/s]. n_per_trip grid steps per round trip 2 L/c (even).
    """
    half = max(1, n_per_trip // 2)
    dt = h.tau / half
    n = int(math.ceil(t_end / dt)) + 1
    t = np.arange(n) * dt
    v0 = _v0(h, t)                   # an instant stop becomes a ramp over one grid step
    lam_h = h.Z / h.mass * dt
    e = math.exp(-lam_h)
    q = (1.0 - e) / lam_h
    F = np.zeros(n)                  # down-going wave at the top
    a = np.zeros(n)                  # incident at the mass: a[k] = F[k - half]
    b = np.zeros(n)                  # reflected at the mass: reaches the top as G[k + half] = b[k]
    w = np.zeros(n)
    for k in range(n):
        G = b[k - half] if k >= half else 0.0
        F[k] = v0[k] - G
        if k >= half:
            a[k] = F[k - half]
        if k > 0:
            # m w' + Z w = 2 Z a with a linear over the step: exact update
            da = a[k] - a[k - 1]
            w[k] = e * w[k - 1] + 2.0 * (a[k - 1] * (1.0 - e) + da * (1.0 - q))
        b[k] = w[k] - a[k]
    T = h.mass * h.g + h.Z * (b - a)
    return t, T, w


def converged_peak(h: Hoist, t_end: float, n_per_trip: int = 2048):
    """Peak rope force at the mass over [0, t_end] from the wave solution at n and 2n steps per round
    trip, Richardson-extrapolated (second order). Returns (peak [N], time of the peak [s], estimated
    error of the extrapolated peak [N] = |fine - coarse| / 3)."""
    _, T1, _ = wave_solution(h, t_end, n_per_trip)
    t2, T2, _ = wave_solution(h, t_end, 2 * n_per_trip)
    p1, p2 = T1.max(), T2.max()
    peak = p2 + (p2 - p1) / 3.0
    return float(peak), float(t2[np.argmax(T2)]), float(abs(p2 - p1) / 3.0)


def lumped_chain(h: Hoist, t_end: float, segments: int, cfl: float = 0.5):
    """Independent check: the same rope as a chain of `segments` point masses and springs (lumped mass,
    half a segment's mass at each end; the end node's force is the end
    segment's, as in the wave solution), top node prescribed, integrated with velocity Verlet (central
    differences) at `cfl` times the stability limit, starting from the static state (linear rope
    law, like the wave solution: the rope carries compression if the motion asks for it).
    Returns (t, T_mass, T_min): time from the start of the stop, total rope force at the end mass and the
    smallest total force along the rope (below zero: a real rope would be slack there)."""
    n = segments
    ds = h.length / n
    k = h.EA / ds
    mi = np.full(n, h.rhoA * ds)                 # nodes 1..n (node 0 is the prescribed top end)
    mi[-1] = h.rhoA * ds / 2.0 + h.mass
    dt = cfl * 2.0 / (2.0 * h.c / ds)            # stability limit 2/omega_max, omega_max = 2c/ds
    steps = int(math.ceil(t_end / dt))
    u = np.zeros(n + 1)
    v = np.zeros(n + 1)
    # static force of segment j (node j to j+1) = weight of the nodes below it
    N_static = h.g * np.cumsum(mi[::-1])[::-1]
    weight = mi * h.g
    t_out = np.empty(steps + 1)
    T_out = np.empty(steps + 1)
    N_min = np.empty(steps + 1)

    def forces(u):
        N = N_static + k * np.diff(u)            # segment forces, N[j] between node j and j+1
        f = weight.copy()
        f[:-1] += N[1:] - N[:-1]
        f[-1] -= N[-1]
        return f, N

    f, N = forces(u)
    t_out[0], T_out[0], N_min[0] = 0.0, N[-1], N.min()
    for i in range(1, steps + 1):
        t = i * dt
        v[1:] += 0.5 * dt * f / mi
        u[1:] += dt * v[1:]
        u[0] = _top_displacement(h, t)
        f, N = forces(u)
        v[1:] += 0.5 * dt * f / mi
        t_out[i], T_out[i], N_min[i] = t, N[-1], N.min()
    return t_out, T_out, N_min


def _top_displacement(h: Hoist, t: float) -> float:
    """Integral of the top end's velocity change."""
    if h.t_stop <= 0.0:
        return -h.speed * t
    if t < h.t_stop:
        return -h.speed * t * t / (2.0 * h.t_stop)
    return -h.speed * (t - h.t_stop / 2.0)


def single_mode_peak(h: Hoist) -> float:
    """The one-mode estimates: massless rope m g + V sqrt(k m) and with the rope-mass correction
    m g + V m sqrt(k / m_eff), m_eff = m + rhoA L / 3 (k = EA/L). Returns both (massless, corrected)."""
    k = h.EA / h.length
    return (h.mass * h.g + h.speed * math.sqrt(k * h.mass),
            h.mass * h.g + h.speed * h.mass * math.sqrt(k / (h.mass + h.rhoA * h.length / 3.0)))
